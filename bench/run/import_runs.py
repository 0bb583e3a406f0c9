"""``locbench import``: another system's output stored as ordinary runs of the filter ``external[name=NAME]``.

A localization system that is not a locbench filter (nav2 AMCL, Beluga, robot_localization, a C++ or MATLAB
program) is scored on locbench's datasets from what it wrote (:mod:`locbench.run.import_formats`). For each seed,
its file is read and checked, the dataset realisation is built as a sweep builds it (its truth is stored beside the
run, as a sweep stores it), and the run is stored like any other: one row per reported pose, the covariance where
the format has one, and the proper scores of its particle clouds where it has them. Nothing is stored unless every
seed's file passes (:func:`import_system`).

What a stored import holds and means:

- **Rows.** Each reported pose is a row (event kind ``reset``: not an event locbench sent); the metrics hold it over
  the ground-truth times up to the next one (zero-order hold, as for a filter's rows). A time within
  :data:`SNAP_S` of one of the dataset's own times (an event's or the truth's) is taken to be that time: a ROS
  stamp is integer nanoseconds, a text file may round.
- **Clock.** Times on the dataset's clock, or on an exported bag's clock (the dataset's plus
  :func:`~locbench.run.ros_messages.clock_offset`), which one decided by which overlaps the truth's span.
- **Covariance.** A pose-only format (TUM) stores NaN covariances and ``covariance: false``: the consistency metrics
  and the Gaussian scores are left out (not applicable), never computed from a made-up spread.
- **Particles.** The cloud in force at each ground-truth time is scored with
  :func:`locbench.evaluate.scores.sample_scores` (the fair estimator, the cloud's weights as given), as a particle
  filter's belief sample is; without a pose topic, a
  cloud's weighted mean (circular heading) and weighted covariance (wrapped heading residuals) are the row.
- **Health.** With a covariance, its position trace and heading variance are the run's health signals
  (:func:`locbench.filters.base.gaussian_health_rows`), from which the report's lost detection is scored.
- **Runtime** is not measured (``runtime_measured: false``): no call times are stored and no call-time metric given.
  A bag gives the latency instead: each row's record (log) time minus its header stamp, s (the pose topic's
  messages; without one, the clouds'), stored as the row diagnostic
  :data:`~locbench.evaluate.metrics.LATENCY_DIAGNOSTIC`, from which the latency metrics are computed. Both times
  are on the bag's clock, so the clock offset cancels. A latency beyond the dataset's duration means the record
  times are on another clock than the stamps (a bag recorded on the wall clock against a played-back sim clock):
  then it is not measured, and ``meta["imported"]["latency"]`` says why.
- **Key and provenance.** The run key is a hash of the files' sha256 digests, the reading options and the dataset
  realisation; ``meta["imported"]`` holds each file's path, size and digest, the format, the topics, the
  description and the sensors the system used (not stated: every event type of the dataset, so the report never
  credits a system with needing less than it may have used). ``locbench verify`` checks those digests instead of
  re-running.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from locbench.core.errors import ConfigError
from locbench.core.events import EVENT_TYPES
from locbench.core.geometry import wrap_angle
from locbench.core.spec import format_spec, stable_hash
from locbench.datasets.dataset import Dataset
from locbench.datasets.recorded.files import RecordedDataError, sha256_of
from locbench.evaluate.hold import hold_ends
from locbench.evaluate.metrics import LATENCY_DIAGNOSTIC
from locbench.evaluate.records import KIND_NAMES, RunRecord, TruthRecord
from locbench.filters.base import gaussian_health_rows
from locbench.run import provenance
from locbench.run.import_formats import SystemOutput, read_output
from locbench.run.ros_messages import clock_offset
from locbench.run.store import Store

FloatArray = npt.NDArray[np.float64]

#: The filter id of imported runs.
EXTERNAL_ID = "external"
#: The version of the import's reading and storing rules (part of the run key), the estimator of a cloud's scores
#: (:data:`locbench.evaluate.scores.SAMPLE_ESTIMATOR`) among them.
IMPORT_VERSION = 3
#: Largest distance of an imported time from a dataset time it is taken to be, s.
SNAP_S = 1e-6
#: The frame poses must be in: the dataset's world frame, ``map`` in an exported bag.
MAP_FRAME = "map"
#: Relative tolerance of a covariance's symmetry.
SYMMETRY_RTOL = 1e-9
_RESET = KIND_NAMES.index("reset")


def external_name(name: str) -> str:
    """The filter name of an imported system: ``external[name=NAME]``."""
    if not name or any(c in name for c in ",=[]| \t\n/"):
        raise ConfigError(f"--name {name!r}: expected a plain name (no spaces, commas, '=', '|', '/', brackets)")
    return format_spec(EXTERNAL_ID, {"name": name})


@dataclass
class Prepared:
    """One seed's import, checked and ready to store."""

    seed: int
    truth: TruthRecord
    run: RunRecord


def _fail(out: SystemOutput, row: int, message: str) -> RecordedDataError:
    return RecordedDataError(out.path, f"{out.where[row]}: {message}")


def check_output(out: SystemOutput, frame: str = MAP_FRAME) -> None:
    """Refuse NaN poses, asymmetric or non-positive-definite covariances, poses in a frame other than ``frame``,
    particle weights that are negative, NaN or all zero, and times that go backwards."""
    for topic, f in out.frames.items():
        if f != frame:
            raise RecordedDataError(
                out.path,
                f"topic {topic!r} is in frame {f!r}, expected {frame!r} (the dataset's map frame): record the "
                f"system's estimate in {frame!r}, or apply the transform {frame} -> {f} to it first",
            )
    bad = np.flatnonzero(~np.all(np.isfinite(out.mean), axis=1))
    if bad.size:
        raise _fail(out, int(bad[0]), f"pose {out.mean[int(bad[0])].tolist()} is not finite; expected numbers")
    back = np.flatnonzero(np.diff(out.t) < 0)
    if back.size:
        k = int(back[0]) + 1
        raise _fail(out, k, f"time {out.t[k]!r} s before the previous {out.t[k - 1]!r} s; expected non-decreasing")
    if out.cov is not None:
        for k, c in enumerate(out.cov):
            if not np.all(np.isfinite(c)):
                raise _fail(out, k, f"covariance {c.ravel().tolist()} is not finite")
            scale = max(float(np.max(np.abs(c))), np.finfo(float).tiny)
            if not np.allclose(c, c.T, rtol=0.0, atol=SYMMETRY_RTOL * scale):
                raise _fail(out, k, f"covariance is not symmetric: {c.tolist()}")
            try:
                np.linalg.cholesky(c)
            except np.linalg.LinAlgError:
                eig = np.linalg.eigvalsh(c).tolist()
                raise _fail(
                    out, k, f"covariance is not positive definite (eigenvalues {eig}); expected a positive-definite 3x3"
                ) from None
    for cloud in out.clouds:
        w, where = cloud.weights, cloud.where
        if w.size == 0:
            raise RecordedDataError(out.path, f"{where}: no particles")
        if not np.all(np.isfinite(w)) or np.any(w < 0):
            k = int(np.flatnonzero(~np.isfinite(w) | (w < 0))[0])
            raise RecordedDataError(
                out.path, f"{where} particle {k + 1}: weight {float(w[k])!r}, expected finite and >= 0"
            )
        if not np.any(w > 0):
            raise RecordedDataError(out.path, f"{where}: every weight is 0, expected a positive sum")
        if not np.all(np.isfinite(cloud.points)):
            raise RecordedDataError(out.path, f"{where}: a particle's pose is not finite")


def _clock(out: SystemOutput, ds: Dataset) -> float:
    """The offset to subtract from the output's times: 0 or the exported bag clock's, whichever overlaps the truth."""
    gt = ds.ground_truth.t
    lo, hi = float(gt[0]), float(gt[-1])
    times = np.concatenate([out.t, [c.t for c in out.clouds]]) if out.clouds else out.t
    first, last = float(np.min(times)), float(np.max(times))
    off = clock_offset(min(lo, ds.events[0].t if ds.events else lo))
    for shift in (0.0, off):
        if first - shift <= hi and last - shift >= lo:
            return shift
    bag = f", or {lo + off!r} to {hi + off!r} s on an exported bag's clock" if off else ""
    raise RecordedDataError(
        out.path,
        f"times {first!r} to {last!r} s do not overlap the dataset's {lo!r} to {hi!r} s{bag}; expected the "
        "system's output on this dataset and seed",
    )


def _snap(t: FloatArray, grid: FloatArray) -> FloatArray:
    """Each time replaced by the nearest dataset time within :data:`SNAP_S`, else kept."""
    if t.size == 0:
        return t
    i = np.clip(np.searchsorted(grid, t), 1, grid.size - 1)
    near = np.where(np.abs(grid[i - 1] - t) <= np.abs(grid[i] - t), grid[i - 1], grid[i])
    return np.where(np.abs(near - t) <= SNAP_S, near, t)


def _latency(out: SystemOutput, clouds: Sequence[Any], ds: Dataset) -> tuple[FloatArray | None, str]:
    """Each row's latency, s, and what ``meta["imported"]["latency"]`` says of it.

    The rows are the pose topic's messages, or without one the clouds (:func:`prepare`), so the latencies are
    theirs. None (not measured) for a text format, a bag with a header stamp of 0, or record times on another clock
    than the stamps: a latency longer than the dataset's whole duration (s) is not a delay of the estimate.
    """
    if out.latency is None:
        return None, "not measured: " + (
            "the format has no record times" if out.fmt != "bag" else "a header stamp is 0 (unset)"
        )
    lat = out.latency if out.t.size else np.array([c.latency_s for c in clouds], dtype=np.float64)
    span = float(ds.ground_truth.t[-1] - ds.ground_truth.t[0])
    worst = float(np.max(lat)) if lat.size else 0.0
    if worst > span:
        return None, (
            f"not measured: a record time is {worst!r} s after its header stamp, longer than the dataset's "
            f"{span!r} s; the record times are on another clock than the stamps (record with the sim clock)"
        )
    return lat, "measured: record time minus header stamp"


def cloud_moments(points: FloatArray, weights: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Weighted mean (heading by the circular mean) and weighted covariance (heading residuals wrapped) of a cloud."""
    w = weights / np.sum(weights)
    theta = math.atan2(float(np.sum(w * np.sin(points[:, 2]))), float(np.sum(w * np.cos(points[:, 2]))))
    mean = np.array([float(np.sum(w * points[:, 0])), float(np.sum(w * points[:, 1])), theta])
    d = points - mean
    d[:, 2] = wrap_angle(d[:, 2])
    return mean, (d * w[:, None]).T @ d


def _cloud_scores(clouds: Sequence[Any], ds: Dataset) -> dict[str, FloatArray]:
    """The per-ground-truth-time scores of the clouds in force (zero-order hold; the first before it)."""
    from locbench.evaluate.scores import SAMPLE_SCORE_KEYS, sample_scores

    gt = ds.ground_truth
    ends = hold_ends(np.array([c.t for c in clouds]), gt.t)
    scores = np.full((4, gt.t.shape[0]), np.nan)
    start = 0
    for c, stop in zip(clouds, ends.tolist(), strict=True):
        if stop > start:
            scores[:, start:stop] = sample_scores(c.points, c.weights, gt.poses[start:stop])
            start = stop
    return dict(zip(SAMPLE_SCORE_KEYS, scores, strict=True))


def file_record(path: Path) -> dict[str, Any]:
    """A file's entry in an import's provenance: its absolute path, size (bytes) and sha256 (a bag folder: of its
    files' digests, sorted by name)."""
    p = path.resolve()
    if p.is_dir():
        h = hashlib.sha256()
        size = 0
        for q in sorted(q for q in p.iterdir() if q.is_file()):
            h.update(f"{q.name} {sha256_of(q)}\n".encode())
            size += q.stat().st_size
        return {"path": str(p), "bytes": size, "sha256": h.hexdigest()}
    return {"path": str(p), "bytes": p.stat().st_size, "sha256": sha256_of(p)}


def prepare(
    name: str,
    dataset: str,
    seed: int,
    path: Path,
    *,
    fmt: str | None = None,
    topics: tuple[str, ...] = (),
    description: str = "",
    sensors: tuple[str, ...] = (),
    frame: str = MAP_FRAME,
) -> Prepared:
    # long: read, check, align the clock, build the rows and the provenance of one seed; one linear recipe
    """Read and check one seed's output and build its run and its realisation's truth (nothing is written)."""
    from locbench.run.execute import _BuildFailed, _realisation
    from locbench.run.plan import STORE_FORMAT, Task, parse_dataset

    out = read_output(path, fmt, topics)
    check_output(out, frame)
    dr = parse_dataset(dataset)
    # the realisation exactly as a sweep builds it, and its truth's record as a sweep stores it
    built = _realisation(Task(dr, seed, ()))
    if isinstance(built, _BuildFailed):
        raise ConfigError(f"{dataset} seed {seed} did not build ({built.message}); nothing imported")
    ds, truth = built
    shift = _clock(out, ds)
    grid = np.unique(np.concatenate([ds.ground_truth.t, [e.t for e in ds.events]]))
    clouds = [dataclasses.replace(c, t=float(_snap(np.array([c.t - shift]), grid)[0])) for c in out.clouds]
    if out.t.size:
        t = _snap(out.t - shift, grid)
        mean = out.mean.copy()
        cov = out.cov.copy() if out.cov is not None else np.full((t.size, 3, 3), np.nan)
    else:  # particles only: each cloud's moments are the row
        t = np.array([c.t for c in clouds])
        moments = [cloud_moments(c.points, c.weights) for c in clouds]
        mean = np.array([m for m, _ in moments]).reshape(-1, 3)
        cov = np.array([c for _, c in moments]).reshape(-1, 3, 3)
    if t.size == 0:
        raise RecordedDataError(out.path, "no pose and no particle cloud; expected at least one")
    latency, latency_note = _latency(out, clouds, ds)
    has_cov = out.cov is not None or not out.t.size
    extra = _cloud_scores(clouds, ds) if clouds else {}
    # the spread the system reported is its health signal (the lost detection's AUROC reads it), as a Gaussian
    # filter's is; a pose-only run has none
    health = gaussian_health_rows(cov, {}) if has_cov else {}
    record = file_record(out.path)
    fname = external_name(name)
    unknown = sorted(set(sensors) - {e.__name__ for e in EVENT_TYPES})
    if unknown:
        valid = ", ".join(sorted(e.__name__ for e in EVENT_TYPES))
        raise ConfigError(f"--sensors: unknown {', '.join(unknown)}; expected some of {valid}")
    stated = bool(sensors)
    if not stated:  # not said: the system may have used anything the dataset offers (the report's "needs" column)
        sensors = tuple(sorted({type(e).__name__ for e in ds.events}))
    options = {"format": out.fmt, "topics": list(out.topics), "frame": frame}
    key = stable_hash(
        {
            "format": STORE_FORMAT,
            "import": IMPORT_VERSION,
            "filter": EXTERNAL_ID,
            "name": name,
            "files": [record["sha256"]],
            "options": options,
            "dataset": dr.id,
            "dataset_params": dr.resolved.params_dict(),
            "dataset_version": dr.version,
            "seed": seed,
        }
    )
    git = provenance.git_state()
    meta: dict[str, Any] = {
        "filter": fname,
        "filter_id": EXTERNAL_ID,
        "filter_config": {"name": name},
        "filter_version": IMPORT_VERSION,
        "dataset": dr.name,
        "dataset_id": dr.id,
        "dataset_params": dr.resolved.params_dict(),
        "dataset_version": dr.version,
        "seed": seed,
        "run_key": key,
        "status": "ok",
        "message": "",
        "diverged_t": None,
        "n_rows": int(t.size),
        "wall_s": 0.0,
        "versions": provenance.versions(),
        "git_commit": git["commit"],
        "git_dirty": git["dirty"],
        "covariance": bool(has_cov),
        "runtime_measured": False,
        "imported": {
            "files": [record],
            **options,
            "clock_offset_s": shift,
            "description": description,
            "sensors": sorted(sensors),
            "sensors_stated": stated,
            "particle_clouds": len(clouds),
            "latency": latency_note,
        },
        "filter_traits": {
            "baseline": False,
            "global_start": False,
            "kidnap_name": None,
            "sensors": sorted(sensors),
            "maps": [],
        },
    }
    run = RunRecord(
        meta,
        np.ascontiguousarray(t, dtype=np.float64),
        np.ascontiguousarray(mean, dtype=np.float64),
        np.ascontiguousarray(cov, dtype=np.float64),
        np.full(t.size, _RESET, np.int8),
        np.zeros(t.size, np.int64),
        diagnostics={LATENCY_DIAGNOSTIC: latency} if latency is not None else {},
        extra=extra,
        health=health,
    )
    return Prepared(seed, truth, run)


def seed_files(patterns: Sequence[str], seeds: Sequence[int]) -> dict[int, Path]:
    """The file of each seed: a pattern with ``{seed}`` is filled in per seed; else one file per seed in order.

    Raises
    ------
    ConfigError
        The files do not pair with the seeds, or some seeds' files are missing (all of them are listed).
    """
    if not seeds:
        raise ConfigError("--seed: give at least one seed")
    if len(patterns) == 1 and "{seed}" in patterns[0]:
        files = {s: Path(patterns[0].replace("{seed}", str(s))) for s in seeds}
    elif len(patterns) == len(seeds):
        files = {s: Path(p) for s, p in zip(seeds, patterns, strict=True)}
    else:
        raise ConfigError(
            f"{len(patterns)} file(s) for {len(seeds)} seed(s): expected one file per seed, in the order of the "
            "seeds, or one name with {seed} in it"
        )
    missing = [f"seed {s}: {p}" for s, p in files.items() if not os.path.lexists(p)]
    if missing:
        raise ConfigError(
            f"no output file for {len(missing)} of {len(seeds)} seeds ({'; '.join(missing)}); nothing imported"
        )
    return files


def import_system(
    results: str | os.PathLike[str],
    name: str,
    dataset: str,
    seeds: Sequence[int],
    files: Sequence[str],
    **options: Any,
) -> list[Path]:
    """Import one system's output for the given seeds into the results folder; nothing is stored unless all pass.

    Parameters
    ----------
    results : path-like
        The results folder (claimed as a sweep claims it).
    name : str
        The system's name: its runs are ``external[name=NAME]``.
    dataset : str
        The dataset spec the output was computed on.
    seeds : sequence of int
        The realisations.
    files : sequence of str
        One file per seed in order, or one name with ``{seed}`` (:func:`seed_files`).
    **options
        ``fmt``, ``topics``, ``description``, ``sensors``, ``frame`` (:func:`prepare`).

    Returns
    -------
    list of Path
        The run folders written.
    """
    external_name(name)
    by_seed = seed_files(files, seeds)
    prepared = [prepare(name, dataset, s, p, **options) for s, p in by_seed.items()]
    store = Store(results)
    store.claim()
    written: list[Path] = []
    for item in prepared:
        store.write_truth(item.truth)
        written.append(store.write_run(item.run))
    return written


def digest_problems(meta: dict[str, Any]) -> list[str]:
    """What no longer matches an imported run's provenance: each file missing or with another sha256."""
    out: list[str] = []
    for entry in meta.get("imported", {}).get("files", []):
        p = Path(entry["path"])
        if not p.exists():
            out.append(f"{p}: missing (imported with sha256 {entry['sha256'][:16]}...)")
            continue
        now = file_record(p)["sha256"]
        if now != entry["sha256"]:
            out.append(f"{p}: sha256 {now[:16]}... differs from the imported {entry['sha256'][:16]}...")
    return out
