"""The report's fixed drawing style: colours, markers, dashes and matplotlib settings.

:data:`PALETTE` is Okabe and Ito's eight (2008, "Color Universal Design"), for series that are not filters
(the datasets of a claim's figure); a filter's colour and marker come from :mod:`locbench.report.palette`,
keyed by its id, so that it is the same in every figure. :func:`style_for` gives the i-th of a figure's own
series a (colour, marker, dash) that repeats only after 63 names (black is kept for the truth).
"""

from __future__ import annotations

from typing import Any, NamedTuple

#: Okabe-Ito colours (black last: it is the ground truth's colour in trajectory figures).
PALETTE: tuple[str, ...] = ("#0072B2", "#E69F00", "#009E73", "#CC79A7", "#56B4E9", "#D55E00", "#F0E442", "#000000")
#: Nine markers (coprime with the eight colours; one per filter id in :mod:`locbench.report.palette`).
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
