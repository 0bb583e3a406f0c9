"""The wheel-encoder motion model (report 003 eq. 1-5, 10) and the increment fallback."""

from __future__ import annotations

import math

import numpy as np
import pytest
from motion_reference import arc, increment_moved, twist_moved, wheel_moved
from numpy.testing import assert_allclose

from locbench.core.events import Odometry
from locbench.core.geometry import compose
from locbench.datasets.dataset import SensorSpec
from locbench.filters._motion import (
    DEFAULT_ENCODER_K,
    MotionModel,
    increment_covariance,
    increment_jacobians,
    increment_variances,
    input_covariance,
    jacobian_state,
    jacobian_wheels,
    predict_arc,
    predict_midpoint,
    propagate_covariance,
    resolve_motion_noise,
    twist_increment_covariance,
    twist_jacobian,
    wheel_to_motion,
    wheel_variances,
)
from locbench.filters.motion import sample_increment_motion, sample_twist_motion, sample_wheel_motion, twist_increment

W = 0.4


def numeric_jacobian(fn, x0: np.ndarray, eps: float = 1e-7) -> np.ndarray:
    """Central differences of ``fn`` at ``x0`` (heading outputs are differences of small angles)."""
    x0 = np.asarray(x0, dtype=np.float64)
    cols = []
    for i in range(x0.size):
        e = np.zeros_like(x0)
        e[i] = eps
        cols.append((np.asarray(fn(x0 + e)) - np.asarray(fn(x0 - e))) / (2 * eps))
    return np.stack(cols, axis=-1)


def test_wheel_to_motion_eq_1_2() -> None:
    dd, dth = wheel_to_motion(0.10, 0.14, W)
    assert dd == pytest.approx(0.12)
    assert dth == pytest.approx(0.1)  # (0.14 - 0.10) / 0.4, counter-clockwise when the right wheel runs ahead


@pytest.mark.parametrize("theta", [0.0, 1.0, -2.5, 3.1])
def test_midpoint_matches_exact_arc_for_small_turns(theta: float) -> None:
    pose = np.array([1.0, -2.0, theta])
    dd = 0.1
    for dth in (1e-12, 1e-4, 1e-2, 0.05):
        mid = predict_midpoint(pose, dd, dth)
        arc = predict_arc(pose, dd, dth)
        # The chord is shorter than the arc by dd * dth^2 / 24: eq. 5 is a second-order approximation of eq. 3-4.
        assert np.hypot(*(mid[:2] - arc[:2])) <= dd * dth**2 / 24 * 1.01 + 1e-15
        assert mid[2] == pytest.approx(arc[2])


def test_arc_matches_eq_3_4_literally() -> None:
    pose, dd, dth = np.array([0.3, 0.4, 2.0]), 0.2, 0.3
    x = pose[0] + dd / dth * (math.sin(pose[2] + dth) - math.sin(pose[2]))  # eq. 3
    y = pose[1] + dd / dth * (math.cos(pose[2]) - math.cos(pose[2] + dth))  # eq. 4
    assert_allclose(predict_arc(pose, dd, dth), [x, y, pose[2] + dth], atol=1e-14)


def test_arc_is_a_circle() -> None:
    # Driving a quarter circle of radius 1 from the origin facing +x ends at (1, 1) facing +y.
    end = predict_arc([0.0, 0.0, 0.0], math.pi / 2, math.pi / 2)
    assert_allclose(end, [1.0, 1.0, math.pi / 2], atol=1e-12)


def test_midpoint_is_vectorised() -> None:
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 3.0]])
    out = predict_midpoint(poses, np.array([0.1, 0.2]), np.array([0.0, 0.4]))
    assert out.shape == (2, 3)
    assert_allclose(out[1], predict_midpoint(poses[1], 0.2, 0.4))
    assert -math.pi < out[1, 2] <= math.pi  # 3.4 wrapped


@pytest.mark.parametrize(("theta", "dd", "dth"), [(0.3, 0.1, 0.02), (-2.9, 0.5, -0.3), (3.1, 0.0, 0.2)])
def test_state_jacobian_against_finite_differences(theta: float, dd: float, dth: float) -> None:
    def f(p: np.ndarray) -> np.ndarray:
        out = predict_midpoint(p, dd, dth)
        out[2] = p[2] + dth  # unwrapped, for differencing
        return out

    assert_allclose(jacobian_state(theta, dd, dth), numeric_jacobian(f, np.array([0.5, -0.2, theta])), atol=1e-7)


@pytest.mark.parametrize(("theta", "dl", "dr"), [(0.3, 0.10, 0.12), (-2.9, 0.3, -0.1), (1.5, 0.0, 0.0)])
def test_wheel_jacobian_against_finite_differences(theta: float, dl: float, dr: float) -> None:
    pose = np.array([0.5, -0.2, theta])

    def f(u: np.ndarray) -> np.ndarray:
        dd, dth = wheel_to_motion(u[0], u[1], W)
        out = predict_midpoint(pose, dd, dth)
        out[2] = theta + dth  # unwrapped, for differencing
        return out

    dd, dth = wheel_to_motion(dl, dr, W)
    assert_allclose(
        jacobian_wheels(theta, float(dd), float(dth), W), numeric_jacobian(f, np.array([dl, dr])), atol=1e-7
    )


def test_increment_jacobians_against_finite_differences() -> None:
    pose = np.array([0.5, -0.2, 2.0])
    inc = np.array([0.3, -0.1, 0.2])
    F, G = increment_jacobians(pose[2], inc[0], inc[1])

    def unwrap(p: np.ndarray, ref: float) -> np.ndarray:
        p = p.copy()
        p[2] = ref + (p[2] - ref + math.pi) % (2 * math.pi) - math.pi
        return p

    ref = pose[2] + inc[2]
    assert_allclose(F, numeric_jacobian(lambda p: unwrap(compose(p, inc), ref), pose), atol=1e-7)
    assert_allclose(G, numeric_jacobian(lambda d: unwrap(compose(pose, d), ref), inc), atol=1e-7)


def test_input_covariance_readings_of_eq_10() -> None:
    per_step = input_covariance(0.1, -0.2, 0.02, 0.03, "per_step", travelled_left=5.0, travelled_right=7.0)
    assert_allclose(per_step, np.diag([0.02**2 * 0.1, 0.03**2 * 0.2]))
    literal = input_covariance(0.1, -0.2, 0.02, 0.03, "cumulative", travelled_left=5.0, travelled_right=7.0)
    assert_allclose(literal, np.diag([0.02**2 * 5.1, 0.03**2 * 7.2]))


def test_cumulative_reading_grows_faster_than_per_step() -> None:
    sensors = SensorSpec(wheelbase_m=W, encoder_k_left=0.01, encoder_k_right=0.01)
    u = Odometry(0.0, 0.1, 0.0, 0.0, d_left=0.1, d_right=0.1)
    out = {}
    for mode in ("per_step", "cumulative"):
        model = MotionModel(resolve_motion_noise(sensors, input_noise=mode))
        pose, P = (0.0, 0.0, 0.0), [[0.0] * 3 for _ in range(3)]
        for _ in range(100):
            step = model.step(pose, u)
            pose, P = step.pose, propagate_covariance(P, step.f02, step.f12, step.noise)
            assert step.encoder
        out[mode] = P[2][2]
        assert model.travelled_left == pytest.approx(10.0)
    # Heading variance after 10 m: per step it is linear in the distance, literally it is quadratic.
    per_step_expected = 100 * 2 * (0.01**2 * 0.1) / W**2
    assert out["per_step"] == pytest.approx(per_step_expected)
    assert out["cumulative"] == pytest.approx(per_step_expected * 101 / 2)


def test_model_step_matches_numpy_helpers() -> None:
    sensors = SensorSpec(wheelbase_m=W, encoder_k_left=0.02, encoder_k_right=0.03)
    model = MotionModel(resolve_motion_noise(sensors))
    pose = (1.0, 2.0, 2.8)
    u = Odometry(0.0, 0.0, 0.0, 0.0, d_left=0.08, d_right=0.13)
    step = model.step(pose, u)
    dd, dth = wheel_to_motion(0.08, 0.13, W)
    assert_allclose(step.pose, predict_midpoint(pose, dd, dth), atol=1e-15)
    F = jacobian_state(pose[2], float(dd), float(dth))
    G = jacobian_wheels(pose[2], float(dd), float(dth), W)
    N = G @ input_covariance(0.08, 0.13, 0.02, 0.03) @ G.T
    assert (step.f02, step.f12) == pytest.approx((F[0, 2], F[1, 2]))
    assert_allclose(np.array(step.noise), N[np.triu_indices(3)], atol=1e-18)
    P0 = np.array([[0.1, 0.01, 0.02], [0.01, 0.2, -0.03], [0.02, -0.03, 0.05]])
    assert_allclose(propagate_covariance(P0.tolist(), step.f02, step.f12, step.noise), F @ P0 @ F.T + N, atol=1e-15)


def test_increment_fallback_without_wheel_travel() -> None:
    sensors = SensorSpec(
        wheelbase_m=W,
        encoder_k_left=0.01,
        encoder_k_right=0.01,
        odometry_sigma_xy_per_m=0.05,
        odometry_sigma_theta_per_m=0.02,
        odometry_sigma_theta_per_rad=0.1,
    )
    model = MotionModel(resolve_motion_noise(sensors))
    pose = (1.0, 2.0, -3.0)
    u = Odometry(0.0, 0.3, 0.4, 0.25)  # no wheel travel
    step = model.step(pose, u)
    assert not step.encoder
    assert_allclose(step.pose, compose(pose, u.delta), atol=1e-15)
    F, G = increment_jacobians(pose[2], u.dx, u.dy)
    N = G @ increment_covariance(0.3, 0.4, 0.25, 0.05, 0.02, 0.1) @ G.T
    assert (step.f02, step.f12) == pytest.approx((F[0, 2], F[1, 2]))
    assert_allclose(np.array(step.noise), N[np.triu_indices(3)], atol=1e-18)
    assert step.noise[5] == pytest.approx(0.02**2 * 0.5 + 0.1**2 * 0.25)


def test_auto_needs_encoder_constants_and_increment_forces_fallback() -> None:
    u = Odometry(0.0, 0.1, 0.0, 0.0, d_left=0.1, d_right=0.1)
    no_k = resolve_motion_noise(SensorSpec(wheelbase_m=W))
    assert not no_k.encoder_given and no_k.k_left == DEFAULT_ENCODER_K
    assert not MotionModel(no_k, "auto").step((0.0, 0.0, 0.0), u).encoder
    assert MotionModel(no_k, "encoder").step((0.0, 0.0, 0.0), u).encoder
    given = resolve_motion_noise(SensorSpec(wheelbase_m=W, encoder_k_left=0.01, encoder_k_right=0.01))
    assert MotionModel(given, "auto").step((0.0, 0.0, 0.0), u).encoder
    assert not MotionModel(given, "increment").step((0.0, 0.0, 0.0), u).encoder
    no_w = resolve_motion_noise(SensorSpec(encoder_k_left=0.01, encoder_k_right=0.01))
    assert not MotionModel(no_w, "encoder").step((0.0, 0.0, 0.0), u).encoder


def test_overrides_take_precedence() -> None:
    sensors = SensorSpec(wheelbase_m=W, encoder_k_left=0.01, encoder_k_right=0.01, odometry_sigma_xy_per_m=0.1)
    noise = resolve_motion_noise(sensors, wheelbase_m=0.5, encoder_k_left=0.2, odometry_sigma_xy_per_m=0.3)
    assert (noise.wheelbase_m, noise.k_left, noise.k_right, noise.sigma_xy_per_m) == (0.5, 0.2, 0.01, 0.3)


def test_sampled_wheel_motion_matches_linearised_covariance() -> None:
    rng = np.random.default_rng(1)
    pose = np.array([0.0, 0.0, 0.7])
    dl, dr, kl, kr = 0.2, 0.25, 0.02, 0.02  # small noise: the mean's nonlinearity bias stays below the tolerance
    vl, vr = wheel_variances(dl, dr, kl, kr)
    samples = sample_wheel_motion(np.tile(pose, (200_000, 1)), dl, dr, W, vl, vr, rng)
    dd, dth = wheel_to_motion(dl, dr, W)
    G = jacobian_wheels(pose[2], float(dd), float(dth), W)
    assert_allclose(samples.mean(axis=0), predict_midpoint(pose, dd, dth), atol=1e-4)
    assert_allclose(np.cov(samples.T), G @ np.diag([vl, vr]) @ G.T, rtol=0.03, atol=1e-8)


def test_sampled_increment_motion_is_deterministic_and_centred() -> None:
    poses = np.tile([1.0, 1.0, 3.0], (100_000, 1))
    a = sample_increment_motion(poses, 0.2, 0.0, 0.1, 1e-4, 1e-4, np.random.default_rng(3))
    b = sample_increment_motion(poses, 0.2, 0.0, 0.1, 1e-4, 1e-4, np.random.default_rng(3))
    assert_allclose(a, b, rtol=0, atol=0)
    assert_allclose(a[:, :2].mean(axis=0), compose([1.0, 1.0, 3.0], [0.2, 0.0, 0.1])[:2], atol=2e-4)
    assert np.all((a[:, 2] > -math.pi) & (a[:, 2] <= math.pi))


# --- twist noise ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("a", [0.0, 1e-5, 9e-4, 1.1e-3, 0.3, -1.2, 2.5])
def test_twist_jacobian_matches_finite_differences(a: float) -> None:
    s = 0.7
    num = numeric_jacobian(lambda q: twist_increment(q[0], q[1]), np.array([s, a]), eps=1e-6)
    assert_allclose(twist_jacobian(s, a), num, atol=1e-8)


def test_twist_increment_is_the_exact_arc() -> None:
    # A quarter circle of radius 2: from the origin heading +x to (2, 2) heading +y.
    assert_allclose(twist_increment(math.pi, math.pi / 2), [2.0, 2.0, math.pi / 2], atol=1e-12)
    assert_allclose(twist_increment(0.4, 0.0), [0.4, 0.0, 0.0], atol=0)


def test_twist_covariance_formula_without_turning() -> None:
    # omega = 0: J = [[1, 0], [0, s/2], [0, 1]], so Sigma = [[vs, 0, 0], [0, s^2/4 va, s/2 va], [0, s/2 va, va]]
    # with s = v dt, vs = (sigma_v dt)^2, va = (sigma_omega dt)^2.
    v, dt, sv, so = 0.8, 0.2, 0.05, 0.1
    s, vs, va = v * dt, (sv * dt) ** 2, (so * dt) ** 2
    expected = np.array([[vs, 0.0, 0.0], [0.0, s * s / 4 * va, s / 2 * va], [0.0, s / 2 * va, va]])
    assert_allclose(twist_increment_covariance(v, 0.0, dt, sv, so), expected, rtol=1e-12, atol=1e-20)


def test_twist_covariance_matches_sampled_arcs() -> None:
    v, w, dt, sv, so = 1.0, 0.8, 0.5, 0.02, 0.02
    rng = np.random.default_rng(7)
    n = 200_000
    inc = twist_increment(v * dt + sv * dt * rng.standard_normal(n), w * dt + so * dt * rng.standard_normal(n))
    assert_cov_close(np.cov(inc.T), twist_increment_covariance(v, w, dt, sv, so))


def assert_cov_close(sampled: np.ndarray, expected: np.ndarray, tol: float = 0.02) -> None:
    """Entries agree to ``tol`` of sqrt(C_ii C_jj) (a sampled off-diagonal near 0 has no relative accuracy)."""
    scale = np.sqrt(np.outer(np.diag(expected), np.diag(expected)))
    assert np.all(np.abs(sampled - expected) <= tol * scale), (sampled, expected)


def _twist_event(v: float = 0.6, w: float = 0.4, dt: float = 0.25) -> Odometry:
    inc = twist_increment(v * dt, w * dt)
    return Odometry(1.0, float(inc[0]), float(inc[1]), float(inc[2]), v=v, omega=w, dt=dt)


def test_motion_model_uses_the_twist_noise_rotated_to_the_world() -> None:
    sensors = SensorSpec(odometry_sigma_xy_per_m=0.1, twist_sigma_v_mps=0.05, twist_sigma_omega_radps=0.02)
    u = _twist_event()
    th = 0.9
    step = MotionModel(resolve_motion_noise(sensors)).step((1.0, 2.0, th), u)
    assert u.v is not None and u.omega is not None and u.dt is not None
    G = np.array([[math.cos(th), -math.sin(th), 0.0], [math.sin(th), math.cos(th), 0.0], [0.0, 0.0, 1.0]])
    N = G @ twist_increment_covariance(u.v, u.omega, u.dt, 0.05, 0.02) @ G.T
    assert_allclose(step.noise, [N[0, 0], N[0, 1], N[0, 2], N[1, 1], N[1, 2], N[2, 2]], rtol=1e-12, atol=1e-20)
    # The mean is still the event's own increment.
    assert_allclose(step.pose, compose([1.0, 2.0, th], [u.dx, u.dy, u.dtheta]), atol=1e-12)


def test_twist_noise_applies_only_when_given_and_the_event_has_a_twist() -> None:
    base = SensorSpec(odometry_sigma_xy_per_m=0.1, odometry_sigma_theta_per_m=0.05)
    u = _twist_event()
    plain = MotionModel(resolve_motion_noise(base)).step((0.0, 0.0, 0.3), u)
    vxy, vth = increment_variances(u.dx, u.dy, u.dtheta, 0.1, 0.05, 0.0)
    assert plain.noise == (vxy, 0.0, 0.0, vxy, 0.0, vth)  # no twist sigma: the increment noise, unchanged
    given = resolve_motion_noise(SensorSpec(odometry_sigma_xy_per_m=0.1, twist_sigma_v_mps=0.05))
    no_twist = Odometry(1.0, u.dx, u.dy, u.dtheta)
    assert MotionModel(given).step((0.0, 0.0, 0.3), no_twist).noise[1] == 0.0  # isotropic increment noise
    # Only sigma_v given: sigma_omega counts as 0, so the heading gets no noise from the twist.
    assert MotionModel(given).step((0.0, 0.0, 0.3), u).noise[5] == 0.0


def test_twist_overrides_take_precedence() -> None:
    sensors = SensorSpec(twist_sigma_v_mps=0.1, twist_sigma_omega_radps=0.2)
    assert resolve_motion_noise(sensors).twist_sigmas(_twist_event()) == (0.1, 0.2)
    noise = resolve_motion_noise(sensors, twist_sigma_v_mps=0.3)
    assert (noise.twist_sigma_v_mps, noise.twist_sigma_omega_radps) == (0.3, 0.2)
    assert resolve_motion_noise(SensorSpec()).twist_sigmas(_twist_event()) is None


def test_sampled_twist_motion_matches_the_covariance_and_the_event() -> None:
    u = _twist_event(v=1.0, w=0.8, dt=0.5)
    assert u.v is not None and u.omega is not None and u.dt is not None
    # The event's increment differs from the exact arc of its twist (a loader may compose differently):
    # the samples are centred on the event, with the arc's noise.
    u = Odometry(u.t, u.dx + 0.01, u.dy, u.dtheta, v=u.v, omega=u.omega, dt=u.dt)
    pose = np.array([0.5, -1.0, -2.0])
    x = sample_twist_motion(np.tile(pose, (200_000, 1)), u, 0.02, 0.02, np.random.default_rng(2))
    assert_allclose(x.mean(axis=0), compose(pose, [u.dx, u.dy, u.dtheta]), atol=2e-4)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    G = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    expected = G @ twist_increment_covariance(u.v, u.omega, u.dt, 0.02, 0.02) @ G.T
    assert_cov_close(np.cov(x.T), expected)


# --- the compiled samplers against the plain forms ---------------------------------------------------------


def _cloud(n: int, seed: int) -> np.ndarray:
    """``n`` poses spread over 4 m and every heading, the first few on and beside the wrap."""
    rng = np.random.default_rng(seed)
    x = np.column_stack([rng.normal(0, 2, n), rng.normal(0, 2, n), rng.uniform(-math.pi, math.pi, n)])
    x[:5, 2] = [math.pi, -math.pi + 1e-12, 3.1, -3.1, 0.0]
    return x


def assert_poses_close(got: np.ndarray, want: np.ndarray, atol: float = 1e-12) -> None:
    """Positions to ``atol`` m, headings to ``atol`` rad modulo 2 pi (a value at +-pi may wrap to either end)."""
    assert_allclose(got[:, :2], want[:, :2], rtol=0, atol=atol)
    dth = np.remainder(got[:, 2] - want[:, 2] + math.pi, 2 * math.pi) - math.pi
    assert_allclose(dth, 0.0, rtol=0, atol=atol)
    assert np.all((got[:, 2] > -math.pi) & (got[:, 2] <= math.pi))


def test_sampled_wheel_motion_is_the_plain_encoder_step() -> None:
    """The same draws (every left wheel, then every right) through the plain eq. 1-2, 5 agree to 1e-12 m, rad."""
    x = _cloud(500, 1)
    got = sample_wheel_motion(x, 0.2, 0.26, W, 1e-4, 4e-4, np.random.default_rng(8))
    e = np.random.default_rng(8).standard_normal((2, 500))
    assert_poses_close(got, wheel_moved(x, 0.2 + 0.01 * e[0], 0.26 + 0.02 * e[1], W))


def test_sampled_increment_motion_is_the_plain_composition() -> None:
    """The same draws (every dx, then dy, then dtheta) through the plain pose (+) increment agree to 1e-12."""
    x = _cloud(500, 2)
    got = sample_increment_motion(x, 0.3, -0.05, 0.4, 1e-4, 9e-4, np.random.default_rng(9))
    e = np.random.default_rng(9).standard_normal((3, 500))
    assert_poses_close(got, increment_moved(x, 0.3 + 0.01 * e[0], -0.05 + 0.01 * e[1], 0.4 + 0.03 * e[2]))


@pytest.mark.parametrize(("v", "omega", "dt"), [(0.4, 0.0, 0.05), (0.3, 1e-4, 0.02), (0.8, -2.5, 0.1)])
def test_sampled_twist_motion_is_the_plain_arc(v: float, omega: float, dt: float) -> None:
    """The same draws (every arc length, then every turn) through the plain arc agree to 1e-12 m, rad."""
    x = _cloud(500, 3)
    u = Odometry(t=1.0, dx=0.02, dy=-0.001, dtheta=0.01, v=v, omega=omega, dt=dt)
    got = sample_twist_motion(x, u, 0.05, 0.1, np.random.default_rng(10))
    e = np.random.default_rng(10).standard_normal((2, 500))
    s, a = v * dt + 0.05 * dt * e[0], omega * dt + 0.1 * dt * e[1]
    assert_poses_close(got, twist_moved(x, s, a, v * dt, omega * dt, (u.dx, u.dy, u.dtheta)))


def test_twist_increment_is_the_plain_arc() -> None:
    """The compiled arc against the plain one across the series' edge and 0: dx and dtheta to 4 ulps of the arc
    length; dy to 1e-9 relative, the cancellation of 1 - cos a just above the series (about eps / a^2)."""
    s = np.full(9, 0.7)
    a = np.array([0.0, 1e-9, -1e-5, 9.99e-4, 1.001e-3, -0.3, 1.2, -2.9, 3.1])
    got, want = twist_increment(s, a), arc(s, a)
    assert_allclose(got[:, [0, 2]], want[:, [0, 2]], rtol=0, atol=4 * np.spacing(0.7))
    assert_allclose(got[:, 1], want[:, 1], rtol=1e-9, atol=0)
    assert twist_increment(np.ones((2, 3)), 0.5).shape == (2, 3, 3)
