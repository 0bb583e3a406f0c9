"""From (filter, dataset, seed) to stored runs: a plan, then its execution.

:func:`plan_sweep` decides the work: every spec resolved (a bad one fails before anything runs), each
(dataset, seed) a :class:`Task` holding the filters that have no up-to-date stored run on it, the tasks
sorted longest first (stored timings where present, else an estimate) so that no worker idles at the end.
:func:`execute_task` does one task, or one filter's part of it, anywhere, a process of this machine or a dask
worker on another: it builds the dataset once and keeps it for the next part (its noise depends only on the
dataset name and the seed, so every filter sees the same realisation), computes the realisation's posterior
Cramer-Rao bound where the plan asks for it (synthetic worlds, :mod:`locbench.evaluate.pcrb`), and runs each filter
over its events (``predict`` for odometry, ``update`` for each observation type the filter routes,
``estimate()`` after every call, and the time of each call; with interleaved timing every filter of the task
in turns over slices of the data, :func:`_interleaved`), returning the records without touching the
results folder. :func:`run_sweep` hands the tasks to an executor (:mod:`locbench.run.executors`, which runs them
one filter at a time) and writes every returned record into the store as it arrives. An exception
inside a filter or a divergence is stored as a result with its status and message; a failure of the
machinery (a worker that died, a dataset that did not build) is recorded the same way for every run of
its task, by :func:`failed_result`; and the sweep goes on.
"""

from __future__ import annotations

import logging
import math
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from locbench.core.errors import DataNotFound, FilterDiverged
from locbench.core.events import EVENT_TYPES, Odometry
from locbench.core.runkey import key_params, source_digest
from locbench.core.seeding import belief_rng, filter_rng
from locbench.core.spec import Spec, stable_hash
from locbench.datasets.dataset import Dataset
from locbench.evaluate.divergence import left_world, world_box
from locbench.filters.base import GAUSSIAN_HEALTH_NAMES, Filter, gaussian_health_rows
from locbench.registry import DATASETS, FILTERS, Resolved, build_dataset, resolve_dataset, resolve_filter
from locbench.run import provenance
from locbench.run.containment import DEFAULT_RULE, call_in_child, current_run_timeout, run_time_limit
from locbench.run.contract import EstimateContractError, check_shapes, first_violation
from locbench.run.store import KIND_NAMES, BoundRecord, RunRecord, Store, TruthRecord

log = logging.getLogger(__name__)

#: Bump when the meaning of stored arrays changes; part of every run key.
STORE_FORMAT = 2
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
    health: dict[str, np.ndarray] = field(default_factory=dict)


class _BeliefScorer:
    """Scores a filter's own belief samples at the ground-truth times while it runs (:mod:`locbench.evaluate.scores`).

    Before each event, every ground-truth time earlier than the event gets the belief in force (the one after
    the previous events: the zero-order hold of :mod:`locbench.evaluate.metrics`); the ground-truth times of one such
    interval share one sample. Only the per-time scores are kept, not the samples. Inactive (no cost) for a
    filter whose :meth:`Filter.belief_sample` is None.
    """

    def __init__(self, flt: Filter, ds: Dataset, rng: np.random.Generator | None) -> None:
        self._flt, self._rng = flt, rng
        self._t = ds.ground_truth.t
        self._poses = ds.ground_truth.poses
        self._next = 0
        self._scores = np.full((4, self._t.shape[0]), np.nan)
        self.active = rng is not None

    def advance(self, t_event: float) -> None:
        """Score the ground-truth times before ``t_event`` with the current belief."""
        if not self.active or self._next >= self._t.shape[0] or self._t[self._next] >= t_event:
            return
        stop = int(np.searchsorted(self._t, t_event, side="left"))
        assert self._rng is not None
        sample = self._flt.belief_sample(self._rng)
        if sample is None:
            self.active = False
            return
        # imported here: scipy and numba stay out of the runner's import (a sweep's start, before its signal handler)
        from locbench.evaluate.scores import sample_scores

        points, weights = sample
        self._scores[:, self._next : stop] = sample_scores(points, weights, self._poses[self._next : stop])
        self._next = stop

    def result(self) -> dict[str, np.ndarray]:
        """The per-time scores (every ground-truth time scored), or nothing for a Gaussian filter."""
        self.advance(np.inf)
        if not self.active:
            return {}
        from locbench.evaluate.scores import SAMPLE_SCORE_KEYS

        return dict(zip(SAMPLE_SCORE_KEYS, self._scores, strict=True))


def incompatibility(flt: Filter, ds: Dataset) -> str | None:
    """Why ``flt`` cannot run on ``ds`` (a recorded skip), or None."""
    missing = sorted(k.value for k in flt.requires - ds.world.kinds)
    if missing:
        return f"{type(flt).__name__} requires map kinds {missing} which {ds.name or ds.id} does not provide"
    bound = flt.unsupported(ds.world)
    if bound is not None:
        return f"{type(flt).__name__} on {ds.name or ds.id}: {bound}"
    wanted = flt.routed_events() - {Odometry}
    present = {type(e) for e in ds.events}
    if wanted and not wanted & present:
        # A filter that would see no observation at all would only dead-reckon under another name.
        names = ", ".join(sorted(t.__name__ for t in wanted))
        return f"{type(flt).__name__} uses {names}, none of which {ds.name or ds.id} provides"
    return None


def run_filter(
    flt: Filter, ds: Dataset, rng: np.random.Generator, sample_rng: np.random.Generator | None = None
) -> FilterTrace:
    """Reset ``flt`` and run it over ``ds``; never raises for a filter's own failure.

    The first row is the belief right after ``reset`` (kind "reset"); then one row per routed event, with the
    filter's :meth:`Filter.health` beside its estimate. With ``sample_rng`` (a generator of the runner's, not
    the filter's), a filter that exposes belief samples has them scored at every ground-truth time
    (:class:`_BeliefScorer`; the scores go into ``extra``).
    """
    run = FilterPass(flt, ds, rng, sample_rng)
    run.advance(len(ds.events))
    return run.finish()


class FilterPass:
    """One filter's pass over a dataset (:func:`run_filter`), advanced in stretches of events.

    :func:`execute_task` advances several passes in turn over slices of a dataset (interleaved timing), so a
    busy moment of the machine falls on every configuration of the task alike; each pass keeps its own filter,
    generators and arrays, so its estimates are those of a pass alone, bit for bit.
    """

    def __init__(
        self, flt: Filter, ds: Dataset, rng: np.random.Generator, sample_rng: np.random.Generator | None = None
    ) -> None:
        self._flt, self._ds = flt, ds
        self._routed = routed = flt.routed_events()
        n_max = 1 + sum(1 for e in ds.events if isinstance(e, Odometry) or type(e) in routed)
        self.t = np.full(n_max, np.nan)
        self.mean = np.full((n_max, 3), np.nan)
        self.cov = np.full((n_max, 3, 3), np.nan)
        self.kind = np.zeros(n_max, dtype=np.int8)
        self.step_ns = np.zeros(n_max, dtype=np.int64)
        self._n_max = n_max
        self.diags: dict[str, np.ndarray] = {}
        self.health: dict[str, np.ndarray] = {}
        # The first row of every diagnostic and health signal, and of both counts at once: the Gaussian health of
        # a filter keeping Filter.health is computed after the run from the stored rows (_gaussian_health_after),
        # in the order the per-event calls would have reported it.
        self._first: dict[str, int] = {}
        self._deferred = type(flt).health is Filter.health
        self._per_event_health = flt.event_health if self._deferred else flt.health
        self._scorer = _BeliefScorer(flt, ds, sample_rng)
        self.status, self.message = "ok", ""
        self.diverged_t: float | None = None
        self.row = 0
        #: The next event to process; the wall time spent in :meth:`advance`, s.
        self.next = 0
        self.wall_s = 0.0
        self._t0 = ds.events[0].t if ds.events else 0.0
        self._box = world_box(ds)
        start = time.perf_counter()
        try:
            flt.reset(ds.initial, ds.world, ds.sensors, rng)
            self._record(float(min(self._t0, ds.ground_truth.t[0])), _RESET, 0)
        except Exception as exc:
            self._fail(exc)
        self.wall_s += time.perf_counter() - start

    @property
    def done(self) -> bool:
        """Stopped early (diverged, failed) or every event processed."""
        return self.status != "ok" or self.next >= len(self._ds.events)

    def _record(self, tt: float, k: int, ns: int) -> None:
        flt, row, n_max = self._flt, self.row, self._n_max
        est = flt.estimate()
        check_shapes(est.mean, est.cov, tt)  # a wrong shape would be broadcast into the rows, or fail as numpy's
        self.t[row], self.kind[row], self.step_ns[row] = tt, k, ns
        self.mean[row] = est.mean
        self.cov[row] = est.cov
        first = self._first
        d = est.diagnostics
        for name, value in d.items():
            arr = self.diags.get(name)
            if arr is None:
                arr = self.diags[name] = np.full(n_max, np.nan)
                first[name] = row
            arr[row] = value
        if _BOTH_COUNTS not in first and "accepted" in d and "rejected" in d:
            first[_BOTH_COUNTS] = row
        for name, value in self._per_event_health().items():
            arr = self.health.get(name)
            if arr is None:
                arr = self.health[name] = np.full(n_max, np.nan)
                first[" " + name] = row
            arr[row] = value
        self.row += 1

    def _fail(self, exc: Exception) -> None:
        if isinstance(exc, EstimateContractError):
            self.status, self.message = "error", str(exc)
            return
        if isinstance(exc, FilterDiverged):
            self.status, self.message = "diverged", str(exc)
            self.diverged_t = float(self.t[self.row - 1]) if self.row else float(self._t0)
            return
        self.status = "error"
        tb = traceback.extract_tb(exc.__traceback__)
        where = f" ({tb[-1].filename.rsplit('/', 1)[-1]}:{tb[-1].lineno})" if tb else ""
        self.message = f"{type(exc).__name__}: {exc}{where}"

    def advance(self, stop: int) -> None:
        """Process the events before index ``stop`` not yet processed (none once :attr:`done`)."""
        if self.done:
            return
        flt, routed, scorer, box = self._flt, self._routed, self._scorer, self._box
        mean, cov = self.mean, self.cov
        events = self._ds.events
        clock = time.perf_counter_ns
        start_s = time.perf_counter()
        try:
            while self.next < stop:
                ev = events[self.next]
                self.next += 1
                typ = type(ev)
                if typ is not Odometry and typ not in routed:
                    continue
                scorer.advance(ev.t)
                if typ is Odometry:
                    start = clock()
                    flt.predict(ev)  # type: ignore[arg-type]
                    ns = clock() - start
                else:
                    start = clock()
                    flt.update(ev)  # type: ignore[arg-type]
                    ns = clock() - start
                self._record(ev.t, _KIND_OF[typ], ns)
                # scalar tests on the row's 12 floats: np.all(np.isfinite(.)) twice cost 8 us per event, these 1 us
                m, c = mean[self.row - 1].tolist(), cov[self.row - 1].ravel().tolist()
                if not (all(map(math.isfinite, m)) and all(map(math.isfinite, c))):
                    raise FilterDiverged(f"non-finite estimate at t={ev.t:.3f} s")
                if not box.contains(m[0], m[1]):
                    raise FilterDiverged(f"{left_world(mean[self.row - 1], box)} at t={ev.t:.3f} s")
        except Exception as exc:
            self._fail(exc)
        self.wall_s += time.perf_counter() - start_s

    def finish(self) -> FilterTrace:
        """The pass's trace (after its filter's extra results and the belief scores, when it ended ok)."""
        self._check_contract()
        row = self.row
        if self._deferred:
            self.health = _gaussian_health_after(
                self._flt, self.cov[:row], {k: v[:row] for k, v in self.diags.items()}, self.health, self._first
            )
        extra: dict[str, np.ndarray] = {}
        if self.status == "ok":
            try:
                extra = {k: np.asarray(v) for k, v in self._flt.extra_results().items()}
                extra |= self._scorer.result()
            except Exception as exc:
                self.status, self.message = "error", f"extra_results failed: {type(exc).__name__}: {exc}"
        return FilterTrace(
            self.t[:row],
            self.mean[:row],
            self.cov[:row],
            self.kind[:row],
            self.step_ns[:row],
            {k: v[:row] for k, v in self.diags.items()},
            self.status,
            self.message,
            self.diverged_t,
            extra,
            {k: v[:row] for k, v in self.health.items()},
        )

    def _check_contract(self) -> None:
        """The estimate contract's values over the rows recorded (:func:`locbench.run.contract.first_violation`): the
        first violation, when it comes before the pass's own end, fails the run there (its rows end with it)."""
        found = first_violation(self.t[: self.row], self.mean[: self.row], self.cov[: self.row])
        if found is None:
            return
        i, message = found
        self.row = i + 1
        self.status, self.message, self.diverged_t = "error", message, None


_BOTH_COUNTS = " accepted+rejected"  # run_filter's key of the first row with both counts (no name has a space)


def _gaussian_health_after(
    flt: Filter,
    cov: np.ndarray,
    diags: dict[str, np.ndarray],
    event: dict[str, np.ndarray],
    first: dict[str, int],
) -> dict[str, np.ndarray]:
    """The health of a filter keeping :meth:`Filter.health`: its Gaussian signals from the run's rows
    (:func:`gaussian_health_rows`, equal bit for bit to the per-event values) with the per-event
    :meth:`Filter.event_health` arrays ``event`` (n_max rows, ``first`` the row each appeared in), every name in
    the order of its first report: by row, the Gaussian ones first as :meth:`Filter.health` merges them."""
    n = cov.shape[0]
    gauss = gaussian_health_rows(cov, diags, flt.health_nis_dof) if n else {}
    starts = {"cov_trace_xy_m2": 0, "heading_var_rad2": 0}
    if "nis" in first:
        starts |= {"nis": first["nis"], "nis_p": first["nis"]}
    if _BOTH_COUNTS in first:
        starts["accepted_fraction"] = first[_BOTH_COUNTS]
    order = [(starts[k], 0, i, k) for i, k in enumerate(GAUSSIAN_HEALTH_NAMES) if k in gauss and k in starts]
    order += [(first[" " + k], 1, i, k) for i, k in enumerate(event)]
    arrays = gauss | {k: v[:n] for k, v in event.items()}
    return {k: arrays[k] for *_, k in sorted(order)}


def run_key(fr: Resolved, dr: Resolved, seed: int) -> str:
    """The cache key of a run: everything that determines its result, the source of the filter's and the dataset
    builder's code included (:func:`locbench.core.runkey.source_digest`)."""
    fcls, dcls = FILTERS.load(fr.id), DATASETS.load(dr.id)
    return stable_hash(
        {
            "format": STORE_FORMAT,
            "filter": fr.id,
            "filter_config": key_params(fr.params),
            "filter_version": getattr(fcls, "version", 1),
            "filter_source": source_digest(fcls),
            "dataset": dr.id,
            "dataset_params": key_params(dr.params),
            "dataset_version": getattr(dcls, "version", 1),
            "dataset_source": source_digest(dcls),
            "seed": seed,
        }
    )


def bound_key(dr: Resolved, seed: int) -> str | None:
    """The cache key of a realisation's bound (what determines it), or None when the dataset has none."""
    from locbench.evaluate.pcrb import BOUND_VERSION

    dcls = DATASETS.load(dr.id)
    if not dcls.has_bound(dr.params):
        return None
    return stable_hash(
        {
            "bound_version": BOUND_VERSION,
            "dataset": dr.id,
            "dataset_params": key_params(dr.params),
            "dataset_version": getattr(dcls, "version", 1),
            "dataset_source": source_digest(dcls),
            "seed": seed,
        }
    )


#: Statuses of a sweep's outcomes beyond a stored run's own (ok, skipped, diverged, error).
CACHED, NOT_STORED = "cached", "not stored"


@dataclass(frozen=True)
class RunOutcome:
    """One line of a sweep's summary.

    ``status`` is a stored run's status (ok, skipped, diverged, error), ``cached`` (stored before and up to date)
    or ``not stored`` (the run finished but writing it failed: a full disk, a read-only folder); ``note`` says
    why a stored run was run again (its files did not load).
    """

    filter: Spec
    dataset: Spec
    seed: int
    status: str
    message: str = ""
    note: str = ""


@dataclass(frozen=True)
class Job:
    """One filter to run on a task's dataset: its resolved config, class, run key and static provenance."""

    filter: Resolved
    filter_cls: type
    key: str
    note: str = ""


@dataclass(frozen=True)
class Task:
    """One dataset realisation and the filters to run on it: the unit an executor hands to a worker.

    It carries the classes themselves (pickled by reference), so a worker needs the code installed but no
    registry entry: test-only or plugin filters run on a dask worker as they run here.
    """

    dataset: Resolved
    dataset_cls: type
    seed: int
    jobs: tuple[Job, ...]
    #: Estimated compute time, s (the plan's order: longest first).
    cost_s: float = 0.0
    #: The key of the realisation's bound to compute and store, or None (recorded data, kidnaps, stored).
    bound_key: str | None = None
    #: Interleaved timing: the seconds of data each filter runs before the next takes over (:func:`_interleaved`);
    #: 0 runs each filter over the whole dataset in turn.
    slice_s: float = 0.0
    #: The time limit of each run, s: None for the default rule on the dataset's duration
    #: (:func:`locbench.run.containment.run_time_limit`), ``inf`` for none; by default the command's ``--run-timeout``.
    run_timeout_s: float | None = field(default_factory=current_run_timeout)

    @property
    def label(self) -> str:
        return f"{self.dataset.name} seed {self.seed}"


@dataclass
class TaskResult:
    """What a worker returns: the realisation's truth (None when the dataset did not build), one record per job."""

    truth: TruthRecord | None
    runs: list[RunRecord]
    bound: BoundRecord | None = None


@dataclass
class Plan:
    """The work of a sweep: tasks to execute, longest first, and the runs already stored."""

    tasks: list[Task]
    cached: list[RunOutcome]
    results: str
    #: (dataset name, seed, filter name) -> position in the order the specs were given, for the summary.
    order: dict[tuple[str, int, str], int] = field(default_factory=dict)

    @property
    def total(self) -> int:
        """Every run of the sweep, cached or to do."""
        return len(self.cached) + sum(len(t.jobs) for t in self.tasks)


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


#: Rough cost of a realisation's bound, s (0.03-0.5 s measured on the synthetic worlds).
_BOUND_COST_S = 0.5


def _estimate_cost(
    store: Store, dr: Resolved, jobs: Sequence[Job], seen: dict[tuple[str, str], dict[str, Any] | None]
) -> float:
    """Estimated compute time of a task, s: stored wall times of the same (dataset, filter) where present.

    ``seen`` caches one stored ``meta.json`` per (dataset, filter) across the tasks of a plan.
    """
    # before any timing is stored: the costs the filter and dataset classes declare (only the order of tasks
    # depends on them)
    duration = DATASETS.load(dr.id).nominal_duration_s
    total = 0.0
    for job in jobs:
        pair = (dr.name, job.filter.name)
        if pair not in seen:
            seen[pair] = store.sample_meta(*pair)
        stored = seen[pair]
        if stored is not None and isinstance(stored.get("wall_s"), (int, float)) and stored.get("status") == "ok":
            total += float(stored["wall_s"])
            continue
        cls: type[Filter] = job.filter_cls
        total += duration * cls.cost_per_data_s * cls.cost_scale(job.filter.params)
    return total


def plan_sweep(
    blocks: Sequence[tuple[Sequence[str], Sequence[str], Sequence[int]]],
    results: str,
    force: bool = False,
    slice_s: float = 0.0,
) -> Plan:
    """Resolve every spec and decide which runs to do; nothing is run or written.

    Parameters
    ----------
    blocks : sequence of (filter specs, dataset specs, seeds)
        Every filter on every dataset for every seed, block after block (a run named twice is planned once).
    results : str
        The results folder; a run whose stored key is unchanged and whose files load is cached.
    force : bool
        Plan every run even when it is stored.
    slice_s : float
        Interleaved timing (:attr:`Task.slice_s`): the filters of each task take turns over this many seconds of
        data; 0 (default) runs them one after the other.
    """
    store = Store(results)
    plan = Plan([], [], results)
    groups: dict[tuple[str, int], tuple[Resolved, dict[str, Job]]] = {}
    truths: dict[tuple[str, int], str | None] = {}  # why a realisation's stored truth is stale, or None
    for fspecs, dspecs, seeds in blocks:
        frs = [resolve_filter(s) for s in fspecs]
        drs = [resolve_dataset(s) for s in dspecs]
        fclasses = {fr.id: FILTERS.load(fr.id) for fr in frs}
        for dr in drs:
            for seed in seeds:
                _, jobs = groups.setdefault((dr.name, seed), (dr, {}))
                for fr in frs:
                    if fr.name in jobs or (dr.name, seed, fr.name) in plan.order:
                        continue
                    plan.order[(dr.name, seed, fr.name)] = len(plan.order)
                    key = run_key(fr, dr, seed)
                    note = ""
                    meta = None if force else store.existing_meta(dr.name, fr.name, seed)
                    up_to_date = meta is not None and meta.get("run_key") == key and not meta.get("transient")
                    if up_to_date and (dr.name, seed) not in truths:
                        truths[(dr.name, seed)] = store.truth_problem(dr.name, seed)
                    if up_to_date and truths[(dr.name, seed)] is not None:
                        note = f"re-run: the stored ground truth is stale ({truths[(dr.name, seed)]})"
                    elif up_to_date:
                        bad = store.unreadable(dr.name, fr.name, seed)
                        if bad is None:
                            plan.cached.append(RunOutcome(fr.spec, dr.spec, seed, CACHED))
                            continue
                        note = f"re-run: the stored run does not load ({bad})"
                    jobs[fr.name] = Job(fr, fclasses[fr.id], key, note)
    seen: dict[tuple[str, str], dict[str, Any] | None] = {}
    for (_, seed), (dr, jobs) in groups.items():
        bkey = bound_key(dr, seed)
        if bkey is not None and not force and store.bound_key(dr.name, seed) == bkey:
            bkey = None  # stored and up to date
        if jobs or bkey is not None:
            todo = tuple(jobs.values())
            cost = _estimate_cost(store, dr, todo, seen) + (_BOUND_COST_S if bkey is not None else 0.0)
            plan.tasks.append(Task(dr, DATASETS.load(dr.id), seed, todo, cost, bkey, slice_s))
    # Longest first (LPT): the last tasks to start are short, so the workers finish together.
    plan.tasks.sort(key=lambda t: -t.cost_s)
    return plan


def _meta(task: Task, job: Job) -> dict[str, Any]:
    """The provenance of one run, taken where it runs (the worker's library versions and commit)."""
    git = provenance.git_state()
    fr, dr = job.filter, task.dataset
    return {
        "filter": fr.name,
        "filter_id": fr.id,
        "filter_config": fr.params_dict(),
        "filter_version": getattr(job.filter_cls, "version", 1),
        "filter_distribution": provenance.distribution(job.filter_cls),
        "dataset": dr.name,
        "dataset_id": dr.id,
        "dataset_params": dr.params_dict(),
        "dataset_version": getattr(task.dataset_cls, "version", 1),
        "dataset_distribution": provenance.distribution(task.dataset_cls),
        "seed": task.seed,
        "run_key": job.key,
        "versions": provenance.versions(),
        "git_commit": git["commit"],
        "git_dirty": git["dirty"],
        # the machine, its load as the run starts and the reference workload's time (runtimes in reference units)
        **provenance.machine(),
    }


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


def forget_realisations() -> None:
    """Drop this process's kept realisations (:data:`_REALISATION`): their memory once a sweep is over."""
    _REALISATION.clear()


def _realisation(task: Task) -> tuple[Dataset, TruthRecord] | _BuildFailed:
    """The task's dataset and its truth's record, built or kept from the previous part; or why it did not build."""
    key = (task.dataset_cls, task.dataset.name, task.seed)
    kept = _REALISATION.pop(key, None)
    if kept is not None:
        _REALISATION[key] = kept  # the newest now
        return kept
    while len(_REALISATION) >= _KEEP:
        del _REALISATION[next(iter(_REALISATION))]
    dr = task.dataset
    t_build = time.perf_counter()
    built: tuple[Dataset, TruthRecord] | _BuildFailed
    try:
        ds: Dataset = build_dataset(task.dataset_cls, dr, task.seed)
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
            "dataset_params": dr.params_dict(),
            "dataset_version": getattr(task.dataset_cls, "version", 1),
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
    return TaskResult(truth, _runs(task, ds), bound)


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
    # the provenance every record takes, computed here once: a child's caches die with it
    provenance.versions()
    provenance.git_state()
    limit = run_time_limit(ds.duration, task.run_timeout_s)
    rule = DEFAULT_RULE if task.run_timeout_s is None else "--run-timeout"
    outcome = call_in_child(lambda: _runs(task, ds), limit * max(1, len(task.jobs)))
    if outcome.ok:
        runs: list[RunRecord] = outcome.value
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
    return TaskResult(truth, runs, bound)


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
    flt: Filter = job.filter_cls(job.filter.params)
    reason = incompatibility(flt, ds)
    if reason is not None:
        return _empty_record(meta | {"status": "skipped", "message": reason, "wall_s": 0.0})
    start = time.perf_counter()
    trace = run_filter(flt, ds, *_rngs(task, job))
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
        flt: Filter = job.filter_cls(job.filter.params)
        reason = incompatibility(flt, ds)
        if reason is not None:
            out[i] = _empty_record(meta | {"status": "skipped", "message": reason, "wall_s": 0.0})
            continue
        live.append((i, job, meta, FilterPass(flt, ds, *_rngs(task, job))))
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


def store_result(
    store: Store, task: Task, result: TaskResult, written: set[tuple[str, int]] | None = None
) -> list[RunOutcome]:
    """Write a task's truth and runs; a write that fails (disk full, read-only) is a ``not stored`` outcome
    whose message names the run's folder and the reason.

    ``written`` holds the (dataset, seed) whose truth this sweep stored already: each part of a task carries
    the same truth, written once, before the first of its runs.
    """
    notes = {job.filter.name: job for job in task.jobs}
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
    for rec in result.runs:
        job = notes[rec.meta["filter"]]
        fspec, dspec = job.filter.spec, task.dataset.spec
        where = store.run_dir(task.dataset.name, job.filter.name, task.seed)
        if truth_error:
            outcomes.append(
                RunOutcome(fspec, dspec, task.seed, NOT_STORED, f"seed {task.seed} -> {where}: {truth_error}")
            )
            continue
        try:
            store.write_run(rec)
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
    from locbench.run import executors

    store = Store(plan.results)
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


def run_group(
    dataset_spec: str, filter_specs: Sequence[str], seed: int, results: str, force: bool = False
) -> list[RunOutcome]:
    """Build one dataset realisation and run, in this process, every filter that has no up-to-date stored run on it."""
    return run_many(filter_specs, [dataset_spec], [seed], results, force=force)


def run_many(
    filter_specs: Sequence[str],
    dataset_specs: Sequence[str],
    seeds: Sequence[int],
    results: str,
    jobs: int = 1,
    force: bool = False,
    progress: Callable[[int], None] | None = None,
    executor: str = "local",
    scheduler: str | None = None,
) -> list[RunOutcome]:
    """Run every filter on every dataset for every seed; returns one outcome per run, in the order given.

    Specs are resolved first, so an unknown id or parameter fails before anything runs (see :func:`run_sweep`).
    """
    plan = plan_sweep([(filter_specs, dataset_specs, seeds)], results, force)
    return run_sweep(plan, executor, jobs, scheduler, progress).outcomes
