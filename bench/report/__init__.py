"""From stored runs to ``<results>/summary/``: ``metrics.parquet``, ``comparisons.csv``, and the report as a small
static site (``index.html``, a page per comparison, experiment, analysis and appendix part, ``figures/``,
``assets/plotly.min.js``) with its Markdown twin (``REPORT.md``, ``md/*.md``).

The package is split by job: :mod:`~locbench.report.collect` reads the store (the only I/O on runs),
:mod:`~locbench.report.tables` and :mod:`~locbench.report.figures` turn arrays into tables and drawings,
:mod:`~locbench.report.build` orders them into sections from the experiments and claims registered in
:mod:`locbench.present.experiments` (by :mod:`locbench.claims`), :mod:`~locbench.report.render` writes Markdown,
PNG and HTML, and :mod:`~locbench.report.site` cuts the sections into pages. Regenerating from the same runs gives
identical bytes.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

from locbench.report.collect import (
    Keep,
    RunInfo,
    collect,
    collect_metrics,
    metrics_parquet,
    read_metrics,
    write_metrics_csv,
)
from locbench.report.doc import Table
from locbench.report.tables import wilson_interval
from locbench.run.store import MARKER, Store

__all__ = [
    "ReportPaths",
    "collect_metrics",
    "read_metrics",
    "suite_filter",
    "summary_text",
    "wilson_interval",
    "write_metrics_csv",
    "write_report",
]

log = logging.getLogger(__name__)

TITLE = "locbench: which localization filter?"


@dataclass(frozen=True)
class ReportPaths:
    """What :func:`write_report` wrote, and the summary tables for the terminal."""

    #: ``REPORT.md``, the landing page in Markdown
    markdown: Path
    #: ``index.html``, the site's landing page
    html: Path
    #: ``metrics.parquet``
    metrics: Path
    summary: tuple[Table, ...]
    #: the status of every stored run the report read
    runs: tuple[RunInfo, ...] = ()


def write_report(store: Store, keep: Keep | None = None, out: Path | None = None, jobs: int = 1) -> ReportPaths:
    """Write ``metrics.parquet``, ``comparisons.csv``, ``figures/*.png``, the site's pages (``index.html`` and one
    ``<page>.html`` each, :mod:`locbench.report.site`), their Markdown (``REPORT.md``, ``md/<page>.md``),
    ``assets/plotly.min.js`` and the folder's manifest, whole: into a temporary sibling folder, then swapped in
    (:mod:`locbench.report.output`).

    Parameters
    ----------
    store : Store
        The results folder.
    keep : callable, optional
        ``keep(dataset, filter)`` restricts the report to some cells (a suite's, see :func:`suite_filter`).
    out : Path, optional
        The folder to write; default ``store.summary``. What the last report wrote there is replaced; any other
        file is kept; a folder that is not empty and was not written by the report is refused.
    jobs : int
        Processes that read the runs and draw the figures (1: this process); the files do not depend on it.

    Raises
    ------
    ConfigError
        The output folder is someone else's, or holds a file of a name the report writes that it did not write.
    OSError
        A write failed (a full disk): the error names the file; the folder is left as it was.
    """
    from locbench.report.build import how_to_read, section_builders, shown
    from locbench.report.context import Report
    from locbench.report.output import OutputFolder
    from locbench.report.render import build_and_draw
    from locbench.report.sections.paired_tests import comparisons_csv
    from locbench.report.site import oversize, site_files

    summary = Path(out) if out is not None else store.summary
    # the summary of a results folder 'locbench run' marked is the report's, manifest or not (older reports)
    legacy = summary.absolute() == store.summary.absolute() and (store.root / MARKER).is_file()
    folder = OutputFolder(summary, legacy=legacy)  # refuses someone else's folder before anything is computed
    col = collect(store, keep, jobs)
    report = Report(col)
    # what several sections share first, so that every section's worker has it
    report.prepare(jobs)
    builders = section_builders(report)
    built, pngs = build_and_draw(builders, jobs)
    sections = shown(built)
    intro = how_to_read()
    with folder:
        metrics = folder.write("metrics.parquet", metrics_parquet(col.metrics))
        folder.write("comparisons.csv", comparisons_csv(report.comparisons))
        for name, data in pngs.items():
            folder.write(f"figures/{name}.png", data)
        site = site_files(TITLE, intro, sections)
        for rel, data in site.items():
            folder.write(rel, data)
        folder.commit()
    for problem in oversize(site):
        log.warning("the report site is over its size limit: %s", problem)
    md, page = folder.final / "REPORT.md", folder.final / "index.html"
    tables = tuple(
        b for s in sections if s.anchor == "summary" for c in s.children for b in c.blocks if isinstance(b, Table)
    )
    log.info("wrote %s (%d metric rows, %d figures)", md, len(col.metrics), len(pngs))
    return ReportPaths(md, page, metrics, tables, tuple(col.runs))


def summary_text(tables: tuple[Table, ...]) -> str:
    """The summary tables as aligned plain text for the terminal."""
    out: list[str] = []
    for t in tables:
        cells = [list(t.header), *[[c.replace("**", "").replace("`", "") for c in r] for r in t.rows]]
        widths = [max(len(r[i]) for r in cells) for i in range(len(t.header))]
        out.append(t.caption.replace("`", ""))
        for k, r in enumerate(cells):
            out.append("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip())
            if k == 0:
                out.append("  ".join("-" * w for w in widths))
        out.append("")
    return "\n".join(out)


def suite_filter(*suite_names: str, results: str | Path | None = None) -> Keep:
    """``keep(dataset, filter)`` for the cells of named suites or suite files (grids expanded, canonical names).

    Suite ``tuned`` has its cells in the results folder (its tuned configurations on the test data,
    :func:`locbench.run.tuning.tuned_cells`), so it needs ``results``.
    """
    from locbench.run.tuning import tuned_cells
    from locbench.suites import suite_pairs

    cells = {(d.name, f.name) for name in suite_names for f, d in suite_pairs(name)}
    if "tuned" in suite_names and results is not None:
        cells |= tuned_cells(results)
    return lambda dataset, filt: (dataset, filt) in cells
