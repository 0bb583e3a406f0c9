"""Pairwise summation of a float64 row, compiled: the sum used where a compiled kernel averages many terms.

A pairwise sum's rounding error grows as log2(n) eps sum |v_i| rather than the n eps of a running sum (Higham,
"The accuracy of floating point summation", SIAM J. Sci. Comput. 14(4), 1993). The order is numpy's for a
contiguous row: halves split at a multiple of 8 down to leaves of at most 128 values, each leaf summed in 8 lanes
combined as a tree (under 8 values in order). Used by the Gaussian energy score and by ``ekf_icp``'s mean range;
kept in the core so that the filters need not import the evaluation.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from numba import njit

FloatArray = npt.NDArray[np.float64]


@njit(cache=True)
def _block_sum(v: FloatArray, lo: int, n: int) -> float:  # pragma: no cover - compiled
    """A leaf of the pairwise sum, ``v[lo : lo + n]`` with n <= 128: under 8 values in order, else 8 lanes (every
    8th value each) combined as a tree, then the remainder in order."""
    if n < 8:
        s = 0.0
        for i in range(lo, lo + n):
            s += v[i]
        return s
    r0, r1, r2, r3 = v[lo], v[lo + 1], v[lo + 2], v[lo + 3]
    r4, r5, r6, r7 = v[lo + 4], v[lo + 5], v[lo + 6], v[lo + 7]
    i = 8
    while i < n - n % 8:
        j = lo + i
        r0 += v[j]
        r1 += v[j + 1]
        r2 += v[j + 2]
        r3 += v[j + 3]
        r4 += v[j + 4]
        r5 += v[j + 5]
        r6 += v[j + 6]
        r7 += v[j + 7]
        i += 8
    s = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        s += v[lo + i]
        i += 1
    return s


@njit(cache=True)
def pairwise_sum(v: FloatArray, lo: int, n: int) -> float:  # pragma: no cover - compiled
    """The sum of ``v[lo : lo + n]`` in the pairwise order of the module docstring.

    The halving is walked on an explicit stack: a self-recursive kernel is not safe in numba's on-disk cache.
    """
    if n <= 128:
        return _block_sum(v, lo, n)
    los = np.empty(64, np.int64)
    ns = np.empty(64, np.int64)
    stage = np.zeros(64, np.int64)
    vals = np.empty(64)
    top, nv = 0, 0
    los[0], ns[0] = lo, n
    while top >= 0:
        if ns[top] <= 128:
            vals[nv] = _block_sum(v, los[top], ns[top])
            nv += 1
            top -= 1
            continue
        half = ns[top] // 2
        half -= half % 8
        if stage[top] == 2:
            vals[nv - 2] = vals[nv - 2] + vals[nv - 1]
            nv -= 1
            top -= 1
            continue
        lo_child = los[top] if stage[top] == 0 else los[top] + half
        n_child = half if stage[top] == 0 else ns[top] - half
        stage[top] += 1
        top += 1
        los[top], ns[top], stage[top] = lo_child, n_child, 0
    return vals[0]
