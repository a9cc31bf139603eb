"""Gravity-gradient channel: simulator output (CSV, JSON MCAP) -> ingestion round trip, and
clear errors for a wrong unit or a non-symmetric tensor (issue 16 item 2)."""

import json
import warnings

import numpy as np
import pytest
import yaml

from gravsurvey.errors import ConfigError, DataError
from gravsurvey.io.ingest import load_flight
from gravsurvey.simulate.run import quick_sim, simulate_flight, simulate_to_dir
from gravsurvey.simulate.simconfig import load_sim_config
from gravsurvey.settings import ingest_options

E = 1e-9
FIELD = {"type": "model", "point_masses": [{"lat_deg": 45.0, "lon_deg": 135.02, "depth_m": 1500.0, "mass_kg": 3e12}]}
UPPER = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


def _sim(tmp_path, **kw):
    sim = quick_sim(
        duration_s=120.0,
        field=FIELD,
        formats=["mcap_json", "csv"],
        noise={"gradiometer": {"rate_hz": 2.0, "white_eotvos_rthz": 3.0, "markov_sigma_eotvos": 1.0}},
        **kw,
    )
    p = tmp_path / "sim.yaml"
    p.write_text(yaml.safe_dump(sim))
    return sim, p


def _load(inputs, base, **extra):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_flight(ingest_options({"inputs": inputs, **extra}, "flights[0]"), base)


@pytest.mark.parametrize("triad", ["platform", "strapdown"])
def test_gradient_round_trip_csv_and_mcap(tmp_path, triad):
    sim, path = _sim(tmp_path, triad=triad)
    out = tmp_path / "out"
    simulate_to_dir(path, out)
    assert (out / "F01" / "gradient.csv").exists()
    fs = simulate_flight(load_sim_config(sim))
    comps = fs.gradient_t_eotvos
    assert comps.shape == (241, 6)
    # the written values are the truth tensor on the triad plus the configured noise
    truth = comps - fs.gradient_error_eotvos
    assert 2.0 < np.std(fs.gradient_error_eotvos) < 6.0  # 3 E/sqrt(Hz) at 2 Hz -> 4.2 E, + 1 E Markov
    tzz = truth[:, 5] if triad == "platform" else None
    if tzz is not None:
        assert np.all((tzz > 3000) & (tzz < 3200))
    trace = truth[:, 0] + truth[:, 3] + truth[:, 5]
    assert np.abs(trace).max() < 1e-3  # Laplace holds on any axes
    for inputs in (
        {"mcap": str(out / "F01" / "F01_json.mcap")},
        {
            "csv": {
                "imu": str(out / "F01" / "imu.csv"),
                "altimeter": str(out / "F01" / "altimeter.csv"),
                "gnss": str(out / "F01" / "gnss.csv"),
                "gradient": str(out / "F01" / "gradient.csv"),
            }
        },
    ):
        rec = _load(inputs, out)
        assert rec.gradient is not None
        gam = rec.gradient.gamma_t
        assert gam.shape == (241, 3, 3)
        got = np.stack([gam[:, i, j] for i, j in UPPER], axis=1) / E
        np.testing.assert_allclose(got, comps, rtol=1e-14, atol=1e-12)
        np.testing.assert_array_equal(gam, gam.transpose(0, 2, 1))
        np.testing.assert_allclose(rec.gradient.time, fs.gradient_time, atol=1e-9)


def test_gradient_channel_off_by_default(tmp_path):
    sim = quick_sim(duration_s=60.0, formats=["csv"])
    fs = simulate_flight(load_sim_config(sim))
    assert fs.gradient_time_ns is None
    p = tmp_path / "sim.yaml"
    p.write_text(yaml.safe_dump(sim))
    simulate_to_dir(p, tmp_path / "o")
    assert not (tmp_path / "o" / "F01" / "gradient.csv").exists()
    rec = _load({"csv": {"imu": "F01/imu.csv", "altimeter": "F01/altimeter.csv"}}, tmp_path / "o")
    assert rec.gradient is None


def test_sim_config_rejects_bad_gradiometer_keys():
    sim = quick_sim(noise={"gradiometer": {"rate_hz": -1.0}})
    with pytest.raises(ConfigError, match="gradiometer.rate_hz"):
        load_sim_config(sim)
    sim = quick_sim(noise={"gradiometer": {"white_noise": 1.0}})
    with pytest.raises(ConfigError, match="gradiometer"):
        load_sim_config(sim)


def _gradient_csv(path, rows, columns):
    lines = ["time_ns," + ",".join(columns)]
    for k, r in enumerate(rows):
        lines.append(f"{1717228800000000000 + k * 10**9}," + ",".join(repr(float(x)) for x in r))
    path.write_text("\n".join(lines) + "\n")


def _base_csv(tmp_path):
    _, path = _sim(tmp_path)
    simulate_to_dir(path, tmp_path / "o")
    return tmp_path / "o"


def test_wrong_unit_and_asymmetric_tensor_are_clear_errors(tmp_path):
    base = _base_csv(tmp_path)
    rec = _load({"csv": {"imu": "F01/imu.csv", "altimeter": "F01/altimeter.csv", "gradient": "F01/gradient.csv"}}, base)
    gam = rec.gradient.gamma_t / E
    six = np.stack([gam[:, i, j] for i, j in UPPER], axis=1)
    csv_in = {"csv": {"imu": "F01/imu.csv", "altimeter": "F01/altimeter.csv", "gradient": "F01/g.csv"}}
    names = ["txx_eotvos", "txy_eotvos", "txz_eotvos", "tyy_eotvos", "tyz_eotvos", "tzz_eotvos"]
    # values written in 1/s^2 under *_eotvos columns: the unit check stops it
    _gradient_csv(base / "F01" / "g.csv", six * E, names)
    with pytest.raises(DataError, match=r"g\.csv: gravity gradient: .*wrong unit"):
        _load(csv_in, base)
    # ... and the same file is fine once declared
    rec2 = _load(csv_in, base, csv={"units": {"gradient": "1/s^2"}})
    np.testing.assert_allclose(rec2.gradient.gamma_t, rec.gradient.gamma_t, rtol=1e-12)
    # a 9-component tensor with the lower triangle off by 50 E: not symmetric
    lower = six[:, [1, 2, 4]] + np.array([50.0, 0.0, 0.0])
    _gradient_csv(base / "F01" / "g.csv", np.hstack([six, lower]), names + ["tyx_eotvos", "tzx_eotvos", "tzy_eotvos"])
    with pytest.raises(DataError, match=r"g\.csv: gravity-gradient tensor not symmetric"):
        _load(csv_in, base)
    # symmetric to its noise (2 E): accepted and symmetrised
    lower = six[:, [1, 2, 4]] + np.random.default_rng(0).normal(0, 2.0, (six.shape[0], 3))
    _gradient_csv(base / "F01" / "g.csv", np.hstack([six, lower]), names + ["tyx_eotvos", "tzx_eotvos", "tzy_eotvos"])
    rec3 = _load(csv_in, base)
    np.testing.assert_array_equal(rec3.gradient.gamma_t, rec3.gradient.gamma_t.transpose(0, 2, 1))
    # a missing column names the file and the column
    _gradient_csv(base / "F01" / "g.csv", six[:, :5], names[:5])
    with pytest.raises(DataError, match=r"g\.csv: line 1: column 'tzz_eotvos' missing"):
        _load(csv_in, base)


def test_asymmetric_tensor_in_mcap_is_a_clear_error(tmp_path):
    from mcap.writer import Writer

    base = _base_csv(tmp_path)
    rec = _load({"csv": {"imu": "F01/imu.csv", "altimeter": "F01/altimeter.csv", "gradient": "F01/gradient.csv"}}, base)
    path = tmp_path / "bad.mcap"
    t0 = rec.t0_unix_ns
    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start()
        sid = {
            n: w.register_schema(name=n, encoding="jsonschema", data=b"{}")
            for n in ("gravsurvey.Imu", "gravsurvey.Altimeter", "gravsurvey.GravityGradient")
        }
        ci = w.register_channel(topic="/imu", message_encoding="json", schema_id=sid["gravsurvey.Imu"])
        ca = w.register_channel(topic="/altimeter", message_encoding="json", schema_id=sid["gravsurvey.Altimeter"])
        cg = w.register_channel(topic="/gradient", message_encoding="json", schema_id=sid["gravsurvey.GravityGradient"])
        for k in range(len(rec.imu.time)):
            t = t0 + round(rec.imu.time[k] * 1e9)
            msg = {
                "time_ns": t,
                "specific_force_t": rec.imu.specific_force_t[k].tolist(),
                "angular_rate_t": rec.imu.angular_rate_t[k].tolist(),
            }
            w.add_message(ci, t, json.dumps(msg).encode(), t)
        for k in range(len(rec.altimeter.time)):
            t = t0 + round(rec.altimeter.time[k] * 1e9)
            w.add_message(ca, t, json.dumps({"time_ns": t, "height_m": float(rec.altimeter.height[k])}).encode(), t)
        for k in range(len(rec.gradient.time)):
            t = t0 + round(rec.gradient.time[k] * 1e9)
            full = (rec.gradient.gamma_t[k] / E).copy()
            full[1, 0] += 40.0  # yx != xy
            w.add_message(cg, t, json.dumps({"time_ns": t, "gradient_t_eotvos": full.ravel().tolist()}).encode(), t)
        w.finish()
    with pytest.raises(DataError, match=r"bad\.mcap topic /gradient: gravity-gradient tensor not symmetric"):
        _load({"mcap": str(path)}, tmp_path)


def test_flight_products_against_truth():
    # the pipeline's dg/dt = T V product on the simulator's own track and tensor reproduces
    # the truth disturbance and horizontal anomaly (noise-free gradiometer)
    from gravsurvey import gradiometer as G

    sim = quick_sim(duration_s=600.0, speed_mps=100.0, field=FIELD, imu_hz=1.0, noise={"gradiometer": {"rate_hz": 1.0}})
    fs = simulate_flight(load_sim_config(sim))
    comps = fs.gradient_t_eotvos * E
    gam = np.empty((comps.shape[0], 3, 3))
    for k, (i, j) in enumerate(UPPER):
        gam[:, i, j] = gam[:, j, i] = comps[:, k]
    tr = fs.truth
    p = G.flight_products(
        fs.gradient_time,
        gam,
        tr["time"],
        tr["lat"],
        tr["lon"],
        tr["height"],
        tr["vel_n"],
        tr["disturbance"][0],
        "platform",
    )
    assert 3000 < p["vertical_eigenvalue_median_eotvos"] < 3200
    assert abs(p["trace_median_eotvos"]) < 1e-3
    assert np.ptp(tr["disturbance"]) > 2e-5  # > 2 mGal of signal (3.2 measured)
    # trapezoid at 1 Hz, 100 m/s, 2.5 km from the mass: 0.011 mGal measured
    np.testing.assert_allclose(p["disturbance"], tr["disturbance"], rtol=0, atol=0.02e-5)
    np.testing.assert_allclose(p["horizontal_n"], tr["anomaly_n"][:, :2] - tr["anomaly_n"][0, :2], rtol=0, atol=0.02e-5)
    q = G.flight_products(
        fs.gradient_time, gam, tr["time"], tr["lat"], tr["lon"], tr["height"], tr["vel_n"], 0.0, "strapdown"
    )
    assert "disturbance" not in q and "attitude" in q["note"]


def test_gravsurvey_run_with_processing_gradiometer(tmp_path):
    from gravsurvey.pipeline import run_survey

    sim = quick_sim(
        duration_s=600.0,
        speed_mps=100.0,
        field=FIELD,
        formats=["mcap_json"],
        noise={"gradiometer": {"rate_hz": 1.0, "white_eotvos_rthz": 1.0}},
    )
    p = tmp_path / "sim.yaml"
    p.write_text(yaml.safe_dump(sim))
    simulate_to_dir(p, tmp_path / "s")
    survey = tmp_path / "s" / "survey.yaml"
    cfg = yaml.safe_load(survey.read_text())
    cfg.setdefault("processing", {})["gradiometer"] = True
    survey.write_text(yaml.safe_dump(cfg))
    res = run_survey(survey, output_dir=tmp_path / "out")
    assert not res.failed
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    g = summary["flights"]["F01"]["estimator"]["gradiometer"]
    assert g["samples"] == 601
    assert 3000 < g["vertical_eigenvalue_median_eotvos"] < 3200
    # gradient-propagated disturbance vs the scalar INM estimate: the same field within the
    # estimate's own error on a 10-min flight (measured 1-3 mGal)
    assert 0.0 < g["disturbance_rms_vs_estimate_mgal"] < 10.0
    cfg["processing"]["gradiometer"] = "yes"
    survey.write_text(yaml.safe_dump(cfg))
    with pytest.raises(ConfigError, match="processing.gradiometer: expected true or false"):
        run_survey(survey, output_dir=tmp_path / "out2")


def test_gradiometer_noise_statistics():
    from gravsurvey.simulate.sensors import gradiometer_errors

    rng = np.random.default_rng(11)
    cfg = {
        "gradiometer": {
            "rate_hz": 4.0,
            "white_eotvos_rthz": 3.0,
            "markov_sigma_eotvos": 0.0,
            "markov_lambda_per_s": 0.001,
        }
    }
    e = gradiometer_errors(40000, 4.0, cfg, rng)
    # one-second sigma 3 E/sqrt(Hz): 6 E per 4 Hz sample, 3 E averaged over 1 s
    assert abs(np.std(e) - 6.0) < 0.1
    assert abs(np.std(e[: 40000 // 4 * 4].reshape(-1, 4, 6).mean(axis=1)) - 3.0) < 0.1
    cfg["gradiometer"].update(white_eotvos_rthz=0.0, markov_sigma_eotvos=2.0, markov_lambda_per_s=0.1)
    e = gradiometer_errors(200000, 4.0, cfg, rng)
    assert abs(np.std(e) - 2.0) < 0.1
    lag = 10  # 2.5 s: correlation exp(-0.25)
    c = np.mean([np.corrcoef(e[:-lag, j], e[lag:, j])[0, 1] for j in range(6)])
    assert abs(c - np.exp(-0.25)) < 0.03


def test_inspect_shows_the_gradient_channel(tmp_path):
    from gravsurvey.io.inspect import format_inspect, inspect_files

    sim = quick_sim(duration_s=60.0, formats=["mcap_json", "csv"], noise={"gradiometer": {"rate_hz": 1.0}})
    p = tmp_path / "sim.yaml"
    p.write_text(yaml.safe_dump(sim))
    simulate_to_dir(p, tmp_path / "s")
    reps = inspect_files([tmp_path / "s" / "F01" / "F01_json.mcap", tmp_path / "s" / "F01" / "gradient.csv"])
    assert all("error" not in r for r in reps)
    roles = [c.get("role") for r in reps for c in r["channels"]]
    assert roles.count("gradient") == 2
    assert "gravsurvey.GravityGradient" in format_inspect(reps)
