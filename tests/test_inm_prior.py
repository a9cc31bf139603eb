"""The anomaly prior and other filter settings passed from a SIM file to survey.yaml (and oracle.yaml)."""

import copy

import pytest
import yaml

from gravsurvey.config import load_config
from gravsurvey.errors import ConfigError
from gravsurvey.simulate.run import quick_sim, simulate_to_dir

NOISE = {
    "accelerometer": {"white_sigma_mps2": 1.0e-3},
    "gravimeter": {"markov_sigma_mps2": 1.0e-6},
    "gyro": {"white_drift_degph": 0.01},
    "altimeter": {"sigma_m": 0.05},
    "gnss": {"horizontal_sigma_m": 0.5, "vertical_sigma_m": 1.0},
}


def _sim(tmp_path, processing=None):
    sim = quick_sim(duration_s=60, noise=copy.deepcopy(NOISE), field="seed_smooth")
    if processing is not None:
        sim["processing"] = processing
    p = tmp_path / "SIM.yaml"
    p.write_text(yaml.safe_dump(sim))
    return p


def test_processing_model_overrides_survey_model(tmp_path):
    over = {"anomaly_sigma_mps2": 1.0e-4, "anomaly_lambda_per_m": 2.0e-4, "gnss_aiding": False}
    simulate_to_dir(_sim(tmp_path, {"model": over}), tmp_path / "out", oracle=True)
    cfg = load_config(tmp_path / "out" / "survey.yaml")
    assert cfg.model.anomaly_sigma_mps2 == 1.0e-4
    assert cfg.model.anomaly_lambda_per_m == 2.0e-4
    assert cfg.model.gnss_aiding is False
    # survey.yaml holds what the SIM author says a user knows, nothing matched to the truth:
    # the estimator's defaults stand for the simulated GNSS and altimeter noise
    assert cfg.model.gnss_horizontal_sigma_m == 1.0 and cfg.model.altimeter_sigma_m == 1.0
    # the matched values (and the overrides) are in oracle.yaml
    oracle = load_config(tmp_path / "out" / "oracle.yaml")
    assert oracle.model.gnss_horizontal_sigma_m == 0.5 and oracle.model.gnss_vertical_sigma_m == 1.0
    assert oracle.model.altimeter_sigma_m == 0.05
    assert oracle.model.anomaly_sigma_mps2 == 1.0e-4 and oracle.model.gnss_aiding is False


def test_processing_model_without_override_and_bad_values(tmp_path):
    simulate_to_dir(_sim(tmp_path), tmp_path / "a")
    cfg = load_config(tmp_path / "a" / "survey.yaml")
    assert cfg.model.anomaly_sigma_mps2 == 1.0e-3 and cfg.model.gnss_aiding is True
    with pytest.raises(ConfigError, match="processing.model: expected a mapping"):
        simulate_to_dir(_sim(tmp_path, {"model": [1, 2]}), tmp_path / "b")
    with pytest.raises(ConfigError, match=r"processing.model.anomaly_sigma_mps2: expected a scalar"):
        simulate_to_dir(_sim(tmp_path, {"model": {"anomaly_sigma_mps2": [1.0]}}), tmp_path / "c")
    # a misspelt key reaches survey.yaml and is rejected, by name, when the survey is loaded
    simulate_to_dir(_sim(tmp_path, {"model": {"anomaly_sigma": 1.0e-4}}), tmp_path / "d")
    with pytest.raises(ConfigError, match="model.anomaly_sigma: unknown key"):
        load_config(tmp_path / "d" / "survey.yaml")
