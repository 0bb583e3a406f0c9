"""Tests of the linear Kalman filter of report 004 (locbench.filters.kf_linear)."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("filterpy")

from locbench.datasets.base import Gaussian2, SensorSpec
from locbench.errors import ConfigError
from locbench.events import LandmarkObservations, LaserScan, Odometry
from locbench.filters.kf_linear import LinearKF, LinearKFConfig
from locbench.geometry import pose_error
from locbench.raycast import cast_rays
from locbench.registry import make_dataset
from locbench.runner import run_filter


def _run(spec: str, seed: int = 0, **cfg: object) -> tuple[np.ndarray, LinearKF]:
    ds = make_dataset(spec, seed)
    f = LinearKF(LinearKFConfig(**cfg))  # type: ignore[arg-type]
    tr = run_filter(f, ds, np.random.default_rng(0))
    assert tr.status == "ok", tr.message
    idx = np.clip(np.searchsorted(tr.t, ds.ground_truth.t, side="right") - 1, 0, len(tr.t) - 1)
    err = pose_error(tr.mean[idx], ds.ground_truth.poses)
    return err, f


def _reset_filter(**cfg: object) -> LinearKF:
    ds = make_dataset("scan_grid", 0)
    f = LinearKF(LinearKFConfig(**cfg))  # type: ignore[arg-type]
    f.reset(
        Gaussian2(mean=np.array([1.0, 1.0, 0.5]), cov=np.diag([0.01, 0.01, 0.01])),
        ds.world,
        SensorSpec(odometry_sigma_xy_per_m=0.01, odometry_sigma_theta_per_m=0.01, odometry_sigma_theta_per_rad=0.01),
        np.random.default_rng(0),
    )
    return f


def test_prediction_is_linear_with_heading_frozen_in_b() -> None:
    f = _reset_filter()
    P0 = f.estimate().cov.copy()
    f.predict(Odometry(t=1.0, dx=0.0, dy=0.0, dtheta=0.0, v=0.2, omega=0.3, dt=1.0))
    est = f.estimate()
    # report 004 sec. II: x += cos(theta) dt v, y += sin(theta) dt v, theta += dt omega, theta at the start
    np.testing.assert_allclose(est.mean, [1.0 + 0.2 * math.cos(0.5), 1.0 + 0.2 * math.sin(0.5), 0.8], atol=1e-12)
    # F = I: P grows by Q only, no heading-position coupling
    dP = est.cov - P0
    assert dP[0, 2] == 0.0 and dP[1, 2] == 0.0 and np.all(np.diag(dP) > 0)
    assert est.diagnostics["linear_input"] == 1.0


def test_increment_fallback_without_commands() -> None:
    f = _reset_filter()
    f.predict(Odometry(t=1.0, dx=0.1, dy=0.02, dtheta=0.1))
    c, s = math.cos(0.5), math.sin(0.5)
    np.testing.assert_allclose(f.estimate().mean, [1.0 + 0.1 * c - 0.02 * s, 1.0 + 0.1 * s + 0.02 * c, 0.6], atol=1e-12)
    assert f.estimate().diagnostics["linear_input"] == 0.0


def test_heading_innovation_is_wrapped() -> None:
    ds = make_dataset("scan_grid", 0)
    grid = ds.world.occupancy
    assert grid is not None
    truth = np.array([2.0, 2.5, math.pi])
    angles = -math.pi + np.radians(np.arange(361.0))
    r = cast_rays(grid.occupied(), grid.resolution, grid.origin[:2], truth, angles, 8.0, method="dda")[0]
    scan = LaserScan(
        t=0.0, angle_min=-math.pi, angle_increment=math.radians(1.0), ranges=r, range_min=0.0, range_max=8.0
    )
    f = LinearKF()
    prior = Gaussian2(mean=np.array([2.0, 2.5, -math.pi + 0.03]), cov=np.diag([0.01, 0.01, 0.01]))
    f.reset(prior, ds.world, ds.sensors, np.random.default_rng(0))
    f.update(scan)
    est = f.estimate()
    assert est.diagnostics["accepted"] == 1.0
    # the match (heading pi) is 0.03 rad away across +-pi, not 2 pi - 0.03: the estimate stays near +-pi
    assert abs(math.remainder(est.mean[2] - math.pi, 2 * math.pi)) < 0.03
    assert -math.pi < est.mean[2] <= math.pi


def test_no_match_is_counted_and_foreign_events_raise() -> None:
    f = _reset_filter(tolerance_m=1e-6)
    ds = make_dataset("scan_grid", 0)
    scan = next(e for e in ds.events if isinstance(e, LaserScan))
    f.update(scan)
    d = f.estimate().diagnostics
    assert d["rejected"] == 1.0 and d["no_match"] == 1.0
    with pytest.raises(TypeError):
        f.update(LandmarkObservations(t=0.0, ids=np.zeros(0, np.int64), ranges=np.zeros(0), bearings=np.zeros(0)))


def test_localizes_on_scan_grid_far_below_odometry() -> None:
    err, f = _run("scan_grid", 0)
    ate = float(np.sqrt(np.mean(err[:, 0] ** 2 + err[:, 1] ** 2)))
    assert ate < 0.05
    assert int(f.extra_results()["no_match_scans"]) < 40


@pytest.mark.parametrize(
    "cfg", [{"heading_step_deg": 7.0}, {"grid_step_m": 0.0}, {"gate_probability": 0.0}, {"min_bearings": 9}]
)
def test_bad_config(cfg: dict[str, float]) -> None:
    with pytest.raises(ConfigError):
        LinearKFConfig(**cfg)  # type: ignore[arg-type]
