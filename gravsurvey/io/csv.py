"""CSV channel reader: header row, named columns, several time formats, declared units.

Lines are split in Python (line numbers kept), each column is converted by numpy in one call
(shortest-repr floats come back exactly; integer-ns and decimal-second times are parsed as
integers, never through float64).  If a column fails to convert, a pass over that column finds
the first bad value and raises a one-line :class:`~gravsurvey.errors.DataError` naming file,
line and column.

A last line without a line end is what a logger that was stopped mid-write leaves: it is
dropped and reported (see :func:`read_csv_channel`), never read with a value cut short.
"""

from __future__ import annotations

import itertools
import os
import warnings

import numpy as np

from gravsurvey.errors import DataError, DataWarning
from gravsurvey.geodesy import STANDARD_GRAVITY_MPS2

GPS_EPOCH_UNIX_S = 315964800  # 1980-01-06T00:00:00 UTC
WEEK_NS = 604800 * 10**9
TIME_FORMATS = ("ns", "s", "gps_week_sow", "iso")

UNITS = {
    # "m/s", "rad", "deg": increments per sample (velocity, angle), as navigation-grade IMUs
    # write them; divided by the nominal sample step after the time repair
    # (gravsurvey.io.ingest.repair_and_check)
    "accel": {"m/s^2": 1.0, "g": STANDARD_GRAVITY_MPS2, "mGal": 1e-5, "m/s": 1.0},
    "gyro": {"rad/s": 1.0, "deg/s": np.pi / 180.0, "deg/h": np.pi / 180.0 / 3600.0, "rad": 1.0, "deg": np.pi / 180.0},
    "height": {"m": 1.0, "ft": 0.3048},
    # GNSS latitude and longitude: kept in degrees (``lat_deg``), so the factor is to degrees
    "latlon": {"deg": 1.0, "rad": 180.0 / np.pi},
    # gravity gradients: Eotvos (1 E = 1e-9 1/s^2) unless declared SI
    "gradient": {"E": 1e-9, "1/s^2": 1.0},
}

#: Units that are increments per sample, not rates: unit kind -> units.
INCREMENT_UNITS = {"accel": ("m/s",), "gyro": ("rad", "deg")}

# quantities per channel: name -> (unit kind or None, width)
QUANTITIES = {
    "imu": (("fx", "accel"), ("fy", "accel"), ("fz", "accel"), ("wx", "gyro"), ("wy", "gyro"), ("wz", "gyro")),
    "altimeter": (("height", "height"),),
    "gnss": (("lat", "latlon"), ("lon", "latlon"), ("height", "height")),
    "gradient": tuple((c, "gradient") for c in ("txx", "txy", "txz", "tyy", "tyz", "tzz")),
}

DEFAULT_COLUMNS = {
    "imu": {
        "time": "time_ns",
        "fx": "fx_mps2",
        "fy": "fy_mps2",
        "fz": "fz_mps2",
        "wx": "wx_radps",
        "wy": "wy_radps",
        "wz": "wz_radps",
    },
    "altimeter": {"time": "time_ns", "height": "height_m"},
    "gnss": {"time": "time_ns", "lat": "lat_deg", "lon": "lon_deg", "height": "height_m"},
    "gradient": {
        "time": "time_ns",
        "txx": "txx_eotvos",
        "txy": "txy_eotvos",
        "txz": "txz_eotvos",
        "tyy": "tyy_eotvos",
        "tyz": "tyz_eotvos",
        "tzz": "tzz_eotvos",
    },
}
#: Columns that replace a GNSS file's latitude, longitude and height when all three are given:
#: Earth-centred Earth-fixed coordinates, m (a receiver's or simulator's XYZ export), converted
#: to geodetic on WGS84 at reading (GRS80's coordinates differ by under 0.1 mm).
ECEF_QUANTITIES = ("x", "y", "z")

#: Optional lower-triangle columns of a gradient CSV (a full 9-component tensor): when all
#: three are in the header they are read and the tensor's symmetry is checked at ingestion.
GRADIENT_LOWER_COLUMNS = {"txy": "tyx_eotvos", "txz": "tzx_eotvos", "tyz": "tzy_eotvos"}
DEFAULT_GPS_TIME_COLUMNS = ["gps_week", "gps_sow"]


#: Smallest file read by pandas' C parser when it is plain (:func:`read_csv_at_once`), bytes: below,
#: the line-by-line reader takes less than importing pandas (0.25 s).
PLAIN_READ_MIN_BYTES = 8 * 2**20

#: Characters of a bad value shown in a message (a block of NUL bytes or a binary line would
#: otherwise fill kilobytes of one error line).
SHOWN_CHARS = 40


#: Repeated header lines listed by number in the note.
MAX_SHOWN_LINES = 5


def _shown(s: str) -> str:
    """``repr`` of a bad field, stripped and cut to :data:`SHOWN_CHARS` characters."""
    s = s.strip()
    return repr(s[:SHOWN_CHARS]) + (f"... ({len(s)} characters)" if len(s) > SHOWN_CHARS else "")


def _seconds_to_ns(strs, path, lines, col):
    """Decimal-second strings -> int64 ns, exactly (no float rounding)."""
    out = np.empty(len(strs), np.int64)
    for k, s in enumerate(strs):
        s = s.strip()
        neg = s.startswith("-")
        body = s[1:] if neg or s.startswith("+") else s
        ip, dot, fp = body.partition(".")
        if (
            not (ip.isdigit() or (ip == "" and fp.isdigit()))
            or (fp and not fp.isdigit())
            or len(fp) > 9
            or (not ip and not fp)
        ):
            raise DataError(
                f"{path}: line {lines[k]}, column {col!r}: expected seconds "
                f"(decimal, at most 9 fractional digits), got {_shown(s)}"
            )
        v = int(ip or "0") * 10**9 + int((fp + "000000000")[:9])
        if v >= 2**63:
            raise DataError(
                f"{path}: line {lines[k]}, column {col!r}: expected seconds, got {_shown(s)}: past the year "
                "2262 (nanoseconds declared as seconds? csv.time_format)"
            )
        out[k] = -v if neg else v
    return out


def _ns(strs, path, lines, col):
    try:
        return np.array(strs).astype(np.int64)
    except (ValueError, OverflowError):
        for k, s in enumerate(strs):
            try:
                v = int(s.strip())
                if not -(2**63) <= v < 2**63:
                    raise ValueError
            except ValueError:
                raise DataError(
                    f"{path}: line {lines[k]}, column {col!r}: expected integer nanoseconds, got {_shown(s)}"
                ) from None
        raise


def _iso(strs, path, lines, col):
    clean = []
    for k, s in enumerate(strs):
        s = s.strip()
        if s.endswith("Z"):
            s = s[:-1]
        elif s.endswith("+00:00"):
            s = s[:-6]
        if "+" in s[10:] or "-" in s[10:]:
            raise DataError(
                f"{path}: line {lines[k]}, column {col!r}: expected ISO 8601 UTC "
                f"time (ending in Z or +00:00 or no offset), got {_shown(strs[k])}"
            )
        clean.append(s)
    try:
        return np.array(clean, dtype="datetime64[ns]").astype(np.int64)
    except ValueError:
        for k, s in enumerate(clean):
            try:
                np.datetime64(s, "ns")
            except ValueError:
                raise DataError(
                    f"{path}: line {lines[k]}, column {col!r}: expected ISO 8601 "
                    f"UTC time like 2024-05-01T10:00:00.123456789Z, got "
                    f"{strs[k].strip()!r}"
                ) from None
        raise


def read_csv_channel(
    path,
    role,
    columns=None,
    time_format="ns",
    units=None,
    delimiter=",",
    gps_leap_seconds=18,
    *,
    notes=None,
    data_loss=None,
):
    """Read one channel's CSV file.

    Parameters
    ----------
    path : str or Path
    role : {"imu", "altimeter", "gnss", "gradient"}
    columns : dict, optional
        quantity -> column name (``DEFAULT_COLUMNS[role]`` completed by these; for a GNSS or
        height channel ``x``, ``y``, ``z`` all given: Earth-fixed positions, m, read instead of
        ``lat``, ``lon``, ``height`` and converted, :data:`ECEF_QUANTITIES`).  ``time`` is
        one column, or two ``[week, seconds_of_week]`` for ``gps_week_sow``, or three
        ``[cycle, week, seconds_of_week]`` for a 10-bit week with its roll-over count
        (full week = 1024 cycle + week; VectorNav's ``GpsCycle, GpsWeek, GpsTow``).
    time_format : {"ns", "s", "gps_week_sow", "iso"}
        Integer ns since the Unix epoch; decimal seconds since the Unix epoch; GPS week and
        seconds of week (GPS time, converted to UTC by ``gps_leap_seconds``); ISO 8601 UTC.
    units : dict, optional
        ``accel``, ``gyro``, ``height`` -> unit name (``UNITS``); SI when omitted.
    delimiter : str
    gps_leap_seconds : int
        GPS - UTC in s (18 since 2017-01-01).
    notes : list of str, optional
        Receives one line per repair (the dropped last line, below).  When both ``notes`` and
        ``data_loss`` are None the line is issued as a :class:`~gravsurvey.errors.DataWarning`.
    data_loss : list of str, optional
        Receives the line again when the file is evidently damaged (a last line cut short).

    Returns
    -------
    time_ns : ndarray of int64, shape (n,)
    values : dict
        IMU: ``specific_force`` (n, 3) m/s^2, ``angular_rate`` (n, 3) rad/s; altimeter:
        ``height`` (n,) m; GNSS: ``lat_deg``, ``lon_deg`` (n,) deg, ``height`` (n,) m;
        gradient: ``gradient`` (n, 9) 1/s^2, the tensor row by row (lower triangle mirrored
        from the upper one unless ``GRADIENT_LOWER_COLUMNS`` are all in the header).
        Values already in SI are returned bit-exactly as written.

    Raises
    ------
    DataError
        Missing file or column, unparsable value (names file, line, column).

    Notes
    -----
    A last data line with no line end (the file cut while it was written) is dropped: with
    fewer fields than the header or a value that does not parse it is cut for sure
    (``"<file>: last line (line L) cut after N bytes, 1 row dropped"``, in ``notes`` and
    ``data_loss``); with every field it may still be cut inside its last number (``5.17e-05``
    cut to ``5.1`` parses), so it is dropped as well, in ``notes`` only.
    """
    path = os.fspath(path)
    cols = dict(DEFAULT_COLUMNS[role])
    if time_format == "gps_week_sow":
        cols["time"] = list(DEFAULT_GPS_TIME_COLUMNS)
    quantities = QUANTITIES[role]
    ecef = role in ("gnss", "altimeter") and set(ECEF_QUANTITIES) <= set(columns or {})
    if ecef:
        # positions as X, Y, Z: the geodetic columns are not looked for
        cols = {"time": cols["time"]}
        quantities = tuple((q, None) for q in ECEF_QUANTITIES)
    cols.update(columns or {})
    units = dict(units or {})
    plain = read_csv_at_once(path, role, cols, quantities, time_format, units, delimiter, ecef)
    if plain is not None:
        return plain
    try:
        with open(path, encoding="utf-8-sig", newline="") as fh:
            text = fh.read()
    except OSError as exc:
        raise DataError(f"{path}: cannot open ({exc.strerror})") from None
    except UnicodeDecodeError as exc:
        raise DataError(f"{path}: not UTF-8 text (byte {exc.start}); expected a CSV file") from None
    all_lines = text.splitlines()
    header = None
    data_lines, line_no, repeated = [], [], []
    for i, ln in enumerate(all_lines, start=1):
        s = ln.strip()
        if not s or s.startswith("#"):
            continue
        if header is None:
            header = [h.strip() for h in s.split(delimiter)]
            header_line = i
            continue
        if s.startswith(header[0]) and [h.strip() for h in s.split(delimiter)] == header:
            # the header again: logs joined end to end (a logger that restarted writes a new one)
            repeated.append(i)
            continue
        if delimiter != "," and "," in ln:
            # a locale with a decimal comma writes ';'- or tab-separated files: 9,81 is 9.81
            ln = ln.replace(",", ".")
        data_lines.append(ln)
        line_no.append(i)
    if repeated:
        msg = (
            f"{path}: skipped {len(repeated)} repeated header line(s) (line {', '.join(map(str, repeated[:MAX_SHOWN_LINES]))}"
            f"{' ...' if len(repeated) > MAX_SHOWN_LINES else ''}): logs joined end to end?"
        )
        _say(msg, notes, data_loss)
    cut = None  # the unterminated last data line: (line number, its text)
    if data_lines and line_no[-1] == len(all_lines) and not text.endswith(("\n", "\r")):
        if header is not None and len(data_lines[-1].split(delimiter)) <= len(header):
            cut = (line_no.pop(), data_lines.pop())
    if header is None:
        raise DataError(f"{path}: no header row (expected columns {', '.join(_flat(cols.values()))})")
    # a spreadsheet's export quotes every field: names and values are read without the quotes
    quoted = bool(header) and all(len(h) >= 2 and h[0] == h[-1] and h[0] in "\"'" for h in header)
    if quoted:
        header = [h[1:-1] for h in header]
    index = {}
    for name in _flat(cols.values()):
        if name not in header:
            # the header read as one field holding another separator, or quoted names: the file's
            # layout, not its column names, is what the config must say
            other = [d for d in (";", "\t", "|", ",") if d != delimiter and len(header) == 1 and d in header[0]]
            hint = f"the header holds {other[0]!r}: set csv.delimiter" if other else f"set csv.columns.{role}"
            raise DataError(
                f"{path}: line {header_line}: column {name!r} missing from the "
                f"header (has {', '.join(_shown(h) if len(h) > SHOWN_CHARS else h for h in header)}); {hint}"
            )
        index[name] = header.index(name)
    ncol = len(header)
    if cut is not None:
        _report_cut_line(path, cut, ncol, cols, index, time_format, delimiter, notes, data_loss)
    if data_lines and _units_row(path, data_lines[0], line_no[0], delimiter, ncol, quantities, cols, index, units):
        _say(
            f"{path}: line {line_no[0]} read as a row of units under the header and skipped",
            notes,
            data_loss,
        )
        data_lines, line_no = data_lines[1:], line_no[1:]
    n = len(data_lines)
    # split; count fields per line first so a short/long line is reported exactly
    rows = [ln.split(delimiter) for ln in data_lines]
    if quoted:
        rows = [[f.strip().strip("\"'") for f in r] for r in rows]
    for k, r in enumerate(rows):
        if len(r) != ncol:
            raise DataError(f"{path}: line {line_no[k]}: {len(r)} fields, header has {ncol}")
    tcols = cols["time"] if isinstance(cols["time"], list) else [cols["time"]]
    if time_format == "gps_week_sow" and len(tcols) not in (2, 3):
        raise DataError(
            f"{path}: time format gps_week_sow needs two time columns "
            "[week, seconds_of_week] or three [cycle, week, seconds_of_week]"
        )
    if time_format != "gps_week_sow" and len(tcols) != 1:
        raise DataError(f"{path}: time format {time_format} needs one time column")
    tstr = [[r[index[c]] for r in rows] for c in tcols]
    if time_format == "ns":
        t = _ns(tstr[0], path, line_no, tcols[0])
    elif time_format == "s":
        t = _seconds_to_ns(tstr[0], path, line_no, tcols[0])
    elif time_format == "iso":
        t = _iso(tstr[0], path, line_no, tcols[0])
    else:
        week = _ns(tstr[-2], path, line_no, tcols[-2])
        if len(tcols) == 3:
            # 10-bit week (0-1023) and the number of roll-overs (GPS ICD: cycles of 1024 weeks)
            cycle = _ns(tstr[0], path, line_no, tcols[0])
            bad = np.flatnonzero((week < 0) | (week > 1023) | (cycle < 0))
            if bad.size:
                k = int(bad[0])
                raise DataError(
                    f"{path}: line {line_no[k]}: columns {tcols[0]!r}, {tcols[1]!r}: expected a "
                    f"roll-over count >= 0 and a 10-bit week 0-1023, got {cycle[k]}, {week[k]}"
                )
            week = cycle * 1024 + week
        sow = _seconds_to_ns(tstr[-1], path, line_no, tcols[-1])
        t = (GPS_EPOCH_UNIX_S - gps_leap_seconds) * 10**9 + week * WEEK_NS + sow
    vals = {}
    for q, kind in quantities:
        c = cols[q]
        strs = [r[index[c]] for r in rows]
        try:
            v = np.array(strs, dtype=np.float64) if n else np.zeros(0)
        except ValueError:
            # an empty cell is no value (a receiver without a fix): NaN, its row dropped and
            # counted with the other non-finite ones on ingest (looked for only here: the
            # common file has none, and the conversion above is the hot path)
            strs = [x if x.strip() else "nan" for x in strs]
            try:
                v = np.array(strs, dtype=np.float64)
            except ValueError:
                v = None
        if v is None:
            for k, s in enumerate(strs):
                try:
                    float(s)
                except ValueError:
                    raise DataError(
                        f"{path}: line {line_no[k]}, column {c!r}: expected a number, got {_shown(s)}"
                    ) from None
            raise DataError(f"{path}: column {c!r}: values that do not convert to numbers")
        vals[q] = _in_si(v, kind, units)
    if role != "gradient":
        return t, _channel_values(role, vals, ecef)
    lower = {q: vals[q] for q in ("txy", "txz", "tyz")}
    if all(c in header for c in GRADIENT_LOWER_COLUMNS.values()):
        for q, c in GRADIENT_LOWER_COLUMNS.items():
            strs = [r[header.index(c)] for r in rows]
            try:
                lower[q] = _in_si(np.array(strs, dtype=np.float64), "gradient", units) if n else np.zeros(0)
            except ValueError:
                k = next(k for k, s_ in enumerate(strs) if not _is_float(s_))
                raise DataError(
                    f"{path}: line {line_no[k]}, column {c!r}: expected a number, got {_shown(strs[k])}"
                ) from None
    values = {
        "gradient": np.stack(
            [
                vals["txx"],
                vals["txy"],
                vals["txz"],
                lower["txy"],
                vals["tyy"],
                vals["tyz"],
                lower["txz"],
                lower["tyz"],
                vals["tzz"],
            ],
            axis=1,
        )
    }
    return t, values


def _in_si(values, kind, units):
    """``values`` of unit kind ``kind`` (None: no unit) in SI, by the declared ``units`` (the
    kind's first unit, SI, when none is declared); the same array when the factor is 1."""
    if kind is None:
        return values
    factor = UNITS[kind][units.get(kind, next(iter(UNITS[kind])))]
    return values * factor if factor != 1.0 else values


def _channel_values(role, vals, ecef):
    """An IMU, altimeter or GNSS channel's values from its columns (SI, as read)."""
    if ecef:
        from ..geodesy import ecef_to_geodetic

        lat, lon, h = ecef_to_geodetic(np.stack([vals["x"], vals["y"], vals["z"]], axis=1))
        vals = {"lat": np.degrees(lat), "lon": np.degrees(lon), "height": h}
    if role == "imu":
        return {
            "specific_force": np.stack([vals["fx"], vals["fy"], vals["fz"]], axis=1),
            "angular_rate": np.stack([vals["wx"], vals["wy"], vals["wz"]], axis=1),
        }
    if role == "altimeter":
        return {"height": vals["height"]}
    return {"lat_deg": vals["lat"], "lon_deg": vals["lon"], "height": vals["height"]}


def read_csv_at_once(path, role, cols, quantities, time_format, units, delimiter, ecef):
    """A plain file read at once by pandas' C parser, or None where anything in it needs the
    line-by-line reader of :func:`read_csv_channel` (which names lines and repairs).

    Plain: at least :data:`PLAIN_READ_MIN_BYTES`, ``,``-separated, ending in a line end (no line
    cut short), time as integer ns or decimal seconds in one column, every line as many fields
    as the header and every value of the used columns a number (no empty cell, short or long
    line, repeated header, row of units or garbage: any of those makes a NaN or a parse error
    here, and the careful reader takes the file from the start).  The numbers are Python's,
    bit for bit those of the careful reader (tests/test_io_csv_faults.py); a 1.13-million-line
    IMU file reads in 0.8 s and 160 MB instead of 5.5 s and 1.4 GB.

    Parameters
    ----------
    path : str
    role : {"imu", "altimeter", "gnss", "gradient"}
        ``"gradient"`` is always read line by line.
    cols : dict
        Quantity -> column name, the defaults completed by the config's.
    quantities : tuple of (str, str or None)
        The quantities read and their unit kinds (:data:`QUANTITIES`, or ECEF's).
    time_format : str
    units : dict
        Declared units per kind.
    delimiter : str
    ecef : bool
        Positions as ECEF X, Y, Z (:data:`ECEF_QUANTITIES`).

    Returns
    -------
    tuple or None
        ``(time_ns, values)`` as :func:`read_csv_channel` returns them, or None.
    """
    if role == "gradient" or delimiter != "," or time_format not in ("ns", "s") or isinstance(cols["time"], list):
        return None
    try:
        with open(path, "rb") as fh:
            fh.seek(0, os.SEEK_END)
            if fh.tell() < max(PLAIN_READ_MIN_BYTES, 1):
                return None
            fh.seek(-1, os.SEEK_END)
            if fh.read(1) not in (b"\n", b"\r"):
                return None
    except OSError:
        return None
    import pandas as pd

    tcol = cols["time"]
    used = [tcol] + [cols[q] for q, _ in quantities]
    # pandas before 3.1 parses floats exactly only with "round_trip" (3.1 deprecates the option,
    # its default being exact: 800,000 hard cases measured equal to Python's float)
    exact = {"float_precision": "round_trip"} if _version(pd.__version__) < (3, 1) else {}
    try:
        df = pd.read_csv(
            path,
            comment="#",
            # every column (not usecols: with it, a line holding more fields than the header
            # was read without a word); the time as text: read as int64, a decimal point made pandas round every stamp
            # through float64 (to 256 ns) without a word
            dtype={c: str if c == tcol else np.float64 for c in used},
            encoding="utf-8-sig",
            engine="c",
            **exact,
        )
    except (ValueError, TypeError, OverflowError, UnicodeDecodeError, pd.errors.ParserError, pd.errors.EmptyDataError):
        return None
    if len(df) == 0 or any(c not in df.columns for c in used):
        return None
    vals = {}
    for q, kind in quantities:
        v = df[cols[q]].to_numpy(np.float64)
        if np.isnan(v).any():
            return None
        vals[q] = _in_si(v, kind, units)
    strs = df[tcol].tolist()
    if any(not isinstance(x, str) for x in strs):
        return None
    try:
        t = (_ns if time_format == "ns" else _seconds_to_ns)(strs, path, [0] * len(strs), tcol)
    except (ValueError, OverflowError, DataError):
        return None
    return t, _channel_values(role, vals, ecef)


def _version(text: str) -> tuple:
    """``(major, minor)`` of a version string such as ``3.1.1`` or ``2.2.3rc1``."""
    parts = []
    for p in text.split(".")[:2]:
        digits = "".join(itertools.takewhile(str.isdigit, p))
        parts.append(int(digits or 0))
    return tuple(parts)


def _units_row(path, line, k, delimiter, ncol, quantities, cols, index, units) -> bool:
    """Whether the first data line is a row of units under the header (``s, m/s^2, deg/s``: an
    export that writes the units apart from the names): no field is a number.

    Raises
    ------
    DataError
        The row names a unit of :data:`UNITS` for a column that differs from the declared one
        (``csv.units``): the values would be read in the wrong unit.
    """
    fields = [f.strip().strip("\"'").strip("[]() ") for f in line.split(delimiter)]
    if len(fields) != ncol or not any(fields) or any(_is_float(f) for f in fields):
        return False
    for q, kind in quantities:
        if kind is None:
            continue
        text = fields[index[cols[q]]]
        known = {u.lower(): u for u in UNITS[kind]}
        said = text if text in UNITS[kind] else known.get(text.lower())
        declared = units.get(kind, next(iter(UNITS[kind])))
        if said is not None and said != declared:
            raise DataError(
                f"{path}: line {k}, column {cols[q]!r}: the row of units says {text!r}, the config "
                f"{declared!r}: set csv.units.{kind}: {said!r}"
            )
    return True


def _say(msg, notes, data_loss, stacklevel=3) -> None:
    """A repair of the file into ``notes``, or issued as a DataWarning (at the caller's caller
    ``stacklevel`` frames up) when the caller collects neither notes nor data loss."""
    if notes is None and data_loss is None:
        warnings.warn(msg, DataWarning, stacklevel=stacklevel)
    if notes is not None:
        notes.append(msg)


def _report_cut_line(path, cut, ncol, cols, index, time_format, delimiter, notes, data_loss):
    """Say that the unterminated last line was dropped, and whether it is surely cut."""
    line, text = cut
    nbytes = len(text.encode("utf-8"))
    fields = text.split(delimiter)
    sure = len(fields) < ncol
    if not sure:
        # every field present: cut for sure only if one of them does not parse
        tcols = cols["time"] if isinstance(cols["time"], list) else [cols["time"]]
        for c in _flat(cols.values()):
            s = fields[index[c]].strip()
            if c in tcols and time_format == "ns":
                ok = s.lstrip("+-").isdigit()
            elif c in tcols:
                ok = bool(s)
            else:
                ok = _is_float(s)
            sure |= not ok
    if sure:
        unit = "byte" if nbytes == 1 else "bytes"
        msg = f"{path}: last line (line {line}) cut after {nbytes} {unit}, 1 row dropped"
    else:
        msg = (
            f"{path}: last line (line {line}, {nbytes} bytes) has no line end, so its last "
            f"value may be cut short: 1 row dropped"
        )
    _say(msg, notes, data_loss, stacklevel=4)
    if sure and data_loss is not None:
        data_loss.append(msg)


def _is_float(s):
    try:
        float(s)
    except ValueError:
        return False
    return True


def _flat(items):
    out = []
    for v in items:
        out.extend(v if isinstance(v, list) else [v])
    return out


def sniff_csv_role(path):
    """Guess a CSV file's channel from its header (for ``inspect``): role, "truth" (the
    simulator's truth.csv) or None."""
    try:
        with open(path, encoding="utf-8-sig", errors="replace") as fh:
            for ln in fh:
                s = ln.strip()
                if s and not s.startswith("#"):
                    header = {h.strip() for h in s.split(",")}
                    break
            else:
                return None
    except OSError:
        return None
    if {"time_ns", "line", "disturbance_mgal"} <= header:
        return "truth"
    for role in ("imu", "gnss", "altimeter", "gradient"):
        if set(_flat(DEFAULT_COLUMNS[role].values())) <= header:
            return role
    return None
