"""Seed 000 (gradiometer-aided navigation) claims as tests, against the simulator's truth
field (gravsurvey.simulate.field) and against closed-form linear-system facts."""

import math

import numpy as np

from gravsurvey import gradiometer as G
from gravsurvey.geodesy import WGS84, geodetic_to_ecef, mat_en, normal_gravitation_ecef
from gravsurvey.simulate import field as F

E = G.EOTVOS
W0 = math.sqrt(9.81 / 6.371e6)  # Schuler frequency, rad/s


def _model():
    return F.field_model_from_dict(
        {
            "type": "model",
            "point_masses": [{"lat_deg": 45.01, "lon_deg": 10.0, "depth_m": 2000.0, "mass_kg": 2e13}],
            "prisms": [
                {
                    "lat_deg": 45.0,
                    "lon_deg": 9.98,
                    "east_m": [-2000.0, 2000.0],
                    "north_m": [-1000.0, 3000.0],
                    "depth_m": [300.0, 2500.0],
                    "density_kgm3": -400.0,
                }
            ],
        }
    )


def _track(n=7):
    lat = np.radians(np.linspace(44.98, 45.03, n))
    lon = np.radians(np.linspace(9.96, 10.04, n))
    h = np.full(n, 1200.0)
    return lat, lon, h, geodetic_to_ecef(lat, lon, h, WGS84)


def test_characteristic_equation_on_simulated_tensors():
    lat, lon, _, r = _track()
    gam = F.total_gradient_n(_model(), r, lat, lon, WGS84)
    p, q = G.characteristic_coefficients(gam)
    roots = G.characteristic_roots(gam)
    # the roots solve lambda^3 + p lambda + q = 0 (relative to the lambda^3 scale; the
    # simulated tensor's trace is ~1e-5 E, not exactly 0, hence 1e-8) ...
    resid = roots**3 + p[:, None] * roots + q[:, None]
    assert np.abs(resid).max() < 1e-8 * np.abs(roots).max() ** 3
    # ... and are the tensor's eigenvalues (independent LAPACK solution)
    np.testing.assert_allclose(roots, np.linalg.eigvalsh(gam), atol=1e-6 * E)
    # p, q are det(lambda I - T)'s coefficients because tr T = 0 (Laplace)
    for k in range(gam.shape[0]):
        c = np.poly(gam[k])
        np.testing.assert_allclose([c[2], c[3]], [p[k], q[k]], rtol=1e-8)
    # the vertical root is ~ 2 w0^2 ~ 3080 E; the anomaly moves it by tens of E
    lam, _ = G.vertical_eigen(gam)
    assert np.all((lam > 3000 * E) & (lam < 3200 * E))
    assert np.ptp(lam) > 5 * E


def test_eigen_vertical_exact_for_a_point_mass_earth():
    # spherical Earth = point mass: the eigenvector is exactly along the gravitation and
    # |lambda| = |grad |g|| = 2 GM / r^3 (seed section 2)
    gm = WGS84.gm
    m = gm / F.G_NEWTON
    rng = np.random.default_rng(3)
    pts = rng.normal(0.0, 1.0, (10, 3))
    pts *= (6.4e6 + rng.uniform(0.0, 1e4, 10) / 1.0)[:, None] / np.linalg.norm(pts, axis=1)[:, None]
    gam = F.point_mass_gradient(pts, [[0.0, 0.0, 0.0]], [m])
    g = F.point_mass_gravitation(pts, [[0.0, 0.0, 0.0]], [m])
    lam, g0 = G.vertical_eigen(gam, down_hint=g)
    gd = g / np.linalg.norm(g, axis=1)[:, None]
    assert np.abs(g0 - gd).max() < 1e-9
    np.testing.assert_allclose(lam, 2.0 * gm / np.linalg.norm(pts, axis=1) ** 3, rtol=1e-9)


def test_eigen_vertical_against_the_ellipsoid_truth():
    # On the level ellipsoid the seed's "dumbbell" vertical is NOT the gravitation direction:
    # measured 0" at the equator, 112" at 45 deg, 4" at 89 deg (the normal gravitation leans
    # 357" north of the ellipsoid normal at 45 deg, the eigenvector 245").
    lat = np.radians([0.0, 45.0, 89.0])
    lon = np.radians([0.0, 20.0, 40.0])
    r = geodetic_to_ecef(lat, lon, np.full(3, 2000.0), WGS84)
    gam = F.total_gradient_n(None, r, lat, lon, WGS84)
    g_n = np.einsum("kji,kj->ki", mat_en(lat, lon), normal_gravitation_ecef(r, WGS84))
    _, g0 = G.vertical_eigen(gam)
    ang = (
        np.degrees(np.arccos(np.clip(np.einsum("ki,ki->k", g0, g_n / np.linalg.norm(g_n, axis=1)[:, None]), -1, 1)))
        * 3600
    )
    assert ang[0] < 0.5 and 100.0 < ang[1] < 125.0 and ang[2] < 10.0


def test_vertical_eigen_rotates_with_the_triad():
    lat, lon, _, r = _track(3)
    gam_n = F.total_gradient_n(_model(), r, lat, lon, WGS84)
    rng = np.random.default_rng(0)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    mat_nt = q * np.sign(np.linalg.det(q))  # triad -> ENU, a proper rotation
    gam_t = np.einsum("ji,kjl,lm->kim", mat_nt, gam_n, mat_nt)
    lam_n, g0_n = G.vertical_eigen(gam_n)
    lam_t, g0_t = G.vertical_eigen(gam_t, down_hint=mat_nt.T @ [0.0, 0.0, -1.0])
    np.testing.assert_allclose(lam_t, lam_n, rtol=1e-9)
    np.testing.assert_allclose(g0_t @ mat_nt.T, g0_n, atol=1e-9)


def test_gravitation_propagated_by_t_v_closes_on_truth():
    # 20 min at 120 m/s across the anomaly at 1 Hz: dg/dt = T V reproduces the
    # simulator's gravitation to the trapezoid's O(dt^2) error.
    model = _model()
    t = np.arange(0.0, 1201.0, 1.0)
    lat = np.radians(45.0 - 0.02 + 0.04 * t / t[-1])
    lon = np.radians(9.95 + 0.1 * t / t[-1])
    h = 1500.0 + 50.0 * np.sin(t / 200.0)
    r = geodetic_to_ecef(lat, lon, h, WGS84)
    v = np.gradient(r, t, axis=0, edge_order=2)
    # exact velocity from a fine difference of the analytic track
    dt = 1e-3
    v = (
        geodetic_to_ecef(
            np.radians(45.0 - 0.02 + 0.04 * (t + dt) / t[-1]),
            np.radians(9.95 + 0.1 * (t + dt) / t[-1]),
            1500.0 + 50.0 * np.sin((t + dt) / 200.0),
            WGS84,
        )
        - geodetic_to_ecef(
            np.radians(45.0 - 0.02 + 0.04 * (t - dt) / t[-1]),
            np.radians(9.95 + 0.1 * (t - dt) / t[-1]),
            1500.0 + 50.0 * np.sin((t - dt) / 200.0),
            WGS84,
        )
    ) / (2 * dt)
    g_true = normal_gravitation_ecef(r, WGS84) + F.anomalous_gravitation_ecef(model, r)
    gam = F.normal_gradient_ecef(r, WGS84) + F.anomalous_gradient_ecef(model, r)
    g_prop = G.propagate_gravitation_e(t, g_true[0], gam, v)
    change = np.abs(g_true - g_true[0]).max()
    assert change > 1e-3  # the gravitation really changed (>100 mGal, mostly by the height)
    assert np.abs(g_prop - g_true).max() < 0.01e-5  # < 0.01 mGal after 144 km


def test_asymptotic_gains_put_all_poles_at_minus_l0():
    for l0, mu in ((3.0, 0.1), (1.0, 0.05), (0.5, 0.3)):
        a, h = G.position_channel_matrix(mu)
        f = G.closed_loop_matrix(a, h, G.asymptotic_gains_position(l0, mu))
        np.testing.assert_allclose(np.poly(f), np.poly([-l0, -l0, -l0]), rtol=1e-12)
        # one Jordan block (elementary divisor (lambda + l0)^3): rank(F + l0 I) = 2
        assert np.linalg.matrix_rank(f + l0 * np.eye(3)) == 2
        assert np.allclose(np.linalg.eigvals(f).real, -l0, rtol=1e-4)
        a, h = G.velocity_channel_matrix()
        f = G.closed_loop_matrix(a, h, G.asymptotic_gains_velocity(l0))
        np.testing.assert_allclose(np.poly(f), np.poly([-l0, -l0]), rtol=1e-12)


def test_seed_steady_state_noise_variances():
    # seed eq. 4.6 and section 5: white measurement noise only, Lyapunov equation
    l0, mu, rho2 = 1.7, 0.3, 0.8
    a, h = G.position_channel_matrix(mu)
    k = G.asymptotic_gains_position(l0, mu)
    p = G.steady_state_error_covariance(a, h, k, np.zeros((3, 3)), mu**2 * rho2)
    np.testing.assert_allclose(np.diag(p), G.seed_noise_variances_position(l0, mu, rho2), rtol=1e-9)
    a, h = G.velocity_channel_matrix()
    k = G.asymptotic_gains_velocity(l0)
    p = G.steady_state_error_covariance(a, h, k, np.zeros((2, 2)), rho2)
    np.testing.assert_allclose(np.diag(p), G.seed_noise_variances_velocity(l0, rho2), rtol=1e-9)


def test_vertical_channel_unstable_free_and_stable_with_height_aiding():
    lam = 2.0 * W0**2
    free = G.vertical_channel_matrix(lam)
    ev = np.linalg.eigvals(free)
    assert abs(ev.real.max() - math.sqrt(lam)) < 1e-12
    # 0.1 m/s initial vertical-velocity error, one hour
    x = G.propagate_linear(free, np.array([0.0, 0.1, 0.0]), 10.0, 361)
    assert abs(x[-1, G.DH]) > 1e4  # exponential divergence (e-folding 9.5 min)
    l0 = 1.0 / 60.0
    aided = G.vertical_channel_matrix(lam, G.height_aiding_gains(l0, lam))
    np.testing.assert_allclose(np.poly(aided), np.poly([-l0] * 3), rtol=1e-9)
    x = G.propagate_linear(aided, np.array([0.0, 0.1, 0.0]), 10.0, 361)
    assert np.abs(x[-60:]).max() < 1e-6


def test_schuler_oscillation_without_and_none_with_the_gradiometer():
    b = 1e-4  # 10 mGal acceleration error
    dt, n = 10.0, 4 * 360 + 1  # four hours
    t = np.arange(n) * dt
    x0 = np.array([0.0, 0.0, b])
    conv = G.propagate_linear(G.horizontal_channel_matrix(W0, gradiometer=False), x0, dt, n)
    grad = G.propagate_linear(G.horizontal_channel_matrix(W0, gradiometer=True), x0, dt, n)
    period = G.oscillation_period(t, conv[:, G.POS])
    assert abs(period - 2 * math.pi / W0) < 0.01 * 2 * math.pi / W0  # 84.4 min
    assert abs(conv[:, G.POS].max() - 2 * b / W0**2) < 0.01 * 2 * b / W0**2  # bounded: 1.3 km
    assert G.oscillation_period(t, grad[:, G.POS]) == math.inf  # no oscillation ...
    assert np.all(np.diff(grad[:, G.POS]) > 0)  # ... monotonic growth b t^2 / 2
    np.testing.assert_allclose(grad[:, G.POS], 0.5 * b * t**2, rtol=1e-9, atol=1e-9)


def test_eigen_vertical_error_is_r_over_3_per_eotvos():
    # seed eq. 3.6: an error dT_13 tilts the eigenvector by dT / (lambda_v - lambda_h)
    lat, lon, _, r = _track(1)
    gam = F.total_gradient_n(None, r, lat, lon, WGS84)[0]
    lam, g0 = G.vertical_eigen(gam)
    d = np.zeros((3, 3))
    d[0, 2] = d[2, 0] = 1.0 * E
    _, g1 = G.vertical_eigen(gam + d)
    ev = np.linalg.eigvalsh(gam)
    pred = G.eigen_vertical_acceleration_error(1.0 * E, lam[0], ev[0:2].mean(), 1.0)
    np.testing.assert_allclose(abs(g1[0, 0] - g0[0, 0]), pred, rtol=2e-3)
    assert 2.0e-3 < 9.8 * pred < 2.2e-3  # ~ r/3 * 1 E in m/s^2


def test_kalman_versus_asymptotic_filter():
    # steady state: same channel, random-walk gradiometer error (q) and white position noise (r)
    mu, q3, r = 0.1, 1e-2, 1e-4
    a, h = G.position_channel_matrix(mu)
    qm = np.diag([0.0, 0.0, q3])
    k_kf, p_kf = G.steady_state_kalman_gain(a, h, qm, r)
    wc = (mu**2 * q3 / r) ** (1.0 / 6.0)  # the Kalman poles are a 3rd-order Butterworth of this radius
    np.testing.assert_allclose(np.abs(np.linalg.eigvals(G.closed_loop_matrix(a, h, k_kf))), wc, rtol=1e-6)
    # Butterworth s^3 + 2 wc s^2 + 2 wc^2 s + wc^3: Kalman gains (2 wc, 2 wc^2/mu, wc^3/mu) against
    # the seed's (3 wc, 3 wc^2/mu, wc^3/mu) -- the same K3, two thirds of K1 and K2
    np.testing.assert_allclose(k_kf, [2 * wc, 2 * wc**2 / mu, wc**3 / mu], rtol=1e-6)
    k_as = G.asymptotic_gains_position(wc, mu)
    p_as = G.steady_state_error_covariance(a, h, k_as, qm, r)
    assert np.all(np.diag(p_kf) <= np.diag(p_as) * (1 + 1e-9))  # the Kalman filter is optimal ...
    assert np.diag(p_as)[2] < 3.0 * np.diag(p_kf)[2]  # ... the asymptotic one within a small factor

    # discrete run on a simulated channel: 1 Hz position differences, sigma 3 m,
    # acceleration error a random walk (eigen-vertical error of a drifting gradiometer)
    rng = np.random.default_rng(7)
    dt, n = 1.0, 7200
    t = np.arange(n) * dt
    q_acc = (2e-6) ** 2  # (m/s^2)^2/s
    b = np.cumsum(rng.normal(0.0, math.sqrt(q_acc * dt), n)) + 1e-4
    v = np.concatenate([[0.0], np.cumsum(0.5 * (b[1:] + b[:-1]) * dt)])
    x = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * dt)])
    z = x + rng.normal(0.0, 3.0, n)
    wcd = (q_acc / 9.0) ** (1.0 / 6.0)
    x_as, x_kf, k_last = G.run_channel_filters(t, z, 9.0, q_acc, wcd, (3.0, 1.0, 1e-3))
    tail = slice(1800, None)

    def rms(e):
        return float(np.sqrt(np.mean(e[tail] ** 2)))

    raw = rms(z - x)
    assert rms(x_kf[:, G.POS] - x) < 0.6 * raw and rms(x_as[:, G.POS] - x) < 0.6 * raw
    assert rms(x_kf[:, G.ACC] - b) <= 1.2 * rms(x_as[:, G.ACC] - b)
    k_c, p_c = G.steady_state_kalman_gain(
        G.horizontal_channel_matrix(0.0, True), np.array([[1.0, 0, 0]]), np.diag([0, 0, q_acc]), 9.0 * dt
    )
    # measured: position 0.40 m, acceleration 2.8e-5 m/s^2 against the Riccati sigmas 0.40 m, 3.0e-5
    sig = np.sqrt(np.diag(p_c))
    for i, truth in ((G.POS, x), (G.ACC, b)):
        assert 0.7 * sig[i] < rms(x_kf[:, i] - truth) < 1.3 * sig[i]
    np.testing.assert_allclose(k_last, k_c, rtol=0.03)  # the discrete gain -> the continuous one
