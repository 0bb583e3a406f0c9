"""docs/design.md's layer line ("Architecture") is the import-linter layers contract of pyproject.toml."""

from __future__ import annotations

import importlib.util
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "design.md"

Layers = list[list[str]]


def contract() -> dict:
    """The import-linter contract of type "layers" in pyproject.toml."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    (layers,) = [c for c in config["tool"]["importlinter"]["contracts"] if c["type"] == "layers"]
    return layers


def contract_layers(layers: dict) -> Layers:
    """The contract's layers, lowest first (import-linter lists the highest first), each as its packages."""
    return [[p.strip().removeprefix("locbench.") for p in entry.split("|")] for entry in reversed(layers["layers"])]


def chain(line: str, joiner: str) -> Layers:
    """``a < b | c < d`` (``joiner`` "|"; "," in the contract's name) as [[a], [b, c], [d]]."""
    return [[p.strip() for p in step.split(joiner)] for step in line.strip().split(" < ")]


def page_line(text: str) -> str:
    """The one line of the first code block of the page's "Architecture" section."""
    section = text.split("\n## Architecture\n", 1)[1].split("\n## ", 1)[0]
    block = section.split("```\n", 2)[1]
    (line,) = [ln for ln in block.splitlines() if ln.strip()]
    return line


def test_the_page_states_the_contract_s_layers() -> None:
    layers = contract()
    page = chain(page_line(PAGE.read_text(encoding="utf-8")), "|")
    assert page == contract_layers(layers), "docs/design.md 'Architecture' and pyproject.toml's contract disagree"
    assert chain(layers["name"].removeprefix("the layers: "), ",") == page, "the contract's name states other layers"
    assert page[0] == ["core"] and page[-1] == ["cli"]


@pytest.mark.parametrize("name", [n for step in contract_layers(contract()) for n in step])
def test_every_layer_is_a_module_of_the_package(name: str) -> None:
    assert importlib.util.find_spec(f"locbench.{name}") is not None


def test_a_page_that_swaps_two_layers_disagrees() -> None:
    text = PAGE.read_text(encoding="utf-8")
    line = page_line(text)
    swapped = text.replace(line, line.replace("evaluate < suites", "suites < evaluate"), 1)
    assert swapped != text
    assert chain(page_line(swapped), "|") != contract_layers(contract())
