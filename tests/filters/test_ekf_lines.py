"""The line-map EKF of report 002 (filters/ekf_lines.py): eq. 3 and its Jacobian, association, gate, length
check, Joseph update, diagnostics, config errors."""

from __future__ import annotations

import math

import laser_reference as ref
import numpy as np
import pytest

from locbench.core.errors import ConfigError
from locbench.core.events import LandmarkObservations, LaserScan, Odometry
from locbench.core.geometry import wrap_angle
from locbench.datasets.dataset import Gaussian2, LineMap, SensorSpec, WorldMap
from locbench.filters._line_extraction import ExtractedLines
from locbench.filters.ekf_lines import LineEKF, LineEKFConfig

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
    rho, psi = ref.expected_line(pose, rp[rows, 0], rp[rows, 1])
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


def _stacked(pose: tuple[float, float, float], rho_w: float, psi_w: float, z: tuple[float, float], sign: float):  # type: ignore[no-untyped-def]
    """The filter's H (2, 3) and innovation v (2,) of one observed line ``z`` against one map line."""
    from locbench.filters.ekf_lines import _stack

    one = np.zeros(1, dtype=np.int64)
    rw, pw = np.array([rho_w]), np.array([psi_w])
    H, v, _ = _stack(
        one, one, np.array([sign]), rw, pw, np.cos(pw), np.sin(pw), np.array([z]), np.zeros((1, 2, 2)),
        np.zeros((2, 2)), *pose,
    )  # fmt: skip
    return H, v


def test_eq3_matches_the_report_form() -> None:
    # h = z - v for the filter's innovation; eq. 3 as the report writes it (polar form of the robot's position)
    pose = (1.3, 2.2, 0.7)
    rho_w, psi_w = 4.0, 0.3
    z = (3.5, 0.1)
    _, v = _stacked(pose, rho_w, psi_w, z, 1.0)
    r = math.hypot(pose[0], pose[1])
    assert z[0] - v[0] == pytest.approx(rho_w - r * math.cos(math.atan2(pose[1], pose[0]) - psi_w), rel=1e-14)
    assert z[1] - v[1] == pytest.approx(psi_w - pose[2], rel=1e-14)
    # the flipped form (-rho_r, psi_r + pi)
    _, vf = _stacked(pose, rho_w, psi_w, z, -1.0)
    assert z[0] - vf[0] == pytest.approx(-(z[0] - v[0]), rel=1e-14)
    assert math.remainder(vf[1] - v[1] - math.pi, 2 * math.pi) == pytest.approx(0.0, abs=1e-14)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_jacobian_matches_finite_differences(sign: float) -> None:
    pose = np.array([1.3, -0.4, 2.9])
    psi_w, rho_w = -2.1, 1.7

    def h(p: np.ndarray) -> np.ndarray:
        rho, psi = ref.expected_line(p, rho_w, psi_w)
        return np.array([sign * float(rho), float(psi)])

    num = np.zeros((2, 3))
    for k in range(3):
        e = np.zeros(3)
        e[k] = 1e-6
        d = h(pose + e) - h(pose - e)
        d[1] = math.remainder(d[1], 2 * math.pi)
        num[:, k] = d / 2e-6
    H, _ = _stacked(tuple(pose), rho_w, psi_w, (1.0, 0.0), sign)
    np.testing.assert_allclose(H, num, atol=1e-7)
    np.testing.assert_allclose(H, ref.expected_line_jacobian(psi_w, sign), rtol=1e-15, atol=1e-16)


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


def test_update_is_the_stacked_joseph_correction_of_eq_5_to_8() -> None:
    """One scan's update against the reference: the accepted lines' H, v and R stacked (eq. 3-4) and one Joseph
    correction (eq. 5-8) at the predicted state; the mean to 1e-12 (m, rad), the covariance to 1e-12 of its
    diagonal's scale, NIS to 1e-10 relative."""
    truth = (2.0, 1.5, 0.3)
    f = _filter((2.04, 1.47, 0.31))
    obs = _observed(truth, [0, 1, 2, 3])
    x0, P0 = f.estimate().mean, f.estimate().cov
    matches = f.associate(obs)
    assert len(matches) == 4
    H = np.zeros((8, 3))
    v = np.zeros(8)
    R = np.zeros((8, 8))
    R0 = np.diag([0.02**2, 0.0175**2])
    rp = LineMap(BOX).rho_psi()
    for r, (j, i, sg, _) in enumerate(matches):
        H[2 * r : 2 * r + 2] = ref.expected_line_jacobian(rp[i, 1], sg)
        v[2 * r : 2 * r + 2] = ref.line_innovation(tuple(obs.rho_psi[j]), rp[i, 0], rp[i, 1], tuple(x0), sg)
        R[2 * r : 2 * r + 2, 2 * r : 2 * r + 2] = obs.cov[j] + R0
    x_ref, P_ref, nis_ref = ref.joseph_correct(x0, P0, v, H, R)
    f._correct(obs)
    est = f.estimate()
    np.testing.assert_allclose(est.mean, x_ref, rtol=0, atol=1e-12)
    scale = np.sqrt(np.outer(np.diag(P_ref), np.diag(P_ref)))
    np.testing.assert_allclose(est.cov / scale, P_ref / scale, rtol=0, atol=1e-12)
    assert est.diagnostics["nis"] == pytest.approx(nis_ref, rel=1e-10)


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


def _random_lines(rng: np.random.Generator):  # type: ignore[no-untyped-def]
    """A random map (rho_w, psi_w), observed lines z (k, 2) with fit covariances (k, 2, 2), R0 and a belief."""
    n, k = int(rng.integers(1, 30)), int(rng.integers(1, 10))
    rho_w, psi_w = rng.uniform(0, 10, n), rng.uniform(-math.pi, math.pi, n)
    z = np.column_stack([rng.uniform(0, 10, k), rng.uniform(-math.pi, math.pi, k)])
    a = rng.normal(size=(k, 2, 2)) * 0.01
    cov = a @ np.transpose(a, (0, 2, 1))
    R0 = np.diag(rng.uniform(1e-4, 1e-2, 2))
    b = rng.normal(size=(3, 3)) * rng.uniform(0.01, 1.0)
    return rho_w, psi_w, z, cov, R0, tuple(rng.normal(size=3) * [3.0, 3.0, 2.0]), b @ b.T + 1e-6 * np.eye(3)


def test_compiled_innovations_and_jacobians_are_eq_3_and_4() -> None:
    """The stacked H, v and R of the accepted lines against the reference of eq. 3-4 on random maps and beliefs:
    v to 1e-12 (m, rad), H to 1e-15, R the fit covariance plus R0 to 1e-15; the acceptance by the gate and the
    length check exact."""
    from locbench.filters.ekf_lines import _accept, _stack

    rng = np.random.default_rng(8)
    for _ in range(200):
        rho_w, psi_w, z, cov, R0, pose, _ = _random_lines(rng)
        n, k = rho_w.shape[0], z.shape[0]
        best = rng.integers(0, n, k).astype(np.int64)
        sign = np.where(rng.random(k) < 0.3, -1.0, 1.0)
        d2 = rng.uniform(0, 10, k)
        d2[rng.random(k) < 0.1] = np.nan
        lengths, len_w = rng.uniform(0, 3, k), rng.uniform(0, 3, n)
        acc, rg, rl = _accept(best, d2, lengths, len_w, 5.99, True, 0.3)
        want_acc = [j for j in range(k) if d2[j] <= 5.99 and not lengths[j] > len_w[best[j]] + 0.3]
        assert acc.tolist() == want_acc and rg == int(np.sum(~(d2 <= 5.99))) and rg + rl + len(acc) == k
        H, v, R = _stack(acc, best, sign, rho_w, psi_w, np.cos(psi_w), np.sin(psi_w), z, cov, R0, *pose)
        m = len(want_acc)
        assert H.shape == (2 * m, 3) and v.shape == (2 * m,) and R.shape == (2 * m, 2 * m)
        R_ref = np.zeros((2 * m, 2 * m))
        for r, j in enumerate(want_acc):
            i, sg = int(best[j]), float(sign[j])
            v_ref = ref.line_innovation((z[j, 0], z[j, 1]), rho_w[i], psi_w[i], pose, sg)
            np.testing.assert_allclose(v[2 * r : 2 * r + 2], v_ref, rtol=0, atol=1e-12)
            np.testing.assert_allclose(H[2 * r : 2 * r + 2], ref.expected_line_jacobian(psi_w[i], sg), atol=1e-15)
            R_ref[2 * r : 2 * r + 2, 2 * r : 2 * r + 2] = cov[j] + R0
        np.testing.assert_allclose(R, R_ref, rtol=1e-15, atol=0)


def test_association_takes_the_nearest_map_line_by_mahalanobis_distance() -> None:
    """_nearest_lines against the reference of eq. 3-5 on random maps and beliefs: for each observed line, over
    every map line in the form its psi selects, d2 = v^T (H P H^T + R)^-1 v; the minimum to 1e-9 relative, at
    the same map line (or one whose d2 ties within that), with its form's sign."""
    from locbench.filters.ekf_lines import _nearest_lines

    rng = np.random.default_rng(9)
    for _ in range(200):
        rho_w, psi_w, z, cov, R0, pose, P = _random_lines(rng)
        best, sign, d2 = _nearest_lines(*pose, rho_w, psi_w, np.cos(psi_w), np.sin(psi_w), z, cov, R0, P)
        for j in range(z.shape[0]):
            d2_ref, sg_ref = [], []
            for i in range(rho_w.shape[0]):
                _, psi_r = ref.expected_line(pose, rho_w[i], psi_w[i])
                sg = -1.0 if abs(math.remainder(z[j, 1] - float(psi_r), 2 * math.pi)) > 0.5 * math.pi else 1.0
                v = np.array(ref.line_innovation((z[j, 0], z[j, 1]), rho_w[i], psi_w[i], pose, sg))
                H = ref.expected_line_jacobian(psi_w[i], sg)
                d2_ref.append(float(v @ np.linalg.solve(H @ P @ H.T + cov[j] + R0, v)))
                sg_ref.append(sg)
            i_ref = int(np.argmin(d2_ref))
            assert d2[j] == pytest.approx(d2_ref[i_ref], rel=1e-9)
            assert d2_ref[int(best[j])] == pytest.approx(d2_ref[i_ref], rel=1e-9)
            assert sign[j] == sg_ref[int(best[j])]
