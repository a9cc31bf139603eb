"""Fault injection on input files (issue 14): every intact message before AND after the damage
is kept, skipped regions are reported, only our own error types escape.

Oracle: the ``mcap`` package's streaming reader on the undamaged file gives every top-level
record's byte range and messages; a record is intact when no damaged byte falls inside it.
File kinds: chunked with CRCs (zstd, lz4, uncompressed), the same with every chunk CRC set to 0
("no CRC", as many real recorders write), and unchunked (top-level messages, no CRC at all).
"""

from __future__ import annotations

import functools
import io
import struct
import tempfile
import warnings
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from mcap.records import Chunk, Message
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import CompressionType
from test_io_support import static_flight, write_json, write_ros2

from gravsurvey.errors import DataError, DataWarning, GravsurveyError
from gravsurvey.io.ingest import load_flight
from gravsurvey.io.mcap import OP_CHUNK, read_mcap, scan_records
from gravsurvey.settings import ingest_options

KINDS = ["ros2_zstd", "ros2_none", "json_lz4", "json_unchunked", "ros2_zstd_nocrc", "ros2_none_nocrc"]
FLIGHT_S = 6.0
N_MESSAGES = 600 + 60 + 60


def _zero_chunk_crcs(data):
    """The same file with every chunk's uncompressed_crc set to 0 (CRC not computed)."""
    b = bytearray(data)
    buf = np.frombuffer(bytes(b), np.uint8)
    n, _, _, arrs = scan_records(buf, 8, len(buf), stop_at_footer=True)
    for k in np.flatnonzero(arrs[0] == OP_CHUNK):
        p = int(arrs[1][k])
        b[p + 24 : p + 28] = b"\0\0\0\0"
    return bytes(b)


@functools.lru_cache(maxsize=None)
def sample(kind):
    """Small multi-chunk files (bytes) of a 6 s static flight (100 Hz IMU, 10 Hz alt/GNSS)."""
    d = static_flight(seconds=FLIGHT_S)
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "f.mcap"
        if kind.startswith("ros2_zstd"):
            write_ros2(p, d, chunk_size=8192)
        elif kind.startswith("ros2_none"):
            write_ros2(p, d, chunk_size=8192, compression=CompressionType.NONE)
        elif kind == "json_lz4":
            write_json(p, d, chunk_size=4096, compression=CompressionType.LZ4)
        else:
            write_json(p, d, use_chunking=False)
        data = p.read_bytes()
    return _zero_chunk_crcs(data) if kind.endswith("_nocrc") else data


@functools.lru_cache(maxsize=None)
def records(kind):
    """(start, end, messages) of every top-level record of the intact file, by the mcap
    package's streaming reader (independent of ours)."""
    data = sample(kind)
    sr = StreamReader(io.BytesIO(data), emit_chunks=True)
    topics, out, start = {}, [], 8
    for rec in sr.records:
        end = sr._stream.count
        if isinstance(rec, Chunk):
            inner = breakup_chunk(rec, validate_crc=False)
            for r in inner:
                if hasattr(r, "topic"):
                    topics[r.id] = r.topic
            msgs = [r for r in inner if isinstance(r, Message)]
        elif isinstance(rec, Message):
            msgs = [rec]
        else:
            if hasattr(rec, "topic"):
                topics[rec.id] = rec.topic
            msgs = []
        out.append((start, end, [(topics[m.channel_id], m.log_time, m.data) for m in msgs]))
        start = end
    assert sum(len(m) for _, _, m in out) == N_MESSAGES
    return out


def intact(kind, damaged):
    """Messages of the records that no damaged byte range [a, b) touches."""
    return Counter(m for s, e, msgs in records(kind) if not any(a < e and s < b for a, b in damaged) for m in msgs)


def everything(kind):
    return intact(kind, [])


def read_damaged(data):
    """(content, Counter of (topic, log_time, payload)) of damaged bytes; runs the ingestion
    front end too (only our own errors may escape)."""
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "d.mcap"
        p.write_bytes(data)
        try:
            c = read_mcap(p, keep_raw=True)
        except DataError as exc:
            assert "not an MCAP file" in str(exc) or "empty file" in str(exc)
            return None, Counter()
        got = Counter((c.channels[ch].topic, lt, bytes(b)) for ch, _, lt, _, b in c.raw if ch in c.channels)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", DataWarning)
                load_flight(ingest_options({"inputs": {"mcap": "d.mcap"}}, "f"), tmp)
        except GravsurveyError:
            pass
        return c, got


def check_outcome(kind, damaged, c, got):
    """The assertions every fault shares."""
    want = intact(kind, damaged)
    missing = want - got
    assert not missing, (
        f"{sum(missing.values())} intact messages lost (damage {damaged}); "
        f"salvage: {c.salvage.describe('f') if c and c.salvage else None}"
    )
    # (without a CRC a corrupted payload is a changed message, not a lost one)
    lost = sum(everything(kind).values()) - sum(got.values())
    if c is not None and lost > 0:
        # a loss is always said: a salvage report, or a note (records with unknown opcodes)
        assert c.salvage is not None or any("unknown opcodes" in n or "no footer" in n for n in c.notes), c.notes
    if c is not None and c.salvage is not None:
        regs = c.salvage.regions
        assert regs and all(r.start < r.end or r.start == r.end for r in regs)
        assert regs == sorted(regs, key=lambda r: r.start)
        assert c.salvage.recovered == len(c.raw)


FUZZ = settings(
    max_examples=60,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)


@FUZZ
@given(kind=st.sampled_from(KINDS), bits=st.lists(st.integers(0, 2**40), min_size=1, max_size=3))
@example(kind="json_unchunked", bits=[11815 * 8])  # issue 14: a message opcode 5 -> 4
@example(kind="json_unchunked", bits=[11815 * 8 + 1])  # 5 -> 7: a stray message index
@example(kind="ros2_zstd", bits=[20000 * 8 + 3])
@example(kind="ros2_zstd_nocrc", bits=[20000 * 8 + 3])
# a message's channel id 1 -> 257 inside an uncompressed chunk without CRC: was an unreported
# "orphan"; now a region naming the chunk
@example(kind="ros2_none_nocrc", bits=[102344 * 8])
# the first chunk (which defines the channels) fails its CRC and the summary (which repeats
# them) is cut by a garbage length: later chunks' 700 messages were on undefined channels;
# now the definitions are rescued from the failed chunk
@example(kind="ros2_zstd", bits=[635 * 8, 57208 * 8 + 7])
# the header record's length +64: the first chunk was taken for the header's content
@example(kind="ros2_zstd", bits=[78])
def test_flipped_bits(kind, bits):
    raw = bytearray(sample(kind))
    pos = sorted({b % (len(raw) * 8) for b in bits})
    for p in pos:
        raw[p // 8] ^= 1 << (p % 8)
    c, got = read_damaged(bytes(raw))
    check_outcome(kind, [(p // 8, p // 8 + 1) for p in pos], c, got)


@FUZZ
@given(kind=st.sampled_from(KINDS), frac=st.floats(0.0, 1.0), length=st.integers(1, 4096))
@example(kind="ros2_zstd", frac=0.3, length=4096)  # wipes out more than one chunk
@example(kind="json_unchunked", frac=0.5, length=300)
# zeroes an lz4 chunk's header (sizes, CRC, compression): an empty chunk that passed every
# check; found by its message index records listing 18 messages
@example(kind="json_lz4", frac=63988.5 / 113194, length=560)
# zeroes part of the summary's copy of channel 3 (/gnss): the preloaded copy, parsed with a
# damaged topic, won over the data section's own definition and 60 GNSS messages were lost
@example(kind="json_lz4", frac=108764.5 / 113194, length=2856)
def test_zeroed_block(kind, frac, length):
    raw = bytearray(sample(kind))
    a = int(frac * (len(raw) - 1))
    b = min(len(raw), a + length)
    raw[a:b] = bytes(b - a)
    c, got = read_damaged(bytes(raw))
    check_outcome(kind, [(a, b)], c, got)


@FUZZ
@given(kind=st.sampled_from(KINDS), frac=st.floats(0.0, 1.0), junk=st.binary(min_size=1, max_size=64))
def test_garbage_overwrite(kind, frac, junk):
    raw = bytearray(sample(kind))
    a = int(frac * (len(raw) - 1))
    raw[a : a + len(junk)] = junk
    del raw[len(sample(kind)) :]
    c, got = read_damaged(bytes(raw))
    check_outcome(kind, [(a, a + len(junk))], c, got)


@FUZZ
@given(kind=st.sampled_from(KINDS), frac=st.floats(0.0, 1.0))
def test_cut_file(kind, frac):
    data = sample(kind)
    cut = int(frac * len(data))
    c, got = read_damaged(data[:cut])
    check_outcome(kind, [(cut, len(data))], c, got)


@pytest.mark.parametrize("kind", KINDS)
def test_intact_files_match_the_mcap_package(kind):
    """Undamaged: exactly the mcap package's messages, nothing reported."""
    c, got = read_damaged(sample(kind))
    assert got == everything(kind)
    assert c.salvage is None and not c.notes


@pytest.mark.parametrize("kind", ["ros2_zstd", "json_lz4", "ros2_zstd_nocrc"])
def test_damaged_middle_chunk_reported_and_rest_kept(kind, tmp_path):
    """One chunk in the middle destroyed: the region names its bytes, its log-time span and
    its message count; everything after it is read."""
    recs = records(kind)
    chunks = [(s, e, m) for s, e, m in recs if len(m) > 1]
    s, e, lost = chunks[len(chunks) // 2]
    raw = bytearray(sample(kind))
    raw[s + 9 + 60 : e - 8] = bytes(e - 8 - s - 9 - 60)  # zero the compressed records
    p = tmp_path / "z.mcap"
    p.write_bytes(bytes(raw))
    c = read_mcap(p, keep_raw=True)
    got = Counter((c.channels[ch].topic, lt, bytes(b)) for ch, _, lt, _, b in c.raw)
    assert got == everything(kind) - Counter(lost)
    (r,) = c.salvage.regions
    assert r.start == s and r.resumed and r.lost_messages == len(lost)
    assert (r.lost_start_ns, r.lost_end_ns) == (min(x[1] for x in lost), max(x[1] for x in lost))
    assert r.log_time_before_ns < r.lost_start_ns <= r.lost_end_ns < r.log_time_after_ns
    assert c.salvage.lost_messages == len(lost)


def test_two_damaged_regions_both_reported(tmp_path):
    recs = records("json_unchunked")
    msgs = [(s, e, m) for s, e, m in recs if m]
    raw = bytearray(sample("json_unchunked"))
    hit = [msgs[100], msgs[500]]
    for s, e, _ in hit:
        raw[s + 1 : s + 9] = b"\xff" * 8  # garbage length field
    p = tmp_path / "two.mcap"
    p.write_bytes(bytes(raw))
    c = read_mcap(p, keep_raw=True)
    got = Counter((c.channels[ch].topic, lt, bytes(b)) for ch, _, lt, _, b in c.raw)
    assert got == everything("json_unchunked") - Counter(m for _, _, ms in hit for m in ms)
    regs = c.salvage.regions
    assert [(r.start, r.end) for r in regs] == [(s, e) for s, e, _ in hit]
    text = c.salvage.describe(p)
    assert "damaged in 2 places" in text and "reading resumed" in text


def test_crcless_corrupted_values_dropped_and_counted(tmp_path):
    """Without chunk CRCs a flipped exponent bit is a valid message with a wrong value: the
    damage checks drop it (and a flipped time stamp), count them, and keep every other sample."""
    d = static_flight(seconds=FLIGHT_S)
    raw = bytearray(sample("ros2_none_nocrc"))
    # IMU sample 123: fz exponent bit flipped (9.8 -> 9.8 * 2**-512); sample 321: stamp sec + 2**6
    fz = struct.pack("<d", d["f"][123, 2])
    k = bytes(raw).index(fz)
    raw[k + 6] ^= 0x20
    t = int(d["imu_t"][321])
    stamp = struct.pack("<iI", t // 10**9, t % 10**9)
    k2 = bytes(raw).index(stamp, bytes(raw).index(struct.pack("<d", d["f"][321, 2])) - 400)
    raw[k2] ^= 0x40
    # the last sample's stamp: sec bit 27 (4 years later; an end sample has one neighbour)
    t = int(d["imu_t"][599])
    stamp = struct.pack("<iI", t // 10**9, t % 10**9)
    k3 = bytes(raw).index(stamp, bytes(raw).index(struct.pack("<d", d["f"][599, 2])) - 400)
    raw[k3 + 3] ^= 0x08
    (tmp_path / "v.mcap").write_bytes(bytes(raw))
    c = read_mcap(tmp_path / "v.mcap")
    assert c.salvage is None
    imu = next(b for cid, b in c.decoded.items() if c.channels[cid].topic == "/imu")
    assert imu.value_check_dropped == 3 and len(imu.time_ns) == 597
    keep = np.setdiff1d(np.arange(600), [123, 321, 599])
    np.testing.assert_array_equal(imu.time_ns, d["imu_t"][keep])
    np.testing.assert_array_equal(imu.values["specific_force"], d["f"][keep])
    opts = ingest_options({"inputs": {"mcap": "v.mcap"}}, "f")
    with pytest.warns(
        DataWarning,
        match=r"imu: 3 messages .* dropped \(3 samples without a "
        r"chunk CRC failed the damage checks",
    ):
        rec = load_flight(opts, tmp_path)
    assert len(rec.imu.time) == 597
    # with CRCs the same flips are caught by the CRC: the chunk is reported, not its values
    assert (
        read_mcap(_write(tmp_path, "crc.mcap", _flip_like(sample("ros2_none"), raw, sample("ros2_none_nocrc")))).salvage
        is not None
    )


def _write(tmp_path, name, data):
    (tmp_path / name).write_bytes(data)
    return tmp_path / name


def _flip_like(target, damaged, original):
    """Apply to ``target`` the byte differences between ``damaged`` and ``original``."""
    t = bytearray(target)
    for i in np.flatnonzero(np.frombuffer(bytes(damaged), np.uint8) != np.frombuffer(original, np.uint8)):
        t[i] = damaged[i]
    return bytes(t)


def test_damage_checks_leave_clean_data_alone():
    """On undamaged data no sample fails the damage checks."""
    from gravsurvey.io.checks import damaged_values

    d = static_flight(seconds=20.0)
    n = len(d["imu_t"])
    bad, why = damaged_values(
        "imu", d["imu_t"], d["imu_t"], {"specific_force": d["f"], "angular_rate": d["w"]}, np.ones(n, bool)
    )
    assert not bad.any(), why
    here = Path(__file__).resolve().parent
    # real ground-robot bags, and the simulated sample flights (turns, turbulence), read as if
    # they had no CRCs
    for f in [
        *sorted((here / "data" / "ros2-imu").glob("*.mcap")),
        *sorted((here.parent / "sample_data").glob("*/F01/*.mcap")),
    ]:
        c = read_mcap(f, check_crc=False)
        assert c.decoded
        for cid, blk in c.decoded.items():
            assert blk.value_check_dropped == 0, (f.name, c.channels[cid].topic)


def test_resync_kernel_matches_reference():
    from gravsurvey.io.mcap import find_resync

    raw = bytearray(sample("json_unchunked"))
    raw[5000:5100] = bytes(100)
    buf = np.frombuffer(bytes(raw), np.uint8)
    known = np.zeros(65536, np.bool_)
    known[[1, 2, 3]] = True
    for start in (4990, 5000, 5050, 12345, len(buf) - 200):
        a = find_resync(buf, start, len(buf), known, 4)
        b = find_resync(buf, start, len(buf), known, 4, use_kernel=False)
        assert a == b and a >= start
    assert find_resync(buf, 5000, len(buf), np.zeros(65536, np.bool_), 4) > 5000


def test_crcless_flip_that_crashed_mechanization(tmp_path):
    """Issue 14: the sample bag with chunk CRCs zeroed and one bit flipped (byte 866968, bit 1,
    inside zstd data) decoded an IMU value of 2.6e21 m/s^2 that was processed as data and ended
    in ZeroDivisionError in mechanization.  The damage checks drop it; with CRCs the chunk is
    refused instead."""
    bag = Path(__file__).resolve().parents[1] / "sample_data" / "grid_ros2" / "F01" / "F01_ros2.mcap"
    raw = bytearray(_zero_chunk_crcs(bag.read_bytes()))
    raw[866968] ^= 0x02
    (tmp_path / "d.mcap").write_bytes(bytes(raw))
    opts = ingest_options(
        {"inputs": {"mcap": "d.mcap"}, "topics": {"imu": "/imu", "altimeter": "/altimeter", "gnss": "/gnss"}}, "f"
    )
    with pytest.warns(
        DataWarning,
        match=r"1 samples without a chunk CRC failed the damage "
        r"checks \(1 non-finite/absurd\)",
    ):
        rec = load_flight(opts, tmp_path)
    assert np.abs(rec.imu.specific_force_t).max() < 50.0
    assert np.abs(rec.imu.angular_rate_t).max() < 1.0
    assert np.all(np.diff(rec.imu.time) > 0)
    intact = read_mcap(bag)
    imu_id = next(k for k, ch in intact.channels.items() if ch.topic == "/imu")
    assert len(rec.imu.time) == intact.counts[imu_id] - 1
    raw = bytearray(bag.read_bytes())
    raw[866968] ^= 0x02
    (tmp_path / "c.mcap").write_bytes(bytes(raw))
    assert "CRC" in read_mcap(tmp_path / "c.mcap").salvage.reason


def test_damaged_opcode_posing_as_data_end_does_not_hide_later_damage(tmp_path):
    """A message index record's opcode 7 -> 15 (one bit) reads as the data end; damage after
    it used to be taken for a damaged summary (a note, no data lost).  Messages read after it
    show it was not the end: the later damaged chunk is reported as lost data."""
    kind = "ros2_zstd"
    recs = records(kind)
    raw = bytearray(sample(kind))
    mi = [s for s, _, _ in recs if raw[s] == 7]
    chunks = [(s, e, m) for s, e, m in recs if len(m) > 1]
    raw[mi[3]] ^= 0x08
    s, e, lost = chunks[10]
    raw[s + 80 : e - 8] = bytes(e - 8 - s - 80)
    c, got = read_damaged(bytes(raw))
    check_outcome(kind, [(mi[3], mi[3] + 1), (s + 80, e - 8)], c, got)
    assert any(r.start == s and r.lost_messages == len(lost) for r in c.salvage.regions)
    assert not any("summary section damaged" in n for n in c.notes)


def test_damaged_summary_alone_is_a_note_not_data_loss(tmp_path):
    kind = "ros2_zstd"
    raw = bytearray(sample(kind))
    data_end = [s for s, _, _ in records(kind) if raw[s] == 15][0]
    raw[data_end + 13 + 8] ^= 0x80  # top bit of the first summary record's length
    c, got = read_damaged(bytes(raw))
    assert c.salvage is None and got == everything(kind)
    assert any("summary section damaged" in n and "all data records were read" in n for n in c.notes)
