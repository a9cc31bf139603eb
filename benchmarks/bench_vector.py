"""Vector gravimetry (issue 16 item 1): horizontal disturbance accuracy with and without turns.

Flights: the sample survey's strapdown grid (configs/sample_grid_ros2.yaml: 3 lines of 8 km and
2 ties with turns, 600 m, 70 m/s, point masses and a dipole, turbulence) and one constant-
heading line of 20 min across the same field; sensors either the sample's own (0.5 m GNSS,
5e-4 m/s^2 accelerometers) or a navigation-grade IMU with PPK GNSS (0.05 m); the field as in
the sample or its masses x4.  The config holds only what a user knows (sensor figures,
``model.horizontal: true``), identification on.  Printed per run: RMS of the estimate against
the simulator's truth (north, east), the RMS of the stated sigma, the truth's own spread, the
median posterior/prior sigma ratio, the fraction of epochs marked observable, and the
vertical product's resolution.

Run: ``python benchmarks/bench_vector.py`` (about a minute after compilation).
"""

from __future__ import annotations

import copy
import sys
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gravsurvey.geodesy import MGAL  # noqa: E402
from gravsurvey.settings import inm_params  # noqa: E402
from gravsurvey.inm.solve import estimate_anomaly  # noqa: E402
from gravsurvey.inm.vector import resolution_filter  # noqa: E402
from gravsurvey.io.record import AltimeterChannel, FlightRecord, GnssChannel, ImuChannel  # noqa: E402
from gravsurvey.simulate.run import simulate_flight  # noqa: E402

NAV_SENSORS = {
    "accelerometer": {"white_sigma_mps2": 1e-4},
    "gyro": {"bias_degph": [0.002, -0.002, 0.001], "white_drift_degph": 0.001},
    "altimeter": {"sigma_m": 0.05},
    "gnss": {"horizontal_sigma_m": 0.05, "vertical_sigma_m": 0.1},
}
NAV_MODEL = {
    "gnss_horizontal_sigma_m": 0.05,
    "gnss_vertical_sigma_m": 0.1,
    "accel_noise_mps2": 1e-4,
    "gyro_drift_degph": 0.001,
    "gyro_bias_sigma_degph": 0.005,
}
SAMPLE_MODEL = {"gnss_horizontal_sigma_m": 0.5, "gnss_vertical_sigma_m": 1.0, "accel_noise_mps2": 5e-4}
LINE = {
    "kind": "line",
    "origin_lat_deg": 49.70,
    "origin_lon_deg": 8.045,
    "altitude_m": 600.0,
    "speed_mps": 70.0,
    "heading_deg": 0.0,
    "duration_s": 1100.0,
    "static_start_s": 60.0,
    "ramp_s": 40.0,
}


def run(plan: str, sensors: str, scale: float):
    cfg = yaml.safe_load((ROOT / "configs" / "sample_grid_ros2.yaml").read_text())
    f = cfg["flights"][0]
    model = dict(SAMPLE_MODEL)
    if sensors == "nav":
        grav = f["sensors"]["gravimeter"]
        f["sensors"] = copy.deepcopy(NAV_SENSORS)
        f["sensors"]["gravimeter"] = grav
        model = dict(NAV_MODEL)
    if plan == "line":
        f["plan"] = dict(LINE)
    for item in cfg["field"].get("point_masses", []) + cfg["field"].get("dipoles", []):
        item["mass_kg"] *= scale
    s = simulate_flight(cfg)
    g = GnssChannel(s.gnss_time, np.radians(s.gnss_lat_deg), np.radians(s.gnss_lon_deg), s.gnss_height)
    rec = FlightRecord(
        s.start_unix_ns,
        ImuChannel(s.imu_time, s.specific_force_t, s.angular_rate_t),
        AltimeterChannel(s.alt_time, s.alt_height),
        g,
        source="bench",
    )
    t0 = time.perf_counter()
    sol = estimate_anomaly(rec, inm_params(dict(model, horizontal=True)), None, "strapdown")
    dt = time.perf_counter() - t0
    truth = np.stack([np.interp(sol.time, s.truth["time"], s.truth[k]) for k in ("dg_north", "dg_east")], axis=1)
    err = sol.dg_horizontal - truth
    prior = sol.identification["horizontal_prior"]["sigma_mps2"]
    missed = sol.identification["horizontal_prior"]["field_sigma_missed_mps2"]
    v = float(np.median(sol.speed))
    g_true = np.interp(sol.time, s.truth["time"], s.truth["disturbance"])
    vert = estimate_anomaly(rec, inm_params(model), None, "strapdown")
    g_true14 = np.interp(vert.time, s.truth["time"], s.truth["disturbance"])
    vertical = (
        np.sqrt(np.mean((vert.g_smooth - g_true14) ** 2)) / MGAL,
        np.sqrt(np.mean((sol.g_smooth - g_true) ** 2)) / MGAL,
    )
    low = {
        res: np.sqrt(
            np.mean(
                (
                    resolution_filter(sol.dg_horizontal, sol.time, v, res * 1e3)
                    - resolution_filter(truth, sol.time, v, res * 1e3)
                )
                ** 2,
                axis=0,
            )
        )
        / MGAL
        for res in (10, 5)
    }
    return dict(
        low=low,
        vertical=vertical,
        rms=np.sqrt(np.mean(err**2, axis=0)) / MGAL,
        sigma=np.sqrt(np.mean(sol.dg_horizontal_sigma**2, axis=0)) / MGAL,
        truth=truth.std(axis=0) / MGAL,
        # the smoother's own sigma against the prior (the stated one adds the vertical's missed
        # field, vector.horizontal_outputs)
        ratio=float(np.median(np.sqrt(np.clip(sol.dg_horizontal_sigma**2 - missed**2, 0.0, None)) / prior)),
        observable=float(np.mean(sol.horizontal_observable)),
        corr=[float(np.corrcoef(sol.dg_horizontal[:, i], truth[:, i])[0, 1]) for i in range(2)],
        resolution_km=sol.resolution_m / 1000.0,
        seconds=dt,
    )


def main():
    print(
        "| flight | sensors | field | RMS N / E (mGal) | at 10 km | at 5 km | sigma N / E | truth std N / E | "
        "corr N / E | post/prior sigma | observable | vertical resolution (km) | vertical RMS 14 / 18 states | "
        "estimate (s) |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for plan in ("grid", "line"):
        for sensors in ("sample", "nav"):
            for scale in (1.0, 4.0):
                r = run(plan, sensors, scale)
                lo10, lo5 = r["low"][10], r["low"][5]
                print(
                    f"| {plan} | {sensors} | x{scale:g} | {r['rms'][0]:.2f} / {r['rms'][1]:.2f} | "
                    f"{lo10[0]:.2f} / {lo10[1]:.2f} | {lo5[0]:.2f} / {lo5[1]:.2f} | "
                    f"{r['sigma'][0]:.2f} / {r['sigma'][1]:.2f} | {r['truth'][0]:.2f} / {r['truth'][1]:.2f} | "
                    f"{r['corr'][0]:.2f} / {r['corr'][1]:.2f} | {r['ratio']:.2f} | {r['observable']:.2f} | "
                    f"{r['resolution_km']:.1f} | {r['vertical'][0]:.2f} / {r['vertical'][1]:.2f} | "
                    f"{r['seconds']:.1f} |",
                    flush=True,
                )


if __name__ == "__main__":
    main()
