"""pytest-benchmark: the bound's laser information from one traversal per beam against differencing seven
casts per scan (issue 24, item 3), on every 10th scan of ``office`` and ``lap`` at their true poses."""

from __future__ import annotations

from typing import Any

import pytest
from bound_support import differenced_laser_information, scan_poses

from locbench import pcrb


@pytest.mark.parametrize("world", ["office", "lap"])
@pytest.mark.parametrize("method", ["one_cast", "differenced"])
def test_laser_information_speed(benchmark: Any, world: str, method: str) -> None:
    args = scan_poses(world)
    fn = pcrb.laser_information if method == "one_cast" else differenced_laser_information
    fn(*args)  # compile outside the timing
    benchmark.pedantic(fn, args=args, rounds=5 if benchmark.disabled else 15, iterations=1)
