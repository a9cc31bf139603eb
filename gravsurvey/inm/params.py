"""Filter parameters and initial state of the 3D-INM estimator.

Defaults are the seed-004 benchmark values (model.md section 3).  Every
quantity is SI; the gyro drift is the only non-SI key (deg/h, named so).

Noise conventions (shared with the simulator's sensor model):

* ``accel_noise_mps2``, ``gyro_drift_degph`` and ``gravimeter_white_mps2``
  are white noises given by their one-second standard deviation
  ``sigma_1s`` (the sigma of the noise averaged over 1 s): continuous
  two-sided spectral density ``sigma_1s**2 * 1 s``; a sample at ``R`` Hz has
  sigma ``sigma_1s * sqrt(R)`` (the simulator's convention,
  gravsurvey/simulate/sensors.py).
* ``altimeter_sigma_m`` is the standard deviation of each altimeter sample.
* The gravimeter error ``f3`` and the anomaly ``g`` are first-order Markov
  processes with stationary standard deviation ``sigma`` and correlation rate
  ``lambda``: ``dx/dt = -lambda x + sqrt(2 lambda) sigma u``.  For the anomaly
  the rate is in space, ``lambda_g(t) = anomaly_lambda_per_m * v(t)``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError, DataError


#: instrument triads: ENU-stabilised platform, or body-fixed (docs/conventions.md)
TRIADS = ("platform", "strapdown")

#: One deg/h (the gyro keys' unit) in rad/s.
RADPS_PER_DEGPH = math.radians(1.0) / 3600.0
RADIUS_SOURCES = ("altimeter", "computed")
#: Boolean settings (everything else but ``radius_source`` is a number).
_BOOL_KEYS = ("gnss_aiding", "identify", "horizontal", "accel_bias_states")
#: Attributes that are not config keys.
_INTERNAL = ("given",)


@dataclass
class InmParams:
    """Settings of the 3D-INM Kalman dynamic inversion (config section ``model``).

    Attributes
    ----------
    filter_rate_hz : float
        Kalman epoch rate, Hz; the IMU rate is decimated by the nearest integer factor.
    accel_noise_mps2 : float
        sigma_f1 = sigma_f2: white error of accelerometers 1 and 2, m/s^2 (one-second sigma).
    gyro_drift_degph : float
        White gyro drift sigma_nu, deg/h (one-second sigma).
    gravimeter_lambda_per_s : float
        lambda_f3, correlation rate of the gravimeter (third accelerometer) error, 1/s.
    gravimeter_sigma_mps2 : float
        sigma_f3, stationary sigma of the gravimeter error, m/s^2.
    gravimeter_white_mps2 : float
        Optional white noise of the gravimeter on top of the Markov error, m/s^2
        (one-second sigma); 0 in the seed.
    anomaly_lambda_per_m : float
        lambda_s, spatial correlation rate of the anomaly, 1/m.
    anomaly_sigma_mps2 : float
        sigma_s, stationary sigma of the anomaly, m/s^2.
    altimeter_sigma_m : float
        sigma_eps, white error of the radial (height) information, m.
    radius_source : str
        ``"altimeter"``: the gravity model takes |q| from the altimeter (Andreev section 6,
        stable in all channels); ``"computed"``: from the navigation solution.
    initial_position_sigma_m, initial_velocity_sigma_mps : float
        Initial 1-sigma of each component of dq (m) and dp (m/s).
    initial_anomaly_sigma_mps2, initial_gravimeter_sigma_mps2 : float
        Initial 1-sigma of g and f3, m/s^2.
    gnss_aiding : bool
        Use the record's GNSS positions (when it has any) as a position measurement besides
        the altimeter (:class:`gravsurvey.inm.errormodel.GnssMeasurement`).  Without it the
        horizontal position is unobserved and gyro biases rotate the whole solution (about
        ``|q| nu t``: km after hours), which moves the normal field under the estimate.
    gnss_horizontal_sigma_m, gnss_vertical_sigma_m : float
        1-sigma of each GNSS sample's east/north and up error, m (> 0).
    initial_attitude_sigma_deg : float or None
        Initial 1-sigma of each triad attitude-error component, deg (GNSS-aided filter only).
        None (default): the coarse alignment's own covariance when the attitude comes from
        the alignment (docs/method.md, "Alignment"), 0.05 deg when it is given (a platform's
        levelled triad, or ``initial.attitude_deg``).
    attitude_passes : int
        Most filter/smoother passes with GNSS aiding (1-5, default 3): after a pass the
        initial attitude is corrected by the smoothed attitude error, the smoothed gyro bias
        is taken off the rates, and the flight is mechanized and filtered again about that
        (the prior stays the alignment's); it stops when the corrections are below 0.001 deg
        and 0.001 deg/h (or within the bias's smoothed sigma).
    gyro_bias_sigma_degph : float
        1-sigma of each gyro's constant bias, deg/h (GNSS-aided filter only: with position
        aiding the bias is observable and is estimated as three extra states).
    identify : bool
        Estimate the anomaly prior (``anomaly_sigma_mps2``, ``anomaly_lambda_per_m``), the
        gravimeter's white noise and the altimeter noise from the flight itself
        (:mod:`gravsurvey.inm.identify`); the keys set in the config are held fixed.  With
        ``false`` the configured values or the seed defaults are used as they are.
    target_resolution_m : float or None
        Half-wavelength resolution (m) the smoother should have; the anomaly sigma is chosen
        to put the smoother's half-power point there (more noise for a finer resolution).
        ``None``: the identified model's own optimum (least expected error).
    horizontal : bool
        Also estimate the horizontal components of the gravity disturbance (north, east) as
        states, with horizontal accelerometer biases (vector gravimetry, seed 003; needs GNSS
        aiding; docs/method.md "Vector gravimetry").  Off by default.
    accel_bias_states : bool or None
        Carry the constant biases of accelerometers 1 and 2 as states (16 instead of 14) in a
        GNSS-aided filter (docs/method.md, "GNSS aiding"): an unmodelled horizontal bias is
        taken for a tilt on straight legs and leaks into the vertical in turns.  ``None`` (the
        default): on, either triad (measured, docs/benchmarks.md, "Horizontal accelerometer-bias
        states on platform flights" and "The accelerometer-bias states on strapdown flights");
        ``False`` keeps the 14 states.
    accel_bias_mps2 : float or None
        The horizontal accelerometers' bias from their datasheet (1-sigma of each constant bias,
        m/s^2; e.g. 1e-3 for 100 micro-g).  Given, a GNSS-aided filter on either triad carries the
        bias states (16) with this prior; on a strapdown triad, after each pass, the smoothed
        bias is also taken off the specific force and the flight mechanized (and the model
        identified) again about it, as the gyro bias is (docs/method.md, "Accelerometer bias").
        ``None`` (the default): the states follow ``accel_bias_states`` with a 5e-4 m/s^2 prior,
        and nothing is taken off.  Opt-in, measured: it removes a tactical strapdown bias's leak
        into the vertical (1e-3 m/s^2: 1.29 -> 0.69 mGal) but costs on some flights whose bias
        is small (docs/benchmarks.md, "Accelerometer bias taken off between passes").
    given : frozenset of str
        The keys held fixed by identification: those written in the config
        (:func:`gravsurvey.settings.inm_params`) or, when constructed directly and not given, every key whose value
        differs from its default.  Not a config key itself.
    """

    filter_rate_hz: float = 1.0
    accel_noise_mps2: float = 1.0e-3
    gyro_drift_degph: float = 0.01
    gravimeter_lambda_per_s: float = 0.025
    gravimeter_sigma_mps2: float = 1.0e-6
    gravimeter_white_mps2: float = 0.0
    anomaly_lambda_per_m: float = 1.0e-5
    anomaly_sigma_mps2: float = 1.0e-3
    altimeter_sigma_m: float = 1.0
    radius_source: str = "altimeter"
    initial_position_sigma_m: float = 50.0
    initial_velocity_sigma_mps: float = 0.05
    initial_anomaly_sigma_mps2: float = 1.0e-3
    initial_gravimeter_sigma_mps2: float = 1.0e-5
    gnss_aiding: bool = True
    gnss_horizontal_sigma_m: float = 1.0
    gnss_vertical_sigma_m: float = 2.0
    attitude_passes: int = 3
    initial_attitude_sigma_deg: float | None = None
    gyro_bias_sigma_degph: float = 0.05
    identify: bool = True
    target_resolution_m: float | None = None
    horizontal: bool = False
    accel_bias_states: bool | None = None
    accel_bias_mps2: float | None = None
    given: frozenset | None = None

    def __post_init__(self):
        self.validate()
        if self.given is None:
            self.given = frozenset(
                f.name
                for f in dataclasses.fields(self)
                if f.name not in _INTERNAL and f.name not in _BOOL_KEYS and getattr(self, f.name) != f.default
            )

    def validate(self, key_path: str = "model") -> None:
        """Raise :class:`ConfigError` naming the key for a value the ``model`` section refuses
        (the schema, :class:`gravsurvey.settings.ModelSection`, is the one rule)."""
        from ..settings import check_inm_params

        check_inm_params(self, key_path)

    def to_dict(self) -> dict:
        """Plain mapping of the settings (for reports)."""
        return {k: v for k, v in dataclasses.asdict(self).items() if k not in _INTERNAL}

    @property
    def gyro_drift_radps(self) -> float:
        """sigma_nu in rad/s."""
        return math.radians(self.gyro_drift_degph) / 3600.0


def accel_bias_states_for(params: InmParams, triad: str) -> bool:
    """Whether the GNSS-aided filter carries the horizontal accelerometer biases (16 states).

    ``params.accel_bias_states`` when the config gives it; else on, for either triad.  On a
    straight leg a horizontal bias ``b`` is indistinguishable from a tilt ``b / g``; in a turn
    that tilt would put ``b |f_h| / g`` into the vertical channel, which a bias does not.  On
    the unseen-flight suite the platform flights gain (quick U230 0.40 -> 0.22 mGal, U215 0.48
    -> 0.21); the strapdown flights with the suite's navigation-grade biases are even on
    balance (quick U016 0.81 -> 0.77, U003 0.20 -> 0.22; issue flight IC07 0.21 -> 0.19), and a
    tactical IMU's (1e-2 m/s^2) without them is off by 12.9 mGal for 1.08 (quick U001), so
    since 2026-12-05 strapdown carries them by default too (docs/benchmarks.md, "The
    accelerometer-bias states on strapdown flights").  The triad no longer decides; the
    argument stays so that a rule per triad can come back without touching the callers.
    """
    if params.accel_bias_states is not None:
        return bool(params.accel_bias_states)
    return True


def solvability_warnings(params: InmParams, speed_mps) -> list[str]:
    """Warn when the anomaly and gravimeter-error models become inseparable (seed 004).

    At ground speed ``v`` the anomaly's time correlation rate is
    ``lambda_g = lambda_s v``; if it is within a factor 2 of ``lambda_f3`` the
    filter can hardly tell g from f3.

    Parameters
    ----------
    params : InmParams
    speed_mps : float or array_like
        Ground speed(s), m/s; e.g. the median speed of each line.

    Returns
    -------
    list of str
        One message per offending speed value (empty when all are fine).
    """
    out = []
    lam_f = params.gravimeter_lambda_per_s
    for v in np.atleast_1d(np.asarray(speed_mps, dtype=float)):
        lam_g = params.anomaly_lambda_per_m * v
        if lam_f > 0 and lam_g > 0 and 0.5 <= lam_g / lam_f <= 2.0:
            out.append(
                f"solvability: lambda_s*v = {lam_g:.3g} 1/s at v = {v:.1f} m/s is within a factor 2 of "
                f"gravimeter_lambda_per_s = {lam_f:.3g} 1/s; anomaly and gravimeter error are hard to separate"
            )
    return out


@dataclass
class InitialState:
    """Navigation state at the first IMU sample.

    Attributes
    ----------
    lat, lon : float
        Geodetic latitude and longitude, rad.
    height : float
        Ellipsoidal height, m.
    vel_n : ndarray, shape (3,)
        Velocity relative to the Earth, ENU, m/s.
    mat_nt : ndarray, shape (3, 3)
        Triad -> local ENU rotation (identity for an ENU platform).
    attitude_cov_t : ndarray, shape (3, 3), or None
        Covariance of the attitude error on the triad axes, rad^2, when the attitude comes
        from the coarse alignment (:mod:`gravsurvey.inm.alignment`); None when it was given.
    alignment : Alignment or None
        The coarse alignment the attitude came from (method, sigmas, time to converge).
    """

    lat: float
    lon: float
    height: float
    vel_n: np.ndarray = field(default_factory=lambda: np.zeros(3))
    mat_nt: np.ndarray = field(default_factory=lambda: np.eye(3))
    attitude_cov_t: np.ndarray | None = None
    alignment: object | None = None


def mat_nb_from_attitude(roll, pitch, heading):
    """Body (forward, left, up) -> ENU rotation from roll, pitch, heading (rad).

    ``mat_nb = Rz(pi/2 - heading) @ Ry(-pitch) @ Rx(roll)`` (docs/conventions.md):
    heading clockwise from north, pitch nose up, roll right wing down.
    """

    def rx(a):
        c, s = math.cos(a), math.sin(a)
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])

    def ry(a):
        c, s = math.cos(a), math.sin(a)
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])

    def rz(a):
        c, s = math.cos(a), math.sin(a)
        return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])

    return rz(0.5 * math.pi - heading) @ ry(-pitch) @ rx(roll)


def _check_triad(triad, key_path):
    if triad not in TRIADS:
        raise ConfigError(f"{key_path}: triad must be 'platform' or 'strapdown', got {triad!r}")


def initial_state_from_gnss(record, triad: str, attitude_deg=None, params=None, ellipsoid=None) -> InitialState:
    """Initial state from the data at the first IMU sample.

    Position and velocity come from a quadratic least-squares fit to the GNSS
    positions over the first 10 s (at least 3 samples); where the first fix came more than
    ``alignment.MAX_GNSS_LEAD_S`` after the first IMU sample and the IMU rests until past it
    (:func:`~gravsurvey.inm.alignment.rest_through_gnss_lead`), the mean of the first fixes at
    rest and a zero velocity.  A record moving before a late first fix cannot be placed: the
    pipeline starts its estimate at the fix (:func:`gravsurvey.consistency.plan_segments`).  A platform triad is
    ENU; a strapdown triad takes ``attitude_deg`` [roll, pitch, heading] when
    given, else the coarse alignment (:func:`gravsurvey.inm.alignment.align`), whose
    covariance and report travel with the state.

    Raises
    ------
    ConfigError
        No usable GNSS data.
    DataError
        A strapdown record that cannot be aligned.
    """
    _check_triad(triad, "triad")
    gn = record.gnss
    if gn is None or len(gn.time) < 3:
        raise ConfigError("initial: no GNSS channel (>= 3 samples) to initialise from; give an 'initial:' block")
    cov, alignment = None, None
    if triad == "strapdown":
        if attitude_deg is None:
            from ..geodesy import WGS84
            from .alignment import align

            alignment = align(record, params, ellipsoid or WGS84)
            mat_nt, cov = alignment.mat_nt, alignment.cov_t
        else:
            mat_nt = mat_nb_from_attitude(*np.radians(np.asarray(attitude_deg, dtype=float)))
    else:
        mat_nt = np.eye(3)
    t0 = float(record.imu.time[0])
    t = np.asarray(gn.time, dtype=float)
    from .alignment import GNSS_LEAD_REST_S, MAX_GNSS_LEAD_S, gnss_lead_s, rest_through_gnss_lead

    if gnss_lead_s(record) > MAX_GNSS_LEAD_S and rest_through_gnss_lead(record):
        # a fix that came after power-on, the aircraft parked until past it: the first fixes are
        # the position at the first IMU sample (a fit extrapolated back over the wait amplified
        # their noise: 79 m off after a 60-s wait), at rest
        ok = np.isfinite(gn.lat) & np.isfinite(gn.lon) & np.isfinite(gn.height)
        sel = np.flatnonzero(ok & (t <= t[ok][0] + GNSS_LEAD_REST_S))
        return InitialState(
            float(np.mean(np.asarray(gn.lat, float)[sel])),
            float(np.mean(np.unwrap(np.asarray(gn.lon, float)[sel]))),
            float(np.mean(np.asarray(gn.height, float)[sel])),
            np.zeros(3),
            mat_nt,
            cov,
            alignment,
        )
    sel = np.flatnonzero(t <= t[0] + 10.0)
    if sel.size < 3:
        sel = np.arange(min(3, t.size))
    from ..geodesy import radii_of_curvature

    tt = t[sel] - t0
    lat = np.asarray(gn.lat, dtype=float)[sel]
    lon = np.unwrap(np.asarray(gn.lon, dtype=float)[sel])
    hh = np.asarray(gn.height, dtype=float)[sel]
    deg = 2 if sel.size >= 4 else 1
    pl = np.polyfit(tt, lat, deg)
    po = np.polyfit(tt, lon, deg)
    ph = np.polyfit(tt, hh, deg)
    lat0, lon0, h0 = np.polyval(pl, 0.0), np.polyval(po, 0.0), np.polyval(ph, 0.0)
    m, n = radii_of_curvature(lat0)
    ve = np.polyval(np.polyder(po), 0.0) * (n + h0) * math.cos(lat0)
    vn = np.polyval(np.polyder(pl), 0.0) * (m + h0)
    vu = np.polyval(np.polyder(ph), 0.0)
    return InitialState(float(lat0), float(lon0), float(h0), np.array([ve, vn, vu]), mat_nt, cov, alignment)


#: Agreement required between an ``initial`` override and the data, in combined sigmas.
INITIAL_AGREEMENT_SIGMAS = 5.0
#: 1-sigma of the GNSS velocity fit's departure from the instantaneous velocity in flight, m/s
#: (exact initial velocities of simulated flights that start in a turn differ from it by up to 5 m/s).
VELOCITY_FIT_MODEL_SIGMA_MPS = 1.0
#: Span of the GNSS fit for the initial velocity (initial_state_from_gnss), s.
_GNSS_FIT_S = 10.0


def _gnss_fit_velocity_factor(record) -> float:
    """Velocity sigma of :func:`initial_state_from_gnss`'s fit per metre of GNSS noise, 1/s."""
    t = np.asarray(record.gnss.time, float)
    sel = np.flatnonzero(t <= t[0] + _GNSS_FIT_S)
    if sel.size < 3:
        sel = np.arange(min(3, t.size))
    tt = t[sel] - float(record.imu.time[0])
    deg = 2 if sel.size >= 4 else 1
    x = np.vander(tt, deg + 1, increasing=True)
    cov = np.linalg.pinv(x.T @ x)
    return float(math.sqrt(max(cov[1, 1], 0.0)))


def resolve_initial_state(
    record, triad: str, params: InmParams | None = None, ellipsoid=None, given=None, key_path: str = "initial"
) -> InitialState:
    """Initial state from the data, with the config's ``initial`` keys as checked overrides.

    Position, velocity (GNSS fit) and, for a strapdown triad, attitude (coarse alignment)
    come from the data.  Each key of ``given`` replaces its value after a check: a value
    that disagrees with the data by more than :data:`INITIAL_AGREEMENT_SIGMAS` combined
    sigmas (its stated ``model.initial_*_sigma`` and the data's) is a :class:`ConfigError`
    naming the key.  A given attitude is used when it is consistent and its sigma
    (``model.initial_attitude_sigma_deg``, default 0.05 deg) beats the alignment's.
    Without GNSS the position and velocity keys are required.

    Parameters
    ----------
    record : FlightRecord
    triad : {"platform", "strapdown"}
    params : InmParams, optional
    ellipsoid : Ellipsoid, optional
    given : dict, optional
        From :func:`gravsurvey.settings.initial_overrides`.
    key_path : str
        Path of the ``initial`` block in error messages.
    """
    from ..geodesy import WGS84, radii_of_curvature

    p = params if params is not None else InmParams()
    ell = ellipsoid or WGS84
    given = dict(given or {})
    _check_triad(triad, "triad")
    gn = record.gnss
    have_gnss = gn is not None and len(gn.time) >= 3
    from .errormodel import GIVEN_ATTITUDE_SIGMA_DEG

    s_att = math.radians(
        GIVEN_ATTITUDE_SIGMA_DEG if p.initial_attitude_sigma_deg is None else p.initial_attitude_sigma_deg
    )
    att_given = given.get("attitude_deg")
    if not have_gnss:
        for k in ("lat_deg", "lon_deg", "height_m", "velocity_enu_mps"):
            if k not in given:
                raise ConfigError(
                    f"{key_path}.{k}: missing; the record has no GNSS (>= 3 samples) to take the initial "
                    "position and velocity from"
                )
        mat_nt, cov, alignment = np.eye(3), None, None
        if triad == "strapdown":
            if att_given is not None:
                mat_nt = mat_nb_from_attitude(*np.radians(att_given))
            else:
                from .alignment import align

                alignment = align(record, p, ell, lat=math.radians(given["lat_deg"]))
                mat_nt, cov = alignment.mat_nt, alignment.cov_t
        return InitialState(
            math.radians(given["lat_deg"]),
            math.radians(given["lon_deg"]),
            given["height_m"],
            np.asarray(given["velocity_enu_mps"], float),
            mat_nt,
            cov,
            alignment,
        )
    try:
        base = initial_state_from_gnss(record, triad, None, params=p, ellipsoid=ell)
    except DataError:
        if triad != "strapdown" or att_given is None:
            raise
        # the data cannot align this triad (no static period, no usable motion): the given
        # attitude is all there is; it cannot be checked
        base = initial_state_from_gnss(record, triad, att_given, params=p, ellipsoid=ell)
    m, n = radii_of_curvature(base.lat, ell)
    k = INITIAL_AGREEMENT_SIGMAS
    from .alignment import MAX_GNSS_LEAD_S, gnss_lead_s, rest_through_gnss_lead

    if gnss_lead_s(record) > MAX_GNSS_LEAD_S and not rest_through_gnss_lead(record):
        # the first fix came late and the aircraft moved before it: the data cannot place the
        # first IMU sample, so the given values are taken as they are
        k = math.inf
    s_h = math.hypot(p.initial_position_sigma_m, p.gnss_horizontal_sigma_m)
    s_v = math.hypot(p.initial_position_sigma_m, p.gnss_vertical_sigma_m)
    # the GNSS fit's own velocity sigma (quadratic least squares, derivative at the first IMU sample)
    s_fit = _gnss_fit_velocity_factor(record)
    # plus the fit's model error: a quadratic over the fit span does not follow an aircraft's
    # gusts and manoeuvres (measured: 0.3-5 m/s between the exact initial velocity and the fit
    # on simulated flights), which no GNSS noise figure describes
    s_vel_h = math.hypot(p.initial_velocity_sigma_mps, p.gnss_horizontal_sigma_m * s_fit, VELOCITY_FIT_MODEL_SIGMA_MPS)
    s_vel_v = math.hypot(p.initial_velocity_sigma_mps, p.gnss_vertical_sigma_m * s_fit, VELOCITY_FIT_MODEL_SIGMA_MPS)
    lat = math.radians(given["lat_deg"]) if "lat_deg" in given else base.lat
    lon = math.radians(given["lon_deg"]) if "lon_deg" in given else base.lon
    d_n = (lat - base.lat) * (m + base.height)
    d_e = (((lon - base.lon + math.pi) % (2 * math.pi)) - math.pi) * (n + base.height) * math.cos(base.lat)
    for key, dist in (("lat_deg", abs(d_n)), ("lon_deg", abs(d_e))):
        if key in given and dist > k * s_h:
            raise ConfigError(
                f"{key_path}.{key}: {given[key]} deg is {dist:.4g} m from the GNSS position at the first "
                f"IMU sample (allowed {k:g} x {s_h:.3g} m from model.initial_position_sigma_m and "
                "model.gnss_horizontal_sigma_m); fix or remove it"
            )
    height = given.get("height_m", base.height)
    if abs(height - base.height) > k * s_v:
        raise ConfigError(
            f"{key_path}.height_m: {height} m differs from the GNSS height {base.height:.2f} m by more "
            f"than {k:g} x {s_v:.3g} m; fix or remove it"
        )
    vel = np.asarray(given.get("velocity_enu_mps", base.vel_n), float)
    dv = np.abs(vel - base.vel_n)
    if dv[0] > k * s_vel_h or dv[1] > k * s_vel_h or dv[2] > k * s_vel_v:
        fmt = ", ".join
        raise ConfigError(
            f"{key_path}.velocity_enu_mps: [{fmt(f'{x:.3f}' for x in vel)}] m/s differs from the GNSS velocity "
            f"[{fmt(f'{x:.3f}' for x in base.vel_n)}] m/s by more than {k:g} sigma ({s_vel_h:.3g} m/s horizontal, "
            f"{s_vel_v:.3g} m/s up, from model.initial_velocity_sigma_mps and the GNSS fit); fix or remove it"
        )
    mat_nt, cov, alignment = base.mat_nt, base.attitude_cov_t, base.alignment
    if triad == "strapdown" and att_given is not None and alignment is None:
        mat_nt, cov = mat_nb_from_attitude(*np.radians(att_given)), None
    elif triad == "strapdown" and att_given is not None:
        from scipy.spatial.transform import Rotation

        m_given = mat_nb_from_attitude(*np.radians(att_given))
        th_n = Rotation.from_matrix(m_given @ mat_nt.T).as_rotvec()
        lev, head = math.hypot(th_n[0], th_n[1]), abs(th_n[2])
        s_lev = math.hypot(s_att, alignment.sigma_level_rad)
        s_head = math.hypot(s_att, alignment.sigma_heading_rad)
        if lev > k * s_lev or head > k * s_head:
            al = alignment.attitude_deg()
            raise ConfigError(
                f"{key_path}.attitude_deg: {list(np.round(att_given, 3))} (roll, pitch, heading) disagrees with the "
                f"alignment from the data ({al[0]:.3f}, {al[1]:.3f}, {al[2] % 360:.3f}) by {math.degrees(lev):.3g} deg "
                f"level, {math.degrees(head):.3g} deg heading (allowed {k:g} x {math.degrees(s_lev):.2g} / "
                f"{math.degrees(s_head):.2g} deg with model.initial_attitude_sigma_deg); fix or remove it"
            )
        if s_att < alignment.sigma_heading_rad:
            mat_nt, cov = m_given, None
    return InitialState(lat, lon, height, vel, mat_nt, cov, alignment)
