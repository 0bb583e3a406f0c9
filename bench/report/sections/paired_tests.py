"""The report's statistics: ranks across datasets, the skill score, accuracy-at-threshold curves, the seed audit,
``comparisons.csv`` and the marks of the recorded tables (the ties with the best: :mod:`locbench.present.ranking`).

The tests themselves are pure functions of :mod:`locbench.evaluate.significance`; this module picks the per-run values
out of the tidy metrics and turns the results into :mod:`locbench.report.doc` blocks. It names no dataset or
filter: groups of datasets are found from which configurations ran where.
"""

from __future__ import annotations

import io
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from locbench.core.errors import LocbenchError
from locbench.core.spec import Spec
from locbench.evaluate import significance as sg
from locbench.evaluate.metrics import (
    ATE_M,
    METRICS,
    UPDATE_US_MEDIAN,
    WITHIN_FRACTION,
    WITHIN_THRESHOLDS_CM,
    member_id,
)
from locbench.present.ranking import Column, hover_grid, mark_ties, per_seed, samples_for, tie_footnote
from locbench.registry import dataset_recording
from locbench.report import figures as fg
from locbench.report import tables as tb
from locbench.report.doc import Plot, Section, Table, Text

if TYPE_CHECKING:
    from locbench.report.context import ComparisonRecord, Report
    from locbench.run.store import Store

NAN = float("nan")

#: Fewest datasets a cross-dataset rank table rests on.
MIN_DATASETS = 3
#: Fewest configurations of a rank table (Friedman's test needs 3).
MIN_CONFIGS = 3
#: Most dataset groups shown (the largest first).
MAX_GROUPS = 4

CSV_COLUMNS = (
    "dataset",
    "metric",
    "configuration",
    "reference",
    "n",
    "statistic",
    "p",
    "p_holm",
    "effect",
    "effect_low",
    "effect_high",
)


def comparisons_csv(records: Sequence[ComparisonRecord]) -> bytes:
    """The tidy pairwise results as ``comparisons.csv`` bytes (identical bytes on rerun: sorted, ``%.10g``)."""
    frame = pd.DataFrame([r.__dict__ for r in records], columns=list(CSV_COLUMNS))
    frame = frame.sort_values(["dataset", "metric", "configuration"], kind="stable")
    buf = io.StringIO()
    frame.to_csv(buf, index=False, float_format="%.10g", na_rep="nan", lineterminator="\n")
    return buf.getvalue().encode()


def effects_table(records: Sequence[ComparisonRecord], dataset: str) -> Table | None:
    """The paired effects of one dataset's comparisons, in display units (the appendix)."""
    rows: list[tuple[str, ...]] = []
    for r in records:
        if r.dataset != dataset:
            continue
        info = METRICS[r.metric]
        scale = info.scale
        eff = (
            f"{tb.num(r.effect * scale)} [{tb.num(r.effect_low * scale)}, {tb.num(r.effect_high * scale)}]"
            if not math.isnan(r.effect)
            else "n/a"
        )
        rows.append(
            (
                tb.header(r.metric),
                f"`{r.configuration}`",
                f"`{r.reference}`",
                str(r.n),
                sg.format_p(r.p),
                sg.format_p(r.p_holm),
                eff,
            )
        )
    if not rows:
        return None
    return Table(
        ("metric", "configuration", "best", "n", "p", "p (Holm)", "median paired difference [95 % bootstrap]"),
        tuple(rows),
        caption=f"`{dataset}`: each configuration against the column's best",
    )


# --- across datasets --------------------------------------------------------------------------------------


def one_per_recording(
    datasets: Sequence[str], recordings: Mapping[str, str | None]
) -> tuple[tuple[str, ...], dict[str, str]]:
    """``datasets`` with one dataset kept per recording, and each left out one -> the one kept in its place.

    A dataset's recording is ``recordings[d]`` (:meth:`locbench.datasets.dataset.DatasetBuilder.recording`; None or
    absent: a world of its own, always kept). Of the datasets that read one recording the kept one is the
    recording's own loader (its id is the recording's, as ``intel`` for the Intel Research Lab log that
    ``radish[site=intel]`` reads too), and among several such, or none, the first by name.
    """
    by_recording: dict[str, list[str]] = {}
    for d in sorted(datasets):
        rec = recordings.get(d)
        if rec is not None:
            by_recording.setdefault(rec, []).append(d)
    dropped: dict[str, str] = {}
    for rec, names in by_recording.items():
        own = [d for d in names if Spec.parse(d).ident == _recording_loader(rec)]
        keep = (own or names)[0]
        dropped.update({d: keep for d in names if d != keep})
    return tuple(d for d in datasets if d not in dropped), dropped


def _recording_loader(recording: str) -> str | None:
    """The loader id a recording name belongs to, or None for a user's file (``file <absolute path>``, which no
    loader owns)."""
    return None if recording.startswith("file ") else Spec.parse(recording).ident


def dataset_groups(
    ran: dict[str, set[str]], recordings: Mapping[str, str | None] | None = None
) -> list[tuple[tuple[str, ...], tuple[str, ...]]]:
    """Groups of datasets that a set of configurations all ran on: ``(configurations, datasets)``.

    Candidates are each dataset's own set of configurations S with every dataset on which all of S ran, one per
    recording (:func:`one_per_recording` with ``recordings``, dataset -> the recording it reads); a candidate is
    kept when it has at least :data:`MIN_CONFIGS` configurations and :data:`MIN_DATASETS` datasets and no other
    candidate has both a superset of its configurations and of its datasets. The largest (configurations x
    datasets) first, at most :data:`MAX_GROUPS`.
    """
    cands: dict[frozenset[str], frozenset[str]] = {}
    for s in {frozenset(v) for v in ran.values() if len(v) >= MIN_CONFIGS}:
        g = frozenset(one_per_recording(sorted(d for d, v in ran.items() if s <= v), recordings or {})[0])
        if len(g) >= MIN_DATASETS:
            cands[s] = g
    kept = [
        (s, g)
        for s, g in cands.items()
        if not any((s2 >= s and g2 >= g) and (s2, g2) != (s, g) for s2, g2 in cands.items())
    ]
    kept.sort(key=lambda sg_: (-len(sg_[0]) * len(sg_[1]), sorted(sg_[1]), sorted(sg_[0])))
    return [(tuple(sorted(s)), tuple(sorted(g))) for s, g in kept[:MAX_GROUPS]]


@dataclass(frozen=True)
class RankResult:
    """Average ranks of configurations over datasets, Friedman's test and Nemenyi's critical difference."""

    configs: tuple[str, ...]
    ranks: np.ndarray
    friedman: sg.TestResult
    cd: float
    n: int


def rank_result(scores: pd.DataFrame) -> RankResult | None:
    """Ranks of the columns of a (dataset x configuration) table of per-dataset means (rows with a gap dropped)."""
    m = scores.dropna(axis=0, how="any")
    if m.shape[0] < MIN_DATASETS or m.shape[1] < MIN_CONFIGS:
        return None
    a = m.to_numpy(dtype=np.float64)
    ranks = sg.average_ranks(a)
    return RankResult(
        tuple(str(c) for c in m.columns),
        ranks,
        sg.friedman(a),
        sg.critical_difference(a.shape[1], a.shape[0]),
        a.shape[0],
    )


def draw_cd(ax: Axes, res: RankResult, title: str) -> None:
    """Demsar's critical-difference diagram: average ranks on an axis (1 = best, left), a thick bar joining
    configurations whose ranks lie within the CD (not significantly different by Nemenyi), the CD drawn above."""
    k = len(res.configs)
    order = np.argsort(res.ranks, kind="stable")
    # room either side for the labels
    ax.set_xlim(0.5 - 0.35 * k, k + 0.5 + 0.35 * k)
    ax.set_ylim(-((k + 1) // 2 + 0.6), 2.0)
    ax.plot([1, k], [0, 0], color="black", lw=1)
    for r in range(1, k + 1):
        ax.plot([r, r], [0, 0.15], color="black", lw=1)
        ax.text(r, 0.3, str(r), ha="center", va="bottom", fontsize=7)
    ax.plot([1, 1 + res.cd], [1.4, 1.4], color="black", lw=1.5)
    ax.text(1 + res.cd / 2, 1.55, f"CD = {res.cd:.2f}", ha="center", va="bottom", fontsize=7)
    half = (k + 1) // 2
    for pos, i in enumerate(order):
        left = pos < half
        level = -(pos + 1) if left else -(k - pos)
        x_end = 0.6 if left else k + 0.4
        r = res.ranks[i]
        ax.plot([r, r, x_end], [0, level, level], color="#444444", lw=0.8)
        ax.text(
            x_end + (0.05 if not left else -0.05),
            level,
            f"{res.configs[i]} ({r:.2f})",
            ha="left" if not left else "right",
            va="center",
            fontsize=6.5,
        )
    for j, g in enumerate(sg.cliques(res.ranks, res.cd)):
        lo, hi = res.ranks[g[0]], res.ranks[g[-1]]
        y = -0.35 - 0.25 * j
        ax.plot([lo - 0.03, hi + 0.03], [y, y], color="#0072B2", lw=3, solid_capstyle="round")
    ax.set_axis_off()
    ax.set_title(title, fontsize=8)


def _means_table(report: Report, datasets: Sequence[str], configs: Sequence[str], metric: str) -> pd.DataFrame:
    data = {}
    for d in datasets:
        sub = report.rows(d)
        data[d] = {f: tb.mean_of(sub[sub["filter"] == f], metric) for f in configs}
    return pd.DataFrame.from_dict(data, orient="index", columns=list(configs))


def skill_scores(report: Report, datasets: Sequence[str], config: str, baseline: str) -> list[np.ndarray]:
    """Per dataset (a stratum), the skill 1 - ATE / ATE(baseline) of each seed both ran."""
    out = []
    for d in datasets:
        sub = report.rows(d)
        mine = per_seed(sub[sub["filter"] == config], ATE_M)
        ref = per_seed(sub[sub["filter"] == baseline], ATE_M)
        seeds = sorted(set(mine) & set(ref))
        if seeds:
            out.append(sg.skill([mine[s] for s in seeds], [ref[s] for s in seeds]))
    return out


def within_curve(report: Report, datasets: Sequence[str], config: str) -> np.ndarray:
    """Per threshold, the mean over datasets of the mean over runs of ``within_<k>cm_fraction``."""
    per = []
    for d in datasets:
        sub = report.rows(d)
        sub = sub[sub["filter"] == config]
        row = [tb.mean_of(sub, member_id(WITHIN_FRACTION, k)) for k in WITHIN_THRESHOLDS_CM]
        if not any(math.isnan(x) for x in row):
            per.append(row)
    return np.mean(np.array(per), axis=0) if per else np.full(len(WITHIN_THRESHOLDS_CM), NAN)


def _iqm_rows(a: np.ndarray) -> np.ndarray:
    return np.asarray(sg.iqm(a, axis=1))


def across_datasets(report: Report) -> Section:
    """Rank tables with Friedman and Nemenyi, critical-difference diagrams, the skill score and accuracy at
    thresholds, for each group of datasets that a set of configurations all ran on."""
    sec = Section("Across datasets", "across")
    col = report.col
    ran: dict[str, set[str]] = {}
    for d in sorted(col.datasets):
        if not math.isnan(report.kidnap_distance(d)):
            continue
        sub = report.rows(d)
        ran[d] = {f for f in report.filters_on(d) if tb.values(sub[sub["filter"] == f], ATE_M).size}
    recordings = {d: _recording(d) for d in ran}
    groups = dataset_groups(ran, recordings)
    if not groups:
        return sec
    sec.add(
        Text(
            "Which configuration is best over many datasets? For each group of datasets that a set of "
            "configurations all ran on (kidnap variants left out): the average rank of each configuration's mean "
            "ATE and mean update-call median over the datasets (1 = best), Friedman's test that all rank equally, "
            "and Nemenyi's critical difference CD (Demsar 2006): two configurations whose average ranks differ by "
            "less than the CD are not significantly different (joined by a bar in the diagram). Skill: 1 - ATE / "
            "ATE(dead reckoning) on the same seed (1 = no error, 0 = no better than dead reckoning), so no "
            "large-error dataset dominates; its interquartile mean over every (dataset, seed) with a "
            "stratified-bootstrap 95 % interval (seeds resampled within each dataset; Agarwal et al. 2021). "
            "Within: the fraction of ground-truth times with position error at most each threshold, mean over "
            "runs and then datasets. Each recording counts once: of datasets that read the same recording (the "
            "loaders declare which) a group keeps the recording's own loader, else the first by name, and says "
            "which it left out."
        )
    )
    for gi, (configs, datasets) in enumerate(groups, start=1):
        # the datasets all of the group's configurations ran on that the group left out as another's recording
        ran_all = sorted(d for d, v in ran.items() if set(configs) <= v)
        dropped = one_per_recording(ran_all, recordings)[1]
        sec.children.append(_group_section(report, gi, configs, datasets, dropped))
    return sec


def _recording(name: str) -> str | None:
    """The recording a stored dataset name reads, or None (a synthetic world, or a name the registry does not
    know: a plugin's dataset, counted as its own)."""
    try:
        return dataset_recording(name)
    except LocbenchError:
        return None


def _group_section(
    report: Report, gi: int, configs: Sequence[str], datasets: Sequence[str], dropped: Mapping[str, str]
) -> Section:
    # long: one across-datasets section: rank tables, both CD diagrams and the skill table share its data
    col = report.col
    configs = col.filter_order(configs)
    baseline = next((f for f in configs if col.is_baseline(f)), None)
    ate = rank_result(_means_table(report, datasets, configs, ATE_M))
    upd_cfg = [
        f
        for f in configs
        if all(tb.values(report.rows(d)[report.rows(d)["filter"] == f], UPDATE_US_MEDIAN).size for d in datasets)
    ]
    upd = rank_result(_means_table(report, datasets, upd_cfg, UPDATE_US_MEDIAN))
    names = ", ".join(f"`{col.display(d)}`" for d in datasets)
    left_out = "; ".join(f"`{col.display(d)}` (reads `{col.display(k)}`'s recording)" for d, k in dropped.items())
    same = f" Left out as duplicates of a recording: {left_out}." if dropped else ""
    blocks: list[Any] = [Text(f"{len(datasets)} datasets: {names}.{same}")]
    rows: list[tuple[str, ...]] = []
    keys: list[tuple[float, ...]] = []
    curves: dict[str, np.ndarray] = {}
    for f in configs:
        r_ate = float(ate.ranks[ate.configs.index(f)]) if ate and f in ate.configs else NAN
        r_upd = float(upd.ranks[upd.configs.index(f)]) if upd and f in upd.configs else NAN
        if baseline is not None and f != baseline:
            strata = skill_scores(report, datasets, f, baseline)
            val, lo, hi = sg.stratified_bootstrap(strata, _iqm_rows)
            n_sk = sum(s.size for s in strata)
            sk_text, sk_key = (f"{val:.3f} [{lo:.3f}, {hi:.3f}] (n={n_sk})", val) if strata else ("n/a", NAN)
        else:
            sk_text, sk_key = "-", NAN
        curve = within_curve(report, datasets, f)
        curves[f] = curve
        rows.append(
            (
                f"`{f}`",
                tb.num(r_ate),
                tb.num(r_upd),
                sk_text,
                *(tb.num(100 * x) for x in curve),
            )
        )
        keys.append((NAN, r_ate, r_upd, sk_key, *(100 * x for x in curve)))
    head = (
        "configuration",
        "average rank, ATE",
        "average rank, update median",
        "skill IQM [95 % CI]",
        *(f"within {k} cm (%)" for k in WITHIN_THRESHOLDS_CM),
    )
    notes = []
    for label, res in (("ATE", ate), ("update median", upd)):
        if res is None:
            notes.append(f"{label}: too few datasets or configurations with values for a rank test.")
            continue
        groups = sg.cliques(res.ranks, res.cd)
        tied = "; ".join(", ".join(f"`{res.configs[i]}`" for i in g) for g in groups) or "none"
        notes.append(
            f"{label}: Friedman chi2 = {res.friedman.statistic:.2f} over {res.n} datasets and "
            f"{len(res.configs)} configurations, p = {sg.format_p(res.friedman.p)}; Nemenyi CD = {res.cd:.2f} "
            f"at {100 * sg.ALPHA:.0f} %; groups not significantly different: {tied}."
        )
    blocks.append(
        Table(
            head,
            tuple(rows),
            caption=f"Group {gi}: ranks, skill and accuracy at thresholds",
            footnotes=tuple(notes),
            sort_keys=tuple(keys),
        )
    )
    panels = [(lab, r) for lab, r in (("ATE", ate), ("update median", upd)) if r is not None]
    if panels:

        def draw(fig: Figure) -> None:
            axes = fig.subplots(len(panels), 1, squeeze=False)
            for ax, (lab, r) in zip(axes[:, 0], panels, strict=True):
                draw_cd(ax, r, f"group {gi}: average rank of {lab} over {r.n} datasets (Nemenyi, 5 %)")

        k = max(len(r.configs) for _, r in panels)
        blocks.append(
            Plot(
                f"across_{gi}_critical_difference",
                f"Group {gi}: critical-difference diagrams (ATE, update median)",
                draw,
                size=(7.5, (0.28 * k + 1.6) * len(panels)),
            )
        )
    shown = [f for f in configs if not np.all(np.isnan(curves[f]))]
    if shown:
        thresholds = np.array(WITHIN_THRESHOLDS_CM, dtype=np.float64)

        def draw_within(fig: Figure) -> None:
            ax = fig.add_subplot()
            for f in shown:
                st = report.palette.style(f)
                ax.plot(thresholds, 100 * curves[f], color=st.color, marker=st.marker, ls=st.linestyle, label=f, lw=1)
            ax.set_xscale("log")
            ax.minorticks_off()
            ax.set_xticks(thresholds, [f"{k:g}" for k in thresholds])
            ax.set_ylim(0, 102)
            title = f"group {gi}: accuracy at thresholds, mean over runs and datasets"
            fg.finish(ax, "position error threshold (cm)", "ground-truth times within (%)", title, absent=missing)

        missing = {f: "no finite error on these datasets" for f in configs if f not in shown}
        caption = f"Group {gi}: accuracy at thresholds"
        blocks.append(Plot(f"across_{gi}_within", caption, draw_within, shows=tuple(configs)))
    return Section(f"Group {gi}: {len(configs)} configurations on {len(datasets)} datasets", f"across-{gi}", blocks)


# --- seed audit -------------------------------------------------------------------------------------------


def seed_audit(report: Report, datasets: Sequence[str]) -> Section:
    """Each main configuration's ATE spread over seeds: runs, median, 90th percentile, worst seed and its value."""
    sec = Section("Seed audit", "seed-audit")
    sec.add(
        Text(
            "Every suite fixes its seeds in advance (0..N-1, the provenance lists them) and every table's `runs` "
            "column says how many runs a cell rests on; no run is repeated to find a better seed set. The ATE "
            "spread over seeds of each main configuration: median, 90th percentile and the worst seed."
        )
    )
    for d in datasets:
        rows = []
        for f in report.filters_on(d):
            sub = report.rows(d)
            sub = sub[sub["filter"] == f]
            v = per_seed(sub, ATE_M)
            if not v:
                continue
            seeds = np.array(sorted(v))
            med, p90, worst, seed = sg.spread([v[s] for s in seeds], seeds)
            rows.append((f"`{f}`", str(len(v)), tb.num(100 * med), tb.num(100 * p90), tb.num(100 * worst), str(seed)))
        if rows:
            sec.add(
                Table(
                    (
                        "configuration",
                        "runs",
                        "median ATE (cm)",
                        "90th percentile (cm)",
                        "worst ATE (cm)",
                        "worst seed",
                    ),
                    tuple(rows),
                    caption=f"`{d}`: ATE over seeds",
                )
            )
    return sec


# --- the summary's per-run ratio to the bound ------------------------------------------------------------


def ratio_per_seed(df: pd.DataFrame, config: str, bound: str) -> dict[int, float]:
    """seed -> ATE / the bound's ATE on that seed (the per-run value behind the ATE / PCRB column)."""
    mine = per_seed(df[df["filter"] == config], ATE_M)
    ref = per_seed(df[df["filter"] == bound], ATE_M)
    return {s: mine[s] / ref[s] for s in mine if s in ref and ref[s] > 0}


def mark_grid(
    report: Report,
    filters: Sequence[str],
    datasets: Sequence[str],
    cells: Sequence[Sequence[tuple[str, float]]],
    metric_of: Callable[[str], str],
) -> tuple[list[list[str]], str, tuple[tuple[str, ...], ...]]:
    """A (configuration x dataset) table whose columns are datasets (the recorded data): each column's best and
    its ties in bold, as text cells, with the footnote that applies and the cells' hovers (paired effects)."""
    rows = [[f"`{f}`", *(c[0] for c in r)] for f, r in zip(filters, cells, strict=True)]
    keys = [[NAN, *(c[1] for c in r)] for r in cells]
    columns = [
        Column(j + 1, METRICS[metric_of(d)], samples_for(report.rows(d), filters, metric_of(d)))
        for j, d in enumerate(datasets)
    ]
    hovers = hover_grid(rows)
    marks = mark_ties(rows, keys, columns, report.eligible(list(filters)), hovers=hovers)
    return rows, tie_footnote(marks), tuple(tuple(h) for h in hovers)


def appendix_sections(report: Report, datasets: Sequence[str]) -> list[Section]:
    """The appendix's paired effects of the summary datasets' comparisons and the seed audit."""
    eff = Section("Paired comparisons", "paired")
    eff.add(
        Text(
            "Every configuration of the summary tables against its column's best over the seeds both share: "
            "the two-sided Wilcoxon signed-rank p-value, Holm-corrected within the column, and the paired effect "
            "(median of the per-seed differences, configuration minus best, in the column's units) with its 95 % "
            "percentile-bootstrap interval. Every dataset's comparisons are in `comparisons.csv` (SI units)."
        )
    )
    for d in datasets:
        t = effects_table(report.comparisons, d)
        if t is not None:
            eff.add(t)
    return [eff, seed_audit(report, datasets)]


def verify_line(store: Store) -> str:
    """The provenance line of the last ``locbench verify`` on this store (:mod:`locbench.run.verify`)."""
    from locbench.run.verify import read_record, record_text, store_digest, stored_runs

    return record_text(read_record(store.root), store_digest(r.run_key for r in stored_runs(store)))
