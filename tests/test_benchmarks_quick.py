"""The benchmark suite's --quick mode runs end to end (every stage works; no timings asserted).

Marked ``slow`` (15 minutes cold on 2 cores): left out of the default test run (README / CI)
by ``addopts`` in pyproject.toml; run it with ``python -m pytest -q -m slow``.
"""

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_benchmark_quick_runs_and_writes_well_formed_json(tmp_path):
    out = tmp_path / "results.json"
    p = subprocess.run(
        [sys.executable, str(REPO / "benchmarks" / "run.py"), "--quick", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=1200,
        check=False,
        cwd=str(tmp_path),
    )
    assert p.returncode == 0, f"benchmarks/run.py --quick exited {p.returncode}\n{p.stderr[-4000:]}"
    res = json.loads(out.read_text())
    assert res["quick"] is True
    assert res["errors"] == []
    for k in ("cpu", "cores", "python", "numpy", "numba", "git_commit"):
        assert k in res["machine"]

    # accuracy: every scenario has forward, smoother, the default post-processor and classic,
    # each with a finite RMS over a non-empty scored set
    rows = res["accuracy"]["rows"]
    scen = {r["scenario"] for r in rows}
    assert {"seed_smooth", "seed_steps", "survey_platform", "survey_strapdown"} <= scen
    for s in scen:
        got = {r["estimate"]: r for r in rows if r["scenario"] == s}
        for est in ("forward", "smoother", "classic"):
            assert est in got, (s, est)
        assert len(got) >= 5, (s, sorted(got))  # + at least the default and one baseline
        for r in got.values():
            assert r["rms_mgal"] is not None and math.isfinite(r["rms_mgal"]) and r["rms_mgal"] >= 0, r
            assert r["n_scored"] > 0, r
        assert got["classic"]["resolution_m"] > 0
    xo = res["accuracy"]["crossovers"]
    assert {r["scenario"] for r in xo} == {"survey_platform", "survey_strapdown"}
    assert all(r["count"] and r["count"] > 0 and r["rms_mgal"] is not None for r in xo)

    # speed: 10 and 100 Hz, every stage timed, memory measured
    speed = res["speed"]
    assert sorted(r["imu_hz"] for r in speed) == [10.0, 100.0]
    for r in speed:
        for k in ("ingest_s", "estimate_s", "postprocess_s", "outputs_s", "total_s", "s_per_flight_h", "max_rss_mb"):
            assert r[k] is not None and r[k] >= 0, (k, r)
    assert sorted(r["length_x"] for r in res["scaling"]) == [1, 4, 16]

    # per-stage peer benchmarks all ran
    for name in ("bench_ingest", "bench_inm", "bench_wavelet"):
        assert "error" not in res["stages"][name], res["stages"][name]
        assert res["stages"][name]["rows"], name

    # the Markdown table was printed
    assert "| scenario |" in p.stdout and "s per flight-hour" in p.stdout
