"""pytest-benchmark: building a synthetic realisation (simulation, sensors, ray-cast laser scans), the cost every
sweep pays once per (dataset, seed). A benchmark, not a timed test: a wall-clock bound fails on a busy machine."""

from __future__ import annotations

from typing import Any

import pytest

from locbench.registry import make_dataset


@pytest.mark.parametrize("world", ["office", "tiny_circle"])
def test_dataset_build_speed(benchmark: Any, world: str) -> None:
    make_dataset(world, 0)  # numba compile / cache load outside the timing
    ds = benchmark.pedantic(make_dataset, args=(world, 1), rounds=1 if benchmark.disabled else 5, iterations=1)
    assert len(ds.events) > 0
