"""Finding, verifying, fetching and parsing the files of recorded datasets.

Every recorded loader resolves its files through :func:`locate`:

1. the local folder: ``<root>/<relative path>``, where ``root`` is the loader's ``root`` parameter when
   given, else the environment variable ``LOCBENCH_DATA`` (``.ci/run`` points it at ``../shared/datasets``);
2. else, when the file has an official download, the download cache (``LOCBENCH_CACHE``, default
   ``pooch.os_cache("locbench")``), fetched there with pooch and verified by sha256.

A file whose sha256 is known is verified once per (path, size, mtime) in a process, so that a file that
was edited or truncated after it was published is reported as a checksum mismatch rather than parsed.

Errors are :class:`RecordedDataError` (a :class:`~locbench.core.errors.ConfigError`): the message names the
file, the line (1-based, counting every line of the file) or the variable and index where there is one, the
field, what was found and what was expected, on one line of at most
:data:`~locbench.core.errors.MAX_MESSAGE_CHARS` characters (a quoted value is cut by :func:`quote`).

The shared checks of every loader live here: :func:`read_table` (text tables: field count, numbers, integers,
finiteness, a last record cut inside a field), :meth:`Table.check_range` and :meth:`Table.check_time_increasing`
(physical ranges and time order of a column), :func:`mat_numbers` (MAT variables: dtype, finiteness) with
:func:`check_range` and :func:`check_increasing` for arrays, and the resource bounds :func:`check_cells` (grid
size in cells before it is allocated) and :func:`check_count` (how many items a value would make).
"""

from __future__ import annotations

import hashlib
import math
import os
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from locbench.core.errors import ConfigError, DataNotFound, DependencyNotInstalled, one_line

FloatArray = npt.NDArray[np.float64]

#: Longest quoted value inside a message, characters.
MAX_QUOTE_CHARS = 200
#: Largest occupancy grid a loader builds, cells (4096 x 4096: 134 MB of float64 occupancy; a map read at this size
#: stays under 1 GB in all, measured in tests/fuzz/test_fuzz_loaders.py).
MAX_GRID_CELLS = 1 << 24
#: The most a dataset's ``max_grid_cells`` parameter may raise that to (a 2 GiB grid of float64).
MAX_GRID_CELLS_BOUND = 1 << 28
#: Largest count of derived items (waypoints, database poses ...) a single parameter may ask for.
MAX_DERIVED_ITEMS = 1_000_000
#: Largest id or count in an integer field of a text table (ids and barcodes are small; 2**31 - 1 keeps int64
#: casts and dict keys exact).
MAX_INTEGER_FIELD = 2**31 - 1
#: Generous bound on any position in a recording, m: no indoor or campus dataset is 1000 km across.
MAX_POSITION_M = 1.0e6


def quote(value: Any, limit: int = MAX_QUOTE_CHARS) -> str:
    """``repr(value)`` on one line, cut to ``limit`` characters (the cut is marked and says how long it was)."""
    text = repr(value)
    text = text.replace("\n", " ").replace("\r", " ")
    if len(text) <= limit:
        return text
    return f"{text[: max(limit - 30, 10)]}... [{len(text)} chars]"


#: Environment variable naming the folder that holds the recorded datasets (SOURCES.md layout).
DATA_ENV = "LOCBENCH_DATA"
#: Environment variable naming the download cache (default: pooch's per-user cache for "locbench").
CACHE_ENV = "LOCBENCH_CACHE"


class RecordedDataError(ConfigError):
    """A recorded-data file is missing, corrupt or malformed.

    Attributes
    ----------
    path : Path
        The file.
    line : int or None
        1-based line number in the file, when the problem is on a line.
    """

    def __init__(self, path: str | os.PathLike[str], message: str, line: int | None = None) -> None:
        self.path = Path(path)
        self.line = line
        where = f"{self.path}:{line}" if line is not None else f"{self.path}"
        super().__init__(one_line(f"{where}: {message}"))


class MissingDataFile(RecordedDataError, DataNotFound):
    """A dataset file is in neither the local data folder nor the download cache."""


@dataclass(frozen=True)
class RemoteFile:
    """One file of a dataset: where it lies relative to the data root, its checksum and its official download.

    Attributes
    ----------
    relpath : str
        Path below the data root, with ``/`` separators (``utias_mrclam/MRCLAM_Dataset6/Barcodes.dat``).
    sha256 : str or None
        Hex digest of the file's bytes (of the decompressed file when ``decompress`` is set); None when unknown.
    url : str or None
        Official download (http/https); None when the dataset has none.
    download_sha256 : str or None
        Hex digest of the downloaded bytes when they differ from the file's (a compressed download).
    decompress : str or None
        ``"bz2"`` (or ``"bzip2"``) or ``"gzip"`` when the download must be decompressed.
    """

    relpath: str
    sha256: str | None = None
    url: str | None = None
    download_sha256: str | None = None
    decompress: str | None = None


def data_root(root: str | os.PathLike[str] | None = None) -> Path | None:
    """The local data folder: ``root`` when given (non-empty), else ``$LOCBENCH_DATA``, else None."""
    if root is not None and str(root) != "":
        return Path(root).expanduser()
    env = os.environ.get(DATA_ENV, "")
    return Path(env).expanduser() if env else None


def user_path_candidates(path: str | os.PathLike[str]) -> list[Path]:
    """Where a path the user typed (a bag, a log folder, a sidecar) is looked for: as given (absolute or relative to
    the working folder), then, when relative, under ``$LOCBENCH_DATA``."""
    p = Path(path).expanduser()
    root = os.environ.get(DATA_ENV, "")
    return [p] + ([Path(root).expanduser() / p] if not p.is_absolute() and root else [])


def cache_root() -> Path:
    """The download cache folder (``$LOCBENCH_CACHE`` or pooch's per-user cache)."""
    env = os.environ.get(CACHE_ENV, "")
    if env:
        return Path(env).expanduser()
    try:
        import pooch
    except ImportError:
        return Path.home() / ".cache" / "locbench"
    return Path(pooch.os_cache("locbench"))


def sha256_of(path: str | os.PathLike[str]) -> str:
    """Hex sha256 of a file's bytes (read in 1 MiB chunks)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


_VERIFIED: dict[tuple[str, int, int], str] = {}


def verify_sha256(path: str | os.PathLike[str], expected: str) -> None:
    """Raise :class:`RecordedDataError` unless the file's sha256 equals ``expected`` (cached per size and mtime)."""
    p = Path(path)
    st = p.stat()
    key = (str(p.resolve()), st.st_size, st.st_mtime_ns)
    digest = _VERIFIED.get(key)
    if digest is None:
        digest = sha256_of(p)
        _VERIFIED[key] = digest
    if digest != expected.lower():
        raise RecordedDataError(
            p, f"checksum mismatch: sha256 is {digest}, expected {expected.lower()} (a corrupt, edited or other copy)"
        )


def locate(
    spec: RemoteFile,
    root: str | os.PathLike[str] | None = None,
    *,
    download: bool = False,
    verify: bool = True,
) -> Path:
    """The verified local path of a dataset file, fetching it into the cache when allowed.

    Parameters
    ----------
    spec : RemoteFile
        The file.
    root : path-like or None
        The local data folder; None reads ``$LOCBENCH_DATA``.
    download : bool
        Fetch from ``spec.url`` into :func:`cache_root` when the file is not in the local folder.
    verify : bool
        Check the sha256 when it is known.

    Raises
    ------
    RecordedDataError
        The file is absent (the message says where it was looked for and how to get it) or its checksum
        does not match.
    """
    base = data_root(root)
    candidates = [base / spec.relpath] if base is not None else []
    cached = cache_root() / spec.relpath
    candidates.append(cached)
    for path in candidates:
        if path.is_file():
            if verify and spec.sha256:
                verify_sha256(path, spec.sha256)
            return path
    if download and spec.url:
        return _fetch(spec, cached)
    # the error names candidates[0]; the message names only the other places looked in
    also = f" (nor in {', '.join(str(c) for c in candidates[1:])})" if len(candidates) > 1 else ""
    if spec.url:
        how = f"set {DATA_ENV} to the folder that holds it, or download it with 'locbench fetch'"
    else:
        how = f"this dataset has no official download; set {DATA_ENV} to the folder that holds it"
    raise MissingDataFile(candidates[0], f"missing file{also}; {how}")


def _fetch(spec: RemoteFile, target: Path) -> Path:
    try:
        import pooch
    except ImportError:
        raise DependencyNotInstalled(
            "downloading recorded datasets needs pooch (a dependency of locbench); install it with: pip install pooch"
        ) from None
    assert spec.url is not None
    target.parent.mkdir(parents=True, exist_ok=True)
    known = spec.download_sha256 or (spec.sha256 if spec.decompress is None else None)
    processor: Callable[..., str] | None = None
    if spec.decompress is not None:
        method = {"bz2": "bzip2", "gz": "gzip"}.get(spec.decompress, spec.decompress)
        processor = pooch.Decompress(method=method, name=target.name)
    try:
        got = pooch.retrieve(
            spec.url,
            known_hash=f"sha256:{known}" if known else None,
            fname=target.name + (f".{spec.decompress}" if spec.decompress else ""),
            path=target.parent,
            processor=processor,
            progressbar=False,
        )
    except ValueError as exc:  # pooch's hash mismatch; it has already removed the bad download
        raise RecordedDataError(target, f"download from {spec.url} failed: {exc}") from None
    path = Path(got)
    if spec.sha256:
        try:
            verify_sha256(path, spec.sha256)
        except RecordedDataError:
            path.unlink(missing_ok=True)  # nothing unverified stays in the cache
            raise
    return path


# --- text tables ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Table:
    """Numeric rows of a whitespace-separated text file and the 1-based file line of each row."""

    path: Path
    rows: FloatArray
    lines: npt.NDArray[np.int64]

    def column(self, k: int) -> FloatArray:
        return self.rows[:, k]

    def fail(self, row: int, message: str) -> RecordedDataError:
        """An error naming this table's file and the line of ``row``."""
        return RecordedDataError(self.path, message, int(self.lines[row]))

    def check_time_non_decreasing(self, col: int = 0, name: str = "time") -> None:
        """Raise at the first row whose ``col`` is smaller than the previous row's."""
        t = self.rows[:, col]
        back = np.flatnonzero(np.diff(t) < 0)
        if back.size:
            k = int(back[0]) + 1
            now, before = float(t[k]), float(t[k - 1])
            raise self.fail(k, f"{name} goes backwards: {now!r} after {before!r} (expected non-decreasing)")

    def check_range(self, col: int, name: str, lo: float = -math.inf, hi: float = math.inf) -> None:
        """Raise at the first row whose ``col`` lies outside [``lo``, ``hi``] (``name`` carries the unit)."""
        a = self.rows[:, col]
        bad = np.flatnonzero((a < lo) | (a > hi))
        if bad.size:
            k = int(bad[0])
            raise self.fail(k, f"field {col + 1} ({name}) is {float(a[k])!r}, expected {_interval(lo, hi)}")

    def check_rows(self, name: str, minimum: int) -> None:
        """Raise unless the table has at least ``minimum`` rows (``name`` says what a row is)."""
        n = int(self.rows.shape[0])
        if n < minimum:
            raise RecordedDataError(self.path, f"{n} {name} row(s), expected at least {minimum}")


def _interval(lo: float, hi: float) -> str:
    if math.isinf(lo):
        return f"<= {hi!r}"
    if math.isinf(hi):
        return f">= {lo!r}"
    return f"in [{lo!r}, {hi!r}]"


def float_fields(
    p: Path, tokens: list[str], lines: list[int], cols: tuple[str, ...], kind: str, position: Callable[[int], int]
) -> npt.NDArray[np.float64]:
    """The numeric fields of one record type, converted at once, as a (len(lines), len(cols)) array.

    ``tokens`` holds the fields row by row and ``lines`` each row's line number. On a field that is not a finite
    number, the slow path finds the first one (file order) and raises :class:`RecordedDataError` naming its line
    and ``position(c)``, the field's 1-based place on its line for column ``c``.
    """
    ncol = len(cols)
    if not lines:
        return np.zeros((0, ncol))
    try:
        arr = np.array(tokens, dtype=np.float64).reshape(len(lines), ncol)
    except ValueError:
        arr = None
    if arr is not None and np.all(np.isfinite(arr)):
        return arr
    for r, lineno in enumerate(lines):
        for c in range(ncol):
            tok = tokens[r * ncol + c]
            try:
                v = float(tok)
            except ValueError:
                v = math.nan
            if not math.isfinite(v):
                raise RecordedDataError(
                    p, f"{kind} field {position(c)} ({cols[c]}) is {quote(tok)}, expected a finite number", lineno
                )
    raise AssertionError("unreachable: a conversion failed but every field converts")


def check_range(
    path: str | os.PathLike[str], name: str, a: npt.ArrayLike, lo: float = -math.inf, hi: float = math.inf
) -> None:
    """Raise :class:`RecordedDataError` at the first element of ``a`` outside [``lo``, ``hi``].

    ``name`` names the variable or field (with its unit); the element's 1-based index is given.
    """
    arr = np.asarray(a, dtype=np.float64)
    bad = np.flatnonzero(((arr < lo) | (arr > hi)).ravel())
    if bad.size:
        idx = np.unravel_index(int(bad[0]), arr.shape) if arr.ndim else ()
        where = ", ".join(str(int(i) + 1) for i in idx)
        value = float(arr[idx]) if arr.ndim else float(arr)
        raise RecordedDataError(path, f"{name} at ({where}) is {value!r}, expected {_interval(lo, hi)}")


def check_increasing(
    path: str | os.PathLike[str], name: str, t: npt.ArrayLike, *, strict: bool = False, rows: str = "sample"
) -> None:
    """Raise at the first element of the 1-D time series ``t`` that goes backwards (or repeats, when ``strict``)."""
    arr = np.asarray(t, dtype=np.float64)
    d = np.diff(arr)
    bad = np.flatnonzero(d <= 0 if strict else d < 0)
    if bad.size:
        k = int(bad[0]) + 1
        expected = "strictly increasing" if strict else "non-decreasing"
        what = "time repeats" if d[k - 1] == 0 else "time goes backwards"
        raise RecordedDataError(
            path,
            f"{name}: {what} at {rows} {k + 1} (1-based): {float(arr[k])!r} after {float(arr[k - 1])!r}, "
            f"expected {expected}",
        )


def check_cells(source: str | os.PathLike[str], rows: float, cols: float, limit: int, what: str) -> None:
    """Refuse a grid of ``rows`` x ``cols`` cells above ``limit`` before anything is allocated.

    ``what`` says which parameter raises the limit; the message names ``source`` (the file or parameter).
    """
    cells = float(rows) * float(cols)
    if not (math.isfinite(cells) and cells <= limit):
        raise RecordedDataError(
            source,
            f"grid of {rows:.4g} x {cols:.4g} = {cells:.4g} cells, expected at most {limit} cells ({what})",
        )


def check_count(source: str | os.PathLike[str], count: float, limit: int, what: str) -> None:
    """Refuse a derived item count above ``limit`` (waypoints from a spacing, steps from a jump) before allocation."""
    if not (math.isfinite(count) and count <= limit):
        raise RecordedDataError(source, f"{what}: {count:.4g} items, expected at most {limit}")


_SPLIT = re.compile(r"[ \t,]+")


def read_table(
    path: str | os.PathLike[str],
    columns: Sequence[str],
    *,
    comment: str = "#",
    integer_columns: Sequence[int] = (),
) -> Table:
    """Read a whitespace- (or comma-) separated numeric table with a clear error for any bad line.

    Parameters
    ----------
    path : path-like
        The file; ``#`` comment lines and blank lines are skipped; CRLF line ends are accepted.
    columns : sequence of str
        Column names with units (used in messages); every data line must have exactly this many fields.
    comment : str
        Comment prefix.
    integer_columns : sequence of int
        Columns that must hold integers.

    Raises
    ------
    RecordedDataError
        Naming the line: a wrong field count (a line cut short is reported as truncated when it is the
        last line and lacks its newline), a field that is not a number, or a non-integer id.
    """
    # long: one pass over the table's lines, every refusal naming its line; the numpydoc is a third of it
    p = Path(path)
    try:
        raw = p.read_bytes()
    except FileNotFoundError:
        raise MissingDataFile(p, "missing file") from None
    try:
        text = raw.decode("utf-8")  # comments may be any text (a TUM header names a run); numbers are ASCII
    except UnicodeDecodeError as exc:
        bad_line = raw[: exc.start].count(b"\n") + 1
        what = f"byte {raw[exc.start]:#04x} is not UTF-8 text (expected a numeric text table)"
        raise RecordedDataError(p, what, bad_line) from None
    ncol = len(columns)
    lines = text.split("\n")
    ends_with_newline = text.endswith("\n")
    tail = lines[-1].strip()
    if not ends_with_newline and tail and not tail.startswith(comment) and len(_SPLIT.split(tail)) == ncol:
        # A record cut inside its last field still parses (12.345 -> 12.3): refuse any last line without its end.
        raise RecordedDataError(
            p,
            f"truncated line: the last line {quote(tail)} has no line end, so its last field may be cut (expected a "
            f"complete record of {ncol} fields ending in a newline)",
            len(lines),
        )
    rows: list[list[float]] = []
    numbers: list[int] = []
    for k, line in enumerate(lines):
        stripped = line.strip()
        if not stripped or stripped.startswith(comment):
            continue
        fields = _SPLIT.split(stripped)
        lineno = k + 1
        if len(fields) != ncol:
            last = k == len(lines) - 1 and not ends_with_newline
            what = "truncated line" if last and len(fields) < ncol else "wrong column count"
            raise RecordedDataError(p, f"{what}: {len(fields)} fields, expected {ncol} ({', '.join(columns)})", lineno)
        values = []
        for j, f in enumerate(fields):
            try:
                if not f.isascii():  # float() would take other scripts' digits
                    raise ValueError(f)
                v = float(f)
            except ValueError:
                raise RecordedDataError(
                    p, f"field {j + 1} ({columns[j]}) is {quote(f)}, expected a number", lineno
                ) from None
            if not math.isfinite(v):
                raise RecordedDataError(
                    p,
                    f"field {j + 1} ({columns[j]}) is {quote(f)}, a non-finite value (expected a finite number)",
                    lineno,
                )
            if j in integer_columns and (v != math.floor(v) or abs(v) > MAX_INTEGER_FIELD):
                raise RecordedDataError(
                    p,
                    f"field {j + 1} ({columns[j]}) is {quote(f)}, expected an integer of magnitude at most "
                    f"{MAX_INTEGER_FIELD}",
                    lineno,
                )
            values.append(v)
        rows.append(values)
        numbers.append(lineno)
    arr = np.array(rows, dtype=np.float64).reshape(-1, ncol)
    return Table(p, arr, np.array(numbers, dtype=np.int64))


def load_mat(path: str | os.PathLike[str], what: str = "MATLAB file") -> dict[str, Any]:
    """The variables of a MATLAB file (``scipy.io.loadmat``); :class:`MissingDataFile` if it does not exist,
    :class:`RecordedDataError` naming the file when it is not a readable ``what``."""
    from scipy.io import loadmat  # scipy is a core dependency; imported here to keep `import locbench` light

    try:
        mat: dict[str, Any] = loadmat(os.fspath(path))
    except FileNotFoundError:
        raise MissingDataFile(path, "missing file") from None
    except Exception as exc:  # scipy raises ValueError, MatReadError, TypeError ... for a file that is not one
        raise RecordedDataError(path, f"not a readable {what} ({type(exc).__name__}: {exc})") from None
    return mat


#: ``numpy.dtype.kind`` codes and their names, for :func:`mat_numbers` messages.
_KIND_NAMES = {"f": "float", "i": "signed integer", "u": "unsigned integer", "b": "logical"}


def mat_numbers(
    path: str | os.PathLike[str], mat: Mapping[str, Any], name: str, expected: str, *, kinds: str = "f"
) -> FloatArray:
    """Variable ``name`` of a loaded MATLAB file (``scipy.io.loadmat``'s dict) as float64.

    Parameters
    ----------
    path : path-like
        The file (for messages).
    mat : mapping
        ``scipy.io.loadmat``'s dict.
    name : str
        The variable.
    expected : str
        What the caller wants, in words (units, shape).
    kinds : str
        The ``numpy.dtype.kind`` codes the format allows: ``"f"`` (float, the default: an integer or logical
        array where the format stores doubles means the file was written wrongly, and an int32 distance is
        already truncated), ``"fiu"`` for counts and ids, ``"fiub"`` for 0/1 flags.

    Raises
    ------
    RecordedDataError
        Naming the file, the variable and ``expected``: the variable is missing, is not numbers of an allowed
        dtype (text, a struct, complex, an integer where floats are expected) or holds a non-finite value (its
        1-based index is given). The shape is the caller's to check.
    """
    if name not in mat:
        have = sorted(k for k in mat if not k.startswith("__"))
        raise RecordedDataError(
            path, f"variable {name!r}: missing variable, expected {expected} (the file has {quote(have)})"
        )
    raw = np.asarray(mat[name])
    if raw.dtype.kind not in kinds:
        allowed = " or ".join(_KIND_NAMES[k] for k in kinds)
        raise RecordedDataError(
            path, f"variable {name!r}: {raw.dtype} array, expected {expected} of real numbers (stored as {allowed})"
        )
    arr = raw.astype(np.float64)
    bad = np.flatnonzero(~np.isfinite(arr.ravel()))
    if bad.size:
        idx = np.unravel_index(int(bad[0]), arr.shape)
        where = ", ".join(str(int(i) + 1) for i in idx)
        raise RecordedDataError(
            path,
            f"variable {name!r}: non-finite value {float(arr[idx])!r} at ({where}) (1-based), expected finite numbers",
        )
    return arr


# --- checks shared by the bag and plain-text loaders ---------------------------------------------

#: Largest deviation of a pose quaternion's norm from 1 (float32 round-off is about 1e-7; a zero or a hand-scaled
#: quaternion is far off).
QUATERNION_NORM_TOL = 1e-3
#: Largest tilt of a pose's z axis from the world's vertical, rad (10 degrees): a planar robot's odometry and truth
#: rotate about z only; a larger roll or pitch would be read as a heading it is not.
MAX_TILT_RAD = math.radians(10.0)
#: Largest scan ``range_max``, m.
MAX_SCAN_RANGE_M = 1000.0


def quaternion_problem(q: npt.ArrayLike) -> tuple[int, str] | None:
    """The first row of quaternions ``q`` (n, 4) as (qx, qy, qz, qw) that is not a planar unit rotation, and why.

    A row must have norm 1 within :data:`QUATERNION_NORM_TOL` and tilt its z axis at most :data:`MAX_TILT_RAD` from
    the vertical; None when every row does.
    """
    a = np.asarray(q, dtype=np.float64).reshape(-1, 4)
    with np.errstate(invalid="ignore"):
        norm = np.sqrt(np.sum(a * a, axis=1))
        # cos(tilt) = the world z component of the body z axis = 1 - 2 (qx^2 + qy^2) for a unit quaternion
        cos_tilt = 1.0 - 2.0 * (a[:, 0] ** 2 + a[:, 1] ** 2) / np.where(norm > 0, norm * norm, 1.0)
    bad = np.flatnonzero(~(np.abs(norm - 1.0) <= QUATERNION_NORM_TOL))
    if bad.size:
        k = int(bad[0])
        return k, (
            f"orientation quaternion (x, y, z, w) = {quote(tuple(a[k].tolist()))} has norm {float(norm[k])!r}, "
            f"expected a unit quaternion (within {QUATERNION_NORM_TOL})"
        )
    tilted = np.flatnonzero(~(cos_tilt >= math.cos(MAX_TILT_RAD)))
    if tilted.size:
        k = int(tilted[0])
        tilt = math.acos(max(-1.0, min(1.0, float(cos_tilt[k]))))
        return k, (
            f"orientation tilted {tilt:.4g} rad from the vertical (roll or pitch), expected a planar pose (a rotation "
            f"about z, tilt at most {MAX_TILT_RAD:.4g} rad)"
        )
    return None


def scan_problem(n: int, angle_min: float, angle_increment: float, range_min: float, range_max: float) -> str | None:
    """Why a scan of ``n`` beams with this geometry (rad, m) is unusable, or None.

    It needs a beam, a finite ``angle_min`` within +-2 pi, a non-zero ``angle_increment`` with the beams spanning at
    most 2 pi, and 0 <= ``range_min`` < ``range_max`` <= :data:`MAX_SCAN_RANGE_M`.
    """
    inc, a0 = angle_increment, angle_min
    if n < 1:
        return "no ranges, expected at least one beam"
    if not (math.isfinite(a0) and abs(a0) <= 2 * math.pi):
        return f"angle_min {a0!r} rad, expected a finite angle within +-2 pi"
    if not (math.isfinite(inc) and inc != 0.0 and abs(inc) * (n - 1) <= 2 * math.pi + 1e-6):
        return f"angle_increment {inc!r} rad over {n} beams, expected non-zero with the beams spanning at most 2 pi"
    if not (math.isfinite(range_min) and 0.0 <= range_min < range_max <= MAX_SCAN_RANGE_M):
        return (
            f"range_min {range_min!r}, range_max {range_max!r} m, expected 0 <= range_min < range_max <= "
            f"{MAX_SCAN_RANGE_M}"
        )
    return None


#: Twist-against-pose consistency (:func:`twist_contradiction`): an odometry step "moves" above these (m, rad) ...
TWIST_MOVE_M = 1e-3
TWIST_MOVE_RAD = 1e-3
#: ... the twist "says stationary" where |v| dt and |omega| dt are both below a tenth of them, and a share of moving
#: steps above :data:`TWIST_ZERO_SHARE` with a stationary twist, or a total distance (turn) by the twist outside
#: [1 / TWIST_RATIO, TWIST_RATIO] times the poses' (when they travel at least 1 m, turn at least 1 rad), contradicts.
TWIST_ZERO_SHARE = 0.1
TWIST_RATIO = 2.0


def twist_contradiction(increments: npt.ArrayLike, v: npt.ArrayLike, omega: npt.ArrayLike, dt: npt.ArrayLike) -> str:
    """How an odometry stream's twist contradicts its own pose increments, or "" when it does not.

    ``increments`` (n, 3) are (dx m, dy m, dtheta rad) and ``v`` (m/s), ``omega`` (rad/s), ``dt`` (s) the twist
    reported with each. A driver that leaves the twist at zero (or fills it in another unit or frame) while the pose
    moves is common; a filter that predicts from the twist (``kf_linear``, a twist-given motion model) is then
    wrong by metres, so the loaders say so (the dataset's ``metadata["warnings"]``).
    """
    inc = np.asarray(increments, dtype=np.float64).reshape(-1, 3)
    dt_ = np.asarray(dt, dtype=np.float64)
    s_twist = np.abs(np.asarray(v, dtype=np.float64)) * dt_
    a_twist = np.abs(np.asarray(omega, dtype=np.float64)) * dt_
    s_pose = np.hypot(inc[:, 0], inc[:, 1])
    a_pose = np.abs(inc[:, 2])
    moving = (s_pose > TWIST_MOVE_M) | (a_pose > TWIST_MOVE_RAD)
    still = (s_twist < 0.1 * TWIST_MOVE_M) & (a_twist < 0.1 * TWIST_MOVE_RAD)
    n_moving, n_zero = int(np.sum(moving)), int(np.sum(moving & still))
    problems = []
    if n_moving and n_zero > TWIST_ZERO_SHARE * n_moving:
        problems.append(f"the twist is zero in {n_zero} of the {n_moving} steps in which the pose moves")
    for what, unit, tw, po, least in (
        ("distance", "m", s_twist, s_pose, 1.0),
        ("turn", "rad", a_twist, a_pose, 1.0),
    ):
        total_pose, total_twist = float(np.sum(po)), float(np.sum(tw))
        if total_pose >= least and not (1.0 / TWIST_RATIO <= total_twist / total_pose <= TWIST_RATIO):
            problems.append(
                f"the twist's {what} is {total_twist:.4g} {unit} against the poses' {total_pose:.4g} {unit}"
            )
    if not problems:
        return ""
    return (
        "odometry twist contradicts its pose: " + "; ".join(problems) + " (filters that predict from the twist, such "
        "as kf_linear, will be wrong; check the driver's twist field and its frame)"
    )
