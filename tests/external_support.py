"""Writers of a "system output" in each format ``locbench import`` reads, from a run's rows (for the import tests)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from locbench.run.ros_messages import header, planar_pose, stamp_ns, typestore

POSE = "geometry_msgs/msg/PoseWithCovarianceStamped"
ODOM = "nav_msgs/msg/Odometry"
CLOUD = "nav2_msgs/msg/ParticleCloud"


def _num(v: float) -> str:
    return repr(float(v))


def write_tumcov(path: Path, t: np.ndarray, mean: np.ndarray, cov: np.ndarray) -> Path:
    rows = [
        " ".join(_num(v) for v in (tt, *m, c[0, 0], c[0, 1], c[0, 2], c[1, 1], c[1, 2], c[2, 2]))
        for tt, m, c in zip(t, mean, cov, strict=True)
    ]
    path.write_text("# t x y theta c_xx c_xy c_xtheta c_yy c_ytheta c_thetatheta\n" + "\n".join(rows) + "\n")
    return path


def _quat(theta: float) -> tuple[float, float, float, float]:
    return (0.0, 0.0, float(np.sin(theta / 2)), float(np.cos(theta / 2)))


def write_openvins(path: Path, t: np.ndarray, mean: np.ndarray, cov: np.ndarray) -> Path:
    rows = []
    for tt, m, c in zip(t, mean, cov, strict=True):
        pr = (1e-4, 0.0, 0.0, 1e-4, 0.0, c[2, 2])  # roll and pitch variances of a planar system: small, unused
        pt = (c[0, 0], c[0, 1], 0.0, c[1, 1], 0.0, 1e-4)
        rows.append(" ".join(_num(v) for v in (tt, m[0], m[1], 0.0, *_quat(m[2]), *pr, *pt)))
    path.write_text("# timestamp(s) tx ty tz qx qy qz qw Pr11 Pr12 Pr13 Pr22 Pr23 Pr33 Pt11 Pt12 Pt13 Pt22 Pt23 Pt33\n")
    with path.open("a") as fh:
        fh.write("\n".join(rows) + "\n")
    return path


def write_tum_rows(path: Path, t: np.ndarray, mean: np.ndarray) -> Path:
    rows = [" ".join(_num(v) for v in (tt, m[0], m[1], 0.0, *_quat(m[2]))) for tt, m in zip(t, mean, strict=True)]
    path.write_text("\n".join(rows) + "\n")
    return path


def _cov36(c: np.ndarray) -> np.ndarray:
    out = np.zeros((6, 6))
    out[np.ix_([0, 1, 5], [0, 1, 5])] = c
    return out.ravel()


def write_bag(
    path: Path,
    fmt: str,
    poses: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
    *,
    msgtype: str = POSE,
    topic: str = "/amcl_pose",
    frame: str = "map",
    offset: float = 0.0,
    clouds: Sequence[tuple[float, np.ndarray, np.ndarray]] = (),
    delays_ns: Sequence[int] = (),
    cloud_delay_ns: int = 0,
) -> Path:
    """A ROS 1 (``fmt`` "rosbag1") or ROS 2 bag of poses (t, mean, cov) on ``topic`` and particle clouds.

    Each message is recorded at its header stamp plus its publish delay (ns): ``delays_ns[k]`` for the k-th pose
    (none given: 0), ``cloud_delay_ns`` for every cloud."""
    ts = typestore()
    mt = ts.types
    msgs = []
    if poses is not None:
        delays = list(delays_ns) or [0] * len(poses[0])
        for tt, m, c, d in zip(*poses, delays, strict=True):
            st = float(tt) + offset
            pwc = mt["geometry_msgs/msg/PoseWithCovariance"](pose=planar_pose(ts, *m), covariance=_cov36(c))
            if msgtype == POSE:
                msg = mt[POSE](header=header(ts, st, frame), pose=pwc)
            else:
                zero = mt["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
                tw = mt["geometry_msgs/msg/TwistWithCovariance"](
                    twist=mt["geometry_msgs/msg/Twist"](linear=zero, angular=zero), covariance=np.zeros(36)
                )
                msg = mt[ODOM](header=header(ts, st, frame), child_frame_id="base_link", pose=pwc, twist=tw)
            msgs.append((stamp_ns(st) + d, topic, msgtype, msg))
    for tt, pts, w in clouds:
        st = float(tt) + offset
        parts = [
            mt["nav2_msgs/msg/Particle"](pose=planar_pose(ts, *p), weight=float(x)) for p, x in zip(pts, w, strict=True)
        ]
        cloud = mt[CLOUD](header=header(ts, st, frame), particles=parts)
        msgs.append((stamp_ns(st) + cloud_delay_ns, "/particle_cloud", CLOUD, cloud))
    msgs.sort(key=lambda m: m[0])
    if fmt == "rosbag2":
        from rosbags.rosbag2 import Writer as Writer2

        writer: Any = Writer2(path, version=8)
        serialize = ts.serialize_cdr
    else:
        from rosbags.rosbag1 import Writer as Writer1

        writer, serialize = Writer1(path), ts.serialize_ros1
    with writer:
        conns: dict[str, Any] = {}
        for log_ns, tp, ty, msg in msgs:
            if tp not in conns:
                conns[tp] = writer.add_connection(tp, ty, typestore=ts)
            writer.write(conns[tp], log_ns, serialize(msg, ty))
    return path


def last_per_time(t: np.ndarray, *arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    """The rows that are the last at their time (the estimate after every event of that instant)."""
    keep = np.r_[t[1:] != t[:-1], True]
    return (t[keep], *(a[keep] for a in arrays))
