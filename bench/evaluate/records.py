"""The records a run leaves and evaluation reads: a run's per-event estimates, its realisation's truth, its bound.

These are plain values (arrays and a JSON-able ``meta``) with no I/O: :mod:`locbench.run.execute` makes them,
:mod:`locbench.run.store` writes and reads them, and :mod:`locbench.evaluate.metrics` and the report compute on
them. They live here, below the run layer, so that evaluation never imports the machinery that produces them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from locbench.datasets.dataset import Dataset, Kidnap, Relations, Trajectory2D, Waypoints

FloatArray = npt.NDArray[np.float64]

#: Event kinds stored in ``RunRecord.kind``: the index into this tuple.
# Codes are stored in runs: append new kinds at the end, never reorder.
KIND_NAMES = ("Odometry", "LaserScan", "LandmarkObservations", "PoseFix", "reset", "RangeObservations")
#: The statuses of a run (``RunRecord.status``).
STATUSES = ("ok", "skipped", "diverged", "error")


@dataclass(eq=False)
class TruthRecord:
    """The ground truth of one dataset realisation, as metrics need it."""

    dataset: str
    seed: int
    ground_truth: Trajectory2D
    waypoints: Waypoints | None
    kidnaps: tuple[Kidnap, ...]
    duration_s: float
    meta: dict[str, Any] = field(default_factory=dict)
    #: The world's line segments (n, 4) and landmark positions (m, 2), m, for figures; empty when absent.
    map_segments: FloatArray = field(default_factory=lambda: np.zeros((0, 4)))
    map_landmarks: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    #: Reference relative poses (Intel), and what the trajectory is ("ground truth" or "SLAM reference").
    relations: Relations | None = None
    truth_label: str = "ground truth"

    @classmethod
    def from_dataset(cls, ds: Dataset, seed: int, meta: dict[str, Any]) -> TruthRecord:
        w = ds.world
        segs = w.lines.segments if w.lines is not None else np.zeros((0, 4))
        lms = w.landmarks.xy if w.landmarks is not None else np.zeros((0, 2))
        return cls(
            ds.name or ds.id,
            seed,
            ds.ground_truth,
            ds.waypoints,
            ds.kidnaps,
            ds.duration,
            meta,
            segs,
            lms,
            ds.relations,
            ds.truth_label,
        )


@dataclass(eq=False)
class BoundRecord:
    """The posterior Cramer-Rao bound of one synthetic realisation (:func:`locbench.evaluate.pcrb.bound_covariances`).

    Attributes
    ----------
    dataset, seed : str, int
        The realisation.
    t : ndarray, shape (n,)
        Ground-truth times, s.
    covs : dict of str to ndarray, shape (n, 3, 3)
        The bound's pose covariance at each time by row name (m^2, rad^2; world frame).
    meta : dict
        ``bound_key`` (what the bound was computed from), ``compute_s``, ``versions``.
    """

    dataset: str
    seed: int
    t: FloatArray
    covs: dict[str, FloatArray]
    meta: dict[str, Any] = field(default_factory=dict)


@dataclass(eq=False)
class RunRecord:
    """One (filter, dataset, seed) run.

    Attributes
    ----------
    meta : dict
        ``filter``, ``filter_id``, ``filter_config``, ``filter_traits`` (what the report labels the configuration
        by, :class:`locbench.run.plan.FilterTraits`; absent from runs stored before it), ``dataset``,
        ``dataset_id``, ``dataset_params``, ``seed``, ``run_key``, ``status`` (one of ok, skipped, diverged,
        error), ``message``, ``diverged_t``, ``versions``, ``git_commit``, ``git_dirty``, ``wall_s``, ``started``.
    t : ndarray, shape (n,)
        Time of each recorded estimate, s (the event it followed; the first row is the reset belief).
    mean : ndarray, shape (n, 3)
        Estimated pose after each event.
    cov : ndarray, shape (n, 3, 3)
        Its covariance.
    kind : ndarray of int8, shape (n,)
        Index into :data:`KIND_NAMES` of the event that produced the row.
    step_ns : ndarray of int64, shape (n,)
        Time of the ``predict``/``update`` call for that row, ns (0 for the reset row).
    diagnostics : dict of str to ndarray (n,)
        Per-row filter diagnostics, NaN where absent.
    extra : dict of str to ndarray
        Filter-specific arrays (e.g. ``smoothed_t``, ``smoothed_mean`` of a smoother).
    health : dict of str to ndarray (n,)
        Per-row :meth:`Filter.health` signals, NaN where absent.
    """

    meta: dict[str, Any]
    t: FloatArray
    mean: FloatArray
    cov: FloatArray
    kind: npt.NDArray[np.int8]
    step_ns: npt.NDArray[np.int64]
    diagnostics: dict[str, FloatArray] = field(default_factory=dict)
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    health: dict[str, FloatArray] = field(default_factory=dict)

    @property
    def status(self) -> str:
        return str(self.meta.get("status", "error"))

    def step_times_us(self, kind_name: str) -> FloatArray:
        """Per-call times in microseconds of the rows of one kind ('predict' = Odometry, 'update' = the rest)."""
        if kind_name == "predict":
            sel = self.kind == KIND_NAMES.index("Odometry")
        elif kind_name == "update":
            sel = (self.kind != KIND_NAMES.index("Odometry")) & (self.kind != KIND_NAMES.index("reset"))
        else:
            sel = self.kind == KIND_NAMES.index(kind_name)
        return self.step_ns[sel].astype(np.float64) / 1e3
