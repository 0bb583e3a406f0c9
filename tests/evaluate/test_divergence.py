"""The divergence bound: a finite estimate far outside the world is a diverged run, not an ok one."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from locbench.datasets.dataset import Landmarks, OccupancyGrid, WorldMap
from locbench.evaluate.divergence import DIVERGENCE_FACTOR, Box, left_world, world_box, world_extent
from locbench.registry import make_dataset
from locbench.run.store import Store
from locbench.run.sweep import run_many


def test_world_extent_covers_truth_landmarks_and_grid() -> None:
    ds = make_dataset("tiny_line", 0)
    grid = OccupancyGrid(np.zeros((20, 40)), 0.5, (-30.0, -4.0, 0.0))
    lms = Landmarks(np.array([1], dtype=np.int64), np.array([[50.0, 7.0]]))
    ds = dataclasses.replace(ds, world=WorldMap(occupancy=grid, landmarks=lms))
    e = world_extent(ds)
    assert e.x_min == -30.0 and e.x_max == 50.0
    assert e.y_min == -4.0 and e.y_max == 7.0
    box = world_box(ds)
    assert box.x_min == pytest.approx(-30.0 - DIVERGENCE_FACTOR * 80.0)
    assert box.y_max == pytest.approx(7.0 + DIVERGENCE_FACTOR * 80.0)


def test_left_world_says_why() -> None:
    box = Box(-10.0, 10.0, -5.0, 5.0)
    assert left_world(np.array([9.0, -4.0, 3.0]), box) is None
    assert "non-finite" in (left_world(np.array([np.nan, 0.0, 0.0]), box) or "")
    msg = left_world(np.array([-9.6e299, 0.0, 0.0]), box)
    assert msg is not None and "-9.6e+299" in msg and "left the world's bound" in msg


@pytest.mark.usefixtures("harness_registry")
def test_a_finite_estimate_far_outside_the_world_is_a_diverged_run(tmp_path: Path) -> None:
    out = run_many(["bad[mode=far]", "bad[fail_at_s=100]"], ["line"], [0], str(tmp_path))
    assert [o.status for o in out] == ["diverged", "ok"]
    meta = json.loads((Store(tmp_path).run_dir("line", out[0].filter, 0) / "meta.json").read_text())
    assert meta["status"] == "diverged" and "left the world's bound" in meta["message"]
