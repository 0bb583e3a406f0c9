"""Lazy registries of filters and datasets.

Entries are import paths (``"locbench.filters.ekf_landmarks:LandmarkEKF"``), imported only when a
filter or dataset is made, so a missing optional dependency shows as "unavailable: install ..."
instead of an ImportError at start-up. Third-party packages can add entries through the
``locbench.filters`` and ``locbench.datasets`` entry-point groups.
"""

from __future__ import annotations

import dataclasses
import importlib
import importlib.metadata
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

import numpy as np

from locbench.errors import DependencyNotInstalled, UnknownIdError
from locbench.seeding import dataset_rng
from locbench.spec import Spec, build_params, format_spec, non_default_params, params_to_dict, parse_spec

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


class Registry(Generic[T]):
    """An id -> lazily imported class mapping."""

    def __init__(self, kind: str, group: str) -> None:
        self.kind = kind
        self.group = group
        self._entries: dict[str, Entry] = {}
        self._plugins_loaded = False

    def register(
        self,
        id: str,
        entry_point: str,
        summary: str = "",
        requires_modules: tuple[str, ...] = (),
        install_hint: str = "",
    ) -> None:
        """Add an entry; re-registering an id replaces it."""
        if ":" not in entry_point:
            raise ValueError(f"entry point {entry_point!r} must be 'module:attribute'")
        self._entries[id] = Entry(id, entry_point, summary, requires_modules, install_hint)

    def unregister(self, id: str) -> None:
        self._entries.pop(id, None)

    def snapshot(self) -> dict[str, Entry]:
        """A copy of the entries (tests restore it so that test-only registrations don't leak)."""
        self._load_plugins()
        return dict(self._entries)

    def restore(self, snap: dict[str, Entry]) -> None:
        self._entries = dict(snap)

    def _load_plugins(self) -> None:
        if self._plugins_loaded:
            return
        self._plugins_loaded = True
        for ep in importlib.metadata.entry_points(group=self.group):
            if ep.name not in self._entries:
                self.register(ep.name, ep.value)
                dist = ep.dist
                if dist is not None:
                    e = self._entries[ep.name]
                    self._entries[ep.name] = dataclasses.replace(
                        e, distribution=dist.name, distribution_version=dist.version
                    )

    def ids(self) -> list[str]:
        """Every registered id, sorted."""
        self._load_plugins()
        return sorted(self._entries)

    def entry(self, id: str) -> Entry:
        self._load_plugins()
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
        origin = f" ({e.distribution} {e.distribution_version})" if e.distribution else ""
        return described or f"plugin from {e.entry_point}{origin}"

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
        """The entry's class, or None and why its module does not import (a missing optional dependency)."""
        module_name, attr = e.entry_point.split(":", 1)
        try:
            module = importlib.import_module(module_name)
        except ImportError as exc:
            missing = getattr(exc, "name", None) or ""
            if missing.split(".")[0] == "locbench":
                raise  # a broken entry point of our own is a bug, not a missing dependency
            hint = e.install_hint or "pip install 'locbench[all]'"
            return None, f"unavailable: {exc}; install with: {hint}"
        cls: type[T] = getattr(module, attr)
        return cls, None

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
            raise DependencyNotInstalled(f"{self.kind} {id!r} is {reason}")
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


FILTERS: Registry[Any] = Registry("filter", "locbench.filters")
DATASETS: Registry[Any] = Registry("dataset", "locbench.datasets")

FILTERS.register(
    "odometry",
    "locbench.filters.odometry:OdometryFilter",
    "dead reckoning from odometry increments; the baseline row of every table",
)
FILTERS.register(
    "ekf_landmarks",
    "locbench.filters.ekf_landmarks:LandmarkEKF",
    "EKF, wheel-encoder motion model and range-bearing landmarks, optional GPS fixes (reports 003, 001)",
)

FILTERS.register(
    "ukf_landmarks",
    "locbench.filters.ukf_landmarks:LandmarkUKF",
    "unscented KF (filterpy, Merwe sigma points) with ekf_landmarks' motion, landmark, range and fix models",
    requires_modules=("filterpy",),
    install_hint="pip install 'locbench[filterpy]'",
)
FILTERS.register(
    "ekf_lines",
    "locbench.filters.ekf_lines:LineEKF",
    "EKF on a map of lines, chi-square gated association, Joseph form (report 002)",
)
FILTERS.register(
    "ekf_icp",
    "locbench.filters.ekf_icp:IcpEKF",
    "EKF whose update is ICP between the scan and a scan ray-cast from the occupancy grid (report 000)",
)
FILTERS.register(
    "kf_linear",
    "locbench.filters.kf_linear:LinearKF",
    "linear Kalman filter (filterpy) with a scan-database pose measurement (report 004)",
    requires_modules=("filterpy",),
    install_hint="pip install 'locbench[filterpy]'",
)
FILTERS.register(
    "pf",
    "locbench.filters.pf:ParticleFilter",
    "Monte Carlo localization: encoder motion model, landmark and laser likelihood-field models, augmented MCL",
)
FILTERS.register(
    "gtsam_fls",
    "locbench.filters.gtsam_fls:GtsamFixedLagSmoother",
    "gtsam fixed-lag smoother (incremental or batch): odometry between-factors, bearing-range factors, fixes",
    requires_modules=("gtsam",),
    install_hint="pip install 'locbench[gtsam]'",
)

#: The built-in filters in registration order (the baseline first): every suite's "every filter".
BUILTIN_FILTERS: tuple[str, ...] = tuple(FILTERS._entries)

DATASETS.register(
    "room",
    "locbench.datasets.synthetic.scenarios:RoomScenario",
    "report 003's 7 m x 2 m room: 4 landmarks, start + 5 waypoints, Kinect-like sensor",
)
DATASETS.register(
    "office",
    "locbench.datasets.synthetic.scenarios:OfficeScenario",
    "one office floor with walls, doors, landmarks and a waypoint tour; every sensor",
)
DATASETS.register(
    "tiny_line",
    "locbench.datasets.synthetic.scenarios:TinyLineScenario",
    "a 10 s straight drive past 3 landmarks (conformance checks)",
)
DATASETS.register(
    "tiny_circle",
    "locbench.datasets.synthetic.scenarios:TinyCircleScenario",
    "a circle whose heading crosses +-pi, 4 landmarks (conformance checks)",
)

DATASETS.register(
    "lap",
    "locbench.datasets.synthetic.lap:LapScenario",
    "report 000's office lap: 0.05 m grid, rectangular lap, Hokuyo-like laser, people not on the map",
)
DATASETS.register(
    "line_room",
    "locbench.datasets.synthetic.line_room:LineRoomScenario",
    "report 002's polygonal rooms for the line-map EKF",
)
DATASETS.register(
    "scan_grid",
    "locbench.datasets.synthetic.scan_grid:ScanGridScenario",
    "report 004's scan database at grid poses, translate-or-rotate commands of 1 s",
)
DATASETS.register(
    "landmark_geometry",
    "locbench.datasets.synthetic.landmark_geometry:LandmarkGeometryScenario",
    "report 001's paths x landmark layouts, landmarks detected by a 151-ray laser; GPS variant",
)

DATASETS.register(
    "mrclam",
    "locbench.datasets.recorded.mrclam:MrclamDataset",
    "UTIAS MRCLAM (recorded): one robot of a dataset, (v, omega) odometry, camera landmark sightings, Vicon truth",
)
DATASETS.register(
    "lost_in_the_woods",
    "locbench.datasets.recorded.lost_in_the_woods:LostInTheWoods",
    "Barfoot's Lost in the Woods (recorded): v/omega at 10 Hz, range-bearing to 17 tubes, Vicon truth",
)
DATASETS.register(
    "intel",
    "locbench.datasets.recorded.intel:IntelDataset",
    "Intel Research Lab (recorded CARMEN log): odometry, 180-beam laser, grid and lines from the GMapping "
    "reference, Kuemmerle relations",
)

DATASETS.register(
    "radish",
    "locbench.datasets.recorded.radish:RadishDataset",
    "Radish corrected CARMEN logs (recorded, any NAME-corrected.log.gz): laser, map and SLAM reference; raw odometry "
    "for intel, aces, freiburg-079, semi-synthetic elsewhere",
)
DATASETS.register(
    "librsf",
    "locbench.datasets.recorded.librsf:LibrsfDataset",
    "libRSF ranging sets (Pfeifer, TU Chemnitz): Indoor UWB (real) and M3500 / W3500 with non-Gaussian range noise",
)
DATASETS.register(
    "plaza",
    "locbench.datasets.recorded.plaza:PlazaDataset",
    "CMU Plaza range-only runs (recorded, Djugash et al. 2009): odometry, radio ranges to 4 beacons, GPS truth",
)
DATASETS.register(
    "rosbag",
    "locbench.datasets.recorded.rosbag:RosbagDataset",
    "a user's ROS 1 / ROS 2 bag: nav_msgs/Odometry, sensor_msgs/LaserScan, a truth pose topic, a map_server map",
    requires_modules=("rosbags",),
    install_hint="pip install 'locbench[ros]'",
)
DATASETS.register(
    "textlog",
    "locbench.datasets.recorded.textlog:TextlogDataset",
    "a user's plain-text log (locbench-textlog v1): JSON-lines events, TUM truth, map_server map, landmark files",
)

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


def make_filter(spec: str | Resolved) -> Any:
    """A fresh, un-reset filter for ``spec``."""
    r = resolve_filter(spec) if isinstance(spec, str) else spec
    return FILTERS.load(r.id)(r.params)


def make_dataset(spec: str | Resolved, seed: int | np.random.Generator = 0) -> Any:
    """Build the dataset for ``spec``.

    With an integer ``seed`` the randomness comes from :func:`locbench.seeding.dataset_rng`, exactly as in
    the runner, so ``make_dataset("room", 3)`` is the data every filter saw for seed 3.

    Raises
    ------
    ConfigError
        The built dataset breaks the contract (:meth:`locbench.datasets.base.Dataset.check`: no odometry, events
        out of order, truth not spanning the events, a declared sensor stream empty ...); the message names the
        dataset and, for recorded data, its files.
    """
    r = resolve_dataset(spec) if isinstance(spec, str) else spec
    return build_dataset(DATASETS.load(r.id), r, seed)


def build_dataset(builder_cls: type, r: Resolved, seed: int | np.random.Generator) -> Any:
    """Build the dataset of ``r`` with its builder class given (a worker that has no registry entry for it)."""
    gen = seed if isinstance(seed, np.random.Generator) else dataset_rng(r.name, seed)
    ds = builder_cls().build(r.params, gen)
    ds = dataclasses.replace(ds, id=r.id, name=r.name, params=r.params_dict())
    ds.check()  # every dataset, synthetic or recorded: a broken one is an error naming its files, never a run
    return ds
