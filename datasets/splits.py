"""Tuning and test units of every dataset, declared once (docs/protocols.md, "Splits").

A **unit** is what a split assigns whole: a seed of a synthetic world, a robot of an MRCLAM dataset, a Radish site,
a libRSF set. **Tuning units** may be read by anything that chooses a number: a tuning study, and every calibration
of a default (MRCLAM's nominal noise, the synthetic worlds' systematic odometry error, the semi-synthetic Radish
sites' encoder error). **Test units** are read only to report. Every split below is fixed by a stated rule that
does not look at any filter's result; the derivation functions take the split and refuse a test unit
(:meth:`Split.check_tuning`).

* **Synthetic seeds.** Test seeds are 0 .. N - 1 (the comparison's runs); tuning seeds start at
  :data:`TUNING_SEED_START` = 1000 (a study's train seeds, and the :data:`CALIBRATION_SEEDS` of the synthetic
  odometry calibration), so the two never meet while N <= 1000.
* **MRCLAM Dataset 6** (five robots): leave-one-robot-out cross-validation, five folds (:func:`mrclam_folds`): fold r
  holds robot r out and tunes on the other four. The nominal noise a run of robot r is given is derived on fold r's
  tuning robots; the tuned suite's study of fold k gives its train robots fold k's noise (``noise_fold``).
* **Radish sites** (the eleven published corrected logs, :data:`RADISH_SITES`): 7 tuning and 4 test sites by the
  rule of :func:`radish_split`: intel, aces and freiburg-079 tune (the paired sites: the only logs with raw
  odometry, which the encoder-error fit needs); the other eight, sorted by name, alternate tuning, test, tuning, ...
  starting with tuning. A site outside the eleven (a user's own log) is a test site.
* **libRSF**: split by set (:data:`LIBRSF_SPLIT`): the simulated world M3500 (every noise file of it) tunes; W3500
  and the one real set (Indoor UWB, alone of its kind) test. Nothing is calibrated on libRSF today (its noise
  is the files' declared one); the split is what a future calibration must use.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from locbench.core.errors import ConfigError

#: The first tuning seed of a synthetic world: tuning seeds are TUNING_SEED_START .. + K - 1, test seeds 0 .. N - 1.
TUNING_SEED_START = 1000
#: How many tuning seeds a calibration of a synthetic default averages over (as many as the comparison's test seeds).
CALIBRATION_SEED_COUNT = 20


def tuning_seeds(k: int) -> tuple[int, ...]:
    """The first ``k`` tuning seeds of a synthetic world: TUNING_SEED_START .. TUNING_SEED_START + k - 1."""
    if k < 0:
        raise ConfigError(f"a seed count must be >= 0, got {k}")
    return tuple(range(TUNING_SEED_START, TUNING_SEED_START + k))


def test_seeds(n: int) -> tuple[int, ...]:
    """The first ``n`` test seeds of a synthetic world: 0 .. n - 1 (at most TUNING_SEED_START of them)."""
    if not 0 <= n <= TUNING_SEED_START:
        raise ConfigError(f"test seeds are 0 .. {TUNING_SEED_START - 1}; {n} of them would reach the tuning seeds")
    return tuple(range(n))


def is_tuning_seed(seed: int) -> bool:
    """Whether ``seed`` is a tuning seed (>= TUNING_SEED_START)."""
    return seed >= TUNING_SEED_START


@dataclass(frozen=True)
class Split:
    """A split of one dataset's units into tuning and test units.

    Attributes
    ----------
    name : str
        What the units are (``"mrclam fold 3"``, ``"radish sites"``).
    tuning : tuple of str or int
        The tuning units, in a fixed order.
    test : tuple of str or int
        The test units.
    rule : str
        The rule that made the split, in words (it never looks at a filter's result).
    """

    name: str
    tuning: tuple[str | int, ...]
    test: tuple[str | int, ...]
    rule: str

    def __post_init__(self) -> None:
        both = set(self.tuning) & set(self.test)
        if both:
            raise ConfigError(f"split {self.name}: units {sorted(map(str, both))} are both tuning and test units")

    def role(self, unit: str | int) -> str:
        """``"tuning"`` or ``"test"``; a unit the split does not name is a test unit (it never calibrates)."""
        return "tuning" if unit in self.tuning else "test"

    def check_tuning(self, units: Iterable[str | int]) -> tuple[str | int, ...]:
        """``units`` as a tuple when every one is a tuning unit; a :class:`ConfigError` naming the others otherwise.

        A derivation of a default calls this on the units it is about to read.
        """
        got = tuple(units)
        bad = [u for u in got if u not in self.tuning]
        if bad:
            what = "is a test unit" if len(bad) == 1 else "are test units"
            raise ConfigError(
                f"split {self.name}: {', '.join(map(str, bad))} {what}"
                f"; a default may be calibrated on tuning units only ({', '.join(map(str, self.tuning))})"
            )
        return got


#: Synthetic seeds: the calibrations of the synthetic defaults read these (never the test seeds 0 .. N - 1).
CALIBRATION_SEEDS = tuning_seeds(CALIBRATION_SEED_COUNT)
SYNTHETIC_CALIBRATION = Split(
    "synthetic calibration seeds",
    CALIBRATION_SEEDS,
    test_seeds(CALIBRATION_SEED_COUNT),
    f"tuning seeds start at {TUNING_SEED_START}; test seeds are 0 .. N - 1",
)

# --- MRCLAM ----------------------------------------------------------------------------------------------------

#: The robots of an MRCLAM dataset (subjects 1-5).
MRCLAM_ROBOTS: tuple[int, ...] = (1, 2, 3, 4, 5)


def mrclam_fold(held_out: int) -> Split:
    """Leave-one-robot-out fold ``held_out``: the other robots tune, robot ``held_out`` tests."""
    if held_out not in MRCLAM_ROBOTS:
        raise ConfigError(f"an MRCLAM fold holds out one of robots {list(MRCLAM_ROBOTS)}, got {held_out!r}")
    return Split(
        f"mrclam fold {held_out}",
        tuple(r for r in MRCLAM_ROBOTS if r != held_out),
        (held_out,),
        "leave one robot out: the held-out robot tests, the other four tune",
    )


def mrclam_folds() -> tuple[Split, ...]:
    """The five leave-one-robot-out folds of an MRCLAM dataset, in robot order."""
    return tuple(mrclam_fold(r) for r in MRCLAM_ROBOTS)


#: The robots as units of their defaults: each robot's default noise is its own fold's, derived without it, so every
#: robot is a test unit of its default (a tuned configuration's units are its study's fold).
MRCLAM_DEFAULTS = Split(
    "mrclam defaults", (), MRCLAM_ROBOTS, "every robot's default noise is derived without it: each is a test unit"
)


# --- Radish ----------------------------------------------------------------------------------------------------

#: The eleven published corrected logs (SOURCES.md section 6), sorted.
RADISH_SITES: tuple[str, ...] = (
    "acapulco",
    "aces",
    "belgioioso",
    "csail",
    "freiburg-079",
    "freiburg-101",
    "freiburg-campus",
    "infinite-corridor",
    "intel",
    "orebro",
    "seattle",
)
#: Fixed tuning sites: the paired sites, the only ones with raw odometry (the encoder-error fit needs it).
RADISH_FIXED_TUNING: tuple[str, ...] = ("intel", "aces", "freiburg-079")


def radish_split(sites: Sequence[str] = RADISH_SITES, fixed: Sequence[str] = RADISH_FIXED_TUNING) -> Split:
    """The Radish split by its rule: ``fixed`` tune; the other sites, sorted by name, alternate tuning and test,
    starting with tuning.

    Parameters
    ----------
    sites : sequence of str
        The sites to split (the eleven published ones by default).
    fixed : sequence of str
        Sites that tune whatever the rule gives (each must be in ``sites``).
    """
    missing = [s for s in fixed if s not in sites]
    if missing:
        raise ConfigError(f"radish split: fixed tuning sites {missing} are not among the sites")
    rest = sorted(s for s in set(sites) if s not in fixed)
    return Split(
        "radish sites",
        (*fixed, *rest[0::2]),
        tuple(rest[1::2]),
        f"{', '.join(fixed)} tune (the paired sites); the others sorted by name alternate tuning, test, ... "
        "starting with tuning",
    )


RADISH_SPLIT = radish_split()

# --- libRSF ----------------------------------------------------------------------------------------------------

#: libRSF's units are its sets (``librsf[set=...]``; every noise file of a simulated world is in its world's unit).
LIBRSF_SPLIT = Split(
    "librsf sets",
    ("m3500",),
    ("w3500", "indoor_uwb"),
    "by world: M3500 (all its noise files) tunes; W3500 and the one real set (Indoor UWB) test",
)


__all__: Sequence[str] = (
    "CALIBRATION_SEEDS",
    "LIBRSF_SPLIT",
    "MRCLAM_DEFAULTS",
    "MRCLAM_ROBOTS",
    "RADISH_SITES",
    "RADISH_SPLIT",
    "SYNTHETIC_CALIBRATION",
    "TUNING_SEED_START",
    "Split",
    "is_tuning_seed",
    "mrclam_fold",
    "mrclam_folds",
    "radish_split",
    "test_seeds",
    "tuning_seeds",
)
