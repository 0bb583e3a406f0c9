"""The report's fixed drawing style: a colour-blind-safe palette, distinct markers and matplotlib settings.

Colours are Okabe and Ito's eight (2008, "Color Universal Design"), safe for the common forms of colour
blindness; markers are nine, so with :func:`style_for` the (colour, marker) pair of the i-th name repeats
only after 63 names (black is kept for the truth): no two lines of one figure share both.
"""

from __future__ import annotations

from typing import Any, NamedTuple

from locbench.docfmt import PALETTE

#: Nine markers (coprime with the eight colours).
MARKERS: tuple[str, ...] = ("o", "s", "^", "D", "v", "P", "X", "<", "*")
LINESTYLES: tuple[str, ...] = ("-", "--", "-.", ":")

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


class LineStyle(NamedTuple):
    """The colour, marker and dash of one series."""

    color: str
    marker: str
    linestyle: str


def style_for(index: int) -> LineStyle:
    """The style of the ``index``-th name of a figure's stable order."""
    return LineStyle(
        PALETTE[index % (len(PALETTE) - 1)],  # black is kept for the truth
        MARKERS[index % len(MARKERS)],
        LINESTYLES[(index // (len(PALETTE) - 1)) % len(LINESTYLES)],
    )
