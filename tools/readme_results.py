"""The README's result numbers, generated from results/summary/metrics.csv (and the suites' run counts).

Usage::

    python tools/readme_results.py            # print the generated blocks and the per-filter diagnostics
    python tools/readme_results.py --write    # rewrite README.md's generated blocks from the committed summary
    python tools/readme_results.py --check    # exit 1 naming every block of README.md that disagrees

A generated block in README.md lies between ``<!-- gen:NAME -->`` and ``<!-- /gen:NAME -->`` (a table on lines of
its own, or a value inside a sentence); :func:`blocks` makes every one from the tidy metrics, with the report's
own formatting and aggregation (:mod:`locbench.report.tables`), so the README and the summary cannot disagree:
``tests/test_readme_results.py`` regenerates them from the committed ``metrics.csv`` and compares. After
``nox -s bench`` run ``--write``. Numbers outside the blocks (measurements of timings, the interpretation
around the tables) are not generated; every result number of a table is.
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from locbench.pcrb import BOUND_ALL, BOUND_NO_LASER
from locbench.report.collect import describe_filter
from locbench.report.tables import ate_over_bound, consistency_cell, mean_of, median_text, num, rate, waypoint_rmse_mean
from locbench.suites import KIDNAP_DISTANCES_M, KIDNAP_FILTERS, SUITES

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
METRICS_CSV = ROOT / "results" / "summary" / "metrics.csv"

#: ``<!-- gen:NAME -->text<!-- /gen:NAME -->``; the text may span lines.
BLOCK = re.compile(r"<!-- gen:(?P<name>[\w-]+) -->(?P<body>.*?)<!-- /gen:(?P=name) -->", re.DOTALL)

#: The README's headline rows, in its order (the main comparison's default configurations).
HEADLINE = ("odometry", "ekf_landmarks", "ukf_landmarks", "gtsam_fls", "pf", "pf[adaptive=kld]", "ekf_lines")
HEADLINE += ("ekf_icp", "kf_linear")
#: The recorded table's columns: (header, datasets joined by " / ", metric).
RECORDED = (
    ("MRCLAM 6, robots 1 / 2 / 3 / 4 / 5", ("mrclam", *(f"mrclam[robot={r}]" for r in range(2, 6))), "ate_m"),
    ("Lost in the Woods", ("lost_in_the_woods",), "ate_m"),
    ("Intel (relation error)", ("intel",), "relation_error_m"),
    ("Plaza 1 / 2", ("plaza", "plaza[run=2]"), "ate_m"),
)
RECORDED_FILTERS = (*HEADLINE[:6], "ekf_icp", "ekf_lines", "kf_linear")
#: A filter whose default does not run on a recording, and the configuration the table shows there instead.
RECORDED_VARIANTS = {("pf", "intel"): "pf[use_laser=true]"}
MATCHED = ("room[matched=true]", "office[matched=true]")


def cm(x: float) -> str:
    return num(100.0 * x)


def table(head: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n" + "\n".join(lines) + "\n"


def kidnap_cell(df: pd.DataFrame, base: str, name: str, d: float) -> tuple[int, int]:
    sub = df[(df["dataset"] == f"{base}[kidnap_m={d:g}]") & (df["filter"] == name)]
    k, n, _, _, _ = rate(sub, "kidnap_recovered")
    return k, n


def office_summary(df: pd.DataFrame) -> str:
    """The headline table on ``office``: the report's summary columns that metrics.csv holds."""
    sub = df[df["dataset"] == "office"]
    wp = waypoint_rmse_mean(sub)
    rows = []
    for f in HEADLINE:
        s = sub[sub["filter"] == f]
        kid = describe_filter(f).kidnap_name
        k, n = kidnap_cell(df, "office", kid or f, 2.0)
        kidnap = f"{100 * k / n:.0f}" if n else "-"
        if kid:
            kidnap += f" (`{kid}`)"
        anees, _, _, _ = consistency_cell(s)
        rows.append(
            (
                f"`{f}`",
                cm(mean_of(s, "ate_m")),
                num(ate_over_bound(sub, f)),
                cm(wp.get(f, float("nan"))),
                anees,
                cm(mean_of(s, "energy_score_m")),
                num(mean_of(s, "update_us_median")).replace("n/a", "-"),
                num(mean_of(s, "realtime_factor")),
                kidnap,
            )
        )
    head = ("filter", "ATE (cm)", "ATE / PCRB", "mean waypoint RMSE (cm)", "ANEES", "energy score (cm)")
    head += ("update median (us)", "real-time factor", "kidnap recovery at 2 m (%)")
    return table(head, rows)


def kidnaps(df: pd.DataFrame) -> str:
    """Recovered runs / runs per kidnap distance on ``office`` and ``room``, for suite ``kidnap``'s filters."""
    rows = []
    for f in KIDNAP_FILTERS:
        cells = []
        for base in ("office", "room"):
            counts = [kidnap_cell(df, base, f, d) for d in KIDNAP_DISTANCES_M]
            cells.append(" / ".join(f"{k}/{n}" for k, n in counts) if any(n for _, n in counts) else "-")
        rows.append((f"`{f}`", *cells))
    d = " / ".join(f"{x:g}" for x in KIDNAP_DISTANCES_M)
    return table(("filter", f"`office`, D = {d} m", f"`room`, D = {d} m"), rows)


def consistency(df: pd.DataFrame) -> str:
    """Mean ANEES and ATE over the bound on the model-matched worlds, every filter that ran on both or one."""
    names = sorted({str(f) for f in df[df["dataset"].isin(MATCHED)]["filter"].unique()} - {BOUND_ALL, BOUND_NO_LASER})
    rows = []
    for f in names:
        cells: list[str] = []
        for ds in MATCHED:
            sub = df[df["dataset"] == ds]
            s = sub[sub["filter"] == f]
            if s.empty:
                cells += ["-", "-", "-"]
                continue
            no_laser = sub[sub["filter"].isin([f, BOUND_NO_LASER])].replace({BOUND_NO_LASER: BOUND_ALL})
            bound = ate_over_bound(no_laser, f) if (sub["filter"] == BOUND_NO_LASER).any() else ate_over_bound(sub, f)
            cells += [str(s["seed"].nunique()), consistency_cell(s)[0], num(bound)]
        rows.append((f"`{f}`", *cells))
    head = ("filter", "`room` runs", "`room` ANEES", "`room` ATE / PCRB", "`office` runs", "`office` ANEES")
    return table((*head, "`office` ATE / PCRB (no laser)"), rows)


def recorded(df: pd.DataFrame) -> str:
    """ATE (cm; for Intel the mean relation error) of one run per filter and recording."""
    rows = []
    for f in RECORDED_FILTERS:
        cells = []
        for _, datasets, metric in RECORDED:
            vals = []
            for ds in datasets:
                name = RECORDED_VARIANTS.get((f, ds), f)
                s = df[(df["dataset"] == ds) & (df["filter"] == name)]
                v = mean_of(s, metric)
                vals.append(cm(v) if np.isfinite(v) else "-")
            text = " / ".join(vals) if any(v != "-" for v in vals) else "-"
            variant = {RECORDED_VARIANTS[(f, ds)] for ds in datasets if (f, ds) in RECORDED_VARIANTS}
            cells.append(text + "".join(f" (`{v}`)" for v in sorted(variant)) if text != "-" else text)
        rows.append((f"`{f}`", *cells))
    return table(("filter", *(h for h, _, _ in RECORDED)), rows)


def global_localization(df: pd.DataFrame, laser: bool) -> Callable[[], str]:
    """``k of n runs, median T s`` of the global-localization configuration on ``office``."""
    name = "pf[augmented=true,init=uniform" + (",use_laser=true]" if laser else "]")

    def text() -> str:
        s = df[(df["dataset"] == "office") & (df["filter"] == name)]
        k, n, _, _, _ = rate(s, "converged")
        t = s[s["metric"] == "time_to_converge_s"]["value"]
        return f"{k} of {n} runs, median {median_text(t)} s"

    return text


def blocks(df: pd.DataFrame) -> dict[str, str]:
    """Every generated block of the README, by name."""
    kidnapped = {f"{b}[kidnap_m={d:g}]" for b in ("office", "room") for d in KIDNAP_DISTANCES_M}
    used = {"office", "room", *MATCHED, *kidnapped, *(ds for _, group, _ in RECORDED for ds in group)}
    df = df[df["dataset"].isin(used)]  # what every block reads, once (the whole frame is 15 MB)
    makers: dict[str, Callable[[], str]] = {
        "office-summary": lambda: office_summary(df),
        "kidnap": lambda: kidnaps(df),
        "consistency": lambda: consistency(df),
        "recorded": lambda: recorded(df),
        "global-laser": global_localization(df, laser=True),
        "global-landmarks": global_localization(df, laser=False),
    }
    out = {name: make() for name, make in makers.items()}
    out |= {f"suite-{s.name}-runs": str(s.runs) for s in SUITES.values()}
    return out


def render(text: str, generated: dict[str, str]) -> str:
    """``text`` with the body of every block replaced by its generated text; a block with no generator is an
    error naming it."""

    def sub(m: re.Match[str]) -> str:
        name = m.group("name")
        if name not in generated:
            raise KeyError(f"README.md: no generator for the block {name!r}; known: {', '.join(sorted(generated))}")
        return f"<!-- gen:{name} -->{generated[name]}<!-- /gen:{name} -->"

    return BLOCK.sub(sub, text)


def disagreements(text: str, generated: dict[str, str]) -> list[str]:
    """The names of the README's blocks whose text differs from the generated one."""
    return [m.group("name") for m in BLOCK.finditer(text) if generated.get(m.group("name")) != m.group("body")]


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("metrics", nargs="?", default=str(METRICS_CSV))
    mode = ap.add_mutually_exclusive_group()
    mode.add_argument("--write", action="store_true", help="rewrite README.md's generated blocks")
    mode.add_argument("--check", action="store_true", help="exit 1 when a block of README.md disagrees")
    args = ap.parse_args(argv)
    generated = blocks(pd.read_csv(args.metrics))
    text = README.read_text(encoding="utf-8")
    if args.write:
        README.write_text(render(text, generated), encoding="utf-8")
        return 0
    if args.check:
        bad = disagreements(text, generated)
        for name in bad:
            print(f"README.md: block {name!r} disagrees with {args.metrics}; run tools/readme_results.py --write")
        return 1 if bad else 0
    for name, body in generated.items():
        print(f"--- {name}:{body}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
