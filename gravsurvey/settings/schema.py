"""The config schema proper: one pydantic model per section (keys, types, limits, defaults,
descriptions with units), the defaults read from the stage settings classes."""

from __future__ import annotations

import dataclasses
import re
from typing import Annotated, Any, Literal, Optional, Union

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Discriminator,
    Field,
    Tag,
    create_model,
    field_validator,
    model_validator,
)
from pydantic_core import PydanticCustomError

from ..consistency import CheckOptions
from ..drift import DriftOptions
from ..errors import ConfigError
from ..grid import GRID_METHODS, GridOptions
from ..inm.params import RADIUS_SOURCES, TRIADS, InmParams
from ..io.checks import HEIGHT_OK
from ..io.csv import DEFAULT_COLUMNS, ECEF_QUANTITIES, INCREMENT_UNITS, TIME_FORMATS, UNITS
from ..io.formats.flight import GRAVIMETER_FORMATS, NAV_FORMATS
from ..truth import TRUTH_TIME_FORMATS
from ..io.ingest import IngestOptions, imu_axes_matrix
from ..io.mcap import DEFAULT_JSON_FIELDS, DEFAULT_MAX_RECORD_BYTES
from ..levelling import LEVELLING_MODELS, LevellingOptions
from ..marine import NORMAL_GRAVITY_CHOICES
from ..segmentation import SEGMENTATION_MODES, SegmentationOptions
from ..ties import G_ABS_RANGE_MGAL
from ..wavelet import BOUNDARY_MODES, LOWPASS_METHODS, METHODS, THRESHOLDINGS, WAVELETS, PostprocessOptions


#: flight names: safe in file names and XYZ line labels
FLIGHT_NAME_PATTERN = r"^[A-Za-z0-9_.-]{1,64}$"
PROCESSING_METHODS = ("inm", "classic")
ELLIPSOIDS = ("WGS84", "GRS80")
#: most a GNSS lever arm component may be, m (a larger one is a unit mistake: mm or cm)
MAX_LEVER_ARM_M = 100.0


def stage_default(cls, name: str):
    """Default of attribute ``name`` of the stage settings dataclass ``cls`` (the one source)."""
    for f in dataclasses.fields(cls):
        if f.name == name:
            if f.default is not dataclasses.MISSING:
                return f.default
            return f.default_factory()  # type: ignore[misc,operator]
    raise KeyError(f"{cls.__name__} has no attribute {name!r}")


def _defaults_of(cls):
    """``Field`` factory whose defaults are read from the stage settings class ``cls``."""

    def field(name: str, desc: str, **limits) -> Any:
        return Field(stage_default(cls, name), description=desc, **limits)

    return field


def fail(message: str, key: tuple = ()) -> PydanticCustomError:
    """A validation failure whose text is ``message``, at ``key`` below the current model."""
    return PydanticCustomError("gravsurvey", "{message}", {"message": message, "key": tuple(key)})


def _keys_of(cls) -> list[str]:
    return [f.alias or n for n, f in cls.model_fields.items()]


class Section(BaseModel):
    """Base of every config section: strict types (no ``"1"`` for 1), finite numbers, unknown
    keys refused with the nearest valid one, an empty (null) section meaning the defaults."""

    model_config = ConfigDict(strict=True, extra="forbid", allow_inf_nan=False, populate_by_name=True)

    @model_validator(mode="before")
    @classmethod
    def _mapping_with_known_keys(cls, data: Any) -> Any:
        if data is None:
            return {}
        if isinstance(data, BaseModel):
            return data
        if not isinstance(data, dict):
            raise PydanticCustomError("mapping", "expected a mapping", {"kind": type(data).__name__})
        valid = _keys_of(cls)
        for k in data:
            if str(k) not in valid:
                raise PydanticCustomError("unknown_key", "unknown key", {"key": str(k), "valid": valid})
        return data

    def given(self) -> set[str]:
        """The keys written in the config (not defaulted)."""
        return set(self.model_fields_set)


# ============================================================================ model (3D-INM)
_m = _defaults_of(InmParams)


class ModelSection(Section):
    """``model``: 3D-INM Kalman filter (docs/method.md)."""

    identify: bool = _m(
        "identify",
        "identify the anomaly prior (`anomaly_sigma_mps2`, `anomaly_lambda_per_m`), "
        "`gravimeter_white_mps2` and `altimeter_sigma_m` from the flight (those written in "
        "the config are held fixed); `false`: the configured values or the defaults as they are",
    )
    target_resolution_m: Optional[float] = _m(
        "target_resolution_m",
        "half-wavelength resolution the smoother should have, m (the anomaly sigma is "
        "chosen to put its half-power point there: finer = noisier); null: the resolution of least expected "
        "error for the flight",
        gt=0,
    )
    horizontal: bool = _m(
        "horizontal",
        "also estimate the horizontal disturbance (north, east; deflections xi, eta) as states, with "
        "horizontal accelerometer biases (vector gravimetry; needs GNSS aiding; docs/method.md)",
    )
    accel_bias_states: Optional[bool] = _m(
        "accel_bias_states",
        "carry the horizontal accelerometer biases as filter states (16 instead of 14) on GNSS-aided "
        "flights: an unmodelled bias is taken for tilt and leaks into the vertical in turns "
        "(docs/method.md, GNSS aiding); null: on, either triad (false: the 14 states)",
    )
    accel_bias_mps2: Optional[float] = _m(
        "accel_bias_mps2",
        "datasheet bias of the horizontal accelerometers, m/s^2 (1-sigma of each, e.g. 1e-3 for 100 micro-g): "
        "the GNSS-aided filter estimates the biases (on either triad) with this prior and, on a strapdown triad, "
        "takes them off the specific force between passes (docs/method.md, Accelerometer bias); null: the prior 5e-4 m/s^2, and "
        "taken off (on either triad) only where a pass finds a bias over 1.5e-3 m/s^2 (a tactical-grade IMU; a "
        "warning says so)",
        gt=0,
        le=0.5,
    )
    filter_rate_hz: float = _m(
        "filter_rate_hz",
        "Kalman epoch rate, Hz (the IMU rate is decimated; at least 0.2: the lines are found on 10-s means of the epochs). "
        "Not given, a flight with tactical-grade gyros (a white drift of 3 deg/h or more, given or chosen by likelihood) "
        "runs at 5 Hz instead, at most 36 000 epochs over the record (docs/method.md, 'Following passes'); given, it "
        "is used as it is",
        ge=0.2,
    )
    accel_noise_mps2: float = _m(
        "accel_noise_mps2",
        "sigma_f1 = sigma_f2, horizontal accelerometer white noise, m/s^2 (one-second sigma); on a strapdown "
        "triad also the tilt leak identification takes off the vertical white level. Not given, a GNSS-aided "
        "strapdown flight takes 5e-4 or 2.5e-4 instead where the filter's likelihood is clearly higher "
        "(docs/method.md, 'Accelerometer noise by likelihood'); given (the datasheet figure), it is used as it is",
        ge=0,
    )
    gyro_drift_degph: float = _m(
        "gyro_drift_degph",
        "sigma_nu, white gyro drift, deg/h (one-second sigma: the datasheet's angle random walk in deg/sqrt(h) x 60). "
        "Not given, a GNSS-aided flight (either triad) takes 0.1, 1 or 10 instead where a screen pass and the "
        "filter's likelihood clearly say the gyros are noisier (docs/method.md, 'Gyro noise by likelihood'); given, "
        "it is used as it is",
        ge=0,
    )
    gravimeter_lambda_per_s: float = _m(
        "gravimeter_lambda_per_s", "lambda_f3, gravimeter error correlation rate, 1/s", ge=0
    )
    gravimeter_sigma_mps2: float = _m(
        "gravimeter_sigma_mps2",
        "sigma_f3, gravimeter Markov error, m/s^2. Where this flight's gravimeter drift is known, it goes here "
        "with gravimeter_lambda_per_s: the filter then holds it apart from the field, which the flight's own data "
        "cannot (docs/benchmarks.md, 'The worst flights'); a datasheet's nominal figure here takes field off on "
        "flights whose drift is smaller (same section): it belongs in drift.sigma_mps2",
        ge=0,
    )
    gravimeter_white_mps2: float = _m(
        "gravimeter_white_mps2", "gravimeter white noise on top of the Markov error, m/s^2 (one-second sigma)", ge=0
    )
    anomaly_lambda_per_m: float = _m(
        "anomaly_lambda_per_m",
        "lambda_s, spatial correlation rate of the anomaly, 1/m (lambda_g = lambda_s * speed)",
        ge=0,
    )
    anomaly_sigma_mps2: float = _m("anomaly_sigma_mps2", "sigma_s, anomaly sigma, m/s^2", ge=0)
    altimeter_sigma_m: float = _m("altimeter_sigma_m", "sigma_eps, radial (height) measurement noise, m", ge=0)
    radius_source: Literal[RADIUS_SOURCES] = _m(  # type: ignore[valid-type]
        "radius_source",
        "|q| of the gravity model: `altimeter` (Andreev: stable in all channels) or `computed` "
        "(the navigation solution)",
    )
    initial_position_sigma_m: float = _m("initial_position_sigma_m", "initial sigma of each dq component, m", ge=0)
    initial_velocity_sigma_mps: float = _m(
        "initial_velocity_sigma_mps", "initial sigma of each dp component, m/s", ge=0
    )
    initial_anomaly_sigma_mps2: float = _m("initial_anomaly_sigma_mps2", "initial sigma of g, m/s^2", ge=0)
    initial_gravimeter_sigma_mps2: float = _m("initial_gravimeter_sigma_mps2", "initial sigma of f3, m/s^2", ge=0)
    gnss_aiding: bool = _m(
        "gnss_aiding",
        "use the record's GNSS positions (when it has a GNSS channel) as a "
        "position measurement; the filter then carries 14 states: the seed's 8 plus attitude "
        'error and gyro bias (docs/method.md, "GNSS position aiding"); `false`: the seed\'s '
        "altimeter-only filter",
    )
    gnss_horizontal_sigma_m: float = _m(
        "gnss_horizontal_sigma_m", "sigma of each GNSS sample's east and north error, m", gt=0
    )
    gnss_vertical_sigma_m: float = _m("gnss_vertical_sigma_m", "sigma of each GNSS sample's height error, m", gt=0)
    initial_attitude_sigma_deg: Optional[float] = _m(
        "initial_attitude_sigma_deg",
        "initial sigma of each attitude-error component, deg (GNSS-aided filter "
        "only); null: the alignment's own covariance when the attitude comes from the alignment, 0.05 deg when "
        "it was given",
        ge=0,
    )
    attitude_passes: int = _m(
        "attitude_passes",
        "most filter/smoother passes of a GNSS-aided flight: each re-mechanizes about the "
        "smoothed initial-attitude correction with the smoothed gyro bias taken off the rates; "
        "stops below 0.001 deg and 0.001 deg/h (or the bias's own sigma)",
        ge=1,
        le=5,
    )
    gyro_bias_sigma_degph: float = _m(
        "gyro_bias_sigma_degph",
        "sigma of each gyro's constant bias, deg/h (GNSS-aided filter only). Not given: 0.05, or where the "
        "likelihood takes a noisier gyro (gyro_drift_degph not given) a tenth of that gyro's white drift if larger "
        "(docs/method.md, 'Gyro noise by likelihood')",
        ge=0,
    )

    @model_validator(mode="after")
    def _accel_bias_states_kept(self):
        if self.accel_bias_mps2 is not None and self.accel_bias_states is False:
            raise fail(
                f"expected null or true with accel_bias_mps2 given ({self.accel_bias_mps2:g} m/s^2: the biases are "
                "estimated as states), got false",
                ("accel_bias_states",),
            )
        return self


# ============================================================================ lines
_ln = _defaults_of(SegmentationOptions)


class WindowSection(Section):
    """One time window ``{name, start_s, stop_s[, kind]}`` (s after the flight's first sample)."""

    name: str = Field(..., description="line name, unique in the flight", min_length=1)
    start_s: float = Field(..., description="start, s after the flight's first sample")
    stop_s: float = Field(..., description="end, s after the flight's first sample")
    kind: Optional[Literal["line", "tie"]] = Field(
        None, description="`line` or `tie`; default: `tie` for names `T<digit>...`, else `line`"
    )

    @model_validator(mode="after")
    def _ordered(self):
        if self.stop_s <= self.start_s:
            raise fail(f"expected finite start_s < stop_s, got {self.start_s:g} .. {self.stop_s:g}")
        return self


def check_unique_windows(windows: list[WindowSection], key: tuple) -> None:
    seen = set()
    for i, w in enumerate(windows):
        if w.name in seen:
            raise fail(f"'{w.name}' appears twice", key + (i, "name"))
        seen.add(w.name)


class LinesSection(Section):
    """``lines``: line segmentation (docs/outputs.md)."""

    mode: Literal[SEGMENTATION_MODES] = _ln(  # type: ignore[valid-type]
        "mode",
        "`auto` (straight-line detection from heading and speed), `windows` (the `windows` below), "
        "`whole` (the whole flight is line L01)",
    )
    min_line_m: float = _ln("min_line_m", "shortest line kept, along-track length, m", gt=0)
    min_line_s: Optional[float] = _ln(
        "min_line_s", "optional additional time limit, s (null: none; lines are specified by length)", gt=0
    )
    heading_tol_deg: float = _ln("heading_tol_deg", "heading deviation allowed on a line, deg", gt=0)
    min_speed_mps: float = _ln("min_speed_mps", "slower epochs are not line (stationary, taxi), m/s", ge=0)
    max_turn_rate_degps: float = _ln("max_turn_rate_degps", "faster heading change is a turn, deg/s", gt=0)
    max_vertical_speed_mps: Optional[float] = _ln(
        "max_vertical_speed_mps", "faster climb/descent is not line, m/s (null: no limit)", gt=0
    )
    max_climb_mps: Optional[float] = _ln(
        "max_climb_mps",
        "a climb/descent faster than this averaged over 60 s is not line either (a steady climb to the "
        "survey's altitude), m/s (null: no limit; a drape steeper than this needs a larger value)",
        gt=0,
    )
    speed_tol_mps: float = _ln("speed_tol_mps", "speed change allowed on a line, m/s", gt=0)
    smooth_s: float = _ln("smooth_s", "smoothing of heading/speed before detection, s", gt=0)
    merge_gap_s: float = _ln("merge_gap_s", "line pieces separated by less are merged, s", ge=0)
    transit_angle_deg: Optional[float] = _ln(
        "transit_angle_deg",
        "straight legs within this of the dominant direction are lines, within this of its "
        "perpendicular tie lines, in between transits (not lines; so are the short offset legs of procedure "
        "turns and the short connecting legs across the lines, docs/outputs.md), deg; null: no transits, "
        "`tie_angle_deg` decides",
        gt=0,
        lt=45,
    )
    line_heading_deg: Optional[float] = _ln(
        "line_heading_deg",
        "the survey plan's line direction, deg clockwise from north (axial: 10 and 190 alike), in the dominant "
        "direction's place: a flight that flew only tie lines names them T01...; null: each flight's own",
        ge=-360,
        le=360,
    )
    tie_angle_deg: float = _ln(
        "tie_angle_deg",
        "with `transit_angle_deg: null`: lines more than this from the dominant direction are tie lines, deg",
        gt=0,
        lt=90,
    )
    windows: list[WindowSection] = Field(
        default_factory=list,
        description="`mode: windows`: `{name, start_s, stop_s[, kind]}` for every flight (s after its first sample)",
    )

    @model_validator(mode="after")
    def _windows_given(self):
        if self.mode == "windows" and not self.windows:
            raise fail("required (a non-empty list) when mode is 'windows'", ("windows",))
        check_unique_windows(self.windows, ("windows",))
        return self


# ============================================================================ postprocess
_pp = _defaults_of(PostprocessOptions)


class PostprocessSection(Section):
    """``postprocess``: per-line post-processor (docs/wavelet.md)."""

    method: Literal[("default",) + METHODS] = _pp(  # type: ignore[valid-type]
        "method",
        "`default` (= `none`: the smoothed Kalman estimate, at the resolution stated in summary.json), "
        "`ti_cosphi`, `cosphi` (the seed's rule, faithful), `visushrink`, `sure`, `bayes`, `butterworth`, "
        "`gaussian`, `none`",
    )
    wavelet: Literal[WAVELETS] = _pp("wavelet", "`db10`, `coif4`, `auto` (the smaller Phi)")  # type: ignore[valid-type]
    thresholding: Literal[THRESHOLDINGS] = _pp(  # type: ignore[valid-type]
        "thresholding", "`soft` or `hard` (`cosphi`, `visushrink`)"
    )
    boundary: Literal[BOUNDARY_MODES] = _pp(  # type: ignore[valid-type]
        "boundary", "PyWavelets extension mode of the decimated pyramid"
    )
    resolution_m: Optional[float] = _pp(
        "resolution_m",
        "half-wavelength resolution of `butterworth`/`gaussian`, "
        "m (required by them unless `filter_length_s` is given)",
        gt=0,
    )
    filter_length_s: Optional[float] = _pp(
        "filter_length_s", "alternative to `resolution_m`: full filter wavelength, s", gt=0
    )
    butterworth_order: int = _pp(
        "butterworth_order", "Butterworth prototype order (applied forward-backward)", ge=1, le=12
    )
    threshold_steps: int = _pp("threshold_steps", "thresholds tried per level by `cosphi`", ge=1, le=100)
    max_level: Optional[int] = _pp("max_level", "highest level searched (null: 1 + floor(log2 N))", ge=1, le=64)
    min_level: int = _pp("min_level", "lowest level searched by `ti_cosphi`", ge=1, le=64)

    @model_validator(mode="after")
    def _one_length(self):
        if self.resolution_m is not None and self.filter_length_s is not None:
            raise fail("give at most one of resolution_m and filter_length_s, not both")
        if self.method in LOWPASS_METHODS and self.resolution_m is None and self.filter_length_s is None:
            raise fail(f"required by method {self.method!r} (or give filter_length_s)", ("resolution_m",))
        if self.max_level is not None and self.max_level < self.min_level:
            raise fail(f"must be >= min_level ({self.min_level})", ("max_level",))
        return self


# ============================================================================ drift
_dr = _defaults_of(DriftOptions)


class DriftSection(Section):
    """``drift``: the gravimeter drift told from the field by the survey's lines (docs/method.md)."""

    estimate: bool = _dr(
        "estimate",
        "separate the drift with the lines (a field shared by neighbouring lines, a drift in time): "
        "the fitted drift when the likelihood needs it, else the datasheet drift (`sigma_mps2`, `tau_s`) "
        "as far as the lines show it, unless they speak against it",
    )
    block_s: float = _dr("block_s", "block length of the field-plus-drift fit, s", ge=10, le=3600)
    sigma_mps2: float = _dr(
        "sigma_mps2",
        "centre of the prior on the drift's Gauss-Markov sigma, the datasheet drift taken off when the lines "
        "cannot fit one, and the drift the stated sigma (`sigma_mgal`) carries where none is taken off "
        "(a datasheet figure), m/s^2",
        gt=0,
        le=1e-3,
    )
    tau_s: float = _dr(
        "tau_s",
        "centre of the prior on the drift's correlation time, and the datasheet drift's (also in the stated sigma), s",
        gt=0,
        le=1e6,
    )
    field_filter: bool = _dr(
        "field_filter",
        "where a drift is taken off, Wiener-filter each line against what the lines left of it (the drift fit's "
        "field against the drift's posterior; its resolution is stated with the smoother's); only with "
        "`postprocess.method` none, the default",
    )
    tares: bool = _dr(
        "tares",
        "look for tares, steps in the gravimeter's reading (a spring meter after a shock, a strapdown "
        "gravimeter's bias jump), and take off those the lines need with the drift (a note names each)",
    )


# ============================================================================ checks (survey level)
_ck = _defaults_of(CheckOptions)


class ChecksSection(Section):
    """``checks``: gaps, clocks, input consistency and result plausibility (docs/reliability.md)."""

    max_imu_gap_s: float = _ck(
        "max_imu_gap_s",
        "IMU gaps up to this long are bridged by the mechanization; "
        "longer ones split the flight into separately estimated segments, s",
        gt=0,
    )
    max_aiding_gap_s: float = _ck(
        "max_aiding_gap_s",
        "gaps with neither altimeter nor GNSS samples up to this "
        "long are bridged (the smoothed sigma grows across them); longer ones split "
        "the flight, s",
        gt=0,
    )
    max_time_offset_s: float = _ck(
        "max_time_offset_s",
        "largest IMU-GNSS clock offset (measured by cross-correlating specific force) accepted, s",
        gt=0,
    )
    max_gravity_mismatch_mgal: float = _ck(
        "max_gravity_mismatch_mgal",
        "largest median difference between the specific-force magnitude the IMU "
        "measures and the one the GNSS track and normal gravity imply, mGal; beyond it an error when a GNSS "
        "column mix-up explains it or it exceeds 5x this, else a note",
        gt=0,
    )
    max_abs_disturbance_mgal: float = _ck(
        "max_abs_disturbance_mgal", "largest absolute disturbance of the final product on lines, mGal", gt=0
    )
    max_track_deviation_m: float = _ck(
        "max_track_deviation_m",
        "largest horizontal distance of the GNSS-aided navigation from the GNSS track (31-epoch running median), m",
        gt=0,
    )
    allow_no_lines: bool = _ck("allow_no_lines", "accept a flight in which no survey line is found")
    allow_nonfinite: bool = _ck("allow_nonfinite", "accept non-finite values in the estimate or product")


# ============================================================================ levelling, grid
_lv = _defaults_of(LevellingOptions)


class LevellingSection(Section):
    """``levelling``: crossover levelling (gravsurvey/levelling.py, docs/survey.md)."""

    enabled: Optional[bool] = _lv(
        "enabled",
        "null: level when there are at least `min_crossovers_per_unknown` "
        "crossovers per unknown; true: whenever there are crossovers; false: never",
    )
    model: Literal[LEVELLING_MODELS] = _lv(  # type: ignore[valid-type]
        "model",
        "`constant` per line, `line_trend` (constant + trend per line), `flight_trend` (constant per "
        "line + drift per untied flight), `flight_constant` (one constant per flight: the reduced model "
        "for surveys with few crossovers)",
    )
    robust: bool = _lv("robust", "Huber IRLS (outlying crossovers lose weight)")
    huber_k: float = _lv("huber_k", "Huber constant, robust standard deviations", gt=0)
    sigma_floor_mgal: float = _lv(
        "sigma_floor_mgal", "smallest line sigma in the weights `1/(sigma_a^2 + sigma_b^2)`, mGal", gt=0
    )
    max_iterations: int = _lv("max_iterations", "IRLS iterations at most", ge=1)
    min_crossovers_per_unknown: float = _lv(
        "min_crossovers_per_unknown",
        "redundancy needed for automatic levelling (below it the adjustment fits noise)",
        gt=0,
    )
    significance: float = _lv(
        "significance",
        "with `enabled: null`, corrections are applied only when the F-test of 'no level errors' "
        "rejects it at this level (levelling.significance_test)",
        gt=0,
        lt=1,
    )


_gr = _defaults_of(GridOptions)


class GridSection(Section):
    """``grid``: gridding of the levelled lines (gravsurvey/grid.py, docs/survey.md)."""

    enabled: Optional[bool] = _gr("enabled", "null: grid when the survey has >= 2 lines; false: never")
    method: Literal[GRID_METHODS] = _gr(  # type: ignore[valid-type]
        "method",
        "`equivalent_sources` (point sources as harmonica fits them, continued to `altitude_m`) or verde `spline` "
        "(2-D, at the flight heights)",
    )
    spacing_m: Optional[float] = _gr("spacing_m", "grid cell size, m (null: line spacing / 4)", gt=0)
    altitude_m: Optional[float] = _gr("altitude_m", "ellipsoidal height of the grid, m (null: median flight height)")
    max_distance_m: Optional[float] = _gr(
        "max_distance_m", "cells farther from the data are empty, m (null: 0.6 line spacing)", gt=0
    )
    depth_m: Optional[float] = _gr(
        "depth_m", "equivalent-source depth below the data, m (null: 1.5 line spacing)", gt=0
    )
    damping: Optional[float] = _gr(
        "damping", "damping of the source coefficients (null: from 0.01, 1, 100 by block k-fold cross-validation)", gt=0
    )
    cv_folds: int = _gr("cv_folds", "cross-validation folds", ge=2)


# ============================================================================ flights


class TieReadingSection(Section):
    """A still reading at the base: ``{reading_mgal[, time_s]}`` or ``{start_s, stop_s}``."""

    reading_mgal: Optional[float] = Field(
        None,
        description="absolute gravity the processed data read at the base, mGal",
        ge=G_ABS_RANGE_MGAL[0],
        le=G_ABS_RANGE_MGAL[1],
    )
    time_s: Optional[float] = Field(
        None, description="when, s after the flight's first sample (default: the flight's first/last epoch)"
    )
    start_s: Optional[float] = Field(None, description="still window start, s after the flight's first sample")
    stop_s: Optional[float] = Field(None, description="still window end, s after the flight's first sample")

    @model_validator(mode="after")
    def _one_form(self):
        value_form = self.reading_mgal is not None
        window_form = self.start_s is not None or self.stop_s is not None
        if value_form == window_form:
            raise fail(
                "give either reading_mgal (with time_s) or start_s and stop_s, not "
                f"{'both' if value_form else 'neither'}"
            )
        if window_form:
            if self.start_s is None or self.stop_s is None:
                raise fail("a window needs both start_s and stop_s (s after the flight's first sample)")
            if self.stop_s <= self.start_s:
                raise fail(f"expected start_s < stop_s, got {self.start_s:g} .. {self.stop_s:g}")
            if self.time_s is not None:
                raise fail("only with reading_mgal (a window has its own times)", ("time_s",))
        return self


class TieSection(Section):
    """``flights[i].tie``: base tie, absolute level and linear drift of a flight (docs/survey.md)."""

    base_gravity_mgal: float = Field(
        ..., description="absolute gravity at the base station, mGal", ge=G_ABS_RANGE_MGAL[0], le=G_ABS_RANGE_MGAL[1]
    )
    before: Optional[TieReadingSection] = Field(
        None,
        description="base reading before the flight: `{reading_mgal, time_s}` or a still window `{start_s, stop_s}`",
    )
    after: Optional[TieReadingSection] = Field(None, description="base reading after the flight (as `before`)")
    base_lat_deg: Optional[float] = Field(
        None,
        description="base latitude for its normal gravity, deg (null: median position in the window)",
        ge=-90,
        le=90,
    )
    base_height_m: Optional[float] = Field(None, description="base ellipsoidal height, m (null: median in the window)")

    @model_validator(mode="after")
    def _a_reading(self):
        if self.before is None and self.after is None:
            raise fail("needs a base reading before and/or after the flight (before:, after:)")
        return self


def three_numbers(v: list[float]) -> list[float]:
    if len(v) != 3:
        raise fail(f"expected a list of 3 numbers, got {v!r:.60}")
    return v


#: a vector of 3 numbers (the meaning of each is in the key's description)
Vector3 = Annotated[list[float], AfterValidator(three_numbers)]


class InitialSection(Section):
    """``flights[i].initial``: optional overrides of the first state (checked against the data)."""

    lat_deg: Optional[float] = Field(None, description="geodetic latitude, deg", gt=-90, lt=90)
    lon_deg: Optional[float] = Field(None, description="longitude, deg")
    height_m: Optional[float] = Field(None, description="ellipsoidal height, m")
    velocity_enu_mps: Optional[Vector3] = Field(None, description="[E, N, U] velocity relative to the Earth, m/s")
    attitude_deg: Optional[Vector3] = Field(
        None,
        description="[roll, pitch, heading] of the triad w.r.t. ENU, deg "
        "(strapdown only; used instead of the alignment when its sigma "
        "`model.initial_attitude_sigma_deg` is smaller)",
    )


def _role_model(name: str, table: dict, desc: str, vector_keys=(), optional=None) -> type:
    """A section whose keys are the roles, each a mapping of quantity -> name(s) (from ``table``;
    ``optional``: role -> {quantity: description} of keys without a default)."""
    roles = {}
    for role, names in table.items():
        extra = {
            q: (Optional[Any], Field(None, description=text, json_schema_extra={"type_text": "string"}))
            for q, text in (optional or {}).get(role, {}).items()
        }
        fields = {
            q: (
                Optional[Any],
                Field(
                    None,
                    description=f"{desc} for {q} (default `{v}`)",
                    json_schema_extra={"type_text": "string" + (" or list" if q in vector_keys else "")},
                ),
            )
            for q, v in names.items()
        } | extra
        sub = create_model(f"{name}_{role}", __base__=Section, __doc__=f"{desc}: {role} channel", **fields)  # type: ignore[call-overload]
        roles[role] = (Optional[sub], Field(None, description=f"{role} channel"))
    return create_model(name, __base__=Section, __doc__=desc, **roles)  # type: ignore[call-overload]


def _names(v, allowed_lengths, what: str):
    if isinstance(v, str) and v:
        return v
    if isinstance(v, list) and len(v) in allowed_lengths and all(isinstance(x, str) and x for x in v):
        return list(v)
    raise fail(f"expected {what}, got {v!r:.60}")


JsonFields = _role_model("JsonFields", DEFAULT_JSON_FIELDS, "MCAP JSON field name", ("specific_force", "angular_rate"))
_ECEF_TEXT = {
    q: f"CSV column name for ECEF {q.upper()}, m (no default; with x, y and z the positions are read as "
    "Earth-centred Earth-fixed coordinates instead of lat/lon/height)"
    for q in ECEF_QUANTITIES
}
CsvColumns = _role_model(
    "CsvColumns", DEFAULT_COLUMNS, "CSV column name", ("time",), {"gnss": _ECEF_TEXT, "altimeter": _ECEF_TEXT}
)
UnitsSection = create_model(  # type: ignore[call-overload]
    "UnitsSection",
    __base__=Section,
    __doc__="units of the channels as written",
    **{
        k: (
            Literal[tuple(v)],  # type: ignore[misc]
            Field(
                next(iter(v)),
                description=f"unit of {k}: {', '.join(v)}"
                + (
                    f" ({' and '.join(INCREMENT_UNITS[k])}: increments per sample, accel and gyro alike; "
                    "docs/input-formats.md)"
                    if k in INCREMENT_UNITS
                    else " (the GNSS's latitude and longitude)"
                    if k == "latlon"
                    else ""
                ),
            ),
        )
        for k, v in UNITS.items()
    },
)


class McapSection(Section):
    """``flights[i].mcap``: MCAP reading options (docs/input-formats.md)."""

    json_fields: JsonFields = Field(  # type: ignore[valid-type]
        default_factory=JsonFields,
        description="JSON field names per channel; "  # type: ignore[valid-type]
        "`specific_force`/`angular_rate`: one array field or 3 scalar fields",
    )
    units: UnitsSection = Field(
        default_factory=UnitsSection,
        description="units of accel, gyro, height, "  # type: ignore[valid-type]
        "gradient, GNSS latitude/longitude (latlon)",
    )
    time_source: Literal["auto", "log_time"] = Field(
        "auto", description="`auto` (header.stamp / JSON time, else log_time) or `log_time`"
    )
    check_crc: bool = Field(True, description="verify chunk CRCs")
    max_record_mib: int = Field(
        DEFAULT_MAX_RECORD_BYTES // 2**20,
        description="largest record read, MiB (a larger length field is damage)",
        ge=1,
        le=65536,
    )

    @field_validator("json_fields", mode="after")
    @classmethod
    def _field_names(cls, v):
        for role, names in v:
            if names is None:
                continue
            for q, x in names:
                if x is not None:
                    try:
                        _names(
                            x,
                            (3,) if q in ("specific_force", "angular_rate") else (),
                            "a field name"
                            + (" or a list of 3 field names" if q in ("specific_force", "angular_rate") else ""),
                        )
                    except PydanticCustomError as exc:
                        raise fail(exc.context["message"], (role, q)) from None  # type: ignore[index]
        return v


class CsvSection(Section):
    """``flights[i].csv``: CSV layout (docs/input-formats.md)."""

    columns: CsvColumns = Field(default_factory=CsvColumns, description="column names per channel")  # type: ignore[valid-type]
    time_format: Literal[TIME_FORMATS] = Field("ns", description="`ns`, `s`, `gps_week_sow` or `iso`")  # type: ignore[valid-type]
    units: UnitsSection = Field(
        default_factory=UnitsSection,
        description="units of accel, gyro, height, "  # type: ignore[valid-type]
        "gradient, GNSS latitude/longitude (latlon)",
    )
    delimiter: str = Field(",", description="one character such as `,` `;` or a tab")
    gps_leap_seconds: int = Field(18, description="GPS - UTC, s (time_format `iso`)", ge=0, le=100)

    @field_validator("delimiter")
    @classmethod
    def _one_char(cls, d):
        if len(d) != 1 or d in '#"\r\n0123456789.-+eE':
            raise fail(f"expected one character such as ',' ';' or a tab, got {d!r}")
        return d

    @model_validator(mode="after")
    def _time_columns(self):
        for role, cm in self.columns:
            if cm is None:
                continue
            given = {q for q, v in cm if v is not None}
            if given & set(ECEF_QUANTITIES):
                missing = [q for q in ECEF_QUANTITIES if q not in given]
                both = sorted(given & {"lat", "lon", "height"})
                if missing or both:
                    raise fail(
                        "ECEF positions need the x, y and z columns together and no lat/lon/height, got "
                        + (f"no {', '.join(missing)}" if missing else f"also {', '.join(both)}"),
                        ("columns", role),
                    )
            for q, v in cm:
                if v is None:
                    continue
                if q == "time":
                    v = _names_at(
                        v,
                        (2, 3),
                        "a column name, or [week, seconds_of_week] or [cycle, week, seconds_of_week] columns",
                        ("columns", role, q),
                    )
                    if isinstance(v, list) != (self.time_format == "gps_week_sow"):
                        raise fail(
                            f"time_format {self.time_format} needs "
                            f"{'two columns' if isinstance(v, str) else 'one column'}, got {v!r}",
                            ("columns", role, q),
                        )
                else:
                    _names_at(v, (), "a column name", ("columns", role, q))
        return self


def _names_at(v, lengths, what, key):
    try:
        return _names(v, lengths, what)
    except PydanticCustomError as exc:
        raise fail(exc.context["message"], key) from None  # type: ignore[index]


#: Largest clock offset a channel may be given, s (a week: GPS time against a logger's local
#: time zone is hours; a bigger value is a wrong unit).
MAX_TIME_OFFSET_S = 7 * 86400.0


class TimeOffsetsSection(Section):
    """``flights[i].time_offsets_s``: seconds added to a channel's stamps as read (docs/input-formats.md)."""

    imu: float = Field(0.0, description="added to the IMU stamps, s", ge=-MAX_TIME_OFFSET_S, le=MAX_TIME_OFFSET_S)
    altimeter: float = Field(
        0.0, description="added to the altimeter stamps, s", ge=-MAX_TIME_OFFSET_S, le=MAX_TIME_OFFSET_S
    )
    gnss: float = Field(
        0.0,
        description="added to the GNSS stamps, s (a GNSS in GPS time against an IMU in UTC: -18)",
        ge=-MAX_TIME_OFFSET_S,
        le=MAX_TIME_OFFSET_S,
    )
    gradient: float = Field(
        0.0, description="added to the gradiometer stamps, s", ge=-MAX_TIME_OFFSET_S, le=MAX_TIME_OFFSET_S
    )


class FlightChecksSection(Section):
    """``flights[i].checks``: gap detection and plausibility of the inputs (docs/input-formats.md)."""

    gap_factor: float = Field(
        5.0, description="a sample step longer than this many nominal steps is a gap", ge=1.5, le=1e6
    )
    plausibility: Literal["error", "warn"] = Field("error", description="implausible inputs: `error` or `warn`")


class CsvInputs(Section):
    """``inputs.csv``: one CSV file per channel."""

    imu: str = Field(..., description="IMU CSV file", min_length=1)
    altimeter: Optional[str] = Field(
        None,
        description="altimeter CSV file (default: the GNSS file: its heights are the height channel)",
        min_length=1,
    )
    gnss: Optional[str] = Field(None, description="GNSS CSV file", min_length=1)
    gradient: Optional[str] = Field(None, description="gravity-gradient CSV file", min_length=1)

    @model_validator(mode="after")
    def _height_channel(self):
        if self.altimeter is None and self.gnss is None:
            raise fail(
                "missing: give the altimeter CSV file, or the GNSS file (its heights are then the height channel)",
                ("altimeter",),
            )
        return self


class NavSection(Section):
    """``inputs.gravimeter.nav`` (the navigation of a gravimeter flight) or ``inputs.nav`` (an NMEA or
    GNSS trajectory file as the GNSS of an INS flight; heights must be ellipsoidal)."""

    format: Literal[NAV_FORMATS] = Field(..., description="`nmea`, `trajectory` or `rtklib` (an RTKLIB .pos solution)")  # type: ignore[valid-type]
    file: str = Field(..., description="navigation file", min_length=1)
    time_source: Optional[Literal["auto", "fix", "logger"]] = Field(
        None, description="nmea only: `auto`, `fix` (the fix clock) or `logger` (default `auto`)"
    )
    time_system: Optional[Literal["auto", "gps", "utc"]] = Field(
        None, description="trajectory only: `auto`, `gps` or `utc` (default `auto`)"
    )

    @model_validator(mode="after")
    def _format_options(self):
        if self.time_source is not None and self.format != "nmea":
            raise fail(f"nmea only (format is {self.format})", ("time_source",))
        if self.time_system is not None and self.format != "trajectory":
            raise fail(f"trajectory only (format is {self.format})", ("time_system",))
        return self


class GravimeterSection(Section):
    """``inputs.gravimeter``: a vendor gravimeter file + navigation (classic chain only;
    docs/input-formats.md)."""

    format: Literal[tuple(GRAVIMETER_FORMATS)] = Field(  # type: ignore[misc,valid-type]
        ..., description="`mgd77t`, `dgs_laptop`, `at1a`, `zls`, `bgm_serial` or `bgm_rgs`"
    )
    file: Optional[str] = Field(None, description="the gravimeter file (or `files`)", min_length=1)
    files: Optional[list[Annotated[str, Field(min_length=1)]]] = Field(
        None, description="several files (zls only: a list of files or a directory)", min_length=1
    )
    offset_mgal: Optional[float] = Field(
        None,
        description="base-tie offset: absolute gravity = scale x reading + offset_mgal, mGal; required for "
        "meter-unit formats (dgs_laptop, at1a, zls, bgm_serial), default 0 for the others",
    )
    scale: float = Field(1.0, description="meter calibration factor applied to the reading first", gt=0)
    counts_scale_mgal: Optional[float] = Field(
        None, description="bgm_serial only (required there): mGal per count", gt=0
    )
    time_source: Optional[Literal["auto", "meter", "logger"]] = Field(
        None, description="dgs_laptop only: `auto`, `meter` or `logger` clock (default `auto`)"
    )
    height_m: Optional[float] = Field(
        None,
        description="constant ellipsoidal height of the meter, m (overrides nav heights)",
        ge=HEIGHT_OK[0],
        le=HEIGHT_OK[1],
    )
    nav: Optional[NavSection] = Field(
        None, description="navigation file; required for formats without positions (dgs_laptop's are optional)"
    )

    @model_validator(mode="after")
    def _format_rules(self):
        fmt, info = self.format, GRAVIMETER_FORMATS[self.format]
        if (self.file is None) == (self.files is None):
            raise fail("give file (one path) or files (a list of paths)")
        if self.files is not None and fmt != "zls" and len(self.files) > 1:
            raise fail(f"format {fmt} reads one file per flight; got {len(self.files)}", ("files",))
        if self.offset_mgal is None and not info["absolute"]:
            raise fail(
                f"missing; {fmt} readings are in meter units with an arbitrary offset: give the base-tie offset "
                "(absolute gravity = scale x reading + offset_mgal)",
                ("offset_mgal",),
            )
        if fmt == "bgm_serial" and self.counts_scale_mgal is None:
            raise fail("missing; bgm_serial needs the meter's mGal per count", ("counts_scale_mgal",))
        if fmt != "bgm_serial" and self.counts_scale_mgal is not None:
            raise fail("only for format bgm_serial", ("counts_scale_mgal",))
        if self.time_source is not None and fmt != "dgs_laptop":
            raise fail("only for format dgs_laptop (the others have one clock)", ("time_source",))
        if self.nav is None and not info["positions"]:
            raise fail(
                f"missing; {fmt} files hold no positions: give nav: {{format: nmea|trajectory|rtklib, file: ...}}",
                ("nav",),
            )
        return self


class InputsSection(Section):
    """``flights[i].inputs``: exactly one of ``mcap``, ``csv``, ``gravimeter``."""

    mcap: Optional[str] = Field(None, description="one MCAP file with the channels", min_length=1)
    csv: Optional[CsvInputs] = Field(None, description="`{imu: f, altimeter: f, gnss: f}`")
    gravimeter: Optional[GravimeterSection] = Field(
        None,
        description="`{format: f, file: f, ...}`: a vendor gravimeter file + "
        "navigation, classic chain only (docs/input-formats.md)",
    )
    nav: Optional[NavSection] = Field(
        None,
        description="`{format: nmea|trajectory|rtklib, file: f}`: a navigation file that is the flight's GNSS, next to "
        "`mcap` or `csv` (docs/input-formats.md)",
    )

    @model_validator(mode="before")
    @classmethod
    def _exactly_one(cls, data):
        # before the fields: with two inputs, naming the choice helps more than a key inside one
        if data is None:
            data = {}
        if isinstance(data, dict) and set(data) <= set(cls.model_fields):
            given = [k for k in ("mcap", "csv", "gravimeter") if data.get(k) is not None]
            if len(given) != 1:
                raise fail(f"expected exactly one of mcap, csv, gravimeter, got {', '.join(given) or 'none'}")
            if data.get("nav") is not None and data.get("gravimeter") is not None:
                raise fail("only next to mcap or csv; a gravimeter's navigation is inputs.gravimeter.nav", ("nav",))
        return data


class TopicsSection(Section):
    """``flights[i].topics``: MCAP topic per channel (else found by schema)."""

    imu: str = Field(stage_default(IngestOptions, "topics")["imu"], description="IMU topic", min_length=1)
    altimeter: str = Field(
        stage_default(IngestOptions, "topics")["altimeter"], description="altimeter topic", min_length=1
    )
    gnss: str = Field(stage_default(IngestOptions, "topics")["gnss"], description="GNSS topic", min_length=1)
    gradient: Optional[str] = Field(
        None, description="gravity-gradient topic (default `/gradient`, else found by its schema)", min_length=1
    )


#: Flight-level keys handed to ingestion (io/ingest.py)
INGEST_KEYS = ("inputs", "topics", "mcap", "csv", "checks", "imu_axes", "gnss_lever_arm_m", "time_offsets_s")


class TruthColumns(Section):
    """``flights[i].truth.columns``: the reference file's column names."""

    time: str = Field("time_ns", description="time column (see `time_format`)", min_length=1)
    disturbance_mgal: str = Field("disturbance_mgal", description="gravity disturbance column, mGal", min_length=1)


class TruthSection(Section):
    """``flights[i].truth`` as a mapping: a reference profile in any CSV (docs/formats.md)."""

    file: str = Field(..., description="the reference CSV", min_length=1)
    columns: TruthColumns = Field(default_factory=TruthColumns, description="column names")  # type: ignore[valid-type]
    time_format: Literal[TRUTH_TIME_FORMATS] = Field(  # type: ignore[valid-type]
        "ns", description="`ns` (integer Unix ns) or `s` (Unix seconds)"
    )
    delimiter: str = Field(",", description="one character such as `,` `;` or a tab", min_length=1, max_length=1)


class FlightSection(Section):
    """``flights[i]``: one flight."""

    name: Optional[str] = Field(
        None, description="unique flight name, `[A-Za-z0-9_.-]{1,64}` (default `F01`, `F02`, ...)"
    )
    inputs: InputsSection = Field(
        ...,
        description="`{mcap: file}` or `{csv: {imu: f, altimeter: f, gnss: f}}` "
        "or `{gravimeter: {format: f, file: f, ...}}` (vendor gravimeter file + "
        "navigation, classic chain only: docs/input-formats.md)",
    )
    topics: TopicsSection = Field(default_factory=TopicsSection, description="MCAP topic per channel")
    mcap: McapSection = Field(
        default_factory=McapSection,
        description="JSON field names, units, time source, CRC check, record size bound (docs/input-formats.md)",
    )
    csv: CsvSection = Field(
        default_factory=CsvSection, description="column names, time format, units, delimiter (docs/input-formats.md)"
    )
    checks: FlightChecksSection = Field(
        default_factory=FlightChecksSection,
        description="gap detection and plausibility checks of the inputs (docs/input-formats.md)",
    )
    time_offsets_s: TimeOffsetsSection = Field(
        default_factory=TimeOffsetsSection,
        description="seconds added to each channel's stamps as read, `{imu, altimeter, gnss, gradient}` "
        "(clocks known to differ; docs/input-formats.md)",
    )
    triad: Literal[TRIADS] = Field(  # type: ignore[valid-type]
        "platform",
        description="`platform` (ENU-stabilised) or `strapdown` "  # type: ignore[valid-type]
        "(body-fixed triad; docs/conventions.md)",
    )
    imu_axes: Any = Field(
        "FLU",
        json_schema_extra={"type_text": "`FLU` \\| `FRD` \\| `RFU` \\| 3x3 matrix"},
        description="the IMU's axis convention: `FLU` forward-left-up (gravsurvey's "
        "own), `FRD` forward-right-down (VectorNav, Xsens, iMAR, NovAtel), `RFU` "
        "right-forward-up, or a 3x3 proper rotation `M` with `vec_flu = M vec_sensor`; "
        "with `triad: platform` the third axis must then read +g (checked before processing)",
    )
    gnss_lever_arm_m: Optional[list[float]] = Field(
        None,
        json_schema_extra={"type_text": "[forward, left, up], numbers, or null"},
        description="[forward, left, up] "
        "GNSS antenna position from the IMU on the aircraft's (FLU) axes, m (a strapdown "
        "triad's; on a platform the aircraft's attitude comes from the track); null: found from "
        "the aided track and applied when clear (a warning says so); applied to the GNSS "
        "positions and, where the height channel is the GNSS's own heights, to those",
    )
    initial: Optional[InitialSection] = Field(
        None,
        description="optional overrides of the state at the first IMU sample (`initial` below); null: from the data",
    )
    truth: Optional[
        Annotated[
            Union[Annotated[str, Field(min_length=1), Tag("<path>")], Annotated[TruthSection, Tag("<mapping>")]],
            Discriminator(lambda v: "<mapping>" if isinstance(v, dict) else "<path>"),
        ]
    ] = Field(
        None,
        description="reference profile: a simulator truth CSV path (docs/formats.md), or "
        "`{file, columns: {time, disturbance_mgal}, time_format: ns|s, delimiter}` for any CSV; adds "
        "`truth_mgal`, `error_mgal`",
    )
    lines: Optional[list[WindowSection]] = Field(
        None, description="explicit line windows for this flight, `{name, start_s, stop_s[, kind]}`"
    )
    tie: Optional[TieSection] = Field(None, description="base tie (`flights[].tie` below, docs/survey.md)")

    @field_validator("lines")
    @classmethod
    def _window_names(cls, v):
        if v is not None:
            check_unique_windows(v, ())
        return v

    @field_validator("name")
    @classmethod
    def _safe_name(cls, v):
        if v is not None and not re.match(FLIGHT_NAME_PATTERN, v):
            raise fail(f"expected 1-64 characters of A-Z a-z 0-9 _ . -, got {v!r}")
        return v

    @field_validator("imu_axes")
    @classmethod
    def _axes(cls, v):
        try:
            imu_axes_matrix(v, "")
        except ConfigError as exc:
            raise fail(str(exc).split(": ", 1)[1]) from None
        return v

    @model_validator(mode="after")
    def _increments_or_rates(self):
        for sec in ("mcap", "csv"):
            units = getattr(self, sec).units
            inc = [u in INCREMENT_UNITS[q] for q, u in (("accel", units.accel), ("gyro", units.gyro))]
            if inc[0] != inc[1]:
                raise fail(
                    f"accel {units.accel!r} and gyro {units.gyro!r}: one is an increment per sample and the other a "
                    "rate; declare both as increments (m/s with rad or deg) or both as rates",
                    (sec, "units"),
                )
        return self

    @model_validator(mode="after")
    def _offsets_need_channels(self):
        if self.inputs.gravimeter is not None and any(v != 0.0 for _, v in self.time_offsets_s):
            raise fail(
                "a gravimeter flight's channels come from its own file and navigation; offsets are for mcap or "
                "csv inputs",
                ("time_offsets_s",),
            )
        return self

    @field_validator("gnss_lever_arm_m")
    @classmethod
    def _arm(cls, v):
        if v is None:
            return v
        if len(v) != 3:
            raise fail(f"expected [forward, left, up] in m on the IMU's (FLU) axes, got {v!r:.60}")
        if max(abs(x) for x in v) > MAX_LEVER_ARM_M:
            raise fail(f"expected [forward, left, up] in m within {MAX_LEVER_ARM_M:g} m, got {v!r}")
        return v


# ============================================================================ top level
class SurveySection(Section):
    """``survey``: name and description."""

    name: Optional[str] = Field(
        None, description="survey name in outputs (default: the config file's name)", min_length=1
    )
    description: Optional[str] = Field(None, description="free text")

    @field_validator("name")
    @classmethod
    def _not_blank(cls, v):
        if v is not None and not v.strip():
            raise fail(f"expected a non-empty string, got {v!r}")
        return v


class ProcessingSection(Section):
    """``processing``: the estimation chain."""

    method: Literal[PROCESSING_METHODS] = Field(  # type: ignore[valid-type]
        "inm",
        description="`inm` (3D-INM Kalman/RTS) or `classic` (the "  # type: ignore[valid-type]
        "conventional scalar reduction, docs/benchmarks.md)",
    )
    classic_resolution_m: Optional[float] = Field(
        None,
        description="half-wavelength resolution of the classic method's low-pass, m (null: classic's default)",
        gt=0,
    )
    normal_gravity: Literal[NORMAL_GRAVITY_CHOICES] = Field(  # type: ignore[valid-type]
        "exact",
        description="classic only: normal gravity subtracted: `exact` (the field of `ellipsoid`) or a "
        "closed-form formula (IGF1967 for comparisons with NCEI/MGD77 archives; docs/input-formats.md)",
    )
    gradiometer: bool = Field(
        False,
        description="seed-000 products of a flight's gravity-gradient channel in "
        "summary.json `flights.<F>.estimator.gradiometer` (docs/method.md section 7)",
    )

    @model_validator(mode="after")
    def _classic_formula(self):
        if self.normal_gravity != "exact" and self.method != "classic":
            raise fail(
                f"{self.normal_gravity} applies to processing.method classic only (the 3D-INM uses the "
                "exact normal gravity field)",
                ("normal_gravity",),
            )
        return self


class OutputSection(Section):
    """``output``: deliverables."""

    dir: str = Field("out", description="output directory (relative to the config file; `-o` overrides)", min_length=1)
    epsg: Optional[int] = Field(
        None,
        description="projected CRS of `easting_m`/`northing_m` (null: the UTM zone of the data; UPS North / "
        "South, EPSG 5041 / 5042, where the data's median latitude is north of 84 deg N or south of 80 deg S)",
        gt=0,
    )
    plots: bool = Field(True, description="write PNG plots")
    xyz: bool = Field(True, description="write Geosoft XYZ")
    geojson: bool = Field(True, description="write GeoJSON lines")


class SurveyFile(Section):
    """The whole processing config."""

    survey: SurveySection = Field(default_factory=SurveySection, description="`name`, `description`")
    ellipsoid: Literal[ELLIPSOIDS] = Field(  # type: ignore[valid-type]
        "WGS84",
        description="reference of heights, positions and normal "  # type: ignore[valid-type]
        "gravity",
    )
    flights: list[FlightSection] = Field(..., description="one mapping per flight", min_length=1)
    model: ModelSection = Field(default_factory=ModelSection, description="3D-INM filter parameters")
    lines: LinesSection = Field(default_factory=LinesSection, description="line segmentation")
    postprocess: PostprocessSection = Field(
        default_factory=PostprocessSection, description="per-line post-processor (docs/wavelet.md)"
    )
    processing: ProcessingSection = Field(default_factory=ProcessingSection, description="estimation chain")
    output: OutputSection = Field(default_factory=OutputSection, description="deliverables")
    checks: ChecksSection = Field(
        default_factory=ChecksSection,
        description="gaps, clocks, input consistency "
        "and result plausibility; not the flight-level `checks` of ingestion",
    )
    drift: DriftSection = Field(
        default_factory=DriftSection, description="gravimeter drift from the lines (docs/method.md)"
    )
    levelling: LevellingSection = Field(default_factory=LevellingSection, description="crossover levelling")
    grid: GridSection = Field(default_factory=GridSection, description="gridding of the levelled lines")

    @field_validator("ellipsoid", mode="before")
    @classmethod
    def _upper(cls, v):
        return v.upper() if isinstance(v, str) and v.upper() in ELLIPSOIDS else v

    @model_validator(mode="after")
    def _across_sections(self):
        names = set()
        for i, fl in enumerate(self.flights):
            name = fl.name or f"F{i + 1:02d}"
            if name in names:
                raise fail(f"flight name {name!r} is used twice", ("flights", i, "name"))
            names.add(name)
            if fl.inputs.gravimeter is not None and self.processing.method != "classic":
                raise fail(
                    "a gravimeter file is processed by the classic chain only; set processing.method: "
                    f"classic (got {self.processing.method!r})",
                    ("flights", i, "inputs", "gravimeter"),
                )
        return self
