"""Metrics of localization runs: pure functions on arrays (no I/O), as the DESIGN protocols define them.

Conventions shared by every function here:

- **Zero-order hold** (:mod:`locbench.evaluate.hold`, the one definition the runner uses too). A run stores a
  belief after each predict/update call. The estimate in force at a time ``t`` is the last stored row with
  ``t_row <= t`` (a real-time filter reports its latest belief); a query before the first row gets the first
  row (the reset belief, which holds from the start). At equal times the later row wins, so a predict and an
  update at the same ``t`` score the update.
- Errors are taken at the **ground-truth times** (and at the waypoint times for waypoint errors), never
  at the filter's own times, so that filters with different update rates are scored on the same grid.
- **Align once, then compute** (as evo associates estimate and reference before any metric): :func:`align`
  holds a run's estimates at the ground-truth times once, giving an :class:`Aligned` view (times, held
  means and covariances, truth, wrapped errors, NEES); every per-time metric takes that view.
- Position errors in m, headings in rad wrapped to (-pi, pi], times in s, runtimes in microseconds.
- No alignment of the estimate to the truth: a localization filter works in the map frame.

**A metric is one declaration.** Every id of ``results/summary/metrics.parquet`` is declared once, in :data:`METRICS`,
as a :class:`Metric`: its id (a named constant here, ``ATE_M``), the function that gives one run's value and how the
report shows it (header, display unit and scale, which way is better, whether the summary table has it, its line in
docs/protocols.md). :func:`run_metrics` computes every declared metric of a run, the report's tables read the display
records, and :func:`declare` adds a metric (a plugin's or a study's) the same way. An id never changes meaning.
Undefined values (no update calls, a path shorter than the RPE distance) are left out of the returned dict rather
than stored as NaN.

**Recovery criterion** (DESIGN "Kidnap recovery"): at a ground-truth time the filter is *within* when
its position error is <= :data:`RECOVERY_POSITION_M` (0.25 m) and its wrapped heading error is
<= :data:`RECOVERY_HEADING_RAD` (0.25 rad). It *recovers* at the first ground-truth time t_s from which
it is within at every ground-truth sample of [t_s, t_s + :data:`RECOVERY_HOLD_S`] (2 s); the hold must
end inside the ground truth, so a run that ends during the hold has not recovered. Errors are taken by
the zero-order hold like every other metric.

Metric ids added on top of the DESIGN list (each documented here, none changes an existing id):

- ``kidnap_distance_m``, ``kidnap_recovered``, ``kidnap_time_to_recover_s``,
  ``kidnap_false_confidence_fraction``: only when the truth has kidnap events, and always about the
  **first** kidnap (a later kidnap only cuts its window short). ``kidnap_distance_m`` is |(dx, dy)|
  of the jump, m, from the truth record. ``kidnap_recovered`` is 1 when the recovery t_s lies in
  [t_k, t_k + :data:`KIDNAP_WINDOW_S`] (30 s; the 2 s hold may run past the window) and before the
  next kidnap, else 0; ``kidnap_time_to_recover_s`` = t_s - t_k, s, present only when recovered.
  ``kidnap_false_confidence_fraction`` is the fraction of the time from t_k to the recovery (not
  recovered: to the end of the 30 s window, the next kidnap or the end of the truth, whichever is
  first) during which the NEES exceeds the one-sided :data:`FALSE_CONFIDENCE_PROBABILITY` (99.9 %)
  chi-square(3) quantile, 16.27: the filter is wrong and does not know it. Each ground-truth sample's
  NEES holds until the next sample; an empty window (recovered at t_k itself) gives 0.
- ``converged`` (1/0) and ``time_to_converge_s``, for every ok run (global localization): the
  recovery criterion searched from the first ground-truth time over the whole run;
  ``time_to_converge_s`` = t_s - t_0, s, present only when converged. A filter started at the true
  pose typically has ``converged`` = 1 and ``time_to_converge_s`` = 0.
- ``updates_to_converge``, for every ok run that converged: how many measurement updates (stored rows of any
  kind but odometry and the reset) the filter had made when it met the criterion, counted up to the row in force at
  t_s; 0 when its initial belief already meets the criterion at t_0 and the run converges there. A belief whose
  first update at t_0 fixes its heading has ``time_to_converge_s`` = 0 whatever it started from (every ground-truth
  time sees an updated belief); the count still tells one update from ten.
- ``smoothed_ate_m``, ``smoothed_heading_rmse_rad``: when the run's ``extra`` holds a smoothed
  trajectory (``smoothed_t`` (n,), s, and ``smoothed_mean`` (n, 3), world frame), its ATE and wrapped
  heading RMSE, defined exactly as ``ate_m`` and ``heading_rmse_rad`` (zero-order hold of the
  smoothed poses at the ground-truth times).
- ``particles_mean``: the mean particle count over the run's steps, from the ``particles`` diagnostic
  (particle filters; with KLD sampling the count adapts).
- ``accepted_fraction``: measurements fused over measurements offered, over the run, from the
  ``accepted``/``rejected`` diagnostics (gated landmark sightings, extracted lines, ICP matches).
- ``relation_error_m``, ``relation_error_rad``: when the dataset has reference relations (Intel), the
  relation-based error of Kuemmerle et al. 2009 ("On measuring the accuracy of SLAM algorithms", Auton.
  Robots 27(4), eq. 1-2): for each relation (t1, t2, delta*) the estimated relation delta =
  x_hat(t1)^-1 (+) x_hat(t2) (zero-order hold) is compared with delta* through e = delta*^-1 (+) delta;
  the metrics are the mean absolute translational error |e_xy| (m) and rotational error |e_theta| (rad)
  over the relations whose two times lie within the run (the paper's "abs" columns);
  ``relation_count`` is how many were used.
- ``crps_x_m``, ``crps_y_m``, ``crps_heading_rad``, ``energy_score_m`` and each one's block-bootstrap interval
  ``<stem>_ci_low_<unit>``, ``<stem>_ci_high_<unit>`` (``crps_x_ci_low_m`` ...): the proper scores of the
  filter's own belief, mean over the ground-truth times (:mod:`locbench.evaluate.scores`).
- On a dataset whose trajectory is a *SLAM reference* (``TruthRecord.truth_label``), ``ate_m`` and the
  other trajectory errors measure agreement with that reference, not with the truth; the report labels them.
"""

from __future__ import annotations

import functools
import logging
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, TypedDict

import numpy as np
import numpy.typing as npt
from scipy import stats

from locbench.core.geometry import between, wrap_angle
from locbench.evaluate.aligned import Aligned, NoCovariance, align, nees
from locbench.evaluate.hold import estimate_at
from locbench.evaluate.records import KIND_NAMES
from locbench.evaluate.scores import SCORE_IDS, score_metrics

if TYPE_CHECKING:
    from locbench.datasets.dataset import Kidnap
    from locbench.evaluate.records import RunRecord, TruthRecord

log = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]

#: Coverage of the NEES consistency band (two-sided) and of the confidence intervals over seeds.
CONFIDENCE = 0.95
#: Travelled distance between the two poses of a relative-pose-error pair, m.
RPE_DELTA_M = 1.0
#: Degrees of freedom of the pose error (x, y, theta).
POSE_DOF = 3
#: Recovery criterion (DESIGN "Kidnap recovery"): largest position error, m ...
RECOVERY_POSITION_M = 0.25
#: ... largest wrapped heading error, rad ...
RECOVERY_HEADING_RAD = 0.25
#: ... held without a break for this long, s.
RECOVERY_HOLD_S = 2.0
#: A kidnap counts as recovered only when the hold starts within this time after the kidnap, s.
KIDNAP_WINDOW_S = 30.0
#: One-sided chi-square(3) probability whose quantile marks false confidence after a kidnap.
FALSE_CONFIDENCE_PROBABILITY = 0.999
#: Tolerance on time comparisons, s (ground-truth times are sums of float steps).
_T_EPS = 1e-6

# --- metric ids (each declared in METRICS, at the end of the module) ----------------------------------------------
# An id with a <name> part names a family of ids (member_id fills it in).

FAILED = "failed"
ATE_M = "ate_m"
ATE_OVER_PCRB = "ate_over_pcrb"
WAYPOINT_ERROR_M = "waypoint_<j>_error_m"
WAYPOINT_EST_X_M = "waypoint_<j>_est_x_m"
WAYPOINT_EST_Y_M = "waypoint_<j>_est_y_m"
WAYPOINT_MARKED_X_M = "waypoint_<j>_marked_x_m"
WAYPOINT_MARKED_Y_M = "waypoint_<j>_marked_y_m"
WAYPOINT_RMSE_MEAN_M = "waypoint_rmse_mean_m"
SMOOTHED_ATE_M = "smoothed_ate_m"
SMOOTHED_HEADING_RMSE_RAD = "smoothed_heading_rmse_rad"
HEADING_RMSE_RAD = "heading_rmse_rad"
RPE_M_PER_M = "rpe_m_per_m"
FINAL_ERROR_M = "final_error_m"
WITHIN_FRACTION = "within_<k>cm_fraction"
RELATION_ERROR_M = "relation_error_m"
RELATION_ERROR_RAD = "relation_error_rad"
RELATION_COUNT = "relation_count"
ANEES = "anees"
NEES_IN_BAND_FRACTION = "nees_in_band_fraction"
NLL = "nll"
CRPS_X_M, CRPS_Y_M, CRPS_HEADING_RAD, ENERGY_SCORE_M = SCORE_IDS
SCORE_CI_LOW = "<score>_ci_low_<unit>"
SCORE_CI_HIGH = "<score>_ci_high_<unit>"
LOST_AUROC = "lost_auroc"
PREDICT_US_MEAN = "predict_us_mean"
PREDICT_US_MEDIAN = "predict_us_median"
PREDICT_US_P95 = "predict_us_p95"
UPDATE_US_MEAN = "update_us_mean"
UPDATE_US_MEDIAN = "update_us_median"
UPDATE_US_P95 = "update_us_p95"
REALTIME_FACTOR = "realtime_factor"
LATENCY_S_MEDIAN = "latency_s_median"
LATENCY_S_P95 = "latency_s_p95"
#: The row diagnostic an imported bag's latency is stored in, s (:mod:`locbench.run.import_runs`).
LATENCY_DIAGNOSTIC = "latency_s"
#: The suffix of a metric id in reference units.
REF_SUFFIX = "_ref"
PREDICT_US_MEDIAN_REF = PREDICT_US_MEDIAN + REF_SUFFIX
UPDATE_US_MEDIAN_REF = UPDATE_US_MEDIAN + REF_SUFFIX
REALTIME_FACTOR_REF = REALTIME_FACTOR + REF_SUFFIX
KIDNAP_DISTANCE_M = "kidnap_distance_m"
KIDNAP_RECOVERED = "kidnap_recovered"
KIDNAP_TIME_TO_RECOVER_S = "kidnap_time_to_recover_s"
KIDNAP_FALSE_CONFIDENCE_FRACTION = "kidnap_false_confidence_fraction"
CONVERGED = "converged"
TIME_TO_CONVERGE_S = "time_to_converge_s"
UPDATES_TO_CONVERGE = "updates_to_converge"
ACCEPTED_FRACTION = "accepted_fraction"
PARTICLES_MEAN = "particles_mean"
RECORDED_ATE_MEDIAN_M = "recorded_ate_median_m"


def member_id(family: str, *parts: object) -> str:
    """The id of one member of a family of ids: ``member_id(WAYPOINT_ERROR_M, 3)`` is ``waypoint_3_error_m``.

    Each ``<name>`` part of ``family`` is replaced, in order, by one of ``parts``.
    """
    names = _PLACEHOLDER.findall(family)
    if len(names) != len(parts):
        raise ValueError(f"{family!r} has {len(names)} part(s) to fill, got {len(parts)}")
    out = family
    for name, part in zip(names, parts, strict=True):
        out = out.replace(name, str(part), 1)
    return out


_PLACEHOLDER = re.compile(r"<[a-z]+>")


# --- the aligned view: a run held at the ground-truth times, once ------------------------------------


def align_run(run: RunRecord, truth: TruthRecord) -> Aligned:
    """The :class:`Aligned` view of a stored run (means and covariances) at its truth's ground-truth times."""
    gt = truth.ground_truth
    # an imported pose-only run stores no covariance (``covariance`` false): its view has none
    return align(run.t, run.mean, gt.t, gt.poses, run.cov if run.meta.get("covariance", True) else None)


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


def ate(a: Aligned) -> float:
    """Absolute trajectory error: position RMSE over every ground-truth time, no alignment.

    ATE = sqrt(mean_k |p_hat(t_k) - p(t_k)|^2) over the ground-truth times t_k, m.
    """
    d2 = np.sum(a.error[:, :2] ** 2, axis=1)
    return float(np.sqrt(np.mean(d2)))


#: Position-error thresholds of the accuracy-at-threshold metrics ``within_<k>cm_fraction``, cm.
WITHIN_THRESHOLDS_CM = (5, 10, 25, 50)


def within_fractions(a: Aligned) -> dict[str, float]:
    """Accuracy at thresholds: the fraction of ground-truth times whose position error is at most each of
    :data:`WITHIN_THRESHOLDS_CM`, as ``within_<k>cm_fraction`` (zero-order hold, no alignment)."""
    err = a.position_error
    return {member_id(WITHIN_FRACTION, k): float(np.mean(err <= k / 100.0)) for k in WITHIN_THRESHOLDS_CM}


def heading_rmse(a: Aligned) -> float:
    """Heading RMSE over every ground-truth time with the difference wrapped to (-pi, pi], rad."""
    return float(np.sqrt(np.mean(a.error[:, 2] ** 2)))


def final_error(a: Aligned) -> float:
    """Position error at the last ground-truth time, m."""
    return float(a.position_error[-1])


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


def rpe_per_metre(a: Aligned, delta_m: float = RPE_DELTA_M) -> float:
    """Relative pose error per metre travelled (metric id ``rpe_m_per_m``).

    Definition: take the pairs (i, j) of ground-truth times from :func:`distance_pairs` (j is the first
    sample at least ``delta_m`` of travelled path after i). For each pair compare the relative motions
    R_true = between(x_i, x_j) and R_est = between(x_hat(t_i), x_hat(t_j)) (each in its own start
    frame, estimates by zero-order hold); the translational error is |xy(between(R_true, R_est))| =
    |xy(R_est) - xy(R_true)|, divided by the travelled distance s_j - s_i. RPE is the mean of these
    ratios over all pairs, m/m (dimensionless drift; 0.01 = 1 cm per metre).

    Parameters
    ----------
    a : Aligned
        The run at the ground-truth times.
    delta_m : float
        Travelled distance per pair, m.

    Returns
    -------
    float
        Mean translational drift per metre; NaN when the path is shorter than ``delta_m``.
    """
    gt = a.truth
    pairs, dist = distance_pairs(gt[:, :2], delta_m)
    if pairs.shape[0] == 0:
        return float("nan")
    est = a.mean
    rel_true = between(gt[pairs[:, 0]], gt[pairs[:, 1]])
    rel_est = between(est[pairs[:, 0]], est[pairs[:, 1]])
    err = between(rel_true, rel_est)
    return float(np.mean(np.hypot(err[:, 0], err[:, 1]) / dist))


# --- consistency --------------------------------------------------------------------------------


def nees_at_truth(a: Aligned) -> FloatArray:
    """NEES of the pose (x, y, theta) at every ground-truth time, heading error wrapped, shape (k,)."""
    return a.nees


def nll(errors: npt.ArrayLike, cov: npt.ArrayLike, maha: npt.ArrayLike | None = None) -> FloatArray:
    """Negative log-likelihood of the truth under the filter's Gaussian, per row.

    NLL = 0.5 (e^T P^-1 e + log det(2 pi P)), with e the estimate minus the truth (angles already wrapped,
    :func:`locbench.core.geometry.pose_error`) and P the filter's covariance: the negative log of the Gaussian
    density N(truth; estimate, P). Dimensionless for the density in the state's SI units (m, m, rad); lower
    is better, and unlike the NEES it also penalises a covariance much larger than the error.

    Parameters
    ----------
    errors : array-like, shape (n, d)
        Estimate minus truth.
    cov : array-like, shape (n, d, d)
        The filter's covariance at the same rows.
    maha : array-like, shape (n,), optional
        ``nees(errors, cov)`` when the caller has it already (:attr:`Aligned.nees`); computed here otherwise.

    Returns
    -------
    ndarray, shape (n,)
        NLL per row; +inf where P is singular or not positive definite (to rounding), the rows whose NEES
        is +inf (:func:`nees`).
    """
    e = np.asarray(errors, dtype=np.float64)
    P = np.asarray(cov, dtype=np.float64)
    maha = nees(e, P) if maha is None else np.asarray(maha, dtype=np.float64)
    sign, logdet = np.linalg.slogdet(P)
    bad = (sign <= 0) | ~np.isfinite(maha) | ~np.isfinite(logdet)
    # a collapsed P gives +inf + (-inf): the row is +inf by definition, computed without a warning
    with np.errstate(invalid="ignore", over="ignore"):
        out = 0.5 * (maha + e.shape[1] * np.log(2.0 * np.pi) + logdet)
    out[bad] = np.inf
    return out


def nll_at_truth(a: Aligned) -> FloatArray:
    """NLL of the pose (x, y, theta) at every ground-truth time, heading error wrapped, shape (k,)."""
    if a.cov is None:
        raise NoCovariance("this aligned trajectory has no covariance: no NLL")
    # the view's NEES is the same e^T P^-1 e: solved once for both
    return nll(a.error, a.cov, a.nees)


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


# --- recovery: kidnap and global localization ----------------------------------------------------


def within_recovery(a: Aligned) -> npt.NDArray[np.bool_]:
    """Whether the estimate meets the recovery criterion at each ground-truth time.

    Returns
    -------
    ndarray of bool, shape (k,)
        Position error <= :data:`RECOVERY_POSITION_M` and |wrapped heading error| <=
        :data:`RECOVERY_HEADING_RAD` (zero-order hold of the estimate).
    """
    e = a.error
    with np.errstate(invalid="ignore"):
        return (a.position_error <= RECOVERY_POSITION_M) & (np.abs(e[:, 2]) <= RECOVERY_HEADING_RAD)


def first_hold(
    t: npt.ArrayLike,
    ok: npt.ArrayLike,
    t_from: float,
    latest_start: float = np.inf,
    hold_s: float = RECOVERY_HOLD_S,
) -> float | None:
    """The first time from which a condition holds at every sample for ``hold_s`` seconds.

    Parameters
    ----------
    t : array-like, shape (k,)
        Sample times, s, increasing.
    ok : array-like of bool, shape (k,)
        The condition at each sample.
    t_from : float
        Only samples at or after this time count, s.
    latest_start : float
        The hold must start at or before this time, s (it may end later).
    hold_s : float
        Required duration, s: every sample in [t_s, t_s + hold_s] is ok and a sample at or after
        t_s + hold_s exists.

    Returns
    -------
    float or None
        t_s, a sample time, or None when the condition never holds long enough in time.
    """
    tt = np.asarray(t, dtype=np.float64)
    good = np.asarray(ok, dtype=bool) & (tt >= t_from - _T_EPS)
    if not good.any():
        return None
    # Runs of consecutive ok samples: the earliest start of a long-enough run is the answer, since a
    # later start inside the same run only shortens it.
    edges = np.diff(np.concatenate([[0], good.astype(np.int8), [0]]))
    starts = np.flatnonzero(edges == 1)
    ends = np.flatnonzero(edges == -1) - 1
    long_enough = (tt[ends] - tt[starts] >= hold_s - _T_EPS) & (tt[starts] <= latest_start + _T_EPS)
    if not long_enough.any():
        return None
    return float(tt[starts[np.argmax(long_enough)]])


def time_fraction(t: npt.ArrayLike, flag: npt.ArrayLike, t0: float, t1: float) -> float:
    """Fraction of [t0, t1] during which a per-sample flag, held until the next sample, is set.

    The flag in force at a time is that of the last sample at or before it (the first sample before
    the first). Returns 0 for an empty interval (t1 <= t0).
    """
    if t1 - t0 <= _T_EPS:
        return 0.0
    tt = np.asarray(t, dtype=np.float64)
    inner = tt[(tt > t0) & (tt < t1)]
    edges = np.concatenate([[t0], inner, [t1]])
    on = np.asarray(estimate_at(tt, np.asarray(flag, dtype=bool), edges[:-1]), dtype=bool)
    return float(np.sum(np.diff(edges)[on]) / (t1 - t0))


def false_confidence_bound(probability: float = FALSE_CONFIDENCE_PROBABILITY, dof: int = POSE_DOF) -> float:
    """One-sided chi-square quantile above which the NEES counts as false confidence (16.27 for 99.9 %, 3)."""
    return float(stats.chi2.ppf(probability, dof))


def kidnap_metrics(a: Aligned, kidnaps: Sequence[Kidnap]) -> dict[str, float]:
    """Recovery from the first kidnap of a run (definitions in the module docstring).

    Parameters
    ----------
    a : Aligned
        The run at the ground-truth times, with its covariances (after a kidnap the truth is the pose after
        the jump).
    kidnaps : sequence of Kidnap
        The truth's kidnap events (time s, world-frame jump (dx m, dy m, dtheta rad)); only the first
        (earliest) is scored.

    Returns
    -------
    dict of str to float
        ``kidnap_distance_m``, ``kidnap_recovered``, ``kidnap_time_to_recover_s`` (only when recovered)
        and ``kidnap_false_confidence_fraction``; empty without kidnaps.
    """
    if not kidnaps:
        return {}
    ordered = sorted(kidnaps, key=lambda k: k.t)
    first = ordered[0]
    tt = a.t
    t_k = float(first.t)
    # the window ends at 30 s, at the next kidnap (which would score a different jump) or with the truth
    t_next = float(ordered[1].t) if len(ordered) > 1 else np.inf
    window_end = min(t_k + KIDNAP_WINDOW_S, t_next, float(tt[-1]))
    ok = within_recovery(a)
    if np.isfinite(t_next):
        ok = ok & (tt < t_next - _T_EPS)  # a hold must not straddle the next jump
    t_s = first_hold(tt, ok, t_k, latest_start=min(t_k + KIDNAP_WINDOW_S, t_next))
    out = {KIDNAP_DISTANCE_M: float(np.hypot(first.delta[0], first.delta[1]))}
    out[KIDNAP_RECOVERED] = 1.0 if t_s is not None else 0.0
    if t_s is not None:
        out[KIDNAP_TIME_TO_RECOVER_S] = t_s - t_k
    if a.cov is None:
        return out  # no covariance, no false confidence
    confident = a.nees > false_confidence_bound()
    out[KIDNAP_FALSE_CONFIDENCE_FRACTION] = time_fraction(tt, confident, t_k, window_end if t_s is None else t_s)
    return out


def convergence_metrics(a: Aligned) -> dict[str, float]:
    """Global localization: ``converged`` (1/0) and ``time_to_converge_s`` (only when converged).

    The recovery criterion (module docstring) searched from the first ground-truth time t_0 over the
    whole run; ``time_to_converge_s`` = t_s - t_0, s.
    """
    tt = a.t
    t_s = first_hold(tt, within_recovery(a), float(tt[0]))
    if t_s is None:
        return {CONVERGED: 0.0}
    return {CONVERGED: 1.0, TIME_TO_CONVERGE_S: t_s - float(tt[0])}


def updates_to_converge(a: Aligned, is_update: npt.ArrayLike, initial: npt.ArrayLike) -> float | None:
    """The number of measurement updates a run made before it converged (module docstring).

    Parameters
    ----------
    a : Aligned
        The run held at the ground-truth times (its ``rows`` index the run's stored rows).
    is_update : array-like of bool, shape (n,)
        Whether each stored row of the run follows a measurement update (not odometry, not the reset).
    initial : array-like, shape (3,)
        The initial belief's mean (x m, y m, theta rad, world frame), judged against the first truth pose.

    Returns
    -------
    float or None
        The updates among the stored rows up to the one in force at the convergence time t_s; 0 when the
        initial belief already meets the recovery criterion and the run converges at t_0; None when the run
        never converges.
    """
    tt = a.t
    ok = within_recovery(a)
    t_s = first_hold(tt, ok, float(tt[0]))
    if t_s is None:
        return None
    k = int(np.searchsorted(tt, t_s - _T_EPS))
    start = Aligned(tt[:1], a.rows[:1], np.asarray(initial, dtype=np.float64)[None, :], a.truth[:1])
    if k == 0 and bool(within_recovery(start)[0]):
        return 0.0
    upd = np.asarray(is_update, dtype=bool)
    return float(np.count_nonzero(upd[: int(a.rows[k]) + 1]))


def smoothed_metrics(extra: Mapping[str, np.ndarray], a: Aligned) -> dict[str, float]:
    """ATE and heading RMSE of a smoothed trajectory stored in a run's ``extra``, if there is one.

    Parameters
    ----------
    extra : mapping
        The run's filter-specific arrays; uses ``smoothed_t`` (n,), s, and ``smoothed_mean`` (n, 3),
        world frame.
    a : Aligned
        The run at the ground-truth times: its times and truth (the smoothed poses are held there).

    Returns
    -------
    dict of str to float
        ``smoothed_ate_m`` and ``smoothed_heading_rmse_rad``; empty when the run has no smoothed
        trajectory or an empty one.

    Raises
    ------
    ValueError
        When only one of the two arrays is present or their shapes do not match.
    """
    has_t, has_m = "smoothed_t" in extra, "smoothed_mean" in extra
    if not (has_t or has_m):
        return {}
    if not (has_t and has_m):
        raise ValueError("a run's extra must hold both 'smoothed_t' (n,) and 'smoothed_mean' (n, 3), or neither")
    st = np.asarray(extra["smoothed_t"], dtype=np.float64)
    sm = np.asarray(extra["smoothed_mean"], dtype=np.float64)
    if st.ndim != 1 or sm.shape != (st.shape[0], 3):
        raise ValueError(
            f"smoothed trajectory: expected 'smoothed_t' (n,) and 'smoothed_mean' (n, 3), got {st.shape} and {sm.shape}"
        )
    if st.shape[0] == 0:
        return {}
    if np.any(np.diff(st) < 0):
        raise ValueError("smoothed trajectory: 'smoothed_t' must be non-decreasing")
    smoothed = align(st, sm, a.t, a.truth)
    return {SMOOTHED_ATE_M: ate(smoothed), SMOOTHED_HEADING_RMSE_RAD: heading_rmse(smoothed)}


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


#: The runtime metrics of :func:`run_metrics` with a twin in reference units (``<id>_ref``, :func:`reference_units`).
REFERENCE_TIMES = (PREDICT_US_MEAN, PREDICT_US_MEDIAN, PREDICT_US_P95, UPDATE_US_MEAN, UPDATE_US_MEDIAN, UPDATE_US_P95)


def reference_units(
    metrics: Mapping[str, float], reference_s: float, reference_cpu_s: float | None = None
) -> dict[str, float]:
    """The runtime metrics of one run in reference units, from its raw ones and the reference workload's times.

    A time in reference units is the raw time over the reference workload's time on the same machine under the
    same load (:mod:`locbench.run.reference_workload`): what it would be on a machine whose reference workload takes
    1 s. So ``<call>_us_<stat>_ref`` = ``<call>_us_<stat>`` / reference (us on that machine) and
    ``realtime_factor_ref`` = ``realtime_factor`` * ``reference_s`` (its real-time factor there). Totals (the
    real-time factor, the mean and p95 per call) take the wall time ``reference_s``, which holds the turns other
    processes took, as the totals do; the per-call medians take the CPU time ``reference_cpu_s`` when given: a
    call of microseconds is rarely interrupted, so its median hardly moves with the load (docs/history/performance.md).

    Parameters
    ----------
    metrics : mapping of str to float
        A run's metrics (:func:`run_metrics`); the runtime ones present are converted.
    reference_s, reference_cpu_s : float
        The reference workload's wall and CPU time, s; > 0 and finite (``reference_cpu_s`` None: ``reference_s``).
    """
    cpu_s = reference_s if reference_cpu_s is None else reference_cpu_s
    for name, value in (("reference_s", reference_s), ("reference_cpu_s", cpu_s)):
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a positive finite time in s, got {value!r}")
    out = {
        f"{k}{REF_SUFFIX}": metrics[k] / (cpu_s if k.endswith("_median") else reference_s)
        for k in REFERENCE_TIMES
        if k in metrics
    }
    if REALTIME_FACTOR in metrics:
        out[REALTIME_FACTOR_REF] = metrics[REALTIME_FACTOR] * reference_s
    return out


def _positive(x: object) -> float | None:
    """``x`` as a float when it is a positive finite number (not a bool), else None."""
    if isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x) and x > 0:
        return float(x)
    return None


def relation_errors(
    t_est: npt.ArrayLike, mean: npt.ArrayLike, t1: npt.ArrayLike, t2: npt.ArrayLike, delta_ref: npt.ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Per-relation translational and rotational errors (Kuemmerle et al. 2009, eq. 1-2).

    Parameters
    ----------
    t_est : array-like, shape (n,)
        Times of the stored estimates, s.
    mean : array-like, shape (n, 3)
        Estimated poses (x m, y m, theta rad), world frame.
    t1, t2 : array-like, shape (m,)
        Times of the two poses of each relation, s.
    delta_ref : array-like, shape (m, 3)
        Reference pose of t2 in the frame of the pose at t1 (dx m, dy m, dtheta rad).

    Returns
    -------
    trans, rot : ndarray, shape (k,)
        |e_xy| (m) and |wrap(e_theta)| (rad) of e = delta_ref^-1 (+) delta_est, for the k relations whose
        two times lie inside [t_est[0], t_est[-1]].
    """
    t = np.asarray(t_est, dtype=np.float64)
    a = np.asarray(t1, dtype=np.float64)
    b = np.asarray(t2, dtype=np.float64)
    ref = np.asarray(delta_ref, dtype=np.float64).reshape(-1, 3)
    inside = (a >= t[0] - _T_EPS) & (b >= t[0] - _T_EPS) & (a <= t[-1] + _T_EPS) & (b <= t[-1] + _T_EPS)
    m = np.asarray(mean, dtype=np.float64)
    est = between(estimate_at(t, m, a[inside]), estimate_at(t, m, b[inside]))
    e = between(ref[inside], est)
    return np.hypot(e[:, 0], e[:, 1]), np.abs(wrap_angle(e[:, 2]))


# --- one run ------------------------------------------------------------------------------------


def run_metrics(
    run: RunRecord, truth: TruthRecord, rpe_delta_m: float = RPE_DELTA_M, aligned: Aligned | None = None
) -> dict[str, float]:
    """Every declared metric (:data:`METRICS`) of one stored run, keyed by its metric id.

    Parameters
    ----------
    run : RunRecord
        The stored run.
    truth : TruthRecord
        The ground truth of the same dataset and seed.
    rpe_delta_m : float
        Travelled distance of the RPE pairs, m (``rpe_m_per_m`` is defined with the default 1 m).
    aligned : Aligned, optional
        ``align_run(run, truth)`` when the caller has it already (the report keeps its NEES series); made
        here otherwise.

    Returns
    -------
    dict of str to float
        For a run with status "skipped": empty. For any other status except "ok": ``{"failed": 1}``.
        For an ok run: ``failed`` = 0 and the value of every declared metric that is defined for it, in
        declaration order. The built-in ones: ``waypoint_<j>_error_m``, ``waypoint_<j>_est_x_m``,
        ``waypoint_<j>_est_y_m``, ``waypoint_<j>_marked_x_m``, ``waypoint_<j>_marked_y_m`` (j from 1,
        when the dataset has waypoints), ``ate_m``, ``heading_rmse_rad``, ``rpe_m_per_m``,
        ``final_error_m``, ``within_<k>cm_fraction`` (:func:`within_fractions`), ``anees``,
        ``nees_in_band_fraction`` (single-run two-sided 95 % chi-square(3) band), ``nll`` (mean over the
        truth times of :func:`nll`, +inf if any is),
        ``predict_us_{mean,median,p95}``, ``update_us_{mean,median,p95}``,
        ``realtime_factor``, the same in reference units (``<id>_ref``, :func:`reference_units`) when the run's
        meta has ``reference_s`` (and ``reference_cpu_s``), ``converged`` and ``time_to_converge_s``; with kidnaps
        in the truth
        ``kidnap_distance_m``, ``kidnap_recovered``, ``kidnap_time_to_recover_s`` and
        ``kidnap_false_confidence_fraction`` (first kidnap); with a smoothed trajectory in
        ``run.extra`` ``smoothed_ate_m`` and ``smoothed_heading_rmse_rad``; with reference relations in the
        truth ``relation_error_m``, ``relation_error_rad`` and ``relation_count``. Undefined values are left out.
    """
    status = run.status
    if status == "skipped":
        return {}
    if status != "ok":
        return {FAILED: 1.0}
    if run.t.shape[0] == 0:
        raise ValueError("an ok run has no estimates")
    view = RunView(run, truth, aligned if aligned is not None else align_run(run, truth), rpe_delta_m)
    out: dict[str, float] = {}
    for metric in METRICS.values():
        try:
            out.update(metric.values(view))
        except NoCovariance:
            continue  # a consistency metric of a run without covariance does not apply: left out
    return {k: v for k, v in out.items() if not np.isnan(v)}


def particle_count_metrics(diagnostics: dict[str, FloatArray]) -> dict[str, float]:
    """``particles_mean``: the mean particle count over a run's steps, from the ``particles`` diagnostic.

    Only filters that report a count (the particle filter; with ``adaptive=kld`` it varies) have it; rows
    without a count (NaN) are ignored.
    """
    count = diagnostics.get("particles")
    if count is None:
        return {}
    c = np.asarray(count, dtype=np.float64)
    c = c[np.isfinite(c)]
    return {PARTICLES_MEAN: float(np.mean(c))} if c.size else {}


def acceptance_metrics(diagnostics: dict[str, FloatArray]) -> dict[str, float]:
    """``accepted_fraction``: measurements a filter fused over those it was offered, over the whole run.

    Read from the per-step ``accepted`` and ``rejected`` diagnostics (counts per update; NaN or 0 on
    predict rows, so summing every row is right). Left out when a filter reports neither or was offered
    nothing. For ``ekf_lines`` it is the fraction of extracted lines that passed the gate (report 002).
    """
    acc, rej = diagnostics.get("accepted"), diagnostics.get("rejected")
    if acc is None or rej is None:
        return {}
    total = float(np.nansum(acc) + np.nansum(rej))
    return {ACCEPTED_FRACTION: float(np.nansum(acc)) / total} if total > 0 else {}


# --- declarations: a metric is one record --------------------------------------------------------------------------

#: The tables of docs/protocols.md a metric is listed in (one generated table each), in the page's order.
GROUPS = ("run", "accuracy", "consistency", "scores", "runtime", "recovery", "filter", "over runs")
#: Which way a metric is better: lower, higher, closer to its target (in ratio), or neither (not ranked).
BETTER = ("lower", "higher", "closer", "")
#: What a summary cell without a value shows: the value is undefined ("n/a") or does not apply ("-").
ABSENT = ("n/a", "-")

#: A function that gives the values of several metric ids of one run at once (the kidnap metrics, the waypoints).
Family = Callable[["RunView"], Mapping[str, float]]


@dataclass(eq=False)
class RunView:
    """One ok run as a metric reads it: the stored run, its truth and the run held at the ground-truth times.

    Attributes
    ----------
    run : RunRecord
        The stored run (estimates, covariances, step kinds and times, diagnostics, ``extra``, meta).
    truth : TruthRecord
        The ground truth of its dataset and seed (trajectory, waypoints, kidnaps, relations, duration).
    aligned : Aligned
        The run's means and covariances held at the truth's ground-truth times (:func:`align_run`).
    rpe_delta_m : float
        Travelled distance of the RPE pairs, m.
    """

    run: RunRecord
    truth: TruthRecord
    aligned: Aligned
    rpe_delta_m: float = RPE_DELTA_M
    _families: dict[Family, Mapping[str, float]] = field(default_factory=dict, repr=False)

    def shared(self, family: Family) -> Mapping[str, float]:
        """``family(self)``, computed once per run however many metrics read it."""
        if family not in self._families:
            self._families[family] = family(self)
        return self._families[family]


@dataclass(frozen=True)
class Metric:
    """One metric, declared once: its id, how one run's value is computed and how the report shows it.

    A metric with ``compute`` or ``family`` is a row of ``metrics.parquet`` for every ok run that defines it; one with
    neither is a statistic over runs that the report computes (its declaration holds how it is shown).

    Attributes
    ----------
    id : str
        The id in ``metrics.parquet``; it never changes meaning. An id with ``<name>`` parts (``waypoint_<j>_error_m``)
        declares a family of ids (:func:`member_id`; a one-letter part is a number), whose values a ``family``
        function gives.
    header : str
        The report's name of it (``ATE``).
    unit : str
        The unit of its value in ``metrics.parquet``: SI (``m``, ``rad``, ``s``), ``us`` for call times, ``1`` for a
        fraction or a 1/0 flag, ``x`` for a ratio, ``""`` for a dimensionless score.
    display_unit : str
        The unit the report shows it in (``cm``); ``""`` none.
    scale : float
        The factor from its value to the shown one (100 from m to cm, degrees(1) from rad to deg).
    better : str
        One of :data:`BETTER`: "lower", "higher", "closer" (to ``target``, in ratio) or "" (not ranked).
    target : float
        The best value of a "closer" metric (the ANEES: :data:`POSE_DOF`).
    definition : str
        Its line in the table of docs/protocols.md (generated from the declarations).
    group : str
        The table it is listed in (:data:`GROUPS`; "" for none, a metric declared outside this module).
    compute : callable or None
        ``compute(view)``: the value of one ok run (:class:`RunView`), NaN when undefined (left out).
    family : callable or None
        ``family(view)``: the values of several ids of one run, computed once and shared by the metrics that name it
        (:meth:`RunView.shared`); the metric takes its own id's value, or every id of its pattern.
    summary : bool
        The report's summary table shows it: a column per metric, in declaration order, the mean over seeds in the
        display unit, ranked by a paired test (the report's own cell for the metrics it computes over runs).
    note : str
        The summary table's footnote for its column ("" none).
    absent : str
        A summary cell without a value (:data:`ABSENT`): "n/a" (undefined) or "-" (does not apply: a filter
        without update calls has no update time).
    bound : bool
        The accuracy bound (:mod:`locbench.evaluate.pcrb`) gives it too: the summary shows the bound's value.
    """

    id: str
    header: str
    unit: str
    display_unit: str = ""
    scale: float = 1.0
    better: str = "lower"
    target: float = float("nan")
    definition: str = ""
    group: str = ""
    compute: Callable[[RunView], float] | None = None
    family: Family | None = None
    summary: bool = False
    note: str = ""
    absent: str = "n/a"
    bound: bool = False

    def __post_init__(self) -> None:
        problems = []
        if not re.fullmatch(r"[a-z0-9_]+", _PLACEHOLDER.sub("x", self.id)):
            problems.append("an id is lower-case letters, digits and '_' (and <name> parts)")
        if self.better not in BETTER:
            problems.append(f"better must be one of {BETTER}")
        if self.better == "closer" and not np.isfinite(self.target):
            problems.append("a metric closest to a target needs a finite target")
        if self.group and self.group not in GROUPS:
            problems.append(f"group must be one of {GROUPS} or ''")
        if self.absent not in ABSENT:
            problems.append(f"absent must be one of {ABSENT}")
        if self.compute is not None and self.family is not None:
            problems.append("it is computed by compute or by a family, not both")
        if self.is_family and self.compute is not None:
            problems.append("a family of ids takes its values from a family function, not compute")
        if self.is_family and self.summary:
            problems.append("the summary shows one id's mean, not a family's")
        if problems:
            raise ValueError(f"metric {self.id!r}: " + "; ".join(problems))

    @property
    def is_family(self) -> bool:
        """The id names a family of ids (it has ``<name>`` parts)."""
        return _is_family_id(self.id)

    @property
    def per_run(self) -> bool:
        """A row of ``metrics.parquet`` (computed from each run), not a statistic over runs."""
        return self.compute is not None or self.family is not None

    def matches(self, metric_id: str) -> bool:
        """Whether ``metric_id`` is this metric's id or, for a family, one of its members."""
        return metric_id == self.id or (self.is_family and _is_member(self.id, metric_id))

    def values(self, view: RunView) -> dict[str, float]:
        """This metric's values of one ok run, by id (empty when it is not computed from runs or has none)."""
        if self.compute is not None:
            return {self.id: float(self.compute(view))}
        if self.family is None:
            return {}
        got = view.shared(self.family)
        return {k: float(v) for k, v in got.items() if self.matches(k)}


@functools.cache
def _pattern(family: str) -> re.Pattern[str]:
    return re.compile(family_regex(family))


# every run asks these of the same few ids: answered once per id (a report asks them millions of times)
@functools.cache
def _is_family_id(metric_id: str) -> bool:
    """Whether a declared id has ``<name>`` parts."""
    return bool(_PLACEHOLDER.search(metric_id))


@functools.cache
def _is_member(family: str, metric_id: str) -> bool:
    """Whether ``metric_id`` is a member of the family of ids ``family``."""
    return _pattern(family).fullmatch(metric_id) is not None


def family_regex(family: str) -> str:
    """The regular expression (for a full match) of a family's member ids: a one-letter part (``<j>``) stands for
    a number, a longer one (``<score>``) for a part of an id (letters, digits, ``_``)."""
    out = re.escape(family)
    for name in _PLACEHOLDER.findall(family):
        out = out.replace(re.escape(name), r"(\d+)" if len(name) == 3 else "([a-z0-9_]+)", 1)
    return out


#: Every declared metric by id, in declaration order (the order of the summary's metric columns and of the docs'
#: tables). Add one with :func:`declare`.
METRICS: dict[str, Metric] = {}


def declare(metric: Metric) -> Metric:
    """Declare a metric: from then on :func:`run_metrics` computes it for every ok run (``metrics.parquet``), and with
    ``summary=True`` the report's summary table shows it.

    Raises
    ------
    ValueError
        When its id, or a member of its family, is declared already: an id never changes meaning.
    """
    clash = [m.id for m in METRICS.values() if m.matches(metric.id) or metric.matches(m.id)]
    if clash:
        raise ValueError(f"metric {metric.id!r} is declared already ({clash[0]!r}); an id never changes meaning")
    METRICS[metric.id] = metric
    return metric


def declared(metric_id: str) -> Metric:
    """The declaration of a metric id: its own or its family's (``waypoint_3_error_m``: ``waypoint_<j>_error_m``).

    Raises
    ------
    KeyError
        For an id nothing declares.
    """
    m = METRICS.get(metric_id)
    if m is not None:
        return m
    for m in METRICS.values():
        if m.is_family and m.matches(metric_id):
            return m
    raise KeyError(f"no metric declares the id {metric_id!r}")


# the families of the built-in metrics: each is computed once per run


def _waypoint_point(metric_id: str, header: str, definition: str) -> Metric:
    """The record of one coordinate (m, world frame) of a waypoint's estimated or marked point: shown in cm, no
    better direction, in the waypoint family."""
    return Metric(
        metric_id,
        header=header,
        **_IN_CM,
        better="",
        group="accuracy",
        family=_waypoints,
        definition=definition,
    )


def _waypoints(v: RunView) -> dict[str, float]:
    wp = v.truth.waypoints
    if wp is None or not len(wp):
        return {}
    err, est_xy = waypoint_errors(v.run.t, v.run.mean, wp.t, wp.xy)
    out: dict[str, float] = {}
    for j in range(err.shape[0]):
        out[member_id(WAYPOINT_ERROR_M, j + 1)] = float(err[j])
        out[member_id(WAYPOINT_EST_X_M, j + 1)] = float(est_xy[j, 0])
        out[member_id(WAYPOINT_EST_Y_M, j + 1)] = float(est_xy[j, 1])
        # The marked point itself, so that the distance of the mean estimate needs only the CSV.
        out[member_id(WAYPOINT_MARKED_X_M, j + 1)] = float(wp.xy[j, 0])
        out[member_id(WAYPOINT_MARKED_Y_M, j + 1)] = float(wp.xy[j, 1])
    return out


def _within(v: RunView) -> dict[str, float]:
    return within_fractions(v.aligned)


def _smoothed(v: RunView) -> dict[str, float]:
    return smoothed_metrics(v.run.extra, v.aligned)


def _relations(v: RunView) -> dict[str, float]:
    rel = v.truth.relations
    if rel is None or not len(rel):
        return {}
    trans, rot = relation_errors(v.run.t, v.run.mean, rel.t1, rel.t2, rel.delta)
    out = {RELATION_COUNT: float(trans.shape[0])}
    if trans.shape[0]:
        out[RELATION_ERROR_M] = float(np.mean(trans))
        out[RELATION_ERROR_RAD] = float(np.mean(rot))
    return out


def _scores(v: RunView) -> dict[str, float]:
    return score_metrics(v.aligned, v.run.extra)


#: The runtime ids of each timed call, in the order of :func:`runtime_stats`' statistics.
_CALL_TIMES = {
    "predict": {"mean": PREDICT_US_MEAN, "median": PREDICT_US_MEDIAN, "p95": PREDICT_US_P95},
    "update": {"mean": UPDATE_US_MEAN, "median": UPDATE_US_MEDIAN, "p95": UPDATE_US_P95},
}


def _runtime(v: RunView) -> dict[str, float]:
    if v.run.meta.get("runtime_measured", True) is False:
        return {}  # an imported run: the system's call times are not known
    out = {
        ids[stat]: value
        for call, ids in _CALL_TIMES.items()
        for stat, value in runtime_stats(v.run.step_times_us(call)).items()
    }
    out[REALTIME_FACTOR] = realtime_factor(v.truth.duration_s, v.run.step_ns)
    return out


def _latency(v: RunView) -> dict[str, float]:
    """Median and 95th percentile of the per-estimate latency, s: record time minus header stamp of an imported
    bag's messages (none for a built-in filter or a run without both times)."""
    lat = v.run.diagnostics.get(LATENCY_DIAGNOSTIC)
    if lat is None:
        return {}
    stats = runtime_stats(np.asarray(lat, dtype=np.float64)[np.isfinite(lat)])
    return {LATENCY_S_MEDIAN: stats["median"], LATENCY_S_P95: stats["p95"]} if stats else {}


def _reference(v: RunView) -> dict[str, float]:
    ref, ref_cpu = (_positive(v.run.meta.get(k)) for k in ("reference_s", "reference_cpu_s"))
    if ref is None:  # runs stored before reference_s was recorded have none
        return {}
    return reference_units(v.shared(_runtime), ref, ref_cpu)


def _convergence(v: RunView) -> dict[str, float]:
    return convergence_metrics(v.aligned)


def _updates_to_converge(v: RunView) -> float:
    non_update = (KIND_NAMES.index("Odometry"), KIND_NAMES.index("reset"))
    got = updates_to_converge(v.aligned, ~np.isin(v.run.kind, non_update), v.run.mean[0])
    return float("nan") if got is None else got


def _kidnap(v: RunView) -> dict[str, float]:
    return kidnap_metrics(v.aligned, v.truth.kidnaps)


def _acceptance(v: RunView) -> dict[str, float]:
    return acceptance_metrics(v.run.diagnostics)


def _particles(v: RunView) -> dict[str, float]:
    return particle_count_metrics(v.run.diagnostics)


_CM = 100.0
_DEG = float(np.degrees(1.0))
_PERCENT = 100.0
_MS = 1000.0


class _Shown(TypedDict):
    """How a metric's stored unit is shown: the unit, the report's unit and the factor between them."""

    unit: str
    display_unit: str
    scale: float


#: The common displays: a length stored in m shown in cm, an angle in rad shown in degrees, a fraction stored as
#: 1 shown in %.
_IN_CM = _Shown(unit="m", display_unit="cm", scale=_CM)
_IN_DEG = _Shown(unit="rad", display_unit="deg", scale=_DEG)
_AS_PERCENT = _Shown(unit="1", display_unit="%", scale=_PERCENT)
_LATENCY_NOTE = (
    "Latency: median over an imported system's estimates of the bag's record time minus the header stamp (when it "
    "published the estimate after the data it is for); built-in filters have call times instead."
)

# The built-in metrics. Their order is the order of the summary's metric columns (those with summary=True) and of the
# rows of each docs table.
for _m in (
    Metric(
        FAILED,
        header="failed",
        unit="1",
        better="",
        group="run",
        compute=lambda v: 0.0,
        definition="1 for a run that failed or diverged (its only row), 0 for an ok run",
    ),
    Metric(
        ATE_M,
        header="ATE",
        **_IN_CM,
        group="accuracy",
        compute=lambda v: ate(v.aligned),
        summary=True,
        bound=True,
        definition="position RMSE over every ground-truth time",
    ),
    Metric(
        ATE_OVER_PCRB,
        header="ATE / PCRB",
        unit="x",
        display_unit="x",
        group="over runs",
        summary=True,
        definition="sqrt(mean over seeds of `ate_m`^2) over the bound's on the same seeds "
        "(`locbench.evaluate.aggregate.ate_over_pcrb`; 1 = as accurate as any estimator can be)",
    ),
    Metric(
        WAYPOINT_ERROR_M,
        header="waypoint error",
        **_IN_CM,
        group="accuracy",
        family=_waypoints,
        bound=True,
        definition="e_ij = |p_hat_i(t_j) - p_j| against the marked point of waypoint j (j from 1)",
    ),
    _waypoint_point(
        WAYPOINT_EST_X_M,
        "estimated x at the waypoint",
        "x of the estimated position at waypoint j's time (world frame)",
    ),
    _waypoint_point(WAYPOINT_EST_Y_M, "estimated y at the waypoint", "y of the same"),
    _waypoint_point(
        WAYPOINT_MARKED_X_M,
        "marked x of the waypoint",
        "x of waypoint j's marked point (so the mean estimate's distance needs only `metrics.parquet`)",
    ),
    _waypoint_point(WAYPOINT_MARKED_Y_M, "marked y of the waypoint", "y of the same"),
    Metric(
        WAYPOINT_RMSE_MEAN_M,
        header="mean waypoint RMSE",
        **_IN_CM,
        group="over runs",
        summary=True,
        definition="the mean over the waypoints of RMSE_j = sqrt(mean over runs of e_ij^2); "
        "its paired test takes each run's mean of `waypoint_<j>_error_m`",
    ),
    Metric(
        SMOOTHED_ATE_M,
        header="smoothed ATE",
        **_IN_CM,
        group="accuracy",
        family=_smoothed,
        definition="the ATE of a smoother's lag-smoothed trajectory (gtsam's fixed-lag smoother)",
    ),
    Metric(
        SMOOTHED_HEADING_RMSE_RAD,
        header="smoothed heading RMSE",
        **_IN_DEG,
        group="accuracy",
        family=_smoothed,
        definition="the heading RMSE of the same smoothed trajectory",
    ),
    Metric(
        HEADING_RMSE_RAD,
        header="heading RMSE",
        **_IN_DEG,
        group="accuracy",
        summary=True,
        bound=True,
        compute=lambda v: heading_rmse(v.aligned),
        definition="RMSE of the wrapped heading error",
    ),
    Metric(
        RPE_M_PER_M,
        header="RPE",
        unit="m/m",
        display_unit="%",
        scale=_PERCENT,
        group="accuracy",
        compute=lambda v: rpe_per_metre(v.aligned, v.rpe_delta_m),
        definition="mean translational error of the relative motion over 1 m of travelled path, divided by "
        "that distance",
    ),
    Metric(
        FINAL_ERROR_M,
        header="final error",
        **_IN_CM,
        group="accuracy",
        compute=lambda v: final_error(v.aligned),
        definition="position error at the last ground-truth time",
    ),
    Metric(
        WITHIN_FRACTION,
        header="within k cm",
        **_AS_PERCENT,
        better="higher",
        group="accuracy",
        family=_within,
        definition="the fraction of ground-truth times whose position error is at most k cm, k = 5, 10, 25, 50 "
        "(accuracy at thresholds)",
    ),
    Metric(
        RELATION_ERROR_M,
        header="relation error",
        **_IN_CM,
        group="accuracy",
        family=_relations,
        definition="mean translational relation error over reference relative poses (Kuemmerle et al. 2009, "
        "eq. 1-2), for datasets whose trajectory is a SLAM reference",
    ),
    Metric(
        RELATION_ERROR_RAD,
        header="relation error",
        **_IN_DEG,
        group="accuracy",
        family=_relations,
        definition="mean rotational relation error over the same relations",
    ),
    Metric(
        RELATION_COUNT,
        header="relations",
        unit="1",
        better="",
        group="accuracy",
        family=_relations,
        definition="how many reference relations have both times within the run",
    ),
    Metric(
        ANEES,
        header="ANEES",
        unit="",
        better="closer",
        target=float(POSE_DOF),
        group="consistency",
        summary=True,
        compute=lambda v: anees(v.aligned.nees),
        definition="mean NEES over a run's ground-truth times (3 for a consistent filter)",
    ),
    Metric(
        NEES_IN_BAND_FRACTION,
        header="NEES in 95 % band",
        **_AS_PERCENT,
        better="higher",
        group="consistency",
        compute=lambda v: fraction_in_band(v.aligned.nees, chi2_band(POSE_DOF, 1)),
        definition="fraction of ground-truth times whose NEES lies in the single-run two-sided 95 % chi-square(3) "
        "band [0.216, 9.35]",
    ),
    # +inf when any time's covariance is singular, as the ANEES
    Metric(
        NLL,
        header="NLL",
        unit="",
        group="consistency",
        compute=lambda v: float(np.mean(nll_at_truth(v.aligned))),
        definition="mean over the ground-truth times of 0.5 (e' P^-1 e + log det(2 pi P)), +inf when a "
        "covariance is singular",
    ),
    Metric(
        CRPS_X_M,
        header="CRPS x",
        **_IN_CM,
        group="scores",
        family=_scores,
        definition="mean over the ground-truth times of the CRPS of the belief's x marginal at the true x",
    ),
    Metric(CRPS_Y_M, "CRPS y", "m", "cm", _CM, group="scores", family=_scores, definition="the same for y"),
    Metric(
        CRPS_HEADING_RAD,
        header="CRPS heading",
        **_IN_DEG,
        group="scores",
        family=_scores,
        definition="the same for the heading, each belief's heading unwrapped onto the branch nearest the true "
        "heading (error wrapped to (-pi, pi], scored at 0)",
    ),
    Metric(
        ENERGY_SCORE_M,
        header="energy score",
        **_IN_CM,
        group="scores",
        family=_scores,
        summary=True,
        note="Energy score: proper score of the filter's own position belief, mean over the ground-truth times "
        "(lower is better).",
        definition="mean over the ground-truth times of the energy score of the belief's position (x, y) at "
        "the true position",
    ),
    Metric(
        SCORE_CI_LOW,
        header="interval low",
        unit="as the score",
        better="",
        group="scores",
        family=_scores,
        definition="the lower end of the 95 % block-bootstrap interval of each score's mean (`crps_x_ci_low_m`, "
        "`energy_score_ci_low_m`, ...)",
    ),
    Metric(
        SCORE_CI_HIGH,
        header="interval high",
        unit="as the score",
        better="",
        group="scores",
        family=_scores,
        definition="its upper end (`crps_x_ci_high_m`, ...)",
    ),
    Metric(
        LOST_AUROC,
        header="lost AUROC",
        unit="",
        better="higher",
        group="over runs",
        summary=True,
        definition="AUROC of a configuration's best health signal for the times its position error exceeds "
        "0.25 m, over its runs (below)",
    ),
    Metric(
        PREDICT_US_MEAN,
        header="predict mean",
        unit="us",
        display_unit="us",
        group="runtime",
        family=_runtime,
        definition="mean time of a predict call",
    ),
    Metric(
        PREDICT_US_MEDIAN,
        header="predict median",
        unit="us",
        display_unit="us",
        group="runtime",
        family=_runtime,
        definition="median time of a predict call",
    ),
    Metric(
        PREDICT_US_P95,
        header="predict p95",
        unit="us",
        display_unit="us",
        group="runtime",
        family=_runtime,
        definition="95th percentile of the time of a predict call",
    ),
    Metric(
        UPDATE_US_MEAN,
        header="update mean",
        unit="us",
        display_unit="us",
        group="runtime",
        family=_runtime,
        definition="mean time of an update call",
    ),
    Metric(
        UPDATE_US_MEDIAN,
        header="update median",
        unit="us",
        display_unit="us",
        group="runtime",
        family=_runtime,
        summary=True,
        absent="-",
        definition="median time of an update call (none without update calls)",
    ),
    Metric(
        UPDATE_US_P95,
        header="update p95",
        unit="us",
        display_unit="us",
        group="runtime",
        family=_runtime,
        definition="95th percentile of the time of an update call",
    ),
    Metric(
        REALTIME_FACTOR,
        header="real-time factor",
        unit="x",
        display_unit="x",
        better="higher",
        group="runtime",
        family=_runtime,
        summary=True,
        definition="dataset duration over the run's total compute time (higher is faster)",
    ),
    *(
        Metric(
            f"{raw}{REF_SUFFIX}",
            header=f"{call} {stat}",
            unit="ref us",
            display_unit="ref us",
            group="runtime",
            family=_reference,
            definition=f"`{raw}` over the run's " + ("`reference_cpu_s`" if stat == "median" else "`reference_s`"),
        )
        for call, ids in _CALL_TIMES.items()
        for stat, raw in ids.items()
    ),
    Metric(
        REALTIME_FACTOR_REF,
        header="real-time factor",
        unit="ref x",
        display_unit="ref x",
        better="higher",
        group="runtime",
        family=_reference,
        definition="`realtime_factor` x the run's `reference_s`",
    ),
    *(
        Metric(
            metric_id,
            header=f"latency {stat}",
            unit="s",
            display_unit="ms",
            scale=_MS,
            group="runtime",
            family=_latency,
            summary=stat == "median",  # the median is the summary's column; absent: a built-in filter's row
            absent="-",
            note=_LATENCY_NOTE if stat == "median" else "",
            definition=definition,
        )
        for stat, metric_id, definition in (
            (
                "median",
                LATENCY_S_MEDIAN,
                "median over the estimates of an imported bag's record (log) time minus header stamp (the system's "
                "delay; none for built-in filters or formats without both times)",
            ),
            ("p95", LATENCY_S_P95, "95th percentile of the same"),
        )
    ),
    Metric(
        KIDNAP_DISTANCE_M,
        header="kidnap distance",
        unit="m",
        display_unit="m",
        better="",
        group="recovery",
        family=_kidnap,
        definition="length of the first kidnap's jump",
    ),
    Metric(
        KIDNAP_RECOVERED,
        header="kidnap recovery",
        **_AS_PERCENT,
        better="higher",
        group="recovery",
        family=_kidnap,
        summary=True,
        definition="1 when the filter recovered from the first kidnap within 30 s of it, else 0",
    ),
    Metric(
        KIDNAP_TIME_TO_RECOVER_S,
        header="time to recover",
        unit="s",
        display_unit="s",
        group="recovery",
        family=_kidnap,
        definition="from the first kidnap to the start of the recovery (recovered runs only)",
    ),
    Metric(
        KIDNAP_FALSE_CONFIDENCE_FRACTION,
        header="false confidence",
        **_AS_PERCENT,
        group="recovery",
        family=_kidnap,
        definition="share of the time from the kidnap to the recovery (or the window's end) with the NEES above "
        "the 99.9 % chi-square(3) quantile",
    ),
    Metric(
        CONVERGED,
        header="convergence",
        **_AS_PERCENT,
        better="higher",
        group="recovery",
        family=_convergence,
        definition="1 when the recovery criterion holds from some ground-truth time on, else 0",
    ),
    Metric(
        TIME_TO_CONVERGE_S,
        header="time to converge",
        unit="s",
        display_unit="s",
        group="recovery",
        family=_convergence,
        definition="from the first ground-truth time to that time (converged runs only)",
    ),
    Metric(
        UPDATES_TO_CONVERGE,
        header="updates to converge",
        unit="1",
        group="recovery",
        compute=_updates_to_converge,
        definition="measurement updates made up to that time; 0 when the initial belief meets the criterion at the "
        "first ground-truth time (converged runs only)",
    ),
    Metric(
        ACCEPTED_FRACTION,
        header="accepted",
        **_AS_PERCENT,
        better="higher",
        group="filter",
        family=_acceptance,
        definition="measurements fused over measurements offered, over the run (gated landmark sightings, "
        "extracted lines, ICP matches)",
    ),
    Metric(
        PARTICLES_MEAN,
        header="mean particles",
        unit="1",
        better="",
        group="filter",
        family=_particles,
        definition="mean particle count over the run's steps (particle filters)",
    ),
    Metric(
        RECORDED_ATE_MEDIAN_M,
        header="recorded median ATE",
        **_IN_CM,
        group="over runs",
        summary=True,
        definition="median over the recorded datasets with independent ground truth of a configuration's mean "
        "ATE there; its paired test pairs the datasets",
    ),
):
    declare(_m)
del _m
