"""Maps from laser scans at known poses: the occupancy grid of a box room, its no-return beams, its line segments,
and the resolution check."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_recorded_intel import ANGLES, HALF_X, HALF_Y, NO_RETURN_M, box_ranges

from locbench.datasets.dataset import OccupancyGrid
from locbench.datasets.recorded.scan_map import build_occupancy_grid, extract_map_lines


def box_grid(resolution: float = 0.05) -> OccupancyGrid:
    poses = np.array([[0.0, 0.0, h] for h in (0.0, math.pi / 2, math.pi, -math.pi / 2)])
    ranges = np.stack([box_ranges(p) for p in poses])
    return build_occupancy_grid(poses, ranges, ANGLES, resolution)


def test_grid_of_a_box_room() -> None:
    g = box_grid()
    occ = g.cell_centers(np.argwhere(g.occupied()))
    # every occupied cell lies on a wall (within one cell)
    d_wall = np.minimum(np.abs(np.abs(occ[:, 0]) - HALF_X), np.abs(np.abs(occ[:, 1]) - HALF_Y))
    assert occ.shape[0] > 300
    assert d_wall.max() <= g.resolution
    # the inside is free, beyond the walls is unknown
    near = g.world_to_cell(np.array([[0.3, 0.2], [-0.2, -0.3], [0.0, 0.0]]))  # crossed by many beams
    assert np.all(g.free()[near[:, 0], near[:, 1]])
    rows, cols = np.indices(g.shape)
    xy = g.cell_centers(np.stack([rows, cols], axis=-1))
    interior = (np.abs(xy[..., 0]) < HALF_X - 0.2) & (np.abs(xy[..., 1]) < HALF_Y - 0.2)
    o = g.occupancy[interior]
    assert np.mean((o >= 0.0) & (o < 0.5)) > 0.8  # far cells fall between 1 deg beams: unseen, not occupied
    outside = g.world_to_cell(np.array([[3.5, 0.0], [0.0, -2.6]]))
    assert np.all(g.occupancy[outside[:, 0], outside[:, 1]] == -1.0)


def test_no_return_beams_add_nothing() -> None:
    pose = np.array([[0.0, 0.0, 0.0]])
    r = box_ranges(pose[0])[None, :].copy()
    beyond_wall = np.array([HALF_X + 0.01, 0.0])
    g1 = build_occupancy_grid(pose, r, ANGLES, 0.05)
    r[0, 80:100] = NO_RETURN_M
    g2 = build_occupancy_grid(pose, r, ANGLES, 0.05, max_range_m=NO_RETURN_M)
    # without the scanner's no-return reading, 81.83 m is a return: the beams cross the cell beyond the wall
    g3 = build_occupancy_grid(pose, r, ANGLES, 0.05)
    r[0, 80:100] = np.inf
    g4 = build_occupancy_grid(pose, r, ANGLES, 0.05)
    w1, w2, w3, w4 = (g.world_to_cell(beyond_wall) for g in (g1, g2, g3, g4))
    assert g1.occupied()[w1[0], w1[1]]
    assert g2.occupancy[w2[0], w2[1]] == -1.0  # never observed: the no-return beams neither hit nor cleared
    assert 0.0 <= g3.occupancy[w3[0], w3[1]] < 0.5
    assert g4.occupancy[w4[0], w4[1]] == -1.0  # a non-finite range is a no-return by default


def test_lines_of_a_box_room() -> None:
    lines, stats = extract_map_lines(box_grid())
    seg = lines.segments
    assert len(lines) == 4, seg
    for s in seg:
        vertical = abs(s[0] - s[2]) < abs(s[1] - s[3])
        if vertical:  # x = +-3, spanning y in [-2, 2]
            assert abs(abs(s[0]) - HALF_X) < 0.05 and abs(s[0] - s[2]) < 0.02
            assert abs(abs(s[1] - s[3]) - 2 * HALF_Y) < 0.15
        else:
            assert abs(abs(s[1]) - HALF_Y) < 0.05 and abs(s[1] - s[3]) < 0.02
            assert abs(abs(s[0] - s[2]) - 2 * HALF_X) < 0.15
    assert stats["segments"] == 4
    assert stats["total_length_m"] == pytest.approx(2 * (2 * HALF_X + 2 * HALF_Y), abs=0.6)
    assert stats["cells_on_lines"] <= stats["occupied_cells"]


def test_bad_resolution() -> None:
    with pytest.raises(ValueError, match="map_resolution_m must be > 0"):
        build_occupancy_grid(np.zeros((1, 3)), np.ones((1, 180)), ANGLES, 0.0)
