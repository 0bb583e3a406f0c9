"""Rerun a calibration of the synthetic robot's systematic odometry error and print the fitted constants.

Usage: python tools/derive/calibrate_odometry.py [room|lap]

Both fits are functions of :mod:`locbench.datasets.synthetic.odometry_calibration`: ``room`` runs
``calibrate_room_odometry`` (the encoder scales and the wheelbase ratio of ``locbench.datasets.synthetic.toolkit``),
``lap`` runs ``calibrate_lap_odometry`` (``LAP_SYSTEMATIC_SCALE`` of ``locbench.datasets.synthetic.lap``).
"""

from __future__ import annotations

import sys

from locbench.datasets.synthetic.odometry_calibration import calibrate_lap_odometry, calibrate_room_odometry

if __name__ == "__main__":
    which = sys.argv[1] if len(sys.argv) > 1 else "room"
    print(calibrate_room_odometry() if which == "room" else calibrate_lap_odometry())
