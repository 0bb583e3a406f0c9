"""Unscented Kalman filter with the landmark EKF's models: the filter users compare an EKF against.

The state, the motion model, the measurement models and the association are those of
:mod:`locbench.filters.ekf_landmarks` (reports 003 and 001); only the way the Gaussian is carried through the
nonlinear functions differs. filterpy's ``UnscentedKalmanFilter`` with ``MerweScaledSigmaPoints`` (van der
Merwe 2004; the scaled unscented transform of Julier 2002) does the algebra:

    sigma points  chi_0 = x,  chi_i = x +- (sqrt((n + lambda) P))_i,   lambda = alpha^2 (n + kappa) - n,
    weights       Wm_0 = lambda / (n + lambda),  Wc_0 = Wm_0 + 1 - alpha^2 + beta,  Wm_i = Wc_i = 1 / (2 (n + lambda)).

Defaults alpha = 1, beta = 2, kappa = 0 (n = 3): kappa = 3 - n is Julier's rule for a Gaussian prior, and
alpha = 1 keeps the points at sqrt(3) standard deviations, so that they sample the nonlinearity over the
belief's own extent (a tiny alpha, robot_localization's 0.001, makes the transform a numerical linearisation
with weights near -1e6).

Prediction: each sigma point is moved by the EKF's mean motion (the midpoint chord of report 003 eq. 5 when the
encoder model applies, else the composed increment), and the motion noise G U G^T + Q that the EKF adds
(:class:`~locbench.filters._motion.MotionModel`, evaluated at the mean) is added to the transformed covariance
(additive-noise UKF).

Headings are angles: the mean of sigma points takes the circular mean of their headings,
atan2(sum Wm sin theta, sum Wm cos theta), and every state residual wraps its heading to (-pi, pi]; the
predicted bearing of a landmark is averaged and wrapped the same way, and the bearing innovation is wrapped
(:func:`locbench.filters._kalman.wrapped_residual`).

Correction: the sightings of one event are fused one at a time, known identities first, then nearest
neighbours, exactly as in the EKF; the sigma points are redrawn from the current (x, P) before each
measurement, so each one sees the state corrected by the previous. The nearest-neighbour gate uses the unscented
predicted measurement and S = sum Wc (z_i - z)(z_i - z)^T + R of every candidate landmark at once. Range-only
beacons and pose fixes use the same gates as the EKF (1 dof, and none for fixes). A gated-out measurement
leaves the state unchanged. The gain step is the Kalman core's sigma-point form (K = P_xz S^-1,
P - K S K^T, symmetrised), fed by filterpy's unscented transform and cross covariance.

Speed: filterpy calls its callbacks once per sigma point, so they are kept small. The matrix square root is
LAPACK's Cholesky called directly (the factor scipy returns, without its checks), the unscented transform
handed to ``predict`` and the sums of the correction wrap the angle residuals of all points at once, and the
measurement functions map all points in one call; every sum keeps filterpy's order of terms, so the estimates
are those of filterpy's own loops to the bit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter
from scipy.linalg.lapack import dpotrf

from locbench.core.errors import ConfigError, FilterDiverged
from locbench.core.events import Odometry, PoseFix
from locbench.core.geometry import TWO_PI, wrap_angle, wrap_scalar
from locbench.datasets.dataset import Gaussian2, SensorSpec, WorldMap
from locbench.filters import _ukf_kernels as kern
from locbench.filters._kalman import gain_update, subtract
from locbench.filters._landmark_index import NEAR_M
from locbench.filters.base import NON_NEGATIVE, Estimate, FilterConfig, FilterDoc, bound
from locbench.filters.ekf_landmarks import LandmarkEKF, LandmarkEKFConfig

FloatArray = npt.NDArray[np.float64]


def _residual_heading(a: FloatArray, b: FloatArray) -> FloatArray:
    """Pose difference a - b with the heading wrapped to (-pi, pi] (the sigma points' ``subtract``)."""
    y = a - b
    y[2] = math.pi - ((math.pi - float(y[2])) % TWO_PI)  # wrap_scalar, inlined: called six times per draw
    return y


def _residual_bearing(a: FloatArray, b: FloatArray) -> FloatArray:
    """(range, bearing) difference a - b with the bearing wrapped to (-pi, pi]."""
    y = np.asarray(a, dtype=np.float64) - b
    y[1] = wrap_scalar(float(y[1]))
    return y


def upper_cholesky(A: FloatArray) -> FloatArray:
    """Upper Cholesky factor U (U^T U = A) of a positive-definite matrix, the sigma points' matrix square root.

    LAPACK's ``dpotrf`` called directly: the factor ``scipy.linalg.cholesky`` (filterpy's default) returns, bit
    for bit, without that wrapper's argument checks, which cost some 40 times the factorisation of a 3x3.
    """
    U, info = dpotrf(A, lower=0, clean=1)
    if info != 0:
        raise np.linalg.LinAlgError(f"covariance is not positive definite (dpotrf info {info})")
    return np.asarray(U, dtype=np.float64)


def _moments(
    sigmas: FloatArray, Wc: FloatArray, mean: FloatArray, noise_cov: FloatArray | None, angle: int
) -> FloatArray:
    """sum_k Wc_k r_k r_k^T (+ noise) with r_k = sigmas_k - mean, component ``angle`` wrapped (none if -1).

    The sum runs over the points in order, as filterpy's loop of outer products does, so the result is the same
    to the bit; numpy does it in one pass.
    """
    r = sigmas - mean
    if angle >= 0:
        r[:, angle] = wrap_angle(r[:, angle])
    return _weighted_outer_sum(Wc, r, r, noise_cov)


def _weighted_outer_sum(Wc: FloatArray, a: FloatArray, b: FloatArray, start: FloatArray | None) -> FloatArray:
    """sum_k Wc_k a_k b_k^T, accumulated over k in order (numpy reduces the leading axis one row at a time), plus
    ``start`` if given."""
    out: FloatArray = (Wc[:, None, None] * (a[:, :, None] * b[:, None, :])).sum(axis=0)
    if start is not None:
        out += start
    return out


def circular_mean(angles: FloatArray, weights: FloatArray) -> float:
    """Weighted circular mean atan2(sum w sin a, sum w cos a) of angles (rad), in (-pi, pi]."""
    return wrap_scalar(math.atan2(float(weights @ np.sin(angles)), float(weights @ np.cos(angles))))


def state_mean(sigmas: FloatArray, weights: FloatArray) -> FloatArray:
    """Weighted mean of poses (n, 3): arithmetic in x and y, circular in the heading."""
    return np.array([weights @ sigmas[:, 0], weights @ sigmas[:, 1], circular_mean(sigmas[:, 2], weights)])


def range_bearing_mean(sigmas: FloatArray, weights: FloatArray) -> FloatArray:
    """Weighted mean of (range, bearing) measurements (n, 2): arithmetic range, circular bearing."""
    return np.array([weights @ sigmas[:, 0], circular_mean(sigmas[:, 1], weights)])


def _fix_mean(sigmas: FloatArray, weights: FloatArray) -> FloatArray:
    if sigmas.shape[1] == 3:
        return state_mean(sigmas, weights)
    return np.asarray(weights @ sigmas, dtype=np.float64)


def pose_transform(
    sigmas: FloatArray, Wm: FloatArray, Wc: FloatArray, noise_cov: FloatArray | None, mean_fn: Any, residual_fn: Any
) -> tuple[FloatArray, FloatArray]:
    """filterpy's ``unscented_transform`` for poses (the ``UT`` argument of ``predict``): the same mean and
    covariance, with the heading residuals wrapped for all points at once instead of one call per point.

    ``mean_fn`` is the filter's ``x_mean_fn``; ``residual_fn`` (the heading-wrapping residual) is replaced by its
    vectorised equivalent.
    """
    x = mean_fn(sigmas, Wm)
    return x, _moments(sigmas, Wc, x, noise_cov, 2)


@dataclass(frozen=True, kw_only=True)
class LandmarkUKFConfig(LandmarkEKFConfig):
    """Configuration of :class:`LandmarkUKF`: every field of :class:`LandmarkEKFConfig`, and the sigma points.

    Attributes
    ----------
    alpha : float
        Spread of the sigma points (Merwe's scaling), in (0, 1]; 1 puts them at sqrt(n + kappa) sigma.
    beta : float
        Prior-knowledge term of the zeroth covariance weight; 2 is optimal for a Gaussian.
    kappa : float
        Secondary scaling; 3 - n = 0 for the 3-dof pose (Julier's rule).
    """

    alpha: float = field(default=1.0, metadata=bound(0.0, 1.0, low_open=True))
    beta: float = field(default=2.0, metadata=NON_NEGATIVE)
    kappa: float = 0.0

    def __post_init__(self) -> None:
        super().__post_init__()  # the bounds declared on the fields (alpha, beta); kappa's rule joins alpha
        if self.alpha**2 * (3.0 + self.kappa) <= 0.0:
            raise ConfigError(f"kappa must be > -3 (n + lambda > 0 for the 3-dof pose), got {self.kappa}")


class LandmarkUKF(LandmarkEKF):
    """Unscented Kalman filter on (x, y, theta) with the models and association of :class:`LandmarkEKF`.

    It inherits the EKF's configuration, event routing, sensor-limit pruning and the order in which one event's
    sightings are associated and fused; it replaces the state (a filterpy ``UnscentedKalmanFilter``), the
    prediction and every correction (module docstring). Diagnostics as the EKF's.
    """

    id: ClassVar[str] = "ukf_landmarks"
    order: ClassVar[int] = 20
    description: ClassVar[str] = (
        "unscented KF (filterpy, Merwe sigma points) with ekf_landmarks' motion, landmark, range and fix models"
    )
    requires_modules: ClassVar[tuple[str, ...]] = ("filterpy",)
    install_hint: ClassVar[str] = "pip install 'locbench[filterpy]'"
    doc: ClassVar[FilterDoc | None] = FilterDoc(
        "Julier & Uhlmann, van der Merwe; models of 003, 001",
        "`ekf_landmarks`' motion model through Merwe scaled sigma points (filterpy `UnscentedKalmanFilter`), "
        "circular heading mean",
        "`ekf_landmarks`' range-bearing, range-only and pose-fix models through the unscented transform, wrapped "
        "residuals; the same association and gates",
        "additive-noise UKF: each sigma point moves with the EKF's mean motion, the EKF's motion noise is added",
    )
    #: the default alone: the EKF's nearest-neighbour configuration is not repeated with sigma points
    comparison_configurations: ClassVar[tuple[dict[str, str], ...]] = ()
    Config: ClassVar[type[FilterConfig]] = LandmarkUKFConfig
    # 2: the process noise Q is the dataset's when it declares one (0 on a model-matched world); 3: estimates equal
    # to version 2's to rounding (stored version-2 runs moved by at most 5.6e-10 m in waypoint errors)
    version: ClassVar[int] = 3
    cost_per_data_s: ClassVar[float] = 0.05  # the EKF's model through 7 sigma points
    source: ClassVar[str] = (
        "Julier & Uhlmann 2004; van der Merwe 2004 (scaled sigma points, filterpy); models of 003_e5c93f9be776ee5e "
        "and 001_71e01b0c4f2511a1"
    )

    config: LandmarkUKFConfig
    _compiled_update: ClassVar[bool] = False  # its own corrections, in the EKF's order (_fuse_sightings)

    def reset(self, initial: Gaussian2, world: WorldMap, sensors: SensorSpec, rng: np.random.Generator) -> None:
        """Start from ``initial`` with the landmarks of ``world``; ``rng`` is unused (the UKF is deterministic)."""
        self._ukf: Any = None  # filterpy is untyped; a previous run's state must not be checked by the EKF's reset
        super().reset(initial, world, sensors, rng)
        cfg = self.config
        points = MerweScaledSigmaPoints(
            3, alpha=cfg.alpha, beta=cfg.beta, kappa=cfg.kappa, sqrt_method=upper_cholesky, subtract=_residual_heading
        )
        ukf = UnscentedKalmanFilter(
            dim_x=3,
            dim_z=2,
            dt=0.0,
            hx=None,
            fx=None,
            points=points,
            x_mean_fn=state_mean,
            residual_x=_residual_heading,
        )
        # the state is the kernels' buffer (_ukf_kernels); ukf.x and ukf.P are views of it (_sync)
        lam = points.alpha**2 * (points.n + points.kappa) - points.n  # filterpy's lambda, its n + lambda below
        self._kb = kern.weights_buffer(ukf.Wm, ukf.Wc, lam + points.n)
        self._kx, self._kP = self._kb[0:3], self._kb[3:12].reshape(3, 3)
        self._kb[0:3] = self._x
        self._kb[3:12] = np.asarray(self._P, dtype=np.float64).reshape(9)
        ukf.x, ukf.P = self._kx, self._kP
        self._ukf = ukf
        self._R_lm = np.diag([self._rr, self._rb])
        # the k-d tree's bound (_gate_radius) needs non-negative weights (alpha = 1, beta = 2, kappa = 0 has them)
        self._weights_nonnegative = bool(np.all(ukf.Wm >= 0.0) and np.all(ukf.Wc >= 0.0))
        self._wc_sum = float(np.sum(ukf.Wc))
        self._check_finite(math.nan)

    # --- predict ---------------------------------------------------------------------------------------------

    def predict(self, u: Odometry) -> None:
        """Move every sigma point with the mean motion; add the EKF's motion noise (module docstring).

        One compiled call (:func:`._ukf_kernels.predict`: filterpy's arithmetic in its order); filterpy's own
        ``predict`` when the kernel declines (a failed factorisation or a non-finite value), which raises as
        before.
        """
        ukf, kb = self._ukf, self._kb
        self._sync()
        step = self._motion.step(self._kx.tolist(), u)  # noise and model choice at the mean (and the travel count)
        n00, n01, n02, n11, n12, n22 = step.noise
        q0, q1, q2 = self._q
        Q = [n00 + q0, n01, n02, n01, n11 + q1, n12, n02, n12, n22 + q2]
        kb[kern.B_Q : kern.B_Q + 9] = Q
        if step.encoder:
            W = self._motion.noise.wheelbase_m
            assert W is not None and u.d_left is not None and u.d_right is not None  # guaranteed by step.encoder
            dd, dth = 0.5 * (u.d_left + u.d_right), (u.d_right - u.d_left) / W  # eq. 1-2
            if kern.predict(kb, True, dd, dth, 0.0) != 0:
                ukf.Q = np.array(Q).reshape(3, 3)
                ukf.predict(UT=pose_transform, fx=_move_midpoint, dd=dd, dth=dth)
                self._finish(ukf.x, ukf.P)
        elif kern.predict(kb, False, u.dx, u.dy, u.dtheta) != 0:
            ukf.Q = np.array(Q).reshape(3, 3)
            ukf.predict(UT=pose_transform, fx=_move_increment, dx=u.dx, dy=u.dy, dth=u.dtheta)
            self._finish(ukf.x, ukf.P)
        self._t = u.t
        self._nis, self._nis_dof, self._accepted, self._rejected = math.nan, 0, 0, 0
        self._check_finite(u.t)

    # --- corrections ------------------------------------------------------------------------------------------

    def _sync(self) -> None:
        """Make the buffer the state again if ``ukf.x`` or ``ukf.P`` were replaced (filterpy's ``predict``, tests)."""
        ukf = self._ukf
        if ukf.x is not self._kx or ukf.P is not self._kP:
            self._kb[0:3] = np.asarray(ukf.x, dtype=np.float64).reshape(3)
            self._kb[3:12] = np.asarray(ukf.P, dtype=np.float64).reshape(9)
            ukf.x, ukf.P = self._kx, self._kP

    def _finish(self, x: FloatArray, P: FloatArray) -> None:
        x[2] = wrap_scalar(float(x[2]))
        self._kb[0:3] = x
        self._kb[3:12] = (0.5 * (P + P.T)).reshape(9)
        self._ukf.x, self._ukf.P = self._kx, self._kP

    def _correct(
        self, z: FloatArray, R: FloatArray, h_all: Any, z_mean: Any, residual: Any, angle: int, gate: float
    ) -> float | None:
        """One unscented correction; its NIS, or None (state unchanged) when outside ``gate``.

        filterpy's update in its parts: the sigma points are redrawn at the state the previous measurement left,
        ``h_all`` maps all of them at once to measurements (n_sigma, m), their weighted mean is ``z_mean`` (the
        plain weighted sum if None), S (R included) and P_xz are filterpy's sums of outer products, with the
        residuals' component ``angle`` wrapped (-1: none); the gain step is the core's
        :func:`~locbench.filters._kalman.gain_update` (K = P_xz S^-1, P - K S K^T, as filterpy's), which also gives
        the NIS for the gate. ``residual`` forms the innovation.
        """
        ukf = self._ukf
        x, P = ukf.x, ukf.P
        sigmas = ukf.points_fn.sigma_points(x, P)
        sigmas_h = h_all(sigmas)
        zp = np.dot(ukf.Wm, sigmas_h) if z_mean is None else z_mean(sigmas_h, ukf.Wm)
        S = _moments(sigmas_h, ukf.Wc, zp, R, angle)
        dx = sigmas - x
        dx[:, 2] = wrap_angle(dx[:, 2])
        dz = sigmas_h - zp
        if angle >= 0:
            dz[:, angle] = wrap_angle(dz[:, angle])
        c = gain_update(x, P, residual(z, zp), S, _weighted_outer_sum(ukf.Wc, dx, dz, None))
        if not c.nis <= gate:
            return None
        self._finish(c.x, c.P)
        return c.nis

    def _correct_landmark(self, r: float, b: float, row: int, gate: float) -> float | None:
        """Fuse one (range, bearing) of landmark ``row``; its NIS, or None if gated out."""
        lx, ly = self._lm_list[row]
        self._sync()
        x = self._kx
        if math.hypot(lx - float(x[0]), ly - float(x[1])) < 1e-6:
            return None  # on top of the landmark: the bearing is undefined
        kb = self._kb
        if kern.landmark_sums(kb, r, b, lx, ly, self._rr, self._rb) == 0:  # the sums of _correct, compiled
            o = kb[kern.B_S : kern.B_SIGH]
            x_new, P_new, nis = _gain(x, self._kP, o[10:12], o[0:4].reshape(2, 2), o[4:10].reshape(3, 2))
            if not nis <= gate:
                return None
            self._finish(x_new, P_new)
            return nis

        def h_all(sigmas: FloatArray) -> FloatArray:
            return _range_bearing_points(sigmas, lx, ly)

        return self._correct(np.array([r, b]), self._R_lm, h_all, range_bearing_mean, _residual_bearing, 1, gate)

    def _nearest(self, r: float, b: float, used: set[int]) -> int | None:
        """Row of the landmark nearest to (r, b) in the unscented Mahalanobis distance, inside the gate; else None.

        A large map with non-negative weights tests only the landmarks of the k-d tree within
        :meth:`_gate_radius`, in row order; every landmark's d2 is the same number either way (the weighted
        sums are taken per landmark, :func:`_weighted_sum`), so the first smallest is the same row.
        """
        ukf = self._ukf
        self._sync()
        if kern.sigma_points(self._kb) == 0:  # filterpy's points, compiled
            sig = self._kb[kern.B_SIG : kern.B_SIG + 21].reshape(7, 3).copy()
        else:
            sig = ukf.points_fn.sigma_points(ukf.x, ukf.P)  # (7, 3); raises as before
        rows: list[int] | None = None
        if self._index is not None and self._weights_nonnegative:
            radius = self._gate_radius(r, sig)
            if radius is not None:
                rows = self._index.candidates(sig[0].tolist(), r, b, radius[0], radius[1])
                if not rows:
                    return None
        d2 = self._mahalanobis_all(r, b, used, sig, rows)
        best = int(np.argmin(d2))
        if not d2[best] <= self._gate:
            return None
        return best if rows is None else rows[best]

    def _gate_radius(self, r: float, sig: FloatArray) -> tuple[float, float] | None:
        """(radius m, near m) for :meth:`LandmarkIndex.candidates`: a landmark farther than ``near`` from the
        mean that passes the gate lies within ``radius`` of the sighted point; None when no such bound follows.

        The bound of :mod:`._landmark_index` for the unscented S, with weights Wm, Wc >= 0 (sum Wm = 1) and the
        sigma points within rho (m) of the mean in position and tau (rad) in heading. A landmark at d0 >= near
        >= 2 rho from the mean has every sigma point's range within rho of d0 and bearing within
        delta = asin(rho / near) + tau of the mean's (an angle subtended plus the heading's spread), so the
        predicted range is within rho of d0 and the circular mean bearing within delta (all points lie in an
        arc of half-width delta < pi / 2); hence S_00 <= sum Wc (2 rho)^2 + sigma_r^2 and
        S_11 <= sum Wc (2 delta)^2 + sigma_b^2, and d2 <= g bounds |vr| and |vb| as for the EKF. The landmark
        then lies within (|vr| + rho) + (r + |vr| + rho) min(|vb| + delta, pi) of the sighted point.
        """
        d = sig[1:, :2] - sig[0, :2]
        rho = math.sqrt(float(np.max(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1])))
        tau = float(np.max(np.abs(wrap_angle(sig[1:, 2] - sig[0, 2]))))
        near = max(NEAR_M, 2.0 * rho)
        delta = math.asin(min(1.0, rho / near)) + tau
        if not delta < 0.5 * math.pi:
            return None  # a heading spread this wide bounds nothing: test every landmark
        g, wc = self._gate, self._wc_sum
        vr = math.sqrt(g * (wc * 4.0 * rho * rho + self._rr))
        vb = math.sqrt(g * (wc * 4.0 * delta * delta + self._rb))
        return (vr + rho) + (r + vr + rho) * min(vb + delta, math.pi), near

    def _mahalanobis_all(
        self, r: float, b: float, used: set[int], sig: FloatArray, rows: list[int] | None = None
    ) -> FloatArray:
        """Squared Mahalanobis distance of (r, b) to the map landmarks ``rows`` (default every one) through the
        unscented transform of the sigma points ``sig`` (7, 3); inf where excluded."""
        ukf = self._ukf
        Wm, Wc = ukf.Wm, ukf.Wc
        xy = self._lm_xy if rows is None else self._lm_xy[rows]
        lx = xy[None, :, 0] - sig[:, None, 0]
        ly = xy[None, :, 1] - sig[:, None, 1]
        rng = np.hypot(lx, ly)  # (7, L)
        brg = np.arctan2(ly, lx) - sig[:, None, 2]
        r_hat = _weighted_sum(Wm, rng)
        b_hat = np.arctan2(_weighted_sum(Wm, np.sin(brg)), _weighted_sum(Wm, np.cos(brg)))
        er, eb = rng - r_hat, wrap_angle(brg - b_hat)
        s00 = _weighted_sum(Wc, er * er) + self._rr
        s01 = _weighted_sum(Wc, er * eb)
        s11 = _weighted_sum(Wc, eb * eb) + self._rb
        vr, vb = r - r_hat, wrap_angle(b - b_hat)
        det = s00 * s11 - s01 * s01
        with np.errstate(divide="ignore", invalid="ignore"):
            d2 = (s11 * vr * vr - 2.0 * s01 * vr * vb + s00 * vb * vb) / det
        if rows is not None and used:
            used = {i for i, row in enumerate(rows) if row in used}
        return self._exclude(d2, ~(det > 0.0) | ~(np.min(rng, axis=0) > 1e-6), r_hat, b_hat, used)

    def _exclude(
        self, d2: FloatArray, bad: npt.NDArray[np.bool_], d: FloatArray, pb: FloatArray, used: set[int]
    ) -> FloatArray:
        """``d2`` with inf where a landmark is no candidate: ``bad``, already ``used``, or (when pruning) predicted
        at a range ``d`` or bearing ``pb`` outside the sensor limits."""
        if self._limits.shape[0] == 3:
            lo, hi, half = self._limits.tolist()
            bad |= (d < lo) | (d > hi) | (np.abs(pb) > half)
        if used:
            bad[list(used)] = True
        d2[bad] = np.inf
        return d2

    def _correct_range(self, r: float, row: int) -> float | None:
        """Fuse one range to beacon ``row`` through the unscented transform; its NIS, or None if gated out."""
        R = np.array([[self._range_sigma * self._range_sigma]])
        bx, by = self._lm_list[row]

        def h_all(sigmas: FloatArray) -> FloatArray:
            return np.array([[math.hypot(bx - sx, by - sy)] for sx, sy, _ in sigmas.tolist()])

        return self._correct(np.array([r]), R, h_all, None, subtract, -1, self._range_gate)

    def _update_pose_fix(self, z: PoseFix) -> None:
        """GPS-like fix (report 001): h(x) = (x, y) or (x, y, theta) with the fix's covariance, heading wrapped."""
        m = int(z.z.shape[0])
        if m not in (2, 3) or z.cov.shape != (m, m):
            raise ValueError(f"PoseFix at t={z.t} must have z (2,) or (3,) and a matching cov, got {z.cov.shape}")
        R = 0.5 * (z.cov + z.cov.T)
        residual = _residual_heading if m == 3 else subtract

        def h_all(sigmas: FloatArray) -> FloatArray:
            return sigmas[:, :m].copy()

        nis = self._correct(
            np.asarray(z.z, dtype=np.float64), R, h_all, _fix_mean, residual, 2 if m == 3 else -1, math.inf
        )
        assert nis is not None  # no gate on fixes
        self._nis, self._nis_dof, self._accepted, self._rejected = nis, m, 1, 0

    # --- output -----------------------------------------------------------------------------------------------

    def _check_finite(self, t: float) -> None:
        ukf = self._ukf
        if ukf is None:
            return  # called by the EKF's reset before the UKF exists; checked again at the end of reset
        self._sync()
        if not all(map(math.isfinite, self._kb[0:12].tolist())):  # np.isfinite's verdict, without its calls
            raise FilterDiverged(f"LandmarkUKF state became non-finite at t={t:.3f} s")

    def estimate(self) -> Estimate:
        """The current mean (3,), covariance (3, 3) and the diagnostics of the last call."""
        return Estimate(t=self._t, mean=self._ukf.x.copy(), cov=self._ukf.P.copy(), diagnostics=self._diagnostics())


def _gain(
    x: FloatArray, P: FloatArray, y: FloatArray, S: FloatArray, Pxz: FloatArray
) -> tuple[FloatArray, FloatArray, float]:
    """(x+, P+, NIS) of :func:`~locbench.filters._kalman.gain_update`: its numpy operations, without the
    log-likelihood and the record the UKF does not read."""
    Sinv = np.linalg.inv(S)
    K = Pxz @ Sinv
    P_new = P - K @ S @ K.T
    nis = float(y @ Sinv @ y)
    return x + K @ y, 0.5 * (P_new + P_new.T), nis


def _weighted_sum(w: FloatArray, a: FloatArray) -> FloatArray:
    """sum_i w_i a[i, :] for (n, L) ``a``, one landmark (column) at a time in the order of i: each column's sum
    is the same number whatever the other columns (a BLAS product's rounding depends on where a column falls)."""
    out = w[0] * a[0]
    for i in range(1, a.shape[0]):
        out = out + w[i] * a[i]
    return out


def _move_midpoint(s: FloatArray, dt: float, dd: float, dth: float) -> tuple[float, float, float]:
    """One sigma point moved along the chord at the midpoint heading (report 003 eq. 5; heading not wrapped)."""
    x, y, th = s.tolist()
    h = th + 0.5 * dth
    return (x + dd * math.cos(h), y + dd * math.sin(h), th + dth)


def _move_increment(s: FloatArray, dt: float, dx: float, dy: float, dth: float) -> tuple[float, float, float]:
    """One sigma point with the odometry increment (robot frame) composed on it (heading not wrapped)."""
    x, y, th = s.tolist()
    c, sn = math.cos(th), math.sin(th)
    return (x + c * dx - sn * dy, y + sn * dx + c * dy, th + dth)


def _range_bearing_points(sigmas: FloatArray, lx: float, ly: float) -> FloatArray:
    """(range, bearing) of the landmark at (lx, ly) from every pose of ``sigmas`` (n, 3), shape (n, 2)."""
    dx = lx - sigmas[:, 0]
    dy = ly - sigmas[:, 1]
    out = np.empty((sigmas.shape[0], 2))
    out[:, 0] = np.hypot(dx, dy)
    out[:, 1] = wrap_angle(np.arctan2(dy, dx) - sigmas[:, 2])
    return out
