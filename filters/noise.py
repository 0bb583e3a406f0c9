"""The shared sensor and process noise resolution, public: a plugin filter's nominal noise as the built-in
filters resolve it.

Each value is the filter's config override, else the dataset's nominal value
(:class:`~locbench.datasets.dataset.SensorSpec`), else a module default that is logged because the user did not
choose it. The implementation is ``locbench.filters._noise`` (where the built-in filters import it from); this
module is the stable name a plugin imports.
"""

from __future__ import annotations

from locbench.filters._noise import (
    DEFAULT_PROCESS_SIGMA_THETA_RAD,
    DEFAULT_PROCESS_SIGMA_XY_M,
    DEFAULT_SIGMA_BEARING_RAD,
    DEFAULT_SIGMA_RANGE_M,
    landmark_noise,
    process_noise,
    range_only_noise,
)

__all__ = [
    "DEFAULT_PROCESS_SIGMA_THETA_RAD",
    "DEFAULT_PROCESS_SIGMA_XY_M",
    "DEFAULT_SIGMA_BEARING_RAD",
    "DEFAULT_SIGMA_RANGE_M",
    "landmark_noise",
    "process_noise",
    "range_only_noise",
]
