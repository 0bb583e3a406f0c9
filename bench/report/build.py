"""The report's sections, in reading order, built from the collected runs and the registered experiments.

Order: how to read this, summary tables (one per summary experiment), claims, accuracy against runtime,
consistency, kidnap and global localization, recorded data, one section per experiment, appendix (detail
tables, failed and skipped runs, provenance). Which datasets are main comparisons, which sections and
claims an experiment has, comes from :mod:`locbench.claims`; the report names no dataset or filter.
"""

from __future__ import annotations

from collections import defaultdict
from functools import cached_property

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

import locbench
from locbench.claims import Experiment, all_claims, experiments, sections_for, waypoint_stats
from locbench.lost import LOST_THRESHOLDS_M
from locbench.metrics import CONFIDENCE, METRICS, POSE_DOF, chi2_band, estimate_at, mean_over_runs
from locbench.pcrb import BOUND_ROWS
from locbench.report import figures as fg
from locbench.report import health as hl
from locbench.report import interactive as ia
from locbench.report import significance as sig
from locbench.report import tables as tb
from locbench.report.collect import Collected
from locbench.report.doc import Bullets, Plot, Section, Table, Text
from locbench.report.palette import Palette, split_by_sweep
from locbench.report.reference import INDEPENDENT_KINDS, KINDS, kind_caption, robustness_table, semi_synthetic
from locbench.report.reference import reference_kind as _reference_kind
from locbench.report.style import LINESTYLES, LineStyle
from locbench.report.tuning import tuning_section
from locbench.spec import Spec

#: The kidnap protocol's dataset parameter (DESIGN "Kidnap recovery"): variants differing only in it form one
#: recovery-against-distance curve.
KIDNAP_PARAM = "kidnap_m"
#: The protocol's parameter of model-matched worlds: the simulator's noise is the filters' nominal noise.
MATCHED_PARAM = "matched"
#: The kidnap distance whose recovery rate the summary table shows, m.
SUMMARY_KIDNAP_M = 2.0
#: Most panels of one trajectory figure before it is split into defaults and one figure per sweep.
MAX_TRACK_PANELS = 12
#: Most series of one NEES or waypoint figure before it is split the same way.
MAX_LINE_SERIES = 10
#: Ellipses drawn along each track.
ELLIPSES_PER_TRACK = 10
NAN = float("nan")


class Report:
    """Builds the sections from one :class:`Collected`; styles are fixed per filter for every figure."""

    def __init__(self, col: Collected) -> None:
        self.col = col
        self.df = col.metrics
        # claims read the filters' rows only (a claim is about filters; the bound is no candidate)
        self.filter_df = self.df[~self.df["filter"].isin(BOUND_ROWS)] if len(self.df) else self.df
        self.by_ds: dict[str, pd.DataFrame] = {str(d): g for d, g in self.df.groupby("dataset")} if len(self.df) else {}
        self.exps = [e for e in experiments() if self._has(e.dataset)]

    @cached_property
    def comparisons(self) -> list[sig.ComparisonRecord]:
        """Every dataset's paired comparisons with the best (``comparisons.csv``)."""
        return sig.all_comparisons(self)

    # --- helpers ------------------------------------------------------------------------------------

    @cached_property
    def palette(self) -> Palette:
        """One style per configuration for every figure: a colour and marker per filter id, shades for sweeps."""
        names = {r.filter for r in self.col.runs}
        return Palette(names, self.col.filter_order(names))

    def styles_for(self, names: list[str]) -> dict[str, LineStyle]:
        """The palette's styles of a figure's series (the same in every figure)."""
        return self.palette.styles(names)

    def _has(self, dataset_id: str) -> bool:
        return any(info.spec.ident == dataset_id for info in self.col.datasets.values())

    def rows(self, dataset: str) -> pd.DataFrame:
        return self.by_ds.get(dataset, self.df.iloc[0:0])

    def filters_on(self, dataset: str, global_start: bool = False) -> list[str]:
        sub = self.rows(dataset)
        names = {str(f) for f in sub["filter"].unique()} if len(sub) else set()
        return self.col.filter_order(
            {f for f in names if self.col.is_global(f) == global_start and not self.col.is_bound(f)}
        )

    def eligible(self, filters: list[str]) -> list[bool]:
        """Which rows may be marked best: all but the baseline."""
        return [not self.col.is_baseline(f) for f in filters]

    def bounds_on(self, dataset: str) -> list[str]:
        """The bound's rows stored for a dataset name (synthetic, not kidnapped), in their fixed order."""
        sub = self.rows(dataset)
        present = {str(f) for f in sub["filter"].unique()} if len(sub) else set()
        return [b for b in BOUND_ROWS if b in present]

    def bound_styles(self, names: list[str]) -> dict[str, LineStyle]:
        """Styles of a figure's series; the bound's rows in black, dashed, without markers."""
        filters = [n for n in names if not self.col.is_bound(n)]
        out = self.styles_for(filters)
        for i, b in enumerate(n for n in names if self.col.is_bound(n)):
            out[b] = LineStyle("#000000", "", ("--", ":")[i % 2])
        return out

    def split(self, names: list[str], limit: int) -> list[tuple[str, list[str]]]:
        """A crowded figure's configurations as the defaults and one group per sweep (:func:`split_by_sweep`)."""
        return split_by_sweep(names, limit)

    def variants_of(self, dataset_id: str) -> list[str]:
        return sorted(n for n, info in self.col.datasets.items() if info.spec.ident == dataset_id)

    def kidnap_distance(self, dataset: str) -> float:
        v = tb.values(self.rows(dataset), "kidnap_distance_m")
        return float(np.median(v)) if v.size else NAN

    def recorded(self) -> list[str]:
        return [n for n, info in sorted(self.col.datasets.items()) if info.recorded]

    def ground_truth(self, dataset: str) -> bool:
        return all(tr.truth_label == "ground truth" for (d, _), tr in self.col.truths.items() if d == dataset)

    def _truth_meta(self, dataset: str) -> tuple[str, dict, str]:
        for (d, _), tr in sorted(self.col.truths.items()):
            if d == dataset:
                return str(tr.meta.get("dataset_id", "")), dict(tr.meta.get("metadata", {}) or {}), tr.truth_label
        return self.col.datasets[dataset].spec.ident if dataset in self.col.datasets else "", {}, "ground truth"

    def reference_kind(self, dataset: str) -> str:
        """Motion capture, GPS, survey, not stated, SLAM or simulation (:mod:`locbench.report.reference`)."""
        ident, meta, label = self._truth_meta(dataset)
        return _reference_kind(ident or self.col.datasets[dataset].spec.ident, meta, label)

    def _recorded_header(self, dataset: str) -> str:
        semi = " (semi-synthetic)" if semi_synthetic(self._truth_meta(dataset)[1]) else ""
        return f"`{self.col.display(dataset)}`{semi}"

    # --- sections -------------------------------------------------------------------------------------

    def sections(self) -> list[Section]:
        out = [
            self.summary(),
            sig.across_datasets(self),
            tuning_section(self.col) or Section("", ""),
            self.claims(),
            self.pareto(),
            self.consistency(),
            hl.lost_section(self),
            self.kidnap_and_global(),
            self.recorded_data(),
            *[self.experiment(e) for e in self.exps],
            self.appendix(),
        ]
        return [s for s in out if s.blocks or s.children]

    def how_to_read(self) -> list[str]:
        return [
            "locbench runs every localization filter on the same synthetic worlds and recorded datasets and "
            "measures them the same way. Start with the **summary** tables: one row per filter configuration on "
            "each main comparison, errors in cm, times in us; in bold the best value of each column and every "
            "configuration a paired test over the seeds does not find different from it (the dead-reckoning "
            "baseline is never marked). Then the ranks **across datasets**, the **claims** of the five source reports, "
            "each with its verdict and the measured value; the **accuracy against runtime** fronts (lower and "
            "further right is better); **consistency** (does a filter's covariance describe its error?); kidnap "
            "recovery; the recorded data; and one section per experiment. Values are means over seeds; the "
            f"appendix gives every dataset's table with {100 * CONFIDENCE:.0f} % Student-t intervals. What every "
            "metric means: `docs/protocols.md` in the repository.",
        ]

    def summary(self) -> Section:
        sec = Section("Summary", "summary")
        for e in self.exps:
            if e.summary and e.dataset in self.col.datasets:
                sec.children.append(Section(f"{e.title}", f"summary-{e.dataset}", [self.summary_table(e.dataset)]))
        return sec

    def _kidnap_variant(self, dataset: str) -> str | None:
        base = self.col.datasets[dataset].spec
        for n in self.variants_of(base.ident):
            spec = self.col.datasets[n].spec
            if spec.without(KIDNAP_PARAM) == base and np.isclose(self.kidnap_distance(n), SUMMARY_KIDNAP_M):
                return n
        return None

    def _kidnap_config(self, filter_name: str, candidates: list[str]) -> str | None:
        """The configuration's own kidnap configuration: the one its class declares (``Filter.kidnap_params``
        added to its parameters) when it was run, else its id with every parameter it sets and the fewest more
        (``f`` -> ``f[recovery=on]``, ``f[a=1]`` -> ``f[a=1,recovery=on]``), if exactly one is that close."""
        declared = self.col.filters[filter_name].kidnap_name
        if declared is not None and declared in candidates:
            return declared
        spec = self.col.filters[filter_name].spec
        mine = set(spec.params)
        fits = [
            (len(self.col.filters[c].spec.params), c)
            for c in candidates
            if self.col.filters[c].spec.ident == spec.ident and mine <= set(self.col.filters[c].spec.params)
        ]
        if not fits:
            return None
        fewest = min(n for n, _ in fits)
        best = [c for n, c in fits if n == fewest]
        return best[0] if len(best) == 1 else None

    def _recorded_ate(self, filter_name: str) -> tuple[float, int]:
        per = []
        for ds in self.recorded():
            if not self.ground_truth(ds) or self.reference_kind(ds) not in INDEPENDENT_KINDS:
                continue
            sub = self.rows(ds)
            v = tb.values(sub[sub["filter"] == filter_name], "ate_m")
            if v.size:
                per.append(float(np.mean(v)))
        return (100.0 * float(np.median(per)), len(per)) if per else (NAN, 0)

    def summary_table(self, dataset: str) -> Table:
        df = self.rows(dataset)
        filters = self.filters_on(dataset)
        wp = tb.waypoint_rmse_mean(df)
        kid = self._kidnap_variant(dataset)
        kdf = self.rows(kid) if kid else df.iloc[0:0]
        kfilters = self.filters_on(kid) if kid else []
        rows: list[list[str]] = []
        keys: list[list[float]] = []
        notes: list[str] = []
        substituted: dict[str, str] = {}
        knames: list[str | None] = []
        for f in filters:
            sub = df[df["filter"] == f]
            runs = int(tb.values(sub, "failed").size)
            ate = tb.mean_of(sub, "ate_m") * 100.0
            wpm = wp.get(f, NAN) * 100.0
            head = tb.mean_of(sub, "heading_rmse_rad") * METRICS["heading_rmse_rad"].scale
            an_text, an_key, _, _ = tb.consistency_cell(sub)
            es = tb.mean_of(sub, "energy_score_m") * METRICS["energy_score_m"].scale
            upd = tb.mean_of(sub, "update_us_median")
            rtf = tb.mean_of(sub, "realtime_factor")
            # the kidnap runs of this configuration, or of its filter's one kidnap configuration
            kname = f if f in kfilters else self._kidnap_config(f, kfilters)
            knames.append(kname)
            if kname is not None and kname != f:
                substituted[f] = kname
            # lost detection where a filter does get lost: its kidnap configuration on the kidnapped world
            # (a configuration without kidnap runs has none, so the column means one thing throughout)
            if kid:
                lost_auc = hl.best_auroc(self.col, kid, kname) if kname is not None else NAN
            else:
                lost_auc = hl.best_auroc(self.col, dataset, f)
            if kname is not None:
                _, n_k, r_k, _, _ = tb.rate(kdf[kdf["filter"] == kname], "kidnap_recovered")
                k_text = f"{100 * r_k:.0f} ({n_k})" + ("²" if kname != f else "") if n_k else "n/a"
                k_key = 100 * r_k if n_k else NAN
            else:
                k_text, k_key = "-", NAN
            rec, n_rec = self._recorded_ate(f)
            eff = tb.ate_over_bound(df, f)
            rows.append(
                [
                    f"`{f}`",
                    str(runs),
                    tb.num(ate),
                    tb.num(eff),
                    tb.num(wpm),
                    tb.num(head),
                    an_text,
                    tb.num(es),
                    tb.num(lost_auc) if not np.isnan(lost_auc) else "-",
                    tb.num(upd) if not np.isnan(upd) else "-",
                    tb.num(rtf),
                    k_text,
                    f"{tb.num(rec)} ({n_rec})" if n_rec else "-",
                ]
            )
            keys.append([NAN, float(runs), ate, eff, wpm, head, an_key, es, lost_auc, upd, rtf, k_key, rec])
        eligible = [not self.col.is_baseline(f) for f in filters]
        bounds = self.bounds_on(dataset)
        for b in bounds:
            sub = df[df["filter"] == b]
            ate = tb.mean_of(sub, "ate_m") * 100.0
            wpm = wp.get(b, NAN) * 100.0
            head = tb.mean_of(sub, "heading_rmse_rad") * METRICS["heading_rmse_rad"].scale
            runs = tb.run_count(sub)
            rows.append([f"`{b}`", str(runs), tb.num(ate), "-", tb.num(wpm), tb.num(head), *["-"] * 7])
            keys.append([NAN, float(runs), ate, NAN, wpm, head, *[NAN] * 7])
            eligible.append(False)
        hovers = sig.hover_grid(rows)
        marks = sig.mark_ties(
            rows, keys, sig.summary_columns(self, dataset, filters, len(bounds), kid, knames), eligible, hovers=hovers
        )
        notes.append(sig.tie_footnote(marks))
        runs_all = [int(tb.values(df[df["filter"] == f], "failed").size) for f in filters]
        n_typ = max(set(runs_all), key=runs_all.count) if runs_all else 0
        notes.append(
            f"ANEES: mean over runs of each run's average NEES (heading wrapped), against the two-sided 95 % "
            f"chi-square band for the run count ({band_for(n_typ)} for {n_typ} runs); closest to "
            f"{POSE_DOF} is marked best."
        )
        notes.append(
            "Energy score: proper score of the filter's own position belief, mean over the ground-truth times "
            f"(lower is better). Lost AUROC: how well the filter's best health signal separates the times its "
            f"position error exceeds {LOST_THRESHOLDS_M[0]:g} m from the others (1 perfect, 0.5 chance; '-': never "
            "lost, or no kidnap runs)"
            + (f", on `{kid}` with the kidnap configuration as for kidnap recovery" if kid else "")
            + '; see "Does the filter know that it is lost?".'
        )
        if bounds:
            notes.append(tb.BOUND_FOOTNOTE)
        if any("¹" in r[6] for r in rows):
            notes.append(tb.COLLAPSE_FOOTNOTE)
        if kid:
            notes.append(
                f"Kidnap recovery: percentage of the runs of `{kid}` that recovered (run count in brackets)."
                + (
                    " ² The filter's kidnap configuration: "
                    + ", ".join(f"`{a}` -> `{b}`" for a, b in sorted(substituted.items()))
                    + "."
                    if substituted
                    else ""
                )
            )
        notes.append(
            "Recorded median ATE: median over the recorded datasets with independent ground truth (motion capture, "
            "GPS, survey or a stated truth; never a SLAM reference or a simulated world) that this configuration "
            "ran on (their number in brackets) of its mean ATE there."
        )
        columns = (
            "filter",
            "runs",
            "ATE (cm)",
            tb.header("ate_over_pcrb"),
            "mean waypoint RMSE (cm)",
            "heading RMSE (deg)",
            "ANEES (verdict)",
            "energy score (cm)",
            f"lost AUROC ({LOST_THRESHOLDS_M[0]:g} m{f', {SUMMARY_KIDNAP_M:g} m kidnap' if kid else ''})",
            "update median (us)",
            "real-time factor (x)",
            f"kidnap recovery at {SUMMARY_KIDNAP_M:g} m (%)",
            "recorded median ATE (cm)",
        )
        return Table(
            columns,
            tuple(tuple(r) for r in rows),
            caption=f"`{dataset}`: mean over seeds",
            footnotes=tuple(notes),
            sort_keys=tuple(tuple(k) for k in keys),
            hovers=tuple(tuple(h) for h in hovers),
        )

    def claims(self) -> Section:
        sec = Section("Claims of the source reports", "claims")
        rows: list[tuple[str, ...]] = []
        counts: dict[str, int] = defaultdict(int)
        for c in all_claims():
            if not self._has(c.dataset):
                continue
            if c.across_variants:
                df = self.filter_df[self.filter_df["dataset"].isin(self.variants_of(c.dataset))]
            else:
                df = self.rows(c.dataset)
            res = c.evaluate(df)
            counts[res.verdict] += 1
            rows.append((c.source.citation, c.text, f"**{res.verdict}**", res.measured, res.test or "-", c.reported))
        if not rows:
            return sec
        sec.add(
            Text(
                "Every claim of the five source reports that locbench checks, once, on the experiment it concerns. "
                "A claim that does not reproduce is reported with the measured value; no filter was tuned to make "
                "one pass. A claim that compares two filters or settings names its test, the number of runs and the "
                'p-value; its verdict follows the rule of docs/protocols.md ("no worse": the one-sided test does not '
                "find the other better at 5 %; a difference: the test finds it at 5 %). "
                + ", ".join(f"{n} {v}" for v, n in sorted(counts.items()))
                + "."
            ),
            Table(("report", "claim", "verdict", "measured", "test (n, p)", "the report's value"), tuple(rows)),
        )
        return sec

    # --- accuracy against runtime --------------------------------------------------------------------------

    def _pareto_points(self, dataset: str, metric: str) -> list[fg.ParetoPoint]:
        df = self.rows(dataset)
        pts = []
        for f in self.filters_on(dataset):
            sub = df[df["filter"] == f]
            x, y = tb.mean_of(sub, "realtime_factor"), tb.mean_of(sub, metric) * METRICS[metric].scale
            if np.isfinite(x) and np.isfinite(y) and x > 0 and y > 0:
                pts.append(fg.ParetoPoint(f, self.col.filters[f].spec.ident, x, y))
        return pts

    def pareto(self) -> Section:
        sec = Section("Accuracy against runtime", "pareto")
        sec.add(
            Text(
                "Each marker is one filter configuration (mean over seeds): x is the real-time factor (dataset "
                "duration over compute time, higher is faster), y the ATE (lower is better), both logarithmic. "
                "A line joins each filter's own non-dominated configurations (a parameter sweep draws its "
                "curve); the dotted step is the front over all of them. Runs started without a pose are left out."
            )
        )
        for e in self.exps:
            if not e.summary or e.dataset not in self.col.datasets:
                continue
            pts = self._pareto_points(e.dataset, "ate_m")
            if pts:
                sec.add(self._pareto_plot(f"{slug(e.dataset)}_pareto", e.dataset, [(e.dataset, "ATE (cm)", pts)]))
        rec = [
            (self.col.display(d), tb.header(self._recorded_metric(d)), self._pareto_points(d, self._recorded_metric(d)))
            for d in self.recorded()
        ]
        rec = [r for r in rec if r[2]]
        if rec:
            sec.add(self._pareto_plot("recorded_pareto", "recorded data", rec))
        return sec

    def _pareto_plot(self, name: str, title: str, panels: list[tuple[str, str, list[fg.ParetoPoint]]]) -> Plot:
        pts_all = [p for _, _, pts in panels for p in pts]
        styles = self.styles_for(sorted({p.group for p in pts_all} | {p.label for p in pts_all}))

        def draw(fig: Figure) -> None:
            n = len(panels)
            ncols = 1 if n == 1 else 3
            nrows = int(np.ceil(n / ncols))
            axes = fig.subplots(nrows, ncols, squeeze=False)
            for k, ax in enumerate(axes.flat):
                if k >= n:
                    ax.set_axis_off()
                    continue
                label, ylabel, pts = panels[k]
                fg.draw_pareto(ax, pts, styles, "real-time factor (x)", ylabel, label, per_config=n == 1)
                if n > 1:
                    leg = ax.get_legend()
                    if leg is not None:
                        leg.remove()
                    ax.legend(fontsize=5.5, loc="best")

        size = (7.0, 4.2) if len(panels) == 1 else (11.0, 3.2 * int(np.ceil(len(panels) / 3)))
        interactive = (
            ia.pareto(f"{title}: ATE against real-time factor", panels[0][2], styles, panels[0][1])
            if len(panels) == 1
            else None
        )
        what = "accuracy" if len(panels) > 1 else "ATE"
        return Plot(name, f"{title}: {what} against real-time factor", draw, size=size, interactive=interactive)

    def _recorded_metric(self, dataset: str) -> str:
        if (self.rows(dataset)["metric"] == "relation_error_m").any():
            return "relation_error_m"
        return "ate_m"

    # --- consistency ---------------------------------------------------------------------------------

    def consistency(self) -> Section:
        sec = Section("Consistency", "consistency")
        pairs: list[tuple[str, str]] = []
        alone: list[str] = []
        for e in self.exps:
            if e.fold_variants or e.dataset not in self.col.datasets:
                continue
            # the shipped world beside its model-matched twin (DESIGN "Model-matched worlds")
            twin = Spec(e.dataset, ((MATCHED_PARAM, "true"),)).name
            if twin in self.col.datasets:
                pairs.append((e.dataset, twin))
            else:
                alone.append(e.dataset)
        alone += self.recorded()
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
            table, inf = self._shipped_matched_table(shipped, twin)
            collapsed |= inf
            sec.add(table)
            sec.add(*self.nees_plots(twin))
        rows: list[tuple[str, ...]] = []
        keys: list[tuple[float, ...]] = []
        for ds in alone:
            for f in self.filters_on(ds):
                cells, ckeys, inf = self._consistency_cells(ds, f)
                if cells is None:
                    continue
                collapsed |= inf
                rows.append((f"`{self.col.display(ds)}`", f"`{f}`", *cells))
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

    def _consistency_cells(self, dataset: str, f: str) -> tuple[tuple[str, ...] | None, tuple[float, ...], bool]:
        """``runs, band, ANEES, time in band, NLL`` of one (dataset, filter), their sort keys and whether a run
        collapsed; None when it has no NEES."""
        sub = self.rows(dataset)
        sub = sub[sub["filter"] == f]
        text, key, inf, n = tb.consistency_cell(sub)
        if n == 0:
            return None, (), False
        inband = tb.mean_of(sub, "nees_in_band_fraction") * 100.0
        nll = tb.mean_of(sub[np.isfinite(sub["value"]) | (sub["metric"] != "nll")], "nll")
        es = tb.mean_of(sub, "energy_score_m") * METRICS["energy_score_m"].scale
        cx, cy = (tb.mean_of(sub, m) * METRICS[m].scale for m in ("crps_x_m", "crps_y_m"))
        ch = tb.mean_of(sub, "crps_heading_rad") * METRICS["crps_heading_rad"].scale
        crps = f"{tb.num(cx)} / {tb.num(cy)} / {tb.num(ch)}"
        cells = (str(n), tb.band_text(n), text, tb.num(inband), tb.num(nll), tb.num(es), crps)
        return cells, (float(n), NAN, key, inband, nll, es, NAN), inf > 0

    def _shipped_matched_table(self, shipped: str, twin: str) -> tuple[Table, bool]:
        """One row per filter: ANEES, NLL and ATE / PCRB on the shipped world and on its model-matched twin."""
        rows: list[tuple[str, ...]] = []
        keys: list[tuple[float, ...]] = []
        collapsed = False
        # the configurations run on the twin (the consistency suite's), not every sweep of the shipped world
        for f in self.filters_on(twin):
            row: list[str] = [f"`{f}`"]
            key: list[float] = [NAN]
            for ds in (shipped, twin):
                cells, ckeys, inf = self._consistency_cells(ds, f)
                collapsed |= inf
                eff = tb.ate_over_bound(self.rows(ds), f)
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

    # --- kidnap and global -----------------------------------------------------------------------------

    def kidnap_and_global(self) -> Section:
        sec = Section("Kidnap and global localization", "kidnap")
        kid = [n for n in self.col.datasets if not np.isnan(self.kidnap_distance(n))]
        if kid:
            sec.add(
                Text(
                    "After the first kidnap of a run (a silent jump of the truth by D), a filter has recovered when "
                    "its position error is <= 0.25 m and its heading error <= 0.25 rad at every ground-truth time "
                    "for 2 s, starting within 30 s of the kidnap. Each cell: recovered runs / runs (a failed run "
                    "counts as not recovered); the figures draw the rate with its 95 % Wilson interval. False "
                    "confidence: the share of the time before recovery with the NEES above its 99.9 % "
                    "chi-square(3) quantile, mean over runs and distances."
                )
            )
            for ident in sorted({self.col.datasets[n].spec.ident for n in kid}):
                sec.children.append(
                    self._kidnap_family_section(ident, [n for n in kid if self.col.datasets[n].spec.ident == ident])
                )
        glob = sorted({f for r in self.col.runs for f in [r.filter] if self.col.is_global(f)})
        if glob:
            rows: list[tuple[str, ...]] = []
            for ds in sorted(self.col.datasets):
                df = self.rows(ds)
                for f in self.filters_on(ds, global_start=True):
                    sub = df[df["filter"] == f]
                    k, n, r, lo, hi = tb.rate(sub, "converged")
                    rows.append(
                        (
                            f"`{ds}`",
                            f"`{f}`",
                            str(n),
                            f"{k}/{n} = {r:.2f} [{lo:.2f}, {hi:.2f}]" if n else "n/a",
                            tb.median_text(tb.values(sub, "time_to_converge_s")),
                        )
                    )
            sec.children.append(
                Section(
                    "Global localization",
                    "global",
                    [
                        Text(
                            "Filters started without knowing their pose. A run has converged at the first time at "
                            "which the recovery criterion above holds; success rate with its 95 % Wilson interval "
                            "and median time over the converged runs."
                        ),
                        Table(("dataset", "filter", "runs", "converged (95 % Wilson)", "median time (s)"), tuple(rows)),
                    ],
                )
            )
        return sec

    def _kidnap_family_section(self, ident: str, names: list[str]) -> Section:
        fam_of = {n: self.col.datasets[n].spec.without(KIDNAP_PARAM).name for n in names}
        dists = sorted({self.kidnap_distance(n) for n in names})
        rows: list[tuple[str, ...]] = []
        curves: list[fg.RateCurve] = []
        kstyles: dict[str, LineStyle] = {}
        families = sorted(set(fam_of.values()))
        for fam in families:
            members = sorted((n for n in names if fam_of[n] == fam), key=self.kidnap_distance)
            filters = self.col.filter_order({f for n in members for f in self.filters_on(n)})
            for f in filters:
                cells, pts = [], []
                fc: list[float] = []
                for d in dists:
                    n = next((m for m in members if self.kidnap_distance(m) == d), None)
                    if n is None:
                        cells.append("")
                        continue
                    sub = self.rows(n)
                    sub = sub[sub["filter"] == f]
                    k, cnt, r, lo, hi = tb.rate(sub, "kidnap_recovered")
                    cells.append(f"{k}/{cnt}" if cnt else "")
                    if cnt:
                        pts.append((d, r, lo, hi))
                    fc.extend(tb.values(sub, "kidnap_false_confidence_fraction"))
                label = f if len(families) == 1 else f"{f} on {fam}"
                rows.append((f"`{f}`", f"`{fam}`", *cells, tb.num(float(np.mean(fc))) if fc else "n/a"))
                if pts:
                    a = np.array(pts)
                    curves.append(fg.RateCurve(label, label, a[:, 0], a[:, 1], a[:, 2], a[:, 3]))
                    # the filter's own colour and marker; a second family of worlds gets its own dash
                    st = self.palette.style(f)
                    kstyles[label] = st._replace(linestyle=LINESTYLES[families.index(fam) % len(LINESTYLES)])
        styles = kstyles
        title = f"{ident}: recovery within 30 s, 95 % Wilson intervals"

        def draw(fig: Figure) -> None:
            fg.draw_recovery(fig.add_subplot(), curves, styles, title)

        blocks: list = [
            Table(
                ("filter", "dataset", *(f"D = {d:g} m" for d in dists), "false confidence"),
                tuple(rows),
                caption=f"{ident}: recovered runs / runs at each kidnap distance",
            )
        ]
        if curves:
            blocks.append(Plot(f"kidnap_{slug(ident)}", title, draw, size=(7.5, 4.2)))
        return Section(f"Kidnap: {ident}", f"kidnap-{slug(ident)}", blocks)

    # --- recorded data --------------------------------------------------------------------------------

    def recorded_data(self) -> Section:
        sec = Section("Recorded data", "recorded")
        names = self.recorded()
        if not names:
            return sec
        status: dict[tuple[str, str], set[str]] = defaultdict(set)
        for r in self.col.runs:
            if r.dataset in names:
                status[(r.filter, r.dataset)].add(r.status)
        filters = self.col.filter_order({f for f, _ in status})

        def cell(f: str, ds: str, metric: str) -> tuple[str, float]:
            sub = self.rows(ds)
            v = tb.values(sub[sub["filter"] == f], metric) * METRICS[metric].scale
            if v.size:
                return tb.num(float(np.mean(v))) + (f" (n={v.size})" if v.size > 1 else ""), float(np.mean(v))
            st = status.get((f, ds), set())
            if "skipped" in st:
                return "skipped", NAN
            if st - {"ok"}:
                return "failed", NAN
            return "-", NAN

        groups = [(k, [d for d in names if self.reference_kind(d) == k]) for k in KINDS]
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
            head = ("filter", *(self._recorded_header(d) for d in group))
            fs = [f for f in filters if any((f, d) in status for d in group)]
            acc = [[cell(f, d, self._recorded_metric(d)) for d in group] for f in fs]
            rtf = [[cell(f, d, "realtime_factor") for d in group] for f in fs]
            acc_cells, acc_note, acc_hover = sig.mark_grid(self, fs, group, acc, self._recorded_metric)
            rtf_cells, rtf_note, rtf_hover = sig.mark_grid(self, fs, group, rtf, lambda d: "realtime_factor")
            metrics_text = "; ".join(f"`{self.col.display(d)}` {tb.header(self._recorded_metric(d))}" for d in group)
            sub = Section(f"Reference: {kind}", f"recorded-{slug(kind)}")
            sub.add(
                Text(f"Accuracy: {metrics_text}; {kind_caption(kind)}."),
                Table(
                    head,
                    tuple(tuple(r) for r in acc_cells),
                    caption=f"Accuracy (cm); {kind_caption(kind)}",
                    footnotes=(acc_note,),
                    sort_keys=tuple((NAN, *(c[1] for c in r)) for r in acc),
                    hovers=acc_hover,
                ),
                Table(
                    head,
                    tuple(tuple(r) for r in rtf_cells),
                    caption=f"Real-time factor (x); {kind_caption(kind)}",
                    footnotes=(rtf_note,),
                    sort_keys=tuple((NAN, *(c[1] for c in r)) for r in rtf),
                    hovers=rtf_hover,
                ),
            )
            worse = self._not_below_baseline(fs, group, acc)
            if worse:
                sub.add(Text(f"Not below dead reckoning ({kind_caption(kind)}): {worse}."))
            sec.children.append(sub)
        noise_of = {}
        for d in names:
            rn = self._truth_meta(d)[1].get("range_noise")
            if isinstance(rn, dict) and isinstance(rn.get("world"), str) and isinstance(rn.get("noise"), str):
                noise_of[d] = (rn["world"], rn["noise"])
        robust = robustness_table(self.df[self.df["dataset"].isin(names)], filters, noise_of)
        if robust is not None:
            sec.children.append(Section("Robustness to range noise", "recorded-robustness", [robust]))
        return sec

    def _not_below_baseline(self, fs: list[str], group: list[str], acc: list[list[tuple[str, float]]]) -> str:
        """The (filter, dataset) cells of a recorded group whose accuracy is no better than the baseline's."""
        base = [i for i, f in enumerate(fs) if self.col.is_baseline(f)]
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
                    out.append(f"`{f}` on `{self.col.display(d)}` ({tb.num(v)} against {tb.num(ref)})")
        return "; ".join(out)

    # --- experiments ---------------------------------------------------------------------------------

    def experiment(self, e: Experiment) -> Section:
        sec = Section(e.title, f"exp-{slug(e.dataset)}")
        text = e.text + (f" Source: {e.source.citation}." if e.source else "")
        sec.add(Text(text))
        base = e.dataset
        if not e.fold_variants and base in self.col.datasets:
            filters = self.filters_on(base)
            bounds = self.bounds_on(base)
            caption = f"`{base}`: mean ± 95 % interval over seeds"
            sec.add(tb.comparison_table(self.rows(base), filters, caption, bounds, self.eligible(filters)))
            wt = tb.waypoint_table(self.rows(base), filters + bounds, f"`{base}`: RMSE at each waypoint over runs (cm)")
            if wt is not None:
                sec.add(wt)
            count = self.count_plot(base)
            sec.add(
                *self.trajectory_plots(base),
                *self.waypoint_plots(base),
                *self.nees_plots(base),
                *([count] if count is not None else []),
            )
        # with the bound's rows: an experiment's own tables show the accuracy limit too
        rows = self.df[self.df["dataset"].isin(self.variants_of(e.dataset))]
        for fn in sections_for(e.dataset):
            sec.add(*fn(rows, slug(e.dataset)))
        return sec

    def trajectory_plots(self, dataset: str) -> list[Plot]:
        """Every configuration's estimate on the first seed: one figure, or, past :data:`MAX_TRACK_PANELS`, one
        of the defaults and one per sweep (:meth:`split`), so that no configuration is left out."""
        keys = [k for k in self.col.ok_dirs if k[0] == dataset and not self.col.is_global(k[1])]
        if not keys:
            return []
        seed = min(k[2] for k in keys)
        truth = self.col.truths[(dataset, seed)]
        filters = self.col.filter_order({k[1] for k in keys if k[2] == seed})
        gt = truth.ground_truth
        world = fg.World(
            truth.map_segments,
            truth.map_landmarks,
            gt.xy,
            truth.truth_label,
            truth.waypoints.xy if truth.waypoints is not None else np.zeros((0, 2)),
        )
        t_marks = np.linspace(gt.t[0], gt.t[-1], ELLIPSES_PER_TRACK + 2)[1:-1]
        tracks: dict[str, fg.Track] = {}
        for f in filters:
            run = self.col.read_run(dataset, f, seed)
            tracks[f] = fg.Track(
                f,
                run.mean[:, :2],
                estimate_at(run.t, run.mean, t_marks)[:, :2],
                estimate_at(run.t, run.cov, t_marks)[:, :2, :2],
            )
        plots = []
        for key, names in self.split(filters, MAX_TRACK_PANELS):
            what = {"": "each filter's", "defaults": "each filter's default"}.get(key, f"`{key}`'s configurations'")
            caption = (
                f"`{dataset}`, seed {seed}: {what} estimate (colour) with 95 % position ellipses, the "
                f"{truth.truth_label} (black), the map (grey) and the waypoints (x)"
            )
            stem = f"{slug(dataset)}_trajectories{_stem_part(key)}"
            title = f"{dataset}{_part(key)}, seed {seed}: trajectories"
            plots.append(self._trajectory_plot(stem, caption, title, world, [tracks[f] for f in names]))
        return plots

    def _trajectory_plot(self, stem: str, caption: str, title: str, world: fg.World, tracks: list[fg.Track]) -> Plot:
        styles = self.styles_for([tr.label for tr in tracks])

        def draw(fig: Figure) -> None:
            fg.draw_trajectories(fig, world, tracks, styles)

        size = fg.trajectory_size(world, [tr.label for tr in tracks])
        return Plot(stem, caption, draw, size=size, interactive=ia.tracks(title, world, tracks, styles))

    def count_plot(self, dataset: str) -> Plot | None:
        """The particle count over time of the filters whose count adapts (KLD sampling), first seed."""
        keys = sorted(k for k in self.col.ok_dirs if k[0] == dataset and not self.col.is_global(k[1]))
        if not keys or not (self.rows(dataset)["metric"] == "particles_mean").any():
            return None
        seed = keys[0][2]
        series: list[tuple[str, np.ndarray, np.ndarray]] = []
        for f in self.filters_on(dataset):
            sub = self.rows(dataset)
            if (dataset, f, seed) not in self.col.ok_dirs or not len(
                tb.values(sub[sub["filter"] == f], "particles_mean")
            ):
                continue
            run = self.col.read_run(dataset, f, seed)
            count = run.diagnostics.get("particles")
            if count is None or not np.isfinite(count).any():
                continue
            ok = np.isfinite(count)
            if np.nanmax(count) > np.nanmin(count):
                series.append((f, run.t[ok], count[ok]))
        if not series:
            return None
        styles = self.styles_for([f for f, _, _ in series])
        title = f"{dataset}, seed {seed}: particle count after each step (adaptive filters)"

        def draw(fig: Figure) -> None:
            ax = fig.add_subplot()
            for f, t, c in series:
                st = styles[f]
                ax.step(t, c, where="post", color=st.color, ls=st.linestyle, lw=0.9, label=f)
            ax.set_yscale("log")
            fg.finish(ax, "t (s)", "particles", title)

        return Plot(f"{slug(dataset)}_particle_count", title, draw)

    def waypoint_plots(self, dataset: str) -> list[Plot]:
        """RMSE at each waypoint: one figure, or the defaults and one per sweep past :data:`MAX_LINE_SERIES`."""
        ws = waypoint_stats(self.rows(dataset))
        if not len(ws):
            return []
        filters = [f for f in self.filters_on(dataset) if (ws["filter"] == f).any()]
        bounds = [b for b in self.bounds_on(dataset) if (ws["filter"] == b).any()]
        plots = []
        for key, names in self.split(filters, MAX_LINE_SERIES):
            labels = names + bounds
            series = [
                ws[ws["filter"] == f].sort_values("waypoint")["rmse_m"].to_numpy(dtype=np.float64) * 100.0
                for f in labels
            ]
            styles = self.bound_styles(labels)
            title = f"{dataset}{_part(key)}: waypoint RMSE over runs (log scale; black: the bound)"

            def draw(
                fig: Figure,
                labels: list[str] = labels,
                series: list = series,
                styles: dict = styles,
                title: str = title,
            ) -> None:
                fg.draw_waypoint_rmse(fig.add_subplot(), labels, series, styles, title)

            plots.append(Plot(f"{slug(dataset)}_waypoint_rmse{_stem_part(key)}", title, draw))
        return plots

    def nees_plots(self, dataset: str) -> list[Plot]:
        """Mean NEES over runs: one figure, or the defaults and one per sweep past :data:`MAX_LINE_SERIES`."""
        entries = sorted((f, s) for (d, f), s in self.col.nees.items() if d == dataset and not self.col.is_global(f))
        if not entries:
            return []
        seed = min(k[2] for k in self.col.ok_dirs if k[0] == dataset)
        grid = self.col.truths[(dataset, seed)].ground_truth.t
        order = self.col.filter_order({f for f, _ in entries})
        by = dict(entries)
        mean = {f: fg.NeesSeries(f, mean_over_runs(grid, by[f])[0], len(by[f])) for f in order}
        plots = []
        for key, names in self.split(order, MAX_LINE_SERIES):
            series = [mean[f] for f in names]
            bands = {n: chi2_band(POSE_DOF, n, CONFIDENCE) for n in sorted({s.runs for s in series})}
            styles = self.styles_for(names)
            title = f"{dataset}{_part(key)}: mean NEES over runs"
            caption = f"{title} (pose, heading wrapped; runs from a uniform prior left out)"

            def draw(
                fig: Figure, series: list = series, bands: dict = bands, styles: dict = styles, title: str = title
            ) -> None:
                fg.draw_nees(fig.add_subplot(), grid, series, bands, styles, title)

            plots.append(Plot(f"{slug(dataset)}_nees{_stem_part(key)}", caption, draw, size=(7.5, 4.2)))
        return plots

    # --- appendix --------------------------------------------------------------------------------------

    def appendix(self) -> Section:
        sec = Section("Appendix", "appendix")
        shown = {e.dataset for e in self.exps if not e.fold_variants}
        folded = {e.dataset for e in self.exps if e.fold_variants}
        detail = Section("Every dataset", "appendix-datasets")
        for ds in sorted(self.col.datasets):
            info = self.col.datasets[ds]
            if ds in shown or info.spec.ident in folded:
                continue
            filters = self.filters_on(ds) + self.filters_on(ds, global_start=True)
            if not filters:
                continue
            detail.add(
                tb.comparison_table(
                    self.rows(ds),
                    filters,
                    f"`{info.display}`: mean ± 95 % interval",
                    self.bounds_on(ds),
                    self.eligible(filters),
                )
            )
        if detail.blocks:
            sec.children.append(detail)
        main = [e.dataset for e in self.exps if e.summary and e.dataset in self.col.datasets]
        sec.children += sig.appendix_sections(self, main)
        sec.children.append(self.failures())
        sec.children.append(self.provenance())
        return sec

    def failures(self) -> Section:
        sec = Section("Failed and skipped runs", "failures")
        groups: dict[tuple[str, str, str, str], list[int]] = defaultdict(list)
        for r in self.col.runs:
            if r.status != "ok":
                groups[(r.status, r.filter, r.dataset, r.message)].append(r.seed)
        if not groups and not self.col.broken:
            return sec.add(Text("None."))
        rows = tuple(
            (st, f"`{f}`", f"`{self.col.display(d)}`", str(len(seeds)), seed_ranges(seeds), msg)
            for (st, f, d, msg), seeds in sorted(groups.items())
        )
        if rows:
            sec.add(Table(("status", "filter", "dataset", "runs", "seeds", "reason"), rows))
        if self.col.broken:
            sec.add(
                Text("Unreadable run folders (left out of every table):"),
                Table(("folder", "error"), tuple((f"`{p}`", e) for p, e in sorted(self.col.broken))),
            )
        return sec

    def provenance(self) -> Section:
        commits: dict[str, bool] = {}
        versions: dict[str, set[str]] = defaultdict(set)
        for m in self.col.metas:
            if m.get("git_commit"):
                c = str(m["git_commit"])
                commits[c] = commits.get(c, False) or bool(m.get("git_dirty", False))
            for lib, ver in (m.get("versions") or {}).items():
                versions[str(lib)].add(str(ver))
        counts: dict[str, int] = defaultdict(int)
        for r in self.col.runs:
            counts[r.status] += 1
        seeds: dict[str, set[int]] = defaultdict(set)
        for r in self.col.runs:
            seeds[r.dataset].add(r.seed)
        by_range: dict[str, list[str]] = defaultdict(list)
        for d, s in seeds.items():
            by_range[seed_ranges(s)].append(d)
        items = (
            f"locbench {locbench.__version__}",
            "git commit of the runs: "
            + (", ".join(f"`{c}`" + (" (dirty)" if d else "") for c, d in sorted(commits.items())) or "unknown"),
            "libraries: "
            + (", ".join(f"{lib} {' / '.join(sorted(v))}" for lib, v in sorted(versions.items())) or "unknown"),
            "seeds: " + "; ".join(f"{rng} ({len(ds)} datasets)" for rng, ds in sorted(by_range.items())),
            "runs: "
            + ", ".join(f"{counts[s]} {s}" for s in ("ok", "diverged", "error", "skipped") if counts[s])
            + (f", {len(self.col.broken)} unreadable" if self.col.broken else ""),
            *([sig.verify_line(self.col.store)] if self.col.store is not None else []),
        )
        return Section("Provenance", "provenance", [Bullets(items)])


def _part(key: str) -> str:
    """A split figure's part in its title: ``, defaults`` or ``, pf's configurations``."""
    return {"": "", "defaults": ", defaults"}.get(key, f", {key}'s configurations")


def _stem_part(key: str) -> str:
    """A split figure's part in its file stem: the defaults keep the figure's own name."""
    return f"_{slug(key)}" if key and key != "defaults" else ""


def band_for(runs: int) -> str:
    return tb.band_text(runs)


def slug(name: str) -> str:
    """A file-name-safe, bounded stem for a name; long or changed names get a short hash of the full name."""
    import hashlib
    import re

    s = re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("_") or "x"
    if s != name or len(s) > 80:
        s = f"{s[:80]}-{hashlib.sha256(name.encode()).hexdigest()[:8]}"
    return s


def seed_ranges(seeds: list[int] | set[int]) -> str:
    """``0-4, 7, 9-10`` for the seeds 0 1 2 3 4 7 9 10."""
    s = sorted(set(seeds))
    parts: list[str] = []
    i = 0
    while i < len(s):
        j = i
        while j + 1 < len(s) and s[j + 1] == s[j] + 1:
            j += 1
        parts.append(str(s[i]) if i == j else f"{s[i]}-{s[j]}")
        i = j + 1
    return ", ".join(parts) if parts else "none"
