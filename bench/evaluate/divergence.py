"""When is a run's estimate no longer an estimate: the bound around the world outside which a run has diverged.

A non-finite estimate is the obvious case; an estimate of x = -9.6e299 m is finite but as meaningless. The runner
marks a run ``diverged`` as soon as its mean leaves :func:`world_box`: the axis-aligned box of everything the
dataset knows about the world (the ground truth, the landmarks, the line map and the occupancy grid),
enlarged on every side by ``factor`` times its larger side (at least 1 m). With the default factor 1e3 a filter
on a 20 m office may wander 20 km before it is called diverged, so the bound never catches a filter that is
merely bad; it catches overflow-bound numbers that would otherwise be scored as an "ok" run.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

if TYPE_CHECKING:
    from locbench.datasets.dataset import Dataset

#: How many times the world's extent an estimate may stray beyond it before the run counts as diverged.
DIVERGENCE_FACTOR = 1.0e3


class Box(NamedTuple):
    """An axis-aligned box in the world frame, m."""

    x_min: float
    x_max: float
    y_min: float
    y_max: float

    def contains(self, x: float, y: float) -> bool:
        """True when (x, y) lies inside (NaN lies outside)."""
        return self.x_min <= x <= self.x_max and self.y_min <= y <= self.y_max


def world_extent(ds: Dataset) -> Box:
    """The box of the dataset's ground truth, landmarks, map lines and occupancy grid, m."""
    xs: list[float] = []
    ys: list[float] = []

    def add(x: np.ndarray, y: np.ndarray) -> None:
        if x.size:
            xs.extend((float(np.min(x)), float(np.max(x))))
            ys.extend((float(np.min(y)), float(np.max(y))))

    gt = ds.ground_truth
    add(gt.xy[:, 0], gt.xy[:, 1])
    w = ds.world
    if w.landmarks is not None:
        add(w.landmarks.xy[:, 0], w.landmarks.xy[:, 1])
    if w.lines is not None:
        seg = w.lines.segments
        add(seg[:, [0, 2]].ravel(), seg[:, [1, 3]].ravel())
    if w.occupancy is not None:
        g = w.occupancy
        rows, cols = g.shape
        ox, oy = g.origin[0], g.origin[1]
        add(np.array([ox, ox + cols * g.resolution]), np.array([oy, oy + rows * g.resolution]))
    if not xs:
        return Box(0.0, 0.0, 0.0, 0.0)
    return Box(min(xs), max(xs), min(ys), max(ys))


def world_box(ds: Dataset, factor: float = DIVERGENCE_FACTOR) -> Box:
    """:func:`world_extent` enlarged on every side by ``factor`` x its larger side (at least 1 m), m."""
    e = world_extent(ds)
    margin = factor * max(e.x_max - e.x_min, e.y_max - e.y_min, 1.0)
    return Box(e.x_min - margin, e.x_max + margin, e.y_min - margin, e.y_max + margin)


def left_world(mean: np.ndarray, box: Box) -> str | None:
    """Why the pose ``mean`` (x m, y m, theta rad) is no estimate any more, or None while it is one."""
    x, y, th = float(mean[0]), float(mean[1]), float(mean[2])
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(th)):
        return "non-finite estimate"
    if not box.contains(x, y):
        return (
            f"estimate ({x:.4g}, {y:.4g}) m left the world's bound x in [{box.x_min:.4g}, {box.x_max:.4g}], "
            f"y in [{box.y_min:.4g}, {box.y_max:.4g}] m ({DIVERGENCE_FACTOR:g} x the world's extent around it)"
        )
    return None
