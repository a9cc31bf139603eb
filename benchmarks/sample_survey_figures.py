"""The sample survey from raw files to the grid: figures and numbers of docs/survey.md.

Usage::

    python benchmarks/sample_survey_figures.py [--figures docs/img] [--out DIR]

Runs ``gravsurvey run sample_data/grid_ros2/survey.yaml`` (into ``--out``, default a temporary
directory), prints the levelling decision and statistics (overall and per line, before and
after), the error of the profiles against the simulator's truth before and after levelling,
and the grid against the truth at the line samples (the grid interpolated there; the lines are
flown at the grid altitude). With ``--figures DIR`` it copies the run's map and levelling plots
to ``DIR/sample_grid_map.png`` and ``DIR/sample_levelling.png``.
"""

from __future__ import annotations

import csv
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_data" / "grid_ros2"


def _rows(path: Path) -> list:
    with open(path, newline="") as fh:
        return list(csv.DictReader(ln for ln in fh if not ln.startswith("#")))


def _f(rows, key) -> np.ndarray:
    return np.array([float(r[key]) if r[key] not in ("",) else np.nan for r in rows])


def grid_at(grid_nc: Path, e: np.ndarray, n: np.ndarray, variable: str = "gravity_disturbance") -> np.ndarray:
    """The grid's ``variable`` bilinearly interpolated at (easting, northing), mGal; NaN outside
    or in empty cells."""
    import xarray as xr
    from scipy.interpolate import RegularGridInterpolator

    with xr.open_dataset(grid_nc) as ds:
        g = ds[variable].values.astype(float)
        ip = RegularGridInterpolator(
            (ds["northing"].values, ds["easting"].values), g, bounds_error=False, fill_value=np.nan
        )
    return ip(np.column_stack([n, e]))


def stats(err: np.ndarray) -> dict:
    err = err[np.isfinite(err)]
    return {
        "n": int(err.size),
        "mean_mgal": float(err.mean()),
        "std_mgal": float(err.std()),
        "rms_mgal": float(np.sqrt(np.mean(err**2))),
    }


def run(out: Path) -> dict:
    r = subprocess.run(
        [sys.executable, "-m", "gravsurvey", "run", str(SAMPLE / "survey.yaml"), "-o", str(out), "-q"],
        capture_output=True,
        text=True,
        check=False,
    )
    if r.returncode != 0:
        raise SystemExit(f"gravsurvey run failed ({r.returncode}): {r.stderr.strip()}")
    summary = json.loads((out / "summary.json").read_text())
    rows = [r for r in _rows(out / "profiles.csv") if r["line"]]
    truth = _f(rows, "truth_mgal")
    before = _f(rows, "disturbance_mgal") - truth
    after = _f(rows, "levelled_mgal") - truth
    res = {
        "levelling": summary["levelling"],
        "crossovers": summary["crossovers"],
        "grid": summary["grid"],
        "profiles_vs_truth": {"before_levelling": stats(before), "after_levelling": stats(after)},
        "per_line": {},
    }
    for fl, f in summary["flights"].items():
        for name, ln in f["lines"].items():
            sel = np.array([r["flight"] == fl and r["line"] == name for r in rows])
            res["per_line"][f"{fl}/{name}"] = {
                "kind": ln["kind"],
                "before": stats(before[sel]),
                "after": stats(after[sel]),
                "correction_mgal": (ln.get("levelling") or {}).get("constant_mgal"),
                "crossovers_before": ((ln.get("levelling") or {}).get("before") or {}).get("rms_mgal"),
                "crossovers_after": ((ln.get("levelling") or {}).get("after") or {}).get("rms_mgal"),
            }
    g = grid_at(out / "grid.nc", _f(rows, "easting_m"), _f(rows, "northing_m"))
    res["grid_vs_truth_at_lines"] = stats(g - truth)
    # the grid's sigma is about the survey's level (relative: no base ties): the mean error is out
    sg = grid_at(out / "grid.nc", _f(rows, "easting_m"), _f(rows, "northing_m"), "gravity_disturbance_sigma")
    ok = np.isfinite(g - truth) & np.isfinite(sg)
    z = (g - truth - np.mean((g - truth)[ok]))[ok] / sg[ok]
    res["grid_sigma_at_lines"] = {
        "rms_sigma_mgal": float(np.sqrt(np.mean(sg[ok] ** 2))),
        "error_over_sigma_rms": float(np.sqrt(np.mean(z**2))),
    }
    res["timings_s"] = {fl: f["timings_s"] for fl, f in summary["flights"].items()}
    return res


def main() -> int:
    args = sys.argv[1:]
    figs = Path(args[args.index("--figures") + 1]) if "--figures" in args else None
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(args[args.index("--out") + 1]) if "--out" in args else Path(tmp) / "out"
        res = run(out)
        if figs is not None:
            figs.mkdir(parents=True, exist_ok=True)
            shutil.copy(out / "grid_map.png", figs / "sample_grid_map.png")
            if (out / "levelling.png").exists():
                shutil.copy(out / "levelling.png", figs / "sample_levelling.png")
    lev = res["levelling"] or {}
    dec = lev.get("decision") or {}
    print(f"levelling: applied={dec.get('applied')} model={dec.get('model')} rule: {dec.get('rule')}")
    for t in dec.get("tried", []):
        print(
            f"  {t['model']}: {t['n_observations']} crossovers, {t['n_unknowns']} unknowns, "
            f"F = {t['f_statistic']:.3g}, p = {t['p_value']:.3g}"
        )
    if lev:
        print(
            f"  crossover RMS {lev['before']['rms_mgal']:.2f} -> {lev['after']['rms_mgal']:.2f} mGal "
            f"({lev['before']['count']} crossovers)"
        )
    print("profiles vs truth (mean / std / RMS, mGal):")
    for k, s in res["profiles_vs_truth"].items():
        print(f"  {k}: {s['mean_mgal']:+.2f} / {s['std_mgal']:.2f} / {s['rms_mgal']:.2f} (n={s['n']})")
    print("per line: kind, correction, crossover RMS before -> after, error RMS before -> after (mGal)")
    for k, v in res["per_line"].items():
        c = v["correction_mgal"]
        xb, xa = v["crossovers_before"], v["crossovers_after"]
        print(
            f"  {k:8s} {v['kind']:4s} {'' if c is None else f'{c:+.2f}':>6s} "
            f"{'' if xb is None else f'{xb:.2f}':>5s} -> {'' if xa is None else f'{xa:.2f}':>5s}   "
            f"{v['before']['rms_mgal']:.2f} -> {v['after']['rms_mgal']:.2f}"
        )
    g, s = res["grid"], res["grid_vs_truth_at_lines"]
    print(
        f"grid: {g['shape']} cells of {g['spacing_m']:.0f} m at {g['altitude_m']:.0f} m, CV RMS {g['cv_rms_mgal']:.2f} "
        f"mGal; vs truth at the line samples: mean {s['mean_mgal']:+.2f}, std {s['std_mgal']:.2f}, "
        f"RMS {s['rms_mgal']:.2f} mGal (n={s['n']})"
    )
    sg = res["grid_sigma_at_lines"]
    print(
        f"grid sigma at the line samples: RMS {sg['rms_sigma_mgal']:.2f} mGal; (error - mean) / sigma RMS "
        f"{sg['error_over_sigma_rms']:.2f}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
