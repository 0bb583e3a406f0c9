"""The synthetic toolkit every scenario builds on: the shared robot's odometry error, the seeded noise streams,
the drive with an optional kidnap, and the assembly of a motion and a sensor suite into a checked dataset; a world
whose robot drives a tour is built by :func:`tour_dataset` (or, with its own streams or robot, by
:func:`drive_and_assemble`).

Every scenario's robot is the same H20-like differential drive with the same wheel-odometry error
(calibrated on the room by :mod:`locbench.datasets.synthetic.odometry_calibration`) and the same execution
noise between its commanded twist and its true motion (wheel slip, :data:`SLIP_K_TRUE`, see
:mod:`locbench.datasets.synthetic.robot`), drawn from its own child stream (:func:`execution_stream`,
spawned after every other stream so that those are unchanged by it). The generator is split into one child
stream per noise source (odometry, landmarks, laser, fixes, kidnap), so that e.g. ``laser_beams`` or
``known_ids`` does not change the odometry realisation of a seed. The named scenarios are in
:mod:`locbench.datasets.synthetic.scenarios` and the report modules beside it.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from locbench.core.errors import ConfigError
from locbench.core.events import Event, LandmarkObservations, LaserScan, PoseFix
from locbench.core.limits import check_beams
from locbench.core.spec import bound, params_to_dict
from locbench.datasets.dataset import (
    Dataset,
    Gaussian2,
    SensorSpec,
    Trajectory2D,
    Waypoints,
    sort_events,
)
from locbench.datasets.synthetic.robot import DriveLimits, KidnapChooser, Leg, Motion, simulate_route
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
from locbench.datasets.synthetic.world import World

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
# Systematic errors fitted by calibrate_room_odometry() (odometry_calibration) on 2026-11-22: scipy
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
    # long: the dataset's fields (events, metadata, initial belief, declared streams) assembled in one place
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
            "procedure": "locbench.datasets.synthetic.odometry_calibration.calibrate_room_odometry",
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


def kidnap_distance(width_m: float, height_m: float) -> MappingProxyType[str, Any]:
    """Field metadata of a world's ``kidnap_m``: a distance in [0, the diagonal of its ``width_m`` x ``height_m``
    bounds] m, checked when the spec is parsed: no two poses of the world lie further apart. A distance inside
    the bound may still find no free landing; the build says so in one line."""
    return bound(0.0, math.hypot(width_m, height_m), unit="m", what="a kidnap distance")


def check_kidnap_params(kidnap_m: float, kidnap_rad: float) -> None:
    """ConfigError unless ``kidnap_m`` >= 0 m (finite) and |``kidnap_rad``| <= pi (shared by every scenario)."""
    if not (kidnap_m >= 0 and math.isfinite(kidnap_m)):
        raise ConfigError(f"parameter 'kidnap_m' must be a distance >= 0 m, got {kidnap_m}")
    if not (abs(kidnap_rad) <= math.pi):
        raise ConfigError(f"parameter 'kidnap_rad' must be a rotation in [-pi, pi] rad, got {kidnap_rad}")


def check_laser_beams(name: str, beams: int, allow_zero: bool) -> None:
    if beams < 0 or (beams < 2 and not (allow_zero and beams == 0)):
        expected = "0 (no laser) or >= 2" if allow_zero else ">= 2"
        raise ConfigError(f"parameter {name!r} must be {expected}, got {beams}")
    check_beams(name, beams)


@dataclass(frozen=True)
class ScenarioStreams:
    """The child streams of a scenario's generator, spawned in the order every scenario uses.

    Attributes
    ----------
    noise : dict
        One stream per noise source (:data:`STREAMS`).
    execution : Generator
        The execution noise (:func:`execution_stream`).
    initial : Generator or None
        The initial belief's draw on a model-matched world (:func:`matched_stream`), else None.
    """

    noise: dict[str, np.random.Generator]
    execution: np.random.Generator
    initial: np.random.Generator | None


def scenario_streams(rng: np.random.Generator, matched: bool) -> ScenarioStreams:
    """Spawn a scenario's streams from its generator: the noise sources, then the execution noise, then (matched
    worlds only) the initial belief's draw; a fixed order, so that a seed gives the same realisation."""
    noise = split_streams(rng)
    execution = execution_stream(rng)
    return ScenarioStreams(noise, execution, matched_stream(rng) if matched else None)


def nominal_sensor_spec(
    matched: bool,
    landmarks: LandmarkSensor | None = None,
    laser: LaserSensor | None = None,
    fixes: PoseFixSensor | None = None,
    **overrides: Any,
) -> SensorSpec:
    """The nominal noise handed to the filters: the shared odometry, the process noise of a matched or default
    world, the landmark sensor's and laser's own noise and limits and the fixes' reported sigma (``overrides``
    replace any of them, e.g. a nominal landmark noise other than the true one)."""
    fields: dict[str, Any] = {**nominal_odometry_spec(), **matched_process_noise(matched)}
    if landmarks is not None:
        fields.update(
            landmark_sigma_range_m=landmarks.sigma_range_m,
            landmark_sigma_bearing_rad=landmarks.sigma_bearing_rad,
            landmark_min_range_m=landmarks.min_range_m,
            landmark_max_range_m=landmarks.max_range_m,
            landmark_fov_rad=landmarks.fov_rad,
        )
    fields["laser_sigma_m"] = laser.sigma_m if laser is not None else None
    fields["pose_fix_sigma_xy_m"] = fixes.reported_sigma_xy_m if fixes is not None else None
    fields.update(overrides)
    return SensorSpec(**fields)


# --- a tour driven in a world ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Tour:
    """Where a scenario's robot starts and drives, and when a kidnap happens.

    Attributes
    ----------
    start : tuple of float
        True start pose (x m, y m, theta rad), world frame.
    legs : tuple of GoTo or Arc
        The route (:func:`~locbench.datasets.synthetic.robot.simulate_route`).
    limits : DriveLimits
        Speeds, accelerations, step and dwells; its wheelbase is replaced by the robot's true one when driven.
    initial_sigma : tuple of float
        Standard deviations of the initial belief around the start handed to the filters (m, m, rad).
    kidnap_fraction : float
        Time of a kidnap as a fraction of the kidnap-free run (:func:`drive`), when a kidnap distance is given.
    """

    start: tuple[float, float, float]
    legs: tuple[Leg, ...]
    limits: DriveLimits
    initial_sigma: tuple[float, float, float]
    kidnap_fraction: float = 0.5


class TourParams(Protocol):
    """The parameters every world that drives a tour with the shared robot has (room, office, line_room)."""

    @property
    def kidnap_m(self) -> float:
        """Kidnap distance, m (0 = no kidnap)."""

    @property
    def kidnap_rad(self) -> float:
        """Kidnap rotation magnitude, rad (sign drawn at random)."""

    @property
    def matched(self) -> bool:
        """Model-matched world (:func:`matched_encoder_model`, :func:`matched_initial_mean`)."""


def drive_and_assemble(
    *,
    dataset_id: str,
    params: Any,
    world: World,
    tour: Tour,
    streams: ScenarioStreams,
    suite: SensorSuite,
    spec: SensorSpec,
    wheelbase_m: float,
    kidnap: tuple[float, float] = (0.0, 0.0),
    slip: bool = True,
    resolution_m: float = 0.05,
    metadata: dict[str, Any] | None = None,
) -> tuple[Dataset, Motion]:
    """Drive ``tour`` in ``world`` and turn the motion and ``suite`` into a checked dataset (:func:`assemble`).

    Parameters
    ----------
    dataset_id : str
        The dataset's id.
    params : dataclass
        The scenario's parameters, recorded in the dataset.
    world : World
    tour : Tour
    streams : ScenarioStreams
        The scenario's child streams: ``noise["kidnap"]`` chooses a kidnap, ``execution`` draws the wheel slip,
        ``initial`` (model-matched worlds) the initial belief's mean.
    suite : SensorSuite
        The true odometry error and sensors.
    spec : SensorSpec
        The nominal noise handed to the filters.
    wheelbase_m : float
        The robot's true wheelbase, m.
    kidnap : tuple of float
        Kidnap distance (m, 0 = none) and rotation magnitude (rad), at ``tour.kidnap_fraction`` of the run.
    slip : bool
        Execute the commanded twist with the wheel slip of :data:`SLIP_K_TRUE`; False: exactly.
    resolution_m : float
        Cell side of the world's occupancy grid, m.
    metadata : dict or None
        Entries added to the dataset's metadata.

    Returns
    -------
    Dataset
    Motion
        The true motion (for events a scenario adds).
    """
    limits = dataclasses.replace(tour.limits, wheelbase_m=wheelbase_m)
    motion = drive(
        world,
        tour.start,
        tour.legs,
        limits,
        kidnap[0],
        kidnap[1],
        tour.kidnap_fraction,
        streams.noise["kidnap"],
        slip_rng=streams.execution if slip else None,
    )
    ds = assemble(
        dataset_id=dataset_id,
        params=params,
        world=world,
        motion=motion,
        suite=suite,
        streams=streams.noise,
        spec=spec,
        initial_sigma=tour.initial_sigma,
        resolution_m=resolution_m,
        metadata=metadata,
        initial_rng=streams.initial,
    )
    return ds, motion


def tour_dataset(
    dataset_id: str,
    params: TourParams,
    rng: np.random.Generator,
    world: World,
    tour: Tour,
    *,
    landmarks: LandmarkSensor | None = None,
    laser: LaserSensor | None = None,
    fixes: PoseFixSensor | None = None,
    resolution_m: float = 0.05,
) -> Dataset:
    """The dataset of a world whose shared robot drives ``tour`` with the given sensors: the scenario's streams
    (:func:`scenario_streams`), the robot of a default or model-matched world (its odometry error, true wheelbase and
    the filters' nominal noise), the kidnap of ``params``; see :func:`drive_and_assemble` for the rest."""
    streams = scenario_streams(rng, params.matched)
    ds, _ = drive_and_assemble(
        dataset_id=dataset_id,
        params=params,
        world=world,
        tour=tour,
        streams=streams,
        suite=SensorSuite(encoder=encoder_model(params.matched), landmarks=landmarks, laser=laser, fixes=fixes),
        spec=nominal_sensor_spec(params.matched, landmarks=landmarks, laser=laser, fixes=fixes),
        wheelbase_m=true_wheelbase(params.matched),
        kidnap=(params.kidnap_m, params.kidnap_rad),
        resolution_m=resolution_m,
    )
    return ds
