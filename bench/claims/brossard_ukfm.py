"""The invariant EKF against the EKF from a wrong initial heading: UKF-M's 2-D question on ``room`` and ``office``.

Source: M. Brossard, A. Barrau and S. Bonnabel, "A Code for Unscented Kalman Filtering on Manifolds (UKF-M)",
ICRA 2020, whose 2-D localization benchmark (100 Monte Carlo runs, a 45 deg initial heading error with a matching
initial covariance) reports a position NEES of 275 for the EKF against 2.02 for the invariant EKF (Barrau and
Bonnabel 2017) and about 1.0 for the SE(2) UKFs, and a position RMSE of 0.76 m against 0.45 m.

Suite ``heading`` runs ``ekf_landmarks``, ``ukf_landmarks``, ``iekf_landmarks`` and ``pf`` on ``room`` and ``office``
with ``initial_heading_error_deg`` 0, 15, 45 and 90; the 45 deg variant, the one the claims read, on 50 seeds.
The published trend becomes two claims per world, both on the 45 deg variant and both judged over the seeds with a
one-sided Wilcoxon signed-rank test (docs/protocols.md, "Claims": a difference is reproduced only when the test
finds it at 5 %):

* the invariant EKF stays consistent where the EKF does not: its mean ANEES over runs lies inside the two-sided
  95 % chi-square(3N)/N band, and its per-run ANEES is lower than the EKF's;
* its position error is lower: its per-run ATE is lower than the EKF's.

The measured text gives both filters' means (and the band), so a verdict can be read against the published values.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from locbench.claims import Claim, ClaimResult, Source, found, paired, pick_filter, register, spec_of, test_text
from locbench.evaluate.metrics import ANEES, ATE_M, POSE_DOF, chi2_band
from locbench.evaluate.significance import wilcoxon_paired
from locbench.suites import HEADING_CLAIM_DEG, SUITES

SOURCE_UKFM = Source(
    "ukfm",
    "A Code for Unscented Kalman Filtering on Manifolds (UKF-M) (2-D localization benchmark; invariant EKF of "
    "Barrau and Bonnabel 2017)",
    "M. Brossard, A. Barrau, S. Bonnabel",
)
#: The dataset parameter of the wrong initial heading, and the value the claims read (deg).
HEADING_PARAM = "initial_heading_error_deg"
CLAIM_HEADING_DEG = HEADING_CLAIM_DEG
#: The filters the claims compare: the invariant EKF against the EKF on the same models.
IEKF, EKF = "iekf_landmarks", "ekf_landmarks"


def heading_rows(df: pd.DataFrame, error_deg: float) -> pd.DataFrame:
    """The rows of the variant with this initial heading error and no other parameter (the plain name at 0)."""
    keep = []
    for n in df["dataset"].unique():
        params = dict(spec_of(str(n)).params)
        value = float(params.pop(HEADING_PARAM, 0.0))
        if not params and value == error_deg:
            keep.append(n)
    return df[df["dataset"].isin(keep)]


def _pair(df: pd.DataFrame, metric: str) -> tuple[str, str, np.ndarray, np.ndarray] | ClaimResult:
    """(iekf name, ekf name, their per-seed values) of ``metric`` on the 45 deg variant, or "not evaluated"."""
    rows = heading_rows(df, CLAIM_HEADING_DEG)
    a_name, b_name = pick_filter(rows, IEKF), pick_filter(rows, EKF)
    if a_name is None or b_name is None:
        missing = IEKF if a_name is None else EKF
        return ClaimResult("not evaluated", f"no {missing} runs at {CLAIM_HEADING_DEG} deg")
    a, b = paired(rows, a_name, b_name, metric)
    return a_name, b_name, a, b


def check_consistent(df: pd.DataFrame) -> ClaimResult:
    """Reproduced when the invariant EKF's mean ANEES lies in the band and the test finds its ANEES lower."""
    return _judge(df, ANEES)


def check_lower_error(df: pd.DataFrame) -> ClaimResult:
    """Reproduced when the test finds the invariant EKF's per-run ATE lower than the EKF's."""
    return _judge(df, ATE_M)


def _judge(df: pd.DataFrame, metric: str) -> ClaimResult:
    """The one-sided Wilcoxon test of the invariant EKF's per-run ``metric`` below the EKF's on the 45 deg variant;
    for the ANEES also the band (a lower ANEES outside the band is no consistency)."""
    got = _pair(df, metric)
    if isinstance(got, ClaimResult):
        return got
    a_name, b_name, a, b = got
    test = wilcoxon_paired(a, b, alternative="less")
    ma, mb = float(np.mean(a)), float(np.mean(b))
    if metric == ATE_M:
        text = (
            f"mean ATE over {a.size} runs {a_name} {100 * ma:.1f} cm, {b_name} {100 * mb:.1f} cm; median "
            f"difference {100 * float(np.median(a - b)):+.2f} cm"
        )
        return ClaimResult(found(test), text, "one-sided " + test_text(test))
    lo, hi = chi2_band(POSE_DOF, int(a.size))
    inside = bool(lo <= ma <= hi)
    text = (
        f"mean ANEES over {a.size} runs {a_name} {ma:.2f}, {b_name} {mb:.2f}; band [{lo:.2f}, {hi:.2f}] "
        f"({a_name} {'inside' if inside else 'outside'})"
    )
    return ClaimResult(found(test) if inside else "not reproduced", text, "one-sided " + test_text(test))


def _claims(dataset: str) -> tuple[Claim, Claim]:
    where = f"On {dataset}[{HEADING_PARAM}={CLAIM_HEADING_DEG}] (the belief's heading {CLAIM_HEADING_DEG} deg off"
    where += ", its standard deviation as large)"
    return (
        Claim(
            f"{dataset}_heading45_iekf_consistent",
            dataset,
            SOURCE_UKFM,
            f"{where} the invariant EKF stays consistent where the EKF does not: iekf_landmarks' mean ANEES over "
            "runs lies in the two-sided 95 % chi-square(3N)/N band, and a one-sided Wilcoxon signed-rank test over "
            "the seeds finds its per-run ANEES lower than ekf_landmarks' at 5 %.",
            "position NEES: EKF 275, invariant EKF 2.02, SE(2) UKFs about 1.0 (100 runs, 45 deg)",
            check_consistent,
            across_variants=True,
            suite=SUITES["heading"],
        ),
        Claim(
            f"{dataset}_heading45_iekf_lower_error",
            dataset,
            SOURCE_UKFM,
            f"{where} the invariant EKF's position error is lower than the EKF's: a one-sided Wilcoxon "
            "signed-rank test over the seeds finds iekf_landmarks' per-run ATE lower than ekf_landmarks' at 5 %.",
            "position RMSE: EKF 0.76 m, invariant EKF 0.45 m (100 runs, 45 deg)",
            check_lower_error,
            across_variants=True,
            suite=SUITES["heading"],
        ),
    )


register(*_claims("room"), *_claims("office"))
