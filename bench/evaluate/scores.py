"""Proper scores of a filter's own belief against the truth: pure functions on arrays (no I/O).

A proper scoring rule is minimised in expectation only by the distribution the truth is drawn from, so unlike
the ANEES (which asks only whether a Gaussian's spread matches the error) it rewards a belief that is both
sharp and right, and it scores a particle filter by its particles rather than by a Gaussian it does not use.
Definitions (docs/protocols.md "Proper scores"; Gneiting & Raftery 2007, "Strictly proper scoring rules,
prediction, and estimation", JASA 102(477), eq. 20-22):

- **CRPS** of a scalar belief F at the truth y: E|X - y| - 0.5 E|X - X'| with X, X' independent draws of F
  (the unit of y). A Gaussian N(mu, sigma^2) has the closed form sigma [z (2 Phi(z) - 1) + 2 phi(z) - 1/sqrt(pi)],
  z = (y - mu) / sigma. A point mass scores its absolute error.
- **A sample of the belief** (x_i, w_i), i = 1..M, weights normalised, is scored by the *fair* estimator
  (Ferro 2014, "Fair scores for ensemble forecasts", QJRMS 140, with weights):
  sum_i w_i |x_i - y| - 0.5 sum_{i != j} w_i w_j |x_i - x_j| / (1 - sum_i w_i^2). Derivation: with the weights
  fixed and the members independent draws of F, E|X_i - X_j| = E|X - X'| for every i != j, so the expectation of
  the pair sum is E|X - X'| sum_{i != j} w_i w_j = E|X - X'| (1 - sum_i w_i^2); dividing by that makes the spread
  term, and so the score, unbiased for F's score at any M (the first term is unbiased as it stands). Equal
  weights 1/M give the familiar 1 / (M (M - 1)). The plain form (spread over 1 instead, the exact score of the
  discrete belief sum_i w_i delta_{x_i}) is high by E|X - X'| sum_i w_i^2 / 2 in expectation: a 64-member
  sample of a wide belief is scored worse than the belief it was drawn from. A sample whose weight is all on one
  member (sum w_i^2 = 1: M = 1 included) has no pair to estimate the spread from and is scored as a point mass.
- **Heading**: each belief's heading is unwrapped onto the branch nearest the true heading (the error
  wrap(theta - theta_true) in (-pi, pi]) and scored against 0; a Gaussian's mean error is wrapped the same way.
- **Energy score** of a belief on the position (x, y) at the truth y: E||X - y|| - 0.5 E||X - X'|| (m). For a
  Gaussian the second term is closed form, sqrt(lambda_1 / pi) E(1 - lambda_2 / lambda_1) with lambda_1 >=
  lambda_2 the eigenvalues of the position covariance and E the complete elliptic integral of the second kind;
  the first term has none and is a quasi-Monte Carlo mean over :data:`ENERGY_DRAWS` fixed scrambled-Sobol normal
  draws (seed :data:`ENERGY_SEED`), the same draws at every time, so the score is deterministic. A point mass
  scores its Euclidean error exactly; a sample, the fair estimator above with the norm for |.|.
- Scores are taken at every ground-truth time with the belief in force there (the run's aligned view,
  :func:`locbench.evaluate.aligned.align`, as every metric in :mod:`locbench.evaluate.metrics`), then averaged;
  the interval of that mean is a circular block bootstrap over time (:func:`block_bootstrap_ci`) with blocks of
  :data:`BLOCK_S` seconds of ground truth.
- A particle filter exposes a sample of its particles of the size the run sets (:meth:`Filter.belief_sample`;
  :data:`locbench.filters.base.SCORE_SAMPLE_SIZE` members by default, a run setting that enters the run key);
  the runner scores it at each ground-truth time while the filter runs (:func:`sample_scores`, fair) and stores
  the per-time scores, not the samples (:data:`SAMPLE_SCORE_KEYS` in the run's ``extra``).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
from numba import njit
from scipy import special, stats

from locbench.core.geometry import wrap_angle
from locbench.core.pairwise import pairwise_sum
from locbench.evaluate.aligned import NoCovariance

if TYPE_CHECKING:
    from locbench.evaluate.aligned import Aligned

FloatArray = npt.NDArray[np.float64]

#: The four per-run score ids (``metrics.parquet``), each the mean over the ground-truth times.
SCORE_IDS = ("crps_x_m", "crps_y_m", "crps_heading_rad", "energy_score_m")
#: Keys of the per-ground-truth-time scores a sampled belief leaves in a run's ``extra``, in SCORE_IDS order.
SAMPLE_SCORE_KEYS = tuple(f"belief_{s}" for s in SCORE_IDS)
#: The estimator of a sample's scores (module docstring), part of the run key of every sampled run: changing it
#: recomputes their stored per-time scores.
SAMPLE_ESTIMATOR = "fair"
#: Quasi-Monte Carlo draws for the first term of a Gaussian's energy score, and their seed.
ENERGY_DRAWS = 1024
ENERGY_SEED = 0
#: Block length of the bootstrap over time, s of ground truth (about the time between a filter's corrections
#: and a few of its error's correlation times on the synthetic worlds; at least one sample).
BLOCK_S = 5.0
#: Bootstrap resamples and the generator's seed (fixed: the interval is part of the reproducible record).
BOOTSTRAP_RESAMPLES = 1000
BOOTSTRAP_SEED = 0
#: Coverage of the interval.
CONFIDENCE = 0.95


def crps_normal(y: npt.ArrayLike, mu: npt.ArrayLike, sigma: npt.ArrayLike) -> FloatArray:
    """CRPS of N(mu, sigma^2) at y in closed form (Gneiting & Raftery 2007, eq. 21), the unit of y.

    ``sigma`` = 0 is the point mass at mu (score |y - mu|); broadcasting as numpy.
    """
    y, mu, s = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (y, mu, sigma)))
    d = y - mu
    out = np.atleast_1d(np.abs(d)).astype(np.float64)
    s, d = np.atleast_1d(s), np.atleast_1d(d)
    pos = s > 0
    z = d[pos] / s[pos]
    out[pos] = s[pos] * (z * (2.0 * special.ndtr(z) - 1.0) + 2.0 * stats.norm.pdf(z) - 1.0 / np.sqrt(np.pi))
    return out.reshape(y.shape)


@functools.cache
def _energy_draws() -> FloatArray:
    """The fixed standard-normal draws (ENERGY_DRAWS, 2) of a Gaussian's energy score (scrambled Sobol)."""
    u = stats.qmc.Sobol(d=2, scramble=True, seed=ENERGY_SEED).random(ENERGY_DRAWS)
    return np.asarray(stats.norm.ppf(u), dtype=np.float64)


def _sqrt_psd(cov: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Eigenvalues (n, 2) ascending (negative rounding clipped to 0) and a square root L (n, 2, 2), L L^T = cov."""
    c = 0.5 * (cov + np.swapaxes(cov, 1, 2))
    lam, vec = np.linalg.eigh(c)
    lam = np.clip(lam, 0.0, None)
    return lam, vec * np.sqrt(lam)[:, None, :]


def energy_score_gaussian(y: npt.ArrayLike, mu: npt.ArrayLike, cov: npt.ArrayLike) -> FloatArray:
    """Energy score of N(mu, cov) on the plane at y, m (module docstring; deterministic).

    Parameters
    ----------
    y, mu : array-like, shape (n, 2)
        Truth and mean, m.
    cov : array-like, shape (n, 2, 2)
        Covariance, m^2 (a singular one is a point mass along its null directions).

    Returns
    -------
    ndarray, shape (n,)
    """
    yy = np.asarray(y, dtype=np.float64)
    d = np.asarray(mu, dtype=np.float64) - yy
    lam, root = _sqrt_psd(np.asarray(cov, dtype=np.float64))
    out = _energy_first_term(np.ascontiguousarray(d), np.ascontiguousarray(root), _energy_draws())
    big, small = lam[:, 1], lam[:, 0]
    ratio = np.divide(small, big, out=np.ones_like(big), where=big > 0)
    half_spread = np.sqrt(big / np.pi) * special.ellipe(1.0 - ratio)
    return out - half_spread


@njit(cache=True)
def _energy_first_term(d: FloatArray, root: FloatArray, z: FloatArray) -> FloatArray:  # pragma: no cover - compiled
    # E||d + L z|| over the fixed draws z, per time: one pass without the (times x draws) temporaries. The norm is
    # sqrt(px^2 + py^2), which vectorises where libm's hypot does not; the two agree to rounding
    n, m = d.shape[0], z.shape[0]
    out = np.empty(n)
    norms = np.empty(m)
    zx = np.ascontiguousarray(z[:, 0])
    zy = np.ascontiguousarray(z[:, 1])
    for t in range(n):
        dx, dy = d[t, 0], d[t, 1]
        a, b, c, e = root[t, 0, 0], root[t, 0, 1], root[t, 1, 0], root[t, 1, 1]
        for j in range(m):
            px = dx + a * zx[j] + b * zy[j]
            py = dy + c * zx[j] + e * zy[j]
            norms[j] = math.sqrt(px * px + py * py)
        out[t] = pairwise_sum(norms, 0, m) / m
    return out


def gaussian_scores(
    mean: npt.ArrayLike, cov: npt.ArrayLike, truth: npt.ArrayLike
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The four per-time scores of Gaussian beliefs (pose mean (n, 3), covariance (n, 3, 3)) at truth (n, 3).

    Returns CRPS of x (m), of y (m), of the wrapped heading (rad) and the position energy score (m), each (n,).
    """
    m = np.asarray(mean, dtype=np.float64)
    p = np.asarray(cov, dtype=np.float64)
    g = np.asarray(truth, dtype=np.float64)
    sd = np.sqrt(np.clip(np.diagonal(p, axis1=1, axis2=2), 0.0, None))
    cx = crps_normal(g[:, 0], m[:, 0], sd[:, 0])
    cy = crps_normal(g[:, 1], m[:, 1], sd[:, 1])
    ch = crps_normal(0.0, wrap_angle(m[:, 2] - g[:, 2]), sd[:, 2])
    es = energy_score_gaussian(g[:, :2], m[:, :2], p[:, :2, :2])
    return cx, cy, ch, es


def sample_scores(
    points: npt.ArrayLike, weights: npt.ArrayLike, truth: npt.ArrayLike, fair: bool = True
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The four scores of one weighted pose sample at each of k truth poses, in one compiled pass.

    Parameters
    ----------
    points : array-like, shape (m, 3)
        The sample's poses (x m, y m, theta rad), world frame.
    weights : array-like, shape (m,)
        Their weights, normalised here.
    truth : array-like, shape (k, 3)
        Truth poses, world frame.
    fair : bool
        The fair estimator of the score of the belief the sample was drawn from (True, what the runner stores:
        sum_i w_i |x_i - y| - sum_{i<j} w_i w_j |x_i - x_j| / sum_{i<j} 2 w_i w_j, module docstring), or the plain
        score of the discrete belief sum_i w_i delta_{x_i} itself (False: the pair sum over 1).

    Returns
    -------
    tuple of four ndarrays, shape (k,)
        CRPS of x (m), of y (m), of the heading (rad) and the position energy score (m) (the norm for |.|), each
        member's heading error wrapped to (-pi, pi] about the truth's heading and scored against 0. The runner
        calls it at every ground-truth time of a particle filter's run.
    """
    p = np.ascontiguousarray(points, dtype=np.float64)
    w = np.asarray(weights, dtype=np.float64)
    w = np.ascontiguousarray(w / w.sum())
    g = np.ascontiguousarray(np.asarray(truth, dtype=np.float64).reshape(-1, 3))
    heading_error = np.ascontiguousarray(wrap_angle(p[None, :, 2] - g[:, 2:3]))
    out = _sample_scores_kernel(p, w, g, heading_error, fair)
    return out[0], out[1], out[2], out[3]


def sample_scores_batch(
    points: npt.ArrayLike, weights: npt.ArrayLike, stops: npt.ArrayLike, truth: npt.ArrayLike, fair: bool = True
) -> FloatArray:
    """:func:`sample_scores` of several samples at once, each at its own consecutive run of truth poses.

    Parameters
    ----------
    points : array-like, shape (s, m, 3)
        The samples' poses (x m, y m, theta rad), world frame.
    weights : array-like, shape (s, m)
        Their weights, each row already normalised to sum 1.
    stops : array-like of int, shape (s,)
        Sample i scores the truth rows from ``stops[i - 1]`` (0 for the first) up to ``stops[i]``.
    truth : array-like, shape (k, 3)
        Truth poses, world frame, ``k = stops[-1]``.
    fair : bool
        The estimator, as for :func:`sample_scores`.

    Returns
    -------
    ndarray, shape (4, k)
        CRPS of x (m), of y (m), of the heading (rad) and the position energy score (m) at each truth pose: equal
        bit for bit to :func:`sample_scores` called once per sample (the same operations in the same order),
        without its per-call cost. The runner scores a particle filter's samples in batches with it.
    """
    p = np.ascontiguousarray(points, dtype=np.float64)
    w = np.ascontiguousarray(weights, dtype=np.float64)
    ends = np.asarray(stops, dtype=np.int64)
    g = np.ascontiguousarray(np.asarray(truth, dtype=np.float64).reshape(-1, 3))
    counts = np.diff(ends, prepend=0)
    owner = np.repeat(np.arange(p.shape[0]), counts)  # the sample that scores each truth row
    heading_error = np.ascontiguousarray(wrap_angle(p[owner, :, 2] - g[:, 2:3]))
    return _sample_scores_batch_kernel(p, w, np.ascontiguousarray(ends), g, heading_error, fair)


@njit(cache=True)
def _spread(p: FloatArray, w: FloatArray) -> tuple[float, float, float, float]:  # pragma: no cover - compiled
    """The pair sums of one sample that do not depend on the truth: sum_{i<j} w_i w_j |dx|, |dy| and ||d||, and
    sum_{i<j} w_i w_j."""
    m = p.shape[0]
    sx = sy = se = pairs = 0.0
    for i in range(m):
        for j in range(i + 1, m):
            ww = w[i] * w[j]
            pairs += ww
            dx, dy = p[i, 0] - p[j, 0], p[i, 1] - p[j, 1]
            sx += ww * abs(dx)
            sy += ww * abs(dy)
            se += ww * math.sqrt(dx * dx + dy * dy)
    return sx, sy, se, pairs


@njit(cache=True)
def _score_rows(
    p: FloatArray, w: FloatArray, g: FloatArray, h: FloatArray, fair: bool, out: FloatArray, first: int, stop: int
) -> None:  # pragma: no cover - compiled
    """The four scores of one sample (``p`` (m, 3), normalised ``w``) at the truth rows ``first`` to ``stop`` of
    ``g`` (with their wrapped heading errors ``h``), written into the same columns of ``out`` (4, k)."""
    m = p.shape[0]
    sx, sy, se, pairs = _spread(p, w)
    # each unordered pair once: 0.5 * sum_{i != j} = sum_{i<j}; the fair estimator divides by the pairs' weight
    # sum_{i != j} w_i w_j = 2 sum_{i<j} w_i w_j (= 1 - sum_i w_i^2); no pair with weight: a point mass
    scale = 1.0
    if fair:
        scale = 0.5 / pairs if pairs > 0.0 else 0.0
    for r in range(first, stop):
        fx = fy = fh = fe = sh = 0.0
        for i in range(m):
            dx, dy = p[i, 0] - g[r, 0], p[i, 1] - g[r, 1]
            fx += w[i] * abs(dx)
            fy += w[i] * abs(dy)
            fe += w[i] * math.sqrt(dx * dx + dy * dy)
            hi = h[r, i]
            fh += w[i] * abs(hi)
            for j in range(i + 1, m):
                sh += w[i] * w[j] * abs(hi - h[r, j])
        out[0, r] = fx - scale * sx
        out[1, r] = fy - scale * sy
        out[2, r] = fh - scale * sh
        out[3, r] = fe - scale * se


@njit(cache=True)
def _sample_scores_kernel(
    p: FloatArray, w: FloatArray, g: FloatArray, h: FloatArray, fair: bool
) -> FloatArray:  # pragma: no cover - compiled
    """The four scores (4, k) of :func:`sample_scores`: the members ``p`` (m, 3) with normalised weights ``w``
    (m,), the truths ``g`` (k, 3), the members' wrapped heading errors ``h`` (k, m), rad, and the estimator."""
    out = np.empty((4, g.shape[0]))
    _score_rows(p, w, g, h, fair, out, 0, g.shape[0])
    return out


@njit(cache=True)
def _sample_scores_batch_kernel(
    p: FloatArray, w: FloatArray, stops: npt.NDArray[np.int64], g: FloatArray, h: FloatArray, fair: bool
) -> FloatArray:  # pragma: no cover - compiled
    """The four scores (4, k) of :func:`sample_scores_batch`: sample i (``p[i]``, ``w[i]``) at the truth rows from
    ``stops[i - 1]`` to ``stops[i]``."""
    out = np.empty((4, g.shape[0]))
    first = 0
    for i in range(p.shape[0]):
        _score_rows(p[i], w[i], g, h, fair, out, first, stops[i])
        first = stops[i]
    return out


def block_length(t: npt.ArrayLike, block_s: float = BLOCK_S) -> int:
    """Samples per bootstrap block: ``block_s`` over the median spacing of ``t``, at least 1, at most len(t)."""
    tt = np.asarray(t, dtype=np.float64)
    if tt.size < 2:
        return 1
    dt = float(np.median(np.diff(tt)))
    n = round(block_s / dt) if dt > 0 else 1
    return int(min(max(n, 1), tt.size))


def block_bootstrap_ci(
    values: npt.ArrayLike,
    block: int,
    resamples: int = BOOTSTRAP_RESAMPLES,
    confidence: float = CONFIDENCE,
    seed: int = BOOTSTRAP_SEED,
) -> tuple[float, float]:
    """Percentile interval of the mean of a time series by the circular block bootstrap (Politis & Romano 1992).

    Each resample joins ceil(n / block) blocks of ``block`` consecutive values whose starts are drawn
    uniformly (the series wrapped end to start, so every value is equally likely), the last block cut so that
    the resample has n values; the interval is the (1 -+ confidence) / 2 quantiles of the resampled means.
    (nan, nan) for no values or a non-finite value.
    """
    v = np.asarray(values, dtype=np.float64)
    n = v.size
    if n == 0 or not np.all(np.isfinite(v)):
        return float("nan"), float("nan")
    size = int(min(max(block, 1), n))
    k = -(-n // size)
    last = n - (k - 1) * size
    # sums of every circular block from its start, by one cumulative sum over the series twice
    c = np.concatenate([[0.0], np.cumsum(np.concatenate([v, v]))])
    s0 = np.arange(n)
    full, part = c[s0 + size] - c[s0], c[s0 + last] - c[s0]
    head, tail = _block_starts(n, k, resamples, seed)
    means = (full[head].sum(axis=1) + part[tail]) / n
    a = (1.0 - confidence) / 2.0
    lo, hi = np.quantile(means, [a, 1.0 - a])
    return float(lo), float(hi)


@functools.lru_cache(maxsize=16)
def _block_starts(n: int, k: int, resamples: int, seed: int) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """The block starts of :func:`block_bootstrap_ci` for a series of ``n`` values in ``k`` blocks: the first
    ``k - 1`` blocks' (resamples, k - 1) and the last block's (resamples,), read-only.

    They depend on the series' length only (the generator is seeded with ``seed`` for every series), so a run's
    four scores, and every run on the same truth, share one draw.
    """
    starts = np.random.default_rng(seed).integers(0, n, size=(resamples, k))
    head, tail = np.ascontiguousarray(starts[:, :-1]), np.ascontiguousarray(starts[:, -1])
    head.flags.writeable = False
    tail.flags.writeable = False
    return head, tail


def ci_ids(score_id: str) -> tuple[str, str]:
    """The ``metrics.parquet`` ids of a score's interval: ``crps_x_m`` -> ``crps_x_ci_low_m``, ``crps_x_ci_high_m``."""
    stem, unit = score_id.rsplit("_", 1)
    return f"{stem}_ci_low_{unit}", f"{stem}_ci_high_{unit}"


def score_metrics(a: Aligned, extra: Mapping[str, np.ndarray]) -> dict[str, float]:
    """The proper-score rows of one run: each of :data:`SCORE_IDS` and its block-bootstrap interval.

    A run whose ``extra`` holds the per-time scores of its own samples (:data:`SAMPLE_SCORE_KEYS`, one per
    ground-truth time) is scored by those; any other by its Gaussian (mean, covariance) held at the truth times,
    read from the run's aligned view ``a`` (:func:`locbench.evaluate.aligned.align`, with covariances).
    """
    gt_t = a.t
    if all(k in extra for k in SAMPLE_SCORE_KEYS):
        per = [np.asarray(extra[k], dtype=np.float64) for k in SAMPLE_SCORE_KEYS]
        if any(p.shape != gt_t.shape for p in per):
            raise ValueError(
                f"stored belief scores have {per[0].shape[0]} rows for {gt_t.shape[0]} ground-truth times; re-run"
            )
    else:
        if a.cov is None:
            raise NoCovariance("a Gaussian belief's scores need the aligned covariances")
        per = list(gaussian_scores(a.mean, a.cov, a.truth))
    size = block_length(gt_t)
    out: dict[str, float] = {}
    for sid, s in zip(SCORE_IDS, per, strict=True):
        out[sid] = float(np.mean(s))
        lo_id, hi_id = ci_ids(sid)
        out[lo_id], out[hi_id] = block_bootstrap_ci(s, size)
    return out
