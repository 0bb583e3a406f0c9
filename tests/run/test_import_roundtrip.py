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
from locbench.evaluate.metrics import LATENCY_DIAGNOSTIC, LATENCY_S_MEDIAN, LATENCY_S_P95, run_metrics
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
    return k.startswith(("predict_us", "update_us", "realtime_factor", "latency_")) or k.endswith("_ref")


def _comparable(values: dict[str, float]) -> dict[str, float]:
    return {k: v for k, v in values.items() if not _timing(k) and k not in DIAGNOSTICS}


def _assert_same(native: dict[str, float], imported: dict[str, float], pose_only: bool = False) -> None:
    want = {k: v for k, v in _comparable(native).items() if not (pose_only and _consistency(k))}
    # a bag's latency is the imported run's own (a native run has call times instead)
    assert {k for k in imported if not k.startswith("latency_")} == set(want)
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
    # a text file has no record times: no latency, runtime not measured
    assert LATENCY_DIAGNOSTIC not in run.diagnostics and not any(_timing(k) for k in values)
    assert run.meta["imported"]["latency"] == "not measured: the format has no record times"


def test_openvins_gives_the_native_metrics_of_its_block_diagonal_covariance(ekf: Any, tmp_path: Path) -> None:
    res, rec, truth = ekf
    import_system(res, "ov", "office", [0], [str(write_openvins(tmp_path / "ov.txt", rec.t, rec.mean, rec.cov))])
    # the format has no position-heading terms: the native run with those set to 0 is what it can carry
    cov = rec.cov.copy()
    cov[:, 0, 2] = cov[:, 2, 0] = cov[:, 1, 2] = cov[:, 2, 1] = 0.0
    native = RunRecord(rec.meta, rec.t, rec.mean, cov, rec.kind, rec.step_ns, rec.diagnostics, rec.extra)
    _assert_same(run_metrics(native, truth), run_metrics(_imported(res, "ov"), truth))


def _exported_clock_bag(rec: RunRecord, folder: Path, fmt: str, msgtype: str, **options: Any) -> Path:
    """A native run's poses (the last row of each time) as a ``fmt`` bag of ``msgtype`` ("pose" or "odometry") on
    an exported bag's clock (+1000 s)."""
    t, mean, cov = last_per_time(rec.t, rec.mean, rec.cov)
    kind = {"msgtype": ODOM, "topic": "/odometry/filtered"} if msgtype == "odometry" else {}
    path = folder / ("out.bag" if fmt == "rosbag1" else "out")
    return write_bag(path, fmt, (t, mean, cov), offset=SIM_EPOCH_S, **kind, **options)


@pytest.mark.parametrize(("fmt", "msgtype"), [("rosbag2", "pose"), ("rosbag1", "odometry")])
def test_bags_of_poses_on_the_exported_clock_give_the_native_metrics(
    ekf: Any, tmp_path: Path, fmt: str, msgtype: str
) -> None:
    res, rec, truth = ekf
    bag = _exported_clock_bag(rec, tmp_path, fmt, msgtype)
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

    def belief_sample(rng: np.random.Generator, size: int) -> Any:
        got = sample(rng, size)
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


def _delays_ns(n: int) -> np.ndarray:
    """Publish delays of 5 to 45 ms, in ns: below the office events' 50 ms spacing, so the record order is the
    stamps'."""
    return np.random.default_rng(7).integers(5_000_000, 45_000_000, n)


@pytest.mark.parametrize(("fmt", "msgtype"), [("rosbag2", "pose"), ("rosbag1", "odometry")])
def test_a_bag_with_publish_delays_gives_exactly_those_latencies(
    ekf: Any, tmp_path: Path, fmt: str, msgtype: str
) -> None:
    res, rec, truth = ekf
    delays = _delays_ns(last_per_time(rec.t)[0].size)
    # on the exported bag's clock (+1000 s): the shift is in both times and cancels in the latency
    bag = _exported_clock_bag(rec, tmp_path, fmt, msgtype, delays_ns=delays.tolist())
    name = f"late{fmt}"
    import_system(res, name, "office", [0], [str(bag)])
    run = _imported(res, name)
    want = delays.astype(np.float64) / 1e9
    np.testing.assert_array_equal(run.diagnostics[LATENCY_DIAGNOSTIC], want)  # our integer-ns arithmetic, exact
    assert run.meta["imported"]["latency"].startswith("measured")
    values = run_metrics(run, truth)
    assert values[LATENCY_S_MEDIAN] == float(np.median(want))
    assert values[LATENCY_S_P95] == float(np.percentile(want, 95.0))
    assert 0.005 <= values[LATENCY_S_MEDIAN] <= values[LATENCY_S_P95] < 0.045
    # the call-time metrics stay unmeasured, every other metric is the native run's
    assert not any(k.startswith(("predict_us", "update_us", "realtime_factor")) for k in values)
    _assert_same(run_metrics(rec, truth), values)


def test_particle_clouds_alone_give_the_clouds_latency(tmp_path: Path) -> None:
    _, _, clouds = _pf_native_with_clouds(0)
    bag = write_bag(
        tmp_path / "late_clouds", "rosbag2", None, clouds=clouds, cloud_delay_ns=120_000_000, offset=SIM_EPOCH_S
    )
    import_system(tmp_path / "res", "lc", "room", [0], [str(bag)])
    store = Store(tmp_path / "res")
    run = store.read_run(store.run_dir("room", "external[name=lc]", 0))
    np.testing.assert_array_equal(run.diagnostics[LATENCY_DIAGNOSTIC], np.full(run.t.size, 0.12))
    values = run_metrics(run, store.read_truth("room", 0))
    assert values[LATENCY_S_MEDIAN] == values[LATENCY_S_P95] == 0.12


def test_record_times_on_another_clock_leave_the_latency_unmeasured(ekf: Any, tmp_path: Path) -> None:
    res, rec, truth = ekf
    # recorded on a wall clock (2026) while the stamps are the played-back sim clock: not a delay
    wall = [1_790_000_000 * 10**9] * last_per_time(rec.t)[0].size
    bag = _exported_clock_bag(rec, tmp_path, "rosbag2", "pose", delays_ns=wall)
    import_system(res, "wall", "office", [0], [str(bag)])
    run = _imported(res, "wall")
    assert LATENCY_DIAGNOSTIC not in run.diagnostics
    assert "another clock" in run.meta["imported"]["latency"]
    assert not any(_timing(k) for k in run_metrics(run, truth))


def test_the_summary_shows_the_latency_of_a_bag_import_and_a_dash_for_the_built_in(ekf: Any, tmp_path: Path) -> None:
    from locbench.report.collect import collect
    from locbench.report.context import Report
    from locbench.report.doc import Table
    from locbench.report.sections.summary import summary_blocks

    res, rec, _ = ekf
    delays = np.full(last_per_time(rec.t)[0].size, 25_000_000)
    bag = _exported_clock_bag(rec, tmp_path, "rosbag2", "pose", delays_ns=delays.tolist())
    import_system(res, "sum_lat", "office", [0], [str(bag)])
    tables = [b for b in summary_blocks(Report(collect(Store(res))), "office") if isinstance(b, Table)]
    # the defaults' block (and the sweeps' when there are any) share the columns
    rows = {r[0]: dict(zip(t.header, r, strict=True)) for t in tables for r in t.rows}
    assert rows["`external[name=sum_lat]`"]["latency median (ms)"].replace("**", "") == "25"
    assert rows["`ekf_landmarks`"]["latency median (ms)"] == "-"  # a built-in filter has call times, not a latency
    assert rows["`ekf_landmarks`"]["update median (us)"] != "-"
