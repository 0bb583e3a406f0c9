"""The interactive figures' paths: simplified to at most 1000 points, no dropped point farther than 1 mm from the
drawn line unless the cap forced a coarser tolerance."""

from __future__ import annotations

import numpy as np

from locbench.report.interactive import MAX_PATH_POINTS, PATH_TOLERANCE_M, path, simplify


def _distance_to_polyline(p: np.ndarray, line: np.ndarray) -> float:
    """The distance (m) of point ``p`` from the polyline ``line`` (K x 2)."""
    a, b = line[:-1], line[1:]
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300), 0.0, 1.0)
    return float(np.min(np.hypot(*(a + t[:, None] * ab - p).T)))


def test_a_smooth_path_keeps_every_point_within_the_tolerance() -> None:
    t = np.linspace(0.0, 2.0 * np.pi, 5000)
    xy = np.column_stack([3.0 * np.cos(t), 2.0 * np.sin(t)])
    keep = simplify(xy)
    assert keep[0] == 0 and keep[-1] == len(xy) - 1 and np.all(np.diff(keep) > 0)
    assert 10 < keep.size <= MAX_PATH_POINTS
    line = xy[keep]
    worst = max(_distance_to_polyline(xy[i], line) for i in range(0, len(xy), 7))
    assert worst <= PATH_TOLERANCE_M * (1 + 1e-9)


def test_a_straight_path_is_its_two_ends_and_a_noisy_one_is_capped() -> None:
    xy = np.column_stack([np.linspace(0.0, 5.0, 3000), np.zeros(3000)])
    assert simplify(xy).tolist() == [0, 2999]
    rng = np.random.default_rng(0)
    noisy = np.cumsum(rng.normal(0.0, 0.01, (20000, 2)), axis=0)  # every point off the line by more than 1 mm
    keep = simplify(noisy)
    assert keep.size <= MAX_PATH_POINTS and keep[0] == 0 and keep[-1] == len(noisy) - 1
    trace = path("p", noisy, {"color": "#000000"})
    assert len(trace["x"]) == keep.size == len(trace["y"])


def test_short_and_gapped_paths() -> None:
    assert simplify(np.zeros((2, 2))).tolist() == [0, 1]
    gapped = np.column_stack([np.arange(3000.0), np.arange(3000.0)])
    gapped[100] = np.nan
    keep = simplify(gapped)
    assert keep.size <= MAX_PATH_POINTS and keep[0] == 0
