"""The site's pages: which section goes on which page, the navigation, the Markdown twins' links."""

from __future__ import annotations

from locbench.report.doc import Section, Table, Text
from locbench.report.site import findings, page_html, page_markdown, paginate


def _sections() -> list[Section]:
    summary = Section("Summary", "summary")
    summary.children.append(
        Section("Main A", "summary-a", [Text("Which to use: with x, `f` (ATE 1 cm); with y, `g`.")])
    )
    claims = Section("Claims", "claims", [Table(("report", "claim", "verdict"), (("r", "c", "**reproduced**"),))])
    recorded = Section("Recorded data", "recorded", [Text("intro")])
    recorded.children += [Section("Reference: GPS", "recorded-GPS"), Section("Robustness", "recorded-robustness")]
    return [
        summary,
        Section("Across datasets", "across", [Text("ranks")]),
        claims,
        Section("Accuracy against runtime", "pareto", [Text("fronts")]),
        recorded,
        Section("Main A", "exp-a", [Text("a")]),
        Section("Experiment B", "exp-b", [Text("b")]),
        Section("Generalization", "generalization", [Text("new analysis")]),
        Section("Appendix", "appendix", children=[Section("Provenance", "provenance", [Text("p")])]),
    ]


def test_pages_by_group_landing_first() -> None:
    pages = paginate(_sections())
    assert [(p.name, p.group) for p in pages] == [
        ("index", "Decision"),
        ("exp-a", "Main comparisons"),
        ("claims", "Experiments and claims"),
        ("exp-b", "Experiments and claims"),
        ("across", "Analysis"),
        ("generalization", "Analysis"),
        ("recorded", "Recorded data"),
        ("recorded-GPS", "Recorded data"),
        ("recorded-robustness", "Recorded data"),
        ("appendix", "Appendix"),
        ("provenance", "Appendix"),
    ]
    assert [s.anchor for s in pages[0].sections] == ["summary", "pareto"]
    assert [s.anchor for s in pages[6].sections] == ["recorded"] and not pages[6].sections[0].children


def test_findings_link_their_pages_and_markdown_links_the_markdown() -> None:
    pages = paginate(_sections())
    assert findings(pages) == ["[Main A](exp-a.html): with x, `f` (ATE 1 cm).", "[Claims](claims.html): 1 reproduced."]
    landing = page_markdown("T", pages, pages[0])
    assert "- [Main A](md/exp-a.md): with x" in landing and "](figures/" not in landing
    sub = page_markdown("T", pages, pages[7])
    assert sub.startswith("[Which filter?](../REPORT.md) | ") and "[Provenance](provenance.md)" in sub
    parent = page_markdown("T", pages, pages[6])
    assert "- [Reference: GPS](recorded-GPS.md)" in parent


def test_every_page_has_the_same_navigation() -> None:
    pages = paginate(_sections())
    navs = set()
    for p in pages:
        page = page_html("T", pages, p)
        nav = page[page.index('<nav class="site"') : page.index("</nav>")]
        assert nav.count('aria-current="page"') == 1 and f'href="{p.html_file}" aria-current' in nav
        navs.add(nav.replace(' aria-current="page"', ""))
        assert "assets/plotly.min.js" not in page  # no interactive plot here: no bundle named
    assert len(navs) == 1


def test_a_page_of_one_section_states_its_title_once() -> None:
    pages = paginate(_sections())
    for p in pages[1:]:
        page, md = page_html("T", pages, p), page_markdown("T", pages, p)
        assert page.count(f">{p.title}</h") == 1 and page.count("<h1") == 1, p.name
        assert f'<h1 id="{p.sections[0].anchor}">{p.title}</h1>' in page, p.name
        assert md.count(f"</a>{p.title}\n") == 1 and f'\n# <a id="{p.sections[0].anchor}"></a>' in md, p.name
    # the landing page keeps the site's title over its sections
    assert "<h1>T</h1>" in page_html("T", pages, pages[0])
