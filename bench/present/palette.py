"""One style per filter configuration, keyed by its filter id, for every figure of a report.

A filter id keeps one colour and one marker in every PNG and every plotly figure: the colour is the id's
place in a fixed order (the package's own filters sorted by id, then plug-ins and unregistered names sorted),
so it does not depend on which filters a figure shows. The configurations of one filter (a sweep
``pf[particles=300]``, a tuned configuration) are shades of that colour, darker to lighter in the filter's
order, with a dash of their own; the default configuration (no parameters) has the colour itself, solid.
The bound's rows (:data:`locbench.evaluate.pcrb.BOUND_ROWS`) are black and dashed, without markers.

Colours are Paul Tol's "muted" qualitative scheme (Tol 2021, "Colour Schemes", SRON/EPS/TN/09-002): nine
colours distinct under the common colour-vision deficiencies, one per filter of the package with one to spare.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable, Sequence

from locbench.core.spec import Spec
from locbench.evaluate.pcrb import BOUND_ROWS
from locbench.present.docfmt import LINESTYLES, MARKERS, LineStyle

#: Tol's muted scheme, in his order (indigo, cyan, teal, green, olive, sand, rose, wine, purple).
FILTER_COLORS: tuple[str, ...] = (
    "#332288",
    "#88CCEE",
    "#44AA99",
    "#117733",
    "#999933",
    "#DDCC77",
    "#CC6677",
    "#882255",
    "#AA4499",
)
#: The colour of the ground truth and of the bound's rows.
BLACK = "#000000"
#: Dashes of a filter's non-default configurations, in turn (the default is solid).
VARIANT_DASHES: tuple[str, ...] = ("--", "-.", ":")
#: How far the shades of a filter's configurations go towards black (negative) and white (positive).
SHADE_RANGE = (-0.5, 0.45)

#: matplotlib marker -> plotly marker symbol (:data:`locbench.present.docfmt.MARKERS`, and "" for none).
PLOTLY_SYMBOLS: dict[str, str] = {
    "o": "circle",
    "s": "square",
    "^": "triangle-up",
    "D": "diamond",
    "v": "triangle-down",
    "P": "cross",
    "X": "x",
    "<": "triangle-left",
    "*": "star",
    "": "circle",
}
#: matplotlib linestyle -> plotly line dash.
PLOTLY_DASHES: dict[str, str] = {"-": "solid", "--": "dash", "-.": "dashdot", ":": "dot"}


def id_order(idents: Iterable[str]) -> list[str]:
    """The filter ids in colour order: the package's registered filters sorted, then every other id sorted.

    The package's own filters come first so that installing a plug-in never changes their colours.
    """
    from locbench.registry import FILTERS

    builtin: list[str] = []
    for ident in FILTERS.ids():
        try:
            if FILTERS.entry(ident).entry_point.startswith("locbench."):
                builtin.append(ident)
        except Exception:  # an entry that cannot be described is ordered with the others
            continue
    rest = sorted((set(idents) | set(FILTERS.ids())) - set(builtin))
    return sorted(builtin) + rest


def shade(color: str, amount: float) -> str:
    """``color`` (``#rrggbb``) mixed towards white (``amount`` > 0) or black (< 0) by ``|amount|`` in [0, 1]."""
    rgb = [int(color[i : i + 2], 16) for i in (1, 3, 5)]
    target = 255 if amount > 0 else 0
    a = min(abs(amount), 1.0)
    mixed = [round(c + (target - c) * a) for c in rgb]
    return "#" + "".join(f"{c:02X}" for c in mixed)


def shades(n: int) -> list[float]:
    """The shade amounts of a filter's ``n`` non-default configurations, darker to lighter, none at 0.

    One configuration is drawn a little lighter than the default; several spread evenly over
    :data:`SHADE_RANGE`, the middle one (if any) pushed off the default's own colour.
    """
    lo, hi = SHADE_RANGE
    if n <= 0:
        return []
    if n == 1:
        return [0.3]
    out = [lo + (hi - lo) * k / (n - 1) for k in range(n)]
    return [a if abs(a) >= 0.15 else (0.15 if a >= 0 else -0.15) for a in out]


class Palette:
    """The style of every configuration of a report, from the full set of its configuration names.

    Parameters
    ----------
    names : iterable of str
        Every filter configuration the report shows (canonical spec strings); the shade of a
        configuration is its place among those of its filter id, so build one palette per report and
        use it for every figure.
    order : sequence of str, optional
        The same names in the report's table order (a filter's configurations are shaded in it);
        default: sorted by name.
    """

    def __init__(self, names: Iterable[str], order: Sequence[str] | None = None) -> None:
        names = list(names)
        listed = [n for n in order if n in set(names)] if order is not None else []
        configs = [n for n in dict.fromkeys([*listed, *sorted(set(names))]) if n not in BOUND_ROWS]
        self._ident = {n: Spec.parse(n).ident for n in configs}
        self._ids = id_order(self._ident.values())
        by_id: dict[str, list[str]] = defaultdict(list)
        for n in configs:
            by_id[self._ident[n]].append(n)
        self._styles: dict[str, LineStyle] = {}
        for ident, members in by_id.items():
            base = self.base(ident)
            variants = [n for n in members if n != ident]
            self._styles[ident] = base
            for k, (n, a) in enumerate(zip(variants, shades(len(variants)), strict=True)):
                self._styles[n] = LineStyle(shade(base.color, a), base.marker, VARIANT_DASHES[k % len(VARIANT_DASHES)])
        for i, b in enumerate(BOUND_ROWS):
            self._styles[b] = LineStyle(BLACK, "", ("--", ":")[i % 2])

    def base(self, ident: str) -> LineStyle:
        """The style of a filter id (its default configuration): its colour and marker, a solid line.

        Past the ninth id colours and markers repeat together, so the dash changes with each round.
        """
        if ident not in self._ids:
            self._ids = id_order([*self._ids, ident])
        i = self._ids.index(ident)
        return LineStyle(
            FILTER_COLORS[i % len(FILTER_COLORS)],
            MARKERS[i % len(MARKERS)],
            LINESTYLES[(i // len(FILTER_COLORS)) % len(LINESTYLES)],
        )

    def style(self, name: str) -> LineStyle:
        """The style of one configuration (a name the palette was not built with gets its filter's style)."""
        if name in self._styles:
            return self._styles[name]
        return self.base(Spec.parse(name).ident)

    def styles(self, names: Iterable[str]) -> dict[str, LineStyle]:
        """``{name: style}`` for a figure's series."""
        return {n: self.style(n) for n in names}


def plotly_line(st: LineStyle, width: float = 1.0) -> dict[str, object]:
    """A plotly ``line`` dict of a style: the same colour and dash as the PNG."""
    return {"color": st.color, "width": width, "dash": PLOTLY_DASHES.get(st.linestyle, "solid")}


def plotly_marker(st: LineStyle, size: float = 7.0) -> dict[str, object]:
    """A plotly ``marker`` dict of a style: the same colour and symbol as the PNG."""
    return {"color": st.color, "symbol": PLOTLY_SYMBOLS.get(st.marker, "circle"), "size": size}


def split_by_sweep(names: Sequence[str], limit: int) -> list[tuple[str, list[str]]]:
    """A figure's configurations as one group when at most ``limit``, else the defaults and one per sweep.

    Returns ``(key, names)`` pairs in order: ``("", names)`` when few enough; otherwise ``("defaults",
    every default configuration and every filter with no default shown)`` then ``(filter id, its default and
    its other configurations)`` for each filter with more than one configuration. Every name is in at least
    one group, so a figure split this way never drops a configuration.
    """
    if len(names) <= limit:
        return [("", list(names))]
    by_id: dict[str, list[str]] = defaultdict(list)
    for n in names:
        by_id[Spec.parse(n).ident].append(n)
    defaults = [n for n in names if n in by_id or len(by_id[Spec.parse(n).ident]) == 1]
    groups: list[tuple[str, list[str]]] = [("defaults", defaults)] if defaults else []
    for ident, members in by_id.items():
        if len(members) > 1:
            groups.append((ident, members))
    return groups
