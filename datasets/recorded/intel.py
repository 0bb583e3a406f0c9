"""The Intel Research Lab (Seattle) laser log of the Freiburg SLAM benchmark, as the dataset ``intel``.

Source and citation
-------------------
Official origin: http://ais.informatik.uni-freiburg.de/slamevaluation/datasets.php (``intel.clf``,
``intel.relations``); raw log recorded by Dirk Haehnel, distributed through Radish (A. Howard, N. Roy, "The
Robotics Data Set Repository (Radish)", 2003). The relations and the relation error: R. Kuemmerle, B. Steder,
C. Dornhege, M. Ruhnke, G. Grisetti, C. Stachniss, A. Kleiner, "On measuring the accuracy of SLAM algorithms",
Autonomous Robots 27(4):387-407, 2009. ``intel.gfs.log`` is GMapping output (G. Grisetti, C. Stachniss,
W. Burgard, "Improved techniques for grid mapping with Rao-Blackwellized particle filters", IEEE T-RO 23(1),
2007) from C. Stachniss' dataset page. Downloads used by :meth:`IntelDataset.fetch`: ``intel.clf`` from the
bzip2 blob of ``MOLAorg/mola_test_datasets`` (CC BY 3.0), the relations and the GMapping log from
``xiaofeng419/SLAM-2D-LIDAR-SCAN``, each at the commit and with the sha256 of ``shared/datasets/SOURCES.md``.

Files and format
----------------
``LOCBENCH_DATA/freiburg_slam_benchmark/``: ``intel.clf`` (the raw CARMEN log: 26915 ODOM, 13631 FLASER of
180 beams; see :mod:`locbench.datasets.recorded.carmen`), ``intel.gfs.log`` (CARMEN; 910 FLASER whose pose is
GMapping's corrected pose, times = logger seconds) and ``intel.relations`` (``t1 t2 dx dy dz droll dpitch
dyaw``: the pose at ipc time t2 in the frame of the pose at t1, m and rad; 2984 rows).

Time base, frames, units
------------------------
Every time is the raw log's ``ipc_timestamp`` (Unix s), the clock of the relations. Poses are (x m, y m,
theta rad) in the frame of the GMapping map (its first pose is near the origin). The laser sits at the robot
origin (``PARAM robot_frontlaser_offset 0.0``).

Events
------
* ``Odometry``: the increment between consecutive raw ODOM poses, ``between(prev, cur)`` in the previous robot
  frame, stamped with the later message's time. The log's ``tv`` and ``rv`` fields are all zero, so no twist
  is given.
* ``LaserScan``: each FLASER: 180 beams, first at -90 deg, 1 deg apart (the Freiburg description of this
  log). CARMEN's SICK driver writes 81.83 m when a beam has no return (2.8 % of the readings; the largest
  other reading is 26.4 m); readings at or above 81.83 m become ``inf`` and ``range_max`` is 81.83 m.
* Stamps that go backwards: 631 FLASER and 602 ODOM messages are stamped earlier than the message before them
  in the file, by up to 0.90 s. Both streams are ordered by stamp (a stable sort, so equal stamps keep file
  order) and the odometry increments are taken between consecutive poses in that order: the odometry pose
  handed to a filter at time t is then the logged pose with the latest stamp <= t, and every scan is used at
  the time the relations give it. A step back of more than 1 s is still an error.

Reference trajectory (a SLAM reference, not ground truth)
---------------------------------------------------------
The 910 corrected FLASER poses of ``intel.gfs.log``, each matched to the ``intel.clf`` FLASER whose
``logger_timestamp`` is nearest (every match within 5 ms, one to one), stamped with that scan's
``ipc_timestamp`` and ordered by it; ``truth_label = "SLAM reference"``. Events are trimmed to its time span
(32.9 s to 2683.8 s of the log). The initial belief is the first reference pose with standard deviations
0.1 m and 0.05 rad (:data:`~locbench.datasets.recorded.reference.SLAM_INITIAL_SIGMA`: the reference is itself an
estimate, and this is of the order of its own error; the value is not tuned on any filter result).

Primary metric: the relations of Kuemmerle et al. (``Dataset.relations``): every relation time is checked to
be the ``ipc_timestamp`` of a FLASER of ``intel.clf`` (all 2984 are; all lie inside the reference span).

Map
---
An occupancy grid built from the reference's 910 corrected scans by log-odds ray casting
(:func:`~locbench.datasets.recorded.scan_map.build_occupancy_grid`; readings at or above :data:`NO_RETURN_M` add
nothing). Default cell 0.05 m. Built once per (file, size, mtime, resolution). The grid's size is computed from the
scans' extent before anything is allocated and refused above ``max_grid_cells``
(:data:`~locbench.datasets.recorded.files.MAX_GRID_CELLS`, 4096 x 4096 cells, by default); ``map_resolution_m``
lies in [:data:`~locbench.datasets.recorded.scan_map.MIN_RESOLUTION_M`,
:data:`~locbench.datasets.recorded.scan_map.MAX_RESOLUTION_M`].

Validation beyond the CARMEN parser's: each of ``intel.clf`` and ``intel.gfs.log`` must hold FLASER messages of
180 beams (the message names the file that does not); ``intel.clf`` needs ODOM messages at more than one time and
inside the reference's span; ``PARAM robot_frontlaser_offset`` must be a number within 10 m.

Plausibility (:func:`~locbench.datasets.recorded.carmen.read_carmen_flagged` on the ODOM and FLASER messages of
``intel.clf`` and the FLASER messages of ``intel.gfs.log``, with :data:`BOUNDS`: the policy's, the range bound
tightened to the SICK's no-return reading :data:`NO_RETURN_M` and the heading bound to 2 pi, CARMEN's headings being
wrapped): a flagged message is left out and listed in ``Dataset.flagged``: a flagged ODOM gives no pose (the
increment spans from the pose before it to the one after), a flagged raw FLASER no scan, a flagged reference scan
no reference pose and no part in the map; the odometry noise is derived from the reference scans whose reference
and raw scan are both kept. The pose track is judged over the time between stamps plus
:data:`~locbench.datasets.recorded.carmen.FREIBURG_MAX_BACKSTEP_S` (1 s): the
stamps are the IPC delivery times, which come in bursts (half the consecutive ODOM stamps lie less than 1 ms apart
while the pose moved 3 cm, then none for up to 3.5 s): on the stamps alone the bound flags 323 ODOM and 2348 FLASER
poses of the shared log, with 0.1 s of slack still 10 and 4; with 1 s the speed bound catches a jump of more than
5 m, and the turn-rate bound no turn (1 s at 10 rad/s exceeds pi). The shared files flag nothing. Relation times
are checked against every FLASER of the log, flagged or not (a relation is the benchmark's, not the scan's).

Map lines (for ``ekf_lines``): the greedy Hough extraction of
:func:`~locbench.datasets.recorded.scan_map.extract_map_lines` on the grid; its counts are stored in
``metadata["map"]``.

Nominal noise (``SensorSpec``)
------------------------------
No official values exist. ``laser_sigma_m`` = 0.05 m: GMapping's default ``sigma`` (the endpoint-matching
standard deviation, ROS ``gmapping`` parameter ``~sigma``;
:data:`~locbench.datasets.recorded.reference.GMAPPING_SIGMA_M`), the model with which the reference itself was
computed. The odometry noise is derived from the reference, never from filter results:
:func:`~locbench.datasets.recorded.reference.derive_odometry_noise` of the raw log's FLASER odometry fields against
the reference poses at the consecutive reference scans (the method-of-moments fit of the increment model; an upper
bound on the odometry noise, since the reference's own error enters it).
"""

from __future__ import annotations

import functools
import logging
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from locbench.core.errors import ConfigError
from locbench.core.events import Event, LaserScan, Odometry
from locbench.core.geometry import between, wrap_angle
from locbench.core.spec import bound
from locbench.datasets.dataset import (
    Dataset,
    Gaussian2,
    LineMap,
    OccupancyGrid,
    Relations,
    SensorSpec,
    Trajectory2D,
    WorldMap,
    sort_events,
)
from locbench.datasets.recorded import plausibility
from locbench.datasets.recorded.carmen import FREIBURG_MAX_BACKSTEP_S, CarmenFlags, CarmenLog, read_carmen_flagged
from locbench.datasets.recorded.common import RecordedDataset
from locbench.datasets.recorded.files import (
    MAX_GRID_CELLS,
    MAX_GRID_CELLS_BOUND,
    RecordedDataError,
    RemoteFile,
    locate,
    quote,
    read_table,
)
from locbench.datasets.recorded.reference import GMAPPING_SIGMA_M, SLAM_INITIAL_SIGMA, derive_odometry_noise
from locbench.datasets.recorded.scan_map import (
    MAX_RESOLUTION_M,
    MIN_RESOLUTION_M,
    build_occupancy_grid,
    extract_map_lines,
)

FloatArray = npt.NDArray[np.float64]
logger = logging.getLogger(__name__)

FOLDER = "freiburg_slam_benchmark"
_MOLA = "https://github.com/MOLAorg/mola_test_datasets/raw/13a2ed141116bc654e14ffca1d88fb740b3d1253/datasets/radish"
_XF = "https://raw.githubusercontent.com/xiaofeng419/SLAM-2D-LIDAR-SCAN/d469252f5b33e574bd239ad2625779497ac1d4cc/DataSet/RawData"

CLF = RemoteFile(
    f"{FOLDER}/intel.clf",
    sha256="8db0ad6231b48bad4118e6a2dc78e83213b2c306be3b4ed80a90969891abfe7b",
    url=f"{_MOLA}/intel.clf.bz2",
    download_sha256="d9ce4addefc9405d5e78fd883d2214766552537d262009f8e6f0137885f9f72a",
    decompress="bz2",
)
GFS = RemoteFile(
    f"{FOLDER}/intel.gfs.log",
    sha256="b066a0e3c62e69901540895017871835169d13c56a4cbb78f42599cf3563484f",
    url=f"{_XF}/intel.gfs.log",
)
RELATIONS = RemoteFile(
    f"{FOLDER}/intel.relations",
    sha256="330378f153eeae652d6756c1746f335801f66c3e097d90611548e6c4f593c359",
    url=f"{_XF}/intel.relations",
)

#: CARMEN's no-return reading of this log's SICK laser, m.
NO_RETURN_M = 81.83
#: Beam geometry of the Intel FLASER messages: 180 beams, first at -90 deg, 1 deg apart.
ANGLE_MIN_RAD = -math.pi / 2
ANGLE_INCREMENT_RAD = math.pi / 180
#: The plausibility bounds tightened with the scanner's limit (no reading beyond its no-return value) and CARMEN's
#: wrapped headings.
BOUNDS = plausibility.BOUNDS.tightened(range_m=NO_RETURN_M, heading_abs_rad=2 * math.pi)
#: Largest |logger time difference| between a reference scan and its raw scan, s (SOURCES.md).
MATCH_TOLERANCE_S = 0.005


@dataclass(frozen=True, kw_only=True)
class IntelParams:
    """Parameters of ``intel``.

    Attributes
    ----------
    root : str
        Folder that holds ``freiburg_slam_benchmark/`` (empty: ``$LOCBENCH_DATA``, then the download cache).
    map_resolution_m : float
        Cell side of the occupancy grid built from the reference, m, in [MIN_RESOLUTION_M, MAX_RESOLUTION_M].
    max_grid_cells : int
        Largest occupancy grid built, cells (:data:`~locbench.datasets.recorded.files.MAX_GRID_CELLS` by default;
        the Intel map at 0.05 m is about 0.3 M cells); raise it for a finer grid.
    """

    root: str = ""
    map_resolution_m: float = 0.05
    max_grid_cells: int = field(default=MAX_GRID_CELLS, metadata=bound(1, MAX_GRID_CELLS_BOUND, what="a cell count"))

    def __post_init__(self) -> None:
        if not MIN_RESOLUTION_M <= self.map_resolution_m <= MAX_RESOLUTION_M:
            raise ConfigError(
                f"parameter 'map_resolution_m' must be a cell side in [{MIN_RESOLUTION_M}, {MAX_RESOLUTION_M}] m, "
                f"got {self.map_resolution_m!r}"
            )
        if self.max_grid_cells < 1:
            raise ConfigError(f"parameter 'max_grid_cells' must be >= 1, got {self.max_grid_cells!r}")


# --- reference, relations, noise ---------------------------------------------------------------------------


def match_reference(clf: CarmenLog, gfs: CarmenLog) -> npt.NDArray[np.int64]:
    """Index into ``clf.flaser`` of each FLASER of ``gfs``, matched by nearest ``logger_timestamp``.

    Raises
    ------
    RecordedDataError
        A reference scan has no raw scan within 5 ms, or two reference scans match the same raw scan.
    """
    lg = clf.flaser.logger_t
    order = np.argsort(lg, kind="stable")
    s = lg[order]
    q = gfs.flaser.logger_t
    if s.size == 0:
        raise RecordedDataError(clf.path, "no FLASER messages (expected the raw scans of the reference)")
    j = np.clip(np.searchsorted(s, q), 1, max(s.size - 1, 1))
    left = np.clip(j - 1, 0, s.size - 1)
    right = np.clip(j, 0, s.size - 1)
    pick = np.where(np.abs(s[right] - q) < np.abs(s[left] - q), right, left)
    err = np.abs(s[pick] - q)
    bad = np.flatnonzero(err > MATCH_TOLERANCE_S)
    if bad.size:
        k = int(bad[0])
        raise RecordedDataError(
            gfs.path,
            f"FLASER logger_timestamp {q[k]:.6f} has no FLASER in {clf.path.name} within "
            f"{MATCH_TOLERANCE_S * 1e3:g} ms (nearest is {err[k] * 1e3:.1f} ms away)",
            int(gfs.flaser.lines[k]),
        )
    idx = order[pick]
    uniq, first = np.unique(idx, return_index=True)
    if uniq.size != idx.size:
        dup = np.setdiff1d(np.arange(idx.size), first)[0]
        raise RecordedDataError(
            gfs.path, "FLASER matches a raw scan already matched by another reference scan", int(gfs.flaser.lines[dup])
        )
    return idx.astype(np.int64)


#: Largest relative displacement of a relation, m (the Intel lab is about 30 m across; its relations are at most 2.1 m,
#: the Freiburg benchmark's other buildings' at most 4.4 m).
MAX_RELATION_M = 100.0


def read_relations(path: str | os.PathLike[str], scan_times: npt.ArrayLike) -> Relations:
    """Read a ``.relations`` file and check every time against the raw log's FLASER ``ipc_timestamp``.

    Parameters
    ----------
    path : path-like
        ``t1 t2 dx dy dz droll dpitch dyaw`` per line (s, m, rad).
    scan_times : array-like
        The FLASER ``ipc_timestamp`` values of the raw log, s.

    Raises
    ------
    RecordedDataError
        A malformed line, no relation at all, a displacement beyond :data:`MAX_RELATION_M` or a turn beyond
        +-2 pi, t1 = t2, a (t1, t2) pair given twice, or a time that is no FLASER time (naming the line). A
        relation with t2 < t1 is valid (the pose at t2 seen from the pose at t1; the benchmark's own file has 6).
    """
    cols = ("t1 s", "t2 s", "dx m", "dy m", "dz m", "droll rad", "dpitch rad", "dyaw rad")
    tab = read_table(path, cols)
    if tab.rows.shape[0] == 0:
        raise RecordedDataError(path, "no relation, expected at least one 't1 t2 dx dy dz droll dpitch dyaw' line")
    for c in (2, 3, 4):
        tab.check_range(c, cols[c], -MAX_RELATION_M, MAX_RELATION_M)
    tab.check_range(7, cols[7], -2 * math.pi, 2 * math.pi)
    same = np.flatnonzero(tab.column(0) == tab.column(1))
    if same.size:
        raise tab.fail(int(same[0]), "t1 equals t2, expected a relation between two different scans")
    # a repeated (t1, t2) pair would weigh that relation twice in the relation error
    order = np.lexsort((tab.column(1), tab.column(0)))
    pairs = tab.rows[order][:, :2]
    dup = np.flatnonzero(np.all(pairs[1:] == pairs[:-1], axis=1))
    if dup.size:
        r = int(order[dup[0] + 1])
        first = int(tab.lines[order[dup[0]]])
        raise tab.fail(r, f"the pair (t1, t2) repeats the relation on line {first}, expected each pair once")
    known = np.unique(np.asarray(scan_times, dtype=np.float64))
    for c, name in ((0, "t1"), (1, "t2")):
        t = tab.column(c)
        pos = np.clip(np.searchsorted(known, t), 0, max(known.size - 1, 0))
        miss = np.flatnonzero(known[pos] != t) if known.size else np.arange(t.size)
        if miss.size:
            r = int(miss[0])
            raise tab.fail(r, f"{name} = {t[r]:.6f} is not the ipc_timestamp of any FLASER of the log (expected one)")
    delta = np.column_stack([tab.column(2), tab.column(3), wrap_angle(tab.column(7))])
    return Relations(tab.column(0).copy(), tab.column(1).copy(), delta)


@functools.lru_cache(maxsize=4)
def _reference_map(
    gfs_path: str, size: int, mtime_ns: int, resolution_m: float, max_cells: int
) -> tuple[OccupancyGrid, LineMap, dict]:
    gfs, flags = _read_reference(Path(gfs_path))
    beams = gfs.flaser.ranges.shape[1]
    angles = ANGLE_MIN_RAD + ANGLE_INCREMENT_RAD * np.arange(beams)
    kept = flags.flaser_kept  # a flagged reference scan has no part in the map
    grid = build_occupancy_grid(
        gfs.flaser.pose[kept],
        gfs.flaser.ranges[kept],
        angles,
        resolution_m,
        max_range_m=NO_RETURN_M,
        max_cells=max_cells,
        source=gfs_path,
    )
    grid.occupancy.setflags(write=False)
    lines, stats = extract_map_lines(grid)
    lines.segments.setflags(write=False)
    stats = {**stats, "resolution_m": resolution_m, "rows": float(grid.shape[0]), "cols": float(grid.shape[1])}
    return grid, lines, stats


def _read_raw(path: Path) -> tuple[CarmenLog, CarmenFlags]:
    """The raw log and its flagged messages (module docstring)."""
    return read_carmen_flagged(path, max_backstep_s=FREIBURG_MAX_BACKSTEP_S, bounds=BOUNDS)


def _read_reference(path: Path) -> tuple[CarmenLog, CarmenFlags]:
    """The GMapping log and its flagged FLASER messages (its ODOM lines are stamped 0: not read)."""
    return read_carmen_flagged(path, max_backstep_s=FREIBURG_MAX_BACKSTEP_S, time_checked=("FLASER",), bounds=BOUNDS)


def reference_map(
    gfs_path: str | os.PathLike[str], resolution_m: float = 0.05, max_cells: int = MAX_GRID_CELLS
) -> tuple[OccupancyGrid, LineMap, dict]:
    """The occupancy grid and map lines built from a corrected CARMEN log (cached per file and resolution);
    a grid above ``max_cells`` cells is refused before it is allocated; flagged scans are left out."""
    p = Path(gfs_path)
    st = p.stat()
    return _reference_map(str(p.resolve()), st.st_size, st.st_mtime_ns, float(resolution_m), int(max_cells))


# --- the dataset -----------------------------------------------------------------------------------------


def load_intel(
    folder: str | os.PathLike[str] | None = None,
    *,
    map_resolution_m: float = 0.05,
    verify: bool = True,
    max_grid_cells: int = MAX_GRID_CELLS,
) -> Dataset:
    """The Intel Research Lab dataset from a folder holding ``freiburg_slam_benchmark/`` (see the module docstring).

    Parameters
    ----------
    folder : path-like or None
        The data root (the folder that contains ``freiburg_slam_benchmark/``); None: ``$LOCBENCH_DATA``, then
        the download cache.
    map_resolution_m : float
        Cell side of the occupancy grid, m.
    verify : bool
        Check each file's sha256 against the published one (a copy that differs raises a checksum mismatch).
    max_grid_cells : int
        Largest occupancy grid built, cells.

    Raises
    ------
    RecordedDataError
        A missing, corrupt or malformed file (naming the file, the line and what was expected).
    """
    root = None if folder is None or str(folder) == "" else folder
    clf_path = locate(CLF, root, verify=verify)
    gfs_path = locate(GFS, root, verify=verify)
    rel_path = locate(RELATIONS, root, verify=verify)
    return _assemble(clf_path, gfs_path, rel_path, map_resolution_m, max_grid_cells)


def _assemble(
    clf_path: Path, gfs_path: Path, rel_path: Path, map_resolution_m: float, max_grid_cells: int = MAX_GRID_CELLS
) -> Dataset:
    # long: the checks of the three files and their cross-checks, in the order the errors should be reported
    clf, clf_flags = _read_raw(clf_path)
    gfs, gfs_flags = _read_reference(gfs_path)
    for path, log in ((clf_path, clf), (gfs_path, gfs)):
        if len(log.flaser) == 0:
            raise RecordedDataError(path, "no FLASER message, expected 180-beam laser scans (Intel)")
        if log.flaser.ranges.shape[1] != 180:
            raise RecordedDataError(path, f"FLASER has {log.flaser.ranges.shape[1]} ranges, expected 180 (Intel)")
    if int(gfs_flags.flaser_kept.sum()) < 2:
        raise RecordedDataError(gfs_path, "fewer than 2 FLASER messages (expected the 910 corrected scans)")
    if int(clf_flags.odom_kept.sum()) < 2:  # every ODOM stamped alike is refused by the reader
        raise RecordedDataError(clf_path, f"{len(clf.odom)} ODOM message(s), expected odometry at increasing times")
    match = match_reference(clf, gfs)
    # a flagged reference scan gives no reference pose
    ref_kept = gfs_flags.flaser_kept
    ref_t_unsorted = clf.flaser.ipc_t[match][ref_kept]
    order = np.argsort(ref_t_unsorted, kind="stable")
    ref_t = ref_t_unsorted[order]
    ref_pose = np.asarray(gfs.flaser.pose)[ref_kept][order]
    ref_pose = np.column_stack([ref_pose[:, :2], wrap_angle(ref_pose[:, 2])])
    t0, t1 = float(ref_t[0]), float(ref_t[-1])

    events: list[Event] = []
    od = clf.odom
    o_order = np.argsort(od.ipc_t, kind="stable")
    o_order = o_order[clf_flags.odom_kept[o_order]]  # a flagged pose is skipped: the increment spans it
    ot = od.ipc_t[o_order]
    op = od.pose[o_order]
    inc = between(op[:-1], op[1:])
    for k in np.flatnonzero((ot[1:] >= t0) & (ot[1:] <= t1)):
        events.append(Odometry(float(ot[k + 1]), float(inc[k, 0]), float(inc[k, 1]), float(inc[k, 2])))
    if not events:
        raise RecordedDataError(
            clf_path,
            f"no ODOM message inside the reference span [{t0!r}, {t1!r}] s (ODOM spans {float(ot[0])!r} .. "
            f"{float(ot[-1])!r} s), expected odometry during the reference",
        )
    las = clf.flaser
    offset = _laser_offset(clf_path, clf.params.get("robot_frontlaser_offset", "0.0"))
    ranges = np.where(las.ranges >= NO_RETURN_M, np.inf, las.ranges)
    for k in np.flatnonzero((las.ipc_t >= t0) & (las.ipc_t <= t1) & clf_flags.flaser_kept):
        events.append(
            LaserScan(
                float(las.ipc_t[k]),
                ANGLE_MIN_RAD,
                ANGLE_INCREMENT_RAD,
                ranges[k].copy(),
                0.0,
                NO_RETURN_M,
                (offset, 0.0, 0.0),
            )
        )

    grid, lines, map_stats = reference_map(gfs_path, map_resolution_m, max_grid_cells)
    relations = read_relations(rel_path, las.ipc_t)
    # the noise pairs: reference scans whose raw scan (its odometry pose) is kept as well
    raw_kept = clf_flags.flaser_kept[match][ref_kept][order]
    odo_at_ref = np.asarray(las.odom_pose)[match][ref_kept][order][raw_kept]
    sxy, stm, str_ = derive_odometry_noise(odo_at_ref, ref_pose[raw_kept])
    sensors = SensorSpec(
        laser_sigma_m=GMAPPING_SIGMA_M,
        odometry_sigma_xy_per_m=sxy,
        odometry_sigma_theta_per_m=stm,
        odometry_sigma_theta_per_rad=str_,
    )
    initial = Gaussian2(ref_pose[0].copy(), np.diag(np.square(SLAM_INITIAL_SIGMA)))
    truth = Trajectory2D(ref_t, ref_pose[:, :2].copy(), ref_pose[:, 2].copy())
    backsteps = {
        "ODOM": int(np.sum(np.diff(od.ipc_t) < 0)),
        "FLASER": int(np.sum(np.diff(las.ipc_t) < 0)),
    }
    metadata: dict[str, Any] = {
        "source": "Freiburg SLAM benchmark, Intel Research Lab (Kuemmerle et al. 2009; Radish)",
        "files": [str(clf_path), str(gfs_path), str(rel_path)],
        "odom_messages": len(od),
        "flaser_messages": len(las),
        "skipped_messages": dict(clf.skipped),
        "stamps_back_in_file_order": backsteps,
        "reference_scans": len(gfs.flaser),
        "relations": len(relations),
        "map": map_stats,
        "odometry_noise_derived": {
            "sigma_xy_per_m": sxy,
            "sigma_theta_per_m": stm,
            "sigma_theta_per_rad": str_,
            "pairs": int(raw_kept.sum()) - 1,
        },
    }
    return Dataset(
        id="intel",
        params={"map_resolution_m": map_resolution_m},
        events=sort_events(events),
        ground_truth=truth,
        initial=initial,
        world=WorldMap(occupancy=grid, lines=lines),
        sensors=sensors,
        metadata=metadata,
        relations=relations,
        truth_label="SLAM reference",
        sources=(str(clf_path), str(gfs_path), str(rel_path)),
        declared=frozenset({LaserScan}),
        flagged=plausibility.merge(clf_flags.flagged, gfs_flags.flagged),
    )


def _laser_offset(path: Path, text: str) -> float:
    """The ``PARAM robot_frontlaser_offset`` value, m: a finite number within 10 m of the robot centre."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and abs(value) <= 10.0):
        raise RecordedDataError(
            path, f"PARAM robot_frontlaser_offset is {quote(text)}, expected the laser's offset in m (within 10 m)"
        )
    return value


class IntelDataset(RecordedDataset):
    """Intel Research Lab (Freiburg SLAM benchmark): raw CARMEN log, GMapping reference, Kuemmerle relations."""

    id: ClassVar[str] = "intel"
    Params: ClassVar[type] = IntelParams
    version: ClassVar[int] = 1
    description: ClassVar[str] = (
        "Intel Research Lab (recorded CARMEN log): odometry, 180-beam laser, grid and lines from the GMapping "
        "reference, Kuemmerle relations"
    )
    folder: ClassVar[str] = FOLDER
    reference_kind: ClassVar[str] = "SLAM"

    @classmethod
    def files(cls, params: Any) -> list[RemoteFile]:
        """``intel.clf``, ``intel.gfs.log`` and ``intel.relations`` with their checksums and downloads."""
        return [CLF, GFS, RELATIONS]

    def paths(self, params: Any) -> dict[str, Path]:
        """Verified local paths, looking in ``params.root`` first when it is set."""
        root = params.root or None
        return {spec.relpath: locate(spec, root) for spec in self.files(params)}

    def build(self, params: IntelParams, rng: np.random.Generator) -> Dataset:
        """The dataset (the recording does not depend on ``rng``)."""
        p = self.paths(params)
        return _assemble(
            p[CLF.relpath], p[GFS.relpath], p[RELATIONS.relpath], params.map_resolution_m, params.max_grid_cells
        )
