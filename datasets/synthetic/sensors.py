"""Sensor simulators turning a true :class:`~locbench.datasets.synthetic.robot.Motion` into events.

- wheel-encoder odometry with systematic (wheel diameter, wheelbase) and random errors (report 003
  eq. 1, 2, 5 and 10);
- a range-bearing landmark sensor with range limits, field of view, optional wall occlusion and
  optional withheld identities;
- a planar laser ray-cast in the occupancy grid (:mod:`locbench.raycast.cast`);
- GPS-like position fixes.

Every function draws all its randomness from the Generator it is given, always the same number of draws
for the same motion, so that switching a noise off (sigma 0) leaves the rest of the realisation unchanged.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from locbench.core.errors import ConfigError
from locbench.core.events import UNKNOWN_ID, LandmarkObservations, LaserScan, Odometry, PoseFix
from locbench.core.geometry import wrap_angle
from locbench.core.limits import SCAN_SAMPLE_BYTES, check_bytes
from locbench.datasets.dataset import OccupancyGrid
from locbench.datasets.synthetic.robot import Motion
from locbench.datasets.synthetic.world import World
from locbench.raycast.cast import cast_rays

logger = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]


def sample_steps(motion: Motion, rate_hz: float, offset_steps: int = 0) -> npt.NDArray[np.int64]:
    """Indices into ``motion.t`` at which a sensor running at ``rate_hz`` samples (a whole number of steps apart)."""
    if not rate_hz > 0:
        raise ConfigError(f"sensor rate_hz must be > 0, got {rate_hz}")
    every = max(1, round(1.0 / (rate_hz * motion.dt)))
    return np.arange(offset_steps, motion.t.shape[0], every, dtype=np.int64)


# --- wheel odometry -----------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class EncoderModel:
    """How the robot's wheel odometry errs.

    Attributes
    ----------
    wheelbase_nominal_m : float
        The wheelbase W the odometry computes with (report 003 eq. 1), m; the true one is in the Motion.
    scale_left, scale_right : float
        Systematic relative travel error of each wheel (wheel-diameter mismatch): measured travel =
        true travel x (1 + scale).
    k_left, k_right : float
        Random encoder error constants, sqrt(m): each step's measured travel gets a zero-mean Gaussian error
        of variance k^2 |true travel| (report 003 eq. 10).
    """

    wheelbase_nominal_m: float
    scale_left: float = 0.0
    scale_right: float = 0.0
    k_left: float = 0.0
    k_right: float = 0.0

    def __post_init__(self) -> None:
        if not self.wheelbase_nominal_m > 0:
            raise ConfigError(f"EncoderModel.wheelbase_nominal_m must be > 0 m, got {self.wheelbase_nominal_m}")
        if self.k_left < 0 or self.k_right < 0:
            raise ConfigError(f"EncoderModel.k_left / k_right must be >= 0 sqrt(m), got {self.k_left}, {self.k_right}")


def measured_wheel_travel(
    motion: Motion, model: EncoderModel, rng: np.random.Generator
) -> tuple[FloatArray, FloatArray]:
    """Measured (d_left, d_right) per step, m: scale error plus random error of variance k^2 |d| (eq. 10)."""
    z = rng.standard_normal((motion.n_steps, 2))
    dl = motion.d_left * (1.0 + model.scale_left) + model.k_left * np.sqrt(np.abs(motion.d_left)) * z[:, 0]
    dr = motion.d_right * (1.0 + model.scale_right) + model.k_right * np.sqrt(np.abs(motion.d_right)) * z[:, 1]
    return dl, dr


def odometry_increments(d_left: FloatArray, d_right: FloatArray, wheelbase_m: float) -> FloatArray:
    """(dx, dy, dtheta) in the previous robot frame from wheel travel, shape (n, 3) (report 003 eq. 1, 2, 5)."""
    dth = (d_right - d_left) / wheelbase_m
    dd = 0.5 * (d_left + d_right)
    return np.column_stack([dd * np.cos(0.5 * dth), dd * np.sin(0.5 * dth), dth])


def wheel_odometry(motion: Motion, model: EncoderModel, rng: np.random.Generator) -> list[Odometry]:
    """Odometry events, one per step, stamped at the end of the step.

    Each carries the increment computed from the measured wheel travel with the nominal wheelbase (report
    003 eq. 1, 2, 5), the measured wheel travel, and the commanded (v, omega, dt).
    """
    dl, dr = measured_wheel_travel(motion, model, rng)
    inc = odometry_increments(dl, dr, model.wheelbase_nominal_m)
    t = motion.t[1:]
    return [
        Odometry(
            t=float(t[k]),
            dx=float(inc[k, 0]),
            dy=float(inc[k, 1]),
            dtheta=float(inc[k, 2]),
            d_left=float(dl[k]),
            d_right=float(dr[k]),
            v=float(motion.v[k]),
            omega=float(motion.omega[k]),
            dt=motion.dt,
        )
        for k in range(motion.n_steps)
    ]


def dead_reckon(start: npt.ArrayLike, increments: FloatArray) -> FloatArray:
    """Compose increments (n, 3) from ``start`` (3,): the odometry-only trajectory, shape (n+1, 3)."""
    out = np.empty((increments.shape[0] + 1, 3))
    x, y, th = (float(v) for v in np.asarray(start, dtype=np.float64)[:3])
    out[0] = (x, y, th)
    for k in range(increments.shape[0]):
        dx, dy, dth = increments[k]
        c, s = math.cos(th), math.sin(th)
        x += c * dx - s * dy
        y += s * dx + c * dy
        th = th + dth
        out[k + 1] = (x, y, th)
    out[:, 2] = wrap_angle(out[:, 2])
    return out


# --- landmarks ----------------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class LandmarkSensor:
    """A range-bearing landmark detector (Kinect-like in report 003, laser-based in report 001).

    Attributes
    ----------
    rate_hz : float
        Frames per second.
    min_range_m, max_range_m : float
        Landmarks are seen when their true range is within these limits, m.
    fov_rad : float
        Full field of view centred on the robot's x axis, rad.
    sigma_range_m, sigma_bearing_rad : float
        True measurement noise standard deviations (0 = exact).
    known_ids : bool
        Report identities; when False every id is ``UNKNOWN_ID`` and the rows are shuffled.
    occlusion : bool
        Walls hide landmarks behind them.
    detection_prob : float
        Probability that a visible landmark is reported in a frame.
    """

    rate_hz: float = 5.0
    min_range_m: float = 0.3
    max_range_m: float = 6.0
    fov_rad: float = math.pi
    sigma_range_m: float = 0.02
    sigma_bearing_rad: float = 0.01
    known_ids: bool = True
    occlusion: bool = True
    detection_prob: float = 1.0

    def __post_init__(self) -> None:
        if not 0 <= self.min_range_m < self.max_range_m:
            raise ConfigError(
                f"LandmarkSensor: need 0 <= min_range_m < max_range_m, got {self.min_range_m}, {self.max_range_m}"
            )
        if not 0 < self.fov_rad <= 2 * math.pi:
            raise ConfigError(f"LandmarkSensor.fov_rad must be in (0, 2 pi], got {self.fov_rad}")
        if self.sigma_range_m < 0 or self.sigma_bearing_rad < 0:
            raise ConfigError("LandmarkSensor: sigma_range_m and sigma_bearing_rad must be >= 0")
        if not 0 <= self.detection_prob <= 1:
            raise ConfigError(f"LandmarkSensor.detection_prob must be in [0, 1], got {self.detection_prob}")


def landmark_observations(
    motion: Motion, world: World, sensor: LandmarkSensor, rng: np.random.Generator, offset_steps: int = 0
) -> list[LandmarkObservations]:
    """Landmark sightings at the sensor rate; frames with nothing seen are left out."""
    steps = sample_steps(motion, sensor.rate_hz, offset_steps)
    poses = motion.poses[steps]
    lm = world.landmarks
    m, n_lm = steps.shape[0], lm.shape[0]
    # Draw everything up front so the realisation does not depend on what happens to be visible.
    z = rng.standard_normal((2, m, n_lm))
    u_detect = rng.random((m, n_lm))
    shuffle_keys = rng.random((m, n_lm))
    if n_lm == 0:
        return []
    rel = lm[None, :, :] - poses[:, None, 0:2]
    rng_true = np.hypot(rel[..., 0], rel[..., 1])
    brg_true = wrap_angle(np.arctan2(rel[..., 1], rel[..., 0]) - poses[:, None, 2])
    seen = (
        (rng_true >= sensor.min_range_m)
        & (rng_true <= sensor.max_range_m)
        & (np.abs(brg_true) <= 0.5 * sensor.fov_rad)
        & (u_detect < sensor.detection_prob)
    )
    r_meas = np.maximum(rng_true + sensor.sigma_range_m * z[0], 0.0)
    b_meas = wrap_angle(brg_true + sensor.sigma_bearing_rad * z[1])
    ids_all = np.arange(n_lm, dtype=np.int64)
    out: list[LandmarkObservations] = []
    for k in range(m):
        idx = np.flatnonzero(seen[k])
        if sensor.occlusion and idx.size:
            idx = idx[world.line_of_sight(poses[k, 0:2], lm[idx])]
        if idx.size == 0:
            continue
        if sensor.known_ids:
            ids = ids_all[idx]
        else:
            # Shuffled, so that the row order does not give the identity away.
            idx = idx[np.argsort(shuffle_keys[k, idx], kind="stable")]
            ids = np.full(idx.size, UNKNOWN_ID, dtype=np.int64)
        out.append(
            LandmarkObservations(
                t=float(motion.t[steps[k]]), ids=ids, ranges=r_meas[k, idx].copy(), bearings=b_meas[k, idx].copy()
            )
        )
    return out


# --- laser --------------------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class LaserSensor:
    """A planar laser rangefinder ray-cast in the occupancy grid.

    Attributes
    ----------
    rate_hz : float
        Scans per second.
    beams : int
        Number of beams, spread evenly over ``fov_rad`` including both ends.
    fov_rad : float
        Angular span, centred on the sensor's x axis, rad.
    min_range_m, max_range_m : float
        Returns outside these limits are reported as ``inf`` (no return), m.
    sigma_m : float
        Gaussian range noise, m.
    dropout_prob : float
        Probability that a beam returns nothing (``inf``).
    sensor_pose : tuple of float
        Mounting pose in the robot frame (x m, y m, theta rad).
    """

    rate_hz: float = 10.0
    beams: int = 181
    fov_rad: float = math.radians(240.0)
    min_range_m: float = 0.02
    max_range_m: float = 5.6
    sigma_m: float = 0.01
    dropout_prob: float = 0.01
    sensor_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if self.beams < 2:
            raise ConfigError(f"LaserSensor.beams must be >= 2, got {self.beams}")
        if not 0 < self.fov_rad <= 2 * math.pi:
            raise ConfigError(f"LaserSensor.fov_rad must be in (0, 2 pi], got {self.fov_rad}")
        if not 0 <= self.min_range_m < self.max_range_m:
            raise ConfigError(
                f"LaserSensor: need 0 <= min_range_m < max_range_m, got {self.min_range_m}, {self.max_range_m}"
            )
        if self.sigma_m < 0 or not 0 <= self.dropout_prob <= 1:
            raise ConfigError("LaserSensor: sigma_m must be >= 0 and dropout_prob in [0, 1]")

    @property
    def angle_min(self) -> float:
        return -0.5 * self.fov_rad

    @property
    def angle_increment(self) -> float:
        return self.fov_rad / (self.beams - 1)

    def angles(self) -> FloatArray:
        """Beam angles in the sensor frame, rad, shape (beams,)."""
        return self.angle_min + self.angle_increment * np.arange(self.beams, dtype=np.float64)


def laser_sensor_poses(
    motion: Motion, sensor: LaserSensor, offset_steps: int = 0
) -> tuple[npt.NDArray[np.int64], FloatArray]:
    """The motion steps at the sensor rate and the world pose of the laser at each, shape (S,), (S, 3)."""
    steps = sample_steps(motion, sensor.rate_hz, offset_steps)
    # the scans' arrays are (S, B): refused before ray-casting when the plan is too large to hold
    check_bytes(
        "laser simulation",
        f"{steps.shape[0]} scans x {sensor.beams} beams",
        float(steps.shape[0]) * float(sensor.beams) * SCAN_SAMPLE_BYTES,
        "lower the dataset's 'laser_beams'",
    )
    poses = motion.poses[steps]
    sx, sy, sth = sensor.sensor_pose
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    world_sensor = np.column_stack([poses[:, 0] + c * sx - s * sy, poses[:, 1] + s * sx + c * sy, poses[:, 2] + sth])
    return steps, world_sensor


def noisy_scans(
    motion: Motion, steps: npt.NDArray[np.int64], true_r: FloatArray, sensor: LaserSensor, rng: np.random.Generator
) -> list[LaserScan]:
    """LaserScan events from true ranges (S, B): Gaussian range noise, then dropouts and out-of-range -> inf."""
    sx, sy, sth = sensor.sensor_pose
    z = rng.standard_normal(true_r.shape)
    u = rng.random(true_r.shape)
    with np.errstate(invalid="ignore"):  # inf + noise stays inf
        r = true_r + sensor.sigma_m * z
    r[(u < sensor.dropout_prob) | (r > sensor.max_range_m) | (r < sensor.min_range_m)] = np.inf
    return [
        LaserScan(
            t=float(motion.t[steps[k]]),
            angle_min=sensor.angle_min,
            angle_increment=sensor.angle_increment,
            ranges=r[k].copy(),
            range_min=sensor.min_range_m,
            range_max=sensor.max_range_m,
            sensor_pose=(float(sx), float(sy), float(sth)),
        )
        for k in range(steps.shape[0])
    ]


def laser_scans(
    motion: Motion, grid: OccupancyGrid, sensor: LaserSensor, rng: np.random.Generator, offset_steps: int = 0
) -> list[LaserScan]:
    """Laser scans at the sensor rate, all ray-cast in one call."""
    steps, world_sensor = laser_sensor_poses(motion, sensor, offset_steps)
    true_r = cast_rays(
        grid.occupied(), grid.resolution, grid.origin[:2], world_sensor, sensor.angles(), sensor.max_range_m
    )
    return noisy_scans(motion, steps, true_r, sensor, rng)


# --- GPS-like fixes -----------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class PoseFixSensor:
    """GPS-like (x, y) fixes in the world frame (report 001).

    Attributes
    ----------
    rate_hz : float
        Fixes per second.
    sigma_xy_m : float
        True noise per axis, m (0 = exact).
    reported_sigma_xy_m : float
        The standard deviation written into each fix's covariance, m (> 0).
    """

    rate_hz: float = 1.0
    sigma_xy_m: float = 0.7
    reported_sigma_xy_m: float = 0.7

    def __post_init__(self) -> None:
        if self.sigma_xy_m < 0 or not self.reported_sigma_xy_m > 0:
            raise ConfigError("PoseFixSensor: sigma_xy_m must be >= 0 and reported_sigma_xy_m > 0")


def pose_fixes(motion: Motion, sensor: PoseFixSensor, rng: np.random.Generator, offset_steps: int = 0) -> list[PoseFix]:
    """Position fixes at the sensor rate."""
    steps = sample_steps(motion, sensor.rate_hz, offset_steps)
    z = rng.standard_normal((steps.shape[0], 2))
    xy = motion.poses[steps, 0:2] + sensor.sigma_xy_m * z
    cov = np.eye(2) * sensor.reported_sigma_xy_m**2
    return [PoseFix(t=float(motion.t[steps[k]]), z=xy[k].copy(), cov=cov.copy()) for k in range(steps.shape[0])]
