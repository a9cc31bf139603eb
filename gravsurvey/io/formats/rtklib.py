"""RTKLIB position solutions (``.pos``, the output of ``rnx2rtkp`` / RTKPOST / ``rtknavi``).

The most common post-processed GNSS file of a survey: ``%`` comment lines, the last of them
naming the columns, then one solution per line, whitespace-separated::

    % (lat/lon/height=WGS84/ellipsoidal,Q=1:fix,2:float,3:sbas,4:dgps,5:single,6:ppp,ns=# of satellites)
    %  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m) ...
    2024/07/15 06:30:18.000   47.000000000   11.000000000   800.0000   1   9   0.0040   0.0030   0.0100 ...

=================== ===================================================================
layout              read as
=================== ===================================================================
time                ``yyyy/mm/dd hh:mm:ss.sss`` or GPS ``week seconds-of-week``, in the
                    scale the header's first label names: ``GPST`` (to UTC with the
                    leap-second table), ``UTC``, ``JST`` (UTC + 9 h)
position            ``latitude(deg) longitude(deg) height(m)``;
                    ``latitude(d'") longitude(d'") height(m)`` (degrees, minutes, seconds);
                    ``x-ecef(m) y-ecef(m) z-ecef(m)`` (converted to geodetic on WGS84)
height              ellipsoidal unless the header says ``height=.../geodetic`` (above the
                    geoid): then returned as ``height_ortho`` with ``height`` NaN, which the
                    INS refuses by name
Q, ns               ``quality`` (1 fix, 2 float, 3 SBAS, 4 DGPS, 5 single, 6 PPP) and
                    ``n_sat``; the count per quality is a note when not all are fixed
=================== ===================================================================

East/north/up baselines (``e-baseline(m)``) have no absolute position and are refused, naming
the RTKLIB option that writes one.
"""

from __future__ import annotations

import os

import numpy as np

from gravsurvey.errors import DataError

from .common import (
    GPS_EPOCH_UNIX_S,
    NS,
    LineTally,
    civil_to_ns,
    finish,
    gps_to_unix_ns,
    read_lines,
    week_sow_to_unix_ns,
)

#: RTKLIB's solution quality flags (``Q``).
QUALITY = {1: "fix", 2: "float", 3: "sbas", 4: "dgps", 5: "single", 6: "ppp"}
#: Time scales an RTKLIB header may name, and their offset from UTC, s (GPST: leap table).
TIME_SCALES = {"GPST": None, "UTC": 0, "JST": 9 * 3600}


def _dms(d: str, m: str, s: str) -> float:
    """Degrees from RTKLIB's ``d m s`` fields (the sign on the degrees, also ``-0``)."""
    sign = -1.0 if d.strip().startswith("-") else 1.0
    return sign * (abs(float(d)) + float(m) / 60.0 + float(s) / 3600.0)


def read_rtklib_pos(path) -> "FormatTable":  # noqa: F821
    """Read an RTKLIB position solution file.

    Parameters
    ----------
    path : path-like

    Returns
    -------
    FormatTable
        ``format='rtklib'``; columns ``lat``, ``lon`` (rad), ``height`` (ellipsoidal, m; NaN
        where the file's heights are above the geoid), ``height_ortho`` (m, then), ``quality``
        and ``n_sat``; ``meta['time_system']`` the header's scale, ``meta['position']`` one of
        ``llh``, ``dms``, ``xyz``.

    Raises
    ------
    DataError
        No RTKLIB column header (names the file and what was expected), a baseline solution,
        or fewer than half the content lines are solutions.
    """
    path = os.fspath(path)
    lines = read_lines(path)
    tally = LineTally(path)
    head, geoid, start = None, False, len(lines)
    for i, ln in enumerate(lines):
        s = ln.strip()
        if not s:
            continue
        if not s.startswith("%"):
            start = i
            break
        low = s.lower()
        if "height=" in low and "geodetic" in low:
            geoid = True
        if any(k in low for k in ("latitude(", "x-ecef(", "e-baseline(")):
            head = (i, s.lstrip("%").split())
    if head is None:
        raise DataError(
            f"{path}: no RTKLIB column header (a '%' line such as '%  GPST  latitude(deg) longitude(deg) "
            "height(m)  Q  ns ...'); expected an RTKLIB .pos file"
        )
    hline, names = head
    scale = names[0].upper()
    joined = " ".join(names).lower()
    if scale not in TIME_SCALES:
        raise DataError(f"{path}: line {hline + 1}: time label {names[0]!r}, expected one of {', '.join(TIME_SCALES)}")
    if "e-baseline(" in joined:
        raise DataError(
            f"{path}: line {hline + 1}: east/north/up baselines hold no absolute position; write the solution "
            "as latitude/longitude/height (RTKLIB out-solformat = llh)"
        )
    layout = "xyz" if "x-ecef(" in joined else "dms" if "latitude(d'" in joined else "llh"
    npos = 7 if layout == "dms" else 3
    times, pos, qual, nsat = [], [], [], []
    for n, ln in enumerate(lines[start:], start=start + 1):
        s = ln.strip()
        if not s or s.startswith("%"):
            continue
        tally.n_lines += 1
        f = s.split()
        if len(f) < 2 + npos + 2:
            tally.bad(n, f"{len(f)} fields, a solution has at least {2 + npos + 2}", s)
            continue
        try:
            if "/" in f[0]:
                y, mo, d = (int(x) for x in f[0].split("/"))
                hh, mm, ss = f[1].split(":")
                t = civil_to_ns(y, mo, d, int(hh), int(mm), ss)
                if scale == "GPST":
                    t = gps_to_unix_ns(t - GPS_EPOCH_UNIX_S * NS)
                else:
                    t -= TIME_SCALES[scale] * NS
            else:
                if scale != "GPST":
                    raise ValueError(f"week and seconds need GPST, the header says {scale}")
                t = week_sow_to_unix_ns(int(f[0]), f[1])
            p = f[2 : 2 + npos]
            if layout == "dms":
                row = (_dms(*p[0:3]), _dms(*p[3:6]), float(p[6]))
            else:
                row = tuple(float(x) for x in p)
            q, ns_ = int(f[2 + npos]), int(f[3 + npos])
        except ValueError as exc:
            tally.bad(n, f"unparsable field ({exc})", s)
            continue
        if layout != "xyz" and (abs(row[0]) > 90 or abs(row[1]) > 360):
            tally.bad(n, "latitude/longitude out of range", s)
            continue
        times.append(t)
        pos.append(row)
        qual.append(q)
        nsat.append(ns_)
    a = np.asarray(pos, float).reshape(-1, 3)
    if layout == "xyz":
        from gravsurvey.geodesy import ecef_to_geodetic

        lat, lon, h = ecef_to_geodetic(a) if len(a) else (np.zeros(0),) * 3
    else:
        lat, lon, h = np.radians(a[:, 0]), np.radians(a[:, 1]), a[:, 2]
    cols = {"lat": lat, "lon": lon, "height": h, "quality": np.asarray(qual, float), "n_sat": np.asarray(nsat, float)}
    notes = [f"{path}: time scale {scale}" + (" (converted to UTC)" if scale != "UTC" else "")]
    if geoid:
        cols["height_ortho"] = cols["height"]
        cols["height"] = np.full(len(times), np.nan)
        notes.append(f"{path}: heights above the geoid (header: height=.../geodetic), not ellipsoidal")
    if qual and any(q != 1 for q in qual):
        # all fixed is the usual survey solution and says nothing; others err by decimetres
        # (float, PPP) to metres (single, DGPS)
        counts = np.bincount(np.clip(np.asarray(qual, int), 0, 7), minlength=8)
        notes.append(
            f"{path}: solutions by quality: "
            + ", ".join(f"{QUALITY.get(k, f'Q={k}')} {c}" for k, c in enumerate(counts) if c)
            + " (not all fixed: float, PPP and single positions err by decimetres to metres)"
        )
    units = {"lat": "rad", "lon": "rad", "height": "m", "height_ortho": "m", "quality": "1", "n_sat": "1"}
    meta = {"time_system": scale, "position": layout}
    return finish(path, "rtklib", tally, times, cols, {k: units[k] for k in cols}, notes, meta)
