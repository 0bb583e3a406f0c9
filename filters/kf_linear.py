"""A linear Kalman filter with a scan-database pose measurement (report 004, Bettaieb).

Report 004 runs a textbook linear KF (section I: x_p = A x + B u, P_p = A P A^T + Q, y = z - H x_p,
S = H P_p H^T + R, K = P_p H^T S^-1, x = x_p + K y, P = (I - K H) P_p) with

* a **velocity model** (section II): for a command (v, omega) held for dt,

      x_p = x + cos(theta) dt v,   y_p = y + sin(theta) dt v,   theta_p = theta + dt omega

  (the report prints cos(omega) and v_x, v_y; the heading and one forward speed are meant);
* a **sensor model**: the live scan tolerance-matched against scans recorded at known poses
  (:mod:`locbench.filters._scan_database`), giving a pose measurement, so H = I.

The linearity assumption, made visible
--------------------------------------
cos(theta) and sin(theta) make the motion nonlinear in the state. As in the report, the heading of the
current estimate is used as a **fixed coefficient** of the input matrix, so the prediction is linear in
(state, input):

    F = I,   B = [[cos(theta_hat) dt, 0], [sin(theta_hat) dt, 0], [0, dt]],   u = (v, omega).

Two things follow, both by design and both measured by ``scan_grid`` against
``scan_grid[mixed_commands=true]``: (1) the translation uses the heading at the *start* of the command,
exact when a command only translates or only rotates (report 004: "the ability to only control either the
translational and rotational velocity independent of each other ... satisfied the Kalman filter's linearity
assumption") and off by about v dt * omega dt / 2 sideways per command when it does both; (2) with F = I
the covariance never carries the coupling d(x, y)/d(theta) that an EKF's Jacobian adds, so heading
uncertainty does not widen the position uncertainty.

Prediction input: the commanded (v, omega, dt) of the Odometry event when present (report 004), else the
odometry increment (dx, dy, dtheta) in the previous robot frame, again with the estimated heading as a
fixed coefficient: B = [[c, -s, 0], [s, c, 0], [0, 0, 1]], u = (dx, dy, dtheta).

Process noise Q (the report only says the velocity error "was assumed gaussian"): the dataset's nominal
per-distance odometry noise (``SensorSpec.odometry_sigma_*``, read as in :mod:`locbench.filters._motion`)
for the step's travel |v| dt and turn |omega| dt, plus a small additive floor per step (config).

Update: the pose from the scan database with its covariance R (H = I); the heading innovation is
wrapped by handing filterpy a measurement whose heading is the estimate's plus the wrapped difference.
A scan with no database entry within the tolerance (and, by default, inside a chi-square validation
region of the predicted belief, see ``gate_probability``) gives no update and is counted (``no_match``).
PoseFix events are **not** consumed: report 004's filter fuses only its velocity and sensor models.

The prediction is written out for F = I (x + B u, P + Q; with B's zero entries each component of a commanded
B u is one product); the update is the Kalman core's Joseph form with H = I
(:func:`locbench.filters._kalman.joseph_correct`), and the NIS y^T S^-1 y is taken by a solve with S.
``tests/filters/test_kf_linear.py`` holds both steps to filterpy's ``KalmanFilter`` within rounding.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt
from scipy.stats import chi2

from locbench.core.errors import ConfigError, FilterDiverged
from locbench.core.events import LaserScan, Observation, Odometry
from locbench.core.geometry import wrap_scalar
from locbench.core.tunable import tunable
from locbench.datasets.dataset import Gaussian2, MapKind, SensorSpec, WorldMap
from locbench.filters._kalman import joseph_correct
from locbench.filters._motion import increment_variances, resolve_motion_noise
from locbench.filters._scan_database import ScanDatabase, build_database, lattice_too_large, match_scan
from locbench.filters.base import NON_NEGATIVE, Estimate, Filter, FilterConfig, FilterDoc, bound

FloatArray = npt.NDArray[np.float64]
logger = logging.getLogger(__name__)

_NAN = float("nan")
#: The diagnostics after a predict (``no_match`` filled in per call); copied, the order is the stored one.
_EMPTY_DIAG: dict[str, float] = {
    "nis": _NAN,
    "accepted": 0.0,
    "rejected": 0.0,
    "n_matches": _NAN,
    "match_score_m": _NAN,
    "no_match": 0.0,
    "linear_input": _NAN,
}
#: H of the pose measurement.
_I3 = np.eye(3)

#: Laser range noise assumed for the default tolerance when the dataset gives none, m.
DEFAULT_LASER_SIGMA_M = 0.01


@dataclass(frozen=True, kw_only=True)
class LinearKFConfig(FilterConfig):
    """Configuration of :class:`LinearKF`.

    Attributes
    ----------
    grid_step_m : float
        Spacing of the database positions, m. Report 004 gives none; 0.25 m, the default spacing of
        ``scan_grid`` (set it equal to the dataset's ``grid_step_m``).
    heading_step_deg : float
        Spacing of the database headings, deg; must divide 45 (the bearing spacing). 5 deg default.
    tolerance_m : float or None
        Largest mean absolute range difference of a match, m. None: grid_step_m / 2 + the nominal laser
        sigma, the mean difference at which a pose about half a cell from a database pose still matches
        on walls seen head-on, plus the noise.
    max_range_m : float
        Range cap of the recorded scans, m (scan ranges are capped at the smaller of this and their own
        range_max).
    clearance_m : float
        Database positions keep at least this distance from occupied cells, m.
    min_bearings : int
        Fewest of the eight bearings a scan must cover to be matched (a 240 deg laser covers 5).
    gate_probability : float
        Matches are kept only when the matched database pose lies inside this chi-square (3 dof)
        validation region of the predicted belief (covariance P plus the database quantisation). Report
        004 matches globally (``1.0`` switches the gate off, as in the report); a gate is needed in any
        room with symmetries, where the global best match can be the mirror pose. 0.999 -> 16.27.
    use_commands : bool
        Predict from the commanded (v, omega, dt) when the event has it (report 004); False always uses
        the (dx, dy, dtheta) increment.
    sigma_floor_xy_m, sigma_floor_theta_rad : float
        Additive process noise per odometry event (world frame), m and rad, on top of the per-distance
        noise: keeps P from collapsing while standing still.
    odometry_sigma_xy_per_m, odometry_sigma_theta_per_m, odometry_sigma_theta_per_rad : float or None
        Overrides of the dataset's nominal per-distance noise (m/sqrt(m), rad/sqrt(m), rad/sqrt(rad)).
    """

    grid_step_m: float = field(default=0.25, metadata=bound(0.0, low_open=True, unit="m"))
    heading_step_deg: float = 5.0
    tolerance_m: float | None = field(
        default=None,
        metadata=tunable(
            0.02, 1.0, log=True, base=bound(0.0, low_open=True, unit="m", optional=True, none_means="the default")
        ),
    )
    max_range_m: float = field(
        default=8.0, metadata=bound(0.0, low_open=True, finite=True, unit="m", what="a finite distance")
    )
    clearance_m: float = field(default=0.2, metadata=bound(0.0, unit="m"))
    min_bearings: int = field(default=4, metadata=bound(1, 8, expected="in 1..8"))
    gate_probability: float = field(
        default=0.999,
        metadata=tunable(0.9, 0.99999, base=bound(0.0, 1.0, low_open=True, expected="in (0, 1] (1 = no gate)")),
    )
    use_commands: bool = True
    sigma_floor_xy_m: float = field(default=0.001, metadata=NON_NEGATIVE)
    sigma_floor_theta_rad: float = field(default=0.0005, metadata=NON_NEGATIVE)
    odometry_sigma_xy_per_m: float | None = field(default=None, metadata=tunable(1e-3, 0.2, log=True))
    odometry_sigma_theta_per_m: float | None = field(default=None, metadata=tunable(1e-3, 0.5, log=True))
    odometry_sigma_theta_per_rad: float | None = None

    def __post_init__(self) -> None:
        super().__post_init__()  # the bounds declared on the fields; the step rule follows
        q = 45.0 / self.heading_step_deg if self.heading_step_deg > 0 else 0.5
        if abs(q - round(q)) > 1e-9 or round(q) < 1:
            raise ConfigError(f"heading_step_deg must divide 45 deg exactly (5, 15, 45), got {self.heading_step_deg}")


class LinearKF(Filter):
    """Report 004's linear Kalman filter: velocity model with the heading as a fixed input coefficient,
    pose measurements from a scan database (see the module docstring).

    Diagnostics of :meth:`estimate`: ``nis`` (of the last accepted scan; NaN after a predict), ``accepted``
    and ``rejected`` (1/0 for the last scan: rejected = no database entry within the tolerance),
    ``n_matches`` (entries within the tolerance), ``match_score_m`` (best mean absolute difference),
    ``no_match`` (scans without a match so far), ``linear_input`` (1 when the last predict used the
    commanded twist, 0 for the increment).
    """

    id: ClassVar[str] = "kf_linear"
    order: ClassVar[int] = 50
    description: ClassVar[str] = "linear Kalman filter (filterpy) with a scan-database pose measurement (report 004)"
    requires_modules: ClassVar[tuple[str, ...]] = ("filterpy",)
    install_hint: ClassVar[str] = "pip install 'locbench[filterpy]'"
    doc: ClassVar[FilterDoc | None] = FilterDoc(
        "004",
        "filterpy `KalmanFilter`, translate-or-rotate velocity model",
        "pose from matching 8 ranges of the scan against a database of scans at known grid poses (average "
        "absolute difference under a tolerance)",
        "a true linear KF, with its linearity assumption visible in the results",
    )
    consumes: ClassVar[frozenset[type]] = frozenset({Odometry, LaserScan})
    requires: ClassVar[frozenset[MapKind]] = frozenset({MapKind.OCCUPANCY})
    Config: ClassVar[type[FilterConfig]] = LinearKFConfig
    # 2: estimates equal to version 1's to rounding (stored version-1 runs moved by at most 5.6e-10 m in waypoint
    # errors)
    version: ClassVar[int] = 2
    health_nis_dof: ClassVar[float | None] = 3  # the pose fix
    cost_per_data_s: ClassVar[float] = 0.3
    source: ClassVar[str] = "004_2a620520509b0112 (linear KF, velocity model and scan-database sensor model, sec. I-II)"

    config: LinearKFConfig

    def unsupported(self, world: WorldMap) -> str | None:
        """The database's memory bound (:data:`~locbench.filters._scan_database.MAX_LATTICE_POSITIONS`): a map too
        large for it at ``grid_step_m`` is a stored skip with the reason, not a failed run."""
        if world.occupancy is None or not self.config.grid_step_m > 0:
            return None
        return lattice_too_large(world.occupancy, self.config.grid_step_m)

    def reset(self, initial: Gaussian2, world: WorldMap, sensors: SensorSpec, rng: np.random.Generator) -> None:
        """Record the scan database on the world's occupancy grid and start from ``initial``; ``rng`` is unused."""
        cfg = self.config
        if world.occupancy is None:
            raise ConfigError("LinearKF needs world.occupancy (an occupancy grid); the dataset provides none")
        self._db: ScanDatabase = build_database(
            world.occupancy, cfg.grid_step_m, cfg.heading_step_deg, cfg.max_range_m, cfg.clearance_m
        )
        sigma_laser = sensors.laser_sigma_m if sensors.laser_sigma_m is not None else DEFAULT_LASER_SIGMA_M
        self._tol = cfg.tolerance_m if cfg.tolerance_m is not None else 0.5 * cfg.grid_step_m + sigma_laser
        noise = resolve_motion_noise(
            sensors,
            odometry_sigma_xy_per_m=cfg.odometry_sigma_xy_per_m,
            odometry_sigma_theta_per_m=cfg.odometry_sigma_theta_per_m,
            odometry_sigma_theta_per_rad=cfg.odometry_sigma_theta_per_rad,
        )
        p = cfg.gate_probability
        self._gate = math.inf if p >= 1.0 else float(chi2.ppf(p, 3))
        self._sig = (noise.sigma_xy_per_m, noise.sigma_theta_per_m, noise.sigma_theta_per_rad)
        x = np.asarray(initial.mean, dtype=np.float64).reshape(3, 1).copy()
        x[2, 0] = wrap_scalar(float(x[2, 0]))
        self._x: FloatArray = x  # (3, 1), filterpy's layout; replaced, never written in place, after reset
        self._P: FloatArray = np.asarray(initial.cov, dtype=np.float64).copy()
        self._t = 0.0
        self._no_match = 0
        self._diag: dict[str, float] = self._empty_diag()
        logger.debug("LinearKF: %d database entries, tolerance %.3f m", len(self._db), self._tol)

    def _empty_diag(self) -> dict[str, float]:
        d = dict(_EMPTY_DIAG)
        d["no_match"] = float(getattr(self, "_no_match", 0))
        return d

    # --- predict ---------------------------------------------------------------------------------

    def predict(self, u: Odometry) -> None:
        """Linear prediction x = x + B u with the estimated heading frozen in B; P = P + Q (F = I)."""
        x0, x1, th = self._x[:, 0].tolist()
        c, s = math.cos(th), math.sin(th)
        use_cmd = self.config.use_commands and u.v is not None and u.omega is not None and u.dt is not None
        if use_cmd:
            dt, v, om = float(u.dt), float(u.v), float(u.omega)  # type: ignore[arg-type]
            dist, turn = abs(v) * dt, abs(om) * dt
        else:
            B = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
            uu = np.array([[u.dx], [u.dy], [u.dtheta]])
            dist, turn = math.hypot(u.dx, u.dy), abs(u.dtheta)
        sxy, stm, str_ = self._sig
        var_xy, var_th = increment_variances(dist, 0.0, turn, sxy, stm, str_)
        cfg = self.config
        q_xy = var_xy + cfg.sigma_floor_xy_m**2
        q_th = var_th + cfg.sigma_floor_theta_rad**2
        # x = F x + B u, P = F P F^T + Q with F = I: x + B u, P + Q
        if use_cmd:
            # B = [[c dt, 0], [s dt, 0], [0, dt]]: each row of B u has one nonzero product
            x_new = [x0 + (c * dt) * v, x1 + (s * dt) * v, wrap_scalar(th + dt * om)]
        else:
            x_new = (self._x + np.dot(B, uu))[:, 0].tolist()  # three-term rows: BLAS's rounding kept
            x_new[2] = wrap_scalar(x_new[2])
        P = self._P.tolist()
        self._x = np.array([[x_new[0]], [x_new[1]], [x_new[2]]])
        self._P = np.array(
            [
                [P[0][0] + q_xy, P[0][1] + 0.0, P[0][2] + 0.0],
                [P[1][0] + 0.0, P[1][1] + q_xy, P[1][2] + 0.0],
                [P[2][0] + 0.0, P[2][1] + 0.0, P[2][2] + q_th],
            ]
        )
        self._check_finite(u.t)
        self._t = u.t
        self._diag = self._empty_diag()
        self._diag["linear_input"] = 1.0 if use_cmd else 0.0

    # --- update ----------------------------------------------------------------------------------

    def update(self, z: Observation) -> None:
        """Match the scan against the database; fuse the pose (H = I) or count a miss."""
        self.check_consumes(z)
        assert isinstance(z, LaserScan)
        self._t = z.t
        self._diag = self._empty_diag()
        x, P = self._x, self._P
        match, _ = match_scan(
            self._db, z, self._tol, self.config.min_bearings, prior=(x.reshape(3), P), gate=self._gate
        )
        if match is None:
            self._no_match += 1
            self._diag.update(rejected=1.0, no_match=float(self._no_match))
            return
        x0, x1, th = x[:, 0].tolist()
        z0, z1, zt = match.z.tolist()
        # the heading innovation wrapped: z's heading put within pi of the estimate's
        zt = th + wrap_scalar(zt - th)
        y = np.array([z0 - x0, z1 - x1, zt - th])
        c = joseph_correct(x.reshape(3), P, y, _I3, match.cov)
        x_new = c.x.reshape(3, 1)
        x_new[2, 0] = wrap_scalar(float(x_new[2, 0]))
        self._x = x_new
        self._P = c.P
        self._check_finite(z.t)
        nis = float(y @ np.linalg.solve(c.S, y))
        self._diag.update(
            nis=nis,
            accepted=1.0,
            n_matches=float(match.n_matches),
            match_score_m=match.best_score_m,
        )

    def _check_finite(self, t: float) -> None:
        # math.isfinite over the 12 floats: the verdict of np.all(np.isfinite(...)) without two reductions
        if not all(map(math.isfinite, self._x[:, 0].tolist() + self._P.ravel().tolist())):
            raise FilterDiverged(f"LinearKF: non-finite state at t={t:.3f} s")

    # --- output ----------------------------------------------------------------------------------

    def estimate(self) -> Estimate:
        """Current mean (x, y, theta) and covariance."""
        return Estimate(t=self._t, mean=self._x.reshape(3).copy(), cov=self._P.copy(), diagnostics=dict(self._diag))

    def extra_results(self) -> dict[str, Any]:
        """The number of scans without a database match and the database size."""
        return {"no_match_scans": np.array(self._no_match), "database_entries": np.array(len(self._db))}
