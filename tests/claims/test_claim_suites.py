"""Every claim reads runs that a suite makes: its experiment names the suite object, and the suite runs the datasets
and filters the claim's check needs (evaluated on a frame of exactly that suite's runs, it is evaluated)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest

from locbench import claims
from locbench.suites import SUITES, Block, Suite, suite_pairs

#: Waypoints of the synthetic rows (report 003's room has 5; the only claims that read waypoints are its own).
WAYPOINTS = 5
#: The suites ``nox -s bench`` runs into results/summary beside 'tuned', whose runs the report's claims read.
BENCH_SUITES = ("all", "consistency")


def _rows_of(suite: Suite, seed: int = 0) -> pd.DataFrame:
    """Tidy metrics rows (random values) for every (filter, dataset, seed) the suite runs, and nothing else."""
    rng = np.random.default_rng(seed)
    seeds = max(b.seeds for b in suite.blocks)
    rows = []
    for f, d in suite_pairs(suite.name):
        for s in range(seeds):
            values = {
                "failed": 0.0,
                "ate_m": rng.uniform(0.01, 1.0),
                "final_error_m": rng.uniform(0.01, 1.0),
                "heading_rmse_rad": rng.uniform(0.0, 0.3),
                "anees": rng.uniform(1.0, 5.0),
                "accepted_fraction": rng.uniform(0.0, 1.0),
                "kidnap_recovered": float(rng.integers(0, 2)),
            }
            for j in range(1, WAYPOINTS + 1):
                values[f"waypoint_{j}_error_m"] = rng.uniform(0.01, 1.0)
                for q in ("est_x_m", "est_y_m", "marked_x_m", "marked_y_m"):
                    values[f"waypoint_{j}_{q}"] = rng.uniform(0.0, 5.0)
            rows += [(str(d), str(f), s, k, v) for k, v in values.items()]
    return pd.DataFrame(rows, columns=["dataset", "filter", "seed", "metric", "value"])


def _claim_rows(claim: claims.Claim, df: pd.DataFrame) -> pd.DataFrame:
    """The rows the report hands the claim: its plain dataset name, or every variant of its id."""
    if claim.across_variants:
        return df[[claims.spec_id(str(d)) == claim.dataset for d in df["dataset"]]]
    return df[df["dataset"] == claim.dataset]


def _verdict(claim: claims.Claim, suite: Suite) -> claims.ClaimResult:
    return claim.evaluate(_claim_rows(claim, _rows_of(suite)))


def test_every_experiment_names_a_registered_suite_that_runs_its_dataset() -> None:
    exps = claims.experiments()
    assert exps
    for e in exps:
        assert SUITES.get(e.suite.name) is e.suite, e.dataset
        assert any(claims.spec_id(str(d)) == e.dataset for _, d in suite_pairs(e.suite.name)), e.dataset


@pytest.mark.parametrize("claim", claims.all_claims(), ids=lambda c: c.id)
def test_every_claim_is_evaluated_on_the_runs_of_its_suite(claim: claims.Claim) -> None:
    suite = claims.claim_suite(claim)
    assert SUITES.get(suite.name) is suite
    res = _verdict(claim, suite)
    assert res.verdict != "not evaluated", f"{claim.id} on suite {suite.name!r}: {res.measured}"


@pytest.mark.parametrize("claim", claims.all_claims(), ids=lambda c: c.id)
def test_every_claim_suite_is_inside_what_the_benchmark_runs(claim: claims.Claim) -> None:
    suite = claims.claim_suite(claim)
    ran = {p for name in BENCH_SUITES for p in suite_pairs(name)}
    missing = [f"{f} on {d}" for f, d in suite_pairs(suite.name) if (f, d) not in ran]
    assert not missing, f"{claim.id}: suite {suite.name!r} runs cells results/summary lacks: {missing[:5]}"


def test_a_claim_on_a_suite_without_its_filters_is_not_evaluated() -> None:
    claim = next(c for c in claims.all_claims() if c.id == "room_pf_le_ekf")
    no_pf = Suite("odometry_only", (Block(("odometry", "ekf_landmarks"), ("room",), 5),))
    SUITES[no_pf.name] = no_pf  # suite_pairs reads suites by name
    try:
        assert _verdict(claim, no_pf).verdict == "not evaluated"
    finally:
        del SUITES[no_pf.name]


def test_an_experiment_whose_suite_does_not_run_its_dataset_is_refused() -> None:
    exp = claims.experiment_of("room")
    assert exp is not None
    with pytest.raises(ValueError, match="runs no room dataset"):
        dataclasses.replace(exp, suite=SUITES["scan_grid"])
