"""Gravity-gradient tensors of the simulator's field (issue 16 item 2): analytic values,
symmetry, Laplace (zero trace away from masses), finite differences of the simulator's own
gravitation, and harmonica's independent prism implementation."""

import numpy as np
import pytest

from gravsurvey.geodesy import WGS84, geodetic_to_ecef, mat_en, normal_gravitation_ecef
from gravsurvey.simulate import field as F

E = F.EOTVOS
BOUNDS = (-1000.0, 2000.0, -500.0, 1500.0, -3000.0, -1000.0)
POINTS = np.array([[300.0, -800.0, 200.0], [5000.0, 4000.0, -500.0], [0.0, 0.0, 0.0], [-7000.0, 900.0, 4000.0]])


def _fd_jacobian(fun, pts, h):
    """Central-difference Jacobian d fun_i / d x_j of an (n, 3) -> (n, 3) function."""
    out = np.empty((pts.shape[0], 3, 3))
    for j in range(3):
        d = np.zeros(3)
        d[j] = h
        out[:, :, j] = (fun(pts + d) - fun(pts - d)) / (2.0 * h)
    return out


def test_point_mass_analytic_on_axis():
    # 1e12 kg at 2 km straight below: Gamma_uu = 2 G M / d^3, horizontal -G M / d^3, no cross terms.
    m, d = 1.0e12, 2000.0
    gam = F.point_mass_gradient([0.0, 0.0, 0.0], [[0.0, 0.0, -d]], [m])[0]
    k = F.G_NEWTON * m / d**3
    np.testing.assert_allclose(np.diag(gam), [-k, -k, 2.0 * k], rtol=1e-14)
    assert np.abs(gam - np.diag(np.diag(gam))).max() == 0.0


def test_point_mass_symmetric_tracefree_and_fd():
    rng = np.random.default_rng(1)
    src = rng.normal(0.0, 3000.0, (5, 3)) - [0.0, 0.0, 5000.0]
    mass = rng.normal(0.0, 1e12, 5)
    pts = rng.normal(0.0, 3000.0, (20, 3)) + [0.0, 0.0, 2000.0]
    gam = F.point_mass_gradient(pts, src, mass)
    scale = np.abs(gam).max()
    assert np.abs(gam - gam.transpose(0, 2, 1)).max() <= 1e-15 * scale
    assert np.abs(np.trace(gam, axis1=1, axis2=2)).max() <= 1e-12 * scale
    fd = _fd_jacobian(lambda p: F.point_mass_gravitation(p, src, mass), pts, 1.0)
    assert np.abs(gam - fd).max() <= 1e-5 * scale


def test_prism_matches_fd_of_gravitation_and_is_tracefree():
    rho = 2670.0
    gam = F.prism_gradient_local(POINTS[:, 0], POINTS[:, 1], POINTS[:, 2], BOUNDS, rho)
    assert gam.shape == (4, 3, 3)
    assert np.abs(gam).max() > 100 * E  # a real signal, not zeros
    fd = _fd_jacobian(lambda p: F.prism_gravitation_local_numpy(p[:, 0], p[:, 1], p[:, 2], BOUNDS, rho), POINTS, 1.0)
    assert np.abs(gam - fd).max() < 1e-3 * E
    assert np.abs(gam - gam.transpose(0, 2, 1)).max() == 0.0
    assert np.abs(np.trace(gam, axis1=1, axis2=2)).max() < 1e-9 * E


def test_prism_far_field_tends_to_point_mass():
    # 30 diagonals away the tensor equals the point mass's to O((D/R)^2) ~ 1e-3.
    w, e, s, n, b, t = BOUNDS
    vol = (e - w) * (n - s) * (t - b)
    c = np.array([(w + e) / 2, (s + n) / 2, (b + t) / 2])
    p = c + np.array([60000.0, 80000.0, 50000.0])
    gam = F.prism_gradient_local(p[0], p[1], p[2], BOUNDS, 2000.0)
    ref = F.point_mass_gradient(p, c, [2000.0 * vol])[0]
    np.testing.assert_allclose(gam, ref, atol=2e-3 * np.abs(ref).max())


def test_prism_matches_harmonica():
    hm = pytest.importorskip("harmonica")
    # harmonica's z axis points down for g_z: g_ez and g_nz change sign, g_zz does not.
    comps = {
        "g_ee": (0, 0, 1),
        "g_nn": (1, 1, 1),
        "g_zz": (2, 2, 1),
        "g_en": (0, 1, 1),
        "g_ez": (0, 2, -1),
        "g_nz": (1, 2, -1),
    }
    gam = F.prism_gradient_local(POINTS[:, 0], POINTS[:, 1], POINTS[:, 2], BOUNDS, 2670.0)
    coords = (POINTS[:, 0], POINTS[:, 1], POINTS[:, 2])
    for name, (i, j, sgn) in comps.items():
        ref = hm.prism_gravity(coords, np.array(BOUNDS), 2670.0, field=name)  # Eotvos
        np.testing.assert_allclose(sgn * gam[:, i, j] / E, ref, atol=1e-6, err_msg=name)


def test_normal_gradient_laplace_symmetry_and_spherical_values():
    lat = np.radians([0.0, 30.0, 55.0, 89.0])
    lon = np.radians([0.0, 40.0, -100.0, 10.0])
    h = np.array([0.0, 1000.0, 3000.0, 10000.0])
    r = geodetic_to_ecef(lat, lon, h, WGS84)
    r = np.stack(r, axis=-1) if isinstance(r, tuple) else r
    gam_n = F.total_gradient_n(None, r, lat, lon, WGS84)
    # Laplace outside the masses: tr = 0 (the centrifugal part is not in the gravitation)
    assert np.abs(np.trace(gam_n, axis1=1, axis2=2)).max() < 2e-5 * E
    # close to a sphere's: -GM/r^3 horizontal, +2GM/r^3 vertical (the J2 terms: 0.65% measured); east-north ~ 0
    k = WGS84.gm / np.linalg.norm(r, axis=1) ** 3
    np.testing.assert_allclose(gam_n[:, 2, 2], 2.0 * k, rtol=1e-2)
    np.testing.assert_allclose(gam_n[:, 0, 0], -k, rtol=1e-2)
    assert np.abs(gam_n[:, 0, 1]).max() < 1e-3 * k.max()
    assert 3000 * E < gam_n[0, 2, 2] < 3100 * E  # the seed's |lambda| ~ 3080 E
    # the symmetrised central difference agrees with a 10x coarser one to ~1e-4 E (step error)
    coarse = _fd_jacobian(lambda p: normal_gravitation_ecef(p, WGS84), r, 1000.0)
    m = mat_en(lat, lon)
    coarse_n = np.einsum("kji,kjl,klm->kim", m, coarse, m)
    assert np.abs(gam_n - coarse_n).max() < 1e-3 * E


def test_model_gradient_matches_fd_of_model_gravitation():
    model = F.field_model_from_dict(
        {
            "type": "model",
            "point_masses": [{"lat_deg": 45.01, "lon_deg": 10.0, "depth_m": 3000.0, "mass_kg": 5e12}],
            "dipoles": [
                {
                    "lat_deg": 45.0,
                    "lon_deg": 10.03,
                    "depth_m": 2000.0,
                    "mass_kg": 2e12,
                    "separation_m": 3000.0,
                    "azimuth_deg": 30.0,
                }
            ],
            "prisms": [
                {
                    "lat_deg": 45.0,
                    "lon_deg": 9.98,
                    "east_m": [-2000.0, 2000.0],
                    "north_m": [-1000.0, 3000.0],
                    "depth_m": [500.0, 2500.0],
                    "density_kgm3": -400.0,
                }
            ],
        }
    )
    lat = np.radians([45.0, 45.005, 45.02])
    lon = np.radians([10.0, 9.99, 10.03])
    r = geodetic_to_ecef(lat, lon, np.full(3, 1500.0), WGS84)
    r = np.stack(r, axis=-1) if isinstance(r, tuple) else r
    gam = F.anomalous_gradient_ecef(model, r)
    assert np.abs(gam).max() > 10 * E
    fd = _fd_jacobian(lambda p: F.anomalous_gravitation_ecef(model, p), r, 1.0)
    assert np.abs(gam - fd).max() < 2e-3 * E
    assert np.abs(np.trace(gam, axis1=1, axis2=2)).max() < 1e-8 * E
    # total on ENU = normal + anomalous, rotated
    tot = F.total_gradient_n(model, r, lat, lon, WGS84)
    norm = F.total_gradient_n(None, r, lat, lon, WGS84)
    m = mat_en(lat, lon)
    np.testing.assert_allclose(tot - norm, np.einsum("kji,kjl,klm->kim", m, gam, m), atol=1e-9 * E)
