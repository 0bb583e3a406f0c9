"""One plausibility policy for every recorded loader: physical bounds per quantity, flagged samples, refusals.

A recording is real data: a motion-capture system loses a marker for 15 ms, a laser returns one absurd range, a
log repeats a line. The policy separates two kinds of trouble.

*Structural* problems make the file something other than what its format says (columns swapped, a key given twice,
every time equal, time going backwards): the loader refuses the file in one line naming the file, the line and the
expectation (:class:`~locbench.datasets.recorded.files.RecordedDataError`).

*Physical-bound* violations of single samples (a speed, a turn rate, a range, a variance, a heading magnitude, an
exact duplicate) are *flagged*: the sample is left out of what the filters and the metrics see, and recorded as a
:class:`~locbench.datasets.dataset.FlaggedSample` in :attr:`Dataset.flagged
<locbench.datasets.dataset.Dataset.flagged>`,
which the runner stores in the run's provenance and the report counts. A file is accepted with flags only while they
stay isolated: at most :data:`MAX_FLAGGED_FRACTION` of one quantity's samples in one file, and no stretch of
consecutive flagged samples longer than :data:`MAX_FLAGGED_SPAN_S`; beyond either it is refused, naming the first
flagged line and the bound.

The bounds in :data:`BOUNDS` hold for every loader. A loader may tighten one with its own platform's documented
limit (an iRobot Create's top speed, a scanner's maximum range), stated beside it; it never loosens one.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from locbench.core.geometry import wrap_angle
from locbench.datasets.dataset import FlaggedSample
from locbench.datasets.recorded.files import RecordedDataError

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

#: Largest share of one quantity's samples in one file that may be flagged before the file is refused (1 %).
MAX_FLAGGED_FRACTION = 0.01
#: Longest stretch of consecutive flagged samples, s (from the last accepted sample before it to the first after):
#: a glitch is isolated; a stretch longer than this is a broken recording, refused.
MAX_FLAGGED_SPAN_S = 2.0


@dataclass(frozen=True)
class Bounds:
    """Physical bounds of the quantities a recorded loader reads, one set for every loader.

    Attributes
    ----------
    speed_mps : float
        Largest ground speed of a robot, m/s (research platforms: Pioneer 1.2, Husky 1.0, iRobot Create 0.5).
    turn_rate_radps : float
        Largest yaw rate, rad/s.
    range_m : float
        Largest range a ranging sensor reports, m (2-D scanners: 80 m; UWB: a few hundred metres).
    variance_m2 : float
        Largest variance a recording may state for a range, m^2 (a 100 m standard deviation).
    heading_abs_rad : float
        Largest magnitude of a recorded heading before wrapping, rad (recordings wrap to (-pi, pi] or [0, 2 pi);
        a few turns of slack admit unwrapped logs).
    position_jitter_m : float
        Measurement noise allowed on top of ``speed_mps * dt`` between two pose samples, m.
    heading_jitter_rad : float
        Measurement noise allowed on top of ``turn_rate_radps * dt`` between two pose samples, rad.
    """

    speed_mps: float = 5.0
    turn_rate_radps: float = 10.0
    range_m: float = 1000.0
    variance_m2: float = 1.0e4
    heading_abs_rad: float = 8.0 * math.pi
    position_jitter_m: float = 0.05
    heading_jitter_rad: float = 0.1

    def tightened(self, **limits: float) -> Bounds:
        """These bounds with some made stricter (a platform's own limit); a looser value is refused."""
        for name, value in limits.items():
            if not value <= getattr(self, name):  # also NaN
                raise ValueError(f"bound {name}={value!r} loosens the policy's {getattr(self, name)!r}")
        return Bounds(**{**self.__dict__, **limits})


#: The policy's bounds.
BOUNDS = Bounds()


class Flags:
    """The flagged samples of one stream (one quantity's rows) of one file, and the refusal when they are too many.

    Parameters
    ----------
    path : path-like
        The file.
    what : str
        What a sample is, for messages ("ground-truth", "odometry", "UWB range").
    t : array of float, shape (n,)
        Each sample's time, s.
    lines : array of int, shape (n,), optional
        Each sample's 1-based line in the file (None: a binary format without lines).
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        what: str,
        t: npt.ArrayLike,
        lines: npt.ArrayLike | None = None,
    ) -> None:
        self.path = Path(path)
        self.what = what
        self.t = np.asarray(t, dtype=np.float64)
        self.lines = None if lines is None else np.asarray(lines, dtype=np.int64)
        self.mask: BoolArray = np.zeros(self.t.shape[0], dtype=bool)
        self._samples: list[FlaggedSample] = []

    @property
    def kept(self) -> BoolArray:
        """True where a sample is not flagged."""
        return ~self.mask

    def __len__(self) -> int:
        return int(self.mask.sum())

    def flag(self, bad: npt.ArrayLike, quantity: str, values: npt.ArrayLike, bound: str) -> None:
        """Flag the samples where ``bad`` is true (already flagged ones are not counted twice).

        Parameters
        ----------
        bad : array of bool, shape (n,)
        quantity : str
            The quantity and its unit ("speed, m/s").
        values : array of float, shape (n,)
            Each sample's value of the quantity (what the message quotes).
        bound : str
            The bound broken, in words ("at most 1.0 m/s plus 0.05 m").
        """
        new = np.asarray(bad, dtype=bool) & ~self.mask
        vals = np.broadcast_to(np.asarray(values, dtype=np.float64), self.mask.shape)
        for k in np.flatnonzero(new):
            line = None if self.lines is None else int(self.lines[k])
            self._samples.append(
                FlaggedSample(str(self.path), line, float(self.t[k]), self.what, quantity, float(vals[k]), bound)
            )
        self.mask |= new

    def flag_outside(self, values: npt.ArrayLike, quantity: str, lo: float, hi: float) -> None:
        """Flag the samples whose ``values`` lie outside [``lo``, ``hi``] or are not finite."""
        v = np.asarray(values, dtype=np.float64)
        with np.errstate(invalid="ignore"):
            bad = ~((v >= lo) & (v <= hi))
        self.flag(bad, quantity, v, f"in [{lo:g}, {hi:g}]")

    def flag_duplicates(self, rows: npt.ArrayLike, quantity: str = "a repeat of the previous sample") -> None:
        """Flag a sample equal in every column to the one before it (a doubled line): counted once, not twice."""
        n = self.t.shape[0]
        if n < 2:  # nothing to repeat (and an empty array has no row length to reshape by)
            return
        r = np.asarray(rows, dtype=np.float64).reshape(n, -1)
        dup = np.zeros(n, dtype=bool)
        dup[1:] = np.all(r[1:] == r[:-1], axis=1)
        self.flag(dup, quantity, self.t, "one sample per line")

    def flag_track(
        self,
        xy: npt.ArrayLike,
        theta: npt.ArrayLike | None = None,
        bounds: Bounds = BOUNDS,
        breaks: npt.ArrayLike = (),
        stamp_uncertainty_s: float = 0.0,
    ) -> None:
        """Flag the pose samples a robot could not have reached from the last accepted one.

        Sample ``k`` is accepted when, against the last accepted sample ``g``, it moved at most
        ``speed_mps * (t_k - t_g) + position_jitter_m`` and turned at most
        ``turn_rate_radps * (t_k - t_g) + heading_jitter_rad``; else it is flagged and ``g`` stays. Comparing with
        the last accepted sample (not the previous one) flags a glitch alone, not the good sample after it. Samples
        flagged before this call (a duplicate, a heading out of bounds) take no part: neither judged nor a reference.
        ``breaks`` are times (s) at which the pose may jump (a kidnap): the first sample at or after a break is
        accepted as the new reference. ``stamp_uncertainty_s`` is how far a recording's stamps may lie from the
        instant they describe, s (a log stamped when a message was delivered, in bursts): it is added to every
        ``t_k - t_g``, so the bounds judge the time that may really have passed.
        """
        idx = np.flatnonzero(~self.mask)
        p = np.asarray(xy, dtype=np.float64)[idx]
        th = None if theta is None else np.asarray(theta, dtype=np.float64)[idx]
        t = self.t[idx]
        if p.shape[0] < 2:
            return
        if not stamp_uncertainty_s >= 0.0:  # also NaN
            raise ValueError(f"stamp_uncertainty_s must be >= 0 s, got {stamp_uncertainty_s!r}")
        segment = np.searchsorted(np.sort(np.asarray(breaks, dtype=np.float64)), t, side="right")
        # One vectorised pass decides the common case (no violation at all) without the walk.
        dt = np.diff(t) + stamp_uncertainty_s
        step = np.hypot(np.diff(p[:, 0]), np.diff(p[:, 1]))
        fast = step > bounds.speed_mps * dt + bounds.position_jitter_m
        if th is not None:
            turn = np.abs(wrap_angle(np.diff(th)))
            fast |= turn > bounds.turn_rate_radps * dt + bounds.heading_jitter_rad
        fast &= segment[1:] == segment[:-1]
        if not fast.any():
            return
        bad = np.zeros(self.t.shape[0], dtype=bool)
        speed = np.zeros(self.t.shape[0])
        g = int(np.flatnonzero(fast)[0])  # every sample up to here passed the one-step check
        for k in range(g + 1, p.shape[0]):
            if segment[k] != segment[g]:
                g = k
                continue
            span = t[k] - t[g] + stamp_uncertainty_s
            moved = math.hypot(p[k, 0] - p[g, 0], p[k, 1] - p[g, 1])
            ok = moved <= bounds.speed_mps * span + bounds.position_jitter_m
            if ok and th is not None:
                turned = abs(math.remainder(th[k] - th[g], 2 * math.pi))
                ok = turned <= bounds.turn_rate_radps * span + bounds.heading_jitter_rad
            if ok:
                g = k
            else:
                bad[idx[k]] = True
                speed[idx[k]] = moved / span if span > 0 else math.inf
        bound = f"at most {bounds.speed_mps:g} m/s plus {bounds.position_jitter_m:g} m"
        if th is not None:
            bound += f" and {bounds.turn_rate_radps:g} rad/s plus {bounds.heading_jitter_rad:g} rad"
        if stamp_uncertainty_s:
            bound += f" over the time between stamps plus {stamp_uncertainty_s:g} s of stamp uncertainty"
        self.flag(bad, "apparent speed, m/s", speed, bound)

    def flag_increments(
        self, moved_m: npt.ArrayLike, turned_rad: npt.ArrayLike, dt_s: npt.ArrayLike, bounds: Bounds = BOUNDS
    ) -> None:
        """Flag odometry increments faster than the bounds allow over their interval (plus the jitter)."""
        d = np.abs(np.asarray(moved_m, dtype=np.float64))
        a = np.abs(np.asarray(turned_rad, dtype=np.float64))
        dt = np.asarray(dt_s, dtype=np.float64)
        with np.errstate(invalid="ignore"):
            bad = ~(
                (d <= bounds.speed_mps * dt + bounds.position_jitter_m)
                & (a <= bounds.turn_rate_radps * dt + bounds.heading_jitter_rad)
            )
            rate = np.where(dt > 0, d / np.where(dt > 0, dt, 1.0), np.inf)
        self.flag(
            bad,
            "odometry speed, m/s",
            rate,
            f"at most {bounds.speed_mps:g} m/s plus {bounds.position_jitter_m:g} m and "
            f"{bounds.turn_rate_radps:g} rad/s plus {bounds.heading_jitter_rad:g} rad",
        )

    def finish(self) -> tuple[FlaggedSample, ...]:
        """The flagged samples, after refusing a stream whose flags are not isolated.

        Raises
        ------
        RecordedDataError
            More than :data:`MAX_FLAGGED_FRACTION` of the samples flagged, or a stretch of consecutive flagged
            samples longer than :data:`MAX_FLAGGED_SPAN_S`; the message names the first flagged line and its bound.
        """
        n = self.t.shape[0]
        if not self._samples:
            return ()
        first = min(self._samples, key=lambda s: (s.t, s.line or 0))
        count = len(self._samples)
        if count > MAX_FLAGGED_FRACTION * n:
            raise RecordedDataError(
                self.path,
                f"{count} of {n} {self.what} samples break the plausibility bounds, expected at most "
                f"{MAX_FLAGGED_FRACTION:.0%} (locbench.datasets.recorded.plausibility); the first: {first.describe()}",
                first.line,
            )
        span, start = _longest_flagged_span(self.t, self.mask)
        if span > MAX_FLAGGED_SPAN_S:
            at = next(s for s in sorted(self._samples, key=lambda s: s.t) if s.t >= self.t[start])
            raise RecordedDataError(
                self.path,
                f"{self.what} samples break the plausibility bounds for {span:.3g} s in a row, expected isolated "
                f"glitches of at most {MAX_FLAGGED_SPAN_S:g} s; the first: {at.describe()}",
                at.line,
            )
        return tuple(sorted(self._samples, key=lambda s: (s.t, s.line or 0)))


def _longest_flagged_span(t: FloatArray, mask: BoolArray) -> tuple[float, int]:
    """Longest time from the accepted sample before a flagged stretch to the accepted one after it, s, and the
    stretch's first index (a stretch at either end is measured to the first or last sample)."""
    best, best_start = 0.0, 0
    n = t.shape[0]
    k = 0
    while k < n:
        if not mask[k]:
            k += 1
            continue
        j = k
        while j < n and mask[j]:
            j += 1
        lo = t[k - 1] if k > 0 else t[k]
        hi = t[j] if j < n else t[j - 1]
        if hi - lo > best:
            best, best_start = float(hi - lo), k
        k = j
    return best, best_start


def refuse_all_times_equal(path: str | os.PathLike[str], what: str, t: npt.ArrayLike, line: int | None = None) -> None:
    """Refuse a stream of two or more samples whose times are all equal (a structural error: no clock)."""
    a = np.asarray(t, dtype=np.float64)
    if a.shape[0] > 1 and np.all(a == a[0]):
        raise RecordedDataError(
            path, f"every {what} sample has the time {float(a[0])!r}, expected times that advance", line
        )


def merge(*groups: Iterable[FlaggedSample]) -> tuple[FlaggedSample, ...]:
    """The flagged samples of several streams in time order."""
    return tuple(sorted((s for g in groups for s in g), key=lambda s: (s.t, s.source, s.line or 0)))
