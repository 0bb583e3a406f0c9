"""pytest-benchmark: ``gtsam_fls`` on a real event stream against a minimal fixed-lag smoother loop.

Run with ``nox -s perf``; in the normal test run (``--benchmark-disable``) each case runs once.

Both cases start from scratch every round (a fresh filter or smoother, set up outside the timing), so the
median does not depend on the number of rounds: a benchmark that replays one observation into one smoother
grows its graph with every call.

- ``filter``: ``gtsam_fls`` (its defaults) over the first ``N_OBS`` observations of ``office`` (seed 0) and the
  odometry between them: every predict and update call, as the runner makes them.
- ``minimal``: the floor the runner's protocol allows (an estimate after every event): a minimal loop that
  builds the same graph from the same events with a bare ``IncrementalFixedLagSmoother`` of the same
  parameters. Odometry is composed onto the newest pose (the shared motion model and covariance
  propagation) and the estimate is that composition; each sighting adds the between factor of the composed
  odometry, a new pose, its bearing-range factors and a prior for a landmark that is new to the window,
  updates the smoother and reads the newest pose and its marginal. No gating, no diagnostics, no checks.
  A test checks that its estimates equal the filter's (1e-6 m, rad), so the ratio filter / minimal is the
  wrapper's own cost over the protocol's floor.
- ``wrapper``: the ``filter`` case with its smoother replaced by a stub that hands back the answers recorded
  from a real run (update results, poses, marginals) without computing anything: the wrapper's own Python
  cost. ``filter`` minus ``wrapper`` is what the gtsam calls cost inside the filter, which can exceed
  ``minimal`` (docs/history/performance.md).

Each case stores the median time per observation in ``extra_info`` (``us_per_obs``); the session prints both
and their ratio.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest

gtsam = pytest.importorskip("gtsam")

from locbench.core.events import Odometry  # noqa: E402
from locbench.core.geometry import wrap_scalar  # noqa: E402
from locbench.datasets.dataset import Dataset  # noqa: E402
from locbench.filters._motion import MotionModel, propagate_covariance  # noqa: E402
from locbench.filters._noise import process_noise  # noqa: E402
from locbench.filters.gtsam_fls import MIN_PROCESS_SIGMA, GtsamFixedLagSmoother, _rotate_cov  # noqa: E402
from locbench.registry import make_dataset, resolve_filter  # noqa: E402

_X = gtsam.symbol_shorthand.X
_L = gtsam.symbol_shorthand.L

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


def _run(flt: GtsamFixedLagSmoother, events: list[Any]) -> list[tuple[Any, Any]]:
    """Every predict and update call as the runner makes them, and the estimate (mean, cov) after each."""
    out = []
    for ev in events:
        if isinstance(ev, Odometry):
            flt.predict(ev)
        else:
            flt.update(ev)
        est = flt.estimate()
        out.append((est.mean, est.cov))
    return out


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


def _world_cov(pose: Any, cov_body: Any) -> list[list[float]]:
    c, s = math.cos(pose.theta()), math.sin(pose.theta())
    r = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    b = np.asarray(cov_body)
    return (r @ (0.5 * (b + b.T)) @ r.T).tolist()


def minimal_loop(ds: Dataset, events: list[Any], smoother: Any) -> list[tuple[tuple[float, float, float], Any]]:
    """The protocol's floor: the filter's graph from the same events, an estimate (mean, covariance) after
    every event.

    Known landmark ids only (``office`` gives them), ``new_pose="observation"``; the filter's defaults.
    """
    cfg = resolve_filter("gtsam_fls").params
    motion = MotionModel(cfg.motion_noise(ds.sensors), cfg.motion_model, mean="model")
    sxy, _, sth = process_noise(cfg.sigma_xy_m, cfg.sigma_xy_m, cfg.sigma_theta_rad, ds.sensors)
    qxy, qth = max(sxy, MIN_PROCESS_SIGMA[0]) ** 2, max(sth, MIN_PROCESS_SIGMA[1]) ** 2
    sr, sb = ds.sensors.landmark_sigma_range_m, ds.sensors.landmark_sigma_bearing_rad
    br_noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([sb, sr]))
    lm = ds.world.landmarks
    lm_row, lm_xy = lm.index_of(), np.asarray(lm.xy, dtype=np.float64).reshape(-1, 2)
    lm_noise = gtsam.noiseModel.Isotropic.Sigma(2, cfg.landmark_sigma_m)
    m = ds.initial.mean
    node = gtsam.Pose2(float(m[0]), float(m[1]), float(m[2]))
    c0 = np.asarray(ds.initial.cov)
    r0 = np.array([[math.cos(m[2]), -math.sin(m[2]), 0], [math.sin(m[2]), math.cos(m[2]), 0], [0, 0, 1.0]])
    prior = gtsam.PriorFactorPose2(_X(0), node, gtsam.noiseModel.Gaussian.Covariance(r0.T @ c0 @ r0))
    node_cov = c0.tolist()
    n_nodes, n_lm, last_update = 1, 0, -math.inf
    lm_key: dict[int, int] = {}
    lm_stamp: dict[int, float] = {}
    delta, delta_cov, steps = (0.0, 0.0, 0.0), [[0.0] * 3 for _ in range(3)], 0
    t0 = math.nan
    out: list[tuple[tuple[float, float, float], Any]] = []
    for ev in events:
        if isinstance(ev, Odometry):
            if math.isnan(t0):
                t0 = ev.t - ev.dt if ev.dt is not None else ev.t
            st = motion.step(delta, ev)
            n = st.noise
            delta_cov = propagate_covariance(
                delta_cov, st.f02, st.f12, (n[0] + qxy, n[1], n[2], n[3] + qxy, n[4], n[5] + qth)
            )
            delta, steps = st.pose, steps + 1
            # the estimate: newest pose (+) increment, F P_w F' + R Sigma R' in world coordinates
            c, s = math.cos(node.theta()), math.sin(node.theta())
            ex, ey = c * delta[0] - s * delta[1], s * delta[0] + c * delta[1]
            cov = propagate_covariance(node_cov, -ey, ex, _rotate_cov(c, s, delta_cov))
            out.append(((node.x() + ex, node.y() + ey, wrap_scalar(node.theta() + delta[2])), cov))
            continue
        if math.isnan(t0):
            t0 = ev.t
        factors, values, stamps = gtsam.NonlinearFactorGraph(), gtsam.Values(), {}
        if prior is not None:
            factors.add(prior)
            values.insert(_X(0), node)
            stamps[_X(0)] = t0
            prior = None
        key = _X(n_nodes - 1)
        if steps:
            key = _X(n_nodes)
            inc = gtsam.Pose2(*delta)
            c, s = math.cos(delta[2]), math.sin(delta[2])
            rd = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
            dc = np.asarray(delta_cov)
            noise = gtsam.noiseModel.Gaussian.Covariance(0.5 * (rd.T @ dc @ rd + (rd.T @ dc @ rd).T))
            factors.add(gtsam.BetweenFactorPose2(_X(n_nodes - 1), key, inc, noise))
            values.insert(key, node.compose(inc))
            stamps[key] = ev.t
            n_nodes += 1
        for ident, r, b in zip(ev.ids.tolist(), ev.ranges.tolist(), ev.bearings.tolist(), strict=True):
            row = lm_row[ident]
            lk = lm_key.get(row)
            if lk is None or lm_stamp[row] < last_update - cfg.lag_s:
                lk = lm_key[row] = _L(n_lm)
                n_lm += 1
                factors.add(gtsam.PriorFactorPoint2(lk, lm_xy[row], lm_noise))
                values.insert(lk, lm_xy[row])
            lm_stamp[row] = ev.t
            factors.add(gtsam.BearingRangeFactor2D(key, lk, gtsam.Rot2.fromAngle(b), r, br_noise))
            stamps[lk] = ev.t
        smoother.update(factors, values, stamps)
        last_update = ev.t
        node = smoother.calculateEstimatePose2(key)
        node_cov = _world_cov(node, smoother.marginalCovariance(key))
        delta, delta_cov, steps = (0.0, 0.0, 0.0), [[0.0] * 3 for _ in range(3)], 0
        out.append(((node.x(), node.y(), node.theta()), node_cov))
    return out


def test_minimal_loop_builds_the_filters_graph(office: Dataset) -> None:
    events, _, make, _ = _record(office)
    assert office.world.landmarks is not None and office.world.landmarks.std_xy is None
    mine, theirs = minimal_loop(office, events, make()), _run(_fresh_filter(office), events)
    assert len(mine) == len(theirs) == len(events)
    np.testing.assert_allclose(np.array([m for m, _ in mine]), np.array([m for m, _ in theirs]), rtol=0, atol=1e-6)
    np.testing.assert_allclose(np.array([c for _, c in mine]), np.array([c for _, c in theirs]), rtol=1e-5, atol=1e-10)


def test_minimal_fixed_lag_loop(benchmark: Any, office: Dataset) -> None:
    events, _, make, _ = _record(office)
    benchmark.pedantic(minimal_loop, setup=lambda: ((office, events, make()), {}), rounds=7, warmup_rounds=1)
    _store(benchmark, "minimal")


def test_gtsam_fls_wrapper_alone(benchmark: Any, office: Dataset) -> None:
    events, _, _, answers = _record(office)

    def stubbed() -> GtsamFixedLagSmoother:
        flt = _fresh_filter(office)
        flt._make_smoother = lambda: _Stub(answers)  # type: ignore[method-assign]
        return flt

    benchmark.pedantic(_run, setup=lambda: ((stubbed(), events), {}), rounds=7, warmup_rounds=1)
    _store(benchmark, "wrapper")
