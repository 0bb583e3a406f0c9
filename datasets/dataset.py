"""The dataset contract: world map, ground truth, waypoints, kidnaps, nominal noise and events.

Frames: world frame x-y in metres, headings in radians wrapped to (-pi, pi].
"""

from __future__ import annotations

import abc
import dataclasses
import enum
import itertools
import math
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from locbench.core.errors import ConfigError, one_line
from locbench.core.events import (
    EVENT_TYPES,
    Event,
    LandmarkObservations,
    LaserScan,
    Odometry,
    PoseFix,
    RangeObservations,
    event_order,
)
from locbench.core.geometry import is_symmetric_psd, wrap_angle
from locbench.core.grid import OccupancyGrid  # one of the map types here; loaders and plugins import it from here
from locbench.core.runkey import RUN_KEY_OMIT_IF_DEFAULT
from locbench.core.spec import bound

FloatArray = npt.NDArray[np.float64]


class MapKind(enum.Enum):
    """The kinds of world map a filter can require."""

    OCCUPANCY = "occupancy"
    LANDMARKS = "landmarks"
    LINES = "lines"


@dataclass(frozen=True, eq=False)
class Landmarks:
    """Point landmarks: ``ids`` (n,) int64 and world positions ``xy`` (n, 2) in m; optional ``std_xy`` (n, 2)."""

    ids: npt.NDArray[np.int64]
    xy: FloatArray
    std_xy: FloatArray | None = None

    def __len__(self) -> int:
        return int(self.ids.shape[0])

    def index_of(self) -> dict[int, int]:
        """Map landmark id -> row in ``xy``."""
        return {int(i): k for k, i in enumerate(self.ids)}


@dataclass(frozen=True, eq=False)
class LineMap:
    """Line segments ``segments`` (n, 4) as (x1, y1, x2, y2) in m, world frame."""

    segments: FloatArray

    def __len__(self) -> int:
        return int(self.segments.shape[0])

    def rho_psi(self) -> FloatArray:
        """Each segment's infinite line in Hessian normal form, shape (n, 2).

        ``rho`` >= 0 is the distance from the world origin (m) and ``psi`` the direction of the
        normal (rad), so that the line is {p : p . (cos psi, sin psi) = rho} (report 002).
        """
        s = self.segments
        d = s[:, 2:4] - s[:, 0:2]
        psi = np.arctan2(d[:, 0], -d[:, 1])  # normal = direction rotated by -90 deg
        rho = s[:, 0] * np.cos(psi) + s[:, 1] * np.sin(psi)
        neg = rho < 0
        rho = np.where(neg, -rho, rho)
        psi = np.where(neg, psi + np.pi, psi)
        return np.stack([rho, wrap_angle(psi)], axis=-1)

    def lengths(self) -> FloatArray:
        """Segment lengths, m, shape (n,)."""
        d = self.segments[:, 2:4] - self.segments[:, 0:2]
        return np.hypot(d[:, 0], d[:, 1])


@dataclass(frozen=True, eq=False)
class WorldMap:
    """The map handed to filters: any of an occupancy grid, landmarks and line segments."""

    occupancy: OccupancyGrid | None = None
    landmarks: Landmarks | None = None
    lines: LineMap | None = None

    @property
    def kinds(self) -> frozenset[MapKind]:
        out = set()
        if self.occupancy is not None:
            out.add(MapKind.OCCUPANCY)
        if self.landmarks is not None and len(self.landmarks) > 0:
            out.add(MapKind.LANDMARKS)
        if self.lines is not None and len(self.lines) > 0:
            out.add(MapKind.LINES)
        return frozenset(out)


@dataclass(frozen=True, eq=False)
class Gaussian2:
    """A Gaussian belief over the planar pose: ``mean`` (3,) (x m, y m, theta rad) and ``cov`` (3, 3)."""

    mean: FloatArray
    cov: FloatArray


@dataclass(frozen=True, eq=False)
class Trajectory2D:
    """A time series of world-frame poses: ``t`` (n,) s, ``xy`` (n, 2) m, ``theta`` (n,) rad."""

    t: FloatArray
    xy: FloatArray
    theta: FloatArray

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def poses(self) -> FloatArray:
        """Stacked (n, 3) poses."""
        return np.column_stack([self.xy, self.theta])

    def path_length(self) -> float:
        """Total distance travelled, m."""
        return float(np.sum(np.hypot(*np.diff(self.xy, axis=0).T))) if len(self) > 1 else 0.0


@dataclass(frozen=True, eq=False)
class Waypoints:
    """Marked points on the floor and the times at which the robot stands on them.

    ``t`` (n,) s and ``xy`` (n, 2) m; waypoint j (from 1) is row j-1. The start point is not a waypoint.
    """

    t: FloatArray
    xy: FloatArray

    def __len__(self) -> int:
        return int(self.t.shape[0])


@dataclass(frozen=True, eq=False)
class Relations:
    """Reference relative poses between pairs of times (Kuemmerle et al. 2009, "On measuring the accuracy of SLAM
    algorithms", Auton. Robots 27(4)).

    Row k says: the pose at ``t2[k]`` seen from the pose at ``t1[k]`` is ``delta[k]`` = (dx m, dy m, dtheta rad),
    in the frame of the pose at ``t1[k]``. It is relative, not an absolute trajectory.
    """

    t1: FloatArray
    t2: FloatArray
    delta: FloatArray

    def __len__(self) -> int:
        return int(self.t1.shape[0])


@dataclass(frozen=True)
class Kidnap:
    """At time ``t`` (s) the true pose jumps by ``delta`` (dx m, dy m, dtheta rad, world frame).

    Filters are told nothing.
    """

    t: float
    delta: tuple[float, float, float]


@dataclass(frozen=True, kw_only=True)
class MotionNoiseFields:
    """The odometry noise of the motion model, one field each: a dataset's nominal values (the first fields of
    :class:`SensorSpec`) and a filter config's overrides of them (``MotionNoiseConfig`` of
    :mod:`locbench.filters.motion`, None there taking the dataset's value), which ``resolve_motion_noise`` of that
    module turns into the noise a filter uses.

    Attributes
    ----------
    wheelbase_m : float or None
        Distance between the drive wheels, m (report 003 eq. 1); > 0 where given (a filter config refuses another
        value).
    encoder_k_left, encoder_k_right : float or None
        Encoder noise constants k_L, k_R in sqrt(m): the wheel travel variance grows as
        k^2 * sum |delta wheel| (report 003 eq. 10).
    odometry_sigma_xy_per_m, odometry_sigma_theta_per_m : float or None
        Per-step increment noise for filters that use (dx, dy, dtheta) directly, as standard deviation
        per sqrt(m) travelled (m / sqrt(m), rad / sqrt(m)).
    odometry_sigma_theta_per_rad : float or None
        Extra heading noise per sqrt(rad) turned.
    twist_sigma_v_mps, twist_sigma_omega_radps : float or None
        White noise of a MEASURED twist (speed m/s, turn rate rad/s) per odometry sample, for datasets whose
        odometry is (v, omega) held for ``dt`` (MRCLAM, Lost in the Woods): the increment's variance is
        (sigma * dt)^2 per component. A filter config's run key holds them only when set
        (:data:`~locbench.core.runkey.RUN_KEY_OMIT_IF_DEFAULT`).
    """

    wheelbase_m: float | None = field(default=None, metadata=bound(0.0, low_open=True, optional=True))
    encoder_k_left: float | None = None
    encoder_k_right: float | None = None
    odometry_sigma_xy_per_m: float | None = None
    odometry_sigma_theta_per_m: float | None = None
    odometry_sigma_theta_per_rad: float | None = None
    twist_sigma_v_mps: float | None = field(default=None, metadata=RUN_KEY_OMIT_IF_DEFAULT)
    twist_sigma_omega_radps: float | None = field(default=None, metadata=RUN_KEY_OMIT_IF_DEFAULT)


@dataclass(frozen=True, kw_only=True)
class SensorSpec(MotionNoiseFields):
    """The nominal sensor noise and geometry handed to filters (the simulator's true noise may differ).

    Every field is optional: a dataset sets what its sensors provide. The odometry noise comes first, the fields of
    :class:`MotionNoiseFields`; then:

    Attributes
    ----------
    landmark_sigma_range_m, landmark_sigma_bearing_rad : float or None
        Range-bearing noise (report 003 eq. 9).
    landmark_min_range_m, landmark_max_range_m, landmark_fov_rad : float or None
        Landmark sensor limits; ``landmark_fov_rad`` is the full field of view centred on x.
    laser_sigma_m : float or None
        Range noise of the laser, m.
    pose_fix_sigma_xy_m : float or None
        Standard deviation of a GPS-like fix per axis, m.
    range_sigma_m : float or None
        Standard deviation of a range-only (radio beacon) measurement, m.
    process_sigma_xy_m, process_sigma_theta_rad : float or None
        Standard deviation of the additive process noise Q per odometry step (report 003 eq. 8), per world
        axis (m) and on the heading (rad): unmodelled motion on top of the odometry noise. None leaves the
        filters' default (report 003's 1 mm, 0.5 mrad); a model-matched world, whose motion is exactly the
        odometry model, declares 0.
    """

    landmark_sigma_range_m: float | None = None
    landmark_sigma_bearing_rad: float | None = None
    landmark_min_range_m: float | None = None
    landmark_max_range_m: float | None = None
    landmark_fov_rad: float | None = None
    laser_sigma_m: float | None = None
    pose_fix_sigma_xy_m: float | None = None
    range_sigma_m: float | None = None
    process_sigma_xy_m: float | None = None
    process_sigma_theta_rad: float | None = None


@dataclass(frozen=True)
class FlaggedSample:
    """A recorded sample that broke a physical bound and was left out (:mod:`~locbench.datasets.recorded.plausibility`).

    Attributes
    ----------
    source : str
        The file it was read from.
    line : int or None
        Its 1-based line in the file (None in a binary format).
    t : float
        Its time, s.
    stream : str
        What the sample is ("ground-truth", "odometry", "UWB range").
    quantity : str
        The quantity that broke its bound, with its unit ("apparent speed, m/s").
    value : float
        The sample's value of that quantity.
    bound : str
        The bound, in words.
    """

    source: str
    line: int | None
    t: float
    stream: str
    quantity: str
    value: float
    bound: str

    def describe(self) -> str:
        """One line: where, when, what and which bound."""
        where = f"{self.source}:{self.line}" if self.line is not None else self.source
        return f"{where} at t={self.t!r} s: {self.stream} {self.quantity} {self.value:.4g}, expected {self.bound}"

    def record(self) -> dict[str, Any]:
        """JSON-friendly form for a run's provenance."""
        return {
            "source": self.source,
            "line": self.line,
            "t": self.t,
            "stream": self.stream,
            "quantity": self.quantity,
            "value": self.value if math.isfinite(self.value) else repr(self.value),
            "bound": self.bound,
        }


#: Labels of :attr:`Dataset.truth_label`: what the "ground truth" trajectory really is.
TRUTH_LABELS = ("ground truth", "SLAM reference")


@dataclass(frozen=True, eq=False)
class Dataset:
    """Everything a run needs: events in time order plus what metrics and filters are given.

    Attributes
    ----------
    id : str
        Registry id (``room``); ``name`` adds the parameters (``room[kidnap_m=2]``).
    params : dict
        The resolved parameters (all fields, JSON-friendly).
    events : tuple of Event
        Sorted by time; at equal times odometry comes first.
    ground_truth : Trajectory2D
        True poses, world frame.
    initial : Gaussian2
        The initial belief handed to filters.
    world : WorldMap
        The map handed to filters.
    sensors : SensorSpec
        The nominal noise handed to filters.
    waypoints : Waypoints or None
    kidnaps : tuple of Kidnap
    name : str
        The display / storage name ``id[key=value,...]`` (non-default parameters only).
    metadata : dict
        Free-form provenance (calibration, generator version, source files).
    relations : Relations or None
        Reference relative poses for the relation error (Intel); None elsewhere.
    truth_label : str
        ``"ground truth"`` for a measured truth (simulator, Vicon, GPS) or ``"SLAM reference"`` when the
        trajectory is another estimator's output (Intel's GMapping poses); the report labels it.
    sources : tuple of str
        The files a recorded dataset was read from; contract violations name them.
    declared : frozenset of type
        The observation event types the dataset says it provides (a recorded format's sensors); the contract
        requires at least one event of each, so a stream lost to trimming or a bad file is an error, not a
        silently sensor-less run.
    flagged : tuple of FlaggedSample
        Recorded samples left out because they broke a physical bound (isolated glitches; see
        :mod:`locbench.datasets.recorded.plausibility`); neither the filters nor the metrics see them.
    """

    id: str
    params: dict[str, Any]
    events: tuple[Event, ...]
    ground_truth: Trajectory2D
    initial: Gaussian2
    world: WorldMap
    sensors: SensorSpec
    waypoints: Waypoints | None = None
    kidnaps: tuple[Kidnap, ...] = ()
    name: str = ""
    metadata: dict[str, Any] = field(default_factory=dict)
    relations: Relations | None = None
    truth_label: str = "ground truth"
    sources: tuple[str, ...] = ()
    declared: frozenset[type] = frozenset()
    flagged: tuple[FlaggedSample, ...] = ()

    @property
    def duration(self) -> float:
        """Time spanned by the ground truth, s."""
        return float(self.ground_truth.t[-1] - self.ground_truth.t[0]) if len(self.ground_truth) else 0.0

    def provides(self) -> frozenset[type | MapKind]:
        """The event types present and the map kinds available."""
        types_present = {type(e) for e in self.events}
        return frozenset(types_present) | self.world.kinds

    def check(self) -> None:
        """Validate the contract; raise :class:`ConfigError` naming the field that is wrong."""
        check_dataset_contract(self)


def _sources(paths: tuple[str, ...]) -> str:
    """The files as ``folder/{a, b}`` when they share a folder, else listed."""
    parents = {p.rsplit("/", 1)[0] for p in paths if "/" in p}
    if len(paths) > 1 and len(parents) == 1 and all("/" in p for p in paths):
        return f"{parents.pop()}/{{{', '.join(p.rsplit('/', 1)[1] for p in paths)}}}"
    return ", ".join(paths)


def check_dataset_contract(ds: Dataset) -> None:
    """Raise ``ConfigError`` naming the first field of ``ds`` that breaks the dataset contract (and, for recorded
    data, its files), in one line of bounded length."""
    try:
        _check_contract(ds)
    except ConfigError as exc:
        raise ConfigError(one_line(str(exc))) from None


def _check_contract(ds: Dataset) -> None:
    where = f"dataset {ds.name or ds.id!r}" + (f" (from {_sources(ds.sources)})" if ds.sources else "")
    if not ds.events:
        raise ConfigError(f"{where}: no events")
    keys = [event_order(e) for e in ds.events]
    for k, (a, b) in enumerate(itertools.pairwise(keys)):
        if b < a:
            raise ConfigError(f"{where}: events[{k + 1}] at t={ds.events[k + 1].t} is out of order")
    for k, e in enumerate(ds.events):
        if type(e) not in EVENT_TYPES:
            raise ConfigError(f"{where}: events[{k}] has unknown type {type(e).__name__}")
    gt = ds.ground_truth
    if gt.t.ndim != 1 or gt.xy.shape != (gt.t.shape[0], 2) or gt.theta.shape != gt.t.shape:
        raise ConfigError(f"{where}: ground_truth arrays must be t (n,), xy (n, 2), theta (n,)")
    if np.any(np.diff(gt.t) < 0):
        raise ConfigError(f"{where}: ground_truth.t goes backwards")
    if not (np.all(np.isfinite(gt.xy)) and np.all(np.isfinite(gt.theta))):
        raise ConfigError(f"{where}: ground_truth has non-finite poses")
    if gt.t[0] > ds.events[0].t + 1e-9 or gt.t[-1] < ds.events[-1].t - 1e-9:
        raise ConfigError(
            f"{where}: ground truth [{gt.t[0]:.3f}, {gt.t[-1]:.3f}] s does not cover the events "
            f"[{ds.events[0].t:.3f}, {ds.events[-1].t:.3f}] s"
        )
    if ds.initial.mean.shape != (3,) or ds.initial.cov.shape != (3, 3) or not is_symmetric_psd(ds.initial.cov):
        raise ConfigError(f"{where}: initial belief must be mean (3,) and a symmetric PSD cov (3, 3)")
    kinds = ds.world.kinds
    present = {type(e) for e in ds.events}
    if LandmarkObservations in present and MapKind.LANDMARKS not in kinds:
        raise ConfigError(f"{where}: has landmark observations but world.landmarks is empty")
    if RangeObservations in present and MapKind.LANDMARKS not in kinds:
        raise ConfigError(f"{where}: has range observations but world.landmarks (the beacons) is empty")
    if LaserScan in present and not (kinds & {MapKind.OCCUPANCY, MapKind.LINES}):
        raise ConfigError(f"{where}: has laser scans but neither an occupancy grid nor a line map")
    if Odometry not in present:
        raise ConfigError(f"{where}: has no odometry events")
    missing = sorted(t.__name__ for t in ds.declared - present)
    if missing:
        raise ConfigError(f"{where}: no {', '.join(missing)} event, expected the declared sensor streams")
    if PoseFix in present:
        for k, e in enumerate(ds.events):
            if isinstance(e, PoseFix) and e.cov.shape != (e.z.shape[0], e.z.shape[0]):
                raise ConfigError(f"{where}: events[{k}] PoseFix cov shape {e.cov.shape} does not match z")
    if ds.truth_label not in TRUTH_LABELS:
        raise ConfigError(f"{where}: truth_label {ds.truth_label!r} is not one of {TRUTH_LABELS}")
    if ds.relations is not None:
        r = ds.relations
        n = r.t1.shape[0]
        if r.t1.shape != (n,) or r.t2.shape != (n,) or r.delta.shape != (n, 3):
            raise ConfigError(f"{where}: relations must be t1 (n,), t2 (n,), delta (n, 3)")
    if ds.waypoints is not None:
        w = ds.waypoints
        if w.xy.shape != (w.t.shape[0], 2):
            raise ConfigError(f"{where}: waypoints must be t (n,) and xy (n, 2)")


#: Field metadata of a dataset parameter that changes only the initial belief a filter is handed: the truth, the
#: events and the noise are the realisation of the same name without it (:func:`realisation_name`), so the
#: parameter's effect is paired by run. Merge it with other metadata (``base=`` of :func:`~locbench.core.spec.bound`).
BELIEF_ONLY: MappingProxyType[str, Any] = MappingProxyType({"belief_only": True})


def realisation_name(name: str, params: Any) -> str:
    """The name whose random stream a realisation of dataset ``name`` (typed ``params``) draws: ``name`` less its
    :data:`BELIEF_ONLY` parameters."""
    from locbench.core.spec import Spec

    belief = [f.name for f in dataclasses.fields(params) if f.metadata.get("belief_only")]
    return Spec.parse(name).without(*belief).name if belief else name


def sort_events(events: list[Event]) -> tuple[Event, ...]:
    """Events sorted by time with odometry first on ties (a stable sort keeps stream order)."""
    return tuple(sorted(events, key=event_order))


class DatasetBuilder(abc.ABC):
    """What the registry points at: a parameter class and a ``build`` that makes the dataset.

    ``build`` must depend only on (params, seed) so that every filter sees the same realisation
    for a seed (the pairing protocol). It does no work in ``__init__``.
    """

    #: The id the dataset is registered under: the registry finds every class of a module of
    #: :mod:`locbench.datasets` whose own body sets it, so a loader module registers its own dataset ids. Empty (the
    #: default, inherited ids do not count): not registered by the package (a base class; a plugin's builder).
    id: ClassVar[str] = ""
    #: Frozen keyword-only dataclass of the dataset's parameters (field names carry units).
    Params: ClassVar[type]
    #: Bump when the generated data changes for the same (params, seed); part of the run key.
    version: ClassVar[int] = 1
    #: One line for ``locbench list`` (a registration made with a summary of its own shows that instead).
    description: ClassVar[str] = ""
    #: Top-level modules the builder needs beyond locbench's dependencies, and the command that installs them
    #: (as :attr:`locbench.filters.base.Filter.requires_modules`).
    requires_modules: ClassVar[tuple[str, ...]] = ()
    install_hint: ClassVar[str] = ""
    #: Rough duration of the data at the default parameters, s: the runner orders a sweep's tasks by it.
    nominal_duration_s: ClassVar[float] = 100.0

    @abc.abstractmethod
    def build(self, params: Any, rng: np.random.Generator) -> Dataset:
        """Make the dataset for resolved ``params`` with all randomness drawn from ``rng``."""

    @classmethod
    def data_unavailable(cls) -> str | None:
        """Why the default parameters' data is not on this machine (recorded datasets), or None."""
        return None

    def fetch(self, params: Any) -> list[str]:
        """Download (and verify) what ``params`` needs into the cache; the local paths. Synthetic data: nothing."""
        return []

    @classmethod
    def recording(cls, params: Any) -> str | None:
        """The recording ``params`` read, named with the parameters that choose it, or None: a synthetic world reads
        none (each seed is a world of its own).

        Two datasets that name the same recording (``intel`` and ``radish[site=intel]`` both read the Intel Research
        Lab log) are one piece of evidence where datasets are counted: the across-datasets ranking keeps one of
        them (:mod:`locbench.report.sections.paired_tests`). A name is a spec whose id is the loader the recording
        belongs to (``mrclam[dataset=6,robot=1]``), or ``file <absolute path>`` for a user's file.
        """
        return None

    @classmethod
    def has_bound(cls, params: Any) -> bool:
        """Whether a realisation of ``params`` has a posterior Cramer-Rao bound (:mod:`locbench.evaluate.pcrb`), which
        needs the simulator's true model: none for recorded data."""
        return False


class SyntheticBuilder(DatasetBuilder):
    """Base of the synthetic worlds that record their true noise model, so each realisation has a bound."""

    @classmethod
    def has_bound(cls, params: Any) -> bool:
        """True unless the run is kidnapped (a jump is outside the motion model the bound is built on)."""
        return not getattr(params, "kidnap_m", 0.0) > 0.0
