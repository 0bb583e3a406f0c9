"""The UTIAS Multi-Robot Cooperative Localization and Mapping dataset (MRCLAM): 5 robots, 15 landmarks, Vicon truth.

Source
------
K. Y. K. Leung, Y. Halpern, T. D. Barfoot, H. H. T. Liu, "The UTIAS Multi-Robot Cooperative Localization and
Mapping Dataset", Int. J. Robotics Research 30(8):969-974, 2011. Official download:
http://asrl.utias.utoronto.ca/datasets/mrclam/ (``MRCLAM_Dataset1.zip`` .. ``MRCLAM_Dataset9.zip``). Five iRobot
Create robots (subjects 1-5) drive for 15-30 minutes in a 15 m x 8 m hall among 15 cylindrical landmarks
(subjects 6-20) carrying barcodes; each robot's monocular camera reports range and bearing to the barcodes it
reads. A Vicon system gives every robot's pose (about 1 mm) and the landmarks' surveyed positions.

Files and checksums
-------------------
The loader reads ``$LOCBENCH_DATA/utias_mrclam/MRCLAM_DatasetN/`` (N = 1..9). Only Dataset 6 is in the shared
data folder and only its 17 files have known sha256 (SOURCES.md); they are verified file by file, wherever the
file comes from. For Datasets 1-5 and 7-9 NOTHING is verified: their files are read as found. The download
(:meth:`MrclamDataset.fetch`) takes the official zip with pooch and unpacks it into the cache (``pooch.Unzip``);
the zip's own hash is unknown, so the download itself is not verified, but after extraction every Dataset 6
file is checked against its sha256 (a mismatch is removed from the cache and raised); other datasets'
extracted files stay unverified.

Format
------
Whitespace/tab separated text, 4 ``#`` header lines, CRLF line ends (read with
:func:`~locbench.datasets.recorded.files.read_table`):

==========================  ==========================================================================
file                        columns
==========================  ==========================================================================
``Barcodes.dat``            subject #, barcode #
``Landmark_Groundtruth``    subject #, x (m), y (m), x std-dev (m), y std-dev (m)
``RobotR_Groundtruth.dat``  time (s), x (m), y (m), heading (rad): Vicon, about 65 Hz (measured on Dataset 6)
``RobotR_Odometry.dat``     time (s), forward speed v (m/s), turn rate omega (rad/s): the velocity commands
``RobotR_Measurement.dat``  time (s), BARCODE # (despite the header's "Subject #"), range (m), bearing (rad)
==========================  ==========================================================================

Rates measured on Dataset 6 (robots 1-5 pooled): the Vicon truth has a median interval of 16.0 ms and 65
samples/s on average (63-69 per robot), not the 100 Hz sometimes quoted; the odometry a median interval of
10 ms and 68 samples/s on average.

Validation (besides the table checks of :func:`~locbench.datasets.recorded.files.read_table`: field count,
numbers, integer ids, finite values, a last line without its line end refused as cut). Refused (structural or a
limit): truth, odometry and sighting times going backwards (repeated stamps are allowed: they move nothing), every
truth or odometry time equal, positions beyond :data:`~locbench.datasets.recorded.files.MAX_POSITION_M`, a gap above
:data:`MAX_GAP_S` between two odometry or two truth samples anywhere in the file (an odometry sample is held over its
interval and the truth interpolated between its samples: a gap is never bridged), a run without one odometry
interval with dt > 0 inside the truth span. Flagged (:mod:`~locbench.datasets.recorded.plausibility`: left out,
listed in ``Dataset.flagged``, the file refused beyond 1 % or a 2 s stretch): a Vicon sample the robot could not
have reached from the last accepted one (faster than :data:`MAX_SPEED_MPS` plus :data:`TRUTH_JITTER_M`, or than
the policy's turn rate plus its heading jitter), a speed beyond :data:`MAX_SPEED_MPS` or a turn rate beyond
:data:`MAX_TURN_RATE_RADPS` in the odometry, a range outside [0, :data:`MAX_RANGE_M`], a bearing or heading beyond
+-2 pi, a line that repeats the one before it in every field.

Time is Unix seconds (NTP-synchronised between robots and Vicon); it is kept as is (no shift). The world frame is
the Vicon frame; the robot frame has x forward; bearings are counter-clockwise from x, measured from the robot
origin (the camera is treated as sitting on it, as the dataset's own measurement model does).

How the dataset is derived
--------------------------
* **Time span.** Events are trimmed to the ground truth: the first odometry sample at or after the first Vicon
  sample starts the run (time t0), and no event lies after the last Vicon sample. The truth starts with its
  pose at t0 (linearly interpolated between the two Vicon samples around t0, headings unwrapped; at most 10 ms
  apart) followed by every Vicon sample after t0, so the truth covers every event and its first pose is the
  pose at the start of the odometry. Sightings before t0 are dropped (nothing moves the filters there).
* **Odometry.** Sample k = (t_k, v_k, omega_k) is a command held until the next sample (causal zero-order hold):
  one :class:`~locbench.core.events.Odometry` at t_{k+1} carries ``v = v_k``, ``omega = omega_k``,
  ``dt = t_{k+1} - t_k`` and the exact constant-twist increment in the frame of the pose at t_k, with
  a = omega dt::

      dx = v dt sin(a) / a,   dy = v dt (1 - cos a) / a,   dtheta = a      (a -> 0: dx = v dt, dy = 0)

  (:func:`locbench.core.geometry.twist_increment`, through ``sinc`` so it is exact and stable at a = 0). The exact
  arc is chosen over a first-order step because it is what the twist says happened; at 10 ms steps the two differ
  by far less than the twist's own error. Samples with a repeated time stamp (dt = 0, 10 in Robot 4's file)
  move nothing and give no event.
* **Observations.** The barcode column maps to a subject through ``Barcodes.dat``. Subjects 6-20 (landmarks)
  become :class:`~locbench.core.events.LandmarkObservations` with ``ids`` = subject numbers, one event per time
  stamp (all rows of one camera frame together). Sightings of the other robots (subjects 1-5) are NOT given to
  the filters: they are counted in ``metadata["robot_sightings"]`` and returned in full by
  :func:`read_robot_sightings` (a side array: time, subject, range, bearing). Barcodes missing from
  ``Barcodes.dat`` (misreads, e.g. 43, 34 and 50 in Dataset 6) are dropped and counted per barcode in
  ``metadata["unknown_barcodes"]``.
* **Map.** ``Landmark_Groundtruth.dat``: ids = subjects, positions and their Vicon standard deviations
  (:attr:`~locbench.datasets.dataset.Landmarks.std_xy`).
* **Initial belief.** Mean = the truth pose at t0. Covariance diag(0.01 m, 0.01 m, 0.02 rad)^2
  (:data:`INITIAL_SIGMA_XY_M`, :data:`INITIAL_SIGMA_THETA_RAD`): ten times Vicon's ~1 mm for position, and a
  heading margin that covers the offsets between the Vicon body frame and the camera's axis seen in Dataset 6
  (per-robot median bearing residual up to 0.014 rad, robot 4). The filters thus start "known", as on
  ``room``, without being told a sub-millimetre certainty the robot frame does not have.
* **Waypoints.** Every ``waypoint_spacing_m`` (default 5 m) of distance travelled along the truth, waypoint j is
  the first Vicon sample at which the travelled distance reaches j * spacing, marked at the truth position
  at that time. The distance is measured along the truth thinned to points at least
  :data:`PATH_STEP_M` = 5 cm apart, because the raw Vicon jitter (about 1 mm per sample against
  about 1 mm of travel) inflates the raw path length by 5-10 %. The spacing must be at least that step and
  may make at most :data:`~locbench.datasets.recorded.files.MAX_DERIVED_ITEMS` waypoints.

Nominal noise: how the frozen constants were derived
----------------------------------------------------
The dataset publishes no noise figures. The noise a run of robot r is given is derived on the other four robots of
Dataset 6 (leave-one-robot-out fold r, :func:`locbench.datasets.splits.mrclam_fold`), so no robot's own data enters
its noise: :func:`~locbench.datasets.recorded.mrclam_noise.derive_nominal_noise` (robust standard deviations of the
camera residuals and of the twist's error over 1 s windows, against the Vicon truth and the surveyed map; the
procedure is in :mod:`~locbench.datasets.recorded.mrclam_noise`) was run ONCE per fold and its results frozen in
:data:`FOLD_NOISE` (:func:`nominal_sensors`); ``tests/datasets/recorded/test_recorded_mrclam.py`` reruns it on the
shared files and checks they agree within 10 %. They were not chosen by looking at any filter's error. A robot of
another dataset (1-5, 7-9) is given the fold of its robot number (those data entered no fold).

Known caveats: the camera has outliers (misread barcodes mapped to a wrong landmark, reflections) that a robust
std ignores; a filter that fuses every detection without a gate sees them at full weight.
"""

from __future__ import annotations

import functools
import math
import os
import re
import shutil
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from locbench.core.errors import ConfigError, DependencyNotInstalled
from locbench.core.events import Event, LandmarkObservations, Odometry
from locbench.core.geometry import twist_increment, wrap_angle
from locbench.datasets.dataset import (
    Dataset,
    FlaggedSample,
    Gaussian2,
    Landmarks,
    SensorSpec,
    Trajectory2D,
    Waypoints,
    WorldMap,
    sort_events,
)
from locbench.datasets.recorded import plausibility
from locbench.datasets.recorded.common import RecordedDataset
from locbench.datasets.recorded.files import (
    MAX_DERIVED_ITEMS,
    MAX_POSITION_M,
    RecordedDataError,
    RemoteFile,
    Table,
    cache_root,
    locate,
    read_table,
    verify_sha256,
)
from locbench.datasets.splits import MRCLAM_ROBOTS

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

#: Sub-folder of the data root.
FOLDER = "utias_mrclam"
#: Official zip of dataset N.
ZIP_URL = "http://asrl.utias.utoronto.ca/datasets/mrclam/MRCLAM_Dataset{n}.zip"
#: Dataset numbers and robot numbers.
DATASET_NUMBERS = tuple(range(1, 10))
ROBOTS = MRCLAM_ROBOTS
#: Subjects that are robots; landmarks are subjects 6-20.
ROBOT_SUBJECTS = frozenset(ROBOTS)
FIRST_LANDMARK_SUBJECT = 6
CITATION = (
    'K. Y. K. Leung, Y. Halpern, T. D. Barfoot, H. H. T. Liu, "The UTIAS Multi-Robot Cooperative Localization '
    'and Mapping Dataset", Int. J. Robotics Research 30(8):969-974, 2011'
)

#: sha256 of Dataset 6's files (SOURCES.md); the other datasets' are unknown.
DATASET6_SHA256: dict[str, str] = {
    "Barcodes.dat": "6b418dfacabb6556e0bf3a4e90efeca89775fae1e73521d7baeb8844828186eb",
    "Landmark_Groundtruth.dat": "ca586b164e66caf642895f735c66fe4195ceb963ba7dce303b3aa0307072795d",
    "Robot1_Groundtruth.dat": "a5922ef6a548ed5a9ca656817f0ac23ab1226a4725e296068abf51df7133906e",
    "Robot1_Measurement.dat": "0ad9f9baf5bf45746363c3a7653c2292f75e65ef851933c79b5a22622131a5b3",
    "Robot1_Odometry.dat": "11aff992a8d6825afb4a1fd0ba0f00c49cdd341acabe590dce73545607f1d7d6",
    "Robot2_Groundtruth.dat": "94a6b85947715d1a4d26428ea0eb5244f267b72198b3cf9f62df13b2a3282e24",
    "Robot2_Measurement.dat": "658f259bf510a46b20b3f6b011b4ec3fb94abf4cb151e4b70157bcf59976ef9c",
    "Robot2_Odometry.dat": "a99435568f62a9f371c2287730a1d83d94d75bbf1351bb3d470ed70e60b1cbfe",
    "Robot3_Groundtruth.dat": "9de1eceb29374b0e805215e81fa93677ff47db28767f5c9e1f05dceb526904b4",
    "Robot3_Measurement.dat": "7a09702f5f6b9eefc903eb626c55413c606b3c018a85d775d43c551754eeb11d",
    "Robot3_Odometry.dat": "a08e5b6a5dd208c8c63ab972022b9a609865628a219b04d0addbb939ea77bda3",
    "Robot4_Groundtruth.dat": "285bc8ce97ed13f8f6096d99ac42c1af6a2a6f598f21e58ca9f7fd51a54b39d4",
    "Robot4_Measurement.dat": "a9669363963cfdf57e1ad4d2f6af39ea8cec0269c69e3d02260758af5cddad89",
    "Robot4_Odometry.dat": "c7027d13fdc31ed9686097fcc7fbaf19b95935a7970e7ab433fdc1a1d119e97f",
    "Robot5_Groundtruth.dat": "121bab6a92544864dd39138eaf3f3bc273d0342e3cdd0a745d0d2019c0b5757e",
    "Robot5_Measurement.dat": "9cfb9b8872395b40bb64b0e194b98e7b480711a379a4005674850f83cdebd151",
    "Robot5_Odometry.dat": "d6e9fab30a0da8f73917a2fabf71360387a42975d42f552f9042496538cb2efe",
}
KNOWN_SHA256: dict[int, dict[str, str]] = {6: DATASET6_SHA256}

#: Initial belief standard deviations around the first truth pose (see the module docstring).
INITIAL_SIGMA_XY_M = 0.01
INITIAL_SIGMA_THETA_RAD = 0.02
#: Minimum spacing of the thinned truth used to measure distance travelled, m.
PATH_STEP_M = 0.05
#: Default distance between waypoints, m.
WAYPOINT_SPACING_M = 5.0
#: Physical bounds of the validation: an iRobot Create's top speed is 0.5 m/s (Dataset 6 commands at most 0.086 m/s
#: and 0.57 rad/s); twice that speed and about 2.5 times its top turn rate.
MAX_SPEED_MPS = 1.0
MAX_TURN_RATE_RADPS = 10.0
#: Largest interval between two odometry samples or two Vicon samples, anywhere in the file, s (Dataset 6: at most
#: 1.03 s for the odometry, 2.03 s for the truth). An odometry sample is held over its interval and the truth is
#: interpolated between its samples, so a longer gap (a clock jump, lost data) is refused, never bridged.
MAX_GAP_S = 10.0
#: Allowance for Vicon noise between two close samples, m: a truth step may move at most
#: ``MAX_SPEED_MPS * dt + TRUTH_JITTER_M`` (Dataset 6: at most 0.025 m in one 16 ms step).
TRUTH_JITTER_M = 0.05
MAX_RANGE_M = 100.0
#: The plausibility bounds tightened with the platform's limits (an iRobot Create in a 15 m hall).
BOUNDS = plausibility.BOUNDS.tightened(
    speed_mps=MAX_SPEED_MPS,
    turn_rate_radps=MAX_TURN_RATE_RADPS,
    range_m=MAX_RANGE_M,
    heading_abs_rad=2 * math.pi,
    position_jitter_m=TRUTH_JITTER_M,
)

# --- the nominal noise: frozen output of mrclam_noise.derive_fold_noise (Dataset 6, one fold per held-out robot) ---

#: The SensorSpec fields of the nominal noise, in the order of the tables below.
NOISE_FIELDS: tuple[str, ...] = (
    "twist_sigma_v_mps",
    "twist_sigma_omega_radps",
    "odometry_sigma_xy_per_m",
    "odometry_sigma_theta_per_m",
    "odometry_sigma_theta_per_rad",
    "landmark_sigma_range_m",
    "landmark_sigma_bearing_rad",
)
#: Held-out robot -> the noise derived on the other four robots of Dataset 6 (derive_fold_noise, rounded to 3
#: significant digits; the fields of NOISE_FIELDS, in m/s, rad/s, m/sqrt(m), rad/sqrt(m), rad/sqrt(rad), m, rad).
#: derive_fold_noise on Dataset 6 pooled, per fold, 11035-13849 landmark sightings (median residual +0.006 to
#: +0.026 m, -0.0006 to -0.0023 rad) and 2713-2958 one-second windows (1504-1704 straight, 44-118 turning in place;
#: fold 5 has 44: robot 5 turns in place most), dt_eff = 0.0182-0.0190 s.
FOLD_NOISE: dict[int, dict[str, float]] = {
    1: {
        "twist_sigma_v_mps": 0.0536,
        "twist_sigma_omega_radps": 0.118,
        "odometry_sigma_xy_per_m": 0.0213,
        "odometry_sigma_theta_per_m": 0.0317,
        "odometry_sigma_theta_per_rad": 0.182,
        "landmark_sigma_range_m": 0.144,
        "landmark_sigma_bearing_rad": 0.0082,
    },
    2: {
        "twist_sigma_v_mps": 0.0538,
        "twist_sigma_omega_radps": 0.108,
        "odometry_sigma_xy_per_m": 0.0216,
        "odometry_sigma_theta_per_m": 0.0332,
        "odometry_sigma_theta_per_rad": 0.158,
        "landmark_sigma_range_m": 0.128,
        "landmark_sigma_bearing_rad": 0.00784,
    },
    3: {
        "twist_sigma_v_mps": 0.0537,
        "twist_sigma_omega_radps": 0.117,
        "odometry_sigma_xy_per_m": 0.0214,
        "odometry_sigma_theta_per_m": 0.0325,
        "odometry_sigma_theta_per_rad": 0.196,
        "landmark_sigma_range_m": 0.147,
        "landmark_sigma_bearing_rad": 0.00929,
    },
    4: {
        "twist_sigma_v_mps": 0.0552,
        "twist_sigma_omega_radps": 0.12,
        "odometry_sigma_xy_per_m": 0.0216,
        "odometry_sigma_theta_per_m": 0.0337,
        "odometry_sigma_theta_per_rad": 0.182,
        "landmark_sigma_range_m": 0.135,
        "landmark_sigma_bearing_rad": 0.00749,
    },
    5: {
        "twist_sigma_v_mps": 0.0547,
        "twist_sigma_omega_radps": 0.109,
        "odometry_sigma_xy_per_m": 0.0215,
        "odometry_sigma_theta_per_m": 0.0342,
        "odometry_sigma_theta_per_rad": 0.264,
        "landmark_sigma_range_m": 0.14,
        "landmark_sigma_bearing_rad": 0.00994,
    },
}
#: What the noise was before it was derived per fold: pooled over all five robots of Dataset 6, every robot's own data
#: included (kept for the comparison in docs/data.md; no run is given it).
POOLED_NOISE_ALL_ROBOTS: dict[str, float] = {
    "twist_sigma_v_mps": 0.0542,
    "twist_sigma_omega_radps": 0.115,
    "odometry_sigma_xy_per_m": 0.0215,
    "odometry_sigma_theta_per_m": 0.0331,
    "odometry_sigma_theta_per_rad": 0.182,
    "landmark_sigma_range_m": 0.139,
    "landmark_sigma_bearing_rad": 0.00841,
}

_GT_COLUMNS = ("time [s]", "x [m]", "y [m]", "heading [rad]")
_ODO_COLUMNS = ("time [s]", "forward velocity [m/s]", "angular velocity [rad/s]")
_MEAS_COLUMNS = ("time [s]", "barcode #", "range [m]", "bearing [rad]")
_BARCODE_COLUMNS = ("subject #", "barcode #")
_LANDMARK_COLUMNS = ("subject #", "x [m]", "y [m]", "x std-dev [m]", "y std-dev [m]")


def nominal_sensors(robot: int) -> SensorSpec:
    """The frozen nominal noise a run of ``robot`` is given: fold ``robot``'s, derived on the other four robots of
    Dataset 6 (see the module docstring)."""
    if robot not in FOLD_NOISE:
        raise ConfigError(f"robot must be one of {sorted(FOLD_NOISE)}, got {robot!r}")
    return SensorSpec(**FOLD_NOISE[robot])


# --- file names ------------------------------------------------------------------------------------------


def dataset_folder_name(dataset: int) -> str:
    """``MRCLAM_DatasetN``."""
    return f"MRCLAM_Dataset{dataset}"


def robot_file_names(robot: int) -> dict[str, str]:
    """The three per-robot files, keyed ``groundtruth``, ``odometry``, ``measurement``."""
    return {
        "groundtruth": f"Robot{robot}_Groundtruth.dat",
        "odometry": f"Robot{robot}_Odometry.dat",
        "measurement": f"Robot{robot}_Measurement.dat",
    }


def file_names(robot: int) -> dict[str, str]:
    """Every file one robot's run needs, keyed ``barcodes``, ``landmarks`` and those of :func:`robot_file_names`."""
    return {"barcodes": "Barcodes.dat", "landmarks": "Landmark_Groundtruth.dat", **robot_file_names(robot)}


def _check_numbers(dataset: int, robot: int) -> None:
    if dataset not in DATASET_NUMBERS:
        raise ConfigError(f"dataset must be one of {list(DATASET_NUMBERS)}, got {dataset!r}")
    if robot not in ROBOTS:
        raise ConfigError(f"robot must be one of {list(ROBOTS)}, got {robot!r}")


# --- parsing (cached per path, size and mtime) -----------------------------------------------------------


def _cache_key(path: str | os.PathLike[str]) -> tuple[str, int, int]:
    p = Path(path)
    try:
        st = p.stat()
    except FileNotFoundError:
        raise RecordedDataError(p, "missing file (expected an MRCLAM .dat text file)") from None
    return str(p.resolve()), st.st_size, st.st_mtime_ns


@functools.lru_cache(maxsize=32)
def _table_cached(path: str, size: int, mtime_ns: int, columns: tuple[str, ...], ints: tuple[int, ...]) -> Table:
    return read_table(path, columns, integer_columns=ints)


def _table(path: str | os.PathLike[str], columns: tuple[str, ...], ints: tuple[int, ...] = ()) -> Table:
    return _table_cached(*_cache_key(path), columns, ints)


def read_barcodes(path: str | os.PathLike[str]) -> dict[int, int]:
    """Barcode # -> subject # from ``Barcodes.dat``.

    Raises
    ------
    RecordedDataError
        A malformed line, or a barcode or subject listed twice (naming the line).
    """
    tab = _table(path, _BARCODE_COLUMNS, (0, 1))
    out: dict[int, int] = {}
    seen_subject: set[int] = set()
    for k, (s, b) in enumerate(tab.rows):
        subject, barcode = int(s), int(b)
        if barcode in out:
            raise tab.fail(k, f"barcode {barcode} listed twice (expected one subject per barcode)")
        if subject in seen_subject:
            raise tab.fail(k, f"subject {subject} listed twice (expected one barcode per subject)")
        out[barcode] = subject
        seen_subject.add(subject)
    if not out:
        raise RecordedDataError(path, "no barcodes (expected 'subject# barcode#' lines)")
    return out


def read_landmarks(path: str | os.PathLike[str]) -> Landmarks:
    """The surveyed landmarks of ``Landmark_Groundtruth.dat``: ids = subjects, (x, y) m and their std-dev m."""
    tab = _table(path, _LANDMARK_COLUMNS, (0,))
    for col in (1, 2):
        tab.check_range(col, _LANDMARK_COLUMNS[col], -MAX_POSITION_M, MAX_POSITION_M)
    ids = tab.rows[:, 0].astype(np.int64)
    for k in range(ids.shape[0]):
        if ids[k] < FIRST_LANDMARK_SUBJECT:
            raise tab.fail(k, f"subject {ids[k]} is a robot (expected a landmark subject >= {FIRST_LANDMARK_SUBJECT})")
        if np.any(tab.rows[k, 3:5] < 0):
            raise tab.fail(k, "negative standard deviation (expected >= 0)")
    seen: set[int] = set()
    for k, i in enumerate(ids.tolist()):
        if i in seen:
            raise tab.fail(k, f"landmark {i} listed twice (expected one line per landmark)")
        seen.add(i)
    if ids.size == 0:
        raise RecordedDataError(path, "no landmarks (expected 'subject# x y x_std y_std' lines)")
    return Landmarks(ids=ids, xy=tab.rows[:, 1:3].copy(), std_xy=tab.rows[:, 3:5].copy())


def read_groundtruth(path: str | os.PathLike[str]) -> Trajectory2D:
    """The Vicon poses of one robot (headings wrapped to (-pi, pi]) without the flagged ones (:func:`groundtruth`)."""
    return groundtruth(path)[0]


def groundtruth(path: str | os.PathLike[str]) -> tuple[Trajectory2D, tuple[FlaggedSample, ...]]:
    """The Vicon poses of one robot (headings wrapped to (-pi, pi]) and the samples flagged and left out.

    Time must not go backwards nor be the same everywhere, and no gap may exceed :data:`MAX_GAP_S` (refused); a
    heading beyond +-2 pi, an exact repeat of the previous line, or a pose the robot could not have reached from
    the last accepted one (:data:`BOUNDS`) is flagged.
    """
    tab = _table(path, _GT_COLUMNS)
    tab.check_rows("ground-truth", 2)
    tab.check_time_non_decreasing(0, "time [s]")
    plausibility.refuse_all_times_equal(tab.path, "ground-truth", tab.rows[:, 0], int(tab.lines[1]))
    for col in (1, 2):
        tab.check_range(col, _GT_COLUMNS[col], -MAX_POSITION_M, MAX_POSITION_M)
    _check_gaps(tab, "ground-truth")
    flags = plausibility.Flags(tab.path, "ground-truth", tab.rows[:, 0], tab.lines)
    h = BOUNDS.heading_abs_rad
    flags.flag_outside(tab.rows[:, 3], "heading, rad", -h, h)
    flags.flag_duplicates(tab.rows)
    flags.flag_track(tab.rows[:, 1:3], tab.rows[:, 3], BOUNDS)
    kept = tab.rows[flags.kept]
    truth = Trajectory2D(t=kept[:, 0].copy(), xy=kept[:, 1:3].copy(), theta=wrap_angle(kept[:, 3]))
    return truth, flags.finish()


def _check_gaps(tab: Table, what: str) -> None:
    """Refuse an interval above :data:`MAX_GAP_S` between two rows of ``tab`` (column 0: time, s)."""
    dt = np.diff(tab.rows[:, 0])
    gap = np.flatnonzero(dt > MAX_GAP_S)
    if gap.size:
        k = int(gap[0]) + 1
        raise tab.fail(
            k,
            f"{what} time jumps {float(dt[k - 1]):.6g} s from the previous sample, expected gaps of at most "
            f"{MAX_GAP_S} s (a gap is not bridged)",
        )


def read_odometry(path: str | os.PathLike[str]) -> Table:
    """The velocity commands (t s, v m/s, omega rad/s) without the flagged rows (:func:`odometry`)."""
    return odometry(path)[0]


def odometry(path: str | os.PathLike[str]) -> tuple[Table, tuple[FlaggedSample, ...]]:
    """The velocity commands (t s, v m/s, omega rad/s) and the rows flagged and left out.

    Time must not go backwards nor be the same everywhere, and no gap may exceed :data:`MAX_GAP_S` (refused); a
    speed beyond :data:`MAX_SPEED_MPS`, a turn rate beyond :data:`MAX_TURN_RATE_RADPS` or an exact repeat of the
    previous line is flagged (a left-out command: the one before it is held over both intervals).
    """
    tab = _table(path, _ODO_COLUMNS)
    tab.check_rows("odometry", 2)
    tab.check_time_non_decreasing(0, "time [s]")
    plausibility.refuse_all_times_equal(tab.path, "odometry", tab.rows[:, 0], int(tab.lines[1]))
    _check_gaps(tab, "odometry")
    flags = plausibility.Flags(tab.path, "odometry", tab.rows[:, 0], tab.lines)
    flags.flag_outside(tab.rows[:, 1], _ODO_COLUMNS[1], -BOUNDS.speed_mps, BOUNDS.speed_mps)
    flags.flag_outside(tab.rows[:, 2], _ODO_COLUMNS[2], -BOUNDS.turn_rate_radps, BOUNDS.turn_rate_radps)
    flags.flag_duplicates(tab.rows)
    return _kept(tab, flags), flags.finish()


def read_measurements(path: str | os.PathLike[str]) -> Table:
    """The camera's barcode sightings (t s, barcode #, range m, bearing rad) without the flagged rows."""
    return measurements(path)[0]


def measurements(path: str | os.PathLike[str]) -> tuple[Table, tuple[FlaggedSample, ...]]:
    """The camera's barcode sightings (t s, barcode #, range m, bearing rad) and the rows flagged and left out.

    Time must not go backwards (refused); a range outside [0, :data:`MAX_RANGE_M`], a bearing beyond +-2 pi or an
    exact repeat of the previous line is flagged.
    """
    tab = _table(path, _MEAS_COLUMNS, (1,))
    tab.check_time_non_decreasing(0, "time [s]")
    flags = plausibility.Flags(tab.path, "sighting", tab.rows[:, 0], tab.lines)
    flags.flag_outside(tab.rows[:, 2], _MEAS_COLUMNS[2], 0.0, BOUNDS.range_m)
    flags.flag_outside(tab.rows[:, 3], _MEAS_COLUMNS[3], -BOUNDS.heading_abs_rad, BOUNDS.heading_abs_rad)
    flags.flag_duplicates(tab.rows)
    return _kept(tab, flags), flags.finish()


def _kept(tab: Table, flags: plausibility.Flags) -> Table:
    """``tab`` without its flagged rows (each kept row keeps its line number)."""
    return Table(tab.path, tab.rows[flags.kept], tab.lines[flags.kept])


# --- derived quantities -----------------------------------------------------------------------------------


def odometry_events(t: FloatArray, v: FloatArray, omega: FloatArray) -> list[Odometry]:
    """One :class:`Odometry` per interval between consecutive samples with dt > 0 (zero-order hold of sample k).

    ``t``, ``v``, ``omega`` are the samples (n,) in s, m/s, rad/s; the event of interval (t_k, t_{k+1}] is stamped
    t_{k+1} and carries (v_k, omega_k, dt) and the exact increment of :func:`locbench.core.geometry.twist_increment`.
    """
    dt = np.diff(t)
    keep = np.flatnonzero(dt > 0)
    dx, dy, dth = twist_increment(v[keep], omega[keep], dt[keep])
    te = t[keep + 1]
    return [
        Odometry(t=float(te[i]), dx=float(dx[i]), dy=float(dy[i]), dtheta=float(dth[i]),
                 v=float(v[k]), omega=float(omega[k]), dt=float(dt[k]))
        for i, k in enumerate(keep.tolist())
    ]  # fmt: skip


@dataclass(frozen=True, eq=False)
class Sightings:
    """Camera sightings as parallel arrays: ``t`` (n,) s, ``subject`` (n,) int64, ``ranges`` (n,) m, ``bearings``
    (n,) rad (robot frame)."""

    t: FloatArray
    subject: IntArray
    ranges: FloatArray
    bearings: FloatArray

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def select(self, mask: npt.NDArray[np.bool_]) -> Sightings:
        return Sightings(self.t[mask], self.subject[mask], self.ranges[mask], self.bearings[mask])


def split_sightings(meas: Table, barcodes: dict[int, int]) -> tuple[Sightings, Sightings, dict[int, int]]:
    """Map barcodes to subjects and split: (landmark sightings, robot sightings, {unknown barcode: count}).

    Landmark sightings are subjects >= 6, robot sightings subjects 1-5; rows whose barcode is not in
    ``barcodes`` are dropped and counted.
    """
    rows = meas.rows
    codes = rows[:, 1].astype(np.int64)
    subject = np.array([barcodes.get(int(c), -1) for c in codes], dtype=np.int64)
    unknown = subject < 0
    counts: dict[int, int] = {}
    for c in codes[unknown].tolist():
        counts[int(c)] = counts.get(int(c), 0) + 1
    allsight = Sightings(rows[:, 0].copy(), subject, rows[:, 2].copy(), wrap_angle(rows[:, 3]))
    is_robot = np.isin(subject, list(ROBOT_SUBJECTS))
    return allsight.select(subject >= FIRST_LANDMARK_SUBJECT), allsight.select(is_robot), dict(sorted(counts.items()))


def landmark_events(s: Sightings) -> list[LandmarkObservations]:
    """One :class:`LandmarkObservations` per distinct time stamp (rows are in time order)."""
    if len(s) == 0:
        return []
    starts = np.flatnonzero(np.r_[True, np.diff(s.t) != 0])
    ends = np.r_[starts[1:], len(s)]
    return [
        LandmarkObservations(t=float(s.t[a]), ids=s.subject[a:b].copy(), ranges=s.ranges[a:b].copy(),
                             bearings=s.bearings[a:b].copy())
        for a, b in zip(starts.tolist(), ends.tolist(), strict=True)
    ]  # fmt: skip


def interpolate_pose(truth: Trajectory2D, t: npt.ArrayLike) -> FloatArray:
    """Truth poses (x, y, theta wrapped) linearly interpolated at times ``t`` (heading unwrapped first), (n, 3)."""
    tq = np.atleast_1d(np.asarray(t, dtype=np.float64))
    th = np.unwrap(truth.theta)
    return np.column_stack(
        [np.interp(tq, truth.t, truth.xy[:, 0]), np.interp(tq, truth.t, truth.xy[:, 1]),
         wrap_angle(np.interp(tq, truth.t, th))]
    )  # fmt: skip


def distance_travelled(xy: FloatArray, step_m: float = PATH_STEP_M) -> FloatArray:
    """Distance travelled up to each point, m, along the path thinned to points at least ``step_m`` apart.

    A point is kept when it lies ``step_m`` or more from the last kept point; the distance at every point is
    that of the last kept point at or before it (so jitter smaller than ``step_m`` adds nothing).
    """
    n = xy.shape[0]
    out = np.zeros(n)
    last = xy[0]
    acc = 0.0
    # A Python loop over ~6e4 points (tens of ms); the thinning is sequential by nature.
    xs, ys = xy[:, 0].tolist(), xy[:, 1].tolist()
    lx, ly = float(last[0]), float(last[1])
    for i in range(1, n):
        d = math.hypot(xs[i] - lx, ys[i] - ly)
        if d >= step_m:
            acc += d
            lx, ly = xs[i], ys[i]
        out[i] = acc
    return out


def waypoints_by_distance(truth: Trajectory2D, spacing_m: float, step_m: float = PATH_STEP_M) -> Waypoints:
    """Waypoint j (from 1) at the first truth sample where the distance travelled reaches j * ``spacing_m``.

    Raises :class:`ConfigError` (before allocating) when that would make more than ``MAX_DERIVED_ITEMS``
    waypoints.
    """
    s = distance_travelled(truth.xy, step_m)
    count = float(s[-1]) / spacing_m if s.size else 0.0
    if not (math.isfinite(count) and count <= MAX_DERIVED_ITEMS):
        raise ConfigError(
            f"waypoint_spacing_m={spacing_m!r}: {float(s[-1]):.4g} m travelled would make {count:.4g} waypoints, "
            f"expected at most {MAX_DERIVED_ITEMS} (raise the spacing)"
        )
    n = int(count)
    idx = np.searchsorted(s, spacing_m * np.arange(1, n + 1), side="left")
    return Waypoints(t=truth.t[idx].copy(), xy=truth.xy[idx].copy())


# --- the run of one robot --------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class RobotRun:
    """Everything parsed for one robot, before it becomes a :class:`Dataset`.

    Attributes
    ----------
    truth : Trajectory2D
        Trimmed Vicon truth starting at t0 (see the module docstring).
    odometry : list of Odometry
        Events in the truth span.
    landmarks : Sightings
        Landmark sightings (subjects 6-20) in the truth span.
    robots : Sightings
        Sightings of the other robots (subjects 1-5) in the truth span: the side array not given to filters.
    unknown_barcodes : dict
        {barcode: count} of rows whose barcode is not in ``Barcodes.dat`` (whole file).
    world : Landmarks
        The surveyed landmark map.
    flagged : tuple of FlaggedSample
        The truth, odometry and sighting rows left out by the plausibility bounds (whole files), in time order.
    """

    truth: Trajectory2D
    odometry: list[Odometry]
    landmarks: Sightings
    robots: Sightings
    unknown_barcodes: dict[int, int]
    world: Landmarks
    flagged: tuple[FlaggedSample, ...] = ()


def _resolve_paths(folder: str | os.PathLike[str], robot: int) -> dict[str, Path]:
    base = Path(folder)
    return {key: base / name for key, name in file_names(robot).items()}


def _verify_folder(paths: dict[str, Path], dataset: int | None) -> None:
    sums = KNOWN_SHA256.get(dataset, {}) if dataset is not None else {}
    for p in paths.values():
        if not p.is_file():
            raise RecordedDataError(p, "missing file (expected an MRCLAM .dat text file)")
        if p.name in sums:
            verify_sha256(p, sums[p.name])


def _check_subjects_on_map(meas: Table, barcodes: dict[int, int], world: Landmarks, map_name: str) -> None:
    """Raise at the first sighting whose barcode names a landmark subject that the map does not have."""
    on_map = set(world.ids.tolist())
    for k, code in enumerate(meas.rows[:, 1].astype(np.int64).tolist()):
        subject = barcodes.get(code, -1)
        if subject >= FIRST_LANDMARK_SUBJECT and subject not in on_map:
            raise meas.fail(
                k,
                f"barcode {code} maps to subject {subject}, which is not in {map_name} (expected a surveyed landmark)",
            )


def parse_robot_run(paths: dict[str, Path]) -> RobotRun:
    """Parse one robot's files (keys as in :func:`file_names`) and trim everything to the truth span."""
    barcodes = read_barcodes(paths["barcodes"])
    world = read_landmarks(paths["landmarks"])
    gt, gt_flags = groundtruth(paths["groundtruth"])
    odo, odo_flags = odometry(paths["odometry"])
    meas, meas_flags = measurements(paths["measurement"])
    t, v, om = odo.rows[:, 0], odo.rows[:, 1], odo.rows[:, 2]
    g0, g1 = float(gt.t[0]), float(gt.t[-1])
    inside = np.flatnonzero((t >= g0) & (t <= g1))
    if inside.size < 2:
        raise RecordedDataError(
            paths["odometry"], f"fewer than 2 odometry samples inside the ground truth span [{g0:.3f}, {g1:.3f}] s"
        )
    t0 = float(t[inside[0]])
    events = odometry_events(t[inside], v[inside], om[inside])
    if not events:
        raise RecordedDataError(
            paths["odometry"],
            f"every odometry sample inside the ground truth span [{g0:.3f}, {g1:.3f}] s has the same time {t0!r}, "
            "expected increasing times (at least one interval with dt > 0)",
        )
    after = gt.t > t0
    first = interpolate_pose(gt, t0)[0]
    truth = Trajectory2D(
        t=np.r_[t0, gt.t[after]],
        xy=np.vstack([first[None, :2], gt.xy[after]]),
        theta=np.r_[first[2], gt.theta[after]],
    )
    _check_subjects_on_map(meas, barcodes, world, paths["landmarks"].name)
    lms, robots, unknown = split_sightings(meas, barcodes)
    lms = lms.select((lms.t >= t0) & (lms.t <= g1))
    robots = robots.select((robots.t >= t0) & (robots.t <= g1))
    return RobotRun(truth, events, lms, robots, unknown, world, plausibility.merge(gt_flags, odo_flags, meas_flags))


def dataset_from_run(
    run: RobotRun, *, noise_fold: int, waypoint_spacing_m: float, metadata: dict[str, Any], sources: Sequence[str] = ()
) -> Dataset:
    """Assemble the :class:`Dataset` of one parsed robot run, given the nominal noise of fold ``noise_fold`` (the
    robot's own fold unless a tuning study holds another robot out; see the module docstring); ``sources`` are its
    files."""
    robot = noise_fold
    if not (math.isfinite(waypoint_spacing_m) and waypoint_spacing_m > 0):
        raise ConfigError(f"waypoint_spacing_m must be a distance > 0 m, got {waypoint_spacing_m}")
    truth = run.truth
    events: list[Event] = [*run.odometry, *landmark_events(run.landmarks)]
    mean = truth.poses[0].copy()
    cov = np.diag([INITIAL_SIGMA_XY_M**2, INITIAL_SIGMA_XY_M**2, INITIAL_SIGMA_THETA_RAD**2])
    robot_counts: dict[int, int] = {}
    for s in run.robots.subject.tolist():
        robot_counts[int(s)] = robot_counts.get(int(s), 0) + 1
    meta = {
        **metadata,
        "citation": CITATION,
        "t0_unix_s": float(truth.t[0]),
        "landmark_sightings": len(run.landmarks),
        "robot_sightings": {"total": len(run.robots), "per_subject": dict(sorted(robot_counts.items()))},
        "robot_sightings_note": "not given to filters; read_robot_sightings() returns them",
        "unknown_barcodes": {str(k): v for k, v in run.unknown_barcodes.items()},
        "unknown_barcode_rows": int(sum(run.unknown_barcodes.values())),
        "waypoint_spacing_m": waypoint_spacing_m,
        "initial_sigma": {"xy_m": INITIAL_SIGMA_XY_M, "theta_rad": INITIAL_SIGMA_THETA_RAD},
        "nominal_noise": (
            f"fold {robot}: frozen from tools/derive/derive_mrclam_noise.py on Dataset 6's robots "
            f"{', '.join(str(r) for r in ROBOTS if r != robot)} (robot {robot} held out); see the module docstring"
        ),
    }
    return Dataset(
        id="mrclam",
        params={},
        events=sort_events(events),
        ground_truth=truth,
        initial=Gaussian2(mean=mean, cov=cov),
        world=WorldMap(landmarks=run.world),
        sensors=nominal_sensors(robot),
        waypoints=waypoints_by_distance(truth, waypoint_spacing_m),
        metadata=meta,
        sources=tuple(sources),
        declared=frozenset({LandmarkObservations}),
        flagged=run.flagged,
    )


_FOLDER_RE = re.compile(r"MRCLAM_Dataset(\d)$")


def _dataset_number(folder: str | os.PathLike[str]) -> int | None:
    m = _FOLDER_RE.search(Path(folder).name)
    return int(m.group(1)) if m else None


def load_mrclam(
    folder: str | os.PathLike[str],
    robot: int,
    *,
    waypoint_spacing_m: float = WAYPOINT_SPACING_M,
    verify: bool = True,
) -> Dataset:
    """Load one robot's run from an unpacked MRCLAM folder (a user's own copy).

    Parameters
    ----------
    folder : path-like
        The folder holding ``Barcodes.dat``, ``Landmark_Groundtruth.dat`` and ``RobotR_*.dat``. When its name is
        ``MRCLAM_DatasetN`` and N has known checksums (only 6), the files are verified.
    robot : int
        1..5.
    waypoint_spacing_m : float
        Distance travelled between waypoints, m.
    verify : bool
        Check sha256 where known.

    Raises
    ------
    RecordedDataError
        A missing, corrupt or malformed file (naming the file, the line and what was expected).
    """
    dataset = _dataset_number(folder)
    if robot not in ROBOTS:
        raise ConfigError(f"robot must be one of {list(ROBOTS)}, got {robot!r}")
    paths = _resolve_paths(folder, robot)
    _verify_folder(paths, dataset if verify else None)
    run = parse_robot_run(paths)
    meta = {"dataset": dataset, "robot": robot, "folder": str(Path(folder)), "verified": verify and dataset == 6}
    return dataset_from_run(
        run,
        noise_fold=robot,
        waypoint_spacing_m=waypoint_spacing_m,
        metadata=meta,
        sources=[str(p) for p in paths.values()],
    )


def read_robot_sightings(folder: str | os.PathLike[str], robot: int) -> Sightings:
    """The other robots' sightings (subjects 1-5) by ``robot`` inside its truth span: the side array of a run."""
    return parse_robot_run(_resolve_paths(folder, robot)).robots


# --- the registered builder -------------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class MrclamParams:
    """Parameters of ``mrclam``.

    Attributes
    ----------
    dataset : int
        MRCLAM dataset number, 1..9 (only 6 is in the shared data folder, and only 6 is checksum-verified).
    robot : int
        Robot (subject) number, 1..5.
    waypoint_spacing_m : float
        Distance travelled along the truth between waypoints, m.
    noise_fold : int
        The leave-one-robot-out fold whose frozen nominal noise the run is given (:data:`FOLD_NOISE`): 0, the
        default, is the robot's own fold (derived without it); 1..5 another fold, as a tuning study of fold k
        gives its train robots fold k's noise, so that nothing the study reads comes from robot k.
    """

    dataset: int = 6
    robot: int = 1
    waypoint_spacing_m: float = WAYPOINT_SPACING_M
    noise_fold: int = 0

    def __post_init__(self) -> None:
        _check_numbers(self.dataset, self.robot)
        if self.noise_fold != 0 and self.noise_fold not in FOLD_NOISE:
            raise ConfigError(
                f"noise_fold must be 0 (the robot's own fold) or one of {sorted(FOLD_NOISE)}, got {self.noise_fold!r}"
            )
        if not (math.isfinite(self.waypoint_spacing_m) and self.waypoint_spacing_m >= PATH_STEP_M):
            raise ConfigError(
                f"waypoint_spacing_m must be a distance >= {PATH_STEP_M} m (the step of the thinned path), "
                f"got {self.waypoint_spacing_m}"
            )


class MrclamDataset(RecordedDataset):
    """MRCLAM: one robot of one dataset, landmark sightings by subject, Vicon truth (module docstring)."""

    id: ClassVar[str] = "mrclam"
    Params: ClassVar[type] = MrclamParams
    # 2: the nominal noise is derived per leave-one-robot-out fold (robot r's from the other four), not pooled over all
    version: ClassVar[int] = 2
    description: ClassVar[str] = (
        "UTIAS MRCLAM (recorded): one robot of a dataset, (v, omega) odometry, camera landmark sightings, Vicon truth"
    )
    folder: ClassVar[str] = FOLDER
    reference_kind: ClassVar[str] = "motion capture"
    identity_keys: ClassVar[tuple[str, ...]] = ("dataset", "robot")

    @classmethod
    def files(cls, params: Any) -> list[RemoteFile]:
        """The five files of one robot; sha256 for Dataset 6 only; ``url`` is the zip that holds them."""
        p: MrclamParams = params
        sums = KNOWN_SHA256.get(p.dataset, {})
        sub = f"{FOLDER}/{dataset_folder_name(p.dataset)}"
        url = ZIP_URL.format(n=p.dataset)
        return [RemoteFile(f"{sub}/{name}", sums.get(name), url) for name in file_names(p.robot).values()]

    def build(self, params: MrclamParams, rng: np.random.Generator) -> Dataset:
        located = self.paths(params)
        by_name = {Path(rel).name: path for rel, path in located.items()}
        paths = {key: by_name[name] for key, name in file_names(params.robot).items()}
        run = parse_robot_run(paths)
        meta = {
            "dataset": params.dataset,
            "robot": params.robot,
            "files": {k: str(v) for k, v in paths.items()},
            "verified": params.dataset in KNOWN_SHA256,
        }
        return dataset_from_run(
            run,
            noise_fold=params.noise_fold or params.robot,
            waypoint_spacing_m=params.waypoint_spacing_m,
            metadata=meta,
            sources=[str(p) for p in paths.values()],
        )

    def fetch(self, params: Any) -> list[str]:
        """Download the official zip with pooch (unverified: its hash is unknown), unpack it into the cache and
        verify every extracted file whose sha256 is known (Dataset 6); every local path of :meth:`files`."""
        p: MrclamParams = params
        specs = self.files(p)
        try:
            return [str(locate(s)) for s in specs]
        except RecordedDataError as exc:
            if "checksum mismatch" in str(exc):
                raise
        try:
            import pooch
        except ImportError:
            raise DependencyNotInstalled(
                "downloading MRCLAM needs pooch (a dependency of locbench); install it with: pip install pooch"
            ) from None
        target = cache_root() / FOLDER / dataset_folder_name(p.dataset)
        target.mkdir(parents=True, exist_ok=True)
        members = pooch.retrieve(
            ZIP_URL.format(n=p.dataset),
            known_hash=None,
            fname=f"{dataset_folder_name(p.dataset)}.zip",
            path=cache_root() / FOLDER,
            processor=pooch.Unzip(extract_dir=f"{dataset_folder_name(p.dataset)}.unzipped"),
            progressbar=False,
        )
        return [str(_place(members, s, target)) for s in specs]


def _place(members: Sequence[str], spec: RemoteFile, target: Path) -> Path:
    """Move the extracted member named like ``spec`` into ``target`` and verify it where its sha256 is known."""
    name = spec.relpath.rsplit("/", 1)[-1]
    found = [Path(m) for m in members if Path(m).name == name]
    dest = target / name
    if not found and not dest.is_file():
        raise RecordedDataError(dest, f"missing file: the downloaded zip has no {name} (expected it in the archive)")
    if found:
        shutil.copyfile(found[0], dest)
    if spec.sha256:
        try:
            verify_sha256(dest, spec.sha256)
        except RecordedDataError:
            dest.unlink(missing_ok=True)  # nothing unverified stays where locate() would find it
            raise
    return dest


__all__: Sequence[str] = (
    "MrclamDataset",
    "MrclamParams",
    "Sightings",
    "load_mrclam",
    "nominal_sensors",
    "read_robot_sightings",
)
