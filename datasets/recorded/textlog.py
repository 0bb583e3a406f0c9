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

The events file is read by :mod:`~locbench.datasets.recorded.jsonl_events` and the landmark, line, waypoint and
relation tables by :mod:`~locbench.datasets.recorded.text_tables` (the bag loader reads its sidecars with both);
the map through :func:`~locbench.datasets.recorded.ros_map.load_map_and_lines`. This module reads the manifest and
the truth and assembles the dataset, and writes a dataset as a textlog (:func:`write_textlog`).

Validation: each file is a regular file of bounded size (:func:`~locbench.core.limits.check_input_file`); every
error is one line naming the file, the 1-based line, the field and what was expected
(:class:`~locbench.datasets.recorded.files.RecordedDataError`). The events' bounds are those of
:mod:`~locbench.datasets.recorded.jsonl_events`; the manifest's numbers are bounded like the events', its
kidnaps lie inside the truth's span; no unknown field anywhere and no key given twice in one object (a typo is an
error, not a silently default value).

Plausibility (:mod:`~locbench.datasets.recorded.plausibility`, the policy's
:data:`~locbench.datasets.recorded.plausibility.BOUNDS`): the events flagged by
:mod:`~locbench.datasets.recorded.jsonl_events` (a doubled line, an implausible odometry increment or twist,
sighting, range or fix) and these truth samples are flagged, left out and listed in ``Dataset.flagged`` (a stream
with more than 1 % of them, or a 2 s stretch, is refused): a truth pose repeating the previous one, a second pose at
the previous one's time, or a pose the robot could not have reached from the last accepted one (speed and turn-rate
bounds plus their jitter; the track restarts at each kidnap).
"""

from __future__ import annotations

import functools
import json
import logging
import os
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from locbench.core.errors import ConfigError
from locbench.core.events import Event, Odometry
from locbench.core.geometry import is_symmetric_psd, quaternion_to_yaw
from locbench.core.limits import check_input_file
from locbench.core.spec import params_to_dict
from locbench.datasets.dataset import (
    TRUTH_LABELS,
    Dataset,
    DatasetBuilder,
    FlaggedSample,
    Gaussian2,
    Kidnap,
    LineMap,
    OccupancyGrid,
    SensorSpec,
    Trajectory2D,
    WorldMap,
    check_dataset_contract,
    sort_events,
)
from locbench.datasets.recorded import plausibility
from locbench.datasets.recorded.files import (
    MAX_POSITION_M,
    RecordedDataError,
    quaternion_problem,
    quote,
    read_table,
    twist_contradiction,
    user_path_candidates,
)
from locbench.datasets.recorded.jsonl_events import (
    MAX_TIME_S,
    event_object,
    is_number,
    json_hooks,
    no_duplicate_keys,
    read_events_flagged,
)
from locbench.datasets.recorded.ros_map import load_map_and_lines, save_map_server_map
from locbench.datasets.recorded.text_tables import (
    MAX_TABLE_FILE_BYTES,
    read_landmarks,
    read_lines,
    read_relations,
    read_waypoints,
    table_text,
)
from locbench.datasets.recorded.tum import TUM_COLUMNS, atomic_write_text, write_tum

log = logging.getLogger(__name__)

FORMAT = "locbench-textlog"
#: The format version this module reads and writes; a manifest of a later version is refused.
VERSION = 1
MANIFEST = "textlog.json"
#: Default file names (the manifest may name others).
DEFAULT_FILES = {"events": "events.jsonl", "truth": "truth.tum"}
#: Largest manifest, bytes (the events file's and the tables' bounds are in their modules).
MAX_MANIFEST_BYTES = 1 << 20
#: What the reference trajectory is (the report's kinds); a manifest names one or leaves "not stated".
REFERENCE_KINDS = ("motion capture", "GPS", "survey", "not stated", "SLAM", "simulation")
#: Initial belief around the first truth pose when the manifest gives none: standard deviations (m, rad).
DEFAULT_INITIAL_SIGMA = (0.05, 0.05)


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
        if not is_number(v) or not (lo <= float(v) <= hi):
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
    hooks = json_hooks(path)
    try:
        data = json.loads(text, object_pairs_hook=no_duplicate_keys(path), parse_int=hooks[0], parse_constant=hooks[1])
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


# --- the truth ---------------------------------------------------------------------------------


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
        grid, lines = load_map_and_lines(yaml_path, want_lines and lines_path is None)
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
    def recording(cls, params: TextlogParams) -> str | None:
        """``file <absolute path>`` of the user's recording (None without a path): two specs of one file read one
        recording, whatever else they set."""
        return f"file {os.path.realpath(params.path)}" if params.path else None

    @classmethod
    def data_unavailable(cls) -> str | None:
        """Always a reason for the default parameters: there is no default log."""
        return "unavailable: no default log; name one with textlog[path=<folder with textlog.json>]"

    def fetch(self, params: TextlogParams) -> list[str]:
        """Nothing to download: the local path of the folder (an error when absent)."""
        return [str(resolve_folder(params.path))]


# --- writing -------------------------------------------------------------------------------------


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
    out = Path(folder)
    if out.exists() and not out.is_dir():
        raise ConfigError(f"{out}: is a file; expected a folder for the textlog")
    if out.is_dir() and any(out.iterdir()) and not (out / MANIFEST).is_file():
        raise ConfigError(f"{out}: a folder that is not empty and holds no {MANIFEST}; expected an empty folder")
    out.mkdir(parents=True, exist_ok=True)
    notes: list[str] = []
    manifest: dict[str, Any] = {"format": FORMAT, "version": VERSION, "source": source}
    manifest.update(DEFAULT_FILES)
    lines = [json.dumps(event_object(e), allow_nan=False, separators=(",", ":")) for e in ds.events]
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
        atomic_write_text(out / "landmarks.txt", table_text(head, rows, ints=1))
        manifest["landmarks"] = "landmarks.txt"
    if w.lines is not None and len(w.lines):
        atomic_write_text(out / "lines.txt", table_text("x1 y1 x2 y2 (m)", w.lines.segments))
        manifest["lines"] = "lines.txt"
    if ds.waypoints is not None and len(ds.waypoints):
        wp = ds.waypoints
        atomic_write_text(out / "waypoints.txt", table_text("t (s) x y (m)", np.column_stack([wp.t, wp.xy])))
        manifest["waypoints"] = "waypoints.txt"
    if ds.relations is not None and len(ds.relations):
        r = ds.relations
        rows = np.column_stack([r.t1, r.t2, r.delta])
        atomic_write_text(out / "relations.txt", table_text("t1 t2 (s) dx dy (m) dtheta (rad)", rows))
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
