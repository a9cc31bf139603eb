#!/usr/bin/env python
"""Speed and agreement of the 3D-INM filter + smoother against filterpy; mechanization per sample.

Usage::

    python benchmarks/bench_inm.py [--quick]

Prints a Markdown table.  ``run(quick) -> list[dict]`` is what ``benchmarks/run.py`` calls.
Timings are reported, never asserted.  The filter is the one a default run uses: the GNSS-aided
model (``errormodel.N_STATE_AIDED`` = 14 states), built as ``gravsurvey.inm.solve`` builds it.
Goals (issue 17.6): filter + RTS smoother >= 50x faster than filterpy's ``KalmanFilter`` +
``KalmanFilter.rts_smoother`` on the same Phi, Q, H, R, z (paired, interleaved repetitions:
ours, filterpy, ours, filterpy, ...; median of the per-pair ratios, with their range), and
agreement to 1e-9 relative; mechanization <= 2 us per IMU sample.

Agreement is reported three ways (docs/benchmarks.md, "Kalman filter"): against filterpy on the
model as the pipeline poses it; against an extended-precision textbook filter
(:func:`gravsurvey.inm.kalman.filter_and_smooth_exact`, the first epochs only: it is slow);
and against filterpy on the same model in the true-error basis
(:func:`gravsurvey.inm.errormodel.true_error_basis`), where the covariance is well conditioned.

The test flight is built here from closed-form kinematics (a flight along a parallel,
noiseless sensors plus seed-level white noise); only gravsurvey.geodesy is used for it.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from gravsurvey.geodesy import (  # noqa: E402
    WGS84,
    geodetic_to_ecef,
    mat_en,
    mat_ie,
    normal_gravitation_ecef,
    radii_of_curvature,
)
from gravsurvey.inm.errormodel import (  # noqa: E402
    N_STATE_AIDED,
    AltimeterMeasurement,
    GnssMeasurement,
    discretise,
    epoch_geometry,
    initial_covariance,
    true_error_basis,
)
from gravsurvey.inm.kalman import (  # noqa: E402
    change_basis,
    filter_and_smooth,
    filter_and_smooth_exact,
    restore_basis,
)
from gravsurvey.inm.mechanization import mechanize  # noqa: E402
from gravsurvey.inm.params import InitialState, InmParams  # noqa: E402
from gravsurvey.inm.solve import estimate_anomaly, stack_measurements  # noqa: E402
from gravsurvey.io.record import AltimeterChannel, FlightRecord, ImuChannel  # noqa: E402


def _flight(duration_s, rate_hz=10.0, seed=0):
    """Platform flight due east at 50 m/s, 1000 m, 45 N; seed-level sensor noise."""
    t = np.arange(int(duration_s * rate_hz) + 1) / rate_hz
    lat0, h, v = np.radians(45.0), 1000.0, 50.0
    _, n_rad = radii_of_curvature(lat0)
    wl = v / ((n_rad + h) * np.cos(lat0))
    lat = np.full_like(t, lat0)
    lon = np.radians(135.0) + wl * t
    r_e = geodetic_to_ecef(lat, lon, h)
    m_ie = mat_ie(t)
    r_i = np.einsum("nij,nj->ni", m_ie, r_e)
    wt = WGS84.omega + wl
    f_i = -(wt**2) * r_i * np.array([1.0, 1.0, 0.0]) - np.einsum("nij,nj->ni", m_ie, normal_gravitation_ecef(r_e))
    m_in = np.einsum("nij,njk->nik", m_ie, mat_en(lat, lon))
    f_t = np.einsum("nji,nj->ni", m_in, f_i)
    w_t = wt * np.stack([np.zeros_like(t), np.cos(lat), np.sin(lat)], axis=-1)
    rng = np.random.default_rng(seed)
    f_t[:, :2] += rng.normal(size=(t.size, 2)) * 1e-3 * np.sqrt(rate_hz)
    w_t += rng.normal(size=w_t.shape) * np.radians(0.01) / 3600 * np.sqrt(rate_hz)
    alt_t = t[:: int(rate_hz)]
    rec = FlightRecord(0, ImuChannel(t, f_t, w_t), AltimeterChannel(alt_t, h + rng.normal(size=alt_t.size)))
    init = InitialState(lat0, float(lon[0]), h, np.array([v, 0.0, 0.0]), np.eye(3))
    # GNSS positions at 1 Hz with 1 m / 2 m noise, for the 14-state aided model
    gnss = (
        alt_t,
        lat[:: int(rate_hz)] + rng.normal(size=alt_t.size) / 6.4e6,
        lon[:: int(rate_hz)] + rng.normal(size=alt_t.size) / 4.5e6,
        h + 2.0 * rng.normal(size=alt_t.size),
    )
    return rec, init, gnss


def _model(rec, init, params, gnss):
    """``(x0, P0, Phi, Q, z, H, R)`` of the GNSS-aided model as gravsurvey.inm.solve builds it, and
    ``(T, T^-1)`` of its true-error basis."""
    nav = mechanize(
        rec.imu.time, rec.imu.specific_force_t, rec.imu.angular_rate_t, init, rec.altimeter.time, rec.altimeter.height
    )
    idx = np.arange(0, rec.imu.time.size, 10)
    n = N_STATE_AIDED
    phi, q = discretise(epoch_geometry(nav, idx), params, 1.0, aided=True)
    parts = [
        AltimeterMeasurement(rec.altimeter.time, rec.altimeter.height, params.altimeter_sigma_m).build(
            nav, idx, 0.5, n
        ),
        GnssMeasurement(*gnss, 1.0, 2.0).build(nav, idx, 0.5, n),
    ]
    c = nav.mat_it[idx[0]]
    p0 = initial_covariance(params, c.T @ nav.r_i[idx[0]], c.T @ nav.v_i[idx[0]])
    z, h, r = stack_measurements(parts)
    c = nav.mat_it[idx]
    basis = true_error_basis(np.einsum("nji,nj->ni", c, nav.r_i[idx]), np.einsum("nji,nj->ni", c, nav.v_i[idx]))
    return (np.zeros(n), p0, phi, q, z, h, r), basis


def _filterpy(x0, p0, phi, q, z, h, r):
    """filterpy's KalmanFilter (predict, update) and KalmanFilter.rts_smoother, as documented."""
    from filterpy.kalman import KalmanFilter

    n = x0.size
    kf = KalmanFilter(dim_x=n, dim_z=z.shape[1])
    kf.x, kf.P = x0.copy(), p0.copy()
    xf, pf = np.empty((phi.shape[0], n)), np.empty((phi.shape[0], n, n))
    for k in range(phi.shape[0]):
        if k:
            kf.predict(F=phi[k], Q=q[k])
        ok = np.isfinite(z[k])
        if ok.all():
            kf.update(z[k], R=r[k], H=h[k])
        elif ok.any():  # filterpy has no partial update: the available components only
            kf.dim_z = int(ok.sum())
            kf.update(z[k][ok], R=r[k][np.ix_(ok, ok)], H=h[k][ok])
            kf.dim_z = z.shape[1]
        xf[k], pf[k] = kf.x, kf.P
    # KalmanFilter.rts_smoother indexes Fs[k+1] as the k -> k+1 transition, as we do
    xs, ps, _, _ = kf.rts_smoother(xf, pf, Fs=phi, Qs=q)
    return xf, pf, xs, ps


def _median_range(v):
    v = np.asarray(v, float)
    return float(np.median(v)), float(v.min()), float(v.max())


def _paired(fa, fb, reps):
    """``reps`` interleaved pairs (a, b, a, b, ...): a noisy spell on the shared machine hits both
    sides of a pair alike.  Returns the wall times of each side, the per-pair ratios b / a, and
    the per-pair ratios of CPU time (process time: less inflated by other processes' load)."""
    ta, tb, ca, cb = [], [], [], []
    for _ in range(reps):
        t, c = time.perf_counter(), time.process_time()
        fa()
        ta.append(time.perf_counter() - t)
        ca.append(time.process_time() - c)
        t, c = time.perf_counter(), time.process_time()
        fb()
        tb.append(time.perf_counter() - t)
        cb.append(time.process_time() - c)
    ta, tb = np.array(ta), np.array(tb)
    return ta, tb, tb / ta, np.array(cb) / np.array(ca)


def _rel(a, b):
    """Largest difference relative to each component's largest magnitude over the flight
    (states: per component; covariances: per (i, j) by sqrt(max P_ii max P_jj))."""
    if a.ndim == 2:
        return float(np.max(np.abs(a - b) / (np.abs(b).max(axis=0) + 1e-300)))
    sd = np.sqrt(np.abs(np.einsum("kii->ki", b))).max(axis=0) + 1e-300
    return float(np.max(np.abs(a - b) / (sd[:, None] * sd[None, :])))


def _sigmas(a, b, p_b):
    """Largest difference in units of each epoch's own sigmas (covariances: sigma_i sigma_j)."""
    sd = np.sqrt(np.abs(np.einsum("kii->ki", p_b))) + 1e-300
    if a.ndim == 2:
        return float(np.max(np.abs(a - b) / sd))
    return float(np.max(np.abs(a - b) / (sd[:, :, None] * sd[:, None, :])))


def _agreement(ours, other, prefix):
    """States and covariances, filtered and smoothed: relative and in sigmas."""
    xf, pf, xs, ps = other
    out = {}
    for key, a, b, p in (
        ("x_f", ours["x_f"], xf, pf),
        ("p_f", ours["p_f"], pf, pf),
        ("x_s", ours["x_s"], xs, ps),
        ("p_s", ours["p_s"], ps, ps),
    ):
        out[f"{prefix}_{key}_rel"] = _rel(a, b)
        out[f"{prefix}_{key}_sigmas"] = _sigmas(a, b, p)
    out[f"{prefix}_rel"] = max(out[f"{prefix}_{k}_rel"] for k in ("x_f", "p_f", "x_s", "p_s"))
    out[f"{prefix}_sigmas"] = max(out[f"{prefix}_{k}_sigmas"] for k in ("x_f", "p_f", "x_s", "p_s"))
    return out


def compare_filterpy(model, basis, reps, n_exact):
    """Time our filter + smoother against filterpy's (paired) and measure their agreement."""
    filter_and_smooth(*model[:2], *[a[:5] for a in model[2:]])  # compile (or load) outside the timing
    _filterpy(*model[:2], *[a[:5] for a in model[2:]])  # and import filterpy outside it
    # filter_and_smooth is exactly what gravsurvey.inm.solve calls
    t_ours, t_fp, ratio, cpu_ratio = _paired(lambda: filter_and_smooth(*model), lambda: _filterpy(*model), reps)
    ours = filter_and_smooth(*model)
    row = {"stage": "filter+smoother, 14 states (GNSS-aided, the default)", "n": model[2].shape[0], "pairs": reps}
    row["ours_s"], row["ours_s_min"], row["ours_s_max"] = _median_range(t_ours)
    row["filterpy_s"], row["filterpy_s_min"], row["filterpy_s_max"] = _median_range(t_fp)
    row["speedup"], row["speedup_min"], row["speedup_max"] = _median_range(ratio)
    row["cpu_speedup"], row["cpu_speedup_min"], row["cpu_speedup_max"] = _median_range(cpu_ratio)
    row.update(_agreement(ours, _filterpy(*model), "filterpy"))
    # the yardstick: extended precision on the first epochs (both double paths against it)
    short = model[:2] + tuple(a[:n_exact] for a in model[2:])
    exact = filter_and_smooth_exact(*short)
    row["n_exact"] = n_exact
    row.update(_agreement(filter_and_smooth(*short), exact, "ours_vs_exact"))
    fp_short = _filterpy(*short)
    row.update(
        _agreement(dict(x_f=fp_short[0], p_f=fp_short[1], x_s=fp_short[2], p_s=fp_short[3]), exact, "filterpy_vs_exact")
    )
    # the same model in the true-error basis: well conditioned, so the two must agree to rounding
    t, t_inv = basis
    x0b, p0b, phib, qb, hb = change_basis(t, t_inv, model[0], model[1], model[2], model[3], model[5])
    tb_model = (x0b, p0b, phib, qb, model[4], hb, model[6])
    ours_b = filter_and_smooth(*tb_model)
    row.update(_agreement(ours_b, _filterpy(*tb_model), "basis_filterpy"))
    # and the basis change does not change our estimate beyond the rounding of the original basis
    xs_back, ps_back = restore_basis(t_inv, ours_b["x_s"], ours_b["p_s"])
    row["basis_vs_original_x_s_sigmas"] = _sigmas(xs_back, ours["x_s"], ours["p_s"])
    row["goal"] = ">= 50x; <= 1e-9 relative"
    return row


def run(quick: bool = False) -> list[dict]:
    params = InmParams()
    hours = 1.0 if quick else 4.0
    rec, init, gnss = _flight(hours * 3600.0)
    reps = 5 if quick else 11
    model, basis = _model(rec, init, params, gnss)
    rows = [compare_filterpy(model, basis, reps, 200 if quick else 600)]
    # mechanization per IMU sample (median of repetitions, with the range)
    t = rec.imu.time
    mechanize(
        t[:100],
        rec.imu.specific_force_t[:100],
        rec.imu.angular_rate_t[:100],
        init,
        rec.altimeter.time,
        rec.altimeter.height,
    )
    times = []
    for _ in range(reps):
        t0 = time.perf_counter()
        mechanize(t, rec.imu.specific_force_t, rec.imu.angular_rate_t, init, rec.altimeter.time, rec.altimeter.height)
        times.append(time.perf_counter() - t0)
    med, lo, hi = _median_range(times)
    rows.append(
        {
            "stage": "mechanization",
            "n": int(t.size),
            "ours_s": med,
            "ours_s_min": lo,
            "ours_s_max": hi,
            "us_per_sample": 1e6 * med / t.size,
            "goal": "<= 2 us/sample",
        }
    )
    estimate_anomaly(rec, params, init, "platform")  # kernels of this path compiled or loaded untimed
    times = []
    for _ in range(3 if quick else 5):
        t0 = time.perf_counter()
        estimate_anomaly(rec, params, init, "platform")
        times.append(time.perf_counter() - t0)
    med, lo, hi = _median_range(times)
    rows.append(
        {
            "stage": "estimate_anomaly (all, 8 states: no GNSS given)",
            "n": int(t.size),
            "ours_s": med,
            "ours_s_min": lo,
            "ours_s_max": hi,
            "s_per_flight_hour": med / hours,
        }
    )
    return rows


def main(argv=None):
    quick = "--quick" in (argv if argv is not None else sys.argv[1:])
    rows = run(quick)
    print("| stage | n | ours (s), median [range] | filterpy (s) | ratio / per sample | goal |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        rng = f"{r['ours_s']:.4f} [{r['ours_s_min']:.4f}, {r['ours_s_max']:.4f}]"
        if "filterpy_s" in r:
            print(
                f"| {r['stage']} | {r['n']} epochs, {r['pairs']} pairs | {rng} | {r['filterpy_s']:.3f} "
                f"[{r['filterpy_s_min']:.3f}, {r['filterpy_s_max']:.3f}] | {r['speedup']:.1f}x "
                f"[{r['speedup_min']:.1f}, {r['speedup_max']:.1f}] (CPU time: {r['cpu_speedup']:.1f}x "
                f"[{r['cpu_speedup_min']:.1f}, {r['cpu_speedup_max']:.1f}]) | {r['goal']} |"
            )
        elif "us_per_sample" in r:
            print(f"| {r['stage']} | {r['n']} samples | {rng} | - | {r['us_per_sample']:.2f} us/sample | {r['goal']} |")
        else:
            print(
                f"| {r['stage']} | {r['n']} samples | {rng} | - | {r['s_per_flight_hour']:.3f} s per flight hour | - |"
            )
    r = rows[0]
    print()
    print(
        "| comparison (14 states) | epochs | max relative (x_f, p_f, x_s, p_s) | max in sigmas (x_f, p_f, x_s, p_s) |"
    )
    print("|---|---|---|---|")
    for prefix, label, n in (
        ("filterpy", "ours vs filterpy, pipeline basis", r["n"]),
        ("ours_vs_exact", "ours vs extended precision", r["n_exact"]),
        ("filterpy_vs_exact", "filterpy vs extended precision", r["n_exact"]),
        ("basis_filterpy", "ours vs filterpy, true-error basis", r["n"]),
    ):
        rel = ", ".join(f"{r[f'{prefix}_{k}_rel']:.1e}" for k in ("x_f", "p_f", "x_s", "p_s"))
        sig = ", ".join(f"{r[f'{prefix}_{k}_sigmas']:.1e}" for k in ("x_f", "p_f", "x_s", "p_s"))
        print(f"| {label} | {n} | {rel} | {sig} |")
    print(
        f"| ours, true-error basis mapped back vs ours, pipeline basis (x_s) | {r['n']} | - | "
        f"{r['basis_vs_original_x_s_sigmas']:.1e} |"
    )


if __name__ == "__main__":
    main()
