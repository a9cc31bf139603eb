"""One flight through the 3D-INM: mechanize, discretise, filter, smooth, georeference."""

from __future__ import annotations

import dataclasses
import functools
import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError, DataError, GravsurveyError
from ..geodesy import MGAL, WGS84, Ellipsoid, ecef_to_geodetic, geodetic_to_ecef, local_displacement, mat_en, mat_ie
from ..filters import centred_mean
from ..io.record import FlightRecord
from .errormodel import (
    ACCEL_BIAS_SIGMA_MPS2,
    BA,
    BG,
    DP,
    DQ,
    F3,
    TH,
    AltimeterMeasurement,
    G,
    N_STATE_BIAS,
    GnssMeasurement,
    discretise,
    epoch_geometry,
    attitude_at,
    hermite_position,
    initial_covariance,
    nearest_sample,
    initial_mean,
    state_perm,
)
from .gnssqc import GnssLatency, GnssLeverArm, estimate_gnss_lever_arm, gnss_latency_fit, track_attitude
from .heightqc import (
    COARSE_FINE_STEP_S,
    LATENCY_DRIFT_MIN_S,
    LATENCY_K,
    LATENCY_MAX_S,
    LATENCY_MIN_S,
    SAME_FRACTION,
    HeightFaults,
    coarse_height_offset,
    estimate_latency,
    estimate_latency_drift,
    find_height_faults,
    gnss_height_fraction,
    noisy_stretches,
    repair_heights,
)
from .identify import (
    WALK_MIN_LOG_LR,
    config_models_drift,
    drift_sigma_passed,
    field_attitude_noise_degph,
    filter_height_sigma,
    height_noise_density,
    horizontal_prior,
    identify_params,
    keep_default_prior,
    model_resolution_m,
    refine_prior,
    spectral_model_of,
    straight_weight,
    wide_prior_params,
    vertical_residual,
)
from .kalman import filter_and_smooth, likelihood_gain_z, log_likelihood
from .mechanization import Navigation, mechanize, navigation_to_geodetic, rodrigues
from .params import (
    RADPS_PER_DEGPH,
    TRIADS,
    InitialState,
    InmParams,
    accel_bias_states_for,
    initial_state_from_gnss,
    solvability_warnings,
)
from .vector import horizontal_outputs, missed_field_per_component

__all__ = [
    "InmSolution",
    "estimate_anomaly",
    "solvability_warnings",
    "initial_state_from_gnss",
    "heights_at_imu",
    "antenna_offset_enu",
]


@dataclass
class InmSolution:
    """Per-epoch output of :func:`estimate_anomaly` (N epochs at the filter rate).

    Attributes
    ----------
    time : ndarray (N,)
        s, same base as the FlightRecord.
    g_forward, sigma_forward : ndarray (N,)
        Forward-filter gravity disturbance and its 1-sigma, m/s^2 (positive = stronger gravity).
    g_smooth, sigma_smooth : ndarray (N,)
        RTS-smoothed gravity disturbance and 1-sigma, m/s^2.
    f3_smooth, f3_sigma : ndarray (N,)
        Smoothed gravimeter error and 1-sigma, m/s^2.
    lat, lon : ndarray (N,)
        Corrected geodetic position, rad (WGS84 or the chosen ellipsoid).
    height : ndarray (N,)
        Corrected ellipsoidal height, m.
    vel_n : ndarray (N, 3)
        Corrected Earth-relative velocity, ENU, m/s.
    speed : ndarray (N,)
        Ground speed, m/s.
    heading : ndarray (N,)
        Track over ground, rad clockwise from north in [0, 2 pi).
    innovations_normalised : ndarray (N,) or (N, m)
        Whitened innovations (NaN where no measurement); (N,) when one
        measurement per epoch.
    dq_smooth, dp_smooth : ndarray (N, 3)
        Smoothed navigation corrections on the triad (m, m/s).
    sigma_position_m : ndarray (N, 3)
        Smoothed 1-sigma of the position error on the triad axes, m (``dq``; with GNSS
        aiding ``dq + q x theta``, the true position error).
    x_smooth, p_smooth : ndarray (N, n), (N, n, n)
        Full smoothed state and covariance (seed order, see errormodel); n = 8, or 14 with
        GNSS aiding (attitude error ``TH`` and gyro bias ``BG`` appended).
    warnings : list of str
    params : InmParams
        The settings the filter ran with (identified values filled in).
    identification : dict
        What :func:`gravsurvey.inm.identify.identify_params` found (empty when
        ``params.identify`` is false).
    resolution_m : float
        Half-wavelength resolution of ``g_smooth``, m: the half-power point of the smoother's
        steady-state transfer function for the model it ran with
        (:func:`gravsurvey.inm.identify.wiener_resolution_m`).
    gnss_aided : bool
        Whether GNSS positions were used as a measurement (``model.gnss_aiding`` and a GNSS
        channel in the record).
    attitude : ndarray (N, 3)
        Corrected roll, pitch, heading of a strapdown (forward-left-up) triad, rad (heading
        in [0, 2 pi)); NaN for a platform triad.
    attitude_sigma : ndarray (N, 3)
        Smoothed 1-sigma of roll, pitch and heading, rad (GNSS-aided strapdown only; NaN
        otherwise).
    passes : int
        Filter/smoother passes run (``model.attitude_passes``).
    attitude_corrections : list of float
        Size of the initial-attitude correction after each pass, rad (when the passes end at
        ``attitude_passes``, the last entry is the one the last pass would still apply).
    initial_corrections : list of (float, float)
        Size of the initial position (m) and velocity (m/s) correction after each pass but the
        last (GNSS-aided only).
    passes_reverted : dict or None
        When the gyro-bias corrections of three passes grew (:func:`diverging_gyro_axis`) and the
        estimate is the first of them, about its linearisation: ``axis`` (0 or 1, triad),
        ``pass`` (0-based index of the third) and ``bias_corrections_degph`` (the three
        corrections on that axis).
    follow_tilts_rad : list of float
        The smoothed tilt of the mechanization (rad) that started each following pass
        (:func:`_follow_passes`; empty: the passes' mechanization was near enough).
    gyro_bias_t, gyro_bias_sigma_t : ndarray (3,) or None
        The gyro biases on the triad axes and their smoothed 1-sigma, rad/s (GNSS-aided only):
        what the passes took off the rates plus the last pass's smoothed bias state.
    accel_bias_t, accel_bias_sigma_t : ndarray (2,) or None
        The biases of accelerometers 1 and 2 and their smoothed 1-sigma, m/s^2, when the filter
        carried them as states (16 or 18): what the passes took off the specific force plus the
        last pass's smoothed bias state.
    accel_bias_taken_off : bool
        Whether the passes took the estimated accelerometer bias off the specific force
        (``model.accel_bias_mps2`` given, strapdown triad).
    alignment : Alignment or None
        The coarse alignment the initial attitude came from (None: given).
    attitude_converge_s : float
        Time after the first epoch from which the forward filter's heading sigma stays
        within twice its median over the flight, s (GNSS-aided strapdown; NaN otherwise).
    gnss_residual_rms_m : float
        RMS horizontal distance of the corrected track from the GNSS positions, m.
    gnss_residual_systematic_m : float
        RMS of that residual's 20-s running means (what is not GNSS noise), m.
    dg_horizontal : ndarray (N, 2) or None
        Smoothed horizontal gravity disturbance ``[north, east]``, m/s^2 (``dg = g_true -
        gamma`` on local ENU; deflections ``xi = -dg_north / gamma``, ``eta = -dg_east /
        gamma``).  None unless ``model.horizontal`` and GNSS aiding.
    dg_horizontal_sigma : ndarray (N, 2) or None
        Its smoothed 1-sigma, m/s^2.
    horizontal_observable : ndarray of bool (N,) or None
        Whether the data determine the horizontal components at that epoch: both posterior
        sigmas below :data:`gravsurvey.inm.vector.OBSERVABLE_SIGMA_RATIO` times the prior's
        (docs/method.md, "Vector gravimetry").
    log_likelihood : float
        The last pass's log-likelihood of its measurements (NaN unless the accelerometer noise
        was chosen by it, :func:`choose_accel_noise`) ...
    log_likelihood_epochs : ndarray (N,) or None
        ... and its terms per filter epoch (:func:`gravsurvey.inm.kalman.log_likelihood`).
    """

    time: np.ndarray
    g_forward: np.ndarray
    sigma_forward: np.ndarray
    g_smooth: np.ndarray
    sigma_smooth: np.ndarray
    f3_smooth: np.ndarray
    f3_sigma: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    height: np.ndarray
    vel_n: np.ndarray
    speed: np.ndarray
    heading: np.ndarray
    innovations_normalised: np.ndarray
    dq_smooth: np.ndarray
    dp_smooth: np.ndarray
    sigma_position_m: np.ndarray
    x_smooth: np.ndarray
    p_smooth: np.ndarray
    x_forward: np.ndarray
    warnings: list = field(default_factory=list)
    gnss_aided: bool = False
    params: InmParams | None = None
    identification: dict = field(default_factory=dict)
    resolution_m: float = float("nan")
    attitude: np.ndarray | None = None
    attitude_sigma: np.ndarray | None = None
    passes: int = 1
    attitude_corrections: list = field(default_factory=list)
    initial_corrections: list = field(default_factory=list)
    passes_reverted: dict | None = None
    gyro_bias_t: np.ndarray | None = None
    gyro_bias_sigma_t: np.ndarray | None = None
    accel_bias_t: np.ndarray | None = None
    accel_bias_sigma_t: np.ndarray | None = None
    accel_bias_taken_off: bool = False
    alignment: object | None = None
    attitude_converge_s: float = float("nan")
    gnss_residual_rms_m: float = float("nan")
    gnss_residual_systematic_m: float = float("nan")
    dg_horizontal: np.ndarray | None = None
    dg_horizontal_sigma: np.ndarray | None = None
    horizontal_observable: np.ndarray | None = None
    log_likelihood: float = float("nan")
    log_likelihood_epochs: np.ndarray | None = None
    gyro_screen_z: float = float("nan")
    follow_tilts_rad: list = field(default_factory=list)


def _check_record(record):
    imu = record.imu
    t = np.asarray(imu.time, float)
    src = record.source or "record"
    if t.ndim != 1 or t.size < 4:
        raise DataError(f"{src}: imu: need at least 4 samples, got {t.size}")
    if not np.all(np.diff(t) > 0):
        raise DataError(f"{src}: imu.time: expected strictly increasing times")
    for name in ("specific_force_t", "angular_rate_t"):
        a = np.asarray(getattr(imu, name), float)
        if a.shape != (t.size, 3):
            raise DataError(f"{src}: imu.{name}: expected shape ({t.size}, 3), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise DataError(f"{src}: imu.{name}: non-finite values")
    alt = record.altimeter
    if alt is None or len(alt.time) == 0:
        raise DataError(f"{src}: altimeter: no samples; the 3D-INM needs radial (height) information")


def stack_measurements(parts):
    """Concatenate per-epoch measurement sets ``[(z, H, R), ...]`` into one ``(z, H, R)``.

    ``z`` (N, m_i) are joined along the component axis, ``H`` (N, m_i, n) likewise and ``R``
    block-diagonally (the sources' errors are independent).
    """
    if len(parts) == 1:
        return parts[0]
    z = np.concatenate([p[0] for p in parts], axis=1)
    h = np.concatenate([p[1] for p in parts], axis=1)
    n, m = z.shape
    r = np.zeros((n, m, m))
    o = 0
    for p in parts:
        k = p[0].shape[1]
        r[:, o : o + k, o : o + k] = p[2]
        o += k
    return z, h, r


#: Shortest record (s) whose anomaly prior is identified; shorter ones keep the default prior.
MIN_REFINE_S = 900.0

#: An IMU step longer than this many nominal steps (the longer of its neighbours) is a gap for
#: :func:`imu_gap_noise`.
IMU_GAP_STEPS = 1.5
#: Window (s) of the running mean whose residual is the specific force a straight line across a
#: gap of about this length misses (:func:`missed_accel_sigma`).
IMU_GAP_WINDOW_S = 1.0

#: Shortest time (s) between the two GNSS fixes of one speed in :func:`median_ground_speed`:
#: the fixes' noise (1 m) over 2 s adds 0.7 m/s to a component, a few mm/s to a 70-m/s norm.
SPEED_BASELINE_S = 2.0

#: Smoothed tilt of the passes' mechanization (rad) above which passes follow the smoothed
#: attitude (:func:`_follow_passes`): ``|r| e^2 / 2`` is 3 m at 1 mrad.  Measured on the unseen
#: suite's quick strapdown draws: the passes leave navigation-grade gyros' mechanization within
#: 0.21 mrad (75 draws), fibre-optic gyros' (0.72 deg/h) within 0.63, a tactical IMU's 1.7-7.0
#: mrad (13 draws each; docs/benchmarks.md, "Following passes, and the gyro noise searched on
#: platforms").  Between, following changed little but the gyro noise the likelihood chose
#: (fibre-optic U006: 10 deg/h, 2.0 -> 5.6 mGal).
FOLLOW_TILT_RAD = 1e-3
#: At most this many following passes.
FOLLOW_PASSES = 2
#: Kalman epoch rate (Hz) of a flight with tactical-grade gyros (:func:`tactical_rate_params`),
#: where the config does not give ``model.filter_rate_hz``: the estimate runs at this rate
#: (:func:`estimate_anomaly`; the gyro noise searched at the configured rate first).  Measured
#: on 40 tactical quick draws of the unseen suite: 18 better by over 5 %, 8 worse; held out
#: (seeds 2000-2019) median RMS / bound 1.78 -> 1.41 (U2012 1.33 -> 0.52 mGal, U2006 3.21 ->
#: 1.33, U2010 4.78 -> 2.93; U2000 1.29 -> 1.75); 2 Hz kept less (median 1.49); at full length
#: mixed (docs/benchmarks.md, "A faster filter for tactical gyros").
TACTICAL_RATE_HZ = 5.0
#: ... but never more filter epochs than this: the passes hold covariances per epoch, so memory
#: grows with them (a full-length tactical draw of 235 min, 2.5 Hz: peak RSS 1.10 -> 1.73 GB; 92
#: min at 5 Hz: 0.72 -> 1.31 GB); a longer flight gets the highest rate that keeps within it.
TACTICAL_MAX_EPOCHS = 36_000
#: A gyro white drift (deg/h, given or chosen) from which a flight runs at
#: :data:`TACTICAL_RATE_HZ`: between the candidates 1 and 10 (:data:`GYRO_NOISE_CANDIDATES_DEGPH`);
#: a tactical IMU's datasheet figure (0.1 deg/sqrt(h): 6 deg/h) is above it.  Passes that
#: followed with 1 deg/h chosen were neutral at 5 Hz (tactical U005 0.48 -> 0.48 mGal, U010
#: 1.77 -> 1.74, U2017 0.90 -> 0.94, U2018 0.97 -> 0.96) and are left at the configured rate.
TACTICAL_GYRO_DEGPH = 3.0

#: The passes stop once the initial-attitude correction is below this, rad (0.001 deg).
ATTITUDE_CONVERGED_RAD = math.radians(1e-3)

#: ... and once every gyro-bias correction is below this, rad/s (0.001 deg/h), or below its own
#: smoothed sigma.  An uncorrected horizontal gyro bias tilts the mechanization by ``b t``
#: (0.05 deg/h: 0.5 mrad after 40 min) and the filter, linearised about that navigation, left a
#: slow vertical error of ~35 mGal per deg/h of bias (docs/method.md, "Passes"); 0.001 deg/h
#: leaves ~0.04 mGal.
GYRO_BIAS_CONVERGED_RADPS = 1e-3 * RADPS_PER_DEGPH

#: ... and once the initial velocity correction is below this, m/s, and the position's below
#: :data:`POSITION_CONVERGED_M`.  The initial position and velocity come from a fit to the first
#: seconds of GNSS; in turbulence the velocity is off by the gusts (1-4.6 m/s on the unseen
#: suite), and the mechanization about it carries a Schuler oscillation of ``dv / w_s`` (800 m per
#: m/s) that the filter, linearised about it, left in the disturbance (measured: U005 of the
#: unseen suite, 5.5 m horizontal turbulence, a 1.8 mGal oscillation of 84 min).  0.1 m/s leaves
#: 80 m (under 0.1 mGal).
VELOCITY_CONVERGED_MPS = 0.1
POSITION_CONVERGED_M = 30.0

#: With ``model.accel_bias_mps2`` the passes also stop only once every accelerometer-bias
#: correction is below this, m/s^2 (2 micro-g), or below its own smoothed sigma.  A horizontal
#: bias ``b`` left in the specific force is a tilt ``b / g`` to the mechanization, which puts
#: ``b |f_h| / g`` into the vertical in turns (docs/method.md, "Accelerometer bias").
ACCEL_BIAS_CONVERGED_MPS2 = 2.0e-5

#: A horizontal accelerometer bias found by a pass (16 states, the default prior
#: :data:`gravsurvey.inm.errormodel.ACCEL_BIAS_SIGMA_MPS2`) above this, m/s^2 (150 micro-g; on 136
#: runs of the unseen suite's navigation-grade strapdown draws at most 6e-4 was found, on 144
#: platform runs 7.9e-4), is a tactical-grade IMU's: taken off between passes as with a datasheet
#: ``model.accel_bias_mps2`` of :data:`ACCEL_BIAS_PRIOR_PER_FOUND` times the found bias (a
#: strapdown triad's; on a platform as well since 2026-12-07: 7 tactical draws 2.0x -> 1.2x the
#: bound median, docs/benchmarks.md "Following passes, and the gyro noise searched on
#: platforms").  Left in, it is a tilt to the identification, which reads the unaided vertical
#: channel: quick U010 with 1e-2 / -6e-3 m/s^2
#: identified a vertical white level of 4.3e-4 m/s^2 and went 1.55 -> 6.22 mGal
#: (docs/benchmarks.md, "A tactical-grade IMU").
ACCEL_BIAS_FOUND_MPS2 = 1.5e-3
#: The datasheet-like prior sigma a found bias sets, per found bias (the larger axis).
ACCEL_BIAS_PRIOR_PER_FOUND = 2.0

#: The filter's anomaly state is a zero-mean Markov process (sigma of the identified prior,
#: often under a mGal on a weak field), but the vertical channel carries a constant the prior
#: does not hold: the gravimeter's bias (0.6-6 mGal on the unseen suite) and the field's mean
#: over the flight.  Left in, the prior pulls the estimate towards zero at every epoch and the
#: heights pull it back: the vertical channel's innovations are too large for its model (quick
#: U2635, a 4.6-mGal bias under a 0.3-mGal prior: the altimeter's whitened innovations 1.75
#: against 1.03 without the bias), the smoothed estimate carries the fight (0.57 against 0.36
#: mGal) and the likelihood takes a noisier gyro to explain it (10 deg/h on a navigation-grade
#: platform).  The mean of the identification's wide-prior pass (which holds the constant) is
#: therefore taken off the specific force along the ellipsoid normal before the passes with
#: the chosen prior, and added back to the estimate; not where it is under this, m/s^2.
VERTICAL_OFFSET_MIN_MPS2 = 1.0e-7
#: ... nor where it is within this many of the chosen prior's sigmas, which the prior holds
#: (taken off there too it moved the sample survey's F01 1.72 -> 1.84 mGal, its constant 0.94
#: sigma; docs/benchmarks.md, "The vertical channel's constant").
VERTICAL_OFFSET_PER_PRIOR = 3.0

#: An accelerometer-bias correction above this (m/s^2) re-runs the identification about the
#: corrected specific force in the next pass: the vertical channel's tilt leak, which the noise
#: levels were identified with, has changed.
REIDENTIFY_ACCEL_BIAS_MPS2 = 5.0e-5

#: An initial-attitude correction above this (rad, 0.5 deg) re-runs the identification about
#: the corrected attitude in the next pass (after an alignment: 0.004-0.13 deg measured, not re-run).
REIDENTIFY_RAD = math.radians(0.5)

#: When the passes end at ``attitude_passes`` and the last pass would still move the
#: linearisation by more than this (rad, 0.5 deg) - its initial-attitude correction, or the tilt
#: ``b T`` that its gyro-bias correction beyond the bias's sigma builds over the record - the
#: linearisation never settled and the flight fails (DataError) instead of giving an estimate
#: with that error (measured: 10 deg/h gyro biases under the default 0.05 deg/h prior, five
#: passes, corrections 55, 4.8, 17.7, 11.5 deg: 10.6 mGal RMS against truth with exit 0 before).
PASSES_FAILED_RAD = math.radians(0.5)
#: ... and above this (0.05 deg) a warning: the estimate still carries some of the linearisation's
#: error (one pass with 0.047 deg/h over 92 min, 0.07 deg: 1.2 mGal; a heading 1 deg off: 0.5).
PASSES_WARN_RAD = math.radians(0.05)
#: Three passes whose gyro-bias corrections on an axis have one sign, each at least this times
#: the one before, show that taking them off did not reduce them: the iteration does not
#: converge there, and each further pass moves the linearisation further off. The passes then
#: stop and the estimate is the first of the three (full unseen U1103, strapdown in strong
#: turbulence with the default 1e-3 m/s^2 accelerometer noise: the roll gyro's correction
#: 0.011, 0.013, 0.018, 0.023, 0.030 deg/h over five passes, the true bias -0.029; 3.13 mGal
#: after one pass, 3.43 / 4.08 / 5.00 / 6.28 after two to five; with the datasheet's 2e-4 they
#: converge; measured before the measurement model's offset term of 2026-12-06, whose absence
#: sent such passes off). :func:`diverging_gyro_axis`.
PASSES_GROWTH_RATIO = 1.0
#: ... counted on the two tilting gyros (triad x and y) only, and where the tilt the last
#: two corrections build over the record exceeds this (rad, 0.01 deg): a heading gyro's
#: correction on straight lines wanders unobserved (quick U010: 0.066 then 0.123 deg/h,
#: harmless), and 0.0025 deg/h over 40 min (0.002 deg; quick U014) changes nothing worth a pass.
PASSES_GROWTH_TILT_RAD = math.radians(0.01)

#: White noise of the horizontal accelerometers (one-second sigma, m/s^2) tried after the
#: default's on a strapdown flight, in this order (:func:`choose_accel_noise`).  Only quieter
#: ones: adopted when in turbulence the default 1e-3 settled on wrong gyro biases (quick U1617:
#: heading gyro -0.38 deg/h for +0.04 drawn, 3.68 mGal; 1.26 mGal with 2.5e-4), which was the
#: measurement model's missing offset term (2026-12-06; docs/benchmarks.md, "Fixes between the
#: filter's epochs"); since, the likelihood finds a quiet IMU's figure, and on the 93 strapdown
#: quick flights the choice still pays on net (without it 9 worse by over 5 %, 5 better: quick
#: U1652 +37 %, U1602 +35 %, U016 +18 %; U1726 -27 %).  A noisier candidate (2e-3) was the most
#: likely on some flights and lost there (quick U001 0.58 -> 0.83 mGal; docs/benchmarks.md,
#: "Accelerometer noise by likelihood").
ACCEL_NOISE_CANDIDATES_MPS2 = (5.0e-4, 2.5e-4)
#: A candidate replaces the one before it only when its likelihood is this many standard errors
#: higher (:func:`gravsurvey.inm.kalman.likelihood_gain_z`): small differences in the total
#: log-likelihood go either way (quick U1659: +3.2, 0.30 standard errors, 1.21 -> 1.73 x the
#: bound; docs/benchmarks.md, "Accelerometer noise by likelihood").
ACCEL_NOISE_GAIN_Z = 2.0


#: Gyro white drifts (one-second sigma, deg/h) tried above the default's on a GNSS-aided flight,
#: in this order (:func:`choose_gyro_noise`): a navigation-grade ring-laser gyro (angle random
#: walk ~0.002 deg/sqrt(h)), a fibre-optic one (~0.01-0.02), a tactical one (~0.1-0.2).  With
#: the default 0.01 deg/h a fibre-optic IMU's gyros (0.72 deg/h) cost quick U007 0.61 -> 1.32
#: mGal and a tactical one's (6 deg/h) up to 30x (docs/benchmarks.md, "A tactical-grade IMU").
GYRO_NOISE_CANDIDATES_DEGPH = (0.1, 1.0, 10.0)
#: The screen: one pass about the default estimate's last linearisation with the first
#: candidate; only a likelihood gain above this many standard errors runs the candidates'
#: whole estimates (on the suite's navigation-grade draws the screen stays below it but on one
#: of 13 strapdown flights, quick U006, 16, and 3 of 92 platform flights; fibre-optic gyros
#: give 12-33, tactical 14-47).
GYRO_SCREEN_Z = 10.0
#: A gyro candidate replaces the one before it when its whole estimate is this many standard
#: errors more likely (as :data:`ACCEL_NOISE_GAIN_Z`).
GYRO_NOISE_GAIN_Z = 2.0
#: A gyro noise chosen within this factor of what the field's horizontal components ask of the
#: attitude (:func:`~gravsurvey.inm.identify.field_attitude_noise_degph`: one step of the
#: candidates' decades) may be the field's, not the gyros': the warning names both.  Of 180
#: simulated flights with navigation-grade gyros 16 took a noisier one, 14 within 0.3-6.3 times
#: that figure (fields of 61-100 mGal but one), full U014 10.9 and quick U006 49; of 51 with
#: fibre-optic or tactical gyros 49 took 10.8-8300 times it (fibre-optic U006 4.9, U012 0.2).
FIELD_GYRO_FACTOR = 10.0
#: A gyro candidate's bias prior per its white drift (deg/h per deg/h one-second sigma): a
#: datasheet's in-run bias is about a tenth of it or less (a tactical IMU's 0.75 deg/h for 6, a
#: fibre-optic one's 0.05 for 0.7).
GYRO_BIAS_PER_WHITE = 0.1


def _likelihood_search(
    first, params: InmParams, key: str, candidates, gain_z: float, estimate, companion=None, every=False
):
    """The whole estimate with ``params.<key>`` set to each of ``candidates`` in turn, each
    replacing the one before while more likely by ``gain_z`` standard errors
    (:func:`gravsurvey.inm.kalman.likelihood_gain_z`); the search stops at the first that is not,
    or that fails (a GravsurveyError or a numerical failure: a candidate that cannot be estimated
    is no reason to fail a flight the default estimated; reported, its warnings not shown).
    With ``every``, each candidate is tried against the best so far (the likelihood need not
    rise step by step: one candidate's prior chosen on its own estimate can make it as likely
    as the next while the one after is far more likely).

    Returns ``(value, (sol, shown), log_likelihoods, gains, failed)``: the value kept, its
    estimate and warnings, and per value tried (keys ``f"{v:.3g}"``) the total log-likelihood,
    the gain over the one before (None where not finite) and a failure's first line.
    """
    value, best, shown = float(getattr(params, key)), *first
    lls = {f"{value:.3g}": float(best.log_likelihood)}
    gains, failed = {}, {}
    for v in candidates:
        try:
            other, caught = recorded(
                estimate, dataclasses.replace(params, **{key: v}, **(companion(v) if companion else {})), False
            )
        except (GravsurveyError, np.linalg.LinAlgError, FloatingPointError) as exc:
            failed[f"{v:.3g}"] = str(exc).splitlines()[0]
            if every:
                continue
            break
        z = likelihood_gain_z(other.log_likelihood_epochs, best.log_likelihood_epochs)
        lls[f"{v:.3g}"] = float(other.log_likelihood)
        gains[f"{v:.3g}"] = z if math.isfinite(z) else None
        if z > gain_z:
            value, best, shown = v, other, caught
        elif not every:
            break
    return value, (best, shown), lls, gains, failed


def may_choose_gyro_noise(params: InmParams, triad: str) -> bool:
    """Whether :func:`estimate_anomaly` may choose the gyros' white drift: identification on and
    ``model.gyro_drift_degph`` not given in the config, on either triad (a platform's gyros are
    integrated as a strapdown triad's; docs/benchmarks.md, "Following passes, and the gyro noise
    searched on platforms").  ``triad`` is taken for the same call as
    :func:`may_choose_accel_noise`'s."""
    return bool(params.identify) and "gyro_drift_degph" not in getattr(params, "given", ())


def choose_gyro_noise(first, params: InmParams, estimate):
    """The estimate with the default or a noisier gyro white drift, whichever the filter's
    likelihood clearly prefers, when the screen asks for it.

    ``first[0].gyro_screen_z`` (one pass with the first of :data:`GYRO_NOISE_CANDIDATES_DEGPH`
    about the default estimate's linearisation) above :data:`GYRO_SCREEN_Z` runs the whole
    estimate with each candidate in turn, each kept where more likely than the best before it by
    :data:`GYRO_NOISE_GAIN_Z` standard errors; unlike :func:`choose_accel_noise` every candidate
    is tried (quick tactical U2004: 0.1 deg/h with the prior chosen on its own estimate as
    likely as 1, 10 far more likely than either; 0.50 mGal with 10, 2.99 stopped at 0.1).  A candidate
    carries the bias prior of its grade (:data:`GYRO_BIAS_PER_WHITE`) where the config gives none.

    Returns
    -------
    (sol, shown) : the estimate chosen and its warnings
    params : InmParams
        ``params`` with the gyro drift chosen (and its bias prior).
    report : dict
        ``value``, ``how``, ``screen_z``, each candidate's ``log_likelihood`` and ``gain_z``
        (and ``failed``; ``gyro_bias_sigma_degph`` where a candidate's bias prior was taken):
        summary.json's ``identification.gyro_drift_degph``.
    """
    screen = float(first[0].gyro_screen_z)
    asked = math.isfinite(screen) and screen > GYRO_SCREEN_Z
    value, (best, shown), lls, gains, failed = _likelihood_search(
        first,
        params,
        "gyro_drift_degph",
        [v for v in GYRO_NOISE_CANDIDATES_DEGPH if asked and v > float(params.gyro_drift_degph)],
        GYRO_NOISE_GAIN_Z,
        estimate,
        companion=lambda v: _gyro_bias_companion(params, v),
        every=True,
    )
    kept = value == float(params.gyro_drift_degph)
    report = {
        "value": value,
        "sigma_factor": None,
        "how": (
            "default (a noisier gyro not clearly more likely)"
            if kept
            else "filter likelihood (a noisier gyro clearly more likely)"
        ),
        "screen_z": screen if math.isfinite(screen) else None,
        "log_likelihood": lls,
        "gain_z": gains,
    }
    if failed:
        report["failed"] = failed
    chosen = {} if kept else _gyro_bias_companion(params, value)
    if chosen:
        report["gyro_bias_sigma_degph"] = chosen["gyro_bias_sigma_degph"]
    return (best, shown), dataclasses.replace(params, gyro_drift_degph=value, **chosen), report


def _gyro_bias_companion(params: InmParams, white_degph: float) -> dict:
    """The gyro-bias prior of a gyro of white drift ``white_degph``: :data:`GYRO_BIAS_PER_WHITE`
    times it, never below the configured or default prior, unless the config gives one."""
    if "gyro_bias_sigma_degph" in getattr(params, "given", ()):
        return {}
    return {"gyro_bias_sigma_degph": max(float(params.gyro_bias_sigma_degph), GYRO_BIAS_PER_WHITE * float(white_degph))}


def may_choose_accel_noise(params: InmParams, triad: str) -> bool:
    """Whether :func:`estimate_anomaly` may choose the horizontal accelerometers' noise, before
    any estimate: a strapdown triad, identification on and ``model.accel_noise_mps2`` not given
    in the config."""
    return triad == "strapdown" and bool(params.identify) and "accel_noise_mps2" not in getattr(params, "given", ())


def chooses_accel_noise(params: InmParams, triad: str, sol) -> bool:
    """... and whether it does, after the estimate with the default: GNSS-aided, its last pass
    with a finite likelihood."""
    return may_choose_accel_noise(params, triad) and bool(sol.gnss_aided) and math.isfinite(sol.log_likelihood)


def recorded(estimate, params, show_on_failure: bool = True):
    """``(estimate(params), warnings it raised)``, the warnings not shown.  An estimate that fails
    (DataError) shows its warnings before the error goes on (they often name its cause), unless
    ``show_on_failure`` is false."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            return estimate(params), list(caught)
        except DataError as exc:
            error = exc
    # shown once the recording has ended, or they would be recorded again
    if show_on_failure:
        show_warnings(caught)
    raise error


def show_warnings(caught) -> None:
    """Show warnings recorded earlier (``warnings.WarningMessage``), each as first raised."""
    for w in caught:
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)


def choose_accel_noise(first, params: InmParams, estimate):
    """The estimate with the default or a quieter accelerometer noise, whichever the filter's
    likelihood clearly prefers.

    The horizontal accelerometers' white noise sets how much of the GNSS track the filter
    leaves to them rather than to attitude and gyro bias.  Each candidate of
    :data:`ACCEL_NOISE_CANDIDATES_MPS2` below ``params.accel_noise_mps2`` runs the whole
    estimate (its own passes converge about its own linearisation: compared about the
    default's, the default is always the more likely, since its passes settled there; what
    does not depend on the noise, the first mechanization, the height checks on it and the
    identification's spectral fits, ``estimate`` may share with the default's), and the
    estimates compare by their last pass's log-likelihood of the same measurements
    (:func:`gravsurvey.inm.kalman.log_likelihood`).  A candidate replaces the estimate before it
    only when more likely by :data:`ACCEL_NOISE_GAIN_Z` standard errors
    (:func:`gravsurvey.inm.kalman.likelihood_gain_z`); the search stops at the first that is
    not, or that fails (a GravsurveyError or a numerical failure; reported, its warnings not
    shown).

    Parameters
    ----------
    first : (InmSolution, list)
        The estimate with ``params`` and the warnings it raised (:func:`recorded`).
    params : InmParams
    estimate : callable
        ``estimate(params) -> InmSolution``: the whole estimate with other settings.

    Returns
    -------
    sol : InmSolution
        The one chosen; its ``identification["accel_noise_mps2"]`` says the value, how it was
        found, each candidate's log-likelihood and its gain in standard errors over the one
        before (``gain_z``).
    shown : list
        Its warnings (``warnings.WarningMessage``), to be shown.
    """
    value, (best, shown), lls, gains, failed = _likelihood_search(
        first,
        params,
        "accel_noise_mps2",
        [v for v in ACCEL_NOISE_CANDIDATES_MPS2 if v < float(params.accel_noise_mps2)],
        ACCEL_NOISE_GAIN_Z,
        estimate,
    )
    report = {
        "value": value,
        "sigma_factor": None,
        "how": (
            "default (no quieter candidate clearly more likely)"
            if value == float(params.accel_noise_mps2)
            else "filter likelihood (a quieter candidate clearly more likely; strapdown)"
        ),
        "log_likelihood": lls,
        "gain_z": gains,
    }
    if failed:
        report["failed"] = failed
    best.identification = {**best.identification, "accel_noise_mps2": report}
    return best, shown


def estimate_anomaly(
    record,
    params: InmParams,
    initial: InitialState | None,
    triad: str,
    ellipsoid: Ellipsoid = WGS84,
    attitude_deg=None,
    reference: bool = False,
    gnss_lever_arm_t=None,
) -> InmSolution:
    """Estimate the gravity disturbance along a flight (3D-INM + Kalman + RTS).

    A GNSS-aided flight runs up to ``params.attitude_passes`` passes: after each, the initial
    attitude is corrected by the smoothed attitude error at the first epoch
    (``C_true = C Exp(theta)``), the smoothed gyro bias is taken off the angular rates, and the
    flight is mechanized and filtered again about that.  The prior is kept (the alignment's,
    zero-mean bias about the raw rates): its mean becomes the old attitude and bias seen from
    the new point (:func:`gravsurvey.inm.errormodel.initial_mean`), an iterated
    (Gauss-Newton) smoother.
    With a datasheet accelerometer bias (``params.accel_bias_mps2``) the filter carries the
    horizontal accelerometer biases as states on either triad, and on a strapdown one after
    each pass their smoothed value comes off the specific force the same way (prior mean
    shifted to match; the model identified again when it moved by more than
    :data:`REIDENTIFY_ACCEL_BIAS_MPS2`).
    With ``params.horizontal`` (and GNSS) one more pass follows about the last linearisation
    point with the 18-state model (horizontal disturbance and accelerometer biases; its prior
    from the vertical estimate, :func:`gravsurvey.inm.identify.horizontal_prior`), and the
    solution is that pass's (``dg_horizontal``, ``dg_horizontal_sigma``,
    ``horizontal_observable``).

    Parameters
    ----------
    record : FlightRecord
    params : InmParams
    initial : InitialState or None
        State at the first IMU sample; None: from GNSS (:func:`initial_state_from_gnss`).
    triad : {"platform", "strapdown"}
    ellipsoid : Ellipsoid
    attitude_deg : sequence of 3 floats, optional
        Roll, pitch, heading for a strapdown triad initialised from GNSS.
    reference : bool
        Use the pure-numpy reference kernels (slow; tests).
    gnss_lever_arm_t : ndarray (3,), optional
        GNSS antenna position from the IMU on the aircraft's axes (FLU: a strapdown triad's; on
        a platform the aircraft's attitude comes from the track,
        :func:`gnssqc.track_attitude`), m. None: found from the aided track
        (:func:`gnssqc.estimate_gnss_lever_arm`) and applied when clear.

    Returns
    -------
    InmSolution

    Notes
    -----
    On a GNSS-aided strapdown triad whose ``model.accel_noise_mps2`` is not given (and with
    ``model.identify``), the horizontal accelerometers' white noise is chosen by the filter's
    likelihood: the whole estimate (every pass) runs again with each of
    :data:`ACCEL_NOISE_CANDIDATES_MPS2` below the default while each is clearly more likely than
    the one before (:data:`ACCEL_NOISE_GAIN_Z` standard errors), and the last such is returned
    (:func:`choose_accel_noise`; docs/method.md, "Accelerometer noise by likelihood").  Before
    that, without a given ``model.gyro_drift_degph`` (either triad), the first estimate's last
    linearisation is filtered once more with a noisier gyro (the screen); where its likelihood gain exceeds
    :data:`GYRO_SCREEN_Z` the whole estimate runs with each of :data:`GYRO_NOISE_CANDIDATES_DEGPH`
    in the same way (:func:`choose_gyro_noise`; docs/method.md, "Gyro noise by likelihood"),
    and the accelerometer noise is chosen about the gyro noise chosen.  The
    estimates share the work the noise does not change (:class:`FirstStage`, the spectral
    fits); each is, to the bit, the estimate with its noise given.
    """

    # what the first estimate found that the others reuse (_estimate_once's ``shared``)
    shared = {}

    estimate_at = functools.partial(
        _estimate_once, record, initial=initial, triad=triad, ellipsoid=ellipsoid, attitude_deg=attitude_deg
    )

    def estimate(p, screen=None):
        return estimate_at(
            p,
            reference=reference,
            gnss_lever_arm_t=gnss_lever_arm_t,
            likelihood=True,
            shared=shared,
            gyro_screen_degph=screen,
        )

    params_in = params
    gyro_ok, accel_ok = may_choose_gyro_noise(params, triad), may_choose_accel_noise(params, triad)
    rate_report = None
    if not gyro_ok:
        # a given gyro noise of tactical grade: the faster rate from the start
        faster = tactical_rate_params(params, record)
        if faster is not None:
            rate_report, params = _tactical_rate_report(params, faster, False), faster
    if not (gyro_ok or accel_ok):
        sol = _estimate_once(record, params, initial, triad, ellipsoid, attitude_deg, reference, gnss_lever_arm_t)
        if rate_report is not None:
            sol.identification = {**sol.identification, "filter_rate_hz": rate_report}
        return sol
    # the warnings of an estimate are shown only for the one returned
    first = recorded(functools.partial(estimate, screen=GYRO_NOISE_CANDIDATES_DEGPH[0] if gyro_ok else None), params)
    gyro_report = None
    if gyro_ok and first[0].gnss_aided and math.isfinite(first[0].log_likelihood):
        first, params, gyro_report = choose_gyro_noise(first, params, estimate)
        faster = tactical_rate_params(params, record)
        if faster is not None:
            # a tactical-grade gyro noise chosen (at the configured rate, its candidates'
            # likelihoods compared there): the estimate with it runs again at the faster rate,
            # and the accelerometer noises are tried at that rate
            rate_report, params = _tactical_rate_report(params, faster, True), faster
            first = recorded(estimate, params)
    sol, shown = (
        choose_accel_noise(first, params, estimate)
        if accel_ok and chooses_accel_noise(params, triad, first[0])
        else first
    )
    if rate_report is not None:
        sol.identification = {**sol.identification, "filter_rate_hz": rate_report}
    if gyro_report is not None:
        sol.identification = {**sol.identification, "gyro_drift_degph": gyro_report}
        model = sol.identification.get("spectral_model") or {}
        field_q = field_attitude_noise_degph(model.get("anomaly_sigma_mps2"), model.get("anomaly_tau_s"))
        gyro_report["field_attitude_noise_degph"] = field_q
        if gyro_report["value"] != float(params_in.gyro_drift_degph):
            warn = gyro_noise_warning(gyro_report["value"], float(params_in.gyro_drift_degph), field_q, model)
            sol.identification["warnings"] = [*sol.identification.get("warnings", []), warn]
            sol.warnings = [*sol.warnings, warn]
    show_warnings(shown)
    return sol


def gyro_noise_warning(chosen_degph: float, default_degph: float, field_q_degph, model: dict) -> str:
    """The warning for a gyro white drift the likelihood took over the default.

    Where the chosen figure is within :data:`FIELD_GYRO_FACTOR` of what the field's horizontal
    components ask of the attitude (``field_q_degph``, from
    :func:`~gravsurvey.inm.identify.field_attitude_noise_degph`), the likelihood cannot tell
    noisier gyros from those components (the scalar model has no states for them), and the
    warning says so; otherwise it says the gyros are noisier.

    Parameters
    ----------
    chosen_degph, default_degph : float
        The white drift taken and the default's, deg/h (one-second sigma).
    field_q_degph : float or None
        The field's figure, deg/h; None where the prior is not known.
    model : dict
        The identification's ``spectral_model`` (its ``anomaly_sigma_mps2``, m/s^2, and
        ``anomaly_tau_s``, s, named).
    """
    prefers = (
        f"the filter's likelihood clearly prefers a white drift of {chosen_degph:g} deg/h (one-second sigma) "
        f"to {default_degph:g}"
    )
    give = "give the datasheet's angle random walk as model.gyro_drift_degph (deg/sqrt(h) x 60)"
    if field_q_degph is None or chosen_degph > FIELD_GYRO_FACTOR * field_q_degph:
        return f"the gyros are noisier than the default model's: {prefers}; {give}"
    sigma_mgal = float(model.get("anomaly_sigma_mps2", 0.0)) / MGAL
    tau_s = float(model.get("anomaly_tau_s", 0.0))
    return (
        f"the gyros are noisier than the default model's, or the attitude takes up the field's horizontal "
        f"components (its deflections of the vertical, at the prior's {sigma_mgal:.2g} mGal over {tau_s:.0f} s, "
        f"ask about {field_q_degph:.2g} deg/h of it; the scalar model has no states for them): {prefers}, and the "
        f'estimate uses it either way (docs/method.md, "Gyro noise by likelihood"); {give} to hold it'
    )


def tactical_rate_params(params: InmParams, record) -> InmParams | None:
    """``params`` at the rate a flight with tactical-grade gyros runs at, or None where it stays.

    A flight whose gyro white drift (``params.gyro_drift_degph``, given or chosen by likelihood)
    is :data:`TACTICAL_GYRO_DEGPH` or more runs with :data:`TACTICAL_RATE_HZ` filter epochs per second
    (at most :data:`TACTICAL_MAX_EPOCHS` over the record), where the config does not give
    ``model.filter_rate_hz`` and its rate is below that.  The error model holds each epoch's
    geometry for the whole step; with a tactical IMU's tilts of mrad, wandering by the second, a
    1-s step leaves errors the disturbance takes up (docs/method.md, "Following passes").
    """
    if "filter_rate_hz" in params.given or float(params.gyro_drift_degph) < TACTICAL_GYRO_DEGPH:
        return None
    t = np.asarray(record.imu.time, float)
    span = float(t[-1] - t[0]) if t.size > 1 else 0.0
    rate = TACTICAL_RATE_HZ if span <= 0.0 else min(TACTICAL_RATE_HZ, TACTICAL_MAX_EPOCHS / span)
    if not rate > float(params.filter_rate_hz):
        return None
    return dataclasses.replace(params, filter_rate_hz=rate)


def _tactical_rate_report(params, faster, chosen: bool) -> dict:
    """summary.json's ``identification.filter_rate_hz`` where :func:`tactical_rate_params` raised
    it; ``chosen``: the gyro noise was the likelihood's choice, not the config's."""
    how = "chosen by the filter's likelihood" if chosen else "given"
    return {
        "value": float(faster.filter_rate_hz),
        "how": (
            f"raised from {params.filter_rate_hz:g} Hz for tactical-grade gyros: a white drift of "
            f"{params.gyro_drift_degph:g} deg/h ({how}; {TACTICAL_GYRO_DEGPH:g} or more)"
        ),
    }


@dataclass(frozen=True)
class FirstStage:
    """The first mechanization of a flight and the height channels' checks on it
    (:func:`first_stage`): what every accelerometer noise :func:`estimate_anomaly` tries
    starts from.

    ``record``: the record with its height channels repaired (and the altimeter moved onto
    the GNSS heights where those are weighed); ``nav``: its mechanization about the initial
    state; ``speed_mps``: the flight's typical speed; ``gnss_up``: the GNSS heights' noise
    report (or None); ``gnss_vertical_sigma_m``: their noise where they are weighed by it
    (m; None: the configured figure stays); ``height_warnings``, ``height_facts``: the
    repairs' warnings and report; ``caught``: the warnings raised meanwhile
    (``warnings.WarningMessage``), shown by each estimate that uses the stage.
    """

    record: FlightRecord
    nav: Navigation
    speed_mps: float
    gnss_up: dict | None
    gnss_vertical_sigma_m: float | None
    height_warnings: tuple
    height_facts: dict
    caught: tuple


def first_stage(
    record, params, initial, ellipsoid, reference, gnss_heights, lever_arm_t=None, triad="strapdown"
) -> FirstStage:
    """The first mechanization about ``initial`` and the height channels' faults found and
    repaired against it (:class:`FirstStage`).  ``params``: the configuration's (its
    accelerometer noise is not read); ``gnss_heights``: the height channel is the GNSS's own
    heights; ``lever_arm_t`` (FLU, m): the antenna's offset from the IMU, where known (those
    heights are then checked at the IMU and kept at the antenna); ``triad``: whose attitude
    turns it (a platform's aircraft's from the track)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        nav = _mechanize(record, params, initial, ellipsoid, reference)
        dh = None
        if gnss_heights and _has_arm(lever_arm_t):
            # the antenna's swing in a turn is no step, nor a noisy stretch, of the heights
            body = _body_attitude(nav, ellipsoid) if triad == "platform" else None
            dh = antenna_offset_enu(nav, lever_arm_t, body, np.asarray(record.altimeter.time, float), ellipsoid)[:, 2]
            record = _heights_raised(record, -dh)
        # the height channel's spikes, frozen stretches, steps and latency, found against
        # this first mechanization, repaired before anything reads the heights (and the
        # flight mechanized again: the gravity model's radius may come from them)
        record, height_warnings, height_facts = _repaired_heights(record, nav, ellipsoid)
        if dh is not None:
            # back at the antenna, sample by sample, where each pass moves them from
            record = _heights_raised(record, dh)
        if not gnss_heights:
            # the GNSS heights enter as the position's up component: their steps (a float
            # stretch, a new ambiguity fix) read as gravity as the altimeter's would
            record, gnss_height_warnings, gnss_height_facts = _repaired_gnss_heights(record, nav, ellipsoid)
            height_warnings = height_warnings + gnss_height_warnings
            if gnss_height_facts:
                height_facts = {**height_facts, "gnss": gnss_height_facts}
        gnss_up, sigma = None, None
        if not gnss_heights and params.identify and "gnss_vertical_sigma_m" not in params.given:
            weighed = _gnss_height_sigma(record, nav, ellipsoid)
            if weighed is not None and weighed[1] is not None:
                # GNSS heights quieter than the altimeter's: weighed by their own noise, not
                # the default figure (every pass, the identification's first pass too), the
                # altimeter moved onto them (two channels metres apart, both weighed, made
                # the estimate jump at every gap of one of them: 64 mGal)
                gnss_up, record = weighed
                sigma = gnss_up["value"]
            elif weighed is not None:
                # quieter but wandering: reported, not weighed
                gnss_up = weighed[0]
        if height_warnings or (gnss_up is not None and gnss_up["value"] is not None):
            nav = _mechanize(record, params, initial, ellipsoid, reference)
        speed = _typical_speed(record, nav, ellipsoid)
    return FirstStage(record, nav, speed, gnss_up, sigma, tuple(height_warnings), height_facts, tuple(caught))


def _estimate_once(
    record,
    params,
    initial,
    triad,
    ellipsoid,
    attitude_deg,
    reference,
    gnss_lever_arm_t,
    likelihood=False,
    shared=None,
    gyro_screen_degph=None,
) -> InmSolution:
    """:func:`estimate_anomaly` with the model's accelerometer noise as it is (same arguments);
    ``likelihood``: also the last pass's log-likelihood (``InmSolution.log_likelihood``);
    ``gyro_screen_degph``: with ``likelihood``, one more pass about the last one's
    linearisation with this gyro white drift, its likelihood gain over the last pass in
    standard errors in ``InmSolution.gyro_screen_z`` (:func:`choose_gyro_noise`);
    ``shared``: a dict shared by the estimates of one flight, holding (key ``"stage"``) the
    :class:`FirstStage` the first of them found and (key ``"fits"``) the identification's
    spectral fits (:func:`gravsurvey.inm.identify.identify_params`'s ``memo``)."""
    if triad not in TRIADS:
        raise ConfigError(f"triad: expected 'platform' or 'strapdown', got {triad!r}")
    _check_record(record)
    if initial is None:
        initial = initial_state_from_gnss(record, triad, attitude_deg, params=params, ellipsoid=ellipsoid)
    # the state the passes mechanize from (position, velocity and attitude corrected after each)
    cur = dataclasses.replace(initial, vel_n=np.asarray(initial.vel_n, float), mat_nt=np.array(initial.mat_nt, float))
    theta_prior = np.zeros(3)  # the prior attitude seen from the current linearisation point
    # the prior position and velocity errors seen from the current point, inertial axes (m, m/s)
    dr_prior_i, dv_prior_i = np.zeros(3), np.zeros(3)
    pv_corrections = []
    gyro_bias_t = np.zeros(3)  # the gyro bias taken off the rates before mechanizing, rad/s
    corrections = []
    passes = int(params.attitude_passes)
    ident = {}
    given_params, reidentify = params, True
    accel_bias = accel_bias_states_for(params, triad)
    # a datasheet accelerometer bias given on a strapdown triad: the estimated bias comes off the
    # specific force between passes (as the gyro bias comes off the rates); m/s^2 on triad axes 1
    # and 2.  Not on a platform: measured there, it helps most flights with a tactical bias but
    # wrecks some whose first-pass bias estimate is wrong (quick U018 0.32 -> 1.21 mGal as drawn;
    # docs/benchmarks.md, "Accelerometer bias taken off between passes").  A tactical-grade bias
    # a pass finds (_found_accel_bias) is taken off on either triad: on 144 runs of navigation-grade
    # platform draws at most 7.9e-4 was found
    take_off_accel_bias = params.accel_bias_mps2 is not None and triad == "strapdown"
    accel_bias_t = np.zeros(2)
    found_accel_bias = None  # a tactical-grade bias a pass found (_found_accel_bias)
    vertical_offset = 0.0  # the constant disturbance taken off the specific force, m/s^2
    height_warnings, height_facts = [], {}
    gnss_latency = None  # a GnssLatency once the first aided pass has measured it
    # an antenna offset not given: measured on the aided track and applied; up to
    # LEVER_FITS fits, each finding what the smoothed track took up of the last step
    lever_open = gnss_lever_arm_t is None
    lever_fits, lever_steps = [], []
    # a height channel that is the GNSS's own heights enters once, not again as GNSS's up
    gnss_heights = _heights_are_gnss(record)
    # what a straight line across an IMU gap or a clipped stretch misses: a property of the
    # record's own specific force, found once (constant biases taken off later leave it as is)
    gap_sigma = missed_accel_sigma(np.asarray(record.imu.time, float), record.imu.specific_force_t)
    # the linearisation each pass ran about, and each pass's gyro-bias correction and sigma
    # (rad/s): corrections that keep growing send the passes back to where they began to
    befores, found = [], []
    reverted = None
    limit = passes
    k = -1
    while k + 1 < limit:
        k += 1
        if k == 0 and gnss_latency is None:
            # the first mechanization and the height channels' checks on it: the same for every
            # accelerometer noise tried, so found once and shared
            stage_input = record
            if shared is None or "stage" not in shared:
                stage = first_stage(
                    record, given_params, cur, ellipsoid, reference, gnss_heights, gnss_lever_arm_t, triad
                )
                if shared is not None:
                    shared["stage"] = stage
            else:
                stage = shared["stage"]
            show_warnings(stage.caught)
            record, nav, speed0, gnss_up = stage.record, stage.nav, stage.speed_mps, stage.gnss_up
            height_warnings, height_facts = list(stage.height_warnings), dict(stage.height_facts)
            if stage.gnss_vertical_sigma_m is not None:
                given_params = dataclasses.replace(given_params, gnss_vertical_sigma_m=stage.gnss_vertical_sigma_m)
                params = dataclasses.replace(params, gnss_vertical_sigma_m=stage.gnss_vertical_sigma_m)
        else:
            nav = _mechanize(record, params, cur, ellipsoid, reference, gyro_bias_t)

        def bind(record, nav):
            # a platform's triad is levelled: an antenna offset turns with the aircraft, whose
            # attitude comes from the track
            body_i = (
                _body_attitude(nav, ellipsoid)
                if triad == "platform" and (lever_open or _has_arm(gnss_lever_arm_t))
                else None
            )
            # heights that are the GNSS's are the antenna's: moved to the IMU for the filter and
            # the identification (the arm swings with the attitude on the lines too)
            pass_record = record
            if gnss_heights and _has_arm(gnss_lever_arm_t):
                pass_record = heights_at_imu(record, nav, gnss_lever_arm_t, body_i, ellipsoid)
            # every pass about this linearisation point: the navigation, the prior attitude and
            # gyro bias seen from it
            one_pass = functools.partial(
                _one_pass,
                pass_record,
                initial=cur,
                nav=nav,
                ellipsoid=ellipsoid,
                reference=reference,
                theta_prior=theta_prior,
                lever_arm_t=gnss_lever_arm_t,
                body_mat_i=body_i,
                gyro_bias_prior=-gyro_bias_t,
                accel_bias_prior=-accel_bias_t,
                pv_prior_i=(dr_prior_i, dv_prior_i),
                gnss_vertical=not gnss_heights,
                gap_accel_sigma_mps2=gap_sigma,
            )
            return body_i, pass_record, one_pass

        body_i, pass_record, one_pass = bind(record, nav)
        if given_params.identify and reidentify:
            memo = None if shared is None else shared.setdefault("fits", {})
            params, ident = _identify(pass_record, given_params, nav, ellipsoid, speed0, one_pass, accel_bias, memo)
            ident["identified_in_pass"] = k + 1
            reidentify = False
            offset = float(ident.pop("wide_pass_mean_mps2", 0.0))
            if abs(offset) > max(VERTICAL_OFFSET_MIN_MPS2, VERTICAL_OFFSET_PER_PRIOR * params.anomaly_sigma_mps2):
                # the constant the chosen prior cannot hold, off the specific force (added back
                # to the estimate) and the flight mechanized again about it
                record = _vertical_offset_off(record, nav, offset, ellipsoid)
                vertical_offset += offset
                nav = _mechanize(record, params, cur, ellipsoid, reference, gyro_bias_t)
                body_i, pass_record, one_pass = bind(record, nav)
        idx, c, gnss_used, n_state, out = one_pass(params, accel_bias=accel_bias)
        if not gnss_used:
            break
        if gnss_latency is None:
            # late GNSS stamps, measured on this first aided track: taken off, and the pass run
            # again (the model identified again) on the corrected stamps
            arm_c = c if body_i is None else attitude_at(body_i, nav.time[idx])
            gnss_latency = _gnss_latency(record, nav, idx, c, out, ellipsoid, gnss_lever_arm_t, arm_c)
            if gnss_latency.taken_off:
                record = dataclasses.replace(record, gnss=gnss_latency.shift(record.gnss))
                reidentify = True
                k -= 1
                continue
        if lever_open:
            fit = _gnss_lever_arm(record, nav, idx, c, out, ellipsoid, gnss_lever_arm_t, not gnss_heights, body_i)
            step = _lever_arm_step(fit, lever_fits, lever_steps)
            lever_fits.append(fit)
            lever_open = bool(np.any(step != 0.0)) and len(lever_fits) < LEVER_FITS
            if np.any(step != 0.0):
                # the pass run again with the antenna there, the model identified again: the
                # attitude's wander on the lines moved the antenna (a 3-m arm's end 5 cm in a
                # 1-deg pitch), which the identification took for the heights' noise
                lever_steps.append(step)
                gnss_lever_arm_t = step if gnss_lever_arm_t is None else gnss_lever_arm_t + step
                reidentify = True
                if gnss_heights:
                    # heights that are the antenna's checked again at the IMU: its swing in the
                    # turns had looked like steps and noisy stretches
                    stage = first_stage(
                        stage_input, given_params, cur, ellipsoid, reference, gnss_heights, gnss_lever_arm_t, triad
                    )
                    record = stage.record
                    if gnss_latency.taken_off:
                        record = dataclasses.replace(record, gnss=gnss_latency.shift(record.gnss))
                    if vertical_offset != 0.0:
                        record = _vertical_offset_off(record, nav, vertical_offset, ellipsoid)
                    height_warnings, height_facts = list(stage.height_warnings), dict(stage.height_facts)
                k -= 1
                continue
        th0, db, db_sig = _pass_correction(out)
        span_s = float(nav.time[-1] - nav.time[0])
        if not take_off_accel_bias and n_state >= N_STATE_BIAS and k < limit - 1:
            found_bias = _found_accel_bias(out)
            if found_bias is not None:
                # a tactical-grade bias: from here on as if the datasheet had given it
                take_off_accel_bias = True
                found_accel_bias = found_bias
                given_params = dataclasses.replace(given_params, accel_bias_mps2=found_bias["prior_mps2"])
                params = dataclasses.replace(params, accel_bias_mps2=found_bias["prior_mps2"])
        if reverted is None:
            found.append((db, db_sig))
        grew = None if reverted is not None else diverging_gyro_axis(found, span_s)
        if grew is not None:
            # taking the last two corrections off did not reduce them: back to the linearisation
            # the first was applied to, and one pass there is the estimate
            reverted = {
                "axis": grew,
                "pass": k,
                "bias_corrections_degph": [float(d[grew] / RADPS_PER_DEGPH) for d, _ in found[-3:]],
            }
            corrections.append(float(np.linalg.norm(th0)))
            state, vertical_offset = befores[-2]
            (cur, dr_prior_i, dv_prior_i, theta_prior, gyro_bias_t, accel_bias_t, record, params, ident) = state
            limit = k + 2
            reidentify = False
            continue
        if k == limit - 1:
            corrections.append(_check_passes_settled(record, out, span_s, passes, reverted))
            break
        corrections.append(float(np.linalg.norm(th0)))
        dr_i, dv_i = _initial_pv_correction(out, nav, idx, c)
        pv_corrections.append((float(np.linalg.norm(dr_i)), float(np.linalg.norm(dv_i))))
        # a bias correction within its own smoothed sigma (the heading gyro's on straight lines,
        # where it is unobservable) is not one another pass could confirm
        bias_done = np.all(np.abs(db) < np.maximum(GYRO_BIAS_CONVERGED_RADPS, db_sig))
        da = None
        if take_off_accel_bias and n_state >= N_STATE_BIAS:
            da, da_sig = _accel_bias_correction(out)
            bias_done = bias_done and np.all(np.abs(da) < np.maximum(ACCEL_BIAS_CONVERGED_MPS2, da_sig))
        pv_done = pv_corrections[-1][0] < POSITION_CONVERGED_M and pv_corrections[-1][1] < VELOCITY_CONVERGED_MPS
        if corrections[-1] < ATTITUDE_CONVERGED_RAD and bias_done and pv_done:
            break
        # the model was identified on a navigation this far off (a given attitude degrees off: tilt
        # leaks the horizontal specific force into the vertical channel): identify it again about
        # the corrected attitude
        reidentify = corrections[-1] > REIDENTIFY_RAD or (
            da is not None and float(np.max(np.abs(da))) > REIDENTIFY_ACCEL_BIAS_MPS2
        )
        # this pass's linearisation, kept for going back (the last two: a record with an
        # accelerometer bias taken off is a copy per pass)
        state = (cur, dr_prior_i, dv_prior_i, theta_prior, gyro_bias_t, accel_bias_t, record, params, ident)
        befores = [*befores[-1:], (state, vertical_offset)]
        # C_true = C Exp(theta) on inertial axes, at the corrected position (whose ENU axes
        # differ from the old point's by the position change over the Earth's radius)
        rot = rodrigues(np.ascontiguousarray(th0))
        cur = _corrected_initial_state(cur, nav, dr_i, dv_i, nav.mat_it[0] @ rot, ellipsoid)
        dr_prior_i, dv_prior_i = dr_prior_i - dr_i, dv_prior_i - dv_i
        # prior attitude (old point) seen from the new point: C_old = C_new Exp(-th0)
        theta_prior = theta_prior - th0
        # the smoothed gyro bias comes off the rates; the bias state is then what remains, its
        # prior (zero mean about the raw rates) seen from the new point has mean -bias taken off
        gyro_bias_t = gyro_bias_t + db
        if da is not None:
            # the same for the accelerometer bias: off the specific force, the state's prior mean
            # (zero about the raw specific force) then minus what was taken off
            accel_bias_t = accel_bias_t + da
            record = _accel_bias_off(record, da)
    follow_kw, follow_tilts = {}, []
    if gnss_used and not params.horizontal:
        free_nav = nav
        nav, idx, out, theta_follow, follow_tilts = _follow_passes(
            record, params, cur, ellipsoid, reference, gyro_bias_t, nav, idx, out, one_pass, accel_bias
        )
        if follow_tilts:
            c = nav.mat_it[idx]
            follow_kw = {"nav": nav, "theta_shift": theta_follow}
            if given_params.identify and ident:
                # the anomaly prior came from a first pass about the free mechanization, whose
                # tilt (over FOLLOW_TILT_RAD) the linear filter mis-models: its errors were read
                # as field.  That pass runs again about the followed attitude and the estimate
                # with what it finds.  The noise levels stay the free mechanization's vertical
                # channel's: the followed one carries the smoothed attitude's epoch-to-epoch
                # steps into the specific force (tactical quick U010: a gravimeter white of
                # 3.4e-4 m/s^2, 4.2 mGal against 1.8; docs/method.md, "Following passes")
                follow_pass = functools.partial(one_pass, **follow_kw)
                memo = None if shared is None else shared.setdefault("fits", {})
                params, ident = _identify(
                    pass_record, given_params, free_nav, ellipsoid, speed0, follow_pass, accel_bias, memo
                )
                # (the record's constant was taken off before: what this pass's mean shows is
                # what that left)
                ident.pop("wide_pass_mean_mps2", None)
                ident["identified_in_pass"] = k + 1 + len(follow_tilts)
                ident["identified_following"] = True
                idx, _, _, _, out = follow_pass(params, accel_bias=accel_bias)
                # only a prior refine_prior chose and that stands (its expected error reported):
                # not a configured sigma or resolution, nor the default prior kept on a short
                # record or standing in for one expecting a useless error (_broad_prior_instead)
                chosen = "expected_error_mgal" in ident and "anomaly_sigma_mps2" not in params.given
                if chosen and params.target_resolution_m is None:
                    params, ident, idx, out = _prior_on_estimate(
                        record, params, ident, free_nav, speed0, idx, out, follow_pass, accel_bias
                    )
    # the last pass's log-likelihood per epoch: the screen's reference and the solution's
    ll_epochs = log_likelihood(out["p_p"], out["innov"], *out["measurements"]) if likelihood else None
    screen_z = float("nan")
    if gyro_screen_degph is not None and likelihood and gnss_used:
        # the same linearisation, a noisier gyro: the innovations say whether the IMU's gyros are
        # of another grade than the default's (a pass, not a whole estimate)
        *_, out_g = one_pass(
            dataclasses.replace(params, gyro_drift_degph=float(gyro_screen_degph)), accel_bias=accel_bias, **follow_kw
        )
        screen_z = likelihood_gain_z(log_likelihood(out_g["p_p"], out_g["innov"], *out_g["measurements"]), ll_epochs)
    hsol = None
    if params.horizontal:
        if gnss_used:
            hsol = _horizontal_pass(record, params, nav, ellipsoid, out["x_s"][:, G], one_pass)
            idx, c, gnss_used, n_state, out, hprior = hsol
        else:
            ident.setdefault("warnings", []).append(
                "model.horizontal: the horizontal disturbance needs GNSS position aiding (model.gnss_aiding and "
                "a GNSS channel); not estimated"
            )
    sol = _solution(record, params, ellipsoid, triad, nav, idx, c, gnss_used, n_state, out, k + 1, corrections)
    if vertical_offset != 0.0:
        # the estimate is of the disturbance less the constant taken off
        sol.g_forward = sol.g_forward + vertical_offset
        sol.g_smooth = sol.g_smooth + vertical_offset
    if ident:
        ident["vertical_offset_mgal"] = vertical_offset / MGAL
    if likelihood:
        if hsol is not None:
            # the horizontal pass's own
            ll_epochs = log_likelihood(out["p_p"], out["innov"], *out["measurements"])
        sol.log_likelihood_epochs = ll_epochs
        sol.log_likelihood = float(np.sum(ll_epochs))
    sol.initial_corrections = pv_corrections
    sol.passes_reverted = reverted
    sol.follow_tilts_rad = follow_tilts
    sol.gyro_screen_z = screen_z
    if hsol is not None:
        missed = float(ident.get("field_sigma_missed_mps2", 0.0))
        sol.dg_horizontal, sol.dg_horizontal_sigma, sol.horizontal_observable = horizontal_outputs(
            out["x_s"], out["p_s"], hprior[0], missed
        )
        ident["horizontal_prior"] = {
            "sigma_mps2": hprior[0],
            "lambda_per_m": hprior[1],
            "observable_fraction": float(np.mean(sol.horizontal_observable)),
            # in the stated sigma of each component beside the smoother's (vector.horizontal_outputs)
            "field_sigma_missed_mps2": missed_field_per_component(missed),
        }
    if gnss_used:
        _, db, sol.gyro_bias_sigma_t = _pass_correction(out)
        sol.gyro_bias_t = gyro_bias_t + db
        if n_state >= N_STATE_BIAS:
            da, sol.accel_bias_sigma_t = _accel_bias_correction(out)
            sol.accel_bias_t = accel_bias_t + da
            sol.accel_bias_taken_off = take_off_accel_bias
    if found_accel_bias is not None:
        ident["accel_bias_found"] = found_accel_bias
        found = "/".join(f"{b:.1e}" for b in found_accel_bias["found_mps2"])
        # a platform's datasheet figure sets the prior only (it is not taken off where given:
        # docs/method.md, "Accelerometer bias"), so only a strapdown triad's user is sent there
        advice = (
            f"as with model.accel_bias_mps2 = {found_accel_bias['prior_mps2']:.1e} (give the datasheet figure there)"
            if triad == "strapdown"
            else f"with a prior of {found_accel_bias['prior_mps2']:.1e} m/s^2"
        )
        ident.setdefault("warnings", []).append(
            f"horizontal accelerometer biases of {found} m/s^2 found, beyond the default prior "
            f"({ACCEL_BIAS_SIGMA_MPS2:.0e} m/s^2: a tactical-grade IMU); taken off between passes {advice}"
        )
    elif params.accel_bias_mps2 is not None:
        ident.setdefault("warnings", []).append(
            "model.accel_bias_mps2: the accelerometer biases need GNSS position aiding (model.gnss_aiding and a "
            "GNSS channel); not estimated"
        )
    sol.alignment = initial.alignment
    sol.params = params
    sol.identification = ident
    if gnss_up is not None:
        ident["gnss_vertical_sigma_m"] = gnss_up
    if height_warnings or height_facts:
        ident["height_faults"] = height_facts
        ident["warnings"] = height_warnings + list(ident.get("warnings", []))
    if gnss_latency is not None and math.isfinite(gnss_latency.latency_s):
        ident["gnss_latency"] = gnss_latency.report()
        if gnss_latency.taken_off:
            ident["warnings"] = [
                f"{record.source_of('gnss')}: gnss: {gnss_latency.text()}, taken off (the aided track's residual "
                'follows the horizontal velocity; docs/method.md, "GNSS latency")'
            ] + list(ident.get("warnings", []))
    if lever_fits:
        ident["gnss_lever_arm"], lever_warning = _lever_arm_report(record, lever_fits, gnss_lever_arm_t, lever_steps)
        if lever_warning:
            ident["warnings"] = [lever_warning] + list(ident.get("warnings", []))
    if gnss_used:
        ident["gnss_vertical_used"] = not gnss_heights
        if gnss_heights and triad == "platform" and gnss_lever_arm_t is not None:
            off = float(np.hypot(*np.asarray(gnss_lever_arm_t, float)[:2]))
            if off >= PLATFORM_ARM_WARN_M:
                ident["warnings"] = list(ident.get("warnings", [])) + [
                    f"{record.source_of('gnss')}: the heights are the GNSS antenna's, {off:.2g} m off the vertical "
                    "through the IMU, on a platform: the aircraft's attitude is known only from its track, so its "
                    f"pitch and roll in turbulence move the antenna's height (1 deg: {100 * off * math.pi / 180:.2g} cm) "
                    "by what the product carries; an antenna above the gravimeter avoids it "
                    '(docs/method.md, "GNSS antenna lever arm")'
                ]
        if gnss_heights:
            ident["notes"] = list(ident.get("notes", [])) + [
                "gnss: the height channel is the GNSS's own heights; they enter once, as the height "
                "measurement (the GNSS position's up component left out)"
            ]
    expected = ident.get("expected_error_mgal")
    if expected is not None and expected > EXPECTED_ERROR_WARN_MGAL:
        ident["warnings"] = list(ident.get("warnings", [])) + [
            f"{record.source or 'record'}: the model identified from this flight expects an error of "
            f"{expected:.3g} mGal in its product (height noise {params.altimeter_sigma_m:.2g} m as the filter "
            f"weighs it): beyond what a survey can use, the field is not resolved; the heights or the "
            'gravimeter are far noisier than a survey\'s (docs/method.md, "Identification")'
        ]
    sol.warnings = sol.warnings + list(ident.get("warnings", []))
    alt_t = np.asarray(record.altimeter.time, float)
    sol.resolution_m = (
        float(ident["resolution_m"])
        if ident.get("resolution_m")
        else model_resolution_m(params, speed0, float(np.median(np.diff(alt_t))) if alt_t.size > 1 else 1.0)
    )
    if gnss_used:
        antenna = None
        if _has_arm(gnss_lever_arm_t):
            antenna = antenna_offset_enu(nav, gnss_lever_arm_t, body_i, np.asarray(record.gnss.time, float), ellipsoid)
        _check_track(record, params, sol, ellipsoid, antenna)
    return sol


#: The corrected track may not leave the GNSS positions by more than this many GNSS sigmas
#: (median distance): beyond it the navigation has diverged (wrong axes, triad or attitude).
TRACK_RESIDUAL_SIGMAS = 20.0


#: The corrected track's systematic departure from the GNSS positions (RMS of the horizontal
#: residual's running means over this span, s) ...
TRACK_SYSTEMATIC_WINDOW_S = 20.0
#: ... beyond this many GNSS sigmas is a warning: the IMU and the GNSS disagree beyond their
#: noise. Measured: 36 simulated flights of the unseen suite and the issue's 0.06-0.25 m; a gyro z scale 1 % off 3.6 m (56 mGal, exit 0
#: before), an accelerometer x scale 5 % off 2.9 m (13.5 mGal).
TRACK_SYSTEMATIC_SIGMAS = 2.0


def _systematic_residual(t, d):
    """RMS of the running means of ``d`` (k, 2) over :data:`TRACK_SYSTEMATIC_WINDOW_S` and RMS of
    the scatter about them, m."""
    cs = np.vstack([np.zeros((1, d.shape[1])), np.cumsum(d, axis=0)])
    lo = np.searchsorted(t, t - 0.5 * TRACK_SYSTEMATIC_WINDOW_S)
    hi = np.searchsorted(t, t + 0.5 * TRACK_SYSTEMATIC_WINDOW_S, side="right")
    m = (cs[hi] - cs[lo]) / (hi - lo)[:, None]
    return float(np.sqrt(np.mean(np.sum(m * m, axis=1)))), float(np.sqrt(np.mean(np.sum((d - m) ** 2, axis=1))))


def _check_track(record, params, sol, ellipsoid, antenna=None):
    """DataError when the corrected navigation leaves the GNSS track (median distance >> GNSS sigma).

    ``antenna``: the antenna's offset from the IMU at the GNSS times, ENU m ``(k, 3)``
    (:func:`antenna_offset_enu`), taken off the residual; None: at the IMU."""

    gn = record.gnss
    tg = np.asarray(gn.time, float)
    ok = (tg >= sol.time[0]) & (tg <= sol.time[-1]) & np.isfinite(gn.lat) & np.isfinite(gn.lon)
    if ok.sum() < 3:
        return
    lat = np.interp(tg[ok], sol.time, sol.lat)
    lon = np.interp(tg[ok], sol.time, np.unwrap(sol.lon))
    de, dn = local_displacement(lat, lon, np.asarray(gn.lat, float)[ok], np.asarray(gn.lon, float)[ok], 0.0, ellipsoid)
    if antenna is not None:
        de, dn = de - antenna[ok, 0], dn - antenna[ok, 1]
    d = np.hypot(de, dn)
    rms = float(np.sqrt(np.mean(d * d)))
    sol.gnss_residual_rms_m = rms
    sys_m, scatter_m = _systematic_residual(tg[ok], np.stack([de, dn], axis=1))
    sol.gnss_residual_systematic_m = sys_m
    limit_sys = TRACK_SYSTEMATIC_SIGMAS * params.gnss_horizontal_sigma_m
    if sys_m > limit_sys and isinstance(getattr(sol, "identification", None), dict):
        sol.identification.setdefault("warnings", []).append(
            f"{record.source_of('gnss')}: the corrected track departs from the GNSS positions systematically by "
            f"{sys_m:.2g} m RMS ({TRACK_SYSTEMATIC_WINDOW_S:g}-s means; {scatter_m:.2g} m of scatter about them), "
            f"beyond {limit_sys:.2g} m ({TRACK_SYSTEMATIC_SIGMAS:g} x model.gnss_horizontal_sigma_m): the IMU and "
            "the GNSS disagree beyond their noise (an IMU scale factor or axis, a clock or lever-arm fault, or "
            "GNSS errors larger than model.gnss_horizontal_sigma_m); the product may carry it"
        )
    # 1 s epochs interpolated between: allow the speed x interpolation error on top of the sigma;
    # the median, so that a few GNSS outliers do not fail a good flight (a diverged one is off
    # almost everywhere)
    med = float(np.median(d))
    limit = TRACK_RESIDUAL_SIGMAS * params.gnss_horizontal_sigma_m + 0.05 * float(np.median(sol.speed))
    if not med <= limit:
        raise DataError(
            f"{record.source or 'record'}: the navigation leaves the GNSS track: corrected positions are "
            f"{med:.3g} m (median; RMS {rms:.3g} m) from the GNSS positions (expected about "
            f"model.gnss_horizontal_sigma_m = {params.gnss_horizontal_sigma_m:g} m); check triad, imu_axes "
            "and the initial attitude"
        )


#: Noise density (per-sample variance x spacing) of the altimeter over the GNSS heights' from
#: which the GNSS's up component is weighed by its own identified noise instead of the default
#: ``gnss_vertical_sigma_m`` (2 m): a survey GNSS beside a barometric-class altimeter was all
#: but unused (2-m altimeter, 0.1-m GNSS on four 25-min simulated flights: 0.45-8.6 mGal ->
#: 0.24-6.9; docs/method.md, "GNSS heights weighed by their own noise").  Below it (the
#: altimeter as good or better, as on every flight of the unseen suites) nothing changes.
GNSS_UP_DENSITY_RATIO = 2.0


def _gnss_height_sigma(record, nav, ellipsoid):
    """The GNSS heights' identified per-sample sigma where their noise density is
    :data:`GNSS_UP_DENSITY_RATIO` times below the altimeter's (both fitted against the inertial
    height, :func:`~gravsurvey.inm.identify.height_noise_density`), as a report entry
    (``value`` m, ``how``, ``altimeter_offset_m``), and the record with the altimeter's heights
    moved onto the GNSS's by their median difference; where such heights wander
    (:data:`~gravsurvey.inm.identify.WALK_MIN_LOG_LR`), an entry with ``value`` None saying so
    and None for the record (not weighed); else None."""
    gn = record.gnss
    if gn is None or len(gn.time) < 16:
        return None
    f_t = record.imu.specific_force_t
    alt = height_noise_density(nav, f_t, record.altimeter.time, record.altimeter.height, ellipsoid)
    gns = height_noise_density(nav, f_t, gn.time, gn.height, ellipsoid)
    if alt is None or gns is None or not alt[0] > GNSS_UP_DENSITY_RATIO * gns[0]:
        return None
    # the wander's fits only for heights that would be weighed (most flights stop above)
    gns = height_noise_density(nav, f_t, gn.time, gn.height, ellipsoid, walk=True)
    if gns[3] >= WALK_MIN_LOG_LR:
        # heights that wander (identify.WALK_MIN_LOG_LR) weighed by their white noise alone made
        # the filter follow the wander as field (a 5-cm, 300-s one on GNSS heights 3x quieter
        # than the altimeter: 1.09 -> 10.1 mGal, docs/benchmarks.md "A slowly varying GNSS
        # height error"): the altimeter leads, the GNSS's up component keeps its default sigma
        return {
            "value": None,
            "sigma_factor": None,
            "how": (
                f"not weighed by its own noise: the GNSS heights ({gns[1]:.3g} m per {gns[2]:.3g}-s sample, "
                f"{alt[0] / gns[0]:.0f}x below the altimeter's noise density) wander (log-likelihood ratio "
                f"{gns[3]:.3g}); the altimeter leads"
            ),
            "height_walk_log_likelihood_ratio": gns[3],
        }, None
    # the altimeter's constant offset from the GNSS heights (the ellipsoidal reference)
    at, ah = _altimeter(record)
    gt, gh = np.asarray(gn.time, float), np.asarray(gn.height, float)
    ok = np.isfinite(gh)
    inside = (at >= gt[ok][0]) & (at <= gt[ok][-1])
    if inside.sum() < 16:
        return None
    offset = float(np.median(np.interp(at[inside], gt[ok], gh[ok]) - ah[inside]))
    moved = dataclasses.replace(record.altimeter, time=at, height=ah + offset, height_sigma_m=_altimeter_sigma(record))
    entry = {
        "value": gns[1],
        "sigma_factor": None,
        "how": (
            f"identified: the GNSS heights {gns[1]:.3g} m per {gns[2]:.3g}-s sample against the inertial height, "
            f"the altimeter's {alt[1]:.3g} m per {alt[2]:.3g} s ({alt[0] / gns[0]:.0f}x the noise density); "
            f"the altimeter's heights moved {offset:+.2f} m onto the GNSS's"
        ),
        "altimeter_offset_m": offset,
    }
    return entry, dataclasses.replace(record, altimeter=moved)


def _repaired_heights(record, nav, ellipsoid):
    """The record with its height channel's spikes and frozen samples dropped, steps taken off
    and stamps moved back by a clear latency (:mod:`gravsurvey.inm.heightqc`), the warnings that
    say so, and the facts for the report (``spikes``, ``frozen``, ``steps``: time s and size m
    each, ``latency_s`` and ``latency_sigma_s``; empty when nothing was found)."""
    alt_t = np.asarray(record.altimeter.time, float)
    alt_h = np.asarray(record.altimeter.height, float)
    inside = np.flatnonzero(np.isfinite(alt_h) & (alt_t >= nav.time[0]) & (alt_t <= nav.time[-1]))
    if inside.size < 16:
        return record, [], {}
    coarse, ratio = coarse_height_offset(nav, alt_t[inside], alt_h[inside], ellipsoid)
    if coarse is not None:
        source = record.source_of("altimeter")
        what = (
            f"{source}: altimeter: the heights match the inertial height {coarse:+.2f} s earlier than their stamps "
            f"(the high-passed residual's variance {ratio:.3g}x smaller)"
        )
        if abs(coarse) > LATENCY_MAX_S:
            raise DataError(
                f"{what}: the height clock is out of step with the IMU's (expected within {LATENCY_MAX_S:g} s); if "
                f"they are known to differ, as GPS time runs 18 s ahead of UTC, give the flight time_offsets_s: "
                f"{{altimeter: {-coarse:+.2f}}}"
            )
        # within LATENCY_MAX_S: taken off first, the regression below refines the rest
        alt_t = alt_t - coarse
        inside = np.flatnonzero(np.isfinite(alt_h) & (alt_t >= nav.time[0]) & (alt_t <= nav.time[-1]))
    t, e = vertical_residual(nav, alt_t[inside], alt_h[inside], ellipsoid)
    # a noisy stretch is weighed by its own noise and left out of the searches (against the
    # quiet rest's sigma it is full of steps: 2 m of noise for 300 s read as 7 steps, 60 mGal)
    own, quiet, faults_q, faults = _faults_outside_noise(t, e, alt_h[inside])
    noisy = np.isfinite(own)
    latency = _height_latency(nav, t[quiet], e[quiet], faults_q) if quiet.size >= 16 else None
    if coarse is not None:
        latency = (
            (coarse + latency[0], *latency[1:]) if latency is not None else (coarse, COARSE_FINE_STEP_S, 0.0, 0.0, 0.0)
        )
        # the drift term is about the already shifted stamps
        if latency[2] != 0.0:
            latency = (latency[0], latency[1], latency[2], latency[3], latency[4] + coarse)
        alt_t = alt_t + coarse  # the shift below is taken from the stamps as recorded
    if not faults and latency is None and not noisy.any():
        return record, [], {}
    fixed = np.array(alt_h, float)
    fixed[inside] = repair_heights(alt_h[inside], faults)
    for start, size in faults.steps:
        # the samples after the checked span follow the last level too
        fixed[inside[-1] + 1 :] -= size
    shifted = alt_t if latency is None else alt_t - (latency[0] + latency[2] * (alt_t - latency[4]))
    sigma = record.altimeter.height_sigma_m
    sigma = np.full(alt_h.size, np.nan) if sigma is None else np.array(sigma, float)
    sigma[inside[noisy]] = np.fmax(sigma[inside[noisy]], own[noisy])
    record = dataclasses.replace(
        record, altimeter=dataclasses.replace(record.altimeter, time=shifted, height=fixed, height_sigma_m=sigma)
    )
    steps = [(float(t[i]), float(size)) for i, size in faults.steps]
    facts = {
        "spikes": int(faults.spikes.size - faults.frozen),
        "frozen": faults.frozen,
        "steps": [{"time_s": a, "size_m": b} for a, b in steps],
    }
    what = _noisy_report(t, own, facts, "sample(s)")
    if latency is not None:
        facts["latency_s"], facts["latency_sigma_s"] = latency[:2]
        drift = ""
        if latency[2] != 0.0:
            facts["drift_ppm"], facts["drift_sigma_ppm"] = latency[2] * 1e6, latency[3] * 1e6
            drift = (
                f" at mid-record, drifting {latency[2] * 1e6:+.0f} ppm (+-{latency[3] * 1e6:.0f}: a clock running "
                f"{'slow' if latency[2] > 0 else 'fast'})"
            )
        what.append(
            f"stamps {latency[0]:+.3f} s (+-{latency[1]:.3f}) late against the IMU{drift}, taken off (the residual "
            "against the inertial height follows the vertical velocity)"
        )
    if faults.spikes.size - faults.frozen:
        what.append(f"{faults.spikes.size - faults.frozen} spike(s) dropped")
    if faults.frozen:
        what.append(f"{faults.frozen} sample(s) of a frozen (repeated) value dropped")
    if steps:
        listed = ", ".join(f"{b:+.2f} m at {a:.0f} s" for a, b in steps)
        what.append(f"{len(steps)} step(s) taken off the heights after them ({listed} after the record's start)")
    source = record.source_of("altimeter")
    return (
        record,
        [
            f"{source}: altimeter.height: {' and '.join(what)}; found against the inertial height "
            '(docs/method.md, "Height spikes, steps and latency")'
        ],
        facts,
    )


def _faults_outside_noise(t, e, heights=None):
    """A height channel's noisy stretches and its faults outside them.

    ``own`` (k,): each sample's own sigma in a noisy stretch, NaN elsewhere
    (:func:`heightqc.noisy_stretches`); ``quiet``: the indices of the other samples;
    ``faults_q``: :func:`heightqc.find_height_faults` on those (indices into ``quiet``);
    ``faults``: the same with indices into ``t``."""
    own = noisy_stretches(t, e)
    quiet = np.flatnonzero(~np.isfinite(own))
    if quiet.size < 16:
        return own, quiet, HeightFaults(), HeightFaults()
    faults_q = find_height_faults(t[quiet], e[quiet], None if heights is None else heights[quiet])
    faults = HeightFaults(
        spikes=quiet[faults_q.spikes].astype(np.int64),
        steps=[(int(quiet[i]), size) for i, size in faults_q.steps],
        frozen=faults_q.frozen,
    )
    return own, quiet, faults_q, faults


def _noisy_report(t, own, facts, what):
    """The warning's words on a height channel's noisy stretches (``own``: each sample's own
    sigma, NaN outside them; :func:`heightqc.noisy_stretches`), with ``noisy_s`` and
    ``noisy_sigma_m`` added to ``facts``; an empty list when there are none."""
    noisy = np.isfinite(own)
    if not noisy.any():
        return []
    facts["noisy_s"] = float(np.sum(np.diff(t)[noisy[1:]]))
    facts["noisy_sigma_m"] = float(np.nanmax(own))
    return [
        f"{int(noisy.sum())} {what} over {facts['noisy_s']:.0f} s noisier than the rest (up to "
        f"{facts['noisy_sigma_m']:.2f} m) weighed by their own noise"
    ]


def _repaired_gnss_heights(record, nav, ellipsoid):
    """The record with its GNSS heights' spikes dropped (the fix) and steps taken off
    (:func:`heightqc.find_height_faults` against the first mechanization's height, as the
    altimeter's) and its noisy stretches given their own sigma (:func:`heightqc.noisy_stretches`),
    the warnings that say so and the facts (``spikes``, ``steps``, ``noisy_s``,
    ``noisy_sigma_m``)."""
    gn = record.gnss
    if gn is None or len(gn.time) == 0:
        return record, [], {}
    gt = np.asarray(gn.time, float)
    gh = np.asarray(gn.height, float)
    inside = np.flatnonzero(np.isfinite(gh) & (gt >= nav.time[0]) & (gt <= nav.time[-1]))
    if inside.size < 16:
        return record, [], {}
    t, e = vertical_residual(nav, gt[inside], gh[inside], ellipsoid)
    # a noisy stretch (a float solution) is weighed by its own noise, and its scatter is not
    # searched for steps: against the quiet rest's sigma it is full of them
    own, _, _, faults = _faults_outside_noise(t, e)
    noisy = np.isfinite(own)
    if not faults and not noisy.any():
        return record, [], {}
    fixed = np.array(gh, float)
    fixed[inside] = repair_heights(gh[inside], faults)
    for _, size in faults.steps:
        fixed[inside[-1] + 1 :] -= size
    sigma = np.full(gh.size, np.nan) if gn.height_sigma_m is None else np.array(gn.height_sigma_m, float)
    sigma[inside[noisy]] = np.fmax(sigma[inside[noisy]], own[noisy])
    drop = ~np.isfinite(fixed) & np.isfinite(gh)
    gnss = dataclasses.replace(
        gn,
        time=gt[~drop],
        lat=np.asarray(gn.lat, float)[~drop],
        lon=np.asarray(gn.lon, float)[~drop],
        height=fixed[~drop],
        height_sigma_m=sigma[~drop],
    )
    record = dataclasses.replace(record, gnss=gnss)
    steps = [(float(t[i]), float(size)) for i, size in faults.steps]
    facts = {"spikes": int(faults.spikes.size), "steps": [{"time_s": a, "size_m": b} for a, b in steps]}
    what = _noisy_report(t, own, facts, "fix(es)")
    if faults.spikes.size:
        what.append(f"{faults.spikes.size} fix(es) with a height spike dropped")
    if steps:
        listed = ", ".join(f"{b:+.2f} m at {a:.0f} s" for a, b in steps)
        what.append(f"{len(steps)} step(s) taken off the heights after them ({listed} after the record's start)")
    return (
        record,
        [
            f"{record.source_of('gnss')}: gnss.height: {' and '.join(what)}; found against the inertial height "
            '(a float stretch or a new ambiguity fix; docs/method.md, "Height spikes, steps and latency")'
        ],
        facts,
    )


def _gnss_latency(record, nav, idx, c, out, ellipsoid, lever_arm_t=None, arm_c=None) -> GnssLatency:
    """How late the GNSS stamps are, constant or drifting, from a pass's smoothed track.

    The corrected navigation (at the antenna, with a lever arm) minus the GNSS positions, east
    and north, regressed on the navigation's velocity (:func:`gnssqc.gnss_latency_fit`).
    """
    err_q, err_p, _ = _triad_errors(out["x_s"], c, nav.r_i[idx], nav.v_i[idx])
    r_corr = nav.r_i[idx] - np.einsum("nij,nj->ni", c, err_q)
    if lever_arm_t is not None:
        r_corr = r_corr + np.einsum("nij,j->ni", c if arm_c is None else arm_c, np.asarray(lever_arm_t, float))
    v_corr = nav.v_i[idx] - np.einsum("nij,nj->ni", c, err_p)
    t_e = nav.time[idx]
    lat, lon, height, vel_n = navigation_to_geodetic(t_e, r_corr, v_corr, ellipsoid)
    gn = record.gnss
    tg = np.asarray(gn.time, float)
    ok = (tg >= t_e[0]) & (tg <= t_e[-1]) & np.isfinite(gn.lat) & np.isfinite(gn.lon)
    if ok.sum() < 32:
        return GnssLatency()
    t = tg[ok]
    la = np.interp(t, t_e, lat)
    lo = np.interp(t, t_e, np.unwrap(lon))
    # the navigation's offset from the fixes, east and north
    res = np.stack(
        local_displacement(np.asarray(gn.lat, float)[ok], np.asarray(gn.lon, float)[ok], la, lo, 0.0, ellipsoid), axis=1
    )
    vel = np.stack([np.interp(t, t_e, vel_n[:, j]) for j in range(2)], axis=1)
    return gnss_latency_fit(t, res, vel)


#: The identification's expected error of the product, mGal, beyond which the prior of least
#: expected error is not trusted (:func:`_broad_prior_instead`) and, where a prior was given,
#: a warning says the field is not resolved: a survey's product is of use at a few mGal, and
#: the unseen suite's flights expect at most 5.4 (140 summaries of 2026-12-06); a platform's
#: GNSS heights from an antenna 2.3 m off the IMU's vertical in strong turbulence expected 124
#: (and had 77).
EXPECTED_ERROR_WARN_MGAL = 20.0
#: Lever-arm fits on one flight at most: the first finds most of the offset, the smoothed
#: track having taken up some (1.76 of 2 m up on the fuzzing flight, 4.2 of 6 m forward on
#: test_alignment.py's), the next ones the rest (:func:`_lever_arm_step`).
LEVER_FITS = 3
#: Horizontal distance of a GNSS antenna from a platform's IMU, m, from which heights that are
#: the antenna's get a warning: the aircraft's pitch and roll, unknown on a platform, move
#: the antenna's height by this times the angle (measured on 20 quick draws with an antenna
#: [3, -1, 1.5] m: platforms up to 3.5x the error of an antenna at the IMU).
PLATFORM_ARM_WARN_M = 0.5
#: Once an offset is applied, a further step is taken at this many standard errors: the flight
#: has an antenna off the IMU, and what is left is the share the track took up.
LEVER_FOLLOW_K = 2.0
#: The share of an offset a fit sees, bounds of its secant estimate.
LEVER_GAIN_RANGE = (0.5, 1.0)


def _gnss_lever_arm(
    record, nav, idx, c, out, ellipsoid, lever_arm_t=None, vertical=True, body_mat_i=None
) -> GnssLeverArm:
    """Where the GNSS antenna is from the IMU (beyond ``lever_arm_t``, already applied), from a
    pass's smoothed track (:func:`gnssqc.estimate_gnss_lever_arm`; ``vertical``: the up
    component too; ``body_mat_i``: the aircraft's attitude where it is not the triad's,
    :func:`_body_attitude`)."""
    err_q, _, _ = _triad_errors(out["x_s"], c, nav.r_i[idx], nav.v_i[idx])
    corr = -np.einsum("nij,nj->ni", c, err_q)
    gn = record.gnss
    te = nav.time[idx]
    ts = np.asarray(gn.time, float)
    lat, lon, hh = (np.asarray(v, float) for v in (gn.lat, gn.lon, gn.height))
    ok = (ts >= te[0]) & (ts <= te[-1]) & np.isfinite(lat) & np.isfinite(lon) & np.isfinite(hh)
    if ok.sum() < 32:
        return GnssLeverArm()
    ts, lat, lon, hh = ts[ok], lat[ok], lon[ok], hh[ok]
    m_ie = mat_ie(ts, ellipsoid.omega)
    r_g = np.einsum("nij,nj->ni", m_ie, geodetic_to_ecef(lat, lon, hh, ellipsoid))
    m_in = np.einsum("nij,njk->nik", m_ie, mat_en(lat, lon))
    # the navigation between its samples and its slow correction between the epochs
    r_c = hermite_position(nav, ts) + np.stack([np.interp(ts, te, corr[:, j]) for j in range(3)], axis=1)
    arm_i = nav.mat_it[nearest_sample(nav.time, ts)] if body_mat_i is None else attitude_at(body_mat_i, ts)
    mat_ut = np.einsum("nji,njk->nik", m_in, arm_i)
    if lever_arm_t is not None:
        r_c = r_c + np.einsum("nij,j->ni", arm_i, np.asarray(lever_arm_t, float))
    res = np.einsum("nji,nj->ni", m_in, r_c - r_g)
    axes = 3 if vertical else 2
    lever, sig = estimate_gnss_lever_arm(ts, res[:, :axes], mat_ut)
    return GnssLeverArm(lever, sig)


#: Rate of the aircraft's attitude from the track, Hz (:func:`_body_attitude`): a bank changes
#: over seconds.
BODY_ATTITUDE_HZ = 10.0


def _has_arm(lever_arm_t) -> bool:
    """Whether an antenna offset (3,) m is given and not zero."""
    return lever_arm_t is not None and bool(np.any(np.asarray(lever_arm_t, float) != 0.0))


def heights_at_imu(record, nav, lever_arm_t, body_mat_i, ellipsoid: Ellipsoid = WGS84):
    """The record with its height channel moved from a GNSS antenna to the IMU.

    Where the height channel is the GNSS's own heights, each is the antenna's: ``lever_arm_t``
    turned by the aircraft's attitude puts it ``dh = u . (C l)`` above the IMU (``u`` the
    ellipsoid's normal), which moves with every bank and pitch: a 3-m arm forward and a 1-deg
    pitch are 5 cm.  The attitude's own error enters as ``l theta`` (0.2 mm for 3 m and 0.003
    deg), so the heights are moved rather than the measurement given the arm.

    Parameters
    ----------
    record : FlightRecord
    nav : Navigation
        The mechanization the heights are moved along (its attitude and position).
    lever_arm_t : ndarray (3,)
        Antenna from the IMU on the aircraft's axes, m (FLU).
    body_mat_i : tuple (ndarray (m,), ndarray (m, 3, 3)) or None
        The aircraft's axes -> inertial where they are not the triad's (a platform;
        :func:`_body_attitude`); None: the triad's (``nav.mat_it``).
    ellipsoid : Ellipsoid

    Returns
    -------
    FlightRecord
        ``altimeter.height`` less ``dh``, m; the rest shared with ``record``.
    """
    dh = antenna_offset_enu(nav, lever_arm_t, body_mat_i, np.asarray(record.altimeter.time, float), ellipsoid)[:, 2]
    return _heights_raised(record, -dh)


def _heights_raised(record, dh):
    """The record with ``dh`` (m, one per height sample) added to its height channel."""
    alt = record.altimeter
    return dataclasses.replace(record, altimeter=dataclasses.replace(alt, height=np.asarray(alt.height, float) + dh))


def antenna_offset_enu(nav, lever_arm_t, body_mat_i, time, ellipsoid: Ellipsoid = WGS84):
    """Where a GNSS antenna is from the IMU on the local east, north, up axes, m, ``(n, 3)``.

    ``C l``: the arm ``lever_arm_t`` (FLU, m) turned by the aircraft's attitude at ``time`` (s;
    the triad's, ``nav.mat_it``, or ``body_mat_i`` where given, as :func:`heights_at_imu`),
    resolved on the ENU axes at the navigation's position (times outside it: at its ends).
    """
    ts = np.clip(np.asarray(time, float), nav.time[0], nav.time[-1])
    mat = nav.mat_it[nearest_sample(nav.time, ts)] if body_mat_i is None else attitude_at(body_mat_i, ts)
    arm_i = np.einsum("nij,j->ni", mat, np.asarray(lever_arm_t, float))
    m_ie = mat_ie(ts, ellipsoid.omega)
    lat, lon, _ = ecef_to_geodetic(np.einsum("nji,nj->ni", m_ie, hermite_position(nav, ts)), ellipsoid)
    m_in = np.einsum("nij,njk->nik", m_ie, mat_en(lat, lon))
    return np.einsum("nji,nj->ni", m_in, arm_i)


def _body_attitude(nav, ellipsoid):
    """The aircraft's axes (FLU) -> inertial from its track (:func:`gnssqc.track_attitude`), at
    :data:`BODY_ATTITUDE_HZ`: ``(time (m,) s, mat (m, 3, 3))`` (:func:`errormodel.attitude_at`)."""
    dt = float(np.median(np.diff(nav.time))) if nav.time.size > 1 else 1.0
    k = np.arange(0, nav.time.size, max(1, int(round(1.0 / (BODY_ATTITUDE_HZ * dt)))))
    t = nav.time[k]
    lat, lon, _, vel_n = navigation_to_geodetic(t, nav.r_i[k], nav.v_i[k], ellipsoid)
    m_in = np.einsum("nij,njk->nik", mat_ie(t, ellipsoid.omega), mat_en(lat, lon))
    return t, np.einsum("nij,njk->nik", m_in, track_attitude(t, vel_n))


def _lever_arm_step(fit, fits, steps) -> np.ndarray:
    """The lever-arm correction to apply after ``fit`` (3,) m, zero where none.

    The first: the components clear of zero (:attr:`gnssqc.GnssLeverArm.clear_t`). After one
    was applied, a fit sees only the share ``g`` of what is left that the smoothed track has not
    taken up; ``g`` per component is ``(f_(k-1) - f_k) / s`` of the two fits either side of the
    last step ``s`` (the secant of a linear map; within :data:`LEVER_GAIN_RANGE`, their median where
    a component had no step), the correction ``f_k / g`` where it is
    :data:`LEVER_FOLLOW_K` standard errors from zero."""
    if not steps:
        return fit.clear_t
    prev, last = np.asarray(fits[-1].lever_t, float), np.asarray(steps[-1], float)
    cur, sig = np.asarray(fit.lever_t, float), np.asarray(fit.sigma_t, float)
    seen = (last != 0.0) & np.isfinite(prev) & np.isfinite(cur)
    gain = np.full(3, np.nan)
    gain[seen] = np.clip((prev[seen] - cur[seen]) / last[seen], *LEVER_GAIN_RANGE)
    gain[~seen] = float(np.median(gain[seen])) if seen.any() else 1.0
    go = np.isfinite(cur) & np.isfinite(sig) & (np.abs(cur) >= LEVER_FOLLOW_K * sig)
    return np.where(go, cur / gain, 0.0)


def _lever_arm_report(record, fits, lever_t, steps=()):
    """summary.json's ``identification.gnss_lever_arm`` and the flight's warning (None when
    nothing was applied) of the lever-arm fits ``fits`` that ended at ``lever_t`` (None: none
    applied)."""
    applied = lever_t is not None
    last = fits[-1]
    # applied: what the fits took off; the last fit's finding beyond it, under the rule, stays
    # in the report (the smoothed track takes up part of each offset it is shown)
    lever = np.asarray(lever_t if applied else last.lever_t, float)
    sig = np.asarray(last.sigma_t, float)
    rep = {
        "lever_arm_flu_m": [float(v) for v in lever],
        "sigma_m": [float(v) for v in sig],
        "applied": applied,
        "remaining_m": [float(v) for v in (last.lever_t if applied and len(steps) < len(fits) else np.zeros(3))],
        "fits": len(fits),
        "how": 'fit of the aided track\'s residual on the attitude (docs/method.md, "GNSS antenna lever arm")',
    }
    src = record.source_of("gnss")
    flu = ", ".join(f"{v:+.2f}" for v in lever)
    if applied:
        return rep, (
            f"{src}: gnss: the antenna is [{flu}] m (forward, left, up; +-{float(np.nanmax(sig)):.2f}) from the IMU, "
            "found from the aided track (gnss_lever_arm_m not given) and applied; give gnss_lever_arm_m to use "
            'a measured one (docs/method.md, "GNSS antenna lever arm")'
        )
    if any(f.too_long for f in fits):
        return rep, (
            f"{src}: gnss: the aided track's residual follows the attitude as an antenna [{flu}] m from the IMU "
            "would, beyond any aircraft's: not applied (an IMU axis, scale factor or triad, or GNSS errors); "
            "the product may carry it"
        )
    return rep, None


def _height_latency(nav, t, e, faults):
    """The height stamps' latency when it is clear and plausible, else None: ``(latency_s,
    sigma_s, rate, rate_sigma, t_mid_s)``, the stamps late by ``latency_s + rate (t - t_mid_s)``.

    Constant (:data:`heightqc.LATENCY_K` standard errors, at least :data:`heightqc.LATENCY_MIN_S`,
    at most :data:`heightqc.LATENCY_MAX_S`; ``rate`` 0) or drifting (a clock running slow or fast:
    the rate as many standard errors from zero, and the latency changing by at least
    :data:`heightqc.LATENCY_DRIFT_MIN_S` between the middle and the ends:
    :func:`heightqc.estimate_latency_drift`); spikes
    left out, steps taken off first."""
    h_e = np.array(e, float)
    for start, size in faults.steps:
        h_e[start:] += size  # e = h_ins - h_alt: a step up of the heights took e down
    keep = np.ones(t.size, bool)
    keep[faults.spikes] = False
    radial = np.einsum("ij,ij->i", nav.r_i, nav.v_i) / np.linalg.norm(nav.r_i, axis=1)
    v = np.interp(t, nav.time, radial)
    tk, ek, vk = t[keep], h_e[keep], v[keep]
    mid, mid_sig, rate, rate_sig = estimate_latency_drift(tk, ek, vk)
    half = 0.5 * float(tk[-1] - tk[0]) if tk.size else 0.0
    if (
        math.isfinite(rate)
        and abs(rate) >= max(LATENCY_K * rate_sig, 0.0)
        and LATENCY_DRIFT_MIN_S <= abs(rate) * half <= LATENCY_MAX_S
        and abs(mid) + abs(rate) * half <= LATENCY_MAX_S
    ):
        return float(mid), float(mid_sig), float(rate), float(rate_sig), 0.5 * float(tk[0] + tk[-1])
    lat, sig = estimate_latency(tk, ek, vk)
    if not (math.isfinite(lat) and abs(lat) >= max(LATENCY_K * sig, LATENCY_MIN_S) and abs(lat) <= LATENCY_MAX_S):
        return None
    return float(lat), float(sig), 0.0, 0.0, 0.0


def _heights_are_gnss(record) -> bool:
    """Whether the record's height channel is its GNSS heights (:func:`gnss_height_fraction`)."""
    gn = record.gnss
    if gn is None or len(gn.time) == 0:
        return False
    alt_t, alt_h = _altimeter(record)
    frac = gnss_height_fraction(alt_t, alt_h, np.asarray(gn.time, float), np.asarray(gn.height, float))
    return frac >= SAME_FRACTION


def _altimeter(record):
    """Finite altimeter samples: times (s) and heights (m)."""
    alt_t = np.asarray(record.altimeter.time, float)
    alt_h = np.asarray(record.altimeter.height, float)
    good = np.isfinite(alt_h)
    if not good.any():
        raise DataError(f"{record.source_of('altimeter')}: altimeter.height: no finite samples")
    return alt_t[good], alt_h[good]


def _altimeter_sigma(record):
    """The finite altimeter samples' own sigmas (m, NaN: the model's), as :func:`_altimeter`
    keeps them; None when there are none."""
    own = record.altimeter.height_sigma_m
    if own is None:
        return None
    return np.asarray(own, float)[np.isfinite(np.asarray(record.altimeter.height, float))]


def _pass_correction(out):
    """The smoothed corrections a pass found at its first epoch: the attitude error (3,) rad,
    the gyro bias (3,) rad/s and the bias's 1-sigma (3,) rad/s (triad axes)."""
    x0 = out["x_s"][0]
    return x0[TH], x0[BG], np.sqrt(np.diagonal(out["p_s"][0])[BG])


def _accel_bias_correction(out):
    """The smoothed biases of accelerometers 1 and 2 a 16- or 18-state pass found at its first
    epoch (2,) m/s^2, and their 1-sigma (2,) m/s^2."""
    return out["x_s"][0][BA], np.sqrt(np.diagonal(out["p_s"][0])[BA])


def _found_accel_bias(out) -> dict | None:
    """A pass's smoothed horizontal accelerometer bias when it is beyond the default prior's
    reach (:data:`ACCEL_BIAS_FOUND_MPS2` on either axis): ``{"found_mps2": (2,), "prior_mps2"}``
    with the prior :data:`ACCEL_BIAS_PRIOR_PER_FOUND` times the larger; None otherwise."""
    bias, _ = _accel_bias_correction(out)
    most = float(np.max(np.abs(bias)))
    if not most > ACCEL_BIAS_FOUND_MPS2:
        return None
    return {"found_mps2": [float(b) for b in bias], "prior_mps2": ACCEL_BIAS_PRIOR_PER_FOUND * most}


def _accel_bias_off(record, bias_t):
    """``record`` with the bias ``bias_t`` (2,) m/s^2 taken off the specific force of triad axes
    1 and 2 (a copy; the caller's record is left as it is)."""
    f_t = np.array(record.imu.specific_force_t, dtype=float)
    f_t[:, :2] -= np.asarray(bias_t, float)[None, :]
    return dataclasses.replace(record, imu=dataclasses.replace(record.imu, specific_force_t=f_t))


def _vertical_offset_off(record, nav, offset_mps2: float, ellipsoid: Ellipsoid = WGS84):
    """``record`` with a constant disturbance ``offset_mps2`` (m/s^2, positive = stronger
    gravity) taken off its specific force: ``f_t - offset n_t``, with ``n_t`` the ellipsoid
    normal on the triad along the navigation ``nav`` (at the IMU samples; a copy, the caller's
    record is left as it is).  The measured specific force holds ``+g Up`` of a disturbance
    ``g`` (:mod:`gravsurvey.inm.errormodel`), so what is left is the disturbance less the
    offset (:data:`VERTICAL_OFFSET_MIN_MPS2`)."""
    t = np.asarray(nav.time, float)
    # the normal turns with the Earth and the track only (1e-4 rad/s): found about once a
    # second and interpolated, not rotated at every IMU sample
    step = max(1, int(round(1.0 / max(float(np.median(np.diff(t))), 1e-6)))) if t.size > 1 else 1
    k = np.unique(np.r_[np.arange(0, t.size, step), t.size - 1])
    lat, lon, _, _ = navigation_to_geodetic(t[k], nav.r_i[k], nav.v_i[k], ellipsoid)
    up_k = np.einsum("nij,nj->ni", mat_ie(t[k], ellipsoid.omega), mat_en(lat, lon)[:, :, 2])
    up_i = np.stack([np.interp(t, t[k], up_k[:, j]) for j in range(3)], axis=1)
    f_t = np.array(record.imu.specific_force_t, dtype=float)
    f_t -= float(offset_mps2) * np.einsum("nji,nj->ni", nav.mat_it, up_i)
    return dataclasses.replace(record, imu=dataclasses.replace(record.imu, specific_force_t=f_t))


def _triad_errors(x_s, c, r_i, v_i):
    """Position and velocity errors on the triad axes of aided states, and ``q``.

    ``C^T dr_i = dq + q x theta`` and ``C^T dv_i = dp + p x theta`` (errors = computed minus
    true; :func:`gravsurvey.inm.errormodel.continuous_model_n`).

    Parameters
    ----------
    x_s : ndarray (N, n_state)
    c : ndarray (N, 3, 3)
        Triad -> inertial at the epochs.
    r_i, v_i : ndarray (N, 3)
        Mechanized inertial position (m) and velocity (m/s) at the epochs.

    Returns
    -------
    err_q, err_p, q_t : ndarray (N, 3)
        m, m/s, and the triad-resolved position ``q = C^T r_i`` (m).
    """
    th = x_s[:, TH]
    c_t = np.swapaxes(c, 1, 2)
    q_t = np.matmul(c_t, r_i[:, :, None])[:, :, 0]
    p_t = np.matmul(c_t, v_i[:, :, None])[:, :, 0]
    return x_s[:, DQ] + np.cross(q_t, th), x_s[:, DP] + np.cross(p_t, th), q_t


def _initial_pv_correction(out, nav, idx, c):
    """The smoothed position and velocity errors a pass found at its first epoch, inertial axes.

    Returns
    -------
    dr_i, dv_i : ndarray (3,)
        m, m/s.
    """
    err_q, err_p, _ = _triad_errors(out["x_s"][:1], c[:1], nav.r_i[idx[:1]], nav.v_i[idx[:1]])
    return c[0] @ err_q[0], c[0] @ err_p[0]


def _corrected_initial_state(state: InitialState, nav, dr_i, dv_i, mat_it, ellipsoid) -> InitialState:
    """``state`` at the first IMU sample less the errors ``dr_i``, ``dv_i`` (inertial, m and m/s),
    with the triad -> ENU matrix at the corrected position for the triad -> inertial ``mat_it``."""
    t0 = float(nav.time[0])
    r = (nav.r_i[0] - dr_i)[None, :]
    v = (nav.v_i[0] - dv_i)[None, :]
    lat, lon, h, vel_n = navigation_to_geodetic(np.array([t0]), r, v, ellipsoid)
    m_ie = mat_ie(t0, ellipsoid.omega)
    mat_nt = (m_ie @ mat_en(float(lat[0]), float(lon[0]))).T @ mat_it
    return dataclasses.replace(
        state, lat=float(lat[0]), lon=float(lon[0]), height=float(h[0]), vel_n=vel_n[0], mat_nt=mat_nt
    )


def diverging_gyro_axis(found, span_s: float) -> int | None:
    """The tilting gyro whose correction grew over the last three passes, or None.

    The passes are a Gauss-Newton iteration: a correction taken off should leave the next pass
    a smaller one. An axis whose last three corrections have one sign and none smaller than the
    one before, the last two significant, did not converge there: the two corrections taken off
    made it worse. (One growth alone is not: an iteration can overshoot once and settle - quick
    U1002's roll gyro -0.013, -0.018, +0.008, +0.003 deg/h.)

    Parameters
    ----------
    found : list of (ndarray (3,), ndarray (3,))
        Each pass's smoothed gyro-bias correction and its 1-sigma, rad/s, in order
        (:func:`_pass_correction`).
    span_s : float
        The record's length, s.

    Returns
    -------
    int or None
        The first of triad axes 0 and 1 (the gyros that tilt the navigation; the heading gyro's
        correction wanders unobserved on straight lines) that grew, its last two corrections
        beyond their sigma and building more than ``PASSES_GROWTH_TILT_RAD`` of tilt over
        ``span_s``; None otherwise.
    """
    if len(found) < 3:
        return None
    (d0, _), (d1, s1), (d2, s2) = ((np.asarray(d, float)[:2], np.asarray(sg, float)[:2]) for d, sg in found[-3:])
    big = np.ones(2, dtype=bool)
    for d, sg in ((d1, s1), (d2, s2)):
        big &= (np.abs(d) > sg) & (np.abs(d) * span_s > PASSES_GROWTH_TILT_RAD)
    grew = (
        big
        & (d0 * d1 > 0.0)
        & (d1 * d2 > 0.0)
        & (np.abs(d1) >= PASSES_GROWTH_RATIO * np.abs(d0))
        & (np.abs(d2) >= PASSES_GROWTH_RATIO * np.abs(d1))
    )
    return int(np.flatnonzero(grew)[0]) if grew.any() else None


def _check_passes_settled(record, out, span_s, passes, reverted=None) -> float:
    """After the last pass: the correction it would still apply, and a verdict.

    Returns that pass's own initial-attitude correction (rad).  Raises DataError when the
    larger of it and the tilt that its gyro-bias correction beyond the bias's sigma builds over
    ``span_s`` (s) exceeds ``PASSES_FAILED_RAD``; emits a warning above ``PASSES_WARN_RAD``.
    ``reverted``: the passes stopped because a gyro's corrections kept growing
    (``estimate_anomaly``'s record of it: axis, pass, the three corrections); the messages then
    say so, and more passes are not the remedy.
    """
    th0, db, db_sig = _pass_correction(out)
    th = float(np.linalg.norm(th0))
    bias = float(np.max(np.maximum(np.abs(db) - db_sig, 0.0)))
    moved = max(th, bias * span_s)
    what = (
        f"the last of {passes} attitude passes still corrects the initial attitude by {math.degrees(th):.3g} deg "
        f"and a gyro bias by {bias / RADPS_PER_DEGPH:.3g} deg/h beyond its sigma "
        f"({math.degrees(bias * span_s):.3g} deg of tilt over the record)"
    )
    if reverted is not None:
        axis = "xyz"[reverted["axis"]]
        k = reverted["pass"]
        seq = ", ".join(f"{b:+.3g}" for b in reverted["bias_corrections_degph"])
        what = (
            f"the attitude passes did not converge: the gyro-{axis} bias corrections of passes {k - 1}-{k + 1} "
            f"grew ({seq} deg/h), so the estimate is pass {k - 1}'s, which {what[what.index('still corrects') :]}"
        )
    if moved > PASSES_FAILED_RAD:
        remedy = (
            "set model.gyro_bias_sigma_degph to the gyro's datasheet bias, give initial.attitude_deg, or raise "
            "model.attitude_passes"
            if reverted is None
            else "give model.accel_noise_mps2, model.gyro_drift_degph and model.gyro_bias_sigma_degph from the "
            "IMU's datasheet, or initial.attitude_deg"
        )
        raise DataError(f"{record.source or 'record'}: the navigation did not settle: {what}; {remedy}")
    if reverted is not None:
        warnings.warn(
            f"{what}: the estimate may carry some of that error (give model.accel_noise_mps2 and "
            "model.gyro_drift_degph from the IMU's datasheet; more passes would move it further off)"
        )
    elif moved > PASSES_WARN_RAD:
        warnings.warn(f"{what}: the estimate may carry some of that error (raise model.attitude_passes)")
    return th


def _mechanize(record, params, initial, ellipsoid, reference, gyro_bias_t=None, follow=None):
    """Mechanize the record about ``initial`` (gravity with the altimeter radius by default).

    ``gyro_bias_t`` (3,), rad/s: a gyro bias already estimated, taken off the angular rates
    before integrating (the passes' re-linearisation, :func:`estimate_anomaly`).  ``follow``:
    ``(t_ep, theta_ep)``, the attitude turned to an estimate (:func:`mechanize`; the
    following passes, :func:`_follow_passes`).
    """
    imu = record.imu
    alt_t, alt_h = _altimeter(record)
    rate_t = imu.angular_rate_t
    if gyro_bias_t is not None and np.any(gyro_bias_t != 0.0):
        rate_t = np.asarray(rate_t, float) - np.asarray(gyro_bias_t, float)[None, :]
    return mechanize(
        np.asarray(imu.time, float),
        imu.specific_force_t,
        rate_t,
        initial,
        alt_t,
        alt_h,
        use_ext=params.radius_source == "altimeter",
        ellipsoid=ellipsoid,
        reference=reference,
        follow=follow,
    )


def _identify(record, params, nav, ellipsoid, speed0, one_pass, accel_bias=False, memo=None):
    """Identify the model from the flight (gravsurvey.inm.identify; docs/method.md).

    1) noise levels from the vertical channel's spectrum; 2) a first pass with a wide anomaly
    prior; 3) the prior that minimises the expected error given that estimate's spectrum.
    ``one_pass(params, **kw)``: :func:`_one_pass` bound to the current linearisation point;
    ``memo``: the spectral fits shared by the flight's estimates (:func:`identify_params`).
    """
    alt_t, alt_h = _altimeter(record)
    params, ident = identify_params(
        params, nav, record.imu.specific_force_t, alt_t, alt_h, speed0, ellipsoid, memo=memo
    )
    if nav.time[-1] - nav.time[0] < MIN_REFINE_S:
        # too short to see the field's spectrum: the noise levels stay identified, the anomaly
        # prior is the configured or default (broad) one
        params, ident = keep_default_prior(params, ident, speed0, MIN_REFINE_S, float(nav.time[-1] - nav.time[0]))
    elif ident.get("method") != "none" and not {"anomaly_sigma_mps2", "anomaly_lambda_per_m"} <= params.given:
        wide = wide_prior_params(params, ident, speed0)
        idx, _, _, _, first = one_pass(wide, accel_bias=accel_bias)
        weight = _spectrum_weight(record, nav, idx)
        # the constant the wide prior holds (VERTICAL_OFFSET_MIN_MPS2): the caller's to take off
        wide_mean = float(np.mean(first["x_s"][:, G]))
        params, ident = refine_prior(
            params, ident, first["x_s"][:, G], float(np.median(np.diff(nav.time[idx]))), wide, speed0, weight
        )
        expected = ident.get("expected_error_mgal")
        if expected is not None and expected > EXPECTED_ERROR_WARN_MGAL and params.target_resolution_m is None:
            params, ident = _broad_prior_instead(params, ident, speed0, expected)
        ident["wide_pass_mean_mps2"] = wide_mean
    return _prior_consequences(params, ident, nav, speed0)


def _spectrum_weight(record, nav, idx) -> np.ndarray:
    """The weight (N,) of each filter epoch ``idx`` in the spectra :func:`refine_prior` reads:
    the straight stretches (:func:`straight_weight`) less where the specific force is not known
    (gaps, a sensor at its range): the velocity the aiding sets there is a local event, no part
    of the field's or the noise's spectrum."""
    blind = imu_gap_noise(nav.time, idx, record.imu.saturated)
    return straight_weight(nav, record.imu.specific_force_t, nav.time[idx], None if blind is None else blind > 0)


def _prior_consequences(params, ident, nav, speed0):
    """What follows from the anomaly prior :func:`_identify` chose: the filter's height noise
    where the heights wander, and the datasheet drift the smoother passes (its sigma)."""
    walk = ident.get("height_walk") or {}
    if walk.get("applied") and "spectral_model" in ident:
        # the heights wander (identify.WALK_MIN_LOG_LR): the filter's white height noise is
        # set to match it at the half-power point of the prior the filter runs with (chosen,
        # configured, or the default on a short record)
        noise = ident["spectral_model"]
        model = spectral_model_of(params, speed0, float(noise["height_sigma_m"]), float(noise["height_walk_m"]))
        # (the lowest frequency refine_prior's periodogram analyses: its third bin)
        sig = filter_height_sigma(model, speed0, float(ident["height_dt_s"]), 3.0 / float(nav.time[-1] - nav.time[0]))
        params = dataclasses.replace(params, altimeter_sigma_m=sig)
        ident["height_walk"] = walk = {**walk, "filter_height_sigma_m": sig}
        ident["altimeter_sigma_m"] = {
            **ident.get("altimeter_sigma_m", {}),
            "value": sig,
            "white_m": float(model.height_sigma_m),
            "how": (
                f"identified: white {model.height_sigma_m:.3g} m and a height wander of "
                f"{1e3 * model.height_walk_m:.3g} mm in 1 s (log-likelihood ratio "
                f"{float(walk.get('log_likelihood_ratio', float('nan'))):.3g}), as white noise at the smoother's resolution"
            ),
        }
    if not config_models_drift(params.given):
        # honest-sigma hook (docs/method.md "Honest sigma"): the datasheet drift that the filter's
        # gravimeter state does not hold, as the smoother passes it; estimate.py adds it to sigma
        ident["drift_sigma_passed_mps2"] = drift_sigma_passed(ident, float(nav.time[-1] - nav.time[0]))
    return params, ident


def _prior_on_estimate(record, params, ident, nav, speed0, idx, out, one_pass, accel_bias):
    """The anomaly prior chosen again on the spectrum of the estimate made with it, kept where
    the filter's likelihood prefers it.

    The first pass's wide prior lets the disturbance state take up what the attitude states
    would otherwise explain; with a tactical IMU's gyros that is errors of several mGal at
    periods of 100-500 s (quick U009: 1.2-1.7 mGal in those bands against 0.2-0.6 as drawn, over
    a field of 0.1-0.4), which :func:`refine_prior` reads as field.  The estimate under the
    prior it chose carries less of them (0.25-0.3 mGal there), so its spectrum, read through
    that prior's transfer (bands where it passes half or more), gives the field again.  A
    chosen prior's transfer is the spectral model's, not the filter's, so the second choice is
    kept only where the filter's log-likelihood is higher with it.

    ``nav``: the navigation the model's noise levels were identified on; ``one_pass``: the
    pass about the current linearisation (:func:`_one_pass` bound); ``idx``, ``out``: its
    epochs and output with ``params``.  Returns ``params, ident, idx, out`` (those given where
    the first choice stays); ``ident["prior_on_estimate"]`` says what was found.
    """
    weight = _spectrum_weight(record, nav, idx)
    base = {k: v for k, v in ident.items() if k not in REFINE_ONLY_KEYS}
    dt = float(np.median(np.diff(nav.time[idx])))
    new, report = refine_prior(params, base, out["x_s"][:, G], dt, params, speed0, weight)
    same = (new.anomaly_sigma_mps2, new.anomaly_lambda_per_m) == (
        params.anomaly_sigma_mps2,
        params.anomaly_lambda_per_m,
    )
    if same:
        ident["prior_on_estimate"] = {"kept": False, "why": "the same prior"}
        return params, ident, idx, out
    new, report = _prior_consequences(new, report, nav, speed0)
    idx2, _, _, _, out2 = one_pass(new, accel_bias=accel_bias)
    gain = float(np.sum(log_likelihood(out2["p_p"], out2["innov"], *out2["measurements"]))) - float(
        np.sum(log_likelihood(out["p_p"], out["innov"], *out["measurements"]))
    )
    facts = {
        "kept": gain > 0.0,
        "log_likelihood_gain": gain,
        "anomaly_sigma_mps2": new.anomaly_sigma_mps2,
        "anomaly_lambda_per_m": new.anomaly_lambda_per_m,
        "resolution_m": report.get("resolution_m"),
    }
    if not gain > 0.0:
        ident["prior_on_estimate"] = facts
        return params, ident, idx, out
    how = "least expected error (the spectrum of the estimate with the first pass's choice; filter likelihood)"
    for key in ("anomaly_sigma_mps2", "anomaly_lambda_per_m"):
        if report[key]["how"] != "config":
            report[key] = {**report[key], "how": how}
    report["prior_on_estimate"] = facts
    return new, report, idx2, out2


#: Keys of :func:`refine_prior`'s report that hold for the prior it chose only.
REFINE_ONLY_KEYS = (
    "expected_error_mgal",
    "smoother_sigma_scale",
    "field_sigma_missed_mps2",
    "field_sigma_unexcluded_mps2",
    "field_std_seen_mgal",
    "signal_seen_to_m",
    "noise_scale",
)


def _broad_prior_instead(params, ident, speed0, expected):
    """The configured or default (broad) anomaly prior in place of one of least expected error
    that expects ``expected`` mGal (over :data:`EXPECTED_ERROR_WARN_MGAL`): there the first
    pass's spectrum is noise the model does not hold (heights wandering with an antenna's
    unseen swing), read as a strong short field, and the prior passes it all (a 0.5-mGal field
    estimated to 29 mGal where the conventional chain had 0.38).  The identified noise levels
    stay; a warning says so."""
    report = {k: v for k, v in ident.items() if k not in REFINE_ONLY_KEYS}
    new, report = keep_default_prior(params, report, speed0, MIN_REFINE_S)
    why = f"default (the prior of least expected error expected {expected:.3g} mGal)"
    for k in ("anomaly_sigma_mps2", "anomaly_lambda_per_m"):
        if report[k]["how"] != "config":
            report[k]["how"] = why
    res = report.get("resolution_m")
    report["warnings"] = list(ident.get("warnings", [])) + [
        f"model identification: the anomaly prior of least expected error expects {expected:.3g} mGal in the "
        "product (the first pass's spectrum is the heights' or the gravimeter's noise, not a field); the "
        f"configured or default prior ({new.anomaly_sigma_mps2 / 1e-5:.3g} mGal over "
        f"{1e-3 / new.anomaly_lambda_per_m:.3g} km) is used instead"
        + (f", the field smoothed to {res / 1e3:.3g} km" if res else "")
        + ' (docs/method.md, "Identification")'
    ]
    return new, report


def _horizontal_pass(record, params, nav, ellipsoid, g_vertical, one_pass):
    """The 18-state pass (vector gravimetry) about the last vertical pass's linearisation point.

    Its horizontal prior is the Markov process matched to the vertical estimate ``g_vertical``
    (m/s^2, per epoch) through the harmonic relation (:func:`horizontal_prior`).  Returns
    :func:`_one_pass`'s tuple and the prior (sigma m/s^2, lambda 1/m) used; ``one_pass`` is
    :func:`_one_pass` bound to that point.
    """
    t = nav.time
    step = max(1, int(round((t.size - 1) / (t[-1] - t[0]) / params.filter_rate_hz)))
    spacing = _typical_speed(record, nav, ellipsoid) * float(t[min(step, t.size - 1)] - t[0])
    hprior = horizontal_prior(params.anomaly_sigma_mps2, params.anomaly_lambda_per_m, g_vertical, spacing)
    out = one_pass(params, hprior=hprior)
    return (*out, hprior)


#: Share of the decimated epochs' spacings off their median by more than
#: :data:`EPOCH_SPACING_TOL` beyond which the IMU's rate is taken to change within the flight
#: (not a few gaps) and the epochs are laid on a time grid instead.
EPOCH_IRREGULAR_FRACTION = 0.05
#: Relative departure of an epoch spacing from the median that counts as off.
EPOCH_SPACING_TOL = 0.25


def filter_epochs(time_s, rate_hz):
    """The IMU samples that are the filter's epochs, and the half window of a measurement.

    An IMU at one rate is decimated by the nearest integer factor of its mean rate to
    ``rate_hz``.  Where that leaves the epochs unevenly spaced (more than
    :data:`EPOCH_IRREGULAR_FRACTION` of the spacings off their median by over
    :data:`EPOCH_SPACING_TOL`: the IMU's rate changed within the flight, e.g. 100 Hz then
    50 Hz), each epoch is instead the IMU sample nearest a time grid at ``rate_hz``: the
    epochs stay evenly spaced in time, so no measurement falls between two epochs' windows
    and the identification's spectra see an even sampling.

    Parameters
    ----------
    time_s : ndarray, shape (n,)
        IMU sample times, s, increasing.
    rate_hz : float
        Filter epochs per second (``processing.filter_rate_hz``).

    Returns
    -------
    idx : ndarray of int, shape (m,)
        Indices of the epochs into ``time_s``.
    half_window_s : float
        Largest offset, s, of a measurement from the epoch it is assigned to.
    """
    t = np.asarray(time_s, float)
    if t.size < 2 or not t[-1] > t[0]:
        return np.arange(t.size), 0.5
    imu_rate = (t.size - 1) / (t[-1] - t[0])
    step = max(1, int(round(imu_rate / rate_hz)))
    idx = np.arange(0, t.size, step)
    spacing = np.diff(t[idx])
    if spacing.size < 2:
        return idx, 0.5 * step / imu_rate
    typical = float(np.median(spacing))
    off = np.abs(spacing - typical) > EPOCH_SPACING_TOL * typical
    if np.mean(off) <= EPOCH_IRREGULAR_FRACTION:
        return idx, 0.5 * step / imu_rate
    period = 1.0 / rate_hz
    grid = t[0] + period * np.arange(int(math.floor((t[-1] - t[0]) / period)) + 1)
    pos = np.clip(np.searchsorted(t, grid), 1, t.size - 1)
    near = np.where(grid - t[pos - 1] <= t[pos] - grid, pos - 1, pos)
    idx = np.unique(near)
    spacing = np.diff(t[idx])
    # a measurement goes to its nearest epoch; the window only needs to reach across the
    # widest spacing that is not a gap
    return idx, 0.5 * max(period, float(np.quantile(spacing, 0.99)) if spacing.size else period)


def missed_accel_sigma(time_s, f_t) -> float:
    """The specific force a straight line across a short IMU gap misses, m/s^2 (1-sigma): the
    RMS of each axis's departure from its centred running mean over :data:`IMU_GAP_WINDOW_S`,
    the largest of the three (turbulence and manoeuvres; near zero on a calm record)."""
    t = np.asarray(time_s, float)
    f = np.asarray(f_t, float)
    if t.size < 3:
        return 0.0
    width = int(round(IMU_GAP_WINDOW_S / float(np.median(np.diff(t)))))
    if width < 2 or t.size <= 2 * width:
        return 0.0
    # the running mean's ends hold the first and last window's mean: left out
    inner = slice(width, t.size - width)
    return float(max(np.sqrt(np.mean((f[inner, j] - centred_mean(f[:, j], width)[inner]) ** 2)) for j in range(3)))


def imu_gap_noise(time_s, idx, saturated=None, accel_sigma_mps2: float = 1.0):
    """Velocity process noise of the time the specific force is not known, per filter epoch.

    Across an IMU gap the mechanization takes the specific force as the straight line between
    the samples either side, and a sample at an accelerometer's range (``saturated``) holds the
    range, not the force; what either misses enters the velocity, and the filter, not told,
    read the jump as anomaly.  The time not known within an epoch is one error of
    ``accel_sigma_mps2`` (a clipped stretch's excess persists through it; the caller gives
    :func:`missed_accel_sigma` of the record).

    Parameters
    ----------
    time_s : ndarray, shape (n,)
        IMU sample times, s.
    idx : ndarray of int, shape (m,)
        The filter epochs' indices into ``time_s`` (:func:`filter_epochs`).
    saturated : ndarray of bool, shape (n,), optional
        Samples at an accelerometer's range (``ImuChannel.saturated``).
    accel_sigma_mps2 : float

    Returns
    -------
    ndarray, shape (m,) or None
        Per epoch ``k``, the variance (m/s)^2 of each velocity component added over the
        transition from epoch ``k - 1`` (0 at epoch 0): ``(sigma T_k)^2``, ``T_k`` the steps'
        excess over their nominal step (the longer neighbour's; steps over :data:`IMU_GAP_STEPS`
        nominal ones) plus the steps from saturated samples in it, s; None when there is neither.
    """
    d = np.diff(np.asarray(time_s, float))
    if d.size < 2:
        return None
    # the nominal step of each step is the longer of its neighbours': an IMU whose rate changed
    # within the record has no gaps at the other rate, nor where it changed (the global median
    # had made every step at half the rate a gap: 2.62 -> 3.37 mGal on the fuzzing flight)
    local = np.maximum(np.concatenate([d[:1], d[:-1]]), np.concatenate([d[1:], d[-1:]]))
    blind = np.where(d > IMU_GAP_STEPS * local, d - local, 0.0)
    if saturated is not None:
        blind = blind + np.where(np.asarray(saturated, bool)[:-1], d, 0.0)
    if not blind.any():
        return None
    c = np.concatenate([[0.0], np.cumsum(blind)])
    idx = np.asarray(idx)
    var = np.zeros(idx.size)
    var[1:] = (accel_sigma_mps2 * (c[idx[1:]] - c[idx[:-1]])) ** 2
    return var


def _one_pass(
    record,
    params,
    initial,
    nav,
    ellipsoid,
    reference,
    theta_prior,
    lever_arm_t=None,
    hprior=None,
    accel_bias=False,
    gyro_bias_prior=None,
    pv_prior_i=None,
    gnss_vertical=True,
    accel_bias_prior=None,
    gap_accel_sigma_mps2=None,
    body_mat_i=None,
    theta_shift=None,
):
    """Discretise, filter and smooth once about the mechanization ``nav``.

    Returns ``idx`` (IMU indices of the epochs), ``c`` (triad -> inertial at the epochs),
    ``gnss_used``, ``n_state`` and the :func:`filter_and_smooth` dict.  ``hprior``: the
    horizontal disturbance prior (sigma, lambda) when ``params.horizontal``.  ``accel_bias``:
    the 16-state model (horizontal accelerometer biases) when GNSS-aided.  ``gnss_vertical``:
    use the GNSS's up component (False where the heights are the GNSS's).  ``gyro_bias_prior``
    (3,), rad/s: the prior mean of the gyro-bias state (minus the bias taken off the rates);
    ``accel_bias_prior`` (2,), m/s^2: the same for the accelerometer-bias states (16 or 18).
    ``gap_accel_sigma_mps2``: the record's :func:`missed_accel_sigma` (found here when None).
    ``body_mat_i``: the aircraft's attitude for the lever arm where it is not the triad's (a
    platform; :func:`_body_attitude`).  ``theta_shift`` (N, 3), rad: ``nav`` follows an
    estimated attitude, turned by this from the free mechanization the priors describe
    (:func:`_follow_passes`); the states returned are ``nav``'s errors.
    """
    t = nav.time
    alt_t, alt_h = _altimeter(record)
    idx, half = filter_epochs(t, params.filter_rate_hz)
    geom = epoch_geometry(nav, idx, params.radius_source == "altimeter", ellipsoid)
    alt_dt = float(np.median(np.diff(alt_t))) if alt_t.size > 1 else 1.0
    gnss_used = bool(params.gnss_aiding) and record.gnss is not None and len(record.gnss.time) > 0
    # position aiding needs the attitude error explicitly (the seed's dq merges it into the
    # position): 14 states (errormodel.continuous_model_n)
    horizontal = gnss_used and hprior is not None
    accel_bias = gnss_used and accel_bias and not horizontal
    n_state = state_perm(gnss_used, horizontal, accel_bias).size
    phi, q = discretise(
        geom,
        params,
        alt_dt,
        reference=reference,
        aided=gnss_used,
        horizontal=horizontal,
        hprior=hprior,
        accel_bias=accel_bias,
    )
    if gap_accel_sigma_mps2 is None:
        gap_accel_sigma_mps2 = missed_accel_sigma(t, record.imu.specific_force_t)
    gap_var = imu_gap_noise(t, idx, record.imu.saturated, gap_accel_sigma_mps2)
    if gap_var is not None:
        for i in DP:
            q[:, i, i] += gap_var
    meas = [AltimeterMeasurement(alt_t, alt_h, params.altimeter_sigma_m, ellipsoid, _altimeter_sigma(record))]
    if gnss_used:
        gn = record.gnss
        meas.append(
            GnssMeasurement(
                gn.time,
                gn.lat,
                gn.lon,
                gn.height,
                params.gnss_horizontal_sigma_m,
                params.gnss_vertical_sigma_m,
                ellipsoid,
                lever_arm_t,
                vertical=gnss_vertical,
                body_mat_i=body_mat_i,
                height_sigma_m=gn.height_sigma_m,
            )
        )
    z, h, r = stack_measurements([m.build(nav, idx, half, n_state) for m in meas])
    c = nav.mat_it[idx]
    att_cov = initial.attitude_cov_t if params.initial_attitude_sigma_deg is None else None
    if gnss_used:
        q_t0 = c[0].T @ nav.r_i[idx[0]]
        p_t0 = c[0].T @ nav.v_i[idx[0]]
        p0 = initial_covariance(
            params, q_t0, p_t0, attitude_cov_t=att_cov, horizontal=horizontal, hprior=hprior, accel_bias=accel_bias
        )
        dr_t = dv_t = None
        if pv_prior_i is not None:
            dr_t, dv_t = c[0].T @ pv_prior_i[0], c[0].T @ pv_prior_i[1]
        ba_prior = accel_bias_prior if n_state >= N_STATE_BIAS else None
        x0 = initial_mean(theta_prior, q_t0, p_t0, n_state, gyro_bias_prior, dr_t, dv_t, ba_prior)
    else:
        p0 = initial_covariance(params)
        x0 = np.zeros(n_state)
    shift = None
    if theta_shift is not None and gnss_used:
        # the errors of the free mechanization (whose priors x0, p0 and noise these are) are
        # nav's plus the shift's linear response; the filter runs on those, on measurements
        # moved by it, and the shift comes off its states after (docs/method.md, "Following
        # passes")
        q_t = np.einsum("nji,nj->ni", c, nav.r_i[idx])
        p_t = np.einsum("nji,nj->ni", c, nav.v_i[idx])
        shift = attitude_shift_states(phi, theta_shift, q_t, p_t, n_state)
        z = z + np.einsum("kmn,kn->km", h, shift)
    out = filter_and_smooth(x0, p0, phi, q, z, h, r, reference=reference)
    if shift is not None:
        for key in ("x_f", "x_p", "x_s"):
            out[key] = out[key] - shift
    # what the filter ran on, for the likelihood of the last pass (references, not copies)
    out["measurements"] = (z, h, r)
    return idx, c, gnss_used, n_state, out


def _tilt_rad(theta_t, nav, idx) -> float:
    """Largest tilt (rad) in the attitude errors ``theta_t`` (N, 3) on the triad axes: their
    part off the geocentric radius (a turn about it does not move the position on the triad
    axes the 3D-INM's states hold)."""
    th_i = np.einsum("nij,nj->ni", nav.mat_it[idx], theta_t)
    r = nav.r_i[idx]
    up = r / np.linalg.norm(r, axis=1)[:, None]
    tilt = th_i - np.sum(th_i * up, axis=1)[:, None] * up
    return float(np.max(np.linalg.norm(tilt, axis=1))) if tilt.size else 0.0


def _follow_passes(record, params, initial, ellipsoid, reference, gyro_bias_t, nav, idx, out, one_pass, accel_bias):
    """Passes about a navigation that follows the smoothed attitude, while its tilt is large.

    The filter is linear about the free mechanization: a tilt ``e`` of it puts ``|r| e^2 / 2``
    (the Earth's radius) into the radial position the states hold, a second-order error the
    model lacks (1 mrad: 3 m) that reaches the disturbance.  Navigation-grade gyros keep the
    passes' mechanization within 0.21 mrad; a tactical IMU's (0.1 deg/sqrt(h)) leaves it
    1.7-7 mrad off (:data:`FOLLOW_TILT_RAD`).  While the smoothed tilt exceeds :data:`FOLLOW_TILT_RAD`, up to
    :data:`FOLLOW_PASSES` passes mechanize again with the attitude turned to the smoothed one
    (:func:`mechanize`'s ``follow``) and filter about that with the same priors
    (:func:`attitude_shift_states`).

    Returns
    -------
    nav, idx, out
        The last pass's navigation, epochs and smoother output (``nav``'s errors).
    theta : ndarray, shape (N, 3)
        The attitude turn of ``nav`` from the free mechanization, rad.
    tilts : list of float
        The smoothed tilt (rad) that started each following pass (empty: none ran).
    """
    free_t = nav.time[idx]
    theta = np.zeros((idx.size, 3))
    tilts = []
    for _ in range(FOLLOW_PASSES):
        tilt = _tilt_rad(out["x_s"][:, TH], nav, idx)
        if not tilt > FOLLOW_TILT_RAD:
            break
        theta = theta + out["x_s"][:, TH]
        nav = _mechanize(record, params, initial, ellipsoid, reference, gyro_bias_t, follow=(free_t, theta))
        idx, _, _, _, out = one_pass(params, accel_bias=accel_bias, nav=nav, theta_shift=theta)
        tilts.append(tilt)
    return nav, idx, out, theta, tilts


def attitude_shift_states(phi, theta, q_t, p_t, n_state: int) -> np.ndarray:
    """The linear error-state response to turning a navigation's attitude by ``theta``.

    A navigation ``N1`` whose attitude is the free mechanization ``N0``'s turned by
    ``Exp([theta_k x])`` at epoch ``k`` (``C1 = C0 Exp(theta)``, triad axes) has the errors
    ``e1 = e0 - s``.  Each epoch's turn ``d`` (``theta_k`` less what the error dynamics carried
    of the earlier ones, ``s_k = phi_k s_k-1``) enters ``s`` as a prior mean would
    (:func:`gravsurvey.inm.errormodel.initial_mean`: ``theta += d``, ``dq -= q x d``,
    ``dp -= p x d``, the seed's states holding the attitude); the biases and the disturbance get
    none.  ``e0`` obeys the unforced model (its priors and noise), so a filter about ``N1`` runs
    on ``e0 = e1 + s`` with the measurements ``z + H s``, and ``s`` comes off its states after.

    Parameters
    ----------
    phi : ndarray, shape (N, n, n)
        Transition matrices about ``N1`` (``phi[k]`` from epoch ``k - 1`` to ``k``).
    theta : ndarray, shape (N, 3)
        Attitude turn at the epochs, rad, triad axes.
    q_t, p_t : ndarray, shape (N, 3)
        ``N1``'s position (m) and inertial velocity (m/s) on the triad axes at the epochs.
    n_state : int
        States of the model (14 and up: the attitude states :data:`TH` exist).

    Returns
    -------
    ndarray, shape (N, n_state)
    """
    theta = np.asarray(theta, float)
    s = np.zeros((theta.shape[0], n_state))
    for k in range(theta.shape[0]):
        if k > 0:
            s[k] = phi[k] @ s[k - 1]
        d = theta[k] - s[k, TH]
        s[k, TH] += d
        s[k, DQ] -= np.cross(q_t[k], d)
        s[k, DP] -= np.cross(p_t[k], d)
    return s


def _solution(record, params, ellipsoid, triad, nav, idx, c, gnss_used, n_state, out, passes, corrections):
    """Corrected navigation, attitude and the anomaly from the last pass's smoother output."""
    t = nav.time
    x_s, p_s, x_f, p_f = out["x_s"], out["p_s"], out["x_f"], out["p_f"]

    # corrections: true = computed - error; the position and velocity errors on the triad are
    # dq (+ q x theta when aided) and dp (+ p x theta), to inertial through C
    if gnss_used:
        err_q, err_p, q_t = _triad_errors(x_s, c, nav.r_i[idx], nav.v_i[idx])
        # covariance of dq + [q x] theta
        jac = np.zeros((idx.size, 3, n_state))
        jac[:, :, DQ] = np.eye(3)
        sk = np.zeros((idx.size, 3, 3))
        sk[:, 0, 1], sk[:, 0, 2], sk[:, 1, 2] = -q_t[:, 2], q_t[:, 1], -q_t[:, 0]
        sk[:, 1, 0], sk[:, 2, 0], sk[:, 2, 1] = q_t[:, 2], -q_t[:, 1], q_t[:, 0]
        jac[:, :, TH] = sk
        cov_pos = np.einsum("nij,njk,nlk->nil", jac, p_s, jac)
        # dq and [q x] theta are almost opposite (theta enters dq multiplied by the Earth's
        # radius), so their sum's variance is a difference of large numbers: a rounding-level
        # negative value is a zero sigma, not a NaN
        sig_pos = np.sqrt(np.maximum(np.einsum("nii->ni", cov_pos), 0.0))
    else:
        err_q, err_p = x_s[:, DQ].copy(), x_s[:, DP].copy()
        sig_pos = np.sqrt(np.stack([p_s[:, i, i] for i in DQ], axis=1))
    r_corr = nav.r_i[idx] - np.einsum("nij,nj->ni", c, err_q)
    v_corr = nav.v_i[idx] - np.einsum("nij,nj->ni", c, err_p)
    lat, lon, height, vel_n = navigation_to_geodetic(t[idx], r_corr, v_corr, ellipsoid)
    speed = np.hypot(vel_n[:, 0], vel_n[:, 1])
    heading = np.mod(np.arctan2(vel_n[:, 0], vel_n[:, 1]), 2.0 * math.pi)
    innov = out["innov"]
    if innov.shape[1] == 1:
        innov = innov[:, 0]
    warn = solvability_warnings(params, float(np.median(speed)))
    att, att_sig = _attitude(nav, idx, c, x_s, p_s, lat, lon, gnss_used, triad, ellipsoid)
    conv = (
        _heading_converge_s(t[idx], c, p_f, lat, lon, ellipsoid) if gnss_used and triad == "strapdown" else float("nan")
    )
    return InmSolution(
        time=t[idx].copy(),
        g_forward=x_f[:, G].copy(),
        sigma_forward=np.sqrt(p_f[:, G, G]),
        g_smooth=x_s[:, G].copy(),
        sigma_smooth=np.sqrt(p_s[:, G, G]),
        f3_smooth=x_s[:, F3].copy(),
        f3_sigma=np.sqrt(p_s[:, F3, F3]),
        lat=lat,
        lon=lon,
        height=height,
        vel_n=vel_n,
        speed=speed,
        heading=heading,
        innovations_normalised=innov,
        dq_smooth=x_s[:, DQ].copy(),
        dp_smooth=x_s[:, DP].copy(),
        sigma_position_m=sig_pos,
        x_smooth=x_s,
        p_smooth=p_s,
        x_forward=x_f,
        warnings=warn,
        gnss_aided=gnss_used,
        attitude=att,
        attitude_sigma=att_sig,
        passes=passes,
        attitude_corrections=corrections,
        attitude_converge_s=conv,
    )


def _attitude(nav, idx, c, x_s, p_s, lat, lon, gnss_used, triad, ellipsoid):
    """Corrected roll, pitch, heading (rad) and their 1-sigma per epoch, (N, 3) each.

    ``C_true = C (I + [theta x])`` (triad -> inertial), to ENU at the corrected position.
    The sigmas map the smoothed ``theta`` covariance to ENU axes: heading about Up, roll
    about the nose's and pitch about the left wing's horizontal direction (exact in level
    flight).  NaN for a platform triad (its axes are ENU, not the aircraft's).
    """
    n = idx.size
    if triad != "strapdown":
        return np.full((n, 3), np.nan), np.full((n, 3), np.nan)
    th = x_s[:, TH] if gnss_used else np.zeros((n, 3))
    sk = np.zeros((n, 3, 3))
    sk[:, 0, 1], sk[:, 0, 2], sk[:, 1, 2] = -th[:, 2], th[:, 1], -th[:, 0]
    sk[:, 1, 0], sk[:, 2, 0], sk[:, 2, 1] = th[:, 2], -th[:, 1], th[:, 0]
    c_true = c + np.einsum("nij,njk->nik", c, sk)
    m_in = np.einsum("nij,njk->nik", mat_ie(nav.time[idx], ellipsoid.omega), mat_en(lat, lon))
    m_nt = np.einsum("nji,njk->nik", m_in, c_true)
    nose, left, roof = m_nt[:, :, 0], m_nt[:, :, 1], m_nt[:, :, 2]
    heading = np.mod(np.arctan2(nose[:, 0], nose[:, 1]), 2.0 * math.pi)
    pitch = np.arcsin(np.clip(nose[:, 2], -1.0, 1.0))
    roll = np.arctan2(left[:, 2], roof[:, 2])
    sig = np.full((n, 3), np.nan)
    if gnss_used:
        p_th = p_s[:, TH][:, :, TH]
        cov_n = np.einsum("nij,njk,nlk->nil", m_nt, p_th, m_nt)
        along = np.stack([np.sin(heading), np.cos(heading), np.zeros(n)], axis=1)
        across = np.stack([-np.cos(heading), np.sin(heading), np.zeros(n)], axis=1)
        sig[:, 0] = np.sqrt(np.einsum("ni,nij,nj->n", along, cov_n, along))
        sig[:, 1] = np.sqrt(np.einsum("ni,nij,nj->n", across, cov_n, across))
        sig[:, 2] = np.sqrt(cov_n[:, 2, 2])
    return np.stack([roll, pitch, heading], axis=1), sig


def _heading_converge_s(time, c, p_f, lat, lon, ellipsoid):
    """Time from the first epoch after which the forward heading sigma stays <= 2 x its median, s."""
    m_in = np.einsum("nij,njk->nik", mat_ie(time, ellipsoid.omega), mat_en(lat, lon))
    up_t = np.einsum("nji,nj->ni", c, m_in[:, :, 2])  # Up on the triad (C^T M_in e_U)
    p_th = p_f[:, TH][:, :, TH]
    s_head = np.sqrt(np.einsum("ni,nij,nj->n", up_t, p_th, up_t))
    bad = np.flatnonzero(s_head > 2.0 * np.median(s_head))
    if bad.size == 0:
        return 0.0
    k = min(bad[-1] + 1, time.size - 1)
    return float(time[k] - time[0])


def median_ground_speed(time_s, lat, lon, height, ellipsoid: Ellipsoid = WGS84, baseline_s=SPEED_BASELINE_S):
    """Median horizontal ground speed of a track of fixes, m/s.

    Each speed is the horizontal distance from a fix to the first fix at least ``baseline_s``
    after it, over their time difference: between consecutive fixes of a fast receiver the
    fixes' noise biases the norm up (1-m noise at 17 Hz: 83 m/s for 70 flown), over 2 s it adds
    a few mm/s.

    Parameters
    ----------
    time_s : ndarray (n,)
        Fix times, s (sorted here).
    lat, lon : ndarray (n,)
        Geodetic latitude and longitude, rad.
    height : ndarray (n,)
        Ellipsoidal height, m.
    ellipsoid : Ellipsoid
    baseline_s : float
        Shortest time between the two fixes of one speed, s.

    Returns
    -------
    float or None
        The median speed, m/s; None where no two finite fixes are apart in time.
    """
    t, lat, lon, h = (np.asarray(a, float) for a in (time_s, lat, lon, height))
    ok = np.isfinite(t) & np.isfinite(lat) & np.isfinite(lon) & np.isfinite(h)
    keep = np.flatnonzero(ok)[np.argsort(t[ok], kind="stable")]
    t, lat, lon, h = t[keep], lat[keep], lon[keep], h[keep]
    if t.size < 2:
        return None
    # the first fix at least baseline_s after each fix (the last fix where none is)
    j = np.minimum(np.searchsorted(t, t + baseline_s), t.size - 1)
    dt = t[j] - t
    d_east, d_north = local_displacement(lat, lon, lat[j], lon[j], h, ellipsoid)
    # the full baseline where the record has it (the last fixes' shorter ones are noisier)
    use = dt >= baseline_s
    if not use.any():
        use = dt > 0
    v = np.hypot(d_north, d_east)[use] / dt[use]
    v = v[np.isfinite(v)]
    return float(np.median(v)) if v.size else None


def _typical_speed(record, nav, ellipsoid):
    """Median ground speed of the flight, m/s: from GNSS positions (:func:`median_ground_speed`),
    else the mechanization."""
    gn = record.gnss
    if gn is not None and len(gn.time) > 2:
        v = median_ground_speed(gn.time, gn.lat, gn.lon, gn.height, ellipsoid)
        if v is not None:
            return v
    step = max(1, nav.time.size // 2000)
    _, _, _, vel_n = navigation_to_geodetic(nav.time[::step], nav.r_i[::step], nav.v_i[::step], ellipsoid)
    return float(np.median(np.hypot(vel_n[:, 0], vel_n[:, 1])))
