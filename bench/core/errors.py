"""Exceptions shared by the whole package; each message says how to fix the problem."""

from __future__ import annotations


class LocbenchError(Exception):
    """Base of every error locbench raises on purpose; its text is cut to :data:`MAX_MESSAGE_CHARS`."""

    def __str__(self) -> str:
        return _cut(super().__str__())


class DependencyNotInstalled(LocbenchError):
    """An optional dependency of a filter or dataset is missing; the message names the install command."""


class UnknownIdError(LocbenchError, KeyError):
    """An unknown filter, dataset, suite or parameter name; the message lists the valid ones."""

    def __str__(self) -> str:  # KeyError would quote the message
        return _cut(str(self.args[0])) if self.args else ""


class ConfigError(LocbenchError, ValueError):
    """A malformed spec, config value or input file; the message names the field and what was expected."""


class FilterDiverged(LocbenchError):
    """Raised by a filter (or detected by the runner) when its estimate is no longer meaningful."""


class DataNotFound(ConfigError):
    """A recorded dataset's files are not on this machine; runs on it are recorded as skipped with this reason."""


#: Longest message of an input error, characters (the rest is cut with a marker).
MAX_MESSAGE_CHARS = 1000


def one_line(message: str, limit: int = MAX_MESSAGE_CHARS) -> str:
    """``message`` with line breaks flattened and cut to ``limit`` characters (input errors stay one short line)."""
    flat = " ".join(message.split())
    return flat if len(flat) <= limit else flat[: limit - 20] + " ... [cut]"


class ResourceLimit(ConfigError):
    """A config or input whose estimated memory is above a documented limit (:mod:`locbench.core.limits`), refused
    before
    anything is allocated; the message names the parameter to change."""


def _cut(message: str, limit: int = MAX_MESSAGE_CHARS) -> str:
    return message if len(message) <= limit else message[: limit - 20] + " ... [cut]"


#: Longest user-given value quoted in a message, characters.
MAX_SHOWN_CHARS = 200


def shown(value: object, limit: int = MAX_SHOWN_CHARS) -> str:
    """``repr(value)`` cut to ``limit`` characters, for quoting user input in a message (the rest still fits)."""
    text = repr(value)
    return text if len(text) <= limit else f"{text[: limit - 30]}... ({len(text)} characters)"
