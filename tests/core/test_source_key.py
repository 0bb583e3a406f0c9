"""The run key holds the source of the filter's and dataset builder's code: an edit without a version bump
reruns, never reuses (locbench.core.runkey.source_digest)."""

from __future__ import annotations

import importlib
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from locbench.core import runkey
from locbench.core.runkey import source_digest
from locbench.registry import FILTERS
from locbench.run.plan import parse_dataset, parse_filter, plan_sweep, run_key
from locbench.run.store import Store
from locbench.run.sweep import run_many

PKG = "srckey_plugin"

FILTER_SRC = '''"""A filter in a package of its own, as a plugin is."""

from locbench.filters.odometry import OdometryFilter


class EditedOdometry(OdometryFilter):
    version = 1

    def health(self):
        from srckey_plugin._helper import EXTRA  # a function-level import of a private helper

        return super().health() | EXTRA
'''


def _load() -> type:
    for name in [m for m in sys.modules if m == PKG or m.startswith(PKG + ".")]:
        del sys.modules[name]
    importlib.invalidate_caches()
    cls: type = importlib.import_module(f"{PKG}.flt").EditedOdometry
    return cls


@pytest.fixture
def plugin(tmp_path: Path, isolated_registries: None) -> Iterator[Path]:
    pkg = tmp_path / "src" / PKG
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "flt.py").write_text(FILTER_SRC)
    (pkg / "_helper.py").write_text("EXTRA = {}\n")
    sys.path.insert(0, str(pkg.parent))
    FILTERS.register("edited", f"{PKG}.flt:EditedOdometry")
    try:
        yield pkg
    finally:
        sys.path.remove(str(pkg.parent))
        for name in [m for m in sys.modules if m == PKG or m.startswith(PKG + ".")]:
            del sys.modules[name]


def test_an_edit_without_a_version_bump_reruns(plugin: Path, tmp_path: Path) -> None:
    results = str(tmp_path / "results")
    _load()
    assert [o.status for o in run_many(["edited"], ["tiny_line"], [0], results)] == ["ok"]
    assert [o.status for o in run_many(["edited"], ["tiny_line"], [0], results)] == ["cached"]
    key0 = Store(results).existing_meta("tiny_line", "edited", 0)["run_key"]  # type: ignore[index]

    (plugin / "flt.py").write_text(FILTER_SRC.replace("version = 1", "version = 1  # an edit, no bump"))
    _load()
    plan = plan_sweep([(["edited"], ["tiny_line"], [0])], results)
    assert not plan.cached and [j.filter.name for t in plan.tasks for j in t.jobs] == ["edited"]
    assert [o.status for o in run_many(["edited"], ["tiny_line"], [0], results)] == ["ok"]
    key1 = Store(results).existing_meta("tiny_line", "edited", 0)["run_key"]  # type: ignore[index]
    assert key1 != key0

    # a helper module it imports (inside a function) is part of its source too
    (plugin / "_helper.py").write_text("EXTRA = {}  # edited\n")
    _load()
    assert run_key(parse_filter("edited"), parse_dataset("tiny_line"), 0) != key1
    assert [o.status for o in run_many(["edited"], ["tiny_line"], [0], results)] == ["ok"]


def test_the_digest_reads_bytes_not_line_endings(plugin: Path) -> None:
    before = source_digest(_load())
    (plugin / "flt.py").write_bytes(FILTER_SRC.replace("\n", "\r\n").encode())
    assert source_digest(_load()) == before
    (plugin / "flt.py").write_text(FILTER_SRC + "\n")
    assert source_digest(_load()) != before


def test_the_digest_covers_the_class_module_its_bases_and_locbench_modules_only(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from locbench.filters.ekf_landmarks import LandmarkEKF

    seen: list[str] = []
    real = runkey._module_file

    def spy(name: str) -> str | None:
        seen.append(name)
        return real(name)

    monkeypatch.setattr(runkey, "_module_file", spy)
    runkey._digest(LandmarkEKF)
    assert {"locbench.filters.ekf_landmarks", "locbench.filters.base", "locbench.filters._motion"} <= set(seen)
    assert {"locbench.filters._kalman", "locbench.core.geometry"} <= set(seen)
    assert not any(n.split(".")[0] in ("numpy", "scipy") for n in seen)
    # the layers hold: a filter's source never reaches the run layer (the runner, the store) or the report
    assert not any(n.startswith(("locbench.run.", "locbench.report")) for n in seen)
