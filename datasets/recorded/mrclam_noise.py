"""MRCLAM's nominal noise, derived per fold from Dataset 6's Vicon truth and surveyed map (not run at load time).

The dataset publishes no noise figures. The noise a run of robot r is given is what :func:`derive_nominal_noise`
gives on the tuning robots of leave-one-robot-out fold r (:func:`locbench.datasets.splits.mrclam_fold`: the other
four robots of Dataset 6, pooled), so no robot's own data enters the noise it is run with; the five results are
frozen in :data:`locbench.datasets.recorded.mrclam.FOLD_NOISE`. ``tests/datasets/recorded/test_recorded_mrclam.py``
reruns the derivation on the shared files and checks the frozen values within 10 %, and
``tools/derive/derive_mrclam_noise.py`` prints every fold for a folder. The values were not chosen by looking at any
filter's error. The procedure (robust std s(e) = 1.4826 median |e|, taken about zero so that a bias counts as noise,
since the filters model none):

1. **Camera.** For every landmark sighting inside the truth span: the truth pose interpolated at its time
   (linear, heading unwrapped), the predicted range and bearing to the surveyed landmark, the residuals
   e_r and e_b (wrapped). sigma_range = s(e_r), sigma_bearing = s(e_b).
2. **Twist.** The truth span is cut into consecutive windows of T = :data:`NOISE_WINDOW_S` = 1 s (windows that
   overlap a Vicon or odometry gap longer than 0.2 s are skipped). In each window, the Vicon displacement
   (expressed in the frame of the Vicon pose at the window's start: forward e_f, lateral) and heading change
   are compared with the exact integration of the commanded twist (in its own start frame). If the twist had
   white noise sigma per sample, the accumulated error over the window would have variance
   sigma^2 sum(dt_k^2) = sigma^2 T dt_eff, with dt_eff = sum(dt^2)/sum(dt) over the sample intervals of at most
   0.2 s (those of the windows kept); hence
   sigma_v = s(e_f) / sqrt(T dt_eff) and sigma_omega = s(e_theta) / sqrt(T dt_eff). The real error is
   correlated in time, so this is the white noise that gives the right spread over 1 s (about the time between
   landmark sightings), not a per-sample truth.
3. **Per-metre fallback** (``odometry_sigma_*``, for filters that model increment noise per distance): from the
   same windows, with D the commanded distance and A the commanded turn in a window:
   sigma_xy_per_m = sqrt((s(e_f/sqrt D)^2 + s(e_lat/sqrt D)^2) / 2) and sigma_theta_per_m = s(e_theta/sqrt D) over
   windows with D >= 3 cm and A < 0.05 rad (driving straight); sigma_theta_per_rad = s(e_theta/sqrt A) over windows
   with D < 1 cm and A >= 0.05 rad (turning in place).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from locbench.core.geometry import twist_increment, wrap_angle
from locbench.datasets.dataset import Trajectory2D
from locbench.datasets.recorded.files import Table
from locbench.datasets.recorded.mrclam import (
    file_names,
    interpolate_pose,
    read_barcodes,
    read_groundtruth,
    read_landmarks,
    read_measurements,
    read_odometry,
    split_sightings,
)
from locbench.datasets.splits import Split, mrclam_fold

FloatArray = npt.NDArray[np.float64]

#: Window length of the twist comparison, s.
NOISE_WINDOW_S = 1.0
#: Windows that overlap a gap longer than this in the Vicon or odometry stream are skipped, s.
NOISE_MAX_GAP_S = 0.2
#: Per-metre fallback: windows with at least this commanded distance count as "moving", m.
NOISE_MIN_TRAVEL_M = 0.03
#: ... and less than this commanded turn as "straight", rad.
NOISE_STRAIGHT_MAX_TURN_RAD = 0.05
#: Turning in place: less than this distance, m, and at least NOISE_STRAIGHT_MAX_TURN_RAD of turn.
NOISE_IN_PLACE_MAX_TRAVEL_M = 0.01


def robust_std(e: npt.ArrayLike) -> float:
    """1.4826 median |e|: the standard deviation of a zero-mean Gaussian, robust to outliers (a bias counts)."""
    a = np.abs(np.asarray(e, dtype=np.float64))
    return float(1.4826 * np.median(a)) if a.size else math.nan


def _gap_free(a: FloatArray, b: FloatArray, t: FloatArray, max_gap: float) -> npt.NDArray[np.bool_]:
    """Which windows [a, b] overlap no gap longer than ``max_gap`` between samples ``t``."""
    ok = np.ones(a.shape[0], dtype=bool)
    gaps = np.flatnonzero(np.diff(t) > max_gap)
    for g in gaps.tolist():
        ok &= ~((a < t[g + 1]) & (b > t[g]))
    return ok


@dataclass(frozen=True)
class _Windows:
    e_forward: FloatArray
    e_lateral: FloatArray
    e_theta: FloatArray
    travel: FloatArray
    turn: FloatArray


def _twist_windows(truth: Trajectory2D, odo: Table, window_s: float) -> tuple[_Windows, float, float]:
    """Window errors of the integrated twist against Vicon; also sum(dt^2) and sum(dt) of the samples."""
    t, v, om = odo.rows[:, 0], odo.rows[:, 1], odo.rows[:, 2]
    dt = np.diff(t)
    dx, dy, dth = twist_increment(v[:-1], om[:-1], dt)
    th = np.r_[0.0, np.cumsum(dth)]
    c, s = np.cos(th[:-1]), np.sin(th[:-1])
    X = np.r_[0.0, np.cumsum(c * dx - s * dy)]
    Y = np.r_[0.0, np.cumsum(s * dx + c * dy)]
    D = np.r_[0.0, np.cumsum(np.abs(v[:-1] * dt))]
    A = np.r_[0.0, np.cumsum(np.abs(dth))]
    lo, hi = max(t[0], truth.t[0]), min(t[-1], truth.t[-1])
    a = np.arange(lo, hi - window_s, window_s)
    b = a + window_s
    ok = _gap_free(a, b, truth.t, NOISE_MAX_GAP_S) & _gap_free(a, b, t, NOISE_MAX_GAP_S)
    a, b = a[ok], b[ok]

    def odo_at(q: FloatArray) -> tuple[FloatArray, ...]:
        return tuple(np.interp(q, t, arr) for arr in (X, Y, th, D, A))

    ox0, oy0, ot0, od0, oa0 = odo_at(a)
    ox1, oy1, ot1, od1, oa1 = odo_at(b)
    gth = np.unwrap(truth.theta)
    gx0, gy0, gt0 = (np.interp(a, truth.t, arr) for arr in (truth.xy[:, 0], truth.xy[:, 1], gth))
    gx1, gy1, gt1 = (np.interp(b, truth.t, arr) for arr in (truth.xy[:, 0], truth.xy[:, 1], gth))

    def local(
        x0: FloatArray, y0: FloatArray, h0: FloatArray, x1: FloatArray, y1: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        ch, sh = np.cos(h0), np.sin(h0)
        return ch * (x1 - x0) + sh * (y1 - y0), -sh * (x1 - x0) + ch * (y1 - y0)

    ofx, ofy = local(ox0, oy0, ot0, ox1, oy1)
    gfx, gfy = local(gx0, gy0, gt0, gx1, gy1)
    w = _Windows(gfx - ofx, gfy - ofy, (gt1 - gt0) - (ot1 - ot0), od1 - od0, oa1 - oa0)
    inner = dt[dt <= NOISE_MAX_GAP_S]  # the steps of the windows kept (those across a gap are skipped)
    return w, float(np.sum(inner * inner)), float(np.sum(inner))


def _robot_residuals(
    folder: Path, robot: int, window_s: float
) -> tuple[FloatArray, FloatArray, _Windows, float, float]:
    """One robot's camera residuals (range m, bearing rad), twist windows, sum(dt^2) and sum(dt) (module docstring)."""
    paths = {key: folder / name for key, name in file_names(robot).items()}
    barcodes = read_barcodes(paths["barcodes"])
    world = read_landmarks(paths["landmarks"])
    truth = read_groundtruth(paths["groundtruth"])
    lms, _, _ = split_sightings(read_measurements(paths["measurement"]), barcodes)
    lms = lms.select((lms.t >= truth.t[0]) & (lms.t <= truth.t[-1]) & np.isin(lms.subject, world.ids))
    pose = interpolate_pose(truth, lms.t)
    index = world.index_of()
    L = world.xy[[index[int(i)] for i in lms.subject.tolist()]].reshape(-1, 2)
    d = L - pose[:, :2]
    e_r = lms.ranges - np.hypot(d[:, 0], d[:, 1])
    e_b = wrap_angle(lms.bearings - (np.arctan2(d[:, 1], d[:, 0]) - pose[:, 2]))
    w, s2, s1 = _twist_windows(truth, read_odometry(paths["odometry"]), window_s)
    return e_r, e_b, w, s2, s1


def derive_nominal_noise(
    folder: str | os.PathLike[str], split: Split, window_s: float = NOISE_WINDOW_S
) -> dict[str, float]:
    """Recompute the nominal noise from the Vicon truth and the surveyed map (the procedure of the module docstring).

    Parameters
    ----------
    folder : path-like
        An MRCLAM dataset folder (the constants were frozen from Dataset 6).
    split : Split
        Whose tuning robots to pool (a fold of :func:`~locbench.datasets.splits.mrclam_fold`); its test robots are
        never read.
    window_s : float
        Window length of the twist comparison, s.

    Returns
    -------
    dict
        ``twist_sigma_v_mps``, ``twist_sigma_omega_radps``, ``odometry_sigma_xy_per_m``,
        ``odometry_sigma_theta_per_m``, ``odometry_sigma_theta_per_rad``, ``landmark_sigma_range_m``,
        ``landmark_sigma_bearing_rad``, plus diagnostics: the medians (biases) ``range_median_m``,
        ``bearing_median_rad``, the counts ``n_sightings``, ``n_windows``, ``n_straight``, ``n_in_place`` and
        ``dt_eff_s``.
    """
    er: list[FloatArray] = []
    eb: list[FloatArray] = []
    wins: list[_Windows] = []
    sum_dt2 = sum_dt = 0.0
    for robot in split.check_tuning(split.tuning):
        r, b, w, s2, s1 = _robot_residuals(Path(folder), int(robot), window_s)
        er.append(r)
        eb.append(b)
        wins.append(w)
        sum_dt2 += s2
        sum_dt += s1
    e_r, e_b = np.concatenate(er), np.concatenate(eb)
    W = _Windows(
        *(
            np.concatenate([getattr(w, f) for w in wins])
            for f in ("e_forward", "e_lateral", "e_theta", "travel", "turn")
        )
    )
    dt_eff = sum_dt2 / sum_dt
    scale = math.sqrt(window_s * dt_eff)
    straight = (W.travel >= NOISE_MIN_TRAVEL_M) & (W.turn < NOISE_STRAIGHT_MAX_TURN_RAD)
    moving = W.travel >= NOISE_MIN_TRAVEL_M
    in_place = (W.travel < NOISE_IN_PLACE_MAX_TRAVEL_M) & (W.turn >= NOISE_STRAIGHT_MAX_TURN_RAD)
    root_d = np.sqrt(W.travel[moving])
    sxy = math.sqrt(
        0.5 * (robust_std(W.e_forward[moving] / root_d) ** 2 + robust_std(W.e_lateral[moving] / root_d) ** 2)
    )
    return {
        "twist_sigma_v_mps": robust_std(W.e_forward) / scale,
        "twist_sigma_omega_radps": robust_std(W.e_theta) / scale,
        "odometry_sigma_xy_per_m": sxy,
        "odometry_sigma_theta_per_m": robust_std(W.e_theta[straight] / np.sqrt(W.travel[straight])),
        "odometry_sigma_theta_per_rad": robust_std(W.e_theta[in_place] / np.sqrt(W.turn[in_place])),
        "landmark_sigma_range_m": robust_std(e_r),
        "landmark_sigma_bearing_rad": robust_std(e_b),
        "range_median_m": float(np.median(e_r)),
        "bearing_median_rad": float(np.median(e_b)),
        "n_sightings": float(e_r.shape[0]),
        "n_windows": float(W.travel.shape[0]),
        "n_straight": float(np.count_nonzero(straight)),
        "n_in_place": float(np.count_nonzero(in_place)),
        "dt_eff_s": dt_eff,
    }


def derive_fold_noise(
    folder: str | os.PathLike[str], held_out: int, window_s: float = NOISE_WINDOW_S
) -> dict[str, float]:
    """:func:`derive_nominal_noise` on the tuning robots of leave-one-robot-out fold ``held_out`` (the noise a run of
    robot ``held_out`` is given); the same outputs."""
    return derive_nominal_noise(folder, mrclam_fold(held_out), window_s)
