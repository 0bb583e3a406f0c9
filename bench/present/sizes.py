"""The sizes of a written report, measured from its files, for the docs' generated blocks.

``python -m locbench.present.sizes [SUMMARY] PAGE.md ...`` fills the block between ``<!-- gen:report-sizes -->``
and ``<!-- /gen:report-sizes -->`` of each page with the sizes of the files in ``SUMMARY`` (default
``results/summary``): a size stated in the docs is the one of the files beside it, never a remembered number.
"""

from __future__ import annotations

import sys
from pathlib import Path

START, END = "<!-- gen:report-sizes -->", "<!-- /gen:report-sizes -->"


def _mb(n: int) -> str:
    return f"{n / 1e6:.1f} MB"


def sizes_text(summary: Path, shown: str | None = None) -> str:
    """One sentence with the sizes of the report's files (MB, 10^6 bytes), measured from ``summary`` (named
    ``shown`` in the sentence; default its path): the landing page, the figures, the other pages (their count
    and the largest), the plotly.js bundle, the tidy metrics and the folder in all."""
    page = summary / "index.html"
    pngs = sorted((summary / "figures").glob("*.png"))
    parts = [f"`index.html` {_mb(page.stat().st_size)}" if page.is_file() else "no `index.html`"]
    parts.append(f"{len(pngs)} figures of {_mb(sum(p.stat().st_size for p in pngs))} in `figures/`")
    others = sorted((p.stat().st_size, p.name) for p in summary.glob("*.html") if p.name != "index.html")
    if others:
        size, name = max(others)
        parts.append(f"{len(others)} other pages of at most {_mb(size)} (`{name}`)")
    for name in ("assets/plotly.min.js", "metrics.parquet", "metrics.csv"):
        if (summary / name).is_file():
            parts.append(f"`{name}` {_mb((summary / name).stat().st_size)}")
    total = sum(p.stat().st_size for p in summary.rglob("*") if p.is_file())
    return f"Measured from `{shown or summary.as_posix()}`: " + ", ".join(parts) + f"; {_mb(total)} in all."


def with_sizes(text: str, summary: Path) -> str:
    """``text`` with its generated block of sizes filled in (unchanged when it has none)."""
    if START not in text or END not in text:
        return text
    head, rest = text.split(START, 1)
    _, tail = rest.split(END, 1)
    return f"{head}{START}{sizes_text(summary)}{END}{tail}"


def main(argv: list[str]) -> int:
    """Rewrite the size blocks of the pages named in ``argv`` (the first argument a folder: the summary to measure)."""
    summary = Path("results/summary")
    if argv and Path(argv[0]).is_dir():
        summary, argv = Path(argv[0]), argv[1:]
    if not argv:
        print("usage: python -m locbench.present.sizes [SUMMARY] PAGE.md ...", file=sys.stderr)
        return 2
    for name in argv:
        path = Path(name)
        path.write_text(with_sizes(path.read_text(encoding="utf-8"), summary), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
