"""One flight, then a survey of flights.

``process_flight`` runs one flight through ingest -> 3D-INM Kalman/RTS (or the classic
reduction; :func:`estimate_flight` is the only place the method matters) -> line segmentation
-> post-processing per line, and returns the flight's :class:`gravsurvey.estimate.FlightEstimate`.
``run_survey`` runs every flight (in parallel with ``jobs > 1``), projects, finds crossovers
and writes the deliverables atomically into the output directory under a lock.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import math
import platform
import time
import traceback
import warnings
from concurrent.futures import as_completed
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from . import __version__
from .cache import code_fingerprint
from .config import FlightConfig, SurveyConfig, load_config
from .errors import INTERRUPT, DataError, GravsurveyError, os_fault
from .estimate import FlightEstimate, concatenate_estimates, from_classic, from_inm_solution, trim_one_sided_ends
from .geodesy import MGAL
from .io.writers import file_sha256, resolution_statement, to_jsonable
from .pool import single_threaded_blas
from .truth import read_truth_csv, truth_at  # noqa: F401  (public here for notebooks and benchmarks)

log = logging.getLogger("gravsurvey")

CACHE_VERSION = 7


# --------------------------------------------------------------------------
# truth files written by the simulator (docs/formats.md); read here as any
# user-supplied truth would be: a documented CSV, no simulator code involved
# --------------------------------------------------------------------------


# --------------------------------------------------------------------------
# one flight
# --------------------------------------------------------------------------

#: the per-flight result is the flight's :class:`gravsurvey.estimate.FlightEstimate` (this name
#: is kept for callers written before the estimate type existed)
FlightResult = FlightEstimate


def line_segments(cfg: SurveyConfig, fl: FlightConfig, est: FlightEstimate) -> list:
    """The flight's lines (``segmentation.Segment`` list) by the configured ``lines`` mode.

    Windows from the flight (``flights[].lines``) or the survey (``lines.windows``), the whole
    flight (``whole``: one line per run of estimated epochs, never across a gap epoch), or
    automatic segmentation of the track (``auto``).
    """
    from .segmentation import segment_lines, segments_from_windows

    mode = getattr(cfg.lines, "mode", "auto")
    if fl.lines_windows is not None:
        return segments_from_windows(est.time, fl.lines_windows, key_path=f"flights[{fl.index}].lines")
    if mode == "windows":
        return segments_from_windows(est.time, cfg.lines.windows, key_path="lines.windows")
    if mode == "whole":
        from .segmentation import Segment

        # the whole flight, but never across a gap epoch (segment -1: the separator between
        # separately estimated pieces, or epochs a chain left empty)
        seg = np.asarray(est.segment)
        edge = np.diff(np.concatenate([[0], (seg >= 0).astype(np.int8), [0]]))
        runs = list(zip(np.flatnonzero(edge == 1), np.flatnonzero(edge == -1)))
        return [Segment(f"L{i + 1:02d}", "line", int(a), int(b)) for i, (a, b) in enumerate(runs)]
    return segment_lines(est.time, est.lat, est.lon, est.vel_n, options=cfg.lines)


def process_flight(cfg: SurveyConfig, fl: FlightConfig) -> FlightEstimate:
    """Process one flight. Raises GravsurveyError subclasses for data/config problems.

    Warnings raised by any stage become lines of ``FlightEstimate.notes`` (and of the log and
    summary.json) instead of being printed: a cron run that succeeds prints nothing.  BLAS runs
    single-threaded inside (:func:`gravsurvey.pool.single_threaded_blas`).
    """
    early: list[str] = []  # the flight's notes so far, kept for a failure's report
    with warnings.catch_warnings(record=True) as caught, single_threaded_blas():
        warnings.simplefilter("always")
        try:
            result = _process_flight(cfg, fl, early)
        except GravsurveyError as exc:
            # what was noticed before the failure (a channel covering half the others' span,
            # a unit hint) often names its cause: the run prints it with the failure
            from .consistency import PASSED

            lines = [n for n in early if PASSED not in n] + [f"{fl.name}: {w.message}" for w in caught]
            exc.flight_notes = list(dict.fromkeys(lines))
            raise
    seen = set(result.notes)
    for w in caught:
        line = f"{fl.name}: {w.message}"
        if line not in seen:
            result.notes.append(line)
            seen.add(line)
    return result


def estimate_flight(cfg: SurveyConfig, fl: FlightConfig, record, checks, names) -> tuple[FlightEstimate, list, list]:
    """The flight's estimate by the configured ``processing.method``.

    Returns
    -------
    est : FlightEstimate
        The chain's product at every epoch (not yet cut into lines).
    notes : list of str
        Findings of the estimation (without the flight name).
    loss : list of str
        Pieces of the flight not estimated (data loss).
    """
    if cfg.processing_method == "classic":
        return classic_estimate(cfg, fl, record), [], []
    return inm_estimate(cfg, fl, record, checks, names)


def line_products(est: FlightEstimate, segs, postprocess_options, model=None) -> tuple[list, dict, list]:
    """Cut the estimate into lines and make each line's product, in place.

    A chain with a smoothed estimate (3D-INM) has it post-processed per line
    (:func:`gravsurvey.wavelet.postprocess`, default: none, i.e. the smoothed estimate with
    the smoother's resolution); a chain that delivers its product already (classic) keeps it.
    ``est.disturbance`` becomes the product on lines and tie lines of >= 8 epochs, NaN
    elsewhere; ``est.line`` the line name of each epoch.

    Returns
    -------
    seg_out : list of dict
        ``name, kind, start_s, stop_s, n`` of every segment.
    line_info : dict
        Line -> post-processor facts, ``kind``, ``speed_mps``, ``samples``.
    notes : list of str
        Per-line warnings (e.g. the solvability at the line's speed of the model the smoother
        used there, :func:`model_used`).
    """
    from .inm.params import solvability_warnings
    from .wavelet import postprocess

    n = len(est.time)
    product = est.disturbance
    # the smoothed estimate less the drift the lines identified (estimate_drift), if any
    base = est.smoothed if est.smoothed is None or est.drift is None else est.smoothed - est.drift
    if base is not None and est.field_filter is not None:
        base = base - est.field_filter
    filtered_lines = (est.estimator.get("drift") or {}).get("field_filter", {}).get("lines", {})
    final = np.full(n, np.nan)
    line = np.full(n, "", dtype=object)
    seg_out, line_info, notes = [], {}, []
    dt = float(np.median(np.diff(est.time))) if n > 1 else 1.0
    for s in segs:
        a, b = int(s.start_index), int(s.stop_index)
        seg_out.append(
            {
                "name": s.name,
                "kind": s.kind,
                "start_s": float(est.time[a]),
                "stop_s": float(est.time[b - 1]),
                "n": b - a,
            }
        )
        if s.kind not in ("line", "tie") or b - a < 8:
            continue
        speed = float(np.nanmean(est.speed[a:b]))
        if base is None:
            # the chain's own product (the classic low-pass), as the chain stated it
            z, info = product[a:b], {"method": est.method, **est.product_info}
        else:
            if model is not None:
                used = model_used(est, model, a)
                notes += [f"{est.name} {s.name}: {w}" for w in solvability_warnings(used, speed)]
            z, info = postprocess(
                base[a:b],
                dt,
                speed,
                options=postprocess_options,
                sigma=est.sigma[a:b],
                context=(base, a, b),
            )
            if info.get("method") == "none":
                # the product is the smoother's own estimate (and the field filter's, where it
                # ran): state the resolution of both together
                info["resolution_m"] = float(filtered_lines.get(s.name, {}).get("resolution_m", est.resolution_m))
        final[a:b] = z
        line[a:b] = s.name
        line_info[s.name] = {
            **to_jsonable(info),
            # before to_jsonable turns an unbounded resolution (nothing resolved) into null
            "resolution_note": resolution_statement(info.get("resolution_m")),
            "kind": s.kind,
            "speed_mps": speed,
            "samples": b - a,
        }
    est.disturbance = final
    est.line = line
    return seg_out, line_info, notes


def model_used(est: FlightEstimate, model, index: int):
    """The configured ``model`` (InmParams) with the anomaly prior the smoother used at epoch
    ``index``: identified from the flight (per piece of a flight split at gaps) unless given.

    The anomaly correlation decides the seed-004 solvability at a line's speed, so a check
    against the configured (default) prior would warn about a model that was not used.
    """
    ident = _identification_at(est, index)
    found = {}
    for key in ("anomaly_sigma_mps2", "anomaly_lambda_per_m"):
        item = ident.get(key)
        if isinstance(item, dict) and item.get("value") is not None:
            found[key] = float(item["value"])
    return dataclasses.replace(model, **found) if found else model


def _identification_at(est: FlightEstimate, index: int) -> dict:
    """The identification report of the piece of the flight holding epoch ``index`` (the
    flight's own where it was estimated whole; empty where there is none)."""
    ident = est.estimator.get("identification") or {}
    pieces = ident.get("segments")
    if pieces is not None:
        k = int(est.segment[index]) if est.segment is not None and 0 <= index < len(est.segment) else -1
        ident = pieces[k] if 0 <= k < len(pieces) else {}
    return ident


def identification_log_lines(est: FlightEstimate) -> list[str]:
    """The flight's identified model and drift separation as log lines (issue 12: the values,
    their uncertainty and how each was found, as in summary.json ``estimator``).

    One line per estimated piece of the flight (``model:``), then one for the drift; empty for
    an estimate without identification (classic).
    """
    ident = est.estimator.get("identification") or {}
    pieces = ident.get("segments", [ident])
    out = []
    for i, piece in enumerate(pieces):
        items = []
        for key, label, scale, unit in _IDENTIFIED_LOG:
            item = piece.get(key)
            if not isinstance(item, dict) or item.get("value") is None:
                continue
            v = float(item["value"])
            v = 1.0 / v if key == "anomaly_lambda_per_m" and v > 0 else v
            text = f"{label} {v / scale:.3g} {unit}"
            if item.get("sigma_factor"):
                text += f" (x/ {float(item['sigma_factor']):.3g})"
            items.append(f"{text}, {item.get('how', '?')}")
        if not items:
            continue
        tail = []
        if piece.get("resolution_m"):
            tail.append(resolution_statement(piece["resolution_m"]))
        if piece.get("expected_error_mgal") is not None:
            tail.append(f"expected error {float(piece['expected_error_mgal']):.3g} mGal")
        if piece.get("smoother_sigma_scale") is not None:
            tail.append(f"smoother's sigma x {float(piece['smoother_sigma_scale']):.2f} for the field seen")
        if piece.get("vertical_offset_mgal"):
            tail.append(f"a constant of {float(piece['vertical_offset_mgal']):.3g} mGal held out of the prior")
        where = f" (piece {i + 1} of {len(pieces)})" if len(pieces) > 1 else ""
        out.append(f"{est.name}: model{where}: " + "; ".join(items) + ("; " + ", ".join(tail) if tail else ""))
    drift = est.estimator.get("drift")
    if isinstance(drift, dict):
        if drift.get("used"):
            out.append(
                f"{est.name}: drift: {drift.get('drift_rms_mgal', float('nan')):.3g} mGal RMS taken off, "
                f"{drift.get('model')} model leading (fitted weight {float(drift.get('fitted_weight', 1.0)):.2f}, "
                f"log-likelihood ratio {float(drift.get('log_likelihood_ratio', float('nan'))):.2f}, "
                f"{drift.get('lines')} lines, {drift.get('blocks')} blocks)"
            )
        else:
            out.append(f"{est.name}: drift: not taken off: {drift.get('reason', '?')}")
    return out


#: The identified values in the log: summary.json key, label, scale from SI, unit shown.
_IDENTIFIED_LOG = (
    ("anomaly_sigma_mps2", "anomaly sigma", MGAL, "mGal"),
    ("anomaly_lambda_per_m", "anomaly correlation length", 1000.0, "km"),
    ("gravimeter_white_mps2", "gravimeter white", MGAL, "mGal in 1 s"),
    ("altimeter_sigma_m", "height noise", 1.0, "m"),
    ("accel_noise_mps2", "horizontal accelerometer noise", 1.0, "m/s^2 in 1 s"),
)


def estimate_drift(est: FlightEstimate, segs, options=None, filter_lines: bool = True) -> list:
    """Tell the gravimeter drift from the field by the flight's lines, in place.

    :func:`gravsurvey.drift.separate_drift` over the smoothed estimate on the survey-line
    segments (tie lines are left out).  When the data need the drift, ``est.drift`` holds it (taken off before the
    post-processing, :func:`line_products`) and ``est.sigma`` trades the datasheet drift it held
    (``est.drift_sigma_passed``) for the drift's posterior sigma.  When no drift is taken off
    but the lines set the datasheet's aside, the datasheet drift in ``est.sigma`` shrinks to
    the fitted one (:func:`gravsurvey.drift.passed_drift_factor`; ``sigma_drift_passed_mgal`` in
    the report).  A datasheet drift given in the config (``drift.sigma_mps2``, ``drift.tau_s``)
    first takes the place of the default one the identification passed into ``est.sigma``
    (:func:`datasheet_drift_passed`).  The fit's facts go to ``est.estimator["drift"]``
    (summary.json).  Where a drift is taken off, ``filter_lines`` and ``drift.field_filter``
    also filter each line against the drift's residual (:func:`filter_field`).  Tares the lines
    need (``drift.tares``; the step through the smoother's transfer,
    :func:`gravsurvey.drift.step_response`) are taken off with the drift, their sigma in
    ``est.sigma``, even where the drift itself is not.

    Returns
    -------
    list of str
        Notes for the flight (each tare taken off; a drift larger than the datasheet prior).
    """
    from .drift import DriftOptions, passed_drift_factor, separate_drift, step_response
    from .utc import utc_iso
    from .inm.identify import DRIFT_DEFAULT_SIGMA_MPS2, DRIFT_DEFAULT_TAU_S
    from .segmentation import along_line_legs

    options = options if options is not None else DriftOptions()
    if est.smoothed is None:
        return []
    configured = (options.sigma_mps2, options.tau_s) != (DRIFT_DEFAULT_SIGMA_MPS2, DRIFT_DEFAULT_TAU_S)
    if est.drift_sigma_passed > 0.0 and configured:
        # the smoother's identification passed the default datasheet drift into the sigma;
        # the configured one (drift.sigma_mps2, drift.tau_s) is the gravimeter's
        passed = datasheet_drift_passed(est, options)
        _trade_drift_sigma(est, passed)
        est.drift_sigma_passed = passed
    labels = np.full(len(est.time), "", dtype=object)
    for s in along_line_legs(segs):
        # survey lines and the turns' offset legs near their heading only: tie lines cross
        # them, and the smoother's along-track low-pass of a short-wavelength field differs
        # between crossing directions (seen as drift)
        labels[int(s.start_index) : int(s.stop_index)] = s.name
    # an unbounded resolution (a flat estimate: no field along the lines for the stage's field
    # model to misread) leaves the resolution guard off: on the four quick unseen flights with
    # one, the drift taken off moved U233 0.67 -> 0.12 mGal, U217 0.65 -> 0.62, U018 0.33 ->
    # 0.32, U016 0.68 -> 0.80 (2026-12-01)
    res = float(est.resolution_m) if np.isfinite(est.resolution_m) else 0.0
    response = None
    if options.tares and len(est.time) > 1:
        # a tare reaches the estimate through the smoother's transfer (that of the flight's
        # middle piece where it was estimated in pieces)
        mid = len(est.time) // 2
        response = step_response(
            lambda f: _smoother_gain(est, mid, f),
            float(np.median(np.diff(est.time))),
            float(est.time[-1] - est.time[0]),
        )
    drift, sigma, report = separate_drift(est.time, est.lat, est.lon, est.smoothed, labels, options, res, response)
    used = bool(report.get("used"))
    if not used:
        # the lines may have set the datasheet drift aside: the sigma then passes the drift
        # they support (drift.passed_drift_factor), not the datasheet's
        factor = passed_drift_factor(report, options)
        if factor < 1.0 and est.drift_sigma_passed > 0.0:
            passed = factor * est.drift_sigma_passed
            _trade_drift_sigma(est, passed)
            est.drift_sigma_passed = passed
            report = {**report, "sigma_drift_passed_mgal": passed / MGAL}
        elif configured:
            report = {**report, "sigma_drift_passed_mgal": est.drift_sigma_passed / MGAL}
    est.estimator = {**est.estimator, "drift": report}
    if drift is None:
        return []
    est.drift = drift
    if used and report.get("rest_to") == "none":
        # the fitted drift's weight below one, the rest to no drift: that share of the error is
        # the drift the smoother passes, of the size the lines support
        passed = passed_drift_factor(report, options) * est.drift_sigma_passed
        sigma = np.sqrt(sigma**2 + (1.0 - report["fitted_weight"]) * passed**2)
    if used:
        if filter_lines and options.field_filter:
            sigma = filter_field(est, segs, sigma, report)
        _trade_drift_sigma(est, sigma)
    else:
        # tares alone: the drift the sigma passes stays; the steps' own sigma joins it
        est.sigma = np.hypot(est.sigma, sigma)
    notes = [
        f"{est.name}: the lines show a tare, a step of {t['step_mgal']:+.1f} mGal (+-{t['sigma_mgal']:.1f}) "
        f"in the gravimeter's reading at {utc_iso(est.t0_unix_ns + int(round(t['time_s'] * 1e9)), 0)} "
        f"(log-likelihood ratio {t['log_likelihood_ratio']:.0f}); it was taken off with the drift "
        "(drift_mgal in profiles.csv)"
        for t in report.get("tares", ())
    ]
    if used and report["drift_rms_mgal"] > 3.0 * options.sigma_mps2 / MGAL:
        notes.append(
            f"{est.name}: the lines show a gravimeter drift of {report['drift_rms_mgal']:.1f} mGal RMS "
            f"(over 3x the prior drift.sigma_mps2); it was taken off (drift_mgal in profiles.csv)"
        )
    return notes


def _product_is_smoothed(postprocess_options) -> bool:
    """Whether the lines' product is the smoothed estimate as it is (post-processing method
    ``none``, the default): only then does the field filter run (another post-processor sets
    its own resolution)."""
    from .wavelet import DEFAULT_METHOD

    method = getattr(postprocess_options, "method", None) or "default"
    return (DEFAULT_METHOD if method == "default" else method) == "none"


def filter_field(est: FlightEstimate, segs, sigma, report: dict):
    """The field filter (:func:`gravsurvey.drift.field_filter`) on every line and tie line of
    >= 8 epochs where the drift fit's field applies (:func:`gravsurvey.drift.field_filter_applies`),
    in place: ``est.field_filter`` holds what it took off, ``report["field_filter"]`` its facts
    per line (summary.json ``estimator.drift.field_filter``: the expected error, what was taken
    off, the gain's peak and the resolution of the smoother and the filter together).

    Parameters
    ----------
    sigma : ndarray, shape (N,)
        The drift's posterior 1-sigma, m/s^2.

    Returns
    -------
    ndarray, shape (N,)
        ``sigma`` with the filtered lines' residual replaced by the filter's expected error
        (scaled along the line as the posterior was).
    """
    from .drift import field_filter, field_filter_applies, field_filter_gain

    sigma = np.array(sigma, float)
    n = len(est.time)
    if n < 2:
        return sigma
    dt = float(np.median(np.diff(est.time)))
    base = est.smoothed - est.drift
    f_sig = float(report.get("field_sigma_mgal") or 0.0) * MGAL
    f_len = float(report.get("field_length_km") or 0.0) * 1000.0
    tau = float(report.get("drift_tau_s") or 0.0)
    # where the gains are evaluated for the resolution
    freq = np.geomspace(1e-6, 0.5 / dt, 2000)
    taken = np.zeros(n)
    lines = {}
    for s in segs:
        a, b = int(s.start_index), int(s.stop_index)
        if s.kind not in ("line", "tie") or b - a < 8:
            continue
        speed = float(np.nanmean(est.speed[a:b]))
        length = speed * float(est.time[b - 1] - est.time[a])
        if not (np.isfinite(speed) and speed > 0.0) or not field_filter_applies(report, length):
            continue
        seg_sigma = sigma[a:b]
        residual = float(np.median(seg_sigma))
        chunk = base[a:b]
        if residual <= 0.0 or not np.all(np.isfinite(chunk)):
            continue
        filtered, error = field_filter(chunk, dt, speed, f_sig, f_len, residual, tau)
        taken[a:b] = chunk - filtered
        sigma[a:b] = seg_sigma * (error / residual)
        gain = field_filter_gain(freq, f_sig, f_len, speed, residual, tau) * _smoother_gain(est, a, freq)
        lines[s.name] = {
            "error_sigma_mgal": error / MGAL,
            "residual_sigma_mgal": residual / MGAL,
            "taken_off_rms_mgal": float(np.sqrt(np.mean(taken[a:b] ** 2))) / MGAL,
            "gain_peak": float(gain.max()),
            "resolution_m": _half_gain_resolution(freq, gain, speed),
        }
    if lines:
        est.field_filter = taken
        report["field_filter"] = {"lines": lines}
    return sigma


def _smoother_gain(est: FlightEstimate, index: int, freq):
    """The smoother's steady-state gain at ``freq`` (Hz) for the piece holding epoch ``index``
    (:func:`gravsurvey.inm.identify.smoother_gain` of its identified model); a brick wall at the
    stated resolution where the identification holds no model."""
    from .inm.identify import SpectralModel, smoother_gain

    ident = _identification_at(est, index)
    spec, dt_h = ident.get("spectral_model"), ident.get("height_dt_s")
    if spec and dt_h:
        return smoother_gain(freq, SpectralModel(**spec), float(dt_h))
    speed = float(np.nanmedian(est.speed))
    res = float(est.resolution_m)
    if res == math.inf:
        # a flat estimate: nothing resolved
        return np.zeros_like(freq)
    if not np.isfinite(res) or res <= 0.0:
        # not stated: the filter's gain alone
        return np.ones_like(freq)
    return (freq <= speed / (2.0 * res)).astype(float)


def _half_gain_resolution(freq, gain, speed: float) -> float:
    """Half-wavelength (m) where ``gain`` falls below 1/2 above its peak; inf where it never
    reaches 1/2 (nothing resolved)."""
    k = int(np.argmax(gain))
    if gain[k] < 0.5:
        return float("inf")
    below = np.flatnonzero(gain[k:] < 0.5)
    if below.size == 0:
        return speed / (2.0 * float(freq[-1]))
    j = k + int(below[0])
    # the crossing between the two grid points, linear in log frequency
    lo, hi = math.log(freq[j - 1]), math.log(freq[j])
    frac = (gain[j - 1] - 0.5) / (gain[j - 1] - gain[j])
    return speed / (2.0 * math.exp(lo + frac * (hi - lo)))


def datasheet_drift_passed(est: FlightEstimate, options) -> float:
    """1-sigma of the drift ``options`` (``drift.sigma_mps2``, ``drift.tau_s``) that the
    smoother passes into ``est``, m/s^2: :func:`gravsurvey.inm.identify.drift_sigma_passed` over
    each piece's identification and span, the largest; without an identification report (an
    estimate built by hand) the estimate's own figure scaled by the drift's sigma (to which it
    is proportional)."""
    from .inm.identify import DRIFT_DEFAULT_SIGMA_MPS2, drift_sigma_passed

    ident = est.estimator.get("identification") or {}
    passed = []
    for i, rep in enumerate(ident.get("segments", [ident])):
        on = np.flatnonzero(np.asarray(est.segment) == i)
        if on.size and "spectral_model" in rep:
            span = float(est.time[on[-1]] - est.time[on[0]])
            passed.append(drift_sigma_passed(rep, span, options.sigma_mps2, options.tau_s))
    if passed:
        return max(passed)
    return est.drift_sigma_passed * options.sigma_mps2 / DRIFT_DEFAULT_SIGMA_MPS2


def _trade_drift_sigma(est: FlightEstimate, sigma) -> None:
    """``est.sigma`` with the datasheet drift it held (``est.drift_sigma_passed``) replaced in
    quadrature by ``sigma`` (m/s^2, scalar or shape (N,)), in place."""
    est.sigma = np.sqrt(np.clip(est.sigma**2 - est.drift_sigma_passed**2, 0.0, None) + np.square(sigma))


def _process_flight(cfg: SurveyConfig, fl: FlightConfig, notes: list) -> FlightEstimate:
    """:func:`process_flight`'s work; ``notes`` (empty) collects the flight's notes as they come."""
    from .io.ingest import load_flight

    timings = {}
    t = time.perf_counter()
    record = load_flight(fl.ingest, cfg.base_dir)
    notes += [f"{fl.name}: {n}" for n in record.notes]
    timings["ingest_s"] = time.perf_counter() - t

    # input consistency (gravsurvey/consistency.py): clocks, overlap, GNSS vs IMU
    from .consistency import (
        CheckOptions,
        channel_names,
        check_gnss_consistency,
        check_overlap,
        check_platform_axes,
        check_platform_gyros,
        check_result,
        check_strapdown_axes,
        correct_imu_scale,
    )

    checks = getattr(cfg, "checks", None) or CheckOptions()
    names = channel_names(fl.ingest, cfg.base_dir)
    notes += [f"{fl.name}: {n}" for n in check_overlap(record, names)]
    if getattr(fl.ingest, "kind", "") != "gravimeter":
        # a gravimeter file's vertical is built z-up from its reading (io/formats/flight.py); its
        # level is checked against the GNSS below
        notes += [f"{fl.name}: {n}" for n in check_platform_axes(record, fl.triad, names, f"flights[{fl.index}]")]
    notes += [
        f"{fl.name}: {n}"
        for n in check_gnss_consistency(
            record, names, checks, cfg.ellipsoid, fl.initial_given, f"flights[{fl.index}].initial"
        )
    ]
    if getattr(fl.ingest, "kind", "") != "gravimeter":
        # against the GNSS track, once the checks above have found it sound
        notes += [f"{fl.name}: {n}" for n in check_platform_gyros(record, fl.triad, names, f"flights[{fl.index}]")]
        notes += [f"{fl.name}: {n}" for n in check_strapdown_axes(record, fl.triad, names, f"flights[{fl.index}]")]
        record, scale_notes = correct_imu_scale(record, fl.triad, names)
        notes += [f"{fl.name}: {n}" for n in scale_notes]

    t = time.perf_counter()
    est, seg_notes, segment_loss = estimate_flight(cfg, fl, record, checks, names)
    notes += [f"{fl.name}: {n}" for n in seg_notes]
    timings["estimate_s"] = time.perf_counter() - t
    gradio = None
    if cfg.gradiometer:
        gradio = _gradiometer_products(fl, record, est, notes)

    t = time.perf_counter()
    segs = line_segments(cfg, fl, est)
    t_drift = time.perf_counter()
    notes += estimate_drift(est, segs, cfg.drift, filter_lines=_product_is_smoothed(cfg.postprocess))
    timings["drift_s"] = time.perf_counter() - t_drift
    est.line_segments, est.line_info, line_notes = line_products(est, segs, cfg.postprocess, cfg.model)
    notes += line_notes
    # segmentation and post-processing; the drift fit between them has its own entry
    timings["postprocess_s"] = time.perf_counter() - t - timings["drift_s"]
    notes += check_result(
        fl.name, est.disturbance, est.line != "", est, record, checks, len(est.line_info), cfg.ellipsoid
    )
    # checks that passed are facts for summary.json (estimator.checks_passed), not warnings
    from .consistency import PASSED

    passed = [n.replace(PASSED, "", 1) for n in notes if PASSED in n]
    notes = [n for n in notes if PASSED not in n]

    if fl.truth is not None:
        tr = read_truth_csv(fl.truth_spec or fl.truth)
        unix = record.t0_unix_ns + np.round(est.time * 1e9).astype(np.int64)
        est.truth_mgal = truth_at(tr, unix)
        covered = float(np.mean(np.isfinite(est.truth_mgal))) if est.truth_mgal.size else 0.0
        if covered < 0.5:
            # a truth of another flight or day, or in other time units: every score would be
            # null (or of a sliver) without a word
            from .utc import utc_iso

            notes.append(
                f"{fl.name}: flights[{fl.index}].truth covers {100 * covered:.0f} % of the flight "
                f"(truth {utc_iso(int(tr['time_ns'][0]), 0)}..{utc_iso(int(tr['time_ns'][-1]), 0)}, flight "
                f"{utc_iso(int(unix[0]), 0)}..{utc_iso(int(unix[-1]), 0)}): another flight's, or its times "
                "in other units?"
            )

    est.name = fl.name
    est.t0_unix_ns = int(record.t0_unix_ns)
    est.notes = est.notes + notes
    est.timings = timings
    est.data_loss = [f"{fl.name}: {n}" for n in record.data_loss + segment_loss]
    est.estimator = {
        **est.estimator,
        "method": cfg.processing_method,
        "triad": fl.triad,
        "checks_passed": passed,
        **({"gradiometer": gradio} if gradio is not None else {}),
    }
    return est


def _gradiometer_products(fl, record, est: FlightEstimate, notes):
    """processing.gradiometer: seed-000 products of the flight's gradient channel (summary.json)."""
    from .gradiometer import flight_products

    if record.gradient is None:
        notes.append(f"{fl.name}: processing.gradiometer is on but the flight has no gravity-gradient channel")
        return None
    series = est.unprocessed
    p = flight_products(
        record.gradient.time,
        record.gradient.gamma_t,
        est.time,
        est.lat,
        est.lon,
        est.height,
        est.vel_n,
        float(series[0]),
        fl.triad,
    )
    if "disturbance" in p:
        # the gradient-propagated disturbance against the scalar estimate at the gradient epochs
        d = p.pop("disturbance")
        e = np.interp(p.pop("time"), est.time, series)
        p.pop("horizontal_n")
        p["disturbance_rms_vs_estimate_mgal"] = float(np.sqrt(np.mean((d - e) ** 2)) / 1e-5)
    return p


def inm_estimate(cfg: SurveyConfig, fl: FlightConfig, record, checks, names) -> tuple[FlightEstimate, list, list]:
    """3D-INM estimate of a flight, split at long gaps (consistency.plan_segments).

    The first piece starts from the initial state at the first IMU sample (given or from the
    data: :func:`gravsurvey.inm.params.resolve_initial_state`); every later one is
    re-initialised from GNSS on its own slice of the record, with the initial velocity sigma
    widened to what a 10 s GNSS fit gives in flight (``consistency.REINIT_VELOCITY_SIGMA_MPS``).
    Pieces are joined by :func:`gravsurvey.estimate.concatenate_estimates`.

    Returns
    -------
    est : FlightEstimate
    notes : list of str
    loss : list of str
        Pieces not estimated (too short, or not re-initialisable): reported as data loss.
    """

    from .consistency import REINIT_VELOCITY_SIGMA_MPS, plan_segments, span_text
    from .inm.params import resolve_initial_state
    from .inm.solve import estimate_anomaly
    from .io.record import slice_record

    lever = getattr(fl.ingest, "gnss_lever_arm_m", None)
    t0 = int(record.t0_unix_ns)
    given = fl.initial_given or {}
    start_given = all(k in given for k in ("lat_deg", "lon_deg", "height_m", "velocity_enu_mps"))
    spans, notes, loss = plan_segments(record, checks, names, start_given=start_given)
    imu_t0, imu_t1 = float(record.imu.time[0]), float(record.imu.time[-1])
    # the state at the first IMU sample only where a piece starts there (a late first GNSS fix
    # after the aircraft moved cannot place it)
    key = f"flights[{fl.index}].initial"
    if spans[0][0] == imu_t0:
        initial = resolve_initial_state(record, fl.triad, cfg.model, cfg.ellipsoid, fl.initial_given, key)
    if len(spans) == 1 and spans[0] == (imu_t0, imu_t1):
        sol = estimate_anomaly(record, cfg.model, initial, fl.triad, cfg.ellipsoid, gnss_lever_arm_t=lever)
        return from_inm_solution(sol, name=fl.name, t0_unix_ns=t0), notes, loss
    reinit_model = dataclasses.replace(
        cfg.model, initial_velocity_sigma_mps=max(cfg.model.initial_velocity_sigma_mps, REINIT_VELOCITY_SIGMA_MPS)
    )
    parts = []
    for a, b in spans:
        sub = slice_record(record, a, b, margin_s=2.0)
        try:
            if a == imu_t0:
                sol = estimate_anomaly(sub, cfg.model, initial, fl.triad, cfg.ellipsoid, gnss_lever_arm_t=lever)
            else:
                # from the data alone: GNSS position/velocity, attitude by in-motion alignment
                init = resolve_initial_state(sub, fl.triad, reinit_model, cfg.ellipsoid)
                sol = estimate_anomaly(sub, reinit_model, init, fl.triad, cfg.ellipsoid, gnss_lever_arm_t=lever)
            parts.append(from_inm_solution(sol, name=fl.name, t0_unix_ns=t0))
        except GravsurveyError as exc:
            loss.append(f"segment {span_text(record.t0_unix_ns, a, b)} not estimated: {exc}")
    if not parts:
        raise DataError(f"{record.source}: no segment of the flight could be estimated: {'; '.join(loss)}")
    if len(spans) > 1 or len(parts) < len(spans):
        notes.append(
            f"estimated {len(parts)} of {len(spans)} segments: "
            + ", ".join(span_text(record.t0_unix_ns, p.time[0], p.time[-1]) for p in parts)
        )
    parts, edge_notes = trim_one_sided_ends(parts, imu_t0, imu_t1)
    notes += edge_notes
    return concatenate_estimates(parts), notes, loss


def classic_estimate(cfg: SurveyConfig, fl: FlightConfig, record) -> FlightEstimate:
    """The conventional scalar reduction, on the same radial information as the 3D-INM.

    A strapdown triad needs its attitude to find the vertical: it comes from the 3D-INM
    mechanization of the same record (:func:`gravsurvey.classic.strapdown_attitude`). Without
    GNSS the position track for the Eotvos correction comes from the 3D-INM estimate. Both
    through the INS chain's public functions only.
    """
    from .classic import classic_reduction, strapdown_attitude
    from .inm.params import resolve_initial_state

    mat_nt, track = None, None
    needs_nav = fl.triad == "strapdown" or record.gnss is None
    if needs_nav:
        initial = resolve_initial_state(
            record, fl.triad, cfg.model, cfg.ellipsoid, fl.initial_given, f"flights[{fl.index}].initial"
        )
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
    return from_classic(res, name=fl.name, t0_unix_ns=int(record.t0_unix_ns))


# --------------------------------------------------------------------------
# survey
# --------------------------------------------------------------------------


def _flight_key(cfg: SurveyConfig, fl: FlightConfig) -> tuple[str, dict]:
    hashes = {}
    for p in fl.ingest.input_paths():
        p = Path(p)
        hashes[str(p)] = file_sha256(p) if p.is_file() else "missing"
    if fl.truth is not None and Path(fl.truth).is_file():
        hashes[str(fl.truth)] = file_sha256(fl.truth)
    h = hashlib.sha256()
    h.update(cfg.section_hash(fl).encode())
    h.update(json.dumps(hashes, sort_keys=True).encode())
    # the code's own fingerprint too: a checkout or branch installed under the same version
    # number must not reuse results computed by other code
    h.update(f"{__version__}/{CACHE_VERSION}/{code_fingerprint()}".encode())
    return h.hexdigest(), hashes


def _worker(config_path: str, output_dir: str, index: int):
    """Process pool entry: reload the config (cheap) and process one flight."""
    cfg = load_config(config_path, output_dir=output_dir)
    fl = cfg.flights[index]
    try:
        return ("ok", process_flight(cfg, fl))
    except GravsurveyError as exc:
        return ("error", f"{fl.name}: {exc}", getattr(exc, "flight_notes", []))
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
            gr = self.summary.get("grid") or {}
            if gr.get("shape"):
                sg = (gr.get("sigma") or {}).get("median_mgal")
                yield (
                    f"grid: {gr['shape'][0]} x {gr['shape'][1]} cells of {gr['spacing_m']:.0f} m, "
                    f"cross-validation RMS {gr['cv_rms_mgal']:.2f} mGal"
                    + (f", 1-sigma median {sg:.2f} mGal" if sg is not None else "")
                )
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


def run_survey(
    config_path,
    *,
    output_dir=None,
    jobs: int = 1,
    force: bool = False,
    wait_s: float = 0.0,
    progress: bool = False,
    plots: bool | None = None,
) -> RunResult:
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
    results: dict[str, FlightEstimate] = {}
    failed, skipped, processed, notes = [], [], [], []
    keys = {}
    todo = []
    for fl in cfg.flights:
        key, hashes = _flight_key(cfg, fl)
        keys[fl.name] = (key, hashes)
        # no pickle: JSON checked against the key before the arrays are read (gravsurvey.cache)
        cached = None if force else load_result(cache_dir, fl.name, key, FlightEstimate)
        if cached is not None:
            results[fl.name] = cached
            skipped.append(fl.name)
            log.info("%s: inputs and config unchanged, reusing the previous result", fl.name)
            for line in identification_log_lines(cached):
                log.info("%s", line)
            continue
        todo.append(fl)

    def _collect(fl, status, payload):
        if status == "ok":
            payload.input_hashes = keys[fl.name][1]
            results[fl.name] = payload
            processed.append(fl.name)
            save_result(cache_dir, fl.name, keys[fl.name][0], payload)
            log.info("%s: processed in %.1f s", fl.name, sum(payload.timings.values()))
            for line in identification_log_lines(payload):
                log.info("%s", line)
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
            from .pool import WorkerPool  # workers ignore Ctrl-C; interrupted: terminated

            with WorkerPool(min(jobs, len(todo))) as pool:
                futs = dict(
                    zip(pool.submit_all(_worker, [(str(cfg.path), str(out_dir), fl.index) for fl in todo]), todo)
                )
                for fut in as_completed(futs):
                    fl = futs[fut]
                    try:
                        status, payload, *early = fut.result()
                    except Exception as exc:  # worker died (e.g. killed, out of memory)
                        status, payload, early = "bug", f"{fl.name}: worker process failed: {exc}", []
                    notes.extend(early[0] if early else [])
                    _collect(fl, status, payload)
                    if bar:
                        bar.update(1)
        else:
            for fl in todo:
                try:
                    status, payload = "ok", process_flight(cfg, fl)
                except Exception as exc:
                    if INTERRUPT.is_set():
                        # a Ctrl-C swallowed inside numba's compiler leaves it half-done
                        # ("no compiled object yet"): the run was interrupted, not the flight bad
                        raise KeyboardInterrupt from exc
                    if isinstance(exc, GravsurveyError):
                        status, payload = "error", f"{fl.name}: {exc}"
                        notes.extend(getattr(exc, "flight_notes", []))
                    else:
                        status, payload = (
                            "bug",
                            f"{fl.name}: internal error {type(exc).__name__}: {exc}\n{traceback.format_exc()}",
                        )
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
        # the survey stage's warnings (a base tie not applied, levelling or a grid not made, lines
        # left unlevelled) reach the log and the CLI like the flights' own, not summary.json alone
        for n in summary.get("notes", []):
            log.warning("%s", n)
            notes.append(n)
    summary_timing = time.perf_counter() - t_out
    log.info("outputs written in %.1f s; total %.1f s", summary_timing, time.perf_counter() - t_start)
    if not ordered:
        summary = _write_failed_run(cfg, out_dir, failed, OutputTransaction) if failed else {"survey": cfg.name}
    return RunResult(out_dir, processed, skipped, failed, notes, summary, data_loss)


def _summary_head(cfg) -> dict:
    """summary.json's first keys: the survey, the software, when, the config and the method."""
    return {
        "survey": cfg.name,
        "software": {"name": "gravsurvey", "version": __version__, "python": platform.python_version()},
        "created_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "config": {"path": str(cfg.path), "sha256": file_sha256(cfg.path), "settings": cfg.raw},
        "processing_method": cfg.processing_method,
    }


def _write_failed_run(cfg, out_dir, failed, OutputTransaction) -> dict:
    """No flight could be processed: ``summary.json`` says so (``failed_flights``), and the
    deliverables an earlier run left in the folder are removed (the transaction's manifest),
    as a partly failed run drops the failed flights' ones: a folder never shows a previous
    run's profiles as the result of this one."""
    from .io import writers

    summary = {
        **_summary_head(cfg),
        "flights": {},
        "failed_flights": [f.splitlines()[0] for f in failed],
        "notes": ["no flight was processed: no deliverables (an earlier run's in this folder were removed)"],
    }
    with OutputTransaction(out_dir) as tx:
        writers.write_json(tx.path("summary.json"), summary)
    return summary


def _profile_table(cfg: SurveyConfig, results: list[FlightEstimate]):
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
        "disturbance_mgal": np.concatenate([r.disturbance for r in results]) / MGAL,
    }
    # the estimate the product was made from, named for what it holds (docs/outputs.md)
    for col, attr in (("kalman_mgal", "smoothed"), ("unfiltered_mgal", "unfiltered")):
        if any(getattr(r, attr) is not None for r in results):
            table[col] = (
                np.concatenate(
                    [
                        getattr(r, attr) if getattr(r, attr) is not None else np.full(len(r.time), np.nan)
                        for r in results
                    ]
                )
                / MGAL
            )
    if any(r.drift is not None for r in results):
        table["drift_mgal"] = (
            np.concatenate([r.drift if r.drift is not None else np.zeros(len(r.time)) for r in results]) / MGAL
        )
    table["sigma_mgal"] = np.concatenate([r.sigma for r in results]) / MGAL
    if any(r.has_attitude for r in results):
        # strapdown attitude and its 1-sigma per epoch (NaN for flights without it)
        att = np.degrees(np.concatenate([r.attitude for r in results]))
        sig = np.degrees(np.concatenate([r.attitude_sigma for r in results]))
        for j, name in enumerate(("roll", "pitch", "heading")):
            table[f"{name}_deg"] = att[:, j]
            table[f"{name}_sigma_deg"] = sig[:, j]
    if any(r.has_horizontal for r in results):
        table.update(horizontal_columns(results, cfg.ellipsoid))
    if all(r.truth_mgal is not None for r in results):
        table["truth_mgal"] = np.concatenate([r.truth_mgal for r in results])
        table["error_mgal"] = table["disturbance_mgal"] - table["truth_mgal"]
    return table, epsg


def horizontal_columns(results: list[FlightEstimate], ellipsoid=None) -> dict:
    """The horizontal-disturbance columns of the profile table (writers.HORIZONTAL_COLUMNS).

    ``dg_north_mgal, dg_east_mgal`` and their ``_sigma_`` columns in mGal, the deflections
    ``xi_arcsec = -dg_north / gamma``, ``eta_arcsec = -dg_east / gamma`` (gamma: normal
    gravity at the point) and their 1-sigma in arcsec; NaN where ``horizontal_observable`` is
    false and for flights without horizontal components.

    Returns
    -------
    dict
        column -> ndarray, shape (sum of the flights' epochs,).
    """
    from .estimate import deflection_arcsec
    from .geodesy import WGS84

    ell = ellipsoid if ellipsoid is not None else WGS84
    from .io.writers import HORIZONTAL_COLUMNS

    cols: dict = {c: [] for c in HORIZONTAL_COLUMNS}
    for r in results:
        n = len(r.time)
        if not r.has_horizontal:
            for v in cols.values():
                v.append(np.full(n, np.nan))
            continue
        obs = np.asarray(r.horizontal_observable, bool) if r.horizontal_observable is not None else np.ones(n, bool)
        blank = lambda a: np.where(obs, np.asarray(a, float), np.nan) if a is not None else np.full(n, np.nan)  # noqa: E731
        dn, de, sn, se = blank(r.dg_north), blank(r.dg_east), blank(r.sigma_north), blank(r.sigma_east)
        cols["dg_north_mgal"].append(dn / MGAL)
        cols["dg_east_mgal"].append(de / MGAL)
        cols["dg_north_sigma_mgal"].append(sn / MGAL)
        cols["dg_east_sigma_mgal"].append(se / MGAL)
        cols["xi_arcsec"].append(deflection_arcsec(dn, r.lat, r.height, ell))
        cols["eta_arcsec"].append(deflection_arcsec(de, r.lat, r.height, ell))
        cols["xi_sigma_arcsec"].append(np.abs(deflection_arcsec(sn, r.lat, r.height, ell)))
        cols["eta_sigma_arcsec"].append(np.abs(deflection_arcsec(se, r.lat, r.height, ell)))
    return {k: np.concatenate(v) for k, v in cols.items()}


#: a line's horizontal components are meaningful when at least this share of its epochs is observable
HORIZONTAL_MEANINGFUL_FRACTION = 0.5
#: Crossovers of lines more than this far apart in height (m) have the field's change between
#: the two heights predicted and taken off their differences (:func:`_continued_crossovers`);
#: 1 m changes a 10-mGal field of 10 km wavelength by 0.006 mGal, so lines flown within a metre
#: of each other are compared as they are.
CONTINUATION_MIN_DH_M = 1.0


def _product_name(line_stat: dict, drift_off: bool = False) -> str:
    """What a line's final product is, for a plot legend: its post-processor, or ``smoothed``
    for the smoothed estimate itself (post-processor ``none``, the default); ``drift_off``: the
    drift the lines showed was taken off the smoothed estimate first (:func:`estimate_drift`)."""
    method = str(line_stat.get("method") or "")
    name = "smoothed" if method in ("", "none") else method
    return f"{name} less drift" if drift_off else name


def horizontal_line_stats(table: dict, idx) -> dict:
    """summary.json facts of one line's horizontal components (rows ``idx`` of the table).

    ``horizontal_meaningful``: at least :data:`HORIZONTAL_MEANINGFUL_FRACTION` of the line's
    epochs observable (finite ``dg_north_mgal``); ``horizontal_observable_fraction``; means
    of ``dg_north_mgal``, ``dg_east_mgal``, ``xi_arcsec``, ``eta_arcsec`` over the observable
    epochs (None when none).
    """
    dn = np.asarray(table["dg_north_mgal"], float)[idx]
    obs = np.isfinite(dn)
    frac = float(obs.mean()) if obs.size else 0.0
    out = {
        "horizontal_meaningful": bool(obs.size) and frac >= HORIZONTAL_MEANINGFUL_FRACTION,
        "horizontal_observable_fraction": frac,
    }
    for c in ("dg_north_mgal", "dg_east_mgal", "xi_arcsec", "eta_arcsec"):
        v = np.asarray(table[c], float)[idx]
        v = v[np.isfinite(v)]
        out[f"mean_{c}"] = float(v.mean()) if v.size else None
    return out


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
            tie = tie_flight(
                fl.tie,
                r.time,
                r.lat,
                r.height,
                r.unprocessed / MGAL,
                ellipsoid=cfg.ellipsoid,
                key_path=f"flights[{fl.index}].tie",
            )
        except DataError as exc:
            notes.append(f"{r.name}: base tie not applied, the flight stays on a relative level: {exc}")
            continue
        ties[r.name] = tie
        corr[rows[r.name]] = tie.correction(r.time)
        windows = [rd for rd in (fl.tie.before, fl.tie.after) if rd is not None and rd.reading_mgal is None]
        if windows and r.method == "inm":
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
        "units": {
            "*_mgal": "mGal (1e-5 m/s^2)",
            "*_m": "m",
            "*_deg": "deg",
            "time_unix_ns": "ns since 1970-01-01 UTC",
            "time_s": "s",
        },
        "software": f"gravsurvey {__version__}",
        "level": level_state,
        "processing": {
            "method": cfg.processing_method,
            "ellipsoid": getattr(cfg.ellipsoid, "name", None),
            **{
                k: cfg.raw.get(k)
                for k in ("model", "lines", "postprocess", "levelling", "grid")
                if cfg.raw.get(k) is not None
            },
        },
    }


def write_survey_outputs(cfg: SurveyConfig, out_dir, results: list[FlightEstimate], failed=()) -> dict:
    """Write the survey deliverables for processed flights (ties, crossovers, levelling, grid,
    files) into ``out_dir`` atomically; return the summary. The public entry of the output
    stage (benchmarks/bench_outputs.py, tests); :func:`run_survey` calls the same code."""
    from .io.writers import OutputTransaction

    return _write_outputs(cfg, Path(out_dir), list(results), list(failed), OutputTransaction)


def _continued_crossovers(cfg, xo, table, in_line, value_mgal) -> tuple:
    """The crossovers with the field's change between the two lines' heights taken off.

    Where two lines cross more than :data:`CONTINUATION_MIN_DH_M` apart in height, part of
    their difference is the field's own (it weakens upwards): it is predicted by equivalent
    sources fitted to the lines as the grid fits them (:func:`gravsurvey.grid.continuation_difference`,
    the ``grid:`` settings) and taken off, so that the crossover statistics and the levelling
    see level errors only (docs/survey.md, "Crossovers at different heights").

    Returns
    -------
    crossovers : gravsurvey.crossovers.Crossovers
    continuation : dict or None
        For summary.json (``crossovers.continuation``): the largest height difference (m), the
        RMS and largest field change taken off (mGal), the fit's depth, damping and
        cross-validation RMS; None where no two crossing lines differ in height.
    notes : list of str
        When the prediction could not be made although the heights differ.
    """
    from .crossovers import with_continuation
    from .grid import GridOptions, continuation_difference

    dh = np.abs(xo.height_a_m - xo.height_b_m)
    dh = dh[np.isfinite(dh) & xo.valid]
    if not (dh.size and dh.max() > CONTINUATION_MIN_DH_M):
        return xo, None, []
    lab = np.char.add(np.char.add(table["flight"].astype(str), "/"), table["line"].astype(str))
    try:
        cont, fit = continuation_difference(
            table["easting_m"][in_line],
            table["northing_m"][in_line],
            table["height_m"][in_line],
            value_mgal[in_line],
            lab[in_line],
            xo.easting_m,
            xo.northing_m,
            xo.height_a_m,
            xo.height_b_m,
            cfg.grid if cfg.grid is not None else GridOptions(),
        )
    except (DataError, np.linalg.LinAlgError, ValueError) as exc:
        return (
            xo,
            None,
            [
                f"crossovers: lines cross up to {dh.max():.0f} m apart in height, but the field's change "
                f"between the heights could not be predicted ({exc}): the crossover differences and "
                "the levelling include it"
            ],
        )
    cont = np.where(np.isfinite(xo.height_a_m - xo.height_b_m) & xo.valid, cont, 0.0)
    info = {
        "max_height_difference_m": float(dh.max()),
        "rms_mgal": float(np.sqrt(np.mean(cont[xo.valid] ** 2))),
        "max_mgal": float(np.max(np.abs(cont))),
        "fit": fit,
    }
    return with_continuation(xo, cont), info, []


def _flights_across(table, groups, kind_of) -> list[str]:
    """:func:`gravsurvey.segmentation.flights_across_lines` over the table's lines, each line's
    heading from its first and last projected position."""
    from .segmentation import flights_across_lines

    lines = []
    for (flight, name), idx in groups.items():
        if not name:
            continue
        e, n = table["easting_m"][idx], table["northing_m"][idx]
        ok = np.flatnonzero(np.isfinite(e) & np.isfinite(n))
        if ok.size < 2:
            continue
        de, dn = e[ok[-1]] - e[ok[0]], n[ok[-1]] - n[ok[0]]
        heading = float(np.degrees(np.arctan2(de, dn)))
        lines.append((flight, kind_of.get((flight, name), "line"), heading, float(np.hypot(de, dn))))
    return flights_across_lines(lines)


def _write_outputs(cfg, out_dir, results, failed, OutputTransaction) -> dict:
    """Survey products: base ties -> crossovers -> levelling -> grid, then every deliverable.

    Linear in the number of rows, lines and flights (rows of a line are found once by
    :func:`gravsurvey.io.writers.line_groups`; no per-line mask over the whole table).
    """
    from . import report
    from .io import writers
    from .crossovers import Crossovers, find_crossovers
    from .levelling import choose_levelling, understated_sigma_note

    table, epsg = _profile_table(cfg, results)
    in_line = table["line"] != ""
    rows = _flight_rows(results)
    time_s = np.concatenate([np.asarray(r.time, float) for r in results])  # each flight's own time base
    groups = writers.line_groups(table["flight"], table["line"])
    kind_of = {(r.name, ln): info.get("kind", "line") for r in results for ln, info in r.line_info.items()}
    notes = []
    detected = getattr(cfg.lines, "mode", "auto") == "auto"
    auto = {fl.name for fl in cfg.flights if getattr(fl, "lines_windows", None) is None} if detected else set()
    if getattr(cfg.lines, "line_heading_deg", None) is None and auto:
        # flights named by their own direction only (windows name their lines themselves)
        notes += _flights_across(table, {k: v for k, v in groups.items() if k[0] in auto}, kind_of)

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
                "height_m": table["height_m"][idx],
                "sigma_mgal": table["sigma_mgal"][idx],
                "index": idx,
            }
        )
    xo = find_crossovers([{k: v for k, v in ln.items() if k not in ("index", "sigma_mgal")} for ln in lines])
    xo, continuation, continuation_notes = _continued_crossovers(cfg, xo, table, in_line, tied_value)
    notes += continuation_notes
    xo_stats = {**xo.statistics(), "continuation": continuation}

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
        xo_tied.diff_mgal = xo_tied.value_a_mgal - xo_tied.value_b_mgal - xo.continuation_mgal
        lev = choose_levelling(xo_tied, lines, lopt, tied_flights=list(ties))
        understated = understated_sigma_note(lev)
        if understated:
            notes.append(understated)
        if not lev.decision["applied"]:
            notes.append(f"levelling: not applied: {lev.decision['reason']} (levelling.enabled: true forces it)")
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
    level_state = "absolute" if lines and n_abs == len(lines) else "relative" if n_abs == 0 else "partly absolute"
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
        from .grid import grid_lines, sigma_notes

        lab = np.where(in_line, table["flight"].astype(str), "")
        lab = np.char.add(np.char.add(lab, "/"), table["line"].astype(str))
        # a line's errors are correlated over about its resolution (the smoother's and filter's)
        err_len = np.zeros(lab.size)
        for r in results:
            for name, info in r.line_info.items():
                idx = groups.get((r.name, name))
                if idx is not None and info.get("resolution_m"):
                    err_len[idx] = float(info["resolution_m"])
        try:
            grid = grid_lines(
                table["easting_m"][in_line],
                table["northing_m"][in_line],
                table["height_m"][in_line],
                table["levelled_mgal"][in_line],
                lab[in_line],
                gopt,
                sigma_mgal=table["sigma_mgal"][in_line],
                noise_length_m=err_len[in_line],
            )
            grid_info = grid.summary()
            notes.extend(sigma_notes(grid.sigma_info))
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
            # line_info made by line_products has it; one built by a caller may give only resolution_m
            st.setdefault("resolution_note", resolution_statement(st.get("resolution_m")))
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
                for col in ("kalman_mgal", "unfiltered_mgal"):
                    if col in table:
                        st[f"{col[:-5]}_rms_vs_truth_mgal"] = _rms(table[col][idx] - table["truth_mgal"][idx])
                st["levelled_rms_vs_truth_mgal"] = _rms(table["levelled_mgal"][idx] - table["truth_mgal"][idx])
                fl_err[r.name].append(e_)
            if "dg_north_mgal" in table:
                st.update(horizontal_line_stats(table, idx))
            line_stats.append(st)
            lines_of[r.name][name] = st
    flights_summary = {}
    for r in results:
        flights_summary[r.name] = {
            "segments": r.line_segments,
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
    # every line's stated resolution travels with the table into each file (issue 12 item 4)
    metadata["resolution"] = {f"{st['flight']}/{st['line']}": st["resolution_note"] for st in line_stats}
    summary = {
        **_summary_head(cfg),
        "crs_epsg": epsg,
        "crs": metadata["crs"],
        "level": {
            "state": level_state,
            "note": level_note,
            "tied_flights": sorted(ties),
            "untied_flights": [r.name for r in results if r.name not in ties],
        },
        "flights": flights_summary,
        "failed_flights": [f.splitlines()[0] for f in failed],
        "crossovers": xo_stats,
        "levelling": (
            {"applied": True, **{k: v for k, v in lev_stats.items() if k != "per_line"}}
            if lev_stats
            else {"applied": False, **{k: v for k, v in lev_skipped.statistics().items() if k != "per_line"}}
            if lev_skipped is not None
            else None
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
            writers.write_xyz(
                tx.path("profiles.xyz"),
                table,
                title=f"gravsurvey profiles: {cfg.name}",
                metadata=metadata,
                line_notes={(st["flight"], st["line"]): st["resolution_note"] for st in line_stats},
            )
        if cfg.geojson:
            writers.write_geojson(tx.path("lines.geojson"), table, line_stats, epsg, metadata=metadata)
        writers.write_crossovers_csv(tx.path("crossovers.csv"), xo, metadata=metadata)
        if grid is not None:
            from .grid import write_grid_netcdf

            write_grid_netcdf(
                tx.path("grid.nc"),
                grid,
                epsg,
                title=f"{cfg.name}: gravity disturbance (levelled_mgal)",
                attrs={
                    "survey": cfg.name,
                    "software": f"gravsurvey {__version__}",
                    "level": level_state,
                    "source": "profiles.csv levelled_mgal",
                },
            )
        if cfg.plots:
            drift_off = {r.name: r.drift is not None for r in results}
            for ln in lines:
                idx = ln["index"]
                # a line of the table without line_info (a caller's own estimate) states nothing
                stat = lines_of.get(ln["flight"], {}).get(ln["line"], {})
                e, n = table["easting_m"][idx], table["northing_m"][idx]
                step = np.hypot(np.diff(e), np.diff(n))
                dist_km = np.concatenate(([0.0], np.cumsum(np.where(np.isfinite(step), step, 0.0)))) / 1e3
                report.plot_line_profile(
                    tx.path(f"profile_{ln['flight']}_{ln['line']}.png"),
                    dist_km,
                    # a chain without a Kalman estimate (classic) plots its product alone: its
                    # unfiltered reduction (+-1e6 mGal) would hide it
                    table["kalman_mgal"][idx] if "kalman_mgal" in table else None,
                    table["disturbance_mgal"][idx],
                    table["sigma_mgal"][idx],
                    truth_mgal=table["truth_mgal"][idx] if "truth_mgal" in table else None,
                    title=f"{cfg.name} {ln['flight']} {ln['line']}\n"
                    + stat.get("resolution_note", resolution_statement(None)),
                    final_label=f"final ({_product_name(stat, drift_off.get(ln['flight'], False))})",
                    x_label="distance along line, km",
                    horizontal=(
                        {
                            c: table[c][idx]
                            for c in ("dg_north_mgal", "dg_east_mgal", "dg_north_sigma_mgal", "dg_east_sigma_mgal")
                        }
                        if "dg_north_mgal" in table
                        else None
                    ),
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
                    tx.path("grid_map.png"),
                    grid.easting_m,
                    grid.northing_m,
                    grid.value_mgal,
                    table["easting_m"][in_line],
                    table["northing_m"][in_line],
                    track_ids=np.char.add(table["flight"][in_line].astype(str), table["line"][in_line].astype(str)),
                    crs_label=_crs_name(epsg),
                    title=(
                        f"{cfg.name}: gravity disturbance, "
                        + (
                            "tied and levelled"
                            if lev is not None and ties
                            else "levelled"
                            if lev is not None
                            else "tied, not levelled"
                            if ties
                            else "not levelled"
                        )
                        + f" ({level_state} level)"
                    ),
                    note=(
                        f"{grid.method.replace('_', ' ')}, {grid.spacing_m:.0f} m cells, "
                        + (
                            f"at {grid.altitude_m:.0f} m ellipsoidal height"
                            if grid.altitude_m is not None
                            else "at the flight heights"
                        )
                        + f"; cross-validation RMS {grid.cv_rms_mgal:.2f} mGal"
                        + (
                            f"\n1-sigma (dashed contours) median {grid.sigma_info['median_mgal']:.2f} mGal"
                            if (grid.sigma_info or {}).get("median_mgal") is not None
                            else ""
                        )
                    ),
                    sigma_mgal=grid.sigma_mgal,
                )
        summary["output_sha256"] = tx.file_hashes()
        writers.write_json(tx.path("summary.json"), summary)
    return summary
