"""A wrong initial heading (``initial_heading_error_deg``), suite ``heading`` and the claims of ``brossard_ukfm``."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from locbench.claims.brossard_ukfm import check_consistent, check_lower_error, heading_rows
from locbench.core.errors import ConfigError
from locbench.core.runkey import key_params
from locbench.datasets.synthetic.scenarios import OfficeParams, RoomParams
from locbench.registry import make_dataset, resolve_dataset
from locbench.suites import SUITES


@pytest.mark.parametrize("world", ["room", "office"])
def test_the_belief_turns_and_covers_its_error(world: str) -> None:
    plain = make_dataset(world, 4)
    ds = make_dataset(f"{world}[initial_heading_error_deg=45]", 4)
    start = np.array([ds.ground_truth.xy[0, 0], ds.ground_truth.xy[0, 1], ds.ground_truth.theta[0]])
    err = ds.initial.mean - start
    assert err[:2] == pytest.approx([0.0, 0.0], abs=1e-12)
    assert math.remainder(err[2], 2 * math.pi) == pytest.approx(math.radians(45.0), abs=1e-12)
    assert ds.initial.cov[2, 2] == pytest.approx(math.radians(45.0) ** 2)
    assert ds.initial.cov[:2, :2] == pytest.approx(plain.initial.cov[:2, :2])
    assert np.all(ds.initial.cov[2, :2] == 0.0) and np.all(ds.initial.cov[:2, 2] == 0.0)


def test_zero_is_the_shipped_world_and_leaves_the_run_key() -> None:
    assert resolve_dataset("room[initial_heading_error_deg=0]").name == "room"
    assert "initial_heading_error_deg" not in key_params(RoomParams())
    assert "initial_heading_error_deg" not in key_params(OfficeParams())
    with pytest.raises(ConfigError, match="initial_heading_error_deg"):
        resolve_dataset("office[initial_heading_error_deg=-5]")


def test_the_suite_runs_every_filter_at_45_degrees_on_50_seeds_and_elsewhere_on_20() -> None:
    suite = SUITES["heading"]
    runs = {(f, resolve_dataset(d).name, s) for b in suite.blocks for f in b.filters for d in b.datasets
            for s in range(b.seeds)}  # fmt: skip
    errors = [f"[initial_heading_error_deg={e}]" for e in (15, 45, 90)]
    worlds = {w + e for w in ("room", "office") for e in ("", *errors)}
    filters = {"ekf_landmarks", "ukf_landmarks", "iekf_landmarks", "pf"}
    # the claims' paired tests read 45 deg; at 0 deg, the plain worlds, the main comparison's 20 seeds: every filter
    # of its table on the same seeds; 15 and 90 deg, which no claim reads, on the same 20
    assert runs == {(f, w, s) for f in filters for w in worlds for s in range(50 if "=45]" in w else 20)}
    assert sum(b.runs for b in suite.blocks) == len(runs) == 880  # no run twice
    main = {(f, resolve_dataset(d).name, s) for b in SUITES["default"].blocks for f in b.filters for d in b.datasets
            for s in range(b.seeds)}  # fmt: skip
    assert {r for r in runs if "[" not in r[1]} <= main
    assert all(b in SUITES["all"].blocks for b in suite.blocks)  # nox -s bench runs it


def _rows(iekf: np.ndarray, ekf: np.ndarray, metric: str) -> pd.DataFrame:
    recs = [
        {"dataset": "room[initial_heading_error_deg=45]", "filter": f, "seed": s, "metric": metric, "value": v}
        for f, vals in (("iekf_landmarks", iekf), ("ekf_landmarks", ekf))
        for s, v in enumerate(vals)
    ]
    other = {"dataset": "room[initial_heading_error_deg=15]", "filter": "iekf_landmarks", "seed": 0}
    return pd.DataFrame([*recs, other | {"metric": metric, "value": 1e6}])


def test_the_claims_read_the_45_degree_variant_and_follow_the_rule() -> None:
    rng = np.random.default_rng(1)
    base = 3.0 + 0.3 * rng.standard_normal(30)
    df = _rows(base, base + 2.0, "anees")
    assert set(heading_rows(df, 45)["dataset"]) == {"room[initial_heading_error_deg=45]"}
    assert check_consistent(df).verdict == "reproduced"
    # lower but outside the band: no consistency to reproduce
    assert check_consistent(_rows(base + 20.0, base + 40.0, "anees")).verdict == "not reproduced"
    # no difference: not found
    assert check_lower_error(_rows(base, base[::-1].copy(), "ate_m")).verdict == "not reproduced"
    assert check_lower_error(_rows(base, base + 0.5, "ate_m")).verdict == "reproduced"
    assert check_lower_error(_rows(base[:0], base[:0], "ate_m")).verdict == "not evaluated"


def test_the_claims_pair_the_two_filters_on_all_50_seeds_and_leave_pf_and_ukf_out() -> None:
    rng = np.random.default_rng(2)
    base = 0.05 + 0.01 * rng.standard_normal(50)
    df = _rows(base, base + 0.01, "ate_m")
    extra = [
        {"dataset": "room[initial_heading_error_deg=45]", "filter": f, "seed": s, "metric": "ate_m", "value": 9.0}
        for f in ("pf", "ukf_landmarks")
        for s in range(50)
    ]
    got = check_lower_error(pd.concat([df, pd.DataFrame(extra)], ignore_index=True))
    assert got.verdict == "reproduced"
    assert got.measured.startswith("mean ATE over 50 runs iekf_landmarks 5.")


@pytest.mark.parametrize(
    ("world", "turned_spec"),
    [
        ("room", "room[initial_heading_error_deg=90]"),
        ("office", "office[initial_heading_error_deg=15]"),
        ("room[kidnap_m=1]", "room[kidnap_m=1,initial_heading_error_deg=45]"),
    ],
)
def test_every_error_of_a_seed_is_the_plain_worlds_realisation(world: str, turned_spec: str) -> None:
    """The error turns only the initial belief: truth, events and noise are the plain world's for the same seed, so
    the heading's effect is paired by run."""
    import pickle

    plain = make_dataset(world, 2)
    turned = make_dataset(turned_spec, 2)
    assert turned.name != plain.name
    assert np.array_equal(turned.ground_truth.poses, plain.ground_truth.poses)
    assert np.array_equal(turned.ground_truth.t, plain.ground_truth.t)
    assert [pickle.dumps(e) for e in turned.events] == [pickle.dumps(e) for e in plain.events]
    assert not np.array_equal(turned.initial.mean, plain.initial.mean)
    assert make_dataset(world, 3).ground_truth.poses.shape != () and not np.array_equal(
        make_dataset(world, 3).ground_truth.poses[:50], plain.ground_truth.poses[:50]
    )
