"""pytest-benchmark: ``gtsam_fls`` on a real event stream against a minimal fixed-lag smoother loop.

Run with ``nox -s perf``; in the normal test run (``--benchmark-disable``) each case runs once.

Both cases start from scratch every round (a fresh filter or smoother, set up outside the timing), so the
median does not depend on the number of rounds: a benchmark that replays one observation into one smoother
grows its graph with every call.

- ``filter``: ``gtsam_fls`` (its defaults) over the first ``N_OBS`` observations of ``office`` (seed 0) and the
  odometry between them: every predict and update call, as the runner makes them.
- ``minimal``: the same smoother inputs, recorded from that run (each update's new factors, initial values and
  time stamps), replayed into a bare ``IncrementalFixedLagSmoother`` with the same parameters, reading after
  each update what a filter must report: the newest pose and its marginal covariance. This is the floor a
  fixed-lag-smoother filter on gtsam cannot go below; the ratio filter / minimal is the wrapper's cost
  (odometry composition, association and gating, the factor building).
- ``wrapper``: the ``filter`` case with its smoother replaced by a stub that hands back the answers recorded
  from a real run (update results, poses, marginals) without computing anything: the wrapper's own Python
  cost. ``filter`` minus ``wrapper`` is what the gtsam calls cost inside the filter, which can exceed
  ``minimal`` (docs/performance.md).

Each case stores the median time per observation in ``extra_info`` (``us_per_obs``); the session prints both
and their ratio.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest

gtsam = pytest.importorskip("gtsam")

from locbench.datasets.base import Dataset  # noqa: E402
from locbench.events import Odometry  # noqa: E402
from locbench.filters.gtsam_fls import GtsamFixedLagSmoother  # noqa: E402
from locbench.registry import make_dataset, resolve_filter  # noqa: E402

#: Observations per round: about 100 s of ``office``, long enough for the window to fill and slide.
N_OBS = 500
_MEDIANS: dict[str, float] = {}


class _Recorder:
    """Stands in for the smoother: records every update's inputs and every answer, forwarding all to it."""

    def __init__(self, smoother: Any, log: list[tuple[Any, Any, dict[int, float]]], answers: list[Any]) -> None:
        self._smoother = smoother
        self._log = log
        self._answers = answers

    def update(self, factors: Any, values: Any, stamps: dict[int, float]) -> Any:
        self._log.append((factors, values, dict(stamps)))
        return self._answer(self._smoother.update(factors, values, stamps))

    def calculateEstimatePose2(self, key: int) -> Any:  # noqa: N802 - gtsam's name
        return self._answer(self._smoother.calculateEstimatePose2(key))

    def marginalCovariance(self, key: int) -> Any:  # noqa: N802 - gtsam's name
        return self._answer(self._smoother.marginalCovariance(key))

    def _answer(self, value: Any) -> Any:
        self._answers.append(value)
        return value

    def __getattr__(self, name: str) -> Any:
        return getattr(self._smoother, name)


class _Stub:
    """Answers the filter's smoother calls, in order, with the recorded answers; computes nothing."""

    def __init__(self, answers: list[Any]) -> None:
        self._answers = iter(answers)

    def _next(self, *_: Any) -> Any:
        return next(self._answers)

    update = calculateEstimatePose2 = marginalCovariance = _next  # noqa: N815 - gtsam's names


def _stream(ds: Dataset, routed: frozenset[type]) -> list[Any]:
    out, n_obs = [], 0
    for ev in ds.events:
        if isinstance(ev, Odometry):
            out.append(ev)
        elif type(ev) in routed:
            out.append(ev)
            n_obs += 1
            if n_obs == N_OBS:
                break
    return out


@pytest.fixture(scope="module")
def office() -> Dataset:
    return make_dataset("office", 0)


@pytest.fixture(scope="module", autouse=True)
def gtsam_summary(request: pytest.FixtureRequest) -> Iterator[None]:
    yield
    if {"filter", "minimal"} <= _MEDIANS.keys():
        reporter = request.config.pluginmanager.get_plugin("terminalreporter")
        if reporter is not None:
            reporter.write_line("")
            for name, us in sorted(_MEDIANS.items()):
                reporter.write_line(f"gtsam_fls {name:<8} {us:8.1f} us per observation (median round / {N_OBS})")
            reporter.write_line(f"gtsam_fls filter / minimal {_MEDIANS['filter'] / _MEDIANS['minimal']:8.2f} x")
            if "wrapper" in _MEDIANS:
                reporter.write_line(f"gtsam_fls wrapper / minimal {_MEDIANS['wrapper'] / _MEDIANS['minimal']:7.2f} x")


def _fresh_filter(ds: Dataset) -> GtsamFixedLagSmoother:
    fr = resolve_filter("gtsam_fls")
    flt = GtsamFixedLagSmoother(fr.params)
    flt.reset(ds.initial, ds.world, ds.sensors, np.random.default_rng(0))
    return flt


def _run(flt: GtsamFixedLagSmoother, events: list[Any]) -> None:
    for ev in events:
        if isinstance(ev, Odometry):
            flt.predict(ev)
        else:
            flt.update(ev)
        flt.estimate()


def _record(
    ds: Dataset,
) -> tuple[list[Any], list[tuple[Any, Any, dict[int, float]]], Callable[[], Any], list[Any]]:
    flt = _fresh_filter(ds)
    events = _stream(ds, flt.routed_events())
    log: list[tuple[Any, Any, dict[int, float]]] = []
    answers: list[Any] = []
    make = flt._make_smoother
    flt._make_smoother = lambda: _Recorder(make(), log, answers)  # type: ignore[method-assign]
    _run(flt, events)
    return events, log, make, answers


def _store(benchmark: Any, name: str) -> None:
    if not benchmark.disabled:
        us = 1e6 * float(benchmark.stats.stats.median) / N_OBS
        benchmark.extra_info["us_per_obs"] = us
        _MEDIANS[name] = us


def test_gtsam_fls_stream(benchmark: Any, office: Dataset) -> None:
    events, _, _, _ = _record(office)
    benchmark.pedantic(_run, setup=lambda: ((_fresh_filter(office), events), {}), rounds=7, warmup_rounds=1)
    _store(benchmark, "filter")


def newest_pose_keys(log: list[tuple[Any, Any, dict[int, float]]]) -> list[int]:
    """The newest pose after each recorded update (the one the filter reports), found outside the timing."""
    newest, pose_keys = [], []
    for _, _, stamps in log:
        pose_keys += sorted(k for k in stamps if gtsam.Symbol(k).chr() == ord("x"))
        newest.append(pose_keys[-1])
    return newest


def replay(smoother: Any, log: list[tuple[Any, Any, dict[int, float]]], newest: list[int]) -> None:
    """The minimal loop: each recorded update, then the newest pose and its marginal covariance."""
    for (factors, values, stamps), key in zip(log, newest, strict=True):
        smoother.update(factors, values, stamps)
        smoother.calculateEstimatePose2(key)
        smoother.marginalCovariance(key)


def test_minimal_fixed_lag_loop(benchmark: Any, office: Dataset) -> None:
    _, log, make, _ = _record(office)
    assert len(log) > 0.9 * N_OBS  # nearly every observation updated the smoother
    newest = newest_pose_keys(log)
    benchmark.pedantic(replay, setup=lambda: ((make(), log, newest), {}), rounds=7, warmup_rounds=1)
    _store(benchmark, "minimal")


def test_gtsam_fls_wrapper_alone(benchmark: Any, office: Dataset) -> None:
    events, _, _, answers = _record(office)

    def stubbed() -> GtsamFixedLagSmoother:
        flt = _fresh_filter(office)
        flt._make_smoother = lambda: _Stub(answers)  # type: ignore[method-assign]
        return flt

    benchmark.pedantic(_run, setup=lambda: ((stubbed(), events), {}), rounds=7, warmup_rounds=1)
    _store(benchmark, "wrapper")
