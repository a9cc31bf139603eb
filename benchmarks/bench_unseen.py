#!/usr/bin/env python
"""Unseen-flight suite (issue 12 item 6): default configuration vs oracle, scalar chain, Wiener bound.

Usage::

    python benchmarks/bench_unseen.py [--flights N] [--quick] [--first-seed S] [--json out.json]
        [--runs default,oracle,classic] [--heights altimeter|gnss|carrier-phase] [--model KEY=VALUE ...] [--accel-bias B1,B2] [--gyro BIAS_DEGPH,WHITE_DEGPH]
        [--gravimeter-drift MGAL_PER_H] [--gravimeter-tare AT,MGAL] [--gnss-markov SIGMA_M,TAU_S] [--vertical-field-only]
        [--line-levels DZ_M] [--tie-lines N]

Draws ``N`` (default 20) flights with seeds ``S .. S+N-1`` from the unseen-flight generator
(``gravsurvey.simulate.unseen``: random fields, noise x0.3-x3, rates, triads, headings,
speeds, heights, 30-240 min), simulates each once into ``benchmarks/.unseen_cache/<name>/``
(gitignored; reused while the drawn flight is unchanged) and runs ``gravsurvey run`` in-process
(``gravsurvey.pipeline.run_survey``) three times:

* ``default``: ``survey.yaml`` as written by the simulator, i.e. only what a user knows;
* ``oracle``: ``oracle.yaml``, the model matched to the simulated errors and the true field's
  Gauss-Markov fit, exact initial state (no user has this);
* ``classic``: ``survey.yaml`` plus ``processing: {method: classic}`` (the conventional scalar
  chain, docs/benchmarks.md).

Scored samples: the epochs on the simulator's survey lines (truth.csv ``line`` = ``L..``/``T..``)
more than 10 min from the first and last epoch.  RMS after removing the mean error over those
samples (mGal), for the final product (``disturbance_mgal``) and the smoothed Kalman estimate
(``kalman_mgal``) of the default run, the oracle run's final product and the classic product.
The Wiener bound is the RMS error of the non-causal Wiener filter that knows the field's
spectrum, evaluated on the flight's own true field (:func:`oracle_wiener_bound`): the filter
``H = c S_s / (c S_s + S_n)`` run over the whole true profile, the field it loses scored on the
scored samples, plus the noise it passes, ``int H^2 S_n df``; the least over two estimates of
``S_s`` from the truth on the scored lines (:func:`truth_psd`, :func:`truth_psd_multitaper`) and
levels ``c`` of 1/16 to 16.  ``S_n`` is the noise PSD of the drawn sensor errors
(``gravsurvey.simulate.unseen.noise_psd``; derivation in docs/simulate.md).  Until 2026-12-02 the
bound was the formula ``sqrt(int S_s S_n / (S_s + S_n) df)`` on the first estimate; its
scaling to the lines' variance and its window's weight on the lines' middle made ``S_s`` 6-18x
too small where full-length U006's error is decided (docs/simulate.md); the JSON keeps it as
``bound_formula_rms``.  Resolutions (half wavelength, km): stated by the default and classic
products (median over lines), and the bound filter's (Wiener gain 1/2).  Prints a Markdown table and the median and
worst ratio RMS / bound.  Two columns split the default's error: ``drift``, the RMS of the drawn
gravimeter drift (bias + Gauss-Markov + linear, ``gravsurvey.simulate.run.gravimeter_slow_error``) over the
scored samples, and ``kalman less drift``, the RMS of the smoothed Kalman estimate's error (before
the drift stage takes off what the lines show) with that drift taken off: where the second is
near the bound and the default is not, the flight's loss is the drift its lines could not tell
from the field.  ``error/sigma`` is the RMS of the final product's error (mean taken off) over
its stated sigma, with the 5-95 % range a right sigma would score on that flight's error
(:func:`sigma_ratio_range`): outside it, the miss is the sigma's, not chance.  A summary line
sets the missed field the sigma states against the truth's (:func:`missed_field`) and counts the
error/sigma with the truth's in its place.  ``--quick`` caps
every drawn flight at 40 min and 50 Hz IMU (the
same draws otherwise) for a fast check.  ``--model KEY=VALUE`` gives the default run a
``model`` section (a datasheet figure a user would know); ``--accel-bias B1,B2`` replaces the
drawn horizontal accelerometer biases (a tactical IMU's); ``--gyro BIAS_DEGPH,WHITE_DEGPH`` the drawn
gyros (:func:`with_gyro`).  ``--heights gnss`` gives the default run
the GNSS fixes' heights as its height channel; ``--heights carrier-phase`` makes the GNSS
carrier-phase grade and its heights the only height channel (:func:`with_carrier_phase_gnss`);
``--gravimeter-drift MGAL_PER_H`` adds a linear gravimeter drift (:func:`with_gravimeter_drift`);
``--gravimeter-tare AT,MGAL`` a step of the gravimeter's reading at the fraction ``AT`` of the
flight (:func:`with_gravimeter_tare`);
``--gnss-markov SIGMA_M,TAU_S`` a slowly varying GNSS error (:func:`with_gnss_markov`);
``--vertical-field-only`` zeroes the field's horizontal components at the sensors
(:func:`with_vertical_field_only`);
``--line-levels DZ_M`` flies every second line DZ_M higher (:func:`with_line_levels`);
``--tie-lines N`` flies N tie lines across the lines after them (:func:`with_tie_lines`);
``--wind SPEED,FROM_DEG[,ground]`` flies every flight in a steady wind (:func:`with_wind`);
``--airfield HEIGHT_M[,CLIMB_MPS]`` starts and ends every flight parked on the ground
(:func:`with_airfield`); ``--antenna FWD,LEFT,UP`` puts the GNSS antenna off the IMU
(:func:`with_antenna`).
Uses public API only.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import hashlib
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from gravsurvey.errors import GravsurveyError
from gravsurvey.inm.identify import SpectralModel, smoother_gain
from gravsurvey.pipeline import read_truth_csv, run_survey
from gravsurvey.simulate.run import gravimeter_slow_error
from gravsurvey.simulate.simconfig import MAX_ANTENNA_M, MAX_WIND_FRACTION
from gravsurvey.simulate.unseen import (
    RANGES,
    draw_flight_spec,
    limit_spec,
    noise_psd,
    spec_summary,
    write_flight,
)

CACHE = REPO / "benchmarks" / ".unseen_cache"
MGAL = 1e-5
#: scored samples start/stop this long after/before the first/last epoch, s
EDGE_S = 600.0
QUICK_MAX_DURATION_S = 2400.0
QUICK_MAX_IMU_HZ = 50.0


def _spec_hash(spec) -> str:
    return hashlib.sha256(json.dumps(spec["sim"], sort_keys=True).encode()).hexdigest()[:16]


def prepare_flight(spec, cache=CACHE) -> Path:
    """Simulate the flight into the cache unless the same draw is already there; its folder."""
    d = Path(cache) / f"{spec['name']}_{_spec_hash(spec)}"
    done = d / "spec.json"
    if not done.is_file():
        write_flight(spec, d, oracle=True)
        cfg = yaml.safe_load((d / "survey.yaml").read_text())
        cfg["processing"] = {"method": "classic"}
        cfg["output"] = {"dir": "out_classic"}
        (d / "classic.yaml").write_text(
            "# survey.yaml with the conventional scalar chain\n"
            + yaml.safe_dump(cfg, sort_keys=False, default_flow_style=None)
        )
        done.write_text(json.dumps({k: v for k, v in spec.items() if k != "sim"}, indent=1, default=float))
    return d


def read_profiles(path: Path) -> dict:
    """profiles.csv (docs/outputs.md) -> columns (``time_unix_ns`` int64, ``line`` str, floats)."""
    with open(path, newline="") as fh:
        rows = list(csv.reader(line for line in fh if not line.startswith("#")))
    head, rows = rows[0], rows[1:]
    out = {}
    for i, h in enumerate(head):
        col = [r[i] for r in rows]
        if h == "time_unix_ns":
            out[h] = np.array(col, dtype=np.int64)
        elif h in ("flight", "line", "time_utc"):
            out[h] = np.array(col, dtype=object)
        else:
            out[h] = np.array([float(x) if x not in ("", "NaN", "nan") else np.nan for x in col])
    return out


def scored_mask(time_ns, truth) -> np.ndarray:
    """Epochs on the simulator's survey/tie lines, >= EDGE_S from both ends of the flight."""
    tt = truth["time_ns"]
    k = np.clip(np.searchsorted(tt, time_ns), 1, tt.size - 1)
    k = np.where(np.abs(tt[k - 1] - time_ns) <= np.abs(tt[k] - time_ns), k - 1, k)  # nearest truth sample
    on_line = np.array([str(lab).startswith(("L", "T")) for lab in truth["line"][k]])
    t = (time_ns - time_ns[0]) / 1e9
    return on_line & (t >= EDGE_S) & (t <= t[-1] - EDGE_S)


def rms_after_bias(err) -> tuple[float | None, float]:
    """(RMS of ``err`` minus its mean over the finite samples, fraction finite)."""
    e = np.asarray(err, float)
    ok = np.isfinite(e)
    if not ok.any():
        return None, 0.0
    x = e[ok] - e[ok].mean()
    return float(np.sqrt(np.mean(x**2))), float(ok.mean())


def _runs(mask):
    """(start, stop) index pairs of the True runs of a boolean array."""
    m = np.concatenate([[False], mask, [False]]).astype(int)
    d = np.diff(m)
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def _line_residuals(truth_mgal, mask, dt_s):
    """Per scored run (line) of at least 16 samples: (truth less its least-squares straight
    line, that straight line), m/s^2."""
    x_all = np.asarray(truth_mgal, float) * MGAL
    out = []
    for a, b in _runs(mask):
        if b - a < 16:
            continue
        x = x_all[a:b]
        t = np.arange(x.size) * dt_s
        trend = np.polyval(np.polyfit(t, x, 1), t)
        out.append((x - trend, trend))
    return out


def truth_psd(truth_mgal, mask, dt_s=1.0):
    """One-sided PSD ((m/s^2)^2/Hz) of the true disturbance on the scored samples.

    On the frequency grid ``k / T`` of the longest scored run (line) of duration ``T``:

    * within the lines: per line, its least-squares straight line removed, the periodogram of
      the first differences (Blackman-Harris window) divided by ``|2 sin(pi f dt)|^2``:
      differencing flattens the steep field spectrum by ``f^2`` and the window's -92 dB
      sidelobes keep a strong long-wavelength field from leaking into the band where the
      noise decides (a plain Hann periodogram of an 8-min line of an 80 mGal field put
      leakage 100x above the true spectrum at 5 km wavelength); interpolated onto the grid,
      averaged weighted by line length and scaled so its integral equals the lines' mean
      residual variance;
    * wavelengths of a line length and longer: the variance of the lines' straight lines
      about the flight mean (their offsets and slopes; the score removes one mean per
      flight) as power in the lowest bin ``1 / T``.

    Joining the lines into one series instead would turn the jumps between them into
    broadband power that is not in the field.

    Returns
    -------
    (f, psd) : ndarrays (m,) on ``f = k / T``, k = 0..; psd[0] = 0; or (None, None).
    """
    from scipy.signal import periodogram

    lines = _line_residuals(truth_mgal, mask, dt_s)
    if not lines:
        return None, None
    f = np.fft.rfftfreq(max(r.size for r, _ in lines), dt_s)
    df = f[1]
    within = np.zeros_like(f)
    weights, variances, trends = [], [], []
    for r, trend in lines:
        fk, pd = periodogram(np.diff(r), fs=1.0 / dt_s, window="blackmanharris", detrend="constant")
        pk = pd[1:] / (2.0 * np.sin(np.pi * fk[1:] * dt_s)) ** 2
        within[1:] += np.interp(f[1:], fk[1:], pk) * r.size
        weights.append(r.size)
        variances.append(np.var(r))
        trends.append(trend)
    w = np.asarray(weights, float)
    within /= w.sum()
    area = within[1:].sum() * df
    target = float(np.sum(w * np.asarray(variances)) / w.sum())
    if area > 0:
        within *= target / area
    all_trends = np.concatenate(trends)
    long_wave = float(np.var(all_trends))
    psd = within.copy()
    psd[0] = 0.0
    psd[1] += long_wave / df
    return f, psd


#: Time-bandwidth product and number of the Slepian tapers of :func:`truth_psd_multitaper`.
MULTITAPER_NW, MULTITAPER_K = 4.0, 7
#: Levels (factors on a spectrum estimate) the oracle Wiener filter is scanned over.
ORACLE_LEVELS = np.geomspace(1.0 / 16.0, 16.0, 17)


def truth_psd_multitaper(truth_mgal, mask, dt_s=1.0):
    """As :func:`truth_psd`, with Thomson's multitaper estimate of each line's differences.

    The Slepian tapers (``MULTITAPER_NW``, ``MULTITAPER_K``) together weigh the whole line
    about evenly, where the single Blackman-Harris window weighs its middle third: a strong
    field whose short wavelengths lie near the ends of the lines (full-length U006) is then
    not missed.  The bins within the tapers' main lobe of zero frequency (differencing's
    leakage, amplified by ``1 / sin^2``) take what the line's variance leaves after the
    others, instead of the whole spectrum being scaled to it.
    """
    from scipy.signal.windows import dpss

    lines = _line_residuals(truth_mgal, mask, dt_s)
    if not lines:
        return None, None
    f = np.fft.rfftfreq(max(r.size for r, _ in lines), dt_s)
    within = np.zeros_like(f)
    weights, trends = [], []
    for r, trend in lines:
        d = np.diff(r)
        d = d - d.mean()
        fk = np.fft.rfftfreq(d.size, dt_s)
        tapers = dpss(d.size, MULTITAPER_NW, MULTITAPER_K)
        pd = 2.0 * dt_s * np.mean(np.abs(np.fft.rfft(tapers * d, axis=1)) ** 2, axis=0)
        pk = np.zeros_like(pd)
        pk[1:] = pd[1:] / (2.0 * np.sin(np.pi * fk[1:] * dt_s)) ** 2
        lobe = fk <= (MULTITAPER_NW + 1.0) / (d.size * dt_s)
        lobe[0] = False
        resolved = float(pk[1:][~lobe[1:]].sum() * fk[1])
        in_lobe = float(pk[lobe].sum() * fk[1])
        if in_lobe > 0:
            pk[lobe] *= max(np.var(r) - resolved, 0.0) / in_lobe
        within[1:] += np.interp(f[1:], fk[1:], pk[1:]) * r.size
        weights.append(r.size)
        trends.append(trend)
    psd = within / float(sum(weights))
    psd[0] = 0.0
    psd[1] += float(np.var(np.concatenate(trends))) / f[1]
    return f, psd


def oracle_wiener_bound(truth_mgal, mask, dt_s, noise, speed_mps, spectra):
    """Error of the best Wiener filter built from known spectra, on this flight's own field.

    For each spectrum estimate ``(f, S)`` in ``spectra`` and each level ``c`` in
    ``ORACLE_LEVELS``, the filter ``H = c S / (c S + S_n)`` is applied to the whole true
    profile (every epoch, turns included, as the smoother runs; mirrored at its ends): the
    field it loses is ``(H - 1) * truth`` on the scored samples (less its mean, as the score),
    the noise it passes ``int H^2 S_n df``.  The least total RMS is returned: what a filter
    that knows the field's spectrum achieves on this field, with no estimate of that spectrum
    to be wrong (the level scan takes out a level error; two estimates, the shape's).

    Parameters
    ----------
    truth_mgal : ndarray (n,)
        True disturbance at the product's epochs, mGal (NaN allowed: interpolated over).
    mask : ndarray of bool (n,)
        Scored samples.
    dt_s : float
        Epoch spacing, s.
    noise : callable
        ``noise(f_hz)`` -> one-sided noise PSD, (m/s^2)^2/Hz.
    speed_mps : float
    spectra : list of (f, S)
        One-sided field spectrum estimates, (m/s^2)^2/Hz.

    Returns
    -------
    (rms_mgal, resolution_km, level) : the best filter's RMS error, its half-wavelength
    resolution (the lowest frequency above the gain's peak with ``H < 1/2``) and the level ``c``
    it took.
    """
    tr = np.asarray(truth_mgal, float) * MGAL
    n = tr.size
    ok = np.isfinite(tr)
    tr = np.interp(np.arange(n), np.flatnonzero(ok), tr[ok])
    x = np.concatenate([tr, tr[::-1]])
    big_x = np.fft.rfft(x - x.mean())
    f = np.fft.rfftfreq(2 * n, dt_s)
    s_n = np.asarray(noise(f), float)
    best = None
    for f_s, s_s in spectra:
        s = np.interp(f, f_s, s_s)
        for c in ORACLE_LEVELS:
            h = c * s / (c * s + s_n)
            h[0] = 1.0
            lost = np.fft.irfft(big_x * (h - 1.0), 2 * n)[:n][mask]
            lost = lost - lost.mean()
            mse = float(np.mean(lost**2) + np.sum((h**2 * s_n)[1:]) * f[1])
            if best is None or mse < best[0]:
                # the pass band's upper edge: where a drift dominates, the gain is low at the
                # longest wavelengths too, so the search starts at the gain's peak
                peak = int(np.argmax(h[1:]))
                below = np.flatnonzero(h[1:][peak:] < 0.5)
                f_half = f[1:][peak + below[0]] if below.size else f[-1]
                best = (mse, speed_mps / (2.0 * f_half) / 1000.0, float(c))
    return math.sqrt(best[0]) / MGAL, best[1], best[2]


def wiener_bound(f, s_s, s_n, speed_mps):
    """(RMS error of the optimal non-causal filter, mGal; its half-wavelength resolution, km).

    ``sqrt(int_0^fN S_s S_n / (S_s + S_n) df)`` over one-sided PSDs on a uniform grid ``f``
    (rectangle rule; the DC bin is excluded: the score removes the mean); resolution =
    ``speed / (2 f_half)`` with ``f_half`` the lowest frequency where ``S_s < S_n`` (Wiener
    gain below 1/2).
    """
    df = f[1] - f[0]
    keep = f > 0
    f, s_s, s_n = f[keep], s_s[keep], s_n[keep]
    mse = float(np.sum(s_s * s_n / (s_s + s_n)) * df)
    below = np.flatnonzero(s_s < s_n)
    f_half = f[below[0]] if below.size else f[-1]
    return math.sqrt(mse) / MGAL, speed_mps / (2.0 * f_half) / 1000.0


def median_resolution_km(summary, key="resolution_m"):
    """Median over a run's lines (summary.json) of the per-line ``key`` (m), in km; None if none."""
    vals = [ln.get(key) for fl in summary.get("flights", {}).values() for ln in fl.get("lines", {}).values()]
    vals = [v for v in vals if isinstance(v, (int, float)) and v > 0]
    return float(np.median(vals)) / 1000.0 if vals else None


def _normalised_error(err, sigma) -> np.ndarray:
    """(error minus its mean) / stated 1-sigma over the samples where both are finite (and the
    sigma positive), shape (m,)."""
    e, s = np.asarray(err, float), np.asarray(sigma, float)
    ok = np.isfinite(e) & np.isfinite(s) & (s > 0)
    return (e[ok] - e[ok].mean()) / s[ok]


def sigma_ratio_rms(err, sigma) -> float | None:
    """RMS of (error minus its mean) / stated 1-sigma over the finite samples (1 when calibrated)."""
    u = _normalised_error(err, sigma)
    return float(np.sqrt(np.mean(u**2))) if u.size else None


def missed_field(truth_mgal, mask, dt_s: float, identification: dict) -> float | None:
    """The field the default run's smoother misses on this flight, from the truth, mGal.

    RMS over the scored samples (mean taken off) of ``H * truth - truth``, with ``H`` the
    steady-state transfer of the smoother the identification chose
    (``gravsurvey.inm.identify.smoother_gain`` of its ``spectral_model``, the noise scaled by its
    ``noise_scale`` as ``refine_prior`` scales it) applied to the whole true profile in the
    frequency domain (zero-padded to twice its length).  The stated sigma's share of it is
    ``identification.field_sigma_missed_mps2`` (the field the first pass's spectrum showed
    within its margin) plus, inside the smoother's scaled sigma, the field it counted.

    Parameters
    ----------
    truth_mgal : ndarray, shape (n,)
        The true disturbance at the product's epochs (uniformly spaced), mGal.
    mask : ndarray of bool, shape (n,)
        Scored samples.
    dt_s : float
        Epoch spacing, s.
    identification : dict
        summary.json ``estimator.identification`` of the run.

    Returns
    -------
    float or None
        None when the run reports no spectral model (identification off, or nothing to fit).
    """
    model = identification.get("spectral_model")
    if not model or identification.get("height_dt_s") is None:
        return None
    k = math.sqrt(float(identification.get("noise_scale", 1.0)))
    m = SpectralModel(**model)
    m = dataclasses.replace(m, white_mps2=m.white_mps2 * k, height_sigma_m=m.height_sigma_m * k)
    x = np.asarray(truth_mgal, float)
    x = np.nan_to_num(x - np.nanmean(x))
    n = x.size
    gain = smoother_gain(np.fft.rfftfreq(2 * n, dt_s), m, float(identification["height_dt_s"]))
    miss = (np.fft.irfft(np.fft.rfft(x, 2 * n) * gain, 2 * n)[:n] - x)[mask]
    return float(np.sqrt(np.mean((miss - miss.mean()) ** 2))) if miss.size else None


#: draws of the error/sigma a right sigma would show (:func:`sigma_ratio_range`)
NULL_DRAWS = 400


def sigma_ratio_range(err, sigma, draws=NULL_DRAWS, seed=0, percentiles=(5.0, 95.0)):
    """The spread of :func:`sigma_ratio_rms` that a right sigma would show on this flight.

    One flight's error/sigma RMS is a statistic of a correlated series: a drift lasting a line
    leaves few independent samples, and a right sigma can then score well away from 1.  The
    draws are Gaussian series with the spectrum of the flight's own normalised error
    ``(err - mean) / sigma`` (its periodogram over the finite samples in order, zero-padded to
    twice their number; random amplitudes and phases), with the mean taken off as the flight's
    score takes it, scaled so that their mean square over all draws is 1: the sigma is right on
    average for the error about its mean.  Scale-free: only the shape of the error's spectrum
    matters.  The shape is the realised one, so the range is narrower than the truth's where the
    error's correlation time nears the record's length (measured on Gauss-Markov errors plus
    white noise, 3000 samples: a right sigma's score inside its 5-95 % range on 94 %, 84 % and
    72 % of realisations at correlation times of 30, 300 and 1000 samples; tests/test_unseen.py
    holds the first two).

    Parameters
    ----------
    err, sigma : array_like, shape (n,)
        Error and stated 1-sigma, any one unit.
    draws : int
    seed : int
        The draws' random stream (the range is reproducible).
    percentiles : (float, float)

    Returns
    -------
    (low, high) : tuple of float, or None when fewer than 16 finite samples
    """
    u = _normalised_error(err, sigma)
    n = u.size
    if n < 16:
        return None
    m = 2 * n
    amp = np.abs(np.fft.rfft(u - u.mean(), m))
    rng = np.random.default_rng(seed)
    ms = np.empty(draws)
    # in pieces of 50 draws: a full-length flight's 13000 scored samples stay near 50 MB
    for a in range(0, draws, 50):
        k = min(50, draws - a)
        y = np.fft.irfft(amp * (rng.standard_normal((k, amp.size)) + 1j * rng.standard_normal((k, amp.size))), m)
        y = y[:, :n] - y[:, :n].mean(axis=1, keepdims=True)
        ms[a : a + k] = np.mean(y**2, axis=1)
    z = np.sqrt(ms / ms.mean())
    lo, hi = np.percentile(z, percentiles)
    return float(lo), float(hi)


def gnss_heights_config(folder: Path, name: str = "survey.yaml") -> str:
    """Write ``gnss_heights_<name>`` beside ``name``: the same flight with the GNSS fixes'
    heights as the height channel (a log without an altimeter); returns its file name."""
    text = (folder / name).read_text()
    if "altimeter: /altimeter" not in text:
        raise SystemExit(f"{folder / name}: no 'altimeter: /altimeter' topic to replace")
    out = f"gnss_heights_{name}"
    (folder / out).write_text(text.replace("altimeter: /altimeter", "altimeter: /gnss"))
    return out


def model_config(folder: Path, model: dict, name: str = "survey.yaml") -> str:
    """Write ``model_<name>`` beside ``name``: the same survey with ``model`` as its ``model``
    section (datasheet figures a user would know, e.g. ``accel_bias_mps2``); its file name."""
    cfg = yaml.safe_load((folder / name).read_text())
    cfg["model"] = dict(model)
    out = f"model_{name}"
    (folder / out).write_text(
        "# survey.yaml with a model section (bench_unseen --model)\n"
        + yaml.safe_dump(cfg, sort_keys=False, default_flow_style=None)
    )
    return out


#: The gyro biases ``--gyro`` sets, per its BIAS (triad axes 1-3).
GYRO_BIAS_PATTERN = (1.0, -0.7, 0.8)


def with_accel_bias(spec: dict, bias_mps2) -> dict:
    """The drawn flight with its horizontal accelerometer biases replaced by ``bias_mps2`` (2,),
    m/s^2 (a tactical IMU's instead of the suite's draw; the name is unchanged, the cache
    folder's hash differs)."""
    out = json.loads(json.dumps(spec))
    out["sim"]["flights"][0]["sensors"]["accelerometer"]["bias_mps2"] = [float(b) for b in bias_mps2]
    return out


def with_gyro(spec: dict, bias_degph: float, white_degph: float) -> dict:
    """The drawn flight with another grade of gyros: constant biases ``bias_degph`` x (1, -0.7,
    0.8) on triad axes 1-3, deg/h, and a white drift of ``white_degph`` (deg/h, one-second
    sigma: an angle random walk of ``white_degph / 60`` deg/sqrt(h)); a tactical or fibre-optic
    IMU's instead of the suite's navigation-grade draw.  The name is unchanged, the cache
    folder's hash differs."""
    out = json.loads(json.dumps(spec))
    gyro = out["sim"]["flights"][0]["sensors"]["gyro"]
    gyro["bias_degph"] = [float(bias_degph) * k for k in GYRO_BIAS_PATTERN]
    gyro["white_drift_degph"] = float(white_degph)
    return out


def with_gravimeter_drift(spec: dict, mgal_per_h: float) -> dict:
    """The drawn flight with a linear gravimeter drift of ``mgal_per_h`` added (from its first
    sample; a spring meter's or a strapdown gravimeter's drift where no base ties take it off).
    The bound's noise leaves it out (not stationary); the ``drift`` column counts it.  The name
    is unchanged, the cache folder's hash differs."""
    out = json.loads(json.dumps(spec))
    out["sim"]["flights"][0]["sensors"]["gravimeter"]["drift_mgal_per_h"] = float(mgal_per_h)
    return out


def with_gravimeter_tare(spec: dict, at: float, mgal: float) -> dict:
    """The drawn flight with a tare: the gravimeter's reading steps by ``mgal`` at the fraction
    ``at`` of the flight (0-1; a spring meter after a shock, a strapdown gravimeter's bias jump).
    The bound's noise leaves it out (not stationary); the ``drift`` column counts it.  The name
    is unchanged, the cache folder's hash differs."""
    out = json.loads(json.dumps(spec))
    grv = out["sim"]["flights"][0]["sensors"]["gravimeter"]
    grv["tare_mgal"] = float(mgal)
    grv["tare_time_s"] = float(at) * float(spec["duration_s"])
    return out


def with_line_levels(spec: dict, dz_m: float) -> dict:
    """The drawn flight with its lines at two levels: line ``i`` at the drawn altitude plus
    ``(i % 2) * dz_m`` (a survey flown at several levels, or a loose drape: the field differs
    between neighbouring lines by its vertical change too).  The name is unchanged, the cache
    folder's hash differs."""
    out = json.loads(json.dumps(spec))
    plan = out["sim"]["flights"][0]["plan"]
    alt = float(plan["altitude_m"])
    plan["lines"]["altitudes_m"] = [alt, alt + float(dz_m)]
    return out


def with_tie_lines(spec: dict, count: int) -> dict:
    """The drawn flight with ``count`` tie lines flown after its lines, across all of them and
    evenly spread along their length (``count`` spacings of ``length / count``, centred): a
    survey's control lines, whose crossings the levelling uses.  The flight lasts longer by the
    ties and their turns; the name is unchanged, the cache folder's hash differs."""
    if count < 1:
        raise ValueError(f"with_tie_lines: count must be >= 1, got {count}")
    out = json.loads(json.dumps(spec))
    plan = out["sim"]["flights"][0]["plan"]
    plan["ties"] = {"count": int(count), "spacing_m": float(plan["lines"]["length_m"]) / int(count)}
    return out


def with_wind(spec: dict, speed_mps: float, from_deg: float, hold_speed: str = "air") -> dict:
    """The drawn flight in a steady wind of ``speed_mps`` from ``from_deg`` (clockwise from
    north).  The aircraft flies the drawn ground track with its nose along its velocity through
    the air, crabbed on every line the wind crosses; ``hold_speed`` ``air``: each line at the
    drawn speed through the air (upwind lines slower over the ground, downwind faster; turns at
    the drawn speed over the ground), ``ground``: every line at the drawn ground speed, so that
    only a strapdown triad's data change (docs/simulate.md, "Wind").  The name is unchanged,
    the cache folder's hash differs."""
    out = json.loads(json.dumps(spec))
    plan = out["sim"]["flights"][0]["plan"]
    plan["wind_speed_mps"] = float(speed_mps)
    plan["wind_from_deg"] = float(from_deg)
    plan["hold_speed"] = hold_speed
    return out


#: Parked time before take-off and after landing given to a draw without static periods, s.
AIRFIELD_PARKED_S = 300.0


def with_airfield(spec: dict, height_m: float, climb_mps: float | None = None) -> dict:
    """The drawn flight from and to an airfield at ellipsoidal height ``height_m``: parked there
    (the drawn static periods, or :data:`AIRFIELD_PARKED_S` where none was drawn), the take-off
    run, a steady climb right after it and a steady descent before the landing run at
    ``climb_mps`` (the plan's ``max_climb_rate_mps``, the simulator's 5 m/s by default;
    docs/simulate.md, "Static periods"), the lines as drawn.  The name is unchanged, the cache
    folder's hash differs."""
    out = json.loads(json.dumps(spec))
    plan = out["sim"]["flights"][0]["plan"]
    plan["ground_height_m"] = float(height_m)
    if climb_mps is not None:
        plan["max_climb_rate_mps"] = float(climb_mps)
    for key in ("static_start_s", "static_end_s"):
        if not plan.get(key):
            plan[key] = AIRFIELD_PARKED_S
    return out


def with_antenna(spec: dict, arm_flu_m) -> dict:
    """The drawn flight with its GNSS antenna at ``arm_flu_m`` (forward, left, up, m) from the
    IMU on the aircraft's axes: the fixes are the antenna's, turned with the aircraft's attitude
    (crab, bank, pitch, attitude turbulence; docs/simulate.md, ``gnss.antenna_m``); survey.yaml
    does not state it, so gravsurvey finds it from the track.  The name is unchanged, the cache
    folder's hash differs."""
    out = json.loads(json.dumps(spec))
    sensors = out["sim"]["flights"][0]["sensors"]
    sensors["gnss"] = {**sensors.get("gnss", {}), "antenna_m": [float(x) for x in arm_flu_m]}
    return out


def with_carrier_phase_gnss(spec: dict) -> dict:
    """The drawn flight with carrier-phase (PPK) GNSS and no altimeter of its own: the GNSS
    heights carry the drawn altimeter's white noise (``sigma_m``, at the GNSS rate), the
    horizontal positions half of it, and the altimeter is left exact and unused (its sigma 0, so
    :func:`gravsurvey.simulate.unseen.noise_psd`, the bound's noise, counts the GNSS heights
    alone).  The commonest airborne set-up: heights from post-processed carrier-phase GNSS, no
    radar or laser altimeter.  The name is unchanged, the cache folder's hash differs."""
    out = json.loads(json.dumps(spec))
    sensors = out["sim"]["flights"][0]["sensors"]
    sigma = float(sensors["altimeter"]["sigma_m"])
    sensors["gnss"] = {**sensors.get("gnss", {}), "horizontal_sigma_m": 0.5 * sigma, "vertical_sigma_m": sigma}
    sensors["altimeter"] = {**sensors["altimeter"], "sigma_m": 0.0}
    return out


def _numbers(text: str) -> list:
    """Comma-separated numbers of a command-line option; [] when one is not a number."""
    try:
        return [float(b) for b in text.split(",")]
    except ValueError:
        return []


def with_gnss_markov(spec: dict, sigma_m: float, tau_s: float) -> dict:
    """The drawn flight with a slowly varying GNSS error: a first-order Gauss-Markov process of
    ``sigma_m`` (m) in height and half of it east and north, correlation time ``tau_s`` (s), on
    top of the white noise (a real solution's ionosphere, troposphere, orbit and multipath
    errors; docs/benchmarks.md "A slowly varying GNSS height error")."""
    out = json.loads(json.dumps(spec))
    sensors = out["sim"]["flights"][0]["sensors"]
    sensors["gnss"] = {
        **sensors.get("gnss", {}),
        "vertical_markov_sigma_m": float(sigma_m),
        "horizontal_markov_sigma_m": 0.5 * float(sigma_m),
        "markov_tau_s": float(tau_s),
    }
    return out


def with_vertical_field_only(spec: dict) -> dict:
    """The drawn flight with its field's horizontal components set to zero at the sensors
    (``field.horizontal: false``; not a physical field: it shows what the deflections of the
    vertical do, docs/benchmarks.md "The field's horizontal components pose as gyro noise")."""
    out = json.loads(json.dumps(spec))
    out["sim"]["field"]["horizontal"] = False
    return out


def evaluate_flight(
    spec, folder: Path, runs=("default", "oracle", "classic"), heights: str = "altimeter", model=None
) -> dict:
    """Run default / oracle / classic on one prepared flight and score them against truth.

    ``heights="gnss"`` or ``"carrier-phase"``: the default run takes the GNSS heights as its
    height channel (:func:`gnss_heights_config`; with ``"gnss"`` the bound still assumes the
    altimeter; ``"carrier-phase"`` expects a spec of :func:`with_carrier_phase_gnss`).
    ``model`` (dict): a ``model`` section for the default run (:func:`model_config`).
    """
    truth = read_truth_csv(folder / "F01" / "truth.csv")
    truth["line"] = np.array(truth_lines(folder / "F01" / "truth.csv"), dtype=object)
    row = {"name": spec["name"], "seed": spec["seed"], "summary": spec_summary(spec)}
    prof = {}
    default_cfg = gnss_heights_config(folder) if heights in ("gnss", "carrier-phase") else "survey.yaml"
    suffix = "_gnss_heights" if heights in ("gnss", "carrier-phase") else ""
    if model:
        default_cfg = model_config(folder, model, default_cfg)
        suffix += "_model"
    for tag, cfg in (("default", default_cfg), ("oracle", "oracle.yaml"), ("classic", "classic.yaml")):
        if tag not in runs:
            continue
        t0 = time.perf_counter()
        res = run_survey(folder / cfg, output_dir=folder / f"out_{tag}{suffix}", force=True)
        row[f"{tag}_s"] = time.perf_counter() - t0
        if res.failed:
            row[f"{tag}_error"] = res.failed[0].splitlines()[0]
            continue
        prof[tag] = read_profiles(folder / f"out_{tag}{suffix}" / "profiles.csv")
        if tag == "default":
            res_default = res
        row[f"{tag}_resolution_km"] = median_resolution_km(res.summary)
    if not prof:
        return row
    # the truth, the scored samples and the bound from whichever run there is (an oracle- or
    # classic-only run is scored too); the default's own figures only from the default run
    p = prof.get("default") or next(iter(prof.values()))
    mask = scored_mask(p["time_unix_ns"], truth)
    tr = p["truth_mgal"]
    row["scored_samples"] = int(mask.sum())
    if "default" in prof:
        _default_scores(row, spec, p, mask, tr, res_default)
    for tag in ("oracle", "classic"):
        if tag in prof:
            q = prof[tag]
            m = scored_mask(q["time_unix_ns"], truth)
            row[f"{tag}_rms"], row[f"{tag}_coverage"] = rms_after_bias((q["disturbance_mgal"] - q["truth_mgal"])[m])
    f, s_s = truth_psd(tr, mask, float(np.median(np.diff(p["time_unix_ns"]))) / 1e9)
    if f is not None:
        row["truth_psd_check"] = float(s_s.sum() * f[1] / np.var(tr[mask] * MGAL))
        s_n = noise_psd(spec["sim"]["flights"][0], f)
        # the formula on the estimated spectrum (before 2026-12-02 the bound; kept for comparison)
        row["bound_formula_rms"], _ = wiener_bound(f, s_s, s_n, spec["speed_mps"])
        dt_s = float(np.median(np.diff(p["time_unix_ns"]))) / 1e9
        spectra = [(f, s_s), truth_psd_multitaper(tr, mask, dt_s)]
        row["bound_rms"], row["bound_resolution_km"], row["bound_level"] = oracle_wiener_bound(
            tr, mask, dt_s, lambda x: noise_psd(spec["sim"]["flights"][0], x), spec["speed_mps"], spectra
        )
    row["truth_std_mgal"] = float(np.nanstd(tr[mask]))
    return row


def _default_scores(row, spec, p, mask, tr, res_default) -> None:
    """The default run's figures into ``row``: RMS, the smoothed estimate's, the drawn drift,
    error/sigma and the missed field against the truth's."""
    row["default_rms"], row["default_coverage"] = rms_after_bias((p["disturbance_mgal"] - tr)[mask])
    row["kalman_rms"], _ = rms_after_bias((p["kalman_mgal"] - tr)[mask])
    # the drawn gravimeter drift (bias + Markov) at the product's epochs: the part of the error
    # a flight cannot tell from the field unless its lines do (docs/benchmarks.md, "Unseen flights")
    t_ns, slow = gravimeter_slow_error(spec["sim"])
    drift = np.interp(p["time_unix_ns"].astype(float), t_ns.astype(float), slow) / MGAL
    row["drift_rms"], _ = rms_after_bias(drift[mask])
    row["kalman_less_drift_rms"], _ = rms_after_bias((p["kalman_mgal"] - tr - drift)[mask])
    # honest uncertainty (issue 12 item 2): the final product's error over its stated sigma
    err, sig = (p["disturbance_mgal"] - tr)[mask], p["sigma_mgal"][mask]
    row["default_z"] = sigma_ratio_rms(err, sig)
    # what a right sigma would score on this flight's error (its 5-95 % range): a flight
    # outside it is miscalibrated, not unlucky
    row["default_z_range"] = sigma_ratio_range(err, sig)
    # where the stated sigma goes wrong: the missed field it states against the truth's, and the
    # error/sigma with the truth's in its place (docs/benchmarks.md, "The missed field against
    # the truth")
    ident = (next(iter(res_default.summary.get("flights", {}).values()), {}) or {}).get("estimator", {})
    ident = ident.get("identification") or {}
    true_miss = missed_field(tr, mask, float(np.median(np.diff(p["time_unix_ns"]))) / 1e9, ident)
    if true_miss is not None:
        stated = float(ident.get("field_sigma_missed_mps2", 0.0)) / MGAL
        row["missed_field_true_mgal"], row["missed_field_stated_mgal"] = true_miss, stated
        row["default_z_true_missed"] = sigma_ratio_rms(
            err, np.sqrt(np.clip(sig**2 - stated**2, 0.0, None) + true_miss**2)
        )


def run_flight(
    spec, cache=CACHE, runs=("default", "oracle", "classic"), heights: str = "altimeter", model=None
) -> dict:
    """:func:`prepare_flight` then :func:`evaluate_flight`; a flight the pipeline refuses gives a
    row with ``default_error`` (one bad flight must not hide the others' rows).  ``simulate_s``:
    the time spent simulating (0 when cached), s."""
    t0 = time.perf_counter()
    try:
        folder = prepare_flight(spec, cache)
        t_sim = time.perf_counter() - t0
        row = evaluate_flight(spec, folder, runs, heights, model)
    except GravsurveyError as exc:
        t_sim = time.perf_counter() - t0
        row = {
            "name": spec["name"],
            "seed": spec["seed"],
            "summary": spec_summary(spec),
            "default_error": f"{type(exc).__name__}: {exc}",
        }
    row["simulate_s"] = t_sim
    return row


def truth_lines(path):
    """The simulator's line label per row of a truth.csv (``line`` column), as a list of str."""
    with open(path, newline="") as fh:
        rows = list(csv.reader(line for line in fh if not line.startswith("#")))
    i = rows[0].index("line")
    return [r[i] for r in rows[1:]]


def fmt(v, nd=2):
    """``v`` with ``nd`` decimals, ``-`` for None or a non-finite float."""
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v:.{nd}f}"


def _range(lo_hi):
    return "" if not lo_hi else f" ({fmt(lo_hi[0])}-{fmt(lo_hi[1])})"


def print_table(rows):
    print(
        "| flight | drawn | default | kalman | oracle | classic | bound | default/bound | kalman/bound "
        "| res default / classic / bound (km) | truth std | error/sigma (a right sigma's 5-95 %) | drift "
        "| kalman less drift |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        b = r.get("bound_rms")
        ratio = (r["default_rms"] / b) if (b and r.get("default_rms") is not None) else None
        kr = (r["kalman_rms"] / b) if (b and r.get("kalman_rms") is not None) else None
        err = "; ".join(dict.fromkeys(r[k] for k in ("default_error", "oracle_error", "classic_error") if k in r))
        cov = r.get("default_coverage")
        cov = f" ({cov:.0%} covered)" if cov is not None and cov < 0.995 else ""
        print(
            f"| {r['name']} | {r['summary'].split(' ', 1)[1]} | {fmt(r.get('default_rms'))}{cov} | "
            f"{fmt(r.get('kalman_rms'))} | {fmt(r.get('oracle_rms'))} | {fmt(r.get('classic_rms'))} | "
            f"{fmt(b)} | {fmt(ratio)} | {fmt(kr)} | {fmt(r.get('default_resolution_km'), 1)} / "
            f"{fmt(r.get('classic_resolution_km'), 1)} / {fmt(r.get('bound_resolution_km'), 1)} | "
            f"{fmt(r.get('truth_std_mgal'))} | {fmt(r.get('default_z'))}{_range(r.get('default_z_range'))} | "
            f"{fmt(r.get('drift_rms'))} | "
            f"{fmt(r.get('kalman_less_drift_rms'))} |" + (f" {err}" if err else "")
        )
    print()
    for key in ("default", "kalman", "oracle", "classic", "kalman_less_drift"):
        ratios = [
            r[f"{key}_rms"] / r["bound_rms"] for r in rows if r.get(f"{key}_rms") is not None and r.get("bound_rms")
        ]
        if ratios:
            print(
                f"{key:8s} RMS / bound: median {np.median(ratios):.2f}, worst {np.max(ratios):.2f} "
                f"over {len(ratios)} flights"
            )
    formula = [
        r["default_rms"] / r["bound_formula_rms"] for r in rows if r.get("default_rms") and r.get("bound_formula_rms")
    ]
    if formula:
        # the bound as it was computed until 2026-12-02, for comparison with older tables
        print(
            f"default  RMS / formula bound (before 2026-12-02): median {np.median(formula):.2f}, "
            f"worst {np.max(formula):.2f}"
        )
    zs = [r["default_z"] for r in rows if r.get("default_z") is not None]
    if zs:
        inside = sum(0.7 <= z <= 1.5 for z in zs)
        print(
            f"default error/sigma RMS: median {np.median(zs):.2f}, range {min(zs):.2f}-{max(zs):.2f}, "
            f"{inside} of {len(zs)} flights in [0.7, 1.5]"
        )
    both = [r for r in rows if r.get("default_z") is not None and r.get("default_z_true_missed") is not None]
    if both:
        ratio = [math.log((r["missed_field_stated_mgal"] + 0.03) / (r["missed_field_true_mgal"] + 0.03)) for r in both]
        print(
            f"missed field stated / true (+0.03 mGal): median {math.exp(np.median(ratio)):.2f}, "
            f"RMS of the log {math.sqrt(np.mean(np.square(ratio))):.2f}; error/sigma in [0.7, 1.5] with the "
            f"true one in its place: {sum(0.7 <= r['default_z_true_missed'] <= 1.5 for r in both)} of {len(both)} "
            f"(stated: {sum(0.7 <= r['default_z'] <= 1.5 for r in both)})"
        )
    ranged = [r for r in rows if r.get("default_z") is not None and r.get("default_z_range")]
    if ranged:
        over = [r["name"] for r in ranged if r["default_z"] > r["default_z_range"][1]]
        under = [r["name"] for r in ranged if r["default_z"] < r["default_z_range"][0]]
        # outside its 5-95 % range the miss is the sigma's, not chance (a right sigma leaves
        # it on one flight in ten)
        print(
            f"error/sigma above a right sigma's 95 % point on {len(over)} of {len(ranged)} flights "
            f"({', '.join(over) or '-'}), below its 5 % point on {len(under)} ({', '.join(under) or '-'})"
        )
    worse = [
        r["name"]
        for r in rows
        if r.get("default_rms") is not None and r.get("classic_rms") is not None and r["default_rms"] > r["classic_rms"]
    ]
    # only flights where both ran (``--runs default`` has no classic row: "of 0", not "0 of 20")
    both = sum(1 for r in rows if r.get("default_rms") is not None and r.get("classic_rms") is not None)
    print(f"default worse than classic on {len(worse)} of {both} flights: {', '.join(worse) or '-'}")
    # issue 12: never worse than the scalar chain at the same or coarser resolution
    coarser = [
        r["name"]
        for r in rows
        if r["name"] in worse
        and r.get("default_resolution_km") is not None
        and r.get("classic_resolution_km") is not None
        and r["default_resolution_km"] >= r["classic_resolution_km"]
    ]
    print(f"... of which at the same or coarser stated resolution: {len(coarser)}: {', '.join(coarser) or '-'}")
    # issue 12 item 3: the final product against its own input, the smoothed estimate of the
    # same run (what the drift stage and the field filter did to it), beyond a 5 % tolerance
    pairs = [r for r in rows if r.get("default_rms") is not None and r.get("kalman_rms") is not None]
    own = [
        f"{r['name']} {r['kalman_rms']:.2f} -> {r['default_rms']:.2f}"
        for r in pairs
        if r["default_rms"] > 1.05 * r["kalman_rms"]
    ]
    gained = sum(1 for r in pairs if r["default_rms"] < 0.95 * r["kalman_rms"])
    print(
        f"default worse than its own smoothed estimate by over 5 % on {len(own)} of {len(pairs)} flights"
        f" ({', '.join(own) or '-'}); better by over 5 % on {gained}"
    )
    failed = [r["name"] for r in rows if any(k in r for k in ("default_error", "oracle_error", "classic_error"))]
    if failed:
        print(f"runs that failed: {', '.join(failed)}")


def seed_list(first_seed: int, flights: int, seeds: str | None = None) -> list[int]:
    """The seeds a run draws: ``first_seed .. first_seed + flights - 1``, or the comma-separated
    ``seeds`` (in their order) when given.  ValueError names what is not a seed."""
    if seeds is None:
        return list(range(first_seed, first_seed + flights))
    out = []
    for item in seeds.split(","):
        item = item.strip()
        if not (item.isascii() and item.isdigit()):
            raise ValueError(f"expected comma-separated non-negative integer seeds, got {item!r} in {seeds!r}")
        out.append(int(item))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--flights", type=int, default=20, help="number of flights (seeds first-seed ..)")
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument(
        "--seeds",
        default=None,
        metavar="S1,S2,...",
        help="these seeds, in this order, instead of --first-seed and --flights (a chosen set, e.g. "
        "docs/benchmarks.md 'High-latitude surveys')",
    )
    ap.add_argument(
        "--quick",
        action="store_true",
        help=f"cap each flight at {QUICK_MAX_DURATION_S / 60:.0f} min and {QUICK_MAX_IMU_HZ:g} Hz IMU",
    )
    ap.add_argument("--json", type=Path, default=None, help="also write the rows as JSON")
    ap.add_argument("--cache", type=Path, default=CACHE, help="where simulated flights are kept")
    ap.add_argument(
        "--runs",
        default="default,oracle,classic",
        help="comma-separated subset of default,oracle,classic to run (faster checks)",
    )
    ap.add_argument(
        "--heights",
        choices=("altimeter", "gnss", "carrier-phase"),
        default="altimeter",
        help="height channel of the default run: the simulated altimeter, or the GNSS fixes' heights "
        "(a log without an altimeter; docs/benchmarks.md 'GNSS heights as the height channel'); "
        "carrier-phase: the GNSS made carrier-phase grade (its heights with the drawn altimeter's "
        "noise) and the only height channel",
    )
    ap.add_argument(
        "--model",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a model key for the default run (repeatable; a datasheet figure a user knows, e.g. "
        "accel_bias_mps2=1e-3; the value is read as YAML)",
    )
    ap.add_argument(
        "--accel-bias",
        default=None,
        metavar="B1,B2",
        help="replace the drawn horizontal accelerometer biases by these, m/s^2 (a tactical IMU's; "
        "docs/benchmarks.md 'Accelerometer bias taken off between passes')",
    )
    ap.add_argument(
        "--gyro",
        default=None,
        metavar="BIAS_DEGPH,WHITE_DEGPH",
        help="replace the drawn gyros by another grade: biases BIAS x (1, -0.7, 0.8) deg/h on triad axes 1-3 "
        "and a white drift of WHITE deg/h (one-second sigma; docs/benchmarks.md 'A tactical-grade IMU')",
    )
    ap.add_argument(
        "--gravimeter-drift",
        type=float,
        default=None,
        metavar="MGAL_PER_H",
        help="add a linear gravimeter drift, mGal/h (docs/benchmarks.md 'A linear gravimeter drift')",
    )
    ap.add_argument(
        "--gravimeter-tare",
        default=None,
        metavar="AT,MGAL",
        help="add a tare: the gravimeter's reading steps by MGAL at the fraction AT (0-1) of the flight "
        "(docs/benchmarks.md 'A gravimeter tare')",
    )
    ap.add_argument(
        "--vertical-field-only",
        action="store_true",
        help="zero the field's horizontal components at the sensors (not a physical field; "
        "docs/benchmarks.md 'The field's horizontal components pose as gyro noise')",
    )
    ap.add_argument(
        "--gnss-markov",
        default=None,
        metavar="SIGMA_M,TAU_S",
        help="add a Gauss-Markov GNSS error: SIGMA_M in height (half east and north), correlation "
        "time TAU_S (docs/benchmarks.md 'A slowly varying GNSS height error')",
    )
    ap.add_argument(
        "--origin-lat",
        type=float,
        default=None,
        metavar="DEG",
        help="put every survey's origin at this latitude (|DEG| <= 85), the rest as drawn: polar and "
        "high-latitude surveys (docs/benchmarks.md 'High-latitude surveys')",
    )
    ap.add_argument(
        "--line-levels",
        type=float,
        default=None,
        metavar="DZ_M",
        help="fly every second line DZ_M higher (docs/benchmarks.md 'Lines at two levels')",
    )
    ap.add_argument(
        "--tie-lines",
        type=int,
        default=None,
        metavar="N",
        help="fly N tie lines across the lines after them (docs/benchmarks.md 'Tie lines')",
    )
    ap.add_argument(
        "--wind",
        default=None,
        metavar="SPEED,FROM_DEG[,ground]",
        help="fly every flight in a steady wind of SPEED m/s from FROM_DEG: the aircraft crabs, its lines at the "
        "drawn airspeed (',ground': at the drawn ground speed; docs/benchmarks.md 'Flights in a wind')",
    )
    ap.add_argument(
        "--airfield",
        default=None,
        metavar="HEIGHT_M[,CLIMB_MPS]",
        help="start and end every flight parked on the ground at this ellipsoidal height: take-off, a steady "
        "climb (at CLIMB_MPS, default 5 m/s), descent and landing (docs/benchmarks.md 'From the ground and back')",
    )
    ap.add_argument(
        "--antenna",
        default=None,
        metavar="FWD,LEFT,UP",
        help="put every flight's GNSS antenna this far from the IMU on the aircraft's axes, m (not told to "
        "gravsurvey; docs/benchmarks.md 'A GNSS antenna off the IMU')",
    )
    a = ap.parse_args(argv)
    if a.flights < 1:
        ap.error("--flights must be >= 1")
    try:
        seeds = seed_list(a.first_seed, a.flights, a.seeds)
    except ValueError as exc:
        ap.error(f"--seeds: {exc}")
    model = {}
    for item in a.model:
        key, sep, value = item.partition("=")
        if not sep or not key:
            ap.error(f"--model: expected KEY=VALUE, got {item!r}")
        model[key.strip()] = yaml.safe_load(value)
    accel_bias = None
    if a.accel_bias is not None:
        accel_bias = _numbers(a.accel_bias)
        if len(accel_bias) != 2:
            ap.error(f"--accel-bias: expected two numbers B1,B2 (m/s^2), got {a.accel_bias!r}")
    gyro = None
    if a.gyro is not None:
        gyro = _numbers(a.gyro)
        if len(gyro) != 2 or not 0.0 <= gyro[0] <= 100.0 or not 0.0 <= gyro[1] <= 1000.0:
            ap.error(f"--gyro: expected BIAS_DEGPH,WHITE_DEGPH (0-100 deg/h, 0-1000 deg/h), got {a.gyro!r}")
    gnss_markov = None
    if a.gnss_markov is not None:
        gnss_markov = _numbers(a.gnss_markov)
        if len(gnss_markov) != 2 or gnss_markov[0] < 0 or gnss_markov[1] <= 0:
            ap.error(f"--gnss-markov: expected SIGMA_M,TAU_S (m, s > 0), got {a.gnss_markov!r}")
    tare = None
    if a.gravimeter_tare is not None:
        tare = _numbers(a.gravimeter_tare)
        if len(tare) != 2 or not 0.0 <= tare[0] <= 1.0:
            ap.error(
                f"--gravimeter-tare: expected AT,MGAL (AT a fraction 0-1 of the flight), got {a.gravimeter_tare!r}"
            )
    wind = None
    if a.wind is not None:
        parts = a.wind.split(",")
        hold = parts.pop() if len(parts) == 3 and parts[2] == "ground" else "air"
        wind = _numbers(",".join(parts))
        # the slowest draw's limit holds for all
        most = MAX_WIND_FRACTION * RANGES["speed_mps"][0]
        if len(wind) != 2 or not 0.0 <= wind[0] <= most or not -360.0 <= wind[1] <= 360.0:
            ap.error(
                f"--wind: expected SPEED,FROM_DEG[,ground] (0 <= SPEED <= {most:g} m/s, |FROM_DEG| <= 360), "
                f"got {a.wind!r}"
            )
        wind.append(hold)
    airfield = None
    if a.airfield is not None:
        airfield = _numbers(a.airfield)
        if len(airfield) not in (1, 2) or not -400.0 <= airfield[0] <= 15000.0 or min(airfield[1:] or [1.0]) <= 0:
            ap.error(f"--airfield: expected HEIGHT_M[,CLIMB_MPS] (-400 to 15000 m, m/s > 0), got {a.airfield!r}")
    antenna = None
    if a.antenna is not None:
        antenna = _numbers(a.antenna)
        if len(antenna) != 3 or max(abs(x) for x in antenna) > MAX_ANTENNA_M:
            ap.error(f"--antenna: expected FWD,LEFT,UP (m, each within +-{MAX_ANTENNA_M:g}), got {a.antenna!r}")
    if a.tie_lines is not None and not 1 <= a.tie_lines <= 50:
        ap.error(f"--tie-lines: expected 1-50 tie lines, got {a.tie_lines}")
    rows = []
    for seed in seeds:
        try:
            spec = draw_flight_spec(seed, origin_lat_deg=a.origin_lat)
        except ValueError as exc:
            # the latitude out of the generator's range: a usage error on the first draw, before
            # any flight is simulated (the generator holds the bound)
            ap.error(f"--origin-lat: {exc}")
        if a.quick:
            spec = limit_spec(spec, QUICK_MAX_DURATION_S, QUICK_MAX_IMU_HZ)
        if accel_bias is not None:
            spec = with_accel_bias(spec, accel_bias)
        if gyro is not None:
            spec = with_gyro(spec, *gyro)
        if a.heights == "carrier-phase":
            spec = with_carrier_phase_gnss(spec)
        if a.gravimeter_drift is not None:
            spec = with_gravimeter_drift(spec, a.gravimeter_drift)
        if tare is not None:
            spec = with_gravimeter_tare(spec, *tare)
        if gnss_markov is not None:
            spec = with_gnss_markov(spec, *gnss_markov)
        if a.vertical_field_only:
            spec = with_vertical_field_only(spec)
        if a.line_levels is not None:
            spec = with_line_levels(spec, a.line_levels)
        if a.tie_lines is not None:
            spec = with_tie_lines(spec, a.tie_lines)
        if wind is not None:
            spec = with_wind(spec, *wind)
        if airfield is not None:
            spec = with_airfield(spec, *airfield)
        if antenna is not None:
            spec = with_antenna(spec, antenna)
        row = run_flight(spec, a.cache, tuple(a.runs.split(",")), a.heights, model)
        rows.append(row)
        print(
            f"{row['summary']}: default {fmt(row.get('default_rms'))} kalman {fmt(row.get('kalman_rms'))} "
            f"oracle {fmt(row.get('oracle_rms'))} classic {fmt(row.get('classic_rms'))} "
            f"bound {fmt(row.get('bound_rms'))} mGal (sim {row['simulate_s']:.0f} s, run "
            f"{row.get('default_s', 0):.0f}/{row.get('oracle_s', 0):.0f}/{row.get('classic_s', 0):.0f} s, "
            f"error/sigma {fmt(row.get('default_z'))})",
            file=sys.stderr,
            flush=True,
        )
    print_table(rows)
    if a.json:
        a.json.write_text(json.dumps(rows, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
