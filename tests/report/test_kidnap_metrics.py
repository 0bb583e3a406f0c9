"""Kidnap recovery, false confidence, global convergence and smoothed-trajectory metrics on hand-made runs,
and the report's kidnap and global-localization sections on a temporary store."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from locbench.datasets.dataset import Kidnap, Trajectory2D
from locbench.evaluate import metrics as lm
from locbench.evaluate.records import KIND_NAMES, RunRecord, TruthRecord
from locbench.report import wilson_interval, write_report
from locbench.report.collect import collect
from locbench.report.context import Report
from locbench.report.doc import Plot, Table
from locbench.report.render import render_png
from locbench.report.sections.experiment import nees_plots
from locbench.report.sections.kidnap import kidnap_section
from locbench.report.site import site_markdown
from locbench.run.store import Store

ODO = KIND_NAMES.index("Odometry")
RESET = KIND_NAMES.index("reset")

DT = 0.5
T_KIDNAP = 10.0
DELTA = (2.0, 0.0, 0.3)
SMALL_COV = 0.01  # variance of every pose component, so a 2 m error has a huge NEES
LARGE_COV = 100.0


def _truth(
    t_end: float = 60.0, kidnaps: tuple[Kidnap, ...] = (Kidnap(T_KIDNAP, DELTA),), dataset: str = "line", seed: int = 0
) -> TruthRecord:
    """A robot driving along x at 0.1 m/s; at each kidnap the truth jumps by its delta."""
    t = np.arange(0.0, t_end + 1e-9, DT)
    poses = np.column_stack([0.1 * t, np.zeros_like(t), np.zeros_like(t)])
    for k in kidnaps:
        poses[t >= k.t - 1e-9] += np.asarray(k.delta)
    return TruthRecord(dataset, seed, Trajectory2D(t, poses[:, :2], poses[:, 2]), None, kidnaps, t_end)


def _run(
    truth: TruthRecord, within: np.ndarray, var: np.ndarray | float = SMALL_COV, extra: dict | None = None
) -> RunRecord:
    """Estimates at the ground-truth times: the truth where ``within``, else the truth minus the jump (the pose
    the filter would hold if it never noticed the kidnap)."""
    gt = truth.ground_truth
    mean = gt.poses.copy()
    mean[~within] -= np.asarray(DELTA)
    var = np.broadcast_to(np.asarray(var, dtype=np.float64), gt.t.shape)
    cov = np.einsum("n,ij->nij", var, np.eye(3))
    kind = np.full(gt.t.shape, ODO, dtype=np.int8)
    kind[0] = RESET
    step_ns = np.full(gt.t.shape, 1000, dtype=np.int64)
    meta = {"filter": "f", "dataset": truth.dataset, "seed": truth.seed, "status": "ok", "message": ""}
    return RunRecord(meta, gt.t.copy(), mean, cov, kind, step_ns, extra=extra or {})


def _within_from(truth: TruthRecord, t_fix: float) -> np.ndarray:
    """Right before the kidnap and from ``t_fix`` on."""
    t = truth.ground_truth.t
    return (t < T_KIDNAP - 1e-9) | (t >= t_fix - 1e-9)


# --- building blocks ----------------------------------------------------------------------------


def test_constants_are_the_design_values() -> None:
    assert (lm.RECOVERY_POSITION_M, lm.RECOVERY_HEADING_RAD) == (0.25, 0.25)
    assert (lm.RECOVERY_HOLD_S, lm.KIDNAP_WINDOW_S, lm.FALSE_CONFIDENCE_PROBABILITY) == (2.0, 30.0, 0.999)
    assert lm.false_confidence_bound() == pytest.approx(16.266, abs=1e-3)


def test_first_hold_needs_the_full_duration_without_a_break() -> None:
    t = np.arange(0.0, 10.01, 0.5)
    ok = np.zeros(t.shape, dtype=bool)
    ok[(t >= 1.0) & (t <= 2.5)] = True  # 1.5 s: too short
    ok[t >= 4.0] = True
    assert lm.first_hold(t, ok, 0.0) == 4.0
    assert lm.first_hold(t, ok, 5.2) == 5.5  # only samples from t_from count
    assert lm.first_hold(t, ok, 0.0, latest_start=3.9) is None
    assert lm.first_hold(t, ok, 0.0, latest_start=4.0) == 4.0  # the latest start is inclusive
    assert lm.first_hold(t, ok, 9.0) is None  # the data end during the hold
    assert lm.first_hold(t, np.ones(t.shape, dtype=bool), 0.0, hold_s=10.0) == 0.0
    assert lm.first_hold(t, np.zeros(t.shape, dtype=bool), 0.0) is None


def test_time_fraction_holds_each_flag_until_the_next_sample() -> None:
    t = np.array([0.0, 1.0, 2.0, 4.0])
    flag = np.array([True, False, True, False])
    assert lm.time_fraction(t, flag, 0.0, 4.0) == pytest.approx(3.0 / 4.0)  # [0,1) and [2,4)
    assert lm.time_fraction(t, flag, 0.5, 3.0) == pytest.approx(1.5 / 2.5)  # [0.5,1) and [2,3)
    assert lm.time_fraction(t, flag, 2.0, 2.0) == 0.0


def test_within_recovery_thresholds_position_and_wrapped_heading() -> None:
    gt = np.array([[0.0, 0.0, np.pi - 0.1]] * 4)
    est = gt.copy()
    est[1, 0] += 0.25  # on the position bound: within
    est[2, 0] += 0.26
    est[3, 2] = -np.pi + 0.2  # wrapped heading error 0.3 rad
    got = lm.within_recovery(lm.align(np.arange(4.0), est, np.arange(4.0), gt))
    np.testing.assert_array_equal(got, [True, True, False, False])


def test_wilson_interval_hand_values() -> None:
    z2 = 1.959963984540054**2
    assert wilson_interval(0, 20) == pytest.approx((0.0, z2 / (20 + z2)))
    assert wilson_interval(20, 20) == pytest.approx((20 / (20 + z2), 1.0))
    lo, hi = wilson_interval(10, 20)
    assert (lo + hi) / 2 == pytest.approx(0.5) and hi - lo == pytest.approx(0.4, abs=0.01)
    assert np.isnan(wilson_interval(0, 0)[0])
    with pytest.raises(ValueError, match="successes"):
        wilson_interval(3, 2)


# --- kidnap recovery ----------------------------------------------------------------------------


def test_recovered_with_time_and_false_confidence() -> None:
    truth = _truth()
    m = lm.run_metrics(_run(truth, _within_from(truth, 15.0)), truth)
    assert m["kidnap_distance_m"] == pytest.approx(2.0)
    assert m["kidnap_recovered"] == 1.0
    assert m["kidnap_time_to_recover_s"] == pytest.approx(5.0)
    # wrong by 2 m with a 0.1 m sigma from the kidnap to the recovery: falsely confident all along
    assert m["kidnap_false_confidence_fraction"] == pytest.approx(1.0)


def test_not_recovered_counts_the_whole_window() -> None:
    truth = _truth()
    m = lm.run_metrics(_run(truth, _within_from(truth, np.inf)), truth)
    assert m["kidnap_recovered"] == 0.0
    assert "kidnap_time_to_recover_s" not in m
    assert m["kidnap_false_confidence_fraction"] == pytest.approx(1.0)


def test_recovered_too_late_is_not_recovered() -> None:
    truth = _truth()
    late = lm.run_metrics(_run(truth, _within_from(truth, T_KIDNAP + 30.5)), truth)
    assert late["kidnap_recovered"] == 0.0 and "kidnap_time_to_recover_s" not in late
    # a hold that starts exactly at the window end counts, even though it ends 2 s later
    edge = lm.run_metrics(_run(truth, _within_from(truth, T_KIDNAP + 30.0)), truth)
    assert edge["kidnap_recovered"] == 1.0
    assert edge["kidnap_time_to_recover_s"] == pytest.approx(30.0)


def test_a_short_visit_does_not_count_as_recovery() -> None:
    truth = _truth()
    t = truth.ground_truth.t
    within = _within_from(truth, 20.0) | ((t >= 12.0) & (t <= 13.5))  # 1.5 s inside, then lost again
    m = lm.run_metrics(_run(truth, within), truth)
    assert m["kidnap_time_to_recover_s"] == pytest.approx(10.0)
    # NEES is 0 during the visit (exact estimate): 1.5 s + the held half-step of 13.5 s are not confident
    assert m["kidnap_false_confidence_fraction"] == pytest.approx(1.0 - 2.0 / 10.0)


def test_a_heading_error_alone_prevents_recovery() -> None:
    truth = _truth()
    run = _run(truth, _within_from(truth, 15.0))
    run.mean[run.t >= 15.0, 2] += 0.3
    assert lm.run_metrics(run, truth)["kidnap_recovered"] == 0.0


def test_false_confidence_is_the_fraction_with_nees_above_the_bound() -> None:
    truth = _truth()
    t = truth.ground_truth.t
    # honest (large covariance) for the first half of the 30 s window, then over-confident
    var = np.where(t < 25.0, LARGE_COV, SMALL_COV)
    m = lm.run_metrics(_run(truth, _within_from(truth, np.inf), var), truth)
    assert m["kidnap_recovered"] == 0.0
    assert m["kidnap_false_confidence_fraction"] == pytest.approx(0.5)
    honest = lm.run_metrics(_run(truth, _within_from(truth, np.inf), LARGE_COV), truth)
    assert honest["kidnap_false_confidence_fraction"] == 0.0


def test_window_ends_with_the_truth() -> None:
    truth = _truth(t_end=25.0)
    m = lm.run_metrics(_run(truth, _within_from(truth, 23.5)), truth)  # the data end during the 2 s hold
    assert m["kidnap_recovered"] == 0.0
    t = truth.ground_truth.t
    var = np.where(t < 20.0, LARGE_COV, SMALL_COV)
    m = lm.run_metrics(_run(truth, _within_from(truth, np.inf), var), truth)
    assert m["kidnap_false_confidence_fraction"] == pytest.approx(5.0 / 15.0)  # window [10, 25]


def test_immediate_recovery_has_no_false_confidence() -> None:
    truth = _truth()
    m = lm.run_metrics(_run(truth, np.ones(truth.ground_truth.t.shape, dtype=bool)), truth)
    assert m["kidnap_recovered"] == 1.0
    assert m["kidnap_time_to_recover_s"] == 0.0
    assert m["kidnap_false_confidence_fraction"] == 0.0


def test_several_kidnaps_score_the_first_and_cut_its_window() -> None:
    second = Kidnap(20.0, (0.0, 0.0, 0.0))  # a zero jump keeps the truth simple
    truth = _truth(kidnaps=(second, Kidnap(T_KIDNAP, DELTA)))  # stored out of order on purpose
    t = truth.ground_truth.t
    var = np.where(t < 15.0, LARGE_COV, SMALL_COV)
    m = lm.run_metrics(_run(truth, _within_from(truth, 25.0), var), truth)
    assert m["kidnap_distance_m"] == pytest.approx(2.0)
    assert m["kidnap_recovered"] == 0.0  # recovered only after the next kidnap
    assert m["kidnap_false_confidence_fraction"] == pytest.approx(0.5)  # window [10, 20]
    early = lm.run_metrics(_run(truth, _within_from(truth, 16.0)), truth)
    assert early["kidnap_time_to_recover_s"] == pytest.approx(6.0)


def test_no_kidnap_no_kidnap_metrics() -> None:
    truth = _truth(kidnaps=())
    m = lm.run_metrics(_run(truth, np.ones(truth.ground_truth.t.shape, dtype=bool)), truth)
    assert not any(k.startswith("kidnap_") for k in m)
    assert lm.kidnap_metrics(lm.align([0.0], np.zeros((1, 3)), [0.0], np.zeros((1, 3)), np.eye(3)[None]), ()) == {}


# --- global localization ------------------------------------------------------------------------


def test_converged_from_a_wrong_start() -> None:
    truth = _truth(kidnaps=())
    t = truth.ground_truth.t
    m = lm.run_metrics(_run(truth, t >= 7.0), truth)
    assert m["converged"] == 1.0
    assert m["time_to_converge_s"] == pytest.approx(7.0)
    never = lm.run_metrics(_run(truth, np.zeros(t.shape, dtype=bool)), truth)
    assert never["converged"] == 0.0 and "time_to_converge_s" not in never


def test_convergence_looks_at_the_whole_run_and_ignores_the_kidnap() -> None:
    truth = _truth()
    m = lm.run_metrics(_run(truth, _within_from(truth, np.inf)), truth)
    assert m["converged"] == 1.0 and m["time_to_converge_s"] == 0.0  # right before the kidnap for 10 s
    t = truth.ground_truth.t
    m = lm.run_metrics(_run(truth, (t >= 40.0)), truth)
    assert m["time_to_converge_s"] == pytest.approx(40.0)


LANDMARKS = KIND_NAMES.index("LandmarkObservations")


def _updating_run(truth: TruthRecord, heading_errors: list[float]) -> RunRecord:
    """The truth with a wrong heading: the reset belief at t_0 has ``heading_errors[0]`` (rad), the j-th landmark
    update (one at each ground-truth time from t_0 on, with odometry half-way between) leaves ``heading_errors[j]``
    (the last one holds to the end)."""
    gt = truth.ground_truth
    t, kind, mean = [gt.t[0]], [RESET], [gt.poses[0]]
    for k, tk in enumerate(gt.t):
        err = heading_errors[min(k + 1, len(heading_errors) - 1)]
        t.append(tk)
        kind.append(LANDMARKS)
        mean.append(gt.poses[k] + (0.0, 0.0, err))
        if k + 1 < gt.t.size:
            t.append(0.5 * (tk + gt.t[k + 1]))
            kind.append(ODO)
            mean.append(gt.poses[k] + (0.0, 0.0, err))
    mean_a = np.asarray(mean)
    mean_a[0, 2] = gt.poses[0, 2] + heading_errors[0]
    cov = np.broadcast_to(SMALL_COV * np.eye(3), (len(t), 3, 3)).copy()
    meta = {"filter": "f", "dataset": truth.dataset, "seed": truth.seed, "status": "ok", "message": ""}
    n = len(t)
    return RunRecord(meta, np.asarray(t), mean_a, cov, np.asarray(kind, np.int8), np.full(n, 1000, np.int64))


@pytest.mark.parametrize(
    ("errors", "updates", "seconds"),
    [
        ([0.0], 0.0, 0.0),  # the initial belief meets the criterion: no update needed
        ([0.8, 0.0], 1.0, 0.0),  # the update at t_0 fixes the heading: 0 s, but one update
        ([0.8, 0.4, 0.2, 0.1], 2.0, DT),  # the second update brings it within 0.25 rad
        ([0.8, 0.4, 0.3, 0.26, 0.2], 4.0, 3 * DT),
        ([0.8, 0.1, 0.4, 0.4, 0.4, 0.4, 0.0], 6.0, 5 * DT),  # within for a moment, out again: not yet converged
    ],
)
def test_updates_to_converge_counts_the_updates_that_the_time_hides(
    errors: list[float], updates: float, seconds: float
) -> None:
    truth = _truth(kidnaps=())
    m = lm.run_metrics(_updating_run(truth, errors), truth)
    assert m["converged"] == 1.0
    assert m["updates_to_converge"] == updates
    assert m["time_to_converge_s"] == pytest.approx(seconds)


def test_no_convergence_no_update_count() -> None:
    truth = _truth(kidnaps=())
    m = lm.run_metrics(_updating_run(truth, [0.8, 0.5]), truth)
    assert m["converged"] == 0.0 and "updates_to_converge" not in m


# --- smoothed trajectories ----------------------------------------------------------------------


def test_smoothed_ate_and_heading_rmse_by_zero_order_hold() -> None:
    truth = _truth(kidnaps=())
    gt = truth.ground_truth
    st = gt.t[::2].copy()  # the smoother's poses every 1 s, held in between
    sm = gt.poses[::2].copy()
    sm[:, 1] += 0.1
    sm[:, 2] = 0.05
    run = _run(truth, np.ones(gt.t.shape, dtype=bool), extra={"smoothed_t": st, "smoothed_mean": sm})
    m = lm.run_metrics(run, truth)
    # at the odd ground-truth times the held pose is 0.05 m behind in x
    expected = np.sqrt(np.mean(0.1**2 + np.where(np.arange(gt.t.shape[0]) % 2 == 1, 0.05**2, 0.0)))
    assert m["smoothed_ate_m"] == pytest.approx(expected)
    assert m["smoothed_heading_rmse_rad"] == pytest.approx(0.05)
    assert m["ate_m"] == pytest.approx(0.0)  # the filtered estimate is scored as before


def test_smoothed_heading_wraps() -> None:
    t = np.array([0.0, 1.0])
    gt = np.array([[0.0, 0.0, np.pi - 0.05], [0.0, 0.0, np.pi - 0.05]])
    extra = {"smoothed_t": t, "smoothed_mean": np.array([[0.0, 0.0, -np.pi + 0.05]] * 2)}
    run = lm.align(t, gt, t, gt)
    assert lm.smoothed_metrics(extra, run)["smoothed_heading_rmse_rad"] == pytest.approx(0.1)


def test_smoothed_metrics_absent_or_malformed() -> None:
    t, gt = np.array([0.0, 1.0]), np.zeros((2, 3))
    run = lm.align(t, gt, t, gt)
    assert lm.smoothed_metrics({}, run) == {}
    assert lm.smoothed_metrics({"smoothed_t": np.zeros(0), "smoothed_mean": np.zeros((0, 3))}, run) == {}
    with pytest.raises(ValueError, match="both"):
        lm.smoothed_metrics({"smoothed_t": t}, run)
    with pytest.raises(ValueError, match=r"\(n, 3\)"):
        lm.smoothed_metrics({"smoothed_t": t, "smoothed_mean": np.zeros((2, 2))}, run)
    with pytest.raises(ValueError, match="non-decreasing"):
        lm.smoothed_metrics({"smoothed_t": t[::-1], "smoothed_mean": np.zeros((2, 3))}, run)


# --- the report ---------------------------------------------------------------------------------

N_SEEDS = 2


def _write(store: Store, dataset: str, filt: str, seed: int, within: np.ndarray, truth: TruthRecord, **kw) -> None:
    run = _run(truth, within, **kw)
    run.meta.update({"filter": filt, "filter_id": filt.split("[")[0], "dataset": dataset, "run_key": f"{filt}{seed}"})
    store.write_run(run)


@pytest.fixture
def kidnap_store(tmp_path: Path) -> Store:
    """Two kidnap distances of ``line`` with a filter that recovers only from the smaller one (on seed 0),
    dead reckoning that never does, and a globally localizing filter with a smoothed trajectory."""
    st = Store(tmp_path / "results")
    for dataset, dist in (("line[kidnap_m=0.5]", 0.5), ("line[kidnap_m=2]", 2.0)):
        for seed in range(N_SEEDS):
            truth = _truth(t_end=40.0, kidnaps=(Kidnap(T_KIDNAP, (dist, 0.0, 0.3)),), dataset=dataset, seed=seed)
            st.write_truth(truth)
            t = truth.ground_truth.t
            _write(st, dataset, "odometry", seed, _within_from(truth, np.inf), truth)
            fix = 14.0 if (dist < 1.0 and seed == 0) else np.inf
            _write(st, dataset, "tracker", seed, _within_from(truth, fix), truth)
            extra = {"smoothed_t": t.copy(), "smoothed_mean": truth.ground_truth.poses.copy()}
            _write(st, dataset, "pf[init=uniform]", seed, t >= 5.0 + seed, truth, extra=extra)
    return st


def test_kidnap_section_table_and_figure_are_deterministic(kidnap_store: Store) -> None:
    col = collect(kidnap_store)
    first = kidnap_section(Report(col))
    (line,) = [c for c in first.children if c.title == "Kidnap: line"]
    table, plot = line.blocks
    assert isinstance(table, Table) and isinstance(plot, Plot)
    assert table.header == ("filter", "dataset", "D = 0.5 m", "D = 2 m", "false confidence")
    rows = {r[0]: r for r in table.rows}
    assert rows["`tracker`"][2:4] == ("1/2", "0/2")
    assert rows["`odometry`"][2:4] == ("0/2", "0/2")
    assert table.rows[0][0] == "`odometry`"  # the baseline first
    assert render_png(plot) == render_png(kidnap_section(Report(collect(kidnap_store))).children[0].blocks[1])
    (glob,) = [c for c in first.children if c.anchor == "global"]
    (gt,) = [b for b in glob.blocks if isinstance(b, Table)]
    assert [r[1] for r in gt.rows] == ["`pf[init=uniform]`", "`pf[init=uniform]`"]
    assert gt.rows[1][3] == "2/2 = 1.00 [0.34, 1.00]" and gt.rows[1][4] == "5.5"


@pytest.mark.slow
def test_report_kidnap_and_global_sections_regenerate_identically(kidnap_store: Store) -> None:
    text = site_markdown(write_report(kidnap_store).markdown.parent)
    for needle in ("Kidnap: line", "![line: recovery within 30 s", "Global localization", "smoothed ATE (cm)"):
        assert needle in text, needle
    # runs started from a uniform prior are scored apart, not in the NEES figure of their dataset
    nees = nees_plots(Report(collect(kidnap_store)), "line[kidnap_m=2]")
    assert nees and all("uniform prior left out" in p.caption for p in nees)
    files = sorted(p for p in kidnap_store.summary.rglob("*") if p.is_file())
    before = {p: p.read_bytes() for p in files}
    for p in files:
        p.unlink()
    write_report(kidnap_store)
    after = {p: p.read_bytes() for p in sorted(p for p in kidnap_store.summary.rglob("*") if p.is_file())}
    assert after.keys() == before.keys()
    for p, data in before.items():
        assert after[p] == data, p


def test_report_without_kidnaps_or_smoother_has_no_such_sections(tmp_path: Path) -> None:
    st = Store(tmp_path / "results")
    truth = _truth(t_end=20.0, kidnaps=(), dataset="line")
    st.write_truth(truth)
    _write(st, "line", "odometry", 0, np.ones(truth.ground_truth.t.shape, dtype=bool), truth)
    text = site_markdown(write_report(st).markdown.parent)
    assert "Kidnap and global localization" not in text
    assert "Global localization" not in text
    assert "smoothed ATE" not in text
    assert not list((st.summary / "figures").glob("kidnap_*.png"))
