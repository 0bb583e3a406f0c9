"""Unscented Kalman filter with the landmark EKF's models: the filter users compare an EKF against.

The state, the motion model, the measurement models and the association are those of
:mod:`locbench.filters.ekf_landmarks` (reports 003 and 001); only the way the Gaussian is carried through the
nonlinear functions differs: the scaled unscented transform (van der Merwe 2004; Julier 2002),

    sigma points  chi_0 = x,  chi_i = x +- (sqrt((n + lambda) P))_i,   lambda = alpha^2 (n + kappa) - n,
    weights       Wm_0 = lambda / (n + lambda),  Wc_0 = Wm_0 + 1 - alpha^2 + beta,  Wm_i = Wc_i = 1 / (2 (n + lambda)),

the square root the upper Cholesky factor. Defaults alpha = 1, beta = 2, kappa = 0 (n = 3): kappa = 3 - n is
Julier's rule for a Gaussian prior, and alpha = 1 keeps the points at sqrt(3) standard deviations, so that they
sample the nonlinearity over the belief's own extent (a tiny alpha, robot_localization's 0.001, makes the
transform a numerical linearisation with weights near -1e6).

Prediction: each sigma point is moved by the EKF's mean motion (the midpoint chord of report 003 eq. 5 when the
encoder model applies, else the composed increment), and the motion noise G U G^T + Q that the EKF adds
(:class:`~locbench.filters._motion.MotionModel`, evaluated at the mean) is added to the transformed covariance
(additive-noise UKF).

Headings are angles: the mean of sigma points takes the circular mean of their headings,
atan2(sum Wm sin theta, sum Wm cos theta), and every state residual wraps its heading to (-pi, pi]; the
predicted bearing of a landmark is averaged and wrapped the same way, and the bearing innovation is wrapped.

Correction: the sightings of one event are fused one at a time, known identities first, then nearest
neighbours, in the EKF's order (:func:`~locbench.filters._ekf_kernels.sighting_rows`); the sigma points are
redrawn from the current (x, P) before each measurement, so each one sees the state corrected by the previous.
The nearest-neighbour gate uses the unscented predicted measurement and S = sum Wc (z_i - z)(z_i - z)^T + R of
each candidate landmark. Range-only beacons and pose fixes use the same gates as the EKF (1 dof, and none for
fixes). A gated-out measurement leaves the state unchanged. The gain step is the Kalman core's sigma-point form
(:func:`~locbench.filters._kalman.gain_update`: K = P_xz S^-1, P - K S K^T, symmetrised).

Where each equation is implemented: the sigma points, the prediction and the range-bearing sightings' transform
(the sums of the correction and the nearest-neighbour distances) are compiled, :mod:`locbench.filters._ukf_kernels`;
beacon ranges and pose fixes, rare, take the sigma points from there and form their transform in numpy
(:meth:`LandmarkUKF._correct`); every gain step is numpy's (``inv`` and the BLAS products).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import ClassVar, NoReturn

import numpy as np
import numpy.typing as npt

from locbench.core.errors import ConfigError, FilterDiverged
from locbench.core.events import LandmarkObservations, Odometry, PoseFix
from locbench.core.geometry import wrap_angle, wrap_scalar
from locbench.datasets.dataset import Gaussian2, SensorSpec, WorldMap
from locbench.filters import _ekf_kernels as ekf_kern
from locbench.filters import _ukf_kernels as kern
from locbench.filters._kalman import Residual, gain_update, subtract, wrapped_residual
from locbench.filters._landmark_index import INDEX_MIN_LANDMARKS, NEAR_M
from locbench.filters._motion import wheel_increment
from locbench.filters.base import NON_NEGATIVE, FilterConfig, FilterDoc, bound
from locbench.filters.ekf_landmarks import LandmarkEKF, LandmarkEKFConfig

FloatArray = npt.NDArray[np.float64]
#: The residual of a pose with its heading wrapped (a pose fix with a heading).
_RESIDUAL_HEADING = wrapped_residual([2])


def _moments(
    sigmas: FloatArray, Wc: FloatArray, mean: FloatArray, noise_cov: FloatArray | None, angle: int
) -> FloatArray:
    """sum_k Wc_k r_k r_k^T (+ noise) with r_k = sigmas_k - mean, component ``angle`` wrapped (none if -1)."""
    r = sigmas - mean
    if angle >= 0:
        r[:, angle] = wrap_angle(r[:, angle])
    return _weighted_outer_sum(Wc, r, r, noise_cov)


def _weighted_outer_sum(Wc: FloatArray, a: FloatArray, b: FloatArray, start: FloatArray | None) -> FloatArray:
    """sum_k Wc_k a_k b_k^T over the rows k of ``a`` (n, p) and ``b`` (n, q), plus ``start`` (p, q) if given."""
    out: FloatArray = (Wc[:, None, None] * (a[:, :, None] * b[:, None, :])).sum(axis=0)
    if start is not None:
        out += start
    return out


def circular_mean(angles: FloatArray, weights: FloatArray) -> float:
    """Weighted circular mean atan2(sum w sin a, sum w cos a) of angles (rad), in (-pi, pi]."""
    return wrap_scalar(math.atan2(float(weights @ np.sin(angles)), float(weights @ np.cos(angles))))


def _fix_mean(sigmas: FloatArray, weights: FloatArray) -> FloatArray:
    """Weighted mean of predicted pose fixes (n, 2) or (n, 3): arithmetic in x and y, circular in the heading."""
    if sigmas.shape[1] == 3:
        return np.array([weights @ sigmas[:, 0], weights @ sigmas[:, 1], circular_mean(sigmas[:, 2], weights)])
    return np.asarray(weights @ sigmas, dtype=np.float64)


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
    sightings are associated and fused; it replaces the prediction and every correction (module docstring). Its
    state is the 12 floats of the compiled kernels' buffer (mean, covariance row-major), ``_s`` as the EKF's.
    Diagnostics as the EKF's.
    """

    id: ClassVar[str] = "ukf_landmarks"
    order: ClassVar[int] = 20
    description: ClassVar[str] = (
        "unscented KF (Merwe scaled sigma points) with ekf_landmarks' motion, landmark, range and fix models"
    )
    doc: ClassVar[FilterDoc | None] = FilterDoc(
        "Julier & Uhlmann, van der Merwe; models of 003, 001",
        "`ekf_landmarks`' motion model through Merwe scaled sigma points (compiled kernels), circular heading mean",
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
    _index_min_landmarks: ClassVar[int] = INDEX_MIN_LANDMARKS

    def reset(self, initial: Gaussian2, world: WorldMap, sensors: SensorSpec, rng: np.random.Generator) -> None:
        """Start from ``initial`` with the landmarks of ``world``; ``rng`` is unused (the UKF is deterministic)."""
        super().reset(initial, world, sensors, rng)  # the EKF's models, map and buffers; the initial state in _s
        cfg = self.config
        wm, wc, scale = kern.sigma_weights(cfg.alpha, cfg.beta, cfg.kappa)
        self._kb = kern.weights_buffer(wm, wc, scale)
        self._kb[0:12] = self._s
        self._s = self._kb[0:12]  # the state: a view of the kernels' buffer
        self._kx, self._kP = self._kb[0:3], self._kb[3:12].reshape(3, 3)  # its mean and covariance, views
        self._wm, self._wc = wm, wc
        # the k-d tree's bound (_gate_radius) needs non-negative weights (alpha = 1, beta = 2, kappa = 0 has them)
        self._weights_nonnegative = bool(np.all(wm >= 0.0) and np.all(wc >= 0.0))
        self._wc_sum = float(np.sum(wc))
        self._check_finite(math.nan)

    # --- predict ---------------------------------------------------------------------------------------------

    def predict(self, u: Odometry) -> None:
        """Move every sigma point with the mean motion; add the EKF's motion noise (module docstring).

        One compiled call (:func:`._ukf_kernels.predict`); it raises when the kernel cannot complete.
        """
        kb = self._kb
        step = self._motion.step(self._kx.tolist(), u)  # noise and model at the mean (and the travel count)
        n00, n01, n02, n11, n12, n22 = step.noise
        q0, q1, q2 = self._q
        kb[kern.B_Q : kern.B_Q + 9] = [n00 + q0, n01, n02, n01, n11 + q1, n12, n02, n12, n22 + q2]
        if step.encoder:
            W = self._motion.noise.wheelbase_m
            assert W is not None and u.d_left is not None and u.d_right is not None  # guaranteed by step.encoder
            dd, dth = wheel_increment(u.d_left, u.d_right, W)  # eq. 1-2
            code = kern.predict(kb, True, dd, dth, 0.0)
        else:
            code = kern.predict(kb, False, u.dx, u.dy, u.dtheta)
        if code == 2 or code == 3:
            raise FilterDiverged(f"LandmarkUKF state became non-finite at t={u.t:.3f} s")
        if code != 0:
            self._not_positive_definite(u.t)
        self._t = u.t
        self._nis, self._nis_dof, self._accepted, self._rejected = math.nan, 0, 0, 0
        self._check_finite(u.t)

    # --- corrections ------------------------------------------------------------------------------------------

    def _not_positive_definite(self, t: float) -> NoReturn:
        """Raise: P (or the predicted P) has no Cholesky factor, so no sigma points can be drawn."""
        raise np.linalg.LinAlgError(f"LandmarkUKF: the covariance is not positive definite at t={t:.3f} s")

    def _sigma_points(self, t: float) -> FloatArray:
        """The sigma points (7, 3) of the current state, a view of the kernels' buffer; raises if P has no
        Cholesky factor."""
        if kern.sigma_points(self._kb) != 0:
            self._not_positive_definite(t)
        return self._kb[kern.B_SIG : kern.B_SIG + 21].reshape(7, 3)

    def _finish(self, x: FloatArray, P: FloatArray) -> None:
        """Take (x, P) as the state: heading wrapped, P symmetrised."""
        x[2] = wrap_scalar(float(x[2]))
        self._kx[:] = x
        self._kP[:] = 0.5 * (P + P.T)

    def _update_landmarks(self, z: LandmarkObservations) -> None:
        """Fuse the sightings in the EKF's order: known identities first, then nearest neighbour among the
        landmarks not used yet (:func:`._ekf_kernels.sighting_rows`, :meth:`_fuse`)."""
        if self._lm_warn:
            self._warn_landmark_noise()
        rows = self._rows(len(z.ranges))
        used, known = self._used, self.config.association == "known"
        ekf_kern.sighting_rows(z.ids, z.ranges, z.bearings, self._map_ids, self._map_rows, known, rows)
        used.fill(0)
        codes = rows.tolist()
        nis, acc, rej = self._fuse(z.ranges, z.bearings, codes, used, associate=False)
        if ekf_kern.NOT_IN_MAP in codes:
            self._log_unmapped(z)
        if ekf_kern.ASSOCIATE in codes:
            d_nis, d_acc, d_rej = self._fuse(z.ranges, z.bearings, codes, used, associate=True)
            nis, acc, rej = nis + d_nis, acc + d_acc, rej + d_rej
        self._nis = nis if acc else math.nan
        self._nis_dof, self._accepted, self._rejected = 2 * acc, acc, rej
        self._check_finite(z.t)

    def _correct(
        self,
        z: FloatArray,
        R: FloatArray,
        h_all: Callable[[FloatArray], FloatArray],
        z_mean: Callable[[FloatArray, FloatArray], FloatArray] | None,
        residual: Residual,
        angle: int,
        gate: float,
    ) -> float | None:
        """One unscented correction of a beacon range or a pose fix in numpy; its NIS, or None (state unchanged)
        when outside ``gate``.

        The sigma points are drawn at the state the previous measurement left, ``h_all`` maps all of them at once
        to measurements (n_sigma, m), their weighted mean is ``z_mean`` (the plain weighted sum if None); S (R
        included) and P_xz are the weighted sums of outer products of the residuals, their component ``angle``
        wrapped (-1: none); the gain step is :func:`~locbench.filters._kalman.gain_update`, which also gives the
        NIS for the gate. ``residual`` forms the innovation.
        """
        sigmas = self._sigma_points(self._t).copy()
        x, P = self._kx, self._kP
        Wm, Wc = self._wm, self._wc
        sigmas_h = h_all(sigmas)
        zp = np.dot(Wm, sigmas_h) if z_mean is None else z_mean(sigmas_h, Wm)
        S = _moments(sigmas_h, Wc, zp, R, angle)
        dx = sigmas - x
        dx[:, 2] = wrap_angle(dx[:, 2])
        dz = sigmas_h - zp
        if angle >= 0:
            dz[:, angle] = wrap_angle(dz[:, angle])
        c = gain_update(x, P, residual(z, zp), S, _weighted_outer_sum(Wc, dx, dz, None))
        if not c.nis <= gate:
            return None
        self._finish(c.x, c.P)
        return c.nis

    def _correct_landmark(self, r: float, b: float, row: int, gate: float) -> float | None:
        """Fuse one (range, bearing) of landmark ``row``: the compiled sums (:func:`._ukf_kernels.landmark_sums`)
        and the gain step; its NIS, or None if gated out."""
        lx, ly = self._lm_list[row]
        x = self._kx
        if math.hypot(lx - float(x[0]), ly - float(x[1])) < 1e-6:
            return None  # on top of the landmark: the bearing is undefined
        kb = self._kb
        if kern.landmark_sums(kb, r, b, lx, ly, self._rr, self._rb) != 0:
            self._not_positive_definite(self._t)
        o = kb[kern.B_S : kern.B_SIGH]
        c = gain_update(x, self._kP, o[10:12], o[0:4].reshape(2, 2), o[4:10].reshape(3, 2))
        if not c.nis <= gate:
            return None
        self._finish(c.x, c.P)
        return c.nis

    def _nearest_row(self, r: float, b: float, used: npt.NDArray[np.int64]) -> int:
        """Row of the landmark nearest to (r, b) in the unscented Mahalanobis distance, inside the gate, among those
        not ``used`` (marks); -1 for none (:func:`._ukf_kernels.nearest_row`).

        A large map with non-negative weights tests only the landmarks of the k-d tree within :meth:`_gate_radius`,
        in row order; every landmark's d2 is the same number either way, so the first smallest is the same row.
        """
        sig = self._sigma_points(self._t)
        rows = self._all_rows
        if self._index is not None and self._weights_nonnegative:
            radius = self._gate_radius(r, sig)
            if radius is not None:
                cand = self._index.candidates(sig[0].tolist(), r, b, radius[0], radius[1])
                if not cand:
                    return -1
                rows = np.array(cand, dtype=np.int64)
        lims = self._limits
        return int(kern.nearest_row(self._kb, r, b, self._lm_xy, rows, used, lims, self._rr, self._rb, self._gate))

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
        residual = _RESIDUAL_HEADING if m == 3 else subtract

        def h_all(sigmas: FloatArray) -> FloatArray:
            return sigmas[:, :m].copy()

        nis = self._correct(
            np.asarray(z.z, dtype=np.float64), R, h_all, _fix_mean, residual, 2 if m == 3 else -1, math.inf
        )
        assert nis is not None  # no gate on fixes
        self._nis, self._nis_dof, self._accepted, self._rejected = nis, m, 1, 0

    # --- output -----------------------------------------------------------------------------------------------

    def _check_finite(self, t: float) -> None:
        if not all(map(math.isfinite, self._s.tolist())):  # np.isfinite's verdict, without its calls
            raise FilterDiverged(f"LandmarkUKF state became non-finite at t={t:.3f} s")
