"""Deliverable formats, atomic publication and the output lock."""

import csv
import datetime as dt
import errno
import json
import math
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from gravsurvey.errors import DataError, GravsurveyError
from gravsurvey.io import writers as w
from gravsurvey.crossovers import find_crossovers

ROOT = Path(__file__).resolve().parents[1]
T0_NS = 1_714_557_600_000_000_000  # 2024-05-01T10:00:00Z


def make_table(truth=True, n1=5, n2=4):
    n = n1 + n2
    tns = T0_NS + np.arange(n, dtype=np.int64) * 1_000_000_000 + 123_456_789
    t = {
        "flight": np.array(["F01"] * n1 + ["F02"] * n2, dtype=object),
        "line": np.array(["L01"] * n1 + ["T01"] * n2, dtype=object),
        "time_unix_ns": tns,
        "lat_deg": np.linspace(45.0, 45.01, n),
        "lon_deg": np.linspace(135.0, 135.02, n),
        "height_m": np.full(n, 1000.25),
        "easting_m": np.linspace(500000.0, 501000.0, n),
        "northing_m": np.linspace(4982950.0, 4984000.0, n),
        "disturbance_mgal": np.linspace(-3.0, 5.0, n),
        "kalman_mgal": np.linspace(-3.5, 5.5, n),
        "sigma_mgal": np.full(n, 0.75),
        "levelled_mgal": np.linspace(-3.0, 5.0, n) - 0.5,
    }
    t["kalman_mgal"][2] = np.nan
    if truth:
        t["truth_mgal"] = np.linspace(-2.9, 4.9, n)
        t["error_mgal"] = t["disturbance_mgal"] - t["truth_mgal"]
    return t


def documented_columns(section):
    """Column names from the first table under a '## `name`' heading of docs/outputs.md."""
    text = (ROOT / "docs" / "outputs.md").read_text()
    body = text.split(f"## `{section}`", 1)[1].split("\n## ", 1)[0]
    cols = []
    for line in body.splitlines():
        m = re.match(r"\| ((?:`[a-z_]+`(?:, )?)+) \|", line)
        if m:
            cols += re.findall(r"`([a-z_]+)`", m.group(1))
    return cols


def test_profiles_csv_columns_as_documented_and_values(tmp_path):
    t = make_table()
    p = tmp_path / "profiles.csv"
    w.write_profiles_csv(p, t)
    with open(p, newline="") as fh:
        rows = list(csv.reader(fh))
    documented = documented_columns("profiles.csv")
    # the optional columns are documented, in this order, and written only when estimated:
    # attitude for strapdown surveys, horizontal components when the model has them, the
    # estimate column named for what it holds (kalman_mgal: 3D-INM, unfiltered_mgal: classic)
    assert [c for c in documented if c in w.ATTITUDE_COLUMNS] == list(w.ATTITUDE_COLUMNS)
    assert [c for c in documented if c in w.HORIZONTAL_COLUMNS] == list(w.HORIZONTAL_COLUMNS)
    assert [c for c in documented if c in w.ESTIMATE_COLUMNS] == list(w.ESTIMATE_COLUMNS)
    optional = w.ATTITUDE_COLUMNS + w.HORIZONTAL_COLUMNS + ("unfiltered_mgal", "drift_mgal")
    assert rows[0] == [c for c in documented if c not in optional]
    assert rows[0] == list(
        w.PROFILE_COLUMNS[:10] + ("kalman_mgal",) + w.PROFILE_COLUMNS[10:] + w.LEVEL_COLUMNS + w.TRUTH_COLUMNS
    )
    assert len(rows) == 1 + 9
    r = dict(zip(rows[0], rows[3]))
    # 10:00:02.123456789 -> nearest ms .123; independent check with datetime
    ref = dt.datetime(2024, 5, 1, 10, 0, 2, 123000, tzinfo=dt.timezone.utc)
    assert r["time_utc"] == "2024-05-01T10:00:02.123Z"
    assert dt.datetime.fromisoformat(r["time_utc"].replace("Z", "+00:00")) == ref
    assert int(r["time_unix_ns"]) == T0_NS + 2_000_000_000 + 123_456_789
    assert r["kalman_mgal"] == "NaN" and math.isnan(float(r["kalman_mgal"]))
    assert float(r["lat_deg"]) == pytest.approx(45.0025, abs=5e-10)
    assert r["height_m"] == "1000.250"
    assert float(r["error_mgal"]) == pytest.approx(float(r["disturbance_mgal"]) - float(r["truth_mgal"]), abs=2e-4)
    back = w.read_profiles_csv(p)
    np.testing.assert_array_equal(back["time_unix_ns"], t["time_unix_ns"])
    np.testing.assert_allclose(back["disturbance_mgal"], t["disturbance_mgal"], atol=5e-5)
    # without truth: the two optional columns are absent
    t2 = make_table(truth=False)
    w.write_profiles_csv(p, t2)
    assert p.read_text().splitlines()[0].split(",") == list(
        w.PROFILE_COLUMNS[:10] + ("kalman_mgal",) + w.PROFILE_COLUMNS[10:] + w.LEVEL_COLUMNS
    )
    with pytest.raises(ValueError, match="truth_mgal and error_mgal go together"):
        w.write_profiles_csv(p, dict(t2, truth_mgal=t["truth_mgal"]))
    with pytest.raises(ValueError, match="lacks columns"):
        w.write_profiles_csv(p, {k: v for k, v in t2.items() if k != "sigma_mgal"})


def test_utc_rounding_half_up_and_before_epoch_free():
    ns = np.array([T0_NS + 499_999, T0_NS + 500_000, T0_NS + 999_999_999], dtype=np.int64)
    assert w.format_utc(ns).tolist() == [
        "2024-05-01T10:00:00.000Z",
        "2024-05-01T10:00:00.001Z",
        "2024-05-01T10:00:01.000Z",
    ]


def test_crossovers_csv_as_documented(tmp_path):
    a = {
        "flight": "F1",
        "line": "L01",
        "easting_m": np.arange(11.0),
        "northing_m": np.full(11, 3.0),
        "value_mgal": np.arange(11.0),
        "time_s": np.arange(11.0),
    }
    b = {
        "flight": "F2",
        "line": "T01",
        "easting_m": np.full(11, 2.5),
        "northing_m": np.arange(11.0),
        "value_mgal": 100 - 2 * np.arange(11.0),
        "time_s": np.arange(11.0),
    }
    p = tmp_path / "crossovers.csv"
    w.write_crossovers_csv(p, find_crossovers([a, b]))
    rows = list(csv.DictReader(open(p, newline="")))
    assert list(rows[0].keys()) == documented_columns("crossovers.csv") == list(w.CROSSOVER_COLUMNS)
    assert len(rows) == 1
    assert float(rows[0]["diff_mgal"]) == pytest.approx(2.5 - 94.0)
    assert (rows[0]["flight_a"], rows[0]["line_b"]) == ("F1", "T01")
    assert float(rows[0]["angle_deg"]) == pytest.approx(90.0)


def test_xyz_round_trip_and_format(tmp_path):
    t = make_table()
    t["lat_deg"][1] = np.nan
    p = tmp_path / "profiles.xyz"
    w.write_xyz(p, t, title="test survey")
    text = p.read_text()
    lines = text.splitlines()
    assert lines[0] == "/ test survey"
    assert "Line 1001" in lines and "Tie 2001" in lines
    assert "/ Line 1001 = flight F01 line L01" in lines and "/ Tie 2001 = flight F02 line T01" in lines
    # every non-comment, non-header line has one field per column; the NaN is a '*'
    x = w.read_xyz(p)
    assert x.columns == list(
        w.XYZ_COLUMNS[:7] + ("kalman_mgal",) + w.XYZ_COLUMNS[7:] + w.LEVEL_COLUMNS + w.TRUTH_COLUMNS
    )
    data_lines = [ln for ln in lines if not ln.startswith("/") and not re.match(r"(Line|Tie) \d+$", ln)]
    assert all(len(ln.split()) == len(x.columns) for ln in data_lines)
    assert sum(ln.split().count("*") for ln in data_lines) == 2  # lat and kalman NaN
    assert list(x.lines) == ["Line 1001", "Tie 2001"]
    l1 = x.lines["Line 1001"]
    assert np.isnan(l1["lat_deg"][1]) and np.isnan(l1["kalman_mgal"][2])
    np.testing.assert_allclose(l1["lon_deg"], t["lon_deg"][:5], atol=5e-10)
    np.testing.assert_allclose(x.lines["Tie 2001"]["disturbance_mgal"], t["disturbance_mgal"][5:], atol=5e-5)
    np.testing.assert_allclose(l1["time_unix_s"], (T0_NS + np.arange(5) * 1e9 + 123_456_789) / 1e9, atol=6e-4)
    np.testing.assert_allclose(l1["time_unix_s"][0] % 1.0, 0.123, atol=1e-6)


def test_xyz_line_notes_follow_the_line_map(tmp_path):
    t = make_table()
    p = tmp_path / "p.xyz"
    w.write_xyz(p, t, line_notes={("F01", "L01"): "half-wavelength resolution 4.2 km", ("F02", "T01"): "two\nlines"})
    lines = p.read_text().splitlines()
    assert "/ Line 1001 = flight F01 line L01; half-wavelength resolution 4.2 km" in lines
    assert "/ Tie 2001 = flight F02 line T01; two lines" in lines  # one comment line per map entry
    assert list(w.read_xyz(p).lines) == ["Line 1001", "Tie 2001"]  # the notes do not disturb the data


def test_resolution_statement():
    assert w.resolution_statement(4200.0) == "half-wavelength resolution 4.2 km"
    assert w.resolution_statement(12345.0) == "half-wavelength resolution 12.3 km"
    assert w.resolution_statement(math.inf) == "no wavelength resolved above the noise (flat estimate)"
    for missing in (None, math.nan, 0.0):
        assert w.resolution_statement(missing) == "half-wavelength resolution not stated"


def test_rows_outside_lines_only_in_csv(tmp_path):
    # turn epochs (line "") between two lines of one flight, and a stale time_utc that is ignored
    t = make_table(truth=False, n1=6, n2=0)
    t["line"] = np.array(["L01", "L01", "", "", "L02", "L02"], dtype=object)
    t["time_utc"] = np.array(["bogus"] * 6, dtype=object)
    w.write_profiles_csv(tmp_path / "p.csv", t)
    rows = list(csv.DictReader(open(tmp_path / "p.csv", newline="")))
    assert [r["line"] for r in rows] == ["L01", "L01", "", "", "L02", "L02"]
    assert rows[0]["time_utc"] == "2024-05-01T10:00:00.123Z"
    w.write_xyz(tmp_path / "p.xyz", t)
    x = w.read_xyz(tmp_path / "p.xyz")
    assert list(x.lines) == ["Line 1001", "Line 1002"]
    assert [v["lat_deg"].size for v in x.lines.values()] == [2, 2]
    w.write_geojson(tmp_path / "l.geojson", t, None, None)
    g = _strict_json(tmp_path / "l.geojson")
    assert [f["properties"]["line"] for f in g["features"]] == ["L01", "L02"]


def test_xyz_line_numbers():
    h, m = w.xyz_line_labels(["A", "A", "A", "B", "B"], ["L02", "north", "T01", "L02", "x"])
    assert h == ["Line 1002", "Line 1001", "Tie 1001", "Line 2002", "Line 2001"]
    assert m["Line 1001"] == ("A", "north")


def test_xyz_reader_rejects_damaged_files(tmp_path):
    p = tmp_path / "bad.xyz"
    p.write_text("/ a b\n1 2\n")
    with pytest.raises(DataError, match=r"bad\.xyz:2: data before the first Line header"):
        w.read_xyz(p)
    p.write_text("/ a b\nLine 1\n1 2 3\n")
    with pytest.raises(DataError, match=r"bad\.xyz:3: 3 fields, expected 2"):
        w.read_xyz(p)


def _strict_json(path):
    def bad(c):
        raise AssertionError(f"non-standard JSON constant {c}")

    return json.loads(Path(path).read_text(), parse_constant=bad)


def test_geojson_rfc7946(tmp_path):
    t = make_table()
    p = tmp_path / "lines.geojson"
    stats = [
        {
            "flight": "F01",
            "line": "L01",
            "rms_vs_truth_mgal": np.float64(0.4),
            "method": "db4",
            "n": np.int64(5),
            "crossover_rms_mgal": float("nan"),
        }
    ]
    w.write_geojson(p, t, stats, 32653)
    g = _strict_json(p)
    assert g["type"] == "FeatureCollection" and "crs" not in g
    assert len(g["features"]) == 2
    f1, f2 = g["features"]
    assert f1["type"] == "Feature" and f1["geometry"]["type"] == "LineString"
    c = np.array(f1["geometry"]["coordinates"])
    # [lon, lat] order: lon ~135, lat ~45
    np.testing.assert_allclose(c[:, 0], t["lon_deg"][:5], atol=1e-7)
    np.testing.assert_allclose(c[:, 1], t["lat_deg"][:5], atol=1e-7)
    assert f1["properties"]["rms_vs_truth_mgal"] == 0.4 and f1["properties"]["n"] == 5
    assert f1["properties"]["crossover_rms_mgal"] is None
    assert f1["properties"]["projected_crs"] == "EPSG:32653"
    assert f1["properties"]["start_utc"] == "2024-05-01T10:00:00.123Z"
    assert f1["properties"]["length_km"] == pytest.approx(np.hypot(1000.0 * 4 / 8, 1050.0 * 4 / 8) / 1e3, rel=1e-9)
    assert f2["properties"]["line"] == "T01" and "method" not in f2["properties"]
    for f in g["features"]:
        for lon, lat in f["geometry"]["coordinates"]:
            assert -180 <= lon <= 180 and -90 <= lat <= 90


def test_geojson_antimeridian_thinning_and_null_geometry(tmp_path):
    n = 5001
    lon = np.linspace(179.0, 181.0, n)  # crosses 180 at the middle
    lat = np.linspace(-10.0, -12.0, n)
    t = {
        "flight": np.array(["F"] * n + ["F"] * 2, dtype=object),
        "line": np.array(["L01"] * n + ["L02"] * 2, dtype=object),
        "lat_deg": np.concatenate([lat, [np.nan, 1.0]]),
        "lon_deg": np.concatenate([lon, [1.0, 1.0]]),
        "time_unix_ns": np.arange(n + 2, dtype=np.int64),
        "easting_m": np.zeros(n + 2),
        "northing_m": np.zeros(n + 2),
    }
    p = tmp_path / "am.geojson"
    w.write_geojson(p, t, None, None, max_vertices=1000)
    g = _strict_json(p)
    geom = g["features"][0]["geometry"]
    assert geom["type"] == "MultiLineString" and len(geom["coordinates"]) == 2
    west, east = geom["coordinates"]
    assert west[-1][0] == 180.0 and east[0][0] == -180.0
    assert west[-1][1] == pytest.approx(-11.0, abs=1e-3) and east[0][1] == west[-1][1]
    assert len(west) + len(east) <= 1000 + 2
    assert west[0] == [179.0, -10.0] and east[-1] == [-179.0, -12.0]
    assert g["features"][1]["geometry"] is None  # one valid position only


def test_write_json_converts_numpy(tmp_path):
    p = tmp_path / "summary.json"
    w.write_json(
        p, {"a": np.float32(1.5), "b": np.arange(3), "c": (np.nan, np.inf), "d": np.bool_(True), "e": {1: Path("x/y")}}
    )
    assert _strict_json(p) == {"a": 1.5, "b": [0, 1, 2], "c": [None, None], "d": True, "e": {"1": "x/y"}}
    with pytest.raises(TypeError, match="cannot write object to JSON"):
        w.write_json(p, {"x": object()})
    assert _strict_json(p)["a"] == 1.5  # the failed write left the previous file intact
    assert [q.name for q in tmp_path.iterdir()] == ["summary.json"]


# ------------------------------------------------------------------------------- atomic output
def test_transaction_publishes_on_success_and_nothing_on_error(tmp_path):
    out = tmp_path / "out"
    with w.OutputTransaction(out) as tx:
        w.write_json(tx.path("summary.json"), {"run": 1})
        (tx.path("plots/L01.png")).write_bytes(b"one")
        tx.path("obsolete.txt").write_text("x")
        assert not (out / "summary.json").exists()  # nothing visible before commit
        assert tx.staged_files() == ["obsolete.txt", "plots/L01.png", "summary.json"]
        hashes = tx.file_hashes()
    assert set(hashes) == {"obsolete.txt", "plots/L01.png"}
    assert json.loads((out / "summary.json").read_text()) == {"run": 1}
    assert (out / "plots" / "L01.png").read_bytes() == b"one"
    with pytest.raises(RuntimeError, match="boom"):
        with w.OutputTransaction(out) as tx:
            w.write_json(tx.path("summary.json"), {"run": 2})
            raise RuntimeError("boom")
    assert json.loads((out / "summary.json").read_text()) == {"run": 1}
    assert sorted(p.name for p in out.iterdir()) == [".gravsurvey-files.json", "obsolete.txt", "plots", "summary.json"]
    # a later run that no longer makes obsolete.txt removes it
    with w.OutputTransaction(out) as tx:
        w.write_json(tx.path("summary.json"), {"run": 3})
        tx.path("plots/L01.png").write_bytes(b"three")
    assert not (out / "obsolete.txt").exists()
    assert (out / "plots" / "L01.png").read_bytes() == b"three"
    with w.OutputTransaction(out):  # a run that produced nothing deletes nothing
        pass
    assert (out / "plots" / "L01.png").read_bytes() == b"three" and (out / "summary.json").exists()
    with pytest.raises(ValueError, match="relative path"):
        with w.OutputTransaction(out) as tx:
            tx.path("../escape.txt")


def _published(out):
    return {
        str(p.relative_to(out)): p.read_text() for p in out.rglob("*") if p.is_file() and not p.name.startswith(".")
    }


def test_an_error_while_publishing_leaves_the_previous_outputs(tmp_path, monkeypatch):
    """A rename that fails half-way (a file nobody may replace, a full disk) or a folder in the
    way of an output file: the folder is the previous run's afterwards, not a mix (fuzzing,
    2026-12-04: the new lines.geojson beside the previous summary.json)."""
    from gravsurvey.io.writers import atomic

    out = tmp_path / "out"
    with w.OutputTransaction(out) as tx:
        for name in ("a.csv", "b.csv", "summary.json"):
            tx.path(name).write_text("old")
    before = _published(out)
    real_replace = os.replace
    calls = []

    def fail_third(src, dst):
        calls.append(str(dst))
        if len(calls) == 3 and ".previous-versions" not in str(src):
            raise OSError(errno.EACCES, "Permission denied", str(dst))
        real_replace(src, dst)

    monkeypatch.setattr(atomic.os, "replace", fail_third)
    with pytest.raises(OSError, match="Permission denied"):
        with w.OutputTransaction(out) as tx:
            for name in ("a.csv", "b.csv", "new.csv", "summary.json"):
                tx.path(name).write_text("new")
    monkeypatch.setattr(atomic.os, "replace", real_replace)
    assert _published(out) == before  # a.csv and b.csv back to "old", new.csv gone
    assert not [p for p in out.iterdir() if p.name.startswith(".staging-")]
    # a folder in the way: refused before anything is renamed
    (out / "b.csv").unlink()
    (out / "b.csv").mkdir()
    with pytest.raises(IsADirectoryError, match="a folder is in the way"):
        with w.OutputTransaction(out) as tx:
            for name in ("a.csv", "b.csv", "summary.json"):
                tx.path(name).write_text("newer")
    assert _published(out) == {"a.csv": "old", "summary.json": "old"}


def test_ctrl_c_during_publish_waits_for_the_commit(tmp_path, monkeypatch):
    """A SIGINT that arrives half-way through the renames (Python's own handler, as in a
    notebook): every file of the run is published, then the KeyboardInterrupt comes."""
    from gravsurvey.io.writers import atomic

    out = tmp_path / "out"
    with w.OutputTransaction(out) as tx:
        for name in ("a.csv", "b.csv", "summary.json"):
            tx.path(name).write_text("old")
    real_replace = os.replace
    calls = []

    def replace_then_interrupt(src, dst):
        calls.append(dst)
        if len(calls) == 1:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)  # the handler would run here, between two renames
        real_replace(src, dst)

    monkeypatch.setattr(atomic.os, "replace", replace_then_interrupt)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            with w.OutputTransaction(out) as tx:
                for name in ("a.csv", "b.csv", "summary.json"):
                    tx.path(name).write_text("new")
    finally:
        signal.signal(signal.SIGINT, previous)
    assert len(calls) >= 3
    assert {p.name: p.read_text() for p in out.iterdir() if p.suffix in (".csv", ".json") and p.name[0] != "."} == {
        "a.csv": "new",
        "b.csv": "new",
        "summary.json": "new",
    }
    assert not [p for p in out.iterdir() if p.name.startswith(".staging")]


CHILD = textwrap.dedent(
    """
    import os, sys, json, signal
    from gravsurvey.io import writers as w
    out, run, mode = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    names = ["a.csv", "b.xyz", "plots/p.png", "summary.json"]
    if mode == "kill-during-publish":
        real = os.replace
        count = [0]
        def replace(src, dst):
            stage = os.path.join(out, ".staging-")
            if str(src).startswith(stage) and not str(dst).startswith(stage):  # publishing
                count[0] += 1
                if count[0] == 3:   # two files published, then the power goes
                    os.kill(os.getpid(), signal.SIGKILL)
            return real(src, dst)
        os.replace = replace
    with w.OutputLock(out), w.OutputTransaction(out) as tx:
        for name in names[:-1]:
            p = tx.path(name)
            if mode == "kill-mid-write" and name == "b.xyz":
                with open(p, "w") as fh:
                    fh.write("partial " * 1000)
                    fh.flush()
                    print("WRITING", flush=True)
                    sys.stdin.readline()        # parent kills us here
            p.write_text(f"{name} run {run}\\n" * 1000)
        w.write_json(tx.path("summary.json"), {"run": run, "files": tx.file_hashes()})
    print("DONE", flush=True)
    """
)


def run_child(out, run, mode="normal", **kw):
    return subprocess.Popen(
        [sys.executable, "-c", CHILD, str(out), str(run), mode],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        **kw,
    )


def snapshot(out):
    return {
        str(p.relative_to(out)): p.read_bytes()
        for p in Path(out).rglob("*")
        if p.is_file() and not p.relative_to(out).parts[0].startswith(".")
    }


def test_sigkill_mid_write_leaves_previous_outputs(tmp_path):
    out = tmp_path / "out"
    c = run_child(out, 1)
    assert c.communicate(timeout=60)[0].strip() == "DONE" and c.returncode == 0
    before = snapshot(out)
    assert set(before) == {"a.csv", "b.xyz", "plots/p.png", "summary.json"}
    c = run_child(out, 2, "kill-mid-write")
    assert c.stdout.readline().strip() == "WRITING"
    os.kill(c.pid, signal.SIGKILL)
    c.wait(timeout=30)
    assert c.returncode == -signal.SIGKILL
    assert snapshot(out) == before  # previous outputs intact, byte for byte
    staging = [p for p in out.iterdir() if p.name.startswith(".staging-")]
    assert len(staging) == 1  # the killed run's partial files are only there, hidden
    assert not any(".tmp-" in str(p) for p in out.rglob("*") if not str(p).startswith(str(staging[0])))
    c = run_child(out, 3)
    assert c.communicate(timeout=60)[0].strip() == "DONE"
    assert not [p for p in out.iterdir() if p.name.startswith(".staging-")]  # stale staging removed
    after = snapshot(out)
    assert json.loads(after["summary.json"])["run"] == 3
    assert after["a.csv"] == b"a.csv run 3\n" * 1000


def test_sigkill_during_publish_no_partial_files_summary_old(tmp_path):
    out = tmp_path / "out"
    c = run_child(out, 1)
    c.communicate(timeout=60)
    before = snapshot(out)
    c = run_child(out, 2, "kill-during-publish")
    c.communicate(timeout=60)
    assert c.returncode == -signal.SIGKILL
    now = snapshot(out)
    assert set(now) == set(before)
    summary = json.loads(now["summary.json"])
    assert summary["run"] == 1  # summary.json is published last: still the previous run's
    import hashlib

    mixed = 0
    for name, data in now.items():
        if name == "summary.json":
            continue
        # each file is complete: either the previous run's or the new run's version
        assert data in (before[name], f"{name} run 2\n".encode() * 1000)
        new = data != before[name]
        mixed += new
        # and the old summary's hashes tell which ones are not the summary's
        assert (hashlib.sha256(data).hexdigest() == summary["files"][name]) == (not new)
    assert mixed == 2


def test_stale_staging_of_live_transaction_is_kept(tmp_path):
    out = tmp_path / "out"
    with w.OutputTransaction(out) as tx1:
        # a concurrent cleaner (another process's view) must not remove a live staging dir
        assert w.remove_stale_staging(out, min_age_s=0.0) == []
        assert tx1.staging.is_dir()
    # a staging dir of a dead pid, unlocked, is removed; a young one of a live pid stays
    dead = out / ".staging-999999999-dead"
    dead.mkdir()
    young = out / f".staging-{os.getpid()}-young"
    young.mkdir()
    assert w.remove_stale_staging(out) == [dead.name]
    assert young.exists()


# ------------------------------------------------------------------------------- lock
HOLDER = textwrap.dedent(
    """
    import sys
    from gravsurvey.io import writers as w
    with w.OutputLock(sys.argv[1]):
        print("HELD", flush=True)
        sys.stdin.readline()
    """
)


def test_lock_refuses_second_run_with_message(tmp_path):
    out = tmp_path / "out"
    h = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(out)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    try:
        assert h.stdout.readline().strip() == "HELD"
        with pytest.raises(w.LockedError) as ei:
            w.OutputLock(out).acquire()
        msg = str(ei.value)
        assert msg.startswith(f"another gravsurvey run holds {out} (pid {h.pid})")
        assert "\n" not in msg
        assert isinstance(ei.value, GravsurveyError) and ei.value.exit_code == 2
        t0 = time.monotonic()
        with pytest.raises(w.LockedError, match=r"after waiting 0\.5 s"):
            w.OutputLock(out, wait=True, timeout_s=0.5).acquire()
        assert 0.45 <= time.monotonic() - t0 < 3.0
        with pytest.raises(w.LockedError, match=r"after waiting 0\.2 s"):
            w.OutputLock(out, wait_s=0.2).acquire()
        with pytest.raises(w.LockedError, match=r"\(pid \d+\); wait for it"):
            w.OutputLock(out, wait_s=0).acquire()
    finally:
        h.kill()  # SIGKILL: the kernel drops the lock with the process
        h.wait(timeout=30)
    with w.OutputLock(out, wait=True, timeout_s=5.0) as lk:
        assert lk.held
        assert (out / ".gravsurvey.lock").read_text().strip() == str(os.getpid())
        with pytest.raises(w.LockedError):  # same process, second holder: refused too
            w.OutputLock(out).acquire()
    assert not lk.held


def test_lock_waiter_gets_it_when_holder_finishes(tmp_path):
    out = tmp_path / "out"
    h = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(out)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    assert h.stdout.readline().strip() == "HELD"
    h.stdin.write("go\n")
    h.stdin.flush()
    with w.OutputLock(out, wait=True, timeout_s=20.0) as lk:
        assert lk.held
    h.wait(timeout=30)
    assert h.returncode == 0


def test_metadata_in_csv_xyz_geojson(tmp_path):
    meta = {
        "survey": "S1",
        "crs": {"projected": "EPSG:32653 WGS 84 / UTM zone 53N", "projected_epsg": 32653},
        "software": "gravsurvey 9.9",
        "processing": {"model": {"a": 1.5}},
    }
    t = make_table()
    w.write_profiles_csv(tmp_path / "p.csv", t, metadata=meta)
    lines = (tmp_path / "p.csv").read_text().splitlines()
    assert lines[0] == "# survey: S1"
    assert lines[1].startswith("# crs: {") and "EPSG:32653" in lines[1]
    assert lines[4].startswith("flight,line,")
    back = w.read_profiles_csv(tmp_path / "p.csv")  # the reader skips the '#' lines
    np.testing.assert_allclose(back["levelled_mgal"], t["levelled_mgal"], atol=5e-5)
    w.write_xyz(tmp_path / "p.xyz", t, metadata=meta)
    x = w.read_xyz(tmp_path / "p.xyz")
    assert "survey: S1" in x.comments and "software: gravsurvey 9.9" in x.comments
    assert x.columns[0] == "time_unix_s"  # metadata lines do not disturb the column-name line
    w.write_geojson(tmp_path / "l.geojson", t, None, 32653, metadata=meta)
    gj = json.loads((tmp_path / "l.geojson").read_text())
    assert gj["metadata"]["processing"]["model"]["a"] == 1.5 and len(gj["features"]) == 2


def test_line_groups_linear_and_complete():
    f = np.array(["F1"] * 3 + ["F2"] * 4 + ["F1"] * 2, dtype=object)
    ln = np.array(["L1", "L1", "", "L1", "L1", "T1", "T1", "L2", "L2"], dtype=object)
    g = w.line_groups(f, ln)
    assert list(g) == [("F1", "L1"), ("F2", "L1"), ("F2", "T1"), ("F1", "L2")]
    assert g[("F2", "T1")].tolist() == [5, 6]
    # a pair in two separate runs gets both
    g2 = w.line_groups(np.array(["F"] * 5), np.array(["A", "A", "B", "A", "A"]))
    assert g2[("F", "A")].tolist() == [0, 1, 3, 4]
    # 20,000 lines of 50 rows: linear (well under a second; a per-line mask loop took minutes)
    n_lines, m = 20_000, 50
    ff = np.repeat(np.array([f"F{i // 20:03d}" for i in range(n_lines)], dtype=object), m)
    ll = np.repeat(np.array([f"L{i % 20:02d}" for i in range(n_lines)], dtype=object), m)
    t0 = time.perf_counter()
    g3 = w.line_groups(ff, ll)
    assert len(g3) == n_lines and time.perf_counter() - t0 < 5.0
