"""Planar pose algebra on (x, y, theta) triples.

Conventions: SI units, angles in radians, headings wrapped to (-pi, pi], world frame x-y,
robot frame x forward and y to the left. Names follow ``<to>_from_<from>`` where it helps.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

TWO_PI = 2.0 * np.pi


def wrap_angle(a: npt.ArrayLike) -> FloatArray:
    """Wrap angles to the half-open interval (-pi, pi].

    Parameters
    ----------
    a : array-like
        Angles in rad, any shape.

    Returns
    -------
    ndarray
        The same angles in (-pi, pi], float64, same shape (0-d for a scalar input).
    """
    x = np.asarray(a, dtype=np.float64)
    w = np.pi - np.mod(np.pi - x, TWO_PI)  # maps onto (-pi, pi]
    return w


def wrap_scalar(a: float) -> float:
    """Wrap one angle to (-pi, pi] without numpy overhead (hot paths in filters)."""
    w = np.pi - ((np.pi - a) % TWO_PI)
    return float(w)


def compose(a: npt.ArrayLike, b: npt.ArrayLike) -> FloatArray:
    """Pose composition a (+) b: the pose ``b``, given in the frame of ``a``, expressed in a's parent frame.

    Parameters
    ----------
    a, b : array-like, shape (3,) or (N, 3)
        Poses (x m, y m, theta rad). Broadcasts over leading dimensions.

    Returns
    -------
    ndarray, shape broadcast of (3,)
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = a[..., 0] + c * b[..., 0] - s * b[..., 1]
    y = a[..., 1] + s * b[..., 0] + c * b[..., 1]
    th = wrap_angle(a[..., 2] + b[..., 2])
    return np.stack([x, y, th], axis=-1)


def inverse(a: npt.ArrayLike) -> FloatArray:
    """Inverse pose: ``compose(a, inverse(a))`` is the identity."""
    a = np.asarray(a, dtype=np.float64)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = -c * a[..., 0] - s * a[..., 1]
    y = s * a[..., 0] - c * a[..., 1]
    return np.stack([x, y, wrap_angle(-a[..., 2])], axis=-1)


def between(a: npt.ArrayLike, b: npt.ArrayLike) -> FloatArray:
    """Relative pose of ``b`` seen from ``a``: inverse(a) (+) b, i.e. the odometry increment a -> b."""
    return compose(inverse(a), b)


def twist_increment(
    v: npt.ArrayLike, omega: npt.ArrayLike, dt: npt.ArrayLike
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Exact increment of a constant twist held for ``dt``, in the frame of the starting pose.

    Parameters
    ----------
    v, omega, dt : array-like
        Forward speed (m/s), turn rate (rad/s) and duration (s), broadcast together.

    Returns
    -------
    dx, dy, dtheta : ndarray
        (m, m, rad): with a = omega dt, dx = v dt sin(a)/a, dy = v dt (1 - cos a)/a, dtheta = a; written as a
        chord v dt sinc(a/2) at heading a/2, which is exact and has no 0/0 at a = 0.
    """
    dt_ = np.asarray(dt, dtype=np.float64)
    a = np.asarray(omega, dtype=np.float64) * dt_
    s = np.asarray(v, dtype=np.float64) * dt_
    chord = s * np.sinc(a / (2.0 * np.pi))  # np.sinc(x) = sin(pi x) / (pi x): sin(a/2) / (a/2)
    return chord * np.cos(0.5 * a), chord * np.sin(0.5 * a), a


def is_symmetric_psd(cov: npt.ArrayLike, atol: float = 1e-9) -> bool:
    """True when ``cov`` is symmetric and positive semi-definite up to ``atol`` (relative to its scale)."""
    m = np.asarray(cov, dtype=np.float64)
    if m.ndim != 2 or m.shape[0] != m.shape[1] or not np.all(np.isfinite(m)):
        return False
    scale = max(1.0, float(np.max(np.abs(m))))
    if not np.allclose(m, m.T, atol=atol * scale, rtol=0.0):
        return False
    return bool(np.min(np.linalg.eigvalsh(0.5 * (m + m.T))) >= -atol * scale)


def pose_error(estimate: npt.ArrayLike, truth: npt.ArrayLike) -> FloatArray:
    """Error estimate - truth with the heading difference wrapped, shape (..., 3)."""
    e = np.asarray(estimate, dtype=np.float64) - np.asarray(truth, dtype=np.float64)
    e[..., 2] = wrap_angle(e[..., 2])
    return e


def yaw_to_quaternion(theta: npt.ArrayLike) -> FloatArray:
    """Unit quaternions (qx, qy, qz, qw) of rotations by ``theta`` (rad) about z, shape (..., 4); qw >= 0."""
    half = 0.5 * wrap_angle(theta)
    z = np.zeros_like(half)
    return np.stack([z, z, np.sin(half), np.cos(half)], axis=-1)


def quaternion_to_yaw(q: npt.ArrayLike) -> FloatArray:
    """Yaw (rad, in (-pi, pi]) of quaternions (qx, qy, qz, qw), shape (..., 4) -> (...); q and -q give the same."""
    a = np.asarray(q, dtype=np.float64)
    x, y, z, w = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    return np.asarray(wrap_angle(np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))), dtype=np.float64)
