"""Parameters, initial state and georeferencing helpers."""

import math

import numpy as np
import pytest

from gravsurvey.errors import ConfigError
from gravsurvey.georef import project, utm_epsg
from gravsurvey.inm.params import (
    InmParams,
    initial_state_from_gnss,
    mat_nb_from_attitude,
    solvability_warnings,
)
from gravsurvey.io.record import AltimeterChannel, FlightRecord, ImuChannel
from gravsurvey.settings import initial_state, inm_params


def test_defaults_are_seed_004():
    p = inm_params({})
    assert (p.accel_noise_mps2, p.gravimeter_sigma_mps2, p.gravimeter_lambda_per_s) == (1e-3, 1e-6, 0.025)
    assert (p.anomaly_lambda_per_m, p.anomaly_sigma_mps2, p.altimeter_sigma_m) == (1e-5, 1e-3, 1.0)
    assert (p.initial_position_sigma_m, p.initial_velocity_sigma_mps) == (50.0, 0.05)
    assert p.radius_source == "altimeter" and p.filter_rate_hz == 1.0
    assert p.gyro_drift_radps == pytest.approx(0.01 * math.pi / 180 / 3600)


@pytest.mark.parametrize(
    "d,msg",
    [
        (
            {"acel_noise_mps2": 1e-3},
            "model.acel_noise_mps2: unknown key (did you mean 'accel_noise_mps2'?); valid keys",
        ),
        ({"altimeter_sigma_m": -1.0}, "model.altimeter_sigma_m: expected a number >= 0, got -1.0"),
        ({"gravimeter_lambda_per_s": -0.1}, "model.gravimeter_lambda_per_s: expected a number >= 0, got -0.1"),
        ({"filter_rate_hz": 0}, "model.filter_rate_hz: expected a number >= 0.2, got 0"),
        ({"anomaly_sigma_mps2": "big"}, "model.anomaly_sigma_mps2: expected a number >= 0, got 'big'"),
        ({"accel_noise_mps2": True}, "model.accel_noise_mps2: expected a number >= 0, got True"),
        ({"radius_source": "gps"}, "model.radius_source: expected one of altimeter, computed, got 'gps'"),
        ({"gyro_drift_degph": float("nan")}, "model.gyro_drift_degph: expected a finite number >= 0, got nan"),
        ({"attitude_passes": 2.0}, "model.attitude_passes: expected an integer in [1, 5], got 2.0"),
        ({"attitude_passes": 6}, "model.attitude_passes: expected an integer in [1, 5], got 6"),
        ({"target_resolution_m": 0}, "model.target_resolution_m: expected a number > 0, got 0"),
        ({"accel_bias_mps2": 0.0}, "model.accel_bias_mps2: expected a number in (0, 0.5], got 0.0"),
        ({"accel_bias_mps2": 9.8}, "model.accel_bias_mps2: expected a number in (0, 0.5], got 9.8"),
        (
            {"accel_bias_mps2": 1e-3, "accel_bias_states": False},
            "model.accel_bias_states: expected null or true with accel_bias_mps2 given (0.001 m/s^2: the biases "
            "are estimated as states), got false",
        ),
    ],
)
def test_from_dict_rejects_nonsense_naming_the_key(d, msg):
    with pytest.raises(ConfigError) as e:
        inm_params(d)
    assert str(e.value).startswith(msg)
    assert "\n" not in str(e.value)


def test_from_dict_key_path_and_ints():
    with pytest.raises(ConfigError, match=r"^flights\[0\]\.model\.altimeter_sigma_m"):
        inm_params({"altimeter_sigma_m": -2}, key_path="flights[0].model")
    p = inm_params({"filter_rate_hz": 2, "radius_source": "computed"})
    assert p.filter_rate_hz == 2.0 and isinstance(p.filter_rate_hz, float) and p.radius_source == "computed"
    with pytest.raises(ConfigError, match="model: expected a mapping"):
        inm_params([1, 2])


def test_settings_built_in_python_have_defaults_and_the_same_rules():
    """A notebook user writes InmParams(...): the schema's defaults, the schema's checks."""
    p = InmParams()
    assert p == inm_params({}) and p.given == frozenset()
    assert InmParams(altimeter_sigma_m=0.3).given == frozenset({"altimeter_sigma_m"})
    assert inm_params({"altimeter_sigma_m": 1.0}).given == frozenset({"altimeter_sigma_m"})  # written = held
    with pytest.raises(ConfigError, match=r"^model\.filter_rate_hz: expected a number >= 0\.2, got -1$"):
        InmParams(filter_rate_hz=-1)


def test_solvability_warning_within_factor_two():
    p = InmParams()  # lambda_f3 = 0.025 1/s, lambda_s = 1e-5 1/m: inseparable at 2500 m/s
    assert solvability_warnings(p, 50.0) == []
    assert solvability_warnings(p, [1250.0 * 0.99, 5000.0 * 1.01]) == []
    w = solvability_warnings(p, [1300.0, 2500.0, 4900.0])
    assert len(w) == 3 and all("gravimeter_lambda_per_s" in x for x in w)
    p2 = InmParams(anomaly_lambda_per_m=5e-4)  # lambda_g = 0.025 at 50 m/s
    assert len(solvability_warnings(p2, 50.0)) == 1


def test_attitude_convention_matches_simulator():
    from gravsurvey.simulate.trajectory import euler_to_mat_nb

    rng = np.random.default_rng(0)
    for roll, pitch, heading in rng.uniform(-3, 3, size=(10, 3)):
        np.testing.assert_allclose(
            mat_nb_from_attitude(roll, pitch, heading),
            euler_to_mat_nb(np.array(roll), np.array(pitch), np.array(heading)),
            atol=1e-15,
        )
    # physics of the convention: heading 90 deg -> nose east; roll +: right wing (-y) down
    m = mat_nb_from_attitude(math.radians(10), 0.0, math.radians(90))
    np.testing.assert_allclose(m[:, 0], [1, 0, 0], atol=1e-15)
    assert m[2, 1] > 0  # left wing up


def test_initial_state():
    d = {
        "lat_deg": 45.0,
        "lon_deg": 135.0,
        "height_m": 1000.0,
        "velocity_enu_mps": [50.0, 0.0, 0.0],
        "attitude_deg": [0.0, 0.0, 90.0],
    }
    st = initial_state(d, "strapdown")
    assert st.lat == pytest.approx(math.pi / 4) and st.height == 1000.0
    np.testing.assert_allclose(st.mat_nt @ [1, 0, 0], [1, 0, 0], atol=1e-15)
    stp = initial_state({k: v for k, v in d.items() if k != "attitude_deg"}, "platform")
    np.testing.assert_array_equal(stp.mat_nt, np.eye(3))
    with pytest.raises(ConfigError, match=r"^flights\[0\]\.initial\.attitude_deg: missing"):
        initial_state({k: v for k, v in d.items() if k != "attitude_deg"}, "strapdown", "flights[0].initial")
    with pytest.raises(ConfigError, match=r"initial\.velocity_enu_mps: expected a list of 3 numbers"):
        initial_state({**d, "velocity_enu_mps": [1, 2]}, "platform")
    with pytest.raises(ConfigError, match=r"initial\.lat_dg: unknown key \(did you mean 'lat_deg'\?\)"):
        initial_state({**d, "lat_dg": 1}, "platform")
    with pytest.raises(ConfigError, match=r"^initial\.lat_deg: expected a number in \(-90, 90\), got 95$"):
        initial_state({**d, "lat_deg": 95}, "platform")


def test_initial_state_from_gnss_errors():
    rec = FlightRecord(
        0, ImuChannel(np.arange(5.0), np.zeros((5, 3)), np.zeros((5, 3))), AltimeterChannel(np.arange(5.0), np.zeros(5))
    )
    with pytest.raises(ConfigError, match="no GNSS channel"):
        initial_state_from_gnss(rec, "platform")


def test_utm_projection_against_known_point():
    # EPSG:32653 (UTM 53N): 45 N 135 E is the zone's central meridian -> easting 500 km,
    # northing = k0 * meridian arc length to 45 deg = 0.9996 * 4984944.378 m (WGS84)
    e, n, code = project(np.radians([45.0]), np.radians([135.0]))
    assert code == 32653
    assert e[0] == pytest.approx(500000.0, abs=1e-3)
    assert n[0] == pytest.approx(0.9996 * 4984944.378, abs=0.01)
    assert utm_epsg(np.radians([-33.9]), np.radians([18.4])) == 32734
    e2, n2, c2 = project(np.radians([45.0]), np.radians([135.0]), epsg=3857)
    assert c2 == 3857 and e2[0] == pytest.approx(6378137.0 * math.radians(135.0), rel=1e-12)


def test_projection_rejects_bad_epsg():
    with pytest.raises(ConfigError, match=r"^output\.epsg: unknown EPSG code 99999"):
        project(np.radians([45.0]), np.radians([135.0]), epsg=99999)
    with pytest.raises(ConfigError, match=r"not a projected CRS"):
        project(np.radians([45.0]), np.radians([135.0]), epsg=4326)
    with pytest.raises(ConfigError, match=r"expected an integer EPSG code"):
        project(np.radians([45.0]), np.radians([135.0]), epsg="32653")
