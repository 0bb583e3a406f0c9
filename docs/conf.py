"""Sphinx configuration of the locbench documentation (built by ``nox -s docs``, warnings as errors)."""

from __future__ import annotations

import locbench

project = "locbench"
author = "the locbench developers"
copyright = "2026, the locbench developers"
release = locbench.__version__ if hasattr(locbench, "__version__") else ""

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "numpydoc",
]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
myst_enable_extensions = ["dollarmath", "colon_fence", "deflist"]
myst_heading_anchors = 3
exclude_patterns = ["_build"]
html_theme = "pydata_sphinx_theme"
# the members are documented by autodoc itself; numpydoc's member tables would need autosummary stub pages
numpydoc_show_class_members = False
autodoc_member_order = "bysource"
nitpicky = False

import re  # noqa: E402

from sphinx.application import Sphinx  # noqa: E402

#: ``|x|`` in a docstring: plain-text math (an absolute value or a norm), which reST would read as a substitution.
_BARS = re.compile(r"(?<![\\`|])\|(?=[^\s|])([^|\n`]*?[^\s|\\])\|(?![|_`])")


def _escape_bars(app: Sphinx, what: str, name: str, obj: object, options: object, lines: list[str]) -> None:
    """Escape the docstrings' absolute-value bars so that they print as written (table rows are left alone)."""
    for i, line in enumerate(lines):
        row = line.strip()
        if not (row.startswith("|") and row.endswith("|") and row.count("|") > 2) and not row.startswith("+-"):
            lines[i] = _BARS.sub(r"\\|\1\\|", line)


def setup(app: Sphinx) -> None:
    app.connect("autodoc-process-docstring", _escape_bars, priority=400)
