"""The gtsam fixed-lag smoother filter (gtsam_fls)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

pytest.importorskip("gtsam")

import gtsam
import range_only_support as ro

from locbench.core.errors import ConfigError
from locbench.core.events import UNKNOWN_ID, LandmarkObservations, Odometry, PoseFix, RangeObservations
from locbench.core.geometry import is_symmetric_psd, pose_error
from locbench.datasets.dataset import Gaussian2, Landmarks, SensorSpec, WorldMap
from locbench.filters.gtsam_fls import GtsamFixedLagSmoother, GtsamFLSConfig
from locbench.registry import make_dataset, make_filter
from locbench.run.filter_pass import run_filter

X = gtsam.symbol_shorthand.X
L = gtsam.symbol_shorthand.L

SENSORS = SensorSpec(
    wheelbase_m=0.4,
    encoder_k_left=0.01,
    encoder_k_right=0.01,
    landmark_sigma_range_m=0.02,
    landmark_sigma_bearing_rad=0.01,
)
WORLD = WorldMap(landmarks=Landmarks(ids=np.array([7, 8]), xy=np.array([[3.0, 1.0], [3.0, -1.0]])))
INITIAL = Gaussian2(mean=np.zeros(3), cov=np.diag([1e-4, 1e-4, 1e-4]))


def _odo(t: float, d: float = 0.1) -> Odometry:
    """A straight step of ``d`` metres along the robot's x axis at time ``t``."""
    return Odometry(t=t, dx=d, dy=0.0, dtheta=0.0, d_left=d, d_right=d, dt=0.1)


def _sight(t: float, pose: tuple[float, float], ids: list[int], noise: float = 0.0) -> LandmarkObservations:
    """Exact (plus ``noise`` m / rad) range-bearing of landmarks ``ids`` from (x, y) with heading 0."""
    rows = [1 if i == 8 else 0 for i in ids]  # an unknown id is a sighting of landmark 7
    assert WORLD.landmarks is not None
    xy = WORLD.landmarks.xy[rows]
    d = xy - np.asarray(pose)
    return LandmarkObservations(
        t=t,
        ids=np.asarray(ids, dtype=np.int64),
        ranges=np.hypot(d[:, 0], d[:, 1]) + noise,
        bearings=np.arctan2(d[:, 1], d[:, 0]) + noise,
    )


def _new(**kw: object) -> GtsamFixedLagSmoother:
    f = GtsamFixedLagSmoother(GtsamFLSConfig(**kw))  # type: ignore[arg-type]
    f.reset(INITIAL, WORLD, SENSORS, np.random.default_rng(0))
    return f


def _factor_types(f: GtsamFixedLagSmoother) -> dict[str, int]:
    counts: dict[str, int] = {}
    graph = f.smoother.getFactors()
    for i in range(graph.size()):
        fac = graph.at(i)
        if fac is not None:
            counts[type(fac).__name__] = counts.get(type(fac).__name__, 0) + 1
    return counts


def _truth_at(ds, t: np.ndarray) -> np.ndarray:  # type: ignore[no-untyped-def]
    gt = ds.ground_truth
    idx = np.clip(np.searchsorted(gt.t, t, side="right") - 1, 0, len(gt) - 1)
    return gt.poses[idx]


def test_factor_graph_of_a_hand_made_sequence() -> None:
    f = _new(smoother="batch", lag_s=10.0)
    assert f.smoother is None  # nothing built until the first observation
    for k in range(1, 4):
        f.predict(_odo(0.1 * k))
    f.update(_sight(0.3, (0.3, 0.0), [7, 8]))
    f.predict(_odo(0.4))
    f.predict(_odo(0.5))
    f.update(_sight(0.5, (0.5, 0.0), [7]))
    # X0 prior, two composed odometry factors, two landmark priors (landmark 7 is reused), three sightings.
    assert _factor_types(f) == {
        "PriorFactorPose2": 1,
        "BetweenFactorPose2": 2,
        "PriorFactorPoint2": 2,
        "BearingRangeFactor2D": 3,
    }
    values = f.smoother.calculateEstimate()
    for key in (X(0), X(1), X(2), L(0), L(1)):
        assert values.exists(key)
    assert not values.exists(X(3))
    graph = f.smoother.getFactors()
    betweens = [graph.at(i) for i in range(graph.size()) if isinstance(graph.at(i), gtsam.BetweenFactorPose2)]
    assert_allclose([betweens[0].measured().x(), betweens[1].measured().x()], [0.3, 0.2], atol=1e-12)
    # Exact data: the newest pose is where the odometry and the sightings agree.
    est = f.estimate()
    assert_allclose(est.mean, [0.5, 0.0, 0.0], atol=1e-6)
    assert is_symmetric_psd(est.cov)
    assert est.diagnostics["accepted"] == 1.0


def test_observation_without_odometry_attaches_to_the_newest_pose() -> None:
    f = _new(smoother="batch")
    f.update(_sight(0.0, (0.0, 0.0), [7]))
    f.update(_sight(0.0, (0.0, 0.0), [8]))
    types = _factor_types(f)
    assert types["BearingRangeFactor2D"] == 2 and "BetweenFactorPose2" not in types
    assert not f.smoother.calculateEstimate().exists(X(1))


def test_landmark_leaving_the_window_is_made_again() -> None:
    f = _new(lag_s=0.5)
    f.update(_sight(0.0, (0.0, 0.0), [7]))
    for k in range(1, 21):
        f.predict(_odo(0.1 * k, d=0.05))
        if k % 5 == 0:
            f.update(_sight(0.1 * k, (0.05 * k, 0.0), [8]))
    f.update(_sight(2.0, (1.0, 0.0), [7]))  # landmark 7 was marginalised at about t = 0.5 s
    values = f.smoother.calculateEstimate()
    assert values.exists(L(2)) and not values.exists(L(0))
    assert_allclose(f.estimate().mean, [1.0, 0.0, 0.0], atol=1e-6)


def test_the_graph_stays_bounded_over_a_long_run() -> None:
    # Marginalisation removes factors; without slot reuse the graph keeps an empty slot for each
    # (3,726 slots for 23 factors after office, growing with the run). 400 updates, a 0.5 s window.
    f = _new(lag_s=0.5)
    f.update(_sight(0.0, (0.0, 0.0), [7, 8]))
    sizes = []
    for k in range(1, 401):
        f.predict(_odo(0.1 * k, d=0.0))
        f.update(_sight(0.1 * k, (0.0, 0.0), [7, 8]))
        sizes.append(f.smoother.getFactors().size())
    live = f.smoother.getFactors().nrFactors()
    assert live < 30 and max(sizes) < 2 * live + 10, (live, max(sizes))
    assert sizes[-1] == sizes[200]  # no growth after the window filled


def test_unknown_ids_are_associated_or_rejected() -> None:
    f = _new()
    for k in range(1, 4):
        f.predict(_odo(0.1 * k))
    z = _sight(0.3, (0.3, 0.0), [UNKNOWN_ID, 8])
    f.update(z)
    d = f.estimate().diagnostics
    assert (d["accepted"], d["rejected"]) == (2.0, 0.0)
    # A sighting matching no landmark (2 m off in range) fails the gate.
    bad = LandmarkObservations(t=0.3, ids=np.array([UNKNOWN_ID]), ranges=np.array([5.0]), bearings=np.array([0.0]))
    f.update(bad)
    d = f.estimate().diagnostics
    assert (d["accepted"], d["rejected"]) == (0.0, 1.0)


def test_pose_fix_is_a_pose_prior_without_heading() -> None:
    f = _new(smoother="batch", use_pose_fixes=True)
    assert PoseFix in f.routed_events()
    assert PoseFix not in _new().routed_events()
    for k in range(1, 4):
        f.predict(_odo(0.1 * k))
    f.update(PoseFix(t=0.3, z=np.array([0.5, 0.1]), cov=np.diag([0.01, 0.01])))
    est = f.estimate()
    assert _factor_types(f)["PriorFactorPose2"] == 2
    assert 0.3 < est.mean[0] < 0.5 and 0.0 < est.mean[1] < 0.1
    assert abs(est.mean[2]) < 0.05  # pulled sideways, the heading barely moves


def test_config_errors_name_the_field() -> None:
    with pytest.raises(ConfigError, match="lag_s"):
        GtsamFLSConfig(lag_s=0.0)
    with pytest.raises(ConfigError, match="gate_probability"):
        GtsamFLSConfig(gate_probability=1.0)
    with pytest.raises(ConfigError, match="landmark_sigma_m"):
        GtsamFLSConfig(landmark_sigma_m=0.0)


@pytest.fixture(scope="module")
def tiny_line_runs() -> dict[str, object]:
    ds = make_dataset("tiny_line", 0)
    specs = ["ekf_landmarks", "gtsam_fls", "gtsam_fls[smoother=batch]", "gtsam_fls[new_pose=odometry]"]
    return {"ds": ds} | {s: run_filter(make_filter(s), ds, np.random.default_rng(0)) for s in specs}


def test_agrees_with_the_ekf_on_a_straight_line(tiny_line_runs: dict) -> None:  # type: ignore[type-arg]
    ekf, fls = tiny_line_runs["ekf_landmarks"], tiny_line_runs["gtsam_fls"]
    assert ekf.status == fls.status == "ok"
    assert_allclose(fls.t, ekf.t)
    err = pose_error(fls.mean, ekf.mean)
    assert np.max(np.hypot(err[:, 0], err[:, 1])) < 0.005  # m
    assert np.max(np.abs(err[:, 2])) < 0.005  # rad
    ratio = np.linalg.det(fls.cov) / np.linalg.det(ekf.cov)
    assert np.all((ratio > 0.5) & (ratio < 2.0))


@pytest.mark.parametrize("other", ["gtsam_fls[smoother=batch]", "gtsam_fls[new_pose=odometry]"])
def test_variants_agree(tiny_line_runs: dict, other: str) -> None:  # type: ignore[type-arg]
    a, b = tiny_line_runs["gtsam_fls"], tiny_line_runs[other]
    err = pose_error(a.mean, b.mean)
    assert np.max(np.abs(err)) < 0.002
    # Standard deviations within 5 %, covariances within 0.1 of the product of the standard deviations.
    sa, sb = np.sqrt(np.diagonal(a.cov, axis1=1, axis2=2)), np.sqrt(np.diagonal(b.cov, axis1=1, axis2=2))
    assert_allclose(sa, sb, rtol=0.05)
    assert np.all(np.abs(a.cov - b.cov) <= 0.1 * sa[:, :, None] * sa[:, None, :])


def test_extra_results_hold_the_smoothed_trajectory(tiny_line_runs: dict) -> None:  # type: ignore[type-arg]
    ds = tiny_line_runs["ds"]
    n_odo = sum(1 for e in ds.events if isinstance(e, Odometry))
    for spec in ("gtsam_fls", "gtsam_fls[new_pose=odometry]"):
        extra = tiny_line_runs[spec].extra
        t, mean = extra["smoothed_t"], extra["smoothed_mean"]
        assert t.shape == (n_odo + 1,) and mean.shape == (n_odo + 1, 3)
        assert extra["smoothed_is_node"].shape == t.shape
        assert np.all(np.diff(t) > 0.0) and np.all(np.isfinite(mean))
        assert np.all((mean[:, 2] > -math.pi) & (mean[:, 2] <= math.pi))
        # The lag-smoothed track is at least as good as the filtered one.
        tr = tiny_line_runs[spec]
        e_s = pose_error(mean, _truth_at(ds, t))
        e_f = pose_error(tr.mean, _truth_at(ds, tr.t))
        assert np.sqrt(np.mean(e_s[:, 0] ** 2 + e_s[:, 1] ** 2)) <= np.sqrt(np.mean(e_f[:, 0] ** 2 + e_f[:, 1] ** 2))
    assert np.count_nonzero(tiny_line_runs["gtsam_fls"].extra["smoothed_is_node"]) < n_odo / 2


# --- range-only beacons --------------------------------------------------------------------------------


def _ro(**kw: object) -> GtsamFixedLagSmoother:
    return GtsamFixedLagSmoother(GtsamFLSConfig(**kw))  # type: ignore[arg-type]


def test_range_only_update_reduces_the_error_of_drifting_odometry() -> None:
    events, _, truth = ro.scenario()
    odo, _ = ro.run(make_filter("odometry"), events, use_ranges=False)
    f = _ro()
    est, diags = ro.run(f, events)
    e_odo, e_fls = ro.position_rmse(odo, truth), ro.position_rmse(est, truth)
    assert e_odo > 0.3
    assert e_fls < 0.25 * e_odo
    assert sum(d["accepted"] for d in diags) >= 0.95 * len(diags)
    counts = _factor_types(f)
    assert counts.get("RangeFactor2D", 0) > 0 and "BearingRangeFactor2D" not in counts


def _after_drive(f: GtsamFixedLagSmoother, n: int = 60) -> np.ndarray:
    events, _, truth = ro.scenario(n=n)
    f.reset(ro.INITIAL, ro.WORLD, ro.SENSORS, np.random.default_rng(0))
    for ev in events:
        f.predict(ev) if isinstance(ev, Odometry) else f.update(ev)
    return truth[-1]


def _outlier(truth: np.ndarray, t: float = 6.1, extra_m: float = 20.0) -> RangeObservations:
    return RangeObservations(
        t, ro.BEACON_IDS[:1].copy(), np.array([np.hypot(*(ro.BEACON_XY[0] - truth[:2])) + extra_m])
    )


def test_range_gate_rejects_a_gross_outlier() -> None:
    f = _ro()
    truth = _after_drive(f)
    n_factors = f.smoother.getFactors().size()
    before = f.estimate().mean
    f.update(_outlier(truth))
    d = f.estimate().diagnostics
    assert (d["accepted"], d["rejected"]) == (0.0, 1.0)
    assert f.smoother.getFactors().size() == n_factors  # nothing entered the graph
    assert_allclose(f.estimate().mean, before, atol=0)


def test_huber_bounds_the_pull_of_an_ungated_outlier() -> None:
    moved = {}
    for robust in ("huber", "none"):
        f = _ro(range_gate_probability=1.0, range_robust=robust)
        truth = _after_drive(f)
        before = f.estimate().mean
        f.update(_outlier(truth, extra_m=5.0))
        moved[robust] = float(np.hypot(*(f.estimate().mean[:2] - before[:2])))
    assert moved["none"] > 0.3
    assert moved["huber"] < 0.5 * moved["none"]


def test_range_config_is_checked() -> None:
    with pytest.raises(ConfigError, match="range_gate_probability"):
        _ro(range_gate_probability=1.5)
    with pytest.raises(ConfigError, match="range_huber_k"):
        _ro(range_huber_k=0.0)


def test_scalar_nis_equals_the_batched_mahalanobis_distance() -> None:
    f = _new()
    f.predict(_odo(0.1, 0.3))
    f.update(_sight(0.2, (0.3, 0.0), [7, 8], noise=0.01))
    f.predict(Odometry(t=0.3, dx=0.2, dy=0.05, dtheta=0.4, d_left=0.15, d_right=0.25, dt=0.1))
    for r, b in [(2.5, 0.3), (3.0, -0.5), (2.0, 3.1)]:  # the last bearing wraps
        for row in (0, 1):
            batched = float(f._mahalanobis(r, b, rows=[row])[0])
            assert f._nis_one(r, b, row) == pytest.approx(batched, rel=1e-10)
