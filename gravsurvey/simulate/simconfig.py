"""SIM.yaml: the simulator's configuration schema and its validation.

Every key, unit and default is documented in docs/simulate.md.  Validation
fills in defaults and raises :class:`gravsurvey.errors.ConfigError` with a
one-line message naming the key path (``flights[0].plan.line_length_m: ...``)
for unknown keys (with the nearest valid name), wrong types, out-of-range
values and plans that leave the survey map.
"""

from __future__ import annotations

import calendar
import copy
import datetime as _dt
import math
import numbers
import re
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from gravsurvey.errors import ConfigError
from gravsurvey.errors import check_keys as _check_keys
from gravsurvey.geodesy import ELLIPSOIDS, Ellipsoid

from .trajectory import MAP_MAX_EAST_WEST_M, MAP_MAX_NORTH_SOUTH_M, plan_extent

FORMATS = ("mcap_json", "mcap_ros2", "csv")
TRIADS = ("platform", "strapdown")
#: Highest altimeter and GNSS rate, Hz (20 Hz GNSS receivers exist; the unseen-flight suite draws 1-20 Hz).
MAX_AUX_RATE_HZ = 20.0

#: Defaults of every optional key (the schema's shape is the dict's shape).
DEFAULT_RATES = {"imu_hz": 10.0, "altimeter_hz": 1.0, "gnss_hz": 1.0, "truth_hz": None}
#: Largest wind as a fraction of the plan's speed (``plan.wind_speed_mps``; a 30-degree crab).
MAX_WIND_FRACTION = 0.5
DEFAULT_PLAN = {
    "kind": None,
    "origin_lat_deg": None,
    "origin_lon_deg": None,
    "altitude_m": 1000.0,
    "speed_mps": 50.0,
    "heading_deg": 90.0,
    "line_length_m": None,
    "duration_s": None,
    "lines": None,
    "ties": None,
    "max_bank_deg": 25.0,
    "max_roll_rate_degps": 5.0,
    "max_climb_rate_mps": 5.0,
    "static_start_s": 0.0,
    "static_end_s": 0.0,
    "ramp_s": 60.0,
    "wind_speed_mps": 0.0,
    "wind_from_deg": 0.0,
    "hold_speed": "air",
    "ground_height_m": None,
}
DEFAULT_LINES = {"count": None, "spacing_m": None, "length_m": None, "heading_deg": 90.0, "altitudes_m": None}
DEFAULT_TIES = {"count": 0, "spacing_m": 0.0, "altitude_m": None}
DEFAULT_TURBULENCE = {
    "vertical_sigma_m": 0.0,
    "horizontal_sigma_m": 0.0,
    "attitude_sigma_deg": 0.0,
    "corner_period_s": 20.0,
    "min_period_s": 2.0,
    "max_period_s": 600.0,
    "components": 40,
}
DEFAULT_SENSORS = {
    "accelerometer": {"white_sigma_mps2": 0.0, "bias_mps2": [0.0, 0.0]},
    "gravimeter": {
        "bias_mps2": 0.0,
        "markov_sigma_mps2": 0.0,
        "markov_lambda_per_s": 0.025,
        "white_sigma_mps2": 0.0,
        "drift_mgal_per_h": 0.0,
        # a tare: a step in the reading at tare_time_s from the flight's first sample (a spring
        # meter's after a shock, a strapdown gravimeter's bias jump); none while tare_mgal is 0
        "tare_mgal": 0.0,
        "tare_time_s": 0.0,
    },
    "gyro": {"bias_degph": [0.0, 0.0, 0.0], "white_drift_degph": 0.0},
    "altimeter": {"sigma_m": 0.0, "mean_m": 0.0},
    # white per-fix noise plus an optional first-order Gauss-Markov part (a real solution's
    # slowly varying error: ionosphere, troposphere, orbits, multipath), per axis
    "gnss": {
        "horizontal_sigma_m": 0.0,
        "vertical_sigma_m": 0.0,
        "horizontal_markov_sigma_m": 0.0,
        "vertical_markov_sigma_m": 0.0,
        "markov_tau_s": 600.0,
        # the antenna from the IMU on the aircraft's axes (forward, left, up), m: the fixes are
        # the antenna's, turned with the aircraft's attitude
        "antenna_m": [0.0, 0.0, 0.0],
    },
    # gravity gradiometer (seed 000); rate_hz 0 = no gradient channel (the default)
    "gradiometer": {"rate_hz": 0.0, "white_eotvos_rthz": 0.0, "markov_sigma_eotvos": 0.0, "markov_lambda_per_s": 0.001},
}
DEFAULT_PROCESSING = {
    "filter_rate_hz": 1.0,
    "lines_mode": "auto",
    "postprocess_method": "default",
    "output_dir": "out",
    # survey.yaml `model` keys overriding the simulator's matched values (e.g. the anomaly
    # prior a user would set from the area's known field); checked by the processing config
    "model": None,
}
#: Farthest a GNSS antenna may be from the IMU along any aircraft axis, m (a large aircraft's
#: antenna on the tail fin is within it).
MAX_ANTENNA_M = 30.0
TOP_KEYS = ("name", "seed", "ellipsoid", "formats", "field", "processing", "flights")
FLIGHT_KEYS = ("name", "start_utc", "triad", "rates", "plan", "turbulence", "sensors")
_NAME_RE = re.compile(r"^[A-Za-z0-9_-]+$")


@dataclass
class SimConfig:
    """A validated simulation configuration.

    Attributes
    ----------
    name : str
    seed : int
        Master seed; flight ``k`` draws from ``numpy.random.default_rng([seed, k, stream])``.
    ellipsoid : Ellipsoid
    formats : list of str
    field : dict or None
        The raw ``field`` mapping (``None``: no anomalous field).
    field_model : object or None
        :class:`gravsurvey.simulate.field.FieldModel` built from ``field``.
    processing : dict
    flights : list of dict
        Validated flights with every default filled in; ``start_unix_ns`` added
        and ``plan.line_length_m`` resolved for line plans.
    source : Path or None
        The file it came from.
    """

    name: str
    seed: int
    ellipsoid: Ellipsoid
    formats: list
    field: dict | None
    field_model: object
    processing: dict
    flights: list
    source: Path | None = None
    raw: dict = field(default_factory=dict)


def _describe(v):
    return repr(v) if isinstance(v, str) else f"{type(v).__name__} {v!r}"


def check_keys(d, allowed, path):
    """Reject unknown keys of mapping ``d`` (at key path ``path``)."""
    if not isinstance(d, dict):
        raise ConfigError(f"{path}: expected a mapping, got {_describe(d)}")
    _check_keys(d, allowed, path)


def _merge(d, defaults, path):
    """Defaults overlaid with ``d`` (unknown keys rejected); ``None`` = empty."""
    if d is None:
        d = {}
    check_keys(d, defaults, path)
    out = copy.deepcopy(defaults)
    out.update(copy.deepcopy(d))
    return out


def number(v, path, unit, lo=None, hi=None, lo_open=False, integer=False):
    """Validate a real (or integer) number in [lo, hi] (``lo_open``: (lo, hi])."""
    if isinstance(v, bool) or not isinstance(v, numbers.Real) or (integer and not isinstance(v, numbers.Integral)):
        kind = "an integer" if integer else "a number"
        raise ConfigError(f"{path}: expected {kind} ({unit}), got {_describe(v)}")
    x = int(v) if integer else float(v)
    if not math.isfinite(x):
        raise ConfigError(f"{path}: expected a finite number ({unit}), got {v!r}")
    if lo is not None and (x < lo or (lo_open and x == lo)):
        op = ">" if lo_open else ">="
        rng = f"{op} {lo:g}" + (f" and <= {hi:g}" if hi is not None else "")
        raise ConfigError(f"{path}: expected a value {rng} {unit}, got {v!r}")
    if hi is not None and x > hi:
        rng = (f">= {lo:g} and " if lo is not None else "") + f"<= {hi:g}"
        raise ConfigError(f"{path}: expected a value {rng} {unit}, got {v!r}")
    return x


def _choice(v, path, choices):
    if not isinstance(v, str) or v not in choices:
        raise ConfigError(f"{path}: expected one of {list(choices)}, got {_describe(v)}")
    return v


def _vector(v, path, n, unit):
    if not isinstance(v, (list, tuple)) or len(v) != n:
        raise ConfigError(f"{path}: expected a list of {n} numbers ({unit}), got {_describe(v)}")
    return [number(x, f"{path}[{i}]", unit) for i, x in enumerate(v)]


def parse_utc(v, path):
    """ISO 8601 UTC epoch string -> integer ns since the Unix epoch."""
    if not isinstance(v, str):
        raise ConfigError(
            f"{path}: expected an ISO 8601 UTC time string like '2024-06-01T08:00:00Z', got {_describe(v)}"
        )
    s = v.strip()
    if s.endswith("Z") or s.endswith("z"):
        s = s[:-1] + "+00:00"
    try:
        d = _dt.datetime.fromisoformat(s)
    except ValueError:
        raise ConfigError(f"{path}: expected an ISO 8601 UTC time like '2024-06-01T08:00:00Z', got {v!r}") from None
    if d.tzinfo is None:
        raise ConfigError(f"{path}: expected a time zone (e.g. a trailing 'Z' for UTC), got {v!r}")
    d = d.astimezone(_dt.timezone.utc)
    if not 1980 <= d.year <= 2200:
        raise ConfigError(f"{path}: expected a year between 1980 and 2200, got {v!r}")
    return calendar.timegm(d.timetuple()) * 1_000_000_000 + d.microsecond * 1000


#: Latitude limits of the plan, deg: the survey map (trajectory.py) is linear in latitude and
#: longitude, so its truth is exact at any latitude, but its east scale is that of the origin's
#: parallel and a line may not reach the pole.
MAX_ORIGIN_LAT_DEG = 89.0
MAX_REACH_LAT_DEG = 89.5


def _validate_plan(p, path, rates):
    given = set(p) if isinstance(p, dict) else set()
    p = _merge(p, DEFAULT_PLAN, path)
    if p["kind"] is None:
        raise ConfigError(f"{path}.kind: missing required key; expected 'line' or 'grid'")
    _choice(p["kind"], f"{path}.kind", ("line", "grid"))
    for k in ("origin_lat_deg", "origin_lon_deg"):
        if p[k] is None:
            raise ConfigError(f"{path}.{k}: missing required key (deg)")
    p["origin_lat_deg"] = number(
        p["origin_lat_deg"], f"{path}.origin_lat_deg", "deg", -MAX_ORIGIN_LAT_DEG, MAX_ORIGIN_LAT_DEG
    )
    p["origin_lon_deg"] = number(p["origin_lon_deg"], f"{path}.origin_lon_deg", "deg", -180.0, 360.0)
    p["altitude_m"] = number(p["altitude_m"], f"{path}.altitude_m", "m", -400.0, 15000.0)
    p["speed_mps"] = number(p["speed_mps"], f"{path}.speed_mps", "m/s", 1.0, 300.0)
    p["heading_deg"] = number(p["heading_deg"], f"{path}.heading_deg", "deg", -360.0, 360.0)
    p["max_bank_deg"] = number(p["max_bank_deg"], f"{path}.max_bank_deg", "deg", 0.0, 35.0, lo_open=True)
    p["max_roll_rate_degps"] = number(
        p["max_roll_rate_degps"], f"{path}.max_roll_rate_degps", "deg/s", 0.0, 30.0, lo_open=True
    )
    p["max_climb_rate_mps"] = number(
        p["max_climb_rate_mps"], f"{path}.max_climb_rate_mps", "m/s", 0.0, 30.0, lo_open=True
    )
    p["static_start_s"] = number(p["static_start_s"], f"{path}.static_start_s", "s", 0.0, 86400.0)
    p["static_end_s"] = number(p["static_end_s"], f"{path}.static_end_s", "s", 0.0, 86400.0)
    p["ramp_s"] = number(p["ramp_s"], f"{path}.ramp_s", "s", 1.0, 3600.0)
    # a wind of half the speed is a 30-degree crab, and a line flown into it at half the speed
    p["wind_speed_mps"] = number(p["wind_speed_mps"], f"{path}.wind_speed_mps", "m/s", 0.0)
    if p["wind_speed_mps"] > MAX_WIND_FRACTION * p["speed_mps"]:
        raise ConfigError(
            f"{path}.wind_speed_mps: {p['wind_speed_mps']:g} m/s is more than {MAX_WIND_FRACTION:g} x "
            f"{path}.speed_mps ({p['speed_mps']:g} m/s): a stronger wind needs a crab over 30 deg"
        )
    p["wind_from_deg"] = number(p["wind_from_deg"], f"{path}.wind_from_deg", "deg", -360.0, 360.0)
    _choice(p["hold_speed"], f"{path}.hold_speed", ("air", "ground"))
    if p["ground_height_m"] is not None:
        p["ground_height_m"] = number(p["ground_height_m"], f"{path}.ground_height_m", "m", -400.0, 15000.0)
        if p["static_start_s"] <= 0 and p["static_end_s"] <= 0:
            raise ConfigError(
                f"{path}.ground_height_m: the aircraft is on the ground only while parked; give "
                f"{path}.static_start_s or {path}.static_end_s (s) too"
            )
    if p["kind"] == "line":
        for k in ("lines", "ties"):
            if p[k] is not None:
                raise ConfigError(f"{path}.{k}: only allowed with {path}.kind 'grid'")
        has_len, has_dur = p["line_length_m"] is not None, p["duration_s"] is not None
        if has_len == has_dur:
            raise ConfigError(f"{path}: expected exactly one of line_length_m (m) or duration_s (s) for kind 'line'")
        if has_dur:
            p["duration_s"] = number(p["duration_s"], f"{path}.duration_s", "s", 0.0, 7 * 86400.0, lo_open=True)
            p["line_length_m"] = p["duration_s"] * p["speed_mps"]
            key = "duration_s"
        else:
            p["line_length_m"] = number(p["line_length_m"], f"{path}.line_length_m", "m", 0.0, lo_open=True)
            key = "line_length_m"
    else:
        if "heading_deg" in given:
            raise ConfigError(f"{path}.heading_deg: only allowed with {path}.kind 'line' (grids use lines.heading_deg)")
        for k in ("line_length_m", "duration_s"):
            if p[k] is not None:
                raise ConfigError(f"{path}.{k}: only allowed with {path}.kind 'line' (grids use lines.length_m)")
        if p["lines"] is None:
            raise ConfigError(
                f"{path}.lines: missing required key for kind 'grid' (count, spacing_m, length_m, heading_deg)"
            )
        g = _merge(p["lines"], DEFAULT_LINES, f"{path}.lines")
        for k in ("count", "spacing_m", "length_m"):
            if g[k] is None:
                raise ConfigError(f"{path}.lines.{k}: missing required key")
        g["count"] = number(g["count"], f"{path}.lines.count", "lines", 1, 500, integer=True)
        g["spacing_m"] = number(g["spacing_m"], f"{path}.lines.spacing_m", "m", 0.0, lo_open=True)
        g["length_m"] = number(g["length_m"], f"{path}.lines.length_m", "m", 0.0, lo_open=True)
        g["heading_deg"] = number(g["heading_deg"], f"{path}.lines.heading_deg", "deg", -360.0, 360.0)
        if g["altitudes_m"] is not None:
            alts = g["altitudes_m"]
            if not isinstance(alts, list) or not alts:
                raise ConfigError(
                    f"{path}.lines.altitudes_m: expected a non-empty list of heights (m), got {_describe(alts)}"
                )
            g["altitudes_m"] = [
                number(a, f"{path}.lines.altitudes_m[{i}]", "m", -400.0, 15000.0) for i, a in enumerate(alts)
            ]
        p["lines"] = g
        t = _merge(p["ties"], DEFAULT_TIES, f"{path}.ties")
        t["count"] = number(t["count"], f"{path}.ties.count", "lines", 0, 500, integer=True)
        t["spacing_m"] = number(t["spacing_m"], f"{path}.ties.spacing_m", "m", 0.0)
        if t["altitude_m"] is None:
            t["altitude_m"] = p["altitude_m"]
        t["altitude_m"] = number(t["altitude_m"], f"{path}.ties.altitude_m", "m", -400.0, 15000.0)
        if t["count"] > 1 and t["spacing_m"] <= 0:
            raise ConfigError(f"{path}.ties.spacing_m: expected > 0 m with {t['count']} ties")
        if (t["count"] - 1) * t["spacing_m"] > g["length_m"]:
            raise ConfigError(
                f"{path}.ties.spacing_m: {t['count']} ties at {t['spacing_m']:g} m do not fit on lines "
                f"{g['length_m']:g} m long"
            )
        if t["count"] > 0 and g["count"] < 2:
            raise ConfigError(f"{path}.ties.count: ties need at least 2 survey lines (lines.count)")
        p["ties"] = t
        key = "lines.length_m"
    east, north = plan_extent(p)
    if north > MAP_MAX_NORTH_SOUTH_M or east > MAP_MAX_EAST_WEST_M:
        raise ConfigError(
            f"{path}.{key}: the planned lines reach {east / 1000:.0f} km east-west and {north / 1000:.0f} km "
            f"north-south of the origin; the survey map allows at most {MAP_MAX_EAST_WEST_M / 1000:.0f} km and "
            f"{MAP_MAX_NORTH_SOUTH_M / 1000:.0f} km"
        )
    lat_reach = p["origin_lat_deg"] + math.degrees(north / 6.36e6) * (1 if p["origin_lat_deg"] >= 0 else -1)
    if abs(lat_reach) > MAX_REACH_LAT_DEG:
        raise ConfigError(
            f"{path}.{key}: the planned lines reach latitude {lat_reach:.2f} deg; the survey map allows "
            f"|lat| <= {MAX_REACH_LAT_DEG:g} deg"
        )
    return p


def _validate_flight(f, path, index):
    check_keys(f, FLIGHT_KEYS, path)
    f = copy.deepcopy(f)
    name = f.get("name", f"F{index + 1:02d}")
    if not isinstance(name, str) or not _NAME_RE.match(name):
        raise ConfigError(f"{path}.name: expected a name of letters, digits, '_' or '-', got {_describe(name)}")
    f["name"] = name
    if "start_utc" not in f:
        raise ConfigError(f"{path}.start_utc: missing required key (ISO 8601 UTC, e.g. '2024-06-01T08:00:00Z')")
    f["start_unix_ns"] = parse_utc(f["start_utc"], f"{path}.start_utc")
    f["triad"] = _choice(f.get("triad", "platform"), f"{path}.triad", TRIADS)
    r = _merge(f.get("rates"), DEFAULT_RATES, f"{path}.rates")
    r["imu_hz"] = number(r["imu_hz"], f"{path}.rates.imu_hz", "Hz", 1.0, 200.0)
    r["altimeter_hz"] = number(r["altimeter_hz"], f"{path}.rates.altimeter_hz", "Hz", 1.0, MAX_AUX_RATE_HZ)
    r["gnss_hz"] = number(r["gnss_hz"], f"{path}.rates.gnss_hz", "Hz", 1.0, MAX_AUX_RATE_HZ)
    if r["truth_hz"] is None:
        r["truth_hz"] = r["altimeter_hz"]
    r["truth_hz"] = number(r["truth_hz"], f"{path}.rates.truth_hz", "Hz", 0.0, r["imu_hz"], lo_open=True)
    f["rates"] = r
    if "plan" not in f:
        raise ConfigError(f"{path}.plan: missing required key")
    f["plan"] = _validate_plan(f["plan"], f"{path}.plan", r)
    t = _merge(f.get("turbulence"), DEFAULT_TURBULENCE, f"{path}.turbulence")
    tp = f"{path}.turbulence"
    t["vertical_sigma_m"] = number(t["vertical_sigma_m"], f"{tp}.vertical_sigma_m", "m", 0.0, 100.0)
    t["horizontal_sigma_m"] = number(t["horizontal_sigma_m"], f"{tp}.horizontal_sigma_m", "m", 0.0, 100.0)
    t["attitude_sigma_deg"] = number(t["attitude_sigma_deg"], f"{tp}.attitude_sigma_deg", "deg", 0.0, 10.0)
    t["corner_period_s"] = number(t["corner_period_s"], f"{tp}.corner_period_s", "s", 0.0, 1e4, lo_open=True)
    t["min_period_s"] = number(t["min_period_s"], f"{tp}.min_period_s", "s", 0.0, 1e4, lo_open=True)
    t["max_period_s"] = number(t["max_period_s"], f"{tp}.max_period_s", "s", 0.0, 1e5, lo_open=True)
    t["components"] = number(t["components"], f"{tp}.components", "sinusoids", 1, 1000, integer=True)
    if t["max_period_s"] <= t["min_period_s"]:
        raise ConfigError(f"{tp}.max_period_s: expected > min_period_s ({t['min_period_s']:g} s)")
    active = t["vertical_sigma_m"] > 0 or t["horizontal_sigma_m"] > 0 or t["attitude_sigma_deg"] > 0
    if active and t["min_period_s"] * r["imu_hz"] < 4.0:
        raise ConfigError(
            f"{tp}.min_period_s: {t['min_period_s']:g} s is under 4 IMU samples at rates.imu_hz "
            f"{r['imu_hz']:g}; expected >= {4.0 / r['imu_hz']:g} s"
        )
    f["turbulence"] = t
    s_in = f.get("sensors")
    if s_in is None:
        s_in = {}
    check_keys(s_in, DEFAULT_SENSORS, f"{path}.sensors")
    s = {}
    for sec, dflt in DEFAULT_SENSORS.items():
        sp = f"{path}.sensors.{sec}"
        d = _merge(s_in.get(sec), dflt, sp)
        for k, v in d.items():
            unit = k.rsplit("_", 1)[-1]
            if isinstance(dflt[k], list):
                d[k] = _vector(v, f"{sp}.{k}", len(dflt[k]), unit)
            elif k == "markov_lambda_per_s":
                d[k] = number(v, f"{sp}.{k}", "1/s", 0.0, 100.0, lo_open=True)
            elif k in ("mean_m",):
                d[k] = number(v, f"{sp}.{k}", "m", -1e4, 1e4)
            elif k == "markov_tau_s":
                d[k] = number(v, f"{sp}.{k}", "s", 0.0, 1e6, lo_open=True)
            elif k == "drift_mgal_per_h":
                d[k] = number(v, f"{sp}.{k}", "mGal/h", -1e3, 1e3)
            elif k == "tare_mgal":
                d[k] = number(v, f"{sp}.{k}", "mGal", -1e4, 1e4)
            else:
                d[k] = number(v, f"{sp}.{k}", unit, 0.0)
        s[sec] = d
    arm = s["gnss"]["antenna_m"]
    if max(abs(x) for x in arm) > MAX_ANTENNA_M:
        raise ConfigError(
            f"{path}.sensors.gnss.antenna_m: expected forward, left, up from the IMU within "
            f"+-{MAX_ANTENNA_M:g} m each, got {arm}"
        )
    f["sensors"] = s
    return f


def load_sim_config(source) -> SimConfig:
    """Load and validate a SIM.yaml (path) or an already parsed mapping.

    Raises
    ------
    ConfigError
        One line naming the file or key path.
    """
    path = None
    if isinstance(source, SimConfig):
        return source
    if isinstance(source, dict):
        raw = copy.deepcopy(source)
    else:
        path = Path(source)
        try:
            text = path.read_text(encoding="utf-8")
        except OSError as exc:
            raise ConfigError(f"{path}: cannot read simulation config ({exc.strerror})") from None
        try:
            raw = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise ConfigError(f"{path}: invalid YAML: {str(exc).splitlines()[0]}") from None
        if not isinstance(raw, dict):
            raise ConfigError(f"{path}: expected a mapping at the top level, got {_describe(raw)}")
    try:
        return _validate(raw, path)
    except ConfigError as exc:
        if path is not None and not str(exc).startswith(str(path)):
            raise ConfigError(f"{path}: {exc}") from None
        raise


def _validate(raw, path):
    from .field import field_model_from_dict

    check_keys(raw, TOP_KEYS, "")
    name = raw.get("name", "simulated_survey")
    if not isinstance(name, str) or not name.strip():
        raise ConfigError(f"name: expected a non-empty string, got {_describe(name)}")
    seed = number(raw.get("seed", 0), "seed", "integer", 0, 2**63 - 1, integer=True)
    ell_name = raw.get("ellipsoid", "WGS84")
    _choice(ell_name, "ellipsoid", tuple(ELLIPSOIDS))
    ell = ELLIPSOIDS[ell_name]
    formats = raw.get("formats", ["mcap_json"])
    if isinstance(formats, str):
        formats = [formats]
    if not isinstance(formats, list) or not formats:
        raise ConfigError(f"formats: expected a non-empty list of {list(FORMATS)}, got {_describe(formats)}")
    for i, fm in enumerate(formats):
        _choice(fm, f"formats[{i}]", FORMATS)
    fld = raw.get("field")
    fmodel = None
    if fld is not None:
        fmodel = field_model_from_dict(fld, "field", ell)
    proc = _merge(raw.get("processing"), DEFAULT_PROCESSING, "processing")
    proc["filter_rate_hz"] = number(proc["filter_rate_hz"], "processing.filter_rate_hz", "Hz", 0.0, 200.0, lo_open=True)
    for k in ("lines_mode", "postprocess_method", "output_dir"):
        if not isinstance(proc[k], str):
            raise ConfigError(f"processing.{k}: expected a string, got {_describe(proc[k])}")
    pm = proc["model"]
    if pm is not None:
        if not isinstance(pm, dict):
            raise ConfigError(f"processing.model: expected a mapping of survey.yaml model keys, got {_describe(pm)}")
        for k, v in pm.items():
            if not isinstance(k, str) or isinstance(v, (dict, list)) or v is None:
                raise ConfigError(f"processing.model.{k}: expected a scalar value, got {_describe(v)}")
        proc["model"] = dict(pm)
    flights = raw.get("flights")
    if not isinstance(flights, list) or not flights:
        raise ConfigError(f"flights: expected a non-empty list of flights, got {_describe(flights)}")
    out = [_validate_flight(f, f"flights[{i}]", i) for i, f in enumerate(flights)]
    names = [f["name"] for f in out]
    for i, nm in enumerate(names):
        if names.index(nm) != i:
            raise ConfigError(f"flights[{i}].name: duplicate flight name {nm!r}")
    return SimConfig(
        name=name,
        seed=seed,
        ellipsoid=ell,
        formats=list(formats),
        field=fld,
        field_model=fmodel,
        processing=proc,
        flights=out,
        source=path,
        raw=raw,
    )
