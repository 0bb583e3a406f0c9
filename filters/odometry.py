"""Dead reckoning: the baseline row of every table (all reports).

The mean is the composition of the robot's own odometry increments, exactly as reported (no motion
model of its own), so the row shows the odometry the other filters start from. A covariance is
propagated beside it with the dataset's nominal noise, so that NEES and the consistency metrics are
meaningful for this row too: the wheel-encoder input noise of report 003 eq. 10 when the events carry
wheel travel and the dataset gives the encoder constants, else the per-step increment noise
(``SensorSpec.odometry_sigma_*``); see :mod:`locbench.filters._motion`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from locbench.core.errors import FilterDiverged
from locbench.core.events import Observation, Odometry
from locbench.core.geometry import wrap_scalar
from locbench.datasets.dataset import Gaussian2, SensorSpec, WorldMap
from locbench.filters._motion import InputNoise, MotionKind, MotionModel, propagate_covariance, resolve_motion_noise
from locbench.filters.base import Estimate, Filter, FilterConfig, FilterDoc


@dataclass(frozen=True, kw_only=True)
class OdometryConfig(FilterConfig):
    """Configuration of :class:`OdometryFilter`; it changes the covariance only, never the mean.

    Attributes
    ----------
    noise_model : {"auto", "encoder", "increment"}
        Which nominal noise propagates the covariance. ``"auto"``: the encoder input noise (report 003
        eq. 10) when an event has wheel travel and the dataset gives the wheelbase and encoder constants,
        else the increment noise; ``"encoder"``/``"increment"`` force one (``"encoder"`` still falls back
        per event when wheel travel or the wheelbase is missing).
    input_noise : {"per_step", "cumulative"}
        Reading of report 003 eq. 10 (see :mod:`locbench.filters._motion`).
    """

    noise_model: MotionKind = "auto"
    input_noise: InputNoise = "per_step"


class OdometryFilter(Filter):
    """Compose the odometry increments; propagate the nominal odometry covariance.

    Notes
    -----
    x_k = x_{k-1} (+) (dx, dy, dtheta)_k and P_k = F P_{k-1} F^T + N_k, with F the Jacobian of the
    composition w.r.t. the pose and N_k the world-frame motion noise of the step.
    """

    id: ClassVar[str] = "odometry"
    order: ClassVar[int] = 0
    description: ClassVar[str] = "dead reckoning from odometry increments; the baseline row of every table"
    doc: ClassVar[FilterDoc | None] = FilterDoc(
        "all reports",
        "composes the robot's odometry increments exactly",
        "none",
        "the baseline every table starts with",
    )
    consumes: ClassVar[frozenset[type]] = frozenset({Odometry})
    Config: ClassVar[type[FilterConfig]] = OdometryConfig
    version: ClassVar[int] = 1
    cost_per_data_s: ClassVar[float] = 0.002
    baseline: ClassVar[bool] = True
    source: ClassVar[str] = "all reports (odometry baseline); noise model of 003_e5c93f9be776ee5e eq. 10"

    config: OdometryConfig

    def reset(self, initial: Gaussian2, world: WorldMap, sensors: SensorSpec, rng: np.random.Generator) -> None:
        """Start from ``initial``; ``world`` and ``rng`` are unused (dead reckoning is deterministic)."""
        cfg = self.config
        noise = resolve_motion_noise(sensors, input_noise=cfg.input_noise)
        self._model = MotionModel(noise, cfg.noise_model, mean="compose")
        m = np.asarray(initial.mean, dtype=np.float64)
        self._x: tuple[float, float, float] = (float(m[0]), float(m[1]), wrap_scalar(float(m[2])))
        c = np.asarray(initial.cov, dtype=np.float64)
        self._P: list[list[float]] = (0.5 * (c + c.T)).tolist()
        self._t = math.nan
        self._travelled = 0.0

    def predict(self, u: Odometry) -> None:
        """Compose the increment of ``u`` (previous robot frame) onto the pose; grow the covariance."""
        step = self._model.step(self._x, u)
        self._x = step.pose
        self._P = propagate_covariance(self._P, step.f02, step.f12, step.noise)
        self._t = u.t
        self._travelled += math.hypot(u.dx, u.dy)
        if not (math.isfinite(self._x[0]) and math.isfinite(self._x[1]) and math.isfinite(self._x[2])):
            raise FilterDiverged(f"odometry pose became non-finite at t={u.t:.3f} s; check the odometry events")

    def update(self, z: Observation) -> None:
        """Dead reckoning takes no observation: always ``TypeError``."""
        self.check_consumes(z)

    def event_health(self) -> dict[str, float]:
        """The path length ``distance_m``, beside the default :meth:`health`'s covariance growth (no NIS)."""
        return {"distance_m": self._travelled}

    def estimate(self) -> Estimate:
        """The composed pose and its covariance; diagnostics ``distance_m`` (odometry path length so far)."""
        return Estimate(
            t=self._t,
            mean=np.array(self._x),
            cov=np.array(self._P),
            diagnostics={"distance_m": self._travelled},
        )
