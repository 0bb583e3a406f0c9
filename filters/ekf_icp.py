"""EKF localization whose observation is an ICP match against a scan ray-cast in the map (report 000).

Report 000 (Castilho, Gomes, Sousa, Kuehlen, "EKF-based localization with LRF", IST 2016/17) estimates
X = (x, y, theta) (eq. 1) with a Pioneer 3DX's odometry and a Hokuyo laser on a 0.05 m occupancy grid.

Prediction (eq. 11-13). The report predicts with backward differences of the odometry pose,
X^- = X + (dx_odom, dy_odom, dtheta_odom) with F = [[1, 0, -dy_odom], [0, 1, dx_odom], [0, 0, 1]]
(eq. 11-12). Here an odometry event gives the increment (dx, dy, dtheta) in the previous robot frame,
so the world-frame increment is (dx_w, dy_w) = R(theta) (dx, dy): exactly eq. 11-12 written in the
map frame (the report's odometry frame only differs from it by a rotation). Q is diagonal (eq. 13):

    Q = diag(q_x,stat + q_x,dyn |dx_w|,  q_y,stat + q_y,dyn |dy_w|,  q_theta,stat + q_theta,dyn |dtheta|).

The dynamic terms grow with the motion, so their sum over a path does not depend on the odometry rate.
The static terms are per time step of the report's odometry (rosaria publishes the Pioneer's pose once
per 100 ms SIP cycle, 10 Hz); here they are scaled by dt / ``static_noise_period_s`` so that they mean
the same variance per second at any odometry rate (the synthetic robots report at 20 Hz).

Observation (sec. III-A.2, eq. 2-3, 14). At each LaserScan a scan is ray-cast from the occupancy grid
(:func:`locbench.raycast.cast.cast_scan`, which marches on fields cached with the grid) at the predicted sensor
pose with the real scan's geometry (angle_min, angle_increment, beam count, range_max, sensor_pose). Both scans
become points in the robot frame, and point-to-point ICP (:mod:`locbench.filters._icp`, compiled) aligns the
real points (source) onto the ray-cast points (target). If the world point w is seen at p_real = T^-1 w from
the true pose T and at p_pred = X^-1 w from the predicted pose X, the ICP transform is M = X^-1 T: the true pose
in the predicted robot frame. The observation is Z = X (+) M (eq. 2), the predicted observation is Z^ = X
(h(X) = X, H = I, eq. 14), and V = Z - Z^ = (R(theta) t_M, theta_M) (eq. 3, heading wrapped).

Update (eq. 15-18). K = P (P + R)^-1, X = X + K V, with R = diag(r_x, r_y, r_theta) (eq. 16); the
covariance uses the Joseph form (I - K) P (I - K)^T + K R K^T, equal to eq. 18 for the optimal gain but
symmetric PSD under rounding. The prediction, both clouds with the rejection distances below and this
update are scalar compiled kernels (:mod:`locbench.filters._ekf_icp_kernels`), the filter's one implementation
of them.

Matching (sec. III-B): a scan is a mismatch, and the belief stays the prediction, when ICP did not
converge or when fewer points matched than the threshold (``min_matched_fraction`` of the smaller of the
two clouds, at least ``min_matched_points``; the report gives no value).

Kidnap rule (sec. IV-B): after ``kidnap_mismatches`` (100) consecutive mismatches P is multiplied by
``kidnap_cov_factor`` (10) and the ICP threshold is tightened (the correspondence distances below times
``kidnap_threshold_factor``). The counter then restarts, so the rule fires again after another 100
mismatches (P grows by 10 each time; the threshold is tightened once, not compounded). The report does
not say when the threshold is restored; here it returns to normal at the first accepted match, when the
filter has found its position again.

PCL's maximum correspondence distance (appendix: 0.002 m) cannot mean the same here. In PCL it rejects
every nearest-neighbour pair farther apart than 2 mm. The real and the ray-cast scan sample the walls at
different points, the simulated laser has 1 cm range noise and the map 5 cm cells, so a correct pair is
typically 1-3 cm apart even at the true pose: a 2 mm rejection would leave almost no pairs and every scan
would be a mismatch. The rejection distance is derived instead from what a correct pair's distance
should be (a principled choice, not fitted): with sigma_l the laser's range noise (the dataset's nominal
``laser_sigma_m``), c the grid cell and the predicted covariance P,

    floor     D_min = k sqrt(2 sigma_l^2 + c^2 / 6)                  (noise of both points, cell quantisation)
    initial   D_0   = k sqrt(2 sigma_l^2 + c^2 / 6 + lambda_max(P_xy) + r_mean^2 P_thth)

with k = ``correspondence_sigmas`` (3), r_mean the mean range of the real scan, and D_0 capped at
``max_correspondence_cap_m``. ICP starts with D_0 (pairs as far apart as the pose uncertainty allows)
and shrinks it each iteration by Zhang's rule down to D_min (see :mod:`locbench.filters._icp`). The
report's other ICP parameters (700 iterations, transformation epsilon 5e-7) keep their PCL meaning.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from locbench.core.errors import ConfigError, FilterDiverged, ResourceLimit
from locbench.core.events import LaserScan, Observation, Odometry
from locbench.core.geometry import wrap_scalar
from locbench.core.limits import RAYCAST_BYTES_PER_CELL, check_bytes, grid_cells
from locbench.core.tunable import tunable
from locbench.datasets.dataset import Gaussian2, MapKind, OccupancyGrid, SensorSpec, WorldMap
from locbench.filters import _icp
from locbench.filters._ekf_icp_kernels import (
    BUF_SIGMAS,
    correct_pose,
    predict_pose,
    scan_clouds,
    state_buffer,
)
from locbench.filters._icp import MIN_PAIRS, IcpResult
from locbench.filters.base import (
    POSITIVE,
    POSITIVE_OR_DATASET,
    Estimate,
    Filter,
    FilterConfig,
    FilterDoc,
    bound,
)
from locbench.raycast.cast import cast_scan

FloatArray = npt.NDArray[np.float64]
logger = logging.getLogger(__name__)

#: Laser range noise used when neither the config nor the dataset gives one, m (a Hokuyo URG-04LX is +-3 cm).
DEFAULT_LASER_SIGMA_M = 0.01
#: The ICP health before any scan.
_NO_ICP_HEALTH = {"icp_rmse_m": math.nan, "inlier_fraction": math.nan}


@dataclass(frozen=True, kw_only=True)
class IcpEKFConfig(FilterConfig):
    """Configuration of :class:`IcpEKF`; defaults are report 000's appendix A where it gives a value.

    Attributes
    ----------
    q_x_stat_m2, q_y_stat_m2 : float
        Static process noise per ``static_noise_period_s`` (eq. 13), m^2 (appendix: 0.0005).
    q_theta_stat_rad2 : float
        Static heading process noise, rad^2 (appendix: 0.0005).
    q_x_dyn_m2_per_m, q_y_dyn_m2_per_m : float
        Dynamic process noise per metre of world-frame increment |dx_w|, |dy_w| (eq. 13), m^2/m (appendix: 0.001).
    q_theta_dyn_rad2_per_rad : float
        Dynamic heading noise per radian turned, rad^2/rad (appendix: 0.0011).
    r_x_m2, r_y_m2 : float
        Observation noise of the ICP pose (eq. 16), m^2 (appendix: 0.008).
    r_theta_rad2 : float
        Observation noise of the ICP heading, rad^2 (appendix: 0.01).
    static_noise_period_s : float
        The odometry period the static terms refer to, s: rosaria's 10 Hz pose rate (0.1 s); each step's
        static term is scaled by dt / this period.
    max_iterations : int
        ICP iteration cap (appendix: 700).
    transformation_epsilon : float
        ICP convergence, PCL's meaning (appendix: 5e-7): squared translation change m^2, 1 - cos(rotation change).
    correspondence_sigmas : float
        k of the rejection distances D_min and D_0 (module docstring), in standard deviations of a correct
        pair's distance; replaces PCL's 0.002 m maximum correspondence distance. Default 3.
    max_correspondence_cap_m : float
        Upper bound of the initial rejection distance D_0, m (keeps pairs local when P is large). Default 1.
    min_matched_fraction : float
        Mismatch rule 2: at least this fraction of the smaller cloud must be matched. Default 0.5 (most of
        the scan agrees with the map); the report gives no value.
    min_matched_points : int
        And at least this many points. Default 10.
    kidnap_mismatches : int
        Consecutive mismatches that trigger the kidnap rule (sec. IV-B: 100).
    kidnap_cov_factor : float
        P is multiplied by this when the rule fires (sec. IV-B: 10).
    kidnap_threshold_factor : float
        The rejection distances are multiplied by this (< 1: tighter) from the rule firing to the next
        accepted match. Default 0.5; the report says "decreasing its threshold" without a value.
    laser_sigma_m : float or None
        Laser range noise for D_min/D_0, m; None takes the dataset's nominal ``laser_sigma_m``.
    """

    q_x_stat_m2: float = field(default=0.0005, metadata=bound(0.0, what="a variance"))
    q_y_stat_m2: float = field(default=0.0005, metadata=bound(0.0, what="a variance"))
    q_theta_stat_rad2: float = field(default=0.0005, metadata=bound(0.0, what="a variance"))
    q_x_dyn_m2_per_m: float = field(default=0.001, metadata=bound(0.0, what="a variance"))
    q_y_dyn_m2_per_m: float = field(default=0.001, metadata=bound(0.0, what="a variance"))
    q_theta_dyn_rad2_per_rad: float = field(default=0.0011, metadata=bound(0.0, what="a variance"))
    r_x_m2: float = field(default=0.008, metadata=tunable(1e-6, 0.1, log=True, base=POSITIVE))
    r_y_m2: float = field(default=0.008, metadata=tunable(1e-6, 0.1, log=True, base=POSITIVE))
    r_theta_rad2: float = field(default=0.01, metadata=tunable(1e-6, 0.1, log=True, base=POSITIVE))
    static_noise_period_s: float = field(default=0.1, metadata=POSITIVE)
    max_iterations: int = field(default=700, metadata=tunable(5, 700, log=True, integer=True, base=bound(1)))
    transformation_epsilon: float = field(default=5e-7, metadata=POSITIVE)
    correspondence_sigmas: float = field(default=3.0, metadata=tunable(1.0, 6.0, base=POSITIVE))
    max_correspondence_cap_m: float = field(default=1.0, metadata=POSITIVE)
    min_matched_fraction: float = field(default=0.5, metadata=bound(0.0, 1.0))
    min_matched_points: int = field(default=10, metadata=bound(MIN_PAIRS))
    kidnap_mismatches: int = field(default=100, metadata=bound(1))
    kidnap_cov_factor: float = field(default=10.0, metadata=bound(1.0))
    kidnap_threshold_factor: float = field(default=0.5, metadata=bound(0.0, 1.0, low_open=True))
    laser_sigma_m: float | None = field(default=None, metadata=POSITIVE_OR_DATASET)


class IcpEKF(Filter):
    """EKF on (x, y, theta): odometry prediction, ICP-against-the-map pose update (report 000).

    See the module docstring for the equations and the choices made. Diagnostics of :meth:`estimate`
    (after a scan; zeros and NaN after a predict): ``accepted`` and ``rejected`` (1 if the last scan was
    used / was a mismatch), ``iterations`` (ICP iterations), ``matched_points``, ``consecutive_mismatches``,
    ``kidnap_resets`` (times the kidnap rule fired so far), ``nis`` (V^T (P + R)^-1 V of an accepted scan).
    """

    id: ClassVar[str] = "ekf_icp"
    order: ClassVar[int] = 40
    description: ClassVar[str] = (
        "EKF whose update is ICP between the scan and a scan ray-cast from the occupancy grid (report 000)"
    )
    doc: ClassVar[FilterDoc | None] = FilterDoc(
        "000",
        "odometry increments in the world frame, Q static + dynamic (eq. 11-13)",
        "ICP between the scan and a scan ray-cast from the grid at the predicted pose, H = I (eq. 14-18); mismatch "
        "rules; after 100 mismatches P x 10 and a tighter ICP threshold",
        "a mismatch is an ICP that did not converge or matched too few points; the report's appendix parameters "
        "are the default config",
    )
    consumes: ClassVar[frozenset[type]] = frozenset({Odometry, LaserScan})
    requires: ClassVar[frozenset[MapKind]] = frozenset({MapKind.OCCUPANCY})
    Config: ClassVar[type[FilterConfig]] = IcpEKFConfig
    version: ClassVar[int] = 4
    health_nis_dof: ClassVar[float | None] = 3  # the H = I pose update
    cost_per_data_s: ClassVar[float] = 0.3
    source: ClassVar[str] = "000_2af74c528ee7b17b (EKF with LRF: eq. 11-18, sec. III-B, IV-B, appendix A)"

    config: IcpEKFConfig

    def unsupported(self, world: WorldMap) -> str | None:
        """A grid whose ray-cast tables exceed their memory limit is a stored skip with the reason, not a failed
        run."""
        if world.occupancy is None:
            return None
        try:
            _check_raycast_tables(world.occupancy)
        except ResourceLimit as exc:
            return str(exc)
        return None

    def reset(self, initial: Gaussian2, world: WorldMap, sensors: SensorSpec, rng: np.random.Generator) -> None:
        """Start from ``initial`` on ``world.occupancy``; ``rng`` is unused (the filter is deterministic)."""
        cfg = self.config
        grid = world.occupancy
        if grid is None:
            raise ConfigError("IcpEKF needs world.occupancy; the dataset provides no occupancy grid")
        if grid.origin[2] != 0.0:
            raise ConfigError(f"IcpEKF: the occupancy grid origin theta must be 0, got {grid.origin[2]}")
        _check_raycast_tables(grid)
        self._grid = grid
        self._res = float(grid.resolution)
        self._origin = (float(grid.origin[0]), float(grid.origin[1]))
        sigma_l = cfg.laser_sigma_m if cfg.laser_sigma_m is not None else sensors.laser_sigma_m
        if sigma_l is None:
            logger.warning("no nominal laser noise in the config or dataset; using %g m", DEFAULT_LASER_SIGMA_M)
            sigma_l = DEFAULT_LASER_SIGMA_M
        # Variance of a correct pair's distance: laser noise on both clouds' ranges plus cell quantisation.
        self._pair_var = 2.0 * sigma_l**2 + self._res**2 / 6.0
        m = np.asarray(initial.mean, dtype=np.float64)
        c = np.asarray(initial.cov, dtype=np.float64)
        # mean, covariance and constants in one buffer: the compiled steps take one array argument
        self._s = state_buffer(
            np.array([m[0], m[1], wrap_scalar(float(m[2]))]),
            0.5 * (c + c.T),
            (
                cfg.q_x_stat_m2,
                cfg.q_y_stat_m2,
                cfg.q_theta_stat_rad2,
                cfg.q_x_dyn_m2_per_m,
                cfg.q_y_dyn_m2_per_m,
                cfg.q_theta_dyn_rad2_per_rad,
            ),
            (cfg.r_x_m2, cfg.r_y_m2, cfg.r_theta_rad2),
            (self._pair_var, cfg.max_correspondence_cap_m),
        )
        self._t = math.nan
        self._last_odo_t: float | None = None
        self._consecutive = 0
        self._tightened = False
        self._kidnap_resets = 0
        self._diag = self._empty_diag()
        self._icp_health = _NO_ICP_HEALTH
        self._beams: dict[tuple[float, float, int, float], tuple[FloatArray, FloatArray, FloatArray]] = {}
        self._clouds: dict[int, tuple[FloatArray, FloatArray]] = {}

    def _empty_diag(self) -> dict[str, float]:
        return {
            "accepted": 0.0,
            "rejected": 0.0,
            "iterations": 0.0,
            "matched_points": 0.0,
            "consecutive_mismatches": float(self._consecutive),
            "kidnap_resets": float(self._kidnap_resets),
            "nis": math.nan,
        }

    # --- prediction (eq. 11-13) ------------------------------------------------------------------------

    def predict(self, u: Odometry) -> None:
        """Add the world-frame odometry increment (eq. 11); P = F P F^T + Q (eq. 5, 12, 13)."""
        cfg = self.config
        if u.dt is not None and u.dt > 0.0:
            dt = float(u.dt)
        elif self._last_odo_t is not None:
            dt = max(u.t - self._last_odo_t, 0.0)
        else:
            dt = cfg.static_noise_period_s
        self._last_odo_t = u.t
        finite = predict_pose(self._s, float(u.dx), float(u.dy), float(u.dtheta), dt / cfg.static_noise_period_s)
        self._t = u.t
        self._diag = self._empty_diag()
        if not finite:
            raise FilterDiverged(f"non-finite state after odometry at t={u.t:.3f}")

    # --- observation (sec. III-A.2, III-B) and update (eq. 14-18) ----------------------------------------

    def match(self, z: LaserScan) -> tuple[IcpResult | None, int, int]:
        """Ray-cast a scan at the predicted pose and ICP-align the real scan onto it.

        Returns
        -------
        (IcpResult or None, n_real, n_pred)
            None when either cloud has fewer than 3 points; the transform maps real-scan points (robot
            frame at the true pose) onto ray-cast points (robot frame at the predicted pose).
        """
        cfg = self.config
        angles, cos_a, sin_a = self._beam_directions(z)
        sx, sy, sth = z.sensor_pose
        x, y, th = self._s[0:3].tolist()
        c, s = math.cos(th), math.sin(th)
        sensor_world = np.array([x + c * sx - s * sy, y + s * sx + c * sy, th + sth])
        # the shared caster's one-scan path: its fields are cached with the grid object
        pred = cast_scan(self._grid, sensor_world, angles, z.range_max, parallel=False)
        real = np.asarray(z.ranges, dtype=np.float64)
        src, dst = self._cloud_buffers(real.shape[0])
        self._s[BUF_SIGMAS] = cfg.correspondence_sigmas * (cfg.kidnap_threshold_factor if self._tightened else 1.0)
        # both clouds' points (from the beams' cached directions) and the rejection distances
        n_real, n_pred, d_0, d_min = scan_clouds(
            self._s, real, pred, cos_a, sin_a, (sx, sy, z.range_min, z.range_max), src, dst
        )
        if n_real < MIN_PAIRS or n_pred < MIN_PAIRS:
            return None, n_real, n_pred
        # icp_2d without its checks: the clouds are already contiguous (n, 2) and the gates valid
        res = _icp.align(
            src[:n_real], dst[:n_pred], (d_0, d_min), int(cfg.max_iterations), float(cfg.transformation_epsilon)
        )
        return res, n_real, n_pred

    def _cloud_buffers(self, n: int) -> tuple[FloatArray, FloatArray]:
        """Scratch (n, 2) arrays for the two clouds of an n-beam scan (reused: the ICP loop does not keep them)."""
        bufs = self._clouds.get(n)
        if bufs is None:
            bufs = self._clouds[n] = (np.empty((n, 2)), np.empty((n, 2)))
        return bufs

    def _beam_directions(self, z: LaserScan) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The scan's beam angles (sensor frame) and cos, sin of angle + sensor heading, computed once per scan
        geometry (a laser's scans share it)."""
        key = (z.angle_min, z.angle_increment, int(z.ranges.shape[0]), z.sensor_pose[2])
        beams = self._beams.get(key)
        if beams is None:
            angles = z.angles
            a = angles + z.sensor_pose[2]
            beams = self._beams[key] = (angles, np.cos(a), np.sin(a))
        return beams

    def update(self, z: Observation) -> None:
        """Correct with one LaserScan: ICP match, mismatch rules, H = I update (eq. 14-18) or kidnap rule."""
        self.check_consumes(z)
        assert isinstance(z, LaserScan)
        cfg = self.config
        res, n_real, n_pred = self.match(z)
        self._t = z.t
        pairable = min(n_real, n_pred)
        self._icp_health = {
            "icp_rmse_m": float(res.rmse_m) if res is not None else math.nan,
            "inlier_fraction": float(res.matched) / pairable if res is not None and pairable > 0 else math.nan,
        }
        needed = max(cfg.min_matched_points, math.ceil(cfg.min_matched_fraction * min(n_real, n_pred)))
        if res is None or not res.converged or res.matched < needed:
            self._mismatch(z.t, res)
            return
        # V = Z - Z^ with Z = X (+) M (eq. 2-3): the ICP translation rotated into the world frame; eq. 15-18 with
        # H = I (the ICP correction measures the pose itself, eq. 14): K = P (P + R)^-1, x + K V, Joseph form.
        finite, nis = correct_pose(self._s, *res.transform)
        if not finite:
            raise FilterDiverged(f"non-finite state after the scan update at t={z.t:.3f}")
        self._consecutive = 0
        self._tightened = False  # the report's tighter threshold holds until the filter matches again
        self._diag = {
            **self._empty_diag(),
            "accepted": 1.0,
            "iterations": float(res.iterations),
            "matched_points": float(res.matched),
            "nis": nis,
        }

    def _mismatch(self, t: float, res: IcpResult | None) -> None:
        """No update (sec. III-B); after ``kidnap_mismatches`` in a row, P x factor and a tighter threshold."""
        cfg = self.config
        self._consecutive += 1
        if self._consecutive >= cfg.kidnap_mismatches:
            self._s[3:12] *= cfg.kidnap_cov_factor
            self._tightened = True
            self._kidnap_resets += 1
            self._consecutive = 0
            logger.debug("t=%.2f s: %d consecutive mismatches, P x %g", t, cfg.kidnap_mismatches, cfg.kidnap_cov_factor)
        self._diag = {
            **self._empty_diag(),
            "rejected": 1.0,
            "iterations": float(res.iterations) if res is not None else 0.0,
            "matched_points": float(res.matched) if res is not None else 0.0,
        }

    def event_health(self) -> dict[str, float]:
        """The last scan's ``icp_rmse_m`` and ``inlier_fraction`` (NaN before the first scan), beside the default
        :meth:`health`'s Gaussian signals (NIS of the H = I pose update, ``health_nis_dof`` = 3)."""
        return dict(self._icp_health)

    def estimate(self) -> Estimate:
        """The current pose and covariance with the diagnostics of the last call."""
        s = self._s
        return Estimate(t=self._t, mean=s[0:3].copy(), cov=s[3:12].reshape(3, 3).copy(), diagnostics=dict(self._diag))


def _check_raycast_tables(grid: OccupancyGrid) -> None:
    """Refuse (:class:`ResourceLimit`) a grid whose ray-cast tables would exceed the tables' memory limit."""
    check_bytes(
        "ekf_icp",
        f"the ray-cast tables of a {grid.shape[0]} x {grid.shape[1]} grid",
        grid_cells(grid.shape) * RAYCAST_BYTES_PER_CELL,
        "give a coarser or smaller map",
    )
