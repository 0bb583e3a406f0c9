"""pytest-benchmark micro-benchmarks: one predict and one update call of every registered filter.

Run with ``nox -s perf``; in the normal test run they execute once (``--benchmark-disable``) as smoke tests.
Each filter is reset on the office dataset (seed 0) and advanced to the middle of the run, so the
benchmarked calls see a realistic state; then one event is replayed many times.
"""

from __future__ import annotations

from typing import Any

import pytest

from locbench.core.events import Odometry
from locbench.core.seeding import filter_rng
from locbench.datasets.dataset import Dataset
from locbench.registry import FILTERS, make_dataset, resolve_filter

_DATA: dict[str, Dataset] = {}


def _office() -> Dataset:
    if "office" not in _DATA:
        _DATA["office"] = make_dataset("office", 0)
    return _DATA["office"]


def _warm_filter(fid: str) -> tuple[Any, Dataset]:
    ds = _office()
    fr = resolve_filter(fid)
    flt = FILTERS.load(fid)(fr.params)
    flt.reset(ds.initial, ds.world, ds.sensors, filter_rng(fr.name, ds.name, 0))
    routed = flt.routed_events()
    for ev in ds.events[: len(ds.events) // 2]:
        if isinstance(ev, Odometry):
            flt.predict(ev)
        elif type(ev) in routed:
            flt.update(ev)
    return flt, ds


def _cases(kind: str) -> list[Any]:
    out = []
    for fid in FILTERS.ids():
        if FILTERS.unavailable_reason(fid) is None:
            out.append(pytest.param(fid, id=f"{fid}-{kind}"))
    return out


@pytest.mark.parametrize("fid", _cases("predict"))
def test_predict(benchmark: Any, fid: str) -> None:
    flt, ds = _warm_filter(fid)
    u = next(e for e in ds.events[len(ds.events) // 2 :] if isinstance(e, Odometry))
    # repeated calls move the state a little; an EKF's or PF's cost per call does not depend on it
    benchmark(flt.predict, u)


@pytest.mark.parametrize("fid", _cases("update"))
def test_update(benchmark: Any, fid: str) -> None:
    if fid == "gtsam_fls":
        # every replayed observation would add to one smoother's graph, so the median would depend on the
        # round count: test_gtsam_perf.py times it on a real event stream with a fresh smoother per round
        pytest.skip("gtsam_fls updates are benchmarked on an event stream in test_gtsam_perf.py")
    flt, ds = _warm_filter(fid)
    routed = flt.routed_events() - {Odometry}
    if not routed:
        pytest.skip(f"{fid} consumes no observations")
    z = next((e for e in ds.events[len(ds.events) // 2 :] if type(e) in routed), None)
    if z is None:
        pytest.skip(f"office has none of the observations {fid} uses")
    benchmark(flt.update, z)
