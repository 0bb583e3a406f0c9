"""Malformed recorded inputs, one test each: a malformed input is a clean one-line error naming the file and the
field (or is handled correctly), never a traceback, a silent wrong result, or gigabytes of memory.

The small files are built in ``tmp_path`` with the helpers of each loader's own tests.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import scipy.io
from input_support import grey_png
from test_recorded_intel import write_small_intel
from test_recorded_lost_in_the_woods import _small_mat
from test_recorded_mrclam import _small_folder
from test_recorded_plaza import _tiny

from locbench.core.errors import MAX_MESSAGE_CHARS, ConfigError, DataNotFound
from locbench.datasets.dataset import OccupancyGrid
from locbench.datasets.recorded.files import RecordedDataError
from locbench.datasets.recorded.intel import IntelParams, load_intel
from locbench.datasets.recorded.lost_in_the_woods import load_lost_in_the_woods
from locbench.datasets.recorded.mrclam import MrclamParams, load_mrclam
from locbench.datasets.recorded.plaza import load_plaza
from locbench.datasets.recorded.ros_map import load_map_server_map, save_map_server_map


def clean(info: pytest.ExceptionInfo[BaseException], path: Path | str, *words: str) -> str:
    """The error's message, after checking it is one bounded line naming ``path`` and every word."""
    msg = str(info.value)
    assert "\n" not in msg and len(msg) <= MAX_MESSAGE_CHARS, msg[:300]
    assert str(path) in msg, msg
    for w in words:
        assert w in msg, msg
    return msg


# --- truncation ----------------------------------------------------------------------------------------------


def test_mrclam_odometry_cut_inside_its_last_field_at_every_position(tmp_path: Path) -> None:
    folder = _small_folder(tmp_path)
    odo = folder / "Robot1_Odometry.dat"
    raw = odo.read_bytes()
    last_line = raw.rstrip(b"\r\n").rfind(b"\n") + 1
    for cut in range(last_line + 1, len(raw) - 2):  # every cut inside the last record (before its line end)
        odo.write_bytes(raw[:cut])
        with pytest.raises(RecordedDataError) as info:
            load_mrclam(folder, 1, verify=False)
        clean(info, odo, "truncated line")


def test_carmen_message_cut_inside_its_last_field(tmp_path: Path) -> None:
    write_small_intel(tmp_path)
    clf = tmp_path / "freiburg_slam_benchmark" / "intel.clf"
    raw = clf.read_bytes()
    clf.write_bytes(raw.rstrip(b"\n")[:-2])  # the last message lost the end of its logger timestamp
    with pytest.raises(RecordedDataError) as info:
        load_intel(tmp_path, verify=False)
    clean(info, clf, "truncated line")


# --- empty streams -------------------------------------------------------------------------------------------


def test_mrclam_odometry_all_at_one_time_is_an_error(tmp_path: Path) -> None:
    folder = _small_folder(tmp_path)
    odo = folder / "Robot1_Odometry.dat"
    lines = odo.read_text().splitlines(keepends=True)
    body = [ln for ln in lines if not ln.startswith("#")]
    head = [ln for ln in lines if ln.startswith("#")]
    odo.write_text("".join(head) + "".join("105.000 \t 0.500 \t 0.000 \r\n" for _ in body))
    with pytest.raises(RecordedDataError) as info:
        load_mrclam(folder, 1, verify=False)
    clean(info, f"{odo}:6", "every odometry sample has the time 105.0", "expected times that advance")


def test_carmen_odom_stamps_all_equal_is_an_error(tmp_path: Path) -> None:
    write_small_intel(tmp_path)
    clf = tmp_path / "freiburg_slam_benchmark" / "intel.clf"
    out = []
    for line in clf.read_text().splitlines(keepends=True):
        if line.startswith("ODOM"):
            f = line.split()
            f[7], f[9] = "976052858.000000", "1.000000"
            line = " ".join(f) + "\n"
        out.append(line)
    clf.write_text("".join(out))
    with pytest.raises(RecordedDataError) as info:
        load_intel(tmp_path, verify=False)
    clean(info, f"{clf}:5", "every ODOM sample has the time 976052858.0", "expected times that advance")


def test_plaza_gt_of_one_row_is_an_error(tmp_path: Path) -> None:
    d = _tiny()
    d["GT"] = d["GT"][:1]
    path = tmp_path / "one.mat"
    scipy.io.savemat(path, d)
    with pytest.raises(RecordedDataError) as info:
        load_plaza(path)
    clean(info, path, "variable 'GT'", "at least 2")


def test_plaza_dr_outside_the_gt_span_is_an_error(tmp_path: Path) -> None:
    d = _tiny()
    d["DR"] = d["DR"].copy()
    d["DR"][:, 0] += 100.0
    path = tmp_path / "late.mat"
    scipy.io.savemat(path, d)
    with pytest.raises(RecordedDataError) as info:
        load_plaza(path)
    clean(info, path, "variable 'DR'", "no row inside the 'GT' span")


# --- resource bombs from tiny files --------------------------------------------------------------------------


def _map(tmp_path: Path) -> Path:
    grid = OccupancyGrid(np.zeros((4, 5)), 0.05)
    return save_map_server_map(grid, tmp_path / "m.yaml") or tmp_path / "m.yaml"


def test_yaml_with_nested_aliases_is_refused_with_a_short_message(tmp_path: Path) -> None:
    y = tmp_path / "bomb.yaml"
    levels = ['a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]']
    for k in range(1, 9):
        prev = chr(ord("a") + k - 1)
        levels.append(f"{chr(ord('a') + k)}: &{chr(ord('a') + k)} [" + ",".join([f"*{prev}"] * 9) + "]")
    y.write_text("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n" + "\n".join(levels) + "\n")
    assert y.stat().st_size < 1000
    with pytest.raises(RecordedDataError) as info:
        load_map_server_map(y)
    clean(info, y, "YAML alias")


def test_a_huge_yaml_value_is_quoted_short(tmp_path: Path) -> None:
    _map(tmp_path)
    y = tmp_path / "m.yaml"
    y.write_text(y.read_text().replace("resolution: 0.05", "resolution: [" + ", ".join(["1"] * 5000) + "]"))
    with pytest.raises(RecordedDataError) as info:
        load_map_server_map(y)
    clean(info, y, "field 'resolution'", "chars]")


def test_vicon_jump_of_1e9_m_is_refused(tmp_path: Path) -> None:
    folder = _small_folder(tmp_path)
    gt = folder / "Robot1_Groundtruth.dat"
    lines = gt.read_text().splitlines(keepends=True)
    k = len(lines) // 2
    f = lines[k].split()
    lines[k] = f"{f[0]} \t 1000000000.0 \t {f[2]} \t {f[3]} \r\n"
    gt.write_text("".join(lines))
    with pytest.raises(RecordedDataError) as info:
        load_mrclam(folder, 1, verify=False)
    clean(info, f"{gt}:{k + 1}", "x [m]")


def test_a_13000_px_square_png_map_is_refused_before_decoding(tmp_path: Path) -> None:
    pytest.importorskip("PIL")
    png = grey_png(tmp_path / "big.png", 13000, 13000)
    assert png.stat().st_size < 1_000_000
    y = tmp_path / "big.yaml"
    y.write_text("image: big.png\nresolution: 0.05\norigin: [0, 0, 0]\n")
    with pytest.raises(RecordedDataError) as info:
        load_map_server_map(y)
    clean(info, png, "decompression bomb")  # Pillow's own guard, on and turned into an error
    # the limit is a parameter: a smaller one refuses a smaller image
    small = grey_png(tmp_path / "small.png", 300, 300)
    y.write_text("image: small.png\nresolution: 0.05\norigin: [0, 0, 0]\n")
    assert load_map_server_map(y).shape == (300, 300)
    with pytest.raises(RecordedDataError) as info:
        load_map_server_map(y, max_cells=10_000)
    clean(info, small, "expected at most 10000 cells")


@pytest.mark.parametrize("resolution", ["1.0e+6", "1.0e-300"])
def test_map_resolution_out_of_bounds_is_refused(tmp_path: Path, resolution: str) -> None:
    _map(tmp_path)
    y = tmp_path / "m.yaml"
    y.write_text(y.read_text().replace("resolution: 0.05", f"resolution: {resolution}"))
    with pytest.raises(RecordedDataError) as info:
        load_map_server_map(y)
    clean(info, y, "field 'resolution'", "m per pixel")


def test_mrclam_waypoint_spacing_below_the_path_step_is_refused() -> None:
    with pytest.raises(ConfigError, match=r"waypoint_spacing_m must be a distance >= 0\.05 m"):
        MrclamParams(waypoint_spacing_m=1e-7)


@pytest.mark.parametrize("resolution", [0.0005, 1e-300, -1.0, math.inf])
def test_intel_map_resolution_out_of_bounds_is_refused(resolution: float) -> None:
    with pytest.raises(ConfigError, match=r"map_resolution_m' must be a cell side in \[0\.001, 10\.0\] m"):
        IntelParams(map_resolution_m=resolution)


def test_intel_grid_larger_than_the_limit_is_refused_before_allocation(tmp_path: Path) -> None:
    # (a single corrected pose 100 km away no longer reaches the grid: it is off the reachable track, flagged)
    write_small_intel(tmp_path)
    gfs = tmp_path / "freiburg_slam_benchmark" / "intel.gfs.log"
    with pytest.raises(RecordedDataError) as info:
        load_intel(tmp_path, verify=False, max_grid_cells=1000)
    clean(info, gfs, "cells, expected at most 1000", "max_grid_cells")


# --- tracebacks that named no file ---------------------------------------------------------------------------


def _litw(tmp_path: Path, edit: Any) -> Path:
    mat = _small_mat()
    edit(mat)
    path = tmp_path / "dataset2.mat"
    scipy.io.savemat(path, mat)
    return path


@pytest.mark.parametrize(
    ("edit", "words"),
    [
        (lambda m: m.__setitem__("v", np.zeros_like(m["v"])), ("variable 'v'", "every speed is 0")),
        (lambda m: m.__setitem__("v", (m["v"] * 100).astype(np.int16)), ("variable 'v'", "int16", "float")),
        (lambda m: m.__setitem__("r", np.zeros_like(m["r"])), ("variable 'r'", "no sighting")),
        (lambda m: m.__setitem__("t", m["t"] > 1.0), ("variable 't'", "uint8")),  # savemat writes bool as uint8
        (lambda m: m["r"].__setitem__((2, 1), 1e300), ("variable 'r'", "1e+300")),
    ],
)
def test_lost_in_the_woods_bad_variables(tmp_path: Path, edit: Any, words: tuple[str, ...]) -> None:
    path = _litw(tmp_path, edit)
    with pytest.raises(RecordedDataError) as info:
        load_lost_in_the_woods(path)
    clean(info, path, *words)


# --- types and ranges that were accepted silently ------------------------------------------------------------


def test_plaza_dr_stored_as_int32_is_refused(tmp_path: Path) -> None:
    d = _tiny()
    d["DR"] = d["DR"].astype(np.int32)
    path = tmp_path / "int.mat"
    scipy.io.savemat(path, d)
    with pytest.raises(RecordedDataError) as info:
        load_plaza(path)
    clean(info, path, "variable 'DR'", "int32", "float")


def test_plaza_range_offset_that_makes_ranges_negative_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "tiny.mat"
    scipy.io.savemat(path, _tiny())
    with pytest.raises(RecordedDataError) as info:
        load_plaza(path, range_offset_m=1e6)
    clean(info, path, "range_offset_m=1000000.0", "negative")


# --- misleading messages -------------------------------------------------------------------------------------


@pytest.mark.parametrize("beams", [0, 179])
def test_intel_reference_log_with_a_wrong_beam_count_names_that_file(tmp_path: Path, beams: int) -> None:
    write_small_intel(tmp_path)
    gfs = tmp_path / "freiburg_slam_benchmark" / "intel.gfs.log"
    if beams == 0:
        gfs.write_text("")
        words: tuple[str, ...] = ("no FLASER message",)
    else:
        out = []
        for line in gfs.read_text().splitlines(keepends=True):
            f = line.split()
            if f and f[0] == "FLASER":
                f = [f[0], "179", *f[2:181], *f[182:]]
                line = " ".join(f) + "\n"
            out.append(line)
        gfs.write_text("".join(out))
        words = ("FLASER has 179 ranges, expected 180",)
    with pytest.raises(RecordedDataError) as info:
        load_intel(tmp_path, verify=False)
    msg = clean(info, gfs, *words)
    assert "intel.clf" not in msg


@pytest.mark.parametrize(
    ("name", "line", "words"),
    [
        ("Landmark_Groundtruth.dat", "1e20 \t 1.0 \t 1.0 \t 0.001 \t 0.001 \r\n", ("field 1 (subject #)", "1e20")),
        ("Robot1_Measurement.dat", "104.000 \t 1e308 \t 2.000 \t 0.100 \r\n", ("field 2 (barcode #)", "1e308")),
    ],
)
def test_mrclam_huge_ids_are_refused_naming_the_field(tmp_path: Path, name: str, line: str, words: Any) -> None:
    folder = _small_folder(tmp_path)
    path = folder / name
    with open(path, "a", encoding="ascii") as fh:
        fh.write(line)
    with pytest.raises(RecordedDataError) as info:
        load_mrclam(folder, 1, verify=False)
    clean(info, path, "expected an integer", *words)


def test_a_user_map_path_that_does_not_exist_is_an_error_not_a_skip(tmp_path: Path) -> None:
    with pytest.raises(RecordedDataError) as info:
        load_map_server_map(tmp_path / "typo.yaml")
    assert not isinstance(info.value, DataNotFound)
    clean(info, tmp_path / "typo.yaml", "missing map YAML")


# --- the dataset contract runs for every dataset --------------------------------------------------------------


def test_contract_failure_names_the_files(tmp_path: Path) -> None:
    path = tmp_path / "tiny.mat"
    scipy.io.savemat(path, _tiny())
    ds = load_plaza(path)
    ds.check()
    broken = dataclasses.replace(ds, events=tuple(e for e in ds.events if type(e).__name__ != "RangeObservations"))
    with pytest.raises(ConfigError) as info:
        broken.check()
    clean(info, path, "no RangeObservations event")


# --- ROS bags ------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def bag_parts(tmp_path_factory: pytest.TempPathFactory) -> tuple[Any, list[Any], Path]:
    """A ROS 1 bag writer, the messages of ``tiny_circle`` and a folder with its map."""
    pytest.importorskip("rosbags")
    from test_rosbag import _Bag

    from locbench.registry import make_dataset

    ds = make_dataset("tiny_circle", 0)
    folder = tmp_path_factory.mktemp("bagparts")
    assert ds.world.occupancy is not None
    save_map_server_map(ds.world.occupancy, folder / "map.yaml")
    b = _Bag(True)
    return b, b.messages(ds, "nav_msgs/msg/Odometry"), folder


def _write_bag(bag_parts: tuple[Any, list[Any], Path], path: Path, edit: Any = None) -> Path:
    b, msgs, _ = bag_parts
    msgs = [list(m) for m in copy.deepcopy(msgs)]
    if edit is not None:
        edit(b, msgs)
    return b.write(path, [tuple(m) for m in msgs])


def _first(msgs: list[Any], topic: str) -> list[Any]:
    return next(m for m in msgs if m[0] == topic)


def test_a_bag_of_random_bytes_is_a_clean_error(tmp_path: Path) -> None:
    pytest.importorskip("rosbags")
    from locbench.datasets.recorded.rosbag import load_rosbag

    path = tmp_path / "noise.bag"
    path.write_bytes(b"#ROSBAG V2.0\n" + np.random.default_rng(0).bytes(5000))
    with pytest.raises(RecordedDataError) as info:
        load_rosbag(path)
    clean(info, path, "unreadable bag")


def test_a_typo_in_the_bag_path_is_an_error_not_a_skip(tmp_path: Path) -> None:
    pytest.importorskip("rosbags")
    from locbench.datasets.recorded.rosbag import load_rosbag

    with pytest.raises(RecordedDataError) as info:
        load_rosbag(tmp_path / "tpyo.bag")
    assert not isinstance(info.value, DataNotFound)
    clean(info, tmp_path / "tpyo.bag", "missing bag")


def _nan_twist(b: Any, msgs: list[Any]) -> None:
    m = [x for x in msgs if x[0] == "/odom"][5]
    m[2].twist.twist.linear.x = float("nan")


def _zero_increment(b: Any, msgs: list[Any]) -> None:
    _first(msgs, "/scan")[2].angle_increment = 0.0


def _huge_range_max(b: Any, msgs: list[Any]) -> None:
    scan = _first(msgs, "/scan")[2]
    scan.range_max = 3e38  # float32 in the message
    scan.ranges[3] = np.float32(3e38)


def _zero_stamp(b: Any, msgs: list[Any]) -> None:
    scan = _first(msgs, "/scan")[2]
    scan.header.stamp.sec, scan.header.stamp.nanosec = 0, 0


def _odom(msgs: list[Any]) -> list[Any]:
    return [m for m in msgs if m[0] == "/odom"]


def _truth(msgs: list[Any]) -> list[Any]:
    return [m for m in msgs if m[0] == "/ground_truth"]


def _set_quaternion(m: Any, q: tuple[float, float, float, float]) -> None:
    o = m[2].pose.pose.orientation
    o.x, o.y, o.z, o.w = q


def _zero_quaternion(b: Any, msgs: list[Any]) -> None:
    _set_quaternion(_truth(msgs)[3], (0.0, 0.0, 0.0, 0.0))


def _unnormalised_quaternion(b: Any, msgs: list[Any]) -> None:
    o = _odom(msgs)[4][2].pose.pose.orientation
    o.z, o.w = 2.0 * o.z, 2.0 * o.w


def _rolled_quaternion(b: Any, msgs: list[Any]) -> None:
    _set_quaternion(_truth(msgs)[2], (math.sin(math.pi / 4), 0.0, 0.0, math.cos(math.pi / 4)))  # 90 deg about x


def _odometry_at_one_stamp(b: Any, msgs: list[Any]) -> None:
    first = _odom(msgs)[0][2].header.stamp
    for m in _odom(msgs):
        m[2].header.stamp.sec, m[2].header.stamp.nanosec = first.sec, first.nanosec


def _odometry_frame_reset(b: Any, msgs: list[Any]) -> None:
    for m in _odom(msgs)[20:]:
        m[2].pose.pose.position.x += 10.0  # the odometry frame re-zeroed 10 m away mid-run


def _truth_clock_jump(b: Any, msgs: list[Any]) -> None:
    for m in _truth(msgs)[30:]:
        m[2].header.stamp.sec += 1_000_000


@pytest.mark.parametrize(
    ("edit", "words"),
    [
        (_nan_twist, ("topic '/odom' message 6", "twist", "nan")),
        (_zero_increment, ("topic '/scan' message 1", "angle_increment 0.0")),
        (_huge_range_max, ("topic '/scan' message 1", "range_max 3")),
        (_zero_stamp, ("topic '/scan' message 1", "stamp 0.0", "unset header stamp")),
        # poses and clocks that parse but are not valid
        (_zero_quaternion, ("topic '/ground_truth' message 4", "norm 0.0", "unit quaternion")),
        (_unnormalised_quaternion, ("topic '/odom' message 5", "norm 2.0", "unit quaternion")),
        (_rolled_quaternion, ("topic '/ground_truth' message 3", "tilted 1.571 rad", "planar pose")),
        (_odometry_at_one_stamp, ("topic '/odom'", "messages have one stamp")),
        (_odometry_frame_reset, ("odometry (topic '/odom')", "apparent speed", "break the plausibility bounds")),
        (_truth_clock_jump, ("topic '/ground_truth' message 31", "jumps 1e+06 s", "at most 60.0 s")),
    ],
)
def test_bad_bag_messages_are_refused_naming_topic_and_message(
    tmp_path: Path, bag_parts: tuple[Any, list[Any], Path], edit: Any, words: tuple[str, ...]
) -> None:
    from locbench.datasets.recorded.rosbag import load_rosbag

    path = _write_bag(bag_parts, tmp_path / "bad.bag", edit)
    with pytest.raises(RecordedDataError) as info:
        load_rosbag(path, bag_parts[2] / "map.yaml")
    clean(info, path, *words)


def test_the_clean_bag_loads(tmp_path: Path, bag_parts: tuple[Any, list[Any], Path]) -> None:
    from locbench.datasets.recorded.rosbag import load_rosbag

    ds = load_rosbag(_write_bag(bag_parts, tmp_path / "ok.bag"), bag_parts[2] / "map.yaml")
    ds.check()
    assert str(tmp_path / "ok.bag") in ds.sources


# --- the Vicon rate, as measured -----------------------------------------------------------------------------


@pytest.mark.recorded
def test_mrclam_vicon_rate_is_about_65_hz_not_100() -> None:
    from locbench.datasets.recorded.mrclam import MrclamDataset, read_groundtruth

    reason = MrclamDataset.data_unavailable()
    if reason is not None:
        pytest.skip(reason)
    paths = MrclamDataset().paths(MrclamParams(robot=1))
    gt = read_groundtruth(next(p for rel, p in paths.items() if rel.endswith("Robot1_Groundtruth.dat")))
    dt = np.diff(gt.t)
    assert np.median(dt) == pytest.approx(0.016, abs=0.0005)  # the docstring's "median interval 16.0 ms"
    assert 60.0 < len(gt) / (gt.t[-1] - gt.t[0]) < 70.0  # "63-69 samples/s per robot"


@pytest.mark.usefixtures("harness_registry")
def test_make_dataset_runs_the_contract_for_every_dataset(tmp_path: Path) -> None:
    from locbench.registry import make_dataset
    from locbench.run.sweep import run_many

    make_dataset("line", 0)  # a good one passes
    with pytest.raises(ConfigError, match=r"dataset 'line\[steps=0\]': no events"):
        make_dataset("line[steps=0]", 0)
    # the runner stores it as a failed build, never as an ok run
    out = run_many(["odometry"], ["line[steps=0]"], [0], str(tmp_path))
    assert [o.status for o in out] == ["error"] and "no events" in out[0].message


def test_map_line_extraction_is_bounded_before_allocation(monkeypatch: pytest.MonkeyPatch) -> None:
    from locbench.datasets.recorded import scan_map

    occ = np.zeros((20, 20))
    occ[5, :] = 1.0  # 20 occupied cells x 180 angles = 3600 votes
    grid = OccupancyGrid(occ, 0.05)
    assert len(scan_map.extract_map_lines(grid)[0]) == 1
    monkeypatch.setattr(scan_map, "MAX_HOUGH_VOTES", 3000)
    with pytest.raises(ConfigError, match=r"map lines: 20 occupied cells x 180 angles = 3600 Hough votes"):
        scan_map.extract_map_lines(grid)


# --- inputs that parse but would be stored as ok (silent wrong results) --------------------------------------


def _relations(tmp_path: Path, lines: Any) -> Path:
    """The small Intel folder with its relations replaced by ``lines(old_lines)``."""
    write_small_intel(tmp_path)
    rel = tmp_path / "freiburg_slam_benchmark" / "intel.relations"
    rel.write_text("".join(lines(rel.read_text().splitlines(keepends=True))))
    return rel


def _long_relation(old: list[str]) -> list[str]:
    f = old[0].split()
    return [" ".join([f[0], f[1], "1e300", *f[3:]]) + "\n", *old[1:]]


def _same_times(old: list[str]) -> list[str]:
    f = old[1].split()
    return [old[0], " ".join([f[0], f[0], *f[2:]]) + "\n", *old[2:]]


@pytest.mark.parametrize(
    ("lines", "words"),
    [
        (lambda old: [], ("no relation",)),
        (lambda old: ["# only a comment\n"], ("no relation",)),
        (_long_relation, (":1", "dx m", "1e+300", "[-100.0, 100.0]")),
        (_same_times, (":2", "t1 equals t2")),
        (lambda old: old[:1] * 10_000, (":2", "repeats the relation on line 1")),
    ],
)
def test_intel_relations_are_validated(tmp_path: Path, lines: Any, words: tuple[str, ...]) -> None:
    rel = _relations(tmp_path, lines)
    with pytest.raises(RecordedDataError) as info:
        load_intel(tmp_path, verify=False)
    clean(info, rel, *words)


def test_intel_relation_with_t2_before_t1_is_valid(tmp_path: Path) -> None:
    # the benchmark's own intel.relations has 6 such rows: the pose at t2 seen from the pose at t1 is still defined
    rel = _relations(tmp_path, lambda old: old)
    t = np.loadtxt(rel)[:, :2]
    assert np.any(t[:, 1] < t[:, 0])
    ds = load_intel(tmp_path, verify=False)
    assert ds.relations is not None and len(ds.relations) == t.shape[0]


def _plaza(tmp_path: Path, edit: Any) -> Path:
    d = _tiny()
    edit(d)
    path = tmp_path / "plaza.mat"
    scipy.io.savemat(path, d)
    return path


def _one_odometry_row_for_410_s(d: dict[str, np.ndarray]) -> None:
    t = np.arange(0.0, 410.01, 0.5)
    d["GT"] = np.column_stack([t, 0.001 * t, np.zeros_like(t), np.zeros_like(t)])
    d["DR"] = d["DR"][:1]
    d["DRp"] = d["DRp"][:2]


def _all_ranges_at_one_instant(d: dict[str, np.ndarray]) -> None:
    d["TD"] = d["TD"].copy()
    d["TD"][:, 0] = 0.6


def _a_50_m_step_in_a_tenth_of_a_second(d: dict[str, np.ndarray]) -> None:
    d["DR"] = d["DR"].copy()
    d["DR"][1, 0], d["DR"][1, 1] = 0.6, 50.0


def _a_gt_gap(d: dict[str, np.ndarray]) -> None:
    t = np.r_[0.0, 0.5, 1.0, 1.5, 20.0]
    d["GT"] = np.column_stack([t, 0.01 * t, np.zeros_like(t), np.zeros_like(t)])


@pytest.mark.parametrize(
    ("edit", "words"),
    [
        (_one_odometry_row_for_410_s, ("variable 'DR'", "409.5 s short", "(1 odometry row(s))")),
        (_all_ranges_at_one_instant, ("variable 'TD'", "4 ranges at the one time 0.6 s", "one per beacon")),
        (_a_50_m_step_in_a_tenth_of_a_second, ("odometry (variable 'DR')", "t=0.6 s", "speed, m/s 500", "5 m/s")),
        (_a_gt_gap, ("variable 'GT' row 5", "18.5 s", "at most 5.0 s")),
    ],
)
def test_plaza_time_and_motion_bounds(tmp_path: Path, edit: Any, words: tuple[str, ...]) -> None:
    path = _plaza(tmp_path, edit)
    with pytest.raises(RecordedDataError) as info:
        load_plaza(path)
    clean(info, path, *words)


def _edit_rows(path: Path, edit: Any) -> None:
    """Apply ``edit(k, fields) -> fields`` to each data row (after the 4 header lines) of an MRCLAM file."""
    lines = path.read_text().splitlines(keepends=True)
    out = lines[:4]
    for k, line in enumerate(lines[4:]):
        out.append(" \t ".join(edit(k, line.split())) + "\r\n")
    path.write_text("".join(out))


def test_mrclam_odometry_gap_of_1e5_s_is_refused(tmp_path: Path) -> None:
    folder = _small_folder(tmp_path)
    odo = folder / "Robot1_Odometry.dat"
    _edit_rows(odo, lambda k, f: [f"{float(f[0]) + (1e5 if k >= 200 else 0.0):.3f}", *f[1:]])
    with pytest.raises(RecordedDataError) as info:
        load_mrclam(folder, 1, verify=False)
    clean(info, f"{odo}:{4 + 201}", "odometry time jumps 100000 s", "at most 10.0 s")


def test_mrclam_truth_gap_of_1e4_s_is_refused_not_interpolated(tmp_path: Path) -> None:
    folder = _small_folder(tmp_path)
    gt = folder / "Robot1_Groundtruth.dat"
    _edit_rows(gt, lambda k, f: [f"{float(f[0]) + (1e4 if k >= 500 else 0.0):.3f}", *f[1:]])
    with pytest.raises(RecordedDataError) as info:
        load_mrclam(folder, 1, verify=False)
    clean(info, f"{gt}:{4 + 501}", "ground-truth time jumps 10000 s")


def test_mrclam_speed_of_9_9_m_per_s_is_refused(tmp_path: Path) -> None:
    folder = _small_folder(tmp_path)
    odo = folder / "Robot1_Odometry.dat"
    _edit_rows(odo, lambda k, f: [f[0], "9.900", f[2]])
    with pytest.raises(RecordedDataError) as info:
        load_mrclam(folder, 1, verify=False)
    clean(info, f"{odo}:5", "forward velocity", "9.9", "[-1, 1]", "break the plausibility bounds")
    # the truth moving at that speed is refused as well
    folder = _small_folder(tmp_path / "truth")
    gt = folder / "Robot1_Groundtruth.dat"
    _edit_rows(gt, lambda k, f: [f[0], f"{9.9 * (float(f[0]) - 100.0):.8f}", *f[2:]])
    with pytest.raises(RecordedDataError) as info:
        load_mrclam(folder, 1, verify=False)
    clean(info, f"{gt}:6", "ground-truth apparent speed, m/s 9.9", "at most 1 m/s plus 0.05 m")


@pytest.mark.parametrize("name", ["v_var", "om_var", "r_var", "b_var"])
def test_lost_in_the_woods_variance_of_1e300_is_refused(tmp_path: Path, name: str) -> None:
    path = _litw(tmp_path, lambda m: m.__setitem__(name, np.array([[1e300]])))
    with pytest.raises(RecordedDataError) as info:
        load_lost_in_the_woods(path)
    clean(info, path, f"variable {name!r}", "1e+300")


def test_map_yaml_with_a_duplicate_key_is_refused(tmp_path: Path) -> None:
    _map(tmp_path)
    y = tmp_path / "m.yaml"
    y.write_text(y.read_text() + "resolution: 0.5\n")
    with pytest.raises(RecordedDataError) as info:
        load_map_server_map(y)
    clean(info, y, "duplicate key 'resolution'", "first on line")


def test_pgm_with_trailing_bytes_is_refused(tmp_path: Path) -> None:
    _map(tmp_path)
    pgm = next(tmp_path.glob("*.pgm"))
    pgm.write_bytes(pgm.read_bytes() + b"\x00" * 7)
    with pytest.raises(RecordedDataError) as info:
        load_map_server_map(tmp_path / "m.yaml")
    clean(info, pgm, "7 trailing bytes", "expected exactly 20")


def test_bag_truth_topic_equal_to_the_odometry_topic_is_refused() -> None:
    pytest.importorskip("rosbags")
    from locbench.registry import resolve_dataset

    with pytest.raises(ConfigError) as info:
        resolve_dataset("rosbag[path=run.bag,truth_topic=/odom]")
    msg = str(info.value)
    assert "\n" not in msg and "'truth_topic' is the odometry topic '/odom'" in msg, msg
