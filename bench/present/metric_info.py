"""The metric tables of docs/protocols.md, generated from the metric declarations.

Every metric is declared once, in :data:`locbench.evaluate.metrics.METRICS` (its function and how it is shown); the
page lists each group of them (:data:`~locbench.evaluate.metrics.GROUPS`) in one table between the markers
``<!-- gen:metrics-<group> -->`` and ``<!-- /gen:metrics-<group> -->``. :func:`with_tables` fills them in;
``python -m locbench.present.metric_info docs/protocols.md`` rewrites the page, and a test checks that it holds what
the declarations give.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

from locbench.evaluate.metrics import GROUPS, METRICS, Metric


def _cell(text: str) -> str:
    """Text for a Markdown table cell: a ``|`` escaped, so it does not end the cell."""
    return text.replace("|", "\\|")


def _better(m: Metric) -> str:
    if m.better == "closer":
        return f"closest to {m.target:g}"
    return m.better or "-"


def metric_table(group: str) -> str:
    """The Markdown table of the metrics declared in ``group``, in declaration order (an empty string for none).

    Columns: the id, its definition, its unit in ``metrics.parquet``, the unit the report shows it in, which way is
    better, and whether the summary table has it.
    """
    rows = [m for m in METRICS.values() if m.group == group]
    if not rows:
        return ""
    lines = [
        "| metric id | definition | unit in `metrics.parquet` | shown as | better | summary |",
        "|---|---|---|---|---|---|",
    ]
    for m in rows:
        cells = (
            f"`{m.id}`",
            m.definition,
            m.unit or "-",
            m.display_unit or "-",
            _better(m),
            "yes" if m.summary else "",
        )
        lines.append("| " + " | ".join(_cell(c) for c in cells) + " |")
    return "\n".join(lines)


def _markers(group: str) -> tuple[str, str]:
    key = group.replace(" ", "-")
    return f"<!-- gen:metrics-{key} -->", f"<!-- /gen:metrics-{key} -->"


def with_tables(text: str) -> str:
    """``text`` (docs/protocols.md) with the table of every group written between its markers.

    Raises
    ------
    ValueError
        When a group that has metrics has no markers (or more than one pair) in ``text``.
    """
    for group in GROUPS:
        table = metric_table(group)
        start, end = _markers(group)
        pattern = re.compile(re.escape(start) + r"\n.*?" + re.escape(end), re.DOTALL)
        found = len(pattern.findall(text))
        if not table and not found:
            continue
        if found != 1:
            raise ValueError(f"the page needs one '{start}' ... '{end}' block for the metrics of group {group!r}")
        m = pattern.search(text)
        assert m is not None
        text = f"{text[: m.start()]}{start}\n{table}\n{end}{text[m.end() :]}"
    return text


def main(argv: list[str]) -> int:
    """Rewrite the metric tables of the page(s) named in ``argv`` in place."""
    if not argv:
        print("usage: python -m locbench.present.metric_info docs/protocols.md", file=sys.stderr)
        return 2
    for name in argv:
        path = Path(name)
        text = path.read_text(encoding="utf-8")
        new = with_tables(text)
        if new != text:
            path.write_text(new, encoding="utf-8")
            print(f"rewrote the metric tables of {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
