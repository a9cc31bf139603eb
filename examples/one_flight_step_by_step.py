"""One flight, stage by stage, from Python.

What ``gravsurvey run`` does for a flight, called one stage at a time as a notebook user would:
read the logs into a :class:`~gravsurvey.io.record.FlightRecord`, take the initial state from
the data, estimate the gravity disturbance with the 3D-INM Kalman filter and RTS smoother (the
noise levels and the anomaly prior identified from the flight itself), turn the solution into
the per-flight :class:`~gravsurvey.estimate.FlightEstimate`, and set it against the simulator's
truth.  The sample is flight F01 of ``sample_data/grid_ros2`` (a strapdown IMU, GNSS and a
GNSS-grade height channel in a ROS 2 MCAP bag, over point masses and a dipole; the attitude found
by alignment).  The pipeline goes on from here to the drift from the lines, the survey lines,
crossovers, levelling and grids (``gravsurvey.pipeline``).

Run from the repository's root::

    python examples/one_flight_step_by_step.py [figure.png]

It prints the identified model, the resolution and the error against truth, and draws the
profile with its stated 1-sigma band (docs/examples.md).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from gravsurvey.config import load_config
from gravsurvey.errors import GravsurveyError
from gravsurvey.estimate import from_inm_solution
from gravsurvey.inm.params import resolve_initial_state
from gravsurvey.inm.solve import estimate_anomaly
from gravsurvey.io.ingest import load_flight
from gravsurvey.truth import read_truth_csv, truth_at

REPO = Path(__file__).resolve().parents[1]
SURVEY = REPO / "sample_data" / "grid_ros2" / "survey.yaml"
#: m/s^2 per mGal
MGAL = 1e-5


def run(survey=SURVEY):
    """The flight's estimate and its truth.

    Returns
    -------
    est : FlightEstimate
        The smoothed estimate at every filter epoch (``est.time`` s from ``est.t0_unix_ns``,
        ``est.disturbance`` and ``est.sigma`` m/s^2, ``est.resolution_m`` m).
    truth_mgal : ndarray, shape (N,)
        The simulator's disturbance at the same epochs, mGal (NaN outside its span).
    """
    cfg = load_config(survey)
    flight = cfg.flights[0]
    if flight.truth is None:
        # the example sets the estimate against a reference: a survey without one says so
        raise ValueError(f"{survey}: flights[0] has no truth file (key truth) to compare with")
    # files -> FlightRecord: SI units, checked, times strictly increasing
    record = load_flight(flight.ingest, cfg.base_dir)
    # position and velocity from a GNSS fit, a strapdown triad's attitude from alignment
    initial = resolve_initial_state(record, flight.triad, cfg.model, cfg.ellipsoid)
    # the Kalman/RTS estimate; cfg.model holds the defaults: everything identified from the data
    sol = estimate_anomaly(record, cfg.model, initial, flight.triad, cfg.ellipsoid)
    est = from_inm_solution(sol, name=flight.name, t0_unix_ns=record.t0_unix_ns)
    truth = read_truth_csv(flight.truth)
    unix_ns = est.t0_unix_ns + np.round(est.time * 1e9).astype(np.int64)
    return est, truth_at(truth, unix_ns)


def report(est, truth_mgal) -> dict:
    """The figures the example prints: identified model, resolution, error against truth."""
    ident = est.estimator.get("identification", {})
    err = est.disturbance / MGAL - truth_mgal
    ok = np.isfinite(err)
    # a gravimeter's constant bias is not observable from one flight: scored about the mean
    e = err[ok] - np.mean(err[ok])
    return {
        "anomaly_sigma_mgal": ident["anomaly_sigma_mps2"]["value"] / MGAL,
        "anomaly_length_km": 1e-3 / ident["anomaly_lambda_per_m"]["value"],
        "altimeter_sigma_m": ident["altimeter_sigma_m"]["value"],
        "resolution_km": est.resolution_m / 1000.0,
        "rms_vs_truth_mgal": float(np.sqrt(np.mean(e**2))),
        "median_sigma_mgal": float(np.median(est.sigma[ok]) / MGAL),
    }


def plot(est, truth_mgal, path) -> None:
    """The profile, its 1-sigma band and the truth against time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t_min = est.time / 60.0
    g = est.disturbance / MGAL
    s = est.sigma / MGAL
    ok = np.isfinite(truth_mgal)
    # the bias: the flight's mean error, which one flight cannot see (levelling ties it)
    bias = float(np.mean(g[ok] - truth_mgal[ok]))
    fig, ax = plt.subplots(figsize=(9, 3.6), constrained_layout=True)
    ax.fill_between(t_min, g - bias - s, g - bias + s, color="tab:blue", alpha=0.25, lw=0, label="1-sigma stated")
    ax.plot(t_min, g - bias, color="tab:blue", lw=1.2, label="estimate (its mean error removed)")
    ax.plot(t_min, truth_mgal, color="k", lw=0.9, ls="--", label="truth")
    ax.set_xlabel("time since the first IMU sample, min")
    ax.set_ylabel("gravity disturbance, mGal")
    ax.set_title(f"{est.name}: smoothed 3D-INM estimate, resolution {est.resolution_m / 1000:.1f} km (half-wavelength)")
    ax.legend(loc="best", fontsize=8)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> dict:
    argv = sys.argv[1:] if argv is None else argv
    path = Path(argv[0]) if argv else Path("one_flight.png")
    est, truth_mgal = run()
    facts = report(est, truth_mgal)
    for k, v in facts.items():
        print(f"{k:>22s}: {v:.3f}")
    plot(est, truth_mgal, path)
    print(f"{'figure':>22s}: {path}")
    return facts


if __name__ == "__main__":
    try:
        main()
    except (GravsurveyError, RuntimeError, ValueError) as exc:
        # a config, data or argument problem: one line, as the CLI would say it
        sys.exit(f"{Path(__file__).name}: {exc}")
