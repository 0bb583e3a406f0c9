"""The report's section "Recorded data": every filter on the recorded datasets, grouped by the kind of reference."""

from __future__ import annotations

from collections import defaultdict
from typing import TYPE_CHECKING

import numpy as np

from locbench.evaluate.metrics import METRICS, REALTIME_FACTOR
from locbench.report import tables as tb
from locbench.report import timing as tm
from locbench.report.doc import Section, Table, Text
from locbench.report.names import NAN, slug
from locbench.report.sections import paired_tests as sig
from locbench.report.sections.reference import (
    KINDS,
    dataset_reference_kind,
    kind_caption,
    recorded_header,
    robustness_table,
)

if TYPE_CHECKING:
    from locbench.report.context import Report


def recorded_section(rep: Report) -> Section:
    sec = Section("Recorded data", "recorded")
    names = rep.recorded()
    if not names:
        return sec
    status: dict[tuple[str, str], set[str]] = defaultdict(set)
    for r in rep.col.runs:
        if r.dataset in names:
            status[(r.filter, r.dataset)].add(r.status)
    filters = rep.col.filter_order({f for f, _ in status})

    def cell(f: str, ds: str, metric: str) -> tuple[str, float]:
        sub = rep.rows(ds)
        v = tb.values(sub[sub["filter"] == f], metric) * METRICS[metric].scale
        if v.size:
            return tb.num(float(np.mean(v))) + (f" (n={v.size})" if v.size > 1 else ""), float(np.mean(v))
        st = status.get((f, ds), set())
        if "skipped" in st:
            return "skipped", NAN
        if st - {"ok"}:
            return "failed", NAN
        return "-", NAN

    def with_ref(c: tuple[str, float], f: str, ds: str) -> tuple[str, float]:
        sub = rep.rows(ds)
        return tm.with_ref(c[0], sub[sub["filter"] == f], REALTIME_FACTOR) if np.isfinite(c[1]) else c[0], c[1]

    groups = [(k, [d for d in names if dataset_reference_kind(rep, d) == k]) for k in KINDS]
    sec.add(
        Text(
            "Every filter on the recorded datasets (one recording each; the mean over seeds where a randomised "
            "filter ran several), grouped by the kind of reference the scores are measured against: motion "
            "capture, GPS, survey, not stated (the dataset gives no method), SLAM (another estimator's output, "
            "whose map comes from the same log: agreement with it is not accuracy) and simulation. A SLAM "
            "reference with relations (Intel) is scored by the relation error (Kuemmerle et al. 2009), the "
            "others by ATE against the reference. Semi-synthetic: the recording's scans with simulated motion "
            "increments (the reference increments plus an encoder error fitted where the raw recording exists). "
            "Skipped: the filter needs a map kind or sensor the dataset lacks, or its resources exceed a stated "
            "bound (the appendix lists the reasons)."
        )
    )
    for kind, group in groups:
        if not group:
            continue
        head = ("filter", *(recorded_header(rep, d) for d in group))
        fs = [f for f in filters if any((f, d) in status for d in group)]
        acc = [[cell(f, d, rep.recorded_metric(d)) for d in group] for f in fs]
        rtf = [[with_ref(cell(f, d, REALTIME_FACTOR), f, d) for d in group] for f in fs]
        metrics_text = "; ".join(f"`{rep.col.display(d)}` {tb.header(rep.recorded_metric(d))}" for d in group)
        sub = Section(f"Reference: {kind}", f"recorded-{slug(kind)}")
        sub.add(Text(f"Accuracy: {metrics_text}; {kind_caption(kind)}."))
        for grid, metric_of, what in (
            (acc, rep.recorded_metric, "Accuracy (cm)"),
            (rtf, lambda d: REALTIME_FACTOR, "Real-time factor (x)"),
        ):
            cells, note, hover = sig.mark_grid(rep, fs, group, grid, metric_of)
            sub.add(
                Table(
                    head,
                    tuple(tuple(r) for r in cells),
                    caption=f"{what}; {kind_caption(kind)}",
                    footnotes=(note, *tm.ref_footnote(cells)),
                    sort_keys=tuple((NAN, *(c[1] for c in r)) for r in grid),
                    hovers=hover,
                )
            )
        worse = not_below_baseline(rep, fs, group, acc)
        if worse:
            sub.add(Text(f"Not below dead reckoning ({kind_caption(kind)}): {worse}."))
        sec.children.append(sub)
    noise_of = {}
    for d in names:
        rn = rep.truth_meta(d)[1].get("range_noise")
        if isinstance(rn, dict) and isinstance(rn.get("world"), str) and isinstance(rn.get("noise"), str):
            noise_of[d] = (rn["world"], rn["noise"])
    robust = robustness_table(rep.df[rep.df["dataset"].isin(names)], filters, noise_of)
    if robust is not None:
        sec.children.append(Section("Robustness to range noise", "recorded-robustness", [robust]))
    return sec


def not_below_baseline(rep: Report, fs: list[str], group: list[str], acc: list[list[tuple[str, float]]]) -> str:
    """The (filter, dataset) cells of a recorded group whose accuracy is no better than the baseline's."""
    base = [i for i, f in enumerate(fs) if rep.col.is_baseline(f)]
    if not base:
        return ""
    out = []
    for j, d in enumerate(group):
        ref = acc[base[0]][j][1]
        if not np.isfinite(ref):
            continue
        for i, f in enumerate(fs):
            v = acc[i][j][1]
            if i not in base and np.isfinite(v) and v >= ref:
                out.append(f"`{f}` on `{rep.col.display(d)}` ({tb.num(v)} against {tb.num(ref)})")
    return "; ".join(out)


def input_warnings_section(rep: Report) -> Section:
    """What the loaders warned about a dataset's input (``metadata["warnings"]``: a twist that contradicts the
    poses, events outside the truth's span), so that a number built on a suspect input says so."""
    sec = Section("Input warnings", "input-warnings")
    rows = []
    for d in sorted(rep.col.datasets):
        found = rep.truth_meta(d)[1].get("warnings")
        for w in found if isinstance(found, list) else []:
            rows.append((f"`{rep.col.display(d)}`", str(w)))
    if rows:
        sec.add(Text("The loaders' warnings about these datasets' input:"), Table(("dataset", "warning"), tuple(rows)))
    flagged = _flagged_rows(rep)
    if flagged:
        sec.add(
            Text(
                "Samples the loaders flagged and left out (each broke a physical bound of the plausibility policy, "
                "docs/datasets.md; neither the filters nor the metrics saw them):"
            ),
            Table(("dataset", "stream", "quantity", "samples", "times, s", "bound"), tuple(flagged)),
        )
    return sec


#: Flagged times listed per row of the input-warnings table (the run's provenance has them all).
FLAGGED_TIMES_SHOWN = 5


def _flagged_rows(rep: Report) -> list[tuple[str, ...]]:
    """One row per dataset, stream and quantity of the flagged samples in the truth records."""
    rows: list[tuple[str, ...]] = []
    seen: set[str] = set()
    for (d, _), tr in sorted(rep.col.truths.items()):
        found = tr.meta.get("flagged")
        if d in seen or not isinstance(found, list) or not found:
            continue
        seen.add(d)  # the same recording under every seed: its flags once
        groups: dict[tuple[str, str, str], list[float]] = {}
        for s in found:
            if isinstance(s, dict):
                key = (str(s.get("stream", "")), str(s.get("quantity", "")), str(s.get("bound", "")))
                groups.setdefault(key, []).append(float(s.get("t", float("nan"))))
        for (stream, quantity, bound), times in sorted(groups.items()):
            shown = ", ".join(f"{t:.3f}" for t in times[:FLAGGED_TIMES_SHOWN])
            more = f" and {len(times) - FLAGGED_TIMES_SHOWN} more" if len(times) > FLAGGED_TIMES_SHOWN else ""
            rows.append((f"`{rep.col.display(d)}`", stream, quantity, str(len(times)), shown + more, bound))
    return rows
