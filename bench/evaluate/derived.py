"""What the report needs of one run, computed once where the run is made: its metrics, NEES series and health series.

A sweep's worker has the run and its truth in memory right after the run; it computes them there (:func:`derive`)
and the store keeps them beside the run (``derived.npz``, :meth:`locbench.run.store.Store.write_run`). The report
takes them as stored while their keys hold: the run's arrays are the ones they were computed from (their checksum),
so is the truth (:func:`locbench.run.store.truth_key`) and so is the code that computes them (:func:`code_digest`);
otherwise it computes them again from the run, as here. Our code against itself: the stored values are the ones the
report would compute, bit for bit (``tests/evaluate/test_derived.py``).
"""

from __future__ import annotations

import functools
import hashlib
import inspect
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from locbench.evaluate.lost import HealthSeries, health_series
from locbench.evaluate.metrics import METRICS, align_run, nees_at_truth, run_metrics
from locbench.evaluate.records import RunRecord, TruthRecord

#: The format of the stored derived values; part of :func:`code_digest`.
FORMAT = 1


@dataclass(frozen=True)
class Derived:
    """One ok run's values for the report.

    Attributes
    ----------
    values : dict of str to float
        Every defined metric (:func:`locbench.evaluate.metrics.run_metrics`), keyed by id, in declaration order.
    nees : ndarray, shape (k,), or None
        The NEES at the truth's k times (:func:`locbench.evaluate.metrics.nees_at_truth`); None for a run without
        covariance.
    health : HealthSeries or None
        The position error and health signals at the truth's times (:func:`locbench.evaluate.lost.health_series`);
        None for a run without health signals or a truth that is not ground truth.
    """

    values: dict[str, float]
    nees: np.ndarray | None
    health: HealthSeries | None


def derive(run: RunRecord, truth: TruthRecord) -> Derived:
    """The report's values of an ok run against the truth of its realisation (one alignment shared by all)."""
    aligned = align_run(run, truth)
    values = run_metrics(run, truth, aligned=aligned)
    # an imported run without covariance has no NEES series (its consistency columns stay empty)
    ne = nees_at_truth(aligned) if aligned.cov is not None else None
    hs = None
    if run.health and truth.truth_label == "ground truth":
        kt = truth.kidnaps[0].t if truth.kidnaps else float("nan")
        hs = health_series(aligned, run.health, kt)
    return Derived(values, ne, hs)


def _source_files() -> list[Path]:
    """The modules whose code decides the derived values: this package, the core helpers and filters' health
    signal names, and the module of every declared metric (a plugin's included)."""
    import locbench.core
    import locbench.filters.base

    core = Path(inspect.getsourcefile(locbench.core) or "").parent
    files = set(Path(__file__).parent.glob("*.py")) | set(core.glob("*.py"))
    files.add(Path(inspect.getsourcefile(locbench.filters.base) or ""))
    for metric in METRICS.values():
        for fn in (metric.compute, metric.family):
            if fn is None:
                continue
            module = sys.modules.get(getattr(fn, "__module__", "") or "")
            path = inspect.getsourcefile(module) if module is not None else None
            if path is not None:
                files.add(Path(path))
    return sorted(files)


@functools.cache
def code_digest() -> str:
    """The sha256 of what decides a run's derived values: the stored format, the declared metric ids, numpy's and
    scipy's versions and the source of the modules that compute them (:func:`_source_files`). Any change to them
    makes every stored derived value stale (the report computes it again)."""
    import scipy

    h = hashlib.sha256(f"{FORMAT}|{np.__version__}|{scipy.__version__}|{','.join(METRICS)}".encode())
    for path in _source_files():
        h.update(path.name.encode())
        h.update(path.read_bytes())
    return h.hexdigest()
