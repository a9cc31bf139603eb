"""CSV ingestion: time formats, units, columns, garbage input named by file/line/column."""

from __future__ import annotations

import re
import warnings

import numpy as np
import pytest
from test_io_support import static_flight

from gravsurvey.errors import ConfigError, DataError, DataWarning
from gravsurvey.io.csv import read_csv_channel
from gravsurvey.io.ingest import load_flight
from gravsurvey.settings import ingest_options


def _write_flight_csv(tmp, d, imu_cols=None, imu_fmt=None, acc_scale=1.0, gyro_scale=1.0, times=None):
    """CSV files per docs/formats.md (optionally other columns / scaled units / times)."""
    cols = imu_cols or ["time_ns", "fx_mps2", "fy_mps2", "fz_mps2", "wx_radps", "wy_radps", "wz_radps"]
    t = times if times is not None else [str(x) for x in d["imu_t"]]
    lines = ["# flight TEST", "# units SI", ",".join(cols)]
    for k in range(len(d["imu_t"])):
        f = d["f"][k] * acc_scale
        w = d["w"][k] * gyro_scale
        lines.append(",".join([t[k]] + [repr(float(x)) for x in (*f, *w)]))
    (tmp / "imu.csv").write_text("\n".join(lines) + "\n")
    alt = ["time_ns,height_m"] + [f"{t},{h!r}" for t, h in zip(d["alt_t"], d["h"].tolist())]
    (tmp / "altimeter.csv").write_text("\n".join(alt) + "\n")
    g = ["time_ns,lat_deg,lon_deg,height_m"] + [
        f"{t},{a!r},{b!r},{c!r}"
        for t, a, b, c in zip(d["gnss_t"], d["lat"].tolist(), d["lon"].tolist(), d["gh"].tolist())
    ]
    (tmp / "gnss.csv").write_text("\n".join(g) + "\n")


CSV_IN = {"csv": {"imu": "imu.csv", "altimeter": "altimeter.csv", "gnss": "gnss.csv"}}


def test_time_formats_give_the_same_integer_ns(tmp_path):
    t = np.array([1_700_000_000_000_000_001, 1_700_000_000_010_000_000, 1_700_000_000_999_999_999], dtype=np.int64)
    sec = ["1700000000.000000001", "1700000000.01", "1700000000.999999999"]
    iso = ["2023-11-14T22:13:20.000000001Z", "2023-11-14T22:13:20.010000000+00:00", "2023-11-14T22:13:20.999999999"]
    # GPS time = UTC + 18 s; 1980-01-06 + week * 7 d + sow
    gps = t + 18 * 10**9 - 315964800 * 10**9
    weeks = gps // (604800 * 10**9)
    sow = gps - weeks * 604800 * 10**9
    gps_rows = [f"{w},{s // 10**9}.{s % 10**9:09d}" for w, s in zip(weeks, sow)]
    cases = {
        "ns": ("time_ns", [str(x) for x in t]),
        "s": ("t_s", sec),
        "iso": ("utc", iso),
        "gps_week_sow": ("gps_week,gps_sow", gps_rows),
    }
    for fmt, (hdr, vals) in cases.items():
        p = tmp_path / f"{fmt}.csv"
        p.write_text(f"{hdr},height_m\n" + "".join(f"{v},100.5\n" for v in vals))
        cols = {"time": hdr} if fmt in ("s", "iso") else None
        got, v = read_csv_channel(p, "altimeter", cols, fmt)
        np.testing.assert_array_equal(got, t, err_msg=fmt)
        np.testing.assert_array_equal(v["height"], [100.5] * 3)
    assert weeks[0] == 2288  # independent: 2023-11-14 is in GPS week 2288


def test_units_and_custom_columns(tmp_path):
    d = static_flight(seconds=4.0)
    cols = ["t", "ax", "ay", "az", "gx", "gy", "gz"]
    _write_flight_csv(tmp_path, d, imu_cols=cols, acc_scale=1 / 9.80665, gyro_scale=180 / np.pi * 3600)
    cfg = {
        "inputs": CSV_IN,
        "csv": {
            "columns": {"imu": dict(zip(["time", "fx", "fy", "fz", "wx", "wy", "wz"], cols))},
            "units": {"accel": "g", "gyro": "deg/h"},
        },
    }
    rec = load_flight(ingest_options(cfg, "f"), tmp_path)
    np.testing.assert_allclose(rec.imu.specific_force_t, d["f"], rtol=1e-15, atol=0)
    np.testing.assert_allclose(rec.imu.angular_rate_t, d["w"], rtol=1e-15, atol=0)
    # feet
    (tmp_path / "alt_ft.csv").write_text("time_ns,height_m\n1,1000\n2,3280.84\n")
    _, v = read_csv_channel(tmp_path / "alt_ft.csv", "altimeter", units={"height": "ft"})
    np.testing.assert_allclose(v["height"], [304.8, 1000.000032], rtol=1e-12)


@pytest.mark.parametrize(
    "content, match",
    [
        ("time_ns,height_m\n1,2\n2,abc\n", r"bad.csv: line 3, column 'height_m': expected a number, got 'abc'"),
        (
            "# c\ntime_ns,height_m\n1,2\n2.5,3\n",
            r"bad.csv: line 4, column 'time_ns': expected integer nanoseconds, got '2.5'",
        ),
        ("time_ns,height_m\n1,2\n2,3,4\n", r"bad.csv: line 3: 3 fields, header has 2"),
        ("time_ns,alt\n1,2\n", r"bad.csv: line 1: column 'height_m' missing from the header"),
        ("# only comments\n", r"bad.csv: no header row"),
        ("time_ns,height_m\n1,n/a\n", r"bad.csv: line 2, column 'height_m': expected a number, got 'n/a'"),
        ("time_ns,height_m\n99999999999999999999,1\n", r"line 2, column 'time_ns': expected integer"),
    ],
)
def test_garbage_csv_names_file_line_column(tmp_path, content, match):
    p = tmp_path / "bad.csv"
    p.write_text(content)
    with pytest.raises(DataError, match=match):
        read_csv_channel(p, "altimeter")


def test_bad_time_strings(tmp_path):
    p = tmp_path / "bad.csv"
    p.write_text("t,height_m\n2024-01-01T00:00:00+03:00,1\n")
    with pytest.raises(DataError, match=r"line 2, column 't': expected ISO 8601 UTC"):
        read_csv_channel(p, "altimeter", {"time": "t"}, "iso")
    p.write_text("t,height_m\n2024-13-01T00:00:00Z,1\n")
    with pytest.raises(DataError, match=r"line 2, column 't': expected ISO 8601"):
        read_csv_channel(p, "altimeter", {"time": "t"}, "iso")
    p.write_text("t,height_m\n12.3e4,1\n")
    with pytest.raises(DataError, match=r"line 2, column 't': expected seconds"):
        read_csv_channel(p, "altimeter", {"time": "t"}, "s")
    (tmp_path / "bin.csv").write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(DataError, match=r"bin.csv: not UTF-8"):
        read_csv_channel(tmp_path / "bin.csv", "altimeter")
    with pytest.raises(DataError, match=r"missing.csv: cannot open"):
        read_csv_channel(tmp_path / "missing.csv", "altimeter")


def test_mistyped_imu_csv_through_load_flight(tmp_path):
    d = static_flight(seconds=2.0)
    _write_flight_csv(tmp_path, d)
    text = (tmp_path / "imu.csv").read_text().splitlines()
    parts = text[10].split(",")
    parts[5] = "0x1F"
    text[10] = ",".join(parts)
    (tmp_path / "imu.csv").write_text("\n".join(text))
    with pytest.raises(
        DataError,
        match=r"imu.csv: line 11, column 'wy_radps': expected a "
        r"number, got '0x1F'",
    ):
        load_flight(ingest_options({"inputs": CSV_IN}, "f"), tmp_path)


def test_duplicates_backward_steps_and_gaps_repaired_and_listed(tmp_path):
    d = static_flight(seconds=10.0)
    n = len(d["imu_t"])
    order = list(range(n))
    order.insert(100, 99)  # exact duplicate of sample 99
    order[500], order[501] = order[501], order[500]  # one swap: a backward step
    order = [k for k in order if not 700 <= k < 760]  # 0.6 s gap at 100 Hz
    dd = dict(d)
    dd["imu_t"], dd["f"], dd["w"] = d["imu_t"][order], d["f"][order], d["w"][order]
    _write_flight_csv(tmp_path, dd)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rec = load_flight(ingest_options({"inputs": CSV_IN}, "f"), tmp_path)
    msgs = " | ".join(str(w.message) for w in caught if w.category is DataWarning)
    assert "imu: dropped 1 duplicate samples" in msgs
    assert "imu: 1 backward time steps (re-sorted): 5.000000->4.990000 s" in msgs
    assert "imu: 1 gaps longer than the threshold: 6.990-7.600 s" in msgs
    assert all(m in rec.notes for m in msgs.split(" | "))
    keep = [k for k in range(n) if not 700 <= k < 760]
    np.testing.assert_array_equal(rec.imu.specific_force_t, d["f"][keep])
    assert np.all(np.diff(rec.imu.time) > 0)


def test_config_errors_name_the_key_and_suggest(tmp_path):
    def err(cfg, match):
        with pytest.raises(ConfigError, match=match):
            ingest_options(cfg, "flights[0]")

    err(
        {"inputs": CSV_IN, "csv": {"units": {"accel": "G"}}},
        r"flights\[0\].csv.units.accel: expected one of m/s\^2, g, mGal, m/s, got 'G' \(did you mean 'g'\?\)",
    )
    err({"inputs": CSV_IN, "csv": {"unit": {}}}, r"flights\[0\].csv.unit: unknown key \(did you mean 'units'\?\)")
    err({"inputs": {"mcap": "a", "csv": {}}}, r"flights\[0\].inputs: expected exactly one")
    err({"inputs": {"csv": {"imu": "i.csv"}}}, r"flights\[0\].inputs.csv.altimeter: missing")
    err({"inputs": {"mcap": "a"}, "topics": {"imu": ""}}, r"flights\[0\].topics.imu: expected a non-empty string")
    err({"inputs": {"mcap": "a"}, "topcs": {}}, r"flights\[0\].topcs: unknown key \(did you mean 'topics'\?\)")
    err(
        {"inputs": {"mcap": "a"}, "checks": {"gap_factor": 1}},
        r"flights\[0\].checks.gap_factor: expected a number in \[1.5",
    )
    err({"inputs": {"mcap": "a"}, "mcap": {"check_crc": "yes"}}, r"flights\[0\].mcap.check_crc: expected true or false")
    err(
        {"inputs": {"mcap": "a"}, "mcap": {"json_fields": {"imu": {"specific_force": ["a", "b"]}}}},
        r"flights\[0\].mcap.json_fields.imu.specific_force: expected a field name or a list of 3",
    )
    err(
        {"inputs": CSV_IN, "csv": {"time_format": "gps_week_sow", "columns": {"imu": {"time": "t"}}}},
        r"flights\[0\].csv.columns.imu.time: time_format gps_week_sow needs two columns",
    )
    o = ingest_options({"inputs": {"mcap": "F/x.mcap"}}, "flights[0]", base_dir=tmp_path)
    assert o.input_paths() == [tmp_path / "F" / "x.mcap"]
    assert o.topics == {"imu": "/imu", "altimeter": "/altimeter", "gnss": "/gnss"}
    assert o.check_crc is True and o.gap_factor == 5.0 and o.max_record_bytes == 256 * 2**20


def test_missing_input_file_error(tmp_path):
    with pytest.raises(DataError, match=r"imu.csv: cannot open"):
        load_flight(ingest_options({"inputs": CSV_IN}, "f"), tmp_path)
    with pytest.raises(DataError, match=r"none.mcap: cannot open"):
        load_flight(ingest_options({"inputs": {"mcap": "none.mcap"}}, "f"), tmp_path)


def test_nonfinite_samples_dropped_with_warning(tmp_path):
    d = static_flight(seconds=3.0)
    _write_flight_csv(tmp_path, d)
    lines = (tmp_path / "altimeter.csv").read_text().splitlines()
    lines[5] = lines[5].split(",")[0] + ",nan"
    lines[6] = lines[6].split(",")[0] + ",inf"
    (tmp_path / "altimeter.csv").write_text("\n".join(lines) + "\n")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rec = load_flight(ingest_options({"inputs": CSV_IN}, "f"), tmp_path)
    msgs = [str(w.message) for w in caught if w.category is DataWarning]
    assert any(m.startswith("altimeter: dropped 2 samples with empty, NaN/inf or absurd") for m in msgs)
    # the hole left behind is one 0.3 s step in 27: flagged by the rate-stability check
    assert any(m.startswith("altimeter: nominal rate 10 Hz, 3.70 % of steps off") for m in msgs)
    np.testing.assert_array_equal(rec.altimeter.height, np.delete(d["h"], [4, 5]))


def test_header_only_csv_is_a_clear_error(tmp_path):
    d = static_flight(seconds=2.0)
    _write_flight_csv(tmp_path, d)
    (tmp_path / "imu.csv").write_text("# nothing logged\ntime_ns,fx_mps2,fy_mps2,fz_mps2,wx_radps,wy_radps,wz_radps\n")
    with pytest.raises(DataError, match=r"imu.csv: no usable imu samples"):
        load_flight(ingest_options({"inputs": CSV_IN}, "f"), tmp_path)


def test_an_imu_and_a_gnss_only_read_the_gnss_heights_as_the_height_channel(tmp_path):
    """Without ``inputs.csv.altimeter`` the GNSS file's heights are the height channel (its own
    column names too); without either the error names the key and both ways out."""
    d = static_flight(seconds=5.0)
    _write_flight_csv(tmp_path, d)
    text = (tmp_path / "gnss.csv").read_text().replace("time_ns,lat_deg,lon_deg,height_m", "t,lat,lon,h_ell")
    (tmp_path / "gnss.csv").write_text(text)
    cols = {"gnss": {"time": "t", "lat": "lat", "lon": "lon", "height": "h_ell"}}
    flight = {"inputs": {"csv": {"imu": "imu.csv", "gnss": "gnss.csv"}}, "csv": {"columns": cols}}
    rec = load_flight(ingest_options(flight, "flights[0]"), tmp_path)
    np.testing.assert_array_equal(rec.altimeter.height, rec.gnss.height)
    np.testing.assert_allclose(rec.altimeter.height, d["gh"])
    with pytest.raises(
        ConfigError,
        match=r"flights\[0\]\.inputs\.csv\.altimeter: missing: give the altimeter CSV file, or the GNSS file",
    ):
        ingest_options({"inputs": {"csv": {"imu": "imu.csv"}}}, "flights[0]")


def test_gnss_positions_as_ecef_xyz_are_read_as_the_geodetic_ones(tmp_path):
    """A receiver's or simulator's XYZ export (``csv.columns.gnss: {x, y, z}``): the same
    latitudes, longitudes and heights as the geodetic file, the heights the height channel
    when there is no altimeter file; x without y and z, or with lat, is refused at the key."""
    from gravsurvey.geodesy import geodetic_to_ecef

    d = static_flight(seconds=5.0)
    _write_flight_csv(tmp_path, d)
    want = load_flight(ingest_options({"inputs": CSV_IN}, "flights[0]"), tmp_path)
    r = geodetic_to_ecef(np.radians(d["lat"]), np.radians(d["lon"]), d["gh"])
    rows = ["t,X [m],Y [m],Z [m]"] + [f"{t},{x!r},{y!r},{z!r}" for t, (x, y, z) in zip(d["gnss_t"], r.tolist())]
    (tmp_path / "xyz.csv").write_text("\n".join(rows) + "\n")
    cols = {"gnss": {"time": "t", "x": "X [m]", "y": "Y [m]", "z": "Z [m]"}}
    for inputs in (
        {"imu": "imu.csv", "altimeter": "altimeter.csv", "gnss": "xyz.csv"},
        {"imu": "imu.csv", "gnss": "xyz.csv"},
    ):
        rec = load_flight(ingest_options({"inputs": {"csv": inputs}, "csv": {"columns": cols}}, "flights[0]"), tmp_path)
        np.testing.assert_allclose(rec.gnss.lat, want.gnss.lat, rtol=0, atol=1e-13)  # rad: < 1 um
        np.testing.assert_allclose(rec.gnss.lon, want.gnss.lon, rtol=0, atol=1e-13)
        np.testing.assert_allclose(rec.gnss.height, want.gnss.height, rtol=0, atol=1e-6)
    np.testing.assert_allclose(rec.altimeter.height, want.gnss.height, rtol=0, atol=1e-6)
    for bad, said in (({"x": "X [m]"}, "no y, z"), ({"x": "X [m]", "y": "Y", "z": "Z", "lat": "lat"}, "also lat")):
        with pytest.raises(ConfigError, match=rf"flights\[0\]\.csv\.columns\.gnss: ECEF positions .*{said}"):
            ingest_options({"inputs": CSV_IN, "csv": {"columns": {"gnss": bad}}}, "flights[0]")


def test_a_row_of_units_under_the_header_is_skipped_or_names_the_unit_key(tmp_path):
    """An export writing the units in a second header row: skipped and said when they agree with
    ``csv.units``; a unit that differs refuses the file naming the column and the key (read as
    written, the rates would be 57x off)."""
    d = static_flight(seconds=5.0)
    _write_flight_csv(tmp_path, d)
    want = load_flight(ingest_options({"inputs": CSV_IN}, "f"), tmp_path).imu
    deg = "ns,m/s^2,m/s^2,m/s^2,deg/s,deg/s,deg/s"
    for row, units, scale, error in (
        ("ns,m/s^2,m/s^2,m/s^2,rad/s,rad/s,rad/s", None, 1.0, None),
        ("[ns],[g],[g],[g],[rad/s],[rad/s],[rad/s]", {"accel": "g"}, 1.0 / 9.80665, None),
        (
            deg,
            None,
            1.0,
            "column 'wx_radps': the row of units says 'deg/s', the config 'rad/s': set csv.units.gyro: 'deg/s'",
        ),
    ):
        _write_flight_csv(tmp_path, d, acc_scale=scale)
        lines = (tmp_path / "imu.csv").read_text().splitlines()
        head = next(i for i, ln in enumerate(lines) if ln.startswith("time_ns"))
        (tmp_path / "imu.csv").write_text("\n".join(lines[: head + 1] + [row] + lines[head + 1 :]) + "\n")
        flight = {"inputs": CSV_IN} | ({"csv": {"units": units}} if units else {})
        if error:
            with pytest.raises(DataError, match=re.escape(f"imu.csv: line {head + 2}, {error}")):
                load_flight(ingest_options(flight, "f"), tmp_path)
            continue
        said = rf"imu.csv: line {head + 2} read as a row of units under the header and skipped"
        with pytest.warns(DataWarning, match=said):
            got = load_flight(ingest_options(flight, "f"), tmp_path).imu
        np.testing.assert_array_equal(got.time, want.time)
        np.testing.assert_allclose(got.specific_force_t, want.specific_force_t, rtol=1e-15, atol=0)
