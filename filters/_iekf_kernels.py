"""The compiled correction of :class:`~locbench.filters.iekf_landmarks.LandmarkIEKF`: the EKF's gain and Joseph
step, then the invariant EKF's retraction on SE(2).

The filter keeps its belief in the EKF's buffer layout (:mod:`locbench.filters._ekf_kernels`: mean (x, y, theta)
and the world-frame covariance P_w, row-major), so that the prediction, the Mahalanobis distances of the
association and the estimate are the EKF's. Its own covariance is the left-invariant one, P_b over the body-frame
error xi of X_true = X Exp(xi); the two are tied by P_w = T P_b T^T, T = blockdiag(R(theta), 1) (first order:
X Exp(xi) moves the position by R(theta) xi_v and the heading by xi_w).

One correction (Barrau and Bonnabel 2017, the invariant EKF's update; gtsam's ``ManifoldEKF`` update without its
reset) in the body frame is H_b = H_w T, S = H_b P_b H_b^T + R (= H_w P_w H_w^T + R), K_b = P_b H_b^T S^-1 = T^-1 K_w,
dxi = K_b v, X+ = X Exp(dxi) and P_b+ = (I - K_b H_b) P_b (I - K_b H_b)^T + K_b R K_b^T = T^-1 P_J T^-T, where K_w
and P_J are the EKF's gain and Joseph covariance. With d = K_w v = (d_x, d_y, w) the EKF's world-frame step:

    Exp(xi_v, w) = (V(w) xi_v, w),     V(w) = [[sin w / w, -(1 - cos w) / w], [(1 - cos w) / w, sin w / w]],
    p+ = p + R(theta) V(w) R(theta)^T (d_x, d_y) = p + V(w) (d_x, d_y)       (V commutes with rotations),
    theta+ = theta + w,
    P_w+ = T(theta+) P_b+ T(theta+)^T = G P_J G^T,     G = blockdiag(R(w), 1).

So :func:`retract` takes a state the EKF's correction has just left (the additive step already applied) and the
pose before it, and replaces the step by the group's: the position moves along the arc V(w) d instead of the chord
d, and the covariance turns with the heading correction w.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit

from locbench.filters import _ekf_kernels as ekf

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

_ASSOCIATE = ekf.ASSOCIATE
_NOT_IN_MAP = ekf.NOT_IN_MAP
_ekf_correct = ekf.correct_landmark
_nearest = ekf.nearest_row
_rows_of = ekf.sighting_rows
_wrap = ekf._wrap
_finite = ekf._finite


@njit(cache=True, inline="always")
def _v_factors(w: float) -> tuple[float, float]:
    """(sin w / w, (1 - cos w) / w) of Exp's V(w) (module docstring), the second as 2 sin^2(w / 2) / w: 1 - cos w
    would cancel to a relative error of about 1e-16 / w^2 at small w."""
    if w == 0.0:
        return 1.0, 0.0
    h = math.sin(0.5 * w)
    return math.sin(w) / w, 2.0 * h * h / w


@njit(cache=True)
def retract(s: FloatArray, x0: float, y0: float, th0: float) -> None:
    """Turn the EKF's additive correction of ``s`` from the pose (x0 m, y0 m, th0 rad) into X Exp(dxi) and turn
    the covariance with it (module docstring). The heading step w is wrap(theta - th0), the step the EKF made
    (its gain's heading component, below pi for any sane belief)."""
    dx, dy = s[0] - x0, s[1] - y0
    w = _wrap(s[2] - th0)
    a, b = _v_factors(w)
    s[0] = x0 + a * dx - b * dy
    s[1] = y0 + b * dx + a * dy
    c, n = math.cos(w), math.sin(w)
    p00, p01, p02, p11, p12 = s[3], s[4], s[5], s[7], s[8]
    # G P G^T with G = blockdiag(R(w), 1): the position block turns twice, its column with theta once
    q00 = c * c * p00 - 2.0 * c * n * p01 + n * n * p11
    q01 = c * n * (p00 - p11) + (c * c - n * n) * p01
    q11 = n * n * p00 + 2.0 * c * n * p01 + c * c * p11
    q02 = c * p02 - n * p12
    q12 = n * p02 + c * p12
    s[3], s[4], s[5] = q00, q01, q02
    s[6], s[7], s[8] = q01, q11, q12
    s[9], s[10] = q02, q12


@njit(cache=True)
def correct_landmark(s: FloatArray, r: float, b: float, lx: float, ly: float, rr: float, rb: float,
                     gate: float) -> float:  # fmt: skip
    """One invariant correction with the sighting (``r`` m, ``b`` rad) of the landmark at (lx, ly): the EKF's
    gated gain and Joseph step (:func:`locbench.filters._ekf_kernels.correct_landmark`), then :func:`retract`.
    Its NIS, or NaN with ``s`` unchanged (gated out or invalid)."""
    x0, y0, th0 = s[0], s[1], s[2]
    d2 = _ekf_correct(s, r, b, lx, ly, rr, rb, gate)
    if not math.isnan(d2):
        retract(s, x0, y0, th0)
    return d2


@njit(cache=True)
def update_packed(buf: FloatArray, ids: IntArray, ranges: FloatArray, bearings: FloatArray, ibuf: IntArray) -> int:
    """One event's sightings on the EKF's two buffers (:func:`locbench.filters._ekf_kernels.update_packed`'s
    layout, outputs and return value), each fused by :func:`correct_landmark`: the identified ones in their
    order (pass 0), then those to associate with the nearest unused landmark (pass 1, when the buffer says
    the association is done here; the distances are the EKF's, as S is the same)."""
    m = (buf.shape[0] - ekf.BUF_XY) // 2
    s = buf[ekf.BUF_STATE : ekf.BUF_OUT]
    xy = buf[ekf.BUF_XY :].reshape((m, 2))
    prm = buf[ekf.BUF_LM : ekf.BUF_LIM]
    lims = buf[ekf.BUF_LIM + 1 : ekf.BUF_LIM + 1 + int(buf[ekf.BUF_LIM])]
    all_rows, used, rows = ibuf[2 * m : 3 * m], ibuf[3 * m : 4 * m], ibuf[4 * m :]
    rr, rb, gate = prm[0], prm[1], prm[2]
    used[:] = 0
    _rows_of(ids, ranges, bearings, ibuf[:m], ibuf[m : 2 * m], prm[4] != 0.0, rows)
    nis, acc, rej, missing, left = 0.0, 0, 0, 0, 0
    for phase in range(2):
        g = gate if phase == 1 or prm[3] != 0.0 else math.inf
        for k in range(ids.shape[0]):
            row = rows[k]
            if phase == 0 and row == _ASSOCIATE:
                left += 1
            elif phase == 0 and row < 0:
                rej += 1
                missing += row == _NOT_IN_MAP
            elif (phase == 0) == (row != _ASSOCIATE):
                if phase == 1:
                    row = _nearest(s, ranges[k], bearings[k], xy, all_rows, used, lims, rr, rb, gate)
                d2 = math.nan if row < 0 else correct_landmark(s, ranges[k], bearings[k], xy[row, 0], xy[row, 1],
                                                               rr, rb, g)  # fmt: skip
                fused = not math.isnan(d2)
                if fused:
                    nis += d2
                    used[row] = 1
                acc += fused
                rej += not fused
        if prm[5] == 0.0 or left == 0:
            break  # nothing to associate, or the caller associates with its k-d tree
        left = 0
    out = buf[ekf.BUF_OUT : ekf.BUF_ENC]
    out[0], out[1], out[2], out[3], out[4] = nis, acc, rej, missing, 1.0 if _finite(s) else 0.0
    return left
