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

import logging
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal, NamedTuple

import numpy as np
import pandas as pd
from scipy import stats

from locbench.metrics import mean_estimate_distance, waypoint_rmse

log = logging.getLogger(__name__)

Verdict = Literal["reproduced", "not reproduced", "not evaluated"]
VERDICTS: tuple[Verdict, ...] = ("reproduced", "not reproduced", "not evaluated")

SOURCE_003 = "003_e5c93f9be776ee5e.txt"

#: Report 003 table 1: distance between each waypoint and the mean estimated position over 20 runs, cm,
#: keyed by the locbench filter id.
ROOM_TABLE1_CM: dict[str, tuple[float, ...]] = {
    "odometry": (7.3634, 5.6828, 18.6643, 34.9313, 60.7425),
    "ekf_landmarks": (4.5655, 5.1575, 11.7987, 16.5151, 10.0205),
    "pf": (3.9186, 4.4614, 3.9726, 1.4753, 4.8919),
}

#: Calibration tolerance of the room world: odometry within this factor of table 1 at every waypoint.
CALIBRATION_FACTOR = 1.5
#: "Far below": the EKF/odometry RMSE ratio averaged over waypoints 3-5 is below this, each ratio below 1.
FAR_BELOW_MEAN_RATIO = 0.5
#: "Grows with distance": Spearman rank correlation of RMSE_j with j at least this, and last >= 2x first.
GROWTH_MIN_SPEARMAN = 0.8
GROWTH_MIN_LAST_OVER_FIRST = 2.0

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
        Tidy metrics rows of one dataset name -> :class:`ClaimResult`.
    """

    id: str
    dataset: str
    source: str
    text: str
    reported: str
    check: Callable[[pd.DataFrame], ClaimResult]

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


def _series(ws: pd.DataFrame, filter_name: str, column: str) -> np.ndarray:
    """One filter's statistic over waypoints 1..m, in waypoint order."""
    sub = ws[ws["filter"] == filter_name].sort_values("waypoint")
    return sub[column].to_numpy(dtype=np.float64)


def _cm(values: np.ndarray | tuple[float, ...]) -> str:
    return " / ".join(f"{100.0 * v:.1f}" for v in values)


def _ref_cm(values: tuple[float, ...]) -> str:
    return " / ".join(f"{v:.1f}" for v in values)


def _spearman(y: np.ndarray) -> float:
    """Spearman rank correlation between the order 1..n and ``y`` (NaN for a constant ``y``)."""
    r = stats.rankdata(y)
    if np.ptp(r) == 0:
        return float("nan")
    x = np.arange(1.0, y.size + 1.0)
    return float(np.corrcoef(x, r)[0, 1])


# --- room (report 003) --------------------------------------------------------------------------


def _check_odometry_grows(df: pd.DataFrame) -> ClaimResult:
    name = pick_filter(df, "odometry")
    if name is None:
        return ClaimResult("not evaluated", "no odometry runs")
    rmse = _series(waypoint_stats(df), name, "rmse_m")
    if rmse.size < 2:
        return ClaimResult("not evaluated", f"{name}: fewer than 2 waypoints")
    rho = _spearman(rmse)
    ratio = rmse[-1] / rmse[0] if rmse[0] > 0 else float("inf")
    ok = bool(rho >= GROWTH_MIN_SPEARMAN and ratio >= GROWTH_MIN_LAST_OVER_FIRST)
    text = f"{name} RMSE_j {_cm(rmse)} cm; Spearman rho {rho:.2f}; last/first {ratio:.1f}"
    return ClaimResult("reproduced" if ok else "not reproduced", text)


def _check_odometry_calibrated(df: pd.DataFrame) -> ClaimResult:
    name = pick_filter(df, "odometry")
    if name is None:
        return ClaimResult("not evaluated", "no odometry runs")
    ref = np.asarray(ROOM_TABLE1_CM["odometry"]) / 100.0
    dist = _series(waypoint_stats(df), name, "mean_distance_m")
    if dist.size != ref.size or np.any(np.isnan(dist)):
        return ClaimResult("not evaluated", f"{name}: {dist.size} waypoints with estimates, table 1 has {ref.size}")
    ratio = dist / ref
    ok = bool(np.all((ratio >= 1.0 / CALIBRATION_FACTOR) & (ratio <= CALIBRATION_FACTOR)))
    text = f"{name} distance of mean {_cm(dist)} cm; ratio to table 1 " + " / ".join(f"{r:.2f}" for r in ratio)
    return ClaimResult("reproduced" if ok else "not reproduced", text)


def _check_ekf_far_below(df: pd.DataFrame) -> ClaimResult:
    odo, ekf = pick_filter(df, "odometry"), pick_filter(df, "ekf_landmarks")
    if odo is None or ekf is None:
        return ClaimResult("not evaluated", f"missing runs of {'odometry' if odo is None else 'ekf_landmarks'}")
    ws = waypoint_stats(df)
    r_odo, r_ekf = _series(ws, odo, "rmse_m"), _series(ws, ekf, "rmse_m")
    if min(r_odo.size, r_ekf.size) < 5:
        return ClaimResult("not evaluated", "fewer than 5 waypoints")
    ratio = r_ekf[2:5] / r_odo[2:5]
    ok = bool(np.all(ratio < 1.0) and float(np.mean(ratio)) < FAR_BELOW_MEAN_RATIO)
    text = (
        f"RMSE_3..5 {ekf} {_cm(r_ekf[2:5])} cm vs {odo} {_cm(r_odo[2:5])} cm; ratio "
        + " / ".join(f"{r:.2f}" for r in ratio)
        + f" (mean {float(np.mean(ratio)):.2f})"
    )
    return ClaimResult("reproduced" if ok else "not reproduced", text)


def _check_pf_le_ekf(df: pd.DataFrame) -> ClaimResult:
    pf, ekf = pick_filter(df, "pf"), pick_filter(df, "ekf_landmarks")
    if pf is None or ekf is None:
        return ClaimResult("not evaluated", f"no {'pf' if pf is None else 'ekf_landmarks'} runs yet")
    ws = waypoint_stats(df)
    r_pf, r_ekf = _series(ws, pf, "rmse_m"), _series(ws, ekf, "rmse_m")
    if r_pf.size == 0 or r_pf.size != r_ekf.size:
        return ClaimResult("not evaluated", "waypoints differ between pf and ekf_landmarks runs")
    m_pf, m_ekf = float(np.mean(r_pf)), float(np.mean(r_ekf))
    text = f"mean RMSE_j {pf} {100 * m_pf:.1f} cm vs {ekf} {100 * m_ekf:.1f} cm"
    return ClaimResult("reproduced" if m_pf <= m_ekf else "not reproduced", text)


def _table1_ratio_text() -> str:
    ekf, odo = np.asarray(ROOM_TABLE1_CM["ekf_landmarks"]), np.asarray(ROOM_TABLE1_CM["odometry"])
    ratio = ekf[2:5] / odo[2:5]
    return (
        "table 1 ratio EKF/odometry at 3-5: "
        + " / ".join(f"{r:.2f}" for r in ratio)
        + f" (mean {float(np.mean(ratio)):.2f})"
    )


CLAIMS: tuple[Claim, ...] = (
    Claim(
        "room_odometry_grows",
        "room",
        SOURCE_003,
        "Odometry error grows with the distance travelled: Spearman rank correlation of odometry RMSE_j "
        f"with the waypoint order >= {GROWTH_MIN_SPEARMAN} and RMSE at the last waypoint >= "
        f"{GROWTH_MIN_LAST_OVER_FIRST:g}x the first (fig. 5).",
        f"table 1 odometry {_ref_cm(ROOM_TABLE1_CM['odometry'])} cm (rho 0.90, last/first 8.2)",
        _check_odometry_grows,
    ),
    Claim(
        "room_odometry_calibrated",
        "room",
        SOURCE_003,
        "World calibration: the odometry distance between each waypoint and the mean estimate is within a "
        f"factor {CALIBRATION_FACTOR:g} of table 1 at every waypoint.",
        f"table 1 odometry {_ref_cm(ROOM_TABLE1_CM['odometry'])} cm",
        _check_odometry_calibrated,
    ),
    Claim(
        "room_ekf_far_below_odometry",
        "room",
        SOURCE_003,
        "The EKF (ekf_landmarks) is far below odometry at waypoints 3-5: RMSE_j(EKF) / RMSE_j(odometry) < 1 at "
        f"each and < {FAR_BELOW_MEAN_RATIO:g} on average over the three.",
        _table1_ratio_text(),
        _check_ekf_far_below,
    ),
    Claim(
        "room_pf_le_ekf",
        "room",
        SOURCE_003,
        "The PF is at least as accurate as the EKF: mean over waypoints of RMSE_j(pf) <= that of ekf_landmarks.",
        f"table 1 PF {_ref_cm(ROOM_TABLE1_CM['pf'])} cm vs EKF {_ref_cm(ROOM_TABLE1_CM['ekf_landmarks'])} cm "
        f"(means {np.mean(ROOM_TABLE1_CM['pf']):.1f} vs {np.mean(ROOM_TABLE1_CM['ekf_landmarks']):.1f})",
        _check_pf_le_ekf,
    ),
)


def claims_for(dataset_id: str) -> tuple[Claim, ...]:
    """The registered claims about a dataset id, in registry order."""
    return tuple(c for c in CLAIMS if c.dataset == dataset_id)
