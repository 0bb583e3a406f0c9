"""The zero-order hold: which stored estimate is in force at a given time.

A run stores a belief after each predict/update call. The estimate in force at a time ``t`` is the last stored
row with ``t_row <= t`` (a real-time filter reports its latest belief); a query before the first row gets the
first row (the reset belief, which holds from the start). At equal times the later row wins, so a predict and an
update at the same ``t`` score the update.

This is the one statement of that rule: the metrics hold a stored run at the ground-truth times with
:func:`hold_indices` (:mod:`locbench.evaluate.metrics`), and the runner, which scores a filter's belief samples
while it runs, asks :func:`hold_ends` which ground-truth times each row will hold before the row exists. Only
numpy is imported here: the runner's worker processes load this module, not the metrics' scipy and numba.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt


def hold_indices(t_est: npt.ArrayLike, t_query: npt.ArrayLike) -> npt.NDArray[np.intp]:
    """Row of the estimate in force at each query time (zero-order hold).

    Parameters
    ----------
    t_est : array-like, shape (n,)
        Times of the stored estimates, s, non-decreasing.
    t_query : array-like, shape (m,)
        Query times, s.

    Returns
    -------
    ndarray of intp, shape (m,)
        Index of the last row with ``t_est[row] <= t_query``; 0 for a query before the first row.
    """
    t = np.asarray(t_est, dtype=np.float64)
    if t.ndim != 1 or t.shape[0] == 0:
        raise ValueError("t_est must be a non-empty 1-d array of estimate times")
    idx = np.searchsorted(t, np.asarray(t_query, dtype=np.float64), side="right") - 1
    return np.clip(idx, 0, t.shape[0] - 1)


def estimate_at(t_est: npt.ArrayLike, values: npt.ArrayLike, t_query: npt.ArrayLike) -> np.ndarray:
    """The stored values in force at the query times (zero-order hold, see the module docstring).

    Parameters
    ----------
    t_est : array-like, shape (n,)
        Times of the stored estimates, s, non-decreasing.
    values : array-like, shape (n, ...)
        Anything stored per row: means (n, 3), covariances (n, 3, 3), diagnostics (n,).
    t_query : array-like, shape (m,)
        Query times, s.

    Returns
    -------
    ndarray, shape (m, ...)
        ``values[row]`` of the last row with ``t_est[row] <= t_query`` (the first row before it).
    """
    v = np.asarray(values)
    return v[hold_indices(t_est, t_query)]


def hold_ends(t_est: npt.ArrayLike, t_query: npt.ArrayLike) -> npt.NDArray[np.intp]:
    """Where each row's share of sorted query times ends (zero-order hold, :func:`hold_indices`).

    Parameters
    ----------
    t_est : array-like, shape (n,)
        Times of the estimates, s, non-decreasing (a run's rows, known before they are computed: the reset and
        one row per event the filter is sent).
    t_query : array-like, shape (m,)
        Query times, s, non-decreasing (ground-truth times).

    Returns
    -------
    ndarray of intp, shape (n,)
        ``ends[r]``: row ``r`` is in force at the query times ``t_query[ends[r - 1]:ends[r]]`` (from 0 for the
        first row); a row followed at once by one of the same time holds none. ``ends[-1]`` is ``m``.
    """
    rows = hold_indices(t_est, t_query)
    return np.cumsum(np.bincount(rows, minlength=np.shape(t_est)[0]))
