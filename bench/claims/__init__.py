"""Experiments, source reports and their claims: the modules of this package register them at import in
:mod:`locbench.present.experiments` (whose names this package re-exports for them), and hold the helpers claims share.

The report itself knows no dataset or filter by name. Filters are matched by id: the plain ``id`` when
it has runs, otherwise the first parameterised variant in sorted order, named in the measured text.

Waypoint statistics here follow the DESIGN protocol: RMSE_j = sqrt(mean_i e_ij^2) over the ok runs
(report 003 fig. 5) and the distance between waypoint j and the mean estimated position over runs
(report 003 table 1).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pandas as pd

from locbench.core.spec import Spec
from locbench.evaluate.aggregate import waypoint_stats
from locbench.evaluate.significance import ALPHA, TestResult
from locbench.present.experiments import (
    VERDICTS,
    Claim,
    ClaimResult,
    Experiment,
    SectionFn,
    Source,
    Verdict,
    all_claims,
    claim_suite,
    claims_for,
    experiment_of,
    experiments,
    register,
    register_experiment,
    register_section,
    sections_for,
)

__all__ = [
    "VERDICTS",
    "Claim",
    "ClaimResult",
    "Experiment",
    "SectionFn",
    "Source",
    "Verdict",
    "all_claims",
    "all_found",
    "claim_suite",
    "claims_for",
    "experiment_of",
    "experiments",
    "fmt_cm",
    "found",
    "no_worse",
    "paired",
    "per_seed_mean",
    "pick_filter",
    "register",
    "register_experiment",
    "register_section",
    "sections_for",
    "series",
    "spec_id",
    "spec_of",
    "test_text",
    "waypoint_stats",
]

# --- the rule for claims that compare two filters or settings (docs/protocols.md "Claims") ---------------


def no_worse(test: TestResult) -> Verdict:
    """ "A is no worse than B": reproduced when the one-sided test does not find B better at 5 %."""
    if not test.tested:
        return "not evaluated"
    return "reproduced" if not test.p < ALPHA else "not reproduced"


def found(test: TestResult) -> Verdict:
    """ "A differs from (is better than) B": reproduced only when the test finds it at 5 %."""
    if not test.tested:
        return "not evaluated"
    return "reproduced" if test.p < ALPHA else "not reproduced"


def all_found(tests: list[TestResult]) -> Verdict:
    """Several differences claimed together: each must be found at 5 % (an intersection-union test, which
    needs no correction for the number of parts)."""
    if not tests or not all(t.tested for t in tests):
        return "not evaluated"
    return "reproduced" if all(t.p < ALPHA for t in tests) else "not reproduced"


def test_text(*tests: TestResult) -> str:
    """The tests behind a verdict as the claims table prints them."""
    return "; ".join(t.text() for t in tests)


def paired(df: pd.DataFrame, filter_a: str, filter_b: str, metric: str) -> tuple[np.ndarray, np.ndarray]:
    """The values of one metric of two filters on the seeds both have, in seed order (paired by construction)."""
    sel = df[df["metric"] == metric]
    a = sel[sel["filter"] == filter_a].groupby("seed")["value"].first()
    b = sel[sel["filter"] == filter_b].groupby("seed")["value"].first()
    seeds = a.index.intersection(b.index).sort_values()
    return a.loc[seeds].to_numpy(dtype=np.float64), b.loc[seeds].to_numpy(dtype=np.float64)


def per_seed_mean(df: pd.DataFrame, filter_name: str, pattern: str) -> pd.Series:
    """seed -> the mean of a filter's metrics whose id matches ``pattern`` (a run's mean waypoint error)."""
    sel = df[(df["filter"] == filter_name) & df["metric"].astype(str).str.match(pattern)]
    return sel.groupby("seed")["value"].mean()


# --- tidy-frame helpers -------------------------------------------------------------------------


@lru_cache(maxsize=4096)
def spec_of(name: str) -> Spec:
    """The typed :class:`~locbench.core.spec.Spec` of a stored filter or dataset name, parsed once per name."""
    return Spec.parse(name)


def spec_id(name: str) -> str:
    """The id of a filter or dataset name (``pf[particles=10]`` -> ``pf``)."""
    return spec_of(name).ident


def pick_filter(df: pd.DataFrame, filter_id: str) -> str | None:
    """The filter name in ``df`` to use for an id: the plain id if present, else the first variant sorted."""
    names = sorted({str(f) for f in df["filter"].unique() if spec_id(str(f)) == filter_id})
    if not names:
        return None
    return filter_id if filter_id in names else names[0]


def series(ws: pd.DataFrame, filter_name: str, column: str) -> np.ndarray:
    """One filter's statistic over waypoints 1..m, in waypoint order."""
    sub = ws[ws["filter"] == filter_name].sort_values("waypoint")
    return sub[column].to_numpy(dtype=np.float64)


def fmt_cm(values: np.ndarray | tuple[float, ...]) -> str:
    return " / ".join(f"{100.0 * v:.1f}" for v in values)
