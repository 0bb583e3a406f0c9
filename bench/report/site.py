"""The report as a small static site: a landing page, one page per main comparison, experiment, analysis,
recorded group and appendix part, the same navigation on each, and each page's Markdown twin.

Which section goes on which page is decided here, from the sections' anchors alone (the report names no dataset
or filter): the summary (the decision tables) and the accuracy-against-runtime fronts are the landing page
(``index.html``, in Markdown ``REPORT.md``); a section with sub-sections that would make a long page (the recorded
data, the appendix) becomes a short page of its own text with one page per sub-section; every other top-level
section is one page (``<anchor>.html``, in Markdown ``md/<anchor>.md``). Pages link the PNGs in ``figures/``
(loaded lazily, as the reader scrolls to them) and, on a page with an interactive plot, load ``assets/plotly.min.js``
(written once) when the reader first opens one: the site works offline from ``file://``.

Sizes are part of the contract (:data:`LANDING_MAX_BYTES`, :data:`PAGE_MAX_BYTES`, :data:`REPORT_MD_MAX_LINES`):
:func:`oversize` lists what exceeds them, the report logs it and a test checks a store stays within.
"""

from __future__ import annotations

import html
import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

from locbench.report.doc import Section, Table, Text
from locbench.report.render import (
    JS_SORT,
    _inline,
    _script_safe,
    contents_html,
    html_head,
    html_sections,
    markdown_sections,
    plots_of,
)

#: The landing page's largest size (bytes), its figures not counted (they are files beside it).
LANDING_MAX_BYTES = 2_000_000
#: Any other page's largest size (bytes).
PAGE_MAX_BYTES = 6_000_000
#: ``REPORT.md``'s most lines (the landing page in Markdown).
REPORT_MD_MAX_LINES = 600
#: The plotly.js bundle, one file beside the pages.
PLOTLY_JS = "assets/plotly.min.js"
#: Anchors of the top-level sections on the landing page: the decision tables and the accuracy-runtime fronts.
LANDING = ("summary", "pareto")
#: Top-level sections whose sub-sections are pages of their own (each would make a long page).
SPLIT = ("recorded", "appendix")
#: Navigation groups, in order.
GROUPS = ("Decision", "Main comparisons", "Experiments and claims", "Analysis", "Recorded data", "Appendix")


@dataclass
class Page:
    """One page of the site: its file stem, title, navigation group and sections."""

    name: str
    title: str
    group: str
    sections: list[Section] = field(default_factory=list)

    @property
    def html_file(self) -> str:
        """The page's file, relative to the summary folder."""
        return "index.html" if self.name == "index" else f"{self.name}.html"

    @property
    def md_file(self) -> str:
        """The page's Markdown file, relative to the summary folder."""
        return "REPORT.md" if self.name == "index" else f"md/{self.name}.md"


def _stem(anchor: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]", "-", anchor).strip(".-") or "page"


def _group(sec: Section, mains: set[str]) -> str:
    a = sec.anchor
    if (a.startswith("exp-") and a[4:] in mains) or a.startswith("own-"):
        return "Main comparisons"
    if a.startswith("exp-") or a == "claims":
        return "Experiments and claims"
    return "Analysis"


def paginate(sections: list[Section]) -> list[Page]:
    """The site's pages, the landing page first, then by navigation group in the sections' order.

    The main comparisons are the datasets of the summary's tables (``summary-<slug>``), whose experiment
    sections (``exp-<slug>``) get the group "Main comparisons".
    """
    summary = next((s for s in sections if s.anchor == "summary"), None)
    mains = {c.anchor.removeprefix("summary-") for c in summary.children} if summary else set()
    landing = Page("index", "Which filter?", "Decision", [s for s in sections if s.anchor in LANDING])
    pages: list[Page] = []
    for sec in sections:
        if sec.anchor in LANDING:
            continue
        if sec.anchor in SPLIT and sec.children:
            group = "Recorded data" if sec.anchor == "recorded" else "Appendix"
            pages.append(Page(_stem(sec.anchor), sec.title, group, [Section(sec.title, sec.anchor, sec.blocks)]))
            pages += [Page(_stem(c.anchor), c.title, group, [c]) for c in sec.children]
        else:
            pages.append(Page(_stem(sec.anchor), sec.title, _group(sec, mains), [sec]))
    names = [p.name for p in pages]
    for n in names:
        if names.count(n) > 1 or n == "index":
            raise ValueError(f"two pages named {n!r}")
    return [landing, *sorted(pages, key=lambda p: GROUPS.index(p.group))]


def anchors(pages: list[Page]) -> dict[str, Page]:
    """Every section anchor with the page that holds it."""
    return {sec.anchor: p for p in pages for s in p.sections for _, sec in s.walk()}


def findings(pages: list[Page]) -> list[str]:
    """One line per main finding, each linking its page (Markdown links to the HTML pages, rewritten for the
    Markdown files by :func:`_md_links`): each decision table's first recommendation, the claims' verdicts."""
    where = anchors(pages)
    out: list[str] = []
    for level, sec in (x for s in pages[0].sections for x in s.walk()):
        if level != 3 or not sec.anchor.startswith("summary-"):
            continue
        text = next((b.text for b in sec.blocks if isinstance(b, Text)), "")
        first = text.split(": ", 1)[-1].split("; ")[0].split(". ")[0].rstrip(".")
        slug = sec.anchor.removeprefix("summary-")
        target = where.get(f"exp-{slug}") or where.get(f"own-{slug}")
        link = f"[{sec.title}]({target.html_file})" if target else f"[{sec.title}](#{sec.anchor})"
        if first:
            out.append(f"{link}: {first}.")
    claims = where.get("claims")
    if claims is not None:
        table = next((b for s in claims.sections for b in s.blocks if isinstance(b, Table)), None)
        if table is not None:
            verdicts = [r[2].replace("**", "") for r in table.rows]
            counts = ", ".join(f"{verdicts.count(v)} {v}" for v in sorted(set(verdicts)))
            out.append(f"[{claims.title}]({claims.html_file}): {counts}.")
    return out


# --- HTML ---------------------------------------------------------------------------------------------------

_SITE_CSS = """
nav.site{border-bottom:1px solid #ccc;padding:.3em 0 .6em;font-size:.88em;display:flex;flex-wrap:wrap;gap:.2em 1.4em}
nav.site div{max-width:100%}nav.site b{margin-right:.4em}nav.site a{margin-right:.6em;white-space:nowrap}
nav.site a[aria-current]{font-weight:bold;color:#1a1a1a;text-decoration:none}
"""

# Loads plotly.js (one file beside the pages) on the first opened interactive plot, then draws each plot when its
# <details> opens (a hidden div has no size to lay out in).
_JS_LAZY_PLOTS = (
    "(function(){var waiting=[],state=0;function need(f){if(window.Plotly){f();return;}waiting.push(f);"
    "if(state)return;state=1;var t=document.createElement('script');t.src=document.body.getAttribute('data-plotly');"
    "t.onload=function(){waiting.splice(0).forEach(function(g){g();});};document.head.appendChild(t);}"
    "document.querySelectorAll('script[data-target]').forEach(function(s){"
    "var d=document.getElementById(s.getAttribute('data-target'));var box=d.closest('details');"
    "box.addEventListener('toggle',function(){if(box.open&&!d.hasChildNodes()){need(function(){"
    "if(d.hasChildNodes())return;var spec=JSON.parse(s.textContent);Plotly.newPlot(d,spec.data,spec.layout,"
    "{responsive:true,displaylogo:false});});}});});})();"
)


def navigation(pages: list[Page], current: Page) -> str:
    """The site's navigation, the same on every page (the current page marked)."""
    parts = ['<nav class="site" aria-label="pages">']
    for g in GROUPS:
        members = [p for p in pages if p.group == g]
        if not members:
            continue
        mark = ' aria-current="page"'
        links = [f'<a href="{p.html_file}"{mark if p is current else ""}>{_inline(p.title)}</a>' for p in members]
        parts.append(f"<div><b>{html.escape(g)}</b>{''.join(links)}</div>")
    parts.append("</nav>")
    return "".join(parts)


def _top_level(page: Page) -> int:
    """The heading level of a page's sections: 1 for a page that is one section of its own title (its heading is
    the page's, not repeated under it), else 2 under the page's title."""
    return 1 if page.name != "index" and len(page.sections) == 1 and page.sections[0].title == page.title else 2


def page_html(site_title: str, pages: list[Page], page: Page, intro: Iterable[str] = ()) -> str:
    """One page of the site: navigation, title, the page's sections (figures as lazy images in ``figures/``)."""
    where = anchors(pages)

    def href(anchor: str) -> str:
        target = where[anchor]
        return f"#{anchor}" if target is page else f"{target.html_file}#{anchor}"

    title = site_title if page.name == "index" else f"{page.title} - {site_title}"
    uses_plotly = any(b.interactive is not None for b in plots_of(page.sections))
    top = _top_level(page)
    heading = [] if top == 1 else [f"<h1>{html.escape(title)}</h1>"]
    body = [navigation(pages, page), *heading, *(f"<p>{_md_html(p)}</p>" for p in intro)]
    if page.name == "index":
        body += ["<h2>Main findings</h2>", "<ul>", *(f"<li>{_md_html(f)}</li>" for f in findings(pages)), "</ul>"]
    if page.name != "index" and sum(len(s.walk()) for s in page.sections) > 1:
        body += contents_html(page.sections, href)
    body += html_sections(page.sections, lambda name: f"figures/{name}.png", lazy=True, top=top)
    split = [p for p in pages if p.group == page.group and p is not page and page.sections[0].anchor in SPLIT]
    if split:
        body.append(
            "<ul>" + "".join(f'<li><a href="{p.html_file}">{_inline(p.title)}</a></li>' for p in split) + "</ul>"
        )
    plot_attr = f' data-plotly="{PLOTLY_JS}"' if uses_plotly else ""
    tail = [f"<script>{JS_SORT}</script>"]
    if uses_plotly:
        tail.append(f"<script>{_script_safe(_JS_LAZY_PLOTS)}</script>")
    return (
        "\n".join([*html_head(title, _SITE_CSS), "</head>", f"<body{plot_attr}>", *body, *tail, "</body></html>"])
        + "\n"
    )


_MD_LINK = re.compile(r"\[([^\]]+)\]\(([^)\s]+)\)")


def _md_html(text: str) -> str:
    """Inline Markdown with links to HTML: the link's text formatted as a cell, the rest as :func:`_inline`."""
    out, pos = [], 0
    for m in _MD_LINK.finditer(text):
        out.append(_inline(text[pos : m.start()]))
        out.append(f'<a href="{html.escape(m.group(2))}">{_inline(m.group(1))}</a>')
        pos = m.end()
    out.append(_inline(text[pos:]))
    return "".join(out)


# --- Markdown -----------------------------------------------------------------------------------------------


def _md_links(text: str, pages: list[Page], page: Page) -> str:
    """The Markdown links of a text pointed at the Markdown files instead of the HTML pages."""
    by_html = {p.html_file: p for p in pages}

    def one(m: re.Match[str]) -> str:
        file, _, frag = m.group(2).partition("#")
        target = by_html.get(file)
        if target is None:
            return m.group(0)
        return f"[{m.group(1)}]({_md_rel(page, target)}{'#' + frag if frag else ''})"

    return _MD_LINK.sub(one, text)


def _md_rel(src: Page, dst: Page) -> str:
    """The relative path from one Markdown page to another (``REPORT.md`` at the top, the others in ``md/``)."""
    if src.name == "index":
        return dst.md_file
    return "../REPORT.md" if dst.name == "index" else dst.md_file.removeprefix("md/")


def page_markdown(site_title: str, pages: list[Page], page: Page, intro: Iterable[str] = ()) -> str:
    """One page in Markdown: a line of links to every page, the title, the page's sections."""
    nav = " | ".join(p.title if p is page else f"[{p.title}]({_md_rel(page, p)})" for p in pages)
    title = site_title if page.name == "index" else f"{page.title} - {site_title}"
    top = _top_level(page)
    lines = [] if top == 1 else [f"# {title}", ""]
    lines += [p for para in intro for p in (para, "")]
    if page.name == "index":
        lines += ["## Main findings", "", *(f"- {_md_links(f, pages, page)}" for f in findings(pages)), ""]
        lines += ["## Pages", ""]
        for g in GROUPS:
            members = [p for p in pages if p.group == g and p is not page]
            if members:
                lines.append(f"- {g}: " + ", ".join(f"[{p.title}]({_md_rel(page, p)})" for p in members))
        lines.append("")
    else:
        lines = [nav, "", *lines]
    figures = "figures/" if page.name == "index" else "../figures/"
    lines += markdown_sections(page.sections, figures, top=top)
    split = [p for p in pages if p.group == page.group and p is not page and page.sections[0].anchor in SPLIT]
    lines += [f"- [{p.title}]({_md_rel(page, p)})" for p in split]
    return "\n".join(lines).rstrip() + "\n"


# --- the site -----------------------------------------------------------------------------------------------


def site_files(site_title: str, intro: list[str], sections: list[Section]) -> dict[str, bytes]:
    """Every page of the site in HTML and Markdown, and the plotly.js bundle when a page has an interactive
    plot, by path relative to the summary folder (the figures are written by the caller)."""
    pages = paginate(sections)
    out: dict[str, bytes] = {}
    for p in pages:
        words = intro if p.name == "index" else ()
        out[p.html_file] = page_html(site_title, pages, p, words).encode()
        out[p.md_file] = page_markdown(site_title, pages, p, words).encode()
    if any(b.interactive is not None for b in plots_of(sections)):
        from plotly.offline import get_plotlyjs

        out[PLOTLY_JS] = get_plotlyjs().encode()
    return out


def oversize(files: dict[str, bytes]) -> list[str]:
    """What exceeds the site's limits: the landing page over :data:`LANDING_MAX_BYTES`, another page over
    :data:`PAGE_MAX_BYTES`, ``REPORT.md`` over :data:`REPORT_MD_MAX_LINES` lines (empty when all are within)."""
    out = []
    for rel, data in sorted(files.items()):
        if rel == "index.html" and len(data) > LANDING_MAX_BYTES:
            out.append(f"{rel}: {len(data)} bytes > {LANDING_MAX_BYTES}")
        elif rel.endswith(".html") and len(data) > PAGE_MAX_BYTES:
            out.append(f"{rel}: {len(data)} bytes > {PAGE_MAX_BYTES}")
        elif rel == "REPORT.md" and (lines := data.count(b"\n")) > REPORT_MD_MAX_LINES:
            out.append(f"{rel}: {lines} lines > {REPORT_MD_MAX_LINES}")
    return out


def site_markdown(folder: Path) -> str:
    """Every Markdown page of a written site joined, the landing page first: to find a section wherever its page is."""
    return "\n".join(
        p.read_text(encoding="utf-8") for p in [folder / "REPORT.md", *sorted((folder / "md").glob("*.md"))]
    )


def site_html(folder: Path) -> str:
    """Every HTML page of a written site joined, the landing page first."""
    pages = [folder / "index.html", *sorted(p for p in folder.glob("*.html") if p.name != "index.html")]
    return "\n".join(p.read_text(encoding="utf-8") for p in pages)


__all__ = [
    "LANDING_MAX_BYTES",
    "PAGE_MAX_BYTES",
    "PLOTLY_JS",
    "REPORT_MD_MAX_LINES",
    "Page",
    "anchors",
    "findings",
    "navigation",
    "oversize",
    "page_html",
    "page_markdown",
    "paginate",
    "site_files",
    "site_html",
    "site_markdown",
]
