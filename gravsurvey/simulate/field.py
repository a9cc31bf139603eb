"""Anomalous gravity field models of the flight simulator (the "truth" field).

Everything here is exact forward modelling of simple bodies, independent of the
estimator (this module imports only :mod:`gravsurvey.geodesy` and
:mod:`gravsurvey.errors`).  See ``docs/field-models.md`` for the schema, the
formulas and the measured accuracy.

Sources
-------
* point masses (negative mass = repelling source, i.e. a mass deficit);
* the "gravitational dipole" of seed 003 (Staroseltsev & Yashnikova 2016): an
  attracting and a repelling point mass of equal size;
* rectangular prisms of constant density contrast (basin < 0, ridge > 0),
  closed form of Nagy, Papp & Benedek (2000, 2002), evaluated in the prism's
  own East-North-Up tangent frame and rotated to ECEF.

Along-track time/distance functions (not functions of position)
---------------------------------------------------------------
* :func:`seed_smooth_disturbance`, :func:`seed_steps_disturbance`: the seed 004
  benchmark anomalies as read in ``model.md`` section 3;
* :func:`markov_disturbance`: a realisation of the first-order Gauss-Markov
  process in distance, the filter's own anomaly model.

Sign conventions
----------------
``V`` is the gravitational potential with the geodetic sign (positive,
``g = grad V``); the anomalous *gravitation* vector points towards excess mass.
The gravity *disturbance* is ``-(anomalous gravitation) . Up`` (positive over
excess mass), in m/s^2.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field as dc_field

import numpy as np
from numba import njit, prange

from gravsurvey.errors import ConfigError, DataError, check_keys
from gravsurvey.geodesy import (
    MGAL,
    WGS84,
    Ellipsoid,
    ecef_to_geodetic,
    geodetic_to_ecef,
    mat_en,
    normal_gravitation_ecef,
)

#: Newtonian constant of gravitation, CODATA 2018, m^3 kg^-1 s^-2.
G_NEWTON = 6.67430e-11


#: Observation points processed at once by the vectorised evaluators; bounds the
#: temporaries to a few tens of MB whatever the number of points.
CHUNK_POINTS = 32768

#: Point-mass evaluation holds (points x sources) pairs; at most this many at once.
CHUNK_PAIRS = 1 << 20

#: A prism is evaluated as a point mass + quadrupole beyond the distance (from its
#: centre) where the closed form's rounding error, measured ~3 eps ln(R) R^3/vol
#: relative (the 8-corner sum cancels), exceeds the multipole's truncation error,
#: measured ~0.03 (D/R)^4 (D the diagonal): R_switch = (FAR_COEF D^4 vol/eps)^(1/7),
#: but never closer than FAR_MIN_RATIO diagonals.  See docs/field-models.md.
FAR_COEF = 7.7e-4
FAR_MIN_RATIO = 10.0


# --------------------------------------------------------------------------
# Point masses
# --------------------------------------------------------------------------


def _as_points(r_e, name="r_e"):
    r = np.asarray(r_e, dtype=float)
    if r.ndim == 1 and r.shape[0] == 3:
        r = r[None, :]
    if r.ndim != 2 or r.shape[1] != 3:
        raise DataError(f"{name}: expected an (n, 3) array of positions in m, got shape {r.shape}")
    return r


def point_mass_gravitation(r_e, source_e, mass):
    """Newtonian attraction of point masses at observation points.

    Parameters
    ----------
    r_e : array_like, shape (n, 3)
        Observation points, m (any Cartesian frame; ECEF in the simulator).
    source_e : array_like, shape (m, 3)
        Source positions in the same frame, m.
    mass : array_like, shape (m,)
        Masses, kg; a negative mass repels (a mass deficit).

    Returns
    -------
    g_e : ndarray, shape (n, 3)
        Gravitation ``sum_j G m_j (s_j - r) / |s_j - r|^3``, m/s^2, same frame.
        Undefined (inf/nan) at a source position.
    """
    r = _as_points(r_e)
    s = _as_points(source_e, "source_e")
    m = np.atleast_1d(np.asarray(mass, dtype=float))
    if m.shape != (s.shape[0],):
        raise DataError(f"mass: expected shape ({s.shape[0]},) to match source_e, got {m.shape}")
    out = np.zeros_like(r)
    gm = G_NEWTON * m
    step = max(1, min(CHUNK_POINTS, CHUNK_PAIRS // max(1, m.size)))
    for k0 in range(0, r.shape[0], step):
        d = s[None, :, :] - r[k0 : k0 + step, None, :]  # (k, m, 3)
        dist2 = np.einsum("kmi,kmi->km", d, d)
        w = gm / (dist2 * np.sqrt(dist2))  # (k, m)
        out[k0 : k0 + step] = np.einsum("km,kmi->ki", w, d)
    return out


def point_mass_potential(r_e, source_e, mass):
    """Gravitational potential ``sum_j G m_j / |s_j - r|`` of point masses, m^2/s^2, shape (n,).

    Parameters as in :func:`point_mass_gravitation`.
    """
    r = _as_points(r_e)
    s = _as_points(source_e, "source_e")
    m = np.atleast_1d(np.asarray(mass, dtype=float))
    if m.shape != (s.shape[0],):
        raise DataError(f"mass: expected shape ({s.shape[0]},) to match source_e, got {m.shape}")
    out = np.zeros(r.shape[0])
    gm = G_NEWTON * m
    step = max(1, min(CHUNK_POINTS, CHUNK_PAIRS // max(1, m.size)))
    for k0 in range(0, r.shape[0], step):
        d = s[None, :, :] - r[k0 : k0 + step, None, :]
        dist = np.sqrt(np.einsum("kmi,kmi->km", d, d))
        out[k0 : k0 + step] = (gm / dist).sum(axis=1)
    return out


def _source_point_e(lat_deg, lon_deg, depth_m, ellipsoid):
    return geodetic_to_ecef(math.radians(lat_deg), math.radians(lon_deg), -float(depth_m), ellipsoid)


def dipole_sources(lat_deg, lon_deg, depth_m, mass_kg, separation_m, azimuth_deg, ellipsoid: Ellipsoid = WGS84):
    """The attracting/repelling point-mass pair ("gravitational dipole") of seed 003.

    Seed 003 models a rugged field by superposing the attraction of "attracting"
    and "repelling" point masses; the elementary pair is the dipole.  Here the
    pair's centre is at geodetic ``(lat_deg, lon_deg)``, ``depth_m`` below the
    ellipsoid; the masses ``+mass_kg`` and ``-mass_kg`` sit ``separation_m``
    apart on the horizontal (tangent-plane) line through the centre with
    azimuth ``azimuth_deg`` (clockwise from north); the attracting mass is the
    one on the azimuth side.

    Parameters
    ----------
    lat_deg, lon_deg : float
        Geodetic latitude/longitude of the centre, deg.
    depth_m : float
        Depth of the centre below the ellipsoid, m (> 0).
    mass_kg : float
        Size of each mass, kg (> 0).
    separation_m : float
        Distance between the two masses, m (> 0).
    azimuth_deg : float
        Direction from the repelling to the attracting mass, deg clockwise from north.
    ellipsoid : Ellipsoid

    Returns
    -------
    source_e : ndarray, shape (2, 3)
        ECEF positions (attracting first), m.
    mass : ndarray, shape (2,)
        ``[+mass_kg, -mass_kg]``, kg.
    """
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    centre = geodetic_to_ecef(lat, lon, -float(depth_m), ellipsoid)
    az = math.radians(azimuth_deg)
    half_n = 0.5 * float(separation_m) * np.array([math.sin(az), math.cos(az), 0.0])
    half_e = mat_en(lat, lon) @ half_n
    src = np.stack([centre + half_e, centre - half_e])
    return src, np.array([float(mass_kg), -float(mass_kg)])


# --------------------------------------------------------------------------
# Rectangular prism (Nagy, Papp & Benedek 2000, 2002)
# --------------------------------------------------------------------------
#
# With (x, y, z) a prism corner relative to the observation point (source minus
# observer) and r = |(x, y, z)|, the antiderivatives of 1/r and of x/r^3 over the
# box are (Nagy et al. 2000, eqs. 7-9):
#   V  = G rho ||| x y ln(z+r) + y z ln(x+r) + z x ln(y+r)
#                  - x^2/2 atan(yz/(xr)) - y^2/2 atan(zx/(yr)) - z^2/2 atan(xy/(zr)) |||
#   gx = -G rho ||| y ln(z+r) + z ln(y+r) - x atan(yz/(xr)) |||   (and cyclic)
# where ||| f ||| = sum over the 8 corners of +-f (+ for an even number of
# upper bounds).  Numerical care:
# * ln(z+r) for z < 0 suffers cancellation when |z| ~ r (points beside a long
#   prism, or far away); use ln(z+r) = ln((x^2+y^2)/(r-z)), exact algebra.
# * every log/atan term carries a factor that vanishes where its log or atan
#   argument is singular (observation point on a face plane, edge or corner);
#   those terms are set to their limit 0.
# * the plain atan (not atan2) is required: its jump at x = 0 is multiplied by
#   x (or x^2) and the sum stays continuous.


def _safe_log_sum(a, b, c, r):
    """ln(a + r) with r = sqrt(a^2+b^2+c^2), cancellation-free for a < 0; 0 where a + r == 0."""
    with np.errstate(divide="ignore", invalid="ignore"):
        arg = np.where(a >= 0.0, a + r, (b * b + c * c) / (r - a))
    arg[arg == 0.0] = 1.0  # the term's factor vanishes there: limit 0
    return np.log(arg)


def _safe_atan(num, den):
    """atan(num/den), 0 where den == 0 (its factor vanishes there)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        val = np.arctan(num / den)
    val[den == 0.0] = 0.0
    return val


def _prism_corners(e, n, u, bounds):
    """Corner coordinates relative to the observation points and their signs.

    Returns x, y, z of shape (k, 8) and sign of shape (8,).
    """
    w, ea, s, no, b, t = (float(v) for v in bounds)
    x_b = np.stack([w - e, ea - e], axis=-1)  # (k, 2)
    y_b = np.stack([s - n, no - n], axis=-1)
    z_b = np.stack([b - u, t - u], axis=-1)
    idx = np.array([(i, j, k) for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    x = x_b[:, idx[:, 0]]
    y = y_b[:, idx[:, 1]]
    z = z_b[:, idx[:, 2]]
    # (-1)^(number of lower bounds): +1 for the all-upper corner (index sum 3)
    sign = np.where((3 - idx.sum(axis=1)) % 2 == 0, 1.0, -1.0)
    return x, y, z, sign


def _check_bounds(bounds):
    b = np.asarray(bounds, dtype=float)
    if b.shape != (6,) or not np.all(np.isfinite(b)):
        raise DataError(
            f"prism bounds: expected 6 finite numbers (west, east, south, north, bottom, top), got {bounds!r}"
        )
    if not (b[0] < b[1] and b[2] < b[3] and b[4] < b[5]):
        raise DataError(f"prism bounds: expected west < east, south < north, bottom < top, got {tuple(b)}")
    return b


def _local_points(e, n, u):
    e, n, u = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (e, n, u)))
    return e.shape, e.ravel(), n.ravel(), u.ravel()


def prism_gravitation_local(e, n, u, bounds, density):
    """Gravitation of a homogeneous rectangular prism, closed form, local ENU frame.

    Compiled (numba) path; :func:`prism_gravitation_local_numpy` is the
    pure-numpy reference it is tested against.

    Parameters
    ----------
    e, n, u : array_like, broadcastable, shape (...)
        Observation points' east, north, up coordinates, m.
    bounds : sequence of 6 floats
        ``(west, east, south, north, bottom, top)``, m, in the same frame.
    density : float
        Density (contrast), kg/m^3; negative for a mass deficit.

    Returns
    -------
    g_n : ndarray, shape (..., 3)
        Gravitation (attraction, towards excess mass) on the E, N, U axes, m/s^2.
        Continuous and finite everywhere, including on faces, edges and inside.
    """
    b = _check_bounds(bounds)
    shape, e, n, u = _local_points(e, n, u)
    out = np.empty((e.size, 3))
    _prism_kernel(e, n, u, b, _switch_radius(b), False, out)
    return (G_NEWTON * float(density)) * out.reshape(shape + (3,))


def prism_gravitation_local_numpy(e, n, u, bounds, density):
    """Pure-numpy reference of :func:`prism_gravitation_local` (same parameters and result)."""
    b = _check_bounds(bounds)
    shape, e, n, u = _local_points(e, n, u)
    out = np.empty((e.size, 3))
    far = _far_mask(e, n, u, b)
    near = ~far
    if far.any():
        out[far] = _prism_multipole(e[far], n[far], u[far], b, potential=False)
    if near.any():
        en, nn, un = e[near], n[near], u[near]
        res = np.empty((en.size, 3))
        for k0 in range(0, en.size, CHUNK_POINTS):
            sl = slice(k0, k0 + CHUNK_POINTS)
            res[sl] = _prism_gravitation_chunk(en[sl], nn[sl], un[sl], b)
        out[near] = res
    return (G_NEWTON * float(density)) * out.reshape(shape + (3,))


def _prism_gravitation_chunk(e, n, u, b):
    x, y, z, sign = _prism_corners(e, n, u, b)
    r = np.sqrt(x * x + y * y + z * z)
    lx = _safe_log_sum(x, y, z, r)
    ly = _safe_log_sum(y, z, x, r)
    lz = _safe_log_sum(z, x, y, r)
    ax = x * _safe_atan(y * z, x * r)
    ay = y * _safe_atan(z * x, y * r)
    az = z * _safe_atan(x * y, z * r)
    gx = -((y * lz + z * ly - ax) @ sign)
    gy = -((z * lx + x * lz - ay) @ sign)
    gz = -((x * ly + y * lx - az) @ sign)
    return np.stack([gx, gy, gz], axis=-1)


def prism_potential_local(e, n, u, bounds, density):
    """Gravitational potential of a homogeneous rectangular prism (closed form), m^2/s^2.

    Parameters as in :func:`prism_gravitation_local`; returns shape (...).
    Geodetic sign: positive for a positive density, ``g = grad V``.  Compiled
    path; :func:`prism_potential_local_numpy` is the reference.
    """
    b = _check_bounds(bounds)
    shape, e, n, u = _local_points(e, n, u)
    out = np.empty((e.size, 1))
    _prism_kernel(e, n, u, b, _switch_radius(b), True, out)
    return (G_NEWTON * float(density)) * out[:, 0].reshape(shape)


def prism_potential_local_numpy(e, n, u, bounds, density):
    """Pure-numpy reference of :func:`prism_potential_local`."""
    b = _check_bounds(bounds)
    shape, e, n, u = _local_points(e, n, u)
    out = np.empty(e.size)
    far = _far_mask(e, n, u, b)
    near = ~far
    if far.any():
        out[far] = _prism_multipole(e[far], n[far], u[far], b, potential=True)
    if near.any():
        en, nn, un = e[near], n[near], u[near]
        res = np.empty(en.size)
        for k0 in range(0, en.size, CHUNK_POINTS):
            sl = slice(k0, k0 + CHUNK_POINTS)
            res[sl] = _prism_potential_chunk(en[sl], nn[sl], un[sl], b)
        out[near] = res
    return (G_NEWTON * float(density)) * out.reshape(shape)


def _prism_potential_chunk(e, n, u, b):
    """Closed-form potential corner sum (without G rho), shape (k,)."""
    x, y, z, sign = _prism_corners(e, n, u, b)
    r = np.sqrt(x * x + y * y + z * z)
    lx = _safe_log_sum(x, y, z, r)
    ly = _safe_log_sum(y, z, x, r)
    lz = _safe_log_sum(z, x, y, r)
    f = (
        x * y * lz
        + y * z * lx
        + z * x * ly
        - 0.5 * x * x * _safe_atan(y * z, x * r)
        - 0.5 * y * y * _safe_atan(z * x, y * r)
        - 0.5 * z * z * _safe_atan(x * y, z * r)
    )
    return f @ sign


def _switch_radius(b):
    """Distance from the prism centre beyond which the multipole is used (see ``FAR_COEF``), m."""
    sides = b[1::2] - b[0::2]
    diag2 = float(np.sum(sides**2))
    vol = float(np.prod(sides))
    r_switch = (FAR_COEF * diag2 * diag2 * vol / np.finfo(float).eps) ** (1.0 / 7.0)
    return max(r_switch, FAR_MIN_RATIO * math.sqrt(diag2))


def _far_mask(e, n, u, b):
    """Points where the multipole is more accurate than the closed form."""
    c = 0.5 * (b[0::2] + b[1::2])
    r_switch = _switch_radius(b)
    d2 = (e - c[0]) ** 2 + (n - c[1]) ** 2 + (u - c[2]) ** 2
    return d2 > r_switch * r_switch


def _prism_multipole(e, n, u, b, potential):
    """Point mass + quadrupole of the prism about its centre (without G rho).

    The box is symmetric about its centre, so the dipole and octupole moments
    vanish and the truncation error is of order (diagonal/distance)^4 relative.
    ``V = vol/R + sum_i Q_ii X_i^2 / (2 R^5)`` with the traceless quadrupole
    ``Q_ii = vol (h_i^2 - |h|^2/3)`` (h the half-sides; ``<x_i^2> = h_i^2/3``),
    and ``g = grad V``.
    """
    c = 0.5 * (b[0::2] + b[1::2])
    h2 = (0.5 * (b[1::2] - b[0::2])) ** 2
    vol = 8.0 * math.sqrt(float(h2.prod()))
    q = vol * (h2 - h2.sum() / 3.0)
    x = np.stack([e - c[0], n - c[1], u - c[2]], axis=-1)
    r2 = np.einsum("ki,ki->k", x, x)
    r = np.sqrt(r2)
    s = (x * x) @ q
    if potential:
        return vol / r + s / (2.0 * r2 * r2 * r)
    r3 = r2 * r
    r5 = r3 * r2
    r7 = r5 * r2
    return -vol * x / r3[:, None] + (q * x) / r5[:, None] - (2.5 * s / r7)[:, None] * x


@njit(cache=True)
def _log_sum_scalar(a, b, c, r):
    # scalar twin of _safe_log_sum
    if a >= 0.0:
        arg = a + r
    else:
        arg = (b * b + c * c) / (r - a)
    if arg == 0.0:
        return 0.0
    return math.log(arg)


@njit(cache=True)
def _atan_scalar(num, den):
    # scalar twin of _safe_atan
    if den == 0.0:
        return 0.0
    return math.atan(num / den)


@njit(cache=True, parallel=True)
def _prism_kernel(e, n, u, b, r_switch, potential, out):
    """Closed form (near) / point mass + quadrupole (far) of a unit-density prism without G.

    ``out`` has shape (k, 3) for the gravitation or (k, 1) for the potential.
    """
    ce = 0.5 * (b[0] + b[1])
    cn = 0.5 * (b[2] + b[3])
    cu = 0.5 * (b[4] + b[5])
    hx2 = (0.5 * (b[1] - b[0])) ** 2
    hy2 = (0.5 * (b[3] - b[2])) ** 2
    hz2 = (0.5 * (b[5] - b[4])) ** 2
    vol = (b[1] - b[0]) * (b[3] - b[2]) * (b[5] - b[4])
    h2m = (hx2 + hy2 + hz2) / 3.0
    qx, qy, qz = vol * (hx2 - h2m), vol * (hy2 - h2m), vol * (hz2 - h2m)
    rs2 = r_switch * r_switch
    for k in prange(e.shape[0]):  # points are independent: no cross-thread reduction
        dx, dy, dz = e[k] - ce, n[k] - cn, u[k] - cu
        d2 = dx * dx + dy * dy + dz * dz
        if d2 > rs2:
            d = math.sqrt(d2)
            sq = qx * dx * dx + qy * dy * dy + qz * dz * dz
            if potential:
                out[k, 0] = vol / d + sq / (2.0 * d2 * d2 * d)
            else:
                d3 = d2 * d
                d5 = d3 * d2
                d7 = d5 * d2
                c7 = 2.5 * sq / d7
                out[k, 0] = -vol * dx / d3 + qx * dx / d5 - c7 * dx
                out[k, 1] = -vol * dy / d3 + qy * dy / d5 - c7 * dy
                out[k, 2] = -vol * dz / d3 + qz * dz / d5 - c7 * dz
            continue
        gx = 0.0
        gy = 0.0
        gz = 0.0
        v = 0.0
        for i in range(2):
            x = b[i] - e[k]
            for j in range(2):
                y = b[2 + j] - n[k]
                for m in range(2):
                    z = b[4 + m] - u[k]
                    sgn = 1.0 if (i + j + m) % 2 == 1 else -1.0  # (-1)^(lower bounds)
                    r = math.sqrt(x * x + y * y + z * z)
                    lx = _log_sum_scalar(x, y, z, r)
                    ly = _log_sum_scalar(y, z, x, r)
                    lz = _log_sum_scalar(z, x, y, r)
                    tx = _atan_scalar(y * z, x * r)
                    ty = _atan_scalar(z * x, y * r)
                    tz = _atan_scalar(x * y, z * r)
                    if potential:
                        v += sgn * (x * y * lz + y * z * lx + z * x * ly - 0.5 * (x * x * tx + y * y * ty + z * z * tz))
                    else:
                        gx -= sgn * (y * lz + z * ly - x * tx)
                        gy -= sgn * (z * lx + x * lz - y * ty)
                        gz -= sgn * (x * ly + y * lx - z * tz)
        if potential:
            out[k, 0] = v
        else:
            out[k, 0] = gx
            out[k, 1] = gy
            out[k, 2] = gz


# --------------------------------------------------------------------------
# Field model: sources in geodetic placement, evaluated in ECEF
# --------------------------------------------------------------------------

#: ``field.type`` values: ``model`` = the sources below, a function of position;
#: the others are along-track functions (see :func:`along_track_disturbance`).
FIELD_TYPES = ("model", "seed_smooth", "seed_steps", "markov")

#: Largest accepted |density contrast|, kg/m^3 (osmium is 22 590 kg/m^3).
MAX_DENSITY_KGM3 = 25000.0


@dataclass(frozen=True)
class PointMass:
    """A point mass ``depth_m`` below the ellipsoid at (``lat_deg``, ``lon_deg``); ``mass_kg`` < 0 repels."""

    lat_deg: float
    lon_deg: float
    depth_m: float
    mass_kg: float


@dataclass(frozen=True)
class Dipole:
    """Seed 003 attracting/repelling pair; see :func:`dipole_sources` for the geometry."""

    lat_deg: float
    lon_deg: float
    depth_m: float
    mass_kg: float
    separation_m: float
    azimuth_deg: float


@dataclass(frozen=True)
class Prism:
    """A rectangular prism in the ENU tangent frame at (``lat_deg``, ``lon_deg``, height 0).

    ``east_m = (west, east)``, ``north_m = (south, north)`` are offsets from the
    reference point, m; ``depth_m = (top, bottom)`` depths below the reference
    point, m (negative = above the ellipsoid, e.g. a ridge of topography);
    ``density_kgm3`` the density contrast (basin < 0, ridge > 0).
    """

    lat_deg: float
    lon_deg: float
    east_m: tuple
    north_m: tuple
    depth_m: tuple
    density_kgm3: float

    @property
    def bounds(self):
        """Local ENU bounds ``(west, east, south, north, bottom, top)``, m (up positive)."""
        return (self.east_m[0], self.east_m[1], self.north_m[0], self.north_m[1], -self.depth_m[1], -self.depth_m[0])


@dataclass(frozen=True)
class FieldModel:
    """The simulator's anomalous field.

    Attributes
    ----------
    type : str
        One of :data:`FIELD_TYPES`.
    point_masses, dipoles, prisms : tuple
        Sources (``type == "model"`` only).
    lambda_s_per_m, sigma_mps2 : float
        Gauss-Markov parameters in distance (``type == "markov"``): inverse
        correlation distance, 1/m, and standard deviation, m/s^2.
    seed : int
        Random seed of the Markov realisation.
    ellipsoid : Ellipsoid
        Ellipsoid the source placements (latitude, longitude, depth) refer to.
    horizontal : bool
        Whether the flight's sensors feel the sources' horizontal components (``type ==
        "model"``).  False keeps the vertical only: not a physical field, for tests that
        isolate what the deflections of the vertical do to an estimate.
    """

    type: str = "model"
    point_masses: tuple = ()
    dipoles: tuple = ()
    prisms: tuple = ()
    lambda_s_per_m: float = 1.0e-5
    sigma_mps2: float = 1.0e-3
    seed: int = 0
    ellipsoid: Ellipsoid = dc_field(default=WGS84)
    horizontal: bool = True

    @property
    def n_sources(self) -> int:
        """Number of elementary sources (a dipole counts 2)."""
        return len(self.point_masses) + 2 * len(self.dipoles) + len(self.prisms)


def _point_sources(model: FieldModel):
    """All point masses of the model (dipoles expanded): ``(source_e (m, 3), mass (m,))``."""
    src, mass = [], []
    for p in model.point_masses:
        src.append(_source_point_e(p.lat_deg, p.lon_deg, p.depth_m, model.ellipsoid)[None, :])
        mass.append(np.array([p.mass_kg], dtype=float))
    for d in model.dipoles:
        s, m = dipole_sources(
            d.lat_deg, d.lon_deg, d.depth_m, d.mass_kg, d.separation_m, d.azimuth_deg, model.ellipsoid
        )
        src.append(s)
        mass.append(m)
    if not src:
        return np.zeros((0, 3)), np.zeros(0)
    return np.concatenate(src), np.concatenate(mass)


def _prism_frames(model: FieldModel):
    """Per prism: reference point ECEF (3,), ENU->ECEF matrix (3, 3), bounds (6,), density."""
    out = []
    for p in model.prisms:
        lat, lon = math.radians(p.lat_deg), math.radians(p.lon_deg)
        ref = geodetic_to_ecef(lat, lon, 0.0, model.ellipsoid)
        out.append((ref, mat_en(lat, lon), np.asarray(p.bounds, dtype=float), float(p.density_kgm3)))
    return out


def _check_model_type(model, what):
    if model.type != "model":
        raise ConfigError(
            f"field.type is {model.type!r}: that anomaly is an along-track function, not a function of "
            f"position; {what} needs field.type 'model' (use along_track_disturbance)"
        )


def anomalous_gravitation_ecef(model: FieldModel, r_e):
    """Anomalous gravitation of all sources of ``model`` at ECEF points.

    Parameters
    ----------
    model : FieldModel
        ``type == "model"``.
    r_e : array_like, shape (n, 3)
        ECEF observation points, m.

    Returns
    -------
    g_e : ndarray, shape (n, 3)
        Anomalous gravitation (attraction of the sources) on ECEF axes, m/s^2.
    """
    _check_model_type(model, "anomalous_gravitation_ecef")
    r = _as_points(r_e)
    out = np.zeros_like(r)
    src, mass = _point_sources(model)
    frames = _prism_frames(model)
    for k0 in range(0, r.shape[0], CHUNK_POINTS):
        rc = r[k0 : k0 + CHUNK_POINTS]
        acc = out[k0 : k0 + CHUNK_POINTS]
        if mass.size:
            acc += point_mass_gravitation(rc, src, mass)
        for ref, m, b, rho in frames:
            loc = (rc - ref) @ m  # ENU coordinates: m^T (r - ref), row-wise
            g_n = prism_gravitation_local(loc[:, 0], loc[:, 1], loc[:, 2], b, rho)
            acc += g_n @ m.T
    return out


def anomalous_potential(model: FieldModel, r_e):
    """Anomalous gravitational potential of ``model`` at ECEF points, m^2/s^2, shape (n,).

    Geodetic sign (positive over a positive mass); ``anomalous_gravitation_ecef = grad`` of it.
    """
    _check_model_type(model, "anomalous_potential")
    r = _as_points(r_e)
    out = np.zeros(r.shape[0])
    src, mass = _point_sources(model)
    frames = _prism_frames(model)
    for k0 in range(0, r.shape[0], CHUNK_POINTS):
        rc = r[k0 : k0 + CHUNK_POINTS]
        acc = out[k0 : k0 + CHUNK_POINTS]
        if mass.size:
            acc += point_mass_potential(rc, src, mass)
        for ref, m, b, rho in frames:
            loc = (rc - ref) @ m
            acc += prism_potential_local(loc[:, 0], loc[:, 1], loc[:, 2], b, rho)
    return out


def gravity_disturbance(model: FieldModel, r_e, ellipsoid: Ellipsoid | None = None):
    """Gravity disturbance ``-(anomalous gravitation) . Up`` at ECEF points, m/s^2, shape (n,).

    ``Up`` is the ellipsoid normal through each point (docs/conventions.md);
    positive over excess mass.  ``ellipsoid`` defaults to the model's.
    """
    r = _as_points(r_e)
    g = anomalous_gravitation_ecef(model, r)
    ell = model.ellipsoid if ellipsoid is None else ellipsoid
    lat, lon, _ = ecef_to_geodetic(r, ell)
    up = np.stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)], axis=-1)
    return -np.einsum("ki,ki->k", g, up)


# --------------------------------------------------------------------------
# Gravity-gradient tensors (issue 16 item 2, seed 000)
# --------------------------------------------------------------------------

#: One Eotvos, 1/s^2 (gradients are SI 1/s^2 inside; Eotvos only at the edges).
EOTVOS = 1.0e-9

#: Step of the central differences of the closed-form normal gravitation, m.  The
#: truncation error is ~ (h/r)^2 = 2.5e-10 relative (~1e-6 E), the closed form's
#: rounding (~1e-13 relative of g) / h ~ 1e-5 E; measured trace (Laplace) residual
#: 4e-6 E at 100 m against 5e-5 E at 10 m and 3e-4 E at 1 km.
NORMAL_GRADIENT_STEP_M = 100.0


def point_mass_gradient(r_e, source_e, mass):
    """Gravitation gradient tensor of point masses, exact.

    ``Gamma_ij = d g_i / d r_j = sum_k G m_k (3 d_i d_j / |d|^5 - delta_ij / |d|^3)``
    with ``d = s_k - r``.  Symmetric and trace-free away from the sources.

    Parameters
    ----------
    r_e : array_like, shape (n, 3)
        Observation points, m (any Cartesian frame).
    source_e : array_like, shape (m, 3)
        Source positions in the same frame, m.
    mass : array_like, shape (m,)
        Masses, kg (negative repels).

    Returns
    -------
    gamma : ndarray, shape (n, 3, 3)
        Gradient of the gravitation on the frame's axes, 1/s^2.
    """
    r = _as_points(r_e)
    s = _as_points(source_e, "source_e")
    m = np.atleast_1d(np.asarray(mass, dtype=float))
    if m.shape != (s.shape[0],):
        raise DataError(f"mass: expected shape ({s.shape[0]},) to match source_e, got {m.shape}")
    out = np.zeros((r.shape[0], 3, 3))
    gm = G_NEWTON * m
    step = max(1, min(CHUNK_POINTS, CHUNK_PAIRS // max(1, m.size)))
    eye = np.eye(3)
    for k0 in range(0, r.shape[0], step):
        d = s[None, :, :] - r[k0 : k0 + step, None, :]  # (k, m, 3)
        dist2 = np.einsum("kmi,kmi->km", d, d)
        inv3 = gm / (dist2 * np.sqrt(dist2))  # G m / |d|^3
        out[k0 : k0 + step] = (
            np.einsum("km,kmi,kmj->kij", 3.0 * inv3 / dist2, d, d) - inv3.sum(axis=1)[:, None, None] * eye
        )
    return out


def _atan_ratio(num, den):
    """atan(num/den) with the den -> +0 limit (+-pi/2) where den == 0 and 0 where num == den == 0."""
    with np.errstate(divide="ignore", invalid="ignore"):
        val = np.arctan(num / np.where(den == 0.0, 0.0, den))  # -0.0 -> +0.0: one consistent limit
    val[(num == 0.0) & (den == 0.0)] = 0.0
    return val


def prism_gradient_local(e, n, u, bounds, density):
    """Gravitation gradient tensor of a homogeneous rectangular prism, closed form, local ENU frame.

    Nagy, Papp & Benedek (2000) second derivatives of the prism potential: with
    corner offsets ``x, y, z`` (corner minus observation point),
    ``r = |(x, y, z)|`` and the alternating corner sum ``[[.]]``,

    ``Gamma_ee = -G rho [[atan(y z / (x r))]]``, ``Gamma_en = G rho [[ln(z + r)]]``,
    ``Gamma_eu = G rho [[ln(y + r)]]`` and cyclically.

    The closed form is used at every distance: its rounding error grows like
    ``eps R^3 / volume`` relative, 2e-7 relative at 1000 prism diagonals.

    Parameters
    ----------
    e, n, u : array_like, broadcastable, shape (...)
        Observation points' east, north, up coordinates, m (outside the prism;
        on a face the tensor is discontinuous and one side's limit is returned).
    bounds : sequence of 6 floats
        ``(west, east, south, north, bottom, top)``, m.
    density : float
        Density contrast, kg/m^3.

    Returns
    -------
    gamma_n : ndarray, shape (..., 3, 3)
        ``d g_i / d x_j`` on the E, N, U axes, 1/s^2.
    """
    b = _check_bounds(bounds)
    shape, e, n, u = _local_points(e, n, u)
    out = np.empty((e.size, 3, 3))
    for k0 in range(0, e.size, CHUNK_POINTS):
        sl = slice(k0, k0 + CHUNK_POINTS)
        x, y, z, sign = _prism_corners(e[sl], n[sl], u[sl], b)
        r = np.sqrt(x * x + y * y + z * z)
        blk = out[sl]
        blk[:, 0, 0] = -(_atan_ratio(y * z, x * r) @ sign)
        blk[:, 1, 1] = -(_atan_ratio(z * x, y * r) @ sign)
        blk[:, 2, 2] = -(_atan_ratio(x * y, z * r) @ sign)
        blk[:, 0, 1] = blk[:, 1, 0] = _safe_log_sum(z, x, y, r) @ sign
        blk[:, 0, 2] = blk[:, 2, 0] = _safe_log_sum(y, z, x, r) @ sign
        blk[:, 1, 2] = blk[:, 2, 1] = _safe_log_sum(x, y, z, r) @ sign
    return (G_NEWTON * float(density)) * out.reshape(shape + (3, 3))


def anomalous_gradient_ecef(model: FieldModel, r_e):
    """Gravitation gradient tensor of all sources of ``model`` at ECEF points.

    Parameters
    ----------
    model : FieldModel
        ``type == "model"``.
    r_e : array_like, shape (n, 3)
        ECEF observation points, m.

    Returns
    -------
    gamma_e : ndarray, shape (n, 3, 3)
        ``d g_i / d r_j`` of the anomalous gravitation on ECEF axes, 1/s^2.
    """
    _check_model_type(model, "anomalous_gradient_ecef")
    r = _as_points(r_e)
    out = np.zeros((r.shape[0], 3, 3))
    src, mass = _point_sources(model)
    if mass.size:
        out += point_mass_gradient(r, src, mass)
    for ref, m, b, rho in _prism_frames(model):
        loc = (r - ref) @ m
        gam_n = prism_gradient_local(loc[:, 0], loc[:, 1], loc[:, 2], b, rho)
        out += np.einsum("ij,kjl,ml->kim", m, gam_n, m)  # m gam_n m^T: ENU -> ECEF
    return out


def normal_gradient_ecef(r_e, ellipsoid: Ellipsoid = WGS84):
    """Gradient tensor of the ellipsoid's normal gravitation (attraction only) at ECEF points.

    Central differences (step :data:`NORMAL_GRADIENT_STEP_M`) of the closed-form
    :func:`gravsurvey.geodesy.normal_gravitation_ecef`, symmetrised; accurate to
    ~1e-5 E (trace residual measured 4e-6 E; tests/test_field_gradient.py also
    checks it against the sphere's GM/r^3 tensor to the J2 level).

    Parameters
    ----------
    r_e : array_like, shape (n, 3)
        ECEF points on or outside the ellipsoid, m.

    Returns
    -------
    gamma_e : ndarray, shape (n, 3, 3)
        ``d g_i / d r_j`` on ECEF axes, 1/s^2 (about -1540 E horizontal,
        +3080 E vertical).
    """
    r = _as_points(r_e)
    h = NORMAL_GRADIENT_STEP_M
    out = np.empty((r.shape[0], 3, 3))
    for j in range(3):
        dr = np.zeros(3)
        dr[j] = h
        out[:, :, j] = (normal_gravitation_ecef(r + dr, ellipsoid) - normal_gravitation_ecef(r - dr, ellipsoid)) / (
            2.0 * h
        )
    return 0.5 * (out + np.transpose(out, (0, 2, 1)))


def total_gradient_n(model: FieldModel | None, r_e, lat, lon, ellipsoid: Ellipsoid = WGS84):
    """Normal plus anomalous gravitation gradient on local ENU axes.

    Parameters
    ----------
    model : FieldModel or None
        Anomalous sources (``type == "model"``); None or an along-track field
        type (no sources in space) adds nothing.
    r_e : array_like, shape (n, 3)
        ECEF points, m.
    lat, lon : array_like, shape (n,)
        Geodetic latitude and longitude of the points, rad.

    Returns
    -------
    gamma_n : ndarray, shape (n, 3, 3)
        ``C_ne Gamma_e C_en`` on E, N, U, 1/s^2.
    """
    r = _as_points(r_e)
    gam = normal_gradient_ecef(r, ellipsoid)
    if model is not None and model.type == "model" and (model.n_sources > 0):
        gam = gam + anomalous_gradient_ecef(model, r)
    m_en = mat_en(np.asarray(lat, dtype=float), np.asarray(lon, dtype=float))  # (n, 3, 3) ENU -> ECEF
    return np.einsum("kji,kjl,klm->kim", m_en, gam, m_en)


# --------------------------------------------------------------------------
# Seed along-track anomalies and the Gauss-Markov process
# --------------------------------------------------------------------------


def seed_smooth_disturbance(t_s):
    """Seed 004 smooth anomaly (model.md section 3, our reading), m/s^2.

    ``30 sin(2 pi t/3600) + 20 sin(2 pi t/1500 + 1) + 10 sin(2 pi t/900 + 2)`` mGal,
    ``t_s`` in s from the start of the flight (any shape).  Gravity
    disturbance: positive = stronger gravity.
    """
    t = np.asarray(t_s, dtype=float)
    tp = 2.0 * np.pi * t
    mgal = 30.0 * np.sin(tp / 3600.0) + 20.0 * np.sin(tp / 1500.0 + 1.0) + 10.0 * np.sin(tp / 900.0 + 2.0)
    return mgal * MGAL


#: (time s, step mGal) of the seed's discontinuous anomaly; cumulative.
SEED_STEPS = ((3600.0, 40.0), (7200.0, -60.0), (10800.0, 30.0))


def seed_steps_disturbance(t_s):
    """Seed 004 discontinuous anomaly, m/s^2: 0, then cumulative steps of +40 mGal at 1 h,
    -60 at 2 h, +30 at 3 h (levels 0, 40, -20, 10 mGal); right-continuous (the step
    is in effect from its epoch on).  ``t_s`` in s, any shape."""
    t = np.asarray(t_s, dtype=float)
    mgal = np.zeros_like(t)
    for t0, step in SEED_STEPS:
        mgal = mgal + np.where(t >= t0, step, 0.0)
    return mgal * MGAL


@njit(cache=True)
def _markov_kernel(s, lam, sigma, w0, w, out):
    out[0] = sigma * w0
    for k in range(1, s.shape[0]):
        phi = math.exp(-lam * (s[k] - s[k - 1]))
        out[k] = phi * out[k - 1] + sigma * math.sqrt(max(0.0, 1.0 - phi * phi)) * w[k - 1]


def _markov_reference(s, lam, sigma, w0, w):
    """Pure-numpy/Python reference of :func:`_markov_kernel` (for tests)."""
    out = np.empty(s.shape[0])
    out[0] = sigma * w0
    phi = np.exp(-lam * np.diff(s))
    q = sigma * np.sqrt(np.maximum(0.0, 1.0 - phi * phi))
    for k in range(1, s.shape[0]):
        out[k] = phi[k - 1] * out[k - 1] + q[k - 1] * w[k - 1]
    return out


def markov_disturbance(s_m, lambda_s_per_m, sigma_s_mps2, rng):
    """A realisation of the stationary first-order Gauss-Markov process in distance.

    ``dg/ds = -lambda_s g + sqrt(2 lambda_s) sigma_s w(s)``: covariance
    ``sigma_s^2 exp(-lambda_s |s1 - s2|)``.  Exact discretisation for arbitrary
    (uneven) steps, ``g_k = phi_k g_{k-1} + sigma_s sqrt(1 - phi_k^2) w_k`` with
    ``phi_k = exp(-lambda_s (s_k - s_{k-1}))``; the first value is drawn from the
    stationary distribution N(0, sigma_s^2).

    Parameters
    ----------
    s_m : array_like, shape (n,)
        Along-track distance, m, non-decreasing (n >= 1).
    lambda_s_per_m : float
        Inverse correlation distance, 1/m (> 0).
    sigma_s_mps2 : float
        Standard deviation, m/s^2 (>= 0).
    rng : numpy.random.Generator or int
        Random generator (or seed for ``numpy.random.default_rng``).

    Returns
    -------
    g : ndarray, shape (n,)
        Gravity disturbance, m/s^2.
    """
    s = np.ascontiguousarray(np.asarray(s_m, dtype=float))
    if s.ndim != 1 or s.size < 1:
        raise DataError(f"s_m: expected a 1-D array with at least one distance, got shape {s.shape}")
    if not np.all(np.isfinite(s)):
        raise DataError("s_m: expected finite distances in m, got NaN/inf")
    if np.any(np.diff(s) < 0.0):
        raise DataError("s_m: expected non-decreasing along-track distances in m")
    lam, sig = float(lambda_s_per_m), float(sigma_s_mps2)
    if not (math.isfinite(lam) and lam > 0.0):
        raise ConfigError(f"lambda_s_per_m: expected a positive number in 1/m, got {lambda_s_per_m!r}")
    if not (math.isfinite(sig) and sig >= 0.0):
        raise ConfigError(f"sigma_s_mps2: expected a non-negative number in m/s^2, got {sigma_s_mps2!r}")
    if not isinstance(rng, np.random.Generator):
        rng = np.random.default_rng(rng)
    w = rng.standard_normal(s.size)
    out = np.empty(s.size)
    _markov_kernel(s, lam, sig, w[0], w[1:], out)
    return out


def along_track_disturbance(model: FieldModel, t_s=None, s_m=None, rng=None):
    """Gravity disturbance of an along-track field type, m/s^2.

    Parameters
    ----------
    model : FieldModel
        ``type`` one of ``seed_smooth``, ``seed_steps`` (need ``t_s``) or
        ``markov`` (needs ``s_m``).
    t_s : array_like, optional
        Time from the start of the flight, s.
    s_m : array_like, optional
        Along-track distance, m (non-decreasing).
    rng : numpy.random.Generator or int, optional
        Defaults to ``model.seed``.

    Returns
    -------
    ndarray
        Disturbance (positive = stronger gravity), shape of ``t_s``/``s_m``.
    """
    if model.type in ("seed_smooth", "seed_steps"):
        if t_s is None:
            raise ConfigError(f"field.type {model.type!r} needs the time t_s")
        fn = seed_smooth_disturbance if model.type == "seed_smooth" else seed_steps_disturbance
        return fn(t_s)
    if model.type == "markov":
        if s_m is None:
            raise ConfigError("field.type 'markov' needs the along-track distance s_m")
        return markov_disturbance(s_m, model.lambda_s_per_m, model.sigma_mps2, model.seed if rng is None else rng)
    raise ConfigError(
        "field.type is 'model': the disturbance depends on position; use gravity_disturbance or anomalous_gravitation_ecef"
    )


# --------------------------------------------------------------------------
# Configuration parsing
# --------------------------------------------------------------------------

_SOURCE_KEYS = {
    "point_masses": ("lat_deg", "lon_deg", "depth_m", "mass_kg"),
    "dipoles": ("lat_deg", "lon_deg", "depth_m", "mass_kg", "separation_m", "azimuth_deg"),
    "prisms": ("lat_deg", "lon_deg", "east_m", "north_m", "depth_m", "density_kgm3"),
}
_TOP_KEYS = {
    "model": ("type", "point_masses", "dipoles", "prisms", "horizontal"),
    "seed_smooth": ("type",),
    "seed_steps": ("type",),
    "markov": ("type", "lambda_s_per_m", "sigma_mps2", "seed"),
}
_ALL_TOP_KEYS = sorted({k for keys in _TOP_KEYS.values() for k in keys})


def _describe(v):
    return f"{type(v).__name__} {v!r}" if not isinstance(v, str) else repr(v)


def _parse_float_str(v):
    # PyYAML (YAML 1.1) reads 5.0e11 (no sign after e) as a string: accept such
    # numeric strings; words, nan and inf stay errors.
    try:
        x = float(v.strip())
    except ValueError:
        return None
    return x if math.isfinite(x) else None


def _number(v, path, unit, lo=None, hi=None, lo_open=False, nonzero=False):
    if isinstance(v, str) and _parse_float_str(v) is not None:
        v = _parse_float_str(v)
    if isinstance(v, bool) or not isinstance(v, numbers.Real):
        raise ConfigError(f"{path}: expected a number ({unit}), got {_describe(v)}")
    x = float(v)
    if not math.isfinite(x):
        raise ConfigError(f"{path}: expected a finite number ({unit}), got {v!r}")
    if lo is not None and (x < lo or (lo_open and x == lo)):
        rel = ">" if lo_open else ">="
        raise ConfigError(f"{path}: expected {rel} {lo:g} {unit}, got {v!r}")
    if hi is not None and x > hi:
        raise ConfigError(f"{path}: expected <= {hi:g} {unit}, got {v!r}")
    if nonzero and x == 0.0:
        raise ConfigError(f"{path}: expected a non-zero number ({unit}), got {v!r}")
    return x


def _interval(v, path, unit):
    if not isinstance(v, (list, tuple)) or len(v) != 2:
        raise ConfigError(f"{path}: expected a list of two numbers [low, high] ({unit}), got {_describe(v)}")
    a = _number(v[0], f"{path}[0]", unit)
    b = _number(v[1], f"{path}[1]", unit)
    if not a < b:
        raise ConfigError(f"{path}: expected [low, high] with low < high ({unit}), got {list(v)!r}")
    return (a, b)


def _parse_position(item, path):
    lat = _number(item["lat_deg"], f"{path}.lat_deg", "deg", -90.0, 90.0)
    lon = _number(item["lon_deg"], f"{path}.lon_deg", "deg", -180.0, 360.0)
    return lat, lon


def _parse_point_mass(item, path):
    lat, lon = _parse_position(item, path)
    depth = _number(item["depth_m"], f"{path}.depth_m", "m below the ellipsoid", 0.0, lo_open=True)
    mass = _number(item["mass_kg"], f"{path}.mass_kg", "kg, negative repels", nonzero=True)
    return PointMass(lat, lon, depth, mass)


def _parse_dipole(item, path):
    lat, lon = _parse_position(item, path)
    depth = _number(item["depth_m"], f"{path}.depth_m", "m below the ellipsoid", 0.0, lo_open=True)
    mass = _number(item["mass_kg"], f"{path}.mass_kg", "kg", 0.0, lo_open=True)
    sep = _number(item["separation_m"], f"{path}.separation_m", "m", 0.0, lo_open=True)
    az = _number(item["azimuth_deg"], f"{path}.azimuth_deg", "deg clockwise from north", -360.0, 360.0)
    return Dipole(lat, lon, depth, mass, sep, az)


def _parse_prism(item, path):
    lat, lon = _parse_position(item, path)
    east = _interval(item["east_m"], f"{path}.east_m", "m east of the reference point")
    north = _interval(item["north_m"], f"{path}.north_m", "m north of the reference point")
    depth = _interval(item["depth_m"], f"{path}.depth_m", "m below the ellipsoid, [top, bottom]")
    rho = _number(
        item["density_kgm3"],
        f"{path}.density_kgm3",
        "kg/m^3 density contrast",
        -MAX_DENSITY_KGM3,
        MAX_DENSITY_KGM3,
        nonzero=True,
    )
    return Prism(lat, lon, east, north, depth, rho)


_SOURCE_PARSERS = {"point_masses": _parse_point_mass, "dipoles": _parse_dipole, "prisms": _parse_prism}


def field_model_from_dict(d, key_path: str = "field", ellipsoid: Ellipsoid = WGS84) -> FieldModel:
    """Validate the ``field:`` mapping of a simulation config and build a :class:`FieldModel`.

    Parameters
    ----------
    d : mapping
        The mapping under ``field:`` (schema in ``docs/field-models.md``).
    key_path : str
        Key path of ``d`` in the config, used in error messages.
    ellipsoid : Ellipsoid
        Ellipsoid the placements refer to (the config's top-level ``ellipsoid``).

    Returns
    -------
    FieldModel

    Raises
    ------
    ConfigError
        One line naming the offending key path and what was expected, for any
        unknown key, missing key, wrong type or nonsense value.
    """
    if not isinstance(d, dict):
        raise ConfigError(f"{key_path}: expected a mapping, got {_describe(d)}")
    if "type" not in d:
        check_keys(d, _ALL_TOP_KEYS, key_path)
        raise ConfigError(f"{key_path}.type: missing required key; expected one of {list(FIELD_TYPES)}")
    ftype = d["type"]
    if not isinstance(ftype, str) or ftype not in FIELD_TYPES:
        raise ConfigError(f"{key_path}.type: expected one of {list(FIELD_TYPES)}, got {_describe(ftype)}")
    allowed = _TOP_KEYS[ftype]
    for k in d:
        if k not in allowed and k in _ALL_TOP_KEYS:
            raise ConfigError(
                f"{key_path}.{k}: not allowed with {key_path}.type {ftype!r}; allowed keys {list(allowed)}"
            )
    check_keys(d, allowed, key_path)

    if ftype == "markov":
        lam = _number(d.get("lambda_s_per_m", 1.0e-5), f"{key_path}.lambda_s_per_m", "1/m", 0.0, lo_open=True)
        sig = _number(d.get("sigma_mps2", 1.0e-3), f"{key_path}.sigma_mps2", "m/s^2", 0.0)
        seed = d.get("seed", 0)
        if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0:
            raise ConfigError(f"{key_path}.seed: expected a non-negative integer, got {_describe(seed)}")
        return FieldModel(type=ftype, lambda_s_per_m=lam, sigma_mps2=sig, seed=int(seed), ellipsoid=ellipsoid)
    if ftype != "model":
        return FieldModel(type=ftype, ellipsoid=ellipsoid)

    parsed = {}
    for name, keys in _SOURCE_KEYS.items():
        items = d.get(name, [])
        if items is None:
            items = []
        if not isinstance(items, list):
            raise ConfigError(f"{key_path}.{name}: expected a list of mappings, got {_describe(items)}")
        out = []
        for i, item in enumerate(items):
            path = f"{key_path}.{name}[{i}]"
            if not isinstance(item, dict):
                raise ConfigError(f"{path}: expected a mapping with keys {list(keys)}, got {_describe(item)}")
            check_keys(item, keys, path, required=keys)
            out.append(_SOURCE_PARSERS[name](item, path))
        parsed[name] = tuple(out)
    horizontal = d.get("horizontal", True)
    if not isinstance(horizontal, bool):
        raise ConfigError(
            f"{key_path}.horizontal: expected true or false (whether the sources' horizontal components "
            f"act on the sensors), got {_describe(horizontal)}"
        )
    return FieldModel(type="model", ellipsoid=ellipsoid, horizontal=horizontal, **parsed)
