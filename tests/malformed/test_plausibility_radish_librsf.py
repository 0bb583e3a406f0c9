"""The plausibility policy on Radish corrected logs and libRSF sets: each implausible sample flagged (line and time)
and left out, each structural problem refused in one line naming the file and line."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from test_recorded_intel import box_ranges
from test_recorded_librsf import write_uwb
from test_recorded_radish import ANGLES, NO_RETURN, _flaser, _path, corrected_text, write_raw, write_site

from locbench.core.events import LaserScan, Odometry, RangeObservations
from locbench.core.limits import MAX_LASER_BEAMS
from locbench.datasets.dataset import Dataset, FlaggedSample
from locbench.datasets.recorded import radish
from locbench.datasets.recorded.files import RecordedDataError
from locbench.datasets.recorded.librsf import load_librsf
from locbench.datasets.recorded.radish import SCAN_PERIOD_S, load_radish

#: Scans of a written log: enough that one flagged sample stays within the policy's 1 %.
N = 120
SITE = "plausible"  # a site without a raw log: semi-synthetic odometry, scan k at k * SCAN_PERIOD_S


@pytest.fixture(autouse=True)
def _fresh_caches() -> None:
    """The corrected-log caches are keyed by content; each test writes its own."""
    radish._read_corrected.cache_clear()
    radish._site_map.cache_clear()


def _one_line(exc: pytest.ExceptionInfo[RecordedDataError], path: Path, line: int, *words: str) -> None:
    msg = str(exc.value)
    assert "\n" not in msg and f"{path}:{line}:" in msg, msg
    for w in words:
        assert w in msg, msg


def _only_flag(ds: Dataset) -> FlaggedSample:
    assert len(ds.flagged) == 1, ds.flagged
    return ds.flagged[0]


# --- Radish ------------------------------------------------------------------------------------------------


def _flaser_line(k: int) -> int:
    """1-based line of the k-th FLASER of :func:`corrected_text` (a comment, a PARAM, then ODOM/FLASER/NEFF)."""
    return 4 + 3 * k


def _edit_flaser(text: str, k: int, field: int, value: str, *more: int) -> str:
    """``text`` with fields ``field``, ``*more`` (0-based on the line: beam j is 2 + j) of the k-th FLASER set."""
    lines = text.split("\n")
    parts = lines[_flaser_line(k) - 1].split()
    for f in (field, *more):
        parts[f] = value
    lines[_flaser_line(k) - 1] = " ".join(parts)
    return "\n".join(lines)


def _pose_field(text: str, k: int, offset: int) -> int:
    """Index in the k-th FLASER's fields of pose field ``offset`` (0: x, 2: theta; +3: the odometry pose)."""
    n = int(text.split("\n")[_flaser_line(k) - 1].split()[1])
    return n + 2 + offset


def test_radish_reference_jump_of_2_km_is_flagged_and_left_out(tmp_path: Path) -> None:
    poses = _path(N)
    text = corrected_text(poses)
    k = 60
    jumped = f"{poses[k, 0] + 2000.0:.6f}"
    text = _edit_flaser(text, k, _pose_field(text, k, 0), jumped, _pose_field(text, k, 3))
    write_site(tmp_path, SITE, text)
    ds = load_radish(SITE, tmp_path, verify=False)
    f = _only_flag(ds)
    assert (f.line, f.t, f.stream) == (_flaser_line(k), k * SCAN_PERIOD_S, "reference pose")
    assert f.quantity == "apparent speed, m/s" and f.value > 1000.0
    assert k * SCAN_PERIOD_S not in ds.ground_truth.t.tolist() and len(ds.ground_truth) == N - 1
    assert not any(isinstance(e, LaserScan) and e.t == k * SCAN_PERIOD_S for e in ds.events)
    # the map is built without it: a 2 km jump would stretch the grid over 2 km
    assert ds.world.occupancy is not None and max(ds.world.occupancy.shape) * 0.1 < 20.0


def test_radish_reference_that_stays_2_km_away_is_refused(tmp_path: Path) -> None:
    poses = _path(N)
    text = corrected_text(poses)
    for k in range(60, N):  # the reference moves and stays: not an isolated glitch
        text = _edit_flaser(text, k, _pose_field(text, k, 0), f"{poses[k, 0] + 2000.0:.6f}", _pose_field(text, k, 3))
    path = write_site(tmp_path, SITE, text)
    with pytest.raises(RecordedDataError) as exc:
        load_radish(SITE, tmp_path, verify=False)
    _one_line(exc, path, _flaser_line(60), f"{N - 60} of {N} reference pose samples", "expected at most 1%")


def test_radish_heading_of_1e6_rad_is_flagged(tmp_path: Path) -> None:
    text = corrected_text(_path(N))
    k = 30
    text = _edit_flaser(text, k, _pose_field(text, k, 2), "1000000.0", _pose_field(text, k, 5))
    write_site(tmp_path, SITE, text)
    ds = load_radish(SITE, tmp_path, verify=False)
    f = _only_flag(ds)
    assert (f.line, f.t, f.quantity, f.value) == (_flaser_line(k), 30.0, "heading before wrapping, rad", 1e6)
    assert f.bound == f"in [{-8 * math.pi:g}, {8 * math.pi:g}]"
    assert 30.0 not in ds.ground_truth.t.tolist()


def _saturated_log(poses: np.ndarray) -> str:
    """A corrected log whose every 10th beam has no return (written as the scanner's 81.91 m)."""
    out = ["# corrected log\n", "PARAM robot_frontlaser_offset 0.0 nohost 0\n"]
    for k, p in enumerate(poses):
        r = box_ranges(p, ANGLES)
        r[::10] = np.inf
        out.append(f"ODOM {p[0]:.6f} {p[1]:.6f} {p[2]:.6f} 0 0 0 {k:.6f} host {k:.6f}\n")
        out.append(_flaser(p, k + 0.5, r))
        out.append("NEFF 1 2 3\n")
    return "".join(out)


def test_radish_range_of_1e5_m_is_a_flagged_no_return_and_leaves_the_saturation_alone(tmp_path: Path) -> None:
    text = _saturated_log(_path(N))
    k, beam = 40, 5
    text = _edit_flaser(text, k, 2 + beam, "100000.0")
    write_site(tmp_path, SITE, text)
    ds = load_radish(SITE, tmp_path, verify=False)
    f = _only_flag(ds)
    assert (f.line, f.t, f.stream, f.value) == (_flaser_line(k), k * SCAN_PERIOD_S, "laser beam", 1e5)
    assert f.bound == "in [0, 100]"
    # the saturation value still comes from the scanner's 81.91 m: its beams stay no-returns, not walls at 81.9 m
    assert ds.metadata["no_return_m"] == pytest.approx(radish.NO_RETURN_FRACTION * NO_RETURN)
    scans = {e.t: e for e in ds.events if isinstance(e, LaserScan)}
    assert np.isinf(scans[k * SCAN_PERIOD_S].ranges[beam])  # the scan stays, that beam without a return
    assert all(np.isinf(s.ranges[::10]).all() for s in scans.values())
    assert len(scans) == N


def test_radish_param_given_twice_is_refused_naming_both_lines(tmp_path: Path) -> None:
    text = corrected_text(_path(N)).replace(
        "PARAM robot_frontlaser_offset 0.0 nohost 0\n",
        "PARAM robot_frontlaser_offset 0.0 nohost 0\nPARAM robot_frontlaser_offset -0.04 nohost 0\n",
    )
    path = write_site(tmp_path, SITE, text)
    with pytest.raises(RecordedDataError) as exc:
        load_radish(SITE, tmp_path, verify=False)
    _one_line(exc, path, 3, "PARAM robot_frontlaser_offset given twice, on lines 2 and 3")


def test_radish_param_restated_by_a_later_logging_session_takes_its_value(tmp_path: Path) -> None:
    # belgioioso's log: a converter's header, then the robot's own header restating the laser offset
    head = "# message formats defined: PARAM ODOM FLASER\nPARAM robot_frontlaser_offset 0.0 nohost 0\n"
    write_site(
        tmp_path,
        SITE,
        head
        + corrected_text(_path(N))
        .replace("0.0 nohost", "-0.04 nohost", 1)
        .replace("# corrected log", "# message formats defined: PARAM ODOM FLASER", 1),
    )
    ds = load_radish(SITE, tmp_path, verify=False)
    scan = next(e for e in ds.events if isinstance(e, LaserScan))
    assert scan.sensor_pose[0] == pytest.approx(-0.04) and ds.flagged == ()


def test_radish_raw_odometry_spike_of_50_m_is_flagged(tmp_path: Path) -> None:
    poses = _path(250)  # two flags (the spike and the step back) within 1 % of the raw log's increments
    write_site(tmp_path, "aces", corrected_text(poses, t0=21.0))
    t0 = 976052857.0
    raw = write_raw(tmp_path, "aces", poses, t0=t0)
    lines = raw.read_text(encoding="ascii").split("\n")
    for i, line in enumerate(lines[:-1]):  # ODOM every 0.2 s, as a robot's odometry runs (not every 2 s)
        p = line.split()
        for j in (-3, -1):
            p[j] = f"{t0 + (float(p[j]) - t0) / 10.0:.6f}"
        lines[i] = " ".join(p)
    k = 100  # ODOM k is on line 2k + 1 (an ODOM and a FLASER per pose)
    parts = lines[2 * k].split()
    parts[1] = f"{float(parts[1]) + 50.0:.6f}"
    lines[2 * k] = " ".join(parts)
    raw.write_text("\n".join(lines), encoding="ascii")
    ds = load_radish("aces", tmp_path, verify=False)
    t_k = float(parts[-1])
    assert [(f.line, f.t, f.stream, f.source) for f in ds.flagged] == [
        (2 * k + 1, t_k, "odometry", str(raw)),
        (2 * k + 3, pytest.approx(t_k + 0.2), "odometry", str(raw)),
    ]
    assert all(f.value == pytest.approx(250.0, rel=0.02) for f in ds.flagged)  # 50 m over 0.2 s
    odo = [e for e in ds.events if isinstance(e, Odometry)]
    assert len(odo) == 249 - 2 and not any(abs(e.t - t) < 0.05 for e in odo for t in (t_k, t_k + 0.2))
    assert max(math.hypot(e.dx, e.dy) for e in odo) < 1.0


def test_radish_scan_beyond_the_beam_bound_is_refused_at_parse(tmp_path: Path) -> None:
    n = MAX_LASER_BEAMS + 1
    line = f"FLASER {n} " + "1.0 " * n + "0 0 0 0 0 0 1.0 host 1.0\n"
    path = write_site(tmp_path, SITE, "# log\n" + line + line)
    with pytest.raises(RecordedDataError) as exc:
        load_radish(SITE, tmp_path, verify=False)
    _one_line(exc, path, 2, f"field 2 (n, the number of ranges) is {n}", f"at most {MAX_LASER_BEAMS} beams per scan")


# --- libRSF ------------------------------------------------------------------------------------------------

#: Rows of a written UWB set: enough that one flagged row stays within the policy's 1 %.
M = 120


def _uwb_rows(tmp_path: Path, edit: dict[int, str] | None = None, gt_edit: dict[int, str] | None = None) -> Path:
    """The written UWB set with Input lines (1-based) replaced by ``edit`` and GT lines after ``gt_edit``."""
    path = write_uwb(tmp_path, n=M)
    lines = path.read_text(encoding="ascii").split("\n")
    for at, text in (edit or {}).items():
        lines[at - 1] = text
    path.write_text("\n".join(lines), encoding="ascii")
    gt = path.parent / "Indoor_UWB_GT.txt"
    rows = gt.read_text(encoding="ascii").split("\n")
    for at, text in sorted((gt_edit or {}).items(), reverse=True):
        rows.insert(at, text)
    gt.write_text("\n".join(rows), encoding="ascii")
    return path


def _range_line(k: int) -> int:
    """1-based Input line of the k-th range2 row of :func:`write_uwb` (odom2diff and range2 alternate)."""
    return 2 * k + 2


def _fields(path: Path, line: int) -> list[str]:
    return path.read_text(encoding="ascii").split("\n")[line - 1].split()


def test_librsf_swapped_range_and_variance_columns_are_refused(tmp_path: Path) -> None:
    path = write_uwb(tmp_path, n=M)
    lines = path.read_text(encoding="ascii").split("\n")
    for i, line in enumerate(lines):
        p = line.split()
        if p[:1] == ["range2"]:
            p[2], p[3] = p[3], p[2]
            lines[i] = " ".join(p)
    path.write_text("\n".join(lines), encoding="ascii")
    with pytest.raises(RecordedDataError) as exc:
        load_librsf("indoor_uwb", "", tmp_path, verify=False)
    _one_line(exc, path, _range_line(0), f"in {M} of {M} rows the variance is at least the squared range", "swapped")


def test_librsf_999_m_uwb_range_is_flagged(tmp_path: Path) -> None:
    k = 50
    probe = write_uwb(tmp_path, n=M)
    p = _fields(probe, _range_line(k))
    p[2] = "999.0"
    path = _uwb_rows(tmp_path, {_range_line(k): " ".join(p)})
    ds = load_librsf("indoor_uwb", "", tmp_path, verify=False)
    f = _only_flag(ds)
    assert (f.line, f.t, f.stream, f.value, f.bound) == (_range_line(k), 5.0, "range2 (UWB)", 999.0, "in [0, 300]")
    assert f.source == str(path)
    assert not any(isinstance(e, RangeObservations) and e.t == 5.0 for e in ds.events)


def test_librsf_anchor_moved_900_km_is_refused(tmp_path: Path) -> None:
    probe = write_uwb(tmp_path, n=M)
    edits = {}
    for k in range(1, M, 4):  # every row of anchor 106, at (0, 2.4) m in the set
        p = _fields(probe, _range_line(k))
        p[4] = "900000.0"
        edits[_range_line(k)] = " ".join(p)
    path = _uwb_rows(tmp_path, edits)
    with pytest.raises(RecordedDataError) as exc:
        load_librsf("indoor_uwb", "", tmp_path, verify=False)
    _one_line(exc, path, _range_line(1), "anchor id 106 at (900000.0, 2.4)", "within the 300 m range bound")
    # moved in one row only: an anchor with two positions
    path = _uwb_rows(tmp_path, {_range_line(5): edits[_range_line(5)]})
    with pytest.raises(RecordedDataError) as exc:
        load_librsf("indoor_uwb", "", tmp_path, verify=False)
    _one_line(exc, path, _range_line(5), "anchor id 106 at (900000.0, 2.4)", "the anchors are fixed")


def test_librsf_variance_of_1e300_is_flagged(tmp_path: Path) -> None:
    k = 70
    probe = write_uwb(tmp_path, n=M)
    p = _fields(probe, _range_line(k))
    p[3] = "1e300"
    _uwb_rows(tmp_path, {_range_line(k): " ".join(p)})
    ds = load_librsf("indoor_uwb", "", tmp_path, verify=False)
    f = _only_flag(ds)
    assert (f.line, f.t, f.quantity, f.value) == (_range_line(k), 7.0, "range variance, m^2", 1e300)
    assert ds.sensors.range_sigma_m == pytest.approx(0.1)


def test_librsf_wheel_speed_of_1_km_per_s_is_flagged(tmp_path: Path) -> None:
    k = 80
    probe = write_uwb(tmp_path, n=M)
    p = _fields(probe, 2 * k + 1)  # the k-th odom2diff row
    p[2] = "1000.0"
    _uwb_rows(tmp_path, {2 * k + 1: " ".join(p)})
    ds = load_librsf("indoor_uwb", "", tmp_path, verify=False)
    flags = {(f.line, f.t, f.quantity) for f in ds.flagged}
    # (1000 + 0.3) / 2 m/s beyond the speed bound and the wheels' difference beyond the turn bound: one sample
    assert flags == {(2 * k + 1, 8.0, "speed, m/s")}
    odo = {round(e.t, 3): e for e in ds.events if isinstance(e, Odometry)}
    assert 8.0 not in odo and odo[8.1].dt == pytest.approx(0.2)  # the next sample covers the flagged interval


def test_librsf_two_truth_positions_5_m_apart_at_one_time_are_flagged(tmp_path: Path) -> None:
    k = 90  # after GT row k (t = 9.0 s), a second row at the same time 5 m away
    x = 1.0 + 0.03 * k
    _uwb_rows(tmp_path, gt_edit={k + 1: f"point2 9.000 {x:.6f} 6.0 0 0 0 0 "})
    ds = load_librsf("indoor_uwb", "", tmp_path, verify=False)
    f = _only_flag(ds)
    assert (f.line, f.t, f.stream, f.value) == (k + 2, 9.0, "ground-truth (point2)", math.inf)
    assert f.source.endswith("Indoor_UWB_GT.txt")
    assert ds.ground_truth.t.tolist().count(9.0) == 1 and len(ds.ground_truth) == M
