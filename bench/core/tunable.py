"""Which config fields a user would tune, and over what range, and a field's unit: declared as field metadata.

A field carries ``metadata=tunable(low, high, log=True)`` (a float or an integer between bounds, on a log or a
linear scale) or ``metadata=tunable_choice("a", "b")`` (one of a few values); ``unit="m/sqrt(m)"`` (or
``metadata=field_unit(...)`` on a field that is not tunable) declares a unit the field's name cannot carry.
Noise scales, gates, thresholds and iteration caps are tunable; a compute knob (particles, a smoother's lag) is
not, since it is the user's budget, not an accuracy setting. :func:`tunable_fields` reads them back for
``locbench list FILTER`` and ``locbench tune`` (:mod:`locbench.run.tuning`). The metadata does not enter the run key
(:mod:`locbench.core.runkey` reads only its own flag), so declaring a field tunable changes no stored run. The
values a field accepts at all are its :func:`locbench.filters.base.bound` metadata (``base=`` merges the two);
a search range lies inside it.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Literal

#: The metadata key of a tunable field.
TUNABLE_KEY = "tunable"
#: The metadata key of a field's unit (``locbench list ID`` prints it; else the unit is read from the name's suffix).
UNIT_KEY = "unit"


@dataclass(frozen=True)
class TunableRange:
    """The search space of one config field.

    Attributes
    ----------
    kind : {"float", "int", "choice"}
        A real number or an integer between ``low`` and ``high``, or one of ``choices``.
    low, high : float
        Inclusive bounds, in the field's unit (its name's suffix); unused for a choice.
    log : bool
        Search on a logarithmic scale (noise scales spanning decades); needs ``low`` > 0.
    choices : tuple
        The values of a choice, as the field's type holds them.
    """

    kind: Literal["float", "int", "choice"]
    low: float = 0.0
    high: float = 0.0
    log: bool = False
    choices: tuple[Any, ...] = ()

    def __post_init__(self) -> None:
        if self.kind == "choice":
            if len(self.choices) < 2:
                raise ValueError("a tunable choice needs at least two values")
            return
        if not (math.isfinite(self.low) and math.isfinite(self.high) and self.low < self.high):
            raise ValueError(f"tunable bounds must be finite with low < high, got [{self.low}, {self.high}]")
        if self.log and self.low <= 0.0:
            raise ValueError(f"a log-scale tunable range needs low > 0, got {self.low}")

    def contains(self, value: Any) -> bool:
        """Whether ``value`` lies in the range (or is one of the choices)."""
        if self.kind == "choice":
            return value in self.choices
        return isinstance(value, (int, float)) and self.low <= float(value) <= self.high

    def describe(self) -> str:
        """``[0.001, 1] log``, ``[5, 700] int log``, ``{known, nearest}``: how ``locbench list`` prints it."""
        if self.kind == "choice":
            return "{" + ", ".join(map(str, self.choices)) + "}"
        scale = "log" if self.log else "linear"
        kind = " int" if self.kind == "int" else ""
        return f"[{self.low:g}, {self.high:g}]{kind} {scale}"


def tunable(
    low: float,
    high: float,
    *,
    log: bool = False,
    integer: bool = False,
    unit: str = "",
    base: Mapping[str, Any] | None = None,
) -> MappingProxyType[str, Any]:
    """Field metadata of a tunable number in [``low``, ``high``]; ``unit`` as :func:`field_unit`; ``base`` merges
    other metadata (the run key's)."""
    rng = TunableRange("int" if integer else "float", float(low), float(high), log)
    return MappingProxyType({**field_unit(unit, base), TUNABLE_KEY: rng})


def tunable_choice(*choices: Any, base: Mapping[str, Any] | None = None) -> MappingProxyType[str, Any]:
    """Field metadata of a tunable choice among ``choices``."""
    return MappingProxyType({**(base or {}), TUNABLE_KEY: TunableRange("choice", choices=tuple(choices))})


def field_unit(unit: str, base: Mapping[str, Any] | None = None) -> MappingProxyType[str, Any]:
    """Field metadata declaring the field's unit (``"m/sqrt(m)"``), for a name whose suffix does not say it;
    ``""`` declares nothing. Like the tuning range, it never enters the run key."""
    return MappingProxyType({**(base or {}), **({UNIT_KEY: unit} if unit else {})})


def tunable_fields(cls: type) -> dict[str, TunableRange]:
    """Field name -> search range of every tunable field of the config dataclass ``cls``, in field order."""
    out: dict[str, TunableRange] = {}
    for f in dataclasses.fields(cls):
        rng = f.metadata.get(TUNABLE_KEY)
        if f.init and isinstance(rng, TunableRange):
            out[f.name] = rng
    return out
