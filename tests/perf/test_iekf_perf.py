"""pytest-benchmark: ``iekf_landmarks``' per-event path against a numba invariant EKF written in its own frame.

The reference is a separate implementation of the filter on the office replay (seed 0), in the body frame the
invariant EKF is defined in (Barrau and Bonnabel 2017): the pose X composed with the encoder increment U, the
left-invariant covariance propagated as Ad_{U^-1} P Ad_{U^-1}^T + Q_b, each range-bearing sighting fused with the
body-frame Jacobian in the Joseph form and X Exp(K v), with 3 x 3 matrix loops over a scratch array in two numba
functions called once per event, as ``test_ekf_perf.py``'s EKF reference. The filter keeps the EKF's world-frame
layout instead (``filters/iekf_landmarks.py``), so the reference also checks that layout: the two agree on the
final state to rounding. ``test_iekf_over_reference_paired`` reports the median of the rounds' ratios
filter / reference (paired rounds: the shared machine's load moves both alike).
"""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from numba import njit
from test_ekf_perf import _matmul, _office, _wrap

from locbench.core.events import LandmarkObservations, Odometry
from locbench.core.seeding import filter_rng
from locbench.registry import make_filter


@njit(cache=True)
def _rot(th: float, T: np.ndarray) -> None:
    """T = blockdiag(R(th), 1)."""
    c, s = math.cos(th), math.sin(th)
    T[:, :] = 0.0
    T[0, 0], T[0, 1], T[1, 0], T[1, 1], T[2, 2] = c, -s, s, c, 1.0


@njit(cache=True)
def _sandwich(A: np.ndarray, P: np.ndarray, w: np.ndarray, out: np.ndarray) -> None:
    """out = A P A^T (``w`` a 3 x 3 scratch)."""
    _matmul(A, P, w, False)
    _matmul(w, A, out, True)


@njit(cache=True)
def _ref_predict(x: np.ndarray, P: np.ndarray, dl: float, dr: float, prm: np.ndarray, w: np.ndarray) -> None:
    """X <- X U, P <- Ad_{U^-1} P Ad_{U^-1}^T + T+^T (G U G^T + Q) T+ (report 003 eq. 1-5, 10 for U and its
    noise); prm = (W, k_L, k_R, q_x, q_y, q_th); ``w`` a (6, 3, 3) scratch array."""
    W = prm[0]
    dd, dth = 0.5 * (dl + dr), (dr - dl) / W
    ux, uy = dd * math.cos(0.5 * dth), dd * math.sin(0.5 * dth)  # the midpoint chord in the body frame
    c, s = math.cos(dth), math.sin(dth)
    Ad, N, T, tmp, out = w[0], w[1], w[2], w[3], w[4]
    # U^-1 = (R(dth)^T, -R(dth)^T u); Ad of a pose (x, y, th) = [[c, -s, y], [s, c, -x], [0, 0, 1]]
    ix, iy = -(c * ux + s * uy), -(-s * ux + c * uy)
    Ad[:, :] = 0.0
    Ad[0, 0], Ad[0, 1], Ad[0, 2] = c, s, iy
    Ad[1, 0], Ad[1, 1], Ad[1, 2] = -s, c, -ix
    Ad[2, 2] = 1.0
    h = x[2] + 0.5 * dth
    ch, sh = math.cos(h), math.sin(h)
    g0 = (0.5 * ch + dd * sh / (2.0 * W), 0.5 * sh - dd * ch / (2.0 * W), -1.0 / W)  # dX+/d(delta_l), world
    g1 = (0.5 * ch - dd * sh / (2.0 * W), 0.5 * sh + dd * ch / (2.0 * W), 1.0 / W)
    u0, u1 = prm[1] ** 2 * abs(dl), prm[2] ** 2 * abs(dr)
    for i in range(3):
        for j in range(3):
            N[i, j] = g0[i] * g0[j] * u0 + g1[i] * g1[j] * u1
        N[i, i] += prm[3 + i]
    ct, st = math.cos(x[2]), math.sin(x[2])
    x[0] += ct * ux - st * uy
    x[1] += st * ux + ct * uy
    x[2] = _wrap(x[2] + dth)
    _rot(-x[2], T)  # T+^-1 = T+^T: the world-frame noise into the new body frame
    _sandwich(T, N, tmp, out)
    _sandwich(Ad, P, tmp, N)
    for i in range(3):
        for j in range(3):
            P[i, j] = N[i, j] + out[i, j]


@njit(cache=True)
def _ref_update(x: np.ndarray, P: np.ndarray, ids: np.ndarray, ranges: np.ndarray, bearings: np.ndarray,
                lm_xy: np.ndarray, row_of: np.ndarray, R: np.ndarray, w: np.ndarray) -> None:  # fmt: skip
    """Sequential sightings: body-frame position p = R(theta)^T (l - t), H_b = [[-p_x/|p|, -p_y/|p|, 0],
    [p_y/|p|^2, -p_x/|p|^2, -1]], the Joseph form and X <- X Exp(K v); ``w`` a (6, 3, 3) scratch array."""
    H, PHt, K, A, AP, Pn = w[0, :2], w[1, :, :2], w[2, :, :2], w[3], w[4], w[5]
    for k in range(ids.shape[0]):
        r, b = ranges[k], bearings[k]
        if not (math.isfinite(r) and math.isfinite(b)) or r <= 0.0:
            continue
        row = row_of[ids[k]]
        ct, st = math.cos(x[2]), math.sin(x[2])
        dx, dy = lm_xy[row, 0] - x[0], lm_xy[row, 1] - x[1]
        px, py = ct * dx + st * dy, -st * dx + ct * dy
        q = px * px + py * py
        if q < 1e-12:
            continue
        d = math.sqrt(q)
        H[0, 0], H[0, 1], H[0, 2] = -px / d, -py / d, 0.0
        H[1, 0], H[1, 1], H[1, 2] = py / q, -px / q, -1.0
        nu0, nu1 = r - d, _wrap(b - math.atan2(py, px))
        _matmul(P, H, PHt, True)
        s00 = H[0, 0] * PHt[0, 0] + H[0, 1] * PHt[1, 0] + R[0, 0]
        s01 = H[0, 0] * PHt[0, 1] + H[0, 1] * PHt[1, 1]
        s11 = H[1, 0] * PHt[0, 1] + H[1, 1] * PHt[1, 1] - PHt[2, 1] + R[1, 1]
        det = s00 * s11 - s01 * s01
        for i in range(3):
            K[i, 0] = (PHt[i, 0] * s11 - PHt[i, 1] * s01) / det
            K[i, 1] = (PHt[i, 1] * s00 - PHt[i, 0] * s01) / det
        v0 = K[0, 0] * nu0 + K[0, 1] * nu1
        v1 = K[1, 0] * nu0 + K[1, 1] * nu1
        om = K[2, 0] * nu0 + K[2, 1] * nu1
        if om == 0.0:
            a, c1 = 1.0, 0.0
        else:
            a, c1 = math.sin(om) / om, 2.0 * math.sin(0.5 * om) ** 2 / om
        ex, ey = a * v0 - c1 * v1, c1 * v0 + a * v1  # Exp's translation V(om) v
        x[0] += ct * ex - st * ey
        x[1] += st * ex + ct * ey
        x[2] = _wrap(x[2] + om)
        for i in range(3):
            for j in range(3):
                A[i, j] = (1.0 if i == j else 0.0) - K[i, 0] * H[0, j] - K[i, 1] * H[1, j]
        _sandwich(A, P, AP, Pn)
        for i in range(3):
            for j in range(3):
                P[i, j] = Pn[i, j] + K[i, 0] * K[j, 0] * R[0, 0] + K[i, 1] * K[j, 1] * R[1, 1]


def make_replays() -> tuple[Callable[[], Any], Callable[[], tuple[np.ndarray, np.ndarray]]]:
    """(filter replay, reference replay) of the office run; the reference returns (mean, world-frame cov)."""
    ds = _office()
    flt = make_filter("iekf_landmarks")
    lm, sn = ds.world.landmarks, ds.sensors
    assert lm is not None and sn.wheelbase_m is not None
    events = [e for e in ds.events if type(e) in (Odometry, LandmarkObservations)]
    rng = filter_rng("iekf_landmarks", ds.name, 0)
    # the filter's defaults on office: its encoder constants, its landmark noise and the default Q per step
    prm = np.array([sn.wheelbase_m, sn.encoder_k_left, sn.encoder_k_right, 1e-6, 1e-6, 2.5e-7])
    R = np.diag(np.square([sn.landmark_sigma_range_m, sn.landmark_sigma_bearing_rad]))
    row_of = np.zeros(int(lm.ids.max()) + 1, dtype=np.int64)
    row_of[lm.ids] = range(len(lm.ids))
    lm_xy = np.array(lm.xy, dtype=np.float64, order="C")
    work, T = np.zeros((6, 3, 3)), np.zeros((3, 3))

    def run_filter() -> Any:
        flt.reset(ds.initial, ds.world, ds.sensors, rng)
        call = {Odometry: flt.predict, LandmarkObservations: flt.update}
        for ev in events:
            call[type(ev)](ev)
        return flt

    def run_reference() -> tuple[np.ndarray, np.ndarray]:
        x = np.array(ds.initial.mean, dtype=np.float64)
        _rot(x[2], T)
        P = T.T @ (0.5 * (ds.initial.cov + ds.initial.cov.T)) @ T  # the initial covariance in the body frame
        for ev in events:
            if isinstance(ev, Odometry):
                _ref_predict(x, P, ev.d_left, ev.d_right, prm, work)
            else:
                _ref_update(x, P, ev.ids, ev.ranges, ev.bearings, lm_xy, row_of, R, work)
        _rot(x[2], T)
        return x, T @ P @ T.T

    return run_filter, run_reference


def test_reference_is_the_filters_model() -> None:
    """The body-frame reference and the filter's world-frame layout end the office replay in the same state, to
    rounding (different arithmetic: not bit for bit)."""
    run_filter, run_reference = make_replays()
    est = run_filter().estimate()
    x, P = run_reference()
    np.testing.assert_allclose(est.mean, x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(est.cov, P, rtol=1e-7, atol=1e-15)


def _paired_ratios(a: Callable[[], Any], b: Callable[[], Any], ratios: list[float]) -> Callable[[], None]:
    """One round: a replay of each, alternating which goes first; appends time(a) / time(b) to ``ratios``."""

    def one_round() -> None:
        order = (a, b) if len(ratios) % 2 == 0 else (b, a)
        took = {}
        for which in order:
            t0 = time.perf_counter()
            which()
            took[which] = time.perf_counter() - t0
        ratios.append(took[a] / took[b])

    return one_round


def test_iekf_over_reference_paired(benchmark: Any, request: pytest.FixtureRequest) -> None:
    """The filter's office replay over the reference's, paired, the median of the rounds' ratios."""
    run_filter, run_reference = make_replays()
    run_filter()
    run_reference()
    ratios: list[float] = []
    benchmark.pedantic(
        _paired_ratios(run_filter, run_reference, ratios), rounds=1 if benchmark.disabled else 21, iterations=1
    )
    if not benchmark.disabled:
        ratio = statistics.median(ratios)
        benchmark.extra_info["filter_over_reference"] = ratio
        with request.config.pluginmanager.get_plugin("capturemanager").global_and_fixture_disabled():
            print(f"\niekf_landmarks office replay: filter / numba reference {ratio:.3f} (median of {len(ratios)})")
