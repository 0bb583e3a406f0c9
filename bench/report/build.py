"""The report's sections, in reading order, built from the collected runs and the registered experiments.

Order: how to read this, summary tables (one per summary experiment), claims, accuracy against runtime,
consistency, kidnap and global localization, recorded data, one section per experiment, appendix (detail
tables, failed and skipped runs, provenance). Which datasets are main comparisons, which sections and
claims an experiment has, comes from :mod:`locbench.present.experiments` (registered by :mod:`locbench.claims`); the
report names no dataset or filter.

:class:`Report` holds what every section reads (the rows of a dataset name, the configurations run on it, the
figure styles); each section is a function of it in its own module (:mod:`~locbench.report.sections.summary`,
:mod:`~locbench.report.sections.runtime`, :mod:`~locbench.report.sections.consistency`,
:mod:`~locbench.report.sections.kidnap`,
:mod:`~locbench.report.sections.recorded`, :mod:`~locbench.report.sections.experiment`,
:mod:`~locbench.report.sections.appendix`, and
:mod:`~locbench.report.sections.health`, :mod:`~locbench.report.sections.paired_tests`,
:mod:`~locbench.report.sections.tuned`).
"""

from __future__ import annotations

from collections import defaultdict
from functools import cached_property

import numpy as np
import pandas as pd

from locbench.core.spec import Spec
from locbench.evaluate.metrics import ATE_M, CONFIDENCE, KIDNAP_DISTANCE_M, RELATION_ERROR_M
from locbench.evaluate.pcrb import BOUND_ROWS
from locbench.present.experiments import all_claims, experiments
from locbench.present.palette import Palette, split_by_sweep
from locbench.report import tables as tb
from locbench.report import timing as tm
from locbench.report.collect import Collected
from locbench.report.doc import Section, Table, Text
from locbench.report.names import NAN, seed_ranges, slug
from locbench.report.sections import appendix as ap
from locbench.report.sections import consistency as cs
from locbench.report.sections import experiment as ex
from locbench.report.sections import health as hl
from locbench.report.sections import kidnap as kd
from locbench.report.sections import paired_tests as sig
from locbench.report.sections import recorded as rc
from locbench.report.sections import runtime as rt
from locbench.report.sections import summary as sm
from locbench.report.sections.reference import reference_kind as _reference_kind
from locbench.report.sections.reference import semi_synthetic
from locbench.report.sections.tuned import tuning_section
from locbench.report.style import LineStyle


class Report:
    """What every section reads from one :class:`Collected`; styles are fixed per filter for every figure."""

    def __init__(self, col: Collected) -> None:
        self.col = col
        self.df = col.metrics
        # claims read the filters' rows only (a claim is about filters; the bound is no candidate)
        self.filter_df = self.df[~self.df["filter"].isin(BOUND_ROWS)] if len(self.df) else self.df
        self.by_ds: dict[str, pd.DataFrame] = {str(d): g for d, g in self.df.groupby("dataset")} if len(self.df) else {}
        self.exps = [e for e in experiments() if self.has(e.dataset)]
        # one x axis for every accuracy-runtime figure: reference units where every run has them
        self.pareto_x = tm.pareto_x(self.df)

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

    def has(self, dataset_id: str) -> bool:
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
        v = tb.values(self.rows(dataset), KIDNAP_DISTANCE_M)
        return float(np.median(v)) if v.size else NAN

    @cached_property
    def _builtin(self) -> frozenset[str]:
        """The dataset ids some built-in suite runs."""
        from locbench.suites import SUITES

        return frozenset(Spec.parse(d).ident for suite in SUITES.values() for b in suite.blocks for d in b.datasets)

    @cached_property
    def _own(self) -> list[str]:
        own = [n for n, info in sorted(self.col.datasets.items()) if info.spec.ident not in self._builtin]
        if own or any(e.summary and e.dataset in self.col.datasets for e in self.exps):
            return own
        # nothing else would give a summary (a store of, say, recorded runs only): every dataset name that has
        # no experiment section of its own
        sectioned = {e.dataset for e in self.exps}
        folded = {e.dataset for e in self.exps if e.fold_variants}
        return [
            n
            for n, info in sorted(self.col.datasets.items())
            if n not in sectioned and info.spec.ident not in folded and self.filters_on(n)
        ]

    def own(self) -> list[str]:
        """A user's own datasets, each reported like a main comparison (summary, figures, runtime): the stored
        dataset names whose id no built-in suite runs (a ``rosbag[path=...]`` recording, a plug-in's dataset);
        in a store without those and without a main comparison, every dataset name without a section."""
        return list(self._own)

    def own_title(self, dataset: str) -> str:
        """``Your data: `name``` for a dataset no built-in suite runs, else the name."""
        shown = f"`{self.col.display(dataset)}`"
        return shown if self.col.datasets[dataset].spec.ident in self._builtin else f"Your data: {shown}"

    def recorded(self) -> list[str]:
        return [n for n, info in sorted(self.col.datasets.items()) if info.recorded]

    def ground_truth(self, dataset: str) -> bool:
        return all(tr.truth_label == "ground truth" for (d, _), tr in self.col.truths.items() if d == dataset)

    def truth_meta(self, dataset: str) -> tuple[str, dict, str]:
        for (d, _), tr in sorted(self.col.truths.items()):
            if d == dataset:
                return str(tr.meta.get("dataset_id", "")), dict(tr.meta.get("metadata", {}) or {}), tr.truth_label
        return self.col.datasets[dataset].spec.ident if dataset in self.col.datasets else "", {}, "ground truth"

    def reference_kind(self, dataset: str) -> str:
        """Motion capture, GPS, survey, not stated, SLAM or simulation (:mod:`locbench.report.sections.reference`)."""
        ident, meta, label = self.truth_meta(dataset)
        return _reference_kind(ident or self.col.datasets[dataset].spec.ident, meta, label)

    def recorded_header(self, dataset: str) -> str:
        semi = " (semi-synthetic)" if semi_synthetic(self.truth_meta(dataset)[1]) else ""
        return f"`{self.col.display(dataset)}`{semi}"

    def recorded_metric(self, dataset: str) -> str:
        if (self.rows(dataset)["metric"] == RELATION_ERROR_M).any():
            return RELATION_ERROR_M
        return ATE_M

    # --- sections -------------------------------------------------------------------------------------

    def sections(self) -> list[Section]:
        out = [
            sm.summary_section(self),
            sig.across_datasets(self),
            tuning_section(self.col) or Section("", ""),
            claims_section(self),
            rt.pareto_section(self),
            cs.consistency_section(self),
            hl.lost_section(self),
            kd.kidnap_section(self),
            rc.recorded_section(self),
            rc.input_warnings_section(self),
            *[ex.experiment_section(self, e) for e in self.exps],
            *[ex.own_section(self, d) for d in self.own()],
            ap.appendix_section(self),
        ]
        return [s for s in out if s.blocks or s.children]

    def how_to_read(self) -> list[str]:
        return [
            "locbench runs every localization filter on the same synthetic worlds and recorded datasets and "
            "measures them the same way. Start with the **summary** tables: one row per filter configuration on "
            "each main comparison and on each dataset of your own (the defaults by ATE, then each filter's other "
            "configurations under it), with the sensors and map it needs and a line on which to use with which; "
            "errors in cm, times in us; in bold the best value of each column and every configuration a paired "
            "test over the seeds does not find different from it (the dead-reckoning baseline is never marked, "
            "nor an inconsistent ANEES). Then the ranks **across datasets**, the **claims** of the five source "
            "reports, each with its verdict and the measured value; the **accuracy against runtime** fronts (lower and "
            "further right is better); **consistency** (does a filter's covariance describe its error?); kidnap "
            "recovery; the recorded data; and one section per experiment. Values are means over seeds; the "
            f"appendix gives every dataset's table with {100 * CONFIDENCE:.0f} % Student-t intervals. What every "
            "metric means: `docs/protocols.md` in the repository.",
        ]


def claims_section(rep: Report) -> Section:
    sec = Section("Claims of the source reports", "claims")
    rows: list[tuple[str, ...]] = []
    counts: dict[str, int] = defaultdict(int)
    for c in all_claims():
        if not rep.has(c.dataset):
            continue
        if c.across_variants:
            df = rep.filter_df[rep.filter_df["dataset"].isin(rep.variants_of(c.dataset))]
        else:
            df = rep.rows(c.dataset)
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


def band_for(runs: int) -> str:
    return tb.band_text(runs)


__all__ = ["Report", "band_for", "seed_ranges", "slug"]
