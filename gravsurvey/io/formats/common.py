"""Shared pieces of the vendor-format readers: the result table, time stamps, line tallies.

Every reader returns a :class:`FormatTable`: int64 Unix-ns UTC stamps and a dict of plain
numpy columns, SI inside (m/s^2, rad, m, m/s) unless the column's entry in ``units`` says
otherwise (raw counts, meter units, nT).  Lines that are not records of the format are counted
by reason, reported in ``notes`` and skipped; a file in which too few lines are records of the
format is refused with a :class:`~gravsurvey.errors.DataError` naming the file and the first bad
line.
"""

from __future__ import annotations

import calendar
import os
import re
from dataclasses import dataclass, field

import numpy as np

from gravsurvey.errors import DataError
from gravsurvey.geodesy import MGAL  # noqa: F401  (re-exported to the format readers)

#: 1 knot in m/s (international nautical mile per hour).
KNOT = 1852.0 / 3600.0
#: Nanoseconds per second.
NS = 1_000_000_000
#: A file is refused when fewer than this fraction of its content lines are records.
MIN_GOOD_FRACTION = 0.5
#: Years accepted in dates (int64 ns reach 2262; earlier than 1900 is no digital record).
YEARS = (1900, 2200)
#: GPS epoch 1980-01-06T00:00:00 UTC, Unix seconds.
GPS_EPOCH_UNIX_S = 315964800
#: GPS - UTC (s) from each date on (IERS bulletin C); valid for data after 1999-01-01.
GPS_LEAP_TABLE = (
    (calendar.timegm((1999, 1, 1, 0, 0, 0)), 13),
    (calendar.timegm((2006, 1, 1, 0, 0, 0)), 14),
    (calendar.timegm((2009, 1, 1, 0, 0, 0)), 15),
    (calendar.timegm((2012, 7, 1, 0, 0, 0)), 16),
    (calendar.timegm((2015, 7, 1, 0, 0, 0)), 17),
    (calendar.timegm((2017, 1, 1, 0, 0, 0)), 18),
)


@dataclass
class FormatTable:
    """What a vendor-format reader returns.

    Attributes
    ----------
    source : str
        The file(s) read.
    format : str
        Format name, e.g. ``"mgd77t"``, ``"dgs_laptop"``.
    time_ns : ndarray of int64, shape (n,)
        Record time, ns since the Unix epoch, UTC, in file order (not sorted or repaired;
        :func:`gravsurvey.io.checks.repair_time` does that when the table feeds a record).
    columns : dict of str -> ndarray, shape (n,)
        The record's quantities; see each reader for the names.
    units : dict of str -> str
        Unit of every column (``"m/s^2"``, ``"rad"``, ``"m"``, ``"m/s"``, ``"1"``, ``"counts"``,
        ``"meter units"``...).
    n_lines : int
        Content lines seen (blank and comment lines excluded).
    n_skipped : int
        Content lines skipped as not-a-record or damaged (sum of ``skipped``).
    skipped : dict of str -> int
        Skipped lines per reason.
    notes : list of str
        One line per finding (skipped lines with the first line number, time source,
        missing values).
    meta : dict
        Format-specific metadata (header values, time source used).
    """

    source: str
    format: str
    time_ns: np.ndarray
    columns: dict
    units: dict
    n_lines: int = 0
    n_skipped: int = 0
    skipped: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    meta: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.time_ns.shape[0])

    def time_s(self) -> tuple[np.ndarray, int]:
        """Seconds after the first stamp and that stamp: ``(t (n,), t0_unix_ns)``."""
        if len(self) == 0:
            return np.zeros(0), 0
        t0 = int(self.time_ns.min())
        return (self.time_ns - t0).astype(np.float64) / NS, t0


class LineTally:
    """Counts skipped lines per reason and remembers the first line number of each."""

    def __init__(self, path):
        self.path = os.fspath(path)
        self.n_lines = 0
        self.counts: dict[str, int] = {}
        self.first: dict[str, tuple[int, str]] = {}

    def bad(self, lineno: int, reason: str, text: str = "") -> None:
        """Record a skipped line (1-based ``lineno``)."""
        self.counts[reason] = self.counts.get(reason, 0) + 1
        self.first.setdefault(reason, (lineno, text.strip()[:60]))

    @property
    def n_skipped(self) -> int:
        return sum(self.counts.values())

    def notes(self) -> list[str]:
        """One line per reason: count, first line number and a snippet."""
        out = []
        for r, n in self.counts.items():
            ln, txt = self.first[r]
            out.append(f"{self.path}: {n} line(s) skipped: {r} (first: line {ln}: {txt!r})")
        return out

    def check_enough(self, n_good: int, fmt: str) -> None:
        """Refuse the file when it has no record, or fewer than half its content lines are records.

        Raises
        ------
        DataError
            Naming the file, the format and the first bad line with its reason.
        """
        if n_good > 0 and n_good >= MIN_GOOD_FRACTION * self.n_lines:
            return
        if self.n_lines == 0:
            raise DataError(f"{self.path}: no {fmt} records (the file has no content lines)")
        ln, reason = min((v[0], k) for k, v in self.first.items()) if self.first else (1, "?")
        txt = self.first.get(reason, (0, ""))[1]
        raise DataError(
            f"{self.path}: not a {fmt} file: {n_good} of {self.n_lines} content lines are {fmt} records; "
            f"line {ln}: {reason} ({txt!r})"
        )


def read_lines(path, notes: list | None = None) -> list[str]:
    """The file's lines as text (UTF-8, undecodable bytes replaced so they fail as fields).

    Stray NUL bytes (serial-line padding, seen at line ends of real DGS logs) are removed and
    counted in ``notes``; a file with more than 1 % NUL bytes is binary and refused.

    Raises
    ------
    DataError
        The file cannot be opened, or is binary.
    """
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as exc:
        raise DataError(f"{os.fspath(path)}: cannot read: {exc.strerror or exc}") from None
    n_nul = data.count(b"\x00")
    if n_nul:
        if n_nul > 0.01 * len(data):
            raise DataError(f"{os.fspath(path)}: binary file ({n_nul} NUL bytes), expected text")
        data = data.replace(b"\x00", b"")
        if notes is not None:
            notes.append(f"{os.fspath(path)}: {n_nul} NUL byte(s) removed")
    return data.decode("utf-8", errors="replace").splitlines()


# --------------------------------------------------------------------------- time
def seconds_str_to_ns(s: str) -> int:
    """Exact ns of a decimal seconds string such as ``"05.4059"`` or ``"1674228947.582"``.

    Raises
    ------
    ValueError
        Not a non-negative decimal number.
    """
    s = s.strip()
    if not s or s[0] in "+-":
        raise ValueError(s)
    whole, _, frac = s.partition(".")
    if not (whole.isdigit() or (whole == "" and frac)) or (frac and not frac.isdigit()):
        raise ValueError(s)
    frac = (frac + "000000000")[:9]
    return int(whole or "0") * NS + int(frac)


def civil_to_ns(year: int, month: int, day: int, hour: int, minute: int, sec: str | float) -> int:
    """UTC civil time -> Unix ns; ``sec`` as a decimal string (exact) or float.

    Raises
    ------
    ValueError
        A field out of range (month 13, minute 60, ...).
    """
    if not (
        YEARS[0] <= year <= YEARS[1] and 1 <= month <= 12 and 1 <= day <= 31 and 0 <= hour <= 23 and 0 <= minute <= 59
    ):
        raise ValueError("date/time field out of range")
    sec_ns = seconds_str_to_ns(sec) if isinstance(sec, str) else int(round(float(sec) * NS))
    if not 0 <= sec_ns < 61 * NS:
        raise ValueError("seconds out of range")
    return calendar.timegm((year, month, day, hour, minute, 0)) * NS + sec_ns


def doy_to_ns(year: int, doy: int, hour: int, minute: int, sec: str | float) -> int:
    """UTC year, day of year (1-based), time -> Unix ns."""
    if not (1 <= doy <= 366 and YEARS[0] <= year <= YEARS[1]):
        raise ValueError("year or day of year out of range")
    base = calendar.timegm((year, 1, 1, 0, 0, 0)) + (doy - 1) * 86400
    return base * NS + civil_to_ns(1970, 1, 1, hour, minute, sec)


def gps_leap_seconds(unix_s: float) -> int:
    """GPS - UTC (s) at a UTC instant (table from 1999 on; 13 before)."""
    leap = GPS_LEAP_TABLE[0][1]
    for t, n in GPS_LEAP_TABLE:
        if unix_s >= t:
            leap = n
    return leap


def gps_to_unix_ns(gps_ns: int) -> int:
    """GPS time (ns since the GPS epoch 1980-01-06) -> UTC Unix ns, with the leap table."""
    unix_gps = gps_ns + GPS_EPOCH_UNIX_S * NS
    leap = gps_leap_seconds(unix_gps / NS)
    # a stamp within the leap step itself: take the table at the UTC instant
    leap = gps_leap_seconds((unix_gps - leap * NS) / NS)
    return unix_gps - leap * NS


def week_sow_to_unix_ns(week: int, sow: str | float) -> int:
    """GPS week and seconds of week (GPS time) -> UTC Unix ns."""
    sow_ns = seconds_str_to_ns(sow) if isinstance(sow, str) else int(round(float(sow) * NS))
    if not 0 <= sow_ns < 604800 * NS or not 0 <= week <= 10000:
        raise ValueError("GPS week/seconds of week out of range")
    return gps_to_unix_ns(week * 604800 * NS + sow_ns)


_SEC = r"(\d{1,2}(?:\.\d+)?)"
#: Logger stamps seen in ship and aircraft data-acquisition files, tried in this order.
_STAMPS = (
    ("iso", re.compile(r"(\d{4})-(\d{2})-(\d{2})[T ](\d{2}):(\d{2}):" + _SEC + r"Z?")),
    ("ymd_slash", re.compile(r"(\d{4})/(\d{2})/(\d{2})[ ,T](\d{1,2}):(\d{2}):" + _SEC)),
    ("mdy_slash", re.compile(r"(\d{1,2})/(\d{1,2})/(\d{4})[ ,]\s*(\d{1,2}):(\d{2}):" + _SEC)),
    ("year_doy", re.compile(r"(\d{4}):(\d{3}):(\d{2}):(\d{2}):" + _SEC)),
    ("yy_doy", re.compile(r"(\d{2})\+(\d{3}):(\d{2}):(\d{2}):" + _SEC)),
    ("unix", re.compile(r"(?<![\d.])(\d{10}(?:\.\d+)?)(?![\d.])")),
)

_STAMP_INDEX = {k: i for i, (k, _) in enumerate(_STAMPS)}
_YEAR_END_NS = calendar.timegm((YEARS[1], 1, 1, 0, 0, 0)) * NS


def parse_logger_stamp(prefix: str, first: str | None = None) -> tuple[int, str] | None:
    """The first data-logger time stamp in ``prefix`` -> ``(unix_ns, kind)``, or None.

    Kinds: ``iso`` (2024-12-13T00:00:00.4059Z), ``ymd_slash`` (2022/07/01 12:17:33.233),
    ``mdy_slash`` (03/13/2022,00:00:02.105, US order), ``year_doy`` (2020:244:00:00:00.6212),
    ``yy_doy`` (23+013:00:00:00.113), ``unix`` (1674228947.582, 10 integer digits).
    ``first``: a kind to try first (the previous line's: a file keeps one style), for speed.
    """
    order = ((_STAMPS[_STAMP_INDEX[first]],) + _STAMPS) if first in _STAMP_INDEX else _STAMPS
    for kind, rx in order:
        m = rx.search(prefix)
        if not m:
            continue
        g = m.groups()
        try:
            if kind == "iso" or kind == "ymd_slash":
                return civil_to_ns(int(g[0]), int(g[1]), int(g[2]), int(g[3]), int(g[4]), g[5]), kind
            if kind == "mdy_slash":
                return civil_to_ns(int(g[2]), int(g[0]), int(g[1]), int(g[3]), int(g[4]), g[5]), kind
            if kind == "year_doy":
                return doy_to_ns(int(g[0]), int(g[1]), int(g[2]), int(g[3]), g[4]), kind
            if kind == "yy_doy":
                return doy_to_ns(2000 + int(g[0]), int(g[1]), int(g[2]), int(g[3]), g[4]), kind
            t = seconds_str_to_ns(g[0])
            if t >= _YEAR_END_NS:
                raise ValueError("Unix time after the accepted years")
            return t, kind
        except ValueError:
            continue
    return None


def to_float(s: str) -> float:
    """A field as float; empty -> NaN.  Raises ValueError for anything else that is not a number."""
    s = s.strip()
    if not s:
        return float("nan")
    v = float(s)
    return v


def finish(path, fmt, tally: LineTally, time_ns: list, cols: dict, units: dict, notes=None, meta=None) -> FormatTable:
    """Build the :class:`FormatTable` (arrays, notes) after the per-line loop, refusing too-bad files."""
    tally.check_enough(len(time_ns), fmt)
    out_cols = {k: np.asarray(v, dtype=np.float64) if not isinstance(v, np.ndarray) else v for k, v in cols.items()}
    return FormatTable(
        source=os.fspath(path),
        format=fmt,
        time_ns=np.asarray(time_ns, dtype=np.int64),
        columns=out_cols,
        units=dict(units),
        n_lines=tally.n_lines,
        n_skipped=tally.n_skipped,
        skipped=dict(tally.counts),
        notes=tally.notes() + list(notes or []),
        meta=dict(meta or {}),
    )
