"""The tuning and test units of every dataset, declared once (docs/protocols.md, "Splits")."""

from __future__ import annotations

import pytest

from locbench.core.errors import ConfigError
from locbench.datasets import splits as sp
from locbench.datasets.recorded import librsf, mrclam
from locbench.run import tuning


def test_synthetic_tuning_and_test_seeds_never_meet() -> None:
    assert sp.tuning_seeds(3) == (1000, 1001, 1002)
    assert sp.test_seeds(20) == tuple(range(20))
    assert not set(sp.CALIBRATION_SEEDS) & set(sp.test_seeds(sp.TUNING_SEED_START))
    assert all(sp.is_tuning_seed(s) for s in sp.CALIBRATION_SEEDS)
    assert not sp.is_tuning_seed(999)
    with pytest.raises(ConfigError, match="reach the tuning seeds"):
        sp.test_seeds(sp.TUNING_SEED_START + 1)
    # the tuning studies draw their train seeds from the same declaration
    assert tuning.train_seeds(3) == list(sp.tuning_seeds(3))
    assert tuning.TRAIN_SEED_START == sp.TUNING_SEED_START


def test_mrclam_has_five_leave_one_robot_out_folds() -> None:
    folds = sp.mrclam_folds()
    assert [f.test for f in folds] == [(r,) for r in mrclam.ROBOTS]
    for f in folds:
        assert sorted(f.tuning + f.test) == list(mrclam.ROBOTS)  # type: ignore[type-var]
    assert sp.MRCLAM_ROBOTS == mrclam.ROBOTS
    # the tuned suite's folds are these: fold k's train robots are given fold k's noise, robot k its own
    for f, (train, test) in zip(folds, tuning.mrclam_folds(), strict=True):
        (k,) = f.test
        assert train == tuple(f"mrclam[robot={r},noise_fold={k}]" for r in f.tuning)
        assert test == f"mrclam[robot={k}]"
    with pytest.raises(ConfigError):
        sp.mrclam_fold(6)


def test_radish_split_follows_its_rule() -> None:
    s = sp.RADISH_SPLIT
    assert len(s.tuning) == 7 and len(s.test) == 4
    assert set(s.tuning) | set(s.test) == set(sp.RADISH_SITES)
    assert s.tuning[:3] == ("intel", "aces", "freiburg-079")
    rest = sorted(set(sp.RADISH_SITES) - set(sp.RADISH_FIXED_TUNING))
    assert list(s.tuning[3:]) == rest[0::2] and list(s.test) == rest[1::2]
    assert s.test == ("belgioioso", "freiburg-101", "infinite-corridor", "seattle")
    # a site outside the published eleven never calibrates
    assert s.role("my-building") == "test" and s.role("intel") == "tuning"
    with pytest.raises(ConfigError, match="not among the sites"):
        sp.radish_split(("a", "b"), fixed=("c",))


def test_librsf_split_covers_every_set() -> None:
    s = sp.LIBRSF_SPLIT
    assert set(s.tuning) | set(s.test) == set(librsf.SETS)
    assert s.tuning == ("m3500",)


def test_a_split_refuses_a_unit_on_both_sides_and_a_test_unit_in_a_derivation() -> None:
    with pytest.raises(ConfigError, match="both tuning and test"):
        sp.Split("x", (1, 2), (2, 3), "r")
    fold = sp.mrclam_fold(2)
    assert fold.check_tuning([1, 3]) == (1, 3)
    with pytest.raises(ConfigError, match="2 is a test unit"):
        fold.check_tuning([1, 2])
