"""The gallery's scripts (examples/, docs/examples.md) run as a user runs them and their
figures hold what the page says: a product that follows the truth, a sigma of the error's size."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _example(name):
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _is_png(path: Path) -> bool:
    return path.is_file() and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.stat().st_size > 10_000


def test_one_flight_step_by_step_follows_the_truth_with_a_sigma_of_its_error(tmp_path, capsys):
    """The sample's strapdown flight, stage by stage: 1.2 mGal RMS against truth (measured
    2026-12-06), its median stated sigma within a factor 2 of it, the field resolved to 3-7 km."""
    facts = _example("one_flight_step_by_step").main([str(tmp_path / "one.png")])
    assert _is_png(tmp_path / "one.png")
    assert facts["rms_vs_truth_mgal"] < 1.6
    assert 0.5 < facts["median_sigma_mgal"] / facts["rms_vs_truth_mgal"] < 2.0
    assert 3.0 < facts["resolution_km"] < 7.0
    assert "rms_vs_truth_mgal" in capsys.readouterr().out


@pytest.mark.parametrize("seed", [2017])
def test_an_unseen_flight_is_drawn_processed_and_scored(tmp_path, capsys, seed):
    """A drawn strapdown flight over a 61-mGal field (seed 2017, cut to 40 min): the product on
    its four lines within 5 % of the field's spread of the truth (0.70 mGal on 20.8, measured
    2026-12-06), error/sigma in [0.5, 2]; the draw and the figure reported."""
    facts = _example("an_unseen_flight").main([str(seed), str(tmp_path / "unseen.png")])
    assert _is_png(tmp_path / "unseen.png")
    assert facts["lines"] == 4
    assert facts["rms_vs_truth_mgal"] < 0.05 * facts["field_std_mgal"]
    assert 0.5 < facts["error_over_sigma_rms"] < 2.0
    assert 0.5 < facts["resolution_km"] < 5.0
    assert capsys.readouterr().out.startswith(f"U{seed} strapdown")


def test_survey_from_profiles_levels_and_grids_as_the_run_does(tmp_path, capsys):
    """The sample survey's survey stage called on its profiles.csv gives what the run's own
    summary.json says (measured 2026-12-06: 17 crossovers, RMS 2.43 -> 1.02 mGal with a constant
    per line, grid cross-validated RMS 1.37 mGal), and levelling brings the lines no farther
    from the truth."""
    facts = _example("survey_from_profiles").main([str(tmp_path / "survey.png")])
    assert _is_png(tmp_path / "survey.png")
    assert facts["crossovers"] == 17
    assert facts["crossover_rms_mgal"] == pytest.approx(2.43, abs=0.3)
    assert facts["levelling_model"] == "constant"
    assert facts["levelled_crossover_rms_mgal"] < 0.6 * facts["crossover_rms_mgal"]
    assert facts["levelled_rms_vs_truth_mgal"] <= facts["rms_vs_truth_mgal"] + 0.05
    assert facts["grid_cv_rms_mgal"] < 2.0
    assert "levelling_model" in capsys.readouterr().out
