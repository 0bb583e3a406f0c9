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
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from locbench.evaluate.metrics import ATE_M, FAILED
from locbench.evaluate.significance import FloatArray, TestResult, wilcoxon_paired
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


def _unit_ate(rows: pd.DataFrame) -> dict[tuple[str, int], float]:
    """ATE (m) per test unit, (dataset, seed), of one configuration's rows (NaN for a failed run)."""
    sub = rows[rows["metric"] == ATE_M]
    return {(str(d), int(k)): float(v) for d, k, v in zip(sub["dataset"], sub["seed"], sub["value"], strict=True)}


@dataclass(frozen=True)
class GroupEffect:
    """One filter on one world, tuned against its default on every test unit of its studies (the folds of a
    cross-validated world pooled: unit k's tuned configuration is the one tuned without it)."""

    filter: str
    world: str
    units: tuple[str, ...]
    default_m: FloatArray
    tuned_m: FloatArray

    @property
    def change_pct(self) -> FloatArray:
        """Per unit 100 (tuned / default - 1): negative is better."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.asarray(100.0 * (self.tuned_m / self.default_m - 1.0), dtype=np.float64)

    def test(self) -> TestResult:
        """The paired Wilcoxon signed-rank test of tuned against default ATE across the units (two-sided)."""
        return wilcoxon_paired(self.tuned_m, self.default_m)


def group_effects(df: pd.DataFrame, studies: list[dict[str, Any]]) -> list[GroupEffect]:
    """Per (filter, world), in the order of ``studies``: each test unit's default and tuned ATE."""
    from locbench.registry import resolve_dataset

    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for s in studies:
        groups.setdefault((s["filter"], s["world"]), []).append(s)
    out = []
    for (filt, world), mine in groups.items():
        units: list[str] = []
        d_m: list[float] = []
        t_m: list[float] = []
        for s in mine:
            test_names = [resolve_dataset(d).name for d in s["test"]]
            default = _unit_ate(_test_rows(df, s, s["filter"], test_names))
            best = s.get("best_spec")
            tuned = _unit_ate(_test_rows(df, s, best, test_names)) if best else {}
            for unit in sorted(default):
                units.append(s.get("fold") or (f"seed {unit[1]}" if len(test_names) == 1 else f"{unit[0]} {unit[1]}"))
                d_m.append(default[unit])
                t_m.append(tuned.get(unit, NAN))
        out.append(GroupEffect(filt, world, tuple(units), np.asarray(d_m), np.asarray(t_m)))
    return out


#: Most units whose effects a row lists one by one (the folds of a cross-validated world); more are summarised.
LISTED_UNITS = 6


def _effects_text(g: GroupEffect) -> str:
    """The per-unit changes, listed for a few units (``robot 4 +34``), else better / worse counts and the range."""
    ch = g.change_pct
    if len(g.units) <= LISTED_UNITS:
        return "; ".join(f"{u} {tb.num(c)}" for u, c in zip(g.units, ch, strict=True))
    ok = ch[np.isfinite(ch)]
    if not ok.size:
        return "-"
    better, worse = int(np.sum(ok < 0)), int(np.sum(ok > 0))
    return f"better on {better} of {ok.size}, worse on {worse}; {tb.num(ok.min())} to {tb.num(ok.max())}"


def _intro(tuning: dict[str, Any], studies: list[dict[str, Any]]) -> tuple[Text, Bullets]:
    """The section's opening: the protocol, the sampler, the budget and commit, and each study's split."""
    budgets = sorted({(len(s["trials"]), len(s["train"]) * len(s["train_seeds"])) for s in studies})
    splits = list(dict.fromkeys(_split(s) for s in studies))
    sampler = tuning.get("sampler", {})
    return (
        Text(
            "Each filter's declared tunable parameters (noise scales, gates, thresholds, iteration caps; never a "
            "compute knob) were searched with optuna's seeded TPE sampler "
            f"(multivariate: {sampler.get('multivariate')}, "
            f"{sampler.get('startup_trials')} random trials after the default, seed {sampler.get('seed')}) on train "
            "data, and its best configuration run on test data it never saw; the recordings are cross-validated, "
            "leave one robot out, so the configuration reported for a robot was tuned on the other robots. The "
            "first trial of every study is the default configuration, counted in the budget, so a tuned "
            "configuration is never worse than the default on the train data ('default kept' when no searched trial "
            "beat it). Budget per study (the same for every filter): "
            + "; ".join(f"{t} trials x {r} train runs = {t * r} runs" for t, r in budgets)
            + f". Tuned at commit `{str(tuning.get('commit') or '?')[:12]}`. Objective: the mean of the train runs' "
            "ATE; a trial with a failed or diverged run scores as the worst. Every number below is on test data "
            "(docs/protocols.md, Tuning)."
        ),
        Bullets(tuple(splits)),
    )


def tuning_section(col: Collected) -> Section | None:
    """The section, or None when the results hold no tuned suite."""
    from locbench.run.tuning import read_tuning

    if col.store is None:
        return None
    tuning = read_tuning(col.store.root)
    studies = list(tuning.get("studies", []))
    if not studies:
        return None
    df = col.metrics
    sec = Section("Tuned against default (test data only)", "tuned")
    sec.add(*_intro(tuning, studies))
    rows: list[tuple[str, ...]] = []
    keys: list[tuple[float, ...]] = []
    per_world: dict[str, dict[str, tuple[float, float]]] = {}
    for g in group_effects(df, studies):
        mine = [s for s in studies if s["filter"] == g.filter and s["world"] == g.world]
        d_ate = 100.0 * float(np.nanmean(g.default_m)) if np.isfinite(g.default_m).any() else NAN
        t_ate = 100.0 * float(np.nanmean(g.tuned_m)) if np.isfinite(g.tuned_m).any() else NAN
        change = 100.0 * (t_ate / d_ate - 1.0) if d_ate > 0 and not math.isnan(t_ate) else NAN
        per_world.setdefault(g.world, {})[g.filter] = (d_ate, t_ate if not math.isnan(t_ate) else d_ate)
        test = g.test()
        kept = sum(1 for s in mine if s.get("default_kept"))
        rows.append(
            (
                f"`{g.filter}`",
                g.world,
                f"{tb.num(d_ate)} ({int(np.isfinite(g.default_m).sum())}/{g.default_m.size})",
                f"{tb.num(t_ate)} ({int(np.isfinite(g.tuned_m).sum())}/{g.tuned_m.size})",
                tb.num(change),
                _effects_text(g),
                test.text(),
                _tuned_spec(mine[0]) if len(mine) == 1 else f"default kept in {kept} of {len(mine)} folds",
            )
        )
        keys.append((NAN, NAN, d_ate, t_ate, change, NAN, test.p, NAN))
    sec.add(
        Table(
            (
                "filter",
                "data",
                "default ATE (cm)",
                "tuned ATE (cm)",
                "change (%)",
                "change per test unit (%)",
                "tuned against default, paired",
                "tuned spec",
            ),
            tuple(rows),
            caption="Tuned beside default on the test units: mean ATE, the change per unit, and the paired test "
            "across units",
            footnotes=(
                "Mean over the test units, ok runs / runs in brackets (a failed run has no ATE).",
                "A unit is a test seed of a world, or the held-out robot of a cross-validated recording. The paired "
                "test is Wilcoxon's signed-rank test of the tuned against the default ATE over the units, two-sided; "
                "with five robots no two-sided test can reach 5 % (the smallest exact p is 0.0625), so the per-robot "
                "changes are listed: a gain that rests on one robot shows as such.",
            ),
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
                if any(o["filter"] == s["filter"] for o in mine[:k]):
                    label = "_nolegend_"  # a cross-validated world: one line per fold, one legend entry per filter
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
