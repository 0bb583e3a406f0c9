"""What of a filter's or dataset's config enters the run key: the runner's policy, declared by the configs.

A config field added after runs were stored may carry :data:`RUN_KEY_OMIT_IF_DEFAULT` as its dataclass field
metadata: while it holds its default (which must reproduce the earlier behaviour exactly), the run key leaves
it out, so adding the field does not invalidate the stored runs.

The run key also holds :func:`source_digest` of the filter's and the dataset builder's classes, so that an edit of
their code without a ``version`` bump reruns their runs instead of reusing them (docs/design.md, "Run keys").
"""

from __future__ import annotations

import ast
import dataclasses
import hashlib
import importlib.util
import os
import sys
from types import MappingProxyType
from typing import Any

from locbench.core.spec import params_to_dict, stable_hash

#: Field metadata of config fields added after runs were stored (module docstring).
RUN_KEY_OMIT_IF_DEFAULT: MappingProxyType[str, Any] = MappingProxyType({"run_key_omit_if_default": True})


def key_params(params: Any) -> dict[str, Any]:
    """A config as hashed into the run key: every field, less those marked omit-if-default at their default."""
    out = params_to_dict(params)
    for f in dataclasses.fields(params):
        if f.metadata.get("run_key_omit_if_default") and getattr(params, f.name) == f.default:
            out.pop(f.name, None)
    return out


# --- the source of the code that produced a run ---------------------------------------------------------------

#: Top-level packages whose modules always enter a source digest besides the class's own: locbench's (the shared
#: models, events and geometry a plugin imports from it are part of what produced its runs).
_ALWAYS_HASHED = ("locbench",)


def _module_file(name: str) -> str | None:
    """The file a module is loaded from (its ``.py``, or a compiled or sourceless file), or None (not a module,
    a namespace package, a built-in)."""
    mod = sys.modules.get(name)
    origin = getattr(getattr(mod, "__spec__", None), "origin", None) if mod is not None else None
    if origin is None and mod is None:
        try:
            spec = importlib.util.find_spec(name)
        except (ImportError, ValueError, AttributeError):
            return None
        origin = spec.origin if spec is not None else None
    return origin if origin is not None and os.path.isfile(origin) else None


def _imported_names(source: bytes, module: str, is_package: bool) -> set[str]:
    """Every module name an ``import`` statement anywhere in ``source`` may refer to (function-level ones
    included): ``import a.b`` gives ``a.b``; ``from a import b`` gives ``a`` and ``a.b`` (b may be a submodule)."""
    package = module if is_package else module.rpartition(".")[0]
    out: set[str] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            try:
                base = importlib.util.resolve_name("." * node.level + (node.module or ""), package)
            except (ImportError, ValueError):
                continue
            out.add(base)
            out.update(f"{base}.{a.name}" for a in node.names if a.name != "*")
    return out


#: Digests computed in this process, by class (a reloaded module's class is a new key).
_DIGESTS: dict[type, str] = {}
#: The module names a module's source imports, by (module name, sha256 of its source).
_IMPORTS: dict[tuple[str, str], set[str]] = {}


def source_digest(cls: type) -> str:
    """sha256 of the source of the code that defines ``cls``: the run key's guard against an edit made without
    a ``version`` bump.

    Hashed: the file of the module defining ``cls`` and of each module defining one of its base classes, and,
    transitively, of every module those import (at module level or inside a function) whose top-level package
    is the class's own or ``locbench``; each file's bytes with ``\\r\\n`` read as ``\\n`` (a checkout's line
    endings change nothing), keyed by module name. A compiled or sourceless module is hashed by its file's
    bytes. Not hashed: other packages (numpy, filterpy, gtsam: their versions are in a run's provenance), data
    files read at run time, and modules imported by name at run time (``importlib.import_module``). Any byte of a
    hashed file counts, comments included: an edit reruns the runs even when it changes no number.
    """
    if cls not in _DIGESTS:
        _DIGESTS[cls] = _digest(cls)
    return _DIGESTS[cls]


def _digest(cls: type) -> str:
    """:func:`source_digest` computed afresh."""
    top = cls.__module__.partition(".")[0]
    scope = {top, *_ALWAYS_HASHED}
    todo = [k.__module__ for k in cls.__mro__ if k.__module__.partition(".")[0] in scope]
    files: dict[str, str] = {}
    seen: set[str] = set()
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        path = _module_file(name)
        if path is None:
            continue
        with open(path, "rb") as fh:
            data = fh.read().replace(b"\r\n", b"\n")
        digest = files[name] = hashlib.sha256(data).hexdigest()
        if path.endswith(".py"):
            if (name, digest) not in _IMPORTS:  # parsing is the cost; classes share most modules
                _IMPORTS[(name, digest)] = _imported_names(data, name, os.path.basename(path) == "__init__.py")
            todo.extend(n for n in _IMPORTS[(name, digest)] if n.partition(".")[0] in scope and n not in seen)
    return stable_hash(files)
