"""``gravsurvey inspect`` on a vendor CSV: the ``csv`` settings suggested from its header name the
right columns, units and time format, and a config built from them reads the real VN-310E
recording (tests/data/real-imu, MPL-2.0) as the hand-written config does."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from gravsurvey.io.columns import suggest_csv_settings, suggestion_yaml
from gravsurvey.io.ingest import load_flight
from gravsurvey.settings import ingest_options

DATA = Path(__file__).parent / "data" / "real-imu"


def _header(path):
    return Path(path).read_text().splitlines()[0].split(",")


@pytest.mark.parametrize(
    "header, imu, units, time_format",
    [
        (
            ["timestamp", "acc_x", "acc_y", "acc_z", "gyro_x", "gyro_y", "gyro_z"],
            ["acc_x", "acc_y", "acc_z", "gyro_x", "gyro_y", "gyro_z"],
            {"accel": "m/s^2", "gyro": "rad/s"},
            "s",
        ),
        (
            [
                "Time (ns)",
                "AccX (g)",
                "AccY (g)",
                "AccZ (g)",
                "GyrX (deg/s)",
                "GyrY (deg/s)",
                "GyrZ (deg/s)",
                "Temp (C)",
            ],
            ["AccX (g)", "AccY (g)", "AccZ (g)", "GyrX (deg/s)", "GyrY (deg/s)", "GyrZ (deg/s)"],
            {"accel": "g", "gyro": "deg/s"},
            "ns",
        ),
        (
            ["GPS Week", "GPS SOW [s]", "DeltaVelX [m/s]", "DeltaVelY [m/s]", "DeltaVelZ [m/s]"]
            + ["DeltaThetaX [rad]", "DeltaThetaY [rad]", "DeltaThetaZ [rad]"],
            ["DeltaVelX [m/s]", "DeltaVelY [m/s]", "DeltaVelZ [m/s]", "DeltaThetaX [rad]", "DeltaThetaY [rad]"]
            + ["DeltaThetaZ [rad]"],
            {"accel": "m/s", "gyro": "rad"},
            "gps_week_sow",
        ),
    ],
)
def test_imu_columns_units_and_time_from_the_names(header, imu, units, time_format):
    s = suggest_csv_settings(header)
    cols = s["columns"]["imu"]
    assert [cols[q] for q in ("fx", "fy", "fz", "wx", "wy", "wz")] == imu
    assert s["units"] == units and s["time_format"] == time_format
    assert any("imu_axes" in n for n in s["notes"])


def test_gnss_columns_prefer_the_receiver_and_name_doubts():
    s = suggest_csv_settings(_header(DATA / "vn310-gnss-part.csv"))
    assert s["columns"]["gnss"] == {
        "time": ["GpsCycle", "GpsWeek", "GpsTow [s]"],
        "lat": "GNSS1::PosLla::latitude [deg]",
        "lon": "GNSS1::PosLla::longitude [deg]",
        "height": "GNSS1::PosLla::altitude [m]",
    }
    s = suggest_csv_settings(["time", "lat", "lon", "alt_msl", "ins_lat", "ins_lon"])
    assert s["columns"]["gnss"]["lat"] == "lat" and s["columns"]["gnss"]["height"] == "alt_msl"
    assert any("sea level" in n for n in s["notes"])
    # linear (gravity-free) accelerations are not the specific force; a header of nothing: nothing
    assert (
        "imu"
        not in suggest_csv_settings(["t"] + [f"LinearAccel{a}" for a in "XYZ"] + [f"Gyro{a}" for a in "XYZ"])["columns"]
    )
    assert suggest_csv_settings(["a", "b", "c"])["columns"] == {}
    # a position in radians: read as such (units.latlon), not a note to convert the file
    s = suggest_csv_settings(["time [s]", "Latitude [rad]", "Longitude [rad]", "Height [m]"])
    assert s["units"] == {"latlon": "rad"} and not any("degrees" in n for n in s["notes"])
    # positions as ECEF X, Y, Z (velocities beside them are not positions)
    s = suggest_csv_settings(
        ["time [s]"] + [f"GNSS1::VelEcef::{a} [m/s]" for a in "XYZ"] + [f"GNSS1::PosEcef::{a} [m]" for a in "XYZ"]
    )
    want = {"time": "time [s]", **{a: f"GNSS1::PosEcef::{a.upper()} [m]" for a in "xyz"}}
    assert s["columns"]["gnss"] == want and s["columns"]["altimeter"] == want


def test_the_suggestion_reads_the_real_vn310_as_the_hand_written_config(tmp_path):
    """Both VN-310E files inspected; their suggestions, pasted into a flight with the axes the
    names cannot tell (FRD), load the recording exactly as the hand-written config of
    tests/test_alignment.py does."""
    for name in ("vn310-imu-part.csv", "vn310-gnss-part.csv"):
        (tmp_path / name).write_bytes((DATA / name).read_bytes())
    r = subprocess.run(
        [sys.executable, "-m", "gravsurvey", "inspect", "vn310-imu-part.csv", "vn310-gnss-part.csv"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        stdin=subprocess.DEVNULL,
    )
    assert r.returncode == 1  # neither file is a channel CSV as it stands: said, with the suggestion
    blocks, cur = [], None
    for line in r.stdout.splitlines():
        if line.startswith("    csv:"):
            cur = [line[4:]]
            blocks.append(cur)
        elif cur is not None and line.startswith("      "):
            cur.append(line[4:])
        else:
            cur = None
    assert len(blocks) == 2
    imu_csv, gnss_csv = (yaml.safe_load("\n".join(b))["csv"] for b in blocks)
    csv = {
        "time_format": imu_csv["time_format"],
        "columns": {**imu_csv["columns"], **gnss_csv["columns"]},
        "units": imu_csv["units"],
    }
    assert csv["time_format"] == gnss_csv["time_format"] == "gps_week_sow"
    flight = {
        "inputs": {
            "csv": {"imu": "vn310-imu-part.csv", "altimeter": "vn310-gnss-part.csv", "gnss": "vn310-gnss-part.csv"}
        },
        "csv": csv,
        "imu_axes": "FRD",
    }
    with pytest.warns(Warning):  # the MEMS gyro's bias at rest
        rec = load_flight(ingest_options(flight, base_dir=tmp_path))
    hand = {
        "inputs": flight["inputs"],
        "imu_axes": "FRD",
        "csv": {
            "time_format": "gps_week_sow",
            "columns": {
                "imu": {
                    "time": ["GpsCycle", "GpsWeek", "GpsTow [s]"],
                    **{f"f{a.lower()}": f"IMU::UncompAccel::{a} [m/s^2]" for a in "XYZ"},
                    **{f"w{a.lower()}": f"IMU::UncompGyro::{a} [rad/s]" for a in "XYZ"},
                },
                "altimeter": {"time": ["GpsCycle", "GpsWeek", "GpsTow [s]"], "height": "GNSS1::PosLla::altitude [m]"},
                "gnss": {
                    "time": ["GpsCycle", "GpsWeek", "GpsTow [s]"],
                    "lat": "GNSS1::PosLla::latitude [deg]",
                    "lon": "GNSS1::PosLla::longitude [deg]",
                    "height": "GNSS1::PosLla::altitude [m]",
                },
            },
        },
    }
    with pytest.warns(Warning):
        ref = load_flight(ingest_options(hand, base_dir=tmp_path))
    assert rec.t0_unix_ns == ref.t0_unix_ns
    np.testing.assert_array_equal(rec.imu.specific_force_t, ref.imu.specific_force_t)
    np.testing.assert_array_equal(rec.imu.angular_rate_t, ref.imu.angular_rate_t)
    np.testing.assert_array_equal(rec.gnss.lat, ref.gnss.lat)
    np.testing.assert_array_equal(rec.altimeter.height, ref.altimeter.height)


def test_suggestion_yaml_is_flow_style_per_channel():
    s = suggest_csv_settings(["t", "ax", "ay", "az", "wx", "wy", "wz"])
    lines = suggestion_yaml(s)
    assert lines[0] == "csv:" and yaml.safe_load("\n".join(lines))["csv"]["columns"]["imu"]["fx"] == "ax"
