"""Ranking tables' bold marks: each column's best and every row a paired test does not find different from it.

Shared by the report (:mod:`locbench.report`) and the claims' own tables (:mod:`locbench.claims`), so neither
imports the other's helpers. The tests are :mod:`locbench.evaluate.significance`; this module picks the per-run values
out of
the tidy metrics, marks the cells and writes the footnotes and hover texts.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import pandas as pd

from locbench.core.spec import Spec
from locbench.evaluate import significance as sg
from locbench.evaluate.metrics import (
    FAILED,
    KIDNAP_RECOVERED,
    WAYPOINT_ERROR_M,
    WAYPOINT_RMSE_MEAN_M,
    Metric,
    family_regex,
)
from locbench.evaluate.pcrb import is_bound_row
from locbench.present.docfmt import Table, num

TIES_FOOTNOTE = (
    "Bold: the best value of the column and every configuration not significantly different from it: a "
    "two-sided Wilcoxon signed-rank test over the seeds both share (exact where n and ties allow), "
    f'Holm-corrected within the column, at {100 * sg.ALPHA:.0f} % (docs/protocols.md "Is a difference real?"); '
    "the baseline is never marked. Runtime columns are tested over the per-run medians."
)
UNTESTED_FOOTNOTE = (
    "Each cell rests on one run (or fewer than "
    f"{sg.MIN_PAIRS} shared seeds): no paired test is possible, so only the best value is in bold."
)


# --- per-run values -----------------------------------------------------------------------------------


def per_seed(df: pd.DataFrame, metric: str) -> dict[int, float]:
    """seed -> value of one metric in the rows of one (dataset, configuration); NaN values left out."""
    sel = df[df["metric"].to_numpy() == metric]
    out = {int(s): float(v) for s, v in zip(sel["seed"], sel["value"], strict=True) if not math.isnan(float(v))}
    return out


def samples_for(df: pd.DataFrame, filters: Sequence[str], metric: str) -> list[dict[int, float] | None]:
    """The per-run values of one column, a dict seed -> value per row (None: no values); one pass over ``df``.

    ``waypoint_rmse_mean_m`` (a statistic over runs): each run's mean of ``waypoint_<j>_error_m`` over the waypoints,
    the per-run value its column is tested on; ``kidnap_recovered``:
    a failed run (no value) counts as 0, as the tables' rates do; otherwise the metric's value (NaN left out).
    """
    if metric == WAYPOINT_RMSE_MEAN_M:
        sel = df[df["metric"].astype(str).str.fullmatch(family_regex(WAYPOINT_ERROR_M))]
        grouped = sel.groupby(["filter", "seed"])["value"].mean()
    else:
        sel = df[(df["metric"].to_numpy() == metric) & df["value"].notna().to_numpy()]
        grouped = sel.groupby(["filter", "seed"])["value"].last()
    by: dict[str, dict[int, float]] = {}
    if metric == KIDNAP_RECOVERED:
        failed = df[df["metric"] == FAILED]
        for f, seed in zip(failed["filter"], failed["seed"], strict=True):
            by.setdefault(str(f), {})[int(seed)] = 0.0
    for (f, seed), v in grouped.items():  # type: ignore[misc]
        by.setdefault(str(f), {})[int(seed)] = float(v)
    return [by.get(f) or None for f in filters]


# --- ties with the best ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Column:
    """A ranked column of a table: its index, metric metadata and per-row per-run values."""

    index: int
    info: Metric
    samples: Sequence[dict[int, float] | None]


@dataclass(frozen=True)
class TieMarks:
    """What :func:`mark_ties` found: the ranked columns (table indices) tested and those with no paired test."""

    tested: tuple[int, ...]
    untested_columns: tuple[int, ...]

    @property
    def untested(self) -> bool:
        """Every ranked column was untested (single runs), so the table says no test was possible."""
        return bool(self.untested_columns) and not self.tested


def effect_hover(info: Metric, c: sg.PairedComparison, reference: str) -> str:
    """The hover text of a compared cell: the paired effect against the column's best, in display units."""
    t = c.test
    if not t.tested:
        return f"against {reference}: no paired test possible (n = {t.n})"
    unit = f" {info.display_unit}" if info.display_unit else ""
    s = info.scale
    eff = f"{num(c.effect * s)}{unit}"
    if not math.isnan(c.effect_low):
        eff += f" [{num(c.effect_low * s)}, {num(c.effect_high * s)}] (95 % bootstrap)"
    p = sg.format_p(c.p_holm)
    return (
        f"against {reference}: median paired difference {eff}; Wilcoxon signed-rank, n = {t.n}, "
        f"p (Holm) {p if p.startswith('<') else '= ' + p}"
    )


def _label(cell: str) -> str:
    return cell.replace("**", "").replace("`", "")


def mark_ties(
    rows: list[list[str]],
    keys: list[list[float]],
    columns: Sequence[Column],
    eligible: Sequence[bool],
    *,
    groups: Sequence[object] | None = None,
    hovers: list[list[str]] | None = None,
    labels: Sequence[str] | None = None,
) -> TieMarks:
    """Bold, in place, each column's best and every row tied with it
    (:func:`locbench.evaluate.significance.ties_with_best`).

    ``groups``: per row, the group it is ranked in (rows of one dataset, the same path ...); each column ranks
    each group on its own (default: one group). ``hovers``: a grid like ``rows`` that receives, per compared
    cell, its paired effect against the best (:func:`effect_hover`; the bootstrap then runs). ``labels``: per
    row, its name in those texts (default: its first cell).
    """
    names = [_label(r[0]) for r in rows] if labels is None else list(labels)
    keyed = [0] * len(rows) if groups is None else list(groups)
    tested: list[int] = []
    untested: list[int] = []
    for c in columns:
        target = c.info.target if c.info.better == "closer" else 1.0
        col_untested = []
        for g in dict.fromkeys(keyed):
            ok = [e and k == g for e, k in zip(eligible, keyed, strict=True)]
            v = sg.ties_with_best(
                [k[c.index] for k in keys],
                c.samples,
                ok,
                c.info.better,  # type: ignore[arg-type]
                target,
                effects=hovers is not None,
            )
            for i in v.marked:
                rows[i][c.index] = f"**{rows[i][c.index]}**"
            if v.best is None or not v.comparisons:  # a group with one candidate has nothing to test
                continue
            col_untested.append(v.untested)
            if hovers is not None:
                for x in v.comparisons:
                    hovers[x.index][c.index] = effect_hover(c.info, x, names[v.best])
        if col_untested:
            (untested if all(col_untested) else tested).append(c.index)
    return TieMarks(tuple(tested), tuple(untested))


def tie_footnote(marks: TieMarks, header: Sequence[str] = ()) -> str:
    """The footnote of a marked table; with ``header``, it names the columns where no test was possible."""
    if marks.untested:
        return UNTESTED_FOOTNOTE
    if header and marks.untested_columns:
        cols = ", ".join(header[i] for i in marks.untested_columns)
        return (
            f"{TIES_FOOTNOTE} No paired test is possible in {cols} (fewer than {sg.MIN_PAIRS} shared seeds): "
            "only the best value there is in bold."
        )
    return TIES_FOOTNOTE


def hover_grid(rows: Sequence[Sequence[str]]) -> list[list[str]]:
    """An empty hover grid shaped like ``rows`` (for :func:`mark_ties`)."""
    return [[""] * len(r) for r in rows]


def eligible_names(names: Sequence[str]) -> list[bool]:
    """Which configuration names may be marked best: all but the baseline (its class says so) and the bound's rows;
    a name whose class cannot be loaded counts as a candidate."""
    from locbench.registry import FILTERS  # the registry imports the filters lazily

    out = []
    for n in names:
        if is_bound_row(n):
            out.append(False)
            continue
        try:
            baseline = bool(FILTERS.load(Spec.parse(n).ident).baseline)
        except Exception:  # a plug-in gone or an optional dependency missing: the table still comes out
            baseline = False
        out.append(not baseline)
    return out


def marked_table(
    header: tuple[str, ...],
    rows: Sequence[Sequence[str]],
    keys: Sequence[Sequence[float]],
    columns: Sequence[Column],
    eligible: Sequence[bool],
    *,
    caption: str,
    groups: Sequence[object] | None = None,
    labels: Sequence[str] | None = None,
    footnotes: tuple[str, ...] = (),
) -> Table:
    """An experiment's own ranking table: each column's best and its ties in bold (:func:`mark_ties`, within
    each group), the paired effects as the cells' hovers and the ties footnote (naming the columns where no
    test was possible). ``keys`` holds, per row and column, the printed value the best is chosen by (NaN: none)."""
    cells = [list(r) for r in rows]
    tips = hover_grid(cells)
    marks = mark_ties(cells, [list(k) for k in keys], columns, eligible, groups=groups, hovers=tips, labels=labels)
    return Table(
        header,
        tuple(tuple(r) for r in cells),
        caption=caption,
        footnotes=(*footnotes, tie_footnote(marks, header)),
        sort_keys=tuple(tuple(k) for k in keys),
        hovers=tuple(tuple(h) for h in tips),
    )
