"""The scan-database sensor front-end of report 004: scans recorded at known poses and a tolerance matcher.

Report 004 (section II) records, at each pose of a grid, the ranges seen at **eight fixed bearings**, and
turns a live scan into a pose by "tolerance matching ... using an average difference estimation between
corresponding values in each of the range sets". Here:

Database
    Positions on the square lattice (i * step_m, j * step_m) of the world frame over the occupancy grid
    (the "grid poses"), kept on known-free cells inside the building (not connected to the grid border through
    known-free cells; unknown cells of a mapped grid do not connect) and where the nearest
    occupied cell is at least ``clearance_m`` away (the robot cannot stand closer). Headings every
    ``heading_step_deg`` (a divisor of 45 deg). The eight bearings are 0, 45, ..., 315 deg in the robot
    frame. Because a heading change of 45 deg is a cyclic shift of the eight bearings, the database stores
    per position the ranges of ``360 / heading_step_deg`` world-frame directions (one ray-cast with
    :mod:`locbench.raycast.cast`); the eight ranges of (position, heading h) are columns h, h + m, ..., h + 7m
    (mod 360 / heading_step_deg) with m = 45 / heading_step_deg.

Matching
    The scan beam closest to each of the eight bearings is taken when it lies within half a beam spacing
    (plus 1e-9) of it; a scan with a narrower field of view uses the bearings it covers (at least
    ``min_bearings``). Ranges are capped at min(scan range_max, database max range), a "no return" (inf)
    counting as the cap, and the score of an entry is the mean absolute difference over the used bearings
    (report 004's average difference), m. Entries whose score is at most ``tolerance_m`` match. Optionally
    (the filter's default) only entries inside a chi-square validation region around the predicted pose
    are kept: a room with symmetries (a rectangle seen at 8 bearings looks the same turned by 180 deg)
    otherwise matches poses far from the robot equally well. The region is applied first and only the
    entries inside it are scored (one compiled loop, :func:`_matches`, that returns the matches), so a gated
    match costs in proportion to the region, not to the database.

Pose measurement and its covariance
    With d_i the scores of the n matches and weights w_i = 1 - d_i / tolerance (a triangular kernel: the
    best matches count most, a match at the tolerance not at all; all 1 when every d_i = tolerance), the
    measurement z is the weighted mean of the matched poses (headings averaged as wrapped differences
    from the best match). Its covariance is

        R = sum_i w_i (p_i - z)(p_i - z)^T / sum_i w_i  +  diag(s^2 / 12, s^2 / 12, h^2 / 12),

    the weighted scatter of the matches (large when the room's symmetry or a loose tolerance lets distant
    poses match; it keeps an ambiguous match from pulling the filter hard) plus the quantisation of the
    database: the true pose lies anywhere within one lattice cell (spacing s) and heading bin (h) of a
    database pose, and a uniform distribution over a width s has variance s^2 / 12.

Frames and units: world frame, metres, radians (``heading_step_deg`` in degrees). The sensor's heading
offset in the robot frame is taken into account; its (x, y) offset is ignored (the database is recorded at
the robot origin; every locbench dataset mounts its laser there).
"""

from __future__ import annotations

import functools
import logging
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numba import njit
from scipy import ndimage

from locbench.core.errors import ConfigError
from locbench.core.events import LaserScan
from locbench.core.geometry import wrap_angle, wrap_scalar
from locbench.core.limits import DATABASE_BYTES_PER_RAY, SCAN_DATABASE_BYTES_PER_CELL, check_bytes, grid_cells
from locbench.datasets.dataset import OccupancyGrid
from locbench.raycast.cast import cast_rays

logger = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

#: The number of fixed bearings per recorded scan (report 004: "eight angles at each ... position").
N_BEARINGS = 8
#: Their spacing, rad.
BEARING_STEP_RAD = 2.0 * math.pi / N_BEARINGS


#: Relative slack of the position pre-test of :func:`_matches`: a bound on the entries' distances, computed in
#: another order than each entry's own, must never drop an entry the entry's test keeps.
_GATE_SLACK = 1e-9

#: :func:`locbench.core.geometry.wrap_scalar` compiled (an angle to (-pi, pi]), for the kernels below. numba's
#: on-disk cache of a kernel is keyed on this module's source alone: after editing ``wrap_scalar``, delete the
#: ``*.nbi`` / ``*.nbc`` files under ``filters/__pycache__``.
_wrap = njit(cache=True, inline="always")(wrap_scalar)


@njit(cache=True)
def _matches(
    db: FloatArray,
    offsets: IntArray,
    r: FloatArray,
    tol: float,
    cap: float,
    positions: FloatArray,
    gated: bool,
    centre: FloatArray,
    info: FloatArray,
    gate: float,
    heading_step: float,
) -> tuple[IntArray, IntArray, FloatArray]:
    """The database entries that match a scan: within the tolerance and, with ``gated``, inside the validation
    region (module docstring, report 004's tolerance matching).

    The score of entry (i, h) is the mean over the k bearings b of |min(db[i, (h + o_b) mod M], cap) - r_b|, m.
    With ``gated`` an entry is scored only when inside the region e^T info e <= gate, e = (x_i - cx, y_i - cy,
    wrap(h heading_step - ctheta)); a position is skipped first when its (x, y) alone is outside (the least
    distance over the heading is the Mahalanobis distance under the (x, y) block of the covariance, whose
    inverse is the Schur complement of ``info``; with a relative slack of ``_GATE_SLACK``, as a bound).

    Parameters
    ----------
    db : ndarray, shape (N, M)
        Ranges of the N positions in the M world directions, m.
    offsets : ndarray of int64, shape (k,)
        Column offsets o_b of the scan's bearings.
    r : ndarray, shape (k,)
        The scan's ranges at its bearings, capped, m.
    tol : float
        Largest score of a match, m.
    cap : float
        Range cap, m.
    positions : ndarray, shape (N, 2)
        The positions, world frame, m.
    gated : bool
        Whether the validation region applies.
    centre : ndarray, shape (3,)
        Its centre (x m, y m, theta rad).
    info : ndarray, shape (3, 3)
        The inverse of its covariance.
    gate : float
        Its squared Mahalanobis radius.
    heading_step : float
        The database's heading spacing, rad.

    Returns
    -------
    tuple of ndarray
        The matched entries' positions i and headings h (int64), in row-major order, and their scores (m).
    """
    # long: one compiled pass over positions and headings (pre-test, gate, score, growing output); numpydoc
    n, m = db.shape
    k = offsets.shape[0]
    limit = tol * k
    g = gate * (1.0 + _GATE_SLACK)  # the position pre-test's bound
    # inverse of the (x, y) covariance block: info_xy - info_xt info_tt^-1 info_tx (Schur complement)
    a = info[0, 0] - info[0, 2] * info[2, 0] / info[2, 2]
    b = info[0, 1] - info[0, 2] * info[2, 1] / info[2, 2]
    c = info[1, 1] - info[1, 2] * info[2, 1] / info[2, 2]
    size = 64
    out_i = np.empty(size, dtype=np.int64)
    out_h = np.empty(size, dtype=np.int64)
    out_s = np.empty(size)
    count = 0
    for i in range(n):
        dx = positions[i, 0] - centre[0]
        dy = positions[i, 1] - centre[1]
        if gated and a * dx * dx + 2.0 * b * dx * dy + c * dy * dy > g:
            continue
        for h in range(m):
            if gated:
                dt = _wrap(h * heading_step - centre[2])
                d2 = (
                    info[0, 0] * dx * dx
                    + info[1, 1] * dy * dy
                    + info[2, 2] * dt * dt
                    + 2.0 * (info[0, 1] * dx * dy + info[0, 2] * dx * dt + info[1, 2] * dy * dt)
                )
                if not d2 <= gate:
                    continue
            s = 0.0
            for q in range(k):
                col = h + offsets[q]
                if col >= m:
                    col -= m
                v = db[i, col]
                if v > cap:
                    v = cap
                s += abs(v - r[q])
                if s > limit:  # most entries are rejected after one or two bearings
                    break
            if s <= limit and s / k <= tol:
                if count == size:
                    size *= 2
                    out_i = np.concatenate((out_i, np.empty(size - count, dtype=np.int64)))
                    out_h = np.concatenate((out_h, np.empty(size - count, dtype=np.int64)))
                    out_s = np.concatenate((out_s, np.empty(size - count)))
                out_i[count] = i
                out_h[count] = h
                out_s[count] = s / k
                count += 1
    return out_i[:count], out_h[:count], out_s[:count]


@dataclass(frozen=True, eq=False)
class ScanMatch:
    """A pose measurement from the database.

    Attributes
    ----------
    z : ndarray, shape (3,)
        Measured pose (x m, y m, theta rad in (-pi, pi]), world frame.
    cov : ndarray, shape (3, 3)
        Its covariance (see the module docstring).
    n_matches : int
        Database entries within the tolerance.
    best_score_m : float
        Smallest mean absolute range difference, m.
    n_bearings : int
        Bearings of the scan used.
    """

    z: FloatArray
    cov: FloatArray
    n_matches: int
    best_score_m: float
    n_bearings: int


@dataclass(frozen=True, eq=False)
class ScanDatabase:
    """Scans recorded at lattice positions, every ``heading_step_deg``, at eight fixed bearings.

    Attributes
    ----------
    positions : ndarray, shape (N, 2)
        Recorded positions, world frame, m.
    ranges : ndarray, shape (N, M)
        Range from position i in world direction j * heading_step, m, capped at ``max_range_m`` (a beam
        with no return within it is stored as ``max_range_m``).
    step_m : float
        Lattice spacing, m.
    heading_step_deg : float
        Heading spacing, deg (M = 360 / heading_step_deg).
    max_range_m : float
        Range cap of the recording, m.
    """

    positions: FloatArray
    ranges: FloatArray
    step_m: float
    heading_step_deg: float
    max_range_m: float

    @property
    def n_headings(self) -> int:
        return int(self.ranges.shape[1])

    @property
    def heading_step_rad(self) -> float:
        return math.radians(self.heading_step_deg)

    @functools.cached_property
    def quantisation(self) -> FloatArray:
        """diag(s^2 / 12, s^2 / 12, h^2 / 12): the database's quantisation covariance (module docstring), once."""
        return np.diag([self.step_m**2 / 12.0, self.step_m**2 / 12.0, self.heading_step_rad**2 / 12.0])

    def __len__(self) -> int:
        """Number of (position, heading) entries."""
        return int(self.ranges.shape[0] * self.ranges.shape[1])

    def entry_ranges(self, i: int, h: int) -> FloatArray:
        """The eight ranges of entry (position i, heading index h) at bearings 0, 45, ..., 315 deg, m."""
        m = self.n_headings // N_BEARINGS
        return self.ranges[i, (h + m * np.arange(N_BEARINGS)) % self.n_headings]

    def entry_pose(self, i: int, h: int) -> FloatArray:
        """World pose (x, y, theta) of entry (i, h)."""
        return np.array([self.positions[i, 0], self.positions[i, 1], float(wrap_angle(h * self.heading_step_rad))])


#: Largest lattice of recorded positions (each holds 360 / heading_step_deg ranges per bearing): the memory bound of
#: the database, 200 000 x 72 headings x 8 B = 115 MB of ranges at the default 5 deg.
MAX_LATTICE_POSITIONS = 200_000


def lattice_positions(grid: OccupancyGrid, step_m: float) -> float:
    """How many lattice positions a database on ``grid`` at ``step_m`` would consider (before the free-space cut)."""
    rows, cols = grid.shape
    res = grid.resolution
    return ((cols * res) / step_m + 1.0) * ((rows * res) / step_m + 1.0)


def lattice_too_large(grid: OccupancyGrid, step_m: float) -> str | None:
    """The refusal message when the lattice exceeds :data:`MAX_LATTICE_POSITIONS`, else None."""
    n_lattice = lattice_positions(grid, step_m)
    if n_lattice <= MAX_LATTICE_POSITIONS:
        return None
    rows, cols = grid.shape
    res = grid.resolution
    return (
        f"scan database: a {cols * res:.4g} m x {rows * res:.4g} m map on a {step_m} m lattice has "
        f"{n_lattice:.4g} positions, expected at most {MAX_LATTICE_POSITIONS} (the database's memory bound; "
        "raise grid_step_m)"
    )


def build_database(
    grid: OccupancyGrid,
    step_m: float,
    heading_step_deg: float,
    max_range_m: float,
    clearance_m: float,
) -> ScanDatabase:
    """Record the database on ``grid`` (ray-cast with :func:`locbench.raycast.cast.cast_rays`).

    Parameters
    ----------
    grid : OccupancyGrid
        The map; cells above its occupied threshold block beams.
    step_m : float
        Lattice spacing of the recorded positions, m; the positions are the world points
        (i * step_m, j * step_m) inside the grid.
    heading_step_deg : float
        Heading spacing, deg; must divide 45 exactly.
    max_range_m : float
        Recording range cap, m.
    clearance_m : float
        Positions closer than this to an occupied cell are left out, m.

    Returns
    -------
    ScanDatabase
    """
    # long: report 004's database construction (poses, casts, bearings, index) as one sequence; numpydoc
    if not step_m > 0:
        raise ConfigError(f"scan database: grid_step_m must be > 0 m, got {step_m}")
    per_bearing = 45.0 / heading_step_deg if heading_step_deg > 0 else 0.0
    if not (heading_step_deg > 0 and abs(per_bearing - round(per_bearing)) < 1e-9):
        raise ConfigError(f"scan database: heading_step_deg must divide 45 deg exactly, got {heading_step_deg}")
    if not (max_range_m > 0 and math.isfinite(max_range_m)):
        raise ConfigError(f"scan database: max_range_m must be a finite distance > 0 m, got {max_range_m}")
    if grid.origin[2] != 0.0:
        raise ConfigError("scan database: rotated occupancy grids are not supported")
    occ = grid.occupied()
    rows, cols = grid.shape
    res = grid.resolution
    ox, oy = grid.origin[0], grid.origin[1]
    # Refuse a lattice too large to hold before allocating it (a huge map or a tiny step): MAX_LATTICE_POSITIONS.
    too_large = lattice_too_large(grid, step_m)
    if too_large is not None:
        raise ConfigError(too_large)
    n_lattice = lattice_positions(grid, step_m)
    n_dir = round(360.0 / heading_step_deg)
    check_bytes(
        "kf_linear",
        f"the scan database of a {rows} x {cols} grid ({n_lattice:.4g} positions x {n_dir} headings)",
        grid_cells((rows, cols)) * SCAN_DATABASE_BYTES_PER_CELL + n_lattice * n_dir * DATABASE_BYTES_PER_RAY,
        "raise grid_step_m or heading_step_deg, or give a coarser or smaller map",
    )
    # The lattice holds the world points (i * step, j * step) inside the grid: "grid poses" of the world.
    xs = step_m * np.arange(math.ceil(ox / step_m), math.floor((ox + cols * res) / step_m) + 1)
    ys = step_m * np.arange(math.ceil(oy / step_m), math.floor((oy + rows * res) / step_m) + 1)
    gx, gy = np.meshgrid(xs, ys)
    pts = np.column_stack([gx.ravel(), gy.ravel()])
    # Distance (m) from each cell to the nearest occupied cell; no occupied cell at all means unbounded.
    dist = ndimage.distance_transform_edt(~occ) * res if occ.any() else np.full(occ.shape, np.inf)
    # Free space connected to the grid border lies outside the building: no robot stands there. Only cells known to
    # be free count (a mapped grid's unknown cells, -1, would otherwise join the inside to the border through every
    # open door; on a grid without unknown cells this is all of ~occ).
    free = grid.free()
    labels, _ = ndimage.label(free)
    border = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    outside = np.isin(labels, border[border > 0])
    cells = grid.world_to_cell(pts)
    inside = (cells[:, 0] >= 0) & (cells[:, 0] < rows) & (cells[:, 1] >= 0) & (cells[:, 1] < cols)
    pts, cells = pts[inside], cells[inside]
    keep = (
        free[cells[:, 0], cells[:, 1]]
        & (dist[cells[:, 0], cells[:, 1]] >= clearance_m)
        & ~outside[cells[:, 0], cells[:, 1]]
    )
    pts = pts[keep]
    if pts.shape[0] == 0:
        raise ConfigError(
            f"scan database: no free position {clearance_m} m from the walls on a {step_m} m lattice; "
            "expected a smaller grid_step_m or clearance_m"
        )
    angles = np.arange(n_dir, dtype=np.float64) * math.radians(heading_step_deg)
    poses = np.column_stack([pts, np.zeros(pts.shape[0])])
    r = cast_rays(occ, res, (ox, oy), poses, angles, max_range_m, method="dda")
    r = np.minimum(r, max_range_m)
    logger.debug("scan database: %d positions x %d headings (%d rays)", pts.shape[0], n_dir, r.size)
    return ScanDatabase(
        positions=pts, ranges=r, step_m=float(step_m), heading_step_deg=float(heading_step_deg), max_range_m=max_range_m
    )


def scan_bearing_ranges(scan: LaserScan) -> tuple[IntArray, FloatArray]:
    """The scan's ranges at the eight database bearings it covers.

    Returns
    -------
    bearing_index : ndarray of int64, shape (k,)
        Which of the bearings 0, 45, ..., 315 deg (robot frame) are covered (0..7).
    ranges : ndarray, shape (k,)
        The range of the beam closest to each, m (inf = no return).
    """
    idx, beams = _bearing_beams(
        int(scan.ranges.shape[0]), float(scan.angle_min), float(scan.angle_increment), float(scan.sensor_pose[2])
    )
    return idx, scan.ranges[beams].astype(np.float64)


@functools.lru_cache(maxsize=64)
def _bearing_beams(n: int, angle_min: float, angle_increment: float, heading: float) -> tuple[IntArray, IntArray]:
    """The covered bearings and the beam nearest each, for a scan geometry (a recording has one or two)."""
    if n == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    beam_robot = heading + (angle_min + angle_increment * np.arange(n, dtype=np.float64))  # robot frame
    target = np.arange(N_BEARINGS) * BEARING_STEP_RAD
    diff = np.abs(wrap_angle(beam_robot[None, :] - target[:, None]))  # (8, n)
    nearest = np.argmin(diff, axis=1)
    near = diff[np.arange(N_BEARINGS), nearest]
    half = 0.5 * abs(angle_increment) if n > 1 else 0.0
    ok = near <= half + 1e-9
    idx = np.flatnonzero(ok).astype(np.int64)
    beams = nearest[idx]
    idx.flags.writeable = False  # shared by every call with this geometry
    beams.flags.writeable = False
    return idx, beams


def match_scan(
    db: ScanDatabase,
    scan: LaserScan,
    tolerance_m: float,
    min_bearings: int = 4,
    prior: tuple[FloatArray, FloatArray] | None = None,
    gate: float = math.inf,
) -> tuple[ScanMatch | None, int]:
    """Match a scan against the database (module docstring).

    Parameters
    ----------
    db : ScanDatabase
    scan : LaserScan
    tolerance_m : float
        Largest mean absolute range difference of a match, m.
    min_bearings : int
        Fewest covered bearings for a match to be tried.
    prior : (mean (3,), cov (3, 3)) or None
        The filter's predicted belief; with ``gate`` it restricts the matches to a validation region.
    gate : float
        Largest squared Mahalanobis distance between a matched database pose and the prior mean under
        the prior covariance plus the database quantisation (a chi-square quantile with 3 dof); inf keeps
        every match (report 004's global matching).

    Returns
    -------
    match : ScanMatch or None
        None when fewer than ``min_bearings`` bearings are covered or no entry is within the tolerance.
    n_bearings : int
        Bearings used.
    """
    # long: report 004's matching steps (candidates, tolerance, prior gate, best match) share their arrays; numpydoc
    b_idx, r = scan_bearing_ranges(scan)
    k = int(b_idx.shape[0])
    if k < min_bearings:
        return None, k
    cap = min(float(scan.range_max), db.max_range_m)
    rc = np.minimum(np.where(np.isfinite(r), r, cap), cap)  # no return: beyond the cap
    m = db.n_headings // N_BEARINGS
    hs = db.heading_step_rad
    quant = db.quantisation
    gated = prior is not None and math.isfinite(gate)
    # gate first, then score only the entries inside the validation region (the database is tens of thousands
    # of entries, the region a few dozen)
    info = _NO_INFO
    if prior is not None and gated:
        info = np.asarray(np.linalg.inv(prior[1] + quant), dtype=np.float64)
    centre = np.asarray(prior[0], dtype=np.float64) if prior is not None and gated else _NO_CENTRE
    ii, hh, d = _matches(
        db.ranges,
        (b_idx * m).astype(np.int64),
        rc,
        float(tolerance_m),
        cap,
        db.positions,
        gated,
        centre,
        info,
        float(gate) if gated else 0.0,
        hs,
    )
    if ii.size == 0:
        return None, k
    # the pose measurement: triangular weights, their weighted mean pose and scatter (module docstring); the
    # sums over the matches are numpy's (np.sum and BLAS products), the elementwise steps compiled
    best, w, xy, th = _weights(ii, hh, d, db.positions, hs, float(tolerance_m))
    sw = np.sum(w)
    if not sw > 0:
        w = np.ones_like(d)
        sw = np.sum(w)
    w, dth = _normalised(w, sw, th, best)
    z = np.array([w @ xy[:, 0], w @ xy[:, 1], wrap_scalar(float(th[best] + w @ dth))])
    dev, wdev = _deviations(xy, th, w, z[0], z[1], z[2])
    cov = wdev.T @ dev + quant
    cov = 0.5 * (cov + cov.T)
    return ScanMatch(z=z, cov=cov, n_matches=int(ii.size), best_score_m=float(d[best]), n_bearings=k), k


# The ungated call's unused region (read by :func:`_matches` only when gated).
_NO_INFO = np.eye(3)
_NO_CENTRE = np.zeros(3)


@njit(cache=True)
def _weights(
    ii: IntArray, hh: IntArray, d: FloatArray, positions: FloatArray, hs: float, tol: float
) -> tuple[int, FloatArray, FloatArray, FloatArray]:
    """The matches' triangular weights and poses (module docstring).

    Parameters
    ----------
    ii, hh : ndarray of int64, shape (n,)
        The matched entries' positions and heading indices.
    d : ndarray, shape (n,)
        Their scores, m.
    positions : ndarray, shape (N, 2)
        The database's positions, m.
    hs : float
        The heading spacing, rad.
    tol : float
        The tolerance, m.

    Returns
    -------
    tuple
        (the index of the least score (the first of equal ones), the weights w = 1 - d / tol (ones when
        tol <= 0), the matched positions (n, 2) m, their headings h hs (n,) rad).
    """
    n = d.shape[0]
    best = 0
    for j in range(1, n):
        if d[j] < d[best]:
            best = j
    w = np.empty(n)
    xy = np.empty((n, 2))
    th = np.empty(n)
    for j in range(n):
        w[j] = 1.0 - d[j] / tol if tol > 0 else 1.0
        xy[j, 0] = positions[ii[j], 0]
        xy[j, 1] = positions[ii[j], 1]
        th[j] = float(hh[j]) * hs
    return best, w, xy, th


@njit(cache=True)
def _normalised(w: FloatArray, sw: float, th: FloatArray, best: int) -> tuple[FloatArray, FloatArray]:
    """The weights normalised by their sum ``sw`` and the headings ``th`` (rad) as wrapped differences from the
    best match's: (w / sw, wrap(th - th[best]))."""
    n = w.shape[0]
    wn = np.empty(n)
    dth = np.empty(n)
    for j in range(n):
        wn[j] = w[j] / sw
        dth[j] = _wrap(th[j] - th[best])
    return wn, dth


@njit(cache=True)
def _deviations(
    xy: FloatArray, th: FloatArray, w: FloatArray, z0: float, z1: float, z2: float
) -> tuple[FloatArray, FloatArray]:
    """The matches' deviations from the measured pose (z0 m, z1 m, z2 rad), dev = (x - z0, y - z1,
    wrap(th - z2)) (n, 3), and the weighted deviations w_j dev_j (n, 3), for the scatter sum_j w_j dev_j dev_j^T."""
    n = w.shape[0]
    dev = np.empty((n, 3))
    wdev = np.empty((n, 3))
    for j in range(n):
        dev[j, 0] = xy[j, 0] - z0
        dev[j, 1] = xy[j, 1] - z1
        dev[j, 2] = _wrap(th[j] - z2)
        wdev[j, 0] = dev[j, 0] * w[j]
        wdev[j, 1] = dev[j, 1] * w[j]
        wdev[j, 2] = dev[j, 2] * w[j]
    return dev, wdev
