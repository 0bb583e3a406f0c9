"""What a sweep will run: specs parsed once, run keys, and the tasks to execute.

A filter or dataset spec is parsed here once (:func:`parse_filter`, :func:`parse_dataset`) into a typed value that
holds its resolution against the registry, its class and its :class:`~locbench.core.spec.Spec`; every later stage
(the task a worker runs, the record it returns, the store's folder, the sweep's summary) passes that value on
instead of the text. A filter's value also carries its :class:`FilterTraits`, which each of its runs records for
the report.

:func:`plan_sweep` decides the work: every spec parsed (a bad one fails before anything runs), each (dataset,
seed) a :class:`Task` holding the filters that have no up-to-date stored run on it (:func:`run_key`), the tasks
sorted longest first (stored timings where present, else the classes' declared costs) so that no worker idles at
the end. Nothing is run or written here.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Generic, TypeVar

from locbench.core.errors import ConfigError
from locbench.core.runkey import key_params, source_digest
from locbench.core.spec import Spec, format_spec, stable_hash
from locbench.datasets.dataset import DatasetBuilder
from locbench.filters.base import MAX_SCORE_SAMPLE, SCORE_SAMPLE_SIZE, Filter
from locbench.registry import DATASETS, FILTERS, Resolved, resolve_dataset, resolve_filter
from locbench.run.containment import current_run_timeout
from locbench.run.store import Store

log = logging.getLogger(__name__)

#: Bump when the meaning of stored arrays changes; part of every run key.
STORE_FORMAT = 2


@dataclass(frozen=True)
class FilterTraits:
    """What the report labels a filter configuration by, asked of its class once, when the sweep is planned.

    Every run of the configuration records it (``meta["filter_traits"]``, :meth:`record`), so that the report
    reads what a run was from its record rather than re-deriving it from a name.

    Attributes
    ----------
    baseline : bool
        The class is the baseline every comparison starts with (``Filter.baseline``).
    global_start : bool
        The configuration ignores the initial belief (``Filter.starts_without_pose``).
    kidnap_name : str or None
        The canonical name of this configuration with the class's kidnap parameters set (``Filter.kidnap_params``);
        None when the class declares none.
    sensors : tuple of str
        The event types the configuration routes (``Filter.routed_events``), by class name, sorted.
    maps : tuple of str
        The map kinds the class requires (``Filter.requires``), by value (``occupancy``), sorted.
    """

    baseline: bool
    global_start: bool
    kidnap_name: str | None
    sensors: tuple[str, ...]
    maps: tuple[str, ...]

    @classmethod
    def of(cls, filter_cls: type[Filter], resolved: Resolved, spec: Spec) -> FilterTraits:
        """The traits of the configuration ``resolved`` (``spec``, its canonical name parsed) of ``filter_cls``; its
        kidnap configuration is resolved in the registry.

        A filter does no work in ``__init__`` (the interface's rule), so asking an instance what it routes is cheap.
        """
        extra = dict(getattr(filter_cls, "kidnap_params", {}) or {})
        kidnap = resolve_filter(format_spec(spec.ident, spec.as_dict() | extra)).name if extra else None
        return cls(
            bool(filter_cls.baseline),
            bool(filter_cls.starts_without_pose(resolved.params)),
            kidnap,
            tuple(sorted(t.__name__ for t in filter_cls(resolved.params).routed_events())),
            tuple(sorted(k.value for k in filter_cls.requires)),
        )

    def record(self) -> dict[str, Any]:
        """The traits as a run's record holds them (JSON: lists for the tuples)."""
        return {
            "baseline": self.baseline,
            "global_start": self.global_start,
            "kidnap_name": self.kidnap_name,
            "sensors": list(self.sensors),
            "maps": list(self.maps),
        }

    @classmethod
    def from_record(cls, value: object) -> FilterTraits | None:
        """The traits a run's record holds (:meth:`record`), or None when it holds none or a malformed value."""
        if not isinstance(value, Mapping):
            return None
        flags = value.get("baseline"), value.get("global_start")
        kidnap, sensors, maps = value.get("kidnap_name"), value.get("sensors"), value.get("maps")
        if not all(isinstance(f, bool) for f in flags) or not (kidnap is None or isinstance(kidnap, str)):
            return None
        names = (sensors, maps)
        if not all(isinstance(n, list) and all(isinstance(x, str) for x in n) for n in names):
            return None
        assert isinstance(sensors, list) and isinstance(maps, list)
        return cls(bool(flags[0]), bool(flags[1]), kidnap, tuple(sensors), tuple(maps))


def filter_traits(filter_cls: type[Filter], resolved: Resolved, spec: Spec) -> FilterTraits | None:
    """:meth:`FilterTraits.of`, or None when the class cannot answer (its runs then record none, and the report
    describes the configuration by its name alone)."""
    try:
        return FilterTraits.of(filter_cls, resolved, spec)
    except Exception as exc:  # a plug-in's class that fails here still runs, and fails there with its reason
        log.info("filter %s: no traits recorded: %s: %s", resolved.name, type(exc).__name__, exc)
        return None


C = TypeVar("C")


@dataclass(frozen=True)
class Parsed(Generic[C]):
    """A spec parsed once: its resolution against the registry (id, typed parameters, canonical name), its class
    and its :class:`Spec`. The class travels with it (pickled by reference), so a worker needs the code installed
    but no registry entry: test-only or plugin classes run on a dask worker as they run here."""

    resolved: Resolved
    cls: type[C]
    spec: Spec

    @property
    def id(self) -> str:
        """The registry id (``pf``)."""
        return self.resolved.id

    @property
    def name(self) -> str:
        """The canonical name (``pf[particles=300]``): the store's folder and the report's row."""
        return self.resolved.name

    @property
    def params(self) -> Any:
        """The typed parameters (the class's ``Config`` or ``Params`` dataclass)."""
        return self.resolved.params

    @property
    def version(self) -> Any:
        """The class's ``version`` (1 when it declares none): part of the run key and of every run's record."""
        return getattr(self.cls, "version", 1)


@dataclass(frozen=True)
class ParsedFilter(Parsed[Filter]):
    """A filter spec parsed once (:func:`parse_filter`), with its :class:`FilterTraits` (None: not known)."""

    traits: FilterTraits | None = None


@dataclass(frozen=True)
class ParsedDataset(Parsed[DatasetBuilder]):
    """A dataset spec parsed once (:func:`parse_dataset`)."""


def parse_filter(spec: str) -> ParsedFilter:
    """Parse and resolve a filter spec (``ekf_landmarks[association=nearest]``); an unknown id or parameter is a
    :class:`~locbench.core.errors.ConfigError` naming what is valid."""
    r = resolve_filter(spec)
    cls, parsed = FILTERS.load(r.id), Spec.parse(r.name)
    return ParsedFilter(r, cls, parsed, filter_traits(cls, r, parsed))


def parse_dataset(spec: str) -> ParsedDataset:
    """Parse and resolve a dataset spec (``room[kidnap_m=2]``), as :func:`parse_filter`."""
    r = resolve_dataset(spec)
    return ParsedDataset(r, DATASETS.load(r.id), Spec.parse(r.name))


def samples_belief(cls: type[Filter]) -> bool:
    """Whether the filter class exposes belief samples (:meth:`Filter.belief_sample`), scored while it runs."""
    return cls.belief_sample is not Filter.belief_sample


def run_key(fr: ParsedFilter, dr: ParsedDataset, seed: int, score_sample: int = SCORE_SAMPLE_SIZE) -> str:
    """The cache key of a run: everything that determines its result, the source of the filter's and the dataset
    builder's code included (:func:`locbench.core.runkey.source_digest`).

    A filter that samples its belief (:func:`samples_belief`) stores the scores of its samples, so its key also
    holds the sample size ``score_sample`` (the run setting) and the estimator of those scores
    (:data:`locbench.evaluate.scores.SAMPLE_ESTIMATOR`); a Gaussian filter's key has neither.
    """
    scoring: dict[str, Any] = {}
    if samples_belief(fr.cls):
        # imported here: scipy and numba stay out of planning unless a sampled run is planned
        from locbench.evaluate.scores import SAMPLE_ESTIMATOR

        scoring = {"belief_scores": {"sample": score_sample, "estimator": SAMPLE_ESTIMATOR}}
    return stable_hash(
        scoring
        | {
            "format": STORE_FORMAT,
            "filter": fr.id,
            "filter_config": key_params(fr.params),
            "filter_version": fr.version,
            "filter_source": source_digest(fr.cls),
            "dataset": dr.id,
            "dataset_params": key_params(dr.params),
            "dataset_version": dr.version,
            "dataset_source": source_digest(dr.cls),
            "seed": seed,
        }
    )


def bound_key(dr: ParsedDataset, seed: int) -> str | None:
    """The cache key of a realisation's bound (what determines it), or None when the dataset has none."""
    from locbench.evaluate.pcrb import BOUND_VERSION

    if not dr.cls.has_bound(dr.params):
        return None
    return stable_hash(
        {
            "bound_version": BOUND_VERSION,
            "dataset": dr.id,
            "dataset_params": key_params(dr.params),
            "dataset_version": dr.version,
            "dataset_source": source_digest(dr.cls),
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
    """One filter to run on a task's dataset: its parsed spec, its run key, and why it runs again (if it does)."""

    filter: ParsedFilter
    key: str
    note: str = ""


@dataclass(frozen=True)
class Task:
    """One dataset realisation and the filters to run on it: the unit an executor hands to a worker."""

    dataset: ParsedDataset
    seed: int
    jobs: tuple[Job, ...]
    #: Estimated compute time, s (the plan's order: longest first).
    cost_s: float = 0.0
    #: The key of the realisation's bound to compute and store, or None (recorded data, kidnaps, stored).
    bound_key: str | None = None
    #: Interleaved timing: the seconds of data each filter runs before the next takes over
    #: (:func:`locbench.run.execute.execute_task`); 0 runs each filter over the whole dataset in turn.
    slice_s: float = 0.0
    #: The time limit of each run, s: None for the default rule on the dataset's duration
    #: (:func:`locbench.run.containment.run_time_limit`), ``inf`` for none; by default the command's ``--run-timeout``.
    run_timeout_s: float | None = field(default_factory=current_run_timeout)
    #: Members of each belief sample scored (:meth:`Filter.belief_sample`): the run setting of
    #: :func:`plan_sweep`, part of the run key of a filter that samples its belief.
    score_sample: int = SCORE_SAMPLE_SIZE
    #: Whether the worker computes each ok run's derived values for the report and the store keeps them
    #: (:func:`locbench.run.execute.derived_values`); false for tuning's train runs, which no report reads.
    derive: bool = True

    @property
    def label(self) -> str:
        return f"{self.dataset.name} seed {self.seed}"


@dataclass
class Plan:
    """The work of a sweep: tasks to execute, longest first, the runs already stored, and the store they go to."""

    tasks: list[Task]
    cached: list[RunOutcome]
    store: Store
    #: (dataset name, seed, filter name) -> position in the order the specs were given, for the summary.
    order: dict[tuple[str, int, str], int] = field(default_factory=dict)

    @property
    def total(self) -> int:
        """Every run of the sweep, cached or to do."""
        return len(self.cached) + sum(len(t.jobs) for t in self.tasks)


#: Rough cost of a realisation's bound, s (0.03-0.5 s measured on the synthetic worlds).
_BOUND_COST_S = 0.5


def _estimate_cost(
    store: Store, dr: ParsedDataset, jobs: Sequence[Job], seen: dict[tuple[str, str], dict[str, Any] | None]
) -> float:
    """Estimated compute time of a task, s: stored wall times of the same (dataset, filter) where present.

    ``seen`` caches one stored ``meta.json`` per (dataset, filter) across the tasks of a plan.
    """
    # before any timing is stored: the costs the filter and dataset classes declare (only the order of tasks
    # depends on them)
    duration = dr.cls.nominal_duration_s
    total = 0.0
    for job in jobs:
        pair = (dr.name, job.filter.name)
        if pair not in seen:
            seen[pair] = store.sample_meta(*pair)
        stored = seen[pair]
        if stored is not None and isinstance(stored.get("wall_s"), (int, float)) and stored.get("status") == "ok":
            total += float(stored["wall_s"])
            continue
        cls = job.filter.cls
        total += duration * cls.cost_per_data_s * cls.cost_scale(job.filter.params)
    return total


P = TypeVar("P", bound=Parsed[Any])


def _once(spec: str | P, cache: dict[str, P], parse: Callable[[str], P]) -> P:
    """``spec`` parsed (each text once per plan), or itself when it is parsed already."""
    if not isinstance(spec, str):
        return spec
    if spec not in cache:
        cache[spec] = parse(spec)
    return cache[spec]


def plan_sweep(
    blocks: Sequence[tuple[Sequence[str | ParsedFilter], Sequence[str | ParsedDataset], Sequence[int]]],
    results: Store | str | os.PathLike[str],
    force: bool = False,
    slice_s: float = 0.0,
    score_sample: int = SCORE_SAMPLE_SIZE,
    derive: bool = True,
) -> Plan:
    """Parse every spec and decide which runs to do; nothing is run or written.

    Parameters
    ----------
    blocks : sequence of (filter specs, dataset specs, seeds)
        Every filter on every dataset for every seed, block after block (a run named twice is planned once); a
        spec is a text (parsed here, once) or a value of :func:`parse_filter` / :func:`parse_dataset`.
    results : Store or path
        The results folder; a run whose stored key is unchanged and whose files load is cached.
    force : bool
        Plan every run even when it is stored.
    slice_s : float
        Interleaved timing (:attr:`Task.slice_s`): the filters of each task take turns over this many seconds of
        data; 0 (default) runs them one after the other.
    score_sample : int
        Members of each belief sample a filter that samples its belief is scored by (:attr:`Task.score_sample`;
        ``--score-sample``); it enters those filters' run keys, so changing it re-runs them.
    derive : bool
        Store each ok run's derived values with it (:attr:`Task.derive`); false where no report reads the runs.
    """
    if not 2 <= score_sample <= MAX_SCORE_SAMPLE:
        # at least a pair to estimate the spread from
        raise ConfigError(f"the score sample must have 2 to {MAX_SCORE_SAMPLE} members, got {score_sample}")
    store = results if isinstance(results, Store) else Store(results)
    plan = Plan([], [], store)
    groups: dict[tuple[str, int], tuple[ParsedDataset, dict[str, Job]]] = {}
    truths: dict[tuple[str, int], str | None] = {}  # why a realisation's stored truth is stale, or None
    filters: dict[str, ParsedFilter] = {}
    datasets: dict[str, ParsedDataset] = {}
    for fspecs, dspecs, seeds in blocks:
        frs = [_once(s, filters, parse_filter) for s in fspecs]
        drs = [_once(s, datasets, parse_dataset) for s in dspecs]
        for dr in drs:
            for seed in seeds:
                _, jobs = groups.setdefault((dr.name, seed), (dr, {}))
                for fr in frs:
                    if fr.name in jobs or (dr.name, seed, fr.name) in plan.order:
                        continue
                    plan.order[(dr.name, seed, fr.name)] = len(plan.order)
                    key = run_key(fr, dr, seed, score_sample)
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
                    jobs[fr.name] = Job(fr, key, note)
    seen: dict[tuple[str, str], dict[str, Any] | None] = {}
    for (_, seed), (dr, jobs) in groups.items():
        bkey = bound_key(dr, seed)
        if bkey is not None and not force and store.bound_key(dr.name, seed) == bkey:
            bkey = None  # stored and up to date
        if jobs or bkey is not None:
            todo = tuple(jobs.values())
            cost = _estimate_cost(store, dr, todo, seen) + (_BOUND_COST_S if bkey is not None else 0.0)
            plan.tasks.append(Task(dr, seed, todo, cost, bkey, slice_s, score_sample=score_sample, derive=derive))
    # Longest first (LPT): the last tasks to start are short, so the workers finish together.
    plan.tasks.sort(key=lambda t: -t.cost_s)
    return plan
