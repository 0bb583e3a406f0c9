"""Plain numpy forms of the motion models the library steps in compiled kernels (``locbench.filters._motion_kernels``).

Each function restates one model from its equations, vectorised over a cloud, with numpy's trigonometry and the
heading left unwrapped: the tests compare the compiled steps with these to a stated tolerance, headings modulo
2 pi (the two differ in rounding: numpy's vector sine and cosine, the kernels' series about a reference heading).
"""

from __future__ import annotations

import numpy as np


def midpoint_moved(poses: np.ndarray, delta_d: np.ndarray, delta_theta: np.ndarray) -> np.ndarray:
    """Each pose (N, 3) moved by delta_d (m) along the chord at the midpoint heading and turned by delta_theta (rad)
    (report 003 eq. 5; the heading not wrapped)."""
    h = poses[:, 2] + 0.5 * delta_theta
    return np.column_stack(
        [poses[:, 0] + delta_d * np.cos(h), poses[:, 1] + delta_d * np.sin(h), poses[:, 2] + delta_theta]
    )


def wheel_moved(poses: np.ndarray, d_left: np.ndarray, d_right: np.ndarray, wheelbase: float) -> np.ndarray:
    """Each pose (N, 3) moved by its own wheel travel (m): :func:`midpoint_moved` of eq. 1-2's delta_d and
    delta_theta (the heading not wrapped)."""
    return midpoint_moved(poses, 0.5 * (d_left + d_right), (d_right - d_left) / wheelbase)


def increment_moved(poses: np.ndarray, ix: np.ndarray, iy: np.ndarray, ith: np.ndarray) -> np.ndarray:
    """pose (+) (ix, iy, ith) for each pose (N, 3), the increments in the previous robot frame (m, m, rad; the
    heading not wrapped)."""
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    return np.column_stack([poses[:, 0] + c * ix - s * iy, poses[:, 1] + s * ix + c * iy, poses[:, 2] + ith])


def arc(s: np.ndarray, a: np.ndarray) -> np.ndarray:
    """The constant-twist arc (dx, dy, dtheta), (N, 3): s sin(a)/a, s (1 - cos a)/a, a, with the limits at a = 0."""
    s = np.asarray(s, dtype=np.float64)
    a = np.asarray(a, dtype=np.float64)
    small = np.abs(a) < 1e-4
    safe = np.where(small, 1.0, a)
    sinc = np.where(small, 1.0 - a * a / 6.0, np.sin(a) / safe)
    cosc = np.where(small, a * (0.5 - a * a / 24.0), (1.0 - np.cos(a)) / safe)
    return np.stack(np.broadcast_arrays(s * sinc, s * cosc, a + 0.0 * s), axis=-1)


def twist_moved(
    poses: np.ndarray, s: np.ndarray, a: np.ndarray, s0: float, a0: float, increment: tuple[float, float, float]
) -> np.ndarray:
    """Each pose moved by the event's ``increment`` plus arc(s, a) - arc(s0, a0) (the twist model's noise)."""
    d = arc(s, a) - arc(s0, a0) + np.asarray(increment)
    return increment_moved(poses, d[:, 0], d[:, 1], d[:, 2])
