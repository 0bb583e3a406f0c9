"""Tuning a filter's declared parameters on train data, and the suite that reports tuned against default on test data.

:func:`tune` searches the tunable fields of a filter's config (:mod:`locbench.tunable`) with optuna's TPE sampler.
Each trial is one filter spec holding the trial's values (``ekf_landmarks[sigma_range_m=0.031]``); its runs on the
train datasets and seeds are planned and executed by :func:`locbench.runner.plan_sweep` and
:func:`locbench.runner.run_sweep` (any executor) and stored as ordinary runs in ``<results>/tuning`` (a store of its
own, so that no train run ever enters the report's tables), so a trial whose runs are stored is read back, never
recomputed. The first trial of every study is the default, the plain spec with no tunable field overridden (a field
whose default is the dataset's nominal value stays so), and counts in the budget: N trials are the default and N - 1
searched ones, and the best is the best of them all, so it is never worse than the default on the train data. The
objective is the mean over the train runs of their ATE (or NLL); a trial with a failed or diverged run, or a
non-finite value, scores :data:`WORST` (+inf), worse than any finite one.

The study lives in an optuna journal file under ``<results>/tuning/studies/`` that several processes may share:
rerunning the same command resumes it. The sampler is re-seeded before each trial from the number of trials
finished or running, so an interrupted and resumed study asks the same trials as one run straight through
(an interrupted trial is marked failed, which the sampler ignores, and asked again).

The protocol (docs/protocols.md, "Tuning"): train seeds start at :data:`TRAIN_SEED_START`, disjoint from the test
seeds 0 .. N-1 of the comparison; recordings are split by robot (MRCLAM Dataset 6 robots 1-3 tune, 4-5 test); every
filter gets the same budget, trials x train runs; a tuned configuration is only reported on its test data.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import hashlib
import json
import logging
import math
import os
import signal
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from locbench.errors import ConfigError, DependencyNotInstalled, LocbenchError
from locbench.registry import FILTERS, resolve_dataset, resolve_filter
from locbench.spec import format_spec, non_default_params, parse_spec
from locbench.store import Store
from locbench.tunable import TunableRange, tunable_fields

log = logging.getLogger(__name__)

#: The first train seed: train seeds are TRAIN_SEED_START .. + K - 1, disjoint from the test seeds 0 .. N - 1.
TRAIN_SEED_START = 1000
#: The score of a trial with a failed or diverged run (or a non-finite objective): worse than any finite value.
WORST = math.inf
#: Objective name -> the per-run metric whose mean over the train runs is minimised.
OBJECTIVES = {"ate": "ate_m", "nll": "nll"}
#: Significant digits of a trial's values in its spec (a short name that runs as printed).
SPEC_DIGITS = 4
#: The folder of the train runs and the studies inside a results folder.
TUNING_DIR = "tuning"
#: What the tuned suite writes after tuning: each study's trials and best configuration, for the report.
SUMMARY_FILE = "tuned.json"
#: The study protocol's version, in a journal's name: a journal of an older protocol (no default trial) is not resumed.
STUDY_VERSION = 2
#: The user attribute that marks a study's default trial (the plain spec, evaluated first).
DEFAULT_ATTR = "default"


def _optuna() -> Any:
    try:
        import optuna
    except ImportError:
        raise DependencyNotInstalled("tuning needs optuna; install it with: pip install 'locbench[tune]'") from None
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    return optuna


def train_seeds(k: int) -> list[int]:
    """The ``k`` train seeds: TRAIN_SEED_START .. TRAIN_SEED_START + k - 1."""
    if k < 1:
        raise ConfigError(f"--seeds must be >= 1, got {k}")
    return list(range(TRAIN_SEED_START, TRAIN_SEED_START + k))


def search_space(filter_spec: str) -> tuple[str, dict[str, str], dict[str, TunableRange]]:
    """The filter id, the parameters the spec fixes, and the tunable fields left free (those the spec does not set).

    Raises :class:`ConfigError` when nothing is left to tune.
    """
    resolve_filter(filter_spec)  # an unknown id or parameter fails here, with the valid ones
    ident, fixed = parse_spec(filter_spec)
    free = {k: r for k, r in tunable_fields(FILTERS.load(ident).Config).items() if k not in fixed}
    if not free:
        raise ConfigError(f"{filter_spec}: no tunable parameter left (see 'locbench list {ident}')")
    return ident, fixed, free


def _round(value: Any) -> Any:
    if isinstance(value, float):
        return float(f"{value:.{SPEC_DIGITS}g}")
    return value


def trial_spec(ident: str, fixed: dict[str, str], values: dict[str, Any]) -> str:
    """The canonical spec of one trial: the fixed parameters and the trial's values (rounded), defaults dropped."""
    spelled = format_spec(ident, {**fixed, **{k: _round(v) for k, v in values.items()}})
    return resolve_filter(spelled).name


def study_name(filter_spec: str, datasets: Sequence[str], seeds: int, objective: str) -> str:
    """The identity of a study: the filter, the train datasets (canonical, in order), the seed count, the objective."""
    names = ",".join(resolve_dataset(d).name for d in datasets)
    return f"{resolve_filter(filter_spec).name} on {names} x {seeds} seeds, {objective}"


def journal_path(results: str | os.PathLike[str], name: str) -> Path:
    """Where a study's journal lies: ``<results>/tuning/studies/<filter id>-<hash of the name and
    STUDY_VERSION>.journal``."""
    ident = name.split("[", 1)[0].split(" ", 1)[0]
    digest = hashlib.sha256(f"{name} v{STUDY_VERSION}".encode()).hexdigest()[:12]
    return Path(results) / TUNING_DIR / "studies" / f"{ident}-{digest}.journal"


@dataclass(frozen=True)
class TrialOutcome:
    """One finished trial: its number, spec, objective value (WORST when a run failed) and why it failed."""

    number: int
    spec: str
    value: float
    message: str = ""


@dataclass
class TuneResult:
    """A study's state after :func:`tune`: every finished trial in order and the best configuration."""

    name: str
    filter: str
    datasets: tuple[str, ...]
    seeds: tuple[int, ...]
    objective: str
    trials: list[TrialOutcome] = field(default_factory=list)
    interrupted: bool = False
    #: Trials whose runs were all stored already (read back, nothing computed).
    reused: int = 0

    @property
    def budget_runs(self) -> int:
        """Train runs per trial times trials: the budget the protocol gives every filter."""
        return len(self.trials) * len(self.datasets) * len(self.seeds)

    @property
    def best(self) -> TrialOutcome | None:
        """The finished trial with the lowest finite value (the earliest on a tie, so the default, trial 0, wins
        ties), or None."""
        finite = [t for t in self.trials if math.isfinite(t.value)]
        return min(finite, key=lambda t: (t.value, t.number)) if finite else None

    @property
    def default_kept(self) -> bool:
        """Whether the best configuration is the default (the plain spec): no searched trial beat it."""
        best = self.best
        return best is not None and best.spec == self.filter

    def best_so_far(self) -> list[float]:
        """The best value after each finished trial (+inf until a trial scores)."""
        out, best = [], WORST
        for t in self.trials:
            best = min(best, t.value)
            out.append(best)
        return out


def _distribution(optuna: Any, rng: TunableRange) -> Any:
    d = optuna.distributions
    if rng.kind == "choice":
        return d.CategoricalDistribution(list(rng.choices))
    if rng.kind == "int":
        return d.IntDistribution(int(rng.low), int(rng.high), log=rng.log)
    return d.FloatDistribution(rng.low, rng.high, log=rng.log)


def score_trial(
    store: Store, spec: str, datasets: Sequence[str], seeds: Sequence[int], objective: str
) -> tuple[float, str]:
    """The objective of one trial from its stored runs: the mean of the metric over them, or WORST and why.

    Raises :class:`ConfigError` for a skipped run (the filter cannot run on a train dataset, or its data is absent):
    that is a wrong command, not a bad trial.
    """
    from locbench.metrics import align, ate, nll_at_truth

    values: list[float] = []
    for d in datasets:
        dname = resolve_dataset(d).name
        for seed in seeds:
            meta = store.existing_meta(dname, spec, seed) or {}
            status = str(meta.get("status", "not stored"))
            if status == "skipped":
                raise ConfigError(f"{spec} does not run on {dname}: {meta.get('message', '')}")
            if status != "ok":
                return WORST, f"{status} on {dname} seed {seed}: {meta.get('message', '')}".rstrip(": ")
            run = store.read_run(store.run_dir(dname, spec, seed))
            gt = store.read_truth(dname, seed).ground_truth
            aligned = align(run.t, run.mean, gt.t, gt.poses, run.cov)
            v = ate(aligned) if objective == "ate" else float(np.mean(nll_at_truth(aligned)))
            if not math.isfinite(v):
                return WORST, f"non-finite {OBJECTIVES[objective]} on {dname} seed {seed}"
            values.append(float(v))
    return float(np.mean(values)), ""


def _outcomes(optuna: Any, study: Any) -> list[TrialOutcome]:
    done = study.get_trials(deepcopy=False, states=(optuna.trial.TrialState.COMPLETE,))
    return [
        TrialOutcome(t.number, str(t.user_attrs.get("spec", "")), float(t.value), str(t.user_attrs.get("message", "")))
        for t in sorted(done, key=lambda t: t.number)
    ]


def tune(
    filter_spec: str,
    datasets: Sequence[str],
    trials: int,
    seeds: int,
    results: str | os.PathLike[str],
    *,
    executor: str = "local",
    jobs: int = 1,
    scheduler: str | None = None,
    objective: str = "ate",
    sampler_seed: int = 0,
    fail_stale: bool = False,
    progress: Callable[[TrialOutcome], None] | None = None,
) -> TuneResult:
    """Tune the free tunable fields of ``filter_spec`` on ``datasets`` x ``seeds`` train seeds, to ``trials`` trials.

    Parameters
    ----------
    filter_spec : str
        A filter id, or a spec whose parameters stay fixed (``ekf_landmarks[association=nearest]``).
    datasets : sequence of str
        The train dataset specs (never a test dataset: the protocol's split, docs/protocols.md).
    trials : int
        Finished trials the study should hold, the default (trial 0) included; a rerun with more continues it.
    seeds : int
        Train seeds per dataset, :func:`train_seeds`.
    results : path
        The results folder: train runs go to ``<results>/tuning/runs``, the study to ``<results>/tuning/studies``.
    executor, jobs, scheduler
        Where each trial's runs execute, as for :func:`locbench.runner.run_sweep`.
    objective : {"ate", "nll"}
        The per-run metric whose mean is minimised.
    sampler_seed : int
        The TPE sampler's base seed: the same command asks the same trials.
    fail_stale : bool
        Mark trials left running by a killed process as failed before resuming (only for a study no other process
        is working on, as the tuned suite's own).
    progress : callable, optional
        Called with each trial as it finishes.
    """
    # long: the study's lifecycle (claim the folder, resume, trials through the executor, best spec) in order; numpydoc
    if objective not in OBJECTIVES:
        raise ConfigError(f"unknown objective {objective!r}; valid: {', '.join(OBJECTIVES)}")
    if trials < 1:
        raise ConfigError(f"--trials must be >= 1, got {trials}")
    if not datasets:
        raise ConfigError("tuning needs at least one --dataset")
    ident, fixed, space = search_space(filter_spec)
    seed_list = train_seeds(seeds)
    dnames = tuple(resolve_dataset(d).name for d in datasets)
    optuna = _optuna()
    from optuna.storages import JournalStorage
    from optuna.storages.journal import JournalFileBackend

    from locbench.runner import plan_sweep, run_sweep

    name = study_name(filter_spec, datasets, seeds, objective)
    path = journal_path(results, name)
    # both folders are locbench's before anything is written in them (another tool's folder is refused)
    Store(results).claim()
    Store(Path(results) / TUNING_DIR).claim()
    path.parent.mkdir(parents=True, exist_ok=True)
    storage = JournalStorage(JournalFileBackend(str(path)))
    study = optuna.create_study(study_name=name, storage=storage, direction="minimize", load_if_exists=True)
    states = optuna.trial.TrialState
    if fail_stale:
        for t in study.get_trials(deepcopy=False, states=(states.RUNNING,)):
            storage.set_trial_state_values(t._trial_id, states.FAIL)
    dists = {k: _distribution(optuna, r) for k, r in space.items()}
    train_root = Path(results) / TUNING_DIR
    store = Store(train_root)
    plain = resolve_filter(filter_spec).name
    result = TuneResult(name, plain, dnames, tuple(seed_list), objective)
    while True:
        live = study.get_trials(deepcopy=False, states=(states.COMPLETE, states.RUNNING))
        if len(live) >= trials:
            break
        # The default (the plain spec: a None field stays the dataset's nominal value) is the first trial and counts
        # in the budget, so the best is never worse on the train data than the default.
        with_default = not any(t.user_attrs.get(DEFAULT_ATTR) for t in live)
        if with_default:
            trial = study.ask()  # no parameters: the sampler's observations of each parameter leave it out
        else:
            # Re-seeded per trial from the study's state: a resumed study asks what an uninterrupted one would have.
            # The startup count includes the default, which has no parameters: half the searched trials are random.
            startup = 1 + max(2, (trials - 1) // 2)
            study.sampler = optuna.samplers.TPESampler(
                seed=sampler_seed + len(live), n_startup_trials=startup, constant_liar=True
            )
            trial = study.ask(dists)
        try:
            spec = plain if with_default else trial_spec(ident, fixed, trial.params)
            trial.set_user_attr("spec", spec)
            if with_default:
                trial.set_user_attr(DEFAULT_ATTR, True)
            plan = plan_sweep([([spec], dnames, seed_list)], str(train_root))
            if not plan.tasks:
                result.reused += 1
            sweep = run_sweep(plan, executor, jobs, scheduler)
            if sweep.interrupted:
                raise KeyboardInterrupt
            value, message = score_trial(store, spec, dnames, seed_list, objective)
        except BaseException as exc:
            # Ctrl-C or an error of the command: the trial is failed (the sampler ignores it), never left running
            trial.set_user_attr("message", "interrupted" if isinstance(exc, KeyboardInterrupt) else str(exc))
            study.tell(trial, state=states.FAIL)
            if not isinstance(exc, KeyboardInterrupt):
                raise
            result.interrupted = True
            break
        if message:
            trial.set_user_attr("message", message)
        study.tell(trial, value)
        if progress is not None:
            progress(TrialOutcome(trial.number, spec, value, message))
    result.trials = _outcomes(optuna, study)
    return result


# --- the tuned suite -----------------------------------------------------------------------------------------


#: Trials per study and train runs per trial of the tuned suite: the budget every filter gets (docs/protocols.md).
SUITE_TRIALS = 4
SUITE_TRAIN_SEEDS = 3
#: The test seeds of the synthetic worlds: the main comparison's own (suite ``default``), so the default rows are
#: the stored ones and tuned and default runs are paired by seed.
SUITE_TEST_SEEDS = 20
#: MRCLAM Dataset 6: robots 1-3 tune (one run each, 3 train runs per trial as on the worlds), robots 4-5 test.
MRCLAM_TRAIN = tuple(f"mrclam[robot={r}]" for r in (1, 2, 3))
MRCLAM_TEST = tuple(f"mrclam[robot={r}]" for r in (4, 5))
SYNTHETIC_WORLDS = ("room", "office")


@dataclass(frozen=True)
class SuiteStudy:
    """One study of the tuned suite: a filter tuned on train data, and the test data its best configuration runs on."""

    filter: str
    train: tuple[str, ...]
    seeds: int
    test: tuple[str, ...]
    test_seeds: tuple[int, ...]

    @property
    def world(self) -> str:
        """The study's data, as the report names it: the world, or ``mrclam`` for the recordings."""
        return parse_spec(self.train[0])[0]


def tuned_filters() -> list[str]:
    """The filters of the main comparison that declare tunable fields (odometry declares none); a filter whose
    optional dependency is not installed is left out, with a warning."""
    from locbench.suites import ALL_FILTERS

    out = []
    for f in ALL_FILTERS:
        missing = FILTERS.missing_dependency(f)
        if missing is not None:
            log.warning("suite tuned leaves out %s: %s", f, missing)
        elif tunable_fields(FILTERS.load(f).Config):
            out.append(f)
    return out


def suite_studies() -> list[SuiteStudy]:
    """Every study of the tuned suite: each tunable filter on each world it runs on, and the landmark filters on
    the MRCLAM train robots; in a fixed order."""
    from locbench.datasets.base import MapKind

    out: list[SuiteStudy] = []
    for f in tuned_filters():
        cls = FILTERS.load(f)
        # room and the recordings have landmarks only: a filter that needs a line or occupancy map skips them
        landmark_only = cls.requires <= {MapKind.LANDMARKS}
        for world in SYNTHETIC_WORLDS:
            if world == "room" and not landmark_only:
                continue
            test = tuple(range(SUITE_TEST_SEEDS))
            out.append(SuiteStudy(f, (world,), SUITE_TRAIN_SEEDS, (world,), test))
        if landmark_only:
            out.append(SuiteStudy(f, MRCLAM_TRAIN, 1, MRCLAM_TEST, (0,)))
    return out


def _study_available(s: SuiteStudy) -> str | None:
    from locbench.registry import DATASETS

    for d in (*s.train, *s.test):
        reason = DATASETS.unavailable_reason(parse_spec(d)[0])
        if reason is not None:
            return f"{d}: {reason}"
    reason = FILTERS.missing_dependency(s.filter)
    return reason


def _run_study(s: SuiteStudy, results: str, trials: int) -> TuneResult:
    return tune(s.filter, s.train, trials, s.seeds, results, fail_stale=True)


def _pool_init() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@dataclass
class SuiteResult:
    """What :func:`run_tuned_suite` did: each study's result, the skipped studies, the test sweep's outcomes."""

    studies: list[tuple[SuiteStudy, TuneResult]]
    skipped: list[tuple[SuiteStudy, str]]
    outcomes: list[Any]
    interrupted: bool = False


def run_tuned_suite(
    results: str,
    *,
    executor: str = "local",
    jobs: int = 1,
    scheduler: str | None = None,
    trials: int = SUITE_TRIALS,
    studies: Sequence[SuiteStudy] | None = None,
) -> SuiteResult:
    """Tune every study of the suite, then run each best configuration and the default on the test data.

    With the local executor the studies run in a pool of ``jobs`` processes, one study per process at a time (a
    trial's few runs would not fill a pool); with dask each trial's runs go to the dask workers. The test runs are
    one sweep into ``results`` (the default rows are the comparison's stored runs where present). Writes
    ``<results>/tuning/tuned.json`` for the report.
    """
    from locbench.runner import plan_sweep, run_sweep

    todo = list(studies) if studies is not None else suite_studies()
    ready: list[SuiteStudy] = []
    skipped: list[tuple[SuiteStudy, str]] = []
    for s in todo:
        reason = _study_available(s)
        (skipped.append((s, reason)) if reason else ready.append(s))
    done: list[tuple[SuiteStudy, TuneResult]] = []
    interrupted = False
    if executor == "local" and jobs > 1 and len(ready) > 1:
        # Longest first: the recordings' studies of the particle filter dominate.
        order = sorted(ready, key=lambda s: (not s.train[0].startswith("mrclam"), s.filter != "pf"))
        pool = cf.ProcessPoolExecutor(max_workers=jobs, initializer=_pool_init)
        futures = {pool.submit(_run_study, s, results, trials): s for s in order}
        try:
            for fut in cf.as_completed(futures):
                try:
                    done.append((futures[fut], fut.result()))
                except Exception as exc:  # a study that fails is reported, and the others go on
                    skipped.append((futures[fut], f"failed: {type(exc).__name__}: {exc}"))
        except KeyboardInterrupt:
            interrupted = True
            for proc in list(getattr(pool, "_processes", {}).values()):
                with contextlib.suppress(Exception):
                    proc.kill()
        finally:
            pool.shutdown(wait=not interrupted, cancel_futures=True)
    else:
        for s in ready:
            try:
                r = tune(s.filter, s.train, trials, s.seeds, results, executor=executor, jobs=jobs, scheduler=scheduler)
            except LocbenchError as exc:
                skipped.append((s, f"failed: {exc}"))
                continue
            done.append((s, r))
            if r.interrupted:
                interrupted = True
                break
    if interrupted or any(r.interrupted for _, r in done):
        return SuiteResult(done, skipped, [], True)
    index = {id(s): i for i, s in enumerate(ready)}
    done.sort(key=lambda sr: index[id(sr[0])])
    blocks: list[tuple[Sequence[str], Sequence[str], Sequence[int]]] = []
    for s, r in done:
        best = r.best
        plain = resolve_filter(s.filter).name
        specs = [plain] + ([best.spec] if best is not None and best.spec != plain else [])
        blocks.append((specs, s.test, s.test_seeds))
    plan = plan_sweep(blocks, results)
    sweep = run_sweep(plan, executor, jobs, scheduler)
    write_summary(results, done)
    return SuiteResult(done, skipped, sweep.outcomes, sweep.interrupted)


def write_summary(results: str, done: Sequence[tuple[SuiteStudy, TuneResult]]) -> Path:
    """Write ``<results>/tuning/tuned.json``: per study the filter, data, budget, trials and best configuration."""
    out = []
    for s, r in done:
        best = r.best
        default_cfg = resolve_filter(s.filter).params
        tuned_cfg = non_default_params(resolve_filter(best.spec).params) if best else {}
        _, _, space = search_space(s.filter)
        out.append(
            {
                "filter": s.filter,
                "world": s.world,
                "train": list(s.train),
                "train_seeds": list(r.seeds),
                "test": list(s.test),
                "test_seeds": list(s.test_seeds),
                "objective": r.objective,
                "trials": [asdict(t) for t in r.trials],
                "budget_runs": r.budget_runs,
                "best_spec": best.spec if best else None,
                "best_value": best.value if best else None,
                "default_kept": r.default_kept,
                "tuned": {k: tuned_cfg.get(k, getattr(default_cfg, k)) for k in space} if best else {},
                "defaults": {k: getattr(default_cfg, k) for k in space},
                "ranges": {k: rng.describe() for k, rng in space.items()},
            }
        )
    path = Path(results) / TUNING_DIR / SUMMARY_FILE
    path.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps(out, indent=1, default=str, allow_nan=True) + "\n"
    tmp = path.with_name(f".tmp-{SUMMARY_FILE}")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(path)
    return path


def read_summary(results: str | os.PathLike[str]) -> list[dict[str, Any]]:
    """The tuned suite's summary (``tuned.json``), or an empty list when the suite has not run."""
    path = Path(results) / TUNING_DIR / SUMMARY_FILE
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return []
    except (OSError, json.JSONDecodeError) as exc:
        raise ConfigError(f"{path}: unreadable tuning summary ({exc}); rerun 'locbench run --suite tuned'") from None
    return data if isinstance(data, list) else []


def tuned_cells(results: str | os.PathLike[str]) -> set[tuple[str, str]]:
    """The (dataset, filter) cells of the tuned suite's test runs: default and tuned configuration on the test data."""
    cells: set[tuple[str, str]] = set()
    for st in read_summary(results):
        for d in st["test"]:
            dname = resolve_dataset(d).name
            cells.add((dname, resolve_filter(st["filter"]).name))
            if st.get("best_spec"):
                cells.add((dname, str(st["best_spec"])))
    return cells
