"""Per-direction clearance field for :mod:`locbench.raycast.cast` (``method="march"``).

The isotropic clearance of a cell (its distance to the nearest occupied cell in any direction) is small
wherever a beam runs along a wall, so a beam approaching a wall at a grazing angle takes many short jumps.
This module stores, per cell and per angular sector of beam directions, a lower bound on how far any beam
whose direction lies in that sector can travel from any point of the cell before it enters the interior
of an occupied cell (the "per-direction jump bounds" of CDDT, Walsh & Karaman, ICRA 2018, made exact).

Geometry, in cell units with cell ``c`` = [0, 1]^2 and an occupied cell ``o`` at offset (dx, dy): the
vectors ``q - p`` from a point of ``c`` to a point of ``o`` fill the square ``S = [dx - 1, dx + 1] x
[dy - 1, dy + 1]`` (the Minkowski difference of the two cells). A beam from ``p`` with direction in the
closed sector ``W`` (a wedge of directions with apex at the origin) enters the interior of ``o`` only
if the open square meets ``W``, and then after at least ``K_W(dx, dy) = min |v|, v in S and W``. The
bound of ``c`` is the minimum of ``K_W`` over the occupied cells, which are found row by row (the first
occupied cell of each row inside the wedge has the smallest ``K_W`` of that row, as the table check in
the tests confirm). The 8 * ``n_sub`` sectors are the ``n_sub`` equal parts of each octant (the ray caster
uses the octants, ``n_sub`` = 1); every octant is reduced to the first one (directions with 0 <= dy <= dx)
by flipping and transposing the grid. The bounds of a 400 x 400 grid take about 0.2 s.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
UInt8Array = npt.NDArray[np.uint8]
IntArray = npt.NDArray[np.int64]

#: Subtracted from every bound (cells) before it is rounded down to whole units, so that rounding in the
#: table and in the kernel's positions (about 1e-13 cells) can never turn a bound into an overestimate.
SAFETY_CELLS = 1e-6


@njit(cache=True)
def _clip(xs: FloatArray, ys: FloatArray, n: int, ax: float, ay: float, sign: float) -> int:
    """Clip polygon (xs, ys)[:n] in place to the closed half-plane sign * cross((ax, ay), v) >= 0."""
    ox = np.empty(12)
    oy = np.empty(12)
    m = 0
    for k in range(n):
        px, py = xs[k], ys[k]
        qx, qy = xs[(k + 1) % n], ys[(k + 1) % n]
        fp = sign * (ax * py - ay * px)
        fq = sign * (ax * qy - ay * qx)
        if fp >= 0.0:
            ox[m] = px
            oy[m] = py
            m += 1
        if (fp >= 0.0) != (fq >= 0.0) and fp != fq:
            s = fp / (fp - fq)
            ox[m] = px + s * (qx - px)
            oy[m] = py + s * (qy - py)
            m += 1
    for k in range(m):
        xs[k] = ox[k]
        ys[k] = oy[k]
    return m


@njit(cache=True)
def _wedge_rect_distance(x0: int, x1: int, y0: int, y1: int, u0x: float, u0y: float, u1x: float, u1y: float) -> float:
    """Smallest norm of the rectangle [x0, x1] x [y0, y1] (integers) inside the wedge from u0 to u1; inf if none.

    The wedge turns counter-clockwise from u0 to u1 by less than 90 deg. Infinite only when the open
    rectangle provably misses the wedge (exact signs on the integer corners); otherwise the minimum norm
    over the closed rectangle and wedge, a lower bound.
    """
    if x0 <= 0 <= x1 and y0 <= 0 <= y1:
        # the origin lies in the rectangle: beams enter its interior at once iff the wedge's middle direction
        # points strictly into it (for a wedge inside the first octant this decides every case)
        mx = u0x + u1x
        my = u0y + u1y
        ok = (x0 < 0 or mx > 0.0) and (x1 > 0 or mx < 0.0) and (y0 < 0 or my > 0.0) and (y1 > 0 or my < 0.0)
        return 0.0 if ok else math.inf
    cx = np.array([float(x0), float(x1), float(x1), float(x0)])
    cy = np.array([float(y0), float(y0), float(y1), float(y1)])
    in0 = False
    in1 = False
    for k in range(4):
        if u0x * cy[k] - u0y * cx[k] > 0.0:
            in0 = True
        if cx[k] * u1y - cy[k] * u1x > 0.0:
            in1 = True
    if not (in0 and in1):
        return math.inf
    xs = np.empty(12)
    ys = np.empty(12)
    xs[:4] = cx
    ys[:4] = cy
    n = _clip(xs, ys, 4, u0x, u0y, 1.0)
    if n > 0:
        n = _clip(xs, ys, n, u1x, u1y, -1.0)
    if n == 0:
        return math.inf
    best = math.inf
    for k in range(n):
        px, py = xs[k], ys[k]
        qx, qy = xs[(k + 1) % n], ys[(k + 1) % n]
        ex = qx - px
        ey = qy - py
        ee = ex * ex + ey * ey
        s = 0.0 if ee == 0.0 else min(max(-(px * ex + py * ey) / ee, 0.0), 1.0)
        best = min(best, math.hypot(px + s * ex, py + s * ey))
    return best


def _wedge_directions(n_sub: int) -> FloatArray:
    """Boundary directions (n_sub + 1, 2) of the canonical sub-sectors; the lattice ones are exact."""
    dirs = np.empty((n_sub + 1, 2))
    for k in range(n_sub + 1):
        if k == 0:
            dirs[k] = (1.0, 0.0)
        elif k == n_sub:
            dirs[k] = (1.0, 1.0)  # 45 deg exactly (cos and sin of pi/4 differ in their last bit)
        else:
            dirs[k] = (1.0, math.tan(k * math.pi / (4.0 * n_sub)))
    return dirs


@njit(cache=True)
def _kernel_tables(dirs: FloatArray, size: int) -> tuple[FloatArray, IntArray, IntArray]:
    """``K`` (n_sub, size, size + 1) over dy in [0, size), dx in [-1, size); first/last finite dx per row.

    (dx, dy) is the offset of an occupied cell from the free cell; the rows below (dy < 0) and the cells
    left of dx = -1 are never entered by beams with 0 <= dy <= dx.
    """
    n_sub = dirs.shape[0] - 1
    k_tab = np.full((n_sub, size, size + 1), math.inf)
    first = np.full((n_sub, size), size + 1, dtype=np.int64)
    last = np.full((n_sub, size), -2, dtype=np.int64)
    for s in range(n_sub):
        for dy in range(size):
            for dx in range(-1, size):
                val = _wedge_rect_distance(
                    dx - 1, dx + 1, dy - 1, dy + 1, dirs[s, 0], dirs[s, 1], dirs[s + 1, 0], dirs[s + 1, 1]
                )
                k_tab[s, dy, dx + 1] = val
                if val < math.inf:
                    first[s, dy] = min(first[s, dy], dx)
                    last[s, dy] = max(last[s, dy], dx)
    return k_tab, first, last


@njit(cache=True)
def _canonical_bounds(
    occ: BoolArray, k_tab: FloatArray, first: IntArray, last: IntArray, sin_hi: FloatArray, cap: float, out: FloatArray
) -> None:
    """Bounds (cells) for beams with 0 <= dy <= dx into ``out`` (n_sub, rows, cols); occupied cells untouched.

    Per free cell and sector, each row at or above the cell's contributes its first occupied cell inside the
    wedge (the one with the smallest table value: the table rows are non-decreasing there).
    """
    rows, cols = occ.shape
    n_sub, size = first.shape
    # next occupied column at or right of each column, per row (cols: none)
    nxt = np.empty((rows, cols + 1), dtype=np.int64)
    for i in range(rows):
        nxt[i, cols] = cols
        for j in range(cols - 1, -1, -1):
            nxt[i, j] = j if occ[i, j] else nxt[i, j + 1]
    for i in range(rows):
        for j in range(cols):
            if occ[i, j]:
                continue
            for s in range(n_sub):
                best = cap
                lim = sin_hi[s]
                for dy in range(size):
                    # a beam must rise dy - 1 cells to reach row i + dy, at most sin_hi per unit length
                    if dy - 1 >= best * lim or i + dy >= rows:
                        break
                    fx = first[s, dy]
                    if fx >= size:
                        break  # the wedge leaves the table: every later row is farther than the cap
                    x0 = j + fx
                    if x0 >= cols:
                        continue
                    xo = nxt[i + dy, max(x0, 0)]
                    d = xo - j
                    if xo >= cols or d > last[s, dy] or d >= size:
                        continue
                    best = min(best, k_tab[s, dy, d + 1])
                out[s, i, j] = best


#: Kernel tables per (n_sub, size), built once per process (tens of ms).
_TABLES: dict[tuple[int, int], tuple[FloatArray, IntArray, IntArray, FloatArray]] = {}


def kernel_tables(n_sub: int, size: int) -> tuple[FloatArray, IntArray, IntArray, FloatArray]:
    """``(K, first, last, sin_hi)`` of the first octant's ``n_sub`` sectors over offsets below ``size`` cells.

    ``K[s, dy, dx + 1]`` is ``K_W`` of sector ``s`` for an occupied cell at (dx, dy) (inf where the sector's
    beams never enter it); ``first[s, dy]`` and ``last[s, dy]`` bound the finite dx of row dy; ``sin_hi[s]``
    is the sine of the sector's upper boundary.
    """
    key = (n_sub, size)
    if key not in _TABLES:
        dirs = _wedge_directions(n_sub)
        k_tab, first, last = _kernel_tables(dirs, size)
        hi = dirs[1:]
        _TABLES[key] = (k_tab, first, last, hi[:, 1] / np.hypot(hi[:, 0], hi[:, 1]))
    return _TABLES[key]


def sector_index(flip_x: bool, flip_y: bool, swap: bool, sub: int, n_sub: int) -> int:
    """Plane for an octant (dx < 0, dy < 0, |dy| > |dx|) and its sub-sector (0 = nearest the x or y axis)."""
    return ((int(flip_x) * 2 + int(flip_y)) * 2 + int(swap)) * n_sub + sub


def sector_bounds(occupied: BoolArray, n_sub: int, cap_cells: float) -> FloatArray:
    """Per-sector clearance bounds, cells, shape (8 * n_sub, rows, cols); 0 on occupied cells.

    Plane :func:`sector_index` ``(dx < 0, dy < 0, |dy| > |dx|, sub, n_sub)`` bounds, for the beams whose
    direction (dx, dy) lies in that octant and sub-sector, the distance from any point of a cell to the
    interior of the first occupied cell such a beam enters; capped at ``cap_cells``. Outside the grid is free.
    """
    occ = np.ascontiguousarray(occupied, dtype=np.bool_)
    size = math.ceil(cap_cells) + 3
    k_tab, first, last, sin_hi = kernel_tables(n_sub, size)
    out = np.zeros((8 * n_sub, *occ.shape))
    for fx in (False, True):
        for fy in (False, True):
            for sw in (False, True):
                g = occ[:, ::-1] if fx else occ
                g = g[::-1, :] if fy else g
                g = g.T if sw else g
                part = np.zeros((n_sub, *g.shape))
                _canonical_bounds(np.ascontiguousarray(g), k_tab, first, last, sin_hi, float(cap_cells), part)
                # back to the grid's own axes: undo the transpose, then the flips
                back = part.transpose(0, 2, 1) if sw else part
                back = back[:, ::-1, :] if fy else back
                back = back[:, :, ::-1] if fx else back
                p0 = sector_index(fx, fy, sw, 0, n_sub)
                out[p0 : p0 + n_sub] = back
    out[:, occ] = 0.0
    return out
