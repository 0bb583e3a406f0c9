"""The occupancy grid, the map the ray caster, the laser filters and the synthetic worlds share.

It sits in the ground layer (it needs only numpy) so that :mod:`locbench.raycast` can type its grids without
importing the datasets above it; :mod:`locbench.datasets.dataset` re-exports it with the other map types.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class OccupancyGrid:
    """An occupancy grid in ROS map_server conventions.

    Attributes
    ----------
    occupancy : ndarray, shape (rows, cols)
        Occupancy probability in [0, 1]; -1 where unknown. Row ``i`` spans
        y in [origin_y + i*res, origin_y + (i+1)*res), column ``j`` spans x likewise (row 0 at the bottom,
        as in a nav_msgs/OccupancyGrid message, not as in the PGM image).
    resolution : float
        Cell side, m.
    origin : tuple of float
        World pose (x m, y m, theta rad) of the corner of cell (0, 0); theta must be 0 here.
    occupied_thresh, free_thresh : float
        Probabilities above / below which a cell counts as occupied / free.
    """

    occupancy: FloatArray
    resolution: float
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    occupied_thresh: float = 0.65
    free_thresh: float = 0.196

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.occupancy.shape[0]), int(self.occupancy.shape[1]))

    def occupied(self) -> npt.NDArray[np.bool_]:
        """Boolean mask of occupied cells."""
        return self.occupancy > self.occupied_thresh

    def free(self) -> npt.NDArray[np.bool_]:
        """Boolean mask of known free cells."""
        return (self.occupancy >= 0.0) & (self.occupancy < self.free_thresh)

    def world_to_cell(self, xy: npt.ArrayLike) -> npt.NDArray[np.int64]:
        """(row, col) indices of world points, shape (..., 2); may fall outside the grid."""
        p = np.asarray(xy, dtype=np.float64)
        col = np.floor((p[..., 0] - self.origin[0]) / self.resolution).astype(np.int64)
        row = np.floor((p[..., 1] - self.origin[1]) / self.resolution).astype(np.int64)
        return np.stack([row, col], axis=-1)

    def cell_centers(self, cells: npt.ArrayLike) -> FloatArray:
        """World (x, y) of the centres of (row, col) cells, shape (..., 2)."""
        c = np.asarray(cells, dtype=np.float64)
        x = self.origin[0] + (c[..., 1] + 0.5) * self.resolution
        y = self.origin[1] + (c[..., 0] + 0.5) * self.resolution
        return np.stack([x, y], axis=-1)
