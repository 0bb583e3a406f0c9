"""How the report shows each metric: header, display unit and scale, which way is better, digits.

Display metadata only (the definitions are :mod:`locbench.evaluate.metrics`' pure functions): one record per metric id,
read by the report's tables and by the claims' sections, so it sits below both packages (neither imports the
other to learn how ``ate_m`` is printed). Errors are shown in cm, headings in deg, times in us.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from locbench.evaluate.metrics import POSE_DOF


class MetricInfo(NamedTuple):
    """How a metric is shown: header, display unit and the factor from its SI value, and which way is better.

    ``better`` is ``"lower"``, ``"higher"`` or ``"closer"`` (to ``target``, in ratio: the ANEES against
    the pose dimension) or ``""`` (no best value).
    """

    header: str
    unit: str
    scale: float = 1.0
    better: str = "lower"
    target: float = float("nan")
    digits: int = 3


#: Display metadata of the metric ids the report tables show; errors in cm, headings in deg, times in us.
METRICS: dict[str, MetricInfo] = {
    "ate_m": MetricInfo("ATE", "cm", 100.0),
    "smoothed_ate_m": MetricInfo("smoothed ATE", "cm", 100.0),
    "waypoint_rmse_mean_m": MetricInfo("mean waypoint RMSE", "cm", 100.0),
    "heading_rmse_rad": MetricInfo("heading RMSE", "deg", float(np.degrees(1.0))),
    "rpe_m_per_m": MetricInfo("RPE", "%", 100.0),
    "final_error_m": MetricInfo("final error", "cm", 100.0),
    "anees": MetricInfo("ANEES", "", 1.0, "closer", float(POSE_DOF)),
    "nees_in_band_fraction": MetricInfo("NEES in 95 % band", "%", 100.0, "higher"),
    "nll": MetricInfo("NLL", "", 1.0),
    "crps_x_m": MetricInfo("CRPS x", "cm", 100.0),
    "crps_y_m": MetricInfo("CRPS y", "cm", 100.0),
    "crps_heading_rad": MetricInfo("CRPS heading", "deg", float(np.degrees(1.0))),
    "energy_score_m": MetricInfo("energy score", "cm", 100.0),
    "lost_auroc": MetricInfo("lost AUROC", "", 1.0, "higher"),
    "ate_over_pcrb": MetricInfo("ATE / PCRB", "x", 1.0),
    "predict_us_median": MetricInfo("predict median", "us", 1.0),
    "update_us_median": MetricInfo("update median", "us", 1.0),
    "realtime_factor": MetricInfo("real-time factor", "x", 1.0, "higher"),
    # reference units (locbench.evaluate.metrics.reference_units): us and x on a machine whose reference workload takes
    # 1 s
    "predict_us_median_ref": MetricInfo("predict median", "ref us", 1.0),
    "update_us_median_ref": MetricInfo("update median", "ref us", 1.0),
    "realtime_factor_ref": MetricInfo("real-time factor", "ref x", 1.0, "higher"),
    "kidnap_recovered": MetricInfo("kidnap recovery", "%", 100.0, "higher"),
    "relation_error_m": MetricInfo("relation error", "cm", 100.0),
    "relation_error_rad": MetricInfo("relation error", "deg", float(np.degrees(1.0))),
    "accepted_fraction": MetricInfo("accepted", "%", 100.0, "higher"),
    "particles_mean": MetricInfo("mean particles", "", 1.0, ""),
    "recorded_ate_median_m": MetricInfo("recorded median ATE", "cm", 100.0),
}
