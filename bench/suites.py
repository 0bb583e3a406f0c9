"""Named suites: which filters on which datasets over how many seeds.

A suite is also readable from a TOML file (``locbench run --suite my_suite.toml``)::

    filters = ["odometry", "ekf_landmarks[association=nearest]"]
    datasets = ["room", "office[kidnap_m=1]"]
    seeds = 10
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path

from locbench.errors import ConfigError, UnknownIdError


@dataclass(frozen=True)
class Suite:
    """Filters x datasets x seeds (seeds 0 .. seeds-1)."""

    name: str
    filters: tuple[str, ...]
    datasets: tuple[str, ...]
    seeds: int
    description: str = ""


# ekf_landmarks twice: with the identities the sensor reports, and ignoring them (nearest neighbour
# under the chi-square gate), on the same data so that the two rows are paired.
_GAUSSIAN = ("odometry", "ekf_landmarks", "ekf_landmarks[association=nearest]")

SUITES: dict[str, Suite] = {
    s.name: s
    for s in (
        Suite(
            "default",
            _GAUSSIAN,
            ("room", "office"),
            20,
            "every registered filter on report 003's room and the common office; runs in a few minutes on 2 cores",
        ),
        Suite("room", _GAUSSIAN, ("room",), 20, "report 003's experiment: 20 runs through 5 waypoints"),
        Suite("office", _GAUSSIAN, ("office",), 20, "the main comparison world"),
        Suite(
            "room_unknown_ids",
            ("odometry", "ekf_landmarks[association=nearest]"),
            ("room[known_ids=false]",),
            20,
            "room with landmark identities withheld: nearest-neighbour association under a chi-square gate",
        ),
        Suite("smoke", _GAUSSIAN, ("tiny_line", "tiny_circle"), 2, "seconds-long sanity run"),
    )
}


def get_suite(name: str) -> Suite:
    """A named suite, or a suite read from a ``.toml`` file path."""
    if name.endswith(".toml"):
        return load_suite_file(Path(name))
    try:
        return SUITES[name]
    except KeyError:
        raise UnknownIdError(
            f"unknown suite {name!r}; valid: {', '.join(sorted(SUITES))} or a path to a .toml file"
        ) from None


def load_suite_file(path: Path) -> Suite:
    """Read a suite from TOML; errors name the file and the field."""
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise ConfigError(f"{path}: suite file not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML ({exc})") from None
    unknown = sorted(set(data) - {"filters", "datasets", "seeds", "description"})
    if unknown:
        raise ConfigError(
            f"{path}: unknown field(s) {', '.join(unknown)}; valid: filters, datasets, seeds, description"
        )
    for key in ("filters", "datasets"):
        val = data.get(key)
        if not isinstance(val, list) or not val or not all(isinstance(v, str) for v in val):
            raise ConfigError(
                f"{path}: field '{key}' must be a non-empty list of spec strings like \"room[kidnap_m=2]\""
            )
    seeds = data.get("seeds", 1)
    if not isinstance(seeds, int) or isinstance(seeds, bool) or seeds < 1:
        raise ConfigError(f"{path}: field 'seeds' must be a positive integer, got {seeds!r}")
    return Suite(path.stem, tuple(data["filters"]), tuple(data["datasets"]), seeds, str(data.get("description", "")))
