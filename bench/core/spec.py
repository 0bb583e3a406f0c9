"""Names users type: ``id[key=value,...]`` specs, parameter grids, and typed parameter dataclasses built from them.

A filter config or dataset parameter set is a frozen, keyword-only dataclass whose field names carry
units (``sigma_range_m``). :func:`parse_spec` splits a spec; :func:`expand_grid` turns a grid
``pf[particles=100|300,augmented=true]`` into its specs; :func:`build_params` turns its string
values into the dataclass, with an error that lists the valid keys or says what type was expected.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import math
import re
import types
import typing
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any, Literal, TypeVar, Union, get_args, get_origin

from locbench.core.errors import ConfigError, UnknownIdError, shown
from locbench.core.tunable import UNIT_KEY

P = TypeVar("P")


#: The field-metadata key of a config field's accepted values (:func:`bound`).
BOUND_KEY = "bound"


@dataclasses.dataclass(frozen=True)
class Bound:
    """The values a numeric config field accepts: an interval, either end open or closed, and None if optional.

    Declared on the field (``metadata=bound(0.0, low_open=True, unit="m")``) of a filter config or a dataset's
    parameters, so each states its limits beside each field instead of looping over names. Checked when a spec
    is parsed (:func:`build_params`, with infinite ends capped at :data:`MAX_MAGNITUDE`) and, for a filter config,
    on every construction (:class:`locbench.filters.base.FilterConfig`). NaN is never accepted.

    Attributes
    ----------
    low, high : float
        The interval's ends, in the field's unit (infinite: no limit on that side).
    low_open, high_open : bool
        The end itself is excluded.
    optional : bool
        None is accepted too (the dataset's or the filter's default takes its place).
    finite : bool
        An infinite value is refused even where the interval would hold it.
    unit : str
        Unit printed after a one-sided limit (``> 0 m``).
    what : str
        Printed before the limit (``a variance >= 0``).
    none_means : str
        What None stands for, printed after the limit of an optional field (``(or None for the dataset's value)``;
        empty: not printed).
    expected : str
        The whole expectation as printed, when the generated text does not say it (``in 1..8``).
    """

    low: float = -math.inf
    high: float = math.inf
    low_open: bool = False
    high_open: bool = False
    optional: bool = False
    finite: bool = False
    unit: str = ""
    what: str = ""
    none_means: str = "the dataset's value"
    expected: str = ""

    def accepts(self, value: Any) -> bool:
        """Whether ``value`` lies in the bound (None only when optional; NaN never)."""
        if value is None:
            return self.optional
        # an int is compared as it is: float() of a huge one overflows
        v = value if isinstance(value, int) else float(value)
        if math.isnan(v) or (self.finite and not math.isfinite(v)):
            return False
        above = v > self.low if self.low_open else v >= self.low
        below = v < self.high if self.high_open else v <= self.high
        return bool(above and below)

    def describe(self) -> str:
        """The expectation of the error message: ``> 0 m``, ``in (0, 1]``, ``a variance >= 0``."""
        if self.expected:
            return self.expected
        if math.isinf(self.high):
            text = f"{'>' if self.low_open else '>='} {self.low:g}" + (f" {self.unit}" if self.unit else "")
        elif math.isinf(self.low):
            text = f"{'<' if self.high_open else '<='} {self.high:g}" + (f" {self.unit}" if self.unit else "")
        else:
            text = f"in {'(' if self.low_open else '['}{self.low:g}, {self.high:g}{')' if self.high_open else ']'}"
            text += f" {self.unit}" if self.unit else ""
        if self.what:
            text = f"{self.what} {text}"
        return f"{text} (or None for {self.none_means})" if self.optional and self.none_means else text


def bound(
    low: float = -math.inf,
    high: float = math.inf,
    *,
    base: Mapping[str, Any] | None = None,
    **options: Any,
) -> MappingProxyType[str, Any]:
    """Field metadata of a :class:`Bound` (keyword ``options`` as its attributes); ``base`` merges other metadata
    (the run key's, a tunable range's)."""
    return MappingProxyType({**(base or {}), BOUND_KEY: Bound(float(low), float(high), **options)})


_SPEC_RE = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_\-]*)\s*(?:\[(.*)\])?\s*$")


def parse_spec(text: str) -> tuple[str, dict[str, str]]:
    """Split ``"pf[particles=5000,laser_beams=60]"`` into ``("pf", {"particles": "5000", ...})``.

    Raises
    ------
    ConfigError
        When the text is not ``id`` or ``id[key=value,...]``.
    """
    m = _SPEC_RE.match(text)
    if m is None:
        raise ConfigError(f"malformed spec {shown(text)}: expected 'id' or 'id[key=value,...]'")
    ident, body = m.group(1), m.group(2)
    params: dict[str, str] = {}
    if body is not None and body.strip():
        for item in body.split(","):
            if "=" not in item:
                raise ConfigError(
                    f"malformed parameter {shown(item.strip())} in spec {shown(text)}: expected key=value"
                )
            key, value = (s.strip() for s in item.split("=", 1))
            if not key or key in params:
                raise ConfigError(f"empty or repeated key {shown(key)} in spec {shown(text)}")
            params[key] = value
    return ident, params


@dataclasses.dataclass(frozen=True, order=True)
class Spec:
    """A filter or dataset name parsed once: its id and its parameters as canonical strings.

    Every consumer after the edge (CLI argument, CSV column, folder) reads ``ident`` and :meth:`get`
    instead of re-splitting the text; ``str(spec)`` is the canonical spelling (keys sorted).

    Attributes
    ----------
    ident : str
        The registry id (``pf``).
    params : tuple of (str, str)
        ``(key, value)`` pairs sorted by key, values as written in the canonical name.
    """

    ident: str
    params: tuple[tuple[str, str], ...] = ()

    @classmethod
    def parse(cls, text: str) -> Spec:
        """Parse ``"pf[particles=5000]"``; raises :class:`ConfigError` on a malformed spec."""
        ident, raw = parse_spec(text)
        return cls(ident, tuple(sorted(raw.items())))

    @property
    def name(self) -> str:
        """The canonical spelling ``id[k1=v1,...]``."""
        return format_spec(self.ident, dict(self.params))

    def __str__(self) -> str:
        return self.name

    def as_dict(self) -> dict[str, str]:
        """The parameters as a dict of strings."""
        return dict(self.params)

    def get(self, key: str, default: str | None = None) -> str | None:
        """The string value of parameter ``key``, or ``default`` when it is not set."""
        return dict(self.params).get(key, default)

    def get_float(self, key: str, default: float) -> float:
        """Parameter ``key`` as a number (``default`` when not set)."""
        value = self.get(key)
        return default if value is None else float(value)

    def without(self, *keys: str) -> Spec:
        """The same spec with ``keys`` removed (``office[kidnap_m=2]`` -> ``office``)."""
        return Spec(self.ident, tuple(kv for kv in self.params if kv[0] not in keys))


#: Separates the values of one parameter in a grid spec (``pf[particles=100|300]``).
GRID_SEP = "|"


#: Most configurations a grid, or a block of grids, may expand to (``--max-configs`` raises it).
MAX_CONFIGS = 10_000


def grid_size(text: str) -> int:
    """The number of specs :func:`expand_grid` makes of ``text``, counted without expanding it."""
    _, params = parse_spec(text)
    return math.prod(len(v.split(GRID_SEP)) for v in params.values())


def expand_grid(text: str, limit: int | None = MAX_CONFIGS) -> list[str]:
    """The specs of a parameter grid: ``|`` separates a key's values and keys cross.

    ``"pf[particles=100|300,augmented=true|false]"`` gives the four specs of the cross product, in the order
    written (the first key varies slowest); a spec without ``|`` gives itself. Raises :class:`ConfigError`
    for an empty value (``particles=100||300``), a value repeated within one key, or a grid of more than
    ``limit`` configurations (counted before anything is expanded).
    """
    ident, params = parse_spec(text)
    axes: list[list[str]] = []
    for key, value in params.items():
        values = [v.strip() for v in value.split(GRID_SEP)]
        if len(values) > 1 and (not all(values) or len(set(values)) != len(values)):
            raise ConfigError(
                f"grid parameter {key}={shown(value)} in spec {shown(text)}: "
                "expected distinct non-empty values separated by '|'"
            )
        axes.append(values)
    size = math.prod(len(a) for a in axes)
    if limit is not None and size > limit:
        raise ConfigError(
            f"grid spec {shown(text)}: {size} configurations, more than the limit of {limit} (--max-configs raises it)"
        )
    if all(len(a) == 1 for a in axes):
        return [text.strip()]
    keys = list(params)
    return [format_spec(ident, dict(zip(keys, combo, strict=True))) for combo in itertools.product(*axes)]


def format_spec(ident: str, params: dict[str, Any]) -> str:
    """The canonical spelling ``id[k1=v1,k2=v2]`` with keys sorted; ``id`` alone without parameters."""
    if not params:
        return ident
    body = ",".join(f"{k}={_format_value(params[k])}" for k in sorted(params))
    return f"{ident}[{body}]"


def _format_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return str(int(v)) if v.is_integer() and abs(v) < 1e15 else repr(v)
    if isinstance(v, (tuple, list)):
        return ";".join(_format_value(x) for x in v)
    return str(v)


def _convert(raw: Any, tp: Any, where: str) -> Any:
    """Convert a string (or already typed value) to the annotated type ``tp``."""
    origin = get_origin(tp)
    if origin is Literal:
        allowed = get_args(tp)
        for a in allowed:
            if str(a) == str(raw) or a == raw:
                return a
        raise ConfigError(f"{where}: {shown(raw)} is not one of {', '.join(map(str, allowed))}")
    if origin in (Union, types.UnionType):
        args = [a for a in get_args(tp) if a is not type(None)]
        if type(None) in get_args(tp) and str(raw).lower() in ("none", "null", ""):
            return None
        errors = []
        for a in args:
            try:
                return _convert(raw, a, where)
            except ConfigError as exc:
                errors.append(str(exc))
        raise ConfigError(f"{where}: {shown(raw)} does not fit {tp}")
    if tp is bool:
        if isinstance(raw, bool):
            return raw
        s = str(raw).strip().lower()
        if s in ("1", "true", "yes", "on"):
            return True
        if s in ("0", "false", "no", "off"):
            return False
        raise ConfigError(f"{where}: expected a boolean (true/false), got {shown(raw)}")
    if tp is int:
        if isinstance(raw, bool):
            raise ConfigError(f"{where}: expected an integer, got {shown(raw)}")
        try:
            if isinstance(raw, float) and raw.is_integer():
                return int(raw)
            return int(str(raw).strip())
        except ValueError:
            raise ConfigError(f"{where}: expected an integer, got {shown(raw)}") from None
    if tp is float:
        try:
            val = float(str(raw).strip()) if not isinstance(raw, (int, float)) else float(raw)
        except ValueError:
            raise ConfigError(f"{where}: expected a number, got {shown(raw)}") from None
        return val
    if tp is str:
        return str(raw)
    if origin is tuple:
        parts = raw if isinstance(raw, (tuple, list)) else [p for p in str(raw).split(";") if p.strip()]
        sub = get_args(tp)
        if len(sub) == 2 and sub[1] is Ellipsis:
            return tuple(_convert(p, sub[0], where) for p in parts)
        if len(parts) != len(sub):
            raise ConfigError(f"{where}: expected {len(sub)} values separated by ';', got {shown(raw)}")
        return tuple(_convert(p, s, where) for p, s in zip(parts, sub, strict=True))
    raise ConfigError(f"{where}: unsupported parameter type {tp}")


def param_fields(cls: type) -> dict[str, Any]:
    """Field name -> resolved type annotation of a parameter dataclass."""
    hints = typing.get_type_hints(cls)
    return {f.name: hints[f.name] for f in dataclasses.fields(cls) if f.init}


#: Largest magnitude a numeric parameter takes where its field declares no finite limit on that side: every number
#: a spec gives is bounded when it is parsed, so a build or a reset never meets 1e308, an overflowing product or
#: an allocation of that many elements. A field whose sane range is wider declares it (:func:`bound`).
MAX_MAGNITUDE = 1e6


def _scalar_kind(tp: Any) -> tuple[type | None, bool]:
    """The numeric type of an ``int``, ``float`` or ``X | None`` annotation and whether None is allowed."""
    if tp is bool:
        return None, False
    if tp in (int, float):
        return tp, False
    if get_origin(tp) in (Union, types.UnionType):
        args = [a for a in get_args(tp) if a is not type(None)]
        if len(args) == 1 and args[0] in (int, float):
            return args[0], type(None) in get_args(tp)
    return None, False


def parse_bound(f: dataclasses.Field[Any], tp: Any) -> Bound | None:
    """The values a numeric field accepts when a spec is parsed: its declared :class:`Bound` with each infinite end
    capped at :data:`MAX_MAGNITUDE` (finite), or ``[-MAX_MAGNITUDE, MAX_MAGNITUDE]`` when it declares none; None
    for a field that is not a number (``int``, ``float`` or either or None)."""
    kind, optional = _scalar_kind(tp)
    if kind is None:
        return None
    declared = f.metadata.get(BOUND_KEY)
    if not isinstance(declared, Bound):
        declared = Bound(optional=optional, none_means="")
    low = max(declared.low, -MAX_MAGNITUDE) if math.isinf(declared.low) else declared.low
    high = min(declared.high, MAX_MAGNITUDE) if math.isinf(declared.high) else declared.high
    capped = (low, high) != (declared.low, declared.high)
    # a one-sided limit printed as "> 0 m" would hide the cap: print the interval then
    return dataclasses.replace(declared, low=low, high=high, finite=True, expected="" if capped else declared.expected)


def build_params(cls: type[P], values: dict[str, Any], owner: str) -> P:
    """Build the parameter dataclass ``cls`` from ``values`` (strings from a spec, or typed values).

    Parameters
    ----------
    cls : dataclass type
        The frozen keyword-only parameter class.
    values : dict
        Key -> value; unknown keys are an error that lists the valid ones.
    owner : str
        The filter or dataset id, for error messages.

    Every numeric value given is checked against its field's bound (:func:`parse_bound`) before the class is
    built: a one-line :class:`ConfigError` names the spec, the field, the value and the bound.
    """
    fields = param_fields(cls)
    unknown = sorted(set(values) - set(fields))
    if unknown:
        raise UnknownIdError(
            f"unknown parameter {', '.join(map(repr, unknown))} for {owner!r}; "
            f"valid: {', '.join(sorted(fields)) or '(none)'}"
        )
    spec = format_spec(owner, values)
    kwargs = {k: _convert(v, fields[k], f"{spec}: parameter {k!r}") for k, v in values.items()}
    try:
        obj = cls(**kwargs)
    except (TypeError, ValueError, ArithmeticError) as exc:
        # the rules across fields (a class's own __post_init__) name the spec as given, too
        text = str(exc).removeprefix(f"{owner}:").strip()
        raise ConfigError(f"{spec}: {text}") from None
    # then the bound every number has when parsed (the class's own checks first: their messages say more)
    declared = {f.name: f for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    for k, v in kwargs.items():
        b = parse_bound(declared[k], fields[k])
        if b is not None and not b.accepts(v):
            raise ConfigError(f"{spec}: {k} must be {b.describe()}, got {shown(values[k])}")
    return obj


def params_to_dict(obj: Any) -> dict[str, Any]:
    """A parameter dataclass as a JSON-friendly dict (tuples become lists)."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        out[f.name] = list(v) if isinstance(v, tuple) else v
    return out


def non_default_params(obj: Any) -> dict[str, Any]:
    """Only the fields whose value differs from the class default (for display names)."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        default = (
            f.default
            if f.default is not dataclasses.MISSING
            else (f.default_factory() if f.default_factory is not dataclasses.MISSING else dataclasses.MISSING)
        )
        if default is dataclasses.MISSING or v != default:
            out[f.name] = v
    return out


def stable_hash(obj: Any) -> str:
    """sha256 hex digest of the canonical JSON of ``obj`` (never Python's salted ``hash()``)."""
    text = json.dumps(obj, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()


@dataclasses.dataclass(frozen=True)
class ParamDoc:
    """One parameter of a filter config or dataset, as ``locbench list ID`` prints it."""

    name: str
    type: str
    default: str
    unit: str
    meaning: str


#: Unit of a parameter from the suffix of its name (the house rule: names carry units), longest suffix first.
_UNIT_SUFFIXES = (
    ("_rad2_per_rad", "rad^2/rad"),
    ("_m2_per_m", "m^2/m"),
    ("_sigma_theta_per_rad", "rad/sqrt(rad)"),
    ("_sigma_theta_per_m", "rad/sqrt(m)"),
    ("_sigma_xy_per_m", "m/sqrt(m)"),
    ("_per_m", "1/m"),
    ("_radps", "rad/s"),
    ("_mps", "m/s"),
    ("_rad2", "rad^2"),
    ("_m2", "m^2"),
    ("_deg", "deg"),
    ("_rad", "rad"),
    ("_hz", "Hz"),
    ("_s", "s"),
    ("_m", "m"),
)
_NUMPYDOC_ITEM = re.compile(r"^(\w[\w, ]*?)\s*:\s*(.+)$")


def _attribute_docs(cls: type) -> dict[str, str]:
    """Field name -> description from the numpydoc ``Attributes`` sections of ``cls`` and its bases."""
    out: dict[str, str] = {}
    for klass in cls.__mro__:
        lines = [ln.rstrip() for ln in (klass.__doc__ or "").splitlines()]
        for i, line in enumerate(lines[:-1]):
            if line.strip() != "Attributes" or set(lines[i + 1].strip()) != {"-"}:
                continue
            base = len(line) - len(line.lstrip())
            names: list[str] = []
            for ln in lines[i + 2 :]:
                indent = len(ln) - len(ln.lstrip())
                if not ln.strip():
                    continue
                if indent < base or (indent == base and not _NUMPYDOC_ITEM.match(ln.strip())):
                    break
                m = _NUMPYDOC_ITEM.match(ln.strip()) if indent == base else None
                if m:
                    names = [n.strip() for n in m.group(1).split(",")]
                    for n in names:
                        out.setdefault(n, "")
                else:
                    for n in names:
                        if out.get(n) is not None and not out[n].endswith("\x00"):
                            out[n] = (out[n] + " " + ln.strip()).strip()
            # descriptions found in a subclass win; mark them done for the bases
            out = {k: v if v.endswith("\x00") else v + "\x00" for k, v in out.items()}
    return {k: v.rstrip("\x00") for k, v in out.items()}


def _type_name(tp: Any) -> str:
    origin = get_origin(tp)
    if origin is Literal:
        return "{" + ", ".join(map(str, get_args(tp))) + "}"
    if origin in (Union, types.UnionType):
        args = get_args(tp)
        named = " or ".join(_type_name(a) for a in args if a is not type(None))
        return f"{named} or None" if type(None) in args else named
    if origin is tuple:
        return "tuple of " + ", ".join(_type_name(a) for a in get_args(tp) if a is not Ellipsis)
    return getattr(tp, "__name__", str(tp))


#: Abbreviations whose full stop does not end a sentence (``eq. 10``, ``sec. 4.2``, ``et al.``).
_ABBREVIATIONS = ("eq", "eqs", "sec", "fig", "al", "ref", "refs", "e.g", "i.e", "cf", "vs", "approx")
_MAX_MEANING = 160


def _first_sentence(text: str) -> str:
    """The first sentence of a description (a full stop then a capital, not after an abbreviation), shortened."""
    for m in re.finditer(r"\.(?=\s+[A-Z`(\"]|\s*$)", text):
        word = text[: m.start()].rsplit(None, 1)[-1].lower() if text[: m.start()].strip() else ""
        if word.lstrip("(") not in _ABBREVIATIONS:
            text = text[: m.start() + 1]
            break
    return text if len(text) <= _MAX_MEANING else text[: _MAX_MEANING - 3].rstrip() + "..."


def describe_params(cls: type) -> list[ParamDoc]:
    """Every parameter of the dataclass ``cls``: type, default, unit and meaning.

    The meaning is the first sentence of the field's entry in the numpydoc ``Attributes`` section of the
    class (or a base); the unit is the field's ``metadata["unit"]`` when given
    (:func:`locbench.core.tunable.field_unit`),
    else read from its name's suffix (``_m`` metres, ``_rad`` radians, ``_s`` seconds, ``_m2`` square metres ...),
    else ``-``.
    """
    docs = _attribute_docs(cls)
    hints = param_fields(cls)
    out = []
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        if f.default is not dataclasses.MISSING:
            default = _format_value(f.default) if f.default != "" else '""'
        elif f.default_factory is not dataclasses.MISSING:
            default = _format_value(f.default_factory())
        else:
            default = "(required)"
        # "_" + name: a name that is its suffix alone (sigma_xy_per_m) reads as that suffix, not as its tail (_per_m)
        suffixed = "_" + f.name
        unit = str(f.metadata.get(UNIT_KEY, "")) or next((u for s, u in _UNIT_SUFFIXES if suffixed.endswith(s)), "-")
        meaning = str(f.metadata.get("doc", "")) or _first_sentence(docs.get(f.name, "")) or "(undocumented)"
        out.append(ParamDoc(f.name, _type_name(hints[f.name]), default, unit, meaning))
    return out
