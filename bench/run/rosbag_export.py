"""A dataset realisation as a ROS system reads it: a ROS 1 or ROS 2 bag, a map_server map and the truth.

``locbench export --format rosbag2|rosbag1 --dataset SPEC --seed N --out DIR`` writes into ``DIR``:

- ``bag/`` (ROS 2: ``metadata.yaml`` and an sqlite3 file) or ``dataset.bag`` (ROS 1), written with rosbags, with
  the topics of :data:`TOPICS` the dataset has (docs/external.md lists them with their types);
- ``map.yaml`` and ``map.pgm`` for map_server when the dataset has an occupancy grid;
- ``truth.tum``: the ground truth on the bag's clock (:func:`locbench.run.ros_messages.clock_offset`);
- ``nav2_amcl_params.yaml``: nav2 AMCL's parameters with the dataset's nominal noise (:func:`amcl_params`).

Frames: ``map`` (the dataset's world frame; the map and the truth are in it), ``odom`` (the odometry's origin: the
robot's pose at its first odometry message), ``base_link`` (the robot) and ``laser`` (the scanner, on
``/tf_static``). ``/odom`` carries the odometry integrated from the dataset's increments (Odometry events, in the
previous robot frame) and ``/tf`` the same pose as odom -> base_link; map -> odom is what a localizer publishes and
is not in the bag. Ranges are written as float32 (the message's type): a range differs from the dataset's by at
most half a float32 ulp (6e-8 relative).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from locbench.core.errors import ConfigError
from locbench.core.events import LandmarkObservations, LaserScan, Odometry, PoseFix, RangeObservations
from locbench.datasets.dataset import Dataset
from locbench.datasets.recorded.ros_map import save_map_server_map
from locbench.datasets.recorded.tum import write_tum
from locbench.run.ros_messages import clock_offset, header, planar_pose, ros_time, stamp_ns, typestore

BagFormat = Literal["rosbag1", "rosbag2"]
#: Every topic an export may hold, with its message type (ROS 2 names; a ROS 1 bag uses ``pkg/Type``).
TOPICS = {
    "/clock": "rosgraph_msgs/msg/Clock",
    "/odom": "nav_msgs/msg/Odometry",
    "/tf": "tf2_msgs/msg/TFMessage",
    "/tf_static": "tf2_msgs/msg/TFMessage",
    "/scan": "sensor_msgs/msg/LaserScan",
    "/map": "nav_msgs/msg/OccupancyGrid",
    "/landmarks": "locbench_msgs/msg/LandmarkSightings",
    "/beacon_ranges": "locbench_msgs/msg/BeaconRanges",
    "/fix": "geometry_msgs/msg/PoseWithCovarianceStamped",
}
#: Topics whose last message a late subscriber must still get (ROS 2 transient local, ROS 1 latched).
LATCHED = frozenset({"/tf_static", "/map"})


@dataclass
class RosExport:
    """What :func:`export_ros` wrote: the folder, the bag, each topic's message count, and every file."""

    out: Path
    bag: Path
    counts: dict[str, int]
    files: list[Path] = field(default_factory=list)
    offset_s: float = 0.0


def _odom_poses(events: list[Odometry]) -> np.ndarray:
    """Odometry-frame poses (x m, y m, theta rad) after each increment, starting at the origin (n + 1, 3)."""
    out = np.zeros((len(events) + 1, 3))
    x = y = th = 0.0
    for k, e in enumerate(events, start=1):
        c, s = math.cos(th), math.sin(th)
        x, y = x + c * e.dx - s * e.dy, y + s * e.dx + c * e.dy
        th = math.atan2(math.sin(th + e.dtheta), math.cos(th + e.dtheta))
        out[k] = (x, y, th)
    return out


def _transform(ts: Any, t: float, parent: str, child: str, pose: tuple[float, float, float]) -> Any:
    """``geometry_msgs/msg/TransformStamped`` of a planar pose of ``child`` in ``parent``."""
    mt = ts.types
    p = planar_pose(ts, *pose)
    return mt["geometry_msgs/msg/TransformStamped"](
        header=header(ts, t, parent),
        child_frame_id=child,
        transform=mt["geometry_msgs/msg/Transform"](
            translation=mt["geometry_msgs/msg/Vector3"](x=p.position.x, y=p.position.y, z=0.0),
            rotation=p.orientation,
        ),
    )


def _cov36(cov3: np.ndarray) -> np.ndarray:
    """The row-major 6x6 covariance of (x, y, z, roll, pitch, yaw) holding a planar 3x3 one (x, y, yaw)."""
    c = np.zeros((6, 6))
    idx = [0, 1, 5]
    c[np.ix_(idx, idx)] = cov3
    return c.ravel()


def _messages(ds: Dataset, off: float) -> list[tuple[float, str, Any]]:
    # long: one message builder per event type and topic; kept together so the topics and their frames read as one list
    ts = typestore()
    mt = ts.types
    msgs: list[tuple[float, str, Any]] = []
    t0 = ds.events[0].t if ds.events else float(ds.ground_truth.t[0])
    odo = [e for e in ds.events if isinstance(e, Odometry)]
    poses = _odom_poses(odo)
    zero_twist = mt["geometry_msgs/msg/Twist"](
        linear=mt["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
        angular=mt["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
    )
    prev_t = t0
    # the odometry's origin, at the first time of the dataset
    first = [(t0, poses[0], zero_twist)]
    for k, e in enumerate(odo, start=1):
        dt = e.dt if e.dt is not None else e.t - prev_t
        v = e.v if e.v is not None else (e.dx / dt if dt > 0 else 0.0)
        w = e.omega if e.omega is not None else (e.dtheta / dt if dt > 0 else 0.0)
        twist = mt["geometry_msgs/msg/Twist"](
            linear=mt["geometry_msgs/msg/Vector3"](x=float(v), y=0.0, z=0.0),
            angular=mt["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=float(w)),
        )
        first.append((e.t, poses[k], twist))
        prev_t = e.t
    for t, pose, twist in first:
        st = t + off
        cov_zero = np.zeros(36)
        msgs.append(
            (
                st,
                "/odom",
                mt["nav_msgs/msg/Odometry"](
                    header=header(ts, st, "odom"),
                    child_frame_id="base_link",
                    pose=mt["geometry_msgs/msg/PoseWithCovariance"](pose=planar_pose(ts, *pose), covariance=cov_zero),
                    twist=mt["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=cov_zero),
                ),
            )
        )
        tf = _transform(ts, st, "odom", "base_link", tuple(float(v) for v in pose))  # type: ignore[arg-type]
        msgs.append((st, "/tf", mt["tf2_msgs/msg/TFMessage"](transforms=[tf])))
    scans = [e for e in ds.events if isinstance(e, LaserScan)]
    if scans:
        sensor = tuple(float(v) for v in scans[0].sensor_pose)
        if any(tuple(float(v) for v in s.sensor_pose) != sensor for s in scans):
            raise ConfigError(
                f"{ds.name or ds.id}: scans from more than one sensor pose cannot share the frame 'laser'"
            )
        static = _transform(ts, t0 + off, "base_link", "laser", sensor)  # type: ignore[arg-type]
        msgs.append((t0 + off, "/tf_static", mt["tf2_msgs/msg/TFMessage"](transforms=[static])))
    for ev in ds.events:
        st = ev.t + off
        if isinstance(ev, LaserScan):
            r = np.asarray(ev.ranges, dtype=np.float32)
            n = int(r.shape[0])
            msgs.append(
                (
                    st,
                    "/scan",
                    mt["sensor_msgs/msg/LaserScan"](
                        header=header(ts, st, "laser"),
                        angle_min=float(ev.angle_min),
                        angle_max=float(ev.angle_min + (n - 1) * ev.angle_increment),
                        angle_increment=float(ev.angle_increment),
                        time_increment=0.0,
                        scan_time=0.0,
                        range_min=float(ev.range_min),
                        range_max=float(ev.range_max),
                        ranges=r,
                        intensities=np.zeros(0, np.float32),
                    ),
                )
            )
        elif isinstance(ev, LandmarkObservations):
            ids = np.array([-1 if i is None or i < 0 else int(i) for i in ev.ids], dtype=np.int64)
            msgs.append(
                (
                    st,
                    "/landmarks",
                    mt["locbench_msgs/msg/LandmarkSightings"](
                        header=header(ts, st, "base_link"),
                        ids=ids,
                        ranges=np.asarray(ev.ranges, np.float64),
                        bearings=np.asarray(ev.bearings, np.float64),
                    ),
                )
            )
        elif isinstance(ev, RangeObservations):
            msgs.append(
                (
                    st,
                    "/beacon_ranges",
                    mt["locbench_msgs/msg/BeaconRanges"](
                        header=header(ts, st, "base_link"),
                        ids=np.asarray(ev.ids, np.int64),
                        ranges=np.asarray(ev.ranges, np.float64),
                    ),
                )
            )
        elif isinstance(ev, PoseFix):
            z = np.asarray(ev.z, np.float64)
            cov = np.zeros((3, 3))
            k = z.shape[0]
            cov[:k, :k] = np.asarray(ev.cov, np.float64)
            if k < 3:  # a position-only fix: the heading is unknown (a very large variance, as ROS drivers write)
                cov[2, 2] = 1e9
            msgs.append(
                (
                    st,
                    "/fix",
                    mt["geometry_msgs/msg/PoseWithCovarianceStamped"](
                        header=header(ts, st, "map"),
                        pose=mt["geometry_msgs/msg/PoseWithCovariance"](
                            pose=planar_pose(ts, z[0], z[1], z[2] if k > 2 else 0.0), covariance=_cov36(cov)
                        ),
                    ),
                )
            )
    grid = ds.world.occupancy
    if grid is not None:
        occ = np.asarray(grid.occupancy, np.float64)
        data = np.where(occ < 0, -1, np.rint(100.0 * np.clip(occ, 0.0, 1.0))).astype(np.int8).ravel()
        st = t0 + off
        info = mt["nav_msgs/msg/MapMetaData"](
            map_load_time=ros_time(ts, st),
            resolution=float(grid.resolution),
            width=int(occ.shape[1]),
            height=int(occ.shape[0]),
            origin=planar_pose(ts, grid.origin[0], grid.origin[1], grid.origin[2]),
        )
        msgs.append((st, "/map", mt["nav_msgs/msg/OccupancyGrid"](header=header(ts, st, "map"), info=info, data=data)))
    for t in sorted({m[0] for m in msgs}):
        msgs.append((t, "/clock", mt["rosgraph_msgs/msg/Clock"](clock=ros_time(ts, t))))
    # by time; at one time the clock first, then the topics in a fixed order (a stable sort keeps events' order)
    order = {name: i for i, name in enumerate(TOPICS)}
    msgs.sort(key=lambda m: (stamp_ns(m[0]), order[m[1]]))
    return msgs


def write_bag(ds: Dataset, path: Path, fmt: BagFormat, off: float) -> dict[str, int]:
    """Write the messages of ``ds`` into a new bag at ``path``; returns each topic's message count."""
    ts = typestore()
    msgs = _messages(ds, off)
    used = [name for name in TOPICS if any(m[1] == name for m in msgs)]
    counts = {name: 0 for name in used}
    if fmt == "rosbag2":
        from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
        from rosbags.rosbag2 import Writer as Writer2

        def qos(latched: bool) -> list[Any]:
            durability = QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE
            zero = QosTime(0, 0)
            depth = 1 if latched else 10
            return [
                Qos(
                    QosHistory.KEEP_LAST,
                    depth,
                    QosReliability.RELIABLE,
                    durability,
                    zero,
                    zero,
                    QosLiveliness.AUTOMATIC,
                    zero,
                    False,
                )
            ]

        w2 = Writer2(path, version=8)
        with w2:
            conns = {
                n: w2.add_connection(n, TOPICS[n], typestore=ts, offered_qos_profiles=qos(n in LATCHED)) for n in used
            }
            for t, name, msg in msgs:
                w2.write(conns[name], stamp_ns(t), ts.serialize_cdr(msg, TOPICS[name]))
                counts[name] += 1
    else:
        from rosbags.rosbag1 import Writer as Writer1

        w1 = Writer1(path)
        with w1:
            conns = {n: w1.add_connection(n, TOPICS[n], typestore=ts, latching=1 if n in LATCHED else 0) for n in used}
            for t, name, msg in msgs:
                w1.write(conns[name], stamp_ns(t), ts.serialize_ros1(msg, TOPICS[name]))
                counts[name] += 1
    return counts


def amcl_params(ds: Dataset) -> str:
    """nav2 AMCL's parameter file (YAML) with the dataset's nominal noise where AMCL has a matching parameter.

    AMCL's ``differential`` motion model draws its noise with standard deviations ``alpha1 |rot| + alpha2 |trans|``
    (rotation from rotation and from translation) and ``alpha3 |trans| + alpha4 |rot|`` (translation); the dataset
    declares noise that grows with the square root of the distance, so the alphas are set to the dataset's sigma
    per sqrt(m) over one metre of travel, a starting point to tune rather than an equivalence. ``sigma_hit`` is the
    laser's range noise; the scanner's range limits are the scans'.
    """
    s = ds.sensors
    scans = [e for e in ds.events if isinstance(e, LaserScan)]
    a_rot = s.odometry_sigma_theta_per_rad if s.odometry_sigma_theta_per_rad is not None else 0.2
    a_rt = s.odometry_sigma_theta_per_m if s.odometry_sigma_theta_per_m is not None else 0.2
    a_tr = s.odometry_sigma_xy_per_m if s.odometry_sigma_xy_per_m is not None else 0.2
    lines = [
        "# nav2 AMCL parameters written by locbench export from the dataset's nominal noise (docs/external.md)",
        "amcl:",
        "  ros__parameters:",
        "    use_sim_time: true",
        "    global_frame_id: map",
        "    odom_frame_id: odom",
        "    base_frame_id: base_link",
        "    scan_topic: scan",
        "    robot_model_type: nav2_amcl::DifferentialMotionModel",
        f"    alpha1: {float(a_rot)!r}",
        f"    alpha2: {float(a_rt)!r}",
        f"    alpha3: {float(a_tr)!r}",
        f"    alpha4: {float(a_rt)!r}",
        "    laser_model_type: likelihood_field",
        f"    sigma_hit: {float(s.laser_sigma_m if s.laser_sigma_m is not None else 0.2)!r}",
        "    set_initial_pose: true",
        "    initial_pose:",
        f"      x: {float(ds.initial.mean[0])!r}",
        f"      y: {float(ds.initial.mean[1])!r}",
        "      z: 0.0",
        f"      yaw: {float(ds.initial.mean[2])!r}",
    ]
    if scans:
        lines += [
            f"    laser_min_range: {float(scans[0].range_min)!r}",
            f"    laser_max_range: {float(scans[0].range_max)!r}",
        ]
    return "\n".join(lines) + "\n"


def export_ros(spec: str, seed: int, out: str | os.PathLike[str], fmt: BagFormat = "rosbag2") -> RosExport:
    """Write realisation ``seed`` of dataset ``spec`` as a ROS bag, map, truth and AMCL parameters (module docstring).

    Parameters
    ----------
    spec : str
        Any registered dataset with parameters (``office``, ``room[kidnap_m=2]``).
    seed : int
        The realisation.
    out : path-like
        The folder to write; created, and it must not hold a bag already.
    fmt : {"rosbag2", "rosbag1"}
        The bag format.

    Returns
    -------
    RosExport
        The folder, the bag, each topic's message count and the files written.
    """
    from locbench.registry import make_dataset, resolve_dataset

    if fmt not in ("rosbag1", "rosbag2"):
        raise ConfigError(f"bag format must be rosbag1 or rosbag2, got {fmt!r}")
    ds: Dataset = make_dataset(resolve_dataset(spec), seed)
    root = Path(out)
    root.mkdir(parents=True, exist_ok=True)
    bag = root / ("bag" if fmt == "rosbag2" else "dataset.bag")
    if bag.exists():
        raise ConfigError(f"{bag}: already exists; give an empty folder (a bag is never overwritten)")
    t0 = ds.events[0].t if ds.events else float(ds.ground_truth.t[0])
    off = clock_offset(min(t0, float(ds.ground_truth.t[0])))
    counts = write_bag(ds, bag, fmt, off)
    files = [bag]
    if ds.world.occupancy is not None:
        files.append(save_map_server_map(ds.world.occupancy, root / "map.yaml", mode="trinary"))
        files.append(root / "map.pgm")
    gt = ds.ground_truth
    files.append(write_tum(root / "truth.tum", gt.t + off, gt.poses, f"locbench ground truth: {spec} seed {seed}"))
    params = root / "nav2_amcl_params.yaml"
    params.write_text(amcl_params(ds), encoding="utf-8")
    files.append(params)
    return RosExport(root, bag, counts, files, off)
