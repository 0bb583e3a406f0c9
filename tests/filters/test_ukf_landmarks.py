"""The unscented landmark filter: agreement with the EKF where the models are near-linear, headings across +-pi,
and tracking on the synthetic scenarios."""

from __future__ import annotations

import math

import numpy as np
import pytest
from kalman_reference import range_bearing
from numpy.testing import assert_allclose

pytest.importorskip("filterpy")

from locbench.core.errors import ConfigError
from locbench.core.events import LandmarkObservations, Odometry, PoseFix, RangeObservations
from locbench.core.geometry import wrap_angle
from locbench.core.seeding import filter_rng
from locbench.datasets.dataset import Gaussian2, Landmarks, SensorSpec, WorldMap
from locbench.evaluate.metrics import align, ate
from locbench.filters._noise import DEFAULT_PROCESS_SIGMA_THETA_RAD
from locbench.filters.ekf_landmarks import LandmarkEKF, LandmarkEKFConfig
from locbench.filters.ukf_landmarks import LandmarkUKF, LandmarkUKFConfig, circular_mean
from locbench.registry import FILTERS, make_dataset, resolve_filter
from locbench.run.filter_pass import run_filter

W = 0.4
SENSORS = SensorSpec(
    wheelbase_m=W,
    encoder_k_left=0.01,
    encoder_k_right=0.01,
    landmark_sigma_range_m=0.05,
    landmark_sigma_bearing_rad=0.02,
    range_sigma_m=0.1,
)
LANDMARKS = Landmarks(ids=np.array([10, 11, 12], dtype=np.int64), xy=np.array([[3.0, 1.0], [-3.0, -0.03], [1.0, -4.0]]))
WORLD = WorldMap(landmarks=LANDMARKS)
RNG = np.random.default_rng(0)


def _pair(mean: tuple[float, float, float], cov: np.ndarray) -> tuple[LandmarkEKF, LandmarkUKF]:
    ekf, ukf = LandmarkEKF(LandmarkEKFConfig(use_pose_fixes=True)), LandmarkUKF(LandmarkUKFConfig(use_pose_fixes=True))
    for f in (ekf, ukf):
        f.reset(Gaussian2(np.array(mean), cov), WORLD, SENSORS, RNG)
    return ekf, ukf


def test_a_pose_fix_is_linear_so_the_ukf_equals_the_ekf() -> None:
    P0 = np.array([[0.04, 0.01, -0.005], [0.01, 0.09, 0.002], [-0.005, 0.002, 0.01]])
    ekf, ukf = _pair((0.2, -0.1, 0.4), P0)
    fix = PoseFix(0.1, np.array([0.35, -0.2]), np.diag([0.03, 0.05]))
    ekf.update(fix)
    ukf.update(fix)
    a, b = ekf.estimate(), ukf.estimate()
    assert_allclose(b.mean, a.mean, atol=1e-12)
    assert_allclose(b.cov, a.cov, atol=1e-12)
    assert b.diagnostics["nis"] == pytest.approx(a.diagnostics["nis"], rel=1e-9)


def test_with_a_small_covariance_the_ukf_agrees_with_the_ekf() -> None:
    # Sigma points 1 mm apart see the models as linear: prediction and landmark/range updates agree to first order.
    P0 = np.diag([1e-6, 2e-6, 1e-7])
    ekf, ukf = _pair((0.5, 0.2, 0.3), P0)
    events = [
        Odometry(0.1, 0.05, 0.0, 0.01, d_left=0.048, d_right=0.052),
        LandmarkObservations(0.1, np.array([10, 12]), np.array([2.6, 4.5]), np.array([0.05, -1.75])),
        RangeObservations(0.2, np.array([11]), np.array([3.6])),
    ]
    for ev in events:
        for f in (ekf, ukf):
            f.predict(ev) if isinstance(ev, Odometry) else f.update(ev)
        a, b = ekf.estimate(), ukf.estimate()
        assert_allclose(b.mean, a.mean, atol=1e-6)
        assert_allclose(b.cov, a.cov, rtol=1e-3, atol=1e-10)
        assert b.diagnostics["accepted"] == a.diagnostics["accepted"]


def test_circular_mean_across_pi() -> None:
    w = np.array([0.5, 0.25, 0.25])
    angles = np.array([math.pi - 0.01, -math.pi + 0.01, math.pi - 0.03])  # their arithmetic mean is about 1.57
    assert abs(wrap_angle(circular_mean(angles, w) - (math.pi - 0.01))) < 1e-4


def test_sigma_points_straddling_pi_keep_the_heading_and_its_variance() -> None:
    # Heading 0.001 rad short of pi with sigma 0.1: half the sigma points sit beyond the cut.
    _, ukf = _pair((0.0, 0.0, math.pi - 0.001), np.diag([0.01, 0.01, 0.01]))
    ukf.predict(Odometry(0.1, 0.0, 0.0, 0.0))
    est = ukf.estimate()
    assert abs(wrap_angle(est.mean[2] - (math.pi - 0.001))) < 1e-9
    assert est.cov[2, 2] == pytest.approx(0.01 + DEFAULT_PROCESS_SIGMA_THETA_RAD**2, rel=1e-9)


def test_bearing_innovation_is_wrapped_across_pi() -> None:
    # Landmark 11 is straight behind the robot: predicted bearing -pi + 0.01, measured pi - 0.01 (2 cm off).
    _, ukf = _pair((0.0, 0.0, 0.0), np.diag([0.01, 0.01, 0.01]))
    lm = LANDMARKS.xy[1]
    predicted = float(range_bearing(np.zeros(3), lm)[1])
    assert predicted < -math.pi + 0.02
    ukf.update(LandmarkObservations(0.1, np.array([11]), np.array([3.0]), np.array([math.pi - 0.01])))
    est = ukf.estimate()
    assert est.diagnostics["accepted"] == 1.0
    assert est.diagnostics["nis"] < 1.0  # an unwrapped innovation of ~2 pi would give ~1e5
    assert abs(est.mean[2]) < 0.03


def test_gated_out_range_leaves_the_state_unchanged() -> None:
    _, ukf = _pair((0.0, 0.0, 0.0), np.diag([0.01, 0.01, 0.001]))
    before = ukf.estimate()
    ukf.update(RangeObservations(0.1, np.array([10]), np.array([30.0])))
    after = ukf.estimate()
    assert after.diagnostics["rejected"] == 1.0
    assert np.array_equal(before.mean, after.mean) and np.array_equal(before.cov, after.cov)


@pytest.mark.parametrize("kw", [{"alpha": 0.0}, {"alpha": 1.5}, {"beta": -1.0}, {"kappa": -3.0}])
def test_bad_sigma_point_parameters_are_rejected(kw: dict[str, float]) -> None:
    with pytest.raises(ConfigError):
        LandmarkUKFConfig(**kw)  # type: ignore[arg-type]


def _ate(spec: str, dataset: str, seed: int) -> float:
    ds = make_dataset(dataset, seed)
    fr = resolve_filter(spec)
    tr = run_filter(FILTERS.load(fr.id)(fr.params), ds, filter_rng(fr.name, ds.name, seed))
    assert tr.status == "ok", tr.message
    return ate(align(tr.t, tr.mean, ds.ground_truth.t, ds.ground_truth.poses))


@pytest.mark.parametrize("seed", [0, 1])
def test_tracks_room_like_the_ekf(seed: int) -> None:
    ekf, ukf = _ate("ekf_landmarks", "room", seed), _ate("ukf_landmarks", "room", seed)
    assert ukf < 0.05
    assert ukf < 1.25 * ekf


@pytest.mark.slow
def test_tracks_office_like_the_ekf() -> None:
    ekf, ukf = _ate("ekf_landmarks", "office", 0), _ate("ukf_landmarks", "office", 0)
    assert ukf < 0.06
    assert ukf < 1.25 * ekf
