"""Fixed-lag smoothing localization with gtsam: odometry between-factors and range-bearing to known landmarks.

The belief over the recent trajectory is a factor graph over poses X_i (gtsam ``Pose2``) that gtsam's
fixed-lag smoother (``IncrementalFixedLagSmoother``, iSAM2, by default, or ``BatchFixedLagSmoother``,
Levenberg-Marquardt) keeps to the last ``lag_s`` seconds, marginalising older variables into a prior on
the ones that remain (Dellaert & Kaess, "Factor Graphs for Robot Perception", 2017, sec. 5; the gtsam
4.3 API is described in ``shared/docs/PACKAGES.md`` sec. 3).

Factors
-------
* **Prior** on X_0 from the dataset's initial belief.
* **Odometry** (``BetweenFactorPose2``): the wheel-encoder model of report 003 (eq. 1-5, input noise
  eq. 10, read per step) or the increment fallback, through :class:`locbench.filters._motion.MotionModel`,
  plus a small additive noise per step (report 003 eq. 8, the same defaults as ``ekf_landmarks``). The
  steps between two graph poses are composed into one increment Delta = (dx, dy, dtheta) in the frame of
  the older pose, its covariance Sigma propagated with the model's Jacobians, Sigma <- F Sigma F^T + N;
  gtsam's between error is expressed in the frame of the newer pose, so the factor gets the full 3x3
  Gaussian blockdiag(R(dtheta)^T, 1) Sigma blockdiag(R(dtheta), 1).
* **Landmarks** (``BearingRangeFactor2D``): range and bearing (report 003 eq. 7, 9) to a landmark
  variable L held at its map position by a tight ``PriorFactorPoint2`` (``landmark_sigma_m``, or the
  map's ``std_xy`` when given). gtsam has no native range-bearing factor to a constant point, so the
  known map enters as these nearly fixed variables. A landmark variable is stamped with the time of every
  sighting; one not seen for ``lag_s`` leaves the window with the poses, and its next sighting makes a
  fresh variable with a fresh prior (so the map prior is counted once more, harmless at 1 mm).
* **Beacon ranges** (``RangeFactor2D``, gtsam's pose-to-point range factor, for
  :class:`~locbench.core.events.RangeObservations`): the distance from the robot origin to a beacon of
  ``world.landmarks``, attached to the same landmark variables as the sightings. Ranging radios produce gross
  outliers, so two defences, both configured: (1) a gate on the innovation against the current filtered
  belief, nu^2 / (H P H^T + sigma^2) inside the chi-square (1 dof) quantile of ``range_gate_probability``
  (0.99, as ``ekf_landmarks``; 1 disables it), which drops ranges that are far off before they enter the
  graph; (2) a Huber M-estimator on the ranges that do enter (``range_robust="huber"``, threshold
  ``range_huber_k`` = 1.345 whitened units, the classic 95 %-efficiency constant of Huber 1981 for Gaussian
  data), which bounds the pull of a residual beyond k sigma once the smoother relinearises. A range of an
  unknown id is rejected (a range cannot be associated by nearest neighbour).
* **Pose fixes** (``PriorFactorPose2``, when ``use_pose_fixes``): a 2-D fix is a pose prior whose
  heading standard deviation is ``pose_fix_heading_sigma_rad`` (1000 rad: no heading information); a 3-D
  fix uses its full covariance. Both are rotated into the prior's frame, as gtsam measures the error there.

Graph size (``new_pose``)
-------------------------
``"observation"`` (default): a new pose variable is made only when an observation is fused; ``predict``
composes the odometry step onto the running increment in plain floats and reports the newest graph pose
composed with it (mean X_k (+) Delta, covariance F P_k F^T + G Sigma G^T, the EKF prediction from the
smoother's marginal P_k). The graph holds a pose per sighting (5 Hz on ``room``) instead of per odometry
event (20 Hz), the smoother runs only at observations, and the estimate differs from ``"odometry"`` only
through the linearisation of the composed increment (tests check they agree). ``"odometry"`` makes a
variable for every odometry event and updates the smoother each time (4x the variables and updates).

Association
-----------
With ``association="known"`` an observation's landmark id is used. An id of ``UNKNOWN_ID`` (or every
observation with ``association="nearest"``) is matched to the map landmark whose predicted (range,
bearing) from the current filtered estimate is nearest in Mahalanobis distance, S = H P H^T + R, among
landmarks predicted inside the sensor's range and field of view (widened by the margins) and not used
by the same event; a match beyond the chi-square gate (2 dof, ``gate_probability``) is rejected and
counted in ``rejected``. This is the same rule as ``ekf_landmarks`` so the two are compared on equal terms.

Frames and units: poses (x m, y m, theta rad) in the world frame, headings wrapped to (-pi, pi]. gtsam's
marginal covariance of a ``Pose2`` is in its body-frame tangent space; :meth:`estimate` rotates it to
world (x, y, theta) coordinates, as the other filters report.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import numpy as np
import numpy.typing as npt

from locbench.core.errors import ConfigError, FilterDiverged
from locbench.core.events import UNKNOWN_ID, LandmarkObservations, Observation, Odometry, PoseFix, RangeObservations
from locbench.core.geometry import wrap_angle, wrap_scalar
from locbench.core.runkey import RUN_KEY_OMIT_IF_DEFAULT
from locbench.core.tunable import tunable
from locbench.datasets.dataset import Gaussian2, MapKind, SensorSpec, WorldMap
from locbench.filters._kalman import chi2_1dof_quantile, chi2_2dof_quantile
from locbench.filters._landmark_index import INDEX_MIN_LANDMARKS, LandmarkIndex, gate_radius
from locbench.filters._motion import (
    MotionKind,
    MotionModel,
    MotionNoiseConfig,
    propagate_covariance,
)
from locbench.filters._noise import landmark_noise, process_noise, range_only_noise
from locbench.filters.base import (
    NON_NEGATIVE,
    NON_NEGATIVE_OR_NONE,
    POSITIVE,
    POSITIVE_OR_DATASET,
    PROBABILITY,
    Estimate,
    Filter,
    FilterConfig,
    FilterDoc,
    bound,
)

try:
    import gtsam

    _X = gtsam.symbol_shorthand.X
    _L = gtsam.symbol_shorthand.L
except ImportError:  # pragma: no cover - the class stays readable; its requires_modules make it unavailable
    pass

FloatArray = npt.NDArray[np.float64]
logger = logging.getLogger(__name__)


#: Floor of the process noise (m, rad per odometry step): a standstill increment with zero process noise (a
#: model-matched world, whose robot stands at waypoints) has a singular covariance, which a between factor
#: cannot whiten. 1 % of report 003's variance: its effect on a run is far below the encoder noise.
MIN_PROCESS_SIGMA = (1e-4, 5e-5)


@dataclass(frozen=True, kw_only=True)
class GtsamFLSConfig(FilterConfig, MotionNoiseConfig):
    """Configuration of :class:`GtsamFixedLagSmoother`.

    Attributes
    ----------
    smoother : {"incremental", "batch"}
        ``gtsam.IncrementalFixedLagSmoother`` (iSAM2) or ``gtsam.BatchFixedLagSmoother`` (Levenberg-Marquardt
        over the whole window at every update).
    lag_s : float
        Smoother window, s: variables stamped earlier than the newest stamp minus ``lag_s`` are marginalised.
    new_pose : {"observation", "odometry"}
        Make a pose variable per fused observation (odometry composed in between) or per odometry event.
    relinearize_threshold : float
        iSAM2 relinearisation threshold on the tangent-space update (m, rad); gtsam's default is 0.1, 0.01
        relinearises any pose that moved by more than 1 cm or 10 mrad.
    relinearize_skip : int
        iSAM2 checks for relinearisation every this many updates (gtsam default 10; 1 checks every update).
    sigma_xy_m, sigma_theta_rad : float or None
        Additive process noise per odometry step (report 003 eq. 8), isotropic in x, y; None takes the
        dataset's value, else the defaults of ``ekf_landmarks`` (1 mm, 0.5 mrad;
        :func:`locbench.filters._noise.process_noise`). A between factor's noise must be invertible, so each
        is at least :data:`MIN_PROCESS_SIGMA` (a model-matched world declares 0 and its robot stands still).
    input_noise : {"per_step", "cumulative"}
        Reading of report 003 eq. 10, as in ``ekf_landmarks``: per-step variance k^2 |delta l_k| (Chong and
        Kleeman) or the literal accumulated sum.
    motion_model : {"auto", "encoder", "increment"}
        As in ``ekf_landmarks``: the encoder model (eq. 1-5) when the event has wheel travel and the dataset
        gives the wheelbase and encoder constants (``"auto"``), always when wheel travel exists
        (``"encoder"``), or the (dx, dy, dtheta) increment (``"increment"``).
    association : {"known", "nearest"}
        Use observation ids, or associate every observation by nearest neighbour (``UNKNOWN_ID`` always is).
    gate_probability : float
        Chi-square (2 dof) gate of nearest-neighbour association; 0.99 -> 9.21.
    prune_margin_m, prune_margin_rad : float
        Margins on the sensor's range interval (m) and each side of its field of view (rad) when selecting
        nearest-neighbour candidates.
    landmark_sigma_m : float
        Standard deviation of the prior holding each landmark variable at its map position, m, when the
        map gives no ``std_xy`` (1 mm: PACKAGES.md sec. 3).
    use_pose_fixes : bool
        Fuse PoseFix events as pose priors; when False the runner does not route them.
    pose_fix_heading_sigma_rad : float
        Heading standard deviation of the prior made from a 2-D fix, rad (large: no heading information).
    sigma_range_m, sigma_bearing_rad : float or None
        Range-bearing noise (report 003 eq. 9); None takes the dataset's nominal value.
    range_only_sigma_m : float or None
        Standard deviation of a beacon range, m; None takes ``SensorSpec.range_sigma_m``.
    range_gate_probability : float
        Chi-square (1 dof) gate on each beacon range's innovation against the filtered belief; 1 disables it.
    range_robust : {"huber", "none"}
        Noise model of the range factors: a Huber M-estimator on the Gaussian, or the Gaussian alone.
    range_huber_k : float
        Huber threshold in whitened units (sigmas); 1.345 (Huber 1981).
    wheelbase_m, encoder_k_left, encoder_k_right : float or None
        Overrides of W (m) and k_L, k_R (sqrt(m)); None takes the dataset's value.
    odometry_sigma_xy_per_m, odometry_sigma_theta_per_m, odometry_sigma_theta_per_rad : float or None
        Overrides of the increment fallback noise (m/sqrt(m), rad/sqrt(m), rad/sqrt(rad)).
    twist_sigma_v_mps, twist_sigma_omega_radps : float or None
        Overrides of the white noise of a measured twist (m/s, rad/s); see :mod:`locbench.filters._motion`.
    """

    smoother: Literal["incremental", "batch"] = "incremental"
    lag_s: float = field(default=2.0, metadata=bound(0.0, low_open=True, unit="s"))
    new_pose: Literal["observation", "odometry"] = "observation"
    relinearize_threshold: float = field(default=0.01, metadata=NON_NEGATIVE)
    relinearize_skip: int = field(default=1, metadata=bound(1))
    sigma_xy_m: float | None = field(default=None, metadata=NON_NEGATIVE_OR_NONE)
    sigma_theta_rad: float | None = field(default=None, metadata=NON_NEGATIVE_OR_NONE)
    motion_model: MotionKind = "auto"
    association: Literal["known", "nearest"] = "known"
    gate_probability: float = field(default=0.99, metadata=PROBABILITY)
    prune_margin_m: float = field(default=0.5, metadata=NON_NEGATIVE)
    prune_margin_rad: float = field(default=0.2, metadata=NON_NEGATIVE)
    landmark_sigma_m: float = field(default=0.001, metadata=POSITIVE)
    use_pose_fixes: bool = False
    pose_fix_heading_sigma_rad: float = field(default=1000.0, metadata=POSITIVE)
    sigma_range_m: float | None = field(default=None, metadata=tunable(1e-3, 1.0, log=True, base=POSITIVE_OR_DATASET))
    sigma_bearing_rad: float | None = field(
        default=None, metadata=tunable(1e-3, 0.5, log=True, base=POSITIVE_OR_DATASET)
    )
    range_only_sigma_m: float | None = field(default=None, metadata=POSITIVE_OR_DATASET | RUN_KEY_OMIT_IF_DEFAULT)
    range_gate_probability: float = field(
        default=0.99, metadata=bound(0.0, 1.0, low_open=True, base=RUN_KEY_OMIT_IF_DEFAULT)
    )
    range_robust: Literal["huber", "none"] = field(default="huber", metadata=RUN_KEY_OMIT_IF_DEFAULT)
    range_huber_k: float = field(default=1.345, metadata=POSITIVE | RUN_KEY_OMIT_IF_DEFAULT)


def _rot3(theta: float) -> FloatArray:
    """blockdiag(R(theta), 1): body-frame (x, y, theta) perturbations to world coordinates, shape (3, 3)."""
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _sym(a: FloatArray) -> FloatArray:
    return 0.5 * (a + a.T)


_Upper = tuple[float, float, float, float, float, float]


def _rotate_cov(c: float, s: float, p: list[list[float]]) -> _Upper:
    """R P R^T for R = blockdiag([[c, -s], [s, c]], 1) and a symmetric 3x3 nested list P, in plain floats.

    Reads only the upper triangle of ``p`` and returns the upper triangle of the result (00, 01, 02, 11,
    12, 22). With (c, s) of theta this takes body-frame (x, y, theta) covariance to world coordinates.
    """
    (p00, p01, p02), (_, p11, p12), (_, _, p22) = p
    cc, ss, cs = c * c, s * s, c * s
    w00 = cc * p00 - 2.0 * cs * p01 + ss * p11
    w01 = cs * (p00 - p11) + (cc - ss) * p01
    w02 = c * p02 - s * p12
    w11 = ss * p00 + 2.0 * cs * p01 + cc * p11
    w12 = s * p02 + c * p12
    return (w00, w01, w02, w11, w12, p22)


class GtsamFixedLagSmoother(Filter):
    """gtsam fixed-lag smoother over recent poses, with odometry, range-bearing landmarks and pose fixes.

    See the module docstring for the factors and choices. :meth:`estimate` is the filtered belief (the
    newest pose, composed with the odometry since it); :meth:`extra_results` gives the lag-smoothed
    trajectory.

    Diagnostics of :meth:`estimate`: ``nis`` (sum of the NIS of the sightings fused by the last update,
    against the belief before it; NaN after a predict or when none was fused), ``nis_dof``, ``accepted``
    and ``rejected`` (counts of the last update), ``window_poses`` (pose variables in the smoother after the
    last smoother update) and ``iterations`` (of the last smoother update; NaN when the smoother did not run).
    """

    id: ClassVar[str] = "gtsam_fls"
    order: ClassVar[int] = 70
    description: ClassVar[str] = (
        "gtsam fixed-lag smoother (incremental or batch): odometry between-factors, bearing-range factors, fixes"
    )
    requires_modules: ClassVar[tuple[str, ...]] = ("gtsam",)
    install_hint: ClassVar[str] = "pip install 'locbench[gtsam]'"
    doc: ClassVar[FilterDoc | None] = FilterDoc(
        "gtsam 4.3",
        "odometry between-factors (same noise model as `ekf_landmarks`)",
        "bearing-range factors to prior-held landmarks, pose priors for fixes; incremental (iSAM2) or batch "
        "fixed-lag smoother; filtered estimate scored, smoothed trajectory reported beside",
    )
    consumes: ClassVar[frozenset[type]] = frozenset({Odometry, LandmarkObservations, PoseFix, RangeObservations})
    requires: ClassVar[frozenset[MapKind]] = frozenset({MapKind.LANDMARKS})
    Config: ClassVar[type[FilterConfig]] = GtsamFLSConfig
    # 3: the process noise is the dataset's when it declares one (MIN_PROCESS_SIGMA on a model-matched world)
    version: ClassVar[int] = 3
    cost_per_data_s: ClassVar[float] = 0.1
    source: ClassVar[str] = (
        "gtsam 4.3 fixed-lag smoothers (Dellaert & Kaess 2017); 003_e5c93f9be776ee5e (motion eq. 1-10, "
        "range-bearing eq. 7, 9); 001_71e01b0c4f2511a1 (GPS fixes)"
    )

    config: GtsamFLSConfig

    def routed_events(self) -> frozenset[type]:
        """``consumes`` without PoseFix unless ``use_pose_fixes``."""
        if self.config.use_pose_fixes:
            return self.consumes
        return self.consumes - {PoseFix}

    @property
    def smoother(self) -> Any:
        """The underlying gtsam smoother (for inspection); None before the first smoother update."""
        return getattr(self, "_smoother", None)

    # --- reset ---------------------------------------------------------------------------------------------

    def reset(self, initial: Gaussian2, world: WorldMap, sensors: SensorSpec, rng: np.random.Generator) -> None:
        """Start from ``initial`` with the landmarks of ``world``; ``rng`` is unused (the smoother is deterministic)."""
        cfg = self.config
        if world.landmarks is None or len(world.landmarks) == 0:
            raise ConfigError("GtsamFixedLagSmoother needs world.landmarks; the dataset provides none")
        noise = cfg.motion_noise(sensors)
        self._motion = MotionModel(noise, cfg.motion_model, mean="model")
        sxy, _, sth = process_noise(cfg.sigma_xy_m, cfg.sigma_xy_m, cfg.sigma_theta_rad, sensors)
        sxy, sth = max(sxy, MIN_PROCESS_SIGMA[0]), max(sth, MIN_PROCESS_SIGMA[1])
        self._qxy, self._qth = sxy * sxy, sth * sth

        sr, sb = landmark_noise(cfg.sigma_range_m, cfg.sigma_bearing_rad, sensors, warn=False)
        # Warn about defaulted landmark noise only once sightings arrive (a range-only dataset has none).
        self._lm_warn = cfg.sigma_range_m is None and sensors.landmark_sigma_range_m is None
        self._lm_warn |= cfg.sigma_bearing_rad is None and sensors.landmark_sigma_bearing_rad is None
        self._R = np.diag([sr * sr, sb * sb])
        self._var_r, self._var_b = sr * sr, sb * sb
        # BearingRangeFactor2D's error is (bearing, range).
        self._br_noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([sb, sr]))
        self._gate = chi2_2dof_quantile(cfg.gate_probability)
        sg = range_only_noise(cfg.range_only_sigma_m, sensors, warn=False)
        self._range_warn = cfg.range_only_sigma_m is None and sensors.range_sigma_m is None
        self._range_var = sg * sg
        self._range_gate = chi2_1dof_quantile(cfg.range_gate_probability)
        gauss = gtsam.noiseModel.Isotropic.Sigma(1, sg)
        self._range_noise = (
            gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Huber.Create(cfg.range_huber_k), gauss)
            if cfg.range_robust == "huber"
            else gauss
        )

        lm = world.landmarks
        self._lm_xy = np.asarray(lm.xy, dtype=np.float64).reshape(-1, 2)
        self._lm_xy_list: list[list[float]] = self._lm_xy.tolist()
        self._lm_row = lm.index_of()
        std = None if lm.std_xy is None else np.asarray(lm.std_xy, dtype=np.float64).reshape(-1, 2)
        self._lm_noise = []
        for k in range(len(self._lm_xy)):
            s = (cfg.landmark_sigma_m, cfg.landmark_sigma_m) if std is None else tuple(np.maximum(std[k], 1e-6))
            self._lm_noise.append(gtsam.noiseModel.Diagonal.Sigmas(np.array(s, dtype=np.float64)))
        self._limits = self._sensor_limits(sensors)
        self._index = LandmarkIndex(self._lm_xy) if len(self._lm_xy) >= INDEX_MIN_LANDMARKS else None

        m = np.asarray(initial.mean, dtype=np.float64)
        c = _sym(np.asarray(initial.cov, dtype=np.float64))
        # The newest graph pose (world mean, body-frame marginal covariance) and the increment since it.
        self._set_node(gtsam.Pose2(float(m[0]), float(m[1]), wrap_scalar(float(m[2]))))
        R0 = _rot3(self._node_th)
        node_cov_body = R0.T @ c @ R0
        self._set_node_cov(node_cov_body)
        self._node_key = _X(0)
        self._n_nodes = 1
        self._delta: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._delta_cov = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
        self._steps_since_node = 0
        self._per_odometry = cfg.new_pose == "odometry"
        # The filtered belief in plain floats (world frame); estimate() makes the arrays.
        self._mean_f = (float(m[0]), float(m[1]), wrap_scalar(float(m[2])))
        self._cov_f = c.tolist()

        self._smoother: Any = None
        self._pending_prior: tuple[Any, Any] | None = (
            gtsam.PriorFactorPose2(_X(0), self._node_pose, gtsam.noiseModel.Gaussian.Covariance(_sym(node_cov_body))),
            self._node_pose,
        )
        self._t0 = math.nan
        self._t = math.nan
        self._lm_key: dict[int, int] = {}  # map row -> live gtsam key
        self._lm_stamp: dict[int, float] = {}
        self._n_lm_vars = 0
        self._new_landmarks: list[tuple[int, int]] = []  # (key, map row) to insert at the next update
        self._last_update_t = -math.inf
        self._live_poses: list[tuple[float, int]] = []  # (stamp, node index) of poses in the window
        # Per node: time, smoothed pose (filled when it leaves the window or at the end), odometry after it.
        self._node_t: list[float] = [math.nan]
        self._node_final: list[tuple[float, float, float] | None] = [None]
        self._node_odo: list[list[tuple[float, float, float, float]]] = [[]]
        self._nis, self._nis_dof, self._accepted, self._rejected = math.nan, 0, 0, 0
        self._window_poses = 0
        self._iterations = math.nan

    def _sensor_limits(self, sensors: SensorSpec) -> tuple[float, float, float]:
        """(min range, max range, half field of view) of nearest-neighbour candidates, widened by the margins."""
        cfg = self.config
        rmin, rmax, fov = sensors.landmark_min_range_m, sensors.landmark_max_range_m, sensors.landmark_fov_rad
        lo = -math.inf if rmin is None else rmin - cfg.prune_margin_m
        hi = math.inf if rmax is None else rmax + cfg.prune_margin_m
        half = math.inf if fov is None or fov >= 2.0 * math.pi else 0.5 * fov + cfg.prune_margin_rad
        return (lo, hi, half)

    # --- predict -------------------------------------------------------------------------------------------

    def predict(self, u: Odometry) -> None:
        """Compose one odometry step onto the increment since the newest graph pose (report 003 eq. 1-5, 10)."""
        if math.isnan(self._t0):
            self._t0 = u.t - u.dt if u.dt is not None and math.isfinite(u.dt) else u.t
            self._node_t[0] = self._t0
        step = self._motion.step(self._delta, u)
        # The step's noise is in the frame the increment is expressed in (the newest graph pose's); Q isotropic.
        n = step.noise
        q = (n[0] + self._qxy, n[1], n[2], n[3] + self._qxy, n[4], n[5] + self._qth)
        self._delta_cov = propagate_covariance(self._delta_cov, step.f02, step.f12, q)
        self._delta = pose = step.pose
        self._steps_since_node += 1
        self._t = u.t
        self._nis, self._nis_dof, self._accepted, self._rejected = math.nan, 0, 0, 0
        self._iterations = math.nan
        if self._per_odometry:
            self._smoother_update(u.t, gtsam.NonlinearFactorGraph(), {})
        else:
            self._node_odo[-1].append((u.t, *pose))
            self._compose_estimate()

    def _compose_estimate(self) -> None:
        """Filtered belief: newest graph pose (+) increment; covariance F P_w F^T + G Sigma G^T (world coordinates).

        Plain floats (this runs on every odometry event): F = [[1, 0, -ey], [0, 1, ex], [0, 0, 1]] with
        (ex, ey) the increment's world displacement, G = blockdiag(R(theta_k), 1), P_w the newest pose's
        marginal in world coordinates (cached at the smoother update, with the pose's cos and sin).
        """
        c, s = self._node_c, self._node_s
        dx, dy, dth = self._delta
        ex, ey = c * dx - s * dy, s * dx + c * dy
        rotated = _rotate_cov(c, s, self._delta_cov)
        self._cov_f = propagate_covariance(self._node_cov_world, -ey, ex, rotated)
        self._mean_f = (self._node_x + ex, self._node_y + ey, wrap_scalar(self._node_th + dth))
        if not math.isfinite(ex + ey + sum(rotated)):
            raise FilterDiverged(f"non-finite estimate at t={self._t:.3f} s")

    def _set_node(self, pose: Any) -> None:
        """Make ``pose`` (a gtsam ``Pose2``) the newest graph pose; its floats, cos and sin are cached."""
        self._node_pose = pose
        self._node_x, self._node_y, self._node_th = pose.x(), pose.y(), pose.theta()
        self._node_c, self._node_s = math.cos(self._node_th), math.sin(self._node_th)

    def _set_node_cov(self, cov_body: FloatArray) -> None:
        """Store the newest pose's body-frame marginal (symmetrised) in world coordinates, P_w = G P_b G^T."""
        (b00, b01, b02), (b10, b11, b12), (b20, b21, b22) = np.asarray(cov_body, dtype=np.float64).tolist()
        sym = [[b00, 0.5 * (b01 + b10), 0.5 * (b02 + b20)], [0.0, b11, 0.5 * (b12 + b21)], [0.0, 0.0, b22]]
        w00, w01, w02, w11, w12, w22 = _rotate_cov(self._node_c, self._node_s, sym)
        self._node_cov_world = [[w00, w01, w02], [w01, w11, w12], [w02, w12, w22]]

    # --- update --------------------------------------------------------------------------------------------

    def update(self, z: Observation) -> None:
        """Add the factors of one observation and update the smoother; TypeError for a type not consumed."""
        if type(z) is LandmarkObservations:
            factors, stamps = self._landmark_factors(z)
        elif type(z) is RangeObservations:
            factors, stamps = self._range_factors(z)
        elif type(z) is PoseFix:
            factors, stamps = self._pose_fix_factors(z)
        else:
            self.check_consumes(z)
            raise TypeError(f"GtsamFixedLagSmoother does not consume {type(z).__name__}")  # pragma: no cover
        if math.isnan(self._t0):
            self._t0 = z.t
            self._node_t[0] = z.t
        self._t = z.t
        self._iterations = math.nan
        if factors.size() > 0:
            self._smoother_update(z.t, factors, stamps)

    def _target_key(self) -> int:
        """Key of the pose an observation now attaches to: a new one if odometry arrived since the newest."""
        return _X(self._n_nodes) if self._steps_since_node > 0 else self._node_key

    def _landmark_factors(self, z: LandmarkObservations) -> tuple[Any, dict[int, float]]:
        if self._lm_warn:
            landmark_noise(None, None, SensorSpec(), warn=True)
            self._lm_warn = False
        cfg = self.config
        ids, ranges, bearings = z.ids.tolist(), z.ranges.tolist(), z.bearings.tolist()
        use_ids = cfg.association == "known"
        key = self._target_key()
        factors = gtsam.NonlinearFactorGraph()
        stamps: dict[int, float] = {}
        used: set[int] = set()
        deferred: list[int] = []
        matches: list[tuple[int, int]] = []  # (observation index, map row)
        rej = 0
        for k, ident in enumerate(ids):
            r, b = ranges[k], bearings[k]
            if not (math.isfinite(r) and math.isfinite(b)) or r <= 0.0:
                rej += 1
            elif not use_ids or ident == UNKNOWN_ID:
                deferred.append(k)
            elif (row := self._lm_row.get(ident)) is None:
                logger.debug("landmark id %d is not in the map; observation rejected", ident)
                rej += 1
            else:
                matches.append((k, row))
                used.add(row)
        nis = 0.0
        if deferred or matches:
            for k in deferred:
                row = self._nearest(ranges[k], bearings[k], used)
                if row is not None:
                    matches.append((k, row))
                    used.add(row)
                else:
                    rej += 1
            for k, row in matches:
                nis += self._nis_one(ranges[k], bearings[k], row)
                lkey = self._landmark_key(row, z.t, factors)
                factors.add(
                    gtsam.BearingRangeFactor2D(key, lkey, gtsam.Rot2.fromAngle(bearings[k]), ranges[k], self._br_noise)
                )
                stamps[lkey] = z.t
        acc = len(matches)
        self._nis = nis if acc else math.nan
        self._nis_dof, self._accepted, self._rejected = 2 * acc, acc, rej
        return factors, stamps

    def _range_factors(self, z: RangeObservations) -> tuple[Any, dict[int, float]]:
        """Gated ``RangeFactor2D`` to the beacons' landmark variables (module docstring)."""
        if self._range_warn:
            range_only_noise(None, SensorSpec(), warn=True)
            self._range_warn = False
        key = self._target_key()
        factors = gtsam.NonlinearFactorGraph()
        stamps: dict[int, float] = {}
        x, y = self._mean_f[0], self._mean_f[1]
        (p00, p01, _), (_, p11, _), _ = self._cov_f
        nis, acc, rej = 0.0, 0, 0
        for ident, r in zip(z.ids.tolist(), z.ranges.tolist(), strict=True):
            row = self._lm_row.get(ident) if ident != UNKNOWN_ID else None
            if row is None or not (math.isfinite(r) and r >= 0.0):
                rej += 1
                continue
            mx, my = self._lm_xy_list[row]
            dx, dy = mx - x, my - y
            d = math.hypot(dx, dy)
            if d < 1e-9:
                rej += 1
                continue
            h0, h1 = -dx / d, -dy / d
            S = h0 * h0 * p00 + 2.0 * h0 * h1 * p01 + h1 * h1 * p11 + self._range_var
            d2 = (r - d) ** 2 / S
            if not d2 <= self._range_gate:
                rej += 1
                continue
            lkey = self._landmark_key(row, z.t, factors)
            factors.add(gtsam.RangeFactor2D(key, lkey, r, self._range_noise))
            stamps[lkey] = z.t
            nis += d2
            acc += 1
        self._nis = nis if acc else math.nan
        self._nis_dof, self._accepted, self._rejected = acc, acc, rej
        return factors, stamps

    def _landmark_key(self, row: int, t: float, factors: Any) -> int:
        """The live variable of landmark ``row``, or a new one (with its map prior) if it left the window."""
        key = self._lm_key.get(row)
        # Gone if the last smoother update already marginalised it (stamp before that update's cutoff).
        if key is None or self._lm_stamp[row] < self._last_update_t - self.config.lag_s:
            key = _L(self._n_lm_vars)
            self._n_lm_vars += 1
            self._lm_key[row] = key
            self._new_landmarks.append((key, row))
            factors.add(gtsam.PriorFactorPoint2(key, self._lm_xy[row], self._lm_noise[row]))
        self._lm_stamp[row] = t
        return key

    def _nis_one(self, r: float, b: float, row: int) -> float:
        """:meth:`_mahalanobis` for one landmark in scalar arithmetic (a diagnostic on the hot path; equal to
        rounding): nu^T S^-1 nu with S = H P H^T + R, the 2 x 2 inverse in closed form."""
        x, y, th = self._mean_f
        mx, my = self._lm_xy_list[row]
        lx, ly = mx - x, my - y
        q = max(lx * lx + ly * ly, 1e-12)
        d = math.sqrt(q)
        (p00, p01, p02), (_, p11, p12), (_, _, p22) = self._cov_f  # symmetric by construction
        # H rows: a = (-lx/d, -ly/d, 0), c = (ly/q, -lx/q, -1); P a and P c - P e_theta
        a0, a1 = -lx / d, -ly / d
        c0, c1 = ly / q, -lx / q
        pa0, pa1 = p00 * a0 + p01 * a1, p01 * a0 + p11 * a1
        pc0, pc1, pc2 = p00 * c0 + p01 * c1 - p02, p01 * c0 + p11 * c1 - p12, p02 * c0 + p12 * c1 - p22
        s00 = a0 * pa0 + a1 * pa1 + self._var_r
        s01 = a0 * pc0 + a1 * pc1
        s11 = c0 * pc0 + c1 * pc1 - pc2 + self._var_b
        n0, n1 = r - d, wrap_scalar(b - (math.atan2(ly, lx) - th))
        det = s00 * s11 - s01 * s01
        return (s11 * n0 * n0 - 2.0 * s01 * n0 * n1 + s00 * n1 * n1) / det

    def _nearest(self, r: float, b: float, used: set[int]) -> int | None:
        """Row of the landmark of smallest d2 (:meth:`_mahalanobis`) among those not ``used``, inside the gate;
        else None. A large map tests only the candidates of its k-d tree (:mod:`._landmark_index`, whose bound
        is for this gate's S = H P H^T + R), in row order: each landmark's d2 is the same number either way, so
        the first smallest is the same row."""
        rows: list[int] | None = None
        if self._index is not None:
            radius = gate_radius(r, self._cov_f, self._var_r, self._var_b, self._gate)
            rows = self._index.candidates(self._mean_f, r, b, radius)
            if not rows:
                return None
        d2 = self._mahalanobis(r, b, rows)
        if used:
            if rows is None:
                d2[list(used)] = np.inf
            else:
                d2[[i for i, row in enumerate(rows) if row in used]] = np.inf
        best = int(np.argmin(d2))
        if not d2[best] <= self._gate:
            return None
        return best if rows is None else rows[best]

    def _mahalanobis(self, r: float, b: float, rows: list[int] | None = None) -> FloatArray:
        """Squared Mahalanobis distance of (r, b) to the map landmarks ``rows`` (default all) from the current
        belief (inf outside the limits).

        H = [[-dx/d, -dy/d, 0], [dy/q, -dx/q, -1]] (report 001 fig. 2, corrected), S = H P H^T + R.
        """
        xy = self._lm_xy if rows is None else self._lm_xy[rows]
        x, y, th = self._mean_f
        lx, ly = xy[:, 0] - x, xy[:, 1] - y
        q = np.maximum(lx * lx + ly * ly, 1e-12)
        d = np.sqrt(q)
        pb = wrap_angle(np.arctan2(ly, lx) - th)
        H = np.zeros((len(d), 2, 3))
        H[:, 0, 0], H[:, 0, 1] = -lx / d, -ly / d
        H[:, 1, 0], H[:, 1, 1], H[:, 1, 2] = ly / q, -lx / q, -1.0
        S = H @ np.array(self._cov_f) @ H.transpose(0, 2, 1) + self._R
        nu = np.stack([r - d, wrap_angle(b - pb)], axis=-1)
        d2 = np.einsum("ni,ni->n", nu, np.linalg.solve(S, nu[..., None])[..., 0])
        lo, hi, half = self._limits
        d2[(d < lo) | (d > hi) | (np.abs(pb) > half)] = np.inf
        return d2

    def _pose_fix_factors(self, z: PoseFix) -> tuple[Any, dict[int, float]]:
        m = int(z.z.shape[0])
        if m not in (2, 3) or z.cov.shape != (m, m):
            raise ValueError(f"PoseFix at t={z.t} must have z (2,) or (3,) and a matching cov, got {z.cov.shape}")
        cov = _sym(np.asarray(z.cov, dtype=np.float64))
        if m == 2:
            th = self._mean_f[2]  # no heading in the fix: the prior's heading is the current belief's
            full = np.zeros((3, 3))
            full[:2, :2] = cov
            full[2, 2] = self.config.pose_fix_heading_sigma_rad**2
        else:
            th = float(z.z[2])
            full = cov
        R3 = _rot3(th)
        prior = gtsam.Pose2(float(z.z[0]), float(z.z[1]), th)
        factors = gtsam.NonlinearFactorGraph()
        factors.add(
            gtsam.PriorFactorPose2(
                self._target_key(), prior, gtsam.noiseModel.Gaussian.Covariance(_sym(R3.T @ full @ R3))
            )
        )
        nu = np.asarray(z.z, dtype=np.float64) - np.array(self._mean_f[:m])
        if m == 3:
            nu[2] = wrap_scalar(float(nu[2]))
        S = np.array(self._cov_f)[:m, :m] + cov
        self._nis = float(nu @ np.linalg.solve(S, nu))
        self._nis_dof, self._accepted, self._rejected = m, 1, 0
        return factors, {}

    # --- the smoother --------------------------------------------------------------------------------------

    def _make_smoother(self) -> Any:
        cfg = self.config
        if cfg.smoother == "batch":
            return gtsam.BatchFixedLagSmoother(cfg.lag_s, gtsam.LevenbergMarquardtParams())
        params = gtsam.ISAM2Params()
        params.setRelinearizeThreshold(cfg.relinearize_threshold)
        params.relinearizeSkip = cfg.relinearize_skip
        # Reuse the slots of the factors marginalisation removed: otherwise the graph keeps an empty slot per
        # removed factor and grows with the run (3,726 slots for 23 factors after office, 30,042 after eight
        # laps of it, the median update about 1.5x slower by then; docs/history/performance.md).
        params.findUnusedFactorSlots = True
        return gtsam.IncrementalFixedLagSmoother(cfg.lag_s, params)

    def _between_noise(self) -> Any:
        """Gaussian noise of the composed increment, in the newer pose's frame (gtsam's between error)."""
        Rd = _rot3(self._delta[2])
        return gtsam.noiseModel.Gaussian.Covariance(_sym(Rd.T @ np.asarray(self._delta_cov) @ Rd))

    def _smoother_update(self, t: float, factors: Any, stamps: dict[int, float]) -> None:
        """Add a pose for the odometry since the newest one (if any), the given factors, and update the smoother."""
        cutoff = max(max(stamps.values(), default=t), t) - self.config.lag_s
        # Poses about to be marginalised keep the estimate of the last update that still held them.
        while self._live_poses and self._live_poses[0][0] < cutoff:
            _, idx = self._live_poses.pop(0)
            p = self._smoother.calculateEstimatePose2(_X(idx))
            self._node_final[idx] = (p.x(), p.y(), p.theta())
        values = gtsam.Values()
        for key, row in self._new_landmarks:
            values.insert(key, self._lm_xy[row])
        self._new_landmarks = []
        if self._pending_prior is not None:
            factors.add(self._pending_prior[0])
            values.insert(_X(0), self._pending_prior[1])
            stamps[_X(0)] = self._t0
            self._add_node_record(0, self._t0, self._pending_prior[1], cutoff)
            self._pending_prior = None
        if self._steps_since_node > 0:
            idx = self._n_nodes
            new_key = _X(idx)
            dx, dy, dth = self._delta
            inc = gtsam.Pose2(dx, dy, dth)
            factors.add(gtsam.BetweenFactorPose2(self._node_key, new_key, inc, self._between_noise()))
            guess = self._node_pose.compose(inc)
            values.insert(new_key, guess)
            stamps[new_key] = t
            self._node_t.append(t)
            self._node_final.append(None)
            self._node_odo.append([])
            self._add_node_record(idx, t, guess, cutoff)
            self._node_key = new_key
            self._n_nodes += 1
        if self._smoother is None:
            self._smoother = self._make_smoother()
        try:
            result = self._smoother.update(factors, values, stamps)
            self._set_node(self._smoother.calculateEstimatePose2(self._node_key))
            self._set_node_cov(self._marginal(self._node_key))
        except RuntimeError as exc:
            raise FilterDiverged(f"gtsam smoother failed at t={t:.3f} s: {exc}") from exc
        self._last_update_t = t
        self._iterations = float(result.getIterations())
        self._window_poses = len(self._live_poses)
        self._delta = (0.0, 0.0, 0.0)
        self._delta_cov = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
        self._steps_since_node = 0
        self._compose_estimate()

    def _add_node_record(self, idx: int, t: float, guess: Any, cutoff: float) -> None:
        """Track a new pose variable; its initial value stands in if it is marginalised in its first update."""
        self._node_final[idx] = (guess.x(), guess.y(), guess.theta())
        if t >= cutoff:
            self._live_poses.append((t, idx))

    def _marginal(self, key: int) -> FloatArray:
        s = self._smoother
        if self.config.smoother == "incremental":
            return s.marginalCovariance(key)
        return gtsam.Marginals(s.getFactors(), s.calculateEstimate()).marginalCovariance(key)

    # --- results -------------------------------------------------------------------------------------------

    def estimate(self) -> Estimate:
        """The filtered belief: newest pose (+) odometry since it, world-frame covariance (symmetrised)."""
        return Estimate(
            self._t,
            np.array(self._mean_f),
            np.array(self._cov_f),
            {
                "nis": self._nis,
                "nis_dof": float(self._nis_dof),
                "accepted": float(self._accepted),
                "rejected": float(self._rejected),
                "window_poses": float(self._window_poses),
                "iterations": self._iterations,
            },
        )

    def extra_results(self) -> dict[str, Any]:
        """The lag-smoothed trajectory.

        Returns
        -------
        dict
            ``smoothed_t`` (n,) s and ``smoothed_mean`` (n, 3) (x m, y m, theta rad, world frame): every pose
            variable's last estimate before it left the window (or the final one if still inside), and, with
            ``new_pose="observation"``, each odometry time in between as that pose composed with the odometry
            since it (times strictly increasing); ``smoothed_is_node`` (n,) bool marks the rows that are smoother
            variables.
        """
        final = list(self._node_final)
        s = self._smoother
        if s is not None:
            for _, idx in self._live_poses:
                p = s.calculateEstimatePose2(_X(idx))
                final[idx] = (p.x(), p.y(), p.theta())
        ts: list[float] = []
        rows: list[tuple[float, float, float]] = []
        node: list[bool] = []
        for idx in range(len(self._node_t)):
            base = final[idx]
            if base is None:  # X_0 when the smoother never ran: the prior itself
                base = (self._node_pose.x(), self._node_pose.y(), self._node_pose.theta())
            if math.isfinite(self._node_t[idx]):
                ts.append(self._node_t[idx])
                rows.append(base)
                node.append(True)
            c, sn = math.cos(base[2]), math.sin(base[2])
            # An odometry event at the time of the next pose is that pose (it was made right after).
            until = self._node_t[idx + 1] if idx + 1 < len(self._node_t) else math.inf
            for t, dx, dy, dth in self._node_odo[idx]:
                if t >= until:
                    break
                ts.append(t)
                rows.append((base[0] + c * dx - sn * dy, base[1] + sn * dx + c * dy, wrap_scalar(base[2] + dth)))
                node.append(False)
        mean = np.array(rows, dtype=np.float64).reshape(-1, 3)
        return {
            "smoothed_t": np.array(ts, dtype=np.float64),
            "smoothed_mean": mean,
            "smoothed_is_node": np.array(node, dtype=bool),
        }
