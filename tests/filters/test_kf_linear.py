"""Tests of the linear Kalman filter of report 004 (locbench.filters.kf_linear)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

pytest.importorskip("filterpy")

from locbench.core.errors import ConfigError, FilterDiverged
from locbench.core.events import LandmarkObservations, LaserScan, Odometry
from locbench.core.geometry import pose_error
from locbench.datasets.dataset import Gaussian2, SensorSpec
from locbench.filters.kf_linear import LinearKF, LinearKFConfig
from locbench.raycast.cast import cast_rays
from locbench.registry import make_dataset
from locbench.run.filter_pass import run_filter


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


#: The filter against filterpy agrees to rounding, not bit for bit: both go through numpy and OpenBLAS/LAPACK, whose
#: kernels are chosen per CPU, and a product or layout that differs between the two codes can round differently
#: there. Each element within REL of its array's largest magnitude (normwise); a wrong term is off by O(1).
REL = 1e-12


def _same_as_filterpy(f: LinearKF, kf: Any) -> None:
    """The filter's state equals filterpy's within :data:`REL`, the heading as a wrapped difference."""
    from locbench.core.geometry import wrap_scalar

    x, want = f._x.copy(), np.asarray(kf.x, dtype=np.float64)
    x[2, 0] = want[2, 0] + wrap_scalar(float(x[2, 0] - want[2, 0]))  # near +-pi one side may wrap to the other end
    np.testing.assert_allclose(x, want, rtol=REL, atol=REL * float(np.max(np.abs(want))))
    np.testing.assert_allclose(f._P, kf.P, rtol=REL, atol=REL * float(np.max(np.abs(kf.P))))


def _filterpy_reference(x: np.ndarray, P: np.ndarray) -> Any:
    from filterpy.kalman import KalmanFilter

    kf = KalmanFilter(dim_x=3, dim_z=3)
    kf.x = x.reshape(3, 1).copy()
    kf.P = P.copy()
    return kf


def _random_belief(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    a = rng.normal(size=(3, 3)) * rng.uniform(0.01, 1.0)
    x = rng.normal(size=3) * 5.0
    x[2] = math.remainder(x[2], 2 * math.pi)
    return x, a @ a.T + 1e-6 * np.eye(3)


def test_predict_equals_filterpy() -> None:
    # the written-out predict (F = I, B u in floats) against filterpy's KalmanFilter.predict, commands and increments
    from locbench.core.geometry import wrap_scalar

    rng = np.random.default_rng(7)
    f = _reset_filter()
    for k in range(300):
        x, P = _random_belief(rng)
        f._x, f._P = x.reshape(3, 1).copy(), P.copy()
        kf = _filterpy_reference(x, P)
        v, om, dt = rng.normal() * (k % 3 != 0), rng.normal() * (k % 4 != 0), rng.uniform(0.01, 0.5)
        dx, dy, dth = rng.normal(size=3) * 0.1
        cmd = k % 2 == 0
        u = Odometry(t=1.0, dx=dx, dy=dy, dtheta=dth, v=v if cmd else None, omega=om if cmd else None, dt=dt)
        f.predict(u)
        c, s = math.cos(x[2]), math.sin(x[2])
        if cmd:
            B, uu = np.array([[c * dt, 0.0], [s * dt, 0.0], [0.0, dt]]), np.array([[v], [om]])
        else:
            B, uu = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), np.array([[dx], [dy], [dth]])
        dist, turn = (abs(v) * dt, abs(om) * dt) if cmd else (math.hypot(dx, dy), abs(dth))
        from locbench.filters._motion import increment_variances

        vxy, vth = increment_variances(dist, 0.0, turn, *f._sig)
        cfg = f.config
        Q = np.diag([vxy + cfg.sigma_floor_xy_m**2, vxy + cfg.sigma_floor_xy_m**2, vth + cfg.sigma_floor_theta_rad**2])
        kf.predict(u=uu, B=B, F=np.eye(3), Q=Q)
        kf.x[2, 0] = wrap_scalar(float(kf.x[2, 0]))
        _same_as_filterpy(f, kf)


def test_update_algebra_equals_filterpy(monkeypatch: pytest.MonkeyPatch) -> None:
    # the written-out update (H = I) against filterpy's KalmanFilter.update on random beliefs and pose fixes
    import locbench.filters.kf_linear as kfl
    from locbench.core.geometry import wrap_scalar
    from locbench.filters._scan_database import ScanMatch

    rng = np.random.default_rng(11)
    f = _reset_filter()
    scan = LaserScan(
        t=2.0, angle_min=0.0, angle_increment=math.pi / 4, ranges=np.ones(8), range_min=0.0, range_max=10.0
    )
    for _ in range(300):
        x, P = _random_belief(rng)
        zx, R = _random_belief(rng)
        m = ScanMatch(z=zx, cov=R, n_matches=3, best_score_m=0.01, n_bearings=8)
        monkeypatch.setattr(kfl, "match_scan", lambda *a, m=m, **k: (m, 8))
        f._x, f._P = x.reshape(3, 1).copy(), P.copy()
        f.update(scan)
        kf = _filterpy_reference(x, P)
        zc = zx.reshape(3, 1).copy()
        zc[2, 0] = float(kf.x[2, 0]) + wrap_scalar(float(zc[2, 0] - kf.x[2, 0]))
        kf.update(zc, R=R, H=np.eye(3))
        kf.x[2, 0] = wrap_scalar(float(kf.x[2, 0]))
        kf.P = 0.5 * (kf.P + kf.P.T)
        y = np.asarray(kf.y).reshape(3)
        _same_as_filterpy(f, kf)
        assert f.estimate().diagnostics["nis"] == pytest.approx(float(y @ np.linalg.solve(kf.S, y)), rel=1e-9)


def test_finite_check_matches_numpy_verdict() -> None:
    f = _reset_filter()
    for bad in (math.nan, math.inf, -math.inf):
        for i in range(12):
            x, P = np.ones((3, 1)), np.eye(3)
            (x if i < 3 else P).ravel()[i if i < 3 else i - 3] = bad
            f._x, f._P = x, P
            with pytest.raises(FilterDiverged):
                f._check_finite(0.0)
    f._x, f._P = np.ones((3, 1)), np.eye(3)
    f._check_finite(0.0)
