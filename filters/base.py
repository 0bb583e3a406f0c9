"""The common filter interface every estimator implements.

A filter is built from a frozen config and does no work in ``__init__``; ``reset`` hands it the
initial belief, the world map, the nominal sensor noise and its random generator; the runner then
calls ``predict`` for each odometry event and ``update`` for each observation it consumes, and reads
``estimate()`` after every call.
"""

from __future__ import annotations

import abc
import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from locbench.core.errors import ConfigError
from locbench.core.events import Event, Observation, Odometry
from locbench.core.spec import BOUND_KEY, Bound, bound
from locbench.datasets.dataset import Gaussian2, MapKind, SensorSpec, WorldMap

FloatArray = npt.NDArray[np.float64]


#: The bounds most config fields declare (field metadata; merge others with ``|``): > 0, >= 0, in (0, 1) ...
POSITIVE = bound(0.0, low_open=True)
NON_NEGATIVE = bound(0.0)
PROBABILITY = bound(0.0, 1.0, low_open=True, high_open=True)
#: ... > 0 or None (the dataset's nominal value), and >= 0 or None.
POSITIVE_OR_DATASET = bound(0.0, low_open=True, optional=True)
NON_NEGATIVE_OR_NONE = bound(0.0, optional=True, none_means="")


@dataclass(frozen=True, kw_only=True)
class FilterConfig:
    """Base of every filter config: a frozen keyword-only dataclass whose field names carry units.

    Each field declared with :func:`bound` metadata is checked here, once for every config; a config with rules
    across fields adds them in its own ``__post_init__`` after calling this one.
    """

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            b = f.metadata.get(BOUND_KEY)
            if isinstance(b, Bound):
                value = getattr(self, f.name)
                if not b.accepts(value):
                    raise ConfigError(f"{f.name} must be {b.describe()}, got {value}")


@dataclass(frozen=True, eq=False)
class Estimate:
    """A filter's belief at time ``t``.

    Attributes
    ----------
    t : float
        Time of the last event processed, s.
    mean : ndarray, shape (3,)
        Pose (x m, y m, theta rad in (-pi, pi]), world frame.
    cov : ndarray, shape (3, 3)
        Covariance of the pose, same units.
    diagnostics : dict of str to float
        Per-step numbers: ``nis`` (normalised innovation squared of the last update), ``accepted`` and
        ``rejected`` measurement counts, ``n_eff`` (particles), ``iterations`` ...; NaN when not defined.
    """

    t: float
    mean: FloatArray
    cov: FloatArray
    diagnostics: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class HealthSignal:
    """What a named :meth:`Filter.health` signal measures and which way means trouble.

    ``lost_when`` is ``"high"`` (a large value should mean the filter is lost: NIS, covariance trace, maximum
    weight) or ``"low"`` (a small value should: the NIS p-value, the effective sample size, inlier and accepted
    fractions, w_fast / w_slow); the lost-detection scores (:mod:`locbench.evaluate.lost`) orient each signal by it.
    """

    description: str
    unit: str
    lost_when: str


#: Every health signal a filter may report, by name (a filter reports a subset; the report reads this table).
HEALTH_SIGNALS: Mapping[str, HealthSignal] = MappingProxyType(
    {
        "nis": HealthSignal("NIS of the last update (innovation' S^-1 innovation)", "", "high"),
        "nis_p": HealthSignal("chi-square upper-tail p-value of that NIS for its degrees of freedom", "", "low"),
        "cov_trace_xy_m2": HealthSignal("trace of the position covariance", "m^2", "high"),
        "heading_var_rad2": HealthSignal("heading variance", "rad^2", "high"),
        "ess_fraction": HealthSignal("effective sample size over the particle count, at the last update", "", "low"),
        "max_weight": HealthSignal("largest normalised particle weight", "", "high"),
        "w_fast_over_w_slow": HealthSignal("augmented MCL's short- over long-term likelihood average", "", "low"),
        "icp_rmse_m": HealthSignal("RMS distance of the ICP pairs of the last scan", "m", "high"),
        "inlier_fraction": HealthSignal("ICP pairs of the last scan over the points it could pair", "", "low"),
        "accepted_fraction": HealthSignal("measurements of the last update that passed the gate", "", "low"),
        "distance_m": HealthSignal("odometry path length since the start", "m", "high"),
    }
)


def gaussian_health(est: Estimate, nis_dof: float | None = None) -> dict[str, float]:
    """The health every Gaussian belief has: ``cov_trace_xy_m2``, ``heading_var_rad2``, and ``nis`` with its
    p-value ``nis_p`` when the filter reports an NIS diagnostic (degrees of freedom ``nis_dof``, else the
    ``nis_dof`` diagnostic), and ``accepted_fraction`` of the last update when the diagnostics count accepted and
    rejected measurements; NaN where not defined (a predict)."""
    P = est.cov
    out = {"cov_trace_xy_m2": float(P[0, 0] + P[1, 1]), "heading_var_rad2": float(P[2, 2])}
    if "nis" in est.diagnostics:
        from scipy import special  # here, not at import: the runner starts without scipy

        nis = float(est.diagnostics["nis"])
        dof = float(est.diagnostics.get("nis_dof", np.nan)) if nis_dof is None else float(nis_dof)
        out["nis"] = nis
        out["nis_p"] = float(special.chdtrc(dof, nis)) if np.isfinite(nis) and dof > 0 else float("nan")
    if "accepted" in est.diagnostics and "rejected" in est.diagnostics:
        out["accepted_fraction"] = accepted_share(est.diagnostics["accepted"], est.diagnostics["rejected"])
    return out


#: :func:`gaussian_health`'s signals in the order it reports them.
GAUSSIAN_HEALTH_NAMES = ("cov_trace_xy_m2", "heading_var_rad2", "nis", "nis_p", "accepted_fraction")


def gaussian_health_rows(
    cov: npt.NDArray[np.float64], diagnostics: Mapping[str, npt.NDArray[np.float64]], nis_dof: float | None = None
) -> dict[str, npt.NDArray[np.float64]]:
    """:func:`gaussian_health` of every row of a run at once, from its stored covariances (n, 3, 3) and
    diagnostics (n,) each, NaN where a row lacks one: the same values bit for bit (the same IEEE operations, and
    ``chdtrc`` is one ufunc whether called on a scalar or an array), so the runner need not call it per event.

    Returns every signal whose inputs the run has; ``accepted_fraction`` whenever both counts are diagnostics
    (the caller drops it if no single row had both, as :func:`gaussian_health` would never report it).
    """
    out = {"cov_trace_xy_m2": cov[:, 0, 0] + cov[:, 1, 1], "heading_var_rad2": cov[:, 2, 2].copy()}
    if "nis" in diagnostics:
        from scipy import special

        nis = np.array(diagnostics["nis"], dtype=np.float64)
        if nis_dof is None:
            dof = diagnostics.get("nis_dof", np.full(nis.shape, np.nan))
        else:
            dof = np.full(nis.shape, float(nis_dof))
        ok = np.isfinite(nis) & (dof > 0)
        nis_p = np.full(nis.shape, np.nan)
        nis_p[ok] = special.chdtrc(dof[ok], nis[ok])
        out["nis"], out["nis_p"] = nis, nis_p
    if "accepted" in diagnostics and "rejected" in diagnostics:
        acc, rej = diagnostics["accepted"], diagnostics["rejected"]
        total = acc + rej
        offered = total > 0  # NaN (a row without the counts) is not
        share = np.full(acc.shape, np.nan)
        share[offered] = acc[offered] / total[offered]
        out["accepted_fraction"] = share
    return out


def accepted_share(accepted: float, rejected: float) -> float:
    """Accepted over offered measurements of one update; NaN when nothing was offered."""
    total = accepted + rejected
    return accepted / total if total > 0 else float("nan")


@dataclass(frozen=True)
class FilterDoc:
    """A filter's row in the filter tables of ``README.md`` and ``docs/design.md`` (generated from it).

    Attributes
    ----------
    source : str
        The source reports (by number, ``"003, 001"``) or the reference the filter follows.
    prediction : str
        The motion model, with the source's equation numbers.
    observation : str
        The measurement models and what the update does with them, with the equation numbers.
    notes : str
        What ``docs/design.md`` adds: choices and rules beyond the two models ("" for none).
    """

    source: str
    prediction: str
    observation: str
    notes: str = ""


@dataclass(frozen=True, kw_only=True)
class CheckTolerances:
    """The bounds the conformance checks (:mod:`locbench.checks`) hold a filter to; a filter may widen one.

    Attributes
    ----------
    logdet_drop : float
        How far log det P may fall in one predict (0 for an exact Gaussian filter; sampling noise for particles).
    noise_free_ate_m : float
        Position RMSE allowed on exact data (``tiny_circle[noise_free=true]``), m.
    wrap_position_m, wrap_heading_rad : float
        Largest position (m) and heading (rad) error allowed on the noisy circle whose heading crosses +-pi.
    """

    logdet_drop: float = 1e-9
    noise_free_ate_m: float = 0.05
    wrap_position_m: float = 1.0
    wrap_heading_rad: float = 0.5


#: Members of a belief sample (:meth:`Filter.belief_sample`) the runner scores by default, a run setting
#: (``locbench run --score-sample``) that enters the run key of a filter that samples its belief: the fair
#: scores of :mod:`locbench.evaluate.scores` do not depend on it in expectation, their noise does.
SCORE_SAMPLE_SIZE = 64
#: Most members a score sample may have: scoring one costs m^2 / 2 pairs at every ground-truth time.
MAX_SCORE_SAMPLE = 4096


class Filter(abc.ABC):
    """Base class of every estimator.

    Attributes
    ----------
    id : str
        The id the filter is registered under: the registry finds every class of a module of
        :mod:`locbench.filters` whose own body sets it (:mod:`locbench.registry`), so a new filter is its module
        alone. Empty (the default, inherited ids do not count): not registered by the package (a base class; a
        plugin, whose entry point names it).
    consumes : frozenset of event types
        Every event type the filter can use: :class:`Odometry` (through ``predict``) and the
        observation types it takes through ``update``; any other observation raises ``TypeError``.
    requires : frozenset of MapKind
        Map kinds that must be present; a dataset lacking one is a recorded skip with the reason.
    Config : type
        The filter's frozen config dataclass.
    version : int
        Bump on any change of behaviour; it is part of the run key, so stored runs are redone.
    source : str
        The report or reference the filter follows (for the README and report).
    description : str
        One line for ``locbench list`` (a registration made with a summary of its own shows that instead).
    requires_modules : tuple of str
        Top-level modules the filter needs beyond locbench's dependencies, and ``install_hint``, the command that
        installs them: a missing one makes the filter "unavailable: ... install it with: HINT" instead of an
        ImportError (the filter imports them inside its methods, so that its class can be read without them).
    expected_check_failures : mapping of str to str
        Conformance checks the filter fails by design, each with the reason; they run as strict xfail.
    health_nis_dof : float or None
        Degrees of freedom of the ``nis`` diagnostic for the default :meth:`health`; None reads the
        ``nis_dof`` diagnostic instead.

    Hooks read by the conformance checks: ``expected_check_failures`` and :meth:`check_tolerances`. Read by the
    suites (:mod:`locbench.suites`) and the generated docs tables: ``order``, ``compared``,
    ``comparison_configurations``, ``kidnap_configurations`` and ``doc``.
    """

    id: ClassVar[str] = ""
    expected_check_failures: ClassVar[Mapping[str, str]] = MappingProxyType({})
    consumes: ClassVar[frozenset[type]] = frozenset()
    requires: ClassVar[frozenset[MapKind]] = frozenset()
    Config: ClassVar[type[FilterConfig]] = FilterConfig
    version: ClassVar[int] = 1
    health_nis_dof: ClassVar[float | None] = None
    source: ClassVar[str] = ""
    description: ClassVar[str] = ""
    requires_modules: ClassVar[tuple[str, ...]] = ()
    install_hint: ClassVar[str] = ""
    #: The baseline every comparison starts with (dead reckoning): listed first, never marked best.
    baseline: ClassVar[bool] = False
    #: Parameters that switch on this filter's recovery policy: its kidnap configuration is a configuration
    #: with these set (the report's summary reads kidnap recovery there). Empty: it recovers as configured.
    kidnap_params: ClassVar[dict[str, str]] = {}
    #: The configurations suite ``kidnap`` runs, as parameter overrides (``{}``: the default); None: the kidnap
    #: configuration alone (:attr:`kidnap_params`). A tuple must hold that configuration too.
    kidnap_configurations: ClassVar[tuple[dict[str, str], ...] | None] = None
    #: Configurations beyond the default that the conformance checks also run, as parameter overrides
    #: (``{"adaptive": "kld"}``); the kidnap configuration (:attr:`kidnap_params`) is added to them.
    check_configurations: ClassVar[tuple[dict[str, str], ...]] = ()
    #: Whether the suites that compare every filter run it (``default``, ``kidnap``, ``recorded``,
    #: ``consistency``), which puts it in the report's summary tables; False: it runs only when named.
    compared: ClassVar[bool] = True
    #: Configurations the main comparison (suite ``default``) runs beside the default, as parameter overrides;
    #: they become rows of the summary tables.
    comparison_configurations: ClassVar[tuple[dict[str, str], ...]] = ()
    #: Place among the package's filters in every list of them (the suites, the docs tables): ascending, ties
    #: by id.
    order: ClassVar[int] = 100
    #: The filter's row in the docs' filter tables; None: no row (a plugin's are in its own docs).
    doc: ClassVar[FilterDoc | None] = None
    #: Rough compute seconds per second of data with the default config (measured order of magnitude on
    #: ``office``): the runner orders a sweep's tasks by it before any timing is stored.
    cost_per_data_s: ClassVar[float] = 0.1

    @classmethod
    def cost_scale(cls, config: FilterConfig) -> float:
        """How much more a configuration costs than the default (:attr:`cost_per_data_s`); 1 unless a filter
        has a cost knob."""
        return 1.0

    @classmethod
    def declared_check_failures(cls, config: FilterConfig) -> Mapping[str, str]:
        """The conformance checks ``config`` fails by design, with the reason: :attr:`expected_check_failures`,
        and in a filter that overrides this, those of some of its configurations."""
        return cls.expected_check_failures

    @classmethod
    def starts_without_pose(cls, config: FilterConfig) -> bool:
        """Whether this configuration ignores the initial belief (global localization from a uniform prior).

        Such runs are scored in the report's global-localization table, not beside the filters that start
        from the initial belief.
        """
        return False

    def __init__(self, config: FilterConfig | None = None) -> None:
        # Store only: no RNG, no I/O, no work (scikit-learn's rule), so a filter is cheap to make.
        self.config = config if config is not None else self.Config()

    def routed_events(self) -> frozenset[type]:
        """The observation types the runner should send to ``update`` under this config.

        Defaults to ``consumes`` (odometry included); a filter narrows it when its config switches a sensor off, so that
        unused events neither cost time nor appear in update timings.
        """
        return self.consumes

    def unsupported(self, world: WorldMap) -> str | None:
        """Why this configuration cannot run in ``world`` within its stated resource bounds, or None.

        The runner stores such a run as ``skipped`` with this reason (e.g. a scan database that would exceed its
        memory bound on a large map) instead of failing it in ``reset``. Checked before ``reset``; cheap.
        """
        return None

    def check_tolerances(self) -> CheckTolerances:
        """The bounds of the conformance checks under this config (defaults unless a filter widens one)."""
        return CheckTolerances()

    def check_consumes(self, z: Event) -> None:
        """Raise ``TypeError`` when ``z`` is not an observation type this filter consumes."""
        if type(z) not in self.consumes or isinstance(z, Odometry):
            names = ", ".join(sorted(t.__name__ for t in self.consumes)) or "none"
            raise TypeError(f"{type(self).__name__} does not consume {type(z).__name__} (consumes: {names})")

    @abc.abstractmethod
    def reset(self, initial: Gaussian2, world: WorldMap, sensors: SensorSpec, rng: np.random.Generator) -> None:
        """Start from ``initial`` in ``world``; all randomness comes from ``rng``."""

    @abc.abstractmethod
    def predict(self, u: Odometry) -> None:
        """Propagate the belief with one odometry event."""

    @abc.abstractmethod
    def update(self, z: Observation) -> None:
        """Correct the belief with one observation (``TypeError`` for a type not in ``consumes``)."""

    @abc.abstractmethod
    def estimate(self) -> Estimate:
        """The current belief; cheap to call after every event."""

    def belief_sample(self, rng: np.random.Generator, size: int) -> tuple[FloatArray, FloatArray] | None:
        """A weighted sample of the current belief, for the proper scores (:mod:`locbench.evaluate.scores`); optional.

        Returns poses (m, 3) (x m, y m, theta rad) and weights (m,) summing to 1, or None (the default) when the
        belief is the Gaussian of :meth:`estimate`, which is scored in closed form. ``size`` is the m the run asks
        for (the run setting :data:`SCORE_SAMPLE_SIZE` by default). ``rng`` is the runner's own generator, not the
        filter's: drawing the sample must not change any later estimate.
        """
        return None

    def health(self) -> dict[str, float]:
        """Named floats describing the filter's own state after the last call (:data:`HEALTH_SIGNALS`).

        The default is :func:`gaussian_health` of :meth:`estimate` (with :attr:`health_nis_dof`) and the
        filter's :meth:`event_health`. Must not change the belief or consume the filter's random stream; the
        runner stores the values per event. A filter that keeps this default has the Gaussian part computed by
        the runner from the stored rows after the run (:func:`gaussian_health_rows`, the same values); one that
        overrides it is called after every event.
        """
        return gaussian_health(self.estimate(), self.health_nis_dof) | self.event_health()

    def event_health(self) -> dict[str, float]:
        """The health signals of the last call that are not functions of :meth:`estimate` (ICP residuals, the
        particles' effective sample size, ...); none by default. Never one of :data:`GAUSSIAN_HEALTH_NAMES`."""
        return {}

    def extra_results(self) -> dict[str, Any]:
        """Optional arrays stored with the run at the end (e.g. a smoother's smoothed trajectory)."""
        return {}
