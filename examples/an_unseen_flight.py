"""A flight gravsurvey has never seen: drawn, simulated, processed with the defaults, scored.

The unseen-flight generator (:mod:`gravsurvey.simulate.unseen`, its own code: it shares nothing
with the estimator but the geodesy) draws a survey from wide ranges - a random field of point
masses, prisms and dipoles, sensor noise 0.3-3x the defaults, IMU, GNSS and height rates,
platform or strapdown, speed, altitude, heading, lines and turns - and simulates its logs with
the truth beside them.  The config it writes holds only what a user knows (file names, topics,
triad), so :func:`gravsurvey.pipeline.run_survey` identifies everything else from the flight.
This is what ``benchmarks/bench_unseen.py`` does for each row of its table (docs/benchmarks.md),
without the Wiener bound.

Run from the repository's root (``SEED`` any non-negative integer, a different flight each)::

    python examples/an_unseen_flight.py [SEED] [figure.png]

It prints the draw, the warnings, the resolution and the error against truth, and draws the
survey's lines in map coordinates coloured by the product beside one line's profile
(docs/examples.md).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

from gravsurvey.errors import GravsurveyError
from gravsurvey.io.writers.profiles_csv import read_profiles_csv
from gravsurvey.pipeline import run_survey
from gravsurvey.simulate.unseen import draw_flight_spec, limit_spec, spec_summary, write_flight

#: A short cut of the draw (the benchmark's ``--quick``): ~40 min, IMU at most 50 Hz.
MAX_DURATION_S = 2400.0
MAX_IMU_HZ = 50.0


def run(seed: int, work_dir) -> tuple[dict, dict, dict, list]:
    """Draw flight ``seed``, simulate it into ``work_dir`` and process it with the defaults.

    Returns
    -------
    spec : dict
        The draw (:func:`gravsurvey.simulate.unseen.draw_flight_spec`, cut short).
    table : dict
        The survey's profiles.csv, one array per column (``disturbance_mgal``, ``sigma_mgal``,
        ``truth_mgal``, ``line``, ``easting_m``, ``northing_m``, ...; docs/outputs.md).
    summary : dict
        The survey's summary.json (per line its resolution, the identified model, ...).
    notes : list of str
        The run's warnings.
    """
    spec = limit_spec(draw_flight_spec(seed), MAX_DURATION_S, MAX_IMU_HZ)
    survey = write_flight(spec, work_dir, oracle=False)
    result = run_survey(survey, output_dir=Path(work_dir) / "out", plots=False)
    if result.failed:
        raise RuntimeError(f"flight {spec['name']} failed: {result.failed[0]}")
    table = read_profiles_csv(Path(work_dir) / "out" / "profiles.csv")
    return spec, table, result.summary, list(result.notes)


def report(table: dict, summary: dict) -> dict:
    """Error of the final product against truth on the survey lines, about its mean (one
    flight's gravimeter bias is the ties' and levelling's), error/sigma, and the lines' median
    half-wavelength resolution."""
    err = np.asarray(table["disturbance_mgal"], float) - np.asarray(table["truth_mgal"], float)
    sig = np.asarray(table["sigma_mgal"], float)
    ok = np.isfinite(err) & np.isfinite(sig)
    e = err[ok] - np.mean(err[ok])
    return {
        "rms_vs_truth_mgal": float(np.sqrt(np.mean(e**2))),
        "field_std_mgal": float(np.std(np.asarray(table["truth_mgal"], float)[ok])),
        "error_over_sigma_rms": float(np.sqrt(np.mean((e / sig[ok]) ** 2))),
        "lines": len(set(np.asarray(table["line"])[ok].tolist())),
        "resolution_km": float(
            np.median([ln["resolution_m"] for fl in summary["flights"].values() for ln in fl["lines"].values()])
        )
        / 1000.0,
    }


def plot(spec: dict, table: dict, path) -> None:
    """The lines in map coordinates coloured by the product, and the longest line's profile."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    east = np.asarray(table["easting_m"], float) / 1000.0
    north = np.asarray(table["northing_m"], float) / 1000.0
    g = np.asarray(table["disturbance_mgal"], float)
    truth = np.asarray(table["truth_mgal"], float)
    sig = np.asarray(table["sigma_mgal"], float)
    line = np.asarray(table["line"])
    bias = float(np.nanmean(g - truth))
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True, width_ratios=(1, 1.6))
    sc = ax0.scatter(east, north, c=g - bias, s=2, cmap="viridis")
    fig.colorbar(sc, ax=ax0, label="disturbance, mGal (mean error removed)")
    ax0.set_aspect("equal")
    ax0.set_xlabel("easting, km")
    ax0.set_ylabel("northing, km")
    ax0.set_title(spec["name"] + f": {spec['triad']}, {spec['speed_mps']:.0f} m/s, {spec['altitude_m']:.0f} m")
    # the longest survey line (rows off the lines - turns, the static start - have no line name)
    on = (line != "") & np.isfinite(g)
    names, counts = np.unique(line[on], return_counts=True)
    k = on & (line == names[np.argmax(counts)])
    d = np.hypot(east[k] - east[k][0], north[k] - north[k][0])
    ax1.fill_between(
        d, g[k] - bias - sig[k], g[k] - bias + sig[k], color="tab:blue", alpha=0.25, lw=0, label="1-sigma stated"
    )
    ax1.plot(d, g[k] - bias, color="tab:blue", lw=1.2, label="final product")
    ax1.plot(d, truth[k], color="k", lw=0.9, ls="--", label="truth")
    ax1.set_xlabel(f"distance along line {names[np.argmax(counts)]}, km")
    ax1.set_ylabel("gravity disturbance, mGal")
    ax1.legend(loc="best", fontsize=8)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> dict:
    argv = sys.argv[1:] if argv is None else argv
    if argv and not (argv[0].isascii() and argv[0].isdigit()):
        raise ValueError(f"SEED: expected a non-negative integer, got {argv[0]!r}")
    seed = int(argv[0]) if argv else 2017
    path = Path(argv[1]) if len(argv) > 1 else Path(f"unseen_{seed}.png")
    with tempfile.TemporaryDirectory() as tmp:
        spec, table, summary, notes = run(seed, tmp)
    print(spec_summary(spec))
    for n in notes:
        print("warning:", n)
    facts = report(table, summary)
    for k, v in facts.items():
        print(f"{k:>22s}: {v:.3f}" if isinstance(v, float) else f"{k:>22s}: {v}")
    plot(spec, table, path)
    print(f"{'figure':>22s}: {path}")
    return facts


if __name__ == "__main__":
    try:
        main()
    except (GravsurveyError, RuntimeError, ValueError) as exc:
        # a config, data or argument problem: one line, as the CLI would say it
        sys.exit(f"{Path(__file__).name}: {exc}")
