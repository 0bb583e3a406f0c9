"""Monte Carlo localization: the particle filter of report 003 (sec. 4.2), with augmented MCL.

Report 003 runs a particle filter beside its EKF "with the same encoder model and landmark measurements"
and "linear time resampling [8]" (Carpenter, Clifford & Fearnhead 1999). The standard algorithms it
refers to are those of Dellaert, Fox, Burgard & Thrun (1999) and of Thrun, Burgard & Fox, *Probabilistic
Robotics* (2005, below "PR"): MCL (PR table 8.2), augmented MCL (PR table 8.3) and the likelihood-field
laser model (PR table 6.3).

Belief
    N weighted particles (x m, y m, theta rad) in the world frame, weights kept as normalised logs.
    ``init="belief"`` draws them from the dataset's initial Gaussian; ``init="uniform"`` ignores its mean
    and spreads them uniformly over the free cells of the occupancy grid (global localization), or over
    the bounding box of the landmarks when there is no grid, with headings uniform in (-pi, pi].

Prediction (report 003 eq. 1-2, 5, 10, 8)
    Each particle draws its own wheel travel delta_l ~ N(d_l, sigma_L^2), delta_r ~ N(d_r, sigma_R^2) with
    the eq. 10 variances (read per step by default, as the EKF does; see :mod:`locbench.filters._motion`)
    and moves by eq. 5; then the additive system noise Q = diag(sigma_x^2, sigma_y^2, sigma_theta^2) of
    eq. 8 is added, as in the EKF ("the same encoder model"). An event without wheel travel uses the
    (dx, dy, dtheta) increment model instead. Noise constants come from the dataset's nominal
    :class:`~locbench.datasets.dataset.SensorSpec` unless overridden.

Correction
    * Landmarks (report 003 eq. 7, 9): each sighting (range, bearing) is a Gaussian in range and wrapped
      bearing with R = diag(sigma_range^2, sigma_bearing^2); sightings of one event are independent, so
      their log-likelihoods add. A sighting whose identity is withheld (``UNKNOWN_ID``) is scored by the
      *marginal* over map landmarks with a uniform prior, p(z | x) = (1/M) sum_j p(z | x, c = j) (a
      log-sum-exp), not by the maximum: it is the exact likelihood under an unknown correspondence, it
      never throws away a second plausible landmark, and its values stay comparable between particles.
      Identities not in the map are ignored.
    * Beacon ranges (:class:`~locbench.core.events.RangeObservations`, range-only radios such as the CMU Plaza
      data): the same structure as the landmark model with the range term only, made robust to the gross
      outliers of ranging radios by a mixture with a uniform floor (the z_hit / z_rand form of PR table 6.3):

          p(r | x) = (1 - eps) N(r; |B - p|, sigma^2) + eps / r_span,

      eps = ``range_outlier_fraction`` (0.05, the z_rand of the laser model) and r_span =
      ``range_outlier_span_m`` (100 m: the order of a ranging radio's reach; the floor is a density over
      [0, r_span]). Without the floor a single 20 m outlier at sigma 0.3 m would weigh every particle by
      e^-2000 relative to its neighbours and collapse the cloud on the particles nearest the wrong circle.
      A range whose id is withheld is marginalised over the beacons as for landmarks; ids not in the map
      are ignored.
    * Laser (optional): the likelihood field of :mod:`locbench.filters._likelihood_field` on a subset of
      ``laser_beams`` beams, evenly spaced over the scan (as ROS AMCL's ``laser_max_beams``), max-range
      readings skipped. Its defaults (z_hit 0.95, z_rand 0.05, sigma_hit 0.2 m, max distance 2 m) are
      those of ROS AMCL, since PR gives the model but no values.

Resampling
    Systematic ("low-variance", linear-time) resampling, PR table 4.4 and report 003's ref. [8]: one
    uniform offset u ~ U[0, 1/N) and the points u + k/N located in the cumulative weights in one merge pass;
    done when the effective sample size 1 / sum w_i^2 falls below ``resample_ess_fraction * N`` (Liu &
    Chen's criterion) rather than at every step. Roughening (Gordon et al.) follows every resampling, with
    the spread of the predicted particles (``roughening_k``; the heading's measured about the heading of the
    heaviest particle), so that a weighting in which one particle takes nearly all the weight does not leave
    N copies of it and a zero covariance. ``regularise=true`` replaces it by post-regularised resampling
    (Musso, Oudjane & Le Gland 2001).

KLD sampling (``adaptive="kld"``; Fox, "Adapting the sample size in particle filters through
KLD-sampling", IJRR 2003)
    The particle count adapts at every correction: after the weighting, particles are drawn one at a time in
    proportion to their weights (multinomial, as in ROS AMCL's resampling), each falls in a bin of a
    (x, y, theta) histogram, and drawing stops once the count n reaches

        n = (k - 1) / (2 eps) * (1 - 2 / (9 (k - 1)) + sqrt(2 / (9 (k - 1))) z)^3       (Fox 2003, eq. 13)

    for the k bins occupied so far, kept within [min_particles, max_particles] (the filter starts at the
    maximum). The parameters are ROS AMCL's defaults: eps = kld_err = 0.01, z = kld_z = 0.99 (AMCL, and
    this filter, use the value as the quantile itself), 100 and 5000 particles, bins of 0.5 m x 0.5 m x
    10 deg. Where AMCL keeps the maximum for a single occupied bin (k = 1), Fox's bound gives 0 and the
    count falls to the minimum. The count after every event is the diagnostic ``particles`` (stored with
    the run as ``diag_particles``).

Compiled kernels
    Prediction, weighting, resampling, roughening and the estimate each run as one numba loop over the
    particles that draws its noise from the run's ``numpy.random.Generator`` (numba shares the generator's
    state), so a run stays reproducible from its seed. The headings' sines and cosines are taken through
    the angle sum about one particle's heading with a series for the small difference
    (:func:`~locbench.filters._motion_kernels.sincos_near`), libm's only for particles far from it.

Augmented MCL (PR table 8.3)
    Short- and long-term averages of the measurement likelihood, w_fast and w_slow, updated with
    alpha_fast >> alpha_slow; with probability max(0, 1 - w_fast / w_slow) a particle is replaced by a
    random pose in free space. Choices made here, all documented in the config:

    * w_avg is, by default (``recovery_likelihood="best"``), the product over the sightings of each
      one's likelihood at the particle that explains it best, not PR's predictive likelihood
      sum_i w_i p(z | x_i) (``"mean"``), which falls whenever the cloud has spread between sparse sightings
      and so injected without a kidnap; either is taken to the power 1/m for an observation of m sightings
      or beams (a geometric mean per measurement). Without it a 60-beam scan's likelihood underflows and
      scans or events with different numbers of sightings would not be comparable.
    * Landmarks and laser keep separate (w_slow, w_fast) pairs: their densities have different units.
    * Both averages start at the first w_avg (PR starts them at 0, which leaves the ratio undefined).
    * Injection happens at the start of an update, as a resampling from the mixture (1 - p) belief +
      p injected, so the injected particles are weighted by that observation before the estimate is read
      (in PR they enter unweighted and would drag the weighted mean until the next observation). w_avg is
      then taken over the kept (belief) particles only: taken over the mixture it fed the injected share
      back into w_fast and ran away to replacing every particle at every update.
    * The injected poses are uniform over free space (PR) or, with ``inject="sensor"``, drawn from the
      observation's likelihood (sensor-resetting localization, Lenser & Veloso 2000; see the config).
    * alpha_slow = 0.001 and alpha_fast = 0.1, the values ROS AMCL's documentation suggests (PR only
      requires 0 <= alpha_slow << alpha_fast).

Estimate
    Weighted mean of x and y, circular weighted mean of the heading, and the weighted covariance with the
    heading residuals wrapped (symmetric PSD by construction). Diagnostics: ``n_eff`` (effective sample
    size after the last weighting), ``resampled`` (0/1), ``injected`` (particles injected), ``particles``
    (the particle count), ``p_inject`` and ``w_fast_over_w_slow`` of the sensor of the last update, and
    ``pair_chi2`` (with ``inject_pairs``, at a sighting that forms a pair: the best belief particle's squared
    Mahalanobis residual of it, which ``pair_gate`` compares with its chi-square quantile; NaN otherwise).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import numpy as np
import numpy.typing as npt
from numba import njit, types
from numba.typed import Dict

from locbench.core.errors import ConfigError, FilterDiverged, ResourceLimit
from locbench.core.events import UNKNOWN_ID, LandmarkObservations, LaserScan, Observation, Odometry, RangeObservations
from locbench.core.geometry import wrap_angle
from locbench.core.limits import (
    FREE_SPACE_BYTES_PER_CELL,
    LIKELIHOOD_FIELD_BYTES_PER_CELL,
    PARTICLE_BYTES,
    check_beams,
    check_bytes,
    grid_cells,
)
from locbench.core.runkey import RUN_KEY_OMIT_IF_DEFAULT
from locbench.core.tunable import tunable
from locbench.datasets.dataset import Gaussian2, MapKind, OccupancyGrid, SensorSpec, WorldMap
from locbench.filters._likelihood_field import (
    LikelihoodField,
    log_likelihood,
    make_likelihood_field,
    scan_endpoints_robot_frame,
)
from locbench.filters._motion import MotionKind, MotionNoiseConfig, increment_variances, wheel_variances
from locbench.filters._motion_kernels import increment_step, move_twist, sincos_near, wheel_step, wrap
from locbench.filters._noise import landmark_noise, process_noise, range_only_noise
from locbench.filters._numba_rng import UIntArray, generator_addresses, generator_from
from locbench.filters.base import (
    NON_NEGATIVE,
    NON_NEGATIVE_OR_NONE,
    POSITIVE,
    POSITIVE_OR_DATASET,
    CheckTolerances,
    Estimate,
    Filter,
    FilterConfig,
    FilterDoc,
    bound,
)

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
logger = logging.getLogger(__name__)


_LOG_2PI = math.log(2.0 * math.pi)


@dataclass(frozen=True, kw_only=True)
class ParticleFilterConfig(FilterConfig, MotionNoiseConfig):
    """Configuration of :class:`ParticleFilter`.

    Attributes
    ----------
    particles : int
        Number of particles N. 1000 by default: Dellaert et al. (report 003's ref. [5]) track with
        ~1000 samples; it keeps a 20-seed room and office sweep within seconds per run.
    resample_ess_fraction : float
        Resample when the effective sample size falls below this fraction of N (0.5, Liu & Chen); 1
        resamples after every observation as PR's table 8.2 does.
    augmented : bool
        Augmented MCL (PR table 8.3): random particles when the short-term likelihood drops below the
        long-term one (kidnap recovery, global localization). Off by default: report 003's PF only resamples
        (sec. 4.2), ROS AMCL ships with it off (alphas 0), and on ``room`` it costs accuracy: after a stretch
        without landmarks the odometry's systematic heading error (which the nominal noise does not model)
        lowers w_fast, and an injected particle that fits a single sighting wins (measured: 4 of 20 room runs
        jump by 0.3-1.5 m with it on, none with it off). Switch it on for kidnap suites: ``pf[augmented=true]``.
    alpha_slow, alpha_fast : float
        Decay rates of w_slow and w_fast (0 <= alpha_slow < alpha_fast <= 1); ROS AMCL's suggested 0.001, 0.1.
    roughening_k : float
        Roughening after each resampling (Gordon, Salmond & Smith 1993, sec. 4.1): every particle is jittered by
        a zero-mean Gaussian whose standard deviation in each of the d = 3 dimensions is K E N^(-1/d); K = 0.2
        is their value, 0 switches it off. E is the spread (max - min) in that dimension of the predicted
        particles that enter the correction (injected ones left out), not of the resampled set as in Gordon
        et al.: when one particle takes nearly all the weight the resampled set is N copies of it, its spread
        is 0, and roughening would leave a zero covariance (an infinite NEES; docs/pf_consistency_kidnap.md).
    regularise : bool
        Post-regularised resampling (Musso, Oudjane & Le Gland 2001) instead of roughening: after each
        resampling every particle moves by h L e, e ~ N(0, I), L L^T the weighted covariance of the particles
        before resampling and h = (4 / ((d + 2) N))^(1 / (d + 4)) the optimal bandwidth of a Gaussian kernel.
        Off by default: report 003 names neither; kept as the documented alternative.
    inject : {"uniform", "sensor"}
        Where augmented MCL's injected particles come from. ``"uniform"``: uniform poses over free space (PR
        table 8.3), injected before the weighting. ``"sensor"``: sensor-resetting localization (Lenser &
        Veloso 2000): poses drawn from the current observation's likelihood, injected after its weighting
        (weighted by it again they would count it twice). Candidates are drawn from each sighting's
        (range, bearing), perturbed by its noise and inverted through the landmark's position at a uniform
        direction around it (a range alone: heading uniform), 20 per injected pose, and the event's
        likelihood chooses among them. Only an event of two or more sightings (three ranges) is inverted: one
        sighting allows a circle of poses that go on seeing it alike; the other events (and scans) inject
        uniform poses as ``"uniform"`` does.
    inject_pairs : bool
        With ``inject="sensor"``: a single sighting is inverted together with the previous landmark event
        when that event saw another landmark: candidates from the previous event's sightings of the other
        landmarks (not of this one, whose poses all explain this sighting), moved by the odometry composed
        since, chosen by this sighting's likelihood. For worlds that see one landmark
        at a time (``room``); the odometry between the two events makes these poses less precise than
        those of one event of two sightings (docs/pf_consistency_kidnap.md); see ``pair_gate``.
    pair_gate : float
        With ``inject_pairs``: when > 0, a sighting is inverted with the previous event only when no belief
        particle explains it, i.e. when even the best particle's squared Mahalanobis residual (range,
        bearing; 2 degrees of freedom) exceeds the chi-square quantile of this probability (0.99: 9.21), the
        usual validation gate; the event then injects as a single sighting does (uniform poses). Off (0) by
        default: a pair pose carries the odometry's error between the two events (2-12 cm on ``office``),
        but the uniform poses injected instead when the gate closes occasionally win, and the gate measured
        no better (docs/pf_consistency_kidnap.md).
    recovery_likelihood : {"best", "mean"}
        The w_avg that w_slow and w_fast average, per sighting or beam (geometric mean). ``"mean"``: PR's
        predictive likelihood sum_i w_i p(z | x_i); it falls whenever the cloud has spread (a gap between
        sightings, the odometry's unmodelled systematic error), so with sparse sightings w_fast sits below
        w_slow and particles are injected without a kidnap. ``"best"`` (default): for each sighting the
        likelihood at the particle that explains it best (for a scan, the best particle's), which stays
        high while any particle explains the observation and falls when none does (a kidnap).
    adaptive : {"none", "kld"}
        ``"kld"``: KLD sampling (Fox 2003, module docstring): every correction resamples and the particle
        count adapts between ``min_particles`` and ``max_particles`` (``particles`` and
        ``resample_ess_fraction`` are then unused; the filter starts with ``max_particles``, as ROS AMCL
        does).
    kld_err, kld_z : float
        Fox's epsilon (the bound on the KL divergence between the sample-based and the true posterior) and
        the upper standard normal quantile z_(1-delta); ROS AMCL's defaults 0.01 and 0.99 (AMCL passes its
        ``kld_z`` to the bound as the quantile itself).
    min_particles, max_particles : int
        Bounds of the adaptive count; ROS AMCL's defaults 100 and 5000.
    kld_bin_xy_m, kld_bin_theta_deg : float
        Histogram bin size of KLD sampling, m and deg; ROS AMCL's 0.5 m x 0.5 m x 10 deg.
    init : {"belief", "uniform"}
        ``"belief"``: particles from the dataset's initial Gaussian; ``"uniform"``: global localization from a
        uniform prior over free space (the free grid cells, else the landmarks' bounding box).
    use_landmarks : bool
        Weight with landmark sightings (report 003's PF). Ignored, with a log line, on a world without landmarks.
    use_ranges : bool
        Weight with range-only beacon measurements (to ``world.landmarks``). Ignored on a world without landmarks.
    range_only_sigma_m : float or None
        Standard deviation of a beacon range, m; None takes ``SensorSpec.range_sigma_m``.
    range_outlier_fraction : float
        Weight eps of the uniform outlier floor in the range likelihood (module docstring), in [0, 1).
    range_outlier_span_m : float
        Width of the interval over which the outlier floor is uniform, m (its density is 1 / span).
    use_laser : bool
        Weight with the laser likelihood field on the occupancy grid. Off by default because report 003's PF
        has no laser; on a dataset with a grid but no landmarks set it to true.
    laser_beams : int
        Beams used per scan, evenly spaced over the scan (ROS AMCL's laser_max_beams is 30; 60 here).
    z_hit, z_rand : float
        Mixture weights of the likelihood field (PR table 6.3); ROS AMCL's defaults 0.95 and 0.05.
    sigma_hit_m : float
        Standard deviation of the hit Gaussian, m; ROS AMCL's default 0.2 (it absorbs the map's
        discretisation and the beams' correlation, which a 1 cm sensor sigma would ignore).
    laser_max_dist_m : float
        Distance to the nearest obstacle at which the likelihood field is clipped, m (AMCL default 2.0).
    sigma_x_m, sigma_y_m, sigma_theta_rad : float or None
        Additive system noise per odometry step (report 003 eq. 8), world frame; None takes the dataset's
        value, else the EKF's defaults (:func:`locbench.filters._noise.process_noise`), so that both filters
        have "the same encoder model". It also keeps duplicated particles apart while the robot stands still.
    input_noise : {"per_step", "cumulative"}
        Reading of report 003 eq. 10 (see :mod:`locbench.filters._motion`).
    motion_model : {"auto", "encoder", "increment"}
        As in ``ekf_landmarks``: the encoder model when the event has wheel travel and the dataset gives the
        wheelbase and encoder constants (``"auto"``), always when it can (``"encoder"``), or never.
    sigma_range_m, sigma_bearing_rad : float or None
        Landmark measurement noise R (report 003 eq. 9); None takes the dataset's nominal value.
    wheelbase_m, encoder_k_left, encoder_k_right : float or None
        Overrides of W (m) and k_L, k_R (sqrt(m)); None takes the dataset's value.
    odometry_sigma_xy_per_m, odometry_sigma_theta_per_m, odometry_sigma_theta_per_rad : float or None
        Overrides of the increment-model noise (m/sqrt(m), rad/sqrt(m), rad/sqrt(rad)).
    twist_sigma_v_mps, twist_sigma_omega_radps : float or None
        Overrides of the white noise of a measured twist (m/s, rad/s); see :mod:`locbench.filters._motion`.
    """

    particles: int = field(default=1000, metadata=bound(2, what="an integer"))
    resample_ess_fraction: float = field(default=0.5, metadata=bound(0.0, 1.0))
    augmented: bool = False
    alpha_slow: float = 0.001
    alpha_fast: float = 0.1
    roughening_k: float = field(default=0.2, metadata=tunable(0.0, 1.0, base=NON_NEGATIVE))
    regularise: bool = field(default=False, metadata=RUN_KEY_OMIT_IF_DEFAULT)
    inject: Literal["uniform", "sensor"] = field(default="uniform", metadata=RUN_KEY_OMIT_IF_DEFAULT)
    inject_pairs: bool = field(default=False, metadata=RUN_KEY_OMIT_IF_DEFAULT)
    pair_gate: float = field(default=0.0, metadata=bound(0.0, 1.0, high_open=True, base=RUN_KEY_OMIT_IF_DEFAULT))
    recovery_likelihood: Literal["best", "mean"] = field(default="best", metadata=RUN_KEY_OMIT_IF_DEFAULT)
    adaptive: Literal["none", "kld"] = field(default="none", metadata=RUN_KEY_OMIT_IF_DEFAULT)
    kld_err: float = field(default=0.01, metadata=RUN_KEY_OMIT_IF_DEFAULT)
    kld_z: float = field(default=0.99, metadata=RUN_KEY_OMIT_IF_DEFAULT)
    min_particles: int = field(default=100, metadata=RUN_KEY_OMIT_IF_DEFAULT)
    max_particles: int = field(default=5000, metadata=RUN_KEY_OMIT_IF_DEFAULT)
    kld_bin_xy_m: float = field(default=0.5, metadata=POSITIVE | RUN_KEY_OMIT_IF_DEFAULT)
    kld_bin_theta_deg: float = field(default=10.0, metadata=POSITIVE | RUN_KEY_OMIT_IF_DEFAULT)
    init: Literal["belief", "uniform"] = "belief"
    use_landmarks: bool = True
    use_ranges: bool = field(default=True, metadata=RUN_KEY_OMIT_IF_DEFAULT)
    range_only_sigma_m: float | None = field(default=None, metadata=POSITIVE_OR_DATASET | RUN_KEY_OMIT_IF_DEFAULT)
    range_outlier_fraction: float = field(
        default=0.05, metadata=bound(0.0, 1.0, high_open=True, base=RUN_KEY_OMIT_IF_DEFAULT)
    )
    range_outlier_span_m: float = field(
        default=100.0, metadata=bound(0.0, low_open=True, unit="m", base=RUN_KEY_OMIT_IF_DEFAULT)
    )
    use_laser: bool = False
    laser_beams: int = field(default=60, metadata=bound(1))
    z_hit: float = 0.95
    z_rand: float = 0.05
    sigma_hit_m: float = field(default=0.2, metadata=bound(0.0, low_open=True, unit="m"))
    laser_max_dist_m: float = field(default=2.0, metadata=bound(0.0, low_open=True, unit="m"))
    sigma_x_m: float | None = field(default=None, metadata=NON_NEGATIVE_OR_NONE)
    sigma_y_m: float | None = field(default=None, metadata=NON_NEGATIVE_OR_NONE)
    sigma_theta_rad: float | None = field(default=None, metadata=NON_NEGATIVE_OR_NONE)
    motion_model: MotionKind = "auto"
    sigma_range_m: float | None = field(default=None, metadata=tunable(1e-3, 1.0, log=True, base=POSITIVE_OR_DATASET))
    sigma_bearing_rad: float | None = field(
        default=None, metadata=tunable(1e-3, 0.5, log=True, base=POSITIVE_OR_DATASET)
    )

    def __post_init__(self) -> None:
        super().__post_init__()  # the bounds declared on the fields; the rules across fields follow
        if self.adaptive not in ("none", "kld"):
            raise ConfigError(f"adaptive must be 'none' or 'kld', got {self.adaptive!r}")
        if not 2 <= self.min_particles <= self.max_particles:
            raise ConfigError(
                "need 2 <= min_particles <= max_particles, "
                f"got min_particles={self.min_particles}, max_particles={self.max_particles}"
            )
        if not (self.kld_err > 0.0 and math.isfinite(self.kld_z)):
            raise ConfigError(f"kld_err must be > 0 and kld_z finite, got {self.kld_err}, {self.kld_z}")
        if not 0.0 <= self.alpha_slow < self.alpha_fast <= 1.0:
            raise ConfigError(
                "need 0 <= alpha_slow < alpha_fast <= 1, "
                f"got alpha_slow={self.alpha_slow}, alpha_fast={self.alpha_fast}"
            )
        if self.recovery_likelihood not in ("best", "mean"):
            raise ConfigError(f"recovery_likelihood must be 'best' or 'mean', got {self.recovery_likelihood!r}")
        if self.inject not in ("uniform", "sensor"):
            raise ConfigError(f"inject must be 'uniform' or 'sensor', got {self.inject!r}")
        check_beams("laser_beams", self.laser_beams)
        # the particle set is decided by the config alone: refused here, when the spec is parsed
        size, name = (self.max_particles, "max_particles") if self.adaptive == "kld" else (self.particles, "particles")
        check_bytes("", f"a set of {name}={size}", float(size) * PARTICLE_BYTES, f"lower {name!r}")
        if not (self.z_hit >= 0.0 and self.z_rand >= 0.0 and self.z_hit + self.z_rand > 0.0):
            raise ConfigError(f"z_hit and z_rand must be >= 0 and not both 0, got {self.z_hit}, {self.z_rand}")
        if not (self.use_landmarks or self.use_laser or self.use_ranges):
            raise ConfigError(
                "use_landmarks, use_ranges and use_laser are all false: the particle filter needs one of them"
            )


# --- compiled kernels --------------------------------------------------------------------------------------


@njit(cache=True)
def _sightings_loglik(
    poses: FloatArray,
    ranges: FloatArray,
    bearings: FloatArray,
    rows: IntArray,
    lm_xy: FloatArray,
    with_bearing: bool,
    inv_var_r: float,
    inv_var_b: float,
    log_a: float,
    log_floor: float,
) -> FloatArray:
    """Log-likelihood (N,) of the sightings of every particle, summed over sightings; rows < 0 are marginalised
    over the map (log of the mean likelihood over its landmarks).

    With ``with_bearing`` a sighting is a range and a bearing: log N(range) + log N(wrapped bearing), ``log_a``
    the log of the normalising constant (``log_floor`` unused). Otherwise a range only (``bearings`` unused):
    log((1 - eps) N(r; |B - p|, sigma^2) + eps / span), ``log_a`` = log(1 - eps) - log(sigma sqrt(2 pi)) and
    ``log_floor`` = log(eps / span) (-inf when eps = 0).
    """
    n = poses.shape[0]
    m = ranges.shape[0]
    nl = lm_xy.shape[0]
    log_nl = math.log(nl)
    out = np.zeros(n)
    tmp = np.empty(nl)
    for p in range(n):
        x = poses[p, 0]
        y = poses[p, 1]
        th = poses[p, 2]
        acc = 0.0
        for k in range(m):
            row = rows[k]
            lo = row if row >= 0 else 0
            hi = row + 1 if row >= 0 else nl
            best = -math.inf
            for j in range(lo, hi):
                dx = lm_xy[j, 0] - x
                dy = lm_xy[j, 1] - y
                vr = ranges[k] - math.sqrt(dx * dx + dy * dy)
                if with_bearing:
                    vb = wrap(bearings[k] - math.atan2(dy, dx) + th)
                    ll = log_a - 0.5 * (vr * vr * inv_var_r + vb * vb * inv_var_b)
                else:
                    a = log_a - 0.5 * vr * vr * inv_var_r
                    # log(e^a + e^floor) without overflow
                    ll = max(a, log_floor) + math.log1p(math.exp(-abs(a - log_floor))) if log_floor > -math.inf else a
                tmp[j] = ll
                if ll > best:
                    best = ll
            if row >= 0:
                acc += best
            else:
                s = 0.0
                for j in range(nl):
                    s += math.exp(tmp[j] - best)
                acc += best + math.log(s) - log_nl
        out[p] = acc
    return out


@njit(cache=True)
def _move(
    x: FloatArray,
    wheels: bool,
    u0: float,
    u1: float,
    u2: float,
    s0: float,
    s1: float,
    wheelbase: float,
    q_std: FloatArray,
    gen: UIntArray,
    w: FloatArray,
    logw: FloatArray,
) -> tuple[FloatArray, FloatArray, bool]:
    """Draw every particle's successor in place, add the world-frame noise N(0, diag(q_std^2)) (eq. 8), and
    return the moved cloud's :func:`_weighted_stats` under the weights ``w`` and whether every particle and
    log-weight is finite (the statistics' first pass runs in the same loop as the motion).

    ``wheels``: the encoder model, (u0, u1) = (d_left, d_right) m with standard deviations (s0, s1) =
    (sd_left, sd_right): per particle delta_l ~ N(d_left, sd_left^2), delta_r ~ N(d_right, sd_right^2) moved
    along the chord at the midpoint heading (report 003 eq. 1-2, 5). Otherwise the increment model, (u0, u1,
    u2) = (dx, dy, dtheta) in the previous robot frame with (s0, s1) = (sd_xy, sd_theta): pose (+) (u + e),
    e ~ N(0, diag(sd_xy^2, sd_xy^2, sd_theta^2)). ``gen``: the run's generator (:mod:`._numba_rng`).
    """
    rng = generator_from(gen)
    q0, q1, q2 = q_std[0], q_std[1], q_std[2]
    ref = x[0, 2]
    sr, cr = math.sin(ref), math.cos(ref)
    # the estimate's first pass (weighted sums about the moved first particle's heading) in the same loop
    mx = 0.0
    my = 0.0
    sc = 0.0
    ss = 0.0
    ref1 = 0.0
    sr1 = 0.0
    cr1 = 1.0
    finite = True
    for i in range(x.shape[0]):
        if wheels:
            dl = u0 + s0 * rng.standard_normal()
            dr = u1 + s1 * rng.standard_normal()
            mx_i, my_i, turn = wheel_step(x[i, 2], dl, dr, wheelbase, ref, sr, cr)
        else:
            ix = u0 + s0 * rng.standard_normal()
            iy = u1 + s0 * rng.standard_normal()
            turn = u2 + s1 * rng.standard_normal()
            mx_i, my_i = increment_step(x[i, 2], ix, iy, ref, sr, cr)
        x[i, 0] += mx_i + q0 * rng.standard_normal()
        x[i, 1] += my_i + q1 * rng.standard_normal()
        x[i, 2] = wrap(x[i, 2] + turn + q2 * rng.standard_normal())
        if i == 0:
            ref1 = x[0, 2]
            sr1, cr1 = math.sin(ref1), math.cos(ref1)
        mx, my, sc, ss = _add_weighted(mx, my, sc, ss, w[i], x[i, 0], x[i, 1], x[i, 2], ref1, sr1, cr1)
        finite = finite and math.isfinite(x[i, 0]) and math.isfinite(x[i, 1]) and math.isfinite(x[i, 2])
    mean, cov = _finish_stats(x, w, mx, my, sc, ss)
    return mean, cov, finite and _all_finite(logw)


@njit(cache=True)
def _move_twist(
    x: FloatArray,
    s0: float,
    a0: float,
    sd_s: float,
    sd_a: float,
    dx: float,
    dy: float,
    dtheta: float,
    q_std: FloatArray,
    gen: UIntArray,
    w: FloatArray,
    logw: FloatArray,
) -> tuple[FloatArray, FloatArray, bool]:
    """The twist model's prediction (:mod:`locbench.filters._motion`) of every particle in place, then the
    additive noise of report 003 eq. 8, then :func:`_checked_stats`.

    Each particle draws an arc length s ~ N(s0, sd_s^2) and a turn a ~ N(a0, sd_a^2) (every particle's arc length
    first, then every turn) and moves by :func:`~locbench.filters._motion_kernels.move_twist` (the event's
    increment plus the noise of the arc). Then N(0, diag(q_std^2)) by :func:`_jitter` when any q_std is non-zero.

    Parameters
    ----------
    x : ndarray, shape (N, 3)
        Particles (x m, y m, theta rad), world frame; moved in place.
    s0, a0 : float
        v dt (m) and omega dt (rad) of the event.
    sd_s, sd_a : float
        sigma_v dt (m) and sigma_omega dt (rad).
    dx, dy, dtheta : float
        The event's increment, previous robot frame (m, m, rad).
    q_std : ndarray, shape (3,)
        Standard deviations of the additive noise (m, m, rad).
    gen : ndarray of uint64
        The run's generator (:mod:`._numba_rng`).
    w, logw : ndarray, shape (N,)
        The weights and log-weights, for the statistics.
    """
    rng = generator_from(gen)
    n = x.shape[0]
    noise = np.empty((2, n))
    for r in range(2):
        for i in range(n):
            noise[r, i] = rng.standard_normal()
    move_twist(x, noise, s0, a0, sd_s, sd_a, dx, dy, dtheta)
    if q_std[0] != 0.0 or q_std[1] != 0.0 or q_std[2] != 0.0:
        _jitter(x, q_std, gen)
    return _checked_stats(x, w, logw)


@njit(cache=True)
def _jitter(x: FloatArray, sd: FloatArray, gen: UIntArray) -> None:
    """Add N(0, diag(sd^2)) to every particle in place and wrap the heading (``gen``: :mod:`._numba_rng`)."""
    rng = generator_from(gen)
    s0, s1, s2 = sd[0], sd[1], sd[2]
    for i in range(x.shape[0]):
        x[i, 0] += s0 * rng.standard_normal()
        x[i, 1] += s1 * rng.standard_normal()
        x[i, 2] = wrap(x[i, 2] + s2 * rng.standard_normal())


@njit(cache=True)
def _reweigh(logw: FloatArray, ll: FloatArray, w: FloatArray) -> tuple[float, float]:
    """Bayes' rule on normalised log-weights in place: logw <- logw + ll - log_pred; ``w`` <- exp(logw).

    Returns log_pred = log sum_i w_i p(z | x_i) (the predictive likelihood; -inf or NaN when no particle
    explains z, the weights then left unnormalised) and the effective sample size 1 / sum w_i^2.
    """
    n = logw.shape[0]
    top = -math.inf
    for i in range(n):
        logw[i] += ll[i]
        if logw[i] > top:
            top = logw[i]
    if not math.isfinite(top):
        return top, math.nan
    acc = 0.0
    for i in range(n):
        e = math.exp(logw[i] - top)
        w[i] = e
        acc += e
    log_pred = top + math.log(acc)
    sq = 0.0
    for i in range(n):
        logw[i] -= log_pred
        wi = w[i] / acc
        w[i] = wi
        sq += wi * wi
    return log_pred, 1.0 / sq


@njit(cache=True)
def _weigh_sightings(
    poses: FloatArray,
    ranges: FloatArray,
    bearings: FloatArray,
    rows: IntArray,
    lm_xy: FloatArray,
    with_bearing: bool,
    inv_var_r: float,
    inv_var_b: float,
    log_a: float,
    log_floor: float,
    logw: FloatArray,
    w: FloatArray,
) -> tuple[FloatArray, float, float]:
    """:func:`_sightings_loglik` then :func:`_reweigh` in one call: (log-likelihoods, log_pred, ESS)."""
    ll = _sightings_loglik(poses, ranges, bearings, rows, lm_xy, with_bearing, inv_var_r, inv_var_b, log_a, log_floor)
    log_pred, n_eff = _reweigh(logw, ll, w)
    return ll, log_pred, n_eff


@njit(cache=True)
def _systematic_indices(w: FloatArray, n: int, u: float) -> IntArray:
    """Systematic resampling: for the points (u + k) / n, k = 0..n-1, the index of the first cumulative
    weight (normalised here) above each point (PR table 4.4), O(N + n)."""
    total = 0.0
    for i in range(w.shape[0]):
        total += w[i]
    step = total / n  # the points scaled by the total instead of the weights by 1 / total
    out = np.empty(n, dtype=np.int64)
    last = w.shape[0] - 1
    j = 0
    cum = w[0]
    for k in range(n):
        point = (u + k) * step
        while cum <= point and j < last:
            j += 1
            cum += w[j]
        out[k] = j
    return out


@njit(cache=True)
def _gather(x: FloatArray, idx: IntArray) -> FloatArray:
    """The rows ``idx`` of the particles (a copy)."""
    out = np.empty((idx.shape[0], 3))
    for k in range(idx.shape[0]):
        j = idx[k]
        out[k, 0] = x[j, 0]
        out[k, 1] = x[j, 1]
        out[k, 2] = x[j, 2]
    return out


@njit(cache=True)
def _systematic_draw(x: FloatArray, w: FloatArray, n: int, u: float) -> FloatArray:
    """The particles of :func:`_systematic_indices` (offset ``u``) gathered in one compiled call: the belief
    sample is drawn at every ground-truth time, where two calls and the index array cost more than the draw."""
    return _gather(x, _systematic_indices(w, n, u))


@njit(cache=True)
def _kld_bound(k: int, err: float, z: float) -> float:
    """Fox (2003) eq. 13: the samples needed so that, with probability 1 - delta (z its upper standard normal
    quantile), the KL divergence between the sample-based and the true posterior over k occupied bins stays
    below ``err`` (the Wilson-Hilferty approximation of the chi-square quantile); 0 for k <= 1."""
    if k <= 1:
        return 0.0
    b = 2.0 / (9.0 * (k - 1))
    c = 1.0 - b + math.sqrt(b) * z
    return (k - 1) / (2.0 * err) * c * c * c


@njit(cache=True)
def _kld_resample(
    x: FloatArray,
    w: FloatArray,
    gen: UIntArray,
    err: float,
    z: float,
    n_min: int,
    n_max: int,
    bin_xy: float,
    bin_theta: float,
) -> FloatArray:
    """KLD sampling (Fox 2003, table 1, the resampling step as ROS AMCL does it): draw particles one at a time
    in proportion to ``w``, count the occupied (x, y, theta) bins k as they come, and stop once the count
    reaches the bound of :func:`_kld_bound` for k, kept within [n_min, n_max]. Returns the new set."""
    rng = generator_from(gen)
    n = x.shape[0]
    cdf = np.empty(n)
    acc = 0.0
    for i in range(n):
        acc += w[i]
        cdf[i] = acc
    out = np.empty((n_max, 3))
    seen = Dict.empty(key_type=types.int64, value_type=types.int64)
    bins = 0
    need = float(n_min)
    count = 0
    offset = 1 << 20  # bin indices from -2^20 to 2^20 - 1 pack into 21 bits each
    while count < n_max:
        j = min(np.searchsorted(cdf, rng.random() * acc, side="right"), n - 1)
        out[count, 0] = x[j, 0]
        out[count, 1] = x[j, 1]
        out[count, 2] = x[j, 2]
        count += 1
        key = (
            ((math.floor(x[j, 0] / bin_xy) + offset) << 42)
            | ((math.floor(x[j, 1] / bin_xy) + offset) << 21)
            | (math.floor(x[j, 2] / bin_theta) + offset)
        )
        if key not in seen:
            seen[key] = 1
            bins += 1
            need = max(float(n_min), _kld_bound(bins, err, z))
        if count >= need:
            break
    return out[:count].copy()


@njit(cache=True)
def _spread(x: FloatArray, n: int, ref_heading: float) -> FloatArray:
    """max - min of each coordinate over the first ``n`` particles, the heading's taken over the residuals
    wrapped about ``ref_heading`` (a heading of the cloud), so that a cloud straddling +-pi is not 2 pi wide."""
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for i in range(n):
        r2 = wrap(x[i, 2] - ref_heading)
        lo[0] = min(lo[0], x[i, 0])
        hi[0] = max(hi[0], x[i, 0])
        lo[1] = min(lo[1], x[i, 1])
        hi[1] = max(hi[1], x[i, 1])
        lo[2] = min(lo[2], r2)
        hi[2] = max(hi[2], r2)
    return hi - lo


@njit(cache=True)
def _roughening_spread(x: FloatArray, w: FloatArray, n_pred: int, roughening_k: float) -> FloatArray:
    """K E of roughening (Gordon, Salmond & Smith 1993, sec. 4.1; the config's ``roughening_k``): K times the
    :func:`_spread` (m, m, rad) of the first ``n_pred`` (predicted) particles, the heading's about the heading of
    the heaviest particle (the first of equal weights ``w``). The jitter's standard deviations are this times
    N^(-1/3) for the N particles after the resampling."""
    best = 0
    for i in range(1, x.shape[0]):
        if w[i] > w[best]:
            best = i
    return _spread(x, n_pred, x[best, 2]) * roughening_k


@njit(cache=True)
def _resample_roughened(
    x: FloatArray, w: FloatArray, logw: FloatArray, n_pred: int, roughening_k: float, gen: UIntArray
) -> tuple[FloatArray, FloatArray, FloatArray, bool]:
    """Systematic resampling of all N particles (:func:`_systematic_indices`) roughened by N(0, diag(sd^2)),
    sd = :func:`_roughening_spread` N^(-1/3); then the weights ``w`` and log-weights ``logw`` are set uniform in
    place. The usual resampling (on a low ESS, nothing injected after it) in one call; ``ParticleFilter._resample``
    composes the same steps otherwise. Returns the new particles and their :func:`_checked_stats`."""
    n = x.shape[0]
    sd = _roughening_spread(x, w, n_pred, roughening_k)
    sd = sd * n ** (-1.0 / 3.0)
    out = _gather(x, _systematic_indices(w, n, generator_from(gen).random()))
    _jitter(out, sd, gen)
    lw = -math.log(n)
    for i in range(n):
        logw[i] = lw
        w[i] = 1.0 / n
    mean, cov, finite = _checked_stats(out, w, logw)
    return out, mean, cov, finite


@njit(cache=True)
def _jitter_correlated(x: FloatArray, root: FloatArray, gen: UIntArray) -> None:
    """Add ``root`` e, e ~ N(0, I_3), to every particle in place (``root`` (3, 3), any square root of the
    jitter's covariance) and wrap the heading (``gen``: :mod:`._numba_rng`)."""
    rng = generator_from(gen)
    for i in range(x.shape[0]):
        e0 = rng.standard_normal()
        e1 = rng.standard_normal()
        e2 = rng.standard_normal()
        x[i, 0] += root[0, 0] * e0 + root[0, 1] * e1 + root[0, 2] * e2
        x[i, 1] += root[1, 0] * e0 + root[1, 1] * e1 + root[1, 2] * e2
        x[i, 2] = wrap(x[i, 2] + root[2, 0] * e0 + root[2, 1] * e1 + root[2, 2] * e2)


@njit(cache=True, inline="always")
def _add_weighted(
    mx: float, my: float, sc: float, ss: float, w: float, x: float, y: float, th: float, ref: float, sr: float,
    cr: float,
) -> tuple[float, float, float, float]:  # fmt: skip
    """One particle's terms of the estimate's first pass added to its sums: (mx + w x, my + w y, sc + w cos th,
    ss + w sin th), the sine and cosine through :func:`~locbench.filters._motion_kernels.sincos_near` about ``ref``."""
    si, ci = sincos_near(th, ref, sr, cr)
    return mx + w * x, my + w * y, sc + w * ci, ss + w * si


@njit(cache=True)
def _weighted_stats(poses: FloatArray, w: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Weighted mean (circular for the heading) and weighted covariance (heading residuals wrapped)."""
    n = poses.shape[0]
    mx = 0.0
    my = 0.0
    sc = 0.0
    ss = 0.0
    ref = poses[0, 2]
    sr, cr = math.sin(ref), math.cos(ref)
    for i in range(n):
        mx, my, sc, ss = _add_weighted(mx, my, sc, ss, w[i], poses[i, 0], poses[i, 1], poses[i, 2], ref, sr, cr)
    return _finish_stats(poses, w, mx, my, sc, ss)


@njit(cache=True, inline="always")
def _finish_stats(
    poses: FloatArray, w: FloatArray, mx: float, my: float, sc: float, ss: float
) -> tuple[FloatArray, FloatArray]:
    """:func:`_weighted_stats` from its first pass's sums: the circular mean heading and the covariance pass."""
    n = poses.shape[0]
    mth = math.atan2(ss, sc)
    if mth <= -math.pi:
        mth = math.pi
    c = np.zeros((3, 3))
    for i in range(n):
        r0 = poses[i, 0] - mx
        r1 = poses[i, 1] - my
        r2 = poses[i, 2] - mth
        r2 = r2 - 2.0 * math.pi * math.floor((r2 + math.pi) / (2.0 * math.pi))
        wi = w[i]
        c[0, 0] += wi * r0 * r0
        c[0, 1] += wi * r0 * r1
        c[0, 2] += wi * r0 * r2
        c[1, 1] += wi * r1 * r1
        c[1, 2] += wi * r1 * r2
        c[2, 2] += wi * r2 * r2
    c[1, 0] = c[0, 1]
    c[2, 0] = c[0, 2]
    c[2, 1] = c[1, 2]
    mean = np.empty(3)
    mean[0] = mx
    mean[1] = my
    mean[2] = mth
    return mean, c


@njit(cache=True, inline="always")
def _all_finite(a: FloatArray) -> bool:
    """Whether every element of ``a`` is finite (a loop: numba compiles no generator inside all())."""
    for i in range(a.shape[0]):  # noqa: SIM110
        if not math.isfinite(a[i]):
            return False
    return True


@njit(cache=True)
def _checked_stats(x: FloatArray, w: FloatArray, logw: FloatArray) -> tuple[FloatArray, FloatArray, bool]:
    """:func:`_weighted_stats` and whether every particle and log-weight is finite, in one call."""
    mean, cov = _weighted_stats(x, w)
    finite = True
    for i in range(x.shape[0]):
        finite = finite and math.isfinite(x[i, 0]) and math.isfinite(x[i, 1]) and math.isfinite(x[i, 2])
    return mean, cov, finite and _all_finite(logw)


# --- helpers ------------------------------------------------------------------------------------------------


def _compose_into(delta: FloatArray, dx: float, dy: float, dtheta: float) -> None:
    """delta <- delta (+) (dx, dy, dtheta), in place: an increment in the frame of delta's end pose appended."""
    c, s = math.cos(delta[2]), math.sin(delta[2])
    delta[0] += c * dx - s * dy
    delta[1] += s * dx + c * dy
    delta[2] = wrap_angle(delta[2] + dtheta)


def _regularisation_root(x: FloatArray, w: FloatArray) -> FloatArray:
    """A symmetric square root of the weighted covariance of the particles (negative rounding clipped)."""
    _, cov = _weighted_stats(x, w)
    vals, vecs = np.linalg.eigh(cov)
    out: FloatArray = (vecs * np.sqrt(np.clip(vals, 0.0, None))) @ vecs.T
    return out


def _regularisation_bandwidth(n: int, d: int = 3) -> float:
    """Optimal bandwidth of a Gaussian kernel for n samples in d dimensions, (4 / ((d + 2) n))^(1 / (d + 4))
    (Musso, Oudjane & Le Gland 2001, for a Gaussian density)."""
    return float((4.0 / ((d + 2.0) * n)) ** (1.0 / (d + 4.0)))


#: Candidates drawn per injected pose in sensor resetting, among which the event's likelihood chooses.
_SENSOR_DRAWS = 20


def sightings_poses(
    ranges: FloatArray,
    bearings: FloatArray | None,
    rows: IntArray,
    lm_xy: FloatArray,
    sigma_range: float,
    sigma_bearing: float,
    n: int,
    rng: np.random.Generator,
) -> FloatArray:
    """``n`` poses drawn from the likelihood of one event's sightings (sensor resetting, Lenser & Veloso 2000).

    Each pose takes one of the sightings at random, perturbs its range (and bearing) by the sensor noise and
    places the robot at that range from the landmark in a uniform direction phi around it, the heading
    phi - bearing; without bearings (beacon ranges) the heading is uniform. A withheld id (row < 0) takes a
    landmark of the map at random. The poses cover the set the single sighting allows, and the other
    sightings of the event then weigh them.
    """
    k = rng.integers(0, ranges.shape[0], size=n)
    row = rows[k]
    unknown = row < 0
    row[unknown] = rng.integers(0, lm_xy.shape[0], size=int(unknown.sum()))
    r = np.maximum(ranges[k] + sigma_range * rng.standard_normal(n), 0.0)
    phi = rng.uniform(-math.pi, math.pi, size=n)  # direction from the robot to the landmark
    out = np.empty((n, 3))
    out[:, 0] = lm_xy[row, 0] - r * np.cos(phi)
    out[:, 1] = lm_xy[row, 1] - r * np.sin(phi)
    if bearings is None:
        out[:, 2] = rng.uniform(-math.pi, math.pi, size=n)
    else:
        out[:, 2] = phi - (bearings[k] + sigma_bearing * rng.standard_normal(n))
    out[:, 2] = wrap_angle(out[:, 2])
    return out


def systematic_resample(weights: npt.ArrayLike, n: int, rng: np.random.Generator) -> IntArray:
    """Indices of ``n`` draws by systematic (low-variance) resampling, O(N + n) (PR table 4.4; report 003 [8]).

    ``weights`` (N,) non-negative, normalised here; one uniform u ~ U[0, 1) places the points (u + k) / n.
    """
    w = np.ascontiguousarray(weights, dtype=np.float64)
    if n <= 0:  # augmented MCL may replace every particle by a random one
        return np.empty(0, dtype=np.int64)
    return _systematic_indices(w, int(n), float(rng.random()))


def _take(a: FloatArray, sel: IntArray | slice) -> FloatArray:
    """``a[sel]`` as a contiguous float64 array (a copy: the observation's array is not handed on)."""
    return np.array(a[sel], dtype=np.float64, order="C")


class FreeSpaceSampler:
    """Uniform poses over free space: the free cells of a grid, else an axis-aligned box (x0, y0, x1, y1), m."""

    def __init__(self, grid: OccupancyGrid | None, box: tuple[float, float, float, float] | None) -> None:
        self._cells: IntArray | None = None
        self._grid = grid
        self._box = box
        if grid is not None:
            cells = np.flatnonzero(grid.free())
            if cells.size:
                self._cells = cells
        if self._cells is None and box is None:
            raise ConfigError("no free space to sample from: the grid has no free cell and there are no landmarks")

    def sample(self, n: int, rng: np.random.Generator) -> FloatArray:
        """``n`` poses (x m, y m, theta rad), uniform over free space, heading uniform in (-pi, pi]."""
        out = np.empty((n, 3))
        if self._cells is not None and self._grid is not None:
            g = self._grid
            k = self._cells[rng.integers(0, self._cells.size, size=n)]
            r, c = np.divmod(k, g.shape[1])
            off = rng.random((n, 2))
            out[:, 0] = g.origin[0] + (c + off[:, 0]) * g.resolution
            out[:, 1] = g.origin[1] + (r + off[:, 1]) * g.resolution
        else:
            assert self._box is not None
            x0, y0, x1, y1 = self._box
            u = rng.random((n, 2))
            out[:, 0] = x0 + (x1 - x0) * u[:, 0]
            out[:, 1] = y0 + (y1 - y0) * u[:, 1]
        out[:, 2] = wrap_angle(rng.uniform(-math.pi, math.pi, size=n))
        return out


def _sample_gaussian(mean: FloatArray, cov: FloatArray, n: int, rng: np.random.Generator) -> FloatArray:
    """``n`` draws of N(mean, cov) through a symmetric square root (works for a singular PSD cov)."""
    vals, vecs = np.linalg.eigh(0.5 * (cov + cov.T))
    root = vecs * np.sqrt(np.clip(vals, 0.0, None))
    out = mean + rng.standard_normal((n, 3)) @ root.T
    out[:, 2] = wrap_angle(out[:, 2])
    return out


# --- the filter ---------------------------------------------------------------------------------------------


class ParticleFilter(Filter):
    """Monte Carlo localization with the encoder model, landmark and likelihood-field models, augmented MCL.

    See the module docstring for the model, its sources (report 003 sec. 4.2; Probabilistic Robotics tables
    4.4, 6.3, 8.2, 8.3) and the choices made. ``requires`` is empty because the filter needs landmarks *or*
    an occupancy grid (``requires`` is an all-of set); ``reset`` raises :class:`ConfigError` when the
    configured sensors have no usable map.
    """

    id: ClassVar[str] = "pf"
    order: ClassVar[int] = 60
    description: ClassVar[str] = (
        "Monte Carlo localization: encoder motion model, landmark and laser likelihood-field models, augmented MCL"
    )
    doc: ClassVar[FilterDoc | None] = FilterDoc(
        "003",
        "sampled wheel-encoder model",
        "landmark likelihood (ids known or marginalised); laser likelihood field on the grid; low-variance "
        "resampling on low ESS; augmented MCL; uniform prior for global localization",
        "particles injected uniformly or drawn from the sightings (sensor resetting) for kidnap recovery; "
        "KLD-adaptive sample size (`adaptive=kld`)",
    )
    #: KLD-adaptive MCL (Fox 2003) beside the fixed 1000 particles: does adaptive sampling pay?
    comparison_configurations: ClassVar[tuple[dict[str, str], ...]] = ({"adaptive": "kld"},)
    consumes: ClassVar[frozenset[type]] = frozenset({Odometry, LandmarkObservations, LaserScan, RangeObservations})
    requires: ClassVar[frozenset[MapKind]] = frozenset()
    Config: ClassVar[type[FilterConfig]] = ParticleFilterConfig
    # 2: compiled kernels, so other random streams; 3: augmented MCL may inject every particle; 4: roughening
    # measures the predicted particles' spread, so it never leaves a resampled set of copies (other results);
    # 5: a sighting pair draws from the previous event's other landmarks only (inject_pairs results);
    # 6: the system noise is the dataset's when it declares one (0 on a model-matched world)
    version: ClassVar[int] = 6
    check_configurations: ClassVar[tuple[dict[str, str], ...]] = ({"adaptive": "kld"}, {"init": "uniform"})
    #: The largest weight of the current weights, or None until asked for (:meth:`_max_weight`).
    _w_max: float | None = None

    @classmethod
    def declared_check_failures(cls, config: FilterConfig) -> Mapping[str, str]:
        """``init=uniform`` fails the two tracking checks by design: its estimate starts anywhere in free space."""
        out = dict(cls.expected_check_failures)
        if cls.starts_without_pose(config):
            why = "global localization: from a uniform prior the first estimates are not near the true start"
            out |= {"check_heading_wrap": why, "check_noise_free": why}
        return out

    cost_per_data_s: ClassVar[float] = 0.1

    @classmethod
    def cost_scale(cls, config: FilterConfig) -> float:
        """The particle count over the default's 1000."""
        return getattr(config, "particles", 1000) / 1000.0

    #: The kidnap configuration: augmented MCL with sensor resetting, also from sighting pairs (the one that
    #: recovers on both office and room, docs/pf_consistency_kidnap.md); 003's PF only resamples.
    kidnap_params: ClassVar[dict[str, str]] = {"augmented": "true", "inject": "sensor", "inject_pairs": "true"}
    #: Suite ``kidnap`` runs augmented MCL injecting uniform poses (PR table 8.3), the kidnap configuration
    #: (sensor resetting, Lenser & Veloso 2000, also from pairs of single sightings: it recovers on room too) and
    #: KLD-adaptive MCL (Fox 2003) with the same recovery.
    kidnap_configurations: ClassVar[tuple[dict[str, str], ...] | None] = (
        {"augmented": "true"},
        kidnap_params,
        {"adaptive": "kld"} | kidnap_params,
    )
    source: ClassVar[str] = "003_e5c93f9be776ee5e.txt sec. 4.2; Thrun, Burgard & Fox, Probabilistic Robotics ch. 6, 8"
    config: ParticleFilterConfig

    @classmethod
    def starts_without_pose(cls, config: FilterConfig) -> bool:
        """``init="uniform"`` ignores the initial belief (global localization)."""
        return isinstance(config, ParticleFilterConfig) and config.init == "uniform"

    @property
    def logdet_tolerance(self) -> float:
        """How far log det of the sample covariance may fall in one predict by sampling noise alone.

        Adding independent noise of covariance Q to N samples of covariance C changes log det C by
        a = tr(C^-1 Q) plus a cross term of standard deviation 2 sqrt(a / N); the change is negative only when
        that term beats a, and its worst value over a is k^2 / N at k standard deviations. 25 / N is 5 sigma.
        """
        cfg = self.config
        return 25.0 / (cfg.min_particles if cfg.adaptive == "kld" else cfg.particles)

    def check_tolerances(self) -> CheckTolerances:
        """The conformance checks' bounds: the log det drop of :attr:`logdet_tolerance`, the rest the defaults."""
        return CheckTolerances(logdet_drop=self.logdet_tolerance)

    def routed_events(self) -> frozenset[type]:
        """Odometry, plus landmark sightings, beacon ranges and laser scans as switched on in the config."""
        out: set[type] = {Odometry}
        if self.config.use_landmarks:
            out.add(LandmarkObservations)
        if self.config.use_ranges:
            out.add(RangeObservations)
        if self.config.use_laser:
            out.add(LaserScan)
        return frozenset(out)

    # --- reset -------------------------------------------------------------------------------------------

    def _check_grid_tables(self, world: WorldMap) -> None:
        """Refuse (:class:`ResourceLimit`) a likelihood field / free-space index above the tables' memory limit."""
        cfg, grid = self.config, world.occupancy
        use_laser = cfg.use_laser and grid is not None
        needs_space = cfg.init == "uniform" or cfg.augmented
        if grid is not None and (use_laser or needs_space):
            per_cell = (LIKELIHOOD_FIELD_BYTES_PER_CELL if use_laser else 0) + (
                FREE_SPACE_BYTES_PER_CELL if needs_space else 0
            )
            check_bytes(
                "pf",
                f"the likelihood field / free-space index of a {grid.shape[0]} x {grid.shape[1]} grid",
                grid_cells(grid.shape) * per_cell,
                "give a coarser or smaller map (or use_laser=false, init=belief, augmented=false)",
            )

    def unsupported(self, world: WorldMap) -> str | None:
        """A map whose grid tables exceed their memory limit is a stored skip with the reason, not a failed run."""
        try:
            self._check_grid_tables(world)
        except ResourceLimit as exc:
            return str(exc)
        return None

    def reset(self, initial: Gaussian2, world: WorldMap, sensors: SensorSpec, rng: np.random.Generator) -> None:
        """Draw the particles (from ``initial`` or uniformly over free space) and resolve the noise models.

        Raises
        ------
        ConfigError
            When neither a landmark map (for ``use_landmarks``) nor an occupancy grid (for ``use_laser``)
            is present.
        """
        # long: reset resolves every noise model and map the config allows in one place, so a missing input is one error
        cfg = self.config
        self._rng = rng
        self._uniform: dict[int, FloatArray] = {}  # belief_sample's weights, one array per size
        # the generator's addresses for the kernels' draws (from the same state; see _numba_rng)
        self._gen = generator_addresses(rng)
        self._n = int(cfg.max_particles if cfg.adaptive == "kld" else cfg.particles)
        self._noise = cfg.motion_noise(sensors)
        nz = self._noise
        self._use_encoder = nz.wheelbase_m is not None and (
            cfg.motion_model == "encoder" or (cfg.motion_model == "auto" and nz.encoder_given)
        )
        self._travelled = [0.0, 0.0]
        self._q_std = np.array(process_noise(cfg.sigma_x_m, cfg.sigma_y_m, cfg.sigma_theta_rad, sensors))

        lm = world.landmarks if world.landmarks is not None and len(world.landmarks) > 0 else None
        grid = world.occupancy
        self._use_lm = cfg.use_landmarks and lm is not None
        self._use_ranges = cfg.use_ranges and lm is not None
        self._use_laser = cfg.use_laser and grid is not None
        if cfg.use_landmarks and lm is None:
            logger.info("pf: the world has no landmarks; landmark sightings and ranges will not be used")
        if cfg.use_laser and grid is None:
            logger.info("pf: the world has no occupancy grid; laser scans will not be used")
        if not (self._use_lm or self._use_laser or self._use_ranges):
            raise ConfigError(
                "pf: no usable sensor model: use_landmarks and use_ranges need a landmark map and use_laser an "
                f"occupancy grid; this world has {sorted(k.value for k in world.kinds) or 'neither'} "
                f"(use_landmarks={cfg.use_landmarks}, use_ranges={cfg.use_ranges}, use_laser={cfg.use_laser}); "
                "set use_laser=true on a dataset with a grid"
            )

        if lm is not None:
            self._lm_xy = np.ascontiguousarray(lm.xy, dtype=np.float64).reshape(-1, 2)
            self._lm_row = lm.index_of()
        else:
            self._lm_xy = np.zeros((0, 2))
            self._lm_row = {}
        sr, sb = landmark_noise(cfg.sigma_range_m, cfg.sigma_bearing_rad, sensors, warn=False)
        # Warn about defaulted landmark noise only once sightings arrive (a range-only dataset has none).
        self._lm_warn = self._use_lm and (
            (cfg.sigma_range_m is None and sensors.landmark_sigma_range_m is None)
            or (cfg.sigma_bearing_rad is None and sensors.landmark_sigma_bearing_rad is None)
        )
        self._sr, self._sb = sr, sb
        self._inv_var_r, self._inv_var_b = 1.0 / (sr * sr), 1.0 / (sb * sb)
        self._lm_log_norm = -_LOG_2PI - math.log(sr) - math.log(sb)
        srange = range_only_noise(cfg.range_only_sigma_m, sensors, warn=False)
        self._range_warn = self._use_ranges and cfg.range_only_sigma_m is None and sensors.range_sigma_m is None
        eps = cfg.range_outlier_fraction
        self._srange = srange
        self._range_inv_var = 1.0 / (srange * srange)
        self._range_log_hit = math.log1p(-eps) - 0.5 * _LOG_2PI - math.log(srange)
        self._range_log_floor = math.log(eps / cfg.range_outlier_span_m) if eps > 0.0 else -math.inf

        self._check_grid_tables(world)
        self._grid = grid
        self._fields: dict[float, LikelihoodField] = {}
        self._beam_idx: dict[int, IntArray] = {}

        box = None
        if lm is not None:
            lo, hi = self._lm_xy.min(axis=0), self._lm_xy.max(axis=0)
            box = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
        self._space = FreeSpaceSampler(grid, box) if (cfg.init == "uniform" or cfg.augmented) else None

        if cfg.init == "uniform":
            assert self._space is not None
            self._x = self._space.sample(self._n, rng)
        else:
            self._x = _sample_gaussian(
                np.asarray(initial.mean, dtype=np.float64), np.asarray(initial.cov, dtype=np.float64), self._n, rng
            )
        self._set_uniform_weights(self._n)
        # augmented MCL: per sensor [w_slow, w_fast], started at the first w_avg
        self._w_avg: dict[type, list[float]] = {}
        # sensor resetting: the last landmark event's sightings and the odometry composed since (robot frame)
        self._last_sightings: tuple[tuple[FloatArray, ...], FloatArray] | None = None
        self._t = math.nan
        self._diag = self._fresh_diag()
        self._set_estimate(*_checked_stats(self._x, self._weights(), self._logw))

    def __getstate__(self) -> dict[str, Any]:
        # the generator's addresses belong to this process's generator object: a copy recomputes its own
        state = dict(self.__dict__)
        state.pop("_gen", None)
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        if "_rng" in state:
            self._gen = generator_addresses(self._rng)

    @staticmethod
    def _fresh_diag() -> dict[str, float]:
        return {
            "n_eff": math.nan,
            "resampled": 0.0,
            "injected": 0.0,
            "p_inject": math.nan,
            "w_fast_over_w_slow": math.nan,
            "pair_chi2": math.nan,
        }

    # --- predict -----------------------------------------------------------------------------------------

    def predict(self, u: Odometry) -> None:
        """Move every particle by its own draw from the encoder model (report 003 eq. 1-2, 5, 10) plus Q (eq. 8)."""
        nz = self._noise
        if self._use_encoder and u.d_left is not None and u.d_right is not None:
            W = nz.wheelbase_m
            assert W is not None
            vl, vr = wheel_variances(
                u.d_left, u.d_right, nz.k_left, nz.k_right, nz.input_noise, self._travelled[0], self._travelled[1]
            )
            self._travelled[0] += abs(u.d_left)
            self._travelled[1] += abs(u.d_right)
            moved = _move(
                self._x,
                True,
                u.d_left,
                u.d_right,
                0.0,
                math.sqrt(vl),
                math.sqrt(vr),
                W,
                self._q_std,
                self._gen,
                self._weights(),
                self._logw,
            )
        elif (tw := nz.twist_sigmas(u)) is not None:
            assert u.v is not None and u.omega is not None and u.dt is not None
            moved = _move_twist(
                self._x,
                u.v * u.dt,
                u.omega * u.dt,
                tw[0] * u.dt,
                tw[1] * u.dt,
                u.dx,
                u.dy,
                u.dtheta,
                self._q_std,
                self._gen,
                self._weights(),
                self._logw,
            )
        else:
            vxy, vth = increment_variances(
                u.dx, u.dy, u.dtheta, nz.sigma_xy_per_m, nz.sigma_theta_per_m, nz.sigma_theta_per_rad
            )
            moved = _move(
                self._x,
                False,
                u.dx,
                u.dy,
                u.dtheta,
                math.sqrt(vxy),
                math.sqrt(vth),
                1.0,
                self._q_std,
                self._gen,
                self._weights(),
                self._logw,
            )
        if self._last_sightings is not None:
            _compose_into(self._last_sightings[1], u.dx, u.dy, u.dtheta)
        self._t = u.t
        self._diag = self._fresh_diag()
        self._set_estimate(*moved)

    # --- update ------------------------------------------------------------------------------------------

    def update(self, z: Observation) -> None:
        """Weight the particles with landmark sightings, beacon ranges or a laser scan; resample and inject."""
        prepared: tuple[int, tuple[Any, ...]] | None
        if type(z) is LandmarkObservations:
            prepared = self._prepare_landmarks(z) if self._use_lm else None
        elif type(z) is RangeObservations:
            prepared = self._prepare_ranges(z) if self._use_ranges else None
        elif type(z) is LaserScan:
            prepared = self._prepare_scan(z) if self._use_laser else None
        else:
            self.check_consumes(z)
            raise TypeError(f"ParticleFilter does not consume {type(z).__name__}")  # pragma: no cover
        self._t = z.t
        self._diag = self._fresh_diag()
        self._stats: tuple[Any, ...] | None = None  # the estimate, when the correction's last kernel made it
        if prepared is not None:
            self._correct(type(z), *prepared)
        self._set_estimate(*(self._stats or _checked_stats(self._x, self._weights(), self._logw)))

    def _prepare_landmarks(self, z: LandmarkObservations) -> tuple[int, tuple[FloatArray, FloatArray, IntArray]] | None:
        if self._lm_warn:
            landmark_noise(None, None, SensorSpec(), warn=True)
            self._lm_warn = False
        # a few sightings per event: plain floats are cheaper than numpy's masks here
        ok = [
            math.isfinite(r) and math.isfinite(b) and r > 0.0
            for r, b in zip(z.ranges.tolist(), z.bearings.tolist(), strict=True)
        ]
        sel, rows = self._map_rows(z.ids, ok, "landmark")
        if sel is None:
            return None
        data = (_take(z.ranges, sel), _take(z.bearings, sel), rows)
        return int(rows.size), data

    def _prepare_ranges(self, z: RangeObservations) -> tuple[int, tuple[FloatArray, IntArray]] | None:
        if self._range_warn:
            range_only_noise(None, SensorSpec(), warn=True)
            self._range_warn = False
        ok = [math.isfinite(r) and r >= 0.0 for r in z.ranges.tolist()]
        sel, rows = self._map_rows(z.ids, ok, "beacon")
        if sel is None:
            return None
        return int(rows.size), (_take(z.ranges, sel), rows)

    def _map_rows(self, ids: IntArray, ok: list[bool], what: str) -> tuple[IntArray | slice | None, IntArray]:
        """The indices of the usable observations (``ok``, id withheld or in the map) and their landmark rows
        (-1: withheld, marginalised over the map by :func:`_sightings_loglik`); the indices are ``slice(None)``
        when every observation is usable and None when none is."""
        keep: list[int] = []
        rows: list[int] = []
        for k, ident in enumerate(ids.tolist()):
            if not ok[k]:
                continue
            row = -1 if ident == UNKNOWN_ID else self._lm_row.get(int(ident), -2)
            if row == -2:
                logger.debug("%s id %d is not in the map; ignored", what, ident)
                continue
            keep.append(k)
            rows.append(row)
        if not keep:
            return None, np.empty(0, dtype=np.int64)
        sel = slice(None) if len(keep) == len(ok) else np.asarray(keep, dtype=np.int64)
        return sel, np.asarray(rows, dtype=np.int64)

    def _prepare_scan(self, z: LaserScan) -> tuple[int, tuple[FloatArray, FloatArray]] | None:
        n_all = int(z.ranges.shape[0])
        idx = self._beam_idx.get(n_all)
        if idx is None:
            k = min(self.config.laser_beams, n_all)
            idx = np.unique(np.round(np.linspace(0.0, n_all - 1.0, k)).astype(np.int64))
            self._beam_idx[n_all] = idx
        r = z.ranges[idx]
        ok = np.isfinite(r) & (r >= z.range_min) & (r < z.range_max)
        if not ok.any():
            return None
        angles = z.angle_min + z.angle_increment * idx[ok].astype(np.float64)
        ex, ey = scan_endpoints_robot_frame(r[ok], angles, z.sensor_pose)
        zmax = float(z.range_max)
        if zmax not in self._fields:
            assert self._grid is not None
            cfg = self.config
            self._fields[zmax] = make_likelihood_field(
                self._grid,
                z_hit=cfg.z_hit,
                z_rand=cfg.z_rand,
                sigma_hit_m=cfg.sigma_hit_m,
                max_dist_m=cfg.laser_max_dist_m,
                z_max_m=zmax,
            )
        self._scan_field = self._fields[zmax]
        return int(ok.sum()), (ex, ey)

    def _loglik(self, kind: type, data: tuple[FloatArray, ...], x: FloatArray | None = None) -> FloatArray:
        """Log-likelihood of an observation at each pose of ``x`` (default: the particles)."""
        x = self._x if x is None else x
        if kind is LandmarkObservations:
            ranges, bearings, rows = data
            return _sightings_loglik(
                x,
                ranges,
                bearings,
                rows,  # type: ignore[arg-type]
                self._lm_xy,
                True,
                self._inv_var_r,
                self._inv_var_b,
                self._lm_log_norm,
                -math.inf,
            )
        if kind is RangeObservations:
            ranges, rows = data
            return _sightings_loglik(
                x,
                ranges,
                ranges,  # no bearings
                rows,  # type: ignore[arg-type]
                self._lm_xy,
                False,
                self._range_inv_var,
                0.0,
                self._range_log_hit,
                self._range_log_floor,
            )
        ex, ey = data
        return log_likelihood(self._scan_field, x, ex, ey)

    def _best_loglik(self, kind: type, data: tuple[FloatArray, ...], ll: FloatArray, n_pred: int) -> float:
        """Sum over the sightings of the log-likelihood of each at the particle (of the first ``n_pred``) that
        explains it best; for a scan, the best particle's log-likelihood of the whole scan (``ll``)."""
        if kind is LaserScan:
            return float(np.max(ll[:n_pred]))
        belief = self._x[:n_pred]
        total = 0.0
        for k in range(data[0].shape[0]):
            one = tuple(a[k : k + 1] for a in data)
            total += float(np.max(self._loglik(kind, one, belief)))
        return total

    def _correct(self, kind: type, m: int, data: tuple[FloatArray, ...]) -> None:
        """Augmented MCL step (PR table 8.3): the steps below in order, each chosen by the config.

        Uniform poses enter before the weighting (:meth:`_inject_uniform`), so this observation weights them;
        poses drawn from the observation enter after the resampling (:meth:`_resample`): weighted by it again
        they would count it twice (as in Lenser & Veloso's sensor resetting).
        """
        cfg = self.config
        n = self._n
        avg = self._w_avg.get(kind)
        pair, ll_belief = self._gated_pair(kind, data)
        from_sensor = cfg.inject == "sensor" and (self._sensor_invertible(kind, m) or pair is not None)
        injected = 0
        if cfg.augmented and not from_sensor and avg is not None and avg[0] > 0.0:
            injected = self._inject_uniform(avg, n)
        ll, log_pred, n_eff, w = self._weigh(kind, data, None if injected else ll_belief)
        n_pred = n - injected if n > injected else n  # the predicted (belief) particles come first
        if cfg.augmented:
            avg = self._track_averages(kind, data, ll, log_pred, n_pred, m, avg)
        late = self._injection_count(avg, n) if cfg.augmented and from_sensor and avg else 0
        resampled, reset, late, n = self._resample(w, n_eff, n, n_pred, late, injected > 0)
        if late:
            self._x = np.concatenate([self._x, self._injected_poses(kind, data, late, pair)])
        if cfg.augmented and cfg.inject == "sensor" and cfg.inject_pairs and kind is LandmarkObservations:
            self._last_sightings = (data, np.zeros(3))
        if reset:
            self._set_uniform_weights(n)
        self._diag["resampled"] = 1.0 if resampled else 0.0
        self._diag["injected"] = float(injected + late)

    def _gated_pair(
        self, kind: type, data: tuple[FloatArray, ...]
    ) -> tuple[tuple[tuple[FloatArray, ...], FloatArray] | None, FloatArray | None]:
        """The sighting pair to draw poses from (``inject_pairs``) and the belief's log-likelihood when computed.

        Validation gate: pair poses only when no belief particle explains this (single) sighting.
        """
        cfg = self.config
        if not (cfg.augmented and cfg.inject == "sensor" and cfg.inject_pairs):
            return None, None
        pair = self._sighting_pair(kind, data)
        if pair is None:
            return None, None
        ll_belief = self._loglik(kind, data)
        chi2_best = 2.0 * (self._lm_log_norm - float(np.max(ll_belief)))
        self._diag["pair_chi2"] = chi2_best
        if cfg.pair_gate > 0.0 and chi2_best <= -2.0 * math.log1p(-cfg.pair_gate):
            return None, ll_belief
        return pair, ll_belief

    def _inject_uniform(self, avg: list[float], n: int) -> int:
        """Resample from the mixture (1 - p) belief + p uniform poses (PR table 8.3) before the weighting;
        returns how many uniform poses entered (they come last, with uniform weights for all)."""
        injected = self._injection_count(avg, n)
        if injected:
            keep = systematic_resample(self._weights(), n - injected, self._rng)
            assert self._space is not None
            self._x = np.concatenate([_gather(self._x, keep), self._space.sample(injected, self._rng)])
            self._set_uniform_weights(n)
        return injected

    def _weigh(
        self, kind: type, data: tuple[FloatArray, ...], ll_belief: FloatArray | None
    ) -> tuple[FloatArray, float, float, FloatArray]:
        """Bayes' rule on the log-weights: (log-likelihood per particle, log predictive, ESS, new weights).

        ``ll_belief``: the particles' log-likelihood when the pair gate already computed it.
        """
        w = np.empty(self._x.shape[0])
        if ll_belief is not None:
            ll = ll_belief
            log_pred, n_eff = _reweigh(self._logw, ll, w)
        elif kind is LandmarkObservations:
            ranges, bearings, rows = data
            # the likelihood and Bayes' rule in one call
            lm_args = (self._lm_xy, True, self._inv_var_r, self._inv_var_b, self._lm_log_norm, -math.inf)
            ll, log_pred, n_eff = _weigh_sightings(self._x, ranges, bearings, rows, *lm_args, self._logw, w)  # type: ignore[arg-type]
        else:
            ll = self._loglik(kind, data)
            log_pred, n_eff = _reweigh(self._logw, ll, w)
        self._w, self._w_of, self._w_max = w, self._logw, None
        if not math.isfinite(log_pred):
            raise FilterDiverged(f"ParticleFilter: every particle has zero likelihood at t={self._t:.3f} s")
        self._diag["n_eff"] = n_eff
        return ll, log_pred, n_eff, w

    def _track_averages(
        self,
        kind: type,
        data: tuple[FloatArray, ...],
        ll: FloatArray,
        log_pred: float,
        n_pred: int,
        m: int,
        avg: list[float] | None,
    ) -> list[float]:
        """Update w_slow and w_fast (PR table 8.3) from this observation's average likelihood of the belief.

        The averages measure the belief, so the particles injected in this step are left out (they had uniform
        weights, as the kept ones): counting them lowered w_avg by the injected share, which lowered w_fast,
        which raised the share, until every particle was replaced at every update
        (docs/pf_consistency_kidnap.md). With no particle kept the injected ones are the belief.
        """
        cfg = self.config
        if cfg.recovery_likelihood == "best":
            log_avg = self._best_loglik(kind, data, ll, n_pred)
        elif n_pred < self._n:
            top = float(np.max(ll[:n_pred]))
            log_avg = top + math.log(float(np.mean(np.exp(ll[:n_pred] - top)))) if top > -math.inf else top
        else:
            log_avg = log_pred
        # geometric mean per sighting or beam, so that the average neither underflows nor depends on m
        w_avg = math.exp(log_avg / m)
        if avg is None:
            avg = self._w_avg[kind] = [w_avg, w_avg]
        else:
            avg[0] += cfg.alpha_slow * (w_avg - avg[0])
            avg[1] += cfg.alpha_fast * (w_avg - avg[1])
        return avg

    def _resample(
        self, w: FloatArray, n_eff: float, n: int, n_pred: int, late: int, resampled: bool
    ) -> tuple[bool, bool, int, int]:
        """The resampling the config chooses: KLD sampling at every correction (``adaptive="kld"``), else
        systematic resampling on a low ESS or to make room for ``late`` poses; then roughening or the
        regularised kernel. ``resampled``: the uniform injection already resampled.

        Returns (resampled, weights to reset to uniform, late poses that fit, particle count).
        """
        cfg = self.config
        kld = cfg.adaptive == "kld"
        by_ess = not kld and (late > 0 or n_eff < cfg.resample_ess_fraction * n)
        jitter: FloatArray | None = None
        # the usual resampling (on a low ESS, roughened, nothing injected after it) in one compiled call
        fast = by_ess and not late and not cfg.regularise and cfg.roughening_k > 0.0 and n_pred > 1
        if fast:
            self._x, *stats = _resample_roughened(self._x, w, self._logw, n_pred, cfg.roughening_k, self._gen)
            self._stats = tuple(stats)
            resampled = True
        elif (resampled or kld or by_ess) and cfg.regularise:
            # Musso et al. 2001: the kernel's covariance is h^2 times the weighted covariance before resampling
            jitter = _regularisation_root(self._x, w)
        elif (resampled or kld or by_ess) and cfg.roughening_k > 0.0 and n_pred > 1:
            # roughening measures the spread of the predicted particles (not of the injected ones), the
            # heading's about the best particle's heading (the cloud's own)
            jitter = _roughening_spread(self._x, w, n_pred, cfg.roughening_k)
        if kld:
            # KLD sampling draws the new set, and its size, at every correction (Fox 2003, table 1)
            self._x = _kld_resample(
                self._x,
                w,
                self._gen,
                cfg.kld_err,
                cfg.kld_z,
                cfg.min_particles,
                cfg.max_particles,
                cfg.kld_bin_xy_m,
                math.radians(cfg.kld_bin_theta_deg),
            )
            self._n = n = int(self._x.shape[0])
            late = min(late, n)
            self._x = self._x[: n - late]
            resampled = True
        elif by_ess and not fast:
            self._x = _gather(self._x, systematic_resample(w, n - late, self._rng))
            resampled = True
        if resampled and jitter is not None:
            if jitter.ndim == 2:
                _jitter_correlated(self._x, _regularisation_bandwidth(n) * jitter, self._gen)
            else:
                _jitter(self._x, jitter * n ** (-1.0 / 3.0), self._gen)
        return resampled, kld or (by_ess and not fast), late, n

    @staticmethod
    def _sensor_invertible(kind: type, m: int) -> bool:
        """Whether an event pins the pose down enough to draw poses from it: two range-bearing sightings or
        three ranges. One sighting allows a whole circle of poses, all of which go on seeing it alike while
        only that landmark is in view: injected there they pull the weighted mean round the circle."""
        return (kind is LandmarkObservations and m >= 2) or (kind is RangeObservations and m >= 3)

    def _injection_count(self, avg: list[float], n: int) -> int:
        """How many of ``n`` particles augmented MCL replaces: Binomial(n, max(0, 1 - w_fast / w_slow))."""
        if not avg[0] > 0.0:
            return 0
        ratio = avg[1] / avg[0]
        p_inject = max(0.0, 1.0 - ratio)
        self._diag["w_fast_over_w_slow"] = ratio
        self._diag["p_inject"] = p_inject
        return int(self._rng.binomial(n, p_inject)) if p_inject > 0.0 else 0

    def _sighting_pair(
        self, kind: type, data: tuple[FloatArray, ...]
    ) -> tuple[tuple[FloatArray, ...], FloatArray] | None:
        """The previous landmark event's sightings of other (identified) landmarks than this event's single
        sighting, and the odometry since: the two together pin the pose down. A previous sighting of the same
        landmark is left out: moved by the odometry since (one step when that landmark stays in view and
        another leaves it), its poses form the circle this sighting already allows, every one of which
        explains it (docs/pf_consistency_kidnap.md)."""
        last = self._last_sightings
        if kind is not LandmarkObservations or last is None or data[0].shape[0] != 1:
            return None
        row = int(data[2][0])
        prev = last[0][2]
        other = (prev >= 0) & (prev != row)
        if row < 0 or not bool(np.any(other)):
            return None
        return tuple(a[other] for a in last[0]), last[1]

    def _injected_poses(
        self,
        kind: type,
        data: tuple[FloatArray, ...],
        count: int,
        pair: tuple[tuple[FloatArray, ...], FloatArray] | None = None,
    ) -> FloatArray:
        """``count`` poses drawn from the likelihood of a landmark or beacon event (``inject="sensor"``): 20
        candidates per pose from the single sightings (:func:`sightings_poses`), chosen among by the event's
        likelihood. With ``pair`` (the previous landmark event and the odometry since) the candidates come
        from the previous event's sightings, moved by that odometry, and this event chooses among them."""
        rng = self._rng
        draws = _SENSOR_DRAWS * count
        if kind is LandmarkObservations:
            ranges, bearings, rows = pair[0] if pair is not None else data
            cand = sightings_poses(ranges, bearings, rows, self._lm_xy, self._sr, self._sb, draws, rng)  # type: ignore[arg-type]
        else:
            ranges, rows = data
            cand = sightings_poses(ranges, None, rows, self._lm_xy, self._srange, 0.0, draws, rng)  # type: ignore[arg-type]
        if pair is not None:
            # the previous event's poses moved by the odometry since (each candidate's own frame)
            delta = pair[1]
            c, sn = np.cos(cand[:, 2]), np.sin(cand[:, 2])
            cand[:, 0] += c * delta[0] - sn * delta[1]
            cand[:, 1] += sn * delta[0] + c * delta[1]
            cand[:, 2] = wrap_angle(cand[:, 2] + delta[2])
        ll = self._loglik(kind, data, cand)
        cw = np.exp(ll - np.max(ll))
        return _gather(cand, systematic_resample(cw, count, rng))

    # --- output ------------------------------------------------------------------------------------------

    def _set_uniform_weights(self, n: int) -> None:
        self._logw = np.full(n, -math.log(n))
        self._w, self._w_of, self._w_max = np.full(n, 1.0 / n), self._logw, None

    def _weights(self) -> FloatArray:
        """exp(log-weights), kept from the last weighting while the log-weights are the same array."""
        if self._w_of is not self._logw:
            self._w, self._w_of, self._w_max = np.exp(self._logw), self._logw, None
        return self._w

    def _max_weight(self) -> float:
        """The largest weight, kept with the weights (a prediction leaves them as they are: asked after every
        event, it is computed only after a weighting)."""
        w = self._weights()
        if self._w_max is None:
            self._w_max = float(np.max(w))
        return self._w_max

    def _set_estimate(self, mean: FloatArray, cov: FloatArray, finite: bool) -> None:
        """Keep the statistics of the particles after a step (the runner reads them after every event);
        ``finite``: whether every particle and log-weight is, else the filter has diverged."""
        if not finite:
            raise FilterDiverged(f"ParticleFilter particles became non-finite at t={self._t:.3f} s")
        self._est: tuple[FloatArray, FloatArray] | None = (mean, cov)

    def _diagnostics(self) -> dict[str, float]:
        return {**self._diag, "particles": float(self._n)}

    def particles(self) -> tuple[FloatArray, FloatArray]:
        """Copies of the particles (N, 3) (x m, y m, theta rad) and their normalised weights (N,)."""
        return self._x.copy(), self._weights().copy()

    def belief_sample(self, rng: np.random.Generator, size: int) -> tuple[FloatArray, FloatArray]:
        """``size`` particles drawn by systematic resampling of the weights, each of weight 1/size.

        Particle i is drawn m w_i times in expectation (m = ``size``), so the sample's mean of any function is the
        weighted set's in expectation; its fair scores (:mod:`locbench.evaluate.scores`) match the weighted set's
        within their noise (docs/protocols.md, "Proper scores"). ``rng`` (the runner's, not the filter's) draws only
        the common offset. The weights are one read-only array per size, the same object at every call.
        """
        if size <= 0:  # as systematic_resample: nothing drawn, the generator untouched
            return np.empty((0, 3)), np.empty(0)
        uniform = self._uniform.get(size)
        if uniform is None:
            uniform = self._uniform[size] = np.full(size, 1.0 / size)
            uniform.flags.writeable = False
        return _systematic_draw(self._x, self._weights(), size, float(rng.random())), uniform

    def event_health(self) -> dict[str, float]:
        """The ``ess_fraction`` (n_eff / particles) of the last update, the ``max_weight`` and augmented MCL's
        ``w_fast_over_w_slow`` of the sensor of the last update (NaN when off), beside the default
        :meth:`health`'s covariance trace and heading variance of the particle scatter (no NIS)."""
        w = self._weights()
        n_eff = float(self._diag.get("n_eff", math.nan))
        return {
            "ess_fraction": n_eff / float(w.shape[0]),
            "max_weight": self._max_weight(),
            "w_fast_over_w_slow": float(self._diag.get("w_fast_over_w_slow", math.nan)),
        }

    def estimate(self) -> Estimate:
        """Weighted mean (circular heading), weighted covariance (wrapped residuals) and diagnostics."""
        if self._est is None:  # the particles were set from outside: their statistics from scratch
            self._est = _weighted_stats(self._x, self._weights())
        mean, cov = self._est
        return Estimate(t=self._t, mean=mean.copy(), cov=cov.copy(), diagnostics=self._diagnostics())
