"""Experiments, source reports and their claims: the modules of this package register them at import in
:mod:`locbench.experiments` (whose names this package re-exports for them), and hold the helpers claims share.

The report itself knows no dataset or filter by name. Filters are matched by id: the plain ``id`` when
it has runs, otherwise the first parameterised variant in sorted order, named in the measured text.

Waypoint statistics here follow the DESIGN protocol: RMSE_j = sqrt(mean_i e_ij^2) over the ok runs
(report 003 fig. 5) and the distance between waypoint j and the mean estimated position over runs
(report 003 table 1).
"""

from __future__ import annotations

import re
from functools import lru_cache

import numpy as np
import pandas as pd

from locbench.experiments import (
    VERDICTS,
    Claim,
    ClaimResult,
    Experiment,
    SectionFn,
    Source,
    Verdict,
    all_claims,
    claims_for,
    experiment_of,
    experiments,
    register,
    register_experiment,
    register_section,
    sections_for,
)
from locbench.metrics import mean_estimate_distance, waypoint_rmse
from locbench.significance import ALPHA, TestResult
from locbench.spec import Spec

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

_WP_RE = re.compile(r"^waypoint_(\d+)_(error_m|est_x_m|est_y_m|marked_x_m|marked_y_m)$")


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
    """The typed :class:`~locbench.spec.Spec` of a stored filter or dataset name, parsed once per name."""
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


def waypoint_stats(df: pd.DataFrame) -> pd.DataFrame:
    """Per filter and waypoint statistics over the ok runs of one dataset name.

    Parameters
    ----------
    df : DataFrame
        Tidy metrics rows (``dataset, filter, seed, metric, value``) of a single dataset name.

    Returns
    -------
    DataFrame
        Columns ``filter``, ``waypoint`` (int, from 1), ``rmse_m`` (RMSE_j), ``mean_distance_m``
        (distance between the marked point and the mean estimate; NaN when the CSV lacks the
        estimate columns) and ``runs`` (how many runs entered), sorted by filter then waypoint.
    """
    cols = ["filter", "waypoint", "rmse_m", "mean_distance_m", "runs"]
    parts = df["metric"].astype(str).str.extract(_WP_RE)
    sel = parts[0].notna()
    if not sel.any():
        return pd.DataFrame(columns=cols)
    wp = df.loc[sel, ["filter", "seed", "value"]].copy()
    wp["waypoint"] = parts.loc[sel, 0].astype(int)
    wp["quantity"] = parts.loc[sel, 1]
    # one table (filter, waypoint, seed) x quantity for every group at once: a pivot per group was most of the
    # report's table time; each group's block is then what its own pivot gave (first non-missing value, the
    # rows and columns with no value dropped), so the statistics come out bit for bit the same
    table = wp.groupby(["filter", "waypoint", "seed", "quantity"], sort=True)["value"].first().unstack("quantity")
    quantities = [str(c) for c in table.columns]
    values = table.to_numpy(dtype=np.float64)
    keys = [k[:2] for k in table.index.to_list()]  # (filter, waypoint) of each row
    rows = []
    start = 0
    while start < len(keys):
        stop = start
        while stop < len(keys) and keys[stop] == keys[start]:
            stop += 1
        fname, j = keys[start]
        block = values[start:stop]
        start = stop
        has_col = ~np.all(np.isnan(block), axis=0)
        block = block[:, has_col]
        block = block[~np.all(np.isnan(block), axis=1)]
        q = {c: block[:, k] for k, c in enumerate(c for c, h in zip(quantities, has_col, strict=True) if h)}
        if "error_m" not in q:
            continue
        rmse = float(waypoint_rmse(q["error_m"][:, None])[0])
        dist = float("nan")
        if {"est_x_m", "est_y_m", "marked_x_m", "marked_y_m"} <= q.keys():
            est = np.column_stack([q["est_x_m"], q["est_y_m"]])[:, None, :]
            marked = np.column_stack([q["marked_x_m"], q["marked_y_m"]])[:, None, :]
            dist = float(mean_estimate_distance(est, marked)[0])
        rows.append((str(fname), int(str(j)), rmse, dist, int(np.count_nonzero(~np.isnan(q["error_m"])))))
    return pd.DataFrame(rows, columns=cols)


def series(ws: pd.DataFrame, filter_name: str, column: str) -> np.ndarray:
    """One filter's statistic over waypoints 1..m, in waypoint order."""
    sub = ws[ws["filter"] == filter_name].sort_values("waypoint")
    return sub[column].to_numpy(dtype=np.float64)


def fmt_cm(values: np.ndarray | tuple[float, ...]) -> str:
    return " / ".join(f"{100.0 * v:.1f}" for v in values)
