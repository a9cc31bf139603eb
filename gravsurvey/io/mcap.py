"""MCAP reader: damage-tolerant record scan, bounded chunk decompression, bulk decoding.

Why our own record scanner rather than ``mcap.reader``: the ``mcap`` package (1.6) trusts
declared lengths (``zstandard.decompress(data, uncompressed_size)`` and ``lz4.frame.decompress``
allocate whatever a damaged header says), does not notice short reads, and its indexed reader
raises ``KeyError`` on valid files whose summary lacks repeated channel/schema records.  We scan
the file linearly (the spec's streaming order), which needs neither the summary nor the indexes,
and we check every length against the bytes that are really there.  The ``mcap`` package stays the
independent reference in the tests and the benchmark.

Memory bound: the file is memory-mapped (pages, not heap); besides the decoded output arrays, the
reader holds at most one decompressed chunk, and refuses any chunk whose declared uncompressed
size exceeds ``max_record_bytes`` (default 256 MiB) before allocating anything.  Top-level
records are never copied, only sliced from the map.

Salvage: a damaged record (length beyond end of file, absurd length, failed decompression, CRC
mismatch, bad opcode, a message on an undefined channel, ...) is skipped and reading resumes at
the next intact record (:func:`find_resync`: the next chain of plausible records, or the next
chunk of the summary's chunk index); a chunk cut by the end of the file is decompressed as far
as its bytes go and its complete message records are kept.  :class:`SalvageInfo` lists every
skipped region (:class:`SkippedRegion`) with what was recovered and lost.  Samples not protected
by a verified chunk CRC go through :func:`gravsurvey.io.checks.damaged_values`.
"""

from __future__ import annotations

import io
import json
import mmap
import os
import struct
import zlib
from dataclasses import dataclass, field

import numba
import numpy as np

from gravsurvey.errors import DataError
from gravsurvey.io.checks import damaged_values

MAGIC = b"\x89MCAP0\r\n"
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK = 1, 2, 3, 4, 5, 6
OP_MESSAGE_INDEX, OP_CHUNK_INDEX, OP_ATTACHMENT, OP_ATTACHMENT_INDEX = 7, 8, 9, 10
OP_STATISTICS, OP_METADATA, OP_METADATA_INDEX, OP_SUMMARY_OFFSET, OP_DATA_END = 11, 12, 13, 14, 15
MESSAGE_HEADER_BYTES = 2 + 4 + 8 + 8  # channel_id, sequence, log_time, publish_time
DEFAULT_MAX_RECORD_BYTES = 256 * 2**20

# scan status codes (kernel and reference agree on them)
SCAN_OK = 0  # ended exactly at ``end`` or after a footer
SCAN_SHORT_HEADER = 1  # fewer than 9 bytes left for an opcode + length
SCAN_BEYOND_END = 2  # a record's declared length runs past ``end``
SCAN_BAD_MESSAGE = 3  # a message record shorter than its fixed 22-byte header
SCAN_BAD_OPCODE = 4  # opcode 0; or > 0x0F inside a chunk (not forward-compatible there)
SCAN_UNKNOWN_CHANNEL = 5  # a top-level message on a channel id no earlier record defined
SCAN_EARLY_FOOTER = 6  # (reader only) a footer record that does not end the file
# records that belong in the summary section only (a sign of damage before the data end)
SUMMARY_ONLY_OPS = (OP_CHUNK_INDEX, OP_ATTACHMENT_INDEX, OP_STATISTICS, OP_METADATA_INDEX,
                    OP_SUMMARY_OFFSET)
DAMAGED_START_MAX = 4096  # a file without closing magic is read only if records chain by here
DAMAGE_CHECK_PASSES = 4  # rounds of checks.damaged_values on CRC-less samples
RESYNC_MIN_CHAIN = 4  # records that must chain up for a resynchronisation point to count

# schema names by role, for topic auto-detection
ROLE_SCHEMAS = {
    "imu": ("sensor_msgs/msg/Imu", "sensor_msgs/Imu", "gravsurvey.Imu"),
    "altimeter": ("geometry_msgs/msg/PointStamped", "geometry_msgs/PointStamped",
                  "gravsurvey.Altimeter"),
    "gnss": ("sensor_msgs/msg/NavSatFix", "sensor_msgs/NavSatFix", "gravsurvey.Gnss"),
    # optional gravity-gradient channel (JSON only; docs/formats.md)
    "gradient": ("gravsurvey.GravityGradient",),
}
ROS2_IMU = ("sensor_msgs/msg/Imu", "sensor_msgs/Imu")
ROS2_NAVSATFIX = ("sensor_msgs/msg/NavSatFix", "sensor_msgs/NavSatFix")
ROS2_POINTSTAMPED = ("geometry_msgs/msg/PointStamped", "geometry_msgs/PointStamped")


# ----------------------------------------------------------------------------- record scanning
@numba.njit(cache=True)
def _u64(buf, i):
    v = np.uint64(0)
    for k in range(8):
        v |= np.uint64(buf[i + k]) << np.uint64(8 * k)
    return v


@numba.njit(cache=True)
def _scan_kernel(buf, start, end, stop_at_footer, known_in, check_chan, fill, opcodes, rec_pos,
                 rec_len, chan, logt, pubt, seq):
    """Walk MCAP records in ``buf[start:end]``.

    Parameters
    ----------
    buf : ndarray of uint8
    start, end : int
        Byte range to walk.
    stop_at_footer : bool
        Top level: stop after a footer record; opcode 0 is damage (unknown opcodes 16-255 are
        skipped, as the specification asks).  False (inside a chunk): opcode 0 or > 15 is
        damage.
    known_in : ndarray of bool, shape (65536,)
        Channel ids defined before ``start``.
    check_chan : bool
        A message on a channel id that no earlier channel record defined is damage (the
        specification puts every channel record before its messages).  Channel records met
        on the way are added to a private copy of ``known_in``.
    fill : bool
        False: only count; True: write into the output arrays (sized by a counting pass).
    opcodes, rec_pos, rec_len : ndarray
        Per record: opcode, byte offset of its content, content length.
    chan, logt, pubt, seq : ndarray
        Per record (message records only, others 0): channel id, log time (ns),
        publish time (ns), sequence.

    Returns
    -------
    n : int
        Number of complete records.
    pos : int
        Offset just after the last complete record.
    status : int
        ``SCAN_*`` code.
    """
    known = known_in.copy() if check_chan else known_in
    pos = start
    n = 0
    status = 0
    while pos < end:
        if end - pos < 9:
            status = 1
            break
        op = buf[pos]
        length = _u64(buf, pos + 1)
        if length > np.uint64(end - pos - 9):
            status = 2
            break
        ln = np.int64(length)
        if op == 5 and ln < 22:
            status = 3
            break
        if op == 0 or (not stop_at_footer and op > 15):
            status = 4
            break
        c = pos + 9
        if check_chan:
            if op == 5:
                if not known[np.int64(buf[c]) | (np.int64(buf[c + 1]) << 8)]:
                    status = 5
                    break
            elif op == 4 and ln >= 2:
                known[np.int64(buf[c]) | (np.int64(buf[c + 1]) << 8)] = True
        if fill:
            opcodes[n] = op
            rec_pos[n] = c
            rec_len[n] = ln
            if op == 5:
                chan[n] = np.int64(buf[c]) | (np.int64(buf[c + 1]) << 8)
                seq[n] = (np.int64(buf[c + 2]) | (np.int64(buf[c + 3]) << 8)
                          | (np.int64(buf[c + 4]) << 16) | (np.int64(buf[c + 5]) << 24))
                logt[n] = np.int64(_u64(buf, c + 6))
                pubt[n] = np.int64(_u64(buf, c + 14))
        n += 1
        pos = pos + 9 + ln
        if stop_at_footer and op == 2:
            break
    return n, pos, status


def _scan_reference(buf, start, end, stop_at_footer, known_in=None, check_chan=False):
    """Pure-Python reference of :func:`_scan_kernel` (same outputs); for tests."""
    b = bytes(buf)
    known = set() if known_in is None else set(np.flatnonzero(known_in).tolist())
    pos, status = start, SCAN_OK
    rows = []
    while pos < end:
        if end - pos < 9:
            status = SCAN_SHORT_HEADER
            break
        op, length = struct.unpack_from("<BQ", b, pos)
        if length > end - pos - 9:
            status = SCAN_BEYOND_END
            break
        if op == OP_MESSAGE and length < MESSAGE_HEADER_BYTES:
            status = SCAN_BAD_MESSAGE
            break
        if op == 0 or (not stop_at_footer and op > 15):
            status = SCAN_BAD_OPCODE
            break
        c = pos + 9
        if check_chan and op == OP_MESSAGE and struct.unpack_from("<H", b, c)[0] not in known:
            status = SCAN_UNKNOWN_CHANNEL
            break
        if check_chan and op == OP_CHANNEL and length >= 2:
            known.add(struct.unpack_from("<H", b, c)[0])
        if op == OP_MESSAGE:
            ch, sq, lt, pt = struct.unpack_from("<HIQQ", b, c)
            # times above 2**63 wrap like the kernel's int64 cast
            lt, pt = np.uint64(lt).astype(np.int64), np.uint64(pt).astype(np.int64)
        else:
            ch = sq = lt = pt = 0
        rows.append((op, c, length, ch, int(lt), int(pt), sq))
        pos = c + length
        if stop_at_footer and op == OP_FOOTER:
            break
    cols = list(zip(*rows)) if rows else [()] * 7
    out = [np.array(col, dtype=np.int64) for col in cols]
    return len(rows), pos, status, out


NO_CHANNELS = np.zeros(65536, np.bool_)


def scan_records(buf, start, end, stop_at_footer=False, use_kernel=True, known=None):
    """Index the MCAP records in ``buf[start:end]`` (numba kernel, two passes).

    Parameters
    ----------
    known : ndarray of bool, shape (65536,), optional
        Channel ids defined before ``start``; given, a message on an undefined channel stops
        the scan with ``SCAN_UNKNOWN_CHANNEL`` (see :func:`_scan_kernel`).

    Returns
    -------
    n, pos, status : int
        See :func:`_scan_kernel`.
    arrays : list of ndarray, each shape (n,), int64
        opcodes, content offsets, content lengths, channel ids, log times, publish times,
        sequences.
    """
    check = known is not None
    known = NO_CHANNELS if known is None else known
    if not use_kernel:
        return _scan_reference(buf, start, end, stop_at_footer, known, check)
    z = np.zeros(0, np.int64)
    n, pos, status = _scan_kernel(buf, start, end, stop_at_footer, known, check, False,
                                  z, z, z, z, z, z, z)
    arrs = [np.zeros(n, np.int64) for _ in range(7)]
    _scan_kernel(buf, start, end, stop_at_footer, known, check, True, *arrs)
    return n, pos, status, arrs


@numba.njit(cache=True)
def _chain_at(buf, p, end, known, min_chain):
    """Does a chain of plausible top-level records start at ``p``?

    Plausible: opcode 1..15, length inside ``end``, a message at least 22 bytes long on a
    channel defined earlier (``known``), a footer only as the last record before the closing
    magic.  The chain counts when ``min_chain`` records follow one another, or at least one
    does and the chain ends exactly at ``end``, or with a record cut by ``end`` (a truncated
    file), or at the footer.
    """
    count = 0
    while count < min_chain:
        if p == end:
            return count >= 1
        if end - p < 9:
            return count >= 1
        op = buf[p]
        if op == 0 or op > 15:
            return False
        length = _u64(buf, p + 1)
        if length > np.uint64(end - p - 9):
            return count >= 1 and length < np.uint64(1 << 40)
        ln = np.int64(length)
        if op == 5:
            if ln < 22 or not known[np.int64(buf[p + 9]) | (np.int64(buf[p + 10]) << 8)]:
                return False
        if op == 2:  # a footer: 20 bytes, then the closing magic ends the file
            return ln == 20 and p + 9 + 20 + 8 == end and buf[p + 29] == 0x89
        count += 1
        p = p + 9 + ln
    return True


@numba.njit(cache=True)
def _resync_kernel(buf, start, end, known, min_chain, opcode):
    """First offset >= ``start`` where :func:`_chain_at` holds (and, if ``opcode`` > 0, whose
    record has that opcode); -1 when none."""
    for p in range(start, end - 8):
        op = buf[p]
        if op == 0 or op > 15 or (opcode > 0 and op != opcode):
            continue
        if _chain_at(buf, p, end, known, min_chain):
            return p
    return -1


def _resync_reference(buf, start, end, known, min_chain, opcode):
    """Pure-Python reference of :func:`_resync_kernel` (for tests; slow)."""
    b = bytes(buf)
    ids = set(np.flatnonzero(known).tolist())

    def chain(p):
        count = 0
        while count < min_chain:
            if p == end or end - p < 9:
                return count >= 1
            op, length = struct.unpack_from("<BQ", b, p)
            if op == 0 or op > 15:
                return False
            if length > end - p - 9:
                return count >= 1 and length < 1 << 40
            if op == OP_MESSAGE and (length < MESSAGE_HEADER_BYTES
                                     or struct.unpack_from("<H", b, p + 9)[0] not in ids):
                return False
            if op == OP_FOOTER:
                return length == 20 and p + 9 + 20 + 8 == end and b[p + 29] == 0x89
            count += 1
            p += 9 + length
        return True

    for p in range(start, end - 8):
        op = b[p]
        if op == 0 or op > 15 or (opcode > 0 and op != opcode):
            continue
        if chain(p):
            return p
    return -1


def find_resync(buf, start, end, known, min_chain=4, opcode=0, use_kernel=True):
    """Offset of the next plausible top-level record boundary at or after ``start``.

    Parameters
    ----------
    buf : ndarray of uint8
    start, end : int
    known : ndarray of bool, shape (65536,)
        Channel ids defined so far (messages on others are not plausible).
    min_chain : int
        Records that must follow one another for a boundary to count (fewer when they end
        exactly at ``end`` or a footer).
    opcode : int
        Only boundaries whose first record has this opcode (0: any).

    Returns
    -------
    int
        The offset, or -1.
    """
    if use_kernel:
        return int(_resync_kernel(buf, start, end, known, min_chain, opcode))
    return _resync_reference(buf, start, end, known, min_chain, opcode)


# ----------------------------------------------------------------------------- record parsing
class _Damaged(Exception):
    """Internal: a record's content is inconsistent (caught, turned into salvage)."""


def _str(b, pos, end):
    if pos + 4 > end:
        raise _Damaged("string length beyond record")
    (n,) = struct.unpack_from("<I", b, pos)
    if pos + 4 + n > end:
        raise _Damaged("string beyond record")
    try:
        return bytes(b[pos + 4:pos + 4 + n]).decode("utf-8"), pos + 4 + n
    except UnicodeDecodeError as exc:
        raise _Damaged("string not UTF-8") from exc


def _bytes32(b, pos, end):
    if pos + 4 > end:
        raise _Damaged("byte array length beyond record")
    (n,) = struct.unpack_from("<I", b, pos)
    if pos + 4 + n > end:
        raise _Damaged("byte array beyond record")
    return bytes(b[pos + 4:pos + 4 + n]), pos + 4 + n


def _plausible_name(s):
    """A topic/schema name/encoding that could be real: non-empty, printable."""
    return bool(s) and s.isprintable()


def _parse_schema(b, pos, ln):
    end = pos + ln
    if ln < 2:
        raise _Damaged("schema record too short")
    (sid,) = struct.unpack_from("<H", b, pos)
    name, p = _str(b, pos + 2, end)
    enc, p = _str(b, p, end)
    data, p = _bytes32(b, p, end)
    return SchemaInfo(sid, name, enc, data)


def _parse_channel(b, pos, ln):
    end = pos + ln
    if ln < 4:
        raise _Damaged("channel record too short")
    cid, sid = struct.unpack_from("<HH", b, pos)
    topic, p = _str(b, pos + 4, end)
    enc, p = _str(b, p, end)
    if p + 4 > end:
        raise _Damaged("channel metadata beyond record")
    (mlen,) = struct.unpack_from("<I", b, p)
    p += 4
    mend = p + mlen
    if mend > end:
        raise _Damaged("channel metadata beyond record")
    meta = {}
    while p < mend:
        k, p = _str(b, p, mend)
        v, p = _str(b, p, mend)
        meta[k] = v
    return ChannelInfo(cid, sid, topic, enc, meta)


@dataclass
class SchemaInfo:
    """An MCAP schema record (``id`` 0 never appears: it means schemaless)."""

    id: int
    name: str
    encoding: str
    data: bytes


@dataclass
class ChannelInfo:
    """An MCAP channel record."""

    id: int
    schema_id: int
    topic: str
    message_encoding: str
    metadata: dict


def _utc(ns):
    """ISO 8601 UTC of integer ns since the Unix epoch (ms resolution, for messages)."""
    import datetime

    try:
        d = datetime.datetime.fromtimestamp(ns // 10**9, datetime.timezone.utc)
    except (OverflowError, OSError, ValueError):
        return f"{ns} ns"
    return d.strftime("%Y-%m-%dT%H:%M:%S") + f".{ns % 10**9 // 10**6:03d}Z"


@dataclass
class SkippedRegion:
    """One unreadable stretch of a damaged file, and what reading it would have given.

    Attributes
    ----------
    start, end : int
        Byte range skipped: ``start`` is the first damaged record, ``end`` where reading
        resumed (the file size when it never did).
    reason : str
        What was wrong at ``start``.
    log_time_before_ns, log_time_after_ns : int or None
        Log time of the last message read before the region and of the first one read after
        it: the recording has no readable data strictly between them.
    lost_start_ns, lost_end_ns : int or None
        Log-time span of the lost messages when known (chunk headers or the summary's chunk
        index).
    lost_messages : int or None
        Messages lost in the region when countable (message index records of the lost
        chunks), else None.
    resumed : bool
        Reading resumed after the region (False: the damage runs to the end of the file).
    """

    start: int
    end: int
    reason: str
    log_time_before_ns: int | None = None
    log_time_after_ns: int | None = None
    lost_start_ns: int | None = None
    lost_end_ns: int | None = None
    lost_messages: int | None = None
    resumed: bool = True

    def as_dict(self) -> dict:
        """JSON-serialisable form (times as ns and ISO UTC)."""
        d = {"byte_start": self.start, "byte_end": self.end, "bytes": self.end - self.start,
             "reason": self.reason, "resumed": self.resumed,
             "lost_messages": self.lost_messages}
        for k in ("log_time_before_ns", "log_time_after_ns", "lost_start_ns", "lost_end_ns"):
            v = getattr(self, k)
            d[k] = v
            d[k.replace("_ns", "_utc")] = None if v is None else _utc(v)
        return d

    def describe(self) -> str:
        """One clause for :meth:`SalvageInfo.describe`."""
        s = f"bytes {self.start}-{self.end} skipped ({self.reason})"
        if self.lost_start_ns is not None and self.lost_end_ns is not None:
            s += (f", log time {_utc(self.lost_start_ns)} to {_utc(self.lost_end_ns)} "
                  "lost")
        elif self.resumed and self.log_time_before_ns is not None \
                and self.log_time_after_ns is not None:
            gap = (self.log_time_after_ns - self.log_time_before_ns) * 1e-9
            s += (f", no data between log time {_utc(self.log_time_before_ns)} and "
                  f"{_utc(self.log_time_after_ns)} ({gap:.3f} s)")
        if self.resumed:
            s += (f", {self.lost_messages} messages lost" if self.lost_messages is not None
                  else ", messages lost: not countable")
        return s


@dataclass
class SalvageInfo:
    """What a damaged or truncated file gave back.

    Reading resumes after each damaged stretch at the next intact record (see
    :func:`find_resync`); ``regions`` lists every stretch skipped.

    Attributes
    ----------
    offset : int
        Byte offset of the first damaged/incomplete record.
    file_size : int
        Bytes in the file.
    reason : str
        What was wrong there.
    recovered : int
        Messages recovered (all channels, before and after the damage).
    last_log_time_ns : int or None
        Latest log time recovered.
    lost_until_ns : int or None
        When the damage runs to the end of the file: latest log time known to exist (summary
        statistics, chunk index or the damaged chunk's header); None when unknown.
    lost_messages : int or None
        Messages known to be lost: summary statistics minus recovered, else the sum over
        ``regions`` when every region is countable; None when unknown.
    estimated_lost_s : float or None
        Unread tail bytes / bytes per second of the part read: a rough lost span when the
        damage runs to the end of the file and the file has no summary.
    truncated : bool
        The file ends inside a record (cut short).
    regions : list of SkippedRegion
        Every skipped stretch, in file order.
    """

    offset: int
    file_size: int
    reason: str
    recovered: int = 0
    last_log_time_ns: int | None = None
    lost_until_ns: int | None = None
    lost_messages: int | None = None
    estimated_lost_s: float | None = None
    truncated: bool = False
    regions: list = field(default_factory=list)

    @property
    def bytes_skipped(self) -> int:
        """Bytes in all skipped regions."""
        if not self.regions:
            return self.file_size - self.offset
        return sum(r.end - r.start for r in self.regions)

    def describe(self, path) -> str:
        """One line for warnings and notes."""
        regions = self.regions or [SkippedRegion(self.offset, self.file_size, self.reason,
                                                 resumed=False)]
        tail = regions[-1] if not regions[-1].resumed else None
        if len(regions) == 1:
            s = (f"{path}: damaged at byte {self.offset} of {self.file_size} ({self.reason}); "
                 f"salvaged {self.recovered} messages")
        else:
            s = (f"{path}: damaged in {len(regions)} places, {self.bytes_skipped} of "
                 f"{self.file_size} bytes skipped; salvaged {self.recovered} messages")
        if tail is None or len(regions) > 1:
            s += "; " + "; ".join(r.describe() for r in regions if r.resumed)
            if self.lost_messages is not None:
                s += f"; {self.lost_messages} messages lost in all"
        if tail is None:
            return s + "; reading resumed after the damage"
        lost_bytes = self.file_size - tail.start
        if self.last_log_time_ns is not None:
            s += f" up to log time {_utc(self.last_log_time_ns)}"
        if self.lost_until_ns is not None and self.last_log_time_ns is not None:
            span = max(0, self.lost_until_ns - self.last_log_time_ns) * 1e-9
            s += f"; lost at least {span:.3f} s of data"
        elif self.truncated:
            s += ("; the file ends there (truncated or unfinished recording, no summary): the "
                  "time span lost after it is unknown")
        elif self.estimated_lost_s is not None:
            s += (f"; lost ~{self.estimated_lost_s:.3f} s ({lost_bytes} bytes unread, no summary: "
                  "estimated from the data rate of the part read)")
        else:
            s += f"; lost time span unknown ({lost_bytes} bytes unread, no summary)"
        if self.lost_messages is not None and len(regions) == 1:
            s += f", {self.lost_messages} messages per the summary"
        if len(regions) > 1 or tail.start != self.offset:
            s += f"; reading could not resume after byte {tail.start}"
        return s


@dataclass
class DecodedBlock:
    """Decoded samples of one channel (possibly concatenated over chunks).

    ``values`` maps field names to float64 arrays: ``specific_force`` (n, 3),
    ``angular_rate`` (n, 3) for IMU; ``height`` (n,) for altimeter; ``lat_deg``, ``lon_deg``,
    ``height`` (n,) for GNSS.  ``time_ns`` int64 (n,) is the measurement time; ``log_time_used``
    counts messages whose time fell back to the MCAP log time.
    """

    time_ns: np.ndarray
    values: dict
    log_time_used: int = 0
    undecodable: int = 0
    problems: list = field(default_factory=list)
    log_time_ns: np.ndarray | None = None  # MCAP log time of each decoded message
    verified: np.ndarray | None = None  # bool (n,): sample came from a CRC-checked chunk
    value_check_dropped: int = 0  # unverified samples dropped by checks.damaged_values


@dataclass
class McapContent:
    """Everything :func:`read_mcap` learned from one file.

    Attributes
    ----------
    channels, schemas : dict
        By id.
    counts : dict[int, int]
        Messages per channel id.
    log_times : dict[int, ndarray]
        Log times (ns, int64, file order) per channel id.
    decoded : dict[int, DecodedBlock]
        Decoded samples for channels whose role and encoding we understand.
    raw : list or None
        With ``keep_raw``: (channel_id, sequence, log_time, publish_time, data) per message,
        sorted by log time (stable).
    salvage : SalvageInfo or None
        Set when the file was damaged or truncated.
    notes : list[str]
    """

    path: str
    profile: str = ""
    library: str = ""
    channels: dict = field(default_factory=dict)
    schemas: dict = field(default_factory=dict)
    counts: dict = field(default_factory=dict)
    log_times: dict = field(default_factory=dict)
    decoded: dict = field(default_factory=dict)
    raw: list | None = None
    salvage: SalvageInfo | None = None
    statistics: dict | None = None
    notes: list = field(default_factory=list)
    orphan_messages: int = 0
    chunks: int = 0
    compressions: set = field(default_factory=set)

    def role_of_schema(self, cid):
        ch = self.channels.get(cid)
        if ch is None:
            return None
        sch = self.schemas.get(ch.schema_id)
        name = sch.name if sch else ""
        for role, names in ROLE_SCHEMAS.items():
            if name in names:
                return role
        return None

    def schema_name(self, cid):
        ch = self.channels.get(cid)
        sch = self.schemas.get(ch.schema_id) if ch else None
        return sch.name if sch else ""


# ----------------------------------------------------------------------------- decompression
def _decompress(compression, data, size, complete):
    """Decompress one chunk's records, never producing more than ``size`` bytes.

    ``complete`` False: the chunk was cut by the end of the file; return what the available
    bytes decode to (possibly less than ``size``).  Raises _Damaged on failure.
    """
    if compression == "":
        if complete and len(data) != size:
            raise _Damaged(f"uncompressed chunk holds {len(data)} bytes, header says {size}")
        return bytes(data[:size])
    if compression == "zstd":
        import zstandard

        reader = zstandard.ZstdDecompressor().stream_reader(io.BytesIO(data),
                                                             read_across_frames=True)
        if complete:
            try:
                out = reader.read(size + 1) if size else b""
            except zstandard.ZstdError as exc:
                raise _Damaged(f"zstd: {exc}") from exc
            if len(out) != size:
                raise _Damaged(f"zstd chunk decompressed to {len(out)} bytes, header says {size}")
            return out
        parts, total = [], 0
        while total < size:
            try:
                piece = reader.read(min(1 << 20, size - total))
            except zstandard.ZstdError:
                break
            if not piece:
                break
            parts.append(piece)
            total += len(piece)
        return b"".join(parts)
    if compression == "lz4":
        import lz4.frame

        dec = lz4.frame.LZ4FrameDecompressor()
        try:
            out = dec.decompress(bytes(data), max_length=size + 1 if complete else size)
        except Exception as exc:  # lz4 raises RuntimeError on corrupt frames
            if complete:
                raise _Damaged(f"lz4: {exc}") from exc
            return b""
        if complete and len(out) != size:
            raise _Damaged(f"lz4 chunk decompressed to {len(out)} bytes, header says {size}")
        return out
    raise _Damaged(f"unsupported chunk compression {compression!r} (supported: '', zstd, lz4)")


# ----------------------------------------------------------------------------- decoding
def _gather(buf, offs, width):
    """Rows ``buf[offs[k] : offs[k] + width]`` as an (n, width) uint8 array."""
    return buf[offs[:, None] + np.arange(width)[None, :]]


def _cdr_header_fields(buf, offs, lens):
    """Common CDR prefix: endianness, stamp, frame_id length.

    Returns (ok, little, sec, nsec, flen) arrays; ``ok`` False for payloads too short or with a
    non-CDR encapsulation.
    """
    n = len(offs)
    ok = lens >= 16
    little = np.ones(n, bool)
    sec = np.zeros(n, np.int64)
    nsec = np.zeros(n, np.int64)
    flen = np.zeros(n, np.int64)
    if not ok.any():
        return ok, little, sec, nsec, flen
    g = _gather(buf, offs[ok], 16)
    enc = g[:, 1]
    good = (g[:, 0] == 0) & ((enc == 0) | (enc == 1))
    lit = enc == 1
    body = np.ascontiguousarray(g[:, 4:16])
    le = body.view("<i4")  # (m, 3): sec, nsec, frame_id length
    be = body.view(">i4")
    s = np.where(lit, le[:, 0], be[:, 0]).astype(np.int64)
    ns = np.where(lit, le[:, 1].view("<u4"), be[:, 1].view(">u4")).astype(np.int64)
    fl = np.where(lit, le[:, 2].view("<u4"), be[:, 2].view(">u4")).astype(np.int64)
    idx = np.flatnonzero(ok)
    ok[idx] = good
    little[idx] = lit
    sec[idx], nsec[idx], flen[idx] = s, ns, fl
    return ok, little, sec, nsec, flen


def _align(p, a):
    return (p + a - 1) // a * a


def _decode_ros2(kind, buf, offs, lens, logt):
    """Bulk-decode ROS 2 CDR messages of one channel from one buffer.

    The layout is fixed once the frame_id length and byte order are known, so messages are
    grouped by (byte order, frame_id length) and each group is one numpy gather.

    Parameters
    ----------
    kind : {"imu", "navsatfix", "pointstamped"}
    buf : ndarray of uint8
    offs, lens : ndarray of int64, shape (n,)
        Payload offsets and lengths in ``buf``.
    logt : ndarray of int64, shape (n,)
        MCAP log times (fallback when header.stamp is zero).
    """
    ok, little, sec, nsec, flen = _cdr_header_fields(buf, offs, lens)
    # payload byte offsets (from encapsulation start) of the float64 fields we need
    base = 4 + _align(12 + flen, 8)  # first 8-aligned position after frame_id
    if kind == "imu":
        need = base + 296
        fields = {"angular_rate": (104, 3), "specific_force": (200, 3)}
    elif kind == "pointstamped":
        need = base + 24
        fields = {"point": (0, 3)}
    else:  # navsatfix: status int8, service uint16 (2-aligned), then float64s (8-aligned)
        base = 4 + _align(_align(12 + flen + 1, 2) + 2, 8)
        need = base + 97
        fields = {"lat_deg": (0, 1), "lon_deg": (8, 1), "height": (16, 1)}
    ok &= (lens >= need) & (flen < 1 << 20)
    keep = np.flatnonzero(ok)
    n = len(keep)
    out = {k: np.zeros((n, w)) for k, (o, w) in fields.items()}
    if n:
        key = base[keep] * 2 + little[keep]  # one group per (frame_id layout, byte order)
        if (key == key[0]).all():  # the usual case: one fixed layout for the whole batch
            keys, inv = key[:1], np.zeros(n, np.int64)
        else:
            keys, inv = np.unique(key, return_inverse=True)
        for gi, k in enumerate(keys):
            b0, lit = int(k) // 2, bool(k % 2)
            sel = np.flatnonzero(inv == gi) if len(keys) > 1 else np.arange(n)
            o = offs[keep[sel]]
            for name, (rel, w) in fields.items():
                rows = np.ascontiguousarray(_gather(buf, o + b0 + rel, 8 * w))
                out[name][sel] = rows.view("<f8" if lit else ">f8").reshape(len(sel), w)
    t = sec[keep] * 1_000_000_000 + nsec[keep]
    zero = (sec[keep] == 0) & (nsec[keep] == 0)
    t = np.where(zero, logt[keep], t)
    values = {}
    if kind == "imu":
        values = {"specific_force": out["specific_force"], "angular_rate": out["angular_rate"]}
    elif kind == "pointstamped":
        values = {"height": out["point"][:, 2].copy()}
    else:
        values = {k: out[k][:, 0].copy() for k in ("lat_deg", "lon_deg", "height")}
    return DecodedBlock(t, values, int(zero.sum()), int(len(offs) - n), [], logt[keep])


def _get_path(obj, path):
    for part in path.split("."):
        if not isinstance(obj, dict) or part not in obj:
            raise KeyError(path)
        obj = obj[part]
    return obj


def _as_float(v):
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise TypeError
    return float(v)


def _column(objs, spec):
    """``[obj[spec] for obj in objs]`` as an ndarray, or None if any is missing/non-numeric."""
    if "." in spec:
        col = [_get_path(o, spec) for o in objs]
    else:
        col = [o[spec] for o in objs]
    try:
        a = np.array(col)
    except ValueError:  # ragged lists (numpy >= 1.24 refuses them): the per-message path
        return None
    if a.dtype.kind not in "fi":  # strings, bools, None, ragged lists, huge ints: slow path
        return None
    return a


def _decode_json_fast(objs, fields, mapping, logt):
    """Column-wise extraction when every message is well formed; None -> per-message path."""
    try:
        values = {}
        for name, w in fields:
            spec = mapping[name]
            if w == 3 and isinstance(spec, list):
                cols = [_column(objs, s) for s in spec]
                if any(c is None or c.ndim != 1 for c in cols):
                    return None
                a = np.stack(cols, axis=1)
            else:
                a = _column(objs, spec)
                if a is None or a.shape != ((len(objs), 3) if w == 3 else (len(objs),)):
                    return None
            values[name] = a.astype(np.float64)
        tspec = mapping.get("time")
        if tspec:
            t = _column(objs, tspec)
            if t is None or t.dtype.kind != "i" or t.shape != (len(objs),):
                return None
            t = t.astype(np.int64)
        else:
            return DecodedBlock(np.asarray(logt, np.int64).copy(), values, len(objs), 0, [],
                                np.asarray(logt, np.int64).copy())
    except (KeyError, TypeError, IndexError):
        return None
    return DecodedBlock(t, values, 0, 0, [], np.asarray(logt, np.int64).copy())


def _decode_json(role, payloads, logt, mapping):
    """Decode JSON messages of one channel.

    ``mapping`` gives, per quantity, a dotted key path (a 3-list for vectors, or a path to a
    3-element array), and ``time`` (integer ns; missing -> log time, reported).
    """
    if role == "gradient":
        return _decode_json_gradient(payloads, logt, mapping)
    try:  # one parse for the whole batch; fall back per message if any is broken
        objs = json.loads(b"[" + b",".join(payloads) + b"]")
    except (ValueError, RecursionError):
        objs = []
        for p in payloads:
            try:
                objs.append(json.loads(p))
            except (ValueError, RecursionError):
                objs.append(None)
    fields = {"imu": (("specific_force", 3), ("angular_rate", 3)),
              "altimeter": (("height", 1),),
              "gnss": (("lat_deg", 1), ("lon_deg", 1), ("height", 1))}[role]
    fast = _decode_json_fast(objs, fields, mapping, logt)
    if fast is not None:
        return fast
    vals = {k: [] for k, _ in fields}
    times, keep_lt, lts = [], 0, []
    bad = 0
    problems = []
    for k, obj in enumerate(objs):
        try:
            row = {}
            for name, w in fields:
                spec = mapping[name]
                if w == 3:
                    if isinstance(spec, list):
                        v = [_as_float(_get_path(obj, s)) for s in spec]
                    else:
                        v = _get_path(obj, spec)
                        if not isinstance(v, list) or len(v) != 3:
                            raise TypeError
                        v = [_as_float(x) for x in v]
                else:
                    v = _as_float(_get_path(obj, spec))
                row[name] = v
            tspec = mapping.get("time")
            try:
                t = _get_path(obj, tspec) if tspec else None
            except KeyError:
                t = None
            if t is None:
                t = int(logt[k])
                keep_lt += 1
            elif isinstance(t, bool) or not isinstance(t, int):
                raise TypeError
        except (KeyError, TypeError, ValueError):
            bad += 1
            if len(problems) < 3:
                problems.append(f"message {k}: fields {dict(mapping)} not all present/numeric")
            continue
        for name, _ in fields:
            vals[name].append(row[name])
        times.append(t)
        lts.append(int(logt[k]))
    values = {}
    for name, w in fields:
        values[name] = np.array(vals[name], dtype=np.float64).reshape(-1, w) if w == 3 \
            else np.array(vals[name], dtype=np.float64)
    try:
        t_arr = np.array(times, dtype=np.int64)
    except OverflowError:
        t_arr = np.array([min(max(t, -2**63), 2**63 - 1) for t in times], dtype=np.int64)
    return DecodedBlock(t_arr, values, keep_lt, bad, problems, np.array(lts, dtype=np.int64))


#: Row-major positions of the 6 independent components ``xx, xy, xz, yy, yz, zz`` in a 3x3 tensor.
GRADIENT_UPPER = (0, 1, 2, 4, 5, 8)
_GRADIENT_EXPAND = (0, 1, 2, 1, 3, 4, 2, 4, 5)  # 6 -> row-major 9


def _decode_json_gradient(payloads, logt, mapping):
    """Decode ``gravsurvey.GravityGradient`` JSON messages.

    The tensor field holds the 6 independent components ``[xx, xy, xz, yy, yz, zz]`` or the 9
    of the full tensor row by row (then symmetry is checked at ingestion).  Returns values
    ``{"gradient": (n, 9)}`` row-major, in the file's unit (Eotvos unless configured).
    """
    rows, times, lts, bad, problems, keep_lt = [], [], [], 0, [], 0
    spec, tspec = mapping["gradient"], mapping.get("time")
    for k, p in enumerate(payloads):
        try:
            obj = json.loads(p)
            v = _get_path(obj, spec)
            if not isinstance(v, list) or len(v) not in (6, 9):
                raise TypeError
            v = [_as_float(x) for x in v]
            if len(v) == 6:
                v = [v[i] for i in _GRADIENT_EXPAND]
            try:
                t = _get_path(obj, tspec) if tspec else None
            except KeyError:
                t = None
            if t is None:
                t = int(logt[k])
                keep_lt += 1
            elif isinstance(t, bool) or not isinstance(t, int):
                raise TypeError
        except (KeyError, TypeError, ValueError, RecursionError):
            bad += 1
            if len(problems) < 3:
                problems.append(f"message {k}: field {spec!r} is not a list of 6 or 9 numbers")
            continue
        rows.append(v)
        times.append(t)
        lts.append(int(logt[k]))
    vals = {"gradient": np.array(rows, dtype=np.float64).reshape(-1, 9)}
    return DecodedBlock(np.array(times, dtype=np.int64), vals, keep_lt, bad, problems,
                        np.array(lts, dtype=np.int64))


def _concat_blocks(blocks):
    if not blocks:
        return None
    if len(blocks) == 1:
        return blocks[0]
    vals = {k: np.concatenate([b.values[k] for b in blocks]) for k in blocks[0].values}
    probs = [p for b in blocks for p in b.problems][:3]
    return DecodedBlock(np.concatenate([b.time_ns for b in blocks]), vals,
                        sum(b.log_time_used for b in blocks), sum(b.undecodable for b in blocks),
                        probs, np.concatenate([b.log_time_ns for b in blocks]),
                        np.concatenate([b.verified for b in blocks]))


def _check_values(blk, role):
    """Drop the samples of CRC-less data that fail :func:`checks.damaged_values`; count them.

    The count joins ``undecodable`` (so ingestion reports it with the other dropped messages)
    and the first problem line says why.
    """
    if blk is None or blk.verified is None or blk.verified.all() or len(blk.time_ns) == 0:
        return blk
    nbad, whys = 0, []
    # again after each drop: a corrupted run leaves corrupted neighbours, and a spike is only
    # recognised against neighbours that agree
    for _ in range(DAMAGE_CHECK_PASSES):
        bad, why = damaged_values(role, blk.time_ns, blk.log_time_ns, blk.values,
                                  ~blk.verified)
        if not bad.any():
            break
        nbad += int(bad.sum())
        whys.append(why)
        keep = ~bad
        blk.time_ns, blk.log_time_ns, blk.verified = (blk.time_ns[keep], blk.log_time_ns[keep],
                                                      blk.verified[keep])
        blk.values = {k: v[keep] for k, v in blk.values.items()}
    if not nbad:
        return blk
    blk.value_check_dropped = nbad
    blk.undecodable += nbad
    blk.problems.insert(0, f"{nbad} samples without a chunk CRC failed the damage checks "
                           f"({'; '.join(whys)})")
    return blk


# ----------------------------------------------------------------------------- the reader
DEFAULT_JSON_FIELDS = {
    "imu": {"time": "time_ns", "specific_force": "specific_force_t",
            "angular_rate": "angular_rate_t"},
    "altimeter": {"time": "time_ns", "height": "height_m"},
    "gnss": {"time": "time_ns", "lat_deg": "lat_deg", "lon_deg": "lon_deg",
             "height": "height_m"},
    "gradient": {"time": "time_ns", "gradient": "gradient_t_eotvos"},
}


def _parse_statistics(buf, p):
    mc, = struct.unpack_from("<Q", buf, p)
    t0, t1 = struct.unpack_from("<QQ", buf, p + 26)
    return {"message_count": mc, "message_start_time": t0, "message_end_time": t1}


def _summary_records(buf):
    """The summary section's records via the footer at the file's end, or None.

    Used after damage in the data section: the summary (if the file was finished) still says
    how many messages and what time span the file held, and where every chunk starts.
    """
    size = len(buf)
    foot = size - 8 - 9 - 20
    if foot < 8 or bytes(buf[size - 8:]) != MAGIC or buf[foot] != OP_FOOTER:
        return None
    (ln, s0) = struct.unpack_from("<QQ", buf, foot + 1)
    if ln != 20 or s0 == 0 or not 8 <= s0 < foot:
        return None
    n, _, _, arrs = scan_records(buf, s0, foot, stop_at_footer=True)
    return n, arrs


def _summary_statistics(buf):
    """Statistics record of the summary section, or None (see :func:`_summary_records`)."""
    rec = _summary_records(buf)
    if rec is None:
        return None
    n, arrs = rec
    for k in range(n):
        if arrs[0][k] == OP_STATISTICS and arrs[2][k] >= 42:
            return _parse_statistics(buf, int(arrs[1][k]))
    return None


@dataclass
class ChunkIndexEntry:
    """One chunk index record of the summary (times ns, offsets in bytes)."""

    start_time: int
    end_time: int
    offset: int
    length: int
    message_index_offsets: dict  # channel id -> offset of its message index record


def _chunk_index(buf):
    """Chunk index entries of the summary section sorted by offset (empty when none/damaged)."""
    rec = _summary_records(buf)
    if rec is None:
        return []
    n, arrs = rec
    out = []
    size = len(buf)
    for k in np.flatnonzero(arrs[0][:n] == OP_CHUNK_INDEX):
        p, ln = int(arrs[1][k]), int(arrs[2][k])
        if ln < 36:
            continue
        t0, t1, off, clen, mlen = struct.unpack_from("<QQQQI", buf, p)
        if 36 + mlen > ln or mlen % 10 or not 8 <= off < size or off + clen > size:
            continue
        mio = {}
        for j in range(mlen // 10):
            cid, o = struct.unpack_from("<HQ", buf, p + 36 + 10 * j)
            mio[cid] = o
        out.append(ChunkIndexEntry(t0, t1, off, clen, mio))
    out.sort(key=lambda e: e.offset)
    return out


def _message_index_count(buf, p):
    """Entries of the message index record starting at ``p`` (opcode 7), or None."""
    size = len(buf)
    if not 0 <= p <= size - 9 - 6 or buf[p] != OP_MESSAGE_INDEX:
        return None
    (ln,) = struct.unpack_from("<Q", buf, p + 1)
    if ln < 6 or p + 9 + ln > size:
        return None
    (rl,) = struct.unpack_from("<I", buf, p + 9 + 2)
    if 6 + rl > ln or rl % 16:
        return None
    return rl // 16


class _Reader:
    def __init__(self, path, buf, content, roles, json_fields, check_crc, max_record_bytes,
                 keep_raw):
        self.path = path
        self.buf = buf
        self.c = content
        self.roles = roles  # role -> topic (or None: by schema)
        self.json_fields = json_fields
        self.check_crc = check_crc
        self.max_record_bytes = max_record_bytes
        self.keep_raw = keep_raw
        self.blocks = {}
        self.lt_parts = {}
        self.n_msgs = 0
        self.last_lt = None
        self.first_lt = None
        self.chunk_end_time = None
        self.chunk_start_time = None
        self.known = np.zeros(65536, np.bool_)  # channel ids defined so far
        self.verified = False  # the records being handled passed a chunk CRC check
        self.data_end_seen = False
        self.summary_regions = []  # (region, messages read by then) after the data end
        self.preloaded_schemas, self.preloaded_channels = set(), set()  # from the summary
        self.footer_seen = False
        self.waiting = []  # regions waiting for the first log time read after them
        self.prev_op = -1
        self.unknown_records = 0
        self.chunk_content_end = None  # end offset of the last chunk's compressed records
        self.cur_chunk = None  # (start, end, messages, t0, t1) of the chunk just read
        self.cur_index_count = 0  # messages its message index records list
        self.extra_regions = []  # chunks with fewer messages than their index lists
        self.cur_range = None  # byte range of the chunk being read
        self._index = None

    # which role would decode channel cid, and how ("ros2:imu", "json:imu", ...)
    def _decoder_for(self, cid):
        ch = self.c.channels.get(cid)
        if ch is None:
            return None
        sch = self.c.schemas.get(ch.schema_id)
        name = sch.name if sch else ""
        role = None
        for r, topic in self.roles.items():
            if topic is not None and ch.topic == topic:
                role = r
                break
        if role is None:
            role = self.c.role_of_schema(cid)
        if role is None:
            return None
        enc = ch.message_encoding
        if enc == "cdr":
            if name in ROS2_IMU:
                return ("imu", "imu")
            if name in ROS2_NAVSATFIX:
                return (role if role in ("gnss", "altimeter") else "gnss", "navsatfix")
            if name in ROS2_POINTSTAMPED:
                return ("altimeter", "pointstamped")
            return None
        if enc == "json":
            return (role, "json")
        return None

    def _handle_schema(self, b, pos, ln, preload=False):
        s = _parse_schema(b, pos, ln)
        if s.id == 0:
            raise _Damaged("schema record with reserved id 0")
        old = self.c.schemas.get(s.id)
        if old is not None and s.id in self.preloaded_schemas and not preload:
            self.preloaded_schemas.discard(s.id)
            if (old.name, old.encoding, old.data) != (s.name, s.encoding, s.data):
                # two copies disagree: one is damaged; a CRC-checked or the only plausible
                # copy wins, else the summary's (first) copy stays
                take = self.verified or (_plausible_name(s.name) and not
                                         _plausible_name(old.name))
                self.c.notes.append(f"{self.path}: schema id {s.id}: the summary's copy differs "
                                    f"from the data section's; the "
                                    f"{'data section' if take else 'summary'}'s kept")
                if take:
                    self.c.schemas[s.id] = s
            return
        if old is not None and (old.name, old.encoding, old.data) != (s.name, s.encoding, s.data):
            self.c.notes.append(f"{self.path}: schema id {s.id} redefined; first kept")
            return
        if old is None and preload:
            self.preloaded_schemas.add(s.id)
        self.c.schemas.setdefault(s.id, s)

    def _handle_channel(self, b, pos, ln, preload=False):
        ch = _parse_channel(b, pos, ln)
        old = self.c.channels.get(ch.id)
        if old is not None and ch.id in self.preloaded_channels and not preload:
            self.preloaded_channels.discard(ch.id)
            if (old.topic, old.schema_id, old.message_encoding) != (
                    ch.topic, ch.schema_id, ch.message_encoding):
                # two copies disagree: one is damaged; a CRC-checked or the only plausible
                # copy wins, else the summary's (first) copy stays
                take = self.verified or (
                    _plausible_name(ch.topic) and _plausible_name(ch.message_encoding)
                    and not (_plausible_name(old.topic)
                             and _plausible_name(old.message_encoding)))
                self.c.notes.append(f"{self.path}: channel id {ch.id}: the summary's copy "
                                    "differs from the data section's; the "
                                    f"{'data section' if take else 'summary'}'s kept")
                if take:
                    self.c.channels[ch.id] = ch
            return
        if old is not None and (old.topic, old.schema_id, old.message_encoding) != (
                ch.topic, ch.schema_id, ch.message_encoding):
            self.c.notes.append(f"{self.path}: channel id {ch.id} redefined; first kept")
            return
        if old is None and preload:
            self.preloaded_channels.add(ch.id)
        self.c.channels.setdefault(ch.id, ch)
        self.known[ch.id] = True

    def _definitions(self, buf, ops, pos, lens):
        """Schema and channel records of one chunk (ids are unique per file, so definitions
        may be handled before the chunk's messages)."""
        for k in np.flatnonzero((ops == OP_SCHEMA) | (ops == OP_CHANNEL)):
            if ops[k] == OP_SCHEMA:
                self._handle_schema(buf, int(pos[k]), int(lens[k]))
            else:
                self._handle_channel(buf, int(pos[k]), int(lens[k]))

    def _messages(self, buf, ops, pos, lens, chan, logt, pubt, seq):
        """Handle the message records among ``ops`` (top level or a chunk), in bulk."""
        m = ops == OP_MESSAGE
        if not m.any():
            return
        mc, mlt = chan[m], logt[m]
        mpos = pos[m] + MESSAGE_HEADER_BYTES
        mlen = lens[m] - MESSAGE_HEADER_BYTES
        self.n_msgs += int(m.sum())
        self.last_lt = int(mlt.max()) if self.last_lt is None else max(self.last_lt, int(mlt.max()))
        self.first_lt = int(mlt.min()) if self.first_lt is None else min(self.first_lt,
                                                                           int(mlt.min()))
        for reg in self.waiting:
            reg.log_time_after_ns = int(mlt.min())
        self.waiting = []
        if self.keep_raw:
            mpt, msq = pubt[m], seq[m]
            for k in range(len(mc)):
                self.c.raw.append((int(mc[k]), int(msq[k]), int(mlt[k]), int(mpt[k]),
                                   bytes(buf[mpos[k]:mpos[k] + mlen[k]])))
        for cid in np.unique(mc):
            sel = mc == cid
            cid = int(cid)
            if cid not in self.c.channels:
                self.c.orphan_messages += int(sel.sum())
                if not self.verified and self.cur_range is not None:
                    # no CRC: an undefined channel id is more likely a damaged one
                    a, b = self.cur_range
                    self.extra_regions.append(SkippedRegion(
                        a, b, f"{int(sel.sum())} messages on undefined channel id {cid} in a "
                              "chunk without CRC (damaged channel id?)",
                        lost_messages=int(sel.sum())))
                continue
            self.c.counts[cid] = self.c.counts.get(cid, 0) + int(sel.sum())
            self.lt_parts.setdefault(cid, []).append(mlt[sel])
            dec = self._decoder_for(cid)
            if dec is None:
                continue
            role, kind = dec
            if kind == "json":
                o, ln_ = mpos[sel], mlen[sel]
                payloads = [bytes(buf[o[k]:o[k] + ln_[k]]) for k in range(len(o))]
                blk = _decode_json(role, payloads, mlt[sel], self.json_fields[role])
            else:
                blk = _decode_ros2(kind, buf, mpos[sel], mlen[sel], mlt[sel])
            blk.verified = np.full(len(blk.time_ns), self.verified)
            self.blocks.setdefault(cid, []).append((role, blk))

    def _chunk(self, b, pos, ln, complete):
        """Parse a chunk header and return its decompressed records buffer.

        Sets ``self.verified`` when the chunk's CRC was checked and matched.
        """
        end = pos + ln
        if ln < 8 * 3 + 4:
            raise _Damaged("chunk header too short")
        t_start, t_end, usize, ucrc = struct.unpack_from("<QQQI", b, pos)
        self.chunk_start_time, self.chunk_end_time = t_start, t_end
        comp, p = _str(b, pos + 28, end)
        if p + 8 > end:
            raise _Damaged("chunk records length beyond record")
        (rlen,) = struct.unpack_from("<Q", b, p)
        p += 8
        if usize > self.max_record_bytes:
            raise _Damaged(f"chunk declares {usize} uncompressed bytes, above the "
                           f"{self.max_record_bytes}-byte limit (max_record_bytes)")
        avail = end - p
        if complete and rlen > avail:
            raise _Damaged("chunk records beyond record")
        data = b[p:p + min(rlen, avail)]
        self.chunk_content_end = p + rlen
        out = _decompress(comp, data, usize, complete)
        self.verified = False
        if complete and self.check_crc and ucrc != 0:
            if zlib.crc32(out) != ucrc:
                self._rescue_definitions(np.frombuffer(out, np.uint8))
                raise _Damaged("chunk CRC mismatch")
            self.verified = True
        self.c.compressions.add(comp or "none")
        self.c.chunks += 1
        return np.frombuffer(out, np.uint8)

    def _rescue_definitions(self, cbuf):
        """Schemas and channels of a chunk that failed its CRC, for ids nothing else defines.

        Its messages are dropped, but the messages of later, intact chunks may need these
        definitions (when the summary does not repeat them); a definition that does not parse
        is ignored.
        """
        n, _, _, arrs = scan_records(cbuf, 0, len(cbuf))
        got = []
        for k in np.flatnonzero((arrs[0][:n] == OP_SCHEMA) | (arrs[0][:n] == OP_CHANNEL)):
            p, ln = int(arrs[1][k]), int(arrs[2][k])
            try:
                if arrs[0][k] == OP_SCHEMA:
                    sch = _parse_schema(cbuf, p, ln)
                    if sch.id != 0 and sch.id not in self.c.schemas:
                        self.c.schemas[sch.id] = sch
                        got.append(f"schema {sch.id} ({sch.name})")
                else:
                    ch = _parse_channel(cbuf, p, ln)
                    if ch.id not in self.c.channels:
                        self.c.channels[ch.id] = ch
                        self.known[ch.id] = True
                        got.append(f"channel {ch.id} ({ch.topic})")
            except _Damaged:
                continue
        if got:
            self.c.notes.append(f"{self.path}: definitions taken from a chunk that failed its "
                                f"CRC (its messages dropped): {', '.join(got)}")

    def _inner(self, cbuf, complete):
        n, _, status, arrs = scan_records(cbuf, 0, len(cbuf))
        if status != SCAN_OK and complete:
            raise _Damaged("inconsistent record inside a chunk")
        ops, pos, lens = arrs[0], arrs[1], arrs[2]
        self._definitions(cbuf, ops, pos, lens)
        self._messages(cbuf, ops, pos, lens, *arrs[3:])

    def _process(self, arrs, n):
        """Handle top-level records ``0..n-1`` in order (consecutive messages in bulk).

        Returns
        -------
        (k, reason) of the first record whose content is damaged, or (None, "").
        """
        buf, c = self.buf, self.c
        ops, pos, lens = arrs[0][:n], arrs[1][:n], arrs[2][:n]
        other = np.flatnonzero(ops != OP_MESSAGE)
        k = 0
        while k < n:
            op = int(ops[k])
            if op == OP_MESSAGE:
                self._close_chunk()
                i = np.searchsorted(other, k)
                j = int(other[i]) if i < len(other) else n
                self.verified = False  # top-level messages carry no CRC
                self._messages(buf, *(a[k:j] for a in arrs))
                self.prev_op = OP_MESSAGE
                k = j
                continue
            p, ln = int(pos[k]), int(lens[k])
            if op != OP_MESSAGE_INDEX:
                self._close_chunk()
            self.chunk_end_time = self.chunk_start_time = self.chunk_content_end = None
            self.cur_range = None
            prev = self.prev_op
            self.prev_op = op
            try:
                if not self.data_end_seen and op in SUMMARY_ONLY_OPS:
                    raise _Damaged(f"summary record (opcode {op}) inside the data section")
                if op == OP_MESSAGE_INDEX and prev not in (OP_CHUNK, OP_MESSAGE_INDEX):
                    raise _Damaged("message index record not after a chunk")
                if op > OP_DATA_END:
                    self.unknown_records += 1
                self.verified = False  # top-level records carry no CRC
                if op == OP_HEADER:
                    c.profile, q = _str(buf, p, p + ln)
                    c.library, _ = _str(buf, q, p + ln)
                elif op == OP_SCHEMA:
                    self._handle_schema(buf, p, ln)
                elif op == OP_CHANNEL:
                    self._handle_channel(buf, p, ln)
                elif op == OP_CHUNK:
                    before = self.n_msgs
                    self.cur_range = (p - 9, p + ln)
                    self._inner(self._chunk(buf, p, ln, True), True)
                    self.cur_chunk = (p - 9, p + ln, self.n_msgs - before,
                                      self.chunk_start_time, self.chunk_end_time)
                elif op == OP_MESSAGE_INDEX and self.cur_chunk is not None:
                    cnt = _message_index_count(buf, p - 9)
                    self.cur_index_count += cnt or 0
                elif op == OP_STATISTICS and ln >= 42:
                    c.statistics = _parse_statistics(buf, p)
                elif op == OP_DATA_END:
                    self.data_end_seen = True
                elif op == OP_FOOTER:
                    self.footer_seen = True
            except _Damaged as exc:
                return k, str(exc)
            k += 1
        return None, ""

    def _close_chunk(self):
        """After a chunk's message index records: fewer messages in the chunk than its index
        lists means damage the chunk's checks did not see (no CRC); report the chunk."""
        ch, idx = self.cur_chunk, self.cur_index_count
        self.cur_chunk, self.cur_index_count = None, 0
        if ch is None or idx <= ch[2]:
            return
        start, end, found, t0, t1 = ch
        reg = SkippedRegion(start, end, f"chunk gave {found} messages, its message index "
                                        f"records list {idx}", lost_messages=idx - found)
        if t0 is not None and t1 is not None and t0 <= t1:
            reg.lost_start_ns, reg.lost_end_ns = t0, t1
        self.extra_regions.append(reg)

    def _chunk_index(self):
        if self._index is None:
            self._index = _chunk_index(self.buf)
        return self._index

    def _resync(self, start, exclude=-1):
        """Offset where reading can resume after damage found before ``start`` (-1: none).

        The next plausible chain of records (:func:`find_resync`), or the next chunk of the
        summary's chunk index if that comes first; never ``exclude`` (the damaged record).
        """
        size = len(self.buf)
        cand = -1
        s = start
        while s < size:
            cand = find_resync(self.buf, s, size, self.known, RESYNC_MIN_CHAIN)
            if cand != exclude:
                break
            s, cand = cand + 1, -1
        for e in self._chunk_index():
            if e.offset >= start and e.offset != exclude and (cand == -1 or e.offset < cand):
                if self.buf[e.offset] == OP_CHUNK and struct.unpack_from(
                        "<Q", self.buf, e.offset + 1)[0] == e.length - 9:
                    cand = e.offset
                break
        return cand

    def _lost_in(self, region, damaged_chunk_end=None):
        """Fill in a region's lost-message count and span from the chunk index, else from the
        message index records after a damaged chunk whose own length was intact."""
        idx = [e for e in self._chunk_index()
               if e.offset < region.end and e.offset + e.length > region.start]
        counts = []
        if idx:
            for e in idx:
                counts += [_message_index_count(self.buf, o)
                           for o in e.message_index_offsets.values()]
            region.lost_start_ns = min(e.start_time for e in idx)
            region.lost_end_ns = max(e.end_time for e in idx)
        elif damaged_chunk_end is not None:
            p, size = damaged_chunk_end, len(self.buf)
            counts = []
            while p < size and self.buf[p] == OP_MESSAGE_INDEX:
                cnt = _message_index_count(self.buf, p)
                if cnt is None:
                    break
                counts.append(cnt)
                p += 9 + struct.unpack_from("<Q", self.buf, p + 1)[0]
            if not counts:
                counts = [None]
            t0, t1 = self.chunk_start_time, self.chunk_end_time
            lo = self.first_lt if self.first_lt is not None else 0
            if t0 is not None and t1 is not None and lo <= t0 <= t1:
                region.lost_start_ns, region.lost_end_ns = t0, t1
        else:
            counts = [None]
        if counts and all(x is not None for x in counts):
            region.lost_messages = int(sum(counts))

    def run(self):
        buf = self.buf
        size = len(buf)
        c = self.c
        regions = []
        tail_status, tail_at = SCAN_OK, None
        self._preload_definitions()
        pos = 8
        if size < 8 or bytes(buf[:8]) != MAGIC:
            # a damaged start: still MCAP if a chain of records follows soon, or the file
            # ends with the MCAP magic and a chain of records is found at all
            cand = find_resync(buf, 8, size, self.known, RESYNC_MIN_CHAIN) if size > 17 else -1
            if cand == -1 or (cand > DAMAGED_START_MAX and bytes(buf[size - 8:]) != MAGIC):
                raise DataError(f"{self.path}: not an MCAP file (no MCAP magic at the start)")
            regions.append(SkippedRegion(0, cand, "damaged magic at the start of the file",
                                         lost_messages=0 if cand == 8 else None))
            pos = cand
        while pos < size:
            n, endpos, status, arrs = scan_records(buf, pos, size, stop_at_footer=True,
                                                   known=self.known)
            ops, rpos = arrs[0], arrs[1]
            if status == SCAN_OK and n >= 1 and ops[n - 1] == OP_FOOTER and \
                    (arrs[2][n - 1] != 20 or endpos + 8 != size):
                # a footer must end the file (then the closing magic): a damaged opcode
                status, n, endpos = SCAN_EARLY_FOOTER, n - 1, int(rpos[n - 1]) - 9
            # a wrong length in the record before a break would make the break itself: that
            # record is handled only once it is known to be sound
            lookback = status != SCAN_OK and n >= 1 and ops[n - 1] != OP_CHUNK
            kfail, why = self._process(arrs, n - 1 if lookback else n)
            look, later = None, None
            if kfail is None and lookback:
                x = int(rpos[n - 1]) - 9
                cand = self._resync(x + 1, exclude=endpos)
                if cand != -1 and cand < endpos:  # a record chain starts inside it: damaged
                    look = (x, cand)
                else:
                    later = cand
                    k1, why = self._process([a[n - 1:n] for a in arrs], 1)
                    kfail = None if k1 is None else n - 1
            if kfail is None and look is None and status != SCAN_OK and n >= 1 and \
                    ops[n - 1] == OP_CHUNK and self.chunk_content_end is not None and \
                    self.chunk_content_end < endpos:
                # a chunk whose length field says more than its content: if records chain up
                # inside that excess, the length is damaged (the content passed its checks)
                cand = self._resync(self.chunk_content_end, exclude=endpos)
                if cand != -1 and cand < endpos:
                    look = (self.chunk_content_end, cand)
            damaged_chunk_end = None
            if kfail is not None:
                dstart = int(rpos[kfail]) - 9
                resume = -1
                if ops[kfail] == OP_CHUNK:
                    damaged_chunk_end = int(rpos[kfail] + arrs[2][kfail])
                    # its length is sound when records chain up right after it: resume there
                    # (not inside it, where an uncompressed chunk's own records would chain)
                    if damaged_chunk_end == size or _chain_at(buf, damaged_chunk_end, size,
                                                              self.known, RESYNC_MIN_CHAIN):
                        resume = damaged_chunk_end
                if resume == -1:
                    resume = self._resync(dstart + 1, exclude=dstart)
            elif look is not None:
                dstart, resume = look
                why = ("a record's declared length disagrees with the records that follow "
                       f"(break at byte {endpos}: {_SCAN_REASONS.get(status, 'bad record')})")
            elif status != SCAN_OK:
                dstart = endpos
                why = _SCAN_REASONS.get(status, "bad record")
                if status == SCAN_BEYOND_END:
                    (ln,) = struct.unpack_from("<Q", buf, endpos + 1)
                    if ln > self.max_record_bytes and ln > size:
                        why = (f"record at byte {endpos} declares {ln} bytes, more than the "
                               f"file ({size}); garbage length or truncated file")
                if status == SCAN_BEYOND_END and _opcode_at(buf, endpos) == OP_CHUNK and \
                        bytes(buf[size - 8:]) != MAGIC:
                    resume = -1  # a file cut inside a chunk: salvage the chunk's start below
                else:
                    resume = later if later is not None else self._resync(endpos + 1,
                                                                          exclude=endpos)
                tail_status, tail_at = status, endpos
            else:
                break
            reg = SkippedRegion(dstart, resume if resume != -1 else size, why, self.last_lt)
            if self.data_end_seen:
                # after the data end record: the summary section (a note in _finish unless
                # messages turn up after it, i.e. the data end record was a damaged opcode)
                self.summary_regions.append((reg, self.n_msgs))
            if resume == -1:
                reg.resumed = False
                if dstart == endpos and status == SCAN_BEYOND_END and \
                        _opcode_at(buf, endpos) == OP_CHUNK:
                    self._salvage_cut_chunk(endpos, reg)
            else:
                tail_status = SCAN_OK
            self._lost_in(reg, damaged_chunk_end)
            if self.data_end_seen:
                pass
            elif regions and regions[-1].end == reg.start:  # one stretch, found in two steps
                prev = regions[-1]
                prev.end, prev.resumed = reg.end, reg.resumed
                prev.lost_messages = (None if prev.lost_messages is None or reg.lost_messages
                                      is None else prev.lost_messages + reg.lost_messages)
                if reg.lost_end_ns is not None and prev.lost_end_ns is not None:
                    prev.lost_end_ns = max(prev.lost_end_ns, reg.lost_end_ns)
                reg = prev
            else:
                regions.append(reg)
            if resume == -1:
                break
            self.waiting = [reg]
            pos = resume
        self._finish(regions, tail_status, tail_at)
        return c

    def _preload_definitions(self):
        """Schemas and channels repeated in the summary section, if the file has one.

        Ids are unique within a file, so these are the data section's definitions; knowing
        them first keeps messages decodable when the record that first defined their channel
        is damaged.
        """
        rec = _summary_records(self.buf)
        if rec is None:
            return
        n, arrs = rec
        for k in np.flatnonzero((arrs[0][:n] == OP_SCHEMA) | (arrs[0][:n] == OP_CHANNEL)):
            try:
                if arrs[0][k] == OP_SCHEMA:
                    self._handle_schema(self.buf, int(arrs[1][k]), int(arrs[2][k]), True)
                else:
                    self._handle_channel(self.buf, int(arrs[1][k]), int(arrs[2][k]), True)
            except _Damaged:
                pass

    def _salvage_cut_chunk(self, at, region):
        """The file ends inside a chunk: keep the complete records its bytes decode to."""
        size = len(self.buf)
        (ln,) = struct.unpack_from("<Q", self.buf, at + 1)
        if ln > self.max_record_bytes and ln > size:
            return
        region.reason = "file cut inside a chunk"
        self.cur_range = (at, size)
        try:
            self.chunk_end_time = None
            cb = self._chunk(self.buf, at + 9, size - at - 9, False)
            self.verified = False
            self._inner(cb, False)
        except _Damaged:
            pass

    def _finish(self, regions, tail_status, tail_at):
        buf, c, size = self.buf, self.c, len(self.buf)
        self._close_chunk()
        for r, n_then in self.summary_regions:
            if self.n_msgs == n_then:
                # only the summary section is damaged: every data record has been read
                c.notes.append(f"{self.path}: summary section damaged at byte {r.start} "
                               f"({r.reason}); all data records were read")
            else:  # messages after it: the "data end" record was a damaged opcode
                regions.append(r)
        if self.extra_regions:
            tail = [regions.pop()] if regions and not regions[-1].resumed else []
            regions = sorted(regions + self.extra_regions, key=lambda r: r.start) + tail
        if self.unknown_records:
            c.notes.append(f"{self.path}: skipped {self.unknown_records} records with unknown "
                           "opcodes (16-255: reserved/private per the MCAP specification, or a "
                           "damaged opcode byte)")
        if not regions:
            if not self.footer_seen:
                c.notes.append(f"{self.path}: no footer (unfinished recording?); all records "
                               "read")
            elif bytes(buf[size - 8:size]) != MAGIC:
                c.notes.append(f"{self.path}: no closing magic after the footer")
        else:
            first = regions[0]
            if c.statistics is None:
                c.statistics = _summary_statistics(buf)
            info = SalvageInfo(first.start, size, first.reason, self.n_msgs, self.last_lt,
                               regions=regions)
            tail = regions[-1] if not regions[-1].resumed else None
            if c.statistics:
                info.lost_messages = max(0, c.statistics["message_count"] - self.n_msgs)
            elif all(r.lost_messages is not None for r in regions):
                info.lost_messages = sum(r.lost_messages for r in regions)
            if tail is not None:
                cet = tail.lost_end_ns if tail.lost_end_ns is not None else self.chunk_end_time
                if c.statistics:
                    info.lost_until_ns = c.statistics["message_end_time"]
                elif cet and self.last_lt is not None and cet > self.last_lt:
                    info.lost_until_ns = cet
                # cut short = the damage is the file's end and the file has no closing magic
                info.truncated = (tail_status in (SCAN_SHORT_HEADER, SCAN_BEYOND_END)
                                  and "garbage length" not in tail.reason
                                  and tail.start == tail_at
                                  and bytes(buf[size - 8:]) != MAGIC)
                read = tail.start - 8 - sum(r.end - r.start for r in regions[:-1])
                if not info.truncated and self.last_lt is not None and \
                        self.first_lt is not None and read > 0 and self.last_lt > self.first_lt:
                    # bytes per second of what was read, applied to the unread bytes
                    info.estimated_lost_s = ((size - tail.start) / read
                                             * (self.last_lt - self.first_lt) * 1e-9)
            c.salvage = info
        for cid, parts in self.lt_parts.items():
            c.log_times[cid] = np.concatenate(parts)
        for cid, blocks in self.blocks.items():
            role = blocks[0][0]
            c.decoded[cid] = _check_values(_concat_blocks([b for _, b in blocks]), role)
        if self.keep_raw:
            order = sorted(range(len(c.raw)), key=lambda i: c.raw[i][2])
            c.raw = [c.raw[i] for i in order]


_SCAN_REASONS = {SCAN_SHORT_HEADER: "file ends inside a record header",
                 SCAN_BEYOND_END: "a record's declared length runs past the end of the file",
                 SCAN_BAD_MESSAGE: "a message record shorter than its header",
                 SCAN_BAD_OPCODE: "record with opcode 0",
                 SCAN_UNKNOWN_CHANNEL: "a message on a channel no earlier record defined",
                 SCAN_EARLY_FOOTER: "a footer record before the end of the file"}


def _opcode_at(buf, p):
    """Opcode byte at ``p`` (-1 beyond the buffer)."""
    return int(buf[p]) if 0 <= p < len(buf) else -1


def read_mcap(path, *, topics=None, json_fields=None, check_crc=True,
              max_record_bytes=DEFAULT_MAX_RECORD_BYTES, keep_raw=False) -> McapContent:
    """Read an MCAP file: every message indexed, known sensor channels decoded in bulk.

    Parameters
    ----------
    path : str or Path
    topics : dict, optional
        role (``imu``, ``altimeter``, ``gnss``) -> topic.  Channels on these topics, and
        channels whose schema name identifies a role (``ROLE_SCHEMAS``), are decoded.
    json_fields : dict, optional
        Per role JSON field mapping (see ``DEFAULT_JSON_FIELDS``).
    check_crc : bool
        Verify chunk CRCs (a mismatch is damage: reading stops there).
    max_record_bytes : int
        Refuse chunks declaring more decompressed bytes than this.
    keep_raw : bool
        Also return every message's bytes (for conformance tests and small files).

    Returns
    -------
    McapContent
        ``salvage`` is set if the file was damaged; no exception for damage after the magic.

    Raises
    ------
    DataError
        File missing/unreadable or not MCAP.
    """
    path = os.fspath(path)
    topics = dict(topics or {})
    jf = {r: dict(DEFAULT_JSON_FIELDS[r]) for r in DEFAULT_JSON_FIELDS}
    for r, m in (json_fields or {}).items():
        jf[r].update(m)
    try:
        f = open(path, "rb")
    except OSError as exc:
        raise DataError(f"{path}: cannot open ({exc.strerror})") from None
    with f:
        size = os.fstat(f.fileno()).st_size
        if size == 0:
            raise DataError(f"{path}: empty file, expected an MCAP file")
        mm = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
        try:
            buf = np.frombuffer(mm, np.uint8)
            content = McapContent(path=path, raw=[] if keep_raw else None)
            _Reader(path, buf, content, topics, jf, check_crc, max_record_bytes, keep_raw).run()
            del buf
        finally:
            try:
                mm.close()
            except BufferError:  # an exported view still alive: let GC close it
                pass
    return content
