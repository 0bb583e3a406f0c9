"""The beam end point p = s + r (cos a, sin a) against its plain numpy form."""

from __future__ import annotations

import math

import numpy as np
import pytest
from laser_reference import beam_points

from locbench.raycast.beams import beam_endpoints


@pytest.mark.parametrize("sensor_pose", [(0.0, 0.0, 0.0), (0.12, -0.05, 0.3), (-0.2, 0.1, -math.pi / 2)])
def test_beam_endpoints_are_the_plain_form(sensor_pose: tuple[float, float, float]) -> None:
    """Against ``laser_reference.beam_points`` (numpy's cos and sin) to 4 ulps of the largest coordinate."""
    rng = np.random.default_rng(4)
    ranges = rng.uniform(0.05, 30.0, 721)
    angles = np.linspace(-math.pi, math.pi, 721)
    x, y = beam_endpoints(ranges, angles, sensor_pose)
    want = beam_points(ranges, angles, sensor_pose)
    np.testing.assert_allclose(np.column_stack([x, y]), want, rtol=0, atol=4 * np.spacing(31.0))


def test_beam_endpoints_hand_values_and_shapes() -> None:
    """A beam straight ahead and one to the left of a sensor turned by 90 degrees; empty scans; mismatches."""
    x, y = beam_endpoints([2.0, 1.0], [0.0, math.pi / 2], (1.0, 0.5, math.pi / 2))
    np.testing.assert_allclose(x, [1.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(y, [2.5, 0.5], atol=1e-15)
    x, y = beam_endpoints(np.empty(0), np.empty(0), (0.0, 0.0, 0.0))
    assert x.shape == y.shape == (0,)
    x, _ = beam_endpoints([np.inf], [0.3], (0.0, 0.0, 0.0))
    assert not np.isfinite(x[0])
    with pytest.raises(ValueError, match="same length"):
        beam_endpoints([1.0, 2.0], [0.0], (0.0, 0.0, 0.0))
