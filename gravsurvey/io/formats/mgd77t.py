"""NCEI MGD77T: tab-delimited marine trackline geophysics (``*.m77t``) and its header (``*.h77t``).

Format (NCEI ``mgd77_format_spec.pdf``): one header row naming the 26 fields, then one record
per row, tab-separated; empty cells mean no value and trailing empty cells may be absent.
``DATE`` is ``yyyymmdd``, ``TIME`` ``hhmm`` with an optional fraction of a minute
(``1638.5`` = 16:38:30), ``TIMEZONE`` the hours that make it UTC when added.

Columns returned (SI inside; name = the MGD77T field in lower case):

============ ======= ===================================================================
column       unit    meaning
============ ======= ===================================================================
lat, lon     rad     geodetic position (lon in (-pi, pi], as in the file)
gra_obs      m/s^2   observed gravity (absolute, Eotvos-corrected by the supplier)
eotvos       m/s^2   the supplier's Eotvos correction
freeair      m/s^2   the supplier's free-air anomaly
corr_depth   m       corrected depth (positive down)
bat_ttime    s       two-way travel time
mag_tot,     nT      total field (1st and 2nd sensor), residual, diurnal correction
mag_tot2,
mag_res,
mag_dicorr
mag_sdepth   m       magnetic sensor depth
pos_type,    1       codes as in the specification (NaN when empty)
nav_qualco,
bat_cpco,
bat_typco,
bat_qualco,
mag_qualco,
gra_qualco,
mag_ressen
============ ======= ===================================================================

``meta``: ``survey_id`` (first record's), ``line_id``/``point_id`` are not kept (free text).
"""

from __future__ import annotations

import csv
import os

import numpy as np

from gravsurvey.errors import DataError

from .common import MGAL, NS, LineTally, civil_to_ns, finish, read_lines

FIELDS = (
    "SURVEY_ID",
    "TIMEZONE",
    "DATE",
    "TIME",
    "LAT",
    "LON",
    "POS_TYPE",
    "NAV_QUALCO",
    "BAT_TTIME",
    "CORR_DEPTH",
    "BAT_CPCO",
    "BAT_TYPCO",
    "BAT_QUALCO",
    "MAG_TOT",
    "MAG_TOT2",
    "MAG_RES",
    "MAG_RESSEN",
    "MAG_DICORR",
    "MAG_SDEPTH",
    "MAG_QUALCO",
    "GRA_OBS",
    "EOTVOS",
    "FREEAIR",
    "GRA_QUALCO",
    "LINEID",
    "POINTID",
)
#: Numeric fields -> (unit of the column returned, factor from the file's unit).
NUMERIC = {
    "LAT": ("rad", np.pi / 180.0),
    "LON": ("rad", np.pi / 180.0),
    "POS_TYPE": ("1", 1.0),
    "NAV_QUALCO": ("1", 1.0),
    "BAT_TTIME": ("s", 1.0),
    "CORR_DEPTH": ("m", 1.0),
    "BAT_CPCO": ("1", 1.0),
    "BAT_TYPCO": ("1", 1.0),
    "BAT_QUALCO": ("1", 1.0),
    "MAG_TOT": ("nT", 1.0),
    "MAG_TOT2": ("nT", 1.0),
    "MAG_RES": ("nT", 1.0),
    "MAG_RESSEN": ("1", 1.0),
    "MAG_DICORR": ("nT", 1.0),
    "MAG_SDEPTH": ("m", 1.0),
    "MAG_QUALCO": ("1", 1.0),
    "GRA_OBS": ("m/s^2", MGAL),
    "EOTVOS": ("m/s^2", MGAL),
    "FREEAIR": ("m/s^2", MGAL),
    "GRA_QUALCO": ("1", 1.0),
}


def _time_ns(date: str, hhmm: str, tz: str) -> int:
    date = date.strip()
    if len(date) != 8 or not date.isdigit():
        raise ValueError("DATE is not yyyymmdd")
    whole, _, frac = hhmm.strip().partition(".")
    if not whole.isdigit() or len(whole) > 4 or (frac and not frac.isdigit()):
        raise ValueError("TIME is not hhmm[.fraction]")
    whole = whole.zfill(4)
    hour, minute = int(whole[:2]), int(whole[2:])
    # fraction of a minute, exact to the ns for up to 9 digits
    frac_ns = (int((frac + "0" * 12)[:12]) * 60 * NS) // 10**12 if frac else 0
    t = civil_to_ns(int(date[:4]), int(date[4:6]), int(date[6:]), hour, minute, "0") + frac_ns
    tz = tz.strip()
    if tz:
        tz_h = float(tz)
        if not -13.0 <= tz_h <= 14.0:
            raise ValueError("TIMEZONE outside -13..14 h")
        t += int(round(tz_h * 3600.0)) * NS
    return t


def read_mgd77t(path) -> "FormatTable":  # noqa: F821 (doc name)
    """Read an NCEI MGD77T data file (``.m77t``).

    Parameters
    ----------
    path : path-like

    Returns
    -------
    FormatTable
        ``format='mgd77t'``; columns listed in the module docstring; time UTC.  Rows whose
        date/time, position or a numeric field does not parse are skipped and counted.

    Raises
    ------
    DataError
        The file cannot be read, the header row is not MGD77T (names the missing fields), or
        fewer than half the rows are records.
    """
    path = os.fspath(path)
    lines = read_lines(path)
    tally = LineTally(path)
    header_idx = next((i for i, ln in enumerate(lines) if ln.strip()), None)
    if header_idx is None:
        raise DataError(f"{path}: empty file, expected an MGD77T header row")
    header = [h.strip().upper() for h in lines[header_idx].split("\t")]
    missing = [f for f in ("SURVEY_ID", "DATE", "TIME", "LAT", "LON") if f not in header]
    if missing:
        raise DataError(
            f"{path}: line {header_idx + 1}: not an MGD77T header row (tab-separated field names); "
            f"missing {', '.join(missing)}"
        )
    col = {name: i for i, name in enumerate(header)}
    idx = {name: col[name] for name in NUMERIC if name in col}
    i_tz, i_date, i_time = col.get("TIMEZONE"), col["DATE"], col["TIME"]
    times = []
    vals = {name: [] for name in idx}
    survey = None
    nf = len(header)
    for n, ln in enumerate(lines[header_idx + 1 :], start=header_idx + 2):
        if not ln.strip():
            continue
        tally.n_lines += 1
        f = ln.split("\t")
        if len(f) > nf:
            tally.bad(n, f"{len(f)} fields, header has {nf}", ln)
            continue
        f += [""] * (nf - len(f))
        try:
            t = _time_ns(f[i_date], f[i_time], f[i_tz] if i_tz is not None else "")
        except ValueError as exc:
            tally.bad(n, f"bad DATE/TIME/TIMEZONE ({exc})", ln)
            continue
        try:
            row = {}
            for name, i in idx.items():
                s = f[i].strip()
                row[name] = float(s) if s else np.nan
        except ValueError:
            tally.bad(n, f"unparsable number in {name}", ln)
            continue
        lat, lon = row.get("LAT"), row.get("LON")
        if not (np.isfinite(lat) and np.isfinite(lon)) or abs(lat) > 90 or abs(lon) > 180:
            tally.bad(n, "no or impossible position", ln)
            continue
        survey = survey or f[col["SURVEY_ID"]].strip()
        times.append(t)
        for name in idx:
            vals[name].append(row[name])
    cols = {name.lower(): np.asarray(v, float) * NUMERIC[name][1] for name, v in vals.items()}
    units = {name.lower(): NUMERIC[name][0] for name in idx}
    notes = []
    if "GRA_OBS" in idx:
        ng = int(np.isfinite(cols["gra_obs"]).sum())
        notes.append(f"{path}: GRA_OBS on {ng} of {len(times)} records")
    return finish(path, "mgd77t", tally, times, cols, units, notes, {"survey_id": survey})


def read_mgd77t_header(path) -> dict:
    """Read an MGD77T header file (``.h77t``): field name -> value (str; empty values omitted).

    Useful keys: ``G_FORMU_CO`` (normal gravity formula code: 1 Heiskanen 1924, 2 IGF1930,
    3 IGF1967, 4 other), ``GRAV_INSTR``, ``PLATFORM``.

    Raises
    ------
    DataError
        Not two tab-separated rows with a ``SURVEY_ID`` field.
    """
    path = os.fspath(path)
    rows = [r for r in csv.reader(read_lines(path), delimiter="\t") if any(c.strip() for c in r)]
    if len(rows) < 2 or "SURVEY_ID" not in [c.strip().upper() for c in rows[0]]:
        raise DataError(f"{path}: line 1: not an MGD77T header file (expected a SURVEY_ID column and one data row)")
    return {k.strip().upper(): v.strip() for k, v in zip(rows[0], rows[1]) if v.strip()}


#: MGD77 ``G_FORMU_CO`` -> formula name of :func:`gravsurvey.geodesy.normal_gravity_formula`.
GRAVITY_FORMULA_CODES = {"2": "IGF1930", "3": "IGF1967"}
