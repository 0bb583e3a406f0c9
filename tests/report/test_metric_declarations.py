"""A metric is one declaration: declared in one place, it reaches metrics.parquet, the summary table, the HTML page and
the docs' tables; the library names metrics by their constants."""

from __future__ import annotations

import ast
import re
from collections.abc import Iterator
from pathlib import Path

import pandas as pd
import pytest
from test_report import _fake_store

import locbench
from locbench.evaluate.metrics import FAILED, GROUPS, METRICS, Metric, RunView, align_run, declare, family_regex
from locbench.present.docfmt import num
from locbench.present.metric_info import main, metric_table, with_tables
from locbench.report import write_report
from locbench.report.sections.summary import OWN_COLUMNS, columns
from locbench.report.site import site_html, site_markdown

ROOT = Path(__file__).resolve().parents[2]
PROTOCOLS = ROOT / "docs" / "protocols.md"

TOY = "max_error_m"
TOY_NOTE = "Max error: the largest position error of a run, mean over its runs."


def _max_error(v: RunView) -> float:
    return float(v.aligned.position_error.max())


@pytest.fixture
def toy() -> Iterator[Metric]:
    """The documented path: one declaration, withdrawn after the test."""
    m = declare(
        Metric(
            TOY,
            header="max error",
            unit="m",
            display_unit="cm",
            scale=100.0,
            compute=_max_error,
            summary=True,
            note=TOY_NOTE,
            definition="largest position error over the ground-truth times",
        )
    )
    try:
        yield m
    finally:
        del METRICS[TOY]


def test_a_declared_metric_reaches_the_metrics_file_and_the_summary_table(toy: Metric, tmp_path: Path) -> None:
    store = _fake_store(tmp_path / "results")
    paths = write_report(store)
    csv = pd.read_parquet(paths.metrics)
    mine = csv[csv["metric"] == TOY].set_index(["filter", "seed"])["value"]
    ok = csv[(csv["metric"] == FAILED) & (csv["value"] == 0.0)].set_index(["filter", "seed"])
    assert sorted(mine.index) == sorted(ok.index) and len(mine) == 6  # every ok run, no other
    # its value is the declared function's on the stored run (the metrics file keeps 10 significant digits)
    run = store.read_run(store.run_dir("room", "odometry", 1))
    truth = store.read_truth("room", 1)
    expected = _max_error(RunView(run, truth, align_run(run, truth)))
    assert mine[("odometry", 1)] == pytest.approx(expected, rel=1e-9)

    (table,) = paths.summary
    assert table.header[-1] == "max error (cm)"  # the last metric declared for the summary: the last column
    rows = {r[0]: r for r in table.rows}
    for f in ("odometry", "ekf_landmarks"):
        want = num(100.0 * float(mine.loc[f].mean()))
        assert rows[f"`{f}`"][-1].replace("**", "") == want
    assert rows["`ekf_landmarks`"][-1].startswith("**")  # ranked: the best non-baseline value in bold
    assert not rows["`odometry`"][-1].startswith("**")
    assert TOY_NOTE in table.footnotes
    assert "max error (cm)" in site_markdown(paths.markdown.parent) and "max error (cm)" in site_html(paths.html.parent)


def test_without_the_declaration_there_is_no_such_row_or_column(tmp_path: Path) -> None:
    paths = write_report(_fake_store(tmp_path / "results"))
    assert TOY not in set(pd.read_parquet(paths.metrics)["metric"])
    (table,) = paths.summary
    assert "max error (cm)" not in table.header


def test_the_summary_columns_follow_the_declarations() -> None:
    shown = [m.id for m in METRICS.values() if m.summary]
    assert set(OWN_COLUMNS) <= set(shown)
    assert [c.metric for c in columns() if c.metric is not None] == shown


def test_the_docs_metric_tables_are_the_declarations() -> None:
    text = PROTOCOLS.read_text(encoding="utf-8")
    assert with_tables(text) == text, (
        "docs/protocols.md's metric tables differ from the declarations: "
        "python -m locbench.present.metric_info docs/protocols.md"
    )
    for m in METRICS.values():
        assert m.group in GROUPS and m.definition, m.id  # every built-in metric is on the page, defined
        assert f"| `{m.id}` |" in metric_table(m.group)


def test_the_docs_tables_need_their_markers(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="gen:metrics-run"):
        with_tables("# no markers\n")
    page = tmp_path / "page.md"
    text = PROTOCOLS.read_text(encoding="utf-8")
    page.write_text(text.replace("| `ate_m` |", "| `old_ate_m` |"), encoding="utf-8")
    assert main([str(page)]) == 0
    assert page.read_text(encoding="utf-8") == text


def _library_files() -> list[Path]:
    pkg = Path(locbench.__file__).parent
    return sorted(p for sub in ("evaluate", "present", "report", "claims") for p in (pkg / sub).rglob("*.py"))


def test_library_code_names_metrics_by_their_constants() -> None:
    """No metric id is written out as a string in the layers that read metrics, except where it is defined: the
    module-level constants of locbench.evaluate.metrics and .scores. ``failed`` is left out: it is also the status
    word the tables print."""
    exact = {m.id for m in METRICS.values() if not m.is_family} - {FAILED}
    families = [re.compile(family_regex(m.id)) for m in METRICS.values() if m.is_family]
    found = []
    for path in _library_files():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        defining = path.parent.name == "evaluate" and path.stem in ("metrics", "scores")
        allowed = (
            {id(n) for s in tree.body if isinstance(s, ast.Assign) for n in ast.walk(s.value)} if defining else set()
        )
        for node in ast.walk(tree):
            if not (isinstance(node, ast.Constant) and isinstance(node.value, str)) or id(node) in allowed:
                continue
            if node.value in exact or any(f.fullmatch(node.value) for f in families):
                found.append(f"{path.parent.name}/{path.name}:{node.lineno}: {node.value!r}")
    assert len(_library_files()) > 20 and not found, found
