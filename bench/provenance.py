"""What produced a result: library versions, platform and the git commit of the source tree."""

from __future__ import annotations

import functools
import importlib.metadata
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
    package (``locbench-iekf``), ``locbench`` for the built-in filters and datasets; None for code that no
    installed distribution provides (a script, a test module)."""
    names = _top_level_distributions().get(cls.__module__.partition(".")[0], [])
    if not names:
        return None
    name = sorted(names)[0]
    try:
        return {"name": name, "version": importlib.metadata.version(name)}
    except importlib.metadata.PackageNotFoundError:
        return None
