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

One module per concept (each imports only public names of the others):

- ``scan.py``: the record layer; numba kernels :func:`scan_records` and :func:`find_resync`
  (with pure-Python references), opcodes, scan status codes.
- ``records.py``: record contents; schema, channel, statistics, summary section, chunk index,
  message index counts, bounded chunk decompression; :class:`~records.DamagedRecord`.
- ``decode.py``: payloads; ROS 2 CDR in bulk, JSON, gravity gradient; :class:`DecodedBlock`,
  ``ROLE_SCHEMAS``, ``DEFAULT_JSON_FIELDS``.
- ``value_checks.py``: samples without a verified chunk CRC through the damage checks.
- ``reader.py``: :func:`read_mcap`, :class:`McapContent`, :class:`SalvageInfo`,
  :class:`SkippedRegion`.

Every name below stays importable from ``gravsurvey.io.mcap``.
"""

from gravsurvey.io.mcap.decode import (
    DEFAULT_JSON_FIELDS,
    GRADIENT_UPPER,
    ROLE_SCHEMAS,
    ROS2_IMU,
    ROS2_NAVSATFIX,
    ROS2_POINTSTAMPED,
    DecodedBlock,
)
from gravsurvey.io.mcap.reader import (
    DAMAGED_START_MAX,
    DEFAULT_MAX_RECORD_BYTES,
    RESYNC_MIN_CHAIN,
    McapContent,
    SalvageInfo,
    SkippedRegion,
    read_mcap,
)
from gravsurvey.io.mcap.records import ChannelInfo, ChunkIndexEntry, SchemaInfo
from gravsurvey.io.mcap.scan import (
    MAGIC,
    MESSAGE_HEADER_BYTES,
    NO_CHANNELS,
    OP_ATTACHMENT,
    OP_ATTACHMENT_INDEX,
    OP_CHANNEL,
    OP_CHUNK,
    OP_CHUNK_INDEX,
    OP_DATA_END,
    OP_FOOTER,
    OP_HEADER,
    OP_MESSAGE,
    OP_MESSAGE_INDEX,
    OP_METADATA,
    OP_METADATA_INDEX,
    OP_SCHEMA,
    OP_STATISTICS,
    OP_SUMMARY_OFFSET,
    SCAN_BAD_MESSAGE,
    SCAN_BAD_OPCODE,
    SCAN_BEYOND_END,
    SCAN_EARLY_FOOTER,
    SCAN_OK,
    SCAN_SHORT_HEADER,
    SCAN_UNKNOWN_CHANNEL,
    SUMMARY_ONLY_OPS,
    find_resync,
    scan_records,
)
from gravsurvey.io.mcap.value_checks import DAMAGE_CHECK_PASSES

__all__ = [
    "ChannelInfo",
    "ChunkIndexEntry",
    "DAMAGED_START_MAX",
    "DAMAGE_CHECK_PASSES",
    "DEFAULT_JSON_FIELDS",
    "DEFAULT_MAX_RECORD_BYTES",
    "DecodedBlock",
    "GRADIENT_UPPER",
    "MAGIC",
    "MESSAGE_HEADER_BYTES",
    "McapContent",
    "NO_CHANNELS",
    "OP_ATTACHMENT",
    "OP_ATTACHMENT_INDEX",
    "OP_CHANNEL",
    "OP_CHUNK",
    "OP_CHUNK_INDEX",
    "OP_DATA_END",
    "OP_FOOTER",
    "OP_HEADER",
    "OP_MESSAGE",
    "OP_MESSAGE_INDEX",
    "OP_METADATA",
    "OP_METADATA_INDEX",
    "OP_SCHEMA",
    "OP_STATISTICS",
    "OP_SUMMARY_OFFSET",
    "RESYNC_MIN_CHAIN",
    "ROLE_SCHEMAS",
    "ROS2_IMU",
    "ROS2_NAVSATFIX",
    "ROS2_POINTSTAMPED",
    "SCAN_BAD_MESSAGE",
    "SCAN_BAD_OPCODE",
    "SCAN_BEYOND_END",
    "SCAN_EARLY_FOOTER",
    "SCAN_OK",
    "SCAN_SHORT_HEADER",
    "SCAN_UNKNOWN_CHANNEL",
    "SUMMARY_ONLY_OPS",
    "SalvageInfo",
    "SchemaInfo",
    "SkippedRegion",
    "find_resync",
    "read_mcap",
    "scan_records",
]
