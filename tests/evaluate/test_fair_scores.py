"""The fair estimator of a sample's proper scores (locbench.evaluate.scores): scoringrules' fair estimators, its
expectation over the draws, weights as repeated members, and the particle filter's systematic subsample."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import scoringrules as sr

from locbench.evaluate import scores as sc
from locbench.filters.pf import systematic_resample

#: Agreement with scoringrules: the same sums in another order (relative, and absolute near 0).
RTOL, ATOL = 1e-10, 1e-12


def _pose_sample(rng: np.random.Generator, m: int) -> np.ndarray:
    return np.column_stack([rng.normal(size=m), rng.normal(size=m) * 0.5, rng.uniform(-0.5, 0.5, m)])


def test_equal_weights_match_scoringrules_fair_estimators() -> None:
    """Equal weights: the spread over M (M - 1), scoringrules' ``estimator="fair"``."""
    rng = np.random.default_rng(10)
    pts = _pose_sample(rng, 48)
    truth = np.column_stack([rng.normal(size=(25, 2)), rng.uniform(-0.3, 0.3, 25)])
    cx, cy, _, es = sc.sample_scores(pts, np.ones(48), truth)
    for axis, got in ((0, cx), (1, cy)):
        members = np.broadcast_to(pts[:, axis], (25, 48))
        ref = sr.crps_ensemble(truth[:, axis], members, m_axis=-1, estimator="fair")
        np.testing.assert_allclose(got, ref, rtol=RTOL, atol=ATOL)
    members2 = np.broadcast_to(pts[None, :, :2], (25, 48, 2))
    np.testing.assert_allclose(es, sr.es_ensemble(truth[:, :2], members2, estimator="fair"), rtol=RTOL, atol=ATOL)
    # and not the plain estimator: the spread term differs by the factor M / (M - 1)
    plain = sr.crps_ensemble(truth[:, 0], np.broadcast_to(pts[:, 0], (25, 48)), m_axis=-1, estimator="nrg")
    assert np.all(cx < plain - 1e-3)


def test_weighted_members_match_scoringrules_weighted_fair_estimators() -> None:
    """Weights: the spread over 1 - sum w_i^2, as scoringrules' weighted fair estimators (numpy backend)."""
    rng = np.random.default_rng(11)
    pts = _pose_sample(rng, 40)
    w = rng.uniform(0.1, 1.0, 40)
    truth = np.column_stack([rng.normal(size=(20, 2)), np.zeros(20)])
    cx, cy, _, es = sc.sample_scores(pts, w, truth)
    wk = np.broadcast_to(w / w.sum(), (20, 40))
    for axis, got in ((0, cx), (1, cy)):
        members = np.broadcast_to(pts[:, axis], (20, 40))
        ref = sr.crps_ensemble(truth[:, axis], members, m_axis=-1, ens_w=wk, estimator="fair", backend="numpy")
        np.testing.assert_allclose(got, ref, rtol=RTOL, atol=ATOL)
    members2 = np.broadcast_to(pts[None, :, :2], (20, 40, 2))
    ref2 = sr.es_ensemble(truth[:, :2], members2, ens_w=wk, estimator="fair", backend="numpy")
    np.testing.assert_allclose(es, ref2, rtol=RTOL, atol=ATOL)


def test_fair_scores_are_unbiased_for_the_belief_sampled_at_fixed_weights() -> None:
    """Every draw of M = 4 weighted members from a three-point belief F, enumerated: the fair scores' expectation
    is F's score (the derivation in the module docstring), the plain one's is high by E|X - X'| sum w_i^2 / 2."""
    atoms = np.array([[0.0, 0.0, 0.1], [1.0, -0.5, -0.2], [2.5, 1.0, 0.4]])
    prob = np.array([0.5, 0.3, 0.2])
    w = np.array([0.1, 0.2, 0.3, 0.4])
    truth = np.array([[0.7, 0.2, 0.0], [-1.0, 2.0, 0.3]])
    belief = np.array(sc.sample_scores(atoms, prob, truth, fair=False))  # F itself: the exact discrete score
    spread_x = sum(prob[i] * prob[j] * abs(atoms[i, 0] - atoms[j, 0]) for i in range(3) for j in range(3))
    fair = np.zeros_like(belief)
    plain = np.zeros_like(belief)
    for draw in itertools.product(range(3), repeat=4):
        pr = float(np.prod(prob[list(draw)]))
        fair += pr * np.array(sc.sample_scores(atoms[list(draw)], w, truth))
        plain += pr * np.array(sc.sample_scores(atoms[list(draw)], w, truth, fair=False))
    np.testing.assert_allclose(fair, belief, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(plain[0], belief[0] + 0.5 * spread_x * np.sum(w * w), rtol=1e-12)


def test_integer_weights_are_repeated_members_in_the_plain_score_but_not_the_fair_one() -> None:
    """A member of weight k is k repeated members in the exact score of the discrete belief; in the fair score it
    is not: repeated members are not independent draws, and the fair spread of the repeated ensemble is the
    plain one over 1 - 1/N, of the weighted one over 1 - sum w_i^2."""
    rng = np.random.default_rng(12)
    pts = _pose_sample(rng, 6)
    k = np.array([1, 3, 2, 1, 4, 1])
    expanded = np.repeat(pts, k, axis=0)
    truth = np.array([[0.2, -0.1, 0.05], [1.0, 1.0, -0.2]])
    weighted = np.array(sc.sample_scores(pts, k.astype(float), truth, fair=False))
    repeated = np.array(sc.sample_scores(expanded, np.ones(k.sum()), truth, fair=False))
    np.testing.assert_allclose(weighted, repeated, rtol=1e-12)
    n, w = k.sum(), k / k.sum()
    fair_w = np.array(sc.sample_scores(pts, k.astype(float), truth))
    fair_rep = np.array(sc.sample_scores(expanded, np.ones(n), truth))
    # plain - fair = spread * (1 / (1 - s) - 1) with s = sum w^2 (weighted) or 1 / n (repeated)
    s_w, s_rep = float(np.sum(w * w)), 1.0 / n
    spread_w = (weighted - fair_w) / (1.0 / (1.0 - s_w) - 1.0)
    spread_rep = (repeated - fair_rep) / (1.0 / (1.0 - s_rep) - 1.0)
    np.testing.assert_allclose(spread_w, spread_rep, rtol=1e-10)
    assert np.all(np.abs(fair_w - fair_rep) > 1e-3)


def test_a_sample_with_all_weight_on_one_member_is_a_point_mass() -> None:
    pts = np.array([[1.0, 2.0, 0.1], [5.0, -3.0, 1.0], [0.0, 0.0, 0.0]])
    got = sc.sample_scores(pts, np.array([1.0, 0.0, 0.0]), [[0.0, 0.0, 0.0]])
    np.testing.assert_allclose([g[0] for g in got], [1.0, 2.0, 0.1, np.sqrt(5.0)], rtol=1e-15)


def test_a_systematic_subsample_keeps_the_full_sets_fair_score() -> None:
    """The particle filter's belief sample (64 of 400 weighted particles by systematic resampling): the fair
    scores' expectation over the one uniform offset, exact (the sample is constant between the offsets where a
    point (u + k) / 64 crosses a cumulative weight), is the full weighted set's fair score within 1 %; the plain
    subsample's is at least twice as far from the full set's plain score (its spread is short by 1/64)."""
    rng = np.random.default_rng(13)
    n, m = 400, 64
    pts = np.column_stack([rng.normal(size=n), rng.normal(size=n) * 0.5, rng.normal(size=n) * 0.2])
    w = np.exp(-0.5 * (pts[:, 0] - 0.5) ** 2 / 0.8)
    w /= w.sum()
    truth = np.array([[0.3, 0.1, 0.05], [1.0, -0.5, -0.2]])
    edges = np.unique(np.concatenate([[0.0, 1.0], np.mod(m * np.cumsum(w), 1.0)]))
    offsets, lengths = 0.5 * (edges[:-1] + edges[1:]), np.diff(edges)

    class Offset:
        """A generator whose one uniform is the offset u (systematic_resample draws nothing else)."""

        def __init__(self, u: float) -> None:
            self.u = u

        def random(self) -> float:
            return self.u

    bias = {}
    for fair in (True, False):
        full = np.array(sc.sample_scores(pts, w, truth, fair=fair))
        mean = np.zeros_like(full)
        for u, length in zip(offsets, lengths, strict=True):
            idx = systematic_resample(w, m, Offset(float(u)))  # type: ignore[arg-type]
            mean += length * np.array(sc.sample_scores(pts[idx], np.ones(m), truth, fair=fair))
        bias[fair] = np.abs(mean / full - 1.0)
    assert lengths.sum() == pytest.approx(1.0)
    assert np.all(bias[True] < 0.01)
    assert np.all(bias[True] < 0.5 * bias[False])
