"""Log writers (gravsurvey.simulate.logs) against docs/formats.md, checked with independent decoders.

ROS 2 files are decoded with mcap-ros2-support's DecoderFactory and compared byte for byte with
its encoder; JSON with json.loads; CSV with numpy.loadtxt.  Values are random float64 bit
patterns (subnormals, -0.0, huge and tiny magnitudes) so "exact" means bitwise.
"""

from __future__ import annotations

import io
import json
import os
import struct
from pathlib import Path

import mcap.writer
import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.records import Chunk
from mcap.stream_reader import StreamReader
from mcap_ros2._dynamic import serialize_dynamic
from mcap_ros2.decoder import DecoderFactory

from gravsurvey.errors import ConfigError, DataError
from gravsurvey.simulate import logs as L
from gravsurvey.simulate.logs import SensorLogs, write_flight_logs, write_truth_csv

START_NS = 1_700_000_000_123_456_789  # not on a whole second: nanosec field is exercised


def random_doubles(rng, shape):
    """Finite float64 from random bit patterns: every exponent, sign, subnormals; plus specials."""
    n = int(np.prod(shape))
    bits = rng.integers(0, 2**64, size=2 * n + 16, dtype=np.uint64)
    x = bits.view(np.float64)
    x = x[np.isfinite(x)][:n].copy()
    special = [0.0, -0.0, 5e-324, -5e-324, 1.7976931348623157e308, 0.1, 1e-5, 9.80665, 1e16, -2.5]
    x[: min(n, len(special))] = special[: min(n, len(special))]
    return rng.permutation(x).reshape(shape)


def contract_times(start_ns, rate_hz, n):
    """Sample k at start + round(k * 1e9 / R) (docs/formats.md, Time)."""
    return start_ns + np.array([round(k * 1e9 / rate_hz) for k in range(n)], dtype=np.int64)


def make_logs(rng, n_imu=700, imu_hz=7.0, n_slow=100, slow_hz=1.0, gnss=True):
    t_imu = contract_times(START_NS, imu_hz, n_imu)
    t_alt = contract_times(START_NS, slow_hz, n_slow)
    kw = {}
    if gnss:
        kw = dict(
            gnss_time_ns=contract_times(START_NS + 250_000_000, slow_hz, n_slow),
            lat_deg=rng.uniform(-90, 90, n_slow),
            lon_deg=random_doubles(rng, (n_slow,)),
            gnss_height_m=random_doubles(rng, (n_slow,)),
        )
    return SensorLogs(
        start_unix_ns=START_NS,
        imu_time_ns=t_imu,
        specific_force_t=random_doubles(rng, (n_imu, 3)),
        angular_rate_t=random_doubles(rng, (n_imu, 3)),
        alt_time_ns=t_alt,
        height_m=random_doubles(rng, (n_slow,)),
        accel_sigma_mps2=[1e-3, 2e-3, 3e-3],
        gyro_sigma_radps=1e-6,
        gnss_sigma_m=[0.02, 0.03, 0.05],
        **kw,
    )


def bits(x):
    return np.ascontiguousarray(np.asarray(x, dtype=np.float64)).view(np.uint64)


def assert_bitwise(actual, expected):
    np.testing.assert_array_equal(bits(actual), bits(expected))


@pytest.fixture(scope="module")
def logs():
    return make_logs(np.random.default_rng(20261122))


@pytest.fixture(scope="module")
def written(tmp_path_factory, logs):
    d = tmp_path_factory.mktemp("flight")
    files = write_flight_logs(d, "F01", ["csv", "mcap_ros2", "mcap_json"], logs, comments=["unit test", "two\nlines"])
    return d, files


def test_file_set_and_no_temp_files(written):
    d, files = written
    names = ["F01_json.mcap", "F01_ros2.mcap", "imu.csv", "altimeter.csv", "gnss.csv"]
    assert [f.name for f in files] == names
    assert sorted(os.listdir(d)) == sorted(names)


def read_in_file_order(path, decoders=()):
    with open(path, "rb") as fh:
        reader = make_reader(fh, decoder_factories=list(decoders))
        header = reader.get_header()
        if decoders:
            out = [(s, c, m, dec) for s, c, m, dec in reader.iter_decoded_messages(log_time_order=False)]
        else:
            out = [(s, c, m, None) for s, c, m in reader.iter_messages(log_time_order=False)]
    return header, out


def test_ros2_decodes_to_the_inputs_exactly(written, logs):
    d, _ = written
    header, msgs = read_in_file_order(d / "F01_ros2.mcap", [DecoderFactory()])
    assert header.profile == "ros2"
    times = [m.log_time for _, _, m, _ in msgs]
    assert times == sorted(times), "messages of all topics must be interleaved in time order"
    by_topic = {}
    for schema, channel, message, dec in msgs:
        assert channel.message_encoding == "cdr" and schema.encoding == "ros2msg"
        assert message.log_time == message.publish_time
        stamp = dec.header.stamp.sec * 10**9 + dec.header.stamp.nanosec
        assert stamp == message.log_time
        assert 0 <= dec.header.stamp.nanosec < 10**9
        by_topic.setdefault(channel.topic, []).append((schema.name, message, dec))
    assert set(by_topic) == {"/imu", "/altimeter", "/gnss"}

    imu = by_topic["/imu"]
    assert {s for s, _, _ in imu} == {"sensor_msgs/msg/Imu"}
    np.testing.assert_array_equal([m.log_time for _, m, _ in imu], logs.imu_time_ns)
    assert {dec.header.frame_id for _, _, dec in imu} == {"imu"}
    av = [[x.angular_velocity.x, x.angular_velocity.y, x.angular_velocity.z] for _, _, x in imu]
    la = [[x.linear_acceleration.x, x.linear_acceleration.y, x.linear_acceleration.z] for _, _, x in imu]
    assert_bitwise(av, logs.angular_rate_t)
    assert_bitwise(la, logs.specific_force_t)
    x = imu[0][2]
    assert (x.orientation.x, x.orientation.y, x.orientation.z, x.orientation.w) == (0.0, 0.0, 0.0, 1.0)
    assert list(x.orientation_covariance) == [-1.0] + [0.0] * 8  # REP-145: no orientation
    np.testing.assert_array_equal(
        np.reshape(x.linear_acceleration_covariance, (3, 3)), np.diag(np.array([1e-3, 2e-3, 3e-3]) ** 2)
    )
    np.testing.assert_array_equal(np.reshape(x.angular_velocity_covariance, (3, 3)), np.eye(3) * 1e-12)

    alt = by_topic["/altimeter"]
    assert {s for s, _, _ in alt} == {"geometry_msgs/msg/PointStamped"}
    assert {dec.header.frame_id for _, _, dec in alt} == {"altimeter"}
    np.testing.assert_array_equal([m.log_time for _, m, _ in alt], logs.alt_time_ns)
    assert_bitwise([x.point.z for _, _, x in alt], logs.height_m)
    assert all(x.point.x == 0.0 and x.point.y == 0.0 for _, _, x in alt)

    gnss = by_topic["/gnss"]
    assert {s for s, _, _ in gnss} == {"sensor_msgs/msg/NavSatFix"}
    np.testing.assert_array_equal([m.log_time for _, m, _ in gnss], logs.gnss_time_ns)
    assert_bitwise([x.latitude for _, _, x in gnss], logs.lat_deg)
    assert_bitwise([x.longitude for _, _, x in gnss], logs.lon_deg)
    assert_bitwise([x.altitude for _, _, x in gnss], logs.gnss_height_m)
    x = gnss[0][2]
    assert (x.status.status, x.status.service, x.position_covariance_type) == (0, 1, 2)
    np.testing.assert_array_equal(np.reshape(x.position_covariance, (3, 3)), np.diag(np.array([0.02, 0.03, 0.05]) ** 2))


def test_ros2_payloads_equal_the_reference_encoder(written):
    """Our bulk numpy CDR equals mcap_ros2's own per-message encoder byte for byte."""
    d, _ = written
    with open(d / "F01_ros2.mcap", "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        encoders, seen = {}, {}
        for schema, channel, message, dec in reader.iter_decoded_messages(log_time_order=False):
            if schema.name not in encoders:
                encoders[schema.name] = serialize_dynamic(schema.name, schema.data.decode())[schema.name]
            assert encoders[schema.name](dec) == message.data
            seen[channel.topic] = message.data
    # XCDR1 layout by hand: encapsulation CDR_LE, options 0; Imu is 4 + 312 bytes with "imu".
    imu = seen["/imu"]
    assert imu[:4] == b"\x00\x01\x00\x00" and len(imu) == 316
    assert struct.unpack_from("<I4s", imu, 12) == (4, b"imu\x00")
    assert struct.unpack_from("<4d", imu, 4 + 16) == (0.0, 0.0, 0.0, 1.0)
    alt = seen["/altimeter"]  # frame "altimeter\0" ends at 22 -> 2 pad bytes -> point at 24
    assert len(alt) == 4 + 48 and alt[4 + 22 : 4 + 24] == b"\x00\x00"
    gnss = seen["/gnss"]  # "gnss\0" ends at 17: status int8 @17, service uint16 @18, lat @24
    assert len(gnss) == 4 + 121
    assert struct.unpack_from("<bH", gnss, 4 + 17) == (0, 1)
    assert gnss[-1] == 2


def test_ros2_schemas_are_rosbag2_style_concatenations(written):
    d, _ = written
    with open(d / "F01_ros2.mcap", "rb") as fh:
        summary = make_reader(fh).get_summary()
    texts = {s.name: s.data.decode() for s in summary.schemas.values()}
    sep = "\n" + "=" * 80 + "\n"
    imu = texts["sensor_msgs/msg/Imu"]
    assert imu.startswith("# This is a message to hold data from an IMU")
    for dep in ("std_msgs/Header", "builtin_interfaces/Time", "geometry_msgs/Quaternion", "geometry_msgs/Vector3"):
        assert f"{sep}MSG: {dep}\n" in imu
    assert f"{sep}MSG: sensor_msgs/NavSatStatus\n" in texts["sensor_msgs/msg/NavSatFix"]
    assert f"{sep}MSG: geometry_msgs/Point\n" in texts["geometry_msgs/msg/PointStamped"]


def test_json_decodes_to_the_inputs_exactly(written, logs):
    d, _ = written
    header, msgs = read_in_file_order(d / "F01_json.mcap")
    assert header.profile == ""
    times = [m.log_time for _, _, m, _ in msgs]
    assert times == sorted(times)
    rows = {}
    for schema, channel, message, _ in msgs:
        assert channel.message_encoding == "json" and schema.encoding == "jsonschema"
        obj = json.loads(message.data)
        assert obj["time_ns"] == message.log_time == message.publish_time
        assert isinstance(obj["time_ns"], int)
        schema_doc = json.loads(schema.data)
        assert schema_doc["title"] == schema.name and set(schema_doc["required"]) == set(obj)
        rows.setdefault((channel.topic, schema.name), []).append(obj)
    assert set(rows) == {
        ("/imu", "gravsurvey.Imu"),
        ("/altimeter", "gravsurvey.Altimeter"),
        ("/gnss", "gravsurvey.Gnss"),
    }
    imu = rows[("/imu", "gravsurvey.Imu")]
    np.testing.assert_array_equal([o["time_ns"] for o in imu], logs.imu_time_ns)
    assert_bitwise([o["specific_force_t"] for o in imu], logs.specific_force_t)
    assert_bitwise([o["angular_rate_t"] for o in imu], logs.angular_rate_t)
    alt = rows[("/altimeter", "gravsurvey.Altimeter")]
    np.testing.assert_array_equal([o["time_ns"] for o in alt], logs.alt_time_ns)
    assert_bitwise([o["height_m"] for o in alt], logs.height_m)
    gnss = rows[("/gnss", "gravsurvey.Gnss")]
    np.testing.assert_array_equal([o["time_ns"] for o in gnss], logs.gnss_time_ns)
    for key, ref in (("lat_deg", logs.lat_deg), ("lon_deg", logs.lon_deg), ("height_m", logs.gnss_height_m)):
        assert_bitwise([o[key] for o in gnss], ref)


@pytest.mark.parametrize("name", ["F01_json.mcap", "F01_ros2.mcap"])
def test_mcap_summary_statistics_indexes_and_zstd_chunks(written, logs, name):
    d, _ = written
    path = d / name
    n_imu, n_alt, n_gnss = logs.imu_time_ns.size, logs.alt_time_ns.size, logs.gnss_time_ns.size
    with open(path, "rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None
    st = summary.statistics
    assert st.message_count == n_imu + n_alt + n_gnss
    counts = {summary.channels[c].topic: k for c, k in st.channel_message_counts.items()}
    assert counts == {"/imu": n_imu, "/altimeter": n_alt, "/gnss": n_gnss}
    first = min(logs.imu_time_ns[0], logs.alt_time_ns[0], logs.gnss_time_ns[0])
    last = max(logs.imu_time_ns[-1], logs.alt_time_ns[-1], logs.gnss_time_ns[-1])
    assert (st.message_start_time, st.message_end_time) == (first, last)
    assert st.chunk_count == len(summary.chunk_indexes) >= 1
    assert all(ci.compression == "zstd" for ci in summary.chunk_indexes)
    assert all(ci.message_index_offsets for ci in summary.chunk_indexes)
    chunks = [r for r in StreamReader(str(path), emit_chunks=True, validate_crcs=True).records if isinstance(r, Chunk)]
    assert len(chunks) == st.chunk_count and all(c.compression == "zstd" for c in chunks)
    assert all(len(c.data) < c.uncompressed_size for c in chunks)
    # the indexed (time-ordered) read path gives every message once, in time order
    with open(path, "rb") as fh:
        t = [m.log_time for _, _, m in make_reader(fh).iter_messages()]
    assert len(t) == st.message_count and t == sorted(t)
    with open(path, "rb") as fh:
        md = list(make_reader(fh).iter_metadata())
    assert md[0].name == "gravsurvey" and md[0].metadata["start_unix_ns"] == str(START_NS)
    assert md[0].metadata["start_utc"] == "2023-11-14T22:13:20.123456789Z"
    assert md[0].metadata["comments"] == "unit test\ntwo\nlines"


def test_multichunk_file(tmp_path):
    """Enough messages for several 1 MiB chunks; every chunk zstd, all messages indexed."""
    lg = make_logs(np.random.default_rng(3), n_imu=20000, imu_hz=10.0, n_slow=2000, gnss=False)
    (path,) = write_flight_logs(tmp_path, "F", ["mcap_json"], lg)
    with open(path, "rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary.statistics.chunk_count >= 3
    assert all(ci.compression == "zstd" for ci in summary.chunk_indexes)
    assert {ch.topic for ch in summary.channels.values()} == {"/imu", "/altimeter"}
    with open(path, "rb") as fh:
        msgs = [(c.topic, m.log_time, m.sequence) for _, c, m in make_reader(fh).iter_messages()]
    assert len(msgs) == 22000
    imu = [(t, s) for topic, t, s in msgs if topic == "/imu"]
    assert [t for t, _ in imu] == lg.imu_time_ns.tolist()
    assert [s for _, s in imu] == list(range(20000))


def read_csv(path):
    text = Path(path).read_text()
    assert text.endswith("\n")
    lines = text.splitlines()
    comments = [ln for ln in lines if ln.startswith("#")]
    body = [ln for ln in lines if not ln.startswith("#")]
    header = body[0].split(",")
    data = "\n".join(body[1:])
    t = np.loadtxt(io.StringIO(data), delimiter=",", usecols=0, dtype=np.int64, ndmin=1)
    vals = np.loadtxt(io.StringIO(data), delimiter=",", usecols=range(1, len(header)), dtype=np.float64, ndmin=2)
    return comments, header, t, vals


def test_csv_parses_to_the_inputs_exactly(written, logs):
    d, _ = written
    comments, header, t, v = read_csv(d / "imu.csv")
    assert header == ["time_ns", "fx_mps2", "fy_mps2", "fz_mps2", "wx_radps", "wy_radps", "wz_radps"]
    np.testing.assert_array_equal(t, logs.imu_time_ns)
    assert_bitwise(v[:, :3], logs.specific_force_t)
    assert_bitwise(v[:, 3:], logs.angular_rate_t)
    assert comments[0] == "# gravsurvey simulated sensor log: flight F01, channel imu"
    assert "# start_utc 2023-11-14T22:13:20.123456789Z (start_unix_ns 1700000000123456789)" in comments
    assert comments[-2:] == ["# two", "# lines"]

    _, header, t, v = read_csv(d / "altimeter.csv")
    assert header == ["time_ns", "height_m"]
    np.testing.assert_array_equal(t, logs.alt_time_ns)
    assert_bitwise(v[:, 0], logs.height_m)

    _, header, t, v = read_csv(d / "gnss.csv")
    assert header == ["time_ns", "lat_deg", "lon_deg", "height_m"]
    np.testing.assert_array_equal(t, logs.gnss_time_ns)
    assert_bitwise(v, np.column_stack([logs.lat_deg, logs.lon_deg, logs.gnss_height_m]))


def test_without_gnss_no_gnss_file_or_topic(tmp_path):
    lg = make_logs(np.random.default_rng(5), n_imu=50, n_slow=8, gnss=False)
    files = write_flight_logs(tmp_path, "F02", ["mcap_ros2", "csv"], lg)
    assert [f.name for f in files] == ["F02_ros2.mcap", "imu.csv", "altimeter.csv"]
    with open(files[0], "rb") as fh:
        summary = make_reader(fh).get_summary()
    assert {c.topic for c in summary.channels.values()} == {"/imu", "/altimeter"}
    assert summary.statistics.message_count == 58


def test_determinism(tmp_path, logs):
    a = write_flight_logs(tmp_path / "a", "F01", ["mcap_json", "mcap_ros2", "csv"], logs, ["x"])
    b = write_flight_logs(tmp_path / "b", "F01", ["mcap_json", "mcap_ros2", "csv"], logs, ["x"])
    c = write_flight_logs(tmp_path / "a", "F01", ["mcap_json", "mcap_ros2", "csv"], logs, ["x"])
    for fa, fb, fc in zip(a, b, c):
        assert fa.read_bytes() == fb.read_bytes() == fc.read_bytes()


def test_failure_mid_write_leaves_old_files_and_no_partial_or_temp_files(tmp_path, logs, monkeypatch):
    old = tmp_path / "F01_json.mcap"
    old.write_bytes(b"old complete file")
    calls = {"n": 0}
    real = mcap.writer.Writer.add_message

    def failing(self, *args, **kwargs):
        calls["n"] += 1
        if calls["n"] > 300:
            raise RuntimeError("disk on fire")
        return real(self, *args, **kwargs)

    monkeypatch.setattr(mcap.writer.Writer, "add_message", failing)
    with pytest.raises(RuntimeError, match="disk on fire"):
        write_flight_logs(tmp_path, "F01", ["mcap_json", "mcap_ros2", "csv"], logs)
    assert calls["n"] > 300  # the failure really happened in the middle of a file
    assert os.listdir(tmp_path) == ["F01_json.mcap"]
    assert old.read_bytes() == b"old complete file"


def test_failure_in_last_file_publishes_none(tmp_path, logs, monkeypatch):
    """All requested files appear together or not at all."""

    def boom(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(L, "_csv_files", boom)
    with pytest.raises(DataError, match="F01 logs failed.*No space left"):
        write_flight_logs(tmp_path, "F01", ["mcap_json", "csv"], logs)
    assert os.listdir(tmp_path) == []


def test_new_files_get_umask_permissions(tmp_path, logs):
    (f,) = write_flight_logs(tmp_path, "F01", ["mcap_json"], logs)
    mask = os.umask(0)
    os.umask(mask)
    assert (f.stat().st_mode & 0o777) == (0o666 & ~mask)


def test_ros2_time_split_matches_integer_arithmetic():
    t = np.array([0, 1, 999_999_999, 10**9, START_NS, (2**31 - 1) * 10**9 + 999_999_999], dtype=np.int64)
    sec, nsec = L.ros2_time(t)
    assert sec.dtype == np.int32 and nsec.dtype == np.uint32
    for ti, s, ns in zip(t.tolist(), sec.tolist(), nsec.tolist()):
        assert (s, ns) == divmod(ti, 10**9)


def _replace(lg, **kw):
    d = dict(lg.__dict__)
    d.update(kw)
    return SensorLogs(**d)


@pytest.mark.parametrize(
    "change,match",
    [
        (lambda lg: dict(imu_time_ns=lg.imu_time_ns.astype(float)), "imu time_ns: expected integer"),
        (lambda lg: dict(alt_time_ns=lg.alt_time_ns[::-1].copy()), "altimeter time_ns: times must strictly increase"),
        (
            lambda lg: dict(height_m=np.where(np.arange(lg.height_m.size) == 5, np.nan, lg.height_m)),
            "altimeter height_m: non-finite value at sample 5",
        ),
        (
            lambda lg: dict(specific_force_t=lg.specific_force_t[:, :2]),
            r"imu specific_force_t: expected shape \(50, 3\)",
        ),
        (lambda lg: dict(gnss_height_m=None), "gnss: .* all given or all None"),
        (lambda lg: dict(lat_deg=lg.lat_deg + 200.0), "gnss lat_deg: latitude outside"),
        (lambda lg: dict(start_unix_ns=START_NS + 1), "imu time_ns: first sample .* before start_unix_ns"),
        (lambda lg: dict(gyro_sigma_radps=-1.0), "gyro_sigma_radps"),
        (
            lambda lg: dict(imu_time_ns=lg.imu_time_ns[:0], specific_force_t=np.zeros((0, 3))),
            "imu time_ns: expected a non-empty",
        ),
    ],
)
def test_bad_samples_raise_data_error_naming_the_channel(tmp_path, change, match):
    lg = make_logs(np.random.default_rng(9), n_imu=50, n_slow=8)
    bad = _replace(lg, **change(lg))
    with pytest.raises(DataError, match=match):
        write_flight_logs(tmp_path, "F", ["csv"], bad)
    assert os.listdir(tmp_path) == []


def test_ros2_needs_int32_seconds(tmp_path):
    lg = make_logs(np.random.default_rng(9), n_imu=5, n_slow=2, gnss=False)
    shift = 2**31 * 10**9 - START_NS  # first IMU sample exactly at 2**31 s (2038-01-19T03:14:08Z)
    late = _replace(
        lg, start_unix_ns=START_NS + shift, imu_time_ns=lg.imu_time_ns + shift, alt_time_ns=lg.alt_time_ns + shift
    )
    with pytest.raises(DataError, match="imu time_ns: .* int32 seconds"):
        write_flight_logs(tmp_path, "F", ["mcap_ros2"], late)
    assert [p.name for p in write_flight_logs(tmp_path, "F", ["mcap_json", "csv"], late)] == [
        "F_json.mcap",
        "imu.csv",
        "altimeter.csv",
    ]


@pytest.mark.parametrize(
    "formats,name,match",
    [
        (["mcap"], "F", "log format 'mcap' unknown"),
        (["csv"], "a/b", "flight name 'a/b'"),
        (["csv"], "", "flight name ''"),
    ],
)
def test_bad_formats_or_names_raise_config_error(tmp_path, logs, formats, name, match):
    with pytest.raises(ConfigError, match=match):
        write_flight_logs(tmp_path, name, formats, logs)
    assert os.listdir(tmp_path) == []


def truth_columns(rng, n):
    cols = {c: rng.normal(size=n) * 100 for c in L.TRUTH_COLUMNS[2:]}
    cols["anomaly_u_mgal"] = -cols["disturbance_mgal"]
    # contract order is enforced by the writer, whatever the mapping order
    return {
        "line": np.array(["static"] * 3 + ["L01"] * (n - 6) + ["turn"] * 3),
        "time_ns": contract_times(START_NS, 1.0, n),
        **cols,
    }


def test_truth_csv_round_trip(tmp_path):
    rng = np.random.default_rng(11)
    cols = truth_columns(rng, 40)
    cols["lat_deg"] = random_doubles(rng, (40,))
    cols["extra_int"] = np.arange(40)
    path = write_truth_csv(tmp_path / "F01" / "truth.csv", cols, comments=["flight F01"])
    assert os.listdir(path.parent) == ["truth.csv"]
    text = path.read_text().splitlines()
    assert "# flight F01" in text
    body = [ln for ln in text if not ln.startswith("#")]
    header = body[0].split(",")
    assert header == list(L.TRUTH_COLUMNS) + ["extra_int"]
    rows = [ln.split(",") for ln in body[1:]]
    assert [r[1] for r in rows] == cols["line"].tolist()
    data = io.StringIO("\n".join(body[1:]))
    t = np.loadtxt(data, delimiter=",", usecols=0, dtype=np.int64)
    np.testing.assert_array_equal(t, cols["time_ns"])
    data.seek(0)
    v = np.loadtxt(data, delimiter=",", usecols=range(2, len(header)), dtype=np.float64)
    for j, name in enumerate(header[2:]):
        assert_bitwise(v[:, j], cols[name])
    # rerun: same bytes
    before = path.read_bytes()
    write_truth_csv(path, cols, comments=["flight F01"])
    assert path.read_bytes() == before


@pytest.mark.parametrize(
    "edit,match",
    [
        (lambda c: c.pop("disturbance_mgal"), "truth columns missing: disturbance_mgal"),
        (lambda c: c.__setitem__("time_ns", c["time_ns"] * 1.0), "'time_ns' must be integer"),
        (lambda c: c.__setitem__("line", np.array(["L,01"] * 40)), "'line' row 0"),
        (lambda c: c.__setitem__("ve_mps", np.zeros(39)), "'ve_mps' has 39 rows, expected 40"),
        (lambda c: c.__setitem__("vn_mps", np.full(40, np.inf)), "'vn_mps' not finite at row 0"),
    ],
)
def test_truth_csv_bad_columns(tmp_path, edit, match):
    cols = truth_columns(np.random.default_rng(2), 40)
    edit(cols)
    with pytest.raises(DataError, match=match):
        write_truth_csv(tmp_path / "truth.csv", cols)
    assert os.listdir(tmp_path) == []


def test_output_does_not_depend_on_the_encoding_block_size(tmp_path, logs, monkeypatch):
    """Blocks are an implementation detail: tiny blocks (crossing every topic's boundaries) give the same bytes."""
    ref = write_flight_logs(tmp_path / "ref", "F01", ["mcap_json", "mcap_ros2", "csv"], logs)
    monkeypatch.setattr(L, "_BLOCK", 7)
    small = write_flight_logs(tmp_path / "small", "F01", ["mcap_json", "mcap_ros2", "csv"], logs)
    for a, b in zip(ref, small):
        assert a.read_bytes() == b.read_bytes(), a.name
