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

Range-only beacons (:class:`~locbench.core.events.RangeObservations`, e.g. the CMU Plaza radios; Djugash et al.
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

Where each equation is implemented: the encoder prediction and the range-bearing correction (the filter's most
frequent events) are compiled, :mod:`locbench.filters._ekf_kernels`; the other motion models' steps come from
:class:`~locbench.filters._motion.MotionModel`; range-only and pose-fix corrections go through the Kalman core's
numpy Joseph update, :func:`locbench.filters._kalman.joseph_update`.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import ClassVar, Literal

import numpy as np
import numpy.typing as npt

from locbench.core.errors import ConfigError, FilterDiverged
from locbench.core.events import UNKNOWN_ID, LandmarkObservations, Observation, Odometry, PoseFix, RangeObservations
from locbench.core.geometry import wrap_scalar
from locbench.core.runkey import RUN_KEY_OMIT_IF_DEFAULT
from locbench.core.tunable import tunable
from locbench.datasets.dataset import Gaussian2, MapKind, SensorSpec, WorldMap
from locbench.filters import _ekf_kernels as kern
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
    FilterDoc,
    bound,
)

FloatArray = npt.NDArray[np.float64]
logger = logging.getLogger(__name__)

_RESIDUAL_HEADING = wrapped_residual([2])

# Maps with at least this many landmarks take the EKF's nearest-neighbour candidates from a k-d tree; smaller
# ones test every landmark in one compiled loop, faster there than the tree's query and its Python (paired on
# the tiled office map: the tree 2.1x the loop's time at 88 landmarks, 1.06x at 352, 0.41x at 1408).
_VECTOR_NN_MIN = 256
_NO_LIMITS = np.empty(0)
# the packed compiled calls, bound once (a module attribute costs a lookup per event)
_predict_packed = kern.predict_packed
_update_packed = kern.update_packed
#: Room for the rows of this many sightings in the integer buffer at reset; it grows with a larger event.
_ROWS_CAPACITY = 16


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

    id: ClassVar[str] = "ekf_landmarks"
    order: ClassVar[int] = 10
    description: ClassVar[str] = (
        "EKF, wheel-encoder motion model and range-bearing landmarks, optional GPS fixes (reports 003, 001)"
    )
    doc: ClassVar[FilterDoc | None] = FilterDoc(
        "003, 001",
        "wheel-encoder model (003 eq. 1-5), input covariance growing with wheel travel (eq. 10), additive Q (eq. 8)",
        "range-bearing to landmarks (003 eq. 7, 001 fig. 2 with its Jacobian corrected), known identities or "
        "Mahalanobis nearest neighbour under a chi-square gate; optional GPS pose fixes (001); Joseph form",
        "nearest-neighbour candidates are the landmarks predicted inside the sensor's range and field of view",
    )
    #: the main comparison also runs it with nearest-neighbour association (the landmark identities unused)
    comparison_configurations: ClassVar[tuple[dict[str, str], ...]] = ({"association": "nearest"},)
    consumes: ClassVar[frozenset[type]] = frozenset({Odometry, LandmarkObservations, PoseFix, RangeObservations})
    requires: ClassVar[frozenset[MapKind]] = frozenset({MapKind.LANDMARKS})
    Config: ClassVar[type[FilterConfig]] = LandmarkEKFConfig
    # 3: the process noise Q is the dataset's when it declares one (0 on a model-matched world)
    version: ClassVar[int] = 3
    check_configurations: ClassVar[tuple[dict[str, str], ...]] = ({"association": "nearest"},)
    cost_per_data_s: ClassVar[float] = 0.02
    source: ClassVar[str] = "003_e5c93f9be776ee5e (EKF, eq. 1-10); 001_71e01b0c4f2511a1 (sensor Jacobian, GPS)"

    config: LandmarkEKFConfig
    #: Maps with at least this many landmarks take nearest-neighbour candidates from a k-d tree.
    _index_min_landmarks: ClassVar[int] = _VECTOR_NN_MIN

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
        self._lm_xy = np.ascontiguousarray(lm.xy, dtype=np.float64).reshape(-1, 2)
        self._lm_row = lm.index_of()
        self._lm_list: list[tuple[float, float]] = [(float(a), float(b)) for a, b in self._lm_xy]
        limits = self._sensor_limits(sensors) if cfg.prune_to_sensor_limits else None
        self._limits = _NO_LIMITS if limits is None else np.array(limits)
        # a large map: nearest-neighbour candidates from a k-d tree instead of testing every landmark
        big = len(self._lm_list) >= self._index_min_landmarks
        self._index = LandmarkIndex(self._lm_xy) if big else None
        # the compiled calls' buffers (_ekf_kernels): state, constants and map; the map's ids sorted with rows
        ids = np.asarray(lm.ids, dtype=np.int64).reshape(-1)
        order = np.argsort(ids, kind="stable")
        n_lm = len(self._lm_list)
        self._ibuf = kern.int_buffer(ids[order], order.astype(np.int64), _ROWS_CAPACITY)
        self._map_ids, self._map_rows = self._ibuf[:n_lm], self._ibuf[n_lm : 2 * n_lm]  # views
        self._used = self._ibuf[3 * n_lm : 4 * n_lm]  # a view: the used marks of the current event
        self._rows_room = _ROWS_CAPACITY  # the sightings whose rows the integer buffer holds
        self._all_rows = np.arange(n_lm, dtype=np.int64)
        use_ids = cfg.association == "known"
        here = self._index is None
        lm_prm = np.array([self._rr, self._rb, self._gate, float(cfg.gate_known), float(use_ids), float(here)])
        # the encoder prediction is compiled when the model takes the encoder branch (MotionModel's rule)
        self._encoder = self._motion._use_encoder
        W = noise.wheelbase_m if noise.wheelbase_m is not None else math.nan
        cumulative = float(noise.input_noise == "cumulative")
        enc = np.array([W, noise.k_left, noise.k_right, cumulative, 0.0, 0.0, *self._q])
        self._buf = kern.float_buffer(self._lm_xy, enc, lm_prm, self._limits)
        self._out = self._buf[kern.BUF_OUT : kern.BUF_ENC]
        self._q_arr = np.array(self._q)

        m = np.asarray(initial.mean, dtype=np.float64)
        c = np.asarray(initial.cov, dtype=np.float64)
        # the state: mean (x, y, theta) and the covariance row-major, a view of the buffer
        self._s = self._buf[kern.BUF_STATE : kern.BUF_OUT]
        self._x = [float(m[0]), float(m[1]), wrap_scalar(float(m[2]))]
        self._P = (0.5 * (c + c.T)).tolist()
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

    # The state is the array ``_s``; ``_x`` and ``_P`` read and write it as lists (the slow paths, tests).
    @property
    def _x(self) -> list[float]:
        return self._s[:3].tolist()

    @_x.setter
    def _x(self, x: list[float] | tuple[float, float, float]) -> None:
        self._s[:3] = x

    @property
    def _P(self) -> list[list[float]]:  # noqa: N802 (the covariance's name in the equations)
        return self._s[3:].reshape(3, 3).tolist()

    @_P.setter
    def _P(self, P: list[list[float]]) -> None:  # noqa: N802
        self._s[3:] = np.asarray(P, dtype=np.float64).reshape(9)

    def predict(self, u: Odometry) -> None:
        """Propagate with one odometry event (report 003 eq. 5 and P = F P F^T + G U G^T + Q).

        The encoder model's step and the propagation are one compiled call (:mod:`._ekf_kernels`); the
        increment and twist-noise steps come from :class:`MotionModel` and are propagated compiled."""
        self._t = u.t
        self._nis, self._nis_dof, self._accepted, self._rejected = math.nan, 0, 0, 0
        dl, dr = u.d_left, u.d_right
        if self._encoder and dl is not None and dr is not None:
            ok = _predict_packed(self._buf, dl, dr)
        else:
            step = self._motion.step(self._x, u)
            ok = kern.predict_step(self._s, np.array(step.pose), step.f02, step.f12, np.array(step.noise), self._q_arr)
        if not ok:
            self._diverged(u.t)

    # --- update --------------------------------------------------------------------------------------------

    def update(self, z: Observation) -> None:
        """Correct with landmark observations (eq. 7), beacon ranges or a pose fix (report 001); TypeError otherwise."""
        self._t = z.t
        if type(z) is LandmarkObservations:
            self._update_landmarks(z)  # checks the state's finiteness itself
            return
        if type(z) is RangeObservations:
            self._update_ranges(z)
        elif type(z) is PoseFix:
            self._update_pose_fix(z)
        else:
            self.check_consumes(z)
            raise TypeError(f"LandmarkEKF does not consume {type(z).__name__}")  # pragma: no cover
        self._check_finite(z.t)

    def _update_landmarks(self, z: LandmarkObservations) -> None:
        """Fuse the sightings: known ids first (reliable), then nearest neighbour among the landmarks not used
        yet, one compiled call (:func:`._ekf_kernels.update_landmarks`); with a k-d tree the sightings to
        associate return here for their candidates (:meth:`_fuse`)."""
        if self._lm_warn:
            self._warn_landmark_noise()
        ranges, bearings, out = z.ranges, z.bearings, self._out
        if len(ranges) > self._rows_room:
            self._rows(len(ranges))
        n_def = _update_packed(self._buf, z.ids, ranges, bearings, self._ibuf)
        nis, acc, rej, missing, finite = out.tolist()
        if missing:
            self._log_unmapped(z)
        if n_def:  # the sightings to associate of a map with a k-d tree
            codes = self._rows(len(ranges)).tolist()
            d_nis, d_acc, d_rej = self._fuse(ranges, bearings, codes, self._used, associate=True)
            nis, acc, rej = nis + d_nis, acc + d_acc, rej + d_rej
            finite = kern.state_finite(self._s)
        self._nis = nis if acc else math.nan
        self._nis_dof, self._accepted, self._rejected = 2 * int(acc), int(acc), int(rej)
        if not finite:
            self._diverged(z.t)

    def _warn_landmark_noise(self) -> None:
        """Log the defaulted landmark noise once, at the first sightings (a range-only dataset has none)."""
        landmark_noise(None, None, SensorSpec(), warn=True)
        self._lm_warn = False

    def _rows(self, n: int) -> npt.NDArray[np.int64]:
        """The integer buffer's room for the rows of ``n`` sightings (:func:`._ekf_kernels.sighting_rows`), grown
        when an event has more sightings than any before; a view of its first ``n``."""
        n_lm = len(self._lm_list)
        if n > self._rows_room:
            self._ibuf = np.concatenate([self._ibuf[: 4 * n_lm], np.zeros(2 * n, dtype=np.int64)])
            self._map_ids, self._map_rows = self._ibuf[:n_lm], self._ibuf[n_lm : 2 * n_lm]
            self._used = self._ibuf[3 * n_lm : 4 * n_lm]
            self._rows_room = 2 * n
        return self._ibuf[4 * n_lm : 4 * n_lm + n]

    def _log_unmapped(self, z: LandmarkObservations) -> None:
        """Log each identity of ``z`` that is not in the map (its sighting was rejected)."""
        if logger.isEnabledFor(logging.DEBUG):
            for ident in z.ids.tolist():
                if ident != UNKNOWN_ID and ident not in self._lm_row:
                    logger.debug("landmark id %d is not in the map; observation rejected", ident)

    def _fuse(
        self,
        ranges: FloatArray,
        bearings: FloatArray,
        codes: list[int],
        used: npt.NDArray[np.int64],
        associate: bool,
    ) -> tuple[float, int, int]:
        """Fuse sightings of one event in their order through :meth:`_correct_landmark`; (NIS sum, accepted, rejected).

        ``codes`` are :func:`._ekf_kernels.sighting_rows`' rows. With ``associate`` False: the sightings with a row
        (gated only with ``gate_known``) and the rejected ones (a code < 0 other than ``ASSOCIATE``); with
        ``associate`` True: those to associate, each with the landmark of :meth:`_nearest_row` among those not
        ``used``. The rows fused are marked in ``used``.
        """
        gate = self._gate if associate or self.config.gate_known else math.inf
        nis, acc, rej = 0.0, 0, 0
        for k, code in enumerate(codes):
            if (code == kern.ASSOCIATE) != associate:
                continue
            r, b = float(ranges[k]), float(bearings[k])
            row = self._nearest_row(r, b, used) if associate else code
            d2 = None if row < 0 else self._correct_landmark(r, b, row, gate)
            if d2 is None:
                rej += 1
            else:
                nis += d2
                acc += 1
                used[row] = 1
        return nis, acc, rej

    def _correct_landmark(self, r: float, b: float, row: int, gate: float) -> float | None:
        """Fuse one (range, bearing) of landmark ``row`` (eq. 7, Joseph form); its NIS, or None if gated out."""
        lx, ly = self._lm_list[row]
        d2 = float(kern.correct_landmark(self._s, r, b, lx, ly, self._rr, self._rb, gate))
        return None if math.isnan(d2) else d2

    def _nearest(self, r: float, b: float, used: set[int]) -> int | None:
        """Row of the map landmark nearest to (r, b) in Mahalanobis distance, inside the gate; else None.

        Candidates exclude ``used`` rows and, when pruning, landmarks predicted outside the sensor limits.
        """
        mask = np.zeros(len(self._lm_list), dtype=np.int64)
        mask[list(used)] = 1
        row = self._nearest_row(r, b, mask)
        return None if row < 0 else row

    def _nearest_row(self, r: float, b: float, used: npt.NDArray[np.int64]) -> int:
        """:meth:`_nearest` with ``used`` marks (nonzero) over the rows and -1 for none.

        Small maps test every landmark in one compiled loop (:func:`._ekf_kernels.nearest_row`). From
        ``_VECTOR_NN_MIN`` landmarks on, only those a k-d tree finds within the distance at which a landmark can
        still pass the gate (:mod:`._landmark_index`) are tested, in the same order, so the cost per sighting no
        longer grows with the map and the winner is the same.
        """
        rows = self._all_rows
        if self._index is not None:
            P = self._P
            cand = self._index.candidates(self._x, r, b, gate_radius(r, P, self._rr, self._rb, self._gate))
            rows = np.array(cand, dtype=np.int64)
        s, lims = self._s, self._limits
        return int(kern.nearest_row(s, r, b, self._lm_xy, rows, used, lims, self._rr, self._rb, self._gate))

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
        if not kern.state_finite(self._s):
            self._diverged(t)

    def _diverged(self, t: float) -> None:
        raise FilterDiverged(f"LandmarkEKF state became non-finite at t={t:.3f} s")

    def estimate(self) -> Estimate:
        """The current mean (3,), covariance (3, 3) and the diagnostics of the last call."""
        s = self._s
        return Estimate(t=self._t, mean=s[:3].copy(), cov=s[3:].reshape(3, 3).copy(), diagnostics=self._diagnostics())

    def _diagnostics(self) -> dict[str, float]:
        return {
            "nis": self._nis,
            "nis_dof": float(self._nis_dof),
            "accepted": float(self._accepted),
            "rejected": float(self._rejected),
        }
