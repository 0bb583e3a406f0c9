"""Interactive figures: plotly figure dicts (data only, drawn by the HTML page), styled like their PNGs.

Each takes the same data and the same :class:`~locbench.report.style.LineStyle` mapping as the matplotlib
drawing in :mod:`locbench.report.figures`, so a configuration has one colour, marker and dash in both.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from locbench.present.docfmt import LineStyle
from locbench.present.palette import plotly_line, plotly_marker
from locbench.report import figures as fg

#: Most points of one plotted path (the page stays small).
MAX_PATH_POINTS = 1000
#: The largest distance of a dropped point of a plotted path from the simplified line (m): 1 mm, far below a pixel.
PATH_TOLERANCE_M = 1e-3


def pareto(
    title: str,
    points: Sequence[fg.ParetoPoint],
    styles: Mapping[str, LineStyle],
    ylabel: str,
    xlabel: str = "real-time factor (x)",
) -> dict:
    """The Pareto panel of :func:`~locbench.report.figures.draw_pareto` as plotly: a marker per configuration
    (its shade, edged in its group's colour, the group's symbol), each group's front as a line, the overall
    front as a dotted step; ``xlabel`` names the x axis (raw or reference-unit real-time factor)."""
    layers = fg.pareto_layers(points)
    traces: list[dict[str, Any]] = []
    hover = "%{text}<br>" + xlabel + " %{x:.3g}<br>" + ylabel + " %{y:.3g}<extra></extra>"
    for g, pts, fr in layers.groups:
        st = styles[g]
        for p in pts:
            face = styles.get(p.label, st)
            marker = plotly_marker(face, 8) | {"line": {"color": st.color, "width": 1}}
            traces.append(
                {
                    "type": "scatter",
                    "mode": "markers",
                    "name": p.label,
                    "legendgroup": g,
                    "x": [p.x],
                    "y": [p.y],
                    "text": [p.label],
                    "marker": marker,
                    "hovertemplate": hover,
                }
            )
        if len(fr) > 1:
            traces.append(
                {
                    "type": "scatter",
                    "mode": "lines",
                    "name": f"{g} front",
                    "legendgroup": g,
                    "showlegend": False,
                    "x": [pts[i].x for i in fr],
                    "y": [pts[i].y for i in fr],
                    "line": plotly_line(st, 1),
                    "hoverinfo": "skip",
                }
            )
    if layers.front:
        traces.append(
            {
                "type": "scatter",
                "mode": "lines",
                "name": "front (all)",
                "x": [p.x for p in layers.front],
                "y": [p.y for p in layers.front],
                # matplotlib's step(where="post") over x descending: horizontal first, then vertical
                "line": {"color": "#4d4d4d", "width": 1, "dash": "dot", "shape": "hv"},
                "hoverinfo": "skip",
            }
        )
    return {
        "data": traces,
        "layout": {
            "title": {"text": title},
            "xaxis": {"type": "log", "title": {"text": xlabel}},
            "yaxis": {"type": "log", "title": {"text": ylabel}},
            "height": 460,
        },
    }


def tracks(title: str, world: fg.World, tracks: Sequence[fg.Track], styles: Mapping[str, LineStyle]) -> dict:
    """Every track of a trajectory figure over the map and the truth, one legend entry each."""
    traces: list[dict[str, Any]] = []
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
    traces.append(path(world.truth_label, world.truth_xy, {"color": "#000000", "width": 1.5}))
    traces += [path(tr.label, tr.xy, plotly_line(styles[tr.label], 1)) for tr in tracks]
    (x0, x1), (y0, y1) = fg.world_limits(world)
    return {
        "data": traces,
        "layout": {
            "title": {"text": f"{title} (click a legend entry to hide it)"},
            "xaxis": {"range": [x0, x1], "title": {"text": "x (m)"}},
            "yaxis": {"range": [y0, y1], "title": {"text": "y (m)"}, "scaleanchor": "x"},
            "height": 560,
        },
    }


def path(name: str, xy: np.ndarray, line: dict[str, Any]) -> dict:
    """A path as a plotly line, simplified (:func:`simplify`) to at most :data:`MAX_PATH_POINTS` points."""
    keep = simplify(xy)
    return {
        "type": "scatter",
        "mode": "lines",
        "name": name,
        "x": _r(xy[keep, 0]),
        "y": _r(xy[keep, 1]),
        "line": line,
    }


def simplify(xy: np.ndarray, tol: float = PATH_TOLERANCE_M, most: int = MAX_PATH_POINTS) -> np.ndarray:
    """The indices of the points of a path (N x 2, m) that Ramer-Douglas-Peucker keeps at tolerance ``tol`` (m),
    the tolerance doubled until at most ``most`` remain; the first and last points are always kept.

    A dropped point lies within the tolerance of the line through the kept points around it, so the drawn path
    differs from the full one by at most that (1 mm: below a pixel of any figure of a world).
    """
    n = xy.shape[0]
    if n <= 2:
        return np.arange(n)
    finite = np.isfinite(xy).all(axis=1)
    if not finite.all():  # a path with gaps (NaN) is thinned by a stride instead
        return np.arange(n)[:: max(1, -(-n // most))]
    while True:
        keep = _rdp(xy, tol)
        if keep.size <= most:
            return keep
        tol *= 2.0


def _rdp(xy: np.ndarray, tol: float) -> np.ndarray:
    """Ramer-Douglas-Peucker without recursion: the kept indices, ascending."""
    n = xy.shape[0]
    kept = np.zeros(n, dtype=bool)
    kept[0] = kept[-1] = True
    stack = [(0, n - 1)]
    while stack:
        i, j = stack.pop()
        if j - i < 2:
            continue
        a, b = xy[i], xy[j]
        seg = b - a
        pts = xy[i + 1 : j] - a
        length = float(np.hypot(seg[0], seg[1]))
        # distance to the chord's line; to its start when the path returns to where it was
        cross = np.abs(seg[0] * pts[:, 1] - seg[1] * pts[:, 0])
        d = cross / length if length > 0.0 else np.hypot(pts[:, 0], pts[:, 1])
        k = int(np.argmax(d))
        if d[k] > tol:
            m = i + 1 + k
            kept[m] = True
            stack += [(i, m), (m, j)]
    return np.flatnonzero(kept)


def _r(a: np.ndarray) -> list[float]:
    return [round(float(v), 4) for v in a]
