"""Memory bounds of the filters and the synthetic builders, checked before they allocate.

Each filter and builder estimates the bytes its config and its map need (the tables it builds from the grid's
cells, the particle set, the scans of a simulated laser) with the per-item costs below and refuses an estimate above
:data:`MAX_TABLE_BYTES` with a :class:`~locbench.core.errors.ResourceLimit` (a
:class:`~locbench.core.errors.ConfigError`)
naming the parameter: at spec parsing when the config alone decides it (``pf[particles=...]``, a builder's
``laser_beams``), else when the filter is reset on the map or the builder has planned its scans. The runner records
such a run as failed (status ``error``) with that one-line message, like any other config error.

The per-item costs are peak resident bytes measured once (``resource.getrusage`` of a fresh process, after a warm-up on
a small input; logs in ``docs/history/performance.md``) and rounded up; they are an upper bound of what a run allocates
per item, not an exact account. With the loaders' own bounds (:mod:`locbench.datasets.recorded.files`) this keeps any
run, whatever its input, within about 1 GB: a process of about 200 MB (numpy, scipy, numba), a grid of at most 2^24
cells (134 MB) and tables of at most :data:`MAX_TABLE_BYTES`.

:func:`check_input_file` bounds the files a user names (a suite file, a bag and its map YAML): looked at with
``os.stat`` before anything opens them, so a FIFO (which would block the open), a device (which never ends) or an
oversize file is refused with one line instead of hanging or filling the memory.
"""

from __future__ import annotations

import math
import os
import stat
from pathlib import Path

from locbench.core.errors import ConfigError, ResourceLimit

#: Largest estimated allocation of one filter's tables or one builder's arrays, bytes (384 MiB).
MAX_TABLE_BYTES = 384 << 20
#: Ray-cast tables of ``ekf_icp`` (the march fields and their construction), bytes per grid cell (measured 202-219).
RAYCAST_BYTES_PER_CELL = 256
#: Likelihood field of ``pf[use_laser=true]`` (distance transform, clipped distances, log-likelihood table), bytes
#: per grid cell (measured 43).
LIKELIHOOD_FIELD_BYTES_PER_CELL = 48
#: Free-cell index of ``pf``'s uniform draws (init=uniform, augmented), bytes per grid cell (int64 index + mask).
FREE_SPACE_BYTES_PER_CELL = 16
#: Scan database of ``kf_linear`` on its map (distance transform, labels, masks), bytes per grid cell.
SCAN_DATABASE_BYTES_PER_CELL = 64
#: One recorded range of ``kf_linear``'s scan database (the range and the ray caster's scratch), bytes.
DATABASE_BYTES_PER_RAY = 24
#: One particle of ``pf`` with its weights, copies while resampling and per-update scratch, bytes (measured 98-121).
PARTICLE_BYTES = 160
#: One simulated laser range (true range, noise draws, noisy copy, the event's array), bytes (measured 40-173).
SCAN_SAMPLE_BYTES = 192
#: Most beams per scan a builder simulates or ``pf`` scores (2-D scanners give a few thousand).
MAX_LASER_BEAMS = 10_000


def _size(nbytes: float) -> str:
    if not math.isfinite(nbytes):
        return "an unbounded amount"
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if nbytes >= scale:
            return f"about {nbytes / scale:.3g} {unit}"
    return f"{nbytes:.0f} bytes"


def check_bytes(who: str, what: str, nbytes: float, fix: str, limit: int = MAX_TABLE_BYTES) -> None:
    """Refuse an estimate of ``nbytes`` above ``limit`` before allocating it.

    Parameters
    ----------
    who : str
        The filter or dataset (``"ekf_icp"``, ``"room"``); empty in a config check (the spec parser adds it).
    what : str
        What would be allocated and from what (``"ray-cast tables of a 4096 x 4096 grid"``).
    nbytes : float
        The estimate, bytes.
    fix : str
        Which parameter or input to change (``"lower 'particles'"``).

    Raises
    ------
    ResourceLimit
        One line naming ``who``, ``what``, the estimate, the limit and ``fix``.
    """
    if not nbytes <= limit:  # also NaN
        raise ResourceLimit(
            f"{who + ': ' if who else ''}{what} would take {_size(nbytes)}, expected at most {limit >> 20} MiB "
            f"(locbench.core.limits.MAX_TABLE_BYTES); {fix}"
        )


def check_beams(name: str, beams: int) -> None:
    """Refuse more than :data:`MAX_LASER_BEAMS` beams per scan in parameter ``name`` (the spec parser prefixes the
    filter or dataset)."""
    if beams > MAX_LASER_BEAMS:
        raise ResourceLimit(
            f"parameter {name!r} is {beams}, expected at most {MAX_LASER_BEAMS} beams per scan "
            "(locbench.core.limits.MAX_LASER_BEAMS)"
        )


def grid_cells(shape: tuple[int, int]) -> float:
    """Cells of a grid of ``shape`` (rows, cols), as a float (no overflow)."""
    return float(shape[0]) * float(shape[1])


def check_input_file(
    path: str | os.PathLike[str], what: str, max_bytes: int, *, folder_ok: bool = False
) -> os.stat_result:
    """Refuse a user-named input that is not a regular file of at most ``max_bytes`` (looked at before opening).

    Parameters
    ----------
    path : path-like
        The file (or, with ``folder_ok``, a folder of regular files such as a ROS 2 bag).
    what : str
        What the input is, for the message ("suite file", "bag", "map YAML").
    max_bytes : int
        Largest size accepted, bytes (a folder: the sum of its files).
    folder_ok : bool
        Accept a folder whose entries are all regular files (checked one by one, not followed into subfolders).

    Returns
    -------
    os.stat_result
        The stat of ``path``.

    Raises
    ------
    ConfigError
        One line naming the path and what was expected: missing, unreadable, a folder (unless ``folder_ok``), a FIFO,
        socket or device, or larger than ``max_bytes``.
    """
    p = Path(path)
    expected = f"a regular file{' or a folder of regular files' if folder_ok else ''} of at most {max_bytes} bytes"
    try:
        st = p.stat()
    except FileNotFoundError:
        raise ConfigError(f"{p}: {what} not found") from None
    except OSError as exc:
        raise ConfigError(f"{p}: cannot read the {what} ({exc.strerror})") from None
    if stat.S_ISDIR(st.st_mode):
        if not folder_ok:
            raise ConfigError(f"{p}: is a folder; expected the {what} as {expected}")
        total = 0
        try:
            entries = sorted(p.iterdir())
            for q in entries:
                qst = q.stat()
                if not stat.S_ISREG(qst.st_mode):
                    raise ConfigError(f"{q}: not a regular file in the {what} folder {p}; expected {expected}")
                total += qst.st_size
        except OSError as exc:
            raise ConfigError(f"{p}: cannot read the {what} folder ({exc.strerror})") from None
        if total > max_bytes:
            raise ConfigError(f"{p}: {total} bytes in the {what} folder; expected {expected}")
        return st
    if not stat.S_ISREG(st.st_mode):
        raise ConfigError(f"{p}: not a regular file (a FIFO, socket or device); expected the {what} as {expected}")
    if st.st_size > max_bytes:
        raise ConfigError(f"{p}: {st.st_size} bytes; expected the {what} as {expected}")
    return st
