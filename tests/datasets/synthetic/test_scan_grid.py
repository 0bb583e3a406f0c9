"""Tests of the scan_grid scenario (report 004)."""

from __future__ import annotations

import numpy as np
import pytest

from locbench.core.errors import ConfigError
from locbench.core.events import LaserScan, Odometry
from locbench.datasets.synthetic.scan_grid import COMMAND_S, scan_grid_world
from locbench.registry import make_dataset


def test_translate_or_rotate_commands_held_one_second() -> None:
    ds = make_dataset("scan_grid", 0)
    odo = [e for e in ds.events if isinstance(e, Odometry)]
    assert odo and all(e.dt == COMMAND_S for e in odo)
    v = np.array([e.v for e in odo])
    w = np.array([e.omega for e in odo])
    assert not np.any((v != 0) & (w != 0)), "a command both translated and rotated"
    assert np.max(v) == pytest.approx(0.25) and np.max(np.abs(w)) == pytest.approx(np.pi / 4)
    np.testing.assert_allclose(ds.ground_truth.t, np.arange(len(odo) + 1) * COMMAND_S)
    scans = [e for e in ds.events if isinstance(e, LaserScan)]
    assert len(scans) == len(odo) + 1 and scans[0].ranges.shape == (361,)
    assert len(ds.waypoints) == 8
    # the heading crosses +-pi on the westward rows
    assert np.any(np.abs(ds.ground_truth.theta) > 3.1)


def test_mixed_commands_translate_and_rotate_at_once() -> None:
    ds = make_dataset("scan_grid[mixed_commands=true]", 0)
    odo = [e for e in ds.events if isinstance(e, Odometry)]
    both = [e for e in odo if e.v != 0 and e.omega != 0]
    assert len(both) > 0.5 * len(odo)
    assert ds.metadata["mixed_commands_fraction"] > 0.5


@pytest.mark.parametrize("spec", ["scan_grid", "scan_grid[mixed_commands=true]", "scan_grid[grid_step_m=0.5]"])
def test_truth_stays_clear_of_the_walls(spec: str) -> None:
    ds = make_dataset(spec, 1)
    assert float(np.min(scan_grid_world().wall_distance(ds.ground_truth.xy))) > 0.3


def test_kidnap_and_determinism() -> None:
    a = make_dataset("scan_grid[kidnap_m=1.0]", 2)
    b = make_dataset("scan_grid[kidnap_m=1.0]", 2)
    assert len(a.kidnaps) == 1 and np.hypot(*a.kidnaps[0].delta[:2]) == pytest.approx(1.0)
    np.testing.assert_array_equal(a.ground_truth.poses, b.ground_truth.poses)


def test_odometry_has_the_robot_error() -> None:
    ds = make_dataset("scan_grid", 0)
    odo = [e for e in ds.events if isinstance(e, Odometry) and e.omega != 0]
    # the encoders' wheelbase and scale errors make the measured turn differ from the commanded one
    diff = np.array([e.dtheta - e.omega * e.dt for e in odo])
    assert np.mean(np.abs(diff)) > 1e-3


@pytest.mark.parametrize("bad", ["grid_step_m=0.0", "grid_step_m=1.0", "kidnap_m=-1.0"])
def test_bad_params(bad: str) -> None:
    with pytest.raises(ConfigError):
        make_dataset(f"scan_grid[{bad}]", 0)
