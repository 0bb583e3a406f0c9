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
