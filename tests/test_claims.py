"""The claims registry: discovery of report modules, per-name and across-variant evaluation."""

from __future__ import annotations

import pandas as pd

from locbench import claims


def _rows(dataset: str, filt: str, metric: str, values: list[float]) -> list[tuple[str, str, int, str, float]]:
    return [(dataset, filt, seed, metric, v) for seed, v in enumerate(values)]


def test_report_modules_are_discovered() -> None:
    ids = {c.id for c in claims.all_claims()}
    assert {"room_odometry_grows", "room_ekf_far_below_odometry"} <= ids
    assert all(c.source.endswith(".txt") for c in claims.all_claims())


def test_claim_that_cannot_run_is_not_evaluated() -> None:
    c = claims.Claim("t", "room", "x.txt", "text", "ref", lambda df: claims.ClaimResult("reproduced", str(df["nope"])))
    assert c.evaluate(pd.DataFrame({"a": [1]})).verdict == "not evaluated"


def test_across_variant_claims_are_kept_apart() -> None:
    for c in claims.claims_for("room"):
        assert not c.across_variants
    for c in claims.claims_for("room", across_variants=True):
        assert c.across_variants


def test_spec_id_and_pick_filter() -> None:
    df = pd.DataFrame(
        _rows("room", "pf[particles=10]", "ate_m", [0.1]) + _rows("room", "pf", "ate_m", [0.2]),
        columns=["dataset", "filter", "seed", "metric", "value"],
    )
    assert claims.spec_id("pf[particles=10]") == "pf"
    assert claims.pick_filter(df, "pf") == "pf"
    assert claims.pick_filter(df[df["filter"] != "pf"], "pf") == "pf[particles=10]"
    assert claims.pick_filter(df, "ekf_landmarks") is None
