"""Spikes and steps of the height channel (gravsurvey/inm/heightqc.py): found on the residual
against the inertial height whatever its drift and rate, none where there are none, and
repaired before the estimator reads the heights."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from gravsurvey.estimate import from_inm_solution
from gravsurvey.inm import heightqc as Q
from gravsurvey.inm.params import InmParams
from gravsurvey.inm.solve import estimate_anomaly
from gravsurvey.io.record import AltimeterChannel

from test_inm_identify import (  # noqa: F401  (noisy_flight: the fixture)
    NAVIGATION_GRADE,
    rms_mid,
    noisy_flight,
    record_and_truth_start,
)


def _residual(rate_hz, seed, span_s=2400.0, sigma_m=0.05, drift_m=300.0):
    """An unaided inertial height error (smooth, up to ``drift_m``) plus white height noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, span_s, 1.0 / rate_hz)
    x = t / span_s
    smooth = drift_m * (np.cosh(3.0 * x) - 1.0) / (np.cosh(3.0) - 1.0) + 2.0 * np.sin(2 * np.pi * t / 700.0)
    return t, smooth + sigma_m * rng.standard_normal(t.size)


@pytest.mark.parametrize("rate_hz", [1.0, 5.0, 20.0])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_nothing_found_where_there_is_nothing(rate_hz, seed):
    t, e = _residual(rate_hz, seed)
    faults = Q.find_height_faults(t, e)
    assert not faults and faults.spikes.size == 0 and faults.steps == []


@pytest.mark.parametrize("rate_hz", [1.0, 5.0, 20.0])
def test_spikes_and_steps_are_found_where_they_are(rate_hz):
    t, e = _residual(rate_hz, 7)
    rng = np.random.default_rng(11)
    # the measured height: spikes of 1 m, a step of +0.8 m at 600 s and of -0.6 m at 1500 s
    # (at 1 Hz and 5 cm of noise a jump's standard error is 4.7 cm: 13-17 of them)
    h = np.zeros(t.size)
    spikes = np.sort(rng.choice(np.arange(50, t.size - 50), 10, replace=False))
    h[spikes] += rng.choice([-1.0, 1.0], 10)
    k1, k2 = np.searchsorted(t, 600.0), np.searchsorted(t, 1500.0)
    h[k1:] += 0.8
    h[k2:] -= 0.6
    faults = Q.find_height_faults(t, e - h)  # e = h_ins - h_alt
    assert set(faults.spikes.tolist()) == set(spikes.tolist())
    assert [k for k, _ in faults.steps] == [k1, k2]
    # each size within three standard errors of two 20-s quadratic end-point fits
    se = 0.05 * np.sqrt(2 * 9.0 / (20.0 * rate_hz))
    np.testing.assert_allclose([s for _, s in faults.steps], [0.8, -0.6], atol=3 * se + 1e-3)
    # repaired: the spikes dropped, the steps taken off what follows them
    fixed = Q.repair_heights(h, faults)
    assert np.isnan(fixed[spikes]).all()
    ok = np.isfinite(fixed)
    assert np.max(np.abs(fixed[ok])) < 4 * se + 1e-3


def _turn_residual(rate_hz, seed, a_mps2=0.08, span_s=1300.0, turns=((400.0, 35.0), (900.0, 30.0))):
    """The residual of a poorly aligned mechanization through two turns: 1.5 deg of tilt takes
    ``a_mps2`` of the turn's centripetal force into the vertical (rolled in and out over 3 s),
    a vertical velocity error of -1.5 m/s, 5 cm of height noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, span_s, 1.0 / rate_hz)
    acc = np.zeros(t.size)
    for t0, dur in turns:
        acc += a_mps2 * np.clip((t - t0) / 3.0, 0, 1) * np.clip((t0 + dur - t) / 3.0, 0, 1)
    v = np.cumsum(acc) / rate_hz - 1.5
    return t, np.cumsum(v) / rate_hz + 0.05 * rng.standard_normal(t.size)


@pytest.mark.parametrize("rate_hz", [1.0, 5.0, 11.0, 20.0])
@pytest.mark.parametrize("seed", [1, 2])
def test_a_turn_is_not_a_step(rate_hz, seed):
    """A turn bends the residual (the tilt error's share of the centripetal force), which left
    jumps of 0.4-0.6 m between the 20-s quadratics at its ends: 4-6 false steps here, and on
    quick U010 split by an IMU gap two of them taken off the heights, 65 mGal in the turn. A
    step keeps its size over half-length fits (``heightqc.STEP_SHORT_RATIO``), the bend's
    falls with the window's square: none found, a real 0.5-m step between the turns still is."""
    t, e = _turn_residual(rate_hz, seed)
    assert Q.find_height_faults(t, e).steps == []
    k = np.searchsorted(t, 650.0)
    h = np.where(np.arange(t.size) >= k, 0.5, 0.0)
    (step,) = Q.find_height_faults(t, e - h).steps
    se = 0.05 * np.sqrt(2 * 9.0 / (20.0 * rate_hz))  # as in test_spikes_and_steps_are_found_where_they_are
    assert step[0] == k and abs(step[1] - 0.5) < 3 * se


@pytest.mark.parametrize("rate_hz", [1.0, 5.0, 20.0])
@pytest.mark.parametrize("n_s, level", [(3.0, 0.0), (8.0, 0.0), (1.0, 0.0), (5.0, 1600.0)])
def test_a_short_block_of_wrong_heights_is_dropped_not_two_steps(rate_hz, n_s, level):
    """A radar altimeter's no-lock zeros (or a burst of one wrong value) for a few seconds: the
    samples are dropped like spikes. Before, a 3-s block of zeros at 1 Hz was read as two steps
    of the wrong sizes (-184 and +869 m 19 s apart) and gave 142 mGal of error."""
    t, e = _residual(rate_hz, 5)
    h = 1000.0 + np.zeros(t.size)  # the measured height, flown level at 1000 m
    k = np.searchsorted(t, 1200.0)
    m = int(round(n_s * rate_hz))
    h_bad = h.copy()
    h_bad[k : k + m] = level
    faults = Q.find_height_faults(t, e - (h_bad - h), h_bad)
    assert faults.steps == []
    assert set(faults.spikes.tolist()) == set(range(k, k + m))
    # a block longer than BLOCK_MAX_S with a level change that stays is a step, not a block
    h_step = h.copy()
    h_step[k:] += 0.8
    faults = Q.find_height_faults(t, e - (h_step - h), h_step)
    assert [i for i, _ in faults.steps] == [k] and faults.spikes.size == 0


@pytest.mark.parametrize("rate_hz", [1.0, 5.0])
def test_the_way_back_of_a_block_is_found_with_its_first_step(rate_hz):
    """A GNSS height that loses its ambiguities jumps and, re-fixed, jumps back: the first jump at
    10 standard errors, the way back at 7 (under STEP_K alone). Taken off alone, the first step
    turned a 120-s block into a permanent offset with a step back into it (fuzzing, 2026-12-04:
    15.7 mGal against 2.2 intact); the way back is the opposite jump of a like size near it."""
    t, e = _residual(rate_hz, 7)
    se = 0.05 * np.sqrt(2 * 9.0 / (20.0 * rate_hz))
    k1, k2 = np.searchsorted(t, 1000.0), np.searchsorted(t, 1120.0)
    h = np.zeros(t.size)
    h[k1:k2] += 10.0 * se
    h[k2:] += 3.0 * se  # the way back falls 7 standard errors: 3 of the first 10 stay
    faults = Q.find_height_faults(t, e - h)
    (a, _), (b, _) = faults.steps
    assert a == k1 and abs(b - k2) <= 1  # the weaker end placed within a sample (20 Hz: 0.05 s)
    np.testing.assert_allclose([s for _, s in faults.steps], [10.0 * se, -7.0 * se], atol=3 * se)
    # without the first the way back alone is below the threshold: nothing
    h2 = np.zeros(t.size)
    h2[k2:] -= 7.0 * se
    assert Q.find_height_faults(t, e - h2).steps == []


def test_a_step_in_the_heights_is_repaired_before_the_estimate(noisy_flight):  # noqa: F811
    """A 0.3-m jump of the heights in mid-flight (a GNSS height re-fixing its ambiguities):
    taken off before the filter, the estimate is as good as without it, and the user is told."""
    s, rec, init = noisy_flight
    clean = estimate_anomaly(rec, InmParams(), init, "platform")
    h = np.array(rec.altimeter.height, float)
    mid = h.size // 2
    h[mid:] += 0.3
    h[[1000, 5000, 13000]] += 3.0
    broken = dataclasses.replace(rec, altimeter=AltimeterChannel(rec.altimeter.time, h))
    sol = estimate_anomaly(broken, InmParams(), init, "platform")
    facts = sol.identification["height_faults"]
    assert facts["spikes"] == 3 and len(facts["steps"]) == 1
    assert facts["steps"][0]["time_s"] == pytest.approx(rec.altimeter.time[mid], abs=0.01)
    assert facts["steps"][0]["size_m"] == pytest.approx(0.3, abs=0.03)
    notes = from_inm_solution(sol, name="F01").notes
    assert any("1 step(s) taken off" in n and "3 spike(s) dropped" in n for n in notes), notes
    assert rms_mid(sol, s) < 1.05 * rms_mid(clean, s)
    # what the repair saves: the same record with the check switched off
    off = dataclasses.replace(Q.HeightFaults())
    assert not off
    from gravsurvey.inm import solve

    original = solve.find_height_faults
    try:
        solve.find_height_faults = lambda t, e, h=None: Q.HeightFaults()
        unrepaired = estimate_anomaly(broken, InmParams(), init, "platform")
    finally:
        solve.find_height_faults = original
    assert rms_mid(unrepaired, s) > 2.0 * rms_mid(sol, s)
    # a clean record is left as it is: no facts, no warning
    assert "height_faults" not in clean.identification


def test_latency_is_the_slope_of_the_residual_on_the_vertical_velocity():
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 1800.0, 0.2)
    # turbulence: vertical velocity of 0.5 m/s at periods of 3-30 s; a slow inertial height error
    v = sum(0.2 * np.sin(2 * np.pi * t / p + rng.uniform(0, 6)) for p in (3.0, 5.0, 8.0, 13.0, 21.0, 30.0))
    slow = 5.0 * (t / 1800.0) ** 2
    for lat in (0.0, 0.08, -0.3):
        e = slow + lat * v + 0.05 * rng.standard_normal(t.size)
        got, sigma = Q.estimate_latency(t, e, v)
        assert sigma < 0.005 and abs(got - lat) < 4 * sigma + 1e-3
    # no vertical motion: nothing to regress on, no verdict
    got, sigma = Q.estimate_latency(t, slow + 0.05 * rng.standard_normal(t.size), np.zeros(t.size))
    assert np.isnan(got) and np.isnan(sigma)


def test_a_mechanization_running_off_is_no_latency_at_the_records_ends():
    # exact stamps; the uncorrected mechanization's height runs off as a parabola (its vertical
    # velocity 1 m/s off at the ends, as on quick U1434): the running mean is one-sided within
    # half a window of the ends, where the residual less it is metres, and the velocity's too
    # (before 2026-12-05 both ends were in the regressions: -57 ms at 14 "standard errors",
    # drifting 59 ppm at 10; on U1434 a 50-ms latency drifting -156 ppm was taken off the
    # exact stamps, 1.27 -> 3.17 mGal)
    rng = np.random.default_rng(1)
    t = np.arange(0.0, 2400.0, 0.5)
    tm = t.mean()
    c = -4.5e-4  # m/s^2
    turb = 0.3 * np.convolve(rng.standard_normal(t.size), np.ones(6) / 6, mode="same")
    v = 2 * c * (t - tm) + turb
    e = c * (t - tm) ** 2 + 0.03 * rng.standard_normal(t.size)
    lat, sigma = Q.estimate_latency(t, e, v)
    assert abs(lat) < max(3 * sigma, 0.005)
    mid, mid_sigma, rate, rate_sigma = Q.estimate_latency_drift(t, e, v)
    assert abs(mid) < max(3 * mid_sigma, 0.005)
    assert abs(rate) < 4 * rate_sigma and abs(rate) * 1200.0 < 0.02


@pytest.fixture(scope="module")
def turbulent_flight():
    """30 min of level flight in turbulence (0.8 m of vertical motion at 2-60 s periods),
    navigation-grade noise, 5 Hz heights with 5 cm of noise: the estimator is not told."""
    from gravsurvey.simulate.run import quick_sim, simulate_flight

    sensors = NAVIGATION_GRADE
    turbulence = {
        "vertical_sigma_m": 0.8,
        "horizontal_sigma_m": 1.0,
        "attitude_sigma_deg": 0.3,
        "corner_period_s": 10.0,
        "min_period_s": 2.0,
        "max_period_s": 60.0,
    }
    sim = quick_sim(
        duration_s=1800,
        imu_hz=20,
        altimeter_hz=5.0,
        speed_mps=70.0,
        field="seed_smooth",
        noise=sensors,
        turbulence=turbulence,
        seed=3,
    )
    s = simulate_flight(sim)
    return (s, *record_and_truth_start(s))


def test_late_height_stamps_are_taken_back_before_the_estimate(turbulent_flight):
    """Heights stamped 0.15 s after they were measured (a logger's receive time): found to a few
    ms, taken off the stamps, the estimate as without; the clean flight has none."""
    s, rec, init = turbulent_flight
    clean = estimate_anomaly(rec, InmParams(), init, "platform")
    late = dataclasses.replace(rec, altimeter=AltimeterChannel(rec.altimeter.time + 0.15, rec.altimeter.height))
    sol = estimate_anomaly(late, InmParams(), init, "platform")
    facts = sol.identification["height_faults"]
    assert facts["latency_s"] == pytest.approx(0.15, abs=max(4 * facts["latency_sigma_s"], 0.005))
    assert any("late against the IMU" in n for n in from_inm_solution(sol, name="F01").notes)
    assert rms_mid(sol, s) < 1.05 * rms_mid(clean, s)
    assert "height_faults" not in clean.identification


def test_a_height_clock_seconds_out_of_step_is_found(turbulent_flight):
    """Heights 1.5 s late: found by the coarse search (the regression alone is linear and reads
    such offsets short), taken off, the estimate as without; 18 s (GPS time against UTC): a
    DataError naming the key and the value that puts the clocks in step; in step: nothing."""
    from gravsurvey.errors import DataError

    s, rec, init = turbulent_flight
    clean = estimate_anomaly(rec, InmParams(), init, "platform")
    assert "height_faults" not in clean.identification
    late = dataclasses.replace(rec, altimeter=AltimeterChannel(rec.altimeter.time + 1.5, rec.altimeter.height))
    sol = estimate_anomaly(late, InmParams(), init, "platform")
    assert sol.identification["height_faults"]["latency_s"] == pytest.approx(1.5, abs=0.03)
    assert rms_mid(sol, s) < 1.05 * rms_mid(clean, s)
    gps = dataclasses.replace(rec, altimeter=AltimeterChannel(rec.altimeter.time + 18.0, rec.altimeter.height))
    with pytest.raises(DataError, match=r"altimeter: .*\+18\.00 s .*time_offsets_s: \{altimeter: -18\.00\}"):
        estimate_anomaly(gps, InmParams(), init, "platform")


def test_frozen_heights_and_gaps_are_not_read_as_steps(noisy_flight):  # noqa: F811
    """A height that holds its value for 10 s (a stalled sensor) and a 30-s outage: the frozen
    samples are dropped, no step is read across either, and the estimate is as good as the
    clean one (a first version took both for metre-size steps: 33 and 43 mGal on quick U214)."""
    s, rec, init = noisy_flight
    clean = estimate_anomaly(rec, InmParams(), init, "platform")
    t = rec.altimeter.time
    h = np.array(rec.altimeter.height, float)
    frozen = np.flatnonzero((t >= 1200.0) & (t < 1210.0))
    h[frozen] = h[frozen[0]]
    keep = (t < 2400.0) | (t > 2430.0)
    broken = dataclasses.replace(rec, altimeter=AltimeterChannel(t[keep], h[keep]))
    sol = estimate_anomaly(broken, InmParams(), init, "platform")
    facts = sol.identification["height_faults"]
    assert facts["frozen"] == frozen.size - 1 and facts["spikes"] == 0 and facts["steps"] == []
    assert rms_mid(sol, s) < 1.05 * rms_mid(clean, s)
    # a quantised height repeats by nature: nothing is taken for frozen there
    q = np.round(h / 0.2) * 0.2
    assert Q.frozen_samples(t, q).size == 0


@pytest.mark.parametrize("rate_hz", [1.0, 5.0, 20.0])
def test_a_noisy_stretch_gets_its_own_sigma(rate_hz):
    """Heights of 5 cm noise on a drifting residual, 1 m for 300 s (a GNSS float stretch): that
    stretch (and at most a block either side) marked with about its own noise, nothing else;
    without it nothing is marked."""
    rng = np.random.default_rng(4)
    t = np.arange(0.0, 2400.0, 1.0 / rate_hz)
    drift = 3.0 * np.sin(2 * np.pi * t / 1500.0) + 0.5 * (t / 2400.0) ** 2
    e = drift + 0.05 * rng.standard_normal(t.size)
    assert np.all(np.isnan(Q.noisy_stretches(t, e)))
    burst = (t >= 1000.0) & (t < 1300.0)
    e[burst] += 1.0 * rng.standard_normal(int(burst.sum()))
    own = Q.noisy_stretches(t, e)
    marked = np.isfinite(own)
    assert marked[burst].all()
    block = max(Q.NOISE_BLOCK_S, Q.NOISE_MIN_SAMPLES / rate_hz)
    assert not marked[(t < 1000.0 - 3 * block) | (t >= 1300.0 + 3 * block)].any()
    assert np.median(own[burst]) == pytest.approx(1.0, rel=0.3)


def test_a_noisy_stretch_of_the_heights_is_weighed_not_cut_into_steps(noisy_flight, monkeypatch):  # noqa: F811
    """The altimeter 1 m noisy for 300 s (5 cm elsewhere): weighed by its own noise, no step or
    spike invented in it, said; the product stays near the clean one with a sigma that covers
    it (measured: 1.21 mGal over the flight's middle against 0.63 clean, error/sigma 0.99 in the
    stretch). Searched as before (the noise against the quiet sigma), it was cut into steps and
    spikes (280 mGal)."""
    from gravsurvey.inm import solve

    s, rec, init = noisy_flight
    clean = estimate_anomaly(rec, InmParams(), init, "platform")
    t = np.asarray(rec.altimeter.time, float)
    burst = (t >= 1500.0) & (t < 1800.0)
    rng = np.random.default_rng(8)
    h = np.asarray(rec.altimeter.height, float) + np.where(burst, rng.standard_normal(t.size), 0.0)
    noisy = dataclasses.replace(rec, altimeter=AltimeterChannel(t, h))
    sol = estimate_anomaly(noisy, InmParams(), init, "platform")
    facts = sol.identification["height_faults"]
    assert 300.0 <= facts["noisy_s"] <= 360.0 and facts["steps"] == [] and facts["spikes"] == 0
    assert any("noisier than the rest" in w for w in sol.warnings)
    g = np.interp(sol.time, s.truth["time"], s.truth["disturbance"])
    e = sol.g_smooth - g
    e = e - e[(sol.time > 600.0) & (sol.time < sol.time[-1] - 600.0)].mean()
    keep = (sol.time > 1500.0) & (sol.time < 1800.0)
    assert np.sqrt(np.mean((e[keep] / sol.sigma_smooth[keep]) ** 2)) < 1.5
    assert rms_mid(sol, s) < 2.5 * rms_mid(clean, s)
    monkeypatch.setattr(solve, "noisy_stretches", lambda t, e: np.full(np.size(t), np.nan))
    cut = estimate_anomaly(noisy, InmParams(), init, "platform")
    assert len(cut.identification["height_faults"]["steps"]) > 3
    assert rms_mid(cut, s) > 10.0 * rms_mid(sol, s)
