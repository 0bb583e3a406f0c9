"""The ``locbench`` command line: a thin layer over the library API.

locbench list [FILTER|DATASET ...]
locbench run [--suite NAME|FILE.toml | --filter SPEC ... --dataset SPEC ...]
             [--seeds N] [--results DIR] [--jobs N] [--executor local|dask [--scheduler ADDRESS]] [--force]
             [--connect-timeout S] [--max-configs N] [--max-seeds N] [--interleave [S]] [--run-timeout S]
             [--score-sample M]
locbench tune FILTER --dataset SPEC [SPEC ...] --trials N --seeds K [--results DIR] [--objective ate|nll]
              [--jobs N] [--executor local|dask [--scheduler ADDRESS]] [--max-seeds N] [--run-timeout S]
locbench report [--results DIR] [--suite NAME ...] [--out DIR] [--jobs N]
locbench verify [--results DIR] [--fraction F] [--seed S] [--run-timeout S]
locbench check [ID ...]
locbench fetch SPEC [SPEC ...]
locbench export [--results DIR] [--out DIR] [--dataset SPEC ...] [--filter SPEC ...] [--smoothed]
locbench export --format textlog --dataset SPEC [--seed N] --out FOLDER
locbench export --format rosbag2|rosbag1 --dataset SPEC [--seed N] --out FOLDER
locbench import --name NAME --dataset SPEC --seed N [--seed N ...] [--format F] [--topic T ...] FILE [FILE ...]
"""

from __future__ import annotations

import argparse
import errno
import logging
import os
import sys
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from locbench import __version__
from locbench.core.errors import ConfigError, LocbenchError, one_line
from locbench.core.spec import MAX_CONFIGS
from locbench.suites import MAX_SEEDS

#: ``locbench run --interleave`` without a value: seconds of data each filter of a task runs before the next
#: (:attr:`locbench.run.plan.Task.slice_s`); and the longest slice accepted.
INTERLEAVE_SLICE_S = 5.0
MAX_INTERLEAVE_S = 3600.0

#: The suite that tunes (``locbench run --suite tuned``), run by :mod:`locbench.run.tuning`, not as blocks of runs.
TUNED_SUITE = "tuned"

log = logging.getLogger("locbench")

DEFAULT_RESULTS = "results"


def _results_default() -> str:
    return os.environ.get("LOCBENCH_RESULTS", DEFAULT_RESULTS)


def _cmd_list(args: argparse.Namespace) -> int:
    from locbench.registry import DATASETS, FILTERS
    from locbench.suites import SUITES

    if args.ids:
        return _list_params(args.ids)
    for title, reg in (("filters", FILTERS), ("datasets", DATASETS)):
        print(f"{title}:")
        for ident in reg.ids():
            reason = reg.unavailable_reason(ident)
            state = f"  [{reason}]" if reason else ""
            print(f"  {ident:<18} {reg.summary(ident)}{state}")
    print("suites:")
    for s in SUITES.values():
        print(f"  {s.name:<18} {s.runs:>5} runs: {s.description}")
    return 0


def _list_params(ids: Sequence[str]) -> int:
    """Each parameter of the named filters and datasets: type, default, unit and meaning."""
    from locbench.core.errors import UnknownIdError
    from locbench.core.spec import describe_params
    from locbench.core.tunable import tunable_fields
    from locbench.registry import DATASETS, FILTERS

    for ident in ids:
        if ident in FILTERS:
            reg, kind, cls = FILTERS, "filter", FILTERS.load(ident).Config
        elif ident in DATASETS:
            reg, kind, cls = DATASETS, "dataset", DATASETS.load(ident).Params
        else:
            valid = ", ".join(FILTERS.ids() + DATASETS.ids())
            raise UnknownIdError(f"unknown filter or dataset {ident!r}; valid: {valid}")
        print(f"{kind} {ident}: {reg.summary(ident)}")
        tunable = tunable_fields(cls) if kind == "filter" else None
        tune = f"; tunable ('locbench tune {ident}'): {', '.join(tunable) or 'none'}" if tunable is not None else ""
        print(f"  written {ident}[key=value,...]; a grid: key=a|b|c{tune}")
        rows = [
            (p.name, p.type, p.default, p.unit)
            + ((tunable[p.name].describe() if p.name in tunable else "-",) if tunable is not None else ())
            + (p.meaning,)
            for p in describe_params(cls)
        ]
        if not rows:
            print("  (no parameters)")
            continue
        head: tuple[str, ...] = ("parameter", "type", "default", "unit")
        if tunable is not None:
            head += ("tuning range",)
        head += ("meaning",)
        n = len(head) - 1
        widths = [max(len(r[i]) for r in [*rows, head]) for i in range(n)]
        for r in [head, *rows]:
            print("  " + "  ".join(c.ljust(w) for c, w in zip(r[:n], widths, strict=True)) + "  " + r[n])
    return 0


def _cmd_run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from locbench.run.executors import scheduler_address
    from locbench.run.plan import plan_sweep
    from locbench.run.store import Store
    from locbench.run.sweep import run_sweep
    from locbench.suites import Block, check_seeds, get_suite

    # every input is checked here, before anything is expanded, run or written
    if args.suite and (args.filter or args.dataset):
        raise ConfigError("give either --suite or --filter/--dataset, not both")
    for name, value in (("--max-configs", args.max_configs), ("--max-seeds", args.max_seeds)):
        if value < 1:
            raise ConfigError(f"{name} must be >= 1, got {value}")
    if args.seeds is not None:
        check_seeds(args.seeds, args.max_seeds, "--seeds")
    if args.jobs < 1:
        raise ConfigError(f"--jobs must be >= 1, got {args.jobs}")
    if args.jobs > MAX_JOBS:
        raise ConfigError(f"--jobs {args.jobs}: at most {MAX_JOBS} worker processes")
    if not (0 < args.connect_timeout <= MAX_CONNECT_TIMEOUT_S):
        raise ConfigError(f"--connect-timeout must be in (0, {MAX_CONNECT_TIMEOUT_S:g}] s, got {args.connect_timeout}")
    if args.scheduler is not None and args.executor != "dask":
        raise ConfigError("--scheduler needs --executor dask")
    if not (0 <= args.interleave <= MAX_INTERLEAVE_S):
        raise ConfigError(f"--interleave must be in [0, {MAX_INTERLEAVE_S:g}] s of data, got {args.interleave}")
    scheduler = scheduler_address(args.scheduler, args.connect_timeout) if args.scheduler is not None else None
    limits = {"max_configs": args.max_configs, "max_seeds": args.max_seeds}
    if args.filter or args.dataset:
        if not (args.filter and args.dataset):
            raise ConfigError("--filter and --dataset go together: name at least one of each (see 'locbench list')")
        blocks = [Block(tuple(args.filter), tuple(args.dataset), args.seeds or 1, **limits)]
    else:
        blocks = []
        for name in args.suite or ["default"]:
            if name == TUNED_SUITE:
                continue
            suite = get_suite(name, **limits)
            blocks += list((suite.with_seeds(args.seeds, args.max_seeds) if args.seeds else suite).blocks)
    tuned = TUNED_SUITE in (args.suite or [])
    store = Store(args.results)  # the one store of this command: planned against, claimed, written
    rc = 0
    if blocks or not tuned:
        # every spec is parsed and validated here, once, before anything runs or is written
        specs: list[tuple[Sequence[str], Sequence[str], Sequence[int]]] = [
            (b.filters, b.datasets, range(b.seeds)) for b in blocks
        ]
        if tuned:
            # planned with the other suites: a test realisation they run on too is one task, built once
            specs += _tuned_blocks(args.results)
            tuned = False
        plan = plan_sweep(specs, store, args.force, slice_s=args.interleave, score_sample=args.score_sample)
        store.claim()  # refuses another tool's folder before anything is written or cleaned in it
        bar = tqdm(total=plan.total, unit="run", desc="locbench run", disable=True if args.no_progress else None)
        with bar:
            sweep = run_sweep(
                plan, args.executor, args.jobs, scheduler, progress=bar.update, connect_timeout_s=args.connect_timeout
            )
        if sweep.interrupted:
            print(f"interrupted: {sweep.stored} of {sweep.total} runs stored; run the same command to resume")
            return 130
        rc = _print_summary(sweep, args.results)
        if args.dataset:
            rc = max(rc, _none_ran(sweep.outcomes))
    if tuned:
        store.claim()
        rc = max(rc, _run_tuned(args))
    return rc


def _tuned_blocks(results: str) -> list[tuple[Sequence[str], Sequence[str], Sequence[int]]]:
    """Suite ``tuned``'s blocks beside other suites (printing the studies it skips and why); none, with the reason
    printed, when nothing was tuned: the other suites run alone."""
    from locbench.run.tuning import read_summary, tuned_blocks

    if not read_summary(results):
        _say_untuned(results)
        return []
    blocks, skipped = tuned_blocks(results)
    _say_skipped_studies(skipped)
    return blocks


def _say_untuned(results: str) -> None:
    print(f"  suite tuned skipped: no tuned configurations in {results}/tuning; tune with 'nox -s tune'")


def _say_skipped_studies(skipped: Sequence[tuple[Any, str]]) -> None:
    for s, reason in skipped:
        print(f"  tuned: skipped {s.filter} on {', '.join(s.test)}: {reason}")


def _run_tuned(args: argparse.Namespace) -> int:
    """Suite ``tuned``: the tuned configurations of ``RESULTS/tuning/tuned.json`` and their defaults on test data."""
    from locbench.run.sweep import SweepResult
    from locbench.run.tuning import read_summary, run_tuned_suite

    if not read_summary(args.results) and len(args.suite) > 1:
        # the other suites ran: say why this one did not, and leave the exit code to them
        _say_untuned(args.results)
        return 0
    res = run_tuned_suite(args.results, executor=args.executor, jobs=args.jobs, scheduler=args.scheduler)
    _say_skipped_studies(res.skipped)
    if res.interrupted:
        print("interrupted: suite tuned stopped; run the same command to resume")
        return 130
    return _print_summary(SweepResult(res.outcomes, len(res.outcomes)), args.results)


def _tune_suite(args: argparse.Namespace, scheduler: str | None) -> int:
    """``locbench tune --suite``: every study of suite ``tuned`` on its train data, written to RESULTS/tuning."""
    from locbench.run.tuning import SUITE_TRIALS, tune_suite

    trials = args.trials if args.trials is not None else SUITE_TRIALS
    res = tune_suite(args.results, executor=args.executor, jobs=args.jobs, scheduler=scheduler, trials=trials)
    for s, reason in res.skipped:
        print(f"skipped {s.filter} on {', '.join(s.train)}: {reason}")
    if res.interrupted:
        print("interrupted: the finished trials are kept in the journals; run the same command to resume")
        return 130
    for s, r in res.studies:
        best = r.best
        where = s.world + (f" ({s.fold} held out)" if s.fold else "")
        print(
            f"{s.filter} on {where}: {len(r.trials)} trials x {len(s.train) * s.seeds} train runs, best "
            + (f"{best.value:.4g} ({r.objective}): {best.spec}" if best else "none (every trial failed)")
        )
    print(f"{len(res.studies)} studies written to {Path(args.results) / 'tuning'}")
    return 1 if any(reason.startswith("failed") for _, reason in res.skipped) else 0


#: Most worker processes ``--jobs`` asks for.
MAX_JOBS = 1024
#: Longest ``--connect-timeout``, s.
MAX_CONNECT_TIMEOUT_S = 3600.0


def _print_summary(sweep: Any, results: str) -> int:
    """Counts by status, then one line per (status, filter, dataset, reason) with a count; 1 if any run failed."""
    from locbench.run.plan import NOT_STORED

    outcomes = sweep.outcomes
    counts = Counter(o.status for o in outcomes)
    print(f"{len(outcomes)} runs in {results}/runs: " + ", ".join(f"{n} {s}" for s, n in sorted(counts.items())))
    if sweep.cleaned:
        print(f"  removed {sweep.cleaned} leftover temporary entries of interrupted writes")
    if sweep.retried:
        print(f"  {sweep.retried} task(s) given to a fresh worker after theirs died")
    if sweep.bounds_planned:
        missing = sweep.bounds_planned - sweep.bounds
        print(
            f"  posterior Cramer-Rao bound computed for {sweep.bounds} realisation(s)"
            + (f"; {missing} failed or not stored (see the log; the next run tries again)" if missing else "")
        )
    reruns = [o for o in outcomes if o.note]
    for o in reruns:
        print(f"  {o.note}")
    groups: Counter[tuple[str, str, str, str]] = Counter()
    for o in outcomes:
        if o.status in ("error", "diverged", "skipped", NOT_STORED):
            groups[(o.status, str(o.filter), str(o.dataset), o.message)] += 1
    for (status, filt, dataset, message), n in groups.items():
        times = f" x{n}" if n > 1 else ""
        print(f"  {status}{times}: {filt} on {dataset}: {message}")
    errors, lost = counts.get("error", 0), counts.get(NOT_STORED, 0)
    if errors or lost:
        where = []
        if errors:
            where.append(f"each failed run's message is in {results}/runs/<dataset>/<filter>/seed-NNNN/meta.json")
        if lost:
            where.append("the runs not stored are listed above with their folder and the reason")
        print(f"{errors} run(s) failed and {lost} were not stored; " + "; ".join(where), file=sys.stderr)
        return 1
    return 0


def _none_ran(outcomes: Sequence[Any]) -> int:
    """1 (with the reasons on stderr) when the datasets asked for ran nothing: every run was skipped."""
    if not outcomes or any(o.status != "skipped" for o in outcomes):
        return 0
    reasons = sorted({o.message for o in outcomes})
    print("no run was made: every run was skipped (" + "; ".join(reasons) + ")", file=sys.stderr)
    return 1


def _cmd_report(args: argparse.Namespace) -> int:
    from locbench.report import suite_filter, summary_text, write_report
    from locbench.run.store import Store

    store = Store(args.results)
    if not store.runs.is_dir():
        raise ConfigError(f"{store.runs}: no stored runs; run 'locbench run' first")
    keep = suite_filter(*args.suite, results=args.results) if args.suite else None
    out = Path(args.out) if args.out else None
    if args.jobs < 1:
        raise ConfigError(f"--jobs must be >= 1, got {args.jobs}")
    paths = write_report(store, keep=keep, out=out, jobs=args.jobs)
    print(summary_text(paths.summary), end="")
    print(f"report written to {paths.markdown} and {paths.html}")
    statuses = {r.status for r in paths.runs}
    if statuses == {"skipped"}:
        reasons = sorted({r.message for r in paths.runs})
        print(f"{store.runs} holds only skipped runs (" + "; ".join(reasons) + ")", file=sys.stderr)
        return 1
    return 0


def _cmd_verify(args: argparse.Namespace) -> int:
    from locbench.run.store import MARKER, Store
    from locbench.run.verify import verify, write_record

    if not 0.0 < args.fraction <= 1.0:
        raise ConfigError(f"--fraction: expected a share of the runs in (0, 1], got {args.fraction}")
    if args.seed < 0:
        raise ConfigError(f"--seed: expected a non-negative integer (the sample's seed), got {args.seed}")
    if not 1 <= args.jobs <= MAX_JOBS:
        raise ConfigError(f"--jobs: expected 1-{MAX_JOBS} processes, got {args.jobs}")
    store = Store(args.results)
    if not store.runs.is_dir():
        raise ConfigError(f"{store.runs}: no stored runs; run 'locbench run' first")
    if not (store.root / MARKER).is_file():  # verify.json is written there: only into locbench's own folder
        raise ConfigError(
            f"{store.root}: not a locbench results folder (no {MARKER} file); expected a folder 'locbench run' wrote"
        )
    from locbench.run.tuning import verify_trials

    res = verify(store, args.fraction, args.seed, jobs=args.jobs)
    # and a sample of the committed tuning trials (one per filter), re-run on their train data
    res.trials = verify_trials(args.results, args.seed, jobs=args.jobs)
    record = write_record(store, res)
    for line in res.problems():
        print(f"differs: {line}")
    state = "passed" if res.passed else "FAILED"
    print(
        f"verify {state}: {len(res.checked)} of {res.stored} stored runs re-run with the truth and bound of "
        f"{res.realisations} realisation(s), {len(res.differ) + len(res.artefacts)} differ "
        f"(fraction {args.fraction:g}, seed {args.seed})"
        + (f"; {len(res.trials)} tuning trial(s) re-run on their train data" if res.trials else "")
        + f"; record {record}"
    )
    return 0 if res.passed else 1


def _cmd_tune(args: argparse.Namespace) -> int:
    from locbench.run.executors import scheduler_address
    from locbench.run.tuning import check_trials, train_seeds, tune

    # every argument is bounded as for 'run', before the study's journal is opened or anything runs
    if args.suite:
        if args.filter or args.dataset or args.seeds is not None:
            raise ConfigError("--suite tunes every study of suite 'tuned': it takes no FILTER, --dataset or --seeds")
    elif not (args.filter and args.dataset and args.trials is not None and args.seeds is not None):
        raise ConfigError("tune needs FILTER, --dataset, --trials and --seeds (or --suite for every study)")
    if args.trials is not None:
        check_trials(args.trials)
    if args.max_seeds < 1:
        raise ConfigError(f"--max-seeds must be >= 1, got {args.max_seeds}")
    seeds: int = args.seeds if args.seeds is not None else 0
    trials: int = args.trials if args.trials is not None else 0
    if not args.suite:
        train_seeds(seeds, args.max_seeds)
    if not 1 <= args.jobs <= MAX_JOBS:
        raise ConfigError(f"--jobs: expected 1-{MAX_JOBS} processes, got {args.jobs}")
    if args.scheduler is not None and args.executor != "dask":
        raise ConfigError("--scheduler needs --executor dask")
    scheduler = scheduler_address(args.scheduler) if args.scheduler is not None else None
    if args.suite:
        return _tune_suite(args, scheduler)

    def show(t: Any) -> None:
        value = f"{t.value:.6g}" if t.value != float("inf") else "worst (" + t.message + ")"
        print(f"trial {t.number}: {value}  {t.spec}", flush=True)

    res = tune(
        args.filter,
        args.dataset,
        trials,
        seeds,
        args.results,
        executor=args.executor,
        jobs=args.jobs,
        scheduler=scheduler,
        objective=args.objective,
        max_seeds=args.max_seeds,
        progress=show,
    )
    if res.interrupted:
        print(f"interrupted: {len(res.trials)} trials finished; run the same command to resume")
        return 130
    best = res.best
    print(
        f"{res.name}: {len(res.trials)} trials x {len(res.datasets) * len(res.seeds)} train runs = "
        f"{res.budget_runs} runs ({res.reused} trial(s) read back from stored runs)"
    )
    if best is None:
        print("locbench: error: every trial failed or diverged; no configuration to give", file=sys.stderr)
        return 1
    print(f"best {res.objective} {best.value:.6g} at trial {best.number}")
    print(best.spec)
    return 0


def _cmd_check(args: argparse.Namespace) -> int:
    from locbench.checks import run_checks

    counts: Counter[str] = Counter()
    for r in run_checks(list(args.ids) or None):
        mark = {"passed": "ok", "failed": "FAIL", "xfailed": "xfail", "xpassed": "XPASS", "skipped": "skip"}[r.outcome]
        print(f"{mark:<5} {r.target:<32} {r.check}" + (f": {r.message}" if r.message else ""))
        counts[r.outcome] += 1
    failed = counts["failed"] + counts["xpassed"]
    tally = ", ".join(f"{n} {o}" for o, n in sorted(counts.items()))
    if failed:
        print(f"{failed} check(s) failed ({tally})")
    elif counts["skipped"]:
        print(f"no check failed, but {counts['skipped']} were skipped (see 'skip' above): {tally}")
    else:
        print(f"all {counts['passed'] + counts['xfailed']} checks passed ({tally})")
    return 1 if failed else 0


def _cmd_fetch(args: argparse.Namespace) -> int:
    from locbench.registry import DATASETS, resolve_dataset

    if not args.verbose:
        import pooch

        pooch.get_logger().setLevel(logging.WARNING)  # its "Downloading ..." line; the paths are printed after
    for spec in args.specs:
        r = resolve_dataset(spec)
        try:
            paths = DATASETS.load(r.id)().fetch(r.params)
        except OSError as exc:
            if exc.errno is not None:
                raise  # a local file-system error: the generic one line
            reason = os_error_line(exc).split(" (Caused by", 1)[0]
            raise ConfigError(f"{r.name}: download failed (is the network reachable?): {reason}") from None
        if not paths:
            print(f"{r.name}: nothing to fetch (synthetic)")
        for path in paths:
            print(f"{r.name}: {path}")
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    from pathlib import Path

    from locbench.registry import resolve_dataset, resolve_filter
    from locbench.run.export import export_results, export_textlog

    if args.format in ("rosbag1", "rosbag2"):
        return _export_ros(args)
    if args.format == "textlog":
        if len(args.dataset) != 1 or args.filter or args.smoothed or not args.out:
            raise ConfigError("--format textlog writes one dataset: give --dataset SPEC --seed N --out FOLDER")
        seed = 0 if args.seed is None else args.seed
        if seed < 0:
            raise ConfigError(f"--seed must be >= 0, got {seed}")
        folder, notes = export_textlog(args.dataset[0], seed, args.out)
        for note in notes:
            print(f"note: {note}")
        print(f"{args.dataset[0]} seed {seed} written as a textlog to {folder}; read it as textlog[path={folder}]")
        return 0
    if args.seed is not None:
        raise ConfigError("--seed goes with --format textlog (TUM export writes every stored seed)")
    out = args.out or str(Path(args.results) / "tum")
    written = export_results(
        args.results,
        out,
        datasets=[resolve_dataset(s).name for s in args.dataset],
        filters=[resolve_filter(s).name for s in args.filter],
        smoothed=args.smoothed,
    )
    if not written:
        what = " matching the --dataset/--filter given" if (args.dataset or args.filter) else ""
        print(
            f"locbench: error: no stored run with estimates{what} in {args.results}/runs; nothing written",
            file=sys.stderr,
        )
        return 1
    print(f"{len(written)} TUM trajectory files written under {out}")
    return 0


def _export_ros(args: argparse.Namespace) -> int:
    from locbench.run.rosbag_export import export_ros

    if len(args.dataset) != 1 or args.filter or args.smoothed or not args.out:
        raise ConfigError(f"--format {args.format} writes one dataset: give --dataset SPEC --seed N --out FOLDER")
    seed = 0 if args.seed is None else args.seed
    if seed < 0:
        raise ConfigError(f"--seed must be >= 0, got {seed}")
    res = export_ros(args.dataset[0], seed, args.out, args.format)
    counts = ", ".join(f"{topic} {n}" for topic, n in res.counts.items())
    print(f"{args.dataset[0]} seed {seed} written to {res.out}: {res.bag.name} ({counts} messages)")
    if res.offset_s:
        print(f"note: stamps are the dataset's times + {res.offset_s:g} s (ROS reads a stamp of 0 as unset)")
    return 0


def _seeds_arg(text: str) -> list[int]:
    """``N`` or ``A-B`` (inclusive) as seeds."""
    try:
        if "-" in text[1:]:
            a, b = text.split("-", 1)
            lo, hi = int(a), int(b)
            if lo > hi:
                raise ValueError
            return list(range(lo, hi + 1))
        return [int(text)]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a seed N or a range A-B, got {text!r}") from None


def _cmd_import(args: argparse.Namespace) -> int:
    from locbench.run.import_runs import external_name, import_system

    seeds = sorted({s for group in args.seed for s in group})
    if any(s < 0 for s in seeds):
        raise ConfigError("--seed: seeds are >= 0")
    sensors = tuple(x for x in args.sensors.split(",") if x) if args.sensors else ()
    written = import_system(
        args.results,
        args.name,
        args.dataset,
        seeds,
        args.files,
        fmt=args.format,
        topics=tuple(args.topic),
        description=args.description,
        sensors=sensors,
        frame=args.frame,
    )
    print(f"{len(written)} run(s) of {external_name(args.name)} on {args.dataset} stored in {args.results}/runs")
    return 0


def build_parser() -> argparse.ArgumentParser:
    # long: one argparse declaration per subcommand and option, read top to bottom as the CLI's reference
    from locbench.filters.base import MAX_SCORE_SAMPLE, SCORE_SAMPLE_SIZE

    p = argparse.ArgumentParser(prog="locbench", description="Comparative benchmark of 2-D localization filters.")
    p.add_argument("--version", action="version", version=f"locbench {__version__}")
    p.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    sub = p.add_subparsers(dest="command", required=True)

    lst = sub.add_parser("list", help="registered filters, datasets and suites; or the parameters of some")
    lst.add_argument("ids", nargs="*", metavar="ID", help="a filter or dataset: print its parameters (e.g. pf)")
    lst.set_defaults(func=_cmd_list)

    r = sub.add_parser("run", help="run filters over datasets and store the runs")
    r.add_argument(
        "--suite",
        nargs="+",
        action="extend",
        help="named suites (see 'locbench list') or .toml suite files; default: default",
    )
    r.add_argument(
        "--filter",
        nargs="+",
        action="extend",
        default=[],
        metavar="SPEC",
        help="e.g. ekf_landmarks[association=nearest]",
    )
    r.add_argument("--dataset", nargs="+", action="extend", default=[], metavar="SPEC", help="e.g. room[kidnap_m=2]")
    r.add_argument("--seeds", type=int, default=None, help="number of seeds, 0..N-1 (default: the suite's, or 1)")
    r.add_argument(
        "--results", default=_results_default(), help="results folder (default: results/ or $LOCBENCH_RESULTS)"
    )
    r.add_argument(
        "--jobs", type=int, default=1, help="worker processes (default 1), or LocalCluster workers with --executor dask"
    )
    r.add_argument(
        "--executor",
        choices=("local", "dask"),
        default="local",
        help="local: this process or a pool of --jobs processes; dask: dask.distributed workers",
    )
    r.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help=(
            "with --executor dask: a running scheduler (tcp://host:8786) or its scheduler file (FILE.json, waited "
            "for up to --connect-timeout); default: a LocalCluster of --jobs workers"
        ),
    )
    r.add_argument(
        "--connect-timeout",
        type=float,
        default=30.0,
        metavar="S",
        help="with --scheduler: seconds to wait for the scheduler to answer (default 30)",
    )
    r.add_argument(
        "--max-configs",
        type=int,
        default=MAX_CONFIGS,
        metavar="N",
        help=f"most filter x dataset configurations a block's grids may make (default {MAX_CONFIGS})",
    )
    r.add_argument(
        "--max-seeds",
        type=int,
        default=MAX_SEEDS,
        metavar="N",
        help=f"most seeds a block may run (default {MAX_SEEDS})",
    )
    r.add_argument("--force", action="store_true", help="re-run runs that are already stored")
    r.add_argument(
        "--interleave",
        type=float,
        nargs="?",
        const=INTERLEAVE_SLICE_S,
        default=0.0,
        metavar="S",
        help="interleaved timing: the filters of each (dataset, seed) take turns over S s of data "
        f"(default {INTERLEAVE_SLICE_S:g}), so a busy moment slows them alike; the same estimates, more memory",
    )
    r.add_argument(
        "--score-sample",
        type=int,
        default=SCORE_SAMPLE_SIZE,
        metavar="M",
        help=f"members of each belief sample a sampling filter (pf) is scored by (default {SCORE_SAMPLE_SIZE}, at "
        f"most {MAX_SCORE_SAMPLE}); part of those runs' keys: a new value re-runs them",
    )
    r.add_argument("--no-progress", action="store_true", help="no progress bar")
    _add_run_timeout(r)
    r.set_defaults(func=_cmd_run)

    rep = sub.add_parser("report", help="write summary/metrics.parquet, REPORT.md and figures from stored runs")
    rep.add_argument("--results", default=_results_default(), help="results folder (default: results/)")
    rep.add_argument(
        "--suite",
        nargs="+",
        action="extend",
        default=None,
        help="report only the runs of these suites (names or TOML files), not every stored run",
    )
    rep.add_argument("--out", default=None, help="write the summary here instead of RESULTS/summary")
    rep.add_argument(
        "--jobs", type=int, default=1, help="processes that read the runs and draw the figures (default 1)"
    )
    rep.set_defaults(func=_cmd_report)

    v = sub.add_parser(
        "verify", help="re-run a random sample of stored runs; exit 1 when an array other than call times differs"
    )
    v.add_argument("--results", default=_results_default(), help="results folder (default: results/)")
    v.add_argument("--fraction", type=float, default=0.02, help="share of the stored runs to re-run (default 0.02)")
    v.add_argument("--seed", type=int, default=0, help="seed of the random sample (default 0)")
    v.add_argument("--jobs", type=int, default=1, help="worker processes that re-run the sample (default 1)")
    _add_run_timeout(v)
    v.set_defaults(func=_cmd_verify)
    tu = sub.add_parser(
        "tune",
        help="tune a filter's tunable parameters on train data (optuna TPE); prints the best spec last",
    )
    tu.add_argument("filter", metavar="FILTER", nargs="?", help="a filter id or a spec whose parameters stay fixed")
    tu.add_argument(
        "--suite",
        action="store_true",
        help="every study of suite 'tuned' (each tunable filter, each world and MRCLAM fold, the same budget); "
        "writes RESULTS/tuning/tuned.json, which 'locbench run --suite tuned' runs on test data",
    )
    tu.add_argument("--dataset", nargs="+", action="extend", metavar="SPEC", help="train datasets (e.g. room)")
    tu.add_argument(
        "--trials", type=int, default=None, help="finished trials the study should hold (--suite: the suite's budget)"
    )
    tu.add_argument(
        "--seeds", type=int, default=None, help="train seeds per dataset (1000 .. 1000+K-1, apart from test seeds)"
    )
    tu.add_argument("--objective", choices=("ate", "nll"), default="ate", help="mean ATE (default) or NLL")
    tu.add_argument(
        "--max-seeds", type=int, default=MAX_SEEDS, metavar="N", help=f"most train seeds (default {MAX_SEEDS})"
    )
    tu.add_argument("--results", default=_results_default(), help="results folder; runs and study go to RESULTS/tuning")
    tu.add_argument("--jobs", type=int, default=1, help="worker processes for each trial's runs (default 1)")
    tu.add_argument("--executor", choices=("local", "dask"), default="local", help="as for 'locbench run'")
    tu.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="with --executor dask: a running scheduler or its FILE.json",
    )
    _add_run_timeout(tu)
    tu.set_defaults(func=_cmd_tune)

    c = sub.add_parser("check", help="conformance checks for filters and datasets")
    c.add_argument("ids", nargs="*", help="filter or dataset ids/specs (default: all registered)")
    c.set_defaults(func=_cmd_check)

    fe = sub.add_parser(
        "fetch",
        help="download recorded datasets from their official source into the cache, verified by sha256",
    )
    fe.add_argument("specs", nargs="+", metavar="SPEC", help="e.g. plaza[run=1] or mrclam[dataset=6,robot=1]")
    fe.set_defaults(func=_cmd_fetch)

    ex = sub.add_parser(
        "export", help="write stored runs and their truth as TUM trajectories (for evo), or a dataset as a textlog"
    )
    ex.add_argument(
        "--format",
        choices=("tum", "textlog", "rosbag2", "rosbag1"),
        default="tum",
        help="tum: stored runs (default); textlog: the dataset --dataset at --seed as a plain-text log in --out; "
        "rosbag2/rosbag1: that dataset as a ROS bag with map and truth for a ROS localizer (docs/external.md)",
    )
    ex.add_argument("--seed", type=int, default=None, help="with --format textlog/rosbag*: the realisation (default 0)")
    ex.add_argument("--results", default=_results_default(), help="results folder (default: results/)")
    ex.add_argument("--out", default=None, help="output folder (default: RESULTS/tum)")
    ex.add_argument("--dataset", nargs="+", action="extend", default=[], metavar="SPEC", help="only these datasets")
    ex.add_argument("--filter", nargs="+", action="extend", default=[], metavar="SPEC", help="only these filters")
    ex.add_argument("--smoothed", action="store_true", help="export smoothed trajectories (gtsam_fls) instead")
    ex.set_defaults(func=_cmd_export)

    im = sub.add_parser(
        "import", help="store another system's output (TUM, planar TUM with covariance, OpenVINS, ROS bags) as runs"
    )
    im.add_argument("--name", required=True, help="the system's name: its runs are external[name=NAME]")
    im.add_argument("--dataset", required=True, metavar="SPEC", help="the dataset the output was computed on")
    im.add_argument(
        "--seed", type=_seeds_arg, action="append", required=True, metavar="N", help="a seed or A-B; repeatable"
    )
    im.add_argument("files", nargs="+", metavar="FILE", help="one file per seed in order, or one name with {seed}")
    im.add_argument(
        "--format", choices=("tum", "tumcov", "openvins", "bag"), default=None, help="default: from the file"
    )
    im.add_argument("--topic", action="append", default=[], help="bag topic of the poses and/or particle clouds")
    im.add_argument("--frame", default="map", help="the frame the poses must be in (default map)")
    im.add_argument("--description", default="", help="what the system is (stored in the runs' provenance)")
    im.add_argument("--sensors", default="", help="event types the system used, comma-separated (Odometry,LaserScan)")
    im.add_argument("--results", default=_results_default(), help="results folder (default: results/)")
    im.set_defaults(func=_cmd_import)
    return p


def _run_timeout_arg(text: str) -> float:
    """``--run-timeout``'s value (:func:`locbench.run.containment.parse_run_timeout`) as argparse reads it."""
    from locbench.run.containment import parse_run_timeout

    try:
        return parse_run_timeout(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seconds > 0, or 0/none for no limit, got {text!r}") from None


def _add_run_timeout(p: argparse.ArgumentParser) -> None:
    from locbench.run.containment import DEFAULT_RULE

    p.add_argument(
        "--run-timeout",
        type=_run_timeout_arg,
        default=None,
        metavar="S",
        help=f"time limit of each run, s; 0 or none: no limit (default {DEFAULT_RULE}); a run past it is an "
        "error run and the sweep goes on",
    )


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``locbench`` console script."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(name)s: %(message)s"
    )
    from locbench.run.containment import run_timeout

    try:
        with run_timeout(getattr(args, "run_timeout", None)):  # the runs planned by the command get the limit
            return int(args.func(args))
    except LocbenchError as exc:
        # one line that says what is valid; the traceback would hide it
        print(f"locbench: error: {one_line(str(exc))}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"locbench: error: {one_line(os_error_line(exc))}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


#: What to do about an operating-system error, by errno.
_OS_HINTS = {
    errno.EACCES: "choose a folder you may write, or fix its permissions",
    errno.EPERM: "choose a folder you may write, or fix its permissions",
    errno.EROFS: "the file system is read-only; choose a folder on a writable one",
    errno.ENOSPC: "the disk is full; free space or choose another folder",
    errno.EDQUOT: "the disk quota is exhausted; free space or choose another folder",
    errno.ENOTDIR: "a file stands where a folder is needed; give a folder",
    errno.EISDIR: "a folder stands where a file is needed; give a file",
    errno.ENOENT: "it does not exist",
}


def os_error_line(exc: OSError) -> str:
    """One line for an operating-system or network error: the path, the reason, and what to do."""
    # requests' errors are OSErrors without errno; their text can hold a nested repr: keep the first line
    reason = exc.strerror or (str(exc).splitlines() or [type(exc).__name__])[0]
    where = f"{exc.filename}: " if exc.filename else ""
    hint = _OS_HINTS.get(exc.errno or 0)
    return f"{where}{reason}" + (f" ({hint})" if hint else "")


if __name__ == "__main__":
    sys.exit(main())
