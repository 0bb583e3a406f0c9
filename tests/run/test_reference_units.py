"""Runtimes that transfer: the reference workload, the provenance of time, reference units and interleaved timing."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from locbench.datasets.dataset import Trajectory2D
from locbench.evaluate.metrics import REFERENCE_TIMES, reference_units, run_metrics
from locbench.registry import DATASETS, build_dataset, resolve_dataset, resolve_filter
from locbench.run import provenance, reference_workload
from locbench.run.runner import execute_task, plan_sweep, run_key, run_sweep, slice_stops
from locbench.run.store import KIND_NAMES, RunRecord, TruthRecord

FILTERS = ("odometry", "ekf_landmarks", "ekf_landmarks[association=nearest]")


def test_reference_workload_does_the_same_work_every_time() -> None:
    first = reference_workload.run_once()
    assert math.isfinite(first)
    assert reference_workload.run_once() == first  # bit for bit: the same operations on the same inputs
    piece = reference_workload.run_piece()
    assert reference_workload.run_piece() == piece and first == sum([piece] * reference_workload.PIECES)


def test_reference_measure_is_the_median_of_its_repeats() -> None:
    m = reference_workload.measure(repeats=3, warmup=0)
    assert len(m.runs_s) == 3 and all(t > 0 for t in m.runs_s)
    assert m.wall_s == sorted(m.runs_s)[1] and m.cpu_s > 0
    with pytest.raises(ValueError, match="repeats"):
        reference_workload.measure(repeats=0)


def test_machine_provenance_has_the_keys_with_sane_types() -> None:
    m = provenance.machine()
    assert isinstance(m["reference_s"], float) and 0 < m["reference_s"] < 60
    assert isinstance(m["reference_cpu_s"], float) and 0 < m["reference_cpu_s"] < 60
    assert len(m["reference_runs_s"]) == reference_workload.REPEATS
    assert isinstance(m["cpu_model"], str) and m["cpu_model"]
    counts = m["cpu_count"]
    assert set(counts) == {"logical", "affinity"}
    assert all(v is None or (isinstance(v, int) and v >= 1) for v in counts.values())
    for load in (m["load_avg"], m["reference_load_avg"]):
        assert load is None or (len(load) == 3 and all(isinstance(x, float) and x >= 0 for x in load))
    # measured once per process: a second call reuses it
    assert provenance.machine()["reference_s"] == m["reference_s"]


def test_every_stored_run_records_the_machine_and_keeps_its_run_key(tmp_path: Path) -> None:
    results = str(tmp_path / "results")
    plan = plan_sweep([(FILTERS[:2], ["room"], [0])], results)
    run_sweep(plan)
    for f in FILTERS[:2]:
        meta = json.loads((tmp_path / "results" / "runs" / "room" / f / "seed-0000" / "meta.json").read_text())
        assert {"reference_s", "cpu_model", "cpu_count", "load_avg"} <= set(meta)
        assert meta["reference_s"] == provenance.machine()["reference_s"]
        # provenance is not part of the key: the key is that of the config, dataset and seed alone
        assert meta["run_key"] == run_key(resolve_filter(f), resolve_dataset("room"), 0)
    again = plan_sweep([(FILTERS[:2], ["room"], [0])], results)
    assert not again.tasks and len(again.cached) == 2  # stored runs stay up to date


def test_reference_units_divide_times_and_scale_the_realtime_factor() -> None:
    raw = {k: 10.0 * (i + 1) for i, k in enumerate(REFERENCE_TIMES)} | {"realtime_factor": 50.0, "ate_m": 0.1}
    ref = reference_units(raw, 0.25)
    assert ref == {f"{k}_ref": raw[k] / 0.25 for k in REFERENCE_TIMES} | {"realtime_factor_ref": 50.0 * 0.25}
    # with the CPU time: the per-call medians over it, the totals (mean, p95, real-time factor) over the wall time
    both = reference_units(raw, 0.25, 0.1)
    for k in REFERENCE_TIMES:
        assert both[f"{k}_ref"] == raw[k] / (0.1 if k.endswith("_median") else 0.25)
    assert both["realtime_factor_ref"] == 50.0 * 0.25
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="reference_s"):
            reference_units(raw, bad)
        with pytest.raises(ValueError, match="reference_cpu_s"):
            reference_units(raw, 0.25, bad)


def _run_and_truth(reference_s: object, reference_cpu_s: object = None) -> tuple[RunRecord, TruthRecord]:
    t = np.arange(0.0, 10.01, 0.5)
    gt = Trajectory2D(t, np.column_stack([0.1 * t, 0.0 * t]), np.zeros_like(t))
    kinds = np.full(t.shape, KIND_NAMES.index("Odometry"), dtype=np.int8)
    kinds[0] = KIND_NAMES.index("reset")
    kinds[1::4] = KIND_NAMES.index("LandmarkObservations")
    step_ns = np.arange(t.size, dtype=np.int64) * 1000 + 5000
    meta: dict[str, object] = {"status": "ok", "reference_s": reference_s, "reference_cpu_s": reference_cpu_s}
    cov = np.broadcast_to(np.eye(3) * 0.01, (t.size, 3, 3)).copy()
    run = RunRecord(meta, t, gt.poses + 0.01, cov, kinds, step_ns)
    return run, TruthRecord("w", 0, gt, None, (), 10.0, {})


def test_run_metrics_give_every_timing_in_reference_units_too() -> None:
    out = run_metrics(*_run_and_truth(0.4, 0.1))
    for k in REFERENCE_TIMES:
        assert out[f"{k}_ref"] == out[k] / (0.1 if k.endswith("_median") else 0.4)
    assert out["realtime_factor_ref"] == out["realtime_factor"] * 0.4
    wall_only = run_metrics(*_run_and_truth(0.4))  # a record without the CPU time: the wall time throughout
    assert all(wall_only[f"{k}_ref"] == wall_only[k] / 0.4 for k in REFERENCE_TIMES)
    base = run_metrics(*_run_and_truth(None))
    assert not any(k.endswith("_ref") for k in base)  # a run stored before reference_s: raw values only
    assert {k: v for k, v in out.items() if not k.endswith("_ref")} == base
    assert not any(k.endswith("_ref") for k in run_metrics(*_run_and_truth(True)))  # not a time


def test_interleaved_execution_gives_the_same_estimates() -> None:
    plan = plan_sweep([(FILTERS, ["room"], [1])], "unused-results", force=True, slice_s=3.0)
    task = plan.tasks[0]
    assert task.slice_s == 3.0
    inter = execute_task(task)
    seq = execute_task(dataclasses.replace(task, slice_s=0.0))
    assert [r.meta["filter"] for r in inter.runs] == [r.meta["filter"] for r in seq.runs] == list(FILTERS)
    for a, b in zip(inter.runs, seq.runs, strict=True):
        assert a.status == b.status == "ok"
        for name in ("t", "mean", "cov", "kind"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
        assert a.diagnostics.keys() == b.diagnostics.keys()
        for k in a.diagnostics:
            np.testing.assert_array_equal(a.diagnostics[k], b.diagnostics[k])
        assert a.meta["wall_s"] > 0 and a.meta["n_rows"] == b.meta["n_rows"]
        # the task's own reference (pieces between the slices), the sweep's kept beside it
        assert a.meta["reference_pieces"] >= 1 and a.meta["reference_s"] > 0 and a.meta["reference_cpu_s"] > 0
        assert a.meta["reference_sweep_s"] == b.meta["reference_s"] == provenance.machine()["reference_s"]
        assert "reference_pieces" not in b.meta


def test_slice_stops_cover_the_events_in_order() -> None:
    dr = resolve_dataset("room")
    ds = build_dataset(DATASETS.load(dr.id), dr, 0)
    stops = slice_stops(ds, 5.0)
    assert stops[-1] == len(ds.events) and stops == sorted(set(stops)) and stops[0] > 0
    times = np.array([e.t for e in ds.events])
    for a, b in zip([0, *stops[:-1]], stops, strict=True):
        assert times[b - 1] - times[a] < 5.0 + 1e-9  # one slice spans less than slice_s of data
    assert slice_stops(ds, 1e6) == [len(ds.events)]


def _collected(with_ref: bool) -> object:
    from locbench.report.collect import Collected, describe_filter, frame

    rows = []
    for seed in range(2):
        for f, rtf, ate, ref_s in (("odometry", 900.0, 0.5, 0.5), ("ekf_landmarks", 300.0, 0.05, 0.25)):
            rows += [("room", f, seed, "ate_m", ate), ("room", f, seed, "realtime_factor", rtf)]
            rows += [("room", f, seed, "update_us_median", 40.0), ("room", f, seed, "failed", 0.0)]
            if with_ref:
                rows += [("room", f, seed, "realtime_factor_ref", rtf * ref_s)]
                rows += [("room", f, seed, "update_us_median_ref", 40.0 / ref_s)]
    names = ("odometry", "ekf_landmarks")
    return Collected(metrics=frame(rows), filters={n: describe_filter(n) for n in names})


def test_pareto_x_axis_is_in_reference_units() -> None:
    from locbench.report.context import Report
    from locbench.report.sections.runtime import pareto_points
    from locbench.report.timing import PARETO_X, PARETO_X_RAW, pareto_xlabel

    rep = Report(_collected(True))  # type: ignore[arg-type]
    assert rep.pareto_x == PARETO_X
    pts = {p.label: p.x for p in pareto_points(rep, "room", "ate_m")}
    assert pts == {"odometry": 450.0, "ekf_landmarks": 75.0}  # rtf * reference_s, not the raw 900 and 300
    assert pareto_xlabel(rep.pareto_x) == "real-time factor (ref x)"
    old = Report(_collected(False))  # type: ignore[arg-type]
    assert old.pareto_x == PARETO_X_RAW  # runs stored before reference_s: the raw axis, labelled so
    assert {p.label: p.x for p in pareto_points(old, "room", "ate_m")} == {"odometry": 900.0, "ekf_landmarks": 300.0}


def test_timing_cells_show_raw_and_reference_units() -> None:
    from locbench.report.timing import machine_line, ref_footnote, with_ref

    df = _collected(True).metrics  # type: ignore[attr-defined]
    sub = df[df["filter"] == "ekf_landmarks"]
    assert with_ref("40.0", sub, "update_us_median") == "40.0 (ref 160)"
    assert with_ref("300", sub[sub["metric"] != "update_us_median_ref"], "update_us_median") == "300"
    assert ref_footnote([["a", "40.0 (ref 160)"]]) and not ref_footnote([["a", "40.0"]])
    metas = [provenance.machine() | {"filter": "x"}, {"filter": "old"}]
    line = machine_line(metas)
    assert line.startswith("machine: ") and "reference workload" in line and "1 measurements" in line
    assert machine_line([{"filter": "old"}]).startswith("machine: not recorded")


def test_cli_interleave_runs_and_refuses_a_bad_slice(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from locbench.cli import main

    res = str(tmp_path / "r")
    smoke = ["run", "--filter", "odometry", "ekf_landmarks", "--dataset", "room", "--no-progress", "--results", res]
    for bad in ("-1", "nan", "1e9"):
        assert main([*smoke, "--interleave", bad]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "--interleave must be in [0, 3600] s of data" in err, err
    assert main([*smoke, "--interleave"]) == 0
    meta = json.loads((tmp_path / "r" / "runs" / "room" / "ekf_landmarks" / "seed-0000" / "meta.json").read_text())
    assert meta["reference_pieces"] >= 1 and meta["reference_s"] > 0
