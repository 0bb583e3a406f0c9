"""The generalization table: tuning against test units, on hand-made rows and on a small store of fake runs."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
from test_report import _fake_run, _fake_truth

from locbench.datasets.splits import RADISH_SPLIT
from locbench.evaluate.metrics import ATE_M
from locbench.report.collect import collect
from locbench.report.sections import generalization as gz
from locbench.run.store import Store

COLUMNS = ["dataset", "filter", "seed", "metric", "value"]


def _of(dataset: str, seed: int) -> gz.UnitOf | None:
    if dataset.startswith("radish"):
        return gz.recorded_unit(dataset, {"site": dataset.split("site=")[1].rstrip("]")})
    return gz.synthetic_unit(dataset, seed)


def _rows(cells: dict[tuple[str, str, int], float]) -> pd.DataFrame:
    rows = [(d, f, s, ATE_M, v) for (d, f, s), v in cells.items()]
    rows += [(d, f, s, "failed", 0.0) for (d, f, s) in cells]
    return pd.DataFrame(rows, columns=COLUMNS)


def test_units_follow_the_declared_splits() -> None:
    assert gz.synthetic_unit("room", 3) == gz.UnitOf("room", "seed 3", "test")
    assert gz.synthetic_unit("room", 1003).role == "tuning"
    u = gz.recorded_unit("radish[max_scans=50,site=seattle]", {"site": "seattle", "max_scans": 50})
    assert u == gz.UnitOf("radish[max_scans=50]", "site seattle", "test")
    assert gz.recorded_unit("radish", {"site": "intel"}) == gz.UnitOf("radish", "site intel", "tuning")
    # MRCLAM, Dataset 6 only: every robot is a test unit of its default (its noise was derived without it)
    for r in (1, 4):
        assert gz.recorded_unit(f"mrclam[robot={r}]", {"robot": r, "dataset": 6}) == gz.UnitOf(
            "mrclam", f"robot {r}", "test"
        )
    assert gz.recorded_unit("mrclam[dataset=3]", {"robot": 1, "dataset": 3}) is None
    assert gz.recorded_unit("plaza", {}) is None


def test_family_rows_give_means_ratio_and_units_worse_than_dead_reckoning() -> None:
    tune, test = RADISH_SPLIT.tuning[:2], RADISH_SPLIT.test[:3]
    cells: dict[tuple[str, str, int], float] = {}
    for site in tune:
        cells[(f"radish[site={site}]", "odometry", 0)] = 1.0
        cells[(f"radish[site={site}]", "ekf", 0)] = 0.10
    for k, site in enumerate(test):
        cells[(f"radish[site={site}]", "odometry", 0)] = 0.5
        if k < 2:
            cells[(f"radish[site={site}]", "ekf", 0)] = [0.2, 0.7][k]  # worse than odometry on the second
    # ekf skipped the third test site (no rows: not compared) and failed on a fourth (counted worse)
    cells[("radish[site=seattle]", "odometry", 0)] = 0.4
    df = _rows(cells)
    df = pd.concat([df, pd.DataFrame([("radish[site=seattle]", "ekf", 0, "failed", 1.0)], columns=COLUMNS)])
    # a synthetic world with test seeds only has no ratio and no row
    df = pd.concat([df, _rows({("room", "ekf", 0): 0.1, ("room", "odometry", 0): 0.3})])
    rows = {r.filter: r for r in gz.family_rows(df, _of, "odometry")}
    assert set(rows) == {"ekf", "odometry"}
    ekf = rows["ekf"]
    assert ekf.family == "radish" and ekf.tuning_units == 2 and ekf.test_units == 2
    assert ekf.tuning_ate_m == pytest.approx(0.10)
    assert ekf.test_ate_m == pytest.approx(0.45)
    assert ekf.ratio == pytest.approx(4.5)
    assert (ekf.worse_than_baseline, ekf.compared_units) == (2, 3)  # 0.7 > 0.5, and the failed run on seattle
    assert rows["odometry"].kind == "baseline" and rows["odometry"].ratio == pytest.approx(0.475 / 1.0)
    # a configuration left out by keep gets no row; the baseline always does
    kept = gz.family_rows(df, _of, "odometry", keep=lambda f: False)
    assert [r.filter for r in kept] == ["odometry"]


def test_study_rows_set_the_train_objective_against_the_test_runs() -> None:
    study = {
        "filter": "ekf",
        "world": "room",
        "train": ["room"],
        "train_seeds": [1000, 1001],
        "test": ["room"],
        "test_seeds": [0, 1],
        "objective": "ate",
        "trials": [{"number": 0, "spec": "ekf", "value": 0.2}, {"number": 1, "spec": "ekf[a=1]", "value": 0.1}],
        "best_spec": "ekf[a=1]",
        "best_value": 0.1,
    }
    df = _rows(
        {
            ("room", "odometry", 0): 0.3,
            ("room", "odometry", 1): 0.3,
            ("room", "ekf", 0): 0.2,
            ("room", "ekf", 1): 0.4,
            ("room", "ekf[a=1]", 0): 0.25,
            ("room", "ekf[a=1]", 1): 0.25,
            ("room", "ekf[a=1]", 7): 9.0,  # not a test seed of the study
        }
    )
    rows = gz.study_rows(df, [study], "odometry")
    assert [(r.kind, r.filter) for r in rows] == [("default", "ekf"), ("tuned", "ekf[a=1]")]
    kept = gz.study_rows(df, [{**study, "default_kept": True, "best_spec": "ekf", "best_value": 0.2}], "odometry")
    assert [r.kind for r in kept] == ["default", "tuned (default kept)"]
    d, t = rows
    assert d.tuning_ate_m == 0.2 and d.tuning_units == 2 and d.test_ate_m == pytest.approx(0.3)
    assert (d.worse_than_baseline, d.compared_units) == (1, 2)
    assert t.tuning_ate_m == 0.1 and t.test_ate_m == pytest.approx(0.25) and t.ratio == pytest.approx(2.5)
    assert (t.worse_than_baseline, t.compared_units) == (0, 2)
    table = gz.generalization_table(rows)
    assert table.rows[1][5] == "2.5" and table.rows[0][6] == "1/2"
    # another objective's train values are not ATEs: no row
    assert gz.study_rows(df, [{**study, "objective": "nll"}], "odometry") == []


def test_the_section_on_a_small_store_with_tuning_and_test_seeds(tmp_path: Path) -> None:
    st = Store(tmp_path / "results")
    for seed in (0, 1, 1000):
        truth = _fake_truth(seed)
        st.write_truth(truth)
        st.write_run(_fake_run(truth, "odometry", drift=0.004, sigma=0.01))
        st.write_run(_fake_run(truth, "ekf_landmarks", drift=0.0, sigma=0.01))
    col = collect(st)
    sec = gz.generalization_section(col)
    assert sec.blocks, "a world with tuning and test seeds has a table"
    table = sec.blocks[-1]
    by_filter = {row[1]: row for row in table.rows}  # type: ignore[union-attr]
    assert set(by_filter) == {"`odometry`", "`ekf_landmarks`"}
    ekf = by_filter["`ekf_landmarks`"]
    assert ekf[3].endswith("(1)") and ekf[4].endswith("(2)") and ekf[6] == "0/2"
    # without the tuning seed: no ratio, no section
    st2 = Store(tmp_path / "only-test")
    for seed in (0, 1):
        truth = _fake_truth(seed)
        st2.write_truth(truth)
        st2.write_run(_fake_run(truth, "odometry", drift=0.004, sigma=0.01))
    assert not gz.generalization_section(collect(st2)).blocks
