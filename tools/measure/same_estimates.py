"""Store every array of ``run_filter`` for filters x datasets x seeds, or compare two such files exactly.

The "bit-identical" checks of docs/history/performance.md: run ``dump`` with each checkout's package (for
main, e.g. a copy of its tree on ``PYTHONPATH``), then ``compare``::

    python tools/measure/same_estimates.py dump before.npz "ekf_landmarks;ekf_icp" "office;lap" 2
    python tools/measure/same_estimates.py dump after.npz "ekf_landmarks;ekf_icp" "office;lap" 2
    python tools/measure/same_estimates.py compare before.npz after.npz

Each run keeps its times, means, covariances, kinds, every diagnostic, health signal and extra array, the order of
the diagnostics' and health signals' names, and its status (not the step times);
``compare`` lists the arrays that differ (NaN equal to NaN) and exits 1 if any does.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from locbench.core.seeding import filter_rng
from locbench.registry import make_dataset, make_filter, resolve_filter
from locbench.run.filter_pass import run_filter


def dump(out: str, filters: list[str], datasets: list[str], seeds: int) -> None:
    """Run every filter on every dataset realisation (seeds 0 .. ``seeds`` - 1) and save the arrays."""
    arrays: dict[str, np.ndarray] = {}
    for name in datasets:
        for seed in range(seeds):
            ds = make_dataset(name, seed)
            for spec in filters:
                trace = run_filter(make_filter(spec), ds, filter_rng(resolve_filter(spec).name, ds.name, seed))
                key = f"{spec}|{name}|{seed}"
                arrays |= {f"{key}|t": trace.t, f"{key}|mean": trace.mean, f"{key}|cov": trace.cov}
                arrays |= {f"{key}|kind": trace.kind, f"{key}|status": np.array([trace.status])}
                arrays |= {f"{key}|d|{d}": v for d, v in trace.diagnostics.items()}
                arrays |= {f"{key}|h|{h}": v for h, v in trace.health.items()}
                arrays |= {f"{key}|x|{x}": v for x, v in trace.extra.items()}
                arrays[f"{key}|order"] = np.array([",".join(trace.diagnostics), ",".join(trace.health)])
                print(key, trace.status, len(trace.t), flush=True)
    np.savez(out, **arrays)


def compare(a_path: str, b_path: str) -> int:
    """Print how many arrays differ between two dumps; 1 if any differs or a key is missing."""
    a, b = np.load(a_path), np.load(b_path)
    missing = sorted(set(a.files) ^ set(b.files))
    bad = [k for k in sorted(set(a.files) & set(b.files)) if not np.array_equal(a[k], b[k], a[k].dtype.kind == "f")]
    print(f"{len(a.files)} arrays; {len(bad)} differ; {len(missing)} in one file only")
    for k in bad + missing:
        print("  ", k)
    return 1 if bad or missing else 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="cmd", required=True)
    d = sub.add_parser("dump")
    d.add_argument("out")
    d.add_argument("filters", help="filter specs separated by ';'")
    d.add_argument("datasets", help="dataset specs separated by ';'")
    d.add_argument("seeds", type=int)
    c = sub.add_parser("compare")
    c.add_argument("a")
    c.add_argument("b")
    args = parser.parse_args(argv)
    if args.cmd == "dump":
        dump(args.out, args.filters.split(";"), args.datasets.split(";"), args.seeds)
        return 0
    return compare(args.a, args.b)


if __name__ == "__main__":
    sys.exit(main())
