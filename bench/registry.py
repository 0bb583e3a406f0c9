"""Lazy registries of filters and datasets.

The package's own entries register themselves where they are defined: a class of a module of
:mod:`locbench.filters` (or of :mod:`locbench.datasets` and its sub-packages) whose own body sets ``id`` is the
filter (dataset) of that id, found by walking the package's modules (pkgutil; modules named ``_*`` are private and
not searched). No module is named here, so adding a filter or a recorded format is adding its module. The package
is searched on the first lookup that needs it; a lookup by id first tries the modules named after the id, so
``make_filter("odometry")`` imports one filter module, not all. A module that does not import for a missing
optional dependency is an entry under its module name, unavailable with the reason; two classes declaring one id
are an error naming both.

Entries are import paths (``"locbench.filters.ekf_landmarks:LandmarkEKF"``), and a class's optional dependencies
(its ``requires_modules``) are checked when it is made, so a missing one shows as "unavailable: install ..."
instead of an ImportError at start-up. Third-party packages add entries through the ``locbench.filters`` and
``locbench.datasets`` entry-point groups; :meth:`Registry.register` adds one by hand (tests).

A plugin (an entry of those groups) is code locbench does not control: before its module is imported here,
it is imported and its class checked (:func:`check_class`) in a child Python process under a time limit
(:data:`PLUGIN_IMPORT_TIMEOUT_S`, ``$LOCBENCH_PLUGIN_TIMEOUT``); the plugins of a group share one child,
which reports each as it is done. A plugin whose import raises anything (not only ImportError), hangs,
exits or crashes, or whose class is not what its group expects, is *unavailable* with its entry point and
the reason on one line (:meth:`Registry.load_error`): ``locbench list`` shows it so, making it raises
:class:`PluginUnavailable`, and every other entry works as before. An id the package declares wins over a
plugin's.
"""

from __future__ import annotations

import dataclasses
import importlib
import importlib.metadata
import json
import os
import pkgutil
import select
import subprocess
import sys
import time
import traceback
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

import numpy as np

from locbench.core.errors import DependencyNotInstalled, UnknownIdError, one_line
from locbench.core.seeding import dataset_rng
from locbench.core.spec import Spec, build_params, format_spec, non_default_params, params_to_dict, parse_spec

T = TypeVar("T")


@dataclass(frozen=True)
class Entry:
    """One registered filter or dataset."""

    id: str
    entry_point: str
    #: One line for ``locbench list``; empty: the class's own ``description``.
    summary: str = ""
    #: Top-level modules that must import for the entry to work, and the command that installs them (a class may
    #: declare its own too: ``requires_modules`` and ``install_hint`` on the filter or dataset class).
    requires_modules: tuple[str, ...] = ()
    install_hint: str = ""
    #: The distribution that registered the entry through an entry-point group, and its version ("" for ours).
    distribution: str = ""
    distribution_version: str = ""
    #: Registered through an entry-point group (a plugin: imported in a child process first).
    plugin: bool = False
    #: Declared by a class of the registry's package (found by searching it).
    declared: bool = False
    #: Why the declaring module did not import when the package was searched (a missing optional dependency):
    #: the entry, named after the module, is unavailable with this reason ("" when it imported).
    import_error: str = ""

    def origin(self) -> str:
        """``entry point NAME = module:attr (distribution version)``: where a plugin came from, for messages."""
        dist = f" ({self.distribution} {self.distribution_version})" if self.distribution else ""
        return f"entry point {self.id} = {self.entry_point}{dist}"


class PluginUnavailable(DependencyNotInstalled):
    """A plugin that failed to import or is not a valid filter or dataset class; the message names its entry
    point and the cause."""


#: Seconds a plugin's import (and class check) may take in the probing child process; ``$LOCBENCH_PLUGIN_TIMEOUT``
#: overrides it (seconds > 0).
PLUGIN_IMPORT_TIMEOUT_S = 60.0


def plugin_import_timeout() -> float:
    """The time limit of a plugin's import, s: ``$LOCBENCH_PLUGIN_TIMEOUT`` when set, else the default."""
    raw = os.environ.get("LOCBENCH_PLUGIN_TIMEOUT", "")
    try:
        value = float(raw)
    except ValueError:
        return PLUGIN_IMPORT_TIMEOUT_S
    return value if value > 0 and value == value else PLUGIN_IMPORT_TIMEOUT_S


class DuplicateIdError(ValueError):
    """Two classes of the package declare one id."""


class Registry(Generic[T]):
    """An id -> lazily imported class mapping: the classes its package declares, plugins and hand registrations."""

    def __init__(self, kind: str, group: str, package: str) -> None:
        self.kind = kind
        self.group = group
        #: The package whose modules declare the built-in entries (``id`` on a class).
        self.package = package
        self._entries: dict[str, Entry] = {}
        self._plugins_loaded = False
        #: id -> entry of every class the package's searched modules declare, in the order they were found
        self._declared: dict[str, Entry] = {}
        #: the package's modules (names), once listed; those searched so far; whether all were
        self._modules: list[str] | None = None
        self._searched: set[str] = set()
        self._discovered = False
        #: id -> why the plugin does not load ("" when it does), from the probing child process
        self._probed: dict[str, str] = {}

    def register(
        self,
        id: str,
        entry_point: str,
        summary: str = "",
        requires_modules: tuple[str, ...] = (),
        install_hint: str = "",
    ) -> None:
        """Add an entry by hand; re-registering an id replaces it (a declared one too, also when the package is
        searched later)."""
        if ":" not in entry_point:
            raise ValueError(f"entry point {entry_point!r} must be 'module:attribute'")
        self._entries[id] = Entry(id, entry_point, summary, requires_modules, install_hint)

    def unregister(self, id: str) -> None:
        self._discover()  # a later search must not bring it back
        self._entries.pop(id, None)

    def snapshot(self) -> dict[str, Entry]:
        """A copy of the entries (tests restore it so that test-only registrations don't leak)."""
        self._load_all()
        return dict(self._entries)

    def restore(self, snap: dict[str, Entry]) -> None:
        self._entries = dict(snap)

    def forget_plugins(self) -> None:
        """Drop the plugin entries and what their probes found: the next use reads the entry points again (a
        distribution installed or removed meanwhile, a test's temporary one)."""
        self._entries = {k: e for k, e in self._entries.items() if not e.plugin}
        self._plugins_loaded = False
        self._probed.clear()

    # --- the package's own entries: classes that declare an id -------------------------------------------------

    def _package_modules(self) -> list[str]:
        """The names of the package's public modules, its sub-packages' included (walking imports the sub-packages,
        not the modules)."""
        if self._modules is None:
            pkg = importlib.import_module(self.package)
            prefix = pkg.__name__ + "."
            self._modules = [
                m.name
                for m in pkgutil.walk_packages(pkg.__path__, prefix)
                if not any(part.startswith("_") for part in m.name[len(prefix) :].split("."))
            ]
        return self._modules

    def _search(self, module_name: str) -> None:
        """Register every class ``module_name`` defines whose own body sets a non-empty ``id``.

        A module that does not import because a module outside the package's top-level package is missing (an
        optional dependency), or that raises :class:`DependencyNotInstalled`, becomes an entry under its own name,
        unavailable with the reason; any other failure is a bug of ours and raises.
        """
        if module_name in self._searched:
            return
        self._searched.add(module_name)
        try:
            module = importlib.import_module(module_name)
        except ImportError as exc:
            if (exc.name or "").split(".")[0] == self.package.split(".")[0]:
                raise
            reason = f"unavailable: {exc}; install with: pip install 'locbench[all]'"
            self._declare(self._unreadable(module_name, reason))
            return
        except DependencyNotInstalled as exc:
            self._declare(self._unreadable(module_name, f"unavailable: {exc}"))
            return
        for obj in list(vars(module).values()):
            if not (isinstance(obj, type) and obj.__module__ == module_name):
                continue  # imported from elsewhere: its own module declares it
            ident = vars(obj).get("id")  # inherited ids do not count: a subclass declares its own or none
            if isinstance(ident, str) and ident:
                self._declare(Entry(ident, f"{module_name}:{obj.__qualname__}", declared=True))

    @staticmethod
    def _unreadable(module_name: str, reason: str) -> Entry:
        return Entry(module_name.rsplit(".", 1)[1], f"{module_name}:", declared=True, import_error=one_line(reason))

    def _declare(self, entry: Entry) -> None:
        before = self._declared.get(entry.id)
        if before is not None and before.entry_point != entry.entry_point:
            raise DuplicateIdError(
                f"{self.kind} id {entry.id!r} is declared twice: by {before.entry_point} and {entry.entry_point}"
            )
        self._declared[entry.id] = entry
        self._entries.setdefault(entry.id, entry)  # a registration made by hand before the search wins

    def _discover(self) -> None:
        """Search every module of the package (once)."""
        if self._discovered:
            return
        for name in self._package_modules():
            self._search(name)
        self._discovered = True

    def _search_named(self, id: str) -> None:
        """Search the package's modules named ``id`` (a filter's module is usually named after it): a lookup by id
        then imports one module instead of every one."""
        if not self._discovered:
            for name in self._package_modules():
                if name.rsplit(".", 1)[1] == id:
                    self._search(name)

    def _load_all(self) -> None:
        """The package's entries, then the plugins (which cannot take an id the package declares)."""
        self._discover()
        self._load_plugins()

    def package_ids(self) -> list[str]:
        """The ids the package's own classes declare (not a plugin's, not one registered by hand; one replaced by
        hand is still listed), by the classes' ``order`` (0 without one), then by id; an entry whose module does
        not import here comes after the others."""
        self._discover()

        def key(ident: str) -> tuple[int, float, str]:
            cls = self.class_of(ident)
            return (0, float(getattr(cls, "order", 0)), ident) if cls is not None else (1, 0.0, ident)

        return sorted((i for i in self._declared if i in self._entries), key=key)

    def class_of(self, id: str) -> type[T] | None:
        """The class of ``id`` when its module imports here, whether or not the optional dependencies the class
        declares are installed (a class can be read without them: its declarations); else None."""
        cls, _ = self._import(self.entry(id))
        return cls

    # --- plugins ---------------------------------------------------------------------------------------------

    def _load_plugins(self) -> None:
        if self._plugins_loaded:
            return
        self._plugins_loaded = True
        for ep in importlib.metadata.entry_points(group=self.group):
            if ep.name not in self._entries:
                dist = ep.dist
                self._entries[ep.name] = Entry(
                    ep.name,
                    ep.value,
                    distribution=dist.name if dist is not None else "",
                    distribution_version=dist.version if dist is not None else "",
                    plugin=True,
                )

    def ids(self) -> list[str]:
        """Every registered id, sorted."""
        self._load_all()
        return sorted(self._entries)

    def entry(self, id: str) -> Entry:
        if id not in self._entries:
            self._search_named(id)
        if id not in self._entries:
            self._load_all()
        try:
            return self._entries[id]
        except KeyError:
            raise UnknownIdError(f"unknown {self.kind} {id!r}; valid: {', '.join(self.ids())}") from None

    def summary(self, id: str) -> str:
        """The one line ``locbench list`` prints: the registration's summary, else the class's ``description``
        (a plugin declares it on its class), else where the plugin came from."""
        e = self.entry(id)
        if e.summary:
            return e.summary
        cls, _ = self._import(e)
        described = str(getattr(cls, "description", "") or "") if cls is not None else ""
        if described or not e.plugin:
            return described or f"{e.entry_point.split(':')[0]} (its class cannot be read here)"
        origin = f" ({e.distribution} {e.distribution_version})" if e.distribution else ""
        return f"plugin from {e.entry_point}{origin}"

    def missing_dependency(self, id: str) -> str | None:
        """None when the entry's optional dependencies import, else 'unavailable: install ...'.

        Checked in order: the registration's ``requires_modules`` (without importing the class), the class's
        module itself, then the ``requires_modules`` the class declares (with its ``install_hint``).
        """
        e = self.entry(id)
        reason = _missing_module(e.requires_modules, e.install_hint)
        if reason is not None:
            return reason
        cls, reason = self._import(e)
        if cls is None:
            return reason
        return _missing_module(tuple(getattr(cls, "requires_modules", ())), getattr(cls, "install_hint", "") or "")

    def _import(self, e: Entry) -> tuple[type[T] | None, str | None]:
        """The entry's class, or None and why it does not load (a missing optional dependency, a broken plugin)."""
        if e.import_error:
            return None, e.import_error
        if e.plugin:
            broken = self.load_error(e.id)
            if broken is not None:
                return None, broken
        module_name, attr = e.entry_point.split(":", 1)
        try:
            module = importlib.import_module(module_name)
        except DependencyNotInstalled as exc:  # a module that names its missing dependency itself
            return None, one_line(f"unavailable: {e.origin() + ': ' if e.plugin else ''}{exc}")
        except ImportError as exc:
            missing = getattr(exc, "name", None) or ""
            if missing.split(".")[0] == "locbench" and not e.plugin:
                raise  # a broken entry point of our own is a bug, not a missing dependency
            hint = e.install_hint or "pip install 'locbench[all]'"
            where = f"{e.origin()}: " if e.plugin else ""
            return None, f"unavailable: {where}{exc}; install with: {hint}"
        except Exception as exc:
            if not e.plugin:
                raise
            # it imported in the probing child: a failure here is one that depends on the moment
            return None, self._broken(e, describe_error(exc))
        cls: type[T] = getattr(module, attr)
        return cls, None

    def load_error(self, id: str) -> str | None:
        """Why the plugin ``id`` does not load ("unavailable: entry point ... failed to load: ..."), else None
        (also for an entry of our own); the plugins of the group are probed in a child process on first need
        (:func:`probe_plugins`). A missing module is not a load error but a missing dependency
        (:meth:`missing_dependency`)."""
        e = self.entry(id)
        if not e.plugin:
            return None
        if id not in self._probed:
            todo = [x for x in self._entries.values() if x.plugin and x.id not in self._probed]
            self._probed |= probe_plugins(self.kind, todo, plugin_import_timeout())
        reason = self._probed.get(id, "")
        return self._broken(e, reason) if reason else None

    def _broken(self, e: Entry, reason: str) -> str:
        return one_line(f"unavailable: {e.origin()} failed to load: {reason}")

    def unavailable_reason(self, id: str) -> str | None:
        """Why the entry cannot run here with its default parameters: a missing dependency or missing data.

        A class may define a classmethod ``data_unavailable()`` returning the reason its default data is
        absent (recorded datasets), or None.
        """
        reason = self.missing_dependency(id)
        if reason is not None:
            return reason
        probe = getattr(self.load(id), "data_unavailable", None)
        return probe() if callable(probe) else None

    def load(self, id: str) -> type[T]:
        """Import and return the registered class; ``DependencyNotInstalled`` when an optional dependency is missing."""
        reason = self.missing_dependency(id)
        if reason is not None:
            error = PluginUnavailable if self.load_error(id) is not None else DependencyNotInstalled
            raise error(f"{self.kind} {id!r} is {reason}")
        cls, _ = self._import(self.entry(id))
        assert cls is not None  # it imported in missing_dependency
        return cls

    def __iter__(self) -> Iterator[str]:
        return iter(self.ids())

    def __contains__(self, id: object) -> bool:
        return isinstance(id, str) and id in self.ids()


def _missing_module(modules: tuple[str, ...], hint: str) -> str | None:
    """'unavailable: M is not installed; install it with: HINT' for the first of ``modules`` that does not import."""
    for mod in modules:
        try:
            importlib.import_module(mod)
        except ImportError:
            return f"unavailable: {mod} is not installed; install it with: {hint or 'pip install ' + mod}"
    return None


class PluginClassError(TypeError):
    """A plugin's entry point names no attribute, or not a class of its group (:func:`check_class`)."""


def describe_error(exc: BaseException) -> str:
    """``Type: message (file.py:line)`` of an exception raised by a plugin's import, on one line; the line is the
    innermost one of the plugin's code (not of locbench, which raised on its behalf, nor of importlib). The
    findings of :func:`check_class` and a ``SyntaxError`` (whose message has its line) have no location."""
    text = " ".join(str(exc).split())
    if isinstance(exc, PluginClassError):
        return text
    if isinstance(exc, SyntaxError):
        return f"SyntaxError: {text}"
    frames = [f for f in traceback.extract_tb(exc.__traceback__) if not f.filename.startswith("<frozen")]
    theirs = [f for f in frames if not f.filename.startswith(_PACKAGE_DIR)] or frames
    where = f" ({theirs[-1].filename.rsplit('/', 1)[-1]}:{theirs[-1].lineno})" if theirs else ""
    return f"{type(exc).__name__}: {text}{where}" if text else f"{type(exc).__name__}{where}"


#: The folder of the locbench package (frames in it are not a plugin's).
_PACKAGE_DIR = os.path.dirname(os.path.abspath(__file__)) + os.sep


def check_class(kind: str, cls: object) -> None:
    """Raise :class:`PluginClassError` (or the config's own error) unless ``cls`` is what a plugin of ``kind``
    registers.

    A filter: a subclass of :class:`~locbench.filters.base.Filter` whose ``Config`` is a
    :class:`~locbench.filters.base.FilterConfig` dataclass that builds with its defaults and whose tuning ranges
    are valid; a dataset: a :class:`~locbench.datasets.dataset.DatasetBuilder` whose ``Params`` is a dataclass (a
    dataset's defaults may need a path given).
    """
    if kind == "filter":
        from locbench.core.tunable import tunable_fields
        from locbench.filters.base import Filter, FilterConfig

        base, params, params_base = Filter, "Config", FilterConfig
    else:
        from locbench.datasets.dataset import DatasetBuilder

        base, params, params_base, tunable_fields = DatasetBuilder, "Params", object, None  # type: ignore[assignment]
    if not isinstance(cls, type) or not issubclass(cls, base):
        raise PluginClassError(f"{_name(cls)} is not a subclass of {base.__module__}.{base.__name__}")
    config = getattr(cls, params, None)
    if not (isinstance(config, type) and issubclass(config, params_base) and dataclasses.is_dataclass(config)):
        raise PluginClassError(f"{cls.__name__}.{params} must be a dataclass deriving from {params_base.__name__}")
    if tunable_fields is not None:
        config()  # a filter runs with its default config: the defaults must pass its own checks
        tunable_fields(config)  # every tuning range well-formed


def _name(obj: object) -> str:
    """``module.Name`` of a class or function, else its type's: how a wrong registration is named."""
    named = obj if isinstance(obj, type) or callable(obj) else type(obj)
    return f"{getattr(named, '__module__', '?')}.{getattr(named, '__qualname__', repr(named))}" + (
        "" if named is obj else " instance"
    )


#: The code the probing child runs: ``python -c PROBE KIND ENTRY_POINT ...``; one JSON line per entry point.
_PROBE = "import sys; from locbench.registry import _probe_main; _probe_main(sys.argv[1], sys.argv[2:])"


def _probe_main(kind: str, entry_points: list[str]) -> None:
    """In the probing child: import each entry point and check its class, printing ``{"error": ...}`` for each
    ("" when it loads) as soon as it is done, so the parent knows which one hangs or kills the child. The reports
    go to the original stdout; what a plugin prints goes to stderr (discarded by the parent)."""
    report = os.fdopen(os.dup(1), "w")
    os.dup2(2, 1)
    for ep in entry_points:
        module_name, attr = ep.split(":", 1)
        error = ""
        try:
            module = importlib.import_module(module_name)
            if not hasattr(module, attr):
                raise PluginClassError(f"module {module_name!r} has no attribute {attr!r}")
            check_class(kind, getattr(module, attr))
        except ImportError:
            error = ""  # a missing module: the parent reports it as a missing dependency, with its install hint
        except BaseException as exc:  # SystemExit too: reported, and the next entry point is probed
            error = describe_error(exc)
        report.write(json.dumps({"error": error}) + "\n")
        report.flush()


def probe_plugins(kind: str, entries: list[Entry], timeout_s: float) -> dict[str, str]:
    """Import and check each plugin entry in a child Python process: id -> why it does not load, "" if it does.

    One child for all of them; each entry gets ``timeout_s`` seconds (the child's start included for the first),
    after which the child is killed, the entry is recorded as hanging and the rest go to a fresh child. A child
    that dies takes the entry it was on with it, with its exit status. A ``KeyboardInterrupt`` kills the child
    and propagates. The child sees this process's ``sys.path``.
    """
    verdicts: dict[str, str] = {}
    left = list(entries)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    while left:
        argv = [sys.executable, "-c", _PROBE, kind, *(e.entry_point for e in left)]
        proc = subprocess.Popen(
            argv, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL, env=env
        )
        try:
            assert proc.stdout is not None
            buf = b""
            deadline = time.monotonic() + timeout_s
            while left:
                wait = deadline - time.monotonic()
                ready = select.select([proc.stdout], [], [], max(0.0, min(wait, 1.0)))[0] if wait > 0 else []
                if not ready:
                    if time.monotonic() < deadline:
                        continue
                    verdicts[left.pop(0).id] = f"its import did not finish within {timeout_s:g} s"
                    break
                chunk = os.read(proc.stdout.fileno(), 65536)
                if not chunk:  # the child ended before reporting the entry it was on
                    code = proc.wait()
                    how = f"signal {_signal_name(-code)}" if code < 0 else f"exit code {code}"
                    verdicts[left.pop(0).id] = f"its import ended the process ({how})"
                    break
                buf += chunk
                while b"\n" in buf and left:
                    line, buf = buf.split(b"\n", 1)
                    verdicts[left.pop(0).id] = _verdict(line)
                    deadline = time.monotonic() + timeout_s
        finally:
            if proc.poll() is None:
                proc.kill()
            proc.wait()
            if proc.stdout is not None:
                proc.stdout.close()
    return verdicts


def _verdict(line: bytes) -> str:
    """The error of one report line of the probing child ("" when the entry loads)."""
    try:
        return str(json.loads(line)["error"])
    except (ValueError, KeyError, TypeError):
        return f"the probing process reported {line[:200]!r}"


def _signal_name(sig: int) -> str:
    import signal

    try:
        return signal.Signals(sig).name
    except ValueError:
        return str(sig)


FILTERS: Registry[Any] = Registry("filter", "locbench.filters", "locbench.filters")
DATASETS: Registry[Any] = Registry("dataset", "locbench.datasets", "locbench.datasets")

# --- making things from specs -------------------------------------------------------------------


@dataclass(frozen=True)
class Resolved:
    """A spec resolved against the registry: id, the typed params and the canonical name."""

    id: str
    params: Any
    name: str

    def params_dict(self) -> dict[str, Any]:
        return params_to_dict(self.params)

    @property
    def spec(self) -> Spec:
        """The canonical name as a typed :class:`Spec` (what the runner and the store carry)."""
        return Spec.parse(self.name)


def resolve_filter(spec: str) -> Resolved:
    """Parse ``"ekf_landmarks[association=nearest]"`` into its class's typed config."""
    ident, raw = parse_spec(spec)
    cls = FILTERS.load(ident)
    cfg = build_params(cls.Config, raw, ident)
    return Resolved(ident, cfg, format_spec(ident, non_default_params(cfg)))


def resolve_dataset(spec: str) -> Resolved:
    """Parse ``"room[kidnap_m=2]"`` into its builder's typed parameters."""
    ident, raw = parse_spec(spec)
    cls = DATASETS.load(ident)
    params = build_params(cls.Params, raw, ident)
    return Resolved(ident, params, format_spec(ident, non_default_params(params)))


def dataset_recording(spec: str) -> str | None:
    """The recording the dataset ``spec`` reads (:meth:`locbench.datasets.dataset.DatasetBuilder.recording`), or
    None for a synthetic world."""
    r = resolve_dataset(spec)
    recording: str | None = DATASETS.load(r.id).recording(r.params)
    return recording


def make_filter(spec: str | Resolved) -> Any:
    """A fresh, un-reset filter for ``spec``."""
    r = resolve_filter(spec) if isinstance(spec, str) else spec
    return FILTERS.load(r.id)(r.params)


def make_dataset(spec: str | Resolved, seed: int | np.random.Generator = 0) -> Any:
    """Build the dataset for ``spec``.

    With an integer ``seed`` the randomness comes from :func:`locbench.core.seeding.dataset_rng`, exactly as in
    the runner, so ``make_dataset("room", 3)`` is the data every filter saw for seed 3.

    Raises
    ------
    ConfigError
        The built dataset breaks the contract (:meth:`locbench.datasets.dataset.Dataset.check`: no odometry, events
        out of order, truth not spanning the events, a declared sensor stream empty ...); the message names the
        dataset and, for recorded data, its files.
    """
    r = resolve_dataset(spec) if isinstance(spec, str) else spec
    return build_dataset(DATASETS.load(r.id), r, seed)


def build_dataset(builder_cls: type, r: Resolved, seed: int | np.random.Generator) -> Any:
    """Build the dataset of ``r`` with its builder class given (a worker that has no registry entry for it)."""
    from locbench.datasets.dataset import realisation_name

    # a parameter that changes only the initial belief leaves the realisation the plain name's
    gen = seed if isinstance(seed, np.random.Generator) else dataset_rng(realisation_name(r.name, r.params), seed)
    ds = builder_cls().build(r.params, gen)
    ds = dataclasses.replace(ds, id=r.id, name=r.name, params=r.params_dict())
    ds.check()  # every dataset, synthetic or recorded: a broken one is an error naming its files, never a run
    return ds
