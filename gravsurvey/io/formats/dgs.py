"""Dynamic Gravity Systems AT1M/AT1A marine and airborne gravimeter files.

Three layouts:

* **Processed "laptop" file** (:func:`read_dgs_laptop`): 26 comma-separated fields per line
  (DGS's own header names them, e.g. in the Sikuliaq files)::

      0 QC_Gravity  1 Gravity  2 Long accel  3 Cross accel  4 Beam  5 Sensor temp  6 Status
      7 Checksum  8 Pressure  9 Etemp  10 Ve  11 Vcc  12 Al  13 Ax  14 Latitude  15 Longitude
      16 Speed  17 Course  18 VMOND  19..24 Year Month Day Hour Minute Second  25 NumLine

  optionally behind a logger prefix (``grav_dgs_33_proc<TAB>2024-12-13T00:00:00.4059Z<TAB>``,
  ``03/12/2022,16:04:07.033,``) and after ``#`` header lines.
* **Raw serial string** (:func:`read_dgs_raw`): ``$AT1M_<fw>_<counter>,`` then 18 integer
  fields ``gravity long cross beam temp pressure etemp vcc ve al ax status checksum`` (A/D
  counts), ``latitude longitude speed course`` and a time field (``yyyymmddhhmmss`` when the
  meter's clock is GNSS-synchronised, else a counter), optionally behind a logger prefix.
* **AT1A airborne CSV** (:func:`read_at1a`, the DGP sample layout): ``gravity long_accel
  cross_accel beam temp status pressure etemp gps_week gps_sow``.

Columns of the laptop file (SI where the unit is physical):

=================== ============ ==========================================================
column              unit         meaning
=================== ============ ==========================================================
gravity             m/s^2        the meter's raw gravity (Gravity, meter units ~ mGal x 1e-5;
                                 carries the meter's unknown offset: tie to a base station)
gravity_qc          m/s^2        QC_Gravity (the meter's own filtered output)
long_accel,         meter units  long and cross accelerometers
cross_accel
beam                meter units  beam position
sensor_temp         degC
status              1            status bit field (integer value)
pressure            meter units
etemp               degC         electronics temperature
ve, vcc, al, ax     meter units  cross-coupling monitors (as in the file)
lat, lon            rad          the meter's GNSS position (NaN where 0/0 = no GNSS)
speed               m/s          (file: knots)
course              rad          (file: degrees true)
logger_time_ns      ns           in ``meta`` when a logger prefix is present
=================== ============ ==========================================================

Time (``time_source``): ``'meter'`` = the meter's Year..Second fields, ``'logger'`` = the prefix
stamp, ``'auto'`` (default) = the meter's when every line has them, else the logger's.  When
both exist, ``meta['logger_minus_meter_s']`` gives the median offset (a meter clock that is not
synchronised shows up here, e.g. -12.8 s on the Thompson sample).
"""

from __future__ import annotations

import os

import numpy as np

from gravsurvey.errors import ConfigError, DataError

from .common import KNOT, MGAL, NS, LineTally, civil_to_ns, finish, parse_logger_stamp, read_lines, week_sow_to_unix_ns

#: Laptop-file fields 0..18 (numeric) with (column name, unit, factor to that unit).
LAPTOP_FIELDS = (
    ("gravity_qc", "m/s^2", MGAL),
    ("gravity", "m/s^2", MGAL),
    ("long_accel", "meter units", 1.0),
    ("cross_accel", "meter units", 1.0),
    ("beam", "meter units", 1.0),
    ("sensor_temp", "degC", 1.0),
    ("status", "1", 1.0),
    (None, "", 1.0),  # checksum
    ("pressure", "meter units", 1.0),
    ("etemp", "degC", 1.0),
    ("ve", "meter units", 1.0),
    ("vcc", "meter units", 1.0),
    ("al", "meter units", 1.0),
    ("ax", "meter units", 1.0),
    ("lat", "rad", np.pi / 180.0),
    ("lon", "rad", np.pi / 180.0),
    ("speed", "m/s", KNOT),
    ("course", "rad", np.pi / 180.0),
    ("vmond", "meter units", 1.0),
)
N_LAPTOP = 26
#: Raw serial integer fields after the ``$AT1M_..`` tag (A/D counts).
RAW_FIELDS = (
    "gravity",
    "long_accel",
    "cross_accel",
    "beam",
    "temp",
    "pressure",
    "etemp",
    "vcc",
    "ve",
    "al",
    "ax",
    "status",
    "checksum",
)
TIME_SOURCES = ("auto", "meter", "logger")
_NONE = np.iinfo(np.int64).min


def _split_prefix(first_field: str) -> tuple[str, str]:
    """Split ``'name<TAB>stamp<TAB>9382.77'`` into (prefix, number text)."""
    parts = first_field.rsplit(None, 1)
    if len(parts) == 2:
        return parts[0], parts[1]
    return "", first_field


def _pick_time(path, meter_ns, logger_ns, time_source, what="meter"):
    meter_ns = np.asarray(meter_ns, dtype=np.int64)
    logger_ns = np.asarray(logger_ns, dtype=np.int64)
    have_m = meter_ns != _NONE
    have_l = logger_ns != _NONE
    use = time_source
    if use == "auto":
        use = what if have_m.all() else ("logger" if have_l.all() else what)
    src = meter_ns if use == what else logger_ns
    have = have_m if use == what else have_l
    if not have.all():
        raise DataError(
            f"{path}: {int((~have).sum())} of {len(src)} records have no {use} time stamp (time_source {time_source})"
        )
    notes, meta = [], {"time_source": use}
    both = have_m & have_l
    if both.any():
        off = float(np.median(logger_ns[both] - meter_ns[both]) / NS)
        meta[f"logger_minus_{what}_s"] = off
        notes.append(f"{path}: time from the {use} clock; logger - {what} = {off:+.3f} s (median)")
    else:
        notes.append(f"{path}: time from the {use} clock")
    if have_l.any():
        meta["logger_time_ns"] = np.where(have_l, logger_ns, 0)
    return src, notes, meta


def _check_source(time_source):
    if time_source not in TIME_SOURCES:
        raise ConfigError(f"dgs time_source: expected one of {', '.join(TIME_SOURCES)}, got {time_source!r}")


def read_dgs_laptop(path, *, time_source: str = "auto") -> "FormatTable":  # noqa: F821
    """Read a DGS AT1M/AT1A processed ("laptop") file.

    Parameters
    ----------
    path : path-like
    time_source : {'auto', 'meter', 'logger'}
        See the module docstring.

    Returns
    -------
    FormatTable
        ``format='dgs_laptop'``; columns in the module docstring.  Lines with fewer than 26
        fields, unparsable numbers or an impossible date are skipped and counted; positions
        0/0 become NaN (counted in a note).

    Raises
    ------
    DataError
        Unreadable file, fewer than half the content lines are laptop records (names the first
        bad line), or the chosen clock is missing.
    """
    _check_source(time_source)
    path = os.fspath(path)
    tally = LineTally(path)
    vals = [[] for _ in LAPTOP_FIELDS]
    meter, logger = [], []
    pre_notes = []
    kind = None  # logger stamp style of the previous line
    for n, ln in enumerate(read_lines(path, pre_notes), start=1):
        s = ln.strip()
        if not s or s.startswith("#"):
            continue
        tally.n_lines += 1
        f = s.split(",")
        if len(f) < N_LAPTOP:
            tally.bad(n, f"{len(f)} comma-separated fields, expected {N_LAPTOP}", s)
            continue
        pre = ",".join(f[: len(f) - N_LAPTOP])
        f = f[len(f) - N_LAPTOP :]
        p2, f[0] = _split_prefix(f[0])
        prefix = (pre + "," + p2) if pre and p2 else (pre or p2)
        try:
            nums = [float(x) for x in f[:19]]
            y, mo, d, h, mi = (int(float(x)) for x in f[19:24])
            t = civil_to_ns(y, mo, d, h, mi, f[24].strip())
        except ValueError as exc:
            tally.bad(n, f"unparsable field ({exc})", s)
            continue
        if not all(np.isfinite(nums)):
            tally.bad(n, "non-finite number", s)
            continue
        st = parse_logger_stamp(prefix, kind) if prefix.strip() else None
        kind = st[1] if st else kind
        if prefix.strip() and st is None:
            tally.bad(n, "unrecognised text before the record", s)
            continue
        meter.append(t if y >= 1990 else _NONE)
        logger.append(st[0] if st else _NONE)
        for i, v in enumerate(nums):
            vals[i].append(v)
    tally.check_enough(len(meter), "DGS laptop")
    time_ns, notes, meta = _pick_time(path, meter, logger, time_source)
    notes = pre_notes + notes
    cols, units = {}, {}
    for (name, unit, fac), v in zip(LAPTOP_FIELDS, vals):
        if name is None:
            continue
        cols[name] = np.asarray(v, float) * fac
        units[name] = unit
    nopos = (cols["lat"] == 0) & (cols["lon"] == 0)
    if nopos.any():
        cols["lat"][nopos] = np.nan
        cols["lon"][nopos] = np.nan
        notes.append(f"{path}: {int(nopos.sum())} of {len(nopos)} records have position 0/0 (no GNSS): set to NaN")
    return finish(path, "dgs_laptop", tally, list(time_ns), cols, units, notes, meta)


def read_dgs_raw(path, *, time_source: str = "auto") -> "FormatTable":  # noqa: F821
    """Read a DGS AT1M raw serial log (``$AT1M_...`` strings).

    Parameters
    ----------
    path : path-like
    time_source : {'auto', 'meter', 'logger'}
        'meter': the string's time field when it is ``yyyymmddhhmmss``; see the module docstring.

    Returns
    -------
    FormatTable
        ``format='dgs_raw'``; columns ``gravity long_accel cross_accel beam temp pressure etemp
        vcc ve al ax status`` in A/D counts (unit ``counts``: converting them needs the meter's
        calibration, e.g. ``GravCal`` of its ``.ini``), ``counter`` (the string's sequence
        number), ``lat lon`` (rad, NaN for 0/0), ``speed`` (m/s), ``course`` (rad).  Strings with
        a wrong field count or non-integer counts are skipped and counted.

    Raises
    ------
    DataError
        As :func:`read_dgs_laptop`.
    """
    _check_source(time_source)
    path = os.fspath(path)
    tally = LineTally(path)
    raw = [[] for _ in RAW_FIELDS]
    counter, pos = [], []
    meter, logger = [], []
    pre_notes = []
    kind = None  # logger stamp style of the previous line
    for n, ln in enumerate(read_lines(path, pre_notes), start=1):
        s = ln.strip()
        if not s or s.startswith("#"):
            continue
        tally.n_lines += 1
        k = s.find("$AT1")
        if k < 0:
            tally.bad(n, "no $AT1 string", s)
            continue
        f = s[k:].split(",")
        if len(f) != 19:
            tally.bad(n, f"{len(f)} fields in the $AT1 string, expected 19", s)
            continue
        try:
            tag = f[0].split("_")
            cnt = int(tag[-1]) if len(tag) >= 3 else -1
            ints = [int(x) for x in f[1:14]]
            p = [float(x) for x in f[14:18]]
        except ValueError as exc:
            tally.bad(n, f"unparsable field ({exc})", s)
            continue
        prefix = s[:k]
        st = parse_logger_stamp(prefix, kind) if prefix.strip() else None
        kind = st[1] if st else kind
        if prefix.strip() and st is None:
            tally.bad(n, "unrecognised text before the $AT1 string", s)
            continue
        ts = f[18].strip()
        t_m = _NONE
        if len(ts) == 14 and ts.isdigit() and ts[:2] in ("19", "20"):
            try:
                t_m = civil_to_ns(int(ts[:4]), int(ts[4:6]), int(ts[6:8]), int(ts[8:10]), int(ts[10:12]), ts[12:14])
            except ValueError:
                t_m = _NONE
        meter.append(t_m)
        logger.append(st[0] if st else _NONE)
        counter.append(cnt)
        for i, v in enumerate(ints):
            raw[i].append(v)
        pos.append(p)
    tally.check_enough(len(meter), "DGS raw serial")
    time_ns, notes, meta = _pick_time(path, meter, logger, time_source)
    notes = pre_notes + notes
    cols = {name: np.asarray(v, float) for name, v in zip(RAW_FIELDS, raw) if name != "checksum"}
    units = {name: "counts" for name in cols}
    units["status"] = "1"
    pos = np.asarray(pos, float).reshape(-1, 4)
    nopos = (pos[:, 0] == 0) & (pos[:, 1] == 0)
    lat = np.where(nopos, np.nan, np.radians(pos[:, 0]))
    lon = np.where(nopos, np.nan, np.radians(pos[:, 1]))
    cols.update(
        counter=np.asarray(counter, float), lat=lat, lon=lon, speed=pos[:, 2] * KNOT, course=np.radians(pos[:, 3])
    )
    units.update(counter="1", lat="rad", lon="rad", speed="m/s", course="rad")
    if nopos.any():
        notes.append(f"{path}: {int(nopos.sum())} of {len(nopos)} records have position 0/0 (no GNSS): set to NaN")
    return finish(path, "dgs_raw", tally, list(time_ns), cols, units, notes, meta)


#: AT1A CSV columns (DGP sample layout) with (unit, factor).
AT1A_FIELDS = (
    ("gravity", "m/s^2", MGAL),
    ("long_accel", "meter units", 1.0),
    ("cross_accel", "meter units", 1.0),
    ("beam", "meter units", 1.0),
    ("temp", "degC", 1.0),
    ("status", "1", 1.0),
    ("pressure", "meter units", 1.0),
    ("etemp", "degC", 1.0),
)


def read_at1a(path) -> "FormatTable":  # noqa: F821
    """Read a DGS AT1A airborne CSV (``gravity, long_accel, cross_accel, beam, temp, status,
    pressure, etemp, gps_week, gps_sow``; no header; GPS time).

    Returns
    -------
    FormatTable
        ``format='at1a'``; columns as :data:`AT1A_FIELDS` (gravity in m/s^2 with the meter's
        offset); time UTC from GPS week/seconds of week with the leap-second table
        (:func:`~gravsurvey.io.formats.common.gps_leap_seconds`).  Missing samples are not
        invented: a gap stays a gap (DGP fills them with NaN rows).

    Raises
    ------
    DataError
        Unreadable file, or fewer than half the lines are 10-field numeric records.
    """
    path = os.fspath(path)
    tally = LineTally(path)
    vals = [[] for _ in AT1A_FIELDS]
    times = []
    pre_notes = []
    for n, ln in enumerate(read_lines(path, pre_notes), start=1):
        s = ln.strip()
        if not s or s.startswith("#"):
            continue
        tally.n_lines += 1
        f = s.split(",")
        if len(f) != 10:
            tally.bad(n, f"{len(f)} fields, expected 10", s)
            continue
        try:
            nums = [float(x) for x in f[:8]]
            week = int(f[8])
            t = week_sow_to_unix_ns(week, f[9].strip())
        except ValueError as exc:
            tally.bad(n, f"unparsable field ({exc})", s)
            continue
        times.append(t)
        for i, v in enumerate(nums):
            vals[i].append(v)
    cols = {name: np.asarray(v, float) * fac for (name, _, fac), v in zip(AT1A_FIELDS, vals)}
    units = {name: unit for name, unit, _ in AT1A_FIELDS}
    return finish(
        path,
        "at1a",
        tally,
        times,
        cols,
        units,
        pre_notes + [f"{path}: time: GPS week/seconds of week, converted to UTC"],
    )
