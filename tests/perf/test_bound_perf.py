"""pytest-benchmark: the bound's laser information from one traversal per beam against differencing seven
casts per scan, on every 10th scan of ``office`` and ``lap`` at their true poses; and the whole bound (both rows)
against the seven-cast reference with the numpy covariance recursion."""

from __future__ import annotations

from typing import Any

import pytest
from bound_support import differenced_laser_information, scan_poses, seven_cast_bound

from locbench.evaluate import pcrb
from locbench.registry import make_dataset


@pytest.mark.parametrize("world", ["office", "lap"])
@pytest.mark.parametrize("method", ["one_cast", "differenced"])
def test_laser_information_speed(benchmark: Any, world: str, method: str) -> None:
    args = scan_poses(world)
    fn = pcrb.laser_information if method == "one_cast" else differenced_laser_information
    fn(*args)  # compile outside the timing
    benchmark.pedantic(fn, args=args, rounds=5 if benchmark.disabled else 15, iterations=1)


@pytest.mark.parametrize("world", ["office", "lap"])
@pytest.mark.parametrize("method", ["one_cast", "seven_casts"])
def test_whole_bound_speed(benchmark: Any, world: str, method: str) -> None:
    """Both bound rows of ``world`` (seed 0): this bound against the seven-cast, numpy-recursion reference."""
    ds = make_dataset(world, 0)
    fn = pcrb.bound_covariances if method == "one_cast" else seven_cast_bound
    fn(ds)  # compile outside the timing
    benchmark.pedantic(fn, args=(ds,), rounds=3 if benchmark.disabled else 9, iterations=1)
