"""The plausibility policy on the CARMEN reader, the Intel loader and the TUM reader: an isolated implausible
message or pose is flagged and left out, a structural problem or too many flags is refused in one line naming the
file, the line and the expectation."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from input_support import one_line as _one_line
from test_recorded_intel import T0, box_ranges, flaser_line

from locbench.core.events import LaserScan, Odometry
from locbench.datasets.recorded.carmen import read_carmen, read_carmen_flagged
from locbench.datasets.recorded.files import RecordedDataError
from locbench.datasets.recorded.intel import load_intel
from locbench.datasets.recorded.tum import read_tum, read_tum_flagged


def pose_at(t: float) -> np.ndarray:
    """A slow circle of radius 1 m in the box room (0.1 m/s, 0.1 rad/s), heading along the circle."""
    a = 0.1 * t
    return np.array([math.cos(a), math.sin(a), math.atan2(math.sin(a + math.pi / 2), math.cos(a + math.pi / 2))])


# --- the CARMEN reader -----------------------------------------------------------------------------------------

#: 150 ODOM at 10 Hz and 150 FLASER at 10 Hz, interleaved: line 2 + 2k is ODOM k, line 3 + 2k is FLASER k.
N_MSG = 150


def odom_line(t: float, pose: np.ndarray, tv: float = 0.1, rv: float = 0.1) -> str:
    x, y, th = pose
    return f"ODOM {x:.6f} {y:.6f} {th:.6f} {tv} {rv} 0 {T0 + t:.6f} nohost {t:.6f}\n"


def carmen_lines() -> list[str]:
    out = ["# CARMEN log\n"]
    for k in range(N_MSG):
        t = 0.1 * k
        out.append(odom_line(t, pose_at(t)))
        out.append(flaser_line(box_ranges(pose_at(t + 0.05)), pose_at(t + 0.05), pose_at(t + 0.05), T0 + t + 0.05, t))
    return out


def odom_at(k: int) -> int:
    """The 0-based list index (line - 1) of ODOM k."""
    return 1 + 2 * k


def write_log(tmp_path: Path, lines: list[str]) -> Path:
    p = tmp_path / "log.clf"
    p.write_text("".join(lines))
    return p


def with_range(line: str, beam: int, value: str) -> str:
    f = line.split()
    f[2 + beam] = value
    return " ".join(f) + "\n"


def test_carmen_clean_log_flags_nothing(tmp_path: Path) -> None:
    log, flags = read_carmen_flagged(write_log(tmp_path, carmen_lines()))
    assert len(log.odom) == len(log.flaser) == N_MSG and flags.flagged == ()
    assert flags.odom_kept.all() and flags.flaser_kept.all()


def test_carmen_negative_range_is_flagged_not_refused(tmp_path: Path) -> None:
    lines = carmen_lines()
    lines[odom_at(40) + 1] = with_range(lines[odom_at(40) + 1], 7, "-1.00")
    p = write_log(tmp_path, lines)
    log, flags = read_carmen_flagged(p)
    (f,) = flags.flagged
    assert (f.source, f.line, f.t, f.stream) == (str(p), odom_at(40) + 2, T0 + 4.05, "FLASER")
    assert (f.quantity, f.value, f.bound) == ("range, m", -1.0, "in [0, 1000]")
    assert np.flatnonzero(~flags.flaser_kept).tolist() == [40] and flags.odom_kept.all()
    assert log.flaser.ranges[40, 7] == -1.0  # the log keeps what was read; the caller leaves the message out
    # the plain reader, which other loaders use, still refuses it
    with pytest.raises(
        RecordedDataError, match=rf"log\.clf:{odom_at(40) + 2}: FLASER field 10 \(r_8\) is -1\.0, expected in \[0\.0"
    ):
        read_carmen(p)


def test_carmen_negative_ranges_beyond_1_percent_are_refused(tmp_path: Path) -> None:
    lines = carmen_lines()
    for k in (30, 60, 90):
        lines[odom_at(k) + 1] = with_range(lines[odom_at(k) + 1], 0, "-0.50")
    p = write_log(tmp_path, lines)
    with pytest.raises(RecordedDataError) as info:
        read_carmen_flagged(p)
    _one_line(info, f"{p}:{odom_at(30) + 2}:", "3 of 150 FLASER samples", "at most 1%", "range, m -0.5")


def test_carmen_range_beyond_the_position_limit_is_still_refused(tmp_path: Path) -> None:
    lines = carmen_lines()
    lines[odom_at(10) + 1] = with_range(lines[odom_at(10) + 1], 0, "2000000.0")
    with pytest.raises(RecordedDataError) as info:
        read_carmen_flagged(write_log(tmp_path, lines))
    _one_line(info, f"log.clf:{odom_at(10) + 2}:", "FLASER field 3 (r_1) is 2000000.0", "expected in [")


@pytest.mark.parametrize(
    ("edit", "quantity", "value", "bound"),
    [
        ({"pose": (None, None, 30.0)}, "theta, rad", 30.0, f"in [{-8 * math.pi:g}, {8 * math.pi:g}]"),
        ({"tv": 7.5}, "tv, m/s", 7.5, "in [-5, 5]"),
        ({"rv": -12.0}, "rv, rad/s", -12.0, "in [-10, 10]"),
        ({"pose": (500.0, None, None)}, "apparent speed, m/s", None, "at most 5 m/s plus 0.05 m and 10 rad/s"),
    ],
)
def test_carmen_odom_sample_beyond_a_bound_is_flagged(
    tmp_path: Path, edit: dict, quantity: str, value: float | None, bound: str
) -> None:
    lines = carmen_lines()
    t = 0.1 * 70
    pose = pose_at(t)
    for j, v in enumerate(edit.get("pose", (None, None, None))):
        if v is not None:
            pose[j] = v
    lines[odom_at(70)] = odom_line(t, pose, edit.get("tv", 0.1), edit.get("rv", 0.1))
    p = write_log(tmp_path, lines)
    _, flags = read_carmen_flagged(p)
    (f,) = flags.flagged
    assert (f.line, f.t, f.stream, f.quantity) == (odom_at(70) + 1, T0 + t, "ODOM", quantity)
    assert bound in f.bound
    if value is not None:
        assert f.value == value
    assert np.flatnonzero(~flags.odom_kept).tolist() == [70]  # the message after the glitch is kept


def test_carmen_doubled_line_is_flagged_once(tmp_path: Path) -> None:
    lines = carmen_lines()
    lines.insert(odom_at(20) + 1, lines[odom_at(20)])
    _, flags = read_carmen_flagged(write_log(tmp_path, lines))
    (f,) = flags.flagged
    assert (f.line, f.stream, f.quantity) == (odom_at(20) + 2, "ODOM", "a repeat of the previous sample")
    assert np.flatnonzero(~flags.odom_kept).tolist() == [21]


def test_carmen_jump_that_stays_is_refused_naming_its_line(tmp_path: Path) -> None:
    lines = carmen_lines()
    for k in range(100, N_MSG):  # from ODOM 100 on, the odometry is 50 m away: every later pose unreachable
        lines[odom_at(k)] = odom_line(0.1 * k, pose_at(0.1 * k) + np.array([50.0, 0.0, 0.0]))
    p = write_log(tmp_path, lines)
    with pytest.raises(RecordedDataError) as info:
        read_carmen_flagged(p)
    _one_line(info, f"{p}:{odom_at(100) + 1}:", "50 of 150 ODOM samples", "apparent speed")


def test_carmen_stamp_uncertainty_widens_the_track_bound(tmp_path: Path) -> None:
    # ODOM 50 is stamped 10 ms after ODOM 49 but 2 m away: too fast for its stamps, not for 1 s of stamp uncertainty
    lines = carmen_lines()
    lines[odom_at(50)] = odom_line(0.1 * 49 + 0.01, pose_at(0.1 * 49) + np.array([2.0, 0.0, 0.0]))
    p = write_log(tmp_path, lines)
    _, strict = read_carmen_flagged(p)
    assert [(f.line, f.quantity) for f in strict.flagged] == [(odom_at(50) + 1, "apparent speed, m/s")]
    _, loose = read_carmen_flagged(p, max_backstep_s=1.0)
    assert loose.flagged == ()


def test_carmen_every_stamp_equal_is_refused(tmp_path: Path) -> None:
    lines = [ln.replace(ln.split()[-3], f"{T0:.6f}") if ln.startswith("FLASER") else ln for ln in carmen_lines()]
    p = write_log(tmp_path, lines)
    with pytest.raises(RecordedDataError) as info:
        read_carmen_flagged(p)
    _one_line(info, f"{p}:5:", f"every FLASER sample has the time {T0!r}", "expected times that advance")
    # a stream that is not checked (a GMapping log's ODOM stamped 0) is not judged
    zeros = [odom_line(-T0, pose_at(0.0)) if ln.startswith("ODOM") else ln for ln in carmen_lines()]
    log, flags = read_carmen_flagged(write_log(tmp_path, zeros), time_checked=("FLASER",))
    assert len(log.odom) == N_MSG and flags.flagged == () and flags.odom_kept.all()


def test_carmen_time_going_backwards_is_still_refused(tmp_path: Path) -> None:
    lines = carmen_lines()
    lines[odom_at(30)] = odom_line(0.1 * 28, pose_at(0.1 * 30))
    with pytest.raises(RecordedDataError) as info:
        read_carmen_flagged(write_log(tmp_path, lines))
    _one_line(info, f"log.clf:{odom_at(30) + 1}:", "time goes backwards: ODOM", "expected non-decreasing")


# --- Intel: the flags reach Dataset.flagged ---------------------------------------------------------------------

#: 301 ODOM at 10 Hz, 150 FLASER at 5 Hz, each a reference scan of the GMapping log (150).
N_SCANS = 150


def write_intel(root: Path) -> Path:
    folder = root / "freiburg_slam_benchmark"
    folder.mkdir(parents=True)
    msgs: list[tuple[float, str]] = []
    for k in range(2 * N_SCANS + 1):
        t = 0.1 * k
        msgs.append((t, odom_line(t, pose_at(t), 0.0, 0.0)))
    gfs = []
    for k in range(N_SCANS):
        t = 0.2 * k + 0.05
        p = pose_at(t)
        msgs.append((t, flaser_line(box_ranges(p), p, p, T0 + t, t)))
        gfs.append(flaser_line(box_ranges(p), p, p, t + 0.003, t + 0.003))
        gfs.append(f"ODOM {p[0]:.6f} {p[1]:.6f} {p[2]:.6f} 0 0 0 0 pippo 0\n")
    msgs.sort(key=lambda m: m[0])
    (folder / "intel.clf").write_text("PARAM robot_frontlaser_offset 0.0 nohost 0\n" + "".join(m for _, m in msgs))
    (folder / "intel.gfs.log").write_text("".join(gfs))
    rel = f"{T0 + 0.45:.6f} {T0 + 1.05:.6f} 0.06 0 0 0 0 0.06\n{T0 + 2.05:.6f} {T0 + 10.05:.6f} 0.7 0.1 0 0 0 0.8\n"
    (folder / "intel.relations").write_text(rel)
    return folder


def edit_line(path: Path, lineno: int, edit: object) -> str:
    lines = path.read_text().splitlines(keepends=True)
    lines[lineno - 1] = edit(lines[lineno - 1])  # type: ignore[operator]
    path.write_text("".join(lines))
    return lines[lineno - 1]


def scan_line(folder: Path, t_rel: float) -> int:
    """The 1-based line of the raw FLASER stamped ``T0 + t_rel``."""
    stamp = f" {T0 + t_rel:.6f} "
    lines = (folder / "intel.clf").read_text().splitlines()
    return next(i + 1 for i, ln in enumerate(lines) if ln.startswith("FLASER") and stamp in ln)


@pytest.fixture
def clean_intel(tmp_path: Path) -> object:
    return load_intel(write_intel(tmp_path / "clean").parent, verify=False)


def test_intel_clean_log_flags_nothing(clean_intel: object) -> None:
    ds = clean_intel
    ds.check()  # type: ignore[attr-defined]
    assert ds.flagged == ()  # type: ignore[attr-defined]
    assert len(ds.ground_truth) == N_SCANS  # type: ignore[attr-defined]


def test_intel_raw_scan_beyond_the_scanner_is_flagged_and_left_out(tmp_path: Path, clean_intel: object) -> None:
    folder = write_intel(tmp_path)
    line = scan_line(folder, 6.05)
    edit_line(folder / "intel.clf", line, lambda ln: with_range(ln, 90, "95.00"))
    ds = load_intel(tmp_path, verify=False)
    (f,) = ds.flagged
    assert (f.source, f.line, f.t) == (str(folder / "intel.clf"), line, T0 + 6.05)
    assert (f.stream, f.quantity, f.value) == ("FLASER", "range, m", 95.0)
    assert f.bound == "in [0, 81.83]"  # the SICK's no-return reading is its largest
    scans = [e.t for e in ds.events if isinstance(e, LaserScan)]
    clean = [e.t for e in clean_intel.events if isinstance(e, LaserScan)]  # type: ignore[attr-defined]
    assert T0 + 6.05 not in scans and sorted([*scans, T0 + 6.05]) == clean
    np.testing.assert_array_equal(ds.ground_truth.t, clean_intel.ground_truth.t)  # type: ignore[attr-defined]


def test_intel_doubled_odom_line_is_flagged_and_gives_no_event(tmp_path: Path, clean_intel: object) -> None:
    folder = write_intel(tmp_path)
    clf = folder / "intel.clf"
    lines = clf.read_text().splitlines(keepends=True)
    at = next(i for i, ln in enumerate(lines) if ln.startswith("ODOM") and f" {T0 + 3.0:.6f} " in ln)
    lines.insert(at + 1, lines[at])
    clf.write_text("".join(lines))
    ds = load_intel(tmp_path, verify=False)
    (f,) = ds.flagged
    assert (f.line, f.t, f.stream, f.quantity) == (at + 2, T0 + 3.0, "ODOM", "a repeat of the previous sample")
    odo = [(e.t, *e.delta) for e in ds.events if isinstance(e, Odometry)]
    clean = [(e.t, *e.delta) for e in clean_intel.events if isinstance(e, Odometry)]  # type: ignore[attr-defined]
    assert odo == clean  # without the flag, the doubled line gave one more (zero) increment


def test_intel_reference_pose_off_the_track_is_flagged_and_left_out(tmp_path: Path, clean_intel: object) -> None:
    folder = write_intel(tmp_path)
    gfs = folder / "intel.gfs.log"
    k = 80  # reference scan k is on line 2k + 1

    def far(ln: str) -> str:
        f = ln.split()
        f[2 + 180] = "500.000000"
        return " ".join(f) + "\n"

    edit_line(gfs, 2 * k + 1, far)
    ds = load_intel(tmp_path, verify=False)
    ds.check()
    (f,) = ds.flagged
    assert (f.source, f.line, f.stream) == (str(gfs), 2 * k + 1, "FLASER")
    assert f.quantity == "apparent speed, m/s" and "plus 1 s of stamp uncertainty" in f.bound
    t_ref = T0 + 0.2 * k + 0.05  # the reference is stamped with its raw scan's time
    clean_t = clean_intel.ground_truth.t  # type: ignore[attr-defined]
    np.testing.assert_array_equal(ds.ground_truth.t, clean_t[clean_t != t_ref])
    assert ds.world.occupancy is not None and ds.world.occupancy.shape == clean_intel.world.occupancy.shape  # type: ignore[attr-defined]


def test_intel_too_many_negative_ranges_are_refused(tmp_path: Path) -> None:
    folder = write_intel(tmp_path)
    lines = [scan_line(folder, 0.2 * k + 0.05) for k in (20, 50, 51)]
    for line in lines:
        edit_line(folder / "intel.clf", line, lambda ln: with_range(ln, 3, "-2.00"))
    with pytest.raises(RecordedDataError) as info:
        load_intel(tmp_path, verify=False)
    _one_line(info, f"intel.clf:{lines[0]}:", "3 of 150 FLASER samples", "at most 1%", "range, m -2")


def test_intel_reference_scans_all_at_one_time_are_refused(tmp_path: Path) -> None:
    folder = write_intel(tmp_path)
    gfs = folder / "intel.gfs.log"
    lines = gfs.read_text().splitlines()
    restamped = (" ".join([*ln.split()[:-3], "1.0 nohost 1.0"]) if ln.startswith("FLASER") else ln for ln in lines)
    gfs.write_text("".join(ln + "\n" for ln in restamped))
    with pytest.raises(RecordedDataError) as info:
        load_intel(tmp_path, verify=False)
    _one_line(info, f"{gfs}:3:", "every FLASER sample has the time 1.0", "expected times that advance")


# --- TUM -----------------------------------------------------------------------------------------------------

HEADER = "# timestamp tx ty tz qx qy qz qw\n"


def tum_line(t: float, x: float, y: float, yaw: float = 0.0) -> str:
    return f"{t!r} {x!r} {y!r} 0.0 0.0 0.0 {math.sin(yaw / 2)!r} {math.cos(yaw / 2)!r}\n"


def tum_lines(n: int = 200) -> list[str]:
    """A pose every 0.1 s driving along x at 0.5 m/s; pose k is on line k + 2."""
    return [HEADER] + [tum_line(0.1 * k, 0.05 * k, 1.0) for k in range(n)]


def write_tum_file(tmp_path: Path, lines: list[str]) -> Path:
    p = tmp_path / "ref.tum"
    p.write_text("".join(lines))
    return p


def test_tum_spike_is_kept_by_read_tum_and_flagged_by_read_tum_flagged(tmp_path: Path) -> None:
    lines = tum_lines()
    lines[1 + 120] = tum_line(12.0, 500.0, 1.0)
    p = write_tum_file(tmp_path, lines)
    assert 500.0 in read_tum(p).xy[:, 0].tolist()  # an estimate's jump is what a comparison measures
    traj, flagged = read_tum_flagged(p)
    (f,) = flagged
    assert (f.source, f.line, f.t, f.stream) == (str(p), 122, 12.0, "trajectory")
    assert f.quantity == "apparent speed, m/s" and f.bound.startswith("at most 5 m/s plus 0.05 m")
    assert len(traj) == 199 and 12.0 not in traj.t.tolist()


def test_tum_doubled_line_and_a_second_pose_at_one_time_are_flagged(tmp_path: Path) -> None:
    lines = tum_lines()
    lines.insert(1 + 50, lines[1 + 50])  # pose 50 twice: the copy is line 53
    lines[1 + 101] = tum_line(0.1 * 99, 0.05 * 99 + 0.01, 1.0)  # pose 100 (line 103) stamped at pose 99's time
    _, flagged = read_tum_flagged(write_tum_file(tmp_path, lines))
    assert [(f.line, f.quantity) for f in flagged] == [
        (53, "a repeat of the previous sample"),
        (103, "time of the previous pose, s"),
    ]


def test_tum_jump_that_stays_is_refused_naming_its_line(tmp_path: Path) -> None:
    lines = tum_lines()
    for k in range(150, 200):
        lines[1 + k] = tum_line(0.1 * k, 0.05 * k + 40.0, 1.0)
    p = write_tum_file(tmp_path, lines)
    read_tum(p)  # an estimate may jump
    with pytest.raises(RecordedDataError) as info:
        read_tum_flagged(p)
    _one_line(info, f"{p}:152:", "50 of 200 trajectory samples", "at most 1%")


def test_tum_every_pose_at_one_time_is_refused(tmp_path: Path) -> None:
    p = write_tum_file(tmp_path, [HEADER] + [tum_line(5.0, 0.1 * k, 0.0) for k in range(4)])
    for reader in (read_tum, read_tum_flagged):
        with pytest.raises(RecordedDataError) as info:
            reader(p)
        _one_line(info, f"{p}:3:", "every pose sample has the time 5.0", "expected times that advance")
    assert len(read_tum(write_tum_file(tmp_path, [HEADER, tum_line(5.0, 0.0, 0.0)]))) == 1  # one pose is fine


def test_tum_recorded_quaternion_that_is_no_rotation_is_refused(tmp_path: Path) -> None:
    lines = tum_lines()
    lines[1 + 10] = "1.0 0.5 1.0 0.0 0.0 0.0 0.5 0.5\n"
    with pytest.raises(RecordedDataError) as info:
        read_tum_flagged(write_tum_file(tmp_path, lines))
    _one_line(info, "ref.tum:12:", "expected a unit quaternion")


def test_a_negative_stamp_uncertainty_is_refused() -> None:
    from locbench.datasets.recorded.plausibility import Flags

    f = Flags("x.log", "pose", [0.0, 1.0, 2.0])
    with pytest.raises(ValueError, match=r"stamp_uncertainty_s must be >= 0 s, got -1\.0"):
        f.flag_track(np.zeros((3, 2)), None, stamp_uncertainty_s=-1.0)
