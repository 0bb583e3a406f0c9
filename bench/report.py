"""From stored runs to ``<results>/summary/``: the tidy ``metrics.csv``, ``REPORT.md`` and figures.

Everything written here is deterministic: rows are sorted, floats are formatted the same way every
time, the report carries no wall-clock date and the PNG figures are drawn with the Agg backend, a fixed
style, size and dpi and no software metadata, so regenerating from the same runs gives identical bytes.

Tables are drawn from the metrics frame only (mean and 95 % Student-t interval over seeds, see
:func:`locbench.metrics.mean_ci`); the trajectory and NEES figures also read the per-step estimates of
the stored runs.
"""

from __future__ import annotations

import io
import logging
import re
from collections import defaultdict
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import matplotlib.style
import numpy as np
import pandas as pd
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Ellipse
from scipy import stats

import locbench
from locbench.claims import claims_for, sections_for, spec_id, waypoint_stats
from locbench.claims.report_003 import ROOM_TABLE1_CM
from locbench.errors import ConfigError
from locbench.metrics import (
    CONFIDENCE,
    POSE_DOF,
    chi2_band,
    estimate_at,
    mean_ci,
    mean_over_runs,
    nees_at_truth,
    run_metrics,
)
from locbench.spec import format_spec, parse_spec
from locbench.store import RunRecord, Store, TruthRecord

log = logging.getLogger(__name__)

FloatArray = np.ndarray

COLUMNS = ("dataset", "filter", "seed", "metric", "value")
#: ``value`` is written with 10 significant digits: stable, and far below any metric's noise.
FLOAT_FORMAT = "%.10g"

#: Comparison-table columns: (metric id, header, significant digits).
COMPARISON: tuple[tuple[str, str], ...] = (
    ("ate_m", "ATE (m)"),
    ("heading_rmse_rad", "heading RMSE (rad)"),
    ("rpe_m_per_m", "RPE (m/m)"),
    ("final_error_m", "final error (m)"),
    ("anees", "ANEES"),
    ("nees_in_band_fraction", "NEES in 95 % band"),
    ("predict_us_median", "predict median (us)"),
    ("update_us_median", "update median (us)"),
    ("realtime_factor", "real-time factor"),
)

#: Extra comparison column, shown beside ATE only for datasets where a filter reports a smoothed trajectory.
SMOOTHED_COLUMN = ("smoothed_ate_m", "smoothed ATE (m)")
#: Extra comparison columns, shown first for datasets with reference relations (Kuemmerle et al. 2009).
RELATION_COLUMNS = (("relation_error_m", "relation error (m)"), ("relation_error_rad", "relation error (rad)"))
#: A filter name containing this is scored in the "Global localization" section (started without a pose).
GLOBAL_INIT_MARK = "init=uniform"

FIG_SIZE = (7.0, 4.2)
FIG_DPI = 110
#: A fixed style on top of matplotlib's defaults (a user's matplotlibrc must not change the bytes).
_STYLE: dict[str, Any] = {
    "font.size": 8.0,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "legend.fontsize": 7.0,
    "lines.linewidth": 1.2,
    "path.simplify": False,
    "svg.hashsalt": "locbench",
}
_PNG_META = {"Software": None}
#: Number of covariance ellipses drawn along each trajectory (at a round interval).
_ELLIPSES_PER_TRACK = 12
_CHI2_2D_95 = float(stats.chi2.ppf(0.95, 2))


@dataclass
class RunInfo:
    """Status of one stored run, for the failure list."""

    dataset: str
    filter: str
    seed: int
    status: str
    message: str


@dataclass
class _Collected:
    """Everything :func:`write_report` needs from one pass over the store."""

    metrics: pd.DataFrame
    runs: list[RunInfo] = field(default_factory=list)
    broken: list[tuple[str, str]] = field(default_factory=list)
    metas: list[dict[str, Any]] = field(default_factory=list)
    # (dataset, filter) -> one (t, nees) series per ok run
    nees: dict[tuple[str, str], list[tuple[FloatArray, FloatArray]]] = field(default_factory=dict)
    # (dataset, filter, seed) -> run folder of ok runs
    ok_dirs: dict[tuple[str, str, int], Path] = field(default_factory=dict)
    truths: dict[tuple[str, int], TruthRecord] = field(default_factory=dict)


# --- collecting ---------------------------------------------------------------------------------


def _collect(store: Store) -> _Collected:
    rows: list[tuple[str, str, int, str, float]] = []
    out = _Collected(metrics=pd.DataFrame())
    nees: dict[tuple[str, str], list[tuple[FloatArray, FloatArray]]] = defaultdict(list)
    for run_dir in store.iter_runs():
        rel = _relative(run_dir, store.root)
        try:
            run = store.read_run(run_dir)
            meta = run.meta
            dataset, filt, seed = str(meta["dataset"]), str(meta["filter"]), int(meta["seed"])
            truth: TruthRecord | None = None
            if run.status == "ok":
                key = (dataset, seed)
                if key not in out.truths:
                    out.truths[key] = store.read_truth(dataset, seed)
                truth = out.truths[key]
                values = run_metrics(run, truth)
                ne = nees_at_truth(run.t, run.mean, run.cov, truth.ground_truth.t, truth.ground_truth.poses)
            else:
                values, ne = run_metrics(run, _NO_TRUTH), None
        except Exception as exc:
            log.warning("skipping unreadable run %s: %s", rel, exc)
            # Paths relative to the results folder keep the report independent of where it lives.
            msg = str(exc).replace(f"{store.root.as_posix()}/", "")
            out.broken.append((rel, f"{type(exc).__name__}: {msg}"))
            continue
        out.metas.append(meta)
        out.runs.append(RunInfo(dataset, filt, seed, run.status, str(meta.get("message", "") or "")))
        rows.extend((dataset, filt, seed, k, float(v)) for k, v in values.items())
        if truth is not None and ne is not None:
            nees[(dataset, filt)].append((truth.ground_truth.t, ne))
            out.ok_dirs[(dataset, filt, seed)] = run_dir
    out.nees = dict(nees)
    out.metrics = _frame(rows)
    return out


class _NoTruth:
    """Stands in for the truth of a run that is not ok (its metrics never look at it)."""


_NO_TRUTH: Any = _NoTruth()


def _frame(rows: Sequence[tuple[str, str, int, str, float]]) -> pd.DataFrame:
    df = pd.DataFrame(list(rows), columns=list(COLUMNS))
    df = df.astype({"dataset": "str", "filter": "str", "seed": "int64", "metric": "str", "value": "float64"})
    return df.sort_values(list(COLUMNS[:4]), kind="stable").reset_index(drop=True)


def _relative(path: Path, root: Path) -> str:
    try:
        return path.relative_to(root).as_posix()
    except ValueError:
        return path.as_posix()


def collect_metrics(store: Store) -> pd.DataFrame:
    """The tidy metrics of every stored run.

    Parameters
    ----------
    store : Store
        The results folder.

    Returns
    -------
    DataFrame
        Columns ``dataset, filter, seed, metric, value`` (names with their parameters), sorted by
        dataset, filter, seed and metric. An ok run gives :func:`locbench.metrics.run_metrics`; a failed
        or diverged run ``failed`` = 1; a skipped run nothing. A run folder that cannot be read (or whose
        ground truth is missing) is logged and left out.
    """
    return _collect(store).metrics


def write_metrics_csv(df: pd.DataFrame, path: str | Path) -> Path:
    """Write the tidy metrics as CSV, sorted and with stable float formatting (identical bytes on rerun).

    Values use ``%.10g``; infinities are written ``inf``, NaN ``nan``; line ends are ``\\n``.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    frame = _frame(list(df[list(COLUMNS)].itertuples(index=False, name=None)))
    buf = io.StringIO()
    frame.to_csv(buf, index=False, float_format=FLOAT_FORMAT, na_rep="nan", lineterminator="\n")
    _write_if_changed(path, buf.getvalue().encode())
    return path


def _write_if_changed(path: Path, data: bytes) -> None:
    """Leave an identical file untouched (its modification time too)."""
    if path.is_file() and path.read_bytes() == data:
        return
    path.write_bytes(data)


# --- formatting helpers -------------------------------------------------------------------------


def _num(x: float, digits: int = 3) -> str:
    if np.isnan(x):
        return "n/a"
    if np.isinf(x):
        return "inf" if x > 0 else "-inf"
    if 100.0 <= abs(x) < 1e9:
        return f"{x:.0f}"  # runtimes and real-time factors read better without an exponent
    return f"{x:.{digits}g}"


def _mean_pm(values: Iterable[float]) -> str:
    ci = mean_ci(np.fromiter(values, dtype=np.float64))
    if ci.n == 0:
        return "n/a"
    if np.isnan(ci.low):
        return _num(ci.mean)
    return f"{_num(ci.mean)} ± {_num(ci.half_width, 2)}"


def _md_escape(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ").strip()


def _md_table(header: Sequence[str], rows: Iterable[Sequence[str]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(_md_escape(c) for c in r) + " |" for r in rows]
    return lines


def _seed_ranges(seeds: Iterable[int]) -> str:
    """``0-4, 7, 9-10`` for the seeds 0 1 2 3 4 7 9 10."""
    s = sorted(set(seeds))
    parts: list[str] = []
    i = 0
    while i < len(s):
        j = i
        while j + 1 < len(s) and s[j + 1] == s[j] + 1:
            j += 1
        parts.append(str(s[i]) if i == j else f"{s[i]}-{s[j]}")
        i = j + 1
    return ", ".join(parts) if parts else "none"


def _filter_order(names: Iterable[str]) -> list[str]:
    """Odometry first (the baseline every table starts with), then by name."""
    return sorted(set(names), key=lambda n: (spec_id(n) != "odometry", n))


def _slug(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("_") or "dataset"


# --- report -------------------------------------------------------------------------------------


def write_report(store: Store) -> Path:
    """Write ``metrics.csv``, ``REPORT.md`` and ``figures/*.png`` under ``store.summary``.

    Parameters
    ----------
    store : Store
        The results folder; its ``summary`` folder is created or refreshed (stale figures removed).

    Returns
    -------
    Path
        The written ``REPORT.md``.
    """
    col = _collect(store)
    summary = store.summary
    figdir = summary / "figures"
    figdir.mkdir(parents=True, exist_ok=True)
    write_metrics_csv(col.metrics, summary / "metrics.csv")

    df = col.metrics
    datasets = sorted({r.dataset for r in col.runs})
    figures: dict[str, list[str]] = {}
    extra: dict[str, list[str]] = {}
    extra_figures: set[str] = set()
    for ds in datasets:
        figures[ds] = _dataset_figures(store, col, ds, figdir)
        extra[ds] = []
        # sections registered by the report modules of locbench.claims (a sweep table, a figure ...)
        for fn in sections_for(spec_id(ds)):
            with matplotlib.style.context(["default", _STYLE]):
                sec_lines, sec_figs = fn(df[df["dataset"] == ds], figdir, _slug(ds))
            extra[ds] += sec_lines
            extra_figures.update(sec_figs)
    across_lines = _across_variants(df, figdir, sorted({spec_id(d) for d in datasets}), extra_figures)
    kidnap_lines = _kidnap_section(df, figdir, extra_figures)
    global_lines = _global_localization(df)
    written = {f for fs in figures.values() for f in fs} | extra_figures
    for stale in sorted(figdir.glob("*.png")):
        if stale.name not in written:
            log.info("removing stale figure %s", stale.name)
            stale.unlink()

    lines = _provenance(col)
    for ds in datasets:
        lines += _dataset_section(df[df["dataset"] == ds], col, ds, figures[ds], extra[ds])
    lines += _recorded_section(df, col)
    lines += across_lines
    lines += kidnap_lines
    lines += global_lines
    lines += _failures(col)
    path = summary / "REPORT.md"
    _write_if_changed(path, ("\n".join(lines).rstrip() + "\n").encode())
    log.info("wrote %s (%d metric rows, %d figures)", path, len(df), len(written))
    return path


def _across_variants(df: pd.DataFrame, figdir: Path, ids: list[str], figures_out: set[str]) -> list[str]:
    """Claims and sections evaluated over every stored variant of a dataset id (sweeps, kidnap distances)."""
    lines: list[str] = []
    ids_of = df["dataset"].map(spec_id) if len(df) else pd.Series(dtype=str)
    for ident in ids:
        rows = df[ids_of == ident]
        claims = claims_for(ident, across_variants=True)
        sections = sections_for(ident, across_variants=True)
        if not (claims or sections):
            continue
        lines += [f"## {ident}: across its variants", ""]
        for fn in sections:
            with matplotlib.style.context(["default", _STYLE]):
                sec_lines, sec_figs = fn(rows, figdir, _slug(ident))
            lines += sec_lines
            figures_out.update(sec_figs)
        if claims:
            lines += ["### Claims", ""]
            crow = []
            for c in claims:
                res = c.evaluate(rows)
                crow.append([c.text, f"**{res.verdict}**", res.measured, c.reported])
            lines += _md_table(["claim", "verdict", "measured", "report"], crow)
            lines.append("")
    return lines


# --- kidnap recovery and global localization ------------------------------------------------------


def wilson_interval(successes: int, n: int, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """Two-sided Wilson score interval of a binomial proportion (NaN, NaN for n = 0).

    (p + z^2/2n -+ z sqrt(p(1-p)/n + z^2/4n^2)) / (1 + z^2/n) with p = successes / n and z the normal
    quantile of (1 + confidence) / 2; unlike the Wald interval it stays inside [0, 1] and is not empty
    at 0 or n successes.
    """
    if n <= 0:
        return float("nan"), float("nan")
    if not 0 <= successes <= n:
        raise ValueError(f"successes must be in [0, {n}], got {successes}")
    z = float(stats.norm.ppf(0.5 + confidence / 2.0))
    p = successes / n
    den = 1.0 + z * z / n
    centre = (p + z * z / (2.0 * n)) / den
    half = z * np.sqrt(p * (1.0 - p) / n + z * z / (4.0 * n * n)) / den
    return max(0.0, float(centre - half)), min(1.0, float(centre + half))


def _rate(values: pd.Series, runs: int) -> tuple[str, float, float, float]:
    """``k/n = rate [low, high]`` text, and the rate with its Wilson interval, of a 1/0 series.

    ``runs`` is n: every run that was not skipped, so a failed or diverged run (which has no 1/0 value)
    counts as a failure.
    """
    v = values.to_numpy(dtype=np.float64)
    k = int(np.sum(v > 0.5))
    n = max(int(runs), int(v.size))
    if n == 0:
        return "n/a", float("nan"), float("nan"), float("nan")
    lo, hi = wilson_interval(k, n)
    return f"{k}/{n} = {k / n:.2f} [{lo:.2f}, {hi:.2f}]", k / n, lo, hi


def _median(values: pd.Series) -> str:
    v = values.to_numpy(dtype=np.float64)
    v = v[~np.isnan(v)]
    return _num(float(np.median(v))) if v.size else "n/a"


def _kidnap_family(dataset: str) -> str:
    """The dataset name without its kidnap distance: the variants that a recovery-against-distance line joins."""
    try:
        ident, params = parse_spec(dataset)
    except ConfigError:
        return dataset
    params.pop("kidnap_m", None)
    return format_spec(ident, params)


def _kidnap_section(df: pd.DataFrame, figdir: Path, figures_out: set[str]) -> list[str]:
    """Recovery rate, time to recover and false confidence per dataset id, filter and kidnap distance."""
    if not len(df):
        return []
    dist = df[df["metric"] == "kidnap_distance_m"]
    if dist.empty:
        return []
    # the distance of a dataset name is its recorded |d| (the same for every seed of a synthetic kidnap)
    d_of = dist.groupby("dataset")["value"].median()
    names = sorted(d_of.index, key=lambda n: (spec_id(n), _kidnap_family(n), float(d_of[n]), n))
    lines = [
        "## Kidnap recovery",
        "",
        "After the first kidnap of a run (a silent jump of the truth by a distance D), a filter has recovered "
        "when its position error is <= 0.25 m and its heading error <= 0.25 rad at every ground-truth time "
        "for 2 s, starting within 30 s of the kidnap. Recovery rate over the runs (a failed or diverged run "
        "counts as not recovered) with a 95 % Wilson interval; "
        "median time from the kidnap to the start of that hold, over the recovered runs; false confidence is "
        "the fraction of the time from the kidnap to the recovery (or the end of the 30 s window) with the "
        "NEES above its 99.9 % chi-square(3) quantile (mean ± 95 % interval over seeds).",
        "",
    ]
    for ident in sorted({spec_id(n) for n in names}):
        ds_names = [n for n in names if spec_id(n) == ident]
        rows: list[list[str]] = []
        # (filter, family) -> [(D, rate, low, high)]
        curves: dict[tuple[str, str], list[tuple[float, float, float, float]]] = defaultdict(list)
        families = sorted({_kidnap_family(n) for n in ds_names})
        for f in _filter_order(df[df["dataset"].isin(ds_names)]["filter"].unique()):
            for n in ds_names:
                sub = df[(df["dataset"] == n) & (df["filter"] == f)]
                if sub.empty:
                    continue
                rec = sub[sub["metric"] == "kidnap_recovered"]["value"]
                status = sub[sub["metric"] == "failed"]["value"]
                text, rate, lo, hi = _rate(rec, len(status))
                if not np.isnan(rate):
                    curves[(f, _kidnap_family(n))].append((float(d_of[n]), rate, lo, hi))
                rows.append(
                    [
                        f"`{f}`",
                        _num(float(d_of[n])),
                        f"`{n}`",
                        str(len(status)),
                        str(int(status.sum())),
                        text,
                        _median(sub[sub["metric"] == "kidnap_time_to_recover_s"]["value"]),
                        _mean_pm(sub[sub["metric"] == "kidnap_false_confidence_fraction"]["value"]),
                    ]
                )
        lines += [f"### {ident}", ""]
        lines += _md_table(
            [
                "filter",
                "D (m)",
                "dataset",
                "runs",
                "failed",
                "recovered (95 % Wilson)",
                "median time to recover (s)",
                "false confidence",
            ],
            rows,
        )
        lines.append("")
        if curves:
            name = f"kidnap_{_slug(ident)}.png"
            with matplotlib.style.context(["default", _STYLE]):
                _save(_kidnap_figure(ident, curves, len(families) > 1), figdir / name)
            figures_out.add(name)
            lines += [f"![kidnap_{_slug(ident)}](figures/{name})", ""]
    return lines


def _kidnap_figure(
    ident: str, curves: dict[tuple[str, str], list[tuple[float, float, float, float]]], show_family: bool
) -> Figure:
    """Recovery rate against kidnap distance, a line per filter, with 95 % Wilson intervals."""
    fig = _new_figure()
    ax = fig.add_subplot()
    keys = sorted(curves, key=lambda k: (spec_id(k[0]) != "odometry", k[0], k[1]))
    all_d = sorted({p[0] for pts in curves.values() for p in pts})
    # a small sideways offset per line so that equal rates (0 or 1) and their intervals stay readable
    log_x = all_d[0] > 0 and len(all_d) > 1
    for i, key in enumerate(keys):
        pts = np.array(sorted(curves[key]), dtype=np.float64)
        shift = (i - (len(keys) - 1) / 2.0) * 0.02
        x = pts[:, 0] * 2.0**shift if log_x else pts[:, 0] + shift * (all_d[-1] - all_d[0] + 1.0)
        # the Wilson bounds can land a rounding error inside a rate of exactly 0 or 1
        err = np.clip(np.vstack([pts[:, 1] - pts[:, 2], pts[:, 3] - pts[:, 1]]), 0.0, None)
        label = f"{key[0]} on {key[1]}" if show_family else key[0]
        ax.errorbar(x, pts[:, 1], yerr=err, color=f"C{i % 10}", marker="o", ms=4, capsize=3, label=label)
    if log_x:
        ax.set_xscale("log", base=2)
    ax.set_xticks(all_d, [f"{d:g}" for d in all_d])
    ax.minorticks_off()
    ax.set_ylim(-0.05, 1.05)
    ax.set_xlabel("kidnap distance D (m)")
    ax.set_ylabel("recovery rate")
    ax.set_title(f"{ident}: recovery within 30 s (0.25 m, 0.25 rad held 2 s), 95 % Wilson intervals")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    return fig


def _global_localization(df: pd.DataFrame) -> list[str]:
    """Success rate and median time to converge of the filters started without a pose (``init=uniform``)."""
    if not len(df):
        return []
    sel = df[df["filter"].str.contains(GLOBAL_INIT_MARK, regex=False)]
    if sel.empty:
        return []
    rows = []
    for ds in sorted(sel["dataset"].unique()):
        sub_ds = sel[sel["dataset"] == ds]
        for f in _filter_order(sub_ds["filter"].unique()):
            sub = sub_ds[sub_ds["filter"] == f]
            status = sub[sub["metric"] == "failed"]["value"]
            rows.append(
                [
                    f"`{ds}`",
                    f"`{f}`",
                    str(len(status)),
                    str(int(status.sum())),
                    _rate(sub[sub["metric"] == "converged"]["value"], len(status))[0],
                    _median(sub[sub["metric"] == "time_to_converge_s"]["value"]),
                ]
            )
    return [
        "## Global localization",
        "",
        f"Filters started without knowing their pose (`{GLOBAL_INIT_MARK}`). A run has converged at the first "
        "time from the start at which its position error is <= 0.25 m and its heading error <= 0.25 rad at "
        "every ground-truth time for 2 s; success rate over the runs (a failed or diverged run counts as not "
        "converged) with a 95 % Wilson interval, median time to converge over the converged runs.",
        "",
        *_md_table(["dataset", "filter", "runs", "failed", "converged (95 % Wilson)", "median time (s)"], rows),
        "",
    ]


def _provenance(col: _Collected) -> list[str]:
    commits: dict[str, bool] = {}
    versions: dict[str, set[str]] = defaultdict(set)
    for m in col.metas:
        if m.get("git_commit"):
            c = str(m["git_commit"])
            commits[c] = commits.get(c, False) or bool(m.get("git_dirty", False))
        for lib, ver in (m.get("versions") or {}).items():
            versions[str(lib)].add(str(ver))
    seeds: dict[str, set[int]] = defaultdict(set)
    for r in col.runs:
        seeds[r.dataset].add(r.seed)
    counts: dict[str, int] = defaultdict(int)
    for r in col.runs:
        counts[r.status] += 1
    lines = [
        "# locbench results",
        "",
        "Generated by `locbench report` from the stored runs (regenerate with `nox -s report`); every table is "
        "drawn from `metrics.csv` (columns `dataset, filter, seed, metric, value`). Intervals are two-sided "
        f"{100 * CONFIDENCE:.0f} % Student-t intervals of the mean over seeds.",
        "",
        "## Provenance",
        "",
        f"- locbench {locbench.__version__}",
        "- git commit of the runs: "
        + (", ".join(f"`{c}`" + (" (dirty)" if d else "") for c, d in sorted(commits.items())) or "unknown"),
        "- libraries: "
        + (", ".join(f"{lib} {' / '.join(sorted(v))}" for lib, v in sorted(versions.items())) or "unknown"),
        "- seeds: " + ("; ".join(f"`{ds}` {_seed_ranges(s)}" for ds, s in sorted(seeds.items())) or "none"),
        "- runs: "
        + ", ".join(f"{counts[s]} {s}" for s in ("ok", "diverged", "error", "skipped") if counts[s])
        + (f", {len(col.broken)} unreadable" if col.broken else ""),
        "",
    ]
    return lines


def _dataset_section(
    df: pd.DataFrame, col: _Collected, ds: str, figs: list[str], extra: list[str] | None = None
) -> list[str]:
    lines = [f"## {ds}", ""]
    filters = _filter_order(df["filter"].unique()) if len(df) else []
    if not filters:
        return [*lines, "No runs with metrics (all skipped).", ""]
    if any(tr.truth_label != "ground truth" for (d, _), tr in col.truths.items() if d == ds):
        lines += [
            "The trajectory this dataset gives is a **SLAM reference** (another estimator's output), not ground "
            "truth: ATE, heading, RPE, final error and NEES below measure agreement with that reference. The "
            "relation errors (Kuemmerle et al. 2009) use manually verified relative poses and are the primary metric.",
            "",
        ]
    lines += [f"### Comparison (mean ± {100 * CONFIDENCE:.0f} % interval over seeds)", ""]
    columns = _comparison_columns(df)
    rows = []
    for f in filters:
        sub = df[df["filter"] == f]
        failed = sub[sub["metric"] == "failed"]["value"]
        row = [f"`{f}`", str(len(failed)), str(int(failed.sum()))]
        for metric, _ in columns:
            row.append(_mean_pm(sub[sub["metric"] == metric]["value"]))
        rows.append(row)
    lines += _md_table(["filter", "runs", "failed", *(h for _, h in columns)], rows)
    lines.append("")

    ws = waypoint_stats(df)
    if len(ws):
        lines += _waypoint_tables(ws, filters, spec_id(ds) == "room")

    claims = claims_for(spec_id(ds))
    if claims:
        lines += [f"### Claims of {claims[0].source}" if len({c.source for c in claims}) == 1 else "### Claims", ""]
        crow = []
        for c in claims:
            res = c.evaluate(df)
            crow.append([c.text, f"**{res.verdict}**", res.measured, c.reported])
        lines += _md_table(["claim", "verdict", "measured", "report"], crow)
        lines.append("")

    lines += extra or []
    if figs:
        lines += ["### Figures", ""]
        lines += [f"![{Path(f).stem}](figures/{f})" for f in figs]
        lines.append("")
    return lines


def _comparison_columns(df: pd.DataFrame) -> tuple[tuple[str, str], ...]:
    """The comparison columns; "smoothed ATE" beside ATE when any filter of the dataset has a smoothed trajectory,
    and the relation errors first when the dataset has reference relations."""
    cols = list(COMPARISON)
    if (df["metric"] == SMOOTHED_COLUMN[0]).any():
        at = next(i for i, (m, _) in enumerate(cols) if m == "ate_m") + 1
        cols.insert(at, SMOOTHED_COLUMN)
    if (df["metric"] == RELATION_COLUMNS[0][0]).any():
        cols = [*RELATION_COLUMNS, *cols]
    return tuple(cols)


def _waypoint_tables(ws: pd.DataFrame, filters: list[str], room: bool) -> list[str]:
    n_wp = int(ws["waypoint"].max())
    head = ["filter", "runs", *(str(j) for j in range(1, n_wp + 1))]

    def table(column: str) -> list[list[str]]:
        out = []
        for f in filters:
            sub = ws[ws["filter"] == f].set_index("waypoint")
            if sub.empty:
                continue
            vals = [_cm(sub[column].get(j, np.nan)) for j in range(1, n_wp + 1)]
            out.append([f"`{f}`", str(int(sub["runs"].max())), *vals])
        return out

    lines = [
        "### Waypoints (cm)",
        "",
        "RMSE_j = sqrt(mean_i e_ij^2) over runs, e_ij = |p_hat_i(t_j) - p_j| against the marked point "
        "(report 003 fig. 5):",
        "",
        *_md_table(head, table("rmse_m")),
        "",
        "Distance between waypoint j and the mean estimated position over runs (report 003 table 1):",
        "",
    ]
    rows = table("mean_distance_m")
    if room:
        rows += [
            [f"003 table 1: `{fid}`", "20", *(f"{v:.1f}" for v in ref)] + [""] * max(0, n_wp - len(ref))
            for fid, ref in ROOM_TABLE1_CM.items()
        ]
    lines += [*_md_table(head, rows), ""]
    return lines


#: The recorded-data table's accuracy metric: the relation error where a dataset has relations, else ATE.
_RECORDED_ACCURACY = (("relation_error_m", "relation error, m"), ("ate_m", "ATE, m"))


def _is_recorded(dataset: str) -> bool:
    """Whether a stored dataset name belongs to a recorded-dataset builder (by its registered class)."""
    from locbench.datasets.recorded.base import RecordedDataset
    from locbench.registry import DATASETS

    ident = spec_id(dataset)
    if ident not in DATASETS or DATASETS.missing_dependency(ident) is not None:
        return False
    try:
        return issubclass(DATASETS.load(ident), RecordedDataset)
    except Exception:
        return False


def _recorded_section(df: pd.DataFrame, col: _Collected) -> list[str]:
    """The recorded-data table: a row per filter, a column per recorded dataset; accuracy and runtime."""
    names = sorted({r.dataset for r in col.runs if _is_recorded(r.dataset)})
    if not names:
        return []
    status: dict[tuple[str, str], set[str]] = defaultdict(set)
    for r in col.runs:
        if r.dataset in names:
            status[(r.filter, r.dataset)].add(r.status)
    filters = _filter_order({f for f, _ in status})
    metric_of = {}
    for ds in names:
        have = set(df[df["dataset"] == ds]["metric"].unique())
        metric_of[ds] = next((m for m, _ in _RECORDED_ACCURACY if m in have), "ate_m")

    def cell(f: str, ds: str, metric: str, digits: int = 3) -> str:
        vals = df[(df["dataset"] == ds) & (df["filter"] == f) & (df["metric"] == metric)]["value"]
        if len(vals):
            return _num(float(vals.mean()), digits) + (f" (n={len(vals)})" if len(vals) > 1 else "")
        st = status.get((f, ds), set())
        if "skipped" in st:
            return "skipped"
        if st - {"ok"}:
            return "failed"
        return "not run" if not st else ""

    header = ["filter", *(f"`{ds}`" for ds in names)]
    lines = [
        "## Recorded data",
        "",
        "Every filter on the recorded datasets (one recording each; the mean over seeds where a randomised "
        "filter ran several). Accuracy: "
        + "; ".join(f"`{ds}` {dict(_RECORDED_ACCURACY)[metric_of[ds]]}" for ds in names)
        + ". Intel's trajectory is a SLAM reference, so its primary metric is the relation error "
        "(Kuemmerle et al. 2009). Skipped: the filter needs a map kind or sensor the dataset lacks, or the data "
        "is not on this machine (see the failed and skipped runs).",
        "",
        "### Accuracy",
        "",
    ]
    lines += _md_table(header, [[f"`{f}`", *(cell(f, ds, metric_of[ds]) for ds in names)] for f in filters])
    lines += ["", "### Runtime: real-time factor (dataset duration / compute time)", ""]
    lines += _md_table(header, [[f"`{f}`", *(cell(f, ds, "realtime_factor", 3) for ds in names)] for f in filters])
    lines.append("")
    return lines


def _cm(x: float) -> str:
    return "n/a" if np.isnan(x) else f"{100.0 * x:.1f}"


def _failures(col: _Collected) -> list[str]:
    bad = sorted((r for r in col.runs if r.status != "ok"), key=lambda r: (r.dataset, r.filter, r.seed))
    lines = ["## Failed and skipped runs", ""]
    if not bad and not col.broken:
        return [*lines, "None.", ""]
    if bad:
        rows = [[r.dataset, r.filter, str(r.seed), r.status, r.message] for r in bad]
        lines += [*_md_table(["dataset", "filter", "seed", "status", "message"], rows), ""]
    if col.broken:
        lines += ["Unreadable run folders (left out of every table):", ""]
        lines += _md_table(["folder", "error"], [[f"`{p}`", e] for p, e in sorted(col.broken)])
        lines.append("")
    return lines


# --- figures ------------------------------------------------------------------------------------


def _new_figure() -> Figure:
    fig = Figure(figsize=FIG_SIZE, dpi=FIG_DPI, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Figure, path: Path) -> None:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=FIG_DPI, metadata=_PNG_META)
    _write_if_changed(path, buf.getvalue())


def _dataset_figures(store: Store, col: _Collected, ds: str, figdir: Path) -> list[str]:
    """Draw the figures of one dataset; returns their file names."""
    names: list[str] = []
    slug = _slug(ds)
    with matplotlib.style.context(["default", _STYLE]):
        fig = _trajectory_figure(store, col, ds)
        if fig is not None:
            _save(fig, figdir / f"{slug}_trajectories.png")
            names.append(f"{slug}_trajectories.png")
        ws = waypoint_stats(col.metrics[col.metrics["dataset"] == ds])
        if len(ws):
            fig = _waypoint_figure(ws, ds)
            _save(fig, figdir / f"{slug}_waypoint_rmse.png")
            names.append(f"{slug}_waypoint_rmse.png")
        fig = _nees_figure(col, ds)
        if fig is not None:
            _save(fig, figdir / f"{slug}_nees.png")
            names.append(f"{slug}_nees.png")
    return names


def _nice_step(span: float, count: int) -> float:
    """A round interval (1, 2 or 5 x 10^k) giving about ``count`` steps over ``span``."""
    raw = max(span, 1e-9) / max(count, 1)
    mag = 10.0 ** np.floor(np.log10(raw))
    for m in (1.0, 2.0, 5.0, 10.0):
        if raw <= m * mag:
            return float(m * mag)
    return float(10.0 * mag)


def _trajectory_figure(store: Store, col: _Collected, ds: str) -> Figure | None:
    """One seed's estimated trajectories with 95 % position ellipses, ground truth and waypoints (000 fig. 5)."""
    keys = [k for k in col.ok_dirs if k[0] == ds]
    if not keys:
        return None
    seed = min(k[2] for k in keys)
    truth = col.truths[(ds, seed)]
    gt = truth.ground_truth
    fig = _new_figure()
    ax = fig.add_subplot()
    # the map first, in grey, so the tracks read against the walls and landmarks (000 fig. 5)
    for k, (x1, y1, x2, y2) in enumerate(truth.map_segments):
        ax.plot([x1, x2], [y1, y2], color="0.6", lw=1.2, solid_capstyle="butt", label="walls" if k == 0 else None)
    if len(truth.map_landmarks):
        lm = truth.map_landmarks
        ax.plot(lm[:, 0], lm[:, 1], ls="none", marker="^", ms=5, color="0.45", label="landmarks")
    ax.plot(gt.xy[:, 0], gt.xy[:, 1], color="black", lw=1.0, label=truth.truth_label)
    step = _nice_step(truth.duration_s, _ELLIPSES_PER_TRACK)
    t_marks = np.arange(gt.t[0], gt.t[-1] + 1e-9, step)[1:]
    for i, f in enumerate(_filter_order(k[1] for k in keys if k[2] == seed)):
        run: RunRecord = store.read_run(col.ok_dirs[(ds, f, seed)])
        color = f"C{i % 10}"
        ax.plot(run.mean[:, 0], run.mean[:, 1], color=color, lw=0.9, label=f)
        means = estimate_at(run.t, run.mean, t_marks)
        covs = estimate_at(run.t, run.cov, t_marks)
        for m, cov in zip(means, covs, strict=True):
            w, v = np.linalg.eigh(0.5 * (cov[:2, :2] + cov[:2, :2].T))
            w = np.clip(w, 0.0, None)
            if not np.all(np.isfinite(w)):
                continue
            angle = float(np.degrees(np.arctan2(v[1, 1], v[0, 1])))
            width, height = 2.0 * np.sqrt(_CHI2_2D_95 * w[1]), 2.0 * np.sqrt(_CHI2_2D_95 * w[0])
            ax.add_patch(Ellipse((m[0], m[1]), width, height, angle=angle, fill=False, color=color, lw=0.7))
    if truth.waypoints is not None and len(truth.waypoints):
        wp = truth.waypoints.xy
        ax.plot(wp[:, 0], wp[:, 1], ls="none", marker="x", ms=7, color="black", label="waypoints")
        for j, (x, y) in enumerate(wp, start=1):
            ax.annotate(str(j), (x, y), textcoords="offset points", xytext=(4, 4), fontsize=7)
    # Frame the world (truth, map, waypoints), not the estimates: a dead-reckoned track or its ellipses can run
    # hundreds of metres off and would shrink the world to a dot; what leaves the frame is clipped.
    pts = [gt.xy, truth.map_segments.reshape(-1, 2), truth.map_landmarks]
    if truth.waypoints is not None:
        pts.append(truth.waypoints.xy)
    world = np.vstack([p for p in pts if len(p)])
    lo, hi = world.min(axis=0), world.max(axis=0)
    pad = 0.15 * float(np.max(hi - lo)) + 1.0
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"{ds}, seed {seed}: estimates with 95 % position ellipses every {step:g} s")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    return fig


def _waypoint_figure(ws: pd.DataFrame, ds: str) -> Figure:
    """RMSE per waypoint and filter, grouped bars (report 003 fig. 5)."""
    fig = _new_figure()
    ax = fig.add_subplot()
    filters = _filter_order(ws["filter"].unique())
    n_wp = int(ws["waypoint"].max())
    width = 0.8 / max(len(filters), 1)
    x = np.arange(1, n_wp + 1, dtype=np.float64)
    for i, f in enumerate(filters):
        sub = ws[ws["filter"] == f].set_index("waypoint")["rmse_m"].reindex(range(1, n_wp + 1))
        ax.bar(x - 0.4 + width * (i + 0.5), 100.0 * sub.to_numpy(dtype=np.float64), width, label=f, color=f"C{i % 10}")
    ax.set_xticks(x, [str(j) for j in range(1, n_wp + 1)])
    ax.set_xlabel("waypoint")
    ax.set_ylabel("RMSE (cm)")
    ax.set_title(f"{ds}: position RMSE at each waypoint over runs")
    ax.legend(loc="upper left")
    return fig


def _nees_figure(col: _Collected, ds: str) -> Figure | None:
    """Mean NEES over runs against time with the chi-square(3N)/N band, log y."""
    entries = sorted((f, s) for (d, f), s in col.nees.items() if d == ds)
    if not entries:
        return None
    seed = min(k[2] for k in col.ok_dirs if k[0] == ds)
    grid = col.truths[(ds, seed)].ground_truth.t
    fig = _new_figure()
    ax = fig.add_subplot()
    order = _filter_order(f for f, _ in entries)
    series = dict(entries)
    bands = sorted({len(series[f]) for f in order})
    for n in bands:
        lo, hi = chi2_band(POSE_DOF, n, CONFIDENCE)
        ax.axhspan(lo, hi, color="0.5", alpha=0.15, lw=0, label=f"{100 * CONFIDENCE:.0f} % band, {n} runs")
    for i, f in enumerate(order):
        mean, _ = mean_over_runs(grid, series[f])
        y = np.where(np.isfinite(mean) & (mean > 0), mean, np.nan)
        ax.plot(grid, y, color=f"C{i % 10}", lw=0.9, label=f"{f} ({len(series[f])} runs)")
    ax.axhline(POSE_DOF, color="black", lw=0.6, ls="--")
    ax.set_yscale("log")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("mean NEES")
    ax.set_title(f"{ds}: mean NEES over runs (pose, heading wrapped)")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    return fig
