"""The report's tuning section: each filter tuned against its default on test data only (suite ``tuned``).

It reads the tuned suite's summary (``<results>/tuning/tuned.json``, written by
:func:`locbench.run.tuning.write_summary`)
for the studies (budget, trials, best configuration) and the collected metrics for the test runs; the train runs
live in ``<results>/tuning/runs``, a store the report never reads, so no train score enters a table. The pieces:
tuned beside default per study, the tuned values against the defaults, each study's best-so-far objective against
trials (a figure), and whether each world's ranking by ATE changes once every filter is tuned.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from locbench.evaluate.metrics import ATE_M, FAILED
from locbench.present.palette import Palette
from locbench.report import figures as fg
from locbench.report import tables as tb
from locbench.report.collect import Collected
from locbench.report.doc import Bullets, Plot, Section, Table, Text

NAN = float("nan")


def _test_rows(df: pd.DataFrame, study: dict[str, Any], filt: str, test_names: list[str]) -> pd.DataFrame:
    """The metric rows of ``filt`` on the study's test datasets and test seeds only."""
    seeds = [int(s) for s in study["test_seeds"]]
    return df[(df["filter"] == filt) & df["dataset"].isin(test_names) & df["seed"].isin(seeds)]


def _ate_cm(rows: pd.DataFrame) -> tuple[float, int, int]:
    """Mean test ATE (cm) over the ok runs, the ok runs and all runs."""
    v = tb.values(rows, ATE_M)
    runs = int(tb.values(rows, FAILED).size)
    return (100.0 * float(np.mean(v)) if v.size else NAN), int(v.size), runs


def _seeds(seeds: list[int]) -> str:
    """``0-19`` for a contiguous run of seeds, else the seeds listed."""
    s = sorted(int(x) for x in seeds)
    if s and s == list(range(s[0], s[-1] + 1)) and len(s) > 1:
        return f"{s[0]}-{s[-1]}"
    return ", ".join(map(str, s))


def _split(study: dict[str, Any]) -> str:
    """One line of the train/test split of a study: datasets and seeds of each side."""

    def side(names: list[str], seeds: list[int]) -> str:
        return ", ".join(f"`{n}`" for n in names) + f" (seed{'s' if len(seeds) > 1 else ''} {_seeds(seeds)})"

    return (
        f"`{study['world']}`: tuned on {side(study['train'], study['train_seeds'])}, "
        f"tested on {side(study['test'], study['test_seeds'])}"
    )


def _tuned_spec(study: dict[str, Any]) -> str:
    """The tuned spec column: the best spec, ``default kept`` when no searched trial beat the default."""
    best = study.get("best_spec")
    if not best:
        return "every trial failed"
    return "default kept" if study.get("default_kept") else f"`{best}`"


def _value(v: Any) -> str:
    if v is None:
        return "dataset's"
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def tuning_section(col: Collected) -> Section | None:
    """The section, or None when the results hold no tuned suite."""
    from locbench.registry import resolve_dataset
    from locbench.run.tuning import read_summary

    if col.store is None:
        return None
    studies = read_summary(col.store.root)
    if not studies:
        return None
    df = col.metrics
    sec = Section("Tuned against default (test data only)", "tuned")
    budgets = sorted({(len(s["trials"]), len(s["train"]) * len(s["train_seeds"])) for s in studies})
    splits = list(dict.fromkeys(_split(s) for s in studies))
    sec.add(
        Text(
            "Each filter's declared tunable parameters (noise scales, gates, thresholds, iteration caps; never a "
            "compute knob) were searched with optuna's seeded TPE sampler on train data, and its best configuration "
            "run on test data it never saw. The first trial of every study is the default configuration, counted in "
            "the budget, so a tuned configuration is never worse than the default on the train data ('default kept' "
            "when no searched trial beat it). Budget per filter and data (the same for every filter): "
            + "; ".join(f"{t} trials x {r} train runs = {t * r} runs" for t, r in budgets)
            + ". Objective: the mean of the train runs' ATE; a trial with a failed or diverged run scores as the "
            "worst. Every number below is on test data (docs/protocols.md, Tuning)."
        ),
        Bullets(tuple(splits)),
    )
    rows: list[tuple[str, ...]] = []
    keys: list[tuple[float, ...]] = []
    per_world: dict[str, dict[str, tuple[float, float]]] = {}
    for s in studies:
        test_names = [resolve_dataset(d).name for d in s["test"]]
        d_ate, d_ok, d_n = _ate_cm(_test_rows(df, s, s["filter"], test_names))
        best = s.get("best_spec")
        t_ate, t_ok, t_n = _ate_cm(_test_rows(df, s, best, test_names)) if best else (NAN, 0, 0)
        change = 100.0 * (t_ate / d_ate - 1.0) if d_ate > 0 and not math.isnan(t_ate) else NAN
        per_world.setdefault(s["world"], {})[s["filter"]] = (d_ate, t_ate if best else d_ate)
        rows.append(
            (
                f"`{s['filter']}`",
                s["world"],
                str(s["budget_runs"]),
                f"{tb.num(d_ate)} ({d_ok}/{d_n})",
                f"{tb.num(t_ate)} ({t_ok}/{t_n})" if best else "-",
                tb.num(change),
                _tuned_spec(s),
            )
        )
        keys.append((NAN, NAN, float(s["budget_runs"]), d_ate, t_ate, change, NAN))
    sec.add(
        Table(
            ("filter", "data", "budget (runs)", "default ATE (cm)", "tuned ATE (cm)", "change (%)", "tuned spec"),
            tuple(rows),
            caption="Tuned beside default: mean ATE on the test data (ok runs / runs in brackets)",
            footnotes=("Mean over every test run of the data (several test recordings: over them all).",),
            sort_keys=tuple(keys),
        )
    )
    sec.add(values_table(studies))
    sec.add(trials_plot(studies))
    sec.add(ranking(per_world))
    return sec


def values_table(studies: list[dict[str, Any]]) -> Table:
    """Each tuned value beside its default (``dataset's``: the dataset's nominal value, the default of a None)."""
    rows = []
    for s in studies:
        for k, rng in s["ranges"].items():
            rows.append(
                (
                    f"`{s['filter']}`",
                    s["world"],
                    f"`{k}`",
                    _value(s["defaults"][k]),
                    _value(s["tuned"][k]) if k in s["tuned"] else "-",
                    rng,
                )
            )
    return Table(
        ("filter", "data", "parameter", "default", "tuned", "range searched"),
        tuple(rows),
        caption="Tuned values against the defaults",
    )


def trials_plot(studies: list[dict[str, Any]]) -> Plot:
    """Best-so-far train objective against trials, one panel per world, one line per filter."""
    worlds = list(dict.fromkeys(s["world"] for s in studies))
    filters = list(dict.fromkeys(s["filter"] for s in studies))
    styles = Palette(filters).styles(filters)
    title = "Best train objective so far against trials"

    def draw(fig: Figure) -> None:
        axes = fig.subplots(1, len(worlds), squeeze=False)[0]
        for ax, world in zip(axes, worlds, strict=True):
            mine = [s for s in studies if s["world"] == world]
            curves = []
            for s in mine:
                best, ys = math.inf, []
                for t in s["trials"]:
                    best = min(best, float(t["value"]))
                    ys.append(100.0 * best if math.isfinite(best) else np.nan)
                curves.append(np.asarray(ys, dtype=np.float64))
            # equal best-so-far curves would hide each other: offset sideways, hollow markers, named in the legend
            same = fg.coinciding([s["filter"] for s in mine], curves)
            for k, (s, curve) in enumerate(zip(mine, curves, strict=True)):
                st = styles[s["filter"]]
                xs = np.arange(1, len(curve) + 1) + (0.12 * k if s["filter"] in same else 0.0)
                label = s["filter"] + (f" (= {same[s['filter']]})" if s["filter"] in same else "")
                ax.plot(
                    xs,
                    curve,
                    color=st.color,
                    marker=st.marker or None,
                    linestyle=st.linestyle,
                    label=label,
                    mfc="none" if s["filter"] in same else None,
                )
            ax.set_title(world, fontsize=9)
            ax.set_xlabel("trial")
            ax.set_ylabel("best mean train ATE so far (cm)")
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
            ax.grid(True, which="both", alpha=0.3)
            # each panel's own legend, below its axes (a world need not tune every filter)
            ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(0.0, -0.2), borderaxespad=0.0)
        fig.suptitle(title, fontsize=10)

    per_world = max(sum(1 for s in studies if s["world"] == w) for w in worlds)
    return Plot("tuning_best_so_far", title, draw, size=(3.3 * len(worlds) + 0.6, 3.4 + 0.16 * per_world))


def ranking(per_world: dict[str, dict[str, tuple[float, float]]]) -> Bullets:
    """Per world: the filters ordered by default and by tuned test ATE, and whether the order changes."""
    items = []
    for world, cells in per_world.items():
        names = sorted(cells)
        by_default = sorted(names, key=lambda f: (np.nan_to_num(cells[f][0], nan=math.inf), f))
        by_tuned = sorted(names, key=lambda f: (np.nan_to_num(cells[f][1], nan=math.inf), f))
        verdict = "unchanged" if by_default == by_tuned else "**changes**"
        items.append(
            f"`{world}`: ranking by test ATE {verdict} once every filter is tuned; default: "
            + " < ".join(f"`{f}`" for f in by_default)
            + "; tuned: "
            + " < ".join(f"`{f}`" for f in by_tuned)
        )
    return Bullets(tuple(items))
