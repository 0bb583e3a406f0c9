"""Proper scores (locbench.evaluate.scores) against their closed forms, large samples and scoringrules."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scoringrules as sr

from locbench.evaluate import scores as sc
from locbench.evaluate.metrics import align


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
    np.testing.assert_allclose(sc.crps_sample(y, draws), sc.crps_normal(y, mu, s), rtol=5e-3)


def test_crps_of_a_point_mass_is_the_absolute_error() -> None:
    np.testing.assert_allclose(sc.crps_normal([1.5, -2.0], [0.0, 0.0], [0.0, 0.0]), [1.5, 2.0])
    np.testing.assert_allclose(sc.crps_sample([1.5], [[0.0, 0.0]]), [1.5])


def test_weighted_sample_crps_and_energy_score_match_scoringrules() -> None:
    rng = np.random.default_rng(2)
    y, x, w = rng.normal(size=30), rng.normal(size=(30, 64)), rng.uniform(size=(30, 64))
    ref = sr.crps_ensemble(y, x, m_axis=-1, ens_w=w, estimator="nrg")
    np.testing.assert_allclose(sc.crps_sample(y, x, w), ref, rtol=1e-10, atol=1e-12)
    y2, x2 = rng.normal(size=(30, 2)), rng.normal(size=(30, 64, 2))
    ref2 = sr.es_ensemble(y2, x2, m_axis=-2, v_axis=-1, ens_w=w)
    np.testing.assert_allclose(sc.energy_score_sample(y2, x2, w), ref2, rtol=1e-10, atol=1e-12)


def test_energy_score_of_a_point_mass_is_the_euclidean_error() -> None:
    y = np.array([[3.0, 4.0], [0.0, 0.0]])
    mu = np.array([[0.0, 0.0], [1.0, -1.0]])
    np.testing.assert_allclose(sc.energy_score_gaussian(y, mu, np.zeros((2, 2, 2))), [5.0, np.sqrt(2.0)], rtol=1e-12)
    np.testing.assert_allclose(sc.energy_score_sample(y, mu[:, None, :]), [5.0, np.sqrt(2.0)], rtol=1e-12)


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


def test_compiled_sample_scores_equal_the_reference_sums() -> None:
    rng = np.random.default_rng(5)
    pts = np.column_stack([rng.normal(size=64), rng.normal(size=64), rng.uniform(-np.pi, np.pi, 64)])
    w = rng.uniform(size=64)
    truth = np.array([[0.1, -0.2, 3.1], [1.0, 1.0, -3.0], [0.0, 0.0, 0.0]])
    got = sc.sample_scores(pts, w, truth)
    k = truth.shape[0]
    wk = np.broadcast_to(w, (k, 64))
    ref = (
        sc.crps_sample(truth[:, 0], np.broadcast_to(pts[:, 0], (k, 64)), wk),
        sc.crps_sample(truth[:, 1], np.broadcast_to(pts[:, 1], (k, 64)), wk),
        sc.crps_sample(np.zeros(k), sc.wrap_angle(pts[None, :, 2] - truth[:, 2:3]), wk),
        sc.energy_score_sample(truth[:, :2], np.broadcast_to(pts[None, :, :2], (k, 64, 2)), wk),
    )
    for a, b in zip(got, ref, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-12)


def _pairwise_model(v: list[float]) -> float:
    """numpy's documented pairwise order (halves split at a multiple of 8, leaves of at most 128 summed in 8 lanes
    combined as a tree, under 8 in order), in Python floats: the order the compiled sum must follow exactly."""
    n = len(v)
    if n < 8:
        s = 0.0
        for x in v:
            s += x
        return s
    if n <= 128:
        r = v[:8]
        i = 8
        while i < n - n % 8:
            r = [r[j] + v[i + j] for j in range(8)]
            i += 8
        s = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
        for x in v[i:]:
            s += x
        return s
    half = n // 2
    half -= half % 8
    return _pairwise_model(v[:half]) + _pairwise_model(v[half:])


def test_compiled_gaussian_energy_term_equals_the_numpy_mean() -> None:
    # the numpy form of the compiled first term, and libm's hypot (the form before), within rounding: numpy's
    # reductions and SIMD loops are chosen per CPU, so against numpy the test holds a tolerance, not the bits
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
    eps = np.finfo(np.float64).eps
    for m in (1, 7, 8, 9, 127, 128, 129, 300, 1030):
        v = rng.normal(size=m) * 10.0 ** rng.integers(-8, 8, size=m)
        # the summation order, exactly (our kernel against our model of it); np.sum within a pairwise sum's error
        # bound, (log2 m + 8) eps sum |v|, as numpy's reduction kernels may differ per CPU
        assert sc.pairwise_sum(v, 0, m) == _pairwise_model(v.tolist())
        bound = (math.log2(m) + 8) * eps * float(np.sum(np.abs(v)))
        assert abs(sc.pairwise_sum(v, 0, m) - float(np.sum(v))) <= bound
