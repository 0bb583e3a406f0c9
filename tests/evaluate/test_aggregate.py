"""Hand-computed cases for the aggregations over runs (seeds) of locbench.evaluate.aggregate."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from locbench.evaluate import aggregate as ag


def test_mean_ci_t_interval() -> None:
    ci = ag.mean_ci([1.0, 2.0, 3.0, np.nan])
    h = 4.302652729911275 / np.sqrt(3)  # t_{0.975, 2} * s / sqrt(n) with s = 1
    assert (ci.mean, ci.low, ci.high, ci.n) == pytest.approx((2.0, 2.0 - h, 2.0 + h, 3))
    assert ci.half_width == pytest.approx(h)
    one = ag.mean_ci([5.0])
    assert one.mean == 5.0 and np.isnan(one.low) and one.n == 1
    assert np.isnan(ag.mean_ci([]).mean)


def test_waypoint_rmse_and_distance_of_the_mean() -> None:
    e = np.array([[3.0, 0.0], [4.0, 0.0]])
    np.testing.assert_allclose(ag.waypoint_rmse(e), [np.sqrt(12.5), 0.0])
    # two runs symmetric about waypoint 1: large RMSE, zero distance of the mean (003 table 1)
    est = np.array([[[1.0, 0.0], [5.0, 5.0]], [[-1.0, 0.0], [5.0, 7.0]]])
    marked = np.array([[0.0, 0.0], [2.0, 2.0]])
    np.testing.assert_allclose(ag.mean_estimate_distance(est, marked), [0.0, 5.0])
    np.testing.assert_allclose(ag.mean_estimate_distance(est, np.stack([marked, marked])), [0.0, 5.0])


def test_mean_over_runs_on_a_common_grid() -> None:
    grid = np.array([0.0, 1.0, 2.0])
    runs = [(np.array([0.0, 1.0, 2.0]), np.array([1.0, 2.0, 3.0])), (np.array([0.0, 2.0]), np.array([3.0, np.nan]))]
    mean, count = ag.mean_over_runs(grid, runs)
    np.testing.assert_allclose(mean, [2.0, 2.5, 3.0])
    np.testing.assert_array_equal(count, [2, 2, 1])
    empty, n0 = ag.mean_over_runs(grid, [])
    assert np.all(np.isnan(empty)) and not n0.any()


def test_ate_over_pcrb_is_rms_over_runs_divided_by_the_bound() -> None:
    assert ag.ate_over_pcrb([0.03, 0.04], 0.01) == pytest.approx(np.sqrt((0.03**2 + 0.04**2) / 2) / 0.01)
    assert np.isnan(ag.ate_over_pcrb([], 0.01))
    with pytest.raises(ValueError, match="pcrb_ate_m"):
        ag.ate_over_pcrb([0.1], 0.0)


def test_waypoint_stats_rmse_and_distance_of_mean() -> None:
    rows = [
        ("room", "pf", 0, "waypoint_1_error_m", 0.3),
        ("room", "pf", 0, "waypoint_1_est_x_m", 0.3),
        ("room", "pf", 0, "waypoint_1_est_y_m", 0.0),
        ("room", "pf", 0, "waypoint_1_marked_x_m", 0.0),
        ("room", "pf", 0, "waypoint_1_marked_y_m", 0.0),
        ("room", "pf", 1, "waypoint_1_error_m", 0.4),
        ("room", "pf", 1, "waypoint_1_est_x_m", -0.4),
        ("room", "pf", 1, "waypoint_1_est_y_m", 0.0),
        ("room", "pf", 1, "waypoint_1_marked_x_m", 0.0),
        ("room", "pf", 1, "waypoint_1_marked_y_m", 0.0),
    ]
    ws = ag.waypoint_stats(pd.DataFrame(rows, columns=["dataset", "filter", "seed", "metric", "value"]))
    assert ws.loc[0, "rmse_m"] == pytest.approx(np.sqrt(0.125))
    assert ws.loc[0, "mean_distance_m"] == pytest.approx(0.05)
    assert ws.loc[0, "runs"] == 2
