"""The public API of a filter: every type a filter receives, returns and declares, importable from one module.

A filter written outside locbench (a plugin registered through the ``locbench.filters`` entry-point group, see
the README's "Writing a filter plugin") imports from here, from :mod:`locbench.filters.motion` (the shared
motion models) and from :mod:`locbench.filters.noise` (the shared noise resolution), and from nothing else of
locbench; these names keep their meaning across releases. What a filter receives:

* ``reset(initial, world, sensors, rng)``: :class:`Gaussian2` (mean (3,), cov (3, 3)), :class:`WorldMap`
  (any of :class:`OccupancyGrid`, :class:`Landmarks`, :class:`LineMap`; the kinds in ``requires`` are
  present), :class:`SensorSpec` (the dataset's nominal noise, None where unknown), a ``numpy`` Generator;
* ``predict(u)``: an :class:`Odometry` increment (dx, dy, dtheta in the previous robot frame, optional wheel
  travel and twist);
* ``update(z)``: one of the observation types in its ``consumes``: :class:`LaserScan`,
  :class:`LandmarkObservations`, :class:`RangeObservations`, :class:`PoseFix`.

It returns an :class:`Estimate` and declares a ``Config`` deriving from :class:`FilterConfig`, whose fields
may carry :func:`tunable` / :func:`tunable_choice` ranges, a :func:`field_unit` and the values they accept
(:func:`bound`, :data:`POSITIVE` ..., checked once by :class:`FilterConfig`; a config's own ``__post_init__``
adds rules across fields after calling ``super().__post_init__()``).
"""

from __future__ import annotations

from locbench.core.errors import ConfigError, FilterDiverged
from locbench.core.events import (
    EVENT_TYPES,
    OBSERVATION_TYPES,
    UNKNOWN_ID,
    Event,
    LandmarkObservations,
    LaserScan,
    Observation,
    Odometry,
    PoseFix,
    RangeObservations,
)
from locbench.core.geometry import compose, wrap_angle, wrap_scalar
from locbench.core.runkey import RUN_KEY_OMIT_IF_DEFAULT
from locbench.core.tunable import field_unit, tunable, tunable_choice
from locbench.datasets.dataset import Gaussian2, Landmarks, LineMap, MapKind, OccupancyGrid, SensorSpec, WorldMap
from locbench.filters import motion, noise
from locbench.filters.base import (
    HEALTH_SIGNALS,
    NON_NEGATIVE,
    NON_NEGATIVE_OR_NONE,
    POSITIVE,
    POSITIVE_OR_DATASET,
    PROBABILITY,
    Bound,
    CheckTolerances,
    Estimate,
    Filter,
    FilterConfig,
    FloatArray,
    HealthSignal,
    accepted_share,
    bound,
    gaussian_health,
)

__all__ = [
    "EVENT_TYPES",
    "HEALTH_SIGNALS",
    "NON_NEGATIVE",
    "NON_NEGATIVE_OR_NONE",
    "OBSERVATION_TYPES",
    "POSITIVE",
    "POSITIVE_OR_DATASET",
    "PROBABILITY",
    "RUN_KEY_OMIT_IF_DEFAULT",
    "UNKNOWN_ID",
    "Bound",
    "CheckTolerances",
    "ConfigError",
    "Estimate",
    "Event",
    "Filter",
    "FilterConfig",
    "FilterDiverged",
    "FloatArray",
    "Gaussian2",
    "HealthSignal",
    "LandmarkObservations",
    "Landmarks",
    "LaserScan",
    "LineMap",
    "MapKind",
    "Observation",
    "OccupancyGrid",
    "Odometry",
    "PoseFix",
    "RangeObservations",
    "SensorSpec",
    "WorldMap",
    "accepted_share",
    "bound",
    "compose",
    "field_unit",
    "gaussian_health",
    "motion",
    "noise",
    "tunable",
    "tunable_choice",
    "wrap_angle",
    "wrap_scalar",
]
