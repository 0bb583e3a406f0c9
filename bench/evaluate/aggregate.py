"""Aggregations over runs (seeds) of per-run metrics: pure functions on arrays and tidy frames (no I/O).

:mod:`locbench.evaluate.metrics` computes each run's values; this module combines runs: a mean with its t-interval
over seeds, report 003's waypoint statistics (RMSE_j = sqrt(mean_i e_ij^2) over the ok runs, fig. 5, and the
distance between waypoint j and the mean estimated position over runs, table 1), the efficiency against the
bound over seeds, and the mean over runs of a per-time series. The claims and the report both read them here.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
import pandas as pd
from scipy import stats

from locbench.evaluate.hold import estimate_at
from locbench.evaluate.metrics import CONFIDENCE

FloatArray = npt.NDArray[np.float64]

_WP_RE = re.compile(r"^waypoint_(\d+)_(error_m|est_x_m|est_y_m|marked_x_m|marked_y_m)$")


class MeanCI(NamedTuple):
    """A mean over seeds with its two-sided t-interval (``low``/``high`` NaN when n < 2)."""

    mean: float
    low: float
    high: float
    n: int

    @property
    def half_width(self) -> float:
        return (self.high - self.low) / 2.0


def mean_ci(values: npt.ArrayLike, confidence: float = CONFIDENCE) -> MeanCI:
    """Mean with a Student-t confidence interval, NaNs ignored.

    mean +- t_{(1+c)/2, n-1} * s / sqrt(n) with s the sample standard deviation (ddof = 1). With
    fewer than two finite values the interval is NaN; with an infinite value the mean is infinite and
    the interval NaN.
    """
    v = np.asarray(values, dtype=np.float64).ravel()
    v = v[~np.isnan(v)]
    n = int(v.size)
    if n == 0:
        return MeanCI(float("nan"), float("nan"), float("nan"), 0)
    m = float(np.mean(v))
    if n < 2 or not np.all(np.isfinite(v)):
        return MeanCI(m, float("nan"), float("nan"), n)
    h = float(stats.t.ppf(0.5 + confidence / 2.0, n - 1) * np.std(v, ddof=1) / np.sqrt(n))
    return MeanCI(m, m - h, m + h, n)


def waypoint_rmse(errors: npt.ArrayLike) -> FloatArray:
    """RMSE at each waypoint over runs, RMSE_j = sqrt(mean_i e_ij^2) (report 003 fig. 5).

    Parameters
    ----------
    errors : array-like, shape (runs, m)
        e_ij in m; NaN entries (a run without that waypoint) are ignored.

    Returns
    -------
    ndarray, shape (m,)
        RMSE_j in m.
    """
    e = np.asarray(errors, dtype=np.float64)
    return np.sqrt(np.nanmean(e**2, axis=0))


def mean_estimate_distance(est_xy: npt.ArrayLike, marked_xy: npt.ArrayLike) -> FloatArray:
    """Distance between each waypoint and the mean estimated position over runs (report 003 table 1).

    Parameters
    ----------
    est_xy : array-like, shape (runs, m, 2)
        Estimated positions at the waypoints, m.
    marked_xy : array-like, shape (m, 2) or (runs, m, 2)
        The marked points, m (per run when they may differ; then their mean is used).

    Returns
    -------
    ndarray, shape (m,)
        |mean_i p_hat_ij - p_j| in m.
    """
    est = np.asarray(est_xy, dtype=np.float64)
    mk = np.asarray(marked_xy, dtype=np.float64)
    if mk.ndim == 3:
        mk = np.nanmean(mk, axis=0)
    d = np.nanmean(est, axis=0) - mk
    return np.hypot(d[:, 0], d[:, 1])


def mean_over_runs(
    t_grid: npt.ArrayLike, series: Sequence[tuple[npt.ArrayLike, npt.ArrayLike]]
) -> tuple[FloatArray, npt.NDArray[np.int64]]:
    """Mean over runs of a per-time quantity (the NEES) at each time of a common grid.

    Each run's series is sampled on ``t_grid`` by zero-order hold (so runs whose ground truth has
    different sample times still line up); times before a run's first sample take its first value.

    Parameters
    ----------
    t_grid : array-like, shape (k,)
        Common times, s.
    series : sequence of (t (n_i,), values (n_i,))
        One series per run.

    Returns
    -------
    mean : ndarray, shape (k,)
        Mean over the runs with a finite or infinite (non-NaN) value at that time.
    count : ndarray of int64, shape (k,)
        How many runs entered each mean.
    """
    grid = np.asarray(t_grid, dtype=np.float64)
    if not series:
        return np.full(grid.shape, np.nan), np.zeros(grid.shape, dtype=np.int64)
    stack = np.vstack([estimate_at(t, np.asarray(v, dtype=np.float64), grid) for t, v in series])
    valid = ~np.isnan(stack)
    count = valid.sum(axis=0).astype(np.int64)
    total = np.where(valid, stack, 0.0).sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(count > 0, total / np.maximum(count, 1), np.nan)
    return mean, count


def ate_over_pcrb(ate_m: npt.ArrayLike, pcrb_ate_m: float) -> float:
    """Efficiency of a filter against the posterior Cramer-Rao bound: sqrt(mean over runs of ate_m^2) / bound.

    Parameters
    ----------
    ate_m : array-like, shape (n_runs,)
        The filter's ATE of each run (seed) on one dataset, m.
    pcrb_ate_m : float
        The bound's ATE on the same dataset (RMS over the same seeds, :func:`locbench.evaluate.pcrb.pcrb_metrics`), m.

    Returns
    -------
    float
        Dimensionless, >= 1 up to sampling noise for any estimator the bound covers (1 = efficient); nan for
        no runs.
    """
    a = np.asarray(ate_m, dtype=np.float64)
    if a.size == 0:
        return float("nan")
    if not pcrb_ate_m > 0:
        raise ValueError(f"pcrb_ate_m must be > 0 m, got {pcrb_ate_m}")
    return float(np.sqrt(np.mean(a * a)) / pcrb_ate_m)


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
