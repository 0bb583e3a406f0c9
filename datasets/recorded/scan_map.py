"""Maps built from laser scans at known poses: the occupancy grid and the line segments along its walls.

The loaders whose map is built from their own reference scans (:mod:`~locbench.datasets.recorded.intel`,
:mod:`~locbench.datasets.recorded.radish`) call :func:`build_occupancy_grid` and :func:`extract_map_lines`; a
map_server map (:func:`~locbench.datasets.recorded.ros_map.load_map_and_lines`) takes its lines from
:func:`extract_map_lines`.

Occupancy grid
--------------
For each scan, every beam with a return adds the log-odds of a hit, log(0.7/0.3), to its end cell and of a miss,
log(0.4/0.6), to every cell a Bresenham line crosses from the laser cell to it (the inverse sensor model of
occupancy-grid mapping, S. Thrun, W. Burgard, D. Fox, "Probabilistic Robotics", MIT Press 2005, ch. 9);
no-return beams (non-finite, or at or above the scanner's no-return reading) add nothing. Cells never crossed are
unknown (-1); the others hold p = 1 / (1 + exp(-l)) with ROS thresholds (occupied above 0.65, free below 0.196).
The grid's size is computed from the scans' extent before anything is allocated and refused above ``max_cells``
(:data:`~locbench.datasets.recorded.files.MAX_GRID_CELLS` by default); a dataset's ``map_resolution_m`` lies in
[:data:`MIN_RESOLUTION_M`, :data:`MAX_RESOLUTION_M`].

Map lines (for ``ekf_lines``)
-----------------------------
A Hough transform of the occupied cells (1 deg x one cell), taken greedily: at the strongest bin, the cells within
one cell of its line are fitted by total least squares, the cells within one cell of the fitted line are split into
runs wherever two neighbours lie more than 0.3 m apart, each run at least 0.5 m long becomes a segment, and all
those cells leave the accumulator; this stops when the strongest bin holds fewer cells than a 0.5 m diagonal wall.
The votes are counted before they are allocated and refused above :data:`MAX_HOUGH_VOTES`.
:func:`extract_map_lines` returns the segments and their counts (the loaders store them in ``metadata["map"]``).
"""

from __future__ import annotations

import math
import os

import numpy as np
import numpy.typing as npt
from numba import njit

from locbench.core.errors import ConfigError
from locbench.datasets.dataset import LineMap, OccupancyGrid
from locbench.datasets.recorded.files import MAX_GRID_CELLS, check_cells

FloatArray = npt.NDArray[np.float64]

#: Largest Hough vote count of :func:`extract_map_lines` (occupied cells x angles; 24 bytes each: 432 MB). The Intel
#: map has 14455 occupied cells (2.6 M votes at 1 deg).
MAX_HOUGH_VOTES = 18_000_000
#: Bounds of a dataset's ``map_resolution_m``, m: below 1 mm a cell is finer than the laser by two orders, above 10 m
#: there is no map.
MIN_RESOLUTION_M = 0.001
MAX_RESOLUTION_M = 10.0
#: Inverse sensor model of the grid build (Probabilistic Robotics ch. 9).
P_HIT, P_MISS = 0.7, 0.4


# --- occupancy grid --------------------------------------------------------------------------------------


@njit(cache=True)
def _accumulate(
    logodds: npt.NDArray[np.float64],
    touched: npt.NDArray[np.bool_],
    c0: npt.NDArray[np.int64],
    r0: npt.NDArray[np.int64],
    c1: npt.NDArray[np.int64],
    r1: npt.NDArray[np.int64],
    l_hit: float,
    l_miss: float,
) -> None:  # pragma: no cover - compiled
    """Add ``l_miss`` to every cell a Bresenham line crosses from (r0, c0) to (r1, c1), beam by beam, and ``l_hit``
    to its end cell, marking them ``touched`` (in place; cells as (row, column) of ``logodds``)."""
    for b in range(c0.shape[0]):
        x, y, x1, y1 = c0[b], r0[b], c1[b], r1[b]
        dx = abs(x1 - x)
        dy = -abs(y1 - y)
        sx = 1 if x < x1 else -1
        sy = 1 if y < y1 else -1
        err = dx + dy
        while x != x1 or y != y1:
            logodds[y, x] += l_miss
            touched[y, x] = True
            e2 = 2 * err
            if e2 >= dy:
                err += dy
                x += sx
            if e2 <= dx:
                err += dx
                y += sy
        logodds[y1, x1] += l_hit
        touched[y1, x1] = True


def build_occupancy_grid(
    poses: npt.ArrayLike,
    ranges: npt.ArrayLike,
    angles: npt.ArrayLike,
    resolution_m: float,
    max_range_m: float = math.inf,
    margin_m: float = 1.0,
    *,
    max_cells: int = MAX_GRID_CELLS,
    source: str | os.PathLike[str] = "occupancy grid",
) -> OccupancyGrid:
    """Occupancy grid of scans taken at known poses, by log-odds ray casting (see the module docstring).

    Parameters
    ----------
    poses : array-like, shape (n, 3)
        Laser poses (x m, y m, theta rad), world frame.
    ranges : array-like, shape (n, B)
        Ranges, m; values >= ``max_range_m`` or non-finite are no-returns and add nothing.
    angles : array-like, shape (B,)
        Beam bearings in the laser frame, rad.
    resolution_m : float
        Cell side, m.
    max_range_m : float
        The scanner's no-return reading, m (default: only non-finite ranges are no-returns).
    margin_m : float
        Unknown border around the scans' extent, m.
    max_cells : int
        Largest grid built, cells; a larger one is refused before it is allocated.
    source : path-like
        What the scans came from, for the message.

    Returns
    -------
    OccupancyGrid
        Probabilities in [0, 1], -1 for never-observed cells; origin at the lower-left corner.
    """
    if not resolution_m > 0:
        raise ConfigError(f"map_resolution_m must be > 0 m, got {resolution_m}")
    P = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    R = np.asarray(ranges, dtype=np.float64)
    a = np.asarray(angles, dtype=np.float64)
    hit = np.isfinite(R) & (max_range_m > R)
    bearing = P[:, 2:3] + a[None, :]
    with np.errstate(invalid="ignore"):  # inf x 0 of a no-return beam along an axis: left out by ``hit``
        ex = (P[:, 0:1] + R * np.cos(bearing))[hit]
        ey = (P[:, 1:2] + R * np.sin(bearing))[hit]
    sx = np.broadcast_to(P[:, 0:1], R.shape)[hit]
    sy = np.broadcast_to(P[:, 1:2], R.shape)[hit]
    span_x = max(ex.max(initial=-np.inf), P[:, 0].max()) - min(ex.min(initial=np.inf), P[:, 0].min())
    span_y = max(ey.max(initial=-np.inf), P[:, 1].max()) - min(ey.min(initial=np.inf), P[:, 1].min())
    check_cells(
        source,
        (span_y + 2 * margin_m) / resolution_m + 1,
        (span_x + 2 * margin_m) / resolution_m + 1,
        max_cells,
        f"at {resolution_m!r} m per cell; raise max_grid_cells or map_resolution_m",
    )
    x_lo = math.floor((min(ex.min(initial=np.inf), P[:, 0].min()) - margin_m) / resolution_m) * resolution_m
    y_lo = math.floor((min(ey.min(initial=np.inf), P[:, 1].min()) - margin_m) / resolution_m) * resolution_m
    x_hi = max(ex.max(initial=-np.inf), P[:, 0].max()) + margin_m
    y_hi = max(ey.max(initial=-np.inf), P[:, 1].max()) + margin_m
    cols = math.ceil((x_hi - x_lo) / resolution_m)
    rows = math.ceil((y_hi - y_lo) / resolution_m)
    logodds = np.zeros((rows, cols))
    touched = np.zeros((rows, cols), dtype=np.bool_)

    def cell(v: FloatArray, lo: float) -> npt.NDArray[np.int64]:
        return np.floor((v - lo) / resolution_m).astype(np.int64)

    l_hit = math.log(P_HIT / (1 - P_HIT))
    l_miss = math.log(P_MISS / (1 - P_MISS))
    _accumulate(logodds, touched, cell(sx, x_lo), cell(sy, y_lo), cell(ex, x_lo), cell(ey, y_lo), l_hit, l_miss)
    occ = np.where(touched, 1.0 / (1.0 + np.exp(-logodds)), -1.0)
    return OccupancyGrid(occ, float(resolution_m), (float(x_lo), float(y_lo), 0.0))


# --- map lines -------------------------------------------------------------------------------------------


def extract_map_lines(
    grid: OccupancyGrid,
    *,
    min_length_m: float = 0.5,
    max_gap_m: float = 0.3,
    angle_step_deg: float = 1.0,
) -> tuple[LineMap, dict[str, float]]:
    """Line segments along the occupied cells of a grid by greedy Hough voting (see the module docstring).

    Parameters
    ----------
    grid : OccupancyGrid
        The map.
    min_length_m : float
        Shortest segment kept, m.
    max_gap_m : float
        Largest gap between neighbouring cells of one segment, m.
    angle_step_deg : float
        Angular bin of the Hough accumulator, deg; the distance bin is one cell.

    Raises
    ------
    ConfigError
        More than :data:`MAX_HOUGH_VOTES` votes (occupied cells x angles), before they are allocated.

    Returns
    -------
    LineMap
        Segments (x1, y1, x2, y2), world frame, m.
    dict
        ``occupied_cells``, ``cells_on_lines`` (cells within one cell of a kept segment's line, in its runs),
        ``segments``, ``total_length_m``.
    """
    # long: the Hough steps (vote, peak, walk along the line, split at gaps) share the grid's arrays; numpydoc
    res = grid.resolution
    n_occupied = int(np.count_nonzero(grid.occupied()))
    n_angles = math.ceil(180.0 / angle_step_deg)
    if n_occupied * n_angles > MAX_HOUGH_VOTES:
        # the votes take 24 bytes each (rho, bin, flat index): refuse before allocating them
        raise ConfigError(
            f"map lines: {n_occupied} occupied cells x {n_angles} angles = {n_occupied * n_angles} Hough votes, "
            f"expected at most {MAX_HOUGH_VOTES} (a coarser map, or no line extraction)"
        )
    cells = np.argwhere(grid.occupied())
    pts = grid.cell_centers(cells)
    n = pts.shape[0]
    ang = np.deg2rad(np.arange(0.0, 180.0, angle_step_deg))
    na = ang.shape[0]
    normals = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    rho = pts @ normals.T  # (n, na)
    rho_lo = float(rho.min(initial=0.0)) - res
    bins = np.floor((rho - rho_lo) / res).astype(np.int64)
    nb = int(bins.max(initial=0)) + 2
    flat = bins + (np.arange(na, dtype=np.int64) * nb)[None, :]
    acc = np.bincount(flat.ravel(), minlength=na * nb).astype(np.int64)
    alive = np.ones(n, dtype=bool)
    min_votes = max(2, math.floor(min_length_m / (res * math.sqrt(2.0))))
    tol = res
    segments: list[tuple[float, float, float, float]] = []
    on_lines = 0
    while True:
        k = int(np.argmax(acc))
        if acc[k] < min_votes:
            break
        ia, ib = divmod(k, nb)
        idx = np.flatnonzero(alive)
        voters = idx[bins[idx, ia] == ib]
        line_rho = rho_lo + (ib + 0.5) * res
        near = idx[np.abs(rho[idx, ia] - line_rho) <= tol]
        nrm, c = normals[ia], pts[near].mean(axis=0)
        if near.shape[0] >= 2:  # total least squares: the normal is the direction of least spread
            d = pts[near] - c
            _, vecs = np.linalg.eigh(d.T @ d)
            nrm = vecs[:, 0]
        sel = idx[np.abs((pts[idx] - c) @ nrm) <= tol]
        tangent = np.array([-nrm[1], nrm[0]])
        s = np.sort((pts[sel] - c) @ tangent)
        if s.size:
            cut = np.flatnonzero(np.diff(s) > max_gap_m)
            starts = np.r_[0, cut + 1]
            ends = np.r_[cut, s.size - 1]
            for i0, i1 in zip(starts, ends, strict=True):
                lo, hi = s[i0] - 0.5 * res, s[i1] + 0.5 * res
                if hi - lo >= min_length_m and i1 - i0 + 1 >= min_votes:
                    p1, p2 = c + lo * tangent, c + hi * tangent
                    segments.append((float(p1[0]), float(p1[1]), float(p2[0]), float(p2[1])))
                    on_lines += int(i1 - i0 + 1)
        gone = np.union1d(voters, sel)
        alive[gone] = False
        acc -= np.bincount(flat[gone].ravel(), minlength=na * nb)
    seg = np.array(segments, dtype=np.float64).reshape(-1, 4)
    lm = LineMap(seg)
    stats = {
        "occupied_cells": float(n),
        "cells_on_lines": float(on_lines),
        "segments": float(len(lm)),
        "total_length_m": float(lm.lengths().sum()),
    }
    return lm, stats
