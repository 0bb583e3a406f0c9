"""Hostile input to `locbench tune`: a trial killed with SIGKILL, an edited or foreign journal, unbounded arguments."""

from __future__ import annotations

import json
import os
import select
import signal
import subprocess
import sys
import textwrap
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from locbench.cli import main
from locbench.core.events import Odometry
from locbench.core.tunable import tunable
from locbench.datasets.dataset import Gaussian2, SensorSpec, WorldMap
from locbench.filters.base import Estimate, Filter, FilterConfig
from locbench.registry import FILTERS
from locbench.run.store import Store

optuna = pytest.importorskip("optuna", reason="tuning needs optuna (pip install 'locbench[tune]')")

from locbench.run import tuning  # noqa: E402 - after the skip: the module needs optuna to tune

#: The entry point of the blocking filter, the same in the test process and in the child it kills.
BLOCKER = f"{Path(__file__).stem}:BlockingFilter"
#: Environment of the child: the FIFO its blocking trial announces itself on.
STARTED_FIFO_ENV = "LOCBENCH_TEST_TUNE_STARTED_FIFO"
#: Longest wait for the child to reach its blocking trial, s: only a safety net against a child that never gets
#: there (the synchronisation is the FIFO), generous for a busy machine.
SAFETY_NET_S = 300.0


@dataclass(frozen=True, kw_only=True)
class BlockingConfig(FilterConfig):
    #: an odometry gain; any value but the default makes the filter block at reset while STARTED_FIFO_ENV is set
    gain: float = field(default=1.0, metadata=tunable(0.5, 2.0))


class BlockingFilter(Filter):
    """Dead reckoning whose searched trials, in a process told so, announce themselves on a FIFO and then block
    forever: a trial in progress at a known moment, for a test to kill its process."""

    consumes = frozenset({Odometry})
    Config = BlockingConfig

    def reset(self, initial: Gaussian2, world: WorldMap, sensors: SensorSpec, rng: np.random.Generator) -> None:
        self._x = initial.mean.copy()
        self._t = 0.0
        fifo = os.environ.get(STARTED_FIFO_ENV)
        if fifo and self.config.gain != 1.0:  # type: ignore[attr-defined]
            with open(fifo, "w", encoding="ascii") as f:
                f.write("started\n")
            threading.Event().wait()  # until the test kills this process

    def predict(self, u: Odometry) -> None:
        self._t = u.t
        self._x = self._x + np.asarray(u.delta) * self.config.gain  # type: ignore[attr-defined]

    def update(self, z: Any) -> None:
        self.check_consumes(z)

    def estimate(self) -> Estimate:
        return Estimate(self._t, self._x.copy(), np.eye(3) * 0.01)


def _journal(results: Path) -> Path:
    (path,) = (results / tuning.TUNING_DIR / "studies").glob("*.journal")
    return path


def _wait_started(fifo: int, child: subprocess.Popen[bytes]) -> None:
    """Block until the child writes to the FIFO; the timeout only ends a wait for a child that died or hangs."""
    waited = 0.0
    while waited < SAFETY_NET_S:
        ready, _, _ = select.select([fifo], [], [], 1.0)
        if ready and os.read(fifo, 64):
            return
        waited += 1.0
        if child.poll() is not None:
            raise AssertionError(f"the child ended (rc {child.returncode}) before its trial started")
    raise AssertionError("the child's trial never started")


def test_a_trial_killed_with_sigkill_is_failed_on_resume_and_replaced(
    tmp_path: Path, isolated_registries: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    results = tmp_path / "results"
    fifo_path = tmp_path / "started.fifo"
    os.mkfifo(fifo_path)
    # opened before the child starts, without waiting for a writer: the child's open for writing never blocks
    fifo = os.open(fifo_path, os.O_RDONLY | os.O_NONBLOCK)
    script = textwrap.dedent(
        f"""
        from locbench.registry import FILTERS
        from locbench.run import tuning
        FILTERS.register("blocker", {BLOCKER!r})
        tuning.tune("blocker", ["tiny_line"], 3, 1, {str(results)!r})
        """
    )
    env = {
        **os.environ,
        STARTED_FIFO_ENV: str(fifo_path),
        "PYTHONPATH": os.pathsep.join([str(Path(__file__).parent), os.environ.get("PYTHONPATH", "")]),
    }
    child = subprocess.Popen([sys.executable, "-c", script], env=env, stderr=subprocess.PIPE)
    try:
        _wait_started(fifo, child)
        FILTERS.register("blocker", BLOCKER)
        monkeypatch.syspath_prepend(str(Path(__file__).parent))
        storage, study = tuning.open_journal(
            optuna, _journal(results), tuning.study_name("blocker", ["tiny_line"], 1, "ate")
        )
        running = study.get_trials(states=(optuna.trial.TrialState.RUNNING,))
        assert [t.number for t in running] == [1], "trial 0 (the default) finished, trial 1 is in progress"
        owner = running[0].user_attrs[tuning.OWNER_ATTR]
        assert owner["pid"] == child.pid
        # a trial whose process is alive belongs to a study in progress elsewhere: never failed
        assert tuning.fail_dead_trials(optuna, study, storage, _journal(results)) == []
        child.send_signal(signal.SIGKILL)
        assert child.wait() == -signal.SIGKILL
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
        os.close(fifo)
        assert child.stderr is not None
        child.stderr.close()

    res = tuning.tune("blocker", ["tiny_line"], 3, 1, results)
    assert [t.number for t in res.trials] == [0, 2, 3], "the killed trial is failed and a replacement runs"
    trials = optuna.load_study(study_name=res.name, storage=storage).get_trials()
    killed = trials[1]
    assert killed.state == optuna.trial.TrialState.FAIL and "process died" in killed.user_attrs["message"]
    # the replacement asks what the killed trial asked (the sampler is seeded by the study's state)
    assert trials[2].user_attrs["spec"] == killed.user_attrs["spec"]
    assert len(res.trials) == 3 and res.best is not None


def _tuned(results: Path, trials: int = 3) -> tuning.TuneResult:
    return tuning.tune("ekf_landmarks", ["tiny_line"], trials, 1, results)


def _edit_value(path: Path, number: int, value: Any) -> None:
    lines = path.read_text(encoding="utf-8").splitlines()
    for i, line in enumerate(lines):
        op = json.loads(line)
        if op.get("trial_id") == number and op.get("values") is not None:
            op["values"] = [value]
            lines[i] = json.dumps(op)
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def _cli(results: Path, *extra: str, trials: str = "3", seeds: str = "1") -> list[str]:
    return ["tune", "ekf_landmarks", "--dataset", "tiny_line", "--trials", trials, "--seeds", seeds, "--results",
            str(results), *extra]  # fmt: skip


def test_an_edited_journal_value_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    first = _tuned(tmp_path)
    path = _journal(tmp_path)
    true_value = first.trials[1].value
    _edit_value(path, 1, -1)
    capsys.readouterr()
    assert main(_cli(tmp_path, trials="4")) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert str(path) in err and "trial 1" in err and "-1" in err and repr(true_value) in err
    # the refusal left the journal as it was: no new trial was asked
    assert max(json.loads(ln).get("trial_id", -1) for ln in path.read_text().splitlines()) == 2


def test_a_journal_spec_that_its_parameters_do_not_give_is_refused(tmp_path: Path) -> None:
    _tuned(tmp_path)
    path = _journal(tmp_path)
    text = path.read_text(encoding="utf-8")
    spec = _tuned(tmp_path).trials[1].spec
    path.write_text(text.replace(json.dumps(spec), json.dumps("ekf_landmarks[sigma_range_m=0.5]")), encoding="utf-8")
    with pytest.raises(tuning.ConfigError, match=r"trial 1 records spec .*sigma_range_m=0\.5.*its parameters give"):
        _tuned(tmp_path)


def test_a_trial_whose_runs_are_missing_is_run_again_and_must_match(tmp_path: Path) -> None:
    first = _tuned(tmp_path)
    store = Store(tmp_path / tuning.TUNING_DIR)
    lost = store.run_dir("tiny_line", first.trials[2].spec, tuning.TRAIN_SEED_START)
    for p in sorted(lost.rglob("*"), reverse=True):
        p.unlink() if p.is_file() else p.rmdir()
    lost.rmdir()
    again = _tuned(tmp_path, 4)
    assert lost.is_dir(), "the missing run was run again"
    assert again.trials[:3] == first.trials and len(again.trials) == 4


def test_a_journal_of_random_bytes_is_one_line_naming_the_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _tuned(tmp_path, 2)
    path = _journal(tmp_path)
    rng = np.random.default_rng(7)
    cases = {
        "random bytes": rng.bytes(4096),
        "random bytes, newline-terminated": rng.bytes(4096) + b"\n",
        "JSON but no operation": b'{"a": 1}\n',
        "operations optuna cannot replay": b'{"op_code": 3, "worker_id": "w"}\n',
        "a cut-short last line": path.read_bytes() + b'{"op_code": 4, "wor',
    }
    for what, data in cases.items():
        path.write_bytes(data)
        capsys.readouterr()
        assert main(_cli(tmp_path, trials="2")) == 2, what
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and str(path) in err and "optuna journal" in err, (what, err)
        assert path.read_bytes() == data, f"{what}: the refused journal is left as it was"


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["--seeds", "1000000000"], "--seeds: 1000000000 seeds, more than the limit of 10000"),
        (["--seeds", str(2**63)], f"--seeds: {2**63} seeds, more than the limit"),
        (["--seeds", "0"], "--seeds must be a positive integer"),
        (["--seeds", "-3"], "--seeds must be a positive integer"),
        (["--seeds", "20", "--max-seeds", "10"], "--seeds: 20 seeds, more than the limit of 10"),
        (["--max-seeds", "0"], "--max-seeds must be >= 1"),
        (["--trials", "0"], "--trials must be an integer in 1..10000"),
        (["--trials", str(2**63)], "--trials must be an integer in 1..10000"),
        (["--jobs", "0"], "--jobs: expected 1-1024"),
        (["--jobs", "100000"], "--jobs: expected 1-1024"),
        (["--scheduler", "tcp://h:1"], "--scheduler needs --executor dask"),
        (["--executor", "dask", "--scheduler", "http://h:1"], "--scheduler 'http://h:1'"),
    ],
)
def test_arguments_are_bounded_before_anything_is_written(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], expected: str
) -> None:
    base = _cli(tmp_path, trials="2")
    for flag in ("--seeds", "--trials"):
        if flag in args:
            i = base.index(flag)
            del base[i : i + 2]
    assert main([*base, *args]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and expected in err, err
    assert not (tmp_path / tuning.TUNING_DIR).exists()


def test_the_library_bounds_its_arguments_too(tmp_path: Path) -> None:
    for kwargs in ({"trials": 10**9, "seeds": 1}, {"trials": 2, "seeds": 10**9}, {"trials": True, "seeds": 1}):
        with pytest.raises(tuning.ConfigError):
            tuning.tune("ekf_landmarks", ["tiny_line"], results=tmp_path, **kwargs)  # type: ignore[arg-type]
    assert not (tmp_path / tuning.TUNING_DIR).exists()
