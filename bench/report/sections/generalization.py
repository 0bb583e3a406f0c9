"""The report's generalization table: each filter's ATE on tuning units against test units (docs/protocols.md,
"Splits").

A **unit** is what a split of :mod:`locbench.datasets.splits` assigns whole: a seed of a synthetic dataset (tuning
seeds from 1000), a robot of MRCLAM Dataset 6 (a test unit of
its default, whose noise was derived without it; of a tuned configuration, its study's held-out robot), a Radish site, a
libRSF set. Runs whose datasets differ only in the unit (``radish[site=aces]`` and ``radish[site=seattle]`` at the
same window and resolution) form one **family**; a family's row per filter configuration gives the mean over units of
the unit's mean ATE, on tuning units and on test units, their ratio (test over tuning: above 1, the configuration
does worse on data nothing was calibrated on), and on how many test units it did worse than dead reckoning (the
baseline, ``odometry``): a unit where the configuration's mean ATE exceeds the baseline's, or where its run failed
while the baseline's is ok (a unit it skipped, lacking a sensor or map, is not compared).

With a tuned suite stored (``<results>/tuning/tuned.json``), each study adds a row for the default and the tuned
configuration: the tuning side is the study's train objective (the mean train ATE of the default trial and of the best
trial; the train runs themselves are in a store the report does not read), the test side the test runs in the
results. Everything here is a function of hand-made rows (:func:`family_rows`, :func:`study_rows`), tested so.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from locbench.core.spec import Spec, format_spec, params_to_dict
from locbench.datasets.splits import LIBRSF_SPLIT, MRCLAM_DEFAULTS, RADISH_SPLIT, Split, is_tuning_seed
from locbench.evaluate.metrics import ATE_M, FAILED
from locbench.present.docfmt import num
from locbench.report.collect import Collected
from locbench.report.doc import Section, Table, Text

NAN = float("nan")
TUNING = "tuning"
TEST = "test"

#: Recorded datasets with a declared split: dataset id -> (the parameter that names the unit, its split, the
#: parameters the unit must have besides, e.g. MRCLAM's Dataset 6).
RECORDED_SPLITS: dict[str, tuple[str, Split, dict[str, Any]]] = {
    "mrclam": ("robot", MRCLAM_DEFAULTS, {"dataset": 6}),
    "radish": ("site", RADISH_SPLIT, {}),
    "librsf": ("set", LIBRSF_SPLIT, {}),
}


@dataclass(frozen=True)
class UnitOf:
    """Where one run falls: its family (the dataset name without the unit), the unit, and the unit's role."""

    family: str
    unit: str
    role: str


def recorded_unit(name: str, full: dict[str, Any]) -> UnitOf | None:
    """The unit of a recorded dataset ``name`` whose full parameters (defaults included) are ``full``; None when
    its dataset declares no split."""
    spec = Spec.parse(name)
    if spec.ident not in RECORDED_SPLITS:
        return None
    key, split, required = RECORDED_SPLITS[spec.ident]
    if key not in full or any(full.get(k) != v for k, v in required.items()):
        return None
    unit = full[key]
    family = format_spec(spec.ident, {k: v for k, v in spec.as_dict().items() if k != key})
    return UnitOf(family, f"{key} {unit}", split.role(unit))


def synthetic_unit(name: str, seed: int) -> UnitOf:
    """A synthetic dataset's unit is its seed: tuning from 1000, test below."""
    return UnitOf(name, f"seed {seed}", TUNING if is_tuning_seed(seed) else TEST)


def _full_params(name: str) -> dict[str, Any]:
    from locbench.registry import resolve_dataset

    try:
        return params_to_dict(resolve_dataset(name).params)
    except Exception:  # a dataset of a plug-in that is gone: no split
        return {}


def units_of(col: Collected) -> Callable[[str, int], UnitOf | None]:
    """The unit function of the collected datasets (recorded ones by their split, synthetic ones by seed)."""
    cache: dict[str, dict[str, Any] | None] = {}

    def of(dataset: str, seed: int) -> UnitOf | None:
        info = col.datasets.get(dataset)
        recorded = info.recorded if info is not None else False
        if not recorded:
            return synthetic_unit(dataset, seed)
        if dataset not in cache:
            cache[dataset] = _full_params(dataset)
        return recorded_unit(dataset, cache[dataset] or {})

    return of


@dataclass(frozen=True)
class GeneralizationRow:
    """One configuration on one family: mean ATE (m) over tuning and test units, and its test units worse than the
    baseline."""

    family: str
    filter: str
    kind: str
    tuning_ate_m: float
    tuning_units: int
    test_ate_m: float
    test_units: int
    worse_than_baseline: int
    compared_units: int

    @property
    def ratio(self) -> float:
        """Test over tuning ATE (NaN without both)."""
        if self.tuning_ate_m > 0 and math.isfinite(self.tuning_ate_m) and math.isfinite(self.test_ate_m):
            return self.test_ate_m / self.tuning_ate_m
        return NAN


def _unit_ates(df: pd.DataFrame, of: Callable[[str, int], UnitOf | None]) -> tuple[pd.DataFrame, set[tuple[str, ...]]]:
    """Per (family, role, unit, filter): the mean ATE over the unit's ok runs (m); and the (family, unit, filter)
    that have a run at all, ok or failed (a skipped run has no row)."""
    ran = df[(df["metric"] == ATE_M) | (df["metric"] == FAILED)]
    acc: dict[tuple[str, str, str, str], list[float]] = {}
    attempted: set[tuple[str, ...]] = set()
    units: dict[tuple[str, int], UnitOf | None] = {}
    cols = (ran["dataset"], ran["filter"], ran["seed"], ran["metric"], ran["value"])
    for dataset, filt, seed, metric, value in zip(*cols, strict=True):
        key = (str(dataset), int(seed))
        if key not in units:
            units[key] = of(*key)
        u = units[key]
        if u is None:
            continue
        attempted.add((u.family, u.unit, str(filt)))
        if metric == ATE_M and not math.isnan(float(value)):
            acc.setdefault((u.family, u.role, u.unit, str(filt)), []).append(float(value))
    rows = [(*k, float(np.mean(v))) for k, v in acc.items()]
    return pd.DataFrame(rows, columns=["family", "role", "unit", "filter", "ate"]), attempted


def _worse(
    per_unit: dict[str, float], baseline: dict[str, float], units: Sequence[str], ran: Callable[[str], bool]
) -> tuple[int, int]:
    """Test units where the configuration's ATE exceeds the baseline's or its run failed, over the units both ran
    (a skipped run is no comparison)."""
    compared = [u for u in units if u in baseline and (u in per_unit or ran(u))]
    worse = sum(1 for u in compared if u not in per_unit or per_unit[u] > baseline[u])
    return worse, len(compared)


def family_rows(
    df: pd.DataFrame,
    of: Callable[[str, int], UnitOf | None],
    baseline: str,
    keep: Callable[[str], bool] = lambda f: True,
) -> list[GeneralizationRow]:
    """Every configuration on every family that has tuning and test units: tuning against test ATE (module
    docstring).

    Parameters
    ----------
    df : DataFrame
        Tidy metrics (``dataset``, ``filter``, ``seed``, ``metric``, ``value``; ATE in m).
    of : callable
        (dataset, seed) -> its :class:`UnitOf`, None for a run outside every split.
    baseline : str
        The dead-reckoning configuration's name.
    keep : callable
        Which configurations get a row (the baseline's own row is kept, without a comparison).
    """
    per, attempted = _unit_ates(df, of)
    out: list[GeneralizationRow] = []
    for family, fam in per.groupby("family", sort=True):
        test_units = list(dict.fromkeys(fam.loc[fam["role"] == TEST, "unit"]))
        if not test_units or not (fam["role"] == TUNING).any():
            continue  # a family without both sides has no ratio (the main comparison holds test seeds only)
        base = fam[fam["filter"] == baseline]
        base_test = dict(
            zip(base.loc[base["role"] == TEST, "unit"], base.loc[base["role"] == TEST, "ate"], strict=True)
        )
        for filt, g in fam.groupby("filter", sort=False):
            if not keep(str(filt)) and filt != baseline:
                continue
            tune = g[g["role"] == TUNING]["ate"].to_numpy()
            test = g[g["role"] == TEST]
            per_unit = dict(zip(test["unit"], test["ate"], strict=True))
            ran = {u for (fam_, u, f_) in attempted if fam_ == family and f_ == filt}
            worse, compared = _worse(per_unit, base_test, test_units, ran.__contains__) if filt != baseline else (0, 0)
            out.append(
                GeneralizationRow(
                    str(family),
                    str(filt),
                    "baseline" if filt == baseline else "as run",
                    float(np.mean(tune)) if tune.size else NAN,
                    int(tune.size),
                    float(np.mean(test["ate"])) if len(test) else NAN,
                    len(test),
                    worse,
                    compared,
                )
            )
    return out


def study_rows(
    df: pd.DataFrame, studies: Sequence[dict[str, Any]], baseline: str, name_of: Callable[[str], str] = lambda d: d
) -> list[GeneralizationRow]:
    """The default and the tuned configuration of each tuned-suite study (objective ATE): train objective against
    the test runs' ATE, and the test units (dataset, seed) worse than the baseline.

    Parameters
    ----------
    df : DataFrame
        Tidy metrics.
    studies : sequence of dict
        ``tuned.json``'s studies (:func:`locbench.run.tuning.write_summary`).
    baseline : str
        The dead-reckoning configuration's name.
    name_of : callable
        A study's dataset spec -> its stored (canonical) dataset name.
    """
    ate = df[df["metric"] == ATE_M]
    failed = df[df["metric"] == FAILED]
    out: list[GeneralizationRow] = []
    for s in studies:
        if s.get("objective") != "ate" or not s.get("trials"):
            continue
        names = [name_of(d) for d in s["test"]]
        seeds = [int(x) for x in s["test_seeds"]]
        test = ate[ate["dataset"].isin(names) & ate["seed"].isin(seeds)]
        units = [(d, k) for d in names for k in seeds]

        def unit_means(filt: str, rows: pd.DataFrame = test) -> dict[tuple[str, int], float]:
            mine = rows[rows["filter"] == filt]
            acc: dict[tuple[str, int], list[float]] = {}
            for d, k, v in zip(mine["dataset"], mine["seed"], mine["value"], strict=True):
                if not math.isnan(float(v)):
                    acc.setdefault((str(d), int(k)), []).append(float(v))
            return {u: float(np.mean(v)) for u, v in acc.items()}

        base = unit_means(baseline)
        default_value = float(s["trials"][0]["value"])
        best = s.get("best_spec")
        pairs = [("default", str(s["filter"]), default_value)]
        if best:
            kind = "tuned (default kept)" if s.get("default_kept") else "tuned"
            pairs.append((kind, str(best), float(s.get("best_value", NAN))))
        for kind, filt, train in pairs:
            mine = unit_means(filt)
            mine_failed = failed[(failed["filter"] == filt) & failed["dataset"].isin(names)]
            ran = {str((str(d), int(k))) for d, k in zip(mine_failed["dataset"], mine_failed["seed"], strict=True)}
            worse, compared = _worse(
                {str(u): v for u, v in mine.items()},
                {str(u): v for u, v in base.items()},
                [str(u) for u in units],
                ran.__contains__,
            )
            out.append(
                GeneralizationRow(
                    f"{s['world']} (tuned suite)",
                    filt,
                    kind,
                    train if math.isfinite(train) else NAN,
                    len(s["train"]) * len(s["train_seeds"]),
                    float(np.mean(list(mine.values()))) if mine else NAN,
                    len(mine),
                    worse,
                    compared,
                )
            )
    return out


def _cm(x: float) -> str:
    return num(100.0 * x)


def generalization_table(rows: Sequence[GeneralizationRow]) -> Table:
    """The table of :class:`GeneralizationRow`, ATE in cm."""
    cells = tuple(
        (
            r.family,
            f"`{r.filter}`",
            r.kind,
            f"{_cm(r.tuning_ate_m)} ({r.tuning_units})",
            f"{_cm(r.test_ate_m)} ({r.test_units})",
            num(r.ratio),
            f"{r.worse_than_baseline}/{r.compared_units}" if r.kind != "baseline" else "-",
        )
        for r in rows
    )
    keys = tuple(
        (NAN, NAN, NAN, 100 * r.tuning_ate_m, 100 * r.test_ate_m, r.ratio, float(r.worse_than_baseline)) for r in rows
    )
    return Table(
        (
            "data",
            "configuration",
            "",
            "tuning ATE (cm, units)",
            "test ATE (cm, units)",
            "test / tuning",
            "worse than DR",
        ),
        cells,
        caption="Generalization: mean ATE on tuning units against test units",
        footnotes=(
            "Units: a seed of a synthetic dataset (tuning seeds from 1000), an MRCLAM robot (a test unit of "
            "its default, whose noise was derived without it; of a tuned row, its fold's held-out robot), a Radish "
            "site, a libRSF set (docs/protocols.md, Splits). ATE: the mean over units of each unit's "
            "mean over its ok runs. Worse than DR: test units where the mean ATE exceeds dead reckoning's or the run "
            "failed, over the test units both ran (a skipped run is not compared). Tuned-suite rows: the tuning side "
            "is the train objective (mean train ATE) over the train runs.",
        ),
        sort_keys=keys,
    )


def generalization_section(col: Collected) -> Section:
    """The section (empty when no family has both a configuration and test units)."""
    from locbench.registry import resolve_dataset
    from locbench.run.tuning import read_summary

    sec = Section("Generalization: tuning against test units", "generalization")
    df = col.metrics
    if not len(df):
        return sec
    names = list(dict.fromkeys(df["filter"]))
    baselines = [n for n in names if col.is_baseline(n)]
    baseline = baselines[0] if baselines else ""
    plain = {n for n in names if not col.is_bound(n) and not Spec.parse(n).params}
    rows = family_rows(df, units_of(col), baseline, keep=lambda f: f in plain)
    studies = read_summary(col.store.root) if col.store is not None else []
    rows += study_rows(df, studies, baseline, lambda d: resolve_dataset(d).name)
    if not rows:
        return sec
    sec.add(
        Text(
            "Every default was calibrated on tuning units only (MRCLAM's noise per held-out robot on the other four, "
            "the semi-synthetic Radish sites' encoder error on tuning sites, the synthetic odometry calibration on "
            "tuning seeds) and every tuned configuration was tuned on them. Here each configuration's ATE on the "
            "tuning units stands beside its ATE on the test units: a ratio well above 1 says it does worse on data "
            "nothing was fitted to; the last column counts the test units where it did worse than dead reckoning."
        ),
        generalization_table(rows),
    )
    return sec
