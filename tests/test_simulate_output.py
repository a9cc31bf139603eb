"""Simulator outputs: anomaly signs end to end, sensor error statistics, determinism to the
byte, the committed sample surveys, survey.yaml and truth.csv."""

import csv
import math
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import yaml

from gravsurvey import geodesy as gd
from gravsurvey.errors import ConfigError
from gravsurvey.simulate import sensors as sn
from gravsurvey.simulate.run import (
    SEED_SENSORS,
    gravimeter_slow_error,
    quick_sim,
    simulate_flight,
    simulate_to_dir,
)

ROOT = Path(__file__).resolve().parents[1]
G_NEWTON = 6.67430e-11
SAMPLES = {"seed_line": "sample_seed_line", "grid_ros2": "sample_grid_ros2", "markov_csv": "sample_markov_csv"}


def test_point_mass_below_the_track_adds_gm_over_r2_to_the_vertical_force():
    """A mass on the ellipsoid normal below a point of the line raises F_up there by G M / (h + d)^2.

    The source sits under the track 10 km after the start (9 km + 1 km of the 20 s first
    interval): lat 45, lon of the sample at t = 200 s.
    """
    h, depth, mass = 1000.0, 2000.0, 1.0e13
    base = quick_sim(duration_s=400.0)
    clean = simulate_flight(base)
    lon_src = math.degrees(clean.truth["lon"][2000])
    field = {
        "type": "model",
        "point_masses": [{"lat_deg": 45.0, "lon_deg": lon_src, "depth_m": depth, "mass_kg": mass}],
    }
    s = simulate_flight(quick_sim(duration_s=400.0, field=field))
    d_up = s.specific_force_t[:, 2] - clean.specific_force_t[:, 2]
    expected = G_NEWTON * mass / (h + depth) ** 2
    assert d_up[2000] == pytest.approx(expected, rel=1e-9)
    assert np.argmax(d_up) == 2000
    np.testing.assert_allclose(s.truth["disturbance"], d_up, rtol=0, atol=1e-13)
    # horizontal components point towards the mass: before it (west) the force on the triad
    # has -g_anom, i.e. F_E = -(attraction east) < 0
    d_e = s.specific_force_t[:, 0] - clean.specific_force_t[:, 0]
    assert d_e[1000] < 0 < d_e[3000]
    np.testing.assert_allclose(-s.truth["anomaly_n"][:, 0], d_e, rtol=0, atol=1e-13)


@pytest.mark.parametrize("kind", ["seed_smooth", "seed_steps"])
def test_seed_time_functions_enter_the_vertical_force(kind):
    from gravsurvey.simulate.field import (
        seed_smooth_disturbance,
        seed_steps_disturbance,
    )

    fn = seed_smooth_disturbance if kind == "seed_smooth" else seed_steps_disturbance
    clean = simulate_flight(quick_sim(duration_s=4000.0, imu_hz=1.0))
    s = simulate_flight(quick_sim(duration_s=4000.0, imu_hz=1.0, field=kind))
    d = s.specific_force_t - clean.specific_force_t
    np.testing.assert_allclose(d[:, 2], fn(s.imu_time), rtol=0, atol=1e-13)
    assert np.abs(d[:, :2]).max() == 0.0
    assert np.abs(s.truth["disturbance"]).max() > 10e-5


def test_sensor_error_statistics():
    rate, n = 10.0, 360_000
    cfg = {
        "accelerometer": {"white_sigma_mps2": 1e-3, "bias_mps2": [2e-4, -3e-4]},
        "gravimeter": {
            "bias_mps2": 5e-5,
            "markov_sigma_mps2": 1e-5,
            "markov_lambda_per_s": 0.025,
            "white_sigma_mps2": 0.0,
        },
        "gyro": {"bias_degph": [0.1, 0.0, -0.2], "white_drift_degph": 0.01},
    }
    e = sn.imu_errors(n, rate, cfg, np.random.default_rng(5))
    a = e.accel_t
    # one-second averages of the white noise have sigma_1s
    one_s = (a[:, :2] - [2e-4, -3e-4]).reshape(-1, int(rate), 2).mean(axis=1)
    np.testing.assert_allclose(one_s.std(axis=0), 1e-3, rtol=0.02)
    np.testing.assert_allclose(a[:, :2].mean(axis=0), [2e-4, -3e-4], rtol=0, atol=3 * 1e-3 * math.sqrt(rate / n))
    # gravimeter: bias + stationary Markov, correlation exp(-lambda tau)
    m = a[:, 2] - 5e-5
    np.testing.assert_allclose(m, e.gravimeter_markov, rtol=0, atol=1e-19)
    assert m.std() == pytest.approx(1e-5, rel=0.05)
    lag = 400  # 40 s: exp(-1)
    rho = np.corrcoef(m[:-lag], m[lag:])[0, 1]
    assert rho == pytest.approx(math.exp(-1.0), abs=0.04)
    g = e.gyro_t / sn.DEGPH
    one_s = (g - [0.1, 0.0, -0.2]).reshape(-1, int(rate), 3).mean(axis=1)
    np.testing.assert_allclose(one_s.std(axis=0), 0.01, rtol=0.02)
    # compiled Markov recursion equals the reference path
    w = np.random.default_rng(1).standard_normal(1000)
    out = np.empty(1001)
    sn._markov_kernel(0.99, 0.1, 0.3, w, out)
    np.testing.assert_array_equal(out, sn.markov_reference(0.99, 0.1, 0.3, w))


def test_noise_switches_and_altimeter_gnss_errors():
    quiet = simulate_flight(quick_sim(duration_s=600.0))
    assert np.array_equal(quiet.specific_force_t, quiet.noise_free_specific_force_t)
    assert np.array_equal(quiet.angular_rate_t, quiet.noise_free_angular_rate_t)
    noisy_cfg = {
        "altimeter": {"sigma_m": 1.0, "mean_m": 3.0},
        "gnss": {"horizontal_sigma_m": 2.0, "vertical_sigma_m": 1.5},
    }
    s = simulate_flight(quick_sim(duration_s=3000.0, altimeter_hz=10.0, gnss_hz=10.0, noise=noisy_cfg))
    kin_h = quiet.truth["height"][0]
    err = s.alt_height - kin_h
    assert err.mean() == pytest.approx(3.0, abs=0.05) and err.std() == pytest.approx(1.0, rel=0.05)
    lat = np.radians(s.gnss_lat_deg)
    mm, nn = gd.radii_of_curvature(lat)
    north_m = (lat - np.radians(45.0)) * (mm + 1000.0)
    assert north_m.std() == pytest.approx(2.0, rel=0.05)
    assert (s.gnss_height - 1000.0).std() == pytest.approx(1.5, rel=0.05)
    # the IMU is untouched by altimeter/GNSS errors
    assert np.array_equal(s.specific_force_t[:6001], quiet.specific_force_t)


def test_one_error_source_does_not_change_another():
    a = simulate_flight(quick_sim(duration_s=300.0, noise={"gyro": {"white_drift_degph": 0.01}}))
    b = simulate_flight(
        quick_sim(
            duration_s=300.0,
            noise={
                "gyro": {"white_drift_degph": 0.01},
                "altimeter": {"sigma_m": 1.0},
                "accelerometer": {"white_sigma_mps2": 1e-3},
            },
        )
    )
    assert np.array_equal(a.angular_rate_t, b.angular_rate_t)
    assert not np.array_equal(a.alt_height, b.alt_height)


def test_gravimeter_slow_error_is_the_simulations_own_draw():
    # the benchmark's drift column must score the drift the flight really carries
    sensors = {
        "gravimeter": {
            "bias_mps2": 2.0e-5,
            "markov_sigma_mps2": 1.0e-5,
            "markov_lambda_per_s": 1.0 / 600.0,
            "white_sigma_mps2": 1.0e-5,
        },
        "accelerometer": {"white_sigma_mps2": 1e-3},
    }
    sim = quick_sim(duration_s=900.0, noise=sensors, seed=4, turbulence={"vertical_sigma_m": 1.0})
    s = simulate_flight(sim)
    t_ns, err = gravimeter_slow_error(sim)
    assert np.array_equal(t_ns, s.imu_time_ns)
    assert np.array_equal(err, s.truth["gravimeter_markov"] + 2.0e-5)
    # the slow part: the white noise is left out, the Markov part is there
    assert 0.3e-5 < np.std(err) < 3e-5
    assert np.std(s.truth["gravimeter_error"] - err) > 10 * np.std(np.diff(err))
    with pytest.raises(ConfigError, match="no flight with index 1"):
        gravimeter_slow_error(sim, 1)
    # a linear drift (mGal/h from the first sample) is in the error and in its slow part; the
    # other errors' draws are unchanged
    sim["flights"][0]["sensors"]["gravimeter"]["drift_mgal_per_h"] = -2.0
    d = simulate_flight(sim)
    t_ns2, err2 = gravimeter_slow_error(sim)
    ramp = -2.0e-5 / 3600.0 * (t_ns2 - t_ns2[0]) / 1e9
    np.testing.assert_allclose(err2 - err, ramp, rtol=0, atol=1e-12)
    np.testing.assert_allclose(d.truth["gravimeter_drift"], ramp, rtol=0, atol=1e-12)
    np.testing.assert_allclose(d.truth["gravimeter_error"] - s.truth["gravimeter_error"], ramp, rtol=0, atol=1e-12)
    assert np.array_equal(d.truth["gravimeter_markov"], s.truth["gravimeter_markov"])
    assert abs(ramp[-1]) == pytest.approx(2.0e-5 * 900.0 / 3600.0, rel=0.01)
    sim["flights"][0]["sensors"]["gravimeter"]["drift_mgal_per_h"] = "fast"
    with pytest.raises(ConfigError, match=r"gravimeter.drift_mgal_per_h: expected a number \(mGal/h\)"):
        simulate_flight(sim)
    # a tare: the reading steps by tare_mgal at tare_time_s from the first sample, in the error
    # and its slow part, the other draws unchanged
    sim["flights"][0]["sensors"]["gravimeter"]["drift_mgal_per_h"] = 0.0
    sim["flights"][0]["sensors"]["gravimeter"]["tare_mgal"] = 4.0
    sim["flights"][0]["sensors"]["gravimeter"]["tare_time_s"] = 300.0
    d = simulate_flight(sim)
    t_ns3, err3 = gravimeter_slow_error(sim)
    step = np.where((t_ns3 - t_ns3[0]) / 1e9 >= 300.0, 4.0e-5, 0.0)
    np.testing.assert_allclose(err3 - err, step, rtol=0, atol=1e-12)
    np.testing.assert_allclose(d.truth["gravimeter_drift"], step, rtol=0, atol=1e-12)
    np.testing.assert_allclose(d.truth["gravimeter_error"] - s.truth["gravimeter_error"], step, rtol=0, atol=1e-12)
    assert 0 < np.count_nonzero(step) < step.size
    sim["flights"][0]["sensors"]["gravimeter"]["tare_time_s"] = -1.0
    with pytest.raises(ConfigError, match=r"gravimeter.tare_time_s"):
        simulate_flight(sim)


def _tree_bytes(d):
    return {p.relative_to(d).as_posix(): p.read_bytes() for p in sorted(Path(d).rglob("*")) if p.is_file()}


def test_determinism_same_config_same_bytes(tmp_path):
    sim = quick_sim(
        duration_s=120.0,
        noise=True,
        formats=["mcap_json", "mcap_ros2", "csv"],
        field="seed_smooth",
        triad="strapdown",
        turbulence={"vertical_sigma_m": 1.0, "attitude_sigma_deg": 0.5},
        seed=3,
    )
    p = tmp_path / "sim.yaml"
    p.write_text(yaml.safe_dump(sim))
    simulate_to_dir(p, tmp_path / "a")
    simulate_to_dir(p, tmp_path / "b")
    a, b = _tree_bytes(tmp_path / "a"), _tree_bytes(tmp_path / "b")
    assert sorted(a) == [
        "F01/F01_json.mcap",
        "F01/F01_ros2.mcap",
        "F01/altimeter.csv",
        "F01/gnss.csv",
        "F01/imu.csv",
        "F01/truth.csv",
        "survey.yaml",
    ]
    assert a == b
    sim["seed"] = 4
    p.write_text(yaml.safe_dump(sim))
    simulate_to_dir(p, tmp_path / "c")
    c = _tree_bytes(tmp_path / "c")
    assert c["F01/imu.csv"] != a["F01/imu.csv"] and c["F01/truth.csv"] != a["F01/truth.csv"]


# Tolerances for the committed-sample check when the bytes differ: numpy/libm transcendental
# functions may differ in the last bit between CPUs (e.g. AVX-512 vs AVX2 code paths). Such
# differences change the turn connectors' root-found headings by ~1e-13 rad and hence the
# specific force by up to ~2e-12 m/s^2 (measured with a 1-ulp change of the origin) - nothing
# physical (1e-9 m/s^2 = 1e-4 mGal).
RTOL, ATOL = 1e-9, 1e-9


def _close(a, b, where):
    if isinstance(a, dict):
        assert isinstance(b, dict) and sorted(a) == sorted(b), where
        for k in a:
            _close(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, (list, tuple)):
        assert isinstance(b, (list, tuple)) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            _close(x, y, f"{where}[{i}]")
    elif hasattr(type(a), "__slots__") and not isinstance(a, (int, float, str, bytes)):
        _close({k: getattr(a, k) for k in type(a).__slots__}, {k: getattr(b, k) for k in type(b).__slots__}, where)
    elif isinstance(a, float) or isinstance(b, float):
        assert math.isclose(a, b, rel_tol=RTOL, abs_tol=ATOL), f"{where}: {a!r} != {b!r}"
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


def _csv_token(t):
    try:
        return int(t)
    except ValueError:
        try:
            return float(t)
        except ValueError:
            return t


def _compare_csv(a, b, where):
    la, lb = a.decode().splitlines(), b.decode().splitlines()
    assert len(la) == len(lb), where
    for i, (x, y) in enumerate(zip(la, lb)):
        if x == y:
            continue
        assert not x.startswith("#"), f"{where} line {i + 1}"
        _close([_csv_token(t) for t in x.split(",")], [_csv_token(t) for t in y.split(",")], f"{where}:{i + 1}")


def _mcap_records(data):
    import io
    import json

    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    r = make_reader(io.BytesIO(data), decoder_factories=[DecoderFactory()])
    out = [("metadata", m.name, dict(m.metadata)) for m in r.iter_metadata()]
    r = make_reader(io.BytesIO(data), decoder_factories=[DecoderFactory()])
    if any(c.message_encoding == "json" for c in r.get_summary().channels.values()):
        for schema, channel, msg in r.iter_messages(log_time_order=False):
            out.append((channel.topic, schema.name, msg.log_time, msg.publish_time, json.loads(msg.data)))
    else:
        for schema, channel, msg, dec in r.iter_decoded_messages(log_time_order=False):
            out.append((channel.topic, schema.name, msg.log_time, msg.publish_time, dec))
    return out


@pytest.mark.parametrize("sample", sorted(SAMPLES))
def test_committed_samples_are_current(tmp_path, sample):
    """sample_data/ equals a fresh run of its SIM file (rerun sample_data/regenerate.sh after
    changing the simulator or the writers): byte for byte on the machine that generated it,
    and to 1e-9 (relative or absolute; last-bit differences of libm between CPUs) anywhere."""
    simulate_to_dir(ROOT / "configs" / f"{SAMPLES[sample]}.yaml", tmp_path / sample)
    fresh = _tree_bytes(tmp_path / sample)
    committed = _tree_bytes(ROOT / "sample_data" / sample)
    assert sorted(fresh) == sorted(committed)
    for k in fresh:
        if fresh[k] == committed[k]:
            continue
        where = f"sample_data/{sample}/{k} differs from a fresh simulation (rerun sample_data/regenerate.sh)"
        if k.endswith(".yaml"):
            _close(yaml.safe_load(fresh[k]), yaml.safe_load(committed[k]), where)
        elif k.endswith(".csv"):
            _compare_csv(fresh[k], committed[k], where)
        elif k.endswith(".mcap"):
            _close(_mcap_records(fresh[k]), _mcap_records(committed[k]), where)
        else:
            pytest.fail(where)
    # small enough for the repository: the largest, grid_ros2 (two flights, levelled), is 2.51 MB
    assert sum(len(v) for v in committed.values()) < 3.0e6


def test_sample_comparison_detects_changes(tmp_path):
    """The tolerant comparison above is not blind: a 1e-6 relative change is caught."""
    a = b"# c\ntime_ns,x\n1,0.5\n2,1.25\n"
    _compare_csv(a, b"# c\ntime_ns,x\n1,0.5\n2,1.2500000000000002\n", "ok")
    with pytest.raises(AssertionError):
        _compare_csv(a, b"# c\ntime_ns,x\n1,0.5\n2,1.2500013\n", "changed")
    with pytest.raises(AssertionError):
        _compare_csv(a, b"# c\ntime_ns,x\n1,0.5\n3,1.25\n", "time")
    data = (ROOT / "sample_data" / "grid_ros2" / "F01" / "F01_ros2.mcap").read_bytes()
    recs = _mcap_records(data)
    assert len(recs) > 10000
    _close(recs[:50], _mcap_records(data)[:50], "same")
    changed = list(recs[:50])
    topic, schema, t_log, t_pub, dec = changed[-1]
    changed[-1] = (topic, schema, t_log + 1, t_pub, dec)
    with pytest.raises(AssertionError):
        _close(recs[:50], changed, "log_time")


def test_regenerate_script_uses_the_cli(tmp_path):
    text = (ROOT / "sample_data" / "regenerate.sh").read_text()
    for sample, sim in SAMPLES.items():
        assert f"{sample}:{sim}" in text
    assert "gravsurvey simulate" in text
    if shutil.which("sh") is None:  # pragma: no cover
        pytest.fail("no sh")
    subprocess.run(["sh", "-n", str(ROOT / "sample_data" / "regenerate.sh")], check=True)


def test_the_oracle_knows_the_antenna_a_user_finds(tmp_path):
    """A simulated antenna off the IMU: oracle.yaml states it (``gnss_lever_arm_m``), survey.yaml
    leaves it to be found from the track."""
    noise = {"gnss": {"horizontal_sigma_m": 0.5, "vertical_sigma_m": 1.0, "antenna_m": [2.0, 0.0, 1.5]}}
    simulate_to_dir(quick_sim(duration_s=60.0, noise=noise), tmp_path, oracle=True)
    oracle = yaml.safe_load((tmp_path / "oracle.yaml").read_text())
    user = yaml.safe_load((tmp_path / "survey.yaml").read_text())
    assert oracle["flights"][0]["gnss_lever_arm_m"] == [2.0, 0.0, 1.5]
    assert "gnss_lever_arm_m" not in user["flights"][0]


def test_survey_yaml_and_truth_csv(tmp_path):
    plan = {
        "kind": "grid",
        "origin_lat_deg": 45.0,
        "origin_lon_deg": 135.0,
        "altitude_m": 700.0,
        "speed_mps": 60.0,
        "lines": {"count": 2, "spacing_m": 3000.0, "length_m": 3000.0, "heading_deg": 90.0},
        "static_start_s": 30.0,
        "ramp_s": 30.0,
    }
    noise = {**SEED_SENSORS, "gnss": {"horizontal_sigma_m": 0.5, "vertical_sigma_m": 1.0}}
    sim = quick_sim(plan=plan, triad="strapdown", formats=["csv"], noise=noise, imu_hz=20.0, altimeter_hz=2.0)
    paths = simulate_to_dir(sim, tmp_path, oracle=True)
    assert paths[-1] == tmp_path / "survey.yaml" and paths[-2] == tmp_path / "oracle.yaml"
    cfg = yaml.safe_load((tmp_path / "survey.yaml").read_text())
    # only what a user knows: no model block derived from the simulated errors or field
    assert set(cfg) == {"survey", "ellipsoid", "flights", "lines", "postprocess", "output"}
    f = cfg["flights"][0]
    assert f["inputs"] == {"csv": {"imu": "F01/imu.csv", "altimeter": "F01/altimeter.csv", "gnss": "F01/gnss.csv"}}
    assert f["triad"] == "strapdown" and f["truth"] == "F01/truth.csv"
    # no initial block: position/velocity come from GNSS and the attitude from alignment
    assert "initial" not in f
    s = simulate_flight(sim)
    oracle = yaml.safe_load((tmp_path / "oracle.yaml").read_text())
    assert oracle["model"]["accel_noise_mps2"] == 1e-3 and oracle["model"]["altimeter_sigma_m"] == 1.0
    assert oracle["model"]["gnss_horizontal_sigma_m"] == 0.5
    assert oracle["flights"][0]["initial"]["lat_deg"] == np.degrees(s.truth["lat"][0])
    assert oracle["output"]["dir"] != cfg["output"]["dir"]
    assert "gnss_lever_arm_m" not in oracle["flights"][0]  # the antenna at the IMU
    for rel in ("F01/imu.csv", "F01/altimeter.csv", "F01/gnss.csv", "F01/truth.csv"):
        assert (tmp_path / rel).is_file()
    rows = [
        r for r in csv.reader(l for l in (tmp_path / "F01/truth.csv").read_text().splitlines() if not l.startswith("#"))
    ]
    header, rows = rows[0], rows[1:]
    col = {k: i for i, k in enumerate(header)}
    assert len(rows) == len(s.alt_time)  # truth at the altimeter rate by default
    k = np.arange(len(rows)) * 10  # IMU rows at the truth times
    np.testing.assert_array_equal([float(r[col["lat_deg"]]) for r in rows], np.degrees(s.truth["lat"][k]))
    np.testing.assert_array_equal([float(r[col["roll_deg"]]) for r in rows], np.degrees(s.truth["roll"][k]))
    assert [r[col["line"]] for r in rows] == list(s.truth["line"][k])
    assert {r[col["line"]] for r in rows} == {"static", "turn", "L01", "L02"}
    assert [int(r[col["time_ns"]]) for r in rows[:3]] == [
        s.start_unix_ns,
        s.start_unix_ns + 500_000_000,
        s.start_unix_ns + 1_000_000_000,
    ]


@pytest.mark.parametrize("sample", sorted(SAMPLES))
def test_sample_survey_yaml_is_accepted_by_the_processing_config(sample):
    from gravsurvey.config import load_config

    cfg = load_config(ROOT / "sample_data" / sample / "survey.yaml")
    assert [f.name for f in cfg.flights] == (["F01", "F02"] if sample == "grid_ros2" else ["F01"])


def test_cli_oracle_config_flag(tmp_path):
    """`gravsurvey simulate --oracle-config` adds oracle.yaml; without it there is none."""
    import sys

    sim = quick_sim(duration_s=60.0, noise=True, formats=["csv"])
    p = tmp_path / "SIM.yaml"
    p.write_text(yaml.safe_dump(sim))
    exe = [sys.executable, "-m", "gravsurvey", "simulate", str(p)]
    r = subprocess.run(exe + ["-o", str(tmp_path / "a")], capture_output=True, text=True, timeout=300, check=False)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "a" / "survey.yaml").is_file() and not (tmp_path / "a" / "oracle.yaml").exists()
    r = subprocess.run(
        exe + ["-o", str(tmp_path / "b"), "--oracle-config"], capture_output=True, text=True, timeout=300, check=False
    )
    assert r.returncode == 0, r.stderr
    oracle = yaml.safe_load((tmp_path / "b" / "oracle.yaml").read_text())
    assert oracle["model"]["accel_noise_mps2"] == 1e-3
    assert "model" not in yaml.safe_load((tmp_path / "b" / "survey.yaml").read_text())
