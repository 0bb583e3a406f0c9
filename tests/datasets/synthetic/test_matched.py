"""Model-matched worlds (``matched=true``), the ``consistency`` suite and its claim."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from locbench import claims
from locbench.claims.matched_worlds import check_matched_consistency
from locbench.core.errors import ConfigError
from locbench.core.runkey import key_params
from locbench.datasets.synthetic.scenarios import RoomParams
from locbench.datasets.synthetic.toolkit import ENCODER_K_NOMINAL
from locbench.evaluate.metrics import chi2_band
from locbench.evaluate.pcrb import pcrb_covariances
from locbench.registry import make_dataset
from locbench.report import write_report
from locbench.report.site import site_markdown
from locbench.run.store import Store
from locbench.run.sweep import run_many
from locbench.suites import ALL_FILTERS, SUITES

WORLDS = ("room", "office", "lap", "line_room", "scan_grid", "landmark_geometry")


@pytest.mark.parametrize("world", WORLDS)
def test_matched_world_simulates_the_nominal_noise(world: str) -> None:
    ds = make_dataset(f"{world}[matched=true]", 2)
    odo = ds.metadata["true_odometry_error"]
    assert odo["scale_left"] == odo["scale_right"] == 0.0
    assert odo["k_left"] == odo["k_right"] == ENCODER_K_NOMINAL == ds.sensors.encoder_k_left
    assert odo["wheelbase_true_m"] == ds.sensors.wheelbase_m
    # the initial belief's mean is a draw from the belief around the true start, not the start itself
    err = ds.initial.mean - np.array([*ds.ground_truth.xy[0], ds.ground_truth.theta[0]])
    assert np.any(err != 0.0)
    assert np.all(np.abs(err) < 5 * np.sqrt(np.diag(ds.initial.cov)))
    for name, true in ds.metadata.get("sensors_true", {}).items():
        if name == "landmarks":
            assert true["sigma_range_m"] == ds.sensors.landmark_sigma_range_m
            assert true["sigma_bearing_rad"] == ds.sensors.landmark_sigma_bearing_rad
            assert true["detection_prob"] == 1.0
        if name == "fixes":
            assert true["sigma_xy_m"] == ds.sensors.pose_fix_sigma_xy_m


def test_default_world_keeps_its_systematic_error_and_exact_start() -> None:
    ds = make_dataset("room", 2)
    assert ds.metadata["true_odometry_error"]["scale_left"] != 0.0
    np.testing.assert_array_equal(ds.initial.mean[:2], ds.ground_truth.xy[0])
    # matched=false is the default realisation, and the run key does not carry it
    other = make_dataset("room[matched=false]", 2)
    np.testing.assert_array_equal(other.ground_truth.xy, ds.ground_truth.xy)
    assert "matched" not in key_params(RoomParams())
    assert key_params(RoomParams(matched=True))["matched"] is True


def test_matched_dead_reckoning_spread_follows_the_nominal_encoder_noise() -> None:
    # Odometry-only final heading error over seeds: its spread is the nominal k's (no systematic part).
    errs = []
    for seed in range(12):
        ds = make_dataset("room[matched=true]", seed)
        th = ds.initial.mean[2] + sum(e.dtheta for e in ds.events if type(e).__name__ == "Odometry")
        errs.append(np.angle(np.exp(1j * (th - ds.ground_truth.theta[-1]))))
    odo_only = make_dataset("room[matched=true]", 0)
    odo_only = type(odo_only)(
        **{**odo_only.__dict__, "events": [e for e in odo_only.events if type(e).__name__ == "Odometry"]}
    )
    sd_bound = float(np.sqrt(pcrb_covariances(odo_only)[-1, 2, 2]))
    sd = float(np.sqrt(np.mean(np.square(errs))))
    assert 0.5 * sd_bound < sd < 2.0 * sd_bound


def test_landmark_geometry_matched_refuses_an_initial_offset() -> None:
    with pytest.raises(ConfigError, match="initial_offset_m"):
        make_dataset("landmark_geometry[matched=true,initial_offset_m=2]", 0)


def test_consistency_suite_is_every_filter_on_both_matched_worlds_and_not_in_all() -> None:
    s = SUITES["consistency"]
    assert [(b.filters, b.datasets, b.seeds) for b in s.blocks] == [
        (ALL_FILTERS, ("room[matched=true]", "office[matched=true]"), 50)
    ]
    assert not any("matched" in d for b in SUITES["all"].blocks for d in b.datasets)


def _anees_rows(dataset: str, values: dict[str, list[float]]) -> pd.DataFrame:
    rows = [(dataset, f, s, "anees", v) for f, vs in values.items() for s, v in enumerate(vs)]
    return pd.DataFrame(rows, columns=["dataset", "filter", "seed", "metric", "value"])


def test_claim_is_reproduced_for_consistent_anees_and_not_for_overconfident() -> None:
    rng = np.random.default_rng(0)
    # A consistent filter's run ANEES: time averages of chi-square(3) draws, mean 3.
    good = list(stats.chi2(3).rvs(size=(50, 200), random_state=rng).mean(axis=1))
    df = _anees_rows("room[matched=true]", {"ekf_landmarks": good, "gtsam_fls": good})
    # rows of the shipped world and of another variant are not read
    df = pd.concat([df, _anees_rows("room", {"ekf_landmarks": [9.0] * 50, "gtsam_fls": [9.0] * 50})])
    res = check_matched_consistency(df)
    assert res.verdict == "reproduced", res.measured
    lo, hi = chi2_band(3, 50)
    assert f"[{lo:.2f}, {hi:.2f}]" in res.measured and "ekf_landmarks" in res.measured
    with_pf = pd.concat([df, _anees_rows("room[matched=true]", {"pf": [15.0] * 50})])
    res_pf = check_matched_consistency(with_pf)
    assert res_pf.verdict == "reproduced" and "not judged: pf 15.00" in res_pf.measured
    over = _anees_rows("room[matched=true]", {"ekf_landmarks": [8.9] * 50, "gtsam_fls": good})
    bad = check_matched_consistency(over)
    assert bad.verdict == "not reproduced" and "8.90" in bad.measured
    cautious = _anees_rows("room[matched=true]", {"ekf_landmarks": good, "gtsam_fls": [1.0] * 50})
    assert check_matched_consistency(cautious).verdict == "not reproduced"
    collapsed = _anees_rows("room[matched=true]", {"ekf_landmarks": [*good[:49], np.inf], "gtsam_fls": good})
    assert check_matched_consistency(collapsed).verdict == "not reproduced"


def test_claim_without_matched_runs_is_not_evaluated() -> None:
    df = _anees_rows("room", {"ekf_landmarks": [3.0] * 5, "gtsam_fls": [3.0] * 5})
    assert check_matched_consistency(df).verdict == "not evaluated"
    only_ekf = _anees_rows("office[matched=true]", {"ekf_landmarks": [3.0] * 5})
    assert check_matched_consistency(only_ekf).verdict == "not evaluated"
    ids = {c.id: c for c in claims.all_claims()}
    assert ids["room_matched_consistent"].across_variants and ids["office_matched_consistent"].dataset == "office"


def test_report_shows_each_filter_on_the_shipped_world_beside_its_matched_twin(tmp_path: Path) -> None:
    run_many(["odometry", "ekf_landmarks"], ["room", "room[matched=true]"], [0, 1], str(tmp_path))
    write_report(Store(tmp_path), out=tmp_path / "summary")
    text = site_markdown(tmp_path / "summary")
    section = text[text.index('id="consistency"') :]
    assert "*`room` as shipped beside `room[matched=true]`" in section
    head = (
        "| filter | shipped: runs | shipped: ANEES | shipped: NLL | shipped: energy score (cm) | shipped: ATE / PCRB |"
    )
    assert f"{head} matched: runs |" in section
    df = pd.read_parquet(tmp_path / "summary" / "metrics.parquet")
    sel = df[(df["filter"] == "ekf_landmarks") & (df["metric"] == "anees")]
    shipped = sel[sel["dataset"] == "room"]["value"].mean()
    matched = sel[sel["dataset"] == "room[matched=true]"]["value"].mean()
    row = next(line for line in section.splitlines() if line.startswith("| `ekf_landmarks` |"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[1] == "2" and cells[2].startswith(f"{shipped:.3g} (") and cells[6] == "2"
    assert cells[7].startswith(f"{matched:.3g} (")
    # a finite energy score beside the ANEES on both worlds
    assert float(cells[4]) > 0 and float(cells[9]) > 0
    # the twin's bound is the matched world's own: the filter's efficiency there is finite
    assert float(cells[10]) > 0.5
