"""``locbench verify``: re-run a random sample of stored runs and check they come out bit for bit the same.

A benchmark whose non-timing numbers cannot be regenerated exactly is not a benchmark (MLPerf fixes its runs in
advance; Henderson et al. 2018 show results flip with the seed set). This re-runs a sample of the stored runs
(by default 2 %, at least one per filter configuration) through the same code path as a sweep
(:func:`locbench.runner.execute_task`) and compares every stored array except the call times (``step_ns``):
the times, means, covariances, event kinds, diagnostics and extra arrays, byte for byte, and the status.
The stored runs are read through :meth:`locbench.store.Store.read_run`; nothing in the store is changed except
the record of the result, ``<results>/verify.json``, which the report's provenance shows.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import logging
import math
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from locbench import provenance
from locbench.store import RunRecord, StaleRecord, Store

log = logging.getLogger(__name__)

#: Default share of the stored runs to re-run.
DEFAULT_FRACTION = 0.02
#: The record of the last verification, in the results folder.
RECORD_NAME = "verify.json"
#: Arrays that are allowed to differ: the per-call compute times.
TIMING_ARRAYS = frozenset({"step_ns"})


@dataclass(frozen=True)
class RunId:
    """A stored run: dataset name, filter name, seed, and its stored run key."""

    dataset: str
    filter: str
    seed: int
    run_key: str

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

    @property
    def passed(self) -> bool:
        return not self.differ and bool(self.checked)


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
            out.append(RunId(str(meta["dataset"]), str(meta["filter"]), int(meta["seed"]), str(meta["run_key"])))
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
            log.warning("%s: unreadable run record left out of the sample (%s)", d, exc)
    return sorted(out, key=lambda r: (r.filter, r.dataset, r.seed))


def sample(runs: Sequence[RunId], fraction: float, seed: int) -> list[RunId]:
    """A random sample: ceil(fraction x runs) runs, plus one of each filter configuration the draw missed.

    Deterministic for a seed (``numpy.random.default_rng(seed)``), so a failure can be re-run exactly.
    """
    if not 0.0 < fraction <= 1.0:
        raise ValueError(f"--fraction must be in (0, 1], got {fraction}")
    if not runs:
        return []
    rng = np.random.default_rng(seed)
    k = min(len(runs), max(1, math.ceil(fraction * len(runs))))
    picked = {int(i) for i in rng.choice(len(runs), size=k, replace=False)}
    by_filter: dict[str, list[int]] = {}
    for i, r in enumerate(runs):
        by_filter.setdefault(r.filter, []).append(i)
    for name in sorted(by_filter):
        idx = by_filter[name]
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


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def verify(store: Store, fraction: float = DEFAULT_FRACTION, seed: int = 0, jobs: int = 1) -> VerifyResult:
    """Re-run a sample of the stored runs (:func:`sample`) and compare them with the stored ones (:func:`compare`).

    A run whose key no longer matches what the current code would store (a filter's or dataset's version was
    bumped) differs by definition: the store is stale for it. The re-runs go through the sweep's local executor
    (``jobs`` worker processes); nothing is written to the store. A re-run that fails to return (its worker died)
    differs too.
    """
    from locbench import executors
    from locbench.registry import DATASETS, FILTERS, resolve_dataset, resolve_filter
    from locbench.runner import Job, Task, TaskResult, run_key

    runs = stored_runs(store)
    result = VerifyResult(fraction, seed, len(runs), store_digest=store_digest(r.run_key for r in runs))
    chosen = sample(runs, fraction, seed)
    groups: dict[tuple[str, int], list[RunId]] = {}
    for r in chosen:
        groups.setdefault((r.dataset, r.seed), []).append(r)
    tasks: list[Task] = []
    stored_name: dict[tuple[str, int], str] = {}  # the task's canonical dataset name -> the stored runs' name
    for (dataset, s), members in sorted(groups.items()):
        dr = resolve_dataset(dataset)
        jobs_of_task: list[Job] = []
        for r in members:
            fr = resolve_filter(r.filter)
            key = run_key(fr, dr, s)
            if key != r.run_key:
                result.checked.append(r)
                result.differ.append((r, "stale: the run key changed (a version or parameter of the code)"))
                continue
            jobs_of_task.append(Job(fr, FILTERS.load(fr.id), key))
        if jobs_of_task:
            tasks.append(Task(dr, DATASETS.load(dr.id), s, tuple(jobs_of_task)))
            stored_name[(dr.name, s)] = dataset
    fresh: dict[tuple[str, int, str], RunRecord] = {}
    lost: dict[tuple[str, int], str] = {}

    def handle(task: Task, out: TaskResult) -> None:
        for rec in out.runs:
            fresh[(stored_name[(task.dataset.name, task.seed)], task.seed, rec.meta["filter"])] = rec

    def on_lost(task: Task, why: str) -> None:
        lost[(stored_name[(task.dataset.name, task.seed)], task.seed)] = why

    log.info("re-running %d stored runs in %d tasks", sum(len(t.jobs) for t in tasks), len(tasks))
    executors.run_local(tasks, handle, on_lost, jobs=jobs)
    for (dataset, s), members in sorted(groups.items()):
        for r in members:
            if any(c is r for c in result.checked):
                continue
            rec = fresh.get((dataset, s, r.filter))
            result.checked.append(r)
            if rec is None:
                result.differ.append((r, f"not re-run: {lost.get((dataset, s), 'no result came back')}"))
                continue
            try:
                stored = store.read_run(store.run_dir(r.dataset, r.filter, r.seed))
            except StaleRecord as exc:  # altered since it was written: its checksum or shape contract fails
                result.differ.append((r, f"stale: {exc}"))
                continue
            diff = compare(stored, rec)
            if diff:
                result.differ.append((r, ", ".join(diff)))
    return result


def write_record(store: Store, result: VerifyResult) -> Path:
    """Write ``<results>/verify.json`` (atomically: a temporary file renamed into place)."""
    git = provenance.git_state()
    record: dict[str, Any] = {
        "passed": result.passed,
        "finished_utc": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "fraction": result.fraction,
        "seed": result.seed,
        "stored_runs": result.stored,
        "checked": len(result.checked),
        "differ": [f"{r.label()}: {why}" for r, why in result.differ],
        "store_digest": result.store_digest,
        "git_commit": git["commit"],
    }
    path = store.root / RECORD_NAME
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{RECORD_NAME}.tmp-{os.getpid()}")
    tmp.write_text(json.dumps(record, indent=2) + "\n", encoding="utf-8")
    os.replace(tmp, path)
    return path


def read_record(root: Path) -> dict[str, Any] | None:
    """The last verification's record in a results folder, or None (none yet, or unreadable)."""
    try:
        data = json.loads((Path(root) / RECORD_NAME).read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError, UnicodeDecodeError):
        return None
    return data if isinstance(data, dict) else None


def record_text(record: dict[str, Any] | None, current_digest: str) -> str:
    """The provenance line: when verification last ran on this store and whether it passed."""
    if record is None:
        return "verify: `locbench verify` has not been run on this store"
    state = "passed" if record.get("passed") else "FAILED"
    text = (
        f"verify: {state} on {record.get('finished_utc', '?')}, {record.get('checked', 0)} of "
        f"{record.get('stored_runs', 0)} stored runs re-run (fraction {record.get('fraction')}, seed "
        f"{record.get('seed')}), every array except the call times bit-identical"
        if record.get("passed")
        else f"verify: {state} on {record.get('finished_utc', '?')}: {len(record.get('differ', []))} of "
        f"{record.get('checked', 0)} re-run runs differ"
    )
    if record.get("store_digest") != current_digest:
        text += " (the stored runs have changed since)"
    return text
