#!/usr/bin/env python
"""What a gravity-gradient channel buys (issue 16 item 4, seed 000), measured on simulated flights.

Usage::

    python benchmarks/bench_gradiometer.py [--quick] [--seed N]

Prints Markdown tables (docs/benchmarks.md, "Gradiometer-aided navigation").  For each gradient
noise level (white, E/sqrt(Hz); 0 = the exact tensor) on a simulated flight over a rugged
field of random point masses and prisms (a new random field per ``--seed``):

1. **Gravity by dg/dt = T V**: the gravitation propagated from the measured tensor (platform
   triad = ENU, true velocity, gravity known at the start) against the simulator's truth:
   RMS and final error of the anomalous vertical and horizontal components, mGal.  "Without"
   = a normal-field model (error = the anomaly itself).
2. **The eigen-vertical** (seed eq. 2.1): angle between the measured tensor's eigenvector
   (corrected by the normal field's known eigenvector-vs-gravitation offset) and the true
   gravitation direction, arcsec, and the horizontal acceleration error it causes, mGal.
   "Without" = the conventional INS vertical of a normal-field model (error = the deflection).
3. **Free-inertial horizontal position error** after 10 min and at the end driven by that vertical
   error alone (perfect accelerometers and attitude): conventional Schuler channel vs the
   seed's gradiometer channel (double integrator).
4. **GNSS-aided channel** (1 Hz positions, 3 m): RMS position and acceleration-error estimation
   error of the seed's asymptotic observer vs the Kalman filter on the gradiometer channel.
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

from gravsurvey import gradiometer as G
from gravsurvey.geodesy import WGS84, mat_en, normal_gravitation_ecef
from gravsurvey.simulate import field as F
from gravsurvey.simulate.run import quick_sim, simulate_flight
from gravsurvey.simulate.simconfig import load_sim_config

MGAL = 1e-5
ARCSEC = math.pi / 180.0 / 3600.0
NOISES = (0.0, 1.0, 3.0, 10.0)


def random_field(rng, lat0, lon0, length_m):
    """A rugged field along the line: point masses 1-4 km deep and shallow prisms (seed 003 style)."""
    dlat = 1.0 / 111e3
    dlon = 1.0 / (111e3 * math.cos(math.radians(lat0)))
    pms = []
    for _ in range(12):
        pms.append(
            {
                "lat_deg": lat0 + rng.uniform(-5e3, 5e3) * dlat,
                "lon_deg": lon0 + rng.uniform(0, length_m) * dlon,
                "depth_m": float(rng.uniform(1000, 4000)),
                "mass_kg": float(rng.choice([-1, 1]) * rng.uniform(2e13, 1e14)),
            }
        )
    prisms = []
    for _ in range(4):
        prisms.append(
            {
                "lat_deg": lat0 + rng.uniform(-3e3, 3e3) * dlat,
                "lon_deg": lon0 + rng.uniform(0, length_m) * dlon,
                "east_m": [-float(rng.uniform(1e3, 4e3)), float(rng.uniform(1e3, 4e3))],
                "north_m": [-float(rng.uniform(1e3, 4e3)), float(rng.uniform(1e3, 4e3))],
                "depth_m": [float(rng.uniform(200, 800)), float(rng.uniform(1500, 3000))],
                "density_kgm3": float(rng.choice([-1, 1]) * rng.uniform(200, 500)),
            }
        )
    return {"type": "model", "point_masses": pms, "prisms": prisms}


def flight(seed, duration_s, noise_e, speed=100.0):
    lat0, lon0 = 45.0, 135.0
    fld = random_field(np.random.default_rng(1000 + seed), lat0, lon0, speed * duration_s)
    sim = quick_sim(
        duration_s=duration_s,
        speed_mps=speed,
        lat_deg=lat0,
        lon_deg=lon0,
        field=fld,
        imu_hz=1.0,
        seed=seed,
        noise={"gradiometer": {"rate_hz": 1.0, "white_eotvos_rthz": noise_e}},
    )
    return simulate_flight(load_sim_config(sim)), load_sim_config(sim)


def tensors(fs):
    comps = fs.gradient_t_eotvos * F.EOTVOS
    gam = np.empty((comps.shape[0], 3, 3))
    for k, (i, j) in enumerate(((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))):
        gam[:, i, j] = gam[:, j, i] = comps[:, k]
    return gam


def evaluate(fs, cfg):
    """All measures of one flight (platform triad: triad axes = ENU)."""
    t = fs.gradient_time
    tr = fs.truth
    ti = tr["time"]
    # truth at gradient epochs (IMU at 1 Hz = the same grid)
    assert np.array_equal(ti, t)
    lat, lon = tr["lat"], tr["lon"]
    from gravsurvey.geodesy import geodetic_to_ecef

    r_e = geodetic_to_ecef(lat, lon, tr["height"], WGS84)
    m_en = mat_en(lat, lon)
    gam_n = tensors(fs)
    g_true_n = tr["gravitation_n"]
    g_norm_n = np.einsum("kji,kj->ki", m_en, normal_gravitation_ecef(r_e, WGS84))
    anom_true = g_true_n - g_norm_n
    out = {}
    # 1. gravity by dg/dt = T V on ECEF axes, started from the truth
    gam_e = np.einsum("kij,kjl,kml->kim", m_en, gam_n, m_en)
    vel_e = np.einsum("kij,kj->ki", m_en, tr["vel_n"])
    g_e0 = m_en[0] @ g_true_n[0]
    g_prop_e = G.propagate_gravitation_e(t, g_e0, gam_e, vel_e)
    g_prop_n = np.einsum("kji,kj->ki", m_en, g_prop_e)
    err = g_prop_n - g_true_n
    out["grav_v_rms"] = float(np.sqrt(np.mean(err[:, 2] ** 2))) / MGAL
    out["grav_h_rms"] = float(np.sqrt(np.mean(np.sum(err[:, :2] ** 2, axis=1)))) / MGAL
    out["grav_v_end"] = abs(float(err[-1, 2])) / MGAL
    out["anom_v_rms"] = float(np.sqrt(np.mean(anom_true[:, 2] ** 2))) / MGAL
    out["anom_h_rms"] = float(np.sqrt(np.mean(np.sum(anom_true[:, :2] ** 2, axis=1)))) / MGAL
    # 2. eigen-vertical vs the true gravitation direction, normal offset removed
    _, g0_meas = G.vertical_eigen(gam_n)
    gam_norm_n = F.total_gradient_n(None, r_e, lat, lon, WGS84)
    _, g0_norm = G.vertical_eigen(gam_norm_n)
    unit = lambda v: v / np.linalg.norm(v, axis=1)[:, None]
    g0_used = unit(g0_meas - g0_norm + unit(g_norm_n))
    gmag = np.linalg.norm(g_true_n, axis=1)
    acc_err_grad = (gmag[:, None] * (g0_used - unit(g_true_n)))[:, :2]  # horizontal, m/s^2
    acc_err_conv = (gmag[:, None] * (unit(g_norm_n) - unit(g_true_n)))[:, :2]
    out["tilt_grad_arcsec"] = float(np.sqrt(np.mean(np.sum(acc_err_grad**2, axis=1)))) / 9.8 / ARCSEC
    out["tilt_conv_arcsec"] = float(np.sqrt(np.mean(np.sum(acc_err_conv**2, axis=1)))) / 9.8 / ARCSEC
    # 3. free-inertial horizontal error, east and north channels, 10 and 60 min
    w0 = math.sqrt(9.8 / 6.371e6)
    dt = float(t[1] - t[0])
    b = np.array([[0.0], [1.0]])
    res = {}
    for name, gradio, acc in (("conv", False, acc_err_conv), ("grad", True, acc_err_grad)):
        a = G.horizontal_channel_matrix(w0, gradio)[:2, :2]
        pos = []
        for ax in range(2):
            x = G.propagate_linear(a, np.zeros(2), dt, t.size, b, acc[:-1, ax : ax + 1])
            pos.append(x[:, 0])
        dist = np.hypot(pos[0], pos[1])
        res[f"{name}_10"] = float(dist[min(round(600.0 / dt), t.size - 1)])
        res[f"{name}_end"] = float(dist[-1])
    out.update(res)
    # 4. GNSS-aided gradiometer channel (east axis), asymptotic vs Kalman
    rng = np.random.default_rng(5)
    a2 = G.horizontal_channel_matrix(w0, True)[:2, :2]
    x = G.propagate_linear(a2, np.zeros(2), dt, t.size, b, acc_err_grad[:-1, 0:1])
    z = x[:, 0] + rng.normal(0.0, 3.0, t.size)
    q_acc = max(float(np.var(np.diff(acc_err_grad[:, 0]))) / dt, 1e-16)  # the error's own increment rate
    l0 = (q_acc / 9.0) ** (1.0 / 6.0)
    x_as, x_kf, _ = G.run_channel_filters(t, z, 9.0, q_acc, l0, (3.0, 1.0, 1e-2))
    tail = slice(min(600, t.size // 4), None)
    rms = lambda e: float(np.sqrt(np.mean(e[tail] ** 2)))
    out["aided_pos_as"] = rms(x_as[:, 0] - x[:, 0])
    out["aided_pos_kf"] = rms(x_kf[:, 0] - x[:, 0])
    out["aided_acc_as"] = rms(x_as[:, 2] - acc_err_grad[:, 0]) / MGAL
    out["aided_acc_kf"] = rms(x_kf[:, 2] - acc_err_grad[:, 0]) / MGAL
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="20-min flight, one seed")
    ap.add_argument("--seeds", type=int, default=3, help="random fields (flights) per noise level")
    args = ap.parse_args(argv)
    dur = 1200.0 if args.quick else 3600.0
    seeds = 1 if args.quick else args.seeds
    t0 = time.perf_counter()
    rows = []
    for noise in NOISES:
        acc = []
        for s in range(seeds):
            fs, cfg = flight(s, dur, noise)
            acc.append(evaluate(fs, cfg))
        rows.append((noise, {k: float(np.mean([a[k] for a in acc])) for k in acc[0]}))
    print(
        f"Flight: {dur / 60:.0f} min due east at 100 m/s, 1000 m, 45N; 12 point masses + 4 prisms per field; "
        f"{seeds} field(s) per row (means); gradient 1 Hz, white noise only; platform triad.\n"
    )
    r0 = rows[0][1]
    print(
        f"Anomaly along the line (what a normal-field model misses): vertical RMS {r0['anom_v_rms']:.1f} mGal, "
        f"horizontal RMS {r0['anom_h_rms']:.1f} mGal; conventional vertical error (deflection) RMS "
        f'{r0["tilt_conv_arcsec"]:.2f}"; free-inertial Schuler channel driven by it: '
        f"{r0['conv_10']:.1f} m after 10 min, {r0['conv_end']:.1f} m after {dur / 60:.0f} min.\n"
    )
    print(
        "| gradient noise, E/sqrt(Hz) | gravity by dg/dt=T V: vertical RMS / end, mGal | horizontal RMS, mGal "
        f"| eigen-vertical error RMS, arcsec | free-inertial pos. error 10 / {dur / 60:.0f} min, m | "
        "GNSS-aided pos. RMS asym / KF, m | accel.-error estimate RMS asym / KF, mGal |"
    )
    print("|---|---|---|---|---|---|---|")
    for noise, r in rows:
        print(
            f"| {noise:g} | {r['grav_v_rms']:.3f} / {r['grav_v_end']:.3f} | {r['grav_h_rms']:.3f} | "
            f"{r['tilt_grad_arcsec']:.1f} | {r['grad_10']:.0f} / {r['grad_end']:.0f} | "
            f"{r['aided_pos_as']:.2f} / {r['aided_pos_kf']:.2f} | {r['aided_acc_as']:.1f} / {r['aided_acc_kf']:.1f} |"
        )
    print(f"\n({time.perf_counter() - t0:.0f} s)")
    return rows


if __name__ == "__main__":
    main()
