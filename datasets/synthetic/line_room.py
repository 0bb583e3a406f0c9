"""``line_room``: report 002's experiment, a robot localizing with laser lines in polygonal rooms.

Report 002 (Peng, "EKF map based localization") localizes a laser robot against a map of wall lines in a
simulated polygonal environment and observes that a larger chi-square gate helps "because our observations
are accurate", and that rejecting observed lines longer than their map line helps slightly "because the map
is not ambiguous". Its map and route are not given; this scenario is a documented stand-in:

* two rooms (11 m x 6.5 m in all) with slanted outer walls (not aligned with the axes, so that the lines'
  normals take many directions), a partition wall with a 1 m door, a 0.4 m square pillar in the west room
  (short map lines parallel to the long walls, the situation the length check is for) and a 0.8 m wall stub
  in the east room;
* a route from the west room through the door to three waypoints in the east room and back, 7 marked
  waypoints in all;
* the shared robot, its calibrated wheel-odometry error (:func:`robot_encoder_model`) and its execution
  noise (wheel slip ``SLIP_K_TRUE`` between the commanded twist and the true motion, own stream);
* a 240 deg laser (5 Hz, 5.6 m, ``laser_beams`` beams, range noise ``laser_sigma_m``) ray-cast on a 0.02 m
  occupancy grid of the walls: finer than the 0.05 m of the other scenarios so that the raster (walls seen
  up to a cell in front of their line) stays below the laser's own noise and ``laser_sigma_m`` really sets
  how accurate the observations are. The line map handed to filters holds the wall segments themselves.

The nominal noise handed to filters is the true laser noise and the shared nominal odometry noise.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from locbench.core.errors import ConfigError
from locbench.core.limits import check_beams
from locbench.core.runkey import RUN_KEY_OMIT_IF_DEFAULT
from locbench.datasets.dataset import Dataset, SyntheticBuilder
from locbench.datasets.synthetic.robot import DriveLimits, GoTo, Leg
from locbench.datasets.synthetic.sensors import LaserSensor
from locbench.datasets.synthetic.toolkit import Tour, check_kidnap_params, kidnap_distance, tour_dataset
from locbench.datasets.synthetic.world import World, wall_with_doors

logger = logging.getLogger(__name__)

#: Start pose (x m, y m, theta rad) in the west room.
LINE_ROOM_START = (1.0, 1.0, 0.0)
#: Grid resolution of the ray-cast laser and of the occupancy map, m.
LINE_ROOM_RESOLUTION_M = 0.02
LINE_ROOM_LIMITS = DriveLimits(
    dt_s=0.05, v_max_mps=0.4, accel_mps2=0.4, omega_max_radps=0.8, alpha_radps2=1.5, dwell_s=2.0, start_dwell_s=1.0
)
# y of the top wall (4, 6.5) -> (10, 6) at the partition x = 5
_TOP_AT_5 = 6.5 - 0.5 / 6.0


def line_room_world() -> World:
    """Two polygonal rooms with slanted walls, a partition with a door, a pillar and a wall stub."""
    outer = [(0.0, 0.0), (10.0, 0.0), (11.0, 3.0), (10.0, 6.0), (4.0, 6.5), (0.0, 5.0)]
    walls: list[tuple[float, float, float, float]] = [
        (*outer[k], *outer[(k + 1) % len(outer)]) for k in range(len(outer))
    ]
    walls += wall_with_doors((5.0, 0.0), (5.0, _TOP_AT_5), [(3.0, 1.0)])  # door y 2.5-3.5
    x0, y0, x1, y1 = 3.0, 2.8, 3.4, 3.2  # pillar, west room
    walls += [(x0, y0, x1, y0), (x1, y0, x1, y1), (x1, y1, x0, y1), (x0, y1, x0, y0)]
    walls.append((7.5, 3.5, 8.3, 3.5))  # wall stub, east room
    return World(walls=np.array(walls), landmarks=np.zeros((0, 2)), bounds=(0.0, 0.0, 11.0, 6.5), name="line_room")


def line_room_route() -> list[Leg]:
    """West room (3 waypoints), through the door, east room (3), back through the door (1)."""
    west, east = GoTo((4.3, 3.0), marked=False), GoTo((5.7, 3.0), marked=False)  # straight through the door
    return [
        GoTo((3.5, 1.2)),
        GoTo((1.2, 4.0)),
        GoTo((4.0, 4.5)),
        west,
        east,
        GoTo((8.5, 1.5)),
        GoTo((9.8, 3.0)),
        GoTo((7.0, 5.0)),
        east,
        west,
        GoTo((2.0, 1.5)),
    ]


#: The line_room tour, a kidnap at 50 % of the run.
LINE_ROOM_TOUR = Tour(LINE_ROOM_START, tuple(line_room_route()), LINE_ROOM_LIMITS, (0.02, 0.02, math.radians(1.0)))


@dataclass(frozen=True, kw_only=True)
class LineRoomParams:
    """Parameters of ``line_room``.

    Attributes
    ----------
    laser_sigma_m : float
        Range noise of the laser, m (> 0); also the nominal value handed to filters. 0.01 (Hokuyo-like)
        is "accurate observations"; e.g. 0.05 makes them noisy.
    laser_beams : int
        Beams of the 240 deg laser (>= 2).
    kidnap_m : float
        Kidnap distance at 50 % of the run, m (0 = no kidnap).
    kidnap_rad : float
        Kidnap rotation magnitude, rad (sign drawn at random).
    matched : bool
        Model-matched world: the simulator's noise is the nominal noise handed to the filters (no systematic
        odometry error, encoder k at its nominal value, the initial belief's mean drawn from the belief).
    """

    laser_sigma_m: float = 0.01
    laser_beams: int = 181
    kidnap_m: float = field(default=0.0, metadata=kidnap_distance(11.0, 6.5))
    kidnap_rad: float = 0.5
    matched: bool = field(default=False, metadata=RUN_KEY_OMIT_IF_DEFAULT)

    def __post_init__(self) -> None:
        # checked when the spec is parsed, so a bad value is a one-line error before anything runs
        check_kidnap_params(self.kidnap_m, self.kidnap_rad)
        if self.laser_beams < 2:
            raise ConfigError(f"parameter 'laser_beams' must be >= 2, got {self.laser_beams}")
        check_beams("laser_beams", self.laser_beams)
        if not (self.laser_sigma_m > 0 and math.isfinite(self.laser_sigma_m)):
            raise ConfigError(f"parameter 'laser_sigma_m' must be a range noise > 0 m, got {self.laser_sigma_m}")


class LineRoomScenario(SyntheticBuilder):
    """Report 002's experiment: laser lines in two polygonal rooms; see the module docstring."""

    id: ClassVar[str] = "line_room"
    Params: ClassVar[type] = LineRoomParams
    version: ClassVar[int] = 2
    description: ClassVar[str] = "report 002's polygonal rooms for the line-map EKF"

    def build(self, params: LineRoomParams, rng: np.random.Generator) -> Dataset:
        laser = LaserSensor(
            rate_hz=5.0,
            beams=params.laser_beams,
            fov_rad=math.radians(240.0),
            max_range_m=5.6,
            sigma_m=params.laser_sigma_m,
        )
        return tour_dataset(
            "line_room",
            params,
            rng,
            line_room_world(),
            LINE_ROOM_TOUR,
            laser=laser,
            resolution_m=LINE_ROOM_RESOLUTION_M,
        )
