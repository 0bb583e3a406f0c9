"""The report's section "Accuracy against runtime": ATE against real-time factor per main comparison and on the
recorded data."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from matplotlib.figure import Figure

from locbench.evaluate.metrics import ATE_M, METRICS
from locbench.report import figures as fg
from locbench.report import interactive as ia
from locbench.report import tables as tb
from locbench.report import timing as tm
from locbench.report.doc import Plot, Section, Text
from locbench.report.names import slug

if TYPE_CHECKING:
    from locbench.report.context import Report


def pareto_points(rep: Report, dataset: str, metric: str) -> list[fg.ParetoPoint]:
    df = rep.rows(dataset)
    pts = []
    for f in rep.filters_on(dataset):
        sub = df[df["filter"] == f]
        x, y = tb.mean_of(sub, rep.pareto_x), tb.mean_of(sub, metric) * METRICS[metric].scale
        if np.isfinite(x) and np.isfinite(y) and x > 0 and y > 0:
            pts.append(fg.ParetoPoint(f, rep.col.filters[f].spec.ident, x, y))
    return pts


def pareto_section(rep: Report) -> Section:
    sec = Section("Accuracy against runtime", "pareto")
    sec.add(
        Text(
            "Each marker is one filter configuration (mean over seeds): x is the real-time factor (dataset "
            "duration over compute time, higher is faster)"
            + (
                " in reference units (times the time of a fixed reference workload on the same machine under "
                "the same load: the real-time factor on a machine whose reference workload takes 1 s, so that "
                "sweeps on other machines or loads compare)"
                if rep.pareto_x == tm.PARETO_X
                else ""
            )
            + ", y the ATE (lower is better), both logarithmic. "
            "A line joins each filter's own non-dominated configurations (a parameter sweep draws its "
            "curve); the dotted step is the front over all of them. Runs started without a pose are left out."
        )
    )
    for e in rep.exps:
        if not e.summary or e.dataset not in rep.col.datasets:
            continue
        pts = pareto_points(rep, e.dataset, ATE_M)
        if pts:
            sec.add(pareto_plot(rep, f"{slug(e.dataset)}_pareto", e.dataset, [(e.dataset, "ATE (cm)", pts)]))
    for d in rep.own():
        metric = rep.recorded_metric(d)
        pts = pareto_points(rep, d, metric)
        if pts:
            shown = rep.col.display(d)
            sec.add(pareto_plot(rep, f"{slug(d)}_pareto", shown, [(shown, tb.header(metric), pts)]))
    rec = [
        (rep.col.display(d), tb.header(rep.recorded_metric(d)), pareto_points(rep, d, rep.recorded_metric(d)))
        for d in rep.recorded()
    ]
    rec = [r for r in rec if r[2]]
    if rec:
        sec.add(pareto_plot(rep, "recorded_pareto", "recorded data", rec))
    # the heading stands only above a figure
    return sec if any(isinstance(b, Plot) for b in sec.blocks) else Section("Accuracy against runtime", "pareto")


def pareto_plot(rep: Report, name: str, title: str, panels: list[tuple[str, str, list[fg.ParetoPoint]]]) -> Plot:
    pts_all = [p for _, _, pts in panels for p in pts]
    styles = rep.styles_for(sorted({p.group for p in pts_all} | {p.label for p in pts_all}))
    xlabel = tm.pareto_xlabel(rep.pareto_x)

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
            fg.draw_pareto(ax, pts, styles, xlabel, ylabel, label, per_config=n == 1)
            if n > 1:
                leg = ax.get_legend()
                if leg is not None:
                    leg.remove()
        if n > 1:
            # one legend of the filters for every panel, outside them all
            by_label = {lab: h for ax in axes.flat for h, lab in zip(*ax.get_legend_handles_labels(), strict=True)}
            fig.legend(list(by_label.values()), list(by_label), loc="outside right upper", fontsize=6.5)

    if len(panels) == 1:
        # the configurations' legend goes below the axes in columns, the key of long names below it
        entries = len(panels[0][2]) + 1
        rows = int(np.ceil(entries / 3)) if entries > fg.LEGEND_RIGHT_MAX else 0
        keys = sum(1 for p in panels[0][2] if len(p.label) > fg.SHORT_MAX)
        size = (7.0, 4.2 + 0.17 * rows + 0.2 * keys)
    else:
        size = (11.0, 3.2 * int(np.ceil(len(panels) / 3)))
    interactive = (
        ia.pareto(f"{title}: ATE against real-time factor", panels[0][2], styles, panels[0][1], xlabel)
        if len(panels) == 1
        else None
    )
    what = "accuracy" if len(panels) > 1 else "ATE"
    # one panel lists every configuration; several list the filters
    shows = tuple(dict.fromkeys(p.label if len(panels) == 1 else p.group for p in pts_all))
    caption = f"{title}: {what} against real-time factor"
    return Plot(name, caption, draw, size=size, interactive=interactive, shows=shows)
