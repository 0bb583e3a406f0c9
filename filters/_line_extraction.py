"""Line extraction from a planar laser scan by split-and-merge, shared by the line-map filters.

The front-end of report 002 (``ekf_lines``): the scan is turned into straight segments, each described by
its infinite line in Hessian normal form in the robot frame, a 2x2 covariance, its end points and length.

Steps
-----
1. **Points.** Every finite return within [range_min, range_max) becomes a point in the robot frame (the
   sensor's mounting pose applied).
2. **Breakpoints.** Consecutive points (in beam order) are cut apart where a beam has no return between
   them or where they lie farther apart than ``max(gap_min_m, gap_factor * r * angle_increment)``: a
   depth jump or a door gap, so that a segment never bridges two collinear walls.
3. **Split** (iterative end-point fit, Ramer-Douglas-Peucker): a run is split at the point farthest from
   the chord through its ends while that distance exceeds max(``split_threshold_m``, 3 ``sigma_m``): a point
   on a straight wall lies within 3 sigma of it with probability 0.997, so noise alone rarely splits a wall.
4. **Merge.** Neighbouring segments whose joint fit keeps every point within ``split_threshold_m`` of the
   line are merged (the split step can cut a straight wall where noise makes an end point an outlier).
5. **Fit.** Each segment with at least ``min_points`` points and ``min_length_m`` length is fitted by total
   least squares (orthogonal regression) and gets the first-order covariance of that fit.

Every step runs compiled (numba): the points (:func:`_scan_points`), steps 2-5 as one function over a scan's
points (:func:`_segments`), and the end points and lengths of the segments kept (:func:`_assemble`).

Line parameters: a line is {p : p . (cos psi, sin psi) = rho} in the robot frame with ``rho`` >= 0 (m) and
``psi`` in (-pi, pi] (rad), the convention of :meth:`locbench.datasets.dataset.LineMap.rho_psi`. For a line
passing (nearly) through the robot, rho is near 0 and the sign of the normal, hence psi, may flip by pi
between scans; the consumer must compare lines modulo that flip (``ekf_lines`` does).

Covariance of the fit: with n points, unit normal n(psi), tangent t(psi), centroid c, along-line coordinates
s_i = (p_i - c) . t and S = sum s_i^2, and an independent error of variance sigma^2 across the line at each
point, the linearised least-squares solution gives

    var(psi) = sigma^2 / S,   var(rho) = sigma^2 / n + (c . t)^2 sigma^2 / S,   cov(rho, psi) = (c . t) sigma^2 / S.

sigma is the laser's range noise (an upper bound on its component across the line).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numba import njit

from locbench.core.errors import ConfigError
from locbench.core.events import LaserScan
from locbench.raycast.beams import beam_point

FloatArray = npt.NDArray[np.float64]
logger = logging.getLogger(__name__)


@dataclass(frozen=True, kw_only=True)
class ExtractionParams:
    """Parameters of :func:`extract_lines`.

    Attributes
    ----------
    split_threshold_m : float
        Largest distance of a point from its segment's line before the segment is split, m (at least
        3 ``sigma_m`` is used).
    min_points : int
        Fewest points a segment must have to be reported (>= 3, so the fit has redundancy).
    min_length_m : float
        Shortest segment reported (distance between its end points projected on the line), m.
    gap_min_m : float
        Consecutive points farther apart than ``max(gap_min_m, gap_factor * r * angle_increment)`` start a
        new run, m.
    gap_factor : float
        Multiple of the beam spacing at range r that still counts as contiguous (>= 1).
    sigma_m : float
        Range noise of one point, m (> 0), for the covariance of the fit.
    """

    split_threshold_m: float = 0.05
    min_points: int = 4
    min_length_m: float = 0.3
    gap_min_m: float = 0.2
    gap_factor: float = 3.0
    sigma_m: float = 0.01

    def __post_init__(self) -> None:
        if not self.split_threshold_m > 0:
            raise ConfigError(f"split_threshold_m must be > 0 m, got {self.split_threshold_m}")
        if self.min_points < 3:
            raise ConfigError(f"min_points must be >= 3, got {self.min_points}")
        if self.min_length_m < 0 or self.gap_min_m < 0:
            raise ConfigError("min_length_m and gap_min_m must be >= 0 m")
        if not self.gap_factor >= 1:
            raise ConfigError(f"gap_factor must be >= 1, got {self.gap_factor}")
        if not self.sigma_m > 0:
            raise ConfigError(f"sigma_m must be > 0 m, got {self.sigma_m}")


@dataclass(frozen=True, eq=False)
class ExtractedLines:
    """Lines extracted from one scan, robot frame.

    Attributes
    ----------
    rho_psi : ndarray, shape (k, 2)
        Hessian normal form (rho m >= 0, psi rad in (-pi, pi]).
    cov : ndarray, shape (k, 2, 2)
        Covariance of (rho, psi) from the fit (m^2, m rad, rad^2).
    endpoints : ndarray, shape (k, 2, 2)
        The two end points (x, y) of each segment, m: the first and last point projected on the line.
    lengths : ndarray, shape (k,)
        Distance between the end points, m.
    n_points : ndarray of int64, shape (k,)
        Points that entered each fit.
    """

    rho_psi: FloatArray
    cov: FloatArray
    endpoints: FloatArray
    lengths: FloatArray
    n_points: npt.NDArray[np.int64]

    def __len__(self) -> int:
        return int(self.rho_psi.shape[0])


def scan_points(scan: LaserScan) -> tuple[FloatArray, FloatArray, npt.NDArray[np.int64]]:
    """Valid returns of ``scan`` as robot-frame points.

    Returns
    -------
    points : ndarray, shape (m, 2)
        (x, y) in the robot frame, m, in beam order.
    ranges : ndarray, shape (m,)
        Their measured ranges, m.
    beam : ndarray of int64, shape (m,)
        Their beam indices.
    """
    sx, sy, sth = scan.sensor_pose
    return _scan_points(
        np.asarray(scan.ranges, dtype=np.float64),
        float(scan.range_min),
        float(scan.range_max),
        float(scan.angle_min),
        float(scan.angle_increment),
        float(sx),
        float(sy),
        float(sth),
    )


@njit(cache=True)
def _scan_points(
    r: FloatArray,
    range_min: float,
    range_max: float,
    angle_min: float,
    angle_increment: float,
    sx: float,
    sy: float,
    sth: float,
) -> tuple[FloatArray, FloatArray, npt.NDArray[np.int64]]:
    """Step 1: the valid returns of a scan as robot-frame points, in beam order.

    Parameters
    ----------
    r : ndarray, shape (n,)
        Ranges, m (``inf`` or NaN: no return).
    range_min, range_max : float
        A return is valid when finite and in [range_min, range_max), m.
    angle_min, angle_increment : float
        Bearing of beam i in the sensor frame: angle_min + angle_increment i, rad.
    sx, sy, sth : float
        The sensor's mounting pose in the robot frame (m, m, rad).

    Returns
    -------
    points : ndarray, shape (m, 2)
        (sx + r cos a, sy + r sin a) with a = angle_min + angle_increment i + sth, m.
    ranges : ndarray, shape (m,)
        The valid ranges, m.
    beam : ndarray of int64, shape (m,)
        Their beam indices.
    """
    n = r.shape[0]
    count = 0
    for i in range(n):
        if np.isfinite(r[i]) and r[i] >= range_min and r[i] < range_max:
            count += 1
    pts = np.empty((count, 2))
    rr = np.empty(count)
    beam = np.empty(count, dtype=np.int64)
    j = 0
    for i in range(n):
        ri = r[i]
        if np.isfinite(ri) and ri >= range_min and ri < range_max:
            a = angle_min + angle_increment * float(i) + sth
            pts[j, 0], pts[j, 1] = beam_point(sx, sy, ri, math.cos(a), math.sin(a))
            rr[j] = ri
            beam[j] = i
            j += 1
    return pts, rr, beam


@njit(cache=True)
def _fit_core(xs: FloatArray, ys: FloatArray, var: float) -> tuple[float, float, float, float, float, float]:
    """Total least squares (orthogonal regression) on the points (xs, ys), m, n >= 2.

    The normal n(psi) is the direction of least spread about the centroid c (psi = atan2(-2 S_xy, S_yy - S_xx) / 2
    from the centred second moments), rho = c . n made >= 0 by flipping the normal; the covariance is the module
    docstring's first-order one for an error of variance ``var`` (m^2) across the line at each point.

    Returns
    -------
    tuple of float
        (rho m, psi rad in (-pi, pi], var(rho) m^2, cov(rho, psi) m rad, var(psi) rad^2, the largest distance of
        a point from the line m).
    """
    n = xs.shape[0]
    cx = 0.0
    cy = 0.0
    for i in range(n):
        cx += xs[i]
        cy += ys[i]
    cx /= n
    cy /= n
    sxx = 0.0
    syy = 0.0
    sxy = 0.0
    for i in range(n):
        dx = xs[i] - cx
        dy = ys[i] - cy
        sxx += dx * dx
        syy += dy * dy
        sxy += dx * dy
    # the normal is the direction of least spread: psi minimises sum ((p - c) . n)^2
    psi = 0.5 * math.atan2(-2.0 * sxy, syy - sxx)
    cp = math.cos(psi)
    sp = math.sin(psi)
    rho = cx * cp + cy * sp
    if rho < 0.0:
        rho = -rho
        cp = -cp
        sp = -sp
    psi = math.atan2(sp, cp)
    big_s = 0.0
    resid = 0.0
    for i in range(n):
        dx = xs[i] - cx
        dy = ys[i] - cy
        s = -dx * sp + dy * cp  # along the line, t = (-sin psi, cos psi)
        big_s += s * s
        r = abs(dx * cp + dy * sp)
        if r > resid:
            resid = r
    big_s = max(big_s, 1e-12)
    ct = -cx * sp + cy * cp
    return rho, psi, var / n + ct * ct * var / big_s, ct * var / big_s, var / big_s, resid


def fit_line(points: FloatArray, sigma_m: float) -> tuple[float, float, FloatArray, float]:
    """Total-least-squares line through ``points`` (n, 2), n >= 2.

    Returns
    -------
    rho, psi : float
        Hessian normal form, rho >= 0 (m), psi in (-pi, pi] (rad).
    cov : ndarray, shape (2, 2)
        First-order covariance of (rho, psi) for an error of ``sigma_m`` across the line at each point
        (module docstring).
    max_residual : float
        Largest distance of a point from the fitted line, m.
    """
    p = np.ascontiguousarray(points, dtype=np.float64)
    rho, psi, vr, crp, vp, resid = _fit_core(p[:, 0].copy(), p[:, 1].copy(), sigma_m * sigma_m)
    return rho, psi, np.array([[vr, crp], [crp, vp]]), resid


@njit(cache=True)
def _split_core(xs: FloatArray, ys: FloatArray, lo: int, hi: int, thr: float) -> npt.NDArray[np.int64]:
    """Step 3, iterative end-point fit (Ramer-Douglas-Peucker) on the points [lo, hi) of one run.

    A piece is split at the point farthest from the chord through its ends while that distance exceeds ``thr``
    (m); the farthest point ends the first piece and starts the second. Returns the pieces' index ranges
    [a, b), shape (k, 2), sorted.
    """
    stack = [(lo, hi)]
    pieces = []
    while len(stack) > 0:
        a, b = stack.pop()
        if b - a <= 2:
            pieces.append((a, b))
            continue
        px, py = xs[a], ys[a]
        ux, uy = xs[b - 1] - px, ys[b - 1] - py
        norm = math.hypot(ux, uy)
        best = -1.0
        cut = a
        for i in range(a + 1, b - 1):
            # distance from the chord (from its start when both ends coincide)
            if norm < 1e-12:
                d = math.hypot(xs[i] - px, ys[i] - py)
            else:
                d = abs((xs[i] - px) * uy - (ys[i] - py) * ux) / norm
            if d > best:
                best = d
                cut = i
        if best > thr:
            # the farthest point (a corner) ends the first piece and starts the second
            stack.append((cut, b))
            stack.append((a, cut + 1))
        else:
            pieces.append((a, b))
    out = np.empty((len(pieces), 2), dtype=np.int64)
    for k in range(len(pieces)):
        out[k, 0] = pieces[k][0]
        out[k, 1] = pieces[k][1]
    order = np.argsort(out[:, 0])
    return out[order]


@njit(cache=True)
def _segments(
    xs: FloatArray,
    ys: FloatArray,
    rr: FloatArray,
    beam: npt.NDArray[np.int64],
    gap_min: float,
    gap_factor: float,
    beam_step: float,
    thr: float,
    var: float,
    min_points: int,
) -> tuple[npt.NDArray[np.int64], FloatArray]:
    """Steps 2-5 of the module docstring on the points (xs, ys) at ranges ``rr`` of beams ``beam``.

    ``beam_step`` is the absolute angle increment (rad). Returns the (k, 2) point ranges [lo, hi) of the fitted
    segments with at least ``min_points`` points and their (k, 5) fits (rho, psi, var rho, cov rho psi, var psi),
    before the length check.
    """
    # 2. breakpoints: a missing beam or a gap wider than the local beam spacing allows
    m = xs.shape[0]
    run_start = [0]
    for i in range(m - 1):
        step = math.hypot(xs[i + 1] - xs[i], ys[i + 1] - ys[i])
        allowed = max(gap_min, gap_factor * min(rr[i], rr[i + 1]) * beam_step)
        if beam[i + 1] - beam[i] > 1 or step > allowed:
            run_start.append(i + 1)
    run_start.append(m)
    # 3. split every run of at least two points
    piece_lo = []
    piece_hi = []
    for j in range(len(run_start) - 1):
        a = run_start[j]
        b = run_start[j + 1]
        if b - a >= 2:
            pcs = _split_core(xs, ys, a, b, thr)
            for k in range(pcs.shape[0]):
                piece_lo.append(pcs[k, 0])
                piece_hi.append(pcs[k, 1])
    # 4. merge neighbours of the same run: they share their corner point (previous end - 1 == this start)
    m_lo: list[int] = []
    m_hi: list[int] = []
    for k in range(len(piece_lo)):
        a = piece_lo[k]
        b = piece_hi[k]
        last = len(m_lo) - 1
        if last >= 0 and m_hi[last] > a and b - m_lo[last] >= 3:
            a0 = m_lo[last]
            if _fit_core(xs[a0:b], ys[a0:b], var)[5] <= thr:
                m_hi[last] = b
                continue
        m_lo.append(a)
        m_hi.append(b)
    # 5. fit; a corner point shared with a neighbouring piece is left out of both fits, so it bends neither
    n = len(m_lo)
    ranges = np.empty((n, 2), dtype=np.int64)
    fits = np.empty((n, 5))
    count = 0
    for k in range(n):
        a = m_lo[k]
        b = m_hi[k]
        lo = a + 1 if k > 0 and m_hi[k - 1] > a else a
        hi = b - 1 if k + 1 < n and m_lo[k + 1] < b else b
        if hi - lo < min_points:
            continue
        rho, psi, v_r, c_rp, v_p, _ = _fit_core(xs[lo:hi], ys[lo:hi], var)
        ranges[count, 0] = lo
        ranges[count, 1] = hi
        fits[count, 0] = rho
        fits[count, 1] = psi
        fits[count, 2] = v_r
        fits[count, 3] = c_rp
        fits[count, 4] = v_p
        count += 1
    return ranges[:count], fits[:count]


def extract_lines(scan: LaserScan, params: ExtractionParams | None = None) -> ExtractedLines:
    """Split-and-merge line extraction from one scan; see the module docstring.

    Parameters
    ----------
    scan : LaserScan
        The scan; ranges in m, ``inf`` for no return.
    params : ExtractionParams, optional
        Thresholds; defaults when None.

    Returns
    -------
    ExtractedLines
        Robot-frame lines in beam order (possibly none).
    """
    prm = params if params is not None else ExtractionParams()
    pts, rr, beam = scan_points(scan)
    empty = ExtractedLines(
        np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros((0, 2, 2)), np.zeros(0), np.zeros(0, dtype=np.int64)
    )
    m = pts.shape[0]
    if m < prm.min_points:
        return empty
    # 2-5. breakpoints, split, merge and fit (compiled)
    thr = max(prm.split_threshold_m, 3.0 * prm.sigma_m)
    xs, ys = np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1])
    ranges, fits = _segments(
        xs,
        ys,
        rr,
        beam,
        prm.gap_min_m,
        prm.gap_factor,
        abs(scan.angle_increment),
        thr,
        prm.sigma_m * prm.sigma_m,
        prm.min_points,
    )
    if ranges.shape[0] == 0:
        return empty
    n_keep, rho_psi, cov, endpoints, lengths, n_points = _assemble(xs, ys, ranges, fits, prm.min_length_m)
    if n_keep == 0:
        return empty
    return ExtractedLines(rho_psi=rho_psi, cov=cov, endpoints=endpoints, lengths=lengths, n_points=n_points)


@njit(cache=True)
def _assemble(
    xs: FloatArray, ys: FloatArray, ranges: npt.NDArray[np.int64], fits: FloatArray, min_length: float
) -> tuple[int, FloatArray, FloatArray, FloatArray, FloatArray, npt.NDArray[np.int64]]:
    """The fitted segments at least ``min_length`` long (m; a NaN length is kept), as the arrays of
    :class:`ExtractedLines`.

    A segment's end points are its first and last point projected on its line: with n = (cos psi, sin psi) and
    t = (-sin psi, cos psi), the point p becomes rho n + s t with s = p . t; its length is |s_last - s_first|.

    Parameters
    ----------
    xs, ys : ndarray, shape (m,)
        The scan's points, robot frame, m.
    ranges : ndarray of int64, shape (k, 2)
        Each segment's points [lo, hi).
    fits : ndarray, shape (k, 5)
        Each segment's (rho, psi, var rho, cov rho psi, var psi) from :func:`_fit_core`.
    min_length : float
        Shortest segment kept, m.

    Returns
    -------
    tuple
        (count kept, rho_psi (c, 2), cov (c, 2, 2), endpoints (c, 2, 2), lengths (c,), n_points (c,)).
    """
    k = ranges.shape[0]
    s = np.empty((k, 2))
    keep = np.empty(k, dtype=np.bool_)
    n_keep = 0
    for j in range(k):
        t0 = -math.sin(fits[j, 1])
        t1 = math.cos(fits[j, 1])
        a = ranges[j, 0]
        b = ranges[j, 1] - 1
        s[j, 0] = xs[a] * t0 + ys[a] * t1
        s[j, 1] = xs[b] * t0 + ys[b] * t1
        keep[j] = not abs(s[j, 1] - s[j, 0]) < min_length
        n_keep += keep[j]
    rho_psi = np.empty((n_keep, 2))
    cov = np.empty((n_keep, 2, 2))
    endpoints = np.empty((n_keep, 2, 2))
    lengths = np.empty(n_keep)
    n_points = np.empty(n_keep, dtype=np.int64)
    q = 0
    for j in range(k):
        if not keep[j]:
            continue
        rho = fits[j, 0]
        psi = fits[j, 1]
        n0 = math.cos(psi)
        n1 = math.sin(psi)
        t0 = -n1
        t1 = n0
        rho_psi[q, 0], rho_psi[q, 1] = rho, psi
        cov[q, 0, 0], cov[q, 0, 1], cov[q, 1, 0], cov[q, 1, 1] = fits[j, 2], fits[j, 3], fits[j, 3], fits[j, 4]
        for e in range(2):
            endpoints[q, e, 0] = rho * n0 + s[j, e] * t0
            endpoints[q, e, 1] = rho * n1 + s[j, e] * t1
        lengths[q] = abs(s[j, 1] - s[j, 0])
        n_points[q] = ranges[j, 1] - ranges[j, 0]
        q += 1
    return n_keep, rho_psi, cov, endpoints, lengths, n_points
