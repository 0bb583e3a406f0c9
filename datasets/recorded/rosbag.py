"""Users' own recordings: ROS 1 and ROS 2 bags (read with the ``rosbags`` package) as a locbench dataset.

Spec: ``rosbag[path=<bag>,map=<map.yaml>,odom_topic=/odom,scan_topic=/scan,truth_topic=/ground_truth,...]``.
``path`` is a ROS 1 ``.bag`` file or a ROS 2 bag folder (``metadata.yaml`` plus sqlite3 ``.db3`` or ``.mcap``
storage); a relative path is looked up in the working folder, then under ``$LOCBENCH_DATA``. Spec values cannot
hold ``,`` or ``]``: put such files under a plain name. Reading needs ``pip install 'locbench[ros]'``.

What is read, and how it becomes the dataset (``landmarks``, ``waypoints``, ``events`` and ``fix_topic`` are
optional):

- **Odometry** (``odom_topic``, ``nav_msgs/Odometry``): the message's pose is the robot's pose in its odometry
  frame (only x, y and the yaw of the quaternion are used). Event ``k`` is the increment between consecutive
  poses, expressed in the previous robot frame: (dx, dy) = R(-theta_{k-1}) (p_k - p_{k-1}), dtheta =
  wrap(theta_k - theta_{k-1}); the odometry frame's own origin drops out. The twist's ``linear.x`` and
  ``angular.z`` are passed as ``v`` and ``omega`` with ``dt`` the time since the previous message (the robot's
  velocity estimate, for filters with a velocity model). No wheel travel is known (``d_left``/``d_right`` None).
- **Laser** (``scan_topic``, ``sensor_msgs/LaserScan``): ranges to float64; NaN, +-inf and readings outside
  [range_min, range_max] become ``inf`` (no return, REP 117). Angles are the message's (counter-clockwise from the
  sensor's x axis). The sensor's pose in the robot frame comes from the parameters ``laser_x_m``, ``laser_y_m``,
  ``laser_yaw_rad``: tf is not read (out of scope), so a scanner mounted upside down must be handled before
  recording. ``scan_topic=`` (empty) drops the scans.
- **Ground truth** (``truth_topic``): ``nav_msgs/Odometry``, ``geometry_msgs/PoseStamped`` or
  ``geometry_msgs/PoseWithCovarianceStamped``, whichever type the topic has; its poses must be in the map frame.
  ``truth_label`` says whether it is a measured ground truth or another estimator's output (AMCL, SLAM).
- **Map**: the ROS map_server map named by ``map`` (:func:`~locbench.datasets.recorded.ros_map.load_map_server_map`);
  required when there are scans. With ``map_lines`` (default) line segments are also extracted from its occupied
  cells (the greedy Hough extraction of :func:`~locbench.datasets.recorded.scan_map.extract_map_lines`), so that
  the line-map filter runs too; the map is parsed once per file version
  (:func:`~locbench.datasets.recorded.ros_map.load_map_and_lines`).
- **Time**: the messages' header stamps (s, as recorded: usually Unix time; ``stamps=bag`` uses the time the bag
  recorded each message instead, for drivers that leave headers unset). Each topic's stamps must not go backwards
  (an error names the topic and the message number). Events are trimmed to the ground truth's time span; the
  odometry reference pose is the last message at or before the first truth stamp.
- **Position fixes** (``fix_topic``, ``sensor_msgs/NavSatFix``): latitude and longitude become map-frame (x, y)
  through the tangent plane at the map origin's ``fix_lat0_deg``, ``fix_lon0_deg`` (WGS84, exact through
  earth-centred coordinates; the altitude is dropped) turned by ``fix_yaw_rad`` (the map's x axis, counter-clockwise
  from east); the covariance is the message's east-north block turned likewise, or ``fix_sigma_xy_m``^2 I when its
  ``position_covariance_type`` is unknown (0). Messages without a fix (``status.status`` -1, or NaN) are skipped
  and counted (``metadata["fixes_without_fix"]``).
- **Sidecar files** for what a bag has no standard message for: ``landmarks`` (a landmark map, ``id x y [std_x
  std_y]`` per line), ``waypoints`` (``t x y``, stamped like the bag) and ``events`` (range-bearing sightings,
  ranges to beacons and fixes, one JSON object per line in the textlog format of
  :mod:`~locbench.datasets.recorded.jsonl_events`; the two tables read as a textlog's,
  :mod:`~locbench.datasets.recorded.text_tables`). Relative paths are looked up like the bag's.
- **Twist check**: when the odometry's twist contradicts its own poses (zero while the pose moves, or a total
  distance or turn off by more than a factor 2: :func:`~locbench.datasets.recorded.files.twist_contradiction`), the
  dataset loads with a warning in ``metadata["warnings"]`` (logged, stored with the run's truth and shown in the
  report): filters that predict from the twist (``kf_linear``) would be wrong.
- **Initial belief**: the first ground-truth pose with the covariance diag(``initial_sigma_xy_m``^2 x 2,
  ``initial_sigma_theta_rad``^2).
- **Nominal noise** handed to filters (nothing in a bag says it; documented defaults, override per recording):
  ``laser_sigma_m`` = 0.03 m (a typical scanner's range noise), ``odometry_sigma_xy_per_m`` = 0.05 m/sqrt(m),
  ``odometry_sigma_theta_per_m`` = 0.05 rad/sqrt(m) and ``odometry_sigma_theta_per_rad`` = 0.05 rad/sqrt(rad)
  (a few per cent of the distance travelled, generous for wheel odometry on a flat floor).

Message types are taken from the bag's own definitions (ROS 1 always, ROS 2 from Iron on); older ROS 2 bags
without definitions are decoded with rosbags' latest standard types. A bag that lacks a requested topic raises an
error listing the topics it has. Parsed streams are cached per (bag, size, mtime, topics).

Validation: a bag or map path that does not exist is an error (the user typed it; never a "data not found"
skip); the bag must be a regular file (or a ROS 2 folder of regular files) of at most :data:`MAX_BAG_BYTES` and the
map YAML a regular file of at most :data:`~locbench.datasets.recorded.ros_map.MAX_YAML_BYTES`, looked at with
``os.stat`` before anything opens them (a FIFO, a device or an oversize file: one line naming the path and what
was expected); any failure to open or decode the bag is a clean error naming it; header stamps must be set (> 0) and
non-decreasing per topic; poses finite and within :data:`~locbench.datasets.recorded.files.MAX_POSITION_M`;
twists finite and within :data:`MAX_TWIST`; each scan needs a non-zero ``angle_increment`` with its beams
spanning at most 2 pi and 0 <= ``range_min`` < ``range_max`` <= 1000 m
(:func:`~locbench.datasets.recorded.files.scan_problem`); every odometry and truth orientation a unit quaternion
tilted at most 10 degrees from the vertical (:func:`~locbench.datasets.recorded.files.quaternion_problem`);
odometry and truth stamps that advance, with gaps of at most :data:`MAX_GAP_S`; ``truth_topic`` not ``odom_topic``.
Flagged by the plausibility policy (:mod:`~locbench.datasets.recorded.plausibility`, :data:`BOUNDS`: left out and
listed in ``Dataset.flagged``, a topic with more than 1 % flagged or a 2 s stretch refused): an odometry or truth
pose the robot could not have reached from the last accepted one (a frame reset, a pose at a repeated stamp), a
twist beyond the speed or turn-rate bound, a message repeating the previous one; and the sidecar events' flags.
Scans outside the truth span are counted in ``metadata["scans_outside_truth_span"]``; when a scan topic is read and
has messages, at least one scan must fall inside the truth span (the dataset contract's declared stream).
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Literal

import numpy as np
import numpy.typing as npt

from locbench.core.errors import ConfigError, DependencyNotInstalled
from locbench.core.events import Event, LaserScan, Odometry, PoseFix
from locbench.core.geometry import is_symmetric_psd, quaternion_to_yaw, wrap_angle
from locbench.core.limits import check_input_file
from locbench.core.spec import params_to_dict
from locbench.datasets.dataset import (
    Dataset,
    DatasetBuilder,
    FlaggedSample,
    Gaussian2,
    SensorSpec,
    Trajectory2D,
    WorldMap,
    check_dataset_contract,
    sort_events,
)
from locbench.datasets.recorded import plausibility
from locbench.datasets.recorded.files import (
    MAX_POSITION_M,
    RecordedDataError,
    quaternion_problem,
    quote,
    scan_problem,
    twist_contradiction,
    user_path_candidates,
)
from locbench.datasets.recorded.jsonl_events import MAX_EVENTS_BYTES, read_events_flagged
from locbench.datasets.recorded.ros_map import MAX_YAML_BYTES, load_map_and_lines
from locbench.datasets.recorded.text_tables import read_landmarks, read_waypoints

FloatArray = npt.NDArray[np.float64]

log = logging.getLogger(__name__)

ODOMETRY_TYPES = ("nav_msgs/msg/Odometry",)
#: Largest bag accepted, bytes (a ROS 2 folder: the sum of its files; 16 GiB). The reader streams the bag, so this
#: is no memory bound: it refuses a device or a runaway file before the reader starts on it.
MAX_BAG_BYTES = 16 << 30
#: Largest sidecar file (landmarks, waypoints, events), bytes: the textlog events file's bound.
MAX_SIDECAR_BYTES = MAX_EVENTS_BYTES
#: Bounds of the validation: the largest odometry twist component (m/s, rad/s) and scan range_max (m).
MAX_TWIST = 100.0
#: Largest interval between two messages of the odometry or the truth, s: the truth is interpolated between its
#: samples and an odometry increment spans its interval, so a longer gap (a clock jump) is refused, not bridged.
MAX_GAP_S = 60.0
#: Physical bound of a user's ground robot (m/s, rad/s): an odometry or truth step may move at most
#: ``MAX_SPEED_MPS * dt + MAX_JITTER_M`` and turn at most ``MAX_TURN_RATE_RADPS * dt + MAX_JITTER_RAD`` (the
#: allowances absorb a pose's noise between close stamps); a frame reset or a pose at a repeated stamp fails it. The
#: speed and turn rate are looser than the plausibility policy's, whose 5 m/s and 10 rad/s apply (:data:`BOUNDS`).
MAX_SPEED_MPS = 20.0
MAX_TURN_RATE_RADPS = 20.0
MAX_JITTER_M = 0.05
MAX_JITTER_RAD = 0.05
#: The plausibility bounds of this loader: the policy's, the heading jitter tightened to :data:`MAX_JITTER_RAD`.
BOUNDS = plausibility.BOUNDS.tightened(heading_jitter_rad=MAX_JITTER_RAD)
SCAN_TYPES = ("sensor_msgs/msg/LaserScan",)
FIX_TYPES = ("sensor_msgs/msg/NavSatFix",)
TRUTH_TYPES = ("nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped")
_INSTALL = "reading ROS bags needs the rosbags package; install it with: pip install 'locbench[ros]'"


@dataclass(frozen=True, kw_only=True)
class RosbagParams:
    """Parameters of ``rosbag``.

    Attributes
    ----------
    path : str
        The ROS 1 ``.bag`` file or ROS 2 bag folder.
    map : str
        The map_server YAML file of the map the truth is expressed in ("" = no map; then no scans are allowed).
    odom_topic, scan_topic, truth_topic : str
        Topic names; ``scan_topic`` may be "" to ignore the laser.
    stamps : {"header", "bag"}
        Time of each message: its header stamp, or the time the bag recorded it.
    laser_x_m, laser_y_m, laser_yaw_rad : float
        The scanner's pose in the robot frame (m, m, rad).
    laser_sigma_m : float
        Nominal range noise of the scanner, m.
    odometry_sigma_xy_per_m, odometry_sigma_theta_per_m, odometry_sigma_theta_per_rad : float
        Nominal odometry increment noise (see :class:`~locbench.datasets.dataset.SensorSpec`).
    initial_sigma_xy_m, initial_sigma_theta_rad : float
        Standard deviations of the initial belief around the first truth pose, m and rad.
    truth_label : {"ground truth", "SLAM reference"}
        What the truth topic is.
    map_lines : bool
        Also extract line segments from the map's occupied cells (for ``ekf_lines``).
    fix_topic : str
        A ``sensor_msgs/NavSatFix`` topic read as position fixes ("" = none).
    fix_lat0_deg, fix_lon0_deg : float
        Latitude and longitude (WGS84, deg) of the map frame's origin; required with ``fix_topic``.
    fix_yaw_rad : float
        Direction of the map's x axis, rad counter-clockwise from east (0: x east, y north).
    fix_sigma_xy_m : float
        Nominal fix noise per axis, m: the covariance of fixes whose ``position_covariance_type`` is unknown (0).
    landmarks : str
        A landmark map file (``id x y [std_x std_y]`` per line, m, map frame) ("" = none).
    waypoints : str
        A waypoint file (``t x y`` per line: s in the bag's stamps, m in the map frame) ("" = none).
    events : str
        A sidecar events file in the textlog JSON-lines format holding ``landmarks``, ``ranges`` and ``fix`` events
        (what a bag has no standard message for), stamped like the bag ("" = none).
    landmark_sigma_range_m, landmark_sigma_bearing_rad, range_sigma_m : float
        Nominal noise of range-bearing sightings (m, rad) and of ranges to beacons (m).
    """

    path: str = ""
    map: str = ""
    odom_topic: str = "/odom"
    scan_topic: str = "/scan"
    truth_topic: str = "/ground_truth"
    stamps: Literal["header", "bag"] = "header"
    laser_x_m: float = 0.0
    laser_y_m: float = 0.0
    laser_yaw_rad: float = 0.0
    laser_sigma_m: float = 0.03
    odometry_sigma_xy_per_m: float = 0.05
    odometry_sigma_theta_per_m: float = 0.05
    odometry_sigma_theta_per_rad: float = 0.05
    initial_sigma_xy_m: float = 0.05
    initial_sigma_theta_rad: float = 0.05
    truth_label: Literal["ground truth", "SLAM reference"] = "ground truth"
    map_lines: bool = True
    fix_topic: str = ""
    fix_lat0_deg: float = 0.0
    fix_lon0_deg: float = 0.0
    fix_yaw_rad: float = 0.0
    fix_sigma_xy_m: float = 2.0
    landmarks: str = ""
    waypoints: str = ""
    events: str = ""
    landmark_sigma_range_m: float = 0.1
    landmark_sigma_bearing_rad: float = 0.05
    range_sigma_m: float = 0.1

    def __post_init__(self) -> None:
        for name in (
            "fix_sigma_xy_m",
            "landmark_sigma_range_m",
            "landmark_sigma_bearing_rad",
            "range_sigma_m",
            "laser_sigma_m",
            "odometry_sigma_xy_per_m",
            "odometry_sigma_theta_per_m",
            "odometry_sigma_theta_per_rad",
            "initial_sigma_xy_m",
            "initial_sigma_theta_rad",
        ):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise ConfigError(f"rosbag: parameter {name!r} must be a finite number >= 0, got {v!r}")
        if not (-90.0 <= self.fix_lat0_deg <= 90.0 and -180.0 <= self.fix_lon0_deg <= 180.0):
            raise ConfigError(
                f"rosbag: 'fix_lat0_deg' {self.fix_lat0_deg!r}, 'fix_lon0_deg' {self.fix_lon0_deg!r}: expected a "
                "latitude in [-90, 90] and a longitude in [-180, 180] (deg)"
            )
        if self.fix_topic and self.fix_lat0_deg == 0.0 and self.fix_lon0_deg == 0.0:
            raise ConfigError(
                "rosbag: 'fix_topic' needs the map origin's fix_lat0_deg and fix_lon0_deg (WGS84 degrees) to place "
                "the fixes in the map frame"
            )
        for name in ("laser_x_m", "laser_y_m", "laser_yaw_rad", "fix_yaw_rad"):
            if not math.isfinite(getattr(self, name)):
                raise ConfigError(f"rosbag: parameter {name!r} must be finite, got {getattr(self, name)!r}")
        if not self.odom_topic or not self.truth_topic:
            raise ConfigError("rosbag: 'odom_topic' and 'truth_topic' must name topics")
        if self.truth_topic == self.odom_topic:
            raise ConfigError(
                f"rosbag: 'truth_topic' is the odometry topic {quote(self.odom_topic, 100)}, expected another topic "
                "(a filter would be scored against its own input)"
            )
        if not self.path:
            raise ConfigError(
                "rosbag: parameter 'path' is required: rosbag[path=<.bag file or ROS 2 folder>,map=<yaml>]"
            )


# --- reading the bag -----------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class BagStreams:
    """The three streams of a bag as arrays (the parsed content, before any trimming).

    Attributes
    ----------
    odom_t : ndarray (n,)
        Odometry times, s.
    odom_pose : ndarray (n, 3)
        Poses (x m, y m, yaw rad) in the odometry frame.
    odom_twist : ndarray (n, 2)
        ``twist.linear.x`` m/s and ``twist.angular.z`` rad/s.
    scans : tuple of LaserScan
        The scans with invalid readings set to ``inf`` (:func:`clean_ranges`) and the sensor at the robot origin.
    truth_t : ndarray (m,)
        Ground-truth times, s.
    truth_pose : ndarray (m, 3)
        Ground-truth poses (x m, y m, yaw rad).
    truth_type : str
        The truth topic's message type.
    topics : dict
        Every topic of the bag -> (message type, message count).
    fix_t : ndarray (k,)
        NavSatFix times, s (empty without ``fix_topic``).
    fix_llh : ndarray (k, 3)
        Latitude, longitude (deg) and altitude (m) of each fix.
    fix_cov : ndarray (k, 9)
        ``position_covariance`` (ENU, m^2, row-major) of each fix.
    flagged : tuple of FlaggedSample
        Odometry and truth messages left out by the plausibility policy (:func:`_flag_streams`).
    fix_cov_type, fix_status : ndarray (k,) of int64
        ``position_covariance_type`` (0 unknown ... 3 known) and ``status.status`` (-1 = no fix).
    """

    odom_t: FloatArray
    odom_pose: FloatArray
    odom_twist: FloatArray
    scans: tuple[LaserScan, ...]
    truth_t: FloatArray
    truth_pose: FloatArray
    truth_type: str
    topics: dict[str, tuple[str, int]]
    fix_t: FloatArray = dataclasses.field(default_factory=lambda: np.zeros(0))
    fix_llh: FloatArray = dataclasses.field(default_factory=lambda: np.zeros((0, 3)))
    fix_cov: FloatArray = dataclasses.field(default_factory=lambda: np.zeros((0, 9)))
    fix_cov_type: npt.NDArray[np.int64] = dataclasses.field(default_factory=lambda: np.zeros(0, np.int64))
    fix_status: npt.NDArray[np.int64] = dataclasses.field(default_factory=lambda: np.zeros(0, np.int64))
    flagged: tuple[FlaggedSample, ...] = ()


def _stamp(msg: Any, recorded_ns: int, stamps: str) -> float:
    if stamps == "bag":
        return recorded_ns * 1e-9
    st = msg.header.stamp
    return float(st.sec) + float(st.nanosec) * 1e-9


def _pose_of(msg: Any, msgtype: str) -> Any:
    """The geometry_msgs/Pose inside a truth or odometry message."""
    return msg.pose if msgtype == "geometry_msgs/msg/PoseStamped" else msg.pose.pose


def _planar_poses(poses: list[Any], path: Path, topic: str) -> FloatArray:
    """(x m, y m, yaw rad) of geometry_msgs/Pose messages, shape (n, 3); every orientation must be a planar unit
    quaternion (:func:`~locbench.datasets.recorded.files.quaternion_problem`)."""
    xyq = np.array(
        [
            (p.position.x, p.position.y, p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w)
            for p in poses
        ],
        dtype=np.float64,
    ).reshape(-1, 6)
    q = xyq[:, 2:]
    problem = quaternion_problem(q)
    if problem is not None:
        raise RecordedDataError(path, f"topic {topic!r} message {problem[0] + 1}: {problem[1]}")
    return np.column_stack([xyq[:, :2], quaternion_to_yaw(q)])


def _check_motion(path: Path, topic: str, name: str, t: FloatArray, pose: FloatArray) -> None:
    """Refuse every stamp equal and a gap above :data:`MAX_GAP_S` (too fast a step is flagged later)."""
    if t.size < 2:
        return
    if t[-1] == t[0]:
        raise RecordedDataError(
            path,
            f"topic {topic!r}: all {t.size} {name} messages have one stamp {float(t[0])!r} s, expected stamps that "
            "advance (stamps=bag uses the recording time)",
        )
    dt = np.diff(t)
    gap = np.flatnonzero(dt > MAX_GAP_S)
    if gap.size:
        k = int(gap[0]) + 1
        raise RecordedDataError(
            path,
            f"topic {topic!r} message {k + 1} of {t.size}: {name} stamp jumps {float(dt[k - 1]):.6g} s from the "
            f"previous message, expected gaps of at most {MAX_GAP_S} s (a clock jump is not bridged)",
        )


def _flag_streams(
    path: Path, odom_topic: str, truth_topic: str, odom: tuple[FloatArray, ...], truth: tuple[FloatArray, ...]
) -> tuple[tuple[FloatArray, ...], tuple[FloatArray, ...], tuple[FlaggedSample, ...]]:
    """The odometry (t, pose, twist) and truth (t, pose) without the messages flagged by the plausibility policy
    (:data:`BOUNDS`: a pose off the track reachable from the last accepted one, a twist beyond the speed or turn
    bound, a message repeating the previous one), and the flagged ones."""
    f_odom = plausibility.Flags(path, f"odometry (topic {odom_topic!r})", odom[0])
    f_odom.flag_duplicates(np.column_stack([odom[0], odom[1], odom[2]]))
    f_odom.flag_outside(odom[2][:, 0], "twist speed, m/s", -BOUNDS.speed_mps, BOUNDS.speed_mps)
    f_odom.flag_outside(odom[2][:, 1], "twist turn rate, rad/s", -BOUNDS.turn_rate_radps, BOUNDS.turn_rate_radps)
    f_odom.flag_track(odom[1][:, :2], odom[1][:, 2], BOUNDS)
    f_truth = plausibility.Flags(path, f"ground truth (topic {truth_topic!r})", truth[0])
    f_truth.flag_duplicates(np.column_stack([truth[0], truth[1]]))
    f_truth.flag_track(truth[1][:, :2], truth[1][:, 2], BOUNDS)
    flagged = plausibility.merge(f_odom.finish(), f_truth.finish())
    return tuple(a[f_odom.kept] for a in odom), tuple(a[f_truth.kept] for a in truth), flagged


def resolve_bag_path(path: str | os.PathLike[str], what: str = "bag") -> Path:
    """A user file's local path: as given (absolute or relative to the working folder), else under ``$LOCBENCH_DATA``.

    For a bag, a ROS 2 storage file (``.db3``/``.mcap``) whose folder has a ``metadata.yaml`` stands for that folder.

    Raises
    ------
    RecordedDataError
        When it is in neither place (an error, not a :class:`MissingDataFile` skip: the user named the path).
    """
    candidates = user_path_candidates(path)
    p = candidates[0]
    for c in candidates:
        if os.path.lexists(c):
            storage_file = c.is_file() and c.suffix in (".db3", ".mcap")
            if what == "bag" and storage_file and (c.parent / "metadata.yaml").is_file():
                c = c.parent
            # Looked at before anything opens it: a FIFO would block the reader, a device never end.
            if what == "bag":
                check_input_file(c, "bag", MAX_BAG_BYTES, folder_ok=True)
            elif what == "map":
                check_input_file(c, "map YAML", MAX_YAML_BYTES)
            else:
                check_input_file(c, f"{what} file", MAX_SIDECAR_BYTES)
            return c
    looked = " or ".join(str(c) for c in candidates)
    expected = {"bag": "a ROS 1 .bag file or a ROS 2 bag folder", "map": "a map_server YAML file"}.get(
        what, f"a {what} file"
    )
    # A path the user typed is an error, not a skip: the run must not be stored as "data not found".
    raise RecordedDataError(p, f"missing {what} (looked for {looked}); expected {expected}")


def _signature(path: Path) -> tuple[tuple[str, int, int], ...]:
    """(name, size, mtime) of the bag's files, so that a re-recorded bag is parsed again."""
    files = sorted(q for q in path.iterdir() if q.is_file()) if path.is_dir() else [path]
    return tuple((q.name, q.stat().st_size, q.stat().st_mtime_ns) for q in files)


def read_bag_streams(
    path: str | os.PathLike[str],
    odom_topic: str = "/odom",
    scan_topic: str = "/scan",
    truth_topic: str = "/ground_truth",
    stamps: str = "header",
    fix_topic: str = "",
) -> BagStreams:
    """Parse the odometry, scan and truth topics of a ROS 1 or ROS 2 bag (cached per file signature).

    Raises
    ------
    RecordedDataError
        The bag is not there (an error, not a skip), cannot be opened or decoded, a topic is missing (the message
        lists the bag's topics) or has the wrong message type, a stamp is unset (0) or goes backwards, a pose or
        twist is non-finite or out of bounds, or a scan's geometry is unusable.
    DependencyNotInstalled
        rosbags is not installed.
    """
    p = resolve_bag_path(path)
    return _read_streams_cached(str(p.resolve()), _signature(p), odom_topic, scan_topic, truth_topic, stamps, fix_topic)


@functools.lru_cache(maxsize=4)
def _read_streams_cached(
    path: str,
    signature: tuple[tuple[str, int, int], ...],
    odom_topic: str,
    scan_topic: str,
    truth_topic: str,
    stamps: str,
    fix_topic: str = "",
) -> BagStreams:
    # long: one pass over the bag's messages: every topic's decoder shares the reader and the error context
    del signature  # part of the cache key only
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise DependencyNotInstalled(_INSTALL) from None
    p = Path(path)
    try:
        reader = AnyReader([p], default_typestore=get_typestore(Stores.LATEST))
        reader.open()
    except Exception as exc:  # rosbags raises its own errors, OSError, UnicodeDecodeError ... on foreign bytes
        what = "expected a ROS 1 .bag file or a ROS 2 bag folder"
        raise RecordedDataError(p, f"unreadable bag ({type(exc).__name__}: {quote(str(exc))}); {what}") from None
    try:
        topics = {name: (info.msgtype or "?", int(info.msgcount)) for name, info in reader.topics.items()}
        listing = ", ".join(f"{n} ({t}, {c} messages)" for n, (t, c) in sorted(topics.items())) or "(none)"
        wanted = {"odom_topic": (odom_topic, ODOMETRY_TYPES), "truth_topic": (truth_topic, TRUTH_TYPES)}
        if scan_topic:
            wanted["scan_topic"] = (scan_topic, SCAN_TYPES)
        if fix_topic:
            wanted["fix_topic"] = (fix_topic, FIX_TYPES)
        for param, (topic, types) in wanted.items():
            if topic not in topics:
                raise RecordedDataError(p, f"no topic {topic!r} ({param}); the bag has: {listing}")
            if topics[topic][0] not in types:
                raise RecordedDataError(
                    p, f"topic {topic!r} ({param}) has type {topics[topic][0]}, expected {' or '.join(types)}"
                )
        truth_type = topics[truth_topic][0]
        by_topic: dict[str, list[tuple[float, Any]]] = {t: [] for t, _ in wanted.values()}
        conns = [c for c in reader.connections if c.topic in by_topic]
        try:
            for conn, recorded_ns, raw in reader.messages(connections=conns):
                try:
                    msg = reader.deserialize(raw, conn.msgtype)
                except Exception as exc:  # a corrupt message body raises whatever its decoder meets
                    n = len(by_topic[conn.topic]) + 1
                    raise RecordedDataError(
                        p, f"topic {conn.topic!r} message {n}: cannot decode ({type(exc).__name__}: {quote(str(exc))})"
                    ) from None
                by_topic[conn.topic].append((_stamp(msg, recorded_ns, stamps), msg))
        except RecordedDataError:
            raise
        except Exception as exc:  # a corrupt chunk or index
            raise RecordedDataError(p, f"unreadable bag ({type(exc).__name__}: {quote(str(exc))})") from None
    finally:
        reader.close()

    for topic, items in by_topic.items():
        ts = np.array([t for t, _ in items], dtype=np.float64)
        unset = np.flatnonzero(~(ts > 0))
        if unset.size:
            k = int(unset[0])
            raise RecordedDataError(
                p,
                f"topic {topic!r} message {k + 1} of {ts.size}: {stamps} stamp {float(ts[k])!r} s, expected a time > 0 "
                + ("(an unset header stamp; stamps=bag uses the recording time)" if stamps == "header" else ""),
            )
        back = np.flatnonzero(np.diff(ts) < 0)
        if back.size:
            k = int(back[0]) + 1
            raise RecordedDataError(
                p,
                f"topic {topic!r} message {k + 1} of {ts.size}: {stamps} stamp {float(ts[k])!r} s goes backwards from "
                f"{float(ts[k - 1])!r} s (expected non-decreasing stamps"
                + ("; stamps=bag uses the recording time instead)" if stamps == "header" else ")"),
            )

    odom = by_topic[odom_topic]
    odom_t = np.array([t for t, _ in odom], dtype=np.float64)
    odom_pose = _planar_poses([m.pose.pose for _, m in odom], p, odom_topic)
    odom_twist = np.array([(m.twist.twist.linear.x, m.twist.twist.angular.z) for _, m in odom], dtype=np.float64)
    odom_twist = odom_twist.reshape(-1, 2)
    truth = by_topic[truth_topic]
    truth_t = np.array([t for t, _ in truth], dtype=np.float64)
    truth_pose = _planar_poses([_pose_of(m, truth_type) for _, m in truth], p, truth_topic)
    scans = tuple(
        LaserScan(
            t,
            float(m.angle_min),
            float(m.angle_increment),
            clean_ranges(m.ranges, float(m.range_min), float(m.range_max)),
            float(m.range_min),
            float(m.range_max),
        )
        for t, m in (by_topic[scan_topic] if scan_topic else [])
    )
    for k, scan in enumerate(scans):
        _check_scan(p, scan_topic, k, scan)
        scan.ranges.setflags(write=False)
    for name, arr in (("odometry", odom_pose), ("ground truth", truth_pose)):
        topic = odom_topic if name == "odometry" else truth_topic
        bad = np.flatnonzero(~np.all(np.isfinite(arr), axis=1))
        if bad.size:
            raise RecordedDataError(p, f"topic {topic!r} message {int(bad[0]) + 1}: non-finite {name} pose")
        far = np.flatnonzero(np.any(np.abs(arr[:, :2]) > MAX_POSITION_M, axis=1))
        if far.size:
            k = int(far[0])
            raise RecordedDataError(
                p,
                f"topic {topic!r} message {k + 1}: {name} position ({float(arr[k, 0])!r}, {float(arr[k, 1])!r}) m, "
                f"expected within +-{MAX_POSITION_M} m",
            )
        _check_motion(p, topic, name, odom_t if name == "odometry" else truth_t, arr)
    bad_twist = np.flatnonzero(
        ~np.all(np.isfinite(odom_twist), axis=1) | np.any(np.abs(odom_twist) > MAX_TWIST, axis=1)
    )
    if bad_twist.size:
        k = int(bad_twist[0])
        raise RecordedDataError(
            p,
            f"topic {odom_topic!r} message {k + 1}: twist (linear.x, angular.z) = ({float(odom_twist[k, 0])!r}, "
            f"{float(odom_twist[k, 1])!r}), expected finite values within +-{MAX_TWIST} (m/s, rad/s)",
        )
    (odom_t, odom_pose, odom_twist), (truth_t, truth_pose), flagged = _flag_streams(
        p, odom_topic, truth_topic, (odom_t, odom_pose, odom_twist), (truth_t, truth_pose)
    )
    fix_arrays = _fix_arrays(by_topic[fix_topic] if fix_topic else [])
    arrays = (odom_t, odom_pose, odom_twist, truth_t, truth_pose, *fix_arrays)
    for a in arrays:
        a.setflags(write=False)  # shared through the cache
    fix_t, fix_llh, fix_cov, fix_cov_type, fix_status = fix_arrays
    return BagStreams(
        odom_t,
        odom_pose,
        odom_twist,
        scans,
        truth_t,
        truth_pose,
        truth_type,
        topics,
        fix_t=fix_t,
        fix_llh=fix_llh,
        fix_cov=fix_cov,
        fix_cov_type=fix_cov_type,
        fix_status=fix_status,
        flagged=flagged,
    )


def _fix_arrays(fixes: list[tuple[float, Any]]) -> tuple[npt.NDArray[Any], ...]:
    """(times, lat/lon/alt, covariances, covariance types, statuses) of (stamp, NavSatFix) pairs, as arrays."""
    return (
        np.array([t for t, _ in fixes], dtype=np.float64),
        np.array([(m.latitude, m.longitude, m.altitude) for _, m in fixes], dtype=np.float64).reshape(-1, 3),
        np.array([np.asarray(m.position_covariance, dtype=np.float64) for _, m in fixes]).reshape(-1, 9),
        np.array([int(m.position_covariance_type) for _, m in fixes], dtype=np.int64),
        np.array([int(m.status.status) for _, m in fixes], dtype=np.int64),
    )


# --- from streams to a dataset -------------------------------------------------------------------


def odometry_increments(pose: FloatArray) -> FloatArray:
    """Increments (dx m, dy m, dtheta rad) between consecutive odometry poses, in the previous robot frame.

    ``pose`` (n, 3) -> (n - 1, 3).
    """
    d = np.diff(pose[:, :2], axis=0)
    c, s = np.cos(pose[:-1, 2]), np.sin(pose[:-1, 2])
    return np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], wrap_angle(np.diff(pose[:, 2]))])


def _check_scan(p: Path, topic: str, k: int, scan: LaserScan) -> None:
    """Raise naming message ``k`` (0-based) of ``topic`` unless the scan's geometry is usable."""
    n = int(scan.ranges.shape[0])
    problem = scan_problem(n, scan.angle_min, scan.angle_increment, scan.range_min, scan.range_max)
    if problem is not None:
        raise RecordedDataError(p, f"topic {topic!r} message {k + 1}: {problem}")


def clean_ranges(ranges: FloatArray, range_min: float, range_max: float) -> FloatArray:
    """Ranges with NaN, +-inf and readings outside [range_min, range_max] set to ``inf`` (no return)."""
    r = np.array(ranges, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        bad = ~np.isfinite(r) | (r < range_min) | (r > range_max)
    r[bad] = np.inf
    return r


def load_rosbag(
    path: str | os.PathLike[str], map_yaml: str | os.PathLike[str] | None = None, **options: Any
) -> Dataset:
    """Load a ROS 1 or ROS 2 bag as a dataset (see the module docstring for what is read and how).

    Parameters
    ----------
    path : path-like
        The ``.bag`` file or ROS 2 bag folder.
    map_yaml : path-like or None
        The map_server YAML of the map (required when the bag's scans are used).
    **options
        Any other field of :class:`RosbagParams` (topics, laser pose, nominal noise ...).

    Returns
    -------
    Dataset
        Odometry and laser events in time order, ground truth, initial belief, occupancy map, nominal noise.
    """
    params = RosbagParams(path=str(path), map="" if map_yaml is None else str(map_yaml), **options)
    return build_rosbag_dataset(params)


#: WGS84 ellipsoid: semi-major axis (m) and flattening (NIMA TR8350.2).
WGS84_A = 6378137.0
WGS84_F = 1.0 / 298.257223563


def _ecef(lat: FloatArray, lon: FloatArray) -> FloatArray:
    """Earth-centred, earth-fixed (x, y, z) of points on the WGS84 ellipsoid (height 0), m, shape (n, 3)."""
    e2 = WGS84_F * (2.0 - WGS84_F)
    n = WGS84_A / np.sqrt(1.0 - e2 * np.sin(lat) ** 2)  # prime vertical radius of curvature
    return np.column_stack([n * np.cos(lat) * np.cos(lon), n * np.cos(lat) * np.sin(lon), n * (1.0 - e2) * np.sin(lat)])


def geodetic_to_enu(
    lat_deg: npt.ArrayLike, lon_deg: npt.ArrayLike, lat0_deg: float, lon0_deg: float
) -> tuple[FloatArray, FloatArray]:
    """East and north (m) of WGS84 points in the tangent plane at (``lat0_deg``, ``lon0_deg``).

    Exact through earth-centred coordinates, on the ellipsoid (the altitude is dropped: a planar map's fixes).
    """
    lat = np.radians(np.asarray(lat_deg, dtype=np.float64).reshape(-1))
    lon = np.radians(np.asarray(lon_deg, dtype=np.float64).reshape(-1))
    p0, q0 = math.radians(lat0_deg), math.radians(lon0_deg)
    d = _ecef(lat, lon) - _ecef(np.array([p0]), np.array([q0]))
    east = -math.sin(q0) * d[:, 0] + math.cos(q0) * d[:, 1]
    north = -math.sin(p0) * math.cos(q0) * d[:, 0] - math.sin(p0) * math.sin(q0) * d[:, 1] + math.cos(p0) * d[:, 2]
    return east, north


def _fixes(params: RosbagParams, streams: BagStreams, bag: Path, t0: float, t1: float) -> tuple[list[PoseFix], int]:
    """The NavSatFix messages inside [t0, t1] as map-frame position fixes, and how many had no fix (skipped)."""
    llh, status = streams.fix_llh, streams.fix_status
    with np.errstate(invalid="ignore"):
        valid = (status >= 0) & np.isfinite(llh[:, 0]) & np.isfinite(llh[:, 1])
    keep = np.flatnonzero(valid & (streams.fix_t >= t0) & (streams.fix_t <= t1))
    for k in keep:
        lat, lon = float(llh[k, 0]), float(llh[k, 1])
        if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
            raise RecordedDataError(
                bag,
                f"topic {params.fix_topic!r} message {int(k) + 1}: latitude {lat!r}, longitude {lon!r}, expected "
                "[-90, 90] and [-180, 180] deg",
            )
    east, north = geodetic_to_enu(llh[keep, 0], llh[keep, 1], params.fix_lat0_deg, params.fix_lon0_deg)
    c, sn = math.cos(params.fix_yaw_rad), math.sin(params.fix_yaw_rad)
    rot = np.array([[c, sn], [-sn, c]])  # ENU -> map frame (x axis at fix_yaw_rad from east)
    out = []
    for j, k in enumerate(keep):
        xy = rot @ np.array([east[j], north[j]])
        if not np.all(np.abs(xy) <= MAX_POSITION_M):
            raise RecordedDataError(
                bag,
                f"topic {params.fix_topic!r} message {int(k) + 1}: fix {quote(xy.tolist())} m from the map "
                f"origin, expected within +-{MAX_POSITION_M} m (is fix_lat0_deg / fix_lon0_deg the map's origin?)",
            )
        if streams.fix_cov_type[k] == 0:  # COVARIANCE_TYPE_UNKNOWN
            cov = np.eye(2) * params.fix_sigma_xy_m**2
        else:
            full = streams.fix_cov[k].reshape(3, 3)
            cov = rot @ full[:2, :2] @ rot.T
            if not is_symmetric_psd(full[:2, :2]):
                raise RecordedDataError(
                    bag,
                    f"topic {params.fix_topic!r} message {int(k) + 1}: position_covariance east-north block "
                    f"{quote(full[:2, :2].tolist())}, expected a finite symmetric PSD matrix (m^2)",
                )
        out.append(PoseFix(float(streams.fix_t[k]), xy, cov))
    return out, int(np.sum(~valid))


def _sidecar_events(
    params: RosbagParams, known: frozenset[int] | None, t0: float, t1: float
) -> tuple[list[Event], tuple[FlaggedSample, ...]]:
    """The events of the ``events`` sidecar (textlog JSON lines) inside [t0, t1]: sightings, ranges, fixes only; and
    the events flagged by the plausibility policy."""
    path = resolve_bag_path(params.events, "events")
    events, flagged = read_events_flagged(path, known)
    other = sorted({type(e).__name__ for e in events if isinstance(e, (Odometry, LaserScan))})
    if other:
        raise RecordedDataError(
            path,
            f"has {', '.join(other)} events, expected only landmarks, ranges and fix events (the bag gives "
            "odometry and scans)",
        )
    return [e for e in events if t0 <= e.t <= t1], flagged


def _twist_warning(inc: FloatArray, twist: FloatArray, t: FloatArray, topic: str) -> str:
    """The warning when the odometry's twist contradicts its poses (``twist`` and ``t`` aligned with ``inc``)."""
    why = twist_contradiction(inc, twist[:, 0], twist[:, 1], np.diff(t))
    return f"topic {topic!r}: {why}" if why else ""


def _odometry_events(
    params: RosbagParams, streams: BagStreams, bag: Path, t0: float, t1: float
) -> tuple[list[Event], list[str]]:
    """The odometry increments within the truth span [t0, t1] (the reference pose is the last at or before t0), and
    the warning when their twist contradicts them."""
    ot = streams.odom_t
    first = max(int(np.searchsorted(ot, t0, side="right")) - 1, 0)
    last = int(np.searchsorted(ot, t1, side="right"))
    if last - first < 2:
        raise RecordedDataError(
            bag,
            f"no odometry increments on {params.odom_topic!r} within the ground truth's span [{t0!r}, {t1!r}] s "
            f"({ot.size} odometry messages in [{float(ot[0]) if ot.size else float('nan')!r}, "
            f"{float(ot[-1]) if ot.size else float('nan')!r}] s)",
        )
    inc = odometry_increments(np.asarray(streams.odom_pose[first:last]))
    tw = streams.odom_twist
    events: list[Event] = []
    for j, (dx, dy, dth) in enumerate(inc):
        k = first + 1 + j
        events.append(
            Odometry(
                float(ot[k]),
                float(dx),
                float(dy),
                float(dth),
                v=float(tw[k, 0]),
                omega=float(tw[k, 1]),
                dt=float(ot[k] - ot[k - 1]),
            )
        )
    w = _twist_warning(inc, np.asarray(tw[first + 1 : last]), ot[first:last], params.odom_topic)
    if w:
        log.warning("rosbag %s: %s", bag, w)
    return events, [w] if w else []


def build_rosbag_dataset(params: RosbagParams) -> Dataset:
    """The dataset of ``params`` (what :class:`RosbagDataset` builds)."""
    # long: the bag's streams, sidecars, map and checks assembled in the order their errors should be reported
    bag = resolve_bag_path(params.path)
    streams = read_bag_streams(
        bag, params.odom_topic, params.scan_topic, params.truth_topic, params.stamps, params.fix_topic
    )
    if streams.truth_t.size == 0:
        raise RecordedDataError(bag, f"topic {params.truth_topic!r} has no messages (expected the ground truth)")
    t0, t1 = float(streams.truth_t[0]), float(streams.truth_t[-1])

    events, warnings = _odometry_events(params, streams, bag, t0, t1)
    grid, lines = None, None
    if params.map:
        grid, lines = load_map_and_lines(resolve_bag_path(params.map, "map"), params.map_lines)
    landmarks = None
    if params.landmarks:
        landmarks = read_landmarks(resolve_bag_path(params.landmarks, "landmarks"))
    known = frozenset(int(i) for i in landmarks.ids) if landmarks is not None else None
    extra, side_flags = _sidecar_events(params, known, t0, t1) if params.events else ([], ())
    fixes, no_fix = _fixes(params, streams, bag, t0, t1) if params.fix_topic else ([], 0)
    extra += fixes
    sensor_pose = (params.laser_x_m, params.laser_y_m, params.laser_yaw_rad)
    scans_in = [s for s in streams.scans if t0 <= s.t <= t1]
    if scans_in and grid is None:
        raise ConfigError(
            f"rosbag {bag}: {len(scans_in)} scans on {params.scan_topic!r} need a map: give map=<map_server yaml> "
            "(or scan_topic= to ignore the laser)"
        )
    events.extend(dataclasses.replace(s, sensor_pose=sensor_pose) for s in scans_in)
    events.extend(extra)

    truth = Trajectory2D(
        np.array(streams.truth_t), np.array(streams.truth_pose[:, :2]), wrap_angle(np.array(streams.truth_pose[:, 2]))
    )
    sxy, sth = params.initial_sigma_xy_m, params.initial_sigma_theta_rad
    initial = Gaussian2(truth.poses[0].copy(), np.diag([sxy**2, sxy**2, sth**2]))
    sensors = SensorSpec(
        odometry_sigma_xy_per_m=params.odometry_sigma_xy_per_m,
        odometry_sigma_theta_per_m=params.odometry_sigma_theta_per_m,
        odometry_sigma_theta_per_rad=params.odometry_sigma_theta_per_rad,
        laser_sigma_m=params.laser_sigma_m,
        landmark_sigma_range_m=params.landmark_sigma_range_m,
        landmark_sigma_bearing_rad=params.landmark_sigma_bearing_rad,
        range_sigma_m=params.range_sigma_m,
        pose_fix_sigma_xy_m=params.fix_sigma_xy_m,
    )
    waypoints = None
    if params.waypoints:
        waypoints = read_waypoints(resolve_bag_path(params.waypoints, "waypoints"), truth)
    sidecars = tuple(p for p in (params.landmarks, params.waypoints, params.events) if p)
    ds = Dataset(
        id="rosbag",
        params=params_to_dict(params),
        events=sort_events(events),
        ground_truth=truth,
        initial=initial,
        world=WorldMap(occupancy=grid, landmarks=landmarks, lines=lines),
        sensors=sensors,
        waypoints=waypoints,
        name="rosbag",
        metadata={
            "source": str(bag),
            "format": "ROS 1 bag" if bag.is_file() else "ROS 2 bag",
            "topics": {k: list(v) for k, v in streams.topics.items()},
            "truth_type": streams.truth_type,
            "stamps": params.stamps,
            "map": params.map,
            "scans_outside_truth_span": len(streams.scans) - len(scans_in),
            "fixes_without_fix": no_fix,
            "warnings": warnings,
        },
        truth_label=params.truth_label,
        sources=(str(bag),) + ((params.map,) if params.map else ()) + sidecars,
        declared=(frozenset({LaserScan}) if params.scan_topic and streams.scans else frozenset())
        | frozenset(type(e) for e in extra),
        flagged=plausibility.merge(streams.flagged, side_flags),
    )
    check_dataset_contract(ds)
    return ds


class RosbagDataset(DatasetBuilder):
    """A user's ROS 1 or ROS 2 bag: odometry, laser scans, a ground-truth pose topic and a map_server map."""

    id: ClassVar[str] = "rosbag"
    Params: ClassVar[type] = RosbagParams
    version: ClassVar[int] = 1
    nominal_duration_s: ClassVar[float] = 1000.0
    description: ClassVar[str] = (
        "a user's ROS 1 / ROS 2 bag: nav_msgs/Odometry, sensor_msgs/LaserScan, a truth pose topic, a map_server map"
    )
    requires_modules: ClassVar[tuple[str, ...]] = ("rosbags",)
    install_hint: ClassVar[str] = "pip install 'locbench[ros]'"

    def build(self, params: RosbagParams, rng: np.random.Generator) -> Dataset:
        del rng  # a recording: every seed is the same data
        return build_rosbag_dataset(params)

    @classmethod
    def recording(cls, params: RosbagParams) -> str | None:
        """``file <absolute path>`` of the user's recording (None without a path): two specs of one file read one
        recording, whatever else they set."""
        return f"file {os.path.realpath(params.path)}" if params.path else None

    @classmethod
    def data_unavailable(cls) -> str | None:
        """Always a reason for the default parameters: there is no default bag."""
        return "unavailable: no default recording; name one with rosbag[path=<.bag or ROS 2 folder>,map=<map yaml>]"

    def fetch(self, params: RosbagParams) -> list[str]:
        """Nothing to download: the local paths of the bag and map (an error when absent)."""
        out = [str(resolve_bag_path(params.path))]
        if params.map:
            out.append(str(resolve_bag_path(params.map, "map")))
        return out
