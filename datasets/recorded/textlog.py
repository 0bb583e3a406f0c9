"""Users' own logs in plain text: the ``locbench-textlog`` format (version 1), read as ``textlog[path=FOLDER]``.

A textlog is a folder (docs/datasets.md, section 8, is the full specification; this is its summary):

- ``textlog.json``: the manifest, a JSON object with ``"format": "locbench-textlog"`` and ``"version": 1``, the
  file names below, the nominal noise (``sensors``: fields of :class:`~locbench.datasets.dataset.SensorSpec`), the
  initial belief (``initial``: ``mean`` and ``cov``, or ``sigma_xy_m`` / ``sigma_theta_rad`` around the first truth
  pose), ``truth_label``, ``reference_kind``, ``kidnaps`` and free-form ``metadata``;
- ``events.jsonl``: one JSON object per line, in time order, each with ``t`` (s) and ``type``: ``odometry``
  (dx, dy, dtheta in the previous robot frame, optional wheel travel and twist; or a twist alone), ``scan``,
  ``landmarks`` (range-bearing sightings), ``ranges`` (range-only, to beacons) and ``fix`` (a position or pose fix);
- ``truth.tum``: the ground truth as a TUM trajectory (``t x y z qx qy qz qw``);
- optional: a ROS map_server map (``map``: the YAML the bag loader reads), landmarks (``id x y [std_x std_y]``),
  map line segments (``x1 y1 x2 y2``), waypoints (``t x y``) and relations (``t1 t2 dx dy dtheta``).

Every number is read as the float64 it names (``locbench export --format textlog`` writes ``repr`` floats, so an
exported dataset reads back bit for bit; the truth's headings pass through quaternions and come back within 1e-15
rad). Events outside the truth's time span are left out and counted (``metadata["events_outside_truth_span"]``,
with a warning). An odometry stream whose twist contradicts its increments is loaded with a warning in
``metadata["warnings"]`` (:func:`~locbench.datasets.recorded.files.twist_contradiction`).

Validation: each file is a regular file of bounded size (:func:`~locbench.core.limits.check_input_file`), events lines
at most :data:`MAX_LINE_CHARS` long; every error is one line naming the file, the 1-based line, the field and what
was expected (:class:`~locbench.datasets.recorded.files.RecordedDataError`). Bounds: times finite within
+-:data:`MAX_TIME_S` and non-decreasing in file order; increments within :data:`MAX_STEP_M` and 2 pi; twists within
:data:`MAX_TWIST`, ``dt`` in (0, :data:`MAX_DT_S`]; positions within
:data:`~locbench.datasets.recorded.files.MAX_POSITION_M`; scans as a bag's
(:func:`~locbench.datasets.recorded.files.scan_problem`) with at most :data:`~locbench.core.limits.MAX_LASER_BEAMS`
beams; at most :data:`MAX_ITEMS` sightings or ranges per event, ids -1 (unknown) or in the landmark file; fix
covariances symmetric PSD; no unknown field anywhere and no key given twice in one object (a typo is an error, not
a silently default value); not every event at one time; kidnaps inside the truth's span.

Plausibility (:mod:`~locbench.datasets.recorded.plausibility`, the policy's :data:`~locbench.datasets.recorded.\
plausibility.BOUNDS`): these samples are flagged, left out and listed in ``Dataset.flagged`` (a stream with more
than 1 % of them, or a 2 s stretch, is refused): an events line that repeats the previous one exactly (a doubled
line: counted once); an odometry increment faster than the speed or turn-rate bound over its interval (``dt``, else
the time since the previous odometry event), or a twist beyond them; a sighting or range event with a range outside
[0, range bound] or a bearing beyond the heading bound; a fix whose position variance exceeds the variance bound; a
truth pose repeating the previous one, a second pose at the previous one's time, or a pose the robot could not have
reached from the last accepted one (speed and turn-rate bounds plus their jitter; the track restarts at each
kidnap).
"""

from __future__ import annotations

import functools
import json
import logging
import math
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from locbench.core.errors import ConfigError
from locbench.core.events import (
    UNKNOWN_ID,
    Event,
    LandmarkObservations,
    LaserScan,
    Odometry,
    PoseFix,
    RangeObservations,
)
from locbench.core.geometry import is_symmetric_psd, quaternion_to_yaw, twist_increment
from locbench.core.limits import MAX_LASER_BEAMS, check_input_file
from locbench.core.spec import params_to_dict
from locbench.datasets.dataset import (
    TRUTH_LABELS,
    Dataset,
    DatasetBuilder,
    FlaggedSample,
    Gaussian2,
    Kidnap,
    Landmarks,
    LineMap,
    OccupancyGrid,
    Relations,
    SensorSpec,
    Trajectory2D,
    Waypoints,
    WorldMap,
    check_dataset_contract,
    sort_events,
)
from locbench.datasets.recorded import plausibility
from locbench.datasets.recorded.files import (
    MAX_INTEGER_FIELD,
    MAX_POSITION_M,
    MAX_SCAN_RANGE_M,
    RecordedDataError,
    quaternion_problem,
    quote,
    read_table,
    scan_problem,
    twist_contradiction,
    user_path_candidates,
)
from locbench.datasets.recorded.tum import TUM_COLUMNS, atomic_write_text, write_tum

FloatArray = npt.NDArray[np.float64]

log = logging.getLogger(__name__)

FORMAT = "locbench-textlog"
#: The format version this module reads and writes; a manifest of a later version is refused.
VERSION = 1
MANIFEST = "textlog.json"
#: Default file names (the manifest may name others).
DEFAULT_FILES = {"events": "events.jsonl", "truth": "truth.tum"}
#: Largest manifest, bytes; events file; any other table (truth, landmarks ...), bytes. Parsed events take about
#: the text's size in memory (a float64 per number), so the events bound keeps a run within the 1 GB budget.
MAX_MANIFEST_BYTES = 1 << 20
MAX_EVENTS_BYTES = 512 << 20
MAX_TABLE_FILE_BYTES = 256 << 20
#: Longest line of the events file, characters (a 10 000-beam scan is about 200 000).
MAX_LINE_CHARS = 1 << 20
#: Bounds of the events: time (s), increment (m), twist (m/s, rad/s), twist duration (s), items per event.
MAX_TIME_S = 1.0e10
MAX_STEP_M = 100.0
MAX_TWIST = 100.0
MAX_DT_S = 60.0
MAX_ITEMS = 10_000
#: What the reference trajectory is (the report's kinds); a manifest names one or leaves "not stated".
REFERENCE_KINDS = ("motion capture", "GPS", "survey", "not stated", "SLAM", "simulation")
#: Initial belief around the first truth pose when the manifest gives none: standard deviations (m, rad).
DEFAULT_INITIAL_SIGMA = (0.05, 0.05)

_TWO_PI = 2.0 * math.pi


@dataclass(frozen=True, kw_only=True)
class TextlogParams:
    """Parameters of ``textlog``.

    Attributes
    ----------
    path : str
        The textlog folder (holding ``textlog.json``); a relative path is looked up in the working folder, then
        under ``$LOCBENCH_DATA``.
    """

    path: str = ""

    def __post_init__(self) -> None:
        if not self.path:
            raise ConfigError("textlog: parameter 'path' is required: textlog[path=<folder with textlog.json>]")


# --- the manifest --------------------------------------------------------------------------------


def _no_duplicates(path: Path) -> Callable[[list[tuple[str, Any]]], dict[str, Any]]:
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


def _json_hooks(path: Path) -> tuple[Callable[[str], int], Callable[[str], Any]]:
    """``json`` hooks that refuse NaN and Infinity and keep integers small (so no float conversion overflows); a
    float beyond float64 (1e999) reads as inf and is refused by the field checks. Floats stay with the C parser."""

    def parse_int(text: str) -> int:
        if len(text.lstrip("-")) > 18:
            raise RecordedDataError(path, f"integer {quote(text, 40)} has more than 18 digits, expected a smaller one")
        return int(text)

    return parse_int, _refuse_constant(path)


def _is_number(v: Any) -> bool:
    """A finite JSON number (bool is an int subclass: a true is no number; 1e999 reads as inf)."""
    return type(v) is int or (type(v) is float and math.isfinite(v))


_NUMBER_TYPES = frozenset({float, int})
_NUMBER_OR_NULL_TYPES = frozenset({float, int, type(None)})


@dataclass(frozen=True)
class _Manifest:
    path: Path
    text: str
    data: dict[str, Any]

    def line(self, key: str) -> int | None:
        """1-based line of the first ``"key":`` in the file (for messages)."""
        at = self.text.find(f'"{key}"')
        return self.text.count("\n", 0, at) + 1 if at >= 0 else None

    def fail(self, key: str, message: str) -> RecordedDataError:
        return RecordedDataError(self.path, f"field {key!r}: {message}", self.line(key))

    def number(self, where: str, v: Any, lo: float, hi: float, unit: str) -> float:
        if not _is_number(v) or not (lo <= float(v) <= hi):
            raise self.fail(where.split(".")[0], f"{where} is {quote(v, 60)}, expected a number in [{lo}, {hi}] {unit}")
        return float(v)

    def vector(self, where: str, v: Any, n: int, bound: float, unit: str) -> list[float]:
        if not (isinstance(v, list) and len(v) == n):
            raise self.fail(where.split(".")[0], f"{where} is {quote(v, 80)}, expected a list of {n} numbers ({unit})")
        return [self.number(f"{where}[{i}]", x, -bound, bound, unit) for i, x in enumerate(v)]

    def file(self, key: str, folder: Path) -> Path | None:
        name = self.data.get(key, DEFAULT_FILES.get(key))
        if name is None:
            return None
        if not (isinstance(name, str) and name.strip()):
            raise self.fail(key, f"is {quote(name, 60)}, expected a file name (relative to the folder)")
        p = Path(name).expanduser()
        return p if p.is_absolute() else folder / p


_MANIFEST_KEYS = (
    "format",
    "version",
    "events",
    "truth",
    "map",
    "map_lines",
    "landmarks",
    "lines",
    "waypoints",
    "relations",
    "sensors",
    "initial",
    "truth_label",
    "reference_kind",
    "kidnaps",
    "source",
    "metadata",
)


def read_manifest(folder: Path) -> _Manifest:
    """The folder's ``textlog.json``, checked for its format, version and keys (not yet the values of each)."""
    path = folder / MANIFEST
    if not path.exists():
        raise RecordedDataError(path, f"missing manifest; expected a textlog folder holding {MANIFEST}")
    check_input_file(path, "textlog manifest", MAX_MANIFEST_BYTES)
    raw = path.read_bytes()
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise RecordedDataError(
            path, "not UTF-8 text, expected a JSON object", raw[: exc.start].count(b"\n") + 1
        ) from None
    hooks = _json_hooks(path)
    try:
        data = json.loads(text, object_pairs_hook=_no_duplicates(path), parse_int=hooks[0], parse_constant=hooks[1])
    except json.JSONDecodeError as exc:
        raise RecordedDataError(
            path, f"not JSON ({exc.msg} at column {exc.colno}), expected a JSON object", exc.lineno
        ) from None
    except RecursionError:
        raise RecordedDataError(path, "JSON nested too deeply, expected a flat manifest object") from None
    if not isinstance(data, dict):
        raise RecordedDataError(path, f"a JSON {type(data).__name__}, expected a JSON object (the manifest)")
    m = _Manifest(path, text, data)
    if data.get("format") != FORMAT:
        raise m.fail("format", f"is {quote(data.get('format'), 60)}, expected {FORMAT!r}")
    version = data.get("version")
    if type(version) is not int or version < 1:
        raise m.fail("version", f"is {quote(version, 60)}, expected an integer version (this locbench reads {VERSION})")
    if version > VERSION:
        raise m.fail("version", f"is {version}, written for a newer locbench; this one reads version {VERSION}")
    for key in data:
        if key not in _MANIFEST_KEYS:
            raise m.fail(key, f"unknown field, expected one of {', '.join(_MANIFEST_KEYS)}")
    return m


_SENSOR_FIELDS = tuple(f.name for f in fields(SensorSpec))


def _sensors(m: _Manifest) -> SensorSpec:
    raw = m.data.get("sensors", {})
    if not isinstance(raw, dict):
        raise m.fail("sensors", f"is {quote(raw, 60)}, expected an object of SensorSpec fields")
    values = {}
    for k, v in raw.items():
        if k not in _SENSOR_FIELDS:
            raise m.fail(k, f"unknown sensors field, expected one of {', '.join(_SENSOR_FIELDS)}")
        values[k] = m.number(f"sensors.{k}", v, 0.0, MAX_POSITION_M, "(the field's unit)")
    return SensorSpec(**values)


def _initial(m: _Manifest, truth: Trajectory2D) -> Gaussian2:
    raw = m.data.get("initial", {})
    if not isinstance(raw, dict):
        raise m.fail("initial", f"is {quote(raw, 60)}, expected an object (mean and cov, or sigmas)")
    allowed = ("mean", "cov", "sigma_xy_m", "sigma_theta_rad")
    for k in raw:
        if k not in allowed:
            raise m.fail("initial", f"unknown field {k!r}, expected {', '.join(allowed)}")
    if ("mean" in raw) != ("cov" in raw) or ("mean" in raw and ("sigma_xy_m" in raw or "sigma_theta_rad" in raw)):
        raise m.fail("initial", "expected either both 'mean' and 'cov', or the sigmas around the first truth pose")
    if "mean" in raw:
        mean = np.array(m.vector("initial.mean", raw["mean"], 3, MAX_POSITION_M, "m, m, rad"))
        rows = raw["cov"]
        if not (isinstance(rows, list) and len(rows) == 3):
            raise m.fail("initial", f"initial.cov is {quote(rows, 80)}, expected 3 rows of 3 numbers")
        cov = np.array([m.vector(f"initial.cov[{i}]", r, 3, MAX_POSITION_M**2, "") for i, r in enumerate(rows)])
        if not is_symmetric_psd(cov):
            raise m.fail("initial", f"initial.cov {quote(cov.tolist(), 120)}, expected a symmetric PSD matrix")
        return Gaussian2(mean, cov)
    sxy = m.number("initial.sigma_xy_m", raw.get("sigma_xy_m", DEFAULT_INITIAL_SIGMA[0]), 0.0, MAX_POSITION_M, "m")
    sth = m.number("initial.sigma_theta_rad", raw.get("sigma_theta_rad", DEFAULT_INITIAL_SIGMA[1]), 0.0, 10.0, "rad")
    return Gaussian2(truth.poses[0].copy(), np.diag([sxy**2, sxy**2, sth**2]))


def _kidnaps(m: _Manifest, span: tuple[float, float]) -> tuple[Kidnap, ...]:
    """The manifest's kidnaps; each time must lie inside the truth's ``span`` (s): a kidnap is part of the run."""
    raw = m.data.get("kidnaps", [])
    if not isinstance(raw, list):
        raise m.fail("kidnaps", f'is {quote(raw, 60)}, expected a list of {{"t": s, "delta": [dx, dy, dtheta]}}')
    out = []
    for i, k in enumerate(raw):
        if not (isinstance(k, dict) and set(k) == {"t", "delta"}):
            raise m.fail("kidnaps", f'kidnaps[{i}] is {quote(k, 80)}, expected {{"t": s, "delta": [dx, dy, dtheta]}}')
        t = m.number(f"kidnaps[{i}].t", k["t"], -MAX_TIME_S, MAX_TIME_S, "s")
        if not span[0] <= t <= span[1]:
            inside = f"[{span[0]!r}, {span[1]!r}] s"
            raise m.fail("kidnaps", f"kidnaps[{i}].t is {t!r} s, expected a time inside the recording {inside}")
        d = m.vector(f"kidnaps[{i}].delta", k["delta"], 3, MAX_POSITION_M, "m, m, rad")
        out.append(Kidnap(t, (d[0], d[1], d[2])))
    return tuple(out)


# --- events --------------------------------------------------------------------------------------


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
        if not _is_number(v) or not (lo <= float(v) <= hi):
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
        dth = ln.number("dtheta", -_TWO_PI, _TWO_PI, "rad")
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
    a0 = ln.number("angle_min", -_TWO_PI, _TWO_PI, "rad")
    inc = ln.number("angle_increment", -_TWO_PI, _TWO_PI, "rad")
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
            if not (len(r) == n and all(_is_number(x) for x in r)):
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
    hooks = _json_hooks(p)
    decoder = json.JSONDecoder(object_pairs_hook=_no_duplicates(p), parse_int=hooks[0], parse_constant=hooks[1])
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
                worst = np.array([_worst(np.asarray(e.bearings), -_TWO_PI, _TWO_PI) for e in of])  # type: ignore[union-attr]
                flags.flag_outside(worst, "bearing, rad", -_TWO_PI, _TWO_PI)
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


# --- tables --------------------------------------------------------------------------------------


def read_truth(path: Path) -> Trajectory2D:
    """A TUM trajectory as the ground truth: times non-decreasing, positions within bounds, planar unit rotations
    (every sample: :func:`flag_truth` leaves out the implausible ones)."""
    return _truth_table(path)[0]


def _truth_table(path: Path) -> tuple[Trajectory2D, npt.NDArray[np.int64]]:
    """:func:`read_truth` and each sample's line."""
    check_input_file(path, "TUM truth file", MAX_TABLE_FILE_BYTES)
    table = read_table(path, TUM_COLUMNS)
    table.check_rows("pose", 1)
    table.check_time_non_decreasing(0, "timestamp")
    if table.rows.shape[0] > 1:
        plausibility.refuse_all_times_equal(path, "truth", table.rows[:, 0], int(table.lines[1]))
    for c, name in ((1, "tx [m]"), (2, "ty [m]"), (3, "tz [m]")):
        table.check_range(c, name, -MAX_POSITION_M, MAX_POSITION_M)
    rows = table.rows
    problem = quaternion_problem(rows[:, 4:8])
    if problem is not None:
        raise table.fail(problem[0], problem[1])
    return Trajectory2D(rows[:, 0].copy(), rows[:, 1:3].copy(), quaternion_to_yaw(rows[:, 4:8])), table.lines


def flag_truth(
    path: Path, truth: Trajectory2D, lines: npt.ArrayLike, kidnaps: tuple[Kidnap, ...] = ()
) -> tuple[Trajectory2D, tuple[FlaggedSample, ...]]:
    """The truth without its implausible samples, and those (the module docstring lists them).

    A pose repeating the previous one, a second pose at the previous one's time, and a pose the robot could not
    have reached from the last accepted one are flagged; the track restarts at each kidnap's time.
    """
    flags = plausibility.Flags(path, "truth", truth.t, lines)
    rows = np.column_stack([truth.t, truth.xy, truth.theta])
    flags.flag_duplicates(rows)
    again = np.r_[False, (truth.t[1:] == truth.t[:-1]) & ~flags.mask[1:]]
    flags.flag(again, "time of the previous pose, s", truth.t, "one pose per time")
    flags.flag_track(truth.xy, truth.theta, plausibility.BOUNDS, breaks=[k.t for k in kidnaps])
    kept = flags.kept
    return Trajectory2D(truth.t[kept], truth.xy[kept], truth.theta[kept]), flags.finish()


def read_landmarks(path: Path) -> Landmarks:
    """A landmark file: ``id x y`` or ``id x y std_x std_y`` per line (the first data line decides), ids unique."""
    check_input_file(path, "landmark file", MAX_TABLE_FILE_BYTES)
    first = next(
        (
            ln
            for ln in path.read_text(encoding="utf-8", errors="replace").splitlines()
            if ln.strip() and not ln.lstrip().startswith("#")
        ),
        "",
    )
    with_std = len(first.replace(",", " ").split()) == 5
    cols = ("id", "x [m]", "y [m]") + (("std_x [m]", "std_y [m]") if with_std else ())
    table = read_table(path, cols, integer_columns=(0,))
    table.check_rows("landmark", 1)
    table.check_range(0, "id", 0, MAX_INTEGER_FIELD)
    for c in range(1, len(cols)):
        table.check_range(c, cols[c], 0.0 if c >= 3 else -MAX_POSITION_M, MAX_POSITION_M)
    ids = table.rows[:, 0].astype(np.int64)
    _, first_at, counts = np.unique(ids, return_index=True, return_counts=True)
    if np.any(counts > 1):
        k = int(np.sort(first_at[counts > 1])[0])
        again = int(np.flatnonzero(ids == ids[k])[1])
        raise table.fail(again, f"landmark id {int(ids[k])} given twice, expected unique ids")
    std = table.rows[:, 3:5].copy() if with_std else None
    return Landmarks(ids, table.rows[:, 1:3].copy(), std)


def read_lines(path: Path) -> LineMap:
    """Map line segments ``x1 y1 x2 y2`` (m, world frame), each of non-zero length."""
    check_input_file(path, "line map file", MAX_TABLE_FILE_BYTES)
    cols = ("x1 [m]", "y1 [m]", "x2 [m]", "y2 [m]")
    table = read_table(path, cols)
    for c in range(4):
        table.check_range(c, cols[c], -MAX_POSITION_M, MAX_POSITION_M)
    seg = table.rows.copy()
    zero = np.flatnonzero((seg[:, 0] == seg[:, 2]) & (seg[:, 1] == seg[:, 3]))
    if zero.size:
        raise table.fail(int(zero[0]), "segment of zero length, expected two distinct end points")
    return LineMap(seg)


def read_waypoints(path: Path, truth: Trajectory2D) -> Waypoints:
    """Waypoints ``t x y``: times non-decreasing within the truth's span, positions within bounds."""
    check_input_file(path, "waypoint file", MAX_TABLE_FILE_BYTES)
    table = read_table(path, ("t [s]", "x [m]", "y [m]"))
    table.check_rows("waypoint", 1)
    table.check_time_non_decreasing(0, "t")
    table.check_range(0, "t [s] (within the truth's span)", float(truth.t[0]), float(truth.t[-1]))
    for c, name in ((1, "x [m]"), (2, "y [m]")):
        table.check_range(c, name, -MAX_POSITION_M, MAX_POSITION_M)
    return Waypoints(table.rows[:, 0].copy(), table.rows[:, 1:3].copy())


def read_relations(path: Path) -> Relations:
    """Reference relative poses ``t1 t2 dx dy dtheta`` (s, s, m, m, rad; the pose at t2 in the frame of t1)."""
    check_input_file(path, "relations file", MAX_TABLE_FILE_BYTES)
    cols = ("t1 [s]", "t2 [s]", "dx [m]", "dy [m]", "dtheta [rad]")
    table = read_table(path, cols)
    table.check_rows("relation", 1)
    for c in (2, 3):
        table.check_range(c, cols[c], -MAX_POSITION_M, MAX_POSITION_M)
    table.check_range(4, cols[4], -_TWO_PI, _TWO_PI)
    r = table.rows
    return Relations(r[:, 0].copy(), r[:, 1].copy(), r[:, 2:5].copy())


# --- the dataset ---------------------------------------------------------------------------------


def resolve_folder(path: str | os.PathLike[str]) -> Path:
    """The textlog folder: as given, else under ``$LOCBENCH_DATA``; an error (not a skip) when in neither."""
    candidates = user_path_candidates(path)
    p = candidates[0]
    for c in candidates:
        if c.is_dir():
            return c
    looked = " or ".join(str(c) for c in candidates)
    raise RecordedDataError(p, f"missing textlog folder (looked for {looked}); expected a folder holding {MANIFEST}")


def _grid(m: _Manifest, folder: Path) -> tuple[OccupancyGrid | None, LineMap | None, Path | None]:
    yaml_path = m.file("map", folder)
    lines_path = m.file("lines", folder)
    want_lines = m.data.get("map_lines", True)
    if type(want_lines) is not bool:
        raise m.fail("map_lines", f"is {quote(want_lines, 60)}, expected true or false")
    grid, lines = None, None
    if yaml_path is not None:
        if not yaml_path.exists():
            raise m.fail("map", f"names {str(yaml_path)!r}, which does not exist (expected a map_server YAML)")
        from locbench.datasets.recorded.rosbag import _map  # the bag's cached map reader (imports scipy: lazily)

        grid, lines = _map(yaml_path, want_lines and lines_path is None)
    if lines_path is not None:
        lines = read_lines(lines_path)
    return grid, lines, yaml_path


def _required(m: _Manifest, key: str, folder: Path) -> Path:
    p = m.file(key, folder)
    if p is None:  # the key is present but null: its default does not apply
        raise m.fail(
            key, f"is null, expected the {key} file's name (relative to the folder; default {DEFAULT_FILES[key]})"
        )
    if not p.exists():
        raise RecordedDataError(p, f"missing {key} file (named by {m.path}), expected the textlog's {key}")
    return p


def build_textlog_dataset(params: TextlogParams) -> Dataset:
    """The dataset of a textlog folder (what :class:`TextlogDataset` builds; the module docstring says how)."""
    folder = resolve_folder(params.path)
    m = read_manifest(folder)
    truth_path, events_path = _required(m, "truth", folder), _required(m, "events", folder)
    sources: list[str] = [str(m.path), str(events_path), str(truth_path)]
    full, truth_lines = _cached_truth(str(truth_path.resolve()), *_version(truth_path))
    kidnaps = _kidnaps(m, (float(full.t[0]), float(full.t[-1])))
    truth, truth_flags = flag_truth(truth_path, full, truth_lines, kidnaps)
    landmarks = None
    lm_path = m.file("landmarks", folder)
    if lm_path is not None:
        landmarks = read_landmarks(lm_path)
        sources.append(str(lm_path))
    known = frozenset(int(i) for i in landmarks.ids) if landmarks is not None else None
    events, event_flags = _cached_events(str(events_path.resolve()), *_version(events_path), known)
    grid, lines, map_path = _grid(m, folder)
    sources += [str(q) for q in (map_path, m.file("lines", folder)) if q is not None]
    waypoints = relations = None
    if (wp := m.file("waypoints", folder)) is not None:
        waypoints = read_waypoints(wp, truth)
        sources.append(str(wp))
    if (rel := m.file("relations", folder)) is not None:
        relations = read_relations(rel)
        sources.append(str(rel))
    truth_label = m.data.get("truth_label", "ground truth")
    if truth_label not in TRUTH_LABELS:
        raise m.fail("truth_label", f"is {quote(truth_label, 60)}, expected one of {', '.join(TRUTH_LABELS)}")
    kind = m.data.get("reference_kind", "not stated")
    if kind not in REFERENCE_KINDS:
        raise m.fail("reference_kind", f"is {quote(kind, 60)}, expected one of {', '.join(REFERENCE_KINDS)}")
    extra = m.data.get("metadata", {})
    if not isinstance(extra, dict):
        raise m.fail("metadata", f"is {quote(extra, 60)}, expected a JSON object")

    t0, t1 = float(truth.t[0]), float(truth.t[-1])
    inside = tuple(e for e in events if t0 <= e.t <= t1)
    outside = len(events) - len(inside)
    warnings = _input_warnings(events, inside, (t0, t1), events_path, extra.get("warnings", []))
    metadata = {
        **extra,
        "source": str(folder),
        "format": f"{FORMAT} v{m.data['version']}",
        "reference_kind": kind,
        "events_outside_truth_span": outside,
        "warnings": warnings,
    }
    if isinstance(m.data.get("source"), str):
        metadata["exported_from"] = m.data["source"]
    ds = Dataset(
        id="textlog",
        params=params_to_dict(params),
        events=sort_events(list(inside)),
        ground_truth=truth,
        initial=_initial(m, truth),
        world=WorldMap(occupancy=grid, landmarks=landmarks, lines=lines),
        sensors=_sensors(m),
        waypoints=waypoints,
        kidnaps=kidnaps,
        name="textlog",
        metadata=metadata,
        relations=relations,
        truth_label=truth_label,
        sources=tuple(sources),
        declared=frozenset(type(e) for e in events) - {Odometry},
        flagged=plausibility.merge(truth_flags, event_flags),
    )
    check_dataset_contract(ds)
    return ds


def _input_warnings(
    events: tuple[Event, ...], inside: tuple[Event, ...], span: tuple[float, float], path: Path, inherited: Any
) -> list[str]:
    """The dataset's warnings: an exported dataset's own (``inherited``), then events left out of the truth's span
    and a twist that contradicts the increments (these two logged)."""
    found: list[str] = []
    outside = len(events) - len(inside)
    if outside:
        found.append(
            f"{outside} of {len(events)} events lie outside the ground truth's span [{span[0]!r}, {span[1]!r}] s and "
            "were left out"
        )
    odo = [
        e for e in inside if isinstance(e, Odometry) and e.v is not None and e.omega is not None and e.dt is not None
    ]
    if odo:
        tw = np.array([(e.v, e.omega, e.dt) for e in odo], dtype=np.float64)
        why = twist_contradiction([e.delta for e in odo], tw[:, 0], tw[:, 1], tw[:, 2])
        if why:
            found.append(f"{path}: {why}")
    for w in found:
        log.warning("textlog: %s", w)
    kept = [str(w) for w in inherited if isinstance(w, str)] if isinstance(inherited, list) else []
    return kept + found


def _version(p: Path) -> tuple[int, int]:
    st = p.stat()
    return st.st_size, st.st_mtime_ns


@functools.lru_cache(maxsize=4)
def _cached_events(
    path: str, size: int, mtime_ns: int, known: frozenset[int] | None
) -> tuple[tuple[Event, ...], tuple[FlaggedSample, ...]]:
    """The parsed events and the flagged ones, once per file version (the runner builds a dataset per seed; arrays
    are read-only)."""
    del size, mtime_ns  # cache key only
    return read_events_flagged(path, known)


@functools.lru_cache(maxsize=4)
def _cached_truth(path: str, size: int, mtime_ns: int) -> tuple[Trajectory2D, npt.NDArray[np.int64]]:
    del size, mtime_ns  # cache key only
    tr, lines = _truth_table(Path(path))
    for a in (tr.t, tr.xy, tr.theta, lines):
        a.setflags(write=False)
    return tr, lines


def load_textlog(path: str | os.PathLike[str]) -> Dataset:
    """Load a textlog folder as a dataset (see the module docstring and docs/datasets.md for the format)."""
    return build_textlog_dataset(TextlogParams(path=str(path)))


class TextlogDataset(DatasetBuilder):
    """A user's log in the plain-text ``locbench-textlog`` format (or any dataset exported to it)."""

    id: ClassVar[str] = "textlog"
    Params: ClassVar[type] = TextlogParams
    version: ClassVar[int] = 1
    nominal_duration_s: ClassVar[float] = 1000.0
    description: ClassVar[str] = (
        "a user's plain-text log (locbench-textlog v1): JSON-lines events, TUM truth, map_server map, landmark files"
    )

    def build(self, params: TextlogParams, rng: np.random.Generator) -> Dataset:
        del rng  # a recording: every seed is the same data
        return build_textlog_dataset(params)

    @classmethod
    def data_unavailable(cls) -> str | None:
        """Always a reason for the default parameters: there is no default log."""
        return "unavailable: no default log; name one with textlog[path=<folder with textlog.json>]"

    def fetch(self, params: TextlogParams) -> list[str]:
        """Nothing to download: the local path of the folder (an error when absent)."""
        return [str(resolve_folder(params.path))]


# --- writing -------------------------------------------------------------------------------------


def _event_object(e: Event) -> dict[str, Any]:
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


def _table_text(header: str, rows: npt.ArrayLike, ints: int = 0) -> str:
    """Space-separated rows (the first ``ints`` columns as integers, the rest as repr floats) under a # header."""
    out = [f"# {header}"]
    for r in np.asarray(rows, dtype=np.float64):
        out.append(" ".join([str(int(v)) for v in r[:ints]] + [repr(float(v)) for v in r[ints:]]))
    return "\n".join(out) + "\n"


def _json_safe(value: dict[str, Any]) -> dict[str, Any]:
    """The entries of a metadata dict that JSON can hold exactly (others are left out of the export)."""
    out = {}
    for k, v in value.items():
        try:
            json.dumps(v, allow_nan=False)
        except (TypeError, ValueError):
            continue
        out[str(k)] = v
    return out


def _map_mode(grid: OccupancyGrid) -> tuple[str, bool]:
    """The map_server mode that stores ``grid`` and whether it reads back exactly (trinary cells only)."""
    occ = grid.occupancy
    trinary = bool(np.all((occ == 0.0) | (occ == 1.0) | (occ == -1.0)))
    if trinary and grid.occupied_thresh < 1.0 and grid.free_thresh > 0.0:
        return "trinary", True
    return ("raw" if np.any(occ < 0.0) else "scale"), False


def write_textlog(ds: Dataset, folder: str | os.PathLike[str], source: str = "", reference_kind: str = "") -> list[str]:
    """Write a dataset as a textlog folder (format version :data:`VERSION`), every file atomically.

    Parameters
    ----------
    ds : Dataset
        Any dataset (a synthetic realisation, a recording).
    folder : path-like
        The folder to write; created. An existing folder must be empty or a textlog (its files are replaced).
    source : str
        What was exported (``room seed 0``), kept in the manifest.
    reference_kind : str
        The reference kind to declare (default: ``ds.metadata["reference_kind"]``, else "simulation" for a dataset
        with a bound-capable simulator's truth, else "not stated").

    Returns
    -------
    list of str
        Notes on what does not round-trip exactly (an occupancy grid of graded values is quantized to 8 bits);
        empty when the folder reads back as the same dataset.
    """
    from locbench.datasets.recorded.ros_map import save_map_server_map

    out = Path(folder)
    if out.exists() and not out.is_dir():
        raise ConfigError(f"{out}: is a file; expected a folder for the textlog")
    if out.is_dir() and any(out.iterdir()) and not (out / MANIFEST).is_file():
        raise ConfigError(f"{out}: a folder that is not empty and holds no {MANIFEST}; expected an empty folder")
    out.mkdir(parents=True, exist_ok=True)
    notes: list[str] = []
    manifest: dict[str, Any] = {"format": FORMAT, "version": VERSION, "source": source}
    manifest.update(DEFAULT_FILES)
    lines = [json.dumps(_event_object(e), allow_nan=False, separators=(",", ":")) for e in ds.events]
    atomic_write_text(out / DEFAULT_FILES["events"], "\n".join(lines) + "\n")
    gt = ds.ground_truth
    write_tum(out / DEFAULT_FILES["truth"], gt.t, gt.poses, f"locbench {ds.truth_label}: {source}", keep_all=True)
    w = ds.world
    if w.occupancy is not None:
        mode, exact = _map_mode(w.occupancy)
        save_map_server_map(w.occupancy, out / "map.yaml", mode=mode)  # type: ignore[arg-type]
        manifest["map"] = "map.yaml"
        manifest["map_lines"] = False  # the dataset's own lines (or none), never lines extracted anew
        if not exact:
            notes.append(f"the occupancy grid has graded values: stored in {mode} mode, quantized to 8 bits")
    if w.landmarks is not None and len(w.landmarks):  # an empty map is no map (WorldMap.kinds)
        lm = w.landmarks
        rows = np.column_stack([lm.ids, lm.xy] + ([lm.std_xy] if lm.std_xy is not None else []))
        head = "id x y" + (" std_x std_y" if lm.std_xy is not None else "") + " (m)"
        atomic_write_text(out / "landmarks.txt", _table_text(head, rows, ints=1))
        manifest["landmarks"] = "landmarks.txt"
    if w.lines is not None and len(w.lines):
        atomic_write_text(out / "lines.txt", _table_text("x1 y1 x2 y2 (m)", w.lines.segments))
        manifest["lines"] = "lines.txt"
    if ds.waypoints is not None and len(ds.waypoints):
        wp = ds.waypoints
        atomic_write_text(out / "waypoints.txt", _table_text("t (s) x y (m)", np.column_stack([wp.t, wp.xy])))
        manifest["waypoints"] = "waypoints.txt"
    if ds.relations is not None and len(ds.relations):
        r = ds.relations
        rows = np.column_stack([r.t1, r.t2, r.delta])
        atomic_write_text(out / "relations.txt", _table_text("t1 t2 (s) dx dy (m) dtheta (rad)", rows))
        manifest["relations"] = "relations.txt"
    manifest["sensors"] = {k: float(v) for k in _SENSOR_FIELDS if (v := getattr(ds.sensors, k)) is not None}
    manifest["initial"] = {"mean": ds.initial.mean.tolist(), "cov": ds.initial.cov.tolist()}
    manifest["truth_label"] = ds.truth_label
    kind = reference_kind or str(ds.metadata.get("reference_kind", "not stated"))
    manifest["reference_kind"] = kind if kind in REFERENCE_KINDS else "not stated"
    if ds.kidnaps:
        manifest["kidnaps"] = [{"t": k.t, "delta": [float(v) for v in k.delta]} for k in ds.kidnaps]
    manifest["metadata"] = _json_safe({k: v for k, v in ds.metadata.items() if k not in ("source", "format")})
    atomic_write_text(out / MANIFEST, json.dumps(manifest, indent=1, allow_nan=False) + "\n")
    return notes
