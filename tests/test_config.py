"""Config validation: every key documented, errors name the key path, paths relative to the file."""

import re
from pathlib import Path

import pytest

from gravsurvey import config as C
from gravsurvey.errors import ConfigError
from gravsurvey import settings as S

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_data" / "seed_line" / "survey.yaml"


def _documented():
    return set(re.findall(r"^\| `([\w.]+)` \|", (ROOT / "docs" / "config.md").read_text(), re.M))


def _schema_keys(model, prefix=""):
    """Every key path of a schema section, nested sections included (``flights[i]`` -> ``flights.``)."""
    out = set()
    for name, field in model.model_fields.items():
        out.add(prefix + name)
        for sub in (field.annotation, *getattr(field.annotation, "__args__", ())):
            inner = getattr(sub, "__args__", ())
            for cand in (sub, *inner):
                if isinstance(cand, type) and issubclass(cand, S.Section):
                    out |= _schema_keys(cand, prefix + name + ".")
    return out


def test_every_key_is_documented():
    doc = _documented()
    keys = {k.split(".")[-1] for k in _schema_keys(S.SurveyFile)}
    documented_leaves = {d.split(".")[-1] for d in doc}
    missing = sorted(k for k in keys if k not in documented_leaves)
    assert not missing, f"undocumented config keys: {missing}"
    # and the top-level sections by their full name
    assert set(S.SurveyFile.model_fields) <= doc


def test_generated_reference_matches_the_schema():
    """docs/config.md's reference section is exactly what the schema generates
    (`python -m gravsurvey.settings --doc` rewrites it)."""
    text = (ROOT / "docs" / "config.md").read_text()
    assert S.GENERATED_BEGIN in text and S.GENERATED_END in text
    assert S.splice_reference(text) == text, "docs/config.md is out of date: python -m gravsurvey.settings --doc"
    # the check can fail: a changed description is noticed
    S.ModelSection.model_fields["filter_rate_hz"].description += " (changed)"
    try:
        assert S.splice_reference(text) != text
    finally:
        S.ModelSection.model_fields["filter_rate_hz"].description = S.ModelSection.model_fields[
            "filter_rate_hz"
        ].description[: -len(" (changed)")]


def _sample_with(tmp_path, old, new):
    text = SAMPLE.read_text().replace("F01/", str(SAMPLE.parent / "F01") + "/")
    assert old in text
    p = tmp_path / "c.yaml"
    p.write_text(text.replace(old, new))
    return p


def test_sample_config_loads_with_paths_relative_to_file():
    cfg = C.load_config(SAMPLE)
    fl = cfg.flights[0]
    assert fl.truth == SAMPLE.parent / "F01" / "truth.csv"
    assert all(Path(p).is_file() for p in fl.ingest.input_paths())
    assert cfg.output_dir == SAMPLE.parent / "out"


@pytest.mark.parametrize(
    "old,new,match",
    [
        ("lines: {mode: whole}", "line: {mode: whole}", r"^line: unknown key \(did you mean 'lines'\?\)"),
        ("triad: platform", "triad: gimbal", r"flights\[0\]\.triad: expected one of platform, strapdown"),
        ("triad: platform", "triad: platform\n  colour: red", r"flights\[0\]\.colour: unknown key"),
        ("output: {dir: out}", "output: {dir: out, epsg: -3}", r"^output\.epsg: expected an integer > 0, got -3$"),
        ("output: {dir: out}", "output: {dirr: out}", r"output\.dirr: unknown key \(did you mean 'dir'\?\)"),
        ("ellipsoid: WGS84", "ellipsoid: Krassowsky", r"ellipsoid: expected one of WGS84, GRS80"),
        ("lines: {mode: whole}", "model: {altimeter_sigma_m: -1}\nlines: {mode: whole}", r"model\.altimeter_sigma_m"),
        ("postprocess: {method: default}", "postprocess: {method: median}", r"postprocess\.method"),
        ("lines: {mode: whole}", "lines: {mode: diagonal}", r"lines\.mode"),
        ("name: F01", "name: 'F 01/x'", r"flights\[0\]\.name"),
    ],
)
def test_errors_name_the_key(tmp_path, old, new, match):
    p = _sample_with(tmp_path, old, new)
    with pytest.raises(ConfigError, match=match):
        C.load_config(p)


def test_strapdown_without_initial_attitude(tmp_path):
    text = SAMPLE.read_text()
    assert "initial:" not in text  # the sample is a platform flight initialised from GNSS
    p = tmp_path / "c.yaml"
    p.write_text(
        text.replace("triad: platform", "triad: strapdown").replace(
            "truth: F01/truth.csv", f"truth: {SAMPLE.parent / 'F01' / 'truth.csv'}"
        )
    )
    # issue 13: no initial block needed; position/velocity from GNSS, attitude from the alignment
    fl = C.load_config(p).flights[0]
    assert fl.triad == "strapdown" and fl.initial is None and fl.initial_given is None


def test_yaml_12_floats_and_bad_yaml(tmp_path):
    p = _sample_with(tmp_path, "lines: {mode: whole}", "model: {altimeter_sigma_m: 5e-2}\nlines: {mode: whole}")
    assert C.load_config(p).model.altimeter_sigma_m == 0.05
    bad = tmp_path / "bad.yaml"
    bad.write_text("survey: {name: x\nflights: [\n")
    with pytest.raises(ConfigError, match=r"bad\.yaml: invalid YAML at line \d+"):
        C.load_config(bad)
    lst = tmp_path / "list.yaml"
    lst.write_text("- a\n- b\n")
    with pytest.raises(ConfigError, match="expected a YAML mapping"):
        C.load_config(lst)


def test_example_config_from_init_is_documented_and_valid_apart_from_inputs(tmp_path):
    from gravsurvey.templates import EXAMPLE_CONFIG

    p = tmp_path / "g.yaml"
    p.write_text(EXAMPLE_CONFIG)
    data = C.load_yaml(p)
    doc = _documented()
    for k in data["model"]:
        assert k in doc
    # validation goes as far as the inputs, which do not exist here: that is a data problem
    cfg = C.load_config(p)
    assert cfg.flights[0].name == "F01"


# ---------------------------------------------------------------- issue 14.7: one validation layer


@pytest.mark.parametrize(
    "old,new,match",
    [
        ("output: {dir: out}", "output: {dir: out, epsg: 4326}", r"^output\.epsg: EPSG:4326 .* not a projected CRS"),
        ("output: {dir: out}", "output: {dir: out, epsg: 99999}", r"^output\.epsg: unknown EPSG code 99999"),
        (
            "postprocess: {method: default}",
            "postprocess: {method: butterworth}",
            r"^postprocess\.resolution_m: required by method 'butterworth'",
        ),
        (
            "postprocess: {method: default}",
            "postprocess: {method: gaussian}",
            r"^postprocess\.resolution_m: required by method 'gaussian'",
        ),
        ("truth: ", "truth: nope/", r"^flights\[0\]\.truth: truth file not found"),
        ("truth.csv", "F01_json.mcap", r"^flights\[0\]\.truth: .* not a text CSV"),
        (
            "lines: {mode: whole}",
            "lines: {mode: windows, windows: [{name: A, start_s: 10}]}",
            r"^lines\.windows\[0\]\.stop_s: missing required key \(end, s after the flight's first sample\)$",
        ),
        (
            "  truth: ",
            "  lines: [{name: A, start_s: 500, stop_s: 10}]\n  truth: ",
            r"^flights\[0\]\.lines\[0\]: expected finite start_s < stop_s",
        ),
        ("ellipsoid: WGS84", "ellipsoid: WGS84\nellipsoid: GRS80", r"key 'ellipsoid' given twice"),
    ],
)
def test_checks_run_made_after_processing_are_made_by_load_config(tmp_path, old, new, match):
    """The config mistakes that `run` found only after processing (exit 1, or not at all for a
    duplicate key) are found when the config is loaded: `validate` and `run` alike, exit 2."""
    p = _sample_with(tmp_path, old, new)
    with pytest.raises(ConfigError, match=match):
        C.load_config(p)


def test_truth_file_without_the_required_columns(tmp_path):
    bad = tmp_path / "truth.csv"
    bad.write_text("# header comment\ntime_s,anomaly\n1,2\n")
    p = _sample_with(tmp_path, f"truth: {SAMPLE.parent}/F01/truth.csv", f"truth: {bad}")
    with pytest.raises(
        ConfigError,
        match=r"flights\[0\]\.truth: .* lacks column\(s\) time_ns, "
        r"disturbance_mgal; header has time_s, anomaly",
    ):
        C.load_config(p)


def test_valid_windows_pass_the_structure_check(tmp_path):
    p = _sample_with(
        tmp_path,
        "lines: {mode: whole}",
        "lines: {mode: windows, windows: [{name: L1, start_s: 10, stop_s: 20}, "
        "{name: T1, start_s: 15.5, stop_s: 15.6}]}",
    )
    assert C.load_config(p).lines.mode == "windows"


def _timed_refusal(path, match):
    import time

    t = time.perf_counter()
    with pytest.raises(ConfigError, match=match):
        C.load_yaml(path)
    return time.perf_counter() - t


def test_alias_bombs_deep_and_oversized_yaml_refused_fast(tmp_path):
    bomb = 'a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]\n'
    prev = "a"
    for c in "bcdefghi":  # 9^9 ~ 3.9e8 nodes once expanded, from 342 bytes
        bomb += f"{c}: &{c} [" + ",".join([f"*{prev}"] * 9) + "]\n"
        prev = c
    (tmp_path / "bomb.yaml").write_text(bomb)
    assert _timed_refusal(tmp_path / "bomb.yaml", r"more than 200000 YAML nodes") < 0.5
    (tmp_path / "self.yaml").write_text("a: &a [1, *a]\n")
    assert _timed_refusal(tmp_path / "self.yaml", r"recursive alias") < 0.5
    (tmp_path / "deep.yaml").write_text("a: " + "[" * 100_000 + "]" * 100_000 + "\n")
    assert _timed_refusal(tmp_path / "deep.yaml", r"nested more than 64 levels") < 0.5
    (tmp_path / "big.yaml").write_text("# padding\n" * 300_000)
    assert _timed_refusal(tmp_path / "big.yaml", r"at most 2097152 bytes") < 0.5
    block = "".join(" " * i + "k:\n" for i in range(1200))  # block nesting: parser recursion
    (tmp_path / "deepblock.yaml").write_text(block)
    assert _timed_refusal(tmp_path / "deepblock.yaml", r"nested too deeply") < 2.0


def test_a_small_anchor_config_still_loads(tmp_path):
    """Anchors and aliases themselves are fine (shared model blocks are common)."""
    text = SAMPLE.read_text().replace("F01/", str(SAMPLE.parent / "F01") + "/")
    text = text.replace("lines: {mode: whole}", "lines: &l {mode: whole}\n")
    p = tmp_path / "c.yaml"
    p.write_text(text)
    assert C.load_config(p).lines.mode == "whole"


def test_utf8_bom_is_accepted(tmp_path):
    text = SAMPLE.read_text().replace("F01/", str(SAMPLE.parent / "F01") + "/")
    p = tmp_path / "bom.yaml"
    p.write_bytes(b"\xef\xbb\xbf" + text.encode())
    assert C.load_config(p).name == "sample_seed_line"


# ---------------------------------------------------------------- issue 17: one schema, one error form
SECOND_FLIGHT = "- name: F02\n  inputs: {mcap: F01/F01_json.mcap}\n  truth: F01/truth.csv\nlines: {mode: whole}"


@pytest.mark.parametrize(
    "old,new,message",
    [
        (
            "lines: {mode: whole}",
            "model: {filter_rate_hz: abc}\nlines: {mode: whole}",
            "model.filter_rate_hz: expected a number >= 0.2, got 'abc'",
        ),
        (
            "lines: {mode: whole}",
            "model: {gnss_aiding: 'yes'}\nlines: {mode: whole}",
            "model.gnss_aiding: expected true or false, got 'yes'",
        ),
        (
            "lines: {mode: whole}",
            "model: {attitude_passes: 2.5}\nlines: {mode: whole}",
            "model.attitude_passes: expected an integer in [1, 5], got 2.5",
        ),
        (
            "lines: {mode: whole}",
            "model: {anomaly_sigma_mps2: .nan}\nlines: {mode: whole}",
            "model.anomaly_sigma_mps2: expected a finite number >= 0, got nan",
        ),
        ("lines: {mode: whole}", "model: [1, 2]\nlines: {mode: whole}", "model: expected a mapping, got list [1, 2]"),
        (
            "lines: {mode: whole}",
            SECOND_FLIGHT.replace("mcap: F01/F01_json.mcap", "csv: {imu: i.csv}"),
            "flights[1].inputs.csv.altimeter: missing: give the altimeter CSV file, or the GNSS file (its heights are "
            "then the height channel)",
        ),
        (
            "lines: {mode: whole}",
            SECOND_FLIGHT.replace(
                "{mcap: F01/F01_json.mcap}", "{mcap: F01/F01_json.mcap}\n  mcap: {max_record_mib: 0}"
            ),
            "flights[1].mcap.max_record_mib: expected an integer in [1, 65536], got 0",
        ),
        (
            "lines: {mode: whole}",
            SECOND_FLIGHT.replace("{mcap: F01/F01_json.mcap}", "{mcap: F01/F01_json.mcap}\n  mcap: {unit: {}}"),
            "flights[1].mcap.unit: unknown key (did you mean 'units'?); valid keys here: json_fields, units, "
            "time_source, check_crc, max_record_mib",
        ),
        (
            "lines: {mode: whole}",
            SECOND_FLIGHT.replace("name: F02", "name: F01"),
            "flights[1].name: flight name 'F01' is used twice",
        ),
        (
            "lines: {mode: whole}",
            SECOND_FLIGHT.replace("{mcap: F01/F01_json.mcap}", "{mcap: a.mcap, csv: {}}"),
            "flights[1].inputs: expected exactly one of mcap, csv, gravimeter, got mcap, csv",
        ),
        (
            "lines: {mode: whole}",
            SECOND_FLIGHT.replace(
                "truth: F01/truth.csv", "tie: {base_gravity_mgal: 9.81, before: {reading_mgal: 980000}}"
            ),
            "flights[1].tie.base_gravity_mgal: expected a number in [970000, 990000], got 9.81",
        ),
        (
            "lines: {mode: whole}",
            SECOND_FLIGHT.replace("truth: F01/truth.csv", "initial: {velocity_enu_mps: [1, 2]}"),
            "flights[1].initial.velocity_enu_mps: expected a list of 3 numbers, got [1.0, 2.0]",
        ),
        (
            "lines: {mode: whole}",
            "lines: {mode: windows, windows: [{name: A, start_s: 0, stop_s: 9}, {name: A, start_s: 10, stop_s: 20}]}",
            "lines.windows[1].name: 'A' appears twice",
        ),
        (
            "postprocess: {method: default}",
            "postprocess: {method: gausian}",
            "postprocess.method: expected one of default, ti_cosphi, cosphi, visushrink, sure, bayes, butterworth, "
            "gaussian, none, got 'gausian' (did you mean 'gaussian'?)",
        ),
        (
            "output: {dir: out}",
            "output: {dir: out}\nprocessing: {normal_gravity: IGF1967}",
            "processing.normal_gravity: IGF1967 applies to processing.method classic only (the 3D-INM uses the exact "
            "normal gravity field)",
        ),
        (
            "output: {dir: out}",
            "output: {dir: out}\nlevelling: {max_iterations: 0}",
            "levelling.max_iterations: expected an integer >= 1, got 0",
        ),
        (
            "output: {dir: out}",
            "output: {dir: out}\ngrid: {cv_folds: true}",
            "grid.cv_folds: expected an integer >= 2, got True",
        ),
        (
            "output: {dir: out}",
            "output: {dir: out}\nchecks: {max_imu_gap_s: -1}",
            "checks.max_imu_gap_s: expected a number > 0, got -1",
        ),
    ],
)
def test_schema_errors_are_one_line_with_the_full_key_path(tmp_path, old, new, message):
    p = _sample_with(tmp_path, old, new)
    with pytest.raises(ConfigError) as e:
        C.load_config(p)
    assert str(e.value) == message


def test_empty_sections_mean_the_defaults(tmp_path):
    p = _sample_with(tmp_path, "lines: {mode: whole}", "lines:\nmodel:\ngrid:\nlevelling:\nchecks:")
    cfg = C.load_config(p)
    assert cfg.lines.mode == "auto" and cfg.model == S.inm_params({}) and cfg.grid == S.grid_options({})


def test_the_typed_settings_equal_the_stage_defaults():
    """Every schema default is the stage settings class's own default (one source)."""
    from gravsurvey.consistency import CheckOptions
    from gravsurvey.grid import GridOptions
    from gravsurvey.inm.params import InmParams
    from gravsurvey.levelling import LevellingOptions
    from gravsurvey.segmentation import SegmentationOptions
    from gravsurvey.wavelet import PostprocessOptions

    assert S.inm_params({}) == InmParams()
    assert S.segmentation_options({}) == SegmentationOptions()
    assert S.postprocess_options({}) == PostprocessOptions()
    assert S.check_options({}) == CheckOptions()
    assert S.levelling_options({}) == LevellingOptions()
    assert S.grid_options({}) == GridOptions()


def test_settings_module_doc_check_command(tmp_path):
    """`python -m gravsurvey.settings --check` fails on a stale reference, `--doc` repairs it."""
    stale = tmp_path / "config.md"
    stale.write_text(f"# prose\n\n{S.GENERATED_BEGIN}\n| `old` | stale |\n{S.GENERATED_END}\n")
    assert S.main(["--check", str(stale)]) == 1
    assert S.main(["--doc", str(stale)]) == 0
    assert S.main(["--check", str(stale)]) == 0
    assert stale.read_text().startswith("# prose\n\n") and "`filter_rate_hz`" in stale.read_text()


ODD_VALUES = [None, True, -1, float("nan"), "", "x", [], [None], {}, {1: 2}, [[1, 2], [3]]]
FULL = {
    "survey": {"name": "x"},
    "ellipsoid": "WGS84",
    "flights": [
        {
            "name": "F01",
            "inputs": {"mcap": "a.mcap"},
            "topics": {"imu": "/imu"},
            "triad": "strapdown",
            "imu_axes": "FRD",
            "gnss_lever_arm_m": [0, 0, 1],
            "lines": [{"name": "L1", "start_s": 0, "stop_s": 10}],
            "initial": {"lat_deg": 1.0, "velocity_enu_mps": [1, 2, 3]},
            "tie": {"base_gravity_mgal": 980000, "before": {"start_s": 0, "stop_s": 5}},
            "csv": {"columns": {"imu": {"time": "t"}}, "units": {"gyro": "deg/s"}},
            "mcap": {"json_fields": {"imu": {"specific_force": ["a", "b", "c"]}}},
        }
    ],
    "model": {"filter_rate_hz": 1.0},
    "lines": {"mode": "auto"},
    "postprocess": {"method": "default"},
    "processing": {"method": "inm"},
    "output": {"dir": "out"},
    "checks": {"max_imu_gap_s": 2.0},
    "levelling": {"enabled": None},
    "grid": {"spacing_m": 100.0},
}


def _key_paths(d, p=()):
    items = d.items() if isinstance(d, dict) else enumerate(d) if isinstance(d, list) else ()
    for k, v in items:
        yield p + (k,)
        yield from _key_paths(v, p + (k,))


def test_any_value_anywhere_is_accepted_or_one_config_error_line():
    """Every key of a full config replaced by odd values: the schema and the builders either accept
    it or raise one ConfigError line naming a key path, never another exception (a random search
    over such replacements found a crash on `name: null` and `inputs: null`, now fixed)."""
    import copy

    S.parse_survey(FULL)
    seen_errors = 0
    for path in _key_paths(FULL):
        for value in ODD_VALUES:
            d = copy.deepcopy(FULL)
            cur = d
            for k in path[:-1]:
                cur = cur[k]
            cur[path[-1]] = value
            try:
                doc = S.parse_survey(d)
                for i, f in enumerate(doc.flights):
                    S.ingest_options(f, f"flights[{i}]")
                    if f.initial is not None:
                        S.initial_overrides(f.initial)
                    if f.tie is not None:
                        S.tie_config(f.tie)
                S.inm_params(doc.model)
                S.segmentation_options(doc.lines)
            except ConfigError as e:
                seen_errors += 1
                assert "\n" not in str(e) and re.match(r"^[\w.\[\]]+: ", str(e)), str(e)
    assert seen_errors > 300  # most replacements are wrong, and each said so
