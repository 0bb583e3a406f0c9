"""The bound's laser information by central differences of full casts (its version 1), the reference the
one-cast derivative of :func:`locbench.pcrb.laser_information` is tested and benchmarked against."""

from __future__ import annotations

from typing import Any

import numpy as np

from locbench.events import LaserScan
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
    """The laser information by central differences of seven full casts per scan (the bound's version 1)."""
    from locbench.raycast import cast_rays

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
