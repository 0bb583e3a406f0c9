"""How far two regenerations of the same runs agree on the accuracy-runtime figure (docs/history/performance.md).

Run the same ``locbench run`` twice into two results folders (for example once on an idle machine, once with the
cores busy), ``locbench report --results DIR`` each, then compare their ``summary/metrics.parquet``::

    python tools/measure/timing_transfer.py idle/summary/metrics.parquet busy/summary/metrics.parquet

For every (dataset, configuration) present in both, the figure's place is (mean real-time factor in reference
units over the seeds, mean ATE); the script prints the ratio B / A of the x coordinate, raw and in reference
units, checks that the y coordinate (ATE) is the same bit for bit, and summarises the ratios (median, range) and
the Spearman rank correlation of the configurations' x order. With ``--tolerance LO HI`` it exits 1 when a
configuration's reference-unit ratio falls outside [LO, HI].
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
import pandas as pd
from scipy import stats

from locbench.report.collect import read_metrics

#: The figure's x axis (reference units) and its raw counterpart; the y axis.
X_REF, X_RAW, Y = "realtime_factor_ref", "realtime_factor", "ate_m"


def places(path: str) -> pd.DataFrame:
    """Mean over seeds of the figure's coordinates per (dataset, filter), from one tidy ``metrics.parquet``."""
    tidy = read_metrics(path)
    tidy = tidy[tidy["metric"].isin([X_REF, X_RAW, Y])]
    wide = tidy.pivot_table(index=["dataset", "filter", "seed"], columns="metric", values="value", aggfunc="first")
    missing = {X_REF, X_RAW, Y} - set(wide.columns)
    if missing:
        raise SystemExit(f"{path}: no {', '.join(sorted(missing))} rows (runs stored before reference units?)")
    return wide.groupby(level=["dataset", "filter"]).mean()


def compare(a: pd.DataFrame, b: pd.DataFrame) -> pd.DataFrame:
    """Per configuration in both: x raw and in reference units in A and B, their ratios B / A, and ATE equality."""
    both = a.add_suffix("_a").join(b.add_suffix("_b"), how="inner")
    if both.empty:
        raise SystemExit("the two files share no (dataset, filter)")
    return pd.DataFrame(
        {
            "ref_x_a": both[f"{X_REF}_a"],
            "ref_x_b": both[f"{X_REF}_b"],
            "ratio_raw": both[f"{X_RAW}_b"] / both[f"{X_RAW}_a"],
            "ratio_ref": both[f"{X_REF}_b"] / both[f"{X_REF}_a"],
            "same_ate": both[f"{Y}_a"].to_numpy() == both[f"{Y}_b"].to_numpy(),
        }
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("a", help="metrics.parquet of the first regeneration (A, e.g. idle)")
    ap.add_argument("b", help="metrics.parquet of the second (B, e.g. busy)")
    ap.add_argument("--tolerance", nargs=2, type=float, metavar=("LO", "HI"), help="allowed B / A in reference units")
    args = ap.parse_args(argv)
    table = compare(places(args.a), places(args.b)).dropna()
    with pd.option_context("display.width", 160, "display.max_rows", 200):
        print(table.round(3).to_string())
    for col in ("ratio_raw", "ratio_ref"):
        v = table[col].to_numpy()
        print(f"{col}: median {np.median(v):.3f} ({v.min():.3f}-{v.max():.3f}) over {len(v)} configurations")
    rho = stats.spearmanr(table["ref_x_a"], table["ref_x_b"]).statistic
    print(f"x order (reference units), Spearman A vs B: {rho:.3f}; ATE identical: {bool(table['same_ate'].all())}")
    if args.tolerance is not None:
        lo, hi = args.tolerance
        out = table[(table["ratio_ref"] < lo) | (table["ratio_ref"] > hi)]
        if not out.empty:
            print(f"outside [{lo}, {hi}]: {', '.join(f'{d} {f}' for d, f in out.index)}")
            return 1
    return 0 if table["same_ate"].all() else 1


if __name__ == "__main__":
    sys.exit(main())
