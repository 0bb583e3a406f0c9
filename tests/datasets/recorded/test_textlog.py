"""The plain-text log (``textlog``): export round trips bit for bit, a hand-written log loads, bad input is refused
with one line naming the file, the line and the field, and ``locbench run`` / ``report`` take an exported folder."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from input_support import one_line as _clean
from range_only_support import INITIAL, SENSORS, WORLD, scenario

from locbench.cli import main
from locbench.core.errors import MAX_MESSAGE_CHARS, ConfigError
from locbench.core.events import LandmarkObservations, LaserScan, Odometry, PoseFix, RangeObservations
from locbench.datasets.dataset import Dataset, Trajectory2D
from locbench.datasets.recorded.files import RecordedDataError
from locbench.datasets.recorded.textlog import MANIFEST, VERSION, _cached_events, load_textlog, write_textlog
from locbench.registry import make_dataset, make_filter
from locbench.report.site import site_markdown
from locbench.run.export import export_textlog
from locbench.run.filter_pass import run_filter


def _same_events(a: Dataset, b: Dataset) -> None:
    assert len(a.events) == len(b.events)
    for x, y in zip(a.events, b.events, strict=True):
        assert type(x) is type(y)
        for f in dataclasses.fields(x):
            u, v = getattr(x, f.name), getattr(y, f.name)
            if isinstance(u, np.ndarray):
                assert u.dtype == v.dtype and np.array_equal(u, v), (f.name, x.t)
            else:
                assert u == v and type(u) is type(v), (f.name, x.t, u, v)


def _same_world(a: Dataset, b: Dataset) -> None:
    for name in ("occupancy", "landmarks", "lines"):
        u, v = getattr(a.world, name), getattr(b.world, name)
        assert (u is None) == (v is None), name
    if a.world.occupancy is not None and b.world.occupancy is not None:
        ga, gb = a.world.occupancy, b.world.occupancy
        assert np.array_equal(ga.occupancy, gb.occupancy)
        assert (ga.resolution, ga.origin, ga.occupied_thresh, ga.free_thresh) == (
            gb.resolution,
            gb.origin,
            gb.occupied_thresh,
            gb.free_thresh,
        )
    if a.world.landmarks is not None and b.world.landmarks is not None:
        assert np.array_equal(a.world.landmarks.ids, b.world.landmarks.ids)
        assert np.array_equal(a.world.landmarks.xy, b.world.landmarks.xy)
    if a.world.lines is not None and b.world.lines is not None:
        assert np.array_equal(a.world.lines.segments, b.world.lines.segments)


def _same_estimates(flt: str, a: Dataset, b: Dataset) -> None:
    ta = run_filter(make_filter(flt), a, np.random.default_rng(5), np.random.default_rng(6))
    tb = run_filter(make_filter(flt), b, np.random.default_rng(5), np.random.default_rng(6))
    assert ta.status == tb.status == "ok", (ta.message, tb.message)
    assert np.array_equal(ta.t, tb.t) and np.array_equal(ta.mean, tb.mean) and np.array_equal(ta.cov, tb.cov), flt


def _round_trip(ds: Dataset, back: Dataset) -> None:
    _same_events(ds, back)
    _same_world(ds, back)
    assert back.sensors == ds.sensors
    assert np.array_equal(back.initial.mean, ds.initial.mean) and np.array_equal(back.initial.cov, ds.initial.cov)
    gt, bt = ds.ground_truth, back.ground_truth
    assert np.array_equal(gt.t, bt.t) and np.array_equal(gt.xy, bt.xy)
    np.testing.assert_allclose(bt.theta, gt.theta, atol=1e-15, rtol=0)  # through quaternions: within round-off
    assert back.kidnaps == ds.kidnaps and back.truth_label == ds.truth_label
    if ds.waypoints is not None:
        assert back.waypoints is not None
        assert np.array_equal(back.waypoints.t, ds.waypoints.t) and np.array_equal(back.waypoints.xy, ds.waypoints.xy)
    assert back.declared <= {type(e) for e in back.events}


def test_room_exports_and_reads_back_bit_for_bit(tmp_path: Path) -> None:
    folder, notes = export_textlog("room", 0, tmp_path / "room")
    assert notes == []
    ds, back = make_dataset("room", 0), load_textlog(folder)
    _round_trip(ds, back)
    assert back.metadata["exported_from"] == "room seed 0" and back.metadata["reference_kind"] == "simulation"
    assert back.metadata["warnings"] == [] and back.metadata["format"] == f"locbench-textlog v{VERSION}"
    for flt in ("odometry", "ekf_landmarks", "pf[particles=200]"):
        _same_estimates(flt, ds, back)


def test_every_sensor_and_a_kidnap_read_back_bit_for_bit(tmp_path: Path) -> None:
    from locbench.datasets.dataset import Kidnap

    ds = make_dataset("tiny_circle", 2)
    assert {type(e) for e in ds.events} == {Odometry, LaserScan, LandmarkObservations, PoseFix}
    ds = dataclasses.replace(ds, kidnaps=(Kidnap(7.5, (0.5, -0.25, 0.1)),))
    assert write_textlog(ds, tmp_path / "tiny", source="tiny_circle seed 2") == []
    back = load_textlog(tmp_path / "tiny")
    _round_trip(ds, back)
    for flt in ("ekf_landmarks", "ekf_lines", "pf[use_laser=true]"):
        _same_estimates(flt, ds, back)


def test_range_only_and_relations_read_back(tmp_path: Path) -> None:
    from locbench.datasets.dataset import Relations, sort_events

    events, t, truth = scenario(n=120)
    rel = Relations(t[:-10].copy(), t[10:].copy(), np.tile([0.5, 0.01, 0.1], (t.shape[0] - 10, 1)))
    ds = Dataset(
        "ranges",
        {},
        sort_events(list(events)),
        Trajectory2D(
            np.concatenate([[0.0], t]), np.vstack([[0, 0], truth[:, :2]]), np.concatenate([[0.0], truth[:, 2]])
        ),
        INITIAL,
        WORLD,
        SENSORS,
        relations=rel,
    )
    ds.check()
    assert write_textlog(ds, tmp_path / "r") == []
    back = load_textlog(tmp_path / "r")
    assert {type(e) for e in back.events} == {Odometry, RangeObservations}
    _round_trip(ds, back)
    assert back.relations is not None and np.array_equal(back.relations.delta, rel.delta)
    _same_estimates("ekf_landmarks", ds, back)


def test_cli_export_then_run_and_report(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "log"
    assert main(["export", "--format", "textlog", "--dataset", "tiny_line", "--seed", "1", "--out", str(out)]) == 0
    assert f"read it as textlog[path={out}]" in capsys.readouterr().out
    res = tmp_path / "res"
    spec = f"textlog[path={out}]"
    rc = main(
        ["run", "--dataset", spec, "--filter", "odometry", "ekf_landmarks", "--results", str(res), "--no-progress"]
    )
    assert rc == 0
    assert "2 runs" in capsys.readouterr().out
    assert main(["report", "--results", str(res)]) == 0
    import pandas as pd

    df = pd.read_parquet(res / "summary" / "metrics.parquet")
    rows = df[df["dataset"] == spec]
    assert set(rows["filter"]) == {"odometry", "ekf_landmarks"}
    assert {"ate_m", "anees", "waypoint_1_error_m"} <= set(rows["metric"])  # truth and waypoints came along
    # the exported numbers equal the original's for the deterministic filters
    tl = make_dataset("tiny_line", 1)
    trace = run_filter(make_filter("ekf_landmarks"), tl, np.random.default_rng(0))
    from locbench.evaluate.metrics import align, ate

    want = ate(align(trace.t, trace.mean, tl.ground_truth.t, tl.ground_truth.poses))
    got = float(rows[(rows["filter"] == "ekf_landmarks") & (rows["metric"] == "ate_m")]["value"].iloc[0])
    assert got == pytest.approx(want, rel=1e-9)


def test_cli_export_arguments_are_checked(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["export", "--format", "textlog", "--dataset", "room"]) == 2
    assert "--format textlog writes one dataset" in capsys.readouterr().err
    assert main(["export", "--seed", "3", "--results", str(tmp_path)]) == 2
    assert "--seed goes with --format textlog" in capsys.readouterr().err
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "other.txt").write_text("x")
    assert main(["export", "--format", "textlog", "--dataset", "tiny_line", "--out", str(tmp_path / "full")]) == 2
    assert "not empty and holds no textlog.json" in capsys.readouterr().err


# --- a hand-written log ----------------------------------------------------------------------------------------


def _write_log(folder: Path, events: list[dict[str, Any]], manifest: dict[str, Any] | None = None) -> Path:
    """A small log: a robot driving 2 m along x in 2 s with twist-only odometry, two landmarks, a fix."""
    folder.mkdir(parents=True, exist_ok=True)
    man = {"format": "locbench-textlog", "version": 1, "landmarks": "lm.csv", "sensors": {"range_sigma_m": 0.1}}
    man.update(manifest or {})
    (folder / MANIFEST).write_text(json.dumps(man))
    (folder / "lm.csv").write_text("# id, x, y\n1, 2.0, 1.0\n2, 0.0, -1.0\n")
    truth = "".join(f"{k / 10!r} {k / 10!r} 0 0 0 0 0 1\n" for k in range(21))
    (folder / "truth.tum").write_text("# t x y z qx qy qz qw\n" + truth)
    (folder / "events.jsonl").write_text("".join(json.dumps(e) + "\n" for e in events))
    return folder


def _twist_events() -> list[dict[str, Any]]:
    out: list[dict[str, Any]] = [{"t": k / 10, "type": "odometry", "v": 1.0, "omega": 0.0} for k in range(1, 21)]
    out[0]["dt"] = 0.1
    out.insert(5, {"t": 0.5, "type": "landmarks", "ids": [1, -1], "ranges": [1.9, 1.2], "bearings": [0.5, -1.1]})
    out.insert(8, {"t": 0.7, "type": "ranges", "ids": [2], "ranges": [1.2]})
    out.insert(10, {"t": 0.9, "type": "fix", "z": [0.9, 0.0], "sigma": [0.5, 0.5]})
    return out


def test_a_hand_written_log_with_twist_only_odometry(tmp_path: Path) -> None:
    ds = load_textlog(_write_log(tmp_path / "log", _twist_events()))
    odo = [e for e in ds.events if isinstance(e, Odometry)]
    assert len(odo) == 20 and all(e.dt == pytest.approx(0.1) and e.dx == pytest.approx(0.1) for e in odo)
    assert [type(e).__name__ for e in ds.events[4:8]] == ["Odometry", "LandmarkObservations", "Odometry", "Odometry"]
    fix = next(e for e in ds.events if isinstance(e, PoseFix))
    np.testing.assert_array_equal(fix.cov, np.diag([0.25, 0.25]))
    assert ds.sensors.range_sigma_m == 0.1 and ds.metadata["warnings"] == []
    np.testing.assert_allclose(np.sqrt(np.diag(ds.initial.cov)), 0.05)
    trace = run_filter(make_filter("ekf_landmarks"), ds, np.random.default_rng(0))
    assert trace.status == "ok"


def test_a_twist_that_contradicts_the_increments_is_a_warning(tmp_path: Path) -> None:
    events = [
        {"t": k / 10, "type": "odometry", "dx": 0.1, "dy": 0.0, "dtheta": 0.0, "v": 0.0, "omega": 0.0, "dt": 0.1}
        for k in range(1, 21)
    ]
    events.append({"t": 2.5, "type": "odometry", "dx": 0.1, "dy": 0.0, "dtheta": 0.0})  # after the truth: left out
    ds = load_textlog(_write_log(tmp_path / "log", events))
    warnings = ds.metadata["warnings"]
    assert len(warnings) == 2 and ds.metadata["events_outside_truth_span"] == 1
    assert "1 of 21 events lie outside the ground truth's span" in warnings[0]
    assert "odometry twist contradicts its pose: the twist is zero in 20 of the 20 steps" in warnings[1]


BAD_EVENTS = [
    ("not json", "{t: 1}", ("events.jsonl:2:", "not JSON")),
    ("unknown type", '{"t": 0.1, "type": "imu"}', ("events.jsonl:2:", "field 'type' is 'imu'", "odometry, scan")),
    ("unknown field", '{"t": 0.1, "type": "odometry", "dx": 1, "dy": 0, "dtheta": 0, "vx": 1}', ("field 'vx'",)),
    ("text number", '{"t": 0.1, "type": "odometry", "dx": "1", "dy": 0, "dtheta": 0}', ("'dx'", "expected a number")),
    ("nan", '{"t": 0.1, "type": "odometry", "dx": NaN, "dy": 0, "dtheta": 0}', ("events.jsonl:2:", "NaN")),
    ("half increment", '{"t": 0.1, "type": "odometry", "dx": 0.1, "dy": 0}', ("'dtheta'", "together")),
    ("huge step", '{"t": 0.1, "type": "odometry", "dx": 1e9, "dy": 0, "dtheta": 0}', ("'dx'", "[-100, 100] m")),
    ("bool", '{"t": true, "type": "ranges", "ids": [1], "ranges": [1.0]}', ("field 't'", "expected a number")),
    ("id unknown", '{"t": 0.1, "type": "ranges", "ids": [7], "ranges": [1.0]}', ("id 7 is not a known landmark",)),
    ("id count", '{"t": 0.1, "type": "ranges", "ids": [1, 2], "ranges": [1.0]}', ("2 ids for 1 measurements",)),
    ("bearings", '{"t": 0.1, "type": "landmarks", "ids": [1], "ranges": [1.0], "bearings": []}', ("'bearings'",)),
    ("range < 0", '{"t": 0.1, "type": "ranges", "ids": [1], "ranges": [-1.0]}', ("jsonl:2", "range, m -1,")),
    ("fix cov", '{"t": 0.1, "type": "fix", "z": [0, 0], "cov": [[1, 2], [2, 1]]}', ("'cov'", "positive semi")),
    ("fix both", '{"t": 0.1, "type": "fix", "z": [0, 0], "cov": [[1, 0], [0, 1]], "sigma": [1, 1]}', ("either",)),
    (
        "scan geometry",
        '{"t": 0.1, "type": "scan", "angle_min": 0, "angle_increment": 0, "range_min": 0, "range_max": 5, '
        '"ranges": [1, 2]}',
        ("scan event: angle_increment 0.0 rad",),
    ),
    ("backwards", '{"t": -1.0, "type": "ranges", "ids": [1], "ranges": [1.0]}', ("field 't'", "time order")),
    (
        "1e999",
        '{"t": 0.1, "type": "ranges", "ids": [1], "ranges": [1e999]}',
        ("events.jsonl:2:", "'ranges': item 0 is inf, expected a finite number"),
    ),
    ("huge int", '{"t": 1' + "0" * 30 + ', "type": "ranges"}', ("events.jsonl:2:", "more than 18 digits")),
    ("deep", "[" * 100000 + "]" * 100000, ("events.jsonl:2:", "nested too deeply")),
    ("twist no dt", '{"t": 0.1, "type": "odometry", "v": 1.0, "omega": 0.0}', ("'dt'", "no earlier odometry")),
]


@pytest.mark.parametrize(("line", "words"), [b[1:] for b in BAD_EVENTS], ids=[b[0] for b in BAD_EVENTS])
def test_bad_event_lines_are_refused_naming_line_and_field(tmp_path: Path, line: str, words: tuple[str, ...]) -> None:
    folder = _write_log(tmp_path / "log", [])
    ev = folder / "events.jsonl"
    ev.write_text('{"t": 0.0, "type": "ranges", "ids": [1], "ranges": [1.0]}\n' + line + "\n")
    with pytest.raises(RecordedDataError) as info:
        load_textlog(folder)
    _clean(info, str(ev), *words)


def test_a_cut_last_line_and_a_long_line_are_refused(tmp_path: Path) -> None:
    folder = _write_log(tmp_path / "log", _twist_events())
    ev = folder / "events.jsonl"
    ev.write_bytes(ev.read_bytes()[:-3])
    with pytest.raises(RecordedDataError) as info:
        load_textlog(folder)
    _clean(info, "truncated line")
    ev.write_text('{"t": 0.0, "type": "odometry", "dx": 0, "dy": 0, "dtheta": 0, "pad": "' + "x" * (1 << 20) + '"}\n')
    with pytest.raises(RecordedDataError) as info:
        load_textlog(folder)
    _clean(info, "events.jsonl:1:", "line longer than")


BAD_MANIFESTS = [
    ({"format": "csv"}, ("field 'format'", "expected 'locbench-textlog'")),
    ({"version": 2}, ("field 'version': is 2, written for a newer locbench", "reads version 1")),
    ({"version": "1"}, ("field 'version'", "integer version")),
    ({"colour": 1}, ("field 'colour': unknown field",)),
    ({"sensors": {"laser_sigma": 0.1}}, ("unknown sensors field", "laser_sigma_m")),
    ({"sensors": {"laser_sigma_m": -1}}, ("sensors.laser_sigma_m is -1",)),
    ({"initial": {"mean": [0, 0, 0]}}, ("field 'initial'", "both 'mean' and 'cov'")),
    ({"truth_label": "vicon"}, ("field 'truth_label'", "ground truth")),
    ({"reference_kind": "lidar"}, ("field 'reference_kind'", "motion capture")),
    ({"kidnaps": [{"t": 1.0}]}, ("field 'kidnaps'",)),
    ({"map": "nowhere.yaml"}, ("field 'map'", "does not exist")),
]


@pytest.mark.parametrize(("edit", "words"), BAD_MANIFESTS, ids=[str(m[0])[:30] for m in BAD_MANIFESTS])
def test_bad_manifests_are_refused_naming_the_field(
    tmp_path: Path, edit: dict[str, Any], words: tuple[str, ...]
) -> None:
    folder = _write_log(tmp_path / "log", _twist_events(), edit)
    with pytest.raises(RecordedDataError) as info:
        load_textlog(folder)
    _clean(info, str(folder / MANIFEST), *words)


def test_bad_files_beside_the_manifest(tmp_path: Path) -> None:
    folder = _write_log(tmp_path / "log", _twist_events())
    (folder / "lm.csv").write_text("1 2.0 1.0\n1 0.0 -1.0\n")
    with pytest.raises(RecordedDataError) as info:
        load_textlog(folder)
    _clean(info, "lm.csv:2:", "landmark id 1 given twice")
    folder = _write_log(tmp_path / "log2", _twist_events())
    (folder / "truth.tum").write_text("0.0 0 0 0 0 0 0 2\n1.0 0 0 0 0 0 0 1\n")
    with pytest.raises(RecordedDataError) as info:
        load_textlog(folder)
    _clean(info, "truth.tum:1:", "unit quaternion")
    (folder / "truth.tum").unlink()
    with pytest.raises(RecordedDataError) as info:
        load_textlog(folder)
    _clean(info, "truth.tum", "missing truth file")
    with pytest.raises(RecordedDataError) as info:
        load_textlog(tmp_path / "nothing")
    _clean(info, "missing textlog folder")
    (tmp_path / "empty").mkdir()
    with pytest.raises(RecordedDataError) as info:
        load_textlog(tmp_path / "empty")
    _clean(info, "missing manifest")
    with pytest.raises(ConfigError, match="parameter 'path' is required"):
        make_dataset("textlog", 0)


def test_a_fifo_as_events_file_is_refused_without_blocking(tmp_path: Path) -> None:
    folder = _write_log(tmp_path / "log", _twist_events())
    (folder / "events.jsonl").unlink()
    import os

    os.mkfifo(folder / "events.jsonl")
    with pytest.raises(ConfigError) as info:
        load_textlog(folder)
    _clean(info, "events.jsonl", "not a regular file")


def test_textlog_is_registered_and_skips_without_a_path() -> None:
    from locbench.registry import DATASETS

    assert "textlog" in DATASETS.ids()
    reason = DATASETS.unavailable_reason("textlog")
    assert reason is not None and "textlog[path=" in reason
    assert math.isfinite(DATASETS.load("textlog").nominal_duration_s)


def test_the_report_shows_the_input_warnings(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    events = [
        {"t": k / 10, "type": "odometry", "dx": 0.1, "dy": 0.0, "dtheta": 0.0, "v": 0.0, "omega": 0.0, "dt": 0.1}
        for k in range(1, 21)
    ]
    folder = _write_log(tmp_path / "log", events, {"landmarks": None})
    (folder / "lm.csv").unlink()
    res = tmp_path / "res"
    spec = f"textlog[path={folder}]"
    assert main(["run", "--dataset", spec, "--filter", "odometry", "--results", str(res), "--no-progress"]) == 0
    assert main(["report", "--results", str(res)]) == 0
    capsys.readouterr()
    text = site_markdown(res / "summary")
    assert "Input warnings" in text and "odometry twist contradicts its pose: the twist is zero in 20 of" in text


@pytest.mark.slow
def test_a_recorded_range_only_dataset_reads_back_bit_for_bit(tmp_path: Path) -> None:
    from locbench.registry import DATASETS

    reason = DATASETS.unavailable_reason("plaza")
    if reason:
        pytest.skip(reason)
    ds = make_dataset("plaza[run=1]", 0)
    assert write_textlog(ds, tmp_path / "plaza", reference_kind="GPS") == []
    back = load_textlog(tmp_path / "plaza")
    assert {type(e) for e in back.events} == {Odometry, RangeObservations}
    _round_trip(ds, back)
    _same_estimates("ekf_landmarks", ds, back)


def test_cut_and_mutated_events_files_are_clean_errors_or_load(tmp_path: Path) -> None:
    """Every cut (at 40 places) and 60 seeded single-byte changes of a small log: a one-line locbench error naming
    the events file, or a dataset that passes the contract; never another exception."""
    folder = _write_log(tmp_path / "log", _twist_events())
    ev = folder / "events.jsonl"
    raw = ev.read_bytes()
    rng = np.random.default_rng(25)
    variants = [raw[:cut] for cut in np.linspace(1, len(raw) - 1, 40).astype(int)]
    for pos, byte in zip(
        rng.integers(0, len(raw), 60), rng.choice(list(b'0123456789.,:[]{}"-e nx\n'), 60), strict=True
    ):
        variants.append(raw[:pos] + bytes([byte]) + raw[pos + 1 :])
    outcomes = {"error": 0, "ok": 0}
    for data in variants:
        ev.write_bytes(data)
        _cached_events.cache_clear()  # a same-size rewrite within one clock tick keeps the file's signature
        try:
            load_textlog(folder).check()
            outcomes["ok"] += 1
        except ConfigError as exc:
            msg = str(exc)
            assert "\n" not in msg and len(msg) <= MAX_MESSAGE_CHARS and ("events.jsonl" in msg or "textlog" in msg), (
                msg
            )
            outcomes["error"] += 1
    assert outcomes["error"] > 40  # the cuts alone


def test_a_graded_grid_is_written_quantized_and_said_so(tmp_path: Path) -> None:
    from locbench.datasets.dataset import OccupancyGrid, WorldMap

    ds = make_dataset("tiny_circle", 0)
    g = ds.world.occupancy
    assert g is not None
    graded = OccupancyGrid(np.where(g.occupancy > 0.5, 0.9, 0.1), g.resolution, g.origin, g.occupied_thresh, 0.196)
    ds = dataclasses.replace(ds, world=WorldMap(occupancy=graded, landmarks=ds.world.landmarks, lines=ds.world.lines))
    notes = write_textlog(ds, tmp_path / "graded")
    assert notes == ["the occupancy grid has graded values: stored in scale mode, quantized to 8 bits"]
    back = load_textlog(tmp_path / "graded")
    assert back.world.occupancy is not None
    np.testing.assert_allclose(back.world.occupancy.occupancy, graded.occupancy, atol=0.5 / 255)
    np.testing.assert_array_equal(back.world.occupancy.occupied(), graded.occupied())
