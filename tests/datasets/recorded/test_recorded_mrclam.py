"""The MRCLAM loader: a small MRCLAM folder written by the tests, every kind of bad input, and Dataset 6 itself."""

from __future__ import annotations

import math
import os
import shutil
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from locbench.core.errors import ConfigError
from locbench.core.events import LandmarkObservations, Odometry
from locbench.core.geometry import twist_increment
from locbench.datasets.dataset import Trajectory2D, check_dataset_contract
from locbench.datasets.recorded import mrclam
from locbench.datasets.recorded.files import MissingDataFile, RecordedDataError, sha256_of
from locbench.datasets.recorded.mrclam import (
    MrclamDataset,
    MrclamParams,
    load_mrclam,
    read_robot_sightings,
    waypoints_by_distance,
)
from locbench.datasets.recorded.mrclam_noise import derive_fold_noise
from locbench.registry import DATASETS, make_dataset

HEADER = (
    "# UTIAS Multi-Robot Cooperative Localization and Mapping Dataset\r\n"
    "# produced by the locbench tests\r\n"
    "# Data Fomat:\r\n"
    "# columns\r\n"
)


def _write(path: Path, rows: list[tuple[object, ...]]) -> None:
    body = "".join(" \t ".join(str(v) for v in row) + " \r\n" for row in rows)
    path.write_bytes((HEADER + body).encode("ascii"))


#: The synthetic run: the truth drives along y = -1 at 0.5 m/s from t = 100 s to 110 s (100 Hz).
T_TRUTH = np.round(np.arange(100.0, 110.0 + 1e-9, 0.01), 3)
#: Odometry at 50 Hz from 100.005 s, one sample before the truth and one after it, one repeated time stamp.
T_ODO = np.r_[99.5, np.round(np.arange(100.005, 110.0, 0.02), 3), 110.5]
T_ODO = np.sort(np.r_[T_ODO, 101.005])  # 101.005 twice: dt = 0


def _small_folder(root: Path, name: str = "MRCLAM_Dataset9") -> Path:
    folder = root / name
    folder.mkdir(parents=True)
    _write(folder / "Barcodes.dat", [(1, 5), (2, 14), (6, 63), (7, 81), (8, 7)])
    _write(
        folder / "Landmark_Groundtruth.dat",
        [(6, 2.0, 0.0, 0.001, 0.002), (7, 0.0, 2.0, 0.003, 0.004), (8, -2.0, 0.0, 0.005, 0.006)],
    )
    _write(
        folder / "Robot1_Groundtruth.dat",
        [(f"{t:.3f}", f"{0.5 * (t - 100.0):.8f}", "-1.00000000", "0.00000000") for t in T_TRUTH],
    )
    _write(folder / "Robot1_Odometry.dat", [(f"{t:.3f}", "0.500", "0.000") for t in T_ODO])
    _write(
        folder / "Robot1_Measurement.dat",
        [
            ("99.000", 63, "3.000", "0.100"),  # before the run starts: dropped
            ("101.000", 63, "3.100", "0.200"),
            ("101.000", 81, "3.200", "-0.300"),
            ("101.000", 14, "1.500", "0.050"),  # robot 2: a side array, not an event
            ("102.000", 99, "4.000", "0.000"),  # not in Barcodes.dat: counted
            ("103.000", 7, "2.500", "3.000"),
        ],
    )
    return folder


@pytest.fixture
def small(tmp_path: Path) -> Path:
    return _small_folder(tmp_path)


# --- the small folder --------------------------------------------------------------------------------------


def test_twist_increment_is_the_exact_arc() -> None:
    # A quarter turn at 1 m/s for 1 s: radius 2/pi, ends at (r, r) with heading pi/2.
    dx, dy, dth = twist_increment(1.0, math.pi / 2, 1.0)
    r = 2.0 / math.pi
    assert dx == pytest.approx(r, abs=1e-12) and dy == pytest.approx(r, abs=1e-12) and dth == pytest.approx(math.pi / 2)
    dx, dy, dth = twist_increment(0.3, 0.0, 0.5)
    assert (dx, dy, dth) == (pytest.approx(0.15), 0.0, 0.0)
    # Composing many small exact steps of the same twist gives the one big step.
    n = 100
    x = y = th = 0.0
    sx, sy, sth = twist_increment(0.7, -1.3, 2.0 / n)
    for _ in range(n):
        x, y, th = x + math.cos(th) * sx - math.sin(th) * sy, y + math.sin(th) * sx + math.cos(th) * sy, th + sth
    bx, by, bth = twist_increment(0.7, -1.3, 2.0)
    assert (x, y, th) == (
        pytest.approx(float(bx), abs=1e-12),
        pytest.approx(float(by), abs=1e-12),
        pytest.approx(float(bth)),
    )


def test_small_folder_events_truth_and_map(small: Path) -> None:
    ds = load_mrclam(small, 1, waypoint_spacing_m=1.0)
    check_dataset_contract(ds)
    odo = [e for e in ds.events if isinstance(e, Odometry)]
    obs = [e for e in ds.events if isinstance(e, LandmarkObservations)]
    # Trimmed to the truth: the sample at 99.5 s and the interval ending at 110.5 s are gone; dt = 0 gives nothing.
    inside = T_ODO[(T_ODO >= 100.0) & (T_ODO <= 110.0)]
    assert len(odo) == np.count_nonzero(np.diff(inside) > 0)
    assert odo[0].t == pytest.approx(100.025) and odo[0].dt == pytest.approx(0.02)
    assert all(e.v == 0.5 and e.omega == 0.0 for e in odo)
    assert all(e.dx == pytest.approx(0.5 * e.dt) and e.dy == 0.0 and e.dtheta == 0.0 for e in odo)  # type: ignore[operator]
    # The truth starts at t0 = 100.005 s, interpolated; the initial belief is that pose.
    gt = ds.ground_truth
    assert gt.t[0] == pytest.approx(100.005) and gt.xy[0] == pytest.approx([0.0025, -1.0])
    assert ds.initial.mean == pytest.approx([0.0025, -1.0, 0.0])
    assert np.sqrt(np.diag(ds.initial.cov)) == pytest.approx([0.01, 0.01, 0.02])
    # Sightings: subjects not barcodes, one event per time stamp, robots and unknown barcodes kept apart.
    assert [e.t for e in obs] == [101.0, 103.0]
    assert obs[0].ids.tolist() == [6, 7] and obs[0].ranges.tolist() == [3.1, 3.2]
    assert obs[0].bearings == pytest.approx([0.2, -0.3], abs=1e-12)
    assert obs[1].ids.tolist() == [8] and obs[1].bearings[0] == pytest.approx(3.0)
    assert ds.metadata["unknown_barcodes"] == {"99": 1}
    assert ds.metadata["robot_sightings"] == {"total": 1, "per_subject": {2: 1}}
    side = read_robot_sightings(small, 1)
    assert side.subject.tolist() == [2] and side.ranges.tolist() == [1.5] and side.t.tolist() == [101.0]
    # The map with its standard deviations.
    lm = ds.world.landmarks
    assert lm is not None and lm.ids.tolist() == [6, 7, 8]
    assert lm.std_xy is not None and lm.std_xy.tolist() == [[0.001, 0.002], [0.003, 0.004], [0.005, 0.006]]
    assert ds.sensors.twist_sigma_v_mps == mrclam.FOLD_NOISE[1]["twist_sigma_v_mps"]
    assert ds.metadata["verified"] is False


def test_waypoints_every_fixed_distance(small: Path) -> None:
    ds = load_mrclam(small, 1, waypoint_spacing_m=1.0)
    wp = ds.waypoints
    assert wp is not None and len(wp) == 4  # 4.9975 m travelled from t0
    gt = ds.ground_truth
    for j in range(len(wp)):
        k = int(np.flatnonzero(gt.t == wp.t[j])[0])
        assert wp.xy[j] == pytest.approx(gt.xy[k])  # marked at the truth position at that time
        travelled = gt.xy[k, 0] - gt.xy[0, 0]
        assert j + 1 <= travelled + 1e-9 < j + 1 + mrclam.PATH_STEP_M + 0.006


def test_waypoint_distance_ignores_jitter() -> None:
    rng = np.random.default_rng(1)
    t = np.arange(0.0, 100.0, 0.01)
    xy = np.column_stack([0.1 * t, np.zeros_like(t)]) + rng.normal(0.0, 0.001, (t.size, 2))  # 10 m, 1 mm jitter
    raw = float(np.sum(np.hypot(*np.diff(xy, axis=0).T)))
    wp = waypoints_by_distance(Trajectory2D(t, xy, np.zeros_like(t)), 2.5)
    assert raw > 10.8  # the raw path length is inflated by the jitter ...
    assert len(wp) == 3 and wp.xy[:, 0] == pytest.approx([2.5, 5.0, 7.5], abs=0.06)  # ... the thinned one is not


def test_params_are_checked() -> None:
    with pytest.raises(ConfigError, match="dataset must be one of"):
        MrclamParams(dataset=10)
    with pytest.raises(ConfigError, match="robot must be one of"):
        MrclamParams(robot=6)
    with pytest.raises(ConfigError, match="waypoint_spacing_m"):
        MrclamParams(waypoint_spacing_m=0.0)


# --- bad input: each names the file, the line and what was expected -----------------------------------------


def _replace_line(path: Path, lineno: int, text: str) -> None:
    lines = path.read_bytes().decode("ascii").split("\n")
    lines[lineno - 1] = text + "\r"
    path.write_bytes("\n".join(lines).encode("ascii"))


@pytest.mark.parametrize(
    ("file", "lineno", "text", "expected"),
    [
        ("Robot1_Odometry.dat", 7, "100.065 \t 0.500", "wrong column count: 2 fields, expected 3"),
        (
            "Robot1_Measurement.dat",
            6,
            "101.000 \t 63 \t 3.1x \t 0.2",
            r"field 3 \(range \[m\]\) is '3.1x', expected a number",
        ),
        ("Robot1_Measurement.dat", 6, "101.000 \t 63.5 \t 3.1 \t 0.2", "expected an integer"),
        ("Robot1_Groundtruth.dat", 9, "100.001 \t 0.0 \t -1.0 \t 0.0", r"time \[s\] goes backwards"),
        ("Barcodes.dat", 7, "  6 \t   5 ", "barcode 5 listed twice"),
    ],
)
def test_malformed_line_names_file_and_line(small: Path, file: str, lineno: int, text: str, expected: str) -> None:
    _replace_line(small / file, lineno, text)
    with pytest.raises(RecordedDataError, match=expected) as info:
        load_mrclam(small, 1)
    assert info.value.path.name == file and info.value.line == lineno
    assert f"{file}:{lineno}:" in str(info.value)


def test_truncated_last_line(small: Path) -> None:
    path = small / "Robot1_Odometry.dat"
    raw = path.read_bytes()
    cut = raw.rstrip(b"\r\n ")
    cut = cut[: cut.rfind(b"\t")]  # the last line lost its last field and its line end
    path.write_bytes(cut)
    n_lines = cut.count(b"\n") + 1
    with pytest.raises(RecordedDataError, match="truncated line: 2 fields, expected 3") as info:
        load_mrclam(small, 1)
    assert info.value.line == n_lines and f"Robot1_Odometry.dat:{n_lines}:" in str(info.value)


def test_time_going_backwards_in_odometry(small: Path) -> None:
    _replace_line(small / "Robot1_Odometry.dat", 10, "99.000 \t 0.500 \t 0.000")
    with pytest.raises(RecordedDataError, match=r"time \[s\] goes backwards: \S*99\.0\S* after") as info:
        load_mrclam(small, 1)
    assert info.value.line == 10


def test_missing_file(small: Path) -> None:
    (small / "Robot1_Measurement.dat").unlink()
    with pytest.raises(RecordedDataError, match="missing file") as info:
        load_mrclam(small, 1)
    assert info.value.path.name == "Robot1_Measurement.dat"


def test_barcode_of_a_subject_not_on_the_map(small: Path) -> None:
    _replace_line(small / "Barcodes.dat", 9, "  9 \t   7 ")  # barcode 7 now names subject 9: no such landmark
    with pytest.raises(RecordedDataError, match=r"subject 9, which is not in Landmark_Groundtruth\.dat") as info:
        load_mrclam(small, 1)
    assert info.value.path.name == "Robot1_Measurement.dat" and info.value.line == 10


def test_checksum_mismatch(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    folder = _small_folder(tmp_path, "MRCLAM_Dataset6")
    sums = {name: sha256_of(folder / name) for name in mrclam.file_names(1).values()}
    monkeypatch.setitem(mrclam.KNOWN_SHA256, 6, sums)
    load_mrclam(folder, 1)  # the right sums pass
    _replace_line(folder / "Landmark_Groundtruth.dat", 5, "  6 \t 2.5 \t 0.0 \t 0.001 \t 0.002 ")
    with pytest.raises(RecordedDataError, match="checksum mismatch") as info:
        load_mrclam(folder, 1)
    assert info.value.path.name == "Landmark_Groundtruth.dat"
    load_mrclam(folder, 1, verify=False)  # an edited copy still loads when the user asks not to verify


# --- the builder, the data root and the download -----------------------------------------------------------


@pytest.fixture
def data_env(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    root = tmp_path / "data"
    monkeypatch.setenv("LOCBENCH_DATA", str(root))
    monkeypatch.setenv("LOCBENCH_CACHE", str(tmp_path / "cache"))
    return root


def test_builder_reads_the_data_root_and_reports_missing_files(data_env: Path) -> None:
    params = MrclamParams(dataset=9, robot=1, waypoint_spacing_m=1.0)
    with pytest.raises(MissingDataFile, match=r"MRCLAM_Dataset9/Barcodes\.dat"):
        MrclamDataset().build(params, np.random.default_rng(0))
    _small_folder(data_env / "utias_mrclam")
    ds = MrclamDataset().build(params, np.random.default_rng(0))
    check_dataset_contract(ds)
    assert ds.metadata["dataset"] == 9 and ds.metadata["verified"] is False
    specs = MrclamDataset.files(params)
    assert all(s.sha256 is None and s.url == mrclam.ZIP_URL.format(n=9) for s in specs)
    assert all(
        s.sha256 == mrclam.DATASET6_SHA256[s.relpath.rsplit("/", 1)[-1]] for s in MrclamDataset.files(MrclamParams())
    )


def test_noise_fold_gives_another_folds_noise_and_is_checked(data_env: Path) -> None:
    _small_folder(data_env / "utias_mrclam")
    own = MrclamDataset().build(MrclamParams(dataset=9, robot=1), np.random.default_rng(0))
    other = MrclamDataset().build(MrclamParams(dataset=9, robot=1, noise_fold=5), np.random.default_rng(0))
    assert own.sensors == mrclam.nominal_sensors(1) and other.sensors == mrclam.nominal_sensors(5)
    assert own.sensors != other.sensors and "fold 5" in other.metadata["nominal_noise"]
    assert MrclamParams(robot=1, noise_fold=1) == MrclamParams(robot=1, noise_fold=1)
    with pytest.raises(ConfigError, match="noise_fold must be 0"):
        MrclamParams(robot=1, noise_fold=6)


def test_fetch_unzips_into_the_cache_and_verifies(
    data_env: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    pooch = pytest.importorskip("pooch")
    src = _small_folder(tmp_path / "zip_content")
    calls: list[str] = []

    def fake_retrieve(
        url: str, known_hash: str | None, fname: str, path: Path, processor: object, **kw: object
    ) -> list[str]:
        calls.append(url)
        assert known_hash is None and isinstance(processor, pooch.Unzip)
        out = Path(path) / "unzipped" / src.name
        shutil.copytree(src, out)
        return [str(p) for p in sorted(out.iterdir())]

    monkeypatch.setattr(pooch, "retrieve", fake_retrieve)
    cache = Path(os.environ["LOCBENCH_CACHE"])
    got = MrclamDataset().fetch(MrclamParams(dataset=9, robot=1))
    assert calls == [mrclam.ZIP_URL.format(n=9)]
    assert sorted(Path(g).name for g in got) == sorted(mrclam.file_names(1).values())
    assert all(Path(g).parent == cache / "utias_mrclam" / "MRCLAM_Dataset9" for g in got)
    MrclamDataset().build(MrclamParams(dataset=9, robot=1, waypoint_spacing_m=1.0), np.random.default_rng(0))
    # Dataset 6 from a zip whose files are not the published ones: verified after extraction, removed, raised.
    shutil.rmtree(tmp_path / "cache")
    src = _small_folder(tmp_path / "zip6", "MRCLAM_Dataset6")
    with pytest.raises(RecordedDataError, match="checksum mismatch"):
        MrclamDataset().fetch(MrclamParams(dataset=6, robot=1))
    assert not (cache / "utias_mrclam" / "MRCLAM_Dataset6" / "Barcodes.dat").exists()


# --- Dataset 6 (the shared files) --------------------------------------------------------------------------

needs_data = pytest.mark.skipif(
    MrclamDataset.data_unavailable() is not None, reason=str(MrclamDataset.data_unavailable())
)


@pytest.fixture(scope="module")
def registered() -> Iterator[None]:
    snap = DATASETS.snapshot()
    DATASETS.register("mrclam", "locbench.datasets.recorded.mrclam:MrclamDataset")
    try:
        yield
    finally:
        DATASETS.restore(snap)


@pytest.mark.recorded
@needs_data
def test_dataset6_robot1(registered: None) -> None:
    ds = make_dataset("mrclam[dataset=6,robot=1]", 0)
    check_dataset_contract(ds)
    assert ds.name == "mrclam"  # dataset 6, robot 1 are the defaults
    lm = ds.world.landmarks
    assert lm is not None and lm.ids.tolist() == list(range(6, 21)) and lm.std_xy is not None
    assert lm.xy[0] == pytest.approx([0.58831396, -4.28264845]) and lm.std_xy[0] == pytest.approx(
        [0.0000457, 0.00027395]
    )
    obs = [e for e in ds.events if isinstance(e, LandmarkObservations)]
    ids = np.concatenate([e.ids for e in obs])
    assert ids.min() >= 6 and ids.max() <= 20 and ids.size == ds.metadata["landmark_sightings"] == 1534
    assert ds.metadata["robot_sightings"]["total"] == 407 and 1 not in ds.metadata["robot_sightings"]["per_subject"]
    assert ds.metadata["unknown_barcodes"] == {"43": 1}
    # Robot 1's Vicon stops at 771.9 s of the file while its odometry goes on to 900 s: events end with the truth.
    assert ds.events[-1].t <= ds.ground_truth.t[-1] and ds.ground_truth.t[-1] - ds.ground_truth.t[0] == pytest.approx(
        759.8, abs=0.1
    )
    assert ds.metadata["verified"] is True
    assert len(ds.waypoints) == int(46.1 // 5.0)  # 46.1 m travelled (thinned path)


@pytest.mark.recorded
@pytest.mark.slow
@needs_data
def test_frozen_noise_matches_a_fresh_derivation() -> None:
    """Every fold's frozen noise is what the derivation gives on that fold's four tuning robots (within 10 %)."""
    root = os.environ.get("LOCBENCH_DATA", "")
    folder = Path(root) / "utias_mrclam" / "MRCLAM_Dataset6"
    for robot in mrclam.ROBOTS:
        got = derive_fold_noise(folder, robot)
        frozen = mrclam.FOLD_NOISE[robot]
        assert set(frozen) == set(mrclam.NOISE_FIELDS)
        for name, value in frozen.items():
            assert got[name] == pytest.approx(value, rel=0.10), (robot, name)
        sensors = mrclam.nominal_sensors(robot)
        assert all(getattr(sensors, name) == value for name, value in frozen.items())
