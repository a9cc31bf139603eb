"""GNSS trajectory text files (post-processed positions: Waypoint/GrafNav-style exports).

A header row names the columns, then one position per row; comma- or whitespace-separated.
Columns are recognised by name (case and spacing ignored, common misspellings accepted):

=================== ===================================================================
quantity            header names recognised
=================== ===================================================================
date + time         ``date``/``gps date``/``mdy`` (m/d/yyyy, yyyy/mm/dd or yyyy-mm-dd) and
                    ``time``/``gps time``/``hms`` (h:mm:ss.sss)
GPS week + SOW      ``week``/``gps week`` and ``sow``/``seconds of week``/``gps sow``
latitude            ``lat``, ``latitude``, ``lattitude``
longitude           ``lon``, ``long``, ``longitude``
ellipsoidal height  ``ell_ht``, ``ellipsoidal height``, ``elipsoidal height``, ``h_ell``
orthometric height  ``ortho_ht``, ``orthometric height``
satellites, PDOP    ``num_sats``/``num of satellites``, ``pdop``
=================== ===================================================================

Time scale: week/SOW is GPS time; date/time columns are GPS time when their header says
``gps`` (or ``time_system='gps'``), else UTC; GPS time is converted to UTC with the leap-second
table.  Columns returned: ``lat``, ``lon`` (rad), ``height`` (ellipsoidal, m; NaN if absent),
``height_ortho`` (m, when present), ``n_sat``, ``pdop`` (when present).

A header's labels are trusted: the reader cannot tell swapped height columns apart (one DGP
sample file labels ``ell_ht`` the column its twin calls orthometric).
"""

from __future__ import annotations

import os
import re

import numpy as np

from gravsurvey.errors import ConfigError, DataError

from .common import GPS_EPOCH_UNIX_S, LineTally, civil_to_ns, finish, gps_to_unix_ns, read_lines, week_sow_to_unix_ns

TIME_SYSTEMS = ("auto", "gps", "utc")


def _norm(h: str) -> str:
    return re.sub(r"[^a-z]", "", h.lower())


_ROLES = (
    ("week", ("week", "gpsweek")),
    ("sow", ("sow", "gpssow", "secondsofweek", "gpsseconds", "weekseconds", "gpsweekseconds")),
    ("date", ("date", "gpsdate", "mdy", "utcdate")),
    ("time", ("time", "gpstime", "hms", "utctime")),
    ("lat", ("lat", "latitude", "lattitude")),
    ("lon", ("lon", "long", "longitude")),
    ("height", ("ellht", "ellipsoidalheight", "elipsoidalheight", "hell", "ellipsoidheight", "height", "h")),
    ("height_ortho", ("orthoht", "orthometricheight", "orthometricheigth", "orthoheight")),
    ("n_sat", ("numsats", "numofsatellites", "numofsatelites", "nsat", "sats")),
    ("pdop", ("pdop",)),
)


def _date(s: str) -> tuple[int, int, int]:
    s = s.strip()
    m = re.fullmatch(r"(\d{1,2})/(\d{1,2})/(\d{4})", s)
    if m:
        return int(m.group(3)), int(m.group(1)), int(m.group(2))
    m = re.fullmatch(r"(\d{4})[/-](\d{1,2})[/-](\d{1,2})", s)
    if m:
        return int(m.group(1)), int(m.group(2)), int(m.group(3))
    raise ValueError(f"date {s!r} is not m/d/yyyy or yyyy-mm-dd")


def read_trajectory(path, *, time_system: str = "auto") -> "FormatTable":  # noqa: F821
    """Read a GNSS trajectory text file.

    Parameters
    ----------
    path : path-like
    time_system : {'auto', 'gps', 'utc'}
        Scale of date/time columns (week/SOW is always GPS); 'auto' = GPS when the header
        says so.

    Returns
    -------
    FormatTable
        ``format='trajectory'``; columns in the module docstring; ``meta['columns']`` maps each
        quantity to the header name used, ``meta['time_system']`` the scale read.

    Raises
    ------
    ConfigError
        Unknown ``time_system``.
    DataError
        No header row with latitude, longitude and a time (names the file and the header line
        and what is missing); fewer than half the rows are positions.
    """
    if time_system not in TIME_SYSTEMS:
        raise ConfigError(f"trajectory time_system: expected one of {', '.join(TIME_SYSTEMS)}, got {time_system!r}")
    path = os.fspath(path)
    lines = read_lines(path)
    tally = LineTally(path)
    hi = next((i for i, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("#")), None)
    if hi is None:
        raise DataError(f"{path}: empty file, expected a trajectory header row")
    head = lines[hi]
    delim = "," if "," in head else None
    names = [h.strip() for h in (head.split(delim) if delim else head.split())]
    col = {}
    for i, h in enumerate(names):
        k = _norm(h)
        for role, keys in _ROLES:
            if k in keys and role not in col:
                col[role] = i
                break
    has_time = ("week" in col and "sow" in col) or ("date" in col and "time" in col)
    missing = [q for q in ("lat", "lon") if q not in col] + ([] if has_time else ["date+time or week+sow"])
    if missing:
        raise DataError(
            f"{path}: line {hi + 1}: not a trajectory header (need latitude, longitude and a time); "
            f"missing {', '.join(missing)} in {names}"
        )
    use_week = "week" in col and "sow" in col
    if use_week:
        scale = "gps"
    elif time_system != "auto":
        scale = time_system
    else:
        scale = "gps" if "gps" in (names[col["date"]] + names[col["time"]]).lower() else "utc"
    times, vals = [], {q: [] for q in ("lat", "lon", "height", "height_ortho", "n_sat", "pdop") if q in col}
    nf = len(names)
    for n, ln in enumerate(lines[hi + 1 :], start=hi + 2):
        s = ln.strip()
        if not s or s.startswith("#"):
            continue
        tally.n_lines += 1
        f = s.split(delim) if delim else s.split()
        if len(f) != nf:
            tally.bad(n, f"{len(f)} fields, header has {nf}", s)
            continue
        try:
            if use_week:
                t = week_sow_to_unix_ns(int(float(f[col["week"]])), f[col["sow"]].strip())
            else:
                y, mo, d = _date(f[col["date"]])
                hh, mm, ss = f[col["time"]].strip().split(":")
                t = civil_to_ns(y, mo, d, int(hh), int(mm), ss)
                if scale == "gps":
                    t = gps_to_unix_ns(t - GPS_EPOCH_UNIX_S * 1_000_000_000)
            row = {q: float(f[col[q]]) for q in vals}
        except ValueError as exc:
            tally.bad(n, f"unparsable field ({exc})", s)
            continue
        if abs(row["lat"]) > 90 or abs(row["lon"]) > 360:
            tally.bad(n, "latitude/longitude out of range", s)
            continue
        times.append(t)
        for q in vals:
            vals[q].append(row[q])
    cols = {q: np.asarray(v, float) for q, v in vals.items()}
    cols["lat"] = np.radians(cols["lat"])
    cols["lon"] = np.radians(cols["lon"])
    if "height" not in cols:
        cols["height"] = np.full(len(times), np.nan)
    units = {"lat": "rad", "lon": "rad", "height": "m", "height_ortho": "m", "n_sat": "1", "pdop": "1"}
    units = {k: units[k] for k in cols}
    notes = [f"{path}: time scale {scale.upper()}" + (" (converted to UTC)" if scale == "gps" else "")]
    if "height" not in col:
        notes.append(f"{path}: no ellipsoidal height column: height NaN")
    meta = {"columns": {q: names[i] for q, i in col.items()}, "time_system": scale}
    return finish(path, "trajectory", tally, times, cols, units, notes, meta)
