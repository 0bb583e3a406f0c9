"""The posterior Cramer-Rao bound (PCRB) of a synthetic world, from the simulator's true model.

Tichavsky, Muravchik and Nehorai (1998), "Posterior Cramer-Rao bounds for discrete-time nonlinear
filtering", IEEE Trans. Signal Processing 46(5): for x_{k+1} = f_k(x_k) + w_k, w_k ~ N(0, Q_k), and
measurements z_k = h_k(x_k) + v_k, v_k ~ N(0, R_k), the Fisher information J_k of the state obeys

    J_{k+1} = D22_k - D21_k (J_k + D11_k)^-1 D12_k                                   (TMN eq. 21)

    D11_k = F_k' Q_k^-1 F_k,   D12_k = -F_k' Q_k^-1 = D21_k',
    D22_k = Q_k^-1 + sum over the sensors at k+1 of H' R^-1 H                        (TMN eq. 34-36)

with F_k and H the Jacobians of f_k and h (here evaluated along the true trajectory: the expectation over
the state is taken at its one realised value, the usual practice for a bound "along the trajectory").
Any estimate's error covariance satisfies E[e e'] >= J^-1. With the matrix inversion lemma the recursion
is J_{k+1} = (Q_k + F_k J_k^-1 F_k')^-1 + J_z,k+1, which needs no Q_k^-1: a robot standing still has
Q_k = 0 (its wheel noise is proportional to the travel), so :func:`information_step` uses that form;
:func:`tmn_step` is the literal eq. 21 for a non-singular Q_k (a test checks that they agree).

What the bound of a locbench world covers (docs/pcrb.md):

* motion: the wheel odometry as the control input (x_{k+1} = pose composed with the increment of the true
  wheel travel), each wheel's travel known from its encoder with the true random error of variance
  k^2 |d| (report 003 eq. 10), mapped to the pose increment to first order in that error. The systematic
  wheel-scale and wheelbase errors are deterministic, hence known to the true model: they move no
  information (only the scale divides the variance by (1 + scale)^2, and the Jacobians use the true
  wheelbase). The commanded twist is not used: the planner computes it from the true pose (feedback), so
  it is not an independent input, and only ``kf_linear`` reads it;
* range-bearing landmark sightings with the true noise (range, field-of-view limits, occlusion and
  detection as realised in the dataset: the bound is conditioned on which landmarks were seen, which does
  not depend on the estimate) and known association (withheld identities are associated at the truth);
* range-only observations and GPS-like position fixes with their true noise;
* the laser scans: each returned beam with the true range noise, its range the simulator's exact ray
  traversal of the occupancy grid, differentiated w.r.t. the pose by central differences
  (:func:`laser_information`); beams that graze a cell corner (not differentiable), realised dropouts and
  returns off the map (people) are left out, which can only loosen the bound. On ``landmark_geometry`` the
  sightings are computed from the scans, so with the laser they are not counted again (without it,
  ``laser=False``, the bound uses them with the detector's measured error RMS, the nominal noise).

Kidnapped runs have no bound (a jump is outside the motion model): :func:`pcrb_covariances` refuses them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from numba import njit

from locbench.core.errors import ConfigError
from locbench.core.events import UNKNOWN_ID, LandmarkObservations, LaserScan, PoseFix, RangeObservations
from locbench.core.geometry import wrap_angle
from locbench.datasets.dataset import Dataset
from locbench.evaluate.metrics import ATE_M, HEADING_RMSE_RAD, WAYPOINT_ERROR_M, member_id

FloatArray = npt.NDArray[np.float64]


# --- the recursion: pure functions of arrays ---------------------------------------------------------------


def tmn_step(j: FloatArray, f: FloatArray, q: FloatArray, j_meas: FloatArray) -> FloatArray:
    """One step of Tichavsky et al. 1998 eq. 21 with additive Gaussian process noise.

    Parameters
    ----------
    j : ndarray, shape (n, n)
        Fisher information J_k of the state at step k (units: inverse of the state's squared units).
    f : ndarray, shape (n, n)
        Jacobian F_k of the transition at the true state.
    q : ndarray, shape (n, n)
        Process noise covariance Q_k; must be non-singular (see :func:`information_step` otherwise).
    j_meas : ndarray, shape (n, n)
        Measurement information at step k+1, the sum of H' R^-1 H over its sensors (eq. 36).

    Returns
    -------
    ndarray, shape (n, n)
        J_{k+1} = D22 - D21 (J_k + D11)^-1 D12.
    """
    qi = np.linalg.inv(q)
    d11 = f.T @ qi @ f
    d12 = -f.T @ qi
    d22 = qi + j_meas
    out: FloatArray = d22 - d12.T @ np.linalg.solve(j + d11, d12)
    return 0.5 * (out + out.T)


def information_step(j: FloatArray, f: FloatArray, q: FloatArray, j_meas: FloatArray) -> FloatArray:
    """One step of the same recursion in the form J_{k+1} = (Q_k + F_k J_k^-1 F_k')^-1 + J_meas.

    Equal to :func:`tmn_step` by the matrix inversion lemma when Q_k is non-singular, and defined for a
    singular (even zero) Q_k as long as J_k is (a robot standing still). Arguments as in :func:`tmn_step`.
    """
    p = f @ np.linalg.solve(j, f.T) + q
    out: FloatArray = np.linalg.inv(0.5 * (p + p.T)) + j_meas
    return 0.5 * (out + out.T)


def pcrb_recursion(j0: FloatArray, jacobians: FloatArray, process_cov: FloatArray, meas_info: FloatArray) -> FloatArray:
    """Bound covariances J_k^-1 at steps 0..n.

    Parameters
    ----------
    j0 : ndarray, shape (d, d)
        Prior information J_0 plus the measurement information at step 0.
    jacobians, process_cov : ndarray, shape (n, d, d)
        F_k and Q_k of the transition from step k to k+1.
    meas_info : ndarray, shape (n, d, d)
        Measurement information at step k+1.

    Returns
    -------
    ndarray, shape (n+1, d, d)
        The bound's covariance J_k^-1 at every step.
    """
    out: FloatArray = _recursion(*_contiguous(j0, jacobians, process_cov, meas_info))
    return out


def _contiguous(*arrays: FloatArray) -> list[FloatArray]:
    """The arrays as C-contiguous float64, the layout the compiled recursions are typed for."""
    return [np.ascontiguousarray(a, dtype=np.float64) for a in arrays]


@njit(cache=True)
def _recursion(j0: FloatArray, jacobians: FloatArray, process_cov: FloatArray, meas_info: FloatArray) -> FloatArray:
    """:func:`pcrb_recursion` compiled: :func:`information_step` at every step, the same operations (numba's
    solve, inverse and products call LAPACK and BLAS as numpy's do; equal to rounding)."""
    n = jacobians.shape[0]
    out = np.empty((n + 1, j0.shape[0], j0.shape[1]))
    j = j0.copy()
    out[0] = np.linalg.inv(j)
    for k in range(n):
        f = jacobians[k]
        p = f @ np.linalg.solve(j, np.ascontiguousarray(f.T)) + process_cov[k]
        m = np.linalg.inv(0.5 * (p + p.T)) + meas_info[k]
        j = 0.5 * (m + m.T)
        out[k + 1] = np.linalg.inv(j)
    return out


def covariance_recursion(
    p0: FloatArray, jacobians: FloatArray, process_cov: FloatArray, meas_info: FloatArray
) -> FloatArray:
    """Bound covariances P_k at steps 0..n from a possibly singular prior covariance ``p0`` (d, d).

    The covariance form of :func:`pcrb_recursion`: P^- = F P F' + Q, then P = (I + P^- J_meas)^-1 P^-, which is
    (P^-^-1 + J_meas)^-1 whenever P^- is invertible and stays defined for a zero prior (a robot that starts
    at its exact true pose) and for the standstill steps after it (Q = 0). Other arguments as there.
    """
    out: FloatArray = _covariance_recursion(*_contiguous(p0, jacobians, process_cov, meas_info))
    return out


@njit(cache=True)
def _covariance_recursion(
    p0: FloatArray, jacobians: FloatArray, process_cov: FloatArray, meas_info: FloatArray
) -> FloatArray:
    """:func:`covariance_recursion` compiled: the same products and solve at every step (numba's call LAPACK
    and BLAS as numpy's do; equal to rounding). Python's per-step calls of numpy were a quarter of a bound."""
    n = jacobians.shape[0]
    eye = np.eye(p0.shape[0])
    out = np.empty((n + 1, p0.shape[0], p0.shape[1]))
    p = p0.copy()
    out[0] = p
    for k in range(n):
        f = jacobians[k]
        pp = f @ p @ np.ascontiguousarray(f.T) + process_cov[k]
        p = np.linalg.solve(eye + pp @ meas_info[k], pp)
        p = 0.5 * (p + p.T)
        out[k + 1] = p
    return out


def wheel_travel_from_poses(poses: FloatArray, wheelbase_m: float) -> tuple[FloatArray, FloatArray]:
    """The wheel travel (d_left, d_right) of each step between consecutive poses, m, shape (n,) each.

    Inverts report 003 eq. 1, 2 and 5 (the mid-point arc): dtheta = wrapped heading change, the travel dd is
    the displacement projected on the mid-point heading (signed), d_left/right = dd -/+ W dtheta / 2. Exact
    for poses the simulator produced with that model and wheelbase ``wheelbase_m`` (m).
    """
    poses = np.asarray(poses, dtype=np.float64)
    th0 = poses[:-1, 2]
    dth = wrap_angle(poses[1:, 2] - th0)
    dxy = poses[1:, 0:2] - poses[:-1, 0:2]
    mid = th0 + 0.5 * dth
    dd = np.cos(mid) * dxy[:, 0] + np.sin(mid) * dxy[:, 1]
    return dd - 0.5 * wheelbase_m * dth, dd + 0.5 * wheelbase_m * dth


def odometry_step_terms(
    poses: FloatArray, wheelbase_m: float, k_left: float, k_right: float, scale_left: float, scale_right: float
) -> tuple[FloatArray, FloatArray]:
    """Jacobians F_k and process covariances Q_k of wheel odometry along a true trajectory.

    Parameters
    ----------
    poses : ndarray, shape (n+1, 3)
        True poses (x m, y m, theta rad) at the odometry steps, world frame.
    wheelbase_m : float
        TRUE wheelbase W, m.
    k_left, k_right : float
        True random encoder constants, sqrt(m): a wheel's measured travel has variance k^2 |d| (report 003
        eq. 10).
    scale_left, scale_right : float
        True systematic relative scale of each encoder (deterministic, so known to the true model: the
        travel inferred from a reading has variance k^2 |d| / (1 + scale)^2).

    Returns
    -------
    (F, Q) : ndarrays, shape (n, 3, 3)
        The transition Jacobian w.r.t. the pose and the covariance of the world-frame pose increment
        (first order in the wheel error) of each step. The true wheel travel of step k is recovered from the
        true poses by inverting report 003 eq. 1, 2 and 5 (the mid-point arc).
    """
    poses = np.asarray(poses, dtype=np.float64)
    th0 = poses[:-1, 2]
    dth = wrap_angle(poses[1:, 2] - th0)
    dxy = poses[1:, 0:2] - poses[:-1, 0:2]
    half = 0.5 * dth
    d_left, d_right = wheel_travel_from_poses(poses, wheelbase_m)
    dd = 0.5 * (d_left + d_right)
    n = dth.shape[0]
    f = np.tile(np.eye(3), (n, 1, 1))
    f[:, 0, 2] = -dxy[:, 1]
    f[:, 1, 2] = dxy[:, 0]
    c, s = np.cos(half), np.sin(half)
    w2 = 2.0 * wheelbase_m
    # d(dx, dy, dtheta)_robot / d(d_left, d_right), with dx = dd cos(dth/2), dy = dd sin(dth/2).
    g = np.empty((n, 3, 2))
    g[:, 0, 0] = 0.5 * c + dd * s / w2
    g[:, 0, 1] = 0.5 * c - dd * s / w2
    g[:, 1, 0] = 0.5 * s - dd * c / w2
    g[:, 1, 1] = 0.5 * s + dd * c / w2
    g[:, 2, 0] = -1.0 / wheelbase_m
    g[:, 2, 1] = 1.0 / wheelbase_m
    rot = np.zeros((n, 3, 3))
    ct, st = np.cos(th0), np.sin(th0)
    rot[:, 0, 0], rot[:, 0, 1], rot[:, 1, 0], rot[:, 1, 1], rot[:, 2, 2] = ct, -st, st, ct, 1.0
    gw = rot @ g
    var = np.column_stack(
        [k_left**2 * np.abs(d_left) / (1.0 + scale_left) ** 2, k_right**2 * np.abs(d_right) / (1.0 + scale_right) ** 2]
    )
    q = np.einsum("nij,nj,nkj->nik", gw, var, gw)
    return f, q


def range_bearing_information(
    pose: FloatArray, landmarks_xy: FloatArray, sigma_range_m: float, sigma_bearing_rad: float
) -> FloatArray:
    """Sum of H' R^-1 H of range-bearing sightings of ``landmarks_xy`` (m, shape (m, 2)) from ``pose``.

    H is the Jacobian of (range m, bearing rad) w.r.t. (x, y, theta); R = diag(sigma_range^2,
    sigma_bearing^2). Returns a (3, 3) information matrix.
    """
    d = np.asarray(landmarks_xy, dtype=np.float64).reshape(-1, 2) - pose[None, 0:2]
    q = np.maximum(np.einsum("ij,ij->i", d, d), 1e-12)
    r = np.sqrt(q)
    hr = np.column_stack([-d[:, 0] / r, -d[:, 1] / r, np.zeros_like(r)])
    hb = np.column_stack([d[:, 1] / q, -d[:, 0] / q, -np.ones_like(r)])
    out: FloatArray = hr.T @ hr / sigma_range_m**2 + hb.T @ hb / sigma_bearing_rad**2
    return out


def range_information(pose: FloatArray, landmarks_xy: FloatArray, sigma_range_m: float) -> FloatArray:
    """Sum of H' R^-1 H of range-only measurements to ``landmarks_xy`` (m, shape (m, 2)) from ``pose``."""
    d = np.asarray(landmarks_xy, dtype=np.float64).reshape(-1, 2) - pose[None, 0:2]
    r = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-6)
    hr = np.column_stack([-d[:, 0] / r, -d[:, 1] / r, np.zeros_like(r)])
    out: FloatArray = hr.T @ hr / sigma_range_m**2
    return out


def laser_information(
    occupied: npt.NDArray[np.bool_],
    resolution_m: float,
    origin_xy: tuple[float, float],
    robot_poses: FloatArray,
    mount: tuple[float, float, float],
    angles: FloatArray,
    max_range_m: float,
    min_range_m: float,
    sigma_m: float,
    measured: FloatArray,
    eps: float = 1e-5,
) -> FloatArray:
    """Fisher information of laser scans about the robot pose, one (3, 3) matrix per scan.

    The true range of a beam is the simulator's exact ray traversal of the occupancy grid
    (:func:`locbench.raycast.cast.cast_rays`, ``method="dda"``: the distance to the entry point of the first
    occupied cell, a piecewise smooth function of the pose), plus Gaussian noise of ``sigma_m``. A beam's
    information is g g' / sigma^2, g the gradient of its range w.r.t. the robot pose (x m, y m, theta rad):
    in closed form from the face of the cell the beam hits (:func:`locbench.raycast.cast.scan_gradients`, one
    traversal per beam), and by central differences of step ``eps`` (six more casts of that beam) where the
    range may not be smooth at that step (near a corner of occupied cells); the two agree to the differences'
    own error (about 1e-9 relative). A beam is left out (which can only loosen the bound) where the range is
    not differentiable (the one-sided differences disagree: the beam grazes a cell corner), where
    it has no finite return within [min_range_m, max_range_m], or where the ``measured`` range (S, B, m) is
    missing (a realised dropout) or more than 5 sigma from the map's (a return off the map, e.g. from a
    person). Returns shape (S, 3, 3).
    """
    from locbench.raycast.cast import cast_ray_subset, scan_gradients

    poses = np.asarray(robot_poses, dtype=np.float64)
    mx, my, mth = mount
    occ = np.ascontiguousarray(occupied, dtype=np.bool_)
    ox, oy = float(origin_xy[0]), float(origin_xy[1])
    a = np.ascontiguousarray(angles, dtype=np.float64)

    def sensor_of(p: FloatArray) -> FloatArray:
        c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
        out: FloatArray = np.column_stack([p[:, 0] + c * mx - s * my, p[:, 1] + s * mx + c * my, p[:, 2] + mth])
        return out

    # One traversal per beam gives the range, the face it hits and, away from cell corners, the range's
    # derivative in closed form; the beams near a corner (or too curved in the heading) are differenced as
    # before, from six more casts of those beams only.
    r0, grads, smooth = scan_gradients(
        occ, float(resolution_m), ox, oy, sensor_of(poses), poses[:, 2].copy(), (mx, my), a, float(max_range_m), eps
    )
    with np.errstate(invalid="ignore"):
        returned = np.isfinite(measured) & (np.abs(measured - r0) <= 5.0 * sigma_m)
    ok = np.isfinite(r0) & (r0 >= min_range_m) & (r0 <= max_range_m) & returned
    rows, beams = np.nonzero(ok & ~smooth)
    if rows.size:
        base = r0[rows, beams]
        good = np.ones(rows.size, dtype=np.bool_)
        # the six perturbed casts in one call: (x+, x-, y+, y-, theta+, theta-), each step sign * eps * unit
        steps = [sign * eps * np.eye(3)[i] for i in range(3) for sign in (1.0, -1.0)]
        cast = cast_ray_subset(
            occ, float(resolution_m), ox, oy, np.stack([sensor_of(poses + d) for d in steps]), a, float(max_range_m),
            rows, beams,
        )  # fmt: skip
        for i in range(3):
            rp, rm = cast[2 * i], cast[2 * i + 1]
            with np.errstate(invalid="ignore"):
                fwd, bwd = (rp - base) / eps, (base - rm) / eps
                good &= np.isfinite(fwd) & np.isfinite(bwd) & (np.abs(fwd - bwd) <= 1e-4 * (1.0 + np.abs(fwd)))
                grads[rows, beams, i] = 0.5 * (fwd + bwd)
        ok[rows[~good], beams[~good]] = False
    grads[~ok] = 0.0
    out: FloatArray = np.einsum("sbi,sbj->sij", grads, grads) / sigma_m**2
    return out


def position_fix_information(sigma_xy_m: float) -> FloatArray:
    """H' R^-1 H of an (x, y) fix with per-axis standard deviation ``sigma_xy_m`` (m), shape (3, 3)."""
    out = np.zeros((3, 3))
    out[0, 0] = out[1, 1] = 1.0 / sigma_xy_m**2
    return out


# --- a synthetic dataset's true model ---------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class TrueNoise:
    """The simulator's true random noise of a synthetic dataset (read from its metadata).

    Attributes
    ----------
    wheelbase_m : float
        True wheelbase, m.
    k_left, k_right : float
        True random encoder constants, sqrt(m).
    scale_left, scale_right : float
        True systematic encoder scales (deterministic).
    landmark_sigma_range_m, landmark_sigma_bearing_rad : float or None
        True range-bearing noise (None: no landmark sensor).
    range_sigma_m : float or None
        True range-only noise (None: none).
    fix_sigma_xy_m : float or None
        True per-axis noise of the position fixes (None: no fixes).
    laser_sigma_m : float or None
        True laser range noise, m (None: no laser).
    sightings_from_laser : bool
        The landmark sightings are computed from the laser scans (``landmark_geometry`` unless matched):
        they carry no information beyond the scans', so the bound uses the scans when it uses the laser.
    """

    wheelbase_m: float
    k_left: float
    k_right: float
    scale_left: float = 0.0
    scale_right: float = 0.0
    landmark_sigma_range_m: float | None = None
    landmark_sigma_bearing_rad: float | None = None
    range_sigma_m: float | None = None
    fix_sigma_xy_m: float | None = None
    laser_sigma_m: float | None = None
    sightings_from_laser: bool = False


def true_noise(dataset: Dataset) -> TrueNoise:
    """The true noise model of a synthetic ``dataset`` from its metadata (``true_odometry_error``,
    ``sensors_true``); ConfigError naming the missing field for a dataset that does not record it."""
    meta: dict[str, Any] = dict(dataset.metadata or {})
    odo = meta.get("true_odometry_error")
    if not isinstance(odo, dict):
        raise ConfigError(
            f"dataset {dataset.name!r}: metadata field 'true_odometry_error' missing; expected a synthetic world"
        )
    sensors = meta.get("sensors_true", {}) or {}
    lm = sensors.get("landmarks")
    fixes = sensors.get("fixes")
    lm_r = lm_b = None
    from_laser = False
    if lm is not None:
        lm_r, lm_b = float(lm["sigma_range_m"]), float(lm["sigma_bearing_rad"])
    elif any(isinstance(e, LandmarkObservations) for e in dataset.events):
        from_laser = True
        # Sightings made by a detector (landmark_geometry): its measured error RMS, the nominal noise.
        lm_r, lm_b = dataset.sensors.landmark_sigma_range_m, dataset.sensors.landmark_sigma_bearing_rad
    return TrueNoise(
        wheelbase_m=float(odo["wheelbase_true_m"]),
        k_left=float(odo["k_left"]),
        k_right=float(odo["k_right"]),
        scale_left=float(odo.get("scale_left", 0.0)),
        scale_right=float(odo.get("scale_right", 0.0)),
        landmark_sigma_range_m=lm_r,
        landmark_sigma_bearing_rad=lm_b,
        range_sigma_m=None if sensors.get("ranges") is None else float(sensors["ranges"]["sigma_m"]),
        fix_sigma_xy_m=None if fixes is None else float(fixes["sigma_xy_m"]),
        # scan_grid records no sensors_true: its laser's true noise is the nominal one.
        laser_sigma_m=float(sensors["laser"]["sigma_m"]) if "laser" in sensors else dataset.sensors.laser_sigma_m,
        sightings_from_laser=from_laser,
    )


def _positive(name: str, value: float | None, dataset: Dataset) -> float:
    if value is None or not value > 0:
        raise ConfigError(f"dataset {dataset.name!r}: true {name} must be > 0 for a bound, got {value}")
    return float(value)


def _truth_indices(dataset: Dataset, events: list[Any]) -> npt.NDArray[np.intp]:
    """The ground-truth index of each of ``events`` (each must fall on a ground-truth time, within 1 us), in
    one search."""
    gt_t = dataset.ground_truth.t
    ts = np.array([e.t for e in events], dtype=np.float64)
    ks = np.searchsorted(gt_t, ts - 1e-6)
    bad = (ks >= gt_t.shape[0]) | (np.abs(gt_t[np.minimum(ks, gt_t.shape[0] - 1)] - ts) > 1e-6)
    if bad.any():
        t = float(ts[np.argmax(bad)])
        raise ConfigError(f"dataset {dataset.name!r}: a measurement at t={t} s falls on no ground-truth time")
    return ks


def _laser_information(dataset: Dataset, sigma_m: float, gt_poses: FloatArray) -> FloatArray:
    """Laser information at every ground-truth time, shape (n_truth, 3, 3); one cast per beam layout."""
    info = np.zeros((gt_poses.shape[0], 3, 3))
    grid = dataset.world.occupancy
    scans = [e for e in dataset.events if isinstance(e, LaserScan)]
    if grid is None or not scans:
        return info
    groups: dict[tuple[float, ...], list[LaserScan]] = {}
    for e in scans:
        key = (*e.sensor_pose, e.angle_min, e.angle_increment, float(e.ranges.shape[0]), e.range_min, e.range_max)
        groups.setdefault(key, []).append(e)
    for group in groups.values():
        e0 = group[0]
        idx = _truth_indices(dataset, group)
        per_scan = laser_information(
            grid.occupied(),
            grid.resolution,
            (float(grid.origin[0]), float(grid.origin[1])),
            gt_poses[idx],
            e0.sensor_pose,
            e0.angles,
            e0.range_max,
            e0.range_min,
            sigma_m,
            np.stack([e.ranges for e in group]),
        )
        np.add.at(info, idx, per_scan)
    return info


@dataclass(frozen=True)
class _EventInformation:
    """Information of a dataset's non-laser measurements, in event order (:func:`_event_information`).

    Attributes
    ----------
    index : ndarray of int, shape (E,)
        Ground-truth index of each event.
    info : ndarray, shape (E, 3, 3)
        Its information H' R^-1 H about the pose.
    sighting : ndarray of bool, shape (E,)
        The event is a landmark sighting (left out where the scans they were computed from are counted).
    """

    index: npt.NDArray[np.intp]
    info: FloatArray
    sighting: npt.NDArray[np.bool_]


def _event_information(
    dataset: Dataset, noise: TrueNoise, gt_poses: FloatArray, with_sightings: bool = True
) -> _EventInformation:
    """The information of every landmark sighting (unless ``with_sightings`` is False), range observation
    and position fix of ``dataset``, in event order (both rows of the bound add the same terms, so
    :func:`bound_covariances` computes them once)."""
    kinds = LandmarkObservations | RangeObservations | PoseFix if with_sightings else RangeObservations | PoseFix
    events = [e for e in dataset.events if isinstance(e, kinds)]
    ks = _truth_indices(dataset, events)
    mats = np.empty((len(events), 3, 3))
    sighting = np.array([isinstance(e, LandmarkObservations) for e in events], dtype=np.bool_)
    lm_map = dataset.world.landmarks
    by_id: dict[int, int] = {} if lm_map is None else {int(i): r for r, i in enumerate(lm_map.ids.tolist())}
    if sighting.any():
        assert lm_map is not None
        sr = _positive("landmark sigma_range_m", noise.landmark_sigma_range_m, dataset)
        sb = _positive("landmark sigma_bearing_rad", noise.landmark_sigma_bearing_rad, dataset)
        which = np.flatnonzero(sighting)
        seen = [e for e in events if isinstance(e, LandmarkObservations)]
        mats[which] = _sightings_information(seen, gt_poses[ks[which]], lm_map.xy, by_id, sr, sb)
    for n, e in enumerate(events):
        if isinstance(e, PoseFix):
            mats[n] = position_fix_information(_positive("fix sigma_xy_m", noise.fix_sigma_xy_m, dataset))
        elif isinstance(e, RangeObservations):
            assert lm_map is not None
            sr = _positive("range sigma_m", noise.range_sigma_m, dataset)
            mats[n] = range_information(gt_poses[ks[n]], lm_map.xy[[by_id[int(i)] for i in e.ids.tolist()]], sr)
    return _EventInformation(ks, mats, sighting)


def _sightings_information(
    events: list[LandmarkObservations], poses: FloatArray, xy: FloatArray, by_id: dict[int, int], sr: float, sb: float
) -> FloatArray:
    """:func:`range_bearing_information` of each sighting event (from its true pose, ``poses`` (E, 3)), shape
    (E, 3, 3): the events with the same number of rows at once, through the same numpy operations on stacked
    arrays (elementwise, and one syrk per event in matmul's loop), so the same numbers as one call per event."""
    rows = _associate_all(events, poses, xy, by_id, sr, sb)
    counts = np.array([e.ids.size for e in events], dtype=np.intp)
    ends = np.cumsum(counts)
    out = np.empty((len(events), 3, 3))
    for m in np.unique(counts).tolist():
        which = np.flatnonzero(counts == m)
        take = (ends[which] - m)[:, None] + np.arange(m)[None, :]
        d = xy[rows[take]] - poses[which, None, 0:2]
        q = np.maximum(np.einsum("ij,ij->i", d.reshape(-1, 2), d.reshape(-1, 2)), 1e-12).reshape(d.shape[:2])
        r = np.sqrt(q)
        zero = np.zeros_like(r)
        hr = np.stack([-d[..., 0] / r, -d[..., 1] / r, zero], axis=-1)
        hb = np.stack([d[..., 1] / q, -d[..., 0] / q, -np.ones_like(r)], axis=-1)
        out[which] = hr.transpose(0, 2, 1) @ hr / sr**2 + hb.transpose(0, 2, 1) @ hb / sb**2
    return out


def _associate_all(
    events: list[LandmarkObservations], poses: FloatArray, xy: FloatArray, by_id: dict[int, int], sr: float, sb: float
) -> npt.NDArray[np.intp]:
    """The landmark row of every sighting row of ``events`` (concatenated in event order): by id, else
    (identity withheld) the landmark whose true range and bearing from the event's true pose (``poses``
    (E, 3)) is nearest in Mahalanobis distance (known association)."""
    ids = np.concatenate([e.ids for e in events]).astype(np.int64)
    rows = np.array([by_id.get(int(i), -1) for i in ids.tolist()], dtype=np.intp)
    unknown = np.flatnonzero(ids == UNKNOWN_ID)
    if unknown.size:
        of_event = np.repeat(np.arange(len(events)), [e.ids.size for e in events])[unknown]
        r = np.concatenate([e.ranges for e in events])[unknown]
        b = np.concatenate([e.bearings for e in events])[unknown]
        pose = poses[of_event]
        d = xy[None, :, :] - pose[:, None, 0:2]
        r_true = np.hypot(d[..., 0], d[..., 1])
        b_true = wrap_angle(np.arctan2(d[..., 1], d[..., 0]) - pose[:, 2:3])
        m2 = ((r_true - r[:, None]) / sr) ** 2 + (wrap_angle(b_true - b[:, None]) / sb) ** 2
        rows[unknown] = np.argmin(m2, axis=1)
    missing = np.flatnonzero(rows < 0)
    if missing.size:
        raise KeyError(int(ids[missing[0]]))  # an id the map does not have, as the lookup by id raised
    return rows


def _measurement_information(
    dataset: Dataset,
    noise: TrueNoise,
    gt_poses: FloatArray,
    laser: bool = True,
    events: _EventInformation | None = None,
) -> FloatArray:
    """Measurement information at every ground-truth time, shape (n_truth, 3, 3); ``events``: the dataset's
    :func:`_event_information` when computed already."""
    gt_t = dataset.ground_truth.t
    use_laser = laser and noise.laser_sigma_m is not None and any(isinstance(e, LaserScan) for e in dataset.events)
    if use_laser:
        info = _laser_information(dataset, _positive("laser sigma_m", noise.laser_sigma_m, dataset), gt_poses)
    else:
        info = np.zeros((gt_t.shape[0], 3, 3))
    # sightings computed from the scans already counted carry nothing more
    skip = use_laser and noise.sightings_from_laser
    ev = events if events is not None else _event_information(dataset, noise, gt_poses, with_sightings=not skip)
    keep = ~ev.sighting if skip else np.ones(ev.index.shape[0], dtype=np.bool_)
    # added one event after the other, in event order, as info[k] += ... did
    np.add.at(info, ev.index[keep], ev.info[keep])
    return info


def pcrb_covariances(dataset: Dataset, noise: TrueNoise | None = None, laser: bool = True) -> FloatArray:
    """The bound's pose covariance at every ground-truth time of a synthetic ``dataset``, shape (n, 3, 3).

    Units: m^2 in the position block, rad^2 for the heading, world frame. ``noise`` defaults to
    :func:`true_noise`. The odometry steps are the ground-truth steps (one Odometry event per step, as every
    synthetic world simulates it); the prior is the initial error the world realises (:func:`realised_prior`).
    ``laser`` = False leaves the laser scans out (the bound of an estimator that does not use them).
    """
    _refuse_kidnapped(dataset)
    noise = noise or true_noise(dataset)
    return _covariances(dataset, noise, _step_terms(dataset, noise), laser)


def _refuse_kidnapped(dataset: Dataset) -> None:
    if dataset.kidnaps:
        raise ConfigError(f"dataset {dataset.name!r}: a kidnapped run has no bound (the jump is outside the model)")


def _step_terms(dataset: Dataset, noise: TrueNoise) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The true poses (n, 3) and the odometry's Jacobians and process covariances (:func:`odometry_step_terms`)."""
    gt = dataset.ground_truth
    poses = np.column_stack([gt.xy, gt.theta])
    f, q = odometry_step_terms(
        poses, noise.wheelbase_m, noise.k_left, noise.k_right, noise.scale_left, noise.scale_right
    )
    return poses, f, q


def _covariances(
    dataset: Dataset,
    noise: TrueNoise,
    steps: tuple[FloatArray, FloatArray, FloatArray],
    laser: bool,
    events: _EventInformation | None = None,
) -> FloatArray:
    """:func:`pcrb_covariances` from its parts: ``steps`` from :func:`_step_terms`, ``events`` from
    :func:`_event_information` (None: computed here)."""
    poses, f, q = steps
    info = _measurement_information(dataset, noise, poses, laser, events)
    p0 = realised_prior(dataset)
    if not p0.any():
        # the initial error is zero: no measurement at step 0 can lower a zero covariance
        return covariance_recursion(p0, f, q, info[1:])
    return pcrb_recursion(np.linalg.inv(p0) + info[0], f, q, info[1:])


def realised_prior(dataset: Dataset) -> FloatArray:
    """Covariance of the initial error the world realises, (3, 3), m^2 and rad^2.

    A world whose initial belief's mean is the true start (the default synthetic worlds: the robot starts at
    its exact true pose) realises a zero initial error, whatever covariance the belief declares; a world that
    draws the mean from the belief (the model-matched ones) realises the declared covariance.
    """
    gt = dataset.ground_truth
    start = np.array([gt.xy[0, 0], gt.xy[0, 1], gt.theta[0]])
    mean = np.asarray(dataset.initial.mean, dtype=np.float64)
    if np.array_equal(mean[0:2], start[0:2]) and float(wrap_angle(mean[2] - start[2])) == 0.0:
        return np.zeros((3, 3))
    return np.asarray(dataset.initial.cov, dtype=np.float64)


def pcrb_summary(t: FloatArray, cov: FloatArray, waypoint_t: FloatArray) -> dict[str, float]:
    """Scalar metrics of bound covariances ``cov`` (n, 3, 3) at times ``t`` (s).

    Returns ``ate_m`` = sqrt(mean_k trace of the position block) (m), ``heading_rmse_rad`` = sqrt(mean_k
    P_k[2, 2]) (rad) and ``waypoint_<j>_error_m`` (j from 1) = sqrt(position trace) at the truth time nearest
    waypoint j's time (m): the same definitions as the filters' ``ate_m``, ``heading_rmse_rad`` and waypoint
    errors, with the squared error replaced by its lower bound.
    """
    pos = cov[:, 0, 0] + cov[:, 1, 1]
    out = {ATE_M: math.sqrt(float(np.mean(pos))), HEADING_RMSE_RAD: math.sqrt(float(np.mean(cov[:, 2, 2])))}
    for j, tw in enumerate(np.asarray(waypoint_t, dtype=np.float64).tolist()):
        k = int(np.argmin(np.abs(t - tw)))
        out[member_id(WAYPOINT_ERROR_M, j + 1)] = math.sqrt(float(pos[k]))
    return out


def pcrb_metrics(dataset: Dataset, laser: bool = True) -> dict[str, float]:
    """The bound's ``ate_m``, ``heading_rmse_rad`` and ``waypoint_<j>_error_m`` for a built synthetic
    ``dataset`` under its true noise model (see :func:`pcrb_summary`, :func:`pcrb_covariances`)."""
    waypoint_t = dataset.waypoints.t if dataset.waypoints is not None else np.zeros(0)
    return pcrb_summary(dataset.ground_truth.t, pcrb_covariances(dataset, laser=laser), waypoint_t)


# --- the bound as rows of the benchmark ---------------------------------------------------------------------

#: Bump when the bound of the same realisation changes: a stored bound of another version is recomputed.
#: 2: the prior is the initial error the world realises (zero where the robot starts at its true pose).
#: 3: the scan term's range derivative from one traversal per beam (closed form at the hit cell's face).
BOUND_VERSION = 3
#: The row of the bound with every sensor the world provides (the accuracy limit of the issue's protocol).
BOUND_ALL = "pcrb"
#: The row of the bound without the laser scans: the limit of the estimators that use landmarks and fixes only.
BOUND_NO_LASER = "pcrb[laser=false]"
BOUND_ROWS = (BOUND_ALL, BOUND_NO_LASER)


def is_bound_row(name: str) -> bool:
    """True for the names of the bound's rows in the metrics (they are not filters)."""
    return name in BOUND_ROWS


def bound_covariances(dataset: Dataset) -> dict[str, FloatArray]:
    """The bound's covariances at every ground-truth time of a synthetic, unkidnapped ``dataset``, by row name.

    Returns
    -------
    dict of str to ndarray, shape (n, 3, 3)
        :data:`BOUND_ALL` (every sensor) and, when the dataset has laser scans, :data:`BOUND_NO_LASER`
        (m^2 and rad^2, world frame, at ``dataset.ground_truth.t``).
    """
    _refuse_kidnapped(dataset)
    noise = true_noise(dataset)
    steps = _step_terms(dataset, noise)
    # both rows add the same sightings, ranges and fixes (the laser-free one even where they are computed
    # from the scans): computed once
    events = _event_information(dataset, noise, steps[0])
    out = {BOUND_ALL: _covariances(dataset, noise, steps, True, events)}
    if any(isinstance(e, LaserScan) for e in dataset.events):
        out[BOUND_NO_LASER] = _covariances(dataset, noise, steps, False, events)
    return out
