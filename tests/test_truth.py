"""``flights[i].truth``: a simulator truth.csv path, or any CSV with its columns named (issue 14
item 9), checked before processing (validate and run share the check) and read the same way."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from gravsurvey.config import load_config
from gravsurvey.errors import ConfigError, DataError
from gravsurvey.truth import TruthSpec, read_truth_csv

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_data" / "markov_csv"


def _config(tmp_path, truth) -> Path:
    cfg = yaml.safe_load((SAMPLE / "survey.yaml").read_text())
    f = cfg["flights"][0]
    f["inputs"]["csv"] = {k: str(SAMPLE / v) for k, v in f["inputs"]["csv"].items()}
    f["truth"] = truth
    p = tmp_path / "survey.yaml"
    p.write_text(yaml.safe_dump(cfg))
    return p


@pytest.fixture
def reference(tmp_path):
    """The sample's truth rewritten as another program would: other names, Unix seconds, ';'."""
    t = read_truth_csv(SAMPLE / "F01" / "truth.csv")
    p = tmp_path / "ref.csv"
    with open(p, "w") as fh:
        fh.write("# reference profile\nt_unix;dg;other\n")
        for a, b in zip(t["time_ns"], t["disturbance_mgal"]):
            fh.write(f"{a / 1e9:.3f};{b:.4f};x\n")
    return p, t


def test_mapped_columns_read_like_the_simulator_truth(tmp_path, reference):
    p, t = reference
    truth = {
        "file": str(p),
        "columns": {"time": "t_unix", "disturbance_mgal": "dg"},
        "time_format": "s",
        "delimiter": ";",
    }
    fl = load_config(_config(tmp_path, truth)).flights[0]
    assert fl.truth == p
    got = read_truth_csv(fl.truth_spec)
    np.testing.assert_array_equal(got["time_ns"], t["time_ns"])  # ms-exact times survive the seconds
    np.testing.assert_allclose(got["disturbance_mgal"], t["disturbance_mgal"], atol=5e-5)


def test_a_plain_path_is_the_simulator_layout(tmp_path):
    fl = load_config(_config(tmp_path, str(SAMPLE / "F01" / "truth.csv"))).flights[0]
    assert fl.truth_spec == TruthSpec(SAMPLE / "F01" / "truth.csv")


@pytest.mark.parametrize(
    "truth, message",
    [
        ({"columns": {"time": "t_unix"}}, r"^flights\[0\]\.truth\.file: missing required key"),
        (
            {"file": "REF", "columns": {"disturbance": "dg"}},
            r"^flights\[0\]\.truth\.columns\.disturbance: unknown key \(did you mean 'disturbance_mgal'\?\)",
        ),
        ({"file": "REF", "time_format": "iso"}, r"^flights\[0\]\.truth\.time_format: expected one of ns, s"),
        (
            {"file": "REF", "columns": {"time": "t_unix", "disturbance_mgal": "dgx"}, "delimiter": ";"},
            r"^flights\[0\]\.truth: .*ref\.csv: truth file lacks column\(s\) dgx; header has t_unix, dg, other$",
        ),
        (
            "REF",
            r"^flights\[0\]\.truth: .*ref\.csv: truth file lacks column\(s\) time_ns, disturbance_mgal; .*"
            r"other names: flights\[0\]\.truth: \{file: \.\.\., columns:",
        ),
        (3, r"^flights\[0\]\.truth: expected a string"),
    ],
)
def test_truth_mistakes_are_config_errors_before_processing(tmp_path, reference, truth, message):
    p, _ = reference
    if isinstance(truth, dict) and truth.get("file") == "REF":
        truth = dict(truth, file=str(p))
    elif truth == "REF":
        truth = str(p)
    with pytest.raises(ConfigError, match=message):
        load_config(_config(tmp_path, truth))


def test_a_damaged_value_names_the_file_row_and_column(tmp_path):
    p = tmp_path / "ref.csv"
    p.write_text("time_ns,disturbance_mgal\n1000000000,1.0\n2000000000,abc\n")
    with pytest.raises(DataError, match=r"ref\.csv: column 'disturbance_mgal' row 3: expected a number, got 'abc'"):
        read_truth_csv(p)
