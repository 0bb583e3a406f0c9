"""Tests of the particle filter (report 003 sec. 4.2) and its likelihood-field laser model."""

from __future__ import annotations

import math

import numpy as np
import pytest
import range_only_support as ro

from locbench.core.errors import ConfigError
from locbench.core.events import UNKNOWN_ID, LandmarkObservations, LaserScan, Odometry, RangeObservations
from locbench.datasets.dataset import Gaussian2, Landmarks, OccupancyGrid, SensorSpec, WorldMap
from locbench.evaluate.metrics import align, nees, nees_at_truth
from locbench.filters import _likelihood_field as lf
from locbench.filters.motion import twist_increment, twist_increment_covariance
from locbench.filters.pf import (
    ParticleFilter,
    ParticleFilterConfig,
    _sightings_loglik,
    sightings_poses,
    systematic_resample,
)
from locbench.raycast.cast import cast_scan
from locbench.registry import make_dataset, resolve_filter
from locbench.run.filter_pass import run_filter


def _box_grid(width: float = 4.0, height: float = 3.0, res: float = 0.05) -> OccupancyGrid:
    rows, cols = round(height / res), round(width / res)
    occ = np.zeros((rows, cols))
    occ[0, :] = occ[-1, :] = 1.0
    occ[:, 0] = occ[:, -1] = 1.0
    return OccupancyGrid(occupancy=occ, resolution=res, origin=(0.0, 0.0, 0.0))


LM_XY = np.array([[0.5, 0.5], [3.5, 0.5], [3.5, 2.5], [0.5, 2.5]])
SENSORS = SensorSpec(
    wheelbase_m=0.4,
    encoder_k_left=0.01,
    encoder_k_right=0.01,
    landmark_sigma_range_m=0.02,
    landmark_sigma_bearing_rad=0.02,
)


def _world(grid: bool = True, landmarks: bool = True) -> WorldMap:
    return WorldMap(
        occupancy=_box_grid() if grid else None,
        landmarks=Landmarks(ids=np.arange(4, dtype=np.int64), xy=LM_XY.copy()) if landmarks else None,
    )


def _initial(mean: tuple[float, float, float] = (2.0, 1.5, 0.3), sigma: float = 0.05) -> Gaussian2:
    return Gaussian2(mean=np.array(mean), cov=np.diag([sigma**2, sigma**2, 0.05**2]))


def _sightings(pose: np.ndarray, ids: list[int], t: float = 1.0, known: bool = True) -> LandmarkObservations:
    d = LM_XY[ids] - pose[:2]
    r = np.hypot(d[:, 0], d[:, 1])
    b = np.angle(np.exp(1j * (np.arctan2(d[:, 1], d[:, 0]) - pose[2])))
    out_ids = np.array(ids, dtype=np.int64) if known else np.full(len(ids), UNKNOWN_ID, dtype=np.int64)
    return LandmarkObservations(t=t, ids=out_ids, ranges=r, bearings=b)


def _pf(**kw: object) -> ParticleFilter:
    return ParticleFilter(ParticleFilterConfig(**kw))  # type: ignore[arg-type]


# --- likelihood field ---------------------------------------------------------------------------------------


def test_distance_field_matches_brute_force_and_is_cached() -> None:
    grid = _box_grid(1.0, 0.75, 0.05)
    dist = lf.distance_field(grid)
    occ = np.argwhere(grid.occupied())
    rows, cols = grid.shape
    ii, jj = np.mgrid[0:rows, 0:cols]
    brute = np.min(np.hypot(ii[..., None] - occ[:, 0], jj[..., None] - occ[:, 1]), axis=-1) * 0.05
    np.testing.assert_allclose(dist, brute, atol=1e-12)
    same = OccupancyGrid(occupancy=grid.occupancy.copy(), resolution=0.05)
    assert lf.distance_field(same) is dist  # equal content -> cached array
    assert not dist.flags.writeable


def test_beam_log_likelihood_is_the_mixture() -> None:
    d = np.array([0.0, 0.1, 5.0])
    got = lf.beam_log_likelihood(d, 0.9, 0.1, 0.2, 4.0)
    want = np.log(0.9 * np.exp(-0.5 * (d / 0.2) ** 2) / (math.sqrt(2 * math.pi) * 0.2) + 0.1 / 4.0)
    np.testing.assert_allclose(got, want)


def test_scan_log_likelihood_peaks_at_the_true_pose() -> None:
    grid = _box_grid()
    field = lf.make_likelihood_field(grid, z_hit=0.95, z_rand=0.05, sigma_hit_m=0.05, max_dist_m=1.0, z_max_m=5.0)
    truth = np.array([1.3, 1.1, 0.4])
    angles = np.linspace(-2.0, 2.0, 41)
    ranges = cast_scan(grid, truth, angles, 5.0)
    ok = np.isfinite(ranges)
    ex, ey = lf.scan_endpoints_robot_frame(ranges[ok], angles[ok], (0.0, 0.0, 0.0))
    poses = truth + np.array([[0.0, 0.0, 0.0], [0.2, 0.0, 0.0], [0.0, -0.15, 0.0], [0.0, 0.0, 0.2]])
    ll = lf.log_likelihood(field, poses, ex, ey)
    assert int(np.argmax(ll)) == 0
    # an endpoint off the grid scores like an endpoint at the clipping distance
    far = lf.log_likelihood(field, np.array([[100.0, 100.0, 0.0]]), ex[:1], ey[:1])
    assert far[0] == pytest.approx(field.log_p_outside)


# --- resampling and config ----------------------------------------------------------------------------------


def test_systematic_resample_counts_are_within_one_of_n_w() -> None:
    rng = np.random.default_rng(3)
    w = rng.random(50)
    w /= w.sum()
    idx = systematic_resample(w, 1000, rng)
    counts = np.bincount(idx, minlength=50)
    assert counts.sum() == 1000
    assert np.all(np.abs(counts - 1000 * w) < 1.0 + 1e-9)  # the low-variance property


@pytest.mark.parametrize(
    ("kw", "field"),
    [
        ({"particles": 1}, "particles"),
        ({"resample_ess_fraction": 1.5}, "resample_ess_fraction"),
        ({"alpha_slow": 0.2, "alpha_fast": 0.1}, "alpha_slow"),
        ({"sigma_hit_m": 0.0}, "sigma_hit_m"),
        ({"use_landmarks": False, "use_laser": False, "use_ranges": False}, "use_landmarks"),
        ({"roughening_k": -1.0}, "roughening_k"),
        ({"inject": "gaussian"}, "inject"),
        ({"recovery_likelihood": "max"}, "recovery_likelihood"),
    ],
)
def test_config_errors_name_the_field(kw: dict[str, object], field: str) -> None:
    with pytest.raises(ConfigError, match=field):
        ParticleFilterConfig(**kw)  # type: ignore[arg-type]


def test_spec_parses_config() -> None:
    cfg = resolve_filter("pf[particles=500,init=uniform,use_laser=true]").params
    assert isinstance(cfg, ParticleFilterConfig)
    assert (cfg.particles, cfg.init, cfg.use_laser) == (500, "uniform", True)


def test_routed_events_follow_the_config() -> None:
    assert _pf().routed_events() == {Odometry, LandmarkObservations, RangeObservations}
    assert _pf(use_laser=True, use_landmarks=False, use_ranges=False).routed_events() == {Odometry, LaserScan}
    assert _pf(use_ranges=False).routed_events() == {Odometry, LandmarkObservations}


def test_reset_without_a_usable_map_is_a_clear_error() -> None:
    with pytest.raises(ConfigError, match="use_laser=true"):
        _pf().reset(_initial(), _world(landmarks=False), SENSORS, np.random.default_rng(0))


# --- filtering ----------------------------------------------------------------------------------------------


def test_estimate_is_the_weighted_circular_mean() -> None:
    f = _pf(particles=4)
    f.reset(_initial(), _world(), SENSORS, np.random.default_rng(0))
    f._x = np.array([[0.0, 0.0, math.pi - 0.1], [1.0, 0.0, -math.pi + 0.1], [0.0, 2.0, math.pi], [1.0, 2.0, math.pi]])
    f._logw = np.log(np.full(4, 0.25))
    f._est = None
    est = f.estimate()
    assert est.mean[:2] == pytest.approx([0.5, 1.0])
    assert abs(abs(est.mean[2]) - math.pi) < 1e-12  # across +-pi, not near 0
    assert est.cov[2, 2] == pytest.approx(0.005, rel=1e-6)  # residuals wrapped: 0.1^2 / 2
    np.testing.assert_allclose(est.cov, est.cov.T)


def test_predict_follows_the_encoder_model_and_spreads() -> None:
    f = _pf(particles=2000)
    f.reset(_initial(sigma=0.001), _world(), SENSORS, np.random.default_rng(1))
    before = f.estimate()
    # straight 0.1 m with both wheels
    f.predict(Odometry(t=0.1, dx=0.1, dy=0.0, dtheta=0.0, d_left=0.1, d_right=0.1))
    after = f.estimate()
    expected = before.mean[:2] + 0.1 * np.array([math.cos(before.mean[2]), math.sin(before.mean[2])])
    np.testing.assert_allclose(after.mean[:2], expected, atol=2e-3)
    assert np.linalg.slogdet(after.cov)[1] > np.linalg.slogdet(before.cov)[1]


@pytest.mark.parametrize("known", [True, False])
def test_landmark_update_converges_to_the_true_pose(known: bool) -> None:
    truth = np.array([1.8, 1.2, 0.2])
    f = _pf(particles=2000)
    f.reset(_initial(mean=(2.0, 1.4, 0.3), sigma=0.2), _world(), SENSORS, np.random.default_rng(2))
    for k in range(8):
        f.predict(Odometry(t=0.2 * k, dx=0.0, dy=0.0, dtheta=0.0, d_left=0.0, d_right=0.0))
        f.update(_sightings(truth, [0, 1, 2, 3], t=0.2 * k, known=known))
    est = f.estimate()
    # started 0.28 m away; 2000 particles over the prior leave a few cm of sampling resolution
    assert np.hypot(*(est.mean[:2] - truth[:2])) < 0.06
    assert abs(est.mean[2] - truth[2]) < 0.05
    assert est.diagnostics["n_eff"] > 0


def test_low_ess_triggers_resampling_and_uniform_weights() -> None:
    f = _pf(particles=500)
    f.reset(_initial(sigma=0.3), _world(), SENSORS, np.random.default_rng(4))
    f.update(_sightings(np.array([2.0, 1.5, 0.3]), [0, 1, 2]))
    est = f.estimate()
    assert est.diagnostics["resampled"] == 1.0
    assert est.diagnostics["n_eff"] < 250
    _, w = f.particles()
    np.testing.assert_allclose(w, 1.0 / 500)


def test_uniform_init_covers_free_space() -> None:
    f = _pf(particles=3000, init="uniform")
    f.reset(_initial(), _world(), SENSORS, np.random.default_rng(5))
    x, _ = f.particles()
    grid = _box_grid()
    cells = grid.world_to_cell(x[:, :2])
    assert np.all(grid.free()[cells[:, 0], cells[:, 1]])
    assert x[:, 0].min() < 0.5 and x[:, 0].max() > 3.5
    assert np.ptp(x[:, 2]) > 6.0


def test_uniform_init_without_a_grid_uses_the_landmark_box() -> None:
    f = _pf(particles=500, init="uniform")
    f.reset(_initial(), _world(grid=False), SENSORS, np.random.default_rng(6))
    x, _ = f.particles()
    assert np.all((x[:, 0] >= 0.5) & (x[:, 0] <= 3.5) & (x[:, 1] >= 0.5) & (x[:, 1] <= 2.5))


def test_augmented_mcl_injects_after_a_kidnap() -> None:
    f = _pf(particles=1000, augmented=True)
    f.reset(_initial(sigma=0.02), _world(), SENSORS, np.random.default_rng(7))
    pose = np.array([2.0, 1.5, 0.3])
    still = Odometry(t=0.0, dx=0.0, dy=0.0, dtheta=0.0, d_left=0.0, d_right=0.0)
    for k in range(10):
        f.predict(still)
        f.update(_sightings(pose, [0, 1, 2, 3], t=0.2 * k))
    kidnapped = np.array([1.0, 0.8, -1.0])
    injected = 0.0
    for k in range(60):
        f.predict(still)
        f.update(_sightings(kidnapped, [0, 1, 2, 3], t=2.0 + 0.2 * k))
        injected += f.estimate().diagnostics["injected"]
    assert injected > 0
    assert np.hypot(*(f.estimate().mean[:2] - kidnapped[:2])) < 0.1


def test_laser_only_localizes_on_a_grid() -> None:
    grid = _box_grid()
    truth = np.array([1.2, 1.0, 0.5])
    angles = np.linspace(-2.0, 2.0, 91)
    ranges = cast_scan(grid, truth, angles, 5.0)
    scan = LaserScan(t=0.1, angle_min=-2.0, angle_increment=4.0 / 90, ranges=ranges, range_min=0.02, range_max=5.0)
    f = _pf(particles=2000, use_landmarks=False, use_laser=True, laser_beams=30, sigma_hit_m=0.05)
    f.reset(_initial(mean=(1.3, 1.1, 0.45), sigma=0.1), _world(landmarks=False), SENSORS, np.random.default_rng(8))
    for _ in range(5):
        f.update(scan)
    est = f.estimate()
    assert np.hypot(*(est.mean[:2] - truth[:2])) < 0.05


def test_deterministic_and_tracks_tiny_line() -> None:
    ds = make_dataset("tiny_line", 0)
    a = run_filter(_pf(particles=300), ds, np.random.default_rng(11))
    b = run_filter(_pf(particles=300), ds, np.random.default_rng(11))
    assert a.status == "ok"
    np.testing.assert_array_equal(a.mean, b.mean)
    gt = ds.ground_truth
    idx = np.clip(np.searchsorted(gt.t, a.t, side="right") - 1, 0, len(gt) - 1)
    err = np.hypot(*(a.mean[:, :2] - gt.xy[idx]).T)
    assert float(np.sqrt(np.mean(err**2))) < 0.1


# --- range-only beacons and twist noise ----------------------------------------------------------------


def test_range_only_update_reduces_the_error_of_drifting_odometry() -> None:
    events, _, truth = ro.scenario()
    odo, _ = ro.run(_pf(), events, use_ranges=False)
    pf, _ = ro.run(_pf(), events)
    e_odo, e_pf = ro.position_rmse(odo, truth), ro.position_rmse(pf, truth)
    assert e_odo > 0.3
    assert e_pf < 0.25 * e_odo


def test_range_loglik_is_the_robust_mixture_and_marginalises_unknown_ids() -> None:
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 1.0]])
    lm = ro.BEACON_XY.copy()
    ranges = np.array([8.0, 30.0, 9.0])
    rows = np.array([0, 1, -1], dtype=np.int64)
    sigma, eps, span = 0.2, 0.05, 100.0
    log_hit = math.log(1 - eps) - 0.5 * math.log(2 * math.pi) - math.log(sigma)
    got = _sightings_loglik(poses, ranges, ranges, rows, lm, False, 1 / sigma**2, 0.0, log_hit, math.log(eps / span))

    def p(r: float, d: float) -> float:
        return (1 - eps) * math.exp(-0.5 * ((r - d) / sigma) ** 2) / (sigma * math.sqrt(2 * math.pi)) + eps / span

    for i, pose in enumerate(poses):
        d = np.hypot(*(lm - pose[:2]).T)
        expected = math.log(p(8.0, d[0])) + math.log(p(30.0, d[1])) + math.log(np.mean([p(9.0, dj) for dj in d]))
        assert got[i] == pytest.approx(expected, rel=1e-12)
    # Without the floor (eps = 0) it is the plain Gaussian.
    log_gauss = log_hit - math.log(1 - eps)
    plain = _sightings_loglik(
        poses[:1], ranges[:1], ranges[:1], rows[:1], lm, False, 1 / sigma**2, 0.0, log_gauss, -math.inf
    )
    d0 = float(np.hypot(*lm[0]))
    assert plain[0] == pytest.approx(-0.5 * ((8.0 - d0) / sigma) ** 2 - math.log(sigma * math.sqrt(2 * math.pi)))


def test_bearing_range_loglik_wraps_the_bearing_and_marginalises_unknown_ids() -> None:
    poses = np.array([[0.0, 0.0, 3.0], [1.0, -2.0, -2.5]])
    lm = np.array([[4.0, 1.0], [-3.0, 2.0], [0.5, -6.0]])
    ranges = np.array([4.2, 3.5])
    bearings = np.array([-2.9, 2.7])
    rows = np.array([0, -1], dtype=np.int64)
    sr, sb = 0.3, 0.1
    log_norm = -math.log(2 * math.pi * sr * sb)
    got = _sightings_loglik(poses, ranges, bearings, rows, lm, True, 1 / sr**2, 1 / sb**2, log_norm, -math.inf)

    def p(pose: np.ndarray, r: float, b: float, j: int) -> float:
        dx, dy = lm[j] - pose[:2]
        vb = math.remainder(b - (math.atan2(dy, dx) - pose[2]), 2 * math.pi)
        return math.exp(log_norm - 0.5 * ((r - math.hypot(dx, dy)) ** 2 / sr**2 + vb**2 / sb**2))

    for i, pose in enumerate(poses):
        expected = math.log(p(pose, 4.2, -2.9, 0)) + math.log(np.mean([p(pose, 3.5, 2.7, j) for j in range(3)]))
        assert got[i] == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize(("eps", "robust"), [(0.05, True), (0.0, False)])
def test_outlier_floor_keeps_the_particles_from_collapsing(eps: float, robust: bool) -> None:
    f = _pf(range_outlier_fraction=eps, resample_ess_fraction=0.0)
    init = Gaussian2(mean=np.zeros(3), cov=np.diag([0.25, 0.25, 0.01]))
    f.reset(init, ro.WORLD, ro.SENSORS, np.random.default_rng(0))
    r_true = float(np.hypot(*ro.BEACON_XY[0]))
    f.update(RangeObservations(0.1, ro.BEACON_IDS[:1].copy(), np.array([r_true + 20.0])))
    n_eff = f.estimate().diagnostics["n_eff"]
    if robust:
        assert n_eff > 0.9 * 1000  # the outlier is explained by the floor for every particle
    else:
        assert n_eff < 0.05 * 1000  # the Gaussian alone puts the weight on the particles nearest the wrong circle


def test_ranges_without_a_landmark_map_are_ignored_and_use_ranges_routes() -> None:
    f = _pf(use_ranges=False)
    assert RangeObservations not in f.routed_events()
    f = _pf(use_landmarks=False, use_laser=False)
    f.reset(ro.INITIAL, ro.WORLD, ro.SENSORS, np.random.default_rng(0))  # ranges alone are a usable sensor
    with pytest.raises(ConfigError, match="use_ranges"):
        _pf(use_landmarks=False, use_laser=False, use_ranges=False)
    with pytest.raises(ConfigError, match="range_outlier_fraction"):
        _pf(range_outlier_fraction=1.0)


def test_predict_draws_the_twist_noise_when_the_dataset_gives_it() -> None:
    sensors = SensorSpec(twist_sigma_v_mps=0.04, twist_sigma_omega_radps=0.03)
    f = _pf(particles=100_000, sigma_x_m=0.0, sigma_y_m=0.0, sigma_theta_rad=0.0)
    f.reset(
        Gaussian2(mean=np.array([1.0, 1.0, 0.5]), cov=np.zeros((3, 3))), ro.WORLD, sensors, np.random.default_rng(4)
    )
    v, w, dt = 0.8, 0.5, 0.5
    inc = twist_increment(v * dt, w * dt)
    f.predict(Odometry(0.5, float(inc[0]), float(inc[1]), float(inc[2]), v=v, omega=w, dt=dt))
    x, _ = f.particles()
    c, s = math.cos(0.5), math.sin(0.5)
    G = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    expected = G @ twist_increment_covariance(v, w, dt, 0.04, 0.03) @ G.T
    scale = np.sqrt(np.outer(np.diag(expected), np.diag(expected)))
    assert np.all(np.abs(np.cov(x.T) - expected) <= 0.03 * scale)


def test_sincos_near_matches_libm_near_and_far_from_the_reference() -> None:
    from numba import njit

    from locbench.filters._motion_kernels import sincos_near

    @njit
    def table(a: np.ndarray, ref: float) -> np.ndarray:
        out = np.empty((a.shape[0], 2))
        sr, cr = math.sin(ref), math.cos(ref)
        for i in range(a.shape[0]):
            out[i, 0], out[i, 1] = sincos_near(a[i], ref, sr, cr)
        return out

    rng = np.random.default_rng(5)
    for ref in (0.0, 1.2, math.pi - 0.1, -math.pi + 0.05):
        a = ref + rng.uniform(-2.0, 2.0, 5000)  # both the series (|a - ref| <= 0.5) and libm
        got = table(a, ref)
        np.testing.assert_allclose(got[:, 0], np.sin(a), rtol=0, atol=2e-15)
        np.testing.assert_allclose(got[:, 1], np.cos(a), rtol=0, atol=2e-15)


# --- KLD sampling -------------------------------------------------------------------------------------------


@pytest.mark.parametrize("k", [2, 5, 20, 100])
def test_kld_bound_is_the_chi_square_quantile_over_twice_the_error(k: int) -> None:
    from scipy.stats import chi2, norm

    from locbench.filters.pf import _kld_bound

    # Fox (2003) eq. 13 approximates chi2_(k-1, 1-delta) / (2 eps) (Wilson-Hilferty); within 2 % from k = 5
    exact = chi2.ppf(0.99, k - 1) / (2 * 0.05)
    assert _kld_bound(k, 0.05, float(norm.ppf(0.99))) == pytest.approx(exact, rel=0.02 if k >= 5 else 0.1)
    assert _kld_bound(1, 0.05, 2.0) == 0.0


def test_kld_count_is_large_when_uncertain_and_small_when_converged() -> None:
    # global: uniform over the 4 m x 3 m box; a 1 m-sigma range to one beacon leaves a thick ring of
    # positions with every heading, hundreds of 0.5 m x 0.5 m x 10 deg bins
    f = _pf(adaptive="kld", init="uniform", range_only_sigma_m=1.0)
    f.reset(_initial(), _world(), SENSORS, np.random.default_rng(2))
    assert f.estimate().diagnostics["particles"] == 5000  # AMCL starts at max_particles
    f.predict(Odometry(t=0.1, dx=0.0, dy=0.0, dtheta=0.0))
    f.update(RangeObservations(t=0.1, ids=np.array([0]), ranges=np.array([2.0])))
    uncertain = f.estimate().diagnostics["particles"]
    # tracking: a tight cloud well inside one bin, four precise sightings per step
    pose = np.array([2.2, 1.2, 0.3])
    g = _pf(adaptive="kld")
    g.reset(_initial(mean=(2.2, 1.2, 0.3), sigma=0.01), _world(), SENSORS, np.random.default_rng(2))
    for k in range(5):
        g.predict(Odometry(t=0.1 * k, dx=0.0, dy=0.0, dtheta=0.0, d_left=0.0, d_right=0.0))
        g.update(_sightings(pose, [0, 1, 2, 3], t=0.1 * k))
    converged = g.estimate().diagnostics["particles"]
    assert uncertain == 5000
    assert converged == 100
    assert np.hypot(*(g.estimate().mean[:2] - pose[:2])) < 0.05


def test_kld_count_is_stored_with_the_run_and_fixed_counts_stay_fixed() -> None:
    ds = make_dataset("room", 0)
    fr = resolve_filter("pf[adaptive=kld]")
    trace = run_filter(ParticleFilter(fr.params), ds, np.random.default_rng(3))
    assert trace.status == "ok"
    n = trace.diagnostics["particles"]
    assert np.all(np.isfinite(n)) and np.all((n >= 100) & (n <= 5000))
    assert n[0] == 5000 and np.median(n) < 1000  # starts at the maximum (the reset row), shrinks once tracking
    fixed = run_filter(_pf(particles=300), ds, np.random.default_rng(3))
    assert np.all(fixed.diagnostics["particles"] == 300)


def test_systematic_resample_of_no_particles_is_empty() -> None:
    """Augmented MCL can draw every particle at random (p_inject = 1): then nothing is resampled."""
    rng = np.random.default_rng(3)
    idx = systematic_resample(np.array([0.2, 0.8]), 0, rng)
    assert idx.shape == (0,) and idx.dtype == np.int64


def test_augmented_pf_survives_injecting_every_particle() -> None:
    """A seed on which the slow and fast averages made p_inject = 1 crashed the compiled resampler."""
    from locbench.core.seeding import filter_rng
    from locbench.registry import make_dataset, make_filter
    from locbench.run.filter_pass import run_filter

    ds = make_dataset("room[kidnap_m=0.5]", 7)
    name = "pf[augmented=true]"
    trace = run_filter(make_filter(name), ds, filter_rng(name, "room[kidnap_m=0.5]", 7))
    assert trace.status == "ok", trace.message


# --- a covariance that does not collapse, augmented MCL that does not run away --------------------------


def test_a_degenerate_weighting_leaves_a_nonsingular_covariance() -> None:
    """Four precise sightings far in the tail of a wide cloud give one particle all the weight (ESS 1).
    Roughening measured on the resampled set would leave 200 copies of it: a covariance of 1e-29 and below,
    NEES +inf. Measured on the predicted cloud the covariance stays positive definite."""
    f = _pf(particles=200)
    f.reset(_initial(sigma=0.3), _world(), SENSORS, np.random.default_rng(1))
    truth = np.array([2.4, 1.2, 0.2])
    f.update(_sightings(truth, [0, 1, 2, 3]))
    est = f.estimate()
    assert est.diagnostics["n_eff"] < 1.5 and est.diagnostics["resampled"] == 1.0
    x, _ = f.particles()
    assert np.unique(x, axis=0).shape[0] == 200  # no two particles are copies
    assert np.linalg.eigvalsh(est.cov).min() > 1e-6
    assert np.isfinite(nees((est.mean - truth)[None], est.cov[None])[0])


def test_regularised_resampling_spreads_by_the_weighted_covariance() -> None:
    """Musso et al.'s kernel is the weighted covariance before resampling: it separates the copies of a
    moderate weighting but cannot do better than that covariance when the weighting is degenerate."""
    f = _pf(particles=500, regularise=True)
    f.reset(_initial(sigma=0.3), _world(), SENSORS, np.random.default_rng(4))
    f.update(_sightings(np.array([2.0, 1.5, 0.3]), [0]))
    est = f.estimate()
    assert est.diagnostics["resampled"] == 1.0
    x, _ = f.particles()
    assert np.unique(x, axis=0).shape[0] == 500
    assert np.linalg.eigvalsh(est.cov).min() > 1e-6
    g = _pf(particles=200, regularise=True)
    g.reset(_initial(sigma=0.3), _world(), SENSORS, np.random.default_rng(1))
    g.update(_sightings(np.array([2.4, 1.2, 0.2]), [0, 1, 2, 3]))
    assert np.linalg.eigvalsh(g.estimate().cov).min() < 1e-12  # the documented limit (ESS 1)


def test_pf_nees_is_finite_at_every_step_on_room() -> None:
    """On room seed 2 a sighting at t = 56.6 s leaves an ESS of 1.00001: the covariance must stay nonzero."""
    for seed in (0, 1, 2):
        ds = make_dataset("room", seed)
        trace = run_filter(_pf(), ds, np.random.default_rng(seed))
        gt = ds.ground_truth
        ne = nees_at_truth(align(trace.t, trace.mean, gt.t, gt.poses, trace.cov))
        assert np.all(np.isfinite(ne)), seed


def test_augmented_averages_do_not_run_away_on_office() -> None:
    """w_avg over the mixture of belief and injected particles drives p_inject to 1 on office without a
    kidnap: every particle random at every update, an ATE of metres. Over the belief it stays low."""
    ds = make_dataset("office", 1)
    trace = run_filter(_pf(augmented=True), ds, np.random.default_rng(1))
    assert trace.status == "ok"
    p = trace.diagnostics["p_inject"]
    assert np.nanmean(p) < 0.6
    gt = ds.ground_truth
    idx = np.clip(np.searchsorted(gt.t, trace.t, side="right") - 1, 0, len(gt) - 1)
    assert float(np.sqrt(np.mean(np.sum((trace.mean[:, :2] - gt.xy[idx]) ** 2, axis=1)))) < 0.2


@pytest.mark.parametrize("known", [True, False])
def test_sensor_reset_poses_reproduce_the_sighting(known: bool) -> None:
    pose = np.array([2.0, 1.5, 0.3])
    z = _sightings(pose, [1, 3], known=known)
    rows = np.where(z.ids >= 0, z.ids, -1).astype(np.int64)
    x = sightings_poses(z.ranges, z.bearings, rows, LM_XY, 0.0, 0.0, 400, np.random.default_rng(2))
    # noise-free: every pose sees one of the sightings exactly, at one of the map's landmarks
    d = LM_XY[None, :, :] - x[:, None, :2]
    r = np.hypot(d[..., 0], d[..., 1])
    b = np.angle(np.exp(1j * (np.arctan2(d[..., 1], d[..., 0]) - x[:, 2:3])))
    hit = (np.abs(r[:, :, None] - z.ranges) < 1e-9) & (np.abs(b[:, :, None] - z.bearings) < 1e-9)
    assert np.all(hit.any(axis=(1, 2)))
    if known:
        assert np.all(hit[:, [1, 3], :].any(axis=(1, 2)))
    # the direction around the landmark is uniform: the true pose's neighbourhood is reached
    assert np.min(np.hypot(*(x[:, :2] - pose[:2]).T)) < 0.2
    ranges_only = sightings_poses(z.ranges, None, rows, LM_XY, 0.01, 0.0, 50, np.random.default_rng(3))
    assert np.ptp(ranges_only[:, 2]) > 3.0


def test_sensor_reset_recovers_a_kidnap_faster_than_uniform_injection() -> None:
    pose = np.array([2.0, 1.5, 0.3])
    kidnapped = np.array([1.0, 0.8, -1.0])
    still = Odometry(t=0.0, dx=0.0, dy=0.0, dtheta=0.0, d_left=0.0, d_right=0.0)
    first: dict[str, int] = {}
    for inject in ("uniform", "sensor"):
        f = _pf(particles=500, augmented=True, inject=inject)
        f.reset(_initial(sigma=0.02), _world(), SENSORS, np.random.default_rng(7))
        for k in range(10):
            f.predict(still)
            f.update(_sightings(pose, [0, 2], t=0.2 * k))
        for k in range(60):
            f.predict(still)
            f.update(_sightings(kidnapped, [0, 2], t=2.0 + 0.2 * k))
            if np.hypot(*(f.estimate().mean[:2] - kidnapped[:2])) < 0.1:
                first.setdefault(inject, k)
    assert np.hypot(*(f.estimate().mean[:2] - kidnapped[:2])) < 0.1  # the sensor-reset filter, last run
    assert first["sensor"] < first.get("uniform", 60)


def test_sighting_pairs_recover_a_kidnap_seen_one_landmark_at_a_time() -> None:
    """One sighting per event, alternating landmarks: ``inject_pairs`` inverts each with the previous one
    through the odometry between them (here none: the robot stands still)."""
    pose = np.array([2.0, 1.5, 0.3])
    kidnapped = np.array([1.0, 0.8, -1.0])
    still = Odometry(t=0.0, dx=0.0, dy=0.0, dtheta=0.0, d_left=0.0, d_right=0.0)
    f = _pf(particles=500, augmented=True, inject="sensor", inject_pairs=True)
    f.reset(_initial(sigma=0.02), _world(), SENSORS, np.random.default_rng(7))
    for k in range(10):
        f.predict(still)
        f.update(_sightings(pose, [2 * (k % 2)], t=0.2 * k))
    for k in range(60):
        f.predict(still)
        f.update(_sightings(kidnapped, [2 * (k % 2)], t=2.0 + 0.2 * k))
    assert np.hypot(*(f.estimate().mean[:2] - kidnapped[:2])) < 0.1


def test_sighting_pairs_leave_out_the_previous_sighting_of_the_same_landmark() -> None:
    """The previous event saw landmarks 0 and 2, this one only 0 (2 has left the view). Poses from the
    previous sighting of 0 lie on the circle this sighting allows and all explain it: pair candidates drawn
    from it would inject poses metres off (on office, a median 3-8 m at most pair injections). Only the
    previous sighting of 2 may supply the candidates."""
    pose = np.array([2.0, 1.5, 0.3])
    still = Odometry(t=0.0, dx=0.0, dy=0.0, dtheta=0.0, d_left=0.0, d_right=0.0)
    f = _pf(particles=500, augmented=True, inject="sensor", inject_pairs=True, pair_gate=0.0)
    f.reset(_initial(sigma=0.02), _world(), SENSORS, np.random.default_rng(5))
    for k in range(5):
        f.predict(still)
        f.update(_sightings(pose, [0, 2], t=0.2 * k))
    f.predict(still)
    avg = f._w_avg[LandmarkObservations]
    avg[1] = 0.5 * avg[0]  # w_fast has dipped: about half the particles are injected from the pair
    f.update(_sightings(pose, [0], t=2.0))
    injected = int(f.estimate().diagnostics["injected"])
    assert injected > 100
    x, _ = f.particles()
    dist = np.hypot(*(x[-injected:, :2] - pose[:2]).T)  # the late (sensor) poses are appended last
    assert np.max(dist) < 0.2


@pytest.mark.parametrize("gate", [0.99, 0.0])
def test_sighting_pairs_do_not_inject_while_the_belief_explains_the_sighting(gate: float) -> None:
    """``pair_gate``: a pair pose carries the odometry's error between the two events (here 0.3 m) and,
    injected with the belief's weight whenever w_fast dips, pulls the mean. With the validation gate the
    pair is not used while a belief particle explains the sighting; without it (the default) the mean moves
    by about 0.1 m."""
    pose = np.array([2.0, 1.5, 0.3])
    still = Odometry(t=0.0, dx=0.0, dy=0.0, dtheta=0.0, d_left=0.0, d_right=0.0)
    f = _pf(particles=500, augmented=True, inject="sensor", inject_pairs=True, pair_gate=gate)
    f.reset(_initial(sigma=0.02), _world(), SENSORS, np.random.default_rng(3))
    for k in range(10):
        f.predict(still)
        f.update(_sightings(pose, [2 * (k % 2)], t=0.2 * k))
    f.predict(still)
    f._last_sightings[1][:] = [0.3, 0.0, 0.0]  # type: ignore[index]  # odometry error since the last event
    avg = f._w_avg[LandmarkObservations]
    avg[1] = 0.5 * avg[0]  # w_fast has dipped: p_inject about 0.5
    f.update(_sightings(pose, [0], t=2.0))
    est = f.estimate()
    err = float(np.hypot(*(est.mean[:2] - pose[:2])))
    if gate > 0.0:
        assert est.diagnostics["pair_chi2"] < 9.21  # the belief explains the sighting: gate closed
        assert err < 0.02
    else:
        assert err > 0.05


def test_kernels_draw_the_generators_own_stream() -> None:
    """A kernel given the generator's addresses draws from the generator's own state: its normals and uniform
    are numpy's draws from that state (numba's distribution code against numpy's, to 1 ulp), and the state
    afterwards is the one numpy's draws leave (exactly: the same raw words consumed)."""
    from numba import njit

    from locbench.filters._numba_rng import generator_addresses, generator_from

    @njit
    def draw(gen: np.ndarray, n: int) -> tuple[np.ndarray, float]:
        rng = generator_from(gen)
        out = np.empty(n)
        for i in range(n):
            out[i] = rng.standard_normal()
        return out, rng.random()

    a, b = np.random.default_rng(11), np.random.default_rng(11)
    normals, u = draw(generator_addresses(a), 500)
    want = b.standard_normal(500)
    np.testing.assert_array_max_ulp(normals, want, maxulp=1)
    np.testing.assert_array_max_ulp(np.array([u]), np.array([b.random()]), maxulp=1)
    assert a.bit_generator.state == b.bit_generator.state  # the state advanced in place, draw for draw


def test_a_copied_filter_draws_from_its_own_generator() -> None:
    """A deep copy (or a pickled filter) rebuilds the generator addresses its kernels draw through."""
    import copy

    f = _pf(particles=200)
    f.reset(_initial(), _world(), SENSORS, np.random.default_rng(5))
    g = copy.deepcopy(f)
    u = Odometry(t=0.1, dx=0.1, dy=0.0, dtheta=0.0, d_left=0.1, d_right=0.1)
    f.predict(u)
    g.predict(u)
    np.testing.assert_array_equal(f.particles()[0], g.particles()[0])


@pytest.mark.parametrize("q", [(0.0, 0.0, 0.0), (0.01, 0.02, 0.003)])
def test_compiled_twist_motion_is_the_twist_model(q: tuple[float, float, float]) -> None:
    """``_move_twist`` against the plain numpy form of the twist model (``motion_reference.twist_moved`` on
    numpy's draws, then N(0, diag(q^2)) drawn by ``_jitter`` and the statistics of ``_checked_stats``) from one
    generator state: the particles to 1e-12 (m, rad), the weighted mean and covariance to 1e-12 of their scale,
    the same draws taken (the generators' states equal afterwards). Straight, tiny (series) and zero turns,
    headings across the wrap."""
    from motion_reference import twist_moved

    from locbench.filters._numba_rng import generator_addresses
    from locbench.filters.pf import _checked_stats, _jitter, _move_twist

    rng = np.random.default_rng(21)
    q_std = np.array(q)
    for v, omega, dt in [(0.4, 0.0, 0.05), (0.3, 1e-4, 0.02), (0.0, 0.0, 0.1), (0.8, -2.5, 0.1), (1e-3, 0.7, 0.3)]:
        x = np.column_stack([rng.normal(0, 3, 400), rng.normal(0, 3, 400), rng.uniform(-math.pi, math.pi, 400)])
        x[:5, 2] = [math.pi, -math.pi + 1e-12, 3.1, -3.1, 0.0]
        logw = np.log(rng.dirichlet(np.ones(400)))
        w = np.exp(logw)
        u = Odometry(t=1.0, dx=0.02, dy=-0.001, dtheta=0.01, v=v, omega=omega, dt=dt)
        a, b = np.random.default_rng(5), np.random.default_rng(5)
        e = a.standard_normal((2, 400))
        want = twist_moved(
            x, v * dt + 0.05 * dt * e[0], omega * dt + 0.1 * dt * e[1], v * dt, omega * dt, (0.02, -0.001, 0.01)
        )
        if q_std.any():
            _jitter(want, q_std, generator_addresses(a))
        mean_ref, cov_ref, ok_ref = _checked_stats(want, w, logw)
        got = x.copy()
        mean, cov, ok = _move_twist(
            got, v * dt, omega * dt, 0.05 * dt, 0.1 * dt, u.dx, u.dy, u.dtheta, q_std, generator_addresses(b), w, logw
        )
        # the heading compared modulo 2 pi: a value at +-pi may wrap to either end
        dth = np.remainder(got[:, 2] - want[:, 2] + math.pi, 2 * math.pi) - math.pi
        np.testing.assert_allclose(got[:, :2], want[:, :2], rtol=0, atol=1e-12)
        np.testing.assert_allclose(dth, 0.0, rtol=0, atol=1e-12)
        np.testing.assert_allclose(mean[:2], mean_ref[:2], rtol=0, atol=1e-12)
        assert abs(math.remainder(mean[2] - mean_ref[2], 2 * math.pi)) < 1e-12
        scale = np.sqrt(np.outer(np.diag(cov_ref), np.diag(cov_ref)))
        np.testing.assert_allclose(cov / scale, cov_ref / scale, rtol=0, atol=1e-12)
        assert ok and ok_ref
        assert a.bit_generator.state == b.bit_generator.state  # the same draws were taken


@pytest.mark.parametrize("wheels", [True, False])
def test_compiled_motion_is_the_plain_model(wheels: bool) -> None:
    """``_move`` against the plain numpy forms (``motion_reference``) on numpy's draws from one generator state,
    taken in the kernel's order (per particle: the two wheels or the three increment terms, then the three of
    N(0, diag(q^2))): the particles to 1e-12 (m, rad), the same draws taken. Headings across the wrap."""
    from motion_reference import increment_moved, wheel_moved

    from locbench.filters._numba_rng import generator_addresses
    from locbench.filters.pf import _move

    rng = np.random.default_rng(23)
    n = 400
    x = np.column_stack([rng.normal(0, 3, n), rng.normal(0, 3, n), rng.uniform(-math.pi, math.pi, n)])
    x[:5, 2] = [math.pi, -math.pi + 1e-12, 3.1, -3.1, 0.0]
    w = np.full(n, 1.0 / n)
    q = np.array([0.01, 0.02, 0.003])
    a, b = np.random.default_rng(6), np.random.default_rng(6)
    if wheels:
        e = a.standard_normal((n, 5))
        want = wheel_moved(x, 0.2 + 0.01 * e[:, 0], 0.25 + 0.02 * e[:, 1], 0.4)
        u = (0.2, 0.25, 0.0, 0.01, 0.02, 0.4)
    else:
        e = a.standard_normal((n, 6))
        want = increment_moved(x, 0.1 + 0.01 * e[:, 0], -0.02 + 0.01 * e[:, 1], 0.3 + 0.05 * e[:, 2])
        e = e[:, 1:]  # the additive noise's draws follow the three of the increment
        u = (0.1, -0.02, 0.3, 0.01, 0.05, 1.0)
    want[:, 0] += q[0] * e[:, 2]
    want[:, 1] += q[1] * e[:, 3]
    want[:, 2] += q[2] * e[:, 4]
    got = x.copy()
    *_, ok = _move(got, wheels, *u, q, generator_addresses(b), w, np.log(w))
    dth = np.remainder(got[:, 2] - want[:, 2] + math.pi, 2 * math.pi) - math.pi
    np.testing.assert_allclose(got[:, :2], want[:, :2], rtol=0, atol=1e-12)
    np.testing.assert_allclose(dth, 0.0, rtol=0, atol=1e-12)
    assert np.all((got[:, 2] > -math.pi) & (got[:, 2] <= math.pi))
    assert ok
    assert a.bit_generator.state == b.bit_generator.state  # the same draws were taken


def test_the_belief_sample_is_the_systematic_draw_with_one_read_only_weights_array() -> None:
    ds = make_dataset("room", 0)
    f = _pf(particles=200)
    f.reset(ds.initial, ds.world, ds.sensors, np.random.default_rng(0))
    for ev in ds.events[:40]:
        f.predict(ev) if isinstance(ev, Odometry) else f.update(ev)
    x, w = f.particles()
    a, b = np.random.default_rng(5), np.random.default_rng(5)
    points, weights = f.belief_sample(a, 64)
    # the same draw as systematic resampling's indices with the same generator, gathered
    np.testing.assert_array_equal(points, x[systematic_resample(w, 64, b)])
    assert a.random() == b.random()  # one offset drawn, as systematic_resample draws
    again = f.belief_sample(a, 64)[1]
    assert again is weights and not weights.flags.writeable and np.all(weights == 1.0 / 64)
    empty = f.belief_sample(a, 0)
    assert empty[0].shape == (0, 3) and empty[1].shape == (0,)
