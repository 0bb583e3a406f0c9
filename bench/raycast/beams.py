"""The end point of a laser beam: the one implementation of p = s + r (cos a, sin a).

A beam of range r (m) leaves the sensor at s = (sx, sy) (m) at the angle a (rad) in the frame s is given in; its
end point is (sx + r cos a, sy + r sin a). In the robot frame s is the sensor's mounting position and
a = beam angle + mounting heading; in the world frame s is the sensor's world position and a adds the robot's
heading. :func:`beam_point` is the formula for one beam from the direction's cosine and sine (the filters'
kernels take those from a per-scan table or from libm); :func:`beam_endpoints` is it over a scan.

numba's on-disk cache of a kernel is keyed on its own module's source alone: after editing :func:`beam_point`,
delete the ``*.nbi`` / ``*.nbc`` files under the ``__pycache__`` of the modules that inline it
(``filters/``, ``bench/raycast/``).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit

FloatArray = npt.NDArray[np.float64]


@njit(cache=True, inline="always")
def beam_point(sx: float, sy: float, r: float, cos_a: float, sin_a: float) -> tuple[float, float]:
    """(sx + r cos a, sy + r sin a): the end point (m) of a beam of range ``r`` (m) from (``sx``, ``sy``) (m) in
    the direction whose cosine and sine are ``cos_a``, ``sin_a``, in the frame of (sx, sy)."""
    return sx + r * cos_a, sy + r * sin_a


@njit(cache=True)
def _endpoints(ranges: FloatArray, angles: FloatArray, sx: float, sy: float, sth: float) -> FloatArray:
    """(2, B): :func:`beam_point` of every beam at ``angles[b] + sth`` (libm's cosine and sine)."""
    out = np.empty((2, ranges.shape[0]))
    for b in range(ranges.shape[0]):
        a = angles[b] + sth
        out[0, b], out[1, b] = beam_point(sx, sy, ranges[b], math.cos(a), math.sin(a))
    return out


def beam_endpoints(
    ranges: npt.ArrayLike, angles: npt.ArrayLike, sensor_pose: tuple[float, float, float]
) -> tuple[FloatArray, FloatArray]:
    """Beam end points (x, y), m, in the frame of ``sensor_pose``.

    Parameters
    ----------
    ranges : array-like, shape (B,)
        Ranges, m (a non-finite range gives a non-finite point).
    angles : array-like, shape (B,)
        Beam angles in the sensor frame, rad.
    sensor_pose : tuple of float
        (sx m, sy m, stheta rad): the sensor in the frame of the result (the mounting pose for robot-frame points).

    Returns
    -------
    x, y : ndarray, shape (B,)
        sx + r cos(angle + stheta), sy + r sin(angle + stheta).
    """
    r = np.ascontiguousarray(ranges, dtype=np.float64).reshape(-1)
    a = np.ascontiguousarray(angles, dtype=np.float64).reshape(-1)
    if r.shape != a.shape:
        raise ValueError(f"ranges and angles must have the same length, got {r.shape} and {a.shape}")
    sx, sy, sth = (float(v) for v in sensor_pose)
    out = _endpoints(r, a, sx, sy, sth)
    return out[0], out[1]
