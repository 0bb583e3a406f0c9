"""What produced a result: library versions, platform, the git commit of the source tree, and the machine (CPU,
load and the time of a reference workload, so that runtimes can be read in reference units)."""

from __future__ import annotations

import functools
import importlib.metadata
import os
import platform
import subprocess
from pathlib import Path
from typing import Any

import locbench

_LIBRARIES = ("numpy", "scipy", "numba", "pandas", "matplotlib", "filterpy", "gtsam", "tqdm")


@functools.cache
def versions() -> dict[str, str]:
    """Installed versions of locbench, Python and the libraries results can depend on."""
    out = {"locbench": locbench.__version__, "python": platform.python_version()}
    for lib in _LIBRARIES:
        try:
            out[lib] = importlib.metadata.version(lib)
        except importlib.metadata.PackageNotFoundError:
            out[lib] = "not installed"
    out["platform"] = f"{platform.system()}-{platform.machine()}"
    return out


@functools.cache
def git_state() -> dict[str, Any]:
    """``{"commit": sha or None, "dirty": bool}`` of the tree the package was imported from."""
    src = Path(locbench.__file__).resolve().parent
    try:
        sha = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=src, capture_output=True, text=True, timeout=10, check=True
        ).stdout.strip()
        dirty = bool(
            subprocess.run(
                ["git", "status", "--porcelain", "--untracked-files=no"],
                cwd=src,
                capture_output=True,
                text=True,
                timeout=10,
                check=True,
            ).stdout.strip()
        )
    except (OSError, subprocess.SubprocessError):
        return {"commit": None, "dirty": False}
    return {"commit": sha, "dirty": dirty}


@functools.cache
def _top_level_distributions() -> dict[str, list[str]]:
    return dict(importlib.metadata.packages_distributions())


@functools.cache
def distribution(cls: type) -> dict[str, str] | None:
    """``{"name": ..., "version": ...}`` of the installed distribution that provides ``cls``: a plugin's
    package (``locbench-iterated-ekf``), ``locbench`` for the built-in filters and datasets; None for code that no
    installed distribution provides (a script, a test module)."""
    names = _top_level_distributions().get(cls.__module__.partition(".")[0], [])
    if not names:
        return None
    name = sorted(names)[0]
    try:
        return {"name": name, "version": importlib.metadata.version(name)}
    except importlib.metadata.PackageNotFoundError:
        return None


def cpu_model() -> str:
    """The processor's model name (``/proc/cpuinfo``, else :func:`platform.processor`), or ``"unknown"``."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as fh:
            for line in fh:
                key, _, value = line.partition(":")
                # x86 says "model name"; some ARM kernels say "Processor" or "Hardware" (there "model name" is absent)
                if key.strip().lower() in ("model name", "processor name", "hardware", "cpu model") and value.strip():
                    return value.strip()
    except OSError:
        pass
    return platform.processor().strip() or "unknown"


def cpu_count() -> dict[str, int | None]:
    """``{"logical": os.cpu_count(), "affinity": CPUs this process may run on}`` (None where unknown)."""
    try:
        affinity: int | None = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # not on every platform (macOS, Windows)
        affinity = os.cpu_count()
    return {"logical": os.cpu_count(), "affinity": affinity}


def load_avg() -> list[float] | None:
    """The system's load averages over 1, 5 and 15 minutes (:func:`os.getloadavg`), or None where unavailable."""
    try:
        return [float(x) for x in os.getloadavg()]
    except (AttributeError, OSError):
        return None


_REFERENCE: dict[str, Any] = {}


def reference() -> dict[str, Any]:
    """This process's measurement of the reference workload (:mod:`locbench.run.reference_workload`), made once.

    ``reference_s`` (the median pass's wall time, s), ``reference_cpu_s`` (its thread CPU time, s),
    ``reference_runs_s`` (every timed pass, s) and ``reference_load_avg`` (the load averages when it was
    measured). A ``locbench run`` or ``locbench tune`` is one process, so this is once per sweep;
    :func:`locbench.run.sweep.run_sweep` measures before its workers start, and forked workers inherit it (a dask
    worker on another machine measures its own on its first run).
    """
    if not _REFERENCE:
        from locbench.run.reference_workload import measure

        load = load_avg()
        m = measure()
        _REFERENCE.update(reference_s=m.wall_s, reference_cpu_s=m.cpu_s, reference_runs_s=m.runs_s)
        _REFERENCE["reference_load_avg"] = load
    return dict(_REFERENCE)


def machine() -> dict[str, Any]:
    """The provenance of time of one run: the reference workload, CPU model, CPU counts and the load now.

    Keys ``reference_s``, ``reference_cpu_s``, ``reference_runs_s``, ``reference_load_avg`` (:func:`reference`),
    ``cpu_model``,
    ``cpu_count`` and ``load_avg`` (taken at each call: a run's meta is made as the run starts). None of it
    enters a run key, so adding it changed no stored run.
    """
    return reference() | {"cpu_model": _cpu_model(), "cpu_count": cpu_count(), "load_avg": load_avg()}


_cpu_model = functools.cache(cpu_model)
