"""The shared motion models, public: what the built-in filters predict with, for a plugin filter to reuse.

The wheel-encoder model of report 003 (eq. 1-5, 10), the odometry-increment model and the twist noise of
recorded odometry, their Jacobians, covariances and samplers, and :class:`MotionModel`, which picks one of
them per :class:`~locbench.core.events.Odometry` event. The models, their equations, frames and units are
documented in the implementation modules (``locbench.filters._motion``; the compiled per-particle steps that
the samplers and the particle filter move a cloud with, ``locbench.filters._motion_kernels``); this module is
the stable name a plugin imports: ``from locbench.filters.motion import MotionModel``.

A config that mixes in :class:`MotionNoiseConfig` gets the motion-noise fields every built-in filter has
(``input_noise``, ``wheelbase_m``, ``encoder_k_left`` ... ``motion_noise_scale``) and their resolution against
the dataset's nominal noise (:meth:`MotionNoiseConfig.motion_noise`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from locbench.filters._motion import (
    DEFAULT_ENCODER_K,
    DEFAULT_SIGMA_THETA_PER_M,
    DEFAULT_SIGMA_THETA_PER_RAD,
    DEFAULT_SIGMA_XY_PER_M,
    InputNoise,
    MotionKind,
    MotionModel,
    MotionNoise,
    MotionNoiseConfig,
    Step,
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

if TYPE_CHECKING:
    from locbench.filters._motion_kernels import (
        sample_increment_motion,
        sample_twist_motion,
        sample_wheel_motion,
        twist_increment,
    )

__all__ = [
    "DEFAULT_ENCODER_K",
    "DEFAULT_SIGMA_THETA_PER_M",
    "DEFAULT_SIGMA_THETA_PER_RAD",
    "DEFAULT_SIGMA_XY_PER_M",
    "InputNoise",
    "MotionKind",
    "MotionModel",
    "MotionNoise",
    "MotionNoiseConfig",
    "Step",
    "increment_covariance",
    "increment_jacobians",
    "increment_variances",
    "input_covariance",
    "jacobian_state",
    "jacobian_wheels",
    "predict_arc",
    "predict_midpoint",
    "propagate_covariance",
    "resolve_motion_noise",
    "sample_increment_motion",
    "sample_twist_motion",
    "sample_wheel_motion",
    "twist_increment",
    "twist_increment_covariance",
    "twist_jacobian",
    "wheel_to_motion",
    "wheel_variances",
]

#: The names this module takes from the compiled kernels' module, loaded on first use: importing the plugin API
#: loads no numba (the samplers and the arc run compiled, so they need it).
_COMPILED = frozenset({"sample_increment_motion", "sample_twist_motion", "sample_wheel_motion", "twist_increment"})


def __getattr__(name: str) -> Any:
    """The compiled samplers and arc (:mod:`locbench.filters._motion_kernels`), imported when first asked for."""
    if name in _COMPILED:
        from locbench.filters import _motion_kernels

        return getattr(_motion_kernels, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
