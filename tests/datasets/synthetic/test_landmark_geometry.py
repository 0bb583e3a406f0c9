"""landmark_geometry (report 001): geometry, landmark detection from the scan, variants and claims."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from locbench import claims
from locbench.claims import gadau_gps as report_001
from locbench.core.errors import ConfigError
from locbench.core.events import UNKNOWN_ID, LandmarkObservations, LaserScan, PoseFix
from locbench.datasets.synthetic import landmark_geometry as lg
from locbench.datasets.synthetic.detection_error import (
    DETECTION_ERROR_MEASURED,
    detection_cases,
    detection_error_stats,
)
from locbench.registry import make_dataset
from locbench.report.doc import Plot, Table
from locbench.report.render import render_png

CIRCLE = "landmark_geometry[circuits=1]"


@pytest.fixture(scope="module")
def circle() -> object:
    return make_dataset(CIRCLE, 0)


def _sightings(ds: object) -> list[LandmarkObservations]:
    return [e for e in ds.events if isinstance(e, LandmarkObservations)]  # type: ignore[attr-defined]


@pytest.mark.parametrize("layout", lg.LAYOUTS)
def test_layouts_keep_clear_of_every_path(layout: str) -> None:
    xy = lg.layout_xy(layout)
    assert xy.shape == (int(layout), 2)
    # every path stays within RANDOM_RADIUS_M of the centre; landmarks stand outside that disc with room to spare
    assert np.min(np.hypot(xy[:, 0], xy[:, 1])) - lg.LANDMARK_RADIUS_M - lg.RANDOM_RADIUS_M >= 0.6
    assert np.all(np.abs(xy) < lg.ARENA_HALF_M - 1.0)


def test_every_map_kind_comes_from_one_geometry(circle: object) -> None:
    w = circle.world  # type: ignore[attr-defined]
    np.testing.assert_allclose(w.landmarks.xy, lg.layout_xy("4"))
    assert len(w.lines) == 4 + 4 * lg.DISC_SIDES
    # the disc centres are free, their rims occupied in the grid
    grid = w.occupancy
    occ = grid.occupied()
    for c in w.landmarks.xy:
        rim = grid.world_to_cell(c + np.array([lg.LANDMARK_RADIUS_M, 0.0]))
        assert occ[rim[0], rim[1]]


def test_detection_matches_the_true_centres(circle: object) -> None:
    gt = circle.ground_truth  # type: ignore[attr-defined]
    lm = circle.world.landmarks.xy  # type: ignore[attr-defined]
    dr, db = [], []
    for e in _sightings(circle):
        k = int(np.searchsorted(gt.t, e.t - 1e-9))
        for j, r, b in zip(e.ids.tolist(), e.ranges.tolist(), e.bearings.tolist(), strict=True):
            d = lm[j] - gt.xy[k]
            dr.append(r - math.hypot(*d))
            db.append(math.remainder(b - (math.atan2(d[1], d[0]) - gt.theta[k]), 2 * math.pi))
            assert abs(b) <= 2.0
    assert len(dr) > 100
    assert math.sqrt(np.mean(np.square(dr))) <= lg.NOMINAL_SIGMA_RANGE_M
    assert math.sqrt(np.mean(np.square(db))) <= lg.NOMINAL_SIGMA_BEARING_RAD


def test_detector_rules_on_a_hand_made_scan() -> None:
    # robot at the origin facing +x; a disc straight ahead at 2 m and one cut by the edge of the field of view
    centres = np.array([[2.0, 0.0], [2.0 * math.cos(2.0), 2.0 * math.sin(2.0)]])
    angles = -2.0 + 4.0 / 150 * np.arange(151)
    ranges = np.full(151, np.inf)
    for c in centres:
        # analytic ray-circle intersection
        b = angles
        proj = c[0] * np.cos(b) + c[1] * np.sin(b)
        disc = proj**2 - (c @ c - lg.LANDMARK_RADIUS_M**2)
        hit = disc >= 0
        ranges[hit] = np.minimum(ranges[hit], proj[hit] - np.sqrt(disc[hit]))
    scan = LaserScan(t=0.0, angle_min=-2.0, angle_increment=4.0 / 150, ranges=ranges, range_min=0.05, range_max=12.0)
    obs = lg.detect_landmarks([scan], np.zeros((1, 3)), centres, lg.LANDMARK_RADIUS_M, True, np.random.default_rng(0))
    assert len(obs) == 1
    assert obs[0].ids.tolist() == [0]  # the disc at the edge of the field of view is left out
    assert obs[0].ranges[0] == pytest.approx(2.0, abs=0.005)
    assert obs[0].bearings[0] == pytest.approx(0.0, abs=1e-9)


def test_withheld_ids_and_sensor_streams() -> None:
    known = make_dataset(CIRCLE, 1)
    unknown = make_dataset("landmark_geometry[circuits=1,known_ids=false]", 1)
    assert all(np.all(e.ids == UNKNOWN_ID) for e in _sightings(unknown))
    assert all(np.all(e.ids >= 0) for e in _sightings(known))
    assert not any(isinstance(e, PoseFix) for e in known.events)
    scans = [e for e in known.events if isinstance(e, LaserScan)]
    assert len(scans[0].ranges) == 151
    assert scans[0].angle_min == pytest.approx(-2.0)
    assert scans[0].angles[-1] == pytest.approx(2.0)


def test_gps_and_initial_offset() -> None:
    ds = make_dataset("landmark_geometry[circuits=1,gps=true,initial_offset_m=2]", 0)
    fixes = [e for e in ds.events if isinstance(e, PoseFix)]
    assert len(fixes) == pytest.approx(ds.duration, abs=1.5)
    start = ds.ground_truth.poses[0]
    off = ds.initial.mean[0:2] - start[0:2]
    assert math.hypot(*off) == pytest.approx(2.0)
    assert ds.initial.mean[2] == pytest.approx(start[2])
    # the belief covers the truth: squared Mahalanobis distance of the offset is 1
    assert off @ np.linalg.solve(ds.initial.cov[0:2, 0:2], off) == pytest.approx(1.0)


def test_kidnap_moves_the_rest_of_the_run_rigidly() -> None:
    from locbench.core.seeding import dataset_rng

    name = "landmark_geometry[circuits=1,kidnap_m=1.5]"
    ds = make_dataset(name, 2)
    # the kidnap-free run with the same draws (execution noise included): the dataset's own generator
    plain = lg.LandmarkGeometryScenario().build(lg.LandmarkGeometryParams(circuits=1), dataset_rng(name, 2))
    (kd,) = ds.kidnaps
    assert math.hypot(kd.delta[0], kd.delta[1]) == pytest.approx(1.5)
    assert abs(kd.delta[2]) == pytest.approx(0.5)
    k = int(np.searchsorted(ds.ground_truth.t, kd.t))
    assert kd.t == pytest.approx(0.5 * ds.duration, abs=0.05)
    np.testing.assert_allclose(ds.ground_truth.xy[:k], plain.ground_truth.xy[:k])
    # same step lengths before and after: the robot is not told and carries on with the same wheel motion
    steps = np.hypot(*np.diff(ds.ground_truth.xy, axis=0).T)
    steps_plain = np.hypot(*np.diff(plain.ground_truth.xy, axis=0).T)
    steps[k - 1] = steps_plain[k - 1]
    np.testing.assert_allclose(steps, steps_plain, atol=1e-9)
    world = lg.geometry_world("4")
    assert np.all(world.is_free(ds.ground_truth.xy[k:], 0.29))


@pytest.mark.parametrize("path", lg.PATHS)
def test_paths_close_each_circuit_at_the_start(path: str) -> None:
    ds = make_dataset(f"landmark_geometry[path={path},circuits=1,landmarks=1]", 0)
    assert len(ds.waypoints) == 1
    # within 1 cm: the robot steers back onto its path under execution noise and stops a few mm from the start
    assert math.dist(ds.ground_truth.xy[-1], lg.START[:2]) < 0.01
    world = lg.geometry_world("8")
    assert np.all(world.is_free(ds.ground_truth.xy, 0.5))


def test_bad_parameters_are_named() -> None:
    with pytest.raises(ConfigError, match="landmarks"):
        make_dataset("landmark_geometry[landmarks=5]", 0)
    with pytest.raises(ConfigError, match="initial_offset_m"):
        make_dataset("landmark_geometry[initial_offset_m=-1]", 0)


# --- claims -----------------------------------------------------------------------------------------


def _frame(rows: list[tuple[str, str, int, str, float]]) -> pd.DataFrame:
    return pd.DataFrame(rows, columns=["dataset", "filter", "seed", "metric", "value"])


def _ate_rows(ate_by_layout: dict[str, float], paths: tuple[str, ...] = ("circle", "star")) -> list:
    rows = []
    for p in paths:
        for lay, a in ate_by_layout.items():
            ds = f"landmark_geometry[landmarks={lay},path={p}]"
            for s in range(5):  # the suite's 5 seeds: enough for a one-sided paired test
                rows.append((ds, "ekf_landmarks", s, "ate_m", a * (1.0 + 0.01 * s)))
                rows.append((ds, "odometry", s, "ate_m", 0.6))
    return rows


def test_claims_are_registered_across_variants() -> None:
    ids = {c.id for c in claims.claims_for("landmark_geometry", across_variants=True)}
    assert ids == {"lg_error_falls_with_landmarks", "lg_path_independent", "lg_gps_converges", "lg_kidnap_no_recovery"}
    assert report_001.layout_section in claims.sections_for("landmark_geometry")
    exp = claims.experiment_of("landmark_geometry")
    assert exp is not None and exp.fold_variants and exp.source == report_001.SOURCE_001


def _claim(cid: str) -> claims.Claim:
    return next(c for c in claims.all_claims() if c.id == cid)


def test_landmark_count_claim() -> None:
    good = _frame(_ate_rows({"1": 0.3, "2": 0.05, "3": 0.02, "4": 0.015, "8": 0.02}))
    res = _claim("lg_error_falls_with_landmarks").evaluate(good)
    assert res.verdict == "reproduced", res.measured
    steep = _frame(_ate_rows({"1": 0.3, "2": 0.05, "3": 0.02, "4": 0.015, "8": 0.005}))
    assert _claim("lg_error_falls_with_landmarks").evaluate(steep).verdict == "not reproduced"
    partial = _frame(_ate_rows({"1": 0.3, "4": 0.015}))
    assert _claim("lg_error_falls_with_landmarks").evaluate(partial).verdict == "not evaluated"
    # a non-base variant (known_ids=false) does not enter
    other = _frame([("landmark_geometry[known_ids=false,landmarks=1]", "ekf_landmarks", 0, "ate_m", 0.001)])
    assert report_001.variants(other)["base"].tolist() == [False]


def test_path_claim() -> None:
    df = _frame(_ate_rows({"4": 0.015}, paths=("circle", "star", "random")))
    assert _claim("lg_path_independent").evaluate(df).verdict == "reproduced"
    df.loc[
        (df["dataset"] == "landmark_geometry[landmarks=4,path=random]") & (df["filter"] == "ekf_landmarks"), "value"
    ] = 0.1
    assert _claim("lg_path_independent").evaluate(df).verdict == "not reproduced"


def test_gps_claim() -> None:
    ds = "landmark_geometry[gps=true,initial_offset_m=2]"
    rows = [(ds, "ekf_landmarks[use_pose_fixes=true]", s, "final_error_m", 0.1) for s in range(3)]
    assert _claim("lg_gps_converges").evaluate(_frame(rows)).verdict == "reproduced"
    rows = [(ds, "ekf_landmarks[use_pose_fixes=true]", s, "final_error_m", 0.6) for s in range(3)]
    assert _claim("lg_gps_converges").evaluate(_frame(rows)).verdict == "not reproduced"
    rows = [(ds, "ekf_landmarks", s, "final_error_m", 0.1) for s in range(3)]
    assert _claim("lg_gps_converges").evaluate(_frame(rows)).verdict == "not evaluated"


def test_kidnap_claim() -> None:
    ds = "landmark_geometry[kidnap_m=1]"
    no_metric = _frame([(ds, "ekf_landmarks", 0, "ate_m", 0.2)])
    assert _claim("lg_kidnap_no_recovery").evaluate(no_metric).verdict == "not evaluated"
    lost = _frame([(ds, "ekf_landmarks", s, "kidnap_recovered", float(s == 0)) for s in range(4)])
    assert _claim("lg_kidnap_no_recovery").evaluate(lost).verdict == "reproduced"
    found = _frame([(ds, "ekf_landmarks", s, "kidnap_recovered", 1.0) for s in range(4)])
    assert _claim("lg_kidnap_no_recovery").evaluate(found).verdict == "not reproduced"


def test_layout_section_gives_a_table_and_a_figure() -> None:
    df = _frame(_ate_rows({"1": 0.3, "4": 0.015}))
    table, plot = report_001.layout_section(df, "landmark_geometry")
    assert isinstance(table, Table) and isinstance(plot, Plot)
    assert table.header == ("filter", "path", "1", "2", "3", "4", "8")
    assert any(r[:2] == ("`ekf_landmarks`", "circle") and r[2].strip("*").startswith("30.") for r in table.rows)
    assert plot.name == "landmark_geometry_ate_per_layout"
    assert render_png(plot)[:4] == b"\x89PNG"


@pytest.mark.slow
def test_the_detection_study_reproduces_its_recorded_result() -> None:
    # the detector's measured error is what the nominal landmark noise rounds up
    measured = detection_error_stats(make_dataset(name, seed) for name, seed in detection_cases())
    assert measured == pytest.approx(DETECTION_ERROR_MEASURED, rel=1e-9, abs=1e-12)
    assert measured["range_rms_m"] <= lg.NOMINAL_SIGMA_RANGE_M
    assert measured["bearing_rms_rad"] <= lg.NOMINAL_SIGMA_BEARING_RAD
