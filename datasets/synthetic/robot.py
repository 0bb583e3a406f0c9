"""A differential-drive robot driven through a route of legs at a fixed time step.

The robot turns on the spot toward each goal, drives straight to it, and on a marked waypoint stands
still for a dwell time, so that "the robot stands on waypoint j at time t_j" is well defined (t_j is the
middle of the dwell). Speeds follow trapezoidal profiles with limited linear / angular speed and
acceleration. An :class:`Arc` leg drives a path of constant curvature (``tiny_circle``).

Commanded and executed motion
-----------------------------
Each step the planner commands a twist (v, omega), held for the step; the drive turns it into wheel
travel with the TRUE wheelbase, c_L = (v - omega W / 2) dt and c_R = (v + omega W / 2) dt. With
``slip_k`` > 0 the wheels do not execute that travel exactly (**execution noise**): each wheel's true
travel in step k is

    d = c + slip_k sqrt(|c|) z,   z ~ N(0, 1) independent per wheel and step,

zero-mean wheel slip on the floor and speed-servo tracking error whose variance grows with the commanded
travel, the form of report 003 eq. 10 and the slip ``scan_grid`` already simulates. A robot standing
still (c = 0) does not move. The commanded twist recorded in :class:`Motion` (and in the Odometry
events) is therefore what the robot tried, not what it did: integrating it drifts from the truth (a
random walk of the heading, var = 2 slip_k^2 |c| / W^2 per step), while the wheel travel recorded (and
measured by the encoders, with their own error) is the true one.

The planner knows the true pose (a simulation's perfect feedback, as in ``scan_grid``) and closes the
loop so that the route stays the designed one: a turn ends when the true heading faces the goal, a
straight drive or an arc ends when the true progress along its reference path (the line from where the
drive started to the goal, or the circle of the arc) reaches its length, and with execution noise on,
the drive steers back onto that path, commanded curvature kappa_ref - K_LAT e_lat - K_HEAD e_theta
(e_lat the signed lateral offset, m, positive left; e_theta the heading error, rad; gains per metre
travelled, critically damped over ``STEER_SETTLE_M``). The robot thus stops within a few millimetres of
each goal (a marked waypoint is where it stands), and the commands of a straight drive carry a small
steering omega (below about 1e-2 rad/s on ``room`` with slip_k = 0.002 sqrt(m)). Without execution noise no steering is
commanded and the motion is exact.

The true motion of one step is computed from the true wheel travel with the TRUE wheelbase by report
003 eq. 1, 2 and 5 (the mid-point arc model), the same model the odometry uses with the nominal
wheelbase; with no odometry error, dead reckoning therefore reproduces the truth exactly.

Kidnaps: at a requested time (postponed until the robot is driving toward a goal) the true pose jumps by a
world-frame delta chosen by a callback; the robot is put down at rest and resumes its route from there.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from locbench.datasets.base import Kidnap
from locbench.errors import ConfigError
from locbench.geometry import wrap_scalar

logger = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]

#: Callback choosing a kidnap: (true pose (3,), current goal (x, y) or None) -> world delta or None to postpone.
KidnapChooser = Callable[[FloatArray, "tuple[float, float] | None"], "tuple[float, float, float] | None"]

#: Distance over which the path-following steering settles (critically damped), m.
STEER_SETTLE_M = 0.5
#: Steering gain on the lateral offset, 1/m^2 (= 1 / STEER_SETTLE_M^2).
K_LAT = 1.0 / STEER_SETTLE_M**2
#: Steering gain on the heading error, 1/m (= 2 / STEER_SETTLE_M).
K_HEAD = 2.0 / STEER_SETTLE_M
#: Normal draws made at a time for the execution noise (one row per step; the rows do not depend on it).
_SLIP_BLOCK = 1024


@dataclass(frozen=True, kw_only=True)
class DriveLimits:
    """Speed limits and timing of the simulated robot.

    Attributes
    ----------
    dt_s : float
        Simulation and odometry step, s (0.05 s = 20 Hz).
    v_max_mps, accel_mps2 : float
        Linear speed limit (m/s) and acceleration (m/s^2).
    omega_max_radps, alpha_radps2 : float
        Turn rate limit (rad/s) and angular acceleration (rad/s^2).
    dwell_s : float
        Time standing on a marked waypoint, s.
    start_dwell_s : float
        Time standing at the start before moving, s.
    wheelbase_m : float
        TRUE distance between the drive wheels, m (the odometry may assume another).
    """

    dt_s: float = 0.05
    v_max_mps: float = 0.3
    accel_mps2: float = 0.3
    omega_max_radps: float = 0.6
    alpha_radps2: float = 1.2
    dwell_s: float = 2.0
    start_dwell_s: float = 1.0
    wheelbase_m: float = 0.40

    def __post_init__(self) -> None:
        for name in ("dt_s", "v_max_mps", "accel_mps2", "omega_max_radps", "alpha_radps2", "wheelbase_m"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"DriveLimits.{name} must be > 0, got {getattr(self, name)}")
        for name in ("dwell_s", "start_dwell_s"):
            if not getattr(self, name) >= 0:
                raise ConfigError(f"DriveLimits.{name} must be >= 0 s, got {getattr(self, name)}")


@dataclass(frozen=True)
class GoTo:
    """Turn toward ``xy`` (m, world), drive there; a ``marked`` goal is a waypoint and is dwelt on."""

    xy: tuple[float, float]
    marked: bool = True


@dataclass(frozen=True)
class Arc:
    """Drive ``length_m`` along a path of constant curvature ``curvature_1pm`` (1/m, > 0 turns left)."""

    length_m: float
    curvature_1pm: float
    marked: bool = True


Leg = GoTo | Arc


@dataclass(frozen=True, eq=False)
class Motion:
    """The simulated true motion.

    Attributes
    ----------
    t : ndarray, shape (n+1,)
        Step times, s (t[0] = 0).
    poses : ndarray, shape (n+1, 3)
        True pose (x m, y m, theta rad wrapped) at each step time; after a kidnap, the pose after the jump.
    d_left, d_right : ndarray, shape (n,)
        True (executed) wheel travel during step k (between t[k] and t[k+1]), m.
    v, omega : ndarray, shape (n,)
        Commanded twist held during the step, m/s and rad/s (executed with the slip ``slip_k``).
    dt : float
        Step, s.
    wheelbase_m : float
        The true wheelbase used, m.
    waypoint_t, waypoint_xy : ndarray, shapes (k,), (k, 2)
        When the robot stands on each marked point (middle of the dwell), s, and where, m.
    kidnaps : tuple of Kidnap
        The jumps applied (time = the step time at which the pose jumped).
    slip_k : float
        Execution noise constant, sqrt(m) (0 = the commanded twist is executed exactly).
    """

    t: FloatArray
    poses: FloatArray
    d_left: FloatArray
    d_right: FloatArray
    v: FloatArray
    omega: FloatArray
    dt: float
    wheelbase_m: float
    waypoint_t: FloatArray
    waypoint_xy: FloatArray
    kidnaps: tuple[Kidnap, ...]
    slip_k: float = 0.0

    @property
    def n_steps(self) -> int:
        return int(self.d_left.shape[0])

    @property
    def duration(self) -> float:
        return float(self.t[-1])


def wheel_increment(d_left: float, d_right: float, wheelbase: float) -> tuple[float, float, float]:
    """Pose increment in the previous robot frame from wheel travel (report 003 eq. 1, 2 and 5).

    Parameters
    ----------
    d_left, d_right : float
        Wheel travel, m.
    wheelbase : float
        Wheelbase W, m.

    Returns
    -------
    (dx, dy, dtheta)
        dd cos(dtheta / 2), dd sin(dtheta / 2) and dtheta, with dtheta = (d_r - d_l) / W (eq. 1) and
        dd = (d_l + d_r) / 2 (eq. 2): eq. 5 written in the previous robot frame.
    """
    dth = (d_right - d_left) / wheelbase
    dd = 0.5 * (d_left + d_right)
    return dd * math.cos(0.5 * dth), dd * math.sin(0.5 * dth), dth


def _profile(remaining: float, u: float, u_max: float, acc: float, dt: float) -> tuple[float, float, bool]:
    """One step of a trapezoidal profile: (speed held this step, distance covered, finished)."""
    if remaining <= 1e-12:
        return 0.0, 0.0, True
    # sqrt(2 a r) is the fastest speed from which the robot can still stop within the remaining distance.
    u_new = min(u_max, u + acc * dt, math.sqrt(2.0 * acc * remaining))
    if u_new * dt >= remaining - 1e-12:
        return remaining / dt, remaining, True
    return u_new, u_new * dt, False


class _Slip:
    """Per-step normal draws of the execution noise, one (left, right) row per step, drawn in blocks."""

    def __init__(self, k: float, rng: np.random.Generator | None) -> None:
        self.k = k
        self.rng = rng
        self.buf: list[list[float]] = []
        self.i = 0

    def travel(self, c_left: float, c_right: float) -> tuple[float, float]:
        """Executed wheel travel for commanded travel (c_left, c_right), m."""
        if self.rng is None or self.k == 0.0:
            return c_left, c_right
        if self.i >= len(self.buf):
            self.buf = self.rng.standard_normal((_SLIP_BLOCK, 2)).tolist()
            self.i = 0
        z_left, z_right = self.buf[self.i]
        self.i += 1
        return c_left + self.k * math.sqrt(abs(c_left)) * z_left, c_right + self.k * math.sqrt(abs(c_right)) * z_right


@dataclass(frozen=True)
class _Path:
    """Reference path of a drive: from (x0, y0) with heading th0, straight (kappa = 0) or a circle."""

    x0: float
    y0: float
    th0: float
    kappa: float

    def errors(self, x: float, y: float, th: float, progress: float) -> tuple[float, float, float]:
        """(progress along the path m, lateral offset m (+ left), heading error rad) of a true pose.

        ``progress`` is the previous value (the swept angle of a circle is unwrapped from it).
        """
        c0, s0 = math.cos(self.th0), math.sin(self.th0)
        if self.kappa == 0.0:
            dx, dy = x - self.x0, y - self.y0
            return c0 * dx + s0 * dy, c0 * dy - s0 * dx, wrap_scalar(th - self.th0)
        r = 1.0 / abs(self.kappa)
        sg = 1.0 if self.kappa > 0 else -1.0
        cx, cy = self.x0 - sg * r * s0, self.y0 + sg * r * c0
        phi = math.atan2(y - cy, x - cx)
        phi_start = self.th0 - sg * 0.5 * math.pi
        # unwrap the swept angle next to the previous progress
        swept_prev = progress / r
        swept = swept_prev + wrap_scalar(sg * (phi - phi_start) - swept_prev)
        rho = math.hypot(x - cx, y - cy)
        return r * swept, sg * (r - rho), wrap_scalar(th - (phi + sg * 0.5 * math.pi))


def simulate_route(
    start: npt.ArrayLike,
    legs: Sequence[Leg],
    limits: DriveLimits,
    *,
    kidnap_t_s: float | None = None,
    kidnap_chooser: KidnapChooser | None = None,
    max_duration_s: float = 3600.0,
    slip_k: float = 0.0,
    slip_rng: np.random.Generator | None = None,
) -> Motion:
    """Drive the robot from ``start`` through ``legs``.

    Parameters
    ----------
    start : array-like, shape (3,)
        True start pose (x m, y m, theta rad), world frame.
    legs : sequence of GoTo or Arc
        The route.
    limits : DriveLimits
    kidnap_t_s : float or None
        Earliest time of a kidnap, s; applied at the first step at or after it while the robot drives
        toward a goal and ``kidnap_chooser`` returns a delta.
    kidnap_chooser : callable
        (true pose, goal xy) -> (dx m, dy m, dtheta rad) world-frame jump, or None to try the next step.
    max_duration_s : float
        Safety stop, s.
    slip_k : float
        Execution noise constant, sqrt(m) (module docstring); 0 = the commanded twist is executed exactly.
    slip_rng : Generator or None
        Source of the execution noise (required when ``slip_k`` > 0); one (left, right) pair of standard
        normals per step, standing still included, so a step's draws do not depend on the route before it.

    Returns
    -------
    Motion
    """
    if not legs:
        raise ConfigError("simulate_route: the route needs at least one leg")
    if not (slip_k >= 0 and math.isfinite(slip_k)):
        raise ConfigError(f"simulate_route: slip_k must be >= 0 sqrt(m), got {slip_k}")
    if slip_k > 0 and slip_rng is None:
        raise ConfigError("simulate_route: slip_k > 0 needs a slip_rng (the execution noise's generator)")
    slip = _Slip(slip_k, slip_rng)
    steer = slip_k > 0
    dt = limits.dt_s
    b = limits.wheelbase_m
    x, y, th = (float(v) for v in np.asarray(start, dtype=np.float64)[:3])
    th = wrap_scalar(th)
    poses = [(x, y, th)]
    dl_list: list[float] = []
    dr_list: list[float] = []
    v_list: list[float] = []
    w_list: list[float] = []
    wp_t: list[float] = []
    wp_xy: list[tuple[float, float]] = []
    kidnaps: list[Kidnap] = []
    pending_kidnap = kidnap_t_s is not None and kidnap_chooser is not None
    max_steps = math.ceil(max_duration_s / dt)

    def step(v: float, w: float) -> None:
        nonlocal x, y, th
        d_left, d_right = slip.travel((v - 0.5 * w * b) * dt, (v + 0.5 * w * b) * dt)
        dx, dy, dth = wheel_increment(d_left, d_right, b)
        c, s = math.cos(th), math.sin(th)
        x += c * dx - s * dy
        y += s * dx + c * dy
        th = wrap_scalar(th + dth)
        dl_list.append(d_left)
        dr_list.append(d_right)
        v_list.append(v)
        w_list.append(w)
        poses.append((x, y, th))
        if len(poses) > max_steps:
            raise ConfigError(f"simulate_route: the route takes longer than max_duration_s={max_duration_s} s")

    def dwell(duration: float, mark: bool, xy: tuple[float, float] | None = None) -> None:
        n = round(duration / dt)
        k0 = len(poses) - 1
        for _ in range(n):
            step(0.0, 0.0)
        if mark:
            wp_t.append((k0 + n // 2) * dt)
            wp_xy.append(xy if xy is not None else (x, y))

    def try_kidnap(goal: tuple[float, float] | None) -> bool:
        nonlocal x, y, th, pending_kidnap
        if not pending_kidnap or (len(poses) - 1) * dt < float(kidnap_t_s) - 1e-9:  # type: ignore[arg-type]
            return False
        delta = kidnap_chooser(np.array([x, y, th]), goal)  # type: ignore[misc]
        if delta is None:
            return False
        pending_kidnap = False
        x += delta[0]
        y += delta[1]
        th = wrap_scalar(th + delta[2])
        poses[-1] = (x, y, th)
        kidnaps.append(Kidnap(t=(len(poses) - 1) * dt, delta=(float(delta[0]), float(delta[1]), float(delta[2]))))
        logger.debug("kidnap at t=%.2f s by %s", kidnaps[-1].t, kidnaps[-1].delta)
        return True

    def follow(path: _Path, length: float, v_max: float, acc: float, goal: tuple[float, float] | None) -> bool:
        """Drive ``length`` m along ``path`` (progress measured on the true pose); False if kidnapped."""
        u, s, done = 0.0, 0.0, False
        while not done:
            s, e_lat, e_th = path.errors(x, y, th, s)
            u, _, done = _profile(length - s, u, v_max, acc, dt)
            kappa = path.kappa
            if steer:
                kappa -= K_LAT * e_lat + K_HEAD * e_th
            w = kappa * u
            if steer:
                w = max(-limits.omega_max_radps, min(limits.omega_max_radps, w))
            step(u, w)
            if goal is not None and not done and try_kidnap(goal):
                return False
        return True

    dwell(limits.start_dwell_s, mark=False)
    for leg in legs:
        if isinstance(leg, GoTo):
            gx, gy = float(leg.xy[0]), float(leg.xy[1])
            reached = False
            while not reached:
                # turn on the spot toward the goal until the true heading faces it
                dist = math.hypot(gx - x, gy - y)
                if dist > 1e-9:
                    target = math.atan2(gy - y, gx - x)
                    sign = 1.0 if wrap_scalar(target - th) >= 0 else -1.0
                    u, done = 0.0, False
                    while not done:
                        u, _, done = _profile(
                            sign * wrap_scalar(target - th), u, limits.omega_max_radps, limits.alpha_radps2, dt
                        )
                        step(0.0, sign * u)
                # drive along the line from here to the goal; a kidnap interrupts and the leg starts again
                heading = math.atan2(gy - y, gx - x)
                line = _Path(x, y, heading, 0.0)
                reached = follow(line, math.hypot(gx - x, gy - y), limits.v_max_mps, limits.accel_mps2, (gx, gy))
            if leg.marked:
                dwell(limits.dwell_s, mark=True, xy=(gx, gy))
        elif isinstance(leg, Arc):
            if leg.length_m <= 0:
                raise ConfigError(f"Arc.length_m must be > 0 m, got {leg.length_m}")
            # the speed limit that keeps omega = kappa v within its own limit
            kappa = float(leg.curvature_1pm)
            v_max = limits.v_max_mps if kappa == 0 else min(limits.v_max_mps, limits.omega_max_radps / abs(kappa))
            acc = limits.accel_mps2 if kappa == 0 else min(limits.accel_mps2, limits.alpha_radps2 / abs(kappa))
            follow(_Path(x, y, th, kappa), float(leg.length_m), v_max, acc, None)
            if leg.marked:
                dwell(limits.dwell_s, mark=True)
        else:  # pragma: no cover - type guard
            raise ConfigError(f"unknown leg type {type(leg).__name__}")

    n = len(poses)
    return Motion(
        t=np.arange(n, dtype=np.float64) * dt,
        poses=np.asarray(poses, dtype=np.float64),
        d_left=np.asarray(dl_list, dtype=np.float64),
        d_right=np.asarray(dr_list, dtype=np.float64),
        v=np.asarray(v_list, dtype=np.float64),
        omega=np.asarray(w_list, dtype=np.float64),
        dt=dt,
        wheelbase_m=b,
        waypoint_t=np.asarray(wp_t, dtype=np.float64).reshape(-1),
        waypoint_xy=np.asarray(wp_xy, dtype=np.float64).reshape(-1, 2),
        kidnaps=tuple(kidnaps),
        slip_k=float(slip_k),
    )
