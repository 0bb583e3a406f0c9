"""Lost-detection scores (locbench.evaluate.lost) and the particle filter's belief subsample."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from locbench.core.seeding import belief_rng, filter_rng
from locbench.evaluate import lost
from locbench.evaluate.metrics import align
from locbench.filters.base import SCORE_SAMPLE_SIZE
from locbench.filters.pf import ParticleFilter
from locbench.registry import make_dataset
from locbench.run.filter_pass import run_filter


def test_auroc_of_a_perfect_signal_is_one_and_of_a_random_one_about_a_half() -> None:
    rng = np.random.default_rng(0)
    labels = rng.random(5000) < 0.3
    assert lost.auroc(labels.astype(float), labels) == 1.0
    assert lost.auroc(-labels.astype(float), labels) == 0.0
    assert lost.auroc(rng.random(5000), labels) == pytest.approx(0.5, abs=0.03)
    assert np.isnan(lost.auroc([1.0, 2.0], [False, False]))
    assert lost.precision_at_recall(labels.astype(float), labels) == 1.0
    # a random signal's precision at high recall is about the share of positives
    assert lost.precision_at_recall(rng.random(5000), labels) == pytest.approx(labels.mean(), abs=0.03)


def test_auroc_counts_ties_one_half_and_skips_nan() -> None:
    assert lost.auroc([1.0, 1.0, np.nan], [True, False, True]) == 0.5


def test_forward_fill_and_orientation() -> None:
    np.testing.assert_array_equal(lost.forward_fill([np.nan, 1.0, np.nan, 3.0, np.nan]), [np.nan, 1.0, 1.0, 3.0, 3.0])
    np.testing.assert_array_equal(lost.oriented("ess_fraction", [0.2]), [-0.2])
    np.testing.assert_array_equal(lost.oriented("nis", [4.0]), [4.0])


def test_alarm_threshold_and_detection_delay() -> None:
    quiet = np.arange(100.0)
    thr = lost.alarm_threshold(quiet)
    assert np.mean(quiet > thr) == pytest.approx(lost.FALSE_ALARM_RATE, abs=0.01)
    t = np.arange(0.0, 60.0, 1.0)
    sig = np.where(t >= 13.0, 1000.0, 0.0)
    assert lost.detection_delay(t, sig, thr, 10.0) == 3.0
    assert np.isnan(lost.detection_delay(t, np.zeros_like(t), thr, 10.0))
    late = np.where(t >= 57.0, 1000.0, 0.0)
    assert np.isnan(lost.detection_delay(t, late, thr, 50.0, window_s=5.0))


def test_score_signals_ranks_the_informative_signal_first() -> None:
    t = np.arange(200.0)
    err = np.where(t > 100, 1.0, 0.0)
    s = lost.HealthSeries(t, err, {"nis": err + 0.1 * np.sin(t), "cov_trace_xy_m2": np.cos(t)})
    best = lost.score_signals([s])[0]
    assert best.signal == "nis" and best.auroc[0] == 1.0 and best.lost_share == pytest.approx(99 / 200)


def test_score_signals_aurocs_equal_auroc_at_every_threshold() -> None:
    # the signals are ranked once for all thresholds: the same numbers as auroc() per threshold, NaN left out
    rng = np.random.default_rng(4)
    t = np.arange(3000.0)
    err = rng.gamma(1.0, 0.4, size=t.size)
    sig = err + rng.normal(size=t.size)
    sig[::17] = np.nan
    sig[5::9] = np.round(sig[5::9], 1)  # ties
    s = lost.HealthSeries(t, err, {"nis": sig})
    (score,) = lost.score_signals([s])
    assert score.auroc == tuple(lost.auroc(sig, err > th) for th in lost.LOST_THRESHOLDS_M)
    assert len(set(score.auroc)) == len(lost.LOST_THRESHOLDS_M)


def test_particle_subsample_is_unbiased() -> None:
    """The 64-particle systematic subsample's mean matches the weighted full set's within its standard error."""
    ds = make_dataset("tiny_line", 0)
    flt = ParticleFilter()
    run_filter(flt, ds, filter_rng("pf", ds.name, 0))
    x, w = flt.particles()
    full = np.sum(w[:, None] * x[:, :2], axis=0)
    rng = belief_rng("pf", ds.name, 0)
    means = np.array([np.mean(flt.belief_sample(rng, SCORE_SAMPLE_SIZE)[0][:, :2], axis=0) for _ in range(400)])
    assert means.shape == (400, 2)
    se = np.std(means, axis=0, ddof=1) / np.sqrt(means.shape[0])
    assert np.all(np.abs(means.mean(axis=0) - full) < 4.0 * se + 1e-12)
    pts, wts = flt.belief_sample(rng, SCORE_SAMPLE_SIZE)
    assert pts.shape == (SCORE_SAMPLE_SIZE, 3) and wts.sum() == pytest.approx(1.0)


def test_health_series_holds_each_signal_by_the_aligned_rows() -> None:
    t_est = np.array([0.0, 1.0, 1.0, 2.0])
    mean = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [3.0, 0.0, 0.0]])
    gt_t = np.array([0.5, 1.5, 2.5])
    a = align(t_est, mean, gt_t, np.zeros((3, 3)))
    # the NIS is not defined after a predict (NaN): the last defined value holds; ess_fraction is turned around
    health = {"nis": [np.nan, 4.0, np.nan, 9.0], "ess_fraction": [1.0, 0.5, 0.2, 0.1], "not_a_signal": [0.0] * 4}
    hs = lost.health_series(a, health, 1.0)
    np.testing.assert_array_equal(hs.t, gt_t)
    np.testing.assert_array_equal(hs.error_m, [0.0, 1.0, 3.0])
    np.testing.assert_array_equal(hs.signals["nis"], [np.nan, 4.0, 9.0])
    np.testing.assert_array_equal(hs.signals["ess_fraction"], [-1.0, -0.2, -0.1])
    assert set(hs.signals) == {"nis", "ess_fraction"} and hs.kidnap_t == 1.0


@settings(max_examples=200, deadline=None)
@given(
    values=st.lists(st.sampled_from([0.0, 0.5, 1.0, 2.0, np.nan, -1.0, 3.25]), min_size=1, max_size=60),
    errors=st.lists(st.floats(0.0, 2.0), min_size=60, max_size=60),
)
def test_score_signals_equal_auroc_and_precision_bit_for_bit(values: list[float], errors: list[float]) -> None:
    """One sort per signal gives the numbers auroc() and precision_at_recall() give, ties and NaN included."""
    sig = np.array(values, dtype=float)
    err = np.array(errors[: sig.size], dtype=float)
    s = lost.HealthSeries(np.arange(float(sig.size)), err, {"nis": sig})
    (score,) = lost.score_signals([s])
    want_auroc = tuple(lost.auroc(sig, err > th) for th in lost.LOST_THRESHOLDS_M)
    want_precision = lost.precision_at_recall(sig, err > lost.LOST_THRESHOLDS_M[0])
    assert np.array_equal(score.auroc, want_auroc, equal_nan=True)
    assert np.array_equal(score.precision, want_precision, equal_nan=True)


def test_score_signals_equal_auroc_and_precision_on_long_series() -> None:
    rng = np.random.default_rng(9)
    err = rng.gamma(1.0, 0.5, size=20_000)
    sig = np.round(err + rng.normal(size=err.size), 2)
    sig[::31] = np.nan
    (score,) = lost.score_signals([lost.HealthSeries(np.arange(float(err.size)), err, {"nis": sig})])
    assert score.precision == lost.precision_at_recall(sig, err > lost.LOST_THRESHOLDS_M[0])
    assert score.auroc == tuple(lost.auroc(sig, err > th) for th in lost.LOST_THRESHOLDS_M)
