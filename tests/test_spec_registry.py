"""Spec parsing, typed parameters, seeding and the lazy registry."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pytest

from locbench.core.errors import ConfigError, DependencyNotInstalled, UnknownIdError
from locbench.core.seeding import dataset_rng, filter_rng
from locbench.core.spec import build_params, format_spec, parse_spec, stable_hash
from locbench.registry import DATASETS, FILTERS, DuplicateIdError, Registry, resolve_dataset, resolve_filter


@dataclass(frozen=True, kw_only=True)
class P:
    particles: int = 100
    sigma_m: float = 0.1
    known_ids: bool = True
    mode: Literal["a", "b"] = "a"
    cap_m: float | None = None


def test_parse_and_format_round_trip() -> None:
    ident, params = parse_spec("pf[particles=5000, sigma_m=0.2]")
    assert ident == "pf" and params == {"particles": "5000", "sigma_m": "0.2"}
    assert parse_spec("room") == ("room", {})
    assert format_spec("pf", {"sigma_m": 0.2, "particles": 5000}) == "pf[particles=5000,sigma_m=0.2]"


@pytest.mark.parametrize("bad", ["pf[", "pf[particles]", "pf[a=1,a=2]", "[x=1]", "p f"])
def test_malformed_specs_are_config_errors(bad: str) -> None:
    with pytest.raises(ConfigError):
        parse_spec(bad)


def test_build_params_converts_types() -> None:
    p = build_params(P, {"particles": "5", "sigma_m": "0.5", "known_ids": "false", "mode": "b", "cap_m": "none"}, "x")
    assert p == P(particles=5, sigma_m=0.5, known_ids=False, mode="b", cap_m=None)
    assert build_params(P, {"cap_m": "2"}, "x").cap_m == 2.0


@pytest.mark.parametrize(
    ("values", "match"),
    [
        ({"particles": "many"}, "expected an integer"),
        ({"sigma_m": "x"}, "expected a number"),
        ({"known_ids": "maybe"}, "expected a boolean"),
        ({"mode": "c"}, "not one of a, b"),
    ],
)
def test_bad_values_name_the_parameter(values: dict[str, str], match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        build_params(P, values, "x")


def test_unknown_key_lists_valid_keys() -> None:
    with pytest.raises(UnknownIdError, match="valid: cap_m, known_ids, mode, particles, sigma_m"):
        build_params(P, {"partcles": "5"}, "pf")


def test_stable_hash_is_stable() -> None:
    assert stable_hash({"b": 1, "a": [1, 2]}) == stable_hash({"a": [1, 2], "b": 1})
    assert stable_hash({"a": 1}) == "015abd7f5cc57a2dd94b7590f04ad8084273905ee33ec5cebeae62276a97f862"


def test_seeds_depend_only_on_names() -> None:
    a = dataset_rng("room", 3).normal(size=4)
    assert np.array_equal(a, dataset_rng("room", 3).normal(size=4))
    assert not np.array_equal(a, dataset_rng("room", 4).normal(size=4))
    assert not np.array_equal(a, dataset_rng("office", 3).normal(size=4))
    assert not np.array_equal(filter_rng("pf", "room", 3).normal(size=4), filter_rng("ekf", "room", 3).normal(size=4))


def test_unknown_ids_list_valid_ones() -> None:
    with pytest.raises(UnknownIdError, match=r"valid: .*ekf_landmarks.*odometry"):
        resolve_filter("nope")
    with pytest.raises(UnknownIdError, match=r"valid: .*office.*room"):
        resolve_dataset("nope[x=1]")


def test_missing_optional_dependency_is_unavailable(isolated_registries: None) -> None:
    FILTERS.register(
        "needs_x", "locbench.filters.base:Filter", requires_modules=("no_such_module_x",), install_hint="pip install x"
    )
    reason = FILTERS.unavailable_reason("needs_x")
    assert reason is not None and "pip install x" in reason
    with pytest.raises(DependencyNotInstalled, match="pip install x"):
        FILTERS.load("needs_x")


def test_registration_does_not_leak(isolated_registries: None) -> None:
    DATASETS.register("temp_only", "harness_support:LineBuilder")
    assert "temp_only" in DATASETS


def test_previous_registration_is_gone() -> None:
    assert "temp_only" not in DATASETS


def test_canonical_names_drop_defaults() -> None:
    assert resolve_dataset("room[kidnap_m=0]").name == "room"
    assert resolve_dataset("room[kidnap_m=2]").name == "room[kidnap_m=2]"


# --- registration at the definition: a package's modules are searched for classes that declare an id ------------

MODULES = {
    "__init__.py": "",
    "alpha.py": 'class Alpha:\n    id = "alpha"\n    order = 2\n    description = "the first"\n',
    # an id-less subclass does not inherit its base's id; a class imported from elsewhere is its module's
    "beta.py": (
        "from regpkg.alpha import Alpha\n\nclass Beta:\n    id = 'beta'\n    order = 1\n\n"
        "class Quiet(Alpha):\n    pass\n"
    ),
    "needs_lib.py": "import no_such_library_for_locbench\n",
    "_private.py": 'class Hidden:\n    id = "hidden"\n',
    "sub/__init__.py": "",
    "sub/gamma.py": 'class G1:\n    id = "g1"\n\nclass G2:\n    id = "g2"\n',
}


def _package(root: Path, modules: dict[str, str], monkeypatch: pytest.MonkeyPatch) -> Registry[Any]:
    """A package ``regpkg`` of ``modules`` on ``sys.path`` and a registry that searches it."""
    for name, text in modules.items():
        path = root / "regpkg" / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    monkeypatch.syspath_prepend(str(root))
    for name in [m for m in sys.modules if m == "regpkg" or m.startswith("regpkg.")]:
        monkeypatch.delitem(sys.modules, name)
    return Registry("thing", "locbench.test_no_such_group", "regpkg")


def test_a_package_registers_the_classes_that_declare_an_id(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    reg = _package(tmp_path, MODULES, monkeypatch)
    assert reg.ids() == ["alpha", "beta", "g1", "g2", "needs_lib"]
    assert reg.entry("g2").entry_point == "regpkg.sub.gamma:G2" and reg.entry("g2").declared
    assert reg.summary("alpha") == "the first"
    # by declared order, then id; the module that does not import here last
    assert reg.package_ids() == ["g1", "g2", "beta", "alpha", "needs_lib"]
    reason = reg.unavailable_reason("needs_lib")
    assert reason is not None and "no_such_library_for_locbench" in reason and "install" in reason
    assert reg.class_of("needs_lib") is None
    with pytest.raises(DependencyNotInstalled, match="no_such_library_for_locbench"):
        reg.load("needs_lib")


def test_a_lookup_by_id_searches_the_module_named_after_it_first(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    reg = _package(tmp_path, MODULES, monkeypatch)
    assert reg.load("alpha").__name__ == "Alpha"
    assert "regpkg.alpha" in sys.modules and "regpkg.beta" not in sys.modules
    assert reg.load("g1").__name__ == "G1"  # no module of that name: every module is searched
    assert "regpkg.beta" in sys.modules


def test_one_id_declared_twice_is_an_error_naming_both(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    reg = _package(tmp_path, {**MODULES, "zeta.py": 'class Other:\n    id = "alpha"\n'}, monkeypatch)
    with pytest.raises(
        DuplicateIdError, match=r"'alpha' is declared twice: by regpkg.alpha:Alpha and regpkg.zeta:Other"
    ):
        reg.ids()


def test_a_broken_module_of_the_package_is_a_bug_not_a_missing_dependency(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    reg = _package(tmp_path, {**MODULES, "broken.py": "from regpkg import no_such_module\n"}, monkeypatch)
    with pytest.raises(ImportError, match="no_such_module"):
        reg.ids()
    reg = _package(tmp_path, {**MODULES, "broken.py": "raise RuntimeError('boom')\n"}, monkeypatch)
    with pytest.raises(RuntimeError, match="boom"):
        reg.ids()


def test_a_registration_by_hand_wins_over_a_declared_class(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    reg = _package(tmp_path, MODULES, monkeypatch)
    reg.register("beta", "regpkg.alpha:Alpha", "by hand")
    assert reg.summary("beta") == "by hand" and reg.load("beta").__name__ == "Alpha"
    assert "beta" in reg.package_ids()  # a declared id replaced by hand is still the package's
    reg.unregister("alpha")
    assert "alpha" not in reg.ids() and "alpha" not in reg.package_ids()


def test_the_packages_own_filters_and_datasets_are_declared_by_their_classes() -> None:
    for reg in (FILTERS, DATASETS):
        for ident in reg.package_ids():
            e = reg.entry(ident)
            assert e.declared and not e.plugin
            cls = reg.class_of(ident)
            if cls is not None:
                assert vars(cls)["id"] == ident and e.entry_point == f"{cls.__module__}:{cls.__qualname__}"
    assert FILTERS.entry("pf").entry_point == "locbench.filters.pf:ParticleFilter"
    assert DATASETS.entry("tiny_circle").entry_point == "locbench.datasets.synthetic.scenarios:TinyCircleScenario"
