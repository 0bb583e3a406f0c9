"""A small synthetic range-only (radio beacon) scenario shared by the filter tests.

The robot drives a circle of radius 5 m (v = 0.5 m/s, omega = 0.1 rad/s, 10 Hz) among 4 beacons; its odometry
over-reports speed by 3 % and turn rate by 5 % (a systematic error, so dead reckoning drifts) and carries the
measured twist (v, omega, dt). One range per step, cycling through the beacons (as the CMU Plaza radios do),
with Gaussian noise of ``sigma_range`` m.
"""

from __future__ import annotations

import math

import numpy as np

from locbench.core.events import Odometry, RangeObservations
from locbench.datasets.dataset import Gaussian2, Landmarks, SensorSpec, WorldMap
from locbench.filters.base import Filter

BEACON_IDS = np.array([3, 5, 8, 13], dtype=np.int64)
BEACON_XY = np.array([[-8.0, -3.0], [8.0, -3.0], [8.0, 13.0], [-8.0, 13.0]])
WORLD = WorldMap(landmarks=Landmarks(ids=BEACON_IDS, xy=BEACON_XY))
SENSORS = SensorSpec(odometry_sigma_xy_per_m=0.05, odometry_sigma_theta_per_m=0.05, range_sigma_m=0.1)
INITIAL = Gaussian2(mean=np.zeros(3), cov=np.diag([0.01, 0.01, 0.001]))


def arc(pose: np.ndarray, s: float, a: float) -> np.ndarray:
    """``pose`` moved along a constant-twist arc of length ``s`` turning ``a``."""
    x, y, th = pose
    if abs(a) < 1e-12:
        dx, dy = s, 0.0
    else:
        dx, dy = s * math.sin(a) / a, s * (1.0 - math.cos(a)) / a
    c, sn = math.cos(th), math.sin(th)
    return np.array([x + c * dx - sn * dy, y + sn * dx + c * dy, th + a])


def scenario(
    n: int = 300, sigma_range: float = 0.1, seed: int = 0
) -> tuple[list[Odometry | RangeObservations], np.ndarray, np.ndarray]:
    """Events, truth times (n,) and truth poses (n, 3) (after each step)."""
    rng = np.random.default_rng(seed)
    dt, v, w = 0.1, 0.5, 0.1
    pose = np.zeros(3)
    events: list[Odometry | RangeObservations] = []
    ts, truth = [], []
    for k in range(n):
        t = dt * (k + 1)
        pose = arc(pose, v * dt, w * dt)
        vm, wm = 1.03 * v, 1.05 * w
        inc = arc(np.zeros(3), vm * dt, wm * dt)
        events.append(Odometry(t, float(inc[0]), float(inc[1]), float(inc[2]), v=vm, omega=wm, dt=dt))
        j = k % len(BEACON_IDS)
        r = float(np.hypot(*(BEACON_XY[j] - pose[:2]))) + sigma_range * float(rng.standard_normal())
        events.append(RangeObservations(t, BEACON_IDS[j : j + 1].copy(), np.array([r])))
        ts.append(t)
        truth.append(pose.copy())
    return events, np.array(ts), np.array(truth)


def run(
    flt: Filter,
    events: list[Odometry | RangeObservations],
    use_ranges: bool = True,
    sensors: SensorSpec = SENSORS,
    seed: int = 1,
) -> tuple[np.ndarray, list[dict[str, float]]]:
    """Means (one per odometry event, after the range that follows it) and the diagnostics of every update."""
    flt.reset(INITIAL, WORLD, sensors, np.random.default_rng(seed))
    means: list[np.ndarray] = []
    diags: list[dict[str, float]] = []
    for ev in events:
        if isinstance(ev, Odometry):
            flt.predict(ev)
            if not use_ranges:
                means.append(flt.estimate().mean)
        elif use_ranges:
            flt.update(ev)
            est = flt.estimate()
            means.append(est.mean)
            diags.append(dict(est.diagnostics))
    return np.array(means), diags


def position_rmse(means: np.ndarray, truth: np.ndarray) -> float:
    """RMS position error, m."""
    return float(np.sqrt(np.mean(np.sum((means[:, :2] - truth[:, :2]) ** 2, axis=1))))
