"""The plain-text tables of the ``locbench-textlog`` format: landmarks, map lines, waypoints and relations.

Read by the textlog loader (:mod:`~locbench.datasets.recorded.textlog`; docs/datasets.md section 8) and by the bag
loader for its ``landmarks`` and ``waypoints`` sidecars (:mod:`~locbench.datasets.recorded.rosbag`);
:func:`table_text` writes a table as they read it back. One record a line, fields separated by blanks or commas,
``#`` comment lines allowed (:func:`~locbench.datasets.recorded.files.read_table`); each file is a regular file of
at most :data:`MAX_TABLE_FILE_BYTES` (:func:`~locbench.core.limits.check_input_file`), and every error is one line
naming the file, the line and what was expected (:class:`~locbench.datasets.recorded.files.RecordedDataError`).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import numpy.typing as npt

from locbench.core.limits import check_input_file
from locbench.datasets.dataset import Landmarks, LineMap, Relations, Trajectory2D, Waypoints
from locbench.datasets.recorded.files import MAX_INTEGER_FIELD, MAX_POSITION_M, read_table

#: Largest table file (truth, landmarks, lines, waypoints, relations), bytes.
MAX_TABLE_FILE_BYTES = 256 << 20


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
    table.check_range(4, cols[4], -math.tau, math.tau)
    r = table.rows
    return Relations(r[:, 0].copy(), r[:, 1].copy(), r[:, 2:5].copy())


def table_text(header: str, rows: npt.ArrayLike, ints: int = 0) -> str:
    """Space-separated rows (the first ``ints`` columns as integers, the rest as repr floats) under a # header."""
    out = [f"# {header}"]
    for r in np.asarray(rows, dtype=np.float64):
        out.append(" ".join([str(int(v)) for v in r[:ints]] + [repr(float(v)) for v in r[ints:]]))
    return "\n".join(out) + "\n"
