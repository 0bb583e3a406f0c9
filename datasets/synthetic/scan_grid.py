"""``scan_grid``: report 004's experiment, a robot driven by 1-second translate-or-rotate commands.

Report 004 (section II) drives a simulated robot with "a constant velocity command executed for a single
second" that either translates or rotates, never both, and localizes it against scans recorded at grid
poses. Here:

World
    An 8 m x 6 m room with a cabinet, a pillar, a short partition and a table against the north wall
    (so that no symmetry makes two poses look alike at eight bearings).
Robot and commands
    The shared differential-drive robot of :mod:`locbench.datasets.synthetic.toolkit` (true wheelbase
    and random wheel error as everywhere). A planner that knows the true pose issues one command per second
    toward each goal of a fixed tour (8 marked waypoints, the heading crossing +-pi): rotate at up to
    45 deg/s (one scan bearing per command) until facing the goal within 0.5 deg, then translate at up to
    ``grid_step_m`` per second (one database cell per command). On a marked waypoint it sends two
    stop commands (2 s); the waypoint time is the boundary between them. The robot executes each command
    for 1 s (in 20 steps of 0.05 s) with a random wheel-travel error of variance k^2 |d| (report 003 eq. 10,
    k = ``ENCODER_K_TRUE``), so the commanded twist is what the robot tries, not exactly what it does.
    ``mixed_commands=true``: the planner always sends both a rotation (the same clipped heading error per
    second) and a translation (half the translation speed while turning by more than 0.5 deg, full speed
    after), so every turn is driven as an arc: the commands break the translate-or-rotate assumption.
Events (all at the 1 s command boundaries, where the ground truth is also given)
    - Odometry: one per command, with the commanded (v, omega, dt = 1 s) and the wheel-encoder
      increment (dx, dy, dtheta) and wheel travel over the second, measured with the robot's systematic and
      random encoder error (report 003 eq. 1, 2, 5, 10; the same calibrated constants as ``room``);
    - LaserScan: a 360 deg laser (361 beams 1 deg apart, 8 m, 1 cm noise, 1 % dropouts) ray-cast on the
      0.05 m occupancy grid, one scan per command boundary including t = 0.
``kidnap_m`` (> 0) moves the robot by that distance (direction drawn from the seed, landing in free space)
and by ``kidnap_rad`` at the first command boundary after half the tour; the planner goes on from there.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from locbench.core.errors import ConfigError
from locbench.core.events import Event, LaserScan, Odometry
from locbench.core.geometry import wrap_angle, wrap_scalar
from locbench.core.runkey import RUN_KEY_OMIT_IF_DEFAULT
from locbench.core.spec import params_to_dict
from locbench.datasets.dataset import (
    Dataset,
    Gaussian2,
    Kidnap,
    SyntheticBuilder,
    Trajectory2D,
    Waypoints,
    sort_events,
)
from locbench.datasets.synthetic.robot import wheel_increment
from locbench.datasets.synthetic.sensors import LaserSensor, odometry_increments
from locbench.datasets.synthetic.toolkit import (
    ENCODER_K_TRUE,
    GENERATOR_VERSION,
    WHEELBASE_NOMINAL_M,
    check_kidnap_params,
    encoder_model,
    kidnap_chooser,
    kidnap_distance,
    matched_initial_mean,
    matched_stream,
    nominal_sensor_spec,
    split_streams,
    true_wheelbase,
)
from locbench.datasets.synthetic.world import World
from locbench.raycast.cast import cast_rays

logger = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]

#: Command duration, s (report 004: "a constant velocity command executed for a single second").
COMMAND_S = 1.0
#: Simulation sub-steps per command.
SUBSTEPS = 20
#: Largest rotation rate of a command, rad/s: 45 deg, one of the eight scan bearings per command.
OMEGA_MAX_RADPS = math.pi / 4.0
#: The planner faces a goal within this heading error before translating, rad.
HEADING_TOL_RAD = math.radians(0.5)
#: A goal counts as reached within this distance, m.
GOAL_TOL_M = 0.01

SCAN_GRID_START = (1.0, 1.0, 0.0)
#: The tour: (x, y, marked). Rows along x at y = 1, 2.5, 4, 5 and back down the west side; the heading
#: passes +-pi on the westward rows.
SCAN_GRID_TOUR: tuple[tuple[float, float, bool], ...] = (
    (4.0, 1.0, True),
    (6.0, 1.0, False),
    (6.0, 2.5, True),
    (1.5, 2.5, True),
    (1.5, 4.0, False),
    (6.0, 4.0, True),
    (6.0, 5.0, False),
    (3.0, 5.0, True),
    (1.0, 5.0, False),
    (1.0, 3.0, True),
    (2.5, 1.5, True),
    (5.0, 2.0, True),
)

#: The 360 deg laser.
SCAN_GRID_LASER = LaserSensor(
    rate_hz=1.0,
    beams=361,
    fov_rad=2.0 * math.pi,
    min_range_m=0.02,
    max_range_m=8.0,
    sigma_m=0.01,
    dropout_prob=0.01,
)


def scan_grid_world() -> World:
    """The 8 m x 6 m room of ``scan_grid`` with four obstacles off the tour."""

    def box(x0: float, y0: float, x1: float, y1: float) -> list[tuple[float, float, float, float]]:
        return [(x0, y0, x1, y0), (x1, y0, x1, y1), (x1, y1, x0, y1), (x0, y1, x0, y0)]

    walls: list[tuple[float, float, float, float]] = [
        (0.0, 0.0, 8.0, 0.0),
        (8.0, 0.0, 8.0, 6.0),
        (8.0, 6.0, 0.0, 6.0),
        (0.0, 6.0, 0.0, 0.0),
        (8.0, 3.2, 7.0, 3.2),  # partition from the east wall
    ]
    walls += box(7.2, 0.4, 7.8, 1.6)  # cabinet, south-east corner
    walls += box(3.3, 3.1, 3.7, 3.4)  # pillar between the rows y = 2.5 and 4
    walls += box(4.5, 5.6, 5.7, 6.0)  # table against the north wall
    return World(walls=np.array(walls), landmarks=np.zeros((0, 2)), bounds=(0.0, 0.0, 8.0, 6.0), name="scan_grid")


@dataclass(frozen=True, kw_only=True)
class ScanGridParams:
    """Parameters of ``scan_grid``.

    Attributes
    ----------
    grid_step_m : float
        Spacing of the database poses, m: the translation speed is one spacing per 1 s command
        (a filter's scan database should use the same spacing). In [0.05, 0.5].
    mixed_commands : bool
        Commands translate and rotate at once (arcs), breaking the translate-or-rotate assumption.
    kidnap_m : float
        Kidnap distance after half the tour, m (0 = none).
    kidnap_rad : float
        Kidnap rotation magnitude, rad (sign drawn at random).
    matched : bool
        Model-matched world: no systematic odometry error, encoder k at its nominal value, the initial belief's
        mean drawn from the belief (the slip of the command execution is unchanged).
    """

    grid_step_m: float = 0.25
    mixed_commands: bool = False
    kidnap_m: float = field(default=0.0, metadata=kidnap_distance(8.0, 6.0))
    kidnap_rad: float = 0.5
    matched: bool = field(default=False, metadata=RUN_KEY_OMIT_IF_DEFAULT)

    def __post_init__(self) -> None:
        # checked when the spec is parsed, so a bad value is a one-line error before anything runs
        if not 0.05 <= self.grid_step_m <= 0.5:
            raise ConfigError(f"parameter 'grid_step_m' must be in [0.05, 0.5] m, got {self.grid_step_m}")
        check_kidnap_params(self.kidnap_m, self.kidnap_rad)


@dataclass
class _Commands:
    """What the planner produced: command boundaries' true poses and per-command data."""

    poses: list[tuple[float, float, float]]
    v: list[float]
    omega: list[float]
    d_left: list[float]
    d_right: list[float]
    wp_t: list[float]
    wp_xy: list[tuple[float, float]]
    kidnaps: list[Kidnap]


def drive_commands(
    start: tuple[float, float, float],
    tour: tuple[tuple[float, float, bool], ...],
    v_max: float,
    mixed: bool,
    rng: np.random.Generator,
    kidnap: tuple[float, object] | None = None,
    max_commands: int = 2000,
    wheelbase_m: float | None = None,
) -> _Commands:
    """Plan and execute 1 s commands along ``tour``; see the module docstring.

    ``kidnap`` is (time s, chooser) with a chooser as :func:`~locbench.datasets.synthetic.toolkit.kidnap_chooser`
    returns. Each command draws ``2 * SUBSTEPS`` normals from ``rng`` (slip of each wheel per sub-step).
    ``wheelbase_m`` is the true wheelbase (default: the shared robot's, :func:`true_wheelbase`).
    """
    b_true = true_wheelbase() if wheelbase_m is None else wheelbase_m
    x, y, th = start
    out = _Commands([(x, y, th)], [], [], [], [], [], [], [])
    dt = COMMAND_S / SUBSTEPS
    pending = kidnap

    def execute(v: float, w: float) -> None:
        nonlocal x, y, th
        z = rng.standard_normal((SUBSTEPS, 2))
        dl_sum = dr_sum = 0.0
        for k in range(SUBSTEPS):
            cl = (v - 0.5 * w * b_true) * dt
            cr = (v + 0.5 * w * b_true) * dt
            dl = cl + ENCODER_K_TRUE * math.sqrt(abs(cl)) * z[k, 0]
            dr = cr + ENCODER_K_TRUE * math.sqrt(abs(cr)) * z[k, 1]
            ddx, ddy, ddth = wheel_increment(dl, dr, b_true)
            c, s = math.cos(th), math.sin(th)
            x += c * ddx - s * ddy
            y += s * ddx + c * ddy
            th = wrap_scalar(th + ddth)
            dl_sum += dl
            dr_sum += dr
        out.v.append(v)
        out.omega.append(w)
        out.d_left.append(dl_sum)
        out.d_right.append(dr_sum)
        out.poses.append((x, y, th))
        if len(out.v) > max_commands:
            raise ConfigError(f"scan_grid: the tour did not finish within {max_commands} commands")

    def maybe_kidnap(goal: tuple[float, float]) -> None:
        nonlocal x, y, th, pending
        if pending is None or len(out.v) * COMMAND_S < pending[0] - 1e-9:
            return
        delta = pending[1](np.array([x, y, th]), goal)  # type: ignore[operator]
        if delta is None:
            return
        pending = None
        x, y, th = x + delta[0], y + delta[1], wrap_scalar(th + delta[2])
        out.poses[-1] = (x, y, th)
        out.kidnaps.append(Kidnap(t=len(out.v) * COMMAND_S, delta=(float(delta[0]), float(delta[1]), float(delta[2]))))

    for gx, gy, marked in tour:
        while True:
            maybe_kidnap((gx, gy))
            dist = math.hypot(gx - x, gy - y)
            if dist <= GOAL_TOL_M:
                break
            err = wrap_scalar(math.atan2(gy - y, gx - x) - th)
            w = max(-OMEGA_MAX_RADPS, min(OMEGA_MAX_RADPS, err / COMMAND_S))
            if mixed:
                v = min(v_max if abs(err) <= HEADING_TOL_RAD else 0.5 * v_max, dist / COMMAND_S)
                execute(v, w)
            elif abs(err) > HEADING_TOL_RAD:
                execute(0.0, w)
            else:
                execute(min(v_max, dist / COMMAND_S), 0.0)
        if marked:
            execute(0.0, 0.0)
            out.wp_t.append(len(out.v) * COMMAND_S)
            out.wp_xy.append((gx, gy))
            execute(0.0, 0.0)
    return out


class ScanGridScenario(SyntheticBuilder):
    """Report 004's experiment: 1 s translate-or-rotate commands in a room, a 360 deg laser, odometry with
    the commanded twist (see the module docstring)."""

    id: ClassVar[str] = "scan_grid"
    Params: ClassVar[type] = ScanGridParams
    version: ClassVar[int] = 1
    description: ClassVar[str] = "report 004's scan database at grid poses, translate-or-rotate commands of 1 s"

    def build(self, params: ScanGridParams, rng: np.random.Generator) -> Dataset:
        # long: one scenario's assembly (grid tour, kidnap, scans, dataset) in the order the streams are drawn
        streams = split_streams(rng)
        world = scan_grid_world()
        v_max = params.grid_step_m / COMMAND_S
        kidnap = None
        if params.kidnap_m > 0:
            # At half of a kidnap-free tour (driven with fixed slip draws, so the time depends on the params only).
            probe = drive_commands(
                SCAN_GRID_START, SCAN_GRID_TOUR, v_max, params.mixed_commands, np.random.default_rng(0)
            )
            t_k = math.floor(0.5 * len(probe.v)) * COMMAND_S
            kidnap = (t_k, kidnap_chooser(world, params.kidnap_m, params.kidnap_rad, 0.4, streams["kidnap"]))
        slip_rng, encoder_rng = streams["odometry"].spawn(2)
        b_true = true_wheelbase(params.matched)
        cmds = drive_commands(
            SCAN_GRID_START, SCAN_GRID_TOUR, v_max, params.mixed_commands, slip_rng, kidnap=kidnap, wheelbase_m=b_true
        )
        if params.kidnap_m > 0 and not cmds.kidnaps:
            raise ConfigError(
                f"kidnap_m={params.kidnap_m}: no free landing that far was found; expected a smaller kidnap distance"
            )
        poses = np.asarray(cmds.poses, dtype=np.float64)
        n = len(cmds.v)
        t = np.arange(n + 1, dtype=np.float64) * COMMAND_S
        # Encoders: measured = true x (1 + scale) + k sqrt|d| noise (report 003 eq. 10), nominal wheelbase.
        enc = encoder_model(params.matched)
        d_left, d_right = np.asarray(cmds.d_left), np.asarray(cmds.d_right)
        zo = encoder_rng.standard_normal((n, 2))
        ml = d_left * (1.0 + enc.scale_left) + enc.k_left * np.sqrt(np.abs(d_left)) * zo[:, 0]
        mr = d_right * (1.0 + enc.scale_right) + enc.k_right * np.sqrt(np.abs(d_right)) * zo[:, 1]
        inc = odometry_increments(ml, mr, WHEELBASE_NOMINAL_M)
        events: list[Event] = [
            Odometry(
                t=float(t[k + 1]),
                dx=float(inc[k, 0]),
                dy=float(inc[k, 1]),
                dtheta=float(inc[k, 2]),
                d_left=float(ml[k]),
                d_right=float(mr[k]),
                v=float(cmds.v[k]),
                omega=float(cmds.omega[k]),
                dt=COMMAND_S,
            )
            for k in range(n)
        ]
        laser = SCAN_GRID_LASER
        world_map = world.world_map(0.05)
        grid = world_map.occupancy
        assert grid is not None
        true_r = cast_rays(
            grid.occupied(), grid.resolution, grid.origin[:2], poses, laser.angles(), laser.max_range_m, method="dda"
        )
        zl = streams["laser"].standard_normal(true_r.shape)
        ul = streams["laser"].random(true_r.shape)
        with np.errstate(invalid="ignore"):
            r = true_r + laser.sigma_m * zl
        r[(ul < laser.dropout_prob) | (r > laser.max_range_m) | (r < laser.min_range_m)] = np.inf
        events += [
            LaserScan(
                t=float(t[k]),
                angle_min=laser.angle_min,
                angle_increment=laser.angle_increment,
                ranges=r[k].copy(),
                range_min=laser.min_range_m,
                range_max=laser.max_range_m,
            )
            for k in range(n + 1)
        ]
        spec = nominal_sensor_spec(params.matched, laser=laser)
        initial_sigma = (0.02, 0.02, math.radians(1.0))
        start = poses[0].copy()
        if params.matched:
            start = matched_initial_mean(start, initial_sigma, matched_stream(rng))
        path = float(np.sum(np.hypot(*np.diff(poses[:, 0:2], axis=0).T)))
        ds = Dataset(
            id="scan_grid",
            params=params_to_dict(params),
            events=sort_events(events),
            ground_truth=Trajectory2D(t=t, xy=poses[:, 0:2].copy(), theta=wrap_angle(poses[:, 2])),
            initial=Gaussian2(
                mean=start,
                cov=np.diag(np.square(initial_sigma)),
            ),
            world=world_map,
            sensors=spec,
            waypoints=Waypoints(
                t=np.asarray(cmds.wp_t, dtype=np.float64), xy=np.asarray(cmds.wp_xy, dtype=np.float64).reshape(-1, 2)
            ),
            kidnaps=tuple(cmds.kidnaps),
            name="scan_grid",
            metadata={
                "generator_version": GENERATOR_VERSION,
                "world": world.name,
                "duration_s": float(t[-1]),
                "path_length_m": path,
                "commands": n,
                "mixed_commands_fraction": float(
                    np.mean((np.abs(cmds.v) > 0) & (np.abs(cmds.omega) > 0)) if n else 0.0
                ),
                "odometry_rate_hz": 1.0 / COMMAND_S,
                "grid_step_m": params.grid_step_m,
                "true_odometry_error": {**dataclasses.asdict(enc), "wheelbase_true_m": b_true},
                "matched": params.matched,
            },
            declared=frozenset({LaserScan}),
        )
        ds.check()
        return ds
