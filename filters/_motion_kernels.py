"""The compiled motion of a particle cloud: the one implementation of each motion model's per-particle step.

The models are those of :mod:`locbench.filters._motion` (report 003 eq. 1-2, 5 for the wheel encoders, the
odometry increment, the constant-twist arc of a measured twist). A particle's step from its drawn inputs is
written once here as an inlined scalar kernel; the particle filter's predict (:mod:`locbench.filters.pf`, which
draws the inputs inside its own loop) and the public samplers (:func:`sample_wheel_motion`,
:func:`sample_increment_motion`, :func:`sample_twist_motion`, which draw them with numpy first) both move the
particles through these kernels. A plain numpy form of each model lives in the tests, compared with a tolerance.

Frames and units: poses (x m, y m, theta rad) in the world frame, headings wrapped to (-pi, pi]; wheel travel
in m; increments (dx m, dy m, dtheta rad) in the previous robot frame.

numba's on-disk cache of a kernel is keyed on its own module's source alone: after editing a function compiled
into these kernels from another module (:func:`~locbench.core.geometry.wrap_scalar`,
:func:`~locbench.filters._motion.wheel_increment`, both compiled by :mod:`locbench.filters._ekf_kernels`), delete
the ``*.nbi`` / ``*.nbc`` files under ``filters/__pycache__``.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit

from locbench.core.events import Odometry

# _ekf_kernels compiles the motion model's plain-float functions (wheel_increment among them) for every kernel
# module, and core.geometry.wrap_scalar as _wrap
from locbench.filters._ekf_kernels import _wrap as wrap_mod
from locbench.filters._motion import _SERIES_A, wheel_increment

FloatArray = npt.NDArray[np.float64]

# --- scalar kernels ----------------------------------------------------------------------------------------


@njit(cache=True, inline="always")
def wrap(a: float) -> float:
    """``a`` wrapped to (-pi, pi]; one step covers a heading plus a turn, the modulo only larger values.

    Unlike :func:`~locbench.core.geometry.wrap_scalar` it returns an angle already in range unchanged and wraps
    one turn by one exact subtraction (no fmod in the particle loops); the particle filter's headings and
    bearings are wrapped with it, its twist model with ``wrap_scalar`` (``wrap_mod``)."""
    if -math.pi < a <= math.pi:
        return a
    if math.pi < a <= 3.0 * math.pi:
        return a - 2.0 * math.pi
    if -3.0 * math.pi < a <= -math.pi:
        return a + 2.0 * math.pi
    return math.pi - ((math.pi - a) % (2.0 * math.pi))


#: Below this |angle| (rad) :func:`sincos_near` uses its series: the first omitted terms, d^17 / 17! and
#: d^18 / 18!, are below 1e-19 there, under a quarter of an ulp of the result.
_SERIES_MAX_RAD = 0.5
_SIN_C = (1.0, -1.0 / 6.0, 1.0 / 120.0, -1.0 / 5040.0, 1.0 / 362880.0, -1.0 / 39916800.0, 1.0 / 6227020800.0)
_COS_C = (1.0, -0.5, 1.0 / 24.0, -1.0 / 720.0, 1.0 / 40320.0, -1.0 / 3628800.0, 1.0 / 479001600.0)


@njit(cache=True, inline="always")
def sincos_near(a: float, ref: float, sin_ref: float, cos_ref: float) -> tuple[float, float]:
    """(sin a, cos a) through the angle sum about ``ref`` (whose sine and cosine are given): a Taylor series
    of the small difference d = a - ref and one rotation, a third of the cost of libm's sin and cos for a
    particle cloud (a spread of less than ``_SERIES_MAX_RAD`` about ``ref``); libm for the other angles."""
    d = a - ref
    if abs(d) > _SERIES_MAX_RAD:
        return math.sin(a), math.cos(a)
    d2 = d * d
    # Horner in d^2 up to d^15 (sine) and d^16 (cosine) with the factorials' reciprocals
    sd = -1.0 / 1307674368000.0  # -1 / 15!
    cd = 1.0 / 20922789888000.0  # 1 / 16!
    for k in range(6, -1, -1):
        sd = sd * d2 + _SIN_C[k]
        cd = cd * d2 + _COS_C[k]
    sd *= d
    return sin_ref * cd + cos_ref * sd, cos_ref * cd - sin_ref * sd


@njit(cache=True, inline="always")
def wheel_step(
    theta: float, d_left: float, d_right: float, wheelbase: float, ref: float, sin_ref: float, cos_ref: float
) -> tuple[float, float, float]:
    """One particle's encoder step from heading ``theta`` (rad) with its own wheel travel (m): the world-frame
    translation along the chord at the midpoint heading and the turn, (ex m, ey m, turn rad) (report 003 eq. 1-2,
    5). ``ref``, ``sin_ref``, ``cos_ref``: the cloud's reference heading of :func:`sincos_near`."""
    dd, turn = wheel_increment(d_left, d_right, wheelbase)
    s, c = sincos_near(theta + 0.5 * turn, ref, sin_ref, cos_ref)
    return dd * c, dd * s, turn


@njit(cache=True, inline="always")
def increment_step(
    theta: float, dx: float, dy: float, ref: float, sin_ref: float, cos_ref: float
) -> tuple[float, float]:
    """One particle's increment (dx, dy) (m, previous robot frame) rotated into the world frame at heading
    ``theta`` (rad): (ex m, ey m) of pose (+) increment. ``ref``..: as :func:`wheel_step`."""
    s, c = sincos_near(theta, ref, sin_ref, cos_ref)
    return c * dx - s * dy, s * dx + c * dy


#: The stand-in for a zero argument of sin(y) / y (float64's machine epsilon), whose quotient is then 1.
_EPS = float(np.finfo(np.float64).eps)


@njit(cache=True, inline="always")
def twist_arc(s: float, a: float) -> tuple[float, float, float]:
    """The increment (dx m, dy m, dtheta rad), previous robot frame, of a constant-twist arc of length ``s`` (m)
    turning ``a`` (rad): dx = s sin(a) / a, dy = s (1 - cos a) / a, dtheta = a.

    sin(a) / a is evaluated as sin(y) / y at y = pi (a / pi) (y = eps at a = 0, where the quotient is 1), the
    rounding the particle filter's stored runs carry (y = a rounds differently and would move them);
    (1 - cos a) / a by its series a (1/2 - a^2/24) below ``_SERIES_A``, where the difference loses digits.
    """
    y = math.pi * (a / math.pi)
    if y == 0.0:
        y = _EPS
    sinc = math.sin(y) / y
    cosc = a * (0.5 - a * a / 24.0) if abs(a) < _SERIES_A else (1.0 - math.cos(a)) / a
    return s * sinc, s * cosc, a + 0.0 * s


# --- cloud kernels ------------------------------------------------------------------------------------------


@njit(cache=True)
def move_twist(
    x: FloatArray, noise: FloatArray, s0: float, a0: float, sd_s: float, sd_a: float, dx: float, dy: float,
    dtheta: float,
) -> None:  # fmt: skip
    """The twist model's step of every particle in place, from its standard normal draws ``noise`` (2, N).

    Particle i's arc length is s = s0 + sd_s noise[0, i] and its turn a = a0 + sd_a noise[1, i]; it moves, in its
    own frame, by the event's increment (dx, dy, dtheta) (m, m, rad) plus f(s, a) - f(s0, a0), f the arc of
    :func:`twist_arc`: the noise of the arc, centred on the robot's own increment; the heading is wrapped.
    ``s0`` = v dt (m), ``a0`` = omega dt (rad), ``sd_s`` = sigma_v dt (m), ``sd_a`` = sigma_omega dt (rad).
    """
    b0, b1, b2 = twist_arc(s0, a0)
    for i in range(x.shape[0]):
        i0, i1, i2 = twist_arc(s0 + sd_s * noise[0, i], a0 + sd_a * noise[1, i])
        ix = dx + i0 - b0
        iy = dy + i1 - b1
        ith = dtheta + i2 - b2
        th = x[i, 2]
        c, s = math.cos(th), math.sin(th)
        x[i, 0] = x[i, 0] + c * ix - s * iy
        x[i, 1] = x[i, 1] + s * ix + c * iy
        x[i, 2] = wrap_mod(th + ith)


@njit(cache=True)
def _move_drawn(x: FloatArray, wheels: bool, u: FloatArray, wheelbase: float) -> None:
    """Every particle's step in place from its own drawn inputs ``u`` (N, 3): wheel travel (d_left, d_right, -)
    m with ``wheels`` (:func:`wheel_step`), else an increment (dx m, dy m, dtheta rad) (:func:`increment_step`)."""
    if x.shape[0] == 0:
        return
    ref = x[0, 2]
    sr, cr = math.sin(ref), math.cos(ref)
    for i in range(x.shape[0]):
        if wheels:
            ex, ey, turn = wheel_step(x[i, 2], u[i, 0], u[i, 1], wheelbase, ref, sr, cr)
        else:
            ex, ey = increment_step(x[i, 2], u[i, 0], u[i, 1], ref, sr, cr)
            turn = u[i, 2]
        x[i, 0] += ex
        x[i, 1] += ey
        x[i, 2] = wrap(x[i, 2] + turn)


# --- the public samplers ------------------------------------------------------------------------------------


def _cloud(poses: npt.ArrayLike) -> FloatArray:
    """A fresh (N, 3) float64 copy of ``poses`` for a kernel to move in place."""
    p = np.array(poses, dtype=np.float64, order="C", ndmin=2)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"poses must have shape (N, 3), got {p.shape}")
    return p


def sample_wheel_motion(
    poses: npt.ArrayLike,
    d_left: float,
    d_right: float,
    wheelbase_m: float,
    var_left: float,
    var_right: float,
    rng: np.random.Generator,
) -> FloatArray:
    """Draw one noisy successor per pose from the encoder model (report 003 eq. 1-2, 5, 10).

    Each row gets its own wheel travel delta_l ~ N(d_left, var_left), delta_r ~ N(d_right, var_right)
    (variances from :func:`~locbench.filters._motion.wheel_variances`), moved with eq. 5.

    Parameters
    ----------
    poses : array-like, shape (N, 3)
        Particles (x m, y m, theta rad), world frame.
    d_left, d_right : float
        Measured wheel travel, m.
    wheelbase_m : float
        W, m.
    var_left, var_right : float
        Input variances, m^2.
    rng : numpy.random.Generator
        Draws 2N standard normals: every row's left wheel, then every right wheel.

    Returns
    -------
    ndarray, shape (N, 3)
    """
    p = _cloud(poses)
    noise = rng.standard_normal((2, p.shape[0]))
    u = np.zeros_like(p)
    u[:, 0] = d_left + math.sqrt(var_left) * noise[0]
    u[:, 1] = d_right + math.sqrt(var_right) * noise[1]
    _move_drawn(p, True, u, wheelbase_m)
    return p


def sample_increment_motion(
    poses: npt.ArrayLike,
    dx: float,
    dy: float,
    dtheta: float,
    var_xy: float,
    var_theta: float,
    rng: np.random.Generator,
) -> FloatArray:
    """Draw one noisy successor per pose: pose (+) (increment + noise), noise from
    :func:`~locbench.filters._motion.increment_variances`.

    ``poses`` (N, 3) world frame; the increment in the previous robot frame (m, m, rad); ``var_xy`` m^2 per axis,
    ``var_theta`` rad^2; ``rng`` draws 3N standard normals (every row's dx, then dy, then dtheta). Returns (N, 3).
    """
    p = _cloud(poses)
    noise = rng.standard_normal((3, p.shape[0]))
    sxy, sth = math.sqrt(var_xy), math.sqrt(var_theta)
    u = np.column_stack([dx + sxy * noise[0], dy + sxy * noise[1], dtheta + sth * noise[2]])
    _move_drawn(p, False, u, 1.0)
    return p


def sample_twist_motion(
    poses: npt.ArrayLike,
    u: Odometry,
    sigma_v: float,
    sigma_omega: float,
    rng: np.random.Generator,
) -> FloatArray:
    """Draw one noisy successor per pose from the twist-noise model (:mod:`locbench.filters._motion`).

    Each row draws s ~ N(v dt, (sigma_v dt)^2) and a ~ N(omega dt, (sigma_omega dt)^2) and moves by the
    event's increment plus f(s, a) - f(v dt, omega dt), f the exact arc of :func:`twist_arc`: the noise
    of the arc, centred on the robot's own (dx, dy, dtheta). ``u`` must carry v, omega and dt.

    Parameters
    ----------
    poses : array-like, shape (N, 3)
        Particles (x m, y m, theta rad), world frame.
    u : Odometry
        The event (increment in the previous robot frame; v m/s, omega rad/s, dt s).
    sigma_v, sigma_omega : float
        White noise of the measured speed (m/s) and turn rate (rad/s).
    rng : numpy.random.Generator
        Draws 2N standard normals: every row's arc length, then every turn.

    Returns
    -------
    ndarray, shape (N, 3)
    """
    assert u.v is not None and u.omega is not None and u.dt is not None
    p = _cloud(poses)
    noise = rng.standard_normal((2, p.shape[0]))
    move_twist(p, noise, u.v * u.dt, u.omega * u.dt, sigma_v * u.dt, sigma_omega * u.dt, u.dx, u.dy, u.dtheta)
    return p


def twist_increment(s: npt.ArrayLike, a: npt.ArrayLike) -> FloatArray:
    """Increment (dx, dy, dtheta) in the previous robot frame of a constant-twist arc, shape (..., 3).

    ``s`` is the arc length (m, v dt) and ``a`` the turned angle (rad, omega dt), broadcast together:
    dx = s sin(a)/a, dy = s (1 - cos a)/a, dtheta = a (:func:`twist_arc` at each pair).
    """
    s_, a_ = np.broadcast_arrays(np.asarray(s, dtype=np.float64), np.asarray(a, dtype=np.float64))
    out = np.empty((*s_.shape, 3))
    _twist_arcs(np.ascontiguousarray(s_).reshape(-1), np.ascontiguousarray(a_).reshape(-1), out.reshape(-1, 3))
    return out


@njit(cache=True)
def _twist_arcs(s: FloatArray, a: FloatArray, out: FloatArray) -> None:
    """:func:`twist_arc` of every pair (s[i], a[i]) into out[i] (N, 3)."""
    for i in range(s.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = twist_arc(s[i], a[i])
