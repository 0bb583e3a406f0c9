"""Replay one dataset realisation through one filter and print the median update time.

The before/after figures of docs/history/performance.md: run it once with each checkout's interpreter (for a
paired whole-process comparison, alternate the two commands under a process timer such as
``/usr/bin/time -v``)::

    python tools/measure/replay_timing.py kf_linear office
    python tools/measure/replay_timing.py 'pf[particles=10000]' office --repeat 3

Every event is fed as the runner feeds it (predict for odometry, update for the routed observations, an
estimate after each), with the runner's seed; each call is timed with ``perf_counter_ns``. The first line
gives the update median; the second the predict median and the filter's own time over the run (every
predict, update and estimate; the runner stores the same per-step times as ``step_ns``).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

from locbench.core.events import Odometry
from locbench.core.seeding import filter_rng
from locbench.registry import FILTERS, make_dataset, resolve_filter


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("filter", help="filter spec, e.g. 'pf[particles=10000]'")
    parser.add_argument("dataset", help="dataset spec, e.g. office")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--repeat", type=int, default=1, help="replays of the whole run (a fresh filter each)")
    args = parser.parse_args(argv)
    ds = make_dataset(args.dataset, args.seed)
    fr = resolve_filter(args.filter)
    cls = FILTERS.load(fr.id)
    times: list[int] = []
    predict_times: list[int] = []
    total = 0
    for _ in range(args.repeat):
        flt = cls(fr.params)
        flt.reset(ds.initial, ds.world, ds.sensors, filter_rng(fr.name, ds.name, args.seed))
        routed = flt.routed_events()
        for ev in ds.events:
            t0 = time.perf_counter_ns()
            if isinstance(ev, Odometry):
                flt.predict(ev)
                predict_times.append(time.perf_counter_ns() - t0)
            elif type(ev) in routed:
                flt.update(ev)
                times.append(time.perf_counter_ns() - t0)
            flt.estimate()
            total += time.perf_counter_ns() - t0
    if not times:
        print(f"{args.filter} on {args.dataset}: no update calls", file=sys.stderr)
        return 1
    print(f"{args.filter} on {args.dataset}: {len(times)} updates, median {statistics.median(times) / 1e3:.1f} us")
    p_med = statistics.median(predict_times) / 1e3 if predict_times else float("nan")
    print(
        f"  {len(predict_times)} predicts, median {p_med:.1f} us; filter time {total / 1e9 / args.repeat:.3f} s per run"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
