"""IMU increments per sample (velocity ``m/s``, angle ``rad``/``deg``), as navigation-grade IMUs
write them: read as the rates they average, stamped at the middle of their interval; a survey
written as increments is estimated as the same survey written as rates; increments and rates
mistaken for each other are named."""

from __future__ import annotations

import numpy as np
import pytest
from test_io_csv import CSV_IN, _write_flight_csv
from test_io_support import static_flight

import damage_csv as d
from gravsurvey.config import load_config
from gravsurvey.errors import ConfigError, DataError
from gravsurvey.geodesy import MGAL
from gravsurvey.io.ingest import load_flight
from gravsurvey.pipeline import process_flight
from gravsurvey.settings import FlightSection, ingest_options, validate_section


def _increments(tmp_path, flight, step_ns, unit_scale=1.0):
    """``flight``'s IMU written as increments over each sample's interval, stamped at its end."""
    dt = step_ns * 1e-9
    times = [str(int(t) + step_ns // 2) for t in flight["imu_t"]]
    _write_flight_csv(tmp_path, flight, acc_scale=dt, gyro_scale=dt * unit_scale, times=times)


@pytest.mark.parametrize("gyro_unit, scale", [("rad", 1.0), ("deg", 180.0 / np.pi)])
def test_increments_are_read_as_rates_at_the_middle_of_their_interval(tmp_path, gyro_unit, scale):
    flight = static_flight(seconds=40.0, imu_hz=100.0)
    _increments(tmp_path, flight, 10_000_000, scale)
    opts = ingest_options({"inputs": CSV_IN, "csv": {"units": {"accel": "m/s", "gyro": gyro_unit}}}, "f")
    rec = load_flight(opts, tmp_path)
    np.testing.assert_allclose(rec.imu.specific_force_t, flight["f"], rtol=1e-12)
    np.testing.assert_allclose(rec.imu.angular_rate_t, flight["w"], rtol=1e-9)
    t_abs = rec.t0_unix_ns + np.round(rec.imu.time * 1e9).astype(np.int64)
    np.testing.assert_array_equal(t_abs, flight["imu_t"])


def test_increments_and_rates_mistaken_for_each_other_are_named(tmp_path):
    flight = static_flight(seconds=40.0, imu_hz=100.0)
    _increments(tmp_path, flight, 10_000_000)
    as_rates = ingest_options({"inputs": CSV_IN}, "f")
    with pytest.raises(DataError, match=r"velocity increments per 10-ms sample declared as a rate \(units accel: m/s"):
        load_flight(as_rates, tmp_path)
    _write_flight_csv(tmp_path, flight)
    as_increments = ingest_options({"inputs": CSV_IN, "csv": {"units": {"accel": "m/s", "gyro": "rad"}}}, "f")
    with pytest.raises(DataError, match=r"rates declared as increments per 10-ms sample \(units accel: m/s\^2"):
        load_flight(as_increments, tmp_path)


def test_one_increment_and_one_rate_is_a_config_error():
    with pytest.raises(
        ConfigError, match=r"flights\[0\]\.mcap\.units: accel 'm/s' and gyro 'deg/s': one is an increment"
    ):
        validate_section(
            FlightSection,
            {"inputs": {"mcap": "x.mcap"}, "mcap": {"units": {"accel": "m/s", "gyro": "deg/s"}}},
            "flights[0]",
        )


def test_a_survey_written_as_increments_is_estimated_as_written_as_rates(tmp_path):
    """The sample survey's IMU (10 Hz) rewritten as increments stamped at each interval's end."""

    def to_increments(root):
        step_ns = 100_000_000

        def fn(head, rows):
            for r in rows:
                r[0] = str(int(r[0]) + step_ns // 2)
                r[1:] = [repr(float(x) * step_ns * 1e-9) for x in r[1:]]
            return rows

        d.edit(root, "imu", fn)

    out = {}
    for tag, prep, extra in (
        ("rates", None, ""),
        ("increments", to_increments, "\n  csv: {units: {accel: m/s, gyro: rad}}"),
    ):
        cfg_path = d.copy_sample(tmp_path / tag)
        if prep is not None:
            prep(tmp_path / tag)
        cfg_path.write_text(cfg_path.read_text().replace("\n  triad:", extra + "\n  triad:", 1))
        cfg = load_config(cfg_path, output_dir=tmp_path / tag / "out")
        r = process_flight(cfg, cfg.flights[0])
        out[tag] = r
    a, b = out["rates"], out["increments"]
    np.testing.assert_array_equal(a.time, b.time)
    np.testing.assert_allclose(b.disturbance / MGAL, a.disturbance / MGAL, atol=1e-6)


def test_real_vn310_increments_read_as_its_own_rates():
    """A VectorNav VN-310E's delta-velocity and delta-angle outputs (tests/data/real-imu, MPL-2.0),
    declared as increments, against the same device's rate outputs over the same 32 s at rest."""
    from pathlib import Path

    data = Path(__file__).parent / "data" / "real-imu"
    t = ["GpsCycle", "GpsWeek", "GpsTow [s]"]
    height = {"altimeter": {"time": t, "height": "GNSS1::PosLla::altitude [m]"}}

    def load(imu_file, columns, units):
        cfg = {
            "inputs": {"csv": {"imu": imu_file, "altimeter": "vn310-gnss-part.csv"}},
            "imu_axes": "FRD",
            "csv": {
                "time_format": "gps_week_sow",
                "columns": {"imu": {"time": t, **columns}, **height},
                "units": units,
            },
            "checks": {"plausibility": "warn"},  # a MEMS gyro's bias at rest reads as a unit doubt
        }
        with pytest.warns(Warning):
            return load_flight(ingest_options(cfg, base_dir=data))

    rates = load(
        "vn310-imu-part.csv",
        {
            **{f"f{a.lower()}": f"IMU::UncompAccel::{a} [m/s^2]" for a in "XYZ"},
            **{f"w{a.lower()}": f"IMU::UncompGyro::{a} [rad/s]" for a in "XYZ"},
        },
        {},
    )
    inc = load(
        "vn310-increments-part.csv",
        {
            **{f"f{a.lower()}": f"IMU::DeltaVel::{a} [m/s]" for a in "XYZ"},
            **{f"w{a.lower()}": f"IMU::DeltaTheta::{a} [deg]" for a in "XYZ"},
        },
        {"accel": "m/s", "gyro": "deg"},
    )
    # the increments cover the 20 ms before each stamp: stamped 10 ms earlier
    t_rates = rates.t0_unix_ns + np.round(rates.imu.time * 1e9).astype(np.int64)
    t_inc = inc.t0_unix_ns + np.round(inc.imu.time * 1e9).astype(np.int64)
    assert np.all(np.abs(t_rates - t_inc - 10_000_000) <= 2_000)
    # the device's increments are close to its uncompensated rates integrated: the means agree to
    # 5e-4 m/s^2 (measured 1.9e-4, 4.7e-5 and 5e-7 on x, y, z; declared as rates they would be 50x
    # smaller) and 1e-7 rad/s (measured 1e-8); at rest both read g on +z (FLU)
    np.testing.assert_allclose(inc.imu.specific_force_t.mean(0), rates.imu.specific_force_t.mean(0), atol=5e-4)
    np.testing.assert_allclose(inc.imu.angular_rate_t.mean(0), rates.imu.angular_rate_t.mean(0), atol=1e-7)
    # sample by sample the same motion (the table's vibration): correlation above 0.98 on every axis
    for j in range(3):
        assert np.corrcoef(inc.imu.specific_force_t[:, j], rates.imu.specific_force_t[:, j])[0, 1] > 0.98
    assert inc.imu.specific_force_t.mean(0)[2] == pytest.approx(9.80, abs=0.01)
