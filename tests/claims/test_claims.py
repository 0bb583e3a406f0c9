"""The claims registry: discovery of report modules, per-name and across-variant evaluation."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from locbench import claims


def _rows(dataset: str, filt: str, metric: str, values: list[float]) -> list[tuple[str, str, int, str, float]]:
    return [(dataset, filt, seed, metric, v) for seed, v in enumerate(values)]


def test_report_modules_are_discovered() -> None:
    ids = {c.id for c in claims.all_claims()}
    assert {"room_odometry_grows", "room_ekf_far_below_odometry"} <= ids
    # each claim cites its source report by title and authors, as printed at the head of the report
    seeds = Path(__file__).resolve().parents[3] / "shared" / "seeds"
    for c in claims.all_claims():
        assert c.source.title and c.source.authors and ".txt" not in c.source.citation
        heads = [p.read_text(errors="replace")[:600].lower() for p in seeds.glob(f"{c.source.key}_*.txt")]
        if heads:  # the seed documents lie beside the checkout on the development machines
            assert c.source.title.lower() in heads[0].replace("\n", " "), c.source.title


def test_every_experiment_with_claims_is_registered() -> None:
    exps = {e.dataset: e for e in claims.experiments()}
    assert {c.dataset for c in claims.all_claims()} <= set(exps)
    assert [e.dataset for e in claims.experiments() if e.summary]  # at least one main comparison


def test_claim_that_cannot_run_is_not_evaluated() -> None:
    c = claims.Claim(
        "t",
        "room",
        claims.Source("x", "T", "A"),
        "text",
        "ref",
        lambda df: claims.ClaimResult("reproduced", str(df["nope"])),
    )
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
