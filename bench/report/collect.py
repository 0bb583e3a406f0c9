"""Reading the store once: the tidy metrics, each run's status, and what the figures need.

This is the report's only I/O on stored runs. Every dataset and filter name is parsed here, once, into a
:class:`~locbench.core.spec.Spec`, beside the facts the report needs about it: of a filter configuration, the
traits its runs recorded when they were planned (:class:`locbench.run.plan.FilterTraits`: the baseline, a start
without a pose, its kidnap configuration, the sensors and maps it uses); of a dataset, whether it is recorded and
the name to print, asked of the registry's classes. The rest of the report never looks inside a name.
"""

from __future__ import annotations

import io
import logging
import os
import re
from collections import defaultdict
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from locbench.core.spec import Spec, format_spec, params_to_dict
from locbench.evaluate.derived import Derived, derive
from locbench.evaluate.lost import HealthSeries
from locbench.evaluate.metrics import run_metrics
from locbench.evaluate.pcrb import BOUND_ROWS, is_bound_row, pcrb_summary
from locbench.evaluate.records import RunRecord, TruthRecord
from locbench.run.plan import FilterTraits, parse_filter
from locbench.run.store import Store, truth_key

log = logging.getLogger(__name__)

COLUMNS = ("dataset", "filter", "seed", "metric", "value")
#: ``value`` is written with 10 significant digits: stable, and far below any metric's noise.
FLOAT_FORMAT = "%.10g"


@dataclass(frozen=True)
class RunInfo:
    """Status of one stored run, for the failure list."""

    dataset: str
    filter: str
    seed: int
    status: str
    message: str


@dataclass(frozen=True)
class DatasetInfo:
    """What the report knows of a stored dataset name."""

    name: str
    spec: Spec
    recorded: bool
    #: The name as printed: recorded datasets with their identifying parameters spelled out.
    display: str


@dataclass(frozen=True)
class FilterInfo:
    """What the report knows of a stored filter name."""

    name: str
    spec: Spec
    baseline: bool
    global_start: bool
    #: A row of the posterior Cramer-Rao bound, not a filter (:mod:`locbench.evaluate.pcrb`).
    bound: bool = False
    #: The canonical name of its kidnap configuration as its class declares it (``Filter.kidnap_params``).
    kidnap_name: str | None = None
    #: The event types this configuration uses (``Filter.routed_events``), by class name; empty: not known.
    sensors: tuple[str, ...] = ()
    #: The map kinds its class requires (``Filter.requires``), by value (``occupancy``).
    maps: tuple[str, ...] = ()


@dataclass
class Collected:
    """Everything the report needs from one pass over the store."""

    metrics: pd.DataFrame
    runs: list[RunInfo] = field(default_factory=list)
    broken: list[tuple[str, str]] = field(default_factory=list)
    metas: list[dict[str, Any]] = field(default_factory=list)
    #: (dataset, filter) -> one (t, nees) series per ok run
    nees: dict[tuple[str, str], list[tuple[np.ndarray, np.ndarray]]] = field(default_factory=dict)
    #: (dataset, filter, seed) -> run folder of ok runs
    ok_dirs: dict[tuple[str, str, int], Path] = field(default_factory=dict)
    #: (dataset, filter) -> one lost-detection series per ok run with stored health and ground truth
    health: dict[tuple[str, str], list[HealthSeries]] = field(default_factory=dict)
    truths: dict[tuple[str, int], TruthRecord] = field(default_factory=dict)
    datasets: dict[str, DatasetInfo] = field(default_factory=dict)
    filters: dict[str, FilterInfo] = field(default_factory=dict)
    store: Store | None = None

    def read_run(self, dataset: str, filter_name: str, seed: int) -> RunRecord:
        """The stored ok run (estimates and covariances) of one cell, through the store's API."""
        if self.store is None:
            raise RuntimeError("no store behind these metrics")
        return self.store.read_run(self.ok_dirs[(dataset, filter_name, seed)])

    def filter_order(self, names: Sequence[str] | set[str]) -> list[str]:
        """The baseline first (the row every table starts with), then by name with numbers in numeric order
        (a sweep reads ``particles=100``, ``300``, ``1000``, ``3000``), the bound's rows last."""
        return sorted(set(names), key=lambda n: (self._filter(n).bound, not self._filter(n).baseline, natural_key(n)))

    def _filter(self, name: str) -> FilterInfo:
        if name not in self.filters:
            self.filters[name] = describe_filter(name)
        return self.filters[name]

    def filter_info(self, name: str) -> FilterInfo:
        """What the report knows of a filter name (described on first use)."""
        return self._filter(name)

    def is_baseline(self, name: str) -> bool:
        return self._filter(name).baseline

    def is_bound(self, name: str) -> bool:
        return self._filter(name).bound

    def is_global(self, name: str) -> bool:
        return self._filter(name).global_start

    def display(self, dataset: str) -> str:
        info = self.datasets.get(dataset)
        return info.display if info is not None else dataset


_NUMBER = re.compile(r"(\d+(?:\.\d+)?(?:e[-+]?\d+)?)")


def natural_key(name: str) -> tuple[tuple[int, float, str], ...]:
    """Sort key of a name whose numbers compare as numbers: ``f[n=300]`` before ``f[n=1000]``."""
    return tuple((1, float(part), "") if i % 2 else (0, 0.0, part) for i, part in enumerate(_NUMBER.split(name)))


# --- what a name means, asked of the registry -----------------------------------------------------------


def describe_filter(name: str, traits: FilterTraits | None = None) -> FilterInfo:
    """What the report knows of a filter name: the traits its runs recorded (``traits``).

    A configuration whose runs recorded none (stored before runs recorded them) has them derived as a sweep derives
    them when it plans (:func:`locbench.run.plan.parse_filter`); one whose class cannot be loaded here (an optional
    dependency missing, a plug-in gone) is described by its name alone: not the baseline, starting from the belief.
    """
    spec = Spec.parse(name)
    if is_bound_row(name):
        return FilterInfo(name, spec, False, False, bound=True)
    if traits is None:
        try:
            traits = parse_filter(name).traits
        except Exception as exc:  # the report must still come out without the class
            log.info("filter %s described by its name only: %s", name, exc)
    if traits is None:
        return FilterInfo(name, spec, False, False)
    return FilterInfo(
        name,
        spec,
        traits.baseline,
        traits.global_start,
        kidnap_name=traits.kidnap_name,
        sensors=traits.sensors,
        maps=traits.maps,
    )


def describe_dataset(name: str) -> DatasetInfo:
    """Parse a stored dataset name; recorded datasets get their identifying parameters spelled out."""
    from locbench.datasets.recorded.common import RecordedDataset
    from locbench.registry import DATASETS, resolve_dataset

    spec = Spec.parse(name)
    try:
        cls: Any = DATASETS.load(spec.ident)
    except Exception as exc:
        log.info("dataset %s described by its name only: %s", name, exc)
        return DatasetInfo(name, spec, False, name)
    if not (isinstance(cls, type) and issubclass(cls, RecordedDataset)):
        return DatasetInfo(name, spec, False, name)
    try:
        full = params_to_dict(resolve_dataset(name).params)
    except Exception:
        full = {}
    shown = {k: full[k] for k in cls.identity_keys if k in full}
    shown.update(spec.as_dict())
    return DatasetInfo(name, spec, True, format_spec(spec.ident, shown))


# --- collecting -----------------------------------------------------------------------------------------

#: Selects the (dataset, filter) cells a report covers (``--suite``); None keeps every stored run.
Keep = Callable[[str, str], bool]


#: What reading one run gives: ("ok", rel, (meta, info, rows, truth key or None, nees or None, run folder)) or
#: ("broken", rel, message); the truths read along the way come back beside these.
_RunRead = tuple[str, str, Any]

#: The truths a forked reader has read (:func:`_read_group`): each realisation's once per process.
_TRUTHS: dict[tuple[str, int], TruthRecord] = {}


def _read_runs(
    store: Store,
    keep: Keep | None,
    run_dirs: Sequence[Path],
    truths: dict[tuple[str, int], TruthRecord] | None = None,
) -> tuple[list[_RunRead], dict[Any, Any]]:
    """Read ``run_dirs`` in order and compute each ok run's metrics and NEES series against its truth.

    ``truths`` caches the truths read (a worker keeps one over all its calls); returned with the reads.
    """
    reads: list[_RunRead] = []
    truths = {} if truths is None else truths
    keys: dict[tuple[str, int], str] = {}
    for run_dir in run_dirs:
        rel = _relative(run_dir, store.root)
        try:
            stored = store.read_derived(run_dir)
            run = None
            if stored is not None:
                meta = stored[0]
            else:
                run = store.read_run(run_dir)
                meta = run.meta
            dataset, filt, seed = str(meta["dataset"]), str(meta["filter"]), int(meta["seed"])
            if keep is not None and not keep(dataset, filt):
                continue
            key: tuple[str, int] | None = None
            derived: Derived | None = None
            status = str(meta.get("status", "error"))
            if status == "ok":
                key = (dataset, seed)
                if key not in truths:
                    truths[key] = store.read_truth(dataset, seed)
                truth = truths[key]
                if key not in keys:
                    keys[key] = truth_key(truth)
                # the values the run's worker stored, while they hold for this truth; computed again otherwise
                if stored is not None and stored[2] == keys[key]:
                    derived = stored[1]
                else:
                    derived = derive(run if run is not None else store.read_run(run_dir), truth)
                values = derived.values
            else:
                values = run_metrics(run if run is not None else store.read_run(run_dir), _NO_TRUTH)
        except Exception as exc:
            log.warning("skipping unreadable run %s: %s", rel, exc)
            # Paths relative to the results folder keep the report independent of where it lives.
            msg = str(exc).replace(f"{store.root.as_posix()}/", "")
            reads.append(("broken", rel, f"{type(exc).__name__}: {msg}"))
            continue
        info = RunInfo(dataset, filt, seed, status, str(meta.get("message", "") or ""))
        rows = [(dataset, filt, seed, k, float(v)) for k, v in values.items()]
        ne = derived.nees if derived is not None else None
        hs = derived.health if derived is not None else None
        reads.append(("ok", rel, (meta, info, rows, key, ne, run_dir, hs)))
    return reads, truths


def _read_group(
    store: Store, keep: Keep | None, run_dirs: list[Path], indices: list[int]
) -> tuple[list[tuple[int, list[_RunRead]]], dict[Any, Any]]:
    """Runs ``indices`` of ``run_dirs``, each with its reads, and the truths this process read first for them
    (kept in :data:`_TRUTHS` for the next group it reads)."""
    known = set(_TRUTHS)
    out = [(i, _read_runs(store, keep, [run_dirs[i]], _TRUTHS)[0]) for i in indices]
    return out, {k: v for k, v in _TRUTHS.items() if k not in known}


def _cost(run_dir: Path) -> int:
    """Bytes of a run's files: the work of its metrics grows with its rows and its truth's times."""
    try:
        return sum(e.stat().st_size for e in os.scandir(run_dir) if e.is_file())
    except OSError:
        return 0


def realisation_groups(run_dirs: Sequence[Path]) -> list[list[int]]:
    """The indices of ``run_dirs`` grouped by the realisation their folders name (``<dataset>/*/seed-<n>``: the runs
    that share one truth), the groups in order of first appearance, each in the order of ``run_dirs``."""
    groups: dict[tuple[str, str], list[int]] = {}
    for i, d in enumerate(run_dirs):
        groups.setdefault((d.parent.parent.name, d.name), []).append(i)
    return list(groups.values())


def _read_parallel(store: Store, keep: Keep | None, run_dirs: list[Path], jobs: int) -> list[Any]:
    """:func:`_read_runs` over ``jobs`` forked processes (:func:`locbench.report.forked.forked_map`), one
    realisation's runs per task (its truth read by one worker, once), largest first (the recordings' runs take
    seconds each, a synthetic one milliseconds), the results put back in the order of ``run_dirs``."""
    from locbench.report.forked import forked_map

    cost = [_cost(d) for d in run_dirs]
    tasks = sorted(realisation_groups(run_dirs), key=lambda g: -sum(cost[i] for i in g))
    try:
        # forked: the workers inherit the store and the suite filter (a closure) instead of pickling them
        parts = forked_map([partial(_read_group, store, keep, run_dirs, g) for g in tasks], jobs)
    finally:
        _TRUTHS.clear()  # filled here when a single task ran in this process
    by_index: dict[int, list[_RunRead]] = {}
    truths: dict[Any, Any] = {}
    for reads, new in parts:
        by_index.update(reads)
        for k, v in new.items():
            truths.setdefault(k, v)
    return [([r for i in range(len(run_dirs)) for r in by_index[i]], truths)]


def collect(store: Store, keep: Keep | None = None, jobs: int = 1) -> Collected:
    """One pass over the stored runs: metrics of every run, statuses, NEES series and truths.

    Parameters
    ----------
    store : Store
        The results folder.
    keep : callable, optional
        ``keep(dataset, filter)`` selects the cells to report; None keeps all.
    jobs : int
        Processes that read the runs and compute their metrics (forked; 1: this process). The result does
        not depend on it.
    """
    run_dirs = list(store.iter_runs())
    if jobs > 1 and len(run_dirs) > 1:
        parts = _read_parallel(store, keep, run_dirs, jobs)
    else:
        parts = [_read_runs(store, keep, run_dirs)]
    rows: list[tuple[str, str, int, str, float]] = []
    out = Collected(metrics=pd.DataFrame(), store=store)
    nees: dict[tuple[str, str], list[tuple[np.ndarray, np.ndarray]]] = defaultdict(list)
    read_truths: dict[tuple[str, int], TruthRecord] = {}
    for reads, truths in parts:
        for key, truth in truths.items():
            read_truths.setdefault(key, truth)
        for status, rel, payload in reads:
            if status == "broken":
                out.broken.append((rel, payload))
                continue
            meta, info, run_rows, key, ne, run_dir, hs = payload
            out.metas.append(meta)
            out.runs.append(info)
            rows.extend(run_rows)
            if key is not None:
                truth = out.truths.setdefault(key, read_truths[key])
                if ne is not None:
                    nees[(info.dataset, info.filter)].append((truth.ground_truth.t, ne))
                out.ok_dirs[(info.dataset, info.filter, info.seed)] = run_dir
                if hs is not None:
                    out.health.setdefault((info.dataset, info.filter), []).append(hs)
    out.nees = dict(nees)
    rows.extend(bound_rows(store, out, jobs))
    out.metrics = frame(rows)
    for name in sorted({r.dataset for r in out.runs}):
        out.datasets[name] = describe_dataset(name)
    recorded: dict[str, FilterTraits] = {}
    for meta in out.metas:
        traits = FilterTraits.from_record(meta.get("filter_traits"))
        if traits is not None:
            recorded.setdefault(str(meta["filter"]), traits)
    for name in sorted({r.filter for r in out.runs} | set(BOUND_ROWS)):
        out.filters[name] = describe_filter(name, recorded.get(name))
    return out


def bound_rows(store: Store, col: Collected, jobs: int = 1) -> list[tuple[str, str, int, str, float]]:
    """The metrics rows of the stored bounds of every realisation with an ok run (:func:`pcrb_summary`), read by
    ``jobs`` forked processes.

    A realisation without a bound (recorded data, a kidnap, not computed yet) adds none; an unreadable one
    is logged and listed with the broken records.
    """
    from locbench.report.forked import forked_map

    todo = [
        (dataset, seed, truth.waypoints.t if truth.waypoints is not None else np.zeros(0))
        for (dataset, seed), truth in sorted(col.truths.items())
    ]
    parts = max(1, min(jobs, len(todo)))
    done = forked_map([partial(_bounds_of, store, todo[i::parts]) for i in range(parts)], jobs)
    found = sorted((item for part in done for item in part), key=lambda x: (x[0], x[1]))
    rows: list[tuple[str, str, int, str, float]] = []
    for dataset, seed, part_rows, problem in found:
        if problem:
            log.warning("skipping unreadable bound of %s seed %d: %s", dataset, seed, problem)
            col.broken.append((f"{dataset} seed {seed} (bound)", problem))
        rows += part_rows
    return rows


def _bounds_of(
    store: Store, todo: Sequence[tuple[str, int, np.ndarray]]
) -> list[tuple[str, int, list[tuple[str, str, int, str, float]], str]]:
    """Each realisation's bound rows, or why its bound is unreadable: (dataset, seed, rows, problem)."""
    out: list[tuple[str, int, list[tuple[str, str, int, str, float]], str]] = []
    for dataset, seed, wp_t in todo:
        try:
            bound = store.read_bound(dataset, seed)
        except Exception as exc:
            out.append((dataset, seed, [], f"{type(exc).__name__}: {exc}"))
            continue
        if bound is None:
            continue
        rows: list[tuple[str, str, int, str, float]] = []
        for name, cov in sorted(bound.covs.items()):
            values = pcrb_summary(bound.t, cov, wp_t)
            rows.extend((dataset, name, seed, k, float(v)) for k, v in values.items())
        out.append((dataset, seed, rows, ""))
    return out


class _NoTruth:
    """Stands in for the truth of a run that is not ok (its metrics never look at it)."""


_NO_TRUTH: Any = _NoTruth()


def frame(rows: Sequence[tuple[str, str, int, str, float]]) -> pd.DataFrame:
    """The tidy metrics frame, typed and sorted by dataset, filter, seed and metric."""
    # by column: a frame from a dict of lists is made several times faster than from a list of tuples
    columns = list(zip(*rows, strict=True)) if len(rows) else [()] * len(COLUMNS)
    return tidied(pd.DataFrame({c: list(v) for c, v in zip(COLUMNS, columns, strict=True)}, columns=list(COLUMNS)))


def tidied(df: pd.DataFrame) -> pd.DataFrame:
    """``df``'s :data:`COLUMNS`, typed and sorted as :func:`frame` makes them (stable: equal keys keep their order)."""
    df = df[list(COLUMNS)].astype(
        {"dataset": "str", "filter": "str", "seed": "int64", "metric": "str", "value": "float64"}
    )
    return df.sort_values(list(COLUMNS[:4]), kind="stable").reset_index(drop=True)


def _relative(path: Path, root: Path) -> str:
    try:
        return path.relative_to(root).as_posix()
    except ValueError:
        return path.as_posix()


def collect_metrics(store: Store) -> pd.DataFrame:
    """The tidy metrics of every stored run.

    Returns
    -------
    DataFrame
        Columns ``dataset, filter, seed, metric, value`` (names with their parameters), sorted by
        dataset, filter, seed and metric. An ok run gives :func:`locbench.evaluate.metrics.run_metrics`; a failed
        or diverged run ``failed`` = 1; a skipped run nothing. A run folder that cannot be read (or whose
        ground truth is missing) is logged and left out.
    """
    return collect(store).metrics


def write_if_changed(path: Path, data: bytes) -> None:
    """Leave an identical file untouched (its modification time too)."""
    if path.is_file() and path.read_bytes() == data:
        return
    path.write_bytes(data)


def write_metrics_csv(df: pd.DataFrame, path: str | Path) -> Path:
    """Write the tidy metrics as CSV, sorted and with stable float formatting (identical bytes on rerun).

    Values use ``%.10g``; infinities are written ``inf``, NaN ``nan``; line ends are ``\\n``.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_if_changed(path, metrics_csv(df))
    return path


def metrics_parquet(df: pd.DataFrame) -> bytes:
    """The bytes of ``metrics.parquet``: the tidy metrics (:data:`COLUMNS`, sorted as :func:`frame` sorts them),
    each value rounded to 10 significant digits as ``metrics.csv`` writes it, zstd-compressed, dictionary-encoded
    names; no pandas metadata, so the bytes depend on the rows and the pyarrow version only.

    Read it with ``pandas.read_parquet(path)`` (:func:`read_metrics`).
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    tidy = tidied(df)
    values = np.array([float(FLOAT_FORMAT % v) for v in tidy["value"].to_numpy(dtype=float)], dtype=float)
    table = pa.table(
        {
            "dataset": pa.array(tidy["dataset"].tolist(), pa.string()),
            "filter": pa.array(tidy["filter"].tolist(), pa.string()),
            "seed": pa.array(tidy["seed"].to_numpy(dtype=np.int64), pa.int64()),
            "metric": pa.array(tidy["metric"].tolist(), pa.string()),
            "value": pa.array(values, pa.float64()),
        }
    )
    buf = pa.BufferOutputStream()
    pq.write_table(
        table,
        buf,
        compression="zstd",
        compression_level=9,
        use_dictionary=["dataset", "filter", "metric"],
        write_statistics=False,
        store_schema=False,
    )
    return buf.getvalue().to_pybytes()


def read_metrics(path: str | Path) -> pd.DataFrame:
    """The tidy metrics of a report's ``metrics.parquet`` (or of an older report's ``metrics.csv``), typed as
    :func:`frame` types them."""
    path = Path(path)
    df = pd.read_parquet(path) if path.suffix == ".parquet" else pd.read_csv(path)
    return df.astype({"dataset": "str", "filter": "str", "seed": "int64", "metric": "str", "value": "float64"})


def metrics_csv(df: pd.DataFrame) -> bytes:
    """The bytes of ``metrics.csv`` (:func:`write_metrics_csv`)."""
    tidy = tidied(df)
    buf = io.StringIO()
    tidy.to_csv(buf, index=False, float_format=FLOAT_FORMAT, na_rep="nan", lineterminator="\n")
    return buf.getvalue().encode()
