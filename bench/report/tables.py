"""Tables from the tidy metrics: pure functions from a metrics frame to :class:`~locbench.report.doc.Table`.

Headers, units and which way is better come from the metric declarations (:data:`locbench.evaluate.metrics.METRICS`);
no dataset or filter is named here.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np
import pandas as pd
from scipy import stats

from locbench.evaluate.aggregate import ate_over_pcrb, mean_ci, waypoint_stats
from locbench.evaluate.metrics import (
    ANEES,
    ATE_M,
    ATE_OVER_PCRB,
    CONFIDENCE,
    FAILED,
    FINAL_ERROR_M,
    HEADING_RMSE_RAD,
    METRICS,
    NEES_IN_BAND_FRACTION,
    PARTICLES_MEAN,
    POSE_DOF,
    REALTIME_FACTOR,
    REALTIME_FACTOR_REF,
    RELATION_ERROR_M,
    RPE_M_PER_M,
    SMOOTHED_ATE_M,
    UPDATE_US_MEDIAN,
    UPDATE_US_MEDIAN_REF,
    chi2_band,
    declared,
)
from locbench.evaluate.pcrb import BOUND_ALL
from locbench.present import ranking as rk
from locbench.present.docfmt import num
from locbench.report.doc import Table

NAN = float("nan")


def header(metric: str) -> str:
    """``ATE (cm)``: the metric's header with its display unit."""
    info = declared(metric)
    return f"{info.header} ({info.display_unit})" if info.display_unit else info.header


def values(df: pd.DataFrame, metric: str) -> np.ndarray:
    """The finite-or-infinite (non-NaN) values of one metric in ``df``."""
    # numpy's comparison of the names: pandas' string comparison costs a millisecond a call, the report makes
    # thousands
    v = df["value"].to_numpy(dtype=np.float64)[df["metric"].to_numpy() == metric]
    return v[~np.isnan(v)]


def mean_of(df: pd.DataFrame, metric: str) -> float:
    v = values(df, metric)
    return float(np.mean(v)) if v.size else NAN


def scaled(metric: str, x: float) -> float:
    return x * declared(metric).scale


def mean_pm(df: pd.DataFrame, metric: str) -> tuple[str, float]:
    """``mean ± half-width`` of the 95 % t-interval over seeds, in display units, and the mean for sorting."""
    ci = mean_ci(values(df, metric) * declared(metric).scale)
    if ci.n == 0:
        return "n/a", NAN
    if np.isnan(ci.low):
        return num(ci.mean), ci.mean
    return f"{num(ci.mean)} ± {num(ci.half_width, 2)}", ci.mean


def anees_verdict(anees: float, runs: int) -> tuple[str, tuple[float, float]]:
    """The verdict of a mean ANEES over ``runs`` runs against the two-sided 95 % chi-square(3N)/N band."""
    lo, hi = chi2_band(POSE_DOF, max(runs, 1), CONFIDENCE)
    if np.isnan(anees):
        return "n/a", (lo, hi)
    if anees > hi:
        return "over-confident", (lo, hi)
    if anees < lo:
        return "under-confident", (lo, hi)
    return "consistent", (lo, hi)


def consistency_cell(df: pd.DataFrame) -> tuple[str, float, int, int]:
    """The ANEES cell of one (dataset, filter): ``text, sort key, collapsed runs, runs``.

    A run whose covariance is singular to rounding at some ground-truth time has NEES +inf and so ANEES
    +inf; such runs are counted ("collapsed in k/n runs") and the mean is taken over the others.
    """
    v = values(df, ANEES)
    n = int(v.size)
    if n == 0:
        return "n/a", NAN, 0, 0
    inf = int(np.sum(np.isinf(v)))
    finite = v[np.isfinite(v)]
    if inf:
        rest = f"; {num(float(np.mean(finite)))} over the other {finite.size}" if finite.size else ""
        return f"collapsed in {inf}/{n} runs¹{rest}", np.inf, inf, n
    m = float(np.mean(finite))
    verdict, _ = anees_verdict(m, n)
    return f"{num(m)} ({verdict})", m, 0, n


COLLAPSE_FOOTNOTE = (
    "¹ Collapsed: the filter's covariance became singular to rounding at some ground-truth time of those runs, "
    "so its NEES there is +inf (it claimed certainty it did not have); the ANEES shown is over the other runs."
)


def band_text(runs: int) -> str:
    lo, hi = chi2_band(POSE_DOF, max(runs, 1), CONFIDENCE)
    return f"[{lo:.2f}, {hi:.2f}]"


def waypoint_rmse_mean(df: pd.DataFrame) -> dict[str, float]:
    """Mean over waypoints of RMSE_j per filter name (m)."""
    ws = waypoint_stats(df)
    if not len(ws):
        return {}
    return {str(f): float(np.nanmean(g["rmse_m"].to_numpy(dtype=np.float64))) for f, g in ws.groupby("filter")}


def waypoint_table(df: pd.DataFrame, filters: Sequence[str], caption: str) -> Table | None:
    """RMSE_j per filter and waypoint (cm) over the runs of one dataset name (report 003 fig. 5)."""
    ws = waypoint_stats(df)
    if not len(ws):
        return None
    n_wp = int(ws["waypoint"].max())
    rows: list[tuple[str, ...]] = []
    keys: list[tuple[float, ...]] = []
    for f in filters:
        sub = ws[ws["filter"] == f].set_index("waypoint")
        if sub.empty:
            continue
        vals = [float(sub["rmse_m"].get(j, NAN)) * 100.0 for j in range(1, n_wp + 1)]
        rows.append((f"`{f}`", str(int(sub["runs"].max())), *(num(v) for v in vals)))
        keys.append((NAN, float(sub["runs"].max()), *vals))
    head = ("filter", "runs", *(f"{j}" for j in range(1, n_wp + 1)))
    return Table(head, tuple(rows), caption=caption, sort_keys=tuple(keys))


#: Columns of a dataset's comparison table.
COMPARISON = (
    ATE_M,
    SMOOTHED_ATE_M,
    RELATION_ERROR_M,
    HEADING_RMSE_RAD,
    RPE_M_PER_M,
    FINAL_ERROR_M,
    ANEES,
    NEES_IN_BAND_FRACTION,
    UPDATE_US_MEDIAN,
    UPDATE_US_MEDIAN_REF,
    REALTIME_FACTOR,
    REALTIME_FACTOR_REF,
    PARTICLES_MEAN,
)


def run_count(df: pd.DataFrame) -> int:
    """Runs (seeds) of one (dataset, filter) with rows: ok and failed ones (a skipped run has none)."""
    return int(df["seed"].nunique())


def ate_over_bound(df: pd.DataFrame, filter_name: str) -> float:
    """A filter's efficiency ``ate_over_pcrb`` on one dataset name: sqrt(mean over seeds of ate_m^2) divided
    by the bound's, over the seeds where both have an ATE (:func:`locbench.evaluate.aggregate.ate_over_pcrb`); NaN
    without a bound."""
    ate = df[df["metric"] == ATE_M]
    bound = ate[ate["filter"] == BOUND_ALL].set_index("seed")["value"]
    mine = ate[ate["filter"] == filter_name].set_index("seed")["value"]
    seeds = mine.index.intersection(bound.index)
    b = bound.loc[seeds].to_numpy(dtype=np.float64)
    if not seeds.size or not np.all(b > 0):
        return NAN
    return ate_over_pcrb(mine.loc[seeds].to_numpy(dtype=np.float64), float(np.sqrt(np.mean(b * b))))


BOUND_FOOTNOTE = (
    "`pcrb`: the posterior Cramer-Rao bound of the simulator's true model with every sensor the world "
    "provides (`pcrb[laser=false]`: without the laser scans), a lower bound on any estimator's error "
    "(docs/pcrb.md); its cells are sqrt of the bound, not a filter's result. ATE / PCRB: sqrt(mean over seeds "
    "of ATE^2) over the bound's, on the same seeds (1 = as accurate as any estimator can be)."
)


def comparison_table(
    df: pd.DataFrame,
    filters: Sequence[str],
    caption: str,
    bounds: Sequence[str] = (),
    eligible: Sequence[bool] | None = None,
) -> Table:
    """Mean ± 95 % t-interval over seeds of every comparison metric present, a row per filter; with rows of
    the bound (``bounds``, shown after the filters), the column ``ate_over_pcrb``. With ``eligible`` (per
    filter: may be marked best), each ranked column marks its best and the rows tied with it
    (:func:`locbench.report.sections.paired_tests.mark_ties`)."""
    present = [m for m in COMPARISON if (df["metric"] == m).any()]
    with_bound = bool(bounds) and bool((df["filter"] == BOUND_ALL).any())
    rows: list[tuple[str, ...]] = []
    keys: list[tuple[float, ...]] = []
    for f in [*filters, *bounds]:
        sub = df[df["filter"] == f]
        if f in bounds and sub.empty:
            continue
        failed = values(sub, FAILED)
        n = run_count(sub)
        row = [f"`{f}`", str(n), str(int(np.sum(failed > 0.5)))]
        key = [NAN, float(n), float(np.sum(failed > 0.5))]
        for m in present:
            text, k = mean_pm(sub, m)
            row.append("-" if f in bounds and np.isnan(k) else text)
            key.append(k)
            if m == ATE_M and with_bound:
                eff = NAN if f in bounds else ate_over_bound(df, f)
                row.append(num(eff) if f not in bounds else "-")
                key.append(eff)
        rows.append(tuple(row))
        keys.append(tuple(key))
    cols = [
        h for m in present for h in ((header(m), header(ATE_OVER_PCRB)) if m == ATE_M and with_bound else (header(m),))
    ]
    head = ("filter", "runs", "failed", *cols)
    notes = (BOUND_FOOTNOTE,) if with_bound else ()
    hovers: tuple[tuple[str, ...], ...] = ()
    if eligible is not None:
        shown = [f for f in [*filters, *bounds] if f not in bounds or (df["filter"] == f).any()]
        ranked = [m for m in present if METRICS[m].better]
        index = {
            m: 3
            + present.index(m)
            + (1 if with_bound and ATE_M in present and present.index(ATE_M) < present.index(m) else 0)
            for m in ranked
        }
        flags = [*eligible, *[False] * (len(shown) - len(filters))]
        cells, ks = [list(r) for r in rows], [list(k) for k in keys]
        columns = [rk.Column(index[m], METRICS[m], rk.samples_for(df, shown, m)) for m in ranked]
        tips = rk.hover_grid(cells)
        marks = rk.mark_ties(cells, ks, columns, flags, hovers=tips)
        rows = [tuple(r) for r in cells]
        hovers = tuple(tuple(h) for h in tips)
        notes = (*notes, rk.tie_footnote(marks))
    return Table(head, tuple(rows), caption=caption, footnotes=notes, sort_keys=tuple(keys), hovers=hovers)


def wilson_interval(successes: int, n: int, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """Two-sided Wilson score interval of a binomial proportion (NaN, NaN for n = 0).

    (p + z^2/2n -+ z sqrt(p(1-p)/n + z^2/4n^2)) / (1 + z^2/n) with p = successes / n and z the normal
    quantile of (1 + confidence) / 2; unlike the Wald interval it stays inside [0, 1] and is not empty
    at 0 or n successes.
    """
    if n <= 0:
        return NAN, NAN
    if not 0 <= successes <= n:
        raise ValueError(f"successes must be in [0, {n}], got {successes}")
    z = float(stats.norm.ppf(0.5 + confidence / 2.0))
    p = successes / n
    den = 1.0 + z * z / n
    centre = (p + z * z / (2.0 * n)) / den
    half = z * np.sqrt(p * (1.0 - p) / n + z * z / (4.0 * n * n)) / den
    return max(0.0, float(centre - half)), min(1.0, float(centre + half))


def rate(df: pd.DataFrame, metric: str) -> tuple[int, int, float, float, float]:
    """``k, n, k/n, low, high`` of a 1/0 metric; n counts every run that was not skipped (a failed or
    diverged run, which has no 1/0 value, counts as a failure)."""
    v = values(df, metric)
    k = int(np.sum(v > 0.5))
    n = max(int(values(df, FAILED).size), int(v.size))
    if n == 0:
        return 0, 0, NAN, NAN, NAN
    lo, hi = wilson_interval(k, n)
    return k, n, k / n, lo, hi


def median_text(v: Iterable[float]) -> str:
    a = np.asarray(list(v), dtype=np.float64)
    a = a[~np.isnan(a)]
    return num(float(np.median(a))) if a.size else "n/a"
