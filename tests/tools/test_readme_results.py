"""The documents' result numbers agree with the committed summary: every ``<!-- gen:NAME -->`` block of README.md and
the docs pages is what tools/docs/readme_results.py makes from results/summary (the tidy metrics and the report's
Markdown pages)."""

from __future__ import annotations

import functools

import pytest
import readme_results as tool


@functools.cache
def generated() -> dict[str, str]:
    return dict(tool.blocks(tool.read_metrics(tool.METRICS)))


def documents() -> str:
    """README.md and every docs page with generated blocks, joined."""
    return "\n".join(doc.read_text(encoding="utf-8") for doc in tool.DOCUMENTS)


def test_every_generated_block_of_the_documents_agrees_with_the_committed_summary() -> None:
    text = documents()
    names = [m.group("name") for m in tool.BLOCK.finditer(text)]
    assert "decision" in [m.group("name") for m in tool.BLOCK.finditer(tool.README.read_text(encoding="utf-8"))]
    # the tables and the values that drifted before (global localization, suite default's run count) are blocks
    assert {"office-summary", "kidnap", "consistency", "recorded", "global-laser", "suite-default-runs"} <= set(names)
    # the prose's numbers: run counts, the headline ratios, ranks, tuned changes, lost AUROC, Radish, claims
    prose = {"runs-all-ok", "runs-all-skipped", "ukf-ekf-update", "kld-update", "across-landmark-geometry"}
    prose |= {"tuned-findings", "lost-auroc", "radish-tracked", "librsf-ratio", "claim-room-ekf-below"}
    prose |= {"claims-000-verdict", "matched-band", "pareto-gate"}
    assert prose <= set(names)
    assert set(names) <= set(generated()), "a block of the README has no generator"
    assert tool.disagreements(text, generated()) == [], "run: python tools/docs/readme_results.py --write"


def test_the_history_holds_no_generated_block() -> None:
    """The history keeps the figures of its time: a generated block there would be rewritten to today's."""
    assert not [d for d in tool.DOCUMENTS if "history" in d.parts]


def test_a_number_that_disagrees_is_found() -> None:
    text = tool.render(documents(), generated())
    body = generated()["global-laser"]
    assert body in text and "median" in body
    edited = text.replace(body, body.replace("median ", "median 1"), 1)
    assert tool.disagreements(edited, generated()) == ["global-laser"]
    table = generated()["office-summary"]
    edited = text.replace(table, table.replace("| `ekf_landmarks` | ", "| `ekf_landmarks` | 9", 1))
    assert tool.disagreements(edited, generated()) == ["office-summary"]


def test_a_block_without_a_generator_is_an_error() -> None:
    with pytest.raises(KeyError, match="no generator for the block 'nope'"):
        tool.render("a <!-- gen:nope -->1<!-- /gen:nope --> b", generated())


def test_a_prose_number_that_disagrees_is_found() -> None:
    text = tool.render(documents(), generated())
    for name in ("lost-auroc", "claim-room-ekf-below", "across-landmark-geometry"):
        body = generated()[name]
        edited = text.replace(f"<!-- gen:{name} -->{body}", f"<!-- gen:{name} -->{body.replace('.', ',', 1)}", 1)
        assert tool.disagreements(edited, generated()) == [name]


def test_report_tables_are_read_by_section() -> None:
    report = (
        '## <a id="tuned"></a>Tuned\n\ntext\n\n| filter | value |\n|---|---|\n| `a` | **1.5** |\n| `b` | 2 |\n\n'
        "| x |\n|---|\n| y |\n"
        '## <a id="other"></a>Other\n\n| filter | value |\n|---|---|\n| `c` | 3 |\n'
    )
    tables = tool.md_tables(report, "tuned")
    assert [[next(iter(r.values())) for r in t] for t in tables] == [["`a`", "`b`"], ["y"]]
    assert tool.bold(tables[0][0]["value"]) and tool.plain(tables[0][0]["value"]) == "1.5"


def test_a_report_without_a_quoted_value_is_an_error_naming_it() -> None:
    report = tool.report_text()
    with pytest.raises(ValueError, match="the provenance's run counts"):
        tool.run_counts(report.replace("- runs: ", "- run counts: "))
    with pytest.raises(ValueError, match="claims start with 'The PF is at least as accurate'"):
        tool.claim_values(report.replace("| The PF is at least as accurate", "| The PF is as accurate"))
    with pytest.raises(ValueError, match="no section with the anchor 'summary-office'"):
        tool.office_report(report.replace('<a id="summary-office">', '<a id="summary-elsewhere">'))


def test_span_and_listed() -> None:
    assert tool.span([0.981, 0.992, 0.985]) == "0.981-0.992"
    assert tool.span([3.371, 3.374]) == "3.37"
    assert tool.listed(["a"]) == "a" and tool.listed(["a", "b", "c"]) == "a, b and c"


@pytest.mark.parametrize(
    ("spec", "expected"),
    [
        ("default kept", (1, 1)),
        ("ekf_landmarks[gate_prob=0.99]", (0, 1)),
        ("default kept in 2 of 5 folds", (2, 5)),
        ("default kept in 5 of 5 folds", (5, 5)),
    ],
)
def test_a_tuned_row_counts_its_studies_and_those_that_kept_the_default(spec: str, expected: tuple[int, int]) -> None:
    assert tool.kept_studies({"tuned spec": spec}) == expected
