"""The zero-order hold: the row in force at a time, and each row's share of sorted query times."""

from __future__ import annotations

import numpy as np
import pytest

from locbench.evaluate.hold import estimate_at, hold_ends, hold_indices


def test_hold_ends_split_the_queries_by_the_row_in_force() -> None:
    rows_t = [0.0, 1.0, 1.0, 2.0]  # two rows at 1 s: the later one holds, the earlier none
    queries = [-1.0, 0.0, 0.5, 1.0, 1.5, 2.0, 3.0]
    assert hold_indices(rows_t, queries).tolist() == [0, 0, 0, 2, 2, 3, 3]
    assert hold_ends(rows_t, queries).tolist() == [3, 3, 5, 7]


def test_hold_ends_agree_with_hold_indices_on_random_times() -> None:
    rng = np.random.default_rng(7)
    for _ in range(50):
        rows_t = np.sort(np.round(rng.uniform(0.0, 10.0, rng.integers(1, 30)), 1))
        queries = np.sort(np.round(rng.uniform(-1.0, 11.0, rng.integers(0, 40)), 1))  # ties with the rows
        ends = hold_ends(rows_t, queries)
        assert ends.shape == rows_t.shape and ends[-1] == queries.size
        held = np.repeat(np.arange(rows_t.size), np.diff(ends, prepend=0))
        np.testing.assert_array_equal(held, hold_indices(rows_t, queries))


def test_no_estimates_is_an_error() -> None:
    with pytest.raises(ValueError, match="non-empty"):
        hold_ends([], [0.0])
    with pytest.raises(ValueError, match="non-empty"):
        estimate_at([], np.zeros((0, 3)), [0.0])
