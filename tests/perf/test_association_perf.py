"""pytest-benchmark: nearest-neighbour association against map size.

``ekf_landmarks``, ``ukf_landmarks`` and ``gtsam_fls`` with ``association=nearest`` replay the office run
(the smoother its first quarter) with the office map as it is and with the map tiled 16 and 64 times (copies
shifted 100 m apart along x, never seen, so the sightings and the associations are the same). With the k-d
tree of :mod:`locbench.filters._landmark_index` the time per run stays flat in the map's size; ``scan`` is
the same filter testing every landmark (the code path of maps without an index), its reference.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest

from locbench.core.events import Odometry
from locbench.core.seeding import filter_rng
from locbench.datasets.dataset import Dataset, Landmarks
from locbench.registry import FILTERS, make_dataset, make_filter

_DATA: dict[int, Dataset] = {}


def tiled_office(copies: int) -> Dataset:
    """The office dataset (seed 0) with its landmark map repeated ``copies`` times, 100 m apart along x."""
    if copies not in _DATA:
        ds = make_dataset("office", 0)
        lm = ds.world.landmarks
        assert lm is not None
        step = float(np.ptp(lm.xy[:, 0])) + 100.0
        xy = np.concatenate([lm.xy + np.array([k * step, 0.0]) for k in range(copies)])
        ids = np.concatenate([lm.ids + k * (int(lm.ids.max()) + 1) for k in range(copies)])
        world = dataclasses.replace(ds.world, landmarks=Landmarks(ids=ids, xy=xy))
        _DATA[copies] = dataclasses.replace(ds, world=world)
    return _DATA[copies]


FILTER_IDS = ("ekf_landmarks", "ukf_landmarks", "gtsam_fls")


def replay(ds: Dataset, scan: bool, name: str = "ekf_landmarks") -> Any:
    """Run ``name[association=nearest]`` over ``ds``; ``scan`` tests every landmark (no index)."""
    flt = make_filter(f"{name}[association=nearest]")
    flt.reset(ds.initial, ds.world, ds.sensors, filter_rng(name, ds.name, 0))
    if scan:
        flt._index = None
    routed = flt.routed_events()
    means = []
    # the smoother costs about 30 times the EKF per event: a quarter of the run keeps its cases short
    events = ds.events if name != "gtsam_fls" else ds.events[: len(ds.events) // 4]
    for ev in events:
        if isinstance(ev, Odometry):
            flt.predict(ev)
        elif type(ev) in routed:
            flt.update(ev)
            means.append(flt.estimate().mean)
    return np.array(means)


def _available(name: str) -> Any:
    return pytest.mark.skipif(FILTERS.unavailable_reason(name) is not None, reason=f"{name} is not available")


@pytest.mark.parametrize("name", [pytest.param(n, marks=_available(n)) for n in FILTER_IDS])
@pytest.mark.parametrize("copies", [1, 16, 64])
@pytest.mark.parametrize("method", ["index", "scan"])
def test_nearest_association_map_size(benchmark: Any, name: str, copies: int, method: str) -> None:
    ds = tiled_office(copies)
    if benchmark.disabled and (copies > 16 or name != "ekf_landmarks"):
        pytest.skip("64 copies and the UKF and smoother only when benchmarking (nox -s perf)")
    benchmark.pedantic(replay, args=(ds, method == "scan", name), rounds=5, iterations=1)


@pytest.mark.parametrize("name", [pytest.param(n, marks=_available(n)) for n in FILTER_IDS])
def test_index_and_scan_associate_alike(name: str) -> None:
    """The tiled map's run is the office map's run, with the index and without."""
    base = replay(tiled_office(1), True, name)
    np.testing.assert_array_equal(replay(tiled_office(16), False, name), base)
    np.testing.assert_array_equal(replay(tiled_office(16), True, name), base)
