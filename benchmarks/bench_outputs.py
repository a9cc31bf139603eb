#!/usr/bin/env python
"""Survey outputs vs survey size (issue 17.5): time of the output stage for F flights x 20 lines.

Usage::

    python benchmarks/bench_outputs.py [--quick] [--grid]

Builds synthetic processed flights (no estimation: the benchmark times only what runs after
the flights, ``pipeline.write_survey_outputs``): flight k flies 16 north-south lines of 40 km and 4
east-west tie lines over its own 48 x 40 km block (blocks side by side), at 80 m/s, 1 Hz, with
turns between lines; so the rows, lines and crossovers all grow in proportion to the flights.
Runs the output stage (profile table, crossovers, levelling, CSV, XYZ, GeoJSON, summary; plots
off; the grid only with ``--grid``) and prints a table: flights, lines, rows, crossovers,
seconds, microseconds per row. Linear scaling shows as a constant time per row.
Target (issue 17.5): 100 flights x 20 lines well under a minute.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from gravsurvey.config import SurveyConfig  # noqa: E402
from gravsurvey.geodesy import MGAL, WGS84  # noqa: E402
from gravsurvey.grid import GridOptions  # noqa: E402
from gravsurvey.levelling import LevellingOptions  # noqa: E402
from gravsurvey.estimate import FlightEstimate  # noqa: E402
from gravsurvey.pipeline import write_survey_outputs  # noqa: E402

R_EARTH = 6_371_000.0
LAT0, LON0 = np.radians(47.0), np.radians(11.0)


def synthetic_flight(k: int, n_main: int = 16, n_tie: int = 4, speed: float = 80.0, rng=None) -> FlightEstimate:
    """One processed flight over block k (see the module docstring)."""
    rng = rng or np.random.default_rng(k)
    bx, by = (k % 10) * 50_000.0, (k // 10) * 45_000.0
    legs = []
    for i in range(n_main):
        n = np.arange(0.0, 40_000.0, speed)
        legs.append((f"L{i + 1:02d}", "line", np.full(n.size, bx + 1000.0 + i * 3000.0), n if i % 2 == 0 else n[::-1]))
    for j in range(n_tie):
        e = np.arange(0.0, 47_000.0, speed)
        legs.append((f"T{j + 1:02d}", "tie", bx + e, np.full(e.size, 2000.0 + j * 12_000.0)))
    east, north, name = [], [], []
    for lname, _kind, e, n in legs:
        if east:  # a 60-s turn from the previous leg (straight interpolation, not a line)
            e0, n0 = east[-1][-1], north[-1][-1]
            f = np.linspace(0, 1, 62)[1:-1]
            east.append(e0 + f * (e[0] - e0))
            north.append(n0 + f * (n[0] - n0))
            name.append(np.full(f.size, "", dtype=object))
        east.append(e)
        north.append(n + by)
        name.append(np.full(e.size, lname, dtype=object))
    e = np.concatenate(east)
    n = np.concatenate(north)
    line = np.concatenate(name)
    m = e.size
    t = np.arange(m, dtype=float)
    lat = LAT0 + n / R_EARTH
    lon = LON0 + e / (R_EARTH * np.cos(LAT0))
    val = (5.0 * np.sin(e / 7000.0) * np.cos(n / 9000.0) + rng.normal(0, 0.3) + rng.normal(0, 0.5, m)) * MGAL
    final = np.where(line != "", val, np.nan)
    info = {
        ln: {"kind": kind, "method": "synthetic", "speed_mps": speed, "samples": int((line == ln).sum())}
        for ln, kind, _e, _n in legs
    }
    return FlightEstimate(
        name=f"F{k + 1:03d}",
        method="inm",
        t0_unix_ns=1_700_000_000_000_000_000 + k * 86_400 * 10**9,
        time=t,
        lat=lat,
        lon=lon,
        height=np.full(m, 800.0),
        vel_n=np.zeros((m, 3)),
        speed=np.full(m, speed),
        heading=np.zeros(m),
        smoothed=val,
        forward=val,
        sigma=np.full(m, 0.5 * MGAL),
        disturbance=final,
        line=line,
        line_info=info,
    )


def run(sizes, grid: bool = False, repeats: int = 1):
    """Time the output stage for each number of flights (median of ``repeats``: wall, and CPU
    time of this process, which a shared machine's other load inflates much less); returns
    rows of a table."""
    out = []
    with tempfile.TemporaryDirectory(prefix="gravsurvey-bench-outputs-") as tmp:
        cfg_path = Path(tmp) / "survey.yaml"
        cfg_path.write_text("survey: {name: bench}\n")
        cfg = SurveyConfig(
            path=cfg_path,
            base_dir=Path(tmp),
            raw={"survey": {"name": "bench"}},
            name="bench",
            ellipsoid=WGS84,
            flights=[],
            model=None,
            lines=None,
            postprocess=None,
            plots=False,
            levelling=LevellingOptions(),
            grid=GridOptions(enabled=grid),
        )
        for nf in sizes:
            results = [synthetic_flight(k) for k in range(nf)]
            rows = sum(len(r.time) for r in results)
            walls, cpus = [], []
            for i in range(repeats):
                t0, c0 = time.perf_counter(), time.process_time()
                summary = write_survey_outputs(cfg, Path(tmp) / f"out{nf}_{i}", results)
                walls.append(time.perf_counter() - t0)
                cpus.append(time.process_time() - c0)
            wall, cpu = float(np.median(walls)), float(np.median(cpus))
            out.append(
                {
                    "flights": nf,
                    "lines": sum(len(r.line_info) for r in results),
                    "rows": rows,
                    "crossovers": summary["crossovers"]["count"],
                    "seconds": wall,
                    "cpu_seconds": cpu,
                    "us_per_row": wall / rows * 1e6,
                    "cpu_us_per_row": cpu / rows * 1e6,
                    "levelled": bool(summary.get("levelling") and summary["levelling"].get("applied")),
                }
            )
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="10, 20 and 40 flights only")
    ap.add_argument("--grid", action="store_true", help="include the equivalent-source grid")
    ap.add_argument("--sizes", help="comma-separated numbers of flights (overrides --quick)")
    a = ap.parse_args(argv)
    sizes = (10, 20, 40) if a.quick else (10, 25, 50, 100)
    if a.sizes:
        sizes = tuple(int(v) for v in a.sizes.split(","))
    rows = run(sizes, grid=a.grid)
    print("| flights | lines | rows | crossovers | levelled | output stage wall, s | CPU, s | CPU us per row |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['flights']} | {r['lines']} | {r['rows']:,} | {r['crossovers']} | {r['levelled']} | "
            f"{r['seconds']:.1f} | {r['cpu_seconds']:.1f} | {r['cpu_us_per_row']:.1f} |"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
