"""The posterior Cramer-Rao bound as rows of the benchmark: computed by the sweep, stored beside the truth,
collected into metrics.parquet as ``pcrb`` and shown in every synthetic table and waypoint figure."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from locbench.evaluate.pcrb import BOUND_ALL, BOUND_NO_LASER, bound_covariances, pcrb_summary
from locbench.evaluate.records import BoundRecord
from locbench.registry import make_dataset
from locbench.report import collect_metrics, write_report
from locbench.report.site import site_markdown
from locbench.report.tables import ate_over_bound
from locbench.run.plan import plan_sweep
from locbench.run.store import Store
from locbench.run.sweep import run_many, run_sweep


@pytest.fixture(scope="module")
def swept(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("bound")
    run_many(["odometry", "ekf_landmarks"], ["room", "room[kidnap_m=1]"], [0, 1], str(root))
    return root


def test_sweep_stores_a_bound_per_synthetic_realisation_and_none_for_kidnaps(swept: Path) -> None:
    store = Store(swept)
    for seed in (0, 1):
        bound = store.read_bound("room", seed)
        assert bound is not None and set(bound.covs) == {BOUND_ALL}  # room has no laser
        np.testing.assert_array_equal(bound.covs[BOUND_ALL], bound_covariances(make_dataset("room", seed))[BOUND_ALL])
        assert store.read_bound("room[kidnap_m=1]", seed) is None


def test_the_metrics_file_has_the_bound_rows_with_the_summary_definitions(swept: Path) -> None:
    df = collect_metrics(Store(swept))
    rows = df[(df["filter"] == BOUND_ALL) & (df["dataset"] == "room")]
    assert sorted(rows["seed"].unique()) == [0, 1]
    ds = make_dataset("room", 1)
    cov = bound_covariances(ds)[BOUND_ALL]
    want = pcrb_summary(ds.ground_truth.t, cov, ds.waypoints.t if ds.waypoints is not None else np.zeros(0))
    got = rows[rows["seed"] == 1].set_index("metric")["value"]
    assert set(want) == set(got.index) and any(k.startswith("waypoint_") for k in want)
    for k, v in want.items():
        assert got[k] == pytest.approx(v, rel=1e-12)
    assert not (df[df["dataset"] == "room[kidnap_m=1]"]["filter"] == BOUND_ALL).any()


def test_report_shows_the_bound_and_each_filters_ate_over_pcrb(swept: Path, tmp_path: Path) -> None:
    out = tmp_path / "summary"
    write_report(Store(swept), out=out)
    text = site_markdown(out)
    assert "| `pcrb` |" in text and "ATE / PCRB" in text
    df = pd.read_parquet(out / "metrics.parquet")
    eff = ate_over_bound(df[df["dataset"] == "room"], "ekf_landmarks")
    ate = df[(df["dataset"] == "room") & (df["filter"] == "ekf_landmarks") & (df["metric"] == "ate_m")]["value"]
    bnd = df[(df["dataset"] == "room") & (df["filter"] == BOUND_ALL) & (df["metric"] == "ate_m")]["value"]
    assert eff == pytest.approx(np.sqrt(np.mean(ate**2)) / np.sqrt(np.mean(bnd**2)))
    assert eff > 1.0  # no estimator beats the bound by much; these two runs are far above it
    assert f"| {eff:.3g} |" in text
    assert (out / "figures" / "room_waypoint_rmse.png").is_file()


def test_ate_over_bound_pairs_seeds_and_is_nan_without_a_bound() -> None:
    rows = [
        ("d", "f", 0, "ate_m", 0.03),
        ("d", "f", 1, "ate_m", 0.04),
        ("d", "f", 2, "ate_m", 9.0),  # no bound for seed 2: left out
        ("d", BOUND_ALL, 0, "ate_m", 0.01),
        ("d", BOUND_ALL, 1, "ate_m", 0.01),
    ]
    df = pd.DataFrame(rows, columns=["dataset", "filter", "seed", "metric", "value"])
    assert ate_over_bound(df, "f") == pytest.approx(np.sqrt((0.03**2 + 0.04**2) / 2) / 0.01)
    assert np.isnan(ate_over_bound(df[df["filter"] == "f"], "f"))


def test_a_missing_bound_is_computed_alone_without_rerunning_the_filters(swept: Path) -> None:
    store = Store(swept)
    store.bound_path("room", 1).unlink()
    plan = plan_sweep([(["odometry", "ekf_landmarks"], ["room", "room[kidnap_m=1]"], [0, 1])], str(swept))
    assert [(t.dataset.name, t.seed, t.jobs) for t in plan.tasks] == [("room", 1, ())]
    assert len(plan.cached) == 8
    result = run_sweep(plan)
    assert (result.bounds, result.bounds_planned) == (1, 1)
    assert store.read_bound("room", 1) is not None
    again = plan_sweep([(["odometry"], ["room"], [0, 1])], str(swept))
    assert again.tasks == []


def test_a_bound_of_another_version_is_recomputed(swept: Path) -> None:
    store = Store(swept)
    meta_path = store.bound_path("room", 0).with_suffix(".json")
    meta = json.loads(meta_path.read_text())
    meta_path.write_text(json.dumps(meta | {"bound_key": "stale"}))
    plan = plan_sweep([(["odometry"], ["room"], [0])], str(swept))
    assert [(t.seed, t.jobs, t.bound_key is not None) for t in plan.tasks] == [(0, (), True)]
    run_sweep(plan)
    assert store.bound_key("room", 0) == meta["bound_key"]


def test_laser_worlds_store_the_bound_without_the_laser_too(tmp_path: Path) -> None:
    ds = make_dataset("line_room", 0)
    covs = bound_covariances(ds)
    assert set(covs) == {BOUND_ALL, BOUND_NO_LASER}
    # the scans only add information: the bound with them is tighter everywhere
    tr_all = covs[BOUND_ALL][:, 0, 0] + covs[BOUND_ALL][:, 1, 1]
    tr_no = covs[BOUND_NO_LASER][:, 0, 0] + covs[BOUND_NO_LASER][:, 1, 1]
    assert np.all(tr_all <= tr_no * (1 + 1e-9))
    store = Store(tmp_path)
    store.write_bound(BoundRecord("line_room", 0, ds.ground_truth.t, covs, {"bound_key": "k"}))
    back = store.read_bound("line_room", 0)
    assert back is not None and set(back.covs) == set(covs)
    np.testing.assert_array_equal(back.covs[BOUND_NO_LASER], covs[BOUND_NO_LASER])


def test_an_unreadable_bound_record_names_its_file(tmp_path: Path) -> None:
    store = Store(tmp_path)
    ds = make_dataset("room", 0)
    store.write_bound(BoundRecord("room", 0, ds.ground_truth.t, bound_covariances(ds), {"bound_key": "k"}))
    store.bound_path("room", 0).with_suffix(".json").write_text("{not json")
    with pytest.raises(Exception, match=r"seed-0000\.bound\.json"):
        store.read_bound("room", 0)
