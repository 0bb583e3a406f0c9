"""The estimate contract: what every :class:`~locbench.filters.base.Estimate` a filter returns must satisfy.

A filter's estimate has a mean of shape (3,) (x m, y m, theta rad with theta wrapped to (-pi, pi]) and a
covariance of shape (3, 3) that is symmetric and positive semi-definite. The runner checks it on every
estimate of every run (:class:`locbench.run.filter_pass.FilterPass`): the shapes as each estimate is taken (a wrong
shape would otherwise be broadcast into the run's arrays, silently or as an internal error), the values once
over the whole trace at the end of the run (:func:`first_violation`, vectorised: one batched eigenvalue call
instead of one per event). A violation fails the run with a one-line message naming the contract, the value
and the time. A non-finite estimate is not a violation here: the runner stores it as a divergence.

Tolerances, relative to the scale of each covariance ``m = max(1, max|P_ij|)`` (the scale of
:func:`locbench.core.geometry.is_symmetric_psd`, which ``locbench check`` uses: a filter that passes its checks
passes here; the floor of 1 m^2 or rad^2 keeps the rounding of an update that shrinks a large prior to a small
posterior from failing it):

* symmetric: ``max|P - P^T| <= SYMMETRY_RTOL * m``;
* positive semi-definite: the smallest eigenvalue of ``(P + P^T) / 2`` ``>= -PSD_RTOL * m``;
* heading: ``|theta| <= pi + HEADING_ATOL`` (wrapped, with room for the rounding of a wrap).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

#: Relative tolerance of the symmetry check (see the module).
SYMMETRY_RTOL = 1e-9
#: Relative tolerance of the positive semi-definiteness check: the smallest eigenvalue may be this much of the
#: largest entry below zero (rounding of an update that leaves a variance near zero).
PSD_RTOL = 1e-9
#: Absolute tolerance on the heading bound pi, rad.
HEADING_ATOL = 1e-9
#: The largest heading magnitude accepted, rad.
HEADING_BOUND = math.pi + HEADING_ATOL


class EstimateContractError(Exception):
    """An estimate that breaks the contract; the message is one line naming the contract, the value and the time."""


def check_shapes(mean: Any, cov: Any, t: float) -> None:
    """Raise :class:`EstimateContractError` unless ``mean`` has shape (3,) and ``cov`` shape (3, 3).

    The fast path reads the ``shape`` attribute of the arrays a filter normally returns (about 0.1 us);
    anything else goes through ``np.shape``.
    """
    if getattr(mean, "shape", None) != (3,) and _shape(mean) != (3,):
        raise EstimateContractError(
            f"estimate contract: mean of shape {_shape(mean)} at t={t:.3f} s, expected (3,) (x m, y m, theta rad)"
        )
    if getattr(cov, "shape", None) != (3, 3) and _shape(cov) != (3, 3):
        raise EstimateContractError(
            f"estimate contract: covariance of shape {_shape(cov)} at t={t:.3f} s, expected (3, 3)"
        )


def _shape(x: Any) -> tuple[int, ...] | str:
    try:
        return tuple(np.shape(x))
    except (ValueError, TypeError):
        return f"unknown ({type(x).__name__})"


def first_violation(t: np.ndarray, mean: np.ndarray, cov: np.ndarray) -> tuple[int, str] | None:
    """The first row of a trace whose estimate breaks the contract's values, and the one-line message; or None.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Times of the rows, s.
    mean : ndarray, shape (n, 3)
        Means (x m, y m, theta rad).
    cov : ndarray, shape (n, 3, 3)
        Covariances.

    Rows with a non-finite number are not judged (a divergence, stored as such by the runner).
    """
    n = t.shape[0]
    if n == 0:
        return None
    finite = np.isfinite(mean).all(axis=1) & np.isfinite(cov).all(axis=(1, 2))
    scale = np.maximum(np.abs(cov).max(axis=(1, 2)), 1.0)
    asym = np.abs(cov - cov.transpose(0, 2, 1)).max(axis=(1, 2))
    heading = np.abs(mean[:, 2])
    bad_heading = finite & (heading > HEADING_BOUND)
    bad_sym = finite & (asym > SYMMETRY_RTOL * scale)
    # Positive leading principal minors prove a symmetric matrix positive definite (Sylvester), at a few
    # elementwise operations per row; only the other finite rows (a zero variance, an indefinite matrix) pay for
    # the eigenvalues of their symmetric part (a batched eigvalsh costs about 1 us per row).
    a, b, c = cov[:, 0, 0], cov[:, 0, 1], cov[:, 0, 2]
    d, e, f = cov[:, 1, 1], cov[:, 1, 2], cov[:, 2, 2]
    with np.errstate(invalid="ignore", over="ignore"):
        det = a * (d * f - e * e) - b * (b * f - e * c) + c * (b * e - d * c)
        definite = (a > 0) & (a * d - b * b > 0) & (det > 0)
    doubtful = finite & ~definite
    min_eig = np.full(n, np.inf)
    if doubtful.any():
        sym = 0.5 * (cov[doubtful] + cov[doubtful].transpose(0, 2, 1))
        min_eig[doubtful] = np.linalg.eigvalsh(sym)[:, 0]
    bad_psd = finite & ~bad_sym & (min_eig < -PSD_RTOL * scale)
    bad = bad_heading | bad_sym | bad_psd
    if not bad.any():
        return None
    i = int(np.argmax(bad))
    at = f"at t={t[i]:.3f} s (row {i})"
    if bad_heading[i]:
        return i, (
            f"estimate contract: heading {mean[i, 2]:.6g} rad {at} outside [-pi, pi] (headings are wrapped to "
            f"(-pi, pi], tolerance {HEADING_ATOL:g} rad)"
        )
    if bad_sym[i]:
        return i, (
            f"estimate contract: covariance not symmetric {at}: max|P - P^T| = {asym[i]:.3g} > "
            f"{SYMMETRY_RTOL:g} x max(1, max|P|) = {SYMMETRY_RTOL * scale[i]:.3g}"
        )
    return i, (
        f"estimate contract: covariance not positive semi-definite {at}: smallest eigenvalue {min_eig[i]:.3g} < "
        f"-{PSD_RTOL:g} x max(1, max|P|) = {-PSD_RTOL * scale[i]:.3g}"
    )
