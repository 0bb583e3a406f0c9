"""Claims of report 002 (Peng, EKF map-based localization with lines) on ``line_room``, and its gate-sweep section.

The report tunes the chi-square threshold of its association gate and finds that a larger threshold accepts
more observed lines and, "because our observations are accurate", localizes better; and that rejecting
observed lines longer than their map line "slightly improves" the result. Both are checked on filter
variants ``ekf_lines[chi2_threshold=...,reject_longer=...]`` over every stored variant of ``line_room``
(the accurate observations are the variant with the smallest ``laser_sigma_m``).

The accepted fraction of lines is read from the metric ``accepted_fraction`` (per run: the sum over the
run's updates of the ``accepted`` diagnostic divided by the sum of ``accepted`` + ``rejected``); while
``metrics.parquet`` lacks it, "accepts more" is not evaluated.
"""

from __future__ import annotations

import itertools
import logging
import math

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from locbench.claims import (
    Claim,
    ClaimResult,
    Experiment,
    Source,
    all_found,
    found,
    register,
    register_experiment,
    register_section,
    spec_id,
    test_text,
)
from locbench.core.errors import LocbenchError
from locbench.evaluate.aggregate import mean_ci
from locbench.evaluate.metrics import ACCEPTED_FRACTION, ATE_M, METRICS
from locbench.evaluate.significance import TestResult, wilcoxon_paired
from locbench.present import ranking as rk
from locbench.present.docfmt import PALETTE, Block, Plot, Text
from locbench.suites import SUITES

log = logging.getLogger(__name__)

SOURCE_002 = Source("002", "Lab4 - EKF Map Based Localization", "Songyou Peng")
DATASET = "line_room"
FILTER = "ekf_lines"

_COLUMNS = ["dataset", "laser_sigma_m", "filter", "chi2", "reject_longer", "seed", ATE_M, "accepted"]


def _filter_params(name: str) -> tuple[float, bool] | None:
    """(chi2_threshold, reject_longer) of an ``ekf_lines`` filter name, or None for another filter."""
    if spec_id(name) != FILTER:
        return None
    from locbench.registry import resolve_filter  # the registry imports the filters lazily

    try:
        cfg = resolve_filter(name).params
    except LocbenchError as exc:
        log.warning("cannot read %s: %s", name, exc)
        return None
    return float(cfg.chi2_threshold), bool(cfg.reject_longer)


def _laser_sigma(name: str) -> float:
    from locbench.registry import resolve_dataset

    try:
        return float(resolve_dataset(name).params.laser_sigma_m)
    except LocbenchError as exc:
        log.warning("cannot read %s: %s", name, exc)
        return math.nan


def sweep_table(df: pd.DataFrame) -> pd.DataFrame:
    """One row per ``ekf_lines`` run: dataset, laser_sigma_m, filter, chi2, reject_longer, seed, ate_m, accepted.

    ``accepted`` is the ``accepted_fraction`` metric (NaN when absent). Failed runs have no ``ate_m``
    and are left out.
    """
    sub = df[df["metric"].isin([ATE_M, ACCEPTED_FRACTION])]
    if sub.empty:
        return pd.DataFrame(columns=_COLUMNS)
    wide = sub.pivot_table(index=["dataset", "filter", "seed"], columns="metric", values="value", aggfunc="first")
    rows = []
    sigma_of: dict[str, float] = {}
    for key, r in wide.iterrows():
        ds, flt, seed = (str(key[0]), str(key[1]), int(key[2]))  # type: ignore[index]
        prm = _filter_params(str(flt))
        if prm is None or ATE_M not in r or pd.isna(r[ATE_M]):
            continue
        if ds not in sigma_of:
            sigma_of[ds] = _laser_sigma(str(ds))
        acc = float(r[ACCEPTED_FRACTION]) if ACCEPTED_FRACTION in r and not pd.isna(r[ACCEPTED_FRACTION]) else math.nan
        rows.append((str(ds), sigma_of[ds], str(flt), prm[0], prm[1], int(seed), float(r[ATE_M]), acc))
    return pd.DataFrame(rows, columns=_COLUMNS)


def _accurate(tab: pd.DataFrame) -> pd.DataFrame:
    """The rows of the dataset variant with the smallest laser noise."""
    if tab.empty:
        return tab
    best = tab.sort_values(["laser_sigma_m", "dataset"]).iloc[0]["dataset"]
    return tab[tab["dataset"] == best]


def _means(tab: pd.DataFrame, column: str) -> pd.DataFrame:
    """Mean of ``column`` over seeds per (reject_longer, chi2), sorted by chi2."""
    return tab.groupby(["reject_longer", "chi2"], sort=True)[column].mean().reset_index()


def _by_seed(tab: pd.DataFrame, flag: bool, chi2: float, column: str) -> pd.Series:
    g = tab[(tab["reject_longer"] == flag) & (tab["chi2"] == chi2)]
    return g.groupby("seed")[column].first().dropna()


def _paired_step(tab: pd.DataFrame, flag: bool, lo: float, hi: float, column: str, alternative: str) -> TestResult:
    """One-sided Wilcoxon signed-rank test of ``column`` at threshold ``hi`` against ``lo`` over the seeds both
    have (the same realisations: paired)."""
    a, b = _by_seed(tab, flag, hi, column), _by_seed(tab, flag, lo, column)
    seeds = a.index.intersection(b.index).sort_values()
    return wilcoxon_paired(a.loc[seeds].to_numpy(), b.loc[seeds].to_numpy(), alternative=alternative)  # type: ignore[arg-type]


#: Why a gate claim is not evaluated: it is worded for both settings of the length check.
_BOTH_SETTINGS = "the claim needs at least 2 chi-square thresholds stored with the length check on and with it off"


def _setting(flag: bool) -> str:
    return "length check on" if flag else "length check off"


# --- claims ---------------------------------------------------------------------------------------------


def _check_gate_lowers_error(df: pd.DataFrame) -> ClaimResult:
    tab = _accurate(sweep_table(df))
    if tab.empty:
        return ClaimResult("not evaluated", f"no {FILTER} runs on {DATASET}")
    ds = tab["dataset"].iloc[0]
    m = _means(tab, ATE_M)
    parts, tests = [], []
    for flag, g in m.groupby("reject_longer", sort=True):
        if g.shape[0] < 2:
            continue
        g = g.sort_values("chi2")
        lo, hi = g.iloc[0], g.iloc[-1]
        tests.append(_paired_step(tab, bool(flag), float(lo["chi2"]), float(hi["chi2"]), ATE_M, "less"))
        parts.append(
            f"{_setting(bool(flag))}: ATE "
            + " / ".join(f"{100 * a:.2f}" for a in g[ATE_M])
            + " cm at chi2 "
            + " / ".join(f"{c:g}" for c in g["chi2"])
        )
    if len(parts) < 2:
        return ClaimResult("not evaluated", f"{ds}: {_BOTH_SETTINGS}")
    text = f"{ds}: " + "; ".join(parts)
    return ClaimResult(all_found(tests), text, "one-sided " + test_text(*tests))


def _check_gate_accepts_more(df: pd.DataFrame) -> ClaimResult:
    tab = _accurate(sweep_table(df))
    if tab.empty:
        return ClaimResult("not evaluated", f"no {FILTER} runs on {DATASET}")
    if tab["accepted"].isna().all():
        return ClaimResult("not evaluated", f"metrics.parquet has no {ACCEPTED_FRACTION} metric yet")
    ds = tab["dataset"].iloc[0]
    m = _means(tab.dropna(subset=["accepted"]), "accepted")
    parts, tests = [], []
    for flag, g in m.groupby("reject_longer", sort=True):
        if g.shape[0] < 2:
            continue
        acc = g.sort_values("chi2")["accepted"].to_numpy()
        thresholds = g.sort_values("chi2")["chi2"].to_numpy(dtype=np.float64)
        # every step up in the threshold must accept more, each step found by its own test
        tests += [
            _paired_step(tab, bool(flag), float(lo), float(hi), "accepted", "greater")
            for lo, hi in itertools.pairwise(thresholds)
        ]
        parts.append(
            f"{_setting(bool(flag))}: accepted "
            + " / ".join(f"{100 * a:.1f}" for a in acc)
            + " % at chi2 "
            + " / ".join(f"{c:g}" for c in g.sort_values("chi2")["chi2"])
        )
    if len(parts) < 2:
        return ClaimResult("not evaluated", f"{ds}: {_BOTH_SETTINGS}")
    return ClaimResult(all_found(tests), f"{ds}: " + "; ".join(parts), "one-sided " + test_text(*tests))


def _check_length_check_helps(df: pd.DataFrame) -> ClaimResult:
    tab = _accurate(sweep_table(df))
    if tab.empty:
        return ClaimResult("not evaluated", f"no {FILTER} runs on {DATASET}")
    ds = tab["dataset"].iloc[0]
    wide = tab.pivot_table(index=["chi2", "seed"], columns="reject_longer", values=ATE_M, aggfunc="first")
    if True not in wide.columns or False not in wide.columns:
        return ClaimResult("not evaluated", f"{ds}: runs with the length check on and off are both needed")
    pairs = wide.dropna(subset=[True, False])
    if pairs.empty:
        return ClaimResult("not evaluated", f"{ds}: no (chi2, seed) run with the check both on and off")
    on, off = pairs[True].to_numpy(), pairs[False].to_numpy()
    diff = off - on
    rel = float(np.mean(diff) / np.mean(off)) if np.mean(off) > 0 else math.nan
    changed = int(np.count_nonzero(np.abs(diff) > 1e-9))
    text = (
        f"{ds}: mean ATE on {100 * np.mean(on):.3f} cm vs off {100 * np.mean(off):.3f} cm over {diff.size} "
        f"paired (chi2, seed) runs; improvement {100 * rel:+.2f} %; {changed} runs differ"
    )
    test = wilcoxon_paired(on, off, alternative="less")
    return ClaimResult(found(test), text, "one-sided " + test_text(test))


register(
    Claim(
        "line_room_gate_lowers_error",
        DATASET,
        SOURCE_002,
        "With accurate observations (the line_room variant with the smallest laser_sigma_m) a larger chi-square "
        "threshold lowers the error: a one-sided Wilcoxon signed-rank test over the seeds finds ekf_lines' ATE at "
        "the largest stored threshold lower than at the smallest at 5 %, with the length check on and off.",
        "sec. 2.3 and fig. 2: with a large threshold the expected lines lie closer to the map (no numbers)",
        _check_gate_lowers_error,
        across_variants=True,
    ),
    Claim(
        "line_room_gate_accepts_more",
        DATASET,
        SOURCE_002,
        f"A larger chi-square threshold accepts more lines: at every step up in the threshold a one-sided Wilcoxon "
        f"signed-rank test over the seeds finds {ACCEPTED_FRACTION} higher at 5 %, on the accurate variant, with the "
        "length check on and off.",
        "sec. 2.3: a large threshold accepts more observations (no numbers)",
        _check_gate_accepts_more,
        across_variants=True,
    ),
    Claim(
        "line_room_length_check_helps",
        DATASET,
        SOURCE_002,
        "Rejecting observed lines longer than their map line helps slightly: on the accurate variant, a one-sided "
        "Wilcoxon signed-rank test over the runs paired by (threshold, seed) finds the ATE lower with "
        "reject_longer=true than with false at 5 %.",
        "sec. 2.3: 'the performance slightly improves but not quite obvious' (no numbers)",
        _check_length_check_helps,
        across_variants=True,
    ),
)


# --- section: ATE (and accepted fraction) against the threshold --------------------------------------------


def _gate_section(rows: pd.DataFrame, slug: str) -> list[Block]:
    """ATE (and the accepted fraction) of ekf_lines against the chi-square threshold: a table and a figure."""
    tab = sweep_table(rows)
    if tab.empty:
        return [Text(f"No {FILTER} runs stored.")]
    has_acc = not tab["accepted"].isna().all()
    header = ("dataset", "length check", "chi2 threshold", "runs", "ATE (cm)") + (
        ("accepted lines (%)",) if has_acc else ()
    )

    out: list[tuple[str, ...]] = []
    keys: list[tuple[float, ...]] = []
    groups: list[str] = []
    labels: list[str] = []
    samples: list[dict[int, float] | None] = []
    for (ds, flag, chi2), g in tab.groupby(["dataset", "reject_longer", "chi2"], sort=True):
        ci = mean_ci(100.0 * g[ATE_M].to_numpy())
        cell = f"{ci.mean:.2f}" + (f" [{ci.low:.2f}, {ci.high:.2f}]" if ci.n > 1 else "")
        row = [f"`{ds}`", "on" if flag else "off", f"{chi2:g}", str(ci.n), cell]
        key = [math.nan, math.nan, float(g["chi2"].iloc[0]), float(ci.n), ci.mean / 100.0]
        if has_acc:
            acc = g["accepted"].dropna().to_numpy()
            row.append(f"{100.0 * float(np.mean(acc)):.1f}" if acc.size else "")
            key.append(100.0 * float(np.mean(acc)) if acc.size else math.nan)
        out.append(tuple(row))
        keys.append(tuple(key))
        groups.append(str(ds))
        labels.append(f"{_setting(bool(flag))}, chi2 {chi2:g}")
        samples.append({int(k): float(v) for k, v in zip(g["seed"], g[ATE_M], strict=True)} or None)
    datasets = sorted(tab["dataset"].unique())

    def draw(fig: Figure) -> None:
        ncols = 2 if has_acc else 1
        axes = [fig.add_subplot(1, ncols, k + 1) for k in range(ncols)]
        for d_i, ds in enumerate(datasets):
            sub = tab[tab["dataset"] == ds]
            for flag in (True, False):
                g = sub[sub["reject_longer"] == flag]
                if g.empty:
                    continue
                m = g.groupby("chi2", sort=True)[[ATE_M, "accepted"]].mean()
                color, ls = PALETTE[d_i % len(PALETTE)], "-" if flag else "--"
                label = f"{ds}, {_setting(flag)}"
                axes[0].plot(m.index, 100.0 * m[ATE_M], label=label, color=color, linestyle=ls, marker="o")
                if has_acc:
                    axes[1].plot(m.index, 100.0 * m["accepted"], label=label, color=color, linestyle=ls, marker="o")
        axes[0].set_xlabel("chi-square threshold")
        axes[0].set_ylabel("ATE, mean over seeds (cm)")
        axes[0].set_yscale("log")
        axes[0].legend(fontsize="small", loc="upper left", bbox_to_anchor=(0.0, -0.2))  # below the axes, off the data
        if has_acc:
            axes[1].set_xlabel("chi-square threshold")
            axes[1].set_ylabel("accepted lines (%)")

    return [
        rk.marked_table(
            header,
            out,
            keys,
            [rk.Column(4, METRICS[ATE_M], samples)],
            [True] * len(out),
            caption="ekf_lines: chi-square threshold sweep (report 002)",
            groups=groups,
            labels=labels,
            footnotes=("ATE ranked within each dataset: the settings there run on the same seeds.",),
        ),
        Plot(
            f"{slug}_chi2_sweep",
            "ekf_lines: ATE and accepted lines against the chi-square threshold",
            draw,
            size=(9.0, 3.6) if has_acc else (5.0, 3.6),
        ),
    ]


register_section(DATASET, _gate_section)
register_experiment(
    Experiment(
        DATASET,
        "Line room (report 002)",
        "Report 002's setting: two polygonal rooms whose walls are the line map; ekf_lines extracts lines from "
        "a 181-beam scan and gates them with a chi-square threshold, swept here, with the length check on and off.",
        source=SOURCE_002,
        order=30,
        suite=SUITES["line_room"],
    )
)
