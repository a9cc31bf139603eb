"""Geosoft XYZ line data (``profiles.xyz``, Oasis montaj "Import XYZ"; docs/outputs.md)."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gravsurvey.errors import DataError

from .atomic import atomic_write_text
from .columns import ATTITUDE_COLUMNS, DECIMALS, float_rows, metadata_lines, profile_columns


def xyz_line_labels(flight, line) -> tuple[list[str], dict[str, tuple[str, str]]]:
    """Geosoft line headers for (flight, line) pairs: ``Line <n>`` or ``Tie <n>``.

    ``n = 1000 * f + k`` with ``f`` the flight's 1-based position in order of first appearance
    and ``k`` the number in the line name (``L07`` -> 7, ``T02`` -> 2); names without a number,
    or whose number collides or is >= 1000, are numbered 1, 2, ... in order of appearance among
    the flight's remaining numbers. Names ``T<digits>`` get ``Tie``, all others ``Line``.

    Returns
    -------
    headers : list of str
        One per unique (flight, line), in order of first appearance.
    mapping : dict
        header -> (flight, line).
    """
    flight = [str(f) for f in flight]
    line = [str(x) for x in line]
    pairs = list(dict.fromkeys(zip(flight, line)))
    fnum = {f: i + 1 for i, f in enumerate(dict.fromkeys(f for f, _ in pairs))}
    used: dict[str, set] = {}
    wanted = {}
    for f, ln in pairs:
        m = re.fullmatch(r"[A-Za-z_\-]*0*(\d{1,3})", ln)
        wanted[(f, ln)] = int(m.group(1)) if m and 0 < int(m.group(1)) < 1000 else None
    headers, mapping = [], {}
    kinds = {p: ("Tie" if re.fullmatch(r"T\d+", p[1]) else "Line") for p in pairs}
    for f, ln in pairs:
        k = wanted[(f, ln)]
        kind = kinds[(f, ln)]
        taken = used.setdefault(f + "\0" + kind, set())
        if k is None or k in taken:
            reserved = {wk for p, wk in wanted.items() if p[0] == f and kinds[p] == kind and wk is not None}
            k = 1
            while k in taken or k in reserved:
                k += 1
            if k >= 1000:
                raise ValueError(f"flight {f}: more than 999 lines cannot be numbered for XYZ")
        taken.add(k)
        h = f"{kind} {1000 * fnum[f] + k}"
        headers.append(h)
        mapping[h] = (f, ln)
    return headers, mapping


def write_xyz(
    path,
    table: dict,
    *,
    title: str = "gravsurvey profiles",
    metadata: dict | None = None,
    line_notes: dict | None = None,
) -> None:
    """Write the profile table as Geosoft XYZ line data (Oasis montaj "Import XYZ").

    Layout: ``/`` comment lines (title, units, the line-number map ``/ Line 1001 = F01 L01``, each
    with its ``line_notes`` entry),
    then a ``/`` comment naming the columns, then per line a ``Line <n>`` (or ``Tie <n>``)
    header followed by whitespace-separated rows of :data:`XYZ_COLUMNS` with the optional
    columns of the table in profiles.csv order (estimate, level, horizontal, truth; not the
    attitude) in fixed-width fields; NaN is the Geosoft dummy ``*``. Rows keep
    the table's order; a line's rows must be contiguous in the table.

    Parameters
    ----------
    path : path-like
    table : dict of ndarray
        The profile table.
    title : str
        First comment line.
    metadata : dict, optional
        ``/ key: value`` comment lines after the title (:func:`metadata_lines`).
    line_notes : dict, optional
        ``(flight, line) -> text`` appended to that line's map comment after ``"; "`` (the
        pipeline states each line's resolution there: :func:`resolution_statement`).
    """
    cols = profile_columns(table)
    numeric = ("time_unix_s",) + tuple(c for c in cols[4:] if c not in ATTITUDE_COLUMNS)
    keep = np.asarray(table["line"]).astype(str) != ""
    if not keep.all():  # epochs outside lines (empty line name) are not line data
        table = {c: np.asarray(table[c])[keep] for c in cols if c in table}
    flight = np.asarray(table["flight"]).astype(str)
    line = np.asarray(table["line"]).astype(str)
    headers, mapping = xyz_line_labels(flight, line)
    by_pair = {v: k for k, v in mapping.items()}
    n = flight.size
    # contiguous blocks
    change = np.flatnonzero((flight[1:] != flight[:-1]) | (line[1:] != line[:-1])) + 1
    starts = np.concatenate(([0], change)) if n else np.zeros(0, int)
    stops = np.concatenate((change, [n])) if n else np.zeros(0, int)
    seen = set()
    for a in starts:
        key = (flight[a], line[a])
        if key in seen:
            raise ValueError(f"write_xyz: rows of flight {key[0]} line {key[1]} are not contiguous")
        seen.add(key)
    data = {}
    tns = np.asarray(table["time_unix_ns"], dtype=np.int64)
    data["time_unix_s"] = ((tns + 500_000) // 1_000_000).astype(float) / 1e3  # nearest ms, as time_utc
    for c in numeric[1:]:
        data[c] = np.asarray(table[c], dtype=float)
    width = {c: max(len(c), 16) for c in numeric}
    out = [f"/ {title}"] + [f"/ {m}" for m in metadata_lines(metadata)]
    out += [
        "/ units: time_unix_s s since 1970-01-01T00:00:00Z (UTC); lat_deg lon_deg WGS84 deg;",
        "/ height_m ellipsoidal m; easting_m northing_m projected m; *_mgal mGal; '*' = no value",
    ]
    if any(c.endswith("_arcsec") for c in numeric):
        out.append("/ *_arcsec: deflection of the vertical, arcsec (xi north, eta east)")
    for h in headers:
        f, ln = mapping[h]
        note = (line_notes or {}).get((f, ln))
        out.append(f"/ {h} = flight {f} line {ln}" + (f"; {' '.join(str(note).splitlines())}" if note else ""))
    # column names right-aligned over their fields (the "/" takes the first field's first blank)
    out.append("/" + " ".join(f"{c:>{width[c]}}" for c in numeric)[1:])
    # right-aligned fixed-width fields; 'nan' -> '  *' keeps the width
    rows = float_rows([data[c] for c in numeric], [f"%{width[c]}.{DECIMALS[c]}f" for c in numeric], " ", "  *")
    for a, b in zip(starts, stops):
        out.append(by_pair[(flight[a], line[a])])
        out.extend(rows[a:b])
    atomic_write_text(path, "\n".join(out) + "\n")


@dataclass
class XyzData:
    """What :func:`read_xyz` returns.

    Attributes
    ----------
    columns : list of str
        Column names from the last ``/`` comment line before the first line header.
    lines : dict
        ``"Line 1001"`` -> dict of column -> ndarray (float; ``*`` -> NaN), in file order.
    comments : list of str
        All ``/`` comment lines without the leading ``/ ``.
    """

    columns: list
    lines: dict
    comments: list = field(default_factory=list)


def read_xyz(path) -> XyzData:
    """Read Geosoft XYZ line data as written by :func:`write_xyz` (and the common variants:
    ``Line``/``Tie``/``Trend`` headers in any case, ``/`` comments anywhere, ``*`` dummies).

    Raises
    ------
    DataError
        Data before a line header, no column-name comment, or a row with the wrong field count.
    """
    path = Path(path)
    columns = None
    comments = []
    lines: dict[str, list] = {}
    cur = None
    with open(path, encoding="utf-8") as fh:
        for no, raw in enumerate(fh, 1):
            s = raw.strip()
            if not s:
                continue
            if s.startswith("/"):
                txt = s[1:].strip()
                comments.append(txt)
                if not lines:
                    columns = txt.split()
                continue
            head = s.split()
            if head[0].lower() in ("line", "tie", "trend") and len(head) == 2:
                cur = f"{head[0].capitalize()} {head[1]}"
                if cur in lines:
                    raise DataError(f"{path}:{no}: {cur} appears twice")
                lines[cur] = []
                continue
            if cur is None:
                raise DataError(f"{path}:{no}: data before the first Line header")
            if columns is None or len(head) != len(columns):
                raise DataError(f"{path}:{no}: {len(head)} fields, expected {len(columns or [])}")
            lines[cur].append([math.nan if v == "*" else float(v) for v in head])
    if columns is None:
        raise DataError(f"{path}: no '/' comment line naming the columns")
    out = {}
    for k, rows in lines.items():
        arr = np.array(rows, dtype=float).reshape(-1, len(columns))
        out[k] = {c: arr[:, j] for j, c in enumerate(columns)}
    return XyzData(columns, out, comments)
