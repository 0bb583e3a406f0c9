"""Point-to-point ICP for 2-D scans (the scan matcher of the EKF-ICP filter, report 000 sec. III-A.2, whose
transform gives the observation of eq. 2-3).

Classic ICP (Besl & McKay 1992): exact nearest neighbours within the rejection distance from a uniform
grid of buckets built once on the fixed target cloud (cells of a quarter of the initial rejection distance,
searched in rings around the query until no nearer point can remain; a kd-tree gives the same neighbours,
ties going to the lower index), and the closed-form 2-D rigid alignment of the matched pairs (the 2-D case
of Arun, Huang & Blostein 1987: rotation from the cross-covariance of the centred pairs, then the
translation). The whole loop is one compiled (numba) function, :func:`_icp_loop`: for a few hundred points
per scan the per-call overhead of a kd-tree query and of numpy's small reductions would dominate an interpreted
loop.

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
from numba import njit

logger = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
#: A bucket grid over a point cloud (:func:`_buckets`): order, start, x0, y0, nx, ny, cell.
Buckets = tuple[IntArray, IntArray, float, float, int, int, float]
#: A rigid 2-D transform (tx m, ty m, theta rad).
Transform = tuple[float, float, float]

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


@njit(cache=True)
def _rigid_transform(
    src: FloatArray, dst: FloatArray, si: IntArray, di: IntArray, n: int
) -> tuple[float, float, float]:
    """The least-squares rigid transform of n paired points (the 2-D case of Arun, Huang & Blostein 1987).

    Over the pairs (src[si[k]], dst[di[k]]), k < n, with a and b the points less their centroids, theta =
    atan2(sum a x b, sum a . b) maximises sum b . R(theta) a, and t = mean(dst) - R(theta) mean(src).

    Parameters
    ----------
    src, dst : ndarray, shape (., 2)
        The two clouds, one common frame, m.
    si, di : ndarray of int64
        The pairs' indices into them; the first ``n`` are used (n >= 1).
    n : int
        Number of pairs.

    Returns
    -------
    tuple of float
        (tx m, ty m, theta rad) with dst[di[k]] ~= R(theta) src[si[k]] + t.
    """
    msx = 0.0
    msy = 0.0
    mdx = 0.0
    mdy = 0.0
    for k in range(n):
        msx += src[si[k], 0]
        msy += src[si[k], 1]
        mdx += dst[di[k], 0]
        mdy += dst[di[k], 1]
    msx /= n
    msy /= n
    mdx /= n
    mdy /= n
    # 2-D Procrustes: theta maximises sum b . R a, i.e. atan2(sum a x b, sum a . b), a and b centred.
    sxx = 0.0
    sxy = 0.0
    for k in range(n):
        ax = src[si[k], 0] - msx
        ay = src[si[k], 1] - msy
        bx = dst[di[k], 0] - mdx
        by = dst[di[k], 1] - mdy
        sxx += ax * bx + ay * by
        sxy += ax * by - ay * bx
    th = math.atan2(sxy, sxx)
    c, s = math.cos(th), math.sin(th)
    return mdx - (c * msx - s * msy), mdy - (s * msx + c * msy), th


def rigid_transform_2d(src: FloatArray, dst: FloatArray) -> tuple[float, float, float]:
    """Least-squares rigid transform (tx m, ty m, theta rad) with dst ~= R(theta) src + t, for paired (n, 2)
    points (n >= 2) in one frame (:func:`_rigid_transform` over all of them)."""
    a = np.ascontiguousarray(src, dtype=np.float64)
    b = np.ascontiguousarray(dst, dtype=np.float64)
    idx = np.arange(a.shape[0], dtype=np.int64)
    return _rigid_transform(a, b, idx, idx, int(a.shape[0]))


@njit(cache=True)
def _buckets(pts: FloatArray, gate: float) -> Buckets:
    """A uniform grid of square cells over the points: the point indices sorted by cell (``order``) and each
    cell's first position in it (``start``, one more entry than cells), the grid's lower-left corner, its size
    in cells (nx, ny) and the cell side: ``gate``, or 1/512 of the cloud's extent if that is larger (a
    bound on the grid's memory; a query stays exact with any side)."""
    n = pts.shape[0]
    x0 = pts[0, 0]
    y0 = pts[0, 1]
    x1 = x0
    y1 = y0
    for i in range(n):
        x0 = min(x0, pts[i, 0])
        y0 = min(y0, pts[i, 1])
        x1 = max(x1, pts[i, 0])
        y1 = max(y1, pts[i, 1])
    cell = max(gate, (x1 - x0) / 512.0, (y1 - y0) / 512.0, 1e-9)
    nx = int((x1 - x0) / cell) + 1
    ny = int((y1 - y0) / cell) + 1
    cell_of = np.empty(n, dtype=np.int64)
    start = np.zeros(nx * ny + 1, dtype=np.int64)
    for i in range(n):
        cx = min(int((pts[i, 0] - x0) / cell), nx - 1)
        cy = min(int((pts[i, 1] - y0) / cell), ny - 1)
        cell_of[i] = cy * nx + cx
        start[cell_of[i] + 1] += 1
    for c in range(nx * ny):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    order = np.empty(n, dtype=np.int64)
    for i in range(n):
        order[fill[cell_of[i]]] = i
        fill[cell_of[i]] += 1
    return order, start, x0, y0, nx, ny, cell


@njit(cache=True)
def _nearest_within(px: float, py: float, pts: FloatArray, grid: Buckets, bound: float) -> tuple[float, int]:
    """The nearest of ``pts`` to (px, py) among those closer than ``bound`` (distance, index), exact, ties to
    the lower index (as a kd-tree query); (inf, -1) if none.

    ``grid`` is :func:`_buckets` of ``pts``. The cells are searched in square rings around the query's cell;
    after ring r every unsearched point is at least r cells away, so the search stops once the best distance
    is below that, or the rings have covered ``bound``.
    """
    order, start, x0, y0, nx, ny, cell = grid
    qx = math.floor((px - x0) / cell)
    qy = math.floor((py - y0) / cell)
    rings = math.floor(bound / cell) + 1
    best2 = math.inf
    best = -1
    for r in range(rings + 1):
        for cy in range(qy - r, qy + r + 1):
            if cy < 0 or cy >= ny:
                continue
            edge = cy == qy - r or cy == qy + r
            step = 1 if edge else 2 * r  # inner rows of the ring: only its two end cells
            cx = qx - r
            while cx <= qx + r:
                if 0 <= cx < nx:
                    c = cy * nx + cx
                    for k in range(start[c], start[c + 1]):
                        j = order[k]
                        dx = px - pts[j, 0]
                        dy = py - pts[j, 1]
                        d2 = dx * dx + dy * dy
                        if d2 < best2 or (d2 == best2 and j < best):
                            best2 = d2
                            best = j
                cx += step
        reach = r * cell  # every point of ring r + 1 and beyond is at least this far
        if best2 < reach * reach * (1.0 - 1e-12):
            break
    d = math.sqrt(best2)
    if d < bound:
        return d, best
    return math.inf, -1


@njit(cache=True)
def _associate(
    src: FloatArray,
    dst: FloatArray,
    grid: Buckets,
    tx: float,
    ty: float,
    th: float,
    gate: float,
    si: IntArray,
    di: IntArray,
    dk: FloatArray,
) -> int:
    """Pair each source point, moved by (tx, ty, th), with its nearest target point closer than ``gate``:
    the m pairs go to si, di (indices) and dk (distances); returns m."""
    c, s = math.cos(th), math.sin(th)
    m = 0
    for i in range(src.shape[0]):
        px = c * src[i, 0] - s * src[i, 1] + tx
        py = s * src[i, 0] + c * src[i, 1] + ty
        d, j = _nearest_within(px, py, dst, grid, gate)
        if j >= 0:
            si[m] = i
            di[m] = j
            dk[m] = d
            m += 1
    return m


@njit(cache=True)
def _icp_loop(
    src: FloatArray, dst: FloatArray, gates: tuple[float, float], max_iterations: int, eps: float, T0: Transform
) -> tuple[float, float, float, bool, int, int, float, float]:
    """The iterations of :func:`icp_2d` (module docstring).

    Parameters
    ----------
    src, dst : ndarray, shape (n, 2) and (m, 2), C-contiguous
        Source and target points, one frame, m; n, m >= ``MIN_PAIRS``.
    gates : tuple of float
        (D_0, D_min): the initial rejection distance and the floor of Zhang's adaptive one, m.
    max_iterations : int
        Iteration cap (>= 1).
    eps : float
        PCL's transformation epsilon (m^2 for the translation, 1 - cos for the rotation).
    T0 : tuple of float
        Starting transform (tx m, ty m, theta rad).

    Returns
    -------
    tuple
        (tx, ty, theta, converged, iterations, matched, rmse m, final rejection distance m), the fields of
        :class:`IcpResult`.
    """
    gate0, d_min = gates
    tx, ty, th = T0
    n = src.shape[0]
    # cells of a quarter of the initial gate: a neighbour within it is found in the first rings
    grid = _buckets(dst, 0.25 * gate0)
    si = np.empty(n, dtype=np.int64)
    di = np.empty(n, dtype=np.int64)
    dk = np.empty(n)
    gate = gate0
    cos_tol = 1.0 - eps
    converged = False
    it = 0
    for it in range(1, max_iterations + 1):
        m = _associate(src, dst, grid, tx, ty, th, gate, si, di, dk)
        if m < MIN_PAIRS:
            return tx, ty, th, False, it, m, math.nan, gate
        ntx, nty, nth = _rigid_transform(src, dst, si, di, m)
        # Zhang's adaptive distance: mean + 3 std of the kept pairs, monotone, floored at the noise level.
        mean = 0.0
        for k in range(m):
            mean += dk[k]
        mean /= m
        var = 0.0
        for k in range(m):
            var += (dk[k] - mean) ** 2
        gate = min(gate, max(d_min, mean + 3.0 * math.sqrt(var / m)))
        dt2 = (ntx - tx) ** 2 + (nty - ty) ** 2
        dcos = math.cos(nth - th)
        tx, ty, th = ntx, nty, nth
        if dt2 <= eps and dcos >= cos_tol:
            converged = True
            break
    m = _associate(src, dst, grid, tx, ty, th, gate, si, di, dk)
    sq = 0.0
    for k in range(m):
        sq += dk[k] * dk[k]
    rmse = math.sqrt(sq / m) if m else math.nan
    return tx, ty, th, converged, it, m, rmse, gate


def align(
    src: FloatArray,
    dst: FloatArray,
    gates: tuple[float, float],
    max_iterations: int,
    transformation_epsilon: float,
    initial: Transform = (0.0, 0.0, 0.0),
) -> IcpResult:
    """:func:`icp_2d` on clouds the caller has checked: C-contiguous float64 (n, 2) and (m, 2) arrays of at least
    ``MIN_PAIRS`` points, 0 < D_min <= D_0 = ``gates`` (m), ``max_iterations`` >= 1."""
    tx, ty, th, converged, it, matched, rmse, gate = _icp_loop(
        src, dst, gates, max_iterations, transformation_epsilon, initial
    )
    return IcpResult((tx, ty, th), bool(converged), int(it), int(matched), float(rmse), float(gate))


def icp_2d(
    source: npt.ArrayLike,
    target: npt.ArrayLike,
    *,
    max_correspondence_m: float,
    min_correspondence_m: float,
    max_iterations: int = 700,
    transformation_epsilon: float = 5e-7,
    initial: tuple[float, float, float] = (0.0, 0.0, 0.0),
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
    return align(src, dst, (gate, float(min_correspondence_m)), int(max_iterations), float(transformation_epsilon), T)
