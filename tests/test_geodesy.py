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


def _flight_points(n, seed, h_lo=-500.0, h_hi=20000.0):
    rng = np.random.default_rng(seed)
    lat = np.concatenate([rng.uniform(-np.pi / 2, np.pi / 2, n), np.linspace(-np.pi / 2, np.pi / 2, 181)])
    lon = rng.uniform(-np.pi, np.pi, lat.size)
    h = rng.uniform(h_lo, h_hi, lat.size)
    return lat, lon, h, gd.geodetic_to_ecef(lat, lon, h)


def test_inertial_gravitation_equals_ecef_one_on_rotated_axes():
    """The one-atan form (what the ECEF function and the mechanization call) is the same field
    on any axes rotated about z (the field's own checks: boule, the potential's gradient and
    the surface normal, above)."""
    a, f, gm, om = gd.WGS84.params()
    q0 = gd.normal_gravitation_q0(a, f)
    _, _, _, r_e = _flight_points(3000, 0, -1e4, 1e6)
    g_e = gd.normal_gravitation_ecef(r_e)
    norm = np.linalg.norm(g_e, axis=1)
    ang = 0.7  # an Earth rotation angle: inertial = Rz(ang) ECEF
    m = gd.mat_ie(ang / om, om)
    r_i = r_e @ m.T
    g_i = np.array([gd.normal_gravitation_inertial_scalar(*p, a, f, gm, om, q0) for p in r_i])
    err = np.linalg.norm(g_i - g_e @ m.T, axis=1) / norm
    # the rotation rounds the coordinates, which q(u)'s cancellation (x5e5) makes 2e-13
    # relative (2e-7 mGal); the ECEF function at the rotated-back point differs as much
    back = gd.normal_gravitation_ecef(r_i @ m)
    assert (np.linalg.norm(back - g_e, axis=1) / norm).max() > 2e-14
    assert err.max() < 5e-13  # measured 1.9e-13


def test_geodetic_trig_matches_ecef_to_geodetic():
    a, f = gd.WGS84.a, gd.WGS84.f
    lat, _, h, r_e = _flight_points(5000, 1, -1e4, 1e6)
    la, _, hh = gd.ecef_to_geodetic(r_e)
    got = np.array([gd.geodetic_trig_scalar(*p, a, f) for p in r_e])
    assert np.abs(got[:, 0] - np.sin(la)).max() < 5e-16
    assert np.abs(got[:, 1] - np.cos(la)).max() < 5e-16
    assert np.abs(got[:, 2] - hh).max() < 1e-8
    assert np.abs(got[:, 2] - h).max() < 1e-8
    assert gd.geodetic_trig_scalar(0.0, 0.0, -7e6, a, f) == (-1.0, 0.0, 7e6 - gd.WGS84.b)


@pytest.mark.parametrize("h_lo,h_hi,bound", [(-1e4, 2e4, 1e-12), (1e5, 1e6, 1e-9)])
def test_geodetic_trig_bowring_alone(h_lo, h_hi, bound):
    """No iteration (the mechanization's use): sin, cos of the latitude within 4.1e-13 below
    20 km and 6.6e-10 up to 1000 km; the height as exact as with iterations."""
    a, f = gd.WGS84.a, gd.WGS84.f
    _, _, h, r_e = _flight_points(5000, 4, h_lo, h_hi)
    la, _, hh = gd.ecef_to_geodetic(r_e)
    got = np.array([gd.geodetic_trig_scalar(*p, a, f, 0) for p in r_e])
    assert np.abs(got[:, 0] - np.sin(la)).max() < bound
    assert np.abs(got[:, 1] - np.cos(la)).max() < bound
    assert np.abs(got[:, 2] - hh).max() < 1e-8


def test_zonal_coefficients_grs80_published():
    j2, j4 = gd.normal_gravitation_j2_j4(*gd.GRS80.params())
    # Moritz (2000), Geodetic Reference System 1980: J2 defining, J4 derived
    assert j2 == pytest.approx(0.00108263, abs=1e-13)
    assert j4 == pytest.approx(-0.00000237091222, abs=1e-14)


def test_zonal4_remainder_changes_slowly():
    """Normal gravitation less its degree-0/2/4 part changes by < 1e-12 m/s^2 per metre.

    The mechanization's error bound rests on it (gravsurvey.inm.mechanization docstring);
    the J2-only remainder changes 150x faster (1.1e-10), so J4 is needed.
    """
    a, f, gm, om = gd.WGS84.params()
    q0 = gd.normal_gravitation_q0(a, f)
    j2, j4 = gd.normal_gravitation_j2_j4(a, f, gm, om)
    rng = np.random.default_rng(2)
    _, _, _, r_e = _flight_points(1500, 2)

    def rest(p, jj):
        g = np.array(gd.normal_gravitation_inertial_scalar(*p, a, f, gm, om, q0))
        return g - np.array(gd.zonal4_gravitation_scalar(*p, a, gm, j2, jj))

    worst = {0.0: 0.0, j4: 0.0}
    for p in r_e:
        d = rng.normal(size=3)
        d *= 10.0 / np.linalg.norm(d)
        for jj in worst:
            worst[jj] = max(worst[jj], np.linalg.norm(rest(p + d, jj) - rest(p, jj)) / 10.0)
    assert worst[j4] < 1e-12  # measured 7.2e-13
    assert worst[0.0] > 5e-11


@pytest.mark.parametrize(
    "lat_deg, lon_deg, az_deg",
    [(45.0, 10.0, 30.0), (-62.0, 179.99, 95.0), (0.0, -179.995, 270.0), (84.0, 20.0, 200.0)],
)
def test_local_displacement_matches_geodesic(lat_deg, lon_deg, az_deg):
    """A 3-km step (across the antimeridian, at the equator, at 84 N) against pyproj's geodesic
    on the WGS84 ellipsoid: its length within 1 cm, its direction at the middle within 1e-6 rad; at 5 km of
    height the step scales by (R + h) / R with R the radius of curvature along it."""
    import pyproj

    geod = pyproj.Geod(ellps="WGS84")
    lon_b, lat_b, _ = geod.fwd(lon_deg, lat_deg, az_deg, 3000.0)
    east, north = gd.local_displacement(*np.radians([lat_deg, lon_deg, lat_b, lon_b]))
    assert abs(np.hypot(east, north) - 3000.0) < 0.01
    # the step's direction at its middle: the mean of its azimuths at both ends (meridians
    # converge by 1e-4 rad over 3 km at 45 deg)
    _, az_back, _ = geod.inv(lon_deg, lat_deg, lon_b, lat_b)
    mid_az = np.radians(az_deg) + 0.5 * gd.wrap_deg(az_back + 180.0 - az_deg) * np.pi / 180.0
    assert abs((np.arctan2(east, north) - mid_az + np.pi) % (2.0 * np.pi) - np.pi) < 1e-6
    # at height: each component scaled by its own radius (M + h) / M, (N + h) / N
    e_h, n_h = gd.local_displacement(*np.radians([lat_deg, lon_deg, lat_b, lon_b]), height=5000.0)
    m_rad, n_rad = gd.radii_of_curvature(np.radians(0.5 * (lat_deg + lat_b)))
    np.testing.assert_allclose([e_h, n_h], [east * (n_rad + 5000.0) / n_rad, north * (m_rad + 5000.0) / m_rad])
