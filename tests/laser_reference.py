"""Plain numpy forms of the laser filters' equations, the references the tests compare the library with.

The library computes each of these once, in compiled kernels (``locbench.filters._ekf_icp_kernels``,
``locbench.filters.ekf_lines``, ``locbench.filters._line_extraction``). The forms here write the same equations
the obvious way with numpy, for reading and for comparison within a stated tolerance: numpy's matrix products
(BLAS) and its vectorised sin and cos round differently from the kernels' scalar arithmetic, so equality to the
bit is neither expected nor tested.

Frames and units: world frame for poses (x m, y m, theta rad), robot frame for scan points (m).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from locbench.core.geometry import wrap_angle, wrap_scalar

FloatArray = npt.NDArray[np.float64]


def beam_points(ranges: FloatArray, angles: FloatArray, sensor_pose: tuple[float, float, float]) -> FloatArray:
    """Beam end points in the robot frame, m, shape (n, 2).

    Parameters
    ----------
    ranges : ndarray, shape (n,)
        Finite ranges, m.
    angles : ndarray, shape (n,)
        Beam bearings in the sensor frame, rad.
    sensor_pose : tuple of float
        (sx m, sy m, stheta rad), the sensor's mounting pose in the robot frame.
    """
    sx, sy, sth = sensor_pose
    a = np.asarray(angles, dtype=np.float64) + sth
    r = np.asarray(ranges, dtype=np.float64)
    return np.column_stack([sx + r * np.cos(a), sy + r * np.sin(a)])


def icp_ekf_predict(
    x: FloatArray, P: FloatArray, u: tuple[float, float, float], k: float, q: tuple[float, ...]
) -> tuple[FloatArray, FloatArray]:
    """The odometry prediction of report 000, eq. 11-13.

    Parameters
    ----------
    x, P : ndarray, shapes (3,) and (3, 3)
        Pose (x m, y m, theta rad) and its covariance.
    u : tuple of float
        (dx m, dy m, dtheta rad), the increment in the previous robot frame.
    k : float
        dt / period: the factor of Q's static terms.
    q : tuple of float
        (q_x,stat, q_y,stat, q_theta,stat, q_x,dyn, q_y,dyn, q_theta,dyn) of eq. 13.

    Returns
    -------
    x, P : ndarray
        X + (dx_w, dy_w, dtheta) with the heading wrapped (eq. 11, the increment rotated into the world frame),
        and F P F^T + Q symmetrised (eq. 12-13).
    """
    c, s = math.cos(x[2]), math.sin(x[2])
    dxw, dyw = c * u[0] - s * u[1], s * u[0] + c * u[1]
    F = np.array([[1.0, 0.0, -dyw], [0.0, 1.0, dxw], [0.0, 0.0, 1.0]])
    Q = np.diag([q[i] * k + q[i + 3] * abs(d) for i, d in enumerate((dxw, dyw, u[2]))])
    Pn = F @ P @ F.T + Q
    return np.array([x[0] + dxw, x[1] + dyw, wrap_scalar(x[2] + u[2])]), 0.5 * (Pn + Pn.T)


def icp_gates(
    used_ranges: FloatArray, P: FloatArray, pair_var: float, cap: float, sigmas: float
) -> tuple[float, float]:
    """The ICP rejection distances of :mod:`locbench.filters.ekf_icp`: (D_0, D_min), m.

    D_min = k sqrt(pair_var) and D_0 = min(k sqrt(pair_var + lambda_max(P_xy) + r_mean^2 P_thth), cap), at
    least D_min; ``used_ranges`` are the real scan's usable ranges (m), k = ``sigmas``.
    """
    lam = float(np.linalg.eigvalsh(P[0:2, 0:2])[-1])
    r_mean = float(np.mean(used_ranges))
    d_min = sigmas * math.sqrt(pair_var)
    return max(min(sigmas * math.sqrt(pair_var + lam + r_mean**2 * P[2, 2]), cap), d_min), d_min


def expected_line(pose: npt.ArrayLike, rho_w: npt.ArrayLike, psi_w: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Signed robot-frame (rho m, psi rad) of world lines (rho_w, psi_w) seen from ``pose``, report 002 eq. 3.

    rho_r = rho_w - (x cos psi_w + y sin psi_w) (negative when the robot and the world origin lie on opposite
    sides of the line, which is then (-rho_r, psi_r + pi)); psi_r = psi_w - theta wrapped to (-pi, pi].
    """
    x, y, th = (float(v) for v in np.asarray(pose, dtype=np.float64)[:3])
    rw = np.asarray(rho_w, dtype=np.float64)
    pw = np.asarray(psi_w, dtype=np.float64)
    return rw - (x * np.cos(pw) + y * np.sin(pw)), wrap_angle(pw - th)


def expected_line_jacobian(psi_w: float, sign: float = 1.0) -> FloatArray:
    """H = d(rho_r, psi_r)/d(x, y, theta) of eq. 3, shape (2, 3); ``sign`` = -1 for the flipped form."""
    return np.array([[-sign * math.cos(psi_w), -sign * math.sin(psi_w), 0.0], [0.0, 0.0, -1.0]])


def line_innovation(
    z: tuple[float, float], rho_w: float, psi_w: float, pose: tuple[float, float, float], sign: float
) -> tuple[float, float]:
    """v = z - h(x) of report 002 eq. 4 for an observed line z = (rho, psi) and a map line, in the form ``sign``
    (+1: eq. 3's (rho_r, psi_r); -1: the flipped (-rho_r, psi_r + pi)), the angle wrapped; (m, rad)."""
    rho_r, psi_r = expected_line(pose, rho_w, psi_w)
    h_psi = float(psi_r) + (math.pi if sign < 0 else 0.0)
    return z[0] - sign * float(rho_r), wrap_scalar(z[1] - h_psi)


def joseph_correct(
    x: FloatArray, P: FloatArray, v: FloatArray, H: FloatArray, R: FloatArray
) -> tuple[FloatArray, FloatArray, float]:
    """One EKF correction in the Joseph form, report 002 eq. 5-8: (x + K v, P+ symmetrised, v^T S^-1 v).

    S = H P H^T + R (eq. 5), K = P H^T S^-1 (eq. 6), x + K v (eq. 7), (I - K H) P (I - K H)^T + K R K^T (eq. 8).
    """
    S = H @ P @ H.T + R
    Sinv = np.linalg.inv(S)
    K = P @ H.T @ Sinv
    A = np.eye(P.shape[0]) - K @ H
    Pn = A @ P @ A.T + K @ R @ K.T
    return x + K @ v, 0.5 * (Pn + Pn.T), float(v @ Sinv @ v)
