"""The report's output folder: written whole into a temporary sibling, then swapped in by renames.

Every file the report writes is listed in the folder's manifest, :data:`MANIFEST` (its path relative to the
folder, its size in bytes and its sha256). What a manifest lists and still holds those bytes is locbench's: the
next report replaces it. Anything else in the folder (a screenshot, a figure of another tool, a file edited by
hand since) is someone else's: it is never deleted or overwritten; the new folder takes it over as it is, and a
report that would write a file of the same name is refused before anything changes. A folder that is not empty
and has no manifest is refused too (:class:`~locbench.core.errors.ConfigError`), except the summary of a results folder
that ``locbench run`` marked, from before manifests: there the files of the report's own names are its own.

The new summary is written to ``.<name>.tmp-XXXXXXXX`` beside the folder; only when every file is written is
the old folder moved aside (``.<name>.old-XXXXXXXX``), the new one renamed into its place, the other files
carried over and the old folder's own files removed. A failure part-way (a full disk) removes the temporary
folder and leaves the old summary as it was; its error names the file that could not be written.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import re
import shutil
import tempfile
import time
from pathlib import Path
from types import TracebackType

from locbench.core.errors import ConfigError, one_line
from locbench.run.store import MAX_RECORD_BYTES, STALE_AFTER_S, _follow_umask, carry_over, remove_own

#: The manifest of an output folder: the files locbench wrote there, with their sizes and sha256.
MANIFEST = ".locbench-manifest.json"
#: Format of :data:`MANIFEST` (``format`` field); a manifest of another format is not read.
MANIFEST_FORMAT = 1


def _digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _file_digest(path: Path) -> str:
    h = hashlib.sha256()
    with path.open("rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def manifest_bytes(files: dict[str, tuple[int, str]]) -> bytes:
    """The manifest of ``files`` (relative path -> (bytes, sha256)): sorted, so the same files give the same bytes."""
    body = {
        "format": MANIFEST_FORMAT,
        "written_by": "locbench report",
        "files": {rel: {"bytes": n, "sha256": sha} for rel, (n, sha) in sorted(files.items())},
    }
    return (json.dumps(body, indent=1, sort_keys=True) + "\n").encode()


def _safe_relative(rel: object) -> bool:
    """Whether a manifest entry is a plain relative path inside its folder (no ``..``, not absolute)."""
    if not isinstance(rel, str) or not rel or rel.startswith("/") or "\\" in rel or "\0" in rel:
        return False
    return all(part not in ("", ".", "..") for part in rel.split("/"))


def read_manifest(folder: Path) -> dict[str, tuple[int, str]] | None:
    """The files a folder's manifest lists (relative path -> (bytes, sha256)), or None when it has none.

    Raises
    ------
    ConfigError
        The manifest does not parse, or an entry is not a path inside the folder with a size and a sha256.
    """
    path = folder / MANIFEST
    if not os.path.lexists(path):
        return None
    try:
        if not path.is_file() or path.is_symlink() or path.stat().st_size > MAX_RECORD_BYTES:
            raise ValueError(f"not a regular file below {MAX_RECORD_BYTES} bytes")
        data = json.loads(path.read_text(encoding="utf-8"))
        if not isinstance(data, dict) or data.get("format") != MANIFEST_FORMAT or not isinstance(data["files"], dict):
            raise ValueError(f"expected a JSON object of format {MANIFEST_FORMAT} with a 'files' object")
        out: dict[str, tuple[int, str]] = {}
        for rel, entry in data["files"].items():
            if not (_safe_relative(rel) and isinstance(entry, dict) and isinstance(entry.get("bytes"), int)):
                raise ValueError(f"entry {rel!r} is not a relative path with its bytes and sha256")
            out[rel] = (int(entry["bytes"]), str(entry["sha256"]))
    except (OSError, ValueError, KeyError, TypeError, RecursionError) as exc:
        why = f"{path}: not a locbench manifest ({exc}); move the folder away or remove it"
        raise ConfigError(one_line(why)) from None
    return out


def owned(folder: Path, listed: dict[str, tuple[int, str]]) -> frozenset[str]:
    """The files of ``listed`` that ``folder`` holds with the bytes listed (regular files inside the folder): the
    ones locbench may replace. A file changed since, or reached through a symlink, is not among them."""
    root = folder.resolve()
    own = set()
    for rel, (size, sha) in listed.items():
        p = folder / rel
        try:
            if p.is_symlink() or not p.is_file() or not p.resolve().is_relative_to(root):
                continue
            if p.stat().st_size == size and _file_digest(p) == sha:
                own.add(rel)
        except OSError:
            continue
    return frozenset(own)


def _holds_files(folder: Path) -> bool:
    """Whether anything but folders lies under ``folder`` (a folder of empty folders holds nothing to keep)."""
    # os.walk lists a symlink to a folder among the folders, without entering it: it counts as an entry
    return any(files or any(os.path.islink(os.path.join(top, d)) for d in dirs) for top, dirs, files in os.walk(folder))


class OutputFolder:
    """Write a folder whole: :meth:`write` each file, then :meth:`commit` (the manifest and the swap).

    Parameters
    ----------
    final : Path
        The folder to write (it may exist: see the module's rules).
    legacy : bool
        Whether a non-empty ``final`` without a manifest is the report's own from before manifests (the summary
        of a marked results folder): its files of the names this report writes are then replaced.

    Raises
    ------
    ConfigError
        At construction, before anything is computed or written: ``final`` is not empty and has no manifest
        (unless ``legacy``), or its manifest does not parse; a file there is not a folder.
    """

    def __init__(self, final: Path, legacy: bool = False) -> None:
        final = Path(final)
        if final.is_symlink():
            final = final.resolve()  # the folder the link names is replaced, not the link
        self.final = final
        self.legacy = legacy
        self.tmp: Path | None = None
        self.files: dict[str, tuple[int, str]] = {}
        if os.path.lexists(final) and not final.is_dir():
            raise ConfigError(f"{final}: a file is in the way of the report's folder; give a folder")
        if read_manifest(final) is None and _holds_files(final) and not legacy:
            raise ConfigError(
                f"{final}: not empty and not written by 'locbench report' (no {MANIFEST}); give a new or empty "
                "folder, or one 'locbench report' wrote"
            )

    def __enter__(self) -> OutputFolder:
        parent = self.final.parent
        try:
            parent.mkdir(parents=True, exist_ok=True)
            self._clean_leftovers()
            self.tmp = Path(tempfile.mkdtemp(prefix=f".{self.final.name}.tmp-", dir=parent))
        except OSError as exc:  # named after the folder asked for; the new one is made beside it
            reason = f"{exc.strerror or exc} (its new version is written in {parent} first)"
            raise OSError(exc.errno, reason, str(self.final)) from exc
        _follow_umask(self.tmp, is_dir=True)  # mkdtemp makes 0700; the summary is read by others as before
        return self

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        if self.tmp is not None and self.tmp.exists():
            shutil.rmtree(self.tmp, ignore_errors=True)  # ours alone: every file in it was written here

    def _failed(self, exc: OSError, rel: str) -> OSError:
        """The error of a failed write, naming the file of the final folder and saying the old one is intact."""
        reason = exc.strerror or str(exc) or type(exc).__name__
        return OSError(exc.errno, f"{reason}; {self.final} is left as it was", str(self.final / rel))

    def write(self, rel: str, data: bytes) -> Path:
        """Write ``data`` to ``rel`` (a path relative to the folder, ``figures/a.png``) in the temporary folder.

        Returns the path the file will have once committed. An ``OSError`` names that path.
        """
        if self.tmp is None:
            raise RuntimeError("OutputFolder.write outside its 'with' block")
        if not _safe_relative(rel) or rel == MANIFEST:
            raise ValueError(f"{rel!r}: not a file name the report may write")
        if rel in self.files:
            raise ValueError(f"{rel!r} written twice")
        target = self.tmp / rel
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
            write_file(target, data)
        except OSError as exc:
            raise self._failed(exc, rel) from exc
        self.files[rel] = (len(data), _digest(data))
        return self.final / rel

    def _own(self, folder: Path) -> frozenset[str]:
        """What of ``folder`` locbench may replace: its manifest's files that still hold their bytes (and the
        manifest), or, in a legacy summary, the files of the names this report writes."""
        listed = read_manifest(folder)
        if listed is None:
            if not self.legacy:
                return frozenset()
            return frozenset(rel for rel in self.files if (folder / rel).is_file() and not (folder / rel).is_symlink())
        return owned(folder, listed) | {MANIFEST}

    def _conflicts(self, own: frozenset[str]) -> list[Path]:
        """The entries of the final folder the new files would overwrite that are not locbench's."""
        out = []
        for rel in self.files:
            parts = rel.split("/")
            for i in range(1, len(parts)):  # a folder of the new files must be a plain folder there
                p = self.final.joinpath(*parts[:i])
                if os.path.lexists(p) and (p.is_symlink() or not p.is_dir()):
                    out.append(p)
            p = self.final / rel
            if os.path.lexists(p) and rel not in own:
                out.append(p)
        return sorted(set(out))

    def commit(self) -> None:
        """Write the manifest, then swap the new folder in (see the module's docstring).

        Raises
        ------
        ConfigError
            A file the report writes exists in the folder and is not locbench's (nothing is changed).
        OSError
            The manifest could not be written, or a rename failed (the old folder is then in place).
        """
        if self.tmp is None:
            raise RuntimeError("OutputFolder.commit outside its 'with' block")
        try:
            write_file(self.tmp / MANIFEST, manifest_bytes(self.files))
        except OSError as exc:
            raise self._failed(exc, MANIFEST) from exc
        if not self.final.is_dir():
            self.tmp.rename(self.final)
            return
        conflicts = self._conflicts(self._own(self.final))
        if conflicts:
            more = f" and {len(conflicts) - 1} more" if len(conflicts) > 1 else ""
            raise ConfigError(
                f"{conflicts[0]}{more}: not written by 'locbench report' (not in {MANIFEST} with these bytes); "
                f"move it away to write the report in {self.final}"
            )
        aside = Path(tempfile.mkdtemp(prefix=f".{self.final.name}.old-", dir=self.final.parent))
        aside.rmdir()  # a unique name for the old folder, free again for the rename
        self.final.rename(aside)
        try:
            self.tmp.rename(self.final)
        except OSError:
            aside.rename(self.final)  # the old summary back in place, untouched
            raise
        own = self._own(aside)
        left = carry_over(aside, self.final, own)
        if not remove_own(aside, own):
            raise OSError(
                errno.EEXIST,
                f"kept: it holds files locbench did not write whose names the new report took meanwhile ({left})",
                str(aside),
            )

    def _clean_leftovers(self) -> None:
        """Remove what an interrupted report left beside the folder: temporary folders (everything in one was
        written by the report) and moved-aside old folders' own files, older than :data:`STALE_AFTER_S`."""
        name = re.escape(self.final.name)
        pattern = re.compile(rf"^\.{name}\.(tmp|old)-[A-Za-z0-9_]{{8}}$")
        now = time.time()
        for p in self.final.parent.glob(f".{self.final.name}.*-*"):
            m = pattern.match(p.name)
            try:
                if m is None or p.is_symlink() or not p.is_dir() or now - p.lstat().st_mtime < STALE_AFTER_S:
                    continue
                if m.group(1) == "tmp":
                    shutil.rmtree(p)
                else:
                    listed = read_manifest(p) or {}
                    remove_own(p, owned(p, listed) | {MANIFEST})
            except (OSError, ConfigError):
                continue  # another report's, or not ours to judge: left alone


def write_file(path: Path, data: bytes) -> None:
    """Write one file of the report (the one place the report's bytes reach the disk)."""
    path.write_bytes(data)


__all__ = ["MANIFEST", "OutputFolder", "manifest_bytes", "owned", "read_manifest", "write_file"]
