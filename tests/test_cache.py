"""Issue 14.8: out/.cache cannot run code; it is checked against its key before any array is
read; a cached flight gives byte-identical outputs."""

from __future__ import annotations

import io
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

from gravsurvey.cache import cache_paths, load_result, save_result
from gravsurvey.estimate import FlightEstimate

ROOT = Path(__file__).resolve().parents[1]
EXE = [sys.executable, "-m", "gravsurvey"]


class Payload:
    """Unpickling this would create ``marker`` (what a planted cache file would do)."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (Path.touch, (Path(self.marker),))


def _result(n=50):
    rng = np.random.default_rng(0)
    line = np.full(n, "", dtype=object)
    line[10:40] = "L01"
    return FlightEstimate(
        name="F01",
        method="inm",
        t0_unix_ns=1_700_000_000_000_000_000,
        time=np.arange(n, dtype=float),
        lat=rng.random(n),
        lon=rng.random(n),
        height=rng.random(n),
        vel_n=rng.random((n, 3)),
        speed=rng.random(n),
        heading=rng.random(n),
        smoothed=rng.random(n),
        forward=rng.random(n),
        sigma=rng.random(n),
        disturbance=np.where(line != "", rng.random(n), np.nan),
        dg_north=rng.random(n),
        dg_east=rng.random(n),
        sigma_north=rng.random(n),
        sigma_east=rng.random(n),
        horizontal_observable=rng.random(n) > 0.3,
        line=line,
        line_segments=[{"name": "L01", "kind": "line", "start_s": 10.0, "stop_s": 39.0, "n": 30}],
        line_info={"L01": {"method": "ti_cosphi", "Phi": 0.1, "p": [1e-5, 2e-5]}},
        truth_mgal=None,
        notes=["F01: imu: dropped 1 duplicate samples"],
        timings={"ingest_s": 0.5},
        input_hashes={"a.mcap": "00ff"},
        estimator={"method": "inm", "gnss_aided": True},
        data_loss=[],
    )


def test_round_trip_is_exact(tmp_path):
    r = _result()
    save_result(tmp_path, "F01", "k1", r)
    back = load_result(tmp_path, "F01", "k1", FlightEstimate)
    for f in (
        "time",
        "lat",
        "lon",
        "height",
        "vel_n",
        "speed",
        "heading",
        "smoothed",
        "forward",
        "sigma",
        "disturbance",
        "segment",
        "attitude",
        "attitude_sigma",
        "dg_north",
        "dg_east",
        "sigma_north",
        "sigma_east",
        "horizontal_observable",
    ):
        np.testing.assert_array_equal(getattr(back, f), getattr(r, f))
    assert back.horizontal_observable.dtype == bool
    assert back.line.dtype == object and list(back.line) == list(r.line)
    assert back.truth_mgal is None and back.unfiltered is None and back.forward_sigma is None
    for f in (
        "name",
        "t0_unix_ns",
        "method",
        "line_segments",
        "line_info",
        "notes",
        "timings",
        "input_hashes",
        "estimator",
        "data_loss",
    ):
        assert getattr(back, f) == getattr(r, f), f
    # key order is kept (it is the order of the summary and GeoJSON properties)
    assert list(back.line_info["L01"]) == ["method", "Phi", "p"]
    assert not list(tmp_path.glob("*.pkl"))


def test_wrong_key_altered_or_missing_arrays_are_ignored(tmp_path):
    save_result(tmp_path, "F01", "k1", _result())
    jpath, npath = cache_paths(tmp_path, "F01")
    assert load_result(tmp_path, "F01", "other-key", FlightEstimate) is None
    data = bytearray(npath.read_bytes())
    data[len(data) // 2] ^= 0xFF
    npath.write_bytes(bytes(data))
    assert load_result(tmp_path, "F01", "k1", FlightEstimate) is None
    npath.unlink()
    assert load_result(tmp_path, "F01", "k1", FlightEstimate) is None
    jpath.write_text("{not json")
    assert load_result(tmp_path, "F01", "k1", FlightEstimate) is None


def test_planted_pickle_in_npz_with_a_matching_json_does_not_run(tmp_path):
    """An attacker who can write the cache folder writes both files, with the right key and
    hash: the pickled object array is refused by np.load(allow_pickle=False)."""
    import hashlib

    marker = tmp_path / "pwned"
    save_result(tmp_path, "F01", "k1", _result())
    jpath, npath = cache_paths(tmp_path, "F01")
    buf = io.BytesIO()
    evil = np.empty(1, dtype=object)
    evil[0] = Payload(marker)
    np.savez(buf, time=evil)
    npath.write_bytes(buf.getvalue())
    entry = json.loads(jpath.read_text())
    entry["npz_sha256"] = hashlib.sha256(npath.read_bytes()).hexdigest()
    jpath.write_text(json.dumps(entry))
    assert load_result(tmp_path, "F01", "k1", FlightEstimate) is None
    assert not marker.exists()


def test_cli_rerun_with_planted_cache_files_runs_no_code(tmp_path):
    """End to end: a processed survey's .cache gets a planted pickle (old format name) and a
    planted npz + JSON with the real key; the rerun reprocesses, writes the same outputs and the
    planted code never runs."""
    import hashlib

    src = tmp_path / "seed_line"
    shutil.copytree(ROOT / "sample_data" / "seed_line", src)
    out = tmp_path / "out"
    env = dict(os.environ)
    r = subprocess.run(
        EXE + ["run", str(src / "survey.yaml"), "-o", str(out)], capture_output=True, text=True, env=env, timeout=600
    )
    assert r.returncode == 0, r.stderr
    first = (out / "profiles.csv").read_bytes()
    cache = out / ".cache"
    marker = tmp_path / "pwned"
    import pickle

    (cache / "F01.pkl").write_bytes(pickle.dumps({"key": "x", "result": Payload(marker)}))
    evil = np.empty(1, dtype=object)
    evil[0] = Payload(marker)
    buf = io.BytesIO()
    np.savez(buf, time=evil)
    (cache / "F01.npz").write_bytes(buf.getvalue())
    entry = json.loads((cache / "F01.json").read_text())
    entry["npz_sha256"] = hashlib.sha256(buf.getvalue()).hexdigest()
    (cache / "F01.json").write_text(json.dumps(entry))
    r = subprocess.run(
        EXE + ["run", str(src / "survey.yaml"), "-o", str(out)], capture_output=True, text=True, env=env, timeout=600
    )
    assert r.returncode == 0, r.stderr
    assert not marker.exists()
    assert "reusing" not in (out / "gravsurvey.log").read_text().split(" run ")[-1]
    assert (out / "profiles.csv").read_bytes() == first
    # and the rewritten cache is reused by the next run, with identical outputs
    r = subprocess.run(
        EXE + ["run", str(src / "survey.yaml"), "-o", str(out)], capture_output=True, text=True, env=env, timeout=600
    )
    assert r.returncode == 0 and "reusing" in (out / "gravsurvey.log").read_text().split(" run ")[-1]
    assert (out / "profiles.csv").read_bytes() == first


def test_results_of_other_code_are_not_reused(tmp_path, monkeypatch):
    """The cache key holds the package's source fingerprint, not only its version number: a
    rerun with unchanged inputs reuses the flight, the same rerun by other code (a branch or a
    checkout installed under the same version) reprocesses it, with the same outputs here."""
    import gravsurvey.pipeline as pipeline
    from gravsurvey.cache import code_fingerprint

    assert len(code_fingerprint()) == 64 and code_fingerprint() == code_fingerprint()
    src = tmp_path / "seed_line"
    shutil.copytree(ROOT / "sample_data" / "seed_line", src)
    out = tmp_path / "out"
    first = pipeline.run_survey(src / "survey.yaml", output_dir=out)
    assert first.processed == ["F01"] and not first.skipped
    profiles = (out / "profiles.csv").read_bytes()
    again = pipeline.run_survey(src / "survey.yaml", output_dir=out)
    assert again.skipped == ["F01"] and not again.processed
    monkeypatch.setattr(pipeline, "code_fingerprint", lambda: "0" * 64)
    other = pipeline.run_survey(src / "survey.yaml", output_dir=out)
    assert other.processed == ["F01"] and not other.skipped
    assert (out / "profiles.csv").read_bytes() == profiles
