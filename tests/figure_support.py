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
