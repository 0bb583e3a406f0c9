"""The dead-reckoning baseline: composed increments, exactly; a covariance from the nominal noise."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from locbench.core.events import LandmarkObservations, Odometry, PoseFix
from locbench.core.geometry import compose, is_symmetric_psd
from locbench.datasets.dataset import Gaussian2, Landmarks, SensorSpec, WorldMap
from locbench.filters.odometry import OdometryConfig, OdometryFilter
from locbench.registry import make_filter

W = 0.4
SENSORS = SensorSpec(
    wheelbase_m=W,
    encoder_k_left=0.01,
    encoder_k_right=0.012,
    odometry_sigma_xy_per_m=0.03,
    odometry_sigma_theta_per_m=0.02,
    odometry_sigma_theta_per_rad=0.05,
)
INITIAL = Gaussian2(np.array([1.0, -1.0, 3.0]), np.diag([1e-4, 1e-4, 1e-5]))


def odometry_events(n: int = 200, wheels: bool = True) -> list[Odometry]:
    """A wiggly drive whose heading crosses +-pi; the increment and wheel travel disagree slightly, on purpose."""
    out = []
    for k in range(n):
        dth = 0.04 * math.sin(0.1 * k)
        dd = 0.05 + 0.01 * math.cos(0.3 * k)
        dx, dy = dd * math.cos(dth / 2), dd * math.sin(dth / 2)
        extra = {"d_left": dd - dth * W / 2 + 1e-4, "d_right": dd + dth * W / 2} if wheels else {}
        out.append(Odometry(0.1 * (k + 1), dx, dy, dth, **extra))
    return out


def run(flt: OdometryFilter, events: list[Odometry]) -> tuple[np.ndarray, np.ndarray]:
    flt.reset(INITIAL, WorldMap(), SENSORS, np.random.default_rng(0))
    means, covs = [], []
    for u in events:
        flt.predict(u)
        est = flt.estimate()
        means.append(est.mean)
        covs.append(est.cov)
    return np.array(means), np.array(covs)


@pytest.mark.parametrize("noise_model", ["auto", "encoder", "increment"])
def test_reproduces_composed_increments(noise_model: str) -> None:
    events = odometry_events()
    means, _ = run(OdometryFilter(OdometryConfig(noise_model=noise_model)), events)  # type: ignore[arg-type]
    pose = INITIAL.mean
    for k, u in enumerate(events):
        pose = compose(pose, u.delta)
        assert_allclose(means[k], pose, rtol=0, atol=1e-12)
    assert np.ptp(means[:, 2]) > math.pi  # the heading went through +-pi and stayed wrapped
    assert np.all((means[:, 2] > -math.pi) & (means[:, 2] <= math.pi))


def test_covariance_grows_and_stays_symmetric_psd() -> None:
    _, covs = run(OdometryFilter(), odometry_events())
    dets = [np.linalg.det(c) for c in covs]
    assert all(b >= a for a, b in itertools.pairwise(dets))
    assert all(is_symmetric_psd(c) for c in covs)
    assert np.trace(covs[-1]) > 10 * np.trace(INITIAL.cov)


def test_noise_model_changes_only_the_covariance() -> None:
    m_enc, c_enc = run(OdometryFilter(OdometryConfig(noise_model="encoder")), odometry_events())
    m_inc, c_inc = run(OdometryFilter(OdometryConfig(noise_model="increment")), odometry_events())
    assert_allclose(m_enc, m_inc, rtol=0, atol=0)
    assert not np.allclose(c_enc[-1], c_inc[-1])


def test_increment_noise_matches_the_nominal_variances() -> None:
    # Straight 1 m from a zero covariance in 10 steps: x-variance along the track is 10 * sigma^2 * 0.1 m.
    flt = OdometryFilter(OdometryConfig(noise_model="increment"))
    flt.reset(Gaussian2(np.zeros(3), np.zeros((3, 3))), WorldMap(), SENSORS, np.random.default_rng(0))
    for k in range(10):
        flt.predict(Odometry(0.1 * k, 0.1, 0.0, 0.0))
    est = flt.estimate()
    assert est.cov[0, 0] == pytest.approx(0.03**2 * 1.0)
    assert est.cov[2, 2] == pytest.approx(0.02**2 * 1.0)
    assert est.diagnostics["distance_m"] == pytest.approx(1.0)
    assert est.t == pytest.approx(0.9)


def test_without_wheel_travel_auto_uses_increments() -> None:
    a, ca = run(OdometryFilter(), odometry_events(wheels=False))
    b, cb = run(OdometryFilter(OdometryConfig(noise_model="increment")), odometry_events(wheels=False))
    assert_allclose(a, b, rtol=0, atol=0)
    assert_allclose(ca, cb, rtol=0, atol=0)


def test_update_raises_type_error() -> None:
    flt = OdometryFilter()
    flt.reset(INITIAL, WorldMap(), SENSORS, np.random.default_rng(0))
    obs = LandmarkObservations(0.0, np.array([0]), np.array([1.0]), np.array([0.0]))
    for z in (obs, PoseFix(0.0, np.zeros(2), np.eye(2))):
        with pytest.raises(TypeError, match="does not consume"):
            flt.update(z)


def test_contract_and_registry() -> None:
    flt = make_filter("odometry[noise_model=increment]")
    assert isinstance(flt, OdometryFilter)
    assert flt.config == OdometryConfig(noise_model="increment")
    assert OdometryFilter.consumes == frozenset({Odometry})
    assert OdometryFilter.requires == frozenset()
    assert flt.routed_events() == frozenset({Odometry})
    assert not hasattr(flt, "_x")  # __init__ does no work


def test_deterministic_and_reset_restarts() -> None:
    flt = OdometryFilter()
    m1, c1 = run(flt, odometry_events())
    m2, c2 = run(flt, odometry_events())  # same instance, reset again
    _, c3 = run(OdometryFilter(), odometry_events())
    assert_allclose(m1, m2, rtol=0, atol=0)
    assert_allclose(c1, c3, rtol=0, atol=0)
    assert_allclose(c2, c3, rtol=0, atol=0)


def test_estimate_returns_copies() -> None:
    flt = OdometryFilter()
    flt.reset(
        INITIAL, WorldMap(landmarks=Landmarks(np.array([0]), np.zeros((1, 2)))), SENSORS, np.random.default_rng(0)
    )
    est = flt.estimate()
    est.mean[0] = 99.0
    est.cov[0, 0] = 99.0
    assert flt.estimate().mean[0] == 1.0
    assert math.isnan(est.t)
