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

Salvage: reading stops at the first damaged record (length beyond end of file, absurd length,
failed decompression, CRC mismatch, bad opcode inside a chunk); everything before it is kept; a
chunk cut by the end of the file is decompressed as far as its bytes go and its complete
message records are kept.  :class:`SalvageInfo` says what was recovered and lost.
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
SCAN_BAD_OPCODE = 4  # opcode 0 or > 0x0F inside a chunk (not forward-compatible there)

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
def _scan_kernel(buf, start, end, stop_at_footer, fill, opcodes, rec_pos, rec_len,
                 chan, logt, pubt, seq):
    """Walk MCAP records in ``buf[start:end]``.

    Parameters
    ----------
    buf : ndarray of uint8
    start, end : int
        Byte range to walk.
    stop_at_footer : bool
        Stop after a footer record (top level).
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
        if not stop_at_footer and (op == 0 or op > 15):
            status = 4
            break
        if fill:
            opcodes[n] = op
            rec_pos[n] = pos + 9
            rec_len[n] = ln
            if op == 5:
                c = pos + 9
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


def _scan_reference(buf, start, end, stop_at_footer):
    """Pure-Python reference of :func:`_scan_kernel` (same outputs); for tests."""
    b = bytes(buf)
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
        if not stop_at_footer and (op == 0 or op > 15):
            status = SCAN_BAD_OPCODE
            break
        c = pos + 9
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


def scan_records(buf, start, end, stop_at_footer=False, use_kernel=True):
    """Index the MCAP records in ``buf[start:end]`` (numba kernel, two passes).

    Returns
    -------
    n, pos, status : int
        See :func:`_scan_kernel`.
    arrays : list of ndarray, each shape (n,), int64
        opcodes, content offsets, content lengths, channel ids, log times, publish times,
        sequences.
    """
    if not use_kernel:
        return _scan_reference(buf, start, end, stop_at_footer)
    z = np.zeros(0, np.int64)
    n, pos, status = _scan_kernel(buf, start, end, stop_at_footer, False, z, z, z, z, z, z, z)
    arrs = [np.zeros(n, np.int64) for _ in range(7)]
    _scan_kernel(buf, start, end, stop_at_footer, True, *arrs)
    return n, pos, status, arrs


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
class SalvageInfo:
    """What a damaged or truncated file gave back.

    Attributes
    ----------
    offset : int
        Byte offset of the first damaged/incomplete record.
    file_size : int
        Bytes in the file.
    reason : str
        What was wrong there.
    recovered : int
        Messages recovered (all channels).
    last_log_time_ns : int or None
        Latest log time recovered.
    lost_until_ns : int or None
        Latest log time known to exist (summary statistics or the damaged chunk's header);
        None when unknown.
    lost_messages : int or None
        Messages known to be lost (from summary statistics), None when unknown.
    estimated_lost_s : float or None
        Unread bytes / bytes per second of the part read: a rough lost span when the damage
        is followed by unreadable bytes and the file has no summary.
    truncated : bool
        The damage is the end of the file (a record cut short).
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

    def describe(self, path) -> str:
        """One line for warnings and notes."""
        lost_bytes = self.file_size - self.offset
        s = (f"{path}: damaged at byte {self.offset} of {self.file_size} ({self.reason}); "
             f"salvaged {self.recovered} messages")
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
        if self.lost_messages is not None:
            s += f", {self.lost_messages} messages per the summary"
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
    a = np.array(col)
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
                        probs, np.concatenate([b.log_time_ns for b in blocks]))


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


def _summary_statistics(buf):
    """Statistics from the summary section via the footer at the file's end, or None.

    Used after damage in the data section: the summary (if the file was finished) still says
    how many messages and what time span the file held.
    """
    size = len(buf)
    foot = size - 8 - 9 - 20
    if foot < 8 or bytes(buf[size - 8:]) != MAGIC or buf[foot] != OP_FOOTER:
        return None
    (ln, s0) = struct.unpack_from("<QQ", buf, foot + 1)
    if ln != 20 or s0 == 0 or not 8 <= s0 < foot:
        return None
    n, _, _, arrs = scan_records(buf, s0, foot, stop_at_footer=True)
    for k in range(n):
        if arrs[0][k] == OP_STATISTICS and arrs[2][k] >= 42:
            return _parse_statistics(buf, int(arrs[1][k]))
    return None


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

    def _handle_schema(self, b, pos, ln):
        s = _parse_schema(b, pos, ln)
        if s.id == 0:
            raise _Damaged("schema record with reserved id 0")
        old = self.c.schemas.get(s.id)
        if old is not None and (old.name, old.encoding, old.data) != (s.name, s.encoding, s.data):
            self.c.notes.append(f"{self.path}: schema id {s.id} redefined; first kept")
            return
        self.c.schemas.setdefault(s.id, s)

    def _handle_channel(self, b, pos, ln):
        ch = _parse_channel(b, pos, ln)
        old = self.c.channels.get(ch.id)
        if old is not None and (old.topic, old.schema_id, old.message_encoding) != (
                ch.topic, ch.schema_id, ch.message_encoding):
            self.c.notes.append(f"{self.path}: channel id {ch.id} redefined; first kept")
            return
        self.c.channels.setdefault(ch.id, ch)

    def _messages(self, buf, ops, pos, lens, chan, logt, pubt, seq):
        """Handle schema/channel/message records of one buffer (top level or a chunk)."""
        b = buf
        for k in np.flatnonzero((ops == OP_SCHEMA) | (ops == OP_CHANNEL)):
            # schemas/channels precede their messages; handle them in order with messages by
            # processing definitions first (allowed: ids are unique per file)
            if ops[k] == OP_SCHEMA:
                self._handle_schema(b, int(pos[k]), int(lens[k]))
            else:
                self._handle_channel(b, int(pos[k]), int(lens[k]))
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
            self.blocks.setdefault(cid, []).append(blk)

    def _chunk(self, b, pos, ln, complete):
        """Parse a chunk header and return its decompressed records buffer."""
        end = pos + ln
        if ln < 8 * 3 + 4:
            raise _Damaged("chunk header too short")
        t_start, t_end, usize, ucrc = struct.unpack_from("<QQQI", b, pos)
        self.chunk_end_time = t_end
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
        out = _decompress(comp, data, usize, complete)
        if complete and self.check_crc and ucrc != 0 and zlib.crc32(out) != ucrc:
            raise _Damaged("chunk CRC mismatch")
        self.c.compressions.add(comp or "none")
        self.c.chunks += 1
        return np.frombuffer(out, np.uint8)

    def _inner(self, cbuf, complete):
        n, _, status, arrs = scan_records(cbuf, 0, len(cbuf))
        ops, pos, lens = arrs[0], arrs[1], arrs[2]
        self._messages(cbuf, ops, pos, lens, *arrs[3:])
        if status != SCAN_OK and complete:
            raise _Damaged("inconsistent record inside a chunk")

    def run(self):
        buf = self.buf
        size = len(buf)
        c = self.c
        if size < 8 or bytes(buf[:8]) != MAGIC:
            raise DataError(f"{self.path}: not an MCAP file (no MCAP magic at the start)")
        n, endpos, status, arrs = scan_records(buf, 8, size, stop_at_footer=True)
        ops, pos, lens = arrs[0], arrs[1], arrs[2]
        damage_at = None
        reason = ""
        footer_seen = False
        # process top-level records in order; consecutive message records go in bulk
        other = np.flatnonzero(~np.isin(ops, (OP_MESSAGE, OP_SCHEMA, OP_CHANNEL)))
        k = 0
        try:
            while k < n:
                op = ops[k]
                if op == OP_MESSAGE:
                    # the run of message/schema/channel records starting here, in one batch
                    i = np.searchsorted(other, k)
                    j = int(other[i]) if i < len(other) else n
                    self._messages(buf, *(a[k:j] for a in arrs))
                    k = j
                    continue
                p, ln = int(pos[k]), int(lens[k])
                rec_start = p - 9
                self.chunk_end_time = None  # set by _chunk from this record's header
                try:
                    if op == OP_HEADER:
                        c.profile, q = _str(buf, p, p + ln)
                        c.library, _ = _str(buf, q, p + ln)
                    elif op in (OP_SCHEMA, OP_CHANNEL):
                        self._messages(buf, *(a[k:k + 1] for a in arrs))
                    elif op == OP_CHUNK:
                        self._inner(self._chunk(buf, p, ln, True), True)
                    elif op == OP_STATISTICS and ln >= 42:
                        c.statistics = _parse_statistics(buf, p)
                    elif op == OP_FOOTER:
                        footer_seen = True
                except _Damaged as exc:
                    damage_at, reason = rec_start, str(exc)
                    break
                k += 1
        except _Damaged as exc:
            damage_at, reason = int(pos[k]) - 9, str(exc)
        if damage_at is None and status != SCAN_OK:
            damage_at = endpos
            reason = {SCAN_SHORT_HEADER: "file ends inside a record header",
                      SCAN_BEYOND_END: "a record's declared length runs past the end of the file",
                      SCAN_BAD_MESSAGE: "a message record shorter than its header"}.get(
                status, "bad record")
            if status == SCAN_BEYOND_END:
                op = buf[endpos]
                (ln,) = struct.unpack_from("<Q", buf, endpos + 1)
                if ln > self.max_record_bytes and ln > size:
                    reason = (f"record at byte {endpos} declares {ln} bytes, more than the file "
                              f"({size}); garbage length or truncated file")
                elif op == OP_CHUNK:
                    reason = "file cut inside a chunk"
                    try:  # salvage the complete records of the cut chunk
                        self.chunk_end_time = None
                        cb = self._chunk(buf, endpos + 9, size - endpos - 9, False)
                        self._inner(cb, False)
                    except _Damaged:
                        pass
        elif damage_at is None and not footer_seen:
            c.notes.append(f"{self.path}: no footer (unfinished recording?); all records read")
        elif damage_at is None and bytes(buf[endpos:endpos + 8]) != MAGIC:
            c.notes.append(f"{self.path}: no closing magic after the footer")
        if damage_at is not None:
            if c.statistics is None:
                c.statistics = _summary_statistics(buf)
            info = SalvageInfo(damage_at, size, reason, self.n_msgs, self.last_lt)
            cet = self.chunk_end_time
            if c.statistics:
                info.lost_until_ns = c.statistics["message_end_time"]
                info.lost_messages = max(0, c.statistics["message_count"] - self.n_msgs)
            elif cet and self.last_lt is not None and cet > self.last_lt:
                info.lost_until_ns = cet
            # cut short = the damage is the file's end and the file has no closing magic
            truncated = status in (SCAN_SHORT_HEADER, SCAN_BEYOND_END) and \
                "garbage length" not in reason and damage_at == endpos and \
                bytes(buf[size - 8:]) != MAGIC
            info.truncated = truncated
            if not truncated and self.last_lt is not None and self.first_lt is not None \
                    and damage_at > 8 and self.last_lt > self.first_lt:
                # bytes per second of what was read, applied to the unread bytes
                info.estimated_lost_s = ((size - damage_at) / damage_at
                                         * (self.last_lt - self.first_lt) * 1e-9)
            c.salvage = info
        for cid, parts in self.lt_parts.items():
            c.log_times[cid] = np.concatenate(parts)
        for cid, blocks in self.blocks.items():
            c.decoded[cid] = _concat_blocks(blocks)
        if self.keep_raw:
            order = sorted(range(len(c.raw)), key=lambda i: c.raw[i][2])
            c.raw = [c.raw[i] for i in order]
        return c


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
