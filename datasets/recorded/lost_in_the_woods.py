"""Barfoot's "Lost in the Woods" dataset (``dataset2.mat``): a wheeled robot among 17 tubes, Vicon ground truth.

Source
------
Dataset of T. D. Barfoot's course AER1513 "State Estimation for Aerospace Vehicles" (University of Toronto,
UTIAS), companion to T. D. Barfoot, "State Estimation for Robotics", Cambridge University Press, 2017. There is
no official download: the file must be in ``$LOCBENCH_DATA/lost_in_the_woods/dataset2.mat`` (SOURCES.md gives
its origin and sha256). The robot drives for about 21 minutes among 17 plastic tubes (point landmarks) and
measures range and bearing to them with a laser rangefinder; Vicon gives its pose.

Format
------
MATLAB v5 file read with :func:`scipy.io.loadmat`; N = 12609 samples at 10 Hz, L = 17 tubes:

=============  ========  =====================================================================================
variable       shape     meaning
=============  ========  =====================================================================================
``t``          N x 1     time, s (0 .. 1260.8, step 0.1)
``v``, ``om``  N x 1     measured forward speed (m/s) and turn rate (rad/s) of the robot
``r``, ``b``   N x L     range (m) and bearing (rad) of tube j measured AT THE LASER; ``r = 0``: not seen
``l``          L x 2     tube positions (x, y), m, world (Vicon) frame
``x_true``,    N x 1     Vicon pose of the robot centre: x, y (m), heading (rad)
``y_true``,
``th_true``
``true_valid`` N x 1     1 where the Vicon pose is valid (97.4 % of the samples), 0 where it is not
``d``          1 x 1     offset of the laser ahead of the robot centre along the robot's x axis, m (0.219)
``v_var``,     1 x 1     variances of the speed (m^2/s^2), turn rate (rad^2/s^2), range (m^2) and bearing
``om_var``,              (rad^2) noise, as given by the dataset
``r_var``,
``b_var``
=============  ========  =====================================================================================

Validation: every variable must be a real float array (``true_valid`` may also be integer or logical, holding 0
or 1) of the shape above with finite values; ``t`` strictly increasing; every number within
:data:`~locbench.datasets.recorded.files.MAX_POSITION_M`; ``d`` in [0, :data:`MAX_RANGE_M`]; variances > 0 and at
most the square of their quantity's bound (speed, turn rate, range; pi rad for the bearing). The robot must move and
turn (the per-metre noise divides by the mean speed and turn rate) and see at least one tube. Flagged by the
plausibility policy (:func:`plausible_masks`; left out and listed in ``Dataset.flagged``, a stream with more than
1 % flagged or a 2 s stretch refused): a twist beyond the policy's speed or turn rate, a valid Vicon pose with a
heading beyond 2 pi or off the reachable track (a flagged pose is dropped as an invalid one is), a sighting with a
range outside [0, :data:`MAX_RANGE_M`] or a bearing beyond 2 pi.

Frames and identities
---------------------
World frame = the Vicon frame of ``l`` and of the true poses; robot frame x forward, y left. Landmark ids are
1..17: id j is row j of ``l`` and column j of ``r``/``b`` (MATLAB's 1-based index). The file's time base is
kept (no shift): event and truth times are the file's ``t``.

How the dataset is derived
--------------------------
* **Odometry.** One :class:`~locbench.core.events.Odometry` per sample k >= 1 at ``t[k]``, carrying the measured
  twist (``v``, ``omega``) held over ``dt = t[k] - t[k-1]`` and its exact constant-twist increment in the frame
  of the pose at ``t[k-1]``, with a = omega dt::

      dx = v dt sin(a) / a,   dy = v dt (1 - cos a) / a,   dtheta = a      (a -> 0: dx = v dt, dy = 0)

  evaluated through sinc (:func:`locbench.core.geometry.twist_increment`) so that it is exact and stable for any a.
  Which sample's twist drives the interval (t[k-1], t[k]] is the parameter ``twist_sample``: ``"previous"``
  (default) holds the sample taken at ``t[k-1]`` forward (causal zero-order hold); ``"current"`` uses the sample
  at ``t[k]``, the convention of the course's motion model x_k = f(x_{k-1}, v_k, om_k). On this file the
  default fits the Vicon motion better: the RMS difference between the Vicon speed (turn rate) over an interval
  and the twist is 0.063 m/s (0.067 rad/s) with ``"previous"`` and 0.065 m/s (0.088 rad/s) with ``"current"``.
* **Landmark observations.** One :class:`~locbench.core.events.LandmarkObservations` per sample with at least one
  tube seen (``r > 0``), ids as above. The laser measures (r, b) from a point d ahead of the robot centre, but
  our observations are from the robot origin; each sighting is therefore converted exactly: the tube lies at
  p = (d + r cos b, r sin b) in the robot frame, so the range and bearing from the centre are R = |p| and
  B = atan2(p_y, p_x) (wrapped to (-pi, pi]). A filter that predicts (R, B) from the centre then uses the
  same geometry as the course's model r = |l - x - d (cos th, sin th)|, b = atan2(...) - th.
* **Ground truth.** The Vicon poses with ``true_valid = 1`` only: an invalid sample is dropped, so an invalid
  stretch is simply not scored (metrics are taken at the ground-truth times). Headings are wrapped.
* **Span.** Events and truth are cut to [first valid truth time, last valid truth time] within the optional
  sub-interval [``t_start_s``, ``t_end_s``]; the first odometry event is the one that leaves the first valid
  truth pose, observations at that instant are kept.
* **Initial belief.** The first valid truth pose of the span, with covariance
  diag(``initial_sigma_xy_m``^2, ``initial_sigma_xy_m``^2, ``initial_sigma_theta_rad``^2).

Nominal noise (:class:`~locbench.datasets.dataset.SensorSpec`)
--------------------------------------------------------------
All of it comes from the dataset's own variances and is computed over the whole file (so it does not change
with the sub-interval):

* ``twist_sigma_v_mps = sqrt(v_var)``, ``twist_sigma_omega_radps = sqrt(om_var)``.
* The increment noise of filters that read (dx, dy, dtheta) per metre and per radian (report 003's
  var_xy = s_xy^2 * dist, var_theta = s_thm^2 * dist + s_thr^2 * |dtheta|) is chosen so that the variance
  accumulated over the whole recording equals the twist model's, N (sigma dt)^2 per component. With the mean
  measured |v| (m/s), |omega| (rad/s) and step dt over the N intervals::

      odometry_sigma_xy_per_m     = sqrt(v_var  * dt / mean|v|)
      odometry_sigma_theta_per_m  = sqrt(om_var * dt / (2 mean|v|))
      odometry_sigma_theta_per_rad = sqrt(om_var * dt / (2 mean|omega|))

  The heading variance is split evenly between distance and rotation so that turning on the spot is not
  noiseless. (Unlike the twist model, the increment model also puts s_xy on the lateral axis.)
* ``landmark_sigma_range_m`` and ``landmark_sigma_bearing_rad``: the dataset's r_var and b_var are at the
  laser; mapped to the centre through the Jacobian J of (R, B) with respect to (r, b)::

      dR/dr = (r + d cos b) / R,   dR/db = -r d sin b / R,
      dB/dr = d sin b / R^2,       dB/db = r (r + d cos b) / R^2,

  each sighting's centre-frame standard deviations are sqrt(diag(J diag(r_var, b_var) J^T)); one scalar per
  component must be given to filters, so the nominal value is their root mean square over every sighting in
  the file (the range and bearing correlation is dropped). The spread (min, max) is in ``metadata``; as d is
  small against r the mapping changes little: on this file the centre range sigma is 0.92-1.02 sqrt(r_var)
  and the bearing sigma 0.73-1.44 sqrt(b_var) (the largest at the closest sightings far off the axis).
* Sensor limits from the data: ``landmark_min_range_m`` / ``landmark_max_range_m`` are the smallest and largest
  centre range R of any sighting, ``landmark_fov_rad`` twice the largest |B| (at the laser the bearings span
  +-2.10 rad and ranges 0.39-5.64 m: a 240 degree, 5.6 m laser).
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Literal

import numpy as np
import numpy.typing as npt

from locbench.core.errors import ConfigError
from locbench.core.events import Event, LandmarkObservations, Odometry
from locbench.core.geometry import twist_increment, wrap_angle
from locbench.core.spec import bound, params_to_dict
from locbench.datasets.dataset import (
    Dataset,
    FlaggedSample,
    Gaussian2,
    Landmarks,
    SensorSpec,
    Trajectory2D,
    WorldMap,
    sort_events,
)
from locbench.datasets.recorded import plausibility
from locbench.datasets.recorded.common import RecordedDataset
from locbench.datasets.recorded.files import (
    MAX_POSITION_M,
    MissingDataFile,
    RecordedDataError,
    RemoteFile,
    check_increasing,
    check_range,
    load_mat,
    mat_numbers,
)

FloatArray = npt.NDArray[np.float64]

#: Path of the file below the data root, and its sha256 (SOURCES.md).
RELPATH = "lost_in_the_woods/dataset2.mat"
SHA256 = "bbaeae95687376f115c9a8bf637097c65ce275f3bc66cc2cd8cd2755608682d9"

CITATION = (
    "T. D. Barfoot, AER1513 'State Estimation for Aerospace Vehicles' dataset2.mat ('Lost in the Woods'), "
    "University of Toronto (UTIAS); companion to T. D. Barfoot, 'State Estimation for Robotics', "
    "Cambridge University Press, 2017"
)

_VECTORS = ("t", "v", "om", "x_true", "y_true", "th_true", "true_valid")
_SCALARS = ("d", "v_var", "om_var", "r_var", "b_var")


#: The span of ``dataset2.mat``'s time base, s (it runs 0 .. 1260.8 s), rounded up: the window's ends lie in it.
TIME_SPAN_S = 1261.0


@dataclass(frozen=True, kw_only=True)
class LostInTheWoodsParams:
    """Parameters of ``lost_in_the_woods``.

    Attributes
    ----------
    t_start_s, t_end_s : float, float or None
        Keep only [t_start_s, t_end_s] of the file's time base, s (None: to the end), both within [0,
        :data:`TIME_SPAN_S`]. Default: everything.
    twist_sample : {"previous", "current"}
        Which sample's (v, om) drives the interval (t[k-1], t[k]]: the one at t[k-1] (causal zero-order hold,
        the better fit to the Vicon motion) or the one at t[k] (the course's motion-model convention).
    initial_sigma_xy_m, initial_sigma_theta_rad : float
        Standard deviations of the initial belief around the first valid Vicon pose, m and rad.
    """

    t_start_s: float = field(default=0.0, metadata=bound(0.0, TIME_SPAN_S, unit="s", what="a time"))
    t_end_s: float | None = field(
        default=None, metadata=bound(0.0, TIME_SPAN_S, optional=True, unit="s", what="a time", none_means="the end")
    )
    twist_sample: Literal["previous", "current"] = "previous"
    initial_sigma_xy_m: float = 0.01
    initial_sigma_theta_rad: float = 0.01

    def __post_init__(self) -> None:
        if not math.isfinite(self.t_start_s):
            raise ConfigError(f"t_start_s must be a finite time in s, got {self.t_start_s}")
        if self.t_end_s is not None and not (math.isfinite(self.t_end_s) and self.t_end_s > self.t_start_s):
            raise ConfigError(f"t_end_s must be a finite time > t_start_s = {self.t_start_s} s, got {self.t_end_s}")
        for name in ("initial_sigma_xy_m", "initial_sigma_theta_rad"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ConfigError(f"{name} must be > 0, got {value}")


# --- reading and checking the MAT file ---------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class LostInTheWoodsData:
    """The checked arrays of ``dataset2.mat`` (read-only), N samples and L landmarks; names as in the file."""

    path: Path
    header: str
    t: FloatArray
    v: FloatArray
    om: FloatArray
    r: FloatArray
    b: FloatArray
    l: FloatArray  # noqa: E741 (the file's name)
    x_true: FloatArray
    y_true: FloatArray
    th_true: FloatArray
    true_valid: npt.NDArray[np.bool_]
    d: float
    v_var: float
    om_var: float
    r_var: float
    b_var: float


#: Bounds of the validation (generous: the robot drives below 0.6 m/s among tubes a few metres away). The speed and
#: turn rate are looser than the plausibility policy's, whose 5 m/s and 10 rad/s apply (:data:`BOUNDS`).
MAX_SPEED_MPS = 10.0
MAX_TURN_RATE_RADPS = 50.0
MAX_RANGE_M = 100.0
#: The plausibility bounds of this loader: the policy's, ranges tightened to :data:`MAX_RANGE_M` and headings and
#: bearings to 2 pi.
BOUNDS = plausibility.BOUNDS.tightened(range_m=MAX_RANGE_M, heading_abs_rad=2 * math.pi)
#: The variances and the largest standard deviation each may have: the bound of its own quantity (a speed sigma of
#: at most MAX_SPEED_MPS ...; the file's are 0.066 m/s, 0.090 rad/s, 0.030 m and 0.026 rad).
_VARIANCES = (
    ("v_var", "speed variance in m^2/s^2", MAX_SPEED_MPS),
    ("om_var", "turn-rate variance in rad^2/s^2", MAX_TURN_RATE_RADPS),
    ("r_var", "range variance in m^2", MAX_RANGE_M),
    ("b_var", "bearing variance in rad^2", math.pi),
)


def _vector(
    path: Path, mat: dict[str, Any], name: str, n: int | None, what: str, *, kinds: str = "f", bound: float = math.inf
) -> FloatArray:
    expected = f"{what}, an N x 1 column" + (f" with N = {n}" if n is not None else "")
    arr = mat_numbers(path, mat, name, expected, kinds=kinds)
    check_range(path, f"variable {name!r}", arr, -bound, bound)
    if arr.ndim != 2 or 1 not in arr.shape or (n is not None and arr.size != n):
        raise RecordedDataError(path, f"variable {name!r}: shape {arr.shape}, expected {expected}")
    return arr.ravel()


def _scalar(path: Path, mat: dict[str, Any], name: str, what: str, positive: bool) -> float:
    arr = mat_numbers(path, mat, name, f"{what}, a 1 x 1 number")
    if arr.size != 1:
        raise RecordedDataError(path, f"variable {name!r}: shape {arr.shape}, expected {what}, a 1 x 1 number")
    value = float(arr.ravel()[0])
    if (positive and value <= 0.0) or value < 0.0:
        bound = "> 0" if positive else ">= 0"
        raise RecordedDataError(path, f"variable {name!r}: {value!r}, expected {what} {bound}")
    return value


def _readonly(a: npt.NDArray[Any]) -> npt.NDArray[Any]:
    a.setflags(write=False)
    return a


def read_lost_in_the_woods(path: str | os.PathLike[str]) -> LostInTheWoodsData:
    """Read and check ``dataset2.mat``; parsed once per (path, size, mtime) in a process.

    Raises
    ------
    RecordedDataError
        Naming the file and the variable: a missing file, a file that is not a MATLAB file, a missing
        variable, a wrong shape, a non-numeric or non-finite value, time going backwards, a validity flag other
        than 0/1, a negative range or a non-positive variance.
    """
    p = Path(path)
    try:
        st = p.stat()
    except FileNotFoundError:
        raise MissingDataFile(p, "missing file (expected Barfoot's Lost in the Woods dataset2.mat)") from None
    return _read_cached(str(p.resolve()), st.st_size, st.st_mtime_ns)


@functools.lru_cache(maxsize=4)
def _read_cached(path_str: str, size: int, mtime_ns: int) -> LostInTheWoodsData:
    path = Path(path_str)
    mat = load_mat(path)
    header = mat.get("__header__", b"")
    header_text = header.decode("latin-1") if isinstance(header, bytes) else str(header)

    t = _vector(path, mat, "t", None, "time in s")
    n = t.size
    if n < 2:
        raise RecordedDataError(path, f"variable 't': {n} sample(s), expected at least 2")
    check_increasing(path, "variable 't'", t, strict=True)
    # speeds, turn rates, headings, ranges and bearings beyond their physical bounds are flagged (plausible_masks);
    # beyond MAX_POSITION_M a number is no measurement at all and refused
    v = _vector(path, mat, "v", n, "speed in m/s", bound=MAX_POSITION_M)
    om = _vector(path, mat, "om", n, "turn rate in rad/s", bound=MAX_POSITION_M)
    x_true = _vector(path, mat, "x_true", n, "true x in m", bound=MAX_POSITION_M)
    y_true = _vector(path, mat, "y_true", n, "true y in m", bound=MAX_POSITION_M)
    th_true = _vector(path, mat, "th_true", n, "true heading in rad", bound=MAX_POSITION_M)
    valid = _vector(path, mat, "true_valid", n, "validity flag 0/1", kinds="fiub")
    for name, arr, what in (("v", v, "speed"), ("om", om, "turn rate")):
        if not np.any(arr[:-1] != 0.0):
            raise RecordedDataError(
                path, f"variable {name!r}: every {what} is 0, expected a robot that moves (the noise is per metre)"
            )
    if not np.all((valid == 0.0) | (valid == 1.0)):
        k = int(np.flatnonzero((valid != 0.0) & (valid != 1.0))[0])
        raise RecordedDataError(path, f"variable 'true_valid': {float(valid[k])!r} at sample {k + 1}, expected 0 or 1")

    lm = mat_numbers(path, mat, "l", "landmark positions, an L x 2 array (x, y) in m")
    if lm.ndim != 2 or lm.shape[1] != 2 or lm.shape[0] < 1:
        raise RecordedDataError(path, f"variable 'l': shape {lm.shape}, expected an L x 2 array (x, y) in m")
    check_range(path, "variable 'l'", lm, -MAX_POSITION_M, MAX_POSITION_M)
    n_lm = lm.shape[0]
    meas: dict[str, FloatArray] = {}
    for name, what in (("r", "ranges in m"), ("b", "bearings in rad")):
        arr = mat_numbers(path, mat, name, f"{what}, an N x L array")
        if arr.shape != (n, n_lm):
            raise RecordedDataError(
                path, f"variable {name!r}: shape {arr.shape}, expected {what}, N x L = {n} x {n_lm} (t by l)"
            )
        meas[name] = arr
    check_range(path, "variable 'r' (range in m, 0 = not seen)", meas["r"], -MAX_POSITION_M, MAX_POSITION_M)
    check_range(path, "variable 'b' (bearing in rad)", meas["b"], -MAX_POSITION_M, MAX_POSITION_M)
    if not np.any(meas["r"] > 0.0):
        raise RecordedDataError(path, "variable 'r': no sighting (every range is 0), expected at least one")
    d = _scalar(path, mat, "d", "laser offset in m", positive=False)
    check_range(path, "variable 'd' (laser offset in m)", d, 0.0, MAX_RANGE_M)
    variances = {name: _scalar(path, mat, name, what, positive=True) for name, what, _ in _VARIANCES}
    for name, what, sigma_max in _VARIANCES:
        # a standard deviation beyond the quantity's own bound would make the filters ignore the sensor
        check_range(path, f"variable {name!r} ({what})", variances[name], 0.0, sigma_max**2)
    return LostInTheWoodsData(
        path=path,
        header=header_text,
        t=_readonly(t),
        v=_readonly(v),
        om=_readonly(om),
        r=_readonly(meas["r"]),
        b=_readonly(meas["b"]),
        l=_readonly(lm),
        x_true=_readonly(x_true),
        y_true=_readonly(y_true),
        th_true=_readonly(th_true),
        true_valid=_readonly(valid == 1.0),
        d=d,
        **variances,
    )


def plausible_masks(
    data: LostInTheWoodsData,
) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.bool_], npt.NDArray[np.bool_], tuple[FlaggedSample, ...]]:
    """The plausibility policy on the whole file (:data:`BOUNDS`): which samples' twist (N,), truth (N,) and
    sightings (N x L) are kept, and the flagged ones.

    A twist beyond the speed or turn-rate bound, a valid Vicon pose whose heading exceeds 2 pi or that the robot
    could not have reached from the last accepted one, and a sighting whose range lies outside [0,
    :data:`MAX_RANGE_M`] (0: not seen) or whose bearing exceeds 2 pi are flagged; a stream with more than 1 % of its
    samples flagged, or a 2 s stretch, is refused.
    """
    path, t, b = data.path, data.t, BOUNDS
    twist = plausibility.Flags(path, "twist (variable 'v' and 'om')", t)
    twist.flag_outside(data.v, "speed, m/s", -b.speed_mps, b.speed_mps)
    twist.flag_outside(data.om, "turn rate, rad/s", -b.turn_rate_radps, b.turn_rate_radps)
    valid = np.flatnonzero(data.true_valid)
    truth = plausibility.Flags(path, "truth (variable 'x_true', 'y_true', 'th_true')", t[valid])
    truth.flag_outside(data.th_true[valid], "heading, rad", -b.heading_abs_rad, b.heading_abs_rad)
    truth.flag_track(np.column_stack([data.x_true[valid], data.y_true[valid]]), data.th_true[valid], b)
    row, col = np.nonzero(data.r != 0.0)  # 0 = not seen
    sight = plausibility.Flags(path, "sighting (variable 'r' and 'b')", t[row])
    sight.flag_outside(data.r[row, col], "range, m", 0.0, b.range_m)
    sight.flag_outside(data.b[row, col], "bearing, rad", -b.heading_abs_rad, b.heading_abs_rad)
    flagged = plausibility.merge(twist.finish(), truth.finish(), sight.finish())
    truth_ok = np.ones(t.shape[0], dtype=bool)
    truth_ok[valid[truth.mask]] = False
    sight_ok = np.ones(data.r.shape, dtype=bool)
    sight_ok[row[sight.mask], col[sight.mask]] = False
    return twist.kept, truth_ok, sight_ok, flagged


# --- the geometry ----------------------------------------------------------------------------------------


def laser_to_centre(r: npt.ArrayLike, b: npt.ArrayLike, d: float) -> tuple[FloatArray, FloatArray]:
    """Range (m) and bearing (rad, wrapped) from the robot centre of a point seen at (r, b) from a laser d m ahead."""
    r_, b_ = np.asarray(r, dtype=np.float64), np.asarray(b, dtype=np.float64)
    px = d + r_ * np.cos(b_)
    py = r_ * np.sin(b_)
    return np.hypot(px, py), wrap_angle(np.arctan2(py, px))


def centre_sigmas(
    r: npt.ArrayLike, b: npt.ArrayLike, d: float, r_var: float, b_var: float
) -> tuple[FloatArray, FloatArray]:
    """Standard deviations of the centre range (m) and bearing (rad) of sightings (r, b) at the laser.

    First-order propagation of diag(r_var, b_var) through the Jacobian of :func:`laser_to_centre` (see the
    module docstring); the correlation between the two is not returned.
    """
    r_, b_ = np.asarray(r, dtype=np.float64), np.asarray(b, dtype=np.float64)
    big_r2 = r_ * r_ + d * d + 2.0 * r_ * d * np.cos(b_)
    big_r = np.sqrt(big_r2)
    along = r_ + d * np.cos(b_)
    dr_dr, dr_db = along / big_r, -r_ * d * np.sin(b_) / big_r
    db_dr, db_db = d * np.sin(b_) / big_r2, r_ * along / big_r2
    var_range = dr_dr**2 * r_var + dr_db**2 * b_var
    var_bearing = db_dr**2 * r_var + db_db**2 * b_var
    return np.sqrt(var_range), np.sqrt(var_bearing)


def nominal_sensors(data: LostInTheWoodsData) -> tuple[SensorSpec, dict[str, float]]:
    """The nominal noise and sensor limits of the whole file (module docstring) and the statistics behind them."""
    dt = np.diff(data.t)
    mean_dt = float(np.mean(dt))
    mean_speed = float(np.mean(np.abs(data.v[:-1])))
    mean_turn = float(np.mean(np.abs(data.om[:-1])))
    seen = data.r > 0.0
    r_seen = data.r[seen]
    b_seen = data.b[seen]
    big_r, big_b = laser_to_centre(r_seen, b_seen, data.d)
    s_range, s_bearing = centre_sigmas(r_seen, b_seen, data.d, data.r_var, data.b_var)
    sensors = SensorSpec(
        twist_sigma_v_mps=math.sqrt(data.v_var),
        twist_sigma_omega_radps=math.sqrt(data.om_var),
        odometry_sigma_xy_per_m=math.sqrt(data.v_var * mean_dt / mean_speed),
        odometry_sigma_theta_per_m=math.sqrt(data.om_var * mean_dt / (2.0 * mean_speed)),
        odometry_sigma_theta_per_rad=math.sqrt(data.om_var * mean_dt / (2.0 * mean_turn)),
        landmark_sigma_range_m=float(np.sqrt(np.mean(s_range**2))),
        landmark_sigma_bearing_rad=float(np.sqrt(np.mean(s_bearing**2))),
        landmark_min_range_m=float(big_r.min()),
        landmark_max_range_m=float(big_r.max()),
        landmark_fov_rad=float(2.0 * np.abs(big_b).max()),
    )
    stats = {
        "mean_dt_s": mean_dt,
        "mean_abs_v_mps": mean_speed,
        "mean_abs_omega_radps": mean_turn,
        "sightings": int(r_seen.size),
        "laser_sigma_range_m": math.sqrt(data.r_var),
        "laser_sigma_bearing_rad": math.sqrt(data.b_var),
        "centre_sigma_range_min_m": float(s_range.min()),
        "centre_sigma_range_max_m": float(s_range.max()),
        "centre_sigma_bearing_min_rad": float(s_bearing.min()),
        "centre_sigma_bearing_max_rad": float(s_bearing.max()),
        "laser_range_min_m": float(r_seen.min()),
        "laser_range_max_m": float(r_seen.max()),
        "laser_bearing_abs_max_rad": float(np.abs(b_seen).max()),
    }
    return sensors, stats


# --- the dataset -----------------------------------------------------------------------------------------


def load_lost_in_the_woods(
    path: str | os.PathLike[str], params: LostInTheWoodsParams | None = None, *, dataset_id: str = "lost_in_the_woods"
) -> Dataset:
    """The Lost in the Woods dataset from a local ``dataset2.mat`` (no checksum check here; the builder does one).

    Parameters
    ----------
    path : path-like
        The MAT file.
    params : LostInTheWoodsParams or None
        Sub-interval, twist convention and initial belief; None: the defaults (the whole recording).
    dataset_id : str
        The id recorded in the dataset.

    Raises
    ------
    RecordedDataError
        Malformed file (see :func:`read_lost_in_the_woods`).
    ConfigError
        The sub-interval holds fewer than two valid ground-truth samples.
    """
    # long: the loader's steps over one .mat file's arrays in order, with their refusals; numpydoc
    p = params if params is not None else LostInTheWoodsParams()
    data = read_lost_in_the_woods(path)
    t = data.t
    twist_ok, truth_ok, sight_ok, flagged = plausible_masks(data)
    t_end = math.inf if p.t_end_s is None else p.t_end_s
    keep = data.true_valid & truth_ok & (t >= p.t_start_s) & (t <= t_end)
    idx = np.flatnonzero(keep)
    if idx.size < 2:
        raise ConfigError(
            f"{data.path}: t_start_s={p.t_start_s}, t_end_s={p.t_end_s}: {idx.size} valid ground-truth sample(s) "
            f"in that interval, expected at least 2 (the file spans {t[0]} .. {t[-1]} s)"
        )
    first, last = int(idx[0]), int(idx[-1])

    # Odometry: intervals (t[k-1], t[k]] for k in first+1 .. last, over the samples whose twist is not flagged (a
    # flagged twist's interval joins its neighbour's).
    kept = np.r_[first, np.flatnonzero(twist_ok[first + 1 : last + 1]) + first + 1]
    ks, before = kept[1:], kept[:-1]
    src = before if p.twist_sample == "previous" else ks
    dt = t[ks] - t[before]
    v, om = data.v[src], data.om[src]
    dx, dy, dth = twist_increment(v, om, dt)
    events: list[Event] = [
        Odometry(t=tk, dx=a, dy=b_, dtheta=c, v=vk, omega=wk, dt=h)
        for tk, a, b_, c, vk, wk, h in zip(
            t[ks].tolist(), dx.tolist(), dy.tolist(), dth.tolist(), v.tolist(), om.tolist(), dt.tolist(), strict=True
        )
    ]

    # Landmark sightings, converted from the laser to the robot centre.
    r_span, b_span = data.r[first : last + 1], data.b[first : last + 1]
    big_r, big_b = laser_to_centre(r_span, b_span, data.d)
    seen = (r_span > 0.0) & sight_ok[first : last + 1]
    lm_ids = np.arange(1, data.l.shape[0] + 1, dtype=np.int64)
    for row in np.flatnonzero(seen.any(axis=1)).tolist():
        cols = np.flatnonzero(seen[row])
        events.append(
            LandmarkObservations(
                t=float(t[first + row]),
                ids=lm_ids[cols].copy(),
                ranges=big_r[row, cols].copy(),
                bearings=big_b[row, cols].copy(),
            )
        )

    truth = Trajectory2D(
        t=t[idx].copy(),
        xy=np.column_stack([data.x_true[idx], data.y_true[idx]]),
        theta=wrap_angle(data.th_true[idx]),
    )
    initial = Gaussian2(
        mean=truth.poses[0].copy(),
        cov=np.diag([p.initial_sigma_xy_m**2, p.initial_sigma_xy_m**2, p.initial_sigma_theta_rad**2]),
    )
    sensors, stats = nominal_sensors(data)
    world = WorldMap(landmarks=Landmarks(ids=lm_ids, xy=np.array(data.l, dtype=np.float64)))
    in_span = slice(first, last + 1)
    metadata: dict[str, Any] = {
        "source": CITATION,
        "file": str(data.path),
        "sha256": SHA256,
        "mat_header": data.header,
        "time_base": "the file's t, s (not shifted)",
        "laser_offset_m": data.d,
        "variances": {"v_var": data.v_var, "om_var": data.om_var, "r_var": data.r_var, "b_var": data.b_var},
        "landmark_ids": "1..L = row of l / column of r and b (MATLAB index)",
        "twist_sample": p.twist_sample,
        "span_s": [float(t[first]), float(t[last])],
        "truth_samples_in_span": int(last - first + 1),
        "truth_samples_invalid_dropped": int(np.count_nonzero(~data.true_valid[in_span])),
        "truth_samples_flagged": int(np.count_nonzero(data.true_valid[in_span] & ~truth_ok[in_span])),
        "noise_mapping": stats,
    }
    return Dataset(
        id=dataset_id,
        params=params_to_dict(p),
        events=sort_events(events),
        ground_truth=truth,
        initial=initial,
        world=world,
        sensors=sensors,
        name=dataset_id,
        metadata=metadata,
        truth_label="ground truth",
        sources=(str(data.path),),
        declared=frozenset({LandmarkObservations}),
        flagged=flagged,
    )


class LostInTheWoods(RecordedDataset):
    """Builder of ``lost_in_the_woods``: ``$LOCBENCH_DATA/lost_in_the_woods/dataset2.mat``, checksum verified."""

    id: ClassVar[str] = "lost_in_the_woods"
    Params: ClassVar[type] = LostInTheWoodsParams
    version: ClassVar[int] = 1
    description: ClassVar[str] = (
        "Barfoot's Lost in the Woods (recorded): v/omega at 10 Hz, range-bearing to 17 tubes, Vicon truth"
    )
    folder: ClassVar[str] = "lost_in_the_woods"
    reference_kind: ClassVar[str] = "motion capture"

    @classmethod
    def files(cls, params: Any) -> list[RemoteFile]:
        """The one MAT file; it has no official download."""
        return [RemoteFile(RELPATH, sha256=SHA256, url=None)]

    def build(self, params: LostInTheWoodsParams, rng: np.random.Generator) -> Dataset:
        """The recording (``rng`` is unused: recorded data does not depend on the seed)."""
        path = self.paths(params)[RELPATH]
        return load_lost_in_the_woods(path, params)
