"""benchmarks/bench_drift_lines.py: what a flight's lines can tell of the drift, without noise."""

import importlib.util
import math
from pathlib import Path

import numpy as np
from test_drift import MGAL, field_at, markov, survey


def _bench():
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_drift_lines.py"
    spec = importlib.util.spec_from_file_location("bench_drift_lines", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    return bench


def _truth(lines, spacing_m, seed=2, length_m=60000.0):
    """A truth dict (as read_truth_csv gives it) of a back-and-forth survey and a drawn drift."""
    t, lat, lon, e, n, lab = survey(lines=lines, spacing_m=spacing_m, length_m=length_m)
    truth = {
        "time_ns": (1.7e18 + t * 1e9).astype(np.int64),
        "lat_deg": np.degrees(lat),
        "lon_deg": np.degrees(lon),
        "line": np.where(lab == "", "turn", lab).astype(object),
        "disturbance_mgal": field_at(e, n) / MGAL,
    }
    drift = markov(t.size, 1.0, 1500.0, 2.0 * MGAL, np.random.default_rng(seed))
    return truth, drift


def test_lines_close_together_take_most_of_the_drift_off():
    bench = _bench()
    truth, drift = _truth(lines=6, spacing_m=2000.0)
    out = bench.drift_information(truth, drift, 2.0 * MGAL, 1500.0)
    assert out["lines"] == 6
    assert out["true"]["drift_sigma_mgal"] == 2.0 and out["true"]["drift_tau_s"] == 1500.0
    assert out["left_none"] > 1.0
    # neighbouring lines share the field and not the drift: both models take most of it off
    assert out["left_true"] < 0.3 * out["left_none"], out
    assert out["left_fitted"] < 0.3 * out["left_none"], out
    assert math.isfinite(out["ll_fitted_minus_true"])


def test_one_line_is_no_test_of_the_drift():
    bench = _bench()
    truth, drift = _truth(lines=1, spacing_m=2000.0, length_m=150000.0)
    assert bench.drift_information(truth, drift, 2.0 * MGAL, 1500.0) is None
