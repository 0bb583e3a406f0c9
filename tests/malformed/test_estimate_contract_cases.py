"""The estimate contract's checks (locbench.run.contract) at their tolerances: what passes, what fails, which row is
named."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from locbench.run.contract import (
    HEADING_ATOL,
    PSD_RTOL,
    SYMMETRY_RTOL,
    EstimateContractError,
    check_shapes,
    first_violation,
)


def _trace(n: int = 5, scale: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = np.arange(n, dtype=float) * 0.5
    mean = np.zeros((n, 3))
    cov = np.tile(np.diag([2.0, 1.0, 0.5]) * scale, (n, 1, 1))
    return t, mean, cov


def test_a_good_trace_passes() -> None:
    t, mean, cov = _trace()
    mean[:, 2] = [math.pi, -math.pi, 0.0, 3.0, -3.0]
    cov[:, 0, 1] = cov[:, 1, 0] = 0.3
    assert first_violation(t, mean, cov) is None
    assert first_violation(t[:0], mean[:0], cov[:0]) is None


@pytest.mark.parametrize("scale", [1e-6, 1.0, 1e4])
def test_symmetry_is_judged_relative_to_the_largest_entry(scale: float) -> None:
    t, mean, cov = _trace(scale=scale)
    tol = SYMMETRY_RTOL * max(1.0, 2.0 * scale)
    cov[1, 0, 1] += 0.5 * tol
    assert first_violation(t, mean, cov) is None
    cov[3, 0, 1] += 4.0 * tol
    found = first_violation(t, mean, cov)
    assert found is not None and found[0] == 3
    assert found[1].startswith("estimate contract: covariance not symmetric at t=1.500 s (row 3)")


def test_a_negative_eigenvalue_beyond_the_tolerance_fails() -> None:
    t, mean, cov = _trace()
    cov[2, 2, 2] = -0.5 * PSD_RTOL * 2.0
    assert first_violation(t, mean, cov) is None
    cov[4, 2, 2] = -1e-3
    found = first_violation(t, mean, cov)
    assert found is not None and found[0] == 4 and "not positive semi-definite" in found[1] and "-0.001" in found[1]


def test_a_heading_outside_the_wrap_fails_and_the_first_violation_is_named() -> None:
    t, mean, cov = _trace()
    mean[1, 2] = math.pi + 0.5 * HEADING_ATOL
    assert first_violation(t, mean, cov) is None
    mean[2, 2] = 100.0
    cov[3, 0, 1] = 1.0  # a later violation of another kind
    found = first_violation(t, mean, cov)
    assert found is not None and found[0] == 2 and found[1].startswith("estimate contract: heading 100 rad at t=1.000")


def test_non_finite_rows_are_left_to_the_divergence_check() -> None:
    t, mean, cov = _trace()
    mean[2, 2] = np.nan
    cov[3, 0, 1] = np.inf
    assert first_violation(t, mean, cov) is None


@pytest.mark.parametrize(
    ("mean", "cov", "what"),
    [
        (np.zeros(2), np.eye(3), "mean of shape (2,)"),
        (np.zeros((1, 3)), np.eye(3), "mean of shape (1, 3)"),
        (np.zeros(3), np.ones(3), "covariance of shape (3,)"),
        (np.zeros(3), np.eye(2), "covariance of shape (2, 2)"),
        (np.zeros(3), [[1.0, 0.0], [0.0]], "covariance of shape unknown (list)"),
    ],
)
def test_shapes_other_than_the_contract_are_refused(mean: object, cov: object, what: str) -> None:
    with pytest.raises(EstimateContractError, match=rf"^estimate contract: {re.escape(what)} at t=2.500 s"):
        check_shapes(mean, cov, 2.5)
    check_shapes([0.0, 0.0, 0.0], np.eye(3).tolist(), 2.5)  # sequences of the right shape are accepted
