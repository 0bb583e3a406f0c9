"""The aligned view of a run: its estimates held at the ground-truth times once, which every per-time metric reads.

- **Zero-order hold** (:mod:`locbench.evaluate.hold`): the estimate in force at a time is the last stored row
  at or before it.
- **Align once, then compute** (as evo associates estimate and reference before any metric): :func:`align`
  holds a run's estimates at the ground-truth times once, giving an :class:`Aligned` view (times, held
  means and covariances, truth, wrapped errors, NEES) that :mod:`locbench.evaluate.metrics` and
  :mod:`locbench.evaluate.scores` take.
- Position errors in m, headings in rad wrapped to (-pi, pi], times in s; no alignment of the estimate to the
  truth (a localization filter works in the map frame).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import numpy.typing as npt

from locbench.core.geometry import pose_error
from locbench.evaluate.hold import hold_indices

FloatArray = npt.NDArray[np.float64]


# --- the aligned view: a run held at the ground-truth times, once ------------------------------------


@dataclass(frozen=True, eq=False)
class Aligned:
    """A run's estimates held at the ground-truth times (zero-order hold), made once by :func:`align`.

    Every per-time metric reads this view instead of re-running the hold on the raw arrays (evo associates
    estimate and reference once, then computes). Derived arrays are computed on first use and kept.

    Attributes
    ----------
    t : ndarray, shape (k,)
        Ground-truth times, s.
    rows : ndarray of intp, shape (k,)
        Row of the stored estimates in force at each time (:func:`hold_indices`); other per-row series of the
        run (its health signals) are held by indexing with it.
    mean : ndarray, shape (k, 3)
        Held estimate (x m, y m, theta rad), world frame.
    truth : ndarray, shape (k, 3)
        Ground-truth poses at ``t``, world frame.
    cov : ndarray, shape (k, 3, 3), or None
        Held covariance (None for a trajectory without one: a smoothed trajectory).
    """

    t: FloatArray
    rows: npt.NDArray[np.intp]
    mean: FloatArray
    truth: FloatArray
    cov: FloatArray | None = None

    @cached_property
    def error(self) -> FloatArray:
        """Estimate minus truth with the heading difference wrapped to (-pi, pi], shape (k, 3) (m, m, rad)."""
        return pose_error(self.mean, self.truth)

    @cached_property
    def position_error(self) -> FloatArray:
        """|p_hat(t_k) - p(t_k)|, shape (k,), m."""
        e = self.error
        return np.hypot(e[:, 0], e[:, 1])

    @cached_property
    def nees(self) -> FloatArray:
        """NEES of the pose at every time (:func:`nees`), shape (k,); needs ``cov``."""
        if self.cov is None:
            raise NoCovariance("this aligned trajectory has no covariance: no NEES")
        return nees(self.error, self.cov)


class NoCovariance(ValueError):
    """A metric needs a covariance the run does not have (an imported pose-only run): the metric does not apply."""


def align(
    t_est: npt.ArrayLike,
    mean: npt.ArrayLike,
    gt_t: npt.ArrayLike,
    gt_poses: npt.ArrayLike,
    cov: npt.ArrayLike | None = None,
) -> Aligned:
    """The :class:`Aligned` view of stored estimates at the ground-truth times (zero-order hold).

    Parameters
    ----------
    t_est : array-like, shape (n,)
        Times of the stored estimates, s, non-decreasing.
    mean : array-like, shape (n, 3)
        Estimated poses (x m, y m, theta rad), world frame.
    gt_t : array-like, shape (k,)
        Ground-truth times, s.
    gt_poses : array-like, shape (k, 3)
        Ground-truth poses, world frame.
    cov : array-like, shape (n, 3, 3), optional
        The estimates' covariances.
    """
    rows = hold_indices(t_est, gt_t)
    held_cov = None if cov is None else np.asarray(cov, dtype=np.float64)[rows]
    return Aligned(
        np.asarray(gt_t, dtype=np.float64),
        rows,
        np.asarray(mean, dtype=np.float64)[rows],
        np.asarray(gt_poses, dtype=np.float64),
        held_cov,
    )


def nees(errors: npt.ArrayLike, cov: npt.ArrayLike) -> FloatArray:
    """Normalised estimation error squared, e^T P^-1 e, per row.

    Parameters
    ----------
    errors : array-like, shape (n, d)
        Estimate minus truth with any angle already wrapped (:func:`locbench.core.geometry.pose_error`).
    cov : array-like, shape (n, d, d)
        The filter's covariance at the same rows.

    Returns
    -------
    ndarray, shape (n,)
        NEES (dimensionless, chi-square(d) for a consistent filter). A singular covariance claims
        certainty: its NEES is +inf unless the error is exactly zero (then 0). A covariance that is
        singular to rounding (a collapsed particle set) can make the solve return a negative value;
        that is not a NEES but the same claim of certainty, so it is +inf as well.
    """
    e = np.asarray(errors, dtype=np.float64)
    p = np.asarray(cov, dtype=np.float64)
    out = np.empty(e.shape[0])
    try:
        sol = np.linalg.solve(p, e[..., None])[..., 0]
        out[:] = np.einsum("ni,ni->n", e, sol)
    except np.linalg.LinAlgError:
        # Row by row so that one singular covariance does not spoil the others.
        for k in range(e.shape[0]):
            try:
                out[k] = float(e[k] @ np.linalg.solve(p[k], e[k]))
            except np.linalg.LinAlgError:
                out[k] = 0.0 if not np.any(e[k]) else np.inf
    out[out < 0.0] = np.inf
    return out
