#!/usr/bin/env python
"""What a flight's lines can tell of its gravimeter drift, without noise (issue 12's worst flights).

Usage::

    python benchmarks/bench_drift_lines.py --seeds 13,18,5,317 [--quick] [--cache DIR] [--json out.json]
    python benchmarks/bench_drift_lines.py --first-seed 0 --flights 20

For each drawn flight (``gravsurvey.simulate.unseen.draw_flight_spec``, cut as ``bench_unseen.py
--quick`` cuts it with ``--quick``; simulated into the same cache as ``bench_unseen.py``), the drift
stage's model (``gravsurvey.drift``) is given the *noise-free* truth: the true disturbance plus
the drawn gravimeter drift (bias + Gauss-Markov, ``gravsurvey.simulate.run.gravimeter_slow_error``)
at the truth file's epochs, averaged in blocks over the survey lines (truth.csv ``line`` ``L..``;
tie lines left out, as the stage leaves them) as the stage averages the smoothed estimate.  No sensor noise, no
smoother, no segmentation: only the question the stage asks of the lines.

Printed per flight:

* the *true model*: the field's hyperparameters (and the white term) as the model fits the true
  field alone (``fit_drift`` on the truth's blocks without drift) with the drawn drift's sigma
  and correlation time;
* the *fitted model*: ``fit_drift`` on the blocks of truth plus drift;
* ``LL fitted - true``: the blocks' log-likelihood at the fitted model's hyperparameters less at
  the true model's (``drift.log_likelihood``); positive: the lines prefer a model that is not
  the flight's;
* *drift left* over the scored epochs (on a line, >= 10 min from the ends, as ``bench_unseen``
  scores; RMS after the mean): the drawn drift itself (nothing taken off), less the fitted
  model's posterior mean, less the true model's (``drift.drift_posterior``).

Where the drift left with the true model is a large share of the drift, no estimator that
separates the drift by the lines can take it off, whatever its hyperparameters: that part of
the flight's error is information the flight does not hold (docs/benchmarks.md, "The worst
flights").  Timings are not measured.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))
if str(REPO / "benchmarks") not in sys.path:
    sys.path.insert(0, str(REPO / "benchmarks"))

from bench_unseen import (  # noqa: E402
    CACHE,
    QUICK_MAX_DURATION_S,
    QUICK_MAX_IMU_HZ,
    prepare_flight,
    rms_after_bias,
    scored_mask,
    seed_list,
)

from gravsurvey.drift import (  # noqa: E402
    DriftFit,
    block_length,
    drift_posterior,
    fit_drift,
    line_blocks,
    local_plane,
    log_likelihood,
)
from gravsurvey.geodesy import MGAL  # noqa: E402
from gravsurvey.simulate.run import gravimeter_slow_error  # noqa: E402
from gravsurvey.simulate.unseen import draw_flight_spec, limit_spec  # noqa: E402
from gravsurvey.truth import read_truth_csv  # noqa: E402


def line_labels(truth) -> np.ndarray:
    """The truth file's line label per epoch where it is a survey line (``L..``), else ``""``: the
    drift stage's lines (tie lines are left out of its fit, docs/method.md "Drift from the lines")."""
    return np.array([str(x) if str(x).startswith("L") else "" for x in truth["line"]], dtype=object)


def drift_information(truth, drift_mps2, drift_sigma_mps2: float, drift_tau_s: float) -> dict | None:
    """The drift stage's model given one flight's noise-free truth plus its drawn drift.

    Parameters
    ----------
    truth : dict
        :func:`gravsurvey.truth.read_truth_csv` of the flight's truth.csv (``time_ns``,
        ``lat_deg``, ``lon_deg``, ``line``, ``disturbance_mgal``).
    drift_mps2 : ndarray, shape (N,)
        The drawn gravimeter drift at the truth's epochs, m/s^2.
    drift_sigma_mps2, drift_tau_s : float
        The drawn drift's Gauss-Markov sigma (m/s^2) and correlation time (s).

    Returns
    -------
    dict or None
        ``lines``, ``true`` and ``fitted`` (each ``DriftFit.report()``), ``ll_fitted_minus_true``,
        and the drift left on the scored epochs, mGal: ``left_none``, ``left_fitted``,
        ``left_true``; None when the lines give too few blocks for the stage.
    """
    t_ns = np.asarray(truth["time_ns"], np.int64)
    t = (t_ns - t_ns[0]) / 1e9
    east, north = local_plane(np.radians(truth["lat_deg"]), np.radians(truth["lon_deg"]))
    field = np.asarray(truth["disturbance_mgal"], float) * MGAL
    labels = line_labels(truth)
    block = block_length(float(t[-1] - t[0]))
    alone, lines = line_blocks(t, east, north, field, labels, block)
    blocks, _ = line_blocks(t, east, north, field + drift_mps2, labels, block)
    f_alone = fit_drift(alone, lines)
    fitted = fit_drift(blocks, lines)
    if f_alone is None or fitted is None:
        return None
    true = DriftFit(
        field_sigma_mps2=f_alone.field_sigma_mps2,
        field_length_m=f_alone.field_length_m,
        drift_sigma_mps2=float(drift_sigma_mps2),
        drift_tau_s=float(drift_tau_s),
        white_mps2=f_alone.white_mps2,
        log_lr=float("nan"),
        blocks=fitted.blocks,
        lines=lines,
    )
    mask = scored_mask(t_ns, truth)

    def left(taken):
        return rms_after_bias(((drift_mps2 - taken) / MGAL)[mask])[0]

    return {
        "lines": lines,
        "true": true.report(),
        "fitted": fitted.report(),
        "ll_fitted_minus_true": log_likelihood(fitted, blocks) - log_likelihood(true, blocks),
        "left_none": left(0.0),
        "left_fitted": left(drift_posterior(fitted, blocks, t)[0]),
        "left_true": left(drift_posterior(true, blocks, t)[0]),
    }


def evaluate(seed: int, quick: bool, cache) -> dict:
    """One drawn flight: simulate it unless cached, then :func:`drift_information`."""
    spec = draw_flight_spec(seed)
    if quick:
        spec = limit_spec(spec, QUICK_MAX_DURATION_S, QUICK_MAX_IMU_HZ)
    folder = prepare_flight(spec, cache)
    truth = read_truth_csv(folder / "F01" / "truth.csv")
    t_ns, slow = gravimeter_slow_error(spec["sim"])
    drift = np.interp(truth["time_ns"].astype(float), t_ns.astype(float), slow)
    grv = spec["sim"]["flights"][0]["sensors"]["gravimeter"]
    out = drift_information(truth, drift, grv["markov_sigma_mps2"], 1.0 / grv["markov_lambda_per_s"])
    return {"name": spec["name"], "seed": seed, **(out or {"lines": None})}


def print_table(rows) -> None:
    print(
        "| flight | lines | true model: field mGal @ km, drift mGal @ s | fitted: field, drift | "
        "LL fitted - true | drift left, mGal: none / fitted / true model |"
    )
    print("|---|---|---|---|---|---|")
    for r in rows:
        if r.get("true") is None:
            print(f"| {r['name']} | {r['lines']} | too few blocks | | | |")
            continue
        a, b = r["true"], r["fitted"]
        print(
            f"| {r['name']} | {r['lines']} | {a['field_sigma_mgal']:.2f} @ {a['field_length_km']:.1f}, "
            f"{a['drift_sigma_mgal']:.2f} @ {a['drift_tau_s']:.0f} | {b['field_sigma_mgal']:.2f} @ "
            f"{b['field_length_km']:.1f}, {b['drift_sigma_mgal']:.2f} @ {b['drift_tau_s']:.0f} | "
            f"{r['ll_fitted_minus_true']:+.1f} | {r['left_none']:.2f} / {r['left_fitted']:.2f} / {r['left_true']:.2f} |"
        )
    done = [r for r in rows if r.get("true") is not None and r["left_none"] > 0]
    if done:
        share = [r["left_true"] / r["left_none"] for r in done]
        print(
            f"\ndrift left with the true model / drawn drift: median {statistics.median(share):.2f}, "
            f"range {min(share):.2f}-{max(share):.2f} over {len(done)} flights; "
            f"the lines prefer another model (LL fitted - true > 0) on "
            f"{sum(r['ll_fitted_minus_true'] > 0 for r in done)}"
        )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default=None, help="comma-separated seeds (instead of --first-seed/--flights)")
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--flights", type=int, default=20)
    ap.add_argument("--quick", action="store_true", help="each draw cut as bench_unseen.py --quick cuts it")
    ap.add_argument("--cache", default=str(CACHE), help="simulated flights (shared with bench_unseen.py)")
    ap.add_argument("--json", default=None, help="write the rows here")
    args = ap.parse_args(argv)
    try:
        seeds = seed_list(args.first_seed, args.flights, args.seeds)
    except ValueError as exc:
        ap.error(f"--seeds: {exc}")
    rows = [evaluate(s, args.quick, args.cache) for s in seeds]
    print_table(rows)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
