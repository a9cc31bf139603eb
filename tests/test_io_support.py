"""Test-file builders for the ingestion tests, written with the ``mcap`` / ``mcap_ros2`` writers
straight from docs/formats.md (independent of both our reader and the simulator's writers),
plus checks that these builders produce what the ``mcap`` package itself reads back."""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer
from mcap_ros2.decoder import DecoderFactory
from mcap_ros2.writer import Writer as Ros2Writer

# outside data copied into the repository with their licences (tests/data/*/LICENSE)
EXTERNAL = Path(__file__).resolve().parent / "data"
OMEGA_E = 7.292115e-5
START_NS = 1_750_000_000_123_456_789

_SEP = "=" * 80
_TIME = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec"
_HEADER = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id"
_VEC3 = "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z"
_QUAT = "MSG: geometry_msgs/Quaternion\nfloat64 x\nfloat64 y\nfloat64 z\nfloat64 w"
_POINT = "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z"
_STATUS = "MSG: sensor_msgs/NavSatStatus\nint8 STATUS_FIX=0\nuint16 SERVICE_GPS=1\nint8 status\nuint16 service"
MSGDEFS = {
    "sensor_msgs/msg/Imu": "\n".join(
        [
            "std_msgs/Header header",
            "geometry_msgs/Quaternion orientation",
            "float64[9] orientation_covariance",
            "geometry_msgs/Vector3 angular_velocity",
            "float64[9] angular_velocity_covariance",
            "geometry_msgs/Vector3 linear_acceleration",
            "float64[9] linear_acceleration_covariance",
            _SEP,
            _HEADER,
            _SEP,
            _TIME,
            _SEP,
            _QUAT,
            _SEP,
            _VEC3,
        ]
    ),
    "geometry_msgs/msg/PointStamped": "\n".join(
        ["std_msgs/Header header", "geometry_msgs/Point point", _SEP, _HEADER, _SEP, _TIME, _SEP, _POINT]
    ),
    "sensor_msgs/msg/NavSatFix": "\n".join(
        [
            "std_msgs/Header header",
            "sensor_msgs/NavSatStatus status",
            "float64 latitude",
            "float64 longitude",
            "float64 altitude",
            "float64[9] position_covariance",
            "uint8 position_covariance_type",
            _SEP,
            _HEADER,
            _SEP,
            _TIME,
            _SEP,
            _STATUS,
        ]
    ),
}


def static_flight(seconds=20.0, imu_hz=100.0, alt_hz=10.0, lat_deg=45.0, seed=0):
    """A platform (ENU) triad at rest: F = (0, 0, ~g), w = Earth rate; noisy, physical.

    Returns a dict of int64 ns times and float64 SI arrays (lat/lon in degrees).
    """
    rng = np.random.default_rng(seed)
    n = int(seconds * imu_hz)
    m = int(seconds * alt_hz)
    lat = np.radians(lat_deg)
    ti = START_NS + np.round(np.arange(n) * 1e9 / imu_hz).astype(np.int64)
    ta = START_NS + np.round(np.arange(m) * 1e9 / alt_hz).astype(np.int64)
    f = np.array([0.0, 0.0, 9.806]) + rng.normal(0, 1e-3, (n, 3))
    w = np.array([0.0, OMEGA_E * np.cos(lat), OMEGA_E * np.sin(lat)]) + rng.normal(0, 1e-7, (n, 3))
    h = 250.0 + rng.normal(0, 0.5, m)
    return {
        "imu_t": ti,
        "f": f,
        "w": w,
        "alt_t": ta,
        "h": h,
        "gnss_t": ta.copy(),
        "lat": lat_deg + rng.normal(0, 1e-6, m),
        "lon": 135.0 + rng.normal(0, 1e-6, m),
        "gh": h + rng.normal(0, 0.1, m),
    }


def _stamp(t):
    return {"sec": int(t) // 10**9, "nanosec": int(t) % 10**9}


def write_ros2(
    path,
    d,
    chunk_size=4096,
    compression=CompressionType.ZSTD,
    frame_ids=None,
    topics=("/imu", "/altimeter", "/gnss"),
    zero_stamps=(),
):
    """ROS 2 CDR MCAP via mcap_ros2's encoder.  ``frame_ids``: per IMU message (varying
    lengths exercise the grouped decoder); ``zero_stamps``: IMU indices with header.stamp 0."""
    with open(path, "wb") as fh:
        wr = Ros2Writer(fh, chunk_size=chunk_size, compression=compression)
        s = {k: wr.register_msgdef(k, v) for k, v in MSGDEFS.items()}
        items = []
        for k, t in enumerate(d["imu_t"]):
            fid = frame_ids[k] if frame_ids is not None else "imu"
            msg = {
                "header": {"stamp": _stamp(0 if k in zero_stamps else t), "frame_id": fid},
                "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
                "orientation_covariance": [-1.0] + [0.0] * 8,
                "angular_velocity": dict(zip("xyz", map(float, d["w"][k]))),
                "angular_velocity_covariance": [0.0] * 9,
                "linear_acceleration": dict(zip("xyz", map(float, d["f"][k]))),
                "linear_acceleration_covariance": [0.0] * 9,
            }
            items.append((int(t), 0, topics[0], s["sensor_msgs/msg/Imu"], msg))
        for k, t in enumerate(d["alt_t"]):
            msg = {
                "header": {"stamp": _stamp(t), "frame_id": "altimeter"},
                "point": {"x": 0.0, "y": 0.0, "z": float(d["h"][k])},
            }
            items.append((int(t), 1, topics[1], s["geometry_msgs/msg/PointStamped"], msg))
        for k, t in enumerate(d["gnss_t"]):
            msg = {
                "header": {"stamp": _stamp(t), "frame_id": "gnss"},
                "status": {"status": 0, "service": 1},
                "latitude": float(d["lat"][k]),
                "longitude": float(d["lon"][k]),
                "altitude": float(d["gh"][k]),
                "position_covariance": [0.0] * 9,
                "position_covariance_type": 2,
            }
            items.append((int(t), 2, topics[2], s["sensor_msgs/msg/NavSatFix"], msg))
        items.sort(key=lambda x: (x[0], x[1]))
        for t, _, topic, schema, msg in items:
            wr.write_message(topic, schema, msg, log_time=t, publish_time=t)
        wr.finish()


def write_json(path, d, chunk_size=4096, compression=CompressionType.ZSTD, use_chunking=True, names=None):
    """JSON MCAP per docs/formats.md (``names`` overrides field names: for mapping tests)."""
    nm = {
        "time": "time_ns",
        "f": "specific_force_t",
        "w": "angular_rate_t",
        "h": "height_m",
        "lat": "lat_deg",
        "lon": "lon_deg",
    }
    nm.update(names or {})
    with open(path, "wb") as fh:
        wr = Writer(fh, chunk_size=chunk_size, compression=compression, use_chunking=use_chunking)
        wr.start(profile="", library="tests")
        ids = {}
        for role, title in (
            ("imu", "gravsurvey.Imu"),
            ("altimeter", "gravsurvey.Altimeter"),
            ("gnss", "gravsurvey.Gnss"),
        ):
            sid = wr.register_schema(title, "jsonschema", json.dumps({"title": title, "type": "object"}).encode())
            ids[role] = wr.register_channel(f"/{role}", "json", sid)
        items = []
        for k, t in enumerate(d["imu_t"]):
            items.append(
                (int(t), 0, ids["imu"], {nm["time"]: int(t), nm["f"]: d["f"][k].tolist(), nm["w"]: d["w"][k].tolist()})
            )
        for k, t in enumerate(d["alt_t"]):
            items.append((int(t), 1, ids["altimeter"], {nm["time"]: int(t), nm["h"]: float(d["h"][k])}))
        for k, t in enumerate(d["gnss_t"]):
            items.append(
                (
                    int(t),
                    2,
                    ids["gnss"],
                    {
                        nm["time"]: int(t),
                        nm["lat"]: float(d["lat"][k]),
                        nm["lon"]: float(d["lon"][k]),
                        nm["h"]: float(d["gh"][k]),
                    },
                )
            )
        items.sort(key=lambda x: (x[0], x[1]))
        for seq, (t, _, cid, obj) in enumerate(items):
            wr.add_message(cid, log_time=t, data=json.dumps(obj).encode(), publish_time=t, sequence=seq)
        wr.finish()


def reference_messages(path):
    """All messages by the mcap package's own reader: (topic, log_time, data), file order."""
    with open(path, "rb") as fh:
        return [(c.topic, m.log_time, m.data) for _, c, m in make_reader(fh).iter_messages(log_time_order=False)]


def test_builders_roundtrip_through_mcap_package(tmp_path):
    """The builders write what docs/formats.md says, judged by the mcap package's readers."""
    d = static_flight(seconds=2.0)
    write_ros2(tmp_path / "r.mcap", d)
    write_json(tmp_path / "j.mcap", d)
    with open(tmp_path / "r.mcap", "rb") as fh:
        got = [
            (c.topic, m.log_time, dm)
            for _, c, m, dm in make_reader(fh, decoder_factories=[DecoderFactory()]).iter_decoded_messages(
                topics=["/imu"]
            )
        ]
    assert len(got) == len(d["imu_t"])
    assert [g[1] for g in got] == d["imu_t"].tolist()
    assert got[5][2].linear_acceleration.z == d["f"][5, 2]
    j = [(t, json.loads(b)) for t, _, b in reference_messages(tmp_path / "j.mcap") if t == "/gnss"]
    assert [o["lat_deg"] for _, o in j] == d["lat"].tolist()
    buf = io.BytesIO((tmp_path / "j.mcap").read_bytes())
    assert make_reader(buf).get_summary().statistics.message_count == 200 + 20 + 20
