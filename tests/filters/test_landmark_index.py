"""The k-d tree's nearest-neighbour candidates in the UKF and the fixed-lag smoother.

With the index (maps of ``INDEX_MIN_LANDMARKS`` landmarks and more) a filter tests only the landmarks that
can still pass the gate; the association must be that of testing every landmark, over random beliefs of
every size and sightings near and far. The EKF's own cases are in ``test_ekf_landmarks.py``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from locbench.datasets.dataset import Gaussian2, Landmarks, SensorSpec, WorldMap
from locbench.filters._landmark_index import INDEX_MIN_LANDMARKS
from locbench.registry import FILTERS, make_filter

N_MAP = 200


def _world(rng: np.random.Generator) -> tuple[WorldMap, np.ndarray]:
    xy = rng.uniform(-15.0, 15.0, size=(N_MAP, 2))
    return WorldMap(landmarks=Landmarks(ids=np.arange(N_MAP, dtype=np.int64), xy=xy)), xy


def _set_ukf(flt: Any, x: np.ndarray, P: np.ndarray) -> None:
    flt._x, flt._P = x.tolist(), P.tolist()


def _set_fls(flt: Any, x: np.ndarray, P: np.ndarray) -> None:
    flt._mean_f, flt._cov_f = tuple(x.tolist()), P.tolist()


def _random_sightings(flt: Any, set_state: Any, rng: np.random.Generator, xy: np.ndarray, spread: float) -> int:
    """Compare the index's and the full scan's association 300 times; the number of associations found."""
    assert flt._index is not None and N_MAP >= INDEX_MIN_LANDMARKS
    found = 0
    for _ in range(300):
        a = rng.standard_normal((3, 3)) * spread
        P = a @ a.T + 1e-6 * np.eye(3)
        x = np.array([rng.uniform(-10, 10), rng.uniform(-10, 10), rng.uniform(-math.pi, math.pi)])
        set_state(flt, x, P)
        target = xy[int(rng.integers(N_MAP))]
        dx, dy = target[0] - x[0], target[1] - x[1]
        r = max(math.hypot(dx, dy) + float(rng.normal(0.0, 0.3)), 0.01)
        b = math.atan2(dy, dx) - x[2] + float(rng.normal(0.0, 0.2))
        used = {int(k) for k in rng.integers(0, N_MAP, size=3)}
        with_index = flt._nearest(r, b, used)
        index, flt._index = flt._index, None
        scanned = flt._nearest(r, b, used)
        flt._index = index
        assert with_index == scanned
        found += scanned is not None
    return found


@pytest.mark.parametrize("spread", [0.01, 0.3, 3.0])
def test_ukf_index_finds_the_scanned_nearest_landmark(spread: float) -> None:
    rng = np.random.default_rng(int(spread * 100) + 1)
    world, xy = _world(rng)
    flt = make_filter("ukf_landmarks[association=nearest]")
    flt.reset(Gaussian2(np.zeros(3), np.eye(3) * 0.01), world, SensorSpec(), rng)
    assert flt._weights_nonnegative
    assert _random_sightings(flt, _set_ukf, rng, xy, spread) > 30


@pytest.mark.skipif(FILTERS.unavailable_reason("gtsam_fls") is not None, reason="gtsam not installed")
@pytest.mark.parametrize("spread", [0.01, 0.3, 3.0])
def test_fls_index_finds_the_scanned_nearest_landmark(spread: float) -> None:
    rng = np.random.default_rng(int(spread * 100) + 2)
    world, xy = _world(rng)
    flt = make_filter("gtsam_fls[association=nearest]")
    flt.reset(Gaussian2(np.zeros(3), np.eye(3) * 0.01), world, SensorSpec(), rng)
    assert _random_sightings(flt, _set_fls, rng, xy, spread) > 30


def test_ukf_subset_winner_is_the_full_maps() -> None:
    """Each landmark's d2 is computed on its own, so the nearest landmark over the map is the nearest over any subset
    that holds it (what makes the index's first smallest the scan's)."""
    rng = np.random.default_rng(5)
    world, xy = _world(rng)
    pose = np.array([1.0, -2.0, 0.3])
    flt = make_filter("ukf_landmarks[association=nearest,prune_to_sensor_limits=false]")
    flt.reset(Gaussian2(pose, np.diag([0.2, 0.1, 0.05])), world, SensorSpec(), rng)
    flt._index = None  # every landmark
    used = np.zeros(N_MAP, dtype=np.int64)
    for target in rng.choice(N_MAP, size=10, replace=False).tolist():
        dx, dy = xy[target] - pose[:2]
        r, b = math.hypot(dx, dy) + 0.1, math.atan2(dy, dx) - pose[2] + 0.05
        flt._all_rows = np.arange(N_MAP, dtype=np.int64)
        full = flt._nearest_row(r, b, used)
        assert full >= 0
        for _ in range(10):
            rows = sorted({full, *rng.choice(N_MAP, size=int(rng.integers(1, 30)), replace=False).tolist()})
            flt._all_rows = np.array(rows, dtype=np.int64)
            assert flt._nearest_row(r, b, used) == full


def test_ukf_without_a_bound_scans() -> None:
    """A belief whose heading spread bounds nothing (delta >= pi / 2) gives no radius: every landmark is tested."""
    rng = np.random.default_rng(6)
    world, _ = _world(rng)
    flt = make_filter("ukf_landmarks[association=nearest]")
    flt.reset(Gaussian2(np.zeros(3), np.diag([0.01, 0.01, 4.0])), world, SensorSpec(), rng)
    assert flt._gate_radius(5.0, flt._sigma_points(0.0)) is None
