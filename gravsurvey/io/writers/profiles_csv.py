"""``profiles.csv``: one row per epoch, metadata as ``#`` comment lines (docs/outputs.md)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gravsurvey.errors import DataError

from .atomic import atomic_write_text
from .columns import (
    DECIMALS,
    PROFILE_COLUMNS,
    STRING_COLUMNS,
    column_strings,
    float_rows,
    metadata_lines,
    profile_columns,
)


def write_profiles_csv(path, table: dict, metadata: dict | None = None) -> None:
    """Write ``profiles.csv``: metadata comment lines, a header row, then one row per epoch.

    Parameters
    ----------
    path : path-like
    table : dict of ndarray
        The profile table (module docstring). Non-finite floats are written ``NaN``.
    metadata : dict, optional
        Written first as ``# key: value`` lines (:func:`metadata_lines`); readers skip lines
        starting with ``#`` (pandas: ``comment="#"``).
    """
    cols = profile_columns(table)
    text_cols = [c for c in cols if c in STRING_COLUMNS or c == "time_unix_ns"]
    float_cols = [c for c in cols if c not in text_cols]
    assert list(cols) == text_cols + float_cols  # documented order: text columns first
    text = [column_strings(table, c) for c in text_cols]
    nums = float_rows([table[c] for c in float_cols], [f"%.{DECIMALS[c]}f" for c in float_cols], ",", "NaN")
    lines = [f"# {m}" for m in metadata_lines(metadata)]
    lines.append(",".join(cols))
    lines += [",".join(row) for row in zip(*text, nums)]
    atomic_write_text(path, "\n".join(lines) + "\n")


def read_profiles_csv(path) -> dict:
    """Read ``profiles.csv`` back: strings for flight, line, time_utc; int64 time_unix_ns; floats.

    Raises
    ------
    DataError
        The file is missing a documented column or a row has the wrong number of fields.
    """
    import csv

    path = Path(path)
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(line for line in fh if not line.startswith("#")))
    if not rows:
        raise DataError(f"{path}: empty file, expected a header row")
    head = rows[0]
    missing = [c for c in PROFILE_COLUMNS if c not in head]
    if missing:
        raise DataError(f"{path}: missing columns {missing}")
    body = rows[1:]
    for i, r in enumerate(body):
        if len(r) != len(head):
            raise DataError(f"{path}: line {i + 2} has {len(r)} fields, expected {len(head)}")
    out = {}
    for j, c in enumerate(head):
        vals = [r[j] for r in body]
        if c in STRING_COLUMNS:
            out[c] = np.array(vals, dtype=object)
        elif c == "time_unix_ns":
            out[c] = np.array([int(v) for v in vals], dtype=np.int64)
        else:
            out[c] = np.array([float(v) for v in vals], dtype=float)
    return out
