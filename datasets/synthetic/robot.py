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

from locbench.core.errors import ConfigError
from locbench.core.geometry import wrap_scalar
from locbench.datasets.dataset import Kidnap

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
    drive = _Drive(start, limits, _Slip(slip_k, slip_rng), kidnap_t_s, kidnap_chooser, max_duration_s)
    drive.dwell(limits.start_dwell_s, mark=False)
    for leg in legs:
        if isinstance(leg, GoTo):
            drive.go_to(float(leg.xy[0]), float(leg.xy[1]), leg.marked)
        elif isinstance(leg, Arc):
            drive.arc(leg)
        else:  # pragma: no cover - type guard
            raise ConfigError(f"unknown leg type {type(leg).__name__}")
    return drive.motion()


class _Drive:
    """The state of one drive of :func:`simulate_route`: the true pose, the executed steps and what was marked.

    Each step integrates the executed wheel travel (:class:`_Slip`) from the current true pose; the lists grow by
    one entry per step of ``limits.dt_s``.
    """

    def __init__(
        self,
        start: npt.ArrayLike,
        limits: DriveLimits,
        slip: _Slip,
        kidnap_t_s: float | None,
        kidnap_chooser: KidnapChooser | None,
        max_duration_s: float,
    ) -> None:
        self.limits = limits
        self.slip = slip
        self.steer = slip.k > 0
        self.dt = limits.dt_s
        self.b = limits.wheelbase_m
        x, y, th = (float(v) for v in np.asarray(start, dtype=np.float64)[:3])
        self.x, self.y, self.th = x, y, wrap_scalar(th)
        self.poses = [(self.x, self.y, self.th)]
        self.dl: list[float] = []
        self.dr: list[float] = []
        self.v: list[float] = []
        self.w: list[float] = []
        self.wp_t: list[float] = []
        self.wp_xy: list[tuple[float, float]] = []
        self.kidnaps: list[Kidnap] = []
        self.kidnap_t_s = kidnap_t_s
        self.kidnap_chooser = kidnap_chooser
        self.pending_kidnap = kidnap_t_s is not None and kidnap_chooser is not None
        self.max_duration_s = max_duration_s
        self.max_steps = math.ceil(max_duration_s / self.dt)

    def step(self, v: float, w: float) -> None:
        """Execute the twist (v m/s, w rad/s) for one step."""
        b, dt = self.b, self.dt
        d_left, d_right = self.slip.travel((v - 0.5 * w * b) * dt, (v + 0.5 * w * b) * dt)
        dx, dy, dth = wheel_increment(d_left, d_right, b)
        c, s = math.cos(self.th), math.sin(self.th)
        self.x += c * dx - s * dy
        self.y += s * dx + c * dy
        self.th = wrap_scalar(self.th + dth)
        self.dl.append(d_left)
        self.dr.append(d_right)
        self.v.append(v)
        self.w.append(w)
        self.poses.append((self.x, self.y, self.th))
        if len(self.poses) > self.max_steps:
            raise ConfigError(f"simulate_route: the route takes longer than max_duration_s={self.max_duration_s} s")

    def dwell(self, duration: float, mark: bool, xy: tuple[float, float] | None = None) -> None:
        """Stand still for ``duration`` s; a marked dwell is a waypoint at its middle (at ``xy``, else here)."""
        n = round(duration / self.dt)
        k0 = len(self.poses) - 1
        for _ in range(n):
            self.step(0.0, 0.0)
        if mark:
            self.wp_t.append((k0 + n // 2) * self.dt)
            self.wp_xy.append(xy if xy is not None else (self.x, self.y))

    def try_kidnap(self, goal: tuple[float, float] | None) -> bool:
        """Apply the pending kidnap if its time has come and the chooser gives a delta; True if applied."""
        if not self.pending_kidnap or (len(self.poses) - 1) * self.dt < float(self.kidnap_t_s) - 1e-9:  # type: ignore[arg-type]
            return False
        delta = self.kidnap_chooser(np.array([self.x, self.y, self.th]), goal)  # type: ignore[misc]
        if delta is None:
            return False
        self.pending_kidnap = False
        self.x += delta[0]
        self.y += delta[1]
        self.th = wrap_scalar(self.th + delta[2])
        self.poses[-1] = (self.x, self.y, self.th)
        t = (len(self.poses) - 1) * self.dt
        self.kidnaps.append(Kidnap(t=t, delta=(float(delta[0]), float(delta[1]), float(delta[2]))))
        logger.debug("kidnap at t=%.2f s by %s", self.kidnaps[-1].t, self.kidnaps[-1].delta)
        return True

    def follow(self, path: _Path, length: float, v_max: float, acc: float, goal: tuple[float, float] | None) -> bool:
        """Drive ``length`` m along ``path`` (progress measured on the true pose); False if kidnapped."""
        omega_max = self.limits.omega_max_radps
        u, s, done = 0.0, 0.0, False
        while not done:
            s, e_lat, e_th = path.errors(self.x, self.y, self.th, s)
            u, _, done = _profile(length - s, u, v_max, acc, self.dt)
            kappa = path.kappa
            if self.steer:
                kappa -= K_LAT * e_lat + K_HEAD * e_th
            w = kappa * u
            if self.steer:
                w = max(-omega_max, min(omega_max, w))
            self.step(u, w)
            if goal is not None and not done and self.try_kidnap(goal):
                return False
        return True

    def turn_toward(self, gx: float, gy: float) -> None:
        """Turn on the spot until the true heading faces (gx, gy) m (nothing when already there)."""
        if math.hypot(gx - self.x, gy - self.y) <= 1e-9:
            return
        target = math.atan2(gy - self.y, gx - self.x)
        sign = 1.0 if wrap_scalar(target - self.th) >= 0 else -1.0
        lim = self.limits
        u, done = 0.0, False
        while not done:
            u, _, done = _profile(
                sign * wrap_scalar(target - self.th), u, lim.omega_max_radps, lim.alpha_radps2, self.dt
            )
            self.step(0.0, sign * u)

    def go_to(self, gx: float, gy: float, marked: bool) -> None:
        """A :class:`GoTo` leg: turn, then drive the line from here to the goal; a kidnap starts the leg again."""
        reached = False
        while not reached:
            self.turn_toward(gx, gy)
            line = _Path(self.x, self.y, math.atan2(gy - self.y, gx - self.x), 0.0)
            length = math.hypot(gx - self.x, gy - self.y)
            reached = self.follow(line, length, self.limits.v_max_mps, self.limits.accel_mps2, (gx, gy))
        if marked:
            self.dwell(self.limits.dwell_s, mark=True, xy=(gx, gy))

    def arc(self, leg: Arc) -> None:
        """An :class:`Arc` leg from the current true pose, at the speed that keeps omega = kappa v in its limit."""
        if leg.length_m <= 0:
            raise ConfigError(f"Arc.length_m must be > 0 m, got {leg.length_m}")
        lim = self.limits
        kappa = float(leg.curvature_1pm)
        v_max = lim.v_max_mps if kappa == 0 else min(lim.v_max_mps, lim.omega_max_radps / abs(kappa))
        acc = lim.accel_mps2 if kappa == 0 else min(lim.accel_mps2, lim.alpha_radps2 / abs(kappa))
        self.follow(_Path(self.x, self.y, self.th, kappa), float(leg.length_m), v_max, acc, None)
        if leg.marked:
            self.dwell(lim.dwell_s, mark=True)

    def motion(self) -> Motion:
        """The drive as a :class:`Motion`."""
        n = len(self.poses)
        return Motion(
            t=np.arange(n, dtype=np.float64) * self.dt,
            poses=np.asarray(self.poses, dtype=np.float64),
            d_left=np.asarray(self.dl, dtype=np.float64),
            d_right=np.asarray(self.dr, dtype=np.float64),
            v=np.asarray(self.v, dtype=np.float64),
            omega=np.asarray(self.w, dtype=np.float64),
            dt=self.dt,
            wheelbase_m=self.b,
            waypoint_t=np.asarray(self.wp_t, dtype=np.float64).reshape(-1),
            waypoint_xy=np.asarray(self.wp_xy, dtype=np.float64).reshape(-1, 2),
            kidnaps=tuple(self.kidnaps),
            slip_k=float(self.slip.k),
        )
