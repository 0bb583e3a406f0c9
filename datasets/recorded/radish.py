"""Radish "corrected" CARMEN laser logs (11 buildings, or any ``NAME-corrected.log.gz``) as ``radish[site=NAME]``.

Source and citation
-------------------
Radish, the Robotics Data Set Repository (A. Howard, N. Roy, "The Robotics Data Set Repository (Radish)", 2003;
radish.sourceforge.net). The corrected logs circulate with the Freiburg SLAM benchmark's sites (R. Kuemmerle et
al., "On measuring the accuracy of SLAM algorithms", Autonomous Robots 27(4):387-407, 2009). The copies read here
are byte-for-byte those of ``acschaefer/ple`` (commit ``cfcb5a7``, ``data/carmen/``; SOURCES.md section 6, whose
sha256 are :data:`KNOWN_SHA256`). No licence is stated for the data: cite Radish and each site's author.

Files and format
----------------
``LOCBENCH_DATA/radish_corrected/NAME-corrected.log.gz``: a gzip-compressed CARMEN log (see
:mod:`locbench.datasets.recorded.carmen`). Any ``NAME`` whose file is in the folder is a site: the list is read
from the folder (:func:`available_sites`), never fixed here. A file of the 11 published sites is verified by its
sha256; another file is read as it is. The decompressed log is refused above :data:`MAX_LOG_BYTES` (read in
chunks, so a gzip bomb stops there) and parsed by the CARMEN reader. Only FLASER messages are used: every pose of a
corrected log is the SLAM-corrected one (its FLASER pose equals its odometry fields, and its ODOM lines follow the
corrected path), so these logs hold no raw odometry. Their stamps are unusable on several sites (belgioioso,
freiburg-campus and orebro stamp every scan alike, infinite-corridor jumps by 4e9 s), so no time check is made on
them.

Beam geometry: n beams over the field of view ``PARAM laser_front_laser_fov`` (pi when absent), the first at
-fov / 2; an even n is spaced fov / n (180 or 360 beams: 1 or 0.5 deg), an odd n spans both ends, fov / (n - 1)
(181 or 361 beams). No-return readings: each log writes a saturation value for a beam without a return (81.91 m,
81.83 m, 50 m, 32.767 m ...); a reading at or above :data:`NO_RETURN_FRACTION` of the log's largest plausible reading
(at most :data:`RADISH_BOUNDS` ``range_m``, below) is a no-return (``inf`` in the scans, nothing in the map), and that
threshold is the scan's ``range_max``. The laser
sits ``PARAM robot_frontlaser_offset`` ahead of the robot (-0.04 m on the Freiburg logs, 0 elsewhere); the
corrected pose is taken as the robot pose.

Reference (a SLAM reference, not ground truth)
----------------------------------------------
The corrected FLASER poses, ``truth_label = "SLAM reference"``: scan-matching / Rao-Blackwellized PF SLAM output,
not an independent measurement. The map below is built from the same log. The report says so wherever the
metrics (ATE against the reference) are shown.

Map
---
The occupancy grid of :func:`locbench.datasets.recorded.scan_map.build_occupancy_grid` (log-odds ray casting of the
reference scans, Probabilistic Robotics ch. 9; hits log(0.7/0.3), misses log(0.4/0.6); unknown = -1; ROS
thresholds) from EVERY reference scan of the log (the event window below does not change the map), at
``map_resolution_m`` (0.1 m by default for every site: the largest sites, freiburg-campus and
infinite-corridor, are about 300 m x 300 m with their beams, 9-10 M cells at 0.1 m, within
:data:`~locbench.datasets.recorded.files.MAX_GRID_CELLS`; at 0.05 m they are not), with a 1 m unknown border.
The build is deterministic (the same bytes every time; tested) and cached by the sha256 of the input file (the
content, not its name or time) and the resolution. The line map for ``ekf_lines`` is
:func:`~locbench.datasets.recorded.scan_map.extract_map_lines` of the grid; where the grid has more occupied cells
than :data:`~locbench.datasets.recorded.scan_map.MAX_HOUGH_VOTES` allows, no line map is given (``ekf_lines`` is
then a stored skip naming the missing map kind, and ``metadata["map"]["lines"]`` says why).

Odometry
--------
* **Paired sites** (:data:`RAW_LOGS`: intel, aces, freiburg-079, whose raw logs are in
  ``freiburg_slam_benchmark/``): each corrected scan is paired with the raw scan of identical range readings
  (:func:`pair_scans`: the ranges as logged, compared exactly, taken in file order so that a repeated scan pairs
  with the next raw copy after the previous pair; time is NOT used, since aces' and fr079's time bases differ
  from the raw logs'). Every corrected scan of the three logs pairs (910/910, 440/440, 4791/4791;
  ``metadata["pairing"]``). The run is in the raw log's time base (``ipc_timestamp``): the scans at their raw
  scan's time, the reference pose of each paired scan at that time, the raw ODOM messages ordered by stamp and
  differenced as in :mod:`~locbench.datasets.recorded.intel`. Nominal odometry noise: as intel's,
  :func:`~locbench.datasets.recorded.reference.derive_odometry_noise` from the raw odometry at the paired scans
  against the reference.
* **Other sites: semi-synthetic odometry.** The reference increments between consecutive scans,
  u = between(p_k, p_k+1), with simulated encoder error e ~ N(0, diag(s_xy^2 d, s_xy^2 d, s_tm^2 d + s_tr^2 a))
  (d = |u_xy| m, a = |u_theta| rad; the increment model of :func:`locbench.filters._motion.increment_variances`),
  drawn from the dataset's seeded generator like every synthetic error, one Odometry event just before each scan.
  The parameters :data:`ENCODER_ERROR` are fitted on the three paired sites by ``tools/derive/fit_radish_odometry.py``
  (tuning sites of :data:`~locbench.datasets.splits.RADISH_SPLIT`: no test site enters it;
  :func:`fit_encoder_error`: the method of moments of ``derive_odometry_noise`` pooled over the pairs of
  consecutive paired scans of all three logs; a test reruns it). The nominal noise handed to the filters is the same
  model. Time: the scans at :data:`SCAN_PERIOD_S` apart (the logs' own stamps are unusable, above); the logged
  stamps stay in the log. ``metadata["odometry"]`` says "semi-synthetic"; the report labels it. Real odometry
  also drifts systematically; this zero-mean error does not, so these sites are easier for dead reckoning than
  the paired ones.

Window (CPU budget)
-------------------
``max_scans`` (default :data:`DEFAULT_MAX_SCANS`) keeps the first N reference scans of the log (and the events
up to the last of them), the same window for every filter; 0 keeps the whole log. README and docs/datasets.md say
why (the recorded suite's CPU time).

Plausibility (:mod:`~locbench.datasets.recorded.plausibility`)
--------------------------------------------------------------
The policy's bounds, with the range tightened to 100 m (:data:`RADISH_BOUNDS`): the scanners of these logs are SICK
LMS / PLS units, whose range field holds at most 8191 cm (81.91 m, also their no-return value; the other logs write
50, 51.25 or 32.767 m); 100 m leaves room for another 2-D scanner's log and none for a corrupted number.

* A **beam** beyond the range bound is no measurement at all: it is read as a no-return (``inf``, nothing in the
  map), like the scanner's own saturation value, and listed as a flagged "laser beam" sample (the scan keeps its other
  beams); the no-return threshold is taken from the plausible readings only, so one absurd range cannot turn every
  saturated beam into a wall at the saturation distance. The whole scan is not dropped: its other beams are good
  measurements.
* A **reference pose** (one FLASER message: its scan and its pose) is flagged when its heading is beyond
  ``heading_abs_rad`` before wrapping, or when the track bound (:meth:`~.plausibility.Flags.flag_track`) finds it
  unreachable from the last accepted pose. The track is judged in file order on a scan clock of
  :data:`SCAN_PERIOD_S` a scan (at most 5.05 m and 10.1 rad from the last accepted pose, a scan before): the
  corrected logs keep a scan per stretch of travel (the shared logs' largest step between consecutive scans is
  3.28 m, orebro), their stamps are unusable on several sites, and intel's raw scan stamps jitter by up to 0.9 s
  (judged on them, 8 of its poses would look faster than 5 m/s). It is the clock the semi-synthetic sites run on; a
  flag of a paired site carries its raw scan's stamp. A flagged pose is left out of the events, the reference and
  the map; the fraction and span rules count scans of the whole log.
* A **raw odometry increment** (paired sites; between consecutive ODOM messages by stamp) faster than the speed or
  turn bound over its interval is flagged and left out (a 50 m spike drops its increment and the one back). The
  interval is widened by the log's stamp uncertainty, the largest step back of its ODOM stamps in file order
  (intel.clf: 0.90 s; aces and fr079: 0): ordered by such stamps, intel's consecutive increments step up to 0.92 m
  back and forth within milliseconds (191 of 26915 beyond the bound over the bare interval), which is the stamps'
  jitter, not the robot's motion.
* Refused (structural): a FLASER with more than :data:`~locbench.core.limits.MAX_LASER_BEAMS` beams (at parse, before
  its ranges are read), and a PARAM given twice within one logging session (its lines between two
  ``# message formats defined`` header comments), naming both lines. A PARAM restated by a later session's header
  takes that session's value: belgioioso's log starts with a two-line header (``robot_frontlaser_offset 0.0``) and
  then the robot's own (-0.04 m).

Errors: a missing file (naming where it was looked for), a checksum mismatch of a published site, a file that is
not gzip or decompresses beyond :data:`MAX_LOG_BYTES`, a last FLASER line without its line end (a last line of
another type without one is left out and named in ``metadata``: freiburg-101 ends in a cut ODOM line), every
CARMEN parse error (file, line, field), a log with fewer than 2 FLASER messages, a FLASER pose or range beyond the
CARMEN reader's bounds, a laser offset that is not a number within 10 m, a field of view outside (0, 2 pi], a
paired site whose raw log pairs fewer than :data:`MIN_PAIRED_FRACTION` of the corrected scans, a grid above
``max_grid_cells`` (refused before it is allocated): each raises
:class:`~locbench.datasets.recorded.files.RecordedDataError` naming the file.
"""

from __future__ import annotations

import functools
import gzip
import hashlib
import itertools
import math
import os
import re
import zlib
from collections import defaultdict
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from locbench.core.errors import ConfigError
from locbench.core.events import Event, LaserScan, Odometry
from locbench.core.geometry import between, wrap_angle
from locbench.core.limits import MAX_LASER_BEAMS
from locbench.core.spec import bound
from locbench.datasets.dataset import (
    Dataset,
    FlaggedSample,
    Gaussian2,
    LineMap,
    OccupancyGrid,
    SensorSpec,
    Trajectory2D,
    WorldMap,
    sort_events,
)
from locbench.datasets.recorded.carmen import FREIBURG_MAX_BACKSTEP_S, CarmenLog, parse_carmen_bytes, read_carmen
from locbench.datasets.recorded.common import RecordedDataset
from locbench.datasets.recorded.files import (
    MAX_GRID_CELLS,
    MAX_GRID_CELLS_BOUND,
    MissingDataFile,
    RecordedDataError,
    RemoteFile,
    data_root,
    locate,
    quote,
    verify_sha256,
)
from locbench.datasets.recorded.plausibility import BOUNDS, Flags, merge
from locbench.datasets.recorded.reference import GMAPPING_SIGMA_M, SLAM_INITIAL_SIGMA, derive_odometry_noise
from locbench.datasets.recorded.scan_map import (
    MAX_RESOLUTION_M,
    MIN_RESOLUTION_M,
    build_occupancy_grid,
    extract_map_lines,
)
from locbench.datasets.splits import RADISH_SPLIT, Split

FloatArray = npt.NDArray[np.float64]

FOLDER = "radish_corrected"
RAW_FOLDER = "freiburg_slam_benchmark"
SUFFIX = "-corrected.log.gz"
#: sha256 of the published corrected logs (SOURCES.md section 6); other sites are read unverified.
KNOWN_SHA256: dict[str, str] = {
    "acapulco": "fbd19a018534dee751606a9520fd6be25c86f3d7f1f7d849b1834d047b330116",
    "aces": "5434d44384166250608a64d3a8c32de84512f82c46cb60a2657f138592024569",
    "belgioioso": "a130e3e6d9e5ec5e6a7f94cbb5cb6bca2df2626c7ed6bebb7b7a282253b10f6e",
    "csail": "a98de24fc319651f231f9a8625b78bf1972312b86f7b00d2ddc979c4ac92ae2d",
    "freiburg-079": "0631d30baf4b9d1d209af47da9096e876e1b4cb3d5a2d68ef9c39c5a2360a466",
    "freiburg-101": "7792de88bcb050f8edba92914aea75e8ec2fb73b483c01903bd2753aa655e982",
    "freiburg-campus": "534fae978c3a28fd9994c9b3327a36a2752df8339e232b9b70f96f67f76341b0",
    "infinite-corridor": "6a63c51eb97aa4e720fe207e91f926c283f77b4c534903983f9c5a6cbed6ebc4",
    "intel": "71bef16e9926506cf7417995ef35ace09dbd5de067fd042a3aab85188b5480dc",
    "orebro": "39a189c64489b84996669bc484d6bd6864f8733029a280a0e549a0adaae08a82",
    "seattle": "5719198036b788d78a877ca04efdbfb07c2518508310f51d49c198bf1956bb4b",
}
#: The raw logs of the Freiburg SLAM benchmark that hold the real odometry of a site (SOURCES.md section 3).
RAW_LOGS: dict[str, RemoteFile] = {
    "intel": RemoteFile(
        f"{RAW_FOLDER}/intel.clf", sha256="8db0ad6231b48bad4118e6a2dc78e83213b2c306be3b4ed80a90969891abfe7b"
    ),
    "aces": RemoteFile(
        f"{RAW_FOLDER}/aces.clf", sha256="1b6a069ebbfe261f2bae8bfe1ee91426932d2b964e8c2c0927b15663a4297390"
    ),
    "freiburg-079": RemoteFile(
        f"{RAW_FOLDER}/fr079.clf", sha256="d7ef6348cf29c2b71702f3a3ac779cb19a28184e11a031ee4150ec3b5f4696e6"
    ),
}
#: A site name: what may stand before ``-corrected.log.gz`` (letters, digits, '-', '_', '.'; no path separator).
SITE_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,99}$")
#: Largest decompressed log, bytes (the largest published one, freiburg-079, is about 19 MB).
MAX_LOG_BYTES = 256 * 1024 * 1024
#: A reading at or above this fraction of the log's largest reading is a no-return (module docstring).
NO_RETURN_FRACTION = 0.98
#: Fewest corrected scans a paired site's raw log must pair, as a fraction.
MIN_PAIRED_FRACTION = 0.9
#: Time between scans of a semi-synthetic site, s (the logs' stamps are unusable).
SCAN_PERIOD_S = 1.0
#: Default event window: the first N reference scans (README "Recorded data": the CPU budget).
DEFAULT_MAX_SCANS = 0
#: Default cell side of every site's map, m.
DEFAULT_RESOLUTION_M = 0.1
#: The plausibility policy's bounds with the range tightened to the scanners' (module docstring "Plausibility").
RADISH_BOUNDS = BOUNDS.tightened(range_m=100.0)


@dataclass(frozen=True)
class EncoderError:
    """Simulated encoder error of the semi-synthetic sites (the increment model of the module docstring).

    Attributes
    ----------
    sigma_xy_per_m : float
        m / sqrt(m).
    sigma_theta_per_m : float
        rad / sqrt(m).
    sigma_theta_per_rad : float
        rad / sqrt(rad).
    pairs : int
        Consecutive paired-scan pairs the fit used (all three sites).
    """

    sigma_xy_per_m: float
    sigma_theta_per_m: float
    sigma_theta_per_rad: float
    pairs: int


#: Output of ``tools/derive/fit_radish_odometry.py`` (:func:`fit_encoder_error` on intel, aces and freiburg-079 over
#: their whole logs); tests/datasets/recorded/test_recorded_radish.py reruns the fit and compares.
ENCODER_ERROR = EncoderError(
    sigma_xy_per_m=0.08102589100709597,
    sigma_theta_per_m=0.0574425450998974,
    sigma_theta_per_rad=0.06248129752845295,
    pairs=6138,
)


@dataclass(frozen=True, kw_only=True)
class RadishParams:
    """Parameters of ``radish``.

    Attributes
    ----------
    site : str
        The ``NAME`` of ``radish_corrected/NAME-corrected.log.gz``.
    root : str
        Data root holding ``radish_corrected/`` (and ``freiburg_slam_benchmark/``); empty: ``$LOCBENCH_DATA``.
    map_resolution_m : float
        Cell side of the occupancy grid, m, in [MIN_RESOLUTION_M, MAX_RESOLUTION_M].
    max_grid_cells : int
        Largest occupancy grid built, cells.
    max_scans : int
        Event window: the first N reference scans (0: the whole log).
    """

    site: str = "intel"
    root: str = ""
    map_resolution_m: float = DEFAULT_RESOLUTION_M
    max_grid_cells: int = field(default=MAX_GRID_CELLS, metadata=bound(1, MAX_GRID_CELLS_BOUND, what="a cell count"))
    max_scans: int = DEFAULT_MAX_SCANS

    def __post_init__(self) -> None:
        if not SITE_PATTERN.match(self.site):
            raise ConfigError(
                f"parameter 'site' is {quote(self.site)}, expected the NAME of a radish_corrected/NAME{SUFFIX} "
                "(letters, digits, '.', '_', '-')"
            )
        if not MIN_RESOLUTION_M <= self.map_resolution_m <= MAX_RESOLUTION_M:
            raise ConfigError(
                f"parameter 'map_resolution_m' must be a cell side in [{MIN_RESOLUTION_M}, {MAX_RESOLUTION_M}] m, "
                f"got {self.map_resolution_m!r}"
            )
        if self.max_grid_cells < 1:
            raise ConfigError(f"parameter 'max_grid_cells' must be >= 1, got {self.max_grid_cells!r}")
        if self.max_scans < 0:
            raise ConfigError(f"parameter 'max_scans' must be >= 0 (0: the whole log), got {self.max_scans!r}")


def available_sites(root: str | os.PathLike[str] | None = None) -> list[str]:
    """The sites whose ``NAME-corrected.log.gz`` is in ``<root>/radish_corrected/`` (sorted; empty without it)."""
    base = data_root(root)
    if base is None or not (base / FOLDER).is_dir():
        return []
    names = (p.name[: -len(SUFFIX)] for p in (base / FOLDER).iterdir() if p.name.endswith(SUFFIX) and p.is_file())
    return sorted(n for n in names if SITE_PATTERN.match(n))


# --- reading -----------------------------------------------------------------------------------------


def decompress_log(path: str | os.PathLike[str], limit: int | None = None) -> bytes:
    """The decompressed bytes of a ``.gz`` log, read in chunks and refused beyond ``limit`` bytes
    (None: :data:`MAX_LOG_BYTES`)."""
    p = Path(path)
    limit = MAX_LOG_BYTES if limit is None else limit
    out = bytearray()
    try:
        with gzip.open(p, "rb") as f:
            while chunk := f.read(1 << 20):
                out += chunk
                if len(out) > limit:
                    raise RecordedDataError(
                        p, f"decompresses to more than {limit} bytes, expected a CARMEN log of at most {limit} bytes"
                    )
    except FileNotFoundError:
        raise MissingDataFile(p, "missing file (expected a gzip-compressed corrected CARMEN log)") from None
    except (OSError, EOFError, zlib.error) as exc:
        raise RecordedDataError(p, f"not a readable gzip file ({type(exc).__name__}: {exc})") from None
    return bytes(out)


_DIGESTS: dict[tuple[str, int, int], str] = {}


def content_sha256(path: Path) -> str:
    """sha256 of a file's bytes, memoised per (path, size, mtime)."""
    st = path.stat()
    key = (str(path.resolve()), st.st_size, st.st_mtime_ns)
    if key not in _DIGESTS:
        _DIGESTS[key] = hashlib.sha256(path.read_bytes()).hexdigest()
    return _DIGESTS[key]


@dataclass(frozen=True, eq=False)
class CorrectedLog:
    """The checked FLASER content of one corrected log (arrays read-only)."""

    path: Path
    sha256: str
    log: CarmenLog
    angle_min: float
    angle_increment: float
    no_return_m: float
    laser_offset_m: float
    #: The message type of a last line without its line end that was left out (freiburg-101 ends in a cut ODOM).
    dropped_last_line: str = ""
    #: Per FLASER message: False where its reference pose is flagged (module docstring "Plausibility").
    scan_kept: npt.NDArray[np.bool_] = field(default_factory=lambda: np.ones(0, dtype=bool))
    #: The flagged reference poses and beams, timed on the scan clock (scan k at k * SCAN_PERIOD_S, file order).
    flagged: tuple[FlaggedSample, ...] = ()


@functools.lru_cache(maxsize=4)
def _read_corrected(digest: str) -> CorrectedLog:
    p = Path(_PATHS[digest])
    raw = decompress_log(p)
    unterminated = ""
    if raw and not raw.endswith(b"\n"):
        cut = raw.rfind(b"\n") + 1
        tail = raw[cut:].split()
        if tail[:1] != [b"FLASER"]:  # a cut ODOM/NEFF line is not read; a cut scan still is an error below
            unterminated = tail[0].decode("ascii", "replace") if tail else ""
            raw = raw[:cut]
    log = parse_carmen_bytes(p, raw, max_beams=MAX_LASER_BEAMS)
    _refuse_repeated_params(p, log)
    las = log.flaser
    if len(las) < 2:
        raise RecordedDataError(p, f"{len(las)} FLASER message(s), expected the corrected scans (at least 2)")
    n = las.ranges.shape[1]
    fov = _param_number(p, log, "laser_front_laser_fov", math.pi, 0.0, 2 * math.pi, "the laser's field of view in rad")
    if fov <= 0.0:
        raise RecordedDataError(p, f"PARAM laser_front_laser_fov is {fov!r}, expected a field of view in (0, 2 pi]")
    inc = fov / n if n % 2 == 0 or n == 1 else fov / (n - 1)
    offset = _param_number(p, log, "robot_frontlaser_offset", 0.0, -10.0, 10.0, "the laser's offset in m (within 10 m)")
    # the saturation value from the plausible readings: one absurd range must not move it (module docstring)
    plausible = las.ranges[las.ranges <= RADISH_BOUNDS.range_m]
    top = float(plausible.max()) if plausible.size else 0.0
    if not top > 0.0:
        raise RecordedDataError(
            p, f"every FLASER range is 0 or beyond {RADISH_BOUNDS.range_m:g} m, expected laser readings"
        )
    kept, flagged = _log_flags(p, log)
    return CorrectedLog(p, digest, log, -0.5 * fov, inc, NO_RETURN_FRACTION * top, offset, unterminated, kept, flagged)


def _log_flags(p: Path, log: CarmenLog) -> tuple[npt.NDArray[np.bool_], tuple[FlaggedSample, ...]]:
    """The kept reference poses and the flagged samples of a corrected log (module docstring "Plausibility").

    Judged in file order on the scan clock (scan k at k * :data:`SCAN_PERIOD_S`): the corrected logs keep a scan per
    stretch of travel and their stamps are unusable on several sites (and jitter by up to 0.9 s on intel), so a
    pose is reachable when it lies within 5.05 m and 10.1 rad of the last accepted one, a scan before.
    """
    las = log.flaser
    clock = SCAN_PERIOD_S * np.arange(len(las), dtype=np.float64)
    pose = np.asarray(las.pose)
    ref = Flags(p, "reference pose", clock, las.lines)
    h = RADISH_BOUNDS.heading_abs_rad
    ref.flag_outside(pose[:, 2], "heading before wrapping, rad", -h, h)
    ref.flag_track(pose[:, :2], pose[:, 2], RADISH_BOUNDS)
    flagged = [ref.finish()]
    if (las.ranges > RADISH_BOUNDS.range_m).any():  # else no per-beam arrays (the common case)
        beams = las.ranges.shape[1]
        per_beam = Flags(p, "laser beam", np.repeat(clock, beams), np.repeat(las.lines, beams))
        per_beam.flag_outside(las.ranges.ravel(), "range (read as a no-return), m", 0.0, RADISH_BOUNDS.range_m)
        flagged.append(per_beam.finish())
    return ref.kept, merge(*flagged)


def read_corrected(path: str | os.PathLike[str], sha256: str | None = None) -> CorrectedLog:
    """Read and check one corrected log (module docstring), verifying ``sha256`` when given; cached by content."""
    p = Path(path)
    if not p.is_file():
        raise MissingDataFile(p, "missing file (expected a gzip-compressed corrected CARMEN log)")
    if sha256:
        verify_sha256(p, sha256)
    digest = content_sha256(p)
    _PATHS[digest] = str(p.resolve())
    return _read_corrected(digest)


def _refuse_repeated_params(p: Path, log: CarmenLog) -> None:
    """Refuse a PARAM given twice within one logging session (no header comment between its lines)."""
    for name, at in log.param_lines.items():
        for a, b in itertools.pairwise(at):
            if not any(a < h < b for h in log.header_lines):
                raise RecordedDataError(
                    p,
                    f"PARAM {name} given twice, on lines {a} and {b}, expected each parameter once per logging "
                    "session (a '# message formats defined' header starts a session)",
                    b,
                )


def _param_number(p: Path, log: CarmenLog, name: str, default: float, lo: float, hi: float, what: str) -> float:
    text = log.params.get(name)
    if text is None:
        return default
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and lo <= value <= hi):
        raise RecordedDataError(p, f"PARAM {name} is {quote(text)}, expected {what}")
    return value


# --- pairing with the raw log -------------------------------------------------------------------------


def pair_scans(corrected: npt.ArrayLike, raw: npt.ArrayLike) -> npt.NDArray[np.int64]:
    """Index into ``raw`` of the scan with identical ranges to each corrected scan, or -1 (module docstring).

    Parameters
    ----------
    corrected, raw : array-like, shape (n, B) and (m, B)
        Ranges as logged, m (compared exactly).

    Returns
    -------
    ndarray of int64, shape (n,)
        Strictly increasing over the paired entries (a repeated scan pairs with the next raw copy).
    """
    c = np.ascontiguousarray(corrected, dtype=np.float64)
    r = np.ascontiguousarray(raw, dtype=np.float64)
    out = np.full(c.shape[0], -1, dtype=np.int64)
    if c.ndim != 2 or r.ndim != 2 or c.shape[1] != r.shape[1]:
        return out
    where: dict[bytes, list[int]] = defaultdict(list)
    for i in range(r.shape[0]):
        where[r[i].tobytes()].append(i)
    prev = -1
    for k in range(c.shape[0]):
        cand = where.get(c[k].tobytes())
        if not cand:
            continue
        j = int(np.searchsorted(cand, prev, side="right"))
        if j < len(cand):
            prev = out[k] = cand[j]
    return out


@dataclass(frozen=True, eq=False)
class Pairing:
    """A corrected log paired with its raw log: raw scan index per corrected scan (-1: unpaired)."""

    raw: CarmenLog
    index: npt.NDArray[np.int64]

    @property
    def paired(self) -> int:
        return int(np.count_nonzero(self.index >= 0))


def paired_raw(
    site: str, corrected: CorrectedLog, root: str | os.PathLike[str] | None, verify: bool = True
) -> Pairing | None:
    """The raw log of a paired site and the pairing (None for a site without a raw log)."""
    spec = RAW_LOGS.get(site)
    if spec is None:
        return None
    raw_path = locate(spec, root, verify=verify)
    raw = read_carmen(raw_path, max_backstep_s=FREIBURG_MAX_BACKSTEP_S, max_beams=MAX_LASER_BEAMS)
    idx = pair_scans(corrected.log.flaser.ranges, raw.flaser.ranges)
    pairing = Pairing(raw, idx)
    need = math.ceil(MIN_PAIRED_FRACTION * len(corrected.log.flaser))
    if pairing.paired < need:
        raise RecordedDataError(
            raw_path,
            f"{pairing.paired} of {len(corrected.log.flaser)} scans of {corrected.path.name} have a raw scan of "
            f"identical ranges, expected at least {need} (the raw log of the same recording)",
        )
    return pairing


def paired_poses(corrected: CorrectedLog, pairing: Pairing) -> tuple[FloatArray, FloatArray]:
    """The raw odometry pose and the reference pose at every paired scan, ordered by the raw scan's stamp."""
    sel = np.flatnonzero(pairing.index >= 0)
    raw_idx = pairing.index[sel]
    order = np.argsort(pairing.raw.flaser.ipc_t[raw_idx], kind="stable")
    odom = np.asarray(pairing.raw.flaser.odom_pose)[raw_idx[order]]
    ref = np.asarray(corrected.log.flaser.pose)[sel[order]]
    return odom, ref


def fit_paired_sites(root: str | os.PathLike[str] | None = None, split: Split = RADISH_SPLIT) -> EncoderError:
    """:func:`fit_encoder_error` over the tuning sites of ``split`` that have raw odometry (:data:`RAW_LOGS`; with
    :data:`~locbench.datasets.splits.RADISH_SPLIT` all three of them), in name order: what
    ``tools/derive/fit_radish_odometry.py`` prints. A test site is never read.

    Raises
    ------
    ConfigError
        No tuning site of ``split`` has raw odometry.
    """
    sites = split.check_tuning(s for s in sorted(RAW_LOGS) if s in split.tuning)
    if not sites:
        raise ConfigError(f"split {split.name}: no tuning site has raw odometry ({', '.join(sorted(RAW_LOGS))})")
    pairs = []
    for site in map(str, sites):
        path = locate(RemoteFile(f"{FOLDER}/{site}{SUFFIX}", sha256=KNOWN_SHA256.get(site)), root)
        cl = read_corrected(path)
        pairing = paired_raw(site, cl, root)
        assert pairing is not None
        pairs.append(paired_poses(cl, pairing))
    return fit_encoder_error(pairs)


def fit_encoder_error(pairs: list[tuple[FloatArray, FloatArray]]) -> EncoderError:
    """Pooled method-of-moments fit of the increment model (module docstring) over several logs.

    Parameters
    ----------
    pairs : list of (odometry poses (n, 3), reference poses (n, 3))
        Per log, the raw odometry pose and the reference pose at each paired scan, in time order.
    """
    o = np.concatenate([_stack_increments(a, b)[0] for a, b in pairs])
    e = np.concatenate([_stack_increments(a, b)[1] for a, b in pairs])
    # the same estimator as one log's derive_odometry_noise, fed the pooled increments through poses that compose to
    # them: integrate u and z from the origin so that between() gives them back
    u_poses = _integrate(o)
    z_poses = _integrate(_compose_inc(o, e))
    sxy, stm, str_ = derive_odometry_noise(u_poses, z_poses)
    return EncoderError(sxy, stm, str_, int(o.shape[0]))


def _stack_increments(odom: FloatArray, ref: FloatArray) -> tuple[FloatArray, FloatArray]:
    u = between(odom[:-1], odom[1:])
    z = between(ref[:-1], ref[1:])
    return u, between(u, z)


def _compose_inc(u: FloatArray, e: FloatArray) -> FloatArray:
    """z with between(u, z) = e, row by row (z = u (+) e)."""
    c, s = np.cos(u[:, 2]), np.sin(u[:, 2])
    return np.column_stack(
        [u[:, 0] + c * e[:, 0] - s * e[:, 1], u[:, 1] + s * e[:, 0] + c * e[:, 1], u[:, 2] + e[:, 2]]
    )


def _integrate(inc: FloatArray) -> FloatArray:
    out = np.zeros((inc.shape[0] + 1, 3))
    x = y = th = 0.0
    for k, (dx, dy, dth) in enumerate(inc.tolist()):
        c, s = math.cos(th), math.sin(th)
        x, y, th = x + c * dx - s * dy, y + s * dx + c * dy, th + dth
        out[k + 1] = (x, y, th)
    return out


def simulate_encoder_error(increments: FloatArray, err: EncoderError, rng: np.random.Generator) -> FloatArray:
    """Reference increments (n, 3) with the zero-mean error of the increment model added (module docstring)."""
    d = np.hypot(increments[:, 0], increments[:, 1])
    a = np.abs(increments[:, 2])
    z = rng.standard_normal(increments.shape)
    sd = np.column_stack(
        [
            err.sigma_xy_per_m * np.sqrt(d),
            err.sigma_xy_per_m * np.sqrt(d),
            np.sqrt(err.sigma_theta_per_m**2 * d + err.sigma_theta_per_rad**2 * a),
        ]
    )
    return increments + sd * z


# --- map -----------------------------------------------------------------------------------------------


#: The latest path seen with each content sha256 (what the content-keyed caches read, and name in messages).
_PATHS: dict[str, str] = {}


@functools.lru_cache(maxsize=4)
def _site_map(digest: str, resolution_m: float, max_cells: int) -> tuple[OccupancyGrid, LineMap | None, dict[str, Any]]:
    path = _PATHS[digest]
    cl = _read_corrected(digest)
    las = cl.log.flaser
    use = np.flatnonzero(cl.scan_kept)  # a flagged reference pose paints nothing
    angles = cl.angle_min + cl.angle_increment * np.arange(las.ranges.shape[1])
    pose = _laser_poses(np.asarray(las.pose)[use], cl.laser_offset_m)
    with np.errstate(over="ignore"):  # exp(-l) of a cell missed thousands of times overflows to inf: p = 0 exactly
        grid = build_occupancy_grid(
            pose, las.ranges[use], angles, resolution_m, max_range_m=cl.no_return_m, max_cells=max_cells, source=path
        )
    grid.occupancy.setflags(write=False)
    stats: dict[str, Any] = {
        "resolution_m": resolution_m,
        "rows": grid.shape[0],
        "cols": grid.shape[1],
        "scans": int(use.shape[0]),
        "sha256_input": digest,
    }
    lines: LineMap | None
    try:
        lines, line_stats = extract_map_lines(grid)
        lines.segments.setflags(write=False)
        stats |= line_stats
        stats["lines"] = "extracted"
    except ConfigError as exc:  # too many occupied cells for the Hough bound: no line map (ekf_lines is skipped)
        lines = None
        stats["lines"] = f"none: {exc}"
    return grid, lines, stats


def site_map(
    path: str | os.PathLike[str], resolution_m: float = DEFAULT_RESOLUTION_M, max_cells: int = MAX_GRID_CELLS
) -> tuple[OccupancyGrid, LineMap | None, dict[str, Any]]:
    """The occupancy grid, line map (or None) and map statistics of a corrected log, cached by its sha256."""
    p = Path(path)
    cl = read_corrected(p)
    _PATHS[cl.sha256] = str(p.resolve())
    return _site_map(cl.sha256, float(resolution_m), int(max_cells))


def _laser_poses(pose: FloatArray, offset: float) -> FloatArray:
    out = pose.copy()
    out[:, 0] += offset * np.cos(pose[:, 2])
    out[:, 1] += offset * np.sin(pose[:, 2])
    return out


# --- the dataset -----------------------------------------------------------------------------------------


def load_radish(
    site: str,
    root: str | os.PathLike[str] | None = None,
    rng: np.random.Generator | None = None,
    *,
    map_resolution_m: float = DEFAULT_RESOLUTION_M,
    max_grid_cells: int = MAX_GRID_CELLS,
    max_scans: int = DEFAULT_MAX_SCANS,
    verify: bool = True,
    encoder_error: EncoderError | None = None,
) -> Dataset:
    """The dataset of one site (module docstring).

    Parameters
    ----------
    site : str
        ``NAME`` of ``radish_corrected/NAME-corrected.log.gz``.
    root : path-like or None
        Data root; None: ``$LOCBENCH_DATA``.
    rng : numpy Generator or None
        Draws the semi-synthetic encoder error (unused on a paired site); None: seed 0.
    map_resolution_m, max_grid_cells, max_scans
        See :class:`RadishParams`.
    verify : bool
        Check the sha256 of a published site's file.
    encoder_error : EncoderError or None
        Overrides :data:`ENCODER_ERROR`.
    """
    # long: the loader's steps over one site's files in order, with their refusals; the numpydoc is a third of it
    spec = RemoteFile(f"{FOLDER}/{site}{SUFFIX}", sha256=KNOWN_SHA256.get(site) if verify else None)
    path = locate(spec, root, verify=verify)
    cl = read_corrected(path)
    las = cl.log.flaser
    n_all = len(las)
    pose_all = np.asarray(las.pose)
    ref_all = np.column_stack([pose_all[:, :2], wrap_angle(pose_all[:, 2])])
    ranges_all = np.where(las.ranges >= cl.no_return_m, np.inf, las.ranges)
    pairing = paired_raw(site, cl, root, verify)
    # the run's scans in time order and their times: the raw scan's stamp, or SCAN_PERIOD_S a scan
    if pairing is not None:
        scans = np.flatnonzero(pairing.index >= 0)
        scan_t = pairing.raw.flaser.ipc_t[pairing.index[scans]]
        order = np.argsort(scan_t, kind="stable")
        scans, scan_t = scans[order], scan_t[order]
    else:
        scans = np.arange(n_all)
        scan_t = SCAN_PERIOD_S * scans.astype(np.float64)
    grid, lines, map_stats = site_map(path, map_resolution_m, max_grid_cells)
    metadata: dict[str, Any] = {
        "source": f"Radish corrected CARMEN log {path.name} (Howard & Roy 2003); copy of acschaefer/ple cfcb5a7",
        "file": str(path),
        "site": site,
        "reference": "SLAM-corrected poses of the same log (not independent ground truth); the map is built from them",
        "reference_kind": "SLAM",
        "reference_scans": n_all,
        "no_return_m": cl.no_return_m,
        "dropped_unterminated_last_line": cl.dropped_last_line,
        "beams": int(las.ranges.shape[1]),
        "map": map_stats,
    }
    sources = [str(path)]
    events: list[Event] = []
    err = encoder_error if encoder_error is not None else ENCODER_ERROR
    # the log's flags carry the run's times: the paired raw stamp, else the corrected log's own stamp
    when = dict(zip(las.lines.tolist(), las.ipc_t.tolist(), strict=True)) if pairing is not None else {}
    when.update(zip(las.lines[scans].tolist(), scan_t.tolist(), strict=True))
    flagged = [tuple(replace(f, t=when[f.line]) for f in cl.flagged)]
    kept = cl.scan_kept[scans]
    keep, ref_t = scans[kept], scan_t[kept]
    if max_scans:
        keep, ref_t = keep[:max_scans], ref_t[:max_scans]
    ref = ref_all[keep]
    if pairing is not None:
        raw = pairing.raw
        t0, t1 = float(ref_t[0]), float(ref_t[-1])
        od = raw.odom
        o_order = np.argsort(od.ipc_t, kind="stable")
        ot, op = od.ipc_t[o_order], od.pose[o_order]
        inc = between(op[:-1], op[1:])
        # a spike in the odometry pose: its increment and the one back are flagged and left out; each interval is
        # widened by the stamps' own uncertainty, the largest step back in file order (intel: 0.90 s)
        slack_s = max(0.0, -float(np.diff(od.ipc_t).min(initial=0.0)))
        odo_flags = Flags(raw.path, "odometry", ot[1:], od.lines[o_order][1:])
        odo_flags.flag_increments(np.hypot(inc[:, 0], inc[:, 1]), inc[:, 2], np.diff(ot) + slack_s, RADISH_BOUNDS)
        flagged.append(odo_flags.finish())
        for k in np.flatnonzero((ot[1:] >= t0) & (ot[1:] <= t1) & odo_flags.kept):
            events.append(Odometry(float(ot[k + 1]), float(inc[k, 0]), float(inc[k, 1]), float(inc[k, 2])))
        if not events:
            raise RecordedDataError(raw.path, f"no ODOM message inside the paired scans' span [{t0!r}, {t1!r}] s")
        for kk, t in zip(keep.tolist(), ref_t.tolist(), strict=True):
            events.append(_scan(cl, t, ranges_all[kk]))
        sxy, stm, str_ = derive_odometry_noise(*paired_poses(cl, pairing))
        metadata["odometry"] = f"raw odometry of {raw.path.name}, paired with the corrected scans by identical ranges"
        metadata["pairing"] = {"corrected_scans": n_all, "paired": pairing.paired, "raw_scans": len(raw.flaser)}
        sources.append(str(raw.path))
    else:
        u = between(ref[:-1], ref[1:])
        gen = rng if rng is not None else np.random.default_rng(0)
        noisy = simulate_encoder_error(u, err, gen)
        for j in range(keep.shape[0]):
            if j > 0:
                events.append(Odometry(float(ref_t[j]), *(float(v) for v in noisy[j - 1])))
            events.append(_scan(cl, float(ref_t[j]), ranges_all[keep[j]]))
        sxy, stm, str_ = err.sigma_xy_per_m, err.sigma_theta_per_m, err.sigma_theta_per_rad
        metadata["odometry"] = (
            "semi-synthetic: reference increments with simulated encoder error (fitted on intel, aces, freiburg-079)"
        )
        metadata["semi_synthetic"] = True
        metadata["encoder_error"] = {"sigma_xy_per_m": sxy, "sigma_theta_per_m": stm, "sigma_theta_per_rad": str_}
    metadata["window"] = {"max_scans": max_scans, "scans_used": int(keep.shape[0])}
    sensors = SensorSpec(
        laser_sigma_m=GMAPPING_SIGMA_M,
        odometry_sigma_xy_per_m=sxy,
        odometry_sigma_theta_per_m=stm,
        odometry_sigma_theta_per_rad=str_,
    )
    truth = Trajectory2D(np.asarray(ref_t, dtype=np.float64).copy(), ref[:, :2].copy(), ref[:, 2].copy())
    initial = Gaussian2(ref[0].copy(), np.diag(np.square(SLAM_INITIAL_SIGMA)))
    return Dataset(
        id="radish",
        params={"site": site},
        events=sort_events(events),
        ground_truth=truth,
        initial=initial,
        world=WorldMap(occupancy=grid, lines=lines),
        sensors=sensors,
        metadata=metadata,
        truth_label="SLAM reference",
        sources=tuple(sources),
        declared=frozenset({LaserScan}),
        flagged=merge(*flagged),
    )


def _scan(cl: CorrectedLog, t: float, ranges: FloatArray) -> LaserScan:
    return LaserScan(
        float(t),
        cl.angle_min,
        cl.angle_increment,
        ranges.copy(),
        0.0,
        cl.no_return_m,
        (cl.laser_offset_m, 0.0, 0.0),
    )


def semi_synthetic(site: str) -> bool:
    """Whether a site's odometry is simulated (no raw log pairs with it)."""
    return site not in RAW_LOGS


class RadishDataset(RecordedDataset):
    """Radish corrected CARMEN logs: scans, SLAM reference, map from the reference; raw or semi-synthetic odometry."""

    id: ClassVar[str] = "radish"
    Params: ClassVar[type] = RadishParams
    version: ClassVar[int] = 1
    description: ClassVar[str] = (
        "Radish corrected CARMEN logs (recorded, any NAME-corrected.log.gz): laser, map and SLAM reference; "
        "raw odometry for intel, aces, freiburg-079, semi-synthetic elsewhere"
    )
    folder: ClassVar[str] = FOLDER
    reference_kind: ClassVar[str] = "SLAM"
    identity_keys: ClassVar[tuple[str, ...]] = ("site",)

    @classmethod
    def recording(cls, params: RadishParams) -> str | None:
        """``radish[site=NAME]``; the ``intel`` site is the log the ``intel`` loader reads (the Intel Research Lab
        run, its corrected and raw forms), so it names that loader's recording."""
        return "intel" if params.site == "intel" else super().recording(params)

    @classmethod
    def files(cls, params: RadishParams) -> list[RemoteFile]:
        """The site's corrected log (verified when published) and, for a paired site, its raw log."""
        out = [RemoteFile(f"{FOLDER}/{params.site}{SUFFIX}", sha256=KNOWN_SHA256.get(params.site))]
        if params.site in RAW_LOGS:
            out.append(RAW_LOGS[params.site])
        return out

    def build(self, params: RadishParams, rng: np.random.Generator) -> Dataset:
        """The site (the semi-synthetic odometry error is drawn from ``rng``)."""
        root = params.root or None
        for spec in self.files(params):
            locate(spec, root)
        return load_radish(
            params.site,
            root,
            rng,
            map_resolution_m=params.map_resolution_m,
            max_grid_cells=params.max_grid_cells,
            max_scans=params.max_scans,
        )
