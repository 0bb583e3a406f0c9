"""Tests of the scan-database front-end of report 004 (locbench.filters._scan_database)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from locbench.core.errors import ConfigError
from locbench.core.events import LaserScan
from locbench.core.geometry import wrap_angle
from locbench.datasets.dataset import OccupancyGrid
from locbench.filters._scan_database import (
    N_BEARINGS,
    ScanDatabase,
    build_database,
    match_scan,
    scan_bearing_ranges,
)
from locbench.raycast.cast import cast_rays


def _room() -> OccupancyGrid:
    """A 4 m x 3 m room (0.05 m cells) with a block in one corner so that no symmetry aliases poses."""
    res = 0.05
    occ = np.zeros((70, 90))
    occ[5, 5:86] = occ[65, 5:86] = 1.0
    occ[5:66, 5] = occ[5:66, 85] = 1.0
    occ[50:65, 70:85] = 1.0
    return OccupancyGrid(occupancy=occ, resolution=res, origin=(-0.25, -0.25, 0.0))


def _cast(grid: OccupancyGrid, pose: np.ndarray, angles: np.ndarray) -> np.ndarray:
    return cast_rays(grid.occupied(), grid.resolution, grid.origin[:2], pose, angles, 8.0, method="dda")[0]


def _scan(grid: OccupancyGrid, pose: np.ndarray, beams: int = 361, fov: float = 2 * math.pi) -> LaserScan:
    angles = -0.5 * fov + fov / (beams - 1) * np.arange(beams)
    r = _cast(grid, pose, angles)
    return LaserScan(
        t=0.0, angle_min=-0.5 * fov, angle_increment=fov / (beams - 1), ranges=r, range_min=0.0, range_max=8.0
    )


def test_database_positions_on_world_lattice_and_clear_of_walls() -> None:
    grid = _room()
    db = build_database(grid, 0.25, 15.0, 8.0, 0.2)
    np.testing.assert_allclose(np.round(db.positions / 0.25) * 0.25, db.positions, atol=1e-12)
    assert db.n_headings == 24 and len(db) == db.positions.shape[0] * 24
    # every position at least 0.2 m from the walls (walls at x = 0 and 4, y = 0 and 3 in cell centres)
    assert np.all(db.positions[:, 0] >= 0.2) and np.all(db.positions[:, 1] >= 0.2)


def test_entry_ranges_are_the_eight_bearings_of_a_ray_cast() -> None:
    grid = _room()
    db = build_database(grid, 0.25, 15.0, 8.0, 0.2)
    i, h = 7, 5
    pose = db.entry_pose(i, h)
    expected = _cast(grid, pose, np.arange(N_BEARINGS) * math.pi / 4)
    np.testing.assert_allclose(db.entry_ranges(i, h), np.minimum(expected, 8.0), atol=1e-9)


def test_exact_scan_at_a_database_pose_matches_it() -> None:
    grid = _room()
    db = build_database(grid, 0.25, 5.0, 8.0, 0.2)
    pose = np.array([1.5, 1.0, math.radians(40.0)])
    m, k = match_scan(db, _scan(grid, pose), tolerance_m=0.02)
    assert m is not None and k == N_BEARINGS
    np.testing.assert_allclose(m.z, pose, atol=1e-9)
    assert m.best_score_m == pytest.approx(0.0, abs=1e-9)
    # a single exact match: the covariance is the quantisation s^2/12, h^2/12
    np.testing.assert_allclose(np.diag(m.cov), [0.25**2 / 12, 0.25**2 / 12, math.radians(5.0) ** 2 / 12], rtol=1e-9)


def test_off_lattice_pose_matches_nearby_with_gate() -> None:
    grid = _room()
    db = build_database(grid, 0.25, 5.0, 8.0, 0.2)
    pose = np.array([2.1, 1.62, -2.0])
    prior = (pose + np.array([0.05, -0.05, 0.03]), np.diag([0.1**2, 0.1**2, 0.05**2]))
    m, _ = match_scan(db, _scan(grid, pose), tolerance_m=0.15, prior=prior, gate=16.27)
    assert m is not None
    assert math.hypot(*(m.z[:2] - pose[:2])) < 0.2
    assert abs(math.remainder(m.z[2] - pose[2], 2 * math.pi)) < math.radians(6.0)


def test_narrow_scan_uses_the_bearings_it_covers_and_no_return_is_capped() -> None:
    grid = _room()
    pose = np.array([1.5, 1.0, 0.0])
    scan = _scan(grid, pose, beams=31, fov=math.radians(240.0))
    idx, r = scan_bearing_ranges(scan)
    assert idx.tolist() == [0, 1, 2, 6, 7]  # 0, +-45, +-90 deg; 45 is 3 deg from its beam (8 deg spacing)
    assert r.shape == (5,)
    db = build_database(grid, 0.25, 5.0, 8.0, 0.2)
    none, k = match_scan(db, scan, tolerance_m=0.15, min_bearings=6)
    assert none is None and k == 5


def test_no_match_beyond_tolerance() -> None:
    grid = _room()
    db = build_database(grid, 0.25, 5.0, 8.0, 0.2)
    scan = _scan(grid, np.array([1.5, 1.0, 0.0]))
    far = LaserScan(
        t=0.0,
        angle_min=scan.angle_min,
        angle_increment=scan.angle_increment,
        ranges=scan.ranges * 0 + 0.05,
        range_min=0.0,
        range_max=8.0,
    )
    assert match_scan(db, far, tolerance_m=0.05)[0] is None


@pytest.mark.parametrize(("step", "hstep"), [(0.0, 5.0), (0.25, 7.0)])
def test_bad_database_parameters(step: float, hstep: float) -> None:
    with pytest.raises(ConfigError, match=r"grid_step_m|heading_step_deg"):
        build_database(_room(), step, hstep, 8.0, 0.2)


def _reference_scores(db, scan, tol, prior, gate):  # type: ignore[no-untyped-def]
    """Score every entry in numpy, then gate: the entries (i, h) within the tolerance and inside the validation
    region, their scores, and every entry's score and squared Mahalanobis distance (to find the cases on a
    boundary, where either side is right)."""
    b_idx, r = scan_bearing_ranges(scan)
    cap = min(float(scan.range_max), db.max_range_m)
    rc = np.minimum(np.where(np.isfinite(r), r, cap), cap)
    m = db.n_headings // N_BEARINGS
    cols = (np.arange(db.n_headings)[:, None] + (b_idx * m)[None, :]) % db.n_headings  # (M, k)
    scores = np.abs(np.minimum(db.ranges, cap)[:, cols] - rc).mean(axis=2)  # (N, M)
    hs = db.heading_step_rad
    ii, hh = np.nonzero(scores <= tol)
    d2 = np.zeros(ii.shape)
    if prior is not None and math.isfinite(gate):
        quant = np.diag([db.step_m**2 / 12.0, db.step_m**2 / 12.0, hs**2 / 12.0])
        e = np.column_stack(
            [db.positions[ii] - prior[0][:2], np.remainder(hh * hs - prior[0][2] + np.pi, 2 * np.pi) - np.pi]
        )
        d2 = np.einsum("ij,ij->i", e @ np.linalg.inv(prior[1] + quant), e)
    inside = d2 <= gate
    return ii[inside], hh[inside], scores[ii[inside], hh[inside]], scores, d2


def _reference_match(db, scan, tol, prior, gate):  # type: ignore[no-untyped-def]
    """The matched entries (i, h) and their scores, scored and gated in numpy."""
    return _reference_scores(db, scan, tol, prior, gate)[:3]


@pytest.mark.parametrize("spread", [0.05, 0.3, 1.5])
def test_gate_first_matching_equals_scoring_everything_then_gating(spread: float) -> None:
    grid = _room()
    db = build_database(grid, 0.25, 5.0, 8.0, 0.2)
    rng = np.random.default_rng(3)
    for _ in range(6):
        pose = np.array([rng.uniform(0.4, 3.2), rng.uniform(0.4, 2.2), rng.uniform(-math.pi, math.pi)])
        mean = pose + rng.normal(0.0, [spread, spread, spread / 2])
        a = rng.normal(size=(3, 3)) * spread
        prior = (mean, a @ a.T + np.diag([spread**2, spread**2, (spread / 2) ** 2]))
        scan = _scan(grid, pose)
        ii, _hh, d = _reference_match(db, scan, 0.15, prior, 16.27)
        m, _ = match_scan(db, scan, tolerance_m=0.15, prior=prior, gate=16.27)
        if ii.size == 0:
            assert m is None
            continue
        assert m is not None and m.n_matches == ii.size
        assert m.best_score_m == pytest.approx(float(d.min()), abs=1e-12)
        w = 1.0 - d / 0.15
        z_xy = (w / w.sum()) @ db.positions[ii]
        np.testing.assert_allclose(m.z[:2], z_xy, atol=1e-9)


def _measurement_reference(db: ScanDatabase, ii: np.ndarray, hh: np.ndarray, d: np.ndarray, tol: float):  # type: ignore[no-untyped-def]
    """The pose measurement of the module docstring in numpy: triangular weights, the weighted mean pose
    (headings as wrapped differences from the best match) and the weighted scatter plus the quantisation."""
    best = int(np.argmin(d))
    w = 1.0 - d / tol if tol > 0 else np.ones_like(d)
    if not np.sum(w) > 0:
        w = np.ones_like(d)
    w = w / np.sum(w)
    th = hh * db.heading_step_rad
    xy = db.positions[ii]
    z_th = th[best] + w @ wrap_angle(th - th[best])
    z = np.array([w @ xy[:, 0], w @ xy[:, 1], float(wrap_angle(z_th))])
    dev = np.column_stack([xy - z[:2], wrap_angle(th - z[2])])
    hs = db.heading_step_rad
    cov = (dev * w[:, None]).T @ dev + np.diag([db.step_m**2 / 12.0, db.step_m**2 / 12.0, hs**2 / 12.0])
    return z, 0.5 * (cov + cov.T), float(d[best])


def test_match_scan_is_the_numpy_measurement() -> None:
    """match_scan against numpy, gated and not, on noisy scans at random poses with random priors (many matches
    each, loose tolerances included): the same matches, the measured pose to 1e-12 (m, rad), its covariance to
    1e-12 of its diagonal's scale, the best score to 1e-12 m. A case with a score within 1e-12 m of the
    tolerance or a distance within 1e-9 relative of the gate is skipped: either side of it is right."""
    grid = _room()
    db = build_database(grid, 0.25, 5.0, 8.0, 0.2)
    rng = np.random.default_rng(9)
    compared = 0
    for _ in range(150):
        pose = np.array([rng.uniform(0.4, 3.4), rng.uniform(0.4, 2.4), rng.uniform(-math.pi, math.pi)])
        scan = _scan(
            grid, pose, beams=int(rng.choice([181, 361])), fov=float(rng.choice([math.pi * 4 / 3, 2 * math.pi]))
        )
        scan = LaserScan(
            t=0.0, angle_min=scan.angle_min, angle_increment=scan.angle_increment,
            ranges=scan.ranges + rng.normal(0, 0.02, scan.ranges.shape), range_min=0.0, range_max=8.0,
        )  # fmt: skip
        a = rng.normal(size=(3, 3)) * rng.uniform(0.05, 1.0)
        prior = (pose + rng.normal(0, 0.2, 3), a @ a.T + 1e-3 * np.eye(3))
        tol = float(rng.choice([0.0, 0.1, 0.3, 0.6]))
        gate = float(rng.choice([math.inf, 16.27, 100.0]))
        ii, hh, d, scores, d2 = _reference_scores(db, scan, tol, prior, gate)
        if (tol > 0 and np.any(np.abs(scores - tol) < 1e-12)) or np.any(np.abs(d2 - gate) < 1e-9 * gate):
            continue
        got, k = match_scan(db, scan, tol, 4, prior=prior, gate=gate)
        assert k == scan_bearing_ranges(scan)[0].shape[0]
        assert (got is None) == (ii.size == 0)
        if got is None:
            continue
        z, cov, best = _measurement_reference(db, ii, hh, d, tol)
        assert got.n_matches == ii.size
        np.testing.assert_allclose(got.z, z, rtol=0, atol=1e-12)
        scale = np.sqrt(np.outer(np.diag(cov), np.diag(cov)))
        np.testing.assert_allclose(got.cov / scale, cov / scale, rtol=0, atol=1e-12)
        assert got.best_score_m == pytest.approx(best, abs=1e-12)
        compared += ii.size > 1
    assert compared > 50
