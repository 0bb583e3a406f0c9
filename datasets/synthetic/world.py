"""A synthetic world's geometry, from which every map kind handed to filters is derived.

The geometry is a set of wall segments (zero thickness, world frame, m), point landmarks and a bounding
box. :meth:`World.world_map` turns it into the :class:`~locbench.datasets.dataset.WorldMap` that filters
get: an occupancy grid made by rasterising the walls (every cell a wall passes through is occupied),
a :class:`~locbench.datasets.dataset.LineMap` holding the same segments, and the landmarks with ids
0..n-1. Because all three come from one geometry, every filter localizes in the same world.

The grid origin is offset by half a cell from the bounds, so walls drawn on multiples of the resolution
run through cell centres and rasterise one cell thick (a laser ray-cast on the grid then sees a wall
half a cell, 2.5 cm at 0.05 m, in front of its line).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numba import njit

from locbench.core.errors import ConfigError
from locbench.datasets.dataset import Landmarks, LineMap, OccupancyGrid, WorldMap

logger = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]


def wall_with_doors(
    p: tuple[float, float], q: tuple[float, float], doors: Sequence[tuple[float, float]] = ()
) -> list[tuple[float, float, float, float]]:
    """Split the wall p -> q into segments around door gaps.

    Parameters
    ----------
    p, q : tuple of float
        Wall end points (x, y), m.
    doors : sequence of (offset, width)
        Each gap's centre as a distance from ``p`` along the wall and its width, m.

    Returns
    -------
    list of (x1, y1, x2, y2)
        The solid pieces, in order from ``p``.
    """
    p_ = np.asarray(p, dtype=np.float64)
    q_ = np.asarray(q, dtype=np.float64)
    length = float(np.hypot(*(q_ - p_)))
    u = (q_ - p_) / length
    cuts = sorted((c - w / 2.0, c + w / 2.0) for c, w in doors)
    pieces: list[tuple[float, float, float, float]] = []
    s = 0.0
    for a, b in cuts:
        if a < s - 1e-12 or b > length + 1e-12 or b <= a:
            raise ConfigError(f"door (offset {0.5 * (a + b)} m, width {b - a} m) does not fit wall {p}->{q}")
        if a > s:
            pieces.append((*(p_ + s * u), *(p_ + a * u)))
        s = b
    if s < length:
        pieces.append((*(p_ + s * u), *q_))
    return [tuple(float(v) for v in piece) for piece in pieces]  # type: ignore[misc]


def _segment_cells(x0: float, y0: float, x1: float, y1: float) -> list[tuple[int, int]]:
    """(row, col) of every cell a segment passes through, in grid units, 4-connected (Amanatides-Woo)."""
    i, j = math.floor(y0), math.floor(x0)
    i_end, j_end = math.floor(y1), math.floor(x1)
    dx, dy = x1 - x0, y1 - y0
    step_j = 1 if dx > 0 else -1
    step_i = 1 if dy > 0 else -1
    t_dx = abs(1.0 / dx) if dx != 0 else math.inf
    t_dy = abs(1.0 / dy) if dy != 0 else math.inf
    t_x = ((j + 1 - x0) if dx > 0 else (x0 - j)) * t_dx if dx != 0 else math.inf
    t_y = ((i + 1 - y0) if dy > 0 else (y0 - i)) * t_dy if dy != 0 else math.inf
    cells = [(i, j)]
    # One axis step at a time keeps the raster 4-connected, so no ray slips through a diagonal wall.
    for _ in range(abs(i_end - i) + abs(j_end - j)):
        if t_x < t_y:
            j += step_j
            t_x += t_dx
        else:
            i += step_i
            t_y += t_dy
        cells.append((i, j))
    return cells


@dataclass(frozen=True, eq=False)
class World:
    """The geometry of a synthetic world.

    Attributes
    ----------
    walls : ndarray, shape (n, 4)
        Wall segments (x1, y1, x2, y2), world frame, m; zero thickness (door gaps are missing pieces).
    landmarks : ndarray, shape (m, 2)
        Point landmark positions, world frame, m; landmark ``k`` gets id ``k``.
    bounds : tuple of float
        (x_min, y_min, x_max, y_max) of the region the map covers, m.
    name : str
        For logs and metadata.
    """

    walls: FloatArray
    landmarks: FloatArray
    bounds: tuple[float, float, float, float]
    name: str = "world"

    def __post_init__(self) -> None:
        w = np.asarray(self.walls, dtype=np.float64).reshape(-1, 4)
        lm = np.asarray(self.landmarks, dtype=np.float64).reshape(-1, 2)
        object.__setattr__(self, "walls", w)
        object.__setattr__(self, "landmarks", lm)
        x0, y0, x1, y1 = self.bounds
        if not (x1 > x0 and y1 > y0):
            raise ConfigError(f"world {self.name!r}: bounds must be (x_min, y_min, x_max, y_max), got {self.bounds}")

    # --- map kinds -------------------------------------------------------------------------------

    def occupancy_grid(self, resolution: float = 0.05, margin_m: float = 0.25) -> OccupancyGrid:
        """Rasterise the walls: 1.0 for every cell a wall passes through, 0.0 elsewhere.

        Parameters
        ----------
        resolution : float
            Cell side, m.
        margin_m : float
            Free border added around ``bounds``, m (rounded to whole cells).
        """
        if not resolution > 0:
            raise ConfigError(f"world {self.name!r}: resolution must be > 0 m, got {resolution}")
        pad = round(margin_m / resolution) + 0.5  # half a cell so walls on the resolution lattice hit cell centres
        ox = self.bounds[0] - pad * resolution
        oy = self.bounds[1] - pad * resolution
        cols = math.ceil((self.bounds[2] - ox) / resolution + pad)
        rows = math.ceil((self.bounds[3] - oy) / resolution + pad)
        occ = np.zeros((rows, cols), dtype=np.float64)
        for x1, y1, x2, y2 in self.walls:
            cells = _segment_cells(
                (x1 - ox) / resolution, (y1 - oy) / resolution, (x2 - ox) / resolution, (y2 - oy) / resolution
            )
            idx = np.asarray(cells, dtype=np.int64)
            ok = (idx[:, 0] >= 0) & (idx[:, 0] < rows) & (idx[:, 1] >= 0) & (idx[:, 1] < cols)
            if not np.all(ok):
                raise ConfigError(f"world {self.name!r}: wall {(x1, y1, x2, y2)} leaves the bounds {self.bounds}")
            occ[idx[:, 0], idx[:, 1]] = 1.0
        return OccupancyGrid(occupancy=occ, resolution=float(resolution), origin=(float(ox), float(oy), 0.0))

    def line_map(self) -> LineMap:
        """The wall segments as a :class:`LineMap`."""
        return LineMap(segments=self.walls.copy())

    def landmark_map(self) -> Landmarks:
        """The landmarks with ids 0..n-1."""
        return Landmarks(ids=np.arange(self.landmarks.shape[0], dtype=np.int64), xy=self.landmarks.copy())

    def world_map(self, resolution: float = 0.05) -> WorldMap:
        """Every map kind derived from this geometry: occupancy grid, landmarks and line map."""
        return WorldMap(occupancy=self.occupancy_grid(resolution), landmarks=self.landmark_map(), lines=self.line_map())

    # --- geometric queries used by the simulator -------------------------------------------------

    def wall_distance(self, xy: npt.ArrayLike) -> FloatArray:
        """Distance from each point (..., 2) to the nearest wall, m (inf without walls)."""
        p = np.asarray(xy, dtype=np.float64)
        if self.walls.shape[0] == 0:
            return np.full(p.shape[:-1], np.inf)
        a = self.walls[:, 0:2]
        d = self.walls[:, 2:4] - a
        rel = p[..., None, :] - a  # (..., n, 2)
        t = np.clip(np.sum(rel * d, axis=-1) / np.maximum(np.sum(d * d, axis=-1), 1e-300), 0.0, 1.0)
        closest = rel - t[..., None] * d
        return np.min(np.hypot(closest[..., 0], closest[..., 1]), axis=-1)

    def inside(self, xy: npt.ArrayLike, clearance_m: float = 0.0) -> npt.NDArray[np.bool_]:
        """True for points inside ``bounds`` shrunk by ``clearance_m``."""
        p = np.asarray(xy, dtype=np.float64)
        x0, y0, x1, y1 = self.bounds
        c = clearance_m
        return (p[..., 0] >= x0 + c) & (p[..., 0] <= x1 - c) & (p[..., 1] >= y0 + c) & (p[..., 1] <= y1 - c)

    def is_free(self, xy: npt.ArrayLike, clearance_m: float) -> npt.NDArray[np.bool_]:
        """True for points inside the bounds and at least ``clearance_m`` from every wall."""
        return self.inside(xy, clearance_m) & (self.wall_distance(xy) >= clearance_m)

    def path_is_free(self, p: npt.ArrayLike, q: npt.ArrayLike, clearance_m: float, step_m: float = 0.02) -> bool:
        """True when every point of the straight path p -> q keeps ``clearance_m`` from the walls."""
        p_ = np.asarray(p, dtype=np.float64)[:2]
        q_ = np.asarray(q, dtype=np.float64)[:2]
        n = max(2, math.ceil(float(np.hypot(*(q_ - p_))) / step_m) + 1)
        s = np.linspace(0.0, 1.0, n)[:, None]
        return bool(np.all(self.is_free(p_ + s * (q_ - p_), clearance_m)))

    def line_of_sight(
        self, origin: npt.ArrayLike, targets: npt.ArrayLike, tol_m: float = 1e-6
    ) -> npt.NDArray[np.bool_]:
        """True for each target (m, 2) that no wall crosses the segment from ``origin`` (2,) to it.

        A wall touching the segment within ``tol_m`` of either end does not block it, so a landmark
        mounted on a wall is visible from the wall's side it faces.
        """
        o = np.ascontiguousarray(np.asarray(origin, dtype=np.float64)[:2])
        t_xy = np.ascontiguousarray(np.asarray(targets, dtype=np.float64).reshape(-1, 2))
        if self.walls.shape[0] == 0 or t_xy.shape[0] == 0:
            return np.ones(t_xy.shape[0], dtype=bool)
        return _in_sight(o, t_xy, np.ascontiguousarray(self.walls, dtype=np.float64), float(tol_m))


@njit(cache=True)
def _in_sight(
    o: npt.NDArray[np.float64], t_xy: npt.NDArray[np.float64], walls: npt.NDArray[np.float64], tol_m: float
) -> npt.NDArray[np.bool_]:  # pragma: no cover - compiled
    """:meth:`World.line_of_sight` for targets ``t_xy`` (m, 2) seen from ``o`` (2,) past ``walls`` (n, 4): the
    sight line r = t - o meets wall a + v s at o + u r where u = ((a - o) x s) / (r x s), v = ((a - o) x r) / (r x s);
    it is blocked when u lies in (eps, 1 - eps), eps = ``tol_m`` / |r|, and v in [0, 1]. Compiled: the world's
    sensors ask this at every sighting, where the arrays' temporaries took a quarter of a world's build."""
    out = np.ones(t_xy.shape[0], dtype=np.bool_)
    for i in range(t_xy.shape[0]):
        r0, r1 = t_xy[i, 0] - o[0], t_xy[i, 1] - o[1]
        eps = tol_m / max(math.hypot(r0, r1), 1e-12)
        for j in range(walls.shape[0]):
            s0, s1 = walls[j, 2] - walls[j, 0], walls[j, 3] - walls[j, 1]
            denom = r0 * s1 - r1 * s0
            if not abs(denom) > 1e-12:  # parallel: no crossing
                continue
            ao0, ao1 = walls[j, 0] - o[0], walls[j, 1] - o[1]
            u = (ao0 * s1 - ao1 * s0) / denom  # along the sight line
            v = (ao0 * r1 - ao1 * r0) / denom  # along the wall
            if u > eps and u < 1.0 - eps and v >= 0.0 and v <= 1.0:
                out[i] = False
                break
    return out
