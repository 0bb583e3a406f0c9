"""Split-and-merge line extraction (filters/_line_extraction.py): geometry, gaps, covariance, edge cases."""

from __future__ import annotations

import math

import numpy as np
import pytest

from locbench.core.errors import ConfigError
from locbench.core.events import LaserScan
from locbench.filters._line_extraction import ExtractionParams, extract_lines, fit_line


def _cast(segments: np.ndarray, angles: np.ndarray, max_range: float) -> np.ndarray:
    """Exact ranges from the origin along ``angles`` to the nearest of ``segments`` (x1, y1, x2, y2)."""
    out = np.full(angles.shape, np.inf)
    for k, a in enumerate(angles):
        d = np.array([math.cos(a), math.sin(a)])
        for x1, y1, x2, y2 in segments:
            p, s = np.array([x1, y1]), np.array([x2 - x1, y2 - y1])
            den = d[0] * s[1] - d[1] * s[0]
            if abs(den) < 1e-12:
                continue
            t = (p[0] * s[1] - p[1] * s[0]) / den
            u = (p[0] * d[1] - p[1] * d[0]) / den
            if t > 0 and 0 <= u <= 1 and t < out[k]:
                out[k] = t
    out[out > max_range] = np.inf
    return out


def _scan(segments: list[tuple[float, float, float, float]], beams: int = 181, fov: float = 2 * math.pi * 2 / 3):
    angles = -0.5 * fov + fov / (beams - 1) * np.arange(beams)
    r = _cast(np.asarray(segments, dtype=np.float64), angles, 8.0)
    return LaserScan(0.0, -0.5 * fov, fov / (beams - 1), r, 0.02, 8.0)


def _hessian(seg: tuple[float, float, float, float]) -> tuple[float, float]:
    x1, y1, x2, y2 = seg
    psi = math.atan2(x2 - x1, -(y2 - y1))
    rho = x1 * math.cos(psi) + y1 * math.sin(psi)
    if rho < 0:
        rho, psi = -rho, psi + math.pi
    return rho, math.atan2(math.sin(psi), math.cos(psi))


def test_box_walls_are_recovered() -> None:
    walls = [(3.0, -2.0, 3.0, 2.0), (3.0, 2.0, -1.5, 2.0), (-1.5, 2.0, -1.5, -2.0), (-1.5, -2.0, 3.0, -2.0)]
    lines = extract_lines(_scan(walls))
    assert len(lines) >= 3
    truth = np.array([_hessian(w) for w in walls])
    for (rho, psi), length in zip(lines.rho_psi, lines.lengths, strict=True):
        dpsi = np.abs(np.angle(np.exp(1j * (truth[:, 1] - psi))))
        k = int(np.argmin(np.abs(truth[:, 0] - rho) + dpsi))
        assert rho == pytest.approx(truth[k, 0], abs=1e-6)
        assert dpsi[k] < 1e-6
        assert 0 < length <= 4.5 + 1e-9
    assert np.all(lines.rho_psi[:, 0] >= 0) and np.all(np.abs(lines.rho_psi[:, 1]) <= math.pi)
    assert np.all(np.linalg.eigvalsh(lines.cov) > 0)


def test_door_gap_splits_a_wall() -> None:
    # one wall line x = 2 with a 1 m gap: two segments on the same infinite line, not one bridging the door
    walls = [(2.0, -3.0, 2.0, -0.5), (2.0, 0.5, 2.0, 3.0), (5.0, -5.0, 5.0, 5.0)]
    lines = extract_lines(_scan(walls))
    on_wall = np.abs(lines.rho_psi[:, 0] - 2.0) < 1e-6
    assert np.count_nonzero(on_wall) == 2
    assert np.all(lines.lengths[on_wall] <= 2.5 + 1e-9)


def test_corner_is_split_and_endpoints_lie_on_the_lines() -> None:
    walls = [(2.0, -3.0, 2.0, 1.0), (2.0, 1.0, -2.0, 1.0)]
    lines = extract_lines(_scan(walls))
    assert len(lines) == 2
    for (rho, psi), ends in zip(lines.rho_psi, lines.endpoints, strict=True):
        n = np.array([math.cos(psi), math.sin(psi)])
        np.testing.assert_allclose(ends @ n, rho, atol=1e-9)


def test_line_through_the_sensor_position() -> None:
    # a wall whose infinite line passes 1 mm from the robot: rho ~ 0, psi either normal
    walls = [(0.5, 0.001, 4.0, 0.001), (4.0, -3.0, 4.0, 3.0)]
    scan = _scan(walls, beams=721, fov=math.radians(359.0))
    lines = extract_lines(scan)
    assert len(lines) >= 1
    assert np.all(np.isfinite(lines.rho_psi))


def test_too_few_points_give_no_lines() -> None:
    scan = LaserScan(0.0, -1.0, 0.1, np.array([np.inf, 1.0, 1.0, np.inf, np.inf]), 0.02, 5.0)
    assert len(extract_lines(scan)) == 0
    assert extract_lines(scan).rho_psi.shape == (0, 2)


def test_fit_covariance_matches_monte_carlo() -> None:
    rng = np.random.default_rng(7)
    s = np.linspace(-1.0, 1.5, 20)
    psi0, rho0, sigma = 0.4, 2.0, 0.01
    n, t = np.array([math.cos(psi0), math.sin(psi0)]), np.array([-math.sin(psi0), math.cos(psi0)])
    base = rho0 * n + s[:, None] * t
    draws = []
    for _ in range(2000):
        pts = base + sigma * rng.standard_normal(20)[:, None] * n
        rho, psi, _, _ = fit_line(pts, sigma)
        draws.append((rho, psi))
    emp = np.cov(np.asarray(draws).T)
    _, _, cov, _ = fit_line(base, sigma)
    np.testing.assert_allclose(np.diag(emp), np.diag(cov), rtol=0.15)
    assert emp[0, 1] == pytest.approx(cov[0, 1], rel=0.2)


def test_noise_does_not_shatter_a_wall() -> None:
    rng = np.random.default_rng(1)
    scan = _scan([(3.0, -3.0, 3.0, 3.0)])
    noisy = LaserScan(0.0, scan.angle_min, scan.angle_increment, scan.ranges + 0.03 * rng.standard_normal(181), 0.02, 8)
    lines = extract_lines(noisy, ExtractionParams(sigma_m=0.03))
    assert len(lines) == 1
    assert lines.rho_psi[0, 0] == pytest.approx(3.0, abs=0.02)


@pytest.mark.parametrize(
    "kwargs", [{"split_threshold_m": 0.0}, {"min_points": 2}, {"gap_factor": 0.5}, {"sigma_m": 0.0}, {"gap_min_m": -1}]
)
def test_bad_params_raise(kwargs: dict[str, float]) -> None:
    with pytest.raises(ConfigError):
        ExtractionParams(**kwargs)  # type: ignore[arg-type]


def _scan_points_numpy(scan: LaserScan) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Step 1 of the extraction in numpy: the valid returns' points (robot frame, m), ranges and beam indices."""
    r = np.asarray(scan.ranges, dtype=np.float64)
    ok = np.isfinite(r) & (r >= scan.range_min) & (r < scan.range_max)
    beam = np.flatnonzero(ok).astype(np.int64)
    rr = r[beam]
    sx, sy, sth = scan.sensor_pose
    a = scan.angle_min + scan.angle_increment * beam + sth
    return np.column_stack([sx + rr * np.cos(a), sy + rr * np.sin(a)]), rr, beam


def _segments_numpy(pts: np.ndarray, ranges: np.ndarray, fits: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The end points (k, 2, 2) and lengths (k,) of fitted segments in numpy: each segment's first and last
    point projected on its line (rho n + s t, n = (cos psi, sin psi), t = (-sin psi, cos psi), s the point's
    coordinate along t), the length |s_last - s_first|."""
    psi = fits[:, 1]
    t = np.column_stack([-np.sin(psi), np.cos(psi)])
    nrm = np.column_stack([np.cos(psi), np.sin(psi)])
    ends_xy = pts[np.column_stack([ranges[:, 0], ranges[:, 1] - 1])]  # (k, 2, 2)
    s = np.einsum("kej,kj->ke", ends_xy, t)
    endpoints = fits[:, 0, None, None] * nrm[:, None, :] + s[:, :, None] * t[:, None, :]
    return endpoints, np.abs(s[:, 1] - s[:, 0])


def _random_scan(rng: np.random.Generator) -> LaserScan:
    n = int(rng.integers(1, 400))
    r = rng.uniform(0.0, 12.0, n)
    r[rng.random(n) < 0.1] = np.inf
    r[rng.random(n) < 0.02] = np.nan
    return LaserScan(
        t=0.0,
        angle_min=float(rng.uniform(-math.pi, 0.0)),
        angle_increment=float(rng.uniform(1e-3, 0.05)) * (1 if rng.random() < 0.8 else -1),
        ranges=r,
        range_min=float(rng.uniform(0.0, 0.5)),
        range_max=float(rng.uniform(5.0, 12.0)),
        sensor_pose=(float(rng.normal() * 0.1), float(rng.normal() * 0.1), float(rng.uniform(-math.pi, math.pi))),
    )


def test_scan_points_are_the_valid_returns_in_the_robot_frame() -> None:
    """Step 1 against numpy on random scans: the same beams (indices and ranges as given), the points to 1e-12 m
    (coordinates under 13 m: a few ulp of numpy's vectorised sin and cos; a wrong angle or offset is off by
    centimetres)."""
    from locbench.filters._line_extraction import scan_points

    rng = np.random.default_rng(3)
    for _ in range(300):
        scan = _random_scan(rng)
        (pts, rr, beam), (pts_np, rr_np, beam_np) = scan_points(scan), _scan_points_numpy(scan)
        for g, w in ((pts, pts_np), (rr, rr_np), (beam, beam_np)):
            assert g.dtype == w.dtype and g.shape == w.shape
        assert beam.tolist() == beam_np.tolist()
        assert rr.tolist() == rr_np.tolist() == np.asarray(scan.ranges)[beam].tolist()  # the measured ranges
        np.testing.assert_allclose(pts, pts_np, rtol=0.0, atol=1e-12)


def test_segment_end_points_and_lengths() -> None:
    """The compiled assembly of the fitted segments against numpy on random cuts of random scans: end points and
    lengths to 1e-12 m (coordinates under 20 m), the (rho, psi) and covariances passed through, the segments
    shorter than ``min_length`` dropped (cases with a length within 1e-12 m of it skipped: either side is right)."""
    from locbench.filters import _line_extraction as le

    rng = np.random.default_rng(5)
    checked = 0
    for _ in range(200):
        scan = _random_scan(rng)
        pts, _, _ = le.scan_points(scan)
        m = pts.shape[0]
        if m < 4:
            continue
        cuts = np.sort(rng.choice(np.arange(1, m), size=min(m - 1, int(rng.integers(1, 8))), replace=False))
        lo = np.concatenate([[0], cuts])
        ranges = np.column_stack([lo, np.concatenate([cuts, [m]])]).astype(np.int64)
        k = ranges.shape[0]
        fits = np.column_stack([rng.uniform(0, 5, k), rng.uniform(-math.pi, math.pi, k), rng.random((k, 3))])
        endpoints_np, lengths_np = _segments_numpy(pts, ranges, fits)
        min_length = float(rng.uniform(0.0, 1.0))
        if np.any(np.abs(lengths_np - min_length) < 1e-12):
            continue
        keep = ~(lengths_np < min_length)
        xs, ys = np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1])
        n_keep, rho_psi, cov, endpoints, lengths, n_points = le._assemble(xs, ys, ranges, fits, min_length)
        assert n_keep == np.count_nonzero(keep)
        assert rho_psi.tolist() == fits[keep, :2].tolist()
        assert cov[:, 0, 0].tolist() == fits[keep, 2].tolist() and cov[:, 1, 1].tolist() == fits[keep, 4].tolist()
        assert cov[:, 0, 1].tolist() == cov[:, 1, 0].tolist() == fits[keep, 3].tolist()
        assert n_points.tolist() == (ranges[keep, 1] - ranges[keep, 0]).tolist()
        np.testing.assert_allclose(endpoints, endpoints_np[keep], rtol=0.0, atol=1e-12)
        np.testing.assert_allclose(lengths, lengths_np[keep], rtol=0.0, atol=1e-12)
        checked += n_keep
    assert checked > 100
