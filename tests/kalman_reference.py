"""Plain reference forms of the Kalman family's models, for the tests: numpy matrices and filterpy's loops.

The library computes each model once (``filters/_ekf_kernels.py``, ``filters/_ukf_kernels.py``,
``filters/_motion.py``, ``filters/_kalman.py``); these forms write the same mathematics the textbook way, so a
test holds the library to them within a stated tolerance (numpy, OpenBLAS, LAPACK and libm pick their kernels per
CPU, so the two agree to rounding, not to the bit).

- range-bearing measurement of a landmark and its Jacobian (report 003 eq. 7, report 001 fig. 2 corrected);
- the Joseph update for a direct measurement of the whole state (H = I; report 000 eq. 15-18, report 002 eq. 8);
- the scaled unscented transform (van der Merwe 2004) through filterpy's ``MerweScaledSigmaPoints`` and
  ``unscented_transform``, with numpy's Cholesky factor and the heading residuals wrapped.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from locbench.core.geometry import wrap_angle, wrap_scalar

FloatArray = npt.NDArray[np.float64]


# --- the range-bearing sensor (EKF and UKF) ----------------------------------------------------------------


def range_bearing(pose: npt.ArrayLike, landmarks_xy: npt.ArrayLike) -> FloatArray:
    """Expected (range m, bearing rad) of landmarks seen from ``pose`` (report 003 eq. 7), shape (..., 2).

    ``pose`` (3,) world frame; ``landmarks_xy`` (..., 2) world frame; bearing wrapped to (-pi, pi].
    """
    p = np.asarray(pose, dtype=np.float64)
    lm = np.asarray(landmarks_xy, dtype=np.float64)
    dx, dy = lm[..., 0] - p[0], lm[..., 1] - p[1]
    return np.stack([np.hypot(dx, dy), wrap_angle(np.arctan2(dy, dx) - p[2])], axis=-1)


def range_bearing_jacobian(pose: npt.ArrayLike, landmark_xy: npt.ArrayLike) -> FloatArray:
    """H = d(range, bearing)/d(x, y, theta), shape (2, 3); the corrected form of report 001 fig. 2."""
    p = np.asarray(pose, dtype=np.float64)
    lm = np.asarray(landmark_xy, dtype=np.float64)
    dx, dy = float(lm[0] - p[0]), float(lm[1] - p[1])
    q = dx * dx + dy * dy
    d = math.sqrt(q)
    return np.array([[-dx / d, -dy / d, 0.0], [dy / q, -dx / q, -1.0]])


# --- the Joseph update with H = I ---------------------------------------------------------------------------


def joseph_correct_pose(
    x: FloatArray, P: FloatArray, y: FloatArray, R: FloatArray
) -> tuple[FloatArray, FloatArray, float]:
    """The Joseph-form correction for a direct measurement of the whole state (H = I): (x+, P+ symmetrised, NIS).

    S = P + R, K = P S^-1, P+ = (I - K) P (I - K)^T + K R K^T, NIS = y^T S^-1 y; the innovation ``y`` is the
    caller's (angles wrapped).
    """
    S = P + R
    Sinv = np.linalg.inv(S)
    K = P @ Sinv
    A = np.eye(P.shape[0]) - K
    P_new = A @ P @ A.T + K @ R @ K.T
    return x + K @ y, 0.5 * (P_new + P_new.T), float(y @ Sinv @ y)


# --- the unscented transform (UKF) ---------------------------------------------------------------------------


def residual_heading(a: FloatArray, b: FloatArray) -> FloatArray:
    """Pose difference a - b with the heading wrapped to (-pi, pi]."""
    y = np.asarray(a, dtype=np.float64) - b
    y[2] = wrap_scalar(float(y[2]))
    return y


def residual_bearing(a: FloatArray, b: FloatArray) -> FloatArray:
    """(range, bearing) difference a - b with the bearing wrapped to (-pi, pi]."""
    y = np.asarray(a, dtype=np.float64) - b
    y[1] = wrap_scalar(float(y[1]))
    return y


def upper_cholesky(A: FloatArray) -> FloatArray:
    """The upper Cholesky factor U (U^T U = A) of a positive-definite matrix, from numpy's lower one."""
    return np.asarray(np.linalg.cholesky(A).T, dtype=np.float64)


def sigma_points_of(alpha: float = 1.0, beta: float = 2.0, kappa: float = 0.0) -> Any:
    """filterpy's ``MerweScaledSigmaPoints`` for the pose (n = 3): numpy's factor, headings wrapped."""
    from filterpy.kalman import MerweScaledSigmaPoints

    return MerweScaledSigmaPoints(
        3, alpha=alpha, beta=beta, kappa=kappa, sqrt_method=upper_cholesky, subtract=residual_heading
    )


def circular_mean(angles: FloatArray, weights: FloatArray) -> float:
    """Weighted circular mean atan2(sum w sin a, sum w cos a) of angles (rad), in (-pi, pi]."""
    return wrap_scalar(math.atan2(float(np.sum(weights * np.sin(angles))), float(np.sum(weights * np.cos(angles)))))


def state_mean(sigmas: FloatArray, weights: FloatArray) -> FloatArray:
    """Weighted mean of poses (n, 3): arithmetic in x and y, circular in the heading."""
    return np.array(
        [np.sum(weights * sigmas[:, 0]), np.sum(weights * sigmas[:, 1]), circular_mean(sigmas[:, 2], weights)]
    )


def range_bearing_mean(sigmas: FloatArray, weights: FloatArray) -> FloatArray:
    """Weighted mean of (range, bearing) measurements (n, 2): arithmetic range, circular bearing."""
    return np.array([np.sum(weights * sigmas[:, 0]), circular_mean(sigmas[:, 1], weights)])


def pose_transform(sigmas: FloatArray, pts: Any, Q: FloatArray) -> tuple[FloatArray, FloatArray]:
    """filterpy's ``unscented_transform`` of moved poses (7, 3): (mean, covariance + Q), heading residuals wrapped."""
    from filterpy.kalman import unscented_transform

    x, P = unscented_transform(sigmas, pts.Wm, pts.Wc, Q, state_mean, residual_heading)
    return np.asarray(x, dtype=np.float64), np.asarray(P, dtype=np.float64)


def landmark_transform(
    x: FloatArray, P: FloatArray, pts: Any, lm: FloatArray, R: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """The unscented transform of the range-bearing sensor for the landmark ``lm`` (2,) from the belief (x, P):
    (sigma points (7, 3), their measurements (7, 2), predicted measurement (2,), S (2, 2, R included), P_xz (3, 2)).
    """
    sig = pts.sigma_points(x, P)
    sh = np.array([range_bearing(s, lm) for s in sig])
    zp = range_bearing_mean(sh, pts.Wm)
    S, Pxz = R.copy(), np.zeros((3, 2))
    for k in range(sig.shape[0]):
        dz = residual_bearing(sh[k], zp)
        dx = residual_heading(sig[k], x)
        S += pts.Wc[k] * np.outer(dz, dz)
        Pxz += pts.Wc[k] * np.outer(dx, dz)
    return sig, sh, zp, S, Pxz


def on_the_wrap(angles: npt.ArrayLike) -> bool:
    """Whether a wrapped residual lies within 1e-6 rad of +-pi: a belief spread around the whole circle puts a sigma
    point opposite its circular mean, where a 1-ulp difference flips the residual by 2 pi (both sides are right)."""
    return bool(np.any(math.pi - np.abs(wrap_angle(np.asarray(angles, dtype=np.float64))) < 1e-6))
