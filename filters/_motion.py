"""Wheel-encoder motion model of report 003 and the odometry-increment fallback, shared by the filters.

Two ways to move a pose with one :class:`~locbench.core.events.Odometry` event:

* **encoder** (report 003 eq. 1-5, 10): the wheel travel (delta_l, delta_r) gives the travel of the
  mid-axis point delta_d and the heading change delta_theta; the pose moves along the chord at the midpoint
  heading (eq. 5). The inputs u = (delta_l, delta_r) are noisy with covariance U (eq. 10).
* **increment** (fallback when an event carries no wheel travel, or by choice): the robot's own
  (dx, dy, dtheta) in the previous robot frame is composed onto the pose, with a per-step noise whose
  variance is proportional to the distance travelled and the angle turned (``SensorSpec.odometry_sigma_*``).
* **twist noise** (for recorded odometry that is a *measured* twist (v, omega) held for dt, when the dataset
  gives ``SensorSpec.twist_sigma_v_mps`` / ``twist_sigma_omega_radps`` and the event carries v, omega and dt):
  the increment is still the event's (dx, dy, dtheta); only its covariance changes, see below.

Twist noise
-----------
A measured speed and turn rate with white noise of standard deviations sigma_v (m/s) and sigma_omega
(rad/s), held for dt, give the travelled arc length s = v dt and the turned angle a = omega dt with
variances (sigma_v dt)^2 and (sigma_omega dt)^2, independent. The constant-twist (circular arc) motion maps
them to the increment in the previous robot frame,

    dx = s sin(a) / a,    dy = s (1 - cos(a)) / a,    dtheta = a        (a -> 0: dx = s, dy = 0),

so its covariance is Sigma = J diag((sigma_v dt)^2, (sigma_omega dt)^2) J^T with J = d(dx, dy, dtheta)/d(s, a)
evaluated at the measured (v dt, omega dt) (:func:`twist_increment_covariance`; series near a = 0). Sigma has
rank 2 (no lateral slip is modelled; the filters' additive process noise covers it). It **replaces** the
per-distance increment noise for such events (both describe the same error); an event without v, omega and dt,
or a dataset that gives neither sigma, keeps the increment noise, so results on data without twist noise are
unchanged. The particle filter draws (s, a) per particle and moves through the exact arc
(:func:`~locbench.filters._motion_kernels.sample_twist_motion`), offset so that the noise-free draw is the
event's own increment.

Reading of report 003 eq. 10
----------------------------
Eq. 10 writes sigma_L^2 = k_L^2 sum_{i=0}^{k} |delta l_i|: taken literally, the *per-step* input variance
contains the whole distance driven so far, so the covariance added at step k grows with k and the
accumulated covariance grows quadratically with distance. Its reference [2] (Chong & Kleeman 1997)
models each unit of wheel travel as an independent error, i.e. the variance of one step is
k^2 |delta l_k|, and it is the *accumulated* variance (after propagation) that grows with the total
distance. ``input_noise="per_step"`` (the default) is that reading; ``"cumulative"`` is the literal one,
kept to reproduce the report. Both are available through :func:`wheel_variances` and
:class:`MotionModel`.

Frames and units: poses (x m, y m, theta rad) in the world frame, headings wrapped to (-pi, pi];
wheel travel in m (positive forward); increments in the previous robot frame.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass, field
from typing import Literal, TypeVar

import numpy as np
import numpy.typing as npt

from locbench.core.events import Odometry
from locbench.core.geometry import wrap_angle, wrap_scalar
from locbench.core.runkey import RUN_KEY_OMIT_IF_DEFAULT
from locbench.core.tunable import tunable
from locbench.datasets.dataset import MotionNoiseFields, SensorSpec
from locbench.filters.base import bound

FloatArray = npt.NDArray[np.float64]
InputNoise = Literal["per_step", "cumulative"]
MotionKind = Literal["auto", "encoder", "increment"]

logger = logging.getLogger(__name__)

#: Fallback encoder constant k (sqrt(m)) when neither the config nor the dataset gives one:
#: 1 cm standard deviation after 1 m of wheel travel.
DEFAULT_ENCODER_K = 0.01
#: Fallback increment noise when the dataset gives none: m/sqrt(m), rad/sqrt(m), rad/sqrt(rad).
DEFAULT_SIGMA_XY_PER_M = 0.02
DEFAULT_SIGMA_THETA_PER_M = 0.02
DEFAULT_SIGMA_THETA_PER_RAD = 0.02

# --- the encoder model (report 003 eq. 1-5, 10) -----------------------------------------------------------


# The functions of this section in plain floats (and propagate_upper below) are the one implementation of the
# encoder model's step: Python code (MotionModel.step, the public matrix forms) calls them as written, and the
# compiled filters call them from their kernels (filters/_ekf_kernels.py registers them with numba, which compiles
# IEEE operations in source order, no fused multiply-add without fastmath, libm's cos and sin; this module imports
# no numba, as the plugin API does not). numba's on-disk cache of a kernel is keyed on its own module's source
# alone: after editing one of them, delete the ``*.nbi`` / ``*.nbc`` files under ``filters/__pycache__``.


#: One step's wheel travel: a float (the compiled and per-event paths) or an array of them (the particle paths).
_Travel = TypeVar("_Travel", float, FloatArray)


def wheel_increment(d_left: _Travel, d_right: _Travel, wheelbase_m: float) -> tuple[_Travel, _Travel]:
    """(delta_d m, delta_theta rad) of one step's wheel travel (report 003 eq. 2 and 1); also elementwise on arrays.

    delta_d = (delta_l + delta_r) / 2 is the travel of the mid-axis point, delta_theta = (delta_r - delta_l) / W the
    heading change, counter-clockwise; W = ``wheelbase_m``, m.
    """
    return 0.5 * (d_left + d_right), (d_right - d_left) / wheelbase_m


def input_variances(
    d_left: float, d_right: float, k_left: float, k_right: float, cumulative: bool, travelled_left: float,
    travelled_right: float,
) -> tuple[float, float]:  # fmt: skip
    """(sigma_L^2, sigma_R^2) of one step, m^2 (report 003 eq. 10): :func:`wheel_variances` with its reading as a
    flag (``cumulative``: the travelled distances, m, are added to this step's)."""
    al, ar = abs(d_left), abs(d_right)
    if cumulative:
        al += travelled_left
        ar += travelled_right
    return k_left * k_left * al, k_right * k_right * ar


def encoder_jacobian(
    c: float, s: float, delta_d: float, wheelbase_m: float
) -> tuple[float, float, float, float, float, float]:
    """G = d(eq. 5)/d(delta_l, delta_r) row-major (g00, g01, g10, g11, g20, g21), through eq. 1-2.

    ``c``, ``s`` are cos h and sin h at the midpoint heading h = theta + delta_theta / 2. With
    d(delta_d)/d(delta_l) = d(delta_d)/d(delta_r) = 1/2 and d(delta_theta)/d(delta_l) = -1/W,
    d(delta_theta)/d(delta_r) = +1/W, e.g. dx/d(delta_l) = cos(h)/2 + delta_d sin(h) / (2W).
    """
    hw = 0.5 / wheelbase_m
    return (
        0.5 * c + delta_d * s * hw,
        0.5 * c - delta_d * s * hw,
        0.5 * s - delta_d * c * hw,
        0.5 * s + delta_d * c * hw,
        -1.0 / wheelbase_m,
        1.0 / wheelbase_m,
    )


def encoder_step(
    theta: float, d_left: float, d_right: float, wheelbase_m: float, var_left: float, var_right: float
) -> tuple[float, float, float, float, float, float, float, float, float]:
    """One step of the encoder model from heading ``theta`` (rad): (ex, ey, dtheta, n00, n01, n02, n11, n12, n22).

    (ex, ey) = delta_d (cos h, sin h), m, is the world-frame translation of eq. 5 (h = theta + delta_theta / 2),
    dtheta the heading change (eq. 1; the new heading theta + dtheta is left to the caller to wrap), and n the
    upper triangle of the world-frame motion noise G U G^T, U = diag(``var_left``, ``var_right``) (eq. 10, m^2),
    G from :func:`encoder_jacobian`. F = d(eq. 5)/d(x, y, theta) is the identity but for F[0, 2] = -ey and
    F[1, 2] = ex.
    """
    dd, dth = wheel_increment(d_left, d_right, wheelbase_m)
    h = theta + 0.5 * dth
    c, s = math.cos(h), math.sin(h)
    g00, g01, g10, g11, g20, g21 = encoder_jacobian(c, s, dd, wheelbase_m)
    vl, vr = var_left, var_right
    return (
        dd * c,
        dd * s,
        dth,
        g00 * g00 * vl + g01 * g01 * vr,
        g00 * g10 * vl + g01 * g11 * vr,
        g00 * g20 * vl + g01 * g21 * vr,
        g10 * g10 * vl + g11 * g11 * vr,
        g10 * g20 * vl + g11 * g21 * vr,
        g20 * g20 * vl + g21 * g21 * vr,
    )


def propagate_upper(
    p00: float, p01: float, p02: float, p11: float, p12: float, p22: float, f02: float, f12: float, n00: float,
    n01: float, n02: float, n11: float, n12: float, n22: float,
) -> tuple[float, float, float, float, float, float]:  # fmt: skip
    """F P F^T + N for F = [[1, 0, f02], [0, 1, f12], [0, 0, 1]] on upper triangles (p.., n.. row-major), the
    covariance propagation of every motion model here (report 003 eq. 8 with the input noise of eq. 10)."""
    a, b = f02, f12
    return (
        p00 + 2.0 * a * p02 + a * a * p22 + n00,
        p01 + a * p12 + b * p02 + a * b * p22 + n01,
        p02 + a * p22 + n02,
        p11 + 2.0 * b * p12 + b * b * p22 + n11,
        p12 + b * p22 + n12,
        p22 + n22,
    )


def wheel_to_motion(d_left: npt.ArrayLike, d_right: npt.ArrayLike, wheelbase_m: float) -> tuple[FloatArray, FloatArray]:
    """Mid-axis travel and heading change from wheel travel (report 003 eq. 1-2).

    Parameters
    ----------
    d_left, d_right : array-like
        Travel of the left and right wheel in one step, m (broadcast together).
    wheelbase_m : float
        Distance between the drive wheels W, m.

    Returns
    -------
    delta_d : ndarray
        Travel of the mid-axis point, m: (delta_l + delta_r) / 2 (eq. 2).
    delta_theta : ndarray
        Heading change, rad, counter-clockwise: (delta_r - delta_l) / W (eq. 1).
    """
    return wheel_increment(np.asarray(d_left, dtype=np.float64), np.asarray(d_right, dtype=np.float64), wheelbase_m)


def predict_midpoint(pose: npt.ArrayLike, delta_d: npt.ArrayLike, delta_theta: npt.ArrayLike) -> FloatArray:
    """Move poses along the chord at the midpoint heading (report 003 eq. 5).

    Parameters
    ----------
    pose : array-like, shape (..., 3)
        Poses (x m, y m, theta rad) before the step, world frame.
    delta_d, delta_theta : array-like
        Mid-axis travel (m) and heading change (rad), broadcast against ``pose[..., 0]``.

    Returns
    -------
    ndarray, shape broadcast of (..., 3)
        Poses after the step, heading wrapped to (-pi, pi].
    """
    p = np.asarray(pose, dtype=np.float64)
    dd = np.asarray(delta_d, dtype=np.float64)
    dth = np.asarray(delta_theta, dtype=np.float64)
    heading = p[..., 2] + 0.5 * dth
    x = p[..., 0] + dd * np.cos(heading)
    y = p[..., 1] + dd * np.sin(heading)
    th = wrap_angle(p[..., 2] + dth)
    return np.stack(np.broadcast_arrays(x, y, th), axis=-1)


def predict_arc(pose: npt.ArrayLike, delta_d: npt.ArrayLike, delta_theta: npt.ArrayLike) -> FloatArray:
    """Move poses along the exact circular arc (report 003 eq. 3-4), which eq. 5 approximates.

    Evaluated in the equivalent form without the 0/0 at delta_theta = 0: since
    sin(a + d) - sin(a) = 2 cos(a + d/2) sin(d/2) and cos(a) - cos(a + d) = 2 sin(a + d/2) sin(d/2),
    the arc is the chord at the midpoint heading with length delta_d * sin(d/2) / (d/2); eq. 5 takes
    that length as delta_d, an error of delta_d * d^2 / 24. Parameters and returns as :func:`predict_midpoint`.
    """
    p = np.asarray(pose, dtype=np.float64)
    dd = np.asarray(delta_d, dtype=np.float64)
    dth = np.asarray(delta_theta, dtype=np.float64)
    chord = dd * np.sinc(dth / (2.0 * np.pi))  # np.sinc(x) = sin(pi x) / (pi x)
    heading = p[..., 2] + 0.5 * dth
    x = p[..., 0] + chord * np.cos(heading)
    y = p[..., 1] + chord * np.sin(heading)
    th = wrap_angle(p[..., 2] + dth)
    return np.stack(np.broadcast_arrays(x, y, th), axis=-1)


def jacobian_state(theta: float, delta_d: float, delta_theta: float) -> FloatArray:
    """F = d(eq. 5)/d(x, y, theta) at the previous heading ``theta`` (rad), shape (3, 3)."""
    h = theta + 0.5 * delta_theta
    ex, ey = delta_d * math.cos(h), delta_d * math.sin(h)  # the translation of eq. 5 (encoder_step)
    return np.array([[1.0, 0.0, -ey], [0.0, 1.0, ex], [0.0, 0.0, 1.0]])


def jacobian_wheels(theta: float, delta_d: float, delta_theta: float, wheelbase_m: float) -> FloatArray:
    """G = d(eq. 5)/d(delta_l, delta_r), shape (3, 2), through eq. 1-2 (:func:`encoder_jacobian` at
    h = theta + delta_theta / 2)."""
    h = theta + 0.5 * delta_theta
    return np.array(encoder_jacobian(math.cos(h), math.sin(h), delta_d, wheelbase_m)).reshape(3, 2)


def wheel_variances(
    d_left: float,
    d_right: float,
    k_left: float,
    k_right: float,
    input_noise: InputNoise = "per_step",
    travelled_left: float = 0.0,
    travelled_right: float = 0.0,
) -> tuple[float, float]:
    """Variances (sigma_L^2, sigma_R^2) of one step's wheel travel, m^2 (report 003 eq. 10).

    Parameters
    ----------
    d_left, d_right : float
        This step's wheel travel, m.
    k_left, k_right : float
        Encoder constants k_L, k_R, sqrt(m).
    input_noise : {"per_step", "cumulative"}
        ``"per_step"``: k^2 |delta l_k| (Chong & Kleeman, report 003's ref. [2]); ``"cumulative"``: the
        literal eq. 10, k^2 sum_{i<=k} |delta l_i|. See the module docstring.
    travelled_left, travelled_right : float
        sum_{i<k} |delta l_i| and |delta r_i| before this step, m (used by ``"cumulative"`` only).
    """
    cumulative = input_noise == "cumulative"
    return input_variances(d_left, d_right, k_left, k_right, cumulative, travelled_left, travelled_right)


def input_covariance(
    d_left: float,
    d_right: float,
    k_left: float,
    k_right: float,
    input_noise: InputNoise = "per_step",
    travelled_left: float = 0.0,
    travelled_right: float = 0.0,
) -> FloatArray:
    """U = diag(sigma_L^2, sigma_R^2), shape (2, 2), m^2 (report 003 eq. 10); see :func:`wheel_variances`."""
    vl, vr = wheel_variances(d_left, d_right, k_left, k_right, input_noise, travelled_left, travelled_right)
    return np.diag([vl, vr])


# --- the increment fallback ------------------------------------------------------------------------------


def increment_jacobians(theta: float, dx: float, dy: float) -> tuple[FloatArray, FloatArray]:
    """Jacobians of pose (+) (dx, dy, dtheta) w.r.t. the pose (F) and the increment (G), both (3, 3).

    ``theta`` is the heading before the step (rad); (dx, dy) the increment in the previous robot frame (m).
    """
    c, s = math.cos(theta), math.sin(theta)
    F = np.array([[1.0, 0.0, -s * dx - c * dy], [0.0, 1.0, c * dx - s * dy], [0.0, 0.0, 1.0]])
    G = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return F, G


def increment_variances(
    dx: float, dy: float, dtheta: float, sigma_xy_per_m: float, sigma_theta_per_m: float, sigma_theta_per_rad: float
) -> tuple[float, float]:
    """Variances of one increment: (per axis of dx and dy, m^2; of dtheta, rad^2).

    var_xy = sigma_xy^2 * d and var_theta = sigma_theta_m^2 * d + sigma_theta_rad^2 * |dtheta|, with
    d = hypot(dx, dy) the step's distance: independent errors per unit of travel and of rotation, so
    the accumulated variance grows linearly with distance and angle (the per-step reading of eq. 10).
    """
    dist = math.hypot(dx, dy)
    var_xy = sigma_xy_per_m * sigma_xy_per_m * dist
    var_th = sigma_theta_per_m * sigma_theta_per_m * dist + sigma_theta_per_rad * sigma_theta_per_rad * abs(dtheta)
    return var_xy, var_th


def increment_covariance(
    dx: float, dy: float, dtheta: float, sigma_xy_per_m: float, sigma_theta_per_m: float, sigma_theta_per_rad: float
) -> FloatArray:
    """Covariance of one increment (dx, dy, dtheta) in the previous robot frame, shape (3, 3).

    See :func:`increment_variances`. Its world-frame contribution is G Sigma G^T with G from
    :func:`increment_jacobians`; as the (x, y) block is isotropic, that rotation leaves it unchanged.
    """
    vxy, vth = increment_variances(dx, dy, dtheta, sigma_xy_per_m, sigma_theta_per_m, sigma_theta_per_rad)
    return np.diag([vxy, vxy, vth])


# --- twist noise ----------------------------------------------------------------------------------------

# Below this |a| (rad) the arc functions use their Taylor series (the exact forms lose digits to cancellation).
_SERIES_A = 1e-3


def twist_jacobian(s: float, a: float) -> FloatArray:
    """J = d(dx, dy, dtheta)/d(s, a) of the arc :func:`~locbench.filters._motion_kernels.twist_increment` at
    (s m, a rad), shape (3, 2)."""
    if abs(a) < _SERIES_A:
        a2 = a * a
        f, g = 1.0 - a2 / 6.0, a * (0.5 - a2 / 24.0)  # sin(a)/a, (1 - cos a)/a
        df, dg = a * (-1.0 / 3.0 + a2 / 30.0), 0.5 - a2 / 8.0  # their derivatives in a
    else:
        sa, ca = math.sin(a), math.cos(a)
        f, g = sa / a, (1.0 - ca) / a
        df, dg = (a * ca - sa) / (a * a), (a * sa - (1.0 - ca)) / (a * a)
    return np.array([[f, s * df], [g, s * dg], [0.0, 1.0]])


def twist_increment_covariance(v: float, omega: float, dt: float, sigma_v: float, sigma_omega: float) -> FloatArray:
    """Covariance (3, 3) of the increment (dx m, dy m, dtheta rad), previous robot frame, of a measured twist.

    J diag((sigma_v dt)^2, (sigma_omega dt)^2) J^T with J from :func:`twist_jacobian` at s = v dt, a = omega dt
    (see the module docstring). ``v`` m/s, ``omega`` rad/s, ``dt`` s, ``sigma_v`` m/s, ``sigma_omega`` rad/s.
    """
    J = twist_jacobian(v * dt, omega * dt)
    var = np.array([(sigma_v * dt) ** 2, (sigma_omega * dt) ** 2])
    return (J * var) @ J.T


# --- the resolved noise and the per-step propagation used by the filters ---------------------------------


@dataclass(frozen=True, slots=True)
class MotionNoise:
    """The motion noise a filter uses, resolved from its config overrides, the dataset and the defaults.

    Attributes
    ----------
    wheelbase_m : float or None
        W, m; None when unknown (the encoder model is then unavailable).
    k_left, k_right : float
        Encoder constants, sqrt(m) (report 003 eq. 10).
    encoder_given : bool
        Whether k_left and k_right came from the config or the dataset (not the fallback default).
    sigma_xy_per_m, sigma_theta_per_m, sigma_theta_per_rad : float
        Increment noise, m/sqrt(m), rad/sqrt(m), rad/sqrt(rad).
    input_noise : {"per_step", "cumulative"}
        Reading of eq. 10.
    twist_sigma_v_mps, twist_sigma_omega_radps : float or None
        White noise of a measured twist (m/s, rad/s); None when not given. When either is given the other
        counts as 0 and events with v, omega and dt use the twist noise (module docstring).
    """

    wheelbase_m: float | None
    k_left: float
    k_right: float
    encoder_given: bool
    sigma_xy_per_m: float
    sigma_theta_per_m: float
    sigma_theta_per_rad: float
    input_noise: InputNoise = "per_step"
    twist_sigma_v_mps: float | None = None
    twist_sigma_omega_radps: float | None = None

    @property
    def twist_given(self) -> bool:
        """Whether a twist noise was given (config or dataset)."""
        return self.twist_sigma_v_mps is not None or self.twist_sigma_omega_radps is not None

    def scaled(self, factor: float) -> MotionNoise:
        """The same model with every standard deviation (encoder constants, increment, twist noise) times ``factor``."""

        def mul(v: float | None) -> float | None:
            return None if v is None else v * factor

        return dataclasses.replace(
            self,
            k_left=self.k_left * factor,
            k_right=self.k_right * factor,
            sigma_xy_per_m=self.sigma_xy_per_m * factor,
            sigma_theta_per_m=self.sigma_theta_per_m * factor,
            sigma_theta_per_rad=self.sigma_theta_per_rad * factor,
            twist_sigma_v_mps=mul(self.twist_sigma_v_mps),
            twist_sigma_omega_radps=mul(self.twist_sigma_omega_radps),
        )

    def twist_sigmas(self, u: Odometry) -> tuple[float, float] | None:
        """(sigma_v m/s, sigma_omega rad/s) when the twist noise applies to ``u``, else None."""
        if not self.twist_given or u.v is None or u.omega is None or u.dt is None:
            return None
        sv, so = self.twist_sigma_v_mps, self.twist_sigma_omega_radps
        return (0.0 if sv is None else sv, 0.0 if so is None else so)


def _first(*values: float | None) -> float | None:
    for v in values:
        if v is not None:
            return float(v)
    return None


@dataclass(frozen=True, kw_only=True)
class _InputNoiseChoice:
    """The first field of :class:`MotionNoiseConfig`: a base of its own, so that it comes before the noise fields
    in every config's field order (``locbench list``, the config's documentation)."""

    input_noise: InputNoise = "per_step"


@dataclass(frozen=True, kw_only=True)
class MotionNoiseConfig(MotionNoiseFields, _InputNoiseChoice):
    """Config fields shared by the filters that use the odometry noise model (a mixin of their configs): the reading
    of eq. 10, overrides of the dataset's odometry noise (the fields of
    :class:`~locbench.datasets.dataset.MotionNoiseFields`) and one scale on all of it.

    Attributes
    ----------
    input_noise : {"per_step", "cumulative"}
        Reading of report 003 eq. 10 (see :func:`wheel_variances`).
    wheelbase_m, encoder_k_left, encoder_k_right : float or None
        Overrides of W (m) and k_L, k_R (sqrt(m)); None takes the dataset's nominal value.
    odometry_sigma_xy_per_m, odometry_sigma_theta_per_m, odometry_sigma_theta_per_rad : float or None
        Overrides of the increment noise (m/sqrt(m), rad/sqrt(m), rad/sqrt(rad)); None: the dataset's.
    twist_sigma_v_mps, twist_sigma_omega_radps : float or None
        Overrides of the white noise of a measured twist (m/s, rad/s); None: the dataset's (module docstring).
    motion_noise_scale : float
        Factor on every motion standard deviation above (encoder constants, increment and twist noise) after
        they are resolved. Default 1 (the nominal model); the one motion knob a tuner searches.
    """

    # one knob over every motion noise source (encoders, increments, twist): what a tuner searches
    motion_noise_scale: float = field(
        default=1.0,
        metadata=tunable(
            0.1,
            10.0,
            log=True,
            base=bound(0.0, low_open=True, finite=True, what="a finite factor", base=RUN_KEY_OMIT_IF_DEFAULT),
        ),
    )

    def motion_noise(self, sensors: SensorSpec) -> MotionNoise:
        """The noise model: each override, else the dataset's nominal value, else the module default; every
        standard deviation multiplied by ``motion_noise_scale``."""
        noise = _resolve(sensors, self, self.input_noise)
        return noise if self.motion_noise_scale == 1.0 else noise.scaled(self.motion_noise_scale)


def resolve_motion_noise(
    sensors: SensorSpec, *, input_noise: InputNoise = "per_step", **overrides: float | None
) -> MotionNoise:
    """Take each value from the keyword override, else from ``sensors``, else the module default (logged).

    Parameters
    ----------
    sensors : SensorSpec
        The dataset's nominal noise.
    input_noise : {"per_step", "cumulative"}
        Reading of report 003 eq. 10 (see :func:`wheel_variances`).
    **overrides : float or None
        Any field of :class:`~locbench.datasets.dataset.MotionNoiseFields` (``wheelbase_m``, ``encoder_k_left``
        ... ``twist_sigma_omega_radps``); None takes the dataset's value. Another name is a TypeError.
    """
    return _resolve(sensors, MotionNoiseFields(**overrides), input_noise)


def _resolve(sensors: SensorSpec, overrides: MotionNoiseFields, input_noise: InputNoise) -> MotionNoise:
    """:func:`resolve_motion_noise` with the overrides as one record (a :class:`MotionNoiseConfig` is one)."""
    o = overrides
    kl = _first(o.encoder_k_left, sensors.encoder_k_left)
    kr = _first(o.encoder_k_right, sensors.encoder_k_right)
    sxy = _first(o.odometry_sigma_xy_per_m, sensors.odometry_sigma_xy_per_m)
    stm = _first(o.odometry_sigma_theta_per_m, sensors.odometry_sigma_theta_per_m)
    str_ = _first(o.odometry_sigma_theta_per_rad, sensors.odometry_sigma_theta_per_rad)
    # A dataset that gives per-metre noise but no per-radian term means "none"; default it only when all are absent.
    default_per_rad = DEFAULT_SIGMA_THETA_PER_RAD if sxy is None and stm is None else 0.0
    if sxy is None or stm is None:
        logger.info("no nominal odometry increment noise given; using the defaults of %s", __name__)
    return MotionNoise(
        wheelbase_m=_first(o.wheelbase_m, sensors.wheelbase_m),
        k_left=DEFAULT_ENCODER_K if kl is None else kl,
        k_right=DEFAULT_ENCODER_K if kr is None else kr,
        encoder_given=kl is not None and kr is not None,
        sigma_xy_per_m=DEFAULT_SIGMA_XY_PER_M if sxy is None else sxy,
        sigma_theta_per_m=DEFAULT_SIGMA_THETA_PER_M if stm is None else stm,
        sigma_theta_per_rad=str_ if str_ is not None else default_per_rad,
        input_noise=input_noise,
        twist_sigma_v_mps=_first(o.twist_sigma_v_mps, sensors.twist_sigma_v_mps),
        twist_sigma_omega_radps=_first(o.twist_sigma_omega_radps, sensors.twist_sigma_omega_radps),
    )


@dataclass(slots=True)
class Step:
    """One propagated step, in plain floats for the filters' scalar hot paths.

    ``pose`` is the new mean (x, y, theta wrapped); ``f02`` and ``f12`` the only non-trivial entries of F
    (d x'/d theta and d y'/d theta; F is otherwise the identity); ``noise`` the upper triangle
    (n00, n01, n02, n11, n12, n22) of the world-frame motion noise G U G^T or G Sigma G^T; ``encoder``
    whether the wheel-encoder model was used.
    """

    pose: tuple[float, float, float]
    f02: float
    f12: float
    noise: tuple[float, float, float, float, float, float]
    encoder: bool


class MotionModel:
    """Stateful per-step propagation for a Gaussian filter (keeps the wheel travel for ``"cumulative"``).

    Parameters
    ----------
    noise : MotionNoise
    kind : {"auto", "encoder", "increment"}
        ``"auto"``: the encoder model (report 003) when the event has wheel travel, the wheelbase is known
        and the encoder constants were given; ``"encoder"``: whenever the event has wheel travel and the
        wheelbase is known (default constants otherwise); ``"increment"``: always the increment fallback.
        Without the encoder model, an event's increment gets the twist noise when the noise has one and the
        event carries v, omega and dt, else the per-distance increment noise.
    mean : {"model", "compose"}
        ``"model"``: the mean follows the chosen model (eq. 5 for the encoder); ``"compose"``: the mean is
        always pose (+) (dx, dy, dtheta), the robot's own report (dead reckoning), and only the covariance
        uses the model.
    """

    __slots__ = ("_compose", "_cumulative", "_use_encoder", "kind", "noise", "travelled_left", "travelled_right")

    def __init__(
        self, noise: MotionNoise, kind: MotionKind = "auto", mean: Literal["model", "compose"] = "model"
    ) -> None:
        self.noise = noise
        self.kind = kind
        self._compose = mean == "compose"
        self._cumulative = noise.input_noise == "cumulative"
        self._use_encoder = noise.wheelbase_m is not None and (
            kind == "encoder" or (kind == "auto" and noise.encoder_given)
        )
        self.travelled_left = 0.0
        self.travelled_right = 0.0

    def step(self, pose: tuple[float, float, float] | list[float], u: Odometry) -> Step:
        """Propagate ``pose`` (x m, y m, theta rad) with ``u``; returns the new mean, F and the noise."""
        x, y, th = pose[0], pose[1], pose[2]
        nz = self.noise
        encoder = self._use_encoder and u.d_left is not None and u.d_right is not None
        if encoder:
            W = nz.wheelbase_m
            dl, dr = u.d_left, u.d_right
            assert W is not None and dl is not None and dr is not None  # guaranteed by ``encoder``
            vl, vr = input_variances(
                dl, dr, nz.k_left, nz.k_right, self._cumulative, self.travelled_left, self.travelled_right
            )
            self.travelled_left += abs(dl)
            self.travelled_right += abs(dr)
            ex, ey, dth, n00, n01, n02, n11, n12, n22 = encoder_step(th, dl, dr, W, vl, vr)  # eq. 1-2, 5, G U G^T
            noise = (n00, n01, n02, n11, n12, n22)
            if not self._compose:
                return Step((x + ex, y + ey, wrap_scalar(th + dth)), -ey, ex, noise, True)
        elif (tw := nz.twist_sigmas(u)) is not None:
            assert u.v is not None and u.omega is not None and u.dt is not None  # guaranteed by twist_sigmas
            sg = twist_increment_covariance(u.v, u.omega, u.dt, tw[0], tw[1])
            # World frame: G Sigma G^T, G = blockdiag(R(theta), 1) (Sigma is not isotropic here).
            c0, s0 = math.cos(th), math.sin(th)
            a00, a01, a02, a11, a12, a22 = (
                float(sg[0, 0]),
                float(sg[0, 1]),
                float(sg[0, 2]),
                float(sg[1, 1]),
                float(sg[1, 2]),
                float(sg[2, 2]),
            )
            noise = (
                c0 * c0 * a00 - 2.0 * c0 * s0 * a01 + s0 * s0 * a11,
                c0 * s0 * (a00 - a11) + (c0 * c0 - s0 * s0) * a01,
                c0 * a02 - s0 * a12,
                s0 * s0 * a00 + 2.0 * c0 * s0 * a01 + c0 * c0 * a11,
                s0 * a02 + c0 * a12,
                a22,
            )
        else:
            vxy, vth = increment_variances(
                u.dx, u.dy, u.dtheta, nz.sigma_xy_per_m, nz.sigma_theta_per_m, nz.sigma_theta_per_rad
            )
            # G Sigma G^T with G a rotation and an isotropic (x, y) block is Sigma itself.
            noise = (vxy, 0.0, 0.0, vxy, 0.0, vth)
        c0, s0 = math.cos(th), math.sin(th)
        dx, dy = u.dx, u.dy
        ex, ey = c0 * dx - s0 * dy, s0 * dx + c0 * dy
        return Step((x + ex, y + ey, wrap_scalar(th + u.dtheta)), -ey, ex, noise, encoder)


def propagate_covariance(
    P: list[list[float]], f02: float, f12: float, noise: tuple[float, float, float, float, float, float]
) -> list[list[float]]:
    """F P F^T + N for F = [[1, 0, f02], [0, 1, f12], [0, 0, 1]], in plain floats; symmetric by construction.

    ``P`` is a 3x3 nested list; ``noise`` the upper triangle of N (as in :class:`Step`).
    """
    p00, p01, p02 = P[0]
    n00, n01, n02, n11, n12, n22 = noise
    q00, q01, q02, q11, q12, q22 = propagate_upper(p00, p01, p02, P[1][1], P[1][2], P[2][2], f02, f12, n00, n01,
                                                   n02, n11, n12, n22)  # fmt: skip
    return [[q00, q01, q02], [q01, q11, q12], [q02, q12, q22]]
