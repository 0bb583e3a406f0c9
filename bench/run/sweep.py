"""A sweep: a plan's tasks handed to an executor, and every returned record written into the store as it arrives.

:func:`run_sweep` checks the store (ours, writable, with room), hands the plan's tasks to an executor
(:mod:`locbench.run.executors`, which runs them one filter at a time in workers,
:func:`locbench.run.execute.execute_contained`), and stores each filter's record as it finishes
(:func:`store_result`), so an interrupted sweep keeps every finished run and the same plan resumes. SIGINT
(Ctrl-C) and SIGTERM stop it; a worker that died is retried, then recorded as an error run; the sweep goes on.
:func:`run_many` plans and sweeps in one call.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from locbench.run import executors, provenance
from locbench.run.execute import TaskResult, failed_result
from locbench.run.plan import NOT_STORED, ParsedDataset, ParsedFilter, Plan, RunOutcome, Task, plan_sweep
from locbench.run.store import Store

log = logging.getLogger(__name__)


@dataclass
class SweepResult:
    """The outcome of every run of a plan, and whether the sweep was interrupted."""

    outcomes: list[RunOutcome]
    total: int
    interrupted: bool = False
    #: Tasks handed to a fresh worker after the one running them died.
    retried: int = 0
    #: Leftover temporary entries of earlier interrupted writes that were removed.
    cleaned: int = 0
    #: Realisations whose posterior Cramer-Rao bound was computed and stored, and those the plan asked for.
    bounds: int = 0
    bounds_planned: int = 0

    @property
    def stored(self) -> int:
        """Runs present in the store at the end (cached ones included)."""
        return sum(o.status != NOT_STORED for o in self.outcomes)


def store_result(
    store: Store, task: Task, result: TaskResult, written: set[tuple[str, int]] | None = None
) -> list[RunOutcome]:
    """Write a task's truth and runs; a write that fails (disk full, read-only) is a ``not stored`` outcome
    whose message names the run's folder and the reason.

    ``written`` holds the (dataset, seed) whose truth this sweep stored already: each part of a task carries
    the same truth, written once, before the first of its runs. The records come in the order of the task's jobs
    (:class:`~locbench.run.execute.TaskResult`): each is the run of the job beside it.
    """
    truth_error = ""
    realisation = (task.dataset.name, task.seed)
    if result.truth is not None and (written is None or realisation not in written):
        try:
            store.write_truth(result.truth)
        except OSError as exc:
            truth_error = f"its ground truth was not stored: {_os_message(exc)}"
        else:
            if written is not None:
                written.add(realisation)
    outcomes = []
    derived = result.derived or [None] * len(result.runs)
    for job, rec, values in zip(task.jobs, result.runs, derived, strict=True):
        fspec, dspec = job.filter.spec, task.dataset.spec
        where = store.run_dir(task.dataset.name, job.filter.name, task.seed)
        if truth_error:
            outcomes.append(
                RunOutcome(fspec, dspec, task.seed, NOT_STORED, f"seed {task.seed} -> {where}: {truth_error}")
            )
            continue
        try:
            store.write_run(rec, values)
        except OSError as exc:
            outcomes.append(
                RunOutcome(fspec, dspec, task.seed, NOT_STORED, f"seed {task.seed} -> {where}: {_os_message(exc)}")
            )
            continue
        outcomes.append(RunOutcome(fspec, dspec, task.seed, rec.status, str(rec.meta.get("message", "")), job.note))
    return outcomes


def store_bound(store: Store, task: Task, result: TaskResult) -> bool:
    """Write a task's bound, if it computed one; whether it was stored (a failed write is logged, and the next
    sweep computes it again)."""
    if result.bound is None:
        return False
    try:
        store.write_bound(result.bound)
    except OSError as exc:
        log.error("%s: bound not stored: %s", task.label, _os_message(exc))
        return False
    return True


def _os_message(exc: OSError) -> str:
    """``path: reason`` of an operating-system error, on one line."""
    where = f"{exc.filename}: " if exc.filename else ""
    return f"{where}{exc.strerror or exc}"


def run_sweep(
    plan: Plan,
    executor: str = "local",
    jobs: int = 1,
    scheduler: str | None = None,
    progress: Callable[[int], None] | None = None,
    connect_timeout_s: float | None = None,
) -> SweepResult:
    """Execute a plan and store every run as it arrives.

    Parameters
    ----------
    executor : {"local", "dask"}
        ``local``: this process (``jobs`` = 1) or a pool of ``jobs`` processes; ``dask``: a dask.distributed
        client of the scheduler at ``scheduler``, else of a LocalCluster of ``jobs`` worker processes.
    progress : callable, optional
        Called with the number of runs each finished part stored (one filter's; once with the cached count).
    connect_timeout_s : float, optional
        Seconds to wait for the scheduler at ``scheduler`` (default :data:`locbench.run.executors.CONNECT_TIMEOUT_S`).

    Before anything is computed the store is checked writable, with room for the planned runs
    (:meth:`Store.check_space`): a full disk is one error, not one per computed run.

    SIGINT (Ctrl-C) and SIGTERM stop the sweep: runs not started are cancelled, running ones abandoned, every
    finished run is kept (each is stored as its filter finishes), and the result says ``interrupted``;
    rerunning the same plan resumes.
    """
    store = plan.store
    store.claim()  # another tool's folder is refused before anything is written or cleaned in it
    if plan.tasks:
        store.check_writable()  # a read-only or full results folder is one error before any run, not one per run
        store.check_space(sum(len(t.jobs) for t in plan.tasks) + len(plan.tasks))
    cleaned = len(store.clean_leftovers())
    if plan.tasks:
        provenance.reference()  # once per sweep, here: the workers a pool forks inherit it
    outcomes = list(plan.cached)
    bounds = [0]
    truths: set[tuple[str, int]] = set()
    if progress and plan.cached:
        progress(len(plan.cached))

    def handle(task: Task, result: TaskResult) -> None:
        res = store_result(store, task, result, truths)
        bounds[0] += store_bound(store, task, result)
        outcomes.extend(res)
        if progress:
            progress(len(res))

    def lost(task: Task, message: str) -> None:
        handle(task, failed_result(task, "error", message, transient=True))

    run = executors.get(executor)
    timeout = executors.CONNECT_TIMEOUT_S if connect_timeout_s is None else connect_timeout_s
    status = run(plan.tasks, handle, lost, jobs=jobs, scheduler=scheduler, timeout_s=timeout)
    big = len(plan.order)
    outcomes.sort(key=lambda o: plan.order.get((str(o.dataset), o.seed, str(o.filter)), big))
    planned = sum(t.bound_key is not None for t in plan.tasks)
    return SweepResult(outcomes, plan.total, status.interrupted, status.retried, cleaned, bounds[0], planned)


def run_many(
    filter_specs: Sequence[str | ParsedFilter],
    dataset_specs: Sequence[str | ParsedDataset],
    seeds: Sequence[int],
    results: Store | str,
    jobs: int = 1,
    force: bool = False,
    progress: Callable[[int], None] | None = None,
    executor: str = "local",
    scheduler: str | None = None,
) -> list[RunOutcome]:
    """Run every filter on every dataset for every seed; returns one outcome per run, in the order given.

    Specs are parsed first (:func:`locbench.run.plan.plan_sweep`), so an unknown id or parameter fails before anything
    runs (see :func:`run_sweep`).
    """
    plan = plan_sweep([(filter_specs, dataset_specs, seeds)], results, force)
    return run_sweep(plan, executor, jobs, scheduler, progress).outcomes
