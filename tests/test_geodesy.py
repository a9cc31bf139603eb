"""Geodesy is shared by simulator and estimator, so it is checked against boule and published values."""

import boule
import numpy as np
import pytest

from gravsurvey import geodesy as gd


@pytest.mark.parametrize("ell,ref", [(gd.WGS84, boule.WGS84), (gd.GRS80, boule.GRS80)])
def test_normal_gravity_matches_boule(ell, ref):
    lat = np.radians(np.linspace(-89.5, 89.5, 73))
    h = np.linspace(0.0, 12000.0, 73)
    ours = gd.normal_gravity(lat, h, ell)
    theirs = ref.normal_gravity((0.0, np.degrees(lat), h), si_units=True)
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-9)


def test_published_values_grs80():
    # Moritz (1980) Geodetic Reference System 1980: gamma_e, gamma_p
    assert gd.normal_gravity(0.0, 0.0, gd.GRS80) == pytest.approx(9.7803267715, abs=1e-9)
    assert gd.normal_gravity(np.pi / 2, 0.0, gd.GRS80) == pytest.approx(9.8321863685, abs=1e-9)


def test_gravitation_is_gradient_of_potential():
    rng = np.random.default_rng(1)
    for _ in range(5):
        lat, lon = rng.uniform(-1.5, 1.5), rng.uniform(-3, 3)
        p = gd.geodetic_to_ecef(lat, lon, rng.uniform(0, 1e4))
        g = gd.normal_gravitation_ecef(p)
        d = 100.0
        fd = []
        for e in np.eye(3):
            v = [gd.normal_gravitational_potential(p + k * d * e) for k in (-2, -1, 1, 2)]
            fd.append((v[0] - 8 * v[1] + 8 * v[2] - v[3]) / (12 * d))
        np.testing.assert_allclose(fd, g, atol=2e-8)


def test_gravity_direction_is_ellipsoid_normal_on_surface():
    # On the level ellipsoid the gravity vector is along the geodetic normal (-Up).
    lat = np.radians([-60.0, -10.0, 30.0, 45.0, 80.0])
    lon = np.radians([10.0, 100.0, -120.0, 135.0, 0.0])
    r = gd.geodetic_to_ecef(lat, lon, 0.0)
    g = gd.normal_gravity_ecef(r)
    up = gd.mat_en(lat, lon)[..., :, 2]
    # sine of the angle between -g and Up (arccos is ill-conditioned near 0)
    sinang = np.linalg.norm(np.cross(-g, up), axis=1) / np.linalg.norm(g, axis=1)
    assert np.all(sinang < 1e-12)
    assert np.all(np.einsum("ij,ij->i", g, up) < 0)


def test_geodetic_ecef_round_trip():
    rng = np.random.default_rng(2)
    lat = rng.uniform(-np.pi / 2, np.pi / 2, 1000)
    lon = rng.uniform(-np.pi, np.pi, 1000)
    h = rng.uniform(-500, 20000, 1000)
    la, lo, hh = gd.ecef_to_geodetic(gd.geodetic_to_ecef(lat, lon, h))
    np.testing.assert_allclose(la, lat, atol=1e-12)
    np.testing.assert_allclose(np.angle(np.exp(1j * (lo - lon))), 0, atol=1e-12)
    np.testing.assert_allclose(hh, h, atol=1e-6)


def test_mat_en_orthonormal_and_up():
    m = gd.mat_en(0.7, -1.2)
    np.testing.assert_allclose(m @ m.T, np.eye(3), atol=1e-15)
    r = gd.geodetic_to_ecef(0.7, -1.2, 0.0)
    # Up of a sphere-like point has positive projection on r
    assert m[:, 2] @ r > 0
    np.testing.assert_allclose(np.linalg.det(m), 1.0)


def test_free_air_gradient():
    g0 = gd.normal_gravity(np.radians(45), 0.0)
    g1 = gd.normal_gravity(np.radians(45), 1.0)
    assert (g0 - g1) / 1e-5 == pytest.approx(0.3086, abs=0.001)
