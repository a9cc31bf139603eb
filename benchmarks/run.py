#!/usr/bin/env python
"""gravsurvey benchmark suite: accuracy against truth, speed, scaling, per-stage peers.

Usage::

    python benchmarks/run.py [--quick] [--out benchmarks/results.json] [--only SECTION,...]

Sections (all on freshly simulated data with fixed seeds):

* ``stages``   -- the per-stage benchmark modules (bench_ingest, bench_inm, bench_wavelet), each
  ``run(quick) -> list[dict]``: our decoders/filters against their peers, same run.
* ``accuracy`` -- seed benchmark (smooth, steps; model.md section 3) and the realistic survey
  (platform, strapdown): RMS vs truth (mGal) of the forward filter, the RTS smoother, the final
  profile per post-processing method and the classic scalar reduction at the same resolution;
  crossover RMS for the survey.
* ``speed``    -- end to end, MCAP to deliverables (``pipeline.run_survey``), per flight-hour at
  10 Hz and 100 Hz IMU, per stage, peak memory (max RSS of a fresh child process).
* ``scaling``  -- the same at 1x, 4x, 16x the flight length.

Prints Markdown tables and writes them as JSON with machine info.  Exit status: 0 when every
section ran, 1 when any stage raised (the error is in the JSON and on stderr).  Timings are
reported, never asserted.
"""

from __future__ import annotations

import argparse
import copy
import importlib
import json
import math
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
import traceback
import warnings
from datetime import datetime, timezone
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
for p in (str(REPO), str(REPO / "benchmarks")):
    if p not in sys.path:
        sys.path.insert(0, p)

import numpy as np
import yaml

MGAL = 1e-5
STAGE_MODULES = ("bench_ingest", "bench_inm", "bench_wavelet")
SECTIONS = ("stages", "accuracy", "speed", "scaling")
#: seed scenarios are scored on the middle of the flight (model.md section 3)
SEED_EDGE_S = 600.0


# ------------------------------------------------------------------------------------------
# small helpers
# ------------------------------------------------------------------------------------------


def machine_info() -> dict:
    """CPU, cores, memory, OS, Python and library versions, git commit."""
    import numba
    import scipy

    cpu = platform.processor() or ""
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    mem_gb = None
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemTotal"):
                    mem_gb = round(int(line.split()[1]) / 1024**2, 1)
                    break
    except OSError:
        pass
    try:
        commit = subprocess.run(
            ["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=10, check=False
        ).stdout.strip()
        dirty = bool(
            subprocess.run(
                ["git", "-C", str(REPO), "status", "--porcelain"],
                capture_output=True,
                text=True,
                timeout=10,
                check=False,
            ).stdout.strip()
        )
    except (OSError, subprocess.SubprocessError):
        commit, dirty = "", None
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "memory_gb": mem_gb,
        "os": platform.platform(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "numba": numba.__version__,
        "git_commit": commit,
        "git_dirty": dirty,
        "date_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
    }


def rms(x) -> float | None:
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x**2))) if x.size else None


def empirical_resolution_m(estimate, truth, dt_s, speed_mps, nperseg=1024):
    """Half-wavelength resolution from the measured transfer function estimate/truth.

    ``H(f) = P_xy(f) / P_xx(f)`` (Welch, x = truth, y = estimate); the resolution is
    ``speed / (2 f_half)`` with ``f_half`` the lowest frequency where ``|H|`` falls below 0.5.
    Only meaningful for broadband truth (a Markov field, a survey over masses); returns None when
    the truth has too little power at that frequency to measure ``H`` (its PSD below the error's).
    """
    from scipy.signal import csd, welch

    x = np.asarray(truth, float)
    y = np.asarray(estimate, float)
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    if x.size < 64:
        return None
    nperseg = int(min(nperseg, x.size // 2))
    f, pxx = welch(x - x.mean(), fs=1.0 / dt_s, nperseg=nperseg)
    _, pxy = csd(x - x.mean(), y - y.mean(), fs=1.0 / dt_s, nperseg=nperseg)
    _, pee = welch((y - x) - (y - x).mean(), fs=1.0 / dt_s, nperseg=nperseg)
    h = np.abs(pxy) / np.maximum(pxx, 1e-300)
    below = np.nonzero((h < 0.5) & (f > 0))[0]
    if below.size == 0:
        return None
    i = below[0]
    if pxx[i] < pee[i]:
        # the truth has less power than the error there: H is not measurable (e.g. the
        # seed's smooth anomaly, three spectral lines)
        return None
    # linear interpolation of the 0.5 crossing between bins i-1 and i
    if i > 0 and h[i - 1] >= 0.5:
        fi = f[i - 1] + (h[i - 1] - 0.5) / (h[i - 1] - h[i]) * (f[i] - f[i - 1])
    else:
        fi = f[i]
    return float(speed_mps / (2.0 * fi))


class Errors:
    """Collects stage failures; the run exits non-zero when there are any."""

    def __init__(self):
        self.items: list[dict] = []

    def add(self, where: str, exc: BaseException):
        msg = f"{type(exc).__name__}: {exc}"
        self.items.append({"where": where, "error": msg, "traceback": traceback.format_exc()})
        print(f"benchmark error in {where}: {msg}", file=sys.stderr)


# ------------------------------------------------------------------------------------------
# stages: the per-stage modules of the other issues
# ------------------------------------------------------------------------------------------


def run_stages(quick: bool, errors: Errors) -> dict:
    out = {}
    for name in STAGE_MODULES:
        t = time.perf_counter()
        try:
            mod = importlib.import_module(f"benchmarks.{name}")
            rows = mod.run(quick)
            if not isinstance(rows, list) or not all(isinstance(r, dict) for r in rows):
                raise TypeError(f"{name}.run must return a list of dicts, got {type(rows).__name__}")
            out[name] = {"rows": rows, "seconds": time.perf_counter() - t}
        except Exception as exc:  # report, keep going, fail at the end
            errors.add(f"stages/{name}", exc)
            out[name] = {"error": f"{type(exc).__name__}: {exc}", "seconds": time.perf_counter() - t}
    return out


# ------------------------------------------------------------------------------------------
# simulation helpers
# ------------------------------------------------------------------------------------------


def load_sim_yaml(name: str) -> dict:
    path = REPO / "configs" / name
    with open(path) as fh:
        return yaml.safe_load(fh)


def simulate(sim: dict, work: Path, tag: str) -> Path:
    """Write ``sim`` as SIM.yaml, run the simulator into ``work/tag``; return the survey.yaml."""
    from gravsurvey.simulate.run import simulate_to_dir

    d = work / tag
    d.mkdir(parents=True, exist_ok=True)
    sim_path = d / "SIM.yaml"
    with open(sim_path, "w") as fh:
        yaml.safe_dump(sim, fh, sort_keys=False)
    simulate_to_dir(sim_path, d / "data")
    cfg = d / "data" / "survey.yaml"
    if not cfg.is_file():
        found = sorted((d / "data").rglob("survey.yaml"))
        if not found:
            raise FileNotFoundError(f"simulator wrote no survey.yaml under {d / 'data'}")
        cfg = found[0]
    return cfg


def _set_path(d: dict, path: str, value):
    """Set ``d['a']['b'][0]['c']`` from 'a.b.0.c' (creating mappings as needed)."""
    keys = path.split(".")
    cur = d
    for k in keys[:-1]:
        if isinstance(cur, list):
            cur = cur[int(k)]
        else:
            cur = cur.setdefault(k, {})
    last = keys[-1]
    if isinstance(cur, list):
        cur[int(last)] = value
    else:
        cur[last] = value


def _edit_survey_yaml(cfg_path: Path, edits: dict) -> None:
    with open(cfg_path) as fh:
        d = yaml.safe_load(fh)
    for k, v in edits.items():
        _set_path(d, k, v)
    with open(cfg_path, "w") as fh:
        yaml.safe_dump(d, fh, sort_keys=False)


# ------------------------------------------------------------------------------------------
# accuracy
# ------------------------------------------------------------------------------------------


def evaluate_flight(cfg, fl, methods, edge_s: float):
    """Process one flight stage by stage and score every estimate against truth.

    Returns (per-estimate arrays dict, line dicts for crossovers, facts).
    """
    from gravsurvey.classic import classic_reduction
    from gravsurvey.inm.params import initial_state_from_gnss
    from gravsurvey.inm.solve import estimate_anomaly
    from gravsurvey.io.ingest import load_flight
    from gravsurvey.estimate import from_inm_solution
    from gravsurvey.pipeline import line_segments, read_truth_csv, truth_at
    from gravsurvey.wavelet import postprocess

    timings = {}
    t = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        record = load_flight(fl.ingest, cfg.base_dir)
    timings["ingest_s"] = time.perf_counter() - t
    initial = fl.initial if fl.initial is not None else initial_state_from_gnss(record, fl.triad)
    t = time.perf_counter()
    sol = estimate_anomaly(record, cfg.model, initial, fl.triad, cfg.ellipsoid)
    timings["estimate_s"] = time.perf_counter() - t
    time_s = np.asarray(sol.time, float)
    unix = record.t0_unix_ns + np.round(time_s * 1e9).astype(np.int64)
    truth = truth_at(read_truth_csv(fl.truth), unix) * MGAL
    n = time_s.size
    dt = float(np.median(np.diff(time_s)))
    segs = [
        s
        for s in line_segments(cfg, fl, from_inm_solution(sol))
        if s.kind in ("line", "tie") and s.stop_index - s.start_index >= 8
    ]
    in_line = np.zeros(n, bool)
    for s in segs:
        in_line[s.start_index : s.stop_index] = True
    keep = in_line & (time_s >= time_s[0] + edge_s) & (time_s <= time_s[-1] - edge_s)

    est = {"forward": np.asarray(sol.g_forward, float), "smoother": np.asarray(sol.g_smooth, float)}
    resolution = {"forward": None, "smoother": None}
    how = {"forward": "-", "smoother": "-"}
    infos = {}
    notes = []
    t = time.perf_counter()
    # default method first: its resolution sets the low-pass baselines and the classic row
    default_res = []
    for m in methods:
        z = np.full(n, np.nan)
        res_list = []
        for s in segs:
            a, b = s.start_index, s.stop_index
            speed = float(np.nanmean(np.asarray(sol.speed)[a:b]))
            kw = {}
            if m in ("butterworth", "gaussian"):
                r = float(np.median(default_res)) if default_res else 3000.0
                kw["resolution_m"] = r
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                # exactly as gravsurvey.pipeline calls it: the smoother's sigma and the flight as context
                g_full = np.asarray(sol.g_smooth, float)
                out, info = postprocess(
                    g_full[a:b],
                    dt,
                    speed,
                    method=m,
                    sigma=np.asarray(sol.sigma_smooth, float)[a:b],
                    context=(g_full, a, b),
                    **kw,
                )
            for w in caught:
                notes.append(f"{m} {s.name}: {w.message}")
            z[a:b] = out
            if info.get("resolution_m"):
                res_list.append(float(info["resolution_m"]))
            infos.setdefault(m, []).append({k: info.get(k) for k in ("method", "wavelet", "n", "Phi", "resolution_m")})
        if m == methods[0]:
            default_res = res_list
        est[m] = z
        resolution[m] = float(np.median(res_list)) if res_list else None
        how[m] = "filter transfer function" if res_list else "-"
    timings["postprocess_s"] = time.perf_counter() - t

    # classic scalar reduction at the default method's resolution
    t = time.perf_counter()
    r_classic = float(np.median(default_res)) if default_res else None
    track = None if record.gnss is not None else sol
    mat_nt = None
    if fl.triad == "strapdown":
        mat_nt = _attitude_at_imu(sol, record, initial, cfg)
    try:
        # same radial information as the 3D-INM: the altimeter (GNSS only for the horizontal
        # track of the Eotvos correction)
        cr = classic_reduction(
            record,
            ellipsoid=cfg.ellipsoid,
            resolution_m=r_classic,
            mat_nt=mat_nt,
            triad=fl.triad,
            track=track,
            height_source="altimeter",
        )
        est["classic"] = np.interp(time_s, cr.time, cr.disturbance, left=np.nan, right=np.nan)
        resolution["classic"] = cr.info["resolution_m"]
        how["classic"] = "Gaussian FIR transfer function (-6 dB)"
        infos["classic"] = {
            k: cr.info[k] for k in ("filter_length_s", "resolution_m", "height_source", "velocity_source", "attitude")
        }
    finally:
        timings["classic_s"] = time.perf_counter() - t

    speed_all = float(np.nanmedian(np.asarray(sol.speed)[in_line])) if in_line.any() else float(np.nanmedian(sol.speed))
    lines = []
    for s in segs:
        a, b = s.start_index, s.stop_index
        lines.append({"name": s.name, "a": a, "b": b})
    facts = {
        "n_epochs": n,
        "n_scored": int(keep.sum()),
        "dt_s": dt,
        "speed_mps": speed_all,
        "lines": len(segs),
        "timings_s": timings,
        "infos": infos,
        "resolution": resolution,
        "resolution_how": how,
        "notes": notes,
    }
    return (
        {
            "time": time_s,
            "truth": truth,
            "keep": keep,
            "est": est,
            "lat": np.asarray(sol.lat),
            "lon": np.asarray(sol.lon),
        },
        lines,
        facts,
    )


def _attitude_at_imu(sol, record, initial, cfg):
    """Triad -> ENU attitude at the IMU epochs (for classic, strapdown).

    ``sol.mat_nt`` when the 3D-INM solution carries one at the IMU epochs; otherwise
    :func:`gravsurvey.classic.strapdown_attitude` (the 3D-INM mechanization's gyro attitude).
    """
    from gravsurvey.classic import strapdown_attitude

    mat = getattr(sol, "mat_nt", None)
    if mat is not None and np.shape(mat)[0] == np.size(record.imu.time):
        return np.asarray(mat, float)
    return strapdown_attitude(
        record, initial, ellipsoid=cfg.ellipsoid, use_altimeter=cfg.model.radius_source == "altimeter"
    )


def score_scenario(
    name: str, cfg_path: Path, methods, edge_s: float, errors: Errors, crossovers: bool, measure_resolution: bool = True
):
    from gravsurvey.config import load_config

    cfg = load_config(cfg_path)
    rows, per_flight, facts_all = [], [], {}
    for fl in cfg.flights:
        try:
            arrays, lines, facts = evaluate_flight(cfg, fl, methods, edge_s)
        except Exception as exc:
            errors.add(f"accuracy/{name}/{fl.name}", exc)
            continue
        per_flight.append((fl, arrays, lines))
        facts_all[fl.name] = facts
    if not per_flight:
        return rows, [], facts_all
    names = list(per_flight[0][1]["est"].keys())
    for est_name in names:
        err = np.concatenate([a["est"][est_name][a["keep"]] - a["truth"][a["keep"]] for _, a, _ in per_flight])
        both = np.concatenate([a["keep"] & np.isfinite(a["est"][est_name]) for _, a, _ in per_flight])
        f0 = facts_all[per_flight[0][0].name]
        emp = None
        if measure_resolution:
            fl, a, _ = per_flight[0]
            m = a["keep"] & np.isfinite(a["est"][est_name])
            if m.sum() > 256:
                emp = empirical_resolution_m(a["est"][est_name][m], a["truth"][m], f0["dt_s"], f0["speed_mps"])
        rows.append(
            {
                "scenario": name,
                "triad": per_flight[0][0].triad,
                "estimate": est_name,
                "rms_mgal": (rms(err) or float("nan")) / MGAL,
                "resolution_m": f0["resolution"].get(est_name),
                "resolution_how": f0["resolution_how"].get(est_name),
                "empirical_resolution_m": emp,
                "n_scored": int(np.sum(both)),
            }
        )
    xo_rows = []
    if crossovers:
        xo_rows = _crossovers(name, per_flight, names, errors)
    return rows, xo_rows, facts_all


def _crossovers(name, per_flight, names, errors):
    from gravsurvey.georef import project
    from gravsurvey.crossovers import find_crossovers

    out = []
    lat = np.concatenate([a["lat"] for _, a, _ in per_flight])
    lon = np.concatenate([a["lon"] for _, a, _ in per_flight])
    _, _, epsg = project(lat, lon)
    for est_name in names:
        if est_name == "forward":
            continue
        try:
            lines = []
            for fl, a, segs in per_flight:
                e, nn, _ = project(a["lat"], a["lon"], epsg)
                for s in segs:
                    sl = slice(s["a"], s["b"])
                    v = a["est"][est_name][sl] / MGAL
                    ok = np.isfinite(v)
                    if ok.sum() < 2:
                        continue
                    lines.append(
                        {
                            "flight": fl.name,
                            "line": s["name"],
                            "easting_m": e[sl][ok],
                            "northing_m": nn[sl][ok],
                            "value_mgal": v[ok],
                            "time_s": a["time"][sl][ok],
                        }
                    )
            st = find_crossovers(lines).statistics()
            out.append(
                {
                    "scenario": name,
                    "estimate": est_name,
                    "count": st.get("count"),
                    "mean_mgal": st.get("mean_mgal"),
                    "rms_mgal": st.get("rms_mgal"),
                    "rms_over_sqrt2_mgal": st.get("rms_over_sqrt2_mgal"),
                }
            )
        except Exception as exc:
            errors.add(f"crossovers/{name}/{est_name}", exc)
    return out


def run_accuracy(quick: bool, work: Path, errors: Errors) -> dict:
    from gravsurvey.wavelet import DEFAULT_METHOD, METHODS

    methods = [DEFAULT_METHOD] + [m for m in METHODS if m not in (DEFAULT_METHOD, "none")]
    rows, xo, facts = [], [], {}
    for sc in scenario_list(quick):
        t = time.perf_counter()
        try:
            sim = sc["sim"]()
            cfg_path = simulate(sim, work, sc["name"])
            if sc.get("survey_edits"):
                _edit_survey_yaml(cfg_path, sc["survey_edits"])
        except Exception as exc:
            errors.add(f"accuracy/{sc['name']}/simulate", exc)
            continue
        t_sim = time.perf_counter() - t
        r, x, f = score_scenario(
            sc["name"], cfg_path, methods, sc["edge_s"], errors, sc["crossovers"], sc["measure_resolution"]
        )
        rows += r
        xo += x
        facts[sc["name"]] = {"simulate_s": t_sim, "flights": f, "description": sc["description"]}
    return {"rows": rows, "crossovers": xo, "facts": facts}


# Scenario definitions -------------------------------------------------------------------


def scenario_list(quick: bool) -> list[dict]:
    """Accuracy scenarios (fixed seeds from the SIM files).  Quick: the same physics, shorter."""
    sc = []
    # the Markov experiment is the broadband case for the measured resolution: full runs only
    for kind in ("smooth", "steps") if quick else ("smooth", "steps", "markov"):
        sc.append(
            {
                "name": f"seed_{kind}",
                "description": f"seed benchmark, {kind} anomaly (model.md section 3), platform",
                "sim": (lambda k=kind: _seed_sim(k, quick)),
                "edge_s": SEED_EDGE_S,
                "crossovers": False,
                "measure_resolution": True,
                "survey_edits": {},
            }
        )
    for triad in ("platform", "strapdown"):
        sc.append(
            {
                "name": f"survey_{triad}",
                "description": f"realistic survey, {triad} triad",
                "sim": (lambda tr=triad: survey_sim(tr, quick)),
                "edge_s": 0.0,
                "crossovers": True,
                # lines of 200-500 s cannot resolve a transfer function at ~10 km half-wavelength
                "measure_resolution": False,
                "survey_edits": {},
            }
        )
    return sc


def _seed_sim(kind: str, quick: bool) -> dict:
    """configs/seed_<kind>.yaml as is (4 h at 10 Hz simulates and processes in seconds)."""
    return load_sim_yaml(f"seed_{kind}.yaml")


#: quick variant of the realistic survey: the same field, sensors and turbulence, fewer and
#: shorter lines, so the whole --quick suite stays within a few minutes
QUICK_SURVEY_PLAN = {
    "lines": {"count": 4, "spacing_m": 4000.0, "length_m": 16000.0, "heading_deg": 0.0},
    "ties": {"count": 2, "spacing_m": 8000.0, "altitude_m": 800.0},
    "static_start_s": 120.0,
    "static_end_s": 120.0,
}


def survey_sim(triad: str, quick: bool) -> dict:
    """configs/realistic_survey.yaml reduced to its flight with the given triad."""
    sim = copy.deepcopy(load_sim_yaml("realistic_survey.yaml"))
    flights = [f for f in sim["flights"] if f.get("triad") == triad]
    if not flights:
        raise KeyError(f"configs/realistic_survey.yaml has no {triad} flight")
    sim["flights"] = flights[:1]
    sim["name"] = f"realistic_survey_{triad}"
    if quick:
        fl = sim["flights"][0]
        fl["plan"] = {**fl["plan"], **copy.deepcopy(QUICK_SURVEY_PLAN)}
    return sim


# ------------------------------------------------------------------------------------------
# speed and scaling: a fresh child process per case (clean max RSS, no leftovers)
# ------------------------------------------------------------------------------------------


def _vm_hwm_mb() -> float:
    """Peak resident set of this process image, MB (``VmHWM``).

    Not ``ru_maxrss``: on Linux a child's ``ru_maxrss`` starts at the parent's RSS at fork
    (the pre-exec image's high-water mark is kept), which would report the benchmark driver's
    memory instead of the run's.
    """
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def speed_child(spec: dict) -> dict:
    """Run in a child: simulate (untimed, separate grandchild), then time run_survey end to end."""
    from gravsurvey.pipeline import run_survey

    cfg_path = Path(spec["config"])
    rss0 = _vm_hwm_mb()
    # warm-up on the small flight so numba's cache load / compile is not in the timing
    if spec.get("warmup_config"):
        run_survey(spec["warmup_config"], output_dir=str(Path(spec["out"]) / "warmup"), force=True)
    rss_warm = _vm_hwm_mb()
    t = time.perf_counter()
    res = run_survey(str(cfg_path), output_dir=str(Path(spec["out"]) / "run"), force=True)
    total = time.perf_counter() - t
    if res.failed:
        raise RuntimeError(f"run_survey failed: {res.failed[0].splitlines()[0]}")
    fl = next(iter(res.summary["flights"].values()))
    tim = dict(fl.get("timings_s") or {})
    stage_sum = sum(v for v in tim.values() if isinstance(v, (int, float)))
    tim["outputs_s"] = total - stage_sum
    # split estimate_s: time the mechanization alone on the same record (same work as inside
    # estimate_anomaly); filter+smoother (discretisation, Kalman, RTS, georeferencing) is the rest
    try:
        tim["mechanization_s"] = _time_mechanization(cfg_path)
        tim["filter_smoother_s"] = tim["estimate_s"] - tim["mechanization_s"]
    except Exception as exc:  # reported, and the run fails at the end
        raise RuntimeError(f"mechanization timing: {type(exc).__name__}: {exc}") from exc
    max_rss = _vm_hwm_mb()
    # peak of the run's own allocations (numpy buffers + Python objects): a second, untimed run
    # under tracemalloc (it slows allocation, so it is kept out of the timing)
    import tracemalloc

    tracemalloc.start()
    run_survey(str(cfg_path), output_dir=str(Path(spec["out"]) / "traced"), force=True)
    _, traced_peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return {
        "total_s": total,
        "timings_s": tim,
        "max_rss_mb": max_rss,
        "rss_after_import_mb": rss0,
        "rss_after_warmup_mb": rss_warm,
        "traced_peak_mb": traced_peak / 2**20,
    }


def _time_mechanization(cfg_path) -> float:
    from gravsurvey.config import load_config
    from gravsurvey.inm.mechanization import mechanize
    from gravsurvey.inm.params import initial_state_from_gnss
    from gravsurvey.io.ingest import load_flight

    cfg = load_config(cfg_path)
    fl = cfg.flights[0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = load_flight(fl.ingest, cfg.base_dir)
    initial = fl.initial if fl.initial is not None else initial_state_from_gnss(rec, fl.triad)
    t = time.perf_counter()
    mechanize(
        rec.imu.time,
        rec.imu.specific_force_t,
        rec.imu.angular_rate_t,
        initial,
        rec.altimeter.time,
        rec.altimeter.height,
        use_ext=cfg.model.radius_source == "altimeter",
        ellipsoid=cfg.ellipsoid,
    )
    return time.perf_counter() - t


def _run_child(kind: str, spec: dict, timeout: float) -> dict:
    cmd = [sys.executable, str(Path(__file__).resolve()), f"--child-{kind}", json.dumps(spec)]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, check=False)
    if p.returncode != 0:
        tail = (p.stderr or p.stdout).strip().splitlines()[-5:]
        raise RuntimeError(f"child {kind} exited {p.returncode}: " + " | ".join(tail))
    return json.loads(p.stdout.strip().splitlines()[-1])


def simulate_child(spec: dict) -> dict:
    """Simulate every case of ``spec['cases']`` (one process for all; not timed as processing)."""
    out = []
    for case in spec["cases"]:
        t = time.perf_counter()
        sim = speed_sim(case["duration_s"], case["imu_hz"])
        cfg = simulate(sim, Path(spec["work"]), case["tag"])
        out.append({"config": str(cfg), "simulate_s": time.perf_counter() - t})
    return {"cases": out}


def speed_sim(duration_s: float, imu_hz: float) -> dict:
    """A straight platform flight, seed sensor noise, smooth seed anomaly, MCAP ROS 2 logs."""
    from gravsurvey.simulate.run import quick_sim

    return quick_sim(duration_s=duration_s, imu_hz=imu_hz, noise=True, field="seed_smooth", formats=["mcap_ros2"])


def run_speed(quick: bool, work: Path, errors: Errors, lengths=(1,), rates=(10.0, 100.0), base_s=None, tag="speed"):
    """End-to-end timings: one child simulates all cases, then one fresh child per case runs
    ``pipeline.run_survey`` (after a warm-up flight, so numba's cache load is not timed)."""
    base_s = base_s or (600.0 if quick else 3600.0)
    cases = [{"duration_s": 600.0, "imu_hz": 10.0, "tag": f"{tag}_warm"}]
    for rate in rates:
        for mult in lengths:
            cases.append({"duration_s": base_s * mult, "imu_hz": rate, "mult": mult, "tag": f"{tag}_{rate:g}_{mult}"})
    try:
        sims = _run_child("simulate", {"cases": cases, "work": str(work)}, 7200)["cases"]
    except Exception as exc:
        errors.add(f"{tag}/simulate", exc)
        return []
    warm = sims[0]
    rows = []
    for case, s in zip(cases[1:], sims[1:]):
        name = f"{tag}/{case['imu_hz']:g}Hz/{case['duration_s'] / 3600:g}h"
        try:
            r = _run_child(
                "speed",
                {"config": s["config"], "warmup_config": warm["config"], "out": str(work / f"{case['tag']}_out")},
                7200,
            )
        except Exception as exc:
            errors.add(name, exc)
            continue
        hours = case["duration_s"] / 3600.0
        rows.append(
            {
                "imu_hz": case["imu_hz"],
                "length_x": case["mult"],
                "flight_h": hours,
                "total_s": r["total_s"],
                "s_per_flight_h": r["total_s"] / hours,
                **{k: v for k, v in r["timings_s"].items()},
                "max_rss_mb": r["max_rss_mb"],
                "rss_after_warmup_mb": r["rss_after_warmup_mb"],
                "traced_peak_mb": r["traced_peak_mb"],
                "simulate_s": s["simulate_s"],
            }
        )
    return rows


# ------------------------------------------------------------------------------------------
# Markdown
# ------------------------------------------------------------------------------------------


def _fmt(v, nd=3):
    if v is None:
        return "-"
    if isinstance(v, float):
        if not math.isfinite(v):
            return "nan"
        if abs(v) >= 1000:
            return f"{v:.0f}"
        return (
            f"{v:.{nd}g}" if abs(v) < 1e-2 and v != 0 else f"{v:.{nd}f}".rstrip("0").rstrip(".") if nd else f"{v:.0f}"
        )
    return str(v)


def md_table(rows: list[dict], cols: list[tuple[str, str]]) -> str:
    if not rows:
        return "(no rows)\n"
    head = "| " + " | ".join(h for _, h in cols) + " |"
    sep = "|" + "|".join("---" for _ in cols) + "|"
    body = ["| " + " | ".join(_fmt(r.get(k)) for k, _ in cols) + " |" for r in rows]
    return "\n".join([head, sep, *body]) + "\n"


def markdown(results: dict) -> str:
    out = [f"# gravsurvey benchmarks ({'quick' if results['quick'] else 'full'})\n"]
    m = results["machine"]
    out.append(
        f"Machine: {m['cpu']}, {m['cores']} cores, {m['memory_gb']} GB; {m['os']}; Python {m['python']}, "
        f"numpy {m['numpy']}, numba {m['numba']}; commit {m['git_commit'][:10]}{' (dirty)' if m['git_dirty'] else ''}; "
        f"{m['date_utc']}\n"
    )
    acc = results.get("accuracy")
    if acc:
        out.append("## Accuracy (RMS error vs truth, mGal)\n")
        out.append(
            md_table(
                acc["rows"],
                [
                    ("scenario", "scenario"),
                    ("triad", "triad"),
                    ("estimate", "estimate"),
                    ("rms_mgal", "RMS mGal"),
                    ("resolution_m", "half-wavelength m (stated)"),
                    ("empirical_resolution_m", "half-wavelength m (measured |H|=0.5)"),
                    ("n_scored", "samples"),
                ],
            )
        )
        if acc.get("crossovers"):
            out.append("\n### Crossovers (realistic survey)\n")
            out.append(
                md_table(
                    acc["crossovers"],
                    [
                        ("scenario", "scenario"),
                        ("estimate", "estimate"),
                        ("count", "crossovers"),
                        ("mean_mgal", "mean mGal"),
                        ("rms_mgal", "RMS mGal"),
                        ("rms_over_sqrt2_mgal", "RMS/sqrt2 mGal"),
                    ],
                )
            )
    for key, title in (
        ("speed", "Speed (end to end, MCAP -> deliverables)"),
        ("scaling", "Scaling with flight length"),
    ):
        rows = results.get(key)
        if rows:
            out.append(f"\n## {title}\n")
            out.append(
                md_table(
                    rows,
                    [
                        ("imu_hz", "IMU Hz"),
                        ("length_x", "length x"),
                        ("flight_h", "flight h"),
                        ("ingest_s", "ingest s"),
                        ("mechanization_s", "mechanization s"),
                        ("filter_smoother_s", "filter+smoother s"),
                        ("postprocess_s", "segmentation+wavelet s"),
                        ("outputs_s", "outputs s"),
                        ("total_s", "total s"),
                        ("s_per_flight_h", "s per flight-hour"),
                        ("rss_after_warmup_mb", "RSS after warm-up MB"),
                        ("max_rss_mb", "peak RSS MB"),
                        ("traced_peak_mb", "peak allocated MB (tracemalloc)"),
                    ],
                )
            )
    st = results.get("stages")
    if st:
        out.append("\n## Per-stage benchmarks (peers measured in the same run)\n")
        for name, v in st.items():
            out.append(f"\n### {name}\n")
            if "error" in v:
                out.append(f"ERROR: {v['error']}\n")
                continue
            rows = v["rows"]
            cols = []
            for r in rows:
                for k in r:
                    if k not in cols:
                        cols.append(k)
            out.append(md_table(rows, [(c, c) for c in cols]))
    if results["errors"]:
        out.append("\n## Errors\n")
        for e in results["errors"]:
            out.append(f"- {e['where']}: {e['error']}\n")
    return "\n".join(out)


# ------------------------------------------------------------------------------------------
# main
# ------------------------------------------------------------------------------------------


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="short flights: a few minutes in all (CI)")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results.json"), help="JSON output path")
    ap.add_argument("--only", default=",".join(SECTIONS), help=f"comma-separated subset of {','.join(SECTIONS)}")
    ap.add_argument("--workdir", default=None, help="keep simulated data here (default: a temp dir)")
    ap.add_argument("--child-speed", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--child-simulate", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)

    if args.child_speed:
        print(json.dumps(speed_child(json.loads(args.child_speed))))
        return 0
    if args.child_simulate:
        print(json.dumps(simulate_child(json.loads(args.child_simulate))))
        return 0

    only = [s.strip() for s in args.only.split(",") if s.strip()]
    bad = [s for s in only if s not in SECTIONS]
    if bad:
        ap.error(f"--only: unknown section(s) {', '.join(bad)}; expected {', '.join(SECTIONS)}")
    errors = Errors()
    t_all = time.perf_counter()
    results = {
        "quick": args.quick,
        "machine": machine_info(),
        "command": " ".join(["python", "benchmarks/run.py", *(argv or sys.argv[1:])]),
    }
    tmp = None
    if args.workdir:
        work = Path(args.workdir)
        work.mkdir(parents=True, exist_ok=True)
    else:
        tmp = tempfile.TemporaryDirectory(prefix="gravsurvey-bench-")
        work = Path(tmp.name)
    try:
        section_s = {}
        if "accuracy" in only:
            t = time.perf_counter()
            results["accuracy"] = run_accuracy(args.quick, work, errors)
            section_s["accuracy"] = time.perf_counter() - t
        if "speed" in only:
            t = time.perf_counter()
            results["speed"] = run_speed(args.quick, work, errors, lengths=(1,), tag="speed")
            section_s["speed"] = time.perf_counter() - t
        if "scaling" in only:
            t = time.perf_counter()
            results["scaling"] = run_speed(
                args.quick,
                work,
                errors,
                lengths=(1, 4, 16),
                rates=(10.0,),
                base_s=(300.0 if args.quick else 3600.0),
                tag="scaling",
            )
            section_s["scaling"] = time.perf_counter() - t
        if "stages" in only:
            t = time.perf_counter()
            results["stages"] = run_stages(args.quick, errors)
            section_s["stages"] = time.perf_counter() - t
        results["section_seconds"] = section_s
    finally:
        if tmp is not None:
            tmp.cleanup()
    results["errors"] = errors.items
    results["total_seconds"] = time.perf_counter() - t_all
    text = markdown(results)
    print(text)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp_out = out.with_suffix(out.suffix + ".tmp")
    with open(tmp_out, "w") as fh:
        json.dump(_jsonable(results), fh, indent=1)
    os.replace(tmp_out, out)
    return 1 if errors.items else 0


def _jsonable(o):
    if isinstance(o, dict):
        return {str(k): _jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_jsonable(v) for v in o]
    if isinstance(o, np.ndarray):
        return _jsonable(o.tolist())
    if isinstance(o, (np.floating, float)):
        v = float(o)
        return v if math.isfinite(v) else None
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, (np.bool_,)):
        return bool(o)
    if isinstance(o, Path):
        return str(o)
    return o


if __name__ == "__main__":
    sys.exit(main())
