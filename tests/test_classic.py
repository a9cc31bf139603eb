"""The classic scalar reduction, checked against physics and the simulator's truth."""

import math

import numpy as np
import pytest

from gravsurvey import classic as cl
from gravsurvey import geodesy as gd
from gravsurvey.errors import ConfigError, DataError
from gravsurvey.io.record import AltimeterChannel, FlightRecord, GnssChannel, ImuChannel
from gravsurvey import filters as F

MGAL = 1e-5


# --------------------------------------------------------------------------
# building blocks against closed forms
# --------------------------------------------------------------------------


def test_eotvos_exact_matches_harlan_series():
    """Harlan (1968) eq. 16 is the first-order series of the exact form in f and h/a.

    Harlan uses the ground speed V of the nadir point; the aircraft's speed at height h is
    v_E = V_E (N + h)/N, v_N = V_N (M + h)/M.  Neglected terms at V <= 150 m/s, h <= 10 km:
    2 OMEGA V f h / a ~ 0.012 mGal, f^2 V^2/a ~ 0.004 mGal, (h/a)^2 terms ~ 0.001 mGal:
    bound 0.03 mGal.
    """
    rng = np.random.default_rng(7)
    n = 2000
    lat = rng.uniform(-np.pi / 2 * 0.95, np.pi / 2 * 0.95, n)
    h = rng.uniform(0.0, 10000.0, n)
    speed = rng.uniform(0.0, 150.0, n)
    track = rng.uniform(0.0, 2 * np.pi, n)
    m, nn = gd.radii_of_curvature(lat)
    ve = speed * np.sin(track) * (nn + h) / nn
    vn = speed * np.cos(track) * (m + h) / m
    exact = cl.eotvos_exact(lat, h, ve, vn)
    harlan = cl.eotvos_harlan(lat, h, speed, track)
    err = np.max(np.abs(exact - harlan)) / MGAL
    assert err < 0.03, err
    # and the terms are large: the agreement is not trivial
    assert np.max(np.abs(exact)) / MGAL > 1000.0


def test_eotvos_sign_east_vs_west():
    """Eastward flight adds to the centrifugal effect (gravimeter reads less: correction > 0)."""
    lat = np.radians(45.0)
    east = cl.eotvos_exact(lat, 1000.0, 100.0, 0.0)
    west = cl.eotvos_exact(lat, 1000.0, -100.0, 0.0)
    _, n = gd.radii_of_curvature(lat)
    assert east == pytest.approx(100.0**2 / (n + 1000.0) + 2 * gd.OMEGA_E * 100.0 * math.cos(lat), rel=1e-14)
    assert east > 0 and west < east
    # textbook: 7.503 V cos(lat) sin(track) mGal per knot -> ~1031 mGal for 100 m/s east at 45 N
    assert east / MGAL == pytest.approx(7.503 * 194.384 * math.cos(lat) + 0.004154 * 194.384**2, rel=2e-3)


def test_gaussian_fir_half_gain_at_filter_length():
    """The stated resolution: the discrete kernel's gain is 0.5 at period L (truncation ~e^-8)."""
    for length, dt in ((400.0, 1.0), (120.0, 0.1), (37.0, 1.0)):
        w = F.gaussian_fir(length, dt)
        assert w.sum() == pytest.approx(1.0, abs=1e-14)
        np.testing.assert_array_equal(w, w[::-1])
        k = (w.size - 1) // 2
        t = np.arange(-k, k + 1) * dt
        gain = np.sum(w * np.cos(2 * np.pi * t / length))
        assert gain == pytest.approx(0.5, abs=2e-3), (length, dt, gain)
        assert F.gaussian_transfer(1.0 / length, length) == pytest.approx(0.5, rel=1e-12)


def test_lowpass_is_zero_phase_and_keeps_polynomials():
    """A symmetric unit-gain kernel passes linear trends unchanged and shifts nothing."""
    dt = 1.0
    w = F.gaussian_fir(100.0, dt)
    k = (w.size - 1) // 2
    t = np.arange(2000) * dt
    lin = 3.0 + 0.01 * t
    np.testing.assert_allclose(F.lowpass_valid(lin, w), lin[k:-k], rtol=0, atol=1e-10)
    # a long sinusoid keeps its phase: peak stays put
    x = np.cos(2 * np.pi * (t - 1000.0) / 1500.0)
    y = F.lowpass_valid(x, w)
    assert np.argmax(y) + k == 1000


def test_triangle_mean_of_hdd_is_the_second_difference():
    """The decimation kernel matches the height's second difference, even for aliased motion.

    h = A sin(om t) with a 2.5 s period (aliases at 1 Hz): the triangle mean of hdd sampled at
    100 Hz equals (h(t+1) - 2h(t) + h(t-1)) within the linear-interpolation error
    ~ om^2 dt_imu^2 / 12 ~ 5e-5 relative.  A boxcar leaves a ~17 % mismatch.
    Rounding with a 9.8 m/s^2 offset over 16 h stays < 1e-12 m/s^2.
    """
    om = 2 * np.pi / 2.5
    t = np.arange(0.0, 600.0 + 1e-9, 0.01)
    hdd = -(om**2) * np.sin(om * t)
    tq = np.arange(2.0, 598.0 + 1e-9, 1.0)
    d2 = (np.sin(om * (tq + 1)) - 2 * np.sin(om * tq) + np.sin(om * (tq - 1))) / 1.0
    tri = cl.triangle_mean(t, hdd, tq, 1.0)
    assert np.max(np.abs(tri - d2)) < 1e-4 * om**2
    box = cl.interval_mean(t, hdd, tq, 1.0)
    assert np.max(np.abs(box - d2)) > 0.1 * om**2
    # long flight, gravity-sized offset: exact for linear data to rounding
    t = np.arange(0.0, 16 * 3600.0, 0.1)
    y = 9.8 + 1e-3 * (t / t[-1])
    tq = np.arange(10.0, t[-1] - 10.0, 1.0)
    np.testing.assert_allclose(cl.triangle_mean(t, y, tq, 1.0), 9.8 + 1e-3 * (tq / t[-1]), rtol=0, atol=1e-12)


def test_interval_mean_and_second_difference_are_exact():
    rng = np.random.default_rng(3)
    t = np.sort(rng.uniform(0, 100, 700))
    y = 2.0 - 0.3 * t
    tq = np.linspace(5, 95, 91)
    np.testing.assert_allclose(cl.triangle_mean(t, y, tq, 1.0), 2.0 - 0.3 * tq, atol=1e-12)
    h = 1000.0 + 2.0 * tq - 0.35 * tq**2  # hdd = -0.7 exactly
    d2 = cl.second_difference(h, 1.0)
    assert np.isnan(d2[0]) and np.isnan(d2[-1])
    np.testing.assert_allclose(d2[1:-1], -0.7, atol=1e-9)


# --------------------------------------------------------------------------
# a hand-built record: level flight along a parallel (closed-form physics)
# --------------------------------------------------------------------------


def _parallel_record(
    duration_s=3600.0, v=60.0, lat_deg=50.0, h0=2000.0, imu_hz=10.0, dist=None, heave=None, alt_noise_m=0.0, seed=0
):
    """Flight due east along a parallel; specific force from the exact kinematics.

    The longitude rate is constant, ``dlon/dt = v / ((N + h0) cos lat)``, the height
    ``h(t) = h0 + heave(t)``.  The ENU acceleration's Up component is exactly
    ``hdd - v_E^2/(N + h)`` with ``v_E = (N + h) cos(lat) dlon/dt``, and the Coriolis term's Up
    component is ``-2 OMEGA v_E cos(lat)``, so (docs/conventions.md signs)

        F_up = gamma(lat, h) + dg(t) + hdd - 2 OMEGA v_E cos(lat) - v_E^2 / (N + h)

    ``heave`` returns (h - h0, hdd) at given times.  ``alt_noise_m``: white altimeter noise.
    """
    lat = math.radians(lat_deg)
    _, n = gd.radii_of_curvature(lat)
    lon_rate = v / ((n + h0) * math.cos(lat))
    t_imu = np.arange(0.0, duration_s + 1e-9, 1.0 / imu_hz)

    def height(t):
        if heave is None:
            return np.full_like(t, h0), np.zeros_like(t)
        dh, hdd = heave(t)
        return h0 + dh, hdd

    h_imu, hdd_imu = height(t_imu)
    dg = dist(t_imu) if dist is not None else np.zeros_like(t_imu)
    ve = (n + h_imu) * math.cos(lat) * lon_rate
    gam = gd.normal_gravity(np.full_like(t_imu, lat), h_imu)
    fup = gam + dg + hdd_imu - 2 * gd.OMEGA_E * ve * math.cos(lat) - ve**2 / (n + h_imu)
    f = np.column_stack((np.zeros_like(t_imu), np.zeros_like(t_imu), fup))
    w = np.zeros_like(f)
    t1 = np.arange(0.0, duration_s + 1e-9, 1.0)
    h1, _ = height(t1)
    lon = math.radians(135.0) + lon_rate * t1
    alt = h1 + alt_noise_m * np.random.default_rng(seed).standard_normal(t1.size)
    rec = FlightRecord(
        t0_unix_ns=1_700_000_000 * 10**9,
        imu=ImuChannel(t_imu, f, w),
        altimeter=AltimeterChannel(t1, alt),
        gnss=GnssChannel(t1, np.full_like(t1, lat), lon, h1),
        source="parallel",
    )
    track = {
        "time": t1,
        "lat": np.full_like(t1, lat),
        "lon": lon,
        "vel_n": np.column_stack(((n + h1) * math.cos(lat) * lon_rate, np.zeros_like(t1), np.zeros_like(t1))),
    }
    return rec, track


def _smooth_dist(t):
    return (30 * np.sin(2 * np.pi * t / 3600) + 20 * np.sin(2 * np.pi * t / 1500 + 1)) * MGAL


def test_parallel_flight_recovers_lowpassed_disturbance():
    """Noiseless: classic = the truth through the same pre-average + FIR, to rounding (< 1e-4 mGal)."""
    rec, _ = _parallel_record(dist=_smooth_dist)
    res = cl.classic_reduction(rec, filter_length_s=200.0)
    dt = res.info["dt_s"]
    assert dt == 1.0
    w = F.gaussian_fir(200.0, dt)
    k = (w.size - 1) // 2
    # grid: triangle windows inside the IMU span (1..3599 s), minus one epoch at each end for
    # the second difference of the height
    grid = np.arange(2.0, 3598.0 + 1e-9, 1.0)
    truth_lp = F.lowpass_valid(cl.triangle_mean(rec.imu.time, _smooth_dist(rec.imu.time), grid, dt), w)
    np.testing.assert_allclose(res.time, grid[k:-k])
    err = np.max(np.abs(res.disturbance - truth_lp)) / MGAL
    assert err < 1e-4, err
    assert res.info["resolution_m"] == pytest.approx(60.0 * 200.0 / 2, rel=1e-9)
    # the Eotvos term from GNSS positions equals the closed form with the true speed
    lat = math.radians(50.0)
    _, n = gd.radii_of_curvature(lat)
    e_true = 2 * gd.OMEGA_E * 60.0 * math.cos(lat) + 60.0**2 / (n + 2000.0)
    np.testing.assert_allclose(res.terms["eotvos"], e_true, rtol=0, atol=1e-12)


def _truth_lp(rec, res, dist, length):
    """The truth through the same triangle pre-average + FIR, at the result's epochs."""
    dt = res.info["dt_s"]
    w = F.gaussian_fir(length, dt)
    k = (w.size - 1) // 2
    grid = np.arange(res.time[0] - k * dt, res.time[-1] + k * dt + 1e-9, dt)
    return F.lowpass_valid(cl.triangle_mean(rec.imu.time, dist(rec.imu.time), grid, dt), w)


def _heave(t):
    """20 m vertical oscillation, 600 s period: hdd amplitude 220 mGal."""
    om = 2 * np.pi / 600.0
    return 20.0 * np.sin(om * t), -20.0 * om**2 * np.sin(om * t)


@pytest.mark.parametrize("source", ["gnss", "altimeter"])
def test_vertical_motion_is_removed(source):
    """Kinematic acceleration of 220 mGal amplitude is removed to < 0.01 mGal.

    The triangle mean of hdd equals the second difference of h exactly; what is left is the
    linear interpolation of the 10 Hz IMU inside the triangle (relative ~om^2 dt_imu^2/12 ~ 1e-8
    of 220 mGal) and the height-dependence of the Eotvos term: bound 0.01 mGal.  The
    altimeter-only variant takes position and velocity from a navigation track instead of GNSS.
    """
    rec, track = _parallel_record(duration_s=5400.0, dist=_smooth_dist, heave=_heave)
    if source == "altimeter":
        rec = FlightRecord(rec.t0_unix_ns, rec.imu, rec.altimeter, None, source="alt-only")
        res = cl.classic_reduction(rec, filter_length_s=200.0, track=track)
        assert res.info["height_source"] == "altimeter"
    else:
        res = cl.classic_reduction(rec, filter_length_s=200.0)
        assert res.info["height_source"] == "gnss"
    assert np.max(np.abs(res.terms["kinematic"])) / MGAL > 200.0
    err = np.max(np.abs(res.disturbance - _truth_lp(rec, res, _smooth_dist, 200.0))) / MGAL
    assert err < 0.01, err


def test_height_noise_amplification_matches_formula():
    """White altimeter noise sigma_h becomes sigma_h sqrt(dt 3 / (8 sqrt(pi) s^5)) after the filter.

    The formula (module docstring) is the continuous limit of ||D2 * w|| / dt^2; checked against
    the exact discrete norm (1 %) and against the measured scatter of a noisy flight (sampling
    error ~5 % for ~180 independent filter lengths: bound 15 %).
    """
    length, dt, sig_h = 200.0, 1.0, 1.0
    s = F.SIGMA_PER_LENGTH * length
    formula = sig_h * math.sqrt(dt * 3.0 / (8.0 * math.sqrt(math.pi) * s**5))
    w = F.gaussian_fir(length, dt)
    c = np.convolve(w, [1.0, -2.0, 1.0]) / dt**2
    exact = sig_h * math.sqrt(np.sum(c**2))
    assert exact == pytest.approx(formula, rel=0.01)
    rec, track = _parallel_record(duration_s=20000.0, imu_hz=1.0, alt_noise_m=sig_h, seed=11)
    rec = FlightRecord(rec.t0_unix_ns, rec.imu, rec.altimeter, None, source="noisy")
    res = cl.classic_reduction(rec, filter_length_s=length, track=track)
    measured = np.std(res.disturbance)
    assert measured == pytest.approx(formula, rel=0.15), (measured / MGAL, formula / MGAL)
    assert formula / MGAL > 5.0  # the noise is large: the check is not vacuous


def test_resolution_sets_filter_length():
    rec, _ = _parallel_record(duration_s=2400.0)
    res = cl.classic_reduction(rec, resolution_m=6000.0)
    assert res.info["filter_length_s"] == pytest.approx(2 * 6000.0 / 60.0, rel=1e-9)
    assert res.info["resolution_m"] == pytest.approx(6000.0, rel=1e-9)


def test_errors_name_the_problem():
    rec, _ = _parallel_record(duration_s=1200.0)
    with pytest.raises(ConfigError, match="strapdown"):
        cl.classic_reduction(rec, triad="strapdown")
    with pytest.raises(DataError, match="mat_nt"):
        cl.classic_reduction(rec, mat_nt=np.zeros((5, 3, 3)))
    with pytest.raises(ConfigError, match="not both"):
        cl.classic_reduction(rec, filter_length_s=100.0, resolution_m=3000.0)
    with pytest.raises(DataError, match="too short"):
        cl.classic_reduction(rec, filter_length_s=2000.0)
    nognss = FlightRecord(rec.t0_unix_ns, rec.imu, rec.altimeter, None, source="x.mcap")
    with pytest.raises(DataError, match="x.mcap: classic needs a horizontal track"):
        cl.classic_reduction(nognss)
    with pytest.raises(DataError, match="no GNSS"):
        cl.classic_reduction(nognss, height_source="gnss")


def test_non_finite_heights_are_dropped_and_noted():
    """A few NaN altimeter samples are interpolated over (cubic spline), not propagated."""
    rec, track = _parallel_record(duration_s=2400.0, dist=_smooth_dist, heave=_heave)
    h = rec.altimeter.height.copy()
    h[[500, 501, 1300]] = np.nan
    rec = FlightRecord(rec.t0_unix_ns, rec.imu, AltimeterChannel(rec.altimeter.time, h), None, source="nan")
    with pytest.warns(Warning, match="gaps"):
        res = cl.classic_reduction(rec, filter_length_s=200.0, track=track)
    assert np.all(np.isfinite(res.disturbance))
    assert any("3 non-finite heights dropped" in n for n in res.info["notes"])
    # spline interpolation of a 600 s heave across 2 s holes: error far below the signal
    err = np.max(np.abs(res.disturbance - _truth_lp(rec, res, _smooth_dist, 200.0))) / MGAL
    assert err < 0.05, err


# --------------------------------------------------------------------------
# against the simulator's truth (independent physics: 3D kinematics, rotating Earth)
# --------------------------------------------------------------------------


def _record_from_sim(sim):
    return FlightRecord(
        t0_unix_ns=int(sim.start_unix_ns),
        imu=ImuChannel(sim.imu_time, sim.specific_force_t, sim.angular_rate_t),
        altimeter=AltimeterChannel(sim.alt_time, sim.alt_height),
        gnss=GnssChannel(sim.gnss_time, np.radians(sim.gnss_lat_deg), np.radians(sim.gnss_lon_deg), sim.gnss_height),
        source="sim",
    )


def _truth_lp_sim(sim, res, length):
    dt = res.info["dt_s"]
    w = F.gaussian_fir(length, dt)
    k = (w.size - 1) // 2
    grid = np.arange(res.time[0] - k * dt, res.time[-1] + k * dt + 1e-9 * dt, dt)
    assert grid.size == res.time.size + 2 * k
    return F.lowpass_valid(cl.triangle_mean(sim.truth["time"], sim.truth["disturbance"], grid, dt), w)


def test_simulated_level_flight_gives_lowpassed_truth():
    """Noiseless level flight due east (simulator): classic = truth through the same filter.

    Remaining error sources are numerical: the Eotvos velocity from 1 Hz GNSS positions by
    central differences (exact for a constant-rate longitude) and the Up component of normal
    gravity vs its magnitude (< 1e-9 m/s^2): bound 1e-3 mGal.
    """
    from gravsurvey.simulate.run import quick_sim, simulate_flight

    sim = simulate_flight(quick_sim(duration_s=3600.0, field="seed_smooth", speed_mps=50.0))
    res = cl.classic_reduction(_record_from_sim(sim), filter_length_s=300.0)
    truth = _truth_lp_sim(sim, res, 300.0)
    err = np.max(np.abs(res.disturbance - truth)) / MGAL
    assert err < 1e-3, err
    assert np.ptp(truth) / MGAL > 50.0  # a real signal was recovered

    # the Eotvos term from GNSS positions against the closed form with the true velocity
    i = np.searchsorted(sim.truth["time"], res.time)
    lat, h = sim.truth["lat"][i], sim.truth["height"][i]
    ve = sim.truth["vel_n"][i, 0]
    _, n = gd.radii_of_curvature(lat)
    e_formula = 2 * gd.OMEGA_E * ve * np.cos(lat) + ve**2 / (n + h)
    assert np.max(np.abs(res.terms["eotvos"] - e_formula)) / MGAL < 1e-4
    assert np.mean(res.terms["eotvos"]) / MGAL == pytest.approx(
        7.503 * 50 * 1.94384 * math.cos(math.radians(45.0)) + 0.004154 * (50 * 1.94384) ** 2, rel=3e-3
    )


def test_sign_over_excess_mass_is_positive():
    """A buried point mass under the track: classic disturbance peaks positive over it."""
    from gravsurvey.simulate.run import quick_sim, simulate_flight

    field = {
        "type": "model",
        "point_masses": [{"lat_deg": 45.0, "lon_deg": 135.5, "depth_m": 3000.0, "mass_kg": 5.0e12}],
    }
    sim = simulate_flight(quick_sim(duration_s=4000.0, field=field, speed_mps=50.0))
    res = cl.classic_reduction(_record_from_sim(sim), filter_length_s=200.0)
    truth = _truth_lp_sim(sim, res, 200.0)
    k = np.argmax(res.disturbance)
    assert res.disturbance[k] > 1.0 * MGAL
    # the peak sits over the mass (the longitude of the peak within one sample's travel)
    assert abs(np.degrees(res.lon[k]) - 135.5) < 50.0 / (6.4e6 * math.cos(math.radians(45))) * 180 / math.pi * 2
    assert np.max(np.abs(res.disturbance - truth)) / MGAL < 1e-3


def test_strapdown_with_turbulence_matches_platform_truth():
    """Strapdown triad through turbulence (roll/pitch/heave), attitude from truth mat_nt.

    Heave and attitude motion are large (vertical acceleration > 100 mGal); the triangle
    pre-average cancels it with the height's second difference even though turbulence periods
    down to 2 s alias at the 1 Hz height rate.  Left: the Eotvos term from 1 Hz positions with
    3 m horizontal turbulence (point samples of v^2 terms, ~0.006 mGal measured after the
    filter): bound 0.02 mGal.
    """
    from gravsurvey.simulate.run import quick_sim, simulate_flight

    turb = {"vertical_sigma_m": 5.0, "horizontal_sigma_m": 3.0, "attitude_sigma_deg": 2.0}
    sim = simulate_flight(
        quick_sim(duration_s=3000.0, field="seed_smooth", triad="strapdown", turbulence=turb, imu_hz=20.0)
    )
    rec = _record_from_sim(sim)
    with pytest.raises(ConfigError):
        cl.classic_reduction(rec, triad="strapdown", filter_length_s=300.0)
    res = cl.classic_reduction(rec, triad="strapdown", mat_nt=sim.truth["mat_nt"], filter_length_s=300.0)
    truth = _truth_lp_sim(sim, res, 300.0)
    err = np.max(np.abs(res.disturbance - truth)) / MGAL
    assert err < 0.02, err
    # without the attitude the tilt leaks straight in: the triad's z is not Up
    naive = cl.classic_reduction(rec, filter_length_s=300.0)
    assert np.max(np.abs(naive.disturbance - truth)) / MGAL > 10 * err
    assert np.max(np.abs(res.terms["kinematic"])) / MGAL > 100.0


def test_strapdown_attitude_from_mechanization():
    """The mechanized attitude (noiseless gyros, true initial state) matches the truth, and
    classic with it matches classic with the true attitude to < 0.01 mGal.

    A tilt error e leaks as f_h e + g e^2 / 2 into f_up: for 1e-5 rad that is < 0.01 mGal at
    the ~1 m/s^2 horizontal accelerations of this turbulence.
    """
    from gravsurvey.inm.params import InitialState
    from gravsurvey.simulate.run import quick_sim, simulate_flight

    turb = {"vertical_sigma_m": 2.0, "horizontal_sigma_m": 2.0, "attitude_sigma_deg": 1.0}
    sim = simulate_flight(quick_sim(duration_s=1500.0, field="seed_smooth", triad="strapdown", turbulence=turb))
    rec = _record_from_sim(sim)
    tr = sim.truth
    init = InitialState(
        lat=tr["lat"][0], lon=tr["lon"][0], height=tr["height"][0], vel_n=tr["vel_n"][0], mat_nt=tr["mat_nt"][0]
    )
    mat = cl.strapdown_attitude(rec, init)
    # angle of mat^T truth
    rel = np.einsum("nji,njk->nik", mat, tr["mat_nt"])
    ang = np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1, 1))
    assert np.max(ang) < 1e-5, np.max(ang)
    a = cl.classic_reduction(rec, triad="strapdown", mat_nt=mat, filter_length_s=300.0)
    b = cl.classic_reduction(rec, triad="strapdown", mat_nt=tr["mat_nt"], filter_length_s=300.0)
    assert np.max(np.abs(a.disturbance - b.disturbance)) / MGAL < 0.01
