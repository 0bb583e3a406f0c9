"""The ``locbench`` command line: a thin layer over the library API.

locbench list
locbench run [--suite NAME|FILE.toml | --filter SPEC ... --dataset SPEC ...]
             [--seeds N] [--results DIR] [--jobs N] [--force]
locbench report [--results DIR] [--suite NAME] [--out DIR]
locbench check [ID ...]
locbench fetch SPEC [SPEC ...]
locbench export [--results DIR] [--out DIR] [--dataset SPEC ...] [--filter SPEC ...] [--smoothed]
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

from locbench import __version__
from locbench.errors import ConfigError, LocbenchError

log = logging.getLogger("locbench")

DEFAULT_RESULTS = "results"


def _results_default() -> str:
    return os.environ.get("LOCBENCH_RESULTS", DEFAULT_RESULTS)


def _cmd_list(args: argparse.Namespace) -> int:
    from locbench.registry import DATASETS, FILTERS
    from locbench.suites import SUITES

    for title, reg in (("filters", FILTERS), ("datasets", DATASETS)):
        print(f"{title}:")
        for ident in reg.ids():
            reason = reg.unavailable_reason(ident)
            state = f"  [{reason}]" if reason else ""
            print(f"  {ident:<18} {reg.entry(ident).summary}{state}")
    print("suites:")
    for s in SUITES.values():
        print(f"  {s.name:<18} {s.runs:>5} runs: {s.description}")
    return 0


def _cmd_run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from locbench.registry import resolve_dataset, resolve_filter
    from locbench.runner import run_many
    from locbench.suites import Block, get_suite

    if args.suite and (args.filter or args.dataset):
        raise ConfigError("give either --suite or --filter/--dataset, not both")
    if args.seeds is not None and args.seeds < 1:
        raise ConfigError(f"--seeds must be >= 1, got {args.seeds}")
    if args.jobs < 1:
        raise ConfigError(f"--jobs must be >= 1, got {args.jobs}")
    if args.filter or args.dataset:
        if not (args.filter and args.dataset):
            raise ConfigError("--filter and --dataset go together: name at least one of each (see 'locbench list')")
        blocks = [Block(tuple(args.filter), tuple(args.dataset), args.seeds or 1)]
    else:
        blocks = []
        for name in args.suite or ["default"]:
            suite = get_suite(name)
            blocks += list((suite.with_seeds(args.seeds) if args.seeds else suite).blocks)
    # resolve every spec before running anything, so a typo fails at once
    for b in blocks:
        for spec in b.filters:
            resolve_filter(spec)
        for spec in b.datasets:
            resolve_dataset(spec)
    total = sum(b.runs for b in blocks)
    outcomes = []
    with tqdm(total=total, unit="run", desc="locbench run", disable=None if not args.no_progress else True) as bar:
        for b in blocks:
            outcomes += run_many(
                list(b.filters),
                list(b.datasets),
                list(range(b.seeds)),
                args.results,
                jobs=args.jobs,
                force=args.force,
                progress=bar.update,
            )
    counts = Counter(o.status for o in outcomes)
    print(f"{len(outcomes)} runs in {args.results}/runs: " + ", ".join(f"{n} {s}" for s, n in sorted(counts.items())))
    for o in outcomes:
        if o.status in ("error", "diverged", "skipped"):
            print(f"  {o.status}: {o.filter} on {o.dataset} seed {o.seed}: {o.message}")
    return 0


def _cmd_report(args: argparse.Namespace) -> int:
    from locbench.report import suite_filter, summary_text, write_report
    from locbench.store import Store

    store = Store(args.results)
    if not store.runs.is_dir():
        raise ConfigError(f"{store.runs}: no stored runs; run 'locbench run' first")
    keep = suite_filter(args.suite) if args.suite else None
    out = Path(args.out) if args.out else None
    paths = write_report(store, keep=keep, out=out)
    print(summary_text(paths.summary), end="")
    print(f"report written to {paths.markdown} and {paths.html}")
    return 0


def _cmd_check(args: argparse.Namespace) -> int:
    from locbench.checks import run_checks

    failed = 0
    for r in run_checks(list(args.ids) or None):
        mark = {"passed": "ok", "failed": "FAIL", "xfailed": "xfail", "xpassed": "XPASS", "skipped": "skip"}[r.outcome]
        print(f"{mark:<5} {r.target:<32} {r.check}" + (f": {r.message}" if r.message else ""))
        failed += r.outcome in ("failed", "xpassed")
    print(f"{failed} check(s) failed" if failed else "all checks passed")
    return 1 if failed else 0


def _cmd_fetch(args: argparse.Namespace) -> int:
    from locbench.registry import DATASETS, resolve_dataset

    for spec in args.specs:
        r = resolve_dataset(spec)
        paths = DATASETS.load(r.id)().fetch(r.params)
        if not paths:
            print(f"{r.name}: nothing to fetch (synthetic)")
        for path in paths:
            print(f"{r.name}: {path}")
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    from pathlib import Path

    from locbench.export import export_results
    from locbench.registry import resolve_dataset, resolve_filter

    out = args.out or str(Path(args.results) / "tum")
    written = export_results(
        args.results,
        out,
        datasets=[resolve_dataset(s).name for s in args.dataset],
        filters=[resolve_filter(s).name for s in args.filter],
        smoothed=args.smoothed,
    )
    print(f"{len(written)} TUM trajectory files written under {out}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="locbench", description="Comparative benchmark of 2-D localization filters.")
    p.add_argument("--version", action="version", version=f"locbench {__version__}")
    p.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    sub = p.add_subparsers(dest="command", required=True)

    sub.add_parser("list", help="registered filters, datasets and suites").set_defaults(func=_cmd_list)

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
    r.add_argument("--jobs", type=int, default=1, help="worker processes (default 1)")
    r.add_argument("--force", action="store_true", help="re-run runs that are already stored")
    r.add_argument("--no-progress", action="store_true", help="no progress bar")
    r.set_defaults(func=_cmd_run)

    rep = sub.add_parser("report", help="write summary/metrics.csv, REPORT.md and figures from stored runs")
    rep.add_argument("--results", default=_results_default(), help="results folder (default: results/)")
    rep.add_argument(
        "--suite", default=None, help="report only the runs of this suite (a name or a TOML file), not every stored run"
    )
    rep.add_argument("--out", default=None, help="write the summary here instead of RESULTS/summary")
    rep.set_defaults(func=_cmd_report)

    c = sub.add_parser("check", help="conformance checks for filters and datasets")
    c.add_argument("ids", nargs="*", help="filter or dataset ids/specs (default: all registered)")
    c.set_defaults(func=_cmd_check)

    fe = sub.add_parser(
        "fetch",
        help="download recorded datasets from their official source into the cache, verified by sha256",
    )
    fe.add_argument("specs", nargs="+", metavar="SPEC", help="e.g. plaza[run=1] or mrclam[dataset=6,robot=1]")
    fe.set_defaults(func=_cmd_fetch)

    ex = sub.add_parser("export", help="write stored runs and their truth as TUM trajectories (for evo)")
    ex.add_argument("--results", default=_results_default(), help="results folder (default: results/)")
    ex.add_argument("--out", default=None, help="output folder (default: RESULTS/tum)")
    ex.add_argument("--dataset", nargs="+", action="extend", default=[], metavar="SPEC", help="only these datasets")
    ex.add_argument("--filter", nargs="+", action="extend", default=[], metavar="SPEC", help="only these filters")
    ex.add_argument("--smoothed", action="store_true", help="export smoothed trajectories (gtsam_fls) instead")
    ex.set_defaults(func=_cmd_export)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``locbench`` console script."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(name)s: %(message)s"
    )
    try:
        return int(args.func(args))
    except LocbenchError as exc:
        # one line that says what is valid; the traceback would hide it
        print(f"locbench: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
