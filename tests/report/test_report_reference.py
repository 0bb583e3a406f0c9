"""The reference kinds of recorded data and the robustness table."""

from __future__ import annotations

import math

import pandas as pd

from locbench.report.sections.reference import INDEPENDENT_KINDS, reference_kind, robustness_table, semi_synthetic


def test_reference_kinds() -> None:
    assert reference_kind("mrclam", {}, "ground truth") == "motion capture"
    assert reference_kind("plaza", {}, "ground truth") == "GPS"
    # a SLAM truth label wins over anything the metadata says
    assert reference_kind("radish", {"reference_kind": "GPS"}, "SLAM reference") == "SLAM"
    assert reference_kind("librsf", {"reference_kind": "simulation"}, "ground truth") == "simulation"
    assert reference_kind("librsf", {"reference_kind": "not stated"}, "ground truth") == "not stated"
    assert reference_kind("no_such_dataset", {"reference_kind": "made up"}, "ground truth") == "not stated"
    assert "SLAM" not in INDEPENDENT_KINDS and "simulation" not in INDEPENDENT_KINDS
    assert semi_synthetic({"semi_synthetic": True}) and not semi_synthetic({"semi_synthetic": "yes"})


def _rows(values: dict[tuple[str, str], float]) -> pd.DataFrame:
    return pd.DataFrame(
        [{"dataset": d, "filter": f, "seed": 0, "metric": "ate_m", "value": v} for (d, f), v in values.items()]
    )


def test_robustness_table_gives_the_ratio_to_the_gaussian_reference() -> None:
    df = _rows({("a", "ekf"): 0.3, ("g", "ekf"): 0.15, ("a", "pf"): 0.2, ("g", "pf"): 0.2, ("b", "pf"): 0.4})
    noise_of = {"a": ("w1", "skewed"), "g": ("w1", "gaussian"), "b": ("w2", "heavy-tailed")}
    t = robustness_table(df, ["ekf", "pf", "none"], noise_of)
    assert t is not None
    assert t.header == ("filter", "w1 skewed (x ref)", "w1 gaussian (reference)", "w2 heavy-tailed (x ref)")
    rows = {r[0]: r[1:] for r in t.rows}
    assert rows["`ekf`"] == ("30 (2)", "15", "n/a")
    assert rows["`pf`"][0] == "20 (1)" and rows["`pf`"][2] == "40"  # no reference in w2: no ratio
    assert "`none`" not in rows
    assert math.isnan(t.sort_keys[0][0])
    assert robustness_table(df, ["ekf"], {}) is None
