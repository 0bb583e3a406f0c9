"""The README's result numbers, generated from results/summary/metrics.parquet and the report's Markdown pages
(REPORT.md and md/*.md) (and the suites' run counts),
and the lists of filters and datasets in README.md and the docs pages, generated from the registry.

Usage::

    python tools/docs/readme_results.py            # print the generated blocks and the per-filter diagnostics
    python tools/docs/readme_results.py --write    # rewrite the generated blocks of README.md and the docs pages
    python tools/docs/readme_results.py --check    # exit 1 naming every block of either that disagrees

A generated block lies between ``<!-- gen:NAME -->`` and ``<!-- /gen:NAME -->`` (a table on lines of its own, or a
value inside a sentence). The filter and dataset lists (the filter tables, the README's list of the filters, the
design page's dataset table) are what the classes declare (:func:`locbench.present.catalog.doc_blocks`), so a
filter or a dataset added as one module is listed after ``--write``. :func:`blocks` makes every other one from the
tidy metrics, with the report's
own formatting and aggregation (:mod:`locbench.report.tables`), so the README and the summary cannot disagree:
``tests/tools/test_readme_results.py`` regenerates them from the committed ``metrics.parquet`` and compares. A
number that only the report's pages hold (what the report computes from the stored runs rather than from the metrics:
run counts by status, the lost-detection AUROC, the claims' measured values and verdicts, the ranks across
datasets, the tuned studies, the Wilcoxon ties) is cut from the committed pages' own tables (:func:`report_text`
joins them), and a change of their wording that loses one is an error naming it. After ``nox -s bench`` run
``--write``. Numbers outside the blocks are measurements that the committed summary does not hold (wall and CPU
times, earlier versions' figures, runs outside the committed suites); each sentence says how it was measured.
"""

from __future__ import annotations

import argparse
import itertools
import re
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from locbench.core.events import Odometry
from locbench.evaluate.metrics import GROUPS
from locbench.evaluate.pcrb import BOUND_ALL, BOUND_NO_LASER
from locbench.evaluate.significance import ties_with_best
from locbench.present.catalog import doc_blocks
from locbench.present.metric_info import metric_table
from locbench.present.ranking import samples_for
from locbench.present.sizes import sizes_text
from locbench.report.collect import describe_filter
from locbench.report.collect import read_metrics as _read_metrics
from locbench.report.sections.summary import have_text
from locbench.report.site import site_markdown
from locbench.report.tables import (
    ate_over_bound,
    band_text,
    consistency_cell,
    mean_of,
    median_text,
    num,
    rate,
    waypoint_rmse_mean,
)
from locbench.suites import KIDNAP_DISTANCES_M, KIDNAP_FILTERS, SUITES, suite_pairs

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
#: Every document that may hold generated blocks: the README and the docs pages (the history keeps its own figures).
DOCUMENTS = (README, *sorted((ROOT / "docs").glob("*.md")))
SUMMARY = ROOT / "results" / "summary"
#: The committed tidy metrics (a summary written before the report was a site has ``metrics.csv`` instead).
METRICS = SUMMARY / "metrics.parquet" if (SUMMARY / "metrics.parquet").is_file() else SUMMARY / "metrics.csv"
REPORT_MD = SUMMARY / "REPORT.md"


def report_text(summary: Path = SUMMARY) -> str:
    """The report's Markdown: the landing page ``REPORT.md`` and every page of ``md/`` (sorted), joined; each
    section is found by its anchor wherever its page is."""
    return site_markdown(summary)


def read_metrics(path: str | Path = METRICS) -> pd.DataFrame:
    """The tidy metrics of ``metrics.parquet`` (or an older summary's ``metrics.csv``)."""
    return _read_metrics(path)


#: ``<!-- gen:NAME -->text<!-- /gen:NAME -->``; the text may span lines.
BLOCK = re.compile(r"<!-- gen:(?P<name>[\w-]+) -->(?P<body>.*?)<!-- /gen:(?P=name) -->", re.DOTALL)

#: The headline rows, in the registry's order: the configurations suite ``default`` runs on ``office``.
HEADLINE = tuple(str(f) for f, d in suite_pairs("default") if str(d) == "office")
#: The recorded table's columns: (header, datasets joined by " / ", metric).
RECORDED = (
    ("MRCLAM 6, robots 1 / 2 / 3 / 4 / 5", ("mrclam", *(f"mrclam[robot={r}]" for r in range(2, 6))), "ate_m"),
    ("Lost in the Woods", ("lost_in_the_woods",), "ate_m"),
    ("Intel (relation error)", ("intel",), "relation_error_m"),
    ("Plaza 1 / 2", ("plaza", "plaza[run=2]"), "ate_m"),
)
RECORDED_FILTERS = HEADLINE
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
    """The headline table on ``office``: the report's summary columns that the tidy metrics hold."""
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


def decision(df: pd.DataFrame) -> str:
    """Which default configuration to use with which sensors and map, on ``office`` (every filter runs there).

    For each combination of sensors and map some default configuration needs (as its class declares them), the
    lowest mean ATE among the configurations that need no more, with every one the paired Wilcoxon test
    (Holm-corrected, as the report's bold marks) does not find different from it; the dead-reckoning baseline is
    no candidate. The report's summary makes the same choice over every configuration, tuned and swept ones too.
    """
    sub = df[df["dataset"] == "office"]
    cands = [
        f
        for f in HEADLINE
        if not describe_filter(f).baseline and np.isfinite(mean_of(sub[sub["filter"] == f], "ate_m"))
    ]
    means = [mean_of(sub[sub["filter"] == f], "ate_m") for f in cands]
    samples = samples_for(sub, cands, "ate_m")
    needs = {}
    for f in cands:
        info = describe_filter(f)
        needs[f] = (frozenset(s for s in info.sensors if s != Odometry.__name__), frozenset(info.maps))
    combos = sorted(set(needs.values()), key=lambda n: (len(n[0]) + len(n[1]), have_text(*n)))
    rows = []
    for sensors, maps in combos:
        ok = [needs[f][0] <= sensors and needs[f][1] <= maps for f in cands]
        v = ties_with_best(means, samples, ok, "lower", effects=False)
        if v.best is None:
            continue
        best = cands[v.best]
        s = sub[sub["filter"] == best]
        tied = ", ".join(f"`{cands[i]}`" for i in sorted(v.marked) if i != v.best) or "-"
        rows.append(
            (
                have_text(sensors, maps),
                f"`{best}`",
                cm(means[v.best]),
                num(mean_of(s, "update_us_median")).replace("n/a", "-"),
                num(mean_of(s, "realtime_factor")),
                tied,
            )
        )
    head = ("you have odometry and", "use", "ATE (cm)", "update median (us)", "real-time factor")
    return table((*head, "not found different (paired test)"), rows)


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


# --- the prose's numbers: from the committed report pages' tables and from the metrics ----------------------

#: A site where a filter's ATE is below this keeps track (the Radish sentence); above it, the site is named, m.
TRACKED_M = 0.2
#: A lost-detection AUROC at or above this joins the group the sentence gives as one range.
GOOD_AUROC = 0.95
#: The Gaussian landmark filters (the sentences about "the landmark filters").
LANDMARK = ("ekf_landmarks", "ukf_landmarks", "gtsam_fls")


def md_tables(report: str, anchor: str) -> list[list[dict[str, str]]]:
    """The tables of REPORT.md's section ``anchor`` (up to the next heading), each as rows of header -> cell."""
    lines = section_text(report, anchor).splitlines()
    out: list[list[dict[str, str]]] = []
    head: list[str] | None = None
    for line in [*lines, ""]:
        if not line.startswith("|"):
            head = None
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if head is None:
            head = cells
            out.append([])
        elif not set("".join(cells)) <= set("-"):
            out[-1].append(dict(zip(head, cells, strict=True)))
    return out


def section_text(report: str, anchor: str) -> str:
    """REPORT.md's section ``anchor`` up to the next heading; a missing one is an error naming it."""
    start = report.find(f'<a id="{anchor}"></a>')
    if start < 0:
        raise ValueError(f"REPORT.md: no section with the anchor {anchor!r}")
    end = report.find("\n#", start)
    return report[start : end if end >= 0 else len(report)]


def plain(cell: str) -> str:
    """A cell without its Markdown (bold, code, footnote marks)."""
    return re.sub(r"[*`²¹]", "", cell).strip()


def bold(cell: str) -> bool:
    return cell.startswith("**")


def span(vals: Sequence[float], fmt: Callable[[float], str] = num) -> str:
    """``a-b`` of the smallest and largest value (one value when they print alike)."""
    lo, hi = fmt(min(vals)), fmt(max(vals))
    return lo if lo == hi else f"{lo}-{hi}"


def listed(names: Sequence[str]) -> str:
    if not names:
        return "none"
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def find(pattern: str, text: str, what: str) -> re.Match[str]:
    """``re.search`` that fails naming what it looked for (REPORT.md's wording changed)."""
    m = re.search(pattern, text)
    if m is None:
        raise ValueError(f"REPORT.md: {what} not found (pattern {pattern!r})")
    return m


#: The claims the README gives one verdict for together, by the start of their text in REPORT.md.
CLAIM_GROUPS = {
    "003": ("Odometry error grows", "World calibration: the odometry distance", "The EKF (ekf_landmarks) is far below"),
    "000": ("World calibration: odometry ends", "EKF-ICP ends close", "Moving people", "EKF-ICP recovers"),
    "002": ("With accurate observations", "A larger chi-square threshold accepts"),
    "004": ("The linear KF localizes",),
    "001": ("Error falls with", "The EKF works well", "GPS converges"),
}


#: Values cut from a claim's measured text as they stand: (block, start of the claim, pattern, template).
CLAIM_VALUES = (
    (
        "claim-room-ekf-below",
        "The EKF (ekf_landmarks) is far below",
        r"ekf_landmarks ([\d. /]+) cm vs odometry ([\d. /]+) cm",
        "{} cm against {}",
    ),
    (
        "claim-room-pf-ekf",
        "The PF is at least as accurate",
        r"pf ([\d.]+) cm vs ekf_landmarks ([\d.]+) cm",
        "{} cm against {} cm",
    ),
    ("claim-lap-odometry", "World calibration: odometry ends", r"median final error ([\d.]+) cm", "{} cm"),
    ("claim-lap-ekf_icp", "EKF-ICP ends close", r"median final error ([\d.]+) cm", "{} cm"),
    ("claim-lap-people", "Moving people do not affect", r"median ATE ([\d.]+) cm vs ([\d.]+) cm", "{} against {} cm"),
    (
        "claim-line_room-accepted",
        "A larger chi-square threshold accepts",
        r"length check off: accepted ([\d. /]+) %",
        "{} %",
    ),
    ("claim-line_room-ate", "With accurate observations", r"length check off: ATE ([\d. /]+) cm", "{} cm"),
    ("claim-line_room-length", "Rejecting observed lines", r"(\d+) runs differ", "{} paired runs differ"),
)


def claim_values(report: str) -> dict[str, str]:
    """The claims' measured values and verdicts the README quotes, cut from REPORT.md's claims table."""
    rows = {r["claim"]: r for r in md_tables(report, "claims")[0]}

    def row(start: str) -> dict[str, str]:
        hit = [r for c, r in rows.items() if c.startswith(start)]
        if len(hit) != 1:
            raise ValueError(f"REPORT.md: {len(hit)} claims start with {start!r}")
        return hit[0]

    def measured(start: str, pattern: str) -> re.Match[str]:
        return find(pattern, row(start)["measured"], f"the measured value of the claim {start!r}")

    out: dict[str, str] = {}
    ratios = measured("World calibration: the odometry distance", r"ratio to table 1 ([\d. /]+)")
    out["claim-room-ratios"] = span([float(x) for x in ratios.group(1).split(" / ")], lambda x: f"{x:.2f}")
    for name, start, pattern, template in CLAIM_VALUES:
        out[name] = template.format(*measured(start, pattern).groups())
    out["claim-room-pf-ekf-verdict"] = row("The PF is at least as accurate")["verdict"]
    rec = re.findall(r"D=([\d.]+) m: ([\d.]+)", row("EKF-ICP recovers from small kidnaps")["measured"])
    out["claim-lap-kidnap"] = " / ".join(r for _, r in rec) + " at " + " / ".join(d for d, _ in rec) + " m"
    out["claim-line_room-length-verdict"] = row("Rejecting observed lines")["verdict"]
    m = measured("The linear KF localizes", r"mean ATE ([\d.]+) cm \(\d+ runs\) = ([\d.]+) x odometry's")
    out["claim-scan_grid"] = f"ATE {m.group(1)} cm, {num(100 * float(m.group(2)), 2)} % of odometry's"
    kid = re.findall(
        r"kidnap_m=(\d+)\] ekf_landmarks: recovered in (\d+/\d+)", row("The EKF does not recover")["measured"]
    )
    counts = sorted({k for _, k in kid})
    out["claim-001-kidnap"] = f"{'/'.join(counts) if len(counts) == 1 else ' and '.join(counts)} recovered at "
    out["claim-001-kidnap"] += " and ".join(d for d, _ in kid) + " m"
    out["claim-001-kidnap-verdict"] = row("The EKF does not recover")["verdict"]
    for key, starts in CLAIM_GROUPS.items():
        verdicts = {plain(row(start)["verdict"]) for start in starts}
        v = verdicts.pop() if len(verdicts) == 1 else "mixed"
        out[f"claims-{key}-verdict"] = v if v == "reproduced" else f"**{v}**"
    matched = [r["verdict"] for c, r in rows.items() if "[matched=true]" in c and "are consistent" in c]
    out["claim-matched-verdict"] = matched[0] if len(set(matched)) == 1 else " / ".join(matched)
    return out


def has_tuned(report: str) -> bool:
    """Whether the report holds suite ``tuned``'s section (tuned studies were committed when it was made)."""
    return '<a id="tuned"></a>' in report


_BUDGET = r"Budget per (?:study|filter and data)[^:]*: (\d+) trials x (\d+) train runs"


def kept_studies(row: dict[str, str]) -> tuple[int, int]:
    """A tuned row's studies that kept the default, and its studies: a cross-validated row says "default kept in K
    of N folds" (N studies, one test unit each); any other row is one study, kept when it says "default kept"."""
    m = re.search(r"default kept in (\d+) of (\d+) folds", row["tuned spec"])
    if m:
        return int(m.group(1)), int(m.group(2))
    return int(row["tuned spec"] == "default kept"), 1


def run_counts(report: str) -> dict[str, str]:
    """Runs of suites ``all`` and ``consistency`` (ok, skipped, failed), suite ``tuned``'s test runs and the last
    ``locbench verify``, from REPORT.md's provenance and its tuned table (the tuned configurations that are not
    the default are the reported runs outside ``all`` and ``consistency``)."""
    prov = section_text(report, "provenance")
    line = find(r"- runs: (.*)", prov, "the provenance's run counts").group(1)
    status = {m.group(2): int(m.group(1)) for m in re.finditer(r"(\d+) (\w+)", line)}
    ok, skipped, failed = (
        status.get("ok", 0),
        status.get("skipped", 0),
        status.get("diverged", 0) + status.get("error", 0),
    )
    tuned = md_tables(report, "tuned")[0] if has_tuned(report) else []
    count = re.compile(r"\((\d+)/(\d+)\)")

    def n(cell: str) -> int:
        return int(find(count.pattern, cell, "a tuned cell's run count").group(2))

    kept_rows = [kept_studies(r) for r in tuned]
    n_studies = sum(total for _, total in kept_rows)
    # the tuned runs that are not the default's own: a kept study's tuned rows are its default's (a cross-validated
    # row's studies have one test unit each)
    extra = sum(
        n(r["tuned ATE (cm)"]) - (k if total > 1 else k * n(r["tuned ATE (cm)"]))
        for r, (k, total) in zip(tuned, kept_rows, strict=True)
    )
    test = sum(n(r["default ATE (cm)"]) for r in tuned) + extra
    v = find(r"verify: passed on [^,]+, (\d+) of \d+ stored runs re-run \(fraction ([\d.]+)", prov, "the verify line")
    common = {
        "runs-all-total": str(ok - extra + skipped + failed),
        "runs-all-ok": str(ok - extra),
        "runs-all-skipped": str(skipped),
        "runs-all-failed": "none" if not failed else str(failed),
        "runs-tuned-test": str(test),
        "verify-rerun": f"{v.group(1)} of them ({100 * float(v.group(2)):.0f} %",
    }
    if not has_tuned(report):
        return common | {
            "tuned-train-runs": "none committed yet",
            "tuned-studies": "none committed yet",
        }
    budget = find(_BUDGET, section_text(report, "tuned"), "the tuning budget")
    return common | {
        "tuned-train-runs": f"{n_studies * int(budget.group(1)) * int(budget.group(2))} train runs, never reported",
        "tuned-studies": f"{n_studies} studies of {budget.group(1)} trials x {budget.group(2)} train runs, "
        f"{n_studies * int(budget.group(1)) * int(budget.group(2))} train runs",
    }


def tuned_findings(report: str) -> dict[str, str]:
    """The tuned section in one sentence: the budget, the studies that kept the default, and each (filter, data)
    whose tuned configuration changed its mean test ATE, with the paired test across the test units; or that no
    studies are committed."""
    if not has_tuned(report):
        return {
            "tuned-findings": "no tuned studies are committed with these results: tuning is a step of its own "
            "(`nox -s tune`), and suite `tuned` runs what it committed"
        }
    text = section_text(report, "tuned")
    budget = find(_BUDGET, text, "the budget")
    rows = md_tables(report, "tuned")[0]
    kept = n_studies = 0
    changes = []
    for r in rows:
        k, total = kept_studies(r)
        kept += k
        n_studies += total
        if k == total:
            continue
        change = float(r["change (%)"])
        a, b = (plain(r[c]).split(" (")[0] for c in ("default ATE (cm)", "tuned ATE (cm)"))
        word = "gains" if change < 0 else "loses"
        test = plain(r.get("tuned against default, paired", ""))
        changes.append(
            f"`{plain(r['filter'])}` on `{r['data']}` {word} {num(abs(change), 2)} % ({a} -> {b} cm"
            + (f"; {test})" if test else ")")
        )
    return {
        "tuned-findings": f"{budget.group(1)} trials x {budget.group(2)} train runs per study, the first trial the "
        f"default: the default was kept in {kept} of {n_studies} studies"
        + ("; on the test units " + ", ".join(changes) if changes else "")
    }


def across_landmark_geometry(report: str) -> str:
    """The rank sentence of the largest across-datasets group that holds the ``landmark_geometry`` worlds."""
    groups = []
    for i in range(1, 100):
        anchor = f"across-{i}"
        if f'<a id="{anchor}"></a>' not in report:
            break
        text = section_text(report, anchor)
        names = re.findall(r"`([^`]+)`", find(r"\d+ datasets: (.*)\n", text, "a group's datasets").group(1))
        worlds = sum(n.split("[")[0] == "landmark_geometry" for n in names)
        if worlds:
            groups.append((len(names), -i, anchor, text, worlds))
    if not groups:
        raise ValueError("REPORT.md: no across-datasets group with landmark_geometry worlds")
    n, gi, anchor, text, worlds = max(groups)
    rows = [r for r in md_tables(report, anchor)[0] if r["skill IQM [95 % CI]"] != "-"]
    rows.sort(key=lambda r: float(r["average rank, ATE"]))
    cd = float(find(r"ATE: Friedman .*Nemenyi CD = ([\d.]+)", text, "the ATE critical difference").group(1))
    first, second, third = rows[:3]
    r1, r2 = (float(r["average rank, ATE"]) for r in (first, second))
    tied = "not significantly different" if abs(r2 - r1) < cd else "significantly different"
    skill = " / ".join(r["skill IQM [95 % CI]"].split(" ")[0] for r in rows[:3])
    return (
        f"on the {n} datasets of group {-gi} ({worlds} of them landmark_geometry worlds) {first['configuration']} "
        f"and {second['configuration']} rank first and second in ATE (average ranks {first['average rank, ATE']} "
        f"and {second['average rank, ATE']}, Nemenyi CD {cd:g}: {tied}) and {third['configuration']} third "
        f"({third['average rank, ATE']}); their skill (1 - ATE / ATE(odometry), IQM) is {skill}"
    )


def office_report(report: str) -> dict[str, str]:
    """Sentences on REPORT.md's office summary table: who is bold for ATE, the lost-detection AUROC."""
    # the defaults' table and the sweeps' (tuned and swept configurations), marked over both
    rows = {plain(r["filter"]): r for table in md_tables(report, "summary-office")[:2] for r in table}
    missing = [f for f in HEADLINE if f not in rows]
    columns = [c for c in next(iter(rows.values()), {}) if c.startswith("lost AUROC")]
    if missing or len(columns) != 1 or "ATE (cm)" not in rows[HEADLINE[0]]:
        raise ValueError(f"REPORT.md: the office summary lacks the rows {missing} or its ATE or lost AUROC column")
    best = [f"`{f}`" for f in HEADLINE if bold(rows[f]["ATE (cm)"])]
    auroc = {f: float(plain(rows[f][columns[0]])) for f in HEADLINE[1:] if plain(rows[f][columns[0]]) != "-"}
    good = sorted((f for f, v in auroc.items() if v >= GOOD_AUROC), key=lambda f: -auroc[f])
    rest = sorted((f for f in auroc if f not in good), key=lambda f: -auroc[f])
    text = f"the best health signal of {listed([f'`{f}`' for f in good])} separates lost from not lost with AUROC "
    text += span([auroc[f] for f in good]) if good else "below " + num(GOOD_AUROC)
    text += (", " + listed([f"`{f}`'s {num(auroc[f])}" for f in rest])) if rest and good else ""
    return {
        "office-ate-bold": ("only " + best[0] + " is") if len(best) == 1 else listed(best) + " are",
        "lost-auroc": text,
    }


def robustness(report: str) -> dict[str, str]:
    """libRSF: the ratio of each filter's ATE under non-Gaussian noise to its Gaussian one (REPORT.md's table)."""
    rows = md_tables(report, "recorded-robustness")[0]
    ratios: dict[str, list[float]] = {}
    for r in rows:
        f = plain(r["filter"])
        ratios[f] = [float(x) for c, v in r.items() if "(x ref)" in c for x in re.findall(r"\(([\d.]+)\)", v)]
    filters = [f for f in ratios if not describe_filter(f).baseline]
    pf = [f for f in filters if f.split("[")[0] == "pf"]
    fmt = lambda x: num(x, 2)  # noqa: E731 (the table's own two digits)
    return {
        "librsf-ratio": span([x for f in filters for x in ratios[f]], fmt),
        "librsf-pf-ratio": span([x for f in pf for x in ratios[f]], fmt),
    }


def radish(df: pd.DataFrame, report: str) -> dict[str, str]:
    """Radish: where each laser filter keeps track, odometry's span, and where the filters were skipped."""
    sites = sorted(d for d in df["dataset"].unique() if str(d).split("[")[0] == "radish")
    site = {d: (d.split("site=")[1].rstrip("]") if "site=" in d else "intel") for d in sites}
    means = df[df["dataset"].isin(sites) & (df["metric"] == "ate_m")].groupby(["filter", "dataset"])["value"].mean()
    ate = {(str(f), str(d)): float(v) for (f, d), v in zip(means.index, means.to_numpy(), strict=True)}
    laser = ("pf[use_laser=true]", "ekf_icp")
    tracked = {f: [v for (g, _), v in ate.items() if g == f and v < TRACKED_M] for f in laser}
    lost = {f: [(site[d], v) for (g, d), v in sorted(ate.items()) if g == f and v >= TRACKED_M] for f in laser}
    odo = [v for (f, _), v in ate.items() if f == "odometry"]
    skipped: dict[str, list[str]] = {}
    for r in md_tables(report, "failures")[0]:
        d = plain(r["dataset"])
        ran = {g for g, _ in ate}  # a filter skipped on every site (it needs landmarks) is not news
        if r["status"] == "skipped" and d.split("[")[0] == "radish" and plain(r["filter"]) in ran:
            skipped.setdefault(plain(r["filter"]), []).append(d.split("site=")[1].rstrip("]"))
    a, b = laser
    where = [f"`{f}` is skipped on" if not i else f"`{f}` on" for i, f in enumerate(sorted(skipped))]
    return {
        "radish-sites": str(len(sites)),
        "radish-tracked": f"`{a}` is within {span([100 * v for v in tracked[a]])} cm on {len(tracked[a])} sites "
        f"and `{b}` within {span([100 * v for v in tracked[b]])} cm on {len(tracked[b])}",
        "radish-odometry": f"{span([v for v in odo], lambda x: num(x, 2))} m",
        "radish-lost": f"above {num(100 * TRACKED_M)} cm: "
        + listed([f"`{f}` " + " and ".join(f"{cm(v)} cm on {s}" for s, v in lost[f]) for f in sorted(lost) if lost[f]]),
        "radish-skipped": listed(
            [f"{w} {listed(sorted(skipped[f]))}" for w, f in zip(where, sorted(skipped), strict=True)]
        ),
    }


def office_prose(df: pd.DataFrame) -> dict[str, str]:
    """The sentences under the headline table: cost and accuracy ratios, the bounds, KLD sampling."""

    def cell(ds: str, f: str, metric: str) -> float:
        return mean_of(df[(df["dataset"] == ds) & (df["filter"] == f)], metric)

    office = df[df["dataset"] == "office"]
    no_laser = office[office["filter"].isin([*LANDMARK, BOUND_NO_LASER])].replace({BOUND_NO_LASER: BOUND_ALL})
    matched = []
    for ds in MATCHED:
        sub = df[df["dataset"] == ds]
        if (sub["filter"] == BOUND_NO_LASER).any():
            sub = sub[sub["filter"] != BOUND_ALL].replace({BOUND_NO_LASER: BOUND_ALL})
        matched += [ate_over_bound(sub, f) for f in LANDMARK if (sub["filter"] == f).any()]
    ate = {f: cell("office", f, "ate_m") for f in HEADLINE}
    # a configuration without runs on office (not stored yet) has no place in the order
    energy = {
        f: e for f in HEADLINE[1:] if np.isfinite(e := cell("office", f, "energy_score_m")) and np.isfinite(ate[f])
    }
    order = sorted(energy, key=lambda f: float(num(100 * ate[f])))
    agree = all(float(cm(energy[a])) <= float(cm(energy[b])) for a, b in itertools.pairwise(order))
    best = min(energy, key=lambda f: energy[f])
    kld, pf = "pf[adaptive=kld]", "pf"
    more = {ds: 100 * (cell(ds, kld, "ate_m") / cell(ds, pf, "ate_m") - 1) for ds in ("office", "room")}
    particles = cell("office", kld, "particles_mean")
    update = {f: cell("office", f, "update_us_median") for f in HEADLINE}
    matched_runs = int(df[df["dataset"] == MATCHED[0]]["seed"].nunique())
    return {
        "office-seeds": str(int(office[office["filter"] == "odometry"]["seed"].nunique())),
        "office-landmark-ate": " / ".join(cm(ate[f]) for f in LANDMARK),
        "office-kf-ate": cm(ate["kf_linear"]),
        "pf-ate": f"{cm(ate[pf])} and {cm(cell('room', pf, 'ate_m'))} cm",
        "ukf-ekf-update": f"{update['ukf_landmarks'] / update['ekf_landmarks']:.0f}x",
        "kf-bound": num(ate_over_bound(office, "kf_linear")),
        "landmark-bound-no-laser": span([ate_over_bound(no_laser, f) for f in LANDMARK], lambda x: num(x, 2)),
        "matched-bound": span([100 * abs(x - 1) for x in matched], lambda x: f"{x:.0f}") + " %",
        "kld-particles": f"{float(f'{particles:.2g}'):.0f}",
        "pf-particles": f"{cell('office', pf, 'particles_mean'):.0f}",
        "kld-update": f"{100 * (1 - update[kld] / update[pf]):.0f} %",
        "kld-ate": f"{more['office']:.0f} % more ATE on `office` and {more['room']:.0f} % on `room`",
        "energy-rank": ("ranks as the ATE does" if agree else "does not rank as the ATE does")
        + f" on `office` (`{best}` {cm(energy[best])} cm best)",
        "matched-band": f"{matched_runs} seeds, band {band_text(matched_runs)}",
        "matched-inconsistent": matched_verdicts(df),
        "matched-runs": f"{matched_runs} runs'",
        "kidnap-seeds": str(int(df[df["dataset"] == "office[kidnap_m=2]"]["seed"].nunique())),
        "mrclam-below": mrclam_below(df),
        "ukf-seed0": ukf_seed0(df),
        "librsf-below": librsf_below(df),
    }


def matched_verdicts(df: pd.DataFrame) -> str:
    """ "`ekf_icp` is under-confident and `ekf_lines` over-confident": the filters whose ANEES on the matched
    ``office`` is outside the band, with their verdict."""
    sub = df[df["dataset"] == MATCHED[1]]
    names = sorted({str(f) for f in sub["filter"].unique()} - {BOUND_ALL, BOUND_NO_LASER})
    out: list[str] = []
    for f in names:
        text = consistency_cell(sub[sub["filter"] == f])[0]
        verdict = text.split("(")[-1].rstrip(")")
        if verdict != "consistent":
            out.append(f"`{f}` " + ("is " if not out else "") + verdict)
    return listed(out) if out else "none is outside the band"


def mrclam_below(df: pd.DataFrame) -> str:
    """``every landmark filter is below odometry``, or the (filter, robot) cells that are not."""
    names = RECORDED[0][1]
    worse = []
    for ds in names:
        sub = df[(df["dataset"] == ds) & (df["metric"] == "ate_m")]
        means = sub.groupby("filter")["value"].mean()
        worse += [f"`{f}` on `{ds}`" for f in RECORDED_FILTERS[1:6] if f in means and means[f] >= means["odometry"]]
    return "every landmark filter is below odometry" if not worse else "not below odometry: " + listed(worse)


def ukf_seed0(df: pd.DataFrame) -> str:
    """The UKF against the EKF on seed 0 with known identities (the ``ukf_landmarks`` paragraph)."""
    pairs = []
    for ds in ("room", "office"):
        sub = df[(df["dataset"] == ds) & (df["seed"] == 0) & (df["metric"] == "ate_m")]
        v = sub.groupby("filter")["value"].first()
        pairs.append((ds, float(v["ukf_landmarks"]), float(v["ekf_landmarks"])))
    worst = max(abs(u / e - 1) for _, u, e in pairs)
    return (
        f"within {100 * worst:.0f} % of the EKF's ("
        + ", ".join(f"`{d}` {cm(u)} against {cm(e)} cm" for d, u, e in pairs)
        + ")"
    )


def librsf_below(df: pd.DataFrame) -> str:
    """``all 9``, or ``k of 9``: the libRSF sets on which every filter that ran has a lower ATE than odometry."""
    sets = sorted(d for d in df["dataset"].unique() if str(d).split("[")[0] == "librsf")
    below = 0
    for d in sets:
        means = df[(df["dataset"] == d) & (df["metric"] == "ate_m")].groupby("filter")["value"].mean()
        odo = means.pop("odometry")
        below += bool((means < odo).all())
    return f"all {len(sets)}" if below == len(sets) else f"{below} of {len(sets)}"


def sweep(df: pd.DataFrame, dataset: str, base: str, param: str) -> list[tuple[float, float]]:
    """``(value of param, mean ATE m)`` of every configuration on ``dataset`` that differs from ``base`` in
    ``param`` alone (``base`` included, at its default), by the parameter's value."""
    from dataclasses import asdict

    from locbench.registry import resolve_filter

    ref = asdict(resolve_filter(base).params)
    ref.pop(param)
    sub = df[(df["dataset"] == dataset) & (df["metric"] == "ate_m")]
    out: list[tuple[float, float]] = []
    for name, g in sub.groupby("filter"):
        if str(name).split("[")[0] != base.split("[")[0]:
            continue
        p = asdict(resolve_filter(str(name)).params)
        value = p.pop(param)
        if p == ref:
            out.append((float(value), float(g["value"].mean())))
    return sorted(out)


def pareto(df: pd.DataFrame) -> dict[str, str]:
    """The ``pareto`` sweep on ``office``: where each cost knob stops paying."""
    from locbench.registry import resolve_filter

    def values(points: Sequence[tuple[float, float]]) -> str:
        return " / ".join(f"{v:g}" for v, _ in points)

    def ates(points: Sequence[tuple[float, float]]) -> str:
        return " / ".join(cm(a) for _, a in points)

    icp = sweep(df, "office", "ekf_icp", "max_iterations")
    default = float(resolve_filter("ekf_icp").params.max_iterations)
    kept = [(v, a) for v, a in icp if a < TRACKED_M]
    lost = [(v, a) for v, a in icp if a >= TRACKED_M]
    k = min(kept)
    icp_text = f"`ekf_icp` needs about {k[0]:g} ICP iterations (its default allows {default:g}, ATE "
    icp_text += f"{cm(dict(icp)[default])} cm against {cm(k[1])} cm at {k[0]:g}"
    if lost:
        icp_text += f"; {values(lost).replace(' / ', ' or ')} lose the robot: ATE {ates(lost)} cm"
    gate = sweep(df, "office", "ekf_landmarks[association=nearest]", "gate_probability")
    good = [(v, a) for v, a in gate if a < TRACKED_M]
    bad = [(v, a) for v, a in gate if a >= TRACKED_M]
    gate_text = f"a nearest-neighbour gate of {values(good).replace(' / ', ' or ')} keeps track (ATE {ates(good)} cm)"
    if bad:
        gate_text += f" where {values(bad).replace(' / ', ' and ')} lose it ({ates(bad)} cm)"
    pf = sweep(df, "office", "pf", "particles")
    lag = sweep(df, "office", "gtsam_fls", "lag_s")
    return {
        "pareto-icp": icp_text + ")",
        "pareto-pf": f"ATE {ates(pf)} cm at {values(pf)} particles",
        "pareto-lag": f"ATE {span([100 * a for _, a in lag])} cm at lags {values(lag)} s",
        "pareto-gate": gate_text,
    }


def blocks(df: pd.DataFrame, report: str | None = None) -> dict[str, str]:
    """Every generated block of the README, by name; ``report`` is the report's Markdown (default: the committed
    pages, :func:`report_text`, which the same report code wrote from the same runs as ``df``)."""
    if report is None:
        report = report_text()
    kidnapped = {f"{b}[kidnap_m={d:g}]" for b in ("office", "room") for d in KIDNAP_DISTANCES_M}
    used = {"office", "room", *MATCHED, *kidnapped, *(ds for _, group, _ in RECORDED for ds in group)}
    ident = df["dataset"].astype(str).str.split("[").str[0]
    df = df[df["dataset"].isin(used) | ident.isin(["radish", "librsf"])]  # what every block reads, once (15 MB)
    makers: dict[str, Callable[[], str]] = {
        "office-summary": lambda: office_summary(df),
        "decision": lambda: decision(df),
        "kidnap": lambda: kidnaps(df),
        "consistency": lambda: consistency(df),
        "recorded": lambda: recorded(df),
        "global-laser": global_localization(df, laser=True),
        "global-landmarks": global_localization(df, laser=False),
    }
    out = {name: make() for name, make in makers.items()}
    out |= {f"suite-{s.name}-runs": str(s.runs) for s in SUITES.values()}
    out |= office_prose(df) | radish(df, report) | robustness(report) | office_report(report)
    out |= claim_values(report) | run_counts(report) | tuned_findings(report) | pareto(df)
    out["across-landmark-geometry"] = across_landmark_geometry(report)
    out["report-sizes"] = sizes_text(SUMMARY, "results/summary")
    # the protocols page's metric tables, as locbench.present.metric_info writes them
    out |= {f"metrics-{g.replace(' ', '-')}": f"\n{metric_table(g)}\n" for g in GROUPS if metric_table(g)}
    return out | doc_blocks()


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
    ap.add_argument("metrics", nargs="?", default=str(METRICS))
    mode = ap.add_mutually_exclusive_group()
    mode.add_argument(
        "--write", action="store_true", help="rewrite the generated blocks of README.md and the docs pages"
    )
    mode.add_argument(
        "--check", action="store_true", help="exit 1 when a generated block of README.md or a docs page disagrees"
    )
    args = ap.parse_args(argv)
    generated = blocks(read_metrics(args.metrics))
    if args.write:
        for doc in DOCUMENTS:
            doc.write_text(render(doc.read_text(encoding="utf-8"), generated), encoding="utf-8")
        return 0
    if args.check:
        bad = [(doc, name) for doc in DOCUMENTS for name in disagreements(doc.read_text(encoding="utf-8"), generated)]
        for doc, name in bad:
            source = f"{args.metrics} or the registry"
            print(
                f"{doc.relative_to(ROOT)}: block {name!r} disagrees with {source}; "
                "run tools/docs/readme_results.py --write"
            )
        return 1 if bad else 0
    for name, body in generated.items():
        print(f"--- {name}:{body}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
