"""The compiled per-event arithmetic of :class:`~locbench.filters.ekf_icp.IcpEKF` around its ICP loop: the
filter's one implementation of its prediction, its clouds and rejection distances, and its correction.

Around the compiled ICP loop (:func:`locbench.filters._icp._icp_loop`) the filter's work per event is a few
3 x 3 products, an inverse and the two clouds' points, written out here as scalar expressions (as numpy calls
each would cost its dispatch, 1-5 us, more than the arithmetic):

- :func:`predict_pose`: the odometry prediction (report 000 eq. 11-13), F P F^T + Q with F's structure;
- :func:`scan_clouds`: the usable beams' points of the real and the ray-cast scan, the mean range and the
  rejection distances D_0, D_min of :mod:`locbench.filters.ekf_icp` (the largest eigenvalue of P's position
  block in closed form, :func:`max_eig_2x2`; the mean range summed pairwise,
  :func:`locbench.core.pairwise.pairwise_sum`);
- :func:`correct_pose`: the H = I correction in the Joseph form (eq. 14-18) with the 3 x 3 inverse by cofactors.

numba compiles IEEE double operations in source order, without fused multiply-adds unless ``fastmath`` is asked
for; the tests compare these kernels with numpy forms of the same equations within stated tolerances.

The state lives in one float buffer ``s`` (numba unboxes every array argument on each call): the mean
(x m, y m, theta rad) in ``s[0:3]``, the covariance row-major in ``s[3:12]`` and the constants from
:data:`BUF_Q` on (layout in :func:`state_buffer`).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit

from locbench.core.pairwise import pairwise_sum
from locbench.filters._ekf_kernels import _propagate, _wrap
from locbench.filters._icp import MIN_PAIRS
from locbench.raycast.beams import beam_point

FloatArray = npt.NDArray[np.float64]

#: Offsets in the state buffer: the mean (3) and covariance (9); Q's static and dynamic terms (6, eq. 13);
#: R's diagonal (3, eq. 16); the gates' constants (3: the pair variance of a correct pair m^2, the cap of D_0 m,
#: the number of standard deviations k; the last is rewritten when the kidnap rule tightens the threshold).
BUF_STATE, BUF_Q, BUF_R, BUF_GATE, BUF_SIZE = 0, 12, 18, 21, 24
#: Index of k, the gates' standard deviations, in the state buffer.
BUF_SIGMAS = BUF_GATE + 2


def state_buffer(
    mean: FloatArray, cov: FloatArray, q: tuple[float, ...], r: tuple[float, float, float], gate: tuple[float, float]
) -> FloatArray:
    """The state buffer of the kernels.

    Parameters
    ----------
    mean : ndarray, shape (3,)
        Pose (x m, y m, theta rad), theta wrapped.
    cov : ndarray, shape (3, 3)
        Covariance, symmetric.
    q : tuple of float
        (q_x,stat, q_y,stat, q_theta,stat, q_x,dyn, q_y,dyn, q_theta,dyn) of eq. 13.
    r : tuple of float
        R's diagonal (r_x m^2, r_y m^2, r_theta rad^2).
    gate : tuple of float
        (variance of a correct pair's distance m^2, cap of D_0 m); k starts at 0 (set per scan).

    Returns
    -------
    ndarray, shape (BUF_SIZE,)
    """
    s = np.zeros(BUF_SIZE)
    s[0:3] = mean
    s[3:12] = np.asarray(cov, dtype=np.float64).ravel()
    s[BUF_Q : BUF_Q + 6] = q
    s[BUF_R : BUF_R + 3] = r
    s[BUF_GATE : BUF_GATE + 2] = gate
    return s


@njit(cache=True)
def predict_pose(s: FloatArray, dx: float, dy: float, dtheta: float, k: float) -> bool:
    """``IcpEKF.predict`` on ``s`` in place: the robot-frame increment (dx, dy m, dtheta rad) rotated into the
    world frame (eq. 11), P = F P F^T + Q (eq. 12-13) with the static terms times ``k`` = dt / period; whether
    the new mean is finite."""
    th = s[2]
    c, sn = math.cos(th), math.sin(th)
    dxw = c * dx - sn * dy
    dyw = sn * dx + c * dy
    s[0], s[1], s[2] = s[0] + dxw, s[1] + dyw, _wrap(th + dtheta)
    q00 = s[BUF_Q] * k + s[BUF_Q + 3] * abs(dxw)
    q11 = s[BUF_Q + 1] * k + s[BUF_Q + 4] * abs(dyw)
    q22 = s[BUF_Q + 2] * k + s[BUF_Q + 5] * abs(dtheta)
    # F = [[1, 0, -dyw], [0, 1, dxw], [0, 0, 1]]: the products with its zeros and ones are exact
    _propagate(s, -dyw, dxw, q00, 0.0, 0.0, q11, 0.0, q22)
    return math.isfinite(s[0]) and math.isfinite(s[1]) and math.isfinite(s[2])


@njit(cache=True, inline="always")
def max_eig_2x2(a: float, b: float, c: float) -> float:
    """The larger eigenvalue of the symmetric [[a, b], [b, c]]: (a + c) / 2 + hypot((a - c) / 2, b)."""
    return 0.5 * (a + c) + math.hypot(0.5 * (a - c), b)


@njit(cache=True)
def scan_clouds(
    s: FloatArray,
    real: FloatArray,
    pred: FloatArray,
    cos_a: FloatArray,
    sin_a: FloatArray,
    sensor: tuple[float, float, float, float],
    src: FloatArray,
    dst: FloatArray,
) -> tuple[int, int, float, float]:
    """``IcpEKF.match``'s clouds and rejection distances.

    The usable real beams (finite, within [range_min, range_max]) become ``src[:n_real]`` and the usable
    ray-cast beams (finite, at least range_min) ``dst[:n_pred]``, robot-frame points in beam order
    (:func:`~locbench.raycast.beams.beam_point`: sx + r cos a, sy + r sin a with the beams' directions ``cos_a``,
    ``sin_a`` in the robot frame); ``sensor`` is (sx m, sy m, range_min m, range_max m). Returns (n_real, n_pred,
    D_0 m, D_min m) with D_min = k sqrt(pair variance) and
    D_0 = min(k sqrt(pair variance + lambda_max(P_xy) + r_mean^2 P_thth), cap), at least D_min
    (:mod:`locbench.filters.ekf_icp`; r_mean the mean of the usable real ranges, summed pairwise), both NaN when
    either cloud has fewer than ``MIN_PAIRS`` points.
    """
    sx, sy, rmin, rmax = sensor
    n = real.shape[0]
    used = np.empty(n)
    n_real = 0
    n_pred = 0
    for i in range(n):
        r = real[i]
        if math.isfinite(r) and r >= rmin and r <= rmax:
            src[n_real, 0], src[n_real, 1] = beam_point(sx, sy, r, cos_a[i], sin_a[i])
            used[n_real] = r
            n_real += 1
        p = pred[i]
        if math.isfinite(p) and p >= rmin:
            dst[n_pred, 0], dst[n_pred, 1] = beam_point(sx, sy, p, cos_a[i], sin_a[i])
            n_pred += 1
    if n_real < MIN_PAIRS or n_pred < MIN_PAIRS:
        return n_real, n_pred, math.nan, math.nan
    r_mean = pairwise_sum(used, 0, n_real) / n_real
    lam_xy = max_eig_2x2(s[3], s[4], s[7])
    pair_var, cap, k = s[BUF_GATE], s[BUF_GATE + 1], s[BUF_SIGMAS]
    d_min = k * math.sqrt(pair_var)
    d_0 = min(k * math.sqrt(pair_var + lam_xy + r_mean * r_mean * s[11]), cap)
    return n_real, n_pred, max(d_0, d_min), d_min


@njit(cache=True)
def correct_pose(s: FloatArray, tx: float, ty: float, tth: float) -> tuple[bool, float]:
    """``IcpEKF.update``'s correction with the ICP transform (tx, ty m, tth rad) on ``s`` in place.

    V = (R(theta) (tx, ty), wrap(tth)) (eq. 2-3), S = P + R, K = P S^-1, x + K V (heading wrapped),
    P = (I - K) P (I - K)^T + K R K^T symmetrised (eq. 15-18, Joseph form). Returns (finite, NIS V^T S^-1 V);
    the state is left unchanged when the new mean or covariance is not finite.
    """
    th = s[2]
    c, sn = math.cos(th), math.sin(th)
    v0, v1, v2 = c * tx - sn * ty, sn * tx + c * ty, _wrap(tth)
    p00, p01, p02 = s[3], s[4], s[5]
    p10, p11, p12 = s[6], s[7], s[8]
    p20, p21, p22 = s[9], s[10], s[11]
    r0, r1, r2 = s[BUF_R], s[BUF_R + 1], s[BUF_R + 2]
    s00, s01, s02 = p00 + r0, p01, p02
    s10, s11, s12 = p10, p11 + r1, p12
    s20, s21, s22 = p20, p21, p22 + r2
    # S^-1 by cofactors (S is symmetric positive definite: P is PSD and R positive)
    c00 = s11 * s22 - s12 * s21
    c01 = s12 * s20 - s10 * s22
    c02 = s10 * s21 - s11 * s20
    det = s00 * c00 + s01 * c01 + s02 * c02
    i00, i01, i02 = c00 / det, (s02 * s21 - s01 * s22) / det, (s01 * s12 - s02 * s11) / det
    i10, i11, i12 = c01 / det, (s00 * s22 - s02 * s20) / det, (s02 * s10 - s00 * s12) / det
    i20, i21, i22 = c02 / det, (s01 * s20 - s00 * s21) / det, (s00 * s11 - s01 * s10) / det
    k00 = p00 * i00 + p01 * i10 + p02 * i20
    k01 = p00 * i01 + p01 * i11 + p02 * i21
    k02 = p00 * i02 + p01 * i12 + p02 * i22
    k10 = p10 * i00 + p11 * i10 + p12 * i20
    k11 = p10 * i01 + p11 * i11 + p12 * i21
    k12 = p10 * i02 + p11 * i12 + p12 * i22
    k20 = p20 * i00 + p21 * i10 + p22 * i20
    k21 = p20 * i01 + p21 * i11 + p22 * i21
    k22 = p20 * i02 + p21 * i12 + p22 * i22
    x0 = s[0] + (k00 * v0 + k01 * v1 + k02 * v2)
    x1 = s[1] + (k10 * v0 + k11 * v1 + k12 * v2)
    x2 = s[2] + (k20 * v0 + k21 * v1 + k22 * v2)
    nis = (
        v0 * (i00 * v0 + i01 * v1 + i02 * v2)
        + v1 * (i10 * v0 + i11 * v1 + i12 * v2)
        + v2 * (i20 * v0 + i21 * v1 + i22 * v2)
    )
    a00, a01, a02 = 1.0 - k00, -k01, -k02
    a10, a11, a12 = -k10, 1.0 - k11, -k12
    a20, a21, a22 = -k20, -k21, 1.0 - k22
    # B = A P, then P' = B A^T + K R K^T
    b00 = a00 * p00 + a01 * p10 + a02 * p20
    b01 = a00 * p01 + a01 * p11 + a02 * p21
    b02 = a00 * p02 + a01 * p12 + a02 * p22
    b10 = a10 * p00 + a11 * p10 + a12 * p20
    b11 = a10 * p01 + a11 * p11 + a12 * p21
    b12 = a10 * p02 + a11 * p12 + a12 * p22
    b20 = a20 * p00 + a21 * p10 + a22 * p20
    b21 = a20 * p01 + a21 * p11 + a22 * p21
    b22 = a20 * p02 + a21 * p12 + a22 * p22
    q00 = b00 * a00 + b01 * a01 + b02 * a02 + (k00 * r0 * k00 + k01 * r1 * k01 + k02 * r2 * k02)
    q01 = b00 * a10 + b01 * a11 + b02 * a12 + (k00 * r0 * k10 + k01 * r1 * k11 + k02 * r2 * k12)
    q02 = b00 * a20 + b01 * a21 + b02 * a22 + (k00 * r0 * k20 + k01 * r1 * k21 + k02 * r2 * k22)
    q10 = b10 * a00 + b11 * a01 + b12 * a02 + (k10 * r0 * k00 + k11 * r1 * k01 + k12 * r2 * k02)
    q11 = b10 * a10 + b11 * a11 + b12 * a12 + (k10 * r0 * k10 + k11 * r1 * k11 + k12 * r2 * k12)
    q12 = b10 * a20 + b11 * a21 + b12 * a22 + (k10 * r0 * k20 + k11 * r1 * k21 + k12 * r2 * k22)
    q20 = b20 * a00 + b21 * a01 + b22 * a02 + (k20 * r0 * k00 + k21 * r1 * k01 + k22 * r2 * k02)
    q21 = b20 * a10 + b21 * a11 + b22 * a12 + (k20 * r0 * k10 + k21 * r1 * k11 + k22 * r2 * k12)
    q22 = b20 * a20 + b21 * a21 + b22 * a22 + (k20 * r0 * k20 + k21 * r1 * k21 + k22 * r2 * k22)
    # symmetrised as 0.5 (P' + P'^T): the two halves' products ran in different orders
    q01 = 0.5 * (q01 + q10)
    q02 = 0.5 * (q02 + q20)
    q12 = 0.5 * (q12 + q21)
    finite = True
    for q in (x0, x1, x2, q00, q01, q02, q11, q12, q22):
        finite = finite and math.isfinite(q)
    if not finite:
        return False, nis
    s[0], s[1], s[2] = x0, x1, _wrap(x2)
    s[3], s[4], s[5] = q00, q01, q02
    s[6], s[7], s[8] = q01, q11, q12
    s[9], s[10], s[11] = q02, q12, q22
    return True, nis
