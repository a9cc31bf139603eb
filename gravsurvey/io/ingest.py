"""Ingestion: per-flight input options -> checked :class:`~gravsurvey.io.record.FlightRecord`.

:class:`IngestOptions` holds one flight's ingestion settings (built from the config's
``inputs``, ``topics``, ``mcap``, ``csv``, ``checks`` keys by
:func:`gravsurvey.settings.ingest_options`; see docs/input-formats.md);
``load_flight`` reads the files, repairs the time bases, runs the plausibility checks and
returns the record.  Problems are reported once: a :class:`~gravsurvey.errors.DataWarning`
per finding, the same line in ``record.notes``.
"""

from __future__ import annotations

import dataclasses
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gravsurvey.errors import ConfigError, DataError, DataWarning
from gravsurvey.io import checks as ck
from gravsurvey.io.csv import INCREMENT_UNITS, UNITS, read_csv_channel
from gravsurvey.io.mcap import DEFAULT_JSON_FIELDS, DEFAULT_MAX_RECORD_BYTES, ROLE_SCHEMAS, McapContent, read_mcap
from gravsurvey.io.record import AltimeterChannel, FlightRecord, GnssChannel, GradientChannel, ImuChannel

ROLES = ("imu", "altimeter", "gnss")
#: Channels a flight may have in addition (read when present, never required).
OPTIONAL_ROLES = ("gradient",)
DEFAULT_TOPICS = {"imu": "/imu", "altimeter": "/altimeter", "gnss": "/gnss"}
#: Topic of the optional gradient channel unless ``topics.gradient`` says otherwise (a JSON
#: channel with schema ``gravsurvey.GravityGradient`` on another topic is found by its schema).
DEFAULT_GRADIENT_TOPIC = "/gradient"
#: A gradient file whose median vertical eigenvalue (Earth: ~3080 E) lies outside this range,
#: in Eotvos, is in another unit than declared.
GRADIENT_VERTICAL_RANGE_E = (1000.0, 10000.0)
#: Median asymmetry max|T_ij - T_ji| of a 9-component gradient above which the tensor is
#: rejected as not a gradient tensor (a real one is symmetric to its noise), Eotvos.
GRADIENT_ASYMMETRY_TOL_E = 10.0
#: IMU axis conventions -> matrix mapping the sensor axes onto forward-left-up body axes
#: (``vec_flu = M @ vec_sensor``); any other mounting is given as a 3x3 matrix.
IMU_AXES = {
    "FLU": np.eye(3),
    "FRD": np.diag([1.0, -1.0, -1.0]),  # VectorNav, Xsens, iMAR, NovAtel
    "RFU": np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),
}


@dataclass
class IngestOptions:
    """Validated ingestion settings of one flight (see docs/input-formats.md).

    Paths are as written in the config; :func:`load_flight` resolves them against ``base_dir``.
    """

    kind: str = "mcap"  # "mcap" | "csv" | "gravimeter"
    mcap_path: str | None = None
    csv_paths: dict = field(default_factory=dict)  # role -> path
    topics: dict = field(default_factory=lambda: dict(DEFAULT_TOPICS))
    topics_explicit: tuple = ()
    json_fields: dict = field(default_factory=lambda: {r: dict(m) for r, m in DEFAULT_JSON_FIELDS.items()})
    mcap_units: dict = field(default_factory=lambda: {"accel": "m/s^2", "gyro": "rad/s", "height": "m"})
    time_source: str = "auto"  # "auto" (header.stamp / JSON time, else log_time) | "log_time"
    check_crc: bool = True
    max_record_bytes: int = DEFAULT_MAX_RECORD_BYTES
    csv_columns: dict = field(default_factory=dict)  # role -> {quantity: column}
    csv_time_format: str = "ns"
    csv_units: dict = field(default_factory=lambda: {"accel": "m/s^2", "gyro": "rad/s", "height": "m"})
    csv_delimiter: str = ","
    gps_leap_seconds: int = 18
    #: sensor axes -> forward-left-up triad axes, (3, 3) proper rotation (``imu_axes``)
    mat_axes: np.ndarray = field(default_factory=lambda: np.eye(3))
    #: GNSS antenna position from the IMU on the forward-left-up triad axes, m, (3,) (``gnss_lever_arm_m``);
    #: None: not given (found from the aided track)
    gnss_lever_arm_m: np.ndarray | None = None
    #: nanoseconds added to a channel's stamps as read, role -> int (``time_offsets_s``)
    time_offsets_ns: dict = field(default_factory=dict)
    gap_factor: float = 5.0
    plausibility: str = "error"  # "error" | "warn"
    key_path: str = "flight"
    base_dir: str | None = None  # relative input paths refer to it
    gravimeter: object = None  # io.formats.flight.GravimeterOptions for kind "gravimeter"
    #: ``{format: nmea | trajectory | rtklib, file, ...}``: a navigation file that is the flight's GNSS
    #: (``inputs.nav``, validated by gravsurvey.settings (NavSection))
    nav: dict | None = None

    def _resolve(self, p, base_dir=None):
        base = base_dir if base_dir is not None else self.base_dir
        return Path(base) / p if base is not None else Path(p)

    def input_paths(self, base_dir=None) -> list:
        """The input files (MCAP, or the CSVs in imu, altimeter, gnss order), resolved against
        ``base_dir`` (default: the one given to :func:`gravsurvey.settings.ingest_options`)."""
        if self.kind == "gravimeter":
            return self.gravimeter.paths(base_dir if base_dir is not None else self.base_dir)
        paths = (
            [self._resolve(self.csv_paths[r], base_dir) for r in ROLES + OPTIONAL_ROLES if r in self.csv_paths]
            if self.kind == "csv"
            else [self._resolve(self.mcap_path, base_dir)]
        )
        return paths + ([self._resolve(self.nav["file"], base_dir)] if self.nav else [])


def imu_axes_matrix(value, key_path="imu_axes") -> np.ndarray:
    """Matrix (3, 3) mapping the IMU's axes onto forward-left-up axes from ``imu_axes``.

    Parameters
    ----------
    value : str or list
        ``FLU`` (gravsurvey's own), ``FRD`` (forward-right-down: VectorNav, Xsens, iMAR,
        NovAtel), ``RFU`` (right-forward-up), or a 3x3 matrix (rows: the FLU axes on the
        sensor axes, ``vec_flu = M @ vec_sensor``), which must be a proper rotation.

    Raises
    ------
    ConfigError
        Naming ``key_path`` for an unknown name or a matrix that is not a proper rotation.
    """
    if isinstance(value, str):
        if value.upper() not in IMU_AXES:
            raise ConfigError(f"{key_path}: expected one of {', '.join(IMU_AXES)} or a 3x3 matrix, got {value!r}")
        return IMU_AXES[value.upper()].copy()
    try:
        m = np.array(value, dtype=float)
    except (TypeError, ValueError):
        m = None
    if m is None or m.shape != (3, 3) or not np.all(np.isfinite(m)):
        raise ConfigError(f"{key_path}: expected one of {', '.join(IMU_AXES)} or a 3x3 matrix, got {value!r}")
    if not np.allclose(m @ m.T, np.eye(3), atol=1e-6) or np.linalg.det(m) < 0:
        raise ConfigError(
            f"{key_path}: the matrix must be a proper rotation (orthonormal rows, determinant +1; a "
            f"mirrored axis set cannot be a sensor triad), got {value!r}"
        )
    return m


# ----------------------------------------------------------------------------- loading
@dataclass
class RawChannel:
    """One role's samples before time repair: int64 ns stamps and SI values."""

    role: str
    time_ns: np.ndarray
    values: dict
    source: str  # file (and topic) it came from
    schema: str = ""
    encoding: str = ""
    time_source: str = ""


def _unit_factors(units):
    return {k: UNITS[k][units.get(k, next(iter(UNITS[k])))] for k in UNITS}


def apply_units(role, values, units):
    """Channel values of ``role`` converted to SI by the declared ``units`` (``inputs.units``).

    Parameters
    ----------
    role : str
        ``"imu"`` (``specific_force``, ``angular_rate``), ``"gradient"`` (``gradient``) or a
        height channel (``height``; the GNSS's ``lat_deg`` and ``lon_deg`` too).
    values : dict of ndarray
        The channel's decoded arrays.
    units : dict or None
        Declared units (e.g. ``{"gyro": "deg/s"}``); missing entries are SI.

    Returns
    -------
    dict of ndarray
        A copy of ``values`` with the scaled arrays replaced.
    """
    f = _unit_factors(units)
    out = dict(values)
    if role == "imu":
        if f["accel"] != 1.0:
            out["specific_force"] = values["specific_force"] * f["accel"]
        if f["gyro"] != 1.0:
            out["angular_rate"] = values["angular_rate"] * f["gyro"]
    elif role == "gradient":
        if f["gradient"] != 1.0:
            out["gradient"] = values["gradient"] * f["gradient"]
    else:
        if f["height"] != 1.0:
            out["height"] = values["height"] * f["height"]
        if f["latlon"] != 1.0 and "lat_deg" in values:
            out["lat_deg"] = values["lat_deg"] * f["latlon"]
            out["lon_deg"] = values["lon_deg"] * f["latlon"]
    return out


def select_gradient_channels(content: McapContent, options: IngestOptions, notes: list):
    """The optional gradient channel of an MCAP file: ``{"gradient": [ids]}`` or ``{}``.

    The configured/default topic (``/gradient``) if present, else the one JSON channel with
    schema ``gravsurvey.GravityGradient``.

    Raises
    ------
    DataError
        An explicitly configured topic is absent or undecodable; several candidate topics.
    """
    path = content.path
    topic = options.topics.get("gradient", DEFAULT_GRADIENT_TOPIC)
    ids = [c for c, ch in content.channels.items() if ch.topic == topic]
    if ids:
        dec = [c for c in ids if c in content.decoded]
        if not dec:
            raise DataError(
                f"{path}: topic {topic} (gradient) has schema "
                f"{content.schema_name(ids[0]) or 'none'!r}, encoding "
                f"{content.channels[ids[0]].message_encoding!r}; expected "
                f"{ROLE_SCHEMAS['gradient'][0]} (JSON)"
            )
        return {"gradient": dec}
    if "gradient" in options.topics_explicit:
        raise DataError(f"{path}: configured topic {topic} for gradient not in the file")
    cands = sorted({content.channels[c].topic for c in content.decoded if content.role_of_schema(c) == "gradient"})
    if len(cands) > 1:
        raise DataError(f"{path}: several gradient topics ({', '.join(cands)}); set topics.gradient")
    if cands:
        notes.append(f"gradient: topic {topic} absent; using {cands[0]}")
        return {"gradient": [c for c, ch in content.channels.items() if ch.topic == cands[0] and c in content.decoded]}
    return {}


def gradient_tensors(values_si, source):
    """Checked ``(n, 3, 3)`` gradient tensors from ``(n, 9)`` row-major components in 1/s^2.

    Raises
    ------
    DataError
        The median vertical eigenvalue is outside ``GRADIENT_VERTICAL_RANGE_E`` (a unit other
        than the declared one), or the tensor is not symmetric (median asymmetry above
        ``GRADIENT_ASYMMETRY_TOL_E``).  Returns the symmetric part.
    """
    gam = np.asarray(values_si, dtype=np.float64).reshape(-1, 3, 3)
    if gam.shape[0] == 0:
        return gam
    eot = gam / 1e-9
    asym = np.abs(eot - eot.transpose(0, 2, 1)).max(axis=(1, 2))
    med_asym = float(np.median(asym))
    if med_asym > GRADIENT_ASYMMETRY_TOL_E:
        k = int(np.argmax(asym))
        raise DataError(
            f"{source}: gravity-gradient tensor not symmetric: median "
            f"max|T_ij - T_ji| = {med_asym:.4g} E (sample {k}: {asym[k]:.4g} E); "
            f"expected a symmetric tensor (<= {GRADIENT_ASYMMETRY_TOL_E:g} E)"
        )
    sym = 0.5 * (gam + gam.transpose(0, 2, 1))
    vert = float(np.median(np.abs(np.linalg.eigvalsh(sym / 1e-9)).max(axis=1)))
    lo, hi = GRADIENT_VERTICAL_RANGE_E
    if not lo <= vert <= hi:
        raise DataError(
            f"{source}: gravity gradient: median largest |eigenvalue| is {vert:.4g} E "
            f"after unit conversion; expected ~3080 E ({lo:g}..{hi:g}): wrong unit? "
            "(files carry Eotvos, 1 E = 1e-9 1/s^2, unless csv/mcap.units.gradient "
            "says 1/s^2)"
        )
    return sym


def select_channels(content: McapContent, options: IngestOptions, notes: list):
    """Pick the MCAP channel(s) for each role: configured topic, else schema auto-detection.

    Returns
    -------
    dict
        role -> list of channel ids (possibly empty for GNSS).

    Raises
    ------
    DataError
        An explicitly configured topic is absent or undecodable; a required role has no
        channel; auto-detection is ambiguous.
    """
    path = content.path
    by_topic = {}
    for cid, ch in content.channels.items():
        by_topic.setdefault(ch.topic, []).append(cid)
    avail = (
        ", ".join(f"{t} ({content.schema_name(ids[0]) or 'schemaless'})" for t, ids in sorted(by_topic.items()))
        or "none"
    )
    out = {}
    for role in ROLES:
        topic = options.topics[role]
        ids = by_topic.get(topic, [])
        if ids:
            dec = [c for c in ids if c in content.decoded]
            if not dec:
                ch = content.channels[ids[0]]
                raise DataError(
                    f"{path}: topic {topic} ({role}) has schema "
                    f"{content.schema_name(ids[0]) or 'none'!r}, encoding "
                    f"{ch.message_encoding!r}; expected one of "
                    f"{', '.join(ROLE_SCHEMAS[role])} (cdr) or JSON"
                )
            out[role] = dec
            continue
        if role in options.topics_explicit:
            raise DataError(f"{path}: configured topic {topic} for {role} not in the file; topics: {avail}")
        cands = sorted({content.channels[c].topic for c in content.decoded if content.role_of_schema(c) == role})
        if len(cands) == 1:
            out[role] = [c for c in by_topic[cands[0]] if c in content.decoded]
            notes.append(f"{role}: topic {topic} absent; using {cands[0]} (schema {content.schema_name(out[role][0])})")
        elif len(cands) > 1:
            raise DataError(
                f"{path}: topic {topic} absent and several {role} topics found ({', '.join(cands)}); set topics.{role}"
            )
        elif role == "gnss":
            out[role] = []
        elif role == "altimeter" and (gnss := _gnss_topic(content, options, by_topic)):
            # an IMU and a GNSS only: the GNSS heights are the height channel (as a CSV flight
            # without inputs.csv.altimeter reads them)
            out[role] = [c for c in by_topic[gnss] if c in content.decoded]
            notes.append(f"altimeter: topic {topic} absent; the GNSS heights of {gnss} are the height channel")
        else:
            raise DataError(
                f"{path}: no {role} channel: topic {topic} absent and no channel "
                f"with schema {' / '.join(ROLE_SCHEMAS[role])}; topics: {avail}"
                + ("; set topics.altimeter to a NavSatFix topic to use GNSS heights" if role == "altimeter" else "")
            )
    return out


def _gnss_topic(content: McapContent, options: IngestOptions, by_topic: dict) -> str | None:
    """The topic the GNSS role will read (configured, or the one GNSS-schema topic), if any."""
    topic = options.topics["gnss"]
    if any(c in content.decoded for c in by_topic.get(topic, [])):
        return topic
    if "gnss" in options.topics_explicit:
        return None
    cands = sorted({content.channels[c].topic for c in content.decoded if content.role_of_schema(c) == "gnss"})
    return cands[0] if len(cands) == 1 else None


#: What each role's messages must carry (decoded field names), and what to call them.
ROLE_VALUES = {
    "imu": (("specific_force", "angular_rate"), "IMU samples"),
    "altimeter": (("height",), "heights"),
    "gnss": (("lat_deg", "lon_deg", "height"), "GNSS positions"),
}


def _require_role_values(role, vals, src, content, ids, options) -> None:
    """Refuse a topic whose messages are not the role's kind (topics given in the wrong order)."""
    need, what = ROLE_VALUES.get(role, ((), ""))
    if all(k in vals for k in need):
        return
    carries = next(
        (w for r, (n, w) in ROLE_VALUES.items() if n and all(k in vals for k in n) and r != "altimeter"), None
    )
    listing = ", ".join(
        f"{c.topic} ({content.schema_name(cid) or 'no schema'})" for cid, c in sorted(content.channels.items())
    )
    raise DataError(
        f"{src} ({options.key_path}.topics.{role}): its {content.schema_name(ids[0]) or 'schemaless'} messages carry "
        f"{carries + ', not ' + what if carries else 'no ' + what}: topics given in the wrong order? (the file's topics: {listing})"
    )


def read_raw_channels(options: IngestOptions, base_dir, notes: list, data_loss: list | None = None):
    """Read the files named by ``options``: role -> :class:`RawChannel` (GNSS may be absent).

    Also returns the MCAP content (or None for CSV) for ``inspect``.  ``data_loss`` receives
    the damage of CSV inputs (a last line cut short); the MCAP's is in its content.
    """
    raw = {}
    if options.kind == "mcap":
        path = options._resolve(options.mcap_path, base_dir)
        content = read_mcap(
            path,
            topics=options.topics,
            json_fields=options.json_fields,
            check_crc=options.check_crc,
            max_record_bytes=options.max_record_bytes,
        )
        notes.extend(content.notes)
        if content.salvage is not None:
            notes.append(content.salvage.describe(path))
        if content.orphan_messages:
            notes.append(f"{path}: {content.orphan_messages} messages on undefined channels ignored")
        try:
            chosen = select_channels(content, options, notes)
            chosen.update(select_gradient_channels(content, options, notes))
        except DataError as exc:
            if content.salvage is None:
                raise
            raise DataError(f"{exc} ({content.salvage.describe(path)})") from None
        for role, ids in chosen.items():
            if not ids:
                continue
            blocks = [content.decoded[c] for c in ids]
            src = f"{path} topic {content.channels[ids[0]].topic}"
            t = np.concatenate([b.time_ns for b in blocks])
            lt = np.concatenate([b.log_time_ns for b in blocks])
            vals = {k: np.concatenate([b.values[k] for b in blocks]) for k in blocks[0].values}
            _require_role_values(role, vals, src, content, ids, options)
            if role == "altimeter":
                vals = {"height": vals["height"]}
            enc = content.channels[ids[0]].message_encoding
            used = sum(b.log_time_used for b in blocks)
            tsrc = "header.stamp" if enc == "cdr" else "JSON " + str(options.json_fields[role].get("time"))
            if options.time_source == "log_time":
                t, tsrc = lt, "log_time (configured)"
            elif used:
                tsrc += f" ({used} messages fell back to log_time)"
                notes.append(
                    f"{role}: {used} of {len(t)} messages from {src} carry no "
                    f"measurement time ({tsrc.split(' (')[0]}); used the MCAP log_time"
                )
            bad = sum(b.undecodable for b in blocks)
            if bad:
                probs = "; ".join(p for b in blocks for p in b.problems[:1])
                notes.append(
                    f"{role}: {bad} messages of {src} could not be decoded and were "
                    f"dropped" + (f" ({probs})" if probs else "")
                )
            vals = apply_units(role, vals, options.mcap_units)
            raw[role] = RawChannel(role, t, vals, src, content.schema_name(ids[0]), enc, tsrc)
        if options.nav:
            raw["gnss"] = read_gnss_file(options, base_dir, notes, replaces=raw.get("gnss"))
        return raw, content
    for role, rel in options.csv_paths.items():
        path = options._resolve(rel, base_dir)
        t, vals = read_csv_channel(
            path,
            role,
            options.csv_columns.get(role),
            options.csv_time_format,
            options.csv_units,
            options.csv_delimiter,
            options.gps_leap_seconds,
            notes=notes,
            data_loss=data_loss if data_loss is not None else [],
        )
        raw[role] = RawChannel(role, t, vals, str(path), "csv", "csv", options.csv_time_format)
    if options.nav:
        raw["gnss"] = read_gnss_file(options, base_dir, notes, replaces=raw.get("gnss"))
    return raw, None


def read_gnss_file(options: IngestOptions, base_dir, notes: list, replaces=None) -> RawChannel:
    """The GNSS channel from a navigation file (``inputs.nav``: NMEA, trajectory text or RTKLIB .pos).

    Heights must be ellipsoidal (NMEA: GGA altitude + geoid separation; trajectory: an
    ellipsoidal-height column): the INS and normal gravity refer to the ellipsoid, and a geoid
    height of tens of metres would bias the anomaly by 0.3 mGal per metre.

    Raises
    ------
    DataError
        Missing or unreadable file, no position, or no ellipsoidal height (names the file).
    """
    from gravsurvey.io.formats.flight import read_navigation

    fmt = options.nav["format"]
    path = options._resolve(options.nav["file"], base_dir)
    tab = read_navigation({**options.nav, "file": os.fspath(path)}, key_path=f"{options.key_path}.inputs.nav")
    # the reader's remarks on damage and missing values are findings; its time-source line is not
    info = (": time from the ", ": time scale ", "no RMC/VTG speed")
    notes.extend(f"gnss: {n}" for n in tab.notes if not any(k in n for k in info))
    h = np.asarray(tab.columns["height"], float)
    if not np.isfinite(h).any():
        what = (
            "GGA sentences with the geoid separation (field 11)"
            if fmt == "nmea"
            else "ellipsoidal heights (RTKLIB out-height = ellipsoidal)"
            if fmt == "rtklib"
            else "an ellipsoidal height column (ell_ht, h_ell, ...)"
        )
        raise DataError(
            f"{path}: no ellipsoidal heights; expected {what}: the INS needs heights above "
            f"the ellipsoid (orthometric heights would bias the anomaly by 0.3 mGal/m)"
        )
    if replaces is not None and len(replaces.time_ns):
        notes.append(f"gnss: {path} ({fmt}) used instead of the GNSS channel of {replaces.source}")
    vals = {
        "lat_deg": np.degrees(np.asarray(tab.columns["lat"], float)),
        "lon_deg": np.degrees(np.asarray(tab.columns["lon"], float)),
        "height": h,
    }
    tsrc = str(tab.meta.get("time_source", tab.meta.get("time_system", "file")))
    return RawChannel("gnss", np.asarray(tab.time_ns, np.int64), vals, f"{path} ({fmt})", fmt, "text", tsrc)


def _drop_nonfinite(ch: RawChannel, notes):
    """Drop samples holding NaN/inf or a magnitude no supported unit can mean
    (``checks.DAMAGE_ABS_MAX``: a corrupted digit in a CSV, say 2.6e21 m/s^2, would otherwise
    reach the mechanization); say how many."""
    from .checks import DAMAGE_ABS_MAX

    ok = np.ones(len(ch.time_ns), bool)
    for v in ch.values.values():
        if len(ok):
            a2 = np.abs(np.asarray(v, float).reshape(len(ok), -1))
            # NaN and inf fail the bound too (comparisons with NaN are False), so no isfinite
            # pass; column by column avoids (n, k) boolean temporaries and a row-wise all()
            for j in range(a2.shape[1]):
                ok &= a2[:, j] <= DAMAGE_ABS_MAX
    if not ok.all():
        notes.append(
            f"{ch.role}: dropped {int((~ok).sum())} samples with empty, NaN/inf or absurd "
            f"(> {DAMAGE_ABS_MAX:g}) values ({ch.source})"
        )
        ch.time_ns = ch.time_ns[ok]
        ch.values = {k: v[ok] for k, v in ch.values.items()}


def _drop_no_fix(ch: RawChannel, notes):
    """Drop GNSS samples at latitude 0 and longitude 0 exactly: what receivers write with no fix
    (a survey at the Gulf of Guinea's null point would have some other digit in 15); say how
    many. Kept, one such row made the track jump by 5,000 km and refused the whole flight."""
    if ch.role != "gnss" or "lat_deg" not in ch.values or not len(ch.time_ns):
        return
    zero = (np.asarray(ch.values["lat_deg"]) == 0.0) & (np.asarray(ch.values["lon_deg"]) == 0.0)
    if zero.any() and not zero.all():
        notes.append(f"gnss: dropped {int(zero.sum())} samples at latitude 0, longitude 0 (no fix) ({ch.source})")
        ch.time_ns = ch.time_ns[~zero]
        ch.values = {k: v[~zero] for k, v in ch.values.items()}


def imu_units(options: IngestOptions) -> tuple:
    """The declared (accelerometer, gyro) units of a flight's IMU channel."""
    units = options.csv_units if options.kind == "csv" else options.mcap_units
    return units.get("accel", "m/s^2"), units.get("gyro", "rad/s")


def _increments_to_rates(ch: RawChannel, nominal_step_ns: int, options: IngestOptions) -> list:
    """IMU increments per sample (``m/s``, ``rad``, ``deg``: already scaled to SI) divided by the
    nominal step into rates, in place, the stamps moved to the middle of each sample's interval.

    An increment covers the interval that ends at its stamp; after a gap it still covers one
    nominal step (the samples in between were lost, not merged), so every sample is divided by
    the nominal step, not by the time since the previous one.
    """
    accel_unit, gyro_unit = imu_units(options)
    inc = [q for q, u in (("accel", accel_unit), ("gyro", gyro_unit)) if u in INCREMENT_UNITS[q]]
    if not inc:
        return []
    if len(inc) == 1:
        # refused by the config schema too (FlightSection); here for IngestOptions built in code
        raise ConfigError(
            f"{options.key_path}.{options.kind}.units: accel {accel_unit!r} and gyro {gyro_unit!r}: one is an "
            "increment per sample and the other a rate; declare both as increments (m/s with rad or deg) or both "
            "as rates"
        )
    dt = nominal_step_ns * 1e-9
    if not dt > 0.0:
        return []
    ch.values["specific_force"] = np.asarray(ch.values["specific_force"], float) / dt
    ch.values["angular_rate"] = np.asarray(ch.values["angular_rate"], float) / dt
    ch.time_ns = ch.time_ns - np.int64(nominal_step_ns // 2)
    return [
        ck.Finding(
            "imu",
            "increments",
            "ok",
            f"imu: increments per sample ({accel_unit}, {gyro_unit}) divided by the nominal step "
            f"{dt * 1e3:.4g} ms into rates; stamps moved {dt * 5e2:.4g} ms earlier, to the middle of each interval",
            dt,
        )
    ]


def _drop(ch: RawChannel, idx) -> None:
    keep = np.ones(len(ch.time_ns), bool)
    keep[idx] = False
    ch.time_ns = ch.time_ns[keep]
    ch.values = {k: np.asarray(v)[keep] for k, v in ch.values.items()}


def _drop_frozen(raw: dict) -> list:
    """Drop GNSS epochs and IMU samples that repeat their predecessor while the aircraft moves
    (:func:`checks.frozen_gnss`, :func:`checks.frozen_imu`); one warning per channel."""
    out = []
    g = raw.get("gnss")
    gt = glat = glon = None
    if g is not None and len(g.time_ns) > 2:
        bad = ck.frozen_gnss(g.time_ns, g.values["lat_deg"], g.values["lon_deg"], g.values["height"])
        if bad.size:
            out.append(ck.frozen_finding("gnss", g.source, g.time_ns, bad, "the previous position"))
            _drop(g, bad)
        gt, glat, glon = g.time_ns, g.values["lat_deg"], g.values["lon_deg"]
    imu = raw.get("imu")
    if imu is not None and len(imu.time_ns) > 2:
        bad = ck.frozen_imu(imu.time_ns, imu.values["specific_force"], imu.values["angular_rate"], gt, glat, glon)
        if bad.size:
            out.append(ck.frozen_finding("imu", imu.source, imu.time_ns, bad, "all six values of the previous sample"))
            _drop(imu, bad)
    return out


def repair_and_check(raw: dict, options: IngestOptions):
    """Time repair and plausibility findings for every channel.

    Returns
    -------
    raw : dict
        Same roles, times strictly increasing.
    findings : list of checks.Finding
    reports : dict
        role -> checks.TimeReport
    """
    findings, reports = [], {}
    t0 = min((int(ch.time_ns[0]) for ch in raw.values() if len(ch.time_ns)), default=0)
    for role, ch in raw.items():
        keys = list(ch.values)
        t, vals, rep = ck.repair_time(ch.time_ns, [ch.values[k] for k in keys], options.gap_factor)
        ch.time_ns, ch.values = t, dict(zip(keys, vals))
        reports[role] = rep
        findings += ck.time_findings(role, rep, t0)
        findings += ck.check_epoch(role, t)
    findings += _drop_frozen(raw)
    if "imu" in raw:
        ch = raw["imu"]
        findings += _increments_to_rates(ch, reports["imu"].nominal_step_ns, options)
        for key in ("specific_force", "angular_rate"):
            # repaired in place: a reader's zero-copy view of its buffer is copied first
            if not ch.values[key].flags.writeable:
                ch.values[key] = ch.values[key].copy()
        # a sensor at its range before the glitch repair, which would smooth a plateau's ends
        sat, found = ck.saturated_imu(
            ch.values["specific_force"], ch.values["angular_rate"], (ch.time_ns - t0) * 1e-9, *imu_units(options)
        )
        findings += found
        if sat.any():
            ch.values["saturated"] = sat
        findings += ck.repair_imu_glitches(ch.values["specific_force"], ch.values["angular_rate"], *imu_units(options))
        findings += ck.check_imu(
            ch.time_ns,
            ch.values["specific_force"],
            ch.values["angular_rate"],
            reports["imu"].nominal_step_ns,
            *imu_units(options),
        )
    hunit = options.csv_units["height"] if options.kind == "csv" else options.mcap_units["height"]
    g = raw.get("gnss")
    if g is not None:
        findings += ck.check_gnss(g.values["lat_deg"], g.values["lon_deg"])
        findings += ck.check_height("gnss", g.values["height"], hunit)
    if "altimeter" in raw:
        a = raw["altimeter"]
        findings += ck.check_height("altimeter", a.values["height"], hunit)
        if g is not None and len(g.time_ns) > 1 and a.source != g.source:
            # GNSS height at the altimeter times; relative ns keep float64 exact
            tg = (g.time_ns - g.time_ns[0]).astype(np.float64)
            ta = (a.time_ns - g.time_ns[0]).astype(np.float64)
            ref = np.interp(ta, tg, g.values["height"], left=np.nan, right=np.nan)
            sel = np.isfinite(ref)
            ref, h = ref[sel], a.values["height"][sel]
            findings += [f for f in ck.check_height("altimeter", h, hunit, ref) if f.check == "height vs GNSS"]
    return raw, findings, reports


def load_flight(options: IngestOptions, base_dir=None) -> FlightRecord:
    """Read one flight's logs into a checked :class:`FlightRecord`.

    Parameters
    ----------
    options : IngestOptions
    base_dir : path, optional
        Directory that relative input paths refer to (the config file's directory); default:
        ``options.base_dir``.

    Returns
    -------
    FlightRecord
        Times strictly increasing, SI units, latitude/longitude in rad.  ``notes`` holds one
        line per repair/suspicion (each also issued as a DataWarning).

    Raises
    ------
    DataError
        Missing/unreadable/undecodable input, no IMU or altimeter samples, or a plausibility
        error (unless ``checks.plausibility: warn``); the message names file/channel.
    """
    if options.kind == "gravimeter":
        from gravsurvey.io.formats.flight import gravimeter_record

        return gravimeter_record(
            options.gravimeter,
            base_dir if base_dir is not None else options.base_dir,
            gap_factor=options.gap_factor,
            plausibility=options.plausibility,
        )
    notes, csv_loss = [], []
    raw, content = read_raw_channels(options, base_dir, notes, csv_loss)
    for ch in raw.values():
        _drop_nonfinite(ch, notes)
        _drop_no_fix(ch, notes)
    for role, off in options.time_offsets_ns.items():
        # clocks known to differ (time_offsets_s), before anything compares the channels
        if role in raw:
            raw[role].time_ns = raw[role].time_ns + np.int64(off)
    if "imu" in raw and not np.array_equal(options.mat_axes, np.eye(3)):
        # the sensor axes onto forward-left-up (imu_axes) before the checks, which expect +g on z at rest
        for q in ("specific_force", "angular_rate"):
            raw["imu"].values[q] = raw["imu"].values[q] @ options.mat_axes.T
    from gravsurvey.consistency import drop_clock_restarts  # restarts before the time repair

    clock_notes, clock_loss = drop_clock_restarts(raw)
    notes += clock_notes + clock_loss
    for role in ("imu", "altimeter"):
        if role not in raw or len(raw[role].time_ns) == 0:
            src = raw[role].source if role in raw else (options.mcap_path or "")
            why = [n for n in notes if n.startswith(f"{role}: ")]
            raise DataError(f"{src}: no usable {role} samples" + (f" ({'; '.join(why)})" if why else ""))
    raw, findings, reports = repair_and_check(raw, options)
    errors = [f for f in findings if f.level == "error"]
    if errors and options.plausibility == "error":
        # each finding under the file its channel came from (an altimeter's heights in feet are
        # the altimeter file's, not the IMU's)
        by_source: dict = {}
        for f in errors:
            by_source.setdefault(str(raw[f.channel if f.channel in raw else "imu"].source), []).append(f.message)
        raise DataError(
            "; ".join(f"{src}: implausible data: " + "; ".join(msgs) for src, msgs in by_source.items())
            + " (set checks.plausibility: warn to process anyway)"
        )
    notes += [f.message for f in findings if f.level in ("warning", "error")]
    for n in notes:
        warnings.warn(n, DataWarning, stacklevel=2)
    t0 = min(int(ch.time_ns[0]) for ch in raw.values() if len(ch.time_ns))

    def rel(t):
        return (t - t0) / 1e9

    imu = raw["imu"]
    alt = raw["altimeter"]
    gnss = None
    if "gnss" in raw and len(raw["gnss"].time_ns):
        g = raw["gnss"]
        gnss = GnssChannel(
            rel(g.time_ns), np.radians(g.values["lat_deg"]), np.radians(g.values["lon_deg"]), g.values["height"]
        )
    gradient = None
    if "gradient" in raw and len(raw["gradient"].time_ns):
        gr = raw["gradient"]
        gradient = GradientChannel(rel(gr.time_ns), gradient_tensors(gr.values["gradient"], gr.source))
    src = ", ".join(os.fspath(p) for p in options.input_paths(base_dir))
    record = FlightRecord(
        t0_unix_ns=t0,
        imu=ImuChannel(
            rel(imu.time_ns), imu.values["specific_force"], imu.values["angular_rate"], imu.values.get("saturated")
        ),
        altimeter=AltimeterChannel(rel(alt.time_ns), alt.values["height"]),
        gnss=gnss,
        source=src,
        notes=notes,
        data_loss=_data_loss(options, base_dir, content) + csv_loss + clock_loss,
        gradient=gradient,
        sources={role: str(ch.source) for role, ch in raw.items()},
    )
    if reports["imu"].rebuilt == "coarse" and gnss is not None:
        record = place_rebuilt_imu(record, reports["imu"])
    return record


#: Rebuilt IMU stamps are placed against the GNSS track (:func:`place_rebuilt_imu`) when the
#: offset they leave unknown, half the distinct stamps' step less one sample's, reaches this, s
#: (the cross-correlation's step; less is the aided track's GNSS latency check's to measure).
PLACE_REBUILT_MIN_S = 0.05


def place_rebuilt_imu(record: FlightRecord, rep) -> FlightRecord:
    """The IMU's rebuilt coarse or block stamps moved as a whole onto the GNSS track's time.

    Stamps cut to a coarse clock sit early by up to half its step, a block's read-out stamp late
    by as much (:func:`~gravsurvey.io.checks.rebuild_time_base` cannot tell which); the offset the
    specific forces' cross-correlation with the GNSS track measures
    (:func:`~gravsurvey.consistency.estimate_time_offset`) is taken off when it is clear (its
    verdict correlation) and within that range (one correlation step to spare), with a warning.
    Otherwise the record is returned as it was.

    Parameters
    ----------
    record : FlightRecord
        With GNSS.
    rep : checks.TimeReport
        The IMU's time repair (``rebuilt == "coarse"``).

    Returns
    -------
    FlightRecord
    """
    from gravsurvey.consistency import OFFSET_VERDICT_CORRELATION, estimate_time_offset

    half = 0.5 * (rep.rebuilt_stamp_step_ns - rep.nominal_step_ns) * 1e-9
    if not half >= PLACE_REBUILT_MIN_S:
        return record
    off, c = estimate_time_offset(record, max_lag_s=max(2.0 * half, 1.0))
    if off is None or not c >= OFFSET_VERDICT_CORRELATION or abs(off) > half + PLACE_REBUILT_MIN_S:
        return record
    # times stay non-negative after t0: every channel moves by what the IMU's start would lose
    lead = max(0.0, off - float(record.imu.time[0]))
    t0 = record.t0_unix_ns - int(round(lead * 1e9))

    def moved(ch, by):
        return None if ch is None else dataclasses.replace(ch, time=ch.time + by)

    note = (
        f"imu: the rebuilt stamps placed against the GNSS track, moved {-off:+.2f} s (cross-correlation of "
        f"specific force, r = {c:.2f}; stamps {rep.rebuilt_stamp_step_ns * 1e-9:.3g} s apart leave up to "
        f"{half:.2f} s unknown)"
    )
    warnings.warn(note, DataWarning, stacklevel=2)
    return dataclasses.replace(
        record,
        t0_unix_ns=t0,
        imu=moved(record.imu, lead - off),
        altimeter=moved(record.altimeter, lead),
        gnss=moved(record.gnss, lead),
        gradient=moved(record.gradient, lead),
        notes=record.notes + [note],
    )


def _data_loss(options: IngestOptions, base_dir, content) -> list:
    """The salvage description when the MCAP file was damaged (data after it are lost)."""
    if content is None or content.salvage is None:
        return []
    return [content.salvage.describe(options._resolve(options.mcap_path, base_dir))]
