"""Does the filter know that it is lost? Lost-detection scores of health signals: pure functions (no I/O).

Definitions (docs/protocols.md "Does the filter know that it is lost?"):

- A filter is **lost** at a ground-truth time when its position error there exceeds a threshold,
  :data:`LOST_THRESHOLDS_M` (0.25 m, the recovery criterion's radius, and 0.5 m).
- A **health signal** (:meth:`locbench.filters.base.Filter.health`, stored per event) is read at the ground-truth
  times by the zero-order hold of every metric, a NaN row (a signal not defined at that step: the NIS after a
  predict) holding the signal's last defined value; times before its first value are left out. Each signal is
  oriented by its declared direction (:data:`locbench.filters.base.HEALTH_SIGNALS`: ``lost_when`` "low" is
  negated) so that a higher score should mean lost.
- **AUROC**: the probability that a lost time scores above a not-lost time (ties count one half; the
  Mann-Whitney statistic), over the pooled ground-truth times of a filter's runs on a dataset; 1 perfect, 0.5 no
  better than chance. Undefined (NaN) without both classes.
- **Precision at 95 % recall**: at the highest threshold that flags at least 95 % of the lost times, the share
  of flagged times that are lost.
- **Alarm threshold**: the (1 - :data:`FALSE_ALARM_RATE`) quantile of the oriented signal over every ground-truth
  time of the filter's runs on the same world without a kidnap (5 % of those times raise an alarm); the
  **detection delay** of a kidnapped run is the time from the first kidnap to the first ground-truth time at
  or after it whose oriented signal exceeds the threshold, searched over
  :data:`locbench.evaluate.metrics.KIDNAP_WINDOW_S`
  (none: no alarm).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import stats

from locbench.evaluate.metrics import KIDNAP_WINDOW_S, Aligned
from locbench.filters.base import HEALTH_SIGNALS

FloatArray = npt.NDArray[np.float64]

#: Position errors above which a filter counts as lost, m (the first is the one the tables lead with).
LOST_THRESHOLDS_M = (0.25, 0.5)
#: Recall at which the precision is reported.
RECALL = 0.95
#: Share of the ground-truth times of runs without a kidnap that may raise an alarm.
FALSE_ALARM_RATE = 0.05


def forward_fill(values: npt.ArrayLike) -> FloatArray:
    """Each NaN replaced by the last non-NaN value before it (leading NaNs stay NaN)."""
    v = np.asarray(values, dtype=np.float64)
    ok = ~np.isnan(v)
    idx = np.where(ok, np.arange(v.size), 0)
    np.maximum.accumulate(idx, out=idx)
    out = v[idx]
    out[: int(np.argmax(ok)) if ok.any() else v.size] = np.nan
    return out


def oriented(name: str, values: npt.ArrayLike) -> FloatArray:
    """A signal turned so that higher should mean lost (its :data:`HEALTH_SIGNALS` direction)."""
    v = np.asarray(values, dtype=np.float64)
    return -v if HEALTH_SIGNALS[name].lost_when == "low" else v


@dataclass(frozen=True)
class HealthSeries:
    """One run's position error and oriented health signals at the ground-truth times.

    Attributes
    ----------
    t : ndarray, shape (k,)
        Ground-truth times, s.
    error_m : ndarray, shape (k,)
        Position error, m (zero-order hold of the estimates).
    signals : dict of str to ndarray (k,)
        Oriented signals (higher should mean lost), NaN before a signal's first value.
    kidnap_t : float
        Time of the first kidnap, s, or NaN.
    """

    t: FloatArray
    error_m: FloatArray
    signals: dict[str, FloatArray]
    kidnap_t: float = float("nan")


def health_series(a: Aligned, health: Mapping[str, npt.ArrayLike], kidnap_t: float = float("nan")) -> HealthSeries:
    """The :class:`HealthSeries` of one run from its aligned view ``a`` (:func:`locbench.evaluate.metrics.align`): each
    stored signal is held at the ground-truth times by the view's rows (signals not in :data:`HEALTH_SIGNALS`
    are ignored)."""
    sig = {k: oriented(k, forward_fill(v)[a.rows]) for k, v in health.items() if k in HEALTH_SIGNALS}
    return HealthSeries(a.t, a.position_error, sig, kidnap_t)


def auroc(score: npt.ArrayLike, positive: npt.ArrayLike) -> float:
    """Area under the ROC curve of ``score`` for the boolean ``positive``, ties counted one half; NaN scores are
    left out; NaN without both classes."""
    s = np.asarray(score, dtype=np.float64)
    p = np.asarray(positive, dtype=bool)
    keep = ~np.isnan(s)
    return _auroc_of_ranks(stats.rankdata(s[keep]), p[keep])


def _auroc_of_ranks(ranks: FloatArray, p: npt.NDArray[np.bool_]) -> float:
    """:func:`auroc` from the scores' ranks (NaN scores already left out): one ranking serves every threshold."""
    n_pos, n_neg = int(p.sum()), int((~p).sum())
    if n_pos == 0 or n_neg == 0:
        return float("nan")
    return float((ranks[p].sum() - n_pos * (n_pos + 1) / 2.0) / (n_pos * n_neg))


def roc_curve(score: npt.ArrayLike, positive: npt.ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
    """False-positive rate, true-positive rate and threshold at every distinct score, from the highest down
    (flagged: score >= threshold); the curve starts at (0, 0). NaN scores are left out."""
    s = np.asarray(score, dtype=np.float64)
    p = np.asarray(positive, dtype=bool)
    keep = ~np.isnan(s)
    s, p = s[keep], p[keep]
    order = np.argsort(-s, kind="stable")
    s, p = s[order], p[order]
    last = np.r_[np.flatnonzero(np.diff(s) != 0), s.size - 1] if s.size else np.zeros(0, dtype=np.intp)
    tp = np.cumsum(p)[last].astype(np.float64)
    fp = np.cumsum(~p)[last].astype(np.float64)
    n_pos, n_neg = max(int(p.sum()), 1), max(int((~p).sum()), 1)
    return np.r_[0.0, fp / n_neg], np.r_[0.0, tp / n_pos], np.r_[np.inf, s[last]]


def precision_at_recall(score: npt.ArrayLike, positive: npt.ArrayLike, recall: float = RECALL) -> float:
    """Precision at the highest threshold whose recall is >= ``recall``; NaN without a positive."""
    p = np.asarray(positive, dtype=bool)[~np.isnan(np.asarray(score, dtype=np.float64))]
    if not p.any():
        return float("nan")
    fpr, tpr, _ = roc_curve(score, positive)
    k = int(np.argmax(tpr >= recall - 1e-12))
    tp = tpr[k] * p.sum()
    fp = fpr[k] * max(int((~p).sum()), 1)
    return float(tp / (tp + fp)) if tp + fp > 0 else float("nan")


def alarm_threshold(oriented_quiet: npt.ArrayLike, rate: float = FALSE_ALARM_RATE) -> float:
    """The threshold an oriented signal exceeds at ``rate`` of the times of runs without a kidnap (NaN if none)."""
    v = np.asarray(oriented_quiet, dtype=np.float64)
    v = v[~np.isnan(v)]
    return float(np.quantile(v, 1.0 - rate)) if v.size else float("nan")


def detection_delay(
    t: npt.ArrayLike,
    oriented_signal: npt.ArrayLike,
    threshold: float,
    kidnap_t: float,
    window_s: float = KIDNAP_WINDOW_S,
) -> float:
    """Time from the kidnap to the first time in [kidnap_t, kidnap_t + window_s] whose signal exceeds
    ``threshold``, s; NaN for no alarm (or no threshold)."""
    tt = np.asarray(t, dtype=np.float64)
    v = np.asarray(oriented_signal, dtype=np.float64)
    if not np.isfinite(threshold) or not np.isfinite(kidnap_t):
        return float("nan")
    inside = (tt >= kidnap_t) & (tt <= kidnap_t + window_s)
    with np.errstate(invalid="ignore"):
        hit = np.flatnonzero(inside & (v > threshold))
    return float(tt[hit[0]] - kidnap_t) if hit.size else float("nan")


@dataclass(frozen=True)
class SignalScore:
    """AUROC at each lost threshold and the precision at 95 % recall (first threshold) of one signal."""

    signal: str
    auroc: tuple[float, ...]
    precision: float
    lost_share: float


def _signal_score(name: str, v: FloatArray, lost: list[npt.NDArray[np.bool_]]) -> SignalScore:
    """One signal's :class:`SignalScore` from one stable sort of its values (NaN left out), which gives both its
    ranks (:func:`auroc` at every threshold) and its ROC curve (:func:`precision_at_recall`): the same numbers as
    those functions, bit for bit, since ranks are half-integers and the curve's counts integers, whatever the
    order they are summed in."""
    keep = ~np.isnan(v)
    order = np.argsort(v[keep], kind="stable")
    y = v[keep][order]
    first = np.flatnonzero(np.r_[True, y[:-1] != y[1:]]) if y.size else np.zeros(0, dtype=np.intp)
    counts = np.diff(first, append=y.size)
    # scipy.stats.rankdata's average ranks, in sorted order: a tie group's first ordinal rank plus half its spread
    ranks = np.repeat((first + 1).astype(np.float64) + (counts - 1) / 2.0, counts)
    flags = [lo[keep][order] for lo in lost]
    return SignalScore(
        name,
        tuple(_auroc_of_ranks(ranks, f) for f in flags),
        _precision_of_sorted(flags[0], first),
        float(np.mean(lost[0])),
    )


def _precision_of_sorted(p: npt.NDArray[np.bool_], first: npt.NDArray[np.intp], recall: float = RECALL) -> float:
    """:func:`precision_at_recall` of flags ``p`` in ascending order of their scores, whose tie groups start at
    ``first``: flagged at a group's value are that group and every one above it (:func:`roc_curve`'s counts)."""
    n_pos, n_neg = int(p.sum()), int((~p).sum())
    if n_pos == 0:
        return float("nan")
    pos_before = np.r_[0, np.cumsum(p)][first]
    neg_before = np.r_[0, np.cumsum(~p)][first]
    tpr = np.r_[0.0, (n_pos - pos_before)[::-1].astype(np.float64) / n_pos]
    fpr = np.r_[0.0, (n_neg - neg_before)[::-1].astype(np.float64) / max(n_neg, 1)]
    k = int(np.argmax(tpr >= recall - 1e-12))
    tp = tpr[k] * p.sum()
    fp = fpr[k] * max(n_neg, 1)
    return float(tp / (tp + fp)) if tp + fp > 0 else float("nan")


def score_signals(series: list[HealthSeries], thresholds: tuple[float, ...] = LOST_THRESHOLDS_M) -> list[SignalScore]:
    """Every signal's scores over the pooled times of ``series``, best first (AUROC at the first threshold)."""
    if not series:
        return []
    err = np.concatenate([s.error_m for s in series])
    names = sorted(set.intersection(*(set(s.signals) for s in series)))
    lost = [err > th for th in thresholds]
    out = [_signal_score(name, np.concatenate([s.signals[name] for s in series]), lost) for name in names]
    return sorted(out, key=lambda s: (-np.nan_to_num(s.auroc[0], nan=-1.0), s.signal))
