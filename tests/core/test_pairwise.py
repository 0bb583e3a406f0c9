"""The compiled pairwise sum (locbench.core.pairwise) against a Python model of its order and against np.sum."""

from __future__ import annotations

import math

import numpy as np

from locbench.core.pairwise import pairwise_sum


def _pairwise_model(v: list[float]) -> float:
    """The pairwise order in Python floats (halves split at a multiple of 8, leaves of at most 128 summed in 8 lanes
    combined as a tree, under 8 in order): IEEE additions in a fixed order, the same bits on every machine."""
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


def test_pairwise_sum_follows_its_order_and_the_error_bound_of_a_pairwise_sum() -> None:
    rng = np.random.default_rng(7)
    eps = np.finfo(np.float64).eps
    for m in (1, 7, 8, 9, 127, 128, 129, 300, 1030, 5000):
        v = rng.normal(size=m) * 10.0 ** rng.integers(-8, 8, size=m)
        # the summation order exactly: the compiled kernel against the Python model, both IEEE additions in order
        assert pairwise_sum(v, 0, m) == _pairwise_model(v.tolist())
        # the exact sum (math.fsum) within a pairwise sum's error bound, (log2 m + 8) eps sum |v|; np.sum too (its
        # reduction kernels are chosen per CPU: held to the bound, not to the bits)
        bound = (math.log2(m) + 8) * eps * float(np.sum(np.abs(v)))
        assert abs(pairwise_sum(v, 0, m) - math.fsum(v.tolist())) <= bound
        assert abs(pairwise_sum(v, 0, m) - float(np.sum(v))) <= bound
    # a slice of a longer row: the sum of v[lo : lo + n]
    v = rng.normal(size=700)
    assert pairwise_sum(v, 150, 400) == _pairwise_model(v[150:550].tolist())
