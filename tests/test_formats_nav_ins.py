"""A navigation file (NMEA, GNSS trajectory text) as the GNSS of an INS flight (``inputs.nav``).

The simulated sample flight ``sample_data/markov_csv`` (CSV IMU and altimeter) is processed twice:
with the simulator's own GNSS CSV, and with the same GNSS written here as an NMEA log the way a
receiver writes it (u-blox defaults: GGA + RMC, minutes to 5 decimals = 1.9 cm, altitude above
the geoid and geoid separation to 0.1 m, time of day to 0.01 s). Both are compared with the
simulator's truth.
"""

import csv
import json
import os
import shutil
import subprocess
import sys
import warnings
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pytest

from gravsurvey.errors import ConfigError, DataError
from gravsurvey.io.ingest import load_flight
from gravsurvey.settings import ingest_options as ingest_options_from_dict

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_data" / "markov_csv"
#: geoid separation the "receiver" writes (any value: the reader adds it back), m
GEOID_N_M = 17.9


def nmea(body: str) -> str:
    cs = 0
    for ch in body:
        cs ^= ord(ch)
    return f"${body}*{cs:02X}"


def dm(x: float, deg_digits: int) -> str:
    """ddmm.mmmmm / dddmm.mmmmm: degrees and minutes to 5 decimals (u-blox default)."""
    a = abs(x)
    d = int(a)
    m = round((a - d) * 60.0, 5)
    if m >= 60.0:
        d, m = d + 1, 0.0
    return f"{d:0{deg_digits}d}{m:08.5f}"


def write_nmea(gnss_csv: Path, out: Path) -> np.ndarray:
    """GGA + RMC per fix from the simulator's GNSS CSV; returns the CSV rows (n, 4)."""
    rows = np.array(
        [
            [float(v) for v in r]
            for r in csv.reader(
                ln for ln in gnss_csv.read_text().splitlines() if ln and not ln.startswith(("#", "time"))
            )
        ]
    )
    lines = []
    for t_ns, lat, lon, h in rows:
        tm = datetime.fromtimestamp(int(t_ns) // 10**9, tz=timezone.utc)
        hms = tm.strftime("%H%M%S") + f".{int(t_ns) % 10**9 // 10**7:02d}"
        la, lo = dm(lat, 2), dm(lon, 3)
        ns, ew = ("N" if lat >= 0 else "S"), ("E" if lon >= 0 else "W")
        lines.append(nmea(f"GNGGA,{hms},{la},{ns},{lo},{ew},2,12,0.80,{h - GEOID_N_M:.1f},M,{GEOID_N_M:.1f},M,,"))
        lines.append(nmea(f"GNRMC,{hms},A,{la},{ns},{lo},{ew},135.9,90.0,{tm.strftime('%d%m%y')},,,D,V"))
    out.write_text("\r\n".join(lines) + "\r\n")
    return rows


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    d = tmp_path_factory.mktemp("navins")
    shutil.copytree(SAMPLE / "F01", d / "F01")
    rows = write_nmea(d / "F01" / "gnss.csv", d / "F01" / "gnss.nmea")
    return d, rows


def _run(d: Path, name: str, inputs: str) -> dict:
    cfg = d / f"{name}.yaml"
    cfg.write_text(
        f"survey: {{name: {name}}}\nflights:\n- name: F01\n  inputs:\n{inputs}  triad: platform\n"
        f"  truth: F01/truth.csv\nlines: {{mode: auto}}\ngrid: {{enabled: false}}\n"
        f"output: {{dir: out_{name}, plots: false}}\n"
    )
    r = subprocess.run(
        [sys.executable, "-m", "gravsurvey", "run", str(cfg), "-q"],
        capture_output=True,
        text=True,
        timeout=900,
        env=dict(os.environ),
        stdin=subprocess.DEVNULL,
        cwd=d,
        check=False,
    )
    assert r.returncode == 0, r.stderr
    return json.loads((d / f"out_{name}" / "summary.json").read_text())


def test_nmea_positions_reach_the_record(flight):
    d, rows = flight
    o = ingest_options_from_dict(
        {
            "inputs": {
                "csv": {"imu": "F01/imu.csv", "altimeter": "F01/altimeter.csv"},
                "nav": {"format": "nmea", "file": "F01/gnss.nmea"},
            }
        },
        base_dir=d,
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rec = load_flight(o)
    # a clean NMEA file is no finding
    assert not [w for w in caught if "gnss" in str(w.message)], [str(w.message) for w in caught]
    assert rec.gnss is not None and rec.gnss.time.size == rows.shape[0]
    t = rec.t0_unix_ns + np.round(rec.gnss.time * 1e9).astype(np.int64)
    assert np.array_equal(t, rows[:, 0].astype(np.int64))
    # 5 decimals of a minute: 0.5e-5 / 60 deg at most = 0.93 cm north
    assert np.abs(np.degrees(rec.gnss.lat) - rows[:, 1]).max() * 111_320 < 0.0095
    assert np.abs(rec.gnss.height - rows[:, 3]).max() <= 0.05 + 1e-6  # altitude to 0.1 m
    assert any("F01/gnss.nmea" in p.as_posix() for p in o.input_paths())


def test_ins_flight_with_nmea_gnss_matches_the_csv_gnss_run(flight):
    d, _ = flight
    ref = _run(d, "csvgnss", "    csv: {imu: F01/imu.csv, altimeter: F01/altimeter.csv, gnss: F01/gnss.csv}\n")
    got = _run(
        d,
        "nmeagnss",
        "    csv: {imu: F01/imu.csv, altimeter: F01/altimeter.csv}\n    nav: {format: nmea, file: F01/gnss.nmea}\n",
    )
    e_ref, e_got = ref["flights"]["F01"]["estimator"], got["flights"]["F01"]["estimator"]
    assert e_ref["gnss_aided"] and e_got["gnss_aided"]
    r_ref, r_got = ref["rms_vs_truth_mgal"], got["rms_vs_truth_mgal"]
    # the same flight: NMEA rounding (1 cm, 5 cm in height) changes the result by less than 0.05 mGal
    assert abs(r_got - r_ref) < 0.05, (r_ref, r_got)
    assert r_got < 4.4  # docs/samples.md bound of this sample
    assert got["flights"]["F01"]["input_sha256"] != ref["flights"]["F01"]["input_sha256"]


def test_nav_config_and_data_errors(tmp_path, flight):
    d, _ = flight
    base = {"csv": {"imu": "F01/imu.csv", "altimeter": "F01/altimeter.csv"}}
    with pytest.raises(
        ConfigError, match=r"^flights\[0\]\.inputs\.nav\.format: expected one of nmea, trajectory, rtklib"
    ):
        ingest_options_from_dict({"inputs": {**base, "nav": {"format": "gpx", "file": "x"}}})
    with pytest.raises(ConfigError, match=r"^flights\[0\]\.inputs\.nav\.fiel: unknown key"):
        ingest_options_from_dict({"inputs": {**base, "nav": {"format": "nmea", "fiel": "x"}}})
    with pytest.raises(ConfigError, match=r"^flights\[0\]\.inputs: expected exactly one of mcap, csv, gravimeter"):
        ingest_options_from_dict({"inputs": {"nav": {"format": "nmea", "file": "x"}}})
    # GGA without the geoid separation: heights above the geoid are refused, naming the file
    text = (d / "F01" / "gnss.nmea").read_text().splitlines()
    bad = [nmea(ln[1:].split("*")[0].replace(f",M,{GEOID_N_M:.1f},M,", ",M,,M,")) if "GGA" in ln else ln for ln in text]
    (tmp_path / "F01").mkdir()
    (tmp_path / "F01" / "msl.nmea").write_text("\n".join(bad) + "\n")
    for f in ("imu.csv", "altimeter.csv"):
        (tmp_path / "F01" / f).symlink_to(d / "F01" / f)
    o = ingest_options_from_dict(
        {"inputs": {**base, "nav": {"format": "nmea", "file": "F01/msl.nmea"}}}, base_dir=tmp_path
    )
    with pytest.raises(DataError, match=r"msl\.nmea: no ellipsoidal heights; expected GGA sentences with the geoid"):
        load_flight(o)
    o = ingest_options_from_dict(
        {"inputs": {**base, "nav": {"format": "trajectory", "file": "F01/none.txt"}}}, base_dir=tmp_path
    )
    with pytest.raises(DataError, match=r"none\.txt: navigation file not found"):
        load_flight(o)


def test_trajectory_text_is_the_gnss_of_an_ins_flight(flight, tmp_path):
    """A GrafNav-style export (GPS date/time, ellipsoidal height) from the simulator's GNSS."""
    from gravsurvey.io.formats.common import gps_leap_seconds

    d, rows = flight
    lines = ["GPSDate, GPSTime, Latitude, Longitude, H-Ell, NS, PDOP"]
    for t_ns, lat, lon, h in rows:
        t_gps = int(t_ns) // 10**9 + gps_leap_seconds(int(t_ns) / 1e9)  # UTC -> GPS time
        tm = datetime.fromtimestamp(t_gps, tz=timezone.utc)
        lines.append(
            f"{tm:%m/%d/%Y}, {tm:%H:%M:%S}.{int(t_ns) % 10**9 // 10**6:03d}, {lat:.9f}, {lon:.9f}, {h:.3f}, 12, 1.4"
        )
    (tmp_path / "traj.txt").write_text("\n".join(lines) + "\n")
    o = ingest_options_from_dict(
        {
            "inputs": {
                "csv": {"imu": str(d / "F01" / "imu.csv"), "altimeter": str(d / "F01" / "altimeter.csv")},
                "nav": {"format": "trajectory", "file": str(tmp_path / "traj.txt")},
            }
        }
    )
    rec = load_flight(o)
    t = rec.t0_unix_ns + np.round(rec.gnss.time * 1e9).astype(np.int64)
    assert np.array_equal(t, rows[:, 0].astype(np.int64))  # GPS time back to UTC exactly
    assert np.abs(np.degrees(rec.gnss.lat) - rows[:, 1]).max() < 1e-9
    assert np.abs(rec.gnss.height - rows[:, 3]).max() <= 0.0005 + 1e-9


def _write_pos(rows, path, layout="llh", scale="GPST", height="ellipsoidal", quality=None):
    """An RTKLIB .pos file of the simulator's GNSS rows, as rnx2rtkp writes it."""
    from gravsurvey.geodesy import geodetic_to_ecef
    from gravsurvey.io.formats.common import gps_leap_seconds

    label = {"llh": "latitude(deg) longitude(deg)  height(m)", "xyz": "x-ecef(m)      y-ecef(m)      z-ecef(m)"}
    label["dms"] = "latitude(d'\") longitude(d'\")  height(m)"
    out = [
        "% program   : RTKLIB ver.2.4.3 b34",
        f"% (lat/lon/height=WGS84/{height},Q=1:fix,2:float,3:sbas,4:dgps,5:single,6:ppp,ns=# of satellites)",
        f"%  {scale:<21} {label[layout]}   Q  ns   sdn(m)   sde(m)   sdu(m)  sdne(m)  sdeu(m)  sdun(m) age(s)  ratio",
    ]
    for k, (t_ns, lat, lon, h) in enumerate(rows):
        if scale == "GPST":
            sec = int(t_ns) // 10**9 + gps_leap_seconds(int(t_ns) / 1e9)
        else:
            sec = int(t_ns) // 10**9 + (9 * 3600 if scale == "JST" else 0)
        tm = datetime.fromtimestamp(sec, tz=timezone.utc)
        stamp = f"{tm:%Y/%m/%d %H:%M:%S}.{int(t_ns) % 10**9 // 10**6:03d}"
        if layout == "xyz":
            x, y, z = geodetic_to_ecef(np.radians(lat), np.radians(lon), h).ravel()
            p = f"{x:14.4f} {y:14.4f} {z:14.4f}"
        elif layout == "dms":

            def dms(v):
                a = abs(v)
                d, m = int(a), int((a - int(a)) * 60)
                s = (a - d - m / 60.0) * 3600.0
                return f"{'-' if v < 0 else ''}{d:d} {m:02d} {s:011.8f}"

            p = f"{dms(lat)} {dms(lon)} {h:10.4f}"
        else:
            p = f"{lat:14.9f} {lon:14.9f} {h:10.4f}"
        q = 1 if quality is None else quality[k]
        out.append(f"{stamp} {p}   {q}  11   0.0040   0.0030   0.0100  -0.0010   0.0010  -0.0030   0.00    0.0")
    path.write_text("\n".join(out) + "\n")


@pytest.mark.parametrize("layout, scale", [("llh", "GPST"), ("xyz", "UTC"), ("dms", "JST")])
def test_an_rtklib_solution_is_the_gnss_of_an_ins_flight(flight, tmp_path, layout, scale):
    """An RTKLIB .pos file (the usual post-processed GNSS of a survey) read as the flight's GNSS:
    the simulator's fixes back to the written digits, in each of RTKLIB's position layouts and
    time scales; with all solutions fixed nothing is said."""
    d, rows = flight
    _write_pos(rows, tmp_path / "sol.pos", layout, scale)
    nav = {"format": "rtklib", "file": str(tmp_path / "sol.pos")}
    o = ingest_options_from_dict(
        {
            "inputs": {
                "csv": {"imu": str(d / "F01" / "imu.csv"), "altimeter": str(d / "F01" / "altimeter.csv")},
                "nav": nav,
            }
        }
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rec = load_flight(o)
    assert not [w for w in caught if "gnss" in str(w.message)], [str(w.message) for w in caught]
    t = rec.t0_unix_ns + np.round(rec.gnss.time * 1e9).astype(np.int64)
    assert np.array_equal(t, rows[:, 0].astype(np.int64))
    north_m = np.abs(np.degrees(rec.gnss.lat) - rows[:, 1]).max() * 111_320
    assert north_m < {"llh": 1e-4, "xyz": 2e-4, "dms": 2e-4}[layout]  # 1e-9 deg, 0.1 mm, 1e-8 arcsec
    assert np.abs(rec.gnss.height - rows[:, 3]).max() <= 1e-4


def test_rtklib_heights_above_the_geoid_baselines_and_float_solutions_are_said(flight, tmp_path):
    from gravsurvey.io.formats import read_rtklib_pos

    d, rows = flight
    base = {"csv": {"imu": str(d / "F01" / "imu.csv"), "altimeter": str(d / "F01" / "altimeter.csv")}}
    _write_pos(rows, tmp_path / "geoid.pos", height="geodetic")
    o = ingest_options_from_dict({"inputs": {**base, "nav": {"format": "rtklib", "file": str(tmp_path / "geoid.pos")}}})
    with pytest.raises(
        DataError, match=r"geoid\.pos: no ellipsoidal heights; expected ellipsoidal heights \(RTKLIB out-height"
    ):
        load_flight(o)
    text = (
        (tmp_path / "geoid.pos")
        .read_text()
        .replace("latitude(deg) longitude(deg)  height(m)", "e-baseline(m) n-baseline(m) u-baseline(m)")
    )
    (tmp_path / "enu.pos").write_text(text)
    with pytest.raises(DataError, match=r"enu\.pos: line 3: east/north/up baselines hold no absolute position"):
        read_rtklib_pos(tmp_path / "enu.pos")
    q = [2 if k % 10 == 0 else 1 for k in range(len(rows))]
    _write_pos(rows, tmp_path / "float.pos", quality=q)
    tab = read_rtklib_pos(tmp_path / "float.pos")
    assert np.array_equal(tab.columns["quality"], q)
    assert any(f"solutions by quality: fix {q.count(1)}, float {q.count(2)} (not all fixed" in n for n in tab.notes)
    with pytest.raises(DataError, match=r"traj\.txt: no RTKLIB column header"):
        (tmp_path / "traj.txt").write_text("GPSDate, GPSTime, Latitude, Longitude, H-Ell\n")
        read_rtklib_pos(tmp_path / "traj.txt")
