"""Timed steps without compilation: the warm-up pass compiles every filter's kernels before its clock starts.

The child process below is a fresh process: each numba kernel's first call there compiles it or loads it from
the on-disk cache, both under numba's global compiler lock, whose acquisitions numba reports as
``numba:compiler_lock`` events (``numba.core.event``). The child counts the outermost ones that start inside a
timed ``predict``/``update`` call, in the first and the second pass of each filter: that first-call work in the
timed steps is what made a first run's real-time factor a fraction of the second's. Counting events, not
comparing times, keeps the test independent of the machine's load.
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from locbench.registry import make_dataset, make_filter
from locbench.run import filter_pass
from locbench.run.filter_pass import run_filter

CHILD = r"""
import json, sys, time
from numba.core import event
from locbench.registry import FILTERS, make_dataset, make_filter
from locbench.run.filter_pass import incompatibility, run_filter
import numpy as np


class Compiles(event.Listener):
    # outermost compiler-lock events (a compile or a cache load) and their time: callees nest inside
    def __init__(self):
        self.count, self.ns, self._depth, self._start = 0, 0, 0, 0

    def on_start(self, ev):
        if self._depth == 0:
            self.count += 1
            self._start = time.perf_counter_ns()
        self._depth += 1

    def on_end(self, ev):
        self._depth -= 1
        if self._depth == 0:
            self.ns += time.perf_counter_ns() - self._start


compiles = Compiles()
event.register("numba:compiler_lock", compiles)
datasets = [make_dataset(name, 0) for name in ("tiny_line", "scan_grid")]
out = {}
for fid in sys.argv[1:]:
    flt = make_filter(fid)
    ds = next(d for d in datasets if incompatibility(flt, d) is None)
    passes = []
    for _ in range(2):
        flt = make_filter(fid)
        timed = {"count": 0, "ns": 0}

        def timed_call(call):
            def wrapped(ev):
                n, ns = compiles.count, compiles.ns
                try:
                    return call(ev)
                finally:
                    timed["count"] += compiles.count - n
                    timed["ns"] += compiles.ns - ns
            return wrapped

        flt.predict, flt.update = timed_call(flt.predict), timed_call(flt.update)
        before = compiles.count
        trace = run_filter(flt, ds, np.random.default_rng(7))
        passes.append({
            "status": trace.status,
            "compiles": compiles.count - before,
            "timed_compiles": timed["count"],
            "timed_compile_ns": timed["ns"],
            "step_ns": int(trace.step_ns.sum()),
            "mean": trace.mean.tolist(),
        })
    out[fid] = {"dataset": ds.id, "passes": passes}
print(json.dumps(out))
"""


def _child(filters: list[str]) -> dict[str, dict[str, object]]:
    done = subprocess.run(
        [sys.executable, "-c", CHILD, *filters], capture_output=True, text=True, timeout=900, check=False
    )
    assert done.returncode == 0, done.stderr[-3000:]
    result: dict[str, dict[str, object]] = json.loads(done.stdout.splitlines()[-1])
    return result


@pytest.mark.slow
def test_no_compilation_inside_the_timed_steps_of_a_fresh_process() -> None:
    from locbench.registry import FILTERS

    filters = sorted(FILTERS.ids())
    res = _child(filters)
    compiled_somewhere = 0
    for fid in filters:
        first, second = res[fid]["passes"]  # type: ignore[misc]
        assert first["status"] == second["status"] == "ok", (fid, first["status"])
        # the first pass of the process compiles or loads its kernels (in its warm-up), never inside a timed call
        assert first["timed_compiles"] == 0 and first["timed_compile_ns"] == 0, (fid, first)
        assert second["compiles"] == 0 and second["timed_compiles"] == 0, (fid, second)
        # the same estimates, bit for bit, warmed or not: the warm-up's instance shares nothing with the timed one
        assert first["mean"] == second["mean"], fid
        compiled_somewhere += first["compiles"]
    # the count can fail: the fresh process compiles or loads kernels, in the warm-ups
    assert compiled_somewhere > 0


@pytest.mark.parametrize("fid", ["ekf_landmarks", "pf[particles=200]", "ekf_icp", "odometry"])
def test_the_warm_up_leaves_the_estimates_bit_identical(fid: str, monkeypatch: pytest.MonkeyPatch) -> None:
    ds = make_dataset("tiny_line", 0)
    warmed = run_filter(make_filter(fid), ds, np.random.default_rng(3))
    monkeypatch.setattr(filter_pass, "warm_up", lambda flt, ds: False)
    cold = run_filter(make_filter(fid), ds, np.random.default_rng(3))
    assert warmed.status == cold.status == "ok"
    for a, b in ((warmed.mean, cold.mean), (warmed.cov, cold.cov), (warmed.t, cold.t)):
        np.testing.assert_array_equal(a, b)  # our code against itself on one machine


def test_warm_events_cover_every_routed_type() -> None:
    ds = make_dataset("tiny_line", 0)
    flt = make_filter("ekf_landmarks")
    evs = filter_pass._warm_events(flt.routed_events(), ds.events)
    types = [type(e) for e in evs]
    routed = flt.routed_events() & {type(e) for e in ds.events}
    assert len(evs) >= filter_pass.WARM_EVENTS
    assert all(types.count(t) >= filter_pass.WARM_PER_TYPE for t in routed)
    assert all(t in flt.routed_events() or t.__name__ == "Odometry" for t in types)
    # a warm-up runs once per process for one (filter class, config, event types)
    filter_pass._WARMED.discard((type(flt), repr(flt.config), frozenset(type(e) for e in ds.events)))
    assert filter_pass.warm_up(flt, ds) is True
    assert filter_pass.warm_up(make_filter("ekf_landmarks"), ds) is False
