"""Reading and writing stored runs under ``<results>/runs/``.

Layout (one folder per dataset name, then per filter name, then per seed)::

    runs/<dataset name>/_truth/seed-<seed>.npz        ground truth, waypoints, kidnaps of that realisation
    runs/<dataset name>/_truth/seed-<seed>.json       its provenance (dataset params, seed, versions)
    runs/<dataset name>/<filter name>/seed-<seed>/meta.json       spec, run key, status, versions, commit
    runs/<dataset name>/<filter name>/seed-<seed>/estimates.npz   per-event estimates and timings
    runs/<dataset name>/<filter name>/seed-<seed>/derived.npz     its metrics, NEES and health series (ok runs)

    .locbench                                             the mark of a locbench results folder

The records (:mod:`locbench.evaluate.records`) are written and read here. Every folder is written to a temporary
sibling and renamed into place, so a crash never leaves a half-written run behind. Each JSON record holds the
sha256 of the arrays it names (``files``) and of itself (``meta_sha256``); a record whose file fails its checksum
or its shape contract (:func:`run_problem`, :func:`truth_problem`, :func:`bound_problem`) is stale: the sweep runs
it again and the report leaves it out, listed with the reason. Records written before checksums (no ``files``) are
checked against the contract only. Names are the canonical specs (``room[kidnap_m=2]``); a spec that is not a safe
folder name is sanitised and given a hash of the full spec (:func:`_safe`), so two specs never share a folder.
"""

from __future__ import annotations

import contextlib
import errno
import functools
import hashlib
import io
import json
import logging
import math
import os
import re
import shutil
import tempfile
import time
import uuid
import zipfile
import zlib
from collections.abc import Collection, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from locbench.core.errors import ConfigError, one_line
from locbench.core.spec import Spec
from locbench.datasets.dataset import Kidnap, Relations, Trajectory2D, Waypoints
from locbench.evaluate.records import KIND_NAMES, STATUSES, BoundRecord, RunRecord, TruthRecord

if TYPE_CHECKING:
    from locbench.evaluate.derived import Derived

log = logging.getLogger(__name__)

TRUTH_DIR = "_truth"
#: A run's derived values for the report (:mod:`locbench.evaluate.derived`), beside its estimates.
DERIVED_FILE = "derived.npz"
#: The files locbench writes in a run folder: ``meta.json`` names ``estimates.npz`` and its sha256 (``files``);
#: ``derived.npz`` names that sha256 too. Anything else a run folder holds is someone else's: replacing the run
#: carries it over into the new folder.
RUN_FILES = frozenset({"meta.json", "estimates.npz", DERIVED_FILE})


#: Longest folder name written (POSIX allows 255 bytes; room is left for the ".old-" and ".tmp-" variants).
_MAX_NAME_BYTES = 200
#: Characters a folder name cannot hold on POSIX or Windows, or that would make it hidden or relative.
_UNSAFE = re.compile(r'[\x00-\x1f/\\:*?"<>|]')
#: Hex digits of the sha256 suffix that keeps sanitised names apart (16, as long names always had).
_HASH_CHARS = 16
#: A run folder, exactly (``seed-0000.old`` or ``seed-0000.tmp`` are not runs).
_SEED_DIR = re.compile(r"^seed-\d{4,}$")
#: Temporary entries this module creates: ``mkstemp``/``mkdtemp`` names with our prefix (8 random characters,
#: then the suffix of the file written), and run folders moved aside (``seed-0001.old-<12 hex>``).
_TMP_NAME = re.compile(r"^\.tmp-[A-Za-z0-9_]{8}(\.npz|\.json)?$")
_OLD_NAME = re.compile(r"^seed-\d{4,}\.old-[0-9a-f]{12}$")
#: The file that marks a results folder as locbench's (written when ``locbench run`` creates or first fills it).
MARKER = ".locbench"
#: Free space a sweep needs before it computes anything: a floor and an allowance per run, bytes (a stored
#: run of the synthetic worlds takes 0.1-0.3 MB, a recorded one up to a few MB).
MIN_FREE_BYTES = 64 * 2**20
FREE_BYTES_PER_RUN = 2**20
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

        Only entries under ``runs/<dataset>/<folder>/`` whose names this module creates (:data:`_TMP_NAME`,
        :data:`_OLD_NAME`) and older than ``older_than_s`` go, so another process's write in progress is left
        alone; of a folder, only the files locbench writes there (:data:`RUN_FILES`) go, and the folder only
        when nothing else is left in it.
        """
        removed: list[Path] = []
        if not self.runs.is_dir():
            return removed
        now = time.time()
        for pattern, name in (("*/*/.tmp-*", _TMP_NAME), ("*/*/seed-*.old-*", _OLD_NAME)):
            for p in self.runs.glob(pattern):
                if not name.match(p.name) or p.parent.name.startswith("."):
                    continue  # only names this module creates, only under runs/<dataset>/<filter or _truth>/
                try:
                    if now - p.lstat().st_mtime < older_than_s:
                        continue
                    if p.is_dir() and not p.is_symlink():
                        if not remove_own(p, RUN_FILES):
                            continue  # it still holds a file locbench did not write: kept
                    else:
                        p.unlink()
                except FileNotFoundError:
                    continue  # another process cleaned it first
                removed.append(p)
        return removed

    # --- writing -------------------------------------------------------------------------------
    def claim(self) -> None:
        """Mark the results folder as locbench's, creating it; refuse a non-empty folder without the mark.

        A folder that exists, holds anything and has no :data:`MARKER` belongs to someone else (another tool's
        project): nothing is written or cleaned in it (:class:`ConfigError`).
        """
        marker = self.root / MARKER
        if marker.is_file():
            _makedirs(self.runs)  # a concurrent claimer may not have made it yet
            return
        if self.root.exists() and not self.root.is_dir():
            raise NotADirectoryError(errno.ENOTDIR, os.strerror(errno.ENOTDIR), str(self.root))
        # The mark is the first thing written into a new folder, so another locbench process claiming the same
        # folder at once (the tuned suite's studies share results/tuning) has written it before anything else:
        # a folder seen non-empty is ours if the mark is there by now.
        if self.root.is_dir() and any(self.root.iterdir()) and not marker.is_file():
            raise ConfigError(
                f"{self.root}: not empty and not a locbench results folder (no {MARKER} file); give a new or "
                f"empty folder, or add the file {MARKER} if this folder is one"
            )
        if not self.root.is_dir():
            _makedirs(self.root)
        created = False
        try:
            fd = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666)
        except FileExistsError:
            pass  # claimed by another process meanwhile
        else:
            created = True
            with os.fdopen(fd, "w") as fh:
                fh.write("locbench results folder: runs/ and summary/ are written by locbench\n")
        try:
            _makedirs(self.runs)
        except BaseException:
            if created:  # nothing of ours is left in a folder we cannot write into
                marker.unlink(missing_ok=True)
            raise

    def check_space(self, runs: int) -> None:
        """Raise ``OSError(ENOSPC)`` when the results folder's disk has less room than ``runs`` new runs need
        (:data:`MIN_FREE_BYTES` + :data:`FREE_BYTES_PER_RUN` each), before anything is computed."""
        need = MIN_FREE_BYTES + FREE_BYTES_PER_RUN * max(runs, 0)
        free = shutil.disk_usage(self.runs).free
        if free < need:
            raise OSError(
                errno.ENOSPC,
                f"{free / 2**20:.0f} MB free, {need / 2**20:.0f} MB needed for {runs} run(s) (1 MB each and 64 MB)",
                str(self.runs),
            )

    def check_writable(self) -> None:
        """Raise the ``OSError`` a write into ``runs/`` would meet (no permission, read-only, a file in the way)."""
        _makedirs(self.runs)
        fd, name = tempfile.mkstemp(prefix=".tmp-", dir=self.runs)
        os.close(fd)
        os.unlink(name)

    def write_truth(self, rec: TruthRecord) -> None:
        path = self.truth_path(rec.dataset, rec.seed)
        _makedirs(path.parent)
        _write_npz_and_record(path, truth_arrays(rec), truth_meta(rec))

    def write_bound(self, rec: BoundRecord) -> None:
        """Write a realisation's bound beside its truth (arrays first, then the record that names them)."""
        path = self.bound_path(rec.dataset, rec.seed)
        _makedirs(path.parent)
        meta = {"dataset": rec.dataset, "seed": rec.seed, "rows": sorted(rec.covs), **rec.meta}
        _write_npz_and_record(path, bound_arrays(rec), meta)

    def write_run(self, rec: RunRecord, derived: tuple[Derived, str] | None = None) -> Path:
        """Write a run folder atomically: a uniquely named temporary folder, then renamed into place.

        ``derived``, the run's derived values and the :func:`~locbench.evaluate.derived.truth_digest` of the truth
        they were computed against, are written beside the estimates (``derived.npz``, keyed by the estimates'
        checksum, that truth and :func:`~locbench.evaluate.derived.code_digest`): the report takes them from there.

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
            # stored, not deflated: zlib took 40 ms of the sweep's main process per run against 3 ms, for files
            # half the size; the checksums are of the members, so both kinds read alike
            np.savez(tmp / "estimates.npz", **arrays)  # type: ignore[arg-type]
            digest = npz_digest(tmp / "estimates.npz")
            meta = _sealed(rec.meta | {"files": {"estimates.npz": digest}})
            (tmp / "meta.json").write_text(json.dumps(meta, indent=2))
            if derived is not None:
                np.savez(tmp / DERIVED_FILE, **derived_arrays(derived[0], digest, derived[1]))  # type: ignore[arg-type]
            _swap_into_place(tmp, final)
        finally:
            if tmp.exists():
                shutil.rmtree(tmp, ignore_errors=True)
        return final

    # --- reading -------------------------------------------------------------------------------
    def read_truth(self, dataset: str, seed: int) -> TruthRecord:
        """The stored truth of a realisation, verified (:func:`truth_problem`); a :class:`StaleRecord` otherwise."""
        path = self.truth_path(dataset, seed)
        if not path.is_file():
            raise ConfigError(
                f"{path}: missing ground truth for dataset {dataset!r} seed {seed}; re-run 'locbench run'"
            )
        meta, z = _load_verified(path, path.with_suffix(".json"), truth_problem, required_record=False)
        gt = Trajectory2D(z["gt_t"], z["gt_xy"], z["gt_theta"])
        wp = Waypoints(z["wp_t"], z["wp_xy"]) if bool(z["has_waypoints"]) else None
        kid = tuple(
            Kidnap(float(t), (float(d[0]), float(d[1]), float(d[2])))
            for t, d in zip(z["kidnap_t"], z["kidnap_delta"], strict=True)
        )
        duration = float(z["duration_s"])
        segs = z.get("map_segments", np.zeros((0, 4)))
        lms = z.get("map_landmarks", np.zeros((0, 2)))
        rel = Relations(z["rel_t1"], z["rel_t2"], z["rel_delta"]) if "rel_t1" in z else None
        label = str(meta.get("truth_label", "ground truth"))
        return TruthRecord(dataset, seed, gt, wp, kid, duration, meta, segs, lms, rel, label)

    def truth_problem(self, dataset: str | Spec, seed: int) -> str | None:
        """Why the stored truth of a realisation is missing or stale (its runs are then re-run), or None."""
        path = self.truth_path(dataset, seed)
        if not path.is_file():
            return f"{path}: missing"
        try:
            _load_verified(path, path.with_suffix(".json"), truth_problem, required_record=False)
        except ConfigError as exc:
            return str(exc)
        return None

    def truth_files(self, dataset: str | Spec, seed: int) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """The stored truth's record and arrays as stored, after every check (:func:`_load_verified`): what
        ``locbench verify`` compares with a rebuilt truth. A :class:`StaleRecord` when missing or stale."""
        path = self.truth_path(dataset, seed)
        if not path.is_file():
            raise StaleRecord(f"{path}: missing")
        return _load_verified(path, path.with_suffix(".json"), truth_problem, required_record=True)

    def bound_files(self, dataset: str | Spec, seed: int) -> tuple[dict[str, Any], dict[str, np.ndarray]] | None:
        """The stored bound's record and arrays as stored, verified; None when there is none."""
        path = self.bound_path(dataset, seed)
        if not (path.is_file() or path.with_suffix(".json").is_file()):
            return None
        return _load_verified(path, path.with_suffix(".json"), bound_problem, required_record=True)

    def has_truth(self, dataset: str | Spec, seed: int) -> bool:
        return self.truth_path(dataset, seed).is_file()

    def bound_key(self, dataset: str | Spec, seed: int) -> str | None:
        """The ``bound_key`` of a stored bound that passes its checks, or None (none, unreadable or stale)."""
        try:
            bound = self.read_bound(str(dataset), seed)
        except ConfigError:
            return None
        key = bound.meta.get("bound_key") if bound is not None else None
        return str(key) if key is not None else None

    def read_bound(self, dataset: str, seed: int) -> BoundRecord | None:
        """The stored bound of a realisation, or None when it has none (recorded data, kidnaps, not computed);
        a :class:`StaleRecord` when its files fail their checks (:func:`bound_problem`)."""
        path = self.bound_path(dataset, seed)
        meta_path = path.with_suffix(".json")
        if not (path.is_file() and meta_path.is_file()):
            return None
        meta, z = _load_verified(path, meta_path, bound_problem, required_record=True)
        names = [str(n) for n in meta["rows"]]
        covs = {n: z[f"cov_{i}"] for i, n in enumerate(names)}
        return BoundRecord(dataset, seed, z["t"], covs, meta)

    def unreadable(self, dataset: str | Spec, filter_name: str | Spec, seed: int) -> str | None:
        """Why a stored run is unreadable or stale (it is then re-run), or None when it passes every check."""
        try:
            self.read_run(self.run_dir(dataset, filter_name, seed))
        except ConfigError as exc:
            return str(exc)
        return None

    def read_derived(self, run_dir: str | os.PathLike[str]) -> tuple[dict[str, Any], Derived, str] | None:
        """A stored ok run's record, its stored derived values and the :func:`truth_key` they were computed against,
        when they hold for this run: the record passes its own checks and names this folder, the estimates match
        their checksum, and the derived values' keys match the estimates and the current code. The caller compares
        the truth's key with the truth it reads.

        None otherwise (no derived values, out of date, or a run that fails a check): the caller then reads the run
        with :meth:`read_run`, which computes nothing twice for a hit and raises the reason for a stale run.
        """
        from locbench.evaluate.derived import code_digest

        d = Path(run_dir)
        if not (d / DERIVED_FILE).is_file():
            return None
        try:
            meta = _read_record(d / "meta.json", required=True)
            _check_place(d, meta)
            if meta.get("status") != "ok":
                return None
            z = _members_arrays(*_npz_members(d / DERIVED_FILE))
            # values of other code first, before the estimates are read: then the caller reads them once
            if str(z["key_code"]) != code_digest():
                return None
            digest = _members_digest(*_npz_members(d / "estimates.npz", crc=False))
            if digest != (meta.get("files") or {}).get("estimates.npz") or str(z["key_estimates"]) != digest:
                return None
            return meta, derived_from_arrays(z), str(z["key_truth"])
        except (
            ConfigError,
            OSError,
            ValueError,
            KeyError,
            TypeError,
            EOFError,
            zipfile.BadZipFile,
            zlib.error,
            NotImplementedError,
            RuntimeError,
        ):
            return None

    def read_run(self, run_dir: str | os.PathLike[str]) -> RunRecord:
        """A stored run, verified: its record's own checksum and the folder it lies in, its arrays' checksum and
        shape contract (:func:`run_problem`); a :class:`StaleRecord` naming the file and the reason otherwise."""
        d = Path(run_dir)
        meta, z = _load_verified(d / "estimates.npz", d / "meta.json", run_problem, required_record=True)
        _check_place(d, meta)
        diag = {k[5:]: v for k, v in z.items() if k.startswith("diag_")}
        extra = {k[6:]: v for k, v in z.items() if k.startswith("extra_")}
        health = {k[7:]: v for k, v in z.items() if k.startswith("health_")}
        return RunRecord(meta, z["t"], z["mean"], z["cov"], z["kind"], z["step_ns"], diag, extra, health)


def truth_arrays(rec: TruthRecord) -> dict[str, np.ndarray]:
    """The arrays of a realisation's truth as :meth:`Store.write_truth` stores them (``gt_*``, ``wp_*``, ...)."""
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
    return arrays


def truth_key(rec: TruthRecord) -> str:
    """The sha256 of a realisation's truth as stored (:func:`truth_arrays`: each array's name, dtype, shape and
    bytes, in name order) and its label: the same for the truth in memory and the one read back, so a run's derived
    values name the truth they were computed against."""
    h = hashlib.sha256(rec.truth_label.encode())
    arrays = truth_arrays(rec)
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        h.update(f"|{name}|{a.dtype.str}|{a.shape}|".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def derived_arrays(d: Derived, estimates_key: str, truth_key: str) -> dict[str, np.ndarray]:
    """The arrays of ``derived.npz``: the three keys, the metric ids and values, the NEES series and the health
    series (``health_t``, ``health_error_m``, ``health_kidnap_t``, ``signal_<name>``), each only when present."""
    from locbench.evaluate.derived import code_digest

    out: dict[str, np.ndarray] = {
        "key_estimates": np.array(estimates_key),
        "key_truth": np.array(truth_key),
        "key_code": np.array(code_digest()),
        "metric_ids": np.array(list(d.values), dtype=np.str_),
        "metric_values": np.array(list(d.values.values()), dtype=np.float64),
    }
    if d.nees is not None:
        out["nees"] = d.nees
    if d.health is not None:
        h = d.health
        out |= {"health_t": h.t, "health_error_m": h.error_m, "health_kidnap_t": np.array(h.kidnap_t)}
        out |= {f"signal_{k}": v for k, v in h.signals.items()}
    return out


def derived_from_arrays(z: dict[str, Any]) -> Derived:
    """The :class:`~locbench.evaluate.derived.Derived` that :func:`derived_arrays` stored."""
    from locbench.evaluate.derived import Derived
    from locbench.evaluate.lost import HealthSeries

    values = {str(k): float(v) for k, v in zip(z["metric_ids"].tolist(), z["metric_values"].tolist(), strict=True)}
    health = None
    if "health_t" in z:
        signals = {k[7:]: v for k, v in z.items() if k.startswith("signal_")}
        health = HealthSeries(z["health_t"], z["health_error_m"], signals, float(z["health_kidnap_t"]))
    return Derived(values, z.get("nees"), health)


def truth_meta(rec: TruthRecord) -> dict[str, Any]:
    """The JSON record of a realisation's truth as :meth:`Store.write_truth` stores it (before its checksums)."""
    return {"dataset": rec.dataset, "seed": rec.seed, "truth_label": rec.truth_label, **rec.meta}


def bound_arrays(rec: BoundRecord) -> dict[str, np.ndarray]:
    """The arrays of a bound as :meth:`Store.write_bound` stores them: ``t`` and ``cov_<i>`` of the rows sorted
    by name (the record's ``rows``)."""
    names = sorted(rec.covs)
    return {"t": rec.t} | {f"cov_{i}": rec.covs[n] for i, n in enumerate(names)}


class StaleRecord(ConfigError):
    """A stored record that fails its checksum or shape contract: the sweep runs it again, the report skips it."""


#: Longest JSON record read, bytes (a run's meta.json is a few kB).
MAX_RECORD_BYTES = 1 << 20


def _sealed(meta: dict[str, Any]) -> dict[str, Any]:
    """``meta`` as JSON will hold it, with ``meta_sha256``: the sha256 of the rest (:func:`_record_digest`)."""
    plain = json.loads(json.dumps(meta, default=str))
    return plain | {"meta_sha256": _record_digest(plain)}


def _record_digest(meta: dict[str, Any]) -> str:
    body = {k: v for k, v in meta.items() if k != "meta_sha256"}
    return hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()


def npz_digest(path: Path) -> str:
    """The sha256 of an ``.npz`` file's members (names and bytes, in name order).

    It is the arrays' checksum, not the zip's bytes (which hold the time of writing), so two writers of the same
    truth agree; reading every member also checks the zip's CRC-32s.
    """
    return _members_digest(*_npz_members(path))


def _npz_members(path: Path, crc: bool = True) -> tuple[list[str], dict[str, memoryview | bytes]]:
    """An ``.npz`` file's member names in the zip's order and each member's bytes, read once; their CRC-32s are
    checked unless ``crc`` is false, for a caller that checks the members' sha256 against a record (stronger).

    The file is read whole into one writable buffer; a stored (uncompressed) member, which is what ``numpy.savez``
    writes, is a view into it (its local header checked as ``zipfile`` checks it), so the arrays built from it need
    no copy; any other member is read through ``zipfile``. A name that appears twice gives its last member, as
    ``zipfile`` does.
    """
    buf = bytearray(path.stat().st_size)
    with path.open("rb") as fh:
        if fh.readinto(buf) != len(buf):
            raise zipfile.BadZipFile(f"{path}: changed while it was read")
    view = memoryview(buf)
    with zipfile.ZipFile(io.BytesIO(buf)) as z:
        names = z.namelist()
        data: dict[str, memoryview | bytes] = {}
        for name in dict.fromkeys(names):
            info = z.getinfo(name)
            member = _stored_member(view, info, crc)
            data[name] = memoryview(bytearray(z.read(info))) if member is None else member
        return names, data


#: A zip local file header: its signature, and the offsets of its name's and extra field's lengths.
_LOCAL_HEADER = (b"PK\x03\x04", 30)


def _stored_member(view: memoryview, info: zipfile.ZipInfo, crc: bool = True) -> memoryview | None:
    """The bytes of a stored, unencrypted member as a view into the whole file ``view``, after the checks
    ``zipfile`` makes (the local header's signature and name, the length, the CRC-32 when ``crc``); None for any
    other member, which ``zipfile`` reads. A :class:`zipfile.BadZipFile` when a check fails."""
    if info.compress_type != zipfile.ZIP_STORED or info.flag_bits & 0x1 or info.compress_size != info.file_size:
        return None
    magic, size = _LOCAL_HEADER
    at = info.header_offset
    header = bytes(view[at : at + size])
    if len(header) != size or header[:4] != magic:
        raise zipfile.BadZipFile(f"bad magic number for the file header of {info.orig_filename!r}")
    name_len, extra_len = int.from_bytes(header[26:28], "little"), int.from_bytes(header[28:30], "little")
    raw_name = bytes(view[at + size : at + size + name_len])
    local = raw_name.decode("utf-8" if info.flag_bits & 0x800 else "cp437", errors="replace")
    if local != info.orig_filename:
        raise zipfile.BadZipFile(f"file name in the directory {info.orig_filename!r} and header {local!r} differ")
    start = at + size + name_len + extra_len
    body = view[start : start + info.compress_size]
    if len(body) != info.compress_size:
        raise zipfile.BadZipFile(f"{info.orig_filename!r} is truncated")
    if crc and zlib.crc32(body) != info.CRC:
        raise zipfile.BadZipFile(f"bad CRC-32 for file {info.orig_filename!r}")
    return body


def _members_digest(names: list[str], data: dict[str, memoryview | bytes]) -> str:
    """:func:`npz_digest` of members read by :func:`_npz_members`."""
    h = hashlib.sha256()
    for name in sorted(names):
        h.update(name.encode() + b"\0")
        h.update(data[name])
    return h.hexdigest()


def _members_arrays(names: list[str], data: dict[str, memoryview | bytes]) -> dict[str, Any]:
    """The arrays of members read by :func:`_npz_members`, keyed as ``numpy.load`` keys them (``.npy`` dropped,
    in the zip's order); a member that is not in ``.npy`` format gives its bytes, as ``numpy.load`` does. No
    pickles."""
    keys = [name.removesuffix(".npy") for name in names]
    member = dict(zip(keys, names, strict=True)) | dict(zip(names, names, strict=True))
    out: dict[str, Any] = {}
    for key in keys:
        raw = data[member[key]]
        out[key] = _npy_array(raw) if bytes(raw[:6]) == np.lib.format.MAGIC_PREFIX else bytes(raw)
    return out


#: The header ``numpy.save`` writes in format 1.0 for a plain dtype (no fields, no objects): dtype, order, shape.
_NPY_HEADER = re.compile(
    r"\{'descr': '([<>|=][biufcmMSU]\d+(?:\[\w+\])?)', "
    r"'fortran_order': (True|False), "
    r"'shape': \(((?:\d+, ?)*\d*)\), \} *\n"
)


def _npy_array(raw: memoryview | bytes) -> np.ndarray:
    """The array of one ``.npy`` member. The header ``numpy.save`` writes for a plain dtype is parsed here and the
    array is a view of ``raw`` (writable when ``raw`` is); any other header goes to ``numpy.lib.format.read_array``
    (no pickles), which parses it with :func:`ast.literal_eval` at a cost that dominates a small array's read."""
    head = bytes(raw[:10])
    if head[6:8] == b"\x01\x00":
        end = 10 + int.from_bytes(head[8:10], "little")
        m = _NPY_HEADER.fullmatch(bytes(raw[10:end]).decode("latin1"))
        if m is not None:
            dtype = np.dtype(m.group(1))
            shape = tuple(int(n) for n in m.group(3).split(",") if n.strip())
            count = math.prod(shape)
            if len(raw) - end < count * dtype.itemsize:
                raise ValueError(f"EOF: the array needs {count * dtype.itemsize} bytes, {len(raw) - end} are stored")
            flat = np.frombuffer(raw, dtype=dtype, count=count, offset=end)
            return flat.reshape(shape, order="F" if m.group(2) == "True" else "C")
    return np.lib.format.read_array(io.BytesIO(bytes(raw)), allow_pickle=False)


def _write_npz_and_record(path: Path, arrays: dict[str, np.ndarray], meta: dict[str, Any]) -> None:
    """Write arrays to ``path`` and then the JSON record beside it that holds their checksum."""
    digest: list[str] = []

    def write(p: Path) -> None:
        np.savez(p, **arrays)  # type: ignore[arg-type]
        digest.append(npz_digest(p))

    _atomic_write(path, write)
    sealed = _sealed(meta | {"files": {path.name: digest[0]}})
    _atomic_write(path.with_suffix(".json"), lambda p: p.write_text(json.dumps(sealed, indent=2)))


Problem = Any  # Callable[[dict[str, Any], dict[str, np.ndarray]], str | None]


def _read_record(record: Path, required: bool) -> dict[str, Any]:
    """A JSON record that parses as an object below :data:`MAX_RECORD_BYTES` with a matching ``meta_sha256`` (``{}``
    for a missing record that is not ``required``); :class:`StaleRecord` otherwise."""
    if not (record.is_file() or required):
        return {}
    try:
        if record.stat().st_size > MAX_RECORD_BYTES:
            raise StaleRecord(f"{record}: larger than {MAX_RECORD_BYTES} bytes; not a record locbench wrote")
        data = json.loads(record.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError, UnicodeDecodeError, RecursionError) as exc:
        raise StaleRecord(one_line(f"{record}: unreadable record ({exc})")) from None
    if not isinstance(data, dict):
        raise StaleRecord(f"{record}: not a JSON object")
    if "meta_sha256" in data and data["meta_sha256"] != _record_digest(data):
        raise StaleRecord(f"{record}: its checksum does not match (the record was altered)")
    return data


def _check_place(d: Path, meta: dict[str, Any]) -> None:
    """A :class:`StaleRecord` unless the run record ``meta`` names the run of folder ``d``."""
    name = f"seed-{int(meta['seed']):04d}"
    where = (_safe(str(meta["dataset"])), _safe(str(meta["filter"])), name)
    if (d.parent.parent.name, d.parent.name, d.name) != where:
        raise StaleRecord(
            f"{d / 'meta.json'}: names {meta['filter']} on {meta['dataset']} seed {meta['seed']}, "
            f"which is not the run of this folder"
        )


def _load_verified(
    npz: Path, record: Path, contract: Problem, required_record: bool
) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """The JSON record and the arrays of a stored record, after every check; :class:`StaleRecord` otherwise.

    Checks, in order: the record parses as a JSON object below :data:`MAX_RECORD_BYTES` and its ``meta_sha256``
    matches; the arrays' checksum matches the record's ``files`` entry (both absent in records written before
    checksums); every array loads (no pickles); ``contract(meta, arrays)`` holds.
    """
    meta = _read_record(record, required_record)
    try:
        expected = (meta.get("files") or {}).get(npz.name) if isinstance(meta.get("files", {}), dict) else ""
        # each member read once: its bytes give the checksum, then the array
        names, data = _npz_members(npz, crc=expected is None)
        if expected is not None and _members_digest(names, data) != expected:
            raise StaleRecord(f"{npz}: its sha256 does not match the one recorded in {record.name}")
        arrays = _members_arrays(names, data)
    except StaleRecord:
        raise
    # zipfile raises NotImplementedError for an unknown compression method and RuntimeError for an encrypted member
    except (
        OSError,
        ValueError,
        EOFError,
        zipfile.BadZipFile,
        KeyError,
        zlib.error,
        NotImplementedError,
        RuntimeError,
    ) as exc:
        raise StaleRecord(one_line(f"{npz}: does not load ({type(exc).__name__}: {exc})")) from None
    why = contract(meta, arrays)
    if why is not None:
        raise StaleRecord(one_line(f"{npz}: {why}"))
    return meta, arrays


def _shape(arrays: dict[str, np.ndarray], name: str, kind: str, shape: tuple[int | None, ...]) -> str | None:
    """Why ``arrays[name]`` is missing or not of dtype kind ``kind`` and ``shape`` (None: any length), or None."""
    a = arrays.get(name)
    if a is None:
        return f"missing array {name}"
    if (
        a.dtype.kind not in kind
        or a.ndim != len(shape)
        or any(w is not None and w != n for w, n in zip(shape, a.shape, strict=True))
    ):
        want = "x".join("n" if w is None else str(w) for w in shape) or "scalar"
        return f"array {name} is {a.dtype}{list(a.shape)}, expected {kind}-kind of shape {want}"
    return None


def _first(*problems: str | None) -> str | None:
    return next((p for p in problems if p is not None), None)


def _sorted_finite(a: np.ndarray, name: str) -> str | None:
    if not np.all(np.isfinite(a)):
        return f"non-finite values in {name}"
    if a.size > 1 and not np.all(np.diff(a) >= 0):
        return f"times {name} are not sorted"
    return None


def run_problem(meta: dict[str, Any], arrays: dict[str, np.ndarray]) -> str | None:
    """Why a run's record and arrays break the run contract, or None.

    ``meta`` names a filter, a dataset, an integer seed, a run key and a status of :data:`STATUSES`; the arrays
    are ``t`` (n,), ``mean`` (n, 3), ``cov`` (n, 3, 3) floats, ``kind`` (n,) int8 codes of :data:`KIND_NAMES`,
    ``step_ns`` (n,) int64 >= 0, each ``diag_*`` (n,) floats; ``n`` equals ``n_rows`` where recorded; under status
    ok, ``t`` is finite and sorted, ``mean`` and ``cov`` finite.
    """
    missing = [k for k in ("filter", "dataset", "seed", "run_key", "status") if k not in meta]
    if missing:
        return f"record lacks {', '.join(missing)}"
    if not isinstance(meta["seed"], int) or isinstance(meta["seed"], bool) or meta["seed"] < 0:
        return f"record's seed {meta['seed']!r} is not a non-negative integer"
    if meta["status"] not in STATUSES:
        return f"record's status {meta['status']!r} is not one of {', '.join(STATUSES)}"
    n = arrays["t"].shape[0] if "t" in arrays and arrays["t"].ndim == 1 else None
    why = _first(
        _shape(arrays, "t", "f", (None,)),
        _shape(arrays, "mean", "f", (n, 3)),
        _shape(arrays, "cov", "f", (n, 3, 3)),
        _shape(arrays, "kind", "i", (n,)),
        _shape(arrays, "step_ns", "i", (n,)),
        *(_shape(arrays, k, "f", (n,)) for k in arrays if k.startswith(("diag_", "health_"))),
    )
    if why is not None:
        return why
    if arrays["kind"].size and (arrays["kind"].min() < 0 or arrays["kind"].max() >= len(KIND_NAMES)):
        return "event kind codes out of range"
    if arrays["step_ns"].size and arrays["step_ns"].min() < 0:
        return "negative call times in step_ns"
    if "n_rows" in meta and meta["n_rows"] != n:
        return f"{n} rows, the record says {meta['n_rows']}"
    if meta["status"] == "ok":
        # an imported pose-only run declares it has no covariance (``covariance`` false) and stores NaN
        cov_ok = meta.get("covariance", True) is False or np.all(np.isfinite(arrays["cov"]))
        if not (np.all(np.isfinite(arrays["mean"])) and cov_ok):
            return "non-finite estimates under status ok"
        return _sorted_finite(arrays["t"], "t")
    return None


def truth_problem(meta: dict[str, Any], arrays: dict[str, np.ndarray]) -> str | None:
    """Why a realisation's truth arrays break their contract, or None: ``gt_t`` (n,) finite and sorted,
    ``gt_xy`` (n, 2) and ``gt_theta`` (n,) finite, waypoints (m,) and (m, 2), kidnaps (k,) and (k, 3), a finite
    ``duration_s``, map segments (s, 4) and landmarks (l, 2), relations (r,), (r,) and (r, 3)."""
    n = arrays["gt_t"].shape[0] if "gt_t" in arrays and arrays["gt_t"].ndim == 1 else None
    m = arrays["wp_t"].shape[0] if "wp_t" in arrays and arrays["wp_t"].ndim == 1 else None
    k = arrays["kidnap_t"].shape[0] if "kidnap_t" in arrays and arrays["kidnap_t"].ndim == 1 else None
    checks = [
        _shape(arrays, "gt_t", "f", (None,)),
        _shape(arrays, "gt_xy", "f", (n, 2)),
        _shape(arrays, "gt_theta", "f", (n,)),
        _shape(arrays, "wp_t", "f", (None,)),
        _shape(arrays, "wp_xy", "f", (m, 2)),
        _shape(arrays, "has_waypoints", "b", ()),
        _shape(arrays, "kidnap_t", "f", (None,)),
        _shape(arrays, "kidnap_delta", "f", (k, 3)),
        _shape(arrays, "duration_s", "f", ()),
    ]
    checks += [_shape(arrays, a, "f", (None, w)) for a, w in (("map_segments", 4), ("map_landmarks", 2)) if a in arrays]
    if "rel_t1" in arrays:
        r = arrays["rel_t1"].shape[0] if arrays["rel_t1"].ndim == 1 else None
        checks += [_shape(arrays, "rel_t1", "f", (None,)), _shape(arrays, "rel_t2", "f", (r,))]
        checks.append(_shape(arrays, "rel_delta", "f", (r, 3)))
    why = _first(*checks)
    if why is not None:
        return why
    if not (np.all(np.isfinite(arrays["gt_xy"])) and np.all(np.isfinite(arrays["gt_theta"]))):
        return "non-finite ground truth"
    if not np.isfinite(arrays["duration_s"]):
        return "non-finite duration_s"
    return _sorted_finite(arrays["gt_t"], "gt_t")


def bound_problem(meta: dict[str, Any], arrays: dict[str, np.ndarray]) -> str | None:
    """Why a bound's record and arrays break their contract, or None: ``rows`` names one ``cov_<i>`` (n, 3, 3)
    float array each, ``t`` (n,) finite and sorted, a ``bound_key``."""
    rows = meta.get("rows")
    if not isinstance(rows, list) or "bound_key" not in meta:
        return "record lacks its rows or bound_key"
    n = arrays["t"].shape[0] if "t" in arrays and arrays["t"].ndim == 1 else None
    why = _first(
        _shape(arrays, "t", "f", (None,)), *(_shape(arrays, f"cov_{i}", "f", (n, 3, 3)) for i in range(len(rows)))
    )
    return why if why is not None else _sorted_finite(arrays["t"], "t")


def _makedirs(path: Path) -> None:
    """``mkdir -p`` that names the folder in its error (a file in the way, no permission)."""
    try:
        path.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise NotADirectoryError(errno.ENOTDIR, "a file is in the way of a results folder", str(path)) from None


#: Attempts of the move-aside-and-rename loop before giving up (each is a rename that another writer won).
_SWAP_ATTEMPTS = 100


def _swap_into_place(tmp: Path, final: Path, own: frozenset[str] = RUN_FILES) -> None:
    """Rename folder ``tmp`` to ``final``, moving any folder already there aside (unique name); then carry what
    the old folder holds beyond ``own`` (paths relative to it) into the new one and remove the old folder's own
    files (:func:`carry_over`, :func:`remove_own`). A foreign entry that cannot be carried over stays in the
    moved-aside folder, which is then kept (logged)."""
    aside: list[Path] = []
    for _ in range(_SWAP_ATTEMPTS):
        try:
            tmp.rename(final)
            break
        except OSError as exc:
            if exc.errno not in (errno.ENOTEMPTY, errno.EEXIST, errno.EISDIR):
                raise
        old = final.with_name(f"{final.name}.old-{uuid.uuid4().hex[:12]}")
        try:
            final.rename(old)
        except FileNotFoundError:
            continue  # another writer moved it away first: try our rename again
        aside.append(old)
    else:
        raise OSError(errno.EBUSY, f"could not replace the run folder after {_SWAP_ATTEMPTS} attempts", str(final))
    for old in aside:
        left = carry_over(old, final, own)
        if not remove_own(old, own):
            log.warning("%s: kept, it holds files locbench did not write that %s already has: %s", old, final, left)


def _own_dirs(own: Collection[str]) -> set[str]:
    """The folders (relative paths) that hold the files ``own`` names."""
    return {"/".join(parts[:i]) for rel in own for parts in [rel.split("/")] for i in range(1, len(parts))}


def carry_over(old: Path, new: Path, own: Collection[str]) -> list[Path]:
    """Move every entry under folder ``old`` that is not one of ``own`` (files, as paths relative to ``old``)
    to the same place under ``new``; returns the entries left behind because ``new`` has that name already.

    A folder that holds own files (``figures/``) or that ``new`` has too is entered; any other entry (a file, a
    symlink, a folder of someone else's) is moved whole, by a rename (no copy: nothing is lost when the disk is
    full).
    """
    dirs = _own_dirs(own)
    left: list[Path] = []

    def walk(rel_dir: str) -> None:
        here = old / rel_dir if rel_dir else old
        for entry in sorted(here.iterdir()):
            rel = f"{rel_dir}/{entry.name}" if rel_dir else entry.name
            if rel in own:
                continue
            target = new / rel
            if (
                entry.is_dir()
                and not entry.is_symlink()
                and (rel in dirs or (target.is_dir() and not target.is_symlink()))
            ):
                walk(rel)  # a folder both have: carry over what it holds
                if rel not in dirs:
                    with contextlib.suppress(OSError):  # now empty: the new folder has it
                        entry.rmdir()
                continue
            if os.path.lexists(target):
                left.append(entry)
                continue
            _makedirs(target.parent)
            entry.rename(target)

    if old.is_dir():
        walk("")
    return left


def remove_own(folder: Path, own: Collection[str]) -> bool:
    """Remove the files ``own`` names under ``folder``, then the folders they leave empty and ``folder`` itself
    when it is empty; whether ``folder`` is gone. Nothing else is removed."""
    for rel in own:
        p = folder / rel
        if p.is_file() and not p.is_symlink():
            p.unlink(missing_ok=True)
    for rel in sorted(_own_dirs(own), key=lambda r: -r.count("/")):
        with contextlib.suppress(OSError):  # not empty (a foreign file), or not there
            (folder / rel).rmdir()
    try:
        folder.rmdir()
    except FileNotFoundError:
        return True
    except OSError:
        return False
    return True


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
