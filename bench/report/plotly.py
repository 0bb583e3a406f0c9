"""Interactive figures: plotly figure dicts (data only, drawn by the HTML page), moved as they were from
:mod:`locbench.report.build`."""

from __future__ import annotations

import numpy as np

from locbench.report import figures as fg
from locbench.report.style import LineStyle


def _plotly_pareto(title: str, panels: list[tuple[str, str, list[fg.ParetoPoint]]], xlabel: str) -> dict:
    _, _, pts = panels[0]
    traces = []
    for g in sorted({p.group for p in pts}):
        sel = [p for p in pts if p.group == g]
        traces.append(
            {
                "type": "scatter",
                "mode": "markers",
                "name": g,
                "x": [p.x for p in sel],
                "y": [p.y for p in sel],
                "text": [p.label for p in sel],
                "hovertemplate": f"%{{text}}<br>{xlabel} %{{x:.3g}}<br>ATE %{{y:.3g}} cm<extra></extra>",
            }
        )
    return {
        "data": traces,
        "layout": {
            "title": {"text": f"{title}: ATE against real-time factor"},
            "xaxis": {"type": "log", "title": {"text": xlabel}},
            "yaxis": {"type": "log", "title": {"text": "ATE (cm)"}},
            "height": 460,
        },
    }


def _plotly_tracks(dataset: str, world: fg.World, tracks: list[fg.Track], styles: dict[str, LineStyle]) -> dict:
    traces: list[dict] = []
    segx: list[float | None] = []
    segy: list[float | None] = []
    for x1, y1, x2, y2 in world.segments:
        segx += [float(x1), float(x2), None]
        segy += [float(y1), float(y2), None]
    traces.append(
        {
            "type": "scatter",
            "mode": "lines",
            "name": "map",
            "x": segx,
            "y": segy,
            "line": {"color": "#aaaaaa", "width": 1},
            "hoverinfo": "skip",
        }
    )
    traces.append(_plotly_path(world.truth_label, world.truth_xy, "#000000", 1.5))
    traces += [_plotly_path(tr.label, tr.xy, styles[tr.label].color, 1) for tr in tracks]
    (x0, x1), (y0, y1) = fg.world_limits(world)
    return {
        "data": traces,
        "layout": {
            "title": {"text": f"{dataset}: trajectories (click a legend entry to hide it)"},
            "xaxis": {"range": [x0, x1], "title": {"text": "x (m)"}},
            "yaxis": {"range": [y0, y1], "title": {"text": "y (m)"}, "scaleanchor": "x"},
            "height": 560,
        },
    }


def _plotly_path(name: str, xy: np.ndarray, color: str, width: float) -> dict:
    """A path as a plotly line, thinned to at most about 2000 points (the page stays small)."""
    step = max(1, xy.shape[0] // 2000)
    return {
        "type": "scatter",
        "mode": "lines",
        "name": name,
        "x": _r(xy[::step, 0]),
        "y": _r(xy[::step, 1]),
        "line": {"color": color, "width": width},
    }


def _r(a: np.ndarray) -> list[float]:
    return [round(float(v), 4) for v in a]
