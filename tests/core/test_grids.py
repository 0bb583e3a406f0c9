"""Parameter grids in specs and suite files, the pareto suite, and a suite's (filter, dataset) pairs."""

from __future__ import annotations

from pathlib import Path

import pytest

from locbench.core.errors import ConfigError
from locbench.core.spec import Spec, expand_grid
from locbench.suites import KIDNAP_FILTERS, SUITES, Block, load_suite_file, suite_pairs


def test_grid_expands_to_the_cross_product() -> None:
    assert expand_grid("pf[particles=100|300|1000,augmented=true]") == [
        "pf[augmented=true,particles=100]",
        "pf[augmented=true,particles=300]",
        "pf[augmented=true,particles=1000]",
    ]
    specs = expand_grid("pf[particles=1|2,augmented=true|false]")
    assert specs == [
        "pf[augmented=true,particles=1]",
        "pf[augmented=false,particles=1]",
        "pf[augmented=true,particles=2]",
        "pf[augmented=false,particles=2]",
    ]
    assert expand_grid("room") == ["room"] and expand_grid("room[kidnap_m=2]") == ["room[kidnap_m=2]"]


@pytest.mark.parametrize("bad", ["pf[particles=1||3]", "pf[particles=1|1]", "pf[particles=|3]"])
def test_bad_grids_are_one_line_errors(bad: str) -> None:
    with pytest.raises(ConfigError, match="distinct non-empty values"):
        expand_grid(bad)


def test_blocks_and_suite_files_take_grids(tmp_path: Path) -> None:
    b = Block(("odometry", "gtsam_fls[lag_s=0.5|1|2|4]"), ("room[kidnap_m=1|2]",), 3)
    assert len(b.filters) == 5 and len(b.datasets) == 2 and b.runs == 30
    f = tmp_path / "grid.toml"
    f.write_text('filters = ["pf[particles=100|300]"]\ndatasets = ["room", "office"]\nseeds = 2\n')
    suite = load_suite_file(f)
    assert suite.blocks[0].filters == ("pf[particles=100]", "pf[particles=300]") and suite.runs == 8


def test_pareto_sweeps_each_filters_cost_knob_on_office() -> None:
    pytest.importorskip("gtsam", reason="the suite names gtsam_fls")
    pairs = suite_pairs("pareto")
    assert {d for _, d in pairs} == {Spec("office")}
    knobs: dict[str, set[str]] = {}
    for f, _ in pairs:
        knobs.setdefault(f.ident, set()).update(k for k, _ in f.params)
    assert knobs["pf"] == {"particles"} and knobs["gtsam_fls"] == {"lag_s"}
    assert knobs["ekf_icp"] == {"max_iterations"} and "gate_probability" in knobs["ekf_landmarks"]
    assert Spec("pf") in {f for f, _ in pairs}  # particles=1000 is pf's default: stored as plain "pf"
    assert SUITES["pareto"].runs <= 100


def test_suite_pairs_are_canonical_and_unique() -> None:
    pytest.importorskip("gtsam", reason="the suite names gtsam_fls")
    pairs = suite_pairs("kidnap")
    assert (Spec.parse("pf[augmented=true]"), Spec.parse("room[kidnap_m=0.5]")) in pairs
    assert len(pairs) == len(set(pairs)) == len(KIDNAP_FILTERS) * 8
