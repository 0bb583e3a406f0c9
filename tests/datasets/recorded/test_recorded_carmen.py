"""The CARMEN log reader: values, skipped messages, every malformed-line error, the cache, the shared Intel log."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from locbench.datasets.recorded.carmen import read_carmen
from locbench.datasets.recorded.files import MissingDataFile, RecordedDataError

HEADER = "# message_name [message contents] ipc_timestamp ipc_hostname logger_timestamp\n"


def odom(x: float, y: float, th: float, t: float) -> str:
    return f"ODOM {x:.6f} {y:.6f} {th:.6f} 0.1 0.2 0.3 {t:.6f} nohost {t - 100.0:.6f}\n"


def flaser(ranges: list[float], pose: tuple[float, float, float], t: float) -> str:
    r = " ".join(f"{v:.2f}" for v in ranges)
    x, y, th = pose
    return f"FLASER {len(ranges)} {r} {x} {y} {th} {x + 1} {y + 1} {th + 0.5} {t:.6f} nohost {t - 100.0:.6f}\n"


def good_log() -> str:
    return (
        HEADER
        + "PARAM robot_frontlaser_offset 0.25 nohost 0\n"
        + odom(0.0, 0.0, 0.0, 1000.0)
        + flaser([1.0, 2.0, 3.0], (0.1, 0.2, 0.3), 1000.05)
        + "RLASER 1 5.0 0 0 0 0 0 0 1000.06 nohost 900.06\n"
        + "\n"
        + odom(0.5, 0.1, 0.2, 1000.1)
        + "NEFF 14.2\n"
        + flaser([4.0, 81.83, 6.0], (0.4, 0.5, 0.6), 1000.15)
    )


def write(tmp_path: Path, text: str, name: str = "log.clf") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def test_values_params_and_skipped_messages(tmp_path: Path) -> None:
    log = read_carmen(write(tmp_path, good_log()))
    assert len(log.odom) == 2 and len(log.flaser) == 2
    assert_allclose(log.odom.pose, [[0.0, 0.0, 0.0], [0.5, 0.1, 0.2]])
    assert_allclose(log.odom.tv, [0.1, 0.1])
    assert_allclose(log.odom.rv, [0.2, 0.2])
    assert_allclose(log.odom.accel, [0.3, 0.3])
    assert_allclose(log.odom.ipc_t, [1000.0, 1000.1])
    assert_allclose(log.odom.logger_t, [900.0, 900.1])
    assert_array_equal(log.odom.lines, [3, 7])
    assert_allclose(log.flaser.ranges, [[1.0, 2.0, 3.0], [4.0, 81.83, 6.0]])
    assert_allclose(log.flaser.pose, [[0.1, 0.2, 0.3], [0.4, 0.5, 0.6]])
    assert_allclose(log.flaser.odom_pose, [[1.1, 1.2, 0.8], [1.4, 1.5, 1.1]])
    assert_allclose(log.flaser.ipc_t, [1000.05, 1000.15])
    assert_allclose(log.flaser.logger_t, [900.05, 900.15])
    assert_array_equal(log.flaser.lines, [4, 9])
    assert log.params == {"robot_frontlaser_offset": "0.25"}
    assert log.skipped == {"PARAM": 1, "RLASER": 1, "NEFF": 1}
    assert not log.flaser.ranges.flags.writeable


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(MissingDataFile, match=r"nothere\.clf: missing file"):
        read_carmen(tmp_path / "nothere.clf")


def test_truncated_last_line(tmp_path: Path) -> None:
    text = good_log()
    p = write(tmp_path, text[: text.rindex(" 6.00 ")])  # cut inside the last FLASER, no newline
    with pytest.raises(RecordedDataError, match=r"log\.clf:9: truncated line: \d+ fields, expected 14"):
        read_carmen(p)


def test_flaser_count_not_matching_n(tmp_path: Path) -> None:
    text = good_log().replace("FLASER 3 1.00 2.00 3.00", "FLASER 4 1.00 2.00 3.00")
    with pytest.raises(RecordedDataError, match=r"log\.clf:4: wrong field count: 14 fields, expected 15"):
        read_carmen(write(tmp_path, text))


def test_odom_wrong_field_count(tmp_path: Path) -> None:
    text = good_log().replace("ODOM 0.500000 0.100000 0.200000 0.1", "ODOM 0.500000 0.100000 0.1")
    with pytest.raises(RecordedDataError, match=r"log\.clf:7: wrong field count: 9 fields, expected 10"):
        read_carmen(write(tmp_path, text))


def test_beam_count_not_an_integer(tmp_path: Path) -> None:
    text = good_log().replace("FLASER 3 4.00", "FLASER three 4.00")
    with pytest.raises(RecordedDataError, match=r"log\.clf:9: field 2 \(n, the number of ranges\) is 'three'"):
        read_carmen(write(tmp_path, text))


def test_beam_count_changes(tmp_path: Path) -> None:
    text = good_log() + flaser([1.0, 2.0], (0, 0, 0), 1000.2)
    with pytest.raises(RecordedDataError, match=r"log\.clf:10: FLASER with 2 ranges, expected 3"):
        read_carmen(write(tmp_path, text))


@pytest.mark.parametrize(
    ("old", "new", "where"),
    [
        ("ODOM 0.500000 0.100000 0.2", "ODOM 0.500000 0.1x0000 0.2", r":7: ODOM field 3 \(y\) is '0\.1x0000'"),
        ("FLASER 3 4.00 81.83", "FLASER 3 4.00 abc", r":9: FLASER field 4 \(r_2\) is 'abc'"),
        ("0.4 0.5 0.6 1.4", "0.4 0.5 nan 1.4", r":9: FLASER field 8 \(theta\) is 'nan', expected a finite number"),
        ("nohost 900.150000", "nohost 9o0.150000", r":9: FLASER field 14 \(logger_timestamp\) is '9o0\.150000'"),
        ("1000.100000 nohost", "1000.1O0000 nohost", r":7: ODOM field 8 \(ipc_timestamp\)"),
    ],
)
def test_non_numeric_field(tmp_path: Path, old: str, new: str, where: str) -> None:
    text = good_log()
    assert old in text
    with pytest.raises(RecordedDataError, match=r"log\.clf" + where):
        read_carmen(write(tmp_path, text.replace(old, new)))


def test_time_going_backwards(tmp_path: Path) -> None:
    text = good_log() + odom(0.6, 0.1, 0.2, 1000.05)  # ODOM stamped 0.05 s before the previous ODOM
    p = write(tmp_path, text)
    with pytest.raises(RecordedDataError, match=r"log\.clf:10: time goes backwards: ODOM ipc_timestamp 1000\.050000"):
        read_carmen(p)
    log = read_carmen(p, max_backstep_s=0.1)  # tolerated step back: kept in file order
    assert_allclose(log.odom.ipc_t, [1000.0, 1000.1, 1000.05])
    with pytest.raises(RecordedDataError, match=r"at most 0\.01 s back"):
        read_carmen(p, max_backstep_s=0.01)
    assert len(read_carmen(p, time_checked=("FLASER",)).odom) == 3


def test_non_ascii(tmp_path: Path) -> None:
    p = tmp_path / "log.clf"
    p.write_bytes(good_log().encode() + "ODOM \u00e9\n".encode())
    with pytest.raises(RecordedDataError, match=r"log\.clf:10: non-ASCII byte"):
        read_carmen(p)


def test_cache_per_path_and_mtime(tmp_path: Path) -> None:
    p = write(tmp_path, good_log())
    a = read_carmen(p)
    assert read_carmen(p) is a
    p.write_text(good_log() + odom(1.0, 0.0, 0.0, 1000.3))
    st = p.stat()
    os.utime(p, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    b = read_carmen(p)
    assert b is not a and len(b.odom) == 3


def _intel() -> Path:
    root = os.environ.get("LOCBENCH_DATA", "")
    p = Path(root) / "freiburg_slam_benchmark" / "intel.clf"
    if not root or not p.is_file():
        pytest.skip("recorded data not found: set LOCBENCH_DATA to the folder holding freiburg_slam_benchmark/")
    return p


def test_intel_log_counts_and_its_stamps_going_back() -> None:
    p = _intel()
    with pytest.raises(RecordedDataError, match=r"intel\.clf:28: time goes backwards: ODOM"):
        read_carmen(p)
    log = read_carmen(p, max_backstep_s=1.0)
    assert len(log.odom) == 26915 and len(log.flaser) == 13631
    assert log.flaser.ranges.shape == (13631, 180)
    assert log.skipped == {"PARAM": 2}
    assert log.params["robot_frontlaser_offset"] == "0.0"
    # logger_timestamp is the ipc clock shifted by a constant (the logger's start time)
    assert np.ptp(log.flaser.ipc_t - log.flaser.logger_t) < 1e-5
    assert int(np.sum(np.diff(log.flaser.ipc_t) < 0)) == 631
    assert int(np.sum(np.diff(log.odom.ipc_t) < 0)) == 602
