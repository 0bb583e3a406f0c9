"""The numba ray caster against analytic cases and a plain sampled reference."""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from locbench.core.grid import OccupancyGrid
from locbench.datasets.synthetic.scenarios import office_world
from locbench.raycast import _sectors as _raycast_sectors
from locbench.raycast import cast as raycast
from locbench.raycast.cast import (
    FIELD_OCCUPIED,
    JUMP_UNIT_CELLS,
    cast_rays,
    cast_scan,
    march_field,
    march_sector_field,
)

RES = 0.05


def box_grid(rows: int = 40, cols: int = 80) -> np.ndarray:
    """A 4 m x 2 m box (at 0.05 m) with one-cell walls on its border."""
    occ = np.zeros((rows, cols), dtype=bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    return occ


def sampled_ranges(
    occupied: np.ndarray,
    resolution: float,
    origin_xy: tuple[float, float],
    poses: np.ndarray,
    angles: np.ndarray,
    max_range: float,
    step_fraction: float = 0.05,
) -> np.ndarray:
    """A plain reference of :func:`cast_rays`, its arguments (poses (N, 3), angles (B,)) and its ranges (N, B), m.

    Samples each beam every ``step_fraction * resolution`` metres and returns the distance of the first sample
    inside an occupied cell, so it overestimates the exact range by less than one step and may miss a cell that a
    beam only clips at a corner.
    """
    occ = np.asarray(occupied, dtype=bool)
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    a = np.asarray(angles, dtype=np.float64).reshape(-1)
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
    first = np.argmax(hit, axis=-1)
    return np.where(hit.any(axis=-1), s[first], np.inf)


METHODS = ["march", "dda"]


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("parallel", [False, True])
def test_axis_aligned_rays_hit_walls_at_known_distance(parallel: bool, method: str) -> None:
    occ = box_grid()
    pose = np.array([[1.0, 1.0, 0.0]])
    angles = np.array([0.0, math.pi / 2, math.pi, -math.pi / 2])
    r = cast_rays(occ, RES, (0.0, 0.0), pose, angles, 10.0, parallel=parallel, method=method)
    # east wall cells start at x = 79 * 0.05, north at y = 39 * 0.05, west/south walls end at 0.05
    np.testing.assert_allclose(r[0], [79 * RES - 1.0, 39 * RES - 1.0, 1.0 - RES, 1.0 - RES], atol=1e-12)


@pytest.mark.parametrize("method", METHODS)
def test_diagonal_ray_enters_wall_at_the_analytic_point(method: str) -> None:
    occ = box_grid()
    r = cast_rays(occ, RES, (0.0, 0.0), [1.0, 1.0, math.pi / 4], [0.0], 10.0, method=method)
    # y reaches the north wall (y = 1.95) before x reaches the east wall
    assert r[0, 0] == pytest.approx((39 * RES - 1.0) * math.sqrt(2.0), abs=1e-9)


@pytest.mark.parametrize("method", METHODS)
def test_origin_offset_and_wall_in_the_middle(method: str) -> None:
    occ = np.zeros((20, 100), dtype=bool)
    occ[:, 60] = True  # wall cells span x in [ox + 3.0, ox + 3.05)
    ox, oy = -1.3, 2.2
    r = cast_rays(occ, RES, (ox, oy), [ox + 0.5, oy + 0.5, 0.0], [0.0, math.pi], 10.0, method=method)
    assert r[0, 0] == pytest.approx(2.5, abs=1e-9)
    assert r[0, 1] == np.inf  # nothing to the west: the ray leaves the grid


@pytest.mark.parametrize("method", METHODS)
def test_max_range_and_rays_leaving_the_grid(method: str) -> None:
    occ = box_grid()
    r = cast_rays(occ, RES, (0.0, 0.0), [1.0, 1.0, 0.0], [0.0], 2.95, method=method)
    assert r[0, 0] == pytest.approx(2.95)
    assert cast_rays(occ, RES, (0.0, 0.0), [1.0, 1.0, 0.0], [0.0], 2.94, method=method)[0, 0] == np.inf
    empty = np.zeros((10, 10), dtype=bool)
    r = cast_rays(empty, RES, (0.0, 0.0), [0.2, 0.2, 0.3], np.linspace(-3, 3, 7), 100.0, method=method)
    assert np.all(np.isinf(r))


@pytest.mark.parametrize("method", METHODS)
def test_rays_from_outside_the_grid_enter_it(method: str) -> None:
    occ = box_grid()
    r = cast_rays(occ, RES, (0.0, 0.0), [[-1.0, 1.0, 0.0], [-1.0, 1.0, math.pi]], [0.0], 10.0, method=method)
    assert r[0, 0] == pytest.approx(1.0)
    assert r[1, 0] == np.inf


@pytest.mark.parametrize("method", METHODS)
def test_start_inside_an_occupied_cell_is_zero(method: str) -> None:
    occ = box_grid()
    r = cast_rays(occ, RES, (0.0, 0.0), [0.02, 0.5, 0.0], np.linspace(-3, 3, 9), 10.0, method=method)
    assert np.all(r == 0.0)


def test_agrees_with_reference_on_random_poses_in_a_real_grid() -> None:
    grid = office_world().occupancy_grid(RES)
    rng = np.random.default_rng(7)
    free = np.argwhere(~grid.occupied())
    cells = free[rng.choice(free.shape[0], 60, replace=False)]
    xy = grid.cell_centers(cells) + rng.uniform(-0.02, 0.02, (60, 2))
    poses = np.column_stack([xy, rng.uniform(-math.pi, math.pi, 60)])
    angles = np.linspace(-2.0, 2.0, 41)
    ref = sampled_ranges(grid.occupied(), RES, grid.origin[:2], poses, angles, 6.0, step_fraction=0.05)
    for method in METHODS:  # the reference is slow: one sampling for both kernels
        fast = cast_scan(grid, poses, angles, 6.0, method=method)
        both = np.isfinite(fast) & np.isfinite(ref)
        assert np.mean(np.isfinite(fast) == np.isfinite(ref)) > 0.99
        diff = np.abs(fast[both] - ref[both])
        assert np.mean(diff <= RES) > 0.99  # within one cell
        # the exact traversal never reports a hit later than the sampled one (it may catch a clipped corner)
        assert np.all(fast[both] <= ref[both] + 0.05 * RES + 1e-9)


@pytest.mark.parametrize("method", METHODS)
def test_parallel_and_serial_kernels_are_identical(method: str) -> None:
    grid = office_world().occupancy_grid(RES)
    rng = np.random.default_rng(3)
    poses = np.column_stack([rng.uniform(0.5, 19.5, 300), rng.uniform(0.5, 14.5, 300), rng.uniform(-3, 3, 300)])
    angles = np.linspace(-2.1, 2.1, 61)
    a = cast_rays(grid.occupied(), RES, grid.origin[:2], poses, angles, 8.0, parallel=False, method=method)
    b = cast_rays(grid.occupied(), RES, grid.origin[:2], poses, angles, 8.0, parallel=True, method=method)
    np.testing.assert_array_equal(a, b)


def test_serial_and_threaded_gradient_builds_are_identical() -> None:
    """The bound's one traversal per beam (ranges, derivatives and the smooth flags) from both builds of its
    kernel, on random sensor poses in the office grid."""
    grid = office_world().occupancy_grid(RES)
    rng = np.random.default_rng(4)
    n = 200
    sensors = np.column_stack([rng.uniform(0.5, 19.5, n), rng.uniform(0.5, 14.5, n), rng.uniform(-3, 3, n)])
    headings = sensors[:, 2] - 0.05
    angles = np.linspace(-2.1, 2.1, 61)
    cells = raycast.face_cells(grid.occupied())
    outs = []
    for kernel in (raycast._gradients_serial, raycast._gradients_threads):
        ranges, grads, smooth = np.empty((n, 61)), np.zeros((n, 61, 3)), np.zeros((n, 61), dtype=bool)
        kernel(cells, RES, 0.0, 0.0, sensors, headings, 0.1, -0.02, angles, 8.0, 1e-5, ranges, grads, smooth)
        outs.append((ranges, grads, smooth))
    for a, b in zip(*outs, strict=True):
        np.testing.assert_array_equal(a, b)
    assert outs[0][2].mean() > 0.5  # most beams take the closed form


_BUILD_SCRIPT = """
import sys
import numba
import numpy as np
from locbench.raycast import cast
occ = np.zeros((30, 30), dtype=bool)
occ[0] = occ[-1] = occ[:, 0] = occ[:, -1] = True
poses = np.array([[0.7, 0.8, 0.3], [1.0, 0.4, -2.0]])
kernel = cast._dda_threads if sys.argv[1] == "threads" else cast._dda_serial
ranges = kernel(occ, 0.05, 0.0, 0.0, poses, np.linspace(-3.0, 3.0, 50), 5.0)
try:
    numba.threading_layer()
    threads = True
except ValueError:  # not initialized: nothing ran on numba's threads
    threads = False
print(threads, repr(float(ranges.sum())))
"""


def test_the_two_builds_of_a_kernel_are_cached_apart(tmp_path: Path) -> None:
    """numba keys its on-disk cache on a function's name and code, not on ``parallel``: with the threaded build
    cached first, the serial build, compiled and then loaded from the cache in fresh processes, starts no thread
    and gives the threaded build's ranges."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    out = [
        subprocess.run(
            [sys.executable, "-c", _BUILD_SCRIPT, build], env=env, capture_output=True, text=True, check=True
        ).stdout.split()
        for build in ("threads", "serial", "serial")
    ]
    assert [o[0] for o in out] == ["True", "False", "False"]
    assert out[0][1] == out[1][1] == out[2][1]
    assert any(tmp_path.rglob("*_dda_rays_threads*.nbi")) and any(tmp_path.rglob("*_dda_rays-*.nbi"))


def test_cast_scan_single_pose_shape_and_bad_inputs() -> None:
    grid = OccupancyGrid(occupancy=box_grid().astype(float), resolution=RES)
    assert cast_scan(grid, [1.0, 1.0, 0.0], np.zeros(5), 5.0).shape == (5,)
    with pytest.raises(ValueError, match="poses must have shape"):
        cast_rays(box_grid(), RES, (0.0, 0.0), np.zeros((2, 2)), [0.0], 5.0)
    with pytest.raises(ValueError, match="resolution"):
        cast_rays(box_grid(), 0.0, (0.0, 0.0), [0.0, 0.0, 0.0], [0.0], 5.0)
    with pytest.raises(ValueError, match="method"):
        cast_scan(grid, [1.0, 1.0, 0.0], np.zeros(5), 5.0, method="bresenham")  # type: ignore[arg-type]


def random_boxes_grid(seed: int, n_boxes: int = 80) -> np.ndarray:
    """A 400 x 400 grid (20 m at 0.05 m) with a border wall and random boxes, some touching."""
    rng = np.random.default_rng(seed)
    occ = np.zeros((400, 400), dtype=bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    for _ in range(n_boxes):
        h, w = rng.integers(1, 25, 2)
        i, j = rng.integers(1, 380, 2)
        occ[i : i + h, j : j + w] = True
    return occ


def random_poses(occ: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    free = np.argwhere(~occ)
    cells = free[rng.choice(free.shape[0], n, replace=False)]
    xy = (cells[:, ::-1] + rng.uniform(0.0, 1.0, (n, 2))) * RES
    return np.column_stack([xy, rng.uniform(-math.pi, math.pi, n)])


@pytest.mark.parametrize("seed", [0, 1])
def test_march_equals_the_exact_traversal_on_random_boxes(seed: int) -> None:
    occ = random_boxes_grid(seed)
    rng = np.random.default_rng(100 + seed)
    poses = random_poses(occ, 300, rng)
    # include poses outside the grid and a few exactly axis-parallel / diagonal beams
    poses = np.vstack([poses, [[-0.7, 3.3, 0.2], [21.0, 7.0, math.pi], [5.0, -2.0, 1.4]]])
    angles = np.concatenate([np.linspace(-math.pi, math.pi, 90, endpoint=False), [0.0, math.pi / 4, math.pi / 2]])
    dda = cast_rays(occ, RES, (0.0, 0.0), poses, angles, 12.0, method="dda")
    march = cast_rays(occ, RES, (0.0, 0.0), poses, angles, 12.0, method="march")
    same_inf = np.isinf(dda) == np.isinf(march)
    assert np.mean(same_inf) > 0.9999  # only a beam through a cell corner may pick the other cell
    both = np.isfinite(dda) & np.isfinite(march)
    close = np.abs(dda[both] - march[both]) <= 1e-9
    assert np.mean(close) > 0.9999
    assert np.mean(np.isfinite(dda)) > 0.9  # the test exercises hits, not only misses


def test_march_field_is_a_lower_bound_on_the_clearance_of_every_cell() -> None:
    occ = random_boxes_grid(3, n_boxes=6)[:60, :60].copy()
    field = march_field(occ)
    assert field.dtype == np.uint8
    assert np.all((field == FIELD_OCCUPIED) == occ)
    oi, oj = np.nonzero(occ)
    for i, j in np.argwhere(~occ)[::7]:
        # distance between the unit squares of (i, j) and of every occupied cell, cells
        gap = np.hypot(np.maximum(np.abs(oi - i) - 1, 0), np.maximum(np.abs(oj - j) - 1, 0)).min()
        jump = field[i, j] * JUMP_UNIT_CELLS
        assert jump <= gap
        assert field[i, j] == 0 or jump > gap - JUMP_UNIT_CELLS - 1e-9  # and not needlessly small


def test_grid_without_obstacles_and_auto_method() -> None:
    empty = np.zeros((50, 50), dtype=bool)
    assert np.all(march_field(empty) == FIELD_OCCUPIED - 1)
    r = cast_rays(empty, RES, (0.0, 0.0), [1.0, 1.0, 0.3], np.linspace(-3, 3, 11), 100.0, method="march")
    assert np.all(np.isinf(r))
    # auto marches only when the rays pay for the field
    occ = box_grid()
    few = cast_rays(occ, RES, (0.0, 0.0), [1.0, 1.0, 0.1], [0.0], 10.0, method="auto")
    many = cast_rays(occ, RES, (0.0, 0.0), np.tile([1.0, 1.0, 0.1], (2000, 1)), [0.0], 10.0, method="auto")
    np.testing.assert_allclose(few[0, 0], many[:, 0], atol=1e-12)


def test_cast_scan_keeps_the_field_with_the_grid() -> None:
    grid = OccupancyGrid(occupancy=box_grid().astype(float), resolution=RES)
    cast_scan(grid, [1.0, 1.0, 0.0], np.zeros(3), 5.0)
    arrays = raycast._GRID_CACHE[grid]
    cast_scan(grid, [1.5, 1.0, 0.0], np.zeros(3), 5.0)
    assert raycast._GRID_CACHE[grid] is arrays
    np.testing.assert_array_equal(arrays.field, march_field(grid.occupied()))
    # one-pose scans keep the octant planes too
    planes = raycast._SECTOR_CACHE[grid]
    cast_scan(grid, np.array([1.2, 0.8, 0.3]), np.zeros(3), 5.0)
    assert raycast._SECTOR_CACHE[grid] is planes
    np.testing.assert_array_equal(planes, march_sector_field(grid.occupied()).reshape(-1))


def _lattice_case() -> tuple[np.ndarray, OccupancyGrid, np.ndarray, np.ndarray, np.ndarray]:
    """A walled 70 x 90 room, poses on a lattice of cell corners, beams every 5 deg, and their exact ranges."""
    occ = np.zeros((70, 90), dtype=bool)
    occ[5, 5:85] = occ[65, 5:85] = True
    occ[5:66, 5] = occ[5:66, 85] = True
    grid = OccupancyGrid(occupancy=occ.astype(float), resolution=0.05, origin=(-0.25, -0.25, 0.0))
    lattice = np.array([[x, y, 0.0] for x in np.arange(0.0, 4.0, 0.25) for y in np.arange(0.0, 3.0, 0.25)])
    angles = np.deg2rad(np.arange(0.0, 360.0, 5.0))
    exact = cast_rays(occ, 0.05, (-0.25, -0.25), lattice, angles, 8.0, method="dda")
    return occ, grid, lattice, angles, exact


def _assert_lattice_ranges(marched: np.ndarray, exact: np.ndarray) -> None:
    both_inf = np.isinf(exact) & np.isinf(marched)
    np.testing.assert_allclose(np.where(both_inf, 0.0, marched), np.where(both_inf, 0.0, exact), atol=1e-9)


def test_march_terminates_on_lattice_poses_along_cell_boundaries() -> None:
    """Regression: beams starting on cell corners, (nearly) axis-parallel, next to a wall used to loop forever.

    cos(270 deg) is -1.8e-16, not 0: the beam runs along a grid line and flooring its position kept it in the
    same cell while the clearance there was 0. The march now steps the cell index in that case.
    """
    occ, _, lattice, angles, exact = _lattice_case()
    marched = cast_rays(occ, 0.05, (-0.25, -0.25), lattice, angles, 8.0, method="march")
    _assert_lattice_ranges(marched, exact)


def test_cast_scan_fast_path_matches_the_general_path_when_angles_change() -> None:
    """The one-scan fast path reuses the beams' cos/sin: new angles of the same length must be seen."""
    grid = OccupancyGrid(occupancy=random_boxes_grid(4, n_boxes=30).astype(float), resolution=RES)
    pose = np.array([10.3, 9.7, 0.4])
    for angles in (np.linspace(-2.0, 2.0, 50), np.linspace(-1.0, 3.0, 50), np.linspace(-2.0, 2.0, 51)):
        fast = cast_scan(grid, pose, angles, 12.0)  # float64 vectors: fast path once the grid is cached
        general = cast_scan(grid, pose.tolist(), angles.tolist(), 12.0, parallel=False)
        exact = cast_scan(grid, pose, angles, 12.0, method="dda")
        np.testing.assert_array_equal(fast, general)
        np.testing.assert_array_equal(cast_scan(grid, pose, angles, 12.0, method="march"), general)
        both_inf = np.isinf(exact) & np.isinf(fast)
        np.testing.assert_allclose(np.where(both_inf, 0.0, fast), np.where(both_inf, 0.0, exact), atol=1e-9)
    with pytest.raises(ValueError, match="max_range"):
        cast_scan(grid, pose, np.zeros(3), math.inf)


def test_sector_table_rows_are_non_decreasing_inside_the_wedge() -> None:
    """The row scan of the octant bounds takes each row's first occupied cell: that needs these rows sorted."""
    for n_sub in (1, 2, 4):
        k_tab, first, last, _ = _raycast_sectors.kernel_tables(n_sub, 90)
        for s in range(n_sub):
            for dy in range(90):
                if first[s, dy] >= 90:
                    continue
                row = k_tab[s, dy, first[s, dy] + 1 : min(last[s, dy], 88) + 2]
                assert np.all(np.isfinite(row))
                assert np.all(np.diff(row) >= -1e-12), (n_sub, s, dy)


def test_sector_bounds_equal_the_minimum_over_every_occupied_cell() -> None:
    rng = np.random.default_rng(11)
    occ = rng.random((24, 30)) < 0.06
    for n_sub in (1, 2):
        dirs = _raycast_sectors._wedge_directions(n_sub)
        bounds = _raycast_sectors.sector_bounds(occ, n_sub, 40.0)
        oi, oj = np.nonzero(occ)
        for i, j in np.argwhere(~occ)[::5]:
            for s in range(n_sub):
                brute = 40.0
                for a, b in zip(oi - i, oj - j, strict=True):
                    k = _raycast_sectors._wedge_rect_distance(b - 1, b + 1, a - 1, a + 1, *dirs[s], *dirs[s + 1])
                    brute = min(brute, k)
                assert bounds[_raycast_sectors.sector_index(False, False, False, s, n_sub), i, j] == pytest.approx(
                    brute, abs=1e-12
                )


def test_octant_planes_bound_every_sampled_beam_of_their_octant() -> None:
    """No beam of an octant, from any point of a cell, hits anything nearer than the cell's octant bound."""
    occ = random_boxes_grid(5, n_boxes=25)[:80, :80].copy()
    planes = march_sector_field(occ)
    iso = march_field(occ)
    assert planes.shape == (8, 80, 80)
    assert np.all((planes == FIELD_OCCUPIED) == occ[None])
    assert np.all(planes >= iso[None])
    rng = np.random.default_rng(2)
    free = np.argwhere(~occ)
    cells = free[rng.choice(free.shape[0], 150, replace=False)]
    n = 64
    for octant in range(8):
        # directions inside the octant: (dx < 0, dy < 0, |dy| > |dx|) from its index, boundaries included
        sx = -1.0 if octant & 4 else 1.0
        sy = -1.0 if octant & 2 else 1.0
        # (the octant's boundary directions are rounded into a neighbour octant by cos and sin: the
        # lattice test below covers them)
        phi = rng.uniform(1e-7, math.pi / 4 - 1e-7, n)
        major, minor = np.cos(phi), np.sin(phi)
        dx, dy = (minor, major) if octant & 1 else (major, minor)
        angles = np.arctan2(sy * dy, sx * dx)
        for i, j in cells:
            start = (np.array([j, i]) + rng.uniform(0.0, 1.0, (8, 2))) * RES
            poses = np.column_stack([start, np.zeros(8)])
            exact = cast_rays(occ, RES, (0.0, 0.0), poses, angles, 20.0, method="dda") / RES
            bound = planes[octant, i, j] * JUMP_UNIT_CELLS
            assert exact.min() >= bound - 1e-9, (octant, i, j, exact.min(), bound)
    # and the octant bounds are worth their memory: far above the isotropic clearance on average
    assert planes[:, ~occ].mean() > 1.5 * iso[~occ].mean()


@pytest.mark.parametrize("seed", [0, 1])
def test_one_pose_scans_on_octant_planes_equal_the_exact_traversal(seed: int) -> None:
    occ = random_boxes_grid(seed)
    grid = OccupancyGrid(occupancy=occ.astype(float), resolution=RES)
    rng = np.random.default_rng(200 + seed)
    poses = random_poses(occ, 40, rng)
    poses = np.vstack([poses, [[-0.7, 3.3, 0.2], [5.0, 5.0, 0.0], [7.5, 2.5, math.pi / 2]]])
    angles = np.concatenate([np.linspace(-math.pi, math.pi, 180, endpoint=False), [math.pi / 4, -3 * math.pi / 4]])
    isotropic = cast_rays(occ, RES, (0.0, 0.0), poses, angles, 12.0, method="march")
    dda = cast_rays(occ, RES, (0.0, 0.0), poses, angles, 12.0, method="dda")
    for k, pose in enumerate(poses):
        one = cast_scan(grid, pose, angles, 12.0)  # one pose: the octant planes
        np.testing.assert_array_equal(one, isotropic[k])  # the same ranges, bit for bit
        with np.errstate(invalid="ignore"):  # inf - inf
            same = (one == dda[k]) | (np.abs(one - dda[k]) <= 1e-9)
        assert np.mean(same) > 0.999  # only a beam through a cell corner may pick the other cell
    assert np.mean(np.isfinite(dda)) > 0.9


def test_octant_planes_terminate_on_lattice_poses_along_cell_boundaries() -> None:
    """The lattice regression above, for one-pose scans on the octant planes."""
    _, grid, lattice, angles, exact = _lattice_case()
    for k, pose in enumerate(lattice):
        _assert_lattice_ranges(cast_scan(grid, pose, angles, 8.0), exact[k])


@pytest.mark.parametrize("seed", [0, 1])
def test_many_pose_casts_jump_first_on_the_octant_planes_with_the_same_ranges(seed: int) -> None:
    """Serial casts from several poses take each beam's first jump on the octant planes (interleaved per cell)
    and march on the isotropic field after it: the ranges are those of the isotropic march, bit for bit."""
    occ = random_boxes_grid(seed)
    grid = OccupancyGrid(occupancy=occ.astype(float), resolution=RES)
    rng = np.random.default_rng(300 + seed)
    poses = random_poses(occ, 200, rng)
    occupied_cell = np.argwhere(occ)[7]
    extra = [
        [-0.7, 3.3, 0.2],  # outside the grid
        [25.0, -1.0, 2.5],
        [5.0, 5.0, 0.0],  # on cell corners
        [7.5, 2.5, math.pi / 2],
        [(occupied_cell[1] + 0.5) * RES, (occupied_cell[0] + 0.5) * RES, 1.0],  # in an occupied cell
    ]
    poses = np.vstack([poses, extra])
    angles = np.concatenate([np.linspace(-math.pi, math.pi, 90, endpoint=False), [math.pi / 4, -3 * math.pi / 4]])
    many = cast_scan(grid, poses, angles, 12.0, parallel=False)
    starts = raycast._START_CACHE[grid]  # the path under test was taken
    np.testing.assert_array_equal(starts.reshape(*occ.shape, 8), np.moveaxis(march_sector_field(occ), 0, -1))
    isotropic = cast_rays(occ, RES, (0.0, 0.0), poses, angles, 12.0, parallel=True, method="march")
    np.testing.assert_array_equal(many, isotropic)
    # the isotropic field's own first jump (cast_rays, serial) gives the same ranges too
    serial = cast_rays(occ, RES, (0.0, 0.0), poses, angles, 12.0, parallel=False, method="march")
    np.testing.assert_array_equal(serial, isotropic)
    dda = cast_rays(occ, RES, (0.0, 0.0), poses, angles, 12.0, method="dda")
    with np.errstate(invalid="ignore"):  # inf - inf
        same = (many == dda) | (np.abs(many - dda) <= 1e-9)
    assert np.mean(same) > 0.999
    assert np.all(many[-1] == 0.0)
    assert np.mean(np.isfinite(dda)) > 0.9


def test_many_pose_casts_terminate_on_lattice_poses_along_cell_boundaries() -> None:
    """The lattice regression above, for serial casts from many poses (first jumps on the octant planes)."""
    _, grid, lattice, angles, exact = _lattice_case()
    _assert_lattice_ranges(cast_scan(grid, lattice, angles, 8.0, parallel=False), exact)


def _pool_ranges(occ: np.ndarray, poses: np.ndarray, angles: np.ndarray, max_range: float) -> dict[str, np.ndarray]:
    """Ranges of the pool kernel, called directly on the same rays in each of its layouts: the isotropic field,
    the octant planes (one-pose scans), the isotropic field after a first jump on the interleaved octant values
    (many poses), and that last one cut into pieces of 77 rays that start and end inside a pose's fan (as the
    parallel kernel cuts the rays)."""
    field = march_field(occ)
    flat = field.reshape(-1)
    planes = march_sector_field(occ, field).reshape(-1)
    starts = np.ascontiguousarray(planes.reshape(8, -1).T).reshape(-1)
    rays = (RES, 0.0, 0.0, poses, np.cos(poses[:, 2]), np.sin(poses[:, 2]), np.cos(angles), np.sin(angles))
    t_lim = max_range / RES
    total = poses.shape[0] * angles.shape[0]
    layouts = {"isotropic": (flat, 0, raycast._NO_STARTS), "octant planes": (planes, field.size, raycast._NO_STARTS)}
    layouts["first jump"] = (flat, 0, starts)
    out = {}
    for name, (marched, plane_size, first) in layouts.items():
        out[name] = np.full(total, np.nan)
        raycast._march_pool(field, marched, plane_size, first, *rays, t_lim, 0, total, out[name])
    out["pieces"] = np.full(total, np.nan)
    for start in range(0, total, 77):
        raycast._march_pool(field, flat, 0, starts, *rays, t_lim, start, min(start + 77, total), out["pieces"])
    return out


@pytest.mark.parametrize("seed", [0, 1])
def test_pool_kernel_gives_the_same_ranges_in_every_layout(seed: int) -> None:
    """The pool kernel's ranges are the same bit for bit on the isotropic field, on the octant planes and after a
    first jump, whole or in pieces: random poses, poses on cell corners, in an occupied cell and outside the
    grid (beams that enter it, miss it or enter it past max range), beams along the axes and diagonals, max
    ranges from 0 (every beam ends at once) to beyond the grid, one pose and fans of fewer beams than lanes."""
    occ = random_boxes_grid(seed)
    rng = np.random.default_rng(500 + seed)
    occupied_cell = np.argwhere(occ)[11]
    special = [
        [5.0, 5.0, 0.0],  # on cell corners
        [7.5, 2.5, math.pi / 2],
        [0.05, 0.05, math.pi / 4],
        [(occupied_cell[1] + 0.5) * RES, (occupied_cell[0] + 0.5) * RES, 1.0],  # in an occupied cell
        [-0.7, 3.3, 0.2],  # outside the grid
        [25.0, -1.0, 2.5],
        [-50.0, -50.0, math.pi / 4],
        [10.0, 30.0, 0.0],
    ]
    poses = np.vstack([random_poses(occ, 40, rng), special])
    angles = np.concatenate([np.linspace(-math.pi, math.pi, 60, endpoint=False), [math.pi / 4, -3 * math.pi / 4]])
    dda = cast_rays(occ, RES, (0.0, 0.0), poses, angles, 30.0, method="dda").reshape(-1)
    for max_range in (0.0, 0.3, 4.0, 30.0):
        ranges = _pool_ranges(occ, poses, angles, max_range)
        for name in ("octant planes", "first jump", "pieces"):
            np.testing.assert_array_equal(ranges[name], ranges["isotropic"], err_msg=name)
        for k in (0, 40, poses.shape[0] - 4):  # one pose (a scan), and fewer beams than lanes
            for beams in (angles, angles[:3]):
                one = _pool_ranges(occ, poses[k : k + 1], beams, max_range)
                for name in ("octant planes", "first jump", "pieces"):
                    np.testing.assert_array_equal(one[name], one["isotropic"], err_msg=name)
    # and they are the exact traversal's, but for beams through a cell corner
    with np.errstate(invalid="ignore"):  # inf - inf
        same = (ranges["isotropic"] == dda) | (np.abs(ranges["isotropic"] - dda) <= 1e-9)
    assert np.mean(same) > 0.999
    assert np.mean(np.isfinite(dda)) > 0.5  # hits, not only misses


def test_grids_beyond_the_march_offsets_scan_on_the_isotropic_field_or_take_the_traversal(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The pool's int32 offsets bound the grids it marches: with the bound lowered to this test's grid, one-pose
    scans march on the isotropic field (same ranges), and grids at the bound raise for ``march`` and take
    ``dda`` under ``auto``."""
    occ = random_boxes_grid(0)
    pose = np.array([6.0, 7.0, 0.3])
    angles = np.linspace(-2.0, 2.0, 101)
    expected = cast_scan(OccupancyGrid(occupancy=occ.astype(float), resolution=RES), pose, angles, 12.0)
    monkeypatch.setattr(raycast, "MARCH_MAX_CELLS", 4 * occ.size)
    grid = OccupancyGrid(occupancy=occ.astype(float), resolution=RES)
    np.testing.assert_array_equal(cast_scan(grid, pose, angles, 12.0), expected)
    assert grid not in raycast._SECTOR_CACHE  # the octant planes were not built
    monkeypatch.setattr(raycast, "MARCH_MAX_CELLS", occ.size)
    with pytest.raises(ValueError, match="method='dda'"):
        cast_rays(occ, RES, (0.0, 0.0), pose, angles, 12.0, method="march")
    auto = cast_rays(occ, RES, (0.0, 0.0), np.tile(pose, (1000, 1)), angles, 12.0, method="auto")
    np.testing.assert_array_equal(auto[0], cast_rays(occ, RES, (0.0, 0.0), pose, angles, 12.0, method="dda")[0])
