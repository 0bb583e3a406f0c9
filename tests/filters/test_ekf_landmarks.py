"""The landmark EKF (report 003 with report 001's sensor model and GPS update); its compiled kernels against the
reference forms (tests/kalman_reference.py, the Kalman core's numpy Joseph update) and against the motion model's
Python path, which runs the same source."""

from __future__ import annotations

import math

import numpy as np
import pytest
import range_only_support as ro
from kalman_reference import range_bearing, range_bearing_jacobian
from numpy.testing import assert_allclose

from locbench.core.errors import ConfigError, FilterDiverged
from locbench.core.events import UNKNOWN_ID, LandmarkObservations, LaserScan, Odometry, PoseFix, RangeObservations
from locbench.core.geometry import between, is_symmetric_psd, pose_error, wrap_angle
from locbench.datasets.dataset import Gaussian2, Landmarks, MapKind, SensorSpec, WorldMap
from locbench.filters import _ekf_kernels as kern
from locbench.filters._kalman import chi2_1dof_quantile, chi2_2dof_quantile, joseph_update, wrapped_residual
from locbench.filters._motion import MotionModel, predict_midpoint, propagate_covariance, resolve_motion_noise
from locbench.filters.ekf_landmarks import LandmarkEKF, LandmarkEKFConfig
from locbench.registry import make_filter

W = 0.4
SENSORS = SensorSpec(
    wheelbase_m=W,
    encoder_k_left=0.005,
    encoder_k_right=0.005,
    landmark_sigma_range_m=0.05,
    landmark_sigma_bearing_rad=0.02,
)
LANDMARKS = Landmarks(ids=np.array([10, 11, 12, 13]), xy=np.array([[3.0, 2.0], [3.0, -2.0], [-1.0, 2.0], [-1.0, -2.0]]))
WORLD = WorldMap(landmarks=LANDMARKS)
RNG = np.random.default_rng(0)


def big_world(n: int = 60) -> WorldMap:
    """``n`` landmarks on a grid 1.5 m apart (well separated), ids 100.. in shuffled order."""
    g = np.arange(n)
    xy = np.stack([-4.0 + 1.5 * (g % 8), -4.0 + 1.5 * (g // 8)], axis=-1)
    ids = 100 + np.random.default_rng(5).permutation(n)
    return WorldMap(landmarks=Landmarks(ids=ids, xy=xy))


def make_ekf(**kw: object) -> LandmarkEKF:
    return LandmarkEKF(LandmarkEKFConfig(**kw))  # type: ignore[arg-type]


def drive(
    n: int, world: WorldMap = WORLD, start: tuple[float, float, float] = (0.0, 0.0, 0.0), ids_known: bool = True
) -> tuple[list[Odometry | LandmarkObservations], np.ndarray]:
    """A noise-free drive (wheel travel moved exactly with eq. 5) observing every landmark exactly each step."""
    assert world.landmarks is not None
    pose = np.array(start)
    events: list[Odometry | LandmarkObservations] = []
    truth = []
    for k in range(n):
        t = 0.1 * (k + 1)
        dl = 0.05
        dr = 0.05 + 0.008 * math.sin(0.05 * k)
        new = predict_midpoint(pose, 0.5 * (dl + dr), (dr - dl) / W)
        inc = between(pose, new)
        events.append(Odometry(t, float(inc[0]), float(inc[1]), float(inc[2]), d_left=dl, d_right=dr))
        zs = range_bearing(new, world.landmarks.xy)
        ids = world.landmarks.ids if ids_known else np.full(len(world.landmarks), UNKNOWN_ID)
        events.append(LandmarkObservations(t, ids.astype(np.int64), zs[:, 0].copy(), zs[:, 1].copy()))
        truth.append(new)
        pose = new
    return events, np.array(truth)


def run(
    flt: LandmarkEKF, events: list, initial: Gaussian2, world: WorldMap = WORLD, sensors: SensorSpec = SENSORS
) -> tuple[np.ndarray, np.ndarray, list[dict[str, float]]]:
    flt.reset(initial, world, sensors, RNG)
    means, covs, diags = [], [], []
    for ev in events:
        if isinstance(ev, Odometry):
            flt.predict(ev)
        else:
            flt.update(ev)
        est = flt.estimate()
        means.append(est.mean)
        covs.append(est.cov)
        diags.append(est.diagnostics)
    return np.array(means), np.array(covs), diags


def test_the_kernels_measurement_and_jacobian_against_the_reference_and_finite_differences() -> None:
    lm = np.array([2.0, -1.5])
    for pose in (np.array([0.3, 0.2, 0.4]), np.array([-1.0, 2.0, -3.0]), np.array([4.0, -1.0, 3.1])):
        s = np.concatenate([pose, 0.01 * np.eye(3).reshape(9)])
        ok, vr, vb, h00, h01, h10, h11, _, _, d, pb = kern._innovation(s, 3.0, 0.5, lm[0], lm[1], 1e-4, 1e-4)
        assert ok
        H = np.array([[h00, h01, 0.0], [h10, h11, -1.0]])  # the kernel's entries; H[0, 2] = 0, H[1, 2] = -1 implied
        assert_allclose(H, range_bearing_jacobian(pose, lm), rtol=1e-14, atol=1e-15)
        assert_allclose([d, pb], range_bearing(pose, lm), rtol=1e-14, atol=1e-15)
        assert_allclose([vr, vb], [3.0 - d, wrap_angle(0.5 - pb)], rtol=1e-14, atol=1e-15)
        num = np.zeros((2, 3))
        eps = 1e-7
        for i in range(3):
            e = np.zeros(3)
            e[i] = eps
            diff = range_bearing(pose + e, lm) - range_bearing(pose - e, lm)
            diff[1] = wrap_angle(diff[1])
            num[:, i] = diff / (2 * eps)
        assert_allclose(H, num, atol=1e-6)
        # Report 001 fig. 2 as printed: range row negated, bearing row with dx and dy swapped. It is wrong.
        dx, dy = lm - pose[:2]
        d = math.hypot(dx, dy)
        printed = np.array([[dx / d, dy / d, 0.0], [dx / d**2, -dy / d**2, -1.0]])
        assert not np.allclose(printed, num, atol=1e-3)


def test_chi2_quantile() -> None:
    assert chi2_2dof_quantile(0.99) == pytest.approx(9.2103, abs=1e-4)
    assert chi2_2dof_quantile(0.95) == pytest.approx(5.9915, abs=1e-4)


def test_scalar_update_matches_numpy_joseph_reference() -> None:
    P0 = np.array([[0.04, 0.01, -0.005], [0.01, 0.09, 0.002], [-0.005, 0.002, 0.01]])
    x0 = np.array([0.2, -0.1, 2.9])
    ekf = make_ekf()
    ekf.reset(Gaussian2(x0, P0), WORLD, SENSORS, RNG)
    z = np.array([3.7, -2.6])
    ekf.update(LandmarkObservations(0.0, np.array([12]), z[:1], z[1:]))
    lm = LANDMARKS.xy[2]
    H = range_bearing_jacobian(x0, lm)
    ref = joseph_update(x0, P0, z, range_bearing(x0, lm), H, np.diag([0.05**2, 0.02**2]), wrapped_residual([1]))
    est = ekf.estimate()
    assert_allclose(est.mean, [ref.x[0], ref.x[1], wrap_angle(ref.x[2])], atol=1e-12)
    assert_allclose(est.cov, ref.P, atol=1e-14)
    assert est.diagnostics["nis"] == pytest.approx(ref.nis)
    assert est.diagnostics["accepted"] == 1.0


def _random_state(rng: np.random.Generator) -> np.ndarray:
    a = rng.normal(size=(3, 3)) * 10.0 ** rng.uniform(-3.0, 0.0)
    P = a @ a.T + 1e-9 * np.eye(3)
    x = np.array([rng.normal() * 10.0, rng.normal() * 10.0, rng.uniform(-math.pi, math.pi)])
    return np.concatenate([x, (0.5 * (P + P.T)).reshape(9)])


@pytest.mark.parametrize("input_noise", ["per_step", "cumulative"])
def test_the_encoder_prediction_kernel_is_the_motion_models_step(input_noise: str) -> None:
    """The compiled prediction and MotionModel.step + propagate_covariance run the same source: the same bits on
    any machine (ours against ours)."""
    rng = np.random.default_rng(21)
    noise = resolve_motion_noise(SENSORS, input_noise=input_noise)  # type: ignore[arg-type]
    model = MotionModel(noise, "encoder")
    q = (1e-6, 2e-6, 3e-7)
    prm = np.array([W, noise.k_left, noise.k_right, float(input_noise == "cumulative"), 0.0, 0.0, *q])
    for _ in range(300):
        s = _random_state(rng)
        dl, dr = rng.normal(0.05, 0.05), rng.normal(0.05, 0.05)
        step = model.step(s[:3].tolist(), Odometry(0.0, 0.0, 0.0, 0.0, d_left=dl, d_right=dr))
        n00, n01, n02, n11, n12, n22 = step.noise
        P = propagate_covariance(s[3:].reshape(3, 3).tolist(), step.f02, step.f12,
                                 (n00 + q[0], n01, n02, n11 + q[1], n12, n22 + q[2]))  # fmt: skip
        assert kern.predict_encoder(s, dl, dr, prm)
        assert np.array_equal(s, np.concatenate([step.pose, np.reshape(P, 9)]))
        assert (prm[4], prm[5]) == (model.travelled_left, model.travelled_right)


def test_the_kernels_landmark_update_equals_the_numpy_joseph_form_on_random_beliefs() -> None:
    rng = np.random.default_rng(22)
    R = np.diag([0.05**2, 0.02**2])
    for _ in range(300):
        s = _random_state(rng)
        x0, P0 = s[:3].copy(), s[3:].reshape(3, 3).copy()
        lm = x0[:2] + rng.uniform(-5.0, 5.0, size=2)
        z = range_bearing(x0, lm) + rng.normal(size=2) * (0.05, 0.02)
        nis = kern.correct_landmark(s, z[0], z[1], lm[0], lm[1], R[0, 0], R[1, 1], math.inf)
        want = joseph_update(x0, P0, z, range_bearing(x0, lm), range_bearing_jacobian(x0, lm), R, wrapped_residual([1]))
        # to rounding: the kernel's closed-form 2 x 2 inverse and written-out products against LAPACK and BLAS (the
        # Joseph form's cancellation in a nearly singular posterior reaches ~2e-12 of the correlation scale)
        assert_allclose(s[:2], want.x[:2], rtol=1e-12, atol=1e-12 * float(np.max(np.abs(want.x[:2]))))
        assert abs(wrap_angle(s[2] - want.x[2])) <= 1e-12
        scale = np.sqrt(np.outer(np.diag(want.P), np.diag(want.P)))
        assert_allclose(s[3:].reshape(3, 3) / scale, want.P / scale, rtol=0, atol=1e-10)
        assert nis == pytest.approx(want.nis, rel=1e-10)


def test_joseph_keeps_covariance_symmetric_psd() -> None:
    # Nearly exact sensors and a huge prior: the hard case for a covariance update (gains near H^-1).
    sensors = SensorSpec(wheelbase_m=W, landmark_sigma_range_m=1e-6, landmark_sigma_bearing_rad=1e-7)
    events, _ = drive(150)
    initial = Gaussian2(np.array([0.05, -0.05, 0.02]), np.diag([100.0, 100.0, 10.0]))
    _, covs, _ = run(make_ekf(), events, initial, sensors=sensors)
    for c in covs:
        assert np.array_equal(c, c.T)
        assert is_symmetric_psd(c, atol=1e-12)
        assert np.all(np.diag(c) > 0)


def test_bearing_innovation_wraps_behind_the_robot() -> None:
    # A landmark straight behind, slightly to the left: predicted bearing just below +pi; measured just above -pi.
    world = WorldMap(landmarks=Landmarks(np.array([0]), np.array([[-2.0, 0.002]])))
    ekf = make_ekf(gate_known=True)
    initial = Gaussian2(np.zeros(3), np.diag([0.01, 0.01, 0.01]))
    ekf.reset(initial, world, SENSORS, RNG)
    predicted = range_bearing(np.zeros(3), [-2.0, 0.002])[1]
    assert predicted > 3.14
    ekf.update(LandmarkObservations(0.0, np.array([0]), np.array([2.0]), np.array([-math.pi + 0.001])))
    est = ekf.estimate()
    assert est.diagnostics["accepted"] == 1.0  # an unwrapped innovation of ~2 pi would be gated out
    assert est.diagnostics["nis"] < 0.1
    assert np.all(np.abs(est.mean) < 0.01)


@pytest.mark.parametrize("n_landmarks", [4, 60])
def test_known_and_nearest_association_agree_when_landmarks_are_separated(n_landmarks: int) -> None:
    world = WORLD if n_landmarks == 4 else big_world(n_landmarks)
    initial = Gaussian2(np.array([0.05, -0.03, 0.02]), np.diag([0.01, 0.01, 0.003]))
    known_events, _ = drive(30, world)
    unknown_events, _ = drive(30, world, ids_known=False)
    m_known, c_known, d_known = run(make_ekf(), known_events, initial, world)
    m_nn, c_nn, d_nn = run(make_ekf(association="nearest"), known_events, initial, world)
    m_unk, c_unk, _ = run(make_ekf(), unknown_events, initial, world)
    assert_allclose(m_nn, m_known, atol=1e-12)
    assert_allclose(c_nn, c_known, atol=1e-15)
    assert_allclose(m_unk, m_known, atol=1e-12)
    assert_allclose(c_unk, c_known, atol=1e-15)
    assert [d["accepted"] for d in d_nn] == [d["accepted"] for d in d_known]
    assert d_known[1]["accepted"] == n_landmarks


def test_gate_rejects_a_gross_outlier_and_counts_it() -> None:
    initial = Gaussian2(np.zeros(3), np.diag([0.01, 0.01, 0.003]))
    zs = range_bearing(np.zeros(3), LANDMARKS.xy)
    ranges = zs[:, 0].copy()
    ranges[1] += 3.0  # landmark 11 seen 3 m too far
    unknown = LandmarkObservations(0.0, np.full(4, UNKNOWN_ID), ranges, zs[:, 1].copy())
    known = LandmarkObservations(0.0, LANDMARKS.ids.copy(), ranges, zs[:, 1].copy())
    for cfg, z, accepted in (
        ({}, unknown, 3),
        ({"gate_known": True}, known, 3),
        ({}, known, 4),  # default: known ids are fused without a gate (report 003)
    ):
        ekf = make_ekf(**cfg)
        ekf.reset(initial, WORLD, SENSORS, RNG)
        ekf.update(z)
        d = ekf.estimate().diagnostics
        assert (d["accepted"], d["rejected"]) == (accepted, 4 - accepted), cfg
        if accepted == 3:
            assert d["nis"] < chi2_2dof_quantile(0.99) * 3
            assert np.all(np.abs(ekf.estimate().mean) < 1e-9)  # exact observations of the true pose


def test_invalid_and_unmapped_observations_are_rejected() -> None:
    ekf = make_ekf()
    ekf.reset(Gaussian2(np.zeros(3), np.eye(3) * 0.01), WORLD, SENSORS, RNG)
    ekf.update(LandmarkObservations(0.0, np.array([99, 10, 10]), np.array([1.0, np.nan, -1.0]), np.zeros(3)))
    d = ekf.estimate().diagnostics
    assert (d["accepted"], d["rejected"]) == (0.0, 3.0)
    assert math.isnan(d["nis"])


def test_pruning_to_the_field_of_view() -> None:
    # Only landmark 12 at (-1, 2) lies behind-left; a fake "sighting" of it is outside a 60-degree field of view.
    sensors = SensorSpec(
        wheelbase_m=W,
        landmark_sigma_range_m=0.05,
        landmark_sigma_bearing_rad=0.02,
        landmark_fov_rad=math.radians(60),
        landmark_max_range_m=6.0,
    )
    z_rb = range_bearing(np.zeros(3), LANDMARKS.xy[2])
    z = LandmarkObservations(0.0, np.array([UNKNOWN_ID]), z_rb[:1].copy(), z_rb[1:].copy())
    initial = Gaussian2(np.zeros(3), np.diag([0.01, 0.01, 0.003]))
    for prune, accepted in ((True, 0.0), (False, 1.0)):
        ekf = make_ekf(prune_to_sensor_limits=prune)
        ekf.reset(initial, WORLD, sensors, RNG)
        ekf.update(z)
        assert ekf.estimate().diagnostics["accepted"] == accepted


@pytest.mark.parametrize("with_heading", [False, True])
def test_pose_fix_pulls_the_estimate_and_shrinks_the_covariance(with_heading: bool) -> None:
    ekf = make_ekf(use_pose_fixes=True)
    initial = Gaussian2(np.array([0.0, 0.0, 3.1]), np.diag([1.0, 1.0, 0.1]))
    ekf.reset(initial, WORLD, SENSORS, RNG)
    if with_heading:
        fix = PoseFix(1.0, np.array([1.0, -1.0, -3.1]), np.diag([0.01, 0.01, 0.01]))
    else:
        fix = PoseFix(1.0, np.array([1.0, -1.0]), np.diag([0.01, 0.01]))
    ekf.update(fix)
    est = ekf.estimate()
    assert est.t == 1.0
    assert_allclose(est.mean[:2], [1.0, -1.0], atol=0.02)
    assert np.trace(est.cov) < np.trace(initial.cov)
    assert est.cov[0, 0] < 0.011 and est.cov[1, 1] < 0.011
    assert is_symmetric_psd(est.cov)
    assert est.diagnostics["nis_dof"] == (3.0 if with_heading else 2.0)
    if with_heading:
        # Heading innovation wrapped: the estimate moves across +-pi (towards -3.1), not through 0.
        assert abs(pose_error(est.mean, [1.0, -1.0, -3.1])[2]) < 0.02
        assert est.diagnostics["nis"] < 3.0  # a 2 pi - 0.08 innovation would give a NIS in the hundreds


def test_routed_events_drop_pose_fixes_unless_enabled() -> None:
    assert PoseFix not in make_ekf().routed_events()
    assert make_ekf().routed_events() == frozenset({Odometry, LandmarkObservations, RangeObservations})
    assert make_ekf(use_pose_fixes=True).routed_events() == frozenset(
        {Odometry, LandmarkObservations, PoseFix, RangeObservations}
    )
    assert LandmarkEKF.consumes == frozenset({Odometry, LandmarkObservations, PoseFix, RangeObservations})
    assert LandmarkEKF.requires == frozenset({MapKind.LANDMARKS})


@pytest.mark.parametrize("association", ["known", "nearest"])
@pytest.mark.parametrize("input_noise", ["per_step", "cumulative"])
def test_exact_measurements_converge_from_a_wrong_but_covered_guess(association: str, input_noise: str) -> None:
    events, truth = drive(300)
    initial = Gaussian2(np.array([0.3, -0.2, 0.15]), np.diag([0.3**2, 0.3**2, 0.2**2]))
    means, covs, diags = run(make_ekf(association=association, input_noise=input_noise), events, initial)
    err = pose_error(means[1::2], truth)
    assert np.hypot(err[-1, 0], err[-1, 1]) < 1e-3
    assert abs(err[-1, 2]) < 1e-3
    assert np.max(np.hypot(err[-50:, 0], err[-50:, 1])) < 1e-3
    assert all(d["accepted"] == 4.0 for d in diags[1::2])
    assert all(is_symmetric_psd(c) for c in covs)
    assert np.trace(covs[-1]) < 1e-2 * np.trace(initial.cov)


def test_increment_fallback_without_wheel_travel() -> None:
    events, truth = drive(100)
    stripped = [
        Odometry(e.t, e.dx, e.dy, e.dtheta) if isinstance(e, Odometry) else e for e in events
    ]  # no wheel travel: (dx, dy, dtheta) composed with the increment noise
    initial = Gaussian2(np.array([0.1, 0.1, 0.05]), np.diag([0.04, 0.04, 0.01]))
    means, _, _ = run(make_ekf(), stripped, initial)
    err = pose_error(means[-1], truth[-1])
    assert np.hypot(err[0], err[1]) < 1e-3


def test_predict_diagnostics_and_time() -> None:
    ekf = make_ekf()
    ekf.reset(Gaussian2(np.zeros(3), np.eye(3) * 0.01), WORLD, SENSORS, RNG)
    est = ekf.estimate()
    assert math.isnan(est.t) and math.isnan(est.diagnostics["nis"])
    ekf.predict(Odometry(0.5, 0.1, 0.0, 0.0, d_left=0.1, d_right=0.1))
    est = ekf.estimate()
    assert est.t == 0.5
    assert math.isnan(est.diagnostics["nis"])
    assert (est.diagnostics["accepted"], est.diagnostics["rejected"]) == (0.0, 0.0)
    assert_allclose(est.mean, [0.1, 0.0, 0.0], atol=1e-15)
    assert set(est.diagnostics) == {"nis", "nis_dof", "accepted", "rejected"}


def test_update_of_an_unconsumed_type_raises() -> None:
    ekf = make_ekf()
    ekf.reset(Gaussian2(np.zeros(3), np.eye(3)), WORLD, SENSORS, RNG)
    scan = LaserScan(0.0, -1.0, 0.1, np.ones(21), 0.1, 5.0)
    with pytest.raises(TypeError, match="does not consume LaserScan"):
        ekf.update(scan)
    with pytest.raises(TypeError, match="does not consume Odometry"):
        ekf.update(Odometry(0.0, 0.0, 0.0, 0.0))  # type: ignore[arg-type]


def test_non_finite_state_raises_filter_diverged() -> None:
    ekf = make_ekf()
    ekf.reset(Gaussian2(np.zeros(3), np.eye(3)), WORLD, SENSORS, RNG)
    with pytest.raises(FilterDiverged, match="non-finite"):
        ekf.predict(Odometry(1.0, math.nan, 0.0, 0.0))


def test_deterministic_and_reset_restarts() -> None:
    events, _ = drive(80, ids_known=False)
    initial = Gaussian2(np.array([0.1, 0.0, 0.0]), np.diag([0.05, 0.05, 0.01]))
    ekf = make_ekf()
    a = run(ekf, events, initial)
    b = run(ekf, events, initial)  # the same instance, reset
    c = run(make_ekf(), events, initial)
    for x, y in ((a, b), (a, c)):
        assert_allclose(x[0], y[0], rtol=0, atol=0)
        assert_allclose(x[1], y[1], rtol=0, atol=0)


def test_config_from_spec_and_validation() -> None:
    ekf = make_filter("ekf_landmarks[association=nearest,gate_known=true,sigma_range_m=0.1,input_noise=cumulative]")
    assert isinstance(ekf, LandmarkEKF)
    cfg = ekf.config
    assert (cfg.association, cfg.gate_known, cfg.sigma_range_m, cfg.input_noise) == (
        "nearest",
        True,
        0.1,
        "cumulative",
    )
    assert cfg.sigma_bearing_rad is None
    assert not hasattr(ekf, "_x")  # __init__ does no work
    with pytest.raises(ConfigError, match="gate_probability"):
        LandmarkEKFConfig(gate_probability=1.0)
    with pytest.raises(ConfigError, match="sigma_range_m"):
        LandmarkEKFConfig(sigma_range_m=0.0)
    with pytest.raises(ConfigError, match="landmarks"):
        make_ekf().reset(Gaussian2(np.zeros(3), np.eye(3)), WorldMap(), SENSORS, RNG)


# --- range-only beacons --------------------------------------------------------------------------------


def test_chi2_1dof_quantiles() -> None:
    assert chi2_1dof_quantile(0.95) == pytest.approx(3.841459, abs=1e-5)
    assert chi2_1dof_quantile(0.99) == pytest.approx(6.634897, abs=1e-5)
    assert chi2_1dof_quantile(1.0) == math.inf


def test_range_only_update_reduces_the_error_of_drifting_odometry() -> None:
    events, _, truth = ro.scenario()
    odo, _ = ro.run(make_filter("odometry"), events, use_ranges=False)
    ekf, diags = ro.run(make_ekf(), events)
    e_odo, e_ekf = ro.position_rmse(odo, truth), ro.position_rmse(ekf, truth)
    assert e_odo > 0.3  # the odometry's 3 % / 5 % bias drifts
    assert e_ekf < 0.25 * e_odo
    assert sum(d["accepted"] for d in diags) >= 0.95 * len(diags)


def test_range_update_equals_the_numpy_joseph_form_with_a_numeric_jacobian() -> None:
    f = make_ekf()
    P0 = np.array([[0.04, 0.01, 0.002], [0.01, 0.09, -0.003], [0.002, -0.003, 0.01]])
    x0 = np.array([0.5, -0.2, 0.3])
    f.reset(Gaussian2(x0, P0), ro.WORLD, ro.SENSORS, RNG)
    beacon = ro.BEACON_XY[1]
    r = float(np.hypot(*(beacon - x0[:2]))) + 0.15  # inside the gate
    f.update(RangeObservations(0.1, np.array([5]), np.array([r])))

    def h(x: np.ndarray) -> float:
        return float(np.hypot(*(beacon - x[:2])))

    eps = 1e-7
    H = np.array([[(h(x0 + eps * e) - h(x0 - eps * e)) / (2 * eps) for e in np.eye(3)]])
    ref = joseph_update(x0, P0, np.array([r]), np.array([h(x0)]), H, np.array([[0.1**2]]))
    est = f.estimate()
    assert_allclose(est.mean, ref.x, atol=1e-9)
    assert_allclose(est.cov, ref.P, atol=1e-10)
    assert est.diagnostics["nis"] == pytest.approx(ref.nis, rel=1e-6)
    assert (est.diagnostics["accepted"], est.diagnostics["nis_dof"]) == (1.0, 1.0)


def test_range_gate_rejects_a_gross_outlier() -> None:
    events, _, truth = ro.scenario(n=100)
    gated, open_ = make_ekf(), make_ekf(range_gate_probability=1.0)
    for f in (gated, open_):
        f.reset(ro.INITIAL, ro.WORLD, ro.SENSORS, RNG)
        for ev in events:
            f.predict(ev) if isinstance(ev, Odometry) else f.update(ev)
    before = gated.estimate()
    bad = RangeObservations(
        10.1, ro.BEACON_IDS[:1].copy(), np.array([np.hypot(*(ro.BEACON_XY[0] - truth[-1, :2])) + 20.0])
    )
    gated.update(bad)
    open_before = open_.estimate().mean
    open_.update(bad)
    after = gated.estimate()
    assert (after.diagnostics["accepted"], after.diagnostics["rejected"]) == (0.0, 1.0)
    assert_allclose(after.mean, before.mean, atol=0)
    assert_allclose(after.cov, before.cov, atol=0)
    assert np.hypot(*(open_.estimate().mean[:2] - open_before[:2])) > 0.5  # ungated, the outlier drags the pose


def test_ranges_of_unknown_or_unmapped_beacons_are_rejected() -> None:
    f = make_ekf()
    f.reset(ro.INITIAL, ro.WORLD, ro.SENSORS, RNG)
    f.update(RangeObservations(0.1, np.array([UNKNOWN_ID, 99, 3], dtype=np.int64), np.array([5.0, 5.0, np.nan])))
    d = f.estimate().diagnostics
    assert (d["accepted"], d["rejected"]) == (0.0, 3.0)
    assert_allclose(f.estimate().mean, ro.INITIAL.mean, atol=0)


def test_range_noise_override_and_the_dataset_value() -> None:
    def nis(**kw: object) -> float:
        f = make_ekf(**kw)
        f.reset(ro.INITIAL, ro.WORLD, ro.SENSORS, RNG)
        f.update(RangeObservations(0.1, np.array([3]), np.array([8.6])))
        return f.estimate().diagnostics["nis"]

    P, nu = ro.INITIAL.cov, 8.6 - float(np.hypot(*ro.BEACON_XY[0]))
    h = -ro.BEACON_XY[0] / np.hypot(*ro.BEACON_XY[0])
    hph = float(h @ P[:2, :2] @ h)
    assert nis() == pytest.approx(nu * nu / (hph + 0.1**2))  # SensorSpec.range_sigma_m
    assert nis(range_only_sigma_m=0.5) == pytest.approx(nu * nu / (hph + 0.5**2))
    with pytest.raises(ConfigError, match="range_gate_probability"):
        make_ekf(range_gate_probability=0.0)
    with pytest.raises(ConfigError, match="range_only_sigma_m"):
        make_ekf(range_only_sigma_m=-1.0)


@pytest.mark.parametrize("spread", [0.01, 0.3, 3.0])
def test_index_candidates_find_the_scanned_nearest_landmark(spread: float) -> None:
    """With the k-d tree (maps of 256 landmarks and more) the association is that of testing every landmark,
    over random poses, covariances of every size and sightings near and far, also of landmarks by the robot."""
    rng = np.random.default_rng(int(spread * 100))
    xy = rng.uniform(-15.0, 15.0, size=(300, 2))
    world = WorldMap(landmarks=Landmarks(ids=np.arange(300, dtype=np.int64), xy=xy))
    flt = make_ekf(association="nearest")
    flt.reset(Gaussian2(np.zeros(3), np.eye(3) * 0.01), world, SensorSpec(), rng)
    assert flt._index is not None
    found = 0
    for _ in range(300):
        a = rng.standard_normal((3, 3)) * spread
        flt._P = (a @ a.T + 1e-6 * np.eye(3)).tolist()
        flt._x = [float(rng.uniform(-10, 10)), float(rng.uniform(-10, 10)), float(rng.uniform(-math.pi, math.pi))]
        target = xy[int(rng.integers(300))]
        dx, dy = target[0] - flt._x[0], target[1] - flt._x[1]
        r = math.hypot(dx, dy) + float(rng.normal(0.0, 0.3))
        b = math.atan2(dy, dx) - flt._x[2] + float(rng.normal(0.0, 0.2))
        used = {int(k) for k in rng.integers(0, 300, size=3)}
        with_index = flt._nearest(max(r, 0.01), b, used)
        index, flt._index = flt._index, None
        scanned = flt._nearest(max(r, 0.01), b, used)
        flt._index = index
        assert with_index == scanned
        found += scanned is not None
    assert found > 30  # the test saw associations, not only rejections
