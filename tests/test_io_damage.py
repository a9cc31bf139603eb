"""Damaged MCAP files: truncation, bit flips (hypothesis), garbage lengths, bombs, CRCs."""

from __future__ import annotations

import functools
import io
import struct
import tempfile
import tracemalloc
import warnings
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import zstandard
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.records import Chunk, Message
from mcap.writer import CompressionType
from test_io_support import static_flight, write_json, write_ros2

from gravsurvey.errors import DataError, DataWarning, GravsurveyError
from gravsurvey.io.ingest import load_flight
from gravsurvey.io.mcap import MAGIC, read_mcap
from gravsurvey.settings import ingest_options


@functools.lru_cache(maxsize=None)
def sample(kind):
    """Small multi-chunk files (bytes) of a 6 s static flight."""
    d = static_flight(seconds=6.0)
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "f.mcap"
        if kind == "ros2_zstd":
            write_ros2(p, d, chunk_size=8192)
        elif kind == "ros2_none":
            write_ros2(p, d, chunk_size=8192, compression=CompressionType.NONE)
        elif kind == "json_lz4":
            write_json(p, d, chunk_size=4096, compression=CompressionType.LZ4)
        else:
            write_json(p, d, use_chunking=False)
        return p.read_bytes()


@functools.lru_cache(maxsize=None)
def record_ends(kind):
    """(end offset of each top-level record, its messages), from the mcap package's streaming
    reader on the intact file (the reference for "every message before the damage")."""
    data = sample(kind)
    sr = StreamReader(io.BytesIO(data), emit_chunks=True)
    topics, out = {}, []
    for rec in sr.records:
        end = sr._stream.count  # bytes consumed so far = end of this record (incl. padding)
        if isinstance(rec, Chunk):
            inner = breakup_chunk(rec)
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
        out.append((end, [(topics[m.channel_id], m.log_time, m.data) for m in msgs]))
    assert sum(len(m) for _, m in out) == 600 + 60 + 60
    return out


def _expected_before(kind, offset):
    return Counter(m for end, msgs in record_ends(kind) if end <= offset for m in msgs)


def _recovered(data, **kw):
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "d.mcap"
        p.write_bytes(data)
        try:
            c = read_mcap(p, keep_raw=True, **kw)
        except DataError:
            assert len(data) < 8 or data[:8] != MAGIC  # only "not MCAP" may raise here
            return None, Counter()
        got = Counter((c.channels[ch].topic, lt, bytes(b)) for ch, _, lt, _, b in c.raw if ch in c.channels)
        # the whole pipeline front end: only our own error types
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", DataWarning)
                load_flight(ingest_options({"inputs": {"mcap": "d.mcap"}}, "f"), tmp)
        except GravsurveyError:
            pass
        return c, got


KINDS = ["ros2_zstd", "ros2_none", "json_lz4", "json_unchunked"]
FUZZ = settings(
    max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large]
)


@FUZZ
@given(kind=st.sampled_from(KINDS), frac=st.floats(0.0, 1.0))
def test_truncation_salvages_every_message_before_the_cut(kind, frac):
    data = sample(kind)
    cut = int(frac * len(data))
    c, got = _recovered(data[:cut])
    want = _expected_before(kind, cut)
    assert not (want - got), f"lost messages before the cut at {cut}"
    allm = _expected_before(kind, len(data))
    assert not (got - allm), "salvage invented messages"
    if c is not None and cut < record_ends(kind)[-1][0]:
        # either damage is reported, or the cut fell between records: no footer
        assert c.salvage is not None or any("no footer" in n for n in c.notes)


@FUZZ
@given(kind=st.sampled_from(KINDS), bits=st.lists(st.integers(0, 2**40), min_size=1, max_size=3))
# the bug of issue 14: flipping byte 11815 (a message record's opcode, 5 -> 4 or 1) of the
# unchunked JSON file lost every message of the batch the record was in, back to byte 426:
# definitions and messages were handled in one batch whose damage was reported at its start
@example(kind="json_unchunked", bits=[11815 * 8])
@example(kind="json_unchunked", bits=[11815 * 8 + 2])
def test_bit_flips_never_crash_and_keep_messages_before_damage(kind, bits):
    raw = bytearray(sample(kind))
    positions = [b % (len(raw) * 8) for b in bits]
    for p in positions:
        raw[p // 8] ^= 1 << (p % 8)
    first = min(positions) // 8
    c, got = _recovered(bytes(raw))
    want = _expected_before(kind, first)
    assert not (want - got), f"lost messages before the first flip at byte {first}"


@FUZZ
@given(kind=st.sampled_from(KINDS), frac=st.floats(0.0, 1.0), junk=st.binary(min_size=1, max_size=64))
# a ',' inside a JSON vector ("[1, 2, 3]" -> "[1, 2,, 3]"-like ragged arrays): numpy refused the
# ragged column with ValueError in the bulk JSON decoder
@example(kind="json_unchunked", frac=2216.5 / 160938, junk=b",")
def test_random_garbage_overwrite_only_our_errors(kind, frac, junk):
    raw = bytearray(sample(kind))
    pos = int(frac * (len(raw) - 1))
    raw[pos : pos + len(junk)] = junk
    _, got = _recovered(bytes(raw))
    assert not (_expected_before(kind, pos) - got)


def test_cut_inside_uncompressed_chunk_keeps_its_complete_records(tmp_path):
    data = sample("ros2_none")
    ends = record_ends("ros2_none")
    # a cut in the middle of the third message-bearing chunk
    chunk_ends = [e for e, m in ends if len(m) > 1]
    cut = (chunk_ends[1] + chunk_ends[2]) // 2
    p = tmp_path / "cut.mcap"
    p.write_bytes(data[:cut])
    c = read_mcap(p)
    before = sum(len(m) for e, m in ends if e <= cut)
    assert c.salvage.recovered > before  # complete records of the cut chunk recovered too
    assert "cut inside a chunk" in c.salvage.reason
    opts = ingest_options({"inputs": {"mcap": "cut.mcap"}}, "f")
    with pytest.warns(DataWarning, match=r"salvaged \d+ messages up to log time .* lost"):
        rec = load_flight(opts, tmp_path)
    d = static_flight(seconds=6.0)
    n = len(rec.imu.time)
    assert 0 < n < 600
    np.testing.assert_array_equal(rec.imu.specific_force_t, d["f"][:n])


def test_damage_with_intact_summary_reports_lost_span_and_count(tmp_path):
    data = bytearray(sample("ros2_zstd"))
    ends = record_ends("ros2_zstd")
    chunk_ends = [e for e, m in ends if len(m) > 1]
    lost = [m for e, m in ends if e == chunk_ends[2]][0]
    data[chunk_ends[2] - 40] ^= 0xFF  # inside the 3rd chunk's compressed records
    p = tmp_path / "flip.mcap"
    p.write_bytes(bytes(data))
    c = read_mcap(p, keep_raw=True)
    s = c.salvage
    # reading resumed at the 4th chunk: only the 3rd chunk's messages are lost, counted from
    # its message index records; its log-time span comes from the summary's chunk index
    assert s is not None and len(s.regions) == 1 and s.regions[0].resumed
    r = s.regions[0]
    assert chunk_ends[1] <= r.start < chunk_ends[2]
    assert s.lost_messages == r.lost_messages == len(lost) == 720 - s.recovered
    assert (r.lost_start_ns, r.lost_end_ns) == (min(m[1] for m in lost), max(m[1] for m in lost))
    assert s.lost_until_ns is None  # the file's end was read
    got = Counter((c.channels[ch].topic, lt, bytes(b)) for ch, _, lt, _, b in c.raw)
    assert got == _expected_before("ros2_zstd", len(data)) - Counter(lost)
    text = s.describe(p)
    assert f"{len(lost)} messages lost" in text and "reading resumed" in text


def _header_record():
    body = struct.pack("<I", 0) + struct.pack("<I", 0)
    return bytes([1]) + struct.pack("<Q", len(body)) + body


def _peak_mib(fn):
    """Peak traced Python/numpy heap (MiB) of a second call (the first loads numba kernels)."""
    fn()
    tracemalloc.start()
    try:
        out = fn()
        return out, tracemalloc.get_traced_memory()[1] / 2**20
    finally:
        tracemalloc.stop()


def test_garbage_record_length_refused_with_bounded_memory(tmp_path):
    p = tmp_path / "g.mcap"
    p.write_bytes(MAGIC + _header_record() + bytes([5]) + struct.pack("<Q", 2**62) + b"x" * 100)
    c, peak = _peak_mib(lambda: read_mcap(p))
    assert "declares 4611686018427387904 bytes" in c.salvage.reason
    assert peak < 1


def _chunk_record(payload_records, declared_size, compression="zstd", compressed=None):
    comp = compressed if compressed is not None else payload_records
    body = (
        struct.pack("<QQQI", 0, 0, declared_size, 0)
        + struct.pack("<I", len(compression))
        + compression.encode()
        + struct.pack("<Q", len(comp))
        + comp
    )
    return bytes([6]) + struct.pack("<Q", len(body)) + body


def test_decompression_bomb_refused_with_bounded_memory(tmp_path):
    bomb = zstandard.ZstdCompressor(level=1).compress(b"\0" * (512 * 2**20))
    assert len(bomb) < 100_000
    # declared honestly (512 MiB > 256 MiB limit): refused before decompressing
    p = tmp_path / "b1.mcap"
    p.write_bytes(MAGIC + _header_record() + _chunk_record(None, 512 * 2**20, compressed=bomb))
    c, peak = _peak_mib(lambda: read_mcap(p))
    assert "above the 268435456-byte limit" in c.salvage.reason
    assert peak < 1
    # declared small (lying): we never decompress more than declared + 1 byte
    p = tmp_path / "b2.mcap"
    p.write_bytes(MAGIC + _header_record() + _chunk_record(None, 1000, compressed=bomb))
    c, peak = _peak_mib(lambda: read_mcap(p))
    assert "decompressed to 1001 bytes, header says 1000" in c.salvage.reason
    assert peak < 1
    with pytest.raises(DataError, match="b2.mcap: no usable imu|b2.mcap: no imu"):
        load_flight(ingest_options({"inputs": {"mcap": "b2.mcap"}}, "f"), tmp_path)


def test_crc_check_catches_silent_corruption(tmp_path):
    data = bytearray(sample("ros2_none"))
    d = static_flight(seconds=6.0)
    # flip the lowest mantissa bit of the 1st IMU sample's fz: still a valid message
    target = struct.pack("<d", d["f"][0, 2])
    k = bytes(data).index(target)
    data[k] ^= 1
    p = tmp_path / "c.mcap"
    p.write_bytes(bytes(data))
    assert "CRC" in read_mcap(p).salvage.reason
    c = read_mcap(p, check_crc=False)
    assert c.salvage is None  # without CRCs the corruption goes unseen...
    imu = next(b for cid, b in c.decoded.items() if c.channels[cid].topic == "/imu")
    assert imu.values["specific_force"][0, 2] != d["f"][0, 2]  # ...and the value is wrong


def test_not_mcap_and_missing_file(tmp_path):
    p = tmp_path / "x.mcap"
    p.write_bytes(b"hello world, not an mcap")
    with pytest.raises(DataError, match="x.mcap: not an MCAP file"):
        read_mcap(p)
    with pytest.raises(DataError, match="nope.mcap: cannot open"):
        read_mcap(tmp_path / "nope.mcap")
    (tmp_path / "e.mcap").write_bytes(b"")
    with pytest.raises(DataError, match="e.mcap: empty file"):
        read_mcap(tmp_path / "e.mcap")
