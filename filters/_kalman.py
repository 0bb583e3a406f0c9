"""The Kalman correction in numpy for any measurement model, and the chi-square gates around it.

One measurement update in the Joseph form, after filterpy's ``ExtendedKalmanFilter.update``:

    y = residual(z, h(x))                  innovation (a hook, so that angles are wrapped)
    S = H P H^T + R                        innovation covariance
    K = P H^T S^-1                         gain
    x+ = x + K y
    P+ = (I - K H) P (I - K H)^T + K R K^T     Joseph form: symmetric and PSD for any K (report 002 eq. 8)

with the innovation, S and the normalised innovation squared NIS = y^T S^-1 y returned beside the new state (and
the Gaussian log-likelihood log N(y; 0, S) on request). A sigma-point filter has no H; it forms y, S and the cross
covariance P_xz itself and calls :func:`gain_update` (K = P_xz S^-1, P+ = P - K S K^T).

These are the corrections of the measurements a filter meets rarely (a pose fix, a beacon range, a sigma-point
update) or whose dimension varies. A correction a filter runs at every event is written out for
its model in that filter's compiled kernels (the range-bearing landmark update of ``ekf_landmarks``,
:mod:`locbench.filters._ekf_kernels`); the tests hold those to these forms within rounding.

Gates: a measurement of dimension m is accepted when its NIS is inside the chi-square quantile with m
degrees of freedom of the gate probability (:func:`chi2_quantile`; closed forms for 1 and 2 dof).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from statistics import NormalDist
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from scipy.stats import chi2

from locbench.core.geometry import wrap_scalar

FloatArray = npt.NDArray[np.float64]
#: residual(z, h) -> y, the innovation (filterpy's ``residual`` argument).
Residual = Callable[[FloatArray, FloatArray], FloatArray]

_LOG_2PI = math.log(2.0 * math.pi)


class Correction(NamedTuple):
    """One Kalman correction: the new state and what the update saw (a named tuple: cheap to make per update).

    Attributes
    ----------
    x : ndarray, shape (n,)
        Corrected mean; angles are *not* wrapped (the caller knows which components are angles).
    P : ndarray, shape (n, n)
        Corrected covariance, symmetrised.
    y : ndarray, shape (m,)
        Innovation residual(z, h(x)).
    S : ndarray, shape (m, m)
        Innovation covariance.
    K : ndarray, shape (n, m)
        Gain.
    nis : float
        Normalised innovation squared y^T S^-1 y (chi-square with m dof for a consistent filter).
    """

    x: FloatArray
    P: FloatArray
    y: FloatArray
    S: FloatArray
    K: FloatArray
    nis: float

    @property
    def log_likelihood(self) -> float:
        """log N(y; 0, S) = -(m log 2 pi + log det S + NIS) / 2 (computed when asked: a determinant)."""
        return log_likelihood(self.nis, self.S)


def subtract(z: FloatArray, h: FloatArray) -> FloatArray:
    """The plain residual z - h."""
    return z - h


def wrapped_residual(angles: Sequence[int]) -> Residual:
    """A residual z - h of 1-D vectors whose components ``angles`` (indices, rad) are wrapped to (-pi, pi]."""
    idx = tuple(angles)

    def residual(z: FloatArray, h: FloatArray) -> FloatArray:
        y = np.asarray(z, dtype=np.float64) - h
        for i in idx:  # scalar wraps: sigma-point filters call this per point, where numpy indexing costs more
            y[i] = wrap_scalar(float(y[i]))
        return y

    return residual


def log_likelihood(nis: float, S: FloatArray) -> float:
    """log N(y; 0, S) given NIS = y^T S^-1 y; -inf when S is not positive definite."""
    sign, logdet = np.linalg.slogdet(S)
    if sign <= 0.0:
        return -math.inf
    return -0.5 * (S.shape[0] * _LOG_2PI + float(logdet) + nis)


def joseph_update(
    x: FloatArray,
    P: FloatArray,
    z: FloatArray,
    hx: FloatArray,
    H: FloatArray,
    R: FloatArray,
    residual: Residual = subtract,
) -> Correction:
    """One EKF correction in the Joseph form (module docstring).

    Parameters
    ----------
    x : ndarray, shape (n,)
        Prior mean.
    P : ndarray, shape (n, n)
        Prior covariance.
    z : ndarray, shape (m,)
        Measurement.
    hx : ndarray, shape (m,)
        Predicted measurement h(x).
    H : ndarray, shape (m, n)
        Jacobian of h at x.
    R : ndarray, shape (m, m)
        Measurement noise covariance.
    residual : callable
        residual(z, hx) -> y; :func:`wrapped_residual` for components that are angles.

    Returns
    -------
    Correction
        The new mean (angles not wrapped) and covariance, with y, S, K and NIS.
    """
    return joseph_correct(x, P, residual(z, hx), H, R)


def joseph_correct(x: FloatArray, P: FloatArray, y: FloatArray, H: FloatArray, R: FloatArray) -> Correction:
    """The Joseph-form correction for an innovation ``y`` the caller formed itself (angles already wrapped).

    Shapes as in :func:`joseph_update`.
    """
    PHt = P @ H.T
    S = H @ PHt + R
    Sinv = np.linalg.inv(S)
    K = PHt @ Sinv
    A = np.eye(P.shape[0]) - K @ H
    P_new = A @ P @ A.T + K @ R @ K.T
    nis = float(y @ Sinv @ y)
    return Correction(x + K @ y, 0.5 * (P_new + P_new.T), y, S, K, nis)


def gain_update(x: FloatArray, P: FloatArray, y: FloatArray, S: FloatArray, Pxz: FloatArray) -> Correction:
    """A correction from the cross covariance (sigma-point filters): K = P_xz S^-1, P+ = P - K S K^T.

    ``y`` and ``S`` are the innovation and its covariance as the caller formed them (R included); shapes (m,),
    (m, m), with P_xz (n, m).
    """
    Sinv = np.linalg.inv(S)
    K = Pxz @ Sinv
    P_new = P - K @ S @ K.T
    nis = float(y @ Sinv @ y)
    return Correction(x + K @ y, 0.5 * (P_new + P_new.T), y, S, K, nis)


# --- chi-square gates ------------------------------------------------------------------------------------


def chi2_2dof_quantile(p: float) -> float:
    """The ``p`` quantile of the chi-square distribution with 2 degrees of freedom: -2 ln(1 - p)."""
    return -2.0 * math.log1p(-p)


def chi2_1dof_quantile(p: float) -> float:
    """The ``p`` quantile of the chi-square distribution with 1 degree of freedom, Phi^-1((1 + p) / 2)^2; inf at 1."""
    if p >= 1.0:
        return math.inf
    return NormalDist().inv_cdf(0.5 * (1.0 + p)) ** 2


def chi2_quantile(p: float, dof: int) -> float:
    """The ``p`` quantile of the chi-square distribution with ``dof`` degrees of freedom; inf at ``p`` = 1."""
    if p >= 1.0:
        return math.inf
    if dof == 1:
        return chi2_1dof_quantile(p)
    if dof == 2:
        return chi2_2dof_quantile(p)
    return float(chi2.ppf(p, dof))


def inside_gate(nis: float, threshold: float) -> bool:
    """Whether a measurement with this NIS passes a gate (NaN never does)."""
    return nis <= threshold
