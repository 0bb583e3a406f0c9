"""Rendering the sections: Markdown, PNG figures and HTML.

:func:`markdown_sections` and :func:`html_sections` render sections for the site's pages
(:mod:`locbench.report.site`); :func:`to_markdown` and :func:`to_html` make one whole document of them (the HTML one
self-contained: PNGs and the plotly.js bundle inlined). All are deterministic: PNGs are drawn with the Agg backend,
a fixed style, size and dpi and no software metadata.
"""

from __future__ import annotations

import base64
import dataclasses
import html
import io
import json
import re
from collections.abc import Callable
from functools import partial

import matplotlib.style
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from locbench.report.doc import Bullets, Plot, Section, Table, Text
from locbench.report.style import FIG_DPI, MPL_STYLE


def _figure(plot: Plot) -> Figure:
    """A fresh figure with the plot drawn into it (call inside the report's style context)."""
    fig = Figure(figsize=plot.size, dpi=FIG_DPI, layout="constrained")
    FigureCanvasAgg(fig)
    plot.draw(fig)
    return fig


def render_png(plot: Plot) -> bytes:
    """Draw a plot into PNG bytes: RGB (the figures are opaque; an alpha channel would add a quarter to each file).

    One draw of the canvas (the layout engine runs at its start), then its buffer without the alpha channel encoded
    by Pillow (matplotlib's own PNG writer), with the figure's dpi and no software metadata: no complete draw with
    rendering switched off first, as ``savefig`` makes for a figure with a layout engine (a third of the time).
    """
    from PIL import Image

    with matplotlib.style.context(["default", MPL_STYLE]):
        fig = _figure(plot)
        canvas = fig.canvas
        assert isinstance(canvas, FigureCanvasAgg)  # _figure attaches one
        canvas.draw()
        rgb = np.ascontiguousarray(np.asarray(canvas.buffer_rgba())[..., :3])
        buf = io.BytesIO()
        Image.fromarray(rgb, mode="RGB").save(buf, format="png", dpi=(fig.dpi, fig.dpi))
    return buf.getvalue()


def _md_cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ").strip()


def to_markdown(title: str, intro: list[str], sections: list[Section]) -> str:
    """The whole report as Markdown: title, introduction, contents, then every section."""
    lines = [f"# {title}", "", *[p for para in intro for p in (para, "")], "## Contents", ""]
    for level, sec in (x for s in sections for x in s.walk()):
        lines.append(f"{'  ' * (level - 2)}- [{sec.title}](#{sec.anchor})")
    lines.append("")
    lines += markdown_sections(sections)
    return "\n".join(lines).rstrip() + "\n"


def markdown_sections(sections: list[Section], figures: str = "figures/", top: int = 2) -> list[str]:
    """The lines of every section and its descendants in Markdown, the sections' headings at level ``top``; a
    figure is the PNG ``<figures><name>.png``."""
    lines: list[str] = []
    for level, sec in (x for s in sections for x in s.walk(top)):
        lines += [f'{"#" * level} <a id="{sec.anchor}"></a>{sec.title}', ""]
        for b in sec.blocks:
            if isinstance(b, Text):
                lines += [b.text, ""]
            elif isinstance(b, Bullets):
                lines += [*(f"- {i}" for i in b.items), ""]
            elif isinstance(b, Table):
                if b.caption:
                    lines += [f"*{b.caption}*", ""]
                lines.append("| " + " | ".join(_md_cell(h) for h in b.header) + " |")
                lines.append("|" + "|".join("---" for _ in b.header) + "|")
                lines += ["| " + " | ".join(_md_cell(c) for c in r) + " |" for r in b.rows]
                lines.append("")
                for note in b.footnotes:
                    lines += [note, ""]
            elif isinstance(b, Plot):
                lines += [f"![{_md_cell(b.caption)}]({figures}{b.name}.png)", ""]
    return lines


def plots_of(sections: list[Section]) -> list[Plot]:
    return [b for s in sections for _, sec in s.walk() for b in sec.blocks if isinstance(b, Plot)]


def render_pngs(plots: list[Plot], jobs: int = 1) -> list[bytes]:
    """:func:`render_png` of every plot, in ``jobs`` forked processes when more than 1 (the same bytes: Agg
    draws deterministically, and a plot's ``draw`` is a closure, so the workers inherit it by forking)."""
    from locbench.report.forked import forked_map

    # the largest canvases first (a grid of 30 panels takes as long as a dozen single figures), so no worker
    # is left with one at the end
    order = sorted(range(len(plots)), key=lambda i: -plots[i].size[0] * plots[i].size[1])
    return forked_map([partial(render_png, p) for p in plots], jobs, order)


def figure_pngs(sections: list[Section], jobs: int = 1) -> dict[str, bytes]:
    """Every plot of the sections drawn to PNG bytes, by name (the file ``figures/<name>.png``); ``jobs``
    processes draw them (:func:`render_pngs`)."""
    plots = plots_of(sections)
    names: set[str] = set()
    for plot in plots:
        if plot.name in names:
            raise ValueError(f"two figures named {plot.name!r}")
        names.add(plot.name)
    return {plot.name: data for plot, data in zip(plots, render_pngs(plots, jobs), strict=True)}


def _drawn(fig: Figure) -> None:
    """The draw function of a plot drawn already in a worker of :func:`build_and_draw` (its PNG is kept)."""
    raise RuntimeError("this plot was drawn in a worker process; its PNG is in the report's figures")


def _build_and_draw(builder: Callable[[], Section | None]) -> tuple[Section | None, dict[str, bytes]]:
    """Build a section and draw its plots: the section (each plot's ``draw`` replaced by :func:`_drawn`, since a
    closure does not pickle) and its PNGs by name."""
    sec = builder()
    if sec is None:
        return None, {}
    pngs: dict[str, bytes] = {}
    for _, part in sec.walk():
        for j, b in enumerate(part.blocks):
            if isinstance(b, Plot):
                pngs[b.name] = render_png(b)
                part.blocks[j] = dataclasses.replace(b, draw=_drawn)
    return sec, pngs


def build_and_draw(
    builders: list[Callable[[], Section | None]], jobs: int = 1
) -> tuple[list[Section | None], dict[str, bytes]]:
    """Every section of ``builders`` (in their order) and every plot of them drawn to PNG bytes, by name.

    With ``jobs`` > 1, forked processes build the sections and draw each one's plots where it was built
    (:func:`locbench.report.forked.forked_map`: the builders and draw functions are closures over the report),
    started in reverse reading order: the appendix and the experiments' pages, which hold most of the tables and
    figures, first, so that no worker is left with one of them at the end. The sections and PNGs do not depend on
    ``jobs``.
    """
    from locbench.report.forked import forked_map

    if jobs <= 1 or len(builders) < 2:
        sections = [b() for b in builders]
        return sections, figure_pngs([s for s in sections if s is not None])
    built = forked_map([partial(_build_and_draw, b) for b in builders], jobs, range(len(builders))[::-1])
    pngs: dict[str, bytes] = {}
    for _, drawn in built:
        for name, data in drawn.items():
            if name in pngs:
                raise ValueError(f"two figures named {name!r}")
            pngs[name] = data
    return [sec for sec, _ in built], pngs


# --- HTML -------------------------------------------------------------------------------------------

_INLINE = re.compile(r"(\*\*(.+?)\*\*)|(`([^`]+)`)|(\*([^*]+)\*)")


def _inline(text: str) -> str:
    """Markdown-flavoured cell text to HTML: ``code``, **bold** and *italic* spans, the rest escaped."""
    out, pos = [], 0
    for m in _INLINE.finditer(text):
        out.append(html.escape(text[pos : m.start()]))
        if m.group(1):
            out.append(f"<strong>{_inline(m.group(2))}</strong>")
        elif m.group(3):
            out.append(f"<code>{html.escape(m.group(4))}</code>")
        else:
            out.append(f"<em>{html.escape(m.group(6))}</em>")
        pos = m.end()
    out.append(html.escape(text[pos:]))
    return "".join(out)


_CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",sans-serif;max-width:1250px;margin:0 auto;padding:1em 2em;
color:#1a1a1a;line-height:1.45}
h1{border-bottom:2px solid #0072B2}h2{border-bottom:1px solid #ccc;margin-top:2em}
table{border-collapse:collapse;margin:.6em 0 1.2em;font-size:.86em}
th,td{border:1px solid #d0d0d0;padding:.25em .5em;vertical-align:top}
th{background:#eef3f8;cursor:pointer;user-select:none;position:sticky;top:0}
th.sorted-asc::after{content:" \\25B2"}th.sorted-desc::after{content:" \\25BC"}
tr:nth-child(even) td{background:#fafafa}caption{text-align:left;font-style:italic;padding:.2em 0}
code{font-size:.95em;background:#f3f3f3;padding:0 .2em}img{max-width:100%}
figure{margin:1em 0}figcaption{font-size:.85em;color:#444}
nav ul{columns:2}p.note{font-size:.85em;color:#333}
"""

# Sorting: a click on a header sorts its table by the cells' data-sort number (text where it has none);
# a second click reverses. Written for this page; no library needed for ten lines.
JS_SORT = """
document.querySelectorAll("table.sortable").forEach(function(tbl){
  tbl.querySelectorAll("th").forEach(function(th, col){
    th.addEventListener("click", function(){
      var body = tbl.tBodies[0], rows = Array.prototype.slice.call(body.rows);
      var asc = !th.classList.contains("sorted-asc");
      tbl.querySelectorAll("th").forEach(function(h){h.classList.remove("sorted-asc","sorted-desc");});
      th.classList.add(asc ? "sorted-asc" : "sorted-desc");
      function key(r){var c=r.cells[col]; var k=c.getAttribute("data-sort");
        return (k!==null && k!=="" && !isNaN(parseFloat(k))) ? [0, parseFloat(k)] : [1, c.textContent];}
      rows.sort(function(a,b){var x=key(a), y=key(b);
        if(x[0]!==y[0]) return x[0]-y[0];
        var r = x[0]===0 ? x[1]-y[1] : String(x[1]).localeCompare(String(y[1]));
        return asc ? r : -r;});
      rows.forEach(function(r){body.appendChild(r);});
    });
  });
});
"""


def _table_html(t: Table) -> str:
    parts = ['<table class="sortable">']
    if t.caption:
        parts.append(f"<caption>{_inline(t.caption)}</caption>")
    parts.append("<thead><tr>" + "".join(f"<th>{_inline(h)}</th>" for h in t.header) + "</tr></thead><tbody>")
    for i, row in enumerate(t.rows):
        keys = t.sort_keys[i] if i < len(t.sort_keys) else ()
        tips = t.hovers[i] if i < len(t.hovers) else ()
        cells = []
        for j, c in enumerate(row):
            k = keys[j] if j < len(keys) else float("nan")
            attr = (
                # 10 significant digits as in metrics.parquet: a rounding-level change leaves the page's bytes
                f' data-sort="{k:.10g}"'
                if k == k and abs(k) != float("inf")
                else (' data-sort="1e308"' if k == float("inf") else "")
            )
            if j < len(tips) and tips[j]:
                attr += f' title="{html.escape(tips[j])}"'
            cells.append(f"<td{attr}>{_inline(c)}</td>")
        parts.append("<tr>" + "".join(cells) + "</tr>")
    parts.append("</tbody></table>")
    parts += [f'<p class="note">{_inline(n)}</p>' for n in t.footnotes]
    return "\n".join(parts)


def to_html(title: str, intro: list[str], sections: list[Section], pngs: dict[str, bytes]) -> str:
    """One self-contained page: the same sections, sortable tables, PNGs inlined, plotly plots interactive."""
    from plotly.offline import get_plotlyjs

    body: list[str] = [f"<h1>{html.escape(title)}</h1>", *(f"<p>{_inline(p)}</p>" for p in intro)]
    body += contents_html(sections)

    def src(name: str) -> str:
        return "data:image/png;base64," + base64.b64encode(pngs[name]).decode()

    body += html_sections(sections, src)
    uses_plotly = any(b.interactive is not None for b in plots_of(sections))
    head = html_head(title)
    if uses_plotly:
        head.append(f"<script>{_script_safe(get_plotlyjs())}</script>")
    tail = [f"<script>{JS_SORT}</script>"]
    if uses_plotly:
        tail.append(f"<script>{JS_PLOTS}</script>")
    return "\n".join([*head, "</head><body>", *body, *tail, "</body></html>"]) + "\n"


def contents_html(sections: list[Section], href: Callable[[str], str] = lambda a: f"#{a}") -> list[str]:
    """A table of contents of the sections and their descendants; ``href`` makes an anchor's link."""
    toc = ["<nav><h2>Contents</h2><ul>"]
    for level, sec in (x for s in sections for x in s.walk()):
        toc.append(
            f'<li style="margin-left:{(level - 2) * 1.2}em"><a href="{html.escape(href(sec.anchor))}">'
            f"{_inline(sec.title)}</a></li>"
        )
    toc.append("</ul></nav>")
    return toc


def html_head(title: str, css: str = "") -> list[str]:
    """The page's head up to its style (the caller closes it)."""
    return [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>{html.escape(title)}</title>",
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<style>{_CSS}{css}</style>",
    ]


def html_sections(sections: list[Section], src: Callable[[str], str], lazy: bool = False, top: int = 2) -> list[str]:
    """The HTML of every section and its descendants, the sections' headings at level ``top``; ``src`` gives a
    figure's image source from its name, ``lazy`` lets the browser load an image only as the reader reaches it."""
    body: list[str] = []
    loading = ' loading="lazy"' if lazy else ""
    for level, sec in (x for s in sections for x in s.walk(top)):
        body.append(f'<h{level} id="{sec.anchor}">{_inline(sec.title)}</h{level}>')
        for b in sec.blocks:
            if isinstance(b, Text):
                body.append(f"<p>{_inline(b.text)}</p>")
            elif isinstance(b, Bullets):
                body.append("<ul>" + "".join(f"<li>{_inline(i)}</li>" for i in b.items) + "</ul>")
            elif isinstance(b, Table):
                body.append(_table_html(b))
            elif isinstance(b, Plot):
                body.append(
                    f'<figure><img alt="{html.escape(b.caption)}"{loading} src="{html.escape(src(b.name))}">'
                    f"<figcaption>{_inline(b.caption)}</figcaption></figure>"
                )
                if b.interactive is not None:
                    div = f"plot-{b.name}"
                    spec = json.dumps(b.interactive, sort_keys=True, separators=(",", ":"))
                    body.append(
                        f"<details><summary>interactive version (zoom, hover, legend toggles)</summary>"
                        f'<div id="{html.escape(div)}" class="plotly-div"></div>'
                        f'<script type="application/json" data-target="{html.escape(div)}">{_script_safe(spec)}'
                        "</script></details>"
                    )
    return body


#: Draws each interactive plot when its <details> opens (a hidden div has no size to lay out in), with
#: ``Plotly`` already loaded.
JS_PLOTS = (
    "document.querySelectorAll('script[data-target]').forEach(function(s){"
    "var d=document.getElementById(s.getAttribute('data-target'));var spec=JSON.parse(s.textContent);"
    "var box=d.closest('details');box.addEventListener('toggle',function(){"
    "if(box.open&&!d.hasChildNodes()){Plotly.newPlot(d,spec.data,spec.layout,"
    "{responsive:true,displaylogo:false});}});});"
)


def _script_safe(text: str) -> str:
    """Text that cannot close the <script> element it is inlined in."""
    return text.replace("</", "<\\/")
