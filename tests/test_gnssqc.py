"""Late GNSS stamps and an antenna off the IMU (gravsurvey/inm/gnssqc.py): the latency is the
slope of the aided track's high-passed residual on the velocity, the lever arm its fit on the
attitude; found on simulated flights, taken off before the estimate, and none is found where
there is none."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest

import gravsurvey.inm.solve as solve
from gravsurvey.estimate import from_inm_solution
from gravsurvey.geodesy import STANDARD_GRAVITY_MPS2
from gravsurvey.inm import gnssqc
from gravsurvey.inm.params import InmParams
from gravsurvey.inm.solve import estimate_anomaly
from gravsurvey.io.record import AltimeterChannel, GnssChannel
from gravsurvey.simulate.run import quick_sim, simulate_flight

from sim_record import record_and_initial
from test_inm_gnss import GRID
from test_inm_identify import NAVIGATION_GRADE, rms_mid


def _turning_velocity(t, rng):
    """East/north velocity of a 70 m/s flight: turns of 180 deg every 300 s and surges, (k, 2)."""
    heading = np.pi * np.clip((t % 300.0 - 240.0) / 60.0, 0.0, 1.0) + np.pi * (t // 300.0)
    speed = 70.0 + sum(0.5 * np.sin(2 * np.pi * t / p + rng.uniform(0, 6)) for p in (4.0, 9.0, 17.0, 40.0))
    return np.stack([speed * np.sin(heading), speed * np.cos(heading)], axis=1)


@pytest.mark.parametrize("latency", [0.0, 0.1, -0.25])
def test_latency_is_the_slope_of_the_horizontal_residual_on_the_velocity(latency):
    rng = np.random.default_rng(7)
    t = np.arange(0.0, 1800.0, 0.2)
    v = _turning_velocity(t, rng)
    # the smoothed track's slow error (metres over minutes) and 0.3 m of GNSS noise
    slow = np.stack([3.0 * np.sin(2 * np.pi * t / 900.0), 2.0 * (t / 1800.0) ** 2], axis=1)
    res = slow + latency * v + 0.3 * rng.standard_normal(v.shape)
    got, sigma = gnssqc.estimate_gnss_latency(t, res, v)
    assert sigma < 0.005 and abs(got - latency) < 4 * sigma + 2e-3
    assert gnssqc.latency_is_clear(got, sigma) == (latency != 0.0)
    # straight and steady: nothing to regress on, no verdict
    got, sigma = gnssqc.estimate_gnss_latency(t, slow, np.full((t.size, 2), 50.0))
    assert np.isnan(got) and not gnssqc.latency_is_clear(got, sigma)


def test_gnss_outliers_do_not_make_a_latency():
    """Fixes 30 m off on 0.3 % of the epochs (multipath, a wrong ambiguity) on a straight line
    flown in turbulence: left out of a second fit, no latency is read into them."""
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 1800.0, 0.2)
    surge = sum(0.3 * np.sin(2 * np.pi * t / p + rng.uniform(0, 6)) for p in (3.0, 6.0, 11.0))
    v = np.stack([70.0 + surge, 0.5 * surge], axis=1)
    res = 0.1 * rng.standard_normal(v.shape)
    bad = np.flatnonzero(rng.random(t.size) < 0.003)
    # where the aircraft surges (a fix is more often lost in a manoeuvre)
    res[bad, 0] += 30.0 * np.sign(surge[bad])
    got, sigma = gnssqc.estimate_gnss_latency(t, res, v)
    assert abs(got) < 4 * sigma + 2e-3 and not gnssqc.latency_is_clear(got, sigma)


def test_a_drifting_latency_is_its_middle_and_its_rate():
    """A clock running 150 ppm slow: the latency at the middle and its change per second."""
    rng = np.random.default_rng(9)
    t = np.arange(0.0, 3600.0, 0.2)
    v = _turning_velocity(t, rng)
    lat = 0.05 + 150e-6 * (t - 1800.0)
    res = 2.0 * np.sin(2 * np.pi * t[:, None] / 1200.0) + lat[:, None] * v + 0.3 * rng.standard_normal(v.shape)
    fit = gnssqc.gnss_latency_fit(t, res, v)
    assert abs(fit.mid_latency_s - 0.05) < 4 * fit.mid_sigma_s + 2e-3
    assert abs(fit.rate - 150e-6) < 4 * fit.rate_sigma + 2e-6
    assert fit.drifts and fit.taken_off
    shifted = fit.shift(GnssChannel(t, np.zeros(t.size), np.zeros(t.size), np.zeros(t.size)))
    np.testing.assert_allclose(shifted.time, t - lat, atol=0.01)
    assert fit.report()["drift_taken_off"] and fit.report()["drift_ppm"] == pytest.approx(150.0, abs=10.0)
    assert "ppm" in fit.text() and "a clock running slow" in fit.text()
    # a constant latency is not read as a drift
    res = 2.0 * np.sin(2 * np.pi * t[:, None] / 1200.0) + 0.05 * v + 0.3 * rng.standard_normal(v.shape)
    fit = gnssqc.gnss_latency_fit(t, res, v)
    assert fit.taken_off and not fit.drifts


def test_latency_verdict_bounds():
    assert not gnssqc.latency_is_clear(0.015, 0.001)  # under LATENCY_MIN_S
    assert not gnssqc.latency_is_clear(0.1, 0.03)  # within LATENCY_K standard errors
    assert gnssqc.latency_is_clear(-0.1, 0.01)
    assert not gnssqc.latency_is_clear(1.5, 0.01)  # the clock check's, not a latency
    g = GnssChannel(np.arange(5.0), np.zeros(5), np.zeros(5), np.zeros(5))
    shifted = gnssqc.shift_gnss(g, 0.2)
    np.testing.assert_allclose(shifted.time, np.arange(5.0) - 0.2)
    np.testing.assert_array_equal(g.time, np.arange(5.0))  # the record's channel is not touched
    assert shifted.lat is g.lat


def _turning_grid(triad, noise):
    """A 25 min grid (three 25-km lines, two turns) in turbulence, 5-Hz GNSS and heights: the
    simulated flight, its record and initial state."""
    sim = quick_sim(
        plan={**GRID, "lines": {**GRID["lines"], "heading_deg": 30.0}},
        triad=triad,
        noise={**NAVIGATION_GRADE, **noise},
        field="seed_smooth",
        gnss_hz=5.0,
        altimeter_hz=5.0,
        turbulence={"vertical_sigma_m": 1.0, "horizontal_sigma_m": 1.0, "attitude_sigma_deg": 0.5},
        seed=11,
    )
    s = simulate_flight(sim)
    return (s, *record_and_initial(s))


@pytest.fixture(scope="module")
def turning_strapdown():
    """25 min strapdown grid in turbulence, 5 Hz GNSS with 0.3 m of noise: the estimator is
    told none of it."""
    return _turning_grid(
        "strapdown",
        {"gyro": {"white_drift_degph": 0.005}, "gnss": {"horizontal_sigma_m": 0.3, "vertical_sigma_m": 0.6}},
    )


def test_late_gnss_stamps_are_taken_off_before_the_estimate(turning_strapdown, monkeypatch):
    """GNSS stamped 0.2 s late (a logger's receive time): found to a few ms, taken off, the
    estimate as with the right stamps; left in, the same flight is clearly worse. The clean
    flight has none."""
    s, rec, init = turning_strapdown
    clean = estimate_anomaly(rec, InmParams(), init, "strapdown")
    assert not clean.identification["gnss_latency"]["taken_off"]
    assert abs(clean.identification["gnss_latency"]["latency_s"]) < gnssqc.LATENCY_MIN_S
    late = dataclasses.replace(rec, gnss=dataclasses.replace(rec.gnss, time=rec.gnss.time + 0.2))
    sol = estimate_anomaly(late, InmParams(), init, "strapdown")
    facts = sol.identification["gnss_latency"]
    assert facts["taken_off"]
    assert facts["latency_s"] == pytest.approx(0.2, abs=max(4 * facts["sigma_s"], 0.01))
    assert any(
        re.search(r"gnss: stamps \+0\.(19|20)\d s", n) and "late against the IMU" in n
        for n in from_inm_solution(sol, name="F01").notes
    )
    assert rms_mid(sol, s) < 1.1 * rms_mid(clean, s)
    monkeypatch.setattr(gnssqc.GnssLatency, "taken_off", property(lambda self: False))
    # the antenna declared at the IMU: at constant speed a latency is a forward lever arm, which
    # the lever-arm fit would otherwise find (14 m) and take off instead
    left = estimate_anomaly(late, InmParams(), init, "strapdown", gnss_lever_arm_t=np.zeros(3))
    assert rms_mid(left, s) > 1.5 * rms_mid(sol, s)


def test_a_clock_running_slow_is_taken_off_gnss_and_heights(turning_strapdown, monkeypatch):
    """GNSS and heights on a clock 300 ppm slow against the IMU (0.23 s apart at the ends of 25
    min): both drifts found and taken off, the estimate near the one with the right stamps
    (measured 0.55 against 0.48 mGal, both with the accelerometer noise the likelihood chooses,
    5e-4 m/s^2, the simulated one; 0.47 against 0.45 with the default 1e-3); with constant
    latencies only, 2.66 until the heights' wander was identified, 0.93 since (the drifting
    stamps' height error fitted as a wander), and since the anomaly prior is chosen again on
    its own estimate where passes follow the smoothed attitude (the track's misfit takes a
    10-deg/h gyro there), 0.64 mGal smoothed to 63 km against 4.8."""
    s, rec, init = turning_strapdown
    clean = estimate_anomaly(rec, InmParams(), init, "strapdown")
    t0 = rec.imu.time[0]

    def slow(ch):
        return dataclasses.replace(ch, time=ch.time + 300e-6 * (ch.time - t0))

    late = dataclasses.replace(rec, gnss=slow(rec.gnss), altimeter=slow(rec.altimeter))
    sol = estimate_anomaly(late, InmParams(), init, "strapdown")
    g = sol.identification["gnss_latency"]
    h = sol.identification["height_faults"]
    assert g["drift_taken_off"] and g["drift_ppm"] == pytest.approx(300.0, abs=max(4 * g["drift_sigma_ppm"], 20.0))
    # the heights' regression reads 269 ppm (+-6), 10 % low: it is linear in the latency (a
    # constant 0.3 s reads as 0.28 s, docs/method.md "GNSS latency"); 289 before 2026-12-05, when
    # the record's ends, where the high-pass is one-sided, were in it
    assert h["drift_ppm"] == pytest.approx(300.0, abs=max(4 * h["drift_sigma_ppm"], 35.0))
    notes = from_inm_solution(sol, name="F01").notes
    assert sum("ppm" in n and "running slow" in n for n in notes) == 2
    assert sol.params.accel_noise_mps2 == clean.params.accel_noise_mps2
    assert rms_mid(sol, s) < 1.2 * rms_mid(clean, s)
    monkeypatch.setattr(solve, "LATENCY_DRIFT_MIN_S", float("inf"))
    monkeypatch.setattr(gnssqc.GnssLatency, "drifts", property(lambda self: False))
    constant = estimate_anomaly(late, InmParams(), init, "strapdown")
    assert constant.identification["height_walk"]["applied"]
    assert rms_mid(constant, s) > 1.1 * rms_mid(sol, s) and constant.resolution_m > 5.0 * sol.resolution_m


def _turning_attitude(t):
    """Triad (FLU) -> ENU of a flight turning 180 deg every 300 s in 60 s, banked 25 deg in the
    turns, (k, 3, 3)."""
    frac = np.clip((t % 300.0 - 240.0) / 60.0, 0.0, 1.0)
    psi = np.pi * frac + np.pi * (t // 300.0)
    phi = np.radians(25.0) * np.sin(np.pi * frac)
    fwd = np.stack([np.sin(psi), np.cos(psi), 0 * psi], axis=1)
    left = np.stack([-np.cos(psi), np.sin(psi), 0 * psi], axis=1)
    up = np.tile([0.0, 0.0, 1.0], (t.size, 1))
    c, s = np.cos(phi)[:, None], np.sin(phi)[:, None]
    return np.stack([fwd, c * left + s * up, -s * left + c * up], axis=2)


@pytest.mark.parametrize("arm", [(0.0, 0.0, 0.0), (1.0, -1.0, 2.0)])
def test_lever_arm_is_the_fit_of_the_residual_on_the_attitude(arm):
    """An antenna at ``arm`` (FLU, m): the navigation minus the GNSS is ``-C arm`` on top of the
    track's slow error, 0.3 m of noise and a few fixes 30 m off; found within its standard error,
    applied only when there is one (:class:`gnssqc.GnssLeverArm`)."""
    rng = np.random.default_rng(11)
    t = np.arange(0.0, 3600.0, 0.2)
    c = _turning_attitude(t)
    slow = np.stack([3.0 * np.sin(2 * np.pi * t / 900.0), 2.0 * (t / 3600.0) ** 2, np.cos(2 * np.pi * t / 1300.0)], 1)
    res = slow - np.einsum("kij,j->ki", c, np.asarray(arm)) + 0.3 * rng.standard_normal((t.size, 3))
    bad = np.flatnonzero(rng.random(t.size) < 0.003)
    res[bad, 0] += 30.0
    lever, sigma = gnssqc.estimate_gnss_lever_arm(t, res, c)
    assert np.all(sigma < 0.25) and np.all(np.abs(lever - arm) < 4 * sigma + 0.02)
    fit = gnssqc.GnssLeverArm(lever, sigma)
    np.testing.assert_array_equal(fit.clear_t != 0.0, np.abs(arm) > 0.0)
    # the horizontal only (GNSS heights used as the height channel): the up component is seen
    # in the banks
    lever2, sigma2 = gnssqc.estimate_gnss_lever_arm(t, res[:, :2], c)
    assert np.all(np.abs(lever2 - arm) < 4 * sigma2 + 0.02) and sigma2[2] > sigma[2]
    # an attitude that never changes: nothing to regress on
    still = np.broadcast_to(np.eye(3), (t.size, 3, 3))
    assert np.all(np.isnan(gnssqc.estimate_gnss_lever_arm(t, res, still)[0]))
    assert not gnssqc.GnssLeverArm().clear_t.any()
    # an offset no aircraft has: not applied, said
    far = gnssqc.GnssLeverArm(np.array([0.0, 0.0, 40.0]), np.full(3, 0.1))
    assert not far.clear_t.any() and far.too_long


@pytest.fixture(scope="module")
def turning_platform():
    """The strapdown grid of :func:`turning_strapdown` flown with a levelled platform."""
    return _turning_grid("platform", {"gnss": {"horizontal_sigma_m": 0.3, "vertical_sigma_m": 0.6}})


def _antenna_at(s, rec, arm_flu):
    """``rec`` with its GNSS positions moved to an antenna at ``arm_flu`` (m) on the aircraft's
    axes, by the simulated aircraft attitude."""
    from gravsurvey.geodesy import ecef_to_geodetic, geodetic_to_ecef, mat_en

    tr = s.truth
    gn = rec.gnss
    k = np.clip(np.searchsorted(tr["time"], gn.time), 0, tr["time"].size - 1)
    off_n = np.einsum("nij,j->ni", tr["mat_nb"][k], np.asarray(arm_flu, float))
    off_e = np.einsum("nij,nj->ni", mat_en(gn.lat, gn.lon), off_n)
    lat, lon, h = ecef_to_geodetic(geodetic_to_ecef(gn.lat, gn.lon, gn.height) + off_e)
    return dataclasses.replace(rec, gnss=dataclasses.replace(gn, lat=lat, lon=lon, height=h))


@pytest.mark.parametrize("fixture", ["turning_strapdown", "turning_platform"])
def test_an_antenna_off_the_imu_is_found_and_applied(fixture, request):
    """An antenna 3 m ahead, 1 m right and 1.5 m above the IMU, not declared: the navigation
    tilts to follow it through every turn and the product pays (measured: strapdown 0.45 ->
    2.29 mGal, platform 0.40 -> 0.61); found from the track (on a
    platform with the aircraft's attitude from the track: heading along it, the bank of a
    coordinated turn), applied, said, and the product is the clean flight's. The clean flight
    finds none (found: 0.46 / 0.39 mGal, at [2.95, -0.95, 1.64] / [2.81, -0.81, 1.62] m)."""
    s, rec, init = request.getfixturevalue(fixture)
    triad = fixture.split("_")[1]
    arm = np.array([3.0, -1.0, 1.5])
    moved = _antenna_at(s, rec, arm)
    clean = estimate_anomaly(rec, InmParams(), init, triad)
    assert not clean.identification["gnss_lever_arm"]["applied"]
    zero = estimate_anomaly(moved, InmParams(), init, triad, gnss_lever_arm_t=np.zeros(3))
    found = estimate_anomaly(moved, InmParams(), init, triad)
    rep = found.identification["gnss_lever_arm"]
    assert rep["applied"] and np.all(np.abs(np.asarray(rep["lever_arm_flu_m"]) - arm) < 0.7)
    assert any("the antenna is [" in w and "applied" in w for w in found.warnings)
    assert rms_mid(zero, s) > 1.5 * rms_mid(clean, s)
    assert rms_mid(found, s) < 1.15 * rms_mid(clean, s)
    declared = estimate_anomaly(moved, InmParams(), init, triad, gnss_lever_arm_t=arm)
    assert "gnss_lever_arm" not in declared.identification
    assert rms_mid(declared, s) < 1.15 * rms_mid(clean, s)


def _carrier_phase_grid(triad, arm):
    """The grid of :func:`turning_strapdown` with carrier-phase GNSS (2 cm, 3 cm) as its only
    heights, the antenna at ``arm`` (FLU, m) from the IMU: the flight, its record, the initial
    state."""
    gnss = {"horizontal_sigma_m": 0.02, "vertical_sigma_m": 0.03, "antenna_m": list(arm)}
    s, rec, init = _turning_grid(triad, {"gyro": {"white_drift_degph": 0.005}, "gnss": gnss})
    return s, dataclasses.replace(rec, altimeter=AltimeterChannel(rec.gnss.time, rec.gnss.height)), init


def test_heights_from_the_antenna_are_moved_to_the_imu():
    """Carrier-phase GNSS heights as the only height channel, the antenna 3 m ahead, 1 m right
    and 1.5 m above a strapdown IMU in 0.5 deg of attitude turbulence: each height is the
    antenna's, so that the attitude moves it (2.6 cm at 0.5 deg of pitch).  Found or declared,
    the arm moves the heights to the IMU for the height checks, the identification and the
    filter: the product is the clean flight's (measured 0.154 found, 0.206 declared, 0.216
    clean, mGal), where with the arm given to the GNSS positions only it was 0.997 either way;
    and the track check takes the antenna off (it had read the 3.2 m as the IMU and the GNSS
    disagreeing).  Left out, the product is 5x worse."""
    s, clean_rec, init = _carrier_phase_grid("strapdown", [0.0, 0.0, 0.0])
    _, rec, _ = _carrier_phase_grid("strapdown", [3.0, -1.0, 1.5])
    clean = rms_mid(estimate_anomaly(clean_rec, InmParams(), init, "strapdown"), s)
    zero = estimate_anomaly(rec, InmParams(), init, "strapdown", gnss_lever_arm_t=np.zeros(3))
    assert rms_mid(zero, s) > 3.0 * clean
    found = estimate_anomaly(rec, InmParams(), init, "strapdown")
    rep = found.identification["gnss_lever_arm"]
    assert rep["applied"] and np.all(np.abs(np.asarray(rep["lever_arm_flu_m"]) - [3.0, -1.0, 1.5]) < 0.1)
    declared = estimate_anomaly(rec, InmParams(), init, "strapdown", gnss_lever_arm_t=np.array([3.0, -1.0, 1.5]))
    for sol in (found, declared):
        assert rms_mid(sol, s) < 1.2 * clean
        assert sol.gnss_residual_systematic_m < 0.1
        assert not any("systematically" in w for w in sol.identification.get("warnings", []))


def test_heights_from_an_antenna_off_a_platforms_vertical_are_said_to_carry_its_attitude(turning_platform):
    """On a platform the aircraft's attitude comes from the track alone: heights from an
    antenna above the IMU are moved as well as on a strapdown (the product within 1.3x the
    clean flight's), from an antenna 1 m off that vertical they carry the pitch and roll the
    track does not show, and a warning says so; above it, none."""
    s, clean_rec, init = _carrier_phase_grid("platform", [0.0, 0.0, 0.0])
    clean = rms_mid(estimate_anomaly(clean_rec, InmParams(), init, "platform"), s)
    _, up, _ = _carrier_phase_grid("platform", [0.0, 0.0, 1.5])
    sol = estimate_anomaly(up, InmParams(), init, "platform", gnss_lever_arm_t=np.array([0.0, 0.0, 1.5]))
    assert rms_mid(sol, s) < 1.3 * clean
    assert not any("off the vertical" in w for w in sol.warnings)
    _, side, _ = _carrier_phase_grid("platform", [0.0, -1.0, 1.5])
    sol = estimate_anomaly(side, InmParams(), init, "platform", gnss_lever_arm_t=np.array([0.0, -1.0, 1.5]))
    assert any(
        "the heights are the GNSS antenna's, 1 m off the vertical through the IMU, on a platform" in w
        for w in sol.warnings
    )
    # and not where the heights are an altimeter's of its own
    _, rec2, init2 = turning_platform
    sol = estimate_anomaly(rec2, InmParams(), init2, "platform", gnss_lever_arm_t=np.array([0.0, -1.0, 1.5]))
    assert not any("off the vertical" in w for w in sol.warnings)


def _expecting(monkeypatch, name, mgal):
    """``solve.<name>`` (a ``(params, report)`` maker) patched so that its report expects
    ``mgal`` of error in the product."""
    made = getattr(solve, name)

    def pessimistic(*args, **kwargs):
        params, report = made(*args, **kwargs)
        return params, {**report, "expected_error_mgal": mgal}

    monkeypatch.setattr(solve, name, pessimistic)


def test_a_product_the_model_expects_to_be_useless_is_said_to_be(turning_platform, monkeypatch):
    """An identified model that expects over 20 mGal of error in the product (measured: a
    platform's GNSS heights from an antenna 2.3 m off the IMU's vertical in strong turbulence,
    124 mGal expected, 77 had): a warning says the field is not resolved; the flight as
    recorded expects 0.3 mGal and says nothing."""
    s, rec, init = turning_platform
    clean = estimate_anomaly(rec, InmParams(), init, "platform")
    assert clean.identification["expected_error_mgal"] < 1.0
    assert not any("expects an error of" in w for w in clean.warnings)
    _expecting(monkeypatch, "_identify", 124.0)
    sol = estimate_anomaly(rec, InmParams(), init, "platform")
    assert any(
        re.search(r"^sim: the model identified from this flight expects an error of 124 mGal in its product", w)
        for w in sol.warnings
    )


def test_a_prior_expecting_a_useless_product_gives_way_to_the_broad_one(turning_platform, monkeypatch):
    """The prior of least expected error expecting over 20 mGal (a first-pass spectrum of noise
    read as a strong short field: on a full-length platform draw with GNSS heights from an
    antenna 1.4 m off the IMU's vertical, 59 mGal expected, 28.8 had, the conventional chain
    0.38; with the broad prior 2.0): the configured or default prior is used instead, the
    identified noise kept, and a warning says so."""
    s, rec, init = turning_platform
    _expecting(monkeypatch, "refine_prior", 124.0)
    sol = estimate_anomaly(rec, InmParams(), init, "platform")
    ident = sol.identification
    default = InmParams()
    assert ident["anomaly_sigma_mps2"]["value"] == default.anomaly_sigma_mps2
    assert ident["anomaly_lambda_per_m"]["value"] == default.anomaly_lambda_per_m
    assert "expected 124 mGal" in ident["anomaly_sigma_mps2"]["how"]
    assert "expected_error_mgal" not in ident and "smoother_sigma_scale" not in ident
    assert ident["altimeter_sigma_m"]["how"].startswith("identified")
    assert any(
        w.startswith("model identification: the anomaly prior of least expected error expects 124 mGal")
        and "(100 mGal over 100 km) is used instead" in w
        for w in sol.warnings
    )
    assert not any("expects an error of" in w for w in sol.warnings)


def test_track_attitude_is_a_coordinated_turn():
    """The aircraft's axes from its track: forward along the velocity, the bank of a coordinated
    turn (right turn: right wing down, the up axis towards the turn's centre), proper rotations,
    the heading held where the aircraft is too slow to have one."""
    t = np.arange(0.0, 200.0, 0.1)
    rate = np.radians(3.0) * ((t > 50) & (t < 150))  # a right turn at 3 deg/s
    psi = np.cumsum(rate) * 0.1
    v = np.stack([70.0 * np.sin(psi), 70.0 * np.cos(psi), np.full(t.size, 2.0)], axis=1)
    c = gnssqc.track_attitude(t, v)
    np.testing.assert_allclose(np.linalg.det(c), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.einsum("kji,kjl->kil", c, c), np.broadcast_to(np.eye(3), c.shape), atol=1e-12)
    np.testing.assert_allclose(c[:, :, 0], v / np.linalg.norm(v, axis=1)[:, None], atol=1e-12)
    mid = np.abs(t - 100.0) < 30.0
    bank = np.arcsin(c[mid, 2, 1])  # the left axis's rise
    np.testing.assert_allclose(bank, np.arctan(70.0 * np.radians(3.0) / STANDARD_GRAVITY_MPS2), rtol=1e-3)
    centre = np.cross(c[mid, :, 0], [0.0, 0.0, 1.0])  # right of forward, level
    assert np.all(np.einsum("ki,ki->k", c[mid, :, 2], centre) > 0.3)
    level = np.abs(t - 20.0) < 10.0
    np.testing.assert_allclose(c[level, 2, 1], 0.0, atol=1e-12)
    # a gust heaving it +-1 m/s at a 20-s period does not pitch it; the steady climb does
    heave = v.copy()
    heave[:, 2] = 2.0 + np.sin(2.0 * np.pi * t / 20.0)
    inner = (t > 40.0) & (t < 160.0)
    pitch = np.arcsin(gnssqc.track_attitude(t, heave)[inner, 2, 0])
    np.testing.assert_allclose(pitch, np.arctan2(2.0, 70.0), atol=1e-4)  # the heave's own: 0.014 rad
    # parked for the first 10 s (no heading): the first moving heading held, wings level
    v[t < 10.0] = [0.05, 0.0, 0.0]
    c = gnssqc.track_attitude(t, v)
    np.testing.assert_allclose(c[t < 10.0, :, 0], np.broadcast_to([0.0, 1.0, 0.0], c[t < 10.0, :, 0].shape), atol=1e-6)


@pytest.fixture(scope="module")
def survey_gnss_heights():
    """The grid of :func:`turning_strapdown` with a barometric-class altimeter (0.5 m) and a
    survey GNSS (0.1 m up): the GNSS heights are weighed by their own noise."""
    return _turning_grid(
        "strapdown",
        {
            "gyro": {"white_drift_degph": 0.005},
            "altimeter": {"sigma_m": 0.5},
            "gnss": {"horizontal_sigma_m": 0.1, "vertical_sigma_m": 0.1},
        },
    )


def test_a_gnss_height_stretch_off_by_a_metre_is_taken_off(survey_gnss_heights, monkeypatch):
    """The GNSS heights 1 m high for 200 s (a float stretch between two ambiguity fixes): both
    steps found against the inertial height and taken off, said, and the product is near the
    clean flight's (measured 0.331 against 0.265 mGal: the steps are found to 3 cm, and the
    2.7 cm left from 700 s on shows now that the field is held - 0.800 against 0.796 when the
    prior held too little of it, identify.FIELD_VAR_WINDOW_S); left in, the filter follows the
    heights and reads the steps as gravity (62.6)."""
    s, rec, init = survey_gnss_heights
    gn = rec.gnss
    t = np.asarray(gn.time, float)
    block = (t >= 500.0) & (t < 700.0)
    stepped = dataclasses.replace(rec, gnss=dataclasses.replace(gn, height=np.where(block, gn.height + 1.0, gn.height)))
    clean = estimate_anomaly(rec, InmParams(), init, "strapdown")
    assert "gnss" not in clean.identification.get("height_faults", {})
    sol = estimate_anomaly(stepped, InmParams(), init, "strapdown")
    steps = sol.identification["height_faults"]["gnss"]["steps"]
    assert [round(x["time_s"]) for x in steps] == [500, 700]
    assert [x["size_m"] for x in steps] == pytest.approx([1.0, -1.0], abs=0.1)
    assert any("gnss.height: " in w and "2 step(s) taken off" in w for w in sol.warnings)
    assert rms_mid(sol, s) < 1.4 * rms_mid(clean, s)
    monkeypatch.setattr(solve, "_repaired_gnss_heights", lambda record, nav, ellipsoid: (record, [], {}))
    left = estimate_anomaly(stepped, InmParams(), init, "strapdown")
    assert rms_mid(left, s) > 2.0 * rms_mid(sol, s)


def test_a_noisy_gnss_height_stretch_is_weighed_by_its_own_noise(survey_gnss_heights, monkeypatch):
    """The GNSS heights 1 m noisy for 300 s (a float stretch) where the rest are 0.1 m: the
    stretch weighed by its own noise and said; there the 0.5-m altimeter holds the height, the
    product is coarser (measured 1.86 mGal in the middle 320 s against 0.26 clean) and its sigma
    grows to cover it (2.7 against 0.40 mGal, error/sigma 0.73); weighed as the rest, the filter
    follows the noise (133 mGal)."""
    s, rec, init = survey_gnss_heights
    gn = rec.gnss
    t = np.asarray(gn.time, float)
    burst = (t >= 500.0) & (t < 800.0)
    rng = np.random.default_rng(2)
    noisy = dataclasses.replace(
        rec, gnss=dataclasses.replace(gn, height=gn.height + np.where(burst, rng.standard_normal(t.size), 0.0))
    )
    clean = estimate_anomaly(rec, InmParams(), init, "strapdown")
    sol = estimate_anomaly(noisy, InmParams(), init, "strapdown")
    facts = sol.identification["height_faults"]["gnss"]
    assert 300.0 <= facts["noisy_s"] <= 360.0 and facts["steps"] == []
    assert any("noisier than the rest" in w for w in sol.warnings)
    g = np.interp(sol.time, s.truth["time"], s.truth["disturbance"])
    keep = (sol.time > 500.0) & (sol.time < 800.0)
    e = sol.g_smooth[keep] - g[keep]
    # where only the altimeter holds the height the product is coarser, and its sigma says so
    assert np.sqrt(np.mean(((e - e.mean()) / sol.sigma_smooth[keep]) ** 2)) < 1.5
    keep_clean = (clean.time > 500.0) & (clean.time < 800.0)
    assert np.median(sol.sigma_smooth[keep]) > 3.0 * np.median(clean.sigma_smooth[keep_clean])
    monkeypatch.setattr(solve, "noisy_stretches", lambda t, e: np.full(np.size(t), np.nan))
    left = estimate_anomaly(noisy, InmParams(), init, "strapdown")
    assert rms_mid(left, s) > 10.0 * rms_mid(sol, s)


def test_a_field_mostly_trend_along_short_lines_is_held_by_the_prior(survey_gnss_heights):
    """The grid's field (the sample's smooth one: 5 mGal about a 20-mGal mean, mostly a trend
    along each 25-km line) lies below the first pass's periodogram band; the field seen through
    the Hann-weighted window holds it (identify.FIELD_VAR_WINDOW_S).  Through a 120-s running
    mean the height noise's sidelobes (8 mGal) hid it: the prior was chosen as for no field
    (0.43 mGal), the gyros took up the trend in the turns ("noisier", 10 deg/h) and the middle
    was 0.94 mGal off; measured 0.26 now, the datasheet gyro kept."""
    s, rec, init = survey_gnss_heights
    sol = estimate_anomaly(rec, InmParams(), init, "strapdown")
    ident = sol.identification
    assert ident["field_std_seen_mgal"] > 1.5
    assert ident["gyro_drift_degph"]["how"].startswith("default")
    assert rms_mid(sol, s) < 0.45
