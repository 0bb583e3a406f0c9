"""Metrics of localization runs: pure functions on arrays (no I/O), as the DESIGN protocols define them.

Conventions shared by every function here:

- **Zero-order hold.** A run stores a belief after each predict/update call. The estimate in force at a
  time ``t`` is the last stored row with ``t_row <= t`` (a real-time filter reports its latest belief);
  a query before the first row gets the first row (the reset belief, which holds from the start).
  At equal times the later row wins, so a predict and an update at the same ``t`` score the update.
- Errors are taken at the **ground-truth times** (and at the waypoint times for waypoint errors), never
  at the filter's own times, so that filters with different update rates are scored on the same grid.
- Position errors in m, headings in rad wrapped to (-pi, pi], times in s, runtimes in microseconds.
- No alignment of the estimate to the truth: a localization filter works in the map frame.

Metric ids returned by :func:`run_metrics` are the DESIGN names (``results/summary/metrics.csv``); an id
never changes meaning. Undefined values (no update calls, a path shorter than the RPE distance) are
left out of the returned dict rather than stored as NaN.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import numpy.typing as npt
from scipy import stats

from locbench.geometry import between, pose_error, wrap_angle

if TYPE_CHECKING:
    from locbench.store import RunRecord, TruthRecord

log = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]

#: Coverage of the NEES consistency band (two-sided) and of the confidence intervals over seeds.
CONFIDENCE = 0.95
#: Travelled distance between the two poses of a relative-pose-error pair, m.
RPE_DELTA_M = 1.0
#: Degrees of freedom of the pose error (x, y, theta).
POSE_DOF = 3


# --- zero-order hold ----------------------------------------------------------------------------


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


# --- errors of one run --------------------------------------------------------------------------


def waypoint_errors(
    t_est: npt.ArrayLike, mean: npt.ArrayLike, wp_t: npt.ArrayLike, wp_xy: npt.ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Error at each waypoint against the marked point, e_j = |p_hat(t_j) - p_j| (report 003).

    Parameters
    ----------
    t_est : array-like, shape (n,)
        Estimate times, s.
    mean : array-like, shape (n, 3)
        Estimated poses (x m, y m, theta rad).
    wp_t : array-like, shape (m,)
        Times at which the robot stands on the waypoints, s.
    wp_xy : array-like, shape (m, 2)
        The marked points, m (not the ground truth at ``wp_t``: the report measures against the marks).

    Returns
    -------
    errors : ndarray, shape (m,)
        e_j in m.
    est_xy : ndarray, shape (m, 2)
        The estimated position p_hat(t_j) at each waypoint, m (zero-order hold).
    """
    est_xy = estimate_at(t_est, np.asarray(mean, dtype=np.float64)[:, :2], wp_t)
    errors = np.hypot(*(est_xy - np.asarray(wp_xy, dtype=np.float64)).T)
    return errors, est_xy


def ate(t_est: npt.ArrayLike, mean: npt.ArrayLike, gt_t: npt.ArrayLike, gt_xy: npt.ArrayLike) -> float:
    """Absolute trajectory error: position RMSE over every ground-truth time, no alignment.

    ATE = sqrt(mean_k |p_hat(t_k) - p(t_k)|^2) over the ground-truth times t_k, m.
    """
    est_xy = estimate_at(t_est, np.asarray(mean, dtype=np.float64)[:, :2], gt_t)
    d2 = np.sum((est_xy - np.asarray(gt_xy, dtype=np.float64)) ** 2, axis=1)
    return float(np.sqrt(np.mean(d2)))


def heading_rmse(t_est: npt.ArrayLike, mean: npt.ArrayLike, gt_t: npt.ArrayLike, gt_theta: npt.ArrayLike) -> float:
    """Heading RMSE over every ground-truth time with the difference wrapped to (-pi, pi], rad."""
    est_th = estimate_at(t_est, np.asarray(mean, dtype=np.float64)[:, 2], gt_t)
    d = wrap_angle(est_th - np.asarray(gt_theta, dtype=np.float64))
    return float(np.sqrt(np.mean(d**2)))


def final_error(t_est: npt.ArrayLike, mean: npt.ArrayLike, gt_t: npt.ArrayLike, gt_xy: npt.ArrayLike) -> float:
    """Position error at the last ground-truth time, m."""
    gt_t = np.asarray(gt_t, dtype=np.float64)
    est_xy = estimate_at(t_est, np.asarray(mean, dtype=np.float64)[:, :2], gt_t[-1:])
    return float(np.hypot(*(est_xy[0] - np.asarray(gt_xy, dtype=np.float64)[-1])))


def distance_pairs(gt_xy: npt.ArrayLike, delta_m: float = RPE_DELTA_M) -> tuple[npt.NDArray[np.intp], FloatArray]:
    """Pairs of ground-truth samples a fixed travelled distance apart (for the RPE).

    For each sample i, j(i) is the first later sample whose travelled distance along the ground-truth
    path from i is at least ``delta_m``; samples with no such j are dropped.

    Parameters
    ----------
    gt_xy : array-like, shape (n, 2)
        Ground-truth positions, m.
    delta_m : float
        Travelled distance of a pair, m (> 0).

    Returns
    -------
    pairs : ndarray of intp, shape (k, 2)
        (i, j) index pairs.
    dist : ndarray, shape (k,)
        Travelled distance s_j - s_i of each pair, m (>= ``delta_m``).
    """
    if delta_m <= 0:
        raise ValueError(f"delta_m must be > 0, got {delta_m}")
    xy = np.asarray(gt_xy, dtype=np.float64)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))]) if len(xy) else np.zeros(0)
    # A small tolerance so that an exact 1 m step counts despite rounding in the cumulative sum.
    j = np.searchsorted(s, s + delta_m - 1e-9 * max(1.0, delta_m), side="left")
    i = np.arange(s.shape[0])
    ok = j < s.shape[0]
    pairs = np.column_stack([i[ok], j[ok]]).astype(np.intp)
    return pairs, s[pairs[:, 1]] - s[pairs[:, 0]]


def rpe_per_metre(
    t_est: npt.ArrayLike,
    mean: npt.ArrayLike,
    gt_t: npt.ArrayLike,
    gt_poses: npt.ArrayLike,
    delta_m: float = RPE_DELTA_M,
) -> float:
    """Relative pose error per metre travelled (metric id ``rpe_m_per_m``).

    Definition: take the pairs (i, j) of ground-truth times from :func:`distance_pairs` (j is the first
    sample at least ``delta_m`` of travelled path after i). For each pair compare the relative motions
    R_true = between(x_i, x_j) and R_est = between(x_hat(t_i), x_hat(t_j)) (each in its own start
    frame, estimates by zero-order hold); the translational error is |xy(between(R_true, R_est))| =
    |xy(R_est) - xy(R_true)|, divided by the travelled distance s_j - s_i. RPE is the mean of these
    ratios over all pairs, m/m (dimensionless drift; 0.01 = 1 cm per metre).

    Parameters
    ----------
    t_est : array-like, shape (n,)
    mean : array-like, shape (n, 3)
    gt_t : array-like, shape (k,)
    gt_poses : array-like, shape (k, 3)
        Ground-truth poses (x m, y m, theta rad).
    delta_m : float
        Travelled distance per pair, m.

    Returns
    -------
    float
        Mean translational drift per metre; NaN when the path is shorter than ``delta_m``.
    """
    gt = np.asarray(gt_poses, dtype=np.float64)
    pairs, dist = distance_pairs(gt[:, :2], delta_m)
    if pairs.shape[0] == 0:
        return float("nan")
    est = estimate_at(t_est, np.asarray(mean, dtype=np.float64), gt_t)
    rel_true = between(gt[pairs[:, 0]], gt[pairs[:, 1]])
    rel_est = between(est[pairs[:, 0]], est[pairs[:, 1]])
    err = between(rel_true, rel_est)
    return float(np.mean(np.hypot(err[:, 0], err[:, 1]) / dist))


# --- consistency --------------------------------------------------------------------------------


def nees(errors: npt.ArrayLike, cov: npt.ArrayLike) -> FloatArray:
    """Normalised estimation error squared, e^T P^-1 e, per row.

    Parameters
    ----------
    errors : array-like, shape (n, d)
        Estimate minus truth with any angle already wrapped (:func:`locbench.geometry.pose_error`).
    cov : array-like, shape (n, d, d)
        The filter's covariance at the same rows.

    Returns
    -------
    ndarray, shape (n,)
        NEES (dimensionless, chi-square(d) for a consistent filter). A singular covariance claims
        certainty: its NEES is +inf unless the error is exactly zero (then 0).
    """
    e = np.asarray(errors, dtype=np.float64)
    P = np.asarray(cov, dtype=np.float64)
    out = np.empty(e.shape[0])
    try:
        sol = np.linalg.solve(P, e[..., None])[..., 0]
        out[:] = np.einsum("ni,ni->n", e, sol)
    except np.linalg.LinAlgError:
        # Row by row so that one singular covariance does not spoil the others.
        for k in range(e.shape[0]):
            try:
                out[k] = float(e[k] @ np.linalg.solve(P[k], e[k]))
            except np.linalg.LinAlgError:
                out[k] = 0.0 if not np.any(e[k]) else np.inf
    return out


def nees_at_truth(
    t_est: npt.ArrayLike, mean: npt.ArrayLike, cov: npt.ArrayLike, gt_t: npt.ArrayLike, gt_poses: npt.ArrayLike
) -> FloatArray:
    """NEES of the pose (x, y, theta) at every ground-truth time, heading error wrapped, shape (k,)."""
    idx = hold_indices(t_est, gt_t)
    m = np.asarray(mean, dtype=np.float64)[idx]
    P = np.asarray(cov, dtype=np.float64)[idx]
    return nees(pose_error(m, gt_poses), P)


def chi2_band(dof: int = POSE_DOF, n_runs: int = 1, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """Two-sided chi-square bounds of the mean of ``n_runs`` independent NEES values.

    If each NEES is chi-square(dof), the sum over N runs is chi-square(dof*N), so the mean lies in
    [chi2.ppf(a/2, dof*N) / N, chi2.ppf(1 - a/2, dof*N) / N] with probability ``confidence`` = 1 - a.
    For dof = 3, N = 1 and 95 %: [0.216, 9.348].
    """
    if n_runs < 1:
        raise ValueError(f"n_runs must be >= 1, got {n_runs}")
    a = 1.0 - confidence
    k = dof * n_runs
    return float(stats.chi2.ppf(a / 2, k) / n_runs), float(stats.chi2.ppf(1 - a / 2, k) / n_runs)


def anees(nees_values: npt.ArrayLike) -> float:
    """Average NEES over time of one run (dimensionless; 3 for a consistent 3-DOF filter)."""
    return float(np.mean(np.asarray(nees_values, dtype=np.float64)))


def fraction_in_band(values: npt.ArrayLike, band: tuple[float, float]) -> float:
    """Fraction of values inside the closed interval ``band`` (0..1); NaN for no values."""
    v = np.asarray(values, dtype=np.float64)
    if v.size == 0:
        return float("nan")
    return float(np.mean((v >= band[0]) & (v <= band[1])))


# --- runtime ------------------------------------------------------------------------------------


def runtime_stats(times_us: npt.ArrayLike) -> dict[str, float]:
    """Mean, median and 95th percentile (linear interpolation) of per-call times, microseconds.

    Returns an empty dict when there are no calls.
    """
    x = np.asarray(times_us, dtype=np.float64)
    if x.size == 0:
        return {}
    return {"mean": float(np.mean(x)), "median": float(np.median(x)), "p95": float(np.percentile(x, 95.0))}


def realtime_factor(duration_s: float, compute_ns: npt.ArrayLike) -> float:
    """Dataset duration divided by the total compute time of all predict and update calls.

    Parameters
    ----------
    duration_s : float
        Time spanned by the dataset's ground truth, s.
    compute_ns : array-like
        Per-call times, ns (the reset row's 0 may be included).

    Returns
    -------
    float
        > 1 means faster than real time; +inf when no compute time was recorded.
    """
    total_s = float(np.sum(np.asarray(compute_ns, dtype=np.float64))) * 1e-9
    return float(duration_s / total_s) if total_s > 0 else float("inf")


# --- one run ------------------------------------------------------------------------------------


def run_metrics(run: RunRecord, truth: TruthRecord, rpe_delta_m: float = RPE_DELTA_M) -> dict[str, float]:
    """Every metric of one stored run, keyed by its DESIGN metric id.

    Parameters
    ----------
    run : RunRecord
        The stored run.
    truth : TruthRecord
        The ground truth of the same dataset and seed.
    rpe_delta_m : float
        Travelled distance of the RPE pairs, m (``rpe_m_per_m`` is defined with the default 1 m).

    Returns
    -------
    dict of str to float
        For a run with status "skipped": empty. For any other status except "ok": ``{"failed": 1}``.
        For an ok run: ``failed`` = 0 and ``waypoint_<j>_error_m``, ``waypoint_<j>_est_x_m``,
        ``waypoint_<j>_est_y_m``, ``waypoint_<j>_marked_x_m``, ``waypoint_<j>_marked_y_m`` (j from 1,
        when the dataset has waypoints), ``ate_m``, ``heading_rmse_rad``, ``rpe_m_per_m``,
        ``final_error_m``, ``anees``, ``nees_in_band_fraction`` (single-run two-sided 95 %
        chi-square(3) band), ``predict_us_{mean,median,p95}``, ``update_us_{mean,median,p95}``,
        ``realtime_factor``. Undefined values are left out.
    """
    status = run.status
    if status == "skipped":
        return {}
    if status != "ok":
        return {"failed": 1.0}
    if run.t.shape[0] == 0:
        raise ValueError("an ok run has no estimates")
    gt = truth.ground_truth
    gt_poses = gt.poses
    out: dict[str, float] = {"failed": 0.0}
    if truth.waypoints is not None and len(truth.waypoints):
        err, est_xy = waypoint_errors(run.t, run.mean, truth.waypoints.t, truth.waypoints.xy)
        for j in range(err.shape[0]):
            out[f"waypoint_{j + 1}_error_m"] = float(err[j])
            out[f"waypoint_{j + 1}_est_x_m"] = float(est_xy[j, 0])
            out[f"waypoint_{j + 1}_est_y_m"] = float(est_xy[j, 1])
            # The marked point itself, so that the distance of the mean estimate needs only the CSV.
            out[f"waypoint_{j + 1}_marked_x_m"] = float(truth.waypoints.xy[j, 0])
            out[f"waypoint_{j + 1}_marked_y_m"] = float(truth.waypoints.xy[j, 1])
    out["ate_m"] = ate(run.t, run.mean, gt.t, gt.xy)
    out["heading_rmse_rad"] = heading_rmse(run.t, run.mean, gt.t, gt.theta)
    out["rpe_m_per_m"] = rpe_per_metre(run.t, run.mean, gt.t, gt_poses, rpe_delta_m)
    out["final_error_m"] = final_error(run.t, run.mean, gt.t, gt.xy)
    ne = nees_at_truth(run.t, run.mean, run.cov, gt.t, gt_poses)
    out["anees"] = anees(ne)
    out["nees_in_band_fraction"] = fraction_in_band(ne, chi2_band(POSE_DOF, 1))
    for call in ("predict", "update"):
        for stat, value in runtime_stats(run.step_times_us(call)).items():
            out[f"{call}_us_{stat}"] = value
    out["realtime_factor"] = realtime_factor(truth.duration_s, run.step_ns)
    # Kidnap recovery (kidnap_recovered, kidnap_time_to_recover_s) joins here when truth.kidnaps is set.
    return {k: v for k, v in out.items() if not np.isnan(v)}


# --- aggregations over seeds --------------------------------------------------------------------


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
