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
