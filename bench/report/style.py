"""The report's fixed figure settings: the resolution and the matplotlib style every figure is drawn with.

The colours, markers and dashes (:data:`~locbench.present.docfmt.PALETTE`, :data:`~locbench.present.docfmt.MARKERS`,
:data:`~locbench.present.docfmt.LINESTYLES`, :class:`~locbench.present.docfmt.LineStyle`) live in
:mod:`locbench.present.docfmt` (the claims draw with them too and never import the report); a filter's colour and
marker come from :mod:`locbench.present.palette`, keyed by its id, so that it is the same in every figure.
"""

from __future__ import annotations

from typing import Any

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
