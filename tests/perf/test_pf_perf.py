"""pytest-benchmark: particle throughput of one predict + update step of ``pf`` on the office world.

``nox -s perf`` (``pytest tests/perf --benchmark-only``) measures 1e3, 1e4 and 1e5 particles with the
landmark model and with the 60-beam likelihood field, stores particles/s (from the median step time) in
``benchmark.extra_info`` and
prints one summary line per case. In the normal test run (``--benchmark-disable``) each case runs once as a
smoke test and the 1e5 cases are skipped.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from locbench.datasets.base import Dataset
from locbench.events import LandmarkObservations, LaserScan, Odometry
from locbench.filters.pf import ParticleFilter, ParticleFilterConfig
from locbench.registry import make_dataset

_DATA: dict[str, Dataset] = {}


def _office() -> Dataset:
    if "office" not in _DATA:
        _DATA["office"] = make_dataset("office", 0)
    return _DATA["office"]


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
        # the median: one descheduled round on a shared machine must not move the rate
        median_s = float(benchmark.stats.stats.median)
        rate = n / median_s
        benchmark.extra_info["particles_per_s"] = rate
        benchmark.extra_info["step_ms"] = 1e3 * median_s
        with request.config.pluginmanager.get_plugin("capturemanager").global_and_fixture_disabled():
            # a summary line in the nox -s perf output (pytest-benchmark's table has no throughput column)
            print(f"\npf {sensor:9s} N={n:>6d}: {1e3 * median_s:8.2f} ms/step (median), {rate:12.0f} particles/s")
