"""From (filter, dataset, seed) to stored runs.

For every (dataset, seed) the dataset is built once (its noise depends only on the dataset name and
the seed, so every filter sees the same realisation) and each selected filter is run over its events:
``predict`` for odometry, ``update`` for each observation type the filter routes, ``estimate()`` after
every call, and the time of each call. A finished run whose key is unchanged is not run again unless
forced. An exception inside a filter or a divergence is stored as a result with its status and message,
and the sweep goes on.
"""

from __future__ import annotations

import concurrent.futures as cf
import logging
import math
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from locbench import provenance
from locbench.datasets.base import Dataset
from locbench.divergence import left_world, world_box
from locbench.errors import DataNotFound, FilterDiverged
from locbench.events import EVENT_TYPES, Odometry
from locbench.filters.base import Filter
from locbench.registry import DATASETS, FILTERS, Resolved, make_dataset, resolve_dataset, resolve_filter
from locbench.runkey import key_params
from locbench.seeding import filter_rng
from locbench.spec import stable_hash
from locbench.store import KIND_NAMES, RunRecord, Store, TruthRecord

log = logging.getLogger(__name__)

#: Bump when the meaning of stored arrays changes; part of every run key.
STORE_FORMAT = 1
_RESET = KIND_NAMES.index("reset")
_KIND_OF = {t: KIND_NAMES.index(t.__name__) for t in EVENT_TYPES}


@dataclass
class FilterTrace:
    """What one pass of a filter over a dataset produced (arrays as in :class:`RunRecord`)."""

    t: np.ndarray
    mean: np.ndarray
    cov: np.ndarray
    kind: np.ndarray
    step_ns: np.ndarray
    diagnostics: dict[str, np.ndarray]
    status: str = "ok"
    message: str = ""
    diverged_t: float | None = None
    extra: dict[str, np.ndarray] = field(default_factory=dict)


def incompatibility(flt: Filter, ds: Dataset) -> str | None:
    """Why ``flt`` cannot run on ``ds`` (a recorded skip), or None."""
    missing = sorted(k.value for k in flt.requires - ds.world.kinds)
    if missing:
        return f"{type(flt).__name__} requires map kinds {missing} which {ds.name or ds.id} does not provide"
    wanted = flt.routed_events() - {Odometry}
    present = {type(e) for e in ds.events}
    if wanted and not wanted & present:
        # A filter that would see no observation at all would only dead-reckon under another name.
        names = ", ".join(sorted(t.__name__ for t in wanted))
        return f"{type(flt).__name__} uses {names}, none of which {ds.name or ds.id} provides"
    return None


def run_filter(flt: Filter, ds: Dataset, rng: np.random.Generator) -> FilterTrace:
    """Reset ``flt`` and run it over ``ds``; never raises for a filter's own failure.

    The first row is the belief right after ``reset`` (kind "reset"); then one row per routed event.
    """
    routed = flt.routed_events()
    n_max = 1 + sum(1 for e in ds.events if isinstance(e, Odometry) or type(e) in routed)
    t = np.full(n_max, np.nan)
    mean = np.full((n_max, 3), np.nan)
    cov = np.full((n_max, 3, 3), np.nan)
    kind = np.zeros(n_max, dtype=np.int8)
    step_ns = np.zeros(n_max, dtype=np.int64)
    diags: dict[str, np.ndarray] = {}
    status, message, diverged_t = "ok", "", None
    row = 0

    def record(tt: float, k: int, ns: int) -> None:
        nonlocal row
        est = flt.estimate()
        t[row], kind[row], step_ns[row] = tt, k, ns
        mean[row] = est.mean
        cov[row] = est.cov
        for name, value in est.diagnostics.items():
            arr = diags.get(name)
            if arr is None:
                arr = diags[name] = np.full(n_max, np.nan)
            arr[row] = value
        row += 1

    t0 = ds.events[0].t if ds.events else 0.0
    box = world_box(ds)
    try:
        flt.reset(ds.initial, ds.world, ds.sensors, rng)
        record(float(min(t0, ds.ground_truth.t[0])), _RESET, 0)
        clock = time.perf_counter_ns
        for ev in ds.events:
            typ = type(ev)
            if typ is Odometry:
                start = clock()
                flt.predict(ev)  # type: ignore[arg-type]
                ns = clock() - start
            elif typ in routed:
                start = clock()
                flt.update(ev)  # type: ignore[arg-type]
                ns = clock() - start
            else:
                continue
            record(ev.t, _KIND_OF[typ], ns)
            m, c = mean[row - 1], cov[row - 1]
            if not (np.all(np.isfinite(m)) and np.all(np.isfinite(c))):
                raise FilterDiverged(f"non-finite estimate at t={ev.t:.3f} s")
            if not box.contains(m[0], m[1]):
                raise FilterDiverged(f"{left_world(m, box)} at t={ev.t:.3f} s")
    except FilterDiverged as exc:
        status, message = "diverged", str(exc)
        diverged_t = float(t[row - 1]) if row else float(t0)
    except Exception as exc:
        status = "error"
        tb = traceback.extract_tb(exc.__traceback__)
        where = f" ({tb[-1].filename.rsplit('/', 1)[-1]}:{tb[-1].lineno})" if tb else ""
        message = f"{type(exc).__name__}: {exc}{where}"
    extra: dict[str, np.ndarray] = {}
    if status == "ok":
        try:
            extra = {k: np.asarray(v) for k, v in flt.extra_results().items()}
        except Exception as exc:
            status, message = "error", f"extra_results failed: {type(exc).__name__}: {exc}"
    return FilterTrace(
        t[:row],
        mean[:row],
        cov[:row],
        kind[:row],
        step_ns[:row],
        {k: v[:row] for k, v in diags.items()},
        status,
        message,
        diverged_t,
        extra,
    )


def run_key(fr: Resolved, dr: Resolved, seed: int) -> str:
    """The cache key of a run: everything that determines its result."""
    fcls, dcls = FILTERS.load(fr.id), DATASETS.load(dr.id)
    return stable_hash(
        {
            "format": STORE_FORMAT,
            "filter": fr.id,
            "filter_config": key_params(fr.params),
            "filter_version": getattr(fcls, "version", 1),
            "dataset": dr.id,
            "dataset_params": key_params(dr.params),
            "dataset_version": getattr(dcls, "version", 1),
            "seed": seed,
        }
    )


@dataclass
class RunOutcome:
    """One line of a sweep's summary."""

    filter: str
    dataset: str
    seed: int
    status: str  # ok, skipped, diverged, error, cached
    message: str = ""


def _meta(fr: Resolved, dr: Resolved, seed: int, key: str) -> dict[str, Any]:
    git = provenance.git_state()
    return {
        "filter": fr.name,
        "filter_id": fr.id,
        "filter_config": fr.params_dict(),
        "filter_version": getattr(FILTERS.load(fr.id), "version", 1),
        "dataset": dr.name,
        "dataset_id": dr.id,
        "dataset_params": dr.params_dict(),
        "dataset_version": getattr(DATASETS.load(dr.id), "version", 1),
        "seed": seed,
        "run_key": key,
        "versions": provenance.versions(),
        "git_commit": git["commit"],
        "git_dirty": git["dirty"],
    }


def run_group(
    dataset_spec: str, filter_specs: Sequence[str], seed: int, results: str, force: bool = False
) -> list[RunOutcome]:
    """Build one dataset realisation and run every filter that has no up-to-date stored run on it."""
    store = Store(results)
    dr = resolve_dataset(dataset_spec)
    frs = [resolve_filter(s) for s in filter_specs]
    todo: list[tuple[Resolved, str]] = []
    outcomes: list[RunOutcome] = []
    for fr in frs:
        key = run_key(fr, dr, seed)
        if not force and store.existing_key(dr.name, fr.name, seed) == key and store.has_truth(dr.name, seed):
            outcomes.append(RunOutcome(fr.name, dr.name, seed, "cached"))
        else:
            todo.append((fr, key))
    if not todo:
        return outcomes
    t_build = time.perf_counter()
    try:
        ds: Dataset = make_dataset(dr, seed)
    except DataNotFound as exc:
        # Recorded data that is not on this machine: a recorded skip with the reason, not a failure.
        msg = f"data not found: {exc}"
        for fr, key in todo:
            meta = _meta(fr, dr, seed, key) | {"status": "skipped", "message": msg, "wall_s": 0.0}
            store.write_run(_empty_record(meta))
            outcomes.append(RunOutcome(fr.name, dr.name, seed, "skipped", msg))
        return outcomes
    except Exception as exc:
        msg = f"dataset build failed: {type(exc).__name__}: {exc}"
        log.error("%s seed %d: %s", dr.name, seed, msg)
        for fr, key in todo:
            meta = _meta(fr, dr, seed, key) | {"status": "error", "message": msg, "wall_s": 0.0}
            store.write_run(_empty_record(meta))
            outcomes.append(RunOutcome(fr.name, dr.name, seed, "error", msg))
        return outcomes
    build_s = time.perf_counter() - t_build
    truth_meta = {
        "dataset_id": dr.id,
        "dataset_params": dr.params_dict(),
        "dataset_version": getattr(DATASETS.load(dr.id), "version", 1),
        "build_s": build_s,
        "metadata": ds.metadata,
        "versions": provenance.versions(),
    }
    store.write_truth(TruthRecord.from_dataset(ds, seed, truth_meta))
    for fr, key in todo:
        meta = _meta(fr, dr, seed, key)
        flt: Filter = FILTERS.load(fr.id)(fr.params)
        reason = incompatibility(flt, ds)
        if reason is not None:
            meta |= {"status": "skipped", "message": reason, "wall_s": 0.0}
            store.write_run(_empty_record(meta))
            outcomes.append(RunOutcome(fr.name, dr.name, seed, "skipped", reason))
            continue
        start = time.perf_counter()
        trace = run_filter(flt, ds, filter_rng(fr.name, dr.name, seed))
        meta |= {
            "status": trace.status,
            "message": trace.message,
            "diverged_t": trace.diverged_t,
            "wall_s": time.perf_counter() - start,
            "compute_s": float(trace.step_ns.sum()) / 1e9,
            "dataset_duration_s": ds.duration,
            "n_rows": int(trace.t.shape[0]),
        }
        store.write_run(
            RunRecord(meta, trace.t, trace.mean, trace.cov, trace.kind, trace.step_ns, trace.diagnostics, trace.extra)
        )
        if trace.status != "ok":
            log.warning("%s on %s seed %d: %s: %s", fr.name, dr.name, seed, trace.status, trace.message)
        outcomes.append(RunOutcome(fr.name, dr.name, seed, trace.status, trace.message))
    return outcomes


def _empty_record(meta: dict[str, Any]) -> RunRecord:
    return RunRecord(
        meta, np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros(0, np.int8), np.zeros(0, np.int64)
    )


def run_many(
    filter_specs: Sequence[str],
    dataset_specs: Sequence[str],
    seeds: Sequence[int],
    results: str,
    jobs: int = 1,
    force: bool = False,
    progress: Callable[[int], None] | None = None,
) -> list[RunOutcome]:
    """Run every filter on every dataset for every seed; returns one outcome per run.

    Specs are resolved first, so an unknown id or parameter fails before anything runs. Work is split
    into (dataset, seed) groups, run in ``jobs`` worker processes; ``progress(n)`` is called with the
    number of runs finished by each group.
    """
    frs = [resolve_filter(s) for s in filter_specs]
    drs = [resolve_dataset(s) for s in dataset_specs]
    fnames = [fr.name for fr in frs]
    groups = [(dr.name, s) for dr in drs for s in seeds]
    outcomes: list[RunOutcome] = []
    if jobs <= 1 or len(groups) <= 1:
        for dname, seed in groups:
            res = run_group(dname, fnames, seed, results, force)
            outcomes.extend(res)
            if progress:
                progress(len(res))
        return outcomes
    with cf.ProcessPoolExecutor(max_workers=jobs) as pool:
        futures = {pool.submit(run_group, dname, fnames, seed, results, force): (dname, seed) for dname, seed in groups}
        for fut in cf.as_completed(futures):
            dname, seed = futures[fut]
            try:
                res = fut.result()
            except Exception as exc:
                res = [
                    RunOutcome(f, dname, seed, "error", f"worker failed: {type(exc).__name__}: {exc}") for f in fnames
                ]
            outcomes.extend(res)
            if progress:
                progress(len(res))
    order = {(d, s): i for i, (d, s) in enumerate(groups)}
    outcomes.sort(
        key=lambda o: (order.get((o.dataset, o.seed), math.inf), fnames.index(o.filter) if o.filter in fnames else 0)
    )
    return outcomes
