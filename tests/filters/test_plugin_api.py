"""The plugin path's API: one module of public types, public motion and noise models, what a filter class
declares (description, units, requirements), and the distribution recorded in provenance."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import dataclass, field
from typing import ClassVar

import pytest

import locbench.filters._motion as private_motion
import locbench.filters._noise as private_noise
from locbench.core.errors import DependencyNotInstalled
from locbench.core.spec import describe_params
from locbench.core.tunable import field_unit, tunable, tunable_fields
from locbench.filters import api, motion, noise
from locbench.filters.odometry import OdometryFilter
from locbench.registry import FILTERS
from locbench.run import provenance


def test_every_public_name_resolves_and_is_public() -> None:
    for mod in (api, motion, noise):
        assert mod.__all__ and len(set(mod.__all__)) == len(mod.__all__)
        for name in mod.__all__:
            assert not name.startswith("_") and hasattr(mod, name), (mod.__name__, name)
    assert motion.MotionModel is private_motion.MotionModel and noise.process_noise is private_noise.process_noise
    assert api.Filter.__module__ == "locbench.filters.base" and api.motion is motion


def test_the_api_imports_no_estimator_and_no_heavy_dependency() -> None:
    code = (
        "import sys, locbench.filters.api; "
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('numba', 'scipy', 'pandas', 'matplotlib') "
        "or m.startswith(('locbench.filters.pf', 'locbench.filters.ekf', 'locbench.run.', 'locbench.registry'))))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


@dataclass(frozen=True, kw_only=True)
class _Units:
    """Fields whose unit the name says, or does not.

    Attributes
    ----------
    sigma_xy_per_m : float
        A name that is a unit suffix alone.
    drift_per_m : float
        A rate per metre.
    k : float
        Declared.
    gain : float
        Declared beside a tuning range.
    """

    sigma_xy_per_m: float = 0.1
    drift_per_m: float = 0.1
    k: float = field(default=1.0, metadata=field_unit("sqrt(m)"))
    gain: float = field(default=1.0, metadata=tunable(0.1, 10.0, log=True, unit="m/s^2"))


def test_a_declared_unit_wins_and_a_bare_suffix_name_reads_as_its_suffix() -> None:
    units = {p.name: p.unit for p in describe_params(_Units)}
    assert units == {"sigma_xy_per_m": "m/sqrt(m)", "drift_per_m": "1/m", "k": "sqrt(m)", "gain": "m/s^2"}
    assert list(tunable_fields(_Units)) == ["gain"]
    assert field_unit("") == {}


class _Described(OdometryFilter):
    description: ClassVar[str] = "dead reckoning, declared on the class"


class _NeedsModule(OdometryFilter):
    requires_modules: ClassVar[tuple[str, ...]] = ("no_such_module_for_locbench",)
    install_hint: ClassVar[str] = "pip install the-missing-one"


def test_a_class_declares_its_summary_and_its_requirements(isolated_registries: None) -> None:
    FILTERS.register("described", f"{__name__}:_Described")
    FILTERS.register("needs_module", f"{__name__}:_NeedsModule")
    FILTERS.register("registered", f"{__name__}:_Described", "the registration's own line")
    assert FILTERS.summary("described") == "dead reckoning, declared on the class"
    assert FILTERS.summary("registered") == "the registration's own line"
    reason = FILTERS.unavailable_reason("needs_module")
    assert reason is not None and "no_such_module_for_locbench" in reason and "pip install the-missing-one" in reason
    with pytest.raises(DependencyNotInstalled, match="pip install the-missing-one"):
        FILTERS.load("needs_module")
    assert FILTERS.unavailable_reason("described") is None


def test_provenance_names_the_distribution_of_a_class() -> None:
    assert provenance.distribution(OdometryFilter) == {"name": "locbench", "version": provenance.versions()["locbench"]}
    assert provenance.distribution(_Units) is None  # a test module: no installed distribution provides it
