"""Claims of report 001 (Gadau et al., EKF with laser landmarks and GPS) on ``landmark_geometry``.

Every claim compares variants of the dataset (paths, landmark layouts, GPS, kidnap), so all are registered
``across_variants`` and get the tidy rows of every stored ``landmark_geometry[...]`` name. A variant's
parameters are read back from its name; a name that no longer parses against the current parameters
is left out (logged). The EKF is ``ekf_landmarks`` (the plain id when it has runs, else the first variant,
:func:`locbench.claims.pick_filter`); ATE is the DESIGN ``ate_m`` (position RMSE over the run).

The concrete tests, fixed before any run:

* **landmark count** (sec. IV-A-2 and V): on the base variants (every parameter at its default except
  ``path`` and ``landmarks``), the EKF's ATE averaged over the paths that have all five layouts falls
  strictly from 1 to 2 landmarks and from 2 to the better of 3 (triangle) and 4 (square near), and the
  8-far layout is within a factor :data:`FLAT_FACTOR` of the 4-near one ("stops making a big difference
  after four").
* **path independence** (sec. IV-A-3 and V): for each layout with at least 3 landmarks stored on at least
  two paths (base variants), the largest mean ATE over paths is at most :data:`PATH_FACTOR` times the
  smallest, and the EKF is below odometry on every path.
* **GPS from a wrong start** (sec. IV-A-1, fig. 5): on every variant with ``gps=true`` and
  ``initial_offset_m`` > 0, the mean final position error (``final_error_m``) of ``ekf_landmarks`` with
  ``use_pose_fixes=true`` is below both :data:`GPS_FINAL_FRACTION` of the initial offset and the fix's
  standard deviation per axis.
* **kidnap** (sec. IV-A-4, fig. 7): on every variant with ``kidnap_m`` > 0 the EKF recovers
  (``kidnap_recovered``, DESIGN: error <= 0.25 m and 0.25 rad held 2 s within 30 s) in fewer than half of
  the runs. Not evaluated while the metrics carry no ``kidnap_recovered``.
"""

from __future__ import annotations

import logging
import math
from dataclasses import fields
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from locbench.claims import (
    Claim,
    ClaimResult,
    Experiment,
    Source,
    Verdict,
    all_found,
    paired,
    pick_filter,
    register,
    register_experiment,
    register_section,
    spec_id,
    spec_of,
    test_text,
)
from locbench.core.errors import LocbenchError
from locbench.core.spec import build_params
from locbench.evaluate.aggregate import mean_ci
from locbench.evaluate.metrics import ATE_M, FAILED, FINAL_ERROR_M, KIDNAP_RECOVERED, METRICS
from locbench.evaluate.pcrb import is_bound_row
from locbench.evaluate.significance import ALPHA, TestResult, mann_whitney, wilcoxon_paired
from locbench.present import ranking as rk
from locbench.present.docfmt import Block, Plot, Text
from locbench.present.palette import Palette
from locbench.suites import SUITES

log = logging.getLogger(__name__)

SOURCE_001 = Source(
    "001",
    "Aerial localization using the Extended Kalman Filter",
    "Arwed Gadau, Natan Viana, Rodrigo Contreiras and Rui Anjo",
)
DATASET = "landmark_geometry"
LAYOUT_ORDER = ("1", "2", "3", "4", "8")
PATH_ORDER = ("circle", "star", "pentagon", "random")

#: "Flattens after 4": ATE(8 far) / ATE(4 near) within [1 / FLAT_FACTOR, FLAT_FACTOR].
FLAT_FACTOR = 2.0
#: "Works well independently of the path": max / min of the mean ATE over paths at most this.
PATH_FACTOR = 2.0
#: "Converges": final error below this fraction of the initial offset (and below the fix sigma).
GPS_FINAL_FRACTION = 0.2
#: "Does not recover": recovery rate over seeds below this.
KIDNAP_MAX_RATE = 0.5


def _params_class() -> type:
    # Imported on use: the dataset module pulls in the simulator, which the claims registry does not need.
    from locbench.datasets.synthetic.landmark_geometry import LandmarkGeometryParams

    return LandmarkGeometryParams


def _parse(name: str) -> Any | None:
    """The typed parameters of a ``landmark_geometry[...]`` name, or None when it does not parse."""
    try:
        spec = spec_of(name)
        if spec.ident != DATASET:
            return None
        return build_params(_params_class(), spec.as_dict(), spec.ident)
    except LocbenchError as exc:
        log.warning("left out %s: %s", name, exc)
        return None


def variants(df: pd.DataFrame) -> pd.DataFrame:
    """The rows of ``df`` with the dataset parameters as columns, plus ``base`` (only path / layout differ).

    Parameters
    ----------
    df : DataFrame
        Tidy metrics rows (``dataset, filter, seed, metric, value``) of any dataset names.

    Returns
    -------
    DataFrame
        The rows of ``landmark_geometry`` names that parse, with one column per parameter and a bool
        column ``base``.
    """
    cls = _params_class()
    defaults = cls()
    info: dict[str, dict[str, Any]] = {}
    for name in sorted({str(d) for d in df["dataset"].unique()}):
        p = _parse(name)
        if p is None:
            continue
        row = {f.name: getattr(p, f.name) for f in fields(p)}
        row["base"] = all(
            getattr(p, f.name) == getattr(defaults, f.name) for f in fields(p) if f.name not in ("path", "landmarks")
        )
        info[name] = row
    out = df[df["dataset"].isin(list(info))].copy()
    if not len(out):
        return out.assign(base=pd.Series(dtype=bool))
    cols = pd.DataFrame.from_dict(info, orient="index")
    return out.join(cols, on="dataset")


def _mean_metric(rows: pd.DataFrame, metric: str) -> float:
    v = rows.loc[rows["metric"] == metric, "value"].to_numpy(dtype=np.float64)
    return float(np.mean(v)) if v.size else float("nan")


def _n_failed(rows: pd.DataFrame) -> int:
    return int(rows.loc[rows["metric"] == FAILED, "value"].sum())


def _filter_flag(name: str, key: str) -> bool:
    """True when a filter name sets boolean ``key`` true (``ekf_landmarks[use_pose_fixes=true]``)."""
    try:
        value = spec_of(name).get(key, "false")
    except LocbenchError:
        return False
    return str(value).strip().lower() in ("1", "true", "yes", "on")


def _cm(x: float) -> str:
    return f"{100.0 * x:.1f}"


# --- claims -------------------------------------------------------------------------------------


def _check_landmark_count(df: pd.DataFrame) -> ClaimResult:
    v = variants(df)
    base = v[v["base"]] if len(v) else v
    ekf = pick_filter(base, "ekf_landmarks") if len(base) else None
    if ekf is None:
        return ClaimResult("not evaluated", "no ekf_landmarks runs on the base variants")
    rows = base[base["filter"] == ekf]
    per = {
        (p, lay): _mean_metric(g, ATE_M)
        for (p, lay), g in rows.groupby(["path", "landmarks"], sort=True)
        if not np.isnan(_mean_metric(g, ATE_M))
    }
    paths = [p for p in PATH_ORDER if all((p, lay) in per for lay in LAYOUT_ORDER)]
    if not paths:
        return ClaimResult("not evaluated", f"{ekf}: no path has runs of all layouts {', '.join(LAYOUT_ORDER)}")
    ate = {lay: float(np.mean([per[(p, lay)] for p in paths])) for lay in LAYOUT_ORDER}
    falls = ate["1"] > ate["2"] > min(ate["3"], ate["4"])
    ratio = ate["8"] / ate["4"]
    flat = 1.0 / FLAT_FACTOR <= ratio <= FLAT_FACTOR
    # each fall must be found (layouts are different realisations: unpaired, runs pooled over the paths)
    runs = rows[rows["path"].isin(paths) & (rows["metric"] == ATE_M)]

    def ate_runs(lay: str) -> np.ndarray:
        return runs.loc[runs["landmarks"] == lay, "value"].to_numpy(dtype=np.float64)

    best34 = "3" if ate["3"] <= ate["4"] else "4"
    tests: list[TestResult] = [
        mann_whitney(ate_runs("1"), ate_runs("2"), "greater"),
        mann_whitney(ate_runs("2"), ate_runs(best34), "greater"),
    ]
    falls = falls and all_found(tests) == "reproduced"
    failed = _n_failed(rows)
    text = (
        f"{ekf} ATE (cm) by layout 1 / 2 / 3 / 4 / 8 over {', '.join(paths)}: "
        + " / ".join(_cm(ate[lay]) for lay in LAYOUT_ORDER)
        + f"; 8-far / 4-near {ratio:.2f}"
        + (f"; {failed} failed runs left out" if failed else "")
    )
    verdict: Verdict = (
        "not evaluated" if not all(t.tested for t in tests) else ("reproduced" if falls and flat else "not reproduced")
    )
    return ClaimResult(verdict, text, f"one-sided, 1 > 2 and 2 > {best34}: " + test_text(*tests))


def _check_path_independent(df: pd.DataFrame) -> ClaimResult:
    v = variants(df)
    base = v[v["base"]] if len(v) else v
    ekf = pick_filter(base, "ekf_landmarks") if len(base) else None
    if ekf is None:
        return ClaimResult("not evaluated", "no ekf_landmarks runs on the base variants")
    odo = pick_filter(base, "odometry")
    parts: list[str] = []
    ok = True
    evaluated = 0
    tests: list[TestResult] = []
    for lay in ("3", "4", "8"):
        sub = base[base["landmarks"] == lay]
        e = {p: _mean_metric(sub[(sub["filter"] == ekf) & (sub["path"] == p)], ATE_M) for p in PATH_ORDER}
        e = {p: x for p, x in e.items() if not np.isnan(x)}
        if len(e) < 2:
            continue
        evaluated += 1
        ratio = max(e.values()) / min(e.values())
        below = True
        if odo is not None:
            # below odometry on each path, found by a one-sided paired test (same realisations)
            for p in e:
                on_path = sub[sub["path"] == p]
                a, b = paired(on_path, ekf, odo, ATE_M)
                tests.append(wilcoxon_paired(a, b, alternative="less"))
            below = all(t.tested and t.p < ALPHA for t in tests[-len(e) :])
        ok = ok and ratio <= PATH_FACTOR and below
        parts.append(
            f"layout {lay}: "
            + ", ".join(f"{p} {_cm(x)}" for p, x in e.items())
            + f" cm (max/min {ratio:.2f}"
            + ("" if odo is None else f", below {odo} on every path: {'yes' if below else 'no'}")
            + ")"
        )
    if not evaluated:
        return ClaimResult("not evaluated", f"{ekf}: no layout with >= 3 landmarks stored on two or more paths")
    text = f"{ekf} ATE; " + "; ".join(parts)
    if tests and not all(t.tested for t in tests):
        return ClaimResult("not evaluated", text, "one-sided, EKF below odometry per path: " + test_text(*tests))
    verdict: Verdict = "reproduced" if ok else "not reproduced"
    return ClaimResult(verdict, text, "one-sided, EKF below odometry per path: " + test_text(*tests) if tests else "")


def _check_gps_converges(df: pd.DataFrame) -> ClaimResult:
    v = variants(df)
    if not len(v):
        return ClaimResult("not evaluated", "no landmark_geometry runs")
    sel = v[v["gps"].astype(bool) & (v["initial_offset_m"] > 0)]
    gps_filters = sorted(
        {
            str(f)
            for f in sel["filter"].unique()
            if spec_id(str(f)) == "ekf_landmarks" and _filter_flag(str(f), "use_pose_fixes")
        }
    )
    if not gps_filters:
        return ClaimResult(
            "not evaluated", "no ekf_landmarks[use_pose_fixes=true] runs on gps=true, initial_offset_m>0"
        )
    parts: list[str] = []
    ok = True
    for ds_name, g in sel.groupby("dataset", sort=True):
        offset = float(g["initial_offset_m"].iloc[0])
        sigma = float(g["pose_fix_sigma_m"].iloc[0])
        limit = min(GPS_FINAL_FRACTION * offset, sigma)
        for f in gps_filters:
            fe = _mean_metric(g[g["filter"] == f], FINAL_ERROR_M)
            if np.isnan(fe):
                continue
            ok = ok and fe < limit
            others = [
                f"{o} {_cm(_mean_metric(g[g['filter'] == o], FINAL_ERROR_M))}"
                for o in sorted({str(x) for x in g["filter"].unique()} - {f})
            ]
            parts.append(
                f"{ds_name} {f}: final error {_cm(fe)} cm (limit {_cm(limit)} cm, start {_cm(offset)} cm off)"
                + ("; others " + ", ".join(others) + " cm" if others else "")
            )
    if not parts:
        return ClaimResult("not evaluated", "no final_error_m rows of the GPS filter")
    return ClaimResult("reproduced" if ok else "not reproduced", "; ".join(parts))


def _check_kidnap(df: pd.DataFrame) -> ClaimResult:
    v = variants(df)
    if not len(v):
        return ClaimResult("not evaluated", "no landmark_geometry runs")
    sel = v[v["kidnap_m"] > 0]
    ekf = pick_filter(sel, "ekf_landmarks") if len(sel) else None
    if ekf is None:
        return ClaimResult("not evaluated", "no ekf_landmarks runs on a kidnap_m > 0 variant")
    if not (sel["metric"] == KIDNAP_RECOVERED).any():
        return ClaimResult("not evaluated", "the metrics carry no kidnap_recovered (kidnap recovery not computed)")
    parts: list[str] = []
    ok = True
    names = sorted({str(f) for f in sel["filter"].unique() if spec_id(str(f)) == "ekf_landmarks"})
    for ds_name, g in sel.groupby("dataset", sort=True):
        for f in [ekf, *(n for n in names if n != ekf)]:
            r = g.loc[(g["filter"] == f) & (g["metric"] == KIDNAP_RECOVERED), "value"].to_numpy(dtype=np.float64)
            if not r.size:
                continue
            rate = float(np.mean(r))
            if f == ekf:
                ok = ok and rate < KIDNAP_MAX_RATE
            parts.append(f"{ds_name} {f}: recovered in {int(r.sum())}/{r.size} runs")
    if not parts:
        return ClaimResult("not evaluated", f"{ekf}: no kidnap_recovered rows")
    return ClaimResult("reproduced" if ok else "not reproduced", "; ".join(parts))


register(
    Claim(
        "lg_error_falls_with_landmarks",
        DATASET,
        SOURCE_001,
        "Error falls with the number of landmarks and flattens after 4: the EKF's ATE (mean over the paths "
        "with all layouts, base variants) falls 1 > 2 > min(3 triangle, 4 square near), each fall found by a "
        "one-sided Mann-Whitney test over the runs at 5 %, and the 8-far layout "
        f"is within a factor {FLAT_FACTOR:g} of the 4-near one.",
        "qualitative (sec. IV-A-2, V): 1 and 2 landmarks too few; 3 (triangle) good; 4 (square near) better; "
        "beyond 4 the difference is really small; far landmarks also work",
        _check_landmark_count,
        across_variants=True,
    ),
    Claim(
        "lg_path_independent",
        DATASET,
        SOURCE_001,
        "The EKF works well independently of the path: for each layout with >= 3 landmarks, max/min of the "
        f"EKF's mean ATE over the stored paths <= {PATH_FACTOR:g}, and the EKF below odometry on every path "
        "(a one-sided Wilcoxon signed-rank test over the seeds finds it at 5 % on each).",
        "qualitative (sec. IV-A-3, V): works well with circle, star, pentagon and random paths; only the "
        "time to converge changes",
        _check_path_independent,
        across_variants=True,
    ),
    Claim(
        "lg_gps_converges",
        DATASET,
        SOURCE_001,
        "GPS converges from a wrong start: with gps=true and initial_offset_m > 0, the mean final position "
        f"error of ekf_landmarks[use_pose_fixes=true] < min({GPS_FINAL_FRACTION:g} x offset, fix sigma).",
        "qualitative (fig. 5): the estimate approaches the true route in a short time",
        _check_gps_converges,
        across_variants=True,
    ),
    Claim(
        "lg_kidnap_no_recovery",
        DATASET,
        SOURCE_001,
        "The EKF does not recover from a kidnap: on every kidnap_m > 0 variant, ekf_landmarks recovers "
        f"(kidnap_recovered) in fewer than {100 * KIDNAP_MAX_RATE:.0f} % of the runs.",
        "qualitative (sec. IV-A-4, fig. 7, V): the EKF does not work well after the kidnapping",
        _check_kidnap,
        across_variants=True,
    ),
)


# --- report section: ATE per landmark layout ------------------------------------------------------


def _mean_pm(values: np.ndarray) -> str:
    ci = mean_ci(values)
    if ci.n == 0:
        return ""
    if ci.n < 2 or np.isnan(ci.low):
        return f"{_cm(ci.mean)}"
    return f"{_cm(ci.mean)} ± {_cm(ci.mean - ci.low)}"


def layout_section(df: pd.DataFrame, slug: str) -> list[Block]:
    """ATE per landmark layout on the base variants: a table (cm, mean ± 95 % CI) and a figure.

    Rows are (filter, path); columns the layouts 1, 2, 3, 4, 8; the bound's rows (``pcrb``, in black) last.
    The figure has one line per path and filter (odometry dashed), ATE on a log scale.
    """
    v = variants(df)
    base = v[v["base"] & (v["metric"] == ATE_M)] if len(v) else v
    caption = "ATE per landmark layout (base variants, cm, mean ± 95 % interval over seeds)"
    if not len(base):
        return [Text("No runs of the base variants.")]
    filters = sorted({str(f) for f in base["filter"].unique()}, key=lambda f: (is_bound_row(f), f != "odometry", f))
    paths = [p for p in PATH_ORDER if p in set(base["path"])]

    rows: list[tuple[str, ...]] = []
    series: list[tuple[str, str, list[float]]] = []
    per_run: list[list[dict[int, float] | None]] = []
    for f in filters:
        for p in paths:
            sub = base[(base["filter"] == f) & (base["path"] == p)]
            if not len(sub):
                continue
            cells, means, runs = [], [], []
            for lay in LAYOUT_ORDER:
                at = sub[sub["landmarks"] == lay]
                vals = at["value"].to_numpy(dtype=np.float64)
                cells.append(_mean_pm(vals))
                means.append(float(np.mean(vals)) if vals.size else float("nan"))
                runs.append({int(k): float(x) for k, x in zip(at["seed"], vals, strict=True) if np.isfinite(x)} or None)
            rows.append((f"`{f}`", p, *cells))
            series.append((f, p, means))
            per_run.append(runs)

    def draw(fig: Figure) -> None:
        ax = fig.add_subplot()
        x = np.arange(len(LAYOUT_ORDER))
        # one colour per filter id, as in every figure (the bound black)
        colors = {f: st.color for f, st in Palette(filters).styles(filters).items()}
        markers = {"circle": "o", "star": "*", "pentagon": "p", "random": "s"}
        for f, p, means in series:
            ls = "--" if spec_id(f) == "odometry" else ":" if is_bound_row(f) else "-"
            ax.plot(
                x,
                np.asarray(means) * 100.0,
                linestyle=ls,
                marker=markers.get(p, "o"),
                color=colors[f],
                label=f"{f}, {p}",
            )
        ax.set_xticks(x, ["1", "2", "3\ntriangle", "4\nsquare near", "8\nsquare far"])
        ax.set_yscale("log")
        ax.set_xlabel("landmark layout")
        ax.set_ylabel("ATE (cm)")
        ax.set_title("landmark_geometry: ATE per layout (mean over seeds)")
        ax.legend(fontsize="x-small", ncols=2, loc="upper left", bbox_to_anchor=(1.01, 1.0))

    header = ("filter", "path", *LAYOUT_ORDER)
    return [
        rk.marked_table(
            header,
            rows,
            [(math.nan, math.nan, *m) for _, _, m in series],
            [rk.Column(2 + j, METRICS[ATE_M], [r[j] for r in per_run]) for j in range(len(LAYOUT_ORDER))],
            rk.eligible_names([f for f, _, _ in series]),
            caption=caption,
            groups=[p for _, p, _ in series],
            labels=[f"{f}, {p}" for f, p, _ in series],
            footnotes=("Ranked within each path and layout (the same world and seeds).",),
        ),
        Plot(f"{slug}_ate_per_layout", "landmark_geometry: ATE per landmark layout and path", draw, size=(8.0, 4.2)),
    ]


register_section(DATASET, layout_section)
register_experiment(
    Experiment(
        DATASET,
        "Landmark geometry (report 001)",
        "Report 001's study: circle, star, pentagon and random paths driven twice in a 14 m arena, with 1, 2, "
        "3 (triangle), 4 (square near) or 8 (square far) disc landmarks detected in a 151-beam laser; a GPS "
        "variant from a wrong start and kidnaps. Its 25 variants are folded into one table and one figure.",
        source=SOURCE_001,
        fold_variants=True,
        order=50,
        suite=SUITES["landmark_geometry"],
    )
)
