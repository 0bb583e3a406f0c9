"""The UKF's compiled kernels (filters/_ukf_kernels.py) against the filterpy/numpy forms they replace, on random
beliefs (to rounding: numpy, OpenBLAS and LAPACK pick their kernels per CPU), and the Python path they fall back to."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("filterpy")

from filterpy.kalman import MerweScaledSigmaPoints

from locbench.core.events import LandmarkObservations, Odometry
from locbench.datasets.dataset import Gaussian2, Landmarks, SensorSpec, WorldMap
from locbench.filters import _ukf_kernels as kern
from locbench.filters import ukf_landmarks as ukfm
from locbench.filters._kalman import gain_update

N_BELIEFS = 400
R_LM = (0.01, 0.0004)
#: The kernels against numpy, OpenBLAS, LAPACK and filterpy agree to rounding, not bit for bit: those libraries pick
#: their dot, factorisation and transcendental kernels per CPU at run time (SIMD width, FMA, AVX-512). Each element
#: must lie within REL of its array's largest magnitude (normwise, as the error bounds of sums and Cholesky factors
#: are). 1e-9 leaves room for the cancellation in sigma-point deviations (spreads down to ~1e-5 of means ~10, which
#: turns 1-ulp differences into ~1e-10 relative ones); a wrong weight or term is off by O(1).
REL = 1e-9


def _close(got: np.ndarray, want: np.ndarray, heading: int | None = None) -> None:
    """``got`` equals ``want`` within :data:`REL` normwise; element ``heading`` compared as a wrapped difference."""
    got, want = np.array(got, dtype=np.float64), np.array(want, dtype=np.float64)
    if heading is not None:  # an angle near +-pi may wrap to the other end on one side
        got[heading] = want[heading] + ukfm.wrap_scalar(float(got[heading] - want[heading]))
    scale = float(np.max(np.abs(want)))
    np.testing.assert_allclose(got, want, rtol=REL, atol=REL * scale)


def _points(alpha: float = 1.0, beta: float = 2.0, kappa: float = 0.0) -> MerweScaledSigmaPoints:
    return MerweScaledSigmaPoints(
        3, alpha=alpha, beta=beta, kappa=kappa, sqrt_method=ukfm.upper_cholesky, subtract=ukfm._residual_heading
    )


def _buffer(pts: MerweScaledSigmaPoints, x: np.ndarray, P: np.ndarray) -> np.ndarray:
    lam = pts.alpha**2 * (pts.n + pts.kappa) - pts.n  # filterpy's lambda
    buf = kern.weights_buffer(pts.Wm, pts.Wc, lam + pts.n)
    buf[0:3], buf[3:12] = x, P.reshape(9)
    return buf


def _on_the_wrap(angles: np.ndarray) -> bool:
    """Whether a wrapped residual lies within 1e-6 rad of +-pi: a belief spread around the whole circle puts a sigma
    point opposite its circular mean, where a 1-ulp difference flips the residual by 2 pi (both sides are right)."""
    return bool(np.any(math.pi - np.abs(ukfm.wrap_angle(angles)) < 1e-6))


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


@pytest.mark.parametrize("weights", [(1.0, 2.0, 0.0), (0.5, 2.0, 1.0)])
def test_sigma_points_equal_filterpy(weights: tuple[float, float, float]) -> None:
    pts = _points(*weights)
    for x, P in _beliefs(1):
        buf = _buffer(pts, x, P)
        assert kern.sigma_points(buf) == 0
        _close(buf[kern.B_SIG : kern.B_SIG + 21].reshape(7, 3), pts.sigma_points(x, P))  # against LAPACK's factor


def test_sigma_points_decline_where_the_factorisation_fails() -> None:
    pts = _points()
    buf = _buffer(pts, np.zeros(3), -np.eye(3))
    assert kern.sigma_points(buf) != 0
    with pytest.raises(np.linalg.LinAlgError):
        pts.sigma_points(np.zeros(3), -np.eye(3))


def test_strided_dot_equals_numpy() -> None:
    # against OpenBLAS's ddot, whose summation order depends on the CPU's kernel: the dot product's error bound,
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
@pytest.mark.parametrize("weights", [(1.0, 2.0, 0.0), (0.5, 2.0, 1.0)])
def test_predict_equals_filterpy_transform(encoder: bool, weights: tuple[float, float, float]) -> None:
    pts = _points(*weights)
    rng = np.random.default_rng(3)
    skipped = 0
    for x, P in _beliefs(4):
        buf = _buffer(pts, x, P)
        Q = np.diag(rng.uniform(0.0, 1e-3, 3))
        Q[0, 1] = Q[1, 0] = 1e-5 * rng.normal()
        buf[kern.B_Q : kern.B_Q + 9] = Q.reshape(9)
        d = rng.normal(size=3) * 0.2
        sig = pts.sigma_points(x, P)
        if encoder:
            moved = np.array([ukfm._move_midpoint(s, 0.0, d[0], d[1]) for s in sig])
        else:
            moved = np.array([ukfm._move_increment(s, 0.0, d[0], d[1], d[2]) for s in sig])
        xm, Pm = ukfm.pose_transform(moved, pts.Wm, pts.Wc, Q, ukfm.state_mean, ukfm._residual_heading)
        assert kern.predict(buf, encoder, d[0], d[1], d[2]) == 0
        if _on_the_wrap(moved[:, 2] - xm[2]):
            skipped += 1
            continue
        xm[2] = ukfm.wrap_scalar(float(xm[2]))  # the filter's _finish
        _close(buf[0:3], xm, heading=2)
        _close(buf[3:12], (0.5 * (Pm + Pm.T)).reshape(9))
    assert skipped < N_BELIEFS // 4  # about 10 % of the random beliefs span the whole circle


def test_landmark_sums_equal_the_numpy_correction() -> None:
    pts = _points()
    rng = np.random.default_rng(5)
    R = np.diag(R_LM)
    skipped = 0
    for x, P in _beliefs(6):
        buf = _buffer(pts, x, P)
        lx, ly = rng.normal(size=2) * 10.0
        r, b = rng.uniform(0.1, 10.0), rng.uniform(-3.0, 3.0)
        assert kern.landmark_sums(buf, r, b, lx, ly, *R_LM) == 0
        sig = pts.sigma_points(x, P)
        sh = ukfm._range_bearing_points(sig, lx, ly)
        zp = ukfm.range_bearing_mean(sh, pts.Wm)
        S = ukfm._moments(sh, pts.Wc, zp, R, 1)
        dx = sig - x
        dx[:, 2] = ukfm.wrap_angle(dx[:, 2])
        dz = sh - zp
        dz[:, 1] = ukfm.wrap_angle(dz[:, 1])
        out = buf[kern.B_S : kern.B_SIGH]
        if _on_the_wrap(dx[:, 2]) or _on_the_wrap(dz[:, 1]):
            skipped += 1
            continue
        for k in range(7):  # (range, bearing) per sigma point: the bearing from numpy's arctan2
            _close(buf[kern.B_SIGH + 2 * k : kern.B_SIGH + 2 * k + 2], sh[k], heading=1)
        _close(out[0:4], S.reshape(-1))
        _close(out[4:10], ukfm._weighted_outer_sum(pts.Wc, dx, dz, None).reshape(-1))
        _close(out[10:12], ukfm._residual_bearing(np.array([r, b]), zp), heading=1)
    assert skipped < N_BELIEFS // 4  # about 10 % of the random beliefs span the whole circle


def test_gain_equals_gain_update() -> None:
    rng = np.random.default_rng(7)
    for x, P in _beliefs(8)[:100]:
        A = rng.normal(size=(2, 2))
        S = A @ A.T + np.eye(2) * 0.01
        Pxz, y = rng.normal(size=(3, 2)), rng.normal(size=2)
        c = gain_update(x, P, y, S, Pxz)
        x_new, P_new, nis = ukfm._gain(x, P, y, S, Pxz)
        # both ours, the same numpy calls in one process: the same bits on any CPU
        assert np.array_equal(x_new, c.x) and np.array_equal(P_new, c.P) and nis == c.nis


def _ukf() -> ukfm.LandmarkUKF:
    sensors = SensorSpec(wheelbase_m=0.4, encoder_k_left=0.01, encoder_k_right=0.01,
                         landmark_sigma_range_m=0.05, landmark_sigma_bearing_rad=0.02)  # fmt: skip
    world = WorldMap(landmarks=Landmarks(ids=np.array([1, 2]), xy=np.array([[3.0, 1.0], [-2.0, 2.0]])))
    flt = ukfm.LandmarkUKF(ukfm.LandmarkUKFConfig())
    flt.reset(Gaussian2(np.array([0.1, 0.2, 3.1]), np.diag([0.04, 0.09, 0.2])), world, sensors,
              np.random.default_rng(0))  # fmt: skip
    return flt


def test_a_replaced_state_is_taken_up_and_a_failed_factorisation_raises_as_before() -> None:
    flt = _ukf()
    flt._ukf.x, flt._ukf.P = np.array([1.0, 0.0, 0.5]), np.diag([0.01, 0.01, 0.01])  # as the tests of the index do
    flt.update(LandmarkObservations(0.1, np.array([1]), np.array([2.2]), np.array([0.0])))
    assert flt.estimate().diagnostics["accepted"] == 1.0
    flt._ukf.P = -np.eye(3)
    with pytest.raises(np.linalg.LinAlgError, match="dpotrf"):
        flt.predict(Odometry(0.2, 0.05, 0.0, 0.01, d_left=0.048, d_right=0.052))
