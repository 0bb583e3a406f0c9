"""pytest-benchmark: particle throughput of one predict + update step of ``pf`` on the office world, and the
same step as one compiled call (the fused reference).

``nox -s perf`` (``pytest tests/perf --benchmark-only``) measures 1e3, 1e4 and 1e5 particles with the
landmark model and with the 60-beam likelihood field, stores particles/s (from the median step time) in
``benchmark.extra_info`` and prints one summary line per case. The ``fused`` cases run the landmark step of
the filter as one numba function that calls the filter's own kernels (motion with the estimate's first
pass, weighting, systematic resampling and roughening, the estimate): the same arithmetic without the
filter's Python around it, so the ratio filter / fused is the filter's per-event overhead. In the normal
test run (``--benchmark-disable``) each case runs once as a smoke test and the 1e5 cases are skipped.
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

from locbench.core.events import LandmarkObservations, LaserScan, Odometry
from locbench.datasets.dataset import Dataset
from locbench.filters import pf as pf_mod
from locbench.filters._motion import wheel_variances
from locbench.filters._numba_rng import generator_from
from locbench.filters.pf import ParticleFilter, ParticleFilterConfig
from locbench.registry import make_dataset

_DATA: dict[str, Dataset] = {}


def _office() -> Dataset:
    if "office" not in _DATA:
        _DATA["office"] = make_dataset("office", 0)
    return _DATA["office"]


@njit(cache=True)
def _fused_step(
    x: Any,
    logw: Any,
    w: Any,
    u: Any,
    q_std: Any,
    gen: Any,
    ranges: Any,
    bearings: Any,
    rows: Any,
    lm_xy: Any,
    lm: Any,
    ess_fraction: float,
    roughening_k: float,
) -> Any:
    """One predict (encoder model) + landmark update + estimate of ``pf``'s default configuration in one call.

    ``u`` = (d_left, d_right, sd_left, sd_right, wheelbase); ``lm`` = (1 / var_range, 1 / var_bearing, log
    normaliser). The estimate after the predict is the motion kernel's (as the filter's).
    """
    n = x.shape[0]
    pf_mod._move(x, True, u[0], u[1], 0.0, u[2], u[3], u[4], q_std, gen, w, logw)
    ll = pf_mod._sightings_loglik(x, ranges, bearings, rows, lm_xy, True, lm[0], lm[1], lm[2], -math.inf)
    _, n_eff = pf_mod._reweigh(logw, ll, w)
    if n_eff < ess_fraction * n:
        spread = pf_mod._roughening_spread(x, w, n, roughening_k)
        idx = pf_mod._systematic_indices(w, n, generator_from(gen).random())
        x[:] = pf_mod._gather(x, idx)
        pf_mod._jitter(x, spread * n ** (-1.0 / 3.0), gen)
        logw[:] = -math.log(n)
        w[:] = 1.0 / n
    return pf_mod._checked_stats(x, w, logw)


def make_steps(n: int, seed: int = 0) -> tuple[Callable[[], None], Callable[[], None], ParticleFilter, ParticleFilter]:
    """(filter step, fused step, filter, reference's filter) on the office world for ``n`` particles of the
    landmark model, each on its own filter reset with ``seed``, both replaying one odometry event and one
    landmark event of mid-run (the fused step works on the second filter's arrays)."""
    ds = _office()
    flt = ParticleFilter(ParticleFilterConfig(particles=n))
    flt.reset(ds.initial, ds.world, ds.sensors, np.random.default_rng(seed))
    ref = ParticleFilter(ParticleFilterConfig(particles=n))
    ref.reset(ds.initial, ds.world, ds.sensors, np.random.default_rng(seed))
    mid = len(ds.events) // 2
    odo = next(e for e in ds.events[mid:] if isinstance(e, Odometry) and e.d_left)
    z = next(e for e in ds.events[mid:] if type(e) is LandmarkObservations and len(e.ranges) > 0)

    def step() -> None:
        flt.predict(odo)
        flt.update(z)
        flt.estimate()

    nz = ref._noise
    assert odo.d_left is not None and odo.d_right is not None and nz.wheelbase_m is not None
    vl, vr = wheel_variances(odo.d_left, odo.d_right, nz.k_left, nz.k_right)
    u = np.array([odo.d_left, odo.d_right, math.sqrt(vl), math.sqrt(vr), nz.wheelbase_m])
    prepared = ref._prepare_landmarks(z)
    assert prepared is not None
    ranges, bearings, rows = prepared[1]
    lm = np.array([ref._inv_var_r, ref._inv_var_b, ref._lm_log_norm])
    cfg = ref.config

    def fused() -> None:
        _fused_step(
            ref._x, ref._logw, ref._w, u, ref._q_std, ref._gen, ranges, bearings, rows, ref._lm_xy, lm,
            cfg.resample_ess_fraction, cfg.roughening_k,
        )  # fmt: skip

    return step, fused, flt, ref


def _report(benchmark: Any, request: pytest.FixtureRequest, n: int, label: str) -> None:
    # the median: one descheduled round on a shared machine must not move the rate
    median_s = float(benchmark.stats.stats.median)
    rate = n / median_s
    benchmark.extra_info["particles_per_s"] = rate
    benchmark.extra_info["step_ms"] = 1e3 * median_s
    with request.config.pluginmanager.get_plugin("capturemanager").global_and_fixture_disabled():
        # a summary line in the nox -s perf output (pytest-benchmark's table has no throughput column)
        print(f"\npf {label:9s} N={n:>6d}: {1e3 * median_s:8.3f} ms/step (median), {rate:12.0f} particles/s")


@pytest.mark.parametrize("sensor", ["landmarks", "laser60"])
@pytest.mark.parametrize("n", [1_000, 10_000, 100_000])
def test_pf_step_throughput(benchmark: Any, request: pytest.FixtureRequest, n: int, sensor: str) -> None:
    if n >= 100_000 and benchmark.disabled:
        pytest.skip("1e5 particles only when benchmarking (nox -s perf)")
    ds = _office()
    laser = sensor == "laser60"
    cfg = ParticleFilterConfig(particles=n, use_landmarks=not laser, use_laser=laser, laser_beams=60)
    flt = ParticleFilter(cfg)
    flt.reset(ds.initial, ds.world, ds.sensors, np.random.default_rng(0))
    mid = len(ds.events) // 2
    obs_type = LaserScan if laser else LandmarkObservations
    u = next(e for e in ds.events[mid:] if isinstance(e, Odometry) and e.d_left)
    z = next(e for e in ds.events[mid:] if type(e) is obs_type and len(getattr(e, "ranges", ())) > 0)

    def step() -> None:
        flt.predict(u)
        flt.update(z)
        flt.estimate()

    step()  # compile the numba kernels and build the likelihood field outside the timing
    benchmark(step)
    if not benchmark.disabled:
        _report(benchmark, request, n, sensor)


@pytest.mark.parametrize("n", [1_000, 10_000, 100_000])
def test_pf_fused_reference(benchmark: Any, request: pytest.FixtureRequest, n: int) -> None:
    """The landmark step as one compiled call: the reference ``test_pf_step_throughput[landmarks]`` is held to."""
    if n >= 100_000 and benchmark.disabled:
        pytest.skip("1e5 particles only when benchmarking (nox -s perf)")
    _, fused, _, _ = make_steps(n)
    fused()
    benchmark(fused)
    if not benchmark.disabled:
        _report(benchmark, request, n, "fused")


@pytest.mark.parametrize("n", [1_000, 10_000, 100_000])
def test_pf_over_fused_paired(benchmark: Any, request: pytest.FixtureRequest, n: int) -> None:
    """The filter's landmark step over the fused reference's, paired: each round times a block of filter
    steps and then a block of fused steps, and the ratio is the median of the rounds' ratios (the cases
    above run minutes apart, and on a shared machine their ratio drifts with the load)."""
    if n >= 100_000 and benchmark.disabled:
        pytest.skip("1e5 particles only when benchmarking (nox -s perf)")
    step, fused, _, _ = make_steps(n)
    step()
    fused()
    block = max(3, 100_000 // n)  # steps per block: about 50 ms of work
    ratios: list[float] = []

    def one_round() -> None:
        t0 = time.perf_counter()
        for _ in range(block):
            step()
        t1 = time.perf_counter()
        for _ in range(block):
            fused()
        ratios.append((t1 - t0) / (time.perf_counter() - t1))

    benchmark.pedantic(one_round, rounds=1 if benchmark.disabled else 21, iterations=1)
    if not benchmark.disabled:
        ratio = statistics.median(ratios)
        benchmark.extra_info["filter_over_fused"] = ratio
        with request.config.pluginmanager.get_plugin("capturemanager").global_and_fixture_disabled():
            print(f"\npf landmarks N={n:>6d}: filter / fused {ratio:.3f} (median of {len(ratios)} paired rounds)")


def test_fused_reference_is_the_filter() -> None:
    """The fused reference computes the filter's own step: the same particles and estimate, bit for bit."""
    step, fused, flt, ref = make_steps(500, seed=3)
    for _ in range(6):
        step()
        fused()
        est = flt.estimate()
        mean, cov, finite = pf_mod._checked_stats(ref._x, ref._weights(), ref._logw)
        assert finite
        np.testing.assert_array_equal(flt._x, ref._x)
        np.testing.assert_array_equal(est.mean, mean)
        np.testing.assert_array_equal(est.cov, cov)
