"""`gravsurvey` as users and cron meet it: end-to-end runs, exit codes, one-line errors,
atomic outputs under SIGKILL, the output lock, reruns and `check`."""

from __future__ import annotations

import csv
import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
from types import SimpleNamespace
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from gravsurvey.io.writers import read_xyz
from gravsurvey.settings import inm_params

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "sample_data"
EXE = [sys.executable, "-m", "gravsurvey"]


def gs(*args, cwd=None, timeout=600):
    """Run the CLI in a subprocess (not a terminal: quiet on success)."""
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.run(
        EXE + [str(a) for a in args],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=timeout,
        env=env,
        stdin=subprocess.DEVNULL,
    )


def _bounds_from_docs():
    """RMS bounds per sample survey, from the table in docs/samples.md."""
    text = (ROOT / "docs" / "samples.md").read_text()
    rows = re.findall(r"^\| `sample_data/(\w+)/survey.yaml` \|[^|]*\|[^|]*\|[^|]*\| ([\d.]+) \|", text, re.M)
    return {name: float(b) for name, b in rows}


def _nonblank(text):
    return [ln for ln in text.splitlines() if ln.strip()]


def _copy_sample(name, tmp_path):
    dst = tmp_path / name
    shutil.copytree(SAMPLES / name, dst)
    return dst


@pytest.fixture(scope="module", params=["seed_line", "grid_ros2", "markov_csv"])
def sample_run(request, tmp_path_factory):
    name = request.param
    tmp = tmp_path_factory.mktemp(name)
    src = _copy_sample(name, tmp)
    out = tmp / "out"
    r = gs("run", src / "survey.yaml", "-o", out)
    return name, src, out, r


def test_sample_survey_end_to_end(sample_run):
    name, src, out, r = sample_run
    assert r.returncode == 0, r.stderr
    summary = json.loads((out / "summary.json").read_text())
    # cron: quiet on success when not on a terminal, but for the warnings, the survey stage's as
    # well (grid_ros2: F02 flew across F01's lines; F01's connecting leg has no crossover)
    warned = [f"warning: {n}" for n in summary["notes"]]
    assert (name == "grid_ros2") == bool(warned)
    closing = [f"{len(warned)} warning{'' if len(warned) == 1 else 's'}"] if warned else []
    assert r.stdout == "" and _nonblank(r.stderr) == warned + closing, r.stderr
    for f in (
        "profiles.csv",
        "profiles.xyz",
        "lines.geojson",
        "summary.json",
        "crossovers.csv",
        "gravsurvey.log",
        "survey_map.png",
    ):
        assert (out / f).is_file(), f
    assert list(out.glob("profile_*_*.png"))
    # CSV columns as documented in docs/outputs.md
    with open(out / "profiles.csv", newline="") as fh:
        head = next(csv.reader(line for line in fh if not line.startswith("#")))
    documented = re.findall(r"^\| `(\w+)` \|", (ROOT / "docs" / "outputs.md").read_text(), re.M)
    for col in (
        "flight",
        "line",
        "time_utc",
        "lat_deg",
        "lon_deg",
        "height_m",
        "easting_m",
        "northing_m",
        "disturbance_mgal",
        "kalman_mgal",
        "sigma_mgal",
        "truth_mgal",
        "error_mgal",
    ):
        assert col in head and col in documented
    xyz = read_xyz(out / "profiles.xyz")
    assert len(xyz.lines) >= 1
    gj = json.loads((out / "lines.geojson").read_text())
    assert gj["type"] == "FeatureCollection" and gj["features"]
    for feat in gj["features"]:
        lon, lat = feat["geometry"]["coordinates"][0][:2]
        assert -180 <= lon <= 180 and -90 <= lat <= 90
    assert summary["software"]["version"]
    assert summary["config"]["sha256"]
    # the identified model and the drift decision are in the log as in summary.json (issue 12)
    log = (out / "gravsurvey.log").read_text()
    for fname, fs in summary["flights"].items():
        ident = fs["estimator"]["identification"]
        sigma = ident["anomaly_sigma_mps2"]["value"] / 1e-5
        assert f"{fname}: model: anomaly sigma {sigma:.3g} mGal, {ident['anomaly_sigma_mps2']['how']}" in log
        assert f"{fname}: drift: " in log
        if name == "grid_ros2":
            # strapdown with GNSS: the accelerometer noise chosen by likelihood, in both
            acc = ident["accel_noise_mps2"]
            assert acc["value"] in (1e-3, 5e-4, 2.5e-4) and "0.001" in acc["log_likelihood"]
            assert f"horizontal accelerometer noise {acc['value']:.3g} m/s^2 in 1 s, {acc['how']}" in log
            # short straight stretches pooled: a fact of the fit (summary.json), not a warning
            assert any("pooled" in n for n in ident["notes"]) and not ident["warnings"]
    if name == "grid_ros2":
        # F01: tie T01 crosses the three survey lines, T02 (which ends the flight) the first two
        # (configs/sample_grid_ros2.yaml); lines are kept by length, so neither tie is dropped.
        # F02's four east-west lines cross F01's three survey lines (and its connecting leg L04)
        with open(out / "crossovers.csv", newline="") as fh:
            rows = list(csv.DictReader(line for line in fh if not line.startswith("#")))
        f01 = [r for r in rows if r["flight_a"] == r["flight_b"] == "F01"]
        assert sorted(r["line_a"] for r in f01) == ["L01", "L01", "L02", "L02", "L03"]
        assert sorted(r["line_b"] for r in f01) == ["T01", "T01", "T01", "T02", "T02"]
        across = [r for r in rows if r["flight_a"] != r["flight_b"]]
        assert len(across) >= 12 and summary["crossovers"]["count"] == len(rows)
        assert summary["levelling"]["decision"]["applied"]  # docs/survey.md, "The sample survey"
        # F02 flew across F01's lines (its own "lines" are the survey's tie direction): said, with
        # the key that names them tie lines (docs/outputs.md, "Line segmentation")
        across_notes = [n for n in summary["notes"] if "across the survey's" in n]
        assert len(across_notes) == 1 and across_notes[0].startswith("lines: F02's lines run 9")
        assert "the lines of F01" in across_notes[0] and "lines.line_heading_deg" in across_notes[0]
        # the grid's sigma layer from the profiles' stated sigma (docs/survey.md, "The grid's sigma")
        gs_ = summary["grid"]["sigma"]
        assert gs_["data_sigma_from"] == "stated" and gs_["data_sigma_length_m"] > 0
        import xarray as xr

        with xr.open_dataset(out / "grid.nc", engine="scipy") as ds:
            sg = ds["gravity_disturbance_sigma"].values
            assert np.array_equal(np.isfinite(sg), np.isfinite(ds["gravity_disturbance"].values))
            assert np.nanmin(sg) > 0 and np.nanmedian(sg) == pytest.approx(gs_["median_mgal"], rel=1e-3)
        # F01's lines share errors, which cancel in the held-out residuals: smaller than the
        # stated sigma makes them, and not a note (grid.sigma_notes)
        assert gs_["cv_rms_predicted_mgal"] > 1.5 * gs_["cv_rms_mgal"]
        assert not any(n.startswith("grid: the cross-validation residuals") for n in summary["notes"])
    else:
        assert not any("across the survey's" in n for n in summary["notes"])
    bound = _bounds_from_docs()[name]
    assert summary["rms_vs_truth_mgal"] is not None
    assert summary["rms_vs_truth_mgal"] <= bound, (name, summary["rms_vs_truth_mgal"], bound)


def test_flights_across_only_for_detected_lines(tmp_path):
    # lines: {mode: whole} makes each flight one line L01 from take-off to landing: its direction
    # is no survey direction, and the note on flights across the lines is not made
    src = _copy_sample("grid_ros2", tmp_path)
    cfg = src / "survey.yaml"
    cfg.write_text(cfg.read_text().replace("lines: {mode: auto}", "lines: {mode: whole}"))
    r = gs("run", cfg, "-o", tmp_path / "out", "--no-plots")
    assert r.returncode == 0, r.stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert [ln for fl in summary["flights"].values() for ln in fl["lines"]] == ["L01", "L01"]
    assert not any("across the survey's" in n for n in summary["notes"])


def test_rerun_skips_unchanged_and_check_passes(tmp_path):
    src = _copy_sample("seed_line", tmp_path)
    out = tmp_path / "out"
    r = gs("run", src / "survey.yaml", "-o", out)
    assert r.returncode == 0, r.stderr
    ref = tmp_path / "ref"
    shutil.copytree(out, ref)
    r2 = gs("run", src / "survey.yaml", "-o", out)
    assert r2.returncode == 0, r2.stderr
    log = (out / "gravsurvey.log").read_text()
    assert "unchanged, reusing" in log
    c = gs("check", out, ref)
    assert c.returncode == 0, c.stderr
    # a result that moves beyond tolerance fails with a readable diff
    prof = (ref / "profiles.csv").read_text().splitlines()
    h0 = next(i for i, ln in enumerate(prof) if not ln.startswith("#"))  # after the '# key: value' metadata
    head = prof[h0].split(",")
    j = head.index("disturbance_mgal")
    for i in range(h0 + 1, len(prof)):
        parts = prof[i].split(",")
        if parts[j] not in ("", "nan"):
            parts[j] = repr(float(parts[j]) + 0.5)
            prof[i] = ",".join(parts)
            break
    (ref / "profiles.csv").write_text("\n".join(prof) + "\n")
    # edited behind the summary's back: the reference is damaged, not a different run (exit 1)
    c = gs("check", out, ref)
    assert c.returncode == 1, c.stderr
    assert "profiles.csv: changed since the reference run wrote it" in c.stderr
    # as a different run would have written it (its summary lists the new hash): exit 4
    summary = json.loads((ref / "summary.json").read_text())
    summary["output_sha256"]["profiles.csv"] = hashlib.sha256((ref / "profiles.csv").read_bytes()).hexdigest()
    (ref / "summary.json").write_text(json.dumps(summary))
    c = gs("check", out, ref)
    assert c.returncode == 4, c.stderr
    assert "disturbance_mgal" in c.stderr and "1 of" in c.stderr
    assert "Traceback" not in c.stderr


def _one_line_error(r, code, *needles):
    assert r.returncode == code, (r.returncode, r.stderr)
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, r.stderr
    assert "Traceback" not in r.stderr
    for n in needles:
        assert n in lines[0], (n, lines[0])


def test_error_unknown_key(tmp_path):
    src = _copy_sample("seed_line", tmp_path)
    text = (src / "survey.yaml").read_text().replace("lines: {mode: whole}", "lines: {mode: whole}\npostproces: {}")
    (src / "survey.yaml").write_text(text)
    r = gs("run", src / "survey.yaml")
    _one_line_error(r, 2, "postproces", "postprocess")


def test_error_wrong_type(tmp_path):
    src = _copy_sample("seed_line", tmp_path)
    text = (
        (src / "survey.yaml")
        .read_text()
        .replace("lines: {mode: whole}", "model: {altimeter_sigma_m: one}\nlines: {mode: whole}")
    )
    (src / "survey.yaml").write_text(text)
    r = gs("validate", src / "survey.yaml")
    _one_line_error(r, 2, "model.altimeter_sigma_m")


def test_error_missing_config(tmp_path):
    r = gs("run", tmp_path / "nope.yaml")
    _one_line_error(r, 2, "nope.yaml")


def test_error_missing_input_file(tmp_path):
    src = _copy_sample("seed_line", tmp_path)
    (src / "F01" / "F01_json.mcap").unlink()
    r = gs("run", src / "survey.yaml", "-o", tmp_path / "out")
    assert r.returncode == 1
    assert "F01_json.mcap" in r.stderr and "Traceback" not in r.stderr


def test_error_empty_flight(tmp_path):
    src = _copy_sample("markov_csv", tmp_path)
    imu = src / "F01" / "imu.csv"
    keep = [ln for ln in imu.read_text().splitlines() if ln.startswith("#") or ln.startswith("time")]
    imu.write_text("\n".join(keep) + "\n")
    r = gs("run", src / "survey.yaml", "-o", tmp_path / "out")
    assert r.returncode == 1
    assert "imu" in r.stderr.lower() and "Traceback" not in r.stderr


def test_truncated_mcap_is_salvaged_and_reported(tmp_path):
    """A file cut mid-chunk (power lost while recording) is processed up to the damage, the
    flight's deliverables are written, and the run exits 1 with one line saying what was lost."""
    src = _copy_sample("seed_line", tmp_path)
    f = src / "F01" / "F01_json.mcap"
    data = f.read_bytes()
    f.write_bytes(data[: len(data) // 2])
    r = gs("run", src / "survey.yaml", "-o", tmp_path / "out")
    # what is left (617 s) is too short to identify the anomaly prior: the run says so too
    warned = [ln for ln in r.stderr.splitlines() if ln.startswith("warning: ")]
    assert len(warned) == 1 and "too short to see the field's spectrum" in warned[0], r.stderr
    rest = SimpleNamespace(
        returncode=r.returncode,
        stderr="\n".join(ln for ln in r.stderr.splitlines() if not ln.startswith("warning: ") and ln != "1 warning"),
    )
    _one_line_error(rest, 1, "F01", "salvaged", "F01_json.mcap")
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["flights"]["F01"]["data_loss"]
    assert summary["flights"]["F01"]["lines"]


def test_one_failing_flight_does_not_stop_the_others(tmp_path):
    src = _copy_sample("seed_line", tmp_path)
    text = (src / "survey.yaml").read_text()
    block = text.split("flights:\n", 1)[1].split("\nlines:", 1)[0] + "\n"
    bad = block.replace("name: F01", "name: F02").replace("F01/F01_json.mcap", "F01/missing.mcap")
    (src / "survey.yaml").write_text(text.replace(block, block + bad))
    r = gs("run", src / "survey.yaml", "-o", tmp_path / "out", "--jobs", "2")
    assert r.returncode == 1
    assert "F02" in r.stderr and "Traceback" not in r.stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert "F01" in summary["flights"] and summary["failed_flights"]


def test_sigkill_leaves_previous_outputs_intact(tmp_path):
    src = _copy_sample("seed_line", tmp_path)
    out = tmp_path / "out"
    r = gs("run", src / "survey.yaml", "-o", out)
    assert r.returncode == 0
    before = {
        p.name: p.read_bytes()
        for p in out.iterdir()
        if p.is_file() and not p.name.startswith(".") and p.name != "gravsurvey.log"
    }
    for delay in (1.0, 2.5, 4.0):
        p = subprocess.Popen(
            EXE + ["run", str(src / "survey.yaml"), "-o", str(out), "--force"],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            stdin=subprocess.DEVNULL,
        )
        time.sleep(delay)
        p.send_signal(signal.SIGKILL)
        p.wait()
        # the run is deterministic: every deliverable is either untouched or replaced by an
        # identical complete copy; summary.json differs only by its creation time
        for name, content in before.items():
            if name != "summary.json":
                assert (out / name).read_bytes() == content, name
        # no partial file under a final name: every deliverable parses
        json.loads((out / "summary.json").read_text())
        read_xyz(out / "profiles.xyz")
        assert not [q for q in out.iterdir() if q.name.endswith(".tmp") or ".tmp-" in q.name]
    r = gs("run", src / "survey.yaml", "-o", out, "--force")
    assert r.returncode == 0, r.stderr
    assert not [q for q in out.iterdir() if q.name.startswith(".staging")]


def test_two_runs_on_one_output_dir(tmp_path):
    """While another run holds the output directory, a second run refuses (exit 2, one line),
    or with --wait waits and then completes."""
    from gravsurvey.io.writers import OutputLock

    src = _copy_sample("seed_line", tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    with OutputLock(out):
        r = gs("run", src / "survey.yaml", "-o", out)
        _one_line_error(r, 2, "another gravsurvey run")
        p = subprocess.Popen(
            EXE + ["run", str(src / "survey.yaml"), "-o", str(out), "--wait", "120"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            stdin=subprocess.DEVNULL,
            text=True,
        )
        time.sleep(4.0)
        assert p.poll() is None  # still waiting for the lock
        assert not (out / "summary.json").exists()
    p.communicate(timeout=600)
    assert p.returncode == 0
    assert (out / "summary.json").is_file()


def test_init_writes_a_valid_config(tmp_path):
    cfg = tmp_path / "g.yaml"
    r = gs("init", cfg)
    assert r.returncode == 0
    from gravsurvey.config import load_yaml

    data = load_yaml(cfg)
    assert data["flights"][0]["triad"] == "strapdown"  # the sample it points at (tests/test_templates.py)
    # the example's model block is accepted by the estimator's validation
    inm_params(data["model"], key_path="model")
    r = gs("init", cfg)
    _one_line_error(r, 2, "exists")


def test_version_and_help():
    r = gs("--version")
    assert r.returncode == 0 and re.search(r"\d+\.\d+", r.stdout)
    for cmd in ("run", "simulate", "inspect", "validate", "init", "check"):
        r = gs(cmd, "--help")
        assert r.returncode == 0 and "Example" in r.stdout, cmd


def test_usage_error_exit_2():
    r = gs("run")
    assert r.returncode == 2 and "Traceback" not in r.stderr


def test_yaml_tags_are_not_constructed(tmp_path):
    cfg = tmp_path / "evil.yaml"
    cfg.write_text("survey: !!python/object/apply:os.system ['echo hacked']\n")
    r = gs("validate", cfg)
    _one_line_error(r, 2, "evil.yaml")
