"""The store: one folder per canonical spec, concurrent writers, leftovers, umask and a full disk."""

from __future__ import annotations

import errno
import multiprocessing
import os
import stat
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from locbench.core.errors import ConfigError
from locbench.evaluate.records import RunRecord
from locbench.run import store as store_mod
from locbench.run.store import Store


def _record(dataset: str, filt: str = "odometry", seed: int = 0, value: float = 1.0) -> RunRecord:
    n = 4
    meta = {"dataset": dataset, "filter": filt, "seed": seed, "run_key": f"k{value}", "status": "ok"}
    return RunRecord(
        meta,
        np.arange(n, dtype=float),
        np.full((n, 3), value),
        np.tile(np.eye(3), (n, 1, 1)),
        np.zeros(n, np.int8),
        np.zeros(n, np.int64),
    )


@pytest.mark.parametrize(
    ("a", "b"),
    [
        ("rosbag[map=m.yaml,path=/x/y.bag]", "rosbag[map=m.yaml,path=/x_y.bag]"),
        ("rosbag[path=a\\b]", "rosbag[path=a/b]"),
        ("rosbag[path=a/b]", "rosbag[path=a_b]"),
        ("rosbag[path=" + "d/" * 120 + "]", "rosbag[path=" + "d/" * 120 + "x]"),
    ],
)
def test_different_specs_never_share_a_folder(tmp_path: Path, a: str, b: str) -> None:
    st = Store(tmp_path)
    assert st.run_dir(a, "pf", 0) != st.run_dir(b, "pf", 0)
    assert st.truth_path(a, 0) != st.truth_path(b, 0)
    st.write_run(_record(a, value=1.0))
    st.write_run(_record(b, value=2.0))
    assert len(list(st.iter_runs())) == 2
    assert st.read_run(st.run_dir(a, "odometry", 0)).meta["dataset"] == a
    assert st.read_run(st.run_dir(b, "odometry", 0)).mean[0, 0] == 2.0
    for d in (st.run_dir(a, "odometry", 0), st.run_dir(b, "odometry", 0)):
        assert len(d.parent.parent.name.encode()) <= 255


def test_plain_names_keep_their_folders(tmp_path: Path) -> None:
    st = Store(tmp_path)
    for name in ("room", "room[kidnap_m=2]", "landmark_geometry[gps=true,initial_offset_m=2]", "pf[augmented=true]"):
        assert st.run_dir(name, name, 3) == tmp_path / "runs" / name / name / "seed-0003"


def _write_many(args: tuple[str, int]) -> int:
    root, worker = args
    st = Store(root)
    for i in range(30):
        st.write_run(_record("room", f"f{i % 5}", seed=i % 2, value=float(worker)))
        st.write_truth(_truth("room", i % 2))
    return worker


def _truth(dataset: str, seed: int) -> store_mod.TruthRecord:
    from locbench.datasets.dataset import Trajectory2D

    t = np.arange(3.0)
    return store_mod.TruthRecord(dataset, seed, Trajectory2D(t, np.zeros((3, 2)), np.zeros(3)), None, (), 2.0)


def test_six_concurrent_writers_neither_crash_nor_corrupt(tmp_path: Path) -> None:
    ctx = multiprocessing.get_context("spawn")
    with ctx.Pool(6) as pool:
        assert sorted(pool.map(_write_many, [(str(tmp_path), w) for w in range(6)])) == list(range(6))
    st = Store(tmp_path)
    runs = list(st.iter_runs())
    assert len(runs) == 10  # 5 filters x 2 seeds, each one complete run of one writer
    for r in runs:
        rec = st.read_run(r)
        assert np.all(rec.mean == rec.mean[0, 0])
        assert st.unreadable("room", r.parent.name, int(r.name[5:])) is None
    assert st.read_truth("room", 1).duration_s == 2.0
    assert [p.name for p in tmp_path.rglob("*") if ".tmp-" in p.name or ".old" in p.name] == []


def test_leftovers_are_ignored_and_cleaned(tmp_path: Path) -> None:
    st = Store(tmp_path)
    final = st.write_run(_record("room"))
    for name in ("seed-0000.old-0123456789ab", ".tmp-abc12_yz"):
        leftover = final.parent / name
        leftover.mkdir()
        (leftover / "meta.json").write_text("{}")
    (final.parent.parent / "_truth").mkdir()
    (final.parent.parent / "_truth" / ".tmp-x1y2z3w4.npz").write_bytes(b"")
    # names locbench never writes, and files outside runs/<dataset>/<folder>/, are not its leftovers
    others = [
        final.parent / "notes.old",
        final.parent / ".tmp-mine",
        final.parent / "seed-0000.old",
        tmp_path / "runs" / ".tmp-abcdefgh",
        tmp_path / "data.old-0123456789ab",
    ]
    for other in others:
        other.write_text("someone else's")
    assert list(st.iter_runs()) == [final]
    assert st.clean_leftovers() == []  # fresh: could be another process's write in progress
    removed = st.clean_leftovers(older_than_s=0.0)
    assert sorted(p.name for p in removed) == [".tmp-abc12_yz", ".tmp-x1y2z3w4.npz", "seed-0000.old-0123456789ab"]
    assert all(other.read_text() == "someone else's" for other in others)


def test_unreadable_runs_are_detected(tmp_path: Path) -> None:
    st = Store(tmp_path)
    final = st.write_run(_record("room"))
    assert st.unreadable("room", "odometry", 0) is None
    data = (final / "estimates.npz").read_bytes()
    (final / "estimates.npz").write_bytes(data[: len(data) // 2])
    assert "estimates.npz" in str(st.unreadable("room", "odometry", 0))
    (final / "estimates.npz").unlink()
    assert st.unreadable("room", "odometry", 0) is not None


@pytest.mark.parametrize("mask", [0o022, 0o002, 0o077])
def test_files_follow_the_umask(tmp_path: Path, mask: int) -> None:
    old = os.umask(mask)
    store_mod._umask.cache_clear()
    try:
        st = Store(tmp_path)
        final = st.write_run(_record("room"))
        st.write_truth(_truth("room", 0))
    finally:
        os.umask(old)
        store_mod._umask.cache_clear()
    assert stat.S_IMODE(final.stat().st_mode) == 0o777 & ~mask
    assert stat.S_IMODE((final / "meta.json").stat().st_mode) == 0o666 & ~mask
    assert stat.S_IMODE(st.truth_path("room", 0).stat().st_mode) == 0o666 & ~mask


def test_disk_full_raises_and_leaves_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def full(*args: object, **kwargs: object) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(store_mod.np, "savez", full)
    st = Store(tmp_path)
    with pytest.raises(OSError, match="No space left"):
        st.write_run(_record("room"))
    assert [p.name for p in tmp_path.rglob("*") if p.is_file() or p.name.startswith(".tmp-")] == []


def _claim_at_barrier(root: str, barrier: Any) -> str:
    barrier.wait()
    try:
        Store(Path(root)).claim()
    except Exception as exc:  # reported to the parent, which fails the test
        return f"{type(exc).__name__}: {exc}"
    return ""


def test_concurrent_claims_of_a_new_folder_all_succeed(tmp_path: Path) -> None:
    """Two processes claiming the same new folder at once (the tuned suite's studies share results/tuning): both
    succeed, and the folder is marked, whoever wrote first."""
    ctx = multiprocessing.get_context("fork")
    with ctx.Manager() as manager:
        barrier = manager.Barrier(2)
        with ctx.Pool(2) as pool:
            for k in range(25):
                root = str(tmp_path / f"r{k}" / "tuning")
                errors = pool.starmap(_claim_at_barrier, [(root, barrier)] * 2)
                assert errors == ["", ""], errors
                assert (Path(root) / ".locbench").is_file() and (Path(root) / "runs").is_dir()


def test_a_mark_written_between_the_checks_is_accepted(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The interleaving the concurrent test may miss: the first look finds no mark, another process then marks
    the folder (and starts filling it) before the listing."""
    root = tmp_path / "tuning"
    root.mkdir()
    (root / ".locbench").write_text("x\n")
    (root / "runs").mkdir()
    real = Path.is_file
    seen: list[Path] = []

    def first_miss(self: Path) -> bool:
        if self.name == ".locbench" and not seen:
            seen.append(self)
            return False
        return real(self)

    monkeypatch.setattr(Path, "is_file", first_miss)
    Store(root).claim()
    assert seen


def test_a_foreign_folder_is_still_refused(tmp_path: Path) -> None:
    (tmp_path / "notes.txt").write_text("someone else's\n")
    with pytest.raises(ConfigError, match="not a locbench results folder"):
        Store(tmp_path).claim()
