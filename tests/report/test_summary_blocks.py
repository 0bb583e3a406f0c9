"""The summary table as a reader meets it: defaults and sweeps in two blocks, long names short with the full spec
on hover and in a footnote; and the sizes the docs state, measured from the files."""

from __future__ import annotations

from pathlib import Path

from locbench.present.sizes import END, START, main, with_sizes
from locbench.report import figures as fg
from locbench.report.doc import Table
from locbench.report.sections.summary import split_blocks


def _table() -> Table:
    rows = (("`odometry`", "1"), ("`pf`", "2"), ("`pf[particles=100]`", "3"), ("`pcrb`", "4"))
    keys = tuple((float("nan"), float(i)) for i in range(4))
    hovers = tuple(("", f"h{i}") for i in range(4))
    return Table(("filter", "ATE"), rows, caption="c", footnotes=("n",), sort_keys=keys, hovers=hovers)


def test_defaults_and_sweeps_are_two_blocks_with_their_own_rows() -> None:
    first, second = split_blocks(_table(), [True, True, False, True])
    assert [r[0] for r in first.rows] == ["`odometry`", "`pf`", "`pcrb`"]
    assert [r[0] for r in second.rows] == ["`pf[particles=100]`"]
    assert [h[1] for h in first.hovers] == ["h0", "h1", "h3"] and second.hovers == (("", "h2"),)
    assert second.footnotes == ("n",) and "sweeps" in second.caption and "default" in first.caption
    # nothing to split: the table as it is
    whole = _table()
    assert split_blocks(whole, [True] * 4) == (whole,) and split_blocks(whole, [True] * 4)[0] is whole


def test_a_short_name_is_stable_across_figures_and_tables() -> None:
    long = "ekf_icp[correspondence_sigmas=5.657,max_iterations=580,r_theta_rad2=0.0607]"
    alone = fg.short_names([long])[long]
    among = fg.short_names(["pf", "ekf_icp[max_iterations=5]", long])[long]
    assert alone == among == fg.short_name(long) and alone.startswith("ekf_icp[#")


def test_sizes_are_measured_from_the_files(tmp_path: Path) -> None:
    summary = tmp_path / "summary"
    (summary / "figures").mkdir(parents=True)
    (summary / "index.html").write_bytes(b"x" * 2_500_000)
    (summary / "figures" / "a.png").write_bytes(b"x" * 300_000)
    (summary / "figures" / "b.png").write_bytes(b"x" * 200_000)
    (summary / "claims.html").write_bytes(b"x" * 100_000)
    (summary / "metrics.parquet").write_bytes(b"x" * 1_200_000)
    page = tmp_path / "page.md"
    page.write_text(f"before\n{START}old{END}\nafter\n")
    assert main([str(summary), str(page)]) == 0
    text = page.read_text()
    assert "`index.html` 2.5 MB, 2 figures of 0.5 MB" in text and "old" not in text
    assert "1 other pages of at most 0.1 MB (`claims.html`)" in text and "`metrics.parquet` 1.2 MB" in text
    assert "; 4.3 MB in all." in text
    assert text.startswith("before\n") and text.endswith("\nafter\n")
    assert with_sizes("no block", summary) == "no block"


def test_a_pick_from_fewer_seeds_says_so() -> None:
    from test_report import _per_seed, _summary_of

    rows = _per_seed({"odometry": {"ate_m": 0.5}, "pf": {"ate_m": 0.03}}, seeds=8)
    rows += _per_seed({"pf[particles=3000]": {"ate_m": 0.01}}, seeds=3)
    text, _ = _summary_of(rows)
    assert "`pf[particles=3000]` (ATE 1" in text.text  # type: ignore[attr-defined]
    assert "from 3 seeds where others have up to 8" in text.text  # type: ignore[attr-defined]
    # the same seeds everywhere: nothing to say
    text, _ = _summary_of(_per_seed({"odometry": {"ate_m": 0.5}, "pf": {"ate_m": 0.03}}, seeds=8))
    assert "seeds where" not in text.text  # type: ignore[attr-defined]
