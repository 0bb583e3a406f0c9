"""Nominal noise of the landmark sensors and the additive process noise, resolved once for every filter.

Each value is the filter's config override, else the dataset's nominal value (:class:`SensorSpec`), else a
module default; a defaulted measurement noise is logged because it is a choice the user did not make.
"""

from __future__ import annotations

import logging

from locbench.datasets.dataset import SensorSpec

logger = logging.getLogger(__name__)

#: Range-bearing noise used when neither the config nor the dataset gives one (logged at reset).
DEFAULT_SIGMA_RANGE_M = 0.05
DEFAULT_SIGMA_BEARING_RAD = 0.02
#: Additive process noise Q per odometry step (report 003 eq. 8) when neither the config nor the dataset gives
#: one: 1 mm per axis and 0.5 mrad, small beside the encoder noise. A model-matched world declares zero.
DEFAULT_PROCESS_SIGMA_XY_M = 0.001
DEFAULT_PROCESS_SIGMA_THETA_RAD = 0.0005


def process_noise(
    sigma_x_m: float | None, sigma_y_m: float | None, sigma_theta_rad: float | None, sensors: SensorSpec
) -> tuple[float, float, float]:
    """Standard deviations of the additive process noise Q per odometry step (m, m, rad; report 003 eq. 8):
    each the config override, else the dataset's ``SensorSpec.process_sigma_xy_m`` /
    ``process_sigma_theta_rad``, else :data:`DEFAULT_PROCESS_SIGMA_XY_M` / :data:`DEFAULT_PROCESS_SIGMA_THETA_RAD`."""
    xy = DEFAULT_PROCESS_SIGMA_XY_M if sensors.process_sigma_xy_m is None else sensors.process_sigma_xy_m
    th = DEFAULT_PROCESS_SIGMA_THETA_RAD if sensors.process_sigma_theta_rad is None else sensors.process_sigma_theta_rad
    return (
        float(xy if sigma_x_m is None else sigma_x_m),
        float(xy if sigma_y_m is None else sigma_y_m),
        float(th if sigma_theta_rad is None else sigma_theta_rad),
    )


def range_only_noise(range_only_sigma_m: float | None, sensors: SensorSpec, warn: bool = True) -> float:
    """Standard deviation of a range-only (beacon) measurement, m: the config override, else the dataset's
    ``SensorSpec.range_sigma_m``, else :data:`DEFAULT_SIGMA_RANGE_M` (logged when ``warn``)."""
    sr = range_only_sigma_m if range_only_sigma_m is not None else sensors.range_sigma_m
    if sr is None:
        if warn:
            logger.warning("no nominal range-only noise in the config or dataset; using %g m", DEFAULT_SIGMA_RANGE_M)
        return DEFAULT_SIGMA_RANGE_M
    return float(sr)


def landmark_noise(
    sigma_range_m: float | None, sigma_bearing_rad: float | None, sensors: SensorSpec, warn: bool = True
) -> tuple[float, float]:
    """Range and bearing standard deviations (m, rad): the config override, else the dataset's nominal
    value, else :data:`DEFAULT_SIGMA_RANGE_M` / :data:`DEFAULT_SIGMA_BEARING_RAD` (logged when ``warn``)."""
    sr = sigma_range_m if sigma_range_m is not None else sensors.landmark_sigma_range_m
    sb = sigma_bearing_rad if sigma_bearing_rad is not None else sensors.landmark_sigma_bearing_rad
    if warn and (sr is None or sb is None):
        logger.warning(
            "no nominal landmark noise in the config or dataset; using sigma_range_m=%g, sigma_bearing_rad=%g",
            DEFAULT_SIGMA_RANGE_M,
            DEFAULT_SIGMA_BEARING_RAD,
        )
    return (
        DEFAULT_SIGMA_RANGE_M if sr is None else float(sr),
        DEFAULT_SIGMA_BEARING_RAD if sb is None else float(sb),
    )
