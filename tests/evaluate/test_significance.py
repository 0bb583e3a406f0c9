"""The statistics of ``locbench.evaluate.significance`` against constructed data with known answers and Demsar's
example."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from locbench.evaluate import significance as sg
from locbench.evaluate.metrics import METRICS
from locbench.present.ranking import UNTESTED_FOOTNOTE, Column, mark_ties, tie_footnote
from locbench.registry import dataset_recording
from locbench.report.doc import Section, Table
from locbench.report.sections.paired_tests import dataset_groups, one_per_recording

SEEDS = 20


def test_identical_columns_are_never_significant() -> None:
    a = np.random.default_rng(0).normal(1.0, 0.1, SEEDS)
    res = sg.wilcoxon_paired(a, a.copy())
    assert res.p == 1.0 and res.n == SEEDS
    v = sg.ties_with_best([a.mean(), a.mean()], [dict(enumerate(a)), dict(enumerate(a))], [True, True], "lower")
    assert v.marked == {0, 1}


def test_a_constant_shift_over_20_seeds_is_significant() -> None:
    a = np.random.default_rng(1).normal(1.0, 0.1, SEEDS)
    res = sg.wilcoxon_paired(a + 0.01, a)
    # every |d| tied: the normal approximation with the tie correction, worked by hand
    var = SEEDS * (SEEDS + 1) * (2 * SEEDS + 1) / 24 - (SEEDS**3 - SEEDS) / 48
    z = (SEEDS * (SEEDS + 1) / 4) / math.sqrt(var)
    assert res.p == pytest.approx(2 * stats.norm.sf(z), rel=1e-9)
    assert res.p < 1e-4 and "normal approx" in res.method
    assert sg.wilcoxon_paired(a + 0.01, a, alternative="greater").p == pytest.approx(res.p / 2, rel=1e-9)
    assert sg.wilcoxon_paired(a + 0.01, a, alternative="less").p > 0.99


def test_exact_where_there_are_no_ties() -> None:
    d = np.arange(1.0, 11.0)
    res = sg.wilcoxon_paired(d, np.zeros(10))
    assert "exact" in res.method and res.p == pytest.approx(2 / 2**10)


def test_too_few_pairs_give_no_test() -> None:
    res = sg.wilcoxon_paired(np.arange(5.0) + 1, np.zeros(5))
    assert not res.tested and "no test possible (n = 5)" in res.text()
    assert sg.wilcoxon_paired(np.arange(5.0) + 1, np.zeros(5), alternative="greater").p == pytest.approx(1 / 32)


def test_holm_order_and_adjustment() -> None:
    # sorted: 0.005 x 4 = 0.02, 0.01 x 3 = 0.03, 0.03 x 2 = 0.06, 0.04 x 1 = 0.04 -> 0.06 (monotone)
    got = sg.holm([0.01, 0.04, 0.03, 0.005, math.nan])
    np.testing.assert_allclose(got[:4], [0.03, 0.06, 0.06, 0.02])
    assert math.isnan(got[4])
    np.testing.assert_allclose(sg.holm([0.3, 0.04]), [0.3, 0.08])
    assert sg.holm([0.9, 0.8]).tolist() == [1.0, 1.0]


def test_ties_with_best_marks_the_indistinguishable_and_not_the_different() -> None:
    rng = np.random.default_rng(2)
    base = rng.normal(3.4, 0.3, SEEDS)
    rows = {
        "best": base,
        "twin": base + rng.normal(0.0, 0.01, SEEDS),  # noise around the best: not different
        "worse": base + 1.0,  # a constant shift: different
    }
    samples = [dict(enumerate(v)) for v in rows.values()]
    means = [float(np.mean(v)) for v in rows.values()]
    v = sg.ties_with_best(means, samples, [True, True, True], "lower")
    assert v.best == int(np.argmin(means)) and 2 not in v.marked and len(v.marked) == 2
    worse = next(c for c in v.comparisons if c.index == 2)
    assert worse.effect == pytest.approx(1.0) and worse.effect_low <= 1.0 <= worse.effect_high
    assert worse.p_holm < sg.ALPHA
    # "higher is better" turns round; the baseline (not eligible) is never marked
    v = sg.ties_with_best(means, samples, [True, True, False], "higher")
    assert v.best != 2 and 2 not in v.marked


def test_untested_columns_mark_only_the_best() -> None:
    samples = [{0: 1.0}, {0: 2.0}]
    v = sg.ties_with_best([1.0, 2.0], samples, [True, True], "lower")
    assert v.marked == {0} and v.untested


def test_critical_difference_matches_demsar_2006() -> None:
    # Demsar 2006, sec. 3.2.2: four classifiers on 14 data sets, average ranks 3.143, 2.000, 2.893, 1.964
    ranks = [3.143, 2.000, 2.893, 1.964]
    chi2, ff = sg.friedman_from_ranks(ranks, 14)
    assert chi2 == pytest.approx(9.28, abs=0.01) and ff == pytest.approx(3.69, abs=0.01)
    assert sg.critical_difference(4, 14) == pytest.approx(1.25, abs=0.005)
    # table 5(a): q_0.05 for k = 2..10 (printed to three decimals, not all of them rounded)
    table = [1.960, 2.343, 2.569, 2.728, 2.850, 2.949, 3.031, 3.102, 3.164]
    np.testing.assert_allclose([sg.nemenyi_q(k) for k in range(2, 11)], table, atol=1.5e-3)
    # C4.5+m+cf (1.964) is significantly better than C4.5 (3.143); the rest are within the CD of each other
    p = sg.nemenyi_pvalues(ranks, 14)
    assert p[0, 3] < 0.10 and p[1, 3] > 0.9
    assert sg.cliques(ranks, sg.critical_difference(4, 14)) == [(3, 1, 2, 0)]
    assert sg.cliques(ranks, 1.0) == [(3, 1, 2), (2, 0)]


def test_friedman_and_average_ranks_agree_with_the_formula() -> None:
    rng = np.random.default_rng(3)
    scores = rng.normal(size=(14, 4)) + np.array([0.0, 0.5, 1.0, 1.5])
    ranks = sg.average_ranks(scores)
    assert ranks.sum() == pytest.approx(14 * 10 / 14)  # ranks of 4 sum to 10 on each dataset
    res = sg.friedman(scores)
    assert res.statistic == pytest.approx(sg.friedman_from_ranks(ranks, 14)[0])
    assert not sg.friedman(scores[:, :2]).tested


def test_iqm_and_the_stratified_bootstrap() -> None:
    assert sg.iqm(np.arange(1.0, 9.0)) == pytest.approx(4.5)
    strata = [np.full(10, 0.5), np.array([0.8])]
    value, lo, hi = sg.stratified_bootstrap(strata, lambda a: np.asarray(sg.iqm(a, axis=1)))
    assert value == lo == hi == 0.5  # constant strata: no spread to resample
    rng = np.random.default_rng(4)
    strata = [rng.normal(0.6, 0.1, 20), rng.normal(0.4, 0.1, 20), np.array([0.9])]
    value, lo, hi = sg.stratified_bootstrap(strata, lambda a: np.asarray(sg.iqm(a, axis=1)))
    assert lo < value < hi
    assert (value, lo, hi) == sg.stratified_bootstrap(strata, lambda a: np.asarray(sg.iqm(a, axis=1)))
    np.testing.assert_allclose(sg.skill([1.0, 0.5], [2.0, 0.5]), [0.5, 0.0])


def test_spread_gives_the_worst_seed() -> None:
    med, p90, worst, seed = sg.spread([1.0, 5.0, 2.0, math.nan], [10, 11, 12, 13])
    assert (med, worst, seed) == (2.0, 5.0, 11) and 2.0 < p90 <= 5.0


def test_dataset_groups_keep_the_largest_shared_sets() -> None:
    ran = {
        "w1": {"a", "b", "c", "d"},
        "w2": {"a", "b", "c", "d"},
        "w3": {"a", "b", "c", "d", "sweep"},
        "r1": {"a", "b", "c"},
        "r2": {"a", "b", "c"},
        "laser": {"a", "x", "y"},
    }
    groups = dataset_groups(ran)
    assert (("a", "b", "c", "d"), ("w1", "w2", "w3")) in groups
    assert (("a", "b", "c"), ("r1", "r2", "w1", "w2", "w3")) in groups
    assert all("laser" not in g for _, g in groups)  # a set run on one dataset only


def test_dataset_groups_count_each_recording_once() -> None:
    """``intel`` and ``radish[site=intel]`` read one log: a group keeps the recording's own loader, ``intel``;
    the synthetic worlds and the other sites are each their own."""
    ran = {
        d: {"a", "b", "c"}
        for d in ("intel", "radish[site=intel]", "radish[site=intel,max_scans=500]", "radish[site=aces]", "room")
    }
    recordings = {d: dataset_recording(d) for d in ran}
    groups = dataset_groups(ran, recordings)
    assert groups == [(("a", "b", "c"), ("intel", "radish[site=aces]", "room"))]
    for _, datasets in groups:
        declared = [recordings[d] for d in datasets if recordings[d] is not None]
        assert len(declared) == len(set(declared))
    kept, dropped = one_per_recording(sorted(ran), recordings)
    assert kept == ("intel", "radish[site=aces]", "room")
    assert dropped == {"radish[site=intel]": "intel", "radish[site=intel,max_scans=500]": "intel"}
    # without the recording's own loader: the first by name
    assert one_per_recording(["radish[site=intel]", "radish[site=intel,max_scans=500]"], recordings)[1] == {
        "radish[site=intel]": "radish[site=intel,max_scans=500]"
    }
    # a user's file is no loader's own recording: two specs of one file keep the first by name
    log = "file /data/my-log"
    files = {"textlog[path=/data/my-log]": log, "textlog[path=/data/my-log,max_events=50]": log}
    assert one_per_recording(sorted(files), files)[1] == {
        "textlog[path=/data/my-log]": "textlog[path=/data/my-log,max_events=50]"
    }
    # below the smallest group once the duplicates are gone: no group
    two = {d: {"a", "b", "c"} for d in ("intel", "radish[site=intel]", "room")}
    assert dataset_groups(two, {d: dataset_recording(d) for d in two}) == []


# --- the experiments' own tables and the HTML hover ---------------------------------------------------------


def _scan_grid_rows(seeds: int) -> pd.DataFrame:
    """Tidy metrics of report 004's section on two variants with known answers per variant.

    ``scan_grid``: ``kf_linear`` best, ``pf`` the same plus noise (tied), ``ekf_landmarks`` shifted by 5 cm
    (different), ``odometry`` lowest of all but the baseline (never marked). The mixed variant turns it round:
    ``ekf_landmarks`` is best there and the others are far behind.
    """
    rng = np.random.default_rng(7)
    base = rng.normal(0.10, 0.02, seeds)
    per = {
        "scan_grid": {
            "kf_linear": base,
            "pf": base + 0.001 * (-1.0) ** np.arange(seeds),  # differences symmetric about 0
            "ekf_landmarks": base + 0.05,
            "odometry": base - 0.05,
        },
        "scan_grid[mixed_commands=true]": {
            "kf_linear": base + 0.2,
            "pf": base + 0.3,
            "ekf_landmarks": base,
        },
    }
    rows = []
    for ds, by in per.items():
        for f, ate in by.items():
            for s in range(seeds):
                rows.append((ds, f, s, "ate_m", float(ate[s])))
                rows.append((ds, f, s, "anees", 3.0 + float(rng.normal(0.0, 0.5))))
    return pd.DataFrame(rows, columns=["dataset", "filter", "seed", "metric", "value"])


def _cell(table: Table, dataset: str, filt: str, column: int) -> tuple[str, str]:
    for r, h in zip(table.rows, table.hovers, strict=True):
        if r[0] == f"`{dataset}`" and r[1] == f"`{filt}`":
            return r[column], h[column]
    raise AssertionError(f"no row {dataset} {filt}")


def test_an_experiment_table_marks_ties_within_each_dataset_and_hovers_the_effect() -> None:
    from locbench.claims import bettaieb_stdr as report_004

    blocks = report_004._section(_scan_grid_rows(SEEDS), "scan_grid")
    table = next(b for b in blocks if isinstance(b, Table))
    ate = 3
    kf, kf_tip = _cell(table, "scan_grid", "kf_linear", ate)
    twin, twin_tip = _cell(table, "scan_grid", "pf", ate)
    worse, worse_tip = _cell(table, "scan_grid", "ekf_landmarks", ate)
    odo, odo_tip = _cell(table, "scan_grid", "odometry", ate)
    assert kf.startswith("**") and twin.startswith("**")
    assert not worse.startswith("**") and not odo.startswith("**") and odo_tip == ""
    # the best's own cell has no comparison; the others hover their effect against it
    (best, tip) = ("kf_linear", twin_tip) if kf_tip == "" else ("pf", kf_tip)
    assert f"against {best}" in tip and "p (Holm)" in tip and "Wilcoxon signed-rank, n = 20" in tip
    assert "median paired difference 5" in worse_tip and "(95 % bootstrap)" in worse_tip
    # ranked within each dataset: the mixed variant's best is its own
    assert _cell(table, "scan_grid[mixed_commands=true]", "ekf_landmarks", ate)[0].startswith("**")
    assert not _cell(table, "scan_grid[mixed_commands=true]", "kf_linear", ate)[0].startswith("**")
    assert table.footnotes[-1].startswith("Bold: the best value")


def test_an_experiment_table_on_too_few_seeds_says_no_test_is_possible() -> None:
    from locbench.claims import bettaieb_stdr as report_004

    blocks = report_004._section(_scan_grid_rows(sg.MIN_PAIRS - 1), "scan_grid")
    table = next(b for b in blocks if isinstance(b, Table))
    assert table.footnotes[-1] == UNTESTED_FOOTNOTE
    assert "no paired test possible" in _cell(table, "scan_grid", "pf", 3)[1]
    # only the best is bold
    assert not _cell(table, "scan_grid", "pf", 3)[0].startswith("**")


def test_grouped_marks_name_an_untested_column() -> None:
    rng = np.random.default_rng(3)
    a = rng.normal(1.0, 0.1, SEEDS)
    rows = [["`x`", "1", "1"], ["`y`", "2", "2"]]
    keys = [[math.nan, 1.0, 1.0], [math.nan, 2.0, 2.0]]
    columns = [
        Column(1, METRICS["ate_m"], [dict(enumerate(a)), dict(enumerate(a + 1.0))]),
        Column(2, METRICS["ate_m"], [{0: 1.0}, {0: 2.0}]),
    ]
    marks = mark_ties(rows, keys, columns, [True, True])
    assert marks.tested == (1,) and marks.untested_columns == (2,) and not marks.untested
    note = tie_footnote(marks, ("filter", "left", "right"))
    assert "No paired test is possible in right" in note


def test_the_html_cell_carries_the_hover_and_the_markdown_does_not() -> None:
    from locbench.report.render import to_html, to_markdown

    t = Table(("filter", "ATE"), (("`a`", "**1.0**"), ("`b`", "**1.1**")), hovers=(("", ""), ("", "against a: <x>")))
    sec = Section("S", "s", [t])
    page = to_html("T", [], [sec], {})
    assert '<td title="against a: &lt;x&gt;"><strong>1.1</strong></td>' in page
    assert "against a" not in to_markdown("T", [], [sec])


def test_a_column_with_one_candidate_is_not_called_untested() -> None:
    rows = [["`x`", "1"], ["`odometry`", "2"]]
    columns = [Column(1, METRICS["ate_m"], [dict(enumerate(np.ones(SEEDS))), dict(enumerate(np.ones(SEEDS)))])]
    marks = mark_ties(rows, [[math.nan, 1.0], [math.nan, 2.0]], columns, [True, False])
    assert rows[0][1] == "**1**" and not marks.untested and tie_footnote(marks) != UNTESTED_FOOTNOTE
