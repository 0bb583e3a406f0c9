"""pytest-benchmark: ``ekf_landmarks``' per-event path against a numba EKF of the same model.

The reference is a separate implementation of the filter's model on the office replay (seed 0): the encoder
prediction of report 003 (eq. 1-5, per-step eq. 10, additive Q) and the sequential range-bearing update in
the Joseph form, written with 3 x 3 matrix loops over a scratch array (no allocation per call) in two numba
functions, called once per event from a Python loop over the same events. It is the arithmetic with the
least Python a per-event interface can have (one compiled call per event, the event's fields as arguments),
so the ratio filter / reference is the filter's per-event overhead. ``test_ekf_over_reference_paired`` times
a replay of each in every round and reports the median of the rounds' ratios (unpaired cases drift with the
load of the shared machine).
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

from locbench.core.events import LandmarkObservations, Odometry
from locbench.core.seeding import filter_rng
from locbench.datasets.dataset import Dataset
from locbench.registry import make_dataset, make_filter

_DATA: dict[str, Dataset] = {}


def _office() -> Dataset:
    if "office" not in _DATA:
        _DATA["office"] = make_dataset("office", 0)
    return _DATA["office"]


@njit(cache=True)
def _wrap(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


@njit(cache=True)
def _matmul(a: np.ndarray, b: np.ndarray, out: np.ndarray, transpose_b: bool) -> None:
    """out = a @ b (or a @ b^T) for small matrices, written into ``out`` (no allocation)."""
    for i in range(a.shape[0]):
        for j in range(out.shape[1]):
            acc = 0.0
            for k in range(a.shape[1]):
                acc += a[i, k] * (b[j, k] if transpose_b else b[k, j])
            out[i, j] = acc


@njit(cache=True)
def _ref_predict(x: np.ndarray, P: np.ndarray, dl: float, dr: float, prm: np.ndarray, w: np.ndarray) -> None:
    """x, P <- f(x, u), F P F^T + G U G^T + Q (report 003 eq. 1-5, 10); prm = (W, k_L, k_R, q_x, q_y, q_th);
    ``w`` a (6, 3, 3) scratch array."""
    W = prm[0]
    dd, dth = 0.5 * (dl + dr), (dr - dl) / W
    h = x[2] + 0.5 * dth
    c, s = math.cos(h), math.sin(h)
    F, FP, Pn = w[0], w[1], w[2]
    F[:, :] = 0.0
    F[0, 0] = F[1, 1] = F[2, 2] = 1.0
    F[0, 2], F[1, 2] = -dd * s, dd * c
    g0 = (0.5 * c + dd * s / (2.0 * W), 0.5 * s - dd * c / (2.0 * W), -1.0 / W)  # dx'/d(delta_l)
    g1 = (0.5 * c - dd * s / (2.0 * W), 0.5 * s + dd * c / (2.0 * W), 1.0 / W)  # dx'/d(delta_r)
    u0, u1 = prm[1] ** 2 * abs(dl), prm[2] ** 2 * abs(dr)
    _matmul(F, P, FP, False)
    _matmul(FP, F, Pn, True)
    for i in range(3):
        for j in range(3):
            P[i, j] = Pn[i, j] + g0[i] * g0[j] * u0 + g1[i] * g1[j] * u1
        P[i, i] += prm[3 + i]
    x[0] += dd * c
    x[1] += dd * s
    x[2] = _wrap(x[2] + dth)


@njit(cache=True)
def _ref_update(
    x: np.ndarray,
    P: np.ndarray,
    ids: np.ndarray,
    ranges: np.ndarray,
    bearings: np.ndarray,
    lm_xy: np.ndarray,
    row_of: np.ndarray,
    R: np.ndarray,
    w: np.ndarray,
) -> None:
    """Sequential range-bearing updates (report 003 eq. 7, 9; report 001's Jacobian, corrected), Joseph form;
    ``w`` a (6, 3, 3) scratch array."""
    H, PHt, K, A, AP, Pn = w[0, :2], w[1, :, :2], w[2, :, :2], w[3], w[4], w[5]
    for k in range(ids.shape[0]):
        r, b = ranges[k], bearings[k]
        if not (math.isfinite(r) and math.isfinite(b)) or r <= 0.0:
            continue
        row = row_of[ids[k]]
        dx, dy = lm_xy[row, 0] - x[0], lm_xy[row, 1] - x[1]
        q = dx * dx + dy * dy
        if q < 1e-12:
            continue
        d = math.sqrt(q)
        H[0, 0], H[0, 1], H[0, 2] = -dx / d, -dy / d, 0.0
        H[1, 0], H[1, 1], H[1, 2] = dy / q, -dx / q, -1.0
        nu0, nu1 = r - d, _wrap(b - _wrap(math.atan2(dy, dx) - x[2]))
        _matmul(P, H, PHt, True)
        s00 = H[0, 0] * PHt[0, 0] + H[0, 1] * PHt[1, 0] + H[0, 2] * PHt[2, 0] + R[0, 0]
        s01 = H[0, 0] * PHt[0, 1] + H[0, 1] * PHt[1, 1] + H[0, 2] * PHt[2, 1]
        s11 = H[1, 0] * PHt[0, 1] + H[1, 1] * PHt[1, 1] + H[1, 2] * PHt[2, 1] + R[1, 1]
        det = s00 * s11 - s01 * s01
        for i in range(3):  # K = P H^T S^-1
            K[i, 0] = (PHt[i, 0] * s11 - PHt[i, 1] * s01) / det
            K[i, 1] = (PHt[i, 1] * s00 - PHt[i, 0] * s01) / det
        for i in range(3):
            x[i] += K[i, 0] * nu0 + K[i, 1] * nu1
            for j in range(3):
                A[i, j] = (1.0 if i == j else 0.0) - K[i, 0] * H[0, j] - K[i, 1] * H[1, j]
        x[2] = _wrap(x[2])
        _matmul(A, P, AP, False)
        _matmul(AP, A, Pn, True)
        for i in range(3):
            for j in range(3):
                P[i, j] = Pn[i, j] + K[i, 0] * K[j, 0] * R[0, 0] + K[i, 1] * K[j, 1] * R[1, 1]


def make_replays() -> tuple[Callable[[], Any], Callable[[], Any]]:
    """(filter replay, reference replay) of the office run: each resets and runs predict/update over it."""
    ds = _office()
    flt = make_filter("ekf_landmarks")
    lm = ds.world.landmarks
    assert lm is not None
    events = [e for e in ds.events if type(e) in (Odometry, LandmarkObservations)]
    rng = filter_rng("ekf_landmarks", ds.name, 0)
    sn = ds.sensors
    assert sn.wheelbase_m is not None and sn.encoder_k_left is not None and sn.encoder_k_right is not None
    assert sn.process_sigma_xy_m is None and sn.process_sigma_theta_rad is None  # Q is the filter's default
    prm = np.array([sn.wheelbase_m, sn.encoder_k_left, sn.encoder_k_right, 1e-3**2, 1e-3**2, 5e-4**2])
    R = np.diag([sn.landmark_sigma_range_m**2, sn.landmark_sigma_bearing_rad**2])
    row_of = np.full(int(lm.ids.max()) + 1, -1, dtype=np.int64)
    row_of[lm.ids] = np.arange(len(lm.ids))
    lm_xy = np.ascontiguousarray(lm.xy, dtype=np.float64)
    m0, P0 = np.asarray(ds.initial.mean, dtype=np.float64), np.asarray(ds.initial.cov, dtype=np.float64)

    def run_filter() -> Any:
        flt.reset(ds.initial, ds.world, ds.sensors, rng)
        predict, update = flt.predict, flt.update
        for ev in events:
            if type(ev) is Odometry:
                predict(ev)
            else:
                update(ev)
        return flt

    work = np.zeros((6, 3, 3))

    def run_reference() -> tuple[np.ndarray, np.ndarray]:
        x, P = m0.copy(), 0.5 * (P0 + P0.T)
        for ev in events:
            if type(ev) is Odometry:
                _ref_predict(x, P, ev.d_left, ev.d_right, prm, work)
            else:
                _ref_update(x, P, ev.ids, ev.ranges, ev.bearings, lm_xy, row_of, R, work)
        return x, P

    return run_filter, run_reference


def test_reference_is_the_filters_model() -> None:
    """The reference follows the filter's model: the same final state to rounding (the arithmetic's order
    differs, so not bit for bit), after the whole office replay."""
    run_filter, run_reference = make_replays()
    est = run_filter().estimate()
    x, P = run_reference()
    np.testing.assert_allclose(est.mean, x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(est.cov, P, rtol=1e-7, atol=1e-15)


def test_ekf_over_reference_paired(benchmark: Any, request: pytest.FixtureRequest) -> None:
    """The filter's office replay over the reference's, paired: a replay of each per round (alternating which
    goes first), the median of the rounds' ratios."""
    run_filter, run_reference = make_replays()
    run_filter()
    run_reference()
    ratios: list[float] = []

    def one_round() -> None:
        first_filter = len(ratios) % 2 == 0
        t = []
        for which in (run_filter, run_reference) if first_filter else (run_reference, run_filter):
            t0 = time.perf_counter()
            which()
            t.append(time.perf_counter() - t0)
        ratios.append(t[0] / t[1] if first_filter else t[1] / t[0])

    benchmark.pedantic(one_round, rounds=1 if benchmark.disabled else 21, iterations=1)
    if not benchmark.disabled:
        ratio = statistics.median(ratios)
        benchmark.extra_info["filter_over_reference"] = ratio
        with request.config.pluginmanager.get_plugin("capturemanager").global_and_fixture_disabled():
            print(f"\nekf_landmarks office replay: filter / numba reference {ratio:.3f} (median of {len(ratios)})")


@pytest.mark.parametrize("which", ["filter", "reference"])
def test_ekf_office_replay(benchmark: Any, which: str) -> None:
    """Each replay alone (unpaired: for the absolute times; the paired case above gives the ratio)."""
    run_filter, run_reference = make_replays()
    benchmark.pedantic(run_filter if which == "filter" else run_reference, rounds=11, iterations=1, warmup_rounds=1)
