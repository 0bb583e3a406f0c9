"""Documents both the report and the claims build: sections of text, tables and plots, the number format of
their cells and the palette of their figures.

Builders produce these values and never write files; :mod:`locbench.report.render` turns one list of
sections into ``REPORT.md``, the PNG figures and ``index.html``, so both outputs say the same thing.
Cell and paragraph text is Markdown-flavoured plain text: ``code`` and ``**bold**`` spans only. The report
(:mod:`locbench.report`) and the claims (:mod:`locbench.claims`) both import this module; neither imports the
other's helpers (an import-linter contract in ``pyproject.toml``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
from matplotlib.figure import Figure

#: Draws a figure's content into a fresh matplotlib Figure (no I/O).
DrawFn = Callable[[Figure], None]


@dataclass(frozen=True)
class Text:
    """A paragraph."""

    text: str


@dataclass(frozen=True)
class Bullets:
    """A bulleted list."""

    items: tuple[str, ...]


@dataclass(frozen=True)
class Table:
    """A table: header, rows of cell text, optional caption and footnotes.

    ``sort_keys`` holds, per row, a number per column for sorting in the HTML page (NaN: no numeric
    key, sorted as text); empty means sort every column as text. ``hovers`` holds, per row, a text per
    column shown when the pointer rests on the cell in the HTML page (the paired effect against the column's
    best; "": none); empty means no hovers. The Markdown ignores both.
    """

    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    caption: str = ""
    footnotes: tuple[str, ...] = ()
    sort_keys: tuple[tuple[float, ...], ...] = ()
    hovers: tuple[tuple[str, ...], ...] = ()


@dataclass(frozen=True)
class Plot:
    """A figure: a file stem (``office_pareto``), a caption, the drawing function and its size in inches.

    ``interactive`` optionally holds a plotly figure dict drawn in the HTML page instead of the PNG. ``shows``
    names the configurations of the figure's table that the figure stands for: each is drawn (its name in a
    legend, a title or the key) or named in the figure as not shown, with the reason (the figure test checks it).
    """

    name: str
    caption: str
    draw: DrawFn
    size: tuple[float, float] = (7.0, 4.2)
    interactive: dict[str, Any] | None = None
    shows: tuple[str, ...] = ()


Block = Text | Bullets | Table | Plot


@dataclass
class Section:
    """A titled section with its blocks and sub-sections; ``anchor`` is its stable HTML/Markdown id."""

    title: str
    anchor: str
    blocks: list[Block] = field(default_factory=list)
    children: list[Section] = field(default_factory=list)

    def add(self, *blocks: Block) -> Section:
        self.blocks.extend(blocks)
        return self

    def walk(self, level: int = 2) -> list[tuple[int, Section]]:
        """This section and its descendants with their heading levels, in document order."""
        out = [(level, self)]
        for c in self.children:
            out += c.walk(level + 1)
        return out


def num(x: float, digits: int = 3) -> str:
    """A number with ``digits`` significant digits; large values without an exponent."""
    if np.isnan(x):
        return "n/a"
    if np.isinf(x):
        return "inf" if x > 0 else "-inf"
    if 100.0 <= abs(x) < 1e9:
        return f"{x:.0f}"
    return f"{x:.{digits}g}"


#: Okabe-Ito colours (black last: it is the ground truth's colour in trajectory figures).
PALETTE: tuple[str, ...] = ("#0072B2", "#E69F00", "#009E73", "#CC79A7", "#56B4E9", "#D55E00", "#F0E442", "#000000")
#: Nine markers (coprime with the eight colours; one per filter id in :mod:`locbench.present.palette`).
MARKERS: tuple[str, ...] = ("o", "s", "^", "D", "v", "P", "X", "<", "*")
LINESTYLES: tuple[str, ...] = ("-", "--", "-.", ":")


class LineStyle(NamedTuple):
    """The colour, marker and dash of one series."""

    color: str
    marker: str
    linestyle: str
