"""Left-invariant EKF on SE(2) with ``ekf_landmarks``' inputs, noise, association and gates (Barrau and Bonnabel 2017).

The belief is a pose X in SE(2) and a covariance P_b of the **left-invariant** error: X_true = X Exp(xi), xi =
(xi_x, xi_y, xi_theta) in the robot's body frame (gtsam's ``Pose2`` tangent order). Barrau and Bonnabel
("The invariant extended Kalman filter as a stable observer", IEEE TAC 62(4), 2017):

* Prediction with a body-frame increment U (group-affine dynamics, here X+ = X U):

      X+ = X U,     P_b+ = Ad_{U^-1} P_b Ad_{U^-1}^T + Q_b.

  The error's propagation (the paper's log-linear property) does not depend on the estimate, which is the
  filter's point: the EKF's Jacobian F depends on the estimated heading, the invariant one does not.
* Correction with a measurement z = h(X) + noise: H_b = dh(X Exp(xi))/dxi at 0, S = H_b P_b H_b^T + R,
  K = P_b H_b^T S^-1, X+ = X Exp(K v), P_b+ = (I - K H_b) P_b (I - K H_b)^T + K R K^T (Joseph form, as the
  EKF). No covariance reset after the retraction: the paper has none, and gtsam's ``ManifoldEKF.updateWithVector``
  is compared with ``performReset=False`` (its default reset transports P_b by Ad_{Exp(-K v)}).

**Left, not right.** The odometry, its wheel-encoder noise and the sensor are all in the body frame, and the
left-invariant error is the body-frame one: the prediction's Jacobian Ad_{U^-1} involves only the increment,
the motion noise enters as Q_b without transport by the estimate, and gtsam ships this form
(``InvariantEKFPose2``), so every step is checked against it. A landmark seen in the body frame, z = X^-1 l, is a
*right*-invariant observation whose right-error Jacobian would be state-independent; with known landmarks
there is no unobservable direction for that to protect, and the left form takes the motion noise untransported.

Models (those of :mod:`locbench.filters.ekf_landmarks`): the same mean motion U = X^-1 f(X, u) (report 003's
midpoint chord, or the composed increment, :mod:`locbench.filters._motion`) and the same world-frame motion noise
N = G U G^T + Q, here Q_b = T+^-1 N T+^-T with T = blockdiag(R(theta), 1). A landmark l has body-frame position
p = R(theta)^T (l - t), range |p| and bearing atan2(p_y, p_x), and

    H_b = [[-p_x/|p|, -p_y/|p|,  0],
           [ p_y/|p|^2, -p_x/|p|^2, -1]]    = H_w T,

H_w the EKF's Jacobian; a beacon range has the first row; a pose fix (x, y[, theta]) has H_b = [R(theta) 0; 0 0 1].

How it is computed. The belief is stored as the EKF stores its own (mean, world-frame covariance P_w = T P_b
T^T), which makes three things exact identities rather than approximations:

1. the invariant prediction *is* the EKF's prediction in world coordinates: T+ Ad_{U^-1} T^-1 = F (the EKF's
   Jacobian of the composition, [[I, J R(theta) u_v], [0, 1]]) and T+ Q_b T+^T = N, so ``predict`` is the EKF's;
2. S and the Mahalanobis distance are the EKF's (H_b P_b H_b^T = H_w P_w H_w^T): association and gates are the
   same computations as the EKF's;
3. K_b = T^-1 K_w and the Joseph covariance transforms with T: the correction is the EKF's gain and Joseph step,
   followed by the retraction :func:`locbench.filters._iekf_kernels.retract` (the position moves along the arc
   V(w) d instead of the chord d, and P_w turns with the heading correction w).

The filter and the EKF therefore differ exactly where Barrau and Bonnabel say they should: in how a correction
moves the pose and its covariance, so a heading correction turns the position uncertainty with it.
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np

from locbench.core.events import LandmarkObservations, PoseFix
from locbench.filters import _iekf_kernels as kern
from locbench.filters.base import FilterConfig, FilterDoc
from locbench.filters.ekf_landmarks import LandmarkEKF, LandmarkEKFConfig

_update_packed = kern.update_packed  # bound once (a module attribute costs a lookup per event)
_retract = kern.retract
_correct = kern.correct_landmark


class LandmarkIEKF(LandmarkEKF):
    """Left-invariant EKF on SE(2) with the models, association and gates of :class:`LandmarkEKF`.

    It inherits the EKF's configuration (:class:`~locbench.filters.ekf_landmarks.LandmarkEKFConfig`: every field,
    the tunable noise included), event routing, prediction (module docstring, identity 1) and the order of one
    event's sightings; every correction ends with the group's retraction. Diagnostics as the EKF's.
    """

    id: ClassVar[str] = "iekf_landmarks"
    order: ClassVar[int] = 25
    description: ClassVar[str] = (
        "invariant EKF on SE(2) (left-invariant error) with ekf_landmarks' motion, landmark, range and fix models"
    )
    doc: ClassVar[FilterDoc | None] = FilterDoc(
        "Barrau & Bonnabel 2017; models of 003, 001",
        "`ekf_landmarks`' motion model as X+ = X U with P+ = Ad_{U^-1} P Ad_{U^-1}^T + Q (state-independent error "
        "propagation); checked against gtsam's `InvariantEKFPose2`",
        "`ekf_landmarks`' range-bearing, range-only and pose-fix models with body-frame Jacobians, X+ = X Exp(K v), "
        "Joseph form; the same association and gates",
        "left-invariant (body-frame) error; the covariance turns with each heading correction",
    )
    #: the default alone, as the UKF: the EKF's nearest-neighbour configuration is not repeated
    comparison_configurations: ClassVar[tuple[dict[str, str], ...]] = ()
    Config: ClassVar[type[FilterConfig]] = LandmarkEKFConfig
    version: ClassVar[int] = 1
    cost_per_data_s: ClassVar[float] = 0.02
    source: ClassVar[str] = (
        "Barrau & Bonnabel 2017, IEEE TAC 62(4) (invariant EKF); gtsam InvariantEKFPose2; models of "
        "003_e5c93f9be776ee5e and 001_71e01b0c4f2511a1"
    )

    def _update_landmarks(self, z: LandmarkObservations) -> None:
        """The EKF's fusion of one event's sightings with the invariant correction (compiled,
        :func:`locbench.filters._iekf_kernels.update_packed`); a large map's association through the EKF's
        k-d tree path, whose corrections come back to :meth:`_correct_landmark`."""
        if self._lm_warn:
            self._warn_landmark_noise()
        if len(z.ranges) > self._rows_room:
            self._rows(len(z.ranges))
        n_def = _update_packed(self._buf, z.ids, z.ranges, z.bearings, self._ibuf)
        nis, acc, rej, missing, finite = self._out.tolist()
        if missing:
            self._log_unmapped(z)
        if n_def:
            codes = self._rows(len(z.ranges)).tolist()
            d_nis, d_acc, d_rej = self._fuse(z.ranges, z.bearings, codes, self._used, associate=True)
            nis, acc, rej = nis + d_nis, acc + d_acc, rej + d_rej
            finite = np.isfinite(self._s).all()
        self._nis = nis if acc else math.nan
        self._nis_dof, self._accepted, self._rejected = 2 * int(acc), int(acc), int(rej)
        if not finite:
            self._diverged(z.t)

    def _correct_landmark(self, r: float, b: float, row: int, gate: float) -> float | None:
        """One invariant correction with the sighting of landmark ``row``; its NIS, or None if gated out."""
        lx, ly = self._lm_list[row]
        d2 = float(_correct(self._s, r, b, lx, ly, self._rr, self._rb, gate))
        return None if math.isnan(d2) else d2

    def _correct_range(self, r: float, row: int) -> float | None:
        """A beacon range: the EKF's gated Joseph step (H_b = H_w T), then the retraction."""
        x0, y0, th0 = self._x
        d2 = super()._correct_range(r, row)
        if d2 is not None:
            _retract(self._s, x0, y0, th0)
        return d2

    def _update_pose_fix(self, z: PoseFix) -> None:
        """A pose fix: the EKF's Joseph step (H_b = [R(theta) 0; 0 0 1] = H_w T), then the retraction."""
        x0, y0, th0 = self._x
        super()._update_pose_fix(z)
        _retract(self._s, x0, y0, th0)
