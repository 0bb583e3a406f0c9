"""Hostile and broken filter plugins, installed through a real entry point (a temporary ``*.dist-info`` folder on
``sys.path``, read by ``importlib.metadata`` as ``locbench list`` reads it): none of them takes the command line
down. A plugin that does not import or is not a valid class is listed as unavailable and refused in one line;
one that exits, crashes, hangs or returns estimates that break the contract is a failed run with its reason,
and the sweep goes on."""

from __future__ import annotations

import json
import os
import signal
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from locbench.cli import main
from locbench.registry import FILTERS, make_dataset
from locbench.run.containment import DEFAULT_RULE, call_in_child, run_time_limit
from locbench.run.execute import execute_contained, execute_task
from locbench.run.plan import plan_sweep
from locbench.run.store import Store
from locbench.run.sweep import run_many

DIST, VERSION = "lbtest-plugins", "1.0"

#: A valid plugin filter (dead reckoning) that misbehaves as its config says: ``mode`` what, ``where`` when
#: (in ``reset``, the third ``predict``, or the first ``update``); the estimate modes break the contract from
#: the third prediction on.
HOSTILE = """
import ctypes
import os
import time
from dataclasses import dataclass

import numpy as np

from locbench.filters.api import Estimate, Filter, FilterConfig, LandmarkObservations, Odometry


@dataclass(frozen=True, kw_only=True)
class HostileConfig(FilterConfig):
    mode: str = "ok"
    where: str = "predict"


class Hostile(Filter):
    consumes = frozenset({Odometry, LandmarkObservations})
    Config = HostileConfig

    def reset(self, initial, world, sensors, rng):
        self._x, self._t, self._n = np.array(initial.mean, dtype=float), 0.0, 0
        if self.config.where == "reset":
            self._act()

    def predict(self, u):
        self._t, self._x, self._n = u.t, self._x + u.delta, self._n + 1
        if self.config.where == "predict" and self._n == 3:
            self._act()

    def update(self, z):
        if self.config.where == "update":
            self._act()

    def _act(self):
        mode = self.config.mode
        if mode == "exit":
            os._exit(3)
        if mode == "sysexit":
            raise SystemExit(4)
        if mode == "segv":
            ctypes.string_at(0)
        while mode == "sleep":
            time.sleep(1)
        while mode == "spin":
            pass

    def estimate(self):
        m, c = self._x.copy(), np.eye(3) * 0.01
        mode = self.config.mode if self._n >= 3 else ""
        if mode == "cov3":
            c = np.ones(3)
        elif mode == "asym":
            c[0, 1] += 0.005
        elif mode == "nonpsd":
            c[2, 2] = -0.01
        elif mode == "heading100":
            m[2] = 100.0
        elif mode == "cov2":
            c = np.eye(2)
        elif mode == "mean2":
            m = m[:2]
        return Estimate(self._t, m, c)
"""

_TUNED = """
from dataclasses import dataclass, field

from locbench.filters.api import FilterConfig, tunable
from lbtest_hostile import Hostile


@dataclass(frozen=True, kw_only=True)
class Cfg(FilterConfig):
    gain: float = field(default=1.0, metadata=tunable({low}, {high}{log}))


class Tuned(Hostile):
    Config = Cfg
"""

#: id -> (module name, module source, attribute, what the one-line reason says)
BROKEN = {
    "lbt_raises": ("lbtest_raises", "raise RuntimeError('boom at import')\n", "F", "RuntimeError: boom at import"),
    "lbt_syntax": ("lbtest_syntax", "def f(:\n", "F", "SyntaxError: invalid syntax"),
    "lbt_noclass": ("lbtest_noclass", "X = 1\n", "Missing", "module 'lbtest_noclass' has no attribute 'Missing'"),
    "lbt_notfilter": (
        "lbtest_notfilter",
        "class NotAFilter:\n    pass\n",
        "NotAFilter",
        "lbtest_notfilter.NotAFilter is not a subclass of locbench.filters.base.Filter",
    ),
    "lbt_lowhigh": ("lbtest_lowhigh", _TUNED.format(low=5.0, high=1.0, log=""), "Tuned", "low < high"),
    "lbt_log0": ("lbtest_log0", _TUNED.format(low=0.0, high=1.0, log=", log=True"), "Tuned", "needs low > 0"),
    "lbt_nan": ("lbtest_nan", _TUNED.format(low="float('nan')", high=1.0, log=""), "Tuned", "must be finite"),
    "lbt_hangs": ("lbtest_hangs", "import time\nwhile True:\n    time.sleep(1)\n", "F", "did not finish within 2 s"),
    "lbt_exits": ("lbtest_exits", "import os\nos._exit(5)\n", "F", "its import ended the process (exit code 5)"),
}


@pytest.fixture(scope="module")
def plugins(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """The hostile plugin (``lbt_hostile``) and every broken one, installed as one distribution on sys.path."""
    root = tmp_path_factory.mktemp("plugins")
    info = root / f"{DIST.replace('-', '_')}-{VERSION}.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {DIST}\nVersion: {VERSION}\n")
    (root / "lbtest_hostile.py").write_text(HOSTILE)
    lines = ["[locbench.filters]", "lbt_hostile = lbtest_hostile:Hostile"]
    for ident, (module, source, attr, _) in BROKEN.items():
        (root / f"{module}.py").write_text(source)
        lines.append(f"{ident} = {module}:{attr}")
    (info / "entry_points.txt").write_text("\n".join(lines) + "\n")
    old_timeout = os.environ.get("LOCBENCH_PLUGIN_TIMEOUT")
    os.environ["LOCBENCH_PLUGIN_TIMEOUT"] = "2"
    sys.path.insert(0, str(root))
    FILTERS.forget_plugins()
    try:
        yield root
    finally:
        sys.path.remove(str(root))
        if old_timeout is None:
            del os.environ["LOCBENCH_PLUGIN_TIMEOUT"]
        else:
            os.environ["LOCBENCH_PLUGIN_TIMEOUT"] = old_timeout
        FILTERS.forget_plugins()
        for name in [m for m in sys.modules if m.startswith("lbtest_")]:
            del sys.modules[name]


def _origin(ident: str) -> str:
    module, _, attr, _ = BROKEN[ident]
    return f"entry point {ident} = {module}:{attr} ({DIST} {VERSION}) failed to load: "


def test_list_shows_each_broken_plugin_as_unavailable_with_its_entry_point(
    plugins: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    for ident, (_, _, _, why) in BROKEN.items():
        [line] = [ln for ln in lines if ln.startswith(f"  {ident} ")]
        assert f"[unavailable: {_origin(ident)}" in line and why in line, line
    [hostile] = [ln for ln in lines if ln.startswith("  lbt_hostile ")]
    assert "unavailable" not in hostile
    assert any(ln.startswith("  ekf_landmarks ") for ln in lines) and "suites:" in lines


@pytest.mark.parametrize("ident", sorted(BROKEN))
def test_running_a_broken_plugin_is_one_line_naming_its_entry_point(
    plugins: Path, ident: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["run", "--filter", ident, "--dataset", "tiny_line", "--results", str(tmp_path), "--no-progress"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.startswith(f"locbench: error: filter {ident!r} is unavailable: {_origin(ident)}")
    assert BROKEN[ident][3] in err
    assert not (tmp_path / "runs").exists()


def test_check_fails_a_broken_plugin_in_one_line(plugins: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", "lbt_raises"]) == 1
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("FAIL ") and "check_loads" in out[0] and _origin("lbt_raises") in out[0]


@pytest.mark.slow
def test_other_filters_run_and_tune_beside_broken_plugins(
    plugins: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["run", "--filter", "odometry", "lbt_hostile", "--dataset", "tiny_line", "--results", str(tmp_path)]
    assert main([*argv, "--no-progress"]) == 0
    assert "2 runs in" in capsys.readouterr().out
    tune = ["tune", "ekf_landmarks", "--dataset", "tiny_line", "--trials", "1", "--seeds", "1"]
    assert main([*tune, "--results", str(tmp_path)]) == 0
    assert capsys.readouterr().out.splitlines()[-1].startswith("ekf_landmarks")


def _metas(results: Path) -> dict[str, dict[str, object]]:
    store = Store(results)
    return {str(m["filter"]): m for m in (store.read_run(d).meta for d in store.iter_runs())}


def test_a_filter_that_ends_its_process_is_a_failed_run_and_the_sweep_goes_on(plugins: Path, tmp_path: Path) -> None:
    specs = ["lbt_hostile[mode=exit]", "lbt_hostile[mode=segv]", "lbt_hostile[mode=sysexit]", "odometry"]
    out = {str(o.filter): o for o in run_many(specs, ["tiny_line"], [0], str(tmp_path), jobs=1)}
    assert out["odometry"].status == "ok"
    metas = _metas(tmp_path)
    expected = {
        "lbt_hostile[mode=exit]": "worker process died with exit code 3",
        "lbt_hostile[mode=segv]": "worker process died with signal SIGSEGV",
        "lbt_hostile[mode=sysexit]": "SystemExit: 4",
    }
    for spec, why in expected.items():
        assert out[spec].status == "error" and why in out[spec].message, out[spec]
        assert metas[spec]["status"] == "error" and why in str(metas[spec]["message"])


def _timed_out(metas: dict[str, dict[str, object]], spec: str, limit: float) -> None:
    meta = metas[spec]
    assert meta["status"] == "error" and meta["run_timeout_s"] == limit and meta["run_timeout_rule"] == "--run-timeout"
    assert str(meta["message"]).startswith(f"timed out: the run passed its time limit of {limit:g} s"), meta


def test_a_hanging_filter_times_out_in_this_process(
    plugins: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    specs = ["lbt_hostile[mode=sleep,where=update]", "lbt_hostile[mode=spin]", "odometry"]
    argv = ["run", "--filter", *specs, "--dataset", "tiny_line", "--run-timeout", "2", "--results", str(tmp_path)]
    assert main([*argv, "--no-progress"]) == 1
    assert "3 runs in" in capsys.readouterr().out
    metas = _metas(tmp_path)
    assert metas["odometry"]["status"] == "ok"
    for spec in specs[:2]:
        _timed_out(metas, spec, 2.0)


def test_a_hanging_filter_times_out_in_a_pool(plugins: Path, tmp_path: Path) -> None:
    specs = ["lbt_hostile[mode=sleep,where=reset]", "lbt_hostile[mode=spin,where=update]", "odometry"]
    argv = ["run", "--filter", *specs, "--dataset", "tiny_line", "--run-timeout", "2", "--jobs", "2"]
    assert main([*argv, "--results", str(tmp_path), "--no-progress"]) == 1
    metas = _metas(tmp_path)
    assert metas["odometry"]["status"] == "ok"
    for spec in specs[:2]:
        _timed_out(metas, spec, 2.0)


@pytest.mark.slow
def test_a_hanging_filter_times_out_on_dask(plugins: Path, tmp_path: Path) -> None:
    pytest.importorskip("distributed")
    specs = ["lbt_hostile[mode=sleep]", "odometry"]
    argv = ["run", "--filter", *specs, "--dataset", "tiny_line", "--run-timeout", "2", "--executor", "dask"]
    assert main([*argv, "--results", str(tmp_path), "--no-progress"]) == 1
    metas = _metas(tmp_path)
    assert metas["odometry"]["status"] == "ok"
    _timed_out(metas, specs[0], 2.0)


def test_the_default_limit_follows_the_dataset_and_is_recorded(plugins: Path, tmp_path: Path) -> None:
    assert run_time_limit(5.0, None) == 60.0 and run_time_limit(100.0, None) == 1000.0
    assert run_time_limit(100.0, 3.0) == 3.0 and run_time_limit(100.0, float("inf")) == float("inf")
    run_many(["odometry"], ["tiny_line"], [0], str(tmp_path))
    meta = _metas(tmp_path)["odometry"]
    limit = max(60.0, 10.0 * make_dataset("tiny_line", 0).duration)
    assert meta["run_timeout_s"] == limit and meta["run_timeout_rule"] == DEFAULT_RULE


@pytest.mark.parametrize(
    ("mode", "why"),
    [
        ("cov3", "estimate contract: covariance of shape (3,) at t="),
        ("cov2", "estimate contract: covariance of shape (2, 2) at t="),
        ("mean2", "estimate contract: mean of shape (2,) at t="),
        ("asym", "estimate contract: covariance not symmetric at t="),
        ("nonpsd", "estimate contract: covariance not positive semi-definite at t="),
        ("heading100", "estimate contract: heading 100 rad at t="),
    ],
)
def test_an_estimate_that_breaks_the_contract_fails_its_run(plugins: Path, tmp_path: Path, mode: str, why: str) -> None:
    [out] = run_many([f"lbt_hostile[mode={mode}]"], ["tiny_line"], [0], str(tmp_path))
    assert out.status == "error" and out.message.startswith(why), out.message
    assert "\n" not in out.message


def test_a_run_in_a_child_process_stores_the_same_arrays(tmp_path: Path) -> None:
    plan = plan_sweep([(["ekf_landmarks", "pf"], ["tiny_circle"], [0, 1])], str(tmp_path))
    for task in plan.tasks:
        direct, contained = execute_task(task), execute_contained(task)
        assert [r.meta["filter"] for r in direct.runs] == [r.meta["filter"] for r in contained.runs]
        for a, b in zip(direct.runs, contained.runs, strict=True):
            assert b.status == a.status == "ok"
            for name in ("t", "mean", "cov", "kind"):
                assert np.array_equal(getattr(a, name), getattr(b, name)), name


def _sleep_forever(marker: Path) -> None:
    marker.write_text(str(os.getpid()))
    while True:
        time.sleep(1)


def test_ctrl_c_while_a_child_runs_kills_it_and_is_not_dropped(tmp_path: Path) -> None:
    marker = tmp_path / "child.pid"

    def interrupt_once_started() -> None:
        while not marker.exists() or not marker.read_text():
            time.sleep(0.01)
        os.kill(os.getpid(), signal.SIGINT)

    threading.Thread(target=interrupt_once_started, daemon=True).start()
    with pytest.raises(KeyboardInterrupt):
        call_in_child(lambda: _sleep_forever(marker), float("inf"))
    with pytest.raises(ProcessLookupError):
        os.kill(int(marker.read_text()), 0)  # killed and reaped


def test_a_result_comes_back_and_an_escaped_exception_is_reported() -> None:
    ok = call_in_child(lambda: {"x": np.arange(3)}, 30.0)
    assert ok.ok and np.array_equal(ok.value["x"], np.arange(3))
    raised = call_in_child(lambda: json.loads("{"), 30.0)
    assert not raised.ok and raised.kind == "raised" and raised.message.startswith("JSONDecodeError:")


#: ``locbench run`` of the baseline on the tiny dataset: the command the option tests add to.
RUN_ODOMETRY = ["run", "--filter", "odometry", "--dataset", "tiny_line", "--no-progress"]


@pytest.mark.parametrize("value", ["-1", "nan", "soon"])
def test_a_malformed_run_timeout_is_refused_in_one_line(
    value: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exc:
        main([*RUN_ODOMETRY, "--run-timeout", value, "--results", str(tmp_path)])
    assert exc.value.code == 2
    assert "argument --run-timeout: expected seconds > 0, or 0/none for no limit" in capsys.readouterr().err


def test_run_timeout_0_removes_the_limit_and_says_so(tmp_path: Path) -> None:
    assert main([*RUN_ODOMETRY, "--run-timeout", "0", "--results", str(tmp_path)]) == 0
    meta = _metas(tmp_path)["odometry"]
    assert meta["run_timeout_s"] is None and meta["run_timeout_rule"] == "--run-timeout"
