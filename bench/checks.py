"""Conformance checks for filters and datasets, after scikit-learn's ``check_estimator``.

A filter check takes a filter class or instance (so a filter can be checked before it is registered), runs it
through the runner's own loop (:func:`locbench.run.filter_pass.run_filter`, which resets it, routes each event to
``predict`` or ``update`` and reads ``estimate()`` after every call) and raises :class:`CheckFailed` when the
filter breaks the contract. Each check declares when it applies, from the filter's declared capabilities
(``consumes``, ``requires``, ``routed_events()``); :func:`yield_filter_checks` yields the ones that apply and
:func:`check_filter` runs them. The hooks a check reads are declared on :class:`~locbench.filters.base.Filter`:
``expected_check_failures`` (checks the filter fails by design, with the reason; run as strict xfail) and
``check_tolerances()`` (the bounds it is held to). Checks run on the tiny registered scenarios ``tiny_line``
and ``tiny_circle``; every check is shown to reject a deliberately broken filter in ``tests/test_checks.py``.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from locbench.core.errors import DependencyNotInstalled, LocbenchError, UnknownIdError
from locbench.core.events import EVENT_TYPES, OBSERVATION_TYPES, LandmarkObservations, Odometry, RangeObservations
from locbench.core.geometry import is_symmetric_psd, pose_error
from locbench.core.seeding import belief_rng, filter_rng
from locbench.core.spec import Spec
from locbench.datasets.dataset import Dataset, MapKind, check_dataset_contract
from locbench.filters.base import HEALTH_SIGNALS, Filter, FilterConfig
from locbench.registry import DATASETS, FILTERS, make_dataset, make_filter, resolve_dataset, resolve_filter
from locbench.run.filter_pass import FilterTrace, incompatibility, run_filter

#: What a filter check accepts: a filter instance, or a class (checked with its default config).
FilterLike = Filter | type[Filter]

#: The scenarios every run-based check uses; a filter must be able to run on them for those checks to apply.
CHECK_SCENARIOS = ("tiny_line", "tiny_circle")


class CheckFailed(AssertionError):
    """A conformance check did not hold; the message says what and where."""


@dataclass(frozen=True)
class CheckResult:
    target: str
    check: str
    outcome: str  # passed, failed, xfailed, xpassed, skipped
    message: str = ""


@dataclass(frozen=True)
class FilterCheck:
    """A named check and the capability rule that selects it.

    ``applies(flt)`` returns None when the check applies to ``flt``, else why it does not.
    """

    name: str
    run: Callable[[Filter], None]
    applies: Callable[[Filter], str | None]

    def __call__(self, target: FilterLike) -> None:
        self.run(as_filter(target))


_DATA_CACHE: dict[tuple[str, int], Dataset] = {}


def _tiny(spec: str, seed: int = 0) -> Dataset:
    key = (spec, seed)
    if key not in _DATA_CACHE:
        _DATA_CACHE[key] = make_dataset(spec, seed)
    return _DATA_CACHE[key]


def as_filter(target: FilterLike) -> Filter:
    """An instance of ``target``: the instance itself, or the class with its default config."""
    return target() if isinstance(target, type) else target


def _fresh(flt: Filter) -> Filter:
    """A new, un-reset instance of the same class and config."""
    return type(flt)(flt.config)


def _run(flt: Filter, ds: Dataset, seed: int = 0) -> FilterTrace:
    """One pass of the runner's loop; the trace must end with status ok."""
    reason = incompatibility(flt, ds)
    if reason is not None:
        raise CheckFailed(f"cannot run on the check scenario {ds.name}: {reason}")
    trace = run_filter(flt, ds, filter_rng(type(flt).__name__, ds.name, seed))
    if trace.status != "ok":
        raise CheckFailed(f"run on {ds.name} ended with status {trace.status}: {trace.message}")
    return trace


def _truth_at(ds: Dataset, t: np.ndarray) -> np.ndarray:
    gt = ds.ground_truth
    idx = np.clip(np.searchsorted(gt.t, t, side="right") - 1, 0, len(gt) - 1)
    return gt.poses[idx]


# --- capability rules -----------------------------------------------------------------------------------


def _always(flt: Filter) -> str | None:
    return None


def _runs_on_check_scenarios(flt: Filter) -> str | None:
    """The filter's required map kinds and routed observations exist in the check scenarios."""
    for spec in CHECK_SCENARIOS:
        reason = incompatibility(flt, _tiny(spec))
        if reason is not None:
            return f"not applicable: {reason}"
    return None


def _foreign_observation(flt: Filter) -> Any | None:
    """An observation of a type the filter does not consume, from ``tiny_line``; None if there is none."""
    cls = type(flt)
    foreign = {t for t in OBSERVATION_TYPES if t not in cls.consumes}
    return next((e for e in _tiny("tiny_line").events if type(e) in foreign), None)


def _has_foreign_observation(flt: Filter) -> str | None:
    if _foreign_observation(flt) is None:
        return "not applicable: the filter consumes every observation type of the check scenarios"
    return None


def _consumes_point_observations(flt: Filter) -> str | None:
    routed = flt.routed_events()
    if not routed & {LandmarkObservations, RangeObservations}:
        return "not applicable: routes neither LandmarkObservations nor RangeObservations"
    return _runs_on_check_scenarios(flt)


# --- filter checks ------------------------------------------------------------------------------------------


def check_contract(flt: Filter) -> None:
    """consumes is non-empty and known and includes Odometry; requires holds MapKinds; Config is a frozen
    FilterConfig dataclass; __init__ does no work; routed_events() is a subset of consumes."""
    cls = type(flt)
    if not cls.consumes or Odometry not in cls.consumes or not set(cls.consumes) <= set(EVENT_TYPES):
        raise CheckFailed(f"consumes must be a non-empty set of event types including Odometry, got {cls.consumes}")
    if not all(isinstance(k, MapKind) for k in cls.requires):
        raise CheckFailed(f"requires must hold MapKind members, got {cls.requires}")
    if not (dataclasses.is_dataclass(cls.Config) and issubclass(cls.Config, FilterConfig)):
        raise CheckFailed("Config must be a FilterConfig dataclass")
    if not cls.Config.__dataclass_params__.frozen:  # type: ignore[attr-defined]
        raise CheckFailed("Config must be frozen")
    if not isinstance(flt.config, cls.Config):
        raise CheckFailed(f"config must be a {cls.Config.__name__}, got {type(flt.config).__name__}")
    start = time.perf_counter()
    new = cls(flt.config)
    if time.perf_counter() - start > 0.05 or set(vars(new)) - {"config"}:
        raise CheckFailed(f"__init__ must only store the config; it set {sorted(vars(new))}")
    if not new.routed_events() <= cls.consumes:
        raise CheckFailed("routed_events() must be a subset of consumes")


def check_rejects_unconsumed(flt: Filter) -> None:
    """update() with an observation type the filter does not consume raises TypeError."""
    sample = _foreign_observation(flt)
    assert sample is not None  # guaranteed by the rule that selects this check
    new = _fresh(flt)
    ds = _tiny("tiny_line")
    new.reset(ds.initial, ds.world, ds.sensors, np.random.default_rng(0))
    try:
        new.update(sample)
    except TypeError:
        return
    raise CheckFailed(f"update({type(sample).__name__}) must raise TypeError: it is not in consumes")


def check_determinism(flt: Filter) -> None:
    """The same seed gives an identical trajectory; a reused instance after reset equals a fresh one."""
    ds = _tiny("tiny_circle")
    a, b = _run(_fresh(flt), ds), _run(_fresh(flt), ds)
    for name in ("t", "mean", "cov"):
        if not np.array_equal(getattr(a, name), getattr(b, name), equal_nan=True):
            raise CheckFailed(f"two runs with the same seed differ in {name}")
    reused = _fresh(flt)
    _run(reused, _tiny("tiny_line"), seed=1)
    c = _run(reused, ds)
    if not np.array_equal(a.mean, c.mean, equal_nan=True):
        raise CheckFailed("a reused instance after reset differs from a fresh one")


def check_estimate_sanity(flt: Filter) -> None:
    """Every estimate has mean (3,), cov (3, 3), finite values, theta in (-pi, pi], symmetric PSD cov."""
    tr = _run(_fresh(flt), _tiny("tiny_line"))
    for k in range(tr.t.shape[0]):
        mean, cov = tr.mean[k], tr.cov[k]
        where = f"at row {k} (t={tr.t[k]:.3f})"
        if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(cov))):
            raise CheckFailed(f"{where}: non-finite estimate")
        if not (-np.pi < mean[2] <= np.pi):
            raise CheckFailed(f"{where}: heading {mean[2]} not wrapped to (-pi, pi]")
        if not is_symmetric_psd(cov, atol=1e-9):
            raise CheckFailed(f"{where}: covariance not symmetric PSD:\n{cov}")


def check_heading_wrap(flt: Filter) -> None:
    """On a circle whose heading crosses +-pi the estimate stays wrapped and its error bounded."""
    tol = flt.check_tolerances()
    ds = _tiny("tiny_circle")
    tr = _run(_fresh(flt), ds)
    if np.any(tr.mean[:, 2] <= -np.pi) or np.any(tr.mean[:, 2] > np.pi):
        raise CheckFailed("heading left (-pi, pi]")
    err = pose_error(tr.mean, _truth_at(ds, tr.t))
    worst = float(np.max(np.hypot(err[:, 0], err[:, 1])))
    worst_heading = float(np.max(np.abs(err[:, 2])))
    if worst > tol.wrap_position_m or worst_heading > tol.wrap_heading_rad:
        raise CheckFailed(f"error while crossing +-pi: position {worst:.3f} m, heading {worst_heading:.3f} rad")


def check_noise_free(flt: Filter) -> None:
    """On exact data (tiny_circle[noise_free=true]) the position RMSE stays under the filter's tolerance."""
    tol = flt.check_tolerances().noise_free_ate_m
    ds = _tiny("tiny_circle[noise_free=true]")
    tr = _run(_fresh(flt), ds)
    err = pose_error(tr.mean, _truth_at(ds, tr.t))
    ate = float(np.sqrt(np.mean(err[:, 0] ** 2 + err[:, 1] ** 2)))
    if ate > tol:
        raise CheckFailed(f"noise-free ATE {ate:.4f} m > {tol} m")


def check_predict_grows_uncertainty(flt: Filter) -> None:
    """A predict-only run (tiny_line's odometry alone) never lowers log det P beyond the filter's tolerance."""
    tol = flt.check_tolerances().logdet_drop
    full = _tiny("tiny_line")
    ds = dataclasses.replace(full, events=tuple(e for e in full.events if isinstance(e, Odometry)))
    tr = run_filter(_fresh(flt), ds, filter_rng(type(flt).__name__, full.name, 0))
    if tr.status != "ok":
        raise CheckFailed(f"predict-only run ended with status {tr.status}: {tr.message}")
    logdet = np.linalg.slogdet(tr.cov)[1]
    drops = np.diff(logdet)
    k = int(np.argmin(drops)) if drops.size else 0
    if drops.size and drops[k] < -tol:
        raise CheckFailed(
            f"log det P fell from {logdet[k]:.4f} to {logdet[k + 1]:.4f} on a predict at t={tr.t[k + 1]:.3f}"
        )


def check_empty_observation(flt: Filter) -> None:
    """An observation event with no sightings (or ranges) leaves the estimate unchanged."""
    full = _tiny("tiny_line")
    cut = len(full.events) // 3
    new = _fresh(flt)
    # The runner's loop over the first third of the run, so that the belief is not the initial one.
    tr = run_filter(
        new, dataclasses.replace(full, events=full.events[:cut]), filter_rng(type(flt).__name__, full.name, 0)
    )
    if tr.status != "ok":
        raise CheckFailed(f"run on {full.name} ended with status {tr.status}: {tr.message}")
    routed = new.routed_events()
    empty_ids, empty = np.zeros(0, dtype=np.int64), np.zeros(0)
    t = full.events[cut].t
    for z in (LandmarkObservations(t, empty_ids, empty, empty), RangeObservations(t, empty_ids, empty)):
        if type(z) not in routed:
            continue
        before = new.estimate()
        new.update(z)
        after = new.estimate()
        if not (np.array_equal(before.mean, after.mean) and np.array_equal(before.cov, after.cov)):
            raise CheckFailed(f"an empty {type(z).__name__} changed the estimate from {before.mean} to {after.mean}")


def check_health_and_scores(flt: Filter) -> None:
    """``health()`` gives named floats from :data:`HEALTH_SIGNALS` at every step; drawing belief samples (the
    runner's generator) changes no estimate; the four proper scores of the run are finite."""
    from locbench.evaluate.metrics import align
    from locbench.evaluate.scores import SCORE_IDS, score_metrics

    ds = _tiny("tiny_circle")
    plain = _run(_fresh(flt), ds)
    reason = incompatibility(flt, ds)
    if reason is not None:  # pragma: no cover - _run raised already
        raise CheckFailed(reason)
    sampled = run_filter(_fresh(flt), ds, filter_rng(type(flt).__name__, ds.name, 0), belief_rng("check", ds.name, 0))
    for name in ("t", "mean", "cov"):
        if not np.array_equal(getattr(plain, name), getattr(sampled, name), equal_nan=True):
            raise CheckFailed(f"drawing belief samples changed the estimates ({name})")
    if not sampled.health:
        raise CheckFailed("health() reported no signal")
    unknown = sorted(set(sampled.health) - set(HEALTH_SIGNALS))
    if unknown:
        raise CheckFailed(f"health() reports signals not in HEALTH_SIGNALS: {unknown}")
    gt = ds.ground_truth
    scores = score_metrics(align(sampled.t, sampled.mean, gt.t, gt.poses, sampled.cov), sampled.extra)
    bad = {k: scores[k] for k in SCORE_IDS if not np.isfinite(scores[k])}
    if bad:
        raise CheckFailed(f"proper scores not finite: {bad}")


FILTER_CHECKS: dict[str, FilterCheck] = {
    c.name: c
    for c in (
        FilterCheck("check_contract", check_contract, _always),
        FilterCheck("check_rejects_unconsumed", check_rejects_unconsumed, _has_foreign_observation),
        FilterCheck("check_determinism", check_determinism, _runs_on_check_scenarios),
        FilterCheck("check_estimate_sanity", check_estimate_sanity, _runs_on_check_scenarios),
        FilterCheck("check_heading_wrap", check_heading_wrap, _runs_on_check_scenarios),
        FilterCheck("check_noise_free", check_noise_free, _runs_on_check_scenarios),
        FilterCheck("check_predict_grows_uncertainty", check_predict_grows_uncertainty, _always),
        FilterCheck("check_empty_observation", check_empty_observation, _consumes_point_observations),
        FilterCheck("check_health_and_scores", check_health_and_scores, _runs_on_check_scenarios),
    )
}


def yield_filter_checks(target: FilterLike) -> Iterator[tuple[FilterCheck, str | None]]:
    """Every filter check with None when it applies to ``target``, else why not (scikit-learn's
    ``_yield_all_checks``, chosen by the filter's declared capabilities)."""
    flt = as_filter(target)
    for check in FILTER_CHECKS.values():
        yield check, check.applies(flt)


def check_specs(filter_id: str) -> list[str]:
    """The configurations of a registered filter that the checks run (canonical names): its default, each of
    its ``check_configurations`` and its kidnap configuration (``kidnap_params``)."""
    cls: type[Filter] = FILTERS.load(filter_id)
    out: list[str] = []
    for params in ({}, *cls.check_configurations, *([cls.kidnap_params] if cls.kidnap_params else [])):
        name = resolve_filter(Spec(filter_id, tuple(params.items())).name).name
        if name not in out:
            out.append(name)
    return out


def marking(flt: Filter, check: FilterCheck) -> tuple[str, str] | None:
    """The one marking policy of ``locbench check`` and the pytest conformance tests: ``("skip", why)`` when
    the check does not apply to the filter's declared capabilities, ``("xfail", why)`` when the filter declares
    it fails (strict: passing it anyway is a failure of the declaration), None to run it plainly."""
    reason = check.applies(flt)
    if reason is not None:
        return ("skip", reason)
    declared = type(flt).declared_check_failures(flt.config)
    if check.name in declared:
        return ("xfail", declared[check.name])
    return None


def check_filter(target: FilterLike, name: str | None = None) -> Iterator[CheckResult]:
    """Run every check that applies to ``target`` (a class or an instance, registered or not).

    A check the filter declares in ``expected_check_failures`` is xfailed when it fails and xpassed (a failure
    of the declaration) when it passes.
    """
    flt = as_filter(target)
    label = name or type(flt).__name__
    for check in FILTER_CHECKS.values():
        mark = marking(flt, check)
        if mark is not None and mark[0] == "skip":
            yield CheckResult(label, check.name, "skipped", mark[1])
            continue
        try:
            check.run(flt)
        except (CheckFailed, LocbenchError, AssertionError, TypeError, ValueError) as exc:
            if isinstance(exc, DependencyNotInstalled):
                yield CheckResult(label, check.name, "skipped", str(exc))
            elif mark is not None:
                yield CheckResult(label, check.name, "xfailed", mark[1])
            else:
                yield CheckResult(label, check.name, "failed", f"{type(exc).__name__}: {exc}")
        else:
            if mark is not None:
                yield CheckResult(label, check.name, "xpassed", f"declared to fail ({mark[1]}) but passed")
            else:
                yield CheckResult(label, check.name, "passed")


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


def _dataset_results(spec: str) -> Iterator[CheckResult]:
    resolve_dataset(spec)  # a malformed spec is a clear error, not a failed check
    for name, fn in DATASET_CHECKS.items():
        try:
            fn(spec)
        except (CheckFailed, LocbenchError, AssertionError, TypeError, ValueError) as exc:
            outcome = "skipped" if isinstance(exc, DependencyNotInstalled) else "failed"
            yield CheckResult(spec, name, outcome, f"{type(exc).__name__}: {exc}")
        else:
            yield CheckResult(spec, name, "passed")


def run_checks(ids: list[str] | None = None) -> Iterator[CheckResult]:
    """Run the checks of the given registered filter/dataset specs (all registered ones when None)."""
    if not ids:
        ids = FILTERS.ids() + DATASETS.ids()
    for spec in ids:
        ident = Spec.parse(spec).ident
        if ident in FILTERS:
            checks: list[str] = list(FILTER_CHECKS)
            registry = FILTERS
        elif ident in DATASETS:
            checks, registry = list(DATASET_CHECKS), DATASETS
        else:
            valid = ", ".join(FILTERS.ids() + DATASETS.ids())
            raise UnknownIdError(f"unknown filter or dataset {ident!r}; valid: {valid}")
        broken = registry.load_error(ident)
        if broken is not None:
            # a plugin that does not import or is not a valid class fails, with its entry point and the cause
            yield CheckResult(spec, "check_loads", "failed", broken)
            continue
        if registry is DATASETS and spec != ident:
            # a spec with parameters names its own data (a textlog folder, a bag): only a missing package skips it
            reason = registry.missing_dependency(ident)
        else:
            reason = registry.unavailable_reason(ident)
        if reason is not None:
            for name in checks:
                yield CheckResult(spec, name, "skipped", reason)
        elif registry is FILTERS:
            # a bare id runs every configuration the filter declares for the checks
            for one in check_specs(ident) if spec == ident else [spec]:
                yield from check_filter(make_filter(resolve_filter(one)), name=one)
        else:
            yield from _dataset_results(spec)
