"""Ellipsoid geometry and the normal gravity field of the reference ellipsoid.

This is the only module the simulator and the estimator share; it is checked
against :mod:`boule` and published values in ``tests/test_geodesy.py``.

Conventions
-----------
* Angles in radians, lengths in metres, accelerations in m/s^2 (SI inside).
* ``e`` frame: Earth-centred Earth-fixed (ECEF), z to the north pole, x to
  (lat 0, lon 0).
* ``i`` frame: inertial, coincident with ``e`` at the reference epoch
  ``t = 0`` of a flight; ``e`` rotates about z by ``OMEGA_E * t``.
* ``n`` frame: local geodetic East-North-Up (ENU).
* Normal gravity **vector** is the gradient of the closed-form ellipsoidal
  harmonic potential ``U = V + Phi`` of a level ellipsoid (Heiskanen-Moritz
  2-5, Hofmann-Wellenhof & Moritz 2006 eq. 2-124, 2-126); its magnitude is
  the Li & Goetze (2001) closed form that boule uses.  Gravitation ``V`` (the
  attraction only) is what the navigation equations need: ``grad V = grad U -
  grad Phi`` with the centrifugal potential ``Phi = OMEGA^2 (x^2 + y^2) / 2``.

All scalar kernels are numba-compiled (``cache=True``) so the mechanization
loop can call them; the array wrappers are plain numpy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit


@dataclass(frozen=True)
class Ellipsoid:
    """A level reference ellipsoid.

    Attributes
    ----------
    name : str
    a : float
        Semi-major axis, m.
    f : float
        Flattening.
    gm : float
        Geocentric gravitational constant, m^3/s^2.
    omega : float
        Angular velocity, rad/s.
    """

    name: str
    a: float
    f: float
    gm: float
    omega: float

    @property
    def b(self) -> float:
        """Semi-minor axis, m."""
        return self.a * (1.0 - self.f)

    @property
    def e2(self) -> float:
        """First eccentricity squared."""
        return self.f * (2.0 - self.f)

    @property
    def linear_eccentricity(self) -> float:
        """E = sqrt(a^2 - b^2), m."""
        return math.sqrt(self.a**2 - self.b**2)

    def params(self):
        """Tuple (a, f, gm, omega) for the compiled kernels."""
        return (self.a, self.f, self.gm, self.omega)


WGS84 = Ellipsoid("WGS84", 6378137.0, 1.0 / 298.257223563, 3.986004418e14, 7.292115e-5)
GRS80 = Ellipsoid("GRS80", 6378137.0, 1.0 / 298.257222101, 3.986005e14, 7.292115e-5)
ELLIPSOIDS = {"WGS84": WGS84, "GRS80": GRS80}

#: Earth rotation rate (WGS84 = GRS80), rad/s.
OMEGA_E = WGS84.omega
#: 1 mGal in m/s^2.
MGAL = 1e-5
#: Standard gravity ``g_n`` (CGPM 1901), m/s^2: the unit "g", and the round figure where a
#: formula needs a gravity and a part in a thousand does not matter (a tilt ``dg / g``, a
#: coordinated turn's bank).
STANDARD_GRAVITY_MPS2 = 9.80665


def get_ellipsoid(name: str) -> Ellipsoid:
    """Return the named ellipsoid ("WGS84" or "GRS80")."""
    try:
        return ELLIPSOIDS[name.upper()]
    except KeyError:
        raise ValueError(f"unknown ellipsoid {name!r}; expected one of {sorted(ELLIPSOIDS)}") from None


# --------------------------------------------------------------------------
# Compiled scalar kernels
# --------------------------------------------------------------------------


@njit(cache=True)
def geodetic_to_ecef_scalar(lat, lon, h, a, f):
    """Geodetic (rad, rad, m) -> ECEF (m)."""
    e2 = f * (2.0 - f)
    slat = math.sin(lat)
    clat = math.cos(lat)
    n = a / math.sqrt(1.0 - e2 * slat * slat)
    x = (n + h) * clat * math.cos(lon)
    y = (n + h) * clat * math.sin(lon)
    z = (n * (1.0 - e2) + h) * slat
    return x, y, z


@njit(cache=True)
def ecef_to_geodetic_scalar(x, y, z, a, f):
    """ECEF (m) -> geodetic (rad, rad, m).

    Bowring's initial value refined by four fixed-point iterations on the latitude
    (:func:`geodetic_trig_scalar`, which does it on the latitude's sine and cosine):
    < 1e-12 rad and < 1e-6 m for |h| < 1e6 m.
    """
    sl, cl, h = geodetic_trig_scalar(x, y, z, a, f, 4)
    return math.atan2(sl, cl), math.atan2(y, x), h


@njit(cache=True)
def _ellipsoidal_harmonic(x, y, z, a, f):
    """ECEF -> (u, beta, p, E): ellipsoidal harmonic coordinates."""
    b = a * (1.0 - f)
    big_e2 = a * a - b * b
    p2 = x * x + y * y
    r2 = p2 + z * z
    d = r2 - big_e2
    u2 = 0.5 * d + 0.5 * math.sqrt(d * d + 4.0 * big_e2 * z * z)
    u = math.sqrt(u2)
    p = math.sqrt(p2)
    beta = math.atan2(z * math.sqrt(u2 + big_e2), u * p)
    return u, beta, p, math.sqrt(big_e2)


@njit(cache=True)
def _q(u, big_e):
    """Heiskanen-Moritz q(u) = ((1 + 3 u^2/E^2) atan(E/u) - 3 u/E) / 2."""
    t = math.atan(big_e / u)
    return 0.5 * ((1.0 + 3.0 * u * u / (big_e * big_e)) * t - 3.0 * u / big_e)


@njit(cache=True)
def normal_gravitational_potential_scalar(x, y, z, a, f, gm, omega):
    """Gravitational potential V (attraction only) of the level ellipsoid, m^2/s^2."""
    u, beta, p, big_e = _ellipsoidal_harmonic(x, y, z, a, f)
    b = a * (1.0 - f)
    q0 = _q(b, big_e)
    sb = math.sin(beta)
    return gm / big_e * math.atan(big_e / u) + 0.5 * omega * omega * a * a * _q(u, big_e) / q0 * (sb * sb - 1.0 / 3.0)


@njit(cache=True)
def normal_gravitation_ecef_scalar(x, y, z, a, f, gm, omega):
    """Gradient of the normal gravitational potential V at an ECEF point, m/s^2.

    Attraction only: add ``omega^2 (x, y, 0)`` for normal gravity.
    Valid outside the ellipsoid and down to its surface (any flight height).
    """
    return normal_gravitation_inertial_scalar(x, y, z, a, f, gm, omega, normal_gravitation_q0(a, f))


@njit(cache=True)
def normal_gravitation_q0(a, f):
    """Heiskanen-Moritz ``q0 = q(b)`` of the ellipsoid: the constant of
    :func:`normal_gravitation_inertial_scalar`, computed once per run instead of once per point."""
    b = a * (1.0 - f)
    return _q(b, math.sqrt(a * a - b * b))


@njit(cache=True)
def normal_gravitation_inertial_scalar(x, y, z, a, f, gm, omega, q0):
    """Normal gravitation at a point given on any axes with z along the Earth's axis, m/s^2.

    :func:`normal_gravitation_ecef_scalar` is this function; the mechanization's inner loop
    calls it directly on inertial axes with ``q0`` computed once:

    * the field of a level ellipsoid is symmetric about the rotation axis, so the point
      may be given on inertial axes (the Earth's rotation angle drops out exactly);
    * ``sin``, ``cos`` of the reduced latitude ``beta`` come from its tangent by one square
      root instead of ``atan2`` + ``sin`` + ``cos``; ``atan(E/u)`` is shared by ``q(u)`` and
      ``q'(u)``; ``q0 = q(b)`` (:func:`normal_gravitation_q0`) is passed in: one
      transcendental call per point instead of six.

    Parameters
    ----------
    x, y, z : float
        Position, m, on or outside the ellipsoid.
    a, f, gm, omega : float
        Ellipsoid (m, -, m^3/s^2, rad/s).
    q0 : float
        :func:`normal_gravitation_q0` of ``a, f``.

    Returns
    -------
    gx, gy, gz : float
        Gravitation (attraction only) on the axes of ``x, y, z``, m/s^2.
    """
    b = a * (1.0 - f)
    big_e2 = a * a - b * b
    big_e = math.sqrt(big_e2)
    p2 = x * x + y * y
    d = p2 + z * z - big_e2
    u = math.sqrt(0.5 * d + 0.5 * math.sqrt(d * d + 4.0 * big_e2 * z * z))
    # u * u and big_e * big_e, not u2 and big_e2: the rounding of _ellipsoidal_harmonic and _q,
    # which q(u)'s cancellation (a factor ~5e5) would otherwise turn into 3e-13 relative
    u2 = u * u
    e2 = big_e * big_e
    p = math.sqrt(p2)
    sq = math.sqrt(u2 + e2)
    # tan(beta) = z sq / (u p), as in _ellipsoidal_harmonic
    zs = z * sq
    up = u * p
    hyp = math.sqrt(zs * zs + up * up)
    sb = zs / hyp
    cb = up / hyp
    t = math.atan(big_e / u)
    k3 = 1.0 + 3.0 * u * u / e2
    q_u = 0.5 * (k3 * t - 3.0 * u / big_e)
    dq_du = 0.5 * (6.0 * u / e2 * t - k3 * big_e / (u2 + e2) - 3.0 / big_e)
    w2a2 = omega * omega * a * a
    dv_du = -gm / (u2 + e2) + 0.5 * w2a2 * dq_du / q0 * (sb * sb - 1.0 / 3.0)
    dv_db = w2a2 * q_u / q0 * sb * cb
    if p > 0.0:
        cl = x / p
        sl = y / p
    else:
        cl = 1.0
        sl = 0.0
    nu2 = u2 + e2 * sb * sb
    cu = dv_du * (u2 + e2) / nu2
    cbeta = dv_db / nu2
    # cu dr/du + cbeta dr/dbeta
    radial = cu * u / sq * cb - cbeta * sq * sb
    return radial * cl, radial * sl, cu * sb + cbeta * u * cb


@njit(cache=True)
def normal_gravitation_j2_j4(a, f, gm, omega):
    """Zonal coefficients ``J2, J4`` of the level ellipsoid's gravitation (Heiskanen-Moritz 2-92).

    ``J2 = e^2/3 (1 - 2/15 m e' / q0)`` with ``m = omega^2 a^2 b / GM`` and ``e'`` the second
    eccentricity; ``J4 = -3 e^4 / 35 (1 - 2 + 10 J2 / e^2)``.  GRS80: 0.00108263 (its
    defining value) and -2.37091e-6 (Moritz 2000); tests/test_geodesy.py.

    Returns
    -------
    j2, j4 : float
    """
    b = a * (1.0 - f)
    big_e = math.sqrt(a * a - b * b)
    m = omega * omega * a * a * b / gm
    e2 = big_e * big_e / (a * a)
    j2 = e2 / 3.0 * (1.0 - 2.0 / 15.0 * m * (big_e / b) / _q(b, big_e))
    return j2, -3.0 * e2 * e2 / 35.0 * (-1.0 + 10.0 * j2 / e2)


@njit(cache=True)
def zonal4_gravitation_scalar(x, y, z, a, gm, j2, j4):
    """Degree-0, 2 and 4 zonal part of a gravitation field at a point, m/s^2.

    The gradient of ``GM/r (1 - J2 (a/r)^2 P2(z/r) - J4 (a/r)^4 P4(z/r))``: a polynomial in
    ``x, y, z, 1/r``, no transcendental calls.  For the normal field the rest (``J6 = 6.1e-9``
    and beyond) changes by at most 2.5e-13 m/s^2 per metre at flight heights (measured,
    tests/test_geodesy.py), which is what lets the mechanization carry a normal-gravitation
    value over the few metres of an integration step with this function.

    Parameters
    ----------
    x, y, z : float
        Position, m, z along the Earth's axis (ECEF or inertial axes).
    a, gm, j2, j4 : float
        Semi-major axis (m), GM (m^3/s^2), :func:`normal_gravitation_j2_j4`.

    Returns
    -------
    gx, gy, gz : float
        m/s^2, on the axes of ``x, y, z``.
    """
    r2 = x * x + y * y + z * z
    ir2 = 1.0 / r2
    k0 = gm * ir2 * math.sqrt(ir2)
    s2 = z * z * ir2
    a2r2 = a * a * ir2
    k2 = 1.5 * j2 * a2r2
    k4 = 0.125 * j4 * a2r2 * a2r2
    kh = -k0 * (1.0 + k2 * (1.0 - 5.0 * s2) - k4 * 15.0 * ((21.0 * s2 - 14.0) * s2 + 1.0))
    kz = -k0 * (1.0 + k2 * (3.0 - 5.0 * s2) - k4 * 5.0 * ((63.0 * s2 - 70.0) * s2 + 15.0))
    return kh * x, kh * y, kz * z


@njit(cache=True)
def geodetic_trig_scalar(x, y, z, a, f, n_iter=3):
    """Sine and cosine of the geodetic latitude and the ellipsoidal height of a point, no trig calls.

    Bowring's initial value, then ``n_iter`` fixed-point iterations on the latitude, then the
    height by projection, carried out on ``(sin lat, cos lat)`` normalised from the tangent by
    a square root, so it needs no ``atan2``/``sin``/``cos``; the longitude is not formed
    (:func:`ecef_to_geodetic_scalar` is this with four iterations).  The axes may be ECEF or
    inertial (latitude and height do not depend on the longitude).  Measured against four
    iterations at all latitudes (tests/test_geodesy.py):

    ========  =================  =================  ==================
    n_iter    -1e4..2e4 m        2e4..1e5 m         1e5..1e6 m
    ========  =================  =================  ==================
    0         4.1e-13            9.8e-12            6.6e-10
    1         1.3e-15            3.1e-14            1.9e-12
    3         2.2e-16            2.2e-16            3.3e-16
    ========  =================  =================  ==================

    (largest error of ``sin lat`` and ``cos lat``).  The height is stationary in the
    latitude (its error is second order, ~N dlat^2 < 1e-12 m) and agrees to 5e-9 m, the
    round-off of coordinates ~6.4e6 m, with any ``n_iter``.

    Parameters
    ----------
    x, y, z : float
        Position, m (z along the Earth's axis).
    a, f : float
        Semi-major axis (m), flattening.
    n_iter : int
        Iterations after Bowring's value.

    Returns
    -------
    sin_lat, cos_lat, h : float
        Geodetic latitude as its sine and (non-negative) cosine; height, m.
    """
    e2 = f * (2.0 - f)
    b = a * (1.0 - f)
    ep2 = (a * a - b * b) / (b * b)
    p = math.sqrt(x * x + y * y)
    if p < 1e-9:
        return math.copysign(1.0, z), 0.0, abs(z) - b
    za = z * a
    pb = p * b
    d = math.sqrt(za * za + pb * pb)
    st = za / d
    ct = pb / d
    num = z + ep2 * b * st * st * st
    den = p - e2 * a * ct * ct * ct
    d = math.sqrt(num * num + den * den)
    sl = num / d
    cl = den / d
    for _ in range(n_iter):
        n = a / math.sqrt(1.0 - e2 * sl * sl)
        # |lat| < 0.78 rad: the height from p, else from z (better conditioned there)
        h = p / cl - n if cl > 0.7109135380122773 else z / sl - n * (1.0 - e2)
        den = p * (1.0 - e2 * n / (n + h))
        d = math.sqrt(z * z + den * den)
        sl = z / d
        cl = den / d
    n = a / math.sqrt(1.0 - e2 * sl * sl)
    return sl, cl, p * cl + z * sl - a * a / n


@njit(cache=True)
def _geodetic_to_ecef_arr(lat, lon, h, a, f, out):
    for k in range(lat.shape[0]):
        out[k, 0], out[k, 1], out[k, 2] = geodetic_to_ecef_scalar(lat[k], lon[k], h[k], a, f)


@njit(cache=True)
def _ecef_to_geodetic_arr(r, a, f, out):
    for k in range(r.shape[0]):
        out[k, 0], out[k, 1], out[k, 2] = ecef_to_geodetic_scalar(r[k, 0], r[k, 1], r[k, 2], a, f)


@njit(cache=True)
def _gravitation_arr(r, a, f, gm, omega, out):
    for k in range(r.shape[0]):
        out[k, 0], out[k, 1], out[k, 2] = normal_gravitation_ecef_scalar(r[k, 0], r[k, 1], r[k, 2], a, f, gm, omega)


def _broadcast(*arrays):
    arrs = np.broadcast_arrays(*[np.asarray(x, dtype=float) for x in arrays])
    shape = arrs[0].shape
    return shape, [np.ascontiguousarray(x.ravel()) for x in arrs]


def geodetic_to_ecef(lat, lon, h, ellipsoid: Ellipsoid = WGS84):
    """Geodetic latitude, longitude (rad) and ellipsoidal height (m) to ECEF.

    Returns
    -------
    r_e : ndarray, shape (..., 3)
        ECEF position, m.
    """
    shape, (la, lo, hh) = _broadcast(lat, lon, h)
    out = np.empty((la.size, 3))
    _geodetic_to_ecef_arr(la, lo, hh, ellipsoid.a, ellipsoid.f, out)
    return out.reshape(shape + (3,))


def ecef_to_geodetic(r_e, ellipsoid: Ellipsoid = WGS84):
    """ECEF position ``(..., 3)`` in m to (lat rad, lon rad, h m) arrays."""
    r = np.asarray(r_e, dtype=float)
    shape = r.shape[:-1]
    rr = np.ascontiguousarray(r.reshape(-1, 3))
    out = np.empty_like(rr)
    _ecef_to_geodetic_arr(rr, ellipsoid.a, ellipsoid.f, out)
    out = out.reshape(shape + (3,))
    return out[..., 0], out[..., 1], out[..., 2]


def normal_gravitation_ecef(r_e, ellipsoid: Ellipsoid = WGS84):
    """Normal gravitation (attraction, no centrifugal term) at ECEF points.

    Parameters
    ----------
    r_e : array_like, shape (..., 3)
        ECEF positions, m, on or outside the ellipsoid.

    Returns
    -------
    g_e : ndarray, shape (..., 3)
        Gravitation vector resolved on ECEF axes, m/s^2.
    """
    r = np.asarray(r_e, dtype=float)
    shape = r.shape
    rr = np.ascontiguousarray(r.reshape(-1, 3))
    out = np.empty_like(rr)
    _gravitation_arr(rr, *ellipsoid.params(), out)
    return out.reshape(shape)


def normal_gravity_ecef(r_e, ellipsoid: Ellipsoid = WGS84):
    """Normal gravity vector (gravitation + centrifugal) at ECEF points, m/s^2, ``(..., 3)``."""
    r = np.asarray(r_e, dtype=float)
    g = normal_gravitation_ecef(r, ellipsoid)
    g[..., 0] += ellipsoid.omega**2 * r[..., 0]
    g[..., 1] += ellipsoid.omega**2 * r[..., 1]
    return g


def normal_gravity(lat, h, ellipsoid: Ellipsoid = WGS84):
    """Magnitude of normal gravity at geodetic latitude ``lat`` (rad), height ``h`` (m); m/s^2.

    Closed form (Li & Goetze 2001) through the gradient of the ellipsoidal
    harmonic potential; equals ``boule.Ellipsoid.normal_gravity`` (tested).
    """
    lat = np.asarray(lat, dtype=float)
    r = geodetic_to_ecef(lat, np.zeros_like(lat), h, ellipsoid)
    return np.linalg.norm(normal_gravity_ecef(r, ellipsoid), axis=-1)


def normal_gravitational_potential(r_e, ellipsoid: Ellipsoid = WGS84):
    """Gravitational potential V (m^2/s^2) at ECEF points ``(..., 3)``."""
    r = np.asarray(r_e, dtype=float).reshape(-1, 3)
    v = np.array([normal_gravitational_potential_scalar(*p, *ellipsoid.params()) for p in r])
    return v.reshape(np.asarray(r_e).shape[:-1])


def mat_en(lat, lon):
    """Rotation matrices ENU -> ECEF, shape ``(..., 3, 3)``; columns are E, N, U in ECEF."""
    lat = np.asarray(lat, dtype=float)
    lon = np.asarray(lon, dtype=float)
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    m = np.empty(np.broadcast(lat, lon).shape + (3, 3))
    m[..., 0, 0] = -so
    m[..., 0, 1] = -sl * co
    m[..., 0, 2] = cl * co
    m[..., 1, 0] = co
    m[..., 1, 1] = -sl * so
    m[..., 1, 2] = cl * so
    m[..., 2, 0] = 0.0
    m[..., 2, 1] = cl
    m[..., 2, 2] = sl
    return m


def radii_of_curvature(lat, ellipsoid: Ellipsoid = WGS84):
    """Meridian (M) and prime-vertical (N) radii of curvature, m."""
    s2 = np.sin(lat) ** 2
    e2 = ellipsoid.e2
    w = np.sqrt(1.0 - e2 * s2)
    return ellipsoid.a * (1 - e2) / w**3, ellipsoid.a / w


def local_displacement(lat_a, lon_a, lat_b, lon_b, height=0.0, ellipsoid: Ellipsoid = WGS84):
    """East and north displacement from point ``a`` to point ``b`` a short way off, m.

    The latitude and longitude differences (the longitude's wrapped to [-pi, pi), so across the
    antimeridian too) times the radii of curvature at the mean latitude, at ``height`` above
    the ellipsoid: the local tangent plane, good to a part in 1e5 over a few km (GNSS residuals,
    steps between fixes), not for distances across a survey (:mod:`pyproj` there).

    Parameters
    ----------
    lat_a, lon_a, lat_b, lon_b : array_like
        rad; broadcast together.
    height : array_like
        m above the ellipsoid.
    ellipsoid : Ellipsoid

    Returns
    -------
    east, north : ndarray
        m, the broadcast shape.
    """
    lat_a, lat_b = np.asarray(lat_a, float), np.asarray(lat_b, float)
    mid = 0.5 * (lat_a + lat_b)
    m_rad, n_rad = radii_of_curvature(mid, ellipsoid)
    d_lon = (np.asarray(lon_b, float) - np.asarray(lon_a, float) + np.pi) % (2.0 * np.pi) - np.pi
    return d_lon * (n_rad + height) * np.cos(mid), (lat_b - lat_a) * (m_rad + height)


def wrap_deg(angle_deg):
    """Angles (longitudes, headings, their differences) wrapped to [-180, 180) deg, as a
    receiver writes a longitude; any shape."""
    return (np.asarray(angle_deg, float) + 180.0) % 360.0 - 180.0


def mat_ie(t, omega: float = OMEGA_E):
    """Rotation matrices ECEF -> inertial at times ``t`` (s after the reference epoch), ``(..., 3, 3)``."""
    t = np.asarray(t, dtype=float)
    c, s = np.cos(omega * t), np.sin(omega * t)
    m = np.zeros(t.shape + (3, 3))
    m[..., 0, 0] = c
    m[..., 0, 1] = -s
    m[..., 1, 0] = s
    m[..., 1, 1] = c
    m[..., 2, 2] = 1.0
    return m


# --------------------------------------------------------------------------
# Closed-form normal gravity formulas at the ellipsoid (marine / survey practice)
# --------------------------------------------------------------------------

#: Named closed-form normal gravity formulas (on the ellipsoid, m/s^2 from latitude only).
#: IGF1930: International Gravity Formula 1930 (Cassinis), ``978049 (1 + 0.0052884 sin^2 phi -
#: 0.0000059 sin^2 2phi)`` mGal.  IGF1967: Geodetic Reference System 1967 series, ``978031.846
#: (1 + 0.005278895 sin^2 phi + 0.000023462 sin^4 phi)`` mGal (the formula of most marine
#: gravity archives, e.g. NCEI MGD77).  GRS80 and WGS84: Somigliana's closed form
#: ``gamma_e (1 + k sin^2 phi) / sqrt(1 - e^2 sin^2 phi)`` (Moritz 2000; NIMA TR8350.2).
NORMAL_GRAVITY_FORMULAS = ("IGF1930", "IGF1967", "GRS80", "WGS84")
#: Formula used when none is configured.
DEFAULT_NORMAL_GRAVITY_FORMULA = "GRS80"
#: Somigliana constants (gamma_e m/s^2, k, e^2) of GRS80 (Moritz 2000) and WGS84 (TR8350.2).
SOMIGLIANA = {
    "GRS80": (9.7803267715, 0.001931851353, 0.00669438002290),
    "WGS84": (9.7803253359, 0.00193185265241, 0.00669437999013),
}
#: GRS80 m = omega^2 a^2 b / GM, for the second-order free-air term.
GRS80_M = 0.00344978600308


def normal_gravity_formula(lat, formula: str = DEFAULT_NORMAL_GRAVITY_FORMULA):
    """Normal gravity on the ellipsoid by a named closed-form formula, m/s^2.

    Parameters
    ----------
    lat : array_like, shape (n,)
        Geodetic latitude, rad.
    formula : {'IGF1930', 'IGF1967', 'GRS80', 'WGS84'}
        See :data:`NORMAL_GRAVITY_FORMULAS`.  GRS80/WGS84 equal :func:`normal_gravity` at
        ``h = 0`` to < 1e-9 m/s^2 (tested); IGF1967 is 0.7-0.9 mGal above GRS80 and IGF1930
        about 16 mGal above.

    Returns
    -------
    ndarray, shape (n,)

    Raises
    ------
    ValueError
        Unknown formula name (the message lists the valid ones).
    """
    s2 = np.sin(np.asarray(lat, dtype=float)) ** 2
    key = str(formula).upper()
    if key in SOMIGLIANA:
        ge, k, e2 = SOMIGLIANA[key]
        return ge * (1.0 + k * s2) / np.sqrt(1.0 - e2 * s2)
    if key == "IGF1967":
        return 978031.846e-5 * (1.0 + 0.005278895 * s2 + 0.000023462 * s2 * s2)
    if key == "IGF1930":
        # sin^2(2 phi) = 4 sin^2 phi cos^2 phi
        return 978049.0e-5 * (1.0 + 0.0052884 * s2 - 0.0000059 * 4.0 * s2 * (1.0 - s2))
    raise ValueError(
        f"unknown normal gravity formula {formula!r}; expected one of {', '.join(NORMAL_GRAVITY_FORMULAS)}"
    )


def normal_gravity_formula_at_height(lat, height, formula: str = DEFAULT_NORMAL_GRAVITY_FORMULA):
    """Closed-form normal gravity at ellipsoidal ``height`` (m) above the ellipsoid, m/s^2.

    ``gamma_h = gamma_0 [1 - 2/a (1 + f + m - 2 f sin^2 phi) h + 3 h^2 / a^2]`` (Heiskanen &
    Moritz 1967 eq. 2-124, GRS80 a, f, m for every formula: the height term of the other
    ellipsoids differs by < 1e-6 of itself).  At 0 m it is :func:`normal_gravity_formula`.  It is
    a series to first order in f: with GRS80 it departs from the exact :func:`normal_gravity`
    (and boule) by up to 0.010 mGal per km of height at the equator, 0 at the poles (measured:
    0.0102 mGal at 1 km, 0.070 mGal at 10 km).  Use :func:`normal_gravity` where that matters.

    Parameters
    ----------
    lat : array_like, shape (n,)
        Geodetic latitude, rad.
    height : array_like, shape (n,)
        Ellipsoidal height, m.
    formula : str
        See :func:`normal_gravity_formula`.

    Returns
    -------
    ndarray, shape (n,)
    """
    g0 = normal_gravity_formula(lat, formula)
    a, f = GRS80.a, GRS80.f
    s2 = np.sin(np.asarray(lat, dtype=float)) ** 2
    h = np.asarray(height, dtype=float)
    return g0 * (1.0 - 2.0 / a * (1.0 + f + GRS80_M - 2.0 * f * s2) * h + 3.0 * h * h / (a * a))
