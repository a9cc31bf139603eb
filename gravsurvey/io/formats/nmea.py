"""NMEA 0183 navigation logs: GGA, RMC, VTG (and ZDA for the date), with or without logger stamps.

Ship and aircraft data loggers write NMEA sentences one per line, often behind a logger prefix
(``NAV 2022/07/01 12:17:33.433 GPS $GPRMC,...``, ``seapath<TAB>2020:244:00:00:00.6212<TAB>
$INGGA,...``, ``1674228947.583 $INGGA,...``, ``03/13/2022,00:00:02.105,$INGGA,...``, or an ISO
stamp on a line of its own before a block of sentences).  The reader finds each sentence
wherever it starts on the line, checks its ``*hh`` checksum when present, and takes the
logger stamp from the text before it (the last stamp seen carries forward to prefix-less lines).

One record per position fix: per GGA sentence when the file has any (else per RMC), keyed by
the fix's UTC time of day.  RMC and VTG sentences with the same time of day (VTG: the one
following the fix's line) add speed and course; the date comes from RMC or ZDA, else from the
logger stamp.

Columns:

================ ===== =========================================================
column           unit  meaning
================ ===== =========================================================
lat, lon         rad   geodetic position
height           m     ellipsoidal height = GGA altitude + geoid separation
                       (NaN when the separation field is empty)
height_msl       m     GGA altitude above mean sea level (geoid)
quality          1     GGA fix quality (0 invalid ... 5 float RTK; NaN for RMC)
n_sat            1     satellites used
hdop             1     horizontal dilution of precision
speed            m/s   speed over ground (RMC, else VTG; NaN when none)
course           rad   course over ground, true, clockwise from north
logger_time_ns   ns    the logger's stamp for the fix's line (int64 in ``meta``)
================ ===== =========================================================

Time (``time_source``): ``'fix'`` = date + the sentence's UTC time of day (the GNSS clock);
``'logger'`` = the logger stamp (when the sentence time is missing or the date is unknown);
``'auto'`` (default) = fix time when a date is available from RMC/ZDA/the logger, else the
logger stamp.  ``meta['logger_minus_fix_s']`` is the median logger - fix offset when both exist.
"""

from __future__ import annotations

import os
import re
from functools import reduce
from operator import xor

import numpy as np

from gravsurvey.errors import ConfigError, DataError

from .common import KNOT, NS, LineTally, civil_to_ns, finish, parse_logger_stamp, read_lines, seconds_str_to_ns

#: ``$ttSSS,`` (talker + sentence type) or a proprietary ``$Pxxx,``; group 2 is the type.
_SENTENCE = re.compile(r"[$!](P[A-Z0-9]{1,6}|[A-Z]{2})([A-Z]{3})?,")
TIME_SOURCES = ("auto", "fix", "logger")
#: Sentence types read; every other one is counted in ``meta["ignored_sentences"]``.
USED = ("GGA", "RMC", "VTG", "ZDA")
_DAY_NS = 86400 * NS


def _checksum_ok(sentence: str) -> bool | None:
    """True/False for a sentence with ``*hh``; None when it has none."""
    body, star, cs = sentence.partition("*")
    if not star:
        return None
    cs = cs.strip()[:2]
    try:
        want = int(cs, 16)
    except ValueError:
        return False
    return reduce(xor, body[1:].encode("latin-1", "replace"), 0) == want


def _latlon(v: str, hemi: str, deg_digits: int) -> float:
    v = v.strip()
    if not v:
        return np.nan
    if len(v.split(".")[0]) < deg_digits + 2:
        raise ValueError("position field too short")
    deg = int(v[:deg_digits])
    minutes = float(v[deg_digits:])
    if minutes >= 60.0:
        raise ValueError("minutes >= 60")
    x = deg + minutes / 60.0
    hemi = hemi.strip().upper()
    if hemi in ("S", "W"):
        x = -x
    elif hemi not in ("N", "E"):
        raise ValueError("hemisphere not N/S/E/W")
    return np.radians(x)


def _tod_ns(s: str) -> int:
    s = s.strip()
    if len(s.split(".")[0]) != 6 or not s[:6].isdigit():
        raise ValueError("time of day is not hhmmss[.ss]")
    h, m = int(s[:2]), int(s[2:4])
    sec = seconds_str_to_ns(s[4:])
    if h > 23 or m > 59 or sec >= 61 * NS:
        raise ValueError("time of day out of range")
    return (h * 3600 + m * 60) * NS + sec


def _num(s: str) -> float:
    s = s.strip()
    return float(s) if s else np.nan


def _date_from_ddmmyy(s: str) -> int:
    s = s.strip()
    if len(s) != 6 or not s.isdigit():
        raise ValueError("RMC date is not ddmmyy")
    yy = int(s[4:])
    # NMEA two-digit year: 1980-2079 (GPS era)
    year = 2000 + yy if yy < 80 else 1900 + yy
    return civil_to_ns(year, int(s[2:4]), int(s[:2]), 0, 0, "0")


def read_nmea(path, *, time_source: str = "auto") -> "FormatTable":  # noqa: F821
    """Read GGA/RMC/VTG/ZDA position fixes from an NMEA 0183 log.

    Parameters
    ----------
    path : path-like
    time_source : {'auto', 'fix', 'logger'}
        See the module docstring.

    Returns
    -------
    FormatTable
        ``format='nmea'``, columns of the module docstring, one record per fix in file order.
        Skipped and counted: sentences with a bad checksum, unparsable or out-of-range fields,
        fixes with GGA quality 0 or RMC status V (no fix), lines without any sentence.
        Other sentence types (HDT, GLL, PSXN, ...) are counted in ``meta['ignored_sentences']``,
        not as damage.

    Raises
    ------
    ConfigError
        Unknown ``time_source``.
    DataError
        Unreadable file; fewer than half the content lines hold a sentence or stamp; no fix; no
        way to date the fixes (no RMC/ZDA date, no logger stamp) when ``time_source`` needs it.
    """
    if time_source not in TIME_SOURCES:
        raise ConfigError(f"nmea time_source: expected one of {', '.join(TIME_SOURCES)}, got {time_source!r}")
    path = os.fspath(path)
    tally = LineTally(path)
    lines = read_lines(path)
    gga, rmc, vtg = [], [], []  # parsed sentences with (line index, tod_ns, logger_ns, ...)
    dates = []  # (line index, date_ns) from RMC / ZDA
    ignored: dict[str, int] = {}
    logger_ns = None
    n_ok_lines = 0
    stamp_kind = None
    for n, ln in enumerate(lines, start=1):
        if not ln.strip():
            continue
        tally.n_lines += 1
        m = _SENTENCE.search(ln)
        prefix = ln[: m.start()] if m else ln
        st = parse_logger_stamp(prefix, stamp_kind) if prefix.strip() else None
        if st is not None:
            logger_ns, stamp_kind = st
        if m is None:
            if st is not None:
                n_ok_lines += 1  # a stamp-only line (ISO stamp before a block)
            else:
                tally.bad(n, "no NMEA sentence", ln)
            continue
        sentence = ln[m.start() :].strip()
        # proprietary sentences ($PSXN) have no talker: their "type" is the whole tag
        kind = m.group(2) if m.group(2) else m.group(1)
        # checksums are judged on the sentences used only (some proprietary ones are miscomputed)
        if kind in USED and _checksum_ok(sentence) is False:
            tally.bad(n, f"{kind} checksum mismatch", ln)
            continue
        f = sentence.split("*")[0].split(",")
        try:
            if kind == "GGA":
                if len(f) < 10:
                    raise ValueError("GGA has fewer than 10 fields")
                q = _num(f[6])
                if q == 0:
                    tally.bad(n, "GGA fix quality 0 (no fix)", ln)
                    n_ok_lines += 1
                    continue
                lat, lon = _latlon(f[2], f[3], 2), _latlon(f[4], f[5], 3)
                if not (np.isfinite(lat) and np.isfinite(lon)):
                    raise ValueError("GGA without a position")
                sep = _num(f[11]) if len(f) > 11 else np.nan
                gga.append((n, _tod_ns(f[1]), logger_ns, lat, lon, _num(f[9]), sep, q, _num(f[7]), _num(f[8])))
            elif kind == "RMC":
                if len(f) < 10:
                    raise ValueError("RMC has fewer than 10 fields")
                if f[2].strip().upper() != "A":
                    tally.bad(n, "RMC status not A (no valid fix)", ln)
                    n_ok_lines += 1
                    continue
                lat, lon = _latlon(f[3], f[4], 2), _latlon(f[5], f[6], 3)
                d = _date_from_ddmmyy(f[9])
                rmc.append((n, _tod_ns(f[1]), logger_ns, lat, lon, _num(f[7]) * KNOT, np.radians(_num(f[8])), d))
                dates.append((n, d))
            elif kind == "VTG":
                if len(f) < 8:
                    raise ValueError("VTG has fewer than 8 fields")
                # VTG,course_true,T,course_mag,M,speed_kn,N,speed_kmh,K
                spd = _num(f[5]) * KNOT
                if not np.isfinite(spd):
                    spd = _num(f[7]) / 3.6
                vtg.append((n, np.radians(_num(f[1])), spd))
            elif kind == "ZDA":
                if len(f) < 5:
                    raise ValueError("ZDA has fewer than 5 fields")
                if f[2].strip() and f[3].strip() and f[4].strip():
                    dates.append((n, civil_to_ns(int(f[4]), int(f[3]), int(f[2]), 0, 0, "0")))
            else:
                ignored[kind] = ignored.get(kind, 0) + 1
        except (ValueError, IndexError) as exc:
            tally.bad(n, f"damaged {kind} sentence ({exc})", ln)
            continue
        n_ok_lines += 1

    # a file of sentences we do not use is NMEA, but has no fix: say so
    tally.check_enough(n_ok_lines, "NMEA")
    base = gga if gga else rmc
    if not base:
        raise DataError(
            f"{path}: no usable GGA or RMC position fix in {tally.n_lines} lines"
            + (f" ({'; '.join(tally.notes())})" if tally.counts else "")
        )
    notes = []
    rmc_by_tod: dict[int, tuple] = {}
    for r in rmc:
        rmc_by_tod.setdefault(r[1], r)
    vtg_lines = np.array([v[0] for v in vtg]) if vtg else np.zeros(0, int)
    date_lines = np.array([d[0] for d in dates]) if dates else np.zeros(0, int)
    date_vals = [d[1] for d in dates]

    n = len(base)
    lat = np.empty(n)
    lon = np.empty(n)
    height = np.full(n, np.nan)
    h_msl = np.full(n, np.nan)
    qual = np.full(n, np.nan)
    nsat = np.full(n, np.nan)
    hdop = np.full(n, np.nan)
    speed = np.full(n, np.nan)
    course = np.full(n, np.nan)
    fix_ns = np.full(n, np.iinfo(np.int64).min, dtype=np.int64)
    log_ns = np.full(n, np.iinfo(np.int64).min, dtype=np.int64)
    prev_t = None
    for i, r in enumerate(base):
        line_i, tod, lg = r[0], r[1], r[2]
        lat[i], lon[i] = r[3], r[4]
        if base is gga:
            h_msl[i], height[i] = r[5], r[5] + r[6]
            qual[i], nsat[i], hdop[i] = r[7], r[8], r[9]
            mr = rmc_by_tod.get(tod)
            if mr is not None:
                speed[i], course[i] = mr[5], mr[6]
        else:
            speed[i], course[i] = r[5], r[6]
        if not np.isfinite(speed[i]) and vtg_lines.size:
            j = np.searchsorted(vtg_lines, line_i)
            if j < vtg_lines.size and (i + 1 >= n or vtg_lines[j] < base[i + 1][0]):
                course[i], speed[i] = vtg[j][1], vtg[j][2]
        if lg is not None:
            log_ns[i] = lg
        # date: the nearest RMC/ZDA date (at or before this line, else after), else the logger's
        date0 = None
        if base is rmc:
            date0 = r[7]
        elif base is gga and rmc_by_tod.get(tod) is not None:
            date0 = rmc_by_tod[tod][7]  # the RMC of the same fix carries its date
        elif date_lines.size:
            j = np.searchsorted(date_lines, line_i, side="right") - 1
            date0 = date_vals[max(j, 0)]
            if lg is not None and abs(lg - (date0 + tod)) > _DAY_NS // 2:
                date0 = None  # stale date far from the logger clock: use the logger's day
        if date0 is None and lg is not None:
            date0 = (lg // _DAY_NS) * _DAY_NS
        if date0 is None:
            continue
        t = date0 + tod
        # midnight: the date (or logger day) and the time of day may belong to adjacent days;
        # the reference is the logger clock, else the previous fix
        ref = lg if lg is not None else (prev_t if prev_t is not None else t)
        if t - ref > _DAY_NS // 2:
            t -= _DAY_NS
        elif ref - t > _DAY_NS // 2:
            t += _DAY_NS
        fix_ns[i] = t
        prev_t = t
    have_fix = fix_ns != np.iinfo(np.int64).min
    have_log = log_ns != np.iinfo(np.int64).min
    if time_source == "auto":
        use = "fix" if have_fix.all() else ("logger" if have_log.all() else "fix")
    else:
        use = time_source
    if use == "fix":
        if not have_fix.all():
            raise DataError(
                f"{path}: {int((~have_fix).sum())} of {n} fixes cannot be dated: no RMC/ZDA date and no logger time stamp"
            )
        t_ns = fix_ns
    else:
        if not have_log.all():
            raise DataError(
                f"{path}: time_source logger but {int((~have_log).sum())} of {n} fixes have no logger time stamp"
            )
        t_ns = log_ns
    meta = {
        "time_source": use,
        "fix_sentence": "GGA" if base is gga else "RMC",
        "ignored_sentences": ignored,
        "logger_stamp": stamp_kind,
    }
    if (have_fix & have_log).any():
        off = np.median((log_ns - fix_ns)[have_fix & have_log]) / NS
        meta["logger_minus_fix_s"] = float(off)
        notes.append(f"{path}: time from the {use} clock; logger - fix = {off:+.3f} s (median)")
    else:
        notes.append(f"{path}: time from the {use} clock")
    if base is gga and np.isnan(height).any():
        notes.append(
            f"{path}: {int(np.isnan(height).sum())} of {n} GGA fixes have no geoid separation: ellipsoidal height NaN"
        )
    if np.isnan(speed).all():
        notes.append(f"{path}: no RMC/VTG speed and course")
    cols = {
        "lat": lat,
        "lon": lon,
        "height": height,
        "height_msl": h_msl,
        "quality": qual,
        "n_sat": nsat,
        "hdop": hdop,
        "speed": speed,
        "course": course,
    }
    units = {
        "lat": "rad",
        "lon": "rad",
        "height": "m",
        "height_msl": "m",
        "quality": "1",
        "n_sat": "1",
        "hdop": "1",
        "speed": "m/s",
        "course": "rad",
    }
    # the line tally decides "not NMEA"; fixes are fewer than lines by design
    tally.n_lines, saved = 0, tally.n_lines
    out = finish(path, "nmea", tally, list(t_ns), cols, units, notes, meta)
    out.n_lines = saved
    out.meta["logger_time_ns"] = np.where(have_log, log_ns, 0)
    return out
