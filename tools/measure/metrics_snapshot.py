"""Snapshot what the report reads from a store (metric rows, NEES series, health series) and compare two snapshots.

Usage: python tools/measure/metrics_snapshot.py RESULTS OUT.pkl [--compare BEFORE.pkl]

Reads every run of the store the way ``locbench report`` does (:mod:`locbench.report.collect`) and pickles, per
run folder, its tidy metric rows, its NEES at the ground-truth times and its lost-detection health series. With
``--compare`` it exits 1 unless every value equals the earlier snapshot bit for bit (NaN positions, signs of
zero, dtypes and shapes included): the check that a refactoring of the metrics changed no number. Take the
earlier snapshot with the code before the change (another checkout or virtual environment) on the same store.
"""

from __future__ import annotations

import importlib
import pickle
import sys
from pathlib import Path
from typing import Any

import numpy as np

from locbench.run.store import Store

# the module, not the function of the same name that locbench.report re-exports
collect = importlib.import_module("locbench.report.collect")


def snapshot(results: Path) -> dict[str, Any]:
    """Run folder -> (rows, NEES series, health series) or ("broken", message)."""
    store = Store(results)
    reads, _ = collect._read_runs(store, None, sorted(store.iter_runs()))
    out: dict[str, Any] = {}
    for kind, rel, payload in reads:
        if kind != "ok":
            out[rel] = ("broken", payload)
            continue
        _meta, _info, rows, _key, ne, _run_dir, hs = payload
        out[rel] = (rows, ne, None if hs is None else (hs.t, hs.error_m, dict(hs.signals), hs.kidnap_t))
    return out


def same(a: Any, b: Any) -> bool:
    """Bit-identical: arrays by dtype, shape and bytes; floats by value (NaN equal to NaN) and sign."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return (
            isinstance(a, np.ndarray)
            and isinstance(b, np.ndarray)
            and a.dtype == b.dtype
            and a.shape == b.shape
            and a.tobytes() == b.tobytes()
        )
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, (tuple, list)):
        return isinstance(b, (tuple, list)) and len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) and isinstance(b, float):
        return bool((np.isnan(a) and np.isnan(b)) or (a == b and np.signbit(a) == np.signbit(b)))
    return bool(a == b)


def main() -> int:
    results, out = Path(sys.argv[1]), Path(sys.argv[2])
    snap = snapshot(results)
    out.write_bytes(pickle.dumps(snap))
    rows = sum(len(v[0]) for v in snap.values() if v[0] != "broken")
    print(f"{len(snap)} runs, {rows} metric rows -> {out}")
    if len(sys.argv) > 4 and sys.argv[3] == "--compare":
        before = pickle.loads(Path(sys.argv[4]).read_bytes())
        if before.keys() != snap.keys():
            print("different runs:", sorted(before.keys() ^ snap.keys()))
            return 1
        bad = [k for k in snap if not same(before[k], snap[k])]
        print("differ:", ", ".join(bad) if bad else "none")
        return 1 if bad else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
