"""Vector gravimetry (seed 003): the horizontal gravity disturbance from the 18-state filter.

The states ``GN, GE`` (:mod:`gravsurvey.inm.errormodel`) are the horizontal components of the
gravity disturbance ``dg = g_true - gamma`` on local ENU axes, m/s^2; this module turns the
smoothed states into the products and says where they are determined by the data.

Sign convention: ``dg_north > 0`` pulls north (excess mass to the north).  The deflections of
the vertical (plumb line against the ellipsoid normal) are ``xi = -dg_north / gamma`` (meridian)
and ``eta = -dg_east / gamma`` (prime vertical), radians; ``gamma`` is normal gravity.
"""

from __future__ import annotations

import math

import numpy as np

from ..geodesy import WGS84, Ellipsoid, normal_gravity
from .errormodel import GH

__all__ = [
    "OBSERVABLE_SIGMA_RATIO",
    "horizontal_outputs",
    "missed_field_per_component",
    "deflections_rad",
    "resolution_filter",
    "ARCSEC",
]

#: The horizontal components count as determined by the data where both posterior sigmas are
#: below this fraction of the prior's: the data removed at least half of the prior variance.
#: Measured (docs/benchmarks.md, "Vector gravimetry"): on a straight constant-heading line the
#: median ratio is 0.84-1.00 (attitude and accelerometer errors absorb the field), on the
#: sample grid with its turns 0.66 with a navigation-grade IMU and a strong field.
OBSERVABLE_SIGMA_RATIO = 1.0 / math.sqrt(2.0)

#: One arcsecond, rad.
ARCSEC = math.pi / (180.0 * 3600.0)


def missed_field_per_component(field_sigma_missed_mps2: float) -> float:
    """Each horizontal component's share of the vertical's missed field, m/s^2: a harmonic field's
    two horizontal components carry the vertical's power between them, ``1 / sqrt(2)`` each
    (:func:`horizontal_outputs`)."""
    return float(field_sigma_missed_mps2) / math.sqrt(2.0)


def horizontal_outputs(x_s, p_s, sigma_prior_mps2: float, field_sigma_missed_mps2: float = 0.0):
    """Horizontal disturbance, its 1-sigma and the observability flag from the smoothed states.

    The 1-sigma is the smoother's and, in quadrature, the horizontal share of the field the
    vertical identification left out of the prior (``field_sigma_missed_mps2``, the vertical's
    :func:`gravsurvey.inm.identify.refine_prior` figure): the horizontal prior follows the
    vertical estimate (:func:`gravsurvey.inm.identify.horizontal_prior`), so where that is
    flattened the horizontal one is too, and a harmonic field's two horizontal components carry
    the vertical's power between them (``S_along + S_across = S_up``): each ``1 / sqrt(2)`` of
    the vertical's missed field.  Without it a line whose vertical shows no field stated 0.20
    mGal against errors of 0.5 / 1.2 mGal (docs/benchmarks.md, "Vector gravimetry").  The flag
    compares the smoother's own sigma with the prior's.

    Parameters
    ----------
    x_s : ndarray (N, 18)
        Smoothed 18-state estimate (seed order, errormodel).
    p_s : ndarray (N, 18, 18)
        Its covariance.
    sigma_prior_mps2 : float
        Stationary prior sigma of each component, m/s^2
        (:func:`gravsurvey.inm.identify.horizontal_prior`).
    field_sigma_missed_mps2 : float
        The vertical disturbance's missed field (summary.json
        ``identification.field_sigma_missed_mps2``), m/s^2; 0 leaves the smoother's sigma.

    Returns
    -------
    dg_horizontal : ndarray (N, 2)
        ``[north, east]``, m/s^2.
    dg_horizontal_sigma : ndarray (N, 2)
        1-sigma, m/s^2.
    observable : ndarray of bool (N,)
        Both sigmas below :data:`OBSERVABLE_SIGMA_RATIO` times the prior sigma.
    """
    dg = np.ascontiguousarray(x_s[:, GH])
    sig = np.sqrt(np.stack([p_s[:, GH[0], GH[0]], p_s[:, GH[1], GH[1]]], axis=1))
    observable = np.all(sig < OBSERVABLE_SIGMA_RATIO * sigma_prior_mps2, axis=1)
    missed = missed_field_per_component(field_sigma_missed_mps2)
    return dg, (np.hypot(sig, missed) if missed > 0.0 else sig), observable


def deflections_rad(dg_horizontal, lat, height, ellipsoid: Ellipsoid = WGS84):
    """Deflections of the vertical from the horizontal disturbance.

    Parameters
    ----------
    dg_horizontal : ndarray (N, 2)
        ``[north, east]`` disturbance, m/s^2 (or their sigmas: the map is linear; take the
        absolute value of the result for sigmas).
    lat : ndarray (N,)
        Geodetic latitude, rad.
    height : ndarray (N,)
        Ellipsoidal height, m.
    ellipsoid : Ellipsoid

    Returns
    -------
    xi, eta : ndarray (N,)
        ``xi = -dg_north / gamma`` (north-south), ``eta = -dg_east / gamma`` (east-west), rad;
        divide by :data:`ARCSEC` for arcseconds.
    """
    dg = np.asarray(dg_horizontal, float)
    gamma = normal_gravity(np.asarray(lat, float), np.asarray(height, float), ellipsoid)
    return -dg[:, 0] / gamma, -dg[:, 1] / gamma


def resolution_filter(values, time, speed_mps: float, half_wavelength_m: float):
    """Low-pass a profile to a half-wavelength resolution (how accuracy figures are quoted).

    Zero-phase 4th-order Butterworth (``scipy.signal.sosfiltfilt``) with its cut-off at the
    wavelength ``2 half_wavelength_m`` travelled at ``speed_mps``: "X mGal at L km
    half-wavelength" is the RMS of the difference of two profiles after this filter.

    Parameters
    ----------
    values : ndarray (N,) or (N, k)
        Evenly sampled profile(s) along the flight.
    time : ndarray (N,)
        Sample times, s.
    speed_mps : float
        Ground speed, m/s.
    half_wavelength_m : float
        Resolution, m.

    Returns
    -------
    ndarray
        Same shape as ``values``.
    """
    from scipy.signal import butter, sosfiltfilt

    dt = float(np.median(np.diff(np.asarray(time, float))))
    fc = speed_mps / (2.0 * half_wavelength_m)
    sos = butter(4, min(fc * 2.0 * dt, 0.99), output="sos")
    return sosfiltfilt(sos, np.asarray(values, float), axis=0)
