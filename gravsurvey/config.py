"""Processing configuration: YAML -> validated settings.

The YAML is loaded safely (``yaml.safe_load``: no object construction from tags).
Every key is documented in docs/config.md; paths are relative to the config file.
Sections owned by a stage are validated by that stage's own ``from_dict``
(``model`` by :mod:`gravsurvey.inm.params`, ``lines`` by :mod:`gravsurvey.survey`,
``postprocess`` by :mod:`gravsurvey.wavelet`, a flight's input keys by
:mod:`gravsurvey.io.ingest`); this module checks the frame around them and names
the key path in every error.
"""

from __future__ import annotations

import hashlib
import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from .errors import ConfigError, check_keys
from .io.ingest import INGEST_KEYS as FLIGHT_INGEST_KEYS

TOP_KEYS = ("survey", "ellipsoid", "flights", "model", "lines", "postprocess", "processing", "output",
            "levelling", "grid")
SURVEY_KEYS = ("name", "description")
#: flight keys handled here; every other key of a flight goes to the ingestion options
FLIGHT_OWN_KEYS = ("name", "triad", "initial", "truth", "lines", "tie")
OUTPUT_KEYS = ("dir", "epsg", "plots", "xyz", "geojson")
PROCESSING_KEYS = ("method", "classic_resolution_m")
TRIADS = ("platform", "strapdown")
PROCESSING_METHODS = ("inm", "classic")
_NAME_RE = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")


def expect_mapping(v: Any, path: str) -> dict:
    if v is None:
        return {}
    if not isinstance(v, dict):
        raise ConfigError(f"{path}: expected a mapping, got {type(v).__name__} {v!r:.40}")
    return v


@dataclass
class FlightConfig:
    """One flight of the survey after validation."""

    name: str
    index: int
    triad: str
    raw: dict  # the flight's mapping as written (for hashing and ingestion)
    ingest: Any  # gravsurvey.io.ingest.IngestOptions
    initial: Any | None  # gravsurvey.inm.params.InitialState or None (from GNSS)
    initial_raw: dict | None
    truth: Path | None
    lines_windows: list | None
    tie: Any = None  # gravsurvey.ties.TieConfig or None (no base tie)


@dataclass
class SurveyConfig:
    """The whole validated configuration."""

    path: Path
    base_dir: Path
    raw: dict
    name: str
    ellipsoid: Any
    flights: list[FlightConfig]
    model: Any  # InmParams
    lines: Any  # SegmentationOptions
    postprocess: Any  # wavelet options
    processing_method: str = "inm"
    classic_resolution_m: float | None = None
    output_dir: Path = Path("out")
    epsg: int | None = None
    plots: bool = True
    xyz: bool = True
    geojson: bool = True
    extra: dict = field(default_factory=dict)
    levelling: Any = None  # gravsurvey.levelling.LevellingOptions
    grid: Any = None  # gravsurvey.grid.GridOptions

    def section_hash(self, flight: FlightConfig) -> str:
        """Hash of everything that determines one flight's result (for rerun skipping)."""
        h = hashlib.sha256()
        sections = {k: self.raw.get(k) for k in ("ellipsoid", "model", "lines", "postprocess", "processing")}
        h.update(json.dumps(sections, sort_keys=True, default=str).encode())
        h.update(json.dumps(flight.raw, sort_keys=True, default=str).encode())
        return h.hexdigest()


class _Loader(yaml.SafeLoader):
    """SafeLoader that also reads ``1e-5`` and ``5E+3`` as floats (YAML 1.2 style).

    PyYAML follows YAML 1.1, where a float needs a dot (``1.0e-5``); geophysicists write
    ``1e-5`` and would otherwise get a string and a confusing type error.
    """


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(
        r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
        |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
        |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
        |[-+]?\.(?:inf|Inf|INF)
        |\.(?:nan|NaN|NAN))$""",
        re.X,
    ),
    list("-+0123456789."),
)


def load_yaml(path: Path) -> dict:
    """Read a YAML mapping safely; errors name the file and line."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{path}: config file not found")
    try:
        with open(path, "rb") as fh:
            data = yaml.load(fh, Loader=_Loader)  # noqa: S506 - a SafeLoader subclass
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark
        where = f"line {mark.line + 1}, column {mark.column + 1}" if mark else "?"
        raise ConfigError(f"{path}: invalid YAML at {where}: {exc.problem}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: invalid YAML: {str(exc).splitlines()[0]}") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not a text (UTF-8) YAML file") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a YAML mapping at the top level, got {type(data).__name__}")
    return data


def _resolve(base: Path, p: Any, key: str) -> Path:
    if not isinstance(p, str) or not p:
        raise ConfigError(f"{key}: expected a path string, got {p!r}")
    q = Path(p).expanduser()
    return q if q.is_absolute() else (base / q)


def load_config(path, *, output_dir: str | Path | None = None) -> SurveyConfig:
    """Load and validate a processing config.

    Parameters
    ----------
    path : path-like
        The YAML file.
    output_dir : path-like, optional
        Overrides ``output.dir``.

    Raises
    ------
    ConfigError
        Naming the key path and what was expected.
    """
    from .geodesy import get_ellipsoid
    from .inm.params import InmParams, initial_state_from_dict
    from .io.ingest import ingest_options_from_dict
    from .survey import SegmentationOptions
    from .wavelet import options_from_dict as postprocess_options_from_dict

    path = Path(path).resolve()
    raw = load_yaml(path)
    base = path.parent
    check_keys(raw, TOP_KEYS, "")

    survey = expect_mapping(raw.get("survey"), "survey")
    check_keys(survey, SURVEY_KEYS, "survey")
    name = survey.get("name", path.stem)
    if not isinstance(name, str) or not name.strip():
        raise ConfigError(f"survey.name: expected a non-empty string, got {name!r}")

    ell_name = raw.get("ellipsoid", "WGS84")
    try:
        ellipsoid = get_ellipsoid(str(ell_name))
    except ValueError:
        raise ConfigError(f"ellipsoid: expected one of WGS84, GRS80, got {ell_name!r}") from None

    model = InmParams.from_dict(expect_mapping(raw.get("model"), "model"), key_path="model")
    lines = SegmentationOptions.from_dict(expect_mapping(raw.get("lines"), "lines"), key_path="lines")
    post = postprocess_options_from_dict(
        expect_mapping(raw.get("postprocess"), "postprocess"), key_path="postprocess"
    )

    proc = expect_mapping(raw.get("processing"), "processing")
    check_keys(proc, PROCESSING_KEYS, "processing")
    method = proc.get("method", "inm")
    if method not in PROCESSING_METHODS:
        raise ConfigError(
            f"processing.method: expected one of {', '.join(PROCESSING_METHODS)}, got {method!r}"
        )
    classic_res = proc.get("classic_resolution_m")
    if classic_res is not None and (not isinstance(classic_res, (int, float)) or classic_res <= 0):
        raise ConfigError(f"processing.classic_resolution_m: expected a positive number (m), got {classic_res!r}")

    out = expect_mapping(raw.get("output"), "output")
    check_keys(out, OUTPUT_KEYS, "output")
    out_dir = Path(output_dir) if output_dir is not None else _resolve(base, out.get("dir", "out"), "output.dir")
    epsg = out.get("epsg")
    if epsg is not None and (not isinstance(epsg, int) or isinstance(epsg, bool) or epsg <= 0):
        raise ConfigError(f"output.epsg: expected a positive integer EPSG code, got {epsg!r}")
    flags = {}
    for k in ("plots", "xyz", "geojson"):
        v = out.get(k, True)
        if not isinstance(v, bool):
            raise ConfigError(f"output.{k}: expected true or false, got {v!r}")
        flags[k] = v

    flights_raw = raw.get("flights")
    if not isinstance(flights_raw, list) or not flights_raw:
        raise ConfigError("flights: expected a non-empty list of flights")
    flights: list[FlightConfig] = []
    seen = set()
    for i, fr in enumerate(flights_raw):
        kp = f"flights[{i}]"
        fr = expect_mapping(fr, kp)
        check_keys(fr, FLIGHT_OWN_KEYS + FLIGHT_INGEST_KEYS, kp)
        fname = fr.get("name", f"F{i + 1:02d}")
        if not isinstance(fname, str) or not _NAME_RE.match(fname):
            raise ConfigError(f"{kp}.name: expected 1-64 characters of A-Z a-z 0-9 _ . -, got {fname!r}")
        if fname in seen:
            raise ConfigError(f"{kp}.name: flight name {fname!r} is used twice")
        seen.add(fname)
        triad = fr.get("triad", "platform")
        if triad not in TRIADS:
            raise ConfigError(f"{kp}.triad: expected one of {', '.join(TRIADS)}, got {triad!r}")
        ingest = ingest_options_from_dict(
            {k: v for k, v in fr.items() if k in FLIGHT_INGEST_KEYS}, key_path=kp, base_dir=base
        )
        init_raw = fr.get("initial")
        initial = None
        if init_raw is not None:
            initial = initial_state_from_dict(expect_mapping(init_raw, f"{kp}.initial"), triad, f"{kp}.initial")
        elif triad == "strapdown":
            raise ConfigError(
                f"{kp}.initial: a strapdown flight needs initial.attitude_deg (roll, pitch, heading) "
                "and position/velocity; none given"
            )
        truth = _resolve(base, fr["truth"], f"{kp}.truth") if fr.get("truth") is not None else None
        windows = None
        if fr.get("lines") is not None:
            windows = fr["lines"]
            if not isinstance(windows, list):
                raise ConfigError(f"{kp}.lines: expected a list of {{name, start_s, stop_s}} windows")
        tie = None
        if fr.get("tie") is not None:
            from .ties import TieConfig

            tie = TieConfig.from_dict(fr["tie"], key_path=f"{kp}.tie")
        flights.append(
            FlightConfig(fname, i, triad, fr, ingest, initial, init_raw, truth, windows, tie)
        )

    from .grid import GridOptions
    from .levelling import LevellingOptions

    levelling = LevellingOptions.from_dict(expect_mapping(raw.get("levelling"), "levelling"), key_path="levelling")
    grid = GridOptions.from_dict(expect_mapping(raw.get("grid"), "grid"), key_path="grid")
    return SurveyConfig(
        path=path,
        base_dir=base,
        raw=raw,
        name=name,
        ellipsoid=ellipsoid,
        flights=flights,
        model=model,
        lines=lines,
        postprocess=post,
        processing_method=method,
        classic_resolution_m=classic_res,
        output_dir=out_dir,
        epsg=epsg,
        plots=flags["plots"],
        xyz=flags["xyz"],
        geojson=flags["geojson"],
        levelling=levelling,
        grid=grid,
    )
