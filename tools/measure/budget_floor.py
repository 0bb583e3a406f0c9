"""What a full store says about the whole benchmark's wall time: the run-seconds by suite and filter, split into
the filters' own steps and the runner's work around them, the dataset builds and the bounds, and the wall time
two cores could reach if nothing else cost anything.

    python tools/measure/budget_floor.py results [--cores 2]
    python tools/measure/budget_floor.py --belief office pf 'pf[augmented=true]' kf_linear   # the belief scores' share

Reads only what the sweep recorded: each run's ``wall_s`` (its whole pass: the filter's steps, the runner's row
bookkeeping, the belief scores) and ``compute_s`` (the sum of its per-step ``step_ns``: predict and update only),
each truth's ``build_s`` and each bound's ``compute_s``; the tuning studies' trial runs under ``results/tuning``.
A run that two suites share is counted once, in the first suite of ``SUITE_ORDER`` that has it. The floor is the
sum of those seconds over the cores: it leaves out the install, the numba compiles, the process starts, the store's
writes, ``verify`` and the report, so the measured wall time can only be above it.
"""

from __future__ import annotations

import argparse
import collections
import json
import statistics
import time
from pathlib import Path

from locbench.run.store import TRUTH_DIR, Store
from locbench.run.tuning import suite_studies
from locbench.suites import _SUITES_IN_ALL, suite_pairs

#: The suites ``nox -s bench`` runs (suite ``all``'s parts, then ``consistency``); ``tuned``'s test runs are
#: what is left over.
SUITE_ORDER = (*_SUITES_IN_ALL, "consistency")


def _metas(results: Path) -> list[dict]:
    """The ``meta.json`` of every run of the store at ``results`` (its leftovers left out, as the report does)."""
    return [json.loads((run / "meta.json").read_text()) for run in Store(results).iter_runs()]


def _truth_seconds(results: Path) -> tuple[float, float]:
    """The dataset builds' and the bounds' seconds of the store at ``results``, each realisation once."""
    build = bound = 0.0
    for p in Store(results).runs.glob(f"*/{TRUTH_DIR}/*.json"):
        d = json.loads(p.read_text())
        if p.name.endswith(".bound.json"):
            bound += d.get("compute_s") or 0.0
        else:
            build += d.get("build_s") or 0.0
    return build, bound


def belief_share(dataset: str, filters: list[str], rounds: int = 7) -> None:
    """Per filter, the CPU seconds of a run on ``dataset`` seed 0 (one process, median of ``rounds``), its steps,
    the time around them, and the part of a run the runner's belief scores take (a run without the runner's
    belief generator, in turn with one with it)."""
    from locbench.core.seeding import belief_rng, filter_rng
    from locbench.registry import FILTERS, make_dataset, resolve_filter
    from locbench.run.runner import run_filter

    ds = make_dataset(dataset, 0)
    for spec in filters:
        fr = resolve_filter(spec)

        def once(score: bool, fr=fr) -> tuple[float, float]:
            flt = FILTERS.load(fr.id)(fr.params)
            rng, brng = filter_rng(fr.name, dataset, 0), belief_rng(fr.name, dataset, 0) if score else None
            t = time.process_time()
            trace = run_filter(flt, ds, rng, brng)
            return time.process_time() - t, float(trace.step_ns.sum()) / 1e9

        once(True), once(False)  # compiles and caches
        with_scores, without = [], []
        for _ in range(rounds):
            with_scores.append(once(True))
            without.append(once(False))
        run = statistics.median(x[0] for x in with_scores)
        steps = statistics.median(x[1] for x in with_scores)
        bare = statistics.median(x[0] for x in without)
        around, scores = run - steps, run - bare
        print(f"{spec:50s} run {run:.3f} steps {steps:.3f} around {around:.3f} belief scores {scores:.3f} CPU-s")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", type=Path, nargs="?", default=Path("results"))
    ap.add_argument("--cores", type=int, default=2)
    ap.add_argument("--belief", nargs="+", metavar="DATASET FILTER", help="measure the belief scores' share instead")
    args = ap.parse_args(argv)
    if args.belief:
        belief_share(args.belief[0], args.belief[1:])
        return 0
    owner: dict[tuple[str, str], str] = {}
    for name in SUITE_ORDER:
        for f, d in suite_pairs(name):
            owner.setdefault((str(f), str(d)), name)
    wall: collections.Counter[str] = collections.Counter()
    step: collections.Counter[str] = collections.Counter()
    runs: collections.Counter[str] = collections.Counter()
    by_filter: collections.Counter[str] = collections.Counter()
    by_filter_step: collections.Counter[str] = collections.Counter()
    for m in _metas(args.results):
        suite = owner.get((m["filter"], m["dataset"]), "tuned (test runs)")
        wall[suite] += m.get("wall_s") or 0.0
        step[suite] += m.get("compute_s") or 0.0
        runs[suite] += 1
        by_filter[m["filter_id"]] += m.get("wall_s") or 0.0
        by_filter_step[m["filter_id"]] += m.get("compute_s") or 0.0
    tuning_runs = _metas(args.results / "tuning")
    wall["tuned (trials)"] = sum(m.get("wall_s") or 0.0 for m in tuning_runs)
    step["tuned (trials)"] = sum(m.get("compute_s") or 0.0 for m in tuning_runs)
    runs["tuned (trials)"] = len(tuning_runs)
    build, bound = _truth_seconds(args.results)
    t_build, t_bound = _truth_seconds(args.results / "tuning")

    print(f"{'suite':22s} {'runs':>5s} {'run-s':>8s} {'steps-s':>8s} {'around-s':>8s}")
    for name in (*SUITE_ORDER, "tuned (test runs)", "tuned (trials)"):
        print(f"{name:22s} {runs[name]:5d} {wall[name]:8.0f} {step[name]:8.0f} {wall[name] - step[name]:8.0f}")
    total_wall, total_step = sum(wall.values()), sum(step.values())
    print(f"{'all':22s} {sum(runs.values()):5d} {total_wall:8.0f} {total_step:8.0f} {total_wall - total_step:8.0f}")
    print()
    print(f"{'filter':22s} {'run-s':>8s} {'steps-s':>8s} {'around-s':>8s}")
    for k, v in by_filter.most_common():
        print(f"{k:22s} {v:8.0f} {by_filter_step[k]:8.0f} {v - by_filter_step[k]:8.0f}")
    print()
    print(f"dataset builds {build + t_build:.0f} s, bounds {bound + t_bound:.0f} s (each realisation once)")
    print(f"studies: {len(suite_studies())}")
    floor = total_wall + build + bound + t_build + t_bound
    steps_only = total_step + build + bound + t_build + t_bound
    c = args.cores
    print(f"floor on {c} cores, the runs as measured: {floor / c / 60:.1f} min")
    print(f"floor on {c} cores, no time around the filters' steps: {steps_only / c / 60:.1f} min")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
