"""The line-map EKF of report 002 (filters/ekf_lines.py): eq. 3 and its Jacobian, association, gate, length
check, Joseph update, diagnostics, config errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from locbench.core.errors import ConfigError
from locbench.core.events import LandmarkObservations, LaserScan, Odometry
from locbench.core.geometry import wrap_angle
from locbench.datasets.dataset import Gaussian2, LineMap, SensorSpec, WorldMap
from locbench.filters._line_extraction import ExtractedLines
from locbench.filters.ekf_lines import LineEKF, LineEKFConfig, expected_line, expected_line_jacobian

BOX = np.array([[0.0, 0.0, 6.0, 0.0], [6.0, 0.0, 6.0, 4.0], [6.0, 4.0, 0.0, 4.0], [0.0, 4.0, 0.0, 0.0]])
SPEC = SensorSpec(odometry_sigma_xy_per_m=0.01, odometry_sigma_theta_per_m=0.02, laser_sigma_m=0.01)


def _filter(pose: tuple[float, float, float], sigma: float = 0.05, **cfg: object) -> LineEKF:
    f = LineEKF(LineEKFConfig(**cfg))  # type: ignore[arg-type]
    cov = np.diag([sigma**2, sigma**2, (sigma / 2) ** 2])
    f.reset(Gaussian2(np.array(pose), cov), WorldMap(lines=LineMap(BOX)), SPEC, np.random.default_rng(0))
    return f


def _observed(pose: tuple[float, float, float], rows: list[int], lengths: list[float] | None = None) -> ExtractedLines:
    """The map lines ``rows`` as seen exactly from ``pose`` (rho >= 0), with a small fit covariance."""
    rp = LineMap(BOX).rho_psi()
    rho, psi = expected_line(pose, rp[rows, 0], rp[rows, 1])
    neg = rho < 0
    rho, psi = np.abs(rho), wrap_angle(np.where(neg, psi + math.pi, psi))
    k = len(rows)
    ln = np.asarray(lengths if lengths is not None else [1.0] * k, dtype=np.float64)
    return ExtractedLines(
        np.column_stack([rho, psi]),
        np.tile(np.diag([1e-4, 1e-4]), (k, 1, 1)),
        np.zeros((k, 2, 2)),
        ln,
        np.full(k, 10, dtype=np.int64),
    )


def test_eq3_matches_the_report_form() -> None:
    pose = (1.3, 2.2, 0.7)
    rho_w, psi_w = 4.0, 0.3
    rho, psi = expected_line(pose, rho_w, psi_w)
    r = math.hypot(pose[0], pose[1])
    assert float(rho) == pytest.approx(rho_w - r * math.cos(math.atan2(pose[1], pose[0]) - psi_w))
    assert float(psi) == pytest.approx(psi_w - pose[2])


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_jacobian_matches_finite_differences(sign: float) -> None:
    pose = np.array([1.3, -0.4, 2.9])
    psi_w, rho_w = -2.1, 1.7

    def h(p: np.ndarray) -> np.ndarray:
        rho, psi = expected_line(p, rho_w, psi_w)
        return np.array([sign * float(rho), float(psi)])

    num = np.zeros((2, 3))
    for k in range(3):
        e = np.zeros(3)
        e[k] = 1e-6
        d = h(pose + e) - h(pose - e)
        d[1] = math.remainder(d[1], 2 * math.pi)
        num[:, k] = d / 2e-6
    np.testing.assert_allclose(expected_line_jacobian(psi_w, sign), num, atol=1e-7)


def test_exact_observations_are_accepted_and_leave_the_pose() -> None:
    pose = (2.0, 1.5, 0.3)
    f = _filter(pose)
    matches = f.associate(_observed(pose, [0, 1, 2, 3]))
    assert [(j, i) for j, i, _, _ in matches] == [(0, 0), (1, 1), (2, 2), (3, 3)]
    assert all(d2 < 1e-9 for *_, d2 in matches)
    P0 = f.estimate().cov
    f._correct(_observed(pose, [0, 1, 2, 3]))
    est = f.estimate()
    np.testing.assert_allclose(est.mean, pose, atol=1e-9)
    assert np.linalg.det(est.cov) < np.linalg.det(P0)
    np.testing.assert_allclose(est.cov, est.cov.T)
    assert np.all(np.linalg.eigvalsh(est.cov) > 0)
    assert est.diagnostics["accepted"] == 4 and est.diagnostics["rejected"] == 0
    assert est.diagnostics["nis_dof"] == 8


def test_update_pulls_toward_the_observed_pose() -> None:
    truth = (2.0, 1.5, 0.3)
    f = _filter((2.05, 1.46, 0.31))
    f._correct(_observed(truth, [0, 1, 2, 3]))
    err = f.estimate().mean - np.array(truth)
    assert np.hypot(err[0], err[1]) < 0.01 and abs(err[2]) < 0.005


def test_gate_rejects_far_observations() -> None:
    truth = (2.0, 1.5, 0.0)
    f = _filter((2.3, 1.5, 0.0), sigma=0.02, chi2_threshold=9.21)
    f._correct(_observed(truth, [1, 3]))  # the two walls x = 6 and x = 0, 0.3 m off in rho
    d = f.estimate().diagnostics
    assert d["accepted"] == 0 and d["rejected_gate"] == 2 and math.isnan(d["nis"])
    g = _filter((2.3, 1.5, 0.0), sigma=0.02, chi2_threshold=1e6)
    g._correct(_observed(truth, [1, 3]))
    assert g.estimate().diagnostics["accepted"] == 2


def test_line_through_the_robot_matches_either_normal() -> None:
    # the robot stands on the line y = 0 (rho_w = 0): the observed normal may point either way
    pose = (3.0, 0.0, 0.4)
    f = _filter(pose)
    obs = _observed(pose, [0])
    for psi in (obs.rho_psi[0, 1], wrap_angle(obs.rho_psi[0, 1] + math.pi)):
        flipped = ExtractedLines(np.array([[1e-4, psi]]), obs.cov, obs.endpoints, obs.lengths, obs.n_points)
        (match,) = f.associate(flipped)
        assert match[1] == 0 and match[3] < 1.0


def test_length_check_rejects_lines_longer_than_their_map_line() -> None:
    pose = (2.0, 1.5, 0.0)
    on = _filter(pose, reject_longer=True, length_margin_m=0.1)
    on._correct(_observed(pose, [1, 0], lengths=[4.5, 3.0]))  # x = 6 is 4 m long; y = 0 is 6 m long
    d = on.estimate().diagnostics
    assert d["rejected_length"] == 1 and d["accepted"] == 1 and d["rejected"] == 1
    off = _filter(pose, reject_longer=False)
    off._correct(_observed(pose, [1, 0], lengths=[4.5, 3.0]))
    assert off.estimate().diagnostics["accepted"] == 2


def test_predict_compounds_and_grows_covariance() -> None:
    f = _filter((1.0, 1.0, math.pi / 2), sigma=0.01)
    P0 = f.estimate().cov
    f.predict(Odometry(t=0.05, dx=0.1, dy=0.0, dtheta=0.05))
    est = f.estimate()
    np.testing.assert_allclose(est.mean, [1.0, 1.1, math.pi / 2 + 0.05], atol=1e-12)
    assert np.linalg.slogdet(est.cov)[1] > np.linalg.slogdet(P0)[1]
    assert est.diagnostics["accepted"] == 0 and math.isnan(est.diagnostics["nis"])


def test_scan_update_and_foreign_events() -> None:
    f = _filter((2.0, 2.0, 0.0))
    angles = np.linspace(-2.0, 2.0, 61)
    # only the wall x = 6, 4 m ahead, within 4.4 m (a 3.7 m piece of the 4 m wall)
    ranges = np.where(np.cos(angles) > 0, 4.0 / np.maximum(np.cos(angles), 1e-9), np.inf)
    ranges[ranges >= 4.4] = np.inf
    f.update(LaserScan(0.1, -2.0, 4.0 / 60, ranges, 0.02, 4.4))
    d = f.estimate().diagnostics
    assert d["extracted"] >= 1 and d["accepted"] >= 1
    with pytest.raises(TypeError):
        f.update(LandmarkObservations(0.2, np.array([0]), np.array([1.0]), np.array([0.0])))


def test_needs_a_line_map() -> None:
    f = LineEKF()
    with pytest.raises(ConfigError, match="line map"):
        f.reset(Gaussian2(np.zeros(3), np.eye(3)), WorldMap(), SPEC, np.random.default_rng(0))


@pytest.mark.parametrize(
    "kwargs",
    [{"chi2_threshold": 0.0}, {"sigma_rho_m": -1.0}, {"laser_sigma_m": 0.0}, {"min_points": 2}],
)
def test_bad_config_raises(kwargs: dict[str, float]) -> None:
    with pytest.raises(ConfigError):
        LineEKFConfig(**kwargs)  # type: ignore[arg-type]


@pytest.mark.slow
def test_localizes_on_line_room() -> None:
    from locbench.registry import make_dataset
    from locbench.run.filter_pass import run_filter

    ds = make_dataset("line_room[laser_beams=91]", 0)
    tr = run_filter(LineEKF(), ds, np.random.default_rng(0))
    assert tr.status == "ok"
    idx = np.clip(np.searchsorted(tr.t, ds.ground_truth.t, side="right") - 1, 0, tr.t.size - 1)
    err = tr.mean[idx, :2] - ds.ground_truth.xy
    assert float(np.sqrt(np.mean(np.sum(err**2, axis=1)))) < 0.05


def test_joseph_correct_without_likelihood_equals_kalman_core_bit_for_bit() -> None:
    from locbench.filters._kalman import joseph_correct
    from locbench.filters.ekf_lines import _joseph_correct

    rng = np.random.default_rng(2)
    for _ in range(200):
        a = rng.normal(size=(3, 3))
        P = a @ a.T + 1e-4 * np.eye(3)
        k = int(rng.integers(1, 6))
        H = rng.normal(size=(2 * k, 3))
        b = rng.normal(size=(2 * k, 2 * k)) * 0.1
        R = b @ b.T + 1e-3 * np.eye(2 * k)
        x, y = rng.normal(size=3), rng.normal(size=2 * k)
        want = joseph_correct(x, P, y, H, R)
        xn, Pn, nis = _joseph_correct(x, P, y, H, R)
        assert np.array_equal(xn, want.x) and np.array_equal(Pn, want.P) and nis == want.nis


def test_scalar_finite_check_matches_numpy_verdict() -> None:
    from locbench.core.errors import FilterDiverged

    f = LineEKF(LineEKFConfig())
    for bad in (math.nan, math.inf, -math.inf):
        for i in range(12):
            x, P = np.ones(3), np.eye(3)
            (x if i < 3 else P).ravel()[i if i < 3 else i - 3] = bad
            f._x, f._P = x, P
            with pytest.raises(FilterDiverged):
                f._check_finite(0.0)
    f._x, f._P = np.ones(3), np.eye(3)
    f._check_finite(0.0)


def test_compiled_stack_equals_python_loop_bit_for_bit() -> None:
    # the compiled H, v, R of the accepted lines against the plain-float Python loop it replaced
    from locbench.core.geometry import wrap_scalar
    from locbench.filters.ekf_lines import _accept, _stack

    rng = np.random.default_rng(8)
    for _ in range(200):
        n, k = int(rng.integers(1, 30)), int(rng.integers(1, 10))
        rho_w, psi_w = rng.uniform(0, 10, n), rng.uniform(-math.pi, math.pi, n)
        cos_w, sin_w = np.cos(psi_w), np.sin(psi_w)
        z = np.column_stack([rng.uniform(0, 10, k), rng.uniform(-math.pi, math.pi, k)])
        a = rng.normal(size=(k, 2, 2)) * 0.01
        cov = a @ np.transpose(a, (0, 2, 1))
        R0 = np.diag(rng.uniform(1e-4, 1e-2, 2))
        best = rng.integers(0, n, k).astype(np.int64)
        sign = np.where(rng.random(k) < 0.3, -1.0, 1.0)
        d2 = rng.uniform(0, 10, k)
        d2[rng.random(k) < 0.1] = np.nan
        lengths, len_w = rng.uniform(0, 3, k), rng.uniform(0, 3, n)
        px, py, pth = rng.normal(size=3)
        acc, rg, rl = _accept(best, d2, lengths, len_w, 5.99, True, 0.3)
        want_acc = [j for j in range(k) if d2[j] <= 5.99 and not lengths[j] > len_w[best[j]] + 0.3]
        assert acc.tolist() == want_acc and rg == int(np.sum(~(d2 <= 5.99))) and rg + rl + len(acc) == k
        H, v, R = _stack(acc, best, sign, rho_w, psi_w, cos_w, sin_w, z, cov, R0, px, py, pth)
        m = len(want_acc)
        H0, v0, Rr = np.zeros((2 * m, 3)), np.zeros(2 * m), np.zeros((2 * m, 2 * m))
        zl, R_lines = z.tolist(), cov + R0
        for r, j in enumerate(want_acc):
            i, sg = int(best[j]), float(sign[j])
            pw = float(psi_w[i])
            H0[2 * r, 0], H0[2 * r, 1], H0[2 * r + 1, 2] = -sg * math.cos(pw), -sg * math.sin(pw), -1.0
            rho_p = float(rho_w[i]) - (px * float(cos_w[i]) + py * float(sin_w[i]))
            h_psi = wrap_scalar(pw - pth) + (math.pi if sg < 0 else 0.0)
            v0[2 * r] = zl[j][0] - sg * rho_p
            v0[2 * r + 1] = wrap_scalar(zl[j][1] - h_psi)
            Rr[2 * r : 2 * r + 2, 2 * r : 2 * r + 2] = R_lines[j]
        assert np.array_equal(H, H0) and np.array_equal(v, v0) and np.array_equal(R, Rr)
