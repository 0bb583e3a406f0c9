"""Claims of report 000 (EKF-based localization with LRF: EKF-ICP on an office lap) on ``lap``.

Report 000 sec. IV: after one rectangular lap odometry ends about 15 cm from the start and the EKF-ICP
about 2.5 cm; people walking around did not affect the EKF; kidnap recovery (sec. IV-B) worked only when
the robot was not moved far from its last estimate. "About" a reported distance means within a factor
``ABOUT_FACTOR`` (1.5) of it. For the EKF's 2.5 cm we ask a median ``final_error_m`` over seeds of at
most 5 cm (twice the reported value, the laser's and grid's resolution). The end-of-lap claims are
evaluated on the plain ``lap`` (with people, without a kidnap).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from locbench.claims import (
    Claim,
    ClaimResult,
    Experiment,
    Source,
    Verdict,
    found,
    no_worse,
    pick_filter,
    register,
    register_experiment,
    spec_id,
    spec_of,
    test_text,
)
from locbench.core.errors import ConfigError
from locbench.evaluate.metrics import ATE_M, FAILED, FINAL_ERROR_M, KIDNAP_RECOVERED
from locbench.evaluate.significance import TestResult, fisher_rates, mann_whitney
from locbench.suites import SUITES

SOURCE_000 = Source(
    "000",
    "EKF-based localization with LRF",
    "Gonçalo Castilho, Tiago Gomes, Pedro Sousa and Markus Kühlen",
)

#: Report 000 sec. IV: odometry's and the EKF's distance from the start after one lap, m.
REPORTED_ODOMETRY_FINAL_M = 0.15
REPORTED_EKF_FINAL_M = 0.025
#: "About" = within this factor of the reported value (either way).
ABOUT_FACTOR = 1.5
#: The EKF's bar: median final error over seeds at most this, m (twice the reported 2.5 cm).
EKF_FINAL_BAR_M = 2 * REPORTED_EKF_FINAL_M
#: Kidnap recovery rate separating "recovers" from "does not" at a kidnap distance.
RECOVERY_RATE_BAR = 0.5
#: ``people`` of ``lap`` when its name does not set it (LapParams.people).
DEFAULT_PEOPLE = 4


def _params(name: str) -> dict[str, str]:
    try:
        return spec_of(name).as_dict()
    except ConfigError:
        return {}


def _kidnap_m(name: str) -> float:
    return float(_params(name).get("kidnap_m", "0"))


def _people(name: str) -> int:
    return int(float(_params(name).get("people", str(DEFAULT_PEOPLE))))


def _values(df: pd.DataFrame, filter_name: str, metric: str) -> np.ndarray:
    sel = (df["filter"] == filter_name) & (df["metric"] == metric)
    v = df.loc[sel, "value"].to_numpy(dtype=np.float64)
    return v[~np.isnan(v)]


def _no_kidnap(df: pd.DataFrame) -> str | None:
    """Why the end-of-lap claims do not apply to this dataset name, or None when they do."""
    names = sorted({str(d) for d in df["dataset"].unique()})
    if any(_kidnap_m(n) > 0 for n in names):
        return "a kidnap variant (the end-of-lap claims are checked without a kidnap)"
    return None


def _check_odometry_final(df: pd.DataFrame) -> ClaimResult:
    why = _no_kidnap(df)
    if why:
        return ClaimResult("not evaluated", why)
    name = pick_filter(df, "odometry")
    if name is None:
        return ClaimResult("not evaluated", "no odometry runs")
    fin = _values(df, name, FINAL_ERROR_M)
    if fin.size == 0:
        return ClaimResult("not evaluated", f"{name}: no final_error_m")
    med = float(np.median(fin))
    lo, hi = REPORTED_ODOMETRY_FINAL_M / ABOUT_FACTOR, REPORTED_ODOMETRY_FINAL_M * ABOUT_FACTOR
    text = (
        f"{name} median final error {100 * med:.1f} cm over {fin.size} seeds "
        f"(range {100 * fin.min():.1f}-{100 * fin.max():.1f} cm; bar {100 * lo:.0f}-{100 * hi:.1f} cm)"
    )
    return ClaimResult("reproduced" if lo <= med <= hi else "not reproduced", text)


def _check_ekf_final(df: pd.DataFrame) -> ClaimResult:
    why = _no_kidnap(df)
    if why:
        return ClaimResult("not evaluated", why)
    name = pick_filter(df, "ekf_icp")
    if name is None:
        return ClaimResult("not evaluated", "no ekf_icp runs")
    fin = _values(df, name, FINAL_ERROR_M)
    failed = _values(df, name, FAILED)
    n_failed = int(np.sum(failed > 0.5))
    if fin.size == 0:
        return ClaimResult("not evaluated", f"{name}: no final_error_m ({n_failed} failed runs)")
    med = float(np.median(fin))
    text = (
        f"{name} median final error {100 * med:.1f} cm over {fin.size} seeds "
        f"(range {100 * fin.min():.1f}-{100 * fin.max():.1f} cm), {n_failed} failed"
    )
    odo = pick_filter(df, "odometry")
    if odo is not None and _values(df, odo, FINAL_ERROR_M).size:
        text += f"; {odo} {100 * float(np.median(_values(df, odo, FINAL_ERROR_M))):.1f} cm"
    ok = med <= EKF_FINAL_BAR_M and n_failed == 0
    return ClaimResult("reproduced" if ok else "not reproduced", text)


def _check_people(df: pd.DataFrame) -> ClaimResult:
    names = sorted({str(d) for d in df["dataset"].unique() if _kidnap_m(str(d)) == 0})
    with_people = [n for n in names if _people(n) > 0]
    without = [n for n in names if _people(n) == 0]
    if not with_people:
        return ClaimResult("not evaluated", "no lap runs with people")
    parts: list[str] = []
    ok = True
    base = np.zeros(0)
    if without:
        sub0 = df[df["dataset"] == without[0]]
        f0 = pick_filter(sub0, "ekf_icp")
        if f0 is not None:
            base = _values(sub0, f0, ATE_M)
    tests: list[TestResult] = []
    evaluated = False
    for n in with_people:
        sub = df[df["dataset"] == n]
        f = pick_filter(sub, "ekf_icp")
        if f is None:
            continue
        evaluated = True
        failed = int(np.sum(_values(sub, f, FAILED) > 0.5))
        runs = _values(sub, f, FAILED).size
        ate = _values(sub, f, ATE_M)
        med = float(np.median(ate)) if ate.size else float("nan")
        text = f"`{n}` {f}: {failed}/{runs} failed, median ATE {100 * med:.1f} cm"
        ok = ok and failed == 0 and ate.size > 0
        if base.size:
            b_med = float(np.median(base))
            text += f" vs {100 * b_med:.1f} cm without people (ratio {med / b_med if b_med > 0 else float('inf'):.2f})"
            # different realisations (people change the data): an unpaired one-sided test of "worse with people"
            tests.append(mann_whitney(ate, base, alternative="greater"))
        parts.append(text)
    if not evaluated:
        return ClaimResult("not evaluated", "no ekf_icp runs on lap with people")
    if not base.size:
        parts.append("no lap[people=0] runs: ATE comparison not evaluated")
        return ClaimResult("not evaluated" if ok else "not reproduced", "; ".join(parts))
    verdicts = [no_worse(t) for t in tests]
    verdict: Verdict = (
        "not evaluated"
        if "not evaluated" in verdicts
        else ("reproduced" if ok and all(v == "reproduced" for v in verdicts) else "not reproduced")
    )
    return ClaimResult(verdict, "; ".join(parts), "one-sided " + test_text(*tests))


def _check_kidnap(df: pd.DataFrame) -> ClaimResult:
    rec = df[(df["metric"] == KIDNAP_RECOVERED) & df["filter"].map(lambda f: spec_id(str(f)) == "ekf_icp")]
    if rec.empty:
        return ClaimResult("not evaluated", "no kidnap_recovered rows for ekf_icp on lap[kidnap_m=D]")
    rates: list[tuple[float, float, int]] = []
    for n, g in rec.groupby("dataset"):
        d = _kidnap_m(str(n))
        if d > 0:
            rates.append((d, float(np.mean(g["value"].to_numpy(dtype=np.float64) > 0.5)), len(g)))
    rates.sort()
    text = "recovery rate " + ", ".join(f"D={d:g} m: {r:.2f} ({k} runs)" for d, r, k in rates)
    if len({d for d, _, _ in rates}) < 2:
        return ClaimResult("not evaluated", text + "; needs at least two kidnap distances")
    ok = rates[0][1] >= RECOVERY_RATE_BAR and rates[-1][1] < RECOVERY_RATE_BAR
    # the difference between the smallest and the largest kidnap must be found (independent runs)
    (_, r0, n0), (_, r1, n1) = rates[0], rates[-1]
    test = fisher_rates(round(r0 * n0), n0, round(r1 * n1), n1, alternative="greater")
    verdict = found(test) if ok else "not reproduced"
    return ClaimResult(verdict, text, "one-sided " + test_text(test))


register(
    Claim(
        "lap_odometry_15cm",
        "lap",
        SOURCE_000,
        f"World calibration: odometry ends about 15 cm from the start after one lap (median final_error_m over "
        f"seeds within a factor {ABOUT_FACTOR:g} of 15 cm).",
        "odometry about 15 cm from the start (sec. IV, fig. 5)",
        _check_odometry_final,
    ),
    Claim(
        "lap_ekf_icp_final",
        "lap",
        SOURCE_000,
        f"EKF-ICP ends close to the start: median ekf_icp final_error_m over seeds <= {100 * EKF_FINAL_BAR_M:g} cm "
        "and no failed run (twice the report's 2.5 cm).",
        "EKF about 2.5 cm from the start (sec. IV, fig. 5)",
        _check_ekf_final,
    ),
    Claim(
        "lap_people_survive",
        "lap",
        SOURCE_000,
        "Moving people do not affect the EKF: on lap variants with people no ekf_icp run fails or diverges, "
        "and a one-sided Mann-Whitney test (different realisations, so unpaired) does not find its ATE larger "
        "than on lap[people=0] at 5 % (no worse).",
        "people walking around 'did not affect the behaviour of the EKF algorithm at all' (sec. IV)",
        _check_people,
        across_variants=True,
    ),
    Claim(
        "lap_kidnap_small_only",
        "lap",
        SOURCE_000,
        f"EKF-ICP recovers from small kidnaps only: kidnap recovery rate >= {RECOVERY_RATE_BAR:g} at the smallest "
        f"kidnap distance D and < {RECOVERY_RATE_BAR:g} at the largest (lap[kidnap_m=D] runs, DESIGN recovery rule), "
        "and a one-sided Fisher exact test finds the rate at the smallest D higher than at the largest at 5 %.",
        "satisfying results only when the kidnapped position was not too far from the last estimate (sec. IV-B)",
        _check_kidnap,
        across_variants=True,
    ),
)

register_experiment(
    Experiment(
        "lap",
        "Lap with people (report 000)",
        "Report 000's test: a 24.5 m rectangular lap on the office floor through three doors with a 683-beam "
        "Hokuyo-like laser, while people who are not on the map walk around; EKF-ICP against odometry, and "
        "small kidnaps.",
        source=SOURCE_000,
        order=20,
        suite=SUITES["lap"],
    )
)
