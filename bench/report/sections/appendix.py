"""The report's appendix: every dataset's table, paired comparisons, failed and skipped runs, provenance."""

from __future__ import annotations

from collections import defaultdict
from typing import TYPE_CHECKING

import locbench
from locbench.report import tables as tb
from locbench.report import timing as tm
from locbench.report.doc import Bullets, Section, Table, Text
from locbench.report.names import seed_ranges
from locbench.report.sections import paired_tests as sig

if TYPE_CHECKING:
    from locbench.report.context import Report


def appendix_section(rep: Report) -> Section:
    sec = Section("Appendix", "appendix")
    shown = {e.dataset for e in rep.exps if not e.fold_variants} | set(rep.own())
    folded = {e.dataset for e in rep.exps if e.fold_variants}
    detail = Section("Every dataset", "appendix-datasets")
    for ds in sorted(rep.col.datasets):
        info = rep.col.datasets[ds]
        if ds in shown or info.spec.ident in folded:
            continue
        filters = rep.filters_on(ds) + rep.filters_on(ds, global_start=True)
        if not filters:
            continue
        detail.add(
            tb.comparison_table(
                rep.rows(ds),
                filters,
                f"`{info.display}`: mean ± 95 % interval",
                rep.bounds_on(ds),
                rep.eligible(filters),
            )
        )
    if detail.blocks:
        sec.children.append(detail)
    main = [e.dataset for e in rep.exps if e.summary and e.dataset in rep.col.datasets]
    sec.children += sig.appendix_sections(rep, main)
    sec.children.append(failures_section(rep))
    sec.children.append(provenance_section(rep))
    return sec


def failures_section(rep: Report) -> Section:
    sec = Section("Failed and skipped runs", "failures")
    groups: dict[tuple[str, str, str, str], list[int]] = defaultdict(list)
    for r in rep.col.runs:
        if r.status != "ok":
            groups[(r.status, r.filter, r.dataset, r.message)].append(r.seed)
    if not groups and not rep.col.broken:
        return sec.add(Text("None."))
    rows = tuple(
        (st, f"`{f}`", f"`{rep.col.display(d)}`", str(len(seeds)), seed_ranges(seeds), msg)
        for (st, f, d, msg), seeds in sorted(groups.items())
    )
    if rows:
        sec.add(Table(("status", "filter", "dataset", "runs", "seeds", "reason"), rows))
    if rep.col.broken:
        sec.add(
            Text("Unreadable run folders (left out of every table):"),
            Table(("folder", "error"), tuple((f"`{p}`", e) for p, e in sorted(rep.col.broken))),
        )
    return sec


def provenance_section(rep: Report) -> Section:
    commits: dict[str, bool] = {}
    versions: dict[str, set[str]] = defaultdict(set)
    for m in rep.col.metas:
        if m.get("git_commit"):
            c = str(m["git_commit"])
            commits[c] = commits.get(c, False) or bool(m.get("git_dirty", False))
        for lib, ver in (m.get("versions") or {}).items():
            versions[str(lib)].add(str(ver))
    counts: dict[str, int] = defaultdict(int)
    for r in rep.col.runs:
        counts[r.status] += 1
    seeds: dict[str, set[int]] = defaultdict(set)
    for r in rep.col.runs:
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
        + (f", {len(rep.col.broken)} unreadable" if rep.col.broken else ""),
        tm.machine_line(rep.col.metas),
        *([sig.verify_line(rep.col.store)] if rep.col.store is not None else []),
    )
    return Section("Provenance", "provenance", [Bullets(items)])
