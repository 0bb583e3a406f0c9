"""The compiled unscented transform of :class:`~locbench.filters.ukf_landmarks.LandmarkUKF`: its prediction, its
range-bearing correction's sums and its nearest-neighbour distances.

The scaled unscented transform (van der Merwe 2004; Julier 2002) with n = 3:

    sigma points  chi_0 = x,  chi_i = x + U_i,  chi_(n+i) = x - U_i   (U^T U = (n + lambda) P, U_i its row i),
    weights       Wm_0 = lambda / (n + lambda),  Wc_0 = Wm_0 + 1 - alpha^2 + beta,  Wm_i = Wc_i = 1 / (2 (n + lambda)),

with lambda = alpha^2 (n + kappa) - n (:func:`sigma_weights`). U is LAPACK's upper Cholesky factor (``dpotrf``
through numba's binding to scipy's LAPACK). Headings are angles: a sigma point's heading and every state residual
are wrapped to (-pi, pi], the mean heading of the points is their circular mean atan2(sum Wm sin, sum Wm cos), and
so are the predicted bearing and the bearing residuals of a landmark.

- :func:`predict`: every point moved by the mean motion (the chord of report 003 eq. 5, or the composed increment),
  their weighted mean and covariance plus the motion noise (additive-noise UKF), P symmetrised;
- :func:`landmark_sums`: the predicted (range, bearing) of a landmark (report 003 eq. 7) at every point, their mean,
  S = sum Wc (z_i - z)(z_i - z)^T + R, P_xz = sum Wc (chi_i - x)(z_i - z)^T and the innovation, for the gain step
  (:func:`locbench.filters._kalman.gain_update`);
- :func:`nearest_row`: the same transform per candidate landmark for the squared Mahalanobis distance of a sighting.

The weighted sums run in a fixed order (:func:`_dot_strided`, :func:`_circular_mean`, the outer products over the
points in order): the filter's numbers depend on it, so it changes only with the filter's ``version``.

The state lives in a float buffer (one array: numba unboxes each array argument, about 0.4 us, more than a
prediction's arithmetic): mean and covariance (row-major) in ``buf[0:12]``, then the weights, the process
noise and scratch (offsets ``B_*``). A kernel that cannot complete (a factorisation fails, a value is not finite)
returns a nonzero code and leaves the state untouched; the filter raises.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit, types
from numba.np.linalg import _LAPACK, ensure_lapack

from locbench.filters._ekf_kernels import _wrap

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

#: The state's dimension n and the number of sigma points 2 n + 1.
N_STATE, N_SIG = 3, 7

#: Offsets in the float buffer: the state (12), Wm (7), Wc (7), n + lambda (1), the process noise Q
#: row-major (9), the factor's scratch (9), the sigma points (21) and the moved points (21), the correction's
#: outputs (S 4, P_xz 6, innovation 2) and its measurement points (14).
B_STATE, B_WM, B_WC, B_SCALE, B_Q, B_CHOL, B_SIG, B_SIGF, B_S, B_PXZ, B_Y, B_SIGH, B_END = (
    0, 12, 19, 26, 27, 36, 45, 66, 87, 91, 97, 99, 113,
)  # fmt: skip

ensure_lapack()
_xxpotrf = _LAPACK().numba_xxpotrf(types.float64)
_KIND_D, _UPLO_U = ord("d"), ord("U")


@njit(cache=True)
def _dot_strided(w: FloatArray, v: FloatArray, start: int, stride: int) -> float:
    """sum_i w_i v[start + stride i] (a column of a C-ordered (n, k) array): two accumulators fed pairs of products
    per block of four, the tail into the first (the order is part of the filter's numbers)."""
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
    """The sigma points of the state into ``buf[B_SIG:B_SIG + 21]`` (row-major (7, 3); module docstring): x, then
    x + U_k and x - U_k written as x - (-U_k) and x - U_k, headings wrapped; LAPACK's info (written only when 0)."""
    info = upper_factor(buf, B_STATE + 3, buf[B_SCALE])
    if info != 0:
        return info
    x0, x1, x2 = buf[0], buf[1], buf[2]
    sg = buf[B_SIG : B_SIG + 21]
    sg[0], sg[1], sg[2] = x0, x1, x2
    for k in range(3):
        # row k of U (zeros left of the diagonal)
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
    """One unscented prediction on the buffer (module docstring), the motion noise Q at ``B_Q`` set by the caller.

    ``encoder``: each point moves along the chord at its midpoint heading (report 003 eq. 5) with
    (delta_d m, delta_theta rad) = (a, b), else the increment (dx m, dy m, dtheta rad) = (a, b, c) of the previous
    robot frame is composed onto it; the new mean is the points' weighted mean (circular in the heading, then
    wrapped), the new covariance their weighted covariance plus Q, symmetrised. Returns 0 with the state replaced,
    or with the state untouched: 1 the factorisation at the current state failed, 2 a moved heading is not finite,
    3 the new state is not finite, 4 the new covariance has no Cholesky factor (the next draw would fail).
    """
    if sigma_points(buf) != 0:
        return 1
    sg, sf = buf[B_SIG : B_SIG + 21], buf[B_SIGF : B_SIGF + 21]
    for i in range(N_SIG):
        x, y, th = sg[3 * i], sg[3 * i + 1], sg[3 * i + 2]
        if encoder:  # the chord at the midpoint heading, heading not wrapped (the residuals are)
            h = th + 0.5 * b
            if not math.isfinite(h):
                return 2
            sf[3 * i], sf[3 * i + 1], sf[3 * i + 2] = x + a * math.cos(h), y + a * math.sin(h), th + b
        else:  # the increment composed onto the point
            if not math.isfinite(th):
                return 2
            co, sn = math.cos(th), math.sin(th)
            sf[3 * i], sf[3 * i + 1], sf[3 * i + 2] = x + co * a - sn * b, y + sn * a + co * b, th + c
    wm, wc = buf[B_WM : B_WM + N_SIG], buf[B_WC : B_WC + N_SIG]
    # the points' mean: arithmetic x, y, circular heading
    m0 = _dot_strided(wm, sf, 0, 3)
    m1 = _dot_strided(wm, sf, 1, 3)
    m2 = _circular_mean(wm, sf, 2, 3)
    out = buf[B_CHOL : B_CHOL + 9]  # scratch: the new covariance (the factor is not needed any more)
    _moments3(sf, wc, m0, m1, m2, out)
    for k in range(9):
        out[k] += buf[B_Q + k]
    new = buf[B_SIGH : B_SIGH + 12]  # (x, P) of the transform, before the heading's wrap and the symmetrisation
    new[0], new[1], new[2] = m0, m1, m2
    for k in range(9):
        new[3 + k] = out[k]
    if not _finite12(new):
        return 3
    if _factor_ok(buf, new) != 0:
        return 4
    # heading wrapped, P symmetrised
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
    """The weighted circular mean atan2(sum w_i sin a_i, sum w_i cos a_i) of a column a (``v[start + stride i]``,
    rad), wrapped; the sums run from 0 in the order of i."""
    s, c = 0.0, 0.0
    for i in range(w.shape[0]):
        ang = v[start + stride * i]
        s += w[i] * math.sin(ang)
        c += w[i] * math.cos(ang)
    return _wrap(math.atan2(s, c))


@njit(cache=True)
def _moments3(sf: FloatArray, wc: FloatArray, m0: float, m1: float, m2: float, out: FloatArray) -> None:
    """The weighted covariance sum_k Wc_k r_k r_k^T of (7, 3) points ``sf``, r_k = point k - mean (m0, m1, m2) with
    the heading residual wrapped, summed in the order of k, into ``out`` (row-major 3 x 3)."""
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


@njit(cache=True, inline="always")
def _rb_points(buf: FloatArray, lx: float, ly: float) -> tuple[float, float]:
    """The predicted (range m, bearing rad) of the landmark at (lx, ly) from every sigma point (report 003 eq. 7;
    bearing wrapped) into ``buf[B_SIGH:B_SIGH + 14]`` (row-major (7, 2)): (mean range, circular mean bearing)."""
    sg, sh = buf[B_SIG : B_SIG + 21], buf[B_SIGH : B_SIGH + 14]
    for i in range(N_SIG):
        dx = lx - sg[3 * i]
        dy = ly - sg[3 * i + 1]
        sh[2 * i] = math.hypot(dx, dy)
        sh[2 * i + 1] = _wrap(math.atan2(dy, dx) - sg[3 * i + 2])
    wm = buf[B_WM : B_WM + N_SIG]
    return _dot_strided(wm, sh, 0, 2), _circular_mean(wm, sh, 1, 2)


@njit(cache=True, inline="always")
def _rb_sums(buf: FloatArray, z0: float, z1: float, cross: bool) -> tuple[float, float, float, float, float, float,
                                                                          float, float, float, float]:  # fmt: skip
    """The weighted sums over the sigma points of the predicted measurements of :func:`_rb_points`, in the order of
    the points: (s00, s01, s10, s11) = sum Wc_k e_k e_k^T, e_k = z_k - (z0, z1) with the bearing residual wrapped
    (R not added), then, with ``cross``, (p00, p01, p10, p11, p20, p21) = sum Wc_k d_k e_k^T row-major, d_k = point
    k - the state's mean with the heading residual wrapped (zeros without)."""
    sg, sh, wc = buf[B_SIG : B_SIG + 21], buf[B_SIGH : B_SIGH + 14], buf[B_WC : B_WC + N_SIG]
    x0, x1, x2 = buf[0], buf[1], buf[2]
    s00 = s01 = s10 = s11 = 0.0
    p00 = p01 = p10 = p11 = p20 = p21 = 0.0
    for i in range(N_SIG):
        e0 = sh[2 * i] - z0
        e1 = _wrap(sh[2 * i + 1] - z1)
        w = wc[i]
        t00, t01, t10, t11 = w * (e0 * e0), w * (e0 * e1), w * (e1 * e0), w * (e1 * e1)
        if i == 0:
            s00, s01, s10, s11 = t00, t01, t10, t11
        else:
            s00 += t00
            s01 += t01
            s10 += t10
            s11 += t11
        if cross:
            d0 = sg[3 * i] - x0
            d1 = sg[3 * i + 1] - x1
            d2 = _wrap(sg[3 * i + 2] - x2)
            q00, q01, q10, q11, q20, q21 = (
                w * (d0 * e0),
                w * (d0 * e1),
                w * (d1 * e0),
                w * (d1 * e1),
                w * (d2 * e0),
                w * (d2 * e1),
            )
            if i == 0:
                p00, p01, p10, p11, p20, p21 = q00, q01, q10, q11, q20, q21
            else:
                p00 += q00
                p01 += q01
                p10 += q10
                p11 += q11
                p20 += q20
                p21 += q21
    return s00, s01, s10, s11, p00, p01, p10, p11, p20, p21


@njit(cache=True)
def landmark_sums(buf: FloatArray, r: float, b: float, lx: float, ly: float, rr: float, rb: float) -> int:
    """The sums of one range-bearing correction (module docstring) for the sighting (``r`` m, ``b`` rad) of the
    landmark at (lx, ly), R = diag(``rr``, ``rb``): the sigma points of the state, their predicted measurements
    (:func:`_rb_points`), S (+ R) and P_xz (:func:`_rb_sums`) and the innovation (r - range, bearing difference
    wrapped), into ``buf[B_S:]`` (2 x 2), ``buf[B_PXZ:]`` (row-major 3 x 2) and ``buf[B_Y:]``. Returns 0, or nonzero
    (the factorisation failed) with nothing written."""
    if sigma_points(buf) != 0:
        return 1
    z0, z1 = _rb_points(buf, lx, ly)
    s00, s01, s10, s11, p00, p01, p10, p11, p20, p21 = _rb_sums(buf, z0, z1, True)
    o = buf[B_S:B_SIGH]
    o[0], o[1], o[2], o[3] = s00 + rr, s01 + 0.0, s10 + 0.0, s11 + rb  # + R = diag(rr, rb)
    o[4], o[5], o[6], o[7], o[8], o[9] = p00, p01, p10, p11, p20, p21
    o[10], o[11] = r - z0, _wrap(b - z1)
    return 0


@njit(cache=True)
def nearest_row(buf: FloatArray, r: float, b: float, lm_xy: FloatArray, rows: IntArray, used: IntArray,
                limits: FloatArray, rr: float, rb: float, gate: float) -> int:  # fmt: skip
    """The row, among ``rows`` (ascending), of the landmark (``lm_xy`` (M, 2) m) of smallest squared Mahalanobis
    distance d2 = v^T S^-1 v of the sighting (``r`` m, ``b`` rad) through the unscented transform of the sigma
    points in ``buf`` (:func:`sigma_points` of the current state); -1 when none is inside ``gate``. The first of
    equal d2 wins.

    S and the innovation v are those of :func:`landmark_sums` (R = diag(``rr``, ``rb``)). No candidates: rows
    marked in ``used`` (nonzero), landmarks within 1e-6 m of a sigma point (the bearing is undefined), an S that
    is not positive definite, and, when ``limits`` (min range m, max range m, half field of view rad) has size 3,
    landmarks whose predicted range or bearing lies outside the sensor's limits.
    """
    prune = limits.shape[0] == 3
    sh = buf[B_SIGH : B_SIGH + 14]
    best_row, best_d2 = -1, math.inf
    for i in range(rows.shape[0]):
        row = rows[i]
        if used[row]:
            continue
        z0, z1 = _rb_points(buf, lm_xy[row, 0], lm_xy[row, 1])
        nearest = math.inf
        for k in range(N_SIG):
            nearest = min(nearest, sh[2 * k])
        if not nearest > 1e-6:
            continue
        if prune and not (limits[0] <= z0 <= limits[1] and abs(z1) <= limits[2]):
            continue
        s00, s01, _, s11, _, _, _, _, _, _ = _rb_sums(buf, z0, z1, False)
        s00, s11 = s00 + rr, s11 + rb
        det = s00 * s11 - s01 * s01
        if not det > 0.0:
            continue
        vr, vb = r - z0, _wrap(b - z1)
        d2 = (s11 * vr * vr - 2.0 * s01 * vr * vb + s00 * vb * vb) / det
        if d2 < best_d2:
            best_row, best_d2 = row, d2
    return best_row if best_d2 <= gate else -1


def sigma_weights(alpha: float, beta: float, kappa: float) -> tuple[FloatArray, FloatArray, float]:
    """(Wm (7,), Wc (7,), n + lambda) of the scaled sigma points for n = 3 (module docstring)."""
    n = N_STATE
    lam = alpha**2 * (n + kappa) - n
    c = 0.5 / (n + lam)
    wm, wc = np.full(N_SIG, c), np.full(N_SIG, c)
    wm[0] = lam / (n + lam)
    wc[0] = lam / (n + lam) + (1 - alpha**2 + beta)
    return wm, wc, lam + n


def weights_buffer(wm: FloatArray, wc: FloatArray, scale: float) -> FloatArray:
    """A float buffer (``B_END`` floats) with the weights and ``n + lambda`` set; state and Q to the caller."""
    buf = np.zeros(B_END)
    buf[B_WM : B_WM + N_SIG] = wm
    buf[B_WC : B_WC + N_SIG] = wc
    buf[B_SCALE] = scale
    return buf
