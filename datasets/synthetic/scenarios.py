"""The named synthetic scenarios: ``room`` (report 003), ``office``, ``tiny_line`` and ``tiny_circle``, built
with the shared toolkit (:mod:`locbench.datasets.synthetic.toolkit`).

Each scenario is a :class:`~locbench.datasets.dataset.DatasetBuilder` whose ``build(params, rng)`` depends
only on its arguments. The generator is split into one child stream per noise source (odometry,
landmarks, laser, fixes, kidnap), so that e.g. ``laser_beams`` or ``known_ids`` does not change the
odometry realisation of a seed.

Every scenario's robot is the same H20-like differential drive with the same wheel-odometry error
(calibrated on the room by :mod:`locbench.datasets.synthetic.odometry_calibration`) and the same execution
noise between its commanded twist and its true motion (wheel slip, :data:`SLIP_K_TRUE`, see
:mod:`locbench.datasets.synthetic.robot`), drawn from its own child stream (:func:`execution_stream`,
spawned after every other stream so that those are unchanged by it); the tiny scenarios can switch all
noise off.
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
from locbench.core.runkey import RUN_KEY_OMIT_IF_DEFAULT
from locbench.core.spec import bound
from locbench.datasets.dataset import BELIEF_ONLY, Dataset, DatasetBuilder, Gaussian2, SyntheticBuilder
from locbench.datasets.synthetic.robot import Arc, DriveLimits, GoTo, Leg, Motion, simulate_route
from locbench.datasets.synthetic.sensors import LandmarkSensor, LaserSensor, PoseFixSensor
from locbench.datasets.synthetic.toolkit import (
    SLIP_K_TRUE,
    WHEELBASE_NOMINAL_M,
    WHEELBASE_TRUE_RATIO,
    SensorSuite,
    Tour,
    check_kidnap_params,
    check_laser_beams,
    drive_and_assemble,
    execution_stream,
    kidnap_distance,
    nominal_sensor_spec,
    robot_encoder_model,
    scenario_streams,
    split_streams,
    tour_dataset,
    true_wheelbase,
)
from locbench.datasets.synthetic.world import World, wall_with_doors

logger = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]

# --- room (report 003) ----------------------------------------------------------------------------------

ROOM_START = (0.6, 1.0, 0.0)
#: The 5 marked waypoints (m), in visiting order.
ROOM_WAYPOINTS = ((2.0, 0.5), (3.5, 1.5), (5.0, 0.5), (6.4, 1.4), (3.0, 1.0))
ROOM_LIMITS = DriveLimits(
    dt_s=0.05, v_max_mps=0.25, accel_mps2=0.25, omega_max_radps=0.5, alpha_radps2=1.0, dwell_s=2.0, start_dwell_s=1.0
)
#: The room tour: the start, the 5 waypoints, a kidnap at 60 % of the run.
ROOM_TOUR = Tour(
    ROOM_START,
    tuple(GoTo(w) for w in ROOM_WAYPOINTS),
    ROOM_LIMITS,
    (0.01, 0.01, math.radians(1.0)),
    kidnap_fraction=0.6,
)


#: Field metadata of ``initial_heading_error_deg``: 0 to 180 deg, omitted from the run key at 0 (the default world);
#: it turns only the initial belief, so every error of a seed is the plain world's realisation of that seed.
HEADING_ERROR = bound(0.0, 180.0, unit="deg", what="a heading error", base={**RUN_KEY_OMIT_IF_DEFAULT, **BELIEF_ONLY})


def with_heading_error(ds: Dataset, error_deg: float) -> Dataset:
    """``ds`` with its initial belief's heading turned by ``error_deg`` (deg, counter-clockwise) and its heading
    standard deviation set to that error, so the belief covers the error it starts with (UKF-M's 2-D benchmark
    protocol, Brossard, Barrau and Bonnabel 2020); ``ds`` itself at 0. Only the belief handed to the filters
    changes: the truth, the events and every noise stream are those of the world without the error."""
    if error_deg == 0.0:
        return ds
    e = math.radians(error_deg)
    mean = ds.initial.mean.copy()
    mean[2] = math.remainder(mean[2] + e, 2.0 * math.pi)
    cov = ds.initial.cov.copy()
    cov[2, :] = 0.0
    cov[:, 2] = 0.0
    cov[2, 2] = e * e
    return dataclasses.replace(ds, initial=Gaussian2(mean=mean, cov=cov))


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
    initial_heading_error_deg : float
        Heading error of the initial belief, deg (:func:`with_heading_error`).
    """

    known_ids: bool = True
    kidnap_m: float = field(default=0.0, metadata=kidnap_distance(7.0, 2.0))
    kidnap_rad: float = 0.5
    laser_beams: int = 0
    matched: bool = field(default=False, metadata=RUN_KEY_OMIT_IF_DEFAULT)
    initial_heading_error_deg: float = field(default=0.0, metadata=HEADING_ERROR)

    def __post_init__(self) -> None:
        # checked when the spec is parsed, so a bad value is a one-line error before anything runs
        check_kidnap_params(self.kidnap_m, self.kidnap_rad)
        check_laser_beams("laser_beams", self.laser_beams, allow_zero=True)


class RoomScenario(SyntheticBuilder):
    """Report 003's experiment: a 7 m x 2 m room, 4 landmarks, a start and 5 marked waypoints, a
    Kinect-like range-bearing sensor (0.8-3.5 m, 57 deg) and calibrated wheel-encoder odometry."""

    id: ClassVar[str] = "room"
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
        lm = dataclasses.replace(self.landmark_sensor, known_ids=params.known_ids)
        laser = LaserSensor(beams=params.laser_beams) if params.laser_beams else None
        ds = tour_dataset("room", params, rng, room_world(), ROOM_TOUR, landmarks=lm, laser=laser)
        return with_heading_error(ds, params.initial_heading_error_deg)


def room_motion_for(wheelbase_ratio: float, seed: int | None = None) -> Motion:
    """The kidnap-free room tour with a given true / nominal wheelbase ratio; with a ``seed``, with the
    execution noise of ``make_dataset("room", seed)`` (its execution stream), else executed exactly."""
    limits = dataclasses.replace(ROOM_TOUR.limits, wheelbase_m=WHEELBASE_NOMINAL_M * wheelbase_ratio)
    if seed is None:
        return simulate_route(ROOM_TOUR.start, ROOM_TOUR.legs, limits)
    from locbench.core.seeding import dataset_rng

    rng = dataset_rng("room", seed)
    split_streams(rng)
    return simulate_route(ROOM_TOUR.start, ROOM_TOUR.legs, limits, slip_k=SLIP_K_TRUE, slip_rng=execution_stream(rng))


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
#: The office tour, a kidnap at 50 % of the run.
OFFICE_TOUR = Tour(OFFICE_START, tuple(office_route()), OFFICE_LIMITS, (0.02, 0.02, math.radians(1.0)))


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
    initial_heading_error_deg : float
        Heading error of the initial belief, deg (:func:`with_heading_error`).
    """

    known_ids: bool = True
    kidnap_m: float = field(default=0.0, metadata=kidnap_distance(20.0, 15.0))
    kidnap_rad: float = 0.5
    laser_beams: int = 181
    pose_fix_sigma_m: float = 0.7
    matched: bool = field(default=False, metadata=RUN_KEY_OMIT_IF_DEFAULT)
    initial_heading_error_deg: float = field(default=0.0, metadata=HEADING_ERROR)

    def __post_init__(self) -> None:
        # checked when the spec is parsed, so a bad value is a one-line error before anything runs
        check_kidnap_params(self.kidnap_m, self.kidnap_rad)
        check_laser_beams("laser_beams", self.laser_beams, allow_zero=False)
        if not self.pose_fix_sigma_m > 0:
            raise ConfigError(f"parameter 'pose_fix_sigma_m' must be > 0 m, got {self.pose_fix_sigma_m}")


class OfficeScenario(SyntheticBuilder):
    """One office floor with walls, doors, 22 landmarks and a 9-waypoint tour; every sensor."""

    id: ClassVar[str] = "office"
    Params: ClassVar[type] = OfficeParams
    version: ClassVar[int] = 2
    nominal_duration_s: ClassVar[float] = 231.0
    description: ClassVar[str] = "one office floor with walls, doors, landmarks and a waypoint tour; every sensor"

    def build(self, params: OfficeParams, rng: np.random.Generator) -> Dataset:
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
        world = office_world()
        ds = tour_dataset("office", params, rng, world, OFFICE_TOUR, landmarks=lm, laser=laser, fixes=fixes)
        return with_heading_error(ds, params.initial_heading_error_deg)


# --- tiny conformance scenarios -------------------------------------------------------------------------

TINY_LIMITS = DriveLimits(
    dt_s=0.05, v_max_mps=0.6, accel_mps2=0.4, omega_max_radps=0.8, alpha_radps2=1.5, dwell_s=2.0, start_dwell_s=1.0
)
#: Standard deviations of the tiny scenarios' initial belief (m, m, rad).
TINY_INITIAL_SIGMA = (0.01, 0.01, math.radians(1.0))


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

    def world(self) -> World:
        raise NotImplementedError

    def tour(self) -> Tour:
        raise NotImplementedError

    def build(self, params: TinyParams, rng: np.random.Generator) -> Dataset:
        streams = scenario_streams(rng, matched=False)
        nf = params.noise_free
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
        # Nominal noise stays positive even when the data are exact, so filters remain well-posed.
        spec = nominal_sensor_spec(
            False,
            landmarks=lm,
            laser=laser,
            fixes=fixes,
            landmark_sigma_range_m=0.02,
            landmark_sigma_bearing_rad=math.radians(1.0),
            laser_sigma_m=0.01,
        )
        ds, _ = drive_and_assemble(
            dataset_id=self.id,
            params=params,
            world=self.world(),
            tour=self.tour(),
            streams=streams,
            suite=SensorSuite(encoder=robot_encoder_model(nf), landmarks=lm, laser=laser, fixes=fixes),
            spec=spec,
            wheelbase_m=true_wheelbase(nf),
            slip=not nf,
        )
        return ds


class TinyLineScenario(_TinyScenario):
    """A short straight drive (two stops) past 3 landmarks in a 6 m x 4 m box; every sensor type."""

    id: ClassVar[str] = "tiny_line"
    description: ClassVar[str] = "a 10 s straight drive past 3 landmarks (conformance checks)"

    def world(self) -> World:
        return _box_world("tiny_line", 6.0, 4.0, [(2.0, 3.95), (4.0, 0.05), (5.95, 2.5)])

    def tour(self) -> Tour:
        return Tour((0.8, 2.0, 0.0), (GoTo((2.9, 2.0)), GoTo((5.0, 2.0))), TINY_LIMITS, TINY_INITIAL_SIGMA)


class TinyCircleScenario(_TinyScenario):
    """One counter-clockwise circle of radius 1.2 m in a 6 m x 6 m box with 4 landmarks; the heading
    crosses +-pi half way round."""

    id: ClassVar[str] = "tiny_circle"
    description: ClassVar[str] = "a circle whose heading crosses +-pi, 4 landmarks (conformance checks)"
    radius_m: ClassVar[float] = 1.2

    def world(self) -> World:
        return _box_world("tiny_circle", 6.0, 6.0, [(0.05, 3.0), (5.95, 3.0), (3.0, 0.05), (3.0, 5.95)])

    def tour(self) -> Tour:
        r = self.radius_m
        legs = (Arc(length_m=2.0 * math.pi * r, curvature_1pm=1.0 / r),)
        return Tour((3.0, 3.0 - r, 0.0), legs, TINY_LIMITS, TINY_INITIAL_SIGMA)
