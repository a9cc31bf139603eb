#!/usr/bin/env python
"""Crossovers and levelling against GMT x2sys (issue 15.3): the same tracks, exported as text.

Usage::

    python benchmarks/bench_levelling_gmt.py [--figures DIR]

Simulates a line survey with known truth (tests/levelling_truth.py: 3 flights, 8 lines, 4 tie
lines, per-flight offsets and drifts, 0.2 mGal white noise), finds the crossovers with
``gravsurvey.crossovers.find_crossovers`` and levels them with ``gravsurvey.levelling`` (constant
per line, unweighted, not robust: the model ``x2sys_solve -Ec`` fits), exports the lines with
``gravsurvey.levelling.write_gmt_tracks`` and runs ``gmt x2sys_init``, ``x2sys_cross -Il -Qe``,
``x2sys_list -Fnc`` and ``x2sys_solve -Ec``. Prints the largest differences of crossover
positions (m), crossover values (mGal) and per-line corrections (mGal). ``compare()`` is what
tests/test_levelling.py calls (skipped there when ``gmt`` is absent). ``--figures DIR`` also
runs the whole chain on the simulated survey (base ties from 10-min still readings with 1 mGal
noise, robust levelling with the tied flights as datum, equivalent-source grid) and writes the
figures of docs/survey.md (``levelling_example.png``, ``grid_example.png``) with the numbers
measured against the truth field.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
for p in (REPO, REPO / "tests"):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))

from gravsurvey.levelling import LevellingOptions, level_survey, write_gmt_tracks  # noqa: E402
from gravsurvey.crossovers import find_crossovers  # noqa: E402
from gravsurvey.settings import tie_config  # noqa: E402
from levelling_truth import simulated_survey  # noqa: E402


def gmt_available() -> bool:
    """True when a ``gmt`` executable with the x2sys supplement runs."""
    exe = shutil.which("gmt")
    if not exe:
        return False
    try:
        r = subprocess.run([exe, "x2sys_solve", "-"], capture_output=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return b"x2sys_solve" in (r.stdout + r.stderr)


def run_gmt(lines, workdir) -> dict:
    """Run GMT x2sys on the lines; return its crossovers and per-line constant corrections.

    Returns
    -------
    dict
        ``crossovers``: list of (track_1, track_2, x_m, y_m, value_diff_mgal);
        ``corrections``: track name (``<flight>_<line>``) -> correction, mGal.
    """
    work = Path(workdir)
    write_gmt_tracks(work, lines)
    env = dict(os.environ, X2SYS_HOME=str(work / "x2sys"))
    (work / "x2sys").mkdir(exist_ok=True)
    e = np.concatenate([ln["easting_m"] for ln in lines])
    n = np.concatenate([ln["northing_m"] for ln in lines])
    region = f"-R{e.min() - 1e3:.0f}/{e.max() + 1e3:.0f}/{n.min() - 1e3:.0f}/{n.max() + 1e3:.0f}"

    def gmt(*args, out=None):
        r = subprocess.run(["gmt", *args], cwd=work, env=env, capture_output=True, text=True, timeout=120)
        if r.returncode != 0:
            raise RuntimeError(f"gmt {' '.join(args)} failed: {r.stderr.strip()[:300]}")
        if out:
            (work / out).write_text(r.stdout)
        return r.stdout

    gmt("x2sys_init", "GS", "-Dgravsurvey.fmt", "-Egst", "-F", "-Ndc", "-Nsc", region, "-I1000")
    tracks = [f"{ln['flight']}_{ln['line']}.gst" for ln in lines]
    gmt("x2sys_cross", *tracks, "-TGS", "-Il", "-Qe", out="coe.txt")
    xo = []
    cur = None
    for row in (work / "coe.txt").read_text().splitlines():
        if row.startswith("#"):
            continue
        if row.startswith(">"):
            parts = row[1:].split()
            cur = (parts[0], parts[2])
            continue
        f = row.split()
        xo.append((cur[0], cur[1], float(f[0]), float(f[1]), float(f[10])))
    gmt("x2sys_list", "coe.txt", "-TGS", "-Cg", "-Fnc", out="list.txt")
    corr = {}
    for row in gmt("x2sys_solve", "list.txt", "-TGS", "-Cg", "-Ec").splitlines():
        f = row.split()
        if len(f) == 3 and not row.startswith("#"):
            corr[f[0]] = float(f[2])
    return {"crossovers": xo, "corrections": corr}


def compare(seed: int = 1) -> dict:
    """gravsurvey vs GMT on one simulated survey; largest absolute differences.

    Returns
    -------
    dict
        ``n_gravsurvey, n_gmt`` crossovers; ``max_position_m``, ``max_value_mgal`` over matched
        crossovers; ``max_correction_mgal`` over lines; ``rms_before_mgal``, ``rms_after_mgal``
        (gravsurvey) and ``rms_after_gmt_mgal`` (the same crossovers corrected with GMT's
        constants); ``corrections`` per line (gravsurvey, GMT).
    """
    lines, _ = simulated_survey(seed=seed, tie_tilt_deg=7.0)
    xo = find_crossovers(lines)
    lev = level_survey(xo, lines, LevellingOptions(model="constant", robust=False, sigma_floor_mgal=1.0))
    with tempfile.TemporaryDirectory(prefix="gravsurvey-gmt-") as tmp:
        g = run_gmt(lines, tmp)
    # key crossovers by the unordered pair of track names
    mine = {}
    for fa, la, fb, lb, e, n, d in zip(
        xo.flight_a, xo.line_a, xo.flight_b, xo.line_b, xo.easting_m, xo.northing_m, xo.diff_mgal
    ):
        mine[(f"{fa}_{la}", f"{fb}_{lb}")] = (float(e), float(n), float(d))
    dpos, dval = [], []
    for t1, t2, x, y, v in g["crossovers"]:
        if (t1, t2) in mine:
            e, n, d = mine[(t1, t2)]
        elif (t2, t1) in mine:
            e, n, d = mine[(t2, t1)]
            d = -d
        else:
            continue
        dpos.append(np.hypot(e - x, n - y))
        dval.append(abs(d - v))
    corr = {}
    for i, (f, ln) in enumerate(lev.line_keys):
        name = f"{f}_{ln}"
        corr[name] = (float(lev.constant_mgal[i]), g["corrections"].get(name, float("nan")))
    dcorr = [abs(a - b) for a, b in corr.values()]
    # GMT's constants applied to the same crossovers
    idx = {k: i for i, k in enumerate(f"{f}_{ln}" for f, ln in lev.line_keys)}
    gm = np.array([g["corrections"].get(k, np.nan) for k in idx])
    ia = np.array([idx[f"{f}_{ln}"] for f, ln in zip(xo.flight_a, xo.line_a)])
    ib = np.array([idx[f"{f}_{ln}"] for f, ln in zip(xo.flight_b, xo.line_b)])
    after_gmt = xo.diff_mgal - (gm[ia] - gm[ib])
    return {
        "n_gravsurvey": len(xo),
        "n_gmt": len(g["crossovers"]),
        "n_matched": len(dpos),
        "max_position_m": float(max(dpos)) if dpos else float("nan"),
        "max_value_mgal": float(max(dval)) if dval else float("nan"),
        "max_correction_mgal": float(np.nanmax(dcorr)) if dcorr else float("nan"),
        "rms_before_mgal": lev.before["rms_mgal"],
        "rms_after_mgal": lev.after["rms_mgal"],
        "rms_after_gmt_mgal": float(np.sqrt(np.nanmean(after_gmt**2))),
        "corrections": corr,
    }


def figures(directory) -> dict:
    """Ties -> levelling -> grid on the simulated survey; figures and truth errors (docs/survey.md)."""
    from gravsurvey.geodesy import MGAL, normal_gravity
    from gravsurvey.grid import grid_lines
    from gravsurvey.report import plot_grid_map, plot_levelling
    from gravsurvey.ties import tie_flight
    from levelling_truth import truth_field_mgal

    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    lines, flights = simulated_survey(seed=3, tie_tilt_deg=7.0, altitudes={"F1": 800.0, "F2": 800.0, "F3": 800.0})
    rng = np.random.default_rng(7)
    g_base, lat_b, h_b = 980_812.43, np.radians(47.0), 600.0
    dist_base = g_base - float(normal_gravity(np.array([lat_b]), np.array([h_b]))[0]) / MGAL
    ties = {}
    for f, (off, drift, t_end) in flights.items():
        tt = np.concatenate([np.arange(0, 600.0), np.arange(t_end - 600.0, t_end)])
        z = dist_base + off + drift * tt / 3600.0 + rng.normal(0, 1.0, tt.size)
        cfg = tie_config(
            {
                "base_gravity_mgal": g_base,
                "before": {"start_s": 0, "stop_s": 599},
                "after": {"start_s": float(t_end - 600), "stop_s": float(t_end)},
            }
        )
        ties[f] = tie_flight(cfg, tt, np.full(tt.size, lat_b), np.full(tt.size, h_b), z)
    raw_err = np.concatenate([ln["value_mgal"] - ln["truth_mgal"] for ln in lines])
    tied = [dict(ln, value_mgal=ln["value_mgal"] - ties[ln["flight"]].correction(ln["time_s"])) for ln in lines]
    tied_err = np.concatenate([ln["value_mgal"] - ln["truth_mgal"] for ln in tied])
    xo = find_crossovers(tied)
    lev = level_survey(xo, tied, LevellingOptions(), tied_flights=list(ties))
    lev_err = np.concatenate(
        [ln["value_mgal"] - lev.correction(ln["flight"], ln["line"], ln["time_s"]) - ln["truth_mgal"] for ln in tied]
    )
    plot_levelling(
        d / "levelling_example.png",
        lev,
        title="simulated survey: 3 flights, 8 lines, 4 ties; after base ties, tied flights as datum",
    )
    cat = lambda k, src: np.concatenate([ln[k] for ln in src])  # noqa: E731
    val = np.concatenate([ln["value_mgal"] - lev.correction(ln["flight"], ln["line"], ln["time_s"]) for ln in tied])
    lab = np.concatenate([np.full(ln["time_s"].size, f"{ln['flight']}/{ln['line']}") for ln in tied])
    g = grid_lines(cat("easting_m", tied), cat("northing_m", tied), cat("height_m", tied), val, lab)
    GE, GN = np.meshgrid(g.easting_m, g.northing_m)
    gerr = g.value_mgal - truth_field_mgal(GE, GN, g.altitude_m)
    # the grid's sigma is about the survey's level
    zrms = float(np.sqrt(np.nanmean(((gerr - np.nanmean(gerr)) / g.sigma_mgal) ** 2)))
    plot_grid_map(
        d / "grid_example.png",
        g.easting_m,
        g.northing_m,
        g.value_mgal,
        cat("easting_m", tied),
        cat("northing_m", tied),
        track_ids=lab,
        crs_label="local projected x/y (simulation)",
        title="simulated survey: tied, levelled, gridded by equivalent sources",
        note=f"{g.spacing_m:.0f} m cells at {g.altitude_m:.0f} m; CV RMS {g.cv_rms_mgal:.2f} mGal; "
        f"RMS vs truth {np.sqrt(np.nanmean(gerr**2)):.2f} mGal\n1-sigma (dashed) median "
        f"{np.nanmedian(g.sigma_mgal):.2f} mGal; (error - mean) / sigma RMS {zrms:.2f}",
        sigma_mgal=g.sigma_mgal,
    )
    return {
        "raw_mean_error_mgal": float(raw_err.mean()),
        "raw_std_error_mgal": float(raw_err.std()),
        "tied_mean_error_mgal": float(tied_err.mean()),
        "tied_std_error_mgal": float(tied_err.std()),
        "levelled_mean_error_mgal": float(lev_err.mean()),
        "levelled_std_error_mgal": float(lev_err.std()),
        "grid_error_over_sigma_rms": zrms,
        "crossover_rms_before_mgal": lev.before["rms_mgal"],
        "crossover_rms_after_mgal": lev.after["rms_mgal"],
        "drift_recovered_mgal_per_h": {f: t.drift_mgal_per_h for f, t in ties.items()},
        "drift_true_mgal_per_h": {f: v[1] for f, v in flights.items()},
        "grid_rms_vs_truth_mgal": float(np.sqrt(np.nanmean(gerr**2))),
        "grid_cv_rms_mgal": g.cv_rms_mgal,
        "grid_spacing_m": g.spacing_m,
        "grid_altitude_m": g.altitude_m,
    }


def main() -> int:
    if "--figures" in sys.argv:
        r = figures(sys.argv[sys.argv.index("--figures") + 1])
        for k, v in r.items():
            print(f"{k}: {v}")
    if not gmt_available():
        print("GMT (gmt x2sys_*) not found: install it (Debian: apt-get install gmt) to run this comparison")
        return 0
    ver = subprocess.run(["gmt", "--version"], capture_output=True, text=True).stdout.strip()
    r = compare()
    print(f"GMT {ver} x2sys vs gravsurvey, simulated survey (3 flights, 8 lines, 4 ties)\n")
    print("| quantity | value |\n|---|---|")
    print(f"| crossovers gravsurvey / GMT / matched | {r['n_gravsurvey']} / {r['n_gmt']} / {r['n_matched']} |")
    print(f"| max crossover position difference | {r['max_position_m']:.3g} m |")
    print(f"| max crossover value difference | {r['max_value_mgal']:.3g} mGal |")
    print(f"| max per-line correction difference (x2sys_solve -Ec) | {r['max_correction_mgal']:.3g} mGal |")
    print(
        f"| crossover RMS before / after gravsurvey / after GMT | {r['rms_before_mgal']:.3f} / "
        f"{r['rms_after_mgal']:.3f} / {r['rms_after_gmt_mgal']:.3f} mGal |"
    )
    print("\n| line | gravsurvey mGal | GMT mGal |\n|---|---|---|")
    for k, (a, b) in r["corrections"].items():
        print(f"| {k} | {a:.4f} | {b:.4f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
