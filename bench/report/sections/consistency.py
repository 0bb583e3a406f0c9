"""The report's section "Consistency": ANEES, NLL and proper scores, shipped worlds beside their model-matched twins."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from locbench.core.spec import Spec
from locbench.evaluate.metrics import (
    CRPS_HEADING_RAD,
    CRPS_X_M,
    CRPS_Y_M,
    ENERGY_SCORE_M,
    METRICS,
    NEES_IN_BAND_FRACTION,
    NLL,
)
from locbench.report import tables as tb
from locbench.report.doc import Section, Table, Text
from locbench.report.names import MATCHED_PARAM, NAN
from locbench.report.sections.experiment import nees_plots

if TYPE_CHECKING:
    from locbench.report.context import Report


def consistency_section(rep: Report) -> Section:
    sec = Section("Consistency", "consistency")
    pairs: list[tuple[str, str]] = []
    alone: list[str] = []
    for e in rep.exps:
        if e.fold_variants or e.dataset not in rep.col.datasets:
            continue
        # the shipped world beside its model-matched twin (DESIGN "Model-matched worlds")
        twin = Spec(e.dataset, ((MATCHED_PARAM, "true"),)).name
        if twin in rep.col.datasets:
            pairs.append((e.dataset, twin))
        else:
            alone.append(e.dataset)
    alone = list(dict.fromkeys([*alone, *rep.own(), *rep.recorded()]))
    sec.add(
        Text(
            "Is a filter's covariance an honest description of its error? The NEES (heading wrapped) at every "
            "ground-truth time, averaged over a run (ANEES) and over the runs, against the two-sided 95 % "
            "chi-square(3N)/N band for N runs; the time inside the single-run 95 % band [0.216, 9.35]. Above "
            "the band a filter is over-confident, below it under-confident. The shipped synthetic worlds carry "
            "a systematic wheel-encoder error no filter is told of, so Gaussian filters tend to be "
            "over-confident there; on their `matched=true` twins the simulator's noise is exactly the filters' "
            "nominal noise (no process noise Q either), so a filter whose equations are right lands inside the "
            "band, but for the test's 5 % false alarms and its linearisation. Global-localization runs are left "
            "out. NLL: the mean negative log-likelihood of the truth under the filter's Gaussian (lower is "
            "better; unlike the ANEES it also penalises a covariance that is needlessly large), over the runs "
            "whose covariance never collapsed. ATE / PCRB: the filter's RMS ATE over the bound's (docs/pcrb.md). "
            "Energy score and CRPS: proper scores of the filter's own belief (its Gaussian in closed form, the "
            "particle filter's own particles), mean over the ground-truth times and the runs; lower is better, a "
            "point estimate scores its error, and a belief is rewarded for being sharp only where it is right."
        )
    )
    collapsed = False
    for shipped, twin in pairs:
        table, inf = shipped_matched_table(rep, shipped, twin)
        collapsed |= inf
        sec.add(table)
        sec.add(*nees_plots(rep, twin))
    rows: list[tuple[str, ...]] = []
    keys: list[tuple[float, ...]] = []
    for ds in alone:
        for f in rep.filters_on(ds):
            cells, ckeys, inf = consistency_cells(rep, ds, f)
            if cells is None:
                continue
            collapsed |= inf
            rows.append((f"`{rep.col.display(ds)}`", f"`{f}`", *cells))
            keys.append((NAN, NAN, *ckeys))
    if rows:
        sec.add(
            Table(
                (
                    "dataset",
                    "filter",
                    "runs",
                    "95 % band",
                    "ANEES",
                    "time in 95 % band (%)",
                    "NLL",
                    "energy score (cm)",
                    "CRPS x / y (cm) / heading (deg)",
                ),
                tuple(rows),
                caption="Other worlds and the recorded data",
                sort_keys=tuple(keys),
            )
        )
    if collapsed:
        sec.add(Text(tb.COLLAPSE_FOOTNOTE))
    return sec if pairs or rows else Section("Consistency", "consistency")


def consistency_cells(rep: Report, dataset: str, f: str) -> tuple[tuple[str, ...] | None, tuple[float, ...], bool]:
    """``runs, band, ANEES, time in band, NLL`` of one (dataset, filter), their sort keys and whether a run
    collapsed; None when it has no NEES."""
    sub = rep.rows(dataset)
    sub = sub[sub["filter"] == f]
    text, key, inf, n = tb.consistency_cell(sub)
    if n == 0:
        return None, (), False
    inband = tb.mean_of(sub, NEES_IN_BAND_FRACTION) * METRICS[NEES_IN_BAND_FRACTION].scale
    nll = tb.mean_of(sub[np.isfinite(sub["value"]) | (sub["metric"] != NLL)], NLL)
    es, cx, cy, ch = (
        tb.mean_of(sub, m) * METRICS[m].scale for m in (ENERGY_SCORE_M, CRPS_X_M, CRPS_Y_M, CRPS_HEADING_RAD)
    )
    crps = f"{tb.num(cx)} / {tb.num(cy)} / {tb.num(ch)}"
    cells = (str(n), tb.band_text(n), text, tb.num(inband), tb.num(nll), tb.num(es), crps)
    return cells, (float(n), NAN, key, inband, nll, es, NAN), inf > 0


def shipped_matched_table(rep: Report, shipped: str, twin: str) -> tuple[Table, bool]:
    """One row per filter: ANEES, NLL and ATE / PCRB on the shipped world and on its model-matched twin."""
    rows: list[tuple[str, ...]] = []
    keys: list[tuple[float, ...]] = []
    collapsed = False
    # the configurations run on the twin (the consistency suite's), not every sweep of the shipped world
    for f in rep.filters_on(twin):
        row: list[str] = [f"`{f}`"]
        key: list[float] = [NAN]
        for ds in (shipped, twin):
            cells, ckeys, inf = consistency_cells(rep, ds, f)
            collapsed |= inf
            eff = tb.ate_over_bound(rep.rows(ds), f)
            if cells is None:
                row += ["-"] * 5
                key += [NAN] * 5
            else:
                row += [cells[0], cells[2], cells[4], cells[5], tb.num(eff)]
                key += [ckeys[0], ckeys[2], ckeys[4], ckeys[5], eff]
        if any(c != "-" for c in row[1:]):
            rows.append(tuple(row))
            keys.append(tuple(key))
    head = (
        "filter",
        *(
            f"{w}: {c}"
            for w in ("shipped", "matched")
            for c in ("runs", "ANEES", "NLL", "energy score (cm)", "ATE / PCRB")
        ),
    )
    caption = f"`{shipped}` as shipped beside `{twin}` (simulator noise = the filters' nominal noise)"
    return Table(head, tuple(rows), caption=caption, sort_keys=tuple(keys)), collapsed
