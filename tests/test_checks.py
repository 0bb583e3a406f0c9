"""Each conformance check rejects a filter broken in exactly the way it looks for (scikit-learn's
``test_estimator_checks.py``), and the unbroken base passes it, so the rejection is the flaw's doing.

The broken filters are not registered: the checks take a class or an instance.
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np
import pytest

from locbench.checks import (
    FILTER_CHECKS,
    CheckFailed,
    check_contract,
    check_determinism,
    check_empty_observation,
    check_estimate_sanity,
    check_filter,
    check_heading_wrap,
    check_health_and_scores,
    check_noise_free,
    check_predict_grows_uncertainty,
    check_rejects_unconsumed,
    yield_filter_checks,
)
from locbench.core.events import LandmarkObservations, Observation, Odometry
from locbench.core.geometry import wrap_scalar
from locbench.datasets.dataset import Gaussian2, SensorSpec, WorldMap
from locbench.filters.base import CheckTolerances, Estimate, FilterConfig
from locbench.filters.ekf_landmarks import LandmarkEKF
from locbench.filters.odometry import OdometryFilter


class WorkInInit(OdometryFilter):
    """Builds a table in __init__ (scikit-learn's rule: __init__ stores the parameters only)."""

    def __init__(self, config: FilterConfig | None = None) -> None:
        super().__init__(config)
        self.table = np.zeros(10)


class NoOdometry(OdometryFilter):
    """Declares that it consumes observations but not odometry."""

    consumes: ClassVar[frozenset[type]] = frozenset({LandmarkObservations})


class AcceptsAnything(OdometryFilter):
    """Silently ignores observations it does not consume instead of raising TypeError."""

    def update(self, z: Observation) -> None:
        pass


class GlobalRandom(OdometryFilter):
    """Draws noise from an unseeded generator instead of the rng handed to reset."""

    def predict(self, u: Odometry) -> None:
        super().predict(u)
        jitter = np.random.default_rng().normal(0.0, 1e-6)
        self._x = (self._x[0] + jitter, self._x[1], self._x[2])


class AsymmetricCovariance(OdometryFilter):
    """Reports a covariance that is not symmetric."""

    def estimate(self) -> Estimate:
        est = super().estimate()
        cov = est.cov.copy()
        cov[0, 1] += 1e-3
        return Estimate(est.t, est.mean, cov, est.diagnostics)


class NegativeVariance(OdometryFilter):
    """Reports a symmetric covariance with a negative heading variance (not PSD)."""

    def estimate(self) -> Estimate:
        est = super().estimate()
        cov = est.cov.copy()
        cov[2, 2] = -1e-3
        return Estimate(est.t, est.mean, cov, est.diagnostics)


class UnwrappedHeading(OdometryFilter):
    """Adds the heading increments without wrapping: the heading leaves (-pi, pi] on a circle."""

    def reset(self, initial: Gaussian2, world: WorldMap, sensors: SensorSpec, rng: np.random.Generator) -> None:
        super().reset(initial, world, sensors, rng)
        self._theta = self._x[2]

    def predict(self, u: Odometry) -> None:
        super().predict(u)
        self._theta += u.dtheta
        self._x = (self._x[0], self._x[1], self._theta)


class ClampedHeading(OdometryFilter):
    """Clamps the heading to [-3, 3] rad instead of wrapping it: stays in range but is wrong near +-pi."""

    def predict(self, u: Odometry) -> None:
        super().predict(u)
        self._x = (self._x[0], self._x[1], min(max(wrap_scalar(self._x[2]), -3.0), 3.0))


class ScaledOdometry(OdometryFilter):
    """Misreads the odometry by 10 %: wrong even on exact data."""

    def predict(self, u: Odometry) -> None:
        super().predict(Odometry(u.t, 1.1 * u.dx, 1.1 * u.dy, u.dtheta))


class ShrinkingPredict(OdometryFilter):
    """Scales P down on each predict."""

    def predict(self, u: Odometry) -> None:
        super().predict(u)
        self._P = [[0.9 * v for v in row] for row in self._P]


class MovesOnEmptySightings(LandmarkEKF):
    """Nudges the pose on every landmark event, even one without sightings."""

    def update(self, z: Observation) -> None:
        super().update(z)
        if isinstance(z, LandmarkObservations):
            self._x = [self._x[0] + 0.01, self._x[1], self._x[2]]


class LooseOdometry(OdometryFilter):
    """Widens the noise-free bound past ScaledOdometry's error: the check must read the hook."""

    def check_tolerances(self) -> CheckTolerances:
        return CheckTolerances(noise_free_ate_m=10.0)


class LooseScaledOdometry(ScaledOdometry, LooseOdometry):
    pass


class SamplesWithItsOwnStream(OdometryFilter):
    """Draws its belief sample from the filter's own generator: its later estimates change."""

    def reset(self, initial: Gaussian2, world: WorldMap, sensors: SensorSpec, rng: np.random.Generator) -> None:
        super().reset(initial, world, sensors, rng)
        self._own = rng

    def predict(self, u: Odometry) -> None:
        super().predict(u)
        x, y, th = self._x
        self._x = (x + 1e-3 * float(self._own.standard_normal()), y, th)

    def belief_sample(self, rng: np.random.Generator, size: int) -> tuple[np.ndarray, np.ndarray]:
        self._own.standard_normal()
        return np.array([self._x]), np.ones(1)


class UnnamedHealth(OdometryFilter):
    """Reports a health signal nobody declared."""

    def health(self) -> dict[str, float]:
        return {"mood": 1.0}


BROKEN = [
    (check_contract, WorkInInit, OdometryFilter),
    (check_contract, NoOdometry, OdometryFilter),
    (check_rejects_unconsumed, AcceptsAnything, OdometryFilter),
    (check_determinism, GlobalRandom, OdometryFilter),
    (check_estimate_sanity, AsymmetricCovariance, OdometryFilter),
    (check_estimate_sanity, NegativeVariance, OdometryFilter),
    (check_heading_wrap, UnwrappedHeading, OdometryFilter),
    (check_heading_wrap, ClampedHeading, OdometryFilter),
    (check_noise_free, ScaledOdometry, OdometryFilter),
    (check_predict_grows_uncertainty, ShrinkingPredict, OdometryFilter),
    (check_empty_observation, MovesOnEmptySightings, LandmarkEKF),
    (check_health_and_scores, SamplesWithItsOwnStream, OdometryFilter),
    (check_health_and_scores, UnnamedHealth, OdometryFilter),
]


@pytest.mark.parametrize(("check", "broken", "base"), BROKEN, ids=[f"{c.__name__}-{b.__name__}" for c, b, _ in BROKEN])
def test_check_rejects_its_broken_filter(check: object, broken: type, base: type) -> None:
    assert callable(check)
    check(base())  # the unbroken base passes ...
    with pytest.raises(CheckFailed):
        check(broken())  # ... the flaw is rejected


def test_every_check_has_a_broken_filter() -> None:
    covered = {c.__name__ for c, _, _ in BROKEN}
    assert covered == set(FILTER_CHECKS)


def test_checks_take_a_class_or_an_instance() -> None:
    with pytest.raises(CheckFailed):
        FILTER_CHECKS["check_noise_free"](ScaledOdometry)
    with pytest.raises(CheckFailed):
        FILTER_CHECKS["check_noise_free"](ScaledOdometry())


def test_tolerance_hook_is_read_from_the_filter() -> None:
    check_noise_free(LooseScaledOdometry())


def test_checks_are_selected_by_capability() -> None:
    odo = {c.name: reason for c, reason in yield_filter_checks(OdometryFilter)}
    assert odo["check_empty_observation"] is not None  # consumes no point observations
    assert odo["check_rejects_unconsumed"] is None
    ekf = {c.name: reason for c, reason in yield_filter_checks(LandmarkEKF)}
    assert all(reason is None for reason in ekf.values())


def test_check_filter_honours_declared_failures() -> None:
    class DeclaredScaled(ScaledOdometry):
        expected_check_failures: ClassVar[dict[str, str]] = {"check_noise_free": "misreads odometry by design"}

    class DeclaredButFine(OdometryFilter):
        expected_check_failures: ClassVar[dict[str, str]] = {"check_noise_free": "claims a flaw it has not"}

    out = {r.check: r.outcome for r in check_filter(DeclaredScaled)}
    assert out["check_noise_free"] == "xfailed"
    assert out["check_contract"] == "passed"
    assert out["check_empty_observation"] == "skipped"
    assert {r.check: r.outcome for r in check_filter(DeclaredButFine)}["check_noise_free"] == "xpassed"


def test_unwrapped_heading_really_leaves_the_interval() -> None:
    # Guard of the broken filter itself: on the circle its heading must exceed pi for the test above to mean much.
    from locbench.registry import make_dataset
    from locbench.run.filter_pass import run_filter

    tr = run_filter(UnwrappedHeading(), make_dataset("tiny_circle", 0), np.random.default_rng(0))
    # the runner's estimate contract stops it at the first heading outside [-pi, pi], the last row it keeps
    assert tr.status == "error" and tr.message.startswith("estimate contract: heading")
    assert abs(tr.mean[-1, 2]) > math.pi >= np.max(np.abs(tr.mean[:-1, 2]))
