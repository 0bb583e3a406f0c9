"""Tuning a filter's declared parameters on train data, and the suite that reports tuned against default on test data.

:func:`tune` searches the tunable fields of a filter's config (:mod:`locbench.core.tunable`) with optuna's TPE sampler.
Each trial is one filter spec holding the trial's values (``ekf_landmarks[sigma_range_m=0.031]``); its runs on the
train datasets and seeds are planned and executed by :func:`locbench.run.plan.plan_sweep` and
:func:`locbench.run.sweep.run_sweep` (any executor) and stored as ordinary runs in ``<results>/tuning`` (a store of its
own, so that no train run ever enters the report's tables), so a trial whose runs are stored is read back, never
recomputed. The first trial of every study is the default, the plain spec with no tunable field overridden (a field
whose default is the dataset's nominal value stays so), and counts in the budget: N trials are the default and N - 1
searched ones, and the best is the best of them all, so it is never worse than the default on the train data. The
objective is the mean over the train runs of their ATE (or NLL); a trial with a failed or diverged run, or a
non-finite value, scores :data:`WORST` (+inf), worse than any finite one.

The study lives in an optuna journal file under ``<results>/tuning/studies/`` that several processes may share:
rerunning the same command resumes it. The sampler is re-seeded before each trial from the number of trials
finished or running, so an interrupted and resumed study asks the same trials as one run straight through
(an interrupted trial is marked failed, which the sampler ignores, and asked again). A trial left running by a
process that is gone (killed by SIGKILL, a crash) is marked failed when the study resumes and a replacement is
asked, so the study reaches its budget. A resumed journal is trusted only as far as the stored runs confirm it:
each finished trial's value is derived again from its runs (any run missing from the store is run again first) and
a journal whose value differs, or that is not an optuna journal at all, is refused with one line naming the file.

The protocol (docs/protocols.md, "Tuning"): train seeds start at :data:`TRAIN_SEED_START`, disjoint from the test
seeds 0 .. N-1 of the comparison; the recordings are cross-validated by robot (MRCLAM Dataset 6, leave one robot
out: the configuration reported for robot k is tuned on the other four); every filter and study gets the same budget,
:data:`SUITE_TRIALS` trials x :data:`SUITE_TRAIN_RUNS` train runs, with optuna's multivariate TPE; a tuned
configuration is only reported on its test data.

Tuning and testing are two steps. :func:`tune_suite` (``locbench tune --suite``, ``nox -s tune``) runs every study
and writes the studies' journals and ``tuned.json`` (every trial's spec and objective, the budget, the sampler and
its seed, the commit and versions) into the results folder, where they are committed; :func:`run_tuned_suite`
(``locbench run --suite tuned``, part of ``nox -s bench``) reads them and runs each tuned configuration and its
default on the test data only. :func:`verify_trials` re-runs a sample of the committed trials and compares their
objective with the journal's.
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
import socket
import warnings
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from locbench.core.errors import ConfigError, DependencyNotInstalled, LocbenchError, one_line, shown
from locbench.core.spec import format_spec, non_default_params, parse_spec
from locbench.core.tunable import TunableRange, tunable_fields
from locbench.datasets.splits import TUNING_SEED_START, test_seeds, tuning_seeds
from locbench.datasets.splits import mrclam_folds as splits_mrclam_folds
from locbench.evaluate.metrics import ATE_M, NLL
from locbench.registry import FILTERS, resolve_dataset, resolve_filter
from locbench.run.store import Store
from locbench.suites import MAX_SEEDS, check_seeds

log = logging.getLogger(__name__)

#: The first train seed: train seeds are TRAIN_SEED_START .. + K - 1, disjoint from the test seeds 0 .. N - 1 (the
#: tuning seeds of :mod:`locbench.datasets.splits`).
TRAIN_SEED_START = TUNING_SEED_START
#: The score of a trial with a failed or diverged run (or a non-finite objective): worse than any finite value.
WORST = math.inf
#: Objective name -> the per-run metric whose mean over the train runs is minimised.
OBJECTIVES = {"ate": ATE_M, "nll": NLL}
#: Significant digits of a trial's values in its spec (a short name that runs as printed).
SPEC_DIGITS = 4
#: The folder of the train runs and the studies inside a results folder.
TUNING_DIR = "tuning"
#: What the tuned suite writes after tuning: each study's trials and best configuration, for the report.
SUMMARY_FILE = "tuned.json"
#: The study protocol's version, in a journal's name: a journal of an older protocol (no default trial, a univariate
#: sampler) is not resumed.
STUDY_VERSION = 3
#: Random trials before TPE models the observations (optuna's own default), after the default trial.
STARTUP_TRIALS = 10
#: The user attribute that marks a study's default trial (the plain spec, evaluated first).
DEFAULT_ATTR = "default"
#: The user attribute naming the process that runs a trial (host, pid, start time): a trial left running by a
#: process that is gone is failed when the study resumes.
OWNER_ATTR = "owner"
#: Most trials a study may hold (``--trials``).
MAX_TRIALS = 10_000


def _optuna() -> Any:
    try:
        import optuna
    except ImportError:
        raise DependencyNotInstalled("tuning needs optuna; install it with: pip install 'locbench[tune]'") from None
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    return optuna


def train_seeds(k: int, limit: int = MAX_SEEDS) -> list[int]:
    """The ``k`` train seeds: TRAIN_SEED_START .. TRAIN_SEED_START + k - 1 (``k`` in 1 .. ``limit``, as ``run``)."""
    return list(tuning_seeds(check_seeds(k, limit, "--seeds")))


def check_trials(trials: object) -> int:
    """``trials`` when it is an integer 1 .. :data:`MAX_TRIALS`; a one-line :class:`ConfigError` otherwise."""
    if not isinstance(trials, int) or isinstance(trials, bool) or not 1 <= trials <= MAX_TRIALS:
        raise ConfigError(f"--trials must be an integer in 1..{MAX_TRIALS}, got {shown(trials)}")
    return trials


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
    from locbench.evaluate.metrics import align, ate, nll_at_truth

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


def _process_start(pid: int) -> str:
    """When process ``pid`` started, in clock ticks since boot (Linux ``/proc``), or "" where that is not known."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text(encoding="ascii", errors="replace")
    except OSError:
        return ""
    # the command name (field 2) may hold spaces and brackets: the fields after its last ')' are fixed
    fields = stat.rsplit(")", 1)[-1].split()
    return fields[19] if len(fields) > 19 else ""


def _owner() -> dict[str, Any]:
    """This process as a trial's owner: host name, pid and start time (the pair tells a reused pid apart)."""
    return {"host": socket.gethostname(), "pid": os.getpid(), "start": _process_start(os.getpid())}


def _owner_gone(owner: Any) -> bool:
    """Whether the process that owns a running trial is gone: on this host, its pid is free or now names another
    process (a different start time). A trial of another host, or with no owner recorded, is never judged gone."""
    if not isinstance(owner, dict) or owner.get("host") != socket.gethostname():
        return False
    pid = owner.get("pid")
    if not isinstance(pid, int) or isinstance(pid, bool) or pid <= 0:
        return False
    if pid == os.getpid():
        return True  # this process has only just started: the trial's owner was an earlier one with the same pid
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except PermissionError:
        pass  # a process of another user holds the pid: alive, and not ours unless it started at our owner's time
    start = _process_start(pid)
    return bool(start and owner.get("start") and start != owner.get("start"))


def fail_dead_trials(optuna: Any, study: Any, storage: Any, path: Path, every: bool = False) -> list[int]:
    """Mark failed each trial left running by a process that is gone (``every``: each running trial); their numbers.

    A trial that is running when a study resumes was either killed with its process (SIGKILL, a crash, the machine
    stopped) or belongs to another process tuning the same study now; only the first is failed, so the study asks
    a replacement and reaches its budget. Judged by the owner each trial records (:data:`OWNER_ATTR`).
    """
    states = optuna.trial.TrialState
    failed = []
    for t in study.get_trials(deepcopy=False, states=(states.RUNNING,)):
        if every or _owner_gone(t.user_attrs.get(OWNER_ATTR)):
            storage.set_trial_user_attr(t._trial_id, "message", "its process died; failed when the study resumed")
            storage.set_trial_state_values(t._trial_id, states.FAIL)
            failed.append(t.number)
    if failed:
        log.warning("%s: trial(s) %s left running by a process that is gone: marked failed", path, failed)
    return failed


#: The operations an optuna journal holds (its ``op_code``), 0 .. this - 1.
_JOURNAL_OPS = 9


def open_journal(optuna: Any, path: Path, name: str) -> tuple[Any, Any]:
    """The storage and study of the journal ``path`` (created when absent); a one-line :class:`ConfigError` naming
    the file when it is not an optuna journal: a line that is not a JSON operation, a last line without its newline
    (optuna would glue its next operation to it), or operations optuna cannot replay."""
    from optuna.storages import JournalStorage
    from optuna.storages.journal import JournalFileBackend

    expected = "expected an optuna journal (one JSON operation per line); delete it to start the study again"
    try:
        lines = path.read_bytes().split(b"\n") if path.exists() else [b""]
    except OSError as exc:
        raise ConfigError(f"{path}: unreadable study journal ({exc.strerror or exc})") from None
    if lines[-1]:
        raise ConfigError(f"{path}: line {len(lines)} has no newline (a write cut short, or not text); {expected}")
    for number, line in enumerate(lines[:-1], start=1):
        try:
            op = json.loads(line)
        except (UnicodeDecodeError, json.JSONDecodeError):
            raise ConfigError(f"{path}: line {number} is not JSON; {expected}") from None
        code = op.get("op_code") if isinstance(op, dict) else None
        if not isinstance(code, int) or isinstance(code, bool) or not 0 <= code < _JOURNAL_OPS:
            raise ConfigError(f"{path}: line {number} is not a journal operation (no valid op_code); {expected}")
    try:
        storage = JournalStorage(JournalFileBackend(str(path)))
        study = optuna.create_study(study_name=name, storage=storage, direction="minimize", load_if_exists=True)
        study.get_trials(deepcopy=False)
    except (KeyError, IndexError, TypeError, ValueError, AttributeError) as exc:
        reason = one_line(f"{type(exc).__name__}: {exc}", 200)
        raise ConfigError(f"{path}: optuna cannot replay it ({reason}); {expected}") from None
    return storage, study


def check_journal(
    optuna: Any,
    study: Any,
    path: Path,
    trusted: set[int],
    expected_spec: Callable[[Any], str],
    rescore: Callable[[str], tuple[float, str]],
) -> None:
    """Refuse a journal whose finished trials do not match their stored runs; ``trusted`` (trial numbers) grows.

    Each finished trial's spec must be the one its parameters give (``expected_spec``), and its value the one its
    runs give now (``rescore``, which first re-runs any run that is not stored: runs are deterministic, so a run
    lost from the store comes back as it was). A mismatch is a :class:`ConfigError` naming the journal, the
    trial and the two values: the journal was edited, or its runs changed since.
    """
    done = study.get_trials(deepcopy=False, states=(optuna.trial.TrialState.COMPLETE,))
    advice = "the journal was edited or its runs changed; delete it to tune again"
    for t in sorted(done, key=lambda t: t.number):
        if t.number in trusted:
            continue
        recorded = t.user_attrs.get("spec")
        spec = expected_spec(t)
        if recorded != spec:
            raise ConfigError(f"{path}: trial {t.number} records spec {shown(recorded)}, its parameters give {spec}")
        value, _ = rescore(spec)
        if not (value == t.value or (math.isnan(value) and math.isnan(t.value))):
            raise ConfigError(
                f"{path}: trial {t.number} ({spec}) has value {t.value!r} in the journal but {value!r} from its "
                f"stored runs; {advice}"
            )
        trusted.add(t.number)


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
    max_seeds: int = MAX_SEEDS,
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
        Where each trial's runs execute, as for :func:`locbench.run.sweep.run_sweep`.
    objective : {"ate", "nll"}
        The per-run metric whose mean is minimised.
    sampler_seed : int
        The TPE sampler's base seed: the same command asks the same trials.
    fail_stale : bool
        Mark every trial left running as failed before resuming (only for a study no other process is working on,
        as the tuned suite's own); without it, only the trials whose process is gone (:func:`fail_dead_trials`).
    max_seeds : int
        Most train seeds per dataset (``--max-seeds``), as for ``locbench run``.
    progress : callable, optional
        Called with each trial as it finishes.
    """
    # long: the study's lifecycle (claim the folder, resume, trials through the executor, best spec) in order; numpydoc
    if objective not in OBJECTIVES:
        raise ConfigError(f"unknown objective {objective!r}; valid: {', '.join(OBJECTIVES)}")
    check_trials(trials)
    if not datasets:
        raise ConfigError("tuning needs at least one --dataset")
    ident, fixed, space = search_space(filter_spec)
    seed_list = train_seeds(seeds, max_seeds)
    dnames = tuple(resolve_dataset(d).name for d in datasets)
    optuna = _optuna()

    from locbench.run.execute import retained_realisations
    from locbench.run.plan import plan_sweep
    from locbench.run.sweep import run_sweep

    name = study_name(filter_spec, datasets, seeds, objective)
    path = journal_path(results, name)
    # both folders are locbench's before anything is written in them (another tool's folder is refused)
    Store(results).claim()
    train_root = Path(results) / TUNING_DIR
    store = Store(train_root)  # the train runs' store, one for every trial of the study
    store.claim()
    path.parent.mkdir(parents=True, exist_ok=True)
    storage, study = open_journal(optuna, path, name)
    states = optuna.trial.TrialState
    fail_dead_trials(optuna, study, storage, path, every=fail_stale)
    dists = {k: _distribution(optuna, r) for k, r in space.items()}
    plain = resolve_filter(filter_spec).name
    result = TuneResult(name, plain, dnames, tuple(seed_list), objective)

    def run_trial(spec: str, checking: bool = False) -> tuple[float, str]:
        """Run what is not stored of ``spec``'s train runs, then score it from the store (``checking``: a finished
        trial's value re-derived, which runs nothing when its runs are stored and counts in no tally)."""
        plan = plan_sweep([([spec], dnames, seed_list)], store, derive=False)  # no report reads train runs
        if not plan.tasks and not checking:
            result.reused += 1
        if (plan.tasks or not checking) and run_sweep(plan, executor, jobs, scheduler).interrupted:
            raise KeyboardInterrupt
        return score_trial(store, spec, dnames, seed_list, objective)

    def rescore(spec: str) -> tuple[float, str]:
        return run_trial(spec, checking=True)

    def expected_spec(t: Any) -> str:
        return plain if t.user_attrs.get(DEFAULT_ATTR) else trial_spec(ident, fixed, t.params)

    # the study's train datasets are built once, not once per trial (the local executor runs them here)
    keep = retained_realisations(len(dnames) * len(seed_list)) if executor == "local" else contextlib.nullcontext()
    with keep:
        trusted: set[int] = set()  # finished trials whose value was checked against their runs, or computed here
        check_journal(optuna, study, path, trusted, expected_spec, rescore)
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
                # The startup count includes the default, which has no parameters: STARTUP_TRIALS random ones (half the
                # searched trials in a small study); multivariate, since noise scales and gates act together.
                startup = 1 + min(STARTUP_TRIALS, max(2, (trials - 1) // 2))
                # multivariate TPE is marked experimental since optuna 2.2; it is tested
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
                    study.sampler = optuna.samplers.TPESampler(
                        seed=sampler_seed + len(live), n_startup_trials=startup, constant_liar=True, multivariate=True
                    )
                trial = study.ask(dists)
            try:
                trial.set_user_attr(OWNER_ATTR, _owner())
                spec = plain if with_default else trial_spec(ident, fixed, trial.params)
                trial.set_user_attr("spec", spec)
                if with_default:
                    trial.set_user_attr(DEFAULT_ATTR, True)
                value, message = run_trial(spec)
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
            trusted.add(trial.number)
            if progress is not None:
                progress(TrialOutcome(trial.number, spec, value, message))
        # trials other processes finished meanwhile are checked like the journal's earlier ones
        check_journal(optuna, study, path, trusted, expected_spec, rescore)
    result.trials = _outcomes(optuna, study)
    return result


# --- the tuned suite -----------------------------------------------------------------------------------------


#: Trials per study and train runs per trial of the tuned suite: the budget every filter and every study gets
#: (docs/protocols.md, "Tuning"). 30 trials are the default, 10 random ones (:data:`STARTUP_TRIALS`) and 19 that the
#: multivariate TPE proposes, over 2-5 parameters per filter; 4 train runs are what leave-one-robot-out leaves on
#: MRCLAM (the other four robots, one run each), and the worlds get 4 train seeds to match.
SUITE_TRIALS = 30
SUITE_TRAIN_RUNS = 4
#: The TPE sampler's base seed of every study of the suite.
SUITE_SAMPLER_SEED = 0
#: The test seeds of the synthetic worlds: the main comparison's own (suite ``default``), so the default rows are
#: the stored ones and tuned and default runs are paired by seed.
SUITE_TEST_SEEDS = 20
SYNTHETIC_WORLDS = ("room", "office")
#: The format of ``tuned.json`` (2: an object with the budget, sampler and provenance around the studies).
SUMMARY_FORMAT = 2


def mrclam_folds() -> list[tuple[tuple[str, ...], str]]:
    """Leave-one-robot-out on MRCLAM Dataset 6 (:func:`locbench.datasets.splits.mrclam_folds`): per fold k, the
    train specs (the other robots, each given fold k's nominal noise, which was derived without robot k) and the
    test spec (robot k, with its own fold's noise, the default)."""
    out = []
    for fold in splits_mrclam_folds():
        (k,) = fold.test
        train = tuple(f"mrclam[robot={r},noise_fold={k}]" for r in fold.tuning)
        out.append((train, f"mrclam[robot={k}]"))
    return out


@dataclass(frozen=True)
class SuiteStudy:
    """One study of the tuned suite: a filter tuned on train data, and the test data its best configuration runs on.

    ``fold`` names the held-out unit of a cross-validated study (``robot 4``), "" for a world split by seed.
    """

    filter: str
    train: tuple[str, ...]
    seeds: int
    test: tuple[str, ...]
    test_seeds: tuple[int, ...]
    fold: str = ""

    @property
    def world(self) -> str:
        """The study's data, as the report names it: the world, or ``mrclam`` for the recordings."""
        return parse_spec(self.train[0])[0]

    def same_split(self, entry: dict[str, Any]) -> bool:
        """Whether a ``tuned.json`` study entry was tuned for this study (filter, train data and seeds, test data)."""
        return (
            entry.get("filter") == self.filter
            and list(entry.get("train", ())) == list(self.train)
            and len(entry.get("train_seeds", ())) == self.seeds
            and list(entry.get("test", ())) == list(self.test)
        )


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
    """Every study of the tuned suite: each tunable filter on each world it runs on (train seeds against the
    comparison's test seeds), and the landmark filters on each MRCLAM fold; in a fixed order."""
    from locbench.datasets.dataset import MapKind

    out: list[SuiteStudy] = []
    for f in tuned_filters():
        cls = FILTERS.load(f)
        # room and the recordings have landmarks only: a filter that needs a line or occupancy map skips them
        landmark_only = cls.requires <= {MapKind.LANDMARKS}
        for world in SYNTHETIC_WORLDS:
            if world == "room" and not landmark_only:
                continue
            test = test_seeds(SUITE_TEST_SEEDS)
            out.append(SuiteStudy(f, (world,), SUITE_TRAIN_RUNS, (world,), test))
        if landmark_only:
            for train, held_out in mrclam_folds():
                robot = resolve_dataset(held_out).params.robot
                out.append(SuiteStudy(f, train, 1, (held_out,), (0,), fold=f"robot {robot}"))
    return out


def _study_available(s: SuiteStudy) -> str | None:
    from locbench.registry import DATASETS

    for d in (*s.train, *s.test):
        reason = DATASETS.unavailable_reason(parse_spec(d)[0])
        if reason is not None:
            return f"{d}: {reason}"
    reason = FILTERS.missing_dependency(s.filter)
    return reason


def _run_study(s: SuiteStudy, results: str, trials: int, sampler_seed: int) -> TuneResult:
    return tune(s.filter, s.train, trials, s.seeds, results, fail_stale=True, sampler_seed=sampler_seed)


def _pool_init() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@dataclass
class SuiteResult:
    """What :func:`tune_suite` or :func:`run_tuned_suite` did: each study's result (tuning only), the skipped
    studies with why, the test sweep's outcomes (testing only)."""

    studies: list[tuple[SuiteStudy, TuneResult]]
    skipped: list[tuple[SuiteStudy, str]]
    outcomes: list[Any]
    interrupted: bool = False


def tune_suite(
    results: str,
    *,
    executor: str = "local",
    jobs: int = 1,
    scheduler: str | None = None,
    trials: int = SUITE_TRIALS,
    sampler_seed: int = SUITE_SAMPLER_SEED,
    studies: Sequence[SuiteStudy] | None = None,
) -> SuiteResult:
    """Run every study of the suite on its train data and write ``<results>/tuning/tuned.json``.

    With the local executor the studies run in a pool of ``jobs`` processes, one study per process at a time (a
    trial's few runs would not fill a pool); with dask each trial's runs go to the dask workers. Interrupted, the
    journals keep the finished trials and ``tuned.json`` is not written: the same command resumes.
    """
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
        futures = {pool.submit(_run_study, s, results, trials, sampler_seed): s for s in order}
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
                r = tune(
                    s.filter,
                    s.train,
                    trials,
                    s.seeds,
                    results,
                    executor=executor,
                    jobs=jobs,
                    scheduler=scheduler,
                    sampler_seed=sampler_seed,
                )
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
    write_summary(results, done, trials=trials, sampler_seed=sampler_seed)
    return SuiteResult(done, skipped, [])


def run_tuned_suite(
    results: str,
    *,
    executor: str = "local",
    jobs: int = 1,
    scheduler: str | None = None,
    studies: Sequence[SuiteStudy] | None = None,
) -> SuiteResult:
    """Run each tuned configuration of ``<results>/tuning/tuned.json`` and its default on the study's test data.

    Nothing is tuned here (:func:`tune_suite` does that, apart): a declared study with no entry in ``tuned.json``
    for its split, or whose tuned spec no longer resolves, is skipped with the reason. The test runs are one sweep
    into ``results`` (the default rows are the comparison's stored runs where present).

    Raises
    ------
    ConfigError
        ``tuned.json`` is absent or holds no study: tune first.
    """
    from locbench.run.plan import plan_sweep
    from locbench.run.sweep import run_sweep

    blocks, skipped = tuned_blocks(results, studies)
    plan = plan_sweep(blocks, results)
    sweep = run_sweep(plan, executor, jobs, scheduler)
    return SuiteResult([], skipped, sweep.outcomes, sweep.interrupted)


def tuned_blocks(
    results: str | os.PathLike[str], studies: Sequence[SuiteStudy] | None = None
) -> tuple[list[tuple[Sequence[str], Sequence[str], Sequence[int]]], list[tuple[SuiteStudy, str]]]:
    """Suite ``tuned``'s runs as sweep blocks: each study's default and tuned configuration on its test data, with
    the studies that cannot run and why (:func:`run_tuned_suite`). ``locbench run`` plans them with the other
    suites' blocks, so a test realisation the comparison runs on too is built once for both.

    Raises
    ------
    ConfigError
        ``tuned.json`` is absent or holds no study: tune first.
    """
    entries = read_summary(results)
    if not entries:
        raise ConfigError(
            f"{Path(results) / TUNING_DIR / SUMMARY_FILE}: no tuned configurations; tune first with "
            "'nox -s tune' (locbench tune --suite --results RESULTS)"
        )
    todo = list(studies) if studies is not None else suite_studies()
    skipped: list[tuple[SuiteStudy, str]] = []
    blocks: list[tuple[Sequence[str], Sequence[str], Sequence[int]]] = []
    for s in todo:
        entry = next((e for e in entries if s.same_split(e)), None)
        reason = _study_available(s)
        if reason is None and entry is None:
            reason = "not tuned for this split (tune with 'nox -s tune')"
        if reason is None and entry is not None:
            reason = _stale(entry)
        if reason is not None or entry is None:
            skipped.append((s, reason or ""))
            continue
        plain = resolve_filter(s.filter).name
        best = entry.get("best_spec")
        specs = [plain] + ([str(best)] if best and best != plain else [])
        blocks.append((specs, s.test, s.test_seeds))
    return blocks, skipped


def _stale(entry: dict[str, Any]) -> str | None:
    """Why a ``tuned.json`` entry cannot be run as tuned (its best spec no longer resolves), or None."""
    best = entry.get("best_spec")
    if not best:
        return "every trial of its study failed"
    try:
        resolve_filter(str(best))
    except LocbenchError as exc:
        return f"its tuned spec no longer resolves ({one_line(str(exc))}): tune again with 'nox -s tune'"
    return None


def write_summary(
    results: str,
    done: Sequence[tuple[SuiteStudy, TuneResult]],
    *,
    trials: int = SUITE_TRIALS,
    sampler_seed: int = SUITE_SAMPLER_SEED,
) -> Path:
    """Write ``<results>/tuning/tuned.json``: the budget, the sampler, the commit and versions, and per study the
    filter, split, every trial (spec, objective), the best configuration and the search space."""
    from locbench.run import provenance

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
                "fold": s.fold,
                "train": list(s.train),
                "train_seeds": list(r.seeds),
                "test": list(s.test),
                "test_seeds": list(s.test_seeds),
                "objective": r.objective,
                "journal": journal_path("", r.name).as_posix(),
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
    git = provenance.git_state()
    doc = {
        "format": SUMMARY_FORMAT,
        "budget": {"trials": trials, "train_runs": SUITE_TRAIN_RUNS},
        "sampler": {
            "name": "optuna TPESampler",
            "multivariate": True,
            "startup_trials": STARTUP_TRIALS,
            "seed": sampler_seed,
        },
        "commit": git["commit"],
        "dirty": git["dirty"],
        "versions": provenance.versions(),
        "studies": out,
    }
    path = Path(results) / TUNING_DIR / SUMMARY_FILE
    path.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps(doc, indent=1, default=str, allow_nan=True) + "\n"
    tmp = path.with_name(f".tmp-{SUMMARY_FILE}")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(path)
    return path


def read_tuning(results: str | os.PathLike[str]) -> dict[str, Any]:
    """The whole ``tuned.json`` (budget, sampler, provenance, studies), or an empty dict when nothing was tuned.

    Raises :class:`ConfigError` naming the file when it is unreadable or of another format.
    """
    path = Path(results) / TUNING_DIR / SUMMARY_FILE
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return {}
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: unreadable tuning summary ({exc}); tune again with 'nox -s tune'") from None
    if not isinstance(data, dict) or data.get("format") != SUMMARY_FORMAT or not isinstance(data.get("studies"), list):
        raise ConfigError(
            f"{path}: expected a tuning summary of format {SUMMARY_FORMAT} (an object with 'studies'); "
            "tune again with 'nox -s tune'"
        )
    return data


def read_summary(results: str | os.PathLike[str]) -> list[dict[str, Any]]:
    """The studies of ``tuned.json`` (:func:`read_tuning`), or an empty list when nothing was tuned."""
    studies: list[dict[str, Any]] = read_tuning(results).get("studies", [])
    return studies


def study_groups(results: str | os.PathLike[str]) -> dict[str, str]:
    """The tuned configuration of each fold of a cross-validated study -> one name for the study's folds
    (:func:`locbench.run.verify.sample`'s groups); a fold that kept the default is the default's own."""
    groups: dict[str, str] = {}
    for st in read_summary(results):
        best = st.get("best_spec")
        if not (st.get("fold") and best):
            continue
        plain, tuned = resolve_filter(st["filter"]).name, resolve_filter(str(best)).name
        if tuned != plain:
            groups[tuned] = f"{plain} tuned on {st['world']}, every fold"
    return groups


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


# --- re-running committed trials -----------------------------------------------------------------------------


#: Largest relative difference between a re-run trial's objective and its journal's that passes: our code against
#: itself on one machine gives 0; another CPU's numpy, OpenBLAS and gtsam kernels move a run's ATE by up to about
#: 2e-5 relative (docs/reproduction.md), so a committed study is checked on any machine.
TRIAL_RTOL = 1e-4


@dataclass(frozen=True)
class TrialCheck:
    """One committed trial re-run on its train data: the journal's objective against the fresh one."""

    filter: str
    world: str
    fold: str
    number: int
    spec: str
    stored: float
    fresh: float

    @property
    def rel_diff(self) -> float:
        """|fresh - stored| / |stored| (0 when both are equal, +inf when only one is finite)."""
        if self.fresh == self.stored:
            return 0.0
        if not (math.isfinite(self.fresh) and math.isfinite(self.stored)):
            return math.inf
        return abs(self.fresh - self.stored) / max(abs(self.stored), 1e-300)

    @property
    def passed(self) -> bool:
        """Within :data:`TRIAL_RTOL`."""
        return self.rel_diff <= TRIAL_RTOL


def sample_trials(entries: Sequence[dict[str, Any]], seed: int) -> list[tuple[dict[str, Any], dict[str, Any]]]:
    """One (study, trial) per filter of ``entries``, drawn with ``seed``: a study of the filter, then one of its
    finished trials other than the default (whose runs are the comparison's own), else the default."""
    rng = np.random.default_rng(seed)
    out: list[tuple[dict[str, Any], dict[str, Any]]] = []
    for f in sorted({str(e["filter"]) for e in entries}):
        studies = [e for e in entries if e["filter"] == f and e.get("trials")]
        if not studies:
            continue
        study = studies[int(rng.integers(len(studies)))]
        trials = study["trials"]
        searched = [t for t in trials if t["number"] != 0] or list(trials)
        out.append((study, searched[int(rng.integers(len(searched)))]))
    return out


def verify_trials(
    results: str | os.PathLike[str], seed: int = 0, *, executor: str = "local", jobs: int = 1
) -> list[TrialCheck]:
    """Re-run a sample of the committed trials (:func:`sample_trials`) on their train data, in a store of their own
    that is deleted after, and score them as the study did (an empty list when nothing was tuned).

    Every sampled trial's runs go into one sweep (no two trials share a spec, so none shares a run): the workers
    start once and the longest runs are spread over them, where a sweep per trial left a worker idle beside a
    trial's one long run.
    """
    import tempfile

    from locbench.run.plan import plan_sweep
    from locbench.run.sweep import run_sweep

    picked = [
        (study, trial, [resolve_dataset(d).name for d in study["train"]], [int(x) for x in study["train_seeds"]])
        for study, trial in sample_trials(read_summary(results), seed)
    ]
    if not picked:
        return []
    checks: list[TrialCheck] = []
    with tempfile.TemporaryDirectory(prefix="locbench-trial-") as tmp:
        store = Store(tmp)
        store.claim()
        # as the study ran them: train runs keep no derived values
        plan = plan_sweep([([trial["spec"]], names, seeds) for _, trial, names, seeds in picked], store, derive=False)
        if run_sweep(plan, executor, jobs).interrupted:
            raise KeyboardInterrupt
        for study, trial, names, seeds in picked:
            fresh, _ = score_trial(store, trial["spec"], names, seeds, study["objective"])
            checks.append(
                TrialCheck(
                    study["filter"],
                    study["world"],
                    study.get("fold", ""),
                    trial["number"],
                    trial["spec"],
                    float(trial["value"]),
                    fresh,
                )
            )
    return checks
