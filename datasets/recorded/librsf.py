"""libRSF ranging datasets (TU Chemnitz): the real Labyrinth UWB set and the simulated M3500 / W3500 ranging worlds.

Source and citation
-------------------
T. Pfeifer (TU Chemnitz), github.com/TUC-ProAut/libRSF ``datasets/`` (copied byte-for-byte at commit ``d54801a``;
SOURCES.md section 7, whose sha256 are in :data:`SHA256`). Licence: Creative Commons Attribution Share Alike 4.0
International (each folder's ``LICENSE.txt``). Papers: T. Pfeifer, P. Protzel, "Expectation-Maximization for
Adaptive Mixture Models in Graph Optimization", ICRA 2019; T. Pfeifer, S. Lange, P. Protzel, "Advancing Mixture
Models for Least Squares Optimization", RA-L 2021. M3500 comes from L. Carlone, A. Censi, IEEE T-RO 30(2), 2014;
W3500 from GTSAM's W10000.

Sets (``librsf[set=...]``)
--------------------------
* ``indoor_uwb``: ``Indoor_UWB/Indoor_UWB_{Input,GT}.txt``, a differential-drive robot in a labyrinth, UWB ranges to
  4 anchors, wheel-speed odometry, ground-truth position; about 30 s. ``noise`` must be empty.
* ``m3500`` / ``w3500`` with ``noise`` = ``heavy-tailed``, ``multimodal`` or ``skewed``:
  ``Ranging_Simulation/{M,W}3500_{noise}_Input.txt`` and ``{M,W}3500_GT.txt``: 3500 poses at 1 s, 8 ranges a pose to
  8 anchors, body-frame velocity odometry, ground-truth position and heading. The three files of a world share
  their odometry and range layout; only the range noise differs.
* ``noise=gaussian`` (generated here): the same world (the ``heavy-tailed`` file's odometry, anchors and range
  times) with every range replaced by the true distance |anchor - p_GT(t)| plus zero-mean Gaussian noise of the
  variance the files declare for their ranges (0.25 m^2 in all three), drawn from the dataset's seeded generator
  like every synthetic error. It is the Gaussian reference of the robustness table. The non-Gaussian files'
  empirical error variances differ from one another and from the declared one (their cores are near 0.25 m^2,
  their outlier components are not: M3500 about 298, 38 and 15 m^2 for heavy-tailed, multimodal and skewed;
  ``metadata["range_error"]`` gives each file's moments against the truth), so one reference per world at the
  declared variance is what the same world with Gaussian noise means here; a Gaussian of each file's own variance
  (``like=`` that noise) is available for a moment-matched comparison.

Format (one measurement a line; the first field names its type; blanks separate fields)
------------------------------------------------------------------------------------
``range2 t range var x_anchor y_anchor id snr`` (s, m, m^2, m, m, integer, unused);
``odom2 t vx vy omega var_vx var_vy var_omega`` (s, m/s, m/s, rad/s and their variances; body frame);
``odom2diff t v_right v_left v_y wheel_distance var_right var_left var_y`` (s, m/s, m/s, m/s, m, (m/s)^2);
``point2 t x y c11 c12 c21 c22`` (s, m, m, zero covariance) and ``angle t theta var`` (s, rad, rad^2).
Each type has exactly that many fields (:data:`FIELDS`); a type that does not belong to the file is an error.

What the dataset is made of
---------------------------
* **Odometry**: the sample at t_k covers [t_k-1, t_k] (checked on M3500: the first sample at t = 1 s moves the robot
  from the pose at 0 s to the pose at 1 s); the first sample covers the time since the truth's first row (none on
  Indoor UWB, whose first sample is at that time and is not used). ``odom2``: dx = vx dt, dy = vy dt, dtheta = omega
  dt. ``odom2diff``: v = (v_r + v_l) / 2, omega = (v_l - v_r) / (2 wheel_distance), dx = v dt cos(omega dt / 2), dy =
  v dt sin(omega dt / 2), dtheta = omega dt (the mid-rotation model), with the twist (v, omega, dt). The yaw rate's
  convention is established against the truth, not taken from the readme: dead reckoning from the first truth pose
  (heading pi) with omega = (v_r - v_l) / wheel_distance strays 1.9 m (RMS) from the truth over the 30 s, while (v_l -
  v_r) / (2 wheel_distance) follows it to 0.04 m RMS over the first 10 s (the readme's column order of the two wheels
  and the meaning of "distance between wheels", half the track, are what that implies; a test checks it).
* **Ranges** (:class:`~locbench.core.events.RangeObservations`): grouped per identical time, ids = the anchor ids;
  anchors (``world.landmarks``) from the lines' anchor positions (an id with two positions is an error).
* **Truth**: ``point2`` positions; heading from ``angle`` where the file has it (M3500, W3500), else (Indoor UWB)
  the direction of travel over a :data:`HEADING_CHORD_M` chord
  (:func:`~locbench.datasets.recorded.reference.heading_from_track`; the robot drives forwards), a derived heading
  used only by the heading metrics.
* **Initial belief**: the first truth pose, standard deviations :data:`INITIAL_SIGMA` (the UWB heading is derived,
  hence its larger value).
* **Nominal noise** (``SensorSpec``), the files' declared values: ``range_sigma_m`` = sqrt(median declared range
  variance) (constant within each file: 0.25 m^2 simulated, 0.01 m^2 UWB). Odometry: ``odom2diff`` gives the twist
  noise twist_sigma_v = sqrt((var_r + var_l) / 4), twist_sigma_omega = sqrt(var_r + var_l) / (2 wheel_distance);
  ``odom2`` (whose vy is not a unicycle's) gives the per-distance model with the declared per-step variances spread
  over the median step length D: sigma_xy_per_m = sqrt(mean(var_vx, var_vy) dt^2 / D),
  sigma_theta_per_m = sqrt(var_omega dt^2 / D) (the median over samples of each variance).

Window (CPU budget): ``max_steps`` keeps the truth and events up to the first N odometry samples (0: all; default
:data:`DEFAULT_MAX_STEPS`, the same for every filter; README "Recorded data" says why).

Plausibility (:mod:`~locbench.datasets.recorded.plausibility`)
--------------------------------------------------------------
The policy's bounds; for the Labyrinth's UWB ranges the range bound is tightened to 300 m (:data:`UWB_BOUNDS`):
UWB ranging under its emission limit (-41.3 dBm/MHz) reaches a few hundred metres at most in line of sight (the
policy's own figure for UWB), and the Labyrinth's ranges lie in [0.19, 3.37] m. Flagged and left out (the row is
listed in :attr:`Dataset.flagged <locbench.datasets.dataset.Dataset.flagged>`):

* a UWB range outside [0, 300] m; a range variance above ``variance_m2`` (1e4 m^2); a range2 row repeating the one
  before it;
* an odometry sample whose speed (``odom2diff``: (v_r + v_l) / 2; ``odom2``: |(vx, vy)|) or yaw rate is beyond the
  speed or turn bound, or repeating the one before it. The next kept sample covers the flagged one's interval (its
  velocity is held over both: velocities are continuous, and leaving the interval out would stop the robot);
* a truth row off the track (:meth:`~.plausibility.Flags.flag_track`: two positions 5 m apart at one time are an
  infinite speed), with a heading (``angle``) beyond ``heading_abs_rad`` before wrapping, or repeating the one
  before it; its ``angle`` row goes with it.

The simulated files' pseudoranges are not held to the range bound: their outliers (M3500 heavy-tailed: 25 rows
outside [0, 1000] m, multimodal 8, W3500 heavy-tailed 11, from -629 m to 2620 m) are the noise those files were made
with, what the robustness table measures; a pseudorange beyond +-MAX_POSITION_M is still refused. Refused
(structural): range and variance columns swapped (the variance at least the squared range in more than half the
rows: a range no larger than its own standard deviation tells nothing; the shared files have 0 such UWB rows and at
most 4 of 28000 simulated), and an anchor farther than the range bound from every truth position (the anchors are
fixed; nothing beyond the sensor's reach could have been ranged; the shared anchors are within 0.81 m (UWB) and
46.1 m (simulated) of the track).

Errors (:class:`~locbench.datasets.recorded.files.RecordedDataError`, naming the file and line): a missing file, a
checksum mismatch, a file above :data:`MAX_FILE_BYTES`, a non-ASCII byte, an unknown measurement type, a wrong
field count (a last line without its line end is reported as truncated), a field that is not a finite number, an
anchor id that is not an integer, a variance <= 0 where the model divides by it (range, odometry) or < 0, a range or
pseudorange beyond +-MAX_POSITION_M, a position beyond :data:`~locbench.datasets.recorded.files.MAX_POSITION_M`, a
wheel distance <= 0, time going backwards within a stream, an anchor id with two positions, the two structural
refusals above, fewer than 2 truth rows or 2 odometry samples, a stream whose flags are not isolated (the policy's
fraction and span), and no range or odometry inside the truth's span.
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from locbench.core.errors import ConfigError
from locbench.core.events import Event, Odometry, RangeObservations
from locbench.core.geometry import wrap_angle
from locbench.datasets.dataset import (
    Dataset,
    FlaggedSample,
    Gaussian2,
    Landmarks,
    SensorSpec,
    Trajectory2D,
    WorldMap,
    sort_events,
)
from locbench.datasets.recorded.common import RecordedDataset
from locbench.datasets.recorded.files import (
    MAX_INTEGER_FIELD,
    MAX_POSITION_M,
    MissingDataFile,
    RecordedDataError,
    RemoteFile,
    float_fields,
    locate,
    quote,
)
from locbench.datasets.recorded.plausibility import BOUNDS, Bounds, Flags, merge
from locbench.datasets.recorded.reference import heading_from_track

FloatArray = npt.NDArray[np.float64]

FOLDER = "librsf"
#: Field names (with units) of each measurement type after its name.
FIELDS: dict[str, tuple[str, ...]] = {
    "range2": ("t s", "range m", "range variance m^2", "anchor x m", "anchor y m", "anchor id", "snr"),
    "odom2": ("t s", "vx m/s", "vy m/s", "omega rad/s", "var vx (m/s)^2", "var vy (m/s)^2", "var omega (rad/s)^2"),
    "odom2diff": (
        "t s",
        "v_right m/s",
        "v_left m/s",
        "v_y m/s",
        "wheel distance m",
        "var v_right (m/s)^2",
        "var v_left (m/s)^2",
        "var v_y (m/s)^2",
    ),
    "point2": ("t s", "x m", "y m", "c11", "c12", "c21", "c22"),
    "angle": ("t s", "theta rad", "variance rad^2"),
}
#: Largest input file read, bytes (the largest published one is 3.1 MB).
MAX_FILE_BYTES = 64 * 1024 * 1024
#: Largest step between odometry samples, s.
MAX_DT_S = 60.0
#: Chord of the derived UWB heading, m.
HEADING_CHORD_M = 0.3
#: Initial belief standard deviations (x m, y m, theta rad) for a truth heading read from the file / derived.
INITIAL_SIGMA = (0.1, 0.1, 0.05)
INITIAL_SIGMA_DERIVED = (0.1, 0.1, 0.2)
#: Default window: the first N odometry samples.
DEFAULT_MAX_STEPS = 0
#: The policy's bounds for the Labyrinth's UWB ranges (module docstring "Plausibility").
UWB_BOUNDS = BOUNDS.tightened(range_m=300.0)
NOISES = ("heavy-tailed", "multimodal", "skewed")
GENERATED = "gaussian"
SETS = ("indoor_uwb", "m3500", "w3500")

_SIM = "Ranging_Simulation"
SHA256: dict[str, str] = {
    "Indoor_UWB/Indoor_UWB_GT.txt": "49057cc9fdf14e464bca8cfab9894dddc1668c53e08878e30d6d1040e3f9f2a2",
    "Indoor_UWB/Indoor_UWB_Input.txt": "d0a1ac1e96f508a8fe7a0f40d4152d005ecd3e708403a521da93d4377e3c3b77",
    "Ranging_Simulation/M3500_GT.txt": "34300d28b2d58623b5b5010b00b7eb1d084ded9c321f8491cf63e8db63c961fb",
    f"{_SIM}/M3500_heavy-tailed_Input.txt": "0673297e760a8343f42a3d2d210aa95857e2293ea2dbfcbbccbf7a9b76dbda40",
    f"{_SIM}/M3500_multimodal_Input.txt": "9282212dcd3ebdb56f76a71c7576b2025df20f913fb3fd269be8e60f48de4741",
    f"{_SIM}/M3500_skewed_Input.txt": "665a64c634a68594c324bea53d927a98fced249d42536d181ed0326d4193cefb",
    "Ranging_Simulation/W3500_GT.txt": "9d19c28efaeabf24c6f5064b36d2b43a894f160c7b8d9198a25253701069797e",
    f"{_SIM}/W3500_heavy-tailed_Input.txt": "d4e6eac4ba28509f37672554bdfd96302ceed47306bdb86a8d3b2ccbb9e8ec23",
    f"{_SIM}/W3500_multimodal_Input.txt": "a47d15ef21efa9aa79c6248e0d67bad0867916335ab93ee59b84a2b0b7e1995b",
    f"{_SIM}/W3500_skewed_Input.txt": "4f02d32a23fda25bac7497ecbb524c96ec7ea29525895d19f1305025a1e5e111",
}


# --- reading -------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Records:
    """The rows of one measurement type: ``rows`` (n, k) float64 and the 1-based file line of each."""

    path: Path
    kind: str
    rows: FloatArray
    lines: npt.NDArray[np.int64]

    def __len__(self) -> int:
        return int(self.rows.shape[0])

    def fail(self, row: int, message: str) -> RecordedDataError:
        return RecordedDataError(self.path, f"{self.kind} {message}", int(self.lines[row]))

    def check(self, col: int, lo: float, hi: float, *, open_lo: bool = False) -> None:
        """Raise at the first row whose field ``col`` (0-based after the type) is outside [lo, hi] ((lo, hi])."""
        a = self.rows[:, col]
        bad = np.flatnonzero(((a <= lo) if open_lo else (a < lo)) | (a > hi))
        if bad.size:
            k = int(bad[0])
            low = "(" if open_lo else "["
            raise self.fail(
                k, f"field {col + 2} ({FIELDS[self.kind][col]}) is {float(a[k])!r}, expected in {low}{lo!r}, {hi!r}]"
            )

    def subset(self, keep: npt.NDArray[np.bool_]) -> Records:
        """The rows where ``keep`` is true (the flagged ones left out)."""
        return Records(self.path, self.kind, self.rows[keep], self.lines[keep])

    def check_time(self) -> None:
        t = self.rows[:, 0]
        back = np.flatnonzero(np.diff(t) < 0)
        if back.size:
            k = int(back[0]) + 1
            raise self.fail(
                k, f"time goes backwards: {float(t[k])!r} after {float(t[k - 1])!r} (expected non-decreasing)"
            )


def read_librsf(path: str | os.PathLike[str], kinds: tuple[str, ...]) -> dict[str, Records]:
    """Parse a libRSF text file holding the measurement types ``kinds`` (module docstring); checked, cached."""
    p = Path(path)
    try:
        st = p.stat()
    except FileNotFoundError:
        raise MissingDataFile(p, "missing file (expected a libRSF measurement file)") from None
    if st.st_size > MAX_FILE_BYTES:
        raise RecordedDataError(p, f"{st.st_size} bytes, expected a libRSF file of at most {MAX_FILE_BYTES} bytes")
    return _read_cached(str(p.resolve()), st.st_size, st.st_mtime_ns, kinds)


@functools.lru_cache(maxsize=16)
def _read_cached(path: str, size: int, mtime_ns: int, kinds: tuple[str, ...]) -> dict[str, Records]:
    p = Path(path)
    raw = p.read_bytes()
    try:
        text = raw.decode("ascii")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise RecordedDataError(
            p, f"non-ASCII byte {raw[exc.start]:#04x} (expected a libRSF text file)", line
        ) from None
    lines = text.split("\n")
    ends = text.endswith("\n")
    tokens: dict[str, list[str]] = {k: [] for k in kinds}
    numbers: dict[str, list[int]] = {k: [] for k in kinds}
    for i, text_line in enumerate(lines):
        parts = text_line.split()
        if not parts:
            continue
        kind, lineno = parts[0], i + 1
        if kind not in kinds:
            raise RecordedDataError(
                p, f"measurement type {quote(kind)}, expected one of {', '.join(kinds)} in this file", lineno
            )
        want = len(FIELDS[kind]) + 1
        last = i == len(lines) - 1 and not ends
        if len(parts) != want or last:
            what = "truncated line" if last else "wrong field count"
            detail = "no line end, so its last field may be cut; " if last and len(parts) == want else ""
            raise RecordedDataError(
                p, f"{what}: {detail}{len(parts)} fields, expected {want} ({kind} {' '.join(FIELDS[kind])})", lineno
            )
        tokens[kind].extend(parts[1:])
        numbers[kind].append(lineno)
    out = {}
    for kind in kinds:
        # field c sits at place c + 2 on its line (after the record type)
        values = float_fields(p, tokens[kind], numbers[kind], FIELDS[kind], kind, lambda c: c + 2)
        out[kind] = Records(p, kind, values, np.array(numbers[kind], dtype=np.int64))
    return out


@dataclass(frozen=True, eq=False)
class LibrsfArrays:
    """The checked content of one set: ranges, odometry (``odom2`` or ``odom2diff``), truth, anchors."""

    input_path: Path
    gt_path: Path
    ranges: Records
    odom: Records
    point: Records
    angle: Records | None
    anchors: Landmarks
    flagged: tuple[FlaggedSample, ...] = ()


def read_set(input_path: Path, gt_path: Path, differential: bool) -> LibrsfArrays:
    """Read and check one Input / GT pair (module docstring); the flagged rows are left out of what it returns."""
    okind = "odom2diff" if differential else "odom2"
    inp = read_librsf(input_path, ("range2", okind))
    gt = read_librsf(gt_path, ("point2",) if differential else ("point2", "angle"))
    rng_, od, pt = inp["range2"], inp[okind], gt["point2"]
    ang = None if differential else gt["angle"]
    if len(pt) < 2:
        raise RecordedDataError(gt_path, f"{len(pt)} point2 row(s), expected at least 2 truth positions")
    if len(od) < 2:
        raise RecordedDataError(input_path, f"{len(od)} {okind} row(s), expected at least 2 odometry samples")
    if len(rng_) == 0:
        raise RecordedDataError(input_path, "no range2 row, expected ranges to the anchors")
    for rec in (rng_, od, pt) + ((ang,) if ang is not None else ()):
        rec.check_time()
    _refuse_swapped_range_columns(rng_)
    # a UWB range outside its bound is flagged below; a simulated pseudorange may be negative (its outliers are)
    rng_.check(1, -MAX_POSITION_M, MAX_POSITION_M)
    rng_.check(2, 0.0, math.inf, open_lo=True)
    rng_.check(3, -MAX_POSITION_M, MAX_POSITION_M)
    rng_.check(4, -MAX_POSITION_M, MAX_POSITION_M)
    ids = rng_.rows[:, 5]
    bad = np.flatnonzero((ids != np.round(ids)) | (np.abs(ids) > MAX_INTEGER_FIELD))
    if bad.size:
        raise rng_.fail(int(bad[0]), f"field 7 (anchor id) is {float(ids[bad[0]])!r}, expected an integer")
    pt.check(1, -MAX_POSITION_M, MAX_POSITION_M)
    pt.check(2, -MAX_POSITION_M, MAX_POSITION_M)
    if differential:
        od.check(4, 0.0, MAX_POSITION_M, open_lo=True)
        od.check(5, 0.0, math.inf, open_lo=True)
        od.check(6, 0.0, math.inf, open_lo=True)
        od.check(7, 0.0, math.inf)
    else:
        for c in (4, 5, 6):
            od.check(c, 0.0, math.inf, open_lo=True)
    if ang is not None and (len(ang) != len(pt) or np.any(ang.rows[:, 0] != pt.rows[:, 0])):
        raise RecordedDataError(gt_path, f"{len(ang)} angle rows, expected one at each of the {len(pt)} point2 times")
    dt = np.diff(od.rows[:, 0])
    big = np.flatnonzero(dt > MAX_DT_S)
    if big.size:
        raise od.fail(int(big[0]) + 1, f"time step {float(dt[big[0]])!r} s, expected at most {MAX_DT_S} s")
    # anchors: one position per id
    uid, first = np.unique(ids, return_index=True)
    pos = rng_.rows[first, 3:5]
    lookup = np.searchsorted(uid, ids)
    moved = np.flatnonzero(np.any(rng_.rows[:, 3:5] != pos[lookup], axis=1))
    if moved.size:
        k = int(moved[0])
        raise rng_.fail(
            k,
            f"anchor id {int(ids[k])} at ({float(rng_.rows[k, 3])!r}, {float(rng_.rows[k, 4])!r}), expected its "
            f"first position ({float(pos[lookup[k], 0])!r}, {float(pos[lookup[k], 1])!r}) (the anchors are fixed)",
        )
    bounds = UWB_BOUNDS if differential else BOUNDS
    _refuse_far_anchors(rng_, first, pt.rows[:, 1:3], bounds.range_m)
    anchors = Landmarks(ids=uid.astype(np.int64), xy=pos.copy())
    flags = _flags(rng_, od, pt, ang, bounds, differential)
    kept = [f.kept for f in flags]
    return LibrsfArrays(
        input_path,
        gt_path,
        rng_.subset(kept[0]),
        od.subset(kept[1]),
        pt.subset(kept[2]),
        None if ang is None else ang.subset(kept[2]),
        anchors,
        merge(*(f.finish() for f in flags)),
    )


def _refuse_swapped_range_columns(rng_: Records) -> None:
    """Refuse range2 rows whose range and variance columns are swapped.

    A range no larger than its own standard deviation (variance >= range^2) says nothing about where the robot is;
    where that holds in more than half of a file's rows, the columns are swapped (the shared files: 0 of 233 UWB
    rows, at most 4 of 28000 simulated pseudoranges, all outliers).
    """
    r, var = rng_.rows[:, 1], rng_.rows[:, 2]
    with np.errstate(over="ignore"):
        vague = var >= r * r
    if vague.sum() > 0.5 * len(rng_):
        k = int(np.flatnonzero(vague)[0])
        raise rng_.fail(
            k,
            f"field 3 (range m) is {float(r[k])!r} and field 4 (range variance m^2) {float(var[k])!r}: in "
            f"{int(vague.sum())} of {len(rng_)} rows the variance is at least the squared range, expected ranges "
            "larger than their standard deviation (range and variance columns swapped?)",
        )


def _refuse_far_anchors(rng_: Records, first: npt.NDArray[np.int64], truth_xy: FloatArray, range_m: float) -> None:
    """Refuse an anchor farther than the sensor's range bound from every truth position: nothing could range it."""
    xy = rng_.rows[first, 3:5]
    near = np.full(xy.shape[0], np.inf)
    for k in range(xy.shape[0]):  # a few anchors: one row of distances each
        near[k] = np.hypot(truth_xy[:, 0] - xy[k, 0], truth_xy[:, 1] - xy[k, 1]).min()
    far = np.flatnonzero(near > range_m)
    if far.size:
        k = int(far[0])
        raise rng_.fail(
            int(first[k]),
            f"anchor id {int(rng_.rows[first[k], 5])} at ({float(xy[k, 0])!r}, {float(xy[k, 1])!r}) is "
            f"{near[k]:.6g} m from the nearest truth position, expected within the {range_m:g} m range bound "
            "(anchors are fixed, within reach of the robot's track)",
        )


def _flags(
    rng_: Records, od: Records, pt: Records, ang: Records | None, bounds: Bounds, differential: bool
) -> tuple[Flags, Flags, Flags]:
    """The flags of the ranges, the odometry and the truth (module docstring "Plausibility")."""
    r = rng_.rows
    ranges = Flags(rng_.path, "range2 (UWB)" if differential else "range2 (pseudorange)", r[:, 0], rng_.lines)
    ranges.flag_duplicates(r)
    if differential:  # a simulated pseudorange's outliers are the sets' content (module docstring)
        ranges.flag_outside(r[:, 1], "value, m", 0.0, bounds.range_m)
    ranges.flag_outside(r[:, 2], "range variance, m^2", 0.0, bounds.variance_m2)
    o = od.rows
    odo = Flags(od.path, f"odometry ({od.kind})", o[:, 0], od.lines)
    odo.flag_duplicates(o)
    if differential:
        v, w = 0.5 * (o[:, 1] + o[:, 2]), (o[:, 2] - o[:, 1]) / (2.0 * o[:, 4])
    else:
        v, w = np.hypot(o[:, 1], o[:, 2]), o[:, 3]
    odo.flag_outside(v, "speed, m/s", -bounds.speed_mps, bounds.speed_mps)
    odo.flag_outside(w, "yaw rate, rad/s", -bounds.turn_rate_radps, bounds.turn_rate_radps)
    truth = Flags(pt.path, "ground-truth (point2)", pt.rows[:, 0], pt.lines)
    truth.flag_duplicates(pt.rows)
    theta = None
    if ang is not None:
        theta = ang.rows[:, 1]
        h = bounds.heading_abs_rad
        truth.flag_outside(theta, "heading before wrapping, rad", -h, h)
    truth.flag_track(pt.rows[:, 1:3], theta, bounds)
    return ranges, odo, truth


# --- the dataset ---------------------------------------------------------------------------------------


def set_files(set_name: str, noise: str) -> tuple[str, str]:
    """(Input, GT) paths below ``librsf/`` of a set; the generated Gaussian variant reads the heavy-tailed layout."""
    if set_name == "indoor_uwb":
        return "Indoor_UWB/Indoor_UWB_Input.txt", "Indoor_UWB/Indoor_UWB_GT.txt"
    world = set_name.upper()
    source = NOISES[0] if noise == GENERATED else noise
    return f"Ranging_Simulation/{world}_{source}_Input.txt", f"Ranging_Simulation/{world}_GT.txt"


def range_error_moments(arrays: LibrsfArrays) -> dict[str, float]:
    """Mean, variance and median of range - |anchor - p_truth(t)| (truth interpolated at each range's time), m."""
    pt = arrays.point.rows
    r = arrays.ranges.rows
    px = np.interp(r[:, 0], pt[:, 0], pt[:, 1])
    py = np.interp(r[:, 0], pt[:, 0], pt[:, 2])
    e = r[:, 1] - np.hypot(r[:, 3] - px, r[:, 4] - py)
    return {"mean_m": float(e.mean()), "variance_m2": float(e.var()), "median_m": float(np.median(e))}


def load_librsf(
    set_name: str,
    noise: str = "",
    root: str | os.PathLike[str] | None = None,
    rng: np.random.Generator | None = None,
    *,
    max_steps: int = DEFAULT_MAX_STEPS,
    like: str = "",
    verify: bool = True,
) -> Dataset:
    """One libRSF set (module docstring); ``rng`` draws the generated Gaussian ranges (None: seed 0)."""
    # long: the loader's steps over one set's files in order, with their refusals; the numpydoc is a third of it
    rel_in, rel_gt = set_files(set_name, noise)
    p_in = locate(RemoteFile(f"{FOLDER}/{rel_in}", sha256=SHA256.get(rel_in)), root, verify=verify)
    p_gt = locate(RemoteFile(f"{FOLDER}/{rel_gt}", sha256=SHA256.get(rel_gt)), root, verify=verify)
    differential = set_name == "indoor_uwb"
    arrays = read_set(p_in, p_gt, differential)
    pt = arrays.point.rows
    od = arrays.odom.rows
    # each sample covers the time since the previous one; the first, the time since the truth's first row
    dts = np.diff(od[:, 0], prepend=float(pt[0, 0]))
    use = np.flatnonzero(dts > 0.0)
    if max_steps:
        use = use[:max_steps]
    if use.size == 0:
        raise RecordedDataError(p_in, "no odometry sample after the truth's first time")
    od, dts = od[use], dts[use]
    t0 = float(pt[0, 0])
    t1 = min(float(pt[-1, 0]), float(od[-1, 0]))
    in_truth = (pt[:, 0] >= t0) & (pt[:, 0] <= t1)
    pt = pt[in_truth]
    if differential:
        theta = heading_from_track(pt[:, 1:3], HEADING_CHORD_M)
        sigma0 = INITIAL_SIGMA_DERIVED
        heading_note = f"direction of travel over a {HEADING_CHORD_M} m chord of the truth (derived)"
    else:
        assert arrays.angle is not None
        theta = wrap_angle(arrays.angle.rows[in_truth, 1])
        sigma0 = INITIAL_SIGMA
        heading_note = "the GT file's angle rows"
    truth = Trajectory2D(pt[:, 0].copy(), pt[:, 1:3].copy(), np.asarray(theta, dtype=np.float64))

    events: list[Event] = []
    steps = []
    for k in range(od.shape[0]):
        t, dt = float(od[k, 0]), float(dts[k])
        if not t0 <= t <= t1:
            continue
        if differential:
            vr, vl, b = float(od[k, 1]), float(od[k, 2]), float(od[k, 4])
            v, w = 0.5 * (vr + vl), (vl - vr) / (2.0 * b)  # the convention the truth confirms (module docstring)
            d, dth = v * dt, w * dt
            events.append(Odometry(t, d * math.cos(0.5 * dth), d * math.sin(0.5 * dth), dth, v=v, omega=w, dt=dt))
        else:
            events.append(Odometry(t, float(od[k, 1]) * dt, float(od[k, 2]) * dt, float(od[k, 3]) * dt))
            steps.append(math.hypot(float(od[k, 1]), float(od[k, 2])) * dt)
    if not events:
        raise RecordedDataError(p_in, f"no odometry sample inside the truth span [{t0!r}, {t1!r}] s")
    rr = arrays.ranges.rows
    rr = rr[(rr[:, 0] >= t0) & (rr[:, 0] <= t1)]
    if rr.shape[0] == 0:
        raise RecordedDataError(p_in, f"no range inside the truth span [{t0!r}, {t1!r}] s")
    moments = range_error_moments(arrays)
    values = rr[:, 1].copy()
    declared_var = float(np.median(arrays.ranges.rows[:, 2]))
    if noise == GENERATED:
        var = declared_var
        if like:
            like_in, _ = set_files(set_name, like)
            p_like = locate(RemoteFile(f"{FOLDER}/{like_in}", sha256=SHA256.get(like_in)), root, verify=verify)
            var = range_error_moments(read_set(p_like, p_gt, False))["variance_m2"]
        gen = rng if rng is not None else np.random.default_rng(0)
        px = np.interp(rr[:, 0], arrays.point.rows[:, 0], arrays.point.rows[:, 1])
        py = np.interp(rr[:, 0], arrays.point.rows[:, 0], arrays.point.rows[:, 2])
        values = np.hypot(rr[:, 3] - px, rr[:, 4] - py) + math.sqrt(var) * gen.standard_normal(rr.shape[0])
        moments = {"generated_variance_m2": var}
    starts = np.flatnonzero(np.concatenate([[True], np.diff(rr[:, 0]) > 0]))
    ends = np.concatenate([starts[1:], [rr.shape[0]]])
    for a, b in zip(starts.tolist(), ends.tolist(), strict=True):
        events.append(RangeObservations(float(rr[a, 0]), rr[a:b, 5].astype(np.int64), values[a:b].copy()))

    if differential:
        var_lr = np.median(od[:, 5] + od[:, 6])
        b = float(np.median(od[:, 4]))
        sensors = SensorSpec(
            range_sigma_m=math.sqrt(declared_var),
            twist_sigma_v_mps=math.sqrt(var_lr / 4.0),
            twist_sigma_omega_radps=math.sqrt(var_lr) / (2.0 * b),
        )
    else:
        dt_med = float(np.median(dts))
        d_med = max(float(np.median(steps)), 1e-9) if steps else 1.0
        var_xy = 0.5 * (float(np.median(od[:, 4])) + float(np.median(od[:, 5])))
        sensors = SensorSpec(
            range_sigma_m=math.sqrt(declared_var),
            odometry_sigma_xy_per_m=math.sqrt(var_xy * dt_med**2 / d_med),
            odometry_sigma_theta_per_m=math.sqrt(float(np.median(od[:, 6])) * dt_med**2 / d_med),
            odometry_sigma_theta_per_rad=0.0,
        )
    initial = Gaussian2(np.array([pt[0, 1], pt[0, 2], float(theta[0])]), np.diag(np.square(sigma0)))
    metadata: dict[str, Any] = {
        "source": "libRSF datasets (T. Pfeifer, TU Chemnitz; CC BY-SA 4.0), TUC-ProAut/libRSF d54801a",
        "files": [str(p_in), str(p_gt)],
        "set": set_name,
        "noise": noise or "recorded (UWB)",
        "kind": "real"
        if differential
        else ("simulated, generated Gaussian ranges" if noise == GENERATED else "simulated"),
        "truth_heading": heading_note,
        # the Labyrinth's readme gives no method for its ground-truth positions; M3500 / W3500 are simulated
        "reference_kind": "not stated" if differential else "simulation",
        # what the report's robustness table reads (the moment-matched variant is not the reference)
        **({} if differential or like else {"range_noise": {"world": set_name, "noise": noise}}),
        "declared_range_variance_m2": declared_var,
        "range_error": moments,
        "window": {"max_steps": max_steps, "odometry_samples_used": sum(isinstance(e, Odometry) for e in events)},
    }
    return Dataset(
        id="librsf",
        params={"set": set_name, "noise": noise},
        events=sort_events(events),
        ground_truth=truth,
        initial=initial,
        world=WorldMap(landmarks=arrays.anchors),
        sensors=sensors,
        metadata=metadata,
        truth_label="ground truth",
        sources=(str(p_in), str(p_gt)),
        declared=frozenset({RangeObservations}),
        flagged=arrays.flagged,
    )


@dataclass(frozen=True, kw_only=True)
class LibrsfParams:
    """Parameters of ``librsf``.

    Attributes
    ----------
    set : str
        ``indoor_uwb``, ``m3500`` or ``w3500``.
    noise : str
        For m3500 / w3500: ``heavy-tailed``, ``multimodal``, ``skewed`` or ``gaussian`` (generated); empty for
        indoor_uwb.
    like : str
        For ``noise=gaussian`` only: empty (the declared variance) or a noise type whose file's error variance the
        generated noise takes (moment-matched).
    max_steps : int
        Window: the first N odometry samples (0: all).
    root : str
        Data root holding ``librsf/``; empty: ``$LOCBENCH_DATA``.
    """

    set: str = "indoor_uwb"
    noise: str = ""
    like: str = ""
    max_steps: int = DEFAULT_MAX_STEPS
    root: str = ""

    def __post_init__(self) -> None:
        if self.set not in SETS:
            raise ConfigError(f"librsf: set must be one of {', '.join(SETS)}, got {self.set!r}")
        if self.set == "indoor_uwb":
            if self.noise or self.like:
                raise ConfigError(f"librsf: set=indoor_uwb is recorded UWB data and takes no noise, got {self.noise!r}")
        elif self.noise not in (*NOISES, GENERATED):
            raise ConfigError(
                f"librsf: set={self.set} needs noise = one of {', '.join((*NOISES, GENERATED))}, got {self.noise!r}"
            )
        if self.like and (self.noise != GENERATED or self.like not in NOISES):
            raise ConfigError(f"librsf: like={self.like!r} needs noise=gaussian and one of {', '.join(NOISES)}")
        if self.max_steps < 0:
            raise ConfigError(f"librsf: max_steps must be >= 0 (0: all), got {self.max_steps!r}")


class LibrsfDataset(RecordedDataset):
    """libRSF ranging sets: ``librsf[set=indoor_uwb]`` and ``librsf[set=m3500|w3500,noise=...]``."""

    id: ClassVar[str] = "librsf"
    Params: ClassVar[type] = LibrsfParams
    version: ClassVar[int] = 1
    description: ClassVar[str] = (
        "libRSF ranging sets (Pfeifer, TU Chemnitz): Indoor UWB (real) and M3500 / W3500 with non-Gaussian range noise"
    )
    folder: ClassVar[str] = FOLDER
    identity_keys: ClassVar[tuple[str, ...]] = ("set",)

    @classmethod
    def files(cls, params: LibrsfParams) -> list[RemoteFile]:
        """The set's Input and GT files with their sha256 (the libRSF repository is the only source)."""
        names = list(set_files(params.set, params.noise))
        if params.like:
            names.append(set_files(params.set, params.like)[0])
        return [RemoteFile(f"{FOLDER}/{n}", sha256=SHA256.get(n)) for n in names]

    def build(self, params: LibrsfParams, rng: np.random.Generator) -> Dataset:
        """The set; ``rng`` draws the generated Gaussian ranges (recorded sets do not use it)."""
        root = params.root or None
        for spec in self.files(params):
            locate(spec, root)
        return load_librsf(params.set, params.noise, root, rng, max_steps=params.max_steps, like=params.like)
