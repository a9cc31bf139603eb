"""The MCAP reader: :func:`read_mcap` ties scanning, record parsing, decoding and value checks.

It walks the file's top-level records in order, reads chunks, decodes the sensor channels,
and after damage resumes at the next intact record; :class:`SalvageInfo` and
:class:`SkippedRegion` say what was skipped, recovered and lost (package docstring:
:mod:`gravsurvey.io.mcap`).
"""

from __future__ import annotations

import mmap
import os
import struct
import zlib
from dataclasses import dataclass, field

import numpy as np

from gravsurvey.errors import DataError
from gravsurvey.io.mcap.decode import (
    DEFAULT_JSON_FIELDS,
    ROLE_SCHEMAS,
    concat_blocks,
    decode_json,
    decode_ros2,
    decoder_kind,
)
from gravsurvey.io.mcap.records import (
    DamagedRecord,
    chunk_index,
    decompress_chunk,
    message_index_count,
    parse_channel,
    parse_schema,
    parse_statistics,
    plausible_name,
    read_string,
    summary_records,
    summary_statistics,
)
from gravsurvey.io.mcap.scan import (
    MAGIC,
    MESSAGE_HEADER_BYTES,
    OP_CHANNEL,
    OP_CHUNK,
    OP_DATA_END,
    OP_FOOTER,
    OP_HEADER,
    OP_MESSAGE,
    OP_MESSAGE_INDEX,
    OP_SCHEMA,
    OP_STATISTICS,
    SCAN_BEYOND_END,
    SCAN_EARLY_FOOTER,
    SCAN_OK,
    SCAN_REASONS,
    SCAN_SHORT_HEADER,
    SUMMARY_ONLY_OPS,
    chain_at,
    find_resync,
    scan_records,
)
from gravsurvey.io.mcap.value_checks import check_values
from gravsurvey.utc import utc_iso

DEFAULT_MAX_RECORD_BYTES = 256 * 2**20
DAMAGED_START_MAX = 4096  # a file without closing magic is read only if records chain by here
RESYNC_MIN_CHAIN = 4  # records that must chain up for a resynchronisation point to count


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
        d = {
            "byte_start": self.start,
            "byte_end": self.end,
            "bytes": self.end - self.start,
            "reason": self.reason,
            "resumed": self.resumed,
            "lost_messages": self.lost_messages,
        }
        for k in ("log_time_before_ns", "log_time_after_ns", "lost_start_ns", "lost_end_ns"):
            v = getattr(self, k)
            d[k] = v
            d[k.replace("_ns", "_utc")] = None if v is None else utc_iso(v)
        return d

    def describe(self) -> str:
        """One clause for :meth:`SalvageInfo.describe`."""
        s = f"bytes {self.start}-{self.end} skipped ({self.reason})"
        if self.lost_start_ns is not None and self.lost_end_ns is not None:
            s += f", log time {utc_iso(self.lost_start_ns)} to {utc_iso(self.lost_end_ns)} lost"
        elif self.resumed and self.log_time_before_ns is not None and self.log_time_after_ns is not None:
            gap = (self.log_time_after_ns - self.log_time_before_ns) * 1e-9
            s += (
                f", no data between log time {utc_iso(self.log_time_before_ns)} and "
                f"{utc_iso(self.log_time_after_ns)} ({gap:.3f} s)"
            )
        if self.resumed:
            s += (
                f", {self.lost_messages} messages lost"
                if self.lost_messages is not None
                else ", messages lost: not countable"
            )
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
        regions = self.regions or [SkippedRegion(self.offset, self.file_size, self.reason, resumed=False)]
        tail = regions[-1] if not regions[-1].resumed else None
        if len(regions) == 1:
            s = (
                f"{path}: damaged at byte {self.offset} of {self.file_size} ({self.reason}); "
                f"salvaged {self.recovered} messages"
            )
        else:
            s = (
                f"{path}: damaged in {len(regions)} places, {self.bytes_skipped} of "
                f"{self.file_size} bytes skipped; salvaged {self.recovered} messages"
            )
        if tail is None or len(regions) > 1:
            s += "; " + "; ".join(r.describe() for r in regions if r.resumed)
            if self.lost_messages is not None:
                s += f"; {self.lost_messages} messages lost in all"
        if tail is None:
            return s + "; reading resumed after the damage"
        lost_bytes = self.file_size - tail.start
        if self.last_log_time_ns is not None:
            s += f" up to log time {utc_iso(self.last_log_time_ns)}"
        if self.lost_until_ns is not None and self.last_log_time_ns is not None:
            span = max(0, self.lost_until_ns - self.last_log_time_ns) * 1e-9
            s += f"; lost at least {span:.3f} s of data"
        elif self.truncated:
            s += (
                "; the file ends there (truncated or unfinished recording, no summary): the "
                "time span lost after it is unknown"
            )
        elif self.estimated_lost_s is not None:
            s += (
                f"; lost ~{self.estimated_lost_s:.3f} s ({lost_bytes} bytes unread, no summary: "
                "estimated from the data rate of the part read)"
            )
        else:
            s += f"; lost time span unknown ({lost_bytes} bytes unread, no summary)"
        if self.lost_messages is not None and len(regions) == 1:
            s += f", {self.lost_messages} messages per the summary"
        if len(regions) > 1 or tail.start != self.offset:
            s += f"; reading could not resume after byte {tail.start}"
        return s


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
        """Role (``imu``, ``altimeter``, ``gnss``, ``gradient``) that channel ``cid``'s schema
        name identifies (``ROLE_SCHEMAS``), or None."""
        name = self.schema_name(cid)
        for role, names in ROLE_SCHEMAS.items():
            if name in names:
                return role
        return None

    def schema_name(self, cid):
        """Schema name of channel ``cid`` ("" for an unknown channel, schema or schemaless)."""
        ch = self.channels.get(cid)
        sch = self.schemas.get(ch.schema_id) if ch else None
        return sch.name if sch else ""


class _Reader:
    def __init__(self, path, buf, content, roles, json_fields, check_crc, max_record_bytes, keep_raw):
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

    def _decoder_for(self, cid):
        """(role, kind) channel ``cid`` decodes as (:func:`decoder_kind`), or None; the role
        from the configured topics first, else from the schema name."""
        ch = self.c.channels.get(cid)
        if ch is None:
            return None
        role = None
        for r, topic in self.roles.items():
            if topic is not None and ch.topic == topic:
                role = r
                break
        if role is None:
            role = self.c.role_of_schema(cid)
        if role is None:
            return None
        return decoder_kind(role, self.c.schema_name(cid), ch.message_encoding)

    def _handle_schema(self, b, pos, ln, preload=False):
        s = parse_schema(b, pos, ln)
        if s.id == 0:
            raise DamagedRecord("schema record with reserved id 0")
        old = self.c.schemas.get(s.id)
        if old is not None and s.id in self.preloaded_schemas and not preload:
            self.preloaded_schemas.discard(s.id)
            if (old.name, old.encoding, old.data) != (s.name, s.encoding, s.data):
                # two copies disagree: one is damaged; a CRC-checked or the only plausible
                # copy wins, else the summary's (first) copy stays
                take = self.verified or (plausible_name(s.name) and not plausible_name(old.name))
                self.c.notes.append(
                    f"{self.path}: schema id {s.id}: the summary's copy differs "
                    f"from the data section's; the "
                    f"{'data section' if take else 'summary'}'s kept"
                )
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
        ch = parse_channel(b, pos, ln)
        old = self.c.channels.get(ch.id)
        if old is not None and ch.id in self.preloaded_channels and not preload:
            self.preloaded_channels.discard(ch.id)
            if (old.topic, old.schema_id, old.message_encoding) != (ch.topic, ch.schema_id, ch.message_encoding):
                # two copies disagree: one is damaged; a CRC-checked or the only plausible
                # copy wins, else the summary's (first) copy stays
                take = self.verified or (
                    plausible_name(ch.topic)
                    and plausible_name(ch.message_encoding)
                    and not (plausible_name(old.topic) and plausible_name(old.message_encoding))
                )
                self.c.notes.append(
                    f"{self.path}: channel id {ch.id}: the summary's copy "
                    "differs from the data section's; the "
                    f"{'data section' if take else 'summary'}'s kept"
                )
                if take:
                    self.c.channels[ch.id] = ch
            return
        if old is not None and (old.topic, old.schema_id, old.message_encoding) != (
            ch.topic,
            ch.schema_id,
            ch.message_encoding,
        ):
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
        self.first_lt = int(mlt.min()) if self.first_lt is None else min(self.first_lt, int(mlt.min()))
        for reg in self.waiting:
            reg.log_time_after_ns = int(mlt.min())
        self.waiting = []
        if self.keep_raw:
            mpt, msq = pubt[m], seq[m]
            for k in range(len(mc)):
                self.c.raw.append(
                    (int(mc[k]), int(msq[k]), int(mlt[k]), int(mpt[k]), bytes(buf[mpos[k] : mpos[k] + mlen[k]]))
                )
        for cid in np.unique(mc):
            sel = mc == cid
            cid = int(cid)
            if cid not in self.c.channels:
                self.c.orphan_messages += int(sel.sum())
                if not self.verified and self.cur_range is not None:
                    # no CRC: an undefined channel id is more likely a damaged one
                    a, b = self.cur_range
                    self.extra_regions.append(
                        SkippedRegion(
                            a,
                            b,
                            f"{int(sel.sum())} messages on undefined channel id {cid} in a "
                            "chunk without CRC (damaged channel id?)",
                            lost_messages=int(sel.sum()),
                        )
                    )
                continue
            self.c.counts[cid] = self.c.counts.get(cid, 0) + int(sel.sum())
            self.lt_parts.setdefault(cid, []).append(mlt[sel])
            dec = self._decoder_for(cid)
            if dec is None:
                continue
            role, kind = dec
            if kind == "json":
                o, ln_ = mpos[sel], mlen[sel]
                payloads = [bytes(buf[o[k] : o[k] + ln_[k]]) for k in range(len(o))]
                blk = decode_json(role, payloads, mlt[sel], self.json_fields[role])
            else:
                blk = decode_ros2(kind, buf, mpos[sel], mlen[sel], mlt[sel])
            blk.verified = np.full(len(blk.time_ns), self.verified)
            self.blocks.setdefault(cid, []).append((role, blk))

    def _chunk(self, b, pos, ln, complete):
        """Parse a chunk header and return its decompressed records buffer.

        Sets ``self.verified`` when the chunk's CRC was checked and matched.
        """
        end = pos + ln
        if ln < 8 * 3 + 4:
            raise DamagedRecord("chunk header too short")
        t_start, t_end, usize, ucrc = struct.unpack_from("<QQQI", b, pos)
        self.chunk_start_time, self.chunk_end_time = t_start, t_end
        comp, p = read_string(b, pos + 28, end)
        if p + 8 > end:
            raise DamagedRecord("chunk records length beyond record")
        (rlen,) = struct.unpack_from("<Q", b, p)
        p += 8
        if usize > self.max_record_bytes:
            raise DamagedRecord(
                f"chunk declares {usize} uncompressed bytes, above the "
                f"{self.max_record_bytes}-byte limit (max_record_bytes)"
            )
        avail = end - p
        if complete and rlen > avail:
            raise DamagedRecord("chunk records beyond record")
        data = b[p : p + min(rlen, avail)]
        self.chunk_content_end = p + rlen
        out = decompress_chunk(comp, data, usize, complete)
        self.verified = False
        if complete and self.check_crc and ucrc != 0:
            if zlib.crc32(out) != ucrc:
                self._rescue_definitions(np.frombuffer(out, np.uint8))
                raise DamagedRecord("chunk CRC mismatch")
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
                    sch = parse_schema(cbuf, p, ln)
                    if sch.id != 0 and sch.id not in self.c.schemas:
                        self.c.schemas[sch.id] = sch
                        got.append(f"schema {sch.id} ({sch.name})")
                else:
                    ch = parse_channel(cbuf, p, ln)
                    if ch.id not in self.c.channels:
                        self.c.channels[ch.id] = ch
                        self.known[ch.id] = True
                        got.append(f"channel {ch.id} ({ch.topic})")
            except DamagedRecord:
                continue
        if got:
            self.c.notes.append(
                f"{self.path}: definitions taken from a chunk that failed its "
                f"CRC (its messages dropped): {', '.join(got)}"
            )

    def _inner(self, cbuf, complete):
        n, _, status, arrs = scan_records(cbuf, 0, len(cbuf))
        if status != SCAN_OK and complete:
            raise DamagedRecord("inconsistent record inside a chunk")
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
                    raise DamagedRecord(f"summary record (opcode {op}) inside the data section")
                if op == OP_MESSAGE_INDEX and prev not in (OP_CHUNK, OP_MESSAGE_INDEX):
                    raise DamagedRecord("message index record not after a chunk")
                if op > OP_DATA_END:
                    self.unknown_records += 1
                self.verified = False  # top-level records carry no CRC
                if op == OP_HEADER:
                    c.profile, q = read_string(buf, p, p + ln)
                    c.library, _ = read_string(buf, q, p + ln)
                elif op == OP_SCHEMA:
                    self._handle_schema(buf, p, ln)
                elif op == OP_CHANNEL:
                    self._handle_channel(buf, p, ln)
                elif op == OP_CHUNK:
                    before = self.n_msgs
                    self.cur_range = (p - 9, p + ln)
                    self._inner(self._chunk(buf, p, ln, True), True)
                    self.cur_chunk = (p - 9, p + ln, self.n_msgs - before, self.chunk_start_time, self.chunk_end_time)
                elif op == OP_MESSAGE_INDEX and self.cur_chunk is not None:
                    cnt = message_index_count(buf, p - 9)
                    self.cur_index_count += cnt or 0
                elif op == OP_STATISTICS and ln >= 42:
                    c.statistics = parse_statistics(buf, p)
                elif op == OP_DATA_END:
                    self.data_end_seen = True
                elif op == OP_FOOTER:
                    self.footer_seen = True
            except DamagedRecord as exc:
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
        reg = SkippedRegion(
            start, end, f"chunk gave {found} messages, its message index records list {idx}", lost_messages=idx - found
        )
        if t0 is not None and t1 is not None and t0 <= t1:
            reg.lost_start_ns, reg.lost_end_ns = t0, t1
        self.extra_regions.append(reg)

    def _chunk_index(self):
        if self._index is None:
            self._index = chunk_index(self.buf)
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
                if (
                    self.buf[e.offset] == OP_CHUNK
                    and struct.unpack_from("<Q", self.buf, e.offset + 1)[0] == e.length - 9
                ):
                    cand = e.offset
                break
        return cand

    def _lost_in(self, region, damaged_chunk_end=None):
        """Fill in a region's lost-message count and span from the chunk index, else from the
        message index records after a damaged chunk whose own length was intact."""
        idx = [e for e in self._chunk_index() if e.offset < region.end and e.offset + e.length > region.start]
        counts = []
        if idx:
            for e in idx:
                counts += [message_index_count(self.buf, o) for o in e.message_index_offsets.values()]
            region.lost_start_ns = min(e.start_time for e in idx)
            region.lost_end_ns = max(e.end_time for e in idx)
        elif damaged_chunk_end is not None:
            p, size = damaged_chunk_end, len(self.buf)
            counts = []
            while p < size and self.buf[p] == OP_MESSAGE_INDEX:
                cnt = message_index_count(self.buf, p)
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
            if cand == -1 or (cand > DAMAGED_START_MAX and bytes(buf[size - 8 :]) != MAGIC):
                raise DataError(f"{self.path}: not an MCAP file (no MCAP magic at the start)")
            regions.append(
                SkippedRegion(0, cand, "damaged magic at the start of the file", lost_messages=0 if cand == 8 else None)
            )
            pos = cand
        while pos < size:
            n, endpos, status, arrs = scan_records(buf, pos, size, stop_at_footer=True, known=self.known)
            ops, rpos = arrs[0], arrs[1]
            if (
                status == SCAN_OK
                and n >= 1
                and ops[n - 1] == OP_FOOTER
                and (arrs[2][n - 1] != 20 or endpos + 8 != size)
            ):
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
                    k1, why = self._process([a[n - 1 : n] for a in arrs], 1)
                    kfail = None if k1 is None else n - 1
            if (
                kfail is None
                and look is None
                and status != SCAN_OK
                and n >= 1
                and ops[n - 1] == OP_CHUNK
                and self.chunk_content_end is not None
                and self.chunk_content_end < endpos
            ):
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
                    if damaged_chunk_end == size or chain_at(
                        buf, damaged_chunk_end, size, self.known, RESYNC_MIN_CHAIN
                    ):
                        resume = damaged_chunk_end
                if resume == -1:
                    resume = self._resync(dstart + 1, exclude=dstart)
            elif look is not None:
                dstart, resume = look
                why = (
                    "a record's declared length disagrees with the records that follow "
                    f"(break at byte {endpos}: {SCAN_REASONS.get(status, 'bad record')})"
                )
            elif status != SCAN_OK:
                dstart = endpos
                why = SCAN_REASONS.get(status, "bad record")
                if status == SCAN_BEYOND_END:
                    (ln,) = struct.unpack_from("<Q", buf, endpos + 1)
                    if ln > self.max_record_bytes and ln > size:
                        why = (
                            f"record at byte {endpos} declares {ln} bytes, more than the "
                            f"file ({size}); garbage length or truncated file"
                        )
                if (
                    status == SCAN_BEYOND_END
                    and _opcode_at(buf, endpos) == OP_CHUNK
                    and bytes(buf[size - 8 :]) != MAGIC
                ):
                    resume = -1  # a file cut inside a chunk: salvage the chunk's start below
                else:
                    resume = later if later is not None else self._resync(endpos + 1, exclude=endpos)
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
                if dstart == endpos and status == SCAN_BEYOND_END and _opcode_at(buf, endpos) == OP_CHUNK:
                    self._salvage_cut_chunk(endpos, reg)
            else:
                tail_status = SCAN_OK
            self._lost_in(reg, damaged_chunk_end)
            if self.data_end_seen:
                pass
            elif regions and regions[-1].end == reg.start:  # one stretch, found in two steps
                prev = regions[-1]
                prev.end, prev.resumed = reg.end, reg.resumed
                prev.lost_messages = (
                    None
                    if prev.lost_messages is None or reg.lost_messages is None
                    else prev.lost_messages + reg.lost_messages
                )
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
        rec = summary_records(self.buf)
        if rec is None:
            return
        n, arrs = rec
        for k in np.flatnonzero((arrs[0][:n] == OP_SCHEMA) | (arrs[0][:n] == OP_CHANNEL)):
            try:
                if arrs[0][k] == OP_SCHEMA:
                    self._handle_schema(self.buf, int(arrs[1][k]), int(arrs[2][k]), True)
                else:
                    self._handle_channel(self.buf, int(arrs[1][k]), int(arrs[2][k]), True)
            except DamagedRecord:
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
        except DamagedRecord:
            pass

    def _finish(self, regions, tail_status, tail_at):
        buf, c, size = self.buf, self.c, len(self.buf)
        self._close_chunk()
        for r, n_then in self.summary_regions:
            if self.n_msgs == n_then:
                # only the summary section is damaged: every data record has been read
                c.notes.append(
                    f"{self.path}: summary section damaged at byte {r.start} ({r.reason}); all data records were read"
                )
            else:  # messages after it: the "data end" record was a damaged opcode
                regions.append(r)
        if self.extra_regions:
            tail = [regions.pop()] if regions and not regions[-1].resumed else []
            regions = sorted(regions + self.extra_regions, key=lambda r: r.start) + tail
        if self.unknown_records:
            c.notes.append(
                f"{self.path}: skipped {self.unknown_records} records with unknown "
                "opcodes (16-255: reserved/private per the MCAP specification, or a "
                "damaged opcode byte)"
            )
        if not regions:
            if not self.footer_seen:
                c.notes.append(f"{self.path}: no footer (unfinished recording?); all records read")
            elif bytes(buf[size - 8 : size]) != MAGIC:
                c.notes.append(f"{self.path}: no closing magic after the footer")
        else:
            first = regions[0]
            if c.statistics is None:
                c.statistics = summary_statistics(buf)
            info = SalvageInfo(first.start, size, first.reason, self.n_msgs, self.last_lt, regions=regions)
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
                info.truncated = (
                    tail_status in (SCAN_SHORT_HEADER, SCAN_BEYOND_END)
                    and "garbage length" not in tail.reason
                    and tail.start == tail_at
                    and bytes(buf[size - 8 :]) != MAGIC
                )
                read = tail.start - 8 - sum(r.end - r.start for r in regions[:-1])
                if (
                    not info.truncated
                    and self.last_lt is not None
                    and self.first_lt is not None
                    and read > 0
                    and self.last_lt > self.first_lt
                ):
                    # bytes per second of what was read, applied to the unread bytes
                    info.estimated_lost_s = (size - tail.start) / read * (self.last_lt - self.first_lt) * 1e-9
            c.salvage = info
        for cid, parts in self.lt_parts.items():
            c.log_times[cid] = np.concatenate(parts)
        for cid, blocks in self.blocks.items():
            role = blocks[0][0]
            c.decoded[cid] = check_values(concat_blocks([b for _, b in blocks]), role)
        if self.keep_raw:
            order = sorted(range(len(c.raw)), key=lambda i: c.raw[i][2])
            c.raw = [c.raw[i] for i in order]


def _opcode_at(buf, p):
    """Opcode byte at ``p`` (-1 beyond the buffer)."""
    return int(buf[p]) if 0 <= p < len(buf) else -1


def read_mcap(
    path, *, topics=None, json_fields=None, check_crc=True, max_record_bytes=DEFAULT_MAX_RECORD_BYTES, keep_raw=False
) -> McapContent:
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
