"""Point-to-point ICP for 2-D scans (the scan matcher of the EKF-ICP filter, report 000 sec. III-A.2).

Classic ICP (Besl & McKay 1992) with nearest neighbours from a scipy ``cKDTree`` built once on the fixed
target cloud (queried with ``workers=1``: for a few hundred points threads cost more than they save,
PACKAGES.md 4d) and the closed-form 2-D rigid alignment of the matched pairs (the 2-D case of Arun,
Huang & Blostein 1987: rotation from the cross-covariance of the centred pairs, then the translation).

Correspondence rejection follows Zhang ("Iterative point matching for registration of free-form curves
and surfaces", IJCV 1994): a pair is kept when its distance is below D, where D starts at the caller's
``max_correspondence_m`` (what the predicted pose uncertainty allows) and after each iteration becomes
mean + 3 std of the kept distances, never below ``min_correspondence_m`` (what sensor noise and map
discretisation alone allow) and never above its previous value. Each iteration re-estimates the whole
transform from the original source points, so no error accumulates over iterations.

Convergence uses PCL's transformation-epsilon rule (``pcl::registration::DefaultConvergenceCriteria``):
converged when the squared translation change between two iterations is at most epsilon and the cosine
of the rotation change is at least 1 - epsilon.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

logger = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]

#: A rigid 2-D transform needs at least this many pairs.
MIN_PAIRS = 3


@dataclass(frozen=True)
class IcpResult:
    """The outcome of one ICP alignment.

    Attributes
    ----------
    transform : tuple of float
        (tx m, ty m, theta rad) such that target ~= R(theta) source + t, in the clouds' common frame.
    converged : bool
        The transformation-epsilon rule held before ``max_iterations``.
    iterations : int
        Iterations run.
    matched : int
        Source points with a target neighbour within the final rejection distance, at the final transform.
    rmse_m : float
        RMS distance of those pairs, m (NaN when none).
    correspondence_m : float
        The final rejection distance D, m.
    """

    transform: tuple[float, float, float]
    converged: bool
    iterations: int
    matched: int
    rmse_m: float
    correspondence_m: float


def rigid_transform_2d(src: FloatArray, dst: FloatArray) -> tuple[float, float, float]:
    """Least-squares rigid transform (tx, ty, theta) with dst ~= R src + t, for paired (n, 2) points (n >= 2)."""
    ms = src.mean(axis=0)
    md = dst.mean(axis=0)
    a = src - ms
    b = dst - md
    # 2-D Procrustes: theta maximises sum b . R a, i.e. atan2(sum a x b, sum a . b).
    sxx = float(np.dot(a[:, 0], b[:, 0]) + np.dot(a[:, 1], b[:, 1]))
    sxy = float(np.dot(a[:, 0], b[:, 1]) - np.dot(a[:, 1], b[:, 0]))
    th = math.atan2(sxy, sxx)
    c, s = math.cos(th), math.sin(th)
    tx = float(md[0] - (c * ms[0] - s * ms[1]))
    ty = float(md[1] - (s * ms[0] + c * ms[1]))
    return tx, ty, th


def _apply(T: tuple[float, float, float], pts: FloatArray) -> FloatArray:
    c, s = math.cos(T[2]), math.sin(T[2])
    out = np.empty_like(pts)
    out[:, 0] = c * pts[:, 0] - s * pts[:, 1] + T[0]
    out[:, 1] = s * pts[:, 0] + c * pts[:, 1] + T[1]
    return out


def icp_2d(
    source: npt.ArrayLike,
    target: npt.ArrayLike,
    *,
    max_correspondence_m: float,
    min_correspondence_m: float,
    max_iterations: int = 700,
    transformation_epsilon: float = 5e-7,
    initial: tuple[float, float, float] = (0.0, 0.0, 0.0),
    tree: cKDTree | None = None,
) -> IcpResult:
    """Align ``source`` onto ``target`` by point-to-point ICP.

    Parameters
    ----------
    source, target : array-like, shape (n, 2) and (m, 2)
        Points in one common frame, m; ``target`` stays fixed.
    max_correspondence_m : float
        Initial rejection distance D, m: pairs farther apart are not used.
    min_correspondence_m : float
        Floor of the adaptive D, m (<= ``max_correspondence_m``).
    max_iterations : int
        Iteration cap (PCL ``setMaximumIterations``).
    transformation_epsilon : float
        PCL ``setTransformationEpsilon``: squared translation change (m^2) and 1 - cos of the rotation change.
    initial : tuple of float
        Starting transform (tx, ty, theta).
    tree : cKDTree or None
        A tree already built on ``target`` (saves the build when the caller has one).

    Returns
    -------
    IcpResult
        ``converged`` is False when fewer than 3 pairs survive the rejection or the cap is reached.
    """
    src = np.ascontiguousarray(source, dtype=np.float64).reshape(-1, 2)
    dst = np.ascontiguousarray(target, dtype=np.float64).reshape(-1, 2)
    if not (0.0 < min_correspondence_m <= max_correspondence_m):
        raise ValueError(
            f"need 0 < min_correspondence_m <= max_correspondence_m, got {min_correspondence_m}, {max_correspondence_m}"
        )
    if max_iterations < 1:
        raise ValueError(f"max_iterations must be >= 1, got {max_iterations}")
    T = (float(initial[0]), float(initial[1]), float(initial[2]))
    gate = float(max_correspondence_m)
    if src.shape[0] < MIN_PAIRS or dst.shape[0] < MIN_PAIRS:
        return IcpResult(T, False, 0, 0, math.nan, gate)
    kd = tree if tree is not None else cKDTree(dst)
    cos_tol = 1.0 - transformation_epsilon
    converged = False
    it = 0
    for it in range(1, max_iterations + 1):
        d, idx = kd.query(_apply(T, src), k=1, workers=1, distance_upper_bound=gate)
        keep = d < gate
        n_keep = int(np.count_nonzero(keep))
        if n_keep < MIN_PAIRS:
            return IcpResult(T, False, it, n_keep, math.nan, gate)
        dk = d[keep]
        T_new = rigid_transform_2d(src[keep], dst[idx[keep]])
        # Zhang's adaptive distance: mean + 3 std of the kept pairs, monotone, floored at the noise level.
        gate = min(gate, max(min_correspondence_m, float(dk.mean() + 3.0 * dk.std())))
        dt2 = (T_new[0] - T[0]) ** 2 + (T_new[1] - T[1]) ** 2
        dcos = math.cos(T_new[2] - T[2])
        T = T_new
        if dt2 <= transformation_epsilon and dcos >= cos_tol:
            converged = True
            break
    d, _ = kd.query(_apply(T, src), k=1, workers=1, distance_upper_bound=gate)
    keep = d < gate
    n_keep = int(np.count_nonzero(keep))
    rmse = float(np.sqrt(np.mean(d[keep] ** 2))) if n_keep else math.nan
    return IcpResult(T, converged, it, n_keep, rmse, gate)
