"""The consistency protocol on the model-matched worlds: a Gaussian filter whose model holds is consistent.

On ``room[matched=true]`` and ``office[matched=true]`` the simulator's noise is the nominal noise handed to
the filters (no systematic odometry error, the nominal encoder constant, the initial belief's mean drawn
from the belief). There the NEES of a filter whose linearisation is good is chi-square with 3 degrees of
freedom at every time, so the mean over N independent runs of each run's ANEES (its time-averaged NEES)
lies in the two-sided 95 % band chi2(3N)/N (Bar-Shalom, Li and Kirubarajan 2001, sec. 5.4.2; the band of
:func:`locbench.evaluate.metrics.chi2_band`). The claim is ours (the benchmark's protocol), not a source report's,
and it is checked for the two filters whose model is exactly the simulator's: ``ekf_landmarks`` and
``gtsam_fls``. Strictly, the time average of a run's NEES is less spread than one chi-square(3) draw, so
the band is the conservative (wide) one; a filter outside it is inconsistent.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from locbench.claims import Claim, ClaimResult, Source, pick_filter, register, spec_of
from locbench.evaluate.metrics import ANEES, POSE_DOF, chi2_band
from locbench.suites import SUITES

SOURCE_PROTOCOL = Source(
    "consistency",
    "Estimation with Applications to Tracking and Navigation (sec. 5.4: filter consistency, the NEES test)",
    "Y. Bar-Shalom, X. R. Li, T. Kirubarajan",
)
#: The filters whose nominal model is exactly the matched simulator's.
CONSISTENT_FILTERS = ("ekf_landmarks", "gtsam_fls")


def matched_rows(df: pd.DataFrame) -> pd.DataFrame:
    """The rows of the plain model-matched variant (``<id>[matched=true]``, no other parameter)."""
    keep = [
        str(n)
        for n in df["dataset"].unique()
        if spec_of(str(n)).get("matched") == "true" and len(spec_of(str(n)).params) == 1
    ]
    return df[df["dataset"].isin(keep)]


def check_matched_consistency(df: pd.DataFrame, filters: tuple[str, ...] = CONSISTENT_FILTERS) -> ClaimResult:
    """Reproduced when every filter of ``filters`` has its mean ANEES over runs inside chi2_band(3, N).

    The measured text gives each judged filter's value and band, then the other filters' mean ANEES.

    ``df`` holds tidy metrics rows (``dataset, filter, seed, metric, value``) of the variants of one dataset
    id; only the plain ``matched=true`` variant is read. A run with a non-finite ANEES (a singular
    covariance) makes the mean non-finite, hence outside the band.
    """
    rows = matched_rows(df)
    if rows.empty:
        return ClaimResult("not evaluated", "no runs on a matched=true variant")
    parts: list[str] = []
    ok = True
    for fid in filters:
        f = pick_filter(rows, fid)
        if f is None:
            return ClaimResult("not evaluated", f"no {fid} runs on the matched world")
        v = rows.loc[(rows["filter"] == f) & (rows["metric"] == ANEES), "value"].to_numpy(dtype=np.float64)
        if not v.size:
            return ClaimResult("not evaluated", f"{f}: no anees rows on the matched world")
        lo, hi = chi2_band(POSE_DOF, int(v.size))
        mean = float(np.mean(v))
        inside = bool(np.isfinite(mean) and lo <= mean <= hi)
        ok = ok and inside
        parts.append(f"{f}: mean ANEES {mean:.2f} over {v.size} runs, band [{lo:.2f}, {hi:.2f}]")
    # The other filters' values, reported and not judged (their models are not the simulator's).
    others = []
    for f in sorted({str(n) for n in rows["filter"].unique()} - {pick_filter(rows, fid) for fid in filters}):
        v = rows.loc[(rows["filter"] == f) & (rows["metric"] == ANEES), "value"].to_numpy(dtype=np.float64)
        if v.size:
            others.append(f"{f} {float(np.mean(v)):.2f}")
    if others:
        parts.append("not judged: " + ", ".join(others))
    return ClaimResult("reproduced" if ok else "not reproduced", "; ".join(parts))


def _claim(dataset: str) -> Claim:
    return Claim(
        f"{dataset}_matched_consistent",
        dataset,
        SOURCE_PROTOCOL,
        f"On {dataset}[matched=true] (simulator noise = nominal noise), ekf_landmarks and gtsam_fls are "
        "consistent: each one's mean over runs of ANEES lies in the two-sided 95 % chi-square(3N)/N band for "
        "its N runs.",
        "NEES test (sec. 5.4.2): the mean NEES of a consistent filter over N runs is chi-square(nN)/N",
        check_matched_consistency,
        across_variants=True,
        suite=SUITES["consistency"],
    )


register(_claim("room"), _claim("office"))
