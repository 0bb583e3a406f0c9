"""Plain reference forms of the bound's parts, which the tests and benchmarks hold the library's against: the laser
information by central differences of full casts, for the one-traversal derivative of
:func:`locbench.evaluate.pcrb.laser_information`; the corner checks at every crossing, inside the traversal's loop,
for :func:`locbench.raycast.cast.dda_face`; one numpy call per sighting event, for the batched sightings; the
covariance recursion in numpy calls; and the whole bound from these (:func:`seven_cast_bound`)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit

from locbench.core.errors import ConfigError
from locbench.core.events import UNKNOWN_ID, LandmarkObservations, LaserScan, PoseFix, RangeObservations
from locbench.core.geometry import wrap_angle
from locbench.raycast.cast import _clip_to_grid, _dda_start, dda_face, face_cells
from locbench.registry import make_dataset


def differenced_laser_information(
    occ: np.ndarray,
    res: float,
    origin: tuple[float, float],
    poses: np.ndarray,
    mount: tuple[float, float, float],
    angles: np.ndarray,
    max_r: float,
    min_r: float,
    sigma: float,
    measured: np.ndarray,
    eps: float = 1e-5,
) -> np.ndarray:
    """The laser information by central differences of seven full casts per scan (six perturbed poses)."""
    from locbench.raycast.cast import cast_rays

    def cast(p: np.ndarray) -> np.ndarray:
        c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
        sensor = np.column_stack(
            [p[:, 0] + c * mount[0] - s * mount[1], p[:, 1] + s * mount[0] + c * mount[1], p[:, 2] + mount[2]]
        )
        return cast_rays(occ, res, origin, sensor, angles, max_r, method="dda")

    r0 = cast(poses)
    grads = np.empty((*r0.shape, 3))
    with np.errstate(invalid="ignore"):
        ok = (
            np.isfinite(r0)
            & (r0 >= min_r)
            & (r0 <= max_r)
            & np.isfinite(measured)
            & (np.abs(measured - r0) <= 5 * sigma)
        )
    for i in range(3):
        d = np.zeros(3)
        d[i] = eps
        rp, rm = cast(poses + d), cast(poses - d)
        with np.errstate(invalid="ignore"):
            fwd, bwd = (rp - r0) / eps, (r0 - rm) / eps
            ok &= np.isfinite(fwd) & np.isfinite(bwd) & (np.abs(fwd - bwd) <= 1e-4 * (1.0 + np.abs(fwd)))
            grads[..., i] = 0.5 * (fwd + bwd)
    grads[~ok] = 0.0
    return np.einsum("sbi,sbj->sij", grads, grads) / sigma**2


def scan_poses(world: str, every: int = 10) -> tuple[Any, ...]:
    """``laser_information``'s arguments (but the mount) for every ``every``-th scan of ``world`` (seed 0) at
    its true poses: (occupied, resolution, origin, poses, mount, angles, max range, min range, sigma, measured)."""
    ds = make_dataset(world, 0)
    grid = ds.world.occupancy
    assert grid is not None
    scans = [e for e in ds.events if isinstance(e, LaserScan)][::every]
    idx = np.searchsorted(ds.ground_truth.t, np.array([e.t for e in scans]) - 1e-6)
    e0 = scans[0]
    origin = (float(grid.origin[0]), float(grid.origin[1]))
    measured = np.stack([e.ranges for e in scans])
    return (grid.occupied(), grid.resolution, origin, ds.ground_truth.poses[idx], e0.sensor_pose, e0.angles,
            e0.range_max, e0.range_min, 0.01, measured)  # fmt: skip


def python_covariance_recursion(
    p0: np.ndarray, jacobians: np.ndarray, process_cov: np.ndarray, meas_info: np.ndarray
) -> np.ndarray:
    """:func:`locbench.evaluate.pcrb.covariance_recursion` as numpy calls per step."""
    eye = np.eye(p0.shape[0])
    out = np.empty((jacobians.shape[0] + 1, *p0.shape))
    p = out[0] = np.asarray(p0, dtype=np.float64)
    for k in range(jacobians.shape[0]):
        pp = jacobians[k] @ p @ jacobians[k].T + process_cov[k]
        p = np.linalg.solve(eye + pp @ meas_info[k], pp)
        p = out[k + 1] = 0.5 * (p + p.T)
    return out


def truth_index(dataset: Any, t: float) -> int:
    """The ground-truth index of one event at time ``t`` (s), looked up by itself."""
    gt_t = dataset.ground_truth.t
    k = int(np.searchsorted(gt_t, t - 1e-6))
    if k >= gt_t.shape[0] or abs(gt_t[k] - t) > 1e-6:
        raise ConfigError(f"dataset {dataset.name!r}: a measurement at t={t} s falls on no ground-truth time")
    return k


def associate_one(
    e: LandmarkObservations, pose: np.ndarray, xy: np.ndarray, by_id: dict[int, int], sr: float, sb: float
) -> list[int]:
    """The landmark rows of one sighting event, associated one row at a time: by id, else the nearest true range
    and bearing in Mahalanobis distance."""
    rows: list[int] = []
    d = xy - pose[None, 0:2]
    r_true = np.hypot(d[:, 0], d[:, 1])
    b_true = wrap_angle(np.arctan2(d[:, 1], d[:, 0]) - pose[2])
    for i, r, b in zip(e.ids.tolist(), e.ranges.tolist(), e.bearings.tolist(), strict=True):
        if i != UNKNOWN_ID:
            rows.append(by_id[int(i)])
        else:
            m2 = ((r_true - r) / sr) ** 2 + (wrap_angle(b_true - b) / sb) ** 2
            rows.append(int(np.argmin(m2)))
    return rows


def grouped_laser_information(dataset: Any, sigma_m: float, gt_poses: np.ndarray) -> np.ndarray:
    """``pcrb._laser_information`` with each scan's truth index looked up by itself (:func:`truth_index`) in place
    of the one search of ``pcrb._truth_indices``."""
    from locbench.evaluate import pcrb

    saved = pcrb._truth_indices
    pcrb._truth_indices = lambda ds, events: np.array([truth_index(ds, e.t) for e in events], dtype=np.intp)
    try:
        return pcrb._laser_information(dataset, sigma_m, gt_poses)
    finally:
        pcrb._truth_indices = saved


def per_event_information(
    dataset: Any, noise: Any, gt_poses: np.ndarray, laser: bool = True, events: Any = None
) -> np.ndarray:
    """``pcrb._measurement_information`` one event at a time: one ``range_bearing_information``, association and
    truth lookup per event, added in event order (``events`` is ignored: every row computes its own)."""
    from locbench.evaluate import pcrb

    gt_t = dataset.ground_truth.t
    use_laser = laser and noise.laser_sigma_m is not None and any(isinstance(e, LaserScan) for e in dataset.events)
    if use_laser:
        info = grouped_laser_information(
            dataset, pcrb._positive("laser sigma_m", noise.laser_sigma_m, dataset), gt_poses
        )
    else:
        info = np.zeros((gt_t.shape[0], 3, 3))
    lm_map = dataset.world.landmarks
    by_id: dict[int, int] = {} if lm_map is None else {int(i): r for r, i in enumerate(lm_map.ids.tolist())}
    for e in dataset.events:
        if not isinstance(e, LandmarkObservations | RangeObservations | PoseFix):
            continue
        if isinstance(e, LandmarkObservations) and use_laser and noise.sightings_from_laser:
            continue
        k = truth_index(dataset, e.t)
        pose = gt_poses[k]
        if isinstance(e, PoseFix):
            info[k] += pcrb.position_fix_information(pcrb._positive("fix sigma_xy_m", noise.fix_sigma_xy_m, dataset))
            continue
        if isinstance(e, LandmarkObservations):
            sr = pcrb._positive("landmark sigma_range_m", noise.landmark_sigma_range_m, dataset)
            sb = pcrb._positive("landmark sigma_bearing_rad", noise.landmark_sigma_bearing_rad, dataset)
            rows = associate_one(e, pose, lm_map.xy, by_id, sr, sb)
            info[k] += pcrb.range_bearing_information(pose, lm_map.xy[rows], sr, sb)
        else:
            sr = pcrb._positive("range sigma_m", noise.range_sigma_m, dataset)
            info[k] += pcrb.range_information(pose, lm_map.xy[[by_id[int(i)] for i in e.ids.tolist()]], sr)
    return info


def seven_cast_bound(dataset: Any) -> dict[str, np.ndarray]:
    """:func:`locbench.evaluate.pcrb.bound_covariances` from the plain forms: the laser term differenced from seven
    casts per scan, the covariance recursion in numpy, and each row computing its own odometry terms and its
    sightings one event at a time (:func:`per_event_information`): the whole-bound reference."""
    from locbench.evaluate import pcrb

    saved = pcrb.laser_information, pcrb.covariance_recursion, pcrb._measurement_information
    pcrb.laser_information, pcrb.covariance_recursion = differenced_laser_information, python_covariance_recursion
    pcrb._measurement_information = per_event_information
    try:
        out = {pcrb.BOUND_ALL: pcrb.pcrb_covariances(dataset)}
        if any(isinstance(e, LaserScan) for e in dataset.events):
            out[pcrb.BOUND_NO_LASER] = pcrb.pcrb_covariances(dataset, laser=False)
        return out
    finally:
        pcrb.laser_information, pcrb.covariance_recursion, pcrb._measurement_information = saved


@njit(cache=True, inline="always")
def _corner_occupied(occ: np.ndarray, vi: int, vj: int) -> bool:
    rows, cols = occ.shape
    for i in (vi - 1, vi):
        for j in (vj - 1, vj):
            if i < 0 or j < 0 or i >= rows or j >= cols or occ[i, j]:
                return True
    return False


@njit(cache=True, inline="always")
def _crossing_near(occ: np.ndarray, c: float, across: float, lim: float, line: int, vertical: bool) -> bool:
    v = math.floor(c)
    if (c - v) * across < lim and (_corner_occupied(occ, v, line) if vertical else _corner_occupied(occ, line, v)):
        return True
    w = v + 1
    return (w - c) * across < lim and (_corner_occupied(occ, w, line) if vertical else _corner_occupied(occ, line, w))


@njit(cache=True, inline="always")
def _vertex_near(occ: np.ndarray, px: float, py: float, lim: float) -> bool:
    vj = math.floor(px + 0.5)
    vi = math.floor(py + 0.5)
    return math.hypot(px - vj, py - vi) < lim and _corner_occupied(occ, vi, vj)


@njit(cache=True)
def stepwise_dda_face(
    occ: np.ndarray, gx: float, gy: float, dx: float, dy: float, t_lim: float, near0: float, near1: float
) -> tuple[float, int, bool]:
    """:func:`locbench.raycast.cast.dda_face` on the boolean grid with the corner checks at every crossing, inside
    the traversal's loop (the helpers above: the corner checks on the boolean grid)."""
    rows, cols = occ.shape
    t0, t1 = _clip_to_grid(rows, cols, gx, gy, dx, dy)
    if t0 >= t1 or t0 > t_lim:
        return math.inf, -1, True
    i, j, step_i, step_j, t_next_x, t_next_y, t_delta_x, t_delta_y = _dda_start(rows, cols, gx, gy, dx, dy, t0)
    near = t0 > 0.0 or _vertex_near(occ, gx, gy, 3.0 * near0)
    t = t0
    axis = -1
    while True:
        if occ[i, j]:
            near = near or axis < 0 or _vertex_near(occ, gx + t * dx, gy + t * dy, 3.0 * (near0 + near1 * t))
            return t, axis, near
        if t_next_x < t_next_y:
            t = t_next_x
            t_next_x += t_delta_x
            line = j + 1 if step_j > 0 else j
            j += step_j
            axis = 0
            if j < 0 or j >= cols:
                return math.inf, -1, True
            if not near:
                near = _crossing_near(occ, gy + t * dy, abs(dx), near0 + near1 * t, line, True)
        else:
            t = t_next_y
            t_next_y += t_delta_y
            line = i + 1 if step_i > 0 else i
            i += step_i
            axis = 1
            if i < 0 or i >= rows:
                return math.inf, -1, True
            if not near:
                near = _crossing_near(occ, gx + t * dx, abs(dy), near0 + near1 * t, line, False)
        if t > t_lim:
            return math.inf, -1, True


def faces_differ(occ: np.ndarray, rays: np.ndarray, t_lim: float, near0: float, near1: float) -> int:
    """How many of ``rays`` (k, 4: start x, y and direction x, y, grid units) get another (t, axis, near) from
    :func:`locbench.raycast.cast.dda_face` than from :func:`stepwise_dda_face` (an infinite t equals any other)."""
    return _faces_differ(occ, face_cells(occ), rays, t_lim, near0, near1)


@njit(cache=True)
def _faces_differ(
    occ: np.ndarray, cells: np.ndarray, rays: np.ndarray, t_lim: float, near0: float, near1: float
) -> int:
    bad = 0
    for k in range(rays.shape[0]):
        a = dda_face(cells, rays[k, 0], rays[k, 1], rays[k, 2], rays[k, 3], t_lim, near0, near1)
        b = stepwise_dda_face(occ, rays[k, 0], rays[k, 1], rays[k, 2], rays[k, 3], t_lim, near0, near1)
        same_t = a[0] == b[0] or (math.isinf(a[0]) and math.isinf(b[0]))
        bad += not same_t or a[1] != b[1] or a[2] != b[2]
    return bad
