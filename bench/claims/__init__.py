"""Experiments, source reports and their claims, which the report reads through one registration hook.

The modules of this package register, at import:

- :class:`Source`: a source report, cited by title and authors;
- :class:`Experiment`: a dataset id with its title and role in the report (a summary dataset with an
  accuracy-runtime figure, a per-experiment section, variants folded into one table);
- :class:`Claim`: one checkable claim of a source report: a function from the tidy metrics rows
  (``dataset, filter, seed, metric, value``) of the experiment it concerns to a :class:`ClaimResult`;
- report sections (:func:`register_section`): extra tables and figures of an experiment, built as
  :mod:`locbench.report.doc` blocks.

The report itself knows no dataset or filter by name. Filters are matched by id: the plain ``id`` when
it has runs, otherwise the first parameterised variant in sorted order, named in the measured text.

Waypoint statistics here follow the DESIGN protocol: RMSE_j = sqrt(mean_i e_ij^2) over the ok runs
(report 003 fig. 5) and the distance between waypoint j and the mean estimated position over runs
(report 003 table 1).
"""

from __future__ import annotations

import importlib
import logging
import pkgutil
import re
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING, Literal, NamedTuple

import numpy as np
import pandas as pd

from locbench.metrics import mean_estimate_distance, waypoint_rmse
from locbench.significance import ALPHA, TestResult
from locbench.spec import Spec

if TYPE_CHECKING:
    from locbench.report.doc import Block

log = logging.getLogger(__name__)

Verdict = Literal["reproduced", "not reproduced", "not evaluated"]
VERDICTS: tuple[Verdict, ...] = ("reproduced", "not reproduced", "not evaluated")

_WP_RE = re.compile(r"^waypoint_(\d+)_(error_m|est_x_m|est_y_m|marked_x_m|marked_y_m)$")


class ClaimResult(NamedTuple):
    """The verdict of one claim and the measured values behind it, as text; a claim that compares two filters
    or settings also names its test, the number of runs and the p-value (``test``, see :func:`test_text`)."""

    verdict: Verdict
    measured: str
    test: str = ""


@dataclass(frozen=True)
class Source:
    """A source report, cited by its title and authors as printed at its head."""

    key: str
    title: str
    authors: str

    @property
    def citation(self) -> str:
        return f"*{self.title}* ({self.authors})"


@dataclass(frozen=True)
class Experiment:
    """A dataset id's place in the report.

    Attributes
    ----------
    dataset : str
        The dataset id (``office``); its plain name is the experiment's base dataset.
    title : str
        Section heading.
    text : str
        One paragraph: what the experiment tests.
    source : Source or None
        The source report whose experiment it replays.
    summary : bool
        The experiment is a main comparison: a summary table and an accuracy-runtime figure.
    fold_variants : bool
        Its variants are shown folded (by its registered sections) instead of one table each.
    order : int
        Position among the experiment sections (and summary tables), ascending.
    """

    dataset: str
    title: str
    text: str = ""
    source: Source | None = None
    summary: bool = False
    fold_variants: bool = False
    order: int = 100


@dataclass(frozen=True)
class Claim:
    """One checkable claim of a source report.

    Attributes
    ----------
    id : str
        Stable short name (``room_odometry_grows``).
    dataset : str
        Dataset id the claim concerns (``room``): checked on the rows of its plain name, or with
        ``across_variants`` on the rows of every stored variant of that id.
    source : Source
        The source report.
    text : str
        The claim, with the concrete test we apply.
    reported : str
        The report's own numbers behind the claim.
    check : callable
        Tidy metrics rows of one dataset name -> :class:`ClaimResult`; with ``across_variants`` the rows
        of every stored variant of the dataset id (``scan_grid`` and ``scan_grid[mixed_commands=true]``).
    across_variants : bool
        Evaluated once over all variants of the dataset id (a sweep over a dataset parameter, recovery
        against kidnap distance) instead of once per dataset name.
    """

    id: str
    dataset: str
    source: Source
    text: str
    reported: str
    check: Callable[[pd.DataFrame], ClaimResult]
    across_variants: bool = False

    def evaluate(self, df: pd.DataFrame) -> ClaimResult:
        """Run the check; a check that cannot run (missing data) is "not evaluated", never an exception."""
        try:
            return self.check(df)
        except (KeyError, ValueError, IndexError) as exc:
            log.warning("claim %s could not be evaluated: %s", self.id, exc)
            return ClaimResult("not evaluated", f"could not be evaluated: {exc}")


# --- the rule for claims that compare two filters or settings (docs/protocols.md "Claims") ---------------


def no_worse(test: TestResult) -> Verdict:
    """ "A is no worse than B": reproduced when the one-sided test does not find B better at 5 %."""
    if not test.tested:
        return "not evaluated"
    return "reproduced" if not test.p < ALPHA else "not reproduced"


def found(test: TestResult) -> Verdict:
    """ "A differs from (is better than) B": reproduced only when the test finds it at 5 %."""
    if not test.tested:
        return "not evaluated"
    return "reproduced" if test.p < ALPHA else "not reproduced"


def all_found(tests: list[TestResult]) -> Verdict:
    """Several differences claimed together: each must be found at 5 % (an intersection-union test, which
    needs no correction for the number of parts)."""
    if not tests or not all(t.tested for t in tests):
        return "not evaluated"
    return "reproduced" if all(t.p < ALPHA for t in tests) else "not reproduced"


def test_text(*tests: TestResult) -> str:
    """The tests behind a verdict as the claims table prints them."""
    return "; ".join(t.text() for t in tests)


def paired(df: pd.DataFrame, filter_a: str, filter_b: str, metric: str) -> tuple[np.ndarray, np.ndarray]:
    """The values of one metric of two filters on the seeds both have, in seed order (paired by construction)."""
    sel = df[df["metric"] == metric]
    a = sel[sel["filter"] == filter_a].groupby("seed")["value"].first()
    b = sel[sel["filter"] == filter_b].groupby("seed")["value"].first()
    seeds = a.index.intersection(b.index).sort_values()
    return a.loc[seeds].to_numpy(dtype=np.float64), b.loc[seeds].to_numpy(dtype=np.float64)


def per_seed_mean(df: pd.DataFrame, filter_name: str, pattern: str) -> pd.Series:
    """seed -> the mean of a filter's metrics whose id matches ``pattern`` (a run's mean waypoint error)."""
    sel = df[(df["filter"] == filter_name) & df["metric"].astype(str).str.match(pattern)]
    return sel.groupby("seed")["value"].mean()


# --- tidy-frame helpers -------------------------------------------------------------------------


@lru_cache(maxsize=4096)
def spec_of(name: str) -> Spec:
    """The typed :class:`~locbench.spec.Spec` of a stored filter or dataset name, parsed once per name."""
    return Spec.parse(name)


def spec_id(name: str) -> str:
    """The id of a filter or dataset name (``pf[particles=10]`` -> ``pf``)."""
    return spec_of(name).ident


def pick_filter(df: pd.DataFrame, filter_id: str) -> str | None:
    """The filter name in ``df`` to use for an id: the plain id if present, else the first variant sorted."""
    names = sorted({str(f) for f in df["filter"].unique() if spec_id(str(f)) == filter_id})
    if not names:
        return None
    return filter_id if filter_id in names else names[0]


def waypoint_stats(df: pd.DataFrame) -> pd.DataFrame:
    """Per filter and waypoint statistics over the ok runs of one dataset name.

    Parameters
    ----------
    df : DataFrame
        Tidy metrics rows (``dataset, filter, seed, metric, value``) of a single dataset name.

    Returns
    -------
    DataFrame
        Columns ``filter``, ``waypoint`` (int, from 1), ``rmse_m`` (RMSE_j), ``mean_distance_m``
        (distance between the marked point and the mean estimate; NaN when the CSV lacks the
        estimate columns) and ``runs`` (how many runs entered), sorted by filter then waypoint.
    """
    cols = ["filter", "waypoint", "rmse_m", "mean_distance_m", "runs"]
    parts = df["metric"].astype(str).str.extract(_WP_RE)
    sel = parts[0].notna()
    if not sel.any():
        return pd.DataFrame(columns=cols)
    wp = df.loc[sel, ["filter", "seed", "value"]].copy()
    wp["waypoint"] = parts.loc[sel, 0].astype(int)
    wp["quantity"] = parts.loc[sel, 1]
    # one table (filter, waypoint, seed) x quantity for every group at once: a pivot per group was most of the
    # report's table time; each group's block is then what its own pivot gave (first non-missing value, the
    # rows and columns with no value dropped), so the statistics come out bit for bit the same
    table = wp.groupby(["filter", "waypoint", "seed", "quantity"], sort=True)["value"].first().unstack("quantity")
    quantities = [str(c) for c in table.columns]
    values = table.to_numpy(dtype=np.float64)
    keys = [k[:2] for k in table.index.to_list()]  # (filter, waypoint) of each row
    rows = []
    start = 0
    while start < len(keys):
        stop = start
        while stop < len(keys) and keys[stop] == keys[start]:
            stop += 1
        fname, j = keys[start]
        block = values[start:stop]
        start = stop
        has_col = ~np.all(np.isnan(block), axis=0)
        block = block[:, has_col]
        block = block[~np.all(np.isnan(block), axis=1)]
        q = {c: block[:, k] for k, c in enumerate(c for c, h in zip(quantities, has_col, strict=True) if h)}
        if "error_m" not in q:
            continue
        rmse = float(waypoint_rmse(q["error_m"][:, None])[0])
        dist = float("nan")
        if {"est_x_m", "est_y_m", "marked_x_m", "marked_y_m"} <= q.keys():
            est = np.column_stack([q["est_x_m"], q["est_y_m"]])[:, None, :]
            marked = np.column_stack([q["marked_x_m"], q["marked_y_m"]])[:, None, :]
            dist = float(mean_estimate_distance(est, marked)[0])
        rows.append((str(fname), int(str(j)), rmse, dist, int(np.count_nonzero(~np.isnan(q["error_m"])))))
    return pd.DataFrame(rows, columns=cols)


def series(ws: pd.DataFrame, filter_name: str, column: str) -> np.ndarray:
    """One filter's statistic over waypoints 1..m, in waypoint order."""
    sub = ws[ws["filter"] == filter_name].sort_values("waypoint")
    return sub[column].to_numpy(dtype=np.float64)


def fmt_cm(values: np.ndarray | tuple[float, ...]) -> str:
    return " / ".join(f"{100.0 * v:.1f}" for v in values)


# --- the registry: report modules in this package register their claims and report sections ------

SectionFn = Callable[[pd.DataFrame, str], "list[Block]"]

_CLAIMS: list[Claim] = []
_SECTIONS: list[tuple[str, SectionFn]] = []
_EXPERIMENTS_BY_DATASET: dict[str, Experiment] = {}
_loaded = False


def register_experiment(experiment: Experiment) -> None:
    """Add an experiment (one per dataset id)."""
    if experiment.dataset in _EXPERIMENTS_BY_DATASET:
        raise ValueError(f"experiment {experiment.dataset!r} registered twice")
    _EXPERIMENTS_BY_DATASET[experiment.dataset] = experiment


def experiments() -> tuple[Experiment, ...]:
    """Every registered experiment, by ``order`` then dataset id."""
    _load()
    return tuple(sorted(_EXPERIMENTS_BY_DATASET.values(), key=lambda e: (e.order, e.dataset)))


def experiment_of(dataset_id: str) -> Experiment | None:
    """The experiment registered for a dataset id, if any."""
    _load()
    return _EXPERIMENTS_BY_DATASET.get(dataset_id)


def register(*claims: Claim) -> None:
    """Add claims (called at import time by the ``report_NNN`` modules of this package)."""
    known = {c.id for c in _CLAIMS}
    for c in claims:
        if c.id in known:
            raise ValueError(f"claim id {c.id!r} registered twice")
        _CLAIMS.append(c)
        known.add(c.id)


def register_section(dataset_id: str, fn: SectionFn) -> None:
    """Add an extra block of an experiment's report section.

    ``fn(rows, slug)`` gets the tidy metrics rows of every stored variant of the dataset id and a
    file-name slug for its figures (``<slug>_*``) and returns :mod:`locbench.report.doc` blocks (text,
    tables, plots); it does no I/O.
    """
    _SECTIONS.append((dataset_id, fn))


def _load() -> None:
    """Import every ``report_*`` module of this package once (they register on import)."""
    global _loaded
    if _loaded:
        return
    _loaded = True
    for mod in sorted(m.name for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_")):
        importlib.import_module(f"{__name__}.{mod}")


def all_claims() -> tuple[Claim, ...]:
    """Every registered claim, in module then registration order."""
    _load()
    return tuple(_CLAIMS)


def claims_for(dataset_id: str, across_variants: bool = False) -> tuple[Claim, ...]:
    """The registered claims about a dataset id (per dataset name, or across its variants), in order."""
    return tuple(c for c in all_claims() if c.dataset == dataset_id and c.across_variants == across_variants)


def sections_for(dataset_id: str) -> tuple[SectionFn, ...]:
    """The extra report sections registered for a dataset id."""
    _load()
    return tuple(fn for ds, fn in _SECTIONS if ds == dataset_id)
