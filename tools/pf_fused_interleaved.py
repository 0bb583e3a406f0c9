"""``pf``'s landmark step against its fused reference, in interleaved rounds (issue 24, item 1).

Loads the fused reference of ``tests/perf/test_pf_perf.py`` (the filter's own kernels in one compiled call)
and times, round after round, a block of filter steps and a block of fused steps on the office world; prints
per particle count the median step time of each and the median of the per-round ratios filter / fused. On a
shared machine pytest-benchmark's cases run minutes apart and their ratio drifts; interleaving pairs them.

    python tools/pf_fused_interleaved.py [--rounds 21] [--n 1000 10000 100000]
"""

from __future__ import annotations

import argparse
import importlib.util
import statistics
import time
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=21)
    ap.add_argument("--n", type=int, nargs="+", default=[1_000, 10_000, 100_000])
    args = ap.parse_args()
    path = Path(__file__).resolve().parent.parent / "tests" / "perf" / "test_pf_perf.py"
    spec = importlib.util.spec_from_file_location("pf_perf", path)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    for n in args.n:
        step, fused, _, _ = mod.make_steps(n)
        step()
        fused()
        k = max(3, 200_000 // n)  # steps per block: about 0.1 s of work
        a: list[float] = []
        b: list[float] = []
        for _ in range(args.rounds):
            t0 = time.perf_counter()
            for _ in range(k):
                step()
            t1 = time.perf_counter()
            for _ in range(k):
                fused()
            t2 = time.perf_counter()
            a.append((t1 - t0) / k)
            b.append((t2 - t1) / k)
        ratio = statistics.median(x / y for x, y in zip(a, b, strict=True))
        print(
            f"N={n:>6d}: filter {1e6 * statistics.median(a):9.1f} us/step, fused {1e6 * statistics.median(b):9.1f}"
            f" us/step, filter / fused {ratio:.3f} (median of {args.rounds} rounds)"
        )


if __name__ == "__main__":
    main()
