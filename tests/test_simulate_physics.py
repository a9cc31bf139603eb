"""Simulator physics against closed formulas and independent numerical checks.

Truth sources: boule (normal gravity), textbook Eotvos/transport-rate formulas
derived in docs/simulate.md, numerical integration of the simulated velocity,
acceleration and IMU outputs (an independent strapdown navigator below).
"""

import math

import boule
import numpy as np
import pytest

from gravsurvey import geodesy as gd
from gravsurvey.errors import ConfigError
from gravsurvey.simulate import trajectory as tj
from gravsurvey.simulate.run import quick_sim, simulate_flight

W = gd.OMEGA_E


def boule_gamma(lat_rad, h):
    return boule.WGS84.normal_gravity((0.0, np.degrees(lat_rad), h), si_units=True)


def rest_sim(lat_deg, h, triad="platform"):
    sim = quick_sim(lat_deg=lat_deg, altitude_m=h, duration_s=10.0, static_start_s=60.0, triad=triad)
    out = simulate_flight(sim)
    m = out.truth["line"] == "static"
    assert m.sum() >= 500
    return out, m


@pytest.mark.parametrize("lat_deg", [45.0, -30.0, 70.0, 0.0])
def test_rest_on_surface_reads_normal_gravity_and_earth_rate(lat_deg):
    out, m = rest_sim(lat_deg, 0.0)
    f = out.specific_force_t[m]
    lat = math.radians(lat_deg)
    # on the ellipsoid (a level surface of the normal field) gravity is along the normal
    assert np.abs(f[:, 0]).max() < 1e-12
    assert np.abs(f[:, 1]).max() < 1e-9
    assert np.abs(f[:, 2] - boule_gamma(lat, 0.0)).max() < 1e-9
    w = out.angular_rate_t[m]
    np.testing.assert_allclose(
        w, np.tile([0.0, W * math.cos(lat), W * math.sin(lat)], (w.shape[0], 1)), rtol=0, atol=1e-18
    )
    # at rest nothing moves
    assert np.abs(out.truth["vel_n"][m]).max() == 0.0


@pytest.mark.parametrize("lat_deg", [45.0, -60.0])
def test_rest_at_height_north_component_is_plumb_line_curvature(lat_deg):
    """Above the ellipsoid the normal gravity vector tilts north of the normal.

    U(lat, h) = U0 - int_0^h gamma(lat, h') dh' (U0 constant on the ellipsoid), so
    g_N = (1/(M+h)) dU/dlat = -(1/(M+h)) int_0^h dgamma/dlat dh' and the triad reads
    F_N = -g_N.  Evaluated with boule's gamma by quadrature and finite differences;
    ~ +8.1e-6 m/s^2 at 1 km, 45 N (the textbook 0.17" h[km] sin 2 lat).
    """
    h = 1000.0
    out, m = rest_sim(lat_deg, h)
    lat = math.radians(lat_deg)
    hh, wq = np.polynomial.legendre.leggauss(8)
    hh = 0.5 * h * (hh + 1.0)
    d = 1e-5
    dg = (boule_gamma(lat + d, hh) - boule_gamma(lat - d, hh)) / (2 * d)
    mm, _ = gd.radii_of_curvature(lat)
    f_n_expected = 0.5 * h * np.sum(wq * dg) / (mm + h)
    f = out.specific_force_t[m]
    assert abs(f_n_expected) > 5e-6
    assert np.abs(f[:, 1] - f_n_expected).max() < 1e-9
    assert np.abs(np.linalg.norm(f, axis=1) - boule_gamma(lat, h)).max() < 1e-9


@pytest.mark.parametrize(
    "lat_deg,v,h", [(45.0, 50.0, 1000.0), (-60.0, 100.0, 300.0), (10.0, 80.0, 3000.0), (-87.0, 80.0, 2000.0)]
)
def test_level_flight_due_east_eotvos(lat_deg, v, h):
    out = simulate_flight(quick_sim(lat_deg=lat_deg, speed_mps=v, altitude_m=h, duration_s=1800.0))
    lat = math.radians(lat_deg)
    _, nn = gd.radii_of_curvature(lat)
    expected = boule_gamma(lat, h) - 2 * W * v * math.cos(lat) - v**2 / (nn + h)
    err = out.specific_force_t[:, 2] - expected
    assert np.abs(err).max() < 1e-3 * 1e-5  # 0.001 mGal (requirement: 0.01 mGal)
    # a parallel: latitude and height do not change
    assert np.ptp(out.truth["lat"]) == 0.0 and np.ptp(out.truth["height"]) == 0.0


@pytest.mark.parametrize("heading_deg", [30.0, 135.0, 0.0, 250.0])
def test_level_straight_flight_any_heading(heading_deg):
    """A line of constant map heading has lat, lon linear in time (docs/simulate.md), so
    lat'' = lon'' = 0 and F_U = gamma - 2 W cos(lat) v_E - v_E^2/(N+h) - v_N^2/(M+h)
    with v_E = (N+h) cos(lat) lon', v_N = (M+h) lat' computed here from the plan alone."""
    v, h, lat0 = 70.0, 800.0, math.radians(50.0)
    out = simulate_flight(quick_sim(lat_deg=50.0, speed_mps=v, altitude_m=h, heading_deg=heading_deg, duration_s=900.0))
    t = out.imu_time
    psi = math.radians(heading_deg)
    rm, rp = tj.map_scales(lat0, h)
    lat = lat0 + v * math.cos(psi) * t / rm
    lat_dot, lon_dot = v * math.cos(psi) / rm, v * math.sin(psi) / rp
    mm, nn = gd.radii_of_curvature(lat)
    ve = (nn + h) * np.cos(lat) * lon_dot
    vn = (mm + h) * lat_dot
    expected = boule_gamma(lat, h) - 2 * W * np.cos(lat) * ve - ve**2 / (nn + h) - vn**2 / (mm + h)
    np.testing.assert_allclose(out.truth["lat"], lat, rtol=0, atol=1e-14)
    # the gravity vector is tilted by < 1e-6 rad from the normal at 800 m: cos = 1 - 5e-13
    assert np.abs(out.specific_force_t[:, 2] - expected).max() < 1e-8


def _turbulent_grid(triad, imu_hz=50.0, static=20.0, turb_m=2.0, turb_deg=1.0, noise=False, **plan_keys):
    """Two short lines with turns, a hold, turbulence; ``plan_keys`` replace the plan's keys;
    ``noise``: quick_sim's (a ``sensors`` mapping)."""
    plan = {
        "kind": "grid",
        "origin_lat_deg": 52.0,
        "origin_lon_deg": 10.0,
        "altitude_m": 600.0,
        "speed_mps": 60.0,
        "lines": {"count": 2, "spacing_m": 3000.0, "length_m": 2500.0, "heading_deg": 20.0},
        "static_start_s": static,
        "ramp_s": 30.0,
        "max_bank_deg": 28.0,
        **plan_keys,
    }
    turb = {
        "vertical_sigma_m": turb_m,
        "horizontal_sigma_m": turb_m,
        "attitude_sigma_deg": turb_deg,
        "min_period_s": 2.0,
    }
    return simulate_flight(quick_sim(plan=plan, triad=triad, imu_hz=imu_hz, turbulence=turb, seed=7, noise=noise))


def _imu_against_trajectory(s, p, every):
    """Largest differences of a strapdown flight ``s`` from the platform flight ``p`` of the same
    trajectory: its specific force rotated to ENU against the platform's (m/s^2), and its gyros
    against the inertial rate plus the body rate from finite differences of ``C_nb`` (rad/s,
    every ``every``-th sample); and the largest body rate (rad/s), to show it turned."""
    f_rot = np.einsum("nij,nj->ni", s.truth["mat_nt"], s.specific_force_t)
    d = 1e-4
    t = s.imu_time[::every]
    kp, km = tj.kinematics(s.plan, t + d), tj.kinematics(s.plan, t - d)
    c = tj.kinematics(s.plan, t).mat_nb
    om = np.einsum("nji,njk->nik", c, (kp.mat_nb - km.mat_nb) / (2 * d))
    w_nb = np.stack([om[:, 2, 1], om[:, 0, 2], om[:, 1, 0]], axis=1)
    w_in = np.einsum("nji,nj->ni", c, p.angular_rate_t[::every])
    return (
        np.abs(f_rot - p.specific_force_t).max(),
        np.abs(s.angular_rate_t[::every] - (w_in + w_nb)).max(),
        np.abs(w_nb).max(),
    )


def test_strapdown_and_platform_agree_after_rotation():
    p = _turbulent_grid("platform")
    s = _turbulent_grid("strapdown")
    # gyros: w_ib^b = C_bn w_in^n + w_nb^b, the body rate taken from finite differences of C_nb
    df, dw, w_nb = _imu_against_trajectory(s, p, 25)
    assert df < 1e-13 and dw < 1e-9
    assert w_nb > 0.05  # turns and turbulence really rotate the body
    # the aircraft turned, banked within limits, and went through the planned segments
    assert set(s.truth["line"]) == {"static", "turn", "L01", "L02"}
    assert np.degrees(np.abs(s.truth["roll"])).max() < 28.0 + 4 * 1.0


def test_derivatives_integrate_to_positions():
    """Simpson integration of the truth velocity (ECEF) reproduces the ECEF positions, and of
    the truth acceleration the velocities: the derivatives are the trajectory's."""
    s = _turbulent_grid("strapdown", imu_hz=100.0)
    tr = s.truth
    r_e = gd.geodetic_to_ecef(tr["lat"], tr["lon"], tr["height"])
    c_en = gd.mat_en(tr["lat"], tr["lon"])
    v_e = np.einsum("nij,nj->ni", c_en, tr["vel_n"])
    a_e = np.einsum("nij,nj->ni", c_en, tr["acc_n"])
    dt = s.imu_time[1] - s.imu_time[0]
    n = (len(s.imu_time) - 1) // 2 * 2

    def simpson_steps(y):
        return dt / 3.0 * (y[0 : n - 1 : 2] + 4 * y[1:n:2] + y[2 : n + 1 : 2])

    dr = r_e[2 : n + 1 : 2] - r_e[0 : n - 1 : 2]
    dv = v_e[2 : n + 1 : 2] - v_e[0 : n - 1 : 2]
    assert np.abs(v_e).max() > 50 and np.abs(a_e).max() > 2.0
    assert np.abs(simpson_steps(v_e) - dr).max() < 1e-6  # m per 0.02 s
    assert np.abs(simpson_steps(a_e) - dv).max() < 1e-7  # m/s per 0.02 s
    # cumulative over the whole flight
    assert np.abs(np.cumsum(simpson_steps(v_e), axis=0) - (r_e[2 : n + 1 : 2] - r_e[0])).max() < 1e-4


def test_strapdown_navigation_reproduces_the_trajectory():
    """Independent navigator: integrate C_ib' = C_ib [w x], v_i' = C_ib f + G_i, r_i' = v_i in
    the inertial frame with RK4 over pairs of IMU samples (mid-sample = RK midpoint) and
    compare with the truth after several minutes of static, ramp, lines, turns, turbulence."""
    s = _turbulent_grid("strapdown", imu_hz=50.0, static=10.0)
    tr = s.truth
    t = s.imu_time
    f, w = s.specific_force_t, s.angular_rate_t
    r_e = gd.geodetic_to_ecef(tr["lat"], tr["lon"], tr["height"])
    c_en = gd.mat_en(tr["lat"], tr["lon"])
    c_ib = c_en[0] @ tr["mat_nb"][0]
    r = r_e[0].copy()
    v = c_en[0] @ tr["vel_n"][0] + np.cross([0, 0, W], r)

    def grav_i(tt, ri):
        c = gd.mat_ie(tt)
        g_e = gd.normal_gravitation_ecef(c.T @ ri)
        return c @ g_e

    def skew(x):
        return np.array([[0, -x[2], x[1]], [x[2], 0, -x[0]], [-x[1], x[0], 0]])

    def deriv(tt, c, ri, vi, fk, wk):
        return c @ skew(wk), vi, c @ fk + grav_i(tt, ri)

    nsteps = (len(t) - 1) // 2
    for k in range(nsteps):
        i = 2 * k
        h = t[i + 2] - t[i]
        k1 = deriv(t[i], c_ib, r, v, f[i], w[i])
        k2 = deriv(t[i + 1], c_ib + 0.5 * h * k1[0], r + 0.5 * h * k1[1], v + 0.5 * h * k1[2], f[i + 1], w[i + 1])
        k3 = deriv(t[i + 1], c_ib + 0.5 * h * k2[0], r + 0.5 * h * k2[1], v + 0.5 * h * k2[2], f[i + 1], w[i + 1])
        k4 = deriv(t[i + 2], c_ib + h * k3[0], r + h * k3[1], v + h * k3[2], f[i + 2], w[i + 2])
        c_ib = c_ib + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        r = r + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        v = v + h / 6 * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2])
    j = 2 * nsteps
    c_ie = gd.mat_ie(t[j])
    r_true_i = c_ie @ r_e[j]
    c_ib_true = c_ie @ c_en[j] @ tr["mat_nb"][j]
    assert t[j] > 200.0
    assert np.linalg.norm(r - r_true_i) < 2e-4  # m, after > 200 s of manoeuvres (measured 5e-5)
    assert np.abs(c_ib - c_ib_true).max() < 5e-9  # measured 1e-9; 7e-11 at 100 Hz


def test_coordinated_turns_have_no_side_force():
    plan = {
        "kind": "grid",
        "origin_lat_deg": 45.0,
        "origin_lon_deg": 135.0,
        "altitude_m": 800.0,
        "speed_mps": 80.0,
        "lines": {"count": 2, "spacing_m": 6000.0, "length_m": 3000.0, "heading_deg": 90.0},
        "max_bank_deg": 25.0,
    }
    s = simulate_flight(quick_sim(plan=plan, triad="strapdown", imu_hz=10.0))
    m = s.truth["line"] == "turn"
    roll = s.truth["roll"][m]
    assert np.degrees(np.abs(roll)).max() == pytest.approx(25.0, abs=1e-3)  # peak bank = max_bank_deg
    # lateral acceleration of the turn is balanced by the bank: body-y force ~ 0 (0.2 % of g tan 25)
    assert np.abs(s.specific_force_t[m, 1]).max() < 0.01
    assert np.abs(np.linalg.norm(s.truth["acc_n"][m], axis=1)).max() > 4.0


def test_grid_lines_are_flown_where_planned():
    plan = {
        "kind": "grid",
        "origin_lat_deg": 45.0,
        "origin_lon_deg": 135.0,
        "altitude_m": 800.0,
        "speed_mps": 70.0,
        "lines": {"count": 3, "spacing_m": 2000.0, "length_m": 8000.0, "heading_deg": 0.0},
        "ties": {"count": 2, "spacing_m": 4000.0, "altitude_m": 900.0},
    }
    s = simulate_flight(quick_sim(plan=plan, imu_hz=10.0))
    tr = s.truth
    rm, rp = tj.map_scales(math.radians(45.0), 800.0)
    x = (tr["lon"] - math.radians(135.0)) * rp
    y = (tr["lat"] - math.radians(45.0)) * rm
    for name, x_exp, h_exp in (("L01", 0.0, 800.0), ("L02", 2000.0, 800.0), ("L03", 4000.0, 800.0)):
        m = tr["line"] == name
        assert np.abs(x[m] - x_exp).max() < 1e-6 and np.abs(tr["height"][m] - h_exp).max() == 0.0
        assert np.ptp(y[m]) == pytest.approx(8000.0, abs=70 * 0.1 + 1e-6)
    for name in ("T01", "T02"):
        m = tr["line"] == name
        assert np.ptp(y[m]) < 1e-6 and np.abs(tr["height"][m] - 900.0).max() == 0.0
    assert sorted(set(tr["line"])) == ["L01", "L02", "L03", "T01", "T02", "turn"]
    # smooth everywhere: no acceleration jumps between samples (a turn entered abruptly would
    # jump by v * turn rate = 70 * g tan(25 deg) / 70 ~ 4.6 m/s^2; measured max jerk 0.86 m/s^3)
    assert np.abs(np.diff(tr["acc_n"], axis=0)).max() < 0.15
    # roll rate limited by max_roll_rate_degps (default 5), bank by max_bank_deg (25)
    roll_rate = np.degrees(np.gradient(tr["roll"], s.imu_time))
    assert 4.0 < np.abs(roll_rate).max() <= 5.0
    assert np.degrees(np.abs(tr["roll"])).max() == pytest.approx(25.0, abs=1e-3)


def test_attitude_matrix_conventions():
    """docs/conventions.md: nose/left/roof columns, and what positive angles do physically."""
    r, p, h = 0.3, -0.2, 1.1
    m = tj.euler_to_mat_nb(np.array([r, 0.0, 0.0, 0.1]), np.array([p, 0.0, 0.1, 0.0]), np.array([h, 0.0, 0.0, 0.5]))
    s, c = np.sin, np.cos
    nose = [s(h) * c(p), c(h) * c(p), s(p)]
    left = [-s(h) * s(p) * s(r) - c(h) * c(r), -c(h) * s(p) * s(r) + s(h) * c(r), c(p) * s(r)]
    roof = [-s(h) * s(p) * c(r) + c(h) * s(r), -c(h) * s(p) * c(r) - s(h) * s(r), c(p) * c(r)]
    np.testing.assert_allclose(m[0], np.array([nose, left, roof]).T, atol=1e-15)
    np.testing.assert_allclose(m[1], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-15)  # nose N, left W
    assert m[2][2, 0] > 0  # positive pitch: nose up
    assert m[3][2, 1] > 0  # positive roll: left wing up = right wing down
    np.testing.assert_allclose(np.einsum("nji,njk->nik", m, m), np.tile(np.eye(3), (4, 1, 1)), atol=1e-15)


def test_turbulence_amplitude_and_compiled_sum():
    turb = {
        "vertical_sigma_m": 2.0,
        "horizontal_sigma_m": 3.0,
        "attitude_sigma_deg": 0.5,
        "min_period_s": 4.0,
        "max_period_s": 300.0,
    }
    s = simulate_flight(quick_sim(duration_s=6 * 3600.0, imu_hz=1.0, turbulence=turb))
    tr = s.truth
    assert np.std(tr["height"] - 1000.0) == pytest.approx(2.0, rel=0.05)
    rm = tj.map_scales(math.radians(45.0), 1000.0)[0]
    assert np.std((tr["lat"] - math.radians(45.0)) * rm) == pytest.approx(3.0, rel=0.05)
    assert np.degrees(np.std(tr["roll"])) == pytest.approx(0.5, rel=0.05)
    # vertical accelerations of light-to-moderate turbulence: ~0.1-1 m/s^2
    assert 0.05 < np.std(tr["acc_n"][:, 2]) < 1.0
    tb = s.plan.turbulence
    t = np.linspace(0.0, 500.0, 2001)
    np.testing.assert_allclose(
        tj._sinusum(t, tb.amp[2], tb.omega[2], tb.phase[2]),
        tj.sinusum_reference(t, tb.amp[2], tb.omega[2], tb.phase[2]),
        rtol=0,
        atol=1e-12,
    )


def test_gnss_gauss_markov_error_has_its_sigma_and_correlation_time():
    """``gnss.vertical_markov_sigma_m`` / ``horizontal_markov_sigma_m`` / ``markov_tau_s``: a
    first-order Gauss-Markov error on top of the white noise, with its stationary sigma and its
    autocorrelation exp(-1) at one correlation time; a flight without it draws the same white
    noise as before it existed."""
    from gravsurvey.simulate.sensors import gnss_errors

    n, dt, tau = 200_000, 0.5, 300.0
    lat = np.full(n, math.radians(45.0))
    h = np.full(n, 1000.0)
    white = {"gnss": {"horizontal_sigma_m": 0.3, "vertical_sigma_m": 0.5}}
    both = {
        "gnss": {
            **white["gnss"],
            "horizontal_markov_sigma_m": 0.0,
            "vertical_markov_sigma_m": 0.05,
            "markov_tau_s": tau,
        }
    }
    _, _, dh0 = gnss_errors(lat, h, white, np.random.default_rng(5), dt_s=dt)
    _, _, dh1 = gnss_errors(lat, h, both, np.random.default_rng(5), dt_s=dt)
    markov = dh1 - dh0  # the white draws are the same
    assert np.std(dh0) == pytest.approx(0.5, rel=0.01)
    assert np.std(markov) == pytest.approx(0.05, rel=0.1)
    lag = int(tau / dt)
    rho = np.corrcoef(markov[:-lag], markov[lag:])[0, 1]
    assert rho == pytest.approx(math.exp(-1.0), abs=0.06)
    dlat, dlon, _ = gnss_errors(lat, h, both, np.random.default_rng(5), dt_s=dt)
    dlat0, dlon0, _ = gnss_errors(lat, h, white, np.random.default_rng(5), dt_s=dt)
    assert np.array_equal(dlat, dlat0) and np.array_equal(dlon, dlon0)  # no horizontal part asked


def _windy_grid(triad, wind, turb_deg=1.0, hold="ground", turb_m=2.0, wind_from=290.0):
    return _turbulent_grid(
        triad,
        turb_m=turb_m,
        turb_deg=turb_deg,
        wind_speed_mps=wind,
        wind_from_deg=wind_from,
        hold_speed=hold,
    )


def test_a_crosswind_turns_the_nose_not_the_track():
    """In a wind the aircraft flies the plan's ground track with its nose along its air
    velocity: at the plan's ground speed (``hold_speed: ground``) the translation is the
    windless flight's, the heading on a line differs from the track by the crab angle, and the
    gyros still measure the attitude's own rate."""
    calm, windy = _windy_grid("strapdown", 0.0), _windy_grid("strapdown", 15.0)
    for k in ("lat", "lon", "height", "vel_n", "acc_n"):
        np.testing.assert_array_equal(windy.truth[k], calm.truth[k])
    # no turbulence in the attitude: the line's heading is exactly the plan's plus the crab
    still = _windy_grid("strapdown", 15.0, turb_deg=0.0)
    tr = still.truth
    w_e, w_n = tj.wind_velocity_en(15.0, 290.0)
    for name, track_deg in (("L01", 20.0), ("L02", 200.0)):
        m = tr["line"] == name
        a = math.radians(track_deg)
        along, cross = w_e * math.sin(a) + w_n * math.cos(a), w_e * math.cos(a) - w_n * math.sin(a)
        # air velocity = ground - wind; its angle from the track, clockwise positive
        crab = math.atan2(-cross, 60.0 - along)
        dev = np.angle(np.exp(1j * (tr["heading"][m] - a)))
        np.testing.assert_allclose(dev, crab, atol=1e-12)
        assert abs(math.degrees(crab)) > 10.0  # a 15-m/s wind mostly across a 60-m/s track
        np.testing.assert_allclose(tr["roll"][m], 0.0, atol=1e-12)  # straight and level: no bank
    # on the hold the nose is already where the speed ramp and the first line keep it
    rest = tr["line"] == "static"
    np.testing.assert_allclose(tr["heading"][rest], tr["heading"][tr["line"] == "L01"][0], atol=1e-12)
    # gyros: the analytic body rate is the finite-difference rate of C_nb, turns and ramps included
    df, dw, _ = _imu_against_trajectory(windy, _windy_grid("platform", 15.0), 25)
    assert df < 1e-13 and dw < 1e-9


@pytest.mark.parametrize("turb_deg", [0.0, 1.5])
def test_the_fixes_are_the_antennas_turned_with_the_aircraft(turb_deg):
    """``sensors.gnss.antenna_m``: every fix moves from the IMU's by the antenna's offset on
    the aircraft's axes turned by its attitude (crab, bank, pitch, turbulence), the same on a
    platform; its noise is the same draw; an antenna at the IMU leaves the flight as it was; an
    offset no aircraft has is refused naming the key."""
    arm = np.array([3.0, -1.0, 1.5])
    gnss = {"horizontal_sigma_m": 0.3, "vertical_sigma_m": 0.5, "vertical_markov_sigma_m": 0.05}
    wind = {"wind_speed_mps": 15.0, "wind_from_deg": 290.0, "hold_speed": "ground"}
    at_imu = _turbulent_grid("strapdown", turb_deg=turb_deg, noise={"gnss": gnss}, **wind)
    moved = _turbulent_grid("strapdown", turb_deg=turb_deg, noise={"gnss": {**gnss, "antenna_m": arm.tolist()}}, **wind)
    zero = _turbulent_grid("strapdown", turb_deg=turb_deg, noise={"gnss": {**gnss, "antenna_m": [0, 0, 0]}}, **wind)
    for k in ("gnss_lat_deg", "gnss_lon_deg", "gnss_height"):
        np.testing.assert_array_equal(getattr(zero, k), getattr(at_imu, k))
    np.testing.assert_array_equal(moved.specific_force_t, at_imu.specific_force_t)

    def ecef(s):
        lat, lon = np.radians(s.gnss_lat_deg), np.radians(s.gnss_lon_deg)
        return gd.geodetic_to_ecef(lat, lon, s.gnss_height), gd.mat_en(lat, lon)

    r1, c_en = ecef(moved)
    r0, _ = ecef(at_imu)
    off_n = np.einsum("nji,nj->ni", c_en, r1 - r0)  # ECEF -> ENU
    tr = moved.truth
    k = np.searchsorted(tr["time"], moved.gnss_time)
    assert np.array_equal(tr["time"][k], moved.gnss_time)
    # to 10 um: the ENU axes here are the noisy fix's, not the IMU's (3 m / 6400 km apart)
    np.testing.assert_allclose(off_n, np.einsum("nij,j->ni", tr["mat_nb"][k], arm), atol=1e-5)
    if turb_deg == 0.0:
        # on a line in the crosswind the antenna's 3 m forward lie along the nose, not the track
        line = tr["line"][k] == "L01"
        psi = tr["heading"][k][line]
        # 1 m to the right of the nose: (cos psi, -sin psi) east, north
        fwd = off_n[line, :2] - np.stack([np.cos(psi), -np.sin(psi)], axis=1)
        np.testing.assert_allclose(fwd, 3.0 * np.stack([np.sin(psi), np.cos(psi)], axis=1), atol=1e-5)
        assert np.abs(np.angle(np.exp(1j * (psi - math.radians(20.0))))).min() > math.radians(10.0)  # crabbed
        np.testing.assert_allclose(off_n[line, 2], 1.5, atol=1e-5)
    with pytest.raises(ConfigError, match=r"sensors\.gnss\.antenna_m: expected forward, left, up .*-30 m each"):
        simulate_flight(quick_sim(noise={"gnss": {"antenna_m": [0.0, 0.0, 31.0]}}))


def test_a_wind_faster_than_half_the_plan_speed_is_refused():
    plan = {"kind": "line", "origin_lat_deg": 45.0, "origin_lon_deg": 10.0, "duration_s": 600.0, "speed_mps": 60.0}
    with pytest.raises(ConfigError, match=r"plan\.wind_speed_mps: 31 m/s is more than 0\.5 x .*speed_mps \(60 m/s\)"):
        simulate_flight(quick_sim(plan={**plan, "wind_speed_mps": 31.0}))
    with pytest.raises(ConfigError, match=r"plan\.hold_speed: expected one of .*'air'.*'ground'.*got 'airspeed'"):
        simulate_flight(quick_sim(plan={**plan, "hold_speed": "airspeed"}))


def test_lines_flown_at_the_airspeed_in_a_wind():
    """``hold_speed: air`` (the default): each line is flown at the plan speed through the air,
    its ground speed the wind triangle's (upwind slower, downwind faster), with smooth speed
    changes to and from the connectors; the lines start where planned, the heading is along
    the air velocity, and the gyros and accelerometers are the trajectory's."""
    s = _windy_grid("strapdown", 15.0, turb_deg=0.0, hold="air", turb_m=0.0, wind_from=250.0)
    tr = s.truth
    w_e, w_n = tj.wind_velocity_en(15.0, 250.0)
    speeds = {}
    for name, track_deg in (("L01", 20.0), ("L02", 200.0)):
        m = tr["line"] == name
        a = math.radians(track_deg)
        along, cross = w_e * math.sin(a) + w_n * math.cos(a), w_e * math.cos(a) - w_n * math.sin(a)
        v_ground = math.sqrt(60.0**2 - cross**2) + along
        assert tj.ground_speed_at_airspeed(60.0, a, (w_e, w_n)) == pytest.approx(v_ground, rel=1e-15)
        speeds[name] = np.hypot(tr["vel_n"][m, 0], tr["vel_n"][m, 1])
        # the map's scale distortion over 2.5 km: < 1e-4 relative
        np.testing.assert_allclose(speeds[name], v_ground, rtol=1e-4)
        air_e, air_n = tr["vel_n"][m, 0] - w_e, tr["vel_n"][m, 1] - w_n
        np.testing.assert_allclose(np.hypot(air_e, air_n), 60.0, rtol=1e-4)  # the airspeed held
        nose = np.arctan2(air_e, air_n)
        np.testing.assert_allclose(np.angle(np.exp(1j * (tr["heading"][m] - nose))), 0.0, atol=2e-4)
    assert abs(speeds["L01"].mean() - speeds["L02"].mean()) > 5.0  # one line into the wind's along part
    # the lines are where the plan puts them: the windless flight's line positions
    calm = _windy_grid("strapdown", 0.0, turb_deg=0.0, turb_m=0.0)
    for name in ("L01", "L02"):
        (seg,) = [g for g in s.plan.segments if g.label == name]
        (ref,) = [g for g in calm.plan.segments if g.label == name]
        assert (seg.x0, seg.y0, seg.psi0) == pytest.approx((ref.x0, ref.y0, ref.psi0), abs=1e-9)
        assert seg.speed * seg.duration == pytest.approx(ref.speed * ref.duration, abs=1e-9)
        assert seg.speed == pytest.approx(speeds[name].mean(), rel=1e-4) and ref.speed == 60.0
    # smooth: no jumps in acceleration (a speed change entered abruptly would jump by ~0.5 m/s^2)
    assert np.abs(np.diff(tr["acc_n"], axis=0)).max() < 0.05
    # the IMU is the trajectory's: strapdown rotated = platform, gyros = finite-differenced attitude
    w = _windy_grid("strapdown", 15.0, hold="air", wind_from=250.0)
    df, dw, _ = _imu_against_trajectory(w, _windy_grid("platform", 15.0, hold="air", wind_from=250.0), 25)
    assert df < 1e-13 and dw < 1e-9


def _airfield_grid(triad, turb_m=2.0, turb_deg=1.0):
    return _turbulent_grid(
        triad,
        imu_hz=20.0,
        static=60.0,
        turb_m=turb_m,
        turb_deg=turb_deg,
        altitude_m=1200.0,
        lines={"count": 2, "spacing_m": 3000.0, "length_m": 8000.0, "heading_deg": 20.0},
        static_end_s=60.0,
        ground_height_m=150.0,
        max_bank_deg=25.0,
    )


def test_a_flight_from_the_ground_climbs_to_its_lines_and_lands():
    """``plan.ground_height_m``: parked on the ground, the take-off run, a climb on the way to the
    first line at ``max_climb_rate_mps`` at most, the lines at their altitude, a descent after
    the last and the landing run to a stop on the ground; the IMU is the trajectory's."""
    still = _airfield_grid("platform", turb_m=0.0, turb_deg=0.0)
    tr = still.truth
    parked = tr["line"] == "static"
    assert parked[0] and parked[-1] and parked.sum() == 2 * 60 * 20
    np.testing.assert_array_equal(tr["height"][parked], 150.0)
    assert np.abs(tr["vel_n"][parked]).max() == 0.0
    # parked at 150 m: the normal gravity there (boule), nothing else
    lat = tr["lat"][parked]
    np.testing.assert_allclose(still.specific_force_t[parked, 2], boule_gamma(lat, 150.0), atol=1e-9)
    for name in ("L01", "L02"):
        np.testing.assert_array_equal(tr["height"][tr["line"] == name], 1200.0)
    climb = tr["vel_n"][:, 2]
    assert 4.5 < climb.max() <= 5.0 + 1e-9 and -5.0 - 1e-9 <= climb.min() < -4.5
    # up before the first line, down after the last: the heights between are the lines'
    first, last = np.flatnonzero(tr["line"] == "L01")[0], np.flatnonzero(tr["line"] == "L02")[-1]
    assert np.all(np.diff(tr["height"][:first]) >= -1e-9) and np.all(np.diff(tr["height"][last:]) <= 1e-9)
    assert np.abs(np.diff(tr["acc_n"], axis=0)).max() < 0.05  # smooth: no steps in acceleration
    # the vertical velocity is the height's derivative (20-Hz central differences: 4e-5 m/s)
    t = still.imu_time
    np.testing.assert_allclose(np.gradient(tr["height"], t)[1:-1], climb[1:-1], atol=1e-4)
    # with turbulence: strapdown rotated = platform, gyros = the finite-differenced attitude
    df, dw, _ = _imu_against_trajectory(_airfield_grid("strapdown"), _airfield_grid("platform"), 10)
    assert df < 1e-13 and dw < 1e-9


def test_a_ground_height_without_a_parked_period_is_refused():
    plan = {"kind": "line", "origin_lat_deg": 45.0, "origin_lon_deg": 10.0, "duration_s": 600.0}
    with pytest.raises(ConfigError, match=r"plan\.ground_height_m: the aircraft is on the ground only while parked"):
        simulate_flight(quick_sim(plan={**plan, "ground_height_m": 100.0}))


@pytest.mark.parametrize("dh", [5.0, 100.0, 3000.0, -40.0])
def test_a_steady_climb_reaches_its_height_at_its_rate_with_exact_derivatives(dh):
    """``AltitudeStep`` with ``ramp_s``: the height changes by ``dh``, the rate holds at 5 m/s
    between its smoothsteps (a change too small to reach it peaks at ``dh / ramp_s``), and the
    rate and its derivative are the height's (finite differences over 1-ms steps)."""
    dur = tj.steady_climb_duration(dh, 5.0)
    step = tj.AltitudeStep(10.0, dur, 0.0, dh, ramp_s=tj.CLIMB_RAMP_S)
    t = np.arange(0.0, dur + 20.0, 1e-3)
    h = tj.steady_climb_profile(t, step)
    assert h[0, 0] == 0.0 and h[0, -1] == pytest.approx(dh, abs=1e-9)
    assert np.abs(h[1]).max() == pytest.approx(min(5.0, abs(dh) / tj.CLIMB_RAMP_S), rel=1e-6)
    np.testing.assert_allclose(np.gradient(h[0], t), h[1], atol=1e-6)
    np.testing.assert_allclose(np.gradient(h[1], t), h[2], atol=1e-6)


def test_a_climb_too_slow_for_the_usual_run_in_still_finds_its_path():
    """A 0.3-m/s climb to 4 km needs a run-in longer than the connector search's 200 turn radii:
    the search lengthens its step instead of refusing the plan ("no smooth turn path")."""
    plan = {
        "kind": "grid",
        "origin_lat_deg": 52.0,
        "origin_lon_deg": 10.0,
        "altitude_m": 4000.0,
        "speed_mps": 80.0,
        "lines": {"count": 2, "spacing_m": 3000.0, "length_m": 8000.0, "heading_deg": 20.0},
        "static_start_s": 60.0,
        "static_end_s": 60.0,
        "ground_height_m": 100.0,
        "max_climb_rate_mps": 0.3,
    }
    tr = simulate_flight(quick_sim(plan=plan, imu_hz=1.0)).truth
    climb = tr["vel_n"][:, 2]
    assert 0.29 < climb.max() <= 0.3 + 1e-9 and -0.3 - 1e-9 <= climb.min() < -0.29
    for name in ("L01", "L02"):
        np.testing.assert_array_equal(tr["height"][tr["line"] == name], 4000.0)
