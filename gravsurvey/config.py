"""Processing configuration: YAML -> validated settings.

The YAML is loaded safely (``yaml.safe_load``: no object construction from tags).
Every key, its type, unit, default and meaning is declared once, in the schema
(:mod:`gravsurvey.settings`, from which docs/config.md's reference is generated); paths are
relative to the config file.  This module reads the YAML safely, validates it against the schema,
builds the typed settings each stage takes, and makes the :func:`preflight_checks` that need
files or PROJ, so ``validate`` and ``run`` refuse the same configs.
"""

from __future__ import annotations

import hashlib
import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from .errors import ConfigError
from .truth import check_truth_header


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
    #: the ``initial`` keys given (all optional overrides of the data; inm.params.resolve_initial_state)
    initial_given: dict | None = None
    tie: Any = None  # gravsurvey.ties.TieConfig or None (no base tie)
    #: how to read ``truth`` (gravsurvey.truth.TruthSpec; columns, time format), None without truth
    truth_spec: Any = None


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
    normal_gravity: str = "exact"  # classic: "exact" (the ellipsoid's field) or a closed-form formula
    gradiometer: bool = False  # processing.gradiometer: seed-000 products of a gradient channel
    output_dir: Path = Path("out")
    epsg: int | None = None
    plots: bool = True
    xyz: bool = True
    geojson: bool = True
    extra: dict = field(default_factory=dict)
    checks: Any = None  # gravsurvey.consistency.CheckOptions (section ``checks``)
    levelling: Any = None  # gravsurvey.levelling.LevellingOptions
    grid: Any = None  # gravsurvey.grid.GridOptions
    drift: Any = None  # gravsurvey.drift.DriftOptions (section ``drift``)

    def section_hash(self, flight: FlightConfig) -> str:
        """Hash of everything that determines one flight's result (for rerun skipping)."""
        h = hashlib.sha256()
        sections = {
            k: self.raw.get(k) for k in ("ellipsoid", "model", "lines", "postprocess", "processing", "checks", "drift")
        }
        h.update(json.dumps(sections, sort_keys=True, default=str).encode())
        h.update(json.dumps(flight.raw, sort_keys=True, default=str).encode())
        return h.hexdigest()


#: a processing config is a few kB (one block per flight); larger files are refused unread
MAX_CONFIG_BYTES = 2 * 1024 * 1024
#: YAML nodes after expanding aliases: a 1 kB "billion laughs" file expands to ~1e9 nodes and
#: would take GB of memory and minutes downstream (hashing, JSON); a real config has < 1e4
MAX_CONFIG_NODES = 200_000
#: flow-collection nesting ([ and {): PyYAML's scanner is quadratic in it (100k levels: ~2 s
#: before the parser's recursion limit); a real config nests < 5 levels
MAX_CONFIG_FLOW_DEPTH = 64


class _Loader(yaml.SafeLoader):
    """SafeLoader that also reads ``1e-5`` and ``5E+3`` as floats (YAML 1.2 style), and refuses
    a key given twice in one mapping (PyYAML would silently keep the last one).

    PyYAML follows YAML 1.1, where a float needs a dot (``1.0e-5``); geophysicists write
    ``1e-5`` and would otherwise get a string and a confusing type error.
    """

    def construct_mapping(self, node, deep=False):
        if isinstance(node, yaml.MappingNode):
            seen = {}
            for key_node, _ in node.value:
                if isinstance(key_node, yaml.ScalarNode):
                    k = key_node.value
                    if k in seen:
                        raise yaml.constructor.ConstructorError(
                            None, None, f"key {k!r} given twice (first on line {seen[k] + 1})", key_node.start_mark
                        )
                    seen[k] = key_node.start_mark.line
        return super().construct_mapping(node, deep=deep)


def _expanded_nodes(node, limit: int) -> int:
    """Number of YAML nodes with every alias expanded, counted without expanding (memoised per
    node, so a bomb costs time linear in its size); stops counting once above ``limit``.
    A recursive alias (a collection containing itself) counts as more than ``limit``."""
    memo: dict[int, int] = {}
    active: set[int] = set()

    def count(n) -> int:
        key = id(n)
        if key in active:  # an alias inside its own anchor: infinite once expanded
            return limit + 1
        if key in memo:
            return memo[key]
        active.add(key)
        total = 1
        if isinstance(n, yaml.SequenceNode):
            for child in n.value:
                total += count(child)
                if total > limit:
                    break
        elif isinstance(n, yaml.MappingNode):
            for kn, vn in n.value:
                total += count(kn) + count(vn)
                if total > limit:
                    break
        active.discard(key)
        memo[key] = total
        return total

    return count(node)


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
    """Read a YAML mapping safely; errors name the file and line.

    Refused before any object is built: files over :data:`MAX_CONFIG_BYTES`, documents whose
    alias expansion exceeds :data:`MAX_CONFIG_NODES` nodes (alias bombs), a key given twice.
    A UTF-8 byte-order mark is accepted.
    """
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{path}: config file not found")
    try:
        size = path.stat().st_size
        if size > MAX_CONFIG_BYTES:
            raise ConfigError(
                f"{path}: {size} bytes; a config may have at most {MAX_CONFIG_BYTES} bytes (is this the right file?)"
            )
        with open(path, "rb") as fh:
            raw_bytes = fh.read(MAX_CONFIG_BYTES + 1)
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the config: {exc.strerror}") from None
    try:
        text = raw_bytes.decode("utf-8-sig")  # a BOM (Windows editors) is not content
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not a text (UTF-8) YAML file") from None
    b = np.frombuffer(raw_bytes, dtype=np.uint8)
    if b.size:
        # bracket depth, counting brackets inside quotes and comments too: an upper bound
        step = np.isin(b, (0x5B, 0x7B)).astype(np.int64) - np.isin(b, (0x5D, 0x7D))
        if int(np.cumsum(step).max()) > MAX_CONFIG_FLOW_DEPTH:
            raise ConfigError(f"{path}: YAML nested more than {MAX_CONFIG_FLOW_DEPTH} levels deep; refused")
    try:
        loader = _Loader(text)
        try:
            node = loader.get_single_node()
            if node is not None and _expanded_nodes(node, MAX_CONFIG_NODES) > MAX_CONFIG_NODES:
                raise ConfigError(
                    f"{path}: more than {MAX_CONFIG_NODES} YAML nodes once aliases "
                    "are expanded (an alias bomb or a recursive alias?); refused"
                )
            data = loader.construct_document(node) if node is not None else None
        finally:
            loader.dispose()
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark
        where = f"line {mark.line + 1}, column {mark.column + 1}" if mark else "?"
        raise ConfigError(f"{path}: invalid YAML at {where}: {exc.problem}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: invalid YAML: {str(exc).splitlines()[0]}") from None
    except RecursionError:
        raise ConfigError(f"{path}: YAML nested too deeply; refused") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a YAML mapping at the top level, got {type(data).__name__}")
    return data


def _resolve(base: Path, p: str) -> Path:
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
    from . import settings as S
    from .geodesy import get_ellipsoid

    path = Path(path).resolve()
    raw = load_yaml(path)
    base = path.parent
    doc = S.parse_survey(raw)
    flights: list[FlightConfig] = []
    for i, (fr, fs) in enumerate(zip(raw["flights"], doc.flights)):
        kp = f"flights[{i}]"
        initial, given = None, None
        if fs.initial is not None:
            given = S.initial_overrides(fs.initial, f"{kp}.initial")
            complete = {"lat_deg", "lon_deg", "height_m", "velocity_enu_mps"}
            if fs.triad == "strapdown":
                complete.add("attitude_deg")
            if complete <= set(given):
                initial = S.initial_state(fs.initial, fs.triad, f"{kp}.initial")
        flights.append(
            FlightConfig(
                name=fs.name or f"F{i + 1:02d}",
                index=i,
                triad=fs.triad,
                raw=fr,
                ingest=S.ingest_options(fs, key_path=kp, base_dir=base),
                initial=initial,
                initial_raw=fr.get("initial"),
                truth=_resolve(base, _truth_file(fs.truth)) if fs.truth is not None else None,
                truth_spec=_truth_spec(base, fs.truth),
                lines_windows=[w.model_dump(exclude_none=True) for w in fs.lines] if fs.lines is not None else None,
                initial_given=given,
                tie=S.tie_config(fs.tie, f"{kp}.tie") if fs.tie is not None else None,
            )
        )
    out = doc.output
    cfg = SurveyConfig(
        path=path,
        base_dir=base,
        raw=raw,
        name=doc.survey.name if doc.survey.name is not None else path.stem,
        ellipsoid=get_ellipsoid(doc.ellipsoid),
        flights=flights,
        model=S.inm_params(doc.model),
        lines=S.segmentation_options(doc.lines),
        postprocess=S.postprocess_options(doc.postprocess),
        processing_method=doc.processing.method,
        classic_resolution_m=doc.processing.classic_resolution_m,
        normal_gravity=doc.processing.normal_gravity,
        gradiometer=doc.processing.gradiometer,
        output_dir=Path(output_dir) if output_dir is not None else _resolve(base, out.dir),
        epsg=out.epsg,
        plots=out.plots,
        xyz=out.xyz,
        geojson=out.geojson,
        checks=S.check_options(doc.checks),
        levelling=S.levelling_options(doc.levelling),
        grid=S.grid_options(doc.grid),
        drift=S.drift_options(doc.drift),
    )
    preflight_checks(cfg)
    return cfg


def _truth_file(t):
    return t if isinstance(t, str) else t.file


def _truth_spec(base, t):
    """``flights[i].truth`` (a path, or ``{file, columns, time_format, delimiter}``) as a
    :class:`gravsurvey.truth.TruthSpec`."""
    from .truth import TruthSpec

    if t is None:
        return None
    if isinstance(t, str):
        return TruthSpec(_resolve(base, t))
    return TruthSpec(
        _resolve(base, t.file),
        {"time": t.columns.time, "disturbance_mgal": t.columns.disturbance_mgal},
        t.time_format,
        t.delimiter,
    )


def preflight_checks(cfg: SurveyConfig) -> None:
    """Checks ``run`` would otherwise make only after processing, made before it (and by
    ``validate``): every one raises :class:`ConfigError` (exit 2) naming the key path.

    - ``output.epsg``: known to PROJ and projected (metre coordinates), via the same
      :func:`gravsurvey.georef.project` the writers use;
    - ``flights[i].truth``: an existing text CSV whose header has the configured columns
      (only the header is read);

    Everything that needs no file or PROJ (types, ranges, unknown keys, cross-field rules such as
    a low-pass post-processor's length or unique window names) is the schema's
    (:mod:`gravsurvey.settings`), checked before these.
    """
    if cfg.epsg is not None:
        from .georef import project

        project(np.zeros(1), np.zeros(1), cfg.epsg, key="output.epsg")
    for fl in cfg.flights:
        if fl.truth is not None:
            check_truth_header(fl.truth_spec or fl.truth, f"flights[{fl.index}].truth")
