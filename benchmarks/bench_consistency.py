"""Gaps, clocks and consistency on damaged copies of sample_data/markov_csv (docs/reliability.md).

Prints three tables:

1. IMU-GNSS time offset: true offset vs the cross-correlation estimate.
2. Aiding gaps (altimeter and GNSS both missing) bridged by the free INS + Markov model:
   smoothed sigma and error inside the gap vs outside.
3. Long gaps split into segments: RMS vs truth of the whole product.

Run: ``python benchmarks/bench_consistency.py`` (about a minute once the kernels are compiled).
"""

from __future__ import annotations

import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
import damage_csv as d

from gravsurvey.config import load_config
from gravsurvey.consistency import estimate_time_offset
from gravsurvey.io.ingest import load_flight
from gravsurvey.pipeline import process_flight


def _flight(prep, extra=""):
    tmp = Path(tempfile.mkdtemp(prefix="bench_consistency_"))
    try:
        cfg_path = d.copy_sample(tmp / "s", extra)
        prep(tmp / "s")
        cfg = load_config(cfg_path, output_dir=tmp / "out")
        fl = cfg.flights[0]
        return cfg, fl, load_flight(fl.ingest, cfg.base_dir), process_flight(cfg, fl)
    finally:
        shutil.rmtree(tmp)


def offsets():
    print("| true IMU offset, s | estimate, s | correlation |")
    print("|---|---|---|")
    for off in (-2.0, -0.3, -0.1, 0.0, 0.1, 0.3, 1.0, 5.0):
        tmp = Path(tempfile.mkdtemp())
        try:
            cfg_path = d.copy_sample(tmp / "s")
            d.shift_after(tmp / "s", -1, off, names=("imu",))
            cfg = load_config(cfg_path)
            rec = load_flight(cfg.flights[0].ingest, cfg.base_dir)
            est, c = estimate_time_offset(rec)
            print(f"| {off:+.1f} | {est:+.3f} | {c:.3f} |")
        finally:
            shutil.rmtree(tmp)


def aiding_gaps():
    print(
        "| aiding gap, s | sigma outside, mGal | max sigma in gap, mGal | RMS error outside | RMS error in gap, mGal |"
    )
    print("|---|---|---|---|---|")
    for gap in (0, 10, 30, 60, 120):
        a, b = 400.0, 400.0 + gap

        def prep(p, gap=gap, a=a, b=b):
            if gap:
                d.drop_between(p, "altimeter", a, b)
                d.drop_between(p, "gnss", a, b)

        _, _, _, r = _flight(prep, "checks: {max_aiding_gap_s: 130}\n")
        err = r.smoothed / 1e-5 - r.truth_mgal
        on = np.isfinite(err) & (r.time > 200) & (r.time < 760)
        ing = on & (r.time >= a) & (r.time <= b)
        out = on & ~((r.time >= a - 60) & (r.time <= b + 60))
        so = np.median(r.sigma[out]) / 1e-5
        si = np.max(r.sigma[ing]) / 1e-5 if ing.any() else float("nan")
        ei = np.sqrt(np.mean(err[ing] ** 2)) if ing.any() else float("nan")
        print(f"| {gap} | {so:.2f} | {si:.2f} | {np.sqrt(np.mean(err[out] ** 2)):.2f} | {ei:.2f} |")


def splits():
    print("| damage | segments | lines | RMS vs truth on lines, mGal |")
    print("|---|---|---|---|")
    cases = {
        "none": lambda p: None,
        "IMU gap 1.1 s (bridged)": lambda p: d.drop_between(p, "imu", 400, 401.05),
        "IMU gap 60 s": lambda p: d.drop_between(p, "imu", 400, 460),
        "all channels: 30 min gap": lambda p: d.shift_after(p, 480, 1800),
        "IMU clock restart at 600 s, 300 s back (placed)": lambda p: d.restart_clock(p, "imu", 600, 300),
        "IMU clock restarts twice (dropped)": lambda p: (
            d.restart_clock(p, "imu", 300, 100),
            d.restart_clock(p, "imu", 700, 200),
        ),
    }
    for name, prep in cases.items():
        _, _, _, r = _flight(prep)
        err = r.disturbance / 1e-5 - r.truth_mgal
        segs = [n.split("estimated ")[1].split(" of")[0] for n in r.notes if " segments: " in n]
        nseg = len(segs)
        print(
            f"| {name} | {segs[0] if nseg else 1} | {len(r.line_info)} | "
            f"{np.sqrt(np.nanmean(err[r.line != ''] ** 2)):.2f} |"
        )


if __name__ == "__main__":
    offsets()
    print()
    aiding_gaps()
    print()
    splits()
