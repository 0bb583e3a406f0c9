"""The events a dataset feeds to filters: frozen dataclasses with a timestamp ``t`` in seconds.

Frames: odometry increments are in the previous robot frame; ranges and bearings are from the
robot frame (x forward, y left, bearing counter-clockwise from x); pose fixes are in the world frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TypeAlias

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

#: Landmark id used in :class:`LandmarkObservations` when the identity is withheld.
UNKNOWN_ID = -1


@dataclass(frozen=True, slots=True)
class Odometry:
    """The robot's own report of its motion since the previous odometry event.

    Attributes
    ----------
    t : float
        Time stamp, s.
    dx, dy : float
        Translation in the previous robot frame, m.
    dtheta : float
        Heading change, rad (not wrapped: a single step turns less than pi).
    d_left, d_right : float or None
        Raw wheel travel of the left and right wheel, m (report 003 eq. 1-2), when known.
    v, omega, dt : float or None
        Commanded twist (m/s, rad/s) held for ``dt`` seconds (report 001 fig. 1, report 004), when known.
    """

    t: float
    dx: float
    dy: float
    dtheta: float
    d_left: float | None = None
    d_right: float | None = None
    v: float | None = None
    omega: float | None = None
    dt: float | None = None

    @property
    def delta(self) -> FloatArray:
        """The increment as an array (dx, dy, dtheta)."""
        return np.array([self.dx, self.dy, self.dtheta])


@dataclass(frozen=True, slots=True, eq=False)
class LaserScan:
    """A planar range scan.

    Attributes
    ----------
    t : float
        Time stamp, s.
    angle_min, angle_increment : float
        Bearing of the first beam and the step between beams, rad, in the sensor frame.
    ranges : ndarray, shape (n,)
        Measured ranges, m; ``inf`` where a beam has no return (beyond range or dropped).
    range_min, range_max : float
        Valid range interval, m.
    sensor_pose : tuple of float
        Sensor pose (x m, y m, theta rad) in the robot frame.
    """

    t: float
    angle_min: float
    angle_increment: float
    ranges: FloatArray
    range_min: float
    range_max: float
    sensor_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def angles(self) -> FloatArray:
        """Beam bearings in the sensor frame, rad, shape (n,)."""
        return self.angle_min + self.angle_increment * np.arange(self.ranges.shape[0], dtype=np.float64)


@dataclass(frozen=True, slots=True, eq=False)
class LandmarkObservations:
    """Range-bearing sightings of point landmarks at one instant.

    Attributes
    ----------
    t : float
        Time stamp, s.
    ids : ndarray of int64, shape (n,)
        Landmark identities; :data:`UNKNOWN_ID` (-1) where the identity is withheld.
    ranges : ndarray, shape (n,)
        Distance from the sensor (robot origin) to the landmark, m.
    bearings : ndarray, shape (n,)
        Bearing in the robot frame, rad, in (-pi, pi].
    """

    t: float
    ids: IntArray
    ranges: FloatArray
    bearings: FloatArray

    def __len__(self) -> int:
        return int(self.ranges.shape[0])


@dataclass(frozen=True, slots=True, eq=False)
class RangeObservations:
    """Range-only measurements to point landmarks (radio beacons) at one instant.

    Attributes
    ----------
    t : float
        Time stamp, s.
    ids : ndarray of int64, shape (n,)
        Landmark (beacon) identities; :data:`UNKNOWN_ID` (-1) where the identity is withheld.
    ranges : ndarray, shape (n,)
        Distance from the robot origin to the landmark, m.
    """

    t: float
    ids: IntArray
    ranges: FloatArray

    def __len__(self) -> int:
        return int(self.ranges.shape[0])


@dataclass(frozen=True, slots=True, eq=False)
class PoseFix:
    """An absolute pose measurement in the world frame (GPS, scan-database match).

    Attributes
    ----------
    t : float
        Time stamp, s.
    z : ndarray, shape (2,) or (3,)
        Measured (x, y) in m, or (x, y, theta) with theta in rad.
    cov : ndarray, shape (2, 2) or (3, 3)
        Measurement covariance in the same units.
    """

    t: float
    z: FloatArray
    cov: FloatArray = field(repr=False)

    @property
    def has_heading(self) -> bool:
        return int(self.z.shape[0]) == 3


Observation: TypeAlias = LaserScan | LandmarkObservations | PoseFix | RangeObservations
Event: TypeAlias = Odometry | LaserScan | LandmarkObservations | PoseFix | RangeObservations

#: Every event type, in the order used to break ties between equal time stamps (odometry first).
EVENT_TYPES: tuple[type, ...] = (Odometry, LaserScan, LandmarkObservations, PoseFix, RangeObservations)
OBSERVATION_TYPES: tuple[type, ...] = (LaserScan, LandmarkObservations, PoseFix, RangeObservations)


def event_order(ev: Event) -> tuple[float, int]:
    """Sort key: time, then odometry before observations at equal time."""
    return (ev.t, EVENT_TYPES.index(type(ev)))
