"""pytest-benchmark: ``ekf_icp``'s compiled steps outside its ICP loop against the same equations written with numpy.

The numpy side is the reference form of report 000 eq. 11-13 and 15-18 (``tests/laser_reference.py``: ``F @ P @
F.T + Q`` and the H = I Joseph correction with the innovation formed in Python); the compiled side is
:func:`~locbench.filters._ekf_icp_kernels.predict_pose` and :func:`~locbench.filters._ekf_icp_kernels.correct_pose`
on the state buffer. Each round times a batch of each (alternating which goes first) and the case reports the
median of the rounds' ratios compiled / numpy (unpaired cases drift with the load of the shared machine). The
whole-run figure is ``tools/measure/icp_outside_loop.py``'s.
"""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from kalman_reference import joseph_correct_pose

from locbench.core.geometry import wrap_scalar
from locbench.filters._ekf_icp_kernels import correct_pose, predict_pose, state_buffer

_Q = (0.0005, 0.0005, 0.0005, 0.001, 0.001, 0.0011)
_R = (0.008, 0.008, 0.01)
_P0 = np.array([[0.0025, 0.0004, -0.0001], [0.0004, 0.002, 0.0002], [-0.0001, 0.0002, 0.0012]])
_X0 = np.array([10.0, 5.0, 0.3])
#: Steps per batch: one prediction and one correction each.
_STEPS = 500


def _numpy_steps() -> None:
    """The prediction and correction as numpy calls on 3 x 3 arrays."""
    x, P, R = _X0.copy(), _P0.copy(), np.diag(_R)
    for _ in range(_STEPS):
        th = float(x[2])
        c, s = math.cos(th), math.sin(th)
        dxw, dyw = c * 0.01, s * 0.01
        x = np.array([x[0] + dxw, x[1] + dyw, wrap_scalar(th + 0.001)])
        F = np.array([[1.0, 0.0, -dyw], [0.0, 1.0, dxw], [0.0, 0.0, 1.0]])
        Q = np.diag([_Q[0] * 0.5 + _Q[3] * abs(dxw), _Q[1] * 0.5 + _Q[4] * abs(dyw), _Q[2] * 0.5 + _Q[5] * 0.001])
        P = F @ P @ F.T + Q
        P = 0.5 * (P + P.T)
        th = float(x[2])
        c, s = math.cos(th), math.sin(th)
        V = np.array([c * 0.002 - s * 0.001, s * 0.002 + c * 0.001, wrap_scalar(0.0005)])
        x, P, _ = joseph_correct_pose(x, P, V, R)
        x[2] = wrap_scalar(float(x[2]))


def _compiled_steps() -> None:
    """The same steps through the kernels on one state buffer."""
    s = state_buffer(_X0, _P0, _Q, _R, (1e-4, 1.0))
    for _ in range(_STEPS):
        predict_pose(s, 0.01, 0.0, 0.001, 0.5)
        correct_pose(s, 0.002, 0.001, 0.0005)


def _seconds(fn: Callable[[], None]) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def test_ekf_icp_kernels_over_numpy_paired(benchmark: Any, request: pytest.FixtureRequest) -> None:
    """Compiled over numpy steps, paired: a batch of each per round (alternating which goes first), the
    median of the rounds' ratios."""
    _compiled_steps()  # compile outside the rounds
    ratios: list[float] = []

    def one_round() -> None:
        if len(ratios) % 2:
            numpy_s = _seconds(_numpy_steps)
            compiled_s = _seconds(_compiled_steps)
        else:
            compiled_s = _seconds(_compiled_steps)
            numpy_s = _seconds(_numpy_steps)
        ratios.append(compiled_s / numpy_s)

    benchmark.pedantic(one_round, rounds=1 if benchmark.disabled else 21, iterations=1)
    if not benchmark.disabled:
        ratio = statistics.median(ratios)
        benchmark.extra_info["compiled_over_numpy"] = ratio
        with request.config.pluginmanager.get_plugin("capturemanager").global_and_fixture_disabled():
            print(f"\nekf_icp predict + correct: compiled / numpy {ratio:.3f} (median of {len(ratios)})")
