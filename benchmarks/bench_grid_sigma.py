#!/usr/bin/env python
"""The grid's sigma layer against the truth (docs/survey.md, "The grid's sigma").

Usage::

    python benchmarks/bench_grid_sigma.py [--suite DIR ...]

Prints, per simulated survey, the grid's error against the truth field (RMS over the filled
cells after the mean error is removed: the sigma is about the survey's level), the sigma's RMS,
and error/sigma RMS (1 for a right sigma), with the sigma midway between lines over that on them:

- 18 surveys over random fields (``tests/levelling_truth.random_field_survey``: 120 point
  masses 0.5-4 km deep; 8 lines 2, 3 or 4 km apart and 3 ties; 0.2 mGal errors, white, or
  correlated over 3 km along the lines for the 3-km layout), seeds 0-5, stated errors given;
- the three-mass survey of tests/test_grid.py (lines at 600, 1000, 1400 m), seeds 2-4, without
  and with the stated 0.2 mGal.

``--suite DIR ...``: output folders of processed simulated flights (``profiles.csv`` with
``truth_mgal``, and ``summary.json``; e.g. the unseen suite's ``*/out_default`` that
``benchmarks/bench_unseen.py`` writes). Each flight's lines are gridded again from its levelled
profiles with their stated ``sigma_mgal`` and resolution (as ``gravsurvey run`` does), and
error/sigma is taken at the line samples against the truth there; with three or more lines,
each line is also held out in turn and the grid of the others compared with the truth on it
(where the grid reaches it). Prints per flight and the distribution.
"""

from __future__ import annotations

import glob
import json
import sys
import warnings
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
for p in (REPO, REPO / "tests"):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))

from gravsurvey.grid import grid_lines  # noqa: E402
from levelling_truth import random_field_survey, simulated_survey, truth_field_mgal  # noqa: E402


def _cells_against(g, field, e, n, spacing_m):
    """error RMS, sigma RMS, error/sigma RMS over the filled cells, sigma far / near lines."""
    from scipy.spatial import cKDTree

    GE, GN = np.meshgrid(g.easting_m, g.northing_m)
    ok = np.isfinite(g.value_mgal)
    err = g.value_mgal[ok] - field(GE[ok], GN[ok], g.altitude_m)
    err -= err.mean()
    s = g.sigma_mgal[ok]
    d = cKDTree(np.column_stack([e, n])).query(np.column_stack([GE[ok], GN[ok]]))[0]
    ratio = float(np.median(s[d > 0.35 * spacing_m]) / np.median(s[d < 0.15 * spacing_m]))
    return (
        float(np.sqrt(np.mean(err**2))),
        float(np.sqrt(np.mean(s**2))),
        float(np.sqrt(np.mean((err / s) ** 2))),
        ratio,
    )


def synthetic() -> None:
    print("| survey | error RMS, mGal | sigma RMS, mGal | error/sigma RMS | sigma far/near lines |")
    print("|---|---|---|---|---|")
    zs = []
    for seed in range(6):
        for spacing, ell in ((2000.0, 0.0), (4000.0, 0.0), (3000.0, 3000.0)):
            e, n, h, v, lab, field = random_field_survey(seed, spacing, noise_length_m=ell)
            g = grid_lines(e, n, h, v, lab, sigma_mgal=np.full(e.size, 0.2), noise_length_m=ell or None)
            er, sr, z, ratio = _cells_against(g, field, e, n, spacing)
            zs.append(z)
            kind = f"random field, seed {seed}, lines {spacing / 1e3:.0f} km, errors " + (
                f"correlated {ell / 1e3:.0f} km" if ell else "white"
            )
            print(f"| {kind} | {er:.3f} | {sr:.3f} | {z:.2f} | {ratio:.2f} |")
    for seed in (2, 3, 4):
        lines, _ = simulated_survey(seed=seed, altitudes={"F1": 600.0, "F2": 1400.0, "F3": 1000.0})
        rng = np.random.default_rng(seed)
        cat = lambda k: np.concatenate([ln[k] for ln in lines])  # noqa: E731
        e, n, h = cat("easting_m"), cat("northing_m"), cat("height_m")
        v = cat("truth_mgal") + rng.normal(0, 0.2, e.size)
        lab = np.concatenate([np.full(ln["time_s"].size, f"{ln['flight']}/{ln['line']}") for ln in lines])
        for stated in (None, 0.2):
            g = grid_lines(e, n, h, v, lab, sigma_mgal=None if stated is None else np.full(e.size, stated))
            er, sr, z, ratio = _cells_against(g, truth_field_mgal, e, n, 2000.0)
            kind = f"three masses, seed {seed}, " + ("no stated errors" if stated is None else "stated 0.2 mGal")
            print(f"| {kind} | {er:.3f} | {sr:.3f} | {z:.2f} | {ratio:.2f} |")
    print(f"\nrandom fields: error/sigma RMS {min(zs):.2f}-{max(zs):.2f}, median {np.median(zs):.2f}")


def _flight_lines(out: Path):
    import pandas as pd

    t = pd.read_csv(out / "profiles.csv", comment="#")
    summary = json.loads((out / "summary.json").read_text())
    kind, res = {}, {}
    for fl, f in summary["flights"].items():
        for ln, st in f["lines"].items():
            kind[(fl, ln)] = st.get("kind", "line")
            res[(fl, ln)] = st.get("resolution_m") or 0.0
    t = t[t["line"].notna() & np.isfinite(t["levelled_mgal"]) & np.isfinite(t["truth_mgal"])]
    t = t[[kind.get((a, b), "line") in ("line", "tie") for a, b in zip(t["flight"], t["line"])]]
    lab = (t["flight"] + "/" + t["line"]).to_numpy()
    ell = np.array([res[(a, b)] for a, b in zip(t["flight"], t["line"])], float)
    return t, lab, ell


def _grid_at(t, lab, ell, fit, at):
    from scipy.interpolate import RegularGridInterpolator

    g = grid_lines(
        t["easting_m"].to_numpy()[fit],
        t["northing_m"].to_numpy()[fit],
        t["height_m"].to_numpy()[fit],
        t["levelled_mgal"].to_numpy()[fit],
        lab[fit],
        sigma_mgal=t["sigma_mgal"].to_numpy()[fit],
        noise_length_m=ell[fit],
    )
    pts = np.column_stack([t["northing_m"].to_numpy()[at], t["easting_m"].to_numpy()[at]])

    def ip(a):
        return RegularGridInterpolator((g.northing_m, g.easting_m), a, bounds_error=False, fill_value=np.nan)(pts)

    return ip(g.value_mgal) - t["truth_mgal"].to_numpy()[at], ip(g.sigma_mgal)


def suite(dirs) -> None:
    print("| flight | lines | error/sigma RMS at the lines | held out: error RMS, sigma RMS, error/sigma RMS |")
    print("|---|---|---|---|")
    z_all, z_out = [], []
    for d in dirs:
        d = Path(d)
        try:
            t, lab, ell = _flight_lines(d)
        except (OSError, KeyError, ValueError) as exc:
            print(f"| {d} | - | not read: {exc} | |")
            continue
        names = np.unique(lab)
        if names.size < 2:
            continue
        every = np.ones(lab.size, bool)
        err, s = _grid_at(t, lab, ell, every, every)
        ok = np.isfinite(err) & np.isfinite(s)
        mean_err = float(err[ok].mean())  # the level is relative: the sigma is about it
        z = float(np.sqrt(np.mean(((err[ok] - mean_err) / s[ok]) ** 2)))
        z_all.append(z)
        held = []
        if names.size >= 3:
            for nm in names:
                out = lab == nm
                try:
                    err, s = _grid_at(t, lab, ell, ~out, out)
                except Exception:  # noqa: BLE001 - a grid of the other lines may not exist
                    continue
                ok = np.isfinite(err) & np.isfinite(s)
                if ok.sum() >= 20:
                    e_ = err[ok] - mean_err
                    held.append((np.mean(e_**2), np.mean(s[ok] ** 2), np.mean((e_ / s[ok]) ** 2)))
        tail = ""
        if held:
            h = np.sqrt(np.mean(np.array(held), axis=0))
            z_out.append(float(h[2]))
            tail = f"{h[0]:.2f}, {h[1]:.2f}, {h[2]:.2f}"
        print(f"| {d.parent.name.split('_')[0]} | {names.size} | {z:.2f} | {tail} |", flush=True)
    for name, zs in (("at the lines", z_all), ("held-out lines", z_out)):
        if zs:
            zs = np.array(zs)
            inside = int(np.sum((zs >= 0.7) & (zs <= 1.5)))
            q = np.percentile(zs, [5, 25, 50, 75, 95])
            print(
                f"\n{name}: {zs.size} flights, error/sigma RMS in [0.7, 1.5] on {inside}, below {int((zs < 0.7).sum())}, "
                f"above {int((zs > 1.5).sum())}; 5/25/50/75/95 %: " + " / ".join(f"{x:.2f}" for x in q)
            )


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    warnings.simplefilter("ignore", RuntimeWarning)
    if "--suite" in argv:
        pats = argv[argv.index("--suite") + 1 :]
        dirs = sorted({p for pat in pats for p in glob.glob(pat)})
        suite(dirs)
    else:
        synthetic()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
