"""``iekf_landmarks`` takes ``ekf_landmarks``' configuration (inputs, motion noise, association, gates) by inheriting
its class, so a default or a setting of one is the other's too (without gtsam, which the filter's other tests need)."""

from __future__ import annotations

import pytest

from locbench.filters.ekf_landmarks import LandmarkEKFConfig
from locbench.filters.iekf_landmarks import LandmarkIEKF
from locbench.registry import make_filter


@pytest.mark.parametrize("params", ["", "[association=nearest,gate_probability=0.9]", "[motion_noise_scale=2]"])
def test_the_invariant_ekf_takes_the_ekfs_configuration(params: str) -> None:
    assert LandmarkIEKF.Config is LandmarkEKFConfig
    ekf, iekf = make_filter(f"ekf_landmarks{params}"), make_filter(f"iekf_landmarks{params}")
    assert type(iekf) is LandmarkIEKF
    assert iekf.config == ekf.config
