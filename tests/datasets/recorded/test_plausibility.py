"""The plausibility policy of the recorded loaders: bounds, flags, and the refusal of flags that are not isolated."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from locbench.datasets.recorded.files import RecordedDataError
from locbench.datasets.recorded.plausibility import (
    BOUNDS,
    MAX_FLAGGED_FRACTION,
    MAX_FLAGGED_SPAN_S,
    Bounds,
    Flags,
    merge,
    refuse_all_times_equal,
)

PATH = Path("/data/run.txt")


def _flags(n: int, dt: float = 0.1) -> Flags:
    return Flags(PATH, "pose", np.arange(n) * dt, np.arange(n) + 1)


def test_bounds_tighten_but_never_loosen() -> None:
    b = BOUNDS.tightened(speed_mps=1.0)
    assert b.speed_mps == 1.0 and b.turn_rate_radps == BOUNDS.turn_rate_radps
    with pytest.raises(ValueError, match="loosens"):
        BOUNDS.tightened(range_m=BOUNDS.range_m * 2)
    with pytest.raises(ValueError, match="loosens"):
        BOUNDS.tightened(speed_mps=math.nan)
    assert Bounds() == BOUNDS


def test_flag_outside_flags_out_of_range_and_non_finite_values_once() -> None:
    f = _flags(200)
    v = np.zeros(200)
    v[[3, 7]] = [2.0, math.nan]
    f.flag_outside(v, "range, m", 0.0, 1.0)
    f.flag_outside(v, "range, m", 0.0, 1.0)  # again: not counted twice
    assert len(f) == 2 and f.kept.sum() == 198
    s3, s7 = f.finish()
    assert (s3.line, s3.t, s3.value, s3.bound) == (4, 0.30000000000000004, 2.0, "in [0, 1]")
    assert s7.line == 8 and math.isnan(s7.value)


def test_flag_duplicates_flags_the_repeat_only_and_takes_empty_streams() -> None:
    f = _flags(200)
    rows = np.column_stack([f.t, np.arange(200.0)])
    rows[51] = rows[50]
    f.flag_duplicates(rows)
    assert np.flatnonzero(f.mask).tolist() == [51]
    empty = Flags(PATH, "pose", np.zeros(0))
    empty.flag_duplicates(np.zeros((0, 3)))
    assert empty.finish() == ()


def test_flag_track_flags_a_glitch_alone_and_restarts_at_a_break() -> None:
    f = _flags(300, dt=0.01)
    xy = np.column_stack([0.5 * f.t, np.zeros(300)])
    th = np.zeros(300)
    xy[100, 0] += 0.2  # 20 cm off for one sample
    th[200] = 1.0  # a 1 rad heading spike
    f.flag_track(xy, th, BOUNDS.tightened(speed_mps=1.0))
    assert np.flatnonzero(f.mask).tolist() == [100, 200]
    assert f.finish()[0].quantity == "apparent speed, m/s"
    # a jump that stays is one flagged stretch; at a break the track restarts instead
    g = _flags(300, dt=0.01)
    xy2 = np.column_stack([0.5 * g.t + np.where(g.t >= 1.5, 10.0, 0.0), np.zeros(300)])
    g.flag_track(xy2)
    assert g.mask[150:].all() and not g.mask[:150].any()
    h = _flags(300, dt=0.01)
    h.flag_track(xy2, breaks=[1.5])
    assert not h.mask.any()


def test_flag_track_skips_samples_already_flagged() -> None:
    f = _flags(300, dt=0.01)
    xy = np.column_stack([0.5 * f.t, np.zeros(300)])
    xy[100, 0] = 50.0
    f.flag(np.arange(300) == 100, "heading, rad", 9.0, "in [-6.283, 6.283]")
    f.flag_track(xy)
    (only,) = f.finish()
    assert only.quantity == "heading, rad"  # the far sample is neither judged again nor a reference


def test_flag_increments_uses_each_interval() -> None:
    f = _flags(200)
    moved = np.full(200, 0.1)
    turned = np.zeros(200)
    dt = np.full(200, 0.1)
    turned[10] = 2 * math.pi  # a full turn in 0.1 s
    moved[20] = 5.0  # 50 m/s
    dt[30], moved[30] = math.inf, 5.0  # unknown interval: nothing to hold it to
    f.flag_increments(moved, turned, dt)
    assert np.flatnonzero(f.mask).tolist() == [10, 20]


def test_more_than_1_percent_is_refused_naming_the_first_line() -> None:
    n = 300
    f = _flags(n)
    bad = np.zeros(n, dtype=bool)
    bad[[40, 90, 140]] = True  # exactly 1 %
    f.flag(bad, "speed, m/s", 9.0, "at most 5 m/s")
    assert len(f.finish()) == 3 and MAX_FLAGGED_FRACTION * n >= 3
    bad[200] = True
    f.flag(bad, "speed, m/s", 9.0, "at most 5 m/s")
    with pytest.raises(RecordedDataError) as info:
        f.finish()
    msg = str(info.value)
    assert f"{PATH}:41:" in msg and "4 of 300 pose samples" in msg and "at most 1%" in msg and "\n" not in msg


def test_a_stretch_longer_than_2_s_is_refused_naming_its_first_line() -> None:
    f = _flags(3000, dt=0.1)
    bad = np.zeros(3000, dtype=bool)
    bad[1000:1020] = True  # 2.1 s from the accepted sample before to the one after
    f.flag(bad, "speed, m/s", 9.0, "at most 5 m/s")
    with pytest.raises(RecordedDataError) as info:
        f.finish()
    assert f"{PATH}:1001:" in str(info.value) and f"at most {MAX_FLAGGED_SPAN_S:g} s" in str(info.value)
    g = _flags(3000, dt=0.1)
    bad[1019] = False  # 2.0 s: still a glitch
    g.flag(bad, "speed, m/s", 9.0, "at most 5 m/s")
    assert len(g.finish()) == 19


def test_all_times_equal_is_structural() -> None:
    refuse_all_times_equal(PATH, "event", [0.0])  # one sample: nothing to compare
    refuse_all_times_equal(PATH, "event", [0.0, 0.0, 1.0])
    with pytest.raises(RecordedDataError, match=r"run.txt:2: every event sample has the time 0.0"):
        refuse_all_times_equal(PATH, "event", [0.0, 0.0, 0.0], 2)


def test_merge_orders_by_time() -> None:
    a, b = _flags(200), _flags(200)
    a.flag(np.arange(200) == 50, "x", 1.0, "y")
    b.flag(np.arange(200) == 10, "x", 1.0, "y")
    assert [s.line for s in merge(a.finish(), b.finish())] == [11, 51]
