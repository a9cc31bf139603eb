"""MCAP record parsing: schema, channel, statistics, summary section, chunk index, chunk content.

Every parser checks each length against the record's own bytes and raises
:class:`DamagedRecord` (never an IndexError or a struct error) when the content is inconsistent;
the reader turns that into salvage.  Times are integer ns since the Unix epoch, offsets bytes.
"""

from __future__ import annotations

import io
import struct
from dataclasses import dataclass

import numpy as np

from gravsurvey.io.mcap.scan import MAGIC, OP_CHUNK_INDEX, OP_FOOTER, OP_MESSAGE_INDEX, OP_STATISTICS, scan_records


class DamagedRecord(Exception):
    """A record's content is inconsistent with its own lengths or checks.

    Raised by the parsers of this module and by the reader's chunk handling; the reader
    always catches it and turns it into a :class:`~gravsurvey.io.mcap.reader.SkippedRegion`
    (its message is the region's reason), so it never reaches the user.
    """


def read_string(b, pos, end):
    """An MCAP string (uint32 byte length, UTF-8 bytes) at ``pos``, within ``end``.

    Parameters
    ----------
    b : buffer (bytes or ndarray of uint8)
    pos, end : int
        Byte offset of the length prefix; offset the string must end by (the record's end).

    Returns
    -------
    text : str
    next_pos : int
        Offset just after the string.

    Raises
    ------
    DamagedRecord
        The string runs beyond ``end`` or is not UTF-8.
    """
    if pos + 4 > end:
        raise DamagedRecord("string length beyond record")
    (n,) = struct.unpack_from("<I", b, pos)
    if pos + 4 + n > end:
        raise DamagedRecord("string beyond record")
    try:
        return bytes(b[pos + 4 : pos + 4 + n]).decode("utf-8"), pos + 4 + n
    except UnicodeDecodeError as exc:
        raise DamagedRecord("string not UTF-8") from exc


def _bytes32(b, pos, end):
    if pos + 4 > end:
        raise DamagedRecord("byte array length beyond record")
    (n,) = struct.unpack_from("<I", b, pos)
    if pos + 4 + n > end:
        raise DamagedRecord("byte array beyond record")
    return bytes(b[pos + 4 : pos + 4 + n]), pos + 4 + n


def plausible_name(s):
    """A topic/schema name/encoding that could be real: non-empty, printable.

    Parameters
    ----------
    s : str

    Returns
    -------
    bool
    """
    return bool(s) and s.isprintable()


def parse_schema(b, pos, ln):
    """Schema record whose content is ``b[pos:pos + ln]``.

    Parameters
    ----------
    b : buffer (bytes or ndarray of uint8)
    pos, ln : int
        Content offset and length in bytes (after the opcode and length field).

    Returns
    -------
    SchemaInfo

    Raises
    ------
    DamagedRecord
        A field runs beyond the record or a string is not UTF-8.
    """
    end = pos + ln
    if ln < 2:
        raise DamagedRecord("schema record too short")
    (sid,) = struct.unpack_from("<H", b, pos)
    name, p = read_string(b, pos + 2, end)
    enc, p = read_string(b, p, end)
    data, p = _bytes32(b, p, end)
    return SchemaInfo(sid, name, enc, data)


def parse_channel(b, pos, ln):
    """Channel record whose content is ``b[pos:pos + ln]`` (arguments as :func:`parse_schema`).

    Returns a :class:`ChannelInfo`; raises :class:`DamagedRecord` when a field or the metadata
    map runs beyond the record, or a string is not UTF-8.
    """
    end = pos + ln
    if ln < 4:
        raise DamagedRecord("channel record too short")
    cid, sid = struct.unpack_from("<HH", b, pos)
    topic, p = read_string(b, pos + 4, end)
    enc, p = read_string(b, p, end)
    if p + 4 > end:
        raise DamagedRecord("channel metadata beyond record")
    (mlen,) = struct.unpack_from("<I", b, p)
    p += 4
    mend = p + mlen
    if mend > end:
        raise DamagedRecord("channel metadata beyond record")
    meta = {}
    while p < mend:
        k, p = read_string(b, p, mend)
        v, p = read_string(b, p, mend)
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


def decompress_chunk(compression, data, size, complete):
    """Decompress one chunk's records, never producing more than ``size`` bytes.

    Parameters
    ----------
    compression : str
        The chunk's compression field: ``""``, ``"zstd"`` or ``"lz4"``.
    data : buffer
        The chunk's compressed records (sliced from the file, not copied).
    size : int
        Uncompressed size in bytes the chunk header declares (the caller has checked it
        against ``max_record_bytes``).
    complete : bool
        False: the chunk was cut by the end of the file; return what the available bytes
        decode to (possibly less than ``size``).

    Returns
    -------
    bytes

    Raises
    ------
    DamagedRecord
        Unsupported compression, a corrupt stream, or (``complete``) a size other than
        ``size``.
    """
    if compression == "":
        if complete and len(data) != size:
            raise DamagedRecord(f"uncompressed chunk holds {len(data)} bytes, header says {size}")
        return bytes(data[:size])
    if compression == "zstd":
        import zstandard

        reader = zstandard.ZstdDecompressor().stream_reader(io.BytesIO(data), read_across_frames=True)
        if complete:
            try:
                out = reader.read(size + 1) if size else b""
            except zstandard.ZstdError as exc:
                raise DamagedRecord(f"zstd: {exc}") from exc
            if len(out) != size:
                raise DamagedRecord(f"zstd chunk decompressed to {len(out)} bytes, header says {size}")
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
                raise DamagedRecord(f"lz4: {exc}") from exc
            return b""
        if complete and len(out) != size:
            raise DamagedRecord(f"lz4 chunk decompressed to {len(out)} bytes, header says {size}")
        return out
    raise DamagedRecord(f"unsupported chunk compression {compression!r} (supported: '', zstd, lz4)")


def parse_statistics(buf, p):
    """Statistics record content at ``p`` (at least 42 bytes: the caller checks).

    Parameters
    ----------
    buf : buffer
    p : int
        Content offset.

    Returns
    -------
    dict
        ``message_count``, ``message_start_time`` and ``message_end_time`` (ns since the
        Unix epoch).
    """
    (mc,) = struct.unpack_from("<Q", buf, p)
    t0, t1 = struct.unpack_from("<QQ", buf, p + 26)
    return {"message_count": mc, "message_start_time": t0, "message_end_time": t1}


def summary_records(buf):
    """The summary section's records via the footer at the file's end, or None.

    Used after damage in the data section: the summary (if the file was finished) still says
    how many messages and what time span the file held, and where every chunk starts.

    Parameters
    ----------
    buf : ndarray of uint8
        The whole file.

    Returns
    -------
    (n, arrays) or None
        As :func:`~gravsurvey.io.mcap.scan.scan_records` over the summary section; None when
        the file has no intact footer, closing magic or summary offset.
    """
    size = len(buf)
    foot = size - 8 - 9 - 20
    if foot < 8 or bytes(buf[size - 8 :]) != MAGIC or buf[foot] != OP_FOOTER:
        return None
    (ln, s0) = struct.unpack_from("<QQ", buf, foot + 1)
    if ln != 20 or s0 == 0 or not 8 <= s0 < foot:
        return None
    n, _, _, arrs = scan_records(buf, s0, foot, stop_at_footer=True)
    return n, arrs


def summary_statistics(buf):
    """Statistics record of the summary section of the file ``buf`` (ndarray of uint8).

    Returns the dict of :func:`parse_statistics`, or None when the file has no readable summary
    (see :func:`summary_records`) or no statistics record in it.
    """
    rec = summary_records(buf)
    if rec is None:
        return None
    n, arrs = rec
    for k in range(n):
        if arrs[0][k] == OP_STATISTICS and arrs[2][k] >= 42:
            return parse_statistics(buf, int(arrs[1][k]))
    return None


@dataclass
class ChunkIndexEntry:
    """One chunk index record of the summary (times ns, offsets in bytes)."""

    start_time: int
    end_time: int
    offset: int
    length: int
    message_index_offsets: dict  # channel id -> offset of its message index record


def chunk_index(buf):
    """Chunk index entries of the summary section sorted by offset (empty when none/damaged).

    ``buf`` is the whole file (ndarray of uint8); returns a list of :class:`ChunkIndexEntry`,
    only those whose offsets and lengths lie inside the file.
    """
    rec = summary_records(buf)
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


def message_index_count(buf, p):
    """Entries of the message index record starting at ``p`` (opcode 7), or None.

    Parameters
    ----------
    buf : ndarray of uint8
        The whole file.
    p : int
        Offset of the record's opcode byte.

    Returns
    -------
    int or None
        Messages the record lists; None when there is no sound message index record at ``p``.
    """
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
