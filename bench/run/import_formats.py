"""Readers of a localization system's output: the formats ``locbench import`` takes (docs/external.md).

Each reader gives a :class:`SystemOutput`: planar poses (x m, y m, theta rad) in the map frame with their times (s),
the 3x3 covariance of (x, y, theta) where the format has one, the particle clouds where it has them, and where each
row came from (a file line or a bag message), so that a later check names it. A reader refuses what it cannot parse
with one line naming the file, the line or message and the field, and what was expected.

- ``tum``: ``t tx ty tz qx qy qz qw`` (TUM RGB-D; what evo reads and writes); pose only.
- ``tumcov``: ``t x y theta c_xx c_xy c_xtheta c_yy c_ytheta c_thetatheta``: the planar pose and the six
  upper-triangle terms of its covariance, row by row (m^2, m rad, rad^2). From a ROS
  ``geometry_msgs/PoseWithCovariance`` (row-major 6x6 over x, y, z, roll, pitch, yaw) the terms are the entries
  (0,0) (0,1) (0,5) (1,1) (1,5) (5,5), i.e. flat indices 0, 1, 5, 7, 11, 35; theta is the quaternion's yaw.
- ``openvins``: OpenVINS' ``ov_eval`` layout of 20 columns, ``t tx ty tz qx qy qz qw`` then the upper triangle of
  the orientation covariance (``Pr11 Pr12 Pr13 Pr22 Pr23 Pr33``, rad^2) and of the position covariance (``Pt11
  Pt12 Pt13 Pt22 Pt23 Pt33``, m^2). The planar covariance takes var(x) = Pt11, cov(x, y) = Pt12, var(y) = Pt22 and
  var(theta) = Pr33 (the rotation about z); the format has no position-orientation terms, so those are 0.
- ``bag``: a ROS 1 ``.bag`` or ROS 2 bag folder, topics of ``geometry_msgs/PoseWithCovarianceStamped`` (AMCL's
  ``/amcl_pose``), ``nav_msgs/Odometry`` (robot_localization's ``/odometry/filtered``) or ``nav2_msgs/ParticleCloud``
  (``/particle_cloud``), read by topic; header stamps are the times. A bag also gives each message's record (log)
  time, when the system published it: the latency of each estimate is its record time minus its header stamp (s),
  both on the bag's clock (so a clock shift applied to both cancels); a record time before its stamp is refused.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from locbench.core.errors import ConfigError
from locbench.core.geometry import quaternion_to_yaw
from locbench.datasets.recorded.files import RecordedDataError, Table, quaternion_problem, quote, read_table
from locbench.datasets.recorded.rosbag import resolve_bag_path
from locbench.datasets.recorded.tum import TUM_COLUMNS
from locbench.run.ros_messages import PARTICLE_CLOUD, typestore

FloatArray = npt.NDArray[np.float64]

#: Column names of the planar TUM-with-covariance format, with units.
TUMCOV_COLUMNS = (
    "timestamp [s]",
    "x [m]",
    "y [m]",
    "theta [rad]",
    "c_xx [m^2]",
    "c_xy [m^2]",
    "c_xtheta [m rad]",
    "c_yy [m^2]",
    "c_ytheta [m rad]",
    "c_thetatheta [rad^2]",
)
#: OpenVINS' 20 columns (ov_eval's ``Loader::load_data`` layout).
OPENVINS_COLUMNS = (
    *TUM_COLUMNS,
    "Pr11 [rad^2]",
    "Pr12 [rad^2]",
    "Pr13 [rad^2]",
    "Pr22 [rad^2]",
    "Pr23 [rad^2]",
    "Pr33 [rad^2]",
    "Pt11 [m^2]",
    "Pt12 [m^2]",
    "Pt13 [m^2]",
    "Pt22 [m^2]",
    "Pt23 [m^2]",
    "Pt33 [m^2]",
)
#: Flat indices in a row-major 6x6 ROS covariance of the planar terms, in the tumcov order.
ROS_PLANAR_INDICES = (0, 1, 5, 7, 11, 35)
#: The axes (x, y, yaw) of a ROS 6x6 covariance over (x, y, z, roll, pitch, yaw).
_PLANAR_AXES = [0, 1, 5]
FORMATS = ("tum", "tumcov", "openvins", "bag")
POSE_TYPES = ("geometry_msgs/msg/PoseWithCovarianceStamped", "nav_msgs/msg/Odometry")
_COLUMNS = {"tum": TUM_COLUMNS, "tumcov": TUMCOV_COLUMNS, "openvins": OPENVINS_COLUMNS}


@dataclass
class Cloud:
    """One particle cloud: its time (s), particles (m, 3) (x m, y m, theta rad) and weights (m,), its source, and
    its latency (record time minus header stamp, s; NaN when not known)."""

    t: float
    points: FloatArray
    weights: FloatArray
    where: str
    latency_s: float = float("nan")


@dataclass
class SystemOutput:
    """What a system reported for one (dataset, seed), as read from one file.

    Attributes
    ----------
    path : Path
        The file (or bag folder).
    fmt : str
        One of :data:`FORMATS`.
    t : ndarray (n,)
        Times, s, as the file has them.
    mean : ndarray (n, 3)
        Poses (x m, y m, theta rad).
    cov : ndarray (n, 3, 3) or None
        Covariances of (x, y, theta), or None for a pose-only format.
    where : list of str
        Where each row is in the file (``line 12``, ``message 5 of '/amcl_pose'``).
    clouds : list of Cloud
        Particle clouds (bags with a ``nav2_msgs/ParticleCloud`` topic), time-ordered; empty otherwise.
    frames : dict of str to str
        Of a bag's pose topics: the topic's frame (``header.frame_id``) by topic.
    topics : tuple of str
        The bag topics read.
    latency : ndarray (n,) or None
        Of a bag: each row's latency, s: the message's record (log) time minus its header stamp, both on the bag's
        clock. None for a text format (it has no record time) or when a header stamp is 0 (unset in ROS).
    """

    path: Path
    fmt: str
    t: FloatArray
    mean: FloatArray
    cov: FloatArray | None
    where: list[str]
    clouds: list[Cloud] = field(default_factory=list)
    frames: dict[str, str] = field(default_factory=dict)
    topics: tuple[str, ...] = ()
    latency: FloatArray | None = None


def guess_format(path: Path) -> str:
    """The format of a file: a bag by its name or folder, a text file by the field count of its first data line."""
    if path.is_dir() or path.suffix in (".bag", ".db3", ".mcap"):
        return "bag"
    try:
        with path.open(encoding="utf-8", errors="replace") as fh:
            for k, line in enumerate(fh, start=1):
                text = line.strip()
                if text and not text.startswith("#"):
                    n = len(text.replace(",", " ").split())
                    for fmt, cols in _COLUMNS.items():
                        if n == len(cols):
                            return fmt
                    counts = ", ".join(f"{len(c)} ({f})" for f, c in _COLUMNS.items())
                    raise RecordedDataError(path, f"{n} fields; expected {counts}, or give --format", k)
    except OSError as exc:
        raise RecordedDataError(path, f"cannot read ({exc.strerror or exc})") from None
    raise RecordedDataError(path, "no data line; expected one pose per line")


def _poses_from_quaternions(table: Table) -> FloatArray:
    """(x, y, theta) of a table whose columns 1-7 are TUM's; each quaternion a planar unit one."""
    problem = quaternion_problem(table.rows[:, 4:8])
    if problem is not None:
        raise table.fail(problem[0], problem[1])
    return np.column_stack([table.rows[:, 1:3], quaternion_to_yaw(table.rows[:, 4:8])])


def _upper(terms: FloatArray) -> FloatArray:
    """Symmetric 3x3 matrices (n, 3, 3) from upper-triangle terms (n, 6) in the order 00 01 02 11 12 22."""
    c = np.empty((terms.shape[0], 3, 3))
    for k, (i, j) in enumerate(((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))):
        c[:, i, j] = c[:, j, i] = terms[:, k]
    return c


def read_text(path: Path, fmt: str) -> SystemOutput:
    """Read a text format (``tum``, ``tumcov``, ``openvins``) as a :class:`SystemOutput`."""
    table = read_table(path, _COLUMNS[fmt])
    table.check_rows("pose", 1)
    rows = table.rows
    cov: FloatArray | None = None
    if fmt == "tumcov":
        mean = rows[:, 1:4].copy()
        cov = _upper(rows[:, 4:10])
    else:
        mean = _poses_from_quaternions(table)
        if fmt == "openvins":
            pr, pt = rows[:, 8:14], rows[:, 14:20]
            zero = np.zeros(rows.shape[0])
            cov = _upper(np.column_stack([pt[:, 0], pt[:, 1], zero, pt[:, 3], zero, pr[:, 5]]))
    where = [f"line {int(k)}" for k in table.lines]
    return SystemOutput(path, fmt, rows[:, 0].copy(), mean, cov, where)


def _planar(msg_pose: Any) -> tuple[float, float, tuple[float, float, float, float]]:
    p, q = msg_pose.position, msg_pose.orientation
    return float(p.x), float(p.y), (float(q.x), float(q.y), float(q.z), float(q.w))


def _yaws(path: Path, quats: list[tuple[float, float, float, float]], where: list[str]) -> FloatArray:
    q = np.array(quats, dtype=np.float64).reshape(-1, 4)
    problem = quaternion_problem(q)
    if problem is not None:
        raise RecordedDataError(path, f"{where[problem[0]]}: {problem[1]}")
    return quaternion_to_yaw(q)


def read_bag(path: str | os.PathLike[str], topics: tuple[str, ...]) -> SystemOutput:
    # long: one pass over the bag's messages, each of the three types decoded where its rows are gathered
    """Read the pose topic and/or the particle-cloud topic of a bag (their types tell which is which).

    Parameters
    ----------
    path : path-like
        A ROS 1 ``.bag`` file or a ROS 2 bag folder.
    topics : tuple of str
        One topic of a pose type (:data:`POSE_TYPES`) and/or one of ``nav2_msgs/ParticleCloud``; empty: the bag's
        only topic of those types.

    Raises
    ------
    RecordedDataError
        A topic that is not in the bag (the message lists the bag's topics and their types), a topic of another
        type, two pose topics, an unreadable message.
    """
    p = resolve_bag_path(path)
    ts = typestore()
    from rosbags.highlevel import AnyReader

    try:
        reader = AnyReader([p], default_typestore=ts)
        reader.open()
    except Exception as exc:  # rosbags raises its own errors, OSError ... on foreign bytes
        raise RecordedDataError(
            p, f"unreadable bag ({type(exc).__name__}: {quote(str(exc))}); expected a ROS 1 .bag or ROS 2 bag folder"
        ) from None
    try:
        have = {name: (info.msgtype or "?", int(info.msgcount)) for name, info in reader.topics.items()}
        listing = ", ".join(f"{n} ({t}, {c} messages)" for n, (t, c) in sorted(have.items())) or "(none)"
        usable = (*POSE_TYPES, PARTICLE_CLOUD)
        wanted = topics or tuple(n for n, (t, _) in sorted(have.items()) if t in usable)
        for name in wanted:
            if name not in have:
                raise RecordedDataError(p, f"no topic {name!r}; the bag has: {listing}")
            if have[name][0] not in usable:
                raise RecordedDataError(
                    p, f"topic {name!r} is {have[name][0]}, expected one of {', '.join(usable)}; the bag has: {listing}"
                )
        pose_topics = [n for n in wanted if have[n][0] in POSE_TYPES]
        cloud_topics = [n for n in wanted if have[n][0] == PARTICLE_CLOUD]
        if len(pose_topics) > 1 or len(cloud_topics) > 1 or not wanted:
            raise RecordedDataError(
                p, f"expected one pose topic and/or one particle-cloud topic (give --topic); the bag has: {listing}"
            )
        conns = [c for c in reader.connections if c.topic in wanted]
        t: list[float] = []
        xy: list[tuple[float, float]] = []
        quats: list[tuple[float, float, float, float]] = []
        covs: list[FloatArray] = []
        where: list[str] = []
        lag_ns: list[int] = []
        unset = False
        frames: dict[str, str] = {}
        clouds: list[Cloud] = []
        counter = dict.fromkeys(wanted, 0)
        for conn, log_ns, raw in reader.messages(connections=conns):
            counter[conn.topic] += 1
            here = f"message {counter[conn.topic]} of {conn.topic!r}"
            try:
                msg: Any = reader.deserialize(raw, conn.msgtype)
            except Exception as exc:
                raise RecordedDataError(p, f"{here}: undecodable ({type(exc).__name__}: {quote(str(exc))})") from None
            st = msg.header.stamp
            stamp = float(st.sec) + float(st.nanosec) * 1e-9
            # the latency in integer ns, exact: both times are ns on the bag's clock, so any clock shift cancels
            stamp_ns = int(st.sec) * 1_000_000_000 + int(st.nanosec)
            lag = int(log_ns) - stamp_ns
            unset = unset or stamp_ns == 0
            if lag < 0 and stamp_ns:
                raise RecordedDataError(
                    p,
                    f"{here}: recorded at {int(log_ns) / 1e9!r} s, {-lag / 1e9!r} s before its header stamp "
                    f"{stamp_ns / 1e9!r} s; expected the record (log) time, when the system published the estimate, "
                    "at or after the stamp of the data it is for, on the same clock",
                )
            frame = str(msg.header.frame_id)
            frames.setdefault(conn.topic, frame)
            if frames[conn.topic] != frame:
                raise RecordedDataError(
                    p, f"{here}: frame {frame!r}, the topic's earlier messages are in {frames[conn.topic]!r}"
                )
            if conn.msgtype == PARTICLE_CLOUD:
                parts = msg.particles
                pts = [_planar(q.pose) for q in parts]
                yaw = _yaws(p, [q[2] for q in pts], [f"{here} particle {k + 1}" for k in range(len(pts))])
                points = np.column_stack([np.array([(a, b) for a, b, _ in pts]).reshape(-1, 2), yaw])
                weights = np.array([float(q.weight) for q in parts], dtype=np.float64)
                clouds.append(Cloud(stamp, points, weights, here, lag / 1e9))
                continue
            x, y, q = _planar(msg.pose.pose)
            t.append(stamp)
            xy.append((x, y))
            quats.append(q)
            c6 = np.asarray(msg.pose.covariance, dtype=np.float64).reshape(6, 6)
            covs.append(c6[np.ix_(_PLANAR_AXES, _PLANAR_AXES)])  # both triangles: an asymmetric one is refused
            where.append(here)
            lag_ns.append(lag)
    finally:
        reader.close()
    yaw = _yaws(p, quats, where)
    mean = np.column_stack([np.array(xy, dtype=np.float64).reshape(-1, 2), yaw])
    cov = np.array(covs, dtype=np.float64).reshape(-1, 3, 3) if pose_topics else None
    clouds.sort(key=lambda c: c.t)
    latency = None if unset else np.array(lag_ns, dtype=np.float64) / 1e9
    return SystemOutput(
        p, "bag", np.array(t, dtype=np.float64), mean, cov, where, clouds, frames, tuple(wanted), latency
    )


def read_output(path: str | os.PathLike[str], fmt: str | None = None, topics: tuple[str, ...] = ()) -> SystemOutput:
    """Read one output file in format ``fmt`` (None: :func:`guess_format`)."""
    p = Path(path)
    if not os.path.lexists(p):
        raise RecordedDataError(p, "no such file; expected the system's output for this seed")
    kind = fmt or guess_format(p)
    if kind not in FORMATS:
        raise ConfigError(f"unknown import format {kind!r}; expected one of {', '.join(FORMATS)}")
    if kind == "bag":
        return read_bag(p, topics)
    if topics:
        raise ConfigError(f"{p}: --topic goes with bags, not the {kind} text format")
    return read_text(p, kind)
