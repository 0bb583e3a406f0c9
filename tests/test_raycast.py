"""The numba ray caster against analytic cases and the slow numpy reference."""

from __future__ import annotations

import math

import numpy as np
import pytest

from locbench.datasets.base import OccupancyGrid
from locbench.datasets.synthetic.scenarios import office_world
from locbench.raycast import cast_rays, cast_rays_reference, cast_scan

RES = 0.05


def box_grid(rows: int = 40, cols: int = 80) -> np.ndarray:
    """A 4 m x 2 m box (at 0.05 m) with one-cell walls on its border."""
    occ = np.zeros((rows, cols), dtype=bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    return occ


@pytest.mark.parametrize("parallel", [False, True])
def test_axis_aligned_rays_hit_walls_at_known_distance(parallel: bool) -> None:
    occ = box_grid()
    pose = np.array([[1.0, 1.0, 0.0]])
    angles = np.array([0.0, math.pi / 2, math.pi, -math.pi / 2])
    r = cast_rays(occ, RES, (0.0, 0.0), pose, angles, 10.0, parallel=parallel)
    # east wall cells start at x = 79 * 0.05, north at y = 39 * 0.05, west/south walls end at 0.05
    np.testing.assert_allclose(r[0], [79 * RES - 1.0, 39 * RES - 1.0, 1.0 - RES, 1.0 - RES], atol=1e-12)


def test_diagonal_ray_enters_wall_at_the_analytic_point() -> None:
    occ = box_grid()
    r = cast_rays(occ, RES, (0.0, 0.0), [1.0, 1.0, math.pi / 4], [0.0], 10.0)
    # y reaches the north wall (y = 1.95) before x reaches the east wall
    assert r[0, 0] == pytest.approx((39 * RES - 1.0) * math.sqrt(2.0), abs=1e-9)


def test_origin_offset_and_wall_in_the_middle() -> None:
    occ = np.zeros((20, 100), dtype=bool)
    occ[:, 60] = True  # wall cells span x in [ox + 3.0, ox + 3.05)
    ox, oy = -1.3, 2.2
    r = cast_rays(occ, RES, (ox, oy), [ox + 0.5, oy + 0.5, 0.0], [0.0, math.pi], 10.0)
    assert r[0, 0] == pytest.approx(2.5, abs=1e-9)
    assert r[0, 1] == np.inf  # nothing to the west: the ray leaves the grid


def test_max_range_and_rays_leaving_the_grid() -> None:
    occ = box_grid()
    r = cast_rays(occ, RES, (0.0, 0.0), [1.0, 1.0, 0.0], [0.0], 2.95)
    assert r[0, 0] == pytest.approx(2.95)
    assert cast_rays(occ, RES, (0.0, 0.0), [1.0, 1.0, 0.0], [0.0], 2.94)[0, 0] == np.inf
    empty = np.zeros((10, 10), dtype=bool)
    assert np.all(np.isinf(cast_rays(empty, RES, (0.0, 0.0), [0.2, 0.2, 0.3], np.linspace(-3, 3, 7), 100.0)))


def test_rays_from_outside_the_grid_enter_it() -> None:
    occ = box_grid()
    r = cast_rays(occ, RES, (0.0, 0.0), [[-1.0, 1.0, 0.0], [-1.0, 1.0, math.pi]], [0.0], 10.0)
    assert r[0, 0] == pytest.approx(1.0)
    assert r[1, 0] == np.inf


def test_start_inside_an_occupied_cell_is_zero() -> None:
    occ = box_grid()
    r = cast_rays(occ, RES, (0.0, 0.0), [0.02, 0.5, 0.0], np.linspace(-3, 3, 9), 10.0)
    assert np.all(r == 0.0)


def test_agrees_with_reference_on_random_poses_in_a_real_grid() -> None:
    grid = office_world().occupancy_grid(RES)
    rng = np.random.default_rng(7)
    free = np.argwhere(~grid.occupied())
    cells = free[rng.choice(free.shape[0], 60, replace=False)]
    xy = grid.cell_centers(cells) + rng.uniform(-0.02, 0.02, (60, 2))
    poses = np.column_stack([xy, rng.uniform(-math.pi, math.pi, 60)])
    angles = np.linspace(-2.0, 2.0, 41)
    fast = cast_scan(grid, poses, angles, 6.0)
    ref = cast_rays_reference(grid.occupied(), RES, grid.origin[:2], poses, angles, 6.0, step_fraction=0.02)
    both = np.isfinite(fast) & np.isfinite(ref)
    assert np.mean(np.isfinite(fast) == np.isfinite(ref)) > 0.99
    diff = np.abs(fast[both] - ref[both])
    assert np.mean(diff <= RES) > 0.99  # within one cell
    # the exact traversal never reports a hit later than the sampled one (it may catch a clipped corner)
    assert np.all(fast[both] <= ref[both] + 0.02 * RES + 1e-9)


def test_parallel_and_serial_kernels_are_identical() -> None:
    grid = office_world().occupancy_grid(RES)
    rng = np.random.default_rng(3)
    poses = np.column_stack([rng.uniform(0.5, 19.5, 300), rng.uniform(0.5, 14.5, 300), rng.uniform(-3, 3, 300)])
    angles = np.linspace(-2.1, 2.1, 61)
    a = cast_rays(grid.occupied(), RES, grid.origin[:2], poses, angles, 8.0, parallel=False)
    b = cast_rays(grid.occupied(), RES, grid.origin[:2], poses, angles, 8.0, parallel=True)
    np.testing.assert_array_equal(a, b)


def test_cast_scan_single_pose_shape_and_bad_inputs() -> None:
    grid = OccupancyGrid(occupancy=box_grid().astype(float), resolution=RES)
    assert cast_scan(grid, [1.0, 1.0, 0.0], np.zeros(5), 5.0).shape == (5,)
    with pytest.raises(ValueError, match="poses must have shape"):
        cast_rays(box_grid(), RES, (0.0, 0.0), np.zeros((2, 2)), [0.0], 5.0)
    with pytest.raises(ValueError, match="resolution"):
        cast_rays(box_grid(), 0.0, (0.0, 0.0), [0.0, 0.0, 0.0], [0.0], 5.0)
