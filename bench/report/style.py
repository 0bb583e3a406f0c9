"""The report's fixed drawing style: colours, markers, dashes and matplotlib settings.

:data:`PALETTE`, :data:`MARKERS`, :data:`LINESTYLES` and :class:`LineStyle` live in :mod:`locbench.present.docfmt`
(the claims draw with them too and never import the report).

:data:`PALETTE` is Okabe and Ito's eight (2008, "Color Universal Design"), for series that are not filters
(the datasets of a claim's figure); a filter's colour and marker come from :mod:`locbench.present.palette`,
keyed by its id, so that it is the same in every figure. :func:`style_for` gives the i-th of a figure's own
series a (colour, marker, dash) that repeats only after 63 names (black is kept for the truth).
"""

from __future__ import annotations

from typing import Any

from locbench.present.docfmt import LINESTYLES, MARKERS, PALETTE, LineStyle

FIG_DPI = 110
#: A fixed style on top of matplotlib's defaults (a user's matplotlibrc must not change the bytes).
MPL_STYLE: dict[str, Any] = {
    "font.size": 8.0,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "legend.fontsize": 7.0,
    "lines.linewidth": 1.2,
    "path.simplify": False,
    "svg.hashsalt": "locbench",
    "axes.titlesize": 8.5,
}


def style_for(index: int) -> LineStyle:
    """The style of the ``index``-th name of a figure's stable order."""
    return LineStyle(
        PALETTE[index % (len(PALETTE) - 1)],  # black is kept for the truth
        MARKERS[index % len(MARKERS)],
        LINESTYLES[(index // (len(PALETTE) - 1)) % len(LINESTYLES)],
    )
