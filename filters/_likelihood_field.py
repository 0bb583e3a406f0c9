"""The likelihood-field laser model on an occupancy grid (Thrun, Burgard & Fox, Probabilistic Robotics, sec. 6.4).

Each beam endpoint that is not a max-range reading is scored by its distance d to the nearest occupied
cell of the map:

    p(z_k | x, m) = z_hit * N(d; 0, sigma_hit^2) + z_rand / z_max,

a Gaussian around the nearest obstacle mixed with a uniform density over the measurable range [0, z_max]
(algorithm ``likelihood_field_range_finder_model``, table 6.3). Max-range readings (``inf``: no return)
are skipped, as in that algorithm. Endpoints outside the grid take the distance ``max_dist_m``; distances
are clipped at ``max_dist_m`` as well (ROS AMCL's ``laser_likelihood_max_dist``), which only flattens the
far tail of the Gaussian.

The distance field is computed once per grid content with :func:`scipy.ndimage.distance_transform_edt`
over the occupied cells and cached (keyed by a hash of the cells, the resolution and the origin), because
every seed of a dataset rebuilds an identical grid. The per-cell log-likelihood is tabulated once per
(grid, model parameters), so scoring a beam is one table look-up; the scoring loop over particles and
beams is compiled with numba.

Grid conventions are those of :class:`locbench.datasets.dataset.OccupancyGrid` (ROS map_server): row ``i``
spans y in [oy + i*res, oy + (i+1)*res), column ``j`` spans x likewise.
"""

from __future__ import annotations

import hashlib
import logging
import math
import threading
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numba import njit
from scipy import ndimage

from locbench.datasets.dataset import OccupancyGrid
from locbench.raycast.beams import beam_endpoints

logger = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]

#: Distinct grids whose distance field is kept in memory (a benchmark sweep uses a handful of worlds).
_CACHE_SIZE = 8
_cache: OrderedDict[str, FloatArray] = OrderedDict()
_cache_lock = threading.Lock()


def _grid_key(grid: OccupancyGrid) -> str:
    occ = np.ascontiguousarray(grid.occupied())
    h = hashlib.sha1(occ.tobytes(), usedforsecurity=False)
    h.update(repr((occ.shape, float(grid.resolution), tuple(float(v) for v in grid.origin))).encode())
    return h.hexdigest()


def distance_field(grid: OccupancyGrid) -> FloatArray:
    """Euclidean distance from each cell centre to the nearest occupied cell centre, m, shape (rows, cols).

    0 on occupied cells; ``inf`` everywhere when the grid has no occupied cell. Cached per grid content;
    the returned array is read-only.
    """
    if grid.origin[2] != 0.0:
        raise ValueError(f"grid.origin theta must be 0 (rotated grids are not supported), got {grid.origin[2]}")
    key = _grid_key(grid)
    with _cache_lock:
        hit = _cache.get(key)
        if hit is not None:
            _cache.move_to_end(key)
            return hit
    occ = grid.occupied()
    if not occ.any():
        dist = np.full(occ.shape, np.inf)
    else:
        # distance_transform_edt measures to the nearest zero, so the occupied cells are the zeros.
        dist = ndimage.distance_transform_edt(~occ, sampling=grid.resolution).astype(np.float64)
    dist.setflags(write=False)
    with _cache_lock:
        _cache[key] = dist
        while len(_cache) > _CACHE_SIZE:
            _cache.popitem(last=False)
    logger.debug("distance field of a %dx%d grid computed", occ.shape[0], occ.shape[1])
    return dist


@dataclass(frozen=True, eq=False)
class LikelihoodField:
    """A tabulated likelihood-field beam model on one grid.

    Attributes
    ----------
    log_p : ndarray, shape (rows, cols)
        log p(z_k | x, m) of a beam endpoint falling in each cell, log(1/m).
    log_p_outside : float
        The same for an endpoint outside the grid (distance ``max_dist_m``).
    resolution : float
        Cell side, m.
    origin_xy : tuple of float
        World (x, y) of the corner of cell (0, 0), m.
    z_hit, z_rand, sigma_hit_m, max_dist_m, z_max_m : float
        The model parameters the table was made with.
    """

    log_p: FloatArray
    log_p_outside: float
    resolution: float
    origin_xy: tuple[float, float]
    z_hit: float
    z_rand: float
    sigma_hit_m: float
    max_dist_m: float
    z_max_m: float


def beam_log_likelihood(
    distance_m: npt.ArrayLike, z_hit: float, z_rand: float, sigma_hit_m: float, z_max_m: float
) -> FloatArray:
    """log(z_hit N(d; 0, sigma_hit^2) + z_rand / z_max) for endpoint distances ``d`` (m); Prob. Rob. table 6.3."""
    d = np.asarray(distance_m, dtype=np.float64)
    gauss = np.exp(-0.5 * (d / sigma_hit_m) ** 2) / (math.sqrt(2.0 * math.pi) * sigma_hit_m)
    return np.log(z_hit * gauss + z_rand / z_max_m)


def make_likelihood_field(
    grid: OccupancyGrid,
    *,
    z_hit: float,
    z_rand: float,
    sigma_hit_m: float,
    max_dist_m: float,
    z_max_m: float,
) -> LikelihoodField:
    """Tabulate the likelihood-field model on ``grid``.

    Parameters
    ----------
    grid : OccupancyGrid
        The map; cells above ``occupied_thresh`` are obstacles.
    z_hit, z_rand : float
        Mixture weights of the Gaussian hit and the uniform random term (>= 0, not both 0).
    sigma_hit_m : float
        Standard deviation of the hit Gaussian, m.
    max_dist_m : float
        Distances are clipped here, and endpoints outside the grid get it, m.
    z_max_m : float
        Maximum range of the sensor (the support of the uniform term), m.
    """
    if not (z_hit >= 0.0 and z_rand >= 0.0 and z_hit + z_rand > 0.0):
        raise ValueError(f"z_hit and z_rand must be >= 0 and not both 0, got {z_hit}, {z_rand}")
    if not (sigma_hit_m > 0.0 and max_dist_m > 0.0 and z_max_m > 0.0 and math.isfinite(z_max_m)):
        raise ValueError(
            f"sigma_hit_m, max_dist_m and z_max_m must be finite and > 0, got {sigma_hit_m}, {max_dist_m}, {z_max_m}"
        )
    dist = np.minimum(distance_field(grid), max_dist_m)
    with np.errstate(divide="ignore"):  # z_rand = 0 with a far endpoint is a legitimate log(0) = -inf
        log_p = beam_log_likelihood(dist, z_hit, z_rand, sigma_hit_m, z_max_m)
        outside = float(beam_log_likelihood(max_dist_m, z_hit, z_rand, sigma_hit_m, z_max_m))
    return LikelihoodField(
        log_p=np.ascontiguousarray(log_p),
        log_p_outside=outside,
        resolution=float(grid.resolution),
        origin_xy=(float(grid.origin[0]), float(grid.origin[1])),
        z_hit=z_hit,
        z_rand=z_rand,
        sigma_hit_m=sigma_hit_m,
        max_dist_m=max_dist_m,
        z_max_m=z_max_m,
    )


@njit(cache=True)
def _score(
    log_p: FloatArray,
    log_p_outside: float,
    inv_res: float,
    ox: float,
    oy: float,
    poses: FloatArray,
    end_x: FloatArray,
    end_y: FloatArray,
) -> FloatArray:
    rows = log_p.shape[0]
    cols = log_p.shape[1]
    n = poses.shape[0]
    nb = end_x.shape[0]
    out = np.empty(n)
    for p in range(n):
        c = math.cos(poses[p, 2])
        s = math.sin(poses[p, 2])
        gx = (poses[p, 0] - ox) * inv_res
        gy = (poses[p, 1] - oy) * inv_res
        acc = 0.0
        for b in range(nb):
            # endpoint in grid units: robot pose (+) the endpoint in the robot frame
            fx = gx + (c * end_x[b] - s * end_y[b]) * inv_res
            fy = gy + (s * end_x[b] + c * end_y[b]) * inv_res
            if fx >= 0.0 and fy >= 0.0 and fx < cols and fy < rows:
                acc += log_p[int(fy), int(fx)]
            else:
                acc += log_p_outside
        out[p] = acc
    return out


def scan_endpoints_robot_frame(
    ranges: npt.ArrayLike, angles: npt.ArrayLike, sensor_pose: tuple[float, float, float]
) -> tuple[FloatArray, FloatArray]:
    """Beam endpoints (x, y) in the robot frame, m, for finite ``ranges`` at sensor-frame ``angles`` (rad), the
    sensor mounted at ``sensor_pose`` (:func:`locbench.raycast.beams.beam_endpoints`)."""
    return beam_endpoints(ranges, angles, sensor_pose)


def log_likelihood(
    field: LikelihoodField, poses: npt.ArrayLike, end_x: npt.ArrayLike, end_y: npt.ArrayLike
) -> FloatArray:
    """Sum over beams of log p(z_k | x, m) for each pose (Prob. Rob. table 6.3, in logs).

    Parameters
    ----------
    field : LikelihoodField
    poses : array-like, shape (N, 3)
        Robot poses (x m, y m, theta rad), world frame.
    end_x, end_y : array-like, shape (B,)
        Beam endpoints in the robot frame, m (max-range readings already removed; see
        :func:`scan_endpoints_robot_frame`).

    Returns
    -------
    ndarray, shape (N,)
        Log-likelihood of the scan at each pose, sum of B terms in log(1/m).
    """
    p = np.ascontiguousarray(poses, dtype=np.float64)
    ex = np.ascontiguousarray(end_x, dtype=np.float64)
    ey = np.ascontiguousarray(end_y, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"poses must have shape (N, 3), got {p.shape}")
    if ex.shape != ey.shape or ex.ndim != 1:
        raise ValueError(f"end_x and end_y must be 1-D of equal length, got {ex.shape} and {ey.shape}")
    ox, oy = field.origin_xy
    return _score(field.log_p, field.log_p_outside, 1.0 / field.resolution, ox, oy, p, ex, ey)
