"""Conformance checks for filters and datasets.

Each check is a small named function, so that every (filter, check) pair is its own pytest id and its
own line in ``locbench check``. A filter declares the checks it is expected to fail, with the reason,
in its class attribute ``expected_check_failures = {"check_name": "why"}``; tests run those as strict
xfail. Checks run on the tiny registered scenarios ``tiny_line`` and ``tiny_circle``.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from locbench.datasets.base import Dataset, MapKind, check_dataset_contract
from locbench.errors import DependencyNotInstalled, LocbenchError, UnknownIdError
from locbench.events import EVENT_TYPES, OBSERVATION_TYPES, Odometry
from locbench.filters.base import Filter, FilterConfig
from locbench.geometry import is_symmetric_psd, pose_error
from locbench.registry import DATASETS, FILTERS, make_dataset, resolve_dataset, resolve_filter
from locbench.runner import FilterTrace, incompatibility, run_filter
from locbench.seeding import filter_rng

#: ATE tolerance on the noise-free tiny circle, m: exact data must give an almost exact track.
NOISE_FREE_ATE_TOL_M = 0.05
#: Bound on the position error anywhere on the noisy circle crossing +-pi, m.
WRAP_ERROR_BOUND_M = 1.0


class CheckFailed(AssertionError):
    """A conformance check did not hold; the message says what and where."""


@dataclass(frozen=True)
class CheckResult:
    target: str
    check: str
    outcome: str  # passed, failed, xfailed, xpassed, skipped
    message: str = ""


_DATA_CACHE: dict[tuple[str, int], Dataset] = {}


def _tiny(spec: str, seed: int = 0) -> Dataset:
    key = (spec, seed)
    if key not in _DATA_CACHE:
        _DATA_CACHE[key] = make_dataset(spec, seed)
    return _DATA_CACHE[key]


def _run(filter_spec: str, ds: Dataset, seed: int = 0) -> FilterTrace:
    fr = resolve_filter(filter_spec)
    flt = FILTERS.load(fr.id)(fr.params)
    reason = incompatibility(flt, ds)
    if reason is not None:
        raise CheckFailed(f"cannot run on the check scenario {ds.name}: {reason}")
    trace = run_filter(flt, ds, filter_rng(fr.name, ds.name, seed))
    if trace.status != "ok":
        raise CheckFailed(f"run on {ds.name} ended with status {trace.status}: {trace.message}")
    return trace


def _truth_at(ds: Dataset, t: np.ndarray) -> np.ndarray:
    gt = ds.ground_truth
    idx = np.clip(np.searchsorted(gt.t, t, side="right") - 1, 0, len(gt) - 1)
    return gt.poses[idx]


# --- filter checks ------------------------------------------------------------------------------


def check_contract(filter_spec: str) -> None:
    """consumes is non-empty and known and includes Odometry; requires holds MapKinds; __init__ does no work;
    an observation type the filter does not consume raises TypeError."""
    fr = resolve_filter(filter_spec)
    cls: type[Filter] = FILTERS.load(fr.id)
    if not cls.consumes or Odometry not in cls.consumes or not set(cls.consumes) <= set(EVENT_TYPES):
        raise CheckFailed(f"consumes must be a non-empty set of event types including Odometry, got {cls.consumes}")
    if not all(isinstance(k, MapKind) for k in cls.requires):
        raise CheckFailed(f"requires must hold MapKind members, got {cls.requires}")
    if not (dataclasses.is_dataclass(cls.Config) and issubclass(cls.Config, FilterConfig)):
        raise CheckFailed("Config must be a FilterConfig dataclass")
    if not cls.Config.__dataclass_params__.frozen:  # type: ignore[attr-defined]
        raise CheckFailed("Config must be frozen")
    start = time.perf_counter()
    flt = cls(fr.params)
    if time.perf_counter() - start > 0.05 or set(vars(flt)) - {"config"}:
        raise CheckFailed(f"__init__ must only store the config; it set {sorted(vars(flt))}")
    if not flt.routed_events() <= cls.consumes:
        raise CheckFailed("routed_events() must be a subset of consumes")
    ds = _tiny("tiny_line")
    flt.reset(ds.initial, ds.world, ds.sensors, np.random.default_rng(0))
    foreign = [t for t in OBSERVATION_TYPES if t not in cls.consumes]
    if foreign:
        sample = next((e for e in ds.events if type(e) is foreign[0]), None)
        if sample is not None:
            try:
                flt.update(sample)  # type: ignore[arg-type]
            except TypeError:
                pass
            else:
                raise CheckFailed(f"update({foreign[0].__name__}) must raise TypeError: it is not in consumes")


def check_determinism(filter_spec: str) -> None:
    """The same seed gives an identical trajectory; a reused instance after reset equals a fresh one."""
    ds = _tiny("tiny_circle")
    a, b = _run(filter_spec, ds), _run(filter_spec, ds)
    for name in ("t", "mean", "cov"):
        if not np.array_equal(getattr(a, name), getattr(b, name), equal_nan=True):
            raise CheckFailed(f"two runs with the same seed differ in {name}")
    fr = resolve_filter(filter_spec)
    flt = FILTERS.load(fr.id)(fr.params)
    run_filter(flt, _tiny("tiny_line"), filter_rng(fr.name, "tiny_line", 1))
    c = run_filter(flt, ds, filter_rng(fr.name, ds.name, 0))
    if not np.array_equal(a.mean, c.mean, equal_nan=True):
        raise CheckFailed("a reused instance after reset differs from a fresh one")


def check_estimate_sanity(filter_spec: str) -> None:
    """Every estimate has mean (3,), cov (3, 3), finite values, theta in (-pi, pi], symmetric PSD cov."""
    ds = _tiny("tiny_line")
    fr = resolve_filter(filter_spec)
    flt = FILTERS.load(fr.id)(fr.params)
    flt.reset(ds.initial, ds.world, ds.sensors, filter_rng(fr.name, ds.name, 0))
    routed = flt.routed_events()
    for ev in ds.events:
        if isinstance(ev, Odometry):
            flt.predict(ev)
        elif type(ev) in routed:
            flt.update(ev)
        else:
            continue
        est = flt.estimate()
        where = f"after {type(ev).__name__} at t={ev.t:.3f}"
        if np.shape(est.mean) != (3,) or np.shape(est.cov) != (3, 3):
            raise CheckFailed(f"{where}: mean {np.shape(est.mean)} / cov {np.shape(est.cov)}, expected (3,) / (3, 3)")
        if not (np.all(np.isfinite(est.mean)) and np.all(np.isfinite(est.cov))):
            raise CheckFailed(f"{where}: non-finite estimate")
        if not (-np.pi < est.mean[2] <= np.pi):
            raise CheckFailed(f"{where}: heading {est.mean[2]} not wrapped to (-pi, pi]")
        if not is_symmetric_psd(est.cov, atol=1e-9):
            raise CheckFailed(f"{where}: covariance not symmetric PSD:\n{est.cov}")


def check_heading_wrap(filter_spec: str) -> None:
    """On a circle whose heading crosses +-pi the estimate stays wrapped and its error bounded."""
    ds = _tiny("tiny_circle")
    tr = _run(filter_spec, ds)
    if np.any(tr.mean[:, 2] <= -np.pi) or np.any(tr.mean[:, 2] > np.pi):
        raise CheckFailed("heading left (-pi, pi]")
    err = pose_error(tr.mean, _truth_at(ds, tr.t))
    worst = float(np.max(np.hypot(err[:, 0], err[:, 1])))
    if worst > WRAP_ERROR_BOUND_M or float(np.max(np.abs(err[:, 2]))) > 0.5:
        raise CheckFailed(
            f"error while crossing +-pi: position {worst:.3f} m, heading {np.max(np.abs(err[:, 2])):.3f} rad"
        )


def check_noise_free(filter_spec: str) -> None:
    """On exact data (tiny_circle[noise_free=true]) the position RMSE stays under NOISE_FREE_ATE_TOL_M."""
    ds = _tiny("tiny_circle[noise_free=true]")
    tr = _run(filter_spec, ds)
    err = pose_error(tr.mean, _truth_at(ds, tr.t))
    ate = float(np.sqrt(np.mean(err[:, 0] ** 2 + err[:, 1] ** 2)))
    if ate > NOISE_FREE_ATE_TOL_M:
        raise CheckFailed(f"noise-free ATE {ate:.4f} m > {NOISE_FREE_ATE_TOL_M} m")


def check_predict_grows_uncertainty(filter_spec: str) -> None:
    """A predict-only run never lowers log det P (beyond a small tolerance for sampled filters)."""
    ds = _tiny("tiny_line")
    fr = resolve_filter(filter_spec)
    flt = FILTERS.load(fr.id)(fr.params)
    flt.reset(ds.initial, ds.world, ds.sensors, filter_rng(fr.name, ds.name, 0))
    prev = np.linalg.slogdet(flt.estimate().cov)[1]
    tol = float(getattr(flt, "logdet_tolerance", 1e-9))
    for ev in ds.events:
        if isinstance(ev, Odometry):
            flt.predict(ev)
            cur = np.linalg.slogdet(flt.estimate().cov)[1]
            if cur < prev - tol:
                raise CheckFailed(f"log det P fell from {prev:.4f} to {cur:.4f} on a predict at t={ev.t:.3f}")
            prev = cur


FILTER_CHECKS: dict[str, Callable[[str], None]] = {
    f.__name__: f
    for f in (
        check_contract,
        check_determinism,
        check_estimate_sanity,
        check_heading_wrap,
        check_noise_free,
        check_predict_grows_uncertainty,
    )
}


# --- dataset checks -----------------------------------------------------------------------------


def check_dataset_builds(dataset_spec: str) -> None:
    """The dataset builds and satisfies the contract (sorted events, covering truth, maps for observations)."""
    ds = make_dataset(dataset_spec, 0)
    check_dataset_contract(ds)


def check_dataset_determinism(dataset_spec: str) -> None:
    """The same seed gives the same events and truth; the realisation depends only on (name, seed)."""
    a, b = make_dataset(dataset_spec, 3), make_dataset(dataset_spec, 3)
    if len(a.events) != len(b.events) or not np.array_equal(a.ground_truth.poses, b.ground_truth.poses):
        raise CheckFailed("two builds with seed 3 differ")
    for k, (ea, eb) in enumerate(zip(a.events, b.events, strict=True)):
        if type(ea) is not type(eb) or not _event_equal(ea, eb):
            raise CheckFailed(f"two builds with seed 3 differ at events[{k}] ({type(ea).__name__})")


def _event_equal(a: Any, b: Any) -> bool:
    for f in dataclasses.fields(a):
        va, vb = getattr(a, f.name), getattr(b, f.name)
        if isinstance(va, np.ndarray):
            if not np.array_equal(va, vb, equal_nan=True):
                return False
        elif va != vb and not (isinstance(va, float) and np.isnan(va) and np.isnan(vb)):
            return False
    return True


DATASET_CHECKS: dict[str, Callable[[str], None]] = {
    f.__name__: f for f in (check_dataset_builds, check_dataset_determinism)
}


# --- running checks -----------------------------------------------------------------------------


def expected_failures(filter_id: str) -> dict[str, str]:
    """The checks a filter declares it fails, with reasons."""
    return dict(getattr(FILTERS.load(filter_id), "expected_check_failures", {}))


def run_checks(ids: list[str] | None = None) -> Iterator[CheckResult]:
    """Run every check for the given filter/dataset ids (all registered ones when None)."""
    if not ids:
        ids = FILTERS.ids() + DATASETS.ids()
    for spec in ids:
        ident = spec.split("[", 1)[0]
        if ident in FILTERS:
            checks, registry = FILTER_CHECKS, FILTERS
        elif ident in DATASETS:
            checks, registry = DATASET_CHECKS, DATASETS
        else:
            valid = ", ".join(FILTERS.ids() + DATASETS.ids())
            raise UnknownIdError(f"unknown filter or dataset {ident!r}; valid: {valid}")
        reason = registry.unavailable_reason(ident)
        if reason is not None:
            for name in checks:
                yield CheckResult(spec, name, "skipped", reason)
            continue
        # resolve now so a malformed spec is a clear error, not a failed check
        (resolve_filter if registry is FILTERS else resolve_dataset)(spec)
        xfail = expected_failures(ident) if registry is FILTERS else {}
        for name, fn in checks.items():
            try:
                fn(spec)
            except (CheckFailed, LocbenchError, AssertionError, TypeError, ValueError) as exc:
                if isinstance(exc, DependencyNotInstalled):
                    yield CheckResult(spec, name, "skipped", str(exc))
                elif name in xfail:
                    yield CheckResult(spec, name, "xfailed", xfail[name])
                else:
                    yield CheckResult(spec, name, "failed", f"{type(exc).__name__}: {exc}")
            else:
                if name in xfail:
                    yield CheckResult(spec, name, "xpassed", f"declared to fail ({xfail[name]}) but passed")
                else:
                    yield CheckResult(spec, name, "passed")
