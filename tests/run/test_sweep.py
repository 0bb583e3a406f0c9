"""Sweeps: the plan, executors (local pool and dask), workers that die, Ctrl-C, exit status and the summary."""

from __future__ import annotations

import errno
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from locbench.cli import main
from locbench.run import store as store_mod
from locbench.run.plan import NOT_STORED, plan_sweep
from locbench.run.store import Store
from locbench.run.sweep import run_many, run_sweep

TESTS = Path(__file__).resolve().parents[1]

#: A child ``locbench`` with the test-only ``line`` dataset and ``bad`` filter registered.
CHILD = """
import sys
from locbench.registry import DATASETS, FILTERS
DATASETS.register("line", "harness_support:LineBuilder")
FILTERS.register("bad", "harness_support:BadFilter")
from locbench.cli import main
sys.exit(main(sys.argv[1:]))
"""


def _same_arrays(a: Path, b: Path) -> int:
    """Number of runs compared; every stored array but the call times equal bit for bit."""
    sa, sb = Store(a), Store(b)
    runs = list(sa.iter_runs())
    assert [r.relative_to(sa.runs) for r in runs] == [r.relative_to(sb.runs) for r in sb.iter_runs()]
    for r in runs:
        ra, rb = sa.read_run(r), sb.read_run(sb.runs / r.relative_to(sa.runs))
        for name in ("t", "mean", "cov", "kind"):
            assert np.array_equal(getattr(ra, name), getattr(rb, name), equal_nan=True), (r, name)
        assert ra.diagnostics.keys() == rb.diagnostics.keys()
        for k in ra.diagnostics:
            assert np.array_equal(ra.diagnostics[k], rb.diagnostics[k], equal_nan=True), (r, k)
        assert ra.meta["status"] == rb.meta["status"] and ra.meta["run_key"] == rb.meta["run_key"]
    return len(runs)


@pytest.mark.usefixtures("harness_registry")
def test_plan_sorts_longest_first_and_skips_stored_runs(tmp_path: Path) -> None:
    plan = plan_sweep([(["odometry", "pf"], ["room", "office"], [0, 1])], str(tmp_path))
    assert plan.total == 8 and plan.cached == []
    costs = [t.cost_s for t in plan.tasks]
    assert costs == sorted(costs, reverse=True) and plan.tasks[0].dataset.name == "office"
    # stored timings, where present, replace the estimate (which is the same for both here: 10 s)
    res = str(tmp_path / "r")
    run_many(["bad[mode=slow]"], ["line[steps=20]"], [0], res)
    run_many(["bad[fail_at_s=100]"], ["line"], [0], res)
    plan = plan_sweep([(["bad[fail_at_s=100]"], ["line"], [1]), (["bad[mode=slow]"], ["line[steps=20]"], [1])], res)
    assert [t.dataset.name for t in plan.tasks] == ["line[steps=20]", "line"]
    assert 0.5 < plan.tasks[0].cost_s < 5 and plan.tasks[1].cost_s < 0.5
    assert len(plan_sweep([(["bad[mode=slow]"], ["line[steps=20]"], [0])], res).cached) == 1


@pytest.mark.usefixtures("harness_registry")
def test_a_run_whose_files_do_not_load_is_rerun_and_said_so(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run_many(["bad[fail_at_s=100]"], ["line"], [0, 1], str(tmp_path))
    est = Store(tmp_path).run_dir("line", "bad[fail_at_s=100]", 1) / "estimates.npz"
    est.write_bytes(est.read_bytes()[:100])
    argv = ["run", "--filter", "bad[fail_at_s=100]", "--dataset", "line", "--seeds", "2", "--results", str(tmp_path)]
    code = main([*argv, "--no-progress"])
    out = capsys.readouterr().out
    assert code == 0 and "1 cached, 1 ok" in out and "re-run: the stored run does not load" in out
    assert Store(tmp_path).unreadable("line", "bad[fail_at_s=100]", 1) is None


@pytest.mark.usefixtures("harness_registry")
def test_disk_full_is_an_error_and_a_nonzero_status(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    real = np.savez

    def full(path: object, **arrays: object) -> None:
        if "mean" in arrays:  # the runs, not the truth
            raise OSError(errno.ENOSPC, "No space left on device")
        real(path, **arrays)  # type: ignore[arg-type]

    monkeypatch.setattr(store_mod.np, "savez", full)
    argv = ["run", "--filter", "bad[fail_at_s=100]", "--dataset", "line", "--seeds", "3", "--results", str(tmp_path)]
    assert main([*argv, "--no-progress"]) == 1
    cap = capsys.readouterr()
    assert "3 runs in" in cap.out and f"3 {NOT_STORED}" in cap.out and "No space left on device" in cap.out
    assert "0 run(s) failed and 3 were not stored" in cap.err
    assert list(Store(tmp_path).iter_runs()) == []


@pytest.mark.usefixtures("harness_registry")
def test_errors_make_the_status_nonzero_and_skips_are_grouped(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["run", "--filter", "bad[mode=raise]", "ekf_icp", "odometry", "--dataset", "line", "--seeds", "4"]
    assert main([*argv, "--results", str(tmp_path), "--no-progress"]) == 1
    cap = capsys.readouterr()
    lines = cap.out.splitlines()
    assert lines[0] == f"12 runs in {tmp_path}/runs: 4 error, 4 ok, 4 skipped"
    skipped = [ln for ln in lines if ln.startswith("  skipped")]
    assert len(skipped) == 1 and skipped[0].startswith("  skipped x4: ekf_icp on line: ")
    assert any(ln.startswith("  error x4: bad on line: RuntimeError: boom") for ln in lines)
    assert "4 run(s) failed" in cap.err and "meta.json" in cap.err


@pytest.mark.usefixtures("harness_registry")
def test_a_worker_that_dies_is_an_error_run_and_the_sweep_goes_on(tmp_path: Path) -> None:
    out = run_many(["bad[mode=exit]", "bad[fail_at_s=100]"], ["line"], [0, 1], str(tmp_path), jobs=2)
    status = {(str(o.filter), o.seed): o for o in out}
    assert [status[("bad[fail_at_s=100]", s)].status for s in (0, 1)] == ["ok", "ok"]
    for s in (0, 1):
        o = status[("bad[mode=exit]", s)]
        assert o.status == "error" and "worker process died" in o.message
    # a worker's death is not the run's result: the next sweep tries it again
    again = run_many(["bad[mode=exit]", "bad[fail_at_s=100]"], ["line"], [0, 1], str(tmp_path), jobs=2)
    assert sorted(o.status for o in again) == ["cached", "cached", "error", "error"]


@pytest.mark.usefixtures("harness_registry")
def test_local_pool_stores_the_same_arrays_as_one_process(tmp_path: Path) -> None:
    specs = (["odometry", "ekf_landmarks", "bad[fail_at_s=100]"], ["line[noise_m=0.01]", "tiny_circle"], [0, 1])
    run_sweep(plan_sweep([specs], str(tmp_path / "one")))
    run_sweep(plan_sweep([specs], str(tmp_path / "pool")), "local", jobs=2)
    assert _same_arrays(tmp_path / "one", tmp_path / "pool") == 12


def _child(args: list[str], tmp_path: Path) -> subprocess.Popen[str]:
    started = tmp_path / "started"
    started.mkdir(exist_ok=True)
    env = dict(
        os.environ,
        PYTHONPATH=os.pathsep.join([str(TESTS), os.environ.get("PYTHONPATH", "")]),
        LOCBENCH_TEST_STARTED=str(started),
    )
    return subprocess.Popen(
        [sys.executable, "-c", CHILD, *args],
        cwd=tmp_path,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _stored(res: Path) -> int:
    return len(list(Store(res).iter_runs()))


def _interrupt(tmp_path: Path, extra: list[str], dataset: str = "line[steps=20]") -> tuple[int, str, str, int]:
    """Start a slow sweep (0.05 s per step, 8 seeds) and send SIGINT once a run is stored (20 steps a run), or,
    for longer runs, once a run has started (its worker touches a file in ``started/``): no fixed delay.

    Returns (exit status, stdout, stderr, runs stored).
    """
    res = tmp_path / "res"
    argv = ["run", "--filter", "bad[mode=slow]", "--dataset", dataset, "--seeds", "8", "--results", str(res)]
    proc = _child([*argv, "--no-progress", *extra], tmp_path)
    started = tmp_path / "started"
    ready = (lambda: _stored(res) >= 1) if dataset == "line[steps=20]" else (lambda: any(started.iterdir()))
    try:
        while not ready() and proc.poll() is None:
            time.sleep(0.05)
        assert proc.poll() is None, proc.communicate()
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:  # a failed assertion above: end the child, never leave it running
            proc.kill()
            proc.communicate()
    return proc.returncode, out, err, _stored(res)


@pytest.mark.parametrize(
    "extra",
    [["--jobs", "1"], ["--jobs", "2"], pytest.param(["--executor", "dask", "--jobs", "2"], marks=pytest.mark.slow)],
    ids=["inline", "pool", "dask"],
)
def test_ctrl_c_abandons_long_runs_in_progress(tmp_path: Path, extra: list[str], harness_registry: None) -> None:
    if "dask" in extra:
        pytest.importorskip("distributed")
    # every run takes 20 s of sleeps and the signal comes while one runs: none stored means the running ones
    # were abandoned, not awaited (a busy machine slows the start, never this)
    code, out, err, stored = _interrupt(tmp_path, extra, "line[steps=400]")
    assert code == 130, err
    assert err.strip() == "", err
    assert out.strip().splitlines() == ["interrupted: 0 of 8 runs stored; run the same command to resume"]
    assert stored == 0 and [p.name for p in (tmp_path / "res").rglob(".tmp-*")] == []


@pytest.mark.parametrize("extra", [["--jobs", "1"], ["--jobs", "2"]], ids=["inline", "pool"])
def test_ctrl_c_stops_keeps_finished_runs_and_resumes(
    tmp_path: Path, extra: list[str], capsys: pytest.CaptureFixture[str], harness_registry: None
) -> None:
    code, out, err, stored = _interrupt(tmp_path, extra)
    assert code == 130, err
    assert "Traceback" not in err and err.strip() == ""
    assert out.strip().splitlines() == [f"interrupted: {stored} of 8 runs stored; run the same command to resume"]
    assert 1 <= stored < 8
    res = str(tmp_path / "res")
    argv = ["run", "--filter", "bad[mode=slow]", "--dataset", "line[steps=20]", "--seeds", "8", "--results", res]
    assert main([*argv, "--no-progress", "--jobs", "2"]) == 0  # the same command resumes
    assert f"{stored} cached, {8 - stored} ok" in capsys.readouterr().out


@pytest.mark.parametrize(
    "extra",
    [{"jobs": 1}, {"jobs": 2}, pytest.param({"jobs": 2, "executor": "dask"}, marks=pytest.mark.slow)],
    ids=["inline", "pool", "dask"],
)
def test_ctrl_c_after_one_filter_keeps_it_and_the_rerun_does_the_rest(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, extra: dict[str, Any], harness_registry: None
) -> None:
    if extra.get("executor") == "dask":
        pytest.importorskip("distributed")
        monkeypatch.syspath_prepend(str(TESTS))  # the LocalCluster's spawned workers import harness_support
    # the third filter of the one task sends this process SIGINT when it starts: the two before it have finished
    monkeypatch.setenv("LOCBENCH_TEST_SIGNAL", str(tmp_path / "signalled"))
    monkeypatch.setenv("LOCBENCH_TEST_SIGNAL_PID", str(os.getpid()))
    specs = ["odometry", "bad[fail_at_s=100]", "bad[fail_at_s=100,mode=signal]"]
    res = tmp_path / "res"
    sweep = run_sweep(plan_sweep([(specs, ["line"], [0])], str(res)), **extra)
    assert sweep.interrupted and (tmp_path / "signalled").exists()
    assert [str(o.filter) for o in sweep.outcomes] == specs[:2]
    store = Store(res)
    assert set(store.iter_runs()) == {store.run_dir("line", f, 0) for f in specs[:2]}
    kept = {f: (store.run_dir("line", f, 0) / "meta.json").read_bytes() for f in specs[:2]}
    # the same sweep again: the two finished runs are cached (not recomputed, their files untouched), the third runs
    again = run_sweep(plan_sweep([(specs, ["line"], [0])], str(res)), **extra)
    assert not again.interrupted
    assert {str(o.filter): o.status for o in again.outcomes} == {specs[0]: "cached", specs[1]: "cached", specs[2]: "ok"}
    assert {f: (store.run_dir("line", f, 0) / "meta.json").read_bytes() for f in specs[:2]} == kept


@pytest.mark.slow
def test_dask_local_cluster_stores_the_same_arrays_as_the_local_run(tmp_path: Path) -> None:
    pytest.importorskip("distributed")
    assert main(["run", "--suite", "smoke", "--results", str(tmp_path / "local"), "--no-progress"]) == 0
    argv = ["run", "--suite", "smoke", "--results", str(tmp_path / "dask"), "--no-progress"]
    assert main([*argv, "--executor", "dask", "--jobs", "2"]) == 0
    assert _same_arrays(tmp_path / "local", tmp_path / "dask") == 12


@pytest.mark.slow
@pytest.mark.usefixtures("harness_registry")
def test_dask_filter_that_exits_mid_sweep_is_an_error_run_and_the_sweep_goes_on(tmp_path: Path) -> None:
    pytest.importorskip("distributed")
    specs = ["bad[mode=exit]", "bad[fail_at_s=100]"]
    sys.path.insert(0, str(TESTS))  # the LocalCluster's spawned workers import harness_support from sys.path
    try:
        out = run_many(specs, ["line"], [0, 1], str(tmp_path), jobs=2, executor="dask")
    finally:
        sys.path.remove(str(TESTS))
    status = {(str(o.filter), o.seed): o for o in out}
    assert len(status) == 4, [(str(o.filter), o.seed, o.status, o.message) for o in out]
    assert [status[("bad[fail_at_s=100]", s)].status for s in (0, 1)] == ["ok", "ok"], [o.message for o in out]
    for s in (0, 1):
        o = status[("bad[mode=exit]", s)]
        # the filter runs in a child of the dask worker (locbench.run.containment): the worker lives on
        assert o.status == "error" and "worker process died with exit code 3" in o.message


#: A child whose LocalCluster start receives a SIGINT (sent by the child to itself, inside the start): the
#: moment a Ctrl-C used to be dropped.
CHILD_SIGINT_IN_START = """
import os, signal, sys
import distributed
from locbench.registry import DATASETS, FILTERS
DATASETS.register("line", "harness_support:LineBuilder")
FILTERS.register("bad", "harness_support:BadFilter")
real = distributed.LocalCluster
class Interrupted(real):
    def __init__(self, *args, **kwargs):
        os.kill(os.getpid(), signal.SIGINT)
        super().__init__(*args, **kwargs)
distributed.LocalCluster = Interrupted
from locbench.cli import main
if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.slow
def test_sigint_during_the_dask_cluster_start_is_deferred_not_dropped(tmp_path: Path, harness_registry: None) -> None:
    pytest.importorskip("distributed")
    script = tmp_path / "child.py"
    script.write_text(CHILD_SIGINT_IN_START)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(TESTS), os.environ.get("PYTHONPATH", "")]))
    res = tmp_path / "res"
    argv = ["run", "--filter", "bad[mode=slow]", "--dataset", "line[steps=20]", "--seeds", "8", "--results", str(res)]
    proc = subprocess.run(
        [sys.executable, str(script), *argv, "--no-progress", "--executor", "dask", "--jobs", "2"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    # dropped, the sweep would run all 8 runs (a second each) and exit 0
    assert proc.returncode == 130, (proc.stdout, proc.stderr)
    assert proc.stdout.strip().splitlines() == ["interrupted: 0 of 8 runs stored; run the same command to resume"]
    assert _stored(res) == 0


@pytest.mark.slow
def test_dask_local_cluster_leaves_no_process_behind(tmp_path: Path) -> None:
    pytest.importorskip("distributed")
    import psutil

    before = {p.pid for p in psutil.Process().children(recursive=True)}
    assert main(["run", "--suite", "smoke", "--seeds", "1", "--results", str(tmp_path), "--no-progress"]) == 0
    argv = ["run", "--suite", "smoke", "--seeds", "1", "--results", str(tmp_path / "d"), "--no-progress"]
    assert main([*argv, "--executor", "dask", "--jobs", "2"]) == 0
    left = [p for p in psutil.Process().children(recursive=True) if p.pid not in before]
    # multiprocessing's resource tracker is the interpreter's own, shared by every pool: not the sweep's
    ours = [p for p in left if p.is_running() and p.status() != psutil.STATUS_ZOMBIE]
    assert [p for p in ours if "resource_tracker" not in " ".join(p.cmdline())] == []
