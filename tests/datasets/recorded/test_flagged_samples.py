"""Samples a loader flagged reach the run's provenance, the truth record and the report."""

from __future__ import annotations

from pathlib import Path

import pytest

from locbench.registry import DATASETS
from locbench.report.site import site_markdown
from locbench.run.store import Store
from locbench.run.sweep import run_many


@pytest.fixture
def glitchy(harness_registry: None) -> None:
    DATASETS.register("glitchy", "harness_support:GlitchyLineBuilder")


@pytest.mark.usefixtures("glitchy")
def test_flagged_samples_are_counted_in_the_run_and_shown_in_the_report(tmp_path: Path) -> None:
    from locbench.cli import main

    results = tmp_path / "results"
    assert [o.status for o in run_many(["odometry"], ["glitchy", "line"], [0], str(results))] == ["ok", "ok"]
    store = Store(results)
    metas = {store.read_run(r).meta["dataset"]: store.read_run(r).meta for r in store.iter_runs()}
    assert metas["glitchy"]["flagged_samples"] == 1 and metas["glitchy"]["flagged_t"] == [2.5]
    assert "flagged_samples" not in metas["line"]  # a clean recording's provenance is as before
    flagged = store.read_truth("glitchy", 0).meta["flagged"]
    assert flagged == [
        {
            "source": "line.dat",
            "line": 7,
            "t": 2.5,
            "stream": "ground-truth",
            "quantity": "apparent speed, m/s",
            "value": 4.4,
            "bound": "at most 1 m/s",
        }
    ]
    assert main(["report", "--results", str(results)]) == 0
    text = site_markdown(store.summary)
    assert "| `glitchy` | ground-truth | apparent speed, m/s | 1 | 2.500 | at most 1 m/s |" in text
    assert "| `line` | ground-truth" not in text
