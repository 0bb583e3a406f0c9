"""A differential-drive robot driven through a route of legs at a fixed time step.

The robot turns on the spot toward each goal, drives straight to it, and on a marked waypoint stands
still for a dwell time, so that "the robot stands on waypoint j at time t_j" is well defined (t_j is the
middle of the dwell). Speeds follow trapezoidal profiles with limited linear / angular speed and
acceleration. An :class:`Arc` leg drives a path of constant curvature (``tiny_circle``).

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
        True wheel travel during step k (between t[k] and t[k+1]), m.
    v, omega : ndarray, shape (n,)
        Commanded twist held during the step, m/s and rad/s.
    dt : float
        Step, s.
    wheelbase_m : float
        The true wheelbase used, m.
    waypoint_t, waypoint_xy : ndarray, shapes (k,), (k, 2)
        When the robot stands on each marked point (middle of the dwell), s, and where, m.
    kidnaps : tuple of Kidnap
        The jumps applied (time = the step time at which the pose jumped).
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


def simulate_route(
    start: npt.ArrayLike,
    legs: Sequence[Leg],
    limits: DriveLimits,
    *,
    kidnap_t_s: float | None = None,
    kidnap_chooser: KidnapChooser | None = None,
    max_duration_s: float = 3600.0,
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

    Returns
    -------
    Motion
    """
    if not legs:
        raise ConfigError("simulate_route: the route needs at least one leg")
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
        d_left = (v - 0.5 * w * b) * dt
        d_right = (v + 0.5 * w * b) * dt
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

    dwell(limits.start_dwell_s, mark=False)
    for leg in legs:
        if isinstance(leg, GoTo):
            gx, gy = float(leg.xy[0]), float(leg.xy[1])
            reached = False
            while not reached:
                # turn on the spot toward the goal
                dist = math.hypot(gx - x, gy - y)
                if dist > 1e-9:
                    turn = wrap_scalar(math.atan2(gy - y, gx - x) - th)
                    sign = 1.0 if turn >= 0 else -1.0
                    rem, u, done = abs(turn), 0.0, False
                    while not done:
                        u, d, done = _profile(rem, u, limits.omega_max_radps, limits.alpha_radps2, dt)
                        rem -= d
                        step(0.0, sign * u)
                # drive straight to it; a kidnap interrupts and the leg starts again from the new pose
                rem, u, done, kidnapped = math.hypot(gx - x, gy - y), 0.0, False, False
                while not done:
                    u, d, done = _profile(rem, u, limits.v_max_mps, limits.accel_mps2, dt)
                    rem -= d
                    step(u, 0.0)
                    if not done and try_kidnap((gx, gy)):
                        kidnapped = True
                        break
                reached = not kidnapped
            if leg.marked:
                dwell(limits.dwell_s, mark=True, xy=(gx, gy))
        elif isinstance(leg, Arc):
            if leg.length_m <= 0:
                raise ConfigError(f"Arc.length_m must be > 0 m, got {leg.length_m}")
            # the speed limit that keeps omega = kappa v within its own limit
            kappa = float(leg.curvature_1pm)
            v_max = limits.v_max_mps if kappa == 0 else min(limits.v_max_mps, limits.omega_max_radps / abs(kappa))
            acc = limits.accel_mps2 if kappa == 0 else min(limits.accel_mps2, limits.alpha_radps2 / abs(kappa))
            rem, u, done = float(leg.length_m), 0.0, False
            while not done:
                u, d, done = _profile(rem, u, v_max, acc, dt)
                rem -= d
                step(u, kappa * u)
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
    )
