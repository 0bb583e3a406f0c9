"""EKF localization with the wheel-encoder model and range-bearing landmarks (reports 003 and 001).

Prediction (report 003): the wheel-encoder model of eq. 1-5 with input covariance U (eq. 10, read
per step by default; see :mod:`locbench.filters._motion`) and an additive process noise Q (eq. 8):

    x_k^- = f(x_{k-1}, u_k),    P_k^- = F P F^T + G U G^T + Q.

When an odometry event has no wheel travel the increment fallback of :mod:`locbench.filters._motion`
is used instead.

Correction (report 003 eq. 7 and 9, the sensor model of report 001 fig. 2): a landmark B at (x_B, y_B)
is seen at range lambda = |B - p| and bearing alpha = atan2(y_B - y, x_B - x) - theta. Here
z = (range, bearing) (report 001's order; report 003 writes bearing first) and R = diag(sigma_range^2,
sigma_bearing^2). With dx = x_B - x, dy = y_B - y, q = dx^2 + dy^2 and d = sqrt(q), the Jacobian is

    H = [[-dx/d,  -dy/d,   0],
         [ dy/q,  -dx/q,  -1]].

Report 001 prints [[dx/d, dy/d, 0], [dx/q, -dy/q, -1]]: its range row has the wrong sign and its bearing
row has dx and dy swapped; the form above is the derivative and is checked against finite differences
in the tests.

GPS-like pose fixes (report 001): H = [[1, 0, 0], [0, 1, 0]] (or I_3 with a heading) with the fix's own
covariance.

Range-only beacons (:class:`~locbench.events.RangeObservations`, e.g. the CMU Plaza radios; Djugash et al.
2009): a beacon at (x_B, y_B) of ``world.landmarks`` is measured at range r = |B - p| + noise from the robot
origin, R = sigma^2 with sigma = ``range_only_sigma_m`` (else ``SensorSpec.range_sigma_m``), and

    h(x) = sqrt(dx^2 + dy^2),    H = [-dx/d, -dy/d, 0],

a scalar update in the Joseph form, one range at a time as for landmarks. Ranging radios produce gross
outliers (multipath, a wrong first peak), so every range is gated: it is fused only if its squared
Mahalanobis distance nu^2 / S, S = H P H^T + R, is inside the chi-square quantile with 1 degree of freedom of
``range_gate_probability`` (0.99 -> 6.63; 1 disables the gate). A range without a known beacon identity
(``UNKNOWN_ID``, or an id not in the map) is rejected: one range fits every beacon on a circle, so there is
no association by nearest neighbour for ranges.

Choices the reports leave open, made here:

* Observations of one event are fused **sequentially**, one landmark at a time, each linearised at
  the state updated by the previous one. With independent noise (R diagonal per landmark, landmarks
  independent) this equals the batch update for a linear model, and it relinearises as it goes, needs
  only 2x2 inverses and lets nearest-neighbour association see the corrected state.
* Observations with a known id are fused first, then those associated by nearest neighbour, each
  nearest-neighbour search excluding the landmarks already used in the same event.
* Covariance updates use the Joseph form (I - K H) P (I - K H)^T + K R K^T, symmetric and PSD by
  construction (report 002 eq. 8 uses the same).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import ClassVar, Literal

import numpy as np
import numpy.typing as npt

from locbench.datasets.base import Gaussian2, MapKind, SensorSpec, WorldMap
from locbench.errors import ConfigError, FilterDiverged
from locbench.events import UNKNOWN_ID, LandmarkObservations, Observation, Odometry, PoseFix, RangeObservations
from locbench.filters._kalman import (
    chi2_1dof_quantile,
    chi2_2dof_quantile,
    inside_gate,
    joseph_update,
    subtract,
    wrapped_residual,
)
from locbench.filters._landmark_index import LandmarkIndex, gate_radius
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
    POSITIVE_OR_DATASET,
    PROBABILITY,
    Estimate,
    Filter,
    FilterConfig,
    bound,
)
from locbench.geometry import wrap_angle, wrap_scalar
from locbench.runkey import RUN_KEY_OMIT_IF_DEFAULT
from locbench.tunable import tunable

FloatArray = npt.NDArray[np.float64]
logger = logging.getLogger(__name__)

_RESIDUAL_HEADING = wrapped_residual([2])

# Maps with at least this many landmarks are searched with numpy; smaller ones in plain floats (faster there).
_VECTOR_NN_MIN = 48


def range_bearing(pose: npt.ArrayLike, landmarks_xy: npt.ArrayLike) -> FloatArray:
    """Expected (range m, bearing rad) of landmarks seen from ``pose`` (report 003 eq. 7), shape (..., 2).

    ``pose`` (3,) world frame; ``landmarks_xy`` (..., 2) world frame; bearing wrapped to (-pi, pi].
    """
    p = np.asarray(pose, dtype=np.float64)
    lm = np.asarray(landmarks_xy, dtype=np.float64)
    dx, dy = lm[..., 0] - p[0], lm[..., 1] - p[1]
    return np.stack([np.hypot(dx, dy), wrap_angle(np.arctan2(dy, dx) - p[2])], axis=-1)


def range_bearing_jacobian(pose: npt.ArrayLike, landmark_xy: npt.ArrayLike) -> FloatArray:
    """H = d(range, bearing)/d(x, y, theta), shape (2, 3); the corrected form of report 001 fig. 2."""
    p = np.asarray(pose, dtype=np.float64)
    lm = np.asarray(landmark_xy, dtype=np.float64)
    dx, dy = float(lm[0] - p[0]), float(lm[1] - p[1])
    q = dx * dx + dy * dy
    d = math.sqrt(q)
    return np.array([[-dx / d, -dy / d, 0.0], [dy / q, -dx / q, -1.0]])


@dataclass(frozen=True, kw_only=True)
class LandmarkEKFConfig(FilterConfig, MotionNoiseConfig):
    """Configuration of :class:`LandmarkEKF`.

    Attributes
    ----------
    sigma_x_m, sigma_y_m, sigma_theta_rad : float or None
        Standard deviations of the additive process noise Q (report 003 eq. 8), per odometry step, in
        the world frame: unmodelled motion (slip, castor drag) on top of the encoder noise G U G^T. None
        takes the dataset's ``SensorSpec.process_sigma_xy_m`` / ``process_sigma_theta_rad`` (0 on a
        model-matched world), else 1 mm, 1 mm, 0.5 mrad per step (:func:`locbench.filters._noise.process_noise`),
        small so that the encoder noise dominates.
    input_noise : {"per_step", "cumulative"}
        Reading of eq. 10: per-step variance k^2 |delta l_k| (Chong & Kleeman) or the literal accumulated sum.
    motion_model : {"auto", "encoder", "increment"}
        ``"auto"``: the encoder model (eq. 1-5) when the event has wheel travel and the dataset gives the
        wheelbase and encoder constants, else the (dx, dy, dtheta) increment; ``"encoder"`` uses the
        encoder model whenever wheel travel and wheelbase exist; ``"increment"`` always the increment.
    association : {"known", "nearest"}
        ``"known"``: use the observation's landmark id; ``"nearest"``: ignore ids and associate every
        observation by nearest neighbour. An id of ``UNKNOWN_ID`` is always associated by nearest neighbour.
    gate_probability : float
        Probability of the chi-square gate (2 dof) on the squared Mahalanobis distance of the innovation;
        a nearest-neighbour candidate beyond it is rejected. 0.99 -> 9.21.
    gate_known : bool
        Also gate observations with a known id (outlier rejection). Default False: report 003 fuses every
        detection of an identified landmark, and a gated EKF can never re-acquire after a large error.
    prune_to_sensor_limits : bool
        Consider as nearest-neighbour candidates only the landmarks predicted inside the sensor's range
        interval and field of view (from the dataset's SensorSpec, when given), widened by the margins.
    prune_margin_m, prune_margin_rad : float
        Margins of that pruning on the range interval (m) and on each side of the field of view (rad).
    use_pose_fixes : bool
        Fuse PoseFix events (report 001's GPS variant). When False the runner does not route them.
    sigma_range_m, sigma_bearing_rad : float or None
        Measurement noise R (report 003 eq. 9); None takes the dataset's nominal value.
    range_only_sigma_m : float or None
        Standard deviation of a range-only (beacon) measurement, m; None takes ``SensorSpec.range_sigma_m``.
    range_gate_probability : float
        Probability of the chi-square gate (1 dof) on each range-only innovation (outlier rejection);
        0.99 -> 6.63, the same probability as the landmark gate; 1 fuses every range.
    wheelbase_m, encoder_k_left, encoder_k_right : float or None
        Overrides of W (m) and k_L, k_R (sqrt(m)); None takes the dataset's value.
    odometry_sigma_xy_per_m, odometry_sigma_theta_per_m, odometry_sigma_theta_per_rad : float or None
        Overrides of the increment fallback noise (m/sqrt(m), rad/sqrt(m), rad/sqrt(rad)).
    twist_sigma_v_mps, twist_sigma_omega_radps : float or None
        Overrides of the white noise of a measured twist (m/s, rad/s); see :mod:`locbench.filters._motion`.
    """

    sigma_x_m: float | None = field(default=None, metadata=NON_NEGATIVE_OR_NONE)
    sigma_y_m: float | None = field(default=None, metadata=NON_NEGATIVE_OR_NONE)
    sigma_theta_rad: float | None = field(default=None, metadata=NON_NEGATIVE_OR_NONE)
    motion_model: MotionKind = "auto"
    association: Literal["known", "nearest"] = "known"
    gate_probability: float = field(default=0.99, metadata=PROBABILITY)
    gate_known: bool = False
    prune_to_sensor_limits: bool = True
    prune_margin_m: float = field(default=0.5, metadata=NON_NEGATIVE)
    prune_margin_rad: float = field(default=0.2, metadata=NON_NEGATIVE)
    use_pose_fixes: bool = False
    sigma_range_m: float | None = field(default=None, metadata=tunable(1e-3, 1.0, log=True, base=POSITIVE_OR_DATASET))
    sigma_bearing_rad: float | None = field(
        default=None, metadata=tunable(1e-3, 0.5, log=True, base=POSITIVE_OR_DATASET)
    )
    range_only_sigma_m: float | None = field(default=None, metadata=POSITIVE_OR_DATASET | RUN_KEY_OMIT_IF_DEFAULT)
    range_gate_probability: float = field(
        default=0.99, metadata=bound(0.0, 1.0, low_open=True, base=RUN_KEY_OMIT_IF_DEFAULT)
    )


class LandmarkEKF(Filter):
    """Extended Kalman filter on (x, y, theta) with range-bearing landmarks and optional pose fixes.

    Follows report 003 (wheel-encoder prediction, eq. 1-10) with report 001's sensor model and GPS
    update; see the module docstring for the equations and the choices made.

    Diagnostics of :meth:`estimate`: ``nis`` (sum of the NIS of the measurements accepted by the last
    update; NaN after a predict or when none was accepted), ``nis_dof`` (their total dimension, for a
    chi-square check), ``accepted`` and ``rejected`` (counts of the last update; 0 after a predict).
    """

    consumes: ClassVar[frozenset[type]] = frozenset({Odometry, LandmarkObservations, PoseFix, RangeObservations})
    requires: ClassVar[frozenset[MapKind]] = frozenset({MapKind.LANDMARKS})
    Config: ClassVar[type[FilterConfig]] = LandmarkEKFConfig
    # 3: the process noise Q is the dataset's when it declares one (0 on a model-matched world)
    version: ClassVar[int] = 3
    check_configurations: ClassVar[tuple[dict[str, str], ...]] = ({"association": "nearest"},)
    cost_per_data_s: ClassVar[float] = 0.02
    source: ClassVar[str] = "003_e5c93f9be776ee5e (EKF, eq. 1-10); 001_71e01b0c4f2511a1 (sensor Jacobian, GPS)"

    config: LandmarkEKFConfig

    def routed_events(self) -> frozenset[type]:
        """``consumes`` without PoseFix unless ``use_pose_fixes``."""
        if self.config.use_pose_fixes:
            return self.consumes
        return self.consumes - {PoseFix}

    # --- reset / predict ---------------------------------------------------------------------------------

    def reset(self, initial: Gaussian2, world: WorldMap, sensors: SensorSpec, rng: np.random.Generator) -> None:
        """Start from ``initial`` with the landmarks of ``world``; ``rng`` is unused (the EKF is deterministic)."""
        cfg = self.config
        if world.landmarks is None or len(world.landmarks) == 0:
            raise ConfigError("LandmarkEKF needs world.landmarks; the dataset provides none")
        noise = cfg.motion_noise(sensors)
        self._motion = MotionModel(noise, cfg.motion_model, mean="model")
        sx, sy, sth = process_noise(cfg.sigma_x_m, cfg.sigma_y_m, cfg.sigma_theta_rad, sensors)
        self._q = (sx * sx, sy * sy, sth * sth)

        sr, sb = landmark_noise(cfg.sigma_range_m, cfg.sigma_bearing_rad, sensors, warn=False)
        # Warn about defaulted landmark noise only once sightings arrive (a range-only dataset has none).
        self._lm_warn = cfg.sigma_range_m is None and sensors.landmark_sigma_range_m is None
        self._lm_warn |= cfg.sigma_bearing_rad is None and sensors.landmark_sigma_bearing_rad is None
        self._rr, self._rb = sr * sr, sb * sb
        self._gate = chi2_2dof_quantile(cfg.gate_probability)
        self._range_sigma = range_only_noise(cfg.range_only_sigma_m, sensors, warn=False)
        # Warn about a defaulted range noise only if ranges arrive (most datasets have none).
        self._range_warn = cfg.range_only_sigma_m is None and sensors.range_sigma_m is None
        self._range_gate = chi2_1dof_quantile(cfg.range_gate_probability)

        lm = world.landmarks
        self._lm_xy = np.asarray(lm.xy, dtype=np.float64).reshape(-1, 2)
        self._lm_row = lm.index_of()
        self._lm_list: list[tuple[float, float]] = [(float(a), float(b)) for a, b in self._lm_xy]
        self._limits = self._sensor_limits(sensors) if cfg.prune_to_sensor_limits else None
        # a large map: nearest-neighbour candidates from a k-d tree instead of testing every landmark
        big = len(self._lm_list) >= _VECTOR_NN_MIN and math.isfinite(self._gate)
        self._index = LandmarkIndex(self._lm_xy) if big else None

        m = np.asarray(initial.mean, dtype=np.float64)
        self._x = [float(m[0]), float(m[1]), wrap_scalar(float(m[2]))]
        c = np.asarray(initial.cov, dtype=np.float64)
        self._P: list[list[float]] = (0.5 * (c + c.T)).tolist()
        self._t = math.nan
        self._nis = math.nan
        self._nis_dof = 0
        self._accepted = 0
        self._rejected = 0
        self._check_finite(math.nan)

    def _sensor_limits(self, sensors: SensorSpec) -> tuple[float, float, float] | None:
        """(min range, max range, half field of view) widened by the margins, or None if nothing to prune."""
        cfg = self.config
        rmin = sensors.landmark_min_range_m
        rmax = sensors.landmark_max_range_m
        fov = sensors.landmark_fov_rad
        if rmin is None and rmax is None and fov is None:
            return None
        lo = -math.inf if rmin is None else rmin - cfg.prune_margin_m
        hi = math.inf if rmax is None else rmax + cfg.prune_margin_m
        half = math.inf if fov is None or fov >= 2.0 * math.pi else 0.5 * fov + cfg.prune_margin_rad
        return (lo, hi, half)

    def predict(self, u: Odometry) -> None:
        """Propagate with one odometry event (report 003 eq. 5 and P = F P F^T + G U G^T + Q)."""
        step = self._motion.step(self._x, u)
        q0, q1, q2 = self._q
        n = step.noise
        self._x = list(step.pose)
        self._P = propagate_covariance(self._P, step.f02, step.f12, (n[0] + q0, n[1], n[2], n[3] + q1, n[4], n[5] + q2))
        self._t = u.t
        self._nis, self._nis_dof, self._accepted, self._rejected = math.nan, 0, 0, 0
        self._check_finite(u.t)

    # --- update --------------------------------------------------------------------------------------------

    def update(self, z: Observation) -> None:
        """Correct with landmark observations (eq. 7), beacon ranges or a pose fix (report 001); TypeError otherwise."""
        if type(z) is LandmarkObservations:
            self._update_landmarks(z)
        elif type(z) is RangeObservations:
            self._update_ranges(z)
        elif type(z) is PoseFix:
            self._update_pose_fix(z)
        else:
            self.check_consumes(z)
            raise TypeError(f"LandmarkEKF does not consume {type(z).__name__}")  # pragma: no cover
        self._t = z.t
        self._check_finite(z.t)

    def _update_landmarks(self, z: LandmarkObservations) -> None:
        if self._lm_warn:
            landmark_noise(None, None, SensorSpec(), warn=True)
            self._lm_warn = False
        nis, dof, acc, rej = 0.0, 0, 0, 0
        ids = z.ids.tolist()
        ranges = z.ranges.tolist()
        bearings = z.bearings.tolist()
        use_ids = self.config.association == "known"
        gate_known = self.config.gate_known
        used: set[int] = set()
        deferred: list[int] = []
        # Known ids first (reliable), then nearest neighbour among the landmarks not used yet.
        for k, ident in enumerate(ids):
            r, b = ranges[k], bearings[k]
            if not (math.isfinite(r) and math.isfinite(b)) or r <= 0.0:
                rej += 1
                continue
            if not use_ids or ident == UNKNOWN_ID:
                deferred.append(k)
                continue
            row = self._lm_row.get(ident)
            if row is None:
                logger.debug("landmark id %d is not in the map; observation rejected", ident)
                rej += 1
                continue
            d2 = self._correct_landmark(r, b, row, self._gate if gate_known else math.inf)
            if d2 is None:
                rej += 1
            else:
                nis += d2
                dof += 2
                acc += 1
                used.add(row)
        for k in deferred:
            row = self._nearest(ranges[k], bearings[k], used)
            d2 = None if row is None else self._correct_landmark(ranges[k], bearings[k], row, self._gate)
            if row is None or d2 is None:
                rej += 1
            else:
                nis += d2
                dof += 2
                acc += 1
                used.add(row)
        self._nis = nis if acc else math.nan
        self._nis_dof, self._accepted, self._rejected = dof, acc, rej

    def _nearest(self, r: float, b: float, used: set[int]) -> int | None:
        """Row of the map landmark nearest to (r, b) in Mahalanobis distance, inside the gate; else None.

        Candidates exclude ``used`` rows and, when pruning, landmarks predicted outside the sensor limits.
        Small maps are scanned in plain floats (about 1 us per landmark). From ``_VECTOR_NN_MIN`` landmarks
        on, only those a k-d tree finds within the distance at which a landmark can still pass the gate
        (:mod:`._landmark_index`) are tested, so the cost per sighting no longer grows with the map; without
        a finite gate every landmark is tested at once in numpy.
        """
        rows: range | list[int]
        if self._index is not None:
            rows = self._index.candidates(self._x, r, b, gate_radius(r, self._P, self._rr, self._rb, self._gate))
        elif len(self._lm_list) >= _VECTOR_NN_MIN:
            d2 = self._mahalanobis_all(r, b, used)
            best = int(np.argmin(d2))
            return best if d2[best] <= self._gate else None
        else:
            rows = range(len(self._lm_list))
        limits = self._limits
        best_row, best_d2 = -1, math.inf
        for row in rows:
            if row in used:
                continue
            inn = self._innovation(r, b, row)
            if inn is None:
                continue
            if limits is not None:
                d, pb = inn[8], inn[9]
                if not (limits[0] <= d <= limits[1] and abs(pb) <= limits[2]):
                    continue
            if inn[7] < best_d2:
                best_row, best_d2 = row, inn[7]
        return best_row if best_d2 <= self._gate else None

    def _mahalanobis_all(self, r: float, b: float, used: set[int]) -> FloatArray:
        """Squared Mahalanobis distance of (r, b) to every map landmark, vectorised; inf where excluded."""
        x, y, th = self._x
        lx = self._lm_xy[:, 0] - x
        ly = self._lm_xy[:, 1] - y
        q = lx * lx + ly * ly
        d = np.sqrt(q)
        pb = wrap_angle(np.arctan2(ly, lx) - th)
        # H rows per landmark: range (-lx/d, -ly/d, 0), bearing (ly/q, -lx/q, -1); S = H P H^T + R.
        a0, a1 = -lx / d, -ly / d
        c0, c1 = ly / q, -lx / q
        P = self._P
        p00, p01, p02 = P[0]
        p11, p12, p22 = P[1][1], P[1][2], P[2][2]
        ub0 = p00 * c0 + p01 * c1 - p02
        ub1 = p01 * c0 + p11 * c1 - p12
        ub2 = p02 * c0 + p12 * c1 - p22
        s00 = p00 * a0 * a0 + 2.0 * p01 * a0 * a1 + p11 * a1 * a1 + self._rr
        s01 = a0 * ub0 + a1 * ub1
        s11 = c0 * ub0 + c1 * ub1 - ub2 + self._rb
        vr = r - d
        vb = wrap_angle(b - pb)
        d2 = (s11 * vr * vr - 2.0 * s01 * vr * vb + s00 * vb * vb) / (s00 * s11 - s01 * s01)
        return self._exclude(d2, ~(q > 1e-12), d, pb, used)

    def _exclude(
        self, d2: FloatArray, bad: npt.NDArray[np.bool_], d: FloatArray, pb: FloatArray, used: set[int]
    ) -> FloatArray:
        """``d2`` with inf where a landmark is no candidate: ``bad``, already ``used``, or (when pruning) predicted
        at a range ``d`` or bearing ``pb`` outside the sensor limits."""
        if self._limits is not None:
            lo, hi, half = self._limits
            bad |= (d < lo) | (d > hi) | (np.abs(pb) > half)
        if used:
            bad[list(used)] = True
        d2[bad] = np.inf
        return d2

    def _innovation(
        self, r: float, b: float, row: int
    ) -> tuple[float, float, float, float, float, float, float, float, float, float] | None:
        """Innovation of (r, b) against landmark ``row`` at the current state, in plain floats.

        Returns (vr, vb, h00, h01, h10, h11, det S, d2, predicted range, predicted bearing), with H =
        [[h00, h01, 0], [h10, h11, -1]] (the corrected Jacobian of report 001 fig. 2), the bearing innovation
        vb wrapped to (-pi, pi] and d2 = nu^T S^-1 nu; None when the pose sits on the landmark.
        """
        lx, ly = self._lm_list[row]
        x, y, th = self._x
        dx, dy = lx - x, ly - y
        q = dx * dx + dy * dy
        if q < 1e-12:
            return None  # on top of the landmark: the bearing is undefined
        d = math.sqrt(q)
        h00, h01 = -dx / d, -dy / d
        h10, h11 = dy / q, -dx / q
        pb = wrap_scalar(math.atan2(dy, dx) - th)
        vr = r - d
        vb = wrap_scalar(b - pb)
        P = self._P
        p00, p01, p02 = P[0]
        p11, p12, p22 = P[1][1], P[1][2], P[2][2]
        s00 = p00 * h00 * h00 + 2.0 * p01 * h00 * h01 + p11 * h01 * h01 + self._rr
        ub0 = p00 * h10 + p01 * h11 - p02
        ub1 = p01 * h10 + p11 * h11 - p12
        ub2 = p02 * h10 + p12 * h11 - p22
        s01 = h00 * ub0 + h01 * ub1
        s11 = h10 * ub0 + h11 * ub1 - ub2 + self._rb
        det = s00 * s11 - s01 * s01
        d2 = (s11 * vr * vr - 2.0 * s01 * vr * vb + s00 * vb * vb) / det if det > 0.0 else math.inf
        return (vr, vb, h00, h01, h10, h11, det, d2, d, pb)

    def _correct_landmark(self, r: float, b: float, row: int, gate: float) -> float | None:
        """Fuse one (range, bearing) of landmark ``row`` (eq. 7, Joseph form); its NIS, or None if gated out."""
        inn = self._innovation(r, b, row)
        if inn is None or not inn[7] <= gate:
            return None
        vr, vb, h00, h01, h10, h11, det, d2 = inn[:8]
        P = self._P
        p00, p01, p02 = P[0]
        p11, p12, p22 = P[1][1], P[1][2], P[2][2]
        # P H^T, column of the range row (r) and of the bearing row (b).
        r0, r1, r2 = p00 * h00 + p01 * h01, p01 * h00 + p11 * h01, p02 * h00 + p12 * h01
        b0, b1, b2 = p00 * h10 + p01 * h11 - p02, p01 * h10 + p11 * h11 - p12, p02 * h10 + p12 * h11 - p22
        s00 = h00 * r0 + h01 * r1 + self._rr
        s01 = h00 * b0 + h01 * b1
        s11 = h10 * b0 + h11 * b1 - b2 + self._rb
        i00, i01, i11 = s11 / det, -s01 / det, s00 / det
        # K = P H^T S^-1, rows (k_i0, k_i1).
        k00, k01 = r0 * i00 + b0 * i01, r0 * i01 + b0 * i11
        k10, k11 = r1 * i00 + b1 * i01, r1 * i01 + b1 * i11
        k20, k21 = r2 * i00 + b2 * i01, r2 * i01 + b2 * i11
        x, y, th = self._x
        self._x = [x + k00 * vr + k01 * vb, y + k10 * vr + k11 * vb, wrap_scalar(th + k20 * vr + k21 * vb)]
        # Joseph form P' = A P A^T + K R K^T with A = I - K H, H = [[h00, h01, 0], [h10, h11, -1]].
        a00, a01, a02 = 1.0 - k00 * h00 - k01 * h10, -k00 * h01 - k01 * h11, k01
        a10, a11, a12 = -k10 * h00 - k11 * h10, 1.0 - k10 * h01 - k11 * h11, k11
        a20, a21, a22 = -k20 * h00 - k21 * h10, -k20 * h01 - k21 * h11, 1.0 + k21
        # B = A P (rows).
        b00 = a00 * p00 + a01 * p01 + a02 * p02
        b01 = a00 * p01 + a01 * p11 + a02 * p12
        b02 = a00 * p02 + a01 * p12 + a02 * p22
        b10 = a10 * p00 + a11 * p01 + a12 * p02
        b11 = a10 * p01 + a11 * p11 + a12 * p12
        b12 = a10 * p02 + a11 * p12 + a12 * p22
        b20 = a20 * p00 + a21 * p01 + a22 * p02
        b21 = a20 * p01 + a21 * p11 + a22 * p12
        b22 = a20 * p02 + a21 * p12 + a22 * p22
        rr, rb = self._rr, self._rb
        q00 = b00 * a00 + b01 * a01 + b02 * a02 + k00 * k00 * rr + k01 * k01 * rb
        q01 = b00 * a10 + b01 * a11 + b02 * a12 + k00 * k10 * rr + k01 * k11 * rb
        q02 = b00 * a20 + b01 * a21 + b02 * a22 + k00 * k20 * rr + k01 * k21 * rb
        q11 = b10 * a10 + b11 * a11 + b12 * a12 + k10 * k10 * rr + k11 * k11 * rb
        q12 = b10 * a20 + b11 * a21 + b12 * a22 + k10 * k20 * rr + k11 * k21 * rb
        q22 = b20 * a20 + b21 * a21 + b22 * a22 + k20 * k20 * rr + k21 * k21 * rb
        self._P = [[q00, q01, q02], [q01, q11, q12], [q02, q12, q22]]
        return d2

    def _update_ranges(self, z: RangeObservations) -> None:
        """Fuse beacon ranges one at a time (module docstring), each under the chi-square (1 dof) gate."""
        if self._range_warn:
            range_only_noise(None, SensorSpec(), warn=True)
            self._range_warn = False
        nis, acc, rej = 0.0, 0, 0
        for ident, r in zip(z.ids.tolist(), z.ranges.tolist(), strict=True):
            row = self._lm_row.get(ident) if ident != UNKNOWN_ID else None
            d2 = None if row is None or not (math.isfinite(r) and r >= 0.0) else self._correct_range(r, row)
            if d2 is None:
                rej += 1
            else:
                nis += d2
                acc += 1
        self._nis = nis if acc else math.nan
        self._nis_dof, self._accepted, self._rejected = acc, acc, rej

    def _correct_range(self, r: float, row: int) -> float | None:
        """Fuse one range to beacon ``row`` with the Joseph update of the core; its NIS, or None if gated out."""
        x, P = np.array(self._x), np.array(self._P)
        lx, ly = self._lm_list[row]
        dx, dy = lx - x[0], ly - x[1]
        d = math.hypot(dx, dy)
        if d < 1e-9:
            return None  # on the beacon: the range's gradient is undefined
        H = np.array([[-dx / d, -dy / d, 0.0]])
        R = np.array([[self._range_sigma * self._range_sigma]])
        c = joseph_update(x, P, np.array([r]), np.array([d]), H, R)
        if not inside_gate(c.nis, self._range_gate):
            return None
        self._x = [float(c.x[0]), float(c.x[1]), wrap_scalar(float(c.x[2]))]
        self._P = c.P.tolist()
        return c.nis

    def _update_pose_fix(self, z: PoseFix) -> None:
        """GPS-like fix (report 001): H = [I_2 0] or I_3; the fix's own covariance; heading innovation wrapped."""
        m = int(z.z.shape[0])
        if m not in (2, 3) or z.cov.shape != (m, m):
            raise ValueError(f"PoseFix at t={z.t} must have z (2,) or (3,) and a matching cov, got {z.cov.shape}")
        x, P, R = np.array(self._x), np.array(self._P), 0.5 * (z.cov + z.cov.T)
        if not np.linalg.det(P[:m, :m] + R) > 0.0:
            raise ValueError(f"PoseFix at t={z.t}: innovation covariance is singular; check the fix covariance")
        residual = _RESIDUAL_HEADING if m == 3 else subtract
        c = joseph_update(x, P, np.asarray(z.z, dtype=np.float64), x[:m], np.eye(3)[:m], R, residual)
        self._x = [float(c.x[0]), float(c.x[1]), wrap_scalar(float(c.x[2]))]
        self._P = c.P.tolist()
        self._nis, self._nis_dof, self._accepted, self._rejected = c.nis, m, 1, 0

    # --- output --------------------------------------------------------------------------------------------

    def _check_finite(self, t: float) -> None:
        x, P = self._x, self._P
        ok = math.isfinite(x[0] + x[1] + x[2])
        ok = ok and math.isfinite(sum(P[0]) + sum(P[1]) + sum(P[2]))
        if not ok:
            raise FilterDiverged(f"LandmarkEKF state became non-finite at t={t:.3f} s")

    def estimate(self) -> Estimate:
        """The current mean (3,), covariance (3, 3) and the diagnostics of the last call."""
        return Estimate(t=self._t, mean=np.array(self._x), cov=np.array(self._P), diagnostics=self._diagnostics())

    def _diagnostics(self) -> dict[str, float]:
        return {
            "nis": self._nis,
            "nis_dof": float(self._nis_dof),
            "accepted": float(self._accepted),
            "rejected": float(self._rejected),
        }
