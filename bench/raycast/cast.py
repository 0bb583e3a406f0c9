"""Ray casting on an occupancy grid, shared by the laser simulator and the grid-based filters.

Two methods, in numba kernels, behind one API (:func:`cast_rays`, :func:`cast_scan`):

``method="dda"``
    Exact grid traversal (Amanatides & Woo, "A Fast Voxel Traversal Algorithm for Ray Tracing",
    Eurographics 1987): visits every cell the beam crosses.
``method="march"``
    The same traversal, accelerated by ray marching on a distance field (the "ray marching" method of
    range_libc / CDDT, Walsh & Karaman, "CDDT: Fast Approximate 2D Ray Casting for Accelerated
    Localization", ICRA 2018). Each free cell stores its clearance, the smallest distance between any
    of its points and any occupied cell (:func:`march_field`: the Euclidean distance transform,
    ``scipy.ndimage.distance_transform_edt``, of the occupied cells dilated by one cell), rounded down
    to half cells in a uint8. Each step moves the beam by the clearance, or, when that does not leave
    the current cell, one cell on (a DDA step). Four beams step at once, in LLVM vector instructions
    (:func:`locbench.raycast._simd.step4`, a numba intrinsic), whose selects replace a scalar step's
    data-dependent branches: a pool of :data:`POOL_LANES` beams (:func:`_march_pool`) is swept over and
    over, a lane whose beam ends takes the next beam at once, and every lane's next cell is prefetched at
    each step, so that the lane's next visit, a sweep later, finds it in L1. A jump never enters an occupied cell
    and a hit reports the exact entry point of the cell (the later of its two slab entries), so, unlike
    range_libc's marcher (which stops within a tolerance of the wall), the ranges equal the exact
    traversal's up to rounding (about 1e-12 m); a beam crossing a cell for less than 1e-9 cells
    (through a corner point) may miss that cell. The field costs about 60 ns per cell (10 ms for
    400 x 400): :func:`cast_scan` caches it per grid object, :func:`cast_rays` builds it per call when
    there are enough rays. One-pose scans of :func:`cast_scan` march on :func:`march_sector_field`
    instead: per octant of beam directions, the larger of the clearance and an exact lower bound on the
    free distance along any direction of the octant (:mod:`locbench.raycast._sectors`), so that a beam
    running along a wall jumps along it (4.9 instead of 8.7 steps per ray on the benchmark map). Its
    eight planes (1.3 MB for 400 x 400 cells, built in about 0.2 s at the grid's first one-pose scan)
    stay in cache for a scan, whose beams sweep the octants in turn, but not for many poses at once,
    which march on the isotropic field (160 kB). Serial casts from many poses take only each beam's first
    jump on the planes: all beams of a pose start in one cell, whose eight octant values (the planes
    interleaved per cell, another 1.3 MB per grid) are gathered for all poses before marching, one cache
    line per pose. The ranges are the same, bit for bit, on either field. The lanes address cells with int32
    offsets: the march serves grids of fewer than :data:`MARCH_MAX_CELLS` cells, the octant planes grids of
    an eighth of that (larger ones scan on the isotropic field).

Why the kernels are shaped so, and what was measured and tried on the way (the pool, the scalar lane kernels
before it, lock-step refills, the octant planes): docs/history/performance.md, "The ray caster's measurement diary".

Grid conventions are those of :class:`locbench.core.grid.OccupancyGrid` (ROS map_server): row ``i``
spans y in [oy + i*res, oy + (i+1)*res), column ``j`` spans x likewise, and ``origin_xy`` = (ox, oy) is
the world position of the corner of cell (0, 0). Poses are world-frame sensor poses (x m, y m, theta
rad); beam angles are relative to the pose heading. A range is the distance from the sensor to the
point where the beam enters the first occupied cell; ``inf`` when no occupied cell is entered within
``max_range``. A beam starting inside an occupied cell has range 0. Space outside the grid is free.

Grids are treated as immutable (``OccupancyGrid`` is frozen): :func:`cast_scan` keys its cache on the
grid object, so an ``occupancy`` array changed in place after the first cast is not seen.

Threads: each kernel that casts many rays is written once, its rays (or pieces of them) the items of a ``prange``
loop, and compiled twice (:func:`_threads_build`): serial, and with numba's ``parallel=True``, which spreads
the items over numba's threads; the two builds give the same ranges, bit for bit. The threaded builds use numba's
threading layer; with the default ``workqueue`` layer they must not be called from several Python threads at once
(processes are fine). Pass ``parallel=False`` there.
"""

from __future__ import annotations

import logging
import math
import types
import weakref
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal, cast

import numba
import numpy as np
import numpy.typing as npt
from numba import njit, prange
from scipy.ndimage import binary_dilation, distance_transform_edt

from locbench.raycast import _simd as vec
from locbench.raycast._sectors import SAFETY_CELLS, sector_bounds

if TYPE_CHECKING:
    from locbench.core.grid import OccupancyGrid

logger = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
UInt8Array = npt.NDArray[np.uint8]
#: A grid the traversal reads: occupied cells have :data:`CELL_OCCUPIED` set (a boolean grid, or :func:`face_cells`).
GridArray = BoolArray | UInt8Array
IntArray = npt.NDArray[np.int64]
Method = Literal["auto", "march", "dda"]

#: Below this many rays a single thread is faster than waking the thread pool (measured on 2 cores).
PARALLEL_MIN_RAYS = 8192

#: Smallest jump, in cells, worth a ray-marching step; nearer to a wall the kernel takes DDA steps
#: (a jump costs a floor and a DDA re-start, about two DDA steps).
MARCH_MIN_CELLS = 1.0

#: ``cast_rays(method="auto")`` marches when rays >= cells * this ratio: building the distance field
#: (about 60 ns per cell) is then paid back by the faster traversal (about 0.2 us saved per ray).
AUTO_MARCH_RAYS_PER_CELL = 0.5

#: The march field stores clearances in whole units of this many cells (uint8, so that the field of a
#: 400 x 400 grid, 160 kB, stays in a core's L2 cache, where a float32 one, 640 kB, does not).
JUMP_UNIT_CELLS = 0.5

#: A DDA step moves this far (cells) past the cell's exit so that flooring the point gives the next
#: cell; a cell the beam crosses for less than this is skipped (the exact traversal would enter it).
_NUDGE_CELLS = 1e-9
_HUGE = 1e300

#: Field value of an occupied cell.
FIELD_OCCUPIED = 255

#: The pool kernel's lanes address cells with int32 offsets: the march serves grids below this many cells (a
#: larger grid's distance transform alone would take 17 GB), and the eight octant planes grids below an eighth
#: of it (larger grids scan on the isotropic field, with the same ranges).
MARCH_MAX_CELLS = 2**31


@njit(cache=True, inline="always")
def _clip_to_grid(rows: int, cols: int, gx: float, gy: float, dx: float, dy: float) -> tuple[float, float]:
    """Ray parameters (t_in, t_out) where the ray is inside [0, cols] x [0, rows], cells (slab test)."""
    if 0.0 <= gx < cols and 0.0 <= gy < rows:
        return 0.0, math.inf  # starts inside (the common case); the traversal notices the exit itself
    t0 = 0.0
    t1 = math.inf
    if dx != 0.0:
        a = -gx / dx
        b = (cols - gx) / dx
        t0 = max(t0, min(a, b))
        t1 = min(t1, max(a, b))
    elif gx < 0.0 or gx >= cols:
        return math.inf, -math.inf
    if dy != 0.0:
        a = -gy / dy
        b = (rows - gy) / dy
        t0 = max(t0, min(a, b))
        t1 = min(t1, max(a, b))
    elif gy < 0.0 or gy >= rows:
        return math.inf, -math.inf
    return t0, t1


@njit(cache=True, inline="always")
def _dda_start(
    rows: int, cols: int, gx: float, gy: float, dx: float, dy: float, t0: float
) -> tuple[int, int, int, int, float, float, float, float]:
    """The traversal's state where the ray enters the grid at ``t0``: the cell (i, j), the steps (step_i,
    step_j), the ray parameters of the next vertical and horizontal grid lines and their spacings."""
    ex = gx + t0 * dx
    ey = gy + t0 * dy
    j = min(max(math.floor(ex), 0), cols - 1)
    i = min(max(math.floor(ey), 0), rows - 1)
    step_j, t_next_x, t_delta_x = _axis_start(ex, j, dx, t0)
    step_i, t_next_y, t_delta_y = _axis_start(ey, i, dy, t0)
    return i, j, step_i, step_j, t_next_x, t_next_y, t_delta_x, t_delta_y


@njit(cache=True, inline="always")
def _axis_start(e: float, k: int, d: float, t0: float) -> tuple[int, float, float]:
    """Along one grid axis, from the entry coordinate ``e`` (cells) in cell ``k`` with the direction component
    ``d``: the step (+1, -1 or 0), the ray parameter of the next grid line and the spacing of the lines."""
    if d > 0.0:
        return 1, t0 + (k + 1.0 - e) / d, 1.0 / d
    if d < 0.0:
        return -1, t0 + (k - e) / d, -1.0 / d
    return 0, math.inf, math.inf


#: Bits of :func:`face_cells`: the cell is occupied; an occupied (or off-grid) cell lies within two cells.
CELL_OCCUPIED = 1
CELL_NEAR_OCCUPIED = 2


def face_cells(occupied: npt.ArrayLike) -> UInt8Array:
    """The grid coded for :func:`dda_face`.

    Parameters
    ----------
    occupied : array-like of bool, shape (rows, cols)
        The occupancy grid.

    Returns
    -------
    ndarray of uint8, shape (rows, cols)
        :data:`CELL_OCCUPIED` where ``occupied`` is, plus :data:`CELL_NEAR_OCCUPIED` where an occupied or
        off-grid cell is within two cells (Chebyshev distance): the cells out of which a crossing's grid
        vertices may touch an occupied cell.
    """
    occ = np.asarray(occupied, dtype=np.bool_)
    rows, cols = occ.shape
    pad = np.ones((rows + 4, cols + 4), dtype=np.bool_)
    pad[2:-2, 2:-2] = occ
    band = np.zeros_like(occ)
    for di in range(5):
        for dj in range(5):
            band |= pad[di : di + rows, dj : dj + cols]
    out: UInt8Array = occ.astype(np.uint8) * CELL_OCCUPIED | band.astype(np.uint8) * CELL_NEAR_OCCUPIED
    return out


@njit(cache=True, inline="always")
def _corner_occupied(cells: GridArray, vi: int, vj: int) -> bool:
    """Whether a cell touching grid vertex (row vi, column vj) is occupied or lies off the grid (``cells``
    from :func:`face_cells`)."""
    rows = cells.shape[0]
    cols = cells.shape[1]
    for i in (vi - 1, vi):
        for j in (vj - 1, vj):
            if i < 0 or j < 0 or i >= rows or j >= cols or cells[i, j] & CELL_OCCUPIED:
                return True
    return False


@njit(cache=True, inline="always")
def _crossing_near(cells: GridArray, c: float, across: float, lim: float, line: int, vertical: bool) -> bool:
    """At the ray's crossing of grid line ``line`` (vertical: x = line, at y = ``c``; else y = line, at x =
    ``c``): whether one of the two vertices of that line beside the crossing touches an occupied cell and
    lies within ``lim`` of the ray (``across``: |direction component| normal to the line)."""
    v = math.floor(c)
    if (c - v) * across < lim and (_corner_occupied(cells, v, line) if vertical else _corner_occupied(cells, line, v)):
        return True
    w = v + 1
    return (w - c) * across < lim and (
        _corner_occupied(cells, w, line) if vertical else _corner_occupied(cells, line, w)
    )


@njit(cache=True, inline="always")
def _vertex_near(cells: GridArray, px: float, py: float, lim: float) -> bool:
    """Whether the grid vertex nearest to (px, py) (grid units) is within ``lim`` and touches an occupied cell."""
    vj = math.floor(px + 0.5)
    vi = math.floor(py + 0.5)
    return math.hypot(px - vj, py - vi) < lim and _corner_occupied(cells, vi, vj)


@njit(cache=True, inline="always")
def _traverse(
    cells: GridArray,
    gx: float,
    gy: float,
    dx: float,
    dy: float,
    t_lim: float,
    near0: float,
    near1: float,
    faces: bool,
) -> tuple[float, int, bool]:
    """The exact traversal of one beam (Amanatides & Woo 1987): the distance to the first occupied cell it enters.

    ``(gx, gy)`` is the start in grid units (one cell = 1), ``(dx, dy)`` the unit direction; a cell is occupied
    where ``cells[i, j] & CELL_OCCUPIED`` (a boolean grid, or one coded by :func:`face_cells`). Returns (t, axis,
    near): t in cells, inf when no occupied cell is entered within ``t_lim``. With ``faces`` (the grid coded by
    :func:`face_cells`), ``axis`` is 0 when the ray enters the hit cell across a vertical grid line (x = const),
    1 across a horizontal one, -1 when it starts in it (or nothing is hit); ``near`` is True when a grid vertex
    that touches an occupied (or off-grid) cell lies within ``near0 + near1 * t`` cells of the ray before the
    hit, or within three times that of its start or of the hit point: there the range may not be a smooth
    function of the ray (a perturbed ray may hit another cell or face). Without ``faces`` (a constant at each
    call, so the compiler drops that bookkeeping) ``axis`` and ``near`` carry nothing.
    """
    rows = cells.shape[0]
    cols = cells.shape[1]
    t0, t1 = _clip_to_grid(rows, cols, gx, gy, dx, dy)
    if t0 >= t1 or t0 > t_lim:
        return math.inf, -1, True
    i, j, step_i, step_j, t_next_x, t_next_y, t_delta_x, t_delta_y = _dda_start(rows, cols, gx, gy, dx, dy, t0)
    near = True
    if faces:
        near = t0 > 0.0 or _vertex_near(cells, gx, gy, 3.0 * near0)
    adx = abs(dx)
    ady = abs(dy)
    t = t0
    axis = -1
    cell = cells[i, j]
    while not cell & CELL_OCCUPIED:
        # A crossing's vertices touch only cells within two of the cell it leaves (one for the crossing's
        # rounding): away from the occupied cells the checks cannot find a corner, so they are not made.
        check = faces and not near and cell & CELL_NEAR_OCCUPIED
        if t_next_x < t_next_y:
            t = t_next_x
            t_next_x += t_delta_x
            line = j + 1 if step_j > 0 else j
            j += step_j
            axis = 0
            if j < 0 or j >= cols:
                return math.inf, -1, True
            if check:
                near = _crossing_near(cells, gy + t * dy, adx, near0 + near1 * t, line, True)
        else:
            t = t_next_y
            t_next_y += t_delta_y
            line = i + 1 if step_i > 0 else i
            i += step_i
            axis = 1
            if i < 0 or i >= rows:
                return math.inf, -1, True
            if check:
                near = _crossing_near(cells, gx + t * dx, ady, near0 + near1 * t, line, False)
        if t > t_lim:
            return math.inf, -1, True
        cell = cells[i, j]
    if faces:
        near = near or axis < 0 or _vertex_near(cells, gx + t * dx, gy + t * dy, 3.0 * (near0 + near1 * t))
    return t, axis, near


@njit(cache=True, inline="always")
def _dda_one(occ: BoolArray, gx: float, gy: float, dx: float, dy: float, t_lim: float) -> float:
    """Distance along one beam to the first occupied cell of the boolean grid ``occ``, in cells (inf if none
    within ``t_lim``): :func:`_traverse` without the faces."""
    return _traverse(occ, gx, gy, dx, dy, t_lim, 0.0, 0.0, False)[0]


@njit(cache=True)
def dda_face(
    cells: UInt8Array, gx: float, gy: float, dx: float, dy: float, t_lim: float, near0: float, near1: float
) -> tuple[float, int, bool]:
    """The traversal of one beam on the grid coded by :func:`face_cells`, with the face it enters the hit cell
    through and whether it passes near a corner of the occupied cells: (t, axis, near) of :func:`_traverse`."""
    return _traverse(cells, gx, gy, dx, dy, t_lim, near0, near1, True)


@njit(cache=True, inline="always")
def _beam_direction(cp: float, sp: float, cb: float, sb: float) -> tuple[float, float]:
    """Unit direction (cos, sin) of a beam at angle ``b`` from a heading ``h``, from cos and sin of each (``cp``,
    ``sp``; ``cb``, ``sb``) by the angle-sum formulas: no trigonometry per ray."""
    return cp * cb - sp * sb, sp * cb + cp * sb


#: Rays per ``prange`` item of the march: a pool (:func:`_march_pool`) idles while its last beams end.
_CHUNK = 2048

#: Rays per ``prange`` item of the exact traversal: few, so that the items split evenly over the threads (numba
#: gives each thread an equal run of items); within an item, pose and beam counters spare a division per ray.
_DDA_CHUNK = 64

#: ``chunk`` of :func:`_march_rays` for all rays in one piece (more rays than any cast).
_ONE_PIECE = 1 << 62


def _threads_build(kernel: Callable[..., Any], **options: Any) -> tuple[Any, Any]:
    """``kernel`` compiled by numba twice: as written, where its ``prange`` loop runs in order on the calling
    thread, and with ``parallel=True``, where the loop's items spread over numba's threads.

    One kernel, two builds. numba keys its on-disk cache on a function's qualified name and code, not on the
    compile options, so the two builds of one function would take each other's cache entries: the threaded
    build compiles a copy of the function named ``<name>_threads``.
    """
    twin = types.FunctionType(
        kernel.__code__, kernel.__globals__, f"{kernel.__name__}_threads", kernel.__defaults__, kernel.__closure__
    )
    twin.__qualname__ = f"{kernel.__qualname__}_threads"
    twin.__doc__ = kernel.__doc__
    return njit(cache=True, **options)(kernel), njit(cache=True, parallel=True, **options)(twin)


def _dda_rays(
    occ: BoolArray, res: float, ox: float, oy: float, poses: FloatArray, angles: FloatArray, max_range: float
) -> FloatArray:  # pragma: no cover - compiled
    """Ranges (N, B), m, of the exact traversal (:func:`_dda_one`) of every beam ``angles`` (B,) from every sensor
    pose ``poses`` (N, 3): the rays pose-major in items of :data:`_DDA_CHUNK`, the ``prange`` loop (so that one
    pose with many beams also spreads over the threads)."""
    n = poses.shape[0]
    nb = angles.shape[0]
    total = n * nb
    out = np.empty(total)
    inv_res = 1.0 / res
    t_lim = max_range * inv_res
    cb = np.cos(angles)
    sb = np.sin(angles)
    cp = np.cos(poses[:, 2])
    sp = np.sin(poses[:, 2])
    for c in prange((total + _DDA_CHUNK - 1) // _DDA_CHUNK):
        first = c * _DDA_CHUNK
        p = first // nb
        b = first - p * nb
        for k in range(first, min(first + _DDA_CHUNK, total)):
            dx, dy = _beam_direction(cp[p], sp[p], cb[b], sb[b])
            out[k] = _dda_one(occ, (poses[p, 0] - ox) * inv_res, (poses[p, 1] - oy) * inv_res, dx, dy, t_lim) * res
            b += 1
            if b == nb:
                p += 1
                b = 0
    return out.reshape((n, nb))


_dda_serial, _dda_threads = _threads_build(_dda_rays)


#: Lanes of the pool kernel (:func:`_march_pool`), a multiple of 4: each sweep steps them all, four at a time.
POOL_LANES = 32

#: The lowest set bit's index of each 4-bit mask (0 for 0).
_LOWEST_BIT = np.array([0, 0, 1, 0, 2, 0, 1, 0, 3, 0, 1, 0, 2, 0, 1, 0], dtype=np.int64)


@njit(cache=True, inline="always")
def _pool_take(
    fstate: FloatArray,
    istate: npt.NDArray[np.int32],
    k: int,
    gx: float,
    gy: float,
    dx: float,
    dy: float,
    first: IntArray,
    plane_size: int,
    t_lim: float,
    t_end: float,
    rows: int,
    cols: int,
) -> None:
    """Set lane ``k`` of the pool up for a beam from (gx, gy), in cells, along the unit direction (dx, dy).

    ``first`` holds the start cell's value per octant for a shared first jump (all 0 for none, and for a pose
    outside the grid or in an occupied cell; see :func:`_march_pool`). A beam from outside the grid starts where
    it enters it (slab clip). A beam that ends at once (it misses the grid, enters it past ``t_lim``, or its first
    jump leaves the grid or passes ``t_end``) becomes an idle lane, which its first step ends with range inf: no
    branch on it here.
    """
    neg_x = dx < 0.0
    neg_y = dy < 0.0
    # the octant of the direction: exact signs and |dy| > |dx| (the octant planes' convention)
    octant = (neg_x * 2 + neg_y) * 2 + (abs(dy) > abs(dx))
    t0, t1 = _clip_to_grid(rows, cols, gx, gy, dx, dy)  # (0, inf) from inside the grid
    missed = (t0 >= t1) | (t0 > t_lim)
    v0 = first[octant]
    # a first jump of 3 units (1.5 cells) or more always leaves the start cell: it is the step that the march
    # would take from t = 0
    jump = v0 >= 3
    t = v0 * JUMP_UNIT_CELLS if jump else (0.0 if missed else t0)
    j = math.floor(gx + t * dx)
    i = math.floor(gy + t * dy)
    if not jump:
        # a beam from outside starts where it enters the grid: in the cell on the grid's edge
        j = min(max(j, 0), cols - 1)
        i = min(max(i, 0), rows - 1)
    gone = missed | (t > t_end) | (j < 0) | (j >= cols) | (i < 0) | (i >= rows)
    ex_x = 0.0 if neg_x else 1.0
    ex_y = 0.0 if neg_y else 1.0
    fstate[vec.T, k] = math.inf if gone else t
    fstate[vec.T0, k] = t0
    fstate[vec.GX, k] = gx
    fstate[vec.GY, k] = gy
    fstate[vec.DX, k] = dx
    fstate[vec.DY, k] = dy
    fstate[vec.IX, k] = 1.0 / dx if dx != 0.0 else _HUGE
    fstate[vec.IY, k] = 1.0 / dy if dy != 0.0 else _HUGE
    fstate[vec.AX, k] = ex_x - gx
    fstate[vec.AY, k] = ex_y - gy
    fstate[vec.BX, k] = 1.0 - ex_x - gx
    fstate[vec.BY, k] = 1.0 - ex_y - gy
    istate[vec.CI, k] = 0 if gone else i
    istate[vec.CJ, k] = 0 if gone else j
    istate[vec.CB, k] = 0 if gone else octant * plane_size


@njit(cache=True, error_model="numpy")
def _march_pool(
    field: UInt8Array,
    planes: UInt8Array,
    plane_size: int,
    starts: UInt8Array,
    res: float,
    ox: float,
    oy: float,
    poses: FloatArray,
    cp: FloatArray,
    sp: FloatArray,
    cb: FloatArray,
    sb: FloatArray,
    t_lim: float,
    start: int,
    stop: int,
    out: FloatArray,
) -> None:
    """Ranges (m) of the flattened rays ``start .. stop - 1`` (pose-major) of ``poses`` into ``out``.

    ``field`` gives the grid's shape and occupancy. The beams march on ``planes``: the isotropic field
    flattened (``plane_size`` 0), or the eight octant planes of :func:`march_sector_field` flattened
    (``plane_size`` rows * cols), where each beam reads its octant's plane. With ``starts`` (rows * cols * 8,
    uint8: the octant planes interleaved per cell, so that a pose's eight values share one cache line) every
    beam from a free cell jumps first by its start cell's value for its octant, gathered per pose before
    marching so that the poses' cache misses overlap; an empty ``starts`` gives no shared first jump.

    Each step moves a beam by the value of its cell, or one cell on (a DDA step) when that jump would not leave
    the cell; a hit reports the cell's exact entry point. Four lanes step at once (the vector step
    :func:`locbench.raycast._simd.step4`): a pool of :data:`POOL_LANES` beams is swept over and over, and a lane
    whose beam has ended takes the next beam at once. The step's selects replace the unpredictable branches of a
    scalar step; what is left of branching is one per ended beam.
    """
    # long: a compiled kernel: the work-pool march's state (queue, plane cursors, hit flags) must stay in one frame
    rows = field.shape[0]
    cols = field.shape[1]
    flat = field.reshape(-1)
    inv_res = 1.0 / res
    nb = cb.shape[0]
    t_end = t_lim + _NUDGE_CELLS
    p0 = start // nb
    p1 = (stop - 1) // nb + 1 if stop > start else p0
    gxy = np.empty((p1 - p0, 2))
    first = np.zeros((p1 - p0, 8), dtype=np.int64)
    for p in range(p0, p1):
        gx = (poses[p, 0] - ox) * inv_res
        gy = (poses[p, 1] - oy) * inv_res
        gxy[p - p0, 0] = gx
        gxy[p - p0, 1] = gy
        if starts.shape[0] > 0 and 0.0 <= gx < cols and 0.0 <= gy < rows:
            c0 = math.floor(gy) * cols + math.floor(gx)
            if flat[c0] != FIELD_OCCUPIED:
                for o in range(8):
                    first[p - p0, o] = starts[8 * c0 + o]
    fstate = np.zeros((vec.NF, POOL_LANES))
    istate = np.zeros((vec.NC, POOL_LANES), dtype=np.int32)
    # every lane starts idle: it ends at the first step and takes a beam then
    fstate[vec.T, :] = math.inf
    ray = np.full(POOL_LANES, -1, dtype=np.int64)
    nxt = start
    p = p0
    b = start - p0 * nb
    alive = 0
    while alive > 0 or nxt < stop:
        for q in range(0, POOL_LANES, 4):
            ended = vec.step4(
                fstate, istate, planes, q, cols, rows, t_end, t_lim, res, FIELD_OCCUPIED, JUMP_UNIT_CELLS, _NUDGE_CELLS
            )
            while ended:
                k = q + _LOWEST_BIT[ended]
                ended &= ended - 1
                r = ray[k]
                if r >= 0:
                    out[r] = fstate[vec.RES, k]
                    ray[k] = -1
                    alive -= 1
                    fstate[vec.T, k] = math.inf
                if nxt < stop:
                    if b == nb:
                        p += 1
                        b = 0
                    dx, dy = _beam_direction(cp[p], sp[p], cb[b], sb[b])
                    g = p - p0
                    _pool_take(
                        fstate, istate, k, gxy[g, 0], gxy[g, 1], dx, dy, first[g], plane_size, t_lim, t_end, rows, cols
                    )
                    ray[k] = nxt
                    nxt += 1
                    b += 1
                    alive += 1


@njit(cache=True, inline="always")
def _pose_trig(poses: FloatArray, angles: FloatArray, trig: FloatArray) -> tuple[FloatArray, FloatArray]:
    """cos and sin of each pose heading; refreshes the beams' (angle, cos, sin) cache ``trig`` (3, B) if stale."""
    # cos/sin of the beam angles cost about 20 ns per beam, as much as a tenth of a scan's traversal:
    # a scan's angles rarely change, so they are compared (1 ns per beam) and reused
    for b in range(angles.shape[0]):
        if trig[0, b] != angles[b]:
            trig[0, b] = angles[b]
            trig[1, b] = math.cos(angles[b])
            trig[2, b] = math.sin(angles[b])
    n = poses.shape[0]
    cp = np.empty(n)
    sp = np.empty(n)
    for p in range(n):
        cp[p] = math.cos(poses[p, 2])
        sp[p] = math.sin(poses[p, 2])
    return cp, sp


def _march_rays(
    field: UInt8Array,
    planes: UInt8Array,
    plane_size: int,
    starts: UInt8Array,
    res: float,
    ox: float,
    oy: float,
    poses: FloatArray,
    angles: FloatArray,
    max_range: float,
    trig: FloatArray,
    chunk: int,
) -> FloatArray:  # pragma: no cover - compiled
    """The march (:func:`_march_pool`, arguments as there) from ``poses`` (3,) or (N, 3), returning (N, B) m.

    ``trig`` (3, B) caches (angles, cos, sin) between calls and is refreshed here if stale. The rays, pose-major,
    are marched in pieces of ``chunk`` rays, the ``prange`` items (:data:`_ONE_PIECE`: one pool for all).
    """
    poses = poses.reshape((-1, 3))
    n = poses.shape[0]
    nb = angles.shape[0]
    total = n * nb
    out = np.empty(total)
    cp, sp = _pose_trig(poses, angles, trig)
    t_lim = max_range / res
    for c in prange((total + chunk - 1) // chunk):
        first = c * chunk
        last = min(first + chunk, total)
        _march_pool(field, planes, plane_size, starts, res, ox, oy, poses, cp, sp, trig[1], trig[2], t_lim, first, last,
                    out)  # fmt: skip
    return out.reshape((n, nb))


_march_serial, _march_threads = _threads_build(_march_rays, error_model="numpy")


#: Per number of beams, the (angles, cos, sin) rows that serial marches reuse (NaN: not yet set).
_TRIG_CACHE: dict[int, FloatArray] = {}


def _trig_rows(nb: int) -> FloatArray:
    trig = _TRIG_CACHE.get(nb)
    if trig is None:
        trig = np.full((3, nb), np.nan)
        _TRIG_CACHE[nb] = trig
    return trig


def march_field(occupied: npt.ArrayLike) -> UInt8Array:
    """The clearance field that ``method="march"`` jumps on, shape (rows, cols), uint8.

    :data:`FIELD_OCCUPIED` on occupied cells. On a free cell, its clearance (the smallest distance
    between any point of the cell and any point of an occupied cell) in whole units of
    :data:`JUMP_UNIT_CELLS`, rounded down and capped at ``FIELD_OCCUPIED - 1``; 0 where the clearance is
    below :data:`MARCH_MIN_CELLS` (the kernel takes DDA steps there). Two unit cells
    whose centres are (di, dj) cells apart are ``hypot(max(|di| - 1, 0), max(|dj| - 1, 0))`` apart,
    which is the centre distance to the nearest of the 3 x 3 cells around the occupied one: the
    clearance is the Euclidean distance transform of the occupied cells dilated by one cell.
    """
    occ = np.ascontiguousarray(occupied, dtype=np.bool_)
    if occ.size >= MARCH_MAX_CELLS:
        raise ValueError(
            f"the march serves grids of fewer than {MARCH_MAX_CELLS} cells, got {occ.shape[0]} x {occ.shape[1]}: "
            "use method='dda'"
        )
    if not occ.any():
        return np.full(occ.shape, FIELD_OCCUPIED - 1, dtype=np.uint8)
    near = binary_dilation(occ, structure=np.ones((3, 3), dtype=bool))
    clearance = distance_transform_edt(~near)
    # Whole jump units, rounded down so a jump never exceeds the clearance; capped below the marker.
    units = np.minimum(np.floor(clearance / JUMP_UNIT_CELLS), FIELD_OCCUPIED - 1)
    units[clearance < MARCH_MIN_CELLS] = 0
    field = units.astype(np.uint8)
    field[occ] = FIELD_OCCUPIED
    return np.ascontiguousarray(field)


def march_sector_field(occupied: npt.ArrayLike, field: UInt8Array | None = None) -> UInt8Array:
    """Per-octant march field, shape (8, rows, cols), uint8, for beams cast from one pose.

    Plane ``((dx < 0) * 2 + (dy < 0)) * 2 + (|dy| > |dx|)`` serves the beams whose direction (dx, dy) lies in
    that octant: on a free cell it holds the larger of the cell's clearance (:func:`march_field`, passed as
    ``field`` if already built) and a lower bound on how far any such beam can travel from any point of the
    cell before it enters an occupied cell (:func:`locbench.raycast._sectors.sector_bounds`), in whole units
    of :data:`JUMP_UNIT_CELLS` rounded down and capped below :data:`FIELD_OCCUPIED`; :data:`FIELD_OCCUPIED`
    on occupied cells. A beam along a wall has a clearance of a cell or two but an octant bound of up to the
    wall's length: the march takes 4.9 instead of 8.7 steps per ray on the benchmark map's scans.
    """
    occ = np.ascontiguousarray(occupied, dtype=np.bool_)
    iso = march_field(occ) if field is None else field
    if not occ.any():
        return np.ascontiguousarray(np.broadcast_to(iso, (8, *iso.shape)))
    cap_cells = (FIELD_OCCUPIED - 1) * JUMP_UNIT_CELLS + 1.0
    bounds = sector_bounds(occ, 1, cap_cells)
    units = np.minimum(np.floor((bounds - SAFETY_CELLS) / JUMP_UNIT_CELLS), FIELD_OCCUPIED - 1)
    planes = np.maximum(units, iso[None].astype(np.float64)).astype(np.uint8)
    planes[:, occ] = FIELD_OCCUPIED
    return np.ascontiguousarray(planes)


def _check_inputs(
    occupied: npt.ArrayLike, resolution: float, poses: npt.ArrayLike, angles: npt.ArrayLike, max_range: float
) -> tuple[BoolArray, FloatArray, FloatArray]:
    occ = np.ascontiguousarray(occupied, dtype=np.bool_)
    if occ.ndim != 2 or occ.shape[0] == 0 or occ.shape[1] == 0:
        raise ValueError(f"occupied must be a non-empty 2-D array (rows, cols), got shape {occ.shape}")
    p, a = _check_rays(resolution, poses, angles, max_range)
    return occ, p, a


def _check_rays(
    resolution: float, poses: npt.ArrayLike, angles: npt.ArrayLike, max_range: float
) -> tuple[FloatArray, FloatArray]:
    if not (resolution > 0.0 and math.isfinite(resolution)):
        raise ValueError(f"resolution must be a positive number of metres, got {resolution!r}")
    if not (max_range >= 0.0 and math.isfinite(max_range)):
        raise ValueError(f"max_range must be a finite number of metres >= 0, got {max_range!r}")
    p = np.ascontiguousarray(poses, dtype=np.float64)
    if p.ndim == 1:
        p = p.reshape(1, -1)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"poses must have shape (N, 3) as (x m, y m, theta rad), got {np.shape(poses)}")
    a = np.ascontiguousarray(angles, dtype=np.float64).reshape(-1)
    return p, a


def _check_method(method: str) -> None:
    if method not in ("auto", "march", "dda"):
        raise ValueError(f"method must be 'auto', 'march' or 'dda', got {method!r}")


def _use_threads(parallel: bool | None, n_rays: int) -> bool:
    if parallel is None:
        return n_rays >= PARALLEL_MIN_RAYS and numba.get_num_threads() > 1
    return parallel


def cast_rays(
    occupied: npt.ArrayLike,
    resolution: float,
    origin_xy: tuple[float, float],
    poses: npt.ArrayLike,
    angles: npt.ArrayLike,
    max_range: float,
    *,
    parallel: bool | None = None,
    method: Method = "auto",
) -> FloatArray:
    """Cast ``B`` beams from each of ``N`` sensor poses through an occupancy grid.

    Parameters
    ----------
    occupied : array-like of bool, shape (rows, cols)
        True where a cell is occupied; row ``i`` is y, column ``j`` is x (ROS map_server conventions).
    resolution : float
        Cell side, m.
    origin_xy : tuple of float
        World (x, y) of the corner of cell (0, 0), m.
    poses : array-like, shape (N, 3) or (3,)
        World-frame sensor poses (x m, y m, theta rad).
    angles : array-like, shape (B,)
        Beam angles relative to the pose heading, rad.
    max_range : float
        Beams that hit nothing within this distance return ``inf``, m.
    parallel : bool or None
        Spread the rays over numba's threads; ``None`` decides by the number of rays.
    method : {"auto", "march", "dda"}
        ``"dda"`` is the exact traversal, ``"march"`` the same ranges (to rounding) with distance-field
        jumps, whose field is built in this call (about 60 ns per cell); ``"auto"`` marches when there
        are at least :data:`AUTO_MARCH_RAYS_PER_CELL` rays per cell. For repeated casts in one map use
        :func:`cast_scan`, which keeps the field.

    Returns
    -------
    ndarray, shape (N, B)
        Range to the entry point of the first occupied cell, m; 0 for a beam starting in an occupied
        cell; ``inf`` where nothing is hit within ``max_range``.
    """
    _check_method(method)
    occ, p, a = _check_inputs(occupied, resolution, poses, angles, max_range)
    n_rays = p.shape[0] * a.shape[0]
    if method == "auto":
        method = "march" if AUTO_MARCH_RAYS_PER_CELL * occ.size <= n_rays and occ.size < MARCH_MAX_CELLS else "dda"
    grid_array = march_field(occ) if method == "march" else occ
    return _run(grid_array, method, float(resolution), origin_xy, p, a, float(max_range), parallel)


def _run(
    grid_array: BoolArray | UInt8Array,
    method: str,
    resolution: float,
    origin_xy: tuple[float, float],
    p: FloatArray,
    a: FloatArray,
    max_range: float,
    parallel: bool | None,
) -> FloatArray:
    threads = _use_threads(parallel, p.shape[0] * a.shape[0])
    ox = float(origin_xy[0])
    oy = float(origin_xy[1])
    if method == "march":
        field = cast("UInt8Array", grid_array)
        flat = field.reshape(-1)
        if threads:
            # a trig cache of its own: the shared one is for serial casts
            trig = np.full((3, a.shape[0]), np.nan)
            return _march_threads(field, flat, 0, _NO_STARTS, resolution, ox, oy, p, a, max_range, trig, _CHUNK)
        trig = _trig_rows(a.shape[0])
        return _march_serial(field, flat, 0, _NO_STARTS, resolution, ox, oy, p, a, max_range, trig, _ONE_PIECE)
    dda = _dda_threads if threads else _dda_serial
    out: FloatArray = dda(cast("BoolArray", grid_array), resolution, ox, oy, p, a, max_range)
    return out


@dataclass(frozen=True)
class _GridArrays:
    occupied: BoolArray
    field: UInt8Array
    resolution: float
    ox: float
    oy: float


def _plain_vector(x: npt.NDArray[np.generic], size: int = -1) -> bool:
    """Whether ``x`` is a contiguous 1-D float64 array (of ``size`` elements if given)."""
    return x.ndim == 1 and x.dtype == np.float64 and x.flags.c_contiguous and (size < 0 or x.shape[0] == size)


#: Occupancy mask and distance field per grid object, dropped with the grid.
_GRID_CACHE: weakref.WeakKeyDictionary[OccupancyGrid, _GridArrays] = weakref.WeakKeyDictionary()

#: The octant planes (:func:`march_sector_field`, flattened) per grid object, built at the grid's first
#: one-pose cast (about 0.2 s for 400 x 400 cells).
_SECTOR_CACHE: weakref.WeakKeyDictionary[OccupancyGrid, UInt8Array] = weakref.WeakKeyDictionary()


def _sector_planes(grid: OccupancyGrid, arrays: _GridArrays) -> UInt8Array:
    planes = _SECTOR_CACHE.get(grid)
    if planes is None:
        planes = march_sector_field(arrays.occupied, arrays.field).reshape(-1)
        _SECTOR_CACHE[grid] = planes
        logger.debug("ray caster: octant planes built for a %d x %d grid", *arrays.occupied.shape)
    return planes


#: ``starts`` of :func:`_march_pool` for no shared first jump.
_NO_STARTS = np.zeros(0, dtype=np.uint8)

#: The octant planes interleaved per cell (rows * cols * 8) per grid object, for casts from many poses.
_START_CACHE: weakref.WeakKeyDictionary[OccupancyGrid, UInt8Array] = weakref.WeakKeyDictionary()


def _start_octants(grid: OccupancyGrid, arrays: _GridArrays) -> UInt8Array:
    starts = _START_CACHE.get(grid)
    if starts is None:
        starts = np.ascontiguousarray(_sector_planes(grid, arrays).reshape(8, -1).T).reshape(-1)
        _START_CACHE[grid] = starts
    return starts


#: Per grid object, the leading arguments of :func:`_march_serial` for one-pose scans (field, octant planes,
#: plane size, no first jump, resolution, ox, oy), so that :func:`cast_scan`'s fast path finds them in one lookup.
_SCAN_CACHE: weakref.WeakKeyDictionary[
    OccupancyGrid, tuple[UInt8Array, UInt8Array, int, UInt8Array, float, float, float]
] = weakref.WeakKeyDictionary()


def _march_one_pose(
    grid: OccupancyGrid, arrays: _GridArrays, pose: FloatArray, angles: FloatArray, max_range: float
) -> FloatArray:
    """One pose's ranges (B,), serial, on the octant planes: its beams sweep the planes in turn, so the planes
    in use stay in cache, while the many headings of many poses would spread every call over all eight (1.3 MB
    for 400 x 400 cells, more than a core's L2) and those are faster on the isotropic field (160 kB)."""
    scan = _SCAN_CACHE.get(grid)
    if scan is None:
        field = arrays.field
        if 8 * field.size < MARCH_MAX_CELLS:
            scan = (
                field,
                _sector_planes(grid, arrays),
                field.size,
                _NO_STARTS,
                arrays.resolution,
                arrays.ox,
                arrays.oy,
            )
        else:
            scan = (field, field.reshape(-1), 0, _NO_STARTS, arrays.resolution, arrays.ox, arrays.oy)
        _SCAN_CACHE[grid] = scan
    return _march_serial(*scan, pose, angles, max_range, _trig_rows(angles.shape[0]), _ONE_PIECE)[0]


def _grid_arrays(grid: OccupancyGrid) -> _GridArrays:
    arrays = _GRID_CACHE.get(grid)
    if arrays is None:
        occ = np.ascontiguousarray(grid.occupied(), dtype=np.bool_)
        if occ.ndim != 2 or occ.shape[0] == 0 or occ.shape[1] == 0:
            raise ValueError(f"grid.occupancy must be a non-empty 2-D array (rows, cols), got shape {occ.shape}")
        if not (grid.resolution > 0.0 and math.isfinite(grid.resolution)):
            raise ValueError(f"grid.resolution must be a positive number of metres, got {grid.resolution!r}")
        if grid.origin[2] != 0.0:
            raise ValueError(f"grid.origin theta must be 0 (rotated grids are not supported), got {grid.origin[2]}")
        arrays = _GridArrays(
            occupied=occ,
            field=march_field(occ),
            resolution=float(grid.resolution),
            ox=float(grid.origin[0]),
            oy=float(grid.origin[1]),
        )
        _GRID_CACHE[grid] = arrays
        logger.debug("ray caster: distance field built for a %d x %d grid", occ.shape[0], occ.shape[1])
    return arrays


def cast_scan(
    grid: OccupancyGrid,
    pose: npt.ArrayLike,
    angles: npt.ArrayLike,
    max_range: float,
    *,
    parallel: bool | None = None,
    method: Method = "auto",
) -> FloatArray:
    """Ranges of one scan (or several) cast in an :class:`OccupancyGrid`.

    The grid's occupancy mask and distance field are built on the first call and kept while the grid
    object lives, so repeated scans in one map (a filter's expected scans) pay only the traversal.

    Parameters
    ----------
    grid : OccupancyGrid
        The map; cells above ``grid.occupied_thresh`` block beams (unknown cells, -1, do not).
    pose : array-like, shape (3,) or (N, 3)
        World-frame sensor pose(s) (x m, y m, theta rad).
    angles : array-like, shape (B,)
        Beam angles relative to the sensor heading, rad.
    max_range : float
        m; farther beams return ``inf``.
    parallel : bool or None
        As in :func:`cast_rays`.
    method : {"auto", "march", "dda"}
        ``"auto"`` (the default) is ``"march"``, whose fields are cached with the grid (a one-pose serial
        scan marches on :func:`march_sector_field`, several poses on :func:`march_field` after a first jump
        per beam on the former; same ranges).

    Returns
    -------
    ndarray, shape (B,) for one pose, (N, B) for several
        Ranges, m, as in :func:`cast_rays`.
    """
    # long: the public ray caster's argument checks, sensor geometry and choice of kernel, with numpydoc
    scan = _SCAN_CACHE.get(grid)
    if (
        scan is not None
        and (method == "auto" or method == "march")
        and type(pose) is np.ndarray
        and type(angles) is np.ndarray
        and _plain_vector(pose, 3)
        and _plain_vector(angles)
        and (parallel is False or (parallel is None and angles.shape[0] < PARALLEL_MIN_RAYS))
    ):
        # fast path for one scan of float64 vectors in a grid already scanned: the general checks and
        # conversions below cost about 5 us, 7 ns per beam of a 683-beam scan; this path about 2 us
        if not (max_range >= 0.0 and math.isfinite(max_range)):
            raise ValueError(f"max_range must be a finite number of metres >= 0, got {max_range!r}")
        trig = _TRIG_CACHE.get(angles.shape[0])
        if trig is None:
            trig = _trig_rows(angles.shape[0])
        return _march_serial(*scan, pose, angles, float(max_range), trig, _ONE_PIECE)[0]
    _check_method(method)
    if grid.origin[2] != 0.0:
        raise ValueError(f"grid.origin theta must be 0 (rotated grids are not supported), got {grid.origin[2]}")
    single = np.ndim(pose) == 1
    p, a = _check_rays(grid.resolution, pose, angles, max_range)
    arrays = _grid_arrays(grid)
    if method == "dda":
        out = _run(arrays.occupied, "dda", float(grid.resolution), grid.origin[:2], p, a, float(max_range), parallel)
    elif p.shape[0] == 1 and not _use_threads(parallel, a.shape[0]):
        out = _march_one_pose(grid, arrays, p[0], a, float(max_range))[None]
    elif not _use_threads(parallel, p.shape[0] * a.shape[0]):
        # several poses, serial: each beam's first jump on the octant planes, then the isotropic field
        out = _march_serial(
            arrays.field,
            arrays.field.reshape(-1),
            0,
            _start_octants(grid, arrays),
            arrays.resolution,
            arrays.ox,
            arrays.oy,
            p,
            a,
            float(max_range),
            _trig_rows(a.shape[0]),
            _ONE_PIECE,
        )
    else:
        out = _run(arrays.field, "march", float(grid.resolution), grid.origin[:2], p, a, float(max_range), parallel)
    return out[0] if single else out


# --- range derivatives for the bound (locbench.evaluate.pcrb) -------------------------------------------------------


def scan_gradients(
    occ: BoolArray,
    res: float,
    ox: float,
    oy: float,
    sensors: FloatArray,
    headings: FloatArray,
    mount_xy: tuple[float, float],
    angles: FloatArray,
    max_range: float,
    eps: float,
) -> tuple[FloatArray, FloatArray, npt.NDArray[np.bool_]]:
    """Ranges of the ``method="dda"`` traversal and their analytic derivatives w.r.t. the robot pose.

    ``sensors`` (S, 3) are the world sensor poses of robots at headings ``headings`` (S,) with the sensor
    mounted at ``mount_xy`` (m, robot frame). The range of a beam that enters its hit cell across a grid
    line x = X is r = (X - s_x) / cos(phi) (s the sensor, phi the beam's world angle), across y = Y it is
    (Y - s_y) / sin(phi); differentiating through s(x, y, theta) and phi = theta + const gives the gradient.

    Returns (ranges (S, B) m as :func:`cast_rays` gives them, gradients (S, B, 3) in (m/m, m/m, m/rad), and
    ``smooth`` (S, B)): False where central differences of step ``eps`` would not see a smooth function,
    which the caller then takes by differences: the ray passes near a corner of occupied cells
    (:func:`dda_face`), starts in or outside the hit cell's face, ends within reach of ``max_range``, or
    its curvature in the heading brings the one-sided differences' disagreement, about eps |r''|, to half the
    tolerance 1e-4 (1 + |r'|) of :func:`locbench.evaluate.pcrb.laser_information` or more. Spread over numba's
    threads for as many rays as :func:`cast_rays` would spread.
    """
    n, nb = sensors.shape[0], angles.shape[0]
    ranges = np.empty((n, nb))
    grads = np.zeros((n, nb, 3))
    smooth = np.zeros((n, nb), dtype=np.bool_)
    kernel = _gradients_threads if _use_threads(None, n * nb) else _gradients_serial
    cells = face_cells(occ)
    kernel(
        cells, res, ox, oy, sensors, headings, mount_xy[0], mount_xy[1], angles, max_range, eps, ranges, grads, smooth
    )
    return ranges, grads, smooth


@njit(cache=True, inline="always")
def _ray_gradient(
    cells: UInt8Array,
    res: float,
    ox: float,
    oy: float,
    sensors: FloatArray,
    trig: FloatArray,
    mx: float,
    my: float,
    cb: FloatArray,
    sb: FloatArray,
    max_range: float,
    eps: float,
    p: int,
    b: int,
    ranges: FloatArray,
    grads: FloatArray,
    smooth: npt.NDArray[np.bool_],
) -> None:
    """One ray of :func:`scan_gradients`, written into its outputs; ``trig`` (S, 4) holds the cosine and sine
    of each sensor's and each robot's heading (:func:`_heading_trig`)."""
    inv_res = 1.0 / res
    t_lim = max_range * inv_res
    # how far a perturbed ray moves (cells): eps of translation and eps of rotation about the robot, 10x
    near0 = 10.0 * eps * (1.0 + math.hypot(mx, my)) * inv_res
    near1 = 10.0 * eps
    gx = (sensors[p, 0] - ox) * inv_res
    gy = (sensors[p, 1] - oy) * inv_res
    cp = trig[p, 0]
    sp = trig[p, 1]
    dx, dy = _beam_direction(cp, sp, cb[b], sb[b])
    t, axis, near = dda_face(cells, gx, gy, dx, dy, t_lim, near0, near1)
    r = t * res
    ranges[p, b] = r
    if near or axis < 0 or r > max_range - 3.0 * (near0 + near1 * t) * res:
        return
    ct = trig[p, 2]
    st = trig[p, 3]
    dsx = -st * mx - ct * my  # d s_x / d theta
    dsy = ct * mx - st * my
    if axis == 0:
        d, dd, dd2 = dx, -dy, -dx  # D = cos(phi) and its first two derivatives in phi
        n1, n2 = -dsx, ct * mx - st * my  # N = X - s_x: N', N''
        g0, g1, g2 = -1.0 / dx, 0.0, -dsx / dx + r * dy / dx
    else:
        d, dd, dd2 = dy, dx, -dy  # D = sin(phi)
        n1, n2 = -dsy, st * mx + ct * my  # N = Y - s_y
        g0, g1, g2 = 0.0, -1.0 / dy, -dsy / dy - r * dx / dy
    # r = N / D with N = r D: r'' = N'' / D - 2 N' D' / D^2 - r D'' / D + 2 r D'^2 / D^2
    r2 = n2 / d - 2.0 * n1 * dd / (d * d) - r * dd2 / d + 2.0 * r * dd * dd / (d * d)
    if eps * abs(r2) >= 0.5e-4 * (1.0 + abs(g2)):
        return
    grads[p, b, 0] = g0
    grads[p, b, 1] = g1
    grads[p, b, 2] = g2
    smooth[p, b] = True


@njit(cache=True)
def _heading_trig(sensors: FloatArray, headings: FloatArray) -> FloatArray:
    """cos and sin of each sensor's heading and of each robot's, (S, 4): once per scan rather than per ray
    (the same ``math`` calls, so the same numbers)."""
    out = np.empty((sensors.shape[0], 4))
    for p in range(sensors.shape[0]):
        out[p, 0] = math.cos(sensors[p, 2])
        out[p, 1] = math.sin(sensors[p, 2])
        out[p, 2] = math.cos(headings[p])
        out[p, 3] = math.sin(headings[p])
    return out


def _gradient_rays(
    cells: UInt8Array, res: float, ox: float, oy: float, sensors: FloatArray, headings: FloatArray, mx: float,
    my: float, angles: FloatArray, max_range: float, eps: float, ranges: FloatArray, grads: FloatArray,
    smooth: npt.NDArray[np.bool_],
) -> None:  # fmt: skip  # pragma: no cover - compiled
    """:func:`scan_gradients` into its outputs, one ray per ``prange`` item (:func:`_ray_gradient`)."""
    cb = np.cos(angles)
    sb = np.sin(angles)
    nb = angles.shape[0]
    trig = _heading_trig(sensors, headings)
    for k in prange(sensors.shape[0] * nb):
        p = k // nb
        _ray_gradient(cells, res, ox, oy, sensors, trig, mx, my, cb, sb, max_range, eps, p, k - p * nb, ranges, grads,
                      smooth)  # fmt: skip


_gradients_serial, _gradients_threads = _threads_build(_gradient_rays)


def cast_ray_subset(
    occ: BoolArray,
    res: float,
    ox: float,
    oy: float,
    poses: FloatArray,
    angles: FloatArray,
    max_range: float,
    rows: IntArray,
    beams: IntArray,
) -> FloatArray:
    """The ranges of :func:`cast_rays` (``method="dda"``) of the rays (``rows[k]``, ``beams[k]``) only, spread over
    numba's threads: the same traversal and beam direction per ray (:func:`_dda_one`, :func:`_beam_direction`),
    so the same ranges, bit for bit.

    ``poses`` are the sensor poses, (S, 3), giving ranges of shape (K,); or several sets of them, (P, S, 3)
    (the bound's six perturbed poses), cast in one call, giving (P, K).
    """
    p = np.asarray(poses, dtype=np.float64)
    sets = np.ascontiguousarray(p if p.ndim == 3 else p[None])
    out: FloatArray = _ray_subset_parallel(occ, res, ox, oy, sets, angles, max_range, rows, beams)
    return out if p.ndim == 3 else out[0]


@njit(cache=True, parallel=True)
def _ray_subset_parallel(
    occ: BoolArray,
    res: float,
    ox: float,
    oy: float,
    poses: FloatArray,
    angles: FloatArray,
    max_range: float,
    rows: IntArray,
    beams: IntArray,
) -> FloatArray:
    n_sets = poses.shape[0]
    n = rows.shape[0]
    out = np.empty((n_sets, n))
    inv_res = 1.0 / res
    t_lim = max_range * inv_res
    cb = np.cos(angles)
    sb = np.sin(angles)
    # each pose's cos and sin once rather than per ray (the same math calls)
    trig = np.empty((n_sets, poses.shape[1], 2))
    for s in range(n_sets):
        for p in range(poses.shape[1]):
            trig[s, p, 0] = math.cos(poses[s, p, 2])
            trig[s, p, 1] = math.sin(poses[s, p, 2])
    for q in prange(n_sets * n):
        s = q // n
        k = q - s * n
        p = rows[k]
        b = beams[k]
        gx = (poses[s, p, 0] - ox) * inv_res
        gy = (poses[s, p, 1] - oy) * inv_res
        dx, dy = _beam_direction(trig[s, p, 0], trig[s, p, 1], cb[b], sb[b])
        out[s, k] = _dda_one(occ, gx, gy, dx, dy, t_lim) * res
    return out
