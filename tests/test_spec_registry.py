"""Spec parsing, typed parameters, seeding and the lazy registry."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import pytest

from locbench.core.errors import ConfigError, DependencyNotInstalled, UnknownIdError
from locbench.core.seeding import dataset_rng, filter_rng
from locbench.core.spec import build_params, format_spec, parse_spec, stable_hash
from locbench.registry import DATASETS, FILTERS, resolve_dataset, resolve_filter


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
