"""Hand-computed cases for every metric of locbench.evaluate.metrics (the aggregations over seeds:
test_aggregate.py)."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
from scipy import stats

from locbench.core.geometry import compose
from locbench.datasets.dataset import Trajectory2D, Waypoints
from locbench.evaluate import metrics as lm
from locbench.run.store import KIND_NAMES, RunRecord, TruthRecord

ODO = KIND_NAMES.index("Odometry")
LMK = KIND_NAMES.index("LandmarkObservations")
RESET = KIND_NAMES.index("reset")


# --- zero-order hold ----------------------------------------------------------------------------


def test_estimate_at_is_a_zero_order_hold_with_later_rows_winning_ties() -> None:
    t_est = np.array([0.0, 1.0, 1.0, 2.0])
    values = np.array([10.0, 20.0, 30.0, 40.0])
    got = lm.estimate_at(t_est, values, [-1.0, 0.0, 0.5, 0.999, 1.0, 1.5, 2.0, 5.0])
    np.testing.assert_array_equal(got, [10, 10, 10, 10, 30, 30, 40, 40])


def test_estimate_at_keeps_trailing_shape() -> None:
    cov = np.stack([np.eye(3) * k for k in (1.0, 2.0)])
    got = lm.estimate_at([0.0, 1.0], cov, [0.5, 3.0])
    assert got.shape == (2, 3, 3)
    np.testing.assert_array_equal(got[1], 2.0 * np.eye(3))


def test_estimate_at_rejects_empty_run() -> None:
    with pytest.raises(ValueError, match="non-empty"):
        lm.estimate_at([], np.zeros((0, 3)), [0.0])


def _flat(xy: np.ndarray | list[list[float]]) -> np.ndarray:
    """Poses (n, 3) at heading 0 from positions (n, 2)."""
    p = np.asarray(xy, dtype=np.float64)
    return np.column_stack([p, np.zeros(p.shape[0])])


def test_aligned_view_holds_every_array_once_at_the_truth_times() -> None:
    t_est = np.array([0.0, 1.0, 1.0, 2.0])
    mean = np.array([[0.0, 0.0, 3.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.1], [3.0, 1.0, -3.0]])
    cov = np.stack([np.eye(3) * k for k in (1.0, 2.0, 4.0, 8.0)])
    gt_t = np.array([-1.0, 0.5, 1.0, 2.5])
    truth = np.array([[0.0, 0.0, -3.0], [1.0, 0.0, 0.0], [2.0, 1.0, 0.0], [3.0, 1.0, 3.0]])
    a = lm.align(t_est, mean, gt_t, truth, cov)
    np.testing.assert_array_equal(a.rows, [0, 0, 2, 3])
    np.testing.assert_array_equal(a.mean, lm.estimate_at(t_est, mean, gt_t))
    np.testing.assert_array_equal(a.cov, lm.estimate_at(t_est, cov, gt_t))
    # the heading error is wrapped: 3 - (-3) = 6 rad is 6 - 2 pi
    np.testing.assert_allclose(a.error[:, 2], [6.0 - 2 * np.pi, 3.0, 0.1, -6.0 + 2 * np.pi])
    np.testing.assert_allclose(a.position_error, [0.0, 1.0, 1.0, 0.0])
    assert a.cov is not None
    np.testing.assert_array_equal(a.nees, lm.nees(a.error, a.cov))
    assert a.nees is a.nees  # computed once
    with pytest.raises(ValueError, match="no covariance"):
        _ = lm.align(t_est, mean, gt_t, truth).nees


# --- errors -------------------------------------------------------------------------------------


def test_waypoint_errors_against_marked_points_with_hold() -> None:
    t_est = np.array([0.0, 1.0, 2.0])
    mean = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    # waypoint 1 at t=1.5 (estimate (1, 0) in force), waypoint 2 at t=2 (estimate (2, 0))
    err, est = lm.waypoint_errors(t_est, mean, [1.5, 2.0], [[1.0, 1.0], [5.0, 4.0]])
    np.testing.assert_allclose(err, [1.0, 5.0])
    np.testing.assert_allclose(est, [[1.0, 0.0], [2.0, 0.0]])


def test_ate_uses_every_ground_truth_time_and_no_alignment() -> None:
    t_est = np.array([0.0, 1.0])
    mean = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    gt_t = np.array([0.0, 0.5, 1.0])
    gt_xy = np.array([[0.0, 0.0], [0.5, 0.0], [1.0, 0.0]])
    # errors 0, 0.5 (held estimate at x=0), 0
    assert lm.ate(lm.align(t_est, mean, gt_t, _flat(gt_xy))) == pytest.approx(np.sqrt(0.25 / 3))
    # a constant offset (3, 4) is not aligned away
    shifted = lm.align(t_est, mean + np.array([3.0, 4.0, 0.0]), [0.0, 1.0], _flat(gt_xy[[0, 2]]))
    assert lm.ate(shifted) == pytest.approx(5.0)


def test_heading_rmse_wraps_across_pi() -> None:
    t_est = np.array([0.0])
    mean = np.array([[0.0, 0.0, np.pi - 0.1]])
    truth = [[0.0, 0.0, -np.pi + 0.1], [0.0, 0.0, np.pi - 0.1]]
    assert lm.heading_rmse(lm.align(t_est, mean, [0.0, 1.0], truth)) == pytest.approx(np.sqrt(0.04 / 2))


def test_final_error_at_last_ground_truth_time() -> None:
    t_est = np.array([0.0, 5.0])
    mean = np.array([[0.0, 0.0, 0.0], [3.0, 4.0, 0.0]])
    assert lm.final_error(lm.align(t_est, mean, [0.0, 4.0, 9.0], np.zeros((3, 3)))) == pytest.approx(5.0)


def test_distance_pairs_on_a_unit_speed_line() -> None:
    xy = np.column_stack([np.arange(0.0, 3.01, 0.5), np.zeros(7)])
    pairs, dist = lm.distance_pairs(xy, 1.0)
    np.testing.assert_array_equal(pairs, [[0, 2], [1, 3], [2, 4], [3, 5], [4, 6]])
    np.testing.assert_allclose(dist, 1.0)
    assert lm.distance_pairs(xy, 10.0)[0].shape == (0, 2)


def _line_truth(n: int = 101) -> tuple[np.ndarray, np.ndarray]:
    t = np.linspace(0.0, 10.0, n)
    return t, np.column_stack([t, np.zeros(n), np.zeros(n)])


def test_rpe_on_a_known_scale_drift() -> None:
    t, gt = _line_truth()
    est = gt.copy()
    est[:, 0] *= 1.1  # odometry 10 % long: 0.1 m of error per metre travelled
    assert lm.rpe_per_metre(lm.align(t, est, t, gt)) == pytest.approx(0.1)


def test_rpe_ignores_a_global_rigid_offset_but_ate_does_not() -> None:
    t, gt = _line_truth()
    est = compose([2.0, -1.0, 0.7], gt)
    a = lm.align(t, est, t, gt)
    assert lm.rpe_per_metre(a) == pytest.approx(0.0, abs=1e-12)
    assert lm.ate(a) > 1.0


def test_rpe_is_nan_for_a_path_shorter_than_delta() -> None:
    t, gt = _line_truth()
    assert np.isnan(lm.rpe_per_metre(lm.align(t, gt, t, gt), delta_m=50.0))


# --- consistency --------------------------------------------------------------------------------


def test_nees_hand_value_and_wrapped_heading() -> None:
    assert lm.nees(np.array([[1.0, 0.0, 0.0]]), np.diag([4.0, 1.0, 1.0])[None])[0] == pytest.approx(0.25)
    mean = np.array([[0.0, 0.0, np.pi - 0.05]])
    cov = np.diag([1.0, 1.0, 0.01])[None]
    ne = lm.nees_at_truth(lm.align([0.0], mean, [0.0], [[0.0, 0.0, -np.pi + 0.05]], cov))
    assert ne[0] == pytest.approx(1.0)  # wrapped error -0.1 rad, sigma 0.1 rad


def test_nees_of_a_known_gaussian_averages_three() -> None:
    rng = np.random.default_rng(7)
    A = np.array([[0.3, 0.0, 0.0], [0.1, 0.2, 0.0], [0.02, -0.01, 0.05]])
    P = A @ A.T
    e = rng.standard_normal((20000, 3)) @ A.T
    ne = lm.nees(e, np.broadcast_to(P, (e.shape[0], 3, 3)))
    assert lm.anees(ne) == pytest.approx(3.0, abs=0.1)
    assert lm.fraction_in_band(ne, lm.chi2_band(3, 1)) == pytest.approx(0.95, abs=0.01)


def test_nees_singular_covariance_is_infinite_unless_error_is_zero() -> None:
    cov = np.stack([np.zeros((3, 3)), np.zeros((3, 3)), np.eye(3)])
    e = np.array([[0.1, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    np.testing.assert_array_equal(lm.nees(e, cov), [np.inf, 0.0, 3.0])


def test_nees_of_a_covariance_singular_to_rounding_is_infinite_not_negative() -> None:
    # a collapsed particle set: no spread in heading, and rounding has left a tiny negative eigenvalue there
    c, s = np.cos(0.3), np.sin(0.3)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    cov = rot @ np.diag([1e-4, 4e-4, -1e-20]) @ rot.T
    e = np.array([0.01, -0.02, 0.003])
    assert lm.nees(e[None], cov[None])[0] == np.inf


def test_chi2_band_single_and_mean_over_runs() -> None:
    lo, hi = lm.chi2_band(3, 1)
    assert (lo, hi) == pytest.approx((0.2158, 9.3484), abs=1e-4)
    lo20, hi20 = lm.chi2_band(3, 20)
    assert lo20 == pytest.approx(stats.chi2.ppf(0.025, 60) / 20)
    assert hi20 == pytest.approx(stats.chi2.ppf(0.975, 60) / 20)
    assert lo < lo20 < 3.0 < hi20 < hi
    with pytest.raises(ValueError):
        lm.chi2_band(3, 0)


def test_fraction_in_band() -> None:
    assert lm.fraction_in_band([0.1, 1.0, 3.0, 20.0], (0.2, 9.0)) == pytest.approx(0.5)
    assert np.isnan(lm.fraction_in_band([], (0.2, 9.0)))


# --- runtime ------------------------------------------------------------------------------------


def test_runtime_stats_and_realtime_factor() -> None:
    s = lm.runtime_stats([1.0, 2.0, 3.0, 4.0, 100.0])
    assert s == pytest.approx({"mean": 22.0, "median": 3.0, "p95": 80.8})
    assert lm.runtime_stats([]) == {}
    assert lm.realtime_factor(10.0, [0, 1_000_000_000, 1_000_000_000]) == pytest.approx(5.0)
    assert lm.realtime_factor(10.0, [0]) == np.inf


# --- one run ------------------------------------------------------------------------------------


def _truth() -> TruthRecord:
    t = np.array([0.0, 1.0, 2.0])
    gt = Trajectory2D(t, np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]), np.zeros(3))
    wp = Waypoints(np.array([1.0, 2.0]), np.array([[1.0, 0.0], [2.0, 0.1]]))
    return TruthRecord("line", 3, gt, wp, (), 2.0)


def _run(status: str = "ok") -> RunRecord:
    meta = {"filter": "ekf_landmarks", "dataset": "line", "seed": 3, "status": status, "message": ""}
    t = np.array([0.0, 1.0, 1.0, 2.0])
    mean = np.array([[0.0, 0.0, 0.0], [1.2, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.3, 0.0]])
    cov = np.broadcast_to(np.eye(3) * 0.01, (4, 3, 3)).copy()
    kind = np.array([RESET, ODO, LMK, ODO], dtype=np.int8)
    step_ns = np.array([0, 1000, 3000, 2000], dtype=np.int64)
    return RunRecord(meta, t, mean, cov, kind, step_ns)


def test_run_metrics_of_an_ok_run() -> None:
    m = lm.run_metrics(_run(), _truth())
    assert m["failed"] == 0.0
    assert m["waypoint_1_error_m"] == pytest.approx(0.0)
    assert m["waypoint_2_error_m"] == pytest.approx(0.2)
    assert (m["waypoint_2_est_x_m"], m["waypoint_2_est_y_m"]) == pytest.approx((2.0, 0.3))
    assert (m["waypoint_2_marked_x_m"], m["waypoint_2_marked_y_m"]) == pytest.approx((2.0, 0.1))
    assert m["ate_m"] == pytest.approx(np.sqrt(0.09 / 3))
    assert m["final_error_m"] == pytest.approx(0.3)
    assert m["heading_rmse_rad"] == 0.0
    assert m["anees"] == pytest.approx((0.0 + 0.0 + 9.0) / 3)
    assert m["nees_in_band_fraction"] == pytest.approx(1 / 3)  # NEES 0 is below the lower bound
    assert m["predict_us_mean"] == pytest.approx(1.5)
    assert m["predict_us_median"] == pytest.approx(1.5)
    assert m["update_us_p95"] == pytest.approx(3.0)
    assert m["realtime_factor"] == pytest.approx(2.0 / 6e-6)
    assert "rpe_m_per_m" in m
    assert all(np.isfinite(v) for v in m.values())


def test_run_metrics_failed_and_skipped() -> None:
    assert lm.run_metrics(_run("error"), _truth()) == {"failed": 1.0}
    assert lm.run_metrics(_run("diverged"), _truth()) == {"failed": 1.0}
    assert lm.run_metrics(_run("skipped"), _truth()) == {}


def test_run_metrics_leaves_out_undefined_values() -> None:
    run = _run()
    run.kind[:] = np.array([RESET, ODO, ODO, ODO], dtype=np.int8)  # an odometry-only filter
    m = lm.run_metrics(run, _truth())
    assert not any(k.startswith("update_us") for k in m)
    assert "rpe_m_per_m" in m


def test_accepted_fraction_from_diagnostics() -> None:
    from locbench.evaluate.metrics import acceptance_metrics

    diag = {"accepted": np.array([np.nan, 3.0, 0.0, 1.0]), "rejected": np.array([np.nan, 1.0, 0.0, 3.0])}
    assert acceptance_metrics(diag) == {"accepted_fraction": 0.5}
    assert acceptance_metrics({"accepted": np.zeros(3), "rejected": np.zeros(3)}) == {}
    assert acceptance_metrics({"nis": np.ones(2)}) == {}


def test_particle_count_metric_is_the_mean_reported_count() -> None:
    from locbench.evaluate.metrics import particle_count_metrics

    assert particle_count_metrics({}) == {}
    out = particle_count_metrics({"particles": np.array([np.nan, 5000.0, 100.0, 300.0])})
    assert out == {"particles_mean": pytest.approx(1800.0)}
    assert particle_count_metrics({"particles": np.array([np.nan])}) == {}


def test_nll_equals_scipy_logpdf_and_wraps_the_heading() -> None:
    rng = np.random.default_rng(5)
    a = rng.standard_normal((4, 3, 3))
    P = a @ a.transpose(0, 2, 1) + 0.1 * np.eye(3)
    e = rng.standard_normal((4, 3))
    got = lm.nll(e, P)
    want = [-stats.multivariate_normal(mean=np.zeros(3), cov=P[k]).logpdf(e[k]) for k in range(4)]
    np.testing.assert_allclose(got, want, rtol=1e-12)
    # A heading error just across +-pi is small, not 2 pi: pose_error wraps it before the NLL.
    gt = np.array([[0.0, 0.0, np.pi - 0.01]])
    est = np.array([[0.0, 0.0, -np.pi + 0.01]])
    t = np.array([0.0])
    v = lm.nll_at_truth(lm.align(t, est, t, gt, np.eye(3)[None] * 0.01))[0]
    assert v == pytest.approx(0.5 * (0.02**2 / 0.01 + 3 * np.log(2 * np.pi) + np.log(1e-6)))


def test_nll_ranks_an_overcautious_covariance_below_a_matched_one() -> None:
    # Both have a NEES near 3 or below; only the NLL tells the 100-times-too-large covariance apart.
    e = np.random.default_rng(1).standard_normal((2000, 3)) * 0.01
    matched = lm.nll(e, np.broadcast_to(np.eye(3) * 1e-4, (2000, 3, 3))).mean()
    cautious = lm.nll(e, np.broadcast_to(np.eye(3) * 1e-2, (2000, 3, 3))).mean()
    assert matched < cautious


def test_nll_is_inf_for_a_singular_covariance() -> None:
    P = np.stack([np.diag([1.0, 1.0, 0.0]), np.eye(3)])
    e = np.zeros((2, 3))
    out = lm.nll(e, P)
    assert out[0] == np.inf and np.isfinite(out[1])


def test_nll_of_a_collapsed_covariance_is_inf_without_a_warning() -> None:
    # P exactly singular: NEES +inf and log det -inf; their sum must not warn (pytest turns warnings into errors)
    P = np.zeros((1, 3, 3))
    assert lm.nll(np.array([[0.1, 0.0, 0.0]]), P)[0] == np.inf
    rank1 = np.outer([1.0, 0.0, 0.0], [1.0, 0.0, 0.0])[None]
    assert lm.nll(np.array([[0.0, 1.0, 0.0]]), rank1)[0] == np.inf


# --- declarations ----------------------------------------------------------------------------------------------


def _view(run: RunRecord, truth: TruthRecord) -> lm.RunView:
    return lm.RunView(run, truth, lm.align_run(run, truth))


@pytest.fixture
def declared_here() -> Iterator[list[str]]:
    """Ids a test declares; withdrawn afterwards, so the registry is the built-in one again."""
    ids: list[str] = []
    yield ids
    for i in ids:
        lm.METRICS.pop(i, None)


def test_every_value_of_a_run_is_a_declared_metric_and_no_family_value_is_dropped() -> None:
    run, truth = _run(), _truth()
    got = lm.run_metrics(run, truth)
    for k in got:
        assert lm.declared(k).per_run, k
    view = _view(run, truth)
    families = {m.family for m in lm.METRICS.values() if m.family is not None}
    for family in families:
        for k, v in family(view).items():
            assert np.isnan(v) or got[k] == v, k


def test_a_declared_metric_is_computed_for_every_ok_run_and_left_out_when_nan(declared_here: list[str]) -> None:
    toy = lm.declare(
        lm.Metric("max_error_m", header="max error", unit="m", compute=lambda v: float(v.aligned.position_error.max()))
    )
    declared_here.append(toy.id)
    assert lm.run_metrics(_run(), _truth())["max_error_m"] == pytest.approx(0.3)
    assert lm.run_metrics(_run("error"), _truth()) == {"failed": 1.0}
    undefined = lm.declare(lm.Metric("undefined_m", header="undefined", unit="m", compute=lambda v: float("nan")))
    declared_here.append(undefined.id)
    assert "undefined_m" not in lm.run_metrics(_run(), _truth())


def test_a_family_is_computed_once_per_run_for_all_its_metrics(declared_here: list[str]) -> None:
    calls: list[int] = []

    def family(v: lm.RunView) -> dict[str, float]:
        calls.append(1)
        return {"toy_a": 1.0, "toy_part_1_m": 2.0, "toy_part_2_m": 3.0, "toy_unclaimed": 4.0}

    for m in (
        lm.Metric("toy_a", header="a", unit="1", family=family),
        lm.Metric("toy_part_<j>_m", header="part", unit="m", family=family),
    ):
        declared_here.append(lm.declare(m).id)
    got = lm.run_metrics(_run(), _truth())
    assert calls == [1]
    assert (got["toy_a"], got["toy_part_1_m"], got["toy_part_2_m"]) == (1.0, 2.0, 3.0)
    assert "toy_unclaimed" not in got  # a family value no metric declares is not a metric


def test_an_id_is_declared_once() -> None:
    with pytest.raises(ValueError, match="declared already"):
        lm.declare(lm.Metric(lm.ATE_M, header="ATE", unit="m", compute=lambda v: 0.0))
    with pytest.raises(ValueError, match="declared already"):  # a member of a declared family
        lm.declare(lm.Metric("waypoint_3_error_m", header="w3", unit="m", compute=lambda v: 0.0))
    with pytest.raises(ValueError, match="declared already"):  # a family holding a declared id
        lm.declare(lm.Metric("<what>_m_per_m", header="x", unit="1", family=lambda v: {}))


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"id": "Bad Id"}, "lower-case"),
        ({"better": "smaller"}, "better must be one of"),
        ({"better": "closer"}, "finite target"),
        ({"group": "misc"}, "group must be one of"),
        ({"absent": ""}, "absent must be one of"),
        ({"compute": lambda v: 0.0, "family": lambda v: {}}, "not both"),
        ({"id": "toy_<j>_m", "compute": lambda v: 0.0}, "family function"),
        ({"id": "toy_<j>_m", "family": lambda v: {}, "summary": True}, "not a family's"),
    ],
)
def test_a_declaration_is_checked(fields: dict[str, object], message: str) -> None:
    args: dict[str, object] = {"id": "toy_m", "header": "toy", "unit": "m"} | fields
    with pytest.raises(ValueError, match=message):
        lm.Metric(**args)  # type: ignore[arg-type]


def test_member_ids_and_their_declaration() -> None:
    assert lm.member_id(lm.WAYPOINT_ERROR_M, 3) == "waypoint_3_error_m"
    assert lm.member_id(lm.SCORE_CI_LOW, "crps_x", "m") == "crps_x_ci_low_m"
    with pytest.raises(ValueError, match="1 part"):
        lm.member_id(lm.WAYPOINT_ERROR_M)
    assert lm.declared("waypoint_12_error_m") is lm.METRICS[lm.WAYPOINT_ERROR_M]
    assert lm.declared("energy_score_ci_high_m") is lm.METRICS[lm.SCORE_CI_HIGH]
    assert lm.declared(lm.ATE_M) is lm.METRICS[lm.ATE_M]
    assert not lm.METRICS[lm.WAYPOINT_ERROR_M].matches("waypoint_x_error_m")  # a one-letter part is a number
    with pytest.raises(KeyError, match="no metric declares"):
        lm.declared("waypoint_rmse_m")


def test_the_bound_gives_the_metrics_declared_with_bound() -> None:
    from locbench.evaluate.pcrb import pcrb_summary

    t = np.linspace(0.0, 4.0, 5)
    cov = np.broadcast_to(np.diag([0.01, 0.04, 0.001]), (5, 3, 3)).copy()
    ids = pcrb_summary(t, cov, np.array([1.0, 3.0]))
    assert {lm.declared(k).id for k in ids} == {m.id for m in lm.METRICS.values() if m.bound}
