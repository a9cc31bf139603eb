"""Post-processors on the unseen-flight suite (issue 12 item 3): does any beat the smoothed estimate?

Runs each cached unseen flight (benchmarks/bench_unseen.py prepares them) with the default
configuration and ``postprocess.method`` set to each method in turn, and prints the RMS after
bias against truth on the scored line epochs (bench_unseen's scoring) and the stated resolution.

    python benchmarks/bench_postprocess_unseen.py [--quick] [--flights N] [--first-seed S] [--cache DIR]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_unseen import (
    CACHE,
    QUICK_MAX_DURATION_S,
    QUICK_MAX_IMU_HZ,
    median_resolution_km,
    truth_lines,
    prepare_flight,
    read_profiles,
    rms_after_bias,
    scored_mask,
)

from gravsurvey.pipeline import read_truth_csv, run_survey
from gravsurvey.simulate.unseen import draw_flight_spec, limit_spec

METHODS = ("none", "ti_cosphi", "cosphi", "sure")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flights", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=0, help="seed of the first flight (to split a run)")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--cache", type=Path, default=CACHE)
    a = ap.parse_args(argv)
    rows = []
    for seed in range(a.first_seed, a.first_seed + a.flights):
        spec = draw_flight_spec(seed)
        if a.quick:
            spec = limit_spec(spec, QUICK_MAX_DURATION_S, QUICK_MAX_IMU_HZ)
        folder = prepare_flight(spec, a.cache)
        truth = read_truth_csv(folder / "F01" / "truth.csv")
        truth["line"] = np.array(truth_lines(folder / "F01" / "truth.csv"), dtype=object)
        base = yaml.safe_load((folder / "survey.yaml").read_text())
        row = {"name": spec["name"]}
        for m in METHODS:
            cfg = dict(base, postprocess={"method": m}, output={"dir": f"out_pp_{m}", "plots": False})
            path = folder / f"pp_{m}.yaml"
            path.write_text(yaml.safe_dump(cfg))
            res = run_survey(path, force=True)
            if res.failed:
                row[m] = (None, None)
                continue
            p = read_profiles(folder / f"out_pp_{m}" / "profiles.csv")
            mask = scored_mask(p["time_unix_ns"], truth)
            rms, _ = rms_after_bias((p["disturbance_mgal"] - p["truth_mgal"])[mask])
            row[m] = (rms, median_resolution_km(res.summary))
        rows.append(row)
        print(row["name"], " ".join(f"{m} {_f(row[m][0])} @ {_f(row[m][1], 1)} km" for m in METHODS), flush=True)
    print()
    print("| flight | " + " | ".join(f"{m} RMS (res km)" for m in METHODS) + " |")
    print("|---|" + "---|" * len(METHODS))
    for r in rows:
        print(f"| {r['name']} | " + " | ".join(f"{_f(r[m][0])} ({_f(r[m][1], 1)})" for m in METHODS) + " |")
    for m in METHODS[1:]:
        better = [
            r["name"] for r in rows if r[m][0] is not None and r["none"][0] is not None and r[m][0] < r["none"][0]
        ]
        ratio = [r[m][0] / r["none"][0] for r in rows if r[m][0] and r["none"][0]]
        print(
            f"{m}: better than the smoothed estimate on {len(better)} of {len(rows)} flights; "
            f"median RMS ratio to it {np.median(ratio):.2f}, worst {np.max(ratio):.2f}"
        )


def _f(v, nd=2):
    return "-" if v is None else f"{v:.{nd}f}"


if __name__ == "__main__":
    main()
