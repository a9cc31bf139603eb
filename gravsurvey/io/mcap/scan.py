"""MCAP record scanning and resynchronisation: numba kernels with pure-numpy/Python references.

The record layer of the MCAP format (opcode byte, little-endian uint64 content length, content)
walked linearly over a byte buffer, never trusting a declared length beyond the bytes that are
really there; and, after damage, the search for the next offset where a chain of plausible
records starts (:func:`find_resync`).  The references (``use_kernel=False``) give the same
outputs as the kernels and exist for the tests.
"""

from __future__ import annotations

import struct

import numba
import numpy as np

MAGIC = b"\x89MCAP0\r\n"
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK = 1, 2, 3, 4, 5, 6
OP_MESSAGE_INDEX, OP_CHUNK_INDEX, OP_ATTACHMENT, OP_ATTACHMENT_INDEX = 7, 8, 9, 10
OP_STATISTICS, OP_METADATA, OP_METADATA_INDEX, OP_SUMMARY_OFFSET, OP_DATA_END = 11, 12, 13, 14, 15
MESSAGE_HEADER_BYTES = 2 + 4 + 8 + 8  # channel_id, sequence, log_time, publish_time

# scan status codes (kernel and reference agree on them)
SCAN_OK = 0  # ended exactly at ``end`` or after a footer
SCAN_SHORT_HEADER = 1  # fewer than 9 bytes left for an opcode + length
SCAN_BEYOND_END = 2  # a record's declared length runs past ``end``
SCAN_BAD_MESSAGE = 3  # a message record shorter than its fixed 22-byte header
SCAN_BAD_OPCODE = 4  # opcode 0; or > 0x0F inside a chunk (not forward-compatible there)
SCAN_UNKNOWN_CHANNEL = 5  # a top-level message on a channel id no earlier record defined
SCAN_EARLY_FOOTER = 6  # (reader only) a footer record that does not end the file
# records that belong in the summary section only (a sign of damage before the data end)
SUMMARY_ONLY_OPS = (OP_CHUNK_INDEX, OP_ATTACHMENT_INDEX, OP_STATISTICS, OP_METADATA_INDEX, OP_SUMMARY_OFFSET)


@numba.njit(cache=True)
def _u64(buf, i):
    v = np.uint64(0)
    for k in range(8):
        v |= np.uint64(buf[i + k]) << np.uint64(8 * k)
    return v


@numba.njit(cache=True)
def _scan_kernel(
    buf, start, end, stop_at_footer, known_in, check_chan, fill, opcodes, rec_pos, rec_len, chan, logt, pubt, seq
):
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
                seq[n] = (
                    np.int64(buf[c + 2])
                    | (np.int64(buf[c + 3]) << 8)
                    | (np.int64(buf[c + 4]) << 16)
                    | (np.int64(buf[c + 5]) << 24)
                )
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
    buf : ndarray of uint8
    start, end : int
        Byte range to walk (``start`` at an opcode byte).
    stop_at_footer : bool
        Top level (True) or inside a chunk (False): see :func:`_scan_kernel`.
    use_kernel : bool
        False: the pure-Python reference (same outputs; for tests).
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
    n, pos, status = _scan_kernel(buf, start, end, stop_at_footer, known, check, False, z, z, z, z, z, z, z)
    arrs = [np.zeros(n, np.int64) for _ in range(7)]
    _scan_kernel(buf, start, end, stop_at_footer, known, check, True, *arrs)
    return n, pos, status, arrs


@numba.njit(cache=True)
def chain_at(buf, p, end, known, min_chain):
    """Does a chain of plausible top-level records start at ``p``?

    Plausible: opcode 1..15, length inside ``end``, a message at least 22 bytes long on a
    channel defined earlier (``known``), a footer only as the last record before the closing
    magic.  The chain counts when ``min_chain`` records follow one another, or at least one
    does and the chain ends exactly at ``end``, or with a record cut by ``end`` (a truncated
    file), or at the footer.

    Parameters
    ----------
    buf : ndarray of uint8
    p, end : int
        Candidate offset of an opcode byte; end of the readable bytes.
    known : ndarray of bool, shape (65536,)
        Channel ids defined so far.
    min_chain : int
        Records that must follow one another.

    Returns
    -------
    bool
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
    """First offset >= ``start`` where :func:`chain_at` holds (and, if ``opcode`` > 0, whose
    record has that opcode); -1 when none."""
    for p in range(start, end - 8):
        op = buf[p]
        if op == 0 or op > 15 or (opcode > 0 and op != opcode):
            continue
        if chain_at(buf, p, end, known, min_chain):
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
            if op == OP_MESSAGE and (length < MESSAGE_HEADER_BYTES or struct.unpack_from("<H", b, p + 9)[0] not in ids):
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


#: Why a scan stopped (``SCAN_*`` code -> reason in salvage reports).
SCAN_REASONS = {
    SCAN_SHORT_HEADER: "file ends inside a record header",
    SCAN_BEYOND_END: "a record's declared length runs past the end of the file",
    SCAN_BAD_MESSAGE: "a message record shorter than its header",
    SCAN_BAD_OPCODE: "record with opcode 0",
    SCAN_UNKNOWN_CHANNEL: "a message on a channel no earlier record defined",
    SCAN_EARLY_FOOTER: "a footer record before the end of the file",
}
