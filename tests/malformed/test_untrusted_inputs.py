"""Inputs locbench did not write: the store's own files altered, another tool's folder, and CLI inputs out of
bounds. Each gets one line (exit 2) or a rerun, never a traceback, a hang or a wrong run stored as ok."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from locbench.cli import main
from locbench.core.errors import ConfigError
from locbench.datasets.recorded.ros_map import MAX_YAML_BYTES
from locbench.datasets.recorded.rosbag import MAX_BAG_BYTES, resolve_bag_path
from locbench.run.store import MARKER, Store
from locbench.run.sweep import run_many

TESTS = Path(__file__).resolve().parents[1]
SMOKE = ["run", "--filter", "odometry", "--dataset", "tiny_line", "--no-progress"]


def _one_line(capsys: pytest.CaptureFixture[str], *expected: str) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert len(err) < 1200, len(err)
    for text in expected:
        assert text in err, err
    return err


# --- the store verifies what it reads --------------------------------------------------------------------


def _rewrite_npz(path: Path, change: dict[str, np.ndarray]) -> None:
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    arrays.update(change)
    np.savez_compressed(path, **arrays)  # type: ignore[arg-type]


def _flip_byte(path: Path) -> None:
    data = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as z:
        info = z.infolist()[0]
    start = info.header_offset + 30 + len(info.filename) + int.from_bytes(data[info.header_offset + 28 :][:2], "little")
    data[start + info.compress_size // 2] ^= 0xFF  # inside the first member's compressed bytes
    path.write_bytes(bytes(data))


ALTERATIONS = {
    "flipped byte": lambda d: _flip_byte(d / "estimates.npz"),
    "wrong shape": lambda d: _rewrite_npz(d / "estimates.npz", {"mean": np.zeros((2, 2))}),
    "nan rows under ok": lambda d: _rewrite_npz(d / "estimates.npz", {"mean": np.full((5, 3), np.nan)}),
    "reversed times": lambda d: _rewrite_npz(d / "estimates.npz", {"t": np.arange(5.0)[::-1].copy()}),
    "meta names another seed": lambda d: (d / "meta.json").write_text(
        json.dumps(json.loads((d / "meta.json").read_text()) | {"seed": 0})
    ),
    "meta edited": lambda d: (d / "meta.json").write_text(
        json.dumps(json.loads((d / "meta.json").read_text()) | {"filter_version": 99})
    ),
}


@pytest.mark.usefixtures("harness_registry")
@pytest.mark.parametrize("how", list(ALTERATIONS))
def test_an_altered_run_is_stale_rerun_and_left_out_of_the_report(
    tmp_path: Path, how: str, capsys: pytest.CaptureFixture[str]
) -> None:
    res = str(tmp_path)
    run_many(["bad[fail_at_s=100]"], ["line"], [0, 1], res)
    st = Store(tmp_path)
    run = st.run_dir("line", "bad[fail_at_s=100]", 1)
    if how == "nan rows under ok" or how == "reversed times":
        n = st.read_run(run).t.shape[0]
        fix = {"mean": np.full((n, 3), np.nan)} if how.startswith("nan") else {"t": np.arange(float(n))[::-1].copy()}
        _rewrite_npz(run / "estimates.npz", fix)
    else:
        ALTERATIONS[how](run)
    reason = st.unreadable("line", "bad[fail_at_s=100]", 1)
    assert reason is not None and "\n" not in reason
    # the report lists it with the reason and uses none of its numbers
    from locbench.report.collect import collect

    col = collect(st)
    assert [r.seed for r in col.runs] == [0]
    assert len(col.broken) == 1 and "seed-0001" in col.broken[0][0]
    # the sweep runs it again
    argv = ["run", "--filter", "bad[fail_at_s=100]", "--dataset", "line", "--seeds", "2", "--results", res]
    assert main([*argv, "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "1 cached, 1 ok" in out and "re-run" in out
    assert st.unreadable("line", "bad[fail_at_s=100]", 1) is None


@pytest.mark.usefixtures("harness_registry")
def test_an_altered_truth_reruns_its_runs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    res = str(tmp_path)
    run_many(["bad[fail_at_s=100]"], ["line"], [0], res)
    st = Store(tmp_path)
    _rewrite_npz(st.truth_path("line", 0), {"gt_xy": np.zeros((3, 2))})
    assert st.truth_problem("line", 0) is not None
    argv = ["run", "--filter", "bad[fail_at_s=100]", "--dataset", "line", "--results", res, "--no-progress"]
    assert main(argv) == 0
    assert "1 ok" in capsys.readouterr().out
    assert st.truth_problem("line", 0) is None


def test_a_bound_of_the_wrong_shape_does_not_crash_the_report(tmp_path: Path) -> None:
    res = str(tmp_path)
    run_many(["odometry"], ["tiny_line"], [0], res)
    st = Store(tmp_path)
    from locbench.evaluate.records import BoundRecord
    from locbench.report.collect import collect

    t = st.read_truth("tiny_line", 0).ground_truth.t
    st.write_bound(BoundRecord("tiny_line", 0, t, {"PCRB": np.tile(np.eye(3), (t.size, 1, 1))}, {"bound_key": "k"}))
    assert st.read_bound("tiny_line", 0) is not None
    _rewrite_npz(st.bound_path("tiny_line", 0), {"cov_0": np.zeros((2, 3))})
    col = collect(st)
    assert any("bound" in p for p, _ in col.broken)
    assert st.bound_key("tiny_line", 0) is None  # the sweep computes it again


# --- only its own files ----------------------------------------------------------------------------------


def test_a_folder_of_another_tool_is_refused_and_left_alone(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    other = tmp_path / "project"
    (other / "runs" / "a" / "b").mkdir(parents=True)
    mine = [other / "notes.old", other / "runs" / "a" / "b" / ".tmp-abcdefgh", other / "runs" / "a" / "b" / "x.old"]
    for f in mine:
        f.write_text("theirs")
    os.utime(mine[1], (0, 0))
    assert main([*SMOKE, "--results", str(other)]) == 2
    _one_line(capsys, str(other), "not a locbench results folder")
    assert all(f.read_text() == "theirs" for f in mine)
    assert not (other / MARKER).exists()


def test_a_new_folder_is_marked_and_reused(tmp_path: Path) -> None:
    res = tmp_path / "new"
    assert main([*SMOKE, "--results", str(res)]) == 0
    assert (res / MARKER).is_file()
    assert main([*SMOKE, "--results", str(res)]) == 0


def test_the_committed_results_folder_is_marked() -> None:
    assert (TESTS.parent / "results" / MARKER).is_file()


# --- CLI inputs bounded before work ----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("address", "expected"),
    [
        ("garbage", "no port"),
        ("", "empty address"),
        ("tcp://[::1:8786", "malformed IPv6"),
        ("tcp://[fe80::zz]:8786", "malformed IPv6"),
        ("http://127.0.0.1:8787", "dashboard"),
        ("ucx://127.0.0.1:8786", "UCX"),
        ("inproc://10.0.0.1/1/2", "inproc"),
        ("tcp://" + "a" * 100_000 + ":1", "characters"),
        ("tcp://host:99999", "port"),
        ("tcp://ho st:1", "spaces"),
        ("tcp://::1:8786", "brackets"),
    ],
)
def test_a_bad_scheduler_address_is_one_line(
    tmp_path: Path, address: str, expected: str, capsys: pytest.CaptureFixture[str]
) -> None:
    pytest.importorskip("distributed")
    argv = [*SMOKE, "--results", str(tmp_path / "r"), "--executor", "dask", "--scheduler", address]
    assert main(argv) == 2
    _one_line(capsys, "--scheduler", expected)
    assert not (tmp_path / "r").exists()


def test_a_scheduler_that_never_answers_is_one_line_after_the_timeout(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # A socket that listens but never accepts: the kernel completes the TCP handshake, nothing ever replies.
    pytest.importorskip("distributed")
    with socket.socket() as silent:
        silent.bind(("127.0.0.1", 0))
        silent.listen(4)
        address = f"tcp://127.0.0.1:{silent.getsockname()[1]}"
        argv = [*SMOKE, "--results", str(tmp_path / "r"), "--executor", "dask", "--scheduler", address]
        assert main([*argv, "--connect-timeout", "1"]) == 2
    _one_line(capsys, "cannot reach the dask scheduler", "within 1 s")


def test_a_scheduler_that_answers_runs_the_sweep(tmp_path: Path) -> None:
    # The identity probe before the client must let a real scheduler through (in-process: no child to end).
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(
        n_workers=1,
        processes=False,
        protocol="tcp://",
        host="127.0.0.1",
        dashboard_address=":0",
        scheduler_kwargs={"dashboard": False},
    ) as cluster:
        argv = [
            *SMOKE,
            "--results",
            str(tmp_path / "r"),
            "--executor",
            "dask",
            "--scheduler",
            cluster.scheduler_address,
        ]
        assert main(argv) == 0
    assert len(list(Store(tmp_path / "r").iter_runs())) == 1


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["--seeds", "1000000000"], "more than the limit of 10000"),
        (["--seeds", str(2**63 - 1)], "more than the limit"),
        (["--seeds", str(2**64)], "more than the limit"),
        (["--seeds", "0"], "positive integer"),
        (["--connect-timeout", "0"], "--connect-timeout"),
        (["--connect-timeout", "nan"], "--connect-timeout"),
        (["--max-configs", "0"], "--max-configs"),
    ],
)
def test_counts_out_of_bounds_are_one_line(
    tmp_path: Path, argv: list[str], expected: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main([*SMOKE, "--results", str(tmp_path / "r"), *argv]) == 2
    _one_line(capsys, expected)
    assert not (tmp_path / "r").exists()


def test_a_huge_grid_is_refused_before_it_is_expanded(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    grid = "pf[" + ",".join(f"k{i}=" + "|".join(str(v) for v in range(10)) for i in range(10)) + "]"
    argv = ["run", "--filter", grid, "--dataset", "room", "--results", str(tmp_path / "r")]
    assert main(argv) == 2
    _one_line(capsys, "10000000000", "limit of 10000", "--max-configs")
    # the option raises the limit (here the grid then fails on its unknown keys, after counting)
    argv = [
        "run",
        "--filter",
        "pf[particles=10|20|30]",
        "--dataset",
        "room",
        "office",
        "--results",
        str(tmp_path / "r"),
    ]
    assert main([*argv, "--max-configs", "5"]) == 2
    _one_line(capsys, "= 6, more than the limit of 5")


@pytest.mark.parametrize("seeds", ["1e9", str(2**63 - 1), str(2**64), "1000000000"])
def test_suite_file_seed_counts_are_bounded(tmp_path: Path, seeds: str, capsys: pytest.CaptureFixture[str]) -> None:
    f = tmp_path / "s.toml"
    f.write_text(f'filters = ["odometry"]\ndatasets = ["room"]\nseeds = {seeds}\n')
    assert main(["run", "--suite", str(f), "--results", str(tmp_path / "r")]) == 2
    _one_line(capsys, str(f), "seeds")


def test_suite_files_must_be_small_regular_files(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    fifo = tmp_path / "fifo.toml"
    os.mkfifo(fifo)
    big = tmp_path / "big.toml"
    big.write_bytes(b"#" * (2 << 20))
    for path, expected in ((fifo, "not a regular file"), ("/dev/zero", "not a regular file"), (big, "bytes")):
        assert main(["run", "--suite", str(path), "--results", str(tmp_path / "r")]) == 2
        _one_line(capsys, str(path), expected)
    assert main(["run", "--suite", str(tmp_path), "--results", str(tmp_path / "r")]) == 2
    _one_line(capsys, "is a folder")


@pytest.mark.parametrize("what", ["bag", "map"])
def test_bag_and_map_paths_must_be_small_regular_files(tmp_path: Path, what: str) -> None:
    """A FIFO, a device, a folder where a file is expected or an oversize file: one line before anything opens it."""
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    big = tmp_path / "big.yaml"
    with open(big, "wb") as f:  # sparse: no disk used
        f.truncate(MAX_YAML_BYTES + 1)
    cases: list[tuple[str | Path, str]] = [(fifo, "not a regular file"), ("/dev/zero", "not a regular file")]
    if what == "map":
        cases += [(tmp_path, "is a folder; expected the map YAML as a regular file"), (big, "bytes")]
    else:
        (tmp_path / "ros2").mkdir()
        os.mkfifo(tmp_path / "ros2" / "data.db3")
        cases += [(tmp_path / "ros2", "not a regular file in the bag folder")]
    for path, expected in cases:
        with pytest.raises(ConfigError) as info:
            resolve_bag_path(path, what)
        message = str(info.value)
        assert str(path) in message and expected in message and "\n" not in message, message


def test_an_oversize_bag_is_refused_with_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag = tmp_path / "huge.bag"
    with open(bag, "wb") as f:  # sparse: no disk used
        f.truncate(MAX_BAG_BYTES + 1)
    argv = ["run", "--filter", "odometry", "--dataset", f"rosbag[path={bag}]", "--results", str(tmp_path / "r")]
    main(argv)
    out = capsys.readouterr()
    assert "Traceback" not in out.err
    runs = list((tmp_path / "r").rglob("meta.json"))
    assert len(runs) == 1
    meta = json.loads(runs[0].read_text())
    assert meta["status"] == "error" and str(bag) in meta["message"] and f"{MAX_BAG_BYTES} bytes" in meta["message"]


def test_a_long_spec_error_is_capped(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["run", "--filter", "pf[particles=" + "9" * 1_000_000 + "x]", "--dataset", "room"]
    assert main([*argv, "--results", str(tmp_path / "r")]) == 2
    _one_line(capsys, "particles")


# --- faults ----------------------------------------------------------------------------------------------


@pytest.mark.usefixtures("harness_registry")
def test_a_full_disk_is_found_before_anything_is_computed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from locbench.run import store as store_mod

    class Usage:
        free = 10 * 2**20

    monkeypatch.setattr(store_mod.shutil, "disk_usage", lambda p: Usage())
    computed = []
    from locbench.run import executors

    real = executors.execute_contained  # what the executors run, looked up as each part is submitted
    monkeypatch.setattr(executors, "execute_contained", lambda task: computed.append(task) or real(task))
    argv = ["run", "--filter", "bad[fail_at_s=100]", "--dataset", "line", "--results", str(tmp_path), "--no-progress"]
    assert main(argv) == 2
    _one_line(capsys, "MB free", "disk is full")
    assert computed == [] and list(Store(tmp_path).iter_runs()) == []


@pytest.mark.usefixtures("harness_registry")
def test_not_stored_lines_name_the_run_and_its_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import errno

    from locbench.run import store as store_mod

    real = store_mod.np.savez

    def full(path: object, **arrays: object) -> None:
        if "mean" in arrays:
            raise OSError(errno.ENOSPC, "No space left on device")
        real(path, **arrays)  # type: ignore[arg-type]

    monkeypatch.setattr(store_mod.np, "savez", full)
    argv = ["run", "--filter", "bad[fail_at_s=100]", "--dataset", "line", "--seeds", "2", "--results", str(tmp_path)]
    assert main([*argv, "--no-progress"]) == 1
    cap = capsys.readouterr()
    lines = [ln for ln in cap.out.splitlines() if "not stored" in ln and "seed" in ln]
    for seed in (0, 1):
        where = Store(tmp_path).run_dir("line", "bad[fail_at_s=100]", seed)
        assert any(f"seed {seed} -> {where}" in ln for ln in lines), cap.out
    assert "meta.json" not in cap.err and "listed above" in cap.err


WORKER_PARENT = """
import os, sys, time
from concurrent.futures import ProcessPoolExecutor
from locbench.run.executors import _pool_worker_init
pool = ProcessPoolExecutor(max_workers=2, initializer=_pool_worker_init)
futs = [pool.submit(os.getpid) for _ in range(4)]
print(" ".join(str(p) for p in sorted({f.result() for f in futs})), flush=True)
time.sleep(600)
"""


def test_pool_workers_end_when_their_parent_is_killed(tmp_path: Path) -> None:
    import psutil

    parent = subprocess.Popen([sys.executable, "-c", WORKER_PARENT], stdout=subprocess.PIPE, text=True)
    try:
        assert parent.stdout is not None
        pids = [int(p) for p in parent.stdout.readline().split()]
        workers = [psutil.Process(p) for p in pids]
        assert workers
    finally:
        parent.send_signal(signal.SIGKILL)
        parent.wait()
        if parent.stdout is not None:
            parent.stdout.close()
    _, alive = psutil.wait_procs(workers, timeout=60)
    for p in alive:
        p.kill()
    assert alive == []
