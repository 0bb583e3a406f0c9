"""The report's sections, in reading order, built from the report's context and the registered experiments.

Order: how to read this, summary tables (one per summary experiment), tuned against default, generalization
(tuning against test units), claims, accuracy against runtime,
consistency, initial heading error, kidnap and global localization, recorded data, one section per experiment,
appendix (detail tables, failed and skipped runs, provenance). Which datasets are main comparisons, which sections and
claims an experiment has, comes from :mod:`locbench.present.experiments` (registered by :mod:`locbench.claims`); the
report names no dataset or filter.

Each section is a function of the context :class:`~locbench.report.context.Report` in its own module
(:mod:`~locbench.report.sections.summary`, :mod:`~locbench.report.sections.runtime`,
:mod:`~locbench.report.sections.consistency`, :mod:`~locbench.report.sections.heading`,
:mod:`~locbench.report.sections.kidnap`,
:mod:`~locbench.report.sections.recorded`, :mod:`~locbench.report.sections.experiment`,
:mod:`~locbench.report.sections.appendix`, :mod:`~locbench.report.sections.health`,
:mod:`~locbench.report.sections.paired_tests`, :mod:`~locbench.report.sections.tuned`,
:mod:`~locbench.report.sections.generalization`); this module imports them
and orders them, and no section imports it.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable, Iterable
from functools import partial

from locbench.evaluate.metrics import CONFIDENCE
from locbench.present.experiments import all_claims
from locbench.report.context import Report
from locbench.report.doc import Section, Table, Text
from locbench.report.sections import appendix as ap
from locbench.report.sections import consistency as cs
from locbench.report.sections import experiment as ex
from locbench.report.sections import generalization as gz
from locbench.report.sections import heading as hd
from locbench.report.sections import health as hl
from locbench.report.sections import kidnap as kd
from locbench.report.sections import paired_tests as sig
from locbench.report.sections import recorded as rc
from locbench.report.sections import runtime as rt
from locbench.report.sections import summary as sm
from locbench.report.sections.tuned import tuning_section


def section_builders(rep: Report) -> list[Callable[[], Section | None]]:
    """One call per section of the report, in reading order (the module docstring); each builds its section (or
    None, or an empty one, when it has nothing to show). Independent of each other: they may run in any process
    that holds ``rep`` (:func:`locbench.report.render.build_and_draw`)."""
    return [
        partial(sm.summary_section, rep),
        partial(sig.across_datasets, rep),
        partial(tuning_section, rep.col),
        partial(gz.generalization_section, rep.col),
        partial(claims_section, rep),
        partial(rt.pareto_section, rep),
        partial(cs.consistency_section, rep),
        partial(hd.heading_section, rep),
        partial(hl.lost_section, rep),
        partial(kd.kidnap_section, rep),
        partial(rc.recorded_section, rep),
        partial(rc.input_warnings_section, rep),
        *[partial(ex.experiment_section, rep, e) for e in rep.exps],
        *[partial(ex.own_section, rep, d) for d in rep.own()],
        partial(ap.appendix_section, rep),
    ]


def shown(sections: Iterable[Section | None]) -> list[Section]:
    """The sections that have something to show, in order."""
    return [s for s in sections if s is not None and (s.blocks or s.children)]


def build_sections(rep: Report) -> list[Section]:
    """The report's sections in reading order (the module docstring), the empty ones left out."""
    return shown(b() for b in section_builders(rep))


def how_to_read() -> list[str]:
    """The landing page's introduction: how to read the report and where its parts are."""
    return [
        "locbench runs every localization filter on the same synthetic worlds and recorded datasets and "
        "measures them the same way. The **summary** tables below say which filter to use with which sensors "
        "and map: one row per filter configuration on each main comparison and on each dataset of your own (the "
        "defaults by ATE, then each filter's other configurations under it), with the sensors and map it needs and "
        "a line on which to use with which; errors in cm, times in us; in bold the best value of each column and "
        "every configuration a paired test over the seeds does not find different from it (the dead-reckoning "
        "baseline is never marked, nor an inconsistent ANEES). Below them the **accuracy against runtime** fronts "
        "(lower and further right is better). Every other part has its page, linked above: each main comparison "
        "and experiment, the **claims** of the five source reports with their verdicts and measured values, the "
        "ranks **across datasets**, **consistency** (does a filter's covariance describe its error?), lost "
        "detection, kidnap recovery, tuning, the recorded data and the appendix. Values are means over seeds; the "
        f"appendix gives every dataset's table with {100 * CONFIDENCE:.0f} % Student-t intervals. What every "
        "metric means: `docs/protocols.md` in the repository.",
    ]


def claims_section(rep: Report) -> Section:
    """Every registered claim whose experiment ran: its verdict, the measured value and the test."""
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
