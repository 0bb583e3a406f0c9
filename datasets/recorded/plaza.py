"""CMU "Plaza" range-only datasets (Plaza1, Plaza2): odometry, radio ranges to 4 surveyed beacons, GPS truth.

Source and citation
-------------------
J. Djugash, B. Hamner, S. Roth, "Navigating with ranging radios: Five data sets with ground truth", Journal of
Field Robotics 26(9):689-695, 2009 (http://www.frc.ri.cmu.edu/projects/emergencyresponse/RangeData/). The files
read here are the MATLAB copies ``Plaza1_.mat`` and ``Plaza2_.mat`` that the GTSAM authors made from the CMU logs
in 2013 (``borglab/gtsam`` ``examples/Data/``, commit 0ffe6c930302ebd297484e65e6e8d467c91d26b0, which is also the
official download used here; sha256 below and in SOURCES.md). The data licence is not stated.

Format (MATLAB v5, one ``(n, k)`` double matrix per variable; CMU's log description)
------------------------------------------------------------------------------------
``GT`` [t x y heading]  ground truth from GPS (s, m, m, rad);
``DR`` [t d_dist d_heading]  odometry: distance travelled (m) and heading change (rad) since the previous row;
``DRp`` [t x y heading]  the dead-reckoned path (optional here: used only for the check below);
``TL`` [id x y]  surveyed beacon positions (m);
``TD`` [t sender_id beacon_id range]  ranges (m) from the robot's radio (sender) to a beacon.
Times are seconds of the recording's clock; x-y is the GPS-derived local frame (m) shared by GT and TL.

What the dataset is made of, and why
------------------------------------
* **Odometry** (:class:`~locbench.core.events.Odometry`, one per ``DR`` row at its time): the robot moves
  d = ``d_dist`` along the heading at mid-rotation, theta + d_heading / 2, then has turned d_heading, i.e. in
  the previous robot frame dx = d cos(d_heading / 2), dy = d sin(d_heading / 2), dtheta = d_heading. Checked
  against ``DRp`` (see :func:`dead_reckoning_check`): integrated from ``DRp``'s first pose this reproduces Plaza2's
  ``DRp`` to 0.06 m over 1354 m (moving first and turning after, as GTSAM's example composes Pose2(d, 0,
  d_heading), gives 0.44 m; turning first 0.55 m). Plaza1's ``DRp`` headings equal the integrated d_heading
  to 1e-13 rad but its positions are not the integral of any of these models (they drift 42 m away while the
  step lengths equal d_dist exactly, the direction of each step turning away from ``DRp``'s own heading by up
  to 0.55 rad over the run): the positions of Plaza1's ``DRp`` were made with another heading source, and
  ``DRp`` is not used as odometry. No twist is given (the log has distances, not speeds).
* **Ranges** (:class:`~locbench.core.events.RangeObservations`): the ``TD`` rows, sorted by time (a stable sort:
  Plaza1's ``TD`` holds two blocks out of time order, -64 s and -50 s, which the sort puts back; counted in
  ``metadata["td_rows_out_of_order"]``) and grouped per identical time stamp; ids are the beacon ids. The
  sender id is the robot's radio (one per file; kept in metadata).
* **Beacons**: ``TL`` as ``world.landmarks`` (surveyed; no standard deviation given).
* **Ground truth** (:class:`~locbench.datasets.dataset.Trajectory2D`): ``GT``'s positions. Its heading column is
  not used: in Plaza1 it equals ``DRp``'s odometry heading exactly (so it is not independent of the odometry),
  and in Plaza2 it points backwards (the direction of travel minus pi, median deviation 0.018 rad; GTSAM's
  example adds pi to it). The true heading is taken as the GPS direction of travel
  (:func:`~locbench.datasets.recorded.reference.heading_from_track`): the direction of the chord from the first GT
  sample at least ``HEADING_CHORD_M`` / 2 of path behind to the first at least as far ahead (one-sided at the ends).
  The robot only drives forwards (every d_dist >= 0), so the direction of travel is its heading.
* **Initial belief**: the first ground-truth pose (position and derived heading) with covariance
  diag(``INITIAL_SIGMA_XY_M``^2 x 2, ``INITIAL_SIGMA_THETA_RAD``^2): a few times the spread of the derived
  heading (its robust spread against Plaza1's odometry heading, which is locally accurate, is 0.036 rad, and
  against Plaza2's reversed GT heading 0.024 rad).
* **Events** are trimmed to the ground-truth time span (they all lie inside it in both files).
* **Nominal noise** (``SensorSpec``): estimated per run against the ground truth by :func:`estimate_nominal_noise`
  and frozen in :data:`NOMINAL_NOISE` (a test recomputes them), not tuned on any filter's error:

  - ``range_sigma_m``: the robust RMS of the range residuals r - |beacon - p_GT(t)| (p_GT linearly interpolated
    at the range's time), sqrt(median(res^2) / 0.4549) (0.4549 = the median of chi-square with 1 dof). It is
    taken about zero, not about the median, because the ranges carry a systematic offset against the GPS
    truth (median residual +2.8 m in both runs, about 1.2-1.8 m robust spread, a few per cent beyond 5 m;
    :data:`RANGE_RESIDUAL_MEDIAN_M`) that a zero-mean range model can only absorb as noise. The offset is
    left in the data (``range_offset_m`` subtracts a user-chosen calibration).
  - ``odometry_sigma_xy_per_m`` and ``odometry_sigma_theta_per_m``: the odometry is cut into consecutive
    segments of ``NOISE_SEGMENT_M`` of travel; in each, the odometry's displacement and heading change in the
    segment's start frame are compared with the ground truth's (derived heading). With the increment model of
    :mod:`locbench.filters._motion` (per-axis variance sigma_xy^2 d and heading variance sigma_theta^2 d)
    sigma_xy = sqrt(median|e_xy|^2 / (2 ln 2) / D) (the median of chi-square with 2 dof is 2 ln 2) and
    sigma_theta = sqrt(median(e_theta^2) / 0.4549 / D), D the segment length; ``odometry_sigma_theta_per_rad``
    is 0. Bias is included on purpose (the errors are not centred): Plaza2's odometry heading drifts about
    2 rad over the run, which no zero-mean per-segment noise describes; filters that trust the nominal
    odometry noise on long gaps between ranges will be over-confident there.

Errors: a missing file, a file that is not MATLAB v5, a missing variable, a variable not stored as float (an
int32 ``DR`` has already lost its centimetres), a wrong shape, a non-finite value, ``GT`` with fewer than 2 rows,
time not strictly increasing in ``GT``, ``DR`` or ``DRp``, a position beyond
:data:`~locbench.datasets.recorded.files.MAX_POSITION_M`, a beacon id in ``TD`` that is not in ``TL``, a range
below 0 after subtracting ``range_offset_m``, no ``DR`` row inside the ``GT`` span, a gap above :data:`MAX_GAP_S`
(between ``GT`` rows, ``DR`` rows, or from an end of ``GT`` to the nearest ``DR`` row), more ranges at one time
stamp than beacons, and a checksum mismatch raise :class:`~locbench.datasets.recorded.files.RecordedDataError`
naming the file, the variable (and row) and what was expected. Parsed files are cached per (path, size, mtime).

Flagged by the plausibility policy (:mod:`~locbench.datasets.recorded.plausibility`, :data:`BOUNDS`; the row is
left out and listed in ``Dataset.flagged``, a variable with more than 1 % of its rows flagged or a 2 s stretch is
refused): a ``GT`` row the robot could not have reached from the last accepted one; a ``DR`` step outside [0,
:data:`MAX_STEP_M`] m, a turn beyond +-2 pi rad, or a step or turn faster than the bounds over its interval; a
``TD`` range outside [0, :data:`MAX_RANGE_M`] m or a ``TD`` row repeating the one before it.
"""

from __future__ import annotations

import functools
import itertools
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from locbench.core.errors import ConfigError
from locbench.core.events import Event, Odometry, RangeObservations
from locbench.core.geometry import wrap_angle
from locbench.core.spec import bound
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
from locbench.datasets.recorded import plausibility
from locbench.datasets.recorded.common import RecordedDataset
from locbench.datasets.recorded.files import (
    MAX_POSITION_M,
    MissingDataFile,
    RecordedDataError,
    RemoteFile,
    check_increasing,
    check_range,
    load_mat,
    mat_numbers,
    verify_sha256,
)
from locbench.datasets.recorded.reference import heading_from_track

FloatArray = npt.NDArray[np.float64]

FOLDER = "cmu_plaza_ranging"
_GTSAM_COMMIT = "0ffe6c930302ebd297484e65e6e8d467c91d26b0"
_URL = f"https://raw.githubusercontent.com/borglab/gtsam/{_GTSAM_COMMIT}/examples/Data/Plaza{{run}}_.mat"
#: sha256 of the files (SOURCES.md).
SHA256 = {
    1: "9ccbfec19942eabecfa3206bff983bf708b98d6c7db462d81c55376f92d75847",
    2: "72f0abe0fea2050eb5ee1cffc8c43823266a35785b7cdecac4ec5eae727561a2",
}

#: Columns of each variable (names with units), for messages.
COLUMNS: dict[str, tuple[str, ...]] = {
    "GT": ("t s", "x m", "y m", "heading rad"),
    "DR": ("t s", "d_dist m", "d_heading rad"),
    "DRp": ("t s", "x m", "y m", "heading rad"),
    "TL": ("id", "x m", "y m"),
    "TD": ("t s", "sender_id", "beacon_id", "range m"),
}
_REQUIRED = ("GT", "DR", "TL", "TD")

#: Bounds of the validation: the largest odometry step between two DR rows (m) and the largest range (m).
MAX_STEP_M = 100.0
MAX_RANGE_M = 1000.0
#: Largest interval between two ``GT`` rows or two ``DR`` rows, and between the ends of the ``GT`` span and the first
#: and last ``DR`` row, s (both files: at most 0.35 s). The truth is interpolated between its rows and an odometry row
#: covers its whole interval, so a longer gap is refused, never bridged.
MAX_GAP_S = 5.0
#: Physical speed bound of the Plaza robot (a lawn-mower-sized vehicle; both files: at most 4.8 m/s over a 0.1-0.35 s
#: row). The plausibility policy's 5 m/s is tighter and applies: a ``DR`` step over its interval and a ``GT`` step
#: from the last accepted row faster than that (plus its jitter) are flagged.
MAX_SPEED_MPS = 10.0
#: The plausibility bounds of this loader: the policy's, the range bound tightened to :data:`MAX_RANGE_M`, headings
#: (``d_heading``) to 2 pi.
BOUNDS = plausibility.BOUNDS.tightened(range_m=MAX_RANGE_M, heading_abs_rad=2 * math.pi)
#: Path length of the chord whose direction is the ground-truth heading, m (half behind, half ahead).
HEADING_CHORD_M = 2.0
#: Initial belief standard deviations: position (m) and heading (rad).
INITIAL_SIGMA_XY_M = 0.1
INITIAL_SIGMA_THETA_RAD = 0.05
#: Odometry segment length of the noise estimate, m.
NOISE_SEGMENT_M = 10.0
# Medians of chi-square with 1 and 2 degrees of freedom.
_CHI2_1_MEDIAN = 0.454936423119572
_CHI2_2_MEDIAN = 2.0 * math.log(2.0)


@dataclass(frozen=True)
class NominalNoise:
    """Nominal noise of one run (see the module docstring): range m, odometry m/sqrt(m) and rad/sqrt(m)."""

    range_sigma_m: float
    odometry_sigma_xy_per_m: float
    odometry_sigma_theta_per_m: float


#: Frozen output of :func:`estimate_nominal_noise` per run (recomputed by the tests).
NOMINAL_NOISE: dict[int, NominalNoise] = {
    1: NominalNoise(
        range_sigma_m=4.208590314464248,
        odometry_sigma_xy_per_m=0.048640519938908985,
        odometry_sigma_theta_per_m=0.012896115196034615,
    ),
    2: NominalNoise(
        range_sigma_m=4.157704154996107,
        odometry_sigma_xy_per_m=0.040351741278327906,
        odometry_sigma_theta_per_m=0.011471441803497436,
    ),
}
#: Median range residual against the ground truth per run, m (reported; not subtracted by default).
RANGE_RESIDUAL_MEDIAN_M: dict[int, float] = {1: 2.838651029880637, 2: 2.804328083272882}


# --- reading ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class PlazaArrays:
    """The checked variables of one file (``DRp`` None when absent); ``TD`` sorted by time (stable); ``GT``, ``DR``
    and ``TD`` without the rows flagged by the plausibility bounds (``flagged``)."""

    path: Path
    GT: FloatArray
    DR: FloatArray
    DRp: FloatArray | None
    TL: FloatArray
    TD: FloatArray
    td_rows_out_of_order: int
    flagged: tuple[FlaggedSample, ...] = ()


def _variable(path: Path, mat: dict[str, Any], name: str) -> FloatArray:
    cols = COLUMNS[name]
    what = f"a real (n, {len(cols)}) matrix [{' '.join(cols)}]"
    a = mat_numbers(path, mat, name, what)
    if a.ndim != 2 or a.shape[1] != len(cols) or a.shape[0] < 1:
        raise RecordedDataError(path, f"variable {name!r} has shape {a.shape}, expected {what}")
    return a


def _check_time(path: Path, name: str, a: FloatArray) -> None:
    check_increasing(path, f"variable {name!r} column 1 (t s)", a[:, 0], strict=True, rows="row")
    if name != "DR":
        check_range(path, f"variable {name!r} columns 2-3 (x m, y m)", a[:, 1:3], -MAX_POSITION_M, MAX_POSITION_M)


def _check_motion(p: Path, gt: FloatArray, dr: FloatArray) -> None:
    """Refuse gaps above :data:`MAX_GAP_S` in ``GT`` and ``DR`` (and ``DR`` not reaching the ends of ``GT``)."""
    for name, a in (("GT", gt), ("DR", dr)):
        dt = np.diff(a[:, 0])
        gap = np.flatnonzero(dt > MAX_GAP_S)
        if gap.size:
            r = int(gap[0]) + 1
            raise RecordedDataError(
                p,
                f"variable {name!r} row {r + 1}: {float(dt[r - 1]):.6g} s after the previous row, expected gaps of at "
                f"most {MAX_GAP_S} s (a gap is not bridged)",
            )
    lead, tail = float(dr[0, 0] - gt[0, 0]), float(gt[-1, 0] - dr[-1, 0])
    overlaps = dr[0, 0] <= gt[-1, 0] and dr[-1, 0] >= gt[0, 0]  # else load_plaza names the missing overlap
    if overlaps and (lead > MAX_GAP_S or tail > MAX_GAP_S):
        raise RecordedDataError(
            p,
            f"variable 'DR' spans [{float(dr[0, 0])!r}, {float(dr[-1, 0])!r}] s, {max(lead, tail):.6g} s short of an "
            f"end of the GT span [{float(gt[0, 0])!r}, {float(gt[-1, 0])!r}] s, expected at most {MAX_GAP_S} s "
            f"({dr.shape[0]} odometry row(s))",
        )


def _flag(p: Path, gt: FloatArray, dr: FloatArray, td: FloatArray) -> tuple[plausibility.Flags, ...]:
    """The flags of the ``GT``, ``DR`` and ``TD`` rows (the plausibility policy with :data:`BOUNDS`)."""
    f_gt = plausibility.Flags(p, "truth (variable 'GT')", gt[:, 0])
    f_gt.flag_track(gt[:, 1:3], None, BOUNDS)
    f_dr = plausibility.Flags(p, "odometry (variable 'DR')", dr[:, 0])
    f_dr.flag_outside(dr[:, 1], "d_dist, m", 0.0, MAX_STEP_M)
    f_dr.flag_outside(dr[:, 2], "d_heading, rad", -BOUNDS.heading_abs_rad, BOUNDS.heading_abs_rad)
    f_dr.flag_increments(dr[:, 1], dr[:, 2], np.r_[math.inf, np.diff(dr[:, 0])], BOUNDS)
    f_td = plausibility.Flags(p, "range (variable 'TD')", td[:, 0])
    f_td.flag_outside(td[:, 3], "range, m", 0.0, BOUNDS.range_m)
    f_td.flag_duplicates(td)
    return f_gt, f_dr, f_td


@functools.lru_cache(maxsize=8)
def _read_cached(path: str, size: int, mtime_ns: int) -> PlazaArrays:
    p = Path(path)
    mat = load_mat(p, "MATLAB v5 file")
    v = {name: _variable(p, mat, name) for name in _REQUIRED}
    drp = _variable(p, mat, "DRp") if "DRp" in mat else None
    for name in ("GT", "DR"):
        _check_time(p, name, v[name])
    if drp is not None:
        _check_time(p, "DRp", drp)
    if v["GT"].shape[0] < 2:
        raise RecordedDataError(p, f"variable 'GT' has {v['GT'].shape[0]} row(s), expected at least 2 truth poses")
    check_range(p, "variable 'TL' columns 2-3 (x m, y m)", v["TL"][:, 1:3], -MAX_POSITION_M, MAX_POSITION_M)
    tl, td = v["TL"], v["TD"]
    ids = tl[:, 0]
    if np.any(ids != np.round(ids)) or len(np.unique(ids)) != len(ids):
        raise RecordedDataError(p, f"variable 'TL' column 1 (id) is {ids.tolist()}, expected distinct integers")
    unknown = ~np.isin(td[:, 2], ids)
    if unknown.any():
        r = int(np.flatnonzero(unknown)[0])
        raise RecordedDataError(
            p, f"variable 'TD' row {r + 1}: beacon_id {float(td[r, 2])!r} is not in TL (expected one of {ids.tolist()})"
        )
    _check_motion(p, v["GT"], v["DR"])
    flags = _flag(p, v["GT"], v["DR"], td)
    flagged = plausibility.merge(*(f.finish() for f in flags))
    v["GT"], v["DR"], td = (a[f.kept] for a, f in zip((v["GT"], v["DR"], td), flags, strict=True))
    # one range per beacon and radio at an instant: more rows at one stamp than beacons is a stamp lost
    stamps, counts = np.unique(td[:, 0], return_counts=True)
    crowded = np.flatnonzero(counts > tl.shape[0])
    if crowded.size:
        k = int(crowded[0])
        raise RecordedDataError(
            p,
            f"variable 'TD': {int(counts[k])} ranges at the one time {float(stamps[k])!r} s, expected at most one per "
            f"beacon ({tl.shape[0]} in TL) at an instant (a lost or constant time column)",
        )
    out_of_order = int(np.sum(np.diff(td[:, 0]) < 0))
    order = np.argsort(td[:, 0], kind="stable")
    return PlazaArrays(p, v["GT"], v["DR"], drp, tl, td[order], out_of_order, flagged)


def read_plaza_mat(path: str | os.PathLike[str], sha256: str | None = None) -> PlazaArrays:
    """Read and check one Plaza MAT file (module docstring); verify its sha256 when given.

    Raises
    ------
    RecordedDataError
        Missing file, checksum mismatch, unreadable file, missing variable, wrong shape, non-finite value,
        time going backwards (GT, DR, DRp), unknown beacon id, negative range or distance.
    """
    p = Path(path)
    if not p.is_file():
        raise MissingDataFile(p, "missing file (expected a CMU Plaza MATLAB file, e.g. Plaza1_.mat)")
    if sha256:
        verify_sha256(p, sha256)
    st = p.stat()
    return _read_cached(str(p.resolve()), st.st_size, st.st_mtime_ns)


# --- derived quantities ------------------------------------------------------------------------------


def odometry_increments(dr: FloatArray) -> FloatArray:
    """(dx, dy, dtheta) in the previous robot frame of each ``DR`` row, shape (n, 3): the mid-rotation model."""
    d, dh = dr[:, 1], dr[:, 2]
    return np.stack([d * np.cos(0.5 * dh), d * np.sin(0.5 * dh), dh], axis=-1)


def integrate(start: npt.ArrayLike, increments: FloatArray) -> FloatArray:
    """Poses (n + 1, 3) from ``start`` (x, y, theta) composed with each increment (previous robot frame)."""
    x, y, th = (float(v) for v in np.asarray(start, dtype=np.float64))
    out = np.empty((increments.shape[0] + 1, 3))
    out[0] = (x, y, th)
    for k, (dx, dy, dth) in enumerate(increments.tolist()):
        c, s = math.cos(th), math.sin(th)
        x, y, th = x + c * dx - s * dy, y + s * dx + c * dy, th + dth
        out[k + 1] = (x, y, th)
    out[:, 2] = wrap_angle(out[:, 2])
    return out


def dead_reckoning_check(arrays: PlazaArrays) -> dict[str, float]:
    """How far the odometry integrated from ``DRp``'s first pose strays from ``DRp`` (max position m, heading rad)."""
    if arrays.DRp is None or arrays.DRp.shape[0] != arrays.DR.shape[0] + 1:
        return {}
    poses = integrate(arrays.DRp[0, 1:4], odometry_increments(arrays.DR))
    pos = np.hypot(poses[:, 0] - arrays.DRp[:, 1], poses[:, 1] - arrays.DRp[:, 2])
    head = np.abs(wrap_angle(poses[:, 2] - arrays.DRp[:, 3]))
    return {"drp_max_position_diff_m": float(pos.max()), "drp_max_heading_diff_rad": float(head.max())}


def estimate_nominal_noise(arrays: PlazaArrays) -> tuple[NominalNoise, float]:
    """The nominal noise of the module docstring, and the median range residual (m), from the data and the truth."""
    gt = arrays.GT
    # ranges against the interpolated truth
    td = arrays.TD
    if td.shape[0] == 0:
        raise RecordedDataError(arrays.path, "variable 'TD' has no range, expected ranges to estimate their noise from")
    bxy = {int(r[0]): r[1:3] for r in arrays.TL}
    px = np.interp(td[:, 0], gt[:, 0], gt[:, 1])
    py = np.interp(td[:, 0], gt[:, 0], gt[:, 2])
    b = np.array([bxy[int(i)] for i in td[:, 2]])
    res = td[:, 3] - np.hypot(b[:, 0] - px, b[:, 1] - py)
    range_sigma = math.sqrt(float(np.median(res * res)) / _CHI2_1_MEDIAN)

    # odometry segments of NOISE_SEGMENT_M against the truth at the DR times
    dr = arrays.DR
    theta_gt = heading_from_track(gt[:, 1:3], HEADING_CHORD_M)
    tx = np.interp(dr[:, 0], gt[:, 0], gt[:, 1])
    ty = np.interp(dr[:, 0], gt[:, 0], gt[:, 2])
    tth = np.interp(dr[:, 0], gt[:, 0], np.unwrap(theta_gt))
    odo = integrate((0.0, 0.0, 0.0), odometry_increments(dr))[1:]  # pose after each DR row, from a zero start
    odo_th = np.cumsum(dr[:, 2])
    dist = np.cumsum(dr[:, 1])
    marks = np.searchsorted(dist, np.arange(0.0, dist[-1], NOISE_SEGMENT_M), side="left")
    marks = np.unique(np.clip(marks, 0, len(dist) - 1))
    if marks.size < 2:  # a run shorter than one segment: the whole run is the segment
        marks = np.array([0, len(dist) - 1])
    e_xy2, e_th2, lengths = [], [], []
    for i0, i1 in itertools.pairwise(marks.tolist()):
        length = float(dist[i1] - dist[i0])
        if length <= 0.0:
            continue
        # displacement in the segment's start frame: odometry (own heading) and truth (derived heading)
        c, s = math.cos(odo_th[i0]), math.sin(odo_th[i0])
        ox, oy = odo[i1, 0] - odo[i0, 0], odo[i1, 1] - odo[i0, 1]
        o = (c * ox + s * oy, -s * ox + c * oy)
        c, s = math.cos(tth[i0]), math.sin(tth[i0])
        gx, gy = tx[i1] - tx[i0], ty[i1] - ty[i0]
        g = (c * gx + s * gy, -s * gx + c * gy)
        e_xy2.append(((o[0] - g[0]) ** 2 + (o[1] - g[1]) ** 2) / length)
        e_th2.append(float(wrap_angle((odo_th[i1] - odo_th[i0]) - (tth[i1] - tth[i0]))) ** 2 / length)
        lengths.append(length)
    if not lengths:
        raise RecordedDataError(
            arrays.path,
            f"variable 'DR': {dr.shape[0]} row(s) travelling {float(dist[-1])!r} m, expected odometry that moves "
            "(the odometry noise is estimated per metre)",
        )
    sxy = math.sqrt(float(np.median(e_xy2)) / _CHI2_2_MEDIAN)
    sth = math.sqrt(float(np.median(e_th2)) / _CHI2_1_MEDIAN)
    return NominalNoise(range_sigma, sxy, sth), float(np.median(res))


# --- the dataset ---------------------------------------------------------------------------------------


def load_plaza(
    path: str | os.PathLike[str],
    run: int | None = None,
    *,
    range_offset_m: float = 0.0,
    sha256: str | None = None,
    noise: NominalNoise | None = None,
) -> Dataset:
    """Load a Plaza MAT file as a :class:`~locbench.datasets.dataset.Dataset` (module docstring).

    Parameters
    ----------
    path : path-like
        ``Plaza1_.mat`` or ``Plaza2_.mat`` (or a file of the same format).
    run : {1, 2} or None
        Which run's frozen nominal noise to use; None estimates it from this file with
        :func:`estimate_nominal_noise` (for other files of the format).
    range_offset_m : float
        Subtracted from every range, m (a calibration chosen by the user; 0 keeps the recorded ranges).
    sha256 : str or None
        Verify the file's checksum first.
    noise : NominalNoise or None
        Overrides the nominal noise.
    """
    # long: the loader's steps over one .mat file's arrays in order, with their refusals; numpydoc
    arrays = read_plaza_mat(path, sha256)
    gt = arrays.GT
    t0, t1 = float(gt[0, 0]), float(gt[-1, 0])
    theta = heading_from_track(gt[:, 1:3], HEADING_CHORD_M)
    truth = Trajectory2D(t=gt[:, 0].copy(), xy=gt[:, 1:3].copy(), theta=theta)

    events: list[Event] = []
    inc = odometry_increments(arrays.DR)
    for (t, *_), (dx, dy, dth) in zip(arrays.DR.tolist(), inc.tolist(), strict=True):
        if t0 <= t <= t1:
            events.append(Odometry(t=t, dx=dx, dy=dy, dtheta=dth))
    if not any(isinstance(e, Odometry) for e in events):
        raise RecordedDataError(
            arrays.path,
            f"variable 'DR': no row inside the 'GT' span [{t0!r}, {t1!r}] s (DR spans {float(arrays.DR[0, 0])!r} .. "
            f"{float(arrays.DR[-1, 0])!r} s), expected odometry during the truth",
        )
    td = arrays.TD
    keep = (td[:, 0] >= t0) & (td[:, 0] <= t1)
    td = td[keep]
    if np.any(td[:, 3] - range_offset_m < 0.0):
        r = int(np.flatnonzero(td[:, 3] - range_offset_m < 0.0)[0])
        raise RecordedDataError(
            arrays.path,
            f"range_offset_m={range_offset_m!r} makes the range {float(td[r, 3])!r} m at t = {float(td[r, 0])!r} s "
            "negative, expected ranges >= 0 after the offset",
        )
    if td.shape[0]:
        starts = np.flatnonzero(np.concatenate([[True], np.diff(td[:, 0]) > 0]))
        for a, b in zip(starts, np.concatenate([starts[1:], [td.shape[0]]]), strict=True):
            events.append(
                RangeObservations(
                    t=float(td[a, 0]),
                    ids=td[a:b, 2].astype(np.int64),
                    ranges=td[a:b, 3] - range_offset_m,
                )
            )

    if noise is None:
        noise = NOMINAL_NOISE[run] if run is not None else estimate_nominal_noise(arrays)[0]
    sensors = SensorSpec(
        range_sigma_m=noise.range_sigma_m,
        odometry_sigma_xy_per_m=noise.odometry_sigma_xy_per_m,
        odometry_sigma_theta_per_m=noise.odometry_sigma_theta_per_m,
        odometry_sigma_theta_per_rad=0.0,
    )
    tl = arrays.TL
    world = WorldMap(landmarks=Landmarks(ids=tl[:, 0].astype(np.int64), xy=tl[:, 1:3].copy()))
    initial = Gaussian2(
        mean=np.array([gt[0, 1], gt[0, 2], theta[0]]),
        cov=np.diag([INITIAL_SIGMA_XY_M**2, INITIAL_SIGMA_XY_M**2, INITIAL_SIGMA_THETA_RAD**2]),
    )
    metadata: dict[str, Any] = {
        "source": "Djugash, Hamner & Roth 2009, J. Field Robotics 26(9):689-695; GTSAM copy " + _GTSAM_COMMIT,
        "file": arrays.path.name,
        "senders": sorted({int(s) for s in arrays.TD[:, 1]}),
        "td_rows_out_of_order": arrays.td_rows_out_of_order,
        "range_offset_m": range_offset_m,
        "truth_heading": f"direction of travel of GT over a {HEADING_CHORD_M} m chord (GT's heading column unused)",
        **dead_reckoning_check(arrays),
    }
    return Dataset(
        id="plaza",
        params={},
        events=sort_events(events),
        ground_truth=truth,
        initial=initial,
        world=world,
        sensors=sensors,
        metadata=metadata,
        truth_label="ground truth",
        sources=(str(arrays.path),),
        declared=frozenset({RangeObservations}),
        flagged=arrays.flagged,
    )


#: The largest range calibration ``range_offset_m`` takes, m: several times the recorded bias (a median residual
#: of +2.8 m), far below the ranges themselves (tens of metres).
MAX_RANGE_OFFSET_M = 10.0


@dataclass(frozen=True, kw_only=True)
class PlazaParams:
    """Parameters of ``plaza``.

    Attributes
    ----------
    run : int
        1 (Plaza1_.mat, 1933 s) or 2 (Plaza2_.mat, 410 s).
    range_offset_m : float
        Subtracted from every range, m (0: the recorded ranges; see the module docstring on their offset), within
        +-:data:`MAX_RANGE_OFFSET_M`.
    """

    run: int = 1
    range_offset_m: float = field(
        default=0.0, metadata=bound(-MAX_RANGE_OFFSET_M, MAX_RANGE_OFFSET_M, unit="m", what="a range calibration")
    )

    def __post_init__(self) -> None:
        if self.run not in (1, 2):
            raise ConfigError(f"plaza: run must be 1 or 2, got {self.run}")
        if not math.isfinite(self.range_offset_m):
            raise ConfigError(f"plaza: range_offset_m must be finite, got {self.range_offset_m}")


class PlazaDataset(RecordedDataset):
    """CMU Plaza range-only runs (Djugash et al. 2009): ``plaza[run=1]`` and ``plaza[run=2]``."""

    id: ClassVar[str] = "plaza"
    Params: ClassVar[type] = PlazaParams
    version: ClassVar[int] = 1
    description: ClassVar[str] = (
        "CMU Plaza range-only runs (recorded, Djugash et al. 2009): odometry, radio ranges to 4 beacons, GPS truth"
    )
    folder: ClassVar[str] = FOLDER
    reference_kind: ClassVar[str] = "GPS"
    identity_keys: ClassVar[tuple[str, ...]] = ("run",)

    @classmethod
    def files(cls, params: PlazaParams) -> list[RemoteFile]:
        """The run's MAT file, with its sha256 and GTSAM's copy as the download."""
        return [
            RemoteFile(
                relpath=f"{FOLDER}/Plaza{params.run}_.mat",
                sha256=SHA256[params.run],
                url=_URL.format(run=params.run),
            )
        ]

    def build(self, params: PlazaParams, rng: np.random.Generator) -> Dataset:
        """Load the run (verified); ``rng`` is unused (recorded data does not depend on the seed)."""
        (path,) = self.paths(params).values()
        return load_plaza(path, params.run, range_offset_m=params.range_offset_m)
