"""MCAP reader: conformance corpus, real ROS 2 recordings, exact round trips, bulk decoders."""

from __future__ import annotations

import json
from pathlib import Path
import struct
import warnings

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType
from mcap_ros2.decoder import DecoderFactory
from test_io_support import EXTERNAL, static_flight, write_json, write_ros2

from gravsurvey.errors import DataError, DataWarning
from gravsurvey.inm.heightqc import gnss_height_fraction
from gravsurvey.io.ingest import load_flight, read_raw_channels
from gravsurvey.io.inspect import format_inspect, inspect_files
from gravsurvey.io.mcap import read_mcap, scan_records
from gravsurvey.settings import ingest_options

CONFORMANCE = EXTERNAL / "mcap-conformance"
ROS2 = EXTERNAL / "ros2-imu"


def _conformance_files():
    files = sorted(CONFORMANCE.glob("*/*.mcap"))
    assert len(files) == 416, f"expected the 416-file corpus at {CONFORMANCE}, found {len(files)}"
    return files


def test_conformance_corpus_messages_exact():
    """Every conformance file gives exactly its .json's messages in log-time order."""
    keyerror_files = 0
    for f in _conformance_files():
        exp = json.loads(f.with_suffix(".json").read_text())["records"]
        topics = {int(dict(r["fields"])["id"]): dict(r["fields"])["topic"] for r in exp if r["type"] == "Channel"}
        msgs = [dict(r["fields"]) for r in exp if r["type"] == "Message"]
        want = sorted(
            ((topics[int(m["channel_id"])], int(m["log_time"]), bytes(int(x) for x in m["data"])) for m in msgs),
            key=lambda x: x[1],
        )
        c = read_mcap(f, keep_raw=True)
        got = [(c.channels[ch].topic, lt, data) for ch, _, lt, _, data in c.raw]
        assert got == want, f.name
        assert c.salvage is None, f.name
        try:
            with open(f, "rb") as fh:
                list(make_reader(fh).iter_messages())
        except KeyError:
            keyerror_files += 1
    # the corpus README: the mcap package's indexed reader fails on these 112 files
    assert keyerror_files == 112


def test_ten_messages_out_of_order_log_times():
    c = read_mcap(CONFORMANCE / "TenMessages" / "TenMessages-ch-chx-mx-st.mcap", keep_raw=True)
    assert [m[2] for m in c.raw] == [0, 1, 2, 3, 3, 4, 5, 7, 8, 9]
    # equal log times keep file order (sequence 3 before 4)
    assert [m[1] for m in c.raw][3:5] == [3, 4]


def test_scan_kernel_matches_reference():
    for f in list(_conformance_files())[::7] + [ROS2 / "robot_localization_test2.mcap"]:
        buf = np.frombuffer(f.read_bytes(), np.uint8)
        a = scan_records(buf, 8, len(buf), True, use_kernel=True)
        b = scan_records(buf, 8, len(buf), True, use_kernel=False)
        assert a[:3] == b[:3], f.name
        for x, y in zip(a[3], b[3]):
            np.testing.assert_array_equal(x, y)
        # also on truncated buffers: same stop position and status
        cut = len(buf) * 2 // 3
        a = scan_records(buf, 8, cut, True)
        b = scan_records(buf, 8, cut, True, use_kernel=False)
        assert a[:3] == b[:3], f.name


@pytest.fixture(scope="module")
def ros2_reference():
    """Imu/NavSatFix values decoded by mcap_ros2 (independent decoder)."""
    out = {}
    for name in ("robot_localization_test1.mcap", "robot_localization_test2.mcap"):
        vals = {}
        with open(ROS2 / name, "rb") as fh:
            r = make_reader(fh, decoder_factories=[DecoderFactory()])
            for _, ch, _, m in r.iter_decoded_messages(topics=["/imu/data", "/fix"]):
                st = m.header.stamp.sec * 10**9 + m.header.stamp.nanosec
                if ch.topic == "/imu/data":
                    a, w = m.linear_acceleration, m.angular_velocity
                    vals.setdefault(ch.topic, []).append((st, a.x, a.y, a.z, w.x, w.y, w.z))
                else:
                    vals.setdefault(ch.topic, []).append((st, m.latitude, m.longitude, m.altitude))
        out[name] = {k: np.array(v, dtype=object) for k, v in vals.items()}
    return out


def test_ros2_real_recordings_counts_rates_values(ros2_reference):
    counts = {
        "robot_localization_test1.mcap": {"/imu/data": 11865, "/fix": 989, "/husky_velocity_controller/odom": 3952},
        "robot_localization_test2.mcap": {"/imu/data": 3061, "/jackal_velocity_controller/odom": 3060},
    }
    for name, want in counts.items():
        c = read_mcap(ROS2 / name)
        assert c.salvage is None and c.profile == "ros2" and c.compressions == {"zstd"}
        assert {c.channels[k].topic: n for k, n in c.counts.items()} == want
        ids = {c.channels[k].topic: k for k in c.channels}
        imu = c.decoded[ids["/imu/data"]]
        ref = ros2_reference[name]["/imu/data"]
        # bulk decoder == mcap_ros2's per-message decoder, bit for bit
        np.testing.assert_array_equal(imu.time_ns, ref[:, 0].astype(np.int64))
        np.testing.assert_array_equal(imu.values["specific_force"], ref[:, 1:4].astype(float))
        np.testing.assert_array_equal(imu.values["angular_rate"], ref[:, 4:7].astype(float))
        fn = np.linalg.norm(imu.values["specific_force"], axis=1)
        assert 9.7 < np.median(fn) < 9.9
        rate = 1e9 / np.median(np.diff(imu.time_ns))
        if name.endswith("1.mcap"):
            assert abs(rate - 30.0) < 0.1  # README: ~30 Hz
            t0 = np.datetime64(int(imu.time_ns[0]), "ns")
            assert np.datetime64("2015-01-01") <= t0 < np.datetime64("2016-01-01")
            fix = c.decoded[ids["/fix"]]
            r = ros2_reference[name]["/fix"]
            np.testing.assert_array_equal(fix.values["lat_deg"], r[:, 1].astype(float))
            np.testing.assert_array_equal(fix.values["height"], r[:, 3].astype(float))
        else:
            # measured: this bag's header.stamp is a simulation clock (47.58 s after 1970),
            # not 2015 as the README says; 50 Hz, not 30
            assert abs(rate - 50.0) < 0.1
            assert imu.time_ns[0] == 47_580_000_000


def test_ros2_real_recording_load_flight_and_inspect():
    opts = ingest_options(
        {"inputs": {"mcap": "robot_localization_test1.mcap"}, "topics": {"altimeter": "/fix"}}, "flights[0]"
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rec = load_flight(opts, ROS2)
    msgs = [str(w.message) for w in caught if issubclass(w.category, DataWarning)]
    assert any("using /imu/data" in m for m in msgs) and any("using /fix" in m for m in msgs)
    assert len(rec.imu.time) == 11865 and len(rec.gnss.time) == 989
    assert np.all(np.diff(rec.imu.time) > 0)
    assert abs(np.degrees(np.median(rec.gnss.lat)) - 42.3758) < 0.01  # Boston area
    # the heights are the fix's altitudes: the filter takes them once (docs/method.md, "Heights
    # that are the GNSS's own")
    assert gnss_height_fraction(rec.altimeter.time, rec.altimeter.height, rec.gnss.time, rec.gnss.height) == 1.0
    reps = inspect_files([ROS2 / "robot_localization_test1.mcap", ROS2 / "robot_localization_test2.mcap"])
    text = format_inspect(reps)
    json.dumps(reps)
    imu = next(ch for ch in reps[0]["channels"] if ch["topic"] == "/imu/data")
    assert imu["messages"] == 11865 and abs(imu["nominal_rate_hz"] - 30.0) < 0.1
    assert imu["measurement_time"]["start_utc"].startswith("2015-05-21")
    assert imu["gaps"] == 0
    assert not [x for x in imu["checks"] if x["level"] == "error"]
    assert "/husky_velocity_controller/odom" in text and "nav_msgs/msg/Odometry" in text
    imu2 = next(ch for ch in reps[1]["channels"] if ch["topic"] == "/imu/data")
    assert any(x["check"] == "epoch" and x["level"] == "warning" for x in imu2["checks"])
    # second bag has no GNSS/altimeter: clear error naming the file
    with pytest.raises(DataError, match="robot_localization_test2.mcap: no altimeter"):
        load_flight(ingest_options({"inputs": {"mcap": "robot_localization_test2.mcap"}}, "f"), ROS2)


@pytest.mark.parametrize("compression", [CompressionType.ZSTD, CompressionType.LZ4, CompressionType.NONE])
def test_ros2_roundtrip_exact(tmp_path, compression):
    d = static_flight(seconds=5.0)
    write_ros2(tmp_path / "f.mcap", d, compression=compression)
    rec = load_flight(ingest_options({"inputs": {"mcap": "f.mcap"}}, "f"), tmp_path)
    _assert_exact(rec, d)


def test_ros2_varying_frame_id_and_zero_stamps(tmp_path):
    d = static_flight(seconds=3.0)
    n = len(d["imu_t"])
    fids = ["imu", "imu_link", "x" * 13, ""] * (n // 4)
    write_ros2(tmp_path / "f.mcap", d, frame_ids=fids, zero_stamps={7, 8})
    opts = ingest_options({"inputs": {"mcap": "f.mcap"}}, "f")
    with pytest.warns(DataWarning, match="2 of 300 messages .* used the MCAP log_time"):
        rec = load_flight(opts, tmp_path)
    _assert_exact(rec, d)  # log_time == true stamp in these files


@pytest.mark.parametrize("chunked", [True, False])
def test_json_roundtrip_exact_and_field_mapping(tmp_path, chunked):
    d = static_flight(seconds=5.0)
    write_json(tmp_path / "f.mcap", d, use_chunking=chunked, compression=CompressionType.LZ4)
    rec = load_flight(ingest_options({"inputs": {"mcap": "f.mcap"}}, "f"), tmp_path)
    _assert_exact(rec, d)
    names = {"time": "t", "f": "acc", "w": "gyro", "h": "alt", "lat": "phi", "lon": "lam"}
    write_json(tmp_path / "g.mcap", d, names=names)
    cfg = {
        "inputs": {"mcap": "g.mcap"},
        "mcap": {
            "json_fields": {
                "imu": {"time": "t", "specific_force": "acc", "angular_rate": "gyro"},
                "altimeter": {"time": "t", "height": "alt"},
                "gnss": {"time": "t", "lat_deg": "phi", "lon_deg": "lam", "height": "alt"},
            }
        },
    }
    _assert_exact(load_flight(ingest_options(cfg, "f"), tmp_path), d)


def _assert_exact(rec, d):
    np.testing.assert_array_equal(rec.imu.specific_force_t, d["f"])
    np.testing.assert_array_equal(rec.imu.angular_rate_t, d["w"])
    np.testing.assert_array_equal(rec.altimeter.height, d["h"])
    np.testing.assert_array_equal(rec.gnss.height, d["gh"])
    np.testing.assert_array_equal(rec.gnss.lat, np.radians(d["lat"]))
    np.testing.assert_array_equal(rec.gnss.lon, np.radians(d["lon"]))
    assert rec.t0_unix_ns == d["imu_t"][0]
    np.testing.assert_array_equal(np.round(rec.imu.time * 1e9).astype(np.int64) + rec.t0_unix_ns, d["imu_t"])
    np.testing.assert_array_equal(np.round(rec.altimeter.time * 1e9).astype(np.int64) + rec.t0_unix_ns, d["alt_t"])


def test_simulator_writers_roundtrip_exact(tmp_path):
    """Simulator -> MCAP JSON, MCAP ROS 2, CSV -> reader: the same float64 arrays."""
    from gravsurvey.simulate.logs import SensorLogs, write_flight_logs

    d = static_flight(seconds=10.0)
    logs = SensorLogs(
        int(d["imu_t"][0]),
        d["imu_t"],
        d["f"],
        d["w"],
        d["alt_t"],
        d["h"],
        d["gnss_t"],
        d["lat"],
        d["lon"],
        d["gh"],
        1e-3,
        1e-7,
        1.0,
    )
    write_flight_logs(tmp_path, "F01", ["mcap_json", "mcap_ros2", "csv"], logs)
    inputs = [
        {"mcap": "F01_json.mcap"},
        {"mcap": "F01_ros2.mcap"},
        {"csv": {"imu": "imu.csv", "altimeter": "altimeter.csv", "gnss": "gnss.csv"}},
    ]
    for inp in inputs:
        opts = ingest_options({"inputs": inp}, "f")
        with warnings.catch_warnings():
            warnings.simplefilter("error", DataWarning)  # clean data: no warning at all
            rec = load_flight(opts, tmp_path)
        _assert_exact(rec, d)
        raw, _ = read_raw_channels(opts, tmp_path, [])
        np.testing.assert_array_equal(raw["gnss"].values["lat_deg"], d["lat"])
        np.testing.assert_array_equal(raw["gnss"].time_ns, d["gnss_t"])


def _imu_cdr(endian, sec, nsec, frame_id, w, f):
    """sensor_msgs/msg/Imu as XCDR1 by hand (alignment counted after the 4-byte header)."""
    e = "<" if endian == "le" else ">"
    body = bytearray(struct.pack(e + "iI", sec, nsec))
    fid = frame_id.encode() + b"\0"
    body += struct.pack(e + "I", len(fid)) + fid
    body += b"\0" * (-len(body) % 8)
    body += struct.pack(e + "4d", 0, 0, 0, 1) + struct.pack(e + "9d", *[0.0] * 9)
    body += struct.pack(e + "3d", *w) + struct.pack(e + "9d", *[0.0] * 9)
    body += struct.pack(e + "3d", *f) + struct.pack(e + "9d", *[0.0] * 9)
    return bytes([0, 1 if endian == "le" else 0, 0, 0]) + bytes(body)


def test_cdr_bulk_decoder_both_byte_orders_and_short_payloads():
    from gravsurvey.io.mcap.decode import decode_ros2

    rng = np.random.default_rng(5)
    msgs, want = [], []
    for k in range(40):
        endian = "le" if k % 3 else "be"
        fid = "x" * (k % 11)
        w, f = rng.normal(size=3), rng.normal(size=3)
        msgs.append(_imu_cdr(endian, 1_600_000_000 + k, 999_999_999 - k, fid, w, f))
        want.append((np.int64(1_600_000_000 + k) * 10**9 + 999_999_999 - k, w, f))
    msgs.append(msgs[0][:100])  # truncated payload: dropped, counted
    buf = np.frombuffer(b"".join(msgs), np.uint8)
    lens = np.array([len(m) for m in msgs], np.int64)
    offs = np.concatenate([[0], np.cumsum(lens)[:-1]]).astype(np.int64)
    blk = decode_ros2("imu", buf, offs, lens, np.zeros(len(msgs), np.int64))
    assert blk.undecodable == 1
    np.testing.assert_array_equal(blk.time_ns, [t for t, _, _ in want])
    np.testing.assert_array_equal(blk.values["angular_rate"], [w for _, w, _ in want])
    np.testing.assert_array_equal(blk.values["specific_force"], [f for _, _, f in want])


def test_json_times_beyond_int64_clamped_not_a_crash():
    """A time field beyond the int64 range (a damaged or hostile file) is clamped for every role,
    the gravity gradient included (it used to fail the whole read with an OverflowError); the
    time checks at ingestion then report the step."""
    from gravsurvey.io.mcap.decode import DEFAULT_JSON_FIELDS, decode_json

    big, logt = 2**70, np.array([10, 20, 30], np.int64)
    rows = {
        "imu": {"specific_force_t": [0.0, 0.0, 9.8], "angular_rate_t": [0.0, 0.0, 0.0]},
        "gradient": {"gradient_t_eotvos": [1.0, 0.0, 0.0, 1.0, 0.0, -2.0]},
    }
    for role, row in rows.items():
        payloads = [json.dumps({**row, "time_ns": t}).encode() for t in (5, big, -big)]
        blk = decode_json(role, payloads, logt, DEFAULT_JSON_FIELDS[role])
        assert blk.undecodable == 0, role
        assert blk.time_ns.tolist() == [5, 2**63 - 1, -(2**63)], role
        np.testing.assert_array_equal(blk.log_time_ns, logt)


def test_json_bad_messages_dropped_and_counted(tmp_path):
    from mcap.writer import Writer

    d = static_flight(seconds=3.0)
    write_json(tmp_path / "ok.mcap", d)
    # same flight plus broken IMU messages: not JSON, missing field, string value
    with open(tmp_path / "bad.mcap", "wb") as fh:
        wr = Writer(fh)
        wr.start()
        sid = wr.register_schema("gravsurvey.Imu", "jsonschema", b"{}")
        imu = wr.register_channel("/imu", "json", sid)
        alt = wr.register_channel("/altimeter", "json", wr.register_schema("gravsurvey.Altimeter", "jsonschema", b"{}"))
        for k, t in enumerate(d["imu_t"]):
            wr.add_message(
                imu,
                int(t),
                json.dumps(
                    {"time_ns": int(t), "specific_force_t": d["f"][k].tolist(), "angular_rate_t": d["w"][k].tolist()}
                ).encode(),
                int(t),
            )
        t = int(d["imu_t"][-1])
        for i, junk in enumerate(
            [
                b"{not json",
                b'{"time_ns": 5}',
                b'{"time_ns": 6, "specific_force_t": ["1", 2, 3], "angular_rate_t": [0, 0, 0]}',
            ]
        ):
            wr.add_message(imu, t + 1 + i, junk, t + 1 + i)
        for k, ta in enumerate(d["alt_t"]):
            wr.add_message(alt, int(ta), json.dumps({"time_ns": int(ta), "height_m": d["h"][k]}).encode(), int(ta))
        wr.finish()
    with pytest.warns(
        DataWarning, match="imu: 3 messages of .*bad.mcap topic /imu could not be decoded and were dropped"
    ):
        rec = load_flight(ingest_options({"inputs": {"mcap": "bad.mcap"}}, "f"), tmp_path)
    np.testing.assert_array_equal(rec.imu.specific_force_t, d["f"])
    assert rec.gnss is None


def test_json_field_names_not_matching_mapping_is_a_clear_error(tmp_path):
    write_json(tmp_path / "n.mcap", static_flight(seconds=2.0), names={"f": "acc"})
    with pytest.raises(
        DataError,
        match=r"n.mcap topic /imu: no usable imu samples \(imu: 200 "
        r"messages .* could not be decoded .*specific_force_t",
    ):
        load_flight(ingest_options({"inputs": {"mcap": "n.mcap"}}, "f"), tmp_path)


@pytest.mark.parametrize(
    "topics, says",
    [
        (
            {"imu": "/gnss", "altimeter": "/altimeter", "gnss": "/imu"},
            "topic /gnss (f.topics.imu): its sensor_msgs/msg/NavSatFix messages carry GNSS positions, not IMU samples",
        ),
        (
            {"imu": "/imu", "altimeter": "/gnss", "gnss": "/altimeter"},
            "topic /altimeter (f.topics.gnss): its geometry_msgs/msg/PointStamped messages carry no GNSS positions",
        ),
    ],
)
def test_topics_given_in_the_wrong_order_are_named(topics, says):
    """A topic of another kind for a role (fuzzing, 2026-12-04: "internal error KeyError: 'lat_deg'")."""
    base = Path(__file__).resolve().parents[1] / "sample_data" / "grid_ros2"
    opts = ingest_options({"inputs": {"mcap": "F01/F01_ros2.mcap"}, "topics": topics}, "f")
    with pytest.raises(DataError) as exc:
        load_flight(opts, base)
    msg = str(exc.value)
    assert says in msg and "topics given in the wrong order?" in msg and "\n" not in msg
    assert "the file's topics: /imu (sensor_msgs/msg/Imu), /altimeter (geometry_msgs/msg/PointStamped)" in msg


def test_an_mcap_without_an_altimeter_topic_reads_the_gnss_heights(tmp_path):
    """An IMU and a GNSS only: the GNSS topic's heights are the height channel, said in a note."""
    d = static_flight(seconds=3.0)
    d["alt_t"], d["h"] = d["alt_t"][:0], d["h"][:0]
    write_ros2(tmp_path / "f.mcap", d)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rec = load_flight(ingest_options({"inputs": {"mcap": "f.mcap"}}, "f"), tmp_path)
    np.testing.assert_allclose(rec.altimeter.height, d["gh"])
    said = [str(w.message) for w in caught]
    assert "altimeter: topic /altimeter absent; the GNSS heights of /gnss are the height channel" in said
