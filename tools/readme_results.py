"""Print the README's "Results" figures from a regenerated results/summary/metrics.csv.

Usage: ``python tools/readme_results.py [results/summary/metrics.csv]``. The README quotes these numbers;
after ``nox -s bench`` this prints them again so that the README and the summary never disagree.
"""

from __future__ import annotations

import sys

import numpy as np
import pandas as pd

from locbench.pcrb import BOUND_ALL, BOUND_NO_LASER
from locbench.report.tables import ate_over_bound, rate
from locbench.suites import KIDNAP_DISTANCES_M, KIDNAP_FILTERS


def mean(df: pd.DataFrame, metric: str) -> float:
    v = df.loc[df["metric"] == metric, "value"].to_numpy(dtype=np.float64)
    v = v[np.isfinite(v)]
    return float(np.mean(v)) if v.size else float("nan")


def headline(df: pd.DataFrame, dataset: str, filters: list[str]) -> None:
    sub = df[df["dataset"] == dataset]
    print(f"\n{dataset}: filter | runs | ATE cm | ATE/PCRB | ATE/PCRB(no laser) | ANEES | update us | RTF")
    for f in filters:
        s = sub[sub["filter"] == f]
        if s.empty:
            continue
        no_laser = sub[sub["filter"].isin([f, BOUND_NO_LASER])].replace({BOUND_NO_LASER: BOUND_ALL})
        print(
            f"{f} | {s['seed'].nunique()} | {100 * mean(s, 'ate_m'):.3g} | {ate_over_bound(sub, f):.3g} | "
            f"{ate_over_bound(no_laser, f):.3g} | {mean(s, 'anees'):.3g} | {mean(s, 'update_us_median'):.3g} | "
            f"{mean(s, 'realtime_factor'):.4g}"
        )
    for b in (BOUND_ALL, BOUND_NO_LASER):
        s = sub[sub["filter"] == b]
        if not s.empty:
            rms = np.sqrt(np.mean(s[s["metric"] == "ate_m"]["value"] ** 2))
            print(f"{b} | {s['seed'].nunique()} | {100 * rms:.3g} (RMS)")


def kidnaps(df: pd.DataFrame) -> None:
    for base in ("office", "room"):
        print(f"\nkidnap recovery on {base} at D = {KIDNAP_DISTANCES_M}")
        names = sorted({str(f) for f in df[df["dataset"].str.startswith(f"{base}[kidnap_m=")]["filter"].unique()})
        for f in [*KIDNAP_FILTERS, *(n for n in names if n not in KIDNAP_FILTERS)]:
            cells = []
            for d in KIDNAP_DISTANCES_M:
                sub = df[(df["dataset"] == f"{base}[kidnap_m={d:g}]") & (df["filter"] == f)]
                k, n, _, _, _ = rate(sub, "kidnap_recovered")
                cells.append(f"{k}/{n}" if n else "-")
            print(f"{f}: {' / '.join(cells)}")


def consistency(df: pd.DataFrame) -> None:
    for ds in ("room[matched=true]", "office[matched=true]"):
        sub = df[df["dataset"] == ds]
        print(f"\n{ds}: filter | runs | mean ANEES | inf runs | mean NLL | ATE/PCRB")
        for f in sorted(sub["filter"].unique()):
            s = sub[sub["filter"] == f]
            a = s.loc[s["metric"] == "anees", "value"].to_numpy(dtype=np.float64)
            if not a.size:
                continue
            fin = a[np.isfinite(a)]
            print(
                f"{f} | {a.size} | {np.mean(fin) if fin.size else float('nan'):.3g} | {int(np.sum(~np.isfinite(a)))} | "
                f"{mean(s, 'nll'):.3g} | {ate_over_bound(sub, str(f)):.3g}"
            )


def main(path: str) -> None:
    df = pd.read_csv(path)
    filters = [
        "odometry",
        "ekf_landmarks",
        "ukf_landmarks",
        "ekf_landmarks[association=nearest]",
        "gtsam_fls",
        "pf",
        "pf[adaptive=kld]",
        "ekf_lines",
        "ekf_icp",
        "kf_linear",
    ]
    headline(df, "office", filters)
    headline(df, "room", filters)
    kidnaps(df)
    consistency(df)
    print(
        "\nruns:",
        df[df["metric"] == "failed"].shape[0],
        "with rows;",
        int((df[df["metric"] == "failed"]["value"] > 0.5).sum()),
        "failed",
    )


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "results/summary/metrics.csv")
