"""The events file of the ``locbench-textlog`` format: one JSON object per line, read and written.

Read by the textlog loader (:mod:`~locbench.datasets.recorded.textlog`, whose docstring and docs/datasets.md section 8
specify the format) and by the bag loader for its ``events`` sidecar (:mod:`~locbench.datasets.recorded.rosbag`);
:func:`event_object` writes one event as the reader reads it back.

Each line is an object with ``t`` (s) and ``type``: ``odometry`` (dx, dy, dtheta in the previous robot frame,
optional wheel travel and twist; or a twist alone), ``scan``, ``landmarks`` (range-bearing sightings), ``ranges``
(range-only, to beacons) and ``fix`` (a position or pose fix). Every number is read as the float64 it names.

Validation: the file is a regular file of at most :data:`MAX_EVENTS_BYTES`
(:func:`~locbench.core.limits.check_input_file`), each line at most :data:`MAX_LINE_CHARS` long; every error is one
line naming the file, the 1-based line, the field and what was expected
(:class:`~locbench.datasets.recorded.files.RecordedDataError`). Bounds: times finite within +-:data:`MAX_TIME_S`
and non-decreasing in file order; increments within :data:`MAX_STEP_M` and 2 pi; twists within :data:`MAX_TWIST`,
``dt`` in (0, :data:`MAX_DT_S`]; positions within :data:`~locbench.datasets.recorded.files.MAX_POSITION_M`; scans
as a bag's (:func:`~locbench.datasets.recorded.files.scan_problem`) with at most
:data:`~locbench.core.limits.MAX_LASER_BEAMS` beams; at most :data:`MAX_ITEMS` sightings or ranges per event, ids
-1 (unknown) or in the landmark file; fix covariances symmetric PSD; no unknown field and no key given twice in one
object (:func:`no_duplicate_keys`; JSON's NaN and Infinity and integers of more than 18 digits are refused,
:func:`json_hooks`); not every event at one time.

Plausibility (:mod:`~locbench.datasets.recorded.plausibility`, the policy's
:data:`~locbench.datasets.recorded.plausibility.BOUNDS`): these events are flagged, left out and listed (a stream
with more than 1 % of them, or a 2 s stretch, is refused): a line that repeats the previous one exactly (a doubled
line: counted once); an odometry increment faster than the speed or turn-rate bound over its interval (``dt``, else
the time since the previous odometry event), or a twist beyond them; a sighting or range event with a range outside
[0, range bound] or a bearing beyond the heading bound; a fix whose position variance exceeds the variance bound.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from locbench.core.events import (
    UNKNOWN_ID,
    Event,
    LandmarkObservations,
    LaserScan,
    Odometry,
    PoseFix,
    RangeObservations,
)
from locbench.core.geometry import is_symmetric_psd, twist_increment
from locbench.core.limits import MAX_LASER_BEAMS, check_input_file
from locbench.datasets.dataset import FlaggedSample
from locbench.datasets.recorded import plausibility
from locbench.datasets.recorded.files import (
    MAX_INTEGER_FIELD,
    MAX_POSITION_M,
    MAX_SCAN_RANGE_M,
    RecordedDataError,
    quote,
    scan_problem,
)

FloatArray = npt.NDArray[np.float64]

#: Largest events file, bytes. Parsed events take about the text's size in memory (a float64 per number), so the
#: bound keeps a run within the 1 GB budget.
MAX_EVENTS_BYTES = 512 << 20
#: Longest line of the events file, characters (a 10 000-beam scan is about 200 000).
MAX_LINE_CHARS = 1 << 20
#: Bounds of the events: time (s), increment (m), twist (m/s, rad/s), twist duration (s), items per event.
MAX_TIME_S = 1.0e10
MAX_STEP_M = 100.0
MAX_TWIST = 100.0
MAX_DT_S = 60.0
MAX_ITEMS = 10_000


# --- strict JSON ---------------------------------------------------------------------------------


def no_duplicate_keys(path: Path) -> Callable[[list[tuple[str, Any]]], dict[str, Any]]:
    def hook(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for k, v in pairs:
            if k in out:
                raise RecordedDataError(path, f"key {quote(k, 60)} given twice in one object, expected each once")
            out[k] = v
        return out

    return hook


def _refuse_constant(path: Path) -> Callable[[str], Any]:
    def hook(name: str) -> Any:
        raise RecordedDataError(path, f"{name} is not a JSON number, expected a finite number")

    return hook


def json_hooks(path: Path) -> tuple[Callable[[str], int], Callable[[str], Any]]:
    """``json`` hooks that refuse NaN and Infinity and keep integers small (so no float conversion overflows); a
    float beyond float64 (1e999) reads as inf and is refused by the field checks. Floats stay with the C parser."""

    def parse_int(text: str) -> int:
        if len(text.lstrip("-")) > 18:
            raise RecordedDataError(path, f"integer {quote(text, 40)} has more than 18 digits, expected a smaller one")
        return int(text)

    return parse_int, _refuse_constant(path)


def is_number(v: Any) -> bool:
    """A finite JSON number (bool is an int subclass: a true is no number; 1e999 reads as inf)."""
    return type(v) is int or (type(v) is float and math.isfinite(v))


_NUMBER_TYPES = frozenset({float, int})
_NUMBER_OR_NULL_TYPES = frozenset({float, int, type(None)})


# --- reading ------------------------------------------------------------------------------------


class _Line:
    """One events line being read: its fields, and errors that name the file, the line and the field."""

    __slots__ = ("kind", "lineno", "obj", "path")

    def __init__(self, path: Path, lineno: int, obj: dict[str, Any], kind: str) -> None:
        self.path, self.lineno, self.obj, self.kind = path, lineno, obj, kind

    def fail(self, key: str, message: str) -> RecordedDataError:
        return RecordedDataError(self.path, f"{self.kind} event field {key!r}: {message}", self.lineno)

    def number(self, key: str, lo: float, hi: float, unit: str) -> float:
        if key not in self.obj:
            raise self.fail(key, f"missing, expected a number ({unit})")
        v = self.obj[key]
        if not is_number(v) or not (lo <= float(v) <= hi):
            raise self.fail(key, f"is {quote(v, 60)}, expected a number in [{lo:.6g}, {hi:.6g}] {unit}")
        return float(v)

    def optional(self, key: str, lo: float, hi: float, unit: str) -> float | None:
        return self.number(key, lo, hi, unit) if self.obj.get(key) is not None else None

    def array(self, key: str, lo: float, hi: float, unit: str, limit: int, nulls: bool = False) -> FloatArray:
        """A list of numbers (``null`` -> inf when ``nulls``), each within [lo, hi]."""
        v = self.obj.get(key)
        if not isinstance(v, list):
            raise self.fail(key, f"is {quote(v, 60)}, expected a list of numbers ({unit})")
        if len(v) > limit:
            raise self.fail(key, f"has {len(v)} values, expected at most {limit}")
        if not set(map(type, v)) <= (_NUMBER_OR_NULL_TYPES if nulls else _NUMBER_TYPES):
            k = next(i for i, x in enumerate(v) if not (type(x) in _NUMBER_TYPES or (nulls and x is None)))
            raise self.fail(key, f"item {k} is {quote(v[k], 60)}, expected a number ({unit})")
        a = np.array(v, dtype=np.float64)  # null -> NaN (JSON itself has no NaN: parse_constant refuses it)
        null = np.isnan(a) if nulls else np.zeros(a.shape, dtype=bool)
        with np.errstate(invalid="ignore"):
            bad = np.flatnonzero(~(np.isfinite(a) & (a >= lo) & (a <= hi)) & ~null)
        if bad.size:
            k = int(bad[0])
            raise self.fail(
                key, f"item {k} is {quote(v[k], 60)}, expected a finite number in [{lo:.6g}, {hi:.6g}] {unit}"
            )
        a[null] = math.inf  # no return
        return a

    def ids(self, n: int, known: frozenset[int] | None) -> npt.NDArray[np.int64]:
        v = self.obj.get("ids")
        if not (isinstance(v, list) and all(type(x) is int for x in v)):
            raise self.fail("ids", f"is {quote(v, 80)}, expected a list of integer ids (-1 = unknown identity)")
        if len(v) != n:
            raise self.fail("ids", f"has {len(v)} ids for {n} measurements, expected one id per measurement")
        for x in v:
            if x != UNKNOWN_ID and not (0 <= x <= MAX_INTEGER_FIELD and (known is None or x in known)):
                where = "in the landmark file" if known is not None else f"in [0, {MAX_INTEGER_FIELD}]"
                raise self.fail("ids", f"id {x} is not a known landmark, expected -1 (unknown) or an id {where}")
        return np.array(v, dtype=np.int64)


_EVENT_KEYS = {
    "odometry": ("dx", "dy", "dtheta", "d_left", "d_right", "v", "omega", "dt"),
    "scan": ("angle_min", "angle_increment", "range_min", "range_max", "ranges", "sensor_pose"),
    "landmarks": ("ids", "ranges", "bearings"),
    "ranges": ("ids", "ranges"),
    "fix": ("z", "cov", "sigma"),
}


def _odometry(ln: _Line, t: float, last_odometry_t: float | None) -> Odometry:
    inc = ("dx", "dy", "dtheta")
    given = [k in ln.obj for k in inc]
    v = ln.optional("v", -MAX_TWIST, MAX_TWIST, "m/s")
    omega = ln.optional("omega", -MAX_TWIST, MAX_TWIST, "rad/s")
    dt = ln.optional("dt", 1e-12, MAX_DT_S, "s (> 0)")
    if (v is None) != (omega is None):
        raise ln.fail("omega" if omega is None else "v", "missing, expected v and omega together (a twist)")
    if all(given):
        dx, dy = ln.number("dx", -MAX_STEP_M, MAX_STEP_M, "m"), ln.number("dy", -MAX_STEP_M, MAX_STEP_M, "m")
        dth = ln.number("dtheta", -math.tau, math.tau, "rad")
    elif any(given):
        missing = next(k for k, g in zip(inc, given, strict=True) if not g)
        raise ln.fail(missing, "missing, expected dx, dy and dtheta together (an increment)")
    elif v is None or omega is None:
        raise ln.fail("dx", "missing, expected an increment (dx, dy, dtheta) or a twist (v, omega)")
    else:
        if dt is None:
            if last_odometry_t is None or not t > last_odometry_t:
                raise ln.fail("dt", "missing on a twist-only event with no earlier odometry time to measure it from")
            dt = t - last_odometry_t
        sx, sy, sa = twist_increment(v, omega, dt)
        dx, dy, dth = float(sx), float(sy), float(sa)
    d_left = ln.optional("d_left", -MAX_STEP_M, MAX_STEP_M, "m")
    d_right = ln.optional("d_right", -MAX_STEP_M, MAX_STEP_M, "m")
    if (d_left is None) != (d_right is None):
        raise ln.fail("d_right" if d_right is None else "d_left", "missing, expected d_left and d_right together")
    return Odometry(t, dx, dy, dth, d_left, d_right, v, omega, dt)


def _scan(ln: _Line, t: float, default_pose: tuple[float, float, float]) -> LaserScan:
    a0 = ln.number("angle_min", -math.tau, math.tau, "rad")
    inc = ln.number("angle_increment", -math.tau, math.tau, "rad")
    rmin = ln.number("range_min", 0.0, MAX_SCAN_RANGE_M, "m")
    rmax = ln.number("range_max", 0.0, MAX_SCAN_RANGE_M, "m")
    r = ln.array("ranges", -math.inf, math.inf, "m, null = no return", MAX_LASER_BEAMS, nulls=True)
    problem = scan_problem(int(r.shape[0]), a0, inc, rmin, rmax)
    if problem is not None:
        raise RecordedDataError(ln.path, f"scan event: {problem}", ln.lineno)
    with np.errstate(invalid="ignore"):
        r[(r < rmin) | (r > rmax)] = math.inf  # outside the valid interval: no return (REP 117)
    pose = default_pose
    if "sensor_pose" in ln.obj:
        p = ln.array("sensor_pose", -MAX_STEP_M, MAX_STEP_M, "m, m, rad", 3)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ln.fail("sensor_pose", f"is {quote(ln.obj['sensor_pose'], 60)}, expected [x m, y m, theta rad]")
        pose = (float(p[0]), float(p[1]), float(p[2]))
    r.setflags(write=False)
    return LaserScan(t, a0, inc, r, rmin, rmax, pose)


def _fix(ln: _Line, t: float) -> PoseFix:
    z = ln.array("z", -MAX_POSITION_M, MAX_POSITION_M, "m, m[, rad]", 3)
    n = int(z.shape[0])
    if n not in (2, 3) or not np.all(np.isfinite(z)):
        raise ln.fail("z", f"is {quote(ln.obj.get('z'), 60)}, expected [x, y] (m) or [x, y, theta] (m, m, rad)")
    if ("cov" in ln.obj) == ("sigma" in ln.obj):
        raise ln.fail("cov", "expected either 'cov' (an n x n matrix) or 'sigma' (n standard deviations)")
    if "sigma" in ln.obj:
        s = ln.array("sigma", 0.0, MAX_POSITION_M, "m[, rad]", 3)
        if s.shape != (n,):
            raise ln.fail("sigma", f"has {s.shape[0]} values, expected {n} (one per component of z)")
        cov = np.diag(s * s)
    else:
        rows = ln.obj["cov"]
        if not (isinstance(rows, list) and len(rows) == n and all(isinstance(r, list) for r in rows)):
            raise ln.fail("cov", f"is {quote(rows, 80)}, expected {n} rows of {n} numbers")
        for r in rows:
            if not (len(r) == n and all(is_number(x) for x in r)):
                raise ln.fail("cov", f"row {quote(r, 80)}, expected {n} numbers")
        cov = np.array(rows, dtype=np.float64)
        if not is_symmetric_psd(cov):
            raise ln.fail("cov", f"is {quote(rows, 120)}, expected a symmetric positive semi-definite matrix")
    z.setflags(write=False)
    cov.setflags(write=False)
    return PoseFix(t, z, cov)


def _event(ln: _Line, t: float, ctx: _Context) -> Event:
    kind = ln.kind
    if kind == "odometry":
        ev: Event = _odometry(ln, t, ctx.last_odometry_t)
        ctx.last_odometry_t = t
        return ev
    if kind == "scan":
        return _scan(ln, t, ctx.scan_pose)
    if kind == "fix":
        return _fix(ln, t)
    # a range outside [0, the range bound] or a bearing beyond 2 pi is flagged (_flag_events), not refused
    r = ln.array("ranges", -MAX_POSITION_M, MAX_POSITION_M, "m", MAX_ITEMS)
    ids = ln.ids(int(r.shape[0]), ctx.landmark_ids)
    r.setflags(write=False)
    ids.setflags(write=False)
    if kind == "ranges":
        return RangeObservations(t, ids, r)
    b = ln.array("bearings", -MAX_POSITION_M, MAX_POSITION_M, "rad", MAX_ITEMS)
    if b.shape != r.shape:
        raise ln.fail("bearings", f"has {b.shape[0]} values for {r.shape[0]} ranges, expected one per range")
    b.setflags(write=False)
    return LandmarkObservations(t, ids, r, b)


@dataclass
class _Context:
    landmark_ids: frozenset[int] | None
    scan_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)
    last_odometry_t: float | None = None


def read_events(path: str | os.PathLike[str], landmark_ids: frozenset[int] | None = None) -> tuple[Event, ...]:
    """The events of a textlog events file without the flagged ones (:func:`read_events_flagged`)."""
    return read_events_flagged(path, landmark_ids)[0]


def _json_objects(p: Path, decoder: json.JSONDecoder) -> Iterator[tuple[int, dict[str, Any]]]:
    """Each event line of a textlog events file as (1-based line, decoded object); blank and ``#`` lines skipped.

    Raises
    ------
    RecordedDataError
        Naming the line: not UTF-8, longer than :data:`MAX_LINE_CHARS`, a last line without its line end, not
        JSON, a key given twice, nested too deeply, or not a JSON object.
    """
    with open(p, encoding="utf-8", newline="") as fh:
        lineno = 0
        while True:
            try:
                raw = fh.readline(MAX_LINE_CHARS + 1)
            except UnicodeDecodeError:
                raise RecordedDataError(p, "not UTF-8 text, expected JSON lines", lineno + 1) from None
            if not raw:
                return
            lineno += 1
            if len(raw) > MAX_LINE_CHARS:
                raise RecordedDataError(p, f"line longer than {MAX_LINE_CHARS} characters, expected one event", lineno)
            text = raw.strip()
            if not text or text.startswith("#"):
                continue
            if not raw.endswith("\n"):
                raise RecordedDataError(
                    p,
                    "truncated line: the last line has no line end (expected a complete event ending in a newline)",
                    lineno,
                )
            try:
                obj = decoder.decode(text)
            except json.JSONDecodeError as exc:
                raise RecordedDataError(
                    p, f"not JSON ({exc.msg} at column {exc.colno}), expected an event object", lineno
                ) from None
            except RecordedDataError as exc:
                raise RecordedDataError(p, str(exc).split(": ", 1)[-1], lineno) from None
            except RecursionError:
                raise RecordedDataError(p, "JSON nested too deeply, expected a flat event object", lineno) from None
            if not isinstance(obj, dict):
                raise RecordedDataError(p, f"a JSON {type(obj).__name__}, expected an event object", lineno)
            yield lineno, obj


def read_events_flagged(
    path: str | os.PathLike[str], landmark_ids: frozenset[int] | None = None
) -> tuple[tuple[Event, ...], tuple[FlaggedSample, ...]]:
    """Parse a textlog events file (JSON lines) into events, in file order, and the events flagged and left out.

    Parameters
    ----------
    path : path-like
        The file: one JSON object per line; blank lines and lines starting with ``#`` are skipped.
    landmark_ids : frozenset of int or None
        The landmark map's ids: a sighting or range of another id (except -1, unknown) is an error. None accepts
        any id in [0, 2^31 - 1].

    Returns
    -------
    events : tuple of Event
        The accepted events.
    flagged : tuple of FlaggedSample
        The events that broke a plausibility bound (see the module docstring), in time order.

    Raises
    ------
    RecordedDataError
        Naming the line and the field: not a JSON object, an unknown type or field, a key given twice, a missing or
        out-of-bounds value, time going backwards, every event at one time, a line longer than
        :data:`MAX_LINE_CHARS`, a last line without its line end; or too many flagged events of one type.
    """
    p = Path(path)
    check_input_file(p, "textlog events file", MAX_EVENTS_BYTES)
    ctx = _Context(landmark_ids)
    out: list[Event] = []
    lines: list[int] = []
    repeats: list[bool] = []
    previous: Any = None
    last_t = -math.inf
    hooks = json_hooks(p)
    decoder = json.JSONDecoder(object_pairs_hook=no_duplicate_keys(p), parse_int=hooks[0], parse_constant=hooks[1])
    for lineno, obj in _json_objects(p, decoder):
        if out and obj == previous:  # a doubled line: the same event once more (flagged below)
            out.append(out[-1])
            lines.append(lineno)
            repeats.append(True)
            continue
        previous = obj
        kind = obj.get("type")
        if kind not in _EVENT_KEYS:
            raise RecordedDataError(
                p, f"field 'type' is {quote(kind, 60)}, expected one of {', '.join(_EVENT_KEYS)}", lineno
            )
        ln = _Line(p, lineno, obj, kind)
        for k in obj:
            if k not in ("t", "type") and k not in _EVENT_KEYS[kind]:
                raise ln.fail(k, f"unknown field, expected t, type, {', '.join(_EVENT_KEYS[kind])}")
        t = ln.number("t", -MAX_TIME_S, MAX_TIME_S, "s")
        if t < last_t:
            raise ln.fail("t", f"is {t!r}, before the previous event's {last_t!r} (expected events in time order)")
        last_t = t
        out.append(_event(ln, t, ctx))
        lines.append(lineno)
        repeats.append(False)
    if len(out) > 1:
        plausibility.refuse_all_times_equal(p, "event", [e.t for e in out], lines[1])
    return _flag_events(p, out, np.array(lines, dtype=np.int64), np.array(repeats, dtype=bool))


_KIND_OF = {Odometry: "odometry", LaserScan: "scan", LandmarkObservations: "landmarks", RangeObservations: "ranges"}


def _flag_events(
    p: Path, events: list[Event], lines: npt.NDArray[np.int64], repeats: npt.NDArray[np.bool_]
) -> tuple[tuple[Event, ...], tuple[FlaggedSample, ...]]:
    """The events without those breaking the plausibility bounds, and those, per event type (module docstring)."""
    b = plausibility.BOUNDS
    kinds = np.array([_KIND_OF.get(type(e), "fix") for e in events])
    t = np.array([e.t for e in events], dtype=np.float64)
    keep = np.ones(len(events), dtype=bool)
    found = []
    for kind in _EVENT_KEYS:
        at = np.flatnonzero(kinds == kind)
        if not at.size:
            continue
        of = [events[i] for i in at]
        flags = plausibility.Flags(p, f"{kind} event", t[at], lines[at])
        flags.flag(repeats[at], "a repeat of the previous line", t[at], "one event per line")
        if kind == "odometry":
            _flag_odometry(flags, of, b)
        elif kind in ("landmarks", "ranges"):
            worst = np.array([_worst(np.asarray(e.ranges), 0.0, b.range_m) for e in of])  # type: ignore[union-attr]
            flags.flag_outside(worst, "range, m", 0.0, b.range_m)
            if kind == "landmarks":
                worst = np.array([_worst(np.asarray(e.bearings), -math.tau, math.tau) for e in of])  # type: ignore[union-attr]
                flags.flag_outside(worst, "bearing, rad", -math.tau, math.tau)
        elif kind == "fix":
            var = np.array([float(np.max(np.diag(e.cov)[:2])) for e in of])  # type: ignore[union-attr]
            flags.flag_outside(var, "position variance, m^2", 0.0, b.variance_m2)
        keep[at[flags.mask]] = False
        found.append(flags.finish())
    return tuple(e for e, k in zip(events, keep.tolist(), strict=True) if k), plausibility.merge(*found)


def _worst(a: FloatArray, lo: float, hi: float) -> float:
    """The value of ``a`` farthest outside [lo, hi] (its first value when all lie inside; lo when empty)."""
    if a.size == 0:
        return lo
    out = np.maximum(lo - a, a - hi)
    return float(a[int(np.argmax(out))])


def _flag_odometry(flags: plausibility.Flags, events: list[Event], b: plausibility.Bounds) -> None:
    """Flag odometry increments faster than the bounds over their interval, and twists beyond them."""
    odo = [e for e in events if isinstance(e, Odometry)]
    t = np.array([e.t for e in odo], dtype=np.float64)
    # the interval of an increment: its dt, else the time since the previous odometry event (unknown for the first)
    since = np.r_[math.inf, np.diff(t)]
    dt = np.array([e.dt if e.dt is not None else since[i] for i, e in enumerate(odo)], dtype=np.float64)
    inc = np.array([(e.dx, e.dy, e.dtheta) for e in odo], dtype=np.float64).reshape(-1, 3)
    flags.flag_increments(np.hypot(inc[:, 0], inc[:, 1]), inc[:, 2], dt, b)
    v = np.array([0.0 if e.v is None else e.v for e in odo], dtype=np.float64)
    omega = np.array([0.0 if e.omega is None else e.omega for e in odo], dtype=np.float64)
    flags.flag_outside(v, "twist speed, m/s", -b.speed_mps, b.speed_mps)
    flags.flag_outside(omega, "twist turn rate, rad/s", -b.turn_rate_radps, b.turn_rate_radps)


# --- writing ------------------------------------------------------------------------------------


def event_object(e: Event) -> dict[str, Any]:
    """The JSON object of one event (floats as themselves: ``json`` writes ``repr``, the shortest exact text)."""
    if isinstance(e, Odometry):
        obj: dict[str, Any] = {"t": e.t, "type": "odometry", "dx": e.dx, "dy": e.dy, "dtheta": e.dtheta}
        for k in ("d_left", "d_right", "v", "omega", "dt"):
            if getattr(e, k) is not None:
                obj[k] = float(getattr(e, k))
        return obj
    if isinstance(e, LaserScan):
        obj = {
            "t": e.t,
            "type": "scan",
            "angle_min": e.angle_min,
            "angle_increment": e.angle_increment,
            "range_min": e.range_min,
            "range_max": e.range_max,
            "ranges": [x if math.isfinite(x) else None for x in e.ranges.tolist()],
        }
        if tuple(e.sensor_pose) != (0.0, 0.0, 0.0):
            obj["sensor_pose"] = [float(v) for v in e.sensor_pose]
        return obj
    if isinstance(e, LandmarkObservations):
        return {
            "t": e.t,
            "type": "landmarks",
            "ids": [int(i) for i in e.ids],
            "ranges": e.ranges.tolist(),
            "bearings": e.bearings.tolist(),
        }
    if isinstance(e, RangeObservations):
        return {"t": e.t, "type": "ranges", "ids": [int(i) for i in e.ids], "ranges": e.ranges.tolist()}
    return {"t": e.t, "type": "fix", "z": e.z.tolist(), "cov": e.cov.tolist()}
