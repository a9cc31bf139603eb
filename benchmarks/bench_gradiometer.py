#!/usr/bin/env python
"""What a gravity-gradient channel buys (issue 16 item 4, seed 000), measured on simulated flights.

Usage::

    python benchmarks/bench_gradiometer.py [--quick] [--flights N] [--first-seed S]
    python benchmarks/bench_gradiometer.py --mode fields [--quick] [--seeds N]

Prints Markdown tables (docs/benchmarks.md, "Gradiometer-aided navigation").

**Unseen flights** (default mode).  Flights with seeds ``S .. S+N-1`` (default 0..5) of the
unseen-flight generator (:mod:`gravsurvey.simulate.unseen`: random fields, noise, rates,
triads, headings, speeds, heights) shortened by ``limit_spec`` to about 40 min and capped at
50 Hz IMU (``--quick``: seeds 0-1, about 15 min -- the generator's shortest lines make them ~20 min
-- and 20 Hz).  Each flight's SIM config gains a gradient channel (``sensors.gradiometer``,
1 Hz, white noise 0, 1, 3, 10 E/sqrt(Hz); the simulator's exact tensors of the drawn sources
plus the normal field).  Per flight:

* **without** the gradient channel: ``gravsurvey run`` with the default configuration
  (``survey.yaml`` as the simulator writes it, public ``run_survey``); vertical = the product
  ``disturbance_mgal``; horizontal = nothing (the scalar product has no horizontal component:
  its error is the horizontal anomaly itself, i.e. a normal-field model);
* **with** the gradient channel, per noise level: :func:`gravsurvey.gradiometer.flight_products`
  (what ``processing.gradiometer: true`` runs): the gravitation propagated by ``dg/dt = T V``
  along the track, started from the default product's first value (vertical) and zero
  (horizontal).  Track, velocity and the triad's attitude (to rotate a strapdown tensor to
  ENU) are the simulator's truth: this measures the channel, not the navigation solution.

Scoring as ``bench_unseen.py``: epochs of ``profiles.csv`` on survey/tie lines, >= 10 min (at
most 10 % of the flight) from both ends, RMS after removing the mean error, against the simulator's truth (vertical
``truth_mgal``; horizontal ``dg_east``/``dg_north``, RMS of the 2-vector).  **Resolution**
(half-wavelength): "own" = the scalar product's stated resolution (median over lines of
``resolution_m``) and, for the gradient channel, its 1 Hz sampling (half-wavelength = speed /
1 Hz, no filter); "common" = both estimate and truth low-passed to the scalar product's
resolution (:func:`gravsurvey.inm.vector.resolution_filter`) before scoring.  **Navigation**:
the free-inertial horizontal position error 10 min after the start of the scored span, driven
only by the vertical's error (perfect accelerometers): conventional Schuler channel with the
normal-field vertical (error = the deflection) vs the seed's gradiometer channel with the
eigen-vertical (normal field's known eigenvector offset removed).

**Three rugged fields** (``--mode fields``, the first version of this benchmark). For each
noise level on a straight 60-min flight over a field of random point masses and prisms:

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
import copy
import math
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from benchmarks.bench_unseen import EDGE_S, median_resolution_km, read_profiles, rms_after_bias, truth_lines
from gravsurvey import gradiometer as G
from gravsurvey.geodesy import WGS84, geodetic_to_ecef, mat_en, normal_gravitation_ecef
from gravsurvey.inm.vector import resolution_filter
from gravsurvey.pipeline import read_truth_csv, run_survey
from gravsurvey.simulate import field as F
from gravsurvey.simulate.run import quick_sim, simulate_flight
from gravsurvey.simulate.simconfig import load_sim_config
from gravsurvey.simulate.unseen import draw_flight_spec, limit_spec, spec_summary, write_flight

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


def main_fields(args):
    """The three-rugged-fields mode (the first version of this benchmark)."""
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


#: Unseen mode: gradient channel rate, Hz; flight caps (full / --quick); default seeds.
GRAD_HZ = 1.0
FULL_CAPS = (2400.0, 50.0)
QUICK_CAPS = (900.0, 20.0)
DEFAULT_FLIGHTS = 6
#: The navigation column: free-inertial error this long after the start of the scored span, s.
NAV_HORIZON_S = 600.0


def unseen_spec(seed, quick):
    """The drawn flight ``seed``, capped (duration, IMU rate) for the benchmark."""
    dur, imu = QUICK_CAPS if quick else FULL_CAPS
    return limit_spec(draw_flight_spec(seed), max_duration_s=dur, max_imu_hz=imu)


def with_gradiometer(sim, noise_e):
    """A copy of a SIM mapping whose flight carries a 1 Hz gradient channel of white noise ``noise_e``."""
    out = copy.deepcopy(sim)
    out["flights"][0]["sensors"]["gradiometer"] = {"rate_hz": GRAD_HZ, "white_eotvos_rthz": float(noise_e)}
    return out


def run_default(spec, work: Path):
    """Simulate the flight and run ``gravsurvey run`` with its default ``survey.yaml``.

    Returns (profiles dict, median stated resolution m, truth FlightSimulation-free dict).
    """
    folder = work / spec["name"]
    s2 = dict(spec, sim=with_gradiometer(spec["sim"], 0.0))
    survey = write_flight(s2, folder, oracle=False)
    res = run_survey(survey, output_dir=folder / "out", force=True)
    if res.failed:
        raise RuntimeError(f"{spec['name']}: gravsurvey run failed: {res.failed[0].splitlines()[0]}")
    prof = read_profiles(folder / "out" / "profiles.csv")
    truth = read_truth_csv(folder / "F01" / "truth.csv")
    truth["line"] = np.array(truth_lines(folder / "F01" / "truth.csv"), dtype=object)
    res_km = median_resolution_km(res.summary)
    return prof, truth, (res_km * 1000.0 if res_km else None)


def scored_epochs(time_ns, truth):
    """Epochs on survey/tie lines, >= min(10 min, 10 % of the flight) from both ends (``bench_unseen`` rule,
    the edge shortened so that the capped --quick flights keep samples)."""
    tt = truth["time_ns"]
    k = np.clip(np.searchsorted(tt, time_ns), 1, tt.size - 1)
    k = np.where(np.abs(tt[k - 1] - time_ns) <= np.abs(tt[k] - time_ns), k - 1, k)
    on_line = np.array([str(lab).startswith(("L", "T")) for lab in truth["line"][k]])
    t = (time_ns - time_ns[0]) / 1e9
    edge = min(EDGE_S, 0.1 * float(t[-1]))
    return on_line & (t >= edge) & (t <= t[-1] - edge)


def rms_vec_after_bias(err):
    """RMS of the length of a (n, k) error after removing each column's mean."""
    e = np.asarray(err, float)
    e = e - e.mean(axis=0)
    return float(np.sqrt(np.mean(np.sum(e**2, axis=1))))


def gradient_at_epochs(fs, mask_time_s):
    """Indices of the truth (IMU-rate) samples at the gradient epochs."""
    ti = fs.truth["time"]
    k = np.clip(np.searchsorted(ti, mask_time_s - 1e-6), 0, ti.size - 1)
    return k


def evaluate_unseen(spec, prof, truth, res_m, noise_e):
    """Scores of one flight at one gradient noise level (see the module docstring)."""
    sim = with_gradiometer(spec["sim"], noise_e)
    fs = simulate_flight(load_sim_config(sim))
    tr = fs.truth
    tg = fs.gradient_time
    start_ns = int(fs.gradient_time_ns[0]) - int(round(tg[0] * 1e9))
    k = gradient_at_epochs(fs, tg)
    if np.max(np.abs(tr["time"][k] - tg)) > 1e-6:
        raise RuntimeError("gradient epochs are not IMU epochs (integer IMU rate expected)")
    gam_t = tensors(fs)
    # tensor on the triad -> ENU with the simulator's true triad attitude (identity on a platform)
    m_nt = tr["mat_nt"][k]
    gam_n = np.einsum("kij,kjl,kml->kim", m_nt, gam_t, m_nt)
    # scored epochs of the default product; the scalar estimate's first value starts dg/dt = T V
    p = prof
    mask = scored_epochs(p["time_unix_ns"], truth)
    t_p = (p["time_unix_ns"] - start_ns) / 1e9
    first = np.flatnonzero(np.isfinite(p["disturbance_mgal"]))[0]
    t_g0 = float(t_p[first])
    sel = tg >= t_g0 - 1e-9
    d0 = float(p["disturbance_mgal"][first]) * MGAL
    # the track a user has: GNSS positions (ECEF) at the gradient epochs, velocity by central
    # differences there (the trapezoidal sum of T V then telescopes to T times the position noise;
    # differences at the GNSS rate would integrate their noise into a random walk)
    lat_g, lon_g = np.radians(fs.gnss_lat_deg), np.radians(fs.gnss_lon_deg)
    r_g = geodetic_to_ecef(lat_g, lon_g, fs.gnss_height, WGS84)
    r_k = np.stack([np.interp(tg, fs.gnss_time, r_g[:, j]) for j in range(3)], axis=1)
    lat_k = np.interp(tg, fs.gnss_time, lat_g)
    lon_k = np.interp(tg, fs.gnss_time, np.unwrap(lon_g))
    h_k = np.interp(tg, fs.gnss_time, fs.gnss_height)
    v_g = np.einsum("kji,kj->ki", mat_en(lat_k, lon_k), np.gradient(r_k, tg, axis=0))
    tracks = {
        "": (tg, lat_k, lon_k, h_k, v_g),
        "_true": (tr["time"], tr["lat"], tr["lon"], tr["height"], tr["vel_n"]),
    }
    true_h = np.stack([np.interp(t_p, tr["time"], tr["dg_east"]), np.interp(t_p, tr["time"], tr["dg_north"])], axis=1)
    true_h = true_h / MGAL
    true_v = p["truth_mgal"]
    scal_v = p["disturbance_mgal"]
    m = mask & np.isfinite(scal_v) & np.isfinite(true_v)
    out = {"scored": int(m.sum()), "speed": spec["speed_mps"], "res_m": res_m}
    out["v_without"], _ = rms_after_bias((scal_v - true_v)[m])
    out["h_without"] = rms_vec_after_bias(-true_h[m])
    out["truth_v_std"] = float(np.std(true_v[m]))
    fin = np.flatnonzero(np.isfinite(scal_v) & np.isfinite(true_v))
    span = slice(fin[0], fin[-1] + 1)
    ms = m[span]

    def lp(x):
        # estimate and truth low-passed alike to the product's resolution over the finite span
        return resolution_filter(x[span], t_p[span], spec["speed_mps"], res_m)

    if res_m:
        tv, th = lp(true_v), lp(true_h)
        out["v_without_c"], _ = rms_after_bias((lp(np.nan_to_num(scal_v)) - tv)[ms])
        out["h_without_c"] = rms_vec_after_bias(-th[ms])
    for tag, (nav_t, la, lo, hh, vv) in tracks.items():
        prod = G.flight_products(tg[sel], gam_n[sel], nav_t, la, lo, hh, vv, d0, "platform")
        tt = prod["time"]
        grad_v = np.interp(t_p, tt, prod["disturbance"]) / MGAL
        grad_h = np.stack([np.interp(t_p, tt, prod["horizontal_n"][:, j]) for j in range(2)], axis=1) / MGAL
        out[f"v_with{tag}"], _ = rms_after_bias((grad_v - true_v)[m])
        out[f"h_with{tag}"] = rms_vec_after_bias((grad_h - true_h)[m])
        if res_m:
            out[f"v_with{tag}_c"], _ = rms_after_bias((lp(grad_v) - tv)[ms])
            out[f"h_with{tag}_c"] = rms_vec_after_bias((lp(grad_h) - th)[ms])
    # navigation: free-inertial error NAV_HORIZON_S after the start of the scored span
    i0 = int(np.searchsorted(tg, t_p[np.flatnonzero(m)[0]]))
    n = min(int(round(NAV_HORIZON_S * GRAD_HZ)) + 1, tg.size - i0)
    kk = k[i0 : i0 + n]
    lat, lon = tr["lat"][kk], tr["lon"][kk]
    r_e = geodetic_to_ecef(lat, lon, tr["height"][kk], WGS84)
    m_en = mat_en(lat, lon)
    g_true_n = tr["gravitation_n"][kk]
    g_norm_n = np.einsum("kji,kj->ki", m_en, normal_gravitation_ecef(r_e, WGS84))
    _, g0_meas = G.vertical_eigen(gam_n[i0 : i0 + n])
    _, g0_norm = G.vertical_eigen(F.total_gradient_n(None, r_e, lat, lon, WGS84))
    unit = lambda v: v / np.linalg.norm(v, axis=1)[:, None]
    g0_used = unit(g0_meas - g0_norm + unit(g_norm_n))
    gmag = np.linalg.norm(g_true_n, axis=1)
    acc = {
        "conv": (gmag[:, None] * (unit(g_norm_n) - unit(g_true_n)))[:, :2],
        "grad": (gmag[:, None] * (g0_used - unit(g_true_n)))[:, :2],
    }
    w0 = math.sqrt(9.8 / 6.371e6)
    b = np.array([[0.0], [1.0]])
    for name, gradio in (("conv", False), ("grad", True)):
        a = G.horizontal_channel_matrix(w0, gradio)[:2, :2]
        pos = [
            G.propagate_linear(a, np.zeros(2), 1.0 / GRAD_HZ, n, b, acc[name][:-1, ax : ax + 1])[:, 0] for ax in (0, 1)
        ]
        out[f"nav_{name}"] = float(np.hypot(pos[0][-1], pos[1][-1]))
        out[f"tilt_{name}"] = float(np.sqrt(np.mean(np.sum(acc[name] ** 2, axis=1)))) / 9.8 / ARCSEC
    return out


def main_unseen(args):
    """The unseen-flight mode: table per noise level (means over the flights) and per flight."""
    import tempfile

    seeds = range(args.first_seed, args.first_seed + (2 if args.quick else args.flights))
    t0 = time.perf_counter()
    per = {noise: [] for noise in NOISES}
    flights = []
    with tempfile.TemporaryDirectory(prefix="bench_gradiometer_") as tmp:
        for seed in seeds:
            spec = unseen_spec(seed, args.quick)
            prof, truth, res_m = run_default(spec, Path(tmp))
            flights.append((spec, res_m))
            for noise in NOISES:
                per[noise].append(evaluate_unseen(spec, prof, truth, res_m, noise))
    dur, imu = QUICK_CAPS if args.quick else FULL_CAPS
    print(
        f"Unseen flights seeds {seeds.start}-{seeds.stop - 1} (gravsurvey.simulate.unseen, limit_spec to about "
        f"{dur / 60:.0f} min and {imu:.0f} Hz IMU); gradient channel {GRAD_HZ:g} Hz, white noise; "
        "values are means over the flights.\n"
    )
    for spec, res_m in flights:
        r = f"{res_m / 1000:.1f} km" if res_m else "-"
        print(f"- {spec_summary(spec)}; default product resolution {r}")
    print()
    mean = lambda rows, key: float(np.mean([r[key] for r in rows if r.get(key) is not None]))
    r0 = per[NOISES[0]]
    own_g = float(np.mean([s["speed_mps"] / GRAD_HZ for s, _ in flights]))
    res_c = float(np.mean([x for _, x in flights if x])) / 1000.0
    print(
        f"Resolution (half-wavelength): default product {res_c:.1f} km (mean of the flights' stated "
        f"resolutions); gradient channel {own_g:.0f} m (1 Hz sampling, unfiltered). "
        f"Truth along the scored lines: vertical std {mean(r0, 'truth_v_std'):.2f} mGal.\n"
    )
    print(
        "| gradient noise, E/sqrt(Hz) | vertical RMS without / with, mGal (own resolution) "
        "| vertical without / with at the product's resolution | horizontal RMS without / with, mGal (own) "
        "| horizontal without / with at the product's resolution "
        f"| free-inertial pos. error after {NAV_HORIZON_S / 60:.0f} min conventional / eigen-vertical, m "
        "| vertical's error RMS conventional / eigen-vertical, arcsec "
        "| with, true track: vertical / horizontal RMS (own), mGal |"
    )
    print("|---|---|---|---|---|---|---|---|")
    rows = []
    for noise in NOISES:
        rr = per[noise]
        row = {key: mean(rr, key) for key in rr[0] if key not in ("res_m",)}
        rows.append((noise, row))
        print(
            f"| {noise:g} | {row['v_without']:.2f} / {row['v_with']:.2f} | "
            f"{row.get('v_without_c', math.nan):.2f} / {row.get('v_with_c', math.nan):.2f} | "
            f"{row['h_without']:.2f} / {row['h_with']:.2f} | "
            f"{row.get('h_without_c', math.nan):.2f} / {row.get('h_with_c', math.nan):.2f} | "
            f"{row['nav_conv']:.1f} / {row['nav_grad']:.0f} | {row['tilt_conv']:.2f} / {row['tilt_grad']:.0f} | "
            f"{row['v_with_true']:.2f} / {row['h_with_true']:.2f} |"
        )
    print("\nPer flight (vertical RMS own resolution: without / with at 0, 1, 3, 10 E/sqrt(Hz), mGal):\n")
    print("| flight | without | with 0 | with 1 | with 3 | with 10 | horizontal without | with 1 |")
    print("|---|---|---|---|---|---|---|---|")
    for i, (spec, _) in enumerate(flights):
        w = [per[n][i]["v_with"] for n in NOISES]
        print(
            f"| {spec['name']} {spec['triad']} | {per[0.0][i]['v_without']:.2f} | "
            + " | ".join(f"{x:.2f}" for x in w)
            + f" | {per[0.0][i]['h_without']:.2f} | {per[1.0][i]['h_with']:.2f} |"
        )
    print(f"\n({time.perf_counter() - t0:.0f} s)")
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mode", choices=("unseen", "fields"), default="unseen")
    ap.add_argument(
        "--quick", action="store_true", help="unseen: 2 flights of 15 min; fields: 20-min flight, one field"
    )
    ap.add_argument("--flights", type=int, default=DEFAULT_FLIGHTS, help="unseen: number of drawn flights")
    ap.add_argument("--first-seed", type=int, default=0, help="unseen: first generator seed")
    ap.add_argument("--seeds", type=int, default=3, help="fields: random fields (flights) per noise level")
    args = ap.parse_args(argv)
    return main_unseen(args) if args.mode == "unseen" else main_fields(args)


if __name__ == "__main__":
    main()
