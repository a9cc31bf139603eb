"""The gyros' white drift chosen by the filter's likelihood where a screen asks for it
(gravsurvey.inm.solve.choose_gyro_noise; docs/method.md, "Gyro noise by likelihood").

Truth: the simulator (gravsurvey/simulate) and its unseen-flight generator, flight U007 cut to
40 min at 50 Hz (strapdown, 1.7 deg of attitude turbulence), as drawn (navigation-grade gyros,
0.01 deg/h in 1 s) and with a fibre-optic IMU's gyros (0.72 deg/h: an angle random walk of
0.012 deg/sqrt(h)).
"""

import math

import numpy as np
import pytest

from gravsurvey.geodesy import MGAL, STANDARD_GRAVITY_MPS2
from gravsurvey.inm import solve
from gravsurvey.inm.identify import field_attitude_noise_degph
from gravsurvey.inm.params import RADPS_PER_DEGPH, InmParams
from gravsurvey.settings import inm_params
from gravsurvey.inm.solve import choose_gyro_noise, estimate_anomaly, gyro_noise_warning, may_choose_gyro_noise
from gravsurvey.simulate.run import simulate_flight
from gravsurvey.simulate.unseen import draw_flight_spec, limit_spec
from sim_record import record_and_initial, with_tactical_imu
from test_inm_accel_noise import _Sol as _AccelSol
from test_inm_accel_noise import _rms_mgal, stand_in_estimate


class _Sol(_AccelSol):
    """The accelerometer-noise tests' stand-in estimate, with the screen's gain ``screen``."""

    def __init__(self, ll, seed=0, screen=float("nan")):
        super().__init__(ll, seed)
        self.gyro_screen_z = screen


def _search(lls, screen, fail_at=None):
    """choose_gyro_noise over a stand-in estimate whose likelihood per gyro noise is ``lls`` and
    whose screen gained ``screen``."""
    estimate, calls = stand_in_estimate("gyro_drift_degph", lls, fail_at)
    (best, shown), params, report = choose_gyro_noise(
        (_Sol(lls[0.01], screen=screen), ["default's warning"]), InmParams(), estimate
    )
    assert params.gyro_drift_degph == report["value"]
    assert shown == (["default's warning"] if report["value"] == 0.01 else [])
    return best, calls, report


def test_the_candidates_run_only_when_the_screen_asks():
    lls = {0.01: 10.0, 0.1: 50.0, 1.0: 60.0, 10.0: 20.0}
    _, calls, report = _search(lls, screen=solve.GYRO_SCREEN_Z - 0.1)
    assert calls == [] and report["value"] == 0.01 and report["how"].startswith("default")
    assert report["screen_z"] == pytest.approx(solve.GYRO_SCREEN_Z - 0.1)
    _, calls, report = _search(lls, screen=float("nan"))
    assert calls == [] and report["screen_z"] is None
    # asked: every candidate, each kept where clearly more likely than the best before it
    best, calls, report = _search(lls, screen=15.0)
    assert calls == [0.1, 1.0, 10.0] and report["value"] == 1.0
    assert best.log_likelihood == 60.0 and report["how"].startswith("filter likelihood")
    assert report["gain_z"]["10"] < -2.0 and set(report["log_likelihood"]) == {"0.01", "0.1", "1", "10"}
    # more likely but within the scatter: the one before stays
    _, calls, report = _search({0.01: 10.0, 0.1: 10.1, 1.0: 10.0, 10.0: 9.0}, screen=15.0)
    assert calls == [0.1, 1.0, 10.0] and report["value"] == 0.01 and 0.0 < report["gain_z"]["0.1"] < 2.0


def test_a_gyro_candidate_past_one_that_gains_nothing_is_still_tried():
    """The likelihood need not rise step by step (quick tactical U2004: 0.1 deg/h as likely as
    1, with the prior chosen on its own estimate, and 10 far more likely than either)."""
    best, calls, report = _search({0.01: 10.0, 0.1: 50.0, 1.0: 50.2, 10.0: 90.0}, screen=15.0)
    assert calls == [0.1, 1.0, 10.0] and report["value"] == 10.0 and best.log_likelihood == 90.0
    assert report["gain_z"]["1"] < 2.0 < report["gain_z"]["10"]


def test_a_noisier_gyro_carries_its_grades_bias_prior_unless_the_config_gives_one():
    lls = {0.01: 10.0, 0.1: 50.0, 1.0: 60.0, 10.0: 20.0}
    estimate, _ = stand_in_estimate("gyro_drift_degph", lls)
    seen = []

    def recording(p):
        seen.append((p.gyro_drift_degph, p.gyro_bias_sigma_degph))
        return estimate(p)

    _, params, report = choose_gyro_noise((_Sol(lls[0.01], screen=15.0), []), InmParams(), recording)
    default_bias = InmParams().gyro_bias_sigma_degph
    k = solve.GYRO_BIAS_PER_WHITE
    assert seen == [(0.1, max(default_bias, 0.1 * k)), (1.0, max(default_bias, k)), (10.0, 10.0 * k)]
    assert params.gyro_drift_degph == 1.0 and params.gyro_bias_sigma_degph == max(default_bias, k)
    assert report["gyro_bias_sigma_degph"] == params.gyro_bias_sigma_degph
    # a bias prior given in the config stays
    given = inm_params({"gyro_bias_sigma_degph": 0.02})
    seen.clear()
    _, params, report = choose_gyro_noise((_Sol(lls[0.01], screen=15.0), []), given, recording)
    assert {b for _, b in seen} == {0.02} and params.gyro_bias_sigma_degph == 0.02
    assert "gyro_bias_sigma_degph" not in report


def test_a_gyro_candidate_that_fails_is_reported_and_the_rest_tried():
    _, calls, report = _search({0.01: 10.0, 0.1: 50.0, 1.0: 60.0, 10.0: 20.0}, screen=15.0, fail_at=1.0)
    assert calls == [0.1, 1.0, 10.0] and report["value"] == 0.1
    assert "did not settle" in report["failed"]["1"] and report["gain_z"]["10"] < -2.0


def test_a_flight_without_a_given_gyro_noise_chooses_on_either_triad():
    assert may_choose_gyro_noise(InmParams(), "strapdown")
    assert may_choose_gyro_noise(InmParams(), "platform")
    assert not may_choose_gyro_noise(InmParams(gyro_drift_degph=0.5), "platform")
    assert not may_choose_gyro_noise(InmParams(gyro_drift_degph=0.5), "strapdown")
    assert not may_choose_gyro_noise(InmParams(identify=False), "strapdown")
    c = solve.GYRO_NOISE_CANDIDATES_DEGPH
    assert c == tuple(sorted(c)) and c[0] > InmParams().gyro_drift_degph


@pytest.fixture(scope="module")
def u007():
    spec = limit_spec(draw_flight_spec(7), 2400.0, 50.0)
    assert spec["triad"] == "strapdown"
    drawn = simulate_flight(spec["sim"])
    spec["sim"]["flights"][0]["sensors"]["gyro"]["white_drift_degph"] = 0.72
    return drawn, simulate_flight(spec["sim"])


def test_fibre_optic_gyros_are_found_and_the_estimate_recovers(u007):
    """With the default gyro noise the fibre-optic flight's estimate is 2.3x the one as drawn; the
    screen asks (a gain of ~33 standard errors), the candidates find 1 deg/h and the estimate
    comes back to within 1.3x, with a warning that names the figure."""
    drawn, fog = u007
    rms_drawn = _rms_mgal(drawn, estimate_anomaly(record_and_initial(drawn)[0], InmParams(), None, "strapdown"))
    sol = estimate_anomaly(record_and_initial(fog)[0], InmParams(), None, "strapdown")
    report = sol.identification["gyro_drift_degph"]
    assert report["screen_z"] > solve.GYRO_SCREEN_Z and report["value"] == 1.0
    # the default figure given in the config: held (no screen, no candidates)
    fixed = estimate_anomaly(record_and_initial(fog)[0], inm_params({"gyro_drift_degph": 0.01}), None, "strapdown")
    assert "gyro_drift_degph" not in fixed.identification
    rms, rms_fixed = _rms_mgal(fog, sol), _rms_mgal(fog, fixed)
    assert rms_fixed > 1.8 * rms_drawn
    assert rms < 1.3 * rms_drawn, (rms, rms_drawn, rms_fixed)
    assert [
        w
        for w in sol.warnings
        if w.startswith(
            "the gyros are noisier than the default model's: the filter's likelihood clearly prefers a white drift of 1 deg/h (one-second sigma) to 0.01"
        )
    ]


def test_navigation_grade_gyros_keep_the_default_without_running_a_candidate(u007, monkeypatch):
    """As drawn the screen does not ask (its gain is negative), so no candidate runs: the cost is
    the screen's one pass."""
    drawn = u007[0]
    runs = []
    real = solve._estimate_once

    def counted(*args, **kwargs):
        runs.append(args[1].gyro_drift_degph)
        return real(*args, **kwargs)

    monkeypatch.setattr(solve, "_estimate_once", counted)
    sol = estimate_anomaly(record_and_initial(drawn)[0], InmParams(), None, "strapdown")
    report = sol.identification["gyro_drift_degph"]
    assert report["value"] == 0.01 and report["screen_z"] < solve.GYRO_SCREEN_Z
    assert set(runs) == {0.01} and math.isfinite(sol.log_likelihood)
    assert not [w for w in sol.warnings if w.startswith("the gyros are noisier")]


def test_a_platforms_tactical_imu_is_found_too():
    """Quick U008 (a platform, 40 min at 50 Hz) with a tactical IMU (0.1 deg/sqrt(h), 0.75 deg/h
    biases, 1-mg accelerometer biases): held at the default gyro noise the smoothed estimate is
    24 mGal off (1.43 as drawn); the screen asks, the likelihood takes 10 deg/h, the passes
    follow the smoothed attitude and take the accelerometer biases found off: 1.13 mGal (1.24
    before the anomaly prior was identified about the followed attitude, 3.0 with the biases
    left in, 26 with neither)."""
    spec = limit_spec(draw_flight_spec(8), 2400.0, 50.0)
    assert spec["triad"] == "platform"
    drawn = simulate_flight(spec["sim"])
    tactical = simulate_flight(with_tactical_imu(spec)["sim"])
    rec = record_and_initial(tactical)[0]
    sol = estimate_anomaly(rec, InmParams(), None, "platform")
    fixed = estimate_anomaly(rec, inm_params({"gyro_drift_degph": 0.01}), None, "platform")
    assert sol.identification["gyro_drift_degph"]["value"] > 1.0 and sol.follow_tilts_rad
    assert sol.accel_bias_taken_off and sol.identification["accel_bias_found"]["found_mps2"][0] > 5e-3
    assert [w for w in sol.warnings if "taken off between passes with a prior of" in w]
    rms, rms_fixed = _rms_mgal(tactical, sol), _rms_mgal(tactical, fixed)
    drawn_sol = estimate_anomaly(record_and_initial(drawn)[0], InmParams(), None, "platform")
    assert "accel_bias_found" not in drawn_sol.identification and not drawn_sol.accel_bias_taken_off
    rms_drawn = _rms_mgal(drawn, drawn_sol)
    assert rms < 0.1 * rms_fixed and rms < 1.3 * rms_drawn, (rms, rms_fixed, rms_drawn)


def test_the_field_attitude_noise_is_a_markov_tilts_white_rate():
    """A horizontal component of the prior (sigma / sqrt(2), the same correlation) read as a tilt
    ``dg_h / g``: the variance of its one-second increments, ``2 s^2 (1 - exp(-1 / tau))``, is the
    one-second variance of a gyro white drift of the figure, to the ``1 + 1 / (2 tau)`` by which a
    Markov rate is white only above ``1 / tau`` (0.5 % at 100 s)."""
    for sigma_mgal, tau in ((16.0, 231.0), (1.0, 100.0), (60.0, 2000.0)):
        q = field_attitude_noise_degph(sigma_mgal * MGAL, tau) * RADPS_PER_DEGPH
        s_tilt = sigma_mgal * MGAL / math.sqrt(2.0) / STANDARD_GRAVITY_MPS2
        ratio = q**2 / (2.0 * s_tilt**2 * -math.expm1(-1.0 / tau))
        assert 1.0 <= ratio < 1.0 + 0.6 / tau, (tau, ratio)
    # U2702 of the fresh draws: its prior, 15.8 mGal over 231 s, asks 0.22 deg/h
    assert field_attitude_noise_degph(1.58e-4, 231.0) == pytest.approx(0.219, abs=0.001)
    for bad in ((None, 100.0), (1e-4, 0.0), (0.0, 100.0), (float("nan"), 100.0), ("x", 1.0)):
        assert field_attitude_noise_degph(*bad) is None


def test_the_warning_names_the_field_where_it_could_be_the_field():
    model = {"anomaly_sigma_mps2": 1.6e-4, "anomaly_tau_s": 231.0}
    gyro = gyro_noise_warning(10.0, 0.01, 0.05, model)
    assert gyro.startswith("the gyros are noisier than the default model's: the filter's likelihood")
    assert "horizontal" not in gyro and gyro == gyro_noise_warning(10.0, 0.01, None, {})
    both = gyro_noise_warning(1.0, 0.01, 0.16, model)
    assert both.startswith("the gyros are noisier than the default model's, or the attitude takes up the field's")
    assert "at the prior's 16 mGal over 231 s, ask about 0.16 deg/h of it" in both and "drift of 1 deg/h" in both
    # the factor's edge: one candidate step
    assert "horizontal" in gyro_noise_warning(1.0, 0.01, 1.0 / solve.FIELD_GYRO_FACTOR, model)
    assert "horizontal" not in gyro_noise_warning(1.0, 0.01, 0.99 / solve.FIELD_GYRO_FACTOR, model)


def test_a_strong_fields_horizontal_components_pose_as_gyro_noise():
    """Quick U2734 of the fresh draws (a platform, 40 min at 50 Hz, navigation-grade gyros of
    0.02 deg/h, a 95-mGal field): the screen asks and the likelihood takes 1 deg/h, the warning
    names the field's horizontal components as a cause (1 deg/h within ten times the 0.16 they
    ask).  The same flight with the field's horizontal components set to zero in the simulator
    keeps the default, the screen far below its threshold: the deflections of the vertical, not
    the gyros, asked for the noisier gyro."""
    spec = limit_spec(draw_flight_spec(2734), 2400.0, 50.0)
    assert spec["triad"] == "platform"
    drawn = simulate_flight(spec["sim"])
    sol = estimate_anomaly(record_and_initial(drawn)[0], InmParams(), None, "platform")
    report = sol.identification["gyro_drift_degph"]
    assert report["screen_z"] > solve.GYRO_SCREEN_Z and report["value"] >= 0.1
    assert report["value"] <= solve.FIELD_GYRO_FACTOR * report["field_attitude_noise_degph"]
    assert [w for w in sol.warnings if "or the attitude takes up the field's horizontal components" in w]
    spec["sim"]["field"]["horizontal"] = False
    vertical_only = simulate_flight(spec["sim"])
    # the same flight and field but for the horizontal components
    assert np.abs(drawn.truth["dg_north"]).max() > 1e-4 and not vertical_only.truth["dg_north"].any()
    assert np.array_equal(vertical_only.truth["disturbance"], drawn.truth["disturbance"])
    flat = estimate_anomaly(record_and_initial(vertical_only)[0], InmParams(), None, "platform")
    report = flat.identification["gyro_drift_degph"]
    assert report["value"] == 0.01 and report["screen_z"] < solve.GYRO_SCREEN_Z - 10.0
    assert not [w for w in flat.warnings if w.startswith("the gyros are noisier")]
