"""Ideal sensor outputs from the exact kinematics, and the sensor error models.

Ideal outputs (no errors):

* specific force ``F = a_i - G`` resolved on the triad, with (ENU components)
  ``F_n = a_n + 2 w_ie x v_n + C_ne (W x (W x r_e)) - C_ne G_e - G_anom_n``
  where ``a_n`` is the acceleration relative to the Earth (``d^2 r_e/dt^2``
  on ENU), ``w_ie`` the Earth rate, ``G_e`` the normal gravitation of the
  ellipsoid (:func:`gravsurvey.geodesy.normal_gravitation_ecef`) and
  ``G_anom`` the anomalous gravitation.  This is ``C_ni (d^2 r_i/dt^2 - G_i)``
  written out with ``r_i = C_ie(t) r_e``.
* gyros: the triad's absolute angular rate on the triad, ``w_it^t``.  Platform
  (ENU triad): ``w_ie + w_en``.  Strapdown: ``C_bn (w_ie + w_en) + w_nb^b``.

Error models (all off by default; docs/simulate.md).  White noises are given by
their **one-second standard deviation** ``sigma_1s`` (the standard deviation of
the noise averaged over 1 s, i.e. a white noise of two-sided spectral density
``sigma_1s^2 * 1 s``); a sample at rate ``R`` Hz then has standard deviation
``sigma_1s sqrt(R)``, and a filter that averages to 1 Hz epochs sees
``sigma_1s``.  Altimeter and GNSS noises are per sample.

* accelerometers x, y: constant bias + white noise;
* gravimeter (triad z axis, the seed's third accelerometer): constant bias +
  stationary first-order Gauss-Markov ``df3/dt = -lambda f3 + sqrt(2 lambda)
  sigma u`` (exact discretisation) + optional white noise + optional linear drift
  from the flight's first sample (a spring meter's or a strapdown gravimeter's
  drift without base ties; ``drift_mgal_per_h``) + an optional tare, a step of
  ``tare_mgal`` at ``tare_time_s`` from the first sample (a spring meter after a
  shock, a strapdown gravimeter's bias jump);
* gyros: constant bias + white drift (deg/h);
* altimeter: ``h + A + sigma w`` (mean ``A``);
* GNSS: independent white noise in east, north (m, converted to angles through
  the radii of curvature) and height, plus optional first-order Gauss-Markov errors
  per axis (``horizontal_markov_sigma_m``, ``vertical_markov_sigma_m``,
  ``markov_tau_s``): a real solution's slowly varying error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from gravsurvey.geodesy import (
    OMEGA_E,
    WGS84,
    Ellipsoid,
    ecef_to_geodetic,
    mat_en,
    normal_gravitation_ecef,
    radii_of_curvature,
)

from .trajectory import Kinematics, earth_rate_n, mat_ne

#: deg/h in rad/s.
DEGPH = math.pi / 180.0 / 3600.0
#: 1 mGal in m/s^2
MGAL = 1e-5
#: 1 mGal/h in m/s^2 per s
MGAL_PER_H = MGAL / 3600.0


def total_gravitation_n(kin: Kinematics, anomaly_n, ellipsoid: Ellipsoid = WGS84):
    """Normal plus anomalous gravitation on ENU, ``(n, 3)`` m/s^2."""
    g_e = normal_gravitation_ecef(kin.r_e, ellipsoid)
    return np.einsum("nij,nj->ni", mat_ne(kin.lat, kin.lon), g_e) + anomaly_n


def specific_force_n(kin: Kinematics, gravitation_n, omega: float = OMEGA_E):
    """Exact specific force on ENU axes, ``(n, 3)`` m/s^2.

    Parameters
    ----------
    kin : Kinematics
    gravitation_n : ndarray (n, 3)
        Total gravitation (attraction only) on ENU, m/s^2.
    """
    w_ie = earth_rate_n(kin.lat, omega)
    cen_e = np.zeros_like(kin.r_e)
    cen_e[:, 0] = -(omega**2) * kin.r_e[:, 0]
    cen_e[:, 1] = -(omega**2) * kin.r_e[:, 1]
    cen_n = np.einsum("nij,nj->ni", mat_ne(kin.lat, kin.lon), cen_e)
    return kin.acc_n + 2.0 * np.cross(w_ie, kin.vel_n) + cen_n - gravitation_n


def triad_outputs(f_n, w_in_n, mat_nb, w_nb_b, triad: str):
    """Ideal accelerometer and gyro outputs on the triad.

    Parameters
    ----------
    f_n : ndarray (n, 3)
        Specific force on ENU, m/s^2.
    w_in_n : ndarray (n, 3)
        Absolute angular rate of the ENU frame on ENU (``w_ie + w_en``), rad/s.
    mat_nb : ndarray (n, 3, 3)
        Body -> ENU.
    w_nb_b : ndarray (n, 3)
        Body rate w.r.t. ENU on the body, rad/s.
    triad : {"platform", "strapdown"}

    Returns
    -------
    f_t : ndarray (n, 3)
        Specific force on the triad, m/s^2.
    w_t : ndarray (n, 3)
        Absolute angular rate of the triad on the triad, rad/s.
    mat_nt : ndarray (n, 3, 3)
        Triad -> ENU (platform: a read-only broadcast identity).
    """
    n = f_n.shape[0]
    if triad == "platform":
        return f_n.copy(), w_in_n.copy(), np.broadcast_to(np.eye(3), (n, 3, 3))
    if triad == "strapdown":
        f_t = np.einsum("nji,nj->ni", mat_nb, f_n)
        w_t = np.einsum("nji,nj->ni", mat_nb, w_in_n) + w_nb_b
        return f_t, w_t, mat_nb
    raise ValueError(f"triad: expected 'platform' or 'strapdown', got {triad!r}")


# --------------------------------------------------------------------------
# Error models
# --------------------------------------------------------------------------


@njit(cache=True)
def _markov_kernel(phi, q, x0, w, out):
    out[0] = x0
    for k in range(1, out.shape[0]):
        out[k] = phi * out[k - 1] + q * w[k - 1]


def markov_reference(phi, q, x0, w):
    """Pure-numpy reference of the Gauss-Markov recursion (tests)."""
    n = w.shape[0] + 1
    out = np.empty(n)
    out[0] = x0
    for k in range(1, n):
        out[k] = phi * out[k - 1] + q * w[k - 1]
    return out


def gauss_markov(n, dt, lam, sigma, rng):
    """Stationary first-order Gauss-Markov sequence at a constant step.

    ``x_k = phi x_{k-1} + sigma sqrt(1 - phi^2) w_k``, ``phi = exp(-lam dt)``,
    ``x_0 ~ N(0, sigma^2)``: the exact discretisation of
    ``dx/dt = -lam x + sqrt(2 lam) sigma u``.

    Parameters
    ----------
    n : int
    dt : float
        Step, s.
    lam : float
        Inverse correlation time, 1/s (> 0).
    sigma : float
        Stationary standard deviation.
    rng : numpy.random.Generator

    Returns
    -------
    ndarray (n,)
    """
    w = rng.standard_normal(n)
    if sigma == 0.0:
        return np.zeros(n)
    phi = math.exp(-lam * dt)
    q = sigma * math.sqrt(max(0.0, 1.0 - phi * phi))
    out = np.empty(n)
    _markov_kernel(phi, q, sigma * w[0], np.ascontiguousarray(w[1:]), out)
    return out


@dataclass
class ImuErrors:
    """Truth of the IMU errors added to the ideal outputs, ``(n, 3)`` each.

    ``accel_t``: total accelerometer error (x, y: bias + white; z = gravimeter:
    bias + Markov + white + linear drift + tare), m/s^2; ``gravimeter_markov`` (n,) the
    Markov part of the z error, m/s^2; ``gyro_t`` total gyro error, rad/s;
    ``gravimeter_drift`` (n,) the linear drift and tare part of the z error, m/s^2
    (zeros without ``gravimeter.drift_mgal_per_h`` and ``gravimeter.tare_mgal``).
    """

    accel_t: np.ndarray
    gravimeter_markov: np.ndarray
    gyro_t: np.ndarray
    gravimeter_drift: np.ndarray


def imu_errors(n, rate_hz, cfg, rng) -> ImuErrors:
    """Draw the IMU errors for ``n`` samples at ``rate_hz``.

    Parameters
    ----------
    cfg : dict
        The validated ``sensors`` mapping (docs/simulate.md).
    rng : numpy.random.Generator
        Draws happen in a fixed order (accelerometer white, gravimeter Markov,
        gravimeter white, gyro white) whatever the settings, so switching one
        error on does not change the others' realisations.
    """
    acc, grv, gyr = cfg["accelerometer"], cfg["gravimeter"], cfg["gyro"]
    sq = math.sqrt(rate_hz)
    w_acc = rng.standard_normal((n, 2))
    markov = gauss_markov(n, 1.0 / rate_hz, grv["markov_lambda_per_s"], grv["markov_sigma_mps2"], rng)
    w_grv = rng.standard_normal(n)
    w_gyr = rng.standard_normal((n, 3))
    a = np.zeros((n, 3))
    a[:, :2] = np.asarray(acc["bias_mps2"], dtype=float) + acc["white_sigma_mps2"] * sq * w_acc
    # a ramp from the first sample: no draw, so the other errors' realisations stay as they were
    drift = float(grv.get("drift_mgal_per_h", 0.0)) * MGAL_PER_H * np.arange(n) / rate_hz
    tare = float(grv.get("tare_mgal", 0.0))
    if tare != 0.0:
        drift = drift + np.where(np.arange(n) / rate_hz >= float(grv.get("tare_time_s", 0.0)), tare * MGAL, 0.0)
    a[:, 2] = grv["bias_mps2"] + markov + grv["white_sigma_mps2"] * sq * w_grv + drift
    g = np.asarray(gyr["bias_degph"], dtype=float) * DEGPH + gyr["white_drift_degph"] * DEGPH * sq * w_gyr
    return ImuErrors(accel_t=a, gravimeter_markov=markov, gyro_t=g, gravimeter_drift=drift)


#: Order of the 6 independent gradient-tensor components written to the logs.
GRADIENT_COMPONENTS = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


def gradient_triad_components(gamma_n, mat_nt):
    """The 6 independent components of the gradient tensor on the triad axes.

    Parameters
    ----------
    gamma_n : ndarray, shape (n, 3, 3)
        Gradient tensor ``d g_i / d x_j`` on ENU, 1/s^2.
    mat_nt : ndarray, shape (n, 3, 3)
        Triad -> ENU.

    Returns
    -------
    comps : ndarray, shape (n, 6)
        ``T_t = C_tn T_n C_nt`` components ``xx, xy, xz, yy, yz, zz``, 1/s^2.
    """
    gam_t = np.einsum("kji,kjl,klm->kim", mat_nt, gamma_n, mat_nt)
    return np.stack([gam_t[:, i, j] for i, j in GRADIENT_COMPONENTS], axis=1)


def gradiometer_errors(n, rate_hz, cfg, rng):
    """Gradiometer errors of the 6 components, Eotvos, shape (n, 6).

    Per component, independently: white noise of one-second standard deviation
    ``white_eotvos_rthz`` (E/sqrt(Hz); per sample ``* sqrt(rate_hz)``) plus a
    stationary first-order Gauss-Markov process (``markov_sigma_eotvos``,
    ``markov_lambda_per_s``), the slowly drifting part of a real instrument.
    """
    c = cfg["gradiometer"]
    out = rng.standard_normal((n, 6)) * (c["white_eotvos_rthz"] * math.sqrt(rate_hz))
    for j in range(6):
        out[:, j] += gauss_markov(n, 1.0 / rate_hz, c["markov_lambda_per_s"], c["markov_sigma_eotvos"], rng)
    return out


def altimeter_errors(n, cfg, rng):
    """Altimeter error ``A + sigma w`` (m), ``(n,)``."""
    alt = cfg["altimeter"]
    return alt["mean_m"] + alt["sigma_m"] * rng.standard_normal(n)


def antenna_position(kin: Kinematics, arm_flu_m, ellipsoid: Ellipsoid = WGS84):
    """Where a GNSS antenna fixed on the aircraft is: latitude, longitude (rad), height (m).

    The antenna sits at ``arm_flu_m`` from the IMU on the aircraft's axes (forward, left, up),
    turned by the aircraft's attitude ``kin.mat_nb`` (its crab, bank and pitch, turbulence
    included), whatever the triad: a platform's levelled triad sits in the same aircraft.

    Parameters
    ----------
    kin : Kinematics
        The IMU's kinematic truth at the fixes' times.
    arm_flu_m : array_like (3,)
        Antenna from the IMU, forward-left-up, m.
    ellipsoid : Ellipsoid

    Returns
    -------
    lat, lon, height : ndarray (n,)
        The antenna's geodetic position; ``lon`` runs on from ``kin.lon`` (no wrap between them).
    """
    off_n = np.einsum("nij,j->ni", kin.mat_nb, np.asarray(arm_flu_m, float))
    off_e = np.einsum("nij,nj->ni", mat_en(kin.lat, kin.lon), off_n)
    lat, lon, h = ecef_to_geodetic(kin.r_e + off_e, ellipsoid)
    lon = kin.lon + np.mod(lon - kin.lon + np.pi, 2.0 * np.pi) - np.pi
    return lat, lon, h


def gnss_errors(lat, height, cfg, rng, ellipsoid: Ellipsoid = WGS84, dt_s: float = 1.0):
    """GNSS errors (dlat rad, dlon rad, dh m), each ``(n,)``.

    East/north errors in metres are converted through the radii of curvature.  ``dt_s``: the
    fixes' spacing, s (the Gauss-Markov parts' step).
    """
    g = cfg["gnss"]
    n = lat.shape[0]
    w = rng.standard_normal((n, 3))
    m, nn = radii_of_curvature(lat, ellipsoid)
    de = g["horizontal_sigma_m"] * w[:, 0]
    dn = g["horizontal_sigma_m"] * w[:, 1]
    dh = g["vertical_sigma_m"] * w[:, 2]
    sh, sv = g.get("horizontal_markov_sigma_m", 0.0), g.get("vertical_markov_sigma_m", 0.0)
    if sh > 0.0 or sv > 0.0:
        # drawn after the white parts, so a flight without them keeps its noise
        lam = 1.0 / float(g["markov_tau_s"])
        de = de + gauss_markov(n, dt_s, lam, sh, rng)
        dn = dn + gauss_markov(n, dt_s, lam, sh, rng)
        dh = dh + gauss_markov(n, dt_s, lam, sv, rng)
    return dn / (m + height), de / ((nn + height) * np.cos(lat)), dh
