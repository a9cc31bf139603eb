"""One flight, then a survey of flights.

``process_flight`` runs one flight through ingest -> 3D-INM Kalman/RTS (or the classic
reduction) -> line segmentation -> post-processing per line, and returns plain arrays.
``run_survey`` runs every flight (in parallel with ``jobs > 1``), projects, finds crossovers
and writes the deliverables atomically into the output directory under a lock.
"""

from __future__ import annotations

import hashlib
import json
import logging
import platform
import time
import traceback
import warnings
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from . import __version__
from .config import FlightConfig, SurveyConfig, load_config
from .errors import DataError, GravsurveyError, os_fault
from .geodesy import MGAL
from .io.writers import to_jsonable

log = logging.getLogger("gravsurvey")

CACHE_VERSION = 3


# --------------------------------------------------------------------------
# truth files written by the simulator (docs/formats.md); read here as any
# user-supplied truth would be: a documented CSV, no simulator code involved
# --------------------------------------------------------------------------


def read_truth_csv(path: Path) -> dict:
    """Read a truth.csv (docs/formats.md): ``time_ns`` (int64) and float columns."""
    import csv

    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: truth file not found")
    with open(path, newline="") as fh:
        rows = [r for r in csv.reader(line for line in fh if not line.startswith("#"))]
    if len(rows) < 2:
        raise DataError(f"{path}: truth file has no data rows")
    head = [h.strip() for h in rows[0]]
    for need in ("time_ns", "disturbance_mgal"):
        if need not in head:
            raise DataError(f"{path}: truth file lacks column {need!r}; has {', '.join(head)}")
    cols: dict = {h: [] for h in head}
    for ln, r in enumerate(rows[1:], start=2):
        if len(r) != len(head):
            raise DataError(f"{path}: data row {ln} has {len(r)} fields, header has {len(head)}")
        for h, v in zip(head, r):
            cols[h].append(v)
    out = {}
    for h, v in cols.items():
        try:
            out[h] = np.array(v, dtype=np.int64) if h == "time_ns" else np.array(v, dtype=float)
        except ValueError:
            out[h] = np.array(v, dtype=object)
    return out


def _truth_at(truth: dict, unix_ns: np.ndarray) -> np.ndarray:
    """Truth disturbance (mGal) interpolated to the given Unix ns; NaN outside the truth span."""
    t_ref = truth["time_ns"][0]
    tt = (truth["time_ns"] - t_ref).astype(float)
    x = (unix_ns - t_ref).astype(float)
    return np.interp(x, tt, truth["disturbance_mgal"], left=np.nan, right=np.nan)


# --------------------------------------------------------------------------
# one flight
# --------------------------------------------------------------------------


@dataclass
class FlightResult:
    """Arrays and facts about one processed flight (picklable; cached between runs)."""

    name: str
    t0_unix_ns: int
    time: np.ndarray  # s after t0, filter epochs
    lat: np.ndarray  # rad
    lon: np.ndarray  # rad
    height: np.ndarray  # m
    speed: np.ndarray  # m/s
    kalman: np.ndarray  # m/s^2 smoothed estimate (before post-processing)
    forward: np.ndarray  # m/s^2 forward filter
    sigma: np.ndarray  # m/s^2 1-sigma of the smoothed estimate
    final: np.ndarray  # m/s^2 after post-processing, NaN outside lines
    line: np.ndarray  # object array of line names ('' outside lines)
    segments: list  # dicts: name, kind, start_s, stop_s, n
    line_info: dict  # line -> post-processor info
    truth: np.ndarray | None  # mGal at epochs, or None
    notes: list[str] = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    input_hashes: dict = field(default_factory=dict)
    estimator: dict = field(default_factory=dict)  # method, triad, GNSS aiding used
    data_loss: list = field(default_factory=list)  # input damage: processed, but exit code 1
    attitude: np.ndarray | None = None  # (N, 3) rad roll, pitch, heading (strapdown), else None
    attitude_sigma: np.ndarray | None = None  # (N, 3) rad 1-sigma of the same


def _segments(cfg: SurveyConfig, fl: FlightConfig, sol) -> list:
    from .segmentation import segment_lines, segments_from_windows

    mode = getattr(cfg.lines, "mode", "auto")
    if fl.lines_windows is not None:
        return segments_from_windows(sol.time, fl.lines_windows, key_path=f"flights[{fl.index}].lines")
    if mode == "windows":
        return segments_from_windows(sol.time, cfg.lines.windows, key_path="lines.windows")
    if mode == "whole":
        from .segmentation import Segment

        # the whole flight, but never across the NaN epoch between separately estimated
        # segments (a flight split at a gap: consistency.SegmentedSolution)
        seg = np.asarray(getattr(sol, "segment", np.zeros(len(sol.time))))
        edge = np.diff(np.concatenate([[0], (seg >= 0).astype(np.int8), [0]]))
        runs = list(zip(np.flatnonzero(edge == 1), np.flatnonzero(edge == -1)))
        return [Segment(f"L{i + 1:02d}", "line", int(a), int(b)) for i, (a, b) in enumerate(runs)]
    return segment_lines(sol.time, sol.lat, sol.lon, sol.vel_n, options=cfg.lines)


def process_flight(cfg: SurveyConfig, fl: FlightConfig) -> FlightResult:
    """Process one flight. Raises GravsurveyError subclasses for data/config problems.

    Warnings raised by any stage become lines of ``FlightResult.notes`` (and of the log and
    summary.json) instead of being printed: a cron run that succeeds prints nothing.
    """
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = _process_flight(cfg, fl)
    seen = set(result.notes)
    for w in caught:
        line = f"{fl.name}: {w.message}"
        if line not in seen:
            result.notes.append(line)
            seen.add(line)
    return result


def _process_flight(cfg: SurveyConfig, fl: FlightConfig) -> FlightResult:
    from .io.ingest import load_flight
    from .wavelet import postprocess

    timings = {}
    notes: list[str] = []
    t = time.perf_counter()
    record = load_flight(fl.ingest, cfg.base_dir)
    notes += [f"{fl.name}: {n}" for n in record.notes]
    timings["ingest_s"] = time.perf_counter() - t

    # input consistency (gravsurvey/consistency.py): clocks, overlap, GNSS vs IMU
    from .consistency import CheckOptions, channel_names, check_gnss_consistency, check_overlap, check_result

    checks = getattr(cfg, "checks", None) or CheckOptions()
    names = channel_names(fl.ingest, cfg.base_dir)
    notes += [f"{fl.name}: {n}" for n in check_overlap(record, names)]
    notes += [f"{fl.name}: {n}" for n in check_gnss_consistency(
        record, names, checks, cfg.ellipsoid, fl.initial_given, f"flights[{fl.index}].initial")]
    segment_loss: list[str] = []

    t = time.perf_counter()
    if cfg.processing_method == "classic":
        sol = _classic_solution(cfg, fl, record)
    else:
        from .inm.params import resolve_initial_state, solvability_warnings

        initial = resolve_initial_state(record, fl.triad, cfg.model, cfg.ellipsoid, fl.initial_given,
                                        f"flights[{fl.index}].initial")
        sol, seg_notes, segment_loss = _estimate_by_segment(cfg, fl, record, initial, checks, names)
        notes += [f"{fl.name}: {n}" for n in seg_notes]
    timings["estimate_s"] = time.perf_counter() - t
    gradio = None
    if cfg.gradiometer:
        gradio = _gradiometer_products(fl, record, sol, notes)

    t = time.perf_counter()
    segs = _segments(cfg, fl, sol)
    n = len(sol.time)
    final = np.full(n, np.nan)
    line = np.full(n, "", dtype=object)
    seg_out, line_info = [], {}
    dt = float(np.median(np.diff(sol.time))) if n > 1 else 1.0
    for s in segs:
        a, b = int(s.start_index), int(s.stop_index)
        seg_out.append(
            {"name": s.name, "kind": s.kind, "start_s": float(sol.time[a]), "stop_s": float(sol.time[b - 1]), "n": b - a}
        )
        if s.kind not in ("line", "tie") or b - a < 8:
            continue
        speed = float(np.nanmean(sol.speed[a:b]))
        if cfg.processing_method == "classic":
            z, info = sol.final[a:b], dict(sol.info)
        else:
            if cfg.processing_method == "inm":
                for w in solvability_warnings(cfg.model, speed):
                    notes.append(f"{fl.name} {s.name}: {w}")
            z, info = postprocess(sol.g_smooth[a:b], dt, speed, options=cfg.postprocess,
                                  sigma=sol.sigma_smooth[a:b], context=(sol.g_smooth, a, b))
            if info.get("method") == "none":
                # the product is the smoother's own estimate: state the smoother's resolution
                info["resolution_m"] = float(sol.resolution_m)
        final[a:b] = z
        line[a:b] = s.name
        line_info[s.name] = {**to_jsonable(info), "kind": s.kind, "speed_mps": speed, "samples": b - a}
    timings["postprocess_s"] = time.perf_counter() - t
    notes += check_result(fl.name, final, line != "", sol, record, checks, len(line_info), cfg.ellipsoid)
    # checks that passed are facts for summary.json (estimator.checks_passed), not warnings
    from .consistency import PASSED

    passed = [n.replace(PASSED, "", 1) for n in notes if PASSED in n]
    notes = [n for n in notes if PASSED not in n]

    truth = None
    if fl.truth is not None:
        tr = read_truth_csv(fl.truth)
        unix = record.t0_unix_ns + np.round(sol.time * 1e9).astype(np.int64)
        truth = _truth_at(tr, unix)

    return FlightResult(
        name=fl.name,
        t0_unix_ns=int(record.t0_unix_ns),
        time=np.asarray(sol.time, float),
        lat=np.asarray(sol.lat, float),
        lon=np.asarray(sol.lon, float),
        height=np.asarray(sol.height, float),
        speed=np.asarray(sol.speed, float),
        kalman=np.asarray(sol.g_smooth, float),
        forward=np.asarray(sol.g_forward, float),
        sigma=np.asarray(sol.sigma_smooth, float),
        final=final,
        line=line,
        segments=seg_out,
        line_info=line_info,
        truth=truth,
        notes=notes,
        timings=timings,
        data_loss=[f"{fl.name}: {n}" for n in record.data_loss + segment_loss],
        attitude=_per_epoch(getattr(sol, "attitude", None), len(sol.time)),
        attitude_sigma=_per_epoch(getattr(sol, "attitude_sigma", None), len(sol.time)),
        estimator={
            **_attitude_report(sol),
            "method": cfg.processing_method,
            "triad": fl.triad,
            "gnss_aided": bool(getattr(sol, "gnss_aided", False)),
            "identification": getattr(sol, "identification", {}),
            "checks_passed": passed,
            "kalman_resolution_m": float(getattr(sol, "resolution_m", float("nan"))),
            **({"gradiometer": gradio} if gradio is not None else {}),
        },
    )


def _per_epoch(arr, n):
    """An (n, 3) array of the solution, or None (platform, classic, or segments without it)."""
    if arr is None:
        return None
    a = np.asarray(arr, float)
    return a if a.shape == (n, 3) and np.isfinite(a).any() else None


def _attitude_report(sol) -> dict:
    """Alignment and attitude-estimation summary for the flight's ``estimator`` (summary.json)."""
    out = {}
    al = getattr(sol, "alignment", None)
    if al is not None:
        out.update(al.to_dict())
        for w in al.warnings:
            warnings.warn(f"alignment: {w}")
    att_sig = getattr(sol, "attitude_sigma", None)
    if att_sig is not None and np.isfinite(att_sig).any():
        med = np.degrees(np.nanmedian(att_sig, axis=0))
        out["attitude_sigma_median_deg"] = {"roll": float(med[0]), "pitch": float(med[1]), "heading": float(med[2])}
        out["attitude_passes"] = int(sol.passes)
        out["attitude_corrections_deg"] = [float(np.degrees(c)) for c in sol.attitude_corrections]
        out["attitude_converge_s"] = float(sol.attitude_converge_s)
        out["gnss_residual_rms_m"] = float(sol.gnss_residual_rms_m)
    return out
def _gradiometer_products(fl, record, sol, notes):
    """processing.gradiometer: seed-000 products of the flight's gradient channel (summary.json)."""
    from .gradiometer import flight_products

    if record.gradient is None:
        notes.append(f"{fl.name}: processing.gradiometer is on but the flight has no gravity-gradient channel")
        return None
    p = flight_products(record.gradient.time, record.gradient.gamma_t, sol.time, sol.lat, sol.lon, sol.height,
                        sol.vel_n, float(sol.g_smooth[0]), fl.triad)
    if "disturbance" in p:
        # the gradient-propagated disturbance against the scalar estimate at the gradient epochs
        d = p.pop("disturbance")
        est = np.interp(p.pop("time"), sol.time, sol.g_smooth)
        p.pop("horizontal_n")
        p["disturbance_rms_vs_estimate_mgal"] = float(np.sqrt(np.mean((d - est) ** 2)) / 1e-5)
    return p


def _estimate_by_segment(cfg: SurveyConfig, fl: FlightConfig, record, initial, checks, names):
    """3D-INM estimate of a flight split at long gaps (consistency.plan_segments).

    The first segment starts from ``initial`` (state at the first IMU sample); every later one
    is re-initialised from GNSS on its own slice of the record, with the initial velocity sigma
    widened to what a 10 s GNSS fit gives in flight (``consistency.REINIT_VELOCITY_SIGMA_MPS``).
    Segments are joined with a NaN epoch between them.

    Returns
    -------
    sol : InmSolution or consistency.SegmentedSolution
    notes : list of str
    loss : list of str
        Pieces not estimated (too short, or not re-initialisable): reported as data loss.
    """
    import dataclasses

    from .consistency import REINIT_VELOCITY_SIGMA_MPS, concatenate_solutions, plan_segments, span_text
    from .inm.params import resolve_initial_state
    from .inm.solve import estimate_anomaly
    from .io.record import slice_record

    lever = getattr(fl.ingest, "gnss_lever_arm_m", None)
    spans, notes, loss = plan_segments(record, checks, names)
    imu_t0, imu_t1 = float(record.imu.time[0]), float(record.imu.time[-1])
    if len(spans) == 1 and spans[0] == (imu_t0, imu_t1):
        return (estimate_anomaly(record, cfg.model, initial, fl.triad, cfg.ellipsoid, gnss_lever_arm_t=lever),
                notes, loss)
    reinit_model = dataclasses.replace(
        cfg.model, initial_velocity_sigma_mps=max(cfg.model.initial_velocity_sigma_mps, REINIT_VELOCITY_SIGMA_MPS))
    sols = []
    for a, b in spans:
        sub = slice_record(record, a, b, margin_s=2.0)
        try:
            if a == imu_t0:
                sols.append(estimate_anomaly(sub, cfg.model, initial, fl.triad, cfg.ellipsoid,
                                             gnss_lever_arm_t=lever))
            else:
                # from the data alone: GNSS position/velocity, attitude by in-motion alignment
                init = resolve_initial_state(sub, fl.triad, reinit_model, cfg.ellipsoid)
                sols.append(estimate_anomaly(sub, reinit_model, init, fl.triad, cfg.ellipsoid,
                                             gnss_lever_arm_t=lever))
        except GravsurveyError as exc:
            loss.append(f"segment {span_text(record.t0_unix_ns, a, b)} not estimated: {exc}")
    if not sols:
        raise DataError(f"{record.source}: no segment of the flight could be estimated: {'; '.join(loss)}")
    notes.append(f"estimated {len(sols)} of {len(spans)} segments: "
                 + ", ".join(span_text(record.t0_unix_ns, s.time[0], s.time[-1]) for s in sols))
    return concatenate_solutions(sols), notes, loss


class _ClassicSolution:
    """Adapter giving the classic reduction the fields the pipeline reads."""

    def __init__(self, res, record):
        self.time = res.time
        self.lat, self.lon, self.height = res.lat, res.lon, res.height
        self.vel_n = res.vel_n
        self.speed = np.linalg.norm(res.vel_n[:, :2], axis=1)
        self.g_smooth = res.raw
        self.g_forward = res.raw
        self.sigma_smooth = np.full(len(res.time), np.nan)
        self.final = res.disturbance
        self.info = res.info
        # epochs inside a gap of the gravimeter or navigation log carry NaN by design (the
        # readers leave them empty rather than interpolate): they are gap epochs, like the
        # separators between the INS chain's segments (consistency.SegmentedSolution)
        # (the product is also empty where its low-pass window reaches into a gap)
        self.segment = np.where(np.isfinite(res.raw) & np.isfinite(res.disturbance), 0, -1)
        self.resolution_m = float(res.info.get("resolution_m") or np.nan)


def _classic_solution(cfg, fl, record):
    """The conventional scalar reduction, on the same radial information as the 3D-INM.

    A strapdown triad needs its attitude to find the vertical: it comes from the 3D-INM
    mechanization of the same record (``classic.strapdown_attitude``). Without GNSS the
    position track for the Eotvos correction also comes from the mechanization.
    """
    from .classic import classic_reduction, strapdown_attitude
    from .inm.params import resolve_initial_state

    mat_nt, track = None, None
    needs_nav = fl.triad == "strapdown" or record.gnss is None
    if needs_nav:
        initial = resolve_initial_state(record, fl.triad, cfg.model, cfg.ellipsoid, fl.initial_given,
                                        f"flights[{fl.index}].initial")
        if fl.triad == "strapdown":
            mat_nt = strapdown_attitude(record, initial, ellipsoid=cfg.ellipsoid)
        if record.gnss is None:
            from .inm.solve import estimate_anomaly

            track = estimate_anomaly(record, cfg.model, initial, fl.triad, cfg.ellipsoid)
    res = classic_reduction(
        record,
        ellipsoid=cfg.ellipsoid,
        resolution_m=cfg.classic_resolution_m,
        triad=fl.triad,
        mat_nt=mat_nt,
        track=track,
        height_source="altimeter",
    )
    if cfg.normal_gravity != "exact":
        from .marine import use_normal_gravity_formula

        use_normal_gravity_formula(res, cfg.normal_gravity, cfg.ellipsoid)
    if fl.ingest.kind == "gravimeter":
        # no made-up values across gaps of a vendor gravimeter or its navigation
        from .io.formats.flight import blank_gaps

        blank_gaps(res, record, fl.ingest.gap_factor)
    return _ClassicSolution(res, record)


# --------------------------------------------------------------------------
# survey
# --------------------------------------------------------------------------


def _file_sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _flight_key(cfg: SurveyConfig, fl: FlightConfig) -> tuple[str, dict]:
    hashes = {}
    for p in fl.ingest.input_paths():
        p = Path(p)
        hashes[str(p)] = _file_sha256(p) if p.is_file() else "missing"
    if fl.truth is not None and Path(fl.truth).is_file():
        hashes[str(fl.truth)] = _file_sha256(fl.truth)
    h = hashlib.sha256()
    h.update(cfg.section_hash(fl).encode())
    h.update(json.dumps(hashes, sort_keys=True).encode())
    h.update(f"{__version__}/{CACHE_VERSION}".encode())
    return h.hexdigest(), hashes


def _worker(config_path: str, output_dir: str, index: int):
    """Process pool entry: reload the config (cheap) and process one flight."""
    cfg = load_config(config_path, output_dir=output_dir)
    fl = cfg.flights[index]
    try:
        return ("ok", process_flight(cfg, fl))
    except GravsurveyError as exc:
        return ("error", f"{fl.name}: {exc}")
    except Exception as exc:  # a bug in one flight must not stop the others
        return ("bug", f"{fl.name}: internal error {type(exc).__name__}: {exc}\n{traceback.format_exc()}")


@dataclass
class RunResult:
    """What a survey run did, for the CLI's report."""

    out_dir: Path
    processed: list[str]
    skipped: list[str]
    failed: list[str]
    notes: list[str]
    summary: dict
    data_loss: list[str] = field(default_factory=list)

    @property
    def data_problem(self) -> bool:
        """Exit code 1: a flight failed, or was processed from a damaged (salvaged) input."""
        return bool(self.failed or self.data_loss)

    def report_lines(self, verbose: bool = True, problems: bool = True):
        """Lines for the user: with ``problems`` the failed flights and salvaged inputs (for
        stderr), with ``verbose`` the summary (counts, crossovers, RMS vs truth). The warnings
        (``notes``) are printed and counted by the CLI."""
        if problems:
            for f in self.failed:
                yield f"gravsurvey: flight failed: {f.splitlines()[0]}"
            for d in self.data_loss:
                yield f"gravsurvey: input damaged, processed what was salvaged: {d}"
        if verbose:
            yield (
                f"{self.summary.get('survey')}: {len(self.processed)} flight(s) processed, "
                f"{len(self.skipped)} unchanged (skipped), {len(self.failed)} failed -> {self.out_dir}"
            )
            xo = self.summary.get("crossovers", {})
            if xo.get("count"):
                yield f"crossovers: {xo['count']}, RMS {xo['rms_mgal']:.3f} mGal (RMS/sqrt2 {xo['rms_over_sqrt2_mgal']:.3f})"
            for fname, fs in self.summary.get("flights", {}).items():
                if fs.get("rms_vs_truth_mgal") is not None:
                    yield f"{fname}: RMS vs truth {fs['rms_vs_truth_mgal']:.3f} mGal over lines"


def _setup_log(out_dir: Path) -> logging.Handler:
    out_dir.mkdir(parents=True, exist_ok=True)
    h = logging.FileHandler(out_dir / "gravsurvey.log", encoding="utf-8")
    h.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(message)s"))
    log.addHandler(h)
    log.setLevel(logging.INFO)
    return h


def run_survey(config_path, *, output_dir=None, jobs: int = 1, force: bool = False,
               wait_s: float = 0.0, progress: bool = False, plots: bool | None = None) -> RunResult:
    """Run a whole survey and write the deliverables (docs/outputs.md).

    Returns a RunResult; raises ConfigError for config problems (exit 2). Data problems of a
    flight are recorded in ``RunResult.failed`` and the other flights still run.
    """
    from .io.writers import OutputLock, OutputTransaction

    t_start = time.perf_counter()
    cfg = load_config(config_path, output_dir=output_dir)
    if plots is not None:  # `run --no-plots` overrides output.plots
        cfg.plots = plots
    out_dir = Path(cfg.output_dir)
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:  # read-only parent, permissions: the environment, exit 3
        raise os_fault(exc, "create the output directory") from None
    with OutputLock(out_dir, wait_s=wait_s):
        handler = _setup_log(out_dir)
        try:
            return _run_locked(cfg, out_dir, jobs, force, progress, t_start, OutputTransaction)
        finally:
            log.removeHandler(handler)
            handler.close()


def _run_locked(cfg, out_dir, jobs, force, progress, t_start, OutputTransaction) -> RunResult:
    log.info("run %s (%d flights), gravsurvey %s", cfg.path, len(cfg.flights), __version__)
    from .cache import load_result, save_result

    cache_dir = out_dir / ".cache"
    cache_dir.mkdir(exist_ok=True)
    results: dict[str, FlightResult] = {}
    failed, skipped, processed, notes = [], [], [], []
    keys = {}
    todo = []
    for fl in cfg.flights:
        key, hashes = _flight_key(cfg, fl)
        keys[fl.name] = (key, hashes)
        # no pickle: JSON checked against the key before the arrays are read (gravsurvey.cache)
        cached = None if force else load_result(cache_dir, fl.name, key, FlightResult)
        if cached is not None:
            results[fl.name] = cached
            skipped.append(fl.name)
            log.info("%s: inputs and config unchanged, reusing the previous result", fl.name)
            continue
        todo.append(fl)

    def _collect(fl, status, payload):
        if status == "ok":
            payload.input_hashes = keys[fl.name][1]
            results[fl.name] = payload
            processed.append(fl.name)
            save_result(cache_dir, fl.name, keys[fl.name][0], payload)
            log.info("%s: processed in %.1f s", fl.name, sum(payload.timings.values()))
        else:
            failed.append(payload)
            log.error("%s", payload)

    bar = None
    if progress and todo:
        import click

        bar = click.progressbar(length=len(todo), label="flights", file=None)
        bar.__enter__()
    try:
        if jobs > 1 and len(todo) > 1:
            import multiprocessing as mp

            ctx = mp.get_context("spawn")
            with ProcessPoolExecutor(max_workers=min(jobs, len(todo)), mp_context=ctx) as pool:
                futs = {pool.submit(_worker, str(cfg.path), str(out_dir), fl.index): fl for fl in todo}
                for fut in as_completed(futs):
                    fl = futs[fut]
                    try:
                        status, payload = fut.result()
                    except Exception as exc:  # worker died (e.g. killed, out of memory)
                        status, payload = "bug", f"{fl.name}: worker process failed: {exc}"
                    _collect(fl, status, payload)
                    if bar:
                        bar.update(1)
        else:
            for fl in todo:
                try:
                    status, payload = "ok", process_flight(cfg, fl)
                except GravsurveyError as exc:
                    status, payload = "error", f"{fl.name}: {exc}"
                except Exception as exc:
                    status, payload = "bug", f"{fl.name}: internal error {type(exc).__name__}: {exc}\n{traceback.format_exc()}"
                _collect(fl, status, payload)
                if bar:
                    bar.update(1)
    finally:
        if bar:
            bar.__exit__(None, None, None)

    data_loss = []
    for r in results.values():
        notes.extend(r.notes)
        data_loss.extend(getattr(r, "data_loss", []))
    for n in notes:  # every warning reaches the log (the CLI prints and counts them)
        log.warning("%s", n)
    ordered = [results[f.name] for f in cfg.flights if f.name in results]
    t_out = time.perf_counter()
    summary = {}
    if ordered:
        summary = _write_outputs(cfg, out_dir, ordered, failed, OutputTransaction)
    summary_timing = time.perf_counter() - t_out
    log.info("outputs written in %.1f s; total %.1f s", summary_timing, time.perf_counter() - t_start)
    if not ordered:
        summary = {"survey": cfg.name}
    return RunResult(out_dir, processed, skipped, failed, notes, summary, data_loss)


def _profile_table(cfg: SurveyConfig, results: list[FlightResult]):
    from .georef import project

    lat = np.concatenate([r.lat for r in results])
    lon = np.concatenate([r.lon for r in results])
    east, north, epsg = project(lat, lon, cfg.epsg)
    unix = np.concatenate([r.t0_unix_ns + np.round(r.time * 1e9).astype(np.int64) for r in results])
    table = {
        "flight": np.concatenate([np.full(len(r.time), r.name, dtype=object) for r in results]),
        "line": np.concatenate([r.line for r in results]),
        "time_unix_ns": unix,
        "lat_deg": np.degrees(lat),
        "lon_deg": np.degrees(lon),
        "height_m": np.concatenate([r.height for r in results]),
        "easting_m": east,
        "northing_m": north,
        "disturbance_mgal": np.concatenate([r.final for r in results]) / MGAL,
        "kalman_mgal": np.concatenate([r.kalman for r in results]) / MGAL,
        "sigma_mgal": np.concatenate([r.sigma for r in results]) / MGAL,
    }
    if any(r.attitude is not None for r in results):
        # strapdown attitude and its 1-sigma per epoch (NaN for flights without it)
        att = np.concatenate([np.degrees(r.attitude) if r.attitude is not None else np.full((len(r.time), 3), np.nan)
                              for r in results])
        sig = np.concatenate([np.degrees(r.attitude_sigma) if r.attitude_sigma is not None
                              else np.full((len(r.time), 3), np.nan) for r in results])
        for j, name in enumerate(("roll", "pitch", "heading")):
            table[f"{name}_deg"] = att[:, j]
            table[f"{name}_sigma_deg"] = sig[:, j]
    if all(r.truth is not None for r in results):
        table["truth_mgal"] = np.concatenate([r.truth for r in results])
        table["error_mgal"] = table["disturbance_mgal"] - table["truth_mgal"]
    return table, epsg


def _rms(x):
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x**2))) if x.size else None


def _crs_name(epsg) -> str:
    """``"EPSG:32632 WGS 84 / UTM zone 32N"`` (the code alone if pyproj does not know it)."""
    try:
        from pyproj import CRS

        return f"EPSG:{int(epsg)} {CRS.from_epsg(int(epsg)).name}"
    except Exception:
        return f"EPSG:{epsg}"


def _flight_rows(results) -> dict:
    """flight -> slice of its rows in the profile table (flights are concatenated in order)."""
    out, off = {}, 0
    for r in results:
        out[r.name] = slice(off, off + len(r.time))
        off += len(r.time)
    return out


def _apply_ties(cfg, results, rows) -> tuple[dict, np.ndarray, list]:
    """Base ties of the flights that have one (gravsurvey.ties).

    Returns
    -------
    ties : dict
        flight -> FlightTie.
    correction_mgal : ndarray, shape (n_rows,)
        Tie offset per row of the profile table (0 for untied flights), mGal.
    notes : list of str
        Ties that could not be made (bad window): the flight stays relative.
    """
    from .ties import tie_flight

    corr = np.zeros(sum(len(r.time) for r in results))
    ties, notes = {}, []
    cfg_of = {f.name: f for f in cfg.flights}
    for r in results:
        fl = cfg_of.get(r.name)
        if fl is None or fl.tie is None:
            continue
        try:
            tie = tie_flight(fl.tie, r.time, r.lat, r.height, r.kalman / MGAL, ellipsoid=cfg.ellipsoid,
                             key_path=f"flights[{fl.index}].tie")
        except DataError as exc:
            notes.append(f"{r.name}: base tie not applied, the flight stays on a relative level: {exc}")
            continue
        ties[r.name] = tie
        corr[rows[r.name]] = tie.correction(r.time)
        windows = [rd for rd in (fl.tie.before, fl.tie.after) if rd is not None and rd.reading_mgal is None]
        if windows and cfg.processing_method == "inm":
            # docs/survey.md: on the sample survey the parked INM estimate was 1.56 mGal below truth
            # while the lines were 1.15 mGal above it
            notes.append(
                f"{r.name}: base tie read from a window of the 3D-INM estimate: at rest the filter cannot "
                "tell the anomaly from the gravimeter bias, so the tie may be off by mGal; give the "
                "gravimeter's still reading as reading_mgal where available"
            )
    return ties, corr, notes


def _output_metadata(cfg, epsg, level_state) -> dict:
    """What every deliverable carries about itself (docs/outputs.md, "Metadata")."""
    return {
        "survey": cfg.name,
        "crs": {
            "geographic": "EPSG:4326 WGS 84 (lat_deg, lon_deg)",
            "projected": _crs_name(epsg),
            "projected_epsg": int(epsg),
            "height": f"ellipsoidal height above the {getattr(cfg.ellipsoid, 'name', 'WGS84')} ellipsoid, m",
        },
        "units": {"*_mgal": "mGal (1e-5 m/s^2)", "*_m": "m", "*_deg": "deg", "time_unix_ns": "ns since 1970-01-01 UTC",
                  "time_s": "s"},
        "software": f"gravsurvey {__version__}",
        "level": level_state,
        "processing": {
            "method": cfg.processing_method,
            "ellipsoid": getattr(cfg.ellipsoid, "name", None),
            **{k: cfg.raw.get(k) for k in ("model", "lines", "postprocess", "levelling", "grid") if cfg.raw.get(k) is not None},
        },
    }


def write_survey_outputs(cfg: SurveyConfig, out_dir, results: list[FlightResult], failed=()) -> dict:
    """Write the survey deliverables for processed flights (ties, crossovers, levelling, grid,
    files) into ``out_dir`` atomically; return the summary. The public entry of the output
    stage (benchmarks/bench_outputs.py, tests); :func:`run_survey` calls the same code."""
    from .io.writers import OutputTransaction

    return _write_outputs(cfg, Path(out_dir), list(results), list(failed), OutputTransaction)


def _write_outputs(cfg, out_dir, results, failed, OutputTransaction) -> dict:
    """Survey products: base ties -> crossovers -> levelling -> grid, then every deliverable.

    Linear in the number of rows, lines and flights (rows of a line are found once by
    :func:`gravsurvey.io.writers.line_groups`; no per-line mask over the whole table).
    """
    from . import report
    from .io import writers
    from .levelling import level_survey
    from .crossovers import Crossovers, find_crossovers

    table, epsg = _profile_table(cfg, results)
    in_line = table["line"] != ""
    rows = _flight_rows(results)
    time_s = np.concatenate([np.asarray(r.time, float) for r in results])  # each flight's own time base
    groups = writers.line_groups(table["flight"], table["line"])
    kind_of = {(r.name, ln): info.get("kind", "line") for r in results for ln, info in r.line_info.items()}
    notes = []

    # 1. base ties: absolute level and drift per tied flight
    ties, tie_corr, tie_notes = _apply_ties(cfg, results, rows)
    notes += tie_notes
    tied_value = table["disturbance_mgal"] - tie_corr

    # 2. crossovers of the processed values (as before: crossovers.csv and summary "crossovers")
    lines = []
    for (fname, lname), idx in groups.items():
        lines.append(
            {
                "flight": fname,
                "line": lname,
                "easting_m": table["easting_m"][idx],
                "northing_m": table["northing_m"][idx],
                "value_mgal": table["disturbance_mgal"][idx],
                # the flight's common time base: find_crossovers tells a real crossing of two
                # lines of one flight from a track touching itself by their time separation
                "time_s": time_s[idx],
                "sigma_mgal": table["sigma_mgal"][idx],
                "index": idx,
            }
        )
    xo = find_crossovers([{k: v for k, v in ln.items() if k not in ("index", "sigma_mgal")} for ln in lines])
    xo_stats = xo.statistics()

    # 3. levelling of the tied values: the tie corrections at the crossover times, then the adjustment
    from .levelling import LevellingOptions

    lopt = cfg.levelling if cfg.levelling is not None else LevellingOptions()
    lev = None
    lev_skipped = None  # computed, but too few crossovers to apply (summary only)
    lev_corr = np.zeros_like(tie_corr)
    want = lopt.enabled
    if want is not False and xo.count > 0:
        tie_at = lambda f, t: ties[f].correction(t) if f in ties else np.zeros_like(t)  # noqa: E731
        fa, fb = xo.flight_a.astype(str), xo.flight_b.astype(str)
        ca = np.zeros(len(xo))
        cb = np.zeros(len(xo))
        for f in ties:
            ca[fa == f] = tie_at(f, xo.time_a_s[fa == f])
            cb[fb == f] = tie_at(f, xo.time_b_s[fb == f])
        xo_tied = Crossovers(**{c: getattr(xo, c) for c in Crossovers.COLUMNS})
        xo_tied.value_a_mgal = xo.value_a_mgal - ca
        xo_tied.value_b_mgal = xo.value_b_mgal - cb
        xo_tied.diff_mgal = xo_tied.value_a_mgal - xo_tied.value_b_mgal
        lev = level_survey(xo_tied, lines, lopt, tied_flights=list(ties))
        need = lopt.min_crossovers_per_unknown * max(lev.n_unknowns, 1)
        if want is None and lev.n_observations < need:
            notes.append(
                f"levelling: not applied: {lev.n_observations} crossovers for {lev.n_unknowns} unknowns "
                f"(needs {lopt.min_crossovers_per_unknown:g} per unknown; levelling.enabled: true forces it)"
            )
            lev_skipped = lev
            lev = None
        else:
            for ln in lines:
                lev_corr[ln["index"]] = lev.correction(ln["flight"], ln["line"], time_s[ln["index"]])
            notes += [f"levelling: {n}" for n in lev.notes]
    elif want is True:
        notes.append("levelling: no crossovers between lines; nothing levelled")
    table["levelled_mgal"] = np.where(in_line, tied_value - lev_corr, np.nan)

    # level of every line: absolute if its flight is tied, or levelled to a datum of tied flights
    absolute = {}
    for ln in lines:
        key = (ln["flight"], ln["line"])
        j = lev.index_of(key) if lev is not None else None
        via_lev = j is not None and lev.datum == "tied flights" and bool(lev.levelled[j])
        absolute[key] = ln["flight"] in ties or via_lev
    n_abs = sum(absolute.values())
    level_state = ("absolute" if lines and n_abs == len(lines) else "relative" if n_abs == 0 else "partly absolute")
    level_note = {
        "absolute": "levelled_mgal is on an absolute level (base ties)",
        "relative": "levelled_mgal is on a relative level: no base ties (flights[].tie); mean levelling correction zero",
        "partly absolute": "levelled_mgal: lines of tied flights (and lines levelled to them) absolute, the others relative",
    }[level_state]

    # 4. grid of the levelled line data
    grid = None
    grid_info = None
    from .grid import GridOptions

    gopt = cfg.grid if cfg.grid is not None else GridOptions()
    n_lines = sum(1 for k in groups if kind_of.get(k, "line") in ("line", "tie"))
    if gopt.enabled is not False and n_lines >= 2:
        from .grid import grid_lines

        lab = np.where(in_line, table["flight"].astype(str), "")
        lab = np.char.add(np.char.add(lab, "/"), table["line"].astype(str))
        try:
            grid = grid_lines(table["easting_m"][in_line], table["northing_m"][in_line], table["height_m"][in_line],
                              table["levelled_mgal"][in_line], lab[in_line], gopt)
            grid_info = grid.summary()
        except (DataError, np.linalg.LinAlgError, ValueError) as exc:
            notes.append(f"grid: not computed: {exc}")
            grid_info = {"error": str(exc)}
    elif gopt.enabled is True:
        notes.append(f"grid: needs >= 2 lines, the survey has {n_lines}")

    line_stats = []
    lines_of = {r.name: {} for r in results}
    fl_err = {r.name: [] for r in results}
    lev_stats = lev.statistics() if lev is not None else None
    for r in results:
        for name, info in r.line_info.items():
            idx = groups.get((r.name, name))
            if idx is None:
                continue
            st = {"flight": r.name, "line": name, **info}
            d = table["disturbance_mgal"][idx]
            st["mean_mgal"] = float(np.nanmean(d)) if np.isfinite(d).any() else None
            st["std_mgal"] = float(np.nanstd(d)) if np.isfinite(d).any() else None
            e, n = table["easting_m"][idx], table["northing_m"][idx]
            st["length_km"] = float(np.nansum(np.hypot(np.diff(e), np.diff(n)))) / 1e3 if idx.size > 1 else 0.0
            st["crossover"] = xo_stats.get("per_line", {}).get(f"{r.name}/{name}")
            st["level"] = "absolute" if absolute.get((r.name, name)) else "relative"
            if lev_stats is not None:
                st["levelling"] = lev_stats["per_line"].get(f"{r.name}/{name}")
            if "error_mgal" in table:
                e_ = table["error_mgal"][idx]
                st["rms_vs_truth_mgal"] = _rms(e_)
                st["kalman_rms_vs_truth_mgal"] = _rms(table["kalman_mgal"][idx] - table["truth_mgal"][idx])
                st["levelled_rms_vs_truth_mgal"] = _rms(table["levelled_mgal"][idx] - table["truth_mgal"][idx])
                fl_err[r.name].append(e_)
            line_stats.append(st)
            lines_of[r.name][name] = st
    flights_summary = {}
    for r in results:
        flights_summary[r.name] = {
            "segments": r.segments,
            "lines": lines_of[r.name],
            "notes": r.notes,
            "estimator": r.estimator,
            "data_loss": r.data_loss,
            "timings_s": r.timings,
            "input_sha256": r.input_hashes,
            "rms_vs_truth_mgal": _rms(np.concatenate(fl_err[r.name])) if fl_err[r.name] else None,
            "tie": ties[r.name].summary() if r.name in ties else None,
        }

    metadata = _output_metadata(cfg, epsg, level_state)
    summary = {
        "survey": cfg.name,
        "software": {"name": "gravsurvey", "version": __version__, "python": platform.python_version()},
        "created_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "config": {"path": str(cfg.path), "sha256": _file_sha256(cfg.path), "settings": cfg.raw},
        "processing_method": cfg.processing_method,
        "crs_epsg": epsg,
        "crs": metadata["crs"],
        "level": {"state": level_state, "note": level_note, "tied_flights": sorted(ties),
                  "untied_flights": [r.name for r in results if r.name not in ties]},
        "flights": flights_summary,
        "failed_flights": [f.splitlines()[0] for f in failed],
        "crossovers": xo_stats,
        "levelling": (
            {"applied": True, **{k: v for k, v in lev_stats.items() if k != "per_line"}} if lev_stats
            else {"applied": False, **{k: v for k, v in lev_skipped.statistics().items() if k != "per_line"}}
            if lev_skipped is not None else None
        ),
        "grid": grid_info,
        "notes": notes,
        "rms_vs_truth_mgal": _rms(table["error_mgal"][in_line]) if "error_mgal" in table else None,
    }
    if "truth_mgal" in table:
        err = table["levelled_mgal"][in_line] - table["truth_mgal"][in_line]
        err = err[np.isfinite(err)]
        summary["levelled_vs_truth"] = {
            "rms_mgal": _rms(err),
            "mean_mgal": float(err.mean()) if err.size else None,
            "std_mgal": float(err.std()) if err.size else None,
        }
    summary = to_jsonable(summary)

    with OutputTransaction(out_dir) as tx:
        writers.write_profiles_csv(tx.path("profiles.csv"), table, metadata=metadata)
        if cfg.xyz:
            writers.write_xyz(tx.path("profiles.xyz"), table, title=f"gravsurvey profiles: {cfg.name}", metadata=metadata)
        if cfg.geojson:
            writers.write_geojson(tx.path("lines.geojson"), table, line_stats, epsg, metadata=metadata)
        writers.write_crossovers_csv(tx.path("crossovers.csv"), xo, metadata=metadata)
        if grid is not None:
            from .grid import write_grid_netcdf

            write_grid_netcdf(tx.path("grid.nc"), grid, epsg, title=f"{cfg.name}: gravity disturbance (levelled_mgal)",
                              attrs={"survey": cfg.name, "software": f"gravsurvey {__version__}",
                                     "level": level_state, "source": "profiles.csv levelled_mgal"})
        if cfg.plots:
            for ln in lines:
                idx = ln["index"]
                e, n = table["easting_m"][idx], table["northing_m"][idx]
                step = np.hypot(np.diff(e), np.diff(n))
                dist_km = np.concatenate(([0.0], np.cumsum(np.where(np.isfinite(step), step, 0.0)))) / 1e3
                report.plot_line_profile(
                    tx.path(f"profile_{ln['flight']}_{ln['line']}.png"),
                    dist_km,
                    table["kalman_mgal"][idx],
                    table["disturbance_mgal"][idx],
                    table["sigma_mgal"][idx],
                    truth_mgal=table["truth_mgal"][idx] if "truth_mgal" in table else None,
                    title=f"{cfg.name} {ln['flight']} {ln['line']}",
                    x_label="distance along line, km",
                )
            report.plot_survey_map(
                tx.path("survey_map.png"),
                table["easting_m"][in_line],
                table["northing_m"][in_line],
                table["disturbance_mgal"][in_line],
                np.char.add(np.char.add(table["flight"][in_line].astype(str), "/"), table["line"][in_line].astype(str)),
                crossovers=xo,
                crs_label=_crs_name(epsg),
            )
            if xo_stats.get("count"):
                report.plot_crossover_histogram(tx.path("crossovers.png"), xo)
            if lev is not None:
                report.plot_levelling(tx.path("levelling.png"), lev, title=f"{cfg.name}: crossover levelling")
            if grid is not None:
                report.plot_grid_map(
                    tx.path("grid_map.png"), grid.easting_m, grid.northing_m, grid.value_mgal,
                    table["easting_m"][in_line], table["northing_m"][in_line],
                    track_ids=np.char.add(table["flight"][in_line].astype(str), table["line"][in_line].astype(str)),
                    crs_label=_crs_name(epsg),
                    title=(f"{cfg.name}: gravity disturbance, "
                           + ("tied and levelled" if lev is not None and ties else "levelled" if lev is not None
                              else "tied, not levelled" if ties else "not levelled")
                           + f" ({level_state} level)"),
                    note=(f"{grid.method.replace('_', ' ')}, {grid.spacing_m:.0f} m cells, "
                          + (f"at {grid.altitude_m:.0f} m ellipsoidal height" if grid.altitude_m is not None else "at the flight heights")
                          + f"; cross-validation RMS {grid.cv_rms_mgal:.2f} mGal"),
                )
        summary["output_sha256"] = tx.file_hashes()
        writers.write_json(tx.path("summary.json"), summary)
    return summary
