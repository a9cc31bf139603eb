"""Deliverables: profile CSV, Geosoft XYZ, GeoJSON lines, JSON summary, crossover CSV;
atomic output directory updates and the output-directory lock.

Every writer writes to ``<path>.tmp-<pid>`` and renames it onto ``path`` (``os.replace``), so a
file never appears half-written under its final name even outside an :class:`OutputTransaction`.
The formats are documented in docs/outputs.md; this package is their single source.

Profile table
-------------
A dict of equal-length 1-D numpy arrays with the columns of :data:`PROFILE_COLUMNS` and
optionally :data:`TRUTH_COLUMNS`. ``time_utc`` may be omitted and is ignored if given: it is
always derived from ``time_unix_ns`` (nearest ms), so the two cannot disagree. Rows with an
empty ``line`` name (epochs outside lines) are written to ``profiles.csv`` only.

One module per format: :mod:`.profiles_csv`, :mod:`.xyz`, :mod:`.geojson`,
:mod:`.crossovers_csv`, :mod:`.jsonout`; the profile table's columns and shared formatting in
:mod:`.columns`; atomic writes, the output transaction and lock in :mod:`.atomic`. Every public
name is importable from ``gravsurvey.io.writers``.
"""

from __future__ import annotations

from .atomic import (
    SUMMARY_NAME,
    LockedError,
    OutputLock,
    OutputTransaction,
    atomic_write_bytes,
    atomic_write_text,
    file_sha256,
    remove_stale_staging,
)
from .columns import (
    ATTITUDE_COLUMNS,
    CROSSOVER_COLUMNS,
    DECIMALS,
    ESTIMATE_COLUMNS,
    HORIZONTAL_COLUMNS,
    LEVEL_COLUMNS,
    PROFILE_COLUMNS,
    STRING_COLUMNS,
    TRUTH_COLUMNS,
    XYZ_COLUMNS,
    format_utc,
    line_groups,
    metadata_lines,
    resolution_statement,
    profile_columns,
)
from .crossovers_csv import write_crossovers_csv
from .geojson import write_geojson
from .jsonout import to_jsonable, write_json
from .profiles_csv import read_profiles_csv, write_profiles_csv
from .xyz import XyzData, read_xyz, write_xyz, xyz_line_labels

__all__ = [
    "PROFILE_COLUMNS",
    "ESTIMATE_COLUMNS",
    "LEVEL_COLUMNS",
    "ATTITUDE_COLUMNS",
    "HORIZONTAL_COLUMNS",
    "TRUTH_COLUMNS",
    "STRING_COLUMNS",
    "DECIMALS",
    "SUMMARY_NAME",
    "line_groups",
    "metadata_lines",
    "resolution_statement",
    "XYZ_COLUMNS",
    "CROSSOVER_COLUMNS",
    "LockedError",
    "format_utc",
    "profile_columns",
    "write_profiles_csv",
    "read_profiles_csv",
    "xyz_line_labels",
    "write_xyz",
    "read_xyz",
    "XyzData",
    "write_geojson",
    "to_jsonable",
    "write_json",
    "write_crossovers_csv",
    "OutputTransaction",
    "OutputLock",
    "remove_stale_staging",
    "atomic_write_bytes",
    "file_sha256",
    "atomic_write_text",
]
