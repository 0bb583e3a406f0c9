"""What every section of the report reads: :class:`Report`, the context built once from the collected runs.

:class:`Report` holds the tidy metrics by dataset name, the configurations run on each (in the collected filter
order, the bound's rows apart), the experiments present, the figures' x axis and styles (one per filter id, fixed for
every figure) and the paired comparisons that ``comparisons.csv`` and the appendix share. Each section is a function
of it in its own module of :mod:`locbench.report.sections`, which imports this module and nothing that assembles the
report; :mod:`locbench.report.build` orders the sections.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cached_property, partial
from typing import Any

import numpy as np
import pandas as pd

from locbench.core.spec import Spec
from locbench.evaluate import significance as sg
from locbench.evaluate.lost import HealthSeries, SignalScore, score_signals
from locbench.evaluate.metrics import (
    ATE_M,
    KIDNAP_DISTANCE_M,
    KIDNAP_RECOVERED,
    METRICS,
    RELATION_ERROR_M,
    WAYPOINT_ERROR_M,
    WAYPOINT_RMSE_MEAN_M,
    family_regex,
)
from locbench.evaluate.pcrb import BOUND_ROWS
from locbench.present.docfmt import LineStyle
from locbench.present.experiments import experiments
from locbench.present.palette import Palette, split_by_sweep
from locbench.present.ranking import samples_for
from locbench.report import tables as tb
from locbench.report import timing as tm
from locbench.report.collect import Collected
from locbench.report.names import NAN


@dataclass(frozen=True)
class ComparisonRecord:
    """One row of ``comparisons.csv``: a configuration against its column's best on one dataset."""

    dataset: str
    metric: str
    configuration: str
    reference: str
    n: int
    statistic: float
    p: float
    p_holm: float
    effect: float
    effect_low: float
    effect_high: float


#: Metrics compared in ``comparisons.csv`` (each dataset's ranked columns; SI units as in ``metrics.parquet``).
COMPARED = (*(m for m in tb.COMPARISON if METRICS[m].better), WAYPOINT_RMSE_MEAN_M, KIDNAP_RECOVERED)


def dataset_comparisons(
    df: pd.DataFrame, dataset: str, filters: Sequence[str], eligible: Sequence[bool]
) -> list[ComparisonRecord]:
    """Every ranked metric of one dataset: each configuration against the metric's best, with effects."""
    out: list[ComparisonRecord] = []
    present = set(df["metric"].unique())
    for metric in COMPARED:
        if metric == WAYPOINT_RMSE_MEAN_M:
            if not df["metric"].astype(str).str.fullmatch(family_regex(WAYPOINT_ERROR_M)).any():
                continue
        elif metric not in present:
            continue
        info = METRICS[metric]
        samples = samples_for(df, filters, metric)
        means = [float(np.mean(list(s.values()))) if s else NAN for s in samples]
        target = info.target if info.better == "closer" else 1.0
        v = sg.ties_with_best(means, samples, eligible, info.better, target)  # type: ignore[arg-type]
        for c in v.comparisons:
            t = c.test
            out.append(
                ComparisonRecord(
                    dataset,
                    metric,
                    filters[c.index],
                    filters[c.reference],
                    t.n,
                    t.statistic,
                    t.p,
                    c.p_holm,
                    c.effect,
                    c.effect_low,
                    c.effect_high,
                )
            )
    return out


def _scored(series: list[HealthSeries]) -> tuple[SignalScore, ...]:
    return tuple(score_signals(series))


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
        self._signal_scores: dict[tuple[str, str], tuple[SignalScore, ...]] = {}

    @cached_property
    def comparisons(self) -> list[ComparisonRecord]:
        """``comparisons.csv``'s rows: every dataset's ranked metrics, every configuration against the best."""
        out: list[ComparisonRecord] = []
        for call in self._comparison_calls():
            out += call()
        return out

    def _comparison_calls(self) -> list[partial[list[ComparisonRecord]]]:
        calls: list[partial[list[ComparisonRecord]]] = []
        for ds in sorted(self.col.datasets):
            filters = self.filters_on(ds)
            if len(filters) >= 2:
                calls.append(partial(dataset_comparisons, self.rows(ds), ds, filters, self.eligible(filters)))
        return calls

    def prepare(self, jobs: int) -> None:
        """Compute what several sections share, in ``jobs`` forked processes, before the sections are built in
        processes of their own (:func:`locbench.report.render.build_and_draw`), which then inherit it instead of
        each computing it again: :attr:`comparisons` (one task per dataset) and every :meth:`signal_scores` (one
        per configuration and dataset). The values are the ones computed in one process."""
        from locbench.report.forked import forked_map

        comparisons = self._comparison_calls()
        keys = sorted(self.col.health)
        scores = [partial(_scored, self.col.health[k]) for k in keys]
        calls: list[Callable[[], Any]] = [*comparisons, *scores]
        # the largest first: a dataset's comparisons grow with its metric rows, a configuration's scores with its
        # runs; a run's scores weigh as a hundred metric rows, a rough ratio: the order only decides what starts first
        size = [len(c.args[0]) for c in comparisons] + [len(c.args[0]) * 100 for c in scores]
        done = forked_map(calls, jobs, sorted(range(len(calls)), key=lambda i: -size[i]))
        self.__dict__["comparisons"] = [c for part in done[: len(comparisons)] for c in part]
        for k, value in zip(keys, done[len(comparisons) :], strict=True):
            self._signal_scores[k] = value

    # --- helpers ------------------------------------------------------------------------------------

    def signal_scores(self, dataset: str, filter_name: str) -> tuple[SignalScore, ...]:
        """Every lost-detection signal's scores of a configuration on a dataset name over its runs, best first
        (:func:`locbench.evaluate.lost.score_signals`; empty without health series). Scored once: the summary,
        the lost-detection table and the kidnap delays read the same scores."""
        key = (dataset, filter_name)
        if key not in self._signal_scores:
            self._signal_scores[key] = _scored(self.col.health.get(key, []))
        return self._signal_scores[key]

    @cached_property
    def palette(self) -> Palette:
        """One style per configuration for every figure: a colour and marker per filter id, shades for sweeps."""
        names = {r.filter for r in self.col.runs}
        return Palette(names, self.col.filter_order(names))

    def styles_for(self, names: list[str]) -> dict[str, LineStyle]:
        """The palette's styles of a figure's series (the same in every figure)."""
        return self.palette.styles(names)

    def has(self, dataset_id: str) -> bool:
        """Whether some stored dataset name has this dataset id."""
        return any(info.spec.ident == dataset_id for info in self.col.datasets.values())

    def rows(self, dataset: str) -> pd.DataFrame:
        """The tidy metric rows of one dataset name (none: an empty frame of the same columns)."""
        return self.by_ds.get(dataset, self.df.iloc[0:0])

    def filters_on(self, dataset: str, global_start: bool = False) -> list[str]:
        """The configurations run on a dataset name, in the collected filter order, the bound's rows left out;
        with ``global_start`` those that start without a prior (global localization), else the others."""
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
        """The stored dataset names of one dataset id, sorted."""
        return sorted(n for n, info in self.col.datasets.items() if info.spec.ident == dataset_id)

    def kidnap_distance(self, dataset: str) -> float:
        """The median stored kidnap distance of a dataset name, m (NaN without one)."""
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
        """The stored names of recorded datasets, sorted."""
        return [n for n, info in sorted(self.col.datasets.items()) if info.recorded]

    def ground_truth(self, dataset: str) -> bool:
        """Whether every stored truth of a dataset name is ground truth (not, say, a SLAM reference)."""
        return all(tr.truth_label == "ground truth" for (d, _), tr in self.col.truths.items() if d == dataset)

    def truth_meta(self, dataset: str) -> tuple[str, dict, str]:
        """(dataset id, dataset metadata, truth label) of a dataset name's first stored truth; without one, its id,
        no metadata and "ground truth"."""
        for (d, _), tr in sorted(self.col.truths.items()):
            if d == dataset:
                return str(tr.meta.get("dataset_id", "")), dict(tr.meta.get("metadata", {}) or {}), tr.truth_label
        return self.col.datasets[dataset].spec.ident if dataset in self.col.datasets else "", {}, "ground truth"

    def recorded_metric(self, dataset: str) -> str:
        """The accuracy metric a recorded dataset is scored by: the relation error where it has one, else ATE."""
        if (self.rows(dataset)["metric"] == RELATION_ERROR_M).any():
            return RELATION_ERROR_M
        return ATE_M
