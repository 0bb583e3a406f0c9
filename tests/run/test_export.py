"""TUM trajectory export: the file format evo reads, exact round trips, and runs from a results folder."""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
import pytest

from locbench.core.errors import ConfigError
from locbench.core.geometry import quaternion_to_yaw, wrap_angle, yaw_to_quaternion
from locbench.datasets.dataset import Trajectory2D
from locbench.datasets.recorded.files import RecordedDataError
from locbench.evaluate.metrics import estimate_at
from locbench.evaluate.records import KIND_NAMES, RunRecord
from locbench.run.export import (
    export_results,
    export_truth_tum,
    export_tum,
    read_tum,
    write_tum,
)
from locbench.run.store import Store
from locbench.run.sweep import run_many


def test_quaternion_of_a_yaw() -> None:
    yaw = np.array([-math.pi + 1e-9, -2.0, -1e-3, 0.0, 0.5, 3.0, math.pi, 3 * math.pi / 2])
    q = yaw_to_quaternion(yaw)
    assert q.shape == (8, 4)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-15)
    np.testing.assert_array_equal(q[:, :2], 0.0)
    assert np.all(q[:, 3] >= 0.0)
    np.testing.assert_allclose(q[4], [0.0, 0.0, math.sin(0.25), math.cos(0.25)])
    np.testing.assert_allclose(wrap_angle(quaternion_to_yaw(q) - yaw), 0.0, atol=1e-12)
    np.testing.assert_allclose(quaternion_to_yaw(-q), quaternion_to_yaw(q), atol=1e-15)


def test_write_and_read_back_exactly(tmp_path: Path) -> None:
    rng = np.random.default_rng(7)
    n = 200
    t = 1_700_000_000.0 + np.cumsum(rng.uniform(0.01, 0.1, n))
    poses = np.column_stack([rng.normal(0, 50, n), rng.normal(0, 50, n), rng.uniform(-math.pi, math.pi, n)])
    poses[0, 2], poses[1, 2] = math.pi, -math.pi + 1e-12  # both ends of the heading range
    path = write_tum(tmp_path / "deep" / "est.tum", t, poses, comment="a test\nwith two lines")
    lines = path.read_text().splitlines()
    assert lines[0] == "# timestamp tx ty tz qx qy qz qw"
    assert lines[1] == "# a test with two lines"
    assert len(lines) == n + 2
    for line in lines[2:]:
        fields = line.split(" ")  # evo splits on single spaces
        assert len(fields) == 8 and fields[3] == "0.0"
    back = read_tum(path)
    np.testing.assert_array_equal(back.t, t)  # shortest exact float text: bit-identical
    np.testing.assert_array_equal(back.xy, poses[:, :2])
    np.testing.assert_allclose(wrap_angle(back.theta - poses[:, 2]), 0.0, atol=1e-12)
    assert not [p.name for p in path.parent.iterdir() if p.name.startswith(".tmp")]


def test_shared_times_keep_the_last_estimate_and_non_finite_rows_are_left_out(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    t = np.array([0.0, 0.1, 0.1, 0.2, 0.3, 0.3])
    poses = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [np.nan, 0, 0], [4, 0, 0], [5, 0, 0.5]], dtype=float)
    with caplog.at_level(logging.WARNING, logger="locbench.run.export"):
        back = read_tum(write_tum(tmp_path / "a.tum", t, poses))
    assert "leaving out 1 non-finite pose rows of 6" in caplog.text
    np.testing.assert_array_equal(back.t, [0.0, 0.1, 0.3])
    np.testing.assert_array_equal(back.xy[:, 0], [0.0, 2.0, 5.0])
    assert back.theta[-1] == pytest.approx(0.5)


def test_write_rejects_bad_input(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"a\.tum: time goes backwards at row 2: 0\.1 s after 0\.2 s"):
        write_tum(tmp_path / "a.tum", [0.0, 0.2, 0.1], np.zeros((3, 3)))
    with pytest.raises(ConfigError, match=r"expected times \(n,\) and poses \(n, 3\)"):
        write_tum(tmp_path / "a.tum", [0.0, 0.2], np.zeros((3, 3)))
    with pytest.raises(ConfigError, match="no finite pose to write"):
        write_tum(tmp_path / "a.tum", [0.0], np.full((1, 3), np.nan))
    assert not list(tmp_path.iterdir())  # nothing half-written


@pytest.mark.parametrize(
    ("line", "match"),
    [
        ("0.3 1 2 0 0 0 0", r"b\.tum:4: wrong column count: 7 fields, expected 8"),
        ("0.3 1 2 0 0 0 zero 1", r"b\.tum:4: field 7 \(qz\) is 'zero', expected a number"),
        ("0.05 1 2 0 0 0 0 1", r"b\.tum:4: timestamp goes backwards: .*0\.05.* after .*0\.2"),
    ],
)
def test_read_names_the_bad_line(tmp_path: Path, line: str, match: str) -> None:
    p = tmp_path / "b.tum"
    p.write_text("# timestamp tx ty tz qx qy qz qw\n0.1 0 0 0 0 0 0 1\n0.2 1 0 0 0 0 0 1\n" + line + "\n")
    with pytest.raises(RecordedDataError, match=match):
        read_tum(p)


@pytest.fixture
def results(tmp_path: Path, harness_registry: None) -> Path:
    """A results folder with dead reckoning, a filter that breaks half way, on the test-only line dataset."""
    root = tmp_path / "results"
    outcomes = run_many(["odometry", "bad[mode=nan,fail_at_s=2.5]"], ["line"], [0], str(root))
    assert [o.status for o in outcomes] == ["ok", "diverged"]
    return root


def test_export_a_stored_run_and_its_truth(results: Path, tmp_path: Path) -> None:
    store = Store(results)
    run_dir = store.run_dir("line", "odometry", 0)
    rec = store.read_run(run_dir)
    est = read_tum(export_tum(run_dir, tmp_path / "est.tum"))
    assert est.t[0] == rec.t[0] and np.all(np.diff(est.t) > 0)
    # every written pose is the one locbench's metrics hold at that time
    held = estimate_at(rec.t, rec.mean, est.t)
    np.testing.assert_array_equal(est.xy, held[:, :2])
    np.testing.assert_allclose(wrap_angle(est.theta - held[:, 2]), 0.0, atol=1e-12)
    assert "filter odometry dataset line seed 0" in (tmp_path / "est.tum").read_text().splitlines()[1]
    # the same from the record itself
    assert read_tum(export_tum(rec, tmp_path / "est2.tum")).t.tolist() == est.t.tolist()
    truth = store.read_truth("line", 0)
    gt = read_tum(export_truth_tum(truth, tmp_path / "gt.tum"))
    np.testing.assert_array_equal(gt.t, truth.ground_truth.t)
    np.testing.assert_array_equal(gt.xy, truth.ground_truth.xy)
    assert "# locbench ground truth: dataset line seed 0" in (tmp_path / "gt.tum").read_text()
    # a trajectory alone
    traj = Trajectory2D(np.array([0.0, 1.0]), np.zeros((2, 2)), np.array([0.1, -0.1]))
    np.testing.assert_allclose(read_tum(export_truth_tum(traj, tmp_path / "t.tum")).theta, [0.1, -0.1])


def test_export_a_diverged_run_up_to_its_failure(results: Path, tmp_path: Path) -> None:
    run_dir = Store(results).run_dir("line", "bad[fail_at_s=2.5,mode=nan]", 0)
    est = read_tum(export_tum(run_dir, tmp_path / "bad.tum"))
    assert est.t[-1] < 2.5 and est.t.shape[0] == 25  # the reset row and 24 finite steps


def test_smoothed_export(tmp_path: Path) -> None:
    st = np.array([0.0, 0.5, 1.0])
    sm = np.array([[0.0, 0.0, 0.0], [0.5, 0.1, 0.2], [1.0, 0.1, 0.3]])
    rec = RunRecord(
        {"filter": "gtsam_fls", "dataset": "x", "seed": 0, "status": "ok"},
        np.array([0.0, 1.0]),
        np.zeros((2, 3)),
        np.tile(np.eye(3), (2, 1, 1)),
        np.array([KIND_NAMES.index("reset"), 0], dtype=np.int8),
        np.zeros(2, np.int64),
        extra={"smoothed_t": st, "smoothed_mean": sm},
    )
    back = read_tum(export_tum(rec, tmp_path / "s.tum", smoothed=True))
    np.testing.assert_array_equal(back.t, st)
    np.testing.assert_array_equal(back.xy, sm[:, :2])
    np.testing.assert_allclose(back.theta, sm[:, 2], atol=1e-12)
    rec.extra.clear()
    with pytest.raises(ConfigError, match="gtsam_fls on x seed 0 has no smoothed trajectory"):
        export_tum(rec, tmp_path / "s.tum", smoothed=True)


def test_export_a_skipped_run_is_an_error(tmp_path: Path) -> None:
    rec = RunRecord(
        {"filter": "ekf_icp", "dataset": "room", "seed": 1, "status": "skipped", "message": "no laser"},
        np.zeros(0),
        np.zeros((0, 3)),
        np.zeros((0, 3, 3)),
        np.zeros(0, np.int8),
        np.zeros(0, np.int64),
    )
    with pytest.raises(ConfigError, match=r"run ekf_icp on room seed 1 has no estimates \(status skipped: no laser\)"):
        export_tum(rec, tmp_path / "x.tum")
    assert not list(tmp_path.iterdir())


def test_export_a_whole_results_folder(results: Path, tmp_path: Path) -> None:
    out = tmp_path / "tum"
    written = export_results(results, out)
    rel = sorted(str(p.relative_to(out)) for p in written)
    assert rel == [
        "line/_truth/seed-0000.tum",
        "line/bad[fail_at_s=2.5,mode=nan]/seed-0000.tum",
        "line/odometry/seed-0000.tum",
    ]
    only = export_results(results, tmp_path / "only", filters=["odometry"])
    assert [p.name for p in only] == ["seed-0000.tum", "seed-0000.tum"]
    assert export_results(results, tmp_path / "none", smoothed=True) == []


def test_export_long_non_ascii_names(tmp_path: Path, harness_registry: None) -> None:
    # every name the store accepts can be exported: the TUM comment is UTF-8, the folders are cut and hashed
    label = "Küche-Straße-東京-" * 30
    spec = f"line[label={label}]"
    root = tmp_path / "results"
    assert [o.status for o in run_many(["odometry"], [spec], [0], str(root))] == ["ok"]
    written = export_results(root, tmp_path / "tum")
    assert len(written) == 2
    for path in written:
        assert all(len(part.encode()) <= 255 for part in path.parts)
        text = path.read_text(encoding="utf-8")
        assert "東京" in text.splitlines()[1]
        assert read_tum(path).t.size > 0
