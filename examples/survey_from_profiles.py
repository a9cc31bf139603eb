"""Crossovers, levelling and a grid from a run's profiles, as functions over arrays.

``gravsurvey run`` writes ``profiles.csv`` (every epoch of every flight: position, product,
stated sigma, line name; docs/outputs.md) and goes on to the survey stage itself.  A user who
wants to level or grid the lines differently - other levelling options, another grid spacing,
a subset of flights - can call that stage on the table: :func:`gravsurvey.crossovers.find_crossovers`,
:func:`gravsurvey.levelling.choose_levelling` and :func:`gravsurvey.grid.grid_lines`.  The survey
here is ``sample_data/grid_ros2``: two strapdown flights with different gravimeter biases, F01's
lines north-south, F02's east-west across them.

Run from the repository's root::

    python examples/survey_from_profiles.py [figure.png]

It prints the crossover differences before and after levelling, the levelling model chosen and
the grid's cross-validated error, and draws the levelled grid with the lines and crossovers
(docs/examples.md).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

from gravsurvey.crossovers import find_crossovers
from gravsurvey.errors import GravsurveyError
from gravsurvey.grid import grid_lines
from gravsurvey.io.writers import line_groups
from gravsurvey.io.writers.profiles_csv import read_profiles_csv
from gravsurvey.levelling import choose_levelling
from gravsurvey.pipeline import run_survey

REPO = Path(__file__).resolve().parents[1]
SURVEY = REPO / "sample_data" / "grid_ros2" / "survey.yaml"


def survey_lines(table: dict) -> list[dict]:
    """One dict per survey line of a profiles table, as the survey-stage functions take them.

    ``time_s`` is each flight's own time base (s from its first epoch): the levelling's trends
    and the crossovers' same-flight test run on it.
    """
    flight = np.asarray(table["flight"]).astype(str)
    t_ns = np.asarray(table["time_unix_ns"], np.int64)
    t0 = {f: t_ns[flight == f].min() for f in dict.fromkeys(flight)}
    columns = {
        "easting_m": "easting_m",
        "northing_m": "northing_m",
        "height_m": "height_m",
        "value_mgal": "disturbance_mgal",
        "sigma_mgal": "sigma_mgal",
    }
    values = {k: np.asarray(table[c], float) for k, c in columns.items()}
    # a survey without a truth file has no truth column: NaN, and no score against it
    values["truth_mgal"] = (
        np.asarray(table["truth_mgal"], float) if "truth_mgal" in table else np.full(t_ns.size, np.nan)
    )
    out = []
    # each line's rows, the way the run itself groups them (empty line names - turns - skipped)
    for (f, ln), k in line_groups(table["flight"], table["line"]).items():
        out.append({"flight": f, "line": ln, **{c: v[k] for c, v in values.items()}, "time_s": (t_ns[k] - t0[f]) / 1e9})
    return out


def run(survey=SURVEY, work_dir=None):
    """Process the survey, then its crossovers, levelling and grid from the profiles.

    Returns
    -------
    lines : list of dict
        :func:`survey_lines` of the run's profiles.csv, each with ``levelled_mgal`` added.
    xo : Crossovers
    lev : Levelling or None
        ``lev.decision["applied"]`` says whether the crossovers showed level errors beyond
        their noise (otherwise the lines keep their values).
    grid : GridResult
    """
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(work_dir or tmp) / "out"
        result = run_survey(survey, output_dir=out, plots=False)
        if result.failed:
            raise RuntimeError(f"{survey}: {result.failed[0]}")
        lines = survey_lines(read_profiles_csv(out / "profiles.csv"))
    xo = find_crossovers(
        [{k: ln[k] for k in ("flight", "line", "easting_m", "northing_m", "value_mgal", "time_s")} for ln in lines]
    )
    lev = choose_levelling(xo, lines)
    applied = lev is not None and lev.decision["applied"]
    for ln in lines:
        corr = lev.correction(ln["flight"], ln["line"], ln["time_s"]) if applied else 0.0
        ln["levelled_mgal"] = ln["value_mgal"] - corr
    cat = {
        k: np.concatenate([ln[k] for ln in lines])
        for k in ("easting_m", "northing_m", "height_m", "levelled_mgal", "sigma_mgal")
    }
    label = np.concatenate([np.full(ln["time_s"].size, f"{ln['flight']}/{ln['line']}") for ln in lines])
    grid = grid_lines(
        cat["easting_m"], cat["northing_m"], cat["height_m"], cat["levelled_mgal"], label, sigma_mgal=cat["sigma_mgal"]
    )
    return lines, xo, lev, grid


def report(lines, xo, lev, grid) -> dict:
    """Crossover RMS before and after levelling, the levelled lines against truth (about the
    survey's mean: no base tie; only where there is a truth), and the grid's cross-validated RMS."""
    err = np.concatenate([ln["levelled_mgal"] - ln["truth_mgal"] for ln in lines])
    raw = np.concatenate([ln["value_mgal"] - ln["truth_mgal"] for ln in lines])
    ok = np.isfinite(err) & np.isfinite(raw)
    applied = lev is not None and lev.decision["applied"]
    facts = {
        "crossovers": int(xo.count),
        "crossover_rms_mgal": float(xo.rms_mgal),
        "levelled_crossover_rms_mgal": float(lev.after["rms_mgal"]) if applied else float(xo.rms_mgal),
        "levelling_model": lev.decision["model"] if applied else "none",
        "grid_cv_rms_mgal": float(grid.cv_rms_mgal),
    }
    if ok.any():
        facts["rms_vs_truth_mgal"] = float(np.sqrt(np.mean((raw[ok] - raw[ok].mean()) ** 2)))
        facts["levelled_rms_vs_truth_mgal"] = float(np.sqrt(np.mean((err[ok] - err[ok].mean()) ** 2)))
    return facts


def plot(lines, xo, grid, path) -> None:
    """The levelled grid, the lines and the crossovers."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 5.4), constrained_layout=True)
    km = 1e-3
    mesh = ax.pcolormesh(grid.easting_m * km, grid.northing_m * km, grid.value_mgal, shading="nearest", cmap="viridis")
    fig.colorbar(mesh, ax=ax, label="levelled disturbance, mGal (relative level)")
    for ln in lines:
        ax.plot(ln["easting_m"] * km, ln["northing_m"] * km, color="w", lw=0.8)
    ok = xo.valid
    ax.plot(xo.easting_m[ok] * km, xo.northing_m[ok] * km, "o", mfc="none", mec="r", ms=6, label="crossovers")
    ax.set_aspect("equal")
    ax.set_xlabel("easting, km")
    ax.set_ylabel("northing, km")
    ax.set_title(
        f"sample survey grid_ros2: {len(lines)} lines, {int(xo.count)} crossovers, {grid.spacing_m:.0f}-m grid"
    )
    ax.legend(loc="upper right", fontsize=8)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> dict:
    argv = sys.argv[1:] if argv is None else argv
    path = Path(argv[0]) if argv else Path("survey_from_profiles.png")
    lines, xo, lev, grid = run()
    facts = report(lines, xo, lev, grid)
    for k, v in facts.items():
        print(f"{k:>28s}: {v:.3f}" if isinstance(v, float) else f"{k:>28s}: {v}")
    plot(lines, xo, grid, path)
    print(f"{'figure':>28s}: {path}")
    return facts


if __name__ == "__main__":
    try:
        main()
    except (GravsurveyError, RuntimeError, ValueError) as exc:
        # a config, data or argument problem: one line, as the CLI would say it
        sys.exit(f"{Path(__file__).name}: {exc}")
