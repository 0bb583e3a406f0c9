"""Executing a task where it runs: its dataset built, its filters run, and the records returned.

:func:`execute_task` does one task, or one filter's part of it, anywhere, a process of this machine or a dask
worker on another: it builds the dataset once and keeps it for the next part (its noise depends only on the
dataset name and the seed, so every filter sees the same realisation), computes the realisation's posterior
Cramer-Rao bound where the plan asks for it (synthetic worlds, :mod:`locbench.evaluate.pcrb`), and runs each filter
over its events (:mod:`locbench.run.filter_pass`; with interleaved timing every filter of the task in turns over
slices of the data, :func:`_interleaved`), returning the records without touching the results folder.
:func:`execute_contained`, what the executors run, does the same with the filters in a child process under the
run time limit. An exception inside a filter or a divergence is a record with its status and message; a failure
of the machinery (a child that died, a dataset that did not build) is recorded the same way for every run of the
task, by :func:`failed_result`.
"""

from __future__ import annotations

import contextlib
import logging
import math
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from locbench.core.errors import DataNotFound
from locbench.core.seeding import belief_rng, filter_rng
from locbench.datasets.dataset import Dataset
from locbench.evaluate.derived import Derived, derive
from locbench.evaluate.records import BoundRecord, RunRecord, TruthRecord
from locbench.filters.base import Filter
from locbench.registry import build_dataset
from locbench.run import provenance
from locbench.run.containment import DEFAULT_RULE, call_in_child, run_time_limit
from locbench.run.filter_pass import FilterPass, FilterTrace, incompatibility, run_filter, warm_key, warm_up
from locbench.run.plan import Job, Task, samples_belief
from locbench.run.store import truth_key

log = logging.getLogger(__name__)


@dataclass
class TaskResult:
    """What a worker returns: the realisation's truth (None when the dataset did not build), one record per job in
    the order of the task's jobs, the bound when the plan asked for it, and beside each run its derived values
    with the truth's key (:func:`derived_values`; None for a run that is not ok; none at all when the task does
    not derive them), stored with it."""

    truth: TruthRecord | None
    runs: list[RunRecord]
    bound: BoundRecord | None = None
    derived: list[tuple[Derived, str] | None] = field(default_factory=list)


def derived_values(runs: list[RunRecord], truth: TruthRecord) -> list[tuple[Derived, str] | None]:
    """Each ok run's values for the report (:func:`locbench.evaluate.derived.derive`) and the truth's key, computed
    here while the run and its truth are in memory, so that the report need not; None for a run that is not ok or
    whose values fail to compute (the report then computes them and reports the error)."""
    key = truth_key(truth)
    out: list[tuple[Derived, str] | None] = []
    for rec in runs:
        value = None
        if rec.status == "ok":
            try:
                value = (derive(rec, truth), key)
            except Exception as exc:
                log.warning(
                    "%s on %s seed %s: derived values not stored: %s",
                    rec.meta.get("filter"),
                    rec.meta.get("dataset"),
                    rec.meta.get("seed"),
                    exc,
                )
        out.append(value)
    return out


def _meta(task: Task, job: Job) -> dict[str, Any]:
    """The provenance of one run, taken where it runs (the worker's library versions and commit)."""
    git = provenance.git_state()
    fr, dr = job.filter, task.dataset
    meta: dict[str, Any] = {
        "filter": fr.name,
        "filter_id": fr.id,
        "filter_config": fr.resolved.params_dict(),
        "filter_version": fr.version,
        "filter_distribution": provenance.distribution(fr.cls),
        "dataset": dr.name,
        "dataset_id": dr.id,
        "dataset_params": dr.resolved.params_dict(),
        "dataset_version": dr.version,
        "dataset_distribution": provenance.distribution(dr.cls),
        "seed": task.seed,
        "run_key": job.key,
        "versions": provenance.versions(),
        "git_commit": git["commit"],
        "git_dirty": git["dirty"],
        # the machine, its load as the run starts and the reference workload's time (runtimes in reference units)
        **provenance.machine(),
    }
    if samples_belief(fr.cls):
        meta["score_sample"] = task.score_sample  # the run setting its stored scores were drawn with
    if fr.traits is not None:
        meta["filter_traits"] = fr.traits.record()  # what the report labels the run by (locbench.report.collect)
    return meta


def _empty_record(meta: dict[str, Any]) -> RunRecord:
    return RunRecord(
        meta, np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros(0, np.int8), np.zeros(0, np.int64)
    )


def failed_result(task: Task, status: str, message: str, transient: bool = False) -> TaskResult:
    """The one way a failure outside a filter is recorded: a run with ``status`` and ``message`` for every job.

    ``transient`` marks a failure of the machinery (a worker that died) rather than of the run itself, so the
    next sweep runs it again instead of treating the stored error as up to date.
    """
    extra = {"status": status, "message": message, "wall_s": 0.0} | ({"transient": True} if transient else {})
    return TaskResult(None, [_empty_record(_meta(task, job) | extra) for job in task.jobs])


@dataclass(frozen=True)
class _BuildFailed:
    """A dataset that did not build: the status and message of every run on it."""

    status: str
    message: str


#: This process's last built realisations, oldest first: (dataset class, dataset name, seed) -> the dataset
#: and its truth's record, or the failure of its build; so that the parts of a task that run one after another
#: on a worker (:func:`locbench.run.executors.parts`) build their dataset once.
_REALISATION: dict[tuple[type, str, int], tuple[Dataset, TruthRecord] | _BuildFailed] = {}
#: Realisations a process keeps: two, since two workers freed at once may take each other's next part.
_KEEP = 2
#: Set inside :func:`retained_realisations`: how many realisations to keep across sweeps, else None.
_RETAIN: int | None = None


def forget_realisations() -> None:
    """Drop this process's kept realisations (:data:`_REALISATION`): their memory once a sweep is over (kept
    inside :func:`retained_realisations`)."""
    if _RETAIN is None:
        _REALISATION.clear()


@contextlib.contextmanager
def retained_realisations(count: int) -> Iterator[None]:
    """Keep up to ``count`` realisations in this process across the sweeps run inside, then drop them.

    A study runs one small sweep per trial over the same few train datasets: kept, each is built once per study
    instead of once per trial (a recorded dataset's build takes about as long as a Kalman filter's run on it).
    """
    global _RETAIN
    before = _RETAIN
    _RETAIN = max(count, _KEEP, before or 0)
    try:
        yield
    finally:
        _RETAIN = before
        forget_realisations()


def _realisation(task: Task) -> tuple[Dataset, TruthRecord] | _BuildFailed:
    """The task's dataset and its truth's record, built or kept from the previous part; or why it did not build."""
    key = (task.dataset.cls, task.dataset.name, task.seed)
    kept = _REALISATION.pop(key, None)
    if kept is not None:
        _REALISATION[key] = kept  # the newest now
        return kept
    while len(_REALISATION) >= (_RETAIN or _KEEP):
        del _REALISATION[next(iter(_REALISATION))]
    dr = task.dataset
    t_build = time.perf_counter()
    built: tuple[Dataset, TruthRecord] | _BuildFailed
    try:
        ds: Dataset = build_dataset(dr.cls, dr.resolved, task.seed)
    except DataNotFound as exc:
        # Recorded data that is not on this machine: a recorded skip with the reason, not a failure.
        built = _BuildFailed("skipped", f"data not found: {exc}")
    except Exception as exc:
        msg = f"dataset build failed: {type(exc).__name__}: {exc}"
        log.error("%s: %s", task.label, msg)
        built = _BuildFailed("error", msg)
    else:
        truth_meta = {
            "dataset_id": dr.id,
            "dataset_params": dr.resolved.params_dict(),
            "dataset_version": dr.version,
            "build_s": time.perf_counter() - t_build,
            "metadata": ds.metadata,
            "versions": provenance.versions(),
        }
        if ds.flagged:
            truth_meta["flagged"] = [s.record() for s in ds.flagged]
        built = (ds, TruthRecord.from_dataset(ds, task.seed, truth_meta))
    _REALISATION[key] = built
    return built


def execute_task(task: Task) -> TaskResult:
    """Build the task's dataset (or take the one this process kept) and run each of its filters; touches no
    file (any worker can run it).

    Never raises for a failure of a filter or of the dataset: those are records with their status.
    """
    built = _realisation(task)
    if isinstance(built, _BuildFailed):
        return failed_result(task, built.status, built.message)
    ds, truth = built
    bound = _bound(task, ds)
    runs = _runs(task, ds)
    return TaskResult(truth, runs, bound, derived_values(runs, truth) if task.derive else [])


#: The filters (:func:`locbench.run.filter_pass.warm_key`) a child of this process ran to the end ok: warmed up here.
_RAN_OK: set[tuple[type, str, frozenset[type]]] = set()


def _warm_proven(task: Task, ds: Dataset) -> None:
    """Warm up here, before the fork, each filter of ``task`` that a child of this process already ran ok on data
    of the same kind, so that the children inherit its loaded kernels.

    Without it every child loaded each filter's compiled kernels from numba's on-disk cache again: about 0.5 s of
    CPU for an 11-filter task on ``office``, a tenth of its runs. A filter not yet proven here warms up in the
    child, where a crash or a hang in its first events stays contained.
    """
    for job in task.jobs:
        flt: Filter = job.filter.cls(job.filter.params)
        if warm_key(flt, ds) in _RAN_OK:
            warm_up(flt, ds)


def _note_ok(task: Task, ds: Dataset, runs: list[RunRecord]) -> None:
    """Remember the task's filters whose runs (one per job, in the jobs' order) ended ok (:func:`_warm_proven`)."""
    for job, rec in zip(task.jobs, runs, strict=True):
        if rec.meta.get("status") == "ok":
            _RAN_OK.add(warm_key(job.filter.cls(job.filter.params), ds))


def execute_contained(task: Task) -> TaskResult:
    """:func:`execute_task`, its filters run in a child process under the run time limit; what executors run.

    The dataset is built (or taken) and the bound computed here, in the worker, and the child forked from it
    shares them; the child runs the filters (:func:`locbench.run.containment.call_in_child`) and returns their
    records. A child that exits, dies by a signal, lets an exception such as ``SystemExit`` escape or passes
    the limit (``len(task.jobs)`` times the limit of a run, for an interleaved part) is an error run for each
    of the part's filters, with the reason; a death or a timeout is marked transient (the next sweep runs it
    again). Every record carries its limit in ``run_timeout_s`` (None: no limit) and ``run_timeout_rule``.
    """
    built = _realisation(task)
    if isinstance(built, _BuildFailed):
        return failed_result(task, built.status, built.message)
    ds, truth = built
    bound = _bound(task, ds)
    # the provenance every record takes, computed here once: a child's caches die with it (the installed
    # distributions' index alone takes 0.15-0.2 s, which every task's child spent again)
    provenance.versions()
    provenance.git_state()
    provenance.machine()
    for cls in {task.dataset.cls, *(job.filter.cls for job in task.jobs)}:
        provenance.distribution(cls)
    _warm_proven(task, ds)
    limit = run_time_limit(ds.duration, task.run_timeout_s)
    rule = DEFAULT_RULE if task.run_timeout_s is None else "--run-timeout"
    outcome = call_in_child(lambda: _runs(task, ds), limit * max(1, len(task.jobs)))
    if outcome.ok:
        runs: list[RunRecord] = outcome.value
        _note_ok(task, ds, runs)
    else:
        if outcome.kind == "timeout":
            how = "set by --run-timeout" if task.run_timeout_s is not None else f"{DEFAULT_RULE} on {ds.duration:.1f} s"
            message = f"timed out: the run passed its time limit of {limit:g} s ({how}; change it with --run-timeout)"
        else:
            message = outcome.message
        log.error("%s: %s", task.label, message)
        runs = failed_result(task, "error", message, transient=outcome.kind != "raised").runs
        for rec in runs:
            rec.meta["wall_s"] = outcome.wall_s
    for rec in runs:
        rec.meta["run_timeout_s"] = limit if math.isfinite(limit) else None
        rec.meta["run_timeout_rule"] = rule
    return TaskResult(truth, runs, bound, derived_values(runs, truth) if task.derive else [])


def _runs(task: Task, ds: Dataset) -> list[RunRecord]:
    """The records of the task's filters on its built dataset (what :func:`execute_task` runs after the build)."""
    return _interleaved(task, ds) if task.slice_s > 0 else [_run_job(task, job, ds) for job in task.jobs]


def _rngs(task: Task, job: Job) -> tuple[np.random.Generator, np.random.Generator]:
    """A run's filter generator and the runner's belief-sampling one (:mod:`locbench.core.seeding`)."""
    name, ds_name = job.filter.name, task.dataset.name
    return filter_rng(name, ds_name, task.seed), belief_rng(name, ds_name, task.seed)


def _run_job(task: Task, job: Job, ds: Dataset) -> RunRecord:
    """One filter of a task over the whole dataset (a skip when it cannot run on it)."""
    meta = _meta(task, job)
    flt: Filter = job.filter.cls(job.filter.params)
    reason = incompatibility(flt, ds)
    if reason is not None:
        return _empty_record(meta | {"status": "skipped", "message": reason, "wall_s": 0.0})
    start = time.perf_counter()
    trace = run_filter(flt, ds, *_rngs(task, job), task.score_sample)
    return _trace_record(task, job, ds, meta, trace, time.perf_counter() - start)


def _trace_record(
    task: Task, job: Job, ds: Dataset, meta: dict[str, Any], trace: FilterTrace, wall_s: float
) -> RunRecord:
    meta = meta | {
        "status": trace.status,
        "message": trace.message,
        "diverged_t": trace.diverged_t,
        "wall_s": wall_s,
        "compute_s": float(trace.step_ns.sum()) / 1e9,
        "dataset_duration_s": ds.duration,
        "n_rows": int(trace.t.shape[0]),
    }
    if ds.flagged:
        # Recorded samples the loader left out (isolated glitches): counted with their times, so a reader sees what
        # the metrics did not (the truth record holds each one's file, line, quantity and bound).
        meta |= {"flagged_samples": len(ds.flagged), "flagged_t": [s.t for s in ds.flagged]}
    if trace.status != "ok":
        log.warning("%s on %s: %s: %s", job.filter.name, task.label, trace.status, trace.message)
    arrays = (trace.t, trace.mean, trace.cov, trace.kind, trace.step_ns)
    return RunRecord(meta, *arrays, trace.diagnostics, trace.extra, trace.health)


def slice_stops(ds: Dataset, slice_s: float) -> list[int]:
    """The event indices that end each ``slice_s`` seconds of ``ds``'s data (the last is the event count)."""
    n = len(ds.events)
    if n == 0:
        return [0]
    times = np.fromiter((e.t for e in ds.events), dtype=np.float64, count=n)
    edges = np.arange(times[0] + slice_s, times[-1] + slice_s, slice_s)
    stops = np.unique(np.searchsorted(times, edges, side="left"))
    return [int(i) for i in stops if 0 < i < n] + [n]


#: Interleaved timing runs a piece of the reference workload at a task's start and then between slices whenever
#: this much wall time has passed since the last (its cost: a piece, about 4 ms of CPU, per 2 s: 0.2-1.5 %).
REFERENCE_EVERY_S = 2.0


def _reference_piece() -> tuple[float, float]:
    """The wall and thread CPU time of one piece of the reference workload, s (``reference_workload.run_piece``)."""
    from locbench.run.reference_workload import run_piece

    start, start_cpu = time.perf_counter(), time.thread_time()
    run_piece()
    cpu = time.thread_time() - start_cpu
    return time.perf_counter() - start, cpu


def _interleaved(task: Task, ds: Dataset) -> list[RunRecord]:
    """Every filter of a task advanced in turn over ``task.slice_s`` seconds of data at a time.

    A busy moment of the machine then lands on a slice of every configuration of the task, not on one
    configuration's whole run, so the configurations' timings stay comparable; the first filter of each slice
    rotates (none always runs right after another's cache pollution). Pieces of the reference workload run
    between slices (:data:`REFERENCE_EVERY_S`), so the runs' ``reference_s`` (``reference_cpu_s``) is the task's
    own: the pieces' mean wall (CPU) time times the pieces in a pass, under the load the filters ran under (the
    sweep's measurement stays as ``reference_sweep_s``). Estimates are those of :func:`_run_job`, bit for bit
    (each pass has its own filter, generators and arrays); every filter of the task is alive at once, so the
    task's memory is the sum of its filters' rather than the largest.
    """
    from locbench.run.reference_workload import PIECES

    out: list[RunRecord | None] = [None] * len(task.jobs)
    live: list[tuple[int, Job, dict[str, Any], FilterPass]] = []
    for i, job in enumerate(task.jobs):
        meta = _meta(task, job)
        flt: Filter = job.filter.cls(job.filter.params)
        reason = incompatibility(flt, ds)
        if reason is not None:
            out[i] = _empty_record(meta | {"status": "skipped", "message": reason, "wall_s": 0.0})
            continue
        live.append((i, job, meta, FilterPass(flt, ds, *_rngs(task, job), task.score_sample)))
    pieces: list[tuple[float, float]] = []
    last = -np.inf
    for k, stop in enumerate(slice_stops(ds, task.slice_s)):
        if live and time.perf_counter() - last >= REFERENCE_EVERY_S:
            pieces.append(_reference_piece())
            last = time.perf_counter()
        first = k % len(live) if live else 0
        for _, _, _, run in live[first:] + live[:first]:
            run.advance(stop)
    for i, job, meta, run in live:
        start = time.perf_counter()
        trace = run.finish()
        wall, cpu = PIECES * np.mean(pieces, axis=0)
        meta = meta | {
            "reference_sweep_s": meta["reference_s"],
            "reference_s": float(wall),
            "reference_cpu_s": float(cpu),
            "reference_pieces": len(pieces),
        }
        out[i] = _trace_record(task, job, ds, meta, trace, run.wall_s + time.perf_counter() - start)
    return [r for r in out if r is not None]


def _bound(task: Task, ds: Dataset) -> BoundRecord | None:
    """The realisation's bound when the plan asks for it; a failure is logged and leaves it uncomputed (the
    next sweep tries again), never failing the task's runs."""
    if task.bound_key is None:
        return None
    from locbench.evaluate.pcrb import bound_covariances

    start = time.perf_counter()
    try:
        covs = bound_covariances(ds)
    except Exception as exc:
        log.error("%s: posterior Cramer-Rao bound failed: %s: %s", task.label, type(exc).__name__, exc)
        return None
    meta = {"bound_key": task.bound_key, "compute_s": time.perf_counter() - start, "versions": provenance.versions()}
    return BoundRecord(task.dataset.name, task.seed, ds.ground_truth.t, covs, meta)
