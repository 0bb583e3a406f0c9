"""The report's summary: one table per main comparison, a row per filter configuration."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from locbench.lost import LOST_THRESHOLDS_M
from locbench.metrics import METRICS, POSE_DOF
from locbench.report import health as hl
from locbench.report import significance as sig
from locbench.report import tables as tb
from locbench.report.doc import Section, Table
from locbench.report.names import KIDNAP_PARAM, NAN
from locbench.report.reference import INDEPENDENT_KINDS

if TYPE_CHECKING:
    from locbench.report.build import Report

#: The kidnap distance whose recovery rate the summary table shows, m.
SUMMARY_KIDNAP_M = 2.0


def summary_section(rep: Report) -> Section:
    sec = Section("Summary", "summary")
    for e in rep.exps:
        if e.summary and e.dataset in rep.col.datasets:
            sec.children.append(Section(f"{e.title}", f"summary-{e.dataset}", [summary_table(rep, e.dataset)]))
    return sec


def kidnap_variant(rep: Report, dataset: str) -> str | None:
    base = rep.col.datasets[dataset].spec
    for n in rep.variants_of(base.ident):
        spec = rep.col.datasets[n].spec
        if spec.without(KIDNAP_PARAM) == base and np.isclose(rep.kidnap_distance(n), SUMMARY_KIDNAP_M):
            return n
    return None


def kidnap_config(rep: Report, filter_name: str, candidates: list[str]) -> str | None:
    """The configuration's own kidnap configuration: the one its class declares (``Filter.kidnap_params``
    added to its parameters) when it was run, else its id with every parameter it sets and the fewest more
    (``f`` -> ``f[recovery=on]``, ``f[a=1]`` -> ``f[a=1,recovery=on]``), if exactly one is that close."""
    declared = rep.col.filters[filter_name].kidnap_name
    if declared is not None and declared in candidates:
        return declared
    spec = rep.col.filters[filter_name].spec
    mine = set(spec.params)
    fits = [
        (len(rep.col.filters[c].spec.params), c)
        for c in candidates
        if rep.col.filters[c].spec.ident == spec.ident and mine <= set(rep.col.filters[c].spec.params)
    ]
    if not fits:
        return None
    fewest = min(n for n, _ in fits)
    best = [c for n, c in fits if n == fewest]
    return best[0] if len(best) == 1 else None


def recorded_ate(rep: Report, filter_name: str) -> tuple[float, int]:
    per = []
    for ds in rep.recorded():
        if not rep.ground_truth(ds) or rep.reference_kind(ds) not in INDEPENDENT_KINDS:
            continue
        sub = rep.rows(ds)
        v = tb.values(sub[sub["filter"] == filter_name], "ate_m")
        if v.size:
            per.append(float(np.mean(v)))
    return (100.0 * float(np.median(per)), len(per)) if per else (NAN, 0)


def summary_table(rep: Report, dataset: str) -> Table:
    df = rep.rows(dataset)
    filters = rep.filters_on(dataset)
    wp = tb.waypoint_rmse_mean(df)
    kid = kidnap_variant(rep, dataset)
    kdf = rep.rows(kid) if kid else df.iloc[0:0]
    kfilters = rep.filters_on(kid) if kid else []
    rows: list[list[str]] = []
    keys: list[list[float]] = []
    notes: list[str] = []
    substituted: dict[str, str] = {}
    knames: list[str | None] = []
    for f in filters:
        sub = df[df["filter"] == f]
        runs = int(tb.values(sub, "failed").size)
        ate = tb.mean_of(sub, "ate_m") * 100.0
        wpm = wp.get(f, NAN) * 100.0
        head = tb.mean_of(sub, "heading_rmse_rad") * METRICS["heading_rmse_rad"].scale
        an_text, an_key, _, _ = tb.consistency_cell(sub)
        es = tb.mean_of(sub, "energy_score_m") * METRICS["energy_score_m"].scale
        upd = tb.mean_of(sub, "update_us_median")
        rtf = tb.mean_of(sub, "realtime_factor")
        # the kidnap runs of this configuration, or of its filter's one kidnap configuration
        kname = f if f in kfilters else kidnap_config(rep, f, kfilters)
        knames.append(kname)
        if kname is not None and kname != f:
            substituted[f] = kname
        # lost detection where a filter does get lost: its kidnap configuration on the kidnapped world
        # (a configuration without kidnap runs has none, so the column means one thing throughout)
        if kid:
            lost_auc = hl.best_auroc(rep.col, kid, kname) if kname is not None else NAN
        else:
            lost_auc = hl.best_auroc(rep.col, dataset, f)
        if kname is not None:
            _, n_k, r_k, _, _ = tb.rate(kdf[kdf["filter"] == kname], "kidnap_recovered")
            k_text = f"{100 * r_k:.0f} ({n_k})" + ("²" if kname != f else "") if n_k else "n/a"
            k_key = 100 * r_k if n_k else NAN
        else:
            k_text, k_key = "-", NAN
        rec, n_rec = recorded_ate(rep, f)
        eff = tb.ate_over_bound(df, f)
        rows.append(
            [
                f"`{f}`",
                str(runs),
                tb.num(ate),
                tb.num(eff),
                tb.num(wpm),
                tb.num(head),
                an_text,
                tb.num(es),
                tb.num(lost_auc) if not np.isnan(lost_auc) else "-",
                tb.num(upd) if not np.isnan(upd) else "-",
                tb.num(rtf),
                k_text,
                f"{tb.num(rec)} ({n_rec})" if n_rec else "-",
            ]
        )
        keys.append([NAN, float(runs), ate, eff, wpm, head, an_key, es, lost_auc, upd, rtf, k_key, rec])
    eligible = [not rep.col.is_baseline(f) for f in filters]
    bounds = rep.bounds_on(dataset)
    for b in bounds:
        sub = df[df["filter"] == b]
        ate = tb.mean_of(sub, "ate_m") * 100.0
        wpm = wp.get(b, NAN) * 100.0
        head = tb.mean_of(sub, "heading_rmse_rad") * METRICS["heading_rmse_rad"].scale
        runs = tb.run_count(sub)
        rows.append([f"`{b}`", str(runs), tb.num(ate), "-", tb.num(wpm), tb.num(head), *["-"] * 7])
        keys.append([NAN, float(runs), ate, NAN, wpm, head, *[NAN] * 7])
        eligible.append(False)
    hovers = sig.hover_grid(rows)
    marks = sig.mark_ties(
        rows, keys, sig.summary_columns(rep, dataset, filters, len(bounds), kid, knames), eligible, hovers=hovers
    )
    notes.append(sig.tie_footnote(marks))
    runs_all = [int(tb.values(df[df["filter"] == f], "failed").size) for f in filters]
    n_typ = max(set(runs_all), key=runs_all.count) if runs_all else 0
    notes.append(
        f"ANEES: mean over runs of each run's average NEES (heading wrapped), against the two-sided 95 % "
        f"chi-square band for the run count ({tb.band_text(n_typ)} for {n_typ} runs); closest to "
        f"{POSE_DOF} is marked best."
    )
    notes.append(
        "Energy score: proper score of the filter's own position belief, mean over the ground-truth times "
        f"(lower is better). Lost AUROC: how well the filter's best health signal separates the times its "
        f"position error exceeds {LOST_THRESHOLDS_M[0]:g} m from the others (1 perfect, 0.5 chance; '-': never "
        "lost, or no kidnap runs)"
        + (f", on `{kid}` with the kidnap configuration as for kidnap recovery" if kid else "")
        + '; see "Does the filter know that it is lost?".'
    )
    if bounds:
        notes.append(tb.BOUND_FOOTNOTE)
    if any("¹" in r[6] for r in rows):
        notes.append(tb.COLLAPSE_FOOTNOTE)
    if kid:
        notes.append(
            f"Kidnap recovery: percentage of the runs of `{kid}` that recovered (run count in brackets)."
            + (
                " ² The filter's kidnap configuration: "
                + ", ".join(f"`{a}` -> `{b}`" for a, b in sorted(substituted.items()))
                + "."
                if substituted
                else ""
            )
        )
    notes.append(
        "Recorded median ATE: median over the recorded datasets with independent ground truth (motion capture, "
        "GPS, survey or a stated truth; never a SLAM reference or a simulated world) that this configuration "
        "ran on (their number in brackets) of its mean ATE there."
    )
    columns = (
        "filter",
        "runs",
        "ATE (cm)",
        tb.header("ate_over_pcrb"),
        "mean waypoint RMSE (cm)",
        "heading RMSE (deg)",
        "ANEES (verdict)",
        "energy score (cm)",
        f"lost AUROC ({LOST_THRESHOLDS_M[0]:g} m{f', {SUMMARY_KIDNAP_M:g} m kidnap' if kid else ''})",
        "update median (us)",
        "real-time factor (x)",
        f"kidnap recovery at {SUMMARY_KIDNAP_M:g} m (%)",
        "recorded median ATE (cm)",
    )
    return Table(
        columns,
        tuple(tuple(r) for r in rows),
        caption=f"`{dataset}`: mean over seeds",
        footnotes=tuple(notes),
        sort_keys=tuple(tuple(k) for k in keys),
        hovers=tuple(tuple(h) for h in hovers),
    )
