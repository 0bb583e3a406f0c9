"""An iterated extended Kalman filter on range-bearing landmarks: a locbench filter written as a plugin.

It imports locbench's public filter API only: the types from :mod:`locbench.filters.api`, the shared motion
model from :mod:`locbench.filters.motion` and the nominal noise from :mod:`locbench.filters.noise`.

Prediction: the shared motion model (the wheel-encoder model of locbench's report 003 when the events carry
wheel travel and the dataset gives the encoder constants, else the odometry increment with a noise growing
with the distance travelled), plus an additive process noise Q per step.

Update (Bell and Cathey 1993, "The iterated Kalman filter update as a Gauss-Newton method", IEEE Trans.
Automatic Control 38(2), eq. 5): all sightings of one event are stacked into z (2n,) with R = diag(sigma_r^2,
sigma_b^2, ...), and the update iterates, from x_0 = x- (the prior mean),

    K_i = P- H_i^T (H_i P- H_i^T + R)^-1,    x_{i+1} = x- + K_i (z - h(x_i) - H_i (x- - x_i)),

with H_i = dh/dx at x_i, until no component of x_{i+1} - x_i exceeds ``step_tolerance`` or after
``max_iterations``; then P+ = (I - K H) P- (I - K H)^T + K R K^T (Joseph form) at the last linearisation. One
iteration is the EKF update. Bearing residuals and heading differences are wrapped to (-pi, pi]. A sighting
whose id is unknown or not on the map is rejected (counted in the diagnostics).

Frames and units: pose (x m, y m, theta rad) in the world frame; range m, bearing rad in the robot frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from locbench.filters.api import (
    NON_NEGATIVE,
    POSITIVE_OR_DATASET,
    UNKNOWN_ID,
    ConfigError,
    Estimate,
    Filter,
    FilterConfig,
    FilterDiverged,
    FloatArray,
    Gaussian2,
    LandmarkObservations,
    MapKind,
    Observation,
    Odometry,
    SensorSpec,
    WorldMap,
    bound,
    field_unit,
    tunable,
    wrap_angle,
    wrap_scalar,
)
from locbench.filters.motion import MotionKind, MotionModel, propagate_covariance, resolve_motion_noise
from locbench.filters.noise import landmark_noise, process_noise

#: A standard deviation that is >= 0, or None for the dataset's nominal value (checked by the config base).
_SIGMA = bound(0.0, optional=True)


@dataclass(frozen=True, kw_only=True)
class IteratedLandmarkEKFConfig(FilterConfig):
    """Configuration of :class:`IteratedLandmarkEKF`.

    Attributes
    ----------
    max_iterations : int
        Most Gauss-Newton iterations of one update (1: the EKF update).
    step_tolerance : float
        The iterations stop when no component of the step exceeds it (m for x and y, rad for theta).
    motion_model : {"auto", "encoder", "increment"}
        Which motion model predicts (see :class:`locbench.filters.motion.MotionModel`).
    sigma_xy_per_m, sigma_theta_per_m, sigma_theta_per_rad : float or None
        The increment motion noise: position and heading standard deviation per square root of the distance
        travelled, heading per square root of the angle turned; None takes the dataset's nominal value.
    sigma_x_m, sigma_y_m, sigma_theta_rad : float or None
        Additive process noise Q per odometry step; None takes the dataset's value, else a small default.
    sigma_range_m, sigma_bearing_rad : float or None
        Measurement noise R of one sighting; None takes the dataset's nominal value.
    """

    max_iterations: int = field(default=10, metadata=tunable(1, 30, integer=True, base=bound(1)))
    step_tolerance: float = field(default=1e-9, metadata=field_unit("m or rad", base=NON_NEGATIVE))
    motion_model: MotionKind = "auto"
    # the names say what these are but not their unit (the suffix rule would read "_per_m" as 1/m): declared
    sigma_xy_per_m: float | None = field(default=None, metadata=field_unit("m/sqrt(m)", base=_SIGMA))
    sigma_theta_per_m: float | None = field(default=None, metadata=field_unit("rad/sqrt(m)", base=_SIGMA))
    sigma_theta_per_rad: float | None = field(default=None, metadata=field_unit("rad/sqrt(rad)", base=_SIGMA))
    sigma_x_m: float | None = field(default=None, metadata=_SIGMA)
    sigma_y_m: float | None = field(default=None, metadata=_SIGMA)
    sigma_theta_rad: float | None = field(default=None, metadata=_SIGMA)
    sigma_range_m: float | None = field(default=None, metadata=tunable(1e-3, 1.0, log=True, base=POSITIVE_OR_DATASET))
    sigma_bearing_rad: float | None = field(
        default=None, metadata=tunable(1e-3, 0.5, log=True, base=POSITIVE_OR_DATASET)
    )


def range_bearing(pose: FloatArray, xy: FloatArray) -> tuple[FloatArray, FloatArray]:
    """h(x) of landmarks ``xy`` (n, 2) seen from ``pose`` (3,): (range m, bearing rad) rows (2n,) and
    H = dh/dx (2n, 3)."""
    dx, dy = xy[:, 0] - pose[0], xy[:, 1] - pose[1]
    q = np.maximum(dx * dx + dy * dy, 1e-12)  # a landmark on the robot: no bearing, no blow-up
    d = np.sqrt(q)
    h = np.empty(2 * xy.shape[0])
    h[0::2], h[1::2] = d, wrap_angle(np.arctan2(dy, dx) - pose[2])
    H = np.zeros((2 * xy.shape[0], 3))
    H[0::2, 0], H[0::2, 1] = -dx / d, -dy / d
    H[1::2, 0], H[1::2, 1], H[1::2, 2] = dy / q, -dx / q, -1.0
    return h, H


def _wrapped_rows(v: FloatArray) -> FloatArray:
    """``v`` (2n,) with its bearing rows (odd) wrapped to (-pi, pi]."""
    out = v.copy()
    out[1::2] = wrap_angle(out[1::2])
    return out


class IteratedLandmarkEKF(Filter):
    """Iterated EKF on (x, y, theta) with range-bearing sightings of known landmarks (module docstring).

    Diagnostics of :meth:`estimate`: ``nis`` (the stacked innovation at the prior, y^T S^-1 y; NaN after a
    predict or when nothing was accepted), ``nis_dof`` (its dimension), ``accepted`` and ``rejected`` sightings
    and ``iterations`` of the last update.
    """

    consumes: ClassVar[frozenset[type]] = frozenset({Odometry, LandmarkObservations})
    requires: ClassVar[frozenset[MapKind]] = frozenset({MapKind.LANDMARKS})
    Config: ClassVar[type[FilterConfig]] = IteratedLandmarkEKFConfig
    version: ClassVar[int] = 1
    description: ClassVar[str] = "iterated EKF (Gauss-Newton update) on range-bearing landmarks; an example plugin"
    source: ClassVar[str] = "Bell and Cathey 1993, IEEE Trans. Automatic Control 38(2) (the iterated update)"
    cost_per_data_s: ClassVar[float] = 0.03

    config: IteratedLandmarkEKFConfig

    def reset(self, initial: Gaussian2, world: WorldMap, sensors: SensorSpec, rng: np.random.Generator) -> None:
        """Start from ``initial`` with the landmarks of ``world``; ``rng`` is unused (the filter is deterministic)."""
        cfg = self.config
        if world.landmarks is None or len(world.landmarks) == 0:
            raise ConfigError("IteratedLandmarkEKF needs world.landmarks; the dataset provides none")
        noise = resolve_motion_noise(
            sensors,
            odometry_sigma_xy_per_m=cfg.sigma_xy_per_m,
            odometry_sigma_theta_per_m=cfg.sigma_theta_per_m,
            odometry_sigma_theta_per_rad=cfg.sigma_theta_per_rad,
        )
        self._motion = MotionModel(noise, cfg.motion_model, mean="model")
        sx, sy, sth = process_noise(cfg.sigma_x_m, cfg.sigma_y_m, cfg.sigma_theta_rad, sensors)
        self._q = (sx * sx, 0.0, 0.0, sy * sy, 0.0, sth * sth)
        sr, sb = landmark_noise(cfg.sigma_range_m, cfg.sigma_bearing_rad, sensors)
        self._r = np.array([sr * sr, sb * sb])
        self._xy = np.asarray(world.landmarks.xy, dtype=np.float64).reshape(-1, 2)
        self._row = world.landmarks.index_of()
        m = np.asarray(initial.mean, dtype=np.float64)
        self._x = np.array([m[0], m[1], wrap_scalar(float(m[2]))])
        c = np.asarray(initial.cov, dtype=np.float64)
        self._P = 0.5 * (c + c.T)
        self._t = math.nan
        self._last: dict[str, float] = {}

    def predict(self, u: Odometry) -> None:
        """Move the mean with the shared motion model; P = F P F^T + G U G^T + Q."""
        step = self._motion.step((float(self._x[0]), float(self._x[1]), float(self._x[2])), u)
        P = propagate_covariance(self._P.tolist(), step.f02, step.f12, step.noise)
        q = self._q
        self._x = np.array(step.pose)
        self._P = np.array(P) + np.array([[q[0], q[1], q[2]], [q[1], q[3], q[4]], [q[2], q[4], q[5]]])
        self._t = u.t
        self._last = {}
        self._check_finite()

    def update(self, z: Observation) -> None:
        """The iterated update with every sighting of ``z`` whose landmark is on the map."""
        self.check_consumes(z)
        assert isinstance(z, LandmarkObservations)
        self._t = z.t
        rows = [self._row.get(int(i), -1) if int(i) != UNKNOWN_ID else -1 for i in z.ids]
        keep = np.array([r >= 0 for r in rows], dtype=bool)
        n = int(keep.sum())
        self._last = {"accepted": float(n), "rejected": float(len(rows) - n), "iterations": 0.0}
        if n == 0:
            return
        xy = self._xy[[r for r in rows if r >= 0]]
        zz = np.empty(2 * n)
        zz[0::2], zz[1::2] = z.ranges[keep], z.bearings[keep]
        R = np.diag(np.tile(self._r, n))
        x0, P = self._x, self._P
        xi = x0.copy()
        nis = math.nan
        for it in range(1, self.config.max_iterations + 1):
            h, H = range_bearing(xi, xy)
            S = H @ P @ H.T + R
            K = np.linalg.solve(S, H @ P).T  # P H^T S^-1 (S and P symmetric)
            y = _wrapped_rows(zz - h)
            if it == 1:
                nis = float(y @ np.linalg.solve(S, y))
            dx = x0 - xi
            dx[2] = wrap_scalar(float(dx[2]))
            x_new = x0 + K @ (y - H @ dx)
            x_new[2] = wrap_scalar(float(x_new[2]))
            step = x_new - xi
            step[2] = wrap_scalar(float(step[2]))
            xi = x_new
            if float(np.max(np.abs(step))) <= self.config.step_tolerance:
                break
        A = np.eye(3) - K @ H
        self._x = xi
        self._P = A @ P @ A.T + K @ R @ K.T
        self._P = 0.5 * (self._P + self._P.T)
        self._last |= {"nis": nis, "nis_dof": float(2 * n), "iterations": float(it)}
        self._check_finite()

    def estimate(self) -> Estimate:
        """The current mean (3,), covariance (3, 3) and the diagnostics of the last call."""
        diag = {"nis": math.nan, "nis_dof": 0.0, "accepted": 0.0, "rejected": 0.0, "iterations": 0.0} | self._last
        return Estimate(t=self._t, mean=self._x.copy(), cov=self._P.copy(), diagnostics=diag)

    def _check_finite(self) -> None:
        if not (np.all(np.isfinite(self._x)) and np.all(np.isfinite(self._P))):
            raise FilterDiverged(f"IteratedLandmarkEKF's belief became non-finite at t={self._t:.3f} s")
