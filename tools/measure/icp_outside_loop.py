"""CPU seconds of ``ekf_icp``'s office replay (predict + update) inside its compiled ICP loop and outside it.

The before/after figures of docs/history/performance.md: run it with each checkout's package in
turn (main's, e.g. a copy of its tree on ``PYTHONPATH``, then the branch's) and compare the ``outside``
figures pair by pair::

    python tools/measure/icp_outside_loop.py

Four replays of the office dataset (seed 0); the first compiles and fills the caches and is not counted; the
medians of the other three are printed. The loop's time comes from a timer around ``_icp._icp_loop``.
"""

from __future__ import annotations

import statistics
import time
from typing import Any

import numpy as np

from locbench.core.events import LaserScan, Odometry
from locbench.filters import _icp
from locbench.registry import make_dataset, make_filter


def main() -> None:
    ds = make_dataset("office", 0)
    flt = make_filter("ekf_icp")
    clock = time.thread_time
    in_loop = [0.0]
    loop = _icp._icp_loop

    def timed_loop(*args: Any) -> Any:
        t0 = clock()
        out = loop(*args)
        in_loop[0] += clock() - t0
        return out

    _icp._icp_loop = timed_loop
    events = [e for e in ds.events if type(e) in (Odometry, LaserScan)]
    totals, loops = [], []
    for rep in range(4):
        in_loop[0] = 0.0
        flt.reset(ds.initial, ds.world, ds.sensors, np.random.default_rng(0))
        t0 = clock()
        for e in events:
            if type(e) is Odometry:
                flt.predict(e)
            else:
                flt.update(e)
        if rep:
            totals.append(clock() - t0)
            loops.append(in_loop[0])
    outside = [a - b for a, b in zip(totals, loops, strict=True)]
    med = statistics.median
    print(f"total {med(totals):.3f} loop {med(loops):.3f} outside {med(outside):.3f}")


if __name__ == "__main__":
    main()
