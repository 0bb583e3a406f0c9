"""The report's section "Initial heading error": each filter's consistency and error as the initial belief's
heading is turned further off (the worlds' ``initial_heading_error_deg`` variants, suite ``heading``)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from locbench.evaluate.metrics import (
    ATE_M,
    CONVERGED,
    METRICS,
    NEES_IN_BAND_FRACTION,
    TIME_TO_CONVERGE_S,
    UPDATES_TO_CONVERGE,
)
from locbench.report import tables as tb
from locbench.report.doc import Section, Table, Text
from locbench.report.names import NAN

if TYPE_CHECKING:
    from locbench.report.context import Report

#: The dataset parameter of the wrong initial heading, deg (the plain world has 0).
HEADING_PARAM = "initial_heading_error_deg"


def heading_variants(rep: Report) -> dict[str, list[tuple[float, str]]]:
    """Dataset id -> [(heading error deg, dataset name)] ascending, for every id with a stored variant of
    :data:`HEADING_PARAM` and nothing else (its plain name at 0 when stored)."""
    out: dict[str, list[tuple[float, str]]] = {}
    for name, info in rep.col.datasets.items():
        params = dict(info.spec.params)
        if set(params) == {HEADING_PARAM}:
            out.setdefault(info.spec.ident, []).append((float(params[HEADING_PARAM]), name))
    for ident, rows in out.items():
        if ident in rep.col.datasets:
            rows.append((0.0, ident))
        rows.sort()
    return out


def heading_section(rep: Report) -> Section:
    """One table per world: every filter at every heading error (ANEES, time in the band, ATE, convergence)."""
    sec = Section("Initial heading error", "heading")
    variants = heading_variants(rep)
    if not variants:
        return sec
    sec.add(
        Text(
            "UKF-M's question on our worlds (Brossard, Barrau and Bonnabel 2020: 45 deg off, an EKF's position NEES "
            "275 against 2.02 for the invariant EKF): the initial belief's heading is turned by 0, 15, 45 or 90 deg "
            "and its heading standard deviation set to the same angle, so the belief covers its own error; the "
            "truth and the sensors are those of the world. ANEES against the two-sided 95 % chi-square(3N)/N band, "
            "the time inside the single-run 95 % band, ATE, and convergence (docs/protocols.md). The claims table "
            "judges the 45 deg rows of the invariant EKF against the EKF."
        )
    )
    sec.add(
        Text(
            "Convergence is the recovery criterion (position within 0.25 m, heading within 0.25 rad, held 2 s). Its "
            "time is taken at the ground-truth times, which all see a belief after the world's first landmark "
            "update at t = 0: a filter whose first update brings the heading back has converged at 0 s whatever "
            "it started from. The number of measurement updates it made by then tells them apart: 0 when the "
            "initial belief already meets the criterion, 1 when the first update fixes the heading, more when it "
            "takes longer (median and largest over the converged runs)."
        )
    )
    collapsed = False
    for ident, names in sorted(variants.items()):
        table, inf = _table(rep, ident, names)
        collapsed |= inf
        sec.add(table)
    if collapsed:
        sec.add(Text(tb.COLLAPSE_FOOTNOTE))
    return sec


def _table(rep: Report, ident: str, names: list[tuple[float, str]]) -> tuple[Table, bool]:
    """The rows (filter, heading error) of one world, in the collected filter order, and whether a run collapsed:
    the configurations run at a wrong heading (the plain world's other configurations are the main comparison's)."""
    filters = rep.col.filter_order({f for err, n in names if err != 0 for f in rep.filters_on(n)})
    rows: list[tuple[str, ...]] = []
    keys: list[tuple[float, ...]] = []
    collapsed = False
    for f in filters:
        for err, name in names:
            sub = rep.rows(name)
            sub = sub[sub["filter"] == f]
            if not len(sub):
                continue
            text, key, inf, n = tb.consistency_cell(sub)
            collapsed |= inf > 0
            inband = tb.mean_of(sub, NEES_IN_BAND_FRACTION) * METRICS[NEES_IN_BAND_FRACTION].scale
            ate = tb.mean_of(sub, ATE_M) * METRICS[ATE_M].scale
            k, m, _, _, _ = tb.rate(sub, CONVERGED)
            ttc = tb.values(sub, TIME_TO_CONVERGE_S)
            utc = tb.values(sub, UPDATES_TO_CONVERGE)
            rows.append(
                (f"`{f}`", f"{err:g}", str(n), tb.band_text(n), text, tb.num(inband), tb.num(ate), f"{k}/{m}",
                 tb.median_text(ttc), _median_max(utc))
            )  # fmt: skip
            med = float(np.median(ttc)) if ttc.size else NAN
            umed = float(np.median(utc)) if utc.size else NAN
            keys.append((NAN, err, float(n), NAN, key, inband, ate, k / m if m else NAN, med, umed))
    head = (
        "filter",
        "heading error (deg)",
        "runs",
        "95 % band",
        "ANEES",
        "time in 95 % band (%)",
        tb.header(ATE_M),
        CONVERGED,  # the fraction of the runs that converged, headed by the metric's name
        "time to converge (s, median)",
        "updates to converge (median, max)",
    )
    return Table(head, tuple(rows), caption=f"`{ident}`: a wrong initial heading", sort_keys=tuple(keys)), collapsed


def _median_max(v: np.ndarray) -> str:
    """``median (max)`` of whole counts, "n/a" without a value."""
    if not v.size:
        return "n/a"
    return f"{float(np.median(v)):g} ({float(np.max(v)):g})"
