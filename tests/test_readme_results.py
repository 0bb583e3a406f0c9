"""The README's result numbers agree with the committed summary: every ``<!-- gen:NAME -->`` block of README.md
is what tools/readme_results.py makes from results/summary/metrics.csv."""

from __future__ import annotations

import functools

import pandas as pd
import pytest
from tool_support import load_tool

tool = load_tool("readme_results")


@functools.cache
def generated() -> dict[str, str]:
    return dict(tool.blocks(pd.read_csv(tool.METRICS_CSV)))


def test_every_generated_block_of_the_readme_agrees_with_the_committed_summary() -> None:
    text = tool.README.read_text(encoding="utf-8")
    names = [m.group("name") for m in tool.BLOCK.finditer(text)]
    # the tables and the values that drifted before (global localization, suite default's run count) are blocks
    assert {"office-summary", "kidnap", "consistency", "recorded", "global-laser", "suite-default-runs"} <= set(names)
    assert tool.disagreements(text, generated()) == [], "run: python tools/readme_results.py --write"


def test_a_number_that_disagrees_is_found() -> None:
    text = tool.render(tool.README.read_text(encoding="utf-8"), generated())
    body = generated()["global-laser"]
    assert body in text and "median" in body
    edited = text.replace(body, body.replace("median ", "median 1"), 1)
    assert tool.disagreements(edited, generated()) == ["global-laser"]
    table = generated()["office-summary"]
    edited = text.replace(table, table.replace("| `ekf_landmarks` | ", "| `ekf_landmarks` | 9", 1))
    assert tool.disagreements(edited, generated()) == ["office-summary"]


def test_a_block_without_a_generator_is_an_error() -> None:
    with pytest.raises(KeyError, match="no generator for the block 'nope'"):
        tool.render("a <!-- gen:nope -->1<!-- /gen:nope --> b", generated())
