"""The example plugin package (examples/locbench-iterated-ekf-plugin): registered through its entry point, conformant,
runnable, and recorded with its distribution. ``nox -s tests`` installs it; plain pytest skips without it."""

from __future__ import annotations

import importlib.metadata
from pathlib import Path

import pytest

from locbench.cli import main
from locbench.core.spec import describe_params
from locbench.registry import FILTERS
from locbench.run.store import Store
from locbench.run.sweep import run_many

DIST = "locbench-iterated-ekf"

try:
    VERSION = importlib.metadata.version(DIST)
except importlib.metadata.PackageNotFoundError:
    pytestmark = pytest.mark.skip(
        reason=f"{DIST} is not installed: pip install --no-deps ./examples/locbench-iterated-ekf-plugin"
    )
    VERSION = ""


def test_it_is_registered_through_its_entry_point() -> None:
    assert "iterated_ekf" in FILTERS.ids()
    e = FILTERS.entry("iterated_ekf")
    assert (e.entry_point, e.distribution, e.distribution_version) == (
        "locbench_iterated_ekf.iterated_ekf:IteratedLandmarkEKF",
        DIST,
        VERSION,
    )
    cls = FILTERS.load("iterated_ekf")
    assert FILTERS.summary("iterated_ekf") == cls.description != ""
    units = {p.name: p.unit for p in describe_params(cls.Config)}
    assert units["sigma_xy_per_m"] == "m/sqrt(m)" and units["step_tolerance"] == "m or rad"


def test_it_passes_locbench_check(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", "iterated_ekf"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) > 5 and all(ln.startswith("ok ") for ln in lines[:-1]), lines
    assert lines[-1].startswith("all ") and "checks passed" in lines[-1]


def test_it_runs_on_room_and_its_distribution_is_recorded(tmp_path: Path) -> None:
    out = run_many(["iterated_ekf", "iterated_ekf[max_iterations=1]"], ["room"], [0], str(tmp_path))
    assert [o.status for o in out] == ["ok", "ok"]
    store = Store(tmp_path)
    metas = [store.read_run(d).meta for d in store.iter_runs()]
    assert {m["filter"] for m in metas} == {"iterated_ekf", "iterated_ekf[max_iterations=1]"}
    for m in metas:
        assert m["filter_distribution"] == {"name": DIST, "version": VERSION}
        assert m["dataset_distribution"]["name"] == "locbench"
