"""SIM.yaml validation: one-line ConfigError naming the key path; shipped configs are valid."""

import copy
from pathlib import Path

import pytest
import yaml

from gravsurvey.errors import ConfigError
from gravsurvey.simulate.run import load_sim_config, quick_sim

CONFIGS = Path(__file__).resolve().parents[1] / "configs"


def grid_sim():
    sim = quick_sim()
    sim["flights"][0]["plan"] = {
        "kind": "grid",
        "origin_lat_deg": 45.0,
        "origin_lon_deg": 135.0,
        "lines": {"count": 3, "spacing_m": 2000.0, "length_m": 8000.0},
        "ties": {"count": 2, "spacing_m": 4000.0},
    }
    return sim


def edit(sim, path, value):
    sim = copy.deepcopy(sim)
    d = sim
    for k in path[:-1]:
        d = d.setdefault(k, {}) if isinstance(d, dict) else d[k]
    if value is KeyError:
        del d[path[-1]]
    else:
        d[path[-1]] = value
    return sim


CASES = [
    (("flights", 0, "plan", "speeed"), 50.0, "flights[0].plan.speeed", "speed_mps"),
    (("flights", 0, "rates", "imu_hz"), -10.0, "flights[0].rates.imu_hz", ">= 1"),
    (("flights", 0, "rates", "imu_hz"), 500.0, "flights[0].rates.imu_hz", "<= 200"),
    (("flights", 0, "rates", "gnss_hz"), 0.0, "flights[0].rates.gnss_hz", ">= 1"),
    (("flights", 0, "rates", "altimeter_hz"), "fast", "flights[0].rates.altimeter_hz", "expected a number"),
    (("flights", 0, "rates", "gnss_hz"), 25.0, "flights[0].rates.gnss_hz", "<= 20"),
    (("flights", 0, "rates", "altimeter_hz"), 20.5, "flights[0].rates.altimeter_hz", "<= 20"),
    (("flights", 0, "plan", "duration_s"), -5.0, "flights[0].plan.duration_s", "> 0"),
    (("flights", 0, "plan", "max_bank_deg"), 60.0, "flights[0].plan.max_bank_deg", "<= 35"),
    (("flights", 0, "plan", "origin_lat_deg"), 89.5, "flights[0].plan.origin_lat_deg", "<= 89 deg"),
    (("flights", 0, "triad"), "gimbal", "flights[0].triad", "platform"),
    (("flights", 0, "start_utc"), "yesterday", "flights[0].start_utc", "ISO 8601"),
    (("flights", 0, "start_utc"), "2024-06-01T08:00:00", "flights[0].start_utc", "time zone"),
    (("flights", 0, "start_utc"), KeyError, "flights[0].start_utc", "missing"),
    (
        ("flights", 0, "sensors", "gyro", "white_drift_degph"),
        -0.01,
        "flights[0].sensors.gyro.white_drift_degph",
        ">= 0",
    ),
    (("flights", 0, "sensors", "gyro", "bias_degph"), [0.1, 0.2], "flights[0].sensors.gyro.bias_degph", "3 numbers"),
    (("flights", 0, "sensors", "barometer"), {}, "flights[0].sensors.barometer", "unknown key"),
    (
        ("flights", 0, "turbulence"),
        {"vertical_sigma_m": 1.0, "min_period_s": 0.1},
        "flights[0].turbulence.min_period_s",
        "IMU samples",
    ),
    (("formats",), ["mcap_json", "hdf5"], "formats[1]", "mcap_ros2"),
    (("seeed",), 3, "seeed", "seed"),
    (("seed",), -1, "seed", ">= 0"),
    (("field",), {"type": "lumpy"}, "field.type", "seed_smooth"),
    (("ellipsoid",), "Clarke1866", "ellipsoid", "WGS84"),
    (("flights",), [], "flights", "non-empty"),
]


@pytest.mark.parametrize("path,value,key,hint", CASES)
def test_bad_values_name_the_key(path, value, key, hint):
    with pytest.raises(ConfigError) as exc:
        load_sim_config(edit(quick_sim(), path, value))
    msg = str(exc.value)
    assert msg.startswith(key + ":"), msg
    assert hint in msg and "\n" not in msg


def test_line_longer_than_the_map():
    sim = edit(quick_sim(heading_deg=0.0), ("flights", 0, "plan", "duration_s"), KeyError)
    sim["flights"][0]["plan"]["line_length_m"] = 2.0e6
    with pytest.raises(ConfigError, match=r"^flights\[0\]\.plan\.line_length_m: .*map allows"):
        load_sim_config(sim)
    # a 4 h line due east (720 km along a parallel) is fine
    load_sim_config(quick_sim(duration_s=4 * 3600.0))
    # grids: too many lines north-south
    g = grid_sim()
    g["flights"][0]["plan"]["lines"].update(heading_deg=90.0, count=400, spacing_m=2000.0)
    with pytest.raises(ConfigError, match=r"^flights\[0\]\.plan\.lines\.length_m: .*north-south"):
        load_sim_config(g)


def test_grid_specific_errors():
    g = grid_sim()
    g["flights"][0]["plan"]["ties"]["spacing_m"] = 9000.0
    with pytest.raises(ConfigError, match=r"^flights\[0\]\.plan\.ties\.spacing_m: 2 ties at 9000 m do not fit"):
        load_sim_config(g)
    g = grid_sim()
    g["flights"][0]["plan"]["duration_s"] = 100.0
    with pytest.raises(ConfigError, match=r"^flights\[0\]\.plan\.duration_s: only allowed"):
        load_sim_config(g)
    g = grid_sim()
    del g["flights"][0]["plan"]["lines"]["spacing_m"]
    with pytest.raises(ConfigError, match=r"^flights\[0\]\.plan\.lines\.spacing_m: missing"):
        load_sim_config(g)
    g = grid_sim()
    g["flights"][0]["plan"]["heading_deg"] = 0.0
    with pytest.raises(ConfigError, match=r"^flights\[0\]\.plan\.heading_deg: only allowed .* lines\.heading_deg"):
        load_sim_config(g)
    line = quick_sim()
    line["flights"][0]["plan"]["line_length_m"] = 1000.0
    with pytest.raises(ConfigError, match=r"^flights\[0\]\.plan: expected exactly one of"):
        load_sim_config(line)


def test_duplicate_flight_names():
    sim = quick_sim()
    sim["flights"].append(copy.deepcopy(sim["flights"][0]))
    with pytest.raises(ConfigError, match=r"^flights\[1\]\.name: duplicate"):
        load_sim_config(sim)


def test_yaml_file_errors_name_the_file(tmp_path):
    p = tmp_path / "bad.yaml"
    sim = quick_sim()
    sim["flights"][0]["rates"]["imu_hz"] = -1
    p.write_text(yaml.safe_dump(sim))
    with pytest.raises(ConfigError) as exc:
        load_sim_config(p)
    assert str(exc.value).startswith(f"{p}: flights[0].rates.imu_hz:")
    p.write_text("flights: [\n")
    with pytest.raises(ConfigError, match="invalid YAML"):
        load_sim_config(p)
    with pytest.raises(ConfigError, match="cannot read"):
        load_sim_config(tmp_path / "missing.yaml")


def test_defaults_and_start_time():
    cfg = load_sim_config(quick_sim(start_utc="2024-06-01T10:00:00+02:00"))
    f = cfg.flights[0]
    assert f["start_unix_ns"] == 1717228800 * 10**9  # 08:00 UTC
    assert f["rates"]["truth_hz"] == f["rates"]["altimeter_hz"]
    assert f["sensors"]["gravimeter"]["markov_lambda_per_s"] == 0.025
    assert f["plan"]["line_length_m"] == 1200.0 * 50.0


@pytest.mark.parametrize("name", sorted(p.name for p in CONFIGS.glob("*.yaml")))
def test_shipped_configs_are_valid(name):
    cfg = load_sim_config(CONFIGS / name)
    assert cfg.flights


def test_gnss_and_altimeter_up_to_20_hz():
    sim = quick_sim(gnss_hz=20.0, altimeter_hz=20.0, imu_hz=40.0)
    f = load_sim_config(sim).flights[0]
    assert f["rates"]["gnss_hz"] == 20.0 and f["rates"]["altimeter_hz"] == 20.0


def test_polar_plans_are_simulated_up_to_where_lines_would_reach_the_pole():
    """The survey map is exact at any latitude (docs/simulate.md): a line along the 89 deg S
    parallel is a valid plan; one heading north from 89 deg N for 60 km would pass 89.5 deg."""
    assert load_sim_config(quick_sim(lat_deg=-89.0, heading_deg=90.0, duration_s=3600.0)) is not None
    with pytest.raises(ConfigError, match=r"flights\[0\]\.plan\.duration_s: .*reach latitude 89\.54 deg.*<= 89\.5 deg"):
        load_sim_config(quick_sim(lat_deg=89.0, heading_deg=0.0))
