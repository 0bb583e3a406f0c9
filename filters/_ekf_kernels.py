"""The compiled per-event arithmetic of :class:`~locbench.filters.ekf_landmarks.LandmarkEKF`: its one
implementation of the encoder prediction and of the range-bearing correction.

Prediction (report 003 eq. 1-5, 8, 10): the mean moves along the chord at the midpoint heading and the
covariance becomes F P F^T + G U G^T + Q. The step's arithmetic is :func:`locbench.filters._motion.encoder_step`,
:func:`~locbench.filters._motion.input_variances` and :func:`~locbench.filters._motion.propagate_upper`, compiled
here (registered with numba below) from the same source that :class:`~locbench.filters._motion.MotionModel` runs in
Python; a step the encoder model does not cover (an increment or a measured twist) comes from ``MotionModel.step``
and is propagated by :func:`predict_step`.

Correction (report 003 eq. 7 and 9, the sensor model of report 001 fig. 2 with its Jacobian corrected): a landmark
at (l_x, l_y) is seen at range d = |l - p| and bearing atan2(dy, dx) - theta, dx = l_x - x, dy = l_y - y,
q = d^2, R = diag(sigma_range^2, sigma_bearing^2), and

    H = [[-dx/d, -dy/d,  0],
         [ dy/q, -dx/q, -1]].

Each sighting is one Joseph-form update, K = P H^T S^-1, P+ = (I - K H) P (I - K H)^T + K R K^T (report 002
eq. 8), written out for the 3-state and the 2x2 S (inverted in closed form), the products with H's zero and
-1 entries left out. The sightings of one event are fused one at a time (:func:`update_landmarks`): those with a
known identity in their order, then those to associate, each with the nearest landmark in Mahalanobis distance
inside the chi-square gate among those not used yet (:func:`nearest_row`).

The state lives in one array ``s`` of 12 floats: the mean (x m, y m, theta rad) in ``s[0:3]`` and the
covariance, row-major, in ``s[3:12]`` (kept exactly symmetric). Numba unboxes every array argument on each
call (about 0.4 us each), more than the arithmetic of a prediction, so the filter calls the two packed entry
points :func:`predict_packed` and :func:`update_packed`: one float buffer holds the state, the update's
outputs, the constants and the map (layout :data:`BUF_STATE` ... :data:`BUF_XY`), one integer buffer the map's
ids and rows and the scratch (:func:`int_buffer`).

numba compiles IEEE double operations in source order, without fused multiply-adds unless ``fastmath`` is asked
for, and calls libm's ``sin``, ``cos``, ``atan2`` and ``sqrt``, so the kernels and the Python code that shares
their source (``MotionModel.step``, ``wrap_scalar``) compute the same numbers. numba's on-disk cache of a kernel
is keyed on this module's source alone: after editing a function it calls from :mod:`locbench.filters._motion`
or :mod:`locbench.core.geometry`, delete the ``*.nbi`` / ``*.nbc`` files under ``filters/__pycache__``.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit
from numba.extending import register_jitable

from locbench.core.geometry import wrap_scalar
from locbench.filters._motion import encoder_jacobian, encoder_step, input_variances, propagate_upper, wheel_increment

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

# s[3 + 3 i + j] = P[i][j]
_P00, _P01, _P02, _P10, _P11, _P12, _P20, _P21, _P22 = range(3, 12)

#: Offsets in the float buffer: the state (12), the update's outputs (5, see :func:`update_landmarks`), the
#: encoder parameters (9, see :func:`predict_encoder`), the update's parameters (6), the sensor limits
#: (count 0 or 3, then 3 values) and the map's (x, y) row-major from ``BUF_XY`` on.
BUF_STATE, BUF_OUT, BUF_ENC, BUF_LM, BUF_LIM, BUF_XY = 0, 12, 17, 26, 32, 36

#: :func:`sighting_rows`' codes for a sighting that has no row of its own: to associate by nearest neighbour,
#: rejected (not finite, or a range <= 0), or rejected because its identity is not in the map.
ASSOCIATE, INVALID, NOT_IN_MAP = -1, -2, -3

#: :func:`locbench.core.geometry.wrap_scalar` compiled (an angle to (-pi, pi]), for the kernels of the filters.
_wrap = njit(cache=True, inline="always")(wrap_scalar)

# The motion model's plain-float functions, compiled where a kernel calls them (numba's ``register_jitable``: the
# functions stay as they are for Python callers). Registered once, here: the other kernel modules import this one.
for _fn in (wheel_increment, input_variances, encoder_jacobian, encoder_step, propagate_upper):
    register_jitable(inline="always")(_fn)


@njit(cache=True, inline="always")
def _propagate(s: FloatArray, f02: float, f12: float, n00: float, n01: float, n02: float, n11: float, n12: float,
               n22: float) -> None:  # fmt: skip
    """F P F^T + N on the covariance of ``s`` in place (:func:`~locbench.filters._motion.propagate_upper`; F the
    identity but for F[0, 2] = ``f02`` and F[1, 2] = ``f12``, N's upper triangle ``n..``)."""
    q00, q01, q02, q11, q12, q22 = propagate_upper(
        s[_P00], s[_P01], s[_P02], s[_P11], s[_P12], s[_P22], f02, f12, n00, n01, n02, n11, n12, n22
    )
    s[_P00], s[_P01], s[_P02] = q00, q01, q02
    s[_P10], s[_P11], s[_P12] = q01, q11, q12
    s[_P20], s[_P21], s[_P22] = q02, q12, q22


@njit(cache=True, inline="always")
def _finite(s: FloatArray) -> bool:
    """Whether the state is finite: the mean's sum and the sum of the covariance's row sums (a non-finite entry
    makes them non-finite; an overflow of the sums alone does too, and then the state is beyond use anyway)."""
    ok = math.isfinite(s[0] + s[1] + s[2])
    r0 = 0.0 + s[_P00] + s[_P01] + s[_P02]
    r1 = 0.0 + s[_P10] + s[_P11] + s[_P12]
    r2 = 0.0 + s[_P20] + s[_P21] + s[_P22]
    return ok and math.isfinite(r0 + r1 + r2)


@njit(cache=True)
def state_finite(s: FloatArray) -> bool:
    """Whether the state is finite (the test of :func:`_finite`)."""
    return _finite(s)


@njit(cache=True)
def predict_encoder(s: FloatArray, dl: float, dr: float, prm: FloatArray) -> bool:
    """One encoder prediction (report 003 eq. 1-5, 10) with the additive Q (eq. 8) on ``s``; whether it is finite.

    ``dl``, ``dr`` are the wheel travel (m). ``prm`` = (W m, k_L, k_R sqrt(m), cumulative 0/1, travelled left,
    travelled right m, q_x, q_y, q_theta): eq. 10's reading and the distances travelled so far, which are advanced
    in place (as :class:`~locbench.filters._motion.MotionModel` keeps them).
    """
    vl, vr = input_variances(dl, dr, prm[1], prm[2], prm[3] != 0.0, prm[4], prm[5])
    prm[4] += abs(dl)
    prm[5] += abs(dr)
    x, y, th = s[0], s[1], s[2]
    ex, ey, dth, n00, n01, n02, n11, n12, n22 = encoder_step(th, dl, dr, prm[0], vl, vr)
    s[0], s[1], s[2] = x + ex, y + ey, _wrap(th + dth)
    _propagate(s, -ey, ex, n00 + prm[6], n01, n02, n11 + prm[7], n12, n22 + prm[8])
    return _finite(s)


@njit(cache=True)
def predict_step(s: FloatArray, pose: FloatArray, f02: float, f12: float, noise: FloatArray, q: FloatArray) -> bool:
    """A prediction whose step :class:`~locbench.filters._motion.MotionModel` computed (an increment or a measured
    twist): the new mean ``pose`` (3,), F's entries, the noise's upper triangle (6,) plus Q's diagonal ``q`` (3,)
    (report 003 eq. 8); whether the state is finite."""
    s[0], s[1], s[2] = pose[0], pose[1], pose[2]
    _propagate(s, f02, f12, noise[0] + q[0], noise[1], noise[2], noise[3] + q[1], noise[4], noise[5] + q[2])
    return _finite(s)


@njit(cache=True, inline="always")
def _innovation(s: FloatArray, r: float, b: float, lx: float, ly: float, rr: float, rb: float
                ) -> tuple[bool, float, float, float, float, float, float, float, float, float, float]:  # fmt: skip
    """The range-bearing innovation of the landmark at (lx, ly) (report 003 eq. 7, report 001 fig. 2 corrected):
    (valid, v_range, v_bearing, h00, h01, h10, h11, det S, d2, predicted range, predicted bearing).

    H's entries are those of the module docstring (h02 = 0, h12 = -1 are implied), S = H P H^T + R with
    R = diag(``rr``, ``rb``), d2 = v^T S^-1 v (inf unless det S > 0); invalid on top of the landmark, where the
    bearing is undefined.
    """
    x, y, th = s[0], s[1], s[2]
    dx, dy = lx - x, ly - y
    q = dx * dx + dy * dy
    if q < 1e-12:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, math.inf, 0.0, 0.0
    d = math.sqrt(q)
    h00, h01 = -dx / d, -dy / d
    h10, h11 = dy / q, -dx / q
    pb = _wrap(math.atan2(dy, dx) - th)
    vr = r - d
    vb = _wrap(b - pb)
    p00, p01, p02 = s[_P00], s[_P01], s[_P02]
    p11, p12, p22 = s[_P11], s[_P12], s[_P22]
    s00 = p00 * h00 * h00 + 2.0 * p01 * h00 * h01 + p11 * h01 * h01 + rr
    ub0 = p00 * h10 + p01 * h11 - p02
    ub1 = p01 * h10 + p11 * h11 - p12
    ub2 = p02 * h10 + p12 * h11 - p22
    s01 = h00 * ub0 + h01 * ub1
    s11 = h10 * ub0 + h11 * ub1 - ub2 + rb
    det = s00 * s11 - s01 * s01
    d2 = (s11 * vr * vr - 2.0 * s01 * vr * vb + s00 * vb * vb) / det if det > 0.0 else math.inf
    return True, vr, vb, h00, h01, h10, h11, det, d2, d, pb


@njit(cache=True)
def correct_landmark(s: FloatArray, r: float, b: float, lx: float, ly: float, rr: float, rb: float,
                     gate: float) -> float:  # fmt: skip
    """Fuse the sighting (range ``r`` m, bearing ``b`` rad) of the landmark at (lx, ly) into ``s``: one Joseph-form
    update (module docstring; R = diag(``rr``, ``rb``)). Returns its NIS, or NaN with ``s`` unchanged when the
    NIS is not inside ``gate`` or the innovation is invalid (an accepted NIS is never NaN)."""
    ok, vr, vb, h00, h01, h10, h11, det, d2, _, _ = _innovation(s, r, b, lx, ly, rr, rb)
    if not ok or not d2 <= gate:
        return math.nan
    p00, p01, p02 = s[_P00], s[_P01], s[_P02]
    p11, p12, p22 = s[_P11], s[_P12], s[_P22]
    # P H^T, column of the range row (r) and of the bearing row (b).
    r0, r1, r2 = p00 * h00 + p01 * h01, p01 * h00 + p11 * h01, p02 * h00 + p12 * h01
    b0, b1, b2 = p00 * h10 + p01 * h11 - p02, p01 * h10 + p11 * h11 - p12, p02 * h10 + p12 * h11 - p22
    s00 = h00 * r0 + h01 * r1 + rr
    s01 = h00 * b0 + h01 * b1
    s11 = h10 * b0 + h11 * b1 - b2 + rb
    i00, i01, i11 = s11 / det, -s01 / det, s00 / det
    k00, k01 = r0 * i00 + b0 * i01, r0 * i01 + b0 * i11
    k10, k11 = r1 * i00 + b1 * i01, r1 * i01 + b1 * i11
    k20, k21 = r2 * i00 + b2 * i01, r2 * i01 + b2 * i11
    x, y, th = s[0], s[1], s[2]
    s[0], s[1], s[2] = x + k00 * vr + k01 * vb, y + k10 * vr + k11 * vb, _wrap(th + k20 * vr + k21 * vb)
    # Joseph form P' = A P A^T + K R K^T with A = I - K H.
    a00, a01, a02 = 1.0 - k00 * h00 - k01 * h10, -k00 * h01 - k01 * h11, k01
    a10, a11, a12 = -k10 * h00 - k11 * h10, 1.0 - k10 * h01 - k11 * h11, k11
    a20, a21, a22 = -k20 * h00 - k21 * h10, -k20 * h01 - k21 * h11, 1.0 + k21
    b00 = a00 * p00 + a01 * p01 + a02 * p02
    b01 = a00 * p01 + a01 * p11 + a02 * p12
    b02 = a00 * p02 + a01 * p12 + a02 * p22
    b10 = a10 * p00 + a11 * p01 + a12 * p02
    b11 = a10 * p01 + a11 * p11 + a12 * p12
    b12 = a10 * p02 + a11 * p12 + a12 * p22
    b20 = a20 * p00 + a21 * p01 + a22 * p02
    b21 = a20 * p01 + a21 * p11 + a22 * p12
    b22 = a20 * p02 + a21 * p12 + a22 * p22
    q00 = b00 * a00 + b01 * a01 + b02 * a02 + k00 * k00 * rr + k01 * k01 * rb
    q01 = b00 * a10 + b01 * a11 + b02 * a12 + k00 * k10 * rr + k01 * k11 * rb
    q02 = b00 * a20 + b01 * a21 + b02 * a22 + k00 * k20 * rr + k01 * k21 * rb
    q11 = b10 * a10 + b11 * a11 + b12 * a12 + k10 * k10 * rr + k11 * k11 * rb
    q12 = b10 * a20 + b11 * a21 + b12 * a22 + k10 * k20 * rr + k11 * k21 * rb
    q22 = b20 * a20 + b21 * a21 + b22 * a22 + k20 * k20 * rr + k21 * k21 * rb
    s[_P00], s[_P01], s[_P02] = q00, q01, q02
    s[_P10], s[_P11], s[_P12] = q01, q11, q12
    s[_P20], s[_P21], s[_P22] = q02, q12, q22
    return d2


@njit(cache=True)
def nearest_row(s: FloatArray, r: float, b: float, lm_xy: FloatArray, rows: IntArray, used: IntArray,
                limits: FloatArray, rr: float, rb: float, gate: float) -> int:  # fmt: skip
    """The row, among ``rows`` (ascending), of the landmark (``lm_xy`` (M, 2) m) of smallest squared Mahalanobis
    distance d2 to the sighting (r m, b rad), if inside ``gate``; else -1. The first of equal d2 wins.

    Rows marked in ``used`` (nonzero) are no candidates, nor, when ``limits`` (min range m, max range m, half
    field of view rad) has size 3, the landmarks predicted outside the sensor's limits.
    """
    best_row, best_d2 = -1, math.inf
    prune = limits.shape[0] == 3
    for i in range(rows.shape[0]):
        row = rows[i]
        if used[row]:
            continue
        ok, _, _, _, _, _, _, _, d2, d, pb = _innovation(s, r, b, lm_xy[row, 0], lm_xy[row, 1], rr, rb)
        if not ok:
            continue
        if prune and not (limits[0] <= d <= limits[1] and abs(pb) <= limits[2]):
            continue
        if d2 < best_d2:
            best_row, best_d2 = row, d2
    return best_row if best_d2 <= gate else -1


@njit(cache=True)
def sighting_rows(ids: IntArray, ranges: FloatArray, bearings: FloatArray, map_ids: IntArray, map_rows: IntArray,
                  use_ids: bool, rows: IntArray) -> None:  # fmt: skip
    """Sort the sightings of one event for the sequential update: ``rows[k]`` is the map row of sighting k's
    identity, or :data:`ASSOCIATE` (``use_ids`` False, or ``UNKNOWN_ID``), :data:`INVALID` (range or bearing not
    finite, or a range <= 0) or :data:`NOT_IN_MAP`. ``map_ids`` are the map's ids sorted, ``map_rows`` their rows.

    The filters fuse the sightings with a row in their order, then associate the others in theirs, each with the
    landmarks not fused yet (the association sees the state corrected by the identified landmarks).
    """
    for k in range(ids.shape[0]):
        r, b = ranges[k], bearings[k]
        if not (math.isfinite(r) and math.isfinite(b)) or r <= 0.0:
            rows[k] = INVALID
            continue
        ident = ids[k]
        if not use_ids or ident == -1:  # UNKNOWN_ID
            rows[k] = ASSOCIATE
            continue
        j = np.searchsorted(map_ids, ident)
        rows[k] = map_rows[j] if j < map_ids.shape[0] and map_ids[j] == ident else NOT_IN_MAP


@njit(cache=True)
def update_landmarks(s: FloatArray, ids: IntArray, ranges: FloatArray, bearings: FloatArray, lm_xy: FloatArray,
                     map_ids: IntArray, map_rows: IntArray, all_rows: IntArray, used: IntArray,
                     limits: FloatArray, prm: FloatArray, rows: IntArray, out: FloatArray) -> int:  # fmt: skip
    """Fuse one event's sightings (module docstring): :func:`sighting_rows` into ``rows``, the identified ones
    with :func:`correct_landmark`, then (with ``prm[5]`` != 0) those to associate by :func:`nearest_row` over
    every landmark (``all_rows``).

    ``used`` (M,) is cleared and then marks the rows fused (1). ``prm`` = (var_range, var_bearing, gate, gate known
    ids 0/1, use ids 0/1, associate here 0/1). ``out`` receives (NIS sum, accepted, rejected, ids not in the map,
    finite 0/1). Returns the number of sightings left to associate (``rows[k]`` = :data:`ASSOCIATE`) when
    ``prm[5]`` is 0 (the caller takes their candidates from a k-d tree); else 0.
    """
    rr, rb, gate = prm[0], prm[1], prm[2]
    gate_k = gate if prm[3] != 0.0 else math.inf
    used[:] = 0
    sighting_rows(ids, ranges, bearings, map_ids, map_rows, prm[4] != 0.0, rows)
    nis, acc, rej, missing, n_def = 0.0, 0, 0, 0, 0
    for k in range(ids.shape[0]):
        row = rows[k]
        if row == ASSOCIATE:
            n_def += 1
            continue
        if row < 0:
            rej += 1
            missing += row == NOT_IN_MAP
            continue
        d2 = correct_landmark(s, ranges[k], bearings[k], lm_xy[row, 0], lm_xy[row, 1], rr, rb, gate_k)
        if math.isnan(d2):
            rej += 1
        else:
            nis += d2
            acc += 1
            used[row] = 1
    if prm[5] != 0.0 and n_def:
        for k in range(ids.shape[0]):
            if rows[k] != ASSOCIATE:
                continue
            r, b = ranges[k], bearings[k]
            row = nearest_row(s, r, b, lm_xy, all_rows, used, limits, rr, rb, gate)
            d2 = math.nan if row < 0 else correct_landmark(s, r, b, lm_xy[row, 0], lm_xy[row, 1], rr, rb, gate)
            if math.isnan(d2):
                rej += 1
            else:
                nis += d2
                acc += 1
                used[row] = 1
        n_def = 0
    out[0], out[1], out[2], out[3], out[4] = nis, acc, rej, missing, 1.0 if _finite(s) else 0.0
    return n_def


def float_buffer(lm_xy: FloatArray, encoder: FloatArray, landmark: FloatArray, limits: FloatArray) -> FloatArray:
    """The float buffer of :func:`predict_packed` and :func:`update_packed` (layout at ``BUF_STATE``); the
    state is left to the caller (``buf[:12]``)."""
    m = lm_xy.shape[0]
    buf = np.zeros(BUF_XY + 2 * m)
    buf[BUF_ENC:BUF_LM] = encoder
    buf[BUF_LM:BUF_LIM] = landmark
    buf[BUF_LIM] = limits.shape[0]
    buf[BUF_LIM + 1 : BUF_LIM + 1 + limits.shape[0]] = limits
    buf[BUF_XY:] = lm_xy.reshape(-1)
    return buf


def int_buffer(map_ids: IntArray, map_rows: IntArray, capacity: int) -> IntArray:
    """The integer buffer of :func:`update_packed`: the map's ids sorted, their rows, every row, the used
    marks (M each), then the rows of up to ``capacity`` sightings (:func:`sighting_rows`)."""
    m = map_ids.shape[0]
    return np.concatenate([map_ids, map_rows, np.arange(m, dtype=np.int64), np.zeros(m + capacity, dtype=np.int64)])


@njit(cache=True)
def predict_packed(buf: FloatArray, dl: float, dr: float) -> bool:
    """:func:`predict_encoder` on the float buffer."""
    return predict_encoder(buf[BUF_STATE:BUF_OUT], dl, dr, buf[BUF_ENC:BUF_LM])


@njit(cache=True)
def update_packed(buf: FloatArray, ids: IntArray, ranges: FloatArray, bearings: FloatArray, ibuf: IntArray) -> int:
    """:func:`update_landmarks` on the two buffers (``ibuf`` must hold the rows of ``len(ids)`` sightings)."""
    m = (buf.shape[0] - BUF_XY) // 2
    n_lim = int(buf[BUF_LIM])
    return update_landmarks(
        buf[BUF_STATE:BUF_OUT], ids, ranges, bearings, buf[BUF_XY:].reshape((m, 2)), ibuf[:m], ibuf[m : 2 * m],
        ibuf[2 * m : 3 * m], ibuf[3 * m : 4 * m], buf[BUF_LIM + 1 : BUF_LIM + 1 + n_lim], buf[BUF_LM:BUF_LIM],
        ibuf[4 * m :], buf[BUF_OUT:BUF_ENC],
    )  # fmt: skip
