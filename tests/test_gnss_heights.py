"""A height channel that is the GNSS's own heights (a log without an altimeter: ``topics:
{altimeter: /fix}``, or the GNSS file's height column): found, and the heights enter the filter
once, not again as the GNSS position's up component (gravsurvey/inm/heightqc.py,
``gnss_height_fraction``; docs/method.md, "Heights that are the GNSS's own")."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import gravsurvey.inm.solve as solve
from gravsurvey.inm.errormodel import GnssMeasurement
from gravsurvey.inm.heightqc import SAME_FRACTION, gnss_height_fraction
from gravsurvey.inm.mechanization import mechanize
from gravsurvey.inm.params import InmParams
from gravsurvey.inm.solve import estimate_anomaly
from gravsurvey.io.record import AltimeterChannel
from gravsurvey.simulate.run import quick_sim, simulate_flight

from sim_record import record_and_initial
from test_inm_gnss import GRID
from test_inm_identify import NAVIGATION_GRADE, rms_mid


def test_gnss_height_fraction_counts_the_gnss_samples():
    rng = np.random.default_rng(1)
    t = np.arange(0.0, 600.0, 0.2)
    h = 900.0 + np.cumsum(0.1 * rng.standard_normal(t.size))
    assert gnss_height_fraction(t, h, t, h) == 1.0
    # every fifth sample (a 1-Hz height channel cut from 5-Hz GNSS), written with 3 decimals
    assert gnss_height_fraction(t[::5], np.round(h[::5], 3), t, h) == 1.0
    # an altimeter of its own: metres away and centimetres noisy, or the same heights 0.1 s later
    assert gnss_height_fraction(t, h + 2.0 + 0.03 * rng.standard_normal(t.size), t, h) == 0.0
    assert gnss_height_fraction(t + 0.1, h, t, h) == 0.0
    # half the samples (a second receiver stitched in): not the GNSS's heights
    mixed = np.where(np.arange(t.size) % 2 == 0, h, h + 0.5)
    assert gnss_height_fraction(t, mixed, t, h) == pytest.approx(0.5) and 0.5 < SAME_FRACTION
    assert gnss_height_fraction(t[:0], h[:0], t, h) == 0.0
    assert gnss_height_fraction(t, h, t[:1], h[:1]) == pytest.approx(1.0 / t.size)


def _gnss_height_flight(seed):
    """25-min platform grid with code-grade GNSS heights (1.5 m at 2 Hz) and no altimeter: the
    height channel is the GNSS heights."""
    noise = {**NAVIGATION_GRADE, "gnss": {"horizontal_sigma_m": 0.5, "vertical_sigma_m": 1.5}}
    sim = quick_sim(
        plan=GRID, triad="platform", noise=noise, field="seed_smooth", gnss_hz=2.0, altimeter_hz=2.0, seed=seed
    )
    s = simulate_flight(sim)
    rec, init = record_and_initial(s)
    rec = dataclasses.replace(rec, altimeter=AltimeterChannel(rec.gnss.time.copy(), rec.gnss.height.copy()))
    return s, rec, init


#: The simulated sensors' figures and one fixed prior (5 mGal, 20 km), the same for both runs:
#: the comparison is of the measurement model alone (identification picks its prior from a
#: first pass that itself differs between the two).
FIXED = InmParams(
    identify=False,
    altimeter_sigma_m=1.5,
    gnss_vertical_sigma_m=1.5,
    gnss_horizontal_sigma_m=0.5,
    gravimeter_white_mps2=1e-5,
    accel_noise_mps2=5e-4,
    anomaly_sigma_mps2=5e-5,
    anomaly_lambda_per_m=1.0 / 20e3,
)


def test_gnss_measurement_without_its_up_component():
    s, rec, init = _gnss_height_flight(0)
    nav = mechanize(
        rec.imu.time, rec.imu.specific_force_t, rec.imu.angular_rate_t, init, rec.altimeter.time, rec.altimeter.height
    )
    idx = np.arange(0, nav.time.size, 100)
    gn = rec.gnss
    args = (gn.time, gn.lat, gn.lon, gn.height, 0.5, 1.5)
    z, h, r = GnssMeasurement(*args).build(nav, idx, 0.5)
    z2, h2, r2 = GnssMeasurement(*args, vertical=False).build(nav, idx, 0.5)
    have = np.isfinite(z[:, 0])
    assert have.sum() > 100
    np.testing.assert_array_equal(z2[:, :2], z[:, :2])
    np.testing.assert_array_equal(h2, h)
    assert np.all(np.isnan(z2[:, 2])) and np.all(np.isfinite(z[have, 2]))


@pytest.mark.parametrize("seed, ratio", [(0, 1.0), (3, 0.95), (5, 0.95)])
def test_gnss_heights_enter_the_filter_once(seed, ratio, monkeypatch):
    """The same heights as the height measurement and again as GNSS's up, their errors taken
    as independent, weigh the vertical channel as two receivers. Under one model, counted once
    against twice, measured on seeds 0-5: 0.39 / 0.40, 1.43 / 1.68, 1.55 / 1.93, 0.55 / 0.97,
    0.82 / 1.10, 1.07 / 1.47 mGal (seed 0 was 0.38 / 0.41 before the measurement model's offset
    term of 2026-12-06; and with the default identification on 69 quick unseen flights with their
    GNSS heights as the height channel: 24 better by more than 5 %, 2 worse, where the
    identified prior differs; docs/benchmarks.md)."""
    s, rec, init = _gnss_height_flight(seed)
    sol = estimate_anomaly(rec, FIXED, init, "platform")
    assert sol.identification["gnss_vertical_used"] is False
    assert any("the GNSS's own heights" in n for n in sol.identification["notes"])
    monkeypatch.setattr(solve, "_heights_are_gnss", lambda record: False)
    twice = estimate_anomaly(rec, FIXED, init, "platform")
    assert twice.identification["gnss_vertical_used"] is True
    assert rms_mid(sol, s) < ratio * rms_mid(twice, s)


def test_an_altimeter_of_its_own_keeps_gnss_up():
    """A flight with its own altimeter (5 cm, its own samples): the GNSS up component is used."""
    plan = {**GRID, "lines": {**GRID["lines"], "count": 2, "length_m": 8000.0}}
    sim = quick_sim(plan=plan, triad="platform", noise=NAVIGATION_GRADE, gnss_hz=2.0, altimeter_hz=2.0)
    s = simulate_flight(sim)
    rec, init = record_and_initial(s)
    assert not solve._heights_are_gnss(rec)
    sol = estimate_anomaly(rec, InmParams(), init, "platform")
    assert sol.identification["gnss_vertical_used"] is True


@pytest.mark.parametrize("field, before, after", [("seed_smooth", 0.064, 0.241), ("markov", 8.598, 6.812)])
def test_gnss_heights_quieter_than_the_altimeter_are_weighed_by_their_own_noise(field, before, after):
    """A barometric-class altimeter (2 m per sample) beside survey GNSS (0.1 m), both 5 Hz: the
    GNSS's up component is weighed by its identified 0.1 m, not the default 2 m that left it all
    but unused (given the figure, as before: the errors measured, docs/method.md).  Over the
    smooth field the figure given is now the better (0.447 -> 0.064 mGal once the field's
    variance is measured through a Hann window: the prior holds the field), the weighed heights
    not (0.241: their prior is chosen against the altimeter's noise, 10x the pass's; docs/
    method.md, "GNSS heights weighed by their own noise").  The suite's draws (an altimeter of
    1.5-15 cm beside 0.3-3 m GNSS) keep the default."""
    noise = {
        **NAVIGATION_GRADE,
        "altimeter": {"sigma_m": 2.0},
        "gnss": {"horizontal_sigma_m": 0.1, "vertical_sigma_m": 0.1},
    }
    sim = quick_sim(plan=GRID, noise=noise, field=field, gnss_hz=5.0, altimeter_hz=5.0, seed=3, imu_hz=50)
    s = simulate_flight(sim)
    rec, init = record_and_initial(s)
    weighed = estimate_anomaly(rec, InmParams(), init, "platform")
    up = weighed.identification["gnss_vertical_sigma_m"]
    assert up["value"] == pytest.approx(0.1, rel=0.1) and "the altimeter's 1.94 m" in up["how"]
    default = InmParams(gnss_vertical_sigma_m=2.0, given=frozenset({"gnss_vertical_sigma_m"}))
    held = estimate_anomaly(rec, default, init, "platform")
    assert "gnss_vertical_sigma_m" not in held.identification
    assert rms_mid(weighed, s) == pytest.approx(after, rel=0.02)
    assert rms_mid(held, s) == pytest.approx(before, rel=0.02)
    # the suite's kind of heights: the altimeter the better channel, nothing identified for the GNSS
    s2 = simulate_flight(quick_sim(plan=GRID, noise=NAVIGATION_GRADE, field=field, seed=3))
    rec2, init2 = record_and_initial(s2)
    assert "gnss_vertical_sigma_m" not in estimate_anomaly(rec2, InmParams(), init2, "platform").identification


def test_an_altimeter_offset_from_quieter_gnss_heights_is_taken_off():
    """The same altimeter 3 m off the GNSS heights and the GNSS out for 300 s: weighed by their
    own noise beside an altimeter metres away, the estimate would jump at each end of the
    outage (64 mGal on a fuzzing flight before the offset came off), so the altimeter is moved
    onto the GNSS heights first and said; the default weighing (given) leans on the offset
    altimeter across the outage (28.3 mGal)."""
    from gravsurvey.io.record import GnssChannel

    noise = {
        **NAVIGATION_GRADE,
        "altimeter": {"sigma_m": 2.0, "mean_m": 3.0},
        "gnss": {"horizontal_sigma_m": 0.1, "vertical_sigma_m": 0.1},
    }
    s = simulate_flight(
        quick_sim(plan=GRID, noise=noise, field="markov", gnss_hz=5.0, altimeter_hz=5.0, seed=3, imu_hz=50)
    )
    rec, init = record_and_initial(s)
    g = rec.gnss
    keep = (g.time < 600.0) | (g.time > 900.0)
    rec = dataclasses.replace(rec, gnss=GnssChannel(g.time[keep], g.lat[keep], g.lon[keep], g.height[keep]))
    weighed = estimate_anomaly(rec, InmParams(), init, "platform")
    up = weighed.identification["gnss_vertical_sigma_m"]
    assert up["altimeter_offset_m"] == pytest.approx(-3.0, abs=0.05) and "moved -2.99 m onto the GNSS's" in up["how"]
    held = estimate_anomaly(
        rec, InmParams(gnss_vertical_sigma_m=2.0, given=frozenset({"gnss_vertical_sigma_m"})), init, "platform"
    )
    assert rms_mid(weighed, s) == pytest.approx(8.29, rel=0.02)
    assert rms_mid(held, s) == pytest.approx(28.26, rel=0.02)


def test_quieter_gnss_heights_that_wander_are_not_weighed_by_their_white_noise():
    """GNSS heights 20x quieter than a 2-m altimeter but with a 10-cm, 300-s Gauss-Markov error
    (a GNSS solution's slow error) on an hour's straight line: their fit finds the wander
    (identify.WALK_MIN_LOG_LR; measured 45) and they keep the default weight, the altimeter
    leading - the estimate is the one with the GNSS figure given (0.95 mGal); weighed by their
    white 0.1 m the filter follows the wander (3.46)."""
    noise = {
        **NAVIGATION_GRADE,
        "altimeter": {"sigma_m": 2.0},
        "gnss": {
            "horizontal_sigma_m": 0.1,
            "vertical_sigma_m": 0.1,
            "vertical_markov_sigma_m": 0.1,
            "markov_tau_s": 300.0,
        },
    }
    sim = quick_sim(
        duration_s=3600.0, noise=noise, field="seed_smooth", gnss_hz=5.0, altimeter_hz=5.0, seed=3, imu_hz=50
    )
    s = simulate_flight(sim)
    rec, init = record_and_initial(s)
    sol = estimate_anomaly(rec, InmParams(), init, "platform")
    up = sol.identification["gnss_vertical_sigma_m"]
    assert up["value"] is None and "wander" in up["how"] and up["height_walk_log_likelihood_ratio"] > 20
    assert sol.params.gnss_vertical_sigma_m == InmParams().gnss_vertical_sigma_m
    held = estimate_anomaly(
        rec, InmParams(gnss_vertical_sigma_m=2.0, given=frozenset({"gnss_vertical_sigma_m"})), init, "platform"
    )
    white = estimate_anomaly(
        rec, InmParams(gnss_vertical_sigma_m=0.1, given=frozenset({"gnss_vertical_sigma_m"})), init, "platform"
    )
    assert rms_mid(sol, s) == pytest.approx(rms_mid(held, s), rel=0.02)
    assert rms_mid(white, s) > 3.0 * rms_mid(sol, s)


def test_a_wander_on_short_lines_is_found_on_the_whole_record():
    """Carrier-phase GNSS heights as the height channel on a grid of 8-km lines (straight
    stretches of ~5 min) with a 5-cm, 300-s Gauss-Markov error: the straight stretches alone
    leave too few bins below where the wander overtakes the white noise (log-likelihood ratio
    2.5), the whole record shows it (27): found there, 1.80 -> 0.16 mGal (0.32 without the
    wander, where nothing is found on either)."""
    rows = {}
    for mk in (0.0, 0.05):
        noise = {
            **NAVIGATION_GRADE,
            "altimeter": {"sigma_m": 0.0},
            "gnss": {
                "horizontal_sigma_m": 0.03,
                "vertical_sigma_m": 0.05,
                "vertical_markov_sigma_m": mk,
                "markov_tau_s": 300.0,
            },
        }
        sim = quick_sim(plan=GRID, noise=noise, field="seed_smooth", gnss_hz=5.0, altimeter_hz=5.0, seed=3, imu_hz=50)
        s = simulate_flight(sim)
        rec, init = record_and_initial(s)
        g = rec.gnss
        rec = dataclasses.replace(rec, altimeter=AltimeterChannel(g.time, g.height))
        sol = estimate_anomaly(rec, InmParams(), init, "platform")
        rows[mk] = (sol.identification["height_walk"], rms_mid(sol, s))
    clean, wander = rows[0.0][0], rows[0.05][0]
    assert not clean["applied"]
    assert wander["applied"] and wander["found_on"] == "whole record"
    assert wander["height_walk_m"] == pytest.approx(math.sqrt(2 * 0.05**2 / 300.0), rel=0.25)
    assert rows[0.05][1] < 1.5 * rows[0.0][1]
