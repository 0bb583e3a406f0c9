"""``locbench verify``: re-derive a random sample of stored runs and check every stored artefact comes out the same.

A benchmark whose non-timing numbers cannot be regenerated exactly is not a benchmark (MLPerf fixes its runs in
advance; Henderson et al. 2018 show results flip with the seed set). This re-runs a sample of the stored runs
(by default 2 %, at least one per filter configuration) through the same code path as a sweep
(:func:`locbench.run.execute.execute_task`) and compares, byte for byte (our code against itself on one machine):

- each sampled run's arrays except the call times (``step_ns``): the times, means, covariances, event kinds,
  diagnostics and extra arrays, and its status;
- its identity: the folder it lies in must be the one its record names, and the record's filter and dataset
  specs, seed, run key, versions, row count and divergence time must be what the re-run records;
- the truth of its realisation (``_truth/seed-NNNN.npz``): ground truth, waypoints, kidnaps, map, duration and
  the record's dataset spec and seed, rebuilt from the spec;
- its derived values (``derived.npz``: metrics, NEES and health series), where they are stored for the current
  code: recomputed by the re-run's worker, they must be the stored ones;
- the realisation's posterior Cramer-Rao bound, recomputed, where the dataset has one;
- of a run imported from another system's output (``external[name=...]``, :mod:`locbench.run.import_runs`), which
  cannot be re-run: the sha256 of each file it was imported from, read again from its path.

The stored files are read through :class:`locbench.run.store.Store`, with their checksums; nothing in the store is
changed except the record of the result, ``<results>/verify.json``, which the report's provenance shows.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import logging
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from locbench.core.errors import ConfigError, LocbenchError
from locbench.evaluate.records import BoundRecord, RunRecord, TruthRecord
from locbench.run import provenance
from locbench.run.store import StaleRecord, Store, bound_arrays, truth_arrays

if TYPE_CHECKING:
    from locbench.evaluate.derived import Derived
    from locbench.run.plan import Task

log = logging.getLogger(__name__)

#: Default share of the stored runs to re-run.
DEFAULT_FRACTION = 0.02
#: The record of the last verification, in the results folder.
RECORD_NAME = "verify.json"
#: Arrays that are allowed to differ: the per-call compute times.
TIMING_ARRAYS = frozenset({"step_ns"})
#: The fields of a run's record that the re-run must record alike: what the run is, and what it came to.
RUN_FIELDS = (
    "filter",
    "filter_id",
    "filter_config",
    "filter_version",
    "dataset",
    "dataset_id",
    "dataset_params",
    "dataset_version",
    "seed",
    "run_key",
    "n_rows",
    "diverged_t",
    "dataset_duration_s",
)
#: The fields of a truth's record the rebuilt truth must have alike.
TRUTH_FIELDS = ("dataset", "seed", "dataset_id", "dataset_params", "dataset_version", "truth_label", "metadata")
#: Arrays of the truth file that hold the waypoints (reported as such).
WAYPOINT_ARRAYS = frozenset({"wp_t", "wp_xy", "has_waypoints"})


@dataclass(frozen=True)
class RunId:
    """A stored run: dataset name, filter name, seed, and its stored run key."""

    dataset: str
    filter: str
    seed: int
    run_key: str
    #: The folder the run was found in ("": the folder its names give, :meth:`Store.run_dir`).
    folder: str = ""

    def label(self) -> str:
        return f"{self.filter} on {self.dataset} seed {self.seed}"


@dataclass
class VerifyResult:
    """What a verification checked and which runs differ (with the arrays that do)."""

    fraction: float
    seed: int
    stored: int
    checked: list[RunId] = field(default_factory=list)
    differ: list[tuple[RunId, str]] = field(default_factory=list)
    store_digest: str = ""
    #: The realisations whose truth and bound were checked, and those that differ: (label, what differs).
    realisations: int = 0
    artefacts: list[tuple[str, str]] = field(default_factory=list)
    #: Committed tuning trials re-run on their train data (:func:`locbench.run.tuning.verify_trials`).
    trials: list[Any] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return not self.differ and not self.artefacts and bool(self.checked) and all(t.passed for t in self.trials)

    def problems(self) -> list[str]:
        """One line per difference: each run's, then each realisation's truth and bound, then each re-run trial
        outside its tolerance."""
        return (
            [f"{r.label()}: {why}" for r, why in self.differ]
            + [f"{w}: {why}" for w, why in self.artefacts]
            + [
                f"trial {t.number} of {t.filter} on {t.world}{f' ({t.fold})' if t.fold else ''}: objective "
                f"{t.fresh!r} re-run, {t.stored!r} in the journal (relative difference {t.rel_diff:.3g})"
                for t in self.trials
                if not t.passed
            ]
        )


def store_digest(run_keys: Iterable[str]) -> str:
    """A short digest of the stored runs' keys: the report tells whether the store changed since a verification."""
    h = hashlib.sha256("\n".join(sorted(run_keys)).encode())
    return h.hexdigest()[:16]


def stored_runs(store: Store) -> list[RunId]:
    """Every stored run that was run (status other than skipped), from its ``meta.json``, sorted."""
    out: list[RunId] = []
    for d in store.iter_runs():
        try:
            meta = json.loads((d / "meta.json").read_text(encoding="utf-8"))
            if meta.get("status") == "skipped" or "run_key" not in meta:
                continue
            ident = (str(meta["dataset"]), str(meta["filter"]), int(meta["seed"]), str(meta["run_key"]))
            out.append(RunId(*ident, folder=str(d)))
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
            log.warning("%s: unreadable run record left out of the sample (%s)", d, exc)
    return sorted(out, key=lambda r: (r.filter, r.dataset, r.seed, r.folder))


def sample(runs: Sequence[RunId], fraction: float, seed: int, groups: Mapping[str, str] | None = None) -> list[RunId]:
    """A random sample: ceil(fraction x runs) runs, plus one of each filter configuration the draw missed.

    ``groups`` names the group a configuration counts in for that minimum (default: its own): the tuned
    configurations of one cross-validated study, one per fold and each run on its fold's test unit only, are one
    group (:func:`locbench.run.tuning.study_groups`), so the minimum takes one of them, not every fold's run.
    Deterministic for a seed (``numpy.random.default_rng(seed)``), so a failure can be re-run exactly.
    """
    if not 0.0 < fraction <= 1.0:
        raise ValueError(f"--fraction must be in (0, 1], got {fraction}")
    if not runs:
        return []
    rng = np.random.default_rng(seed)
    k = min(len(runs), max(1, math.ceil(fraction * len(runs))))
    picked = {int(i) for i in rng.choice(len(runs), size=k, replace=False)}
    by_group: dict[str, list[int]] = {}
    for i, r in enumerate(runs):
        by_group.setdefault(groups.get(r.filter, r.filter) if groups else r.filter, []).append(i)
    for name in sorted(by_group):
        idx = by_group[name]
        if not picked.intersection(idx):
            picked.add(idx[int(rng.integers(len(idx)))])
    return [runs[i] for i in sorted(picked)]


def compare(stored: RunRecord, fresh: RunRecord) -> list[str]:
    """Names of the arrays (and ``status``) that differ between a stored run and its re-run; call times aside.

    Arrays are equal when dtype, shape and bytes are (so NaN payloads and signed zeros count).
    """
    out: list[str] = []
    if stored.status != fresh.status:
        out.append(f"status ({stored.status} stored, {fresh.status} now)")
    for name in ("t", "mean", "cov", "kind"):
        if not _same(getattr(stored, name), getattr(fresh, name)):
            out.append(name)
    for label, a, b in (("diag", stored.diagnostics, fresh.diagnostics), ("extra", stored.extra, fresh.extra)):
        for key in sorted(set(a) | set(b)):
            if key not in a or key not in b or not _same(a[key], b[key]):
                out.append(f"{label}_{key}")
    return out


def compare_derived(stored: Derived, fresh: Derived) -> list[str]:
    """What differs between a run's stored derived values and the ones of its re-run (bit for bit), the metrics of
    the call times aside (group ``runtime``: they come from the call times, which differ between runs)."""
    from locbench.evaluate.metrics import METRICS

    timing = [m for m in METRICS.values() if m.group == "runtime"]
    out = [
        f"derived {k}"
        for k in sorted(set(stored.values) | set(fresh.values))
        if not any(m.matches(k) for m in timing)
        and (
            (k in stored.values) != (k in fresh.values)
            or not _same(np.float64(stored.values.get(k, np.nan)), np.float64(fresh.values.get(k, np.nan)))
        )
    ]
    if (stored.nees is None) != (fresh.nees is None) or (
        stored.nees is not None and fresh.nees is not None and not _same(stored.nees, fresh.nees)
    ):
        out.append("derived nees")
    a, b = stored.health, fresh.health
    if (a is None) != (b is None) or (
        a is not None
        and b is not None
        and (
            not (_same(a.t, b.t) and _same(a.error_m, b.error_m) and _differing(a.signals, b.signals) == [])
            or not _same(np.float64(a.kidnap_t), np.float64(b.kidnap_t))
        )
    ):
        out.append("derived health")
    return out


def _differences(store: Store, r: RunId, stored: RunRecord, fresh: RunRecord, derived: Derived | None) -> list[str]:
    """What differs between a stored run and its re-run: arrays, record fields, and the stored derived values
    (where they are stored for the current code) against the ones the re-run's worker computed."""
    diff = compare(stored, fresh) + compare_meta(stored.meta, fresh.meta, RUN_FIELDS)
    folder = Path(r.folder) if r.folder else store.run_dir(r.dataset, r.filter, r.seed)
    kept = store.read_derived(folder) if not diff else None
    if kept is not None:
        diff += (
            ["derived values (not computed by the re-run)"] if derived is None else compare_derived(kept[1], derived)
        )
    return diff


def _same(a: npt.ArrayLike, b: npt.ArrayLike) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def _plain(value: Any) -> Any:
    """A record's value as JSON holds it (what the store writes), so a fresh value compares with a stored one."""
    return json.loads(json.dumps(value, default=str))


def compare_meta(stored: dict[str, Any], fresh: dict[str, Any], fields: Sequence[str]) -> list[str]:
    """The ``fields`` whose JSON values differ between a stored record and its re-derived one."""
    return [
        f"record {k} ({_plain(stored.get(k))!r} stored, {_plain(fresh.get(k))!r} now)"
        for k in fields
        if _plain(stored.get(k)) != _plain(fresh.get(k))
    ]


def _differing(stored: dict[str, np.ndarray], fresh: dict[str, np.ndarray]) -> list[str]:
    return [
        k
        for k in sorted(set(stored) | set(fresh))
        if k not in stored or k not in fresh or not _same(stored[k], fresh[k])
    ]


def compare_truth(store: Store, dataset: str, seed: int, fresh: TruthRecord) -> list[tuple[str, str]]:
    """What differs between a realisation's stored truth and its rebuilt one: (what, which arrays or fields)."""
    where = f"{dataset} seed {seed}"
    try:
        meta, arrays = store.truth_files(dataset, seed)
    except StaleRecord as exc:
        return [(f"{where} truth", f"stale: {exc}")]
    keys = _differing(arrays, truth_arrays(fresh))
    out = []
    truth = [k for k in keys if k not in WAYPOINT_ARRAYS] + compare_meta(
        meta, fresh.meta | {"dataset": dataset, "seed": seed, "truth_label": fresh.truth_label}, TRUTH_FIELDS
    )
    if truth:
        out.append((f"{where} truth", ", ".join(truth)))
    waypoints = [k for k in keys if k in WAYPOINT_ARRAYS]
    if waypoints:
        out.append((f"{where} waypoints", ", ".join(waypoints)))
    return out


def compare_bound(
    store: Store, dataset: str, seed: int, key: str | None, fresh: BoundRecord | None
) -> list[tuple[str, str]]:
    """What differs between a realisation's stored bound and the recomputed one (``key``: the bound key the current
    code gives, None when the dataset has no bound)."""
    where = f"{dataset} seed {seed} bound"
    try:
        stored = store.bound_files(dataset, seed)
    except StaleRecord as exc:
        return [(where, f"stale: {exc}")]
    if stored is None:
        return [] if key is None else [(where, "missing: the dataset has one; 'locbench run' computes it")]
    meta, arrays = stored
    if key is None:
        return [(where, "stored, but the dataset has none")]
    if meta.get("bound_key") != key:
        return [(where, "stale: its key changed (a version or parameter of the code)")]
    if fresh is None:
        return [(where, "not recomputed: its computation failed (see the log)")]
    why = _differing(arrays, bound_arrays(fresh))
    why += compare_meta(
        meta, {"dataset": dataset, "seed": seed, "rows": sorted(fresh.covs)}, ("dataset", "seed", "rows")
    )
    return [(where, ", ".join(why))] if why else []


@dataclass
class _Plan:
    """The re-runs of a verification: the tasks, the stored records they are compared with, each realisation's
    bound key and the stored runs' dataset name under each task's canonical one."""

    tasks: list[Task] = field(default_factory=list)
    stored_recs: dict[RunId, RunRecord] = field(default_factory=dict)
    bound_keys: dict[tuple[str, int], str | None] = field(default_factory=dict)
    stored_name: dict[tuple[str, int], str] = field(default_factory=dict)


def _plan(store: Store, groups: dict[tuple[str, int], list[RunId]], result: VerifyResult) -> _Plan:
    """One task per sampled realisation with the jobs still current; a run that cannot be re-run (stale, another
    run's folder, an unknown spec) is recorded in ``result`` as differing instead."""
    from locbench.filters.base import SCORE_SAMPLE_SIZE
    from locbench.run.import_runs import EXTERNAL_ID, digest_problems
    from locbench.run.plan import Job, Task, bound_key, parse_dataset, parse_filter, run_key

    plan = _Plan()
    stored_recs, tasks, bound_keys, stored_name = plan.stored_recs, plan.tasks, plan.bound_keys, plan.stored_name
    for (dataset, s), members in sorted(groups.items()):
        jobs_of_task: list[Job] = []
        # the score sample size the stored runs were drawn with (a run setting); one per re-run task
        task_sample: int | None = None
        try:
            dr = parse_dataset(dataset)
        except LocbenchError as exc:
            for r in members:
                result.checked.append(r)
                result.differ.append((r, f"cannot be re-run: {exc}"))
            continue
        for r in members:
            result.checked.append(r)
            try:
                # its checksums, its shape contract and the folder it lies in (Store.read_run)
                stored_recs[r] = store.read_run(Path(r.folder) if r.folder else store.run_dir(r.dataset, r.filter, s))
                if stored_recs[r].meta.get("filter_id") == EXTERNAL_ID:
                    # an imported run is not computed: its files must be the ones it was imported from
                    problems = digest_problems(stored_recs[r].meta)
                    if problems:
                        result.differ.append((r, "; ".join(problems)))
                    continue
                fr = parse_filter(r.filter)
            except StaleRecord as exc:  # altered since it was written, or another run's folder
                result.differ.append((r, f"stale: {exc}"))
                continue
            except LocbenchError as exc:
                result.differ.append((r, f"cannot be re-run: {exc}"))
                continue
            size = int(stored_recs[r].meta.get("score_sample", SCORE_SAMPLE_SIZE))
            key = run_key(fr, dr, s, size)
            if "score_sample" in stored_recs[r].meta and task_sample not in (None, size):
                why = f"cannot be re-run: score sample {size} beside {task_sample} on one realisation"
                result.differ.append((r, why))
                continue
            if key != r.run_key:
                result.differ.append((r, "stale: the run key changed (a version or parameter of the code)"))
                continue
            if "score_sample" in stored_recs[r].meta:
                task_sample = size
            jobs_of_task.append(Job(fr, key))
        if jobs_of_task:
            bkey = bound_key(dr, s)
            bound_keys[(dataset, s)] = bkey
            stored_bound = store.bound_files(dataset, s) if bkey is not None else None
            # the bound is recomputed when one is stored under the current key (else it differs without it)
            wanted = bkey if stored_bound is not None and stored_bound[0].get("bound_key") == bkey else None
            tasks.append(
                Task(dr, s, tuple(jobs_of_task), bound_key=wanted, score_sample=task_sample or SCORE_SAMPLE_SIZE)
            )
            stored_name[(dr.name, s)] = dataset
    return plan


def verify(store: Store, fraction: float = DEFAULT_FRACTION, seed: int = 0, jobs: int = 1) -> VerifyResult:
    """Re-run a sample of the stored runs (:func:`sample`) and compare everything stored of them (module docstring).

    A run whose key no longer matches what the current code would store (a filter's or dataset's version was
    bumped) differs by definition: the store is stale for it. So does a run whose folder is not the one its
    record names (a run folder copied over another). The re-runs go through the sweep's local executor (``jobs``
    worker processes); nothing is written to the store. A re-run that fails to return (its worker died) differs
    too.

    Raises
    ------
    ConfigError
        The store holds no run to verify.
    """
    from locbench.run import executors
    from locbench.run.execute import TaskResult
    from locbench.run.import_runs import EXTERNAL_ID

    runs = stored_runs(store)
    if not runs:
        raise ConfigError(
            f"{store.runs}: no stored run to verify (none, or every one skipped); run 'locbench run' first"
        )
    result = VerifyResult(fraction, seed, len(runs), store_digest=store_digest(r.run_key for r in runs))
    from locbench.run.tuning import study_groups

    chosen = sample(runs, fraction, seed, study_groups(store.root))
    groups: dict[tuple[str, int], list[RunId]] = {}
    for r in chosen:
        groups.setdefault((r.dataset, r.seed), []).append(r)
    plan = _plan(store, groups, result)
    stored_recs, tasks, bound_keys, stored_name = plan.stored_recs, plan.tasks, plan.bound_keys, plan.stored_name
    fresh: dict[tuple[str, int, str], RunRecord] = {}
    fresh_derived: dict[tuple[str, int, str], Derived] = {}
    truths: dict[tuple[str, int], TruthRecord] = {}
    bounds: dict[tuple[str, int], BoundRecord] = {}
    lost: dict[tuple[str, int], str] = {}

    def handle(task: Task, out: TaskResult) -> None:
        where = (stored_name[(task.dataset.name, task.seed)], task.seed)
        derived = out.derived or [None] * len(out.runs)
        for job, rec, values in zip(task.jobs, out.runs, derived, strict=True):
            fresh[(*where, job.filter.name)] = rec
            if values is not None:
                fresh_derived[(*where, job.filter.name)] = values[0]
        if out.truth is not None:
            truths[where] = out.truth
        if out.bound is not None:
            bounds[where] = out.bound

    def on_lost(task: Task, why: str) -> None:
        lost[(stored_name[(task.dataset.name, task.seed)], task.seed)] = why

    log.info("re-running %d stored runs in %d tasks", sum(len(t.jobs) for t in tasks), len(tasks))
    executors.run_local(tasks, handle, on_lost, jobs=jobs)
    for (dataset, s), members in sorted(groups.items()):
        for r in members:
            if any(d is r for d, _ in result.differ):
                continue
            if r in stored_recs and stored_recs[r].meta.get("filter_id") == EXTERNAL_ID:
                continue  # imported: checked by its files' digests (_plan)
            rec = fresh.get((dataset, s, r.filter))
            if rec is None:
                result.differ.append((r, f"not re-run: {lost.get((dataset, s), 'no result came back')}"))
                continue
            diff = _differences(store, r, stored_recs[r], rec, fresh_derived.get((dataset, s, r.filter)))
            if diff:
                result.differ.append((r, ", ".join(diff)))
        if (dataset, s) in truths:
            result.realisations += 1
            result.artefacts += compare_truth(store, dataset, s, truths[(dataset, s)])
            result.artefacts += compare_bound(store, dataset, s, bound_keys[(dataset, s)], bounds.get((dataset, s)))
    return result


def write_record(store: Store, result: VerifyResult) -> Path:
    """Write ``<results>/verify.json`` (atomically: a temporary file renamed into place); a ``verify.json`` that
    is not such a record (:data:`RECORD_FIELDS`) is not overwritten (:class:`ConfigError`)."""
    git = provenance.git_state()
    record: dict[str, Any] = {
        "passed": result.passed,
        "finished_utc": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "fraction": result.fraction,
        "seed": result.seed,
        "stored_runs": result.stored,
        "checked": len(result.checked),
        "differ": result.problems(),
        "realisations": result.realisations,
        "store_digest": result.store_digest,
        "git_commit": git["commit"],
        "trials": [
            {
                "filter": t.filter,
                "world": t.world,
                "fold": t.fold,
                "trial": t.number,
                "spec": t.spec,
                "journal": t.stored,
                "re_run": t.fresh,
                "rel_diff": t.rel_diff,
            }
            for t in result.trials
        ],
    }
    path = store.root / RECORD_NAME
    if os.path.lexists(path) and not _is_record(path):
        raise ConfigError(f"{path}: not a record 'locbench verify' wrote; move it away to record a verification here")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{RECORD_NAME}.tmp-{os.getpid()}")
    tmp.write_text(json.dumps(record, indent=2) + "\n", encoding="utf-8")
    os.replace(tmp, path)
    return path


#: The fields every record :func:`write_record` writes has: a file without them is someone else's.
RECORD_FIELDS = frozenset({"passed", "finished_utc", "fraction", "seed", "stored_runs", "checked", "store_digest"})


def _is_record(path: Path) -> bool:
    """Whether ``path`` is a record this module wrote (a regular file, a JSON object with its fields)."""
    if path.is_symlink() or not path.is_file():
        return False
    data = read_record(path.parent)
    return data is not None and data.keys() >= RECORD_FIELDS


def read_record(root: Path) -> dict[str, Any] | None:
    """The last verification's record in a results folder, or None (none yet, or unreadable)."""
    try:
        data = json.loads((Path(root) / RECORD_NAME).read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError, UnicodeDecodeError):
        return None
    return data if isinstance(data, dict) else None


def _trial_rtol() -> float:
    from locbench.run.tuning import TRIAL_RTOL

    return TRIAL_RTOL


def record_text(record: dict[str, Any] | None, current_digest: str) -> str:
    """The provenance line: when verification last ran on this store and whether it passed."""
    if record is None:
        return "verify: `locbench verify` has not been run on this store"
    state = "passed" if record.get("passed") else "FAILED"
    text = (
        f"verify: {state} on {record.get('finished_utc', '?')}, {record.get('checked', 0)} of "
        f"{record.get('stored_runs', 0)} stored runs re-run (fraction {record.get('fraction')}, seed "
        f"{record.get('seed')}), every array except the call times bit-identical"
        + (
            f"; {len(record['trials'])} tuning trial(s) re-run on their train data, objectives within "
            f"{_trial_rtol():g} relative of the journals' (largest {max(t['rel_diff'] for t in record['trials']):.2g})"
            if record.get("trials")
            else ""
        )
        if record.get("passed")
        else f"verify: {state} on {record.get('finished_utc', '?')}: {len(record.get('differ', []))} difference(s) "
        f"among {record.get('checked', 0)} re-run runs and their truth and bounds"
    )
    if record.get("store_digest") != current_digest:
        text += " (the stored runs have changed since)"
    return text
