"""Proper scores (locbench.evaluate.scores) against their closed forms, large samples, plain sums and scoringrules."""

from __future__ import annotations

import numpy as np
import pytest
import scoringrules as sr

from locbench.core.geometry import wrap_angle
from locbench.evaluate import scores as sc
from locbench.evaluate.aligned import align


def crps_sample(y: np.ndarray, x: np.ndarray, w: np.ndarray | None = None, fair: bool = False) -> np.ndarray:
    """A plain CRPS of weighted samples (rows of ``x`` (n, m) with weights ``w`` (n, m), normalised per row) at
    ``y`` (n,): sum_i w_i |x_i - y| - 0.5 sum_ij w_i w_j |x_i - x_j| (Gneiting & Raftery 2007, eq. 22), the
    double sum over the sorted members as 2 sum_i w_i x_i (W_below_i - W_above_i); ``fair``: the double sum over
    1 - sum_i w_i^2 instead of 1."""
    xs = np.asarray(x, dtype=np.float64)
    ws = np.full(xs.shape, 1.0 / xs.shape[1]) if w is None else np.asarray(w, dtype=np.float64)
    ws = ws / ws.sum(axis=1, keepdims=True)
    first = np.sum(ws * np.abs(xs - np.asarray(y, dtype=np.float64)[:, None]), axis=1)
    order = np.argsort(xs, axis=1, kind="stable")
    xo = np.take_along_axis(xs, order, axis=1)
    wo = np.take_along_axis(ws, order, axis=1)
    below = np.cumsum(wo, axis=1) - wo
    above = 1.0 - below - wo
    spread = np.sum(wo * xo * (below - above), axis=1)
    return first - (spread / (1.0 - np.sum(ws * ws, axis=1)) if fair else spread)


def energy_score_sample(y: np.ndarray, x: np.ndarray, w: np.ndarray | None = None, fair: bool = False) -> np.ndarray:
    """A plain energy score of weighted samples (rows of ``x`` (n, m, d), weights ``w`` (n, m) normalised per row)
    at ``y`` (n, d): sum_i w_i ||x_i - y|| - 0.5 sum_ij w_i w_j ||x_i - x_j||; ``fair``: the pair sum over
    1 - sum_i w_i^2."""
    xs = np.asarray(x, dtype=np.float64)
    ws = np.full(xs.shape[:2], 1.0 / xs.shape[1]) if w is None else np.asarray(w, dtype=np.float64)
    ws = ws / ws.sum(axis=1, keepdims=True)
    first = np.sum(ws * np.linalg.norm(xs - np.asarray(y, dtype=np.float64)[:, None, :], axis=2), axis=1)
    pair = np.linalg.norm(xs[:, :, None, :] - xs[:, None, :, :], axis=3)
    spread = 0.5 * np.einsum("ni,nij,nj->n", ws, pair, ws)
    return first - (spread / (1.0 - np.sum(ws * ws, axis=1)) if fair else spread)


def test_crps_normal_matches_its_closed_form_and_scoringrules() -> None:
    rng = np.random.default_rng(0)
    y, mu, s = rng.normal(size=40), rng.normal(size=40), rng.uniform(0.05, 3.0, 40)
    np.testing.assert_allclose(sc.crps_normal(y, mu, s), sr.crps_normal(y, mu, s), rtol=1e-12, atol=1e-14)
    # the standard normal at its mean: (sqrt(2) - 1) / sqrt(pi)
    assert sc.crps_normal(0.0, 0.0, 1.0)[()] == pytest.approx((np.sqrt(2.0) - 1.0) / np.sqrt(np.pi), rel=1e-12)


def test_crps_normal_against_a_large_sample() -> None:
    rng = np.random.default_rng(1)
    y, mu, s = np.array([0.3, -2.0, 1.0]), np.array([0.0, 0.5, 1.0]), np.array([1.0, 0.7, 2.0])
    draws = mu[:, None] + s[:, None] * rng.standard_normal((3, 200_000))
    np.testing.assert_allclose(crps_sample(y, draws), sc.crps_normal(y, mu, s), rtol=5e-3)


def test_crps_of_a_point_mass_is_the_absolute_error() -> None:
    np.testing.assert_allclose(sc.crps_normal([1.5, -2.0], [0.0, 0.0], [0.0, 0.0]), [1.5, 2.0])
    # a sample of two members on one pose is a point mass
    cx, cy, ch, _ = sc.sample_scores(np.zeros((2, 3)), np.ones(2), [[1.5, -2.0, 0.3]])
    np.testing.assert_allclose([cx[0], cy[0], ch[0]], [1.5, 2.0, 0.3], rtol=1e-15)


def test_weighted_sample_scores_match_scoringrules() -> None:
    """The compiled plain scores of one weighted pose sample at several truths against scoringrules' ensemble
    scores (the energy form), and the plain sums of this module against them too."""
    rng = np.random.default_rng(2)
    pts = np.column_stack([rng.normal(size=64), rng.normal(size=64), rng.uniform(-0.5, 0.5, 64)])
    w = rng.uniform(size=64)
    truth = np.column_stack([rng.normal(size=30), rng.normal(size=(30, 2))])
    cx, cy, _, es = sc.sample_scores(pts, w, truth, fair=False)
    wk = np.broadcast_to(w, (30, 64))
    for axis, got in ((0, cx), (1, cy)):
        members = np.broadcast_to(pts[:, axis], (30, 64))
        ref = sr.crps_ensemble(truth[:, axis], members, m_axis=-1, ens_w=wk, estimator="nrg")
        np.testing.assert_allclose(got, ref, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(crps_sample(truth[:, axis], members, wk), ref, rtol=1e-10, atol=1e-12)
    members2 = np.broadcast_to(pts[None, :, :2], (30, 64, 2))
    ref2 = sr.es_ensemble(truth[:, :2], members2, m_axis=-2, v_axis=-1, ens_w=wk)
    np.testing.assert_allclose(es, ref2, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(energy_score_sample(truth[:, :2], members2, wk), ref2, rtol=1e-10, atol=1e-12)


def test_energy_score_of_a_point_mass_is_the_euclidean_error() -> None:
    y = np.array([[3.0, 4.0], [0.0, 0.0]])
    mu = np.array([[0.0, 0.0], [1.0, -1.0]])
    np.testing.assert_allclose(sc.energy_score_gaussian(y, mu, np.zeros((2, 2, 2))), [5.0, np.sqrt(2.0)], rtol=1e-12)
    _, _, _, es = sc.sample_scores(np.zeros((1, 3)), np.ones(1), np.column_stack([y - mu, np.zeros(2)]))
    np.testing.assert_allclose(es, [5.0, np.sqrt(2.0)], rtol=1e-12)


def test_gaussian_energy_score_against_a_large_sample() -> None:
    rng = np.random.default_rng(3)
    mu = np.array([[0.0, 0.0], [1.0, 0.5], [0.2, -0.3]])
    cov = np.array([np.eye(2), [[2.0, 0.9], [0.9, 0.6]], [[0.01, 0.0], [0.0, 1e-12]]])
    y = np.zeros((3, 2))
    draws = mu[:, None, :] + np.einsum("nij,nmj->nmi", np.linalg.cholesky(cov), rng.standard_normal((3, 3000, 2)))
    ref = sr.es_ensemble(y, draws, m_axis=-2, v_axis=-1)
    np.testing.assert_allclose(sc.energy_score_gaussian(y, mu, cov), ref, rtol=2e-2)


def test_wrapped_heading_crps_sees_the_branch_nearest_the_truth() -> None:
    # a belief at +pi - 0.01 scored against a truth at -pi + 0.01: 0.02 rad apart, not 2 pi - 0.02
    mean = np.array([[0.0, 0.0, np.pi - 0.01]])
    cov = np.diag([1e-4, 1e-4, 0.0])[None]
    truth = np.array([[0.0, 0.0, -np.pi + 0.01]])
    _, _, ch, _ = sc.gaussian_scores(mean, cov, truth)
    assert ch[0] == pytest.approx(0.02, abs=1e-9)
    _, _, chs, _ = sc.sample_scores(mean, np.ones(1), truth)
    assert chs[0] == pytest.approx(0.02, abs=1e-9)


def test_block_bootstrap_interval_covers_the_mean_and_is_reproducible() -> None:
    rng = np.random.default_rng(4)
    v = np.cumsum(rng.normal(size=2000)) * 0.01 + 1.0  # autocorrelated
    lo, hi = sc.block_bootstrap_ci(v, 100)
    assert lo < float(np.mean(v)) < hi
    assert (lo, hi) == sc.block_bootstrap_ci(v, 100)
    # longer blocks see the autocorrelation: a wider interval than single-sample blocks
    lo1, hi1 = sc.block_bootstrap_ci(v, 1)
    assert hi - lo > hi1 - lo1
    assert np.isnan(sc.block_bootstrap_ci([], 5)[0])


def test_block_length_is_block_s_of_ground_truth() -> None:
    assert sc.block_length(np.arange(0.0, 100.0, 0.05)) == round(sc.BLOCK_S / 0.05)
    assert sc.block_length(np.arange(0.0, 1.0, 0.5)) == 2
    assert sc.block_length(np.zeros(1)) == 1


def test_score_metrics_use_stored_sample_scores_when_present() -> None:
    t = np.array([0.0, 1.0, 2.0])
    mean, cov = np.zeros((3, 3)), np.tile(np.eye(3), (3, 1, 1))
    gt = np.zeros((3, 3))
    a = align(t, mean, t, gt, cov)
    gauss = sc.score_metrics(a, {})
    assert set(gauss) >= set(sc.SCORE_IDS) and all(np.isfinite(gauss[k]) for k in sc.SCORE_IDS)
    stored = {k: np.full(3, 0.5) for k in sc.SAMPLE_SCORE_KEYS}
    assert sc.score_metrics(a, stored)["energy_score_m"] == 0.5
    with pytest.raises(ValueError, match="ground-truth times"):
        sc.score_metrics(a, {k: np.zeros(2) for k in sc.SAMPLE_SCORE_KEYS})
    lo, hi = sc.ci_ids("crps_heading_rad")
    assert (lo, hi) == ("crps_heading_ci_low_rad", "crps_heading_ci_high_rad")


def test_compiled_sample_scores_equal_the_plain_sums() -> None:
    rng = np.random.default_rng(5)
    pts = np.column_stack([rng.normal(size=64), rng.normal(size=64), rng.uniform(-np.pi, np.pi, 64)])
    w = rng.uniform(size=64)
    truth = np.array([[0.1, -0.2, 3.1], [1.0, 1.0, -3.0], [0.0, 0.0, 0.0]])
    k = truth.shape[0]
    wk = np.broadcast_to(w, (k, 64))
    for fair in (True, False):
        got = sc.sample_scores(pts, w, truth, fair=fair)
        ref = (
            crps_sample(truth[:, 0], np.broadcast_to(pts[:, 0], (k, 64)), wk, fair),
            crps_sample(truth[:, 1], np.broadcast_to(pts[:, 1], (k, 64)), wk, fair),
            crps_sample(np.zeros(k), wrap_angle(pts[None, :, 2] - truth[:, 2:3]), wk, fair),
            energy_score_sample(truth[:, :2], np.broadcast_to(pts[None, :, :2], (k, 64, 2)), wk, fair),
        )
        for a, b in zip(got, ref, strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-12)


def test_compiled_gaussian_energy_term_equals_the_numpy_mean() -> None:
    # the compiled first term against its numpy form, with the norm as sqrt and as libm's hypot: numpy's
    # reductions and SIMD loops are chosen per CPU, so the test holds a tolerance, not the bits
    rng = np.random.default_rng(7)
    n = 3001
    d = rng.normal(size=(n, 2)) * rng.lognormal(size=(n, 1))
    a = rng.normal(size=(n, 2, 2)) * 0.3
    cov = a @ np.swapaxes(a, 1, 2)
    cov[:50] = 0.0
    cov[50:60, 1, 1] = 0.0
    _lam, root = sc._sqrt_psd(cov)
    z = sc._energy_draws()
    px = d[:, 0:1] + root[:, 0, 0:1] * z[None, :, 0] + root[:, 0, 1:2] * z[None, :, 1]
    py = d[:, 1:2] + root[:, 1, 0:1] * z[None, :, 0] + root[:, 1, 1:2] * z[None, :, 1]
    expected = np.mean(np.sqrt(px * px + py * py), axis=1)
    got = sc._energy_first_term(d, root, z)
    # a mean of m positive terms: numpy's pairwise sum is within (log2 m + 2) eps relative, so 1e-13 either side
    np.testing.assert_allclose(got, expected, rtol=1e-13, atol=0.0)
    np.testing.assert_allclose(got, np.mean(np.hypot(px, py), axis=1), rtol=1e-13, atol=0.0)


@pytest.mark.parametrize("fair", [True, False])
def test_a_batch_of_samples_scores_as_each_sample_alone_bit_for_bit(fair: bool) -> None:
    """The runner's batched scoring is the one-sample scoring, value for value (our code against itself)."""
    rng = np.random.default_rng(3)
    counts = [1, 4, 1, 7, 2]  # truth times each sample holds
    m = 9
    points = rng.normal(size=(len(counts), m, 3)) * [1.0, 0.5, 3.0]  # headings beyond pi: wrapped about the truth
    weights = rng.uniform(0.1, 1.0, size=(len(counts), m))
    weights[2] = 0.0
    weights[2, 4] = 1.0  # all weight on one member: scored as a point mass
    truth = rng.normal(size=(sum(counts), 3)) * [1.0, 1.0, 2.0]
    stops = np.cumsum(counts)
    # each row normalised as sample_scores normalises its weights (the runner does the same before batching)
    batch = sc.sample_scores_batch(points, np.stack([w / w.sum() for w in weights]), stops, truth, fair)
    starts = stops - counts
    parts = zip(points, weights, starts, stops, strict=True)
    alone = np.hstack([np.array(sc.sample_scores(p, w, truth[a:b], fair)) for p, w, a, b in parts])
    assert batch.shape == (4, sum(counts))
    assert np.array_equal(batch, alone)
