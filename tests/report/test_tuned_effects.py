"""The tuned section's per-unit effects: each test unit's default against its own tuned configuration, pooled over
the folds of a cross-validated recording, with the paired test across units."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd

from locbench.evaluate.metrics import ATE_M
from locbench.registry import resolve_dataset
from locbench.report.sections.tuned import GroupEffect, _effects_text, group_effects


def _rows(cells: list[tuple[str, str, int, float]]) -> pd.DataFrame:
    return pd.DataFrame(
        [
            {"dataset": resolve_dataset(d).name, "filter": f, "seed": k, "metric": ATE_M, "value": v}
            for d, f, k, v in cells
        ]
    )


def _fold(robot: int, best: str) -> dict[str, Any]:
    others = [f"mrclam[robot={r}]" for r in range(1, 6) if r != robot]
    return {
        "filter": "ekf_landmarks",
        "world": "mrclam",
        "fold": f"robot {robot}",
        "train": others,
        "train_seeds": [1000],
        "test": [f"mrclam[robot={robot}]"],
        "test_seeds": [0],
        "best_spec": best,
    }


def test_each_held_out_robot_is_scored_with_the_configuration_tuned_without_it() -> None:
    default = "ekf_landmarks"
    tuned = {r: f"ekf_landmarks[sigma_range_m=0.{r}]" for r in range(1, 6)}
    cells = []
    for r in range(1, 6):
        cells.append((f"mrclam[robot={r}]", default, 0, 0.20))
        # each fold's tuned spec on its own robot; the other folds' specs on it must not be read
        for q in range(1, 6):
            cells.append((f"mrclam[robot={r}]", tuned[q], 0, 0.10 if q == r and r == 4 else 0.30 + q))
    studies = [_fold(r, tuned[r]) for r in range(1, 6)]
    (g,) = group_effects(_rows(cells), studies)
    assert g.units == tuple(f"robot {r}" for r in range(1, 6))
    np.testing.assert_array_equal(g.default_m, [0.2] * 5)
    np.testing.assert_array_equal(g.tuned_m, [1.3, 2.3, 3.3, 0.1, 5.3])
    # a gain that rests on one robot shows as such: robot 4 -50 %, every other robot worse
    text = _effects_text(g)
    assert text.startswith("robot 1 ") and "robot 4 -50" in text
    assert [c < 0 for c in g.change_pct] == [False, False, False, True, False]
    # five units: no two-sided test can reach 5 %, so none is run
    assert g.test().n == 5 and math.isnan(g.test().p)


def test_seeds_of_a_world_are_units_and_tested() -> None:
    g = GroupEffect("pf", "office", tuple(f"seed {k}" for k in range(8)), np.full(8, 0.1), np.full(8, 0.05))
    res = g.test()
    assert res.n == 8 and res.p < 0.01
    assert _effects_text(g) == "better on 8 of 8, worse on 0; -50 to -50"
