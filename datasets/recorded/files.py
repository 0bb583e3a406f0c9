"""Finding, verifying, fetching and parsing the files of recorded datasets.

Every recorded loader resolves its files through :func:`locate`:

1. the local folder: ``<root>/<relative path>``, where ``root`` is the loader's ``root`` parameter when
   given, else the environment variable ``LOCBENCH_DATA`` (``.ci/run`` points it at ``../shared/datasets``);
2. else, when the file has an official download, the download cache (``LOCBENCH_CACHE``, default
   ``pooch.os_cache("locbench")``), fetched there with pooch and verified by sha256.

A file whose sha256 is known is verified once per (path, size, mtime) in a process, so that a file that
was edited or truncated after it was published is reported as a checksum mismatch rather than parsed.

Errors are :class:`RecordedDataError` (a :class:`~locbench.errors.ConfigError`): the message names the
file, the line (1-based, counting every line of the file) where there is one, and what was expected.
"""

from __future__ import annotations

import hashlib
import os
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from locbench.errors import ConfigError, DataNotFound, DependencyNotInstalled

FloatArray = npt.NDArray[np.float64]

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
        super().__init__(f"{where}: {message}")


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
    p = Path(path)
    try:
        raw = p.read_bytes()
    except FileNotFoundError:
        raise MissingDataFile(p, "missing file") from None
    try:
        text = raw.decode("ascii")
    except UnicodeDecodeError as exc:
        bad_line = raw[: exc.start].count(b"\n") + 1
        what = f"non-ASCII byte {raw[exc.start]:#04x} (expected a numeric text table)"
        raise RecordedDataError(p, what, bad_line) from None
    ncol = len(columns)
    lines = text.split("\n")
    ends_with_newline = text.endswith("\n")
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
                v = float(f)
            except ValueError:
                raise RecordedDataError(
                    p, f"field {j + 1} ({columns[j]}) is {f!r}, expected a number", lineno
                ) from None
            if j in integer_columns and v != int(v):
                raise RecordedDataError(p, f"field {j + 1} ({columns[j]}) is {f!r}, expected an integer", lineno)
            values.append(v)
        rows.append(values)
        numbers.append(lineno)
    arr = np.array(rows, dtype=np.float64).reshape(-1, ncol)
    if not np.all(np.isfinite(arr)):
        r = int(np.flatnonzero(~np.all(np.isfinite(arr), axis=1))[0])
        raise RecordedDataError(p, "non-finite value (expected finite numbers)", numbers[r])
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


def mat_numbers(path: str | os.PathLike[str], mat: Mapping[str, Any], name: str, expected: str) -> FloatArray:
    """Variable ``name`` of a loaded MATLAB file (``scipy.io.loadmat``'s dict) as float64.

    Raises :class:`RecordedDataError` naming the file, the variable and ``expected`` (what the caller wants,
    in words) when the variable is missing, is not real numbers (text, a struct, complex) or holds a
    non-finite value (its 1-based index is given). The shape is the caller's to check.
    """
    if name not in mat:
        have = sorted(k for k in mat if not k.startswith("__"))
        raise RecordedDataError(path, f"variable {name!r}: missing variable, expected {expected} (the file has {have})")
    raw = np.asarray(mat[name])
    if raw.dtype.kind not in "biuf":
        raise RecordedDataError(path, f"variable {name!r}: {raw.dtype} array, expected {expected} of real numbers")
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
