"""The UKF's compiled kernels (filters/_ukf_kernels.py) against the reference unscented transform (filterpy's
sigma points and transform with numpy's Cholesky factor, tests/kalman_reference.py) on random beliefs, to rounding,
and the filter's answers where a kernel cannot complete."""

from __future__ import annotations

import math

import kalman_reference as ref
import numpy as np
import pytest
from motion_reference import increment_moved, midpoint_moved

pytest.importorskip("filterpy")

from locbench.core.errors import FilterDiverged
from locbench.core.events import LandmarkObservations, Odometry
from locbench.datasets.dataset import Gaussian2, Landmarks, SensorSpec, WorldMap
from locbench.filters import _ukf_kernels as kern
from locbench.filters import ukf_landmarks as ukfm
from locbench.filters._motion import MotionModel

N_BELIEFS = 400
R_LM = (0.01, 0.0004)
#: The kernels against numpy, OpenBLAS, LAPACK and filterpy agree to rounding, not bit for bit: those libraries pick
#: their dot, factorisation and transcendental kernels per CPU at run time (SIMD width, FMA, AVX-512). Each element
#: must lie within REL of its array's largest magnitude (normwise, as the error bounds of sums and Cholesky factors
#: are). 1e-9 leaves room for the cancellation in sigma-point deviations (spreads down to ~1e-5 of means ~10, which
#: turns 1-ulp differences into ~1e-10 relative ones); a wrong weight or term is off by O(1).
REL = 1e-9
WEIGHTS = [(1.0, 2.0, 0.0), (0.5, 2.0, 1.0)]


def _close(got: np.ndarray, want: np.ndarray, heading: int | None = None) -> None:
    """``got`` equals ``want`` within :data:`REL` normwise; element ``heading`` compared as a wrapped difference."""
    got, want = np.array(got, dtype=np.float64), np.array(want, dtype=np.float64)
    if heading is not None:  # an angle near +-pi may wrap to the other end on one side
        got[heading] = want[heading] + ukfm.wrap_scalar(float(got[heading] - want[heading]))
    scale = float(np.max(np.abs(want)))
    np.testing.assert_allclose(got, want, rtol=REL, atol=REL * scale)


def _buffer(alpha: float, beta: float, kappa: float, x: np.ndarray, P: np.ndarray) -> np.ndarray:
    buf = kern.weights_buffer(*kern.sigma_weights(alpha, beta, kappa))
    buf[0:3], buf[3:12] = x, P.reshape(9)
    return buf


def _beliefs(seed: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Random means (headings across +-pi) and symmetric positive-definite covariances over 7 decades."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(N_BELIEFS):
        A = rng.normal(size=(3, 3))
        P = A @ A.T * 10.0 ** rng.uniform(-6.0, 1.0)
        x = np.array([rng.normal() * 10.0, rng.normal() * 10.0, rng.uniform(-math.pi, math.pi)])
        out.append((x, 0.5 * (P + P.T)))
    return out


@pytest.mark.parametrize("weights", WEIGHTS)
def test_weights_equal_filterpy(weights: tuple[float, float, float]) -> None:
    pts = ref.sigma_points_of(*weights)
    wm, wc, scale = kern.sigma_weights(*weights)
    np.testing.assert_allclose(wm, pts.Wm, rtol=1e-15, atol=0)
    np.testing.assert_allclose(wc, pts.Wc, rtol=1e-15, atol=0)
    alpha, _, kappa = weights
    assert scale == pytest.approx(alpha**2 * (3 + kappa), rel=1e-15)  # n + lambda


@pytest.mark.parametrize("weights", WEIGHTS)
def test_sigma_points_equal_the_reference(weights: tuple[float, float, float]) -> None:
    pts = ref.sigma_points_of(*weights)
    for x, P in _beliefs(1):
        buf = _buffer(*weights, x, P)
        assert kern.sigma_points(buf) == 0
        sig = buf[kern.B_SIG : kern.B_SIG + 21].reshape(7, 3)
        want = pts.sigma_points(x, P)
        for k in range(7):
            _close(sig[k], want[k], heading=2)


def test_sigma_points_decline_where_the_factorisation_fails() -> None:
    buf = _buffer(*WEIGHTS[0], np.zeros(3), -np.eye(3))
    assert kern.sigma_points(buf) != 0
    with pytest.raises(np.linalg.LinAlgError):
        ref.sigma_points_of().sigma_points(np.zeros(3), -np.eye(3))


def test_strided_dot_is_a_dot_product() -> None:
    # against numpy's dot, whose summation order depends on the CPU's kernel: the dot product's error bound,
    # 2 n eps sum |w_i a_ij| for either side (n = 7)
    rng = np.random.default_rng(2)
    eps = np.finfo(np.float64).eps
    for _ in range(2000):
        w = rng.normal(size=7)
        a = rng.normal(size=(7, 3)) * 10.0 ** rng.uniform(-3.0, 3.0)
        for j in range(3):
            bound = 2 * 7 * eps * float(np.abs(w) @ np.abs(a[:, j]))
            assert abs(kern._dot_strided(w, a.reshape(-1), j, 3) - float(w @ a[:, j])) <= bound


@pytest.mark.parametrize("encoder", [True, False])
@pytest.mark.parametrize("weights", WEIGHTS)
def test_predict_equals_the_reference_transform(encoder: bool, weights: tuple[float, float, float]) -> None:
    pts = ref.sigma_points_of(*weights)
    rng = np.random.default_rng(3)
    skipped = 0
    for x, P in _beliefs(4):
        buf = _buffer(*weights, x, P)
        Q = np.diag(rng.uniform(0.0, 1e-3, 3))
        Q[0, 1] = Q[1, 0] = 1e-5 * rng.normal()
        buf[kern.B_Q : kern.B_Q + 9] = Q.reshape(9)
        d = rng.normal(size=3) * 0.2
        sig = pts.sigma_points(x, P)
        moved = midpoint_moved(sig, d[0], d[1]) if encoder else increment_moved(sig, d[0], d[1], d[2])
        xm, Pm = ref.pose_transform(moved, pts, Q)
        assert kern.predict(buf, encoder, d[0], d[1], d[2]) == 0
        if ref.on_the_wrap(moved[:, 2] - xm[2]):
            skipped += 1
            continue
        xm[2] = ukfm.wrap_scalar(float(xm[2]))
        _close(buf[0:3], xm, heading=2)
        _close(buf[3:12], (0.5 * (Pm + Pm.T)).reshape(9))
    assert skipped < N_BELIEFS // 4  # about 10 % of the random beliefs span the whole circle


def test_landmark_sums_equal_the_reference_transform() -> None:
    pts = ref.sigma_points_of()
    rng = np.random.default_rng(5)
    skipped = 0
    for x, P in _beliefs(6):
        buf = _buffer(*WEIGHTS[0], x, P)
        lm = rng.normal(size=2) * 10.0
        r, b = rng.uniform(0.1, 10.0), rng.uniform(-3.0, 3.0)
        assert kern.landmark_sums(buf, r, b, lm[0], lm[1], *R_LM) == 0
        sig, sh, zp, S, Pxz = ref.landmark_transform(x, P, pts, lm, np.diag(R_LM))
        if ref.on_the_wrap(sig[:, 2] - x[2]) or ref.on_the_wrap(sh[:, 1] - zp[1]):
            skipped += 1
            continue
        out = buf[kern.B_S : kern.B_SIGH]
        for k in range(7):  # (range, bearing) per sigma point
            _close(buf[kern.B_SIGH + 2 * k : kern.B_SIGH + 2 * k + 2], sh[k], heading=1)
        _close(out[0:4], S.reshape(-1))
        _close(out[4:10], Pxz.reshape(-1))
        _close(out[10:12], ref.residual_bearing(np.array([r, b]), zp), heading=1)
    assert skipped < N_BELIEFS // 4  # about 10 % of the random beliefs span the whole circle


def _reference_d2(
    x: np.ndarray, P: np.ndarray, pts: object, xy: np.ndarray, r: float, b: float, limits: tuple[float, float, float]
) -> np.ndarray:
    """The squared Mahalanobis distance of (r, b) to each landmark through the reference transform; inf where a
    landmark is no candidate (within 1e-6 m of a sigma point, S not positive definite, outside ``limits``)."""
    out = np.full(len(xy), np.inf)
    for i, lm in enumerate(xy):
        sig, _, zp, S, _ = ref.landmark_transform(x, P, pts, lm, np.diag(R_LM))
        near = np.min(np.hypot(lm[0] - sig[:, 0], lm[1] - sig[:, 1]))
        inside = limits[0] <= zp[0] <= limits[1] and abs(zp[1]) <= limits[2]
        if near > 1e-6 and np.linalg.det(S) > 0.0 and inside:
            v = ref.residual_bearing(np.array([r, b]), zp)
            out[i] = float(v @ np.linalg.solve(S, v))
    return out


def test_nearest_row_equals_the_reference_distances() -> None:
    pts = ref.sigma_points_of()
    rng = np.random.default_rng(9)
    gate = 9.21
    limits = (0.2, 8.0, 1.2)
    rows = np.arange(30, dtype=np.int64)
    decided = 0
    for x, P in _beliefs(10)[:150]:
        xy = x[:2] + rng.uniform(-6.0, 6.0, size=(30, 2))
        used = np.zeros(30, dtype=np.int64)
        used[rng.integers(0, 30, size=3)] = 1
        target = xy[int(rng.integers(30))]
        want = ref.range_bearing(x, target) + rng.normal(size=2) * (0.05, 0.02)
        buf = _buffer(*WEIGHTS[0], x, P)
        assert kern.sigma_points(buf) == 0
        got = kern.nearest_row(buf, want[0], want[1], xy, rows, used, np.array(limits), *R_LM, gate)
        d2 = _reference_d2(x, P, pts, xy, float(want[0]), float(want[1]), limits)
        d2[used == 1] = np.inf
        order = np.argsort(d2, kind="stable")
        best, second = d2[order[0]], d2[order[1]]
        tie = bool(np.isfinite(second)) and second - best <= 1e-9 * best
        if tie or abs(best - gate) <= 1e-9 * gate:
            continue  # a tie or a gate decision within rounding: either answer is right
        assert got == (int(order[0]) if best <= gate else -1)
        decided += got >= 0
    assert decided > 20  # the test saw associations, not only rejections


def test_nearest_row_is_the_first_of_equal_distances_over_any_subset() -> None:
    """Each landmark's distance is computed on its own, so the winner over a subset that holds it is the same."""
    rng = np.random.default_rng(11)
    xy = rng.uniform(-6.0, 6.0, size=(40, 2))
    xy[17] = xy[5]  # two landmarks at one place: equal distances, the first row wins
    buf = _buffer(*WEIGHTS[0], np.array([0.5, -0.3, 0.2]), np.diag([0.2, 0.1, 0.05]))
    assert kern.sigma_points(buf) == 0
    used, lims = np.zeros(40, dtype=np.int64), np.empty(0)
    z = ref.range_bearing(np.array([0.5, -0.3, 0.2]), xy[5])
    full = kern.nearest_row(buf, z[0], z[1], xy, np.arange(40, dtype=np.int64), used, lims, *R_LM, math.inf)
    assert full == 5
    for _ in range(20):
        rows = np.sort(np.unique(np.append(rng.choice(40, size=int(rng.integers(1, 30)), replace=False), 5)))
        assert kern.nearest_row(buf, z[0], z[1], xy, rows.astype(np.int64), used, lims, *R_LM, math.inf) == 5


def _ukf() -> ukfm.LandmarkUKF:
    sensors = SensorSpec(wheelbase_m=0.4, encoder_k_left=0.01, encoder_k_right=0.01,
                         landmark_sigma_range_m=0.05, landmark_sigma_bearing_rad=0.02)  # fmt: skip
    world = WorldMap(landmarks=Landmarks(ids=np.array([1, 2]), xy=np.array([[3.0, 1.0], [-2.0, 2.0]])))
    flt = ukfm.LandmarkUKF(ukfm.LandmarkUKFConfig())
    flt.reset(Gaussian2(np.array([0.1, 0.2, 3.1]), np.diag([0.04, 0.09, 0.2])), world, sensors,
              np.random.default_rng(0))  # fmt: skip
    return flt


def test_a_set_state_is_taken_up_and_a_failed_factorisation_raises() -> None:
    flt = _ukf()
    flt._x, flt._P = [1.0, 0.0, 0.5], np.diag([0.01, 0.01, 0.01]).tolist()  # as the tests of the index do
    flt.update(LandmarkObservations(0.1, np.array([1]), np.array([2.2]), np.array([0.0])))
    assert flt.estimate().diagnostics["accepted"] == 1.0
    flt._P = (-np.eye(3)).tolist()
    with pytest.raises(np.linalg.LinAlgError, match="not positive definite"):
        flt.predict(Odometry(0.2, 0.05, 0.0, 0.01, d_left=0.048, d_right=0.052))
    with pytest.raises(np.linalg.LinAlgError, match="not positive definite"):
        flt.update(LandmarkObservations(0.3, np.array([1]), np.array([2.2]), np.array([0.0])))


def test_a_non_finite_prediction_raises_filter_diverged_and_keeps_the_state() -> None:
    flt = _ukf()
    flt._x = [1.7e308, 0.0, 0.0]  # one step of 1e308 m overflows the mean
    before = flt.estimate()
    with pytest.raises(FilterDiverged, match="non-finite"):
        flt.predict(Odometry(0.2, 1e308, 0.0, 0.0, d_left=1e308, d_right=1e308))
    after = flt.estimate()
    np.testing.assert_array_equal(after.mean, before.mean)  # the kernel left the state (ours against ours)
    np.testing.assert_array_equal(after.cov, before.cov)


def test_the_filter_equals_filterpys_ukf_over_a_drive() -> None:
    """Predictions and landmark updates of the filter against filterpy's ``UnscentedKalmanFilter`` (reference sigma
    points, the same motion noise per step), to rounding."""
    from filterpy.kalman import UnscentedKalmanFilter

    flt = _ukf()
    pts = ref.sigma_points_of()
    xy = np.array([[3.0, 1.0], [-2.0, 2.0]])

    def hx(s: np.ndarray, lm: np.ndarray) -> np.ndarray:
        return ref.range_bearing(s, lm)

    ukf = UnscentedKalmanFilter(3, 2, 0.0, hx, None, pts, x_mean_fn=ref.state_mean, z_mean_fn=ref.range_bearing_mean,
                                residual_x=ref.residual_heading, residual_z=ref.residual_bearing)  # fmt: skip
    ukf.x, ukf.P = flt.estimate().mean.copy(), flt.estimate().cov.copy()
    motion = MotionModel(flt._motion.noise)
    rng = np.random.default_rng(13)
    for k in range(40):
        dl, dr = 0.05 + 0.01 * rng.normal(), 0.05 + 0.01 * rng.normal()
        u = Odometry(0.1 * k, 0.05, 0.0, 0.0, d_left=dl, d_right=dr)
        n00, n01, n02, n11, n12, n22 = motion.step(list(ukf.x), u).noise  # the noise at the mean: an input of both
        q0, q1, q2 = flt._q
        ukf.Q = np.array([[n00 + q0, n01, n02], [n01, n11 + q1, n12], [n02, n12, n22 + q2]])
        flt.predict(u)
        ukf.predict(fx=lambda s, dt, dd=0.5 * (dl + dr), dth=(dr - dl) / 0.4: midpoint_moved(s[None], dd, dth)[0])
        ukf.x[2] = ukfm.wrap_scalar(float(ukf.x[2]))
        ukf.P = 0.5 * (ukf.P + ukf.P.T)
        row = k % 2
        z = ref.range_bearing(ukf.x, xy[row]) + rng.normal(size=2) * (0.05, 0.02)
        flt.update(LandmarkObservations(0.1 * k, np.array([row + 1]), z[:1].copy(), z[1:].copy()))
        ukf.update(z, R=np.diag([0.05**2, 0.02**2]), lm=xy[row])
        ukf.x[2] = ukfm.wrap_scalar(float(ukf.x[2]))
        ukf.P = 0.5 * (ukf.P + ukf.P.T)
        est = flt.estimate()
        _close(est.mean, ukf.x, heading=2)
        _close(est.cov, ukf.P)
