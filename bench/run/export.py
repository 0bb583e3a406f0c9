"""Trajectories in the TUM format, so that stored runs can be checked with other tools (evo, rpg_trajectory_evaluation).

A TUM trajectory file (TUM RGB-D benchmark; the format evo reads with ``evo_ape tum truth.tum est.tum``) has one
pose per line::

    timestamp tx ty tz qx qy qz qw

with the time in seconds, the position in metres and the orientation as a unit quaternion (Hamilton, scalar
last). A planar pose (x, y, theta) is written with tz = 0 and the rotation about z by theta:
(qx, qy, qz, qw) = (0, 0, sin(theta / 2), cos(theta / 2)), qw >= 0 for theta in (-pi, pi]. Fields are separated by
one space, numbers are written in their shortest exact form (a read-back gives the same float64), one ``#`` comment
line says what the file holds (evo skips comment lines).

Timestamps are strictly increasing, as evo expects: where several estimates share a time (an odometry step and a
scan at the same stamp) the last one, the estimate after every event of that instant, is written; it is the one
locbench's metrics hold at that time. Estimate rows that are not finite (a run that diverged) are left out with a
warning. The times are the dataset's own (recordings keep their Unix stamps), so an export lines up with the
recording and with other tools' output on it. Every file is written to a temporary file and renamed into place.

:func:`export_textlog` writes a whole dataset realisation (events, truth, map, noise) as a plain-text log, the
``locbench-textlog`` format of :mod:`locbench.datasets.recorded.textlog`, so that a user sees a worked example of
the format and any dataset can be read back as ``textlog[path=...]``.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import numpy.typing as npt

from locbench.datasets.dataset import Trajectory2D
from locbench.datasets.recorded.tum import TUM_COLUMNS, read_tum, write_tum

__all__ = ["TUM_COLUMNS", "export_results", "export_textlog", "export_truth_tum", "export_tum", "read_tum", "write_tum"]
from locbench.core.errors import ConfigError
from locbench.evaluate.records import RunRecord, TruthRecord
from locbench.run.store import Store, _follow_umask

log = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]


def _load_run(run: RunRecord | str | os.PathLike[str]) -> RunRecord:
    if isinstance(run, RunRecord):
        return run
    d = Path(run)
    return Store(d.parent).read_run(d)


def _umask_mode(path: Path) -> Path:
    """``path`` with the mode the user's umask asks for (the atomic writers' temporary files are 0600)."""
    _follow_umask(path, is_dir=False)
    return path


def export_tum(run: RunRecord | str | os.PathLike[str], path: str | os.PathLike[str], smoothed: bool = False) -> Path:
    """Write a stored run's estimated trajectory as a TUM file.

    Parameters
    ----------
    run : RunRecord or path-like
        The run, or its folder (``runs/<dataset>/<filter>/seed-NNNN``).
    path : path-like
        The file to write.
    smoothed : bool
        Write the smoothed trajectory of a smoother (``extra`` ``smoothed_t`` / ``smoothed_mean``) instead of
        the filtered estimate after each event.

    Returns
    -------
    Path
        The file.

    Raises
    ------
    ConfigError
        An unreadable run folder, a run without estimates (skipped), or ``smoothed`` on a run without a smoothed
        trajectory.
    """
    rec = _load_run(run)
    meta = rec.meta
    what = f"run {meta.get('filter', '?')} on {meta.get('dataset', '?')} seed {meta.get('seed', '?')}"
    if rec.status != "ok":
        log.warning("%s has status %s (%s): exporting what it estimated", what, rec.status, meta.get("message", ""))
    if smoothed:
        if "smoothed_t" not in rec.extra or "smoothed_mean" not in rec.extra:
            raise ConfigError(f"{what} has no smoothed trajectory (only smoothers such as gtsam_fls store one)")
        t, poses = rec.extra["smoothed_t"], rec.extra["smoothed_mean"]
    else:
        t, poses = rec.t, rec.mean
    if np.asarray(t).shape[0] == 0:
        raise ConfigError(f"{what} has no estimates (status {rec.status}: {meta.get('message', '')})")
    label = "smoothed" if smoothed else "filtered"
    comment = (
        f"locbench {label} estimate: filter {meta.get('filter')} dataset {meta.get('dataset')} seed {meta.get('seed')}"
    )
    return _umask_mode(write_tum(path, t, poses, comment))


def export_truth_tum(truth: TruthRecord | Trajectory2D, path: str | os.PathLike[str]) -> Path:
    """Write a ground truth (or a SLAM reference) as a TUM file.

    Parameters
    ----------
    truth : TruthRecord or Trajectory2D
        A stored truth record (its label goes into the comment line) or a trajectory.
    path : path-like
        The file to write.
    """
    if isinstance(truth, TruthRecord):
        gt = truth.ground_truth
        comment = f"locbench {truth.truth_label}: dataset {truth.dataset} seed {truth.seed}"
    else:
        gt, comment = truth, "locbench trajectory"
    return _umask_mode(write_tum(path, gt.t, gt.poses, comment))


def export_results(
    results: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    datasets: Iterable[str] = (),
    filters: Iterable[str] = (),
    smoothed: bool = False,
) -> list[Path]:
    """Export every stored run (and the truth of each dataset realisation) of a results folder as TUM files.

    Layout: ``<out>/<dataset>/<filter>/seed-NNNN.tum`` and ``<out>/<dataset>/_truth/seed-NNNN.tum`` (folder names
    as in the run store). Runs without estimates (skipped) are passed over; with ``smoothed``, only runs that
    have a smoothed trajectory are written.

    Parameters
    ----------
    results : path-like
        The results folder (the one holding ``runs/``).
    out : path-like
        The output folder.
    datasets, filters : iterable of str
        Only these dataset / filter names (as stored: ``room[kidnap_m=2]``); empty = all.
    smoothed : bool
        Export the smoothed trajectories instead of the filtered ones.

    Returns
    -------
    list of Path
        Every file written, in order.
    """
    store = Store(results)
    want_d, want_f = set(datasets), set(filters)
    root = Path(out)
    written: list[Path] = []
    truths: set[tuple[str, int]] = set()
    for run_dir in store.iter_runs():
        rec = store.read_run(run_dir)
        dname, fname, seed = str(rec.meta["dataset"]), str(rec.meta["filter"]), int(rec.meta["seed"])
        if (want_d and dname not in want_d) or (want_f and fname not in want_f):
            continue
        if rec.t.shape[0] == 0 or (smoothed and "smoothed_t" not in rec.extra):
            continue
        rel = run_dir.relative_to(store.runs)
        written.append(export_tum(rec, (root / rel).with_suffix(".tum"), smoothed=smoothed))
        if (dname, seed) not in truths and store.has_truth(dname, seed):
            truths.add((dname, seed))
            truth_rel = store.truth_path(dname, seed).relative_to(store.runs)
            written.append(export_truth_tum(store.read_truth(dname, seed), (root / truth_rel).with_suffix(".tum")))
    return written


def export_textlog(spec: str, seed: int, out: str | os.PathLike[str]) -> tuple[Path, list[str]]:
    """Write the realisation ``seed`` of dataset ``spec`` as a plain-text log (``locbench-textlog``).

    Read back as ``textlog[path=OUT]``, it gives filters the same events, map, noise and initial belief, so a
    deterministic filter's estimates are bit-identical (a randomised one's too, given the same generators: through
    ``locbench run`` its draws are keyed by the dataset's name, which differs).

    Parameters
    ----------
    spec : str
        Any registered dataset with parameters (``room``, ``office[kidnap_m=2]``, ``plaza[run=1]``).
    seed : int
        The realisation (recordings: any seed is the same data).
    out : path-like
        The folder to write (created; an existing one must be empty or a textlog).

    Returns
    -------
    (Path, list of str)
        The folder, and notes on what does not read back exactly (see
        :func:`~locbench.datasets.recorded.textlog.write_textlog`).
    """
    from locbench.datasets.dataset import SyntheticBuilder
    from locbench.datasets.recorded.common import RecordedDataset
    from locbench.datasets.recorded.textlog import write_textlog
    from locbench.registry import DATASETS, make_dataset, resolve_dataset

    r = resolve_dataset(spec)
    cls = DATASETS.load(r.id)
    kind = "simulation" if issubclass(cls, SyntheticBuilder) else ""
    if issubclass(cls, RecordedDataset):
        kind = cls.reference_kind
    ds = make_dataset(r, seed)
    notes = write_textlog(ds, out, source=f"{r.name} seed {seed}", reference_kind=kind)
    for f in Path(out).iterdir():
        if f.is_file() and not f.is_symlink():
            _umask_mode(f)
    return Path(out), notes
