"""The ``landmark_geometry`` detector's error against the truth: the basis of its nominal landmark noise.

:data:`~locbench.datasets.synthetic.landmark_geometry.NOMINAL_SIGMA_RANGE_M` (5 cm) and
:data:`~locbench.datasets.synthetic.landmark_geometry.NOMINAL_SIGMA_BEARING_RAD` (0.007 rad) are the RMS errors
:func:`detection_error_stats` measures over :func:`detection_cases` (every path and layout, seeds 0-2), rounded up;
:data:`DETECTION_ERROR_MEASURED` is what it measured, which ``tests/datasets/synthetic/test_landmark_geometry.py``
checks it still gives, and ``tools/derive/landmark_detection_stats.py`` prints it. The realisations are built by the
caller (the registry's ``make_dataset``, a layer above this one).
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

from locbench.core.events import LandmarkObservations
from locbench.core.geometry import wrap_scalar
from locbench.datasets.dataset import Dataset
from locbench.datasets.synthetic.landmark_geometry import LAYOUTS, PATHS

#: What :func:`detection_error_stats` measured on :func:`detection_cases` (generator version of 2026-12).
DETECTION_ERROR_MEASURED: dict[str, float] = {
    "range_mean_m": -0.03840475684266814,
    "range_rms_m": 0.04206713610746617,
    "bearing_mean_rad": -2.680435789308959e-05,
    "bearing_rms_rad": 0.006147265182316174,
    "sightings": 66325.0,
}


def detection_cases(seeds: Iterable[int] = (0, 1, 2)) -> list[tuple[str, int]]:
    """The realisations the nominal noise is measured on: every (path, layout) of ``landmark_geometry``.

    Parameters
    ----------
    seeds : iterable of int
        The seeds of each (path, layout).

    Returns
    -------
    list of (str, int)
        (dataset name, seed) pairs, paths outermost, then layouts, then seeds.
    """
    kept = tuple(seeds)
    return [(f"landmark_geometry[path={p},landmarks={lay}]", s) for p in PATHS for lay in LAYOUTS for s in kept]


def detection_error_stats(datasets: Iterable[Dataset]) -> dict[str, float]:
    """Errors of :func:`~locbench.datasets.synthetic.landmark_geometry.detect_landmarks` against the truth.

    Each reported sighting is compared with the true range and bearing (robot frame) of its disc centre at
    the ground-truth sample at or after its time.

    Parameters
    ----------
    datasets : iterable of Dataset
        Built ``landmark_geometry`` realisations (for the recorded result, those of :func:`detection_cases`).

    Returns
    -------
    dict
        ``range_mean_m`` and ``range_rms_m`` (m), ``bearing_mean_rad`` and ``bearing_rms_rad`` (rad, wrapped),
        ``sightings`` (their number).
    """
    dr: list[float] = []
    db: list[float] = []
    for ds in datasets:
        gt = ds.ground_truth
        lm = ds.world.landmarks
        assert lm is not None
        for e in ds.events:
            if not isinstance(e, LandmarkObservations):
                continue
            k = int(np.searchsorted(gt.t, e.t - 1e-9))
            x, y, th = gt.xy[k, 0], gt.xy[k, 1], gt.theta[k]
            for j, r, b in zip(e.ids.tolist(), e.ranges.tolist(), e.bearings.tolist(), strict=True):
                cx, cy = lm.xy[j]
                dr.append(r - math.hypot(cx - x, cy - y))
                db.append(wrap_scalar(b - (math.atan2(cy - y, cx - x) - th)))
    a, b = np.asarray(dr), np.asarray(db)
    return {
        "range_mean_m": float(np.mean(a)),
        "range_rms_m": float(np.sqrt(np.mean(a * a))),
        "bearing_mean_rad": float(np.mean(b)),
        "bearing_rms_rad": float(np.sqrt(np.mean(b * b))),
        "sightings": float(a.size),
    }
