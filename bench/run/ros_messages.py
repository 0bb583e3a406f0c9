"""The ROS message types locbench writes and reads in bags, and its clock rule for them.

Every type is taken from rosbags' ROS 2 Humble type store (:func:`typestore`); the types the store lacks are
registered from their message definitions: ``nav2_msgs/msg/Particle`` and ``nav2_msgs/msg/ParticleCloud`` (as
nav2 defines them: a header and a list of poses with weights, the message nav2 AMCL and Beluga publish on
``/particle_cloud``), and two of locbench's own for the observations no standard message carries,
``locbench_msgs/msg/LandmarkSightings`` (ids, ranges in m and bearings in rad in the robot frame; id -1 = the
identity is unknown) and ``locbench_msgs/msg/BeaconRanges`` (ids and ranges in m).

Clock: ROS reads a stamp of 0 as "unset" (tf then answers with its latest transform), and locbench's synthetic worlds
start at t = 0 s. A dataset whose first time is below :data:`SIM_EPOCH_S` is therefore written with every stamp
shifted by :data:`SIM_EPOCH_S` (:func:`clock_offset`); a recording keeps its own (Unix) stamps. The import applies
the same rule backwards, so a system's output recorded against an exported bag lines up with the dataset.
"""

from __future__ import annotations

import functools
import math
from typing import Any

from locbench.core.errors import DependencyNotInstalled

#: The offset written into the stamps of a dataset whose clock starts below it, s.
SIM_EPOCH_S = 1000.0
#: nav2's ``nav2_msgs/msg/Particle`` and ``ParticleCloud`` (nav2_msgs/msg/*.msg, Humble and later).
PARTICLE_MSG = "geometry_msgs/Pose pose\nfloat64 weight\n"
PARTICLE_CLOUD_MSG = "std_msgs/Header header\nnav2_msgs/Particle[] particles\n"
#: locbench's own observation messages (documented in docs/external.md).
LANDMARK_SIGHTINGS_MSG = "std_msgs/Header header\nint64[] ids\nfloat64[] ranges\nfloat64[] bearings\n"
BEACON_RANGES_MSG = "std_msgs/Header header\nint64[] ids\nfloat64[] ranges\n"
PARTICLE_CLOUD = "nav2_msgs/msg/ParticleCloud"
_INSTALL = "writing and reading ROS bags needs the rosbags package; install it with: pip install 'locbench[ros]'"


@functools.cache
def typestore() -> Any:
    """rosbags' ROS 2 Humble type store with the nav2 particle types and locbench's observation types registered."""
    try:
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore
    except ImportError:
        raise DependencyNotInstalled(_INSTALL) from None
    store = get_typestore(Stores.ROS2_HUMBLE)
    types: dict[str, Any] = {}
    for name, text in (
        ("nav2_msgs/msg/Particle", PARTICLE_MSG),
        (PARTICLE_CLOUD, PARTICLE_CLOUD_MSG),
        ("locbench_msgs/msg/LandmarkSightings", LANDMARK_SIGHTINGS_MSG),
        ("locbench_msgs/msg/BeaconRanges", BEACON_RANGES_MSG),
    ):
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store


def clock_offset(first_t: float) -> float:
    """The offset added to a dataset's times in a bag, s: :data:`SIM_EPOCH_S` when its clock starts below it, else 0."""
    return SIM_EPOCH_S if first_t < SIM_EPOCH_S else 0.0


def stamp_ns(t: float) -> int:
    """A time in s as integer nanoseconds (rounded to the nearest)."""
    return round(t * 1e9)


def ros_time(ts: Any, t: float) -> Any:
    """``builtin_interfaces/msg/Time`` of ``t`` s (>= 0)."""
    ns = stamp_ns(t)
    return ts.types["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def header(ts: Any, t: float, frame: str) -> Any:
    """``std_msgs/msg/Header`` at ``t`` s in ``frame``."""
    return ts.types["std_msgs/msg/Header"](stamp=ros_time(ts, t), frame_id=frame)


def planar_pose(ts: Any, x: float, y: float, theta: float) -> Any:
    """``geometry_msgs/msg/Pose`` of a planar pose (z = 0, a rotation about z by theta)."""
    t = ts.types
    return t["geometry_msgs/msg/Pose"](
        position=t["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=0.0),
        orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(theta / 2.0), w=math.cos(theta / 2.0)),
    )
