"""A check of the report's figures for the tests: the texts a drawn plot puts outside its canvas."""

from __future__ import annotations

from typing import Any

import matplotlib.style
from matplotlib.text import Text as MplText

from locbench.report.doc import Plot
from locbench.report.render import _figure
from locbench.report.style import MPL_STYLE


def texts_off_canvas(plot: Plot, tolerance_px: float = 1.0) -> list[str]:
    """The texts of a drawn plot that reach outside its canvas (a clipped title, a legend taller than the
    figure), as ``"'text' at (x0, y0, x1, y1) px"``; empty when every drawn text is whole.

    Only texts the renderer draws count (hidden tick labels do not); their extents are compared with the
    figure's bounding box after the layout has run, as :func:`locbench.report.render.render_png` draws
    it.
    """
    with matplotlib.style.context(["default", MPL_STYLE]):
        fig = _figure(plot)
        renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]
        drawn: list[MplText] = []
        draw_text = renderer.draw_text

        def record(gc: Any, x: float, y: float, s: str, prop: Any, angle: float, *args: Any, **kw: Any) -> None:
            mtext = kw.get("mtext", args[1] if len(args) > 1 else None)
            if isinstance(mtext, MplText):
                drawn.append(mtext)
            draw_text(gc, x, y, s, prop, angle, *args, **kw)

        renderer.draw_text = record
        fig.draw(renderer)
        box = fig.bbox
        out = []
        for t in dict.fromkeys(drawn):
            e = t.get_window_extent(renderer)
            if (
                e.x0 < box.x0 - tolerance_px
                or e.y0 < box.y0 - tolerance_px
                or e.x1 > box.x1 + tolerance_px
                or e.y1 > box.y1 + tolerance_px
            ):
                out.append(f"{t.get_text()!r} at ({e.x0:.0f}, {e.y0:.0f}, {e.x1:.0f}, {e.y1:.0f}) px")
    return out


def _drawn_figure(plot: Plot) -> tuple[Any, Any]:
    """The plot drawn as :func:`locbench.report.render.render_png` draws it (the layout run), and its renderer."""
    fig = _figure(plot)
    fig.canvas.draw()
    return fig, fig.canvas.get_renderer()  # type: ignore[attr-defined]


def _flat(text: str) -> str:
    """A text with its wrapping undone: configuration names are broken after commas, with no space lost."""
    return text.replace("\n", "")


def figure_problems(plot: Plot, tolerance_px: float = 1.0) -> list[str]:
    """What keeps a figure from reading, as one line each; empty when it reads.

    - a text drawn outside the canvas (:func:`texts_off_canvas`);
    - a legend (an axes' or the figure's) over the data area of any axes, by the renderer's extents;
    - axes that draw data without an x or a y label;
    - a configuration of :attr:`Plot.shows` neither named in a text of the figure (legend, title, key) nor
      named there as not shown.
    """
    out = [f"off the canvas: {t}" for t in texts_off_canvas(plot, tolerance_px)]
    with matplotlib.style.context(["default", MPL_STYLE]):
        fig, renderer = _drawn_figure(plot)
        axes = [ax for ax in fig.axes if ax.get_visible() and ax.axison]
        legends = [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None] + list(fig.legends)
        for leg in legends:
            if not leg.get_visible():
                continue
            e = leg.get_window_extent(renderer)
            for ax in axes:
                a = ax.get_window_extent(renderer)
                w = min(e.x1, a.x1) - max(e.x0, a.x0)
                h = min(e.y1, a.y1) - max(e.y0, a.y0)
                if w > tolerance_px and h > tolerance_px:
                    first = leg.get_texts()[0].get_text() if leg.get_texts() else ""
                    out.append(f"legend {first!r} over the data of axes {ax.get_title()!r} ({w:.0f} x {h:.0f} px)")
        for ax in axes:
            has_data = bool(ax.get_lines() or ax.collections or ax.patches or ax.images)
            if has_data and not (ax.get_xlabel().strip() and ax.get_ylabel().strip()):
                out.append(f"axes {ax.get_title()!r} without an axis label: {ax.get_xlabel()!r}, {ax.get_ylabel()!r}")
        texts = " | ".join(_flat(t.get_text()) for t in fig.findobj(MplText) if t.get_visible())
        for name in plot.shows:
            if name not in texts:
                out.append(f"configuration {name!r} neither drawn nor named as not shown")
    return out
