"""The report's section "Does the filter know that it is lost?" and the summary's lost-detection cell.

Built from the lost-detection series that :func:`locbench.report.collect.collect` gathers (one per ok run with
stored health signals and ground truth) with the pure functions of :mod:`locbench.evaluate.lost`; names no dataset or
filter.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from matplotlib.figure import Figure

from locbench.evaluate.lost import (
    FALSE_ALARM_RATE,
    LOST_THRESHOLDS_M,
    RECALL,
    HealthSeries,
    SignalScore,
    alarm_threshold,
    detection_delay,
    roc_curve,
)
from locbench.evaluate.metrics import KIDNAP_WINDOW_S
from locbench.filters.base import HEALTH_SIGNALS
from locbench.report import figures as fg
from locbench.report import tables as tb
from locbench.report.doc import Plot, Section, Table, Text

if TYPE_CHECKING:
    from locbench.report.collect import Collected
    from locbench.report.context import Report

NAN = float("nan")
#: A signal's name and its oriented values over some ground-truth times.
FloatPair = tuple[str, np.ndarray]
#: Signals listed after the best one in the table.
RUNNERS_UP = 2
#: Most panels of the ROC figure.
MAX_ROC_PANELS = 6
#: Why a filter run on a dataset has no curve in the ROC figure when it stored no health signal.
NO_SIGNAL = "no health signal stored"
#: False-positive rates at which two ROC curves are compared (:func:`locbench.report.figures.coinciding`).
ROC_GRID = np.linspace(0.0, 1.0, 101)


def best_signal(rep: Report, dataset: str, filter_name: str) -> SignalScore | None:
    """The filter's best signal on a dataset (highest AUROC at the first lost threshold), or None."""
    scores = rep.signal_scores(dataset, filter_name)
    return scores[0] if scores and np.isfinite(scores[0].auroc[0]) else None


def best_auroc(rep: Report, dataset: str, filter_name: str) -> float:
    """The summary's cell: AUROC of the best signal at the first lost threshold (NaN when never lost)."""
    best = best_signal(rep, dataset, filter_name)
    return best.auroc[0] if best is not None else NAN


def _quiet(col: Collected, base: str | None, filter_name: str, kidnapped: list[HealthSeries]) -> list[FloatPair]:
    """(signal name, oriented values) sources without a kidnap: the same configuration's runs on the world without
    the kidnap when there are any, else the kidnapped runs before their kidnap."""
    out: list[FloatPair] = []
    runs = col.health.get((base, filter_name), []) if base is not None else []
    if runs:
        for s in runs:
            out.extend(s.signals.items())
        return out
    for s in kidnapped:
        before = s.t < s.kidnap_t
        out.extend((k, v[before]) for k, v in s.signals.items())
    return out


def lost_section(rep: Report) -> Section:
    """Lost detection: a table of each filter's best signal per dataset, a ROC figure and the kidnap delays."""
    col = rep.col
    sec = Section("Does the filter know that it is lost?", "lost")
    lo, hi = LOST_THRESHOLDS_M[0], LOST_THRESHOLDS_M[1]
    rows: list[tuple[str, ...]] = []
    keys: list[tuple[float, ...]] = []
    curves: dict[str, list[tuple[str, SignalScore]]] = {}
    # the filters scored but without a curve (never or always lost): named in the figure's panel
    absent: dict[str, dict[str, str]] = {}
    for ds in sorted({d for d, _ in col.health}, key=col.display):
        for f in rep.filters_on(ds):
            series = col.health.get((ds, f), [])
            scores = rep.signal_scores(ds, f)
            if not scores:
                absent.setdefault(ds, {})[f] = NO_SIGNAL  # run here, but nothing to score: the figure says so
                continue
            best = scores[0]
            others = ", ".join(f"{s.signal} {tb.num(s.auroc[0])}" for s in scores[1 : 1 + RUNNERS_UP])
            defined = np.isfinite(best.auroc[0])
            rows.append(
                (
                    f"`{col.display(ds)}`",
                    f"`{f}`",
                    str(len(series)),
                    tb.num(100.0 * best.lost_share),
                    f"`{best.signal}`" if defined else "never lost" if best.lost_share == 0 else "always lost",
                    tb.num(best.auroc[0]) if defined else "-",
                    tb.num(best.auroc[1]) if defined else "-",
                    tb.num(best.precision) if defined else "-",
                    others if defined else "-",
                )
            )
            share = 100.0 * best.lost_share
            keys.append((NAN, NAN, float(len(series)), share, NAN, *best.auroc[:2], best.precision, NAN))
            if defined:
                curves.setdefault(ds, []).append((f, best))
            else:
                absent.setdefault(ds, {})[f] = "never lost" if best.lost_share == 0 else "always lost"
    if not rows:
        return sec
    sec.add(
        Text(
            f"A supervisor can only act on what a filter says about itself. Each filter reports health signals at "
            f"every step (NIS and its chi-square p-value, covariance trace, effective sample size, maximum weight, "
            f"w_fast / w_slow, ICP residual and inlier fraction, accepted fraction); a filter is **lost** at a "
            f"ground-truth time when its position error exceeds {lo:g} m (and {hi:g} m). Per dataset and filter, over "
            f"the pooled ground-truth times of its runs: the share of time lost, the signal that separates lost from "
            f"not lost best (AUROC: 1 perfect, 0.5 chance; chosen on these same times, so optimistic), its AUROC at "
            f"both thresholds and its precision at {100 * RECALL:.0f} % recall (of the times flagged when "
            f"{100 * RECALL:.0f} % of the lost times are, the share that are lost), and the next best signals. "
            f"Definitions: docs/protocols.md."
        ),
        Table(
            (
                "dataset",
                "filter",
                "runs",
                f"time lost > {lo:g} m (%)",
                "best signal",
                f"AUROC ({lo:g} m)",
                f"AUROC ({hi:g} m)",
                f"precision at {100 * RECALL:.0f} % recall",
                "next signals (AUROC)",
            ),
            tuple(rows),
            caption="Each filter's best lost signal",
            sort_keys=tuple(keys),
        ),
    )
    plot = _roc_plot(rep, curves, absent)
    if plot is not None:
        sec.add(plot)
    delays = _delay_table(rep)
    if delays is not None:
        sec.add(delays)
    sec.add(Text("Signals: " + signal_glossary() + "."))
    return sec


def _roc_plot(
    rep: Report, curves: dict[str, list[tuple[str, SignalScore]]], absent: dict[str, dict[str, str]]
) -> Plot | None:
    """ROC curves of each filter's best signal, one panel per dataset with the most filters scored; the filters
    of a panel's dataset without a curve are named in its legend with the reason."""
    col = rep.col
    chosen = sorted(curves, key=lambda d: (-len(curves[d]), col.display(d)))[:MAX_ROC_PANELS]
    if not chosen:
        return None
    chosen.sort(key=col.display)
    lines: dict[str, list[tuple[str, str, np.ndarray, np.ndarray, float]]] = {}
    for ds in chosen:
        for f, best in curves[ds]:
            series = col.health[(ds, f)]
            v = np.concatenate([s.signals[best.signal] for s in series])
            lost = np.concatenate([s.error_m for s in series]) > LOST_THRESHOLDS_M[0]
            fpr, tpr, _ = roc_curve(v, lost)
            lines.setdefault(ds, []).append((f, best.signal, fpr, tpr, best.auroc[0]))
    styles = rep.styles_for(col.filter_order({f for ds in chosen for f, _ in curves[ds]}))
    # one panel a row: each panel's legend stands to its right, and two a row left each plot a narrow strip
    cols = 1
    nrows = -(-len(chosen) // cols)
    title = f"ROC of each filter's best signal against lost (> {LOST_THRESHOLDS_M[0]:g} m)"
    entries = max(len(lines[ds]) + len(absent.get(ds, {})) for ds in chosen)

    def draw(fig: Figure) -> None:
        axes = fig.subplots(nrows, cols, squeeze=False)
        for ax, ds in zip(axes.ravel(), chosen, strict=False):
            # a curve on top of an earlier one is drawn dashed over it and its entry names the curve it lies on
            same = fg.coinciding(
                [f for f, *_ in lines[ds]], [np.interp(ROC_GRID, fpr, tpr) for _, _, fpr, tpr, _ in lines[ds]]
            )
            for f, sig, fpr, tpr, a in lines[ds]:
                st = styles[f]
                label = f"{f}: {sig} ({a:.2f})"
                if f in same:
                    label += f" (on {same[f]})"
                    ax.plot(fpr, tpr, color=st.color, ls=(0, (3, 3)), lw=1.4, label=label, zorder=2.5)
                    continue
                ax.plot(fpr, tpr, color=st.color, ls=st.linestyle, lw=1.0, label=label)
            ax.plot([0, 1], [0, 1], color="0.6", lw=0.6, ls=":")
            ax.tick_params(labelsize=6)
            fg.finish(ax, "false-positive rate", "true-positive rate", col.display(ds), absent=absent.get(ds, {}))
        for ax in axes.ravel()[len(chosen) :]:
            ax.set_visible(False)
        fig.suptitle(title, fontsize=9)

    shows = tuple(
        dict.fromkeys([*(f for ds in chosen for f, _ in curves[ds]), *(f for ds in chosen for f in absent.get(ds, {}))])
    )
    return Plot("lost_roc", title, draw, size=(10.0, (2.8 + 0.12 * entries) * nrows + 0.4), shows=shows)


def _delay_table(rep: Report) -> Table | None:
    """Kidnapped runs: the delay from the kidnap to the first alarm of the filter's best signal there."""
    from locbench.report.names import KIDNAP_PARAM

    col = rep.col
    rows: list[tuple[str, ...]] = []
    keys: list[tuple[float, ...]] = []
    for ds in sorted({d for d, _ in col.health}, key=col.display):
        if np.isnan(rep.kidnap_distance(ds)):
            continue
        base_spec = col.datasets[ds].spec.without(KIDNAP_PARAM).name
        base = base_spec if base_spec in col.datasets else None
        for f in rep.filters_on(ds):
            series = [s for s in col.health.get((ds, f), []) if np.isfinite(s.kidnap_t)]
            best = best_signal(rep, ds, f)
            if not series or best is None:
                continue
            quiet = [v for k, v in _quiet(col, base, f, series) if k == best.signal]
            thr = alarm_threshold(np.concatenate(quiet)) if quiet else NAN
            d = np.array([detection_delay(s.t, s.signals[best.signal], thr, s.kidnap_t) for s in series])
            hit = d[np.isfinite(d)]
            source = "same world, no kidnap" if base is not None and col.health.get((base, f)) else "before the kidnap"
            med = float(np.median(hit)) if hit.size else NAN
            rows.append(
                (
                    f"`{col.display(ds)}`",
                    f"`{f}`",
                    f"`{best.signal}`",
                    source,
                    f"{hit.size}/{d.size}",
                    tb.num(med) if hit.size else "-",
                )
            )
            keys.append((NAN, NAN, NAN, NAN, float(hit.size) / d.size, med))
    if not rows:
        return None
    return Table(
        ("dataset", "filter", "signal", "threshold from", f"alarm within {KIDNAP_WINDOW_S:g} s", "median delay (s)"),
        tuple(rows),
        caption=(
            f"Detection delay after the kidnap: the best signal's threshold is the one that raises an alarm at "
            f"{100 * FALSE_ALARM_RATE:.0f} % of the times of runs without a kidnap (the same configuration on the "
            f"world without the kidnap when it ran there, else its kidnapped runs before the kidnap)"
        ),
        sort_keys=tuple(keys),
    )


def signal_glossary() -> str:
    """One line naming every health signal and which way means lost (for the section's footnote)."""
    return "; ".join(f"`{k}`: {v.description} ({v.lost_when} = lost)" for k, v in HEALTH_SIGNALS.items())
