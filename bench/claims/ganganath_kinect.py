"""Claims of report 003 (Ganganath and Leung, odometry + Kinect landmarks, EKF and PF) on ``room``."""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats

from locbench.claims import (
    Claim,
    ClaimResult,
    Experiment,
    Source,
    fmt_cm,
    found,
    no_worse,
    per_seed_mean,
    pick_filter,
    register,
    register_experiment,
    register_section,
    series,
    test_text,
)
from locbench.evaluate.aggregate import waypoint_stats
from locbench.evaluate.metrics import METRICS, WAYPOINT_ERROR_M, family_regex, member_id
from locbench.evaluate.significance import wilcoxon_paired
from locbench.present import ranking as rk
from locbench.present.docfmt import Block, Text
from locbench.suites import SUITES

SOURCE_003 = Source(
    "003",
    "Mobile robot localization using odometry and Kinect sensor",
    "N. Ganganath and H. Leung",
)

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
#: A run's waypoint errors (all waypoints; waypoints 3-5), the per-run values the paired tests compare.
WAYPOINT_ERRORS = f"^{family_regex(WAYPOINT_ERROR_M)}$"
WAYPOINTS_3_5 = "^(" + "|".join(member_id(WAYPOINT_ERROR_M, j) for j in (3, 4, 5)) + ")$"


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
    rmse = series(waypoint_stats(df), name, "rmse_m")
    if rmse.size < 2:
        return ClaimResult("not evaluated", f"{name}: fewer than 2 waypoints")
    rho = _spearman(rmse)
    ratio = rmse[-1] / rmse[0] if rmse[0] > 0 else float("inf")
    ok = bool(rho >= GROWTH_MIN_SPEARMAN and ratio >= GROWTH_MIN_LAST_OVER_FIRST)
    text = f"{name} RMSE_j {fmt_cm(rmse)} cm; Spearman rho {rho:.2f}; last/first {ratio:.1f}"
    return ClaimResult("reproduced" if ok else "not reproduced", text)


def _check_odometry_calibrated(df: pd.DataFrame) -> ClaimResult:
    name = pick_filter(df, "odometry")
    if name is None:
        return ClaimResult("not evaluated", "no odometry runs")
    ref = np.asarray(ROOM_TABLE1_CM["odometry"]) / 100.0
    dist = series(waypoint_stats(df), name, "mean_distance_m")
    if dist.size != ref.size or np.any(np.isnan(dist)):
        return ClaimResult("not evaluated", f"{name}: {dist.size} waypoints with estimates, table 1 has {ref.size}")
    ratio = dist / ref
    ok = bool(np.all((ratio >= 1.0 / CALIBRATION_FACTOR) & (ratio <= CALIBRATION_FACTOR)))
    text = f"{name} distance of mean {fmt_cm(dist)} cm; ratio to table 1 " + " / ".join(f"{r:.2f}" for r in ratio)
    return ClaimResult("reproduced" if ok else "not reproduced", text)


def _check_ekf_far_below(df: pd.DataFrame) -> ClaimResult:
    odo, ekf = pick_filter(df, "odometry"), pick_filter(df, "ekf_landmarks")
    if odo is None or ekf is None:
        return ClaimResult("not evaluated", f"missing runs of {'odometry' if odo is None else 'ekf_landmarks'}")
    ws = waypoint_stats(df)
    r_odo, r_ekf = series(ws, odo, "rmse_m"), series(ws, ekf, "rmse_m")
    if min(r_odo.size, r_ekf.size) < 5:
        return ClaimResult("not evaluated", "fewer than 5 waypoints")
    ratio = r_ekf[2:5] / r_odo[2:5]
    ok = bool(np.all(ratio < 1.0) and float(np.mean(ratio)) < FAR_BELOW_MEAN_RATIO)
    text = (
        f"RMSE_3..5 {ekf} {fmt_cm(r_ekf[2:5])} cm vs {odo} {fmt_cm(r_odo[2:5])} cm; ratio "
        + " / ".join(f"{r:.2f}" for r in ratio)
        + f" (mean {float(np.mean(ratio)):.2f})"
    )
    # the difference must also be found: each run's mean error at waypoints 3-5, EKF below odometry
    e3, o3 = per_seed_mean(df, ekf, WAYPOINTS_3_5), per_seed_mean(df, odo, WAYPOINTS_3_5)
    seeds = e3.index.intersection(o3.index).sort_values()
    test = wilcoxon_paired(e3.loc[seeds].to_numpy(), o3.loc[seeds].to_numpy(), alternative="less")
    verdict = found(test) if ok else "not reproduced"
    return ClaimResult(verdict, text, "one-sided " + test_text(test))


def _check_pf_le_ekf(df: pd.DataFrame) -> ClaimResult:
    pf, ekf = pick_filter(df, "pf"), pick_filter(df, "ekf_landmarks")
    if pf is None or ekf is None:
        return ClaimResult("not evaluated", f"no {'pf' if pf is None else 'ekf_landmarks'} runs yet")
    ws = waypoint_stats(df)
    r_pf, r_ekf = series(ws, pf, "rmse_m"), series(ws, ekf, "rmse_m")
    if r_pf.size == 0 or r_pf.size != r_ekf.size:
        return ClaimResult("not evaluated", "waypoints differ between pf and ekf_landmarks runs")
    m_pf, m_ekf = float(np.mean(r_pf)), float(np.mean(r_ekf))
    # no worse: the one-sided test over the seeds does not find the EKF's mean waypoint error lower
    e_pf, e_ekf = per_seed_mean(df, pf, WAYPOINT_ERRORS), per_seed_mean(df, ekf, WAYPOINT_ERRORS)
    seeds = e_pf.index.intersection(e_ekf.index).sort_values()
    a, b = e_pf.loc[seeds].to_numpy(), e_ekf.loc[seeds].to_numpy()
    test = wilcoxon_paired(a, b, alternative="greater")
    text = (
        f"mean RMSE_j {pf} {100 * m_pf:.1f} cm vs {ekf} {100 * m_ekf:.1f} cm; per-run mean waypoint error "
        f"{pf} minus {ekf}: median {100 * float(np.median(a - b)):+.2f} cm"
    )
    return ClaimResult(no_worse(test), text, "one-sided " + test_text(test))


def _table1_ratio_text() -> str:
    ekf, odo = np.asarray(ROOM_TABLE1_CM["ekf_landmarks"]), np.asarray(ROOM_TABLE1_CM["odometry"])
    ratio = ekf[2:5] / odo[2:5]
    return (
        "table 1 ratio EKF/odometry at 3-5: "
        + " / ".join(f"{r:.2f}" for r in ratio)
        + f" (mean {float(np.mean(ratio)):.2f})"
    )


register(
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
        f"each and < {FAR_BELOW_MEAN_RATIO:g} on average over the three, and a one-sided Wilcoxon signed-rank test "
        "over the seeds finds each run's mean error at waypoints 3-5 lower for the EKF at 5 %.",
        _table1_ratio_text(),
        _check_ekf_far_below,
    ),
    Claim(
        "room_pf_le_ekf",
        "room",
        SOURCE_003,
        "The PF is at least as accurate as the EKF (no worse): a one-sided Wilcoxon signed-rank test over the "
        "seeds does not find ekf_landmarks' per-run mean waypoint error lower than pf's at 5 %.",
        f"table 1 PF {_ref_cm(ROOM_TABLE1_CM['pf'])} cm vs EKF {_ref_cm(ROOM_TABLE1_CM['ekf_landmarks'])} cm "
        f"(means {np.mean(ROOM_TABLE1_CM['pf']):.1f} vs {np.mean(ROOM_TABLE1_CM['ekf_landmarks']):.1f})",
        _check_pf_le_ekf,
    ),
)


def _table1_section(rows: pd.DataFrame, slug: str) -> list[Block]:
    """Report 003 table 1 beside the measured distance of the mean estimate, on the plain ``room``."""
    base = rows[rows["dataset"] == "room"]
    ws = waypoint_stats(base)
    if not len(ws):
        return []

    n_wp = int(ws["waypoint"].max())
    out: list[tuple[str, ...]] = []
    keys: list[tuple[float, ...]] = []
    names: list[str | None] = []
    for fid, ref in ROOM_TABLE1_CM.items():
        name = pick_filter(base, fid)
        measured = series(ws, name, "mean_distance_m") if name is not None else np.zeros(0)
        out.append((f"`{name or fid}` (measured)", *(f"{100.0 * v:.1f}" for v in measured[:n_wp])))
        keys.append((np.nan, *(float(v) for v in measured[:n_wp])))
        names.append(name)
        out.append((f"`{fid}` (003 table 1)", *(f"{v:.1f}" for v in ref)))
        keys.append(())
        names.append(None)
    header = ("filter", *(str(j) for j in range(1, n_wp + 1)))
    width = len(header)
    # each run's error at waypoint j: the per-run value behind the column (a distance of the mean over runs)
    shown = [n for n in names if n is not None]
    columns = []
    for j in range(1, n_wp + 1):
        per = dict(zip(shown, rk.samples_for(base, shown, member_id(WAYPOINT_ERROR_M, j)), strict=True))
        columns.append(rk.Column(j, METRICS[WAYPOINT_ERROR_M], [per[n] if n is not None else None for n in names]))
    flags = rk.eligible_names(shown)
    eligible = [n is not None and flags[shown.index(n)] for n in names]
    return [
        Text(
            "Distance between each waypoint and the mean estimated position over the runs (cm), as report 003's "
            "table 1 measures it, beside the report's values."
        ),
        rk.marked_table(
            header,
            [r + ("",) * (width - len(r)) for r in out],
            [k + (np.nan,) * (width - len(k)) for k in keys],
            columns,
            eligible,
            caption="room: report 003 table 1",
            labels=[n or "" for n in names],
            footnotes=(
                "Measured rows are ranked by the distance shown and tested over each run's error at the "
                "waypoint; the report's rows are not ranked.",
            ),
        ),
    ]


register_section("room", _table1_section)
register_experiment(
    Experiment(
        "room",
        "Room (report 003)",
        "Report 003's experiment: a 7 m x 2 m room with 4 wall landmarks seen by a Kinect-like sensor "
        "(0.8-3.5 m, 57 deg), a start and 5 marked waypoints, 20 runs.",
        source=SOURCE_003,
        summary=True,
        order=10,
        suite=SUITES["room"],
    )
)
