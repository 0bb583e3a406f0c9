"""The modules of ``locbench.datasets.recorded``: a loader (a module that defines a dataset builder) imports no other
loader, counting imports inside functions; what two loaders share sits in a shared module."""

from __future__ import annotations

import ast
import importlib
import importlib.util
import inspect
import pkgutil
from pathlib import Path

import locbench.datasets.recorded as recorded
from locbench.datasets.dataset import DatasetBuilder

PACKAGE = recorded.__name__


def _module_names() -> list[str]:
    return sorted(m.name for m in pkgutil.iter_modules(recorded.__path__))


def _is_loader(name: str) -> bool:
    mod = importlib.import_module(f"{PACKAGE}.{name}")
    return any(
        isinstance(v, type)
        and issubclass(v, DatasetBuilder)
        and v.__module__ == mod.__name__
        and not inspect.isabstract(v)
        for v in vars(mod).values()
    )


def _recorded_imports(name: str) -> set[str]:
    """The sibling modules ``name`` imports anywhere in its source (function-level imports included)."""
    source = Path(recorded.__path__[0], f"{name}.py").read_text(encoding="utf-8")
    siblings = set(_module_names())
    out: set[str] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = importlib.util.resolve_name("." * node.level + (node.module or ""), PACKAGE)
            targets = [base, *(f"{base}.{a.name}" for a in node.names)]
        else:
            continue
        for t in targets:
            head, _, tail = t.partition(f"{PACKAGE}.")
            if not head and tail.split(".")[0] in siblings:
                out.add(tail.split(".")[0])
    return out


def test_no_loader_imports_another_loader() -> None:
    names = _module_names()
    loaders = {n for n in names if _is_loader(n)}
    # the rule must bite: the loaders and the shared modules are both there
    assert {"intel", "radish", "plaza", "librsf", "rosbag", "textlog"} <= loaders
    assert {"scan_map", "reference", "ros_map", "jsonl_events", "text_tables", "common"}.isdisjoint(loaders)
    found = {n: sorted(_recorded_imports(n) & (loaders - {n})) for n in sorted(loaders)}
    assert all(not v for v in found.values()), {n: v for n, v in found.items() if v}


def test_the_import_scan_sees_function_level_imports() -> None:
    # ros_map imports the line extraction inside a function; the scan must report it
    assert "scan_map" in _recorded_imports("ros_map")
    assert {"jsonl_events", "text_tables", "ros_map"} <= _recorded_imports("rosbag")
