"""EKF-ICP (report 000): the ICP scan matcher, the prediction noise, the H = I update, the mismatch and kidnap rules."""

from __future__ import annotations

import math

import laser_reference as ref
import numpy as np
import pytest
from kalman_reference import joseph_correct_pose

from locbench.core.errors import ConfigError
from locbench.core.events import LaserScan, Odometry
from locbench.core.geometry import compose, inverse
from locbench.datasets.dataset import Gaussian2, SensorSpec
from locbench.datasets.synthetic.scenarios import office_world
from locbench.filters._icp import icp_2d, rigid_transform_2d
from locbench.filters.ekf_icp import IcpEKF, IcpEKFConfig
from locbench.raycast.cast import cast_rays

ANGLES = -math.radians(120.0) + math.radians(240.0) / 682 * np.arange(683)


@pytest.fixture(scope="module")
def world_map():  # type: ignore[no-untyped-def]
    return office_world().world_map(0.05)


def _scan(world_map, pose, sigma: float = 0.0, rng: np.random.Generator | None = None) -> LaserScan:  # type: ignore[no-untyped-def]
    g = world_map.occupancy
    r = cast_rays(g.occupied(), g.resolution, g.origin[:2], np.asarray(pose, dtype=float), ANGLES, 5.6)[0]
    if sigma > 0 and rng is not None:
        r = r + sigma * rng.standard_normal(r.shape)
    r[r > 5.6] = np.inf
    return LaserScan(
        t=1.0, angle_min=float(ANGLES[0]), angle_increment=float(ANGLES[1] - ANGLES[0]), ranges=r,
        range_min=0.02, range_max=5.6,
    )  # fmt: skip


def _filter(world_map, mean, cov=None, **cfg) -> IcpEKF:  # type: ignore[no-untyped-def]
    f = IcpEKF(IcpEKFConfig(**cfg))
    c = np.diag([0.05**2, 0.05**2, math.radians(2.0) ** 2]) if cov is None else cov
    f.reset(Gaussian2(mean=np.asarray(mean, dtype=float), cov=c), world_map, SensorSpec(laser_sigma_m=0.01), None)  # type: ignore[arg-type]
    return f


def test_rigid_transform_exact() -> None:
    rng = np.random.default_rng(1)
    src = rng.uniform(-3, 3, (50, 2))
    T = (0.3, -0.2, 0.4)
    c, s = math.cos(T[2]), math.sin(T[2])
    dst = src @ np.array([[c, s], [-s, c]]) + T[:2]
    np.testing.assert_allclose(rigid_transform_2d(src, dst), T, atol=1e-12)


def test_icp_recovers_offset_between_ray_cast_scans(world_map) -> None:  # type: ignore[no-untyped-def]
    # in a room: in the corridor the match is degenerate along it (report 000 sec. V)
    true_pose = np.array([15.5, 3.0, 0.1])
    pred_pose = np.array([15.56, 2.96, 0.1 + math.radians(1.5)])
    real, pred = _scan(world_map, true_pose), _scan(world_map, pred_pose)
    ok_r, ok_p = np.isfinite(real.ranges), np.isfinite(pred.ranges)
    src = ref.beam_points(real.ranges[ok_r], ANGLES[ok_r], (0.0, 0.0, 0.0))
    dst = ref.beam_points(pred.ranges[ok_p], ANGLES[ok_p], (0.0, 0.0, 0.0))
    res = icp_2d(src, dst, max_correspondence_m=0.4, min_correspondence_m=0.075)
    assert res.converged and res.matched > 0.8 * src.shape[0]
    expected = compose(inverse(pred_pose), true_pose)  # M = X^-1 T
    np.testing.assert_allclose(res.transform[:2], expected[:2], atol=0.02)
    assert abs(res.transform[2] - expected[2]) < math.radians(0.3)


def test_icp_too_few_points_is_not_converged() -> None:
    res = icp_2d(np.zeros((2, 2)), np.zeros((5, 2)), max_correspondence_m=0.1, min_correspondence_m=0.05)
    assert not res.converged and res.matched == 0


def test_update_moves_toward_truth_by_the_gain(world_map) -> None:  # type: ignore[no-untyped-def]
    truth = np.array([15.5, 3.0, 0.3])
    pred = truth + np.array([0.05, -0.04, math.radians(1.0)])
    f = _filter(world_map, pred)
    P = f.estimate().cov
    f.update(_scan(world_map, truth))
    est = f.estimate()
    assert est.diagnostics["accepted"] == 1.0 and est.diagnostics["rejected"] == 0.0
    K = P @ np.linalg.inv(P + np.diag([0.008, 0.008, 0.01]))
    np.testing.assert_allclose(est.mean - pred, K @ (truth - pred), atol=0.012)
    # Joseph form: symmetric, and smaller than the prior
    np.testing.assert_allclose(est.cov, est.cov.T)
    assert np.linalg.det(est.cov) < np.linalg.det(P)


def test_repeated_scans_converge_to_truth(world_map) -> None:  # type: ignore[no-untyped-def]
    rng = np.random.default_rng(3)
    truth = np.array([15.0, 4.0, -1.2])
    f = _filter(world_map, truth + np.array([-0.06, 0.05, -math.radians(2.0)]))
    for k in range(40):  # standing still: zero odometry at 20 Hz, scans at 10 Hz
        f.predict(Odometry(t=0.1 * k + 0.05, dx=0.0, dy=0.0, dtheta=0.0, dt=0.05))
        f.predict(Odometry(t=0.1 * k + 0.1, dx=0.0, dy=0.0, dtheta=0.0, dt=0.05))
        f.update(_scan(world_map, truth, sigma=0.01, rng=rng))
    err = f.estimate().mean - truth
    assert math.hypot(err[0], err[1]) < 0.02 and abs(err[2]) < math.radians(0.5)


def test_prediction_eq_11_to_13(world_map) -> None:  # type: ignore[no-untyped-def]
    f = _filter(world_map, (1.0, 2.0, math.pi / 2), cov=np.zeros((3, 3)))
    f.predict(Odometry(t=0.05, dx=0.1, dy=0.0, dtheta=0.02, dt=0.05))
    est = f.estimate()
    # robot-frame dx = 0.1 at heading pi/2 is world dy = 0.1
    np.testing.assert_allclose(est.mean, (1.0, 2.1, math.pi / 2 + 0.02), atol=1e-12)
    # static terms per 0.1 s scaled to dt = 0.05 s, dynamic terms per |world increment|
    np.testing.assert_allclose(
        np.diag(est.cov), (0.00025 + 0.001 * 0.0, 0.00025 + 0.001 * 0.1, 0.00025 + 0.0011 * 0.02), atol=1e-15
    )


def test_mismatch_keeps_prediction_and_kidnap_rule(world_map) -> None:  # type: ignore[no-untyped-def]
    truth = np.array([12.0, 7.25, 0.0])
    f = _filter(world_map, truth, kidnap_mismatches=5)
    empty = _scan(world_map, truth)
    empty = LaserScan(
        t=1.0, angle_min=empty.angle_min, angle_increment=empty.angle_increment,
        ranges=np.full(683, np.inf), range_min=0.02, range_max=5.6,
    )  # fmt: skip
    P0 = f.estimate().cov
    for k in range(4):
        f.update(empty)
        d = f.estimate().diagnostics
        assert d["rejected"] == 1.0 and d["consecutive_mismatches"] == k + 1
        np.testing.assert_array_equal(f.estimate().cov, P0)
    f.update(empty)  # the 5th: covariance x 10, threshold tightened
    np.testing.assert_allclose(f.estimate().cov, 10.0 * P0)
    assert f.estimate().diagnostics["kidnap_resets"] == 1.0 and f._tightened
    f.update(_scan(world_map, truth))
    assert f.estimate().diagnostics["accepted"] == 1.0 and not f._tightened


def test_scan_far_from_the_prediction_is_a_mismatch(world_map) -> None:  # type: ignore[no-untyped-def]
    # the robot is in a room, the filter believes it is in the corridor: too few points agree
    f = _filter(world_map, (12.0, 7.25, 0.0), cov=np.diag([1e-4, 1e-4, 1e-4]))
    f.update(_scan(world_map, (3.0, 3.0, 1.0)))
    assert f.estimate().diagnostics["rejected"] == 1.0


@pytest.mark.parametrize(
    ("field", "value"),
    [("q_x_stat_m2", -1.0), ("r_theta_rad2", 0.0), ("min_matched_fraction", 1.5), ("kidnap_threshold_factor", 0.0)],
)
def test_config_errors_name_the_field(field: str, value: float) -> None:
    with pytest.raises(ConfigError, match=field):
        IcpEKFConfig(**{field: value})


def test_bucket_nearest_neighbour_is_the_kd_tree_neighbour() -> None:
    """The bucket grid's exact search finds scipy's k-d tree neighbour: the same point, or one whose distance
    ties with it to 1e-15 relative (the two libraries round the distances differently); the same distances to
    1e-15 relative, and no neighbour where the tree finds none within the bound."""
    from numba import njit
    from scipy.spatial import cKDTree

    from locbench.filters._icp import _buckets, _nearest_within

    @njit
    def query(pts: np.ndarray, q: np.ndarray, gate: float, bound: float) -> tuple[np.ndarray, np.ndarray]:
        grid = _buckets(pts, gate)
        d = np.empty(q.shape[0])
        j = np.empty(q.shape[0], dtype=np.int64)
        for i in range(q.shape[0]):
            d[i], j[i] = _nearest_within(q[i, 0], q[i, 1], pts, grid, bound)
        return d, j

    rng = np.random.default_rng(4)
    # a scan-like cloud: points along three walls plus scatter, queried near and far from it
    t = rng.uniform(0.0, 1.0, 300)
    walls = np.concatenate(
        [np.column_stack([4 * t[:100], np.full(100, 3.0)]), np.column_stack([np.full(100, 4.0), 3 * t[100:200]])]
    )
    pts = np.concatenate([walls, rng.uniform(-1.0, 5.0, (100, 2))])
    q = np.concatenate([pts + rng.normal(0.0, 0.05, pts.shape), rng.uniform(-3.0, 7.0, (300, 2))])
    tree = cKDTree(pts)
    for gate, bound in [(0.5, 0.5), (0.5, 0.08), (0.01, 0.01), (3.0, 3.0)]:
        d, j = query(pts, q, gate, bound)
        dk, jk = tree.query(q, k=1, distance_upper_bound=bound)
        # a distance within 1e-12 relative of the bound may fall on either side of it in either library
        clear = np.abs(dk - bound) > 1e-12 * bound
        within = dk < bound
        np.testing.assert_array_equal((j >= 0)[clear], within[clear])
        assert np.all(np.isinf(d[clear & ~within]))
        found = within & (j >= 0)
        np.testing.assert_allclose(d[found], dk[found], rtol=1e-15, atol=0)
        # another index than the tree's is a tie: that point is as near to 1e-15 relative
        tie = found & (j != jk)
        np.testing.assert_allclose(np.hypot(*(q[tie] - pts[j[tie]]).T), dk[tie], rtol=1e-15, atol=0)


def _random_belief(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    a = rng.standard_normal((3, 3)) * rng.uniform(1e-3, 1.0)
    P = a @ a.T + 1e-9 * np.eye(3)
    x = np.array([rng.uniform(-20, 20), rng.uniform(-20, 20), rng.uniform(-math.pi, math.pi)])
    return x, 0.5 * (P + P.T)


_Q = (0.0005, 0.0004, 0.0003, 0.001, 0.002, 0.0011)
_R = (0.008, 0.006, 0.01)


def test_compiled_prediction_is_eq_11_to_13() -> None:
    """predict_pose against the numpy reference of eq. 11-13 on random beliefs and increments: the mean to
    1e-15 relative (plus 1e-15 rad at a heading near 0), the covariance to 1e-13 of its diagonal's scale; the
    kernel's covariance exactly symmetric."""
    from locbench.filters._ekf_icp_kernels import predict_pose, state_buffer

    rng = np.random.default_rng(11)
    for _ in range(300):
        x, P = _random_belief(rng)
        dx, dy, dth = rng.normal(0.0, 0.1, 3)
        k = rng.uniform(0.0, 2.0)
        s = state_buffer(x, P, _Q, _R, (1e-4, 1.0))
        assert predict_pose(s, dx, dy, dth, k)
        xn, Pn = ref.icp_ekf_predict(x, P, (dx, dy, dth), k, _Q)
        np.testing.assert_allclose(s[0:3], xn, rtol=1e-15, atol=1e-15)
        got = s[3:12].reshape(3, 3)
        scale = np.sqrt(np.outer(np.diag(Pn), np.diag(Pn)))
        np.testing.assert_allclose(got / scale, Pn / scale, rtol=0, atol=1e-13)
        assert np.array_equal(got, got.T)


def test_compiled_correction_is_the_joseph_form_of_eq_15_to_18() -> None:
    """correct_pose against the numpy reference of the H = I Joseph correction, V formed as IcpEKF forms it
    (eq. 2-3), on random beliefs: the mean to 1e-12 m or rad, the covariance to 1e-11 of its diagonal's
    scale, NIS to 1e-10 relative; a non-finite result leaves the state."""
    from locbench.filters._ekf_icp_kernels import correct_pose, state_buffer

    rng = np.random.default_rng(12)
    for _ in range(300):
        x, P = _random_belief(rng)
        tx, ty, tth = rng.normal(0.0, 0.1, 3)
        r = tuple(rng.uniform(1e-6, 0.1, 3))
        s = state_buffer(x, P, _Q, r, (1e-4, 1.0))
        ok, nis = correct_pose(s, tx, ty, tth)
        c, sn = math.cos(x[2]), math.sin(x[2])
        V = np.array([c * tx - sn * ty, sn * tx + c * ty, math.remainder(tth, 2 * math.pi)])
        xn, Pn, nis_ref = joseph_correct_pose(x, P, V, np.diag(r))
        xn[2] = math.remainder(xn[2], 2 * math.pi)
        assert ok
        np.testing.assert_allclose(s[0:3], xn, rtol=0, atol=1e-12)
        scale = np.sqrt(np.outer(np.diag(Pn), np.diag(Pn)))
        np.testing.assert_allclose(s[3:12].reshape(3, 3) / scale, Pn / scale, rtol=0, atol=1e-11)
        assert np.array_equal(s[3:12].reshape(3, 3), s[3:12].reshape(3, 3).T)
        assert nis == pytest.approx(nis_ref, rel=1e-10)
    s = state_buffer(x, P, _Q, _R, (1e-4, 1.0))
    before = s.copy()
    assert not correct_pose(s, math.inf, 0.0, 0.0)[0]
    assert np.array_equal(s, before)  # our own buffer, untouched


def test_compiled_clouds_are_the_beam_points_and_gates() -> None:
    """scan_clouds against the numpy references: the same usable beams (counts exact), their points to 1e-14 m
    (ranges under 6 m; a wrong angle or offset is off by centimetres), the largest eigenvalue of P's position
    block and D_0 to 1e-14 relative, D_min to 1e-15 relative."""
    from locbench.filters._ekf_icp_kernels import BUF_SIGMAS, max_eig_2x2, scan_clouds, state_buffer

    rng = np.random.default_rng(13)
    n = 683
    heading = 0.1
    cos_a, sin_a = np.cos(ANGLES + heading), np.sin(ANGLES + heading)
    for trial in range(100):
        x, P = _random_belief(rng)
        s = state_buffer(x, P, _Q, _R, (2.0 * 0.01**2 + 0.05**2 / 6.0, 1.0 if trial % 2 else 1e3))
        s[BUF_SIGMAS] = rng.uniform(1.0, 6.0)
        real, pred = rng.uniform(0.0, 6.0, n), rng.uniform(0.0, 6.0, n)
        real[rng.random(n) < 0.2], pred[rng.random(n) < 0.2] = np.inf, np.nan
        rmin, rmax, sx, sy = 0.02, 5.6, 0.1, -0.05
        src, dst = np.empty((n, 2)), np.empty((n, 2))
        n_real, n_pred, d_0, d_min = scan_clouds(s, real, pred, cos_a, sin_a, (sx, sy, rmin, rmax), src, dst)
        ok_r = np.isfinite(real) & (real >= rmin) & (real <= rmax)
        ok_p = np.isfinite(pred) & (pred >= rmin)
        assert (n_real, n_pred) == (np.count_nonzero(ok_r), np.count_nonzero(ok_p))
        mount = (sx, sy, heading)
        np.testing.assert_allclose(src[:n_real], ref.beam_points(real[ok_r], ANGLES[ok_r], mount), rtol=0, atol=1e-14)
        np.testing.assert_allclose(dst[:n_pred], ref.beam_points(pred[ok_p], ANGLES[ok_p], mount), rtol=0, atol=1e-14)
        lam = float(np.linalg.eigvalsh(P[0:2, 0:2])[-1])
        assert max_eig_2x2(P[0, 0], P[0, 1], P[1, 1]) == pytest.approx(lam, rel=1e-14)
        d0_ref, dmin_ref = ref.icp_gates(real[ok_r], P, s[21], s[22], s[BUF_SIGMAS])
        assert d_min == pytest.approx(dmin_ref, rel=1e-15)
        assert d_0 == pytest.approx(d0_ref, rel=1e-14)
    few = np.full(n, np.inf)
    few[:2] = 1.0
    assert math.isnan(scan_clouds(s, few, pred, cos_a, sin_a, (sx, sy, rmin, rmax), src, dst)[2])
