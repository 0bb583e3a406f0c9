"""The named synthetic scenarios: ``room`` (report 003), ``office``, ``tiny_line`` and ``tiny_circle``.

Each scenario is a :class:`~locbench.datasets.base.DatasetBuilder` whose ``build(params, rng)`` depends
only on its arguments. The generator is split into one child stream per noise source (odometry,
landmarks, laser, fixes, kidnap), so that e.g. ``laser_beams`` or ``known_ids`` does not change the
odometry realisation of a seed.

Every scenario's robot is the same H20-like differential drive with the same wheel-odometry error
(calibrated on the room by ``tools/calibrate_odometry.py``) and the same execution noise between its
commanded twist and its true motion (wheel slip, :data:`SLIP_K_TRUE`, see
:mod:`locbench.datasets.synthetic.robot`), drawn from its own child stream (:func:`execution_stream`,
spawned after every other stream so that those are unchanged by it); the tiny scenarios can switch all
noise off.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from locbench.datasets.base import (
    Dataset,
    DatasetBuilder,
    Gaussian2,
    SensorSpec,
    SyntheticBuilder,
    Trajectory2D,
    Waypoints,
    sort_events,
)
from locbench.datasets.synthetic.robot import Arc, DriveLimits, GoTo, KidnapChooser, Leg, Motion, simulate_route
from locbench.datasets.synthetic.sensors import (
    EncoderModel,
    LandmarkSensor,
    LaserSensor,
    PoseFixSensor,
    landmark_observations,
    laser_scans,
    pose_fixes,
    wheel_odometry,
)
from locbench.datasets.synthetic.world import World, wall_with_doors
from locbench.errors import ConfigError
from locbench.events import Event, LandmarkObservations, LaserScan, PoseFix
from locbench.limits import check_beams
from locbench.runkey import RUN_KEY_OMIT_IF_DEFAULT
from locbench.spec import params_to_dict

logger = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]

#: Recorded in every dataset's metadata; bump with any change of the generated data.
#: 2: execution noise (wheel slip) between the commanded twist and the true motion; re-fitted calibration.
GENERATOR_VERSION = 2

# --- the robot's wheel-odometry error (calibrated on the room, shared by every scenario) -----------------

#: Nominal wheelbase the odometry computes with (report 003 eq. 1), m.
WHEELBASE_NOMINAL_M = 0.40
#: Random encoder error constants k_L = k_R of report 003 eq. 10 (chosen, not fitted), sqrt(m).
ENCODER_K_TRUE = 0.002
# Systematic errors fitted by calibrate_room_odometry() (tools/calibrate_odometry.py) on 2026-11-22: scipy
# least_squares on the log ratio
# (measured / 003 table 1) at the 5 waypoints, measured as table 1 does (distance between each waypoint
# and the mean over seeds 0..19 of the dead-reckoned position at the waypoint time), k fixed at
# ENCODER_K_TRUE, starting from zero error; fitted for exact execution (generator version 1). Kept for
# version 2 (execution noise, SLIP_K_TRUE) because the calibration still holds: room_dead_reckoning_errors()
# gives ROOM_CALIBRATION_ACHIEVED_CM, ratios 0.83-1.24 to table 1 (re-running calibrate_room_odometry() on
# version 2 moves the constants in the fourth digit, to -0.026114, -0.019487, 0.948018, and the achieved
# errors by < 0.05 cm; the shared constants also drive scan_grid, whose data they would change).
#: Relative travel error of the left wheel (wheel-diameter mismatch): measured = true x (1 + scale).
ENCODER_SCALE_LEFT = -0.02603665815749769
#: Relative travel error of the right wheel.
ENCODER_SCALE_RIGHT = -0.019413738308876265
#: True wheelbase / nominal wheelbase (the true wheels stand 5 % closer than the odometry assumes).
WHEELBASE_TRUE_RATIO = 0.9481160253691738
#: Table 1 of report 003, odometry row (cm).
ROOM_TABLE1_ODOMETRY_CM = (7.3634, 5.6828, 18.6643, 34.9313, 60.7425)
#: What the frozen constants give over seeds 0..19 (cm), recorded with room_dead_reckoning_errors() for generator
#: version 2 (version 1, exact execution, as calibrate_room_odometry() recorded it: 6.555, 6.020, 23.203, 28.954,
#: 62.779).
ROOM_CALIBRATION_ACHIEVED_CM: tuple[float, ...] = (6.538, 6.016, 23.178, 28.940, 62.646)

#: Execution noise of the shared robot, sqrt(m): each wheel's true travel in a step is the commanded travel c
#: plus a zero-mean error of variance SLIP_K_TRUE^2 |c| (wheel slip and speed-servo tracking error, the form of
#: report 003 eq. 10). Assumed, not fitted: the value ``scan_grid`` uses for its slip, so every world's robot
#: executes its commands the same way; it equals the random encoder constant and is small against the
#: systematic odometry error (on ``room``, seeds 0-9, dead reckoning the commanded twist has an ATE of about
#: 4 cm and ends 1-15 cm off; the odometry has an ATE of about 29 cm and ends about 60 cm off).
SLIP_K_TRUE = ENCODER_K_TRUE

#: Nominal k handed to filters, sqrt(m): larger than the true random k so that it also covers the
#: systematic error a filter does not model.
ENCODER_K_NOMINAL = 0.01


def robot_encoder_model(noise_free: bool = False) -> EncoderModel:
    """The shared robot's odometry error (all zero when ``noise_free``)."""
    if noise_free:
        return EncoderModel(wheelbase_nominal_m=WHEELBASE_NOMINAL_M)
    return EncoderModel(
        wheelbase_nominal_m=WHEELBASE_NOMINAL_M,
        scale_left=ENCODER_SCALE_LEFT,
        scale_right=ENCODER_SCALE_RIGHT,
        k_left=ENCODER_K_TRUE,
        k_right=ENCODER_K_TRUE,
    )


def matched_encoder_model(k: float = ENCODER_K_NOMINAL) -> EncoderModel:
    """The odometry error of a model-matched world: no systematic error, random constant ``k`` (sqrt(m)) on
    both wheels, the value :func:`nominal_odometry_spec` hands to the filters."""
    return EncoderModel(wheelbase_nominal_m=WHEELBASE_NOMINAL_M, k_left=k, k_right=k)


def matched_initial_mean(
    start: Sequence[float], initial_sigma: tuple[float, float, float], rng: np.random.Generator
) -> FloatArray:
    """Initial belief mean of a model-matched world: the true start plus a draw from the initial belief
    N(0, diag(initial_sigma^2)) (m, m, rad), so that the initial error is what the belief says."""
    z = rng.standard_normal(3)
    return np.asarray(start, dtype=np.float64)[:3] + np.asarray(initial_sigma) * z


def matched_stream(rng: np.random.Generator) -> np.random.Generator:
    """The child generator of a model-matched world's initial draw, spawned after every other stream (only
    when ``matched``, so that the default realisation is unchanged)."""
    return rng.spawn(1)[0]


def matched_process_noise(matched: bool) -> dict[str, float]:
    """SensorSpec process-noise fields of a world: zero on a model-matched one, whose true motion is exactly
    the odometry model (no unmodelled motion for report 003's Q, eq. 8, to cover); none on the others (the
    filters keep their default Q)."""
    return {"process_sigma_xy_m": 0.0, "process_sigma_theta_rad": 0.0} if matched else {}


def encoder_model(matched: bool) -> EncoderModel:
    """The shared robot's odometry error, or a model-matched world's (:func:`matched_encoder_model`)."""
    return matched_encoder_model() if matched else robot_encoder_model()


def true_wheelbase(noise_free: bool = False) -> float:
    """The robot's true wheelbase, m (the nominal one when ``noise_free`` or in a model-matched world)."""
    return WHEELBASE_NOMINAL_M if noise_free else WHEELBASE_NOMINAL_M * WHEELBASE_TRUE_RATIO


def nominal_odometry_spec(k: float = ENCODER_K_NOMINAL, wheelbase_m: float = WHEELBASE_NOMINAL_M) -> dict[str, float]:
    """SensorSpec odometry fields consistent with encoder constant ``k`` (report 003 eq. 10).

    With var(d_L) = var(d_R) = k^2 |d|: a straight step of length s has var(dd) = k^2 s / 2 and
    var(dtheta) = 2 k^2 s / W^2; a turn on the spot by a has var(dtheta) = k^2 |a| / W.
    """
    return {
        "wheelbase_m": wheelbase_m,
        "encoder_k_left": k,
        "encoder_k_right": k,
        "odometry_sigma_xy_per_m": k / math.sqrt(2.0),
        "odometry_sigma_theta_per_m": k * math.sqrt(2.0) / wheelbase_m,
        "odometry_sigma_theta_per_rad": k / math.sqrt(wheelbase_m),
    }


# --- shared assembly ------------------------------------------------------------------------------------

STREAMS = ("odometry", "landmarks", "laser", "fixes", "kidnap")


def split_streams(rng: np.random.Generator) -> dict[str, np.random.Generator]:
    """One independent child generator per noise source, in a fixed order."""
    return dict(zip(STREAMS, rng.spawn(len(STREAMS)), strict=True))


def execution_stream(rng: np.random.Generator) -> np.random.Generator:
    """The child generator of the execution noise (wheel slip): the next child of ``rng``.

    Call it after every other spawn of the scenario (the streams of :func:`split_streams`, and any
    scenario-specific ones), so that adding it left every older stream, hence their draws, unchanged.
    """
    return rng.spawn(1)[0]


def execution_metadata(motion: Motion) -> dict[str, Any]:
    """The execution noise of ``motion`` as recorded in a dataset's metadata."""
    return {
        "model": (
            "per step and wheel: true travel = commanded travel c + slip_k sqrt(|c|) z, z ~ N(0, 1) (wheel slip "
            "and speed-servo tracking error); the planner steers on the true pose (locbench.datasets.synthetic.robot)"
        ),
        "slip_k_sqrt_m": motion.slip_k,
        "stream": "execution (the child spawned after every other stream)",
        "odometry_commands": "Odometry.v / omega / dt are the commanded twist, not the executed one",
    }


def kidnap_chooser(
    world: World, distance_m: float, rotation_rad: float, clearance_m: float, rng: np.random.Generator
) -> KidnapChooser:
    """A kidnap of ``distance_m`` in a random direction, landing in free space with a free path to the goal.

    The rotation is ``rotation_rad`` with a random sign. Each call draws the same number of numbers.
    """

    def choose(pose: FloatArray, goal: tuple[float, float] | None) -> tuple[float, float, float] | None:
        directions = rng.uniform(-math.pi, math.pi, 72)
        sign = 1.0 if rng.random() < 0.5 else -1.0
        for a in directions:
            d = (distance_m * math.cos(a), distance_m * math.sin(a))
            land = (pose[0] + d[0], pose[1] + d[1])
            if not world.is_free(np.asarray(land), clearance_m):
                continue
            if goal is not None and not world.path_is_free(land, goal, clearance_m):
                continue
            return (d[0], d[1], sign * rotation_rad)
        return None

    return choose


def drive(
    world: World,
    start: Sequence[float],
    legs: Sequence[Leg],
    limits: DriveLimits,
    kidnap_m: float,
    kidnap_rad: float,
    kidnap_fraction: float,
    rng: np.random.Generator,
    clearance_m: float = 0.3,
    slip_rng: np.random.Generator | None = None,
) -> Motion:
    """Simulate the route; with ``kidnap_m`` > 0 kidnap the robot at ``kidnap_fraction`` of the kidnap-free run.

    ``rng`` chooses the kidnap; ``slip_rng`` draws the execution noise, wheel slip of :data:`SLIP_K_TRUE` (see
    :func:`~locbench.datasets.synthetic.robot.simulate_route`; None: the commands are executed exactly). The
    kidnap time comes from a run without execution noise, so that it depends on the parameters only; before the
    kidnap the robot moves exactly as in the kidnap-free run of the same seed.
    """
    slip_k = SLIP_K_TRUE if slip_rng is not None else 0.0
    if kidnap_m <= 0:
        return simulate_route(start, legs, limits, slip_k=slip_k, slip_rng=slip_rng)
    probe = simulate_route(start, legs, limits)
    t_kidnap = round(kidnap_fraction * probe.duration / limits.dt_s) * limits.dt_s
    chooser = kidnap_chooser(world, kidnap_m, kidnap_rad, clearance_m, rng)
    motion = simulate_route(
        start, legs, limits, kidnap_t_s=t_kidnap, kidnap_chooser=chooser, slip_k=slip_k, slip_rng=slip_rng
    )
    if not motion.kidnaps:
        raise ConfigError(
            f"kidnap_m={kidnap_m}: no free landing {kidnap_m} m away was found after t={t_kidnap:.1f} s; "
            "expected a smaller kidnap distance"
        )
    return motion


@dataclass(frozen=True)
class SensorSuite:
    """Which sensors a scenario simulates (None = absent) and the odometry error."""

    encoder: EncoderModel
    landmarks: LandmarkSensor | None = None
    laser: LaserSensor | None = None
    fixes: PoseFixSensor | None = None


def assemble(
    *,
    dataset_id: str,
    params: Any,
    world: World,
    motion: Motion,
    suite: SensorSuite,
    streams: dict[str, np.random.Generator],
    spec: SensorSpec,
    initial_sigma: tuple[float, float, float],
    resolution_m: float = 0.05,
    metadata: dict[str, Any] | None = None,
    initial_rng: np.random.Generator | None = None,
) -> Dataset:
    """Turn a motion and a sensor suite into a checked :class:`Dataset`.

    With ``initial_rng`` (model-matched worlds) the initial belief's mean is drawn from the belief around the
    true start (:func:`matched_initial_mean`); otherwise it is the true start.
    """
    world_map = world.world_map(resolution_m)
    events: list[Event] = []
    events.extend(wheel_odometry(motion, suite.encoder, streams["odometry"]))
    if suite.landmarks is not None:
        events.extend(landmark_observations(motion, world, suite.landmarks, streams["landmarks"]))
    if suite.laser is not None:
        assert world_map.occupancy is not None
        events.extend(laser_scans(motion, world_map.occupancy, suite.laser, streams["laser"]))
    if suite.fixes is not None:
        events.extend(pose_fixes(motion, suite.fixes, streams["fixes"]))
    start = motion.poses[0]
    meta: dict[str, Any] = {
        "generator_version": GENERATOR_VERSION,
        "world": world.name,
        "duration_s": motion.duration,
        "path_length_m": float(np.sum(np.hypot(*np.diff(motion.poses[:, 0:2], axis=0).T))),
        "odometry_rate_hz": 1.0 / motion.dt,
        "true_odometry_error": {
            **dataclasses.asdict(suite.encoder),
            "wheelbase_true_m": motion.wheelbase_m,
        },
        "execution_noise": execution_metadata(motion),
        "matched": initial_rng is not None,
        "calibration": {
            "procedure": "tools/calibrate_odometry.py (calibrate_room_odometry)",
            "target_cm": list(ROOM_TABLE1_ODOMETRY_CM),
            "achieved_cm": list(ROOM_CALIBRATION_ACHIEVED_CM),
        },
        "sensors_true": {
            k: dataclasses.asdict(v)
            for k, v in (("landmarks", suite.landmarks), ("laser", suite.laser), ("fixes", suite.fixes))
            if v is not None
        },
    }
    meta.update(metadata or {})
    ds = Dataset(
        id=dataset_id,
        params=params_to_dict(params),
        events=sort_events(events),
        ground_truth=Trajectory2D(t=motion.t.copy(), xy=motion.poses[:, 0:2].copy(), theta=motion.poses[:, 2].copy()),
        initial=Gaussian2(
            mean=start.copy() if initial_rng is None else matched_initial_mean(start, initial_sigma, initial_rng),
            cov=np.diag(np.square(initial_sigma)),
        ),
        world=world_map,
        sensors=spec,
        waypoints=Waypoints(t=motion.waypoint_t.copy(), xy=motion.waypoint_xy.copy()),
        kidnaps=motion.kidnaps,
        name=dataset_id,
        metadata=meta,
        # the streams the world's sensors emit: the contract requires events of each
        declared=frozenset(
            kind
            for kind, sensor in (
                (LandmarkObservations, suite.landmarks),
                (LaserScan, suite.laser),
                (PoseFix, suite.fixes),
            )
            if sensor is not None
        ),
    )
    ds.check()
    return ds


def check_kidnap_params(kidnap_m: float, kidnap_rad: float) -> None:
    """ConfigError unless ``kidnap_m`` >= 0 m (finite) and |``kidnap_rad``| <= pi (shared by every scenario)."""
    if not (kidnap_m >= 0 and math.isfinite(kidnap_m)):
        raise ConfigError(f"parameter 'kidnap_m' must be a distance >= 0 m, got {kidnap_m}")
    if not (abs(kidnap_rad) <= math.pi):
        raise ConfigError(f"parameter 'kidnap_rad' must be a rotation in [-pi, pi] rad, got {kidnap_rad}")


def _check_beams(name: str, beams: int, allow_zero: bool) -> None:
    if beams < 0 or (beams < 2 and not (allow_zero and beams == 0)):
        expected = "0 (no laser) or >= 2" if allow_zero else ">= 2"
        raise ConfigError(f"parameter {name!r} must be {expected}, got {beams}")
    check_beams(name, beams)


# --- room (report 003) ----------------------------------------------------------------------------------

ROOM_START = (0.6, 1.0, 0.0)
#: The 5 marked waypoints (m), in visiting order.
ROOM_WAYPOINTS = ((2.0, 0.5), (3.5, 1.5), (5.0, 0.5), (6.4, 1.4), (3.0, 1.0))
ROOM_LIMITS = DriveLimits(
    dt_s=0.05, v_max_mps=0.25, accel_mps2=0.25, omega_max_radps=0.5, alpha_radps2=1.0, dwell_s=2.0, start_dwell_s=1.0
)


def room_world() -> World:
    """Report 003's 7 m x 2 m room with 4 landmarks mounted on the walls (3 cm in front of the wall line)."""
    corners = [(0.0, 0.0), (7.0, 0.0), (7.0, 2.0), (0.0, 2.0)]
    walls = [(*corners[k], *corners[(k + 1) % 4]) for k in range(4)]
    landmarks = [(6.97, 1.0), (0.03, 1.0), (2.5, 1.97), (4.5, 0.03)]
    return World(walls=np.array(walls), landmarks=np.array(landmarks), bounds=(0.0, 0.0, 7.0, 2.0), name="room")


def room_motion(noise_free: bool = False, seed: int | None = None) -> Motion:
    """The kidnap-free room tour; with a ``seed`` (and not ``noise_free``), with the execution noise of
    ``make_dataset("room", seed)``, else executed exactly."""
    ratio = 1.0 if noise_free else WHEELBASE_TRUE_RATIO
    return room_motion_for(ratio, None if noise_free else seed)


@dataclass(frozen=True, kw_only=True)
class RoomParams:
    """Parameters of ``room``.

    Attributes
    ----------
    known_ids : bool
        Landmark identities reported (True) or withheld.
    kidnap_m : float
        Kidnap distance at 60 % of the run, m (0 = no kidnap).
    kidnap_rad : float
        Kidnap rotation magnitude, rad (sign drawn at random).
    laser_beams : int
        0 = no laser (as in report 003); otherwise a 240 deg, 5.6 m laser with this many beams.
    matched : bool
        Model-matched world: the simulator's noise is the nominal noise handed to the filters (no systematic
        odometry error, encoder k at its nominal value, the initial belief's mean drawn from the belief).
    """

    known_ids: bool = True
    kidnap_m: float = 0.0
    kidnap_rad: float = 0.5
    laser_beams: int = 0
    matched: bool = field(default=False, metadata=RUN_KEY_OMIT_IF_DEFAULT)

    def __post_init__(self) -> None:
        # checked when the spec is parsed, so a bad value is a one-line error before anything runs
        check_kidnap_params(self.kidnap_m, self.kidnap_rad)
        _check_beams("laser_beams", self.laser_beams, allow_zero=True)


class RoomScenario(SyntheticBuilder):
    """Report 003's experiment: a 7 m x 2 m room, 4 landmarks, a start and 5 marked waypoints, a
    Kinect-like range-bearing sensor (0.8-3.5 m, 57 deg) and calibrated wheel-encoder odometry."""

    Params: ClassVar[type] = RoomParams
    version: ClassVar[int] = 2
    nominal_duration_s: ClassVar[float] = 60.0
    description: ClassVar[str] = "report 003's 7 m x 2 m room: 4 landmarks, start + 5 waypoints, Kinect-like sensor"

    #: Kinect-like detector: 0.8-3.5 m, 57 deg horizontal field of view, cm-level range noise (report 003 sec. 3).
    landmark_sensor = LandmarkSensor(
        rate_hz=5.0,
        min_range_m=0.8,
        max_range_m=3.5,
        fov_rad=math.radians(57.0),
        sigma_range_m=0.02,
        sigma_bearing_rad=math.radians(0.5),
        occlusion=True,
    )

    def build(self, params: RoomParams, rng: np.random.Generator) -> Dataset:
        streams = split_streams(rng)
        slip_rng = execution_stream(rng)
        initial_rng = matched_stream(rng) if params.matched else None
        world = room_world()
        limits = dataclasses.replace(ROOM_LIMITS, wheelbase_m=true_wheelbase(params.matched))
        legs = [GoTo(w) for w in ROOM_WAYPOINTS]
        motion = drive(
            world,
            ROOM_START,
            legs,
            limits,
            params.kidnap_m,
            params.kidnap_rad,
            0.6,
            streams["kidnap"],
            slip_rng=slip_rng,
        )
        lm = dataclasses.replace(self.landmark_sensor, known_ids=params.known_ids)
        laser = LaserSensor(beams=params.laser_beams) if params.laser_beams else None
        suite = SensorSuite(encoder=encoder_model(params.matched), landmarks=lm, laser=laser)
        spec = SensorSpec(
            **nominal_odometry_spec(),
            **matched_process_noise(params.matched),
            landmark_sigma_range_m=lm.sigma_range_m,
            landmark_sigma_bearing_rad=lm.sigma_bearing_rad,
            landmark_min_range_m=lm.min_range_m,
            landmark_max_range_m=lm.max_range_m,
            landmark_fov_rad=lm.fov_rad,
            laser_sigma_m=laser.sigma_m if laser else None,
        )
        return assemble(
            dataset_id="room",
            params=params,
            world=world,
            motion=motion,
            suite=suite,
            streams=streams,
            spec=spec,
            initial_sigma=(0.01, 0.01, math.radians(1.0)),
            initial_rng=initial_rng,
        )


def room_motion_for(wheelbase_ratio: float, seed: int | None = None) -> Motion:
    """The kidnap-free room tour with a given true / nominal wheelbase ratio; with a ``seed``, with the
    execution noise of ``make_dataset("room", seed)`` (its execution stream), else executed exactly."""
    limits = dataclasses.replace(ROOM_LIMITS, wheelbase_m=WHEELBASE_NOMINAL_M * wheelbase_ratio)
    legs = [GoTo(w) for w in ROOM_WAYPOINTS]
    if seed is None:
        return simulate_route(ROOM_START, legs, limits)
    from locbench.seeding import dataset_rng

    rng = dataset_rng("room", seed)
    split_streams(rng)
    return simulate_route(ROOM_START, legs, limits, slip_k=SLIP_K_TRUE, slip_rng=execution_stream(rng))


# --- office ---------------------------------------------------------------------------------------------

OFFICE_START = (1.0, 7.25, 0.0)
#: Corridor centre line, m.
_CY = 7.25


def office_world() -> World:
    """One 20 m x 15 m office floor: an east-west corridor (y 6-8.5 m) between three rooms to the south and
    three to the north, 1 m doors, a door between two south rooms, a few cabinets and 22 wall landmarks
    (5 cm in front of their wall, so a wall hides them from its other side)."""
    walls: list[tuple[float, float, float, float]] = []
    walls += wall_with_doors((0.0, 0.0), (20.0, 0.0))
    walls += wall_with_doors((20.0, 0.0), (20.0, 15.0))
    walls += wall_with_doors((20.0, 15.0), (0.0, 15.0))
    walls += wall_with_doors((0.0, 15.0), (0.0, 0.0))
    # corridor walls with one door per room (offsets from x = 0)
    walls += wall_with_doors((0.0, 6.0), (20.0, 6.0), [(3.5, 1.0), (10.5, 1.0), (17.0, 1.0)])
    walls += wall_with_doors((0.0, 8.5), (20.0, 8.5), [(3.0, 1.0), (9.5, 1.0), (17.0, 1.0)])
    # partitions; the one between the middle and east south rooms has a door
    walls += wall_with_doors((7.0, 0.0), (7.0, 6.0))
    walls += wall_with_doors((14.0, 0.0), (14.0, 6.0), [(1.5, 1.0)])
    walls += wall_with_doors((6.0, 8.5), (6.0, 15.0))
    walls += wall_with_doors((13.0, 8.5), (13.0, 15.0))

    def box(x0: float, y0: float, x1: float, y1: float) -> list[tuple[float, float, float, float]]:
        return [(x0, y0, x1, y0), (x1, y0, x1, y1), (x1, y1, x0, y1), (x0, y1, x0, y0)]

    walls += box(0.0, 4.0, 0.6, 5.0)  # cabinet, south-west room
    walls += box(18.0, 14.4, 19.5, 15.0)  # cabinet, north-east room
    walls += box(11.5, 3.0, 12.5, 3.6)  # table, south middle room
    walls += box(2.5, 12.5, 3.5, 13.3)  # table, north-west room
    landmarks = [
        # corridor
        (5.5, 6.05), (12.5, 8.45), (15.0, 6.05), (0.05, 7.25), (19.95, 7.25),
        # south rooms
        (0.05, 2.5), (3.5, 0.05), (6.95, 2.0),
        (7.05, 4.0), (10.5, 0.05), (13.95, 4.0),
        (14.05, 3.0), (17.0, 0.05), (19.95, 4.0),
        # north rooms
        (0.05, 11.0), (3.0, 14.95), (5.95, 10.5),
        (6.05, 12.0), (9.5, 14.95), (12.95, 11.0),
        (13.05, 13.0), (19.95, 11.0),
    ]  # fmt: skip
    return World(walls=np.array(walls), landmarks=np.array(landmarks), bounds=(0.0, 0.0, 20.0, 15.0), name="office")


def office_route() -> list[Leg]:
    """The tour: 9 marked waypoints in five rooms and the corridor, through the doors (unmarked via points)."""

    def via(x: float, y: float) -> GoTo:
        return GoTo((x, y), marked=False)

    return [
        via(3.5, _CY), via(3.5, 4.8),
        GoTo((1.8, 1.8)), GoTo((5.5, 1.5)),  # south-west room
        via(3.5, 4.8), via(3.5, _CY), via(9.5, _CY), via(9.5, 9.8),
        GoTo((8.0, 13.0)), GoTo((11.5, 12.0)),  # north-middle room
        via(9.5, 9.8), via(9.5, _CY),
        GoTo((13.5, _CY)),  # corridor
        via(17.0, _CY), via(17.0, 4.8),
        GoTo((18.5, 1.5)),  # south-east room
        via(15.0, 1.5), via(12.8, 1.5),
        GoTo((9.0, 1.2)),  # south-middle room, through the side door
        via(10.5, 4.8), via(10.5, _CY), via(17.0, _CY), via(17.0, 9.8),
        GoTo((16.0, 12.5)),  # north-east room
        via(17.0, 9.8), via(17.0, _CY),
        GoTo((6.5, _CY)),  # back along the corridor
    ]  # fmt: skip


OFFICE_LIMITS = DriveLimits(
    dt_s=0.05, v_max_mps=0.7, accel_mps2=0.5, omega_max_radps=1.2, alpha_radps2=2.0, dwell_s=2.0, start_dwell_s=1.0
)


@dataclass(frozen=True, kw_only=True)
class OfficeParams:
    """Parameters of ``office``.

    Attributes
    ----------
    known_ids : bool
        Landmark identities reported (True) or withheld.
    kidnap_m : float
        Kidnap distance at 50 % of the run, m (0 = no kidnap).
    kidnap_rad : float
        Kidnap rotation magnitude, rad (sign drawn at random).
    laser_beams : int
        Beams of the 240 deg, 5.6 m laser.
    pose_fix_sigma_m : float
        Standard deviation of the 1 Hz GPS-like fixes per axis, m.
    matched : bool
        Model-matched world (see ``RoomParams.matched``).
    """

    known_ids: bool = True
    kidnap_m: float = 0.0
    kidnap_rad: float = 0.5
    laser_beams: int = 181
    pose_fix_sigma_m: float = 0.7
    matched: bool = field(default=False, metadata=RUN_KEY_OMIT_IF_DEFAULT)

    def __post_init__(self) -> None:
        # checked when the spec is parsed, so a bad value is a one-line error before anything runs
        check_kidnap_params(self.kidnap_m, self.kidnap_rad)
        _check_beams("laser_beams", self.laser_beams, allow_zero=False)
        if not self.pose_fix_sigma_m > 0:
            raise ConfigError(f"parameter 'pose_fix_sigma_m' must be > 0 m, got {self.pose_fix_sigma_m}")


class OfficeScenario(SyntheticBuilder):
    """One office floor with walls, doors, 22 landmarks and a 9-waypoint tour; every sensor."""

    Params: ClassVar[type] = OfficeParams
    version: ClassVar[int] = 2
    nominal_duration_s: ClassVar[float] = 231.0
    description: ClassVar[str] = "one office floor with walls, doors, landmarks and a waypoint tour; every sensor"

    def build(self, params: OfficeParams, rng: np.random.Generator) -> Dataset:
        streams = split_streams(rng)
        slip_rng = execution_stream(rng)
        initial_rng = matched_stream(rng) if params.matched else None
        world = office_world()
        limits = dataclasses.replace(OFFICE_LIMITS, wheelbase_m=true_wheelbase(params.matched))
        motion = drive(
            world,
            OFFICE_START,
            office_route(),
            limits,
            params.kidnap_m,
            params.kidnap_rad,
            0.5,
            streams["kidnap"],
            slip_rng=slip_rng,
        )
        lm = LandmarkSensor(
            rate_hz=5.0,
            min_range_m=0.3,
            max_range_m=6.0,
            fov_rad=math.pi,
            sigma_range_m=0.03,
            sigma_bearing_rad=math.radians(1.0),
            known_ids=params.known_ids,
            occlusion=True,
        )
        laser = LaserSensor(
            rate_hz=10.0, beams=params.laser_beams, fov_rad=math.radians(240.0), max_range_m=5.6, sigma_m=0.01
        )
        fixes = PoseFixSensor(
            rate_hz=1.0, sigma_xy_m=params.pose_fix_sigma_m, reported_sigma_xy_m=params.pose_fix_sigma_m
        )
        suite = SensorSuite(encoder=encoder_model(params.matched), landmarks=lm, laser=laser, fixes=fixes)
        spec = SensorSpec(
            **nominal_odometry_spec(),
            **matched_process_noise(params.matched),
            landmark_sigma_range_m=lm.sigma_range_m,
            landmark_sigma_bearing_rad=lm.sigma_bearing_rad,
            landmark_min_range_m=lm.min_range_m,
            landmark_max_range_m=lm.max_range_m,
            landmark_fov_rad=lm.fov_rad,
            laser_sigma_m=laser.sigma_m,
            pose_fix_sigma_xy_m=fixes.reported_sigma_xy_m,
        )
        return assemble(
            dataset_id="office",
            params=params,
            world=world,
            motion=motion,
            suite=suite,
            streams=streams,
            spec=spec,
            initial_sigma=(0.02, 0.02, math.radians(1.0)),
            initial_rng=initial_rng,
        )


# --- tiny conformance scenarios -------------------------------------------------------------------------

TINY_LIMITS = DriveLimits(
    dt_s=0.05, v_max_mps=0.6, accel_mps2=0.4, omega_max_radps=0.8, alpha_radps2=1.5, dwell_s=2.0, start_dwell_s=1.0
)


@dataclass(frozen=True, kw_only=True)
class TinyParams:
    """Parameters of ``tiny_line`` and ``tiny_circle``.

    Attributes
    ----------
    noise_free : bool
        No odometry error of any kind, no execution noise (the commanded twist is the true motion), exact
        landmark, laser and fix measurements (the nominal noise handed to filters stays positive).
    known_ids : bool
        Landmark identities reported (True) or withheld.
    """

    noise_free: bool = False
    known_ids: bool = True


def _box_world(name: str, width: float, height: float, landmarks: list[tuple[float, float]]) -> World:
    c = [(0.0, 0.0), (width, 0.0), (width, height), (0.0, height)]
    walls = [(*c[k], *c[(k + 1) % 4]) for k in range(4)]
    return World(walls=np.array(walls), landmarks=np.array(landmarks), bounds=(0.0, 0.0, width, height), name=name)


class _TinyScenario(DatasetBuilder):
    """Shared build of the tiny scenarios: a box world, every sensor type, optionally noise-free."""

    Params: ClassVar[type] = TinyParams
    version: ClassVar[int] = 2
    dataset_id: ClassVar[str] = ""

    def world(self) -> World:
        raise NotImplementedError

    def route(self) -> tuple[tuple[float, float, float], list[Leg]]:
        raise NotImplementedError

    def build(self, params: TinyParams, rng: np.random.Generator) -> Dataset:
        streams = split_streams(rng)
        slip_rng = execution_stream(rng)
        world = self.world()
        start, legs = self.route()
        nf = params.noise_free
        limits = dataclasses.replace(TINY_LIMITS, wheelbase_m=true_wheelbase(nf))
        motion = simulate_route(start, legs, limits, slip_k=0.0 if nf else SLIP_K_TRUE, slip_rng=slip_rng)
        lm = LandmarkSensor(
            rate_hz=5.0,
            min_range_m=0.3,
            max_range_m=6.0,
            fov_rad=math.pi,
            sigma_range_m=0.0 if nf else 0.02,
            sigma_bearing_rad=0.0 if nf else math.radians(1.0),
            known_ids=params.known_ids,
            occlusion=True,
        )
        laser = LaserSensor(
            rate_hz=5.0,
            beams=31,
            fov_rad=math.radians(240.0),
            max_range_m=5.6,
            sigma_m=0.0 if nf else 0.01,
            dropout_prob=0.0 if nf else 0.01,
        )
        fixes = PoseFixSensor(rate_hz=1.0, sigma_xy_m=0.0 if nf else 0.5, reported_sigma_xy_m=0.5)
        suite = SensorSuite(encoder=robot_encoder_model(nf), landmarks=lm, laser=laser, fixes=fixes)
        # Nominal noise stays positive even when the data are exact, so filters remain well-posed.
        spec = SensorSpec(
            **nominal_odometry_spec(),
            landmark_sigma_range_m=0.02,
            landmark_sigma_bearing_rad=math.radians(1.0),
            landmark_min_range_m=lm.min_range_m,
            landmark_max_range_m=lm.max_range_m,
            landmark_fov_rad=lm.fov_rad,
            laser_sigma_m=0.01,
            pose_fix_sigma_xy_m=fixes.reported_sigma_xy_m,
        )
        return assemble(
            dataset_id=self.dataset_id,
            params=params,
            world=world,
            motion=motion,
            suite=suite,
            streams=streams,
            spec=spec,
            initial_sigma=(0.01, 0.01, math.radians(1.0)),
        )


class TinyLineScenario(_TinyScenario):
    """A short straight drive (two stops) past 3 landmarks in a 6 m x 4 m box; every sensor type."""

    dataset_id: ClassVar[str] = "tiny_line"
    description: ClassVar[str] = "a 10 s straight drive past 3 landmarks (conformance checks)"

    def world(self) -> World:
        return _box_world("tiny_line", 6.0, 4.0, [(2.0, 3.95), (4.0, 0.05), (5.95, 2.5)])

    def route(self) -> tuple[tuple[float, float, float], list[Leg]]:
        return (0.8, 2.0, 0.0), [GoTo((2.9, 2.0)), GoTo((5.0, 2.0))]


class TinyCircleScenario(_TinyScenario):
    """One counter-clockwise circle of radius 1.2 m in a 6 m x 6 m box with 4 landmarks; the heading
    crosses +-pi half way round."""

    dataset_id: ClassVar[str] = "tiny_circle"
    description: ClassVar[str] = "a circle whose heading crosses +-pi, 4 landmarks (conformance checks)"
    radius_m: ClassVar[float] = 1.2

    def world(self) -> World:
        return _box_world("tiny_circle", 6.0, 6.0, [(0.05, 3.0), (5.95, 3.0), (3.0, 0.05), (3.0, 5.95)])

    def route(self) -> tuple[tuple[float, float, float], list[Leg]]:
        r = self.radius_m
        return (3.0, 3.0 - r, 0.0), [Arc(length_m=2.0 * math.pi * r, curvature_1pm=1.0 / r)]
