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
    with pytest.raises(ConfigError, match=r"^flights\[0\]\.inputs\.nav\.format: expected one of nmea, trajectory"):
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
