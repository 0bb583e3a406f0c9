"""The report's summary: a decision table per main comparison and per dataset of a user's own, a row per filter
configuration.

The table is declared once, as :func:`columns`: each :class:`SummaryColumn` gives its header, its cell (text and
sort key) for a row, the metric it is ranked by (which way is better comes from the metric's declaration,
:data:`locbench.evaluate.metrics.METRICS`), the per-run values its paired test takes and its footnote; the headers,
cells, sort keys, best marks and notes of every summary table are generated from it. Its metric columns are the
metrics declared with ``summary=True``, in declaration order: a metric the report computes over runs (the ratio to
the bound, the lost AUROC ...) or shows in its own way has its column in :data:`OWN_COLUMNS`; any other gets
:func:`metric_column`, the mean over seeds in its display unit, so a metric declared for the summary appears there
without an edit here. Rows: the baseline, then the default configuration of each filter by
ATE, then each filter's other configurations grouped under it in the same order, then the configurations that were
skipped (with the reason stored), then the bound. Above the table, a paragraph generated from the same numbers says
which configuration to use with which sensors and map (:func:`advice`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from locbench.core.events import Odometry
from locbench.evaluate import significance as sg
from locbench.evaluate.lost import LOST_THRESHOLDS_M
from locbench.evaluate.metrics import (
    ANEES,
    ATE_M,
    ATE_OVER_PCRB,
    FAILED,
    KIDNAP_RECOVERED,
    LOST_AUROC,
    METRICS,
    POSE_DOF,
    REALTIME_FACTOR,
    RECORDED_ATE_MEDIAN_M,
    REF_SUFFIX,
    WAYPOINT_RMSE_MEAN_M,
    Metric,
)
from locbench.evaluate.pcrb import BOUND_ALL
from locbench.present import ranking as rk
from locbench.report import figures as fg
from locbench.report import tables as tb
from locbench.report import timing as tm
from locbench.report.doc import Block, Section, Table, Text
from locbench.report.names import KIDNAP_PARAM, NAN, slug
from locbench.report.sections import health as hl
from locbench.report.sections import paired_tests as sig
from locbench.report.sections.reference import INDEPENDENT_KINDS, dataset_reference_kind

if TYPE_CHECKING:
    from locbench.report.context import Report

#: The kidnap distance whose recovery rate the summary table shows, m.
SUMMARY_KIDNAP_M = 2.0
#: How the event types a filter uses read in the table (by class name; another type reads as its class name).
SENSOR_WORDS = {
    Odometry.__name__: Odometry.__name__.lower(),
    "LaserScan": "laser",
    "LandmarkObservations": "landmark sightings",
    "RangeObservations": "beacon ranges",
    "PoseFix": "pose fixes",
}
#: The motion input every filter predicts with (the event type's name, lower case).
ODOMETRY = SENSOR_WORDS[Odometry.__name__]
#: How the map kinds a filter requires read (by ``MapKind`` value).
MAP_WORDS = {"occupancy": "occupancy grid", "landmarks": "landmark map", "lines": "line map"}

PerRun = dict[int, float] | None


def summary_section(rep: Report) -> Section:
    """One decision table per main comparison, then one per dataset of a user's own (:meth:`Report.own`)."""
    sec = Section("Summary", "summary")
    names = [(e.title, e.dataset) for e in rep.exps if e.summary and e.dataset in rep.col.datasets]
    names += [(rep.own_title(d), d) for d in rep.own()]
    for title, ds in names:
        sec.children.append(Section(title, f"summary-{slug(ds)}", summary_blocks(rep, ds)))
    return sec


def summary_blocks(rep: Report, dataset: str) -> list[Block]:
    """The advice paragraph (when there is a choice to make) and the decision table of one dataset name, in two
    blocks when it has sweeps or tuned configurations: the defaults (with the baseline, the skipped
    configurations and the bound), then the other configurations (:func:`split_blocks`)."""
    table, ctx, rows = _summary(rep, dataset)
    text = advice(ctx, rows)
    tables = split_blocks(table, [_is_default(rep, r) for r in rows])
    return [Text(text), *tables] if text else list(tables)


def _is_default(rep: Report, row: Row) -> bool:
    """Whether a row belongs in the defaults' block: a filter's default configuration, the baseline, a skipped
    configuration or the bound."""
    return row.bound or bool(row.skipped) or not rep.col.filter_info(row.name).spec.params


def split_blocks(table: Table, default: Sequence[bool]) -> tuple[Table, ...]:
    """The table's rows in two tables of the same columns: those flagged ``default``, then the rest (the sweeps and
    tuned configurations); one table when either part is empty. Marks, hovers and footnotes stay as computed over
    all rows (a best mark is the best of both blocks)."""
    if all(default) or not any(default):
        return (table,)

    def part(keep: bool, caption: str, notes: tuple[str, ...]) -> Table:
        idx = [i for i, d in enumerate(default) if d == keep]
        return Table(
            table.header,
            tuple(table.rows[i] for i in idx),
            caption=caption,
            footnotes=notes,
            sort_keys=tuple(table.sort_keys[i] for i in idx) if table.sort_keys else (),
            hovers=tuple(table.hovers[i] for i in idx) if table.hovers else (),
        )

    return (
        part(True, f"{table.caption}: each filter's default configuration", ()),
        part(
            False,
            f"{table.caption}: sweeps and tuned configurations (marks as in the block above: the best of both)",
            table.footnotes,
        ),
    )


# --- rows and their context ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Row:
    """One row: a configuration (or the bound) with its rows on the dataset and its kidnap configuration."""

    name: str
    sub: pd.DataFrame
    kname: str | None = None
    bound: bool = False
    #: Why every run of the configuration on this dataset was skipped ("": it ran).
    skipped: str = ""


@dataclass(frozen=True)
class Context:
    """What every cell of one table reads: the dataset's rows and those of its kidnapped variant."""

    rep: Report
    dataset: str
    df: pd.DataFrame
    kid: str | None
    kdf: pd.DataFrame
    waypoints: dict[str, float]
    #: configuration -> the recorded datasets' mean ATE (index of the dataset -> m)
    recorded: dict[str, dict[int, float]]


def needs_text(rep: Report, name: str) -> str:
    """What a configuration needs, from its class's declared inputs: the sensors it uses besides its motion input
    and the map kinds it requires (``laser; occupancy grid``); :data:`ODOMETRY` ``only`` for a filter that uses
    nothing else."""
    info = rep.col.filter_info(name)
    if not info.sensors:
        return "-"
    sensors = [SENSOR_WORDS.get(s, s) for s in info.sensors if s != Odometry.__name__]
    maps = [MAP_WORDS.get(m, m) for m in info.maps]
    if not sensors and not maps:
        return f"{ODOMETRY} only"
    return "; ".join(p for p in (", ".join(sorted(sensors)), ", ".join(sorted(maps))) if p)


def row_order(rep: Report, filters: Sequence[str], ate: Callable[[str], float]) -> list[str]:
    """The baseline first, then each filter's default configuration by ATE (no ATE last, ties by name), then
    each filter's other configurations grouped under it in that order (a filter without a default run placed by
    its best configuration's ATE), each group in the natural order of its names."""
    col = rep.col
    base = [f for f in filters if col.is_baseline(f)]
    rest = [f for f in filters if not col.is_baseline(f)]
    by_id: dict[str, list[str]] = {}
    for f in rest:
        by_id.setdefault(col.filter_info(f).spec.ident, []).append(f)

    def key(x: float) -> float:
        return x if not math.isnan(x) else math.inf

    def rank(ident: str) -> tuple[float, str]:
        members = by_id[ident]
        default = [f for f in members if not col.filter_info(f).spec.params]
        pick = default or members
        return (min(key(ate(f)) for f in pick), ident)

    ids = sorted(by_id, key=rank)
    defaults = [f for i in ids for f in by_id[i] if not col.filter_info(f).spec.params]
    sweeps = [f for i in ids for f in col.filter_order(by_id[i]) if col.filter_info(f).spec.params]
    return [*col.filter_order(base), *defaults, *sweeps]


def _rows(rep: Report, ctx: Context) -> list[Row]:
    df = ctx.df
    filters = rep.filters_on(ctx.dataset)
    kfilters = rep.filters_on(ctx.kid) if ctx.kid else []

    def ate(f: str) -> float:
        return tb.mean_of(df[df["filter"] == f], ATE_M)

    out = []
    for f in row_order(rep, filters, ate):
        # the kidnap runs of this configuration, or of its filter's one kidnap configuration
        kname = f if f in kfilters else kidnap_config(rep, f, kfilters)
        out.append(Row(f, df[df["filter"] == f], kname))
    ran = set(filters)
    reasons: dict[str, str] = {}
    for r in rep.col.runs:
        skipped = r.status == "skipped" and r.dataset == ctx.dataset and r.filter not in ran
        if skipped and not rep.col.is_global(r.filter):
            reasons.setdefault(r.filter, r.message)
    out += [Row(f, df.iloc[0:0], skipped=reasons[f]) for f in rep.col.filter_order(set(reasons))]
    out += [Row(b, df[df["filter"] == b], bound=True) for b in rep.bounds_on(ctx.dataset)]
    return out


# --- the columns ----------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SummaryColumn:
    """One column of the summary table.

    Attributes
    ----------
    header : callable
        Context -> the header text.
    cell : callable
        (context, row) -> (cell text, sort key in the cell's units; NaN: none) of a configuration's row.
    metric : str or None
        The id of the declared metric (:data:`~locbench.evaluate.metrics.METRICS`) the column is ranked by (best
        and ties in bold); None: not ranked.
    samples : callable or None
        (context, rows) -> per row, seed -> the per-run value the paired test takes (None: no test, ranking only).
    bound : bool
        The bound's rows have a value here (computed by ``cell``); otherwise "-".
    skipped : bool
        A skipped configuration's row has a value here (its name, needs, run count); otherwise "-", and in the
        ATE column the reason it was skipped.
    note : callable or None
        (context, cells of the column) -> its footnote ("" for none).
    consistent_only : bool
        Only a row whose ANEES is consistent may be marked best (an over-confident value is never "best").
    always : bool
        Shown even when no row has a value (otherwise a column without any value is left out).
    """

    header: Callable[[Context], str]
    cell: Callable[[Context, Row], tuple[str, float]]
    metric: str | None = None
    samples: Callable[[Context, Sequence[Row]], list[PerRun]] | None = None
    bound: bool = False
    skipped: bool = False
    note: Callable[[Context, Sequence[str]], str] | None = None
    consistent_only: bool = False
    always: bool = False


def _fixed(text: str) -> Callable[[Context], str]:
    return lambda ctx: text


def _mean(metric: str, absent: str = "n/a") -> Callable[[Context, Row], tuple[str, float]]:
    """The mean over runs of a metric in display units (``absent``: the text without a value)."""
    scale = METRICS[metric].scale

    def cell(ctx: Context, row: Row) -> tuple[str, float]:
        x = tb.mean_of(row.sub, metric) * scale
        return (absent if np.isnan(x) else tb.num(x)), x

    return cell


def _mean_and_ref(metric: str, absent: str = "n/a") -> Callable[[Context, Row], tuple[str, float]]:
    """:func:`_mean` followed by ``(ref X)``, the same in reference units (:func:`locbench.report.timing.with_ref`)."""
    raw = _mean(metric, absent)

    def cell(ctx: Context, row: Row) -> tuple[str, float]:
        text, x = raw(ctx, row)
        return (tm.with_ref(text, row.sub, metric) if np.isfinite(x) else text), x

    return cell


def _per_run(metric: str) -> Callable[[Context, Sequence[Row]], list[PerRun]]:
    return lambda ctx, rows: rk.samples_for(ctx.df, [r.name for r in rows], metric)


def _runs(ctx: Context, row: Row) -> tuple[str, float]:
    n = tb.run_count(row.sub) if row.bound else _seeds(row)
    return str(n), float(n)


def _ratio(ctx: Context, row: Row) -> tuple[str, float]:
    eff = tb.ate_over_bound(ctx.df, row.name)
    return tb.num(eff), eff


def _ratio_samples(ctx: Context, rows: Sequence[Row]) -> list[PerRun]:
    return [sig.ratio_per_seed(ctx.df, r.name, BOUND_ALL) or None for r in rows]


def _waypoints(ctx: Context, row: Row) -> tuple[str, float]:
    x = ctx.waypoints.get(row.name, NAN) * METRICS[WAYPOINT_RMSE_MEAN_M].scale
    return tb.num(x), x


def _anees(ctx: Context, row: Row) -> tuple[str, float]:
    text, key, _, _ = tb.consistency_cell(row.sub)
    return text, key


def _anees_note(ctx: Context, cells: Sequence[str]) -> str:
    runs = [int(tb.values(ctx.df[ctx.df["filter"] == f], FAILED).size) for f in ctx.rep.filters_on(ctx.dataset)]
    n = max(set(runs), key=runs.count) if runs else 0
    note = (
        f"ANEES: mean over runs of each run's average NEES (heading wrapped), against the two-sided 95 % "
        f"chi-square band for the run count ({tb.band_text(n)} for {n} runs); closest to {POSE_DOF} among the "
        "consistent ones is marked best (an over- or under-confident value never is)."
    )
    return note + (" " + tb.COLLAPSE_FOOTNOTE if any("¹" in c for c in cells) else "")


def _lost(ctx: Context, row: Row) -> tuple[str, float]:
    # lost detection where a filter does get lost: its kidnap configuration on the kidnapped world
    # (a configuration without kidnap runs has none, so the column means one thing throughout)
    if ctx.kid:
        x = hl.best_auroc(ctx.rep, ctx.kid, row.kname) if row.kname is not None else NAN
    else:
        x = hl.best_auroc(ctx.rep, ctx.dataset, row.name)
    return ("-" if np.isnan(x) else tb.num(x)), x


def _lost_header(ctx: Context) -> str:
    return f"lost AUROC ({LOST_THRESHOLDS_M[0]:g} m{f', {SUMMARY_KIDNAP_M:g} m kidnap' if ctx.kid else ''})"


def _lost_note(ctx: Context, cells: Sequence[str]) -> str:
    return (
        "Lost AUROC: how well the filter's best health signal separates the times its position error exceeds "
        f"{LOST_THRESHOLDS_M[0]:g} m from the others (1 perfect, 0.5 chance; '-': never lost, or no kidnap runs)"
        + (f", on `{ctx.kid}` with the kidnap configuration as for kidnap recovery" if ctx.kid else "")
        + '; see "Does the filter know that it is lost?".'
    )


def _kidnap(ctx: Context, row: Row) -> tuple[str, float]:
    if row.kname is None:
        return "-", NAN
    _, n, r, _, _ = tb.rate(ctx.kdf[ctx.kdf["filter"] == row.kname], KIDNAP_RECOVERED)
    if not n:
        return "n/a", NAN
    return f"{100 * r:.0f} ({n})" + ("²" if row.kname != row.name else ""), 100 * r


def _kidnap_samples(ctx: Context, rows: Sequence[Row]) -> list[PerRun]:
    return [rk.samples_for(ctx.kdf, [r.kname], KIDNAP_RECOVERED)[0] if r.kname else None for r in rows]


def _kidnap_note(ctx: Context, cells: Sequence[str]) -> str:
    if not ctx.kid:
        return ""
    subst = sorted((r, k) for r, k in _substituted(ctx).items())
    return f"Kidnap recovery: percentage of the runs of `{ctx.kid}` that recovered (run count in brackets)." + (
        " ² The filter's kidnap configuration: " + ", ".join(f"`{a}` -> `{b}`" for a, b in subst) + "." if subst else ""
    )


def _substituted(ctx: Context) -> dict[str, str]:
    kfilters = ctx.rep.filters_on(ctx.kid) if ctx.kid else []
    out = {}
    for f in ctx.rep.filters_on(ctx.dataset):
        k = f if f in kfilters else kidnap_config(ctx.rep, f, kfilters)
        if k is not None and k != f:
            out[f] = k
    return out


def _recorded(ctx: Context, row: Row) -> tuple[str, float]:
    per = ctx.recorded.get(row.name, {})
    if not per:
        return "-", NAN
    x = METRICS[RECORDED_ATE_MEDIAN_M].scale * float(np.median(list(per.values())))
    return f"{tb.num(x)} ({len(per)})", x


def _text_key(text: Callable[[Context, Row], str]) -> Callable[[Context, Row], tuple[str, float]]:
    return lambda ctx, row: (text(ctx, row), NAN)


#: The columns before the metrics': which configuration, what it needs, how many runs.
HEAD_COLUMNS: tuple[SummaryColumn, ...] = (
    SummaryColumn(_fixed("filter"), _text_key(lambda ctx, row: f"`{row.name}`"), bound=True, skipped=True, always=True),
    SummaryColumn(
        _fixed("needs (sensors; map)"),
        _text_key(lambda ctx, row: needs_text(ctx.rep, row.name)),
        skipped=True,
        always=True,
        note=lambda ctx, cells: (
            "Needs: the sensors a configuration uses besides its motion input and the map kinds its "
            "class requires, as the filter declares them; a filter that needs what a dataset lacks is skipped there "
            "with the reason."
        ),
    ),
    SummaryColumn(_fixed("runs"), _runs, bound=True, skipped=True, always=True),
)

#: The columns of the summary's metrics that the report computes over runs or shows in its own way, by metric id
#: (each shown where its metric's declaration puts it; any other summary metric gets :func:`metric_column`).
OWN_COLUMNS: dict[str, SummaryColumn] = {
    # the reason a configuration was skipped goes in this column (always shown)
    ATE_M: SummaryColumn(_fixed(tb.header(ATE_M)), _mean(ATE_M), ATE_M, _per_run(ATE_M), bound=True, always=True),
    ATE_OVER_PCRB: SummaryColumn(
        _fixed(tb.header(ATE_OVER_PCRB)),
        _ratio,
        ATE_OVER_PCRB,
        _ratio_samples,
        note=lambda ctx, cells: tb.BOUND_FOOTNOTE if ctx.rep.bounds_on(ctx.dataset) else "",
    ),
    WAYPOINT_RMSE_MEAN_M: SummaryColumn(
        _fixed(tb.header(WAYPOINT_RMSE_MEAN_M)),
        _waypoints,
        WAYPOINT_RMSE_MEAN_M,
        _per_run(WAYPOINT_RMSE_MEAN_M),
        bound=True,
    ),
    ANEES: SummaryColumn(
        _fixed("ANEES (verdict)"), _anees, ANEES, _per_run(ANEES), note=_anees_note, consistent_only=True
    ),
    # one AUROC per configuration over all its runs: a ranking, not a paired test
    LOST_AUROC: SummaryColumn(_lost_header, _lost, LOST_AUROC, lambda ctx, rows: [None] * len(rows), note=_lost_note),
    KIDNAP_RECOVERED: SummaryColumn(
        _fixed(f"kidnap recovery at {SUMMARY_KIDNAP_M:g} m (%)"),
        _kidnap,
        KIDNAP_RECOVERED,
        _kidnap_samples,
        note=_kidnap_note,
    ),
    RECORDED_ATE_MEDIAN_M: SummaryColumn(
        _fixed(tb.header(RECORDED_ATE_MEDIAN_M)),
        _recorded,
        RECORDED_ATE_MEDIAN_M,
        lambda ctx, rows: [ctx.recorded.get(r.name) or None for r in rows],
        note=lambda ctx, cells: (
            "Recorded median ATE: median over the recorded datasets with independent ground "
            "truth (motion capture, GPS, survey or a stated truth; never a SLAM reference or a simulated world) that "
            "this configuration ran on (their number in brackets) of its mean ATE there."
        ),
    ),
}


def metric_column(m: Metric) -> SummaryColumn:
    """The summary column of a declared metric shown as it is: the mean over seeds in its display unit, with the
    mean in reference units beside it when the metric has a twin in them (``<id>_ref``), ranked by the paired test
    of the per-run values; the bound's rows show their value when the bound gives the metric (``m.bound``); its
    footnote is the declaration's ``note``."""
    ref = f"{m.id}{REF_SUFFIX}" in METRICS
    cell = _mean_and_ref(m.id, m.absent) if ref else _mean(m.id, m.absent)

    def note(ctx: Context, cells: Sequence[str]) -> str:
        return " ".join([*([m.note] if m.note else []), *(tm.ref_footnote([list(cells)]) if ref else [])])

    return SummaryColumn(_fixed(tb.header(m.id)), cell, m.id, _per_run(m.id), bound=m.bound, note=note)


def columns() -> tuple[SummaryColumn, ...]:
    """The summary table, one record per column in reading order: :data:`HEAD_COLUMNS`, then a column per metric
    declared with ``summary=True``, in declaration order (read when a table is made, so a metric declared later is
    in it)."""
    return (*HEAD_COLUMNS, *(OWN_COLUMNS.get(m.id) or metric_column(m) for m in METRICS.values() if m.summary))


def kidnap_variant(rep: Report, dataset: str) -> str | None:
    base = rep.col.datasets[dataset].spec
    for n in rep.variants_of(base.ident):
        spec = rep.col.datasets[n].spec
        if spec.without(KIDNAP_PARAM) == base and np.isclose(rep.kidnap_distance(n), SUMMARY_KIDNAP_M):
            return n
    return None


def kidnap_config(rep: Report, filter_name: str, candidates: list[str]) -> str | None:
    """The configuration's own kidnap configuration: the one its class declares (``Filter.kidnap_params``
    added to its parameters) when it was run, else its id with every parameter it sets and the fewest more
    (``f`` -> ``f[recovery=on]``, ``f[a=1]`` -> ``f[a=1,recovery=on]``), if exactly one is that close."""
    declared = rep.col.filters[filter_name].kidnap_name
    if declared is not None and declared in candidates:
        return declared
    spec = rep.col.filters[filter_name].spec
    mine = set(spec.params)
    fits = [
        (len(rep.col.filters[c].spec.params), c)
        for c in candidates
        if rep.col.filters[c].spec.ident == spec.ident and mine <= set(rep.col.filters[c].spec.params)
    ]
    if not fits:
        return None
    fewest = min(n for n, _ in fits)
    best = [c for n, c in fits if n == fewest]
    return best[0] if len(best) == 1 else None


def recorded_means(rep: Report, filter_name: str) -> dict[int, float]:
    """Recorded dataset index -> the configuration's mean ATE there (m), over the recorded datasets with
    independent ground truth (the recorded-median column's cell is their median, its test pairs them)."""
    out: dict[int, float] = {}
    for i, ds in enumerate(rep.recorded()):
        if not rep.ground_truth(ds) or dataset_reference_kind(rep, ds) not in INDEPENDENT_KINDS:
            continue
        sub = rep.rows(ds)
        v = tb.values(sub[sub["filter"] == filter_name], ATE_M)
        if v.size:
            out[i] = float(np.mean(v))
    return out


def _summary(rep: Report, dataset: str) -> tuple[Table, Context, list[Row]]:
    df = rep.rows(dataset)
    kid = kidnap_variant(rep, dataset) if dataset in rep.col.datasets else None
    kdf = rep.rows(kid) if kid else df.iloc[0:0]
    names = rep.filters_on(dataset)
    ctx = Context(rep, dataset, df, kid, kdf, tb.waypoint_rmse_mean(df), {f: recorded_means(rep, f) for f in names})
    rows = _rows(rep, ctx)
    table_columns = columns()
    grid: list[list[tuple[str, float]]] = []
    for c in table_columns:
        cells = []
        for r in rows:
            if r.skipped and not c.skipped:
                # every run skipped: the row says what the configuration lacked, where its ATE would be
                cells.append((f"skipped: {r.skipped}", NAN) if c.metric == ATE_M else ("-", NAN))
            elif r.bound and not c.bound:
                cells.append(("-", NAN))
            else:
                cells.append(c.cell(ctx, r))
        grid.append(cells)
    shown = [j for j, c in enumerate(table_columns) if c.always or any(not math.isnan(k) for _, k in grid[j])]
    cols = [table_columns[j] for j in shown]
    text = [[grid[j][i][0] for j in shown] for i in range(len(rows))]
    keys = [[grid[j][i][1] for j in shown] for i in range(len(rows))]
    hovers = rk.hover_grid(text)
    marks = _mark(ctx, rows, cols, text, keys, hovers)
    notes = [rk.tie_footnote(marks)]
    # a long configuration name (a tuned one's values) is shown short; its full spec on hover and in a footnote
    short = fg.short_names([r.name for r in rows])
    spelled = []
    for i, r in enumerate(rows):
        if short[r.name] != r.name:
            text[i][0] = text[i][0].replace(f"`{r.name}`", f"`{short[r.name]}`")
            hovers[i][0] = r.name
            spelled.append(f"`{short[r.name]}` = `{r.name}`")
    if spelled:
        notes.append("Short names (the full specification; also on hover): " + "; ".join(spelled) + ".")
    for k, c in enumerate(cols):
        if c.note is not None:
            n = c.note(ctx, [r[k] for r in text])
            if n and n not in notes:  # the runtime columns share the note on reference units
                notes.append(n)
    table = Table(
        tuple(c.header(ctx) for c in cols),
        tuple(tuple(r) for r in text),
        caption=f"`{rep.col.display(dataset)}`: mean over seeds",
        footnotes=tuple(notes),
        sort_keys=tuple(tuple(k) for k in keys),
        hovers=tuple(tuple(h) for h in hovers),
    )
    return table, ctx, rows


def _mark(
    ctx: Context,
    rows: Sequence[Row],
    cols: Sequence[SummaryColumn],
    text: list[list[str]],
    keys: list[list[float]],
    hovers: list[list[str]],
) -> rk.TieMarks:
    """Bold each ranked column's best and its ties (:func:`locbench.report.sections.paired_tests.mark_ties`); the
    baseline,
    the bound and skipped rows are never candidates, and in a ``consistent_only`` column neither is a row whose
    ANEES is outside the band."""
    base = [not (r.bound or r.skipped or ctx.rep.col.is_baseline(r.name)) for r in rows]
    consistent = [
        ok and tb.consistency_cell(r.sub)[0].endswith("(consistent)") for ok, r in zip(base, rows, strict=True)
    ]
    runs = [r for r in rows if not (r.bound or r.skipped)]
    pad = [None] * (len(rows) - len(runs))
    tested: list[int] = []
    untested: list[int] = []
    for flags, only in ((base, False), (consistent, True)):
        columns = [
            rk.Column(k, METRICS[c.metric], [*c.samples(ctx, runs), *pad])
            for k, c in enumerate(cols)
            if c.metric is not None and c.samples is not None and c.consistent_only == only
        ]
        if columns:
            m = rk.mark_ties(text, keys, columns, flags, hovers=hovers)
            tested += m.tested
            untested += m.untested_columns
    return rk.TieMarks(tuple(sorted(tested)), tuple(sorted(untested)))


# --- the advice -------------------------------------------------------------------------------------------------


def have_text(sensors: frozenset[str], maps: frozenset[str]) -> str:
    """The sensors and map kinds a configuration needs, in words ("landmark sightings and landmark map")."""
    words = sorted(SENSOR_WORDS.get(s, s) for s in sensors) + sorted(MAP_WORDS.get(m, m) for m in maps)
    if not words:
        return f"{ODOMETRY} only"
    return words[0] if len(words) == 1 else f"{', '.join(words[:-1])} and {words[-1]}"


def _seeds(row: Row) -> int:
    """The runs (seeds) behind a configuration's row."""
    return int(tb.values(row.sub, FAILED).size)


def advice(ctx: Context, rows: Sequence[Row]) -> str:
    """Which configuration to use with what ("if you have X, use Y"), generated from the table's numbers.

    For each combination of sensors and map that some configuration needs (as it declares them, smallest first),
    the configuration with the lowest mean ATE among those that need no more, and every one the column's paired
    test (:func:`locbench.evaluate.significance.ties_with_best`, as the bold marks) does not find different from it. The
    baseline, the bound and skipped configurations are no candidates; "" when there is nothing to choose from.
    """
    col = ctx.rep.col
    cands = [r for r in rows if not (r.bound or r.skipped or col.is_baseline(r.name))]
    means = [tb.mean_of(r.sub, ATE_M) for r in cands]
    cands = [r for r, m in zip(cands, means, strict=True) if np.isfinite(m)]
    if not cands:
        return ""
    means = [tb.mean_of(r.sub, ATE_M) for r in cands]
    samples = rk.samples_for(ctx.df, [r.name for r in cands], ATE_M)
    needs = {}
    for r in cands:
        info = col.filter_info(r.name)
        needs[r.name] = (frozenset(s for s in info.sensors if s != Odometry.__name__), frozenset(info.maps))
    combos = sorted(set(needs.values()), key=lambda n: (len(n[0]) + len(n[1]), have_text(*n)))
    most = max(_seeds(r) for r in cands)
    parts: list[str] = []
    for sensors, maps in combos:
        ok = [needs[r.name][0] <= sensors and needs[r.name][1] <= maps for r in cands]
        v = sg.ties_with_best(means, samples, ok, "lower", effects=False)
        if v.best is None:
            continue
        best = cands[v.best]
        rtf = tb.mean_of(best.sub, REALTIME_FACTOR)
        tied = [cands[i].name for i in sorted(v.marked) if i != v.best]
        n = _seeds(best)
        # a pick from a sweep of fewer seeds than the table's others is less certain: say so
        fewer = f", from {n} seeds where others have up to {most}" if n < most else ""
        parts.append(
            f"with {have_text(sensors, maps)}, `{best.name}` (ATE {tb.num(100 * means[v.best])} cm, real-time "
            f"factor {tb.num(rtf)}{fewer})"
            + (" or, not found different by the paired test, " + ", ".join(f"`{t}`" for t in tied) if tied else "")
        )
    if not parts:
        return ""
    return (
        "Which to use, from this table's ATE (generated from the numbers): "
        + "; ".join(parts)
        + ". A configuration counts for every combination that holds what it needs."
    )
