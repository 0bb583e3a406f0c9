"""The main comparison: every filter on the common ``office`` world (no source report; no claims)."""

from __future__ import annotations

from locbench.claims import Experiment, register_experiment
from locbench.suites import SUITES

register_experiment(
    Experiment(
        "office",
        "Office (main comparison)",
        "The common world: a 20 m x 15 m floor with a corridor, six rooms, doors and 22 landmarks; a 97 m, 231 s "
        "tour through 9 waypoints with wheel odometry, landmark sightings, a 240 deg laser and 1 Hz GPS-like "
        "fixes, so that every filter runs on the same data.",
        summary=True,
        order=0,
        suite=SUITES["default"],
    )
)
