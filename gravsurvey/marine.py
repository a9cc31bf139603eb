"""Marine / conventional survey reductions from navigation: free-air anomaly, Eotvos correction.

Free functions over numpy arrays, SI inside (rad, m, s, m/s^2).  The Eotvos forms themselves
live in :mod:`gravsurvey.classic` (:func:`~gravsurvey.classic.eotvos_harlan`, Harlan 1968
eq. 16, and the exact :func:`~gravsurvey.classic.eotvos_exact`); this module supplies what a
ship or aircraft track file gives them: the velocity from time-stamped positions.

Checked against NCEI's archive values on the real cruise NBP9908 (tests/test_formats_mgd77t.py;
numbers in docs/input-formats.md).
"""

from __future__ import annotations

import numpy as np

from .classic import eotvos_exact, eotvos_harlan
from .errors import DataError
from .geodesy import (
    DEFAULT_NORMAL_GRAVITY_FORMULA,
    NORMAL_GRAVITY_FORMULAS,
    WGS84,
    Ellipsoid,
    normal_gravity,
    normal_gravity_formula_at_height,
    radii_of_curvature,
)

#: Eotvos forms accepted by :func:`eotvos_from_track`.
EOTVOS_FORMS = ("harlan", "exact")


def free_air_anomaly(gravity, lat, height=0.0, formula: str = DEFAULT_NORMAL_GRAVITY_FORMULA):
    """Free-air anomaly ``g - gamma(lat, h)``, m/s^2.

    Parameters
    ----------
    gravity : array_like, shape (n,)
        Observed absolute gravity at the point (Eotvos-corrected, tied), m/s^2.
    lat : array_like, shape (n,)
        Geodetic latitude, rad.
    height : float or array_like, shape (n,)
        Ellipsoidal height of the observation, m (0 at sea level: the classic marine anomaly).
    formula : str
        Normal gravity formula, one of :data:`gravsurvey.geodesy.NORMAL_GRAVITY_FORMULAS`
        (IGF1967 for NCEI/MGD77 archives, GRS80 the default).

    Returns
    -------
    ndarray, shape (n,)
        m/s^2; the free-air correction is the second-order one of
        :func:`gravsurvey.geodesy.normal_gravity_formula_at_height`.
    """
    lat = np.asarray(lat, dtype=float)
    h = np.broadcast_to(np.asarray(height, dtype=float), lat.shape)
    return np.asarray(gravity, dtype=float) - normal_gravity_formula_at_height(lat, h, formula)


def track_velocity(time_s, lat, lon, height=0.0, *, ellipsoid: Ellipsoid = WGS84, max_gap_s: float | None = None):
    """East and north velocity (m/s) from time-stamped geodetic positions.

    Second-order differences on the (possibly uneven) time base (``numpy.gradient`` with the
    sample times), converted with the radii of curvature at ``height``; longitude is unwrapped
    first, so a track across the dateline is continuous.

    Parameters
    ----------
    time_s : array_like, shape (n,)
        Strictly increasing times, s.
    lat, lon : array_like, shape (n,)
        Geodetic latitude and longitude, rad.
    height : float or array_like, shape (n,)
        Ellipsoidal height, m (0: velocity of the point on the ellipsoid, what Harlan's ``V`` is).
    ellipsoid : Ellipsoid
    max_gap_s : float, optional
        Samples next to a step longer than this get NaN (no velocity across a gap).

    Returns
    -------
    v_east, v_north : ndarray, shape (n,)

    Raises
    ------
    DataError
        Fewer than 3 samples, or times not strictly increasing.
    """
    t = np.asarray(time_s, dtype=float)
    lat = np.asarray(lat, dtype=float)
    lon = np.unwrap(np.asarray(lon, dtype=float))
    if t.size < 3:
        raise DataError(f"track: {t.size} positions; need at least 3 for velocities")
    dt = np.diff(t)
    if not np.all(dt > 0):
        raise DataError("track: times must be strictly increasing (repair the time base first)")
    h = np.broadcast_to(np.asarray(height, dtype=float), lat.shape)
    m_rad, n_rad = radii_of_curvature(lat, ellipsoid)
    vn = (m_rad + h) * np.gradient(lat, t, edge_order=2)
    ve = (n_rad + h) * np.cos(lat) * np.gradient(lon, t, edge_order=2)
    if max_gap_s is not None:
        gap = dt > max_gap_s
        bad = np.zeros(t.size, bool)
        bad[:-1] |= gap
        bad[1:] |= gap
        ve = np.where(bad, np.nan, ve)
        vn = np.where(bad, np.nan, vn)
    return ve, vn


def eotvos_from_track(
    time_s,
    lat,
    lon,
    height=0.0,
    *,
    form: str = "harlan",
    ellipsoid: Ellipsoid = WGS84,
    max_gap_s: float | None = None,
):
    """Eotvos correction (m/s^2, add to the observed gravity) from a position track.

    Parameters
    ----------
    time_s, lat, lon, height, ellipsoid, max_gap_s
        As :func:`track_velocity` (times s, angles rad, height m).
    form : {'harlan', 'exact'}
        'harlan': Harlan (1968) eq. 16 (:func:`gravsurvey.classic.eotvos_harlan`) with the
        ground speed and true course of the nadir point on the ellipsoid; 'exact': the closed
        form :func:`gravsurvey.classic.eotvos_exact` with the velocity at ``height``.  They
        differ by < 0.01 mGal at ship speeds.

    Returns
    -------
    ndarray, shape (n,)
        m/s^2; NaN where the velocity is undefined (gaps).
    """
    if form not in EOTVOS_FORMS:
        raise ValueError(f"eotvos form: expected one of {', '.join(EOTVOS_FORMS)}, got {form!r}")
    lat = np.asarray(lat, dtype=float)
    h = np.broadcast_to(np.asarray(height, dtype=float), lat.shape)
    if form == "exact":
        ve, vn = track_velocity(time_s, lat, lon, h, ellipsoid=ellipsoid, max_gap_s=max_gap_s)
        return eotvos_exact(lat, h, ve, vn, ellipsoid)
    ve, vn = track_velocity(time_s, lat, lon, 0.0, ellipsoid=ellipsoid, max_gap_s=max_gap_s)
    speed = np.hypot(ve, vn)
    course = np.arctan2(ve, vn)
    return eotvos_harlan(lat, h, speed, course, ellipsoid)


#: ``processing.normal_gravity`` choices: the exact field of the configured ellipsoid, or a
#: closed-form formula (:data:`gravsurvey.geodesy.NORMAL_GRAVITY_FORMULAS`).
NORMAL_GRAVITY_CHOICES = ("exact",) + NORMAL_GRAVITY_FORMULAS


def use_normal_gravity_formula(result, formula: str, ellipsoid: Ellipsoid = WGS84):
    """Re-reference a :class:`~gravsurvey.classic.ClassicResult` to a closed-form normal gravity formula.

    The classic reduction subtracts the exact normal gravity of ``ellipsoid``
    (:func:`gravsurvey.geodesy.normal_gravity`); this adds back
    ``delta = gamma_exact(lat, h) - gamma_formula(lat, h)`` (second-order free-air term, see
    :func:`gravsurvey.geodesy.normal_gravity_formula_at_height`) to the filtered and the raw
    disturbance and the ``normal_gravity``/``raw`` terms, in place.  ``delta`` depends only on
    latitude and height and is smooth: at most 0.024 mGal per 0.1 deg of latitude (IGF1930;
    IGF1967 0.0002) and 0.01 mGal per km of height (measured).  The zero-phase filter passes a
    linear change unchanged, so adding ``delta`` after the low-pass differs from filtering it
    only by its curvature term, < 1e-4 mGal for a 40 km filter length.  Sizes: exact GRS80
    minus IGF1967 0.83-0.92 mGal, minus IGF1930 -16.3..-2.7 mGal; GRS80 - WGS84 about 0.14 mGal.

    Parameters
    ----------
    result : ClassicResult
    formula : str
        One of :data:`NORMAL_GRAVITY_CHOICES`; ``'exact'`` leaves the result unchanged.
    ellipsoid : Ellipsoid
        The ellipsoid the reduction used.

    Returns
    -------
    ClassicResult
        The same object; ``info['normal_gravity']`` names the reference.
    """
    if formula not in NORMAL_GRAVITY_CHOICES:
        raise ValueError(f"normal gravity: expected one of {', '.join(NORMAL_GRAVITY_CHOICES)}, got {formula!r}")
    if formula == "exact":
        result.info["normal_gravity"] = f"exact {ellipsoid.name}"
        return result
    delta = normal_gravity(result.lat, result.height, ellipsoid) - normal_gravity_formula_at_height(
        result.lat, result.height, formula
    )
    result.disturbance = result.disturbance + delta
    result.raw = result.raw + delta
    if "raw" in result.terms:
        result.terms["raw"] = result.terms["raw"] + delta
    if "normal_gravity" in result.terms:
        result.terms["normal_gravity"] = result.terms["normal_gravity"] - delta
    result.info["normal_gravity"] = f"{formula} closed form"
    return result
