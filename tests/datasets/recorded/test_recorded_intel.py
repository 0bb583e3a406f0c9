"""The Intel Research Lab dataset: assembly on small written logs, every file error, and the shared files."""

from __future__ import annotations

import math
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

from locbench.core.events import LaserScan, Odometry
from locbench.core.geometry import between, compose
from locbench.datasets.recorded.files import MissingDataFile, RecordedDataError
from locbench.datasets.recorded.intel import (
    ANGLE_INCREMENT_RAD,
    ANGLE_MIN_RAD,
    NO_RETURN_M,
    IntelDataset,
    IntelParams,
    load_intel,
)

ANGLES = ANGLE_MIN_RAD + ANGLE_INCREMENT_RAD * np.arange(180)
HALF_X, HALF_Y = 3.0, 2.0  # box room [-3, 3] x [-2, 2] m
T0 = 976052857.0


def box_ranges(pose: np.ndarray, angles: np.ndarray = ANGLES) -> np.ndarray:
    """Exact ranges from ``pose`` to the walls of the box room."""
    b = pose[2] + angles
    c, s = np.cos(b), np.sin(b)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, (HALF_X - pose[0]) / c, np.where(c < 0, (-HALF_X - pose[0]) / c, np.inf))
        ty = np.where(s > 0, (HALF_Y - pose[1]) / s, np.where(s < 0, (-HALF_Y - pose[1]) / s, np.inf))
    return np.minimum(tx, ty)


# --- assembly on small written logs ----------------------------------------------------------------------------


def flaser_line(ranges: np.ndarray, pose: np.ndarray, odo: np.ndarray, t: float, logger_t: float) -> str:
    r = " ".join(f"{v:.2f}" for v in ranges)
    p = " ".join(f"{v:.6f}" for v in pose)
    o = " ".join(f"{v:.6f}" for v in odo)
    return f"FLASER 180 {r} {p} {o} {t:.6f} nohost {logger_t:.6f}\n"


def true_pose(t_rel: float) -> np.ndarray:
    return np.array([-1.0 + 0.2 * t_rel, 0.1 * t_rel, 0.05 * t_rel])


def odo_pose(t_rel: float) -> np.ndarray:
    # the odometry frame differs from the map frame by a fixed offset (as in the real log)
    return compose(np.array([0.3, -0.2, 0.4]), true_pose(t_rel))


def write_small_intel(root: Path) -> dict[str, object]:
    """A 5 s log: ODOM at 10 Hz (one stamped 0.04 s back), FLASER at 5 Hz, 5 reference scans, 3 relations."""
    folder = root / "freiburg_slam_benchmark"
    folder.mkdir(parents=True)
    clf = ["# CARMEN log\n", "PARAM robot_frontlaser_offset 0.0 nohost 0\n"]
    odom_t = [0.1 * k for k in range(51)]
    odom_t[20], odom_t[21] = 2.06, 2.02  # file order 2.06 then 2.02: a stamp going back
    scan_t = [0.2 * k + 0.05 for k in range(25)]
    msgs: list[tuple[float, str]] = []
    for t in odom_t:
        x, y, th = odo_pose(t)
        msgs.append((t, f"ODOM {x:.6f} {y:.6f} {th:.6f} 0 0 0 {T0 + t:.6f} nohost {t:.6f}\n"))
    for t in scan_t:
        r = box_ranges(true_pose(t))
        r[10] = NO_RETURN_M
        msgs.append((t + 1e-4, flaser_line(r, odo_pose(t), odo_pose(t), T0 + t, t)))
    msgs.sort(key=lambda m: m[0])
    # keep the deliberately back-stamped ODOM in its file position (after 2.06)
    clf += [m for _, m in msgs]
    (folder / "intel.clf").write_text("".join(clf))
    ref_idx = [3, 8, 12, 16, 21]
    gfs = []
    for i in ref_idx:
        t = scan_t[i]
        p = true_pose(t)
        gfs.append(flaser_line(box_ranges(p), p, p, t + 0.003, t + 0.003))
        gfs.append(f"ODOM {p[0]:.6f} {p[1]:.6f} {p[2]:.6f} 0 0 0 0 pippo 0\n")
        gfs.append("NEFF 15\n")
    (folder / "intel.gfs.log").write_text("".join(gfs))
    rel = []
    for a, b in ((4, 6), (10, 15), (20, 5)):
        d = between(true_pose(scan_t[a]), true_pose(scan_t[b]))
        rel.append(f"{T0 + scan_t[a]:.6f} {T0 + scan_t[b]:.6f} {d[0]:.6f} {d[1]:.6f} 0 0 0 {d[2]:.6f}\n")
    (folder / "intel.relations").write_text("".join(rel))
    return {"scan_t": scan_t, "ref_idx": ref_idx}


def test_small_log_assembles(tmp_path: Path) -> None:
    info = write_small_intel(tmp_path)
    scan_t: list[float] = info["scan_t"]  # type: ignore[assignment]
    ref_idx: list[int] = info["ref_idx"]  # type: ignore[assignment]
    ds = load_intel(tmp_path, verify=False)
    ds.check()
    assert ds.truth_label == "SLAM reference"
    ref_t = np.array([T0 + scan_t[i] for i in ref_idx])
    assert_allclose(ds.ground_truth.t, ref_t)
    assert_allclose(ds.ground_truth.poses, [true_pose(scan_t[i]) for i in ref_idx], atol=1e-6)
    assert_allclose(ds.initial.mean, true_pose(scan_t[ref_idx[0]]), atol=1e-6)
    t0, t1 = ref_t[0], ref_t[-1]
    assert all(t0 <= e.t <= t1 for e in ds.events)
    scans = [e for e in ds.events if isinstance(e, LaserScan)]
    odos = [e for e in ds.events if isinstance(e, Odometry)]
    assert len(scans) == ref_idx[-1] - ref_idx[0] + 1
    s = scans[0]
    assert s.ranges.shape == (180,) and math.isinf(s.ranges[10]) and s.range_max == NO_RETURN_M
    assert s.angle_min == pytest.approx(-math.pi / 2) and s.angle_increment == pytest.approx(math.pi / 180)
    assert_allclose(s.ranges[11:20], box_ranges(true_pose(scan_t[ref_idx[0]]))[11:20], atol=0.006)
    # odometry in stamp order: composing the increments from the first reference pose follows the truth
    # (the odometry frame's offset drops out of the increments)
    first = ds.initial.mean
    odo_times = [e.t for e in odos]
    assert odo_times == sorted(odo_times)
    pose = first
    prev_t = None
    for e in odos:
        pose = compose(pose, e.delta)
        prev_t = e.t
    assert prev_t is not None
    # the last ODOM in the span is at 4.3 s; the reference's first scan at 0.65 s with the ODOM at 0.6 s
    expected = compose(true_pose(scan_t[ref_idx[0]]), between(true_pose(0.6), true_pose(prev_t - T0)))
    assert_allclose(pose, expected, atol=1e-5)
    r = ds.relations
    assert r is not None and len(r) == 3
    assert_allclose(r.t1, [T0 + scan_t[4], T0 + scan_t[10], T0 + scan_t[20]])
    assert_allclose(r.delta[0], between(true_pose(scan_t[4]), true_pose(scan_t[6])), atol=1e-6)
    assert ds.world.occupancy is not None and ds.world.lines is not None
    assert ds.sensors.laser_sigma_m == 0.05
    # odometry is exact here, so the derived noise is ~0
    assert ds.sensors.odometry_sigma_xy_per_m is not None and ds.sensors.odometry_sigma_xy_per_m < 1e-3


def test_relation_time_that_is_no_scan(tmp_path: Path) -> None:
    write_small_intel(tmp_path)
    p = tmp_path / "freiburg_slam_benchmark" / "intel.relations"
    lines = p.read_text().splitlines(keepends=True)
    lines[1] = lines[1].replace(f"{T0 + 2.05:.6f}", f"{T0 + 2.07:.6f}", 1)
    p.write_text("".join(lines))
    with pytest.raises(RecordedDataError, match=r"intel\.relations:2: t1 = 976052859\.070000 is not the ipc_timestamp"):
        load_intel(tmp_path, verify=False)


def test_relation_wrong_column_count(tmp_path: Path) -> None:
    write_small_intel(tmp_path)
    p = tmp_path / "freiburg_slam_benchmark" / "intel.relations"
    p.write_text(p.read_text() + "1 2 3\n")
    with pytest.raises(RecordedDataError, match=r"intel\.relations:4: wrong column count: 3 fields, expected 8"):
        load_intel(tmp_path, verify=False)


def test_reference_scan_without_raw_scan(tmp_path: Path) -> None:
    write_small_intel(tmp_path)
    p = tmp_path / "freiburg_slam_benchmark" / "intel.gfs.log"
    text = p.read_text().replace("nohost 1.653000", "nohost 1.670000")  # the 2nd reference scan, 20 ms off
    assert "1.670000" in text
    p.write_text(text)
    with pytest.raises(RecordedDataError, match=r"intel\.gfs\.log:4: FLASER logger_timestamp 1\.670000 has no FLASER"):
        load_intel(tmp_path, verify=False)


def test_malformed_raw_log_line(tmp_path: Path) -> None:
    write_small_intel(tmp_path)
    p = tmp_path / "freiburg_slam_benchmark" / "intel.clf"
    lines = p.read_text().splitlines(keepends=True)
    lines[5] = lines[5].replace(" 0 0 0 ", " 0 zero 0 ", 1) if lines[5].startswith("ODOM") else lines[5]
    assert "zero" in lines[5]
    p.write_text("".join(lines))
    with pytest.raises(RecordedDataError, match=r"intel\.clf:6: ODOM field 6 \(rv\) is 'zero'"):
        load_intel(tmp_path, verify=False)


def test_missing_file(tmp_path: Path) -> None:
    write_small_intel(tmp_path)
    (tmp_path / "freiburg_slam_benchmark" / "intel.gfs.log").unlink()
    with pytest.raises(MissingDataFile, match=r"intel\.gfs\.log: missing file"):
        load_intel(tmp_path, verify=False)


def test_checksum_mismatch(tmp_path: Path) -> None:
    write_small_intel(tmp_path)
    with pytest.raises(RecordedDataError, match=r"intel\.clf: checksum mismatch"):
        load_intel(tmp_path)


def test_builder_files_and_params() -> None:
    files = IntelDataset.files(IntelParams())
    assert [f.relpath for f in files] == [
        "freiburg_slam_benchmark/intel.clf",
        "freiburg_slam_benchmark/intel.gfs.log",
        "freiburg_slam_benchmark/intel.relations",
    ]
    assert files[0].decompress == "bz2" and files[0].download_sha256 is not None
    assert all(f.url and f.sha256 for f in files)
    with pytest.raises(ValueError, match="map_resolution_m"):
        IntelDataset().build(IntelParams(map_resolution_m=-1.0), np.random.default_rng(0))


# --- the shared files ----------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def intel() -> object:
    why = IntelDataset.data_unavailable()
    if why:
        pytest.skip(why)
    return IntelDataset().build(IntelParams(), np.random.default_rng(0))


@pytest.mark.slow
def test_shared_intel(intel: object) -> None:
    from locbench.datasets.dataset import Dataset

    assert isinstance(intel, Dataset)
    ds = intel
    ds.check()
    assert ds.truth_label == "SLAM reference"
    assert len(ds.ground_truth) == 910
    assert ds.ground_truth.t[-1] - ds.ground_truth.t[0] == pytest.approx(2683.77 - 32.907, abs=0.01)
    scans = [e for e in ds.events if isinstance(e, LaserScan)]
    odos = [e for e in ds.events if isinstance(e, Odometry)]
    assert 13000 < len(scans) < 13631 and 26000 < len(odos) < 26915
    r = ds.relations
    assert r is not None and len(r) == 2984
    scan_times = np.array([s.t for s in scans])
    assert np.all(np.isin(r.t1, scan_times)) and np.all(np.isin(r.t2, scan_times))
    inf_frac = np.mean([np.isinf(s.ranges).mean() for s in scans])
    assert 0.01 < inf_frac < 0.05
    m = ds.metadata["map"]
    assert ds.world.occupancy is not None and ds.world.occupancy.resolution == 0.05
    assert 100 < m["segments"] < 1000 and 200 < m["total_length_m"] < 1000
    assert len(ds.world.lines) == m["segments"]  # type: ignore[arg-type]
    assert ds.metadata["stamps_back_in_file_order"] == {"ODOM": 602, "FLASER": 631}
    s = ds.sensors
    for v in (s.odometry_sigma_xy_per_m, s.odometry_sigma_theta_per_m, s.odometry_sigma_theta_per_rad):
        assert v is not None and 0.0 < v < 1.0
    # the reference poses lie in the free space of the map built from them
    g = ds.world.occupancy
    cells = g.world_to_cell(ds.ground_truth.xy)
    assert np.mean(g.free()[cells[:, 0], cells[:, 1]]) > 0.95


def test_shared_checksum_mismatch(tmp_path: Path) -> None:
    root = os.environ.get("LOCBENCH_DATA", "")
    src = Path(root) / "freiburg_slam_benchmark"
    if not root or not (src / "intel.clf").is_file():
        pytest.skip("recorded data not found: set LOCBENCH_DATA to the folder holding freiburg_slam_benchmark/")
    dst = tmp_path / "freiburg_slam_benchmark"
    dst.mkdir()
    for name in ("intel.clf", "intel.relations"):
        (dst / name).symlink_to(src / name)
    data = bytearray((src / "intel.gfs.log").read_bytes())
    data[100] = ord("7") if data[100] != ord("7") else ord("8")
    (dst / "intel.gfs.log").write_bytes(bytes(data))
    with pytest.raises(RecordedDataError, match=r"intel\.gfs\.log: checksum mismatch"):
        IntelDataset().build(IntelParams(root=str(tmp_path)), np.random.default_rng(0))
    shutil.rmtree(dst)
