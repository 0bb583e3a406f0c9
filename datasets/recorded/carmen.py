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
:data:`~locbench.datasets.recorded.files.MAX_POSITION_M` or a negative range (:func:`read_carmen`); the time
going backwards within a message stream by more than ``max_backstep_s`` (default 0: strictly non-decreasing).

Plausibility (:func:`read_carmen_flagged`, the policy of :mod:`~locbench.datasets.recorded.plausibility`):
besides the structural checks above, a stream (ODOM or FLASER) of two or more messages all stamped alike is
refused, and these messages are flagged, to be left out by the caller (:class:`CarmenFlags`; a stream with more
than 1 % of them, or a 2 s stretch, is refused): a message repeating the previous one in every field (a doubled
line); an ODOM ``theta`` beyond the heading bound, a ``tv`` beyond the speed bound or an ``rv`` beyond the
turn-rate bound; a FLASER with a range outside [0, range bound] (a negative range is one bad reading, not a
broken file), or a laser or odometry ``theta`` beyond the heading bound; an ODOM pose, FLASER laser pose or
FLASER odometry pose the robot could not have reached from the last accepted one (speed and turn-rate bounds
over the time between the stamps plus ``max_backstep_s``: a log whose stamps may step back by that much carries
that much uncertainty in each stamp; in stamp order). A position or range beyond ``MAX_POSITION_M`` is still
refused (a limit, not a sample).

Time stamps that go backwards in real logs: in ``intel.clf`` 631 FLASER and 602 ODOM messages carry an
``ipc_timestamp`` smaller than the message before them in the file, by up to 0.90 s (the
``logger_timestamp`` is the same clock shifted by a constant and has the same steps). A caller that must
read such a log passes ``max_backstep_s`` (the loaders of the Freiburg SLAM benchmark's raw logs, intel and
radish, pass :data:`FREIBURG_MAX_BACKSTEP_S`, 1 s) and orders the messages itself; the arrays here are always in
file order.

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

from locbench.datasets.dataset import FlaggedSample
from locbench.datasets.recorded import plausibility
from locbench.datasets.recorded.files import (
    MAX_POSITION_M,
    MissingDataFile,
    RecordedDataError,
    float_fields,
    quote,
)

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

#: The ``max_backstep_s`` of the Freiburg SLAM benchmark's raw logs, s: the largest tolerated step back of a stream's
#: stamps (``intel.clf``'s worst is 0.90 s; ``aces.clf`` and ``fr079.clf`` never step back), and each stamp's
#: uncertainty when their pose tracks are judged.
FREIBURG_MAX_BACKSTEP_S = 1.0
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
    return _read_cached(*_cache_key(path, max_backstep_s, time_checked), max_beams)


def _cache_key(
    path: str | os.PathLike[str], max_backstep_s: float, time_checked: Sequence[str]
) -> tuple[str, int, int, float, tuple[str, ...]]:
    """(resolved path, size, mtime, max_backstep_s, time_checked) of a log, after checking the options."""
    p = Path(path)
    try:
        st = p.stat()
    except FileNotFoundError:
        raise MissingDataFile(p, "missing file (expected a CARMEN log)") from None
    for name in time_checked:
        if name not in ("ODOM", "FLASER"):
            raise ValueError(f"time_checked holds {name!r}; expected 'ODOM' and/or 'FLASER'")
    return str(p.resolve()), st.st_size, st.st_mtime_ns, float(max_backstep_s), tuple(time_checked)


@functools.lru_cache(maxsize=8)
def _read_cached(
    path: str, size: int, mtime_ns: int, max_backstep_s: float, time_checked: tuple[str, ...], max_beams: int | None
) -> CarmenLog:
    log = _parse(Path(path), max_beams=max_beams)
    _check_times(log, max_backstep_s, time_checked)
    return log


def _check_times(log: CarmenLog, max_backstep_s: float, time_checked: tuple[str, ...]) -> None:
    for name in time_checked:
        msgs: OdomMessages | LaserMessages = log.odom if name == "ODOM" else log.flaser
        _check_time(log.path, name, msgs.ipc_t, msgs.lines, max_backstep_s)


@dataclass(frozen=True, eq=False)
class CarmenFlags:
    """The messages of a CARMEN log that break the plausibility bounds (:func:`read_carmen_flagged`).

    Attributes
    ----------
    odom_kept, flaser_kept : ndarray of bool, shape (n,)
        True for each ODOM or FLASER message (file order, as :class:`CarmenLog`) that is not flagged; all True for
        a stream that was not checked.
    flagged : tuple of FlaggedSample
        The flagged messages, in time order.
    """

    odom_kept: BoolArray
    flaser_kept: BoolArray
    flagged: tuple[FlaggedSample, ...]


def read_carmen_flagged(
    path: str | os.PathLike[str],
    *,
    max_backstep_s: float = 0.0,
    time_checked: Sequence[str] = ("ODOM", "FLASER"),
    bounds: plausibility.Bounds = plausibility.BOUNDS,
) -> tuple[CarmenLog, CarmenFlags]:
    """Parse a CARMEN log and apply the plausibility policy to its checked streams (cached like :func:`read_carmen`).

    Parameters
    ----------
    path, max_backstep_s, time_checked
        As :func:`read_carmen`; only the streams in ``time_checked`` are judged (a GMapping ``*.gfs.log``'s ODOM
        lines are stamped 0 and say nothing).
    bounds : Bounds
        The policy's bounds, or a loader's tightened ones.

    Returns
    -------
    log : CarmenLog
        Every message, in file order (a negative range kept as read).
    flags : CarmenFlags
        Which messages to leave out, and why (the module docstring lists the bounds).

    Raises
    ------
    RecordedDataError
        As :func:`read_carmen` except for a negative range; a checked stream all stamped alike; more than 1 % of
        a stream flagged, or a 2 s stretch of it.
    """
    return _read_flagged_cached(*_cache_key(path, max_backstep_s, time_checked), bounds)


@functools.lru_cache(maxsize=8)
def _read_flagged_cached(
    path: str,
    size: int,
    mtime_ns: int,
    max_backstep_s: float,
    time_checked: tuple[str, ...],
    bounds: plausibility.Bounds,
) -> tuple[CarmenLog, CarmenFlags]:
    log = _parse(Path(path), ranges_lo=-MAX_POSITION_M)  # a negative range is flagged below, not refused
    _check_times(log, max_backstep_s, time_checked)
    kept: dict[str, BoolArray] = {}
    found = []
    for name in ("ODOM", "FLASER"):
        msgs: OdomMessages | LaserMessages = log.odom if name == "ODOM" else log.flaser
        if name in time_checked:
            kept[name], flagged = _flag_stream(log.path, msgs, bounds, max_backstep_s)
            found.append(flagged)
        else:
            kept[name] = np.ones(len(msgs), dtype=bool)
    for a in kept.values():
        a.setflags(write=False)
    return log, CarmenFlags(kept["ODOM"], kept["FLASER"], plausibility.merge(*found))


def _flag_stream(
    path: Path, msgs: OdomMessages | LaserMessages, b: plausibility.Bounds, stamp_uncertainty_s: float
) -> tuple[BoolArray, tuple[FlaggedSample, ...]]:
    """Which messages of one stream (file order) are kept, and the flagged ones (the module docstring's bounds)."""
    name = "ODOM" if isinstance(msgs, OdomMessages) else "FLASER"
    n = len(msgs)
    if n > 1:
        plausibility.refuse_all_times_equal(path, name, msgs.ipc_t, int(msgs.lines[1]))
    # judged in stamp order (equal stamps keep file order): the order a consumer uses the messages in
    order = np.argsort(msgs.ipc_t, kind="stable")
    flags = plausibility.Flags(path, name, msgs.ipc_t[order], msgs.lines[order])
    h = b.heading_abs_rad
    tracks = [msgs.pose[order]]
    if isinstance(msgs, OdomMessages):
        flags.flag_duplicates(
            np.column_stack([msgs.pose, msgs.tv, msgs.rv, msgs.accel, msgs.ipc_t, msgs.logger_t])[order]
        )
        flags.flag_outside(msgs.pose[order, 2], "theta, rad", -h, h)
        flags.flag_outside(msgs.tv[order], "tv, m/s", -b.speed_mps, b.speed_mps)
        flags.flag_outside(msgs.rv[order], "rv, rad/s", -b.turn_rate_radps, b.turn_rate_radps)
    else:
        flags.flag_duplicates(
            np.column_stack([msgs.ranges, msgs.pose, msgs.odom_pose, msgs.ipc_t, msgs.logger_t])[order]
        )
        flags.flag_outside(_worst(msgs.ranges[order], 0.0, b.range_m), "range, m", 0.0, b.range_m)
        flags.flag_outside(msgs.pose[order, 2], "theta, rad", -h, h)
        flags.flag_outside(msgs.odom_pose[order, 2], "odom_theta, rad", -h, h)
        tracks.append(msgs.odom_pose[order])
    for pose in tracks:
        flags.flag_track(pose[:, :2], pose[:, 2], b, stamp_uncertainty_s=stamp_uncertainty_s)
    kept = np.empty(n, dtype=bool)
    kept[order] = flags.kept
    return kept, flags.finish()


def _worst(block: FloatArray, lo: float, hi: float) -> FloatArray:
    """Per row of ``block``, the value farthest outside [lo, hi] (a value inside when all are)."""
    if block.shape[1] == 0:
        return np.full(block.shape[0], lo)
    k = np.argmax(np.maximum(lo - block, block - hi), axis=1)
    return block[np.arange(block.shape[0]), k]


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


def _parse(p: Path, raw: bytes | None = None, ranges_lo: float = 0.0, max_beams: int | None = None) -> CarmenLog:
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
    _check_bounds(
        p, "FLASER", f[:, :nb], las_ln, 2, tuple(f"r_{j + 1}" for j in range(nb)), MAX_POSITION_M, lo=ranges_lo
    )
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
