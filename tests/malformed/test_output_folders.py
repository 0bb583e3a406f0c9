"""Only our files: ``run --force``, ``report`` and ``verify`` replace what locbench wrote and nothing else, refuse
someone else's folder, leave the old summary whole when a write fails; and ``verify`` re-derives every stored
artefact of a sampled run (estimates, truth, waypoints, bound, the run's identity)."""

from __future__ import annotations

import errno
import json
import os
import shutil
import time
from pathlib import Path

import numpy as np
import pytest

from locbench.cli import main
from locbench.report import output
from locbench.report.output import MANIFEST, read_manifest
from locbench.run.store import MARKER, Store, _sealed, npz_digest
from locbench.run.sweep import run_many

DATASET = "room"  # small, synthetic, with a bound


@pytest.fixture(scope="module")
def swept(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("swept") / "results"
    run_many(["odometry"], [DATASET], [0, 1], str(root))
    assert main(["report", "--results", str(root)]) == 0
    return root


@pytest.fixture
def results(swept: Path, tmp_path: Path) -> Path:
    """A fresh copy of the swept results folder (marked, two runs, their truths and bounds, a report)."""
    root = tmp_path / "results"
    shutil.copytree(swept, root)
    return root


def _one_line(capsys: pytest.CaptureFixture[str], *needles: str) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("locbench: error: "), err
    for needle in needles:
        assert needle in err, err
    return err


def _tree(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _report(results: Path, *extra: str) -> int:
    return main(["report", "--results", str(results), *extra])


# --- run --force ------------------------------------------------------------------------------------------


def test_run_force_keeps_a_file_locbench_did_not_write(results: Path) -> None:
    run = Store(results).run_dir(DATASET, "odometry", 0)
    before = (run / "meta.json").read_bytes()
    (run / "notes.txt").write_text("mine\n")
    (run / "plots").mkdir()
    (run / "plots" / "a.png").write_bytes(b"png")
    argv = ["run", "--filter", "odometry", "--dataset", DATASET, "--seeds", "1", "--results", str(results)]
    assert main([*argv, "--force", "--no-progress"]) == 0
    assert (run / "meta.json").read_bytes() != before  # re-run and replaced
    assert (run / "notes.txt").read_text() == "mine\n" and (run / "plots" / "a.png").read_bytes() == b"png"
    assert not [p for p in run.parent.iterdir() if ".old-" in p.name or p.name.startswith(".tmp-")]


def test_a_left_over_old_run_folder_keeps_a_foreign_file(results: Path) -> None:
    store = Store(results)
    run = store.run_dir(DATASET, "odometry", 0)
    old = run.with_name(f"{run.name}.old-0123456789ab")
    shutil.copytree(run, old)
    (old / "notes.txt").write_text("mine\n")
    stale = time.time() - 3600
    os.utime(old, (stale, stale))
    assert store.clean_leftovers() == []
    assert sorted(p.name for p in old.iterdir()) == ["notes.txt"]  # locbench's files gone, the user's kept


# --- report -----------------------------------------------------------------------------------------------


def test_report_keeps_foreign_pngs_and_files_and_lists_its_own(results: Path) -> None:
    summary = results / "summary"
    listed = read_manifest(summary)
    assert listed is not None and "REPORT.md" in listed and any(k.startswith("figures/") for k in listed)
    (summary / "figures" / "loss.png").write_bytes(b"someone else's figure")
    (summary / "index.png").write_bytes(b"a screenshot")
    (summary / "notes").mkdir()
    (summary / "notes" / "a.md").write_text("mine\n")
    assert _report(results) == 0
    assert (summary / "figures" / "loss.png").read_bytes() == b"someone else's figure"
    assert (summary / "index.png").read_bytes() == b"a screenshot"
    assert (summary / "notes" / "a.md").read_text() == "mine\n"
    listed = read_manifest(summary)
    assert listed is not None and not {"figures/loss.png", "index.png", "notes/a.md"} & listed.keys()
    assert not [p for p in results.iterdir() if p.name.startswith(".summary.")]


def test_report_refuses_an_unmarked_non_empty_out_folder(
    results: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    other = tmp_path / "other-tool"
    other.mkdir()
    (other / "REPORT.md").write_text("another tool's report\n")
    (other / "loss.png").write_bytes(b"png")
    before = _tree(other)
    assert _report(results, "--out", str(other)) == 2
    _one_line(capsys, str(other), "not empty and not written by 'locbench report'", MANIFEST)
    assert _tree(other) == before
    # an empty folder is fine, and is then the report's
    empty = tmp_path / "empty"
    empty.mkdir()
    assert _report(results, "--out", str(empty)) == 0
    assert (empty / "REPORT.md").is_file() and (empty / MANIFEST).is_file()


def test_report_refuses_the_summary_of_an_unmarked_results_folder(
    results: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (results / MARKER).unlink()
    shutil.rmtree(results / "summary")
    (results / "summary").mkdir()
    (results / "summary" / "loss.png").write_bytes(b"png")
    assert _report(results) == 2
    _one_line(capsys, str(results / "summary"), "not written by 'locbench report'")
    assert _tree(results / "summary") == {"loss.png": b"png"}


def test_report_refuses_to_overwrite_a_file_changed_since_it_wrote_it(
    results: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    summary = results / "summary"
    (summary / "REPORT.md").write_text("edited by hand\n")
    before = _tree(summary)
    assert _report(results) == 2
    _one_line(capsys, str(summary / "REPORT.md"), "not written by 'locbench report'", "move it away")
    assert _tree(summary) == before


@pytest.mark.parametrize("fail_at", [0, 2, -1])  # metrics.parquet, the first figure, the manifest (the last write)
def test_a_full_disk_leaves_the_old_summary_whole_and_names_the_file(
    results: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], fail_at: int
) -> None:
    summary = results / "summary"
    (summary / "index.png").write_bytes(b"a screenshot")
    before = _tree(summary)
    n_writes = len(before) - 1  # every listed file and the manifest: all but the screenshot
    target = fail_at % n_writes
    real = output.write_file
    calls: list[Path] = []

    def full(path: Path, data: bytes) -> None:
        calls.append(path)
        if len(calls) - 1 == target:
            raise OSError(errno.ENOSPC, "No space left on device")
        real(path, data)

    monkeypatch.setattr(output, "write_file", full)
    capsys.readouterr()
    assert _report(results) == 2
    tmp = results / calls[-1].relative_to(results).parts[0]  # the temporary sibling the new summary went to
    failed = summary / calls[-1].relative_to(tmp)
    assert (fail_at != -1) or failed.name == MANIFEST
    _one_line(capsys, f"{failed}: No space left on device", f"{summary} is left as it was", "the disk is full")
    assert _tree(summary) == before
    assert not [p for p in results.iterdir() if p.name.startswith(".summary.")]


def test_a_full_disk_on_the_first_report_leaves_no_summary(
    results: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    def full(path: Path, data: bytes) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    shutil.rmtree(results / "summary")
    monkeypatch.setattr(output, "write_file", full)
    assert _report(results) == 2
    _one_line(capsys, str(results / "summary" / "metrics.parquet"), "No space left on device")
    assert sorted(p.name for p in results.iterdir()) == [MARKER, "runs"]


# --- verify: refusals -------------------------------------------------------------------------------------


def _verify(results: Path, *extra: str) -> int:
    return main(["verify", "--results", str(results), "--fraction", "1", *extra])


def test_verify_refuses_an_unmarked_folder(results: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (results / MARKER).unlink()
    assert _verify(results) == 2
    _one_line(capsys, str(results), "not a locbench results folder", MARKER)
    assert not (results / "verify.json").exists()


def test_verify_refuses_a_store_with_nothing_to_verify(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root = tmp_path / "results"
    Store(root).claim()
    assert _verify(root) == 2
    _one_line(capsys, str(root / "runs"), "no stored run to verify")
    assert not (root / "verify.json").exists()


def test_verify_keeps_a_verify_json_it_did_not_write(results: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (results / "verify.json").write_text('{"mine": true}\n')
    assert _verify(results) == 2
    _one_line(capsys, str(results / "verify.json"), "not a record 'locbench verify' wrote")
    assert (results / "verify.json").read_text() == '{"mine": true}\n'


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["--seed", "-1"], "--seed: expected a non-negative integer"),
        (["--fraction", "0"], "--fraction: expected a share of the runs in (0, 1]"),
        (["--jobs", "0"], "--jobs: expected 1-"),
    ],
)
def test_verify_bad_arguments_are_one_line(
    results: Path, capsys: pytest.CaptureFixture[str], argv: list[str], expected: str
) -> None:
    assert main(["verify", "--results", str(results), *argv]) == 2
    _one_line(capsys, expected)
    assert not (results / "verify.json").exists()


# --- verify: every artefact -------------------------------------------------------------------------------


def _alter(npz: Path, array: str, record: dict[str, object] | None = None) -> None:
    """Change one value of one stored array by the smallest step (or fields of its record), and reseal the record
    (a consistent record of other numbers: what only a re-derivation can catch)."""
    with np.load(npz) as z:
        arrays = {k: z[k] for k in z.files}
    a = arrays[array].copy()
    a.flat[a.size // 2] = np.nextafter(a.flat[a.size // 2], np.inf)
    if record is None:
        arrays[array] = a
    np.savez(npz, **arrays)
    meta_path = npz.with_suffix(".json") if npz.name != "estimates.npz" else npz.parent / "meta.json"
    meta = json.loads(meta_path.read_text())
    meta.pop("meta_sha256")
    meta["files"] = {npz.name: npz_digest(npz)}
    meta_path.write_text(json.dumps(_sealed(meta | (record or {}))))


@pytest.mark.parametrize(
    ("path", "array", "record", "expected"),
    [
        ("_truth/seed-0000.npz", "gt_xy", None, f"{DATASET} seed 0 truth: gt_xy"),
        ("_truth/seed-0000.npz", "gt_t", None, f"{DATASET} seed 0 truth: gt_t"),
        ("_truth/seed-0000.npz", "wp_xy", None, f"{DATASET} seed 0 waypoints: wp_xy"),
        ("_truth/seed-0000.npz", "gt_xy", {"seed": 1}, f"{DATASET} seed 0 truth: record seed (1 stored, 0 now)"),
        ("_truth/seed-0000.bound.npz", "cov_0", None, f"{DATASET} seed 0 bound: cov_0"),
        ("_truth/seed-0000.bound.npz", "t", None, f"{DATASET} seed 0 bound: t"),
        ("odometry/seed-0000/estimates.npz", "mean", {"filter_id": "ekf"}, "record filter_id ('ekf' stored"),
        ("odometry/seed-0000/estimates.npz", "mean", {"dataset_version": 99}, "record dataset_version (99 stored"),
    ],
)
def test_verify_detects_each_tampered_artefact(
    results: Path,
    capsys: pytest.CaptureFixture[str],
    path: str,
    array: str,
    record: dict[str, object] | None,
    expected: str,
) -> None:
    _alter(results / "runs" / DATASET / path, array, record)
    assert _verify(results) == 1
    out = capsys.readouterr().out
    assert expected in out, out
    assert out.count("differs: ") == 1, out  # only that artefact; the other realisation passes
    assert json.loads((results / "verify.json").read_text())["passed"] is False


def test_an_intact_store_passes_with_its_truths_and_bounds(results: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert _verify(results) == 0
    assert "2 of 2 stored runs re-run with the truth and bound of 2 realisation(s), 0 differ" in capsys.readouterr().out


def test_verify_detects_a_run_folder_copied_over_another(results: Path, capsys: pytest.CaptureFixture[str]) -> None:
    store = Store(results)
    zero, one = store.run_dir(DATASET, "odometry", 0), store.run_dir(DATASET, "odometry", 1)
    shutil.rmtree(zero)
    shutil.copytree(one, zero)
    assert _verify(results) == 1
    out = capsys.readouterr().out
    assert f"{zero / 'meta.json'}: names odometry on {DATASET} seed 1, which is not the run of this folder" in out


def test_verify_detects_a_missing_bound(results: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bound = Store(results).bound_path(DATASET, 1)
    bound.unlink()
    bound.with_suffix(".json").unlink()
    assert _verify(results) == 1
    assert f"{DATASET} seed 1 bound: missing" in capsys.readouterr().out
