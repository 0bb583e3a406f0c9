"""EKF localization on a map of lines (report 002, Peng, "EKF map based localization").

Prediction (eq. 1-2): the robot's odometry increment u = (dx, dy, dtheta), in the previous robot frame, is
compounded onto the pose, x_k^- = x_{k-1} (+) u_k, and

    P_k^- = A P_{k-1} A^T + W Q_k W^T,

with A = d(x (+) u)/dx and W = d(x (+) u)/du (the rotation by theta; see
:func:`locbench.filters._motion.increment_jacobians`). Q_k is the increment's covariance: the dataset's
nominal per-metre odometry noise (variance growing with the step's length and turn) plus a constant
diagonal per step (report 002: "Q initially contains the sigma of noise in its diagonal").

Observation: lines extracted from the laser scan by split-and-merge (:mod:`locbench.filters._line_extraction`),
each (rho, psi) in the robot frame with the covariance of its fit. A map line (rho_w, psi_w) in the world
frame (:meth:`locbench.datasets.dataset.LineMap.rho_psi`) seen from the pose (x, y, theta) is (eq. 3)

    rho_r = rho_w - sqrt(x^2 + y^2) cos(atan2(y, x) - psi_w) = rho_w - (x cos psi_w + y sin psi_w),
    psi_r = psi_w - theta,

so H = [[-cos psi_w, -sin psi_w, 0], [0, 0, -1]] (checked against finite differences in the tests).
:func:`_expected` (eq. 3) and :func:`_innovation` (eq. 4) serve both the association and the update.
rho_r may come out negative (the robot on the far side of the line from the world origin); the same line
is then (-rho_r, psi_r + pi) and the rho row of H changes sign. Which of the two forms is compared with an
observation is decided by the observation's own psi (the form whose psi is within pi/2 of it), so a line
passing near the robot (rho ~ 0, where the sign of the extracted normal is arbitrary) is matched
continuously.

Association (eq. 4-5): for each observed line the innovation v = z - h(x^-) (psi wrapped) and
S = H P^- H^T + R are computed against every map line; the map line with the smallest Mahalanobis distance
v^T S^-1 v is taken if that distance is below the chi-square threshold (``chi2_threshold``), else the
observation is rejected. Optionally (report 002's optional part, ``reject_longer``) an observation longer
than its map line is rejected: a wall cannot be seen longer than it is. Map segments lying on the same
infinite line (a wall split by doors) are indistinguishable by (rho, psi); the check compares with the
longest of them.

Update (eq. 6-8): every accepted observation of one scan is stacked into one update at the predicted state,
as the report associates first and updates after, with K = P H^T S^-1, x = x^- + K v and the Joseph form
P = (I - K H) P^- (I - K H)^T + K R K^T: the Kalman core's :func:`locbench.filters._kalman.joseph_correct`, whose
dimension varies with the number of lines accepted.

R of one observation is the covariance of its line fit plus a constant diag(sigma_rho_m^2, sigma_psi_rad^2)
for what the per-point range noise does not model: walls rasterised on an occupancy grid are seen up to a
cell in front of their line, corners round off, and the map is not exact.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
import numpy.typing as npt
from numba import njit

from locbench.core.errors import ConfigError, FilterDiverged
from locbench.core.events import LaserScan, Observation, Odometry
from locbench.core.geometry import wrap_scalar
from locbench.core.tunable import tunable
from locbench.datasets.dataset import Gaussian2, MapKind, SensorSpec, WorldMap
from locbench.filters._kalman import joseph_correct
from locbench.filters._line_extraction import ExtractedLines, ExtractionParams, extract_lines
from locbench.filters._motion import MotionModel, propagate_covariance, resolve_motion_noise
from locbench.filters.base import NON_NEGATIVE, Estimate, Filter, FilterConfig, FilterDoc, bound

FloatArray = npt.NDArray[np.float64]
logger = logging.getLogger(__name__)

#: Laser range noise used when neither the config nor the dataset gives one, m (logged at reset).
DEFAULT_LASER_SIGMA_M = 0.01

#: Chi-square quantile with 2 degrees of freedom at probability 0.99, the default gate: -2 ln(0.01).
CHI2_2DOF_099 = 9.21

#: :func:`locbench.core.geometry.wrap_scalar` compiled (an angle to (-pi, pi]), for the kernels below. numba's
#: on-disk cache of a kernel is keyed on this module's source alone: after editing ``wrap_scalar``, delete the
#: ``*.nbi`` / ``*.nbc`` files under ``filters/__pycache__``.
_wrap = njit(cache=True, inline="always")(wrap_scalar)


@dataclass(frozen=True, kw_only=True)
class LineEKFConfig(FilterConfig):
    """Configuration of :class:`LineEKF`.

    Attributes
    ----------
    chi2_threshold : float
        Gate on the squared Mahalanobis distance v^T S^-1 v of an association (report 002 sec. 2.2-2.3);
        default 9.21, the 0.99 quantile of chi-square with 2 dof (the report tunes it and gives no value).
    reject_longer : bool
        Reject an observed line longer than its associated map line plus ``length_margin_m`` (report 002's
        optional check, which it keeps).
    length_margin_m : float
        Slack of that check, m: an extracted segment's ends are its outermost points projected on the line,
        so noise and the raster can make it exceed the wall by a few cm.
    sigma_rho_m, sigma_psi_rad : float
        Constant part of R added to each line's fit covariance (m, rad): the map and raster error the
        per-point noise does not cover (2 cm: a wall rasterised on a 0.05 m grid is seen up to one cell in
        front of its line; 1 deg).
    sigma_dx_m, sigma_dy_m, sigma_dtheta_rad : float
        Constant per-step standard deviations of the odometry increment (robot frame), the diagonal Q of
        report 002 eq. 2, added to the dataset's distance-proportional increment noise. As the additive Q of
        ``ekf_landmarks``: 1 mm, 1 mm, 0.5 mrad per step.
    laser_sigma_m : float or None
        Range noise of one laser return, m, for the line-fit covariance; None takes the dataset's value.
    split_threshold_m, min_points, min_length_m : float, int, float
        Line extraction (see :class:`locbench.filters._line_extraction.ExtractionParams`).
    odometry_sigma_xy_per_m, odometry_sigma_theta_per_m, odometry_sigma_theta_per_rad : float or None
        Overrides of the dataset's nominal increment noise (m/sqrt(m), rad/sqrt(m), rad/sqrt(rad)).
    """

    chi2_threshold: float = field(
        default=CHI2_2DOF_099,
        metadata=tunable(
            1.0, 30.0, log=True, base=bound(0.0, low_open=True, expected="> 0 (a squared Mahalanobis distance)")
        ),
    )
    reject_longer: bool = True
    length_margin_m: float = field(default=0.1, metadata=NON_NEGATIVE)
    sigma_rho_m: float = field(default=0.02, metadata=tunable(1e-3, 0.5, log=True, base=NON_NEGATIVE))
    sigma_psi_rad: float = field(default=0.0175, metadata=tunable(1e-3, 0.5, log=True, base=NON_NEGATIVE))
    sigma_dx_m: float = field(default=0.001, metadata=NON_NEGATIVE)
    sigma_dy_m: float = field(default=0.001, metadata=NON_NEGATIVE)
    sigma_dtheta_rad: float = field(default=0.0005, metadata=NON_NEGATIVE)
    laser_sigma_m: float | None = field(
        default=None, metadata=bound(0.0, low_open=True, unit="m", optional=True, none_means="the dataset's")
    )
    split_threshold_m: float = 0.05
    min_points: int = 4
    min_length_m: float = 0.3
    odometry_sigma_xy_per_m: float | None = field(default=None, metadata=tunable(1e-3, 0.2, log=True))
    odometry_sigma_theta_per_m: float | None = field(default=None, metadata=tunable(1e-3, 0.5, log=True))
    odometry_sigma_theta_per_rad: float | None = None

    def __post_init__(self) -> None:
        super().__post_init__()  # the bounds declared on the fields; the line extraction's joint rule follows
        if not self.split_threshold_m > 0 or self.min_points < 3 or self.min_length_m < 0:
            raise ConfigError(
                "line extraction: split_threshold_m must be > 0 m, min_points >= 3 and min_length_m >= 0 m, got "
                f"{self.split_threshold_m}, {self.min_points}, {self.min_length_m}"
            )


class LineEKF(Filter):
    """EKF on (x, y, theta) with laser lines matched to a line map (report 002).

    See the module docstring for the equations. Diagnostics of :meth:`estimate` (after an update; after a
    predict the counts are 0 and ``nis`` NaN): ``extracted`` (lines found in the scan), ``accepted``,
    ``rejected`` (= ``rejected_gate`` + ``rejected_length``), ``nis`` (v^T S^-1 v of the stacked update; NaN
    when nothing was accepted) and ``nis_dof`` (2 per accepted line).
    """

    id: ClassVar[str] = "ekf_lines"
    order: ClassVar[int] = 30
    description: ClassVar[str] = "EKF on a map of lines, chi-square gated association, Joseph form (report 002)"
    doc: ClassVar[FilterDoc | None] = FilterDoc(
        "002",
        "odometry compounding with noise Jacobians (eq. 1-2)",
        "lines (rho, psi) extracted from the scan by split-and-merge, matched to map lines by Mahalanobis distance "
        "under a chi-square threshold (eq. 3-5), Joseph form (eq. 8); optional rejection of lines longer than "
        "their map line",
    )
    consumes: ClassVar[frozenset[type]] = frozenset({Odometry, LaserScan})
    requires: ClassVar[frozenset[MapKind]] = frozenset({MapKind.LINES})
    Config: ClassVar[type[FilterConfig]] = LineEKFConfig
    version: ClassVar[int] = 3
    cost_per_data_s: ClassVar[float] = 0.15
    source: ClassVar[str] = "002_f01b2dfd20d46b8b (EKF map-based localization with lines, eq. 1-8)"

    config: LineEKFConfig

    def reset(self, initial: Gaussian2, world: WorldMap, sensors: SensorSpec, rng: np.random.Generator) -> None:
        """Start from ``initial`` with the lines of ``world``; ``rng`` is unused (the EKF is deterministic)."""
        cfg = self.config
        if world.lines is None or len(world.lines) == 0:
            raise ConfigError("LineEKF needs world.lines; the dataset provides no line map")
        noise = resolve_motion_noise(
            sensors,
            odometry_sigma_xy_per_m=cfg.odometry_sigma_xy_per_m,
            odometry_sigma_theta_per_m=cfg.odometry_sigma_theta_per_m,
            odometry_sigma_theta_per_rad=cfg.odometry_sigma_theta_per_rad,
        )
        # eq. 1-2 compound the robot's own increment: the increment model, mean = composition
        self._motion = MotionModel(noise, "increment", mean="compose")
        sigma = cfg.laser_sigma_m if cfg.laser_sigma_m is not None else sensors.laser_sigma_m
        if sigma is None or not sigma > 0:
            logger.warning("no nominal laser noise in the config or dataset; using %g m", DEFAULT_LASER_SIGMA_M)
            sigma = DEFAULT_LASER_SIGMA_M
        self._extract = ExtractionParams(
            split_threshold_m=cfg.split_threshold_m,
            min_points=cfg.min_points,
            min_length_m=cfg.min_length_m,
            sigma_m=float(sigma),
        )
        rp = world.lines.rho_psi()
        self._rho_w = rp[:, 0].copy()
        self._psi_w = rp[:, 1].copy()
        self._cos_w = np.cos(self._psi_w)
        self._sin_w = np.sin(self._psi_w)
        self._len_w = _collinear_max_length(rp, world.lines.lengths())
        self._R0 = np.diag([cfg.sigma_rho_m**2, cfg.sigma_psi_rad**2])

        m = np.asarray(initial.mean, dtype=np.float64)
        self._x = np.array([float(m[0]), float(m[1]), wrap_scalar(float(m[2]))])
        c = np.asarray(initial.cov, dtype=np.float64)
        self._P = 0.5 * (c + c.T)
        self._t = math.nan
        self._clear_diagnostics()
        self._check_finite(math.nan)

    def _clear_diagnostics(self) -> None:
        self._nis = math.nan
        self._nis_dof = 0
        self._extracted = 0
        self._accepted = 0
        self._rej_gate = 0
        self._rej_len = 0

    # --- predict (eq. 1-2) ----------------------------------------------------------------------------------

    def predict(self, u: Odometry) -> None:
        """Compound the odometry increment onto the pose; P = A P A^T + W Q W^T (eq. 1-2)."""
        cfg = self.config
        x = self._x
        step = self._motion.step((float(x[0]), float(x[1]), float(x[2])), u)
        n = step.noise
        # the constant robot-frame diagonal of Q, rotated to the world frame by W (rotation by theta)
        c, s = math.cos(x[2]), math.sin(x[2])
        vx, vy = cfg.sigma_dx_m**2, cfg.sigma_dy_m**2
        q00, q01, q11 = c * c * vx + s * s * vy, c * s * (vx - vy), s * s * vx + c * c * vy
        noise = (n[0] + q00, n[1] + q01, n[2], n[3] + q11, n[4], n[5] + cfg.sigma_dtheta_rad**2)
        P = propagate_covariance(self._P.tolist(), step.f02, step.f12, noise)
        self._x = np.array(step.pose)
        self._P = np.array(P)
        self._t = u.t
        self._clear_diagnostics()
        self._check_finite(u.t)

    # --- update (eq. 3-8) -----------------------------------------------------------------------------------

    def update(self, z: Observation) -> None:
        """Extract lines from a scan, associate them (eq. 3-5) and correct the pose (eq. 6-8)."""
        if type(z) is not LaserScan:
            self.check_consumes(z)
            raise TypeError(f"LineEKF does not consume {type(z).__name__}")  # pragma: no cover
        lines = extract_lines(z, self._extract)
        self._clear_diagnostics()
        self._extracted = len(lines)
        if len(lines):
            self._correct(lines)
        self._t = z.t
        self._check_finite(z.t)

    def associate(self, lines: ExtractedLines) -> list[tuple[int, int, float, float]]:
        """Match each observed line to a map line at the current state (eq. 3-5).

        Returns
        -------
        list of (observation index, map line index, sign, squared Mahalanobis distance)
            For every observation inside the gate (and passing the length check when on), in observation
            order; ``sign`` is -1 where the flipped form (-rho_r, psi_r + pi) of the map line is compared.
            The rejection counts of the last update are set as a side effect.
        """
        acc, best, sign, d2 = self._gate(lines)
        return [(j, int(best[j]), float(sign[j]), float(d2[j])) for j in acc.tolist()]

    def _gate(
        self, lines: ExtractedLines
    ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], FloatArray, FloatArray]:
        """The accepted observations (indices, in order) and every observation's nearest map line, sign and
        distance; sets the rejection counts."""
        cfg = self.config
        x, y, th = self._x.tolist()
        best, sign, d2 = _nearest_lines(
            x, y, th, self._rho_w, self._psi_w, self._cos_w, self._sin_w, lines.rho_psi, lines.cov, self._R0, self._P
        )
        acc, rej_gate, rej_len = _accept(
            best, d2, lines.lengths, self._len_w, cfg.chi2_threshold, cfg.reject_longer, cfg.length_margin_m
        )
        self._rej_gate += rej_gate
        self._rej_len += rej_len
        return acc, best, sign, d2

    def _correct(self, lines: ExtractedLines) -> None:
        acc, best, sign, _ = self._gate(lines)
        k = int(acc.shape[0])
        if k == 0:
            return
        px, py, pth = self._x.tolist()
        # eq. 3-4 and the Jacobian per accepted line, stacked
        H, v, R = _stack(
            acc, best, sign, self._rho_w, self._psi_w, self._cos_w, self._sin_w, lines.rho_psi, lines.cov, self._R0,
            px, py, pth,
        )  # fmt: skip
        # S = H P H^T + R (eq. 5), K = P H^T S^-1 (eq. 6), x + K v (eq. 7), Joseph form (eq. 8): the Kalman core.
        c = joseph_correct(self._x, self._P, v, H, R)
        x_new = c.x
        x_new[2] = wrap_scalar(float(x_new[2]))
        self._x = x_new
        self._P = c.P
        self._nis = c.nis
        self._nis_dof = 2 * k
        self._accepted = k

    # --- output ---------------------------------------------------------------------------------------------

    def _check_finite(self, t: float) -> None:
        # math.isfinite over the 12 floats: the verdict of the two numpy reductions at a tenth of their cost
        if not all(map(math.isfinite, self._x.tolist() + self._P.ravel().tolist())):
            raise FilterDiverged(f"LineEKF state became non-finite at t={t:.3f} s")

    def estimate(self) -> Estimate:
        """The current mean (3,), covariance (3, 3) and the diagnostics of the last call."""
        rejected = self._rej_gate + self._rej_len
        return Estimate(
            t=self._t,
            mean=self._x.copy(),
            cov=self._P.copy(),
            diagnostics={
                "nis": self._nis,
                "nis_dof": float(self._nis_dof),
                "extracted": float(self._extracted),
                "accepted": float(self._accepted),
                "rejected": float(rejected),
                "rejected_gate": float(self._rej_gate),
                "rejected_length": float(self._rej_len),
            },
        )


@njit(cache=True)
def _accept(
    best: npt.NDArray[np.int64],
    d2: FloatArray,
    lengths: FloatArray,
    len_w: FloatArray,
    chi2_threshold: float,
    reject_longer: bool,
    margin: float,
) -> tuple[npt.NDArray[np.int64], int, int]:
    """Observations inside the gate (a NaN distance never is) and, with ``reject_longer``, not longer than their
    map line plus ``margin``: (accepted indices in order, rejected by the gate, rejected by length)."""
    k = best.shape[0]
    out = np.empty(k, dtype=np.int64)
    n = 0
    rej_gate = 0
    rej_len = 0
    for j in range(k):
        if not d2[j] <= chi2_threshold:
            rej_gate += 1
        elif reject_longer and lengths[j] > len_w[best[j]] + margin:
            rej_len += 1
        else:
            out[n] = j
            n += 1
    return out[:n], rej_gate, rej_len


@njit(cache=True, inline="always")
def _expected(
    rho_w: float, psi_w: float, cos_w: float, sin_w: float, x: float, y: float, th: float
) -> tuple[float, float]:
    """h(x) of report 002 eq. 3: the map line (rho_w m, psi_w rad) seen from the pose (x m, y m, th rad), as
    (rho_r, psi_r) = (rho_w - (x cos psi_w + y sin psi_w), psi_w - th wrapped to (-pi, pi]); ``cos_w``, ``sin_w``
    are cos psi_w and sin psi_w. rho_r < 0 when the robot and the world origin lie on opposite sides of the line,
    which is then also (-rho_r, psi_r + pi)."""
    return rho_w - (x * cos_w + y * sin_w), _wrap(psi_w - th)


@njit(cache=True, inline="always")
def _innovation(z_rho: float, z_psi: float, rho_r: float, psi_r: float, sign: float) -> tuple[float, float]:
    """v = z - h(x) of report 002 eq. 4 for an observed line z = (rho m, psi rad) and the expected line
    (rho_r, psi_r) of :func:`_expected` in the form ``sign`` (+1: (rho_r, psi_r); -1: (-rho_r, psi_r + pi));
    (v_rho m, v_psi rad wrapped to (-pi, pi])."""
    return z_rho - sign * rho_r, _wrap(z_psi - (psi_r + (math.pi if sign < 0 else 0.0)))


@njit(cache=True)
def _stack(
    acc: npt.NDArray[np.int64],
    best: npt.NDArray[np.int64],
    sign: FloatArray,
    rho_w: FloatArray,
    psi_w: FloatArray,
    cos_w: FloatArray,
    sin_w: FloatArray,
    z: FloatArray,
    cov: FloatArray,
    R0: FloatArray,
    px: float,
    py: float,
    pth: float,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The stacked Jacobian, innovation and noise of the accepted lines (report 002 eq. 3-5).

    Parameters
    ----------
    acc : ndarray of int64, shape (k,)
        The accepted observations.
    best, sign : ndarray, shape (m,)
        Each observation's map line and the form compared (:func:`_nearest_lines`).
    rho_w, psi_w, cos_w, sin_w : ndarray, shape (n,)
        The map lines (m, rad) and cos, sin of psi_w.
    z, cov : ndarray, shapes (m, 2) and (m, 2, 2)
        The observed lines (rho m, psi rad) and their fit covariances.
    R0 : ndarray, shape (2, 2)
        The constant part of R.
    px, py, pth : float
        The predicted pose (m, m, rad).

    Returns
    -------
    H : ndarray, shape (2k, 3)
        Per line [[-sign cos psi_w, -sign sin psi_w, 0], [0, 0, -1]].
    v : ndarray, shape (2k,)
        Per line :func:`_innovation` of :func:`_expected`.
    R : ndarray, shape (2k, 2k)
        Block diagonal, per line its fit covariance plus R0.
    """
    k = acc.shape[0]
    H = np.zeros((2 * k, 3))
    v = np.zeros(2 * k)
    R = np.zeros((2 * k, 2 * k))
    for r in range(k):
        j = acc[r]
        i = best[j]
        sg = sign[j]
        pw = psi_w[i]
        H[2 * r, 0] = -sg * math.cos(pw)
        H[2 * r, 1] = -sg * math.sin(pw)
        H[2 * r + 1, 2] = -1.0
        rho_r, psi_r = _expected(rho_w[i], pw, cos_w[i], sin_w[i], px, py, pth)
        v[2 * r], v[2 * r + 1] = _innovation(z[j, 0], z[j, 1], rho_r, psi_r, sg)
        for a in range(2):
            for b in range(2):
                R[2 * r + a, 2 * r + b] = cov[j, a, b] + R0[a, b]
    return H, v, R


@njit(cache=True)
def _nearest_lines(
    x: float,
    y: float,
    th: float,
    rho_w: FloatArray,
    psi_w: FloatArray,
    cos_w: FloatArray,
    sin_w: FloatArray,
    z: FloatArray,
    cov: FloatArray,
    R0: FloatArray,
    P: FloatArray,
) -> tuple[npt.NDArray[np.int64], FloatArray, FloatArray]:
    """The association of report 002 eq. 3-5: each observed line's nearest map line in Mahalanobis distance.

    For every observed line z_j (``z`` (k, 2), fit covariance ``cov`` (k, 2, 2)) and map line i, the form is
    chosen by z_j's own psi (flipped, sign -1, when psi_r of :func:`_expected` is more than pi/2 from it),
    v = :func:`_innovation`, S = H P H^T + cov_j + R0 with H of :func:`_stack`, and d2 = v^T S^-1 v (inf where S
    is not positive definite). Returns per observed line the map line of least d2 (the first of equal ones; the
    first NaN, as from a non-finite state, when there is one), the sign of its form and that d2.
    """
    k = z.shape[0]
    n = rho_w.shape[0]
    half_pi = 0.5 * math.pi
    p00, p01, p02, p11, p12, p22 = P[0, 0], P[0, 1], P[0, 2], P[1, 1], P[1, 2], P[2, 2]
    best = np.zeros(k, dtype=np.int64)
    best_sign = np.ones(k)
    best_d2 = np.full(k, np.inf)
    for j in range(k):
        r00 = cov[j, 0, 0] + R0[0, 0]
        r01 = cov[j, 0, 1] + R0[0, 1]
        r11 = cov[j, 1, 1] + R0[1, 1]
        s11 = p22 + r11
        first = True
        for i in range(n):
            c = cos_w[i]
            s = sin_w[i]
            rho_r, psi_r = _expected(rho_w[i], psi_w[i], c, s, x, y, th)
            sg = -1.0 if abs(_wrap(z[j, 1] - psi_r)) > half_pi else 1.0
            v_rho, v_psi = _innovation(z[j, 0], z[j, 1], rho_r, psi_r, sg)
            s00 = c * c * p00 + 2.0 * c * s * p01 + s * s * p11 + r00
            s01 = sg * (c * p02 + s * p12) + r01
            det = s00 * s11 - s01 * s01
            d2 = (s11 * v_rho * v_rho - 2.0 * s01 * v_rho * v_psi + s00 * v_psi * v_psi) / det
            if not det > 0.0:
                d2 = np.inf
            if first or d2 < best_d2[j] or (math.isnan(d2) and not math.isnan(best_d2[j])):
                best[j], best_sign[j], best_d2[j] = i, sg, d2
                first = False
            if math.isnan(d2):
                break  # a non-finite state: the first NaN stands
    return best, best_sign, best_d2


def _collinear_max_length(rho_psi: FloatArray, lengths: FloatArray, tol_m: float = 1e-6) -> FloatArray:
    """For each map line, the longest length among the segments on the same infinite line, m, shape (n,).

    Two lines are the same when their (rho, unit normal) agree, or agree with the normal reversed and rho
    negated (rho = 0 lines), within ``tol_m``.
    """
    n = rho_psi.shape[0]
    nrm = np.column_stack([np.cos(rho_psi[:, 1]), np.sin(rho_psi[:, 1])])
    rho = rho_psi[:, 0]
    d_rho = np.abs(rho[:, None] - rho[None, :])
    s_rho = np.abs(rho[:, None] + rho[None, :])
    d_nrm = np.linalg.norm(nrm[:, None] - nrm[None, :], axis=-1)
    s_nrm = np.linalg.norm(nrm[:, None] + nrm[None, :], axis=-1)
    same = ((d_rho < tol_m) & (d_nrm < tol_m)) | ((s_rho < tol_m) & (s_nrm < tol_m))
    out = np.empty(n)
    for i in range(n):
        out[i] = float(np.max(lengths[same[i]]))
    return out
