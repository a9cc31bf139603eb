"""One flight through the 3D-INM: mechanize, discretise, filter, smooth, georeference."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError, DataError
from ..geodesy import WGS84, Ellipsoid
from .errormodel import DP, DQ, F3, G, AltimeterMeasurement, discretise, epoch_geometry, initial_covariance
from .kalman import filter_and_smooth
from .mechanization import mechanize, navigation_to_geodetic
from .params import InitialState, InmParams, initial_state_from_gnss, solvability_warnings

__all__ = ["InmSolution", "estimate_anomaly", "solvability_warnings", "initial_state_from_gnss"]


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
        Smoothed 1-sigma of dq on the triad axes, m.
    x_smooth, p_smooth : ndarray (N, 8), (N, 8, 8)
        Full smoothed state and covariance (seed order, see errormodel).
    warnings : list of str
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


def estimate_anomaly(record, params: InmParams, initial: InitialState | None, triad: str,
                     ellipsoid: Ellipsoid = WGS84, attitude_deg=None, reference: bool = False) -> InmSolution:
    """Estimate the gravity disturbance along a flight (3D-INM + Kalman + RTS).

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

    Returns
    -------
    InmSolution
    """
    if triad not in ("platform", "strapdown"):
        raise ConfigError(f"triad: expected 'platform' or 'strapdown', got {triad!r}")
    _check_record(record)
    if initial is None:
        initial = initial_state_from_gnss(record, triad, attitude_deg)
    imu = record.imu
    t = np.asarray(imu.time, float)
    alt_t = np.asarray(record.altimeter.time, float)
    alt_h = np.asarray(record.altimeter.height, float)
    good = np.isfinite(alt_h)
    alt_t, alt_h = alt_t[good], alt_h[good]
    if alt_t.size == 0:
        raise DataError(f"{record.source or 'record'}: altimeter.height: no finite samples")
    nav = mechanize(t, imu.specific_force_t, imu.angular_rate_t, initial, alt_t, alt_h,
                    use_ext=params.radius_source == "altimeter", ellipsoid=ellipsoid, reference=reference)
    # filter epochs: IMU samples decimated by the nearest integer factor
    imu_rate = (t.size - 1) / (t[-1] - t[0])
    step = max(1, int(round(imu_rate / params.filter_rate_hz)))
    idx = np.arange(0, t.size, step)
    half = 0.5 * step / imu_rate
    geom = epoch_geometry(nav, idx, params.radius_source == "altimeter", ellipsoid)
    alt_dt = float(np.median(np.diff(alt_t))) if alt_t.size > 1 else 1.0
    phi, q = discretise(geom, params, alt_dt, reference=reference)
    meas = AltimeterMeasurement(alt_t, alt_h, params.altimeter_sigma_m, ellipsoid)
    z, h, r = meas.build(nav, idx, half)
    p0 = initial_covariance(params)
    out = filter_and_smooth(np.zeros(8), p0, phi, q, z, h, r, reference=reference)
    x_s, p_s, x_f, p_f = out["x_s"], out["p_s"], out["x_f"], out["p_f"]

    # corrections: true = computed - error; dq, dp on the triad -> inertial through C
    c = nav.mat_it[idx]
    dq = x_s[:, DQ]
    dp = x_s[:, DP]
    r_corr = nav.r_i[idx] - np.einsum("nij,nj->ni", c, dq)
    v_corr = nav.v_i[idx] - np.einsum("nij,nj->ni", c, dp)
    lat, lon, height, vel_n = navigation_to_geodetic(t[idx], r_corr, v_corr, ellipsoid)
    speed = np.hypot(vel_n[:, 0], vel_n[:, 1])
    heading = np.mod(np.arctan2(vel_n[:, 0], vel_n[:, 1]), 2.0 * math.pi)
    innov = out["innov"]
    if innov.shape[1] == 1:
        innov = innov[:, 0]
    sig_pos = np.sqrt(np.stack([p_s[:, i, i] for i in DQ], axis=1))
    warn = solvability_warnings(params, float(np.median(speed)))
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
        dq_smooth=dq.copy(),
        dp_smooth=dp.copy(),
        sigma_position_m=sig_pos,
        x_smooth=x_s,
        p_smooth=p_s,
        x_forward=x_f,
        warnings=warn,
    )
