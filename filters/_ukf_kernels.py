"""Compiled per-event arithmetic of :class:`~locbench.filters.ukf_landmarks.LandmarkUKF` (issue 24).

The UKF's prediction and the sums of its landmark correction are a few hundred floating-point operations on
7 sigma points; through filterpy and numpy each step is a Python call on a tiny array, so the filter spent
its time on the interpreter. These kernels are the same IEEE operations in the same order, compiled (numba
neither reassociates nor contracts to FMA without ``fastmath``), so the estimates are the same bits:

- the matrix square root is LAPACK's ``dpotrf`` itself (numba's binding to scipy's ``cython_lapack``, the
  library behind ``scipy.linalg.lapack.dpotrf``), on the symmetric matrix, so the factor is the same;
- ``w @ v`` of numpy on a column of a (7, k) array (a strided BLAS ``ddot``) is summed as OpenBLAS's
  strided loop does (:func:`_dot_strided`), on a contiguous array (the sines and cosines of a circular
  mean) as its plain loop from 0.0 does (:func:`_circular_mean`);
- the sums of outer products run over the points in order, as numpy's reduction over the leading axis;
- ``math.sin``, ``cos``, ``atan2``, ``hypot`` call the libm numpy's ufuncs call on this machine.

The tests compare every kernel with the numpy/filterpy form it replaces, bit for bit.

The state lives in a float buffer (one array: numba unboxes each array argument, about 0.4 us, more than a
prediction's arithmetic): mean and covariance (row-major) in ``buf[0:12]``, then the weights, the process
noise and scratch (offsets ``B_*``). The caller falls back to the Python path (filterpy's), which raises what
it raises, whenever a kernel returns a nonzero code (a failed factorisation, a non-finite value), and the
kernel leaves the state untouched in that case.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit, types
from numba.np.linalg import _LAPACK, ensure_lapack

FloatArray = npt.NDArray[np.float64]

_TWO_PI = 2.0 * math.pi
N_SIG = 7

#: Offsets in the float buffer: the state (12), Wm (7), Wc (7), n + lambda (1), the process noise Q
#: row-major (9), the factor's scratch (9), the sigma points (21) and the moved points (21), the correction's
#: outputs (S 4, P_xz 6, innovation 2) and its measurement points (14).
B_STATE, B_WM, B_WC, B_SCALE, B_Q, B_CHOL, B_SIG, B_SIGF, B_S, B_PXZ, B_Y, B_SIGH, B_END = (
    0, 12, 19, 26, 27, 36, 45, 66, 87, 91, 97, 99, 113,
)  # fmt: skip

ensure_lapack()
_xxpotrf = _LAPACK().numba_xxpotrf(types.float64)
_KIND_D, _UPLO_U = ord("d"), ord("U")


@njit(cache=True, inline="always")
def _wrap(a: float) -> float:
    """:func:`locbench.core.geometry.wrap_scalar` (and ``wrap_angle`` elementwise): the same expression."""
    return math.pi - ((math.pi - a) % _TWO_PI)


@njit(cache=True)
def _dot_strided(w: FloatArray, v: FloatArray, start: int, stride: int) -> float:
    """numpy's ``w @ a[:, j]`` for a column of a C-ordered (n, k) array (``v[start + stride i]``): OpenBLAS's
    strided ``ddot``, two accumulators fed pairs of products per block of four, the tail into the first."""
    n = w.shape[0]
    t1, t2 = 0.0, 0.0
    i = 0
    while i + 4 <= n:
        m1 = v[start + stride * i] * w[i]
        m2 = v[start + stride * (i + 1)] * w[i + 1]
        m3 = v[start + stride * (i + 2)] * w[i + 2]
        m4 = v[start + stride * (i + 3)] * w[i + 3]
        t1 += m1 + m3
        t2 += m2 + m4
        i += 4
    while i < n:
        t1 += v[start + stride * i] * w[i]
        i += 1
    return t1 + t2


@njit(cache=True)
def upper_factor(buf: FloatArray, p0: int, scale: float) -> int:
    """``dpotrf`` of ``scale * P`` (P the symmetric 3 x 3 at ``buf[p0:p0 + 9]``) into ``buf[B_CHOL:]``
    (column-major: U[i, j] at ``B_CHOL + i + 3 j``, i <= j); LAPACK's info (0: factorised)."""
    a = buf[B_CHOL : B_CHOL + 9]
    for k in range(9):  # symmetric: row-major is column-major
        a[k] = scale * buf[p0 + k]
    return _xxpotrf(_KIND_D, _UPLO_U, 3, a.ctypes, 3)


@njit(cache=True)
def sigma_points(buf: FloatArray) -> int:
    """``MerweScaledSigmaPoints.sigma_points(x, P)`` with the heading-wrapping ``subtract`` into
    ``buf[B_SIG:B_SIG + 21]`` (row-major (7, 3)); LAPACK's info (the points are written only when 0)."""
    info = upper_factor(buf, B_STATE + 3, buf[B_SCALE])
    if info != 0:
        return info
    x0, x1, x2 = buf[0], buf[1], buf[2]
    sg = buf[B_SIG : B_SIG + 21]
    sg[0], sg[1], sg[2] = x0, x1, x2
    for k in range(3):
        # row k of U (zeros left of the diagonal, as scipy's clean factor)
        u0 = buf[B_CHOL] if k == 0 else 0.0
        u1 = buf[B_CHOL + k + 3] if k <= 1 else 0.0
        u2 = buf[B_CHOL + k + 6]
        j = 3 * (k + 1)
        sg[j], sg[j + 1], sg[j + 2] = x0 - (-u0), x1 - (-u1), _wrap(x2 - (-u2))  # subtract(x, -U[k])
        j = 3 * (k + 4)
        sg[j], sg[j + 1], sg[j + 2] = x0 - u0, x1 - u1, _wrap(x2 - u2)  # subtract(x, U[k])
    return 0


@njit(cache=True, inline="always")
def _finite12(v: FloatArray) -> bool:
    """Whether every entry is finite (a loop: numba compiles it without a generator)."""
    for k in range(v.shape[0]):  # noqa: SIM110
        if not math.isfinite(v[k]):
            return False
    return True


@njit(cache=True)
def predict(buf: FloatArray, encoder: bool, a: float, b: float, c: float) -> int:
    """``LandmarkUKF.predict`` after the noise: filterpy's ``predict`` with ``pose_transform`` and the
    filter's ``_finish``, on the buffer (Q at ``B_Q`` set by the caller).

    ``encoder``: the points move by ``_move_midpoint`` with (dd, dth) = (a, b), else by ``_move_increment``
    with (dx, dy, dth) = (a, b, c). Returns 0 with the state replaced, or nonzero with the state untouched
    (a factorisation failed or a value is not finite: the caller takes the Python path).
    """
    if sigma_points(buf) != 0:
        return 1
    sg, sf = buf[B_SIG : B_SIG + 21], buf[B_SIGF : B_SIGF + 21]
    for i in range(N_SIG):
        x, y, th = sg[3 * i], sg[3 * i + 1], sg[3 * i + 2]
        if encoder:  # _move_midpoint
            h = th + 0.5 * b
            if not math.isfinite(h):
                return 2  # math.cos raises on inf in Python
            sf[3 * i], sf[3 * i + 1], sf[3 * i + 2] = x + a * math.cos(h), y + a * math.sin(h), th + b
        else:  # _move_increment
            if not math.isfinite(th):
                return 2
            co, sn = math.cos(th), math.sin(th)
            sf[3 * i], sf[3 * i + 1], sf[3 * i + 2] = x + co * a - sn * b, y + sn * a + co * b, th + c
    wm, wc = buf[B_WM : B_WM + N_SIG], buf[B_WC : B_WC + N_SIG]
    # state_mean: arithmetic x, y (strided dots), circular heading
    m0 = _dot_strided(wm, sf, 0, 3)
    m1 = _dot_strided(wm, sf, 1, 3)
    m2 = _circular_mean(wm, sf, 2, 3)
    out = buf[B_CHOL : B_CHOL + 9]  # scratch: the new covariance (the factor is not needed any more)
    _moments3(sf, wc, m0, m1, m2, out)
    for k in range(9):
        out[k] += buf[B_Q + k]
    new = buf[B_SIGH : B_SIGH + 12]  # (x, P) of the transform, before _finish
    new[0], new[1], new[2] = m0, m1, m2
    for k in range(9):
        new[3 + k] = out[k]
    if not _finite12(new):
        return 3  # the Python path decides (FilterDiverged or filterpy's own error)
    if _factor_ok(buf, new) != 0:
        return 4  # filterpy redraws the points at the new (x, P): only its factorisation's verdict matters
    # _finish: heading wrapped, P symmetrised
    st = buf[B_STATE : B_STATE + 12]
    st[0], st[1], st[2] = new[0], new[1], _wrap(new[2])
    for i in range(3):
        for j in range(3):
            st[3 + 3 * i + j] = 0.5 * (new[3 + 3 * i + j] + new[3 + 3 * j + i])
    return 0


@njit(cache=True)
def _factor_ok(buf: FloatArray, state: FloatArray) -> int:
    """``dpotrf``'s info for ``(n + lambda) P`` of a 12-float state (mean, covariance)."""
    a = buf[B_CHOL : B_CHOL + 9]
    scale = buf[B_SCALE]
    for k in range(9):
        a[k] = scale * state[3 + k]
    return _xxpotrf(_KIND_D, _UPLO_U, 3, a.ctypes, 3)


@njit(cache=True, inline="always")
def _circular_mean(w: FloatArray, v: FloatArray, start: int, stride: int) -> float:
    """``circular_mean(a[:, j], w)``: the sines and cosines are contiguous arrays in numpy (plain dots)."""
    s, c = 0.0, 0.0
    for i in range(w.shape[0]):
        ang = v[start + stride * i]
        s += w[i] * math.sin(ang)
        c += w[i] * math.cos(ang)
    return _wrap(math.atan2(s, c))


@njit(cache=True)
def _moments3(sf: FloatArray, wc: FloatArray, m0: float, m1: float, m2: float, out: FloatArray) -> None:
    """``_moments(sigmas, Wc, mean, None, 2)`` of (7, 3) points: sum_k Wc_k r_k r_k^T in the order of k, the
    heading residual wrapped, into ``out`` (row-major 3 x 3)."""
    for i in range(N_SIG):
        r0 = sf[3 * i] - m0
        r1 = sf[3 * i + 1] - m1
        r2 = _wrap(sf[3 * i + 2] - m2)
        w = wc[i]
        t00, t01, t02 = w * (r0 * r0), w * (r0 * r1), w * (r0 * r2)
        t10, t11, t12 = w * (r1 * r0), w * (r1 * r1), w * (r1 * r2)
        t20, t21, t22 = w * (r2 * r0), w * (r2 * r1), w * (r2 * r2)
        if i == 0:
            out[0], out[1], out[2], out[3], out[4] = t00, t01, t02, t10, t11
            out[5], out[6], out[7], out[8] = t12, t20, t21, t22
        else:
            out[0] += t00
            out[1] += t01
            out[2] += t02
            out[3] += t10
            out[4] += t11
            out[5] += t12
            out[6] += t20
            out[7] += t21
            out[8] += t22


@njit(cache=True)
def landmark_sums(buf: FloatArray, r: float, b: float, lx: float, ly: float, rr: float, rb: float) -> int:
    """The sums of ``LandmarkUKF._correct`` for one (range, bearing) of the landmark at (lx, ly): the sigma
    points, their predicted measurements (``_range_bearing_points``), the mean (``range_bearing_mean``),
    S (``_moments`` + diag(rr, rb)), P_xz (``_weighted_outer_sum``) and the innovation
    (``_residual_bearing``), into ``buf[B_S:]``, ``buf[B_PXZ:]`` (row-major 3 x 2) and ``buf[B_Y:]``.
    Returns 0, or nonzero (the factorisation failed) with nothing written."""
    if sigma_points(buf) != 0:
        return 1
    sg, sh = buf[B_SIG : B_SIG + 21], buf[B_SIGH : B_SIGH + 14]
    for i in range(N_SIG):
        dx = lx - sg[3 * i]
        dy = ly - sg[3 * i + 1]
        sh[2 * i] = math.hypot(dx, dy)
        sh[2 * i + 1] = _wrap(math.atan2(dy, dx) - sg[3 * i + 2])
    wm, wc = buf[B_WM : B_WM + N_SIG], buf[B_WC : B_WC + N_SIG]
    z0 = _dot_strided(wm, sh, 0, 2)
    z1 = _circular_mean(wm, sh, 1, 2)
    x0, x1, x2 = buf[0], buf[1], buf[2]
    s00 = s01 = s10 = s11 = 0.0
    p00 = p01 = p10 = p11 = p20 = p21 = 0.0
    for i in range(N_SIG):
        e0 = sh[2 * i] - z0
        e1 = _wrap(sh[2 * i + 1] - z1)
        d0 = sg[3 * i] - x0
        d1 = sg[3 * i + 1] - x1
        d2 = _wrap(sg[3 * i + 2] - x2)
        w = wc[i]
        t00, t01, t10, t11 = w * (e0 * e0), w * (e0 * e1), w * (e1 * e0), w * (e1 * e1)
        q00, q01, q10, q11, q20, q21 = (
            w * (d0 * e0),
            w * (d0 * e1),
            w * (d1 * e0),
            w * (d1 * e1),
            w * (d2 * e0),
            w * (d2 * e1),
        )
        if i == 0:
            s00, s01, s10, s11 = t00, t01, t10, t11
            p00, p01, p10, p11, p20, p21 = q00, q01, q10, q11, q20, q21
        else:
            s00 += t00
            s01 += t01
            s10 += t10
            s11 += t11
            p00 += q00
            p01 += q01
            p10 += q10
            p11 += q11
            p20 += q20
            p21 += q21
    o = buf[B_S:B_SIGH]
    o[0], o[1], o[2], o[3] = s00 + rr, s01 + 0.0, s10 + 0.0, s11 + rb  # + R = diag(rr, rb)
    o[4], o[5], o[6], o[7], o[8], o[9] = p00, p01, p10, p11, p20, p21
    o[10], o[11] = r - z0, _wrap(b - z1)
    return 0


def weights_buffer(wm: FloatArray, wc: FloatArray, scale: float) -> FloatArray:
    """A float buffer (``B_END`` floats) with the weights and ``n + lambda`` set; state and Q to the caller."""
    buf = np.zeros(B_END)
    buf[B_WM : B_WM + N_SIG] = wm
    buf[B_WC : B_WC + N_SIG] = wc
    buf[B_SCALE] = scale
    return buf
