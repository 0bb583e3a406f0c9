"""What the loaders derive from a recording's reference trajectory, shared by more than one of them.

* :func:`heading_from_track`: the heading of a reference that has positions only, as the direction of travel
  (the GPS truth of :mod:`~locbench.datasets.recorded.plaza`, the UWB truth of
  :mod:`~locbench.datasets.recorded.librsf`; both robots drive forwards only).
* :func:`derive_odometry_noise`: the nominal odometry noise of a raw odometry log against a reference at the same
  instants (:mod:`~locbench.datasets.recorded.intel`, the paired sites of
  :mod:`~locbench.datasets.recorded.radish`).
* The nominal values of a SLAM reference of the Freiburg SLAM benchmark's laser logs (intel, radish):
  :data:`GMAPPING_SIGMA_M` and :data:`SLAM_INITIAL_SIGMA`.

Odometry noise from a reference
-------------------------------
No official noise values come with the logs; the noise is derived from the reference, never from filter results.
For each pair of consecutive instants, u = between(odometry at i, odometry at i+1), z = the same between the
reference poses, e = between(u, z) (the odometry's error in the frame of its own increment); with d = |u_xy| and
a = |u_theta|, the method-of-moments fit of the increment model of
:func:`locbench.filters._motion.increment_variances`, var(e_x) = var(e_y) = sigma_xy^2 d and
var(e_theta) = sigma_theta_m^2 d + sigma_theta_rad^2 a, gives sigma_xy^2 = sum((e_x^2 + e_y^2) / 2) / sum(d) and
(sigma_theta_m^2, sigma_theta_rad^2) as the non-negative least-squares fit of e_theta^2 on (d, a). The
reference's own error enters these values: they bound the odometry noise from above.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from scipy.optimize import nnls

from locbench.core.geometry import between

FloatArray = npt.NDArray[np.float64]

#: GMapping's default endpoint-matching sigma, m (ROS ``gmapping`` parameter ``~sigma``): the laser model with
#: which the Freiburg logs' SLAM references were computed, handed to filters as ``laser_sigma_m``.
GMAPPING_SIGMA_M = 0.05
#: Standard deviations of the initial belief around a SLAM reference's first pose (x, y m; theta rad): the
#: reference is itself an estimate, and this is of the order of its own error (not tuned on any filter result).
SLAM_INITIAL_SIGMA = (0.1, 0.1, 0.05)


def heading_from_track(xy: FloatArray, chord_m: float) -> FloatArray:
    """Direction of travel at each sample of a track: the direction of a chord over ``chord_m`` of path, centred.

    For sample i the chord runs from the last sample at least ``chord_m / 2`` of path before i (or the first
    sample) to the first at least as far after it (or the last sample).

    Parameters
    ----------
    xy : ndarray, shape (n, 2)
        Positions in time order, m, world frame.
    chord_m : float
        Path length of the chord, m (half behind, half ahead).

    Returns
    -------
    ndarray, shape (n,)
        Heading, rad in [-pi, pi], world frame.
    """
    step = np.hypot(*np.diff(xy, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(step)])
    half = 0.5 * chord_m
    lo = np.clip(np.searchsorted(s, s - half, side="right") - 1, 0, len(s) - 1)
    hi = np.clip(np.searchsorted(s, s + half, side="left"), 0, len(s) - 1)
    d = xy[hi] - xy[lo]
    return np.arctan2(d[:, 1], d[:, 0])


def derive_odometry_noise(odom_poses: npt.ArrayLike, ref_poses: npt.ArrayLike) -> tuple[float, float, float]:
    """Per-distance odometry noise from consecutive reference poses (method of moments; module docstring).

    Parameters
    ----------
    odom_poses, ref_poses : array-like, shape (n, 3)
        Raw odometry and reference poses (x m, y m, theta rad) at the same n instants, in time order.

    Returns
    -------
    sigma_xy_per_m, sigma_theta_per_m, sigma_theta_per_rad : float
        m / sqrt(m), rad / sqrt(m), rad / sqrt(rad).
    """
    o = np.asarray(odom_poses, dtype=np.float64)
    r = np.asarray(ref_poses, dtype=np.float64)
    u = between(o[:-1], o[1:])
    z = between(r[:-1], r[1:])
    e = between(u, z)
    d = np.hypot(u[:, 0], u[:, 1])
    a = np.abs(u[:, 2])
    sxy2 = float(np.sum(0.5 * (e[:, 0] ** 2 + e[:, 1] ** 2)) / max(float(np.sum(d)), 1e-12))
    coef, _ = nnls(np.column_stack([d, a]), e[:, 2] ** 2)
    return math.sqrt(sxy2), math.sqrt(float(coef[0])), math.sqrt(float(coef[1]))
