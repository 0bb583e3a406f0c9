"""Time ekf_landmarks' hand-unrolled landmark update against the same update through the Kalman core.

Usage: ``python tools/measure/kalman_fast_path.py {fast,core} N``: N range-bearing updates of one landmark from the same
prior (restored before each update so that both modes do identical work). Run the two modes as paired whole
processes; the difference of their times over N is the cost per update. docs/kalman_core.md has the figures.
"""

from __future__ import annotations

import sys

import numpy as np

from locbench.core.geometry import wrap_angle, wrap_scalar
from locbench.datasets.dataset import Gaussian2, Landmarks, SensorSpec, WorldMap
from locbench.filters._kalman import joseph_update, wrapped_residual
from locbench.filters.ekf_landmarks import LandmarkEKF

SENSORS = SensorSpec(landmark_sigma_range_m=0.05, landmark_sigma_bearing_rad=0.02)
WORLD = WorldMap(landmarks=Landmarks(ids=np.array([1], dtype=np.int64), xy=np.array([[3.0, 1.0]])))
P0 = [[0.04, 0.01, -0.005], [0.01, 0.09, 0.002], [-0.005, 0.002, 0.01]]
X0 = [0.2, -0.1, 0.3]
Z = (3.0, 0.02)


def range_bearing(pose: np.ndarray, lm: np.ndarray) -> np.ndarray:
    """h(x): (range, bearing) of the landmark ``lm`` from ``pose`` (report 003 eq. 7)."""
    dx, dy = lm[0] - pose[0], lm[1] - pose[1]
    return np.array([np.hypot(dx, dy), wrap_angle(np.arctan2(dy, dx) - pose[2])])


def range_bearing_jacobian(pose: np.ndarray, lm: np.ndarray) -> np.ndarray:
    """H = dh/dx (report 001 fig. 2, corrected)."""
    dx, dy = float(lm[0] - pose[0]), float(lm[1] - pose[1])
    q = dx * dx + dy * dy
    d = q**0.5
    return np.array([[-dx / d, -dy / d, 0.0], [dy / q, -dx / q, -1.0]])


def main() -> None:
    mode, n = sys.argv[1], int(sys.argv[2])
    ekf = LandmarkEKF()
    ekf.reset(Gaussian2(np.array(X0), np.array(P0)), WORLD, SENSORS, np.random.default_rng(0))
    r_cov = np.diag([ekf._rr, ekf._rb])
    residual = wrapped_residual([1])
    lm = WORLD.landmarks.xy[0]  # type: ignore[union-attr]
    z = np.array(Z)
    for _ in range(n):
        ekf._x, ekf._P = list(X0), [row[:] for row in P0]
        if mode == "fast":
            ekf._correct_landmark(Z[0], Z[1], 0, np.inf)
        else:
            x, p = np.array(ekf._x), np.array(ekf._P)
            c = joseph_update(x, p, z, range_bearing(x, lm), range_bearing_jacobian(x, lm), r_cov, residual)
            ekf._x = [float(c.x[0]), float(c.x[1]), wrap_scalar(float(c.x[2]))]
            ekf._P = c.P.tolist()
    print(mode, n, ekf._x)


if __name__ == "__main__":
    main()
