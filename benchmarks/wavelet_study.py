#!/usr/bin/env python
"""The wavelet post-processor study behind docs/wavelet.md (issue 5).

Usage::

    python benchmarks/wavelet_study.py [--seeds 1,2,3,4,5] [--no-surrogate]
    python benchmarks/wavelet_study.py --lines     # short survey lines and line edges

Data: the SMOOTHED 3D-INM estimate of the seed scenarios (model.md section 3; configs/
seed_smooth.yaml and configs/seed_steps.yaml, simulated by gravsurvey.simulate and estimated by
gravsurvey.inm.solve.estimate_anomaly, the real pipeline's stages), one line = the whole
flight, scored on the middle of the flight (first and last 10 min dropped).  The configs' own
random seed gives the headline table; ``--seeds`` adds the mean over other noise realisations.

A SURROGATE is also scored for comparison and labelled so: a one-axis vertical-channel Kalman
filter + RTS smoother with the seed's stochastic model (h'' = g + f3, altimeter 1 m at 1 Hz),
written here, sharing no code with the project's estimator.  It reproduces model.md's
feasibility note (forward ~11 mGal, smoother ~4.5 mGal) and has no long-period error.

Prints Markdown tables (RMS in mGal, chosen level n, Phi, resolution in km).
"""

from __future__ import annotations

import argparse
import copy
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))
if str(REPO / "benchmarks") not in sys.path:
    sys.path.insert(0, str(REPO / "benchmarks"))

from gravsurvey import wavelet as W  # noqa: E402
from gravsurvey import filters  # noqa: E402

MGAL = 1e-5
EDGE_S = 600.0


# ------------------------------------------------------------------------------------------
# data
# ------------------------------------------------------------------------------------------
def real_estimate(kind, seed=None):
    """Simulate configs/seed_<kind>.yaml (optionally with another random seed) and run the
    3D-INM estimator with the seed model (InmParams defaults) and the initial state that
    `gravsurvey simulate` writes into the processing config.  Returns time (s), smoothed estimate, truth disturbance (m/s^2), speed."""
    from gravsurvey.inm.params import InitialState, InmParams
    from gravsurvey.inm.solve import estimate_anomaly
    from gravsurvey.io.record import AltimeterChannel, FlightRecord, GnssChannel, ImuChannel
    from gravsurvey.simulate.run import simulate_flight

    sim_d = yaml.safe_load((REPO / "configs" / f"seed_{kind}.yaml").read_text())
    if seed is not None:
        sim_d = copy.deepcopy(sim_d)
        sim_d["seed"] = int(seed)
    sim = simulate_flight(sim_d)
    rec = FlightRecord(
        t0_unix_ns=int(sim.start_unix_ns),
        imu=ImuChannel(sim.imu_time, sim.specific_force_t, sim.angular_rate_t),
        altimeter=AltimeterChannel(sim.alt_time, sim.alt_height),
        gnss=GnssChannel(sim.gnss_time, np.radians(sim.gnss_lat_deg), np.radians(sim.gnss_lon_deg), sim.gnss_height),
        source=f"seed_{kind}",
    )
    # As `gravsurvey simulate` writes it into survey.yaml (flights[].initial): the state at the
    # first IMU sample; the platform triad is ENU (identity mat_nt).
    tr = sim.truth
    initial = InitialState(
        float(tr["lat"][0]), float(tr["lon"][0]), float(tr["height"][0]), np.asarray(tr["vel_n"][0], float), np.eye(3)
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sol = estimate_anomaly(rec, InmParams(identify=False), initial, "platform")  # the seed's own model
    truth = np.interp(sol.time, sim.truth["time"], sim.truth["disturbance"])
    return (
        np.asarray(sol.time, float),
        np.asarray(sol.g_smooth, float),
        truth,
        float(np.nanmean(sol.speed)),
        np.asarray(sol.sigma_smooth, float),
    )


def seed_truth(kind, t):
    """Seed scenario anomaly as a function of time (model.md section 3), m/s^2."""
    if kind == "smooth":
        return MGAL * (
            30 * np.sin(2 * np.pi * t / 3600)
            + 20 * np.sin(2 * np.pi * t / 1500 + 1)
            + 10 * np.sin(2 * np.pi * t / 900 + 2)
        )
    return MGAL * (40.0 * (t >= 3600) - 60.0 * (t >= 7200) + 30.0 * (t >= 10800))


def surrogate_estimate(
    kind, seed=0, duration_s=14400.0, v=50.0, lam_s=1e-5, sig_s=1e-3, lam_f=0.025, sig_f=1e-6, sig_eps=1.0
):
    """SURROGATE: vertical-channel KF + RTS smoother on h'' = g + f3, altimeter 1 m at 1 Hz."""
    from scipy.linalg import expm

    rng = np.random.default_rng(seed)
    sub, dt = 10, 1.0
    h_f = dt / sub
    n = int(duration_s / dt) + 1
    t_f = np.arange((n - 1) * sub + 1) * h_f
    a = np.exp(-lam_f * h_f)
    f3 = np.empty_like(t_f)
    f3[0] = sig_f * rng.standard_normal()
    w = rng.standard_normal(t_f.size) * sig_f * np.sqrt(1 - a * a)
    for i in range(1, t_f.size):
        f3[i] = a * f3[i - 1] + w[i]
    acc = seed_truth(kind, t_f) + f3
    vel = np.concatenate([[0.0], np.cumsum(0.5 * (acc[1:] + acc[:-1]) * h_f)])
    hh = np.concatenate([[0.0], np.cumsum(0.5 * (vel[1:] + vel[:-1]) * h_f)])
    t = t_f[::sub]
    y = hh[::sub] + sig_eps * rng.standard_normal(n)
    lam_g = lam_s * v
    F = np.array([[0, 1, 0, 0], [0, 0, 1, 1], [0, 0, -lam_g, 0], [0, 0, 0, -lam_f]], float)
    Qc = np.diag([0.0, 1e-12, 2 * lam_g * sig_s**2, 2 * lam_f * sig_f**2])
    M = np.zeros((8, 8))
    M[:4, :4], M[:4, 4:], M[4:, 4:] = -F, Qc, F.T
    E = expm(M * dt)
    Phi = E[4:, 4:].T
    Q = Phi @ E[:4, 4:]
    H = np.array([1.0, 0, 0, 0])
    x = np.array([y[0], 0.0, 0.0, 0.0])
    P = np.diag([sig_eps**2, 0.05**2, sig_s**2, sig_f**2])
    xf, Pf = np.empty((n, 4)), np.empty((n, 4, 4))
    xp, Pp = np.empty((n, 4)), np.empty((n, 4, 4))
    for k in range(n):
        if k:
            x = Phi @ x
            P = Phi @ P @ Phi.T + Q
        xp[k], Pp[k] = x, P
        K = P @ H / (H @ P @ H + sig_eps**2)
        x = x + K * (y[k] - H @ x)
        P = P - np.outer(K, H @ P)
        xf[k], Pf[k] = x, P
    xs = xf.copy()
    for k in range(n - 2, -1, -1):
        C = Pf[k] @ Phi.T @ np.linalg.inv(Pp[k + 1])
        xs[k] = xf[k] + C @ (xs[k + 1] - xp[k + 1])
    return t, xs[:, 2], seed_truth(kind, t), v, None


# ------------------------------------------------------------------------------------------
# scoring
# ------------------------------------------------------------------------------------------
def _rms_mgal(x, truth, keep):
    return float(np.sqrt(np.mean((x - truth)[keep] ** 2)) / MGAL)


def method_rows():
    """(label, method, options) of every variant scored."""
    rows = [("smoothed estimate (input)", "none", {})]
    for w in ("db10", "coif4", "auto"):
        rows.append((f"ti_cosphi {w}", "ti_cosphi", {"wavelet": w}))
    rows.append(("ti_cosphi auto, no sigma guard", "ti_cosphi", {"wavelet": "auto", "_nosigma": 1}))
    for w in ("db10", "coif4"):
        for mode in ("symmetric", "periodization", "smooth"):
            for th in ("soft", "hard"):
                rows.append((f"cosphi {w} {mode} {th}", "cosphi", {"wavelet": w, "boundary": mode, "thresholding": th}))
    for m in ("visushrink", "sure", "bayes"):
        for w in ("db10", "coif4"):
            rows.append((f"{m} {w}", m, {"wavelet": w}))
    return rows


LOWPASS_GRID_S = (200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0)


def score(t, z, truth, speed, sigma=None):
    keep = (t >= t[0] + EDGE_S) & (t <= t[-1] - EDGE_S)
    dt = float(np.median(np.diff(t)))
    out = {}
    for label, method, opts in method_rows():
        opts = dict(opts)
        sg = None if opts.pop("_nosigma", None) else sigma
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            zt, info = W.postprocess(z, dt, speed, method, sigma=sg, **opts)
        out[label] = {
            "rms": _rms_mgal(zt, truth, keep),
            "n": info.get("n"),
            "Phi": info.get("Phi"),
            "res_km": (info.get("resolution_m") or 0) / 1e3 or None,
            "wavelet": info.get("wavelet"),
        }
    # low-pass baselines: at the default's resolution, and the oracle best over a grid
    res_default = out["ti_cosphi auto"]["res_km"]
    for m in ("butterworth", "gaussian"):
        if res_default:
            zt, info = W.postprocess(z, dt, speed, m, resolution_m=res_default * 1e3)
            out[f"{m} @ default's resolution"] = {
                "rms": _rms_mgal(zt, truth, keep),
                "n": None,
                "Phi": info["Phi"],
                "res_km": res_default,
            }
        best = None
        for p in LOWPASS_GRID_S:
            zt, info = W.postprocess(z, dt, speed, m, filter_length_s=p)
            r = _rms_mgal(zt, truth, keep)
            if best is None or r < best[0]:
                best = (r, info)
        out[f"{m} best of grid (ORACLE: tuned on truth)"] = {
            "rms": best[0],
            "n": None,
            "Phi": best[1]["Phi"],
            "res_km": best[1]["resolution_m"] / 1e3,
        }
    return out


def _fmt(v, nd=3):
    if v is None:
        return "-"
    if isinstance(v, float):
        if not np.isfinite(v):
            return "nan"
        return f"{v:.2e}" if (abs(v) < 1e-3 and v != 0) else f"{v:.{nd}f}"
    return str(v)


def table(results, names):
    labels = list(results[names[0]].keys())
    head = "| method | " + " | ".join(f"{n}: RMS mGal / n / Phi / res km" for n in names) + " |"
    lines = [head, "|---|" + "---|" * len(names)]
    for lab in labels:
        cells = []
        for n in names:
            r = results[n][lab]
            cells.append(f"{_fmt(r['rms'], 2)} / {_fmt(r['n'])} / {_fmt(r['Phi'])} / {_fmt(r['res_km'], 1)}")
        lines.append(f"| {lab} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def phi_curves(z, wavelet="db10"):
    """Phi(n) at full removal: decimated symmetric, decimated periodized (on a length divisible
    by 2^11, where the transform is exactly orthogonal), and translation-invariant."""
    n2 = (z.size // 2048) * 2048
    rows = []
    _, ti = W.ti_cosphi(z, wavelet)
    for n in range(1, W.n_levels(z.size) + 1):
        sym = W.phi_criterion(z, W.approximation(z, wavelet, n, "symmetric"))
        per = W.phi_criterion(z[:n2], W.approximation(z[:n2], wavelet, n, "periodization"))
        tphi = ti["phi_by_level"][n - 1] if n <= len(ti["phi_by_level"]) else float("nan")
        rows.append((n, sym, per, tphi))
    return rows


def _print_headline(results):
    print("## Headline: real pipeline (3D-INM + RTS), configs' own seeds\n")
    print(table(results, ["real smooth", "real steps", "real markov"]))


# ------------------------------------------------------------------------------------------
# survey lines: short lines and line edges on the real pipeline (docs/wavelet.md section 7)
# ------------------------------------------------------------------------------------------
def survey_line_estimates(which):
    """The smoothed estimate of every flight of a survey, its sigma, speed, truth (mGal) and the
    pipeline's line/tie segments (>= 8 samples), from the pipeline's own stages.

    ``which``: ``"grid_ros2"`` (sample_data/grid_ros2 as shipped) or ``"platform"`` /
    ``"strapdown"`` (configs/realistic_survey.yaml reduced to that flight and simulated into a
    temporary directory with benchmarks/run.py's functions).
    Yields ``(label, z, sigma, speed, truth_mgal, [(name, start, stop), ...])``.
    """
    import tempfile

    from gravsurvey.config import load_config
    from gravsurvey.inm.params import initial_state_from_gnss
    from gravsurvey.inm.solve import estimate_anomaly
    from gravsurvey.io.ingest import load_flight
    from gravsurvey.estimate import from_inm_solution
    from gravsurvey.pipeline import line_segments, read_truth_csv, truth_at

    tmp = None
    if which == "grid_ros2":
        cfg_path = REPO / "sample_data" / "grid_ros2" / "survey.yaml"
    else:
        import run as bench_run

        tmp = tempfile.TemporaryDirectory()
        cfg_path = bench_run.simulate(bench_run.survey_sim(which, False), Path(tmp.name), which)
    cfg = load_config(cfg_path)
    for fl in cfg.flights:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            record = load_flight(fl.ingest, cfg.base_dir)
            initial = fl.initial if fl.initial is not None else initial_state_from_gnss(record, fl.triad)
            sol = estimate_anomaly(record, cfg.model, initial, fl.triad, cfg.ellipsoid)
        t = np.asarray(sol.time, float)
        unix = record.t0_unix_ns + np.round(t * 1e9).astype(np.int64)
        truth = truth_at(read_truth_csv(fl.truth), unix)
        segs = [
            (s.name, int(s.start_index), int(s.stop_index))
            for s in line_segments(cfg, fl, from_inm_solution(sol))
            if s.kind in ("line", "tie") and s.stop_index - s.start_index >= 8
        ]
        yield (
            f"{which} {fl.name}",
            np.asarray(sol.g_smooth, float),
            np.asarray(sol.sigma_smooth, float),
            np.asarray(sol.speed, float),
            truth,
            segs,
        )
    if tmp is not None:
        tmp.cleanup()


def line_study(whiches=("grid_ros2", "platform", "strapdown")):
    """Per survey: RMS vs truth (mGal) over all lines, and in the first/last 5 % of every line
    vs the rest, for the input, the default without context (mirror at the line's ends), with
    context (gated, as the pipeline would pass it) and with context ungated; plus per line."""
    variants = {
        "default (mirror ends)": lambda z, a, b, dt, sp, sg: W.postprocess(z[a:b], dt, sp, sigma=sg),
        "default + context": lambda z, a, b, dt, sp, sg: W.postprocess(z[a:b], dt, sp, sigma=sg, context=(z, a, b)),
    }

    def ungated(z, a, b, dt, sp, sg):
        out, info = W.postprocess(z[a:b], dt, sp, sigma=sg)
        if info["n"]:
            out = W.ti_apply_with_context(z, a, b, info["wavelet"], info["n"], gate_ratio=float("inf"))
        return out, info

    variants["context, gate off"] = ungated
    print("\n## Survey lines: RMS vs truth, mGal (all lines / first+last 5 % / middle 90 %)\n")
    print("| flight | lines (samples) | input | " + " | ".join(variants) + " |")
    print("|---|---|---|" + "---|" * len(variants))
    per_line = []
    for label, z, sigma, speed, truth, segs in (x for w in whiches for x in survey_line_estimates(w)):
        dt = 1.0
        cols = {}
        for name, fn in [("input", None)] + list(variants.items()):
            allr, edge, mid = [], [], []
            for sname, a, b in segs:
                sp = float(np.nanmean(speed[a:b]))
                if fn is None:
                    out, info = z[a:b], {}
                else:
                    out, info = fn(z, a, b, dt, sp, sigma[a:b])
                e = out / MGAL - truth[a:b]
                k = max(1, int(0.05 * (b - a)))
                allr.append(e)
                edge.append(np.r_[e[:k], e[-k:]])
                mid.append(e[k:-k])
                if name == "default (mirror ends)":
                    per_line.append(
                        (
                            label,
                            sname,
                            b - a,
                            float(np.sqrt(np.mean((z[a:b] / MGAL - truth[a:b]) ** 2))),
                            float(np.sqrt(np.mean(e**2))),
                            info.get("n"),
                        )
                    )
            r = [float(np.sqrt(np.mean(np.concatenate(x) ** 2))) for x in (allr, edge, mid)]
            cols[name] = f"{r[0]:.2f} / {r[1]:.2f} / {r[2]:.2f}"
        lens = ",".join(str(b - a) for _, a, b in segs)
        print(f"| {label} | {lens} | " + " | ".join(cols.values()) + " |")
    print("\n| flight | line | samples | input | default | n |")
    print("|---|---|---|---|---|---|")
    for label, sname, n, rin, rout, lev in per_line:
        print(f"| {label} | {sname} | {n} | {rin:.2f} | {rout:.2f} | {lev} |")


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", default="1,2,3,5", help="extra noise realisations (comma list)")
    ap.add_argument("--no-surrogate", action="store_true")
    ap.add_argument("--curves-only", action="store_true", help="only the Phi(n) tables")
    ap.add_argument(
        "--lines", action="store_true", help="only the survey-line study (sample_data/grid_ros2, realistic survey)"
    )
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    if args.lines:
        line_study()
        print(f"\n(line study ran in {time.perf_counter() - t0:.0f} s)")
        return
    results, data = {}, {}
    for kind in ("smooth", "steps", "markov"):
        data[kind] = real_estimate(kind)
        if not args.curves_only:
            results[f"real {kind}"] = score(*data[kind])
    if args.curves_only:
        args.seeds, args.no_surrogate = "", True
    else:
        _print_headline(results)

    seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    if seeds:
        means = {}
        for kind in ("smooth", "steps"):
            per = [score(*real_estimate(kind, s)) for s in seeds]
            keys = per[0].keys()
            means[f"real {kind}, mean of {len(seeds)} seeds"] = {
                k: {
                    "rms": float(np.sqrt(np.mean([p[k]["rms"] ** 2 for p in per]))),
                    "n": "/".join(str(p[k]["n"]) for p in per) if per[0][k]["n"] is not None else None,
                    "Phi": None,
                    "res_km": per[0][k]["res_km"],
                }
                for k in keys
            }
        print(f"\n## Real pipeline, RMS over seeds {seeds} (n per seed)\n")
        print(table(means, list(means)))

    if not args.no_surrogate:
        sur = {f"SURROGATE {k}": score(*surrogate_estimate(k, seed=1)) for k in ("smooth", "steps")}
        print("\n## SURROGATE (vertical-channel KF+RTS, not the project's estimator)\n")
        print(table(sur, list(sur)))

    for kind in ("smooth", "steps"):
        t, z, truth = data[kind][:3]
        print(f"\n## Phi(n) at full removal, db10, real {kind}\n")
        print("| n | decimated symmetric | decimated periodized (N=2^11 k) | translation-invariant | TI RMS mGal |")
        print("|---|---|---|---|---|")
        keep = (t >= t[0] + EDGE_S) & (t <= t[-1] - EDGE_S)
        for n, s, p, ti in phi_curves(z):
            r = _rms_mgal(W.ti_approximation(z, "db10", n), truth, keep)
            print(f"| {n} | {_fmt(s)} | {_fmt(p)} | {_fmt(ti)} | {r:.2f} |")
        # long-period part of the estimator's error: what no low-pass post-processor can remove
        lp = filters.gaussian_lowpass(z - truth, 1.0, 2000.0)
        print(
            f"\nreal {kind}: RMS of the smoother's error at periods > ~2000 s "
            f"(Gaussian low-pass of the error): {np.sqrt(np.mean(lp[keep] ** 2)) / MGAL:.2f} mGal"
        )
    print(f"\n(study ran in {time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
