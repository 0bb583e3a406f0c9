"""A reader for CARMEN log files (``*.clf``, ``*.gfs.log``): ODOM and FLASER messages.

The CARMEN logger writes one message per line, fields separated by blanks, ``#`` comment lines allowed.
Every message ends with three fields: ``ipc_timestamp`` (s, Unix time of the IPC message), ``ipc_host``
(a word) and ``logger_timestamp`` (s since the logger started). The two message types read here are

* ``ODOM x y theta tv rv accel ipc_timestamp ipc_host logger_timestamp`` (10 fields): the odometry pose
  (x m, y m, theta rad, in the odometry frame), translational and rotational speed (m/s, rad/s) and
  acceleration (m/s^2);
* ``FLASER n r_1 .. r_n x y theta odom_x odom_y odom_theta ipc_timestamp ipc_host logger_timestamp``
  (n + 11 fields): the front laser's n ranges (m, beam order counter-clockwise), the laser pose
  (x m, y m, theta rad; in a raw log the odometry pose, in a corrected log such as GMapping's
  ``*.gfs.log`` the corrected pose) and the odometry pose of the robot at the scan.

``PARAM name value ...`` lines are kept as a name -> value mapping (a name given again: the later value), with the
lines of each name in :attr:`CarmenLog.param_lines` and the lines of the logger's header comments
(``# message formats defined: ...``, one per logging session) in :attr:`CarmenLog.header_lines`, so that a
caller can refuse a parameter given twice; every other message type (RLASER, TRUEPOS, NEFF, ROBOTLASER1, SYNC,
...) is skipped and counted per type in :attr:`CarmenLog.skipped`.
The number of beams must be the same in every FLASER of one file (the beam geometry is not in the
message; a consumer gives it once per log).

Checks (each a :class:`~locbench.datasets.recorded.files.RecordedDataError` naming the file and the
1-based line): a missing file; a non-ASCII byte; a wrong field count (for FLASER: a count that does not
match its own ``n``, or above a caller's ``max_beams``, refused before the line's ranges are read; a last
line without its newline is reported as truncated, even with a full field count, since its last field may be
cut); a non-integer beam count; a field that is not a finite number
(named by its position and meaning); a position (ODOM x, y; FLASER pose and odometry pose) beyond
:data:`~locbench.datasets.recorded.files.MAX_POSITION_M` or a negative range; the time going backwards
within a message stream by more than ``max_backstep_s`` (default 0: strictly non-decreasing).

Time stamps that go backwards in real logs: in ``intel.clf`` 631 FLASER and 602 ODOM messages carry an
``ipc_timestamp`` smaller than the message before them in the file, by up to 0.90 s (the
``logger_timestamp`` is the same clock shifted by a constant and has the same steps). A caller that must
read such a log passes ``max_backstep_s`` (the Intel loader uses 1 s) and orders the messages itself;
the arrays here are always in file order.

Speed: ``intel.clf`` (16 MB, 13631 FLASER x 180 beams, 26915 ODOM) parses in about 3 s on one (shared) core;
:func:`read_carmen` caches the result per (resolved path, size, mtime, options).
"""

from __future__ import annotations

import functools
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

from locbench.datasets.recorded.files import (
    MAX_POSITION_M,
    MissingDataFile,
    RecordedDataError,
    float_fields,
    quote,
)

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

#: Field names of an ODOM message after the message name (the host, a word, is not stored).
ODOM_FIELDS = ("x", "y", "theta", "tv", "rv", "accel", "ipc_timestamp", "ipc_host", "logger_timestamp")
#: Field names of a FLASER message after the ranges.
FLASER_TAIL = (
    "x",
    "y",
    "theta",
    "odom_x",
    "odom_y",
    "odom_theta",
    "ipc_timestamp",
    "ipc_host",
    "logger_timestamp",
)


@dataclass(frozen=True, eq=False)
class OdomMessages:
    """The ODOM messages of a log, in file order (arrays read-only).

    Attributes
    ----------
    pose : ndarray, shape (n, 3)
        Odometry pose (x m, y m, theta rad), odometry frame.
    tv, rv, accel : ndarray, shape (n,)
        Translational speed (m/s), rotational speed (rad/s), acceleration (m/s^2) as logged.
    ipc_t, logger_t : ndarray, shape (n,)
        ``ipc_timestamp`` (Unix s) and ``logger_timestamp`` (s since the logger started).
    lines : ndarray of int64, shape (n,)
        1-based line of each message in the file.
    """

    pose: FloatArray
    tv: FloatArray
    rv: FloatArray
    accel: FloatArray
    ipc_t: FloatArray
    logger_t: FloatArray
    lines: IntArray

    def __len__(self) -> int:
        return int(self.ipc_t.shape[0])


@dataclass(frozen=True, eq=False)
class LaserMessages:
    """The FLASER messages of a log, in file order (arrays read-only).

    Attributes
    ----------
    ranges : ndarray, shape (n, beams)
        Ranges as logged, m (no-return readings keep the log's own value, e.g. 81.83 m).
    pose : ndarray, shape (n, 3)
        Laser pose (x m, y m, theta rad): odometry in a raw log, corrected in a SLAM output log.
    odom_pose : ndarray, shape (n, 3)
        Odometry pose of the robot at the scan (x m, y m, theta rad).
    ipc_t, logger_t : ndarray, shape (n,)
        ``ipc_timestamp`` (Unix s) and ``logger_timestamp`` (s since the logger started).
    lines : ndarray of int64, shape (n,)
        1-based line of each message in the file.
    """

    ranges: FloatArray
    pose: FloatArray
    odom_pose: FloatArray
    ipc_t: FloatArray
    logger_t: FloatArray
    lines: IntArray

    def __len__(self) -> int:
        return int(self.ipc_t.shape[0])


@dataclass(frozen=True, eq=False)
class CarmenLog:
    """A parsed CARMEN log: ODOM and FLASER messages, PARAM values and counts of the skipped message types.

    ``param_lines`` holds the 1-based lines of each PARAM name in file order; ``header_lines`` the lines of the
    logger's header comments (``# message formats defined``), each of which starts a logging session.
    """

    path: Path
    odom: OdomMessages
    flaser: LaserMessages
    params: dict[str, str] = field(default_factory=dict)
    skipped: dict[str, int] = field(default_factory=dict)
    param_lines: dict[str, tuple[int, ...]] = field(default_factory=dict)
    header_lines: tuple[int, ...] = ()


def read_carmen(
    path: str | os.PathLike[str],
    *,
    max_backstep_s: float = 0.0,
    time_checked: Sequence[str] = ("ODOM", "FLASER"),
    max_beams: int | None = None,
) -> CarmenLog:
    """Parse a CARMEN log (cached per resolved path, size, mtime and options).

    Parameters
    ----------
    path : path-like
        The log file.
    max_backstep_s : float
        Largest tolerated step back of ``ipc_timestamp`` between consecutive messages of one stream, s;
        0 requires non-decreasing times. Use ``inf`` to skip the check.
    time_checked : sequence of str
        The streams (``"ODOM"``, ``"FLASER"``) whose time is checked. A GMapping ``*.gfs.log`` writes ODOM
        lines stamped 0 after each scan, so only its FLASER times are meaningful.
    max_beams : int or None
        Most ranges a FLASER may hold (None: no bound); a larger count is refused before its ranges are read.

    Returns
    -------
    CarmenLog
        Read-only arrays in file order.

    Raises
    ------
    RecordedDataError
        Naming the file and line: see the module docstring.
    """
    p = Path(path)
    try:
        st = p.stat()
    except FileNotFoundError:
        raise MissingDataFile(p, "missing file (expected a CARMEN log)") from None
    for name in time_checked:
        if name not in ("ODOM", "FLASER"):
            raise ValueError(f"time_checked holds {name!r}; expected 'ODOM' and/or 'FLASER'")
    return _read_cached(
        str(p.resolve()), st.st_size, st.st_mtime_ns, float(max_backstep_s), tuple(time_checked), max_beams
    )


@functools.lru_cache(maxsize=8)
def _read_cached(
    path: str, size: int, mtime_ns: int, max_backstep_s: float, time_checked: tuple[str, ...], max_beams: int | None
) -> CarmenLog:
    log = _parse(Path(path), max_beams=max_beams)
    for name in time_checked:
        msgs: OdomMessages | LaserMessages = log.odom if name == "ODOM" else log.flaser
        _check_time(log.path, name, msgs.ipc_t, msgs.lines, max_backstep_s)
    return log


def _check_time(path: Path, name: str, t: FloatArray, lines: IntArray, max_backstep_s: float) -> None:
    if t.shape[0] < 2:
        return
    back = np.flatnonzero(np.diff(t) < -max_backstep_s)
    if back.size:
        k = int(back[0]) + 1
        allowed = "non-decreasing" if max_backstep_s == 0 else f"at most {max_backstep_s:g} s back"
        raise RecordedDataError(
            path,
            f"time goes backwards: {name} ipc_timestamp {float(t[k]):.6f} after {float(t[k - 1]):.6f} "
            f"(line {int(lines[k - 1])}); "
            f"expected {allowed}",
            int(lines[k]),
        )


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


def parse_carmen_bytes(path: str | os.PathLike[str], raw: bytes, *, max_beams: int | None = None) -> CarmenLog:
    """Parse the bytes of a CARMEN log read elsewhere (a decompressed ``*.log.gz``); errors name ``path``.

    No time check and no cache: the caller checks the streams it uses and caches by content. ``max_beams``: as in
    :func:`read_carmen`.
    """
    return _parse(Path(path), raw, max_beams=max_beams)


def _parse(p: Path, raw: bytes | None = None, max_beams: int | None = None) -> CarmenLog:
    # long: one pass over the log's lines whose record kinds share the parser's state and line numbers for errors
    if raw is None:
        raw = p.read_bytes()
    try:
        text = raw.decode("ascii")
    except UnicodeDecodeError as exc:
        bad = raw[: exc.start].count(b"\n") + 1
        raise RecordedDataError(p, f"non-ASCII byte {raw[exc.start]:#04x} (expected a CARMEN text log)", bad) from None
    text_lines = text.split("\n")
    last = len(text_lines) - 1 if not text.endswith("\n") else -1
    tail = text_lines[-1].split()
    if last >= 0 and tail and tail[0] in ("ODOM", "FLASER"):
        expected = 10 if tail[0] == "ODOM" else (int(tail[1]) + 11 if len(tail) > 1 and tail[1].isdigit() else -1)
        if len(tail) == expected:  # a wrong count is reported below; a full count may hide a field cut short
            raise RecordedDataError(
                p,
                f"truncated line: the last {tail[0]} message has no line end, so its last field may be cut "
                "(expected a complete message ending in a newline)",
                last + 1,
            )
    odom_tok: list[str] = []
    odom_ln: list[int] = []
    las_tok: list[str] = []
    las_ln: list[int] = []
    n_beams = -1
    params: dict[str, str] = {}
    param_lines: dict[str, list[int]] = {}
    header_lines: list[int] = []
    skipped: dict[str, int] = {}
    for k, line in enumerate(text_lines):
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            if parts and "message formats defined" in line:
                header_lines.append(k + 1)
            continue
        kind = parts[0]
        lineno = k + 1
        if kind == "ODOM":
            if len(parts) != 10:
                _count_error(p, lineno, k == last, len(parts), 10, "ODOM " + " ".join(ODOM_FIELDS))
            odom_tok.extend(parts[1:8])
            odom_tok.append(parts[9])
            odom_ln.append(lineno)
        elif kind == "FLASER":
            if len(parts) < 2:
                _count_error(p, lineno, k == last, len(parts), 12, "FLASER n r_1..r_n " + " ".join(FLASER_TAIL))
            try:
                n = int(parts[1])
            except ValueError:
                raise RecordedDataError(
                    p, f"field 2 (n, the number of ranges) is {quote(parts[1])}, expected an integer", lineno
                ) from None
            if n <= 0:
                raise RecordedDataError(p, f"field 2 (n, the number of ranges) is {n}, expected > 0", lineno)
            if max_beams is not None and n > max_beams:
                raise RecordedDataError(
                    p, f"field 2 (n, the number of ranges) is {n}, expected at most {max_beams} beams per scan", lineno
                )
            if len(parts) != n + 11:
                _count_error(
                    p, lineno, k == last, len(parts), n + 11, f"FLASER n={n} r_1..r_{n} " + " ".join(FLASER_TAIL)
                )
            if n_beams < 0:
                n_beams = n
            elif n != n_beams:
                raise RecordedDataError(
                    p, f"FLASER with {n} ranges, expected {n_beams} (the count of the log's first FLASER)", lineno
                )
            las_tok.extend(parts[2 : n + 9])
            las_tok.append(parts[n + 10])
            las_ln.append(lineno)
        elif kind == "PARAM":
            if len(parts) >= 3:
                params[parts[1]] = parts[2]
                param_lines.setdefault(parts[1], []).append(lineno)
            skipped["PARAM"] = skipped.get("PARAM", 0) + 1
        else:
            skipped[kind] = skipped.get(kind, 0) + 1
    odom_cols = ("x", "y", "theta", "tv", "rv", "accel", "ipc_timestamp", "logger_timestamp")
    o = _to_floats(p, odom_tok, odom_ln, odom_cols, "ODOM", offset=1)
    nb = max(n_beams, 0)
    las_cols = tuple(f"r_{j + 1}" for j in range(nb)) + FLASER_TAIL[:7] + ("logger_timestamp",)
    f = _to_floats(p, las_tok, las_ln, las_cols, "FLASER", offset=2)
    odom = OdomMessages(
        pose=_readonly(np.ascontiguousarray(o[:, 0:3])),
        tv=_readonly(o[:, 3].copy()),
        rv=_readonly(o[:, 4].copy()),
        accel=_readonly(o[:, 5].copy()),
        ipc_t=_readonly(o[:, 6].copy()),
        logger_t=_readonly(o[:, 7].copy()),
        lines=_readonly(np.asarray(odom_ln, dtype=np.int64)),
    )
    las = LaserMessages(
        ranges=_readonly(np.ascontiguousarray(f[:, :nb])),
        pose=_readonly(np.ascontiguousarray(f[:, nb : nb + 3])),
        odom_pose=_readonly(np.ascontiguousarray(f[:, nb + 3 : nb + 6])),
        ipc_t=_readonly(f[:, nb + 6].copy()),
        logger_t=_readonly(f[:, nb + 7].copy()),
        lines=_readonly(np.asarray(las_ln, dtype=np.int64)),
    )
    _check_bounds(p, "ODOM", o[:, 0:2], odom_ln, 1, ("x", "y"), MAX_POSITION_M)
    _check_bounds(p, "FLASER", f[:, nb : nb + 2], las_ln, nb + 2, ("x", "y"), MAX_POSITION_M)
    _check_bounds(p, "FLASER", f[:, nb + 3 : nb + 5], las_ln, nb + 5, ("odom_x", "odom_y"), MAX_POSITION_M)
    _check_bounds(p, "FLASER", f[:, :nb], las_ln, 2, tuple(f"r_{j + 1}" for j in range(nb)), MAX_POSITION_M, lo=0.0)
    lines_of = {name: tuple(at) for name, at in param_lines.items()}
    return CarmenLog(p, odom, las, params, skipped, lines_of, tuple(header_lines))


def _check_bounds(
    p: Path,
    kind: str,
    block: FloatArray,
    lines: list[int],
    first_field: int,
    names: tuple[str, ...],
    bound: float,
    lo: float | None = None,
) -> None:
    """Raise at the first value of ``block`` (rows = messages) outside [lo or -bound, bound], naming line and field."""
    low = -bound if lo is None else lo
    bad = np.argwhere((block < low) | (block > bound))
    if bad.size:
        r, c = (int(i) for i in bad[0])
        raise RecordedDataError(
            p,
            f"{kind} field {first_field + c + 1} ({names[c]}) is {float(block[r, c])!r}, "
            f"expected in [{low!r}, {bound!r}]",
            lines[r],
        )


def _count_error(p: Path, lineno: int, is_last: bool, got: int, expected: int, layout: str) -> None:
    what = "truncated line" if is_last and got < expected else "wrong field count"
    raise RecordedDataError(p, f"{what}: {got} fields, expected {expected} ({layout})", lineno)


def _to_floats(
    p: Path, tokens: list[str], lines: list[int], cols: tuple[str, ...], kind: str, offset: int
) -> FloatArray:
    """Convert the numeric fields of one message type at once (:func:`.files.float_fields`)."""
    last = len(cols) - 1
    # The field's position on the line: the host (a word) sits before logger_timestamp.
    return float_fields(p, tokens, lines, cols, kind, lambda c: c + offset + 1 + (1 if c == last else 0))
