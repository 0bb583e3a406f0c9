"""The TUM trajectory format (``timestamp tx ty tz qx qy qz qw``, one pose per line) for planar poses: written by
``locbench export`` and the textlog writer, read as a textlog's truth and by tools that compare with evo."""

from __future__ import annotations

import logging
import os
import tempfile
from pathlib import Path

import numpy as np
import numpy.typing as npt

from locbench.datasets.base import Trajectory2D
from locbench.datasets.recorded.files import read_table
from locbench.errors import ConfigError
from locbench.geometry import quaternion_to_yaw, yaw_to_quaternion

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

    Raises
    ------
    RecordedDataError
        Naming the line: a wrong column count, a field that is not a number, time going backwards.
    """
    table = read_table(path, TUM_COLUMNS)
    table.check_time_non_decreasing(0, "timestamp")
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
