"""The bound's recursion against Stone Soup's PCRB metric on a common model (skips without stonesoup).

Stone Soup (``pip install 'locbench[stonesoup]'``) implements the same recursion for target tracking: a
constant-velocity target seen in bearing and range by static sensors. Our functions get the model's F and
Q and the range-bearing information of the target's position; the covariances must agree.
"""

from __future__ import annotations

import datetime

import numpy as np
import pytest

from locbench.evaluate import pcrb

stonesoup = pytest.importorskip("stonesoup", reason="Stone Soup not installed (pip install 'locbench[stonesoup]')")

from stonesoup.metricgenerator.pcrbmetric import PCRBMetric  # noqa: E402
from stonesoup.models.measurement.nonlinear import CartesianToBearingRange  # noqa: E402
from stonesoup.models.transition.linear import (  # noqa: E402
    CombinedLinearGaussianTransitionModel,
    ConstantVelocity,
)
from stonesoup.types.array import StateVector  # noqa: E402
from stonesoup.types.groundtruth import GroundTruthPath, GroundTruthState  # noqa: E402
from stonesoup.types.state import GaussianState  # noqa: E402


class _SensorColumns:
    """Sensor positions as the metric indexes them (``locations[:, i]``), each a column StateVector: with
    numpy 2 a column slice of ``StateVectors`` is 1-D, which the metric's bearing-range model cannot offset."""

    def __init__(self, xy: np.ndarray) -> None:
        self.xy = xy
        self.shape = (2, xy.shape[0])

    def __getitem__(self, index: tuple[slice, int]) -> StateVector:
        return StateVector(self.xy[index[1]])


def test_recursion_equals_stone_soup_pcrb_metric() -> None:
    dt, n = 1.0, 40
    sigma_b, sigma_r = 0.02, 0.5
    sensors = np.array([[0.0, 50.0], [30.0, -20.0]])  # (x, y) per sensor
    transition = CombinedLinearGaussianTransitionModel([ConstantVelocity(0.05), ConstantVelocity(0.05)])
    measurement = CartesianToBearingRange(ndim_state=4, mapping=(0, 2), noise_covar=np.diag([sigma_b**2, sigma_r**2]))
    t0 = datetime.datetime(2026, 1, 1)
    x = np.array([5.0, 1.0, 2.0, 0.5])  # (x, vx, y, vy)
    states = []
    for k in range(n + 1):
        states.append(GroundTruthState(x.copy(), timestamp=t0 + datetime.timedelta(seconds=k * dt)))
        x = transition.function(
            GroundTruthState(x, timestamp=t0), noise=False, time_interval=datetime.timedelta(seconds=dt)
        )
        x = np.asarray(x, dtype=np.float64).ravel()
    truth = GroundTruthPath(states)
    p0 = np.diag([4.0, 1.0, 4.0, 1.0])
    prior = GaussianState(np.array(states[0].state_vector), p0, timestamp=t0)
    theirs = PCRBMetric._compute_pcrb_single(
        prior, transition, measurement, truth, _SensorColumns(sensors), 1.0, [0, 2], [1, 3]
    )["inverse_j"]

    f = transition.matrix(time_interval=datetime.timedelta(seconds=dt))
    q = transition.covar(time_interval=datetime.timedelta(seconds=dt))
    jz = np.zeros((n, 4, 4))
    for k in range(1, n + 1):
        pos = np.array([states[k].state_vector[0, 0], states[k].state_vector[2, 0], 0.0])
        info = pcrb.range_bearing_information(pos, sensors, sigma_r, sigma_b)[:2, :2]
        jz[k - 1][np.ix_([0, 2], [0, 2])] = info
    ours = pcrb.pcrb_recursion(np.linalg.inv(p0), np.tile(f, (n, 1, 1)), np.tile(q, (n, 1, 1)), jz)
    # Stone Soup differentiates the bearing-range model numerically (compute_jac), ours analytically: they
    # agree to its finite-difference accuracy (measured: 1.5e-6 relative at most).
    np.testing.assert_allclose(ours, theirs, rtol=1e-5, atol=1e-12)
    # and the measurements matter: without them the bound is far larger
    alone = pcrb.pcrb_recursion(np.linalg.inv(p0), np.tile(f, (n, 1, 1)), np.tile(q, (n, 1, 1)), 0 * jz)
    assert alone[-1, 0, 0] > 10 * theirs[-1, 0, 0]
