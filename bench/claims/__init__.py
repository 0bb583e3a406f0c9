"""Claims of the source reports that the report checks against the tidy metrics.

Each :class:`Claim` names the dataset id it concerns, its source report, the claim text, the report's
own numbers as text, and a check: a function from the tidy metrics rows of one dataset
(``dataset, filter, seed, metric, value``) to a :class:`ClaimResult` (verdict and measured values).
Filters are matched by id (the part of the name before ``[``): the plain ``id`` when it has runs,
otherwise the first parameterised variant in sorted order, named in the measured text.

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
from pathlib import Path
from typing import Literal, NamedTuple

import numpy as np
import pandas as pd

from locbench.metrics import mean_estimate_distance, waypoint_rmse

log = logging.getLogger(__name__)

Verdict = Literal["reproduced", "not reproduced", "not evaluated"]
VERDICTS: tuple[Verdict, ...] = ("reproduced", "not reproduced", "not evaluated")

_WP_RE = re.compile(r"^waypoint_(\d+)_(error_m|est_x_m|est_y_m|marked_x_m|marked_y_m)$")


class ClaimResult(NamedTuple):
    """The verdict of one claim and the measured values behind it, as text."""

    verdict: Verdict
    measured: str


@dataclass(frozen=True)
class Claim:
    """One checkable claim of a source report.

    Attributes
    ----------
    id : str
        Stable short name (``room_odometry_grows``).
    dataset : str
        Dataset id the claim concerns (``room``); it is checked on every stored variant of that id.
    source : str
        The source report's file name.
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
    source: str
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


# --- tidy-frame helpers -------------------------------------------------------------------------


def spec_id(name: str) -> str:
    """The id of a filter or dataset name: the part before ``[`` (``pf[particles=10]`` -> ``pf``)."""
    return name.split("[", 1)[0].strip()


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
    rows = []
    for (fname, j), g in wp.groupby(["filter", "waypoint"], sort=True):
        q = g.pivot_table(index="seed", columns="quantity", values="value", aggfunc="first")
        if "error_m" not in q:
            continue
        rmse = float(waypoint_rmse(q["error_m"].to_numpy()[:, None])[0])
        dist = float("nan")
        if {"est_x_m", "est_y_m", "marked_x_m", "marked_y_m"} <= set(q.columns):
            est = q[["est_x_m", "est_y_m"]].to_numpy()[:, None, :]
            marked = q[["marked_x_m", "marked_y_m"]].to_numpy()[:, None, :]
            dist = float(mean_estimate_distance(est, marked)[0])
        rows.append((str(fname), int(str(j)), rmse, dist, int(q["error_m"].notna().sum())))
    return pd.DataFrame(rows, columns=cols)


def series(ws: pd.DataFrame, filter_name: str, column: str) -> np.ndarray:
    """One filter's statistic over waypoints 1..m, in waypoint order."""
    sub = ws[ws["filter"] == filter_name].sort_values("waypoint")
    return sub[column].to_numpy(dtype=np.float64)


def fmt_cm(values: np.ndarray | tuple[float, ...]) -> str:
    return " / ".join(f"{100.0 * v:.1f}" for v in values)


# --- the registry: report modules in this package register their claims and report sections ------

SectionFn = Callable[[pd.DataFrame, Path, str], tuple[list[str], list[str]]]

_CLAIMS: list[Claim] = []
_SECTIONS: list[tuple[str, SectionFn, bool]] = []
_loaded = False


def register(*claims: Claim) -> None:
    """Add claims (called at import time by the ``report_NNN`` modules of this package)."""
    known = {c.id for c in _CLAIMS}
    for c in claims:
        if c.id in known:
            raise ValueError(f"claim id {c.id!r} registered twice")
        _CLAIMS.append(c)
        known.add(c.id)


def register_section(dataset_id: str, fn: SectionFn, across_variants: bool = False) -> None:
    """Add an extra report section for a dataset id.

    ``fn(rows, figdir, slug)`` gets the tidy metrics rows of one dataset name (with ``across_variants``:
    of every stored variant of the dataset id), the figures folder and a file-name slug; it writes its
    figures (named ``<slug>_*.png``) and returns the Markdown lines of its section (starting with a
    ``###`` heading) and the names of the figures it wrote.
    """
    _SECTIONS.append((dataset_id, fn, across_variants))


def _load() -> None:
    """Import every ``report_*`` module of this package once (they register on import)."""
    global _loaded
    if _loaded:
        return
    _loaded = True
    for mod in sorted(m.name for m in pkgutil.iter_modules(__path__) if m.name.startswith("report_")):
        importlib.import_module(f"{__name__}.{mod}")


def all_claims() -> tuple[Claim, ...]:
    """Every registered claim, in module then registration order."""
    _load()
    return tuple(_CLAIMS)


def claims_for(dataset_id: str, across_variants: bool = False) -> tuple[Claim, ...]:
    """The registered claims about a dataset id (per dataset name, or across its variants), in order."""
    return tuple(c for c in all_claims() if c.dataset == dataset_id and c.across_variants == across_variants)


def sections_for(dataset_id: str, across_variants: bool = False) -> tuple[SectionFn, ...]:
    """The extra report sections registered for a dataset id."""
    _load()
    return tuple(fn for ds, fn, av in _SECTIONS if ds == dataset_id and av == across_variants)
