"""The calibration studies of the synthetic robot's systematic odometry error (not run at build time).

Usage: python tools/calibrate_odometry.py [room|lap]

``calibrate_room_odometry`` fitted ``ENCODER_SCALE_LEFT``, ``ENCODER_SCALE_RIGHT`` and ``WHEELBASE_TRUE_RATIO``
(``locbench.datasets.synthetic.toolkit``) to report 003's table 1; ``calibrate_lap_odometry`` fitted
``LAP_SYSTEMATIC_SCALE`` (``locbench.datasets.synthetic.lap``) to a 15 cm median end-of-lap error. Both frozen
results and what they achieve are constants of those modules (``ROOM_CALIBRATION_ACHIEVED_CM``,
``LAP_CALIBRATION_ACHIEVED_M``); ``tests/datasets/synthetic/test_synthetic.py`` checks that the error functions below
still give
them.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from locbench.core.errors import ConfigError
from locbench.datasets.synthetic.lap import LAP_TARGET_FINAL_ERROR_M, lap_encoder_model, lap_motion
from locbench.datasets.synthetic.scenarios import (
    room_motion,
    room_motion_for,
)
from locbench.datasets.synthetic.sensors import EncoderModel, dead_reckon, measured_wheel_travel, odometry_increments
from locbench.datasets.synthetic.toolkit import (
    ENCODER_K_TRUE,
    ROOM_TABLE1_ODOMETRY_CM,
    WHEELBASE_NOMINAL_M,
    split_streams,
)

FloatArray = npt.NDArray[np.float64]


def room_dead_reckoning_errors(
    scale_left: float,
    scale_right: float,
    wheelbase_ratio: float,
    k: float = ENCODER_K_TRUE,
    seeds: Sequence[int] = tuple(range(20)),
    z: Sequence[FloatArray] | None = None,
) -> FloatArray:
    """Table-1 odometry error at each room waypoint for given error constants, m, shape (5,).

    The distance between each waypoint and the mean over ``seeds`` of the dead-reckoned position at the
    waypoint time, with the same noise draws as ``make_dataset("room", seed)`` (the execution noise of the
    true motion and the encoder noise). ``z`` (one (n_seed, 2) array of encoder draws per seed) may hold
    the encoder draws precomputed.
    """
    from locbench.core.seeding import dataset_rng

    model = EncoderModel(
        wheelbase_nominal_m=WHEELBASE_NOMINAL_M, scale_left=scale_left, scale_right=scale_right, k_left=k, k_right=k
    )
    ends = []
    waypoints = None
    for s_i, seed in enumerate(seeds):
        motion = room_motion_for(wheelbase_ratio, seed)
        waypoints = motion.waypoint_xy
        if z is None:
            dl, dr = measured_wheel_travel(motion, model, split_streams(dataset_rng("room", seed))["odometry"])
        else:
            dl = motion.d_left * (1 + scale_left) + k * np.sqrt(np.abs(motion.d_left)) * z[s_i][: motion.n_steps, 0]
            dr = motion.d_right * (1 + scale_right) + k * np.sqrt(np.abs(motion.d_right)) * z[s_i][: motion.n_steps, 1]
        path = dead_reckon(motion.poses[0], odometry_increments(dl, dr, WHEELBASE_NOMINAL_M))
        ends.append(path[np.round(motion.waypoint_t / motion.dt).astype(np.int64), 0:2])
    assert waypoints is not None
    mean_xy = np.mean(np.asarray(ends), axis=0)
    return np.hypot(*(mean_xy - waypoints).T)


def calibrate_room_odometry(seeds: Sequence[int] = tuple(range(20))) -> dict[str, Any]:
    """Fit the world's systematic odometry error to report 003 table 1 (reproducible; not run at build time).

    Least squares (scipy ``least_squares``) over (scale_left, scale_right, wheelbase_ratio) of
    log(measured / target) at the 5 waypoints, with the random constant k fixed at ENCODER_K_TRUE, the
    execution noise at SLIP_K_TRUE and the noise draws of ``make_dataset("room", seed)`` for ``seeds``
    (the true motion is re-simulated for each wheelbase ratio). Returns the fitted constants, the achieved
    errors (cm) and the ratios; freeze them as the module constants.
    """
    from scipy.optimize import least_squares

    from locbench.core.seeding import dataset_rng

    target = np.asarray(ROOM_TABLE1_ODOMETRY_CM) / 100.0
    # Encoder draws for more steps than any tour takes (a prefix of the stream is what a dataset uses).
    n = 2 * room_motion().n_steps
    z = [split_streams(dataset_rng("room", s))["odometry"].standard_normal((n, 2)) for s in seeds]

    def residual(p: FloatArray) -> FloatArray:
        e = room_dead_reckoning_errors(p[0] * 1e-2, p[1] * 1e-2, 1.0 + p[2] * 1e-2, seeds=seeds, z=z)
        return np.log(np.maximum(e, 1e-6) / target)

    best = None
    for x0 in ([0.0, 0.0, 0.0], [1.0, -1.0, 1.0], [-1.0, 1.0, -1.0], [1.0, -1.0, -1.0], [-1.0, 1.0, 1.0]):
        sol = least_squares(residual, np.asarray(x0), diff_step=1e-3)
        if best is None or sol.cost < best.cost:
            best = sol
    assert best is not None
    p = best.x
    achieved = room_dead_reckoning_errors(p[0] * 1e-2, p[1] * 1e-2, 1.0 + p[2] * 1e-2, seeds=seeds, z=z) * 100
    return {
        "scale_left": float(p[0] * 1e-2),
        "scale_right": float(p[1] * 1e-2),
        "wheelbase_ratio": float(1.0 + p[2] * 1e-2),
        "achieved_cm": [float(v) for v in achieved],
        "ratio": [float(v) for v in achieved / (target * 100)],
    }


def lap_dead_reckoning_final_errors(
    scale: float, seeds: Sequence[int] = tuple(range(20)), dataset_name: str = "lap"
) -> FloatArray:
    """Odometry's position error at the last ground-truth time for each seed, m, shape (len(seeds),).

    Uses the same noise draws as ``make_dataset(dataset_name, seed)`` (the execution noise of the true
    motion and the odometry stream).
    """
    from locbench.core.seeding import dataset_rng

    model = lap_encoder_model(scale)
    out = []
    for seed in seeds:
        motion = lap_motion(scale, seed, dataset_name)
        dl, dr = measured_wheel_travel(motion, model, split_streams(dataset_rng(dataset_name, seed))["odometry"])
        path = dead_reckon(motion.poses[0], odometry_increments(dl, dr, WHEELBASE_NOMINAL_M))
        out.append(float(np.hypot(*(path[-1, 0:2] - motion.poses[-1, 0:2]))))
    return np.asarray(out)


def calibrate_lap_odometry(
    seeds: Sequence[int] = tuple(range(20)), target_m: float = LAP_TARGET_FINAL_ERROR_M
) -> dict[str, Any]:
    """Fit ``LAP_SYSTEMATIC_SCALE`` (reproducible; not run at build time).

    Brent's method (scipy ``brentq``) on scale in [0, 1] for median over ``seeds`` of
    :func:`lap_dead_reckoning_final_errors` = ``target_m``. Returns the factor, the achieved median (m)
    and the per-seed errors; freeze them as the module constants.
    """
    from scipy.optimize import brentq

    def f(a: float) -> float:
        return float(np.median(lap_dead_reckoning_final_errors(a, seeds))) - target_m

    lo, hi = 0.0, 1.0
    if f(lo) > 0.0:
        raise ConfigError(f"the random odometry error alone exceeds {target_m} m on this lap; shorten the lap")
    a = float(brentq(f, lo, hi, xtol=1e-6))
    errs = lap_dead_reckoning_final_errors(a, seeds)
    return {"scale": a, "achieved_median_m": float(np.median(errs)), "errors_m": [float(e) for e in errs]}


if __name__ == "__main__":
    which = sys.argv[1] if len(sys.argv) > 1 else "room"
    print(calibrate_room_odometry() if which == "room" else calibrate_lap_odometry())
