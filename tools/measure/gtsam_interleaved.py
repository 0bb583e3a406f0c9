"""Interleaved rounds of the gtsam_fls benchmark cases in one process, for ratios on a noisy machine.

pytest-benchmark runs its cases one after another, so on a shared machine the load can change between the
filter's rounds and the minimal loop's and move their ratio by 2x. This runs one round of each case in turn
(filter, wrapper alone, the minimal loop that builds the same graph from the same events; optionally first
the filter of another checkout and its wrapper), 21 times by default, and prints the median time per
observation of each and the median of the per-round ratios. The cases are those of
``tests/perf/test_gtsam_perf.py`` (imported from it)::

    python tools/measure/gtsam_interleaved.py
    git show main:filters/gtsam_fls.py > /tmp/gtsam_fls_main.py
    python tools/measure/gtsam_interleaved.py --before /tmp/gtsam_fls_main.py
"""

from __future__ import annotations

import argparse
import importlib.util
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from locbench.registry import make_dataset


def _load(name: str, path: Path) -> ModuleType:
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses look their module up while the class is made
    spec.loader.exec_module(module)
    return module


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=21)
    parser.add_argument("--before", type=Path, help="another gtsam_fls.py to run as the 'before' filter")
    args = parser.parse_args(argv)
    bench = _load("_gtsam_perf", Path(__file__).resolve().parents[2] / "tests" / "perf" / "test_gtsam_perf.py")
    ds = make_dataset("office", 0)
    events, _, make, answers = bench._record(ds)

    def filter_round(cls: Any = None, stub: bool = False) -> float:
        flt = bench._fresh_filter(ds) if cls is None else cls(bench.resolve_filter("gtsam_fls").params)
        if cls is not None:
            flt.reset(ds.initial, ds.world, ds.sensors, np.random.default_rng(0))
        if stub:
            flt._make_smoother = lambda: bench._Stub(answers)
        t = time.perf_counter()
        bench._run(flt, events)
        return time.perf_counter() - t

    def minimal_round() -> float:
        smoother = make()
        t = time.perf_counter()
        bench.minimal_loop(ds, events, smoother)
        return time.perf_counter() - t

    cases: dict[str, Callable[[], float]] = {}
    if args.before is not None:
        old = _load("locbench.filters._gtsam_fls_before", args.before)
        cases["before"] = lambda: filter_round(old.GtsamFixedLagSmoother)
        cases["before wrapper"] = lambda: filter_round(old.GtsamFixedLagSmoother, stub=True)
    cases |= {"filter": filter_round, "wrapper": lambda: filter_round(stub=True), "minimal": minimal_round}
    times: dict[str, list[float]] = {name: [] for name in cases}
    for _ in range(args.rounds + 1):  # the first round warms up and is dropped
        for name, run in cases.items():
            times[name].append(run())
    n = bench.N_OBS
    for name, ts in times.items():
        print(f"{name:<15} {1e6 * statistics.median(ts[1:]) / n:8.1f} us per observation (median of {args.rounds})")
    for name in times:
        if name != "minimal":
            ratios = [a / b for a, b in zip(times[name][1:], times["minimal"][1:], strict=True)]
            print(f"{name} / minimal {statistics.median(ratios):6.2f} x (median of the per-round ratios)")
    if "before" in times:
        for after, before in (("filter", "before"), ("wrapper", "before wrapper")):
            ratios = [a / b for a, b in zip(times[after][1:], times[before][1:], strict=True)]
            print(f"{after} / {before} {statistics.median(ratios):6.2f} x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
