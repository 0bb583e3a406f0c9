"""Radish corrected logs: the scan pairing, the map build (deterministic, cached by content, bounded),
semi-synthetic and paired odometry on small written logs, every file error, and the shared files."""

from __future__ import annotations

import gzip
import io
import math
import runpy
import shutil
from contextlib import redirect_stdout
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose
from test_recorded_intel import box_ranges

from locbench.core.errors import ConfigError
from locbench.core.events import LaserScan, Odometry
from locbench.core.geometry import between, compose
from locbench.datasets.recorded import radish
from locbench.datasets.recorded.files import MissingDataFile, RecordedDataError
from locbench.datasets.recorded.radish import (
    ENCODER_ERROR,
    KNOWN_SHA256,
    RAW_LOGS,
    EncoderError,
    RadishParams,
    available_sites,
    fit_encoder_error,
    fit_paired_sites,
    load_radish,
    pair_scans,
    simulate_encoder_error,
    site_map,
)
from locbench.registry import make_dataset, make_filter
from locbench.run.filter_pass import incompatibility

ROOT = Path(__file__).resolve().parents[3]
BEAMS = 181
ANGLES = -math.pi / 2 + (math.pi / 180) * np.arange(BEAMS)  # 181 beams: both ends of the half circle
NO_RETURN = 81.91


def _path(n: int = 12) -> np.ndarray:
    """Poses along a loop inside the box room [-3, 3] x [-2, 2] m."""
    a = np.linspace(0.0, 1.5 * math.pi, n)
    return np.column_stack([1.5 * np.cos(a), 0.8 * np.sin(a), a + math.pi / 2])


def _flaser(pose: np.ndarray, t: float, ranges: np.ndarray | None = None) -> str:
    r = box_ranges(pose, ANGLES) if ranges is None else ranges
    r = np.where(np.isfinite(r) & (r < NO_RETURN), r, NO_RETURN)
    p = " ".join(f"{v:.3f}" for v in r)
    q = f"{pose[0]:.6f} {pose[1]:.6f} {pose[2]:.6f}"
    return f"FLASER {r.size} {p} {q} {q} {t:.6f} host {t:.6f}\n"


def corrected_text(poses: np.ndarray, t0: float = 0.0, extra: str = "") -> str:
    out = ["# corrected log\n", "PARAM robot_frontlaser_offset 0.0 nohost 0\n"]
    for k, p in enumerate(poses):
        out.append(f"ODOM {p[0]:.6f} {p[1]:.6f} {p[2]:.6f} 0 0 0 {t0 + k:.6f} host {t0 + k:.6f}\n")
        out.append(_flaser(p, t0 + k + 0.5))
        out.append("NEFF 1 2 3\n")
    return "".join(out) + extra


def write_site(root: Path, name: str, text: str | bytes) -> Path:
    folder = root / "radish_corrected"
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}-corrected.log.gz"
    raw = text.encode("ascii") if isinstance(text, str) else text
    path.write_bytes(gzip.compress(raw, mtime=0))
    return path


def write_raw(root: Path, name: str, poses: np.ndarray, t0: float, odom_drift: float = 0.02) -> Path:
    """A raw log of the same scans (identical ranges), another time base, odometry that drifts from the poses."""
    folder = root / "freiburg_slam_benchmark"
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    odo = np.array([0.0, 0.0, 0.0])
    prev = poses[0]
    for k, p in enumerate(poses):
        u = between(prev, p)
        odo = compose(odo, u * (1.0 + odom_drift))
        prev = p
        t = t0 + 2.0 * k
        out.append(f"ODOM {odo[0]:.6f} {odo[1]:.6f} {odo[2]:.6f} 0 0 0 {t:.6f} host {t:.6f}\n")
        line = _flaser(p, t + 0.1)
        # the raw scan's pose fields are the odometry
        parts = line.split()
        n = int(parts[1])
        q = [f"{odo[0]:.6f}", f"{odo[1]:.6f}", f"{odo[2]:.6f}"]
        parts[n + 2 : n + 8] = q + q
        out.append(" ".join(parts) + "\n")
    path = folder / RAW_LOGS[name].relpath.rsplit("/", 1)[1]
    path.write_text("".join(out), encoding="ascii")
    return path


# --- pairing -------------------------------------------------------------------------------------------------


def test_pair_scans_by_identical_ranges_in_file_order() -> None:
    raw = np.array([[1.0, 2.0], [3.0, 4.0], [1.0, 2.0], [5.0, 6.0], [1.0, 2.0]])
    corr = np.array([[1.0, 2.0], [5.0, 6.0], [1.0, 2.0], [9.0, 9.0]])
    # a repeated scan pairs with the next raw copy after the previous pair, never backwards
    assert pair_scans(corr, raw).tolist() == [0, 3, 4, -1]
    assert pair_scans(corr[:, :1], raw).tolist() == [-1, -1, -1, -1]  # other beam count: nothing pairs


def test_pairing_does_not_use_time(tmp_path: Path) -> None:
    poses = _path()
    write_site(tmp_path, "aces", corrected_text(poses, t0=21.0))
    write_raw(tmp_path, "aces", poses, t0=976052857.0)
    ds = load_radish("aces", tmp_path, verify=False)
    assert ds.metadata["pairing"] == {"corrected_scans": len(poses), "paired": len(poses), "raw_scans": len(poses)}
    # the run is in the raw log's time base, the truth the corrected poses
    assert ds.ground_truth.t[0] == pytest.approx(976052857.1)
    assert_allclose(ds.ground_truth.xy, poses[:, :2], atol=1e-6)
    assert ds.truth_label == "SLAM reference"
    odo = [e for e in ds.events if isinstance(e, Odometry)]
    assert len(odo) == len(poses) - 1
    # the raw odometry, not the reference increments: 2 % longer
    u = between(poses[0], poses[1])
    assert math.hypot(odo[0].dx, odo[0].dy) == pytest.approx(1.02 * math.hypot(u[0], u[1]), rel=1e-3)
    ds.check()


def test_a_raw_log_of_another_recording_is_refused(tmp_path: Path) -> None:
    poses = _path()
    write_site(tmp_path, "aces", corrected_text(poses))
    write_raw(tmp_path, "aces", poses[::-1] + np.array([0.01, 0.0, 0.0]), t0=5.0)
    with pytest.raises(RecordedDataError, match="identical ranges, expected at least"):
        load_radish("aces", tmp_path, verify=False)


# --- semi-synthetic sites ------------------------------------------------------------------------------------


def test_semi_synthetic_site(tmp_path: Path) -> None:
    poses = _path()
    write_site(tmp_path, "box", corrected_text(poses))
    assert available_sites(tmp_path) == ["box"]
    ds = load_radish("box", tmp_path, np.random.default_rng(3))
    ds.check()
    assert "semi-synthetic" in ds.metadata["odometry"]
    scans = [e for e in ds.events if isinstance(e, LaserScan)]
    odo = np.array([e.delta for e in ds.events if isinstance(e, Odometry)])
    assert len(scans) == len(poses) and odo.shape == (len(poses) - 1, 3)
    assert scans[0].angle_increment == pytest.approx(math.pi / 180)
    ref = between(poses[:-1], poses[1:])
    assert not np.allclose(odo, ref)  # the error is there ...
    assert np.max(np.abs(odo - ref)) < 1.0  # ... and of the fitted size
    again = np.array(
        [e.delta for e in load_radish("box", tmp_path, np.random.default_rng(3)).events if isinstance(e, Odometry)]
    )
    other = np.array(
        [e.delta for e in load_radish("box", tmp_path, np.random.default_rng(4)).events if isinstance(e, Odometry)]
    )
    assert_allclose(again, odo, rtol=0, atol=0)
    assert not np.allclose(other, odo)
    assert ds.sensors.odometry_sigma_xy_per_m == ENCODER_ERROR.sigma_xy_per_m


def test_window_keeps_the_first_scans(tmp_path: Path) -> None:
    write_site(tmp_path, "box", corrected_text(_path(12)))
    ds = load_radish("box", tmp_path, max_scans=5)
    assert sum(isinstance(e, LaserScan) for e in ds.events) == 5
    assert ds.metadata["window"] == {"max_scans": 5, "scans_used": 5}
    # the map is the whole log's
    assert ds.metadata["map"]["scans"] == 12


def test_simulated_error_has_the_model_variance() -> None:
    err = EncoderError(0.1, 0.05, 0.2, 0)
    inc = np.tile([1.0, 0.0, 0.5], (20000, 1))
    e = simulate_encoder_error(inc, err, np.random.default_rng(0)) - inc
    assert_allclose(e.var(axis=0), [0.01, 0.01, 0.05**2 + 0.2**2 * 0.5], rtol=0.05)


def test_fit_recovers_a_known_error() -> None:
    rng = np.random.default_rng(1)
    err = EncoderError(0.05, 0.03, 0.1, 0)
    pairs = []
    for _ in range(3):
        ref = np.cumsum(np.column_stack([np.full(400, 0.3), np.zeros(400), rng.normal(0, 0.3, 400)]), axis=0)
        ref_poses = np.zeros((401, 3))
        for k in range(400):
            ref_poses[k + 1] = compose(ref_poses[k], np.array([0.3, 0.0, ref[k, 2] - (ref[k - 1, 2] if k else 0.0)]))
        z = between(ref_poses[:-1], ref_poses[1:])
        u = simulate_encoder_error(
            z, err, rng
        )  # odometry = reference + error (the error is between(u, z) to first order)
        odo = np.zeros_like(ref_poses)
        for k in range(400):
            odo[k + 1] = compose(odo[k], u[k])
        pairs.append((odo, ref_poses))
    fit = fit_encoder_error(pairs)
    assert fit.pairs == 1200
    assert fit.sigma_xy_per_m == pytest.approx(0.05, rel=0.1)
    assert math.hypot(fit.sigma_theta_per_m, fit.sigma_theta_per_rad) == pytest.approx(math.hypot(0.03, 0.1), rel=0.15)


# --- the map ---------------------------------------------------------------------------------------------------


def test_map_is_deterministic_and_cached_by_content(tmp_path: Path) -> None:
    path = write_site(tmp_path, "box", corrected_text(_path()))
    g1, lines, stats = site_map(path)
    radish._site_map.cache_clear()
    radish._read_corrected.cache_clear()
    g2, _, _ = site_map(path)
    assert g1 is not g2
    assert g1.occupancy.tobytes() == g2.occupancy.tobytes()
    assert stats["resolution_m"] == 0.1 and lines is not None and len(lines) >= 4
    occ = g1.cell_centers(np.argwhere(g1.occupied()))
    d_wall = np.minimum(np.abs(np.abs(occ[:, 0]) - 3.0), np.abs(np.abs(occ[:, 1]) - 2.0))
    assert d_wall.max() <= 0.15
    # the same bytes under another name: the cached grid (keyed by the content's sha256)
    copy = write_site(tmp_path / "other", "box-copy", corrected_text(_path()))
    assert site_map(copy)[0] is g2
    assert stats["sha256_input"] == radish.content_sha256(path)


def test_grid_above_the_limit_is_refused_before_allocation(tmp_path: Path) -> None:
    write_site(tmp_path, "box", corrected_text(_path()))
    with pytest.raises(RecordedDataError, match="expected at most 100 cells"):
        load_radish("box", tmp_path, max_grid_cells=100)


def test_kf_linear_beyond_its_database_bound_is_a_skip(tmp_path: Path) -> None:
    write_site(tmp_path, "box", corrected_text(_path()))
    ds = load_radish("box", tmp_path)
    assert incompatibility(make_filter("kf_linear"), ds) is None
    reason = incompatibility(make_filter("kf_linear[grid_step_m=0.01]"), ds)
    assert reason is not None and "memory bound" in reason and "raise grid_step_m" in reason


# --- bad input -------------------------------------------------------------------------------------------------


def test_not_gzip(tmp_path: Path) -> None:
    (tmp_path / "radish_corrected").mkdir()
    p = tmp_path / "radish_corrected" / "box-corrected.log.gz"
    p.write_bytes(b"FLASER 1 2 3")
    with pytest.raises(RecordedDataError, match="not a readable gzip file") as info:
        load_radish("box", tmp_path)
    assert str(p) in str(info.value)


def test_decompressed_size_is_bounded(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    p = write_site(tmp_path, "box", corrected_text(_path()))
    monkeypatch.setattr(radish, "MAX_LOG_BYTES", 1000)
    radish._read_corrected.cache_clear()  # the content was read before, under the default bound
    with pytest.raises(RecordedDataError, match="decompresses to more than 1000 bytes"):
        load_radish("box", tmp_path)
    assert len(gzip.decompress(p.read_bytes())) > 1000


def test_last_line_without_its_end(tmp_path: Path) -> None:
    poses = _path()
    text = corrected_text(poses, extra="ODOM 1 2 3 0 0 0 99.0 host 99")  # a cut ODOM line: left out, named
    write_site(tmp_path, "box", text)
    assert load_radish("box", tmp_path).metadata["dropped_unterminated_last_line"] == "ODOM"
    cut = corrected_text(poses) + _flaser(poses[0], 99.0).rstrip("\n")  # a cut FLASER line: an error
    write_site(tmp_path / "b", "box", cut)
    with pytest.raises(RecordedDataError, match="truncated line"):
        load_radish("box", tmp_path / "b")


@pytest.mark.parametrize(
    ("param", "words"),
    [
        ("PARAM laser_front_laser_fov 0 nohost 0\n", "field of view in (0, 2 pi]"),
        ("PARAM laser_front_laser_fov abc nohost 0\n", "laser_front_laser_fov"),
        ("PARAM robot_frontlaser_offset 1e9 nohost 0\n", "robot_frontlaser_offset"),
    ],
)
def test_bad_params(tmp_path: Path, param: str, words: str) -> None:
    write_site(tmp_path, "box", corrected_text(_path(), extra=param))  # the last PARAM of a name counts
    with pytest.raises(RecordedDataError, match="PARAM") as info:
        load_radish("box", tmp_path)
    assert words in str(info.value)


def test_one_scan_is_too_few(tmp_path: Path) -> None:
    write_site(tmp_path, "box", corrected_text(_path(1)))
    with pytest.raises(RecordedDataError, match="1 FLASER message"):
        load_radish("box", tmp_path)


def test_missing_site_names_the_path(tmp_path: Path) -> None:
    with pytest.raises(MissingDataFile) as info:
        load_radish("nowhere", tmp_path)
    assert "radish_corrected/nowhere-corrected.log.gz" in str(info.value)


@pytest.mark.parametrize("site", ["../etc", "", "a/b", "x" * 200])
def test_bad_site_names(site: str) -> None:
    with pytest.raises(ConfigError, match="site"):
        RadishParams(site=site)


def test_bad_params_of_the_dataset() -> None:
    with pytest.raises(ConfigError, match="max_scans"):
        RadishParams(max_scans=-1)
    with pytest.raises(ConfigError, match="map_resolution_m"):
        RadishParams(map_resolution_m=0.0)


# --- the shared files -----------------------------------------------------------------------------------------


def _data_root() -> Path:
    import os

    env = os.environ.get("LOCBENCH_DATA", "")
    if not env or not (Path(env) / "radish_corrected").is_dir():
        pytest.skip("LOCBENCH_DATA with radish_corrected/ is not set: the shared files are not here")
    return Path(env)


@pytest.mark.recorded
@pytest.mark.parametrize(("site", "paired"), [("intel", 910), ("aces", 440), ("freiburg-079", 4791)])
def test_pairing_on_the_shared_files(site: str, paired: int) -> None:
    root = _data_root()
    cl = radish.read_corrected(root / "radish_corrected" / f"{site}-corrected.log.gz", KNOWN_SHA256[site])
    pairing = radish.paired_raw(site, cl, root)
    assert pairing is not None and pairing.paired == paired == len(cl.log.flaser)
    # identical ranges, and a strictly increasing raw index
    assert np.array_equal(cl.log.flaser.ranges, pairing.raw.flaser.ranges[pairing.index])
    assert np.all(np.diff(pairing.index) > 0)


@pytest.mark.recorded
def test_the_tool_reproduces_the_encoder_error_constant() -> None:
    _data_root()
    fit = fit_paired_sites()
    assert fit == ENCODER_ERROR
    out = io.StringIO()
    with redirect_stdout(out), pytest.raises(SystemExit) as done:
        runpy.run_path(str(ROOT / "tools" / "derive" / "fit_radish_odometry.py"), run_name="__main__")
    assert done.value.code == 0
    assert f"sigma_xy_per_m={ENCODER_ERROR.sigma_xy_per_m!r}" in out.getvalue()


@pytest.mark.recorded
def test_shared_map_build_is_the_same_bytes_twice() -> None:
    root = _data_root()
    path = root / "radish_corrected" / "aces-corrected.log.gz"
    g1 = site_map(path)[0].occupancy.tobytes()
    radish._site_map.cache_clear()
    g2 = site_map(path)[0].occupancy.tobytes()
    assert g1 == g2


@pytest.mark.recorded
@pytest.mark.slow
def test_every_shared_site_builds() -> None:
    root = _data_root()
    sites = available_sites(root)
    assert set(KNOWN_SHA256) <= set(sites)
    for site in sites:
        ds = make_dataset(f"radish[site={site}]")
        assert ds.truth_label == "SLAM reference"
        assert ds.metadata["map"]["rows"] * ds.metadata["map"]["cols"] <= radish.MAX_GRID_CELLS
        if site in RAW_LOGS:
            assert ds.metadata["pairing"]["paired"] == ds.metadata["reference_scans"]
        else:
            assert "semi-synthetic" in ds.metadata["odometry"]


def test_copying_a_site_under_a_new_name_is_a_new_site(tmp_path: Path) -> None:
    src = write_site(tmp_path, "box", corrected_text(_path()))
    shutil.copy(src, src.parent / "mine-corrected.log.gz")
    assert available_sites(tmp_path) == ["box", "mine"]
    assert load_radish("mine", tmp_path).metadata["site"] == "mine"
