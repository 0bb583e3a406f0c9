"""Reading and writing stored runs under ``<results>/runs/``.

Layout (one folder per dataset name, then per filter name, then per seed)::

    runs/<dataset name>/_truth/seed-<seed>.npz        ground truth, waypoints, kidnaps of that realisation
    runs/<dataset name>/_truth/seed-<seed>.json       its provenance (dataset params, seed, versions)
    runs/<dataset name>/<filter name>/seed-<seed>/meta.json       spec, run key, status, versions, commit
    runs/<dataset name>/<filter name>/seed-<seed>/estimates.npz   per-event estimates and timings

Every folder is written to a temporary sibling and renamed into place, so a crash never leaves a
half-written run behind. Names are the canonical specs (``room[kidnap_m=2]``); a spec that is not a safe
folder name is sanitised and given a hash of the full spec (:func:`_safe`), so two specs never share a folder.
"""

from __future__ import annotations

import errno
import functools
import hashlib
import json
import os
import re
import shutil
import tempfile
import time
import uuid
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from locbench.datasets.base import Dataset, Kidnap, Relations, Trajectory2D, Waypoints
from locbench.errors import ConfigError
from locbench.spec import Spec

FloatArray = npt.NDArray[np.float64]

TRUTH_DIR = "_truth"
#: Event kinds stored in ``RunRecord.kind``: the index into this tuple.
# Codes are stored in runs: append new kinds at the end, never reorder.
KIND_NAMES = ("Odometry", "LaserScan", "LandmarkObservations", "PoseFix", "reset", "RangeObservations")
STATUSES = ("ok", "skipped", "diverged", "error")


#: Longest folder name written (POSIX allows 255 bytes; room is left for the ".old-" and ".tmp-" variants).
_MAX_NAME_BYTES = 200
#: Characters a folder name cannot hold on POSIX or Windows, or that would make it hidden or relative.
_UNSAFE = re.compile(r'[\x00-\x1f/\\:*?"<>|]')
#: Hex digits of the sha256 suffix that keeps sanitised names apart (16, as long names always had).
_HASH_CHARS = 16
#: A run folder, exactly (``seed-0000.old`` or ``seed-0000.tmp`` are not runs).
_SEED_DIR = re.compile(r"^seed-\d{4,}$")
#: Leftovers of an interrupted write older than this are removed when a sweep starts, s (a write in
#: progress lives for a fraction of a second, so another process's temporary folder is never taken).
STALE_AFTER_S = 600.0


def _safe(name: str) -> str:
    """The folder name of a spec: the spec itself when it is a safe name, else sanitised plus a hash.

    A name that holds a character a file system reserves (``/``, ``\\``, ``:``, control characters ...),
    or is longer than :data:`_MAX_NAME_BYTES`, is sanitised (each such character becomes ``_``, the name is
    cut) and given ``~`` and the first :data:`_HASH_CHARS` hex digits of the sha256 of the full name, so
    two specs never share a folder (``path=/x/y.bag`` and ``path=/x_y.bag``); a plain name such as
    ``room[kidnap_m=2]`` is its own folder name, unchanged. ``meta.json`` keeps the full name.
    """
    safe = _UNSAFE.sub("_", name)
    if safe.startswith("."):
        safe = "_" + safe[1:]
    raw = safe.encode()
    if safe == name and len(raw) <= _MAX_NAME_BYTES:
        return name
    digest = hashlib.sha256(name.encode()).hexdigest()[:_HASH_CHARS]
    head = raw[: _MAX_NAME_BYTES - _HASH_CHARS - 1].decode(errors="ignore")
    return f"{head}~{digest}"


@functools.cache
def _umask() -> int:
    """The process's umask (read once: setting it is the only way to read it)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _follow_umask(path: Path, is_dir: bool) -> None:
    """Give a file or folder made by ``mkstemp``/``mkdtemp`` (0600/0700) the mode the user's umask asks for."""
    os.chmod(path, (0o777 if is_dir else 0o666) & ~_umask())


@dataclass(eq=False)
class TruthRecord:
    """The ground truth of one dataset realisation, as metrics need it."""

    dataset: str
    seed: int
    ground_truth: Trajectory2D
    waypoints: Waypoints | None
    kidnaps: tuple[Kidnap, ...]
    duration_s: float
    meta: dict[str, Any] = field(default_factory=dict)
    #: The world's line segments (n, 4) and landmark positions (m, 2), m, for figures; empty when absent.
    map_segments: FloatArray = field(default_factory=lambda: np.zeros((0, 4)))
    map_landmarks: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    #: Reference relative poses (Intel), and what the trajectory is ("ground truth" or "SLAM reference").
    relations: Relations | None = None
    truth_label: str = "ground truth"

    @classmethod
    def from_dataset(cls, ds: Dataset, seed: int, meta: dict[str, Any]) -> TruthRecord:
        w = ds.world
        segs = w.lines.segments if w.lines is not None else np.zeros((0, 4))
        lms = w.landmarks.xy if w.landmarks is not None else np.zeros((0, 2))
        return cls(
            ds.name or ds.id,
            seed,
            ds.ground_truth,
            ds.waypoints,
            ds.kidnaps,
            ds.duration,
            meta,
            segs,
            lms,
            ds.relations,
            ds.truth_label,
        )


@dataclass(eq=False)
class BoundRecord:
    """The posterior Cramer-Rao bound of one synthetic realisation (:func:`locbench.pcrb.bound_covariances`).

    Attributes
    ----------
    dataset, seed : str, int
        The realisation.
    t : ndarray, shape (n,)
        Ground-truth times, s.
    covs : dict of str to ndarray, shape (n, 3, 3)
        The bound's pose covariance at each time by row name (m^2, rad^2; world frame).
    meta : dict
        ``bound_key`` (what the bound was computed from), ``compute_s``, ``versions``.
    """

    dataset: str
    seed: int
    t: FloatArray
    covs: dict[str, FloatArray]
    meta: dict[str, Any] = field(default_factory=dict)


@dataclass(eq=False)
class RunRecord:
    """One (filter, dataset, seed) run.

    Attributes
    ----------
    meta : dict
        ``filter``, ``filter_id``, ``filter_config``, ``dataset``, ``dataset_id``, ``dataset_params``,
        ``seed``, ``run_key``, ``status`` (one of ok, skipped, diverged, error), ``message``,
        ``diverged_t``, ``versions``, ``git_commit``, ``git_dirty``, ``wall_s``, ``started``.
    t : ndarray, shape (n,)
        Time of each recorded estimate, s (the event it followed; the first row is the reset belief).
    mean : ndarray, shape (n, 3)
        Estimated pose after each event.
    cov : ndarray, shape (n, 3, 3)
        Its covariance.
    kind : ndarray of int8, shape (n,)
        Index into :data:`KIND_NAMES` of the event that produced the row.
    step_ns : ndarray of int64, shape (n,)
        Time of the ``predict``/``update`` call for that row, ns (0 for the reset row).
    diagnostics : dict of str to ndarray (n,)
        Per-row filter diagnostics, NaN where absent.
    extra : dict of str to ndarray
        Filter-specific arrays (e.g. ``smoothed_t``, ``smoothed_mean`` of a smoother).
    health : dict of str to ndarray (n,)
        Per-row :meth:`Filter.health` signals, NaN where absent.
    """

    meta: dict[str, Any]
    t: FloatArray
    mean: FloatArray
    cov: FloatArray
    kind: npt.NDArray[np.int8]
    step_ns: npt.NDArray[np.int64]
    diagnostics: dict[str, FloatArray] = field(default_factory=dict)
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    health: dict[str, FloatArray] = field(default_factory=dict)

    @property
    def status(self) -> str:
        return str(self.meta.get("status", "error"))

    def step_times_us(self, kind_name: str) -> FloatArray:
        """Per-call times in microseconds of the rows of one kind ('predict' = Odometry, 'update' = the rest)."""
        if kind_name == "predict":
            sel = self.kind == KIND_NAMES.index("Odometry")
        elif kind_name == "update":
            sel = (self.kind != KIND_NAMES.index("Odometry")) & (self.kind != KIND_NAMES.index("reset"))
        else:
            sel = self.kind == KIND_NAMES.index(kind_name)
        return self.step_ns[sel].astype(np.float64) / 1e3


class Store:
    """The results folder: ``root/runs`` for raw runs and ``root/summary`` for tables and figures."""

    def __init__(self, root: str | os.PathLike[str]) -> None:
        self.root = Path(root)
        self.runs = self.root / "runs"
        self.summary = self.root / "summary"

    # --- paths ---------------------------------------------------------------------------------
    def run_dir(self, dataset: str | Spec, filter_name: str | Spec, seed: int) -> Path:
        """The folder of one run; ``dataset`` and ``filter_name`` are canonical names or :class:`Spec` values."""
        return self.runs / _safe(str(dataset)) / _safe(str(filter_name)) / f"seed-{seed:04d}"

    def truth_path(self, dataset: str | Spec, seed: int) -> Path:
        return self.runs / _safe(str(dataset)) / TRUTH_DIR / f"seed-{seed:04d}.npz"

    def bound_path(self, dataset: str | Spec, seed: int) -> Path:
        return self.runs / _safe(str(dataset)) / TRUTH_DIR / f"seed-{seed:04d}.bound.npz"

    # --- queries -------------------------------------------------------------------------------
    def existing_meta(self, dataset: str | Spec, filter_name: str | Spec, seed: int) -> dict[str, Any] | None:
        """The ``meta.json`` of a stored run, or None when there is none or it does not parse."""
        meta = self.run_dir(dataset, filter_name, seed) / "meta.json"
        try:
            data = json.loads(meta.read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError, UnicodeDecodeError):
            return None
        return data if isinstance(data, dict) else None

    def existing_key(self, dataset: str | Spec, filter_name: str | Spec, seed: int) -> str | None:
        """The run key of a finished stored run, or None."""
        meta = self.existing_meta(dataset, filter_name, seed)
        return None if meta is None or "run_key" not in meta else str(meta["run_key"])

    def sample_meta(self, dataset: str | Spec, filter_name: str | Spec) -> dict[str, Any] | None:
        """The ``meta.json`` of one stored seed of (dataset, filter), the lowest, or None (for timing estimates)."""
        folder = self.run_dir(dataset, filter_name, 0).parent
        try:
            seeds = sorted(p.name for p in folder.iterdir() if _SEED_DIR.match(p.name))
        except OSError:
            return None
        for name in seeds:
            meta = self.existing_meta(dataset, filter_name, int(name[5:]))
            if meta is not None:
                return meta
        return None

    def unreadable(self, dataset: str | Spec, filter_name: str | Spec, seed: int) -> str | None:
        """Why a stored run's files do not load (it is then re-run), or None when they do.

        Opens ``estimates.npz`` (its zip directory, which a truncated or overwritten file lacks) and checks
        the arrays every run has are listed; ``meta.json`` was read by :meth:`existing_meta`.
        """
        est = self.run_dir(dataset, filter_name, seed) / "estimates.npz"
        try:
            with zipfile.ZipFile(est) as z:
                names = set(z.namelist())
        except (OSError, zipfile.BadZipFile, EOFError) as exc:
            return f"{est}: {exc}"
        missing = sorted({"t.npy", "mean.npy", "cov.npy", "kind.npy", "step_ns.npy"} - names)
        return f"{est}: missing {', '.join(missing)}" if missing else None

    def has_truth(self, dataset: str | Spec, seed: int) -> bool:
        return self.truth_path(dataset, seed).is_file()

    def bound_key(self, dataset: str | Spec, seed: int) -> str | None:
        """The ``bound_key`` of a stored bound, or None when there is none or its record does not parse."""
        try:
            meta = json.loads(self.bound_path(dataset, seed).with_suffix(".json").read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError, UnicodeDecodeError):
            return None
        key = meta.get("bound_key") if isinstance(meta, dict) else None
        return str(key) if key is not None and self.bound_path(dataset, seed).is_file() else None

    def iter_runs(self) -> Iterator[Path]:
        """Every stored run folder, sorted (leftover ``.tmp-*`` and ``*.old-*`` entries are not runs)."""
        if not self.runs.is_dir():
            return
        for meta in sorted(self.runs.glob("*/*/seed-*/meta.json")):
            run = meta.parent
            if run.parent.name != TRUTH_DIR and _SEED_DIR.match(run.name) and not run.parent.name.startswith("."):
                yield run

    def clean_leftovers(self, older_than_s: float = STALE_AFTER_S) -> list[Path]:
        """Remove temporary and replaced entries an interrupted write left behind; returns what was removed.

        Only entries older than ``older_than_s`` go, so another process's write in progress is left alone.
        """
        removed: list[Path] = []
        if not self.runs.is_dir():
            return removed
        now = time.time()
        for pattern in ("*/*/.tmp-*", "*/*/*.old*"):
            for p in self.runs.glob(pattern):
                try:
                    if now - p.lstat().st_mtime < older_than_s:
                        continue
                    if p.is_dir() and not p.is_symlink():
                        shutil.rmtree(p)
                    else:
                        p.unlink()
                except FileNotFoundError:
                    continue  # another process cleaned it first
                removed.append(p)
        return removed

    # --- writing -------------------------------------------------------------------------------
    def check_writable(self) -> None:
        """Raise the ``OSError`` a write into ``runs/`` would meet (no permission, read-only, a file in the way)."""
        _makedirs(self.runs)
        fd, name = tempfile.mkstemp(prefix=".tmp-", dir=self.runs)
        os.close(fd)
        os.unlink(name)

    def write_truth(self, rec: TruthRecord) -> None:
        path = self.truth_path(rec.dataset, rec.seed)
        _makedirs(path.parent)
        wp_t = rec.waypoints.t if rec.waypoints is not None else np.zeros(0)
        wp_xy = rec.waypoints.xy if rec.waypoints is not None else np.zeros((0, 2))
        arrays = {
            "gt_t": rec.ground_truth.t,
            "gt_xy": rec.ground_truth.xy,
            "gt_theta": rec.ground_truth.theta,
            "wp_t": wp_t,
            "wp_xy": wp_xy,
            "has_waypoints": np.array(rec.waypoints is not None),
            "kidnap_t": np.array([k.t for k in rec.kidnaps], dtype=np.float64),
            "kidnap_delta": np.array([k.delta for k in rec.kidnaps], dtype=np.float64).reshape(-1, 3),
            "duration_s": np.array(rec.duration_s),
            "map_segments": np.asarray(rec.map_segments, dtype=np.float64).reshape(-1, 4),
            "map_landmarks": np.asarray(rec.map_landmarks, dtype=np.float64).reshape(-1, 2),
        }
        if rec.relations is not None:
            arrays.update(rel_t1=rec.relations.t1, rel_t2=rec.relations.t2, rel_delta=rec.relations.delta)
        meta = {"dataset": rec.dataset, "seed": rec.seed, "truth_label": rec.truth_label, **rec.meta}
        _atomic_write(path, lambda p: np.savez_compressed(p, **arrays))  # type: ignore[arg-type]
        _atomic_write(path.with_suffix(".json"), lambda p: p.write_text(json.dumps(meta, indent=2, default=str)))

    def write_bound(self, rec: BoundRecord) -> None:
        """Write a realisation's bound beside its truth (arrays first, then the record that names them)."""
        path = self.bound_path(rec.dataset, rec.seed)
        _makedirs(path.parent)
        names = sorted(rec.covs)
        arrays = {"t": rec.t} | {f"cov_{i}": rec.covs[n] for i, n in enumerate(names)}
        meta = {"dataset": rec.dataset, "seed": rec.seed, "rows": names, **rec.meta}
        _atomic_write(path, lambda p: np.savez_compressed(p, **arrays))  # type: ignore[arg-type]
        _atomic_write(path.with_suffix(".json"), lambda p: p.write_text(json.dumps(meta, indent=2, default=str)))

    def write_run(self, rec: RunRecord) -> Path:
        """Write a run folder atomically: a uniquely named temporary folder, then renamed into place.

        Several processes may write the same run at once (two sweeps on one results folder): each moves the
        folder in place aside under a unique ``.old-`` name before its rename and retries when another writer
        got in between, so none fails and the folder always holds one complete run. An ``OSError`` (disk
        full, read-only folder) propagates with nothing half-written left behind.
        """
        final = self.run_dir(rec.meta["dataset"], rec.meta["filter"], int(rec.meta["seed"]))
        _makedirs(final.parent)
        tmp = Path(tempfile.mkdtemp(prefix=".tmp-", dir=final.parent))
        try:
            _follow_umask(tmp, is_dir=True)
            arrays: dict[str, np.ndarray] = {
                "t": rec.t,
                "mean": rec.mean,
                "cov": rec.cov,
                "kind": rec.kind,
                "step_ns": rec.step_ns,
            }
            arrays.update({f"diag_{k}": v for k, v in rec.diagnostics.items()})
            arrays.update({f"extra_{k}": v for k, v in rec.extra.items()})
            arrays.update({f"health_{k}": v for k, v in rec.health.items()})
            np.savez_compressed(tmp / "estimates.npz", **arrays)  # type: ignore[arg-type]
            (tmp / "meta.json").write_text(json.dumps(rec.meta, indent=2, default=str))
            _swap_into_place(tmp, final)
        finally:
            if tmp.exists():
                shutil.rmtree(tmp, ignore_errors=True)
        return final

    # --- reading -------------------------------------------------------------------------------
    def read_truth(self, dataset: str, seed: int) -> TruthRecord:
        path = self.truth_path(dataset, seed)
        if not path.is_file():
            raise ConfigError(
                f"{path}: missing ground truth for dataset {dataset!r} seed {seed}; re-run 'locbench run'"
            )
        with np.load(path) as z:
            gt = Trajectory2D(z["gt_t"], z["gt_xy"], z["gt_theta"])
            wp = Waypoints(z["wp_t"], z["wp_xy"]) if bool(z["has_waypoints"]) else None
            kid = tuple(
                Kidnap(float(t), (float(d[0]), float(d[1]), float(d[2])))
                for t, d in zip(z["kidnap_t"], z["kidnap_delta"], strict=True)
            )
            duration = float(z["duration_s"])
            segs = z["map_segments"] if "map_segments" in z.files else np.zeros((0, 4))
            lms = z["map_landmarks"] if "map_landmarks" in z.files else np.zeros((0, 2))
            rel = Relations(z["rel_t1"], z["rel_t2"], z["rel_delta"]) if "rel_t1" in z.files else None
        meta_path = path.with_suffix(".json")
        meta = json.loads(meta_path.read_text()) if meta_path.is_file() else {}
        label = str(meta.get("truth_label", "ground truth"))
        return TruthRecord(dataset, seed, gt, wp, kid, duration, meta, segs, lms, rel, label)

    def read_bound(self, dataset: str, seed: int) -> BoundRecord | None:
        """The stored bound of a realisation, or None when it has none (recorded data, kidnaps, not computed)."""
        path = self.bound_path(dataset, seed)
        meta_path = path.with_suffix(".json")
        if not (path.is_file() and meta_path.is_file()):
            return None
        try:
            meta = json.loads(meta_path.read_text(encoding="utf-8"))
            names = [str(n) for n in meta["rows"]]
        except (OSError, json.JSONDecodeError, UnicodeDecodeError, KeyError, TypeError) as exc:
            raise ConfigError(f"{meta_path}: unreadable bound record ({exc}); re-run 'locbench run'") from None
        with np.load(path) as z:
            covs = {n: z[f"cov_{i}"] for i, n in enumerate(names)}
            return BoundRecord(dataset, seed, z["t"], covs, meta)

    def read_run(self, run_dir: str | os.PathLike[str]) -> RunRecord:
        d = Path(run_dir)
        try:
            meta = json.loads((d / "meta.json").read_text())
        except (OSError, json.JSONDecodeError) as exc:
            raise ConfigError(f"{d / 'meta.json'}: unreadable run record ({exc})") from None
        est = d / "estimates.npz"
        if not est.is_file():
            raise ConfigError(f"{est}: missing estimates for a stored run; re-run with --force")
        with np.load(est) as z:
            diag = {k[5:]: z[k] for k in z.files if k.startswith("diag_")}
            extra = {k[6:]: z[k] for k in z.files if k.startswith("extra_")}
            health = {k[7:]: z[k] for k in z.files if k.startswith("health_")}
            return RunRecord(meta, z["t"], z["mean"], z["cov"], z["kind"], z["step_ns"], diag, extra, health)


def _makedirs(path: Path) -> None:
    """``mkdir -p`` that names the folder in its error (a file in the way, no permission)."""
    try:
        path.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise NotADirectoryError(errno.ENOTDIR, "a file is in the way of a results folder", str(path)) from None


#: Attempts of the move-aside-and-rename loop before giving up (each is a rename that another writer won).
_SWAP_ATTEMPTS = 100


def _swap_into_place(tmp: Path, final: Path) -> None:
    """Rename folder ``tmp`` to ``final``, moving any folder already there aside (unique name) and removing it."""
    for _ in range(_SWAP_ATTEMPTS):
        try:
            tmp.rename(final)
            return
        except OSError as exc:
            if exc.errno not in (errno.ENOTEMPTY, errno.EEXIST, errno.EISDIR):
                raise
        old = final.with_name(f"{final.name}.old-{uuid.uuid4().hex[:12]}")
        try:
            final.rename(old)
        except FileNotFoundError:
            continue  # another writer moved it away first: try our rename again
        shutil.rmtree(old, ignore_errors=True)
    raise OSError(errno.EBUSY, f"could not replace the run folder after {_SWAP_ATTEMPTS} attempts", str(final))


def _atomic_write(path: Path, writer: Any) -> None:
    """Write via a uniquely named temporary file in the same folder, then rename (no half-written files)."""
    fd, tmp_name = tempfile.mkstemp(prefix=".tmp-", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        _follow_umask(tmp, is_dir=False)
        writer(tmp)
        tmp.replace(path)
    finally:
        if tmp.exists():
            tmp.unlink()
