"""The Kalman core: the Joseph update against the textbook forms, the residual hook, NIS, likelihood, gates."""

from __future__ import annotations

import math

import numpy as np
import pytest
from kalman_reference import joseph_correct_pose
from numpy.testing import assert_allclose
from scipy.stats import chi2, multivariate_normal

from locbench.filters._kalman import (
    chi2_1dof_quantile,
    chi2_2dof_quantile,
    chi2_quantile,
    gain_update,
    inside_gate,
    joseph_correct,
    joseph_update,
    wrapped_residual,
)

P = np.array([[0.04, 0.01, -0.005], [0.01, 0.09, 0.002], [-0.005, 0.002, 0.01]])
X = np.array([0.2, -0.1, 2.9])
H = np.array([[1.0, 0.5, 0.0], [0.0, 0.2, -1.0]])
R = np.diag([0.05**2, 0.02**2])


def test_joseph_update_equals_the_standard_form_for_the_optimal_gain() -> None:
    z = np.array([0.4, -0.3])
    c = joseph_update(X, P, z, H @ X, H, R)
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    assert_allclose(c.x, X + K @ (z - H @ X), atol=1e-14)
    assert_allclose(c.P, (np.eye(3) - K @ H) @ P, atol=1e-14)
    assert_allclose(c.S, S)
    assert_allclose(c.K, K)
    assert np.array_equal(c.P, c.P.T)


def test_nis_and_log_likelihood() -> None:
    z = np.array([0.4, -0.3])
    c = joseph_update(X, P, z, H @ X, H, R)
    assert c.nis == pytest.approx(float(c.y @ np.linalg.solve(c.S, c.y)), rel=1e-12)
    assert c.log_likelihood == pytest.approx(multivariate_normal(np.zeros(2), c.S).logpdf(c.y), rel=1e-12)


def test_residual_hook_wraps_the_angle_component() -> None:
    h = np.array([1.0, -math.pi + 0.01])
    z = np.array([1.1, math.pi - 0.01])
    y = wrapped_residual([1])(z, h)
    assert_allclose(y, [0.1, -0.02], atol=1e-12)
    plain = joseph_update(X, P, z, h, H, R)
    wrapped = joseph_update(X, P, z, h, H, R, wrapped_residual([1]))
    assert plain.nis > 1000.0 > 10.0 > wrapped.nis


def test_joseph_correct_with_identity_is_the_direct_pose_update() -> None:
    """With H = I the correction is the textbook direct update: K = P (P + R)^-1, P+ = (I - K) P (I - K)^T + K R K^T
    (tests/kalman_reference.py), to rounding, on random beliefs."""
    rng = np.random.default_rng(7)
    for _ in range(200):
        a = rng.standard_normal((3, 3)) * rng.uniform(1e-3, 3.0)
        Pr = a @ a.T + 1e-9 * np.eye(3)
        Rp = np.diag(rng.uniform(1e-6, 1.0, size=3))
        x, v = rng.standard_normal(3), rng.standard_normal(3) * 0.1
        c = joseph_correct(x, Pr, v, np.eye(3), Rp)
        xn, Pn, nis = joseph_correct_pose(x, Pr, v, Rp)
        assert_allclose(c.x, xn, rtol=1e-13, atol=1e-15)
        scale = np.sqrt(np.outer(np.diag(Pn), np.diag(Pn)))
        assert_allclose(c.P / scale, Pn / scale, rtol=0, atol=1e-12)
        assert c.nis == pytest.approx(nis, rel=1e-12)
        assert np.array_equal(c.P, c.P.T)


def test_gain_update_equals_the_joseph_update_for_a_linear_model() -> None:
    z = np.array([0.4, -0.3])
    a = joseph_update(X, P, z, H @ X, H, R)
    b = gain_update(X, P, z - H @ X, H @ P @ H.T + R, P @ H.T)
    assert_allclose(b.x, a.x, atol=1e-14)
    assert_allclose(b.P, a.P, atol=1e-14)
    assert b.nis == pytest.approx(a.nis, rel=1e-12)


@pytest.mark.parametrize("p", [0.5, 0.95, 0.99])
def test_chi2_quantiles_match_scipy(p: float) -> None:
    assert chi2_1dof_quantile(p) == pytest.approx(chi2.ppf(p, 1), rel=1e-9)
    assert chi2_2dof_quantile(p) == pytest.approx(chi2.ppf(p, 2), rel=1e-9)
    assert chi2_quantile(p, 3) == pytest.approx(chi2.ppf(p, 3), rel=1e-9)
    assert chi2_quantile(1.0, 2) == math.inf


def test_gate() -> None:
    assert inside_gate(9.0, chi2_2dof_quantile(0.99))
    assert not inside_gate(9.3, chi2_2dof_quantile(0.99))
    assert not inside_gate(math.nan, math.inf)
