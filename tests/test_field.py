"""Anomalous field models of the simulator (gravsurvey/simulate/field.py).

Checked against physics, not against our own output: Newton's law, the potential
(gradient by finite differences), Laplace/Poisson, an independent published prism
implementation (harmonica), Gauss-Legendre quadrature of the volume integral,
multipole limits, and the covariance function of the Gauss-Markov process.
"""

import math

import harmonica
import numpy as np
import pytest

from gravsurvey.errors import ConfigError, DataError
from gravsurvey.geodesy import WGS84, ecef_to_geodetic, geodetic_to_ecef, mat_en
from gravsurvey.simulate import field as fm
from gravsurvey.simulate.field import (
    G_NEWTON,
    Dipole,
    FieldModel,
    PointMass,
    Prism,
    along_track_disturbance,
    anomalous_gravitation_ecef,
    anomalous_potential,
    dipole_sources,
    field_model_from_dict,
    gravity_disturbance,
    markov_disturbance,
    point_mass_gravitation,
    point_mass_potential,
    prism_gravitation_local,
    prism_gravitation_local_numpy,
    prism_potential_local,
    prism_potential_local_numpy,
    seed_smooth_disturbance,
    seed_steps_disturbance,
)

MGAL = 1e-5
LAT0, LON0 = 45.0, 135.0


def _up(lat_deg, lon_deg):
    la, lo = math.radians(lat_deg), math.radians(lon_deg)
    return np.array([math.cos(la) * math.cos(lo), math.cos(la) * math.sin(lo), math.sin(la)])


def _mixed_model():
    """One source of every kind, a few km apart around (45 N, 135 E)."""
    return FieldModel(
        point_masses=(PointMass(45.02, 135.01, 2500.0, 4.0e11), PointMass(44.99, 134.98, 1800.0, -2.0e11)),
        dipoles=(Dipole(45.0, 135.03, 3000.0, 6.0e11, 4000.0, 60.0),),
        prisms=(
            Prism(45.01, 134.99, (-3000.0, 2000.0), (-1500.0, 2500.0), (200.0, 2500.0), -350.0),
            Prism(44.98, 135.02, (-1000.0, 1000.0), (-4000.0, 4000.0), (-300.0, 0.0), 400.0),
        ),
    )


# --------------------------------------------------------------------------
# Point masses and the dipole
# --------------------------------------------------------------------------


def test_g_newton_is_codata_2018():
    assert G_NEWTON == 6.67430e-11


def test_point_mass_directly_above_is_newton():
    # 1e12 kg at 2000 m depth, observer 1000 m above the ellipsoid on the same normal:
    # |g| = G M / (3000 m)^2 = 6.67430e-11 * 1e12 / 9e6 = 7.41589e-6 m/s^2 (0.74 mGal), down.
    # (ECEF differences of 3 km out of 6.4e6 m carry ~3e-13 relative rounding.)
    m = FieldModel(point_masses=(PointMass(LAT0, LON0, 2000.0, 1.0e12),))
    r = geodetic_to_ecef(math.radians(LAT0), math.radians(LON0), 1000.0)[None, :]
    g = anomalous_gravitation_ecef(m, r)[0]
    up = _up(LAT0, LON0)
    assert np.linalg.norm(g) == pytest.approx(7.415888888888889e-6, rel=1e-11)
    assert g @ up == pytest.approx(-np.linalg.norm(g), rel=1e-11)
    assert gravity_disturbance(m, r)[0] == pytest.approx(0.7415888888888889 * MGAL, rel=1e-11)
    v = anomalous_potential(m, r)[0]
    assert v == pytest.approx(6.67430e-11 * 1e12 / 3000.0, rel=1e-11)


def test_negative_mass_repels_and_sign_of_disturbance():
    r = geodetic_to_ecef(math.radians(LAT0), math.radians(LON0), 1000.0)[None, :]
    pos = FieldModel(point_masses=(PointMass(LAT0, LON0, 2000.0, 1.0e11),))
    neg = FieldModel(point_masses=(PointMass(LAT0, LON0, 2000.0, -1.0e11),))
    assert gravity_disturbance(pos, r)[0] > 0
    assert gravity_disturbance(neg, r)[0] == pytest.approx(-gravity_disturbance(pos, r)[0], rel=1e-15)


def test_point_mass_shapes_and_bad_input():
    src = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0]])
    g = point_mass_gravitation(np.array([5.0, 3.0, 4.0]), src, [1.0e9, 2.0e9])
    assert g.shape == (1, 3)
    with pytest.raises(DataError, match="mass"):
        point_mass_gravitation(np.zeros((2, 3)) + 100.0, src, [1.0])
    with pytest.raises(DataError, match="r_e"):
        point_mass_potential(np.zeros((2, 2)), src, [1.0, 1.0])


def test_dipole_geometry_net_mass_and_far_field():
    src, mass = dipole_sources(LAT0, LON0, 3000.0, 2.0e12, 6000.0, 90.0)
    assert mass.sum() == 0.0 and mass[0] == 2.0e12
    assert np.linalg.norm(src[0] - src[1]) == pytest.approx(6000.0, rel=1e-12)
    centre = geodetic_to_ecef(math.radians(LAT0), math.radians(LON0), -3000.0)
    assert np.allclose(0.5 * (src[0] + src[1]), centre, atol=1e-8, rtol=0)
    enu = mat_en(math.radians(LAT0), math.radians(LON0)).T @ (src[0] - centre)
    assert np.allclose(enu, [3000.0, 0.0, 0.0], atol=1e-8)  # azimuth 90: attracting mass east

    # along the axis the field of a dipole of moment p = M s falls as 2 G p / R^3
    m_enu = mat_en(math.radians(LAT0), math.radians(LON0))
    for dist in (1.0e5, 2.0e5, 4.0e5):
        r = (centre + m_enu @ np.array([dist, 0.0, 0.0]))[None, :]
        g = point_mass_gravitation(r, src, mass)[0]
        exact = G_NEWTON * 2.0e12 * (1.0 / (dist - 3000.0) ** 2 - 1.0 / (dist + 3000.0) ** 2)
        dipole = 2.0 * G_NEWTON * 2.0e12 * 6000.0 / dist**3
        assert np.linalg.norm(g) == pytest.approx(exact, rel=1e-9, abs=0.0)
        # dipole approximation error is O((s/2R)^2)
        assert abs(np.linalg.norm(g) / dipole - 1.0) < 3.0 * (3000.0 / dist) ** 2
    # disturbance sign: positive over the attracting (east) side, negative over the west
    m = FieldModel(dipoles=(Dipole(LAT0, LON0, 3000.0, 2.0e12, 6000.0, 90.0),))
    east = centre + m_enu @ np.array([3000.0, 0.0, 4000.0])
    west = centre + m_enu @ np.array([-3000.0, 0.0, 4000.0])
    d = gravity_disturbance(m, np.stack([east, west]))
    assert d[0] > 0 and d[1] == pytest.approx(-d[0], rel=1e-9)


# --------------------------------------------------------------------------
# Potential, gradient, Laplace/Poisson (whole model, ECEF)
# --------------------------------------------------------------------------


def _fd4_gradient(fun, r, h):
    """4th-order central differences of a scalar field, (n, 3)."""
    out = np.empty_like(r)
    for i in range(3):
        dv = np.zeros(3)
        dv[i] = h
        out[:, i] = (-fun(r + 2 * dv) + 8 * fun(r + dv) - 8 * fun(r - dv) + fun(r - 2 * dv)) / (12 * h)
    return out


def _flight_points(n=40, h=1000.0, seed=3):
    rng = np.random.default_rng(seed)
    lat = np.radians(LAT0 + rng.uniform(-0.05, 0.05, n))
    lon = np.radians(LON0 + rng.uniform(-0.05, 0.05, n))
    return geodetic_to_ecef(lat, lon, h + rng.uniform(0.0, 2000.0, n))


def test_gravitation_is_gradient_of_potential():
    model = _mixed_model()
    r = _flight_points()
    g = anomalous_gravitation_ecef(model, r)
    fd = _fd4_gradient(lambda x: anomalous_potential(model, x), r, 2.0)
    # truncation (h/d)^4 |g| < 1e-11 relative at d > 1 km; rounding eps |V| / h ~ 1e-14 m/s^2;
    # measured 5e-11 relative
    assert np.abs(fd - g).max() < 1e-9 * np.abs(g).max()
    assert np.abs(g).max() > 3 * MGAL  # the test is not vacuous (measured 6.6 mGal)


def test_laplace_outside_and_poisson_inside():
    model = _mixed_model()
    r = _flight_points(n=20)
    h = 5.0
    hess = np.empty((r.shape[0], 3, 3))
    for i in range(3):
        dv = np.zeros(3)
        dv[i] = h
        f = lambda x: anomalous_gravitation_ecef(model, x)  # noqa: E731
        hess[:, :, i] = (-f(r + 2 * dv) + 8 * f(r + dv) - 8 * f(r - dv) + f(r - 2 * dv)) / (12 * h)
    trace = np.trace(hess, axis1=1, axis2=2)
    scale = np.abs(hess).max(axis=(1, 2))
    assert scale.min() > 1e-9  # > 1 Eotvos: a real gradient is being tested
    assert np.all(np.abs(trace) < 1e-8 * scale)  # measured 2.7e-10
    # symmetric tensor (curl-free field)
    assert np.abs(hess - np.swapaxes(hess, 1, 2)).max() < 1e-8 * scale.max()

    # inside a prism: div g = -4 pi G rho (Poisson)
    rho = -350.0
    b = (-3000.0, 2000.0, -1500.0, 2500.0, -2500.0, -200.0)
    pts = np.array([[0.0, 0.0, -1000.0], [-2500.0, 2000.0, -2400.0], [1500.0, -1000.0, -300.0]])
    div = np.zeros(len(pts))
    for i in range(3):
        dv = np.zeros(3)
        dv[i] = h
        f = lambda p: prism_gravitation_local(p[:, 0], p[:, 1], p[:, 2], b, rho)[:, i]  # noqa: E731
        div += (-f(pts + 2 * dv) + 8 * f(pts + dv) - 8 * f(pts - dv) + f(pts - 2 * dv)) / (12 * h)
    assert np.allclose(div, -4 * math.pi * G_NEWTON * rho, rtol=1e-9, atol=0)  # measured 2e-11


# --------------------------------------------------------------------------
# Prism
# --------------------------------------------------------------------------

BOX = np.array([-5000.0, 5000.0, -2000.0, 2000.0, -3000.0, 0.0])


def _edge_points(b):
    """Points on faces, edges, corners, their planes, and a hair off them."""
    xs = [b[0], b[1], 0.0, b[0] - 1e-6, b[1] + 1e-3, b[0] + 1e-9]
    ys = [b[2], b[3], 0.0, b[3] + 1e-6, b[2] - 1.0]
    zs = [b[4], b[5], -1500.0, b[5] + 1e-6, b[5] + 1000.0, b[4] - 1e-3]
    return np.array([(x, y, z) for x in xs for y in ys for z in zs])


def _harmonica(p, b, rho):
    c = (p[:, 0], p[:, 1], p[:, 2])
    g = (
        np.stack([harmonica.prism_gravity(c, b, rho, field=f, parallel=False) for f in ("g_e", "g_n", "g_z")], axis=-1)
        * MGAL
    )
    g[:, 2] *= -1.0  # harmonica's g_z is the downward component; ours is along Up
    return g, harmonica.prism_gravity(c, b, rho, field="potential", parallel=False)


@pytest.mark.parametrize("rho", [-300.0, 2670.0])
def test_prism_matches_harmonica_including_edges(rho):
    rng = np.random.default_rng(11)
    rand = rng.uniform(-1, 1, (3000, 3)) * np.array([9000.0, 6000.0, 5000.0]) + np.array([0.0, 0.0, -1000.0])
    p = np.vstack([_edge_points(BOX), rand])
    g_ref, v_ref = _harmonica(p, BOX, rho)
    scale = G_NEWTON * abs(rho) * 1.0e4  # G rho L: the size of g near a 10 km body
    for fg, fv in (
        (prism_gravitation_local, prism_potential_local),
        (prism_gravitation_local_numpy, prism_potential_local_numpy),
    ):
        g = fg(p[:, 0], p[:, 1], p[:, 2], BOX, rho)
        v = fv(p[:, 0], p[:, 1], p[:, 2], BOX, rho)
        assert np.all(np.isfinite(g)) and np.all(np.isfinite(v))
        assert np.abs(g - g_ref).max() < 1e-12 * scale  # measured 4e-15
        assert np.abs(v - v_ref).max() < 1e-12 * scale * 1.0e4
    assert np.abs(g_ref).max() > 0.5 * scale


def test_prism_continuous_across_faces_edges_corners():
    b = BOX
    for base in ([b[1], 0.0, -1000.0], [b[1], b[3], -1000.0], [b[1], b[3], b[5]], [0.0, 0.0, b[5]]):
        base = np.array(base)
        offs = np.array(
            [[0, 0, 0], [1e-7, 0, 0], [-1e-7, 0, 0], [0, 1e-7, 0], [0, -1e-7, 0], [0, 0, 1e-7], [0, 0, -1e-7]]
        )
        p = base + offs
        g = prism_gravitation_local(p[:, 0], p[:, 1], p[:, 2], b, 1000.0)
        assert np.all(np.isfinite(g))
        # |g| ~ G rho L ~ 7e-4; a jump would be O(1e-4); measured spread 7e-13
        assert np.ptp(g, axis=0).max() < 1e-11


def _gauss_legendre(p, b, nq=16):
    """Reference: product Gauss-Legendre quadrature of G int (q - p)/|q - p|^3 dq (unit density)."""
    t, w = np.polynomial.legendre.leggauss(nq)
    b = np.asarray(b, dtype=float)
    c, h = 0.5 * (b[0::2] + b[1::2]), 0.5 * (b[1::2] - b[0::2])
    q = np.stack(np.meshgrid(*[c[i] + h[i] * t for i in range(3)], indexing="ij"), -1).reshape(-1, 3)
    wq = np.einsum("i,j,k->ijk", h[0] * w, h[1] * w, h[2] * w).ravel()
    d = q[None] - p[:, None]
    r = np.linalg.norm(d, axis=-1)
    return G_NEWTON * np.einsum("km,kmi->ki", wq / r**3, d), G_NEWTON * (wq / r).sum(axis=1)


@pytest.mark.parametrize(
    "b, tol",
    [
        ((-5000.0, 5000.0, -2000.0, 2000.0, -3000.0, 0.0), 5e-8),
        ((-50.0, 50.0, -50.0, 50.0, -100.0, 0.0), 5e-8),
        ((-500.0, 500.0, -100.0, 100.0, -3000.0, 0.0), 5e-8),
        ((-5000.0, 5000.0, -5000.0, 5000.0, -10.0, 0.0), 5e-7),  # 1000:1 slab
    ],
)
def test_prism_far_field_stable(b, tol):
    # Points from 3 to 1e4 prism diagonals away, including 100 km and 1000 km: the closed
    # form alone loses ~(R/L)^3 digits (measured 0.2 relative at 1e4 diagonals); with the
    # multipole switch the worst measured error is 2e-8 (1.1e-7 for the slab).
    bb = np.array(b)
    diag = np.linalg.norm(bb[1::2] - bb[0::2])
    c = 0.5 * (bb[0::2] + bb[1::2])
    rng = np.random.default_rng(5)
    dirs = rng.normal(size=(400, 3))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    dist = np.concatenate([np.geomspace(3 * diag, 1e4 * diag, 380), np.full(10, 1.0e5), np.full(10, 1.0e6)])
    p = c + dist[:, None] * dirs
    g_ref, v_ref = _gauss_legendre(p, bb)
    for fg, fv in (
        (prism_gravitation_local, prism_potential_local),
        (prism_gravitation_local_numpy, prism_potential_local_numpy),
    ):
        g = fg(p[:, 0], p[:, 1], p[:, 2], bb, 1.0)
        v = fv(p[:, 0], p[:, 1], p[:, 2], bb, 1.0)
        assert np.max(np.linalg.norm(g - g_ref, axis=1) / np.linalg.norm(g_ref, axis=1)) < tol
        assert np.max(np.abs(v - v_ref) / v_ref) < tol


def test_prism_far_field_tends_to_point_mass():
    rho = 2000.0
    vol = 10000.0 * 4000.0 * 3000.0
    c = 0.5 * (BOX[0::2] + BOX[1::2])
    diag = np.linalg.norm(BOX[1::2] - BOX[0::2])
    d = np.array([0.6, -0.48, 0.64])
    errs = []
    for ratio in (5.0, 20.0, 80.0):
        p = (c + ratio * diag * d)[None, :]
        g = prism_gravitation_local(p[:, 0], p[:, 1], p[:, 2], BOX, rho)
        g_pm = point_mass_gravitation(p, c[None, :], [rho * vol])
        errs.append(np.linalg.norm(g - g_pm) / np.linalg.norm(g_pm))
    # quadrupole: relative departure falls as (diag/R)^2 (factor 16 per 4x distance)
    assert errs[0] < 0.05
    assert 10.0 < errs[0] / errs[1] < 25.0 and 10.0 < errs[1] / errs[2] < 25.0


def test_prism_symmetry():
    b = np.array([-3000.0, 3000.0, -2000.0, 2000.0, -1500.0, 1500.0])  # centred on the origin
    rng = np.random.default_rng(7)
    p = rng.uniform(-8000, 8000, (200, 3))
    g = prism_gravitation_local(p[:, 0], p[:, 1], p[:, 2], b, 500.0)
    for axis in range(3):
        q = p.copy()
        q[:, axis] *= -1
        gq = prism_gravitation_local(q[:, 0], q[:, 1], q[:, 2], b, 500.0)
        flip = np.ones(3)
        flip[axis] = -1
        assert np.allclose(gq, g * flip, rtol=0, atol=1e-15)
    # a cube: permuting the coordinates permutes the components
    cube = np.array([-1000.0, 1000.0] * 3)
    gc = prism_gravitation_local(p[:, 0], p[:, 1], p[:, 2], cube, 500.0)
    gp = prism_gravitation_local(p[:, 1], p[:, 2], p[:, 0], cube, 500.0)
    assert np.allclose(gp, gc[:, [1, 2, 0]], rtol=0, atol=1e-15)
    # density is linear: a ridge is minus a basin
    assert np.array_equal(prism_gravitation_local(p[:, 0], p[:, 1], p[:, 2], b, -500.0), -g)


def test_prism_bad_bounds():
    with pytest.raises(DataError, match="west < east"):
        prism_gravitation_local(0.0, 0.0, 0.0, (1.0, -1.0, 0.0, 1.0, 0.0, 1.0), 1.0)
    with pytest.raises(DataError, match="6 finite"):
        prism_potential_local(0.0, 0.0, 0.0, (0.0, 1.0, 0.0, 1.0, 0.0), 1.0)


def test_prism_placement_in_ecef():
    # A 20 m cube 1000-1020 m below (45.01 N, 134.99 E): outside it equals a point mass at
    # its centre (cube: no quadrupole; hexadecapole (20/5000)^4 ~ 3e-10), placed through
    # geodesy's ellipsoid normal.
    lat, lon = 45.01, 134.99
    rho = 3000.0
    m = FieldModel(prisms=(Prism(lat, lon, (-10.0, 10.0), (-10.0, 10.0), (1000.0, 1020.0), rho),))
    centre = geodetic_to_ecef(math.radians(lat), math.radians(lon), -1010.0)
    r = _flight_points(n=30)
    g = anomalous_gravitation_ecef(m, r)
    g_pm = point_mass_gravitation(r, centre[None, :], [rho * 20.0**3])
    assert np.abs(g - g_pm).max() < 1e-9 * np.abs(g_pm).max()  # measured 4e-13


def test_numba_kernel_matches_numpy_reference():
    rng = np.random.default_rng(9)
    p = rng.uniform(-1, 1, (5000, 3)) * np.geomspace(10.0, 1.0e7, 5000)[:, None]
    for b in (BOX, np.array([-5000.0, 5000.0, -5000.0, 5000.0, -10.0, 0.0])):
        g = prism_gravitation_local(p[:, 0], p[:, 1], p[:, 2], b, 1.0)
        gr = prism_gravitation_local_numpy(p[:, 0], p[:, 1], p[:, 2], b, 1.0)
        v = prism_potential_local(p[:, 0], p[:, 1], p[:, 2], b, 1.0)
        vr = prism_potential_local_numpy(p[:, 0], p[:, 1], p[:, 2], b, 1.0)
        # both are within their measured rounding (<= 2e-7 relative) of the truth
        assert np.max(np.abs(g - gr) / np.linalg.norm(gr, axis=1)[:, None]) < 4e-7
        assert np.max(np.abs(v - vr) / np.abs(vr)) < 4e-7


def test_chunking_does_not_change_results(monkeypatch):
    model = _mixed_model()
    r = _flight_points(n=50)
    g_one = anomalous_gravitation_ecef(model, r)
    v_one = anomalous_potential(model, r)
    monkeypatch.setattr(fm, "CHUNK_POINTS", 7)
    # same numbers up to summation-order rounding
    assert np.abs(anomalous_gravitation_ecef(model, r) - g_one).max() < 1e-14 * np.abs(g_one).max()
    assert np.abs(anomalous_potential(model, r) - v_one).max() < 1e-14 * np.abs(v_one).max()


def test_superposition_of_sources():
    model = _mixed_model()
    r = _flight_points(n=25)
    total = anomalous_gravitation_ecef(model, r)
    parts = sum(
        anomalous_gravitation_ecef(FieldModel(**{k: (s,)}), r)
        for k in ("point_masses", "dipoles", "prisms")
        for s in getattr(model, k)
    )
    assert np.allclose(total, parts, rtol=0, atol=1e-18)
    assert model.n_sources == 2 + 2 + 2


def test_gravity_disturbance_is_minus_up_component():
    model = _mixed_model()
    r = _flight_points(n=25)
    lat, lon, _ = ecef_to_geodetic(r)
    g = anomalous_gravitation_ecef(model, r)
    up = np.stack([_up(math.degrees(a), math.degrees(o)) for a, o in zip(lat, lon)])
    assert np.allclose(gravity_disturbance(model, r), -(g * up).sum(axis=1), rtol=0, atol=1e-18)
    # basin (negative density) right under the observer: negative disturbance
    basin = FieldModel(prisms=(Prism(LAT0, LON0, (-5000.0, 5000.0), (-2000.0, 2000.0), (0.0, 3000.0), -300.0),))
    above = geodetic_to_ecef(math.radians(LAT0), math.radians(LON0), 1000.0)[None, :]
    d = gravity_disturbance(basin, above)[0]
    assert -30 * MGAL < d < -5 * MGAL  # infinite-slab bound 2 pi G rho t = -37.7 mGal


# --------------------------------------------------------------------------
# Seed along-track functions and the Gauss-Markov process
# --------------------------------------------------------------------------


def test_seed_smooth_values():
    t = np.array([0.0, 900.0, 3600.0])
    expect = (
        np.array(
            [
                20 * math.sin(1) + 10 * math.sin(2),
                30 * math.sin(math.pi / 2) + 20 * math.sin(2 * math.pi * 0.6 + 1) + 10 * math.sin(2 * math.pi + 2),
                20 * math.sin(2 * math.pi * 2.4 + 1) + 10 * math.sin(8 * math.pi + 2),
            ]
        )
        * MGAL
    )
    assert np.allclose(seed_smooth_disturbance(t), expect, rtol=1e-12, atol=1e-18)
    assert seed_smooth_disturbance(0.0) == pytest.approx(25.922394 * MGAL, rel=1e-6)  # 20 sin 1 + 10 sin 2


def test_seed_steps_values():
    t = np.array([0.0, 3599.9, 3600.0, 7199.0, 7200.0, 10800.0, 14400.0])
    assert np.allclose(seed_steps_disturbance(t), np.array([0, 0, 40, 40, -20, 10, 10]) * MGAL, rtol=0, atol=1e-18)


def test_markov_stationary_variance_and_correlation():
    # phi = exp(-lambda ds) = exp(-0.05); for the AR(1) sequence (Bartlett):
    #   sd(mean x^2)/sigma^2 = sqrt(2 (1+phi^2)/(1-phi^2) / n) = 0.0100,
    #   sd(rho_1) = sqrt((1-phi^2)/n) = 4.9e-4,
    #   sd(rho_10) = sqrt(((1+phi^2)(1-phi^20)/(1-phi^2) - 20 phi^20) / n) = 3.6e-3;
    # bounds are 4.5 sd.
    lam, sigma, ds, n = 1.0e-5, 1.0e-3, 5000.0, 400_000
    s = np.arange(n) * ds
    x = markov_disturbance(s, lam, sigma, np.random.default_rng(2024))
    phi = math.exp(-lam * ds)
    var = np.mean(x * x) / sigma**2
    rho1 = np.sum(x[1:] * x[:-1]) / np.sum(x * x)
    rho10 = np.sum(x[10:] * x[:-10]) / np.sum(x * x)
    sd_var = math.sqrt(2 * (1 + phi**2) / (1 - phi**2) / n)
    sd1 = math.sqrt((1 - phi**2) / n)
    sd10 = math.sqrt(((1 + phi**2) * (1 - phi**20) / (1 - phi**2) - 20 * phi**20) / n)
    assert abs(var - 1.0) < 4.5 * sd_var
    assert abs(rho1 - phi) < 4.5 * sd1
    assert abs(rho10 - phi**10) < 4.5 * sd10


def test_markov_uneven_steps_covariance_function():
    # Over N independent realisations on a fixed uneven grid, the sample covariance of
    # (x(s_0), x(s_k)) estimates sigma^2 exp(-lambda |s_k - s_0|) with
    # sd = sigma^2 sqrt((1 + rho^2)/N) <= 0.01 sigma^2 for N = 20000; bound 4.5 sd.
    lam, sigma = 2.0e-5, 2.0e-4
    rng = np.random.default_rng(77)
    s = np.concatenate([[0.0], np.cumsum(rng.uniform(0.0, 20000.0, 24))])
    s[5] = s[4]  # a zero step is allowed (repeated distance)
    n_real = 20000
    xs = np.stack([markov_disturbance(s, lam, sigma, rng) for _ in range(n_real)])
    cov = xs.T @ xs / n_real
    for k in (0, 1, 4, 5, 10, 24):
        rho = math.exp(-lam * (s[k] - s[0]))
        sd = sigma**2 * math.sqrt((1 + rho**2) / n_real)
        assert abs(cov[0, k] - sigma**2 * rho) < 4.5 * sd
    assert np.array_equal(xs[:, 4], xs[:, 5])
    # between two interior points too (stationarity, not only from the start)
    rho = math.exp(-lam * (s[20] - s[10]))
    assert abs(cov[10, 20] - sigma**2 * rho) < 4.5 * sigma**2 * math.sqrt((1 + rho**2) / n_real)


def test_markov_kernel_matches_reference_and_errors():
    rng = np.random.default_rng(1)
    s = np.cumsum(rng.uniform(0, 100, 500))
    w = rng.standard_normal(500)
    out = np.empty(500)
    fm._markov_kernel(s, 3e-4, 2e-3, w[0], w[1:], out)
    assert np.allclose(out, fm._markov_reference(s, 3e-4, 2e-3, w[0], w[1:]), rtol=0, atol=1e-14 * 2e-3)
    assert np.array_equal(markov_disturbance(s, 3e-4, 2e-3, 5), markov_disturbance(s, 3e-4, 2e-3, 5))
    with pytest.raises(DataError, match="non-decreasing"):
        markov_disturbance([0.0, 10.0, 5.0], 1e-5, 1e-3, 0)
    with pytest.raises(DataError, match="s_m"):
        markov_disturbance([0.0, np.nan], 1e-5, 1e-3, 0)
    with pytest.raises(ConfigError, match="lambda_s_per_m"):
        markov_disturbance([0.0, 1.0], 0.0, 1e-3, 0)
    with pytest.raises(ConfigError, match="sigma_s_mps2"):
        markov_disturbance([0.0, 1.0], 1e-5, -1.0, 0)


def test_along_track_dispatch():
    t = np.linspace(0, 14400, 50)
    assert np.array_equal(along_track_disturbance(FieldModel(type="seed_smooth"), t_s=t), seed_smooth_disturbance(t))
    assert np.array_equal(along_track_disturbance(FieldModel(type="seed_steps"), t_s=t), seed_steps_disturbance(t))
    mk = FieldModel(type="markov", lambda_s_per_m=1e-5, sigma_mps2=1e-3, seed=3)
    s = 50.0 * t
    assert np.array_equal(along_track_disturbance(mk, s_m=s), markov_disturbance(s, 1e-5, 1e-3, 3))
    with pytest.raises(ConfigError, match="s_m"):
        along_track_disturbance(mk, t_s=t)
    with pytest.raises(ConfigError, match="position"):
        along_track_disturbance(FieldModel(), t_s=t)
    with pytest.raises(ConfigError, match="field.type"):
        anomalous_gravitation_ecef(FieldModel(type="seed_smooth"), np.zeros((1, 3)) + 7e6)


# --------------------------------------------------------------------------
# Configuration
# --------------------------------------------------------------------------

GOOD = {
    "type": "model",
    "point_masses": [{"lat_deg": 45.1, "lon_deg": 135.2, "depth_m": 2000, "mass_kg": "5.0e11"}],
    "dipoles": [
        {"lat_deg": 45.0, "lon_deg": 135.5, "depth_m": 3000, "mass_kg": 1e12, "separation_m": 5000, "azimuth_deg": 30}
    ],
    "prisms": [
        {
            "lat_deg": 45.0,
            "lon_deg": 135.3,
            "east_m": [-5000, 5000],
            "north_m": [-2000, 2000],
            "depth_m": [0, 3000],
            "density_kgm3": -300,
        },
        {
            "lat_deg": 45.2,
            "lon_deg": 135.3,
            "east_m": [-1000, 1000],
            "north_m": [-1000, 1000],
            "depth_m": [-800, 0],
            "density_kgm3": 2670,
        },
    ],
}


def _with(path, value):
    import copy

    d = copy.deepcopy(GOOD)
    node = d
    for k in path[:-1]:
        node = node[k]
    if value is KeyError:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    return d


def test_config_good():
    m = field_model_from_dict(GOOD)
    assert m.point_masses == (PointMass(45.1, 135.2, 2000.0, 5.0e11),)  # YAML-1.1 "5.0e11" string accepted
    assert m.dipoles[0].separation_m == 5000.0
    assert m.prisms[1].bounds == (-1000.0, 1000.0, -1000.0, 1000.0, 0.0, 800.0)
    assert m.ellipsoid is WGS84
    assert field_model_from_dict({"type": "seed_steps"}).type == "seed_steps"
    mk = field_model_from_dict({"type": "markov", "lambda_s_per_m": 2e-5, "sigma_mps2": 5e-4, "seed": 4})
    assert (mk.lambda_s_per_m, mk.sigma_mps2, mk.seed) == (2e-5, 5e-4, 4)
    assert field_model_from_dict({"type": "model"}).n_sources == 0
    assert field_model_from_dict({"type": "model"}).horizontal
    assert not field_model_from_dict({"type": "model", "horizontal": False}).horizontal


@pytest.mark.parametrize(
    "path, value, message",
    [
        (("prisms", 1, "density_kgm3"), "x", r"field\.prisms\[1\]\.density_kgm3: expected a number .*got 'x'"),
        (("prisms", 0, "density_kgm3"), 0, r"field\.prisms\[0\]\.density_kgm3: expected a non-zero"),
        (("prisms", 0, "density_kgm3"), 1e6, r"field\.prisms\[0\]\.density_kgm3: expected <= 25000"),
        (("prisms", 0, "depth_m"), [3000, 0], r"field\.prisms\[0\]\.depth_m: expected \[low, high\]"),
        (("prisms", 0, "east_m"), 5000, r"field\.prisms\[0\]\.east_m: expected a list of two numbers"),
        (("prisms", 0, "north_m"), [0, True], r"field\.prisms\[0\]\.north_m\[1\]: expected a number"),
        (
            ("prisms", 0, "densty_kgm3"),
            1.0,
            r"field\.prisms\[0\]\.densty_kgm3: unknown key \(did you mean 'density_kgm3'\?\)",
        ),
        (("prisms", 0, "lat_deg"), KeyError, r"field\.prisms\[0\]\.lat_deg: missing required key"),
        (("point_masses", 0, "depth_m"), -5.0, r"field\.point_masses\[0\]\.depth_m: expected > 0"),
        (("point_masses", 0, "mass_kg"), float("nan"), r"field\.point_masses\[0\]\.mass_kg: expected a finite"),
        (("point_masses", 0, "lat_deg"), 91.0, r"field\.point_masses\[0\]\.lat_deg: expected <= 90"),
        (("point_masses", 0), "pm", r"field\.point_masses\[0\]: expected a mapping"),
        (("point_masses",), {"a": 1}, r"field\.point_masses: expected a list"),
        (("dipoles", 0, "separation_m"), 0, r"field\.dipoles\[0\]\.separation_m: expected > 0"),
        (("dipoles", 0, "mass_kg"), -1e12, r"field\.dipoles\[0\]\.mass_kg: expected > 0"),
        (("type",), "modle", r"field\.type: expected one of"),
        (("type",), KeyError, r"field\.type: missing required key"),
        (("prism",), [], r"field\.prism: unknown key \(did you mean 'prisms'\?\)"),
        (("seed",), 3, r"field\.seed: not allowed with field\.type 'model'"),
        (("horizontal",), "no", r"field\.horizontal: expected true or false .*got 'no'"),
        (("horizontal",), 0, r"field\.horizontal: expected true or false .*got int 0"),
    ],
)
def test_config_errors_name_the_key(path, value, message):
    with pytest.raises(ConfigError, match=message) as exc:
        field_model_from_dict(_with(path, value))
    assert "\n" not in str(exc.value)


def test_config_errors_other_paths():
    with pytest.raises(ConfigError, match=r"sim\.field: expected a mapping"):
        field_model_from_dict([1, 2], key_path="sim.field")
    with pytest.raises(ConfigError, match=r"sim\.field\.sigma_mps2: expected >= 0"):
        field_model_from_dict({"type": "markov", "sigma_mps2": -1}, key_path="sim.field")
    with pytest.raises(ConfigError, match=r"field\.seed: expected a non-negative integer"):
        field_model_from_dict({"type": "markov", "seed": 1.5})
    with pytest.raises(ConfigError, match=r"field\.prisms: not allowed with field\.type 'seed_smooth'"):
        field_model_from_dict({"type": "seed_smooth", "prisms": []})
