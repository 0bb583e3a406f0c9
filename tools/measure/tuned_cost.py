"""Measure the CPU seconds of suite ``tuned``, by phase: the studies, the tuned runs on test data, the defaults there.

    python tools/measure/tuned_cost.py RESULTS_DIR [--jobs 2] [--trials 6]

Phase 1 runs every study of the suite as ``locbench run --suite tuned`` does (a pool of ``--jobs`` processes, one
study each at a time) and prints each study's CPU seconds (``time.process_time`` in its worker) as it finishes;
phase 2 runs the tuned configurations on the test data, phase 3 the defaults there (which ``nox -s bench`` has
stored already from suites ``default`` and ``recorded``, so phase 3 is not a cost of suite ``tuned``). Phases 2 and
3 print the CPU seconds of this process and its children. Run it on an empty folder; the numbers in the README
come from it.
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import resource
import sys
import time

from locbench.run import tuning
from locbench.run.runner import plan_sweep, run_sweep


def _cpu_all() -> float:
    """CPU seconds of this process and its waited-for children (user + system)."""
    s, c = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return s.ru_utime + s.ru_stime + c.ru_utime + c.ru_stime


def _study(s: tuning.SuiteStudy, results: str, trials: int) -> tuple[float, tuning.TuneResult]:
    t0 = time.process_time()
    r = tuning.tune(s.filter, s.train, trials, s.seeds, results, fail_stale=True)
    return time.process_time() - t0, r


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("results")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--trials", type=int, default=tuning.SUITE_TRIALS)
    args = ap.parse_args()
    studies = [s for s in tuning.suite_studies() if tuning._study_available(s) is None]
    order = sorted(studies, key=lambda s: (not s.train[0].startswith("mrclam"), s.filter != "pf"))
    w0, total = time.perf_counter(), 0.0
    done: dict[int, tuning.TuneResult] = {}
    with cf.ProcessPoolExecutor(max_workers=args.jobs) as pool:
        futures = {pool.submit(_study, s, args.results, args.trials): s for s in order}
        for fut in cf.as_completed(futures):
            s = futures[fut]
            cpu, r = fut.result()
            total += cpu
            done[studies.index(s)] = r
            best = r.best
            print(f"study {s.filter} on {s.world}: {cpu:.1f} CPU s, best {best.spec if best else None}", flush=True)
    print(f"phase 1 (tuning): {total:.1f} CPU s, {time.perf_counter() - w0:.1f} s wall", flush=True)
    tuned_blocks, default_blocks = [], []
    for i, s in enumerate(studies):
        best = done[i].best
        if best is not None:
            tuned_blocks.append(([best.spec], s.test, s.test_seeds))
        default_blocks.append(([s.filter], s.test, s.test_seeds))
    for name, blocks in (("phase 2 (tuned on test data)", tuned_blocks), ("phase 3 (defaults)", default_blocks)):
        c0, w0 = _cpu_all(), time.perf_counter()
        run_sweep(plan_sweep(blocks, args.results), "local", args.jobs)
        print(f"{name}: {_cpu_all() - c0:.1f} CPU s, {time.perf_counter() - w0:.1f} s wall", flush=True)
    tuning.write_summary(args.results, [(s, done[i]) for i, s in enumerate(studies)])
    return 0


if __name__ == "__main__":
    sys.exit(main())
