"""The report's section "Kidnap and global localization": recovery against kidnap distance, convergence from a
uniform prior."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from matplotlib.figure import Figure

from locbench.evaluate.metrics import (
    CONVERGED,
    KIDNAP_FALSE_CONFIDENCE_FRACTION,
    KIDNAP_RECOVERED,
    TIME_TO_CONVERGE_S,
)
from locbench.present.docfmt import LINESTYLES, LineStyle
from locbench.report import figures as fg
from locbench.report import tables as tb
from locbench.report.doc import Plot, Section, Table, Text
from locbench.report.names import KIDNAP_PARAM, slug

if TYPE_CHECKING:
    from locbench.report.context import Report


def kidnap_section(rep: Report) -> Section:
    sec = Section("Kidnap and global localization", "kidnap")
    kid = [n for n in rep.col.datasets if not np.isnan(rep.kidnap_distance(n))]
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
        for ident in sorted({rep.col.datasets[n].spec.ident for n in kid}):
            sec.children.append(
                kidnap_family_section(rep, ident, [n for n in kid if rep.col.datasets[n].spec.ident == ident])
            )
    glob = sorted({f for r in rep.col.runs for f in [r.filter] if rep.col.is_global(f)})
    if glob:
        rows: list[tuple[str, ...]] = []
        for ds in sorted(rep.col.datasets):
            df = rep.rows(ds)
            for f in rep.filters_on(ds, global_start=True):
                sub = df[df["filter"] == f]
                k, n, r, lo, hi = tb.rate(sub, CONVERGED)
                rows.append(
                    (
                        f"`{ds}`",
                        f"`{f}`",
                        str(n),
                        f"{k}/{n} = {r:.2f} [{lo:.2f}, {hi:.2f}]" if n else "n/a",
                        tb.median_text(tb.values(sub, TIME_TO_CONVERGE_S)),
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


def kidnap_family_section(rep: Report, ident: str, names: list[str]) -> Section:
    fam_of = {n: rep.col.datasets[n].spec.without(KIDNAP_PARAM).name for n in names}
    dists = sorted({rep.kidnap_distance(n) for n in names})
    rows: list[tuple[str, ...]] = []
    curves: list[fg.RateCurve] = []
    styles: dict[str, LineStyle] = {}
    families = sorted(set(fam_of.values()))
    for fam in families:
        members = sorted((n for n in names if fam_of[n] == fam), key=rep.kidnap_distance)
        filters = rep.col.filter_order({f for n in members for f in rep.filters_on(n)})
        for f in filters:
            cells, pts = [], []
            fc: list[float] = []
            for d in dists:
                n = next((m for m in members if rep.kidnap_distance(m) == d), None)
                if n is None:
                    cells.append("")
                    continue
                sub = rep.rows(n)
                sub = sub[sub["filter"] == f]
                k, cnt, r, lo, hi = tb.rate(sub, KIDNAP_RECOVERED)
                cells.append(f"{k}/{cnt}" if cnt else "")
                if cnt:
                    pts.append((d, r, lo, hi))
                fc.extend(tb.values(sub, KIDNAP_FALSE_CONFIDENCE_FRACTION))
            label = f if len(families) == 1 else f"{f} on {fam}"
            rows.append((f"`{f}`", f"`{fam}`", *cells, tb.num(float(np.mean(fc))) if fc else "n/a"))
            if pts:
                a = np.array(pts)
                curves.append(fg.RateCurve(label, label, a[:, 0], a[:, 1], a[:, 2], a[:, 3]))
                # the filter's own colour and marker; a second family of worlds gets its own dash
                st = rep.palette.style(f)
                styles[label] = st._replace(linestyle=LINESTYLES[families.index(fam) % len(LINESTYLES)])
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
