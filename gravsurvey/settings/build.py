"""Builders: validated sections -> the typed settings each stage takes."""

from __future__ import annotations

import math
import os
from typing import Any

import numpy as np
from pydantic_core import PydanticCustomError

from ..consistency import CheckOptions
from ..drift import DriftOptions
from ..errors import ConfigError, unknown_key_text
from ..grid import GridOptions
from ..inm.params import InitialState, InmParams, mat_nb_from_attitude
from ..io.formats.flight import GravimeterOptions
from ..io.ingest import OPTIONAL_ROLES, ROLES, IngestOptions, imu_axes_matrix
from ..levelling import LevellingOptions
from ..segmentation import SegmentationOptions
from ..ties import TieConfig, TieReading
from ..wavelet import PostprocessOptions

from .messages import key_path_text, validate_section, value_text
from .schema import (
    ChecksSection,
    DriftSection,
    FlightSection,
    GravimeterSection,
    GridSection,
    INGEST_KEYS,
    InitialSection,
    LevellingSection,
    LinesSection,
    ModelSection,
    PostprocessSection,
    Section,
    TieSection,
    WindowSection,
    check_unique_windows,
)


# ============================================================================ builders
def section_dict(section: Section) -> dict:
    return {k: getattr(section, k) for k in type(section).model_fields}


def time_windows(windows: Any, key_path: str = "lines.windows") -> list[WindowSection]:
    """A non-empty list of time windows validated (types, ``start_s < stop_s``, unique names)."""
    if not isinstance(windows, (list, tuple)) or not windows:
        raise ConfigError(
            f"{key_path}: expected a non-empty list of {{name, start_s, stop_s}}, got {value_text(windows)}"
        )
    out = []
    for i, w in enumerate(windows):
        out.append(validate_section(WindowSection, w, f"{key_path}[{i}]"))
    try:
        check_unique_windows(out, ())
    except PydanticCustomError as exc:
        ctx = exc.context or {}
        raise ConfigError(f"{key_path_text(key_path, ctx.get('key', ()))}: {ctx.get('message')}") from None
    return out


def inm_params(section: ModelSection | dict | None = None, key_path: str = "model") -> InmParams:
    """:class:`~gravsurvey.inm.params.InmParams` from the ``model`` section; the keys written in
    it are the ones identification holds fixed (``given``)."""
    s = section if isinstance(section, ModelSection) else validate_section(ModelSection, section, key_path)
    return InmParams(**section_dict(s), given=frozenset(s.given()))


def check_inm_params(params: InmParams, key_path: str = "model") -> None:
    """Raise :class:`ConfigError` naming the key when an :class:`InmParams` built in Python holds a
    value the ``model`` section would refuse."""
    validate_section(ModelSection, {k: getattr(params, k) for k in ModelSection.model_fields}, key_path)


def segmentation_options(section: LinesSection | dict | None = None, key_path: str = "lines") -> SegmentationOptions:
    """:class:`~gravsurvey.segmentation.SegmentationOptions` from the ``lines`` section."""
    s = section if isinstance(section, LinesSection) else validate_section(LinesSection, section, key_path)
    d = section_dict(s)
    d["windows"] = [w.model_dump(exclude_none=True) for w in s.windows]
    return SegmentationOptions(**d)


def postprocess_options(
    section: PostprocessSection | dict | None = None, key_path: str = "postprocess"
) -> PostprocessOptions:
    """:class:`~gravsurvey.wavelet.PostprocessOptions` from the ``postprocess`` section."""
    s = section if isinstance(section, PostprocessSection) else validate_section(PostprocessSection, section, key_path)
    return PostprocessOptions(**section_dict(s))


def check_options(section: ChecksSection | dict | None = None, key_path: str = "checks") -> CheckOptions:
    """:class:`~gravsurvey.consistency.CheckOptions` from the ``checks`` section."""
    s = section if isinstance(section, ChecksSection) else validate_section(ChecksSection, section, key_path)
    return CheckOptions(**section_dict(s))


def drift_options(section: DriftSection | dict | None = None, key_path: str = "drift") -> DriftOptions:
    """:class:`~gravsurvey.drift.DriftOptions` from the ``drift`` section."""
    s = section if isinstance(section, DriftSection) else validate_section(DriftSection, section, key_path)
    return DriftOptions(**section_dict(s))


def levelling_options(section: LevellingSection | dict | None = None, key_path: str = "levelling") -> LevellingOptions:
    """:class:`~gravsurvey.levelling.LevellingOptions` from the ``levelling`` section."""
    s = section if isinstance(section, LevellingSection) else validate_section(LevellingSection, section, key_path)
    return LevellingOptions(**section_dict(s))


def grid_options(section: GridSection | dict | None = None, key_path: str = "grid") -> GridOptions:
    """:class:`~gravsurvey.grid.GridOptions` from the ``grid`` section."""
    s = section if isinstance(section, GridSection) else validate_section(GridSection, section, key_path)
    return GridOptions(**section_dict(s))


def tie_config(section: TieSection | dict, key_path: str = "flights[0].tie") -> TieConfig:
    """:class:`~gravsurvey.ties.TieConfig` from a flight's ``tie`` section."""
    s = section if isinstance(section, TieSection) else validate_section(TieSection, section, key_path)

    def reading(r):
        return None if r is None else TieReading(r.reading_mgal, r.time_s, r.start_s, r.stop_s)

    return TieConfig(s.base_gravity_mgal, reading(s.before), reading(s.after), s.base_lat_deg, s.base_height_m)


def initial_overrides(section: InitialSection | dict, key_path: str = "initial") -> dict:
    """The ``initial`` keys given, as floats (``velocity_enu_mps``, ``attitude_deg``: ndarray (3,)),
    for :func:`gravsurvey.inm.params.resolve_initial_state`."""
    s = section if isinstance(section, InitialSection) else validate_section(InitialSection, section, key_path)
    out: dict = {}
    for k in ("lat_deg", "lon_deg", "height_m"):
        if getattr(s, k) is not None:
            out[k] = float(getattr(s, k))
    for k in ("velocity_enu_mps", "attitude_deg"):
        if getattr(s, k) is not None:
            out[k] = np.asarray(getattr(s, k), dtype=float)
    return out


def initial_state(section: InitialSection | dict, triad: str, key_path: str = "initial") -> InitialState:
    """A complete initial state from an ``initial`` block: position, velocity and, for a strapdown
    triad, ``attitude_deg`` (a platform's triad is ENU)."""
    given = initial_overrides(section, key_path)
    need = ["lat_deg", "lon_deg", "height_m", "velocity_enu_mps"] + (["attitude_deg"] if triad == "strapdown" else [])
    for k in need:
        if k not in given:
            raise ConfigError(f"{key_path}.{k}: missing required key")
    mat_nt = np.eye(3)
    if triad == "strapdown":
        mat_nt = mat_nb_from_attitude(*np.radians(given["attitude_deg"]))
    return InitialState(
        math.radians(given["lat_deg"]),
        math.radians(given["lon_deg"]),
        given["height_m"],
        given["velocity_enu_mps"],
        mat_nt,
    )


def gravimeter_options(
    section: GravimeterSection | dict, key_path: str = "flights[0].inputs.gravimeter"
) -> GravimeterOptions:
    """:class:`~gravsurvey.io.formats.flight.GravimeterOptions` from a flight's ``inputs.gravimeter``."""
    g = section if isinstance(section, GravimeterSection) else validate_section(GravimeterSection, section, key_path)
    return GravimeterOptions(
        format=g.format,
        files=[g.file] if g.file is not None else list(g.files or []),
        offset_mgal=0.0 if g.offset_mgal is None else g.offset_mgal,
        scale=g.scale,
        counts_scale_mgal=g.counts_scale_mgal,
        time_source=g.time_source or "auto",
        height_m=g.height_m,
        nav=g.nav.model_dump(exclude_none=True) if g.nav is not None else None,
        key_path=key_path,
    )


def ingest_options(flight: FlightSection | dict, key_path: str = "flights[0]", base_dir=None) -> IngestOptions:
    """:class:`~gravsurvey.io.ingest.IngestOptions` from a flight's ingestion keys
    (:data:`INGEST_KEYS`; a mapping with only these keys, or a validated :class:`FlightSection`)."""
    if isinstance(flight, FlightSection):
        f = flight
    else:
        if isinstance(flight, dict):
            extra = [k for k in flight if k not in INGEST_KEYS]
            if extra:
                raise ConfigError(f"{key_path}.{extra[0]}: {unknown_key_text(extra[0], INGEST_KEYS)}")
        f = validate_section(FlightSection, flight, key_path)
    o = IngestOptions(key_path=key_path, base_dir=os.fspath(base_dir) if base_dir is not None else None)
    if f.inputs.gravimeter is not None:
        o.kind = "gravimeter"
        o.gravimeter = gravimeter_options(f.inputs.gravimeter, f"{key_path}.inputs.gravimeter")
    elif f.inputs.mcap is not None:
        o.kind, o.mcap_path = "mcap", f.inputs.mcap
    else:
        o.kind = "csv"
        assert f.inputs.csv is not None  # exactly one input kind (InputsSection)
        o.csv_paths = {r: p for r, p in section_dict(f.inputs.csv).items() if p is not None}
        if "altimeter" not in o.csv_paths:
            # an IMU and a GNSS only: the GNSS heights are the height channel (CsvInputs)
            o.csv_paths = {"imu": o.csv_paths["imu"], "altimeter": o.csv_paths["gnss"], **o.csv_paths}
    if f.inputs.nav is not None:
        o.nav = f.inputs.nav.model_dump(exclude_none=True)
    given_topics = f.topics.given()
    o.topics.update({r: getattr(f.topics, r) for r in ROLES + OPTIONAL_ROLES if r in given_topics})
    o.topics_explicit = tuple(r for r in ROLES + OPTIONAL_ROLES if r in given_topics)
    for role, names in section_dict(f.mcap.json_fields).items():
        if names is not None:
            o.json_fields[role].update({q: v for q, v in section_dict(names).items() if v is not None})
    if "units" in f.mcap.given():
        o.mcap_units = section_dict(f.mcap.units)
    o.time_source = f.mcap.time_source
    o.check_crc = f.mcap.check_crc
    o.max_record_bytes = f.mcap.max_record_mib * 2**20
    o.csv_time_format = f.csv.time_format
    for role, names in section_dict(f.csv.columns).items():
        if names is not None:
            o.csv_columns[role] = {q: v for q, v in section_dict(names).items() if v is not None}
    if o.kind == "csv" and f.inputs.csv is not None and f.inputs.csv.altimeter is None and "gnss" in o.csv_columns:
        # the GNSS file read as the altimeter: its time and height columns as named for the GNSS
        o.csv_columns["altimeter"] = {
            q: v for q, v in o.csv_columns["gnss"].items() if q in ("time", "height", "x", "y", "z")
        } | o.csv_columns.get("altimeter", {})
    if "units" in f.csv.given():
        o.csv_units = section_dict(f.csv.units)
    o.csv_delimiter = f.csv.delimiter
    o.gps_leap_seconds = f.csv.gps_leap_seconds
    o.mat_axes = imu_axes_matrix(f.imu_axes, f"{key_path}.imu_axes")
    o.gnss_lever_arm_m = None if f.gnss_lever_arm_m is None else np.asarray(f.gnss_lever_arm_m, dtype=float)
    o.time_offsets_ns = {role: int(round(v * 1e9)) for role, v in f.time_offsets_s if v != 0.0}
    o.gap_factor = float(f.checks.gap_factor)
    o.plausibility = f.checks.plausibility
    return o
