"""The TUM trajectory format (``timestamp tx ty tz qx qy qz qw``, one pose per line) for planar poses: written by
``locbench export`` and the textlog writer, read as a textlog's truth and by tools that compare with evo.

Reading (the plausibility policy of :mod:`~locbench.datasets.recorded.plausibility`): :func:`read_tum` reads any
trajectory, a filter's estimate included, and refuses only what makes the file no trajectory (a bad line, time
going backwards, two or more poses all at one time); it bounds no motion, since a filter's jump is a result to
compare, not a glitch of a recording. :func:`read_tum_flagged` reads a trajectory that is a recording (a reference
from another tool) and, besides those refusals and a quaternion that is no planar unit rotation or a position beyond
:data:`~locbench.datasets.recorded.files.MAX_POSITION_M`, flags a pose repeating the previous line, a second pose
at the previous pose's time, and a pose the robot could not have reached from the last accepted one (the policy's
speed and turn-rate bounds plus their jitter); a file with more than 1 % of them, or a 2 s stretch, is refused.
"""

from __future__ import annotations

import logging
import os
import tempfile
from pathlib import Path

import numpy as np
import numpy.typing as npt

from locbench.core.errors import ConfigError
from locbench.core.geometry import quaternion_to_yaw, yaw_to_quaternion
from locbench.datasets.dataset import FlaggedSample, Trajectory2D
from locbench.datasets.recorded import plausibility
from locbench.datasets.recorded.files import MAX_POSITION_M, Table, quaternion_problem, read_table

log = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]

TUM_COLUMNS = ("timestamp [s]", "tx [m]", "ty [m]", "tz [m]", "qx", "qy", "qz", "qw")
TUM_HEADER = "# timestamp tx ty tz qx qy qz qw"


def _last_per_time(t: FloatArray, rows: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Keep, for each distinct time of a non-decreasing ``t``, the last row."""
    keep = np.ones(t.shape[0], dtype=bool)
    keep[:-1] = t[1:] != t[:-1]
    return t[keep], rows[keep]


def _fmt(v: float) -> str:
    return repr(float(v))  # the shortest string that reads back as the same float64


def write_tum(
    path: str | os.PathLike[str],
    t: npt.ArrayLike,
    poses: npt.ArrayLike,
    comment: str | None = None,
    *,
    keep_all: bool = False,
) -> Path:
    """Write planar poses as a TUM trajectory file (atomically).

    Parameters
    ----------
    path : path-like
        The file to write; its folder is created.
    t : array-like, shape (n,)
        Times, s, non-decreasing; rows sharing a time collapse to the last.
    poses : array-like, shape (n, 3)
        World-frame poses (x m, y m, theta rad); rows with a non-finite value are left out (logged).
    comment : str or None
        Text of a second ``#`` line (provenance).
    keep_all : bool
        Write every row, repeated times included, and refuse a non-finite one (a dataset's truth, which must
        read back row for row; evo wants the default).

    Returns
    -------
    Path
        The file.

    Raises
    ------
    ConfigError
        Shapes that do not match, times going backwards, or no finite pose at all.
    """
    tt = np.asarray(t, dtype=np.float64)
    pp = np.asarray(poses, dtype=np.float64)
    if tt.ndim != 1 or pp.shape != (tt.shape[0], 3):
        raise ConfigError(f"{path}: expected times (n,) and poses (n, 3), got {tt.shape} and {pp.shape}")
    finite = np.isfinite(tt) & np.all(np.isfinite(pp), axis=1)
    if keep_all and not np.all(finite):
        raise ConfigError(f"{path}: row {int(np.flatnonzero(~finite)[0])} is not finite, expected finite poses")
    if not np.all(finite):
        log.warning("%s: leaving out %d non-finite pose rows of %d", path, int(np.sum(~finite)), tt.shape[0])
        tt, pp = tt[finite], pp[finite]
    if tt.shape[0] == 0:
        raise ConfigError(f"{path}: no finite pose to write")
    back = np.flatnonzero(np.diff(tt) < 0)
    if back.size:
        k = int(back[0]) + 1
        raise ConfigError(f"{path}: time goes backwards at row {k}: {float(tt[k])!r} s after {float(tt[k - 1])!r} s")
    if not keep_all:
        tt, pp = _last_per_time(tt, pp)
    q = yaw_to_quaternion(pp[:, 2])
    lines = [TUM_HEADER]
    if comment:
        lines.append("# " + " ".join(comment.split()))
    for k in range(tt.shape[0]):
        x, y = pp[k, 0], pp[k, 1]
        lines.append(" ".join(_fmt(v) for v in (tt[k], x, y, 0.0, q[k, 0], q[k, 1], q[k, 2], q[k, 3])))
    out = Path(path)
    atomic_write_text(out, "\n".join(lines) + "\n")
    return out


def read_tum(path: str | os.PathLike[str]) -> Trajectory2D:
    """Read a TUM trajectory file as planar poses (the yaw of each quaternion; z and roll/pitch are dropped).

    Every pose is kept: an estimate's jump is what a comparison measures (:func:`read_tum_flagged` for a recording).

    Raises
    ------
    RecordedDataError
        Naming the line: a wrong column count, a field that is not a number, time going backwards, two or more
        poses all at one time.
    """
    return _trajectory(_table(path))


def read_tum_flagged(
    path: str | os.PathLike[str], bounds: plausibility.Bounds = plausibility.BOUNDS
) -> tuple[Trajectory2D, tuple[FlaggedSample, ...]]:
    """Read a TUM file that is a recorded trajectory: the poses without the implausible ones, and those.

    Parameters
    ----------
    path : path-like
        The file.
    bounds : Bounds
        The policy's bounds, or a platform's tightened ones.

    Returns
    -------
    trajectory : Trajectory2D
        The accepted poses (x m, y m, theta rad).
    flagged : tuple of FlaggedSample
        The poses left out (the module docstring lists why), in time order.

    Raises
    ------
    RecordedDataError
        As :func:`read_tum`; a position beyond ``MAX_POSITION_M``, a quaternion that is no planar unit rotation;
        more than 1 % of the poses flagged, or a 2 s stretch of them.
    """
    table = _table(path)
    for c in (1, 2, 3):
        table.check_range(c, TUM_COLUMNS[c], -MAX_POSITION_M, MAX_POSITION_M)
    problem = quaternion_problem(table.rows[:, 4:8])
    if problem is not None:
        raise table.fail(problem[0], problem[1])
    traj = _trajectory(table)
    flags = plausibility.Flags(table.path, "trajectory", traj.t, table.lines)
    flags.flag_duplicates(table.rows)
    again = np.r_[False, (traj.t[1:] == traj.t[:-1]) & ~flags.mask[1:]]
    flags.flag(again, "time of the previous pose, s", traj.t, "one pose per time")
    flags.flag_track(traj.xy, traj.theta, bounds)
    kept = flags.kept
    return Trajectory2D(traj.t[kept], traj.xy[kept], traj.theta[kept]), flags.finish()


def _table(path: str | os.PathLike[str]) -> Table:
    """The file's rows, after refusing time going backwards or standing still throughout."""
    table = read_table(path, TUM_COLUMNS)
    table.check_time_non_decreasing(0, "timestamp")
    if table.rows.shape[0] > 1:
        plausibility.refuse_all_times_equal(table.path, "pose", table.rows[:, 0], int(table.lines[1]))
    return table


def _trajectory(table: Table) -> Trajectory2D:
    rows = table.rows
    return Trajectory2D(rows[:, 0].copy(), rows[:, 1:3].copy(), quaternion_to_yaw(rows[:, 4:8]))


def atomic_write_text(path: Path, text: str) -> None:
    """Write through a temporary file in the same folder, then rename over ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=path.suffix, dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:  # names may be non-ASCII
            fh.write(text)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
