#!/usr/bin/env python
"""RMS of the smoothed disturbance versus the initial attitude error (issue 13).

Usage::

    python benchmarks/bench_alignment.py [--quick]

Prints Markdown tables (docs/benchmarks.md, "Alignment").  ``run(quick) -> list[dict]`` returns
the rows.  One strapdown grid flight (3 lines of 25 km + turns at 70 m/s, 10 Hz IMU, gyro
biases up to 0.03 deg/h, 0.5 m GNSS at 5 Hz, seed_smooth anomaly; 22 min in flight from the
first sample, or 24 min with a 120 s static start) is simulated by ``gravsurvey.simulate``;
truth is the simulator's disturbance.  RMS after removing the mean error, over the epochs after
the exact-attitude run's heading has converged (``attitude_converge_s``), smoother output, no
post-processing.  Model: datasheet figures of the simulated accelerometer, gyro and GNSS; the
gravimeter and height noise and the anomaly prior identified from the flight (the default).

Rows:

* ``exact``: started from the simulator's true attitude (1 pass);
* ``given, off by X``: the attitude a user might type, off by X (heading and/or roll/pitch),
  processed by the linear filter with ``initial_attitude_sigma_deg`` = max(X, 0.05) and 1 or 5
  passes (this is what the run did before issue 13, with sigma 0.05 deg and 1 pass; a given
  attitude that far from the data is now a configuration error);
* ``no initial``: the attitude from the coarse alignment (default settings, 3 passes at most),
  with the triad mounted at several headings and tilts (the initial attitude is then anything
  in 0-360 deg heading and up to 5 deg roll/pitch).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from gravsurvey.errors import DataError
from gravsurvey.geodesy import MGAL
from gravsurvey.inm.alignment import attitude_from_mat_nb
from gravsurvey.inm.params import (
    InitialState,
    InmParams,
    mat_nb_from_attitude,
    resolve_initial_state,
)
from gravsurvey.inm.solve import estimate_anomaly
from gravsurvey.io.record import AltimeterChannel, FlightRecord, GnssChannel, ImuChannel
from gravsurvey.simulate.run import quick_sim, simulate_flight

SENSORS = {
    "accelerometer": {"white_sigma_mps2": 5.0e-4},
    "gravimeter": {"markov_sigma_mps2": 1.0e-6, "markov_lambda_per_s": 0.025, "white_sigma_mps2": 1.0e-4},
    "gyro": {"bias_degph": [0.03, -0.02, 0.01], "white_drift_degph": 0.005},
    "altimeter": {"sigma_m": 0.05},
    "gnss": {"horizontal_sigma_m": 0.5, "vertical_sigma_m": 1.0},
}


def _flight(static_s):
    plan = {
        "kind": "grid",
        "origin_lat_deg": 47.0,
        "origin_lon_deg": 11.0,
        "altitude_m": 800.0,
        "speed_mps": 70.0,
        "lines": {"count": 3, "spacing_m": 3000.0, "length_m": 25000.0, "heading_deg": 0.0},
        "static_start_s": static_s,
    }
    sim = quick_sim(
        plan=plan,
        triad="strapdown",
        noise=SENSORS,
        field="seed_smooth",
        gnss_hz=5.0,
        altimeter_hz=5.0,
        seed=3,
        turbulence={"vertical_sigma_m": 1.0, "horizontal_sigma_m": 1.0, "attitude_sigma_deg": 0.5},
    )
    return simulate_flight(sim)


def rotation_deg(roll, pitch, heading):
    """The rotation that turns a level, north-pointing FLU frame to (roll, pitch, heading), deg."""
    return mat_nb_from_attitude(*np.radians([roll, pitch, heading])) @ mat_nb_from_attitude(0.0, 0.0, 0.0).T


def _params(**kw):
    # datasheet figures of the simulated accelerometer, gyro and GNSS; the gravimeter and height
    # noise and the anomaly prior are identified from the flight (the default)
    return InmParams(
        accel_noise_mps2=5e-4, gyro_drift_degph=0.005, gnss_horizontal_sigma_m=0.5, gnss_vertical_sigma_m=1.0, **kw
    )


def _record(s, mount):
    return FlightRecord(
        s.start_unix_ns,
        ImuChannel(s.imu_time, s.specific_force_t @ mount, s.angular_rate_t @ mount),
        AltimeterChannel(s.alt_time, s.alt_height),
        GnssChannel(s.gnss_time, np.radians(s.gnss_lat_deg), np.radians(s.gnss_lon_deg), s.gnss_height),
        source="sim",
    )


def _rms_after(sol, s, t_from):
    """RMS after removing the mean error (the gravimeter bias no flight separates), mGal."""
    keep = sol.time - sol.time[0] >= t_from
    g = np.interp(sol.time, s.truth["time"], s.truth["disturbance"])
    e = (sol.g_smooth - g)[keep]
    return float(np.sqrt(np.mean((e - e.mean()) ** 2))) / MGAL


def _attitude_inside(sol, s, mount):
    """Fraction of epochs after convergence with |attitude error| < 3 sigma, worst of roll/pitch/heading."""
    keep = sol.time - sol.time[0] >= sol.attitude_converge_s
    k = np.clip(np.searchsorted(s.truth["time"], sol.time), 0, s.truth["time"].size - 1)
    true_att = np.array([attitude_from_mat_nb(m @ mount) for m in s.truth["mat_nt"][k]])
    err = sol.attitude - true_att
    err[:, 2] = (err[:, 2] + math.pi) % (2 * math.pi) - math.pi
    return float((np.abs(err[keep]) < 3.0 * sol.attitude_sigma[keep]).mean(axis=0).min())


def run(quick=False) -> list[dict]:
    rows = []
    scenarios = [("in flight", 0.0)] if quick else [("in flight", 0.0), ("120 s static start", 120.0)]
    for label, static in scenarios:
        s = _flight(static)
        tr = s.truth
        eye = np.eye(3)
        ini = InitialState(tr["lat"][0], tr["lon"][0], tr["height"][0], tr["vel_n"][0].copy(), tr["mat_nt"][0].copy())
        exact = estimate_anomaly(_record(s, eye), _params(attitude_passes=1), ini, "strapdown")
        t_from = exact.attitude_converge_s
        base = _rms_after(exact, s, t_from)
        rows.append({"flight": label, "case": "exact attitude", "passes": 1, "rms_mgal": base, "t_from_s": t_from})
        errors = [(1.0, 0.0), (5.0, 0.0), (20.0, 0.0), (0.0, 3.0), (5.0, 5.0)]
        if not quick:
            errors += [(90.0, 0.0), (180.0, 0.0)]
        for dh, dl in errors:
            m = rotation_deg(dl, -dl, dh) @ tr["mat_nt"][0]
            given = InitialState(ini.lat, ini.lon, ini.height, ini.vel_n, m)
            for passes, sig in ((1, 0.05), (1, max(dh, dl, 0.05)), (5, max(dh, dl, 0.05))):
                try:
                    sol = estimate_anomaly(
                        _record(s, eye),
                        _params(attitude_passes=passes, initial_attitude_sigma_deg=sig),
                        given,
                        "strapdown",
                    )
                    rms = _rms_after(sol, s, t_from)
                except DataError:
                    rms = math.inf  # the navigation left the GNSS track
                rows.append(
                    {
                        "flight": label,
                        "case": f"given, heading off {dh:g} deg, roll/pitch off {dl:g} deg",
                        "passes": passes,
                        "sigma_deg": sig,
                        "rms_mgal": rms,
                        "t_from_s": t_from,
                    }
                )
        mounts = [(0.0, 0.0, 0.0), (5.0, -3.0, 90.0), (-4.0, 5.0, 180.0), (3.0, 4.0, 270.0)]
        if quick:
            mounts = mounts[:2]
        for mount_deg in mounts:
            mount = rotation_deg(*mount_deg)
            rec = _record(s, mount)
            ex_m = estimate_anomaly(
                rec,
                _params(attitude_passes=1),
                InitialState(ini.lat, ini.lon, ini.height, ini.vel_n, tr["mat_nt"][0] @ mount),
                "strapdown",
            )
            t0 = time.perf_counter()
            init = resolve_initial_state(rec, "strapdown", _params())
            sol = estimate_anomaly(rec, _params(), init, "strapdown")
            dt = time.perf_counter() - t0
            al = sol.alignment
            rows.append(
                {
                    "flight": label,
                    "case": f"no initial, triad mounted at roll/pitch/heading {mount_deg}",
                    "passes": sol.passes,
                    "rms_mgal": _rms_after(sol, s, sol.attitude_converge_s),
                    "exact_rms_mgal": _rms_after(ex_m, s, sol.attitude_converge_s),
                    "t_from_s": sol.attitude_converge_s,
                    "method": al.method,
                    "inside_3sigma": _attitude_inside(sol, s, mount),
                    "align_sigma_heading_deg": math.degrees(al.sigma_heading_rad),
                    "align_converge_s": al.converge_s,
                    "corrections_deg": [math.degrees(c) for c in sol.attitude_corrections],
                    "seconds": dt,
                }
            )
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args(argv)
    rows = run(a.quick)
    print("| flight | initial attitude | passes | sigma deg | RMS mGal | exact-attitude RMS | from s |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        extra = ""
        if "method" in r:
            extra = (
                f" ({r['method']}, heading sigma {r['align_sigma_heading_deg']:.3f} deg after "
                f"{r['align_converge_s']:.0f} s; corrections {', '.join(f'{c:.4f}' for c in r['corrections_deg'])} "
                f"deg; attitude inside 3 sigma on {100 * r['inside_3sigma']:.1f} % of epochs; {r['seconds']:.1f} s)"
            )
        sig = f"{r['sigma_deg']:g}" if "sigma_deg" in r else "alignment"
        exact = f"{r['exact_rms_mgal']:.3f}" if "exact_rms_mgal" in r else ""
        print(
            f"| {r['flight']} | {r['case']}{extra} | {r['passes']} | {sig} | {r['rms_mgal']:.3f} | {exact} | "
            f"{r['t_from_s']:.0f} |"
        )


if __name__ == "__main__":
    main()
