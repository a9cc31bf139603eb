"""Simulator orchestration: SIM config -> exact truth + noisy sensor samples -> files.

Public API
----------
* :func:`simulate_flight` - one flight in memory (:class:`FlightSimulation`);
* :func:`simulate_to_dir` - a whole survey on disk (logs, truth.csv per flight,
  one ``survey.yaml`` processing config), what ``gravsurvey simulate`` runs;
* :func:`quick_sim` - a small valid SIM mapping for tests;
* :func:`load_sim_config` - re-exported from :mod:`.simconfig`.

Random streams: flight ``k`` of a config with ``seed`` draws turbulence, IMU,
altimeter, GNSS and the Markov field from independent generators
``numpy.random.default_rng([seed, k, stream])``, so output is reproducible to
the byte and switching one error source on leaves the others unchanged.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from gravsurvey.errors import ConfigError
from gravsurvey.geodesy import wrap_deg

from .sensors import (
    DEGPH,
    ImuErrors,
    altimeter_errors,
    antenna_position,
    gnss_errors,
    imu_errors,
    specific_force_n,
    total_gravitation_n,
    triad_outputs,
)
from .simconfig import SimConfig, load_sim_config
from .trajectory import FlightPlan, Kinematics, build_plan, earth_rate_n, kinematics, mat_ne

__all__ = [
    "FlightSimulation",
    "simulate_flight",
    "gravimeter_slow_error",
    "simulate_to_dir",
    "quick_sim",
    "load_sim_config",
    "sample_times_ns",
    "oracle_model_block",
    "matched_anomaly_prior",
    "user_model_block",
    "user_initial_block",
]

MGAL = 1e-5
_STREAM_TURBULENCE, _STREAM_IMU, _STREAM_ALT, _STREAM_GNSS, _STREAM_FIELD = range(5)
_STREAM_GRADIOMETER = 5


@dataclass
class FlightSimulation:
    """One simulated flight.

    Times are float64 seconds after ``start_unix_ns`` (``*_time``) and integer
    Unix ns (``*_time_ns``); sample ``k`` of a sensor at rate ``R`` is at
    ``start_unix_ns + round(k * 1e9 / R)``.

    Attributes
    ----------
    name, triad : str
    start_unix_ns : int
    imu_time : ndarray (n,)
    specific_force_t, angular_rate_t : ndarray (n, 3)
        Sensor outputs with the configured errors, m/s^2 and rad/s, on the triad.
    noise_free_specific_force_t, noise_free_angular_rate_t : ndarray (n, 3)
        The exact outputs.
    alt_time, alt_height : ndarray (m,)
        Altimeter (ellipsoidal height with errors), m.
    gnss_time, gnss_lat_deg, gnss_lon_deg, gnss_height : ndarray (k,)
        The fixes: the antenna's position (``sensors.gnss.antenna_m`` from the IMU, turned
        with the aircraft) with the GNSS errors, deg and m.
    truth : dict
        At IMU times: ``time`` (s), ``lat``, ``lon`` (rad), ``height`` (m),
        ``vel_n`` (n, 3) ENU m/s, ``acc_n`` (n, 3) Earth-relative acceleration
        on ENU, m/s^2, ``mat_nt`` (n, 3, 3) triad -> ENU, ``mat_nb`` body ->
        ENU, ``roll``, ``pitch``, ``heading`` (rad), ``anomaly_n`` (n, 3)
        anomalous gravitation on ENU (m/s^2), ``disturbance`` (n,) m/s^2
        (``-anomaly_n[:, 2]``), ``dg_north``, ``dg_east`` (n,) the horizontal disturbance
        ``g_true - gamma`` north and east, m/s^2 (``anomaly_n[:, 1]``, ``anomaly_n[:, 0]``:
        exact for a ``model`` field, zero for the along-track field types), ``gravitation_n`` (n, 3) total gravitation,
        ``line`` (n,) segment names, ``distance`` (n,) along-track ground
        distance (m); sensor-error truth ``accel_error_t`` (n, 3) m/s^2,
        ``gravimeter_error`` (n,) (= ``accel_error_t[:, 2]``),
        ``gravimeter_markov`` (n,), ``gravimeter_drift`` (n,) (the linear drift),
        ``gyro_error_t`` (n, 3) rad/s,
        ``altimeter_error`` (m,) m at altimeter times, ``gnss_error`` (k, 3)
        (dlat rad, dlon rad, dh m) at GNSS times.
    truth_table : dict
        The truth.csv columns (docs/formats.md) at ``rates.truth_hz``.
    flight : dict
        The validated flight config.
    plan : FlightPlan
    """

    name: str
    triad: str
    start_unix_ns: int
    imu_time_ns: np.ndarray
    imu_time: np.ndarray
    specific_force_t: np.ndarray
    angular_rate_t: np.ndarray
    noise_free_specific_force_t: np.ndarray
    noise_free_angular_rate_t: np.ndarray
    alt_time_ns: np.ndarray
    alt_time: np.ndarray
    alt_height: np.ndarray
    gnss_time_ns: np.ndarray
    gnss_time: np.ndarray
    gnss_lat_deg: np.ndarray
    gnss_lon_deg: np.ndarray
    gnss_height: np.ndarray
    truth: dict
    truth_table: dict
    flight: dict
    plan: FlightPlan
    imu_errors: ImuErrors = field(repr=False, default=None)
    # optional gravity-gradiometer channel (sensors.gradiometer.rate_hz > 0): times (ns and s),
    # the 6 triad components xx, xy, xz, yy, yz, zz with errors, Eotvos, and their error truth
    gradient_time_ns: np.ndarray | None = None
    gradient_time: np.ndarray | None = None
    gradient_t_eotvos: np.ndarray | None = None
    gradient_error_eotvos: np.ndarray | None = None


def _gradient_channel(plan, cfg: SimConfig, f: dict, flight_index: int, ell):
    """Gradiometer samples of one flight: times ns (j,), components with errors and errors, E (j, 6).

    The truth is the normal field's gradient plus the exact tensor of the field model's
    sources (``field.type: model``; along-track anomaly types have no spatial tensor, so
    only the normal field's is written), rotated to the triad.
    """
    from .field import EOTVOS, total_gradient_n
    from .sensors import gradient_triad_components, gradiometer_errors

    rate = f["sensors"]["gradiometer"]["rate_hz"]
    t_ns = sample_times_ns(plan.duration, rate)
    comps = np.empty((t_ns.size, 6))
    model = cfg.field_model if (cfg.field_model is not None and cfg.field_model.type == "model") else None
    for sl in _chunks(t_ns.size):
        kin = kinematics(plan, t_ns[sl] / 1e9)
        gam_n = total_gradient_n(model, kin.r_e, kin.lat, kin.lon, ell)
        mat_nt = np.broadcast_to(np.eye(3), gam_n.shape) if f["triad"] == "platform" else kin.mat_nb
        comps[sl] = gradient_triad_components(gam_n, mat_nt) / EOTVOS
    err = gradiometer_errors(t_ns.size, rate, f["sensors"], _rng(cfg, flight_index, _STREAM_GRADIOMETER))
    return t_ns, comps + err, err


def sample_times_ns(duration_s, rate_hz):
    """Relative sample times ``round(k * 1e9 / rate)`` (int64 ns) for ``k`` with time <= duration."""
    n = int(math.floor(duration_s * rate_hz + 1e-9)) + 1
    k = np.arange(n, dtype=np.int64)
    if float(rate_hz).is_integer():
        r = int(rate_hz)
        return (k * 1_000_000_000 + r // 2) // r
    return np.round(k * (1e9 / rate_hz)).astype(np.int64)


def _rng(cfg: SimConfig, index: int, stream: int):
    return np.random.default_rng([cfg.seed, index, stream])


#: IMU samples evaluated at once: bounds the temporaries (attitude matrices, turbulence
#: sums) to ~100 MB whatever the flight length.
CHUNK = 131072


def _chunks(n):
    for i in range(0, n, CHUNK):
        yield slice(i, min(n, i + CHUNK))


def _distance(t, vel_n):
    """Along-track ground distance (m) by the trapezoid rule over the samples."""
    v = np.hypot(vel_n[:, 0], vel_n[:, 1])
    d = np.zeros_like(v)
    if v.size > 1:
        d[1:] = np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))
    return d


class _Anomaly:
    """Anomalous gravitation (ENU) of the configured field along one flight.

    Position fields (``model``) and time functions (``seed_*``) are evaluated
    directly; the ``markov`` realisation lives on the IMU grid (set by
    :meth:`realise`), other times interpolate it linearly.
    """

    def __init__(self, cfg: SimConfig, index: int):
        self.model = cfg.field_model
        self.kind = None if self.model is None else self.model.type
        self.rng = np.random.default_rng([cfg.seed, 0 if self.model is None else self.model.seed, index, _STREAM_FIELD])
        self.t_grid = None
        self.markov = None

    def realise(self, t_grid, dist):
        """Draw the Markov realisation along the IMU grid; returns it (m/s^2) or None."""
        if self.kind != "markov":
            return None
        from .field import markov_disturbance

        self.t_grid = t_grid
        self.markov = markov_disturbance(dist, self.model.lambda_s_per_m, self.model.sigma_mps2, self.rng)
        return self.markov

    def __call__(self, kin: Kinematics):
        n = kin.t.shape[0]
        out = np.zeros((n, 3))
        if self.kind is None:
            return out
        if self.kind == "model":
            from .field import anomalous_gravitation_ecef

            g_e = anomalous_gravitation_ecef(self.model, kin.r_e)
            out = np.einsum("nij,nj->ni", mat_ne(kin.lat, kin.lon), g_e)
            if not self.model.horizontal:
                out[:, :2] = 0.0
            return out
        if self.kind in ("seed_smooth", "seed_steps"):
            from .field import seed_smooth_disturbance, seed_steps_disturbance

            fn = seed_smooth_disturbance if self.kind == "seed_smooth" else seed_steps_disturbance
            out[:, 2] = -fn(kin.t)
            return out
        if self.kind == "markov":
            if self.markov is not None:
                out[:, 2] = -np.interp(kin.t, self.t_grid, self.markov)
            return out
        raise ConfigError(f"field.type: unsupported {self.kind!r}")  # pragma: no cover


def _imu_truth(plan, t, anomaly: _Anomaly, ell, triad):
    """Exact truth and ideal IMU outputs at the IMU times, evaluated in chunks."""
    n = t.shape[0]
    v3 = ("vel_n", "acc_n", "anomaly_n", "gravitation_n", "specific_force_n", "w_in", "w_nb_b")
    out = {k: np.empty((n, 3)) for k in v3}
    for k in ("lat", "lon", "height", "roll", "pitch", "heading"):
        out[k] = np.empty(n)
    out["mat_nb"] = np.empty((n, 3, 3))
    out["line"] = np.empty(n, dtype=object)
    for sl in _chunks(n):
        kin = kinematics(plan, t[sl])
        an = anomaly(kin)
        grav = total_gravitation_n(kin, an, ell)
        out["specific_force_n"][sl] = specific_force_n(kin, grav, ell.omega)
        out["anomaly_n"][sl] = an
        out["gravitation_n"][sl] = grav
        out["w_in"][sl] = earth_rate_n(kin.lat, ell.omega) + kin.w_en
        out["w_nb_b"][sl] = kin.w_nb_b
        for k in ("lat", "lon", "height", "roll", "pitch", "heading", "vel_n", "acc_n", "mat_nb"):
            out[k][sl] = getattr(kin, k)
        out["line"][sl] = kin.label
    out["distance"] = _distance(t, out["vel_n"])
    markov = anomaly.realise(t, out["distance"])
    if markov is not None:
        # vertical only: the gravitation gains -markov on Up, F = a - G gains +markov
        out["anomaly_n"][:, 2] = -markov
        out["gravitation_n"][:, 2] -= markov
        out["specific_force_n"][:, 2] += markov
    f_t, w_t, mat_nt = triad_outputs(out["specific_force_n"], out["w_in"], out["mat_nb"], out["w_nb_b"], triad)
    return out, f_t, w_t, mat_nt


def _truth_table(plan, t_rel, start_ns, t_ns, anomaly: _Anomaly):
    """truth.csv columns (docs/formats.md) at the times ``t_rel`` (s)."""
    from .logs import TRUTH_COLUMNS

    # every truth.csv column but the two this function fills otherwise (time_ns, line)
    cols = {k: np.empty(t_rel.shape[0]) for k in TRUTH_COLUMNS[2:]}
    line = np.empty(t_rel.shape[0], dtype=object)
    for sl in _chunks(t_rel.shape[0]):
        kin = kinematics(plan, t_rel[sl])
        an = anomaly(kin)
        line[sl] = kin.label
        cols["lat_deg"][sl] = np.degrees(kin.lat)
        # written as a receiver writes it; the survey map's longitude runs on across 180 deg
        cols["lon_deg"][sl] = wrap_deg(np.degrees(kin.lon))
        cols["height_m"][sl] = kin.height
        cols["ve_mps"][sl], cols["vn_mps"][sl], cols["vu_mps"][sl] = kin.vel_n.T
        cols["roll_deg"][sl] = np.degrees(kin.roll)
        cols["pitch_deg"][sl] = np.degrees(kin.pitch)
        cols["heading_deg"][sl] = np.degrees(kin.heading)
        cols["disturbance_mgal"][sl] = -an[:, 2] / MGAL + 0.0
        cols["anomaly_e_mgal"][sl] = an[:, 0] / MGAL
        cols["anomaly_n_mgal"][sl] = an[:, 1] / MGAL
        cols["anomaly_u_mgal"][sl] = an[:, 2] / MGAL
        cols["dg_north_mgal"][sl] = an[:, 1] / MGAL + 0.0
        cols["dg_east_mgal"][sl] = an[:, 0] / MGAL + 0.0
    out = {"time_ns": t_ns + start_ns, "line": line.astype(str)}
    out.update(cols)
    return out


def simulate_flight(sim, flight_index: int = 0) -> FlightSimulation:
    """Simulate one flight of a SIM config in memory.

    Parameters
    ----------
    sim : dict, path or SimConfig
        The simulation config (validated here if not already).
    flight_index : int
        Which flight of ``sim["flights"]``.

    Returns
    -------
    FlightSimulation
    """
    cfg, f, plan, imu_ns, errs = _plan_and_imu_errors(sim, flight_index)
    ell = cfg.ellipsoid
    rates = f["rates"]
    dur = plan.duration
    t_imu = imu_ns / 1e9
    anomaly = _Anomaly(cfg, flight_index)
    tru, f_t, w_t, mat_nt = _imu_truth(plan, t_imu, anomaly, ell, f["triad"])

    alt_ns = sample_times_ns(dur, rates["altimeter_hz"])
    kin_alt = kinematics(plan, alt_ns / 1e9)
    alt_err = altimeter_errors(alt_ns.shape[0], f["sensors"], _rng(cfg, flight_index, _STREAM_ALT))

    gnss_ns = sample_times_ns(dur, rates["gnss_hz"])
    kin_g = kinematics(plan, gnss_ns / 1e9)
    dlat, dlon, dh = gnss_errors(
        kin_g.lat, kin_g.height, f["sensors"], _rng(cfg, flight_index, _STREAM_GNSS), ell, 1.0 / rates["gnss_hz"]
    )
    # the fixes are the antenna's; its errors are drawn as at the IMU (the same metres)
    ant_lat, ant_lon, ant_h = kin_g.lat, kin_g.lon, kin_g.height
    if any(x != 0.0 for x in f["sensors"]["gnss"]["antenna_m"]):
        ant_lat, ant_lon, ant_h = antenna_position(kin_g, f["sensors"]["gnss"]["antenna_m"], ell)

    truth = {
        "time": t_imu,
        "lat": tru["lat"],
        "lon": tru["lon"],
        "height": tru["height"],
        "vel_n": tru["vel_n"],
        "acc_n": tru["acc_n"],
        "mat_nt": mat_nt,
        "mat_nb": tru["mat_nb"],
        "roll": tru["roll"],
        "pitch": tru["pitch"],
        "heading": tru["heading"],
        "anomaly_n": tru["anomaly_n"],
        "disturbance": -tru["anomaly_n"][:, 2] + 0.0,
        "dg_north": tru["anomaly_n"][:, 1] + 0.0,
        "dg_east": tru["anomaly_n"][:, 0] + 0.0,
        "gravitation_n": tru["gravitation_n"],
        "specific_force_n": tru["specific_force_n"],
        "line": tru["line"],
        "distance": tru["distance"],
        "accel_error_t": errs.accel_t,
        "gravimeter_error": errs.accel_t[:, 2].copy(),
        "gravimeter_markov": errs.gravimeter_markov,
        "gravimeter_drift": errs.gravimeter_drift,
        "gyro_error_t": errs.gyro_t,
        "altimeter_error": alt_err,
        "gnss_error": np.stack([dlat, dlon, dh], axis=-1),
    }
    start = int(f["start_unix_ns"])
    grad = {}
    if f["sensors"]["gradiometer"]["rate_hz"] > 0:
        g_ns, g_val, g_err = _gradient_channel(plan, cfg, f, flight_index, ell)
        grad = {
            "gradient_time_ns": g_ns + start,
            "gradient_time": g_ns / 1e9,
            "gradient_t_eotvos": g_val,
            "gradient_error_eotvos": g_err,
        }
    tr_ns = sample_times_ns(dur, rates["truth_hz"])
    truth_table = _truth_table(plan, tr_ns / 1e9, start, tr_ns, anomaly)
    return FlightSimulation(
        name=f["name"],
        triad=f["triad"],
        start_unix_ns=start,
        imu_time_ns=imu_ns + start,
        imu_time=t_imu,
        specific_force_t=f_t + errs.accel_t,
        angular_rate_t=w_t + errs.gyro_t,
        noise_free_specific_force_t=f_t,
        noise_free_angular_rate_t=w_t,
        alt_time_ns=alt_ns + start,
        alt_time=alt_ns / 1e9,
        alt_height=kin_alt.height + alt_err,
        gnss_time_ns=gnss_ns + start,
        gnss_time=gnss_ns / 1e9,
        gnss_lat_deg=np.degrees(ant_lat + dlat),
        gnss_lon_deg=wrap_deg(np.degrees(ant_lon + dlon)),
        gnss_height=ant_h + dh,
        truth=truth,
        truth_table=truth_table,
        flight=f,
        plan=plan,
        imu_errors=errs,
        **grad,
    )


def gravimeter_slow_error(sim, flight_index: int = 0):
    """The slow part of one simulated flight's gravimeter error, as :func:`simulate_flight` draws it.

    The bias plus the Gauss-Markov error and the linear drift (the white part left out), from the same random streams
    as the simulation but without its kinematics, field and logs: for scoring how much of an
    estimate's error is the drift a flight cannot tell from the field (benchmarks/bench_unseen.py).

    Parameters
    ----------
    sim : dict, path or SimConfig
    flight_index : int

    Returns
    -------
    time_unix_ns : ndarray (n,), int64
        IMU sample times, Unix ns.
    error_mps2 : ndarray (n,)
        ``bias + Markov + drift`` of the gravimeter (third accelerometer), m/s^2; equal to
        ``truth["gravimeter_markov"] + truth["gravimeter_drift"] + bias`` of :func:`simulate_flight`.
    """
    # the plan's duration sets the sample count; only the errors of the simulation are needed
    _, f, _, imu_ns, errs = _plan_and_imu_errors(sim, flight_index)
    bias = float(f["sensors"]["gravimeter"]["bias_mps2"])
    return imu_ns + int(f["start_unix_ns"]), bias + errs.gravimeter_markov + errs.gravimeter_drift


def _plan_and_imu_errors(sim, flight_index: int):
    """One flight's config, plan, IMU sample times (ns from its start) and IMU errors, drawn from
    the simulation's own random streams (each stream its own generator, so the order of the
    draws does not matter): ``(cfg, flight, plan, imu_ns, errors)``."""
    cfg = load_sim_config(sim)
    if not 0 <= flight_index < len(cfg.flights):
        raise ConfigError(f"flights: no flight with index {flight_index} (the config has {len(cfg.flights)})")
    f = cfg.flights[flight_index]
    plan = build_plan(f["plan"], f["turbulence"], _rng(cfg, flight_index, _STREAM_TURBULENCE), cfg.ellipsoid)
    imu_ns = sample_times_ns(plan.duration, f["rates"]["imu_hz"])
    errs = imu_errors(imu_ns.shape[0], f["rates"]["imu_hz"], f["sensors"], _rng(cfg, flight_index, _STREAM_IMU))
    return cfg, f, plan, imu_ns, errs


# --------------------------------------------------------------------------
# Quick configs for tests
# --------------------------------------------------------------------------

#: Sensor errors of the seed benchmark (model.md section 3, our reading).
SEED_SENSORS = {
    "accelerometer": {"white_sigma_mps2": 1.0e-3},
    "gravimeter": {"markov_sigma_mps2": 1.0e-6, "markov_lambda_per_s": 0.025},
    "gyro": {"white_drift_degph": 0.01},
    "altimeter": {"sigma_m": 1.0},
}


def quick_sim(**overrides) -> dict:
    """A small valid SIM mapping: a straight flight due east, noiseless by default.

    Keyword overrides (all optional): ``duration_s`` (1200), ``imu_hz`` (10),
    ``altimeter_hz`` (1), ``gnss_hz`` (1), ``truth_hz``, ``triad``
    ("platform"), ``speed_mps`` (50), ``altitude_m`` (1000), ``heading_deg``
    (90), ``lat_deg`` (45), ``lon_deg`` (135), ``field`` (None, a field type
    string such as "seed_smooth", or a full ``field`` mapping), ``noise``
    (False; True = the seed's sensor errors, or a ``sensors`` mapping),
    ``turbulence`` (mapping), ``plan`` (mapping replacing the plan), ``seed``
    (0), ``formats`` (["mcap_json"]), ``start_utc``, ``name``.
    """
    o = dict(overrides)
    unknown = set(o) - {
        "duration_s",
        "imu_hz",
        "altimeter_hz",
        "gnss_hz",
        "truth_hz",
        "triad",
        "speed_mps",
        "altitude_m",
        "heading_deg",
        "lat_deg",
        "lon_deg",
        "field",
        "noise",
        "turbulence",
        "plan",
        "seed",
        "formats",
        "start_utc",
        "name",
        "static_start_s",
        "static_end_s",
    }
    if unknown:
        raise TypeError(f"quick_sim: unknown overrides {sorted(unknown)}")
    plan = o.get("plan") or {
        "kind": "line",
        "origin_lat_deg": o.get("lat_deg", 45.0),
        "origin_lon_deg": o.get("lon_deg", 135.0),
        "altitude_m": o.get("altitude_m", 1000.0),
        "speed_mps": o.get("speed_mps", 50.0),
        "heading_deg": o.get("heading_deg", 90.0),
        "duration_s": o.get("duration_s", 1200.0),
        "static_start_s": o.get("static_start_s", 0.0),
        "static_end_s": o.get("static_end_s", 0.0),
    }
    rates = {
        "imu_hz": o.get("imu_hz", 10.0),
        "altimeter_hz": o.get("altimeter_hz", 1.0),
        "gnss_hz": o.get("gnss_hz", 1.0),
    }
    if "truth_hz" in o:
        rates["truth_hz"] = o["truth_hz"]
    noise = o.get("noise", False)
    sensors = copy.deepcopy(SEED_SENSORS) if noise is True else (copy.deepcopy(noise) if noise else {})
    flight = {
        "name": "F01",
        "start_utc": o.get("start_utc", "2024-06-01T08:00:00Z"),
        "triad": o.get("triad", "platform"),
        "rates": rates,
        "plan": copy.deepcopy(plan),
        "sensors": sensors,
    }
    if o.get("turbulence"):
        flight["turbulence"] = copy.deepcopy(o["turbulence"])
    sim = {
        "name": o.get("name", "quick"),
        "seed": o.get("seed", 0),
        "formats": list(o.get("formats", ["mcap_json"])),
        "flights": [flight],
    }
    fld = o.get("field")
    if isinstance(fld, str):
        sim["field"] = {"type": fld}
    elif fld is not None:
        sim["field"] = copy.deepcopy(fld)
    return sim


# --------------------------------------------------------------------------
# Writing a survey
# --------------------------------------------------------------------------


def matched_anomaly_prior(distance_m, disturbance_mps2, step_m: float = 100.0):
    """First-order Gauss-Markov parameters matched to a true along-track disturbance (ORACLE).

    The truth is resampled on a uniform ground-distance grid of ``step_m``; ``sigma`` is its
    standard deviation and ``lambda = 1 / d_e`` with ``d_e`` the lag where its
    autocorrelation first falls below ``1/e`` (the Markov model's own relation), bounded to
    ``[step_m, track length]``.

    Parameters
    ----------
    distance_m : ndarray (n,)
        Along-track ground distance, non-decreasing, m.
    disturbance_mps2 : ndarray (n,)
        True gravity disturbance at the same samples, m/s^2.
    step_m : float

    Returns
    -------
    (sigma_mps2, lambda_per_m) : tuple of float, or None when the track is shorter than
    four steps or the disturbance is constant.
    """
    d = np.asarray(distance_m, float)
    g = np.asarray(disturbance_mps2, float)
    d_u, first = np.unique(d, return_index=True)
    if d_u.size < 2 or d_u[-1] - d_u[0] < 4 * step_m:
        return None
    grid = np.arange(d_u[0], d_u[-1], step_m)
    x = np.interp(grid, d_u, g[first])
    x = x - x.mean()
    var = float(np.mean(x**2))
    if not var > 0:
        return None
    n = x.size
    spec = np.fft.rfft(x, 2 * n)
    acf = np.fft.irfft(spec * np.conj(spec))[:n] / (n - np.arange(n)) / var
    below = np.flatnonzero(acf < math.exp(-1.0))
    d_e = (below[0] if below.size else n) * step_m
    d_e = min(max(d_e, step_m), n * step_m)
    return float(math.sqrt(var)), float(1.0 / d_e)


def oracle_model_block(cfg: SimConfig, sim: FlightSimulation | None = None) -> dict:
    """The processing ``model`` block matched to the first flight's simulated errors (ORACLE).

    These are values derived from the simulator's truth, which no user has: they go only
    into ``oracle.yaml`` (``simulate_to_dir(..., oracle=True)``, ``gravsurvey simulate
    --oracle-config``), the "oracle-tuned" reference of the benchmarks, never into
    ``survey.yaml``.  A simulated error that is off is replaced by the seed's value (the
    filter needs non-zero noise); the anomaly model is the Markov field's parameters when the
    field is one, else (given the first flight's ``sim``) the Gauss-Markov parameters
    matched to its true along-track disturbance (:func:`matched_anomaly_prior`), else the
    seed's.  The GNSS sigmas are the simulated ones when the GNSS is
    noisy (else the estimator's defaults stand).  Keys of ``processing.model`` override the
    result.
    """
    processing = cfg.processing
    s = cfg.flights[0]["sensors"]

    def pick(v, seed_v):
        return float(v) if v > 0 else seed_v

    lam_s, sig_s = 1.0e-5, 1.0e-3
    if cfg.field_model is not None and cfg.field_model.type == "markov":
        lam_s, sig_s = cfg.field_model.lambda_s_per_m, cfg.field_model.sigma_mps2
    elif cfg.field_model is not None and sim is not None:
        matched = matched_anomaly_prior(sim.truth["distance"], sim.truth["disturbance"])
        if matched is not None:
            sig_s, lam_s = matched
    block = {
        "filter_rate_hz": processing["filter_rate_hz"],
        "accel_noise_mps2": pick(s["accelerometer"]["white_sigma_mps2"], 1.0e-3),
        "gyro_drift_degph": pick(s["gyro"]["white_drift_degph"], 0.01),
        "gravimeter_lambda_per_s": float(s["gravimeter"]["markov_lambda_per_s"]),
        "gravimeter_sigma_mps2": pick(s["gravimeter"]["markov_sigma_mps2"], 1.0e-6),
        "anomaly_lambda_per_m": lam_s,
        "anomaly_sigma_mps2": sig_s,
        "altimeter_sigma_m": pick(s["altimeter"]["sigma_m"], 1.0),
        "radius_source": "altimeter",
    }
    if s["gravimeter"]["white_sigma_mps2"] > 0:
        block["gravimeter_white_mps2"] = float(s["gravimeter"]["white_sigma_mps2"])
    if s["gnss"]["horizontal_sigma_m"] > 0 and s["gnss"]["vertical_sigma_m"] > 0:
        block["gnss_horizontal_sigma_m"] = float(s["gnss"]["horizontal_sigma_m"])
        block["gnss_vertical_sigma_m"] = float(s["gnss"]["vertical_sigma_m"])
    block.update(processing.get("model") or {})
    return block


#: ``filter_rate_hz`` the processing config assumes when survey.yaml does not set it.
DEFAULT_FILTER_RATE_HZ = 1.0


def user_model_block(cfg: SimConfig) -> dict | None:
    """The survey.yaml ``model`` block: only what the SIM file's author says a user knows.

    ``processing.filter_rate_hz`` when it is not the processing default, plus the keys of
    ``processing.model`` verbatim (e.g. datasheet noise figures); nothing derived from the
    simulated errors or field.  None when both are absent (the estimator's defaults apply).
    """
    processing = cfg.processing
    block = {}
    if processing["filter_rate_hz"] != DEFAULT_FILTER_RATE_HZ:
        block["filter_rate_hz"] = processing["filter_rate_hz"]
    block.update(processing.get("model") or {})
    return block or None


def _initial_block(sim: FlightSimulation) -> dict:
    """EXACT state at the first IMU sample (ORACLE: for oracle.yaml only).

    ``attitude_deg`` is the TRIAD's (roll, pitch, heading) w.r.t. ENU: the aircraft's for
    strapdown, ``(0, 0, 90)`` (= identity ``mat_nt``: x E, y N, z U) for the platform."""
    t = sim.truth
    if sim.triad == "platform":
        att = [0.0, 0.0, 90.0]
    else:
        att = [float(np.degrees(t["roll"][0])), float(np.degrees(t["pitch"][0])), float(np.degrees(t["heading"][0]))]
    return {
        "lat_deg": float(np.degrees(t["lat"][0])),
        "lon_deg": float(np.degrees(t["lon"][0])),
        "height_m": float(t["height"][0]),
        "velocity_enu_mps": [float(x) for x in t["vel_n"][0]],
        "attitude_deg": att,
    }


def user_initial_block(sim: FlightSimulation) -> dict | None:
    """The survey.yaml ``initial`` block: none.

    A user's config holds only what the user knows; the pipeline takes position, velocity and
    start time from GNSS and a strapdown triad's attitude from its own alignment
    (gravsurvey.inm.alignment), so no flight needs an ``initial`` block.  (The crew's guess
    this once wrote - a level attitude at the plan heading to a whole degree - contradicts
    the data by more than its stated sigma and is refused as it should be.)
    """
    return None


def _comments(cfg: SimConfig, sim: FlightSimulation) -> list[str]:
    from .logs import utc_iso

    f = sim.flight
    return [
        f"gravsurvey simulate: survey {cfg.name}, flight {sim.name}",
        f"start {utc_iso(sim.start_unix_ns)} ({sim.start_unix_ns} ns), triad {sim.triad}",
        f"ellipsoid {cfg.ellipsoid.name}; specific force m/s^2 and angular rate rad/s on the triad "
        f"(platform x E y N z U; strapdown x fwd y left z up); heights ellipsoidal m",
        f"rates: imu {f['rates']['imu_hz']:g} Hz, altimeter {f['rates']['altimeter_hz']:g} Hz, "
        f"gnss {f['rates']['gnss_hz']:g} Hz; seed {cfg.seed}",
    ]


def simulate_to_dir(sim_path, out_dir, oracle: bool = False) -> list[Path]:
    """Simulate every flight of a SIM config and write a complete survey.

    Writes ``out_dir/<flight>/`` logs (formats from the config; the
    processing config points at the first format) and ``truth.csv`` per
    flight, and ``out_dir/survey.yaml`` (docs/config.md) holding only what a
    user knows (no noise levels or field statistics derived from the truth,
    no exact initial state; :func:`user_model_block`, :func:`user_initial_block`).

    Parameters
    ----------
    sim_path : path, dict or SimConfig
    out_dir : path
    oracle : bool
        Also write ``out_dir/oracle.yaml``: the same survey with the ``model``
        block matched to the simulated errors, the exact initial state and
        the GNSS antenna's offset where there is one (:func:`oracle_model_block`;
        survey.yaml leaves it to be found), the "oracle-tuned" reference of the
        benchmarks.  ``gravsurvey simulate --oracle-config``.

    Returns
    -------
    list of Path
        Every file written, survey.yaml last.
    """
    from .logs import SensorLogs, write_flight_logs, write_truth_csv

    cfg = load_sim_config(sim_path)
    out_dir = Path(out_dir)
    written: list[Path] = []
    flights_yaml = []
    oracle_flights = []
    for k, f in enumerate(cfg.flights):
        sim = simulate_flight(cfg, k)
        s = f["sensors"]
        rate = f["rates"]["imu_hz"]
        logs = SensorLogs(
            start_unix_ns=sim.start_unix_ns,
            imu_time_ns=sim.imu_time_ns,
            specific_force_t=sim.specific_force_t,
            angular_rate_t=sim.angular_rate_t,
            alt_time_ns=sim.alt_time_ns,
            height_m=sim.alt_height,
            gnss_time_ns=sim.gnss_time_ns,
            lat_deg=sim.gnss_lat_deg,
            lon_deg=sim.gnss_lon_deg,
            gnss_height_m=sim.gnss_height,
            accel_sigma_mps2=[
                s["accelerometer"]["white_sigma_mps2"] * math.sqrt(rate),
                s["accelerometer"]["white_sigma_mps2"] * math.sqrt(rate),
                s["gravimeter"]["white_sigma_mps2"] * math.sqrt(rate),
            ],
            gyro_sigma_radps=s["gyro"]["white_drift_degph"] * DEGPH * math.sqrt(rate),
            gnss_sigma_m=[
                s["gnss"]["horizontal_sigma_m"],
                s["gnss"]["horizontal_sigma_m"],
                s["gnss"]["vertical_sigma_m"],
            ],
            gradient_time_ns=sim.gradient_time_ns,
            gradient_t_eotvos=sim.gradient_t_eotvos,
        )
        fdir = out_dir / sim.name
        comments = _comments(cfg, sim)
        files = write_flight_logs(fdir, sim.name, cfg.formats, logs, comments)
        written += files
        truth_path = write_truth_csv(fdir / "truth.csv", sim.truth_table, comments)
        written.append(Path(truth_path))
        first = cfg.formats[0]
        if first == "csv":
            inputs = {
                "csv": {
                    "imu": f"{sim.name}/imu.csv",
                    "altimeter": f"{sim.name}/altimeter.csv",
                    "gnss": f"{sim.name}/gnss.csv",
                }
            }
        else:
            suffix = "json" if first == "mcap_json" else "ros2"
            inputs = {"mcap": f"{sim.name}/{sim.name}_{suffix}.mcap"}
        entry = {"name": sim.name, "inputs": inputs}
        if first != "csv":
            entry["topics"] = {"imu": "/imu", "altimeter": "/altimeter", "gnss": "/gnss"}
        entry["triad"] = sim.triad
        user_entry, oracle_entry = dict(entry), dict(entry)
        initial = user_initial_block(sim)
        if initial is not None:
            user_entry["initial"] = initial
        oracle_entry["initial"] = _initial_block(sim)
        arm = [float(x) for x in sim.flight["sensors"]["gnss"]["antenna_m"]]
        if any(arm):
            # the oracle knows where the antenna is; a user's survey.yaml leaves it to be found
            oracle_entry["gnss_lever_arm_m"] = arm
        user_entry["truth"] = oracle_entry["truth"] = f"{sim.name}/truth.csv"
        flights_yaml.append(user_entry)
        if k == 0 and oracle:  # the matched values come from the first flight; drop its arrays after
            oracle_model = oracle_model_block(cfg, sim)
        oracle_flights.append(oracle_entry)
    proc = cfg.processing
    out_dir.mkdir(parents=True, exist_ok=True)
    tail = {
        "lines": {"mode": proc["lines_mode"]},
        "postprocess": {"method": proc["postprocess_method"]},
        "output": {"dir": proc["output_dir"]},
    }
    head = {"survey": {"name": cfg.name}, "ellipsoid": cfg.ellipsoid.name}
    if oracle:
        doc = {**head, "flights": oracle_flights, "model": oracle_model, **tail}
        doc["output"] = {"dir": proc["output_dir"] + "_oracle"}
        written.append(
            _write_yaml(
                out_dir / "oracle.yaml",
                doc,
                "# written by gravsurvey simulate --oracle-config: ORACLE values derived from the\n"
                "# simulated truth (matched noise model, anomaly prior, exact initial state), which\n"
                "# no user has; the reference of the benchmarks. Process with: gravsurvey run oracle.yaml\n",
            )
        )
    survey = {**head, "flights": flights_yaml}
    model = user_model_block(cfg)
    if model is not None:
        survey["model"] = model
    survey.update(tail)
    written.append(
        _write_yaml(
            out_dir / "survey.yaml",
            survey,
            "# written by gravsurvey simulate; process with: gravsurvey run survey.yaml\n",
        )
    )
    return written


def _write_yaml(target: Path, doc: dict, header: str) -> Path:
    """Write a YAML document atomically (temporary file, then rename)."""
    text = header + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None)
    tmp = target.parent / f".{target.name}.tmp"
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(target)
    return target
