"""3D-INM estimator against the simulator's truth (gravsurvey.simulate is used only here)."""

import math

import numpy as np
import pytest

from gravsurvey.geodesy import MGAL, geodetic_to_ecef, radii_of_curvature
from gravsurvey.inm.params import InitialState, InmParams, initial_state_from_gnss
from gravsurvey.inm.solve import estimate_anomaly
from gravsurvey.io.record import AltimeterChannel, FlightRecord, GnssChannel, ImuChannel
from gravsurvey.simulate.run import quick_sim, simulate_flight

#: Schuler frequency at 1000 m, rad/s (w0^2 = g/R).
W0 = math.sqrt(9.806 / 6.372e6)

#: Filter settings matched to noiseless data: tiny but non-zero noise everywhere.
# the filter's physics under a KNOWN model: identification from the data is off here
# (it is tested in test_inm_identify.py)
TINY = dict(
    accel_noise_mps2=1e-7,
    gyro_drift_degph=1e-5,
    gravimeter_sigma_mps2=1e-8,
    altimeter_sigma_m=1e-4,
    initial_position_sigma_m=1.0,
    initial_velocity_sigma_mps=1e-3,
    identify=False,
)

GRID = {
    "kind": "grid",
    "origin_lat_deg": 45.0,
    "origin_lon_deg": 135.0,
    "altitude_m": 1000.0,
    "speed_mps": 50.0,
    "lines": {"count": 3, "spacing_m": 3000.0, "length_m": 30000.0, "heading_deg": 90.0},
}
TURB = {"vertical_sigma_m": 2.0, "horizontal_sigma_m": 2.0, "attitude_sigma_deg": 1.0}


def record_of(s, gnss=False):
    g = None
    if gnss:
        g = GnssChannel(s.gnss_time, np.radians(s.gnss_lat_deg), np.radians(s.gnss_lon_deg), s.gnss_height)
    return FlightRecord(
        s.start_unix_ns,
        ImuChannel(s.imu_time, s.specific_force_t, s.angular_rate_t),
        AltimeterChannel(s.alt_time, s.alt_height),
        g,
        source="sim",
    )


def initial_of(s):
    tr = s.truth
    return InitialState(tr["lat"][0], tr["lon"][0], tr["height"][0], tr["vel_n"][0].copy(), tr["mat_nt"][0].copy())


def truth_at(s, t, key="disturbance"):
    return np.interp(t, s.truth["time"], s.truth[key])


def rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


def mid(sol, margin=600.0):
    return (sol.time >= sol.time[0] + margin) & (sol.time <= sol.time[-1] - margin)


@pytest.fixture(scope="module")
def smooth_platform():
    s = simulate_flight(quick_sim(duration_s=3600, field="seed_smooth"))
    return s, estimate_anomaly(record_of(s), InmParams(**TINY), initial_of(s), "platform")


def test_noiseless_known_field_recovered(smooth_platform):
    s, sol = smooth_platform
    err = sol.g_smooth - truth_at(s, sol.time)
    keep = sol.time >= 600.0
    # measured 0.003 mGal RMS; the issue asks < 0.1 mGal after the first 10 minutes
    assert rms(err[keep]) < 0.1 * MGAL
    # the sign convention: positive disturbance = stronger gravity, like the truth
    assert np.corrcoef(sol.g_smooth[keep], truth_at(s, sol.time)[keep])[0, 1] > 0.999


def test_strapdown_matches_platform_through_turns_and_turbulence():
    sols = {}
    for triad in ("platform", "strapdown"):
        s = simulate_flight(quick_sim(plan=GRID, field="seed_smooth", triad=triad, turbulence=TURB))
        sols[triad] = estimate_anomaly(record_of(s), InmParams(**TINY), initial_of(s), triad)
        assert np.degrees(np.abs(s.truth["roll"]).max()) > 20.0  # the flight really banks
        assert np.any(s.truth["line"] == "turn")
        keep = sols[triad].time >= 600.0
        assert rms((sols[triad].g_smooth - truth_at(s, sols[triad].time))[keep]) < 0.1 * MGAL
    d = sols["platform"].g_smooth - sols["strapdown"].g_smooth
    assert rms(d[sols["platform"].time >= 600.0]) < 0.2 * MGAL


def test_zero_anomaly_zero_noise_navigation_stays_on_truth():
    """Bounds derived from the anomaly requirement (< 0.05 mGal RMS):

    a horizontal position error dx tilts the modelled gravitation by w0^2 dx,
    a height error dh changes it by the free-air gradient 2 w0^2 dh; keeping
    both below 0.05 mGal needs dx < 0.05 mGal / w0^2 = 0.33 m and
    dh < 0.05 mGal / (2 w0^2) = 0.16 m.
    """
    s = simulate_flight(quick_sim(duration_s=3600, plan=None, triad="strapdown"))
    sol = estimate_anomaly(record_of(s), InmParams(**TINY), initial_of(s), "strapdown")
    assert rms(sol.g_smooth) < 0.05 * MGAL
    assert rms(sol.g_forward[sol.time >= 600.0]) < 0.05 * MGAL
    m_rad, n_rad = radii_of_curvature(45.0 * math.pi / 180.0)
    de = (sol.lon - truth_at(s, sol.time, "lon")) * (n_rad + 1000.0) * math.cos(math.radians(45.0))
    dn = (sol.lat - truth_at(s, sol.time, "lat")) * (m_rad + 1000.0)
    dh = sol.height - truth_at(s, sol.time, "height")
    dx_bound = 0.05 * MGAL / W0**2
    dh_bound = 0.05 * MGAL / (2 * W0**2)
    assert dx_bound == pytest.approx(0.33, abs=0.01) and dh_bound == pytest.approx(0.16, abs=0.01)
    assert np.max(np.hypot(de, dn)) < dx_bound
    assert np.max(np.abs(dh)) < dh_bound


@pytest.fixture(scope="module")
def markov_runs():
    """The seed's first experiment: anomaly drawn from the filter's own model, seed noise."""
    field = {"type": "markov", "lambda_s_per_m": 1e-5, "sigma_mps2": 1e-3}
    out = []
    for seed in (1, 2):
        s = simulate_flight(quick_sim(duration_s=7200, field=field, noise=True, seed=seed))
        # the filter's own (seed) model, as the anomaly was drawn from it
        out.append((s, estimate_anomaly(record_of(s), InmParams(identify=False), initial_of(s), "platform")))
    return out


def test_consistency_normalised_errors(markov_runs):
    for s, sol in markov_runs:
        truth = truth_at(s, sol.time)
        m = mid(sol)
        nf = rms((sol.g_forward - truth)[m] / sol.sigma_forward[m])
        ns = rms((sol.g_smooth - truth)[m] / sol.sigma_smooth[m])
        assert 0.7 <= nf <= 1.5, nf
        assert 0.7 <= ns <= 1.5, ns
        # the smoother must beat the forward filter
        assert rms((sol.g_smooth - truth)[m]) < 0.7 * rms((sol.g_forward - truth)[m])


def test_innovations_white(markov_runs):
    for _, sol in markov_runs:
        nu = sol.innovations_normalised
        nu = nu[np.isfinite(nu)][60:]  # skip the initial transient (1 min)
        n = nu.size
        assert abs(np.std(nu) - 1.0) < 0.1
        nu = nu - nu.mean()
        ac = np.array([np.dot(nu[:-k], nu[k:]) / np.dot(nu, nu) for k in range(1, 11)])
        assert np.all(np.abs(ac) < 3.0 / math.sqrt(n)), ac


def test_georeferencing_with_gnss_grade_initial_errors():
    """1 h, noiseless sensors, initial state off by GNSS-grade errors.

    Schuler error propagation (horizontal channel, external radius makes the
    vertical one a Schuler oscillator too): dx(t) = dx0 cos(w0 t) +
    dv0/w0 sin(w0 t), so |dx| <= |dx0| + |dv0|/w0 in every channel; the
    Earth-rate (Foucault) coupling only rotates this error.  We add 2 %
    for the ellipsoid/latitude approximation of w0.
    """
    s = simulate_flight(quick_sim(duration_s=3600))
    init = initial_of(s)
    m_rad, n_rad = radii_of_curvature(init.lat)
    dx0 = np.array([0.5, -0.4, 0.0])  # m, E N U
    dv0 = np.array([0.01, 0.015, 0.0])  # m/s
    init.lat += dx0[1] / (m_rad + init.height)
    init.lon += dx0[0] / ((n_rad + init.height) * math.cos(init.lat))
    init.vel_n = init.vel_n + dv0
    sol = estimate_anomaly(record_of(s), InmParams(**TINY), init, "platform")
    de = (sol.lon - truth_at(s, sol.time, "lon")) * (n_rad + 1000.0) * math.cos(init.lat)
    dn = (sol.lat - truth_at(s, sol.time, "lat")) * (m_rad + 1000.0)
    bound = (np.linalg.norm(dx0) + np.linalg.norm(dv0) / W0) * 1.02
    err = np.hypot(de, dn)
    assert bound == pytest.approx(15.0, abs=0.5)
    assert np.max(err) < bound
    # the error really is Schuler-like (not zero): it reaches a good part of the bound
    assert np.max(err) > 0.3 * bound
    # height is pinned by the altimeter
    assert np.max(np.abs(sol.height - truth_at(s, sol.time, "height"))) < 0.16


def test_georeferencing_with_seed_noise_within_filter_sigma(markov_runs):
    """Horizontal errors with seed sensor noise stay within 4 sigma of the smoother's position sigma."""
    for s, sol in markov_runs:
        m_rad, n_rad = radii_of_curvature(sol.lat)
        de = (sol.lon - truth_at(s, sol.time, "lon")) * (n_rad + sol.height) * np.cos(sol.lat)
        dn = (sol.lat - truth_at(s, sol.time, "lat")) * (m_rad + sol.height)
        sig = np.hypot(sol.sigma_position_m[:, 0], sol.sigma_position_m[:, 1])
        assert np.all(np.hypot(de, dn) < 4.0 * sig + 1.0)
        assert np.max(np.abs(sol.height - truth_at(s, sol.time, "height"))) < 4.0 * np.max(sol.sigma_position_m[:, 2])


def test_initial_state_from_noiseless_gnss():
    s = simulate_flight(quick_sim(duration_s=120))
    st = initial_state_from_gnss(record_of(s, gnss=True), "platform")
    tr = s.truth
    r = geodetic_to_ecef(st.lat, st.lon, st.height)
    r0 = geodetic_to_ecef(tr["lat"][0], tr["lon"][0], tr["height"][0])
    assert np.linalg.norm(r - r0) < 1e-3
    assert np.max(np.abs(st.vel_n - tr["vel_n"][0])) < 1e-3
    np.testing.assert_array_equal(st.mat_nt, np.eye(3))


@pytest.mark.parametrize("filter_hz,alt_hz", [(2.0, 1.0), (1.0, 5.0)])
def test_other_filter_and_altimeter_rates(filter_hz, alt_hz):
    """Epochs without altimeter data are pure predictions; several samples per epoch are stacked."""
    s = simulate_flight(quick_sim(duration_s=1800, field="seed_smooth", altimeter_hz=alt_hz))
    p = InmParams(**{**TINY, "filter_rate_hz": filter_hz})
    sol = estimate_anomaly(record_of(s), p, initial_of(s), "platform")
    assert np.median(np.diff(sol.time)) == pytest.approx(1.0 / filter_hz)
    keep = (sol.time >= 600.0) & (sol.time <= sol.time[-1] - 30.0)
    assert rms((sol.g_smooth - truth_at(s, sol.time))[keep]) < 0.1 * MGAL
    nu = np.asarray(sol.innovations_normalised)
    if filter_hz > alt_hz:
        assert np.isnan(nu).sum() == pytest.approx(nu.size / 2, abs=2)
    else:
        assert nu.shape == (sol.time.size, int(alt_hz / filter_hz))


def test_gnss_initialisation_and_bad_records():
    from gravsurvey.errors import ConfigError, DataError

    s = simulate_flight(quick_sim(duration_s=900, field="seed_smooth"))
    rec = record_of(s, gnss=True)
    sol = estimate_anomaly(rec, InmParams(**TINY), None, "platform")
    ref = estimate_anomaly(rec, InmParams(**TINY), initial_of(s), "platform")
    keep = sol.time >= 300.0
    assert rms((sol.g_smooth - ref.g_smooth)[keep]) < 0.05 * MGAL
    # issue 13: a strapdown triad without an attitude is aligned from the data; this ENU platform
    # record read as a body triad is level with its x axis (the "nose") east
    sd = estimate_anomaly(rec, InmParams(**TINY), None, "strapdown")
    assert sd.alignment is not None
    np.testing.assert_allclose(np.degrees(sd.attitude[0]), [0.0, 0.0, 90.0], atol=0.05)
    with pytest.raises(ConfigError, match="triad"):
        estimate_anomaly(rec, InmParams(), initial_of(s), "gimbal")
    bad = record_of(s)
    bad.altimeter = AltimeterChannel(np.array([]), np.array([]))
    with pytest.raises(DataError, match="altimeter: no samples"):
        estimate_anomaly(bad, InmParams(), initial_of(s), "platform")
    bad = record_of(s)
    bad.imu.specific_force_t = bad.imu.specific_force_t[:, :2]
    with pytest.raises(DataError, match=r"imu.specific_force_t: expected shape"):
        estimate_anomaly(bad, InmParams(), initial_of(s), "platform")
    bad = record_of(s)
    bad.imu.angular_rate_t = bad.imu.angular_rate_t.copy()
    bad.imu.angular_rate_t[5, 1] = np.nan
    with pytest.raises(DataError, match=r"imu.angular_rate_t: non-finite"):
        estimate_anomaly(bad, InmParams(), initial_of(s), "platform")
