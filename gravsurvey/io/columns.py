"""Which columns of a vendor CSV are which channel's quantities: a suggestion from the header.

``gravsurvey inspect`` on a CSV whose header holds none of gravsurvey's own column names
(docs/input-formats.md) reads the names the way a person would - ``IMU::Accel::X [m/s^2]``,
``acc_x``, ``GyroZ (deg/s)``, ``GNSS1::PosLla::latitude [deg]``, ``GpsWeek`` with ``GpsTow [s]`` -
and proposes the flight's ``csv`` settings (columns, units, time format) for the user to check.
It only suggests: nothing is read with it unless the user puts it in the config.
"""

from __future__ import annotations

import re

__all__ = ["suggest_csv_settings", "suggestion_yaml"]

#: Unit text in a column name (in brackets or parentheses) -> gravsurvey's unit name, per kind.
_UNITS = {
    "accel": {"m/s^2": "m/s^2", "m/s2": "m/s^2", "m/s/s": "m/s^2", "mps2": "m/s^2", "g": "g", "mgal": "mGal"},
    "gyro": {"rad/s": "rad/s", "deg/s": "deg/s", "dps": "deg/s", "deg/h": "deg/h", "°/s": "deg/s"},
    "dvel": {"m/s": "m/s"},
    "dang": {"rad": "rad", "deg": "deg", "°": "deg"},
}
#: Words that make an acceleration column something other than the specific force.
_NOT_SPECIFIC_FORCE = {"linear", "lin", "ecef", "ned", "enu", "nav", "free", "mag", "magnetic"}


def _split(name: str):
    """``(tokens, unit)`` of a column name: lower-case words (camelCase split) and the unit text
    in trailing brackets or parentheses (lower case, spaces removed; '' when none)."""
    m = re.search(r"[\[(]([^\])]*)[\])]\s*$", name)
    unit = m.group(1).strip().lower().replace(" ", "") if m else ""
    base = name[: m.start()] if m else name
    base = re.sub(r"([a-z0-9])([A-Z])", r"\1 \2", base)
    return [t for t in re.split(r"[^a-z0-9]+", base.lower()) if t], unit


def _axis(tokens):
    """'x', 'y' or 'z' when the name ends with an axis (``acc_x``, ``AccelX``), else None."""
    if tokens and tokens[-1] in ("x", "y", "z"):
        return tokens[-1]
    if tokens and len(tokens[-1]) > 1 and tokens[-1][-1] in "xyz" and tokens[-1][:-1] in ("acc", "gyr", "w", "f", "a"):
        return tokens[-1][-1]
    return None


def _kind(tokens):
    """'accel', 'gyro', 'dvel' (velocity increment), 'dang' (angle increment) or None."""
    words = set(tokens[:-1]) | {tokens[-1][:-1]} if tokens else set()
    joined = "".join(tokens)
    if "delta" in words or joined.startswith(("dv", "dtheta")):
        if words & {"vel", "velocity", "v"} or joined.startswith("dv"):
            return "dvel"
        if words & {"theta", "angle", "ang"} or joined.startswith("dtheta"):
            return "dang"
        return None
    if words & _NOT_SPECIFIC_FORCE:
        return None
    if words & {"accel", "acc", "accelerometer", "acceleration", "specific", "f", "a"} or "accel" in joined:
        return "accel"
    if (
        words & {"gyro", "gyr", "gyroscope", "omega", "w"}
        or "gyro" in joined
        or ("angular" in words and "rate" in words)
    ):
        return "gyro"
    return None


def _unit(kind, units_seen):
    for u in units_seen:
        if u in _UNITS[kind]:
            return _UNITS[kind][u]
    return None


def _pick(cands):
    """The candidate with the fewest words (``Accel`` before ``UncompAccel`` before ``IMU::...``)."""
    return min(cands, key=lambda c: (len(c[1]), c[0])) if cands else None


def suggest_csv_settings(header) -> dict:
    """A suggested ``csv`` section for a CSV with these column names.

    Parameters
    ----------
    header : list of str
        The CSV's column names.

    Returns
    -------
    dict
        ``columns`` (role -> quantity -> column name or [week, seconds] names), ``units``
        (``accel``, ``gyro``, ``height``, ``latlon`` as found), ``time_format``, and ``notes`` (what was
        chosen among several candidates, what could not be placed). Empty ``columns`` when
        nothing was recognised.
    """
    parsed = [(name, *_split(name)) for name in header]
    notes = []

    # time: GPS week + seconds of week, else one time column
    def gps(words, units_ok=("", "s")):
        # a GPS column before a receiver's own (``GpsWeek`` before ``GNSS1::Week``), seconds
        # before nanoseconds (gps_week_sow reads seconds of week)
        cands = [(n, t, u) for n, t, u in parsed if t and t[-1] in words and u in units_ok]
        return min(cands, key=lambda c: ("gps" not in c[1], len(c[1]), c[0])) if cands else None

    week = gps(("week", "gpsweek", "wn"))
    tow = gps(("tow", "sow", "gpstow", "seconds"))
    cycle = gps(("cycle", "gpscycle"))
    time_cols, time_format = None, None
    if week and tow:
        time_cols = [c[0] for c in (cycle, week, tow) if c is not None]
        time_format = "gps_week_sow"
    else:
        cands = [
            (n, t, u)
            for n, t, u in parsed
            if t and (t[-1] in ("time", "timestamp", "t", "stamp", "utc") or "".join(t) in ("timens", "times"))
        ]
        if cands:
            n, t, u = min(cands, key=lambda c: (len(c[1]), c[0]))
            time_cols = n
            time_format = "ns" if u == "ns" or t[-1] == "ns" else "s"
            if u not in ("ns", "s", ""):
                notes.append(f"time column {n!r} is in {u!r}: gravsurvey reads ns, s, GPS week/seconds or ISO 8601")
    columns: dict = {}
    units: dict = {}
    # IMU: three axes of the specific force (or velocity increments) and of the rate (or angle increments)
    by = {}
    for n, t, u in parsed:
        ax, k = _axis(t), _kind(t)
        if ax and k:
            by.setdefault(k, {}).setdefault(ax, []).append((n, t, u))
    imu = {}
    for force, rate in (("accel", "gyro"), ("dvel", "dang")):
        if all(by.get(force, {}).get(a) for a in "xyz") and all(by.get(rate, {}).get(a) for a in "xyz"):
            f = {a: _pick([(n, t) for n, t, u in by[force][a]])[0] for a in "xyz"}
            w = {a: _pick([(n, t) for n, t, u in by[rate][a]])[0] for a in "xyz"}
            seen_f = [u for a in "xyz" for n, t, u in by[force][a] if n == f[a]]
            seen_w = [u for a in "xyz" for n, t, u in by[rate][a] if n == w[a]]
            imu = {**{f"f{a}": f[a] for a in "xyz"}, **{f"w{a}": w[a] for a in "xyz"}}
            units["accel"] = _unit(force, seen_f) or ("m/s" if force == "dvel" else "m/s^2")
            units["gyro"] = _unit(rate, seen_w) or ("rad" if rate == "dang" else "rad/s")
            if force == "dvel" and "accel" in by:
                notes.append("the file also has rate columns; the increments were chosen only for lack of them")
            others = [n for a in "xyz" for n, t, u in by[force][a] + by[rate][a] if n not in imu.values()]
            if others:
                notes.append(f"other candidates for the IMU: {', '.join(others)}")
            if not _unit(force, seen_f) or not _unit(rate, seen_w):
                notes.append("an IMU unit is not in the column names: check units.accel and units.gyro")
            break
    if imu:
        columns["imu"] = {"time": time_cols, **imu} if time_cols else imu
        notes.append(
            "the column names do not say the IMU's axes: imu_axes is FLU unless given (VectorNav, Xsens, "
            "iMAR, NovAtel: FRD)"
        )

    # GNSS: latitude, longitude, height (a GNSS or GPS column before an INS one)
    def geo(words, last_only=("h",)):
        cands = [
            (n, t, u)
            for n, t, u in parsed
            if t and (t[-1] in words or any(x in words and x not in last_only for x in t[:-1]))
        ]
        if not cands:
            return None
        return min(cands, key=lambda c: (not ({"gnss", "gps", "gnss1", "gps1"} & set(c[1])), "ins" in c[1], len(c[1])))

    lat = geo(("lat", "latitude", "phi"))
    lon = geo(("lon", "long", "longitude", "lng", "lambda"))
    hgt = geo(("alt", "altitude", "height", "h", "hae", "hell", "ell", "ellipsoidal"))
    if lat and lon and hgt:
        columns["gnss"] = {"lat": lat[0], "lon": lon[0], "height": hgt[0]}
        if time_cols:
            columns["gnss"] = {"time": time_cols, **columns["gnss"]}
        in_rad = [c[2] in ("rad", "radians") for c in (lat, lon)]
        if all(in_rad):
            units["latlon"] = "rad"
        for c in (lat, lon):
            if c[2] and c[2] not in ("deg", "degrees", "°") and not all(in_rad):
                notes.append(
                    f"{c[0]!r} is in {c[2]!r}: gravsurvey reads latitude and longitude in degrees (or radians, "
                    "units.latlon: rad)"
                )
        if hgt[2] in ("ft", "feet"):
            units["height"] = "ft"
        if {"msl", "geoid", "orthometric"} & set(hgt[1]):
            notes.append(f"{hgt[0]!r} looks like a height above sea level: the GNSS height must be ellipsoidal")
    if "gnss" not in columns:
        # positions as Earth-fixed X, Y, Z (``GNSS1::PosEcef::X [m]``, ``ecef_x``)
        xyz = {}
        for a in "xyz":
            cands = [
                (n, t)
                for n, t, u in parsed
                if t
                and _axis(t) == a
                and u in ("", "m")
                and any("ecef" in w for w in t[:-1])
                and not (set(t) & {"vel", "velocity", "acc", "accel"})
            ]
            if cands:
                xyz[a] = _pick(cands)[0]
        if len(xyz) == 3:
            columns["gnss"] = ({"time": time_cols} if time_cols else {}) | xyz
            notes.append("GNSS positions as ECEF X, Y, Z (m); the heights are taken from them")
            if not hgt:
                columns["altimeter"] = ({"time": time_cols} if time_cols else {}) | xyz
    if hgt:
        # the GNSS height is the altimeter when nothing else is
        columns["altimeter"] = {"height": hgt[0]}
        if time_cols:
            columns["altimeter"] = {"time": time_cols, "height": hgt[0]}
    return {"columns": columns, "units": units, "time_format": time_format, "notes": notes}


def suggestion_yaml(suggestion: dict, indent: str = "  ") -> list:
    """The suggested ``csv`` section as YAML lines (flow style per channel), for the report."""
    import json

    if not suggestion.get("columns"):
        return []
    out = ["csv:"]
    if suggestion.get("time_format"):
        out.append(f"{indent}time_format: {suggestion['time_format']}")
    out.append(f"{indent}columns:")
    for role, cols in suggestion["columns"].items():
        body = ", ".join(f"{k}: {json.dumps(v)}" for k, v in cols.items())
        out.append(f"{indent * 2}{role}: {{{body}}}")
    if suggestion.get("units"):
        out.append(f"{indent}units: {{{', '.join(f'{k}: {v}' for k, v in suggestion['units'].items())}}}")
    return out
