"""A fixed reference workload: the unit in which runtimes transfer from one machine (or load) to another.

The workload mixes the three kinds of work the filters do, in 16 equal pieces: a Gaussian filter's predict and
Joseph-form update on 3 x 3 matrices (numpy call overhead dominates, as in every Kalman filter of locbench), a
particle filter's weighting and low-variance resampling of 2,000 particles (vectorised numpy), and a
pure-Python loop (the per-event bookkeeping, association loops and ray marching around the numpy calls). Its
work is fixed: the same inputs (a fixed seed), the same operations in the same order, so it returns the same
checksum every time; only its time varies. :func:`measure` times it a few times and keeps the median, so a
single busy moment does not set the unit.

A runtime in reference units is the raw time divided by the time the reference workload took on the same
machine under the same load (``reference_s`` of the run's provenance; for per-call medians its CPU time
``reference_cpu_s``, :func:`locbench.evaluate.metrics.reference_units`): what the time would be on a machine whose
reference workload takes 1 s. ``python -m locbench.run.reference_workload`` prints this machine's ``reference_s``.
"""

from __future__ import annotations

import statistics
import time
from typing import NamedTuple

import numpy as np

#: Timed repeats of one measurement (the median is kept) and untimed warm-up passes before them.
REPEATS = 5
WARMUP = 1
#: A pass is this many equal pieces (:func:`run_piece`): interleaved timing runs one piece at a time between the
#: filters' slices, so the reference sees the load they see.
PIECES = 16
#: Sizes of the three parts of a piece: a pass takes 0.3-0.4 s on the project's 2-core machine under the load of
#: other work, so a measurement (warm-up and repeats) takes 1-2.5 s.
KALMAN_STEPS = 50
PARTICLES = 2_000
PARTICLE_STEPS = 2
PYTHON_STEPS = 5_000


def _kalman(steps: int) -> float:
    """An EKF over a fixed circle with range-bearing-like 2-D updates; returns the trace of the last covariance."""
    x = np.zeros(3)
    p = np.eye(3) * 0.1
    q = np.diag([1e-4, 1e-4, 1e-5])
    r = np.diag([1e-2, 1e-3])
    eye = np.eye(3)
    for k in range(steps):
        c, s = np.cos(x[2]), np.sin(x[2])
        f = np.array([[1.0, 0.0, -0.05 * s], [0.0, 1.0, 0.05 * c], [0.0, 0.0, 1.0]])
        x = x + np.array([0.05 * c, 0.05 * s, 0.01])
        p = f @ p @ f.T + q
        d = np.array([4.0, 3.0]) - x[:2]
        q2 = float(d @ d)
        h = np.array([[-d[0], -d[1], 0.0], [d[1], -d[0], -q2]]) / q2
        sm = h @ p @ h.T + r
        gain = p @ h.T @ np.linalg.inv(sm)
        innov = np.array([0.01 * np.sin(k), 0.001 * np.cos(k)])
        x = x + gain @ innov
        a = eye - gain @ h
        p = a @ p @ a.T + gain @ r @ gain.T
    return float(np.trace(p))


def _particles(n: int, steps: int) -> float:
    """Motion noise, Gaussian weights against a fixed measurement and low-variance resampling; returns the mean x."""
    rng = np.random.default_rng(20261202)
    pts = rng.normal(0.0, 0.5, size=(n, 3))
    for _ in range(steps):
        pts[:, 0] += 0.05 * np.cos(pts[:, 2]) + rng.normal(0.0, 0.01, n)
        pts[:, 1] += 0.05 * np.sin(pts[:, 2]) + rng.normal(0.0, 0.01, n)
        pts[:, 2] += rng.normal(0.0, 0.005, n)
        d2 = (pts[:, 0] - 1.0) ** 2 + (pts[:, 1] - 0.5) ** 2
        w = np.exp(-0.5 * d2 / 0.25)
        w /= w.sum()
        cum = np.cumsum(w)
        cum[-1] = 1.0
        idx = np.searchsorted(cum, (rng.random() + np.arange(n)) / n)
        pts = pts[idx]
    return float(np.mean(pts[:, 0]))


def _python(steps: int) -> float:
    """Pure-Python arithmetic and branching (an LCG, angle wrapping, a running sum); returns the sum."""
    state = 12345
    total = 0.0
    angle = 0.0
    for _ in range(steps):
        state = (1103515245 * state + 12345) & 0x7FFFFFFF
        angle += (state % 1000) * 0.001 - 0.4995
        if angle > 3.141592653589793:
            angle -= 6.283185307179586
        elif angle < -3.141592653589793:
            angle += 6.283185307179586
        total += angle * angle
    return total


def run_piece() -> float:
    """One of the :data:`PIECES` equal pieces of a pass; returns its checksum (the same on every call)."""
    return _kalman(KALMAN_STEPS) + _particles(PARTICLES, PARTICLE_STEPS) + _python(PYTHON_STEPS)


def run_once() -> float:
    """One pass of the reference workload (:data:`PIECES` pieces); returns its checksum (the same on every call)."""
    return sum(run_piece() for _ in range(PIECES))


class Measurement(NamedTuple):
    """One measurement of the reference workload."""

    #: The median pass's wall time, s (``reference_s``: the clock the runner times filter calls with).
    wall_s: float
    #: The median pass's CPU time of this thread, s (``reference_cpu_s``: the time without the others' turns).
    cpu_s: float
    #: Every timed pass's wall time, s.
    runs_s: list[float]


def measure(repeats: int = REPEATS, warmup: int = WARMUP) -> Measurement:
    """Time :func:`run_once` ``repeats`` times, wall clock and thread CPU time, after ``warmup`` untimed passes."""
    if repeats < 1:
        raise ValueError(f"repeats must be at least 1, got {repeats}")
    for _ in range(warmup):
        run_once()
    wall, cpu = [], []
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), time.thread_time()
        run_once()
        cpu.append(time.thread_time() - start_cpu)
        wall.append(time.perf_counter() - start)
    return Measurement(statistics.median(wall), statistics.median(cpu), wall)


if __name__ == "__main__":
    m = measure()
    print(f"reference_s = {m.wall_s:.4f} s (median of {', '.join(f'{t:.4f}' for t in m.runs_s)}); CPU {m.cpu_s:.4f} s")
