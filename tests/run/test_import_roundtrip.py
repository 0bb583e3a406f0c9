"""``locbench import``: a built-in filter's runs written in each format and imported under another name score the
same as the native runs: every non-timing metric within 1e-9 relative."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("rosbags")

from external_support import (
    ODOM,
    last_per_time,
    write_bag,
    write_openvins,
    write_tum_rows,
    write_tumcov,
)

from locbench.cli import main
from locbench.core.seeding import belief_rng, filter_rng
from locbench.evaluate.metrics import run_metrics
from locbench.evaluate.records import RunRecord, TruthRecord
from locbench.evaluate.scores import SAMPLE_SCORE_KEYS, SCORE_IDS
from locbench.registry import make_dataset, make_filter
from locbench.run.filter_pass import FilterPass
from locbench.run.import_runs import digest_problems, import_system
from locbench.run.ros_messages import SIM_EPOCH_S
from locbench.run.store import Store
from locbench.run.verify import verify

RTOL = 1e-9
#: Filter diagnostics a system's output does not carry (not scores of the estimate).
DIAGNOSTICS = {"accepted_fraction", "particles_mean"}
CONSISTENCY_IDS = {"anees", "nees_in_band_fraction", "nll", "kidnap_false_confidence_fraction"}


def _consistency(k: str) -> bool:
    """A metric of the belief's spread: the NEES family, the NLL and the proper scores with their intervals."""
    return k in CONSISTENCY_IDS or k.startswith(("crps_", "energy_score"))


def _timing(k: str) -> bool:
    return k.startswith(("predict_us", "update_us", "realtime_factor")) or k.endswith("_ref")


def _comparable(values: dict[str, float]) -> dict[str, float]:
    return {k: v for k, v in values.items() if not _timing(k) and k not in DIAGNOSTICS}


def _assert_same(native: dict[str, float], imported: dict[str, float], pose_only: bool = False) -> None:
    want = {k: v for k, v in _comparable(native).items() if not (pose_only and _consistency(k))}
    assert set(imported) == set(want)
    for k, v in want.items():
        np.testing.assert_allclose(imported[k], v, rtol=RTOL, atol=0, err_msg=k)


@pytest.fixture(scope="module")
def ekf(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, RunRecord, TruthRecord]:
    res = tmp_path_factory.mktemp("results")
    assert main(["run", "--filter", "ekf_landmarks", "--dataset", "office", "--seeds", "1", "--results", str(res)]) == 0
    store = Store(res)
    return res, store.read_run(store.run_dir("office", "ekf_landmarks", 0)), store.read_truth("office", 0)


def _imported(res: Path, name: str) -> RunRecord:
    store = Store(res)
    return store.read_run(store.run_dir("office", f"external[name={name}]", 0))


def test_tum_with_covariance_gives_every_metric_of_the_native_run(ekf: Any, tmp_path: Path) -> None:
    res, rec, truth = ekf
    f = write_tumcov(tmp_path / "ekf.txt", rec.t, rec.mean, rec.cov)
    assert (
        main(["import", "--name", "tumcov", "--dataset", "office", "--seed", "0", str(f), "--results", str(res)]) == 0
    )
    run = _imported(res, "tumcov")
    values = run_metrics(run, truth)
    _assert_same(run_metrics(rec, truth), values)
    assert "anees" in values and not any(_timing(k) for k in values)  # runtime: not measured
    imp = run.meta["imported"]
    assert imp["format"] == "tumcov" and imp["files"][0]["path"] == str(f.resolve())
    assert run.meta["filter_id"] == "external" and run.meta["filter"] == "external[name=tumcov]"


def test_tum_pose_only_gives_the_pose_metrics_and_no_consistency(ekf: Any, tmp_path: Path) -> None:
    res, rec, truth = ekf
    t, mean = last_per_time(rec.t, rec.mean)
    import_system(res, "tum", "office", [0], [str(write_tum_rows(tmp_path / "ekf.tum", t, mean))])
    run = _imported(res, "tum")
    assert run.meta["covariance"] is False
    # no --sensors: every event type the dataset has (never credited with needing less than it may have used)
    assert run.meta["imported"]["sensors_stated"] is False
    assert "LaserScan" in run.meta["filter_traits"]["sensors"] and "Odometry" in run.meta["filter_traits"]["sensors"]
    values = run_metrics(run, truth)
    _assert_same(run_metrics(rec, truth), values, pose_only=True)
    assert not any(_consistency(k) for k in values)


def test_openvins_gives_the_native_metrics_of_its_block_diagonal_covariance(ekf: Any, tmp_path: Path) -> None:
    res, rec, truth = ekf
    import_system(res, "ov", "office", [0], [str(write_openvins(tmp_path / "ov.txt", rec.t, rec.mean, rec.cov))])
    # the format has no position-heading terms: the native run with those set to 0 is what it can carry
    cov = rec.cov.copy()
    cov[:, 0, 2] = cov[:, 2, 0] = cov[:, 1, 2] = cov[:, 2, 1] = 0.0
    native = RunRecord(rec.meta, rec.t, rec.mean, cov, rec.kind, rec.step_ns, rec.diagnostics, rec.extra)
    _assert_same(run_metrics(native, truth), run_metrics(_imported(res, "ov"), truth))


@pytest.mark.parametrize(("fmt", "msgtype"), [("rosbag2", "pose"), ("rosbag1", "odometry")])
def test_bags_of_poses_on_the_exported_clock_give_the_native_metrics(
    ekf: Any, tmp_path: Path, fmt: str, msgtype: str
) -> None:
    res, rec, truth = ekf
    t, mean, cov = last_per_time(rec.t, rec.mean, rec.cov)
    kind = {"msgtype": ODOM, "topic": "/odometry/filtered"} if msgtype == "odometry" else {}
    bag = write_bag(
        tmp_path / ("out.bag" if fmt == "rosbag1" else "out"), fmt, (t, mean, cov), offset=SIM_EPOCH_S, **kind
    )
    name = f"{fmt}{msgtype}"
    import_system(res, name, "office", [0], [str(bag)], description="round trip", sensors=("LandmarkObservations",))
    run = _imported(res, name)
    assert run.meta["imported"]["clock_offset_s"] == SIM_EPOCH_S
    assert run.meta["filter_traits"]["sensors"] == ["LandmarkObservations"]
    _assert_same(run_metrics(rec, truth), run_metrics(run, truth))


def test_verify_checks_the_digests_of_imported_runs(ekf: Any, tmp_path: Path) -> None:
    res, rec, _ = ekf
    f = write_tumcov(tmp_path / "v.txt", rec.t, rec.mean, rec.cov)
    import_system(res, "ver", "office", [0], [str(f)])
    meta = _imported(res, "ver").meta
    assert digest_problems(meta) == []
    result = verify(Store(res), fraction=1.0)
    assert result.passed, result.problems()
    f.write_text(f.read_text().replace("\n", "\n\n", 1))  # one byte more: another file
    assert len(digest_problems(meta)) == 1
    result = verify(Store(res), fraction=1.0)
    assert not result.passed
    assert any("external[name=ver]" in line and "sha256" in line for line in result.problems())


def _pf_native_with_clouds(seed: int) -> tuple[RunRecord, TruthRecord, list[tuple[float, np.ndarray, np.ndarray]]]:
    """``pf`` on ``room``, with the belief samples its scorer drew, each at the time of the row it was drawn for."""
    ds = make_dataset("room", seed)
    flt = make_filter("pf[particles=200]")
    now = [min(ds.events[0].t, float(ds.ground_truth.t[0]))]
    clouds: list[tuple[float, np.ndarray, np.ndarray]] = []
    step, update, sample = flt.predict, flt.update, flt.belief_sample

    def predict(ev: Any) -> None:
        now[0] = ev.t
        step(ev)

    def upd(ev: Any) -> None:
        now[0] = ev.t
        update(ev)

    def belief_sample(rng: np.random.Generator) -> Any:
        got = sample(rng)
        if got is not None:
            clouds.append((now[0], np.array(got[0]), np.array(got[1])))
        return got

    flt.predict, flt.update, flt.belief_sample = predict, upd, belief_sample
    run = FilterPass(flt, ds, filter_rng("pf", "room", seed), belief_rng("pf", "room", seed))
    run.advance(len(ds.events))
    tr = run.finish()
    meta = {"filter": "pf", "dataset": "room", "seed": seed, "status": tr.status}
    rec = RunRecord(meta, tr.t, tr.mean, tr.cov, tr.kind, tr.step_ns, tr.diagnostics, tr.extra)
    return rec, TruthRecord.from_dataset(ds, seed, {}), clouds


def test_particle_clouds_give_the_particle_filters_scores(tmp_path: Path) -> None:
    rec, truth, clouds = _pf_native_with_clouds(0)
    assert all(k in rec.extra for k in SAMPLE_SCORE_KEYS) and len(clouds) > 10
    t, mean, cov = last_per_time(rec.t, rec.mean, rec.cov)
    bag = write_bag(tmp_path / "amcl", "rosbag2", (t, mean, cov), clouds=clouds)
    import_system(tmp_path / "res", "amcl", "room", [0], [str(bag)])
    store = Store(tmp_path / "res")
    run = store.read_run(store.run_dir("room", "external[name=amcl]", 0))
    assert run.meta["imported"]["particle_clouds"] == len(clouds)
    values = run_metrics(run, store.read_truth("room", 0))
    _assert_same(run_metrics(rec, truth), values)
    assert set(SCORE_IDS) <= set(values)
    # the clouds alone: the scores are the same, the rows are the clouds' moments
    only = write_bag(tmp_path / "cloudsonly", "rosbag2", None, clouds=clouds)
    import_system(tmp_path / "res", "clouds", "room", [0], [str(only)])
    run2 = store.read_run(store.run_dir("room", "external[name=clouds]", 0))
    v2 = run_metrics(run2, store.read_truth("room", 0))
    for k in SCORE_IDS:
        np.testing.assert_allclose(v2[k], values[k], rtol=RTOL, atol=0, err_msg=k)
    assert json.loads((store.run_dir("room", "external[name=clouds]", 0) / "meta.json").read_text())["covariance"]


def test_the_report_collects_imported_runs_with_and_without_covariance(ekf: Any, tmp_path: Path) -> None:
    from locbench.report.collect import collect

    res, rec, _ = ekf
    t, mean = last_per_time(rec.t, rec.mean)
    import_system(res, "rep_pose", "office", [0], [str(write_tum_rows(tmp_path / "p.tum", t, mean))])
    import_system(res, "rep_cov", "office", [0], [str(write_tumcov(tmp_path / "c.txt", rec.t, rec.mean, rec.cov))])
    col = collect(Store(res))
    assert not col.broken
    m = col.metrics
    for name in ("external[name=rep_pose]", "external[name=rep_cov]"):
        ids = set(m.loc[m["filter"] == name, "metric"])
        assert {"ate_m", "heading_rmse_rad", "failed"} <= ids
        assert not any(_timing(k) for k in ids)
        assert name in col.filters and not col.filters[name].baseline
    assert ("office", "external[name=rep_cov]") in col.nees
    assert ("office", "external[name=rep_pose]") not in col.nees
    assert ("office", "external[name=rep_cov]") in col.health  # the spread it reported: the lost detection's input
