"""The plausibility policy on the MRCLAM and textlog loaders: an isolated glitch is flagged and left out, a
structural problem or too many glitches is refused in one line naming the file, the line and the expectation."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from input_support import one_line as _one_line
from test_recorded_mrclam import _small_folder, _write

from locbench.core.events import Odometry
from locbench.datasets.recorded.files import RecordedDataError
from locbench.datasets.recorded.mrclam import load_mrclam
from locbench.datasets.recorded.textlog import MANIFEST, load_textlog

# --- MRCLAM: a Vicon glitch of 15 ms -------------------------------------------------------------------------

#: A Vicon truth at 15 ms steps, heading 0.63 rad, driving along x at 0.5 m/s (within the Create's 1 m/s).
T_VICON = np.round(np.arange(100.0, 110.0, 0.015), 3)
GLITCH_AT = 400  # row index of the glitch (line 4 header lines + 401)


def _vicon(folder: Path, glitches: list[int]) -> list[tuple[str, ...]]:
    """Write the truth with a glitch at each index of ``glitches``: 0.06572 m off in 15 ms, heading 0.25 rad."""
    rows = []
    for k, t in enumerate(T_VICON):
        x, th = 0.5 * (t - 100.0), 0.63
        if k in glitches:
            x, th = 0.5 * (T_VICON[k - 1] - 100.0) + 0.06572, 0.25
        rows.append((f"{t:.3f}", f"{x:.8f}", "-1.00000000", f"{th:.8f}"))
    _write(folder / "Robot1_Groundtruth.dat", rows)
    return rows


def test_mrclam_vicon_glitch_is_flagged_and_the_recording_runs(tmp_path: Path) -> None:
    folder = _small_folder(tmp_path)
    rows = _vicon(folder, [GLITCH_AT])
    ds = load_mrclam(folder, 1, verify=False)
    ds.check()
    t_glitch = float(rows[GLITCH_AT][0])
    (flag,) = [f for f in ds.flagged if f.stream == "ground-truth"]  # (the small folder doubles an odometry line)
    assert flag.source == str(folder / "Robot1_Groundtruth.dat") and flag.line == 4 + GLITCH_AT + 1
    assert flag.t == t_glitch and flag.stream == "ground-truth" and flag.quantity.startswith("apparent speed")
    assert flag.value == pytest.approx(0.06572 / 0.015, rel=1e-3)
    assert "1 m/s plus 0.05 m" in flag.bound
    assert t_glitch not in ds.ground_truth.t.tolist()
    assert len(ds.ground_truth) == T_VICON.shape[0] - 1  # only the glitch is gone: the sample after it is kept
    assert float(np.max(np.abs(ds.ground_truth.theta - 0.63))) < 1e-12


def test_mrclam_many_vicon_glitches_are_refused_naming_the_first(tmp_path: Path) -> None:
    folder = _small_folder(tmp_path)
    glitches = list(range(100, T_VICON.shape[0], 20))  # 5 % of the samples: not isolated
    _vicon(folder, glitches)
    gt = folder / "Robot1_Groundtruth.dat"
    with pytest.raises(RecordedDataError) as info:
        load_mrclam(folder, 1, verify=False)
    _one_line(info, f"{gt}:{4 + 100 + 1}:", f"{len(glitches)} of {T_VICON.shape[0]} ground-truth", "at most 1%")


def test_mrclam_glitches_for_more_than_2_s_are_refused(tmp_path: Path) -> None:
    folder = _small_folder(tmp_path)
    rows = _vicon(folder, [])
    # the robot is 3 m away for 2.1 s: few samples in all (under 1 %) would be far too many in a row
    far = [k for k, r in enumerate(rows) if 104.0 <= float(r[0]) < 104.0 + 0.015 * 5]
    edited = [(r[0], f"{float(r[1]) + 3.0:.8f}", *r[2:]) if k in far else r for k, r in enumerate(rows)]
    gap = [r for k, r in enumerate(edited) if not (104.0 + 0.015 * 5 <= float(r[0]) < 106.1)]  # a 2 s hole
    _write(folder / "Robot1_Groundtruth.dat", gap)
    with pytest.raises(RecordedDataError) as info:
        load_mrclam(folder, 1, verify=False)
    _one_line(info, "Robot1_Groundtruth.dat:", "in a row", "at most 2 s", "apparent speed")


def test_mrclam_one_sighting_beyond_the_range_bound_is_flagged(tmp_path: Path) -> None:
    folder = _small_folder(tmp_path)
    meas = folder / "Robot1_Measurement.dat"
    rows = [(f"{100.0 + 0.05 * k:.3f}", 63, "3.000", "0.100") for k in range(1, 150)]
    rows[60] = (rows[60][0], 63, "250.000", "0.100")
    _write(meas, rows)
    ds = load_mrclam(folder, 1, verify=False)
    (flag,) = [f for f in ds.flagged if f.stream == "sighting"]
    assert flag.line == 4 + 61 and flag.value == 250.0 and flag.bound == "in [0, 100]"
    seen = [float(e.t) for e in ds.events if not isinstance(e, Odometry)]
    assert float(rows[60][0]) not in seen and len(seen) == 148


# --- textlog ------------------------------------------------------------------------------------------------

N = 300  # truth samples and odometry events, 10 ms apart: one flag is 0.33 %, under the 1 % bound


def _log(
    folder: Path,
    *,
    events: list[str] | None = None,
    truth: list[str] | None = None,
    manifest: dict[str, Any] | None = None,
) -> Path:
    """A textlog of a robot driving along x at 1 m/s for 2.99 s: N truth poses, N - 1 odometry increments."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / MANIFEST).write_text(json.dumps({"format": "locbench-textlog", "version": 1, **(manifest or {})}))
    if truth is None:
        truth = [f"{k / 100!r} {k / 100!r} 0 0 0 0 0 1\n" for k in range(N)]
    (folder / "truth.tum").write_text("# t x y z qx qy qz qw\n" + "".join(truth))
    if events is None:
        events = [_odo(k / 100) for k in range(1, N)]
    (folder / "events.jsonl").write_text("".join(events))
    return folder


def _odo(t: float, dtheta: float = 0.0) -> str:
    return json.dumps({"t": t, "type": "odometry", "dx": 0.01, "dy": 0.0, "dtheta": dtheta, "dt": 0.01}) + "\n"


def test_textlog_doubled_odometry_lines_are_counted_once(tmp_path: Path) -> None:
    events = [_odo(k / 100) for k in range(1, N)]
    events.insert(50, events[49])  # line 51 repeats line 50
    events.insert(201, events[200])
    folder = _log(tmp_path / "log", events=events)
    ds = load_textlog(folder)
    odo = [e for e in ds.events if isinstance(e, Odometry)]
    assert len(odo) == N - 1 and sum(e.dx for e in odo) == pytest.approx(0.01 * (N - 1))
    assert [(f.line, f.t, f.stream) for f in ds.flagged] == [(51, 0.5, "odometry event"), (202, 2.0, "odometry event")]
    assert all(f.quantity == "a repeat of the previous line" for f in ds.flagged)


def test_textlog_every_event_at_t_0_is_refused(tmp_path: Path) -> None:
    events = [_odo(0.0) for _ in range(5)]
    events = [e.replace('"dx": 0.01', f'"dx": {0.01 + k * 1e-3}') for k, e in enumerate(events)]  # not repeats
    folder = _log(tmp_path / "log", events=events)
    with pytest.raises(RecordedDataError) as info:
        load_textlog(folder)
    _one_line(info, f"{folder / 'events.jsonl'}:2:", "every event sample has the time 0.0", "times that advance")


def test_textlog_a_2_pi_turn_in_one_step_is_flagged_by_the_turn_rate(tmp_path: Path) -> None:
    events = [_odo(k / 100) for k in range(1, N)]
    events[99] = _odo(1.0, dtheta=2 * math.pi)  # line 100
    ds = load_textlog(_log(tmp_path / "log", events=events))
    (flag,) = ds.flagged
    assert (flag.line, flag.t, flag.quantity) == (100, 1.0, "odometry speed, m/s")
    assert "10 rad/s plus 0.1 rad" in flag.bound
    assert all(e.dtheta == 0.0 for e in ds.events if isinstance(e, Odometry))
    assert len(ds.events) == N - 2


def test_textlog_a_500_m_truth_spike_is_flagged(tmp_path: Path) -> None:
    # one pose 500 m off for one sample: isolated, so flagged; the poses before and after it agree
    truth = [f"{k / 100!r} {k / 100 + (500.0 if k == 120 else 0.0)!r} 0 0 0 0 0 1\n" for k in range(N)]
    ds = load_textlog(_log(tmp_path / "log", truth=truth))
    (flag,) = ds.flagged
    assert (flag.line, flag.t, flag.stream, flag.quantity) == (2 + 120, 1.2, "truth", "apparent speed, m/s")
    assert len(ds.ground_truth) == N - 1 and float(np.max(ds.ground_truth.xy[:, 0])) < 3.0


def test_textlog_a_500_m_truth_jump_that_stays_is_refused_by_the_span_rule(tmp_path: Path) -> None:
    # from 1.2 s on the truth is 500 m away: every later pose is unreachable from the last accepted one, so the
    # flagged stretch runs to the end (1.79 s, 60 samples = 20 %): refused, naming the first line of the jump
    truth = [f"{k / 100!r} {k / 100 + (500.0 if k >= 120 else 0.0)!r} 0 0 0 0 0 1\n" for k in range(N)]
    folder = _log(tmp_path / "log", truth=truth)
    with pytest.raises(RecordedDataError) as info:
        load_textlog(folder)
    _one_line(info, f"{folder / 'truth.tum'}:122:", "truth samples break the plausibility bounds", "at most 1%")


def test_textlog_a_repeated_truth_time_with_another_pose_is_flagged(tmp_path: Path) -> None:
    truth = [f"{k / 100!r} {k / 100!r} 0 0 0 0 0 1\n" for k in range(N)]
    truth.insert(151, "1.5 1.52 0.01 0 0 0 0 1\n")  # a second pose at 1.5 s, 2 cm from the first
    ds = load_textlog(_log(tmp_path / "log", truth=truth))
    (flag,) = ds.flagged
    assert (flag.line, flag.t, flag.bound) == (153, 1.5, "one pose per time")
    assert flag.quantity == "time of the previous pose, s"
    assert len(ds.ground_truth) == N and np.all(np.diff(ds.ground_truth.t) > 0)


def test_textlog_a_key_given_twice_in_an_event_is_refused(tmp_path: Path) -> None:
    events = [_odo(k / 100) for k in range(1, N)]
    events[9] = '{"t": 0.1, "type": "odometry", "dx": 0.01, "dy": 0.0, "dtheta": 0.0, "dx": 5.0}\n'  # line 10
    folder = _log(tmp_path / "log", events=events)
    with pytest.raises(RecordedDataError) as info:
        load_textlog(folder)
    _one_line(info, f"{folder / 'events.jsonl'}:10:", "key 'dx' given twice in one object")


def test_textlog_a_kidnap_outside_the_recording_is_refused(tmp_path: Path) -> None:
    folder = _log(tmp_path / "log", manifest={"kidnaps": [{"t": 7.5, "delta": [1.0, 0.0, 0.0]}]})
    with pytest.raises(RecordedDataError) as info:
        load_textlog(folder)
    _one_line(info, str(folder / MANIFEST), "kidnaps[0].t is 7.5 s", "inside the recording [0.0, 2.99] s")


def test_textlog_a_truth_jump_at_a_kidnap_is_not_flagged(tmp_path: Path) -> None:
    truth = [f"{k / 100!r} {k / 100 + (2.0 if k >= 150 else 0.0)!r} 0 0 0 0 0 1\n" for k in range(N)]
    folder = _log(tmp_path / "log", truth=truth, manifest={"kidnaps": [{"t": 1.5, "delta": [2.0, 0.0, 0.0]}]})
    ds = load_textlog(folder)
    assert ds.flagged == () and len(ds.ground_truth) == N


def test_textlog_a_sighting_beyond_the_range_bound_is_flagged(tmp_path: Path) -> None:
    events = [_odo(k / 100) for k in range(1, N)]
    ranges = [
        json.dumps({"t": k / 100 + 0.005, "type": "ranges", "ids": [1], "ranges": [2000.0 if k == 50 else 3.0]}) + "\n"
        for k in range(1, N - 1)
    ]
    merged = [e for pair in zip(events, ranges, strict=False) for e in pair]
    folder = _log(tmp_path / "log", events=merged, manifest={"landmarks": "lm.csv"})
    (folder / "lm.csv").write_text("1 2.0 1.0\n")
    ds = load_textlog(folder)
    (flag,) = ds.flagged
    assert (flag.stream, flag.quantity, flag.value, flag.line) == ("ranges event", "range, m", 2000.0, 100)
