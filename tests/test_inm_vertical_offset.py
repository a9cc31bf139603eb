"""The constant the anomaly prior cannot hold: the gravimeter's bias and the field's mean, taken
off the specific force before the passes with the chosen prior where it exceeds three of the
prior's sigmas (gravsurvey.inm.solve, ``VERTICAL_OFFSET_PER_PRIOR``; docs/method.md, "The
vertical channel's constant").

Truth: the simulator's unseen-flight generator, flight U2635 cut to 40 min at 50 Hz (a
navigation-grade platform over a 0.3-mGal field, with a gravimeter bias of 4.57 mGal), as
drawn and with the bias set to zero; and a rolled triad's specific force, against which the
offset's direction is checked.
"""

import warnings
from types import SimpleNamespace

import numpy as np
import pytest

from gravsurvey.geodesy import MGAL, WGS84, geodetic_to_ecef, mat_ie
from gravsurvey.inm import solve
from gravsurvey.inm.params import InmParams
from gravsurvey.io.record import AltimeterChannel, FlightRecord, ImuChannel
from gravsurvey.simulate.run import simulate_flight
from gravsurvey.simulate.unseen import draw_flight_spec, limit_spec
from sim_record import record_and_initial
from test_inm_accel_noise import _rms_mgal


@pytest.fixture(scope="module")
def u2635():
    spec = limit_spec(draw_flight_spec(2635), 2400.0, 50.0)
    assert spec["triad"] == "platform"
    grav = spec["sim"]["flights"][0]["sensors"]["gravimeter"]
    assert grav["bias_mps2"] > 4.5e-5  # the draw this test is about
    drawn = simulate_flight(spec["sim"])
    grav["bias_mps2"] = 0.0
    return drawn, simulate_flight(spec["sim"])


def _estimate(s):
    rec, _ = record_and_initial(s)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sol = solve.estimate_anomaly(rec, InmParams(), None, "platform")
    return sol, [str(w.message) for w in caught]


def test_the_gravimeter_bias_is_taken_off_and_the_estimate_is_as_without_it(u2635):
    drawn, unbiased = u2635
    sol, shown = _estimate(drawn)
    ident = sol.identification
    # the constant found: the bias (4.57 mGal) and the field's mean over the flight (0.02)
    assert ident["vertical_offset_mgal"] == pytest.approx(4.59, abs=0.5)
    # left in, the prior's pull made the likelihood take a tactical gyro (10 deg/h, and the
    # filter at 5 Hz) on this navigation-grade platform, and the smoothed estimate 1.10 mGal
    # off (10 min from either end); without the bias it is 0.36
    assert ident["gyro_drift_degph"]["value"] == 0.01
    assert not any("gyros are noisier" in m for m in shown)
    assert "filter_rate_hz" not in ident
    ref, _ = _estimate(unbiased)
    # without the bias the constant (the field's mean) is within the prior's reach: left
    assert ref.identification["vertical_offset_mgal"] == 0.0
    err, err_ref = _rms_mgal(drawn, sol, 600.0), _rms_mgal(unbiased, ref, 600.0)
    assert err < 1.25 * err_ref and err < 0.45
    # the estimate keeps its level: the constant is added back (the disturbance's mean plus
    # the bias, as the estimate without the change had it)
    assert np.mean(sol.g_smooth) / MGAL == pytest.approx(np.mean(ref.g_smooth) / MGAL + 4.57, abs=0.3)


def test_the_offset_is_taken_along_the_ellipsoid_normal():
    n = 200
    t = np.arange(n) * 0.02
    lat, lon, h = np.radians(45.0), np.radians(10.0), 1000.0
    r_e = geodetic_to_ecef(np.full(n, lat), np.full(n, lon), np.full(n, h), WGS84)
    m_ie = mat_ie(t, WGS84.omega)
    r_i = np.einsum("nij,nj->ni", m_ie, r_e)
    up_e = np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])
    east_e = np.array([-np.sin(lon), np.cos(lon), 0.0])
    north_e = np.cross(up_e, east_e)
    # a triad rolled by 0.3 rad about north: its third axis is not the normal
    a = 0.3
    mat_et = np.stack([np.cos(a) * east_e + np.sin(a) * up_e, north_e, -np.sin(a) * east_e + np.cos(a) * up_e], axis=1)
    mat_it = np.einsum("nij,jk->nik", m_ie, mat_et)
    nav = SimpleNamespace(time=t, r_i=r_i, v_i=np.zeros_like(r_i), mat_it=mat_it)
    f_t = np.tile([0.0, 0.0, 9.8], (n, 1))
    rec = FlightRecord(0, ImuChannel(t, f_t.copy(), np.zeros((n, 3))), AltimeterChannel(t, np.full(n, h)), None)
    out = solve._vertical_offset_off(rec, nav, 5e-5, WGS84)
    # the normal on this triad: (sin a, 0, cos a); the caller's record kept
    assert np.allclose(out.imu.specific_force_t - f_t, -5e-5 * np.array([np.sin(a), 0.0, np.cos(a)]), atol=1e-12)
    assert np.array_equal(rec.imu.specific_force_t, f_t)
