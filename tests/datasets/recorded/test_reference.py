"""What loaders derive from a reference trajectory: the direction of travel of a position track, and the odometry
noise recovered from odometry against a reference."""

from __future__ import annotations

import numpy as np
import pytest

from locbench.core.geometry import compose, wrap_angle
from locbench.datasets.recorded.reference import derive_odometry_noise, heading_from_track


def test_heading_of_a_circle_is_its_tangent() -> None:
    # counter-clockwise circle of radius 5 m, a sample every 0.1 m: the tangent is the angle + pi/2; a chord of
    # 1.05 m spans 6 steps either side (no sample at exactly half the chord)
    r, n = 5.0, 315
    a = np.arange(n) * 0.1 / r
    xy = np.column_stack([r * np.cos(a), r * np.sin(a)])
    got = heading_from_track(xy, 1.05)
    inner = slice(6, n - 6)  # a centred chord; one-sided within half a chord of the ends
    assert np.max(np.abs(wrap_angle(got[inner] - (a[inner] + np.pi / 2)))) < 1e-9
    # at the ends the chord is one-sided: still along the track, within half the chord's turn
    assert abs(wrap_angle(got[0] - np.pi / 2)) < 0.5 / r


def test_heading_over_a_chord_ignores_jitter_shorter_than_it() -> None:
    rng = np.random.default_rng(3)
    x = np.arange(0.0, 50.0, 0.05)
    xy = np.column_stack([x, 0.01 * rng.standard_normal(x.size)])  # driving along +x with 1 cm of noise
    wide = heading_from_track(xy, 2.0)
    narrow = heading_from_track(xy, 0.05)
    assert np.sqrt(np.mean(wide**2)) < 0.015  # about 1.4 cm of noise across 2 m
    assert np.sqrt(np.mean(narrow**2)) > 0.1  # a chord of one step follows the noise


def test_odometry_noise_recovered_from_a_reference() -> None:
    rng = np.random.default_rng(5)
    n = 4000
    d = rng.uniform(0.2, 1.0, n)
    turn = rng.uniform(-0.8, 0.8, n)
    true_inc = np.column_stack([d, np.zeros(n), turn])
    sxy, stm, str_ = 0.05, 0.06, 0.1
    var_th = stm**2 * d + str_**2 * np.abs(turn)
    noisy = true_inc + np.column_stack(
        [rng.normal(0, sxy * np.sqrt(d)), rng.normal(0, sxy * np.sqrt(d)), rng.normal(0, np.sqrt(var_th))]
    )
    ref = [np.zeros(3)]
    odo = [np.zeros(3)]
    for k in range(n):
        ref.append(compose(ref[-1], true_inc[k]))
        odo.append(compose(odo[-1], noisy[k]))
    got = derive_odometry_noise(np.array(odo), np.array(ref))
    assert got[0] == pytest.approx(sxy, rel=0.08)
    assert got[1] == pytest.approx(stm, rel=0.15)
    assert got[2] == pytest.approx(str_, rel=0.1)
