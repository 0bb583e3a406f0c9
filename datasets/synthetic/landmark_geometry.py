"""Report 001's micro-simulator: paths x landmark layouts, landmarks detected by a 151-ray laser.

Report 001 (Gadau, Viana, Contreiras, Anjo, "Aerial localization using the Extended Kalman Filter")
drives a robot on a circle, a "star", a pentagon and a random path past 1, 2, 3 (triangle), 4 (square
near) and "more than four" (square far) landmarks, and localizes it with an EKF on odometry and the
range-bearing of the landmarks seen by a laser of 151 rays over +-2 rad (sec. IV-B), with a GPS variant
that starts from a wrong initial pose (fig. 5) and a kidnap (fig. 7). The report gives no coordinates;
the geometry below is ours and is the whole definition of the scenario.

World (world frame, m; everything centred on the origin):

* a 14 m x 14 m arena (walls at x, y = +-7) so that the laser has something to see everywhere;
* landmarks are discs of radius :data:`LANDMARK_RADIUS_M` (0.15 m), added to the world's geometry as
  16-gon outlines, so the occupancy grid, the line map and the landmark map (the disc centres) all come
  from one :class:`~locbench.datasets.synthetic.world.World`;
* layouts (:data:`LAYOUTS`): ``"1"`` one landmark at (0, 3); ``"2"`` (0, 3) and (0, -3); ``"3"`` a
  triangle on a 3 m circle (at 90, 210 and 330 deg); ``"4"`` a square near the path, (+-2.25, +-2.25)
  (1.2 m outside the circle); ``"8"`` a square far from the path, the corners and edge mid-points of the
  square of half-side 5.5 m (3.5-5.8 m outside the circle).

Paths (:data:`PATHS`), each driven ``circuits`` times (default 2), starting at (0, -2) heading +x and
ending each circuit back there (the end of a circuit is a marked waypoint, 2 s dwell):

* ``circle``: a 2 m radius circle, counter-clockwise, at constant curvature;
* ``pentagon``: the regular pentagon inscribed in that circle, starting at its bottom vertex;
* ``star``: the pentagram on the same five vertices (every second vertex);
* ``random``: 8 points drawn per seed uniformly in the disc of radius 2.2 m (at least 0.5 m apart),
  visited in the drawn order and back to the start; the same loop on every circuit.

Every path keeps at least 0.6 m from every landmark disc of every layout.

Sensors:

* the shared robot's execution noise (wheel slip ``SLIP_K_TRUE`` between the commanded twist and the
  true motion, :mod:`locbench.datasets.synthetic.robot`; the robot steers back onto its circle or line),
  from the ``execution`` stream;
* wheel odometry of the shared robot (:func:`~locbench.datasets.synthetic.toolkit.robot_encoder_model`:
  the room-calibrated systematic and random encoder error, report 003 eq. 10) rather than report 001
  fig. 1's velocity-noise model, so that every synthetic world has the same robot; 20 Hz;
* a laser of 151 beams over [-2, 2] rad (report 001 sec. IV-B), 5 Hz, 12 m range (so that the far square
  stays in range from every point of every path: report 001's micro-simulator saw every landmark),
  1 cm range noise, 1 % dropouts, ray-cast on the 0.05 m occupancy grid by :mod:`locbench.raycast.cast`;
* landmark detection from each scan (report 001 fig. 3): a beam hit landmark j when its end point is
  within the disc radius plus :data:`HIT_TOLERANCE_M` of the disc centre (the simulator knows which
  object a beam hit); each landmark hit by at least one beam is reported with bearing = mean bearing of
  its beams and range = shortest of their ranges + the radius ("theoretic distance + R"); identities
  given, or withheld (``known_ids=false``: ``UNKNOWN_ID`` and shuffled rows);
* with ``gps=true``, 1 Hz (x, y) fixes with ``pose_fix_sigma_m`` per axis (report 001 fig. 2 "GPS sensor").

The nominal landmark noise handed to filters (:data:`NOMINAL_SIGMA_RANGE_M` 5 cm,
:data:`NOMINAL_SIGMA_BEARING_RAD` 0.007 rad) is the measured RMS error of this detector over every path
and layout (:mod:`locbench.datasets.synthetic.detection_error`, which records what it measured), rounded up.

``initial_offset_m = d`` moves the initial belief handed to filters d metres from the true start in a
direction drawn from the seed, with a per-axis standard deviation of max(d, 2 cm) so that the belief
covers the truth (report 001 fig. 5). ``kidnap_m = D`` jumps the truth silently by D metres (direction
drawn from the seed) and by ``kidnap_rad`` (sign drawn) at the middle of the run; the robot carries on
with the same wheel motion from where it was put down, i.e. the rest of the run is the kidnap-free
remainder moved rigidly, which must keep 0.3 m from every wall and landmark (unlike ``room`` and
``office``, whose robot re-plans to its next goal: a circle has no goal to re-plan to).
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import numpy as np
import numpy.typing as npt

from locbench.core.errors import ConfigError
from locbench.core.events import UNKNOWN_ID, Event, LandmarkObservations, LaserScan
from locbench.core.geometry import wrap_angle, wrap_scalar
from locbench.core.runkey import RUN_KEY_OMIT_IF_DEFAULT
from locbench.datasets.dataset import Dataset, Gaussian2, Kidnap, SyntheticBuilder, sort_events
from locbench.datasets.synthetic.robot import Arc, DriveLimits, GoTo, Leg, Motion, simulate_route
from locbench.datasets.synthetic.sensors import LandmarkSensor, LaserSensor, PoseFixSensor, laser_scans
from locbench.datasets.synthetic.toolkit import (
    SLIP_K_TRUE,
    SensorSuite,
    assemble,
    check_kidnap_params,
    encoder_model,
    kidnap_distance,
    nominal_sensor_spec,
    true_wheelbase,
)
from locbench.datasets.synthetic.world import World

logger = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]

PathName = Literal["circle", "star", "pentagon", "random"]
LayoutName = Literal["1", "2", "3", "4", "8"]
PATHS: tuple[str, ...] = ("circle", "star", "pentagon", "random")
LAYOUTS: tuple[str, ...] = ("1", "2", "3", "4", "8")

#: Half side of the square arena, m.
ARENA_HALF_M = 7.0
#: Radius of a landmark disc, m (report 001 used "rather big landmarks"; 0.15 m is our choice).
LANDMARK_RADIUS_M = 0.15
#: Sides of the polygon that stands for a disc in the world geometry (<= 3 mm from the circle at 0.15 m).
DISC_SIDES = 16
#: Radius of the circle path and of the circle the pentagon and the star are inscribed in, m.
PATH_RADIUS_M = 2.0
#: Random paths draw their points in a disc of this radius, m.
RANDOM_RADIUS_M = 2.2
RANDOM_POINTS = 8
RANDOM_MIN_STEP_M = 0.5
#: Start pose (x m, y m, theta rad): the bottom of the circle, heading +x (counter-clockwise).
START = (0.0, -PATH_RADIUS_M, 0.0)
#: Occupancy grid resolution, m.
RESOLUTION_M = 0.05
#: A beam end point this far outside a disc still counts as a hit on it, m: the grid raster of the disc
#: outline is up to one cell diagonal (7 cm) in front of the circle, plus 3 sigma of range noise.
HIT_TOLERANCE_M = 0.1

LIMITS = DriveLimits(
    dt_s=0.05, v_max_mps=0.5, accel_mps2=0.5, omega_max_radps=1.0, alpha_radps2=2.0, dwell_s=2.0, start_dwell_s=1.0
)
#: The 151-ray laser of report 001 sec. IV-B (151 rays, -2 .. 2 rad).
LASER = LaserSensor(
    rate_hz=5.0, beams=151, fov_rad=4.0, min_range_m=0.05, max_range_m=12.0, sigma_m=0.01, dropout_prob=0.01
)
#: Nominal range-bearing noise of the detector handed to filters: the measured RMS errors of
#: :func:`detect_landmarks` over every path and layout, seeds 0-2 (66 291 sightings; range error mean
#: -3.8 cm, RMS 4.2 cm: the grid raster of a disc lies up to a cell in front of it, and the shortest of
#: several noisy beams is biased short; bearing RMS 0.0062 rad, about a quarter of a beam step), rounded up.
NOMINAL_SIGMA_RANGE_M = 0.05
NOMINAL_SIGMA_BEARING_RAD = 0.007


def layout_xy(layout: str) -> FloatArray:
    """Landmark centres of a layout, world frame, m, shape (n, 2) (see the module docstring)."""
    if layout == "1":
        pts = [(0.0, 3.0)]
    elif layout == "2":
        pts = [(0.0, 3.0), (0.0, -3.0)]
    elif layout == "3":
        pts = [(3.0 * math.cos(a), 3.0 * math.sin(a)) for a in np.radians([90.0, 210.0, 330.0])]
    elif layout == "4":
        pts = [(2.25, 2.25), (-2.25, 2.25), (-2.25, -2.25), (2.25, -2.25)]
    elif layout == "8":
        h = 5.5
        pts = [(h, 0.0), (h, h), (0.0, h), (-h, h), (-h, 0.0), (-h, -h), (0.0, -h), (h, -h)]
    else:
        raise ConfigError(f"parameter 'landmarks' must be one of {', '.join(LAYOUTS)}, got {layout!r}")
    return np.asarray(pts, dtype=np.float64)


def disc_polygon(centre: FloatArray, radius: float, sides: int = DISC_SIDES) -> list[tuple[float, float, float, float]]:
    """The closed ``sides``-gon inscribed in a disc, as wall segments (x1, y1, x2, y2), m."""
    a = np.linspace(0.0, 2.0 * math.pi, sides + 1)
    x = centre[0] + radius * np.cos(a)
    y = centre[1] + radius * np.sin(a)
    return [(float(x[k]), float(y[k]), float(x[k + 1]), float(y[k + 1])) for k in range(sides)]


def geometry_world(layout: str) -> World:
    """The arena with the landmark discs of ``layout``; landmark k is the centre of disc k."""
    h = ARENA_HALF_M
    c = [(-h, -h), (h, -h), (h, h), (-h, h)]
    walls: list[tuple[float, float, float, float]] = [(*c[k], *c[(k + 1) % 4]) for k in range(4)]
    centres = layout_xy(layout)
    for p in centres:
        walls += disc_polygon(p, LANDMARK_RADIUS_M)
    return World(walls=np.array(walls), landmarks=centres, bounds=(-h, -h, h, h), name=f"landmark_geometry_{layout}")


def _vertices(count: int) -> list[tuple[float, float]]:
    """Vertices of the regular polygon inscribed in the path circle, from the start point, counter-clockwise."""
    a0 = -0.5 * math.pi
    return [
        (PATH_RADIUS_M * math.cos(a0 + 2 * math.pi * k / count), PATH_RADIUS_M * math.sin(a0 + 2 * math.pi * k / count))
        for k in range(count)
    ]


def random_loop(rng: np.random.Generator) -> list[tuple[float, float]]:
    """``RANDOM_POINTS`` points uniform in the disc of radius ``RANDOM_RADIUS_M``, each >= 0.5 m from the last."""
    pts: list[tuple[float, float]] = []
    last = START[:2]
    # A fixed batch of candidates keeps the number of draws independent of the rejections.
    cand = rng.random((64 * RANDOM_POINTS, 2))
    k = 0
    while len(pts) < RANDOM_POINTS:
        if k >= cand.shape[0]:  # pragma: no cover - 512 candidates for 8 points
            raise ConfigError("random path: could not draw enough well-separated points")
        r = RANDOM_RADIUS_M * math.sqrt(cand[k, 0])
        a = 2.0 * math.pi * cand[k, 1]
        k += 1
        p = (r * math.cos(a), r * math.sin(a))
        if math.hypot(p[0] - last[0], p[1] - last[1]) >= RANDOM_MIN_STEP_M:
            pts.append(p)
            last = p
    return pts


def path_legs(path: str, circuits: int, rng: np.random.Generator) -> list[Leg]:
    """The route of ``path`` driven ``circuits`` times from :data:`START`; each circuit ends marked at the start."""
    start = (START[0], START[1])
    if path == "circle":
        return [Arc(length_m=2.0 * math.pi * PATH_RADIUS_M, curvature_1pm=1.0 / PATH_RADIUS_M) for _ in range(circuits)]
    if path == "pentagon":
        loop = _vertices(5)[1:]
    elif path == "star":
        v = _vertices(5)
        loop = [v[2], v[4], v[1], v[3]]
    elif path == "random":
        loop = random_loop(rng)
    else:
        raise ConfigError(f"parameter 'path' must be one of {', '.join(PATHS)}, got {path!r}")
    legs: list[Leg] = []
    for _ in range(circuits):
        legs += [GoTo(p, marked=False) for p in loop]
        legs.append(GoTo(start, marked=True))
    return legs


def kidnap_remainder(
    motion: Motion,
    world: World,
    distance_m: float,
    rotation_rad: float,
    fraction: float,
    rng: np.random.Generator,
    clearance_m: float = 0.3,
) -> Motion:
    """Jump the truth at ``fraction`` of the run; the rest of the run is the remainder moved rigidly.

    The jump is ``distance_m`` in one of 72 directions drawn from ``rng`` (the first that keeps the moved
    remainder ``clearance_m`` from every wall and disc, trying both rotation signs, the first drawn) and
    ``rotation_rad``. Wheel travel and commands are unchanged: the robot is not told. Marked waypoints after
    the jump move with the robot.
    """
    k = round(fraction * motion.n_steps)
    p = motion.poses[k].copy()
    directions = rng.uniform(-math.pi, math.pi, 72)
    sign = 1.0 if rng.random() < 0.5 else -1.0
    rest = motion.poses[k:]
    probe = rest[:: max(1, round(0.1 / motion.dt)), 0:2]  # every 0.1 s is enough at 0.5 m/s

    def moved(xy: FloatArray, dx: float, dy: float, dth: float) -> FloatArray:
        c, s = math.cos(dth), math.sin(dth)
        rel = xy - p[0:2]
        return np.column_stack([p[0] + dx + c * rel[:, 0] - s * rel[:, 1], p[1] + dy + s * rel[:, 0] + c * rel[:, 1]])

    for a in directions:
        dx, dy = distance_m * math.cos(a), distance_m * math.sin(a)
        for sg in (sign, -sign):
            dth = sg * rotation_rad
            if not np.all(world.is_free(moved(probe, dx, dy, dth), clearance_m)):
                continue
            poses = motion.poses.copy()
            poses[k:, 0:2] = moved(rest[:, 0:2], dx, dy, dth)
            poses[k:, 2] = wrap_angle(rest[:, 2] + dth)
            t_k = float(motion.t[k])
            wp_xy = motion.waypoint_xy.copy()
            after = motion.waypoint_t > t_k
            if np.any(after):
                wp_xy[after] = moved(wp_xy[after], dx, dy, dth)
            logger.debug("kidnap at t=%.2f s by (%.3f, %.3f, %.3f)", t_k, dx, dy, dth)
            return dataclasses.replace(
                motion, poses=poses, waypoint_xy=wp_xy, kidnaps=(Kidnap(t=t_k, delta=(dx, dy, dth)),)
            )
    raise ConfigError(
        f"kidnap_m={distance_m}: no jump of {distance_m} m keeps the rest of the run {clearance_m} m from the walls "
        "and landmarks; expected a smaller kidnap distance"
    )


def detect_landmarks(
    scans: list[LaserScan],
    poses: FloatArray,
    centres: FloatArray,
    radius_m: float,
    known_ids: bool,
    rng: np.random.Generator,
    tolerance_m: float = HIT_TOLERANCE_M,
) -> list[LandmarkObservations]:
    """Range-bearing of the landmark discs hit by the beams of each scan (report 001 fig. 3).

    Parameters
    ----------
    scans : list of LaserScan
        The simulated scans (sensor at the robot origin).
    poses : ndarray, shape (len(scans), 3)
        True robot pose at each scan, world frame; used only to tell which disc a beam hit.
    centres : ndarray, shape (n, 2)
        Disc centres, world frame, m; landmark k has id k.
    radius_m : float
        Disc radius R, m.
    known_ids : bool
        Report ids, or ``UNKNOWN_ID`` with the rows shuffled.
    rng : Generator
        For the shuffle only (one draw per scan and landmark, whatever is seen).
    tolerance_m : float
        How far outside the disc a beam end point may lie and still count as a hit on it, m.

    Returns
    -------
    list of LandmarkObservations
        One per scan that saw at least one whole disc: bearing = mean bearing of the beams that hit the
        disc, range = their shortest range + R (the theoretic distance to the centre). A disc whose run of
        beams touches the first or last beam, or whose neighbouring beam returns closer than the disc (an
        object in front of its edge), is left out: its extent, hence its centre bearing, is unknown.
    """
    n_lm = centres.shape[0]
    shuffle_keys = rng.random((len(scans), n_lm))
    out: list[LandmarkObservations] = []
    for k, scan in enumerate(scans):
        if scan.sensor_pose != (0.0, 0.0, 0.0):
            raise ConfigError("detect_landmarks: the laser must sit at the robot origin")
        r = scan.ranges
        n_beams = r.shape[0]
        if n_lm == 0 or not np.any(np.isfinite(r)):
            continue
        ang = scan.angles
        finite = np.isfinite(r)
        rr = np.where(finite, r, 0.0)
        world_ang = poses[k, 2] + ang
        end = np.column_stack([poses[k, 0] + rr * np.cos(world_ang), poses[k, 1] + rr * np.sin(world_ang)])
        d = np.hypot(end[:, None, 0] - centres[None, :, 0], end[:, None, 1] - centres[None, :, 1])
        nearest = np.argmin(d, axis=1)
        hit = finite & (d[np.arange(n_beams), nearest] <= radius_m + tolerance_m)
        found: list[tuple[int, float, float]] = []
        for j in np.unique(nearest[hit]).tolist():
            idx = np.flatnonzero(hit & (nearest == j))
            i0, i1 = int(idx[0]), int(idx[-1])
            r_min = float(np.min(r[idx]))
            # A disc cut by the edge of the field of view or by a closer object in front of its edge has an
            # unknown extent: its mean beam bearing would be biased, so it is not reported.
            if i0 == 0 or i1 == n_beams - 1 or r[i0 - 1] < r_min or r[i1 + 1] < r_min:
                continue
            found.append((j, r_min + radius_m, wrap_scalar(float(np.mean(ang[idx])))))
        if not found:
            continue
        seen = np.array([f[0] for f in found], dtype=np.int64)
        ranges = np.array([f[1] for f in found])
        bearings = np.array([f[2] for f in found])
        if known_ids:
            ids = seen.astype(np.int64)
        else:
            order = np.argsort(shuffle_keys[k, seen], kind="stable")
            seen, ranges, bearings = seen[order], ranges[order], bearings[order]
            ids = np.full(seen.size, UNKNOWN_ID, dtype=np.int64)
        out.append(LandmarkObservations(t=scan.t, ids=ids, ranges=ranges, bearings=bearings))
    return out


@dataclass(frozen=True, kw_only=True)
class LandmarkGeometryParams:
    """Parameters of ``landmark_geometry``.

    Attributes
    ----------
    path : {"circle", "star", "pentagon", "random"}
        The route (module docstring).
    landmarks : {"1", "2", "3", "4", "8"}
        The landmark layout: 1; 2; 3 in a triangle; 4 in a square near the path; 8 in a square far from it.
    known_ids : bool
        Landmark identities reported (True) or withheld.
    gps : bool
        Add 1 Hz GPS-like (x, y) fixes (report 001's GPS variant).
    pose_fix_sigma_m : float
        Standard deviation of a fix per axis, m (the report gives none; 0.5 m is our choice).
    initial_offset_m : float
        Distance of the initial belief from the true start, m (report 001 fig. 5); 0 = exact start.
    kidnap_m : float
        Kidnap distance at the middle of the run, m (0 = no kidnap).
    kidnap_rad : float
        Kidnap rotation magnitude, rad (sign drawn at random).
    circuits : int
        How many times the path is driven.
    matched : bool
        Model-matched world: the simulator's noise is the nominal noise handed to the filters (no systematic
        odometry error, encoder k at its nominal value, the initial belief's mean drawn from the belief) and
        the sightings come from a Gaussian range-bearing sensor with the nominal noise, range limits and field
        of view instead of the laser detector (no occlusion between discs); needs ``initial_offset_m`` = 0.
    """

    path: PathName = "circle"
    landmarks: LayoutName = "4"
    known_ids: bool = True
    gps: bool = False
    pose_fix_sigma_m: float = 0.5
    initial_offset_m: float = 0.0
    kidnap_m: float = field(default=0.0, metadata=kidnap_distance(2 * ARENA_HALF_M, 2 * ARENA_HALF_M))
    kidnap_rad: float = 0.5
    circuits: int = 2
    matched: bool = field(default=False, metadata=RUN_KEY_OMIT_IF_DEFAULT)

    def __post_init__(self) -> None:
        # checked when the spec is parsed, so a bad value is a one-line error before anything runs
        _check_params(self)


#: Independent noise streams, in a fixed order (adding one at the end leaves the others unchanged).
STREAMS = ("odometry", "landmarks", "laser", "fixes", "kidnap", "route", "initial", "execution")


class LandmarkGeometryScenario(SyntheticBuilder):
    """Report 001's micro-simulator: paths x landmark layouts, laser-detected disc landmarks, GPS variant."""

    id: ClassVar[str] = "landmark_geometry"
    Params: ClassVar[type] = LandmarkGeometryParams
    version: ClassVar[int] = 2
    description: ClassVar[str] = (
        "report 001's paths x landmark layouts, landmarks detected by a 151-ray laser; GPS variant"
    )

    def build(self, params: LandmarkGeometryParams, rng: np.random.Generator) -> Dataset:
        # long: one scenario's assembly: route, kidnap, sensors, spec and metadata in the order the streams are drawn
        streams = dict(zip(STREAMS, rng.spawn(len(STREAMS)), strict=True))
        world = geometry_world(params.landmarks)
        limits = dataclasses.replace(LIMITS, wheelbase_m=true_wheelbase(params.matched))
        legs = path_legs(params.path, params.circuits, streams["route"])
        motion = simulate_route(START, legs, limits, slip_k=SLIP_K_TRUE, slip_rng=streams["execution"])
        if params.kidnap_m > 0:
            motion = kidnap_remainder(motion, world, params.kidnap_m, params.kidnap_rad, 0.5, streams["kidnap"])
        fixes = (
            PoseFixSensor(rate_hz=1.0, sigma_xy_m=params.pose_fix_sigma_m, reported_sigma_xy_m=params.pose_fix_sigma_m)
            if params.gps
            else None
        )
        # the landmarks are seen by the laser: their limits are the laser's, widened by the landmark's radius
        spec = nominal_sensor_spec(
            params.matched,
            laser=LASER,
            fixes=fixes,
            landmark_sigma_range_m=NOMINAL_SIGMA_RANGE_M,
            landmark_sigma_bearing_rad=NOMINAL_SIGMA_BEARING_RAD,
            landmark_min_range_m=LASER.min_range_m + LANDMARK_RADIUS_M,
            landmark_max_range_m=LASER.max_range_m + LANDMARK_RADIUS_M,
            landmark_fov_rad=LASER.fov_rad,
        )
        # Unless matched, the landmark stream is not used by assemble (landmarks come from the scans below).
        matched_sightings = (
            LandmarkSensor(
                rate_hz=LASER.rate_hz,
                min_range_m=LASER.min_range_m + LANDMARK_RADIUS_M,
                max_range_m=LASER.max_range_m + LANDMARK_RADIUS_M,
                fov_rad=LASER.fov_rad,
                sigma_range_m=NOMINAL_SIGMA_RANGE_M,
                sigma_bearing_rad=NOMINAL_SIGMA_BEARING_RAD,
                known_ids=params.known_ids,
                occlusion=False,
            )
            if params.matched
            else None
        )
        suite = SensorSuite(encoder=encoder_model(params.matched), landmarks=matched_sightings, fixes=fixes)
        off = _initial_offset(params.initial_offset_m, streams["initial"])
        meta: dict[str, Any] = {
            "layout": params.landmarks,
            "path": params.path,
            "landmark_radius_m": LANDMARK_RADIUS_M,
            "laser": dataclasses.asdict(LASER),
            "initial_offset_xy_m": [float(off[0]), float(off[1])],
        }
        ds = assemble(
            dataset_id="landmark_geometry",
            params=params,
            world=world,
            motion=motion,
            suite=suite,
            streams=streams,
            spec=spec,
            initial_sigma=(0.02, 0.02, math.radians(1.0)),
            resolution_m=RESOLUTION_M,
            metadata=meta,
            initial_rng=streams["initial"] if params.matched else None,
        )
        assert ds.world.occupancy is not None
        scans = laser_scans(motion, ds.world.occupancy, LASER, streams["laser"])
        scan_steps = np.round(np.array([s.t for s in scans]) / motion.dt).astype(np.int64)
        sightings = (
            []
            if params.matched
            else detect_landmarks(
                scans,
                motion.poses[scan_steps],
                world.landmarks,
                LANDMARK_RADIUS_M,
                params.known_ids,
                streams["landmarks"],
            )
        )
        events: list[Event] = [*ds.events, *scans, *sightings]
        initial = ds.initial
        if params.initial_offset_m > 0:
            sigma_xy = max(params.initial_offset_m, 0.02)
            cov = initial.cov.copy()
            cov[0, 0] = cov[1, 1] = sigma_xy**2
            mean = initial.mean.copy()
            mean[0:2] += off
            initial = Gaussian2(mean=mean, cov=cov)
        ds = dataclasses.replace(ds, events=sort_events(events), initial=initial)
        ds.check()
        return ds


def _initial_offset(distance_m: float, rng: np.random.Generator) -> FloatArray:
    """The (dx, dy) offset of the initial belief, m: ``distance_m`` in a direction drawn from ``rng``."""
    a = rng.uniform(-math.pi, math.pi)
    return np.array([distance_m * math.cos(a), distance_m * math.sin(a)])


def _check_params(p: LandmarkGeometryParams) -> None:
    if p.path not in PATHS:
        raise ConfigError(f"parameter 'path' must be one of {', '.join(PATHS)}, got {p.path!r}")
    if p.landmarks not in LAYOUTS:
        raise ConfigError(f"parameter 'landmarks' must be one of {', '.join(LAYOUTS)}, got {p.landmarks!r}")
    check_kidnap_params(p.kidnap_m, p.kidnap_rad)
    if not (p.initial_offset_m >= 0 and math.isfinite(p.initial_offset_m)):
        raise ConfigError(f"parameter 'initial_offset_m' must be a distance >= 0 m, got {p.initial_offset_m}")
    if not p.pose_fix_sigma_m > 0:
        raise ConfigError(f"parameter 'pose_fix_sigma_m' must be > 0 m, got {p.pose_fix_sigma_m}")
    if p.matched and p.initial_offset_m > 0:
        raise ConfigError(
            f"parameter 'initial_offset_m' must be 0 with matched=true (the initial error is drawn from the belief), "
            f"got {p.initial_offset_m}"
        )
    if not 1 <= p.circuits <= 10:
        raise ConfigError(f"parameter 'circuits' must be an integer in 1..10, got {p.circuits}")
