"""Runtimes in the report both raw and in reference units, and the machine they were measured on.

A metric in reference units is its raw value over the reference workload's time on the same machine under the same
load (:func:`locbench.evaluate.metrics.reference_units`): id ``<metric>_ref``. Runs stored before ``reference_s`` was
recorded
have no such rows; a cell then shows the raw value alone and the accuracy-runtime figures stay on the raw axis.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from locbench.evaluate.metrics import METRICS, REALTIME_FACTOR, REALTIME_FACTOR_REF, REF_SUFFIX
from locbench.report import tables as tb

#: The x metric of the accuracy-runtime figures: the real-time factor in reference units, where every run has it.
PARETO_X = REALTIME_FACTOR_REF
#: Their fallback on stores older than the reference workload.
PARETO_X_RAW = REALTIME_FACTOR

REF_FOOTNOTE = (
    "Values as (ref ...): in reference units, the raw value with the time of a fixed reference workload, measured "
    "on the same machine under the same load, divided out (`reference_s` in each run's provenance; its CPU time "
    "`reference_cpu_s` for the medians): the time, or real-time factor, on a machine whose reference workload takes "
    "1 s. `python -m locbench.run.reference_workload` measures it on yours; docs/protocols.md, Runtime."
)


def ref_metric(metric: str) -> str:
    """The id of ``metric`` in reference units."""
    return f"{metric}{REF_SUFFIX}"


def with_ref(text: str, df: pd.DataFrame, metric: str) -> str:
    """``text`` (a cell of the raw ``metric``'s mean over ``df``) followed by ``(ref X)``, the same mean in
    reference units, when ``df`` has it."""
    ref = tb.mean_of(df, ref_metric(metric))
    return f"{text} (ref {tb.num(ref)})" if np.isfinite(ref) else text


def ref_footnote(cells: Sequence[Sequence[str]]) -> list[str]:
    """``[REF_FOOTNOTE]`` when a cell of the grid shows a value in reference units (:func:`with_ref`), else ``[]``."""
    return [REF_FOOTNOTE] if any("(ref " in c for row in cells for c in row) else []


def pareto_x(df: pd.DataFrame) -> str:
    """The figures' x metric: :data:`PARETO_X` when every run with a real-time factor has it in reference units,
    else :data:`PARETO_X_RAW` (one axis for every figure of the report)."""
    if not len(df):
        return PARETO_X
    counts = df["metric"].value_counts()
    raw, ref = int(counts.get(PARETO_X_RAW, 0)), int(counts.get(PARETO_X, 0))
    return PARETO_X if ref and ref == raw else PARETO_X_RAW


def pareto_xlabel(metric: str) -> str:
    """The axis label of :func:`pareto_x`'s metric: ``real-time factor (ref x)`` or ``real-time factor (x)``."""
    return tb.header(metric) if metric in METRICS else metric


def _range(values: Sequence[float], digits: int = 3) -> str:
    v = np.asarray(values, dtype=np.float64)
    lo, mid, hi = (tb.num(float(x), digits) for x in (v.min(), np.median(v), v.max()))
    return mid if lo == hi else f"{mid} (median; {lo}-{hi})"


def machine_line(metas: Sequence[dict[str, Any]]) -> str:
    """The provenance line of the machines the runs ran on: CPU model and counts, the reference workload's time
    (one value per sweep) and the 1-minute load average as the runs started."""
    models: dict[str, int] = {}
    counts: set[str] = set()
    refs: dict[float, None] = {}
    loads: list[float] = []
    for m in metas:
        if "cpu_model" in m:
            models[str(m["cpu_model"])] = models.get(str(m["cpu_model"]), 0) + 1
        c = m.get("cpu_count")
        if isinstance(c, dict):
            counts.add(f"{c.get('logical')} logical, {c.get('affinity')} usable")
        ref = m.get("reference_s")
        if isinstance(ref, (int, float)) and not isinstance(ref, bool) and ref > 0:
            refs[float(ref)] = None
        load = m.get("load_avg")
        if isinstance(load, list) and load and isinstance(load[0], (int, float)):
            loads.append(float(load[0]))
    if not models and not refs:
        return "machine: not recorded (runs stored before the reference workload)"
    parts = [
        "machine: " + (", ".join(f"{k} ({n} runs)" for k, n in sorted(models.items())) or "unknown"),
        f"CPUs {' / '.join(sorted(counts)) or 'unknown'}",
        f"reference workload {_range(list(refs))} s over {len(refs)} measurements (one per sweep and process, or "
        "per task when interleaved)"
        if refs
        else "no reference workload",
        f"1-minute load average at the runs' start {_range(loads, 2)}" if loads else "load not recorded",
    ]
    return "; ".join(parts)
