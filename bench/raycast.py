"""Ray casting on an occupancy grid, shared by the laser simulator and the grid-based filters.

One exact grid traversal (Amanatides & Woo, "A Fast Voxel Traversal Algorithm for Ray Tracing",
Eurographics 1987) compiled with numba, plus a deliberately simple numpy reference used by tests.

Grid conventions are those of :class:`locbench.datasets.base.OccupancyGrid` (ROS map_server): row ``i``
spans y in [oy + i*res, oy + (i+1)*res), column ``j`` spans x likewise, and ``origin_xy`` = (ox, oy) is
the world position of the corner of cell (0, 0). Poses are world-frame sensor poses (x m, y m, theta
rad); beam angles are relative to the pose heading. A range is the distance from the sensor to the
point where the beam enters the first occupied cell; ``inf`` when no occupied cell is entered within
``max_range``. A beam starting inside an occupied cell has range 0. Space outside the grid is free.

Threads: the parallel kernel uses numba's threading layer; with the default ``workqueue`` layer it must
not be called from several Python threads at once (processes are fine). Pass ``parallel=False`` there.
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING

import numba
import numpy as np
import numpy.typing as npt
from numba import njit, prange

if TYPE_CHECKING:
    from locbench.datasets.base import OccupancyGrid

logger = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

#: Below this many rays a single thread is faster than waking the thread pool (measured on 2 cores).
PARALLEL_MIN_RAYS = 8192


@njit(cache=True, inline="always")
def _cast_one(
    occ: BoolArray, inv_res: float, res: float, ox: float, oy: float, px: float, py: float, ang: float, max_range: float
) -> float:
    """Range of one beam by exact grid traversal, m (inf when nothing is hit within max_range)."""
    rows = occ.shape[0]
    cols = occ.shape[1]
    dx = math.cos(ang)
    dy = math.sin(ang)
    # Work in grid units (one cell = 1); the direction stays a unit vector, so t * res is metres.
    gx = (px - ox) * inv_res
    gy = (py - oy) * inv_res
    t_lim = max_range * inv_res
    # Clip the ray to the grid rectangle [0, cols] x [0, rows] (slab test) so starts outside work too.
    t0 = 0.0
    t1 = math.inf
    if dx != 0.0:
        a = -gx / dx
        b = (cols - gx) / dx
        t0 = max(t0, min(a, b))
        t1 = min(t1, max(a, b))
    elif gx < 0.0 or gx >= cols:
        return math.inf
    if dy != 0.0:
        a = -gy / dy
        b = (rows - gy) / dy
        t0 = max(t0, min(a, b))
        t1 = min(t1, max(a, b))
    elif gy < 0.0 or gy >= rows:
        return math.inf
    if t0 >= t1 or t0 > t_lim:
        return math.inf
    ex = gx + t0 * dx
    ey = gy + t0 * dy
    j = min(max(math.floor(ex), 0), cols - 1)
    i = min(max(math.floor(ey), 0), rows - 1)
    if dx > 0.0:
        step_j = 1
        t_next_x = t0 + (j + 1.0 - ex) / dx
        t_delta_x = 1.0 / dx
    elif dx < 0.0:
        step_j = -1
        t_next_x = t0 + (j - ex) / dx
        t_delta_x = -1.0 / dx
    else:
        step_j = 0
        t_next_x = math.inf
        t_delta_x = math.inf
    if dy > 0.0:
        step_i = 1
        t_next_y = t0 + (i + 1.0 - ey) / dy
        t_delta_y = 1.0 / dy
    elif dy < 0.0:
        step_i = -1
        t_next_y = t0 + (i - ey) / dy
        t_delta_y = -1.0 / dy
    else:
        step_i = 0
        t_next_y = math.inf
        t_delta_y = math.inf
    t = t0
    while True:
        if occ[i, j]:
            return t * res
        if t_next_x < t_next_y:
            t = t_next_x
            t_next_x += t_delta_x
            j += step_j
            if j < 0 or j >= cols:
                return math.inf
        else:
            t = t_next_y
            t_next_y += t_delta_y
            i += step_i
            if i < 0 or i >= rows:
                return math.inf
        if t > t_lim:
            return math.inf


@njit(cache=True)
def _cast_serial(
    occ: BoolArray, res: float, ox: float, oy: float, poses: FloatArray, angles: FloatArray, max_range: float
) -> FloatArray:
    n = poses.shape[0]
    nb = angles.shape[0]
    out = np.empty((n, nb))
    inv_res = 1.0 / res
    for p in range(n):
        for b in range(nb):
            out[p, b] = _cast_one(
                occ, inv_res, res, ox, oy, poses[p, 0], poses[p, 1], poses[p, 2] + angles[b], max_range
            )
    return out


@njit(cache=True, parallel=True)
def _cast_parallel(
    occ: BoolArray, res: float, ox: float, oy: float, poses: FloatArray, angles: FloatArray, max_range: float
) -> FloatArray:
    n = poses.shape[0]
    nb = angles.shape[0]
    out = np.empty((n, nb))
    inv_res = 1.0 / res
    # Flattened so that one pose with many beams also spreads over the threads.
    for k in prange(n * nb):
        p = k // nb
        b = k - p * nb
        out[p, b] = _cast_one(occ, inv_res, res, ox, oy, poses[p, 0], poses[p, 1], poses[p, 2] + angles[b], max_range)
    return out


def _check_inputs(
    occupied: npt.ArrayLike, resolution: float, poses: npt.ArrayLike, angles: npt.ArrayLike, max_range: float
) -> tuple[BoolArray, FloatArray, FloatArray]:
    occ = np.ascontiguousarray(occupied, dtype=np.bool_)
    if occ.ndim != 2 or occ.shape[0] == 0 or occ.shape[1] == 0:
        raise ValueError(f"occupied must be a non-empty 2-D array (rows, cols), got shape {occ.shape}")
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
    return occ, p, a


def cast_rays(
    occupied: npt.ArrayLike,
    resolution: float,
    origin_xy: tuple[float, float],
    poses: npt.ArrayLike,
    angles: npt.ArrayLike,
    max_range: float,
    *,
    parallel: bool | None = None,
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

    Returns
    -------
    ndarray, shape (N, B)
        Range to the entry point of the first occupied cell, m; 0 for a beam starting in an occupied
        cell; ``inf`` where nothing is hit within ``max_range``.
    """
    occ, p, a = _check_inputs(occupied, resolution, poses, angles, max_range)
    n_rays = p.shape[0] * a.shape[0]
    if parallel is None:
        parallel = n_rays >= PARALLEL_MIN_RAYS and numba.get_num_threads() > 1
    kernel = _cast_parallel if parallel else _cast_serial
    return kernel(occ, float(resolution), float(origin_xy[0]), float(origin_xy[1]), p, a, float(max_range))


def cast_scan(
    grid: OccupancyGrid, pose: npt.ArrayLike, angles: npt.ArrayLike, max_range: float, *, parallel: bool | None = None
) -> FloatArray:
    """Ranges of one scan (or several) cast in an :class:`OccupancyGrid`.

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

    Returns
    -------
    ndarray, shape (B,) for one pose, (N, B) for several
    """
    if grid.origin[2] != 0.0:
        raise ValueError(f"grid.origin theta must be 0 (rotated grids are not supported), got {grid.origin[2]}")
    single = np.ndim(pose) == 1
    out = cast_rays(grid.occupied(), grid.resolution, grid.origin[:2], pose, angles, max_range, parallel=parallel)
    return out[0] if single else out


def cast_rays_reference(
    occupied: npt.ArrayLike,
    resolution: float,
    origin_xy: tuple[float, float],
    poses: npt.ArrayLike,
    angles: npt.ArrayLike,
    max_range: float,
    step_fraction: float = 0.05,
) -> FloatArray:
    """Slow, obviously-correct ray marcher with the same signature as :func:`cast_rays` (tests only).

    Samples each beam every ``step_fraction * resolution`` metres and returns the distance of the first
    sample inside an occupied cell, so it overestimates the exact range by less than one step and may
    miss a cell that a beam only clips at a corner.
    """
    occ, p, a = _check_inputs(occupied, resolution, poses, angles, max_range)
    rows, cols = occ.shape
    step = step_fraction * resolution
    s = np.arange(0.0, max_range + step, step)
    s = s[s <= max_range]
    th = p[:, 2:3] + a[None, :]  # (N, B)
    x = p[:, 0, None, None] + np.cos(th)[..., None] * s  # (N, B, S)
    y = p[:, 1, None, None] + np.sin(th)[..., None] * s
    j = np.floor((x - origin_xy[0]) / resolution).astype(np.int64)
    i = np.floor((y - origin_xy[1]) / resolution).astype(np.int64)
    inside = (i >= 0) & (i < rows) & (j >= 0) & (j < cols)
    hit = np.zeros(x.shape, dtype=bool)
    hit[inside] = occ[i[inside], j[inside]]
    any_hit = hit.any(axis=-1)
    first = np.argmax(hit, axis=-1)
    return np.where(any_hit, s[first], np.inf)
