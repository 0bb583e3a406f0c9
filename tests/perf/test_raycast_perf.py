"""pytest-benchmark micro-benchmarks of the shared ray caster, single-threaded, in rays per second.

Run with ``nox -s perf`` (``pytest tests/perf --benchmark-only``); the median rays/s of each benchmark is
in ``extra_info`` (``--benchmark-json``) and is printed in a summary at the end of the session. In the
normal test run (``--benchmark-disable``) each runs once as a smoke test.

Workloads, on a deterministic 400 x 400 grid at 0.05 m (20 m x 20 m: border, a corridor with doors,
rooms and 60 boxes of clutter), max range 10 m, serial kernels (``parallel=False``, one core):

- ``scan``: one pose x 683 beams over 240 deg (a Hokuyo URG-04LX scan), a new pose every call;
- ``particles``: 1000 poses x 60 beams over 360 deg (a particle filter's expected scans).

``march`` is :func:`cast_scan`'s default (distance-field jumps, fields cached with the grid: the scan marches
on the per-octant planes, the particles on the isotropic field, both in the vector pool kernel); ``dda`` is
the plain exact traversal, kept for comparison. The issue's target is 10 M rays/s on one core for both
``march`` workloads; the module docstring of :mod:`locbench.raycast.cast` has the measured rates and their
conditions.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from locbench.core.grid import OccupancyGrid
from locbench.raycast.cast import cast_scan

RES = 0.05
MAX_RANGE_M = 10.0
_RATES: dict[str, float] = {}


def clutter_grid() -> OccupancyGrid:
    """The benchmark map, the same on every machine."""
    rng = np.random.default_rng(20240601)
    occ = np.zeros((400, 400), dtype=bool)
    occ[:2, :] = occ[-2:, :] = occ[:, :2] = occ[:, -2:] = True
    for r in (130, 270):  # corridor walls with doors
        occ[r : r + 2, :] = True
        for c in range(30, 400, 80):
            occ[r : r + 2, c : c + 18] = False
    for c in (100, 200, 300):  # room walls
        occ[:130, c : c + 2] = True
        occ[272:, c : c + 2] = True
    for _ in range(60):
        h, w = rng.integers(2, 14, 2)
        i, j = rng.integers(4, 382, 2)
        occ[i : i + h, j : j + w] = True
    return OccupancyGrid(occupancy=occ.astype(np.float64), resolution=RES)


def free_poses(grid: OccupancyGrid, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    free = np.argwhere(~grid.occupied())
    cells = free[rng.choice(free.shape[0], n, replace=False)]
    xy = grid.cell_centers(cells) + rng.uniform(-0.45 * RES, 0.45 * RES, (n, 2))
    return np.column_stack([xy, rng.uniform(-math.pi, math.pi, n)])


@pytest.fixture(scope="module")
def grid() -> OccupancyGrid:
    return clutter_grid()


@pytest.fixture(scope="module", autouse=True)
def rays_per_second_summary(request: pytest.FixtureRequest) -> Iterator[None]:
    """Print the median rays/s of every benchmark of this module at its end (``nox -s perf`` shows it)."""
    yield
    reporter = request.config.pluginmanager.get_plugin("terminalreporter")
    capture = request.config.pluginmanager.get_plugin("capturemanager")
    if not _RATES or reporter is None or capture is None:
        return
    with capture.global_and_fixture_disabled():  # fd capture would swallow the lines during teardown
        reporter.write_line("")
        reporter.write_sep("-", "ray casting, one core, median rays/s")
        for name, rate in sorted(_RATES.items()):
            reporter.write_line(f"{name:<24} {rate / 1e6:8.2f} M rays/s")
        # the plain traversal runs in the same session: the ratio is steadier than either rate on a shared host
        for workload in sorted({name.rsplit(" ", 1)[0] for name in _RATES}):
            march, dda = _RATES.get(f"{workload} march"), _RATES.get(f"{workload} dda")
            if march is not None and dda is not None:
                reporter.write_line(f"{workload + ' march/dda':<24} {march / dda:8.2f} x")


def _record(benchmark: Any, name: str, n_rays: int) -> None:
    stats = getattr(benchmark, "stats", None)
    if stats is None or getattr(benchmark, "disabled", False):
        return  # --benchmark-disable: one smoke run, no timing
    rate = n_rays / stats.stats.median
    benchmark.extra_info["rays_per_call"] = n_rays
    benchmark.extra_info["rays_per_s"] = rate
    _RATES[name] = rate


@pytest.mark.parametrize("method", ["march", "dda"])
def test_scan_683_beams(benchmark: Any, grid: OccupancyGrid, method: str) -> None:
    poses = free_poses(grid, 256, seed=1)
    angles = np.linspace(-2.0 * math.pi / 3.0, 2.0 * math.pi / 3.0, 683)
    cast_scan(grid, poses[0], angles, MAX_RANGE_M, parallel=False, method=method)  # JIT and distance field
    k = [0]

    def one_scan() -> np.ndarray:
        k[0] = (k[0] + 1) % poses.shape[0]
        return cast_scan(grid, poses[k[0]], angles, MAX_RANGE_M, parallel=False, method=method)

    benchmark.group = "raycast scan 1x683"
    r = benchmark.pedantic(one_scan, rounds=2000, iterations=1, warmup_rounds=10)
    assert r.shape == (683,)
    assert np.mean(np.isfinite(r)) > 0.5
    _record(benchmark, f"scan 1x683 {method}", 683)


@pytest.mark.parametrize("method", ["march", "dda"])
def test_particles_1000x60(benchmark: Any, grid: OccupancyGrid, method: str) -> None:
    poses = free_poses(grid, 1000, seed=2)
    angles = np.linspace(-math.pi, math.pi, 60, endpoint=False)
    cast_scan(grid, poses[:2], angles, MAX_RANGE_M, parallel=False, method=method)  # JIT and distance field

    def all_particles() -> np.ndarray:
        return cast_scan(grid, poses, angles, MAX_RANGE_M, parallel=False, method=method)

    benchmark.group = "raycast particles 1000x60"
    r = benchmark.pedantic(all_particles, rounds=30, iterations=1, warmup_rounds=2)
    assert r.shape == (1000, 60)
    assert np.mean(np.isfinite(r)) > 0.5
    _record(benchmark, f"particles 1000x60 {method}", 60_000)
