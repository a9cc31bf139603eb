"""GNSS position aiding of the 3D-INM (attitude-error and gyro-bias states) against truth."""

import math

import numpy as np
import pytest

from gravsurvey.errors import ConfigError
from gravsurvey.geodesy import MGAL, radii_of_curvature
from gravsurvey.inm.alignment import skew
from gravsurvey.inm.errormodel import (
    BG,
    DP,
    DQ,
    G,
    TH,
    AltimeterMeasurement,
    GnssMeasurement,
    balance_scales,
    continuous_model_n,
    discretise,
    epoch_geometry,
    initial_covariance,
    noise_params,
)
from gravsurvey.inm.mechanization import mechanize
from gravsurvey.inm.params import InitialState, InmParams
from gravsurvey.inm.solve import estimate_anomaly
from gravsurvey.io.record import AltimeterChannel, FlightRecord, GnssChannel, ImuChannel
from gravsurvey.simulate.run import quick_sim, simulate_flight
from gravsurvey.settings import inm_params

from inm_truth import parallel_flight

DEGPH = math.radians(1.0) / 3600.0


def _record(s, gnss=True):
    g = (
        GnssChannel(s.gnss_time, np.radians(s.gnss_lat_deg), np.radians(s.gnss_lon_deg), s.gnss_height)
        if gnss
        else None
    )
    return FlightRecord(
        s.start_unix_ns,
        ImuChannel(s.imu_time, s.specific_force_t, s.angular_rate_t),
        AltimeterChannel(s.alt_time, s.alt_height),
        g,
        source="sim",
    )


def _initial(s):
    tr = s.truth
    return InitialState(tr["lat"][0], tr["lon"][0], tr["height"][0], tr["vel_n"][0].copy(), tr["mat_nt"][0].copy())


def _horizontal_error_m(s, sol):
    lat = np.interp(sol.time, s.truth["time"], s.truth["lat"])
    lon = np.interp(sol.time, s.truth["time"], s.truth["lon"])
    h = np.interp(sol.time, s.truth["time"], s.truth["height"])
    m, n = radii_of_curvature(lat)
    return np.hypot((sol.lat - lat) * (m + h), (sol.lon - lon) * (n + h) * np.cos(lat))


def _rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


def test_balance_scales_remove_the_squarings():
    """The balanced Van Loan matrix of the 14-state model needs no squaring (1-norm <= 0.25)."""
    tr = parallel_flight(60.0, triad="strapdown", yaw_rate=0.05)
    init = InitialState(tr["lat"][0], tr["lon"][0], 1000.0, tr["vel_n"][0], tr["mat_nt"][0])
    nav = mechanize(tr["time"], tr["f_t"], tr["w_t"], init, tr["time"][::10], tr["height"][::10])
    geom = epoch_geometry(nav, np.arange(0, tr["time"].size, 10), True)
    c = noise_params(InmParams(gravimeter_white_mps2=1e-5), 1.0)
    k = 3
    args = [x[k] for x in (geom.r_i, geom.v_i, geom.up_i, geom.e1_i, geom.e2_i, geom.e3_i, geom.w02, geom.speed)]
    a, qc = continuous_model_n.py_func(*args, c, 14)
    s = balance_scales(np.abs(a), np.abs(qc))
    np.testing.assert_array_equal(np.exp2(np.round(np.log2(s))), s)  # powers of two: exact
    dt = geom.dt[k]

    def vl_norm(a, qc):
        return max(np.abs(a).sum(axis=0).max(), (np.abs(qc).sum(axis=0) + np.abs(a).sum(axis=1)).max()) * dt

    assert vl_norm(a, qc) > 1e6  # the gyro bias drives the position with the Earth's radius
    assert vl_norm(a * s[None, :] / s[:, None], qc / np.outer(s, s)) < 0.25  # measured 0.025


def test_aided_discretise_kernel_matches_reference_and_bias_coupling():
    """14-state Phi, Q: numba kernel == scipy reference; a gyro bias rotates the solution."""
    tr = parallel_flight(120.0, triad="strapdown", yaw_rate=0.05)
    init = InitialState(tr["lat"][0], tr["lon"][0], 1000.0, tr["vel_n"][0], tr["mat_nt"][0])
    nav = mechanize(tr["time"], tr["f_t"], tr["w_t"], init, tr["time"][::10], tr["height"][::10])
    idx = np.arange(0, tr["time"].size, 10)
    p = InmParams(gravimeter_white_mps2=1e-5)
    geom = epoch_geometry(nav, idx, True)
    a_phi, a_q = discretise(geom, p, 1.0, aided=True)
    b_phi, b_q = discretise(geom, p, 1.0, reference=True, aided=True)
    assert a_phi.shape == (idx.size, 14, 14)
    # compare in natural units of each state (m, m/s, m/s^2, rad, rad/s): the Taylor and Pade
    # exponentials agree to round-off of the largest terms (|q| ~ 6.4e6 m couples everything)
    u = np.array([1.0, 1e-2, 1.0, 1e-2, 1.0, 1e-2, 1e-5, 1e-5, 1e-6, 1e-6, 1e-6, 1e-7, 1e-7, 1e-7])
    sa = a_phi / u[:, None] * u[None, :]
    sb = b_phi / u[:, None] * u[None, :]
    # measured 3.3e-16 (1.3e-9 before the balancing: ~26 squarings of the unbalanced matrix)
    assert np.max(np.abs(sa - sb)) < 1e-13 * np.max(np.abs(sb))
    sq = np.sqrt(np.abs(np.einsum("kii->ki", b_q[1:]))).max(axis=0)
    sq[sq == 0] = 1.0  # the gyro bias is a constant: no process noise
    # measured 2.1e-10 (scipy's own round-off; 4.9e-9 before the balancing)
    assert np.max(np.abs(a_q[1:] - b_q[1:]) / np.outer(sq, sq)) < 2e-9
    np.testing.assert_array_equal(a_q[1:, BG[0], BG[0]], 0.0)
    # the first 8 x 8 block is the seed model unchanged
    s_phi, _ = discretise(geom, p, 1.0)
    # (A is block upper triangular: the attitude/bias states drive the seed's, not vice versa)
    u8 = u[:8]
    d8 = (a_phi[:, :8, :8] - s_phi) / u8[:, None] * u8[None, :]
    assert np.max(np.abs(d8)) < 1e-13  # measured 0 (1.3e-9 before the balancing)
    # theta integrates -b over one interval (d theta/dt = -w x theta - b, |w| dt << 1)
    k = 50
    np.testing.assert_allclose(a_phi[k][np.ix_(TH, BG)], -np.eye(3) * geom.dt[k], atol=0.06 * geom.dt[k])
    # ... and dq gains (q x b) dt (d(dq)/dt = ... + q x nu): the rotation of the whole solution
    q_t = geom.mat_it[k].T @ nav.r_i[idx[k]]
    b = np.array([1.0, -2.0, 0.5]) * 1e-7
    dq = a_phi[k][np.ix_(DQ, BG)] @ b
    assert np.linalg.norm(dq - np.cross(q_t, b) * geom.dt[k]) < 0.05 * np.linalg.norm(np.cross(q_t, b))


def test_gnss_measurement_geometry():
    """z = computed - GNSS position on ENU (m); several samples per epoch averaged, R / n."""
    tr = parallel_flight(30.0)
    init = InitialState(tr["lat"][0], tr["lon"][0], 1000.0, tr["vel_n"][0], tr["mat_nt"][0])
    nav = mechanize(tr["time"], tr["f_t"], tr["w_t"], init, tr["time"][::10], tr["height"][::10])
    idx = np.arange(0, tr["time"].size, 10)
    t = np.array([0.0, 2.0, 2.2, 5.0, 40.0])
    lat = np.interp(t, tr["time"], tr["lat"])
    lon = np.interp(t, tr["time"], tr["lon"])
    h = np.interp(t, tr["time"], tr["height"]) if "height" in tr else np.full(t.size, 1000.0)
    m, n = radii_of_curvature(lat)
    # GNSS 3 m east, 4 m north, 1 m high of the truth -> z = (-3, -4, -1)
    lat_g = lat + 4.0 / (m + h)
    lon_g = lon + 3.0 / ((n + h) * np.cos(lat))
    meas = GnssMeasurement(t, lat_g, lon_g, h + 1.0, 0.5, 1.0)
    z, hh, r = meas.build(nav, idx, 0.5)
    assert z.shape == (idx.size, 3) and hh.shape == (idx.size, 3, 14)
    np.testing.assert_allclose(z[0], [-3.0, -4.0, -1.0], atol=2e-3)
    np.testing.assert_allclose(z[2], [-3.0, -4.0, -1.0], atol=2e-3)  # 2.0 s and 2.2 s averaged
    np.testing.assert_allclose(np.diag(r[2]), np.array([0.25, 0.25, 1.0]) / 2, rtol=1e-12)
    np.testing.assert_allclose(np.diag(r[5]), [0.25, 0.25, 1.0], rtol=1e-12)
    assert np.isnan(z[1]).all() and np.isnan(z[idx.size - 1]).all()  # no sample; 40 s out of range
    # H on dq is the triad -> ENU rotation (orthonormal); on theta it is that times [q x]
    hq = hh[5][:, DQ]
    np.testing.assert_allclose(hq @ hq.T, np.eye(3), atol=1e-12)
    q_t = nav.mat_it[idx[5]].T @ nav.r_i[idx[5]]
    th = np.array([1e-6, -2e-6, 3e-6])
    np.testing.assert_allclose(hh[5][:, TH] @ th, hq @ np.cross(q_t, th), rtol=1e-9)
    # the altimeter's aided H adds cos(a) (n x q) on theta, |n x q| = |q| sin(a) ~ 21 km at 45 deg
    alt = AltimeterMeasurement(tr["time"][::10], np.full(idx.size, 1000.0), 1.0)
    _, ha, _ = alt.build(nav, idx, 0.5, 14)
    assert 1.5e4 < np.linalg.norm(ha[5, 0, TH]) < 2.5e4
    np.testing.assert_array_equal(ha[5, 0, BG], 0.0)


def test_offset_measurements_see_the_attitude_error_move_the_position():
    """A fix ``d`` from its epoch sees the true position error there, ``C (dq + q x theta) + d C
    (dp + p x theta)``: the ``d [p x]`` term on theta carries the inertial velocity (~450 m/s),
    so without it a 0.03-deg attitude error was 0.08 m wrong at d = 0.4 s, each fix against its
    epoch (a strapdown flight in turbulence, aligned in motion, settled on gyro biases 30 sigma
    off; docs/benchmarks.md, "Fixes between the filter's epochs")."""
    tr = parallel_flight(60.0, triad="strapdown", yaw_rate=0.02)
    # a computed attitude off the truth by theta0: C_true = C (I + [theta x])
    th0 = np.array([3e-4, -5e-4, 2e-4])
    init = InitialState(tr["lat"][0], tr["lon"][0], 1000.0, tr["vel_n"][0], tr["mat_nt"][0] @ (np.eye(3) - skew(th0)))
    nav = mechanize(tr["time"], tr["f_t"], tr["w_t"], init, tr["time"][::10], tr["height"][::10])
    idx = np.arange(0, tr["time"].size, 10)
    # the true error state at each epoch, on the triad
    wt = (tr["lon"][1] - tr["lon"][0]) / (tr["time"][1] - tr["time"][0]) + 7.292115e-5
    v_true = np.cross([0.0, 0.0, wt], tr["r_i"])
    c = nav.mat_it[idx]
    skew_part = np.einsum("nji,njk->nik", c, tr["mat_it"][idx])
    th = np.stack([skew_part[:, 2, 1], skew_part[:, 0, 2], skew_part[:, 1, 0]], axis=1)
    q_t = np.einsum("nji,nj->ni", c, nav.r_i[idx])
    p_t = np.einsum("nji,nj->ni", c, nav.v_i[idx])
    x = np.zeros((idx.size, 14))
    x[:, DQ] = np.einsum("nji,nj->ni", c, nav.r_i[idx] - tr["r_i"][idx]) - np.cross(q_t, th)
    x[:, DP] = np.einsum("nji,nj->ni", c, nav.v_i[idx] - v_true[idx]) - np.cross(p_t, th)
    x[:, TH] = th
    # one fix per epoch, 0.4 s after it or before it, at the true position
    j = idx[1:-1] + np.where(np.arange(idx.size - 2) % 2 == 0, 4, -4)
    t = tr["time"][j]
    gnss = GnssMeasurement(t, tr["lat"][j], tr["lon"][j], tr["height"][j], 0.5, 1.0)
    z, hh, _ = gnss.build(nav, idx, 0.5)
    pred = np.einsum("nij,nj->ni", hh[1:-1], x[1:-1])
    # what the d [p x] term is worth here: 0.4 s x 450 m/s x 6e-4 rad
    moved = 0.4 * np.linalg.norm(np.cross(p_t, th), axis=1)
    assert moved.max() > 0.05
    assert np.max(np.abs(z[1:-1] - pred)) < 0.02 * moved.max()
    # the altimeter: the same term along the normal
    alt = AltimeterMeasurement(t, tr["height"][j], 0.05)
    za, ha, _ = alt.build(nav, idx, 0.5, 14)
    pa = np.einsum("nj,nj->n", ha[1:-1, 0], x[1:-1])
    assert np.max(np.abs(za[1:-1, 0] - pa)) < 0.02 * moved.max()


def test_aided_initial_covariance():
    """dq = C^T dr - q x theta: the attitude sigma shows as |q| sigma_theta across q."""
    p = InmParams(initial_attitude_sigma_deg=0.01, initial_position_sigma_m=2.0)
    q = np.array([0.0, 0.0, 6.4e6])
    pv = np.array([300.0, 0.0, 0.0])
    p0 = initial_covariance(p, q, pv)
    assert p0.shape == (14, 14)
    d = np.sqrt(np.diag(p0))
    np.linalg.cholesky(p0 / np.outer(d, d))  # positive definite (raises otherwise)
    s_th = math.radians(0.01)
    assert p0[DQ[0], DQ[0]] == pytest.approx(4.0 + (6.4e6 * s_th) ** 2, rel=1e-12)
    assert p0[DQ[2], DQ[2]] == pytest.approx(4.0, rel=1e-12)
    assert p0[BG[0], BG[0]] == pytest.approx((0.05 * DEGPH) ** 2, rel=1e-12, abs=0.0)
    assert p0[G, G] == pytest.approx(p.initial_anomaly_sigma_mps2**2, abs=0.0)


SENSORS = {
    "accelerometer": {"white_sigma_mps2": 5.0e-4},
    "gravimeter": {"markov_sigma_mps2": 1.0e-6, "markov_lambda_per_s": 0.025, "white_sigma_mps2": 1.0e-4},
    "gyro": {"bias_degph": [0.03, -0.02, 0.01], "white_drift_degph": 0.005},
    "altimeter": {"sigma_m": 0.05},
    "gnss": {"horizontal_sigma_m": 0.5, "vertical_sigma_m": 1.0},
}
GRID = {
    "kind": "grid",
    "origin_lat_deg": 47.0,
    "origin_lon_deg": 11.0,
    "altitude_m": 800.0,
    "speed_mps": 70.0,
    "lines": {"count": 3, "spacing_m": 3000.0, "length_m": 25000.0, "heading_deg": 0.0},
    "static_start_s": 120.0,
}


@pytest.fixture(scope="module")
def biased_grid():
    """Strapdown grid with gyro biases (<= 0.03 deg/h) and 0.5 m GNSS: 25 min at 10 Hz."""
    sim = quick_sim(
        plan=GRID,
        triad="strapdown",
        noise=SENSORS,
        field="seed_smooth",
        gnss_hz=5.0,
        altimeter_hz=5.0,
        turbulence={"vertical_sigma_m": 1.0, "horizontal_sigma_m": 1.0, "attitude_sigma_deg": 0.5},
        seed=3,
    )
    return simulate_flight(sim)


def _params(aided):
    # one fixed model for both runs: the comparison is of the aiding, not of identification
    return InmParams(
        accel_noise_mps2=5e-4,
        gyro_drift_degph=0.005,
        gravimeter_sigma_mps2=1e-6,
        gravimeter_white_mps2=1e-4,
        altimeter_sigma_m=0.05,
        gnss_aiding=aided,
        gnss_horizontal_sigma_m=0.5,
        gnss_vertical_sigma_m=1.0,
        identify=False,
    )


def test_gnss_aiding_bounds_position_and_estimates_gyro_bias(biased_grid):
    s = biased_grid
    rec = _record(s)
    aided = estimate_anomaly(rec, _params(True), _initial(s), "strapdown")
    free = estimate_anomaly(rec, _params(False), _initial(s), "strapdown")
    assert aided.gnss_aided and not free.gnss_aided
    # aided: attitude, gyro-bias and (by default since 2026-12-05) horizontal accelerometer-bias states
    assert aided.x_smooth.shape[1] == 16 and free.x_smooth.shape[1] == 8
    e_aided = _horizontal_error_m(s, aided)
    e_free = _horizontal_error_m(s, free)
    # 5 Hz samples of 0.5 m white noise: 0.22 m per 1 s epoch before smoothing; measured
    # RMS 0.042 m, max 0.078 m (unaided: the gyro biases rotate the solution, max 458 m)
    assert _rms(e_aided) < 0.15
    assert np.max(e_aided) < 0.3
    assert np.max(e_free) > 100.0
    # the smoother's own position sigma covers the error
    sig = np.sqrt(np.sum(aided.sigma_position_m[:, :2] ** 2, axis=1))
    assert np.mean(e_aided < 3.0 * sig) > 0.95
    # gyro biases, triad axes: observable through the solution's rotation (measured
    # 0.025, -0.020, 0.015 deg/h for 0.03, -0.02, 0.01 after 25 min; prior sigma 0.05)
    # the passes take the smoothed bias off the rates: the total is what was taken off plus
    # the last pass's state (solve.estimate_anomaly), and the last state is the small remainder
    b = aided.gyro_bias_t / DEGPH
    np.testing.assert_allclose(b, SENSORS["gyro"]["bias_degph"], atol=0.01)
    np.testing.assert_allclose(aided.gyro_bias_t - aided.x_smooth[-1, BG], aided.gyro_bias_t, atol=0.01 * DEGPH)


def test_gnss_aiding_improves_anomaly_with_gyro_biases(biased_grid):
    s = biased_grid
    rec = _record(s)
    truth = np.interp
    out = {}
    for aided in (True, False):
        sol = estimate_anomaly(rec, _params(aided), _initial(s), "strapdown")
        keep = sol.time >= 900.0
        g_true = truth(sol.time, s.truth["time"], s.truth["disturbance"])
        out[aided] = _rms((sol.g_smooth - g_true)[keep]) / MGAL
    # measured: aided 3.18 mGal, unaided 4.04 mGal (smoother, no post-processing)
    assert out[True] < 0.9 * out[False]


@pytest.mark.parametrize("field", ["seed_smooth", "seed_steps"])
def test_gnss_aiding_not_worse_on_seed_scenarios(field):
    """Seed sensor noise and a 1 m GNSS on the seed's straight line: aiding does not hurt.

    Scored at the deliverable's resolution (Gaussian low-pass, sigma 60 s ~ the seed's
    post-processed half wavelength): measured smooth 1.43 aided vs 1.49 mGal unaided.  The raw
    smoother is noise-dominated (the seed prior sigma_s = 100 mGal leaves it broadband): 4.5
    vs 4.3 mGal, the extra vertical information widening its bandwidth.
    """
    from scipy.ndimage import gaussian_filter1d

    sensors = {
        "accelerometer": {"white_sigma_mps2": 1.0e-3},
        "gravimeter": {"markov_sigma_mps2": 1.0e-6, "markov_lambda_per_s": 0.025},
        "gyro": {"white_drift_degph": 0.01},
        "altimeter": {"sigma_m": 1.0},
        "gnss": {"horizontal_sigma_m": 1.0, "vertical_sigma_m": 1.0},
    }
    s = simulate_flight(quick_sim(duration_s=5400, speed_mps=70.0, field=field, noise=sensors, seed=5))
    rec = _record(s)
    res = {}
    for aided in (True, False):
        p = InmParams(gnss_aiding=aided, gnss_horizontal_sigma_m=1.0, gnss_vertical_sigma_m=1.0, identify=False)
        sol = estimate_anomaly(rec, p, _initial(s), "platform")
        keep = (sol.time >= 600.0) & (sol.time <= sol.time[-1] - 600.0)
        g_true = np.interp(sol.time, s.truth["time"], s.truth["disturbance"])
        res[aided] = _rms((gaussian_filter1d(sol.g_smooth, 60.0) - g_true)[keep]) / MGAL
    assert res[True] <= 1.0 * res[False]


def test_gnss_params_validation():
    with pytest.raises(ConfigError, match="model.gnss_aiding: expected true or false"):
        inm_params({"gnss_aiding": 1})
    with pytest.raises(ConfigError, match=r"^model\.gnss_horizontal_sigma_m: expected a number > 0, got 0$"):
        inm_params({"gnss_horizontal_sigma_m": 0})
    p = inm_params({"gnss_aiding": False, "gnss_vertical_sigma_m": 3})
    assert p.gnss_aiding is False and p.gnss_vertical_sigma_m == 3.0


def test_no_gnss_channel_runs_the_seed_filter(biased_grid):
    s = biased_grid
    sol = estimate_anomaly(_record(s, gnss=False), _params(True), _initial(s), "strapdown")
    assert not sol.gnss_aided and sol.x_smooth.shape[1] == 8
