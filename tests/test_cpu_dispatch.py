"""The CPU dispatch that ``nox -s tests_dispatch`` asks for is the one numpy and OpenBLAS run.

numpy ignores a name in ``NPY_DISABLE_CPU_FEATURES`` that it does not know, and OpenBLAS maps some names of
``OPENBLAS_CORETYPE`` to other kernels, so without these checks the session could pass on the default dispatch and
prove nothing. Each check skips when its variable is not set (the plain test session).
"""

from __future__ import annotations

import ctypes
import os
from pathlib import Path

import numpy as np
import pytest
from numpy._core import _multiarray_umath  # type: ignore[attr-defined]  # numpy ships no stub for it

#: The exported names of OpenBLAS's core-name query: plain OpenBLAS, and the prefixed builds of numpy and scipy wheels.
_CORENAME_SYMBOLS = ("openblas_get_corename", "scipy_openblas_get_corename64_", "scipy_openblas_get_corename")


def _openblas_cores() -> dict[str, str]:
    """The kernel set (core name) of each OpenBLAS library loaded in this process, by file name."""
    maps = Path("/proc/self/maps")
    if not maps.exists():
        pytest.skip("no /proc/self/maps: the loaded OpenBLAS cannot be found on this system")
    paths = sorted({line.split()[-1] for line in maps.read_text().splitlines() if "openblas" in line.lower()})
    cores = {}
    for path in paths:
        lib = ctypes.CDLL(path)
        for name in _CORENAME_SYMBOLS:
            fn = getattr(lib, name, None)
            if fn is not None:
                fn.restype = ctypes.c_char_p
                cores[Path(path).name] = fn().decode()
                break
    return cores


def test_numpy_runs_without_the_disabled_features() -> None:
    names = os.environ.get("NPY_DISABLE_CPU_FEATURES", "").replace(",", " ").split()
    if not names:
        pytest.skip("NPY_DISABLE_CPU_FEATURES is not set: numpy's default dispatch")
    features = _multiarray_umath.__cpu_features__
    unknown = sorted(set(names) - set(features))
    assert not unknown, f"numpy {np.__version__} ignores unknown CPU features {unknown}; it knows {sorted(features)}"
    still_on = [n for n in names if features[n]]
    assert not still_on, f"NPY_DISABLE_CPU_FEATURES did not take effect: {still_on} still on"
    print("numpy CPU features on:", sorted(n for n, on in features.items() if on))


def test_openblas_runs_the_requested_kernels() -> None:
    want = os.environ.get("OPENBLAS_CORETYPE", "")
    if not want:
        pytest.skip("OPENBLAS_CORETYPE is not set: OpenBLAS's default kernels")
    import scipy.linalg  # noqa: F401  (scipy's own OpenBLAS, loaded beside numpy's)

    cores = _openblas_cores()
    assert cores, "no OpenBLAS library with a core-name query is loaded"
    wrong = {lib: core for lib, core in cores.items() if core.lower() != want.lower()}
    assert not wrong, f"OPENBLAS_CORETYPE={want} did not take effect (or names another core): {wrong}"
    print("OpenBLAS cores:", cores)
