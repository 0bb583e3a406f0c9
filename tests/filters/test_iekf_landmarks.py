"""The invariant EKF on SE(2): every step against gtsam's ``InvariantEKFPose2`` on a scripted sequence (to 1e-9),
its body-frame Jacobians against finite differences on X Exp(xi), and what sets it apart from the EKF."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import range_only_support as ro
from numpy.testing import assert_allclose

from locbench.core.events import LandmarkObservations, Odometry, PoseFix, RangeObservations
from locbench.core.geometry import between, wrap_angle, wrap_scalar
from locbench.datasets.dataset import Gaussian2, Landmarks, SensorSpec, WorldMap
from locbench.filters import _iekf_kernels as kern
from locbench.filters._motion import MotionModel, predict_midpoint
from locbench.filters._noise import process_noise
from locbench.filters.base import Estimate
from locbench.filters.ekf_landmarks import LandmarkEKF, LandmarkEKFConfig
from locbench.filters.iekf_landmarks import LandmarkIEKF
from locbench.registry import make_filter

gtsam = pytest.importorskip("gtsam")

W = 0.4
SENSORS = SensorSpec(wheelbase_m=W, encoder_k_left=0.01, encoder_k_right=0.01)
SENSORS = dataclasses.replace(SENSORS, landmark_sigma_range_m=0.05, landmark_sigma_bearing_rad=0.02)
_ANGLES = np.linspace(0.3, 0.3 + 2.0 * math.pi, 4, endpoint=False)
#: four landmarks on a circle of 3 m about (1, 0), ids 10 to 13
LANDMARKS = Landmarks(ids=np.arange(10, 14), xy=np.stack([1.0 + 3.0 * np.cos(_ANGLES), 3.0 * np.sin(_ANGLES)], axis=1))
WORLD = WorldMap(landmarks=LANDMARKS)
RNG = np.random.default_rng(0)


def _t(theta: float) -> np.ndarray:
    """T = blockdiag(R(theta), 1): the left-invariant error's map to world-frame (x, y, theta) errors."""
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _pose(p: object) -> np.ndarray:
    return np.array([p.x(), p.y(), p.theta()])  # type: ignore[attr-defined]


def body_range_bearing(pose: np.ndarray, lm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(range, bearing) of ``lm`` from ``pose`` and H_b = d h(X Exp(xi)) / d xi at 0, written from the body-frame
    position p = R^T (l - t) (the module docstring's form, independent of the filter's code)."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    dx, dy = lm[0] - pose[0], lm[1] - pose[1]
    px, py = c * dx + s * dy, -s * dx + c * dy
    q = px * px + py * py
    d = math.sqrt(q)
    return np.array([d, math.atan2(py, px)]), np.array([[-px / d, -py / d, 0.0], [py / q, -px / q, -1.0]])


def test_the_body_frame_jacobians_are_the_derivatives_on_the_group() -> None:
    """H_b of a sighting, a range and a pose fix against central differences of h(X Exp(xi)) (gtsam's Exp)."""
    lm = np.array([2.0, -1.5])
    for pose in (np.array([0.3, 0.2, 0.4]), np.array([-1.0, 2.0, -3.0]), np.array([4.0, -1.0, 3.1])):
        X = gtsam.Pose2(*pose)
        _, H = body_range_bearing(pose, lm)
        fix = _t(pose[2])
        num_rb, num_fix = np.zeros((2, 3)), np.zeros((3, 3))
        eps = 1e-6
        for i in range(3):
            e = np.zeros(3)
            e[i] = eps
            plus, minus = _pose(X.compose(gtsam.Pose2.Expmap(e))), _pose(X.compose(gtsam.Pose2.Expmap(-e)))
            d = body_range_bearing(plus, lm)[0] - body_range_bearing(minus, lm)[0]
            d[1] = wrap_scalar(float(d[1]))
            num_rb[:, i] = d / (2 * eps)
            df = plus - minus
            df[2] = wrap_scalar(float(df[2]))
            num_fix[:, i] = df / (2 * eps)
        assert_allclose(H, num_rb, atol=1e-8)
        assert_allclose(fix, num_fix, atol=1e-8)


def _scripted() -> list[Odometry | LandmarkObservations | RangeObservations | PoseFix]:
    """Encoder steps on an arc with sightings (one behind the robot, its bearing near pi), a beacon range and pose
    fixes with and without a heading; the measurements are offset from the truth so that every update moves."""
    rng = np.random.default_rng(3)
    pose = np.array([0.0, 0.0, 0.0])
    out: list[Odometry | LandmarkObservations | RangeObservations | PoseFix] = []
    for k in range(12):
        t = 0.1 * (k + 1)
        dl, dr = 0.05, 0.05 + 0.02 * math.sin(0.4 * k)
        new = predict_midpoint(pose, 0.5 * (dl + dr), (dr - dl) / W)
        inc = between(pose, new)
        out.append(Odometry(t, float(inc[0]), float(inc[1]), float(inc[2]), d_left=dl, d_right=dr))
        pose = new
        dxy = LANDMARKS.xy - pose[:2]
        r = np.hypot(dxy[:, 0], dxy[:, 1]) + rng.normal(0.0, 0.05, 4)
        b = wrap_angle(np.arctan2(dxy[:, 1], dxy[:, 0]) - pose[2] + rng.normal(0.0, 0.02, 4))
        if k % 4 == 1:
            out.append(LandmarkObservations(t, LANDMARKS.ids.copy(), r, b))
        elif k % 4 == 2:
            out.append(LandmarkObservations(t, LANDMARKS.ids[2:].copy(), r[2:], b[2:]))
        elif k == 3:
            out.append(RangeObservations(t, LANDMARKS.ids[:2].copy(), r[:2]))
        elif k == 7:
            out.append(PoseFix(t, pose[:2] + 0.05, np.diag([0.04, 0.09])))
        elif k == 11:
            out.append(PoseFix(t, pose + np.array([0.05, -0.03, 0.04]), np.diag([0.04, 0.09, 0.01])))
    return out


def test_every_step_matches_gtsams_invariant_ekf() -> None:
    """Prediction: gtsam's predict(U, Q_b) with U = X^-1 f(X, u) and Q_b the EKF's world-frame motion noise in the
    body frame; corrections: updateWithVector with the body-frame Jacobians (no reset). After every event the
    filter's mean and covariance (world frame, T P_b T^T) equal gtsam's to 1e-9."""
    cfg = LandmarkEKFConfig(use_pose_fixes=True, range_only_sigma_m=0.1)
    flt = LandmarkIEKF(cfg)
    mean0 = np.array([0.2, -0.1, math.radians(30.0)])
    Pb0 = np.array([[0.04, 0.01, 0.002], [0.01, 0.09, -0.003], [0.002, -0.003, (math.radians(30.0)) ** 2]])
    flt.reset(Gaussian2(mean0, _t(mean0[2]) @ Pb0 @ _t(mean0[2]).T), WORLD, SENSORS, RNG)
    ref = gtsam.InvariantEKFPose2(gtsam.Pose2(*mean0), Pb0)
    motion = MotionModel(cfg.motion_noise(SENSORS), cfg.motion_model, mean="model")
    q = np.diag(np.square(process_noise(None, None, None, SENSORS)))
    R = np.diag([0.05**2, 0.02**2])
    kinds = set()
    for ev in _scripted():
        X = ref.state()
        x = _pose(X)
        if isinstance(ev, Odometry):
            flt.predict(ev)
            step = motion.step(x.tolist(), ev)
            n00, n01, n02, n11, n12, n22 = step.noise
            N = np.array([[n00, n01, n02], [n01, n11, n12], [n02, n12, n22]]) + q
            T1 = _t(step.pose[2])
            ref.predict(gtsam.Pose2(*between(x, np.array(step.pose))), T1.T @ N @ T1)
        elif isinstance(ev, LandmarkObservations):
            flt.update(ev)
            for ident, r, b in zip(ev.ids, ev.ranges, ev.bearings, strict=True):
                x = _pose(ref.state())
                h, H = body_range_bearing(x, LANDMARKS.xy[list(LANDMARKS.ids).index(ident)])
                z = h + np.array([r - h[0], wrap_scalar(float(b - h[1]))])  # the wrapped innovation
                ref.updateWithVector(h, H, z, R, False)
        elif isinstance(ev, RangeObservations):
            flt.update(ev)
            for ident, r in zip(ev.ids, ev.ranges, strict=True):
                x = _pose(ref.state())
                h, H = body_range_bearing(x, LANDMARKS.xy[list(LANDMARKS.ids).index(ident)])
                ref.updateWithVector(h[:1], H[:1], np.array([r]), np.array([[0.1**2]]), False)
        else:
            flt.update(ev)
            m = ev.z.shape[0]
            Hf = _t(x[2])[:m]
            z = x[:m] + (ev.z - x[:m])
            if m == 3:
                z[2] = x[2] + wrap_scalar(float(ev.z[2] - x[2]))
            ref.updateWithVector(x[:m], Hf, z, ev.cov, False)
        kinds.add(type(ev).__name__)
        est = flt.estimate()
        xg = _pose(ref.state())
        assert_allclose(est.mean[:2], xg[:2], rtol=0, atol=1e-9)
        assert abs(wrap_scalar(float(est.mean[2] - xg[2]))) < 1e-9
        Tg = _t(xg[2])
        assert_allclose(est.cov, Tg @ ref.covariance() @ Tg.T, rtol=0, atol=1e-9)
    assert kinds == {"Odometry", "LandmarkObservations", "RangeObservations", "PoseFix"}


def test_the_arc_factors_keep_their_digits_at_small_angles() -> None:
    """V(w)'s factors against their Taylor series (exact to rounding below 1e-3 rad) and the plain closed form
    above; the series' first omitted terms are w^4 / 120 and w^5 / 720."""
    assert kern._v_factors(0.0) == (1.0, 0.0)
    for w in (1e-12, -1e-9, 3e-7, 1e-4, -5e-4):
        assert_allclose(kern._v_factors(w), [1.0 - w * w / 6.0, w * (0.5 - w * w / 24.0)], rtol=1e-15, atol=0)
    for w in (0.3, -2.0, 3.1):
        assert_allclose(kern._v_factors(w), [math.sin(w) / w, (1.0 - math.cos(w)) / w], rtol=1e-14, atol=0)


def _drive(n: int, ids_known: bool = True) -> list[Odometry | LandmarkObservations]:
    pose = np.zeros(3)
    out: list[Odometry | LandmarkObservations] = []
    for k in range(n):
        dl, dr = 0.05, 0.05 + 0.008 * math.sin(0.05 * k)
        new = predict_midpoint(pose, 0.5 * (dl + dr), (dr - dl) / W)
        inc = between(pose, new)
        t = 0.1 * (k + 1)
        out.append(Odometry(t, float(inc[0]), float(inc[1]), float(inc[2]), d_left=dl, d_right=dr))
        dxy = LANDMARKS.xy - new[:2]
        ids = LANDMARKS.ids if ids_known else np.full(4, -1)
        r, b = np.hypot(dxy[:, 0], dxy[:, 1]), wrap_angle(np.arctan2(dxy[:, 1], dxy[:, 0]) - new[2])
        out.append(LandmarkObservations(t, ids.astype(np.int64), r, b))
        pose = new
    return out


def _step(flt: LandmarkEKF, ev: Odometry | LandmarkObservations) -> Estimate:
    if isinstance(ev, Odometry):
        flt.predict(ev)
    else:
        flt.update(ev)
    return flt.estimate()


def _run(flt: LandmarkEKF, events: list, initial: Gaussian2) -> tuple[np.ndarray, np.ndarray]:
    """Means (n, 3) and covariances (n, 3, 3) after each event."""
    flt.reset(initial, WORLD, SENSORS, RNG)
    ests = [_step(flt, ev) for ev in events]
    return np.array([e.mean for e in ests]), np.array([e.cov for e in ests])


def test_prediction_is_the_ekfs_and_corrections_turn_the_covariance() -> None:
    """Identity 1 of the module docstring: a prediction is the EKF's, bit for bit (the same kernel); a correction
    that turns the heading by w turns the EKF's position covariance by R(w)."""
    initial = Gaussian2(np.array([0.1, -0.1, 0.3]), np.diag([0.05, 0.05, 0.1]))
    events = _drive(2)
    ekf, iekf = LandmarkEKF(), LandmarkIEKF()
    m_e, c_e = _run(ekf, events[:1], initial)
    m_i, c_i = _run(iekf, events[:1], initial)
    assert np.array_equal(m_e, m_i) and np.array_equal(c_e, c_i)
    z = events[1]
    assert isinstance(z, LandmarkObservations)
    one = LandmarkObservations(z.t, z.ids[:1], z.ranges[:1] + 0.05, z.bearings[:1] + 0.3)  # one sighting: one step
    ekf.update(one)
    iekf.update(one)
    e, i = ekf.estimate(), iekf.estimate()
    assert e.mean[2] == pytest.approx(i.mean[2], abs=1e-15)  # the heading step is the same
    w = float(e.mean[2] - m_e[0][2])
    assert abs(w) > 0.1
    G = _t(w)
    assert_allclose(i.cov, G @ e.cov @ G.T, rtol=1e-12, atol=1e-15)
    assert not np.allclose(i.mean[:2], e.mean[:2], atol=1e-3)  # the arc, not the chord


@pytest.mark.parametrize("association", ["known", "nearest"])
def test_converges_from_a_45_degree_heading_error(association: str) -> None:
    initial = Gaussian2(np.array([0.3, -0.2, math.radians(45.0)]), np.diag([0.1, 0.1, math.radians(45.0) ** 2]))
    flt = make_filter(f"iekf_landmarks[association={association}]")
    means, covs = _run(flt, _drive(40), initial)  # type: ignore[arg-type]
    truth = np.zeros(3)
    for ev in _drive(40)[::2]:
        truth = predict_midpoint(truth, 0.5 * (ev.d_left + ev.d_right), (ev.d_right - ev.d_left) / W)  # type: ignore[attr-defined,operator]
    err = means[-1] - truth
    err[2] = wrap_scalar(float(err[2]))
    assert np.all(np.abs(err) < 1e-3)
    assert np.all(np.linalg.eigvalsh(covs[-1]) > 0.0)


def test_known_ids_and_nearest_neighbour_agree_and_the_index_path_is_the_loops() -> None:
    """With separated landmarks, associating by nearest neighbour fuses what the ids say; a map whose association
    goes through the k-d tree (the Python path of corrections) gives the compiled loop's numbers."""
    initial = Gaussian2(np.array([0.05, -0.03, 0.02]), np.diag([0.01, 0.01, 0.003]))
    m_k, c_k = _run(LandmarkIEKF(), _drive(20), initial)
    m_n, c_n = _run(LandmarkIEKF(LandmarkEKFConfig(association="nearest")), _drive(20), initial)
    m_u, c_u = _run(LandmarkIEKF(), _drive(20, ids_known=False), initial)
    assert_allclose(m_n, m_k, atol=1e-12)
    assert_allclose(c_n, c_k, atol=1e-15)
    assert_allclose(c_u, c_k, atol=1e-15)
    assert_allclose(m_u, m_k, atol=1e-12)

    class Indexed(LandmarkIEKF):
        _index_min_landmarks = 1

    m_t, c_t = _run(Indexed(), _drive(20, ids_known=False), initial)
    assert_allclose(m_t, m_k, atol=1e-12)
    assert_allclose(c_t, c_k, atol=1e-15)


def test_beacon_ranges_pull_drifting_odometry_back() -> None:
    """The shared range-only scenario (odometry over-reports speed and turn rate): ranges bound the error."""
    events, _, truth = ro.scenario()
    fused, diags = ro.run(LandmarkIEKF(), events)
    dead, _ = ro.run(LandmarkIEKF(), events, use_ranges=False)
    assert ro.position_rmse(fused, truth) < 0.5 * ro.position_rmse(dead, truth)
    assert sum(d["accepted"] for d in diags) > 0.9 * len(diags)
