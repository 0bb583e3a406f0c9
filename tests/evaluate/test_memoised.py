"""What the evaluation computes once and reuses gives what computing it every time gives, bit for bit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from locbench.evaluate import scores as sc
from locbench.evaluate import significance as sg
from locbench.evaluate.aligned import align, nees
from locbench.evaluate.metrics import nll, nll_at_truth


def _bootstrap_drawing_every_time(v: np.ndarray, block: int, resamples: int, seed: int) -> tuple[float, float]:
    """The circular block bootstrap with the starts drawn for each series (what the shared draw must equal)."""
    n = v.size
    size = int(min(max(block, 1), n))
    k = -(-n // size)
    last = n - (k - 1) * size
    c = np.concatenate([[0.0], np.cumsum(np.concatenate([v, v]))])
    s0 = np.arange(n)
    full, part = c[s0 + size] - c[s0], c[s0 + last] - c[s0]
    starts = np.random.default_rng(seed).integers(0, n, size=(resamples, k))
    means = (full[starts[:, :-1]].sum(axis=1) + part[starts[:, -1]]) / n
    a = (1.0 - sc.CONFIDENCE) / 2.0
    lo, hi = np.quantile(means, [a, 1.0 - a])
    return float(lo), float(hi)


@pytest.mark.parametrize("n", [1, 2, 7, 300])
@pytest.mark.parametrize("block", [1, 3, 50, 1000])
def test_block_bootstrap_with_shared_starts_equals_drawing_every_time(n: int, block: int) -> None:
    rng = np.random.default_rng(n * 1000 + block)
    for _ in range(3):  # the second and third series of a length reuse the first one's draw
        v = rng.normal(size=n) * 10.0 ** rng.integers(-4, 4)
        got = sc.block_bootstrap_ci(v, block)
        assert got == _bootstrap_drawing_every_time(v, block, sc.BOOTSTRAP_RESAMPLES, sc.BOOTSTRAP_SEED)


def test_shared_starts_are_read_only() -> None:
    head, tail = sc._block_starts(10, 4, 20, 1)
    assert not head.flags.writeable and not tail.flags.writeable
    assert head.shape == (20, 3) and tail.shape == (20,)


def test_paired_test_and_interval_are_reused_and_equal_fresh_ones() -> None:
    rng = np.random.default_rng(5)
    a, b = rng.normal(size=20), rng.normal(size=20)
    a[3] = np.nan  # left out before the values are keyed
    sg._wilcoxon_of.cache_clear()
    sg._median_interval_of.cache_clear()
    first, again = sg.wilcoxon_paired(a, b), sg.wilcoxon_paired(a.copy(), b.copy())
    assert first == again and sg._wilcoxon_of.cache_info().hits == 1
    keep = np.isfinite(a)
    fresh = sg._wilcoxon_of.__wrapped__((a[keep] - b[keep]).tobytes(), "two-sided")
    assert fresh == first
    d = a - b
    m1, m2 = sg.median_interval(d), sg.median_interval(d.copy())
    assert m1 == m2 and sg._median_interval_of.cache_info().hits == 1
    assert m1 == sg._median_interval_of.__wrapped__(d[np.isfinite(d)].tobytes(), 0.95)
    # a caller's array changed after the call does not change a later answer
    d[0] += 1.0
    assert sg.median_interval(d) == sg._median_interval_of.__wrapped__(d[np.isfinite(d)].tobytes(), 0.95)


def test_small_and_constant_samples_keep_their_answers() -> None:
    assert all(math.isnan(x) for x in sg.median_interval(np.array([np.nan])))
    med, lo, hi = sg.median_interval(np.array([2.0]))
    assert med == 2.0 and math.isnan(lo) and math.isnan(hi)
    assert sg.median_interval(np.full(5, 3.0)) == (3.0, 3.0, 3.0)
    assert math.isnan(sg.wilcoxon_paired(np.arange(3.0), np.zeros(3)).p)
    assert sg.wilcoxon_paired(np.ones(8), np.ones(8)).p == 1.0


def test_nll_at_truth_reusing_the_nees_equals_solving_again() -> None:
    rng = np.random.default_rng(2)
    n = 200
    t = np.arange(n, dtype=float)
    m = rng.normal(size=(n, 3))
    root = rng.normal(size=(n, 3, 3))
    cov = root @ root.transpose(0, 2, 1)
    cov[5] = 0.0  # a collapsed covariance: +inf
    a = align(t, m, t, rng.normal(size=(n, 3)), cov)
    got = nll_at_truth(a)
    want = nll(a.error, a.cov)
    assert np.array_equal(got, want) and np.isinf(got[5])
    assert np.array_equal(nees(a.error, a.cov), a.nees)
