"""The calibrations of the synthetic robot's systematic odometry error (not run at build time).

:func:`calibrate_room_odometry` fitted ``ENCODER_SCALE_LEFT``, ``ENCODER_SCALE_RIGHT`` and ``WHEELBASE_TRUE_RATIO``
(:mod:`locbench.datasets.synthetic.toolkit`) to report 003's table 1; :func:`calibrate_lap_odometry` fitted
``LAP_SYSTEMATIC_SCALE`` (:mod:`locbench.datasets.synthetic.lap`) to a 15 cm median end-of-lap error. Both frozen
results and what they achieve are constants of those modules (``ROOM_CALIBRATION_ACHIEVED_CM``,
``LAP_CALIBRATION_ACHIEVED_M``); the tests of those datasets check that the error functions here still give them,
and ``tools/derive/calibrate_odometry.py`` reruns a fit.

Both fits take a split (:mod:`locbench.datasets.splits`) and read its tuning seeds only (1000-1019 by default). The
frozen constants were fitted on seeds 0-19 before the split existed and are kept: they are the simulated robot's true
error, which no filter is given; on the tuning seeds the room fit moves them by less than its own two mirrored basins
differ, and the lap's 15 cm target is out of reach (docs/protocols.md, Splits; docs/data.md, "Room odometry
calibration", gives the measurements).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from locbench.core.errors import ConfigError
from locbench.core.seeding import dataset_rng
from locbench.datasets.splits import SYNTHETIC_CALIBRATION, Split
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
    """Report 003 table 1's odometry error at each room waypoint for given error constants.

    The distance between each waypoint and the mean over ``seeds`` of the dead-reckoned position at the
    waypoint time (world frame), with the same noise draws as ``make_dataset("room", seed)`` (the execution
    noise of the true motion and the encoder noise of report 003 eq. 10).

    Parameters
    ----------
    scale_left, scale_right : float
        Systematic wheel-scale errors of the left and right encoder (fractions: 0.01 reads 1 % long).
    wheelbase_ratio : float
        True over nominal wheelbase.
    k : float
        Random encoder error constant k_L = k_R, sqrt(m).
    seeds : sequence of int
        The room's seeds to average over.
    z : sequence of array, optional
        Precomputed standard-normal encoder draws, one (n_steps, 2) array per seed (a prefix of each seed's
        odometry stream); by default drawn from the stream.

    Returns
    -------
    ndarray, shape (5,)
        The error at each waypoint, m.
    """
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


def calibrate_room_odometry(split: Split = SYNTHETIC_CALIBRATION) -> dict[str, Any]:
    """Fit the world's systematic odometry error to report 003 table 1 (reproducible; not run at build time).

    Least squares (scipy ``least_squares``) over (scale_left, scale_right, wheelbase_ratio) of
    log(measured / target) at the 5 waypoints (:func:`room_dead_reckoning_errors`), with the random constant k
    fixed at ``ENCODER_K_TRUE``, the execution noise at ``SLIP_K_TRUE`` and the noise draws of
    ``make_dataset("room", seed)`` for the split's tuning seeds (the true motion is re-simulated for each wheelbase
    ratio); no test seed is read.

    Parameters
    ----------
    split : Split
        Whose tuning seeds the fit averages over (:data:`~locbench.datasets.splits.SYNTHETIC_CALIBRATION`: seeds
        1000-1019).

    Returns
    -------
    dict
        ``scale_left``, ``scale_right``, ``wheelbase_ratio`` (the fitted constants, frozen in
        :mod:`locbench.datasets.synthetic.toolkit`), ``achieved_cm`` (the error at each waypoint, cm) and
        ``ratio`` (achieved over table 1).
    """
    from scipy.optimize import least_squares

    seeds = [int(x) for x in split.check_tuning(split.tuning)]
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
    """Odometry's position error at the last ground-truth time of the lap, one per seed.

    Uses the same noise draws as ``make_dataset(dataset_name, seed)`` (the execution noise of the true
    motion and the odometry stream).

    Parameters
    ----------
    scale : float
        The factor on the systematic error (``LAP_SYSTEMATIC_SCALE``).
    seeds : sequence of int
        The seeds.
    dataset_name : str
        The dataset name whose seed streams are drawn (``lap`` or a variant of it).

    Returns
    -------
    ndarray, shape (len(seeds),)
        Distance between the dead-reckoned and the true final position (world frame), m.
    """
    model = lap_encoder_model(scale)
    out = []
    for seed in seeds:
        motion = lap_motion(scale, seed, dataset_name)
        dl, dr = measured_wheel_travel(motion, model, split_streams(dataset_rng(dataset_name, seed))["odometry"])
        path = dead_reckon(motion.poses[0], odometry_increments(dl, dr, WHEELBASE_NOMINAL_M))
        out.append(float(np.hypot(*(path[-1, 0:2] - motion.poses[-1, 0:2]))))
    return np.asarray(out)


def calibrate_lap_odometry(
    split: Split = SYNTHETIC_CALIBRATION, target_m: float = LAP_TARGET_FINAL_ERROR_M
) -> dict[str, Any]:
    """Fit ``LAP_SYSTEMATIC_SCALE`` (reproducible; not run at build time).

    Brent's method (scipy ``brentq``) on scale in [0, 1] for median over the split's tuning seeds of
    :func:`lap_dead_reckoning_final_errors` = ``target_m``; no test seed is read.

    Parameters
    ----------
    split : Split
        Whose tuning seeds' median is fitted (:data:`~locbench.datasets.splits.SYNTHETIC_CALIBRATION`).
    target_m : float
        The median end-of-lap error to reach, m (report 000 sec. IV: about 15 cm).

    Returns
    -------
    dict
        ``scale`` (the factor, frozen in :mod:`locbench.datasets.synthetic.lap`), ``achieved_median_m`` and
        ``errors_m`` (per seed), m.

    Raises
    ------
    ConfigError
        The random error alone exceeds ``target_m`` (no factor in [0, 1] reaches it).
    """
    from scipy.optimize import brentq

    seeds = [int(x) for x in split.check_tuning(split.tuning)]

    def f(a: float) -> float:
        return float(np.median(lap_dead_reckoning_final_errors(a, seeds))) - target_m

    lo, hi = 0.0, 1.0
    if f(lo) > 0.0:
        raise ConfigError(f"the random odometry error alone exceeds {target_m} m on this lap; shorten the lap")
    a = float(brentq(f, lo, hi, xtol=1e-6))
    errs = lap_dead_reckoning_final_errors(a, seeds)
    return {"scale": a, "achieved_median_m": float(np.median(errs)), "errors_m": [float(e) for e in errs]}
