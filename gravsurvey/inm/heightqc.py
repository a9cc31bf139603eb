"""Faults of the height channel, found against the inertial height: spikes, frozen values,
steps, latency.

A GNSS height jumps when the receiver loses and re-fixes its ambiguities, a barometric or
radar-derived height has single-sample outliers. The Kalman filter takes either as a real
vertical motion: a 0.3-m step in the middle of a 40-min flight put 4.4 mGal of error into the
estimate (quick U214 of the unseen suite, 0.44 mGal without), with nothing to show for it.

The aircraft's true height cancels in the residual ``e = h_ins - h_alt`` between the
mechanized and the measured height (:func:`gravsurvey.inm.identify.vertical_residual`): what
is left is the inertial height error, smooth over seconds, plus the measurement's noise. A
spike stands alone off both neighbours (:func:`gravsurvey.io.checks.single_sample_outliers`);
a step is a jump between quadratic fits of ``e`` over the 20 s before and after a point (on
0.5-s means), never across a gap. Both are judged against the flight's own robust scale of the
same statistic, so the threshold follows the channel's noise whatever its rate. A run of
identical values (a stalled sensor) is dropped, except in a record that repeats by nature. A
spike is dropped, a step taken off the heights after it (the height's absolute level changes
normal gravity by 0.3 mGal/m, a constant the levelling owns). Stamps late against the IMU show
as a residual that follows the vertical velocity (:func:`estimate_latency`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..io.checks import robust_sigma, single_sample_outliers
from .identify import edge_samples, running_mean, vertical_residual

__all__ = [
    "HeightFaults",
    "find_height_faults",
    "frozen_samples",
    "repair_heights",
    "estimate_latency",
    "estimate_latency_drift",
    "coarse_height_offset",
    "gnss_height_fraction",
    "noisy_stretches",
]

#: A height sample is one of the GNSS's own when a GNSS sample lies within this time of it ...
SAME_SAMPLE_S = 1e-3
#: ... with a height within this, m (a GNSS height exported to a CSV with 2-3 decimals; two
#: independent sensors, metres apart on the aircraft and centimetres noisy each, do not agree
#: to this on most samples).
SAME_HEIGHT_M = 5e-3
#: The height channel is the GNSS's heights when at least this fraction of its samples are.
SAME_FRACTION = 0.9

#: A spike: a sample off the mean of its neighbours by more than this many robust sigmas, its
#: neighbours off theirs the other way (:func:`gravsurvey.io.checks.single_sample_outliers`).
SPIKE_K = 8.0
#: A short block: a run of samples entered and left by opposite jumps of the residual
#: (:func:`short_blocks`), lasting at most this, s (a radar altimeter's no-lock zeros, a
#: logger's burst of a wrong value): dropped like a spike.
#: Kept, its two edges were read as two steps of the wrong sizes (three zero readings of a 1-Hz
#: altimeter at 1000 m: "steps" of -184 and +869 m, 142 mGal of error).
BLOCK_MAX_S = 10.0
#: Means of the residual over this span before the step search, s (at most the sample spacing
#: coarser: a 1 Hz channel is searched sample by sample).
STEP_BIN_S = 0.5
#: Span of each side's quadratic fit, s.
STEP_WINDOW_S = 20.0
#: A step: the jump between the two fits beyond this many robust sigmas of the same statistic
#: over the flight.
STEP_K = 8.0
#: A step's way back: a GNSS height that loses its ambiguities jumps and, re-fixed, jumps back
#: (a block). Once a step is found, the opposite jump within this span, s, ...
PAIR_MAX_S = 600.0
#: ... beyond this many robust sigmas ...
PAIR_K = 5.0
#: ... and of a size within this ratio of the first's is the block's other end. Left, the first
#: step taken off alone turned a 1-m, 120-s block (its ends at 8.4 and 6.5 sigmas) into a
#: permanent 1.15-m offset with a step back into it: 15.7 mGal against 2.2 intact, exit 0.
PAIR_SIZE_RATIO = (0.5, 2.0)
#: Fewest bins on each side for a fit.
STEP_MIN_BINS = 6
#: A step keeps its size when the two fits are shortened to half :data:`STEP_WINDOW_S`: at
#: least this fraction of it, same sign. A change of the inertial height error's curvature
#: (a poorly aligned mechanization entering a turn: 1.5 deg of tilt against the turn's 3 m/s^2)
#: leaves a jump between 20-s quadratics that falls with the window's square; a step does not.
#: Measured: two false steps at a turn's ends, 0.82 and -0.69 m at 20 s, 0.25 and -0.06 at 10 s
#: (quick U010 split by a 15-s IMU gap: 65 mGal in the turn, 9.7 mGal RMS against 1.5 intact);
#: a 0.3-m step 0.28 m at 40, 20, 10 and 5 s.
STEP_SHORT_RATIO = 0.5
#: Window of the running mean taken off the residual and the vertical velocity before the
#: latency regression (the inertial height error is slow, the turbulence is not), s.
LATENCY_HIGHPASS_S = 20.0
#: A latency is taken off the height stamps when it is this many standard errors from zero ...
LATENCY_K = 8.0
#: ... and at least this long, s: below 40 ms the error ``v_z L`` is under any height noise (2 cm
#: at 0.5 m/s). The simulated flights, stamped exactly, read up to 23 ms at 42 "standard errors"
#: until the record's ends were left out of the regression (``edge_samples``; since, 60 quick
#: flights read at most 13 ms at 3.0 standard errors).
LATENCY_MIN_S = 0.04
#: A drifting latency (a clock running slow or fast) is taken off when its rate is
#: LATENCY_K standard errors from zero and it changes the latency by at least this much between
#: the record's middle and its ends, s: on the 94 simulated flights, stamped exactly, the drift
#: regression read up to 0.105 s (80 ppm over 43 min, at 6 to 93 "standard errors") while the
#: record's ends were in it (quick U1434: 0.19 s, taken off exact stamps); without them 60 quick
#: flights read at most 0.016 s at 3.1 standard errors. 200 ppm over a 40-min flight is 0.24 s.
LATENCY_DRIFT_MIN_S = 0.15
#: The coarse search for a height clock offset (:func:`coarse_height_offset`): shifts up to this
#: far either way, s (the IMU-GNSS clock check's reach) ...
COARSE_MAX_S = 30.0
#: ... in steps of this, s, then refined to :data:`COARSE_FINE_STEP_S` ...
COARSE_STEP_S = 0.5
COARSE_FINE_STEP_S = 0.05
#: ... on at most this many height samples (evenly thinned: a variance needs no more) ...
COARSE_MAX_SAMPLES = 2000
#: ... an offset is believed when it is at least this long (shorter ones are the regression's,
#: :func:`estimate_latency`) and divides the high-passed residual's variance by at least this.
COARSE_MIN_S = 0.5
COARSE_MIN_RATIO = 2.0
#: Longest latency believed, s (beyond it the clocks are out of step, not a processing delay).
LATENCY_MAX_S = 2.0
#: A step is looked for only where the samples either side are at most this far apart, s (or
#: 3 samples): across a longer gap the fits would extrapolate, and a 30-s gap read as a 1.6-m
#: step put 43 mGal into quick U214; there the heights are left to the filter, as before.
STEP_MAX_GAP_S = 2.0
#: A frozen height: at least this many consecutive samples with the very same value ...
FREEZE_MIN_SAMPLES = 5
#: ... lasting at least this long, s ...
FREEZE_MIN_S = 1.0
#: ... in a record whose other samples repeat their predecessor this rarely (a quantised height
#: repeats by nature: there nothing is taken for frozen) ...
FREEZE_MAX_REPEAT_FRACTION = 0.01
#: ... and at most this share of the record frozen (a noiseless simulated height at a constant
#: altitude repeats throughout: that is the signal).
FREEZE_MAX_FRACTION = 0.05


@dataclass
class HeightFaults:
    """Spikes, frozen stretches and steps of a height record.

    Attributes
    ----------
    spikes : ndarray of int
        Indices of the samples to drop (spikes and frozen samples).
    frozen : int
        How many of them repeat a frozen value.
    steps : list of (int, float)
        Index of the first sample after each step and its size (measured height after minus
        before, m), in time order.
    """

    spikes: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    steps: list = field(default_factory=list)
    frozen: int = 0

    def __bool__(self) -> bool:
        return bool(self.spikes.size or self.steps)


def frozen_samples(time, height) -> np.ndarray:
    """Samples of a height that holds its value: the repeats after the first of a run of at least
    :data:`FREEZE_MIN_SAMPLES` equal values over :data:`FREEZE_MIN_S` (a stalled sensor or
    logger); none in a record that repeats values by nature (quantised, or noiseless: more than
    :data:`FREEZE_MAX_FRACTION` of it in such runs).

    Returns
    -------
    ndarray of int
    """
    t = np.asarray(time, float)
    h = np.asarray(height, float)
    if h.size < FREEZE_MIN_SAMPLES + 1:
        return np.zeros(0, np.int64)
    same = h[1:] == h[:-1]
    edge = np.diff(np.concatenate([[0], same.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(edge == 1), np.flatnonzero(edge == -1)
    # runs of repeats: same[a:b] True means samples a+1..b repeat sample a
    runs = [(a, b) for a, b in zip(starts, stops) if b - a + 1 >= FREEZE_MIN_SAMPLES and t[b] - t[a] >= FREEZE_MIN_S]
    in_runs = sum(b - a for a, b in runs)
    if (int(same.sum()) - in_runs) > FREEZE_MAX_REPEAT_FRACTION * h.size or in_runs > FREEZE_MAX_FRACTION * h.size:
        return np.zeros(0, np.int64)
    if not runs:
        return np.zeros(0, np.int64)
    return np.concatenate([np.arange(a + 1, b + 1) for a, b in runs]).astype(np.int64)


def _bins(t, e, dt):
    """Means of ``e`` over bins of :data:`STEP_BIN_S` (at least ``dt``): times, means, and the
    index of each bin's first sample."""
    width = max(STEP_BIN_S, dt)
    k = np.floor((t - t[0]) / width).astype(np.int64)
    first = np.flatnonzero(np.concatenate([[True], k[1:] != k[:-1]]))
    counts = np.diff(np.concatenate([first, [t.size]]))
    return np.add.reduceat(t, first) / counts, np.add.reduceat(e, first) / counts, first


def short_blocks(t, e, dt) -> np.ndarray:
    """Samples of short blocks of the residual (:data:`BLOCK_MAX_S`): entered by a jump and left
    by a jump the other way that undoes at least half of it, within :data:`BLOCK_MAX_S`, each
    jump off the residual's median step by more than :data:`SPIKE_K` robust sigmas of the steps
    (the steps' median is the inertial height error's slope, their spread the noise).

    Parameters
    ----------
    t, e : ndarray (k,)
        Times (s, increasing) and the residual (m).
    dt : float
        Median sample spacing, s (unused: the blocks are found sample by sample).

    Returns
    -------
    ndarray of int
        Indices into ``t``.
    """
    if t.size < 16:
        return np.zeros(0, np.int64)
    dd = np.diff(e)
    sig = robust_sigma(dd)
    if not sig > 0.0:
        return np.zeros(0, np.int64)
    z = (dd - float(np.median(dd))) / sig
    big = np.flatnonzero(np.abs(z) > SPIKE_K)
    out = []
    a = 0
    while a + 1 < big.size:
        i, j = int(big[a]), int(big[a + 1])
        # samples i+1..j lie between the jumps
        if t[j] - t[i + 1] <= BLOCK_MAX_S and z[i] * z[j] < 0 and abs(z[i] + z[j]) < 0.5 * max(abs(z[i]), abs(z[j])):
            out.append(np.arange(i + 1, j + 1))
            a += 2
        else:
            a += 1
    return np.concatenate(out).astype(np.int64) if out else np.zeros(0, np.int64)


def _side_fit(tb, eb, lo, hi, at):
    """Quadratic least-squares fits of ``eb`` over the bins ``[lo_j, hi_j)``, each evaluated at
    ``at_j``; NaN where a side has too few bins. Shapes (M,)."""
    m = at.size
    width = int(np.max(hi - lo)) if m else 0
    out = np.full(m, np.nan)
    if width < STEP_MIN_BINS:
        return out
    idx = lo[:, None] + np.arange(width)[None, :]
    ok = idx < hi[:, None]
    idx = np.minimum(idx, tb.size - 1)
    x = np.where(ok, tb[idx] - at[:, None], 0.0) / STEP_WINDOW_S
    y = np.where(ok, eb[idx], 0.0)
    w = ok.astype(float)
    # normal equations of y ~ c0 + c1 x + c2 x^2 per row; the value at ``at`` is c0
    s = [np.sum(w * x**p, axis=1) for p in range(5)]
    b = [np.sum(w * y * x**p, axis=1) for p in range(3)]
    a = np.stack(
        [np.stack([s[0], s[1], s[2]], -1), np.stack([s[1], s[2], s[3]], -1), np.stack([s[2], s[3], s[4]], -1)], -2
    )
    enough = (hi - lo) >= STEP_MIN_BINS
    det = np.linalg.det(a)
    good = enough & (np.abs(det) > 1e-12 * np.maximum(s[0], 1.0) ** 3)
    if good.any():
        out[good] = np.linalg.solve(a[good], np.stack(b, -1)[good][..., None])[:, 0, 0]
    return out


def _quadratic_rss(t, e) -> float:
    x = (t - t.mean()) / STEP_WINDOW_S
    r = e - np.polyval(np.polyfit(x, e, 2), x)
    return float(r @ r)


def _window_jump(t, e, where: int, window_s: float) -> float:
    """Jump between quadratic fits of ``e`` over ``window_s`` before and after sample
    ``where`` (the step starting there), NaN where a side has too few samples."""
    mid = np.array([0.5 * (t[where - 1] + t[where])])
    lo = np.searchsorted(t, mid - window_s, side="left")
    hi = np.searchsorted(t, mid + window_s, side="right")
    here = np.array([where])
    return float((_side_fit(t, e, here, hi, mid) - _side_fit(t, e, lo, here, mid))[0])


def _keeps_its_size(t, e, where: int) -> bool:
    """Whether the jump at sample ``where`` is a step (:data:`STEP_SHORT_RATIO`): its size over
    half-length fits at least that fraction of the full ones', same sign; kept where the half
    fits have too few samples to tell."""
    full = _window_jump(t, e, where, STEP_WINDOW_S)
    half = _window_jump(t, e, where, 0.5 * STEP_WINDOW_S)
    if not (math.isfinite(full) and math.isfinite(half)) or full == 0.0:
        return True
    return half / full >= STEP_SHORT_RATIO


def _find_steps(t, e, dt) -> list:
    tb, eb, first = _bins(t, e, dt)
    nb = tb.size
    if nb < 2 * STEP_MIN_BINS + 1:
        return []
    # a candidate between bins j-1 and j: fits over the bins within STEP_WINDOW_S on each side
    j = np.arange(1, nb)
    at = 0.5 * (tb[j - 1] + tb[j])
    lo_before = np.searchsorted(tb, at - STEP_WINDOW_S, side="left")
    hi_after = np.searchsorted(tb, at + STEP_WINDOW_S, side="right")
    jump = _side_fit(tb, eb, j, hi_after, at) - _side_fit(tb, eb, lo_before, j, at)
    # not across a gap: the last sample of bin j-1 and the first of bin j too far apart
    last_before = t[first[j] - 1]
    first_after = t[first[j]]
    jump[(first_after - last_before) > max(STEP_MAX_GAP_S, 3.0 * dt)] = np.nan
    s = robust_sigma(jump)
    if not s > 0.0:
        return []
    z = np.abs(np.nan_to_num(jump)) / s
    steps = []
    order = np.argsort(-z)
    taken = np.zeros(nb - 1, bool)
    for c in order:
        if z[c] <= STEP_K:
            break
        if taken[c]:
            continue
        # one step per window: its neighbours see the same jump
        near = np.abs(at - at[c]) < STEP_WINDOW_S
        taken |= near
        if not _keeps_its_size(t, e, int(first[c + 1])):
            continue
        steps.append((c, float(jump[c])))
    for c, size in list(steps):
        # the block's other end: the strongest opposite jump of a like size near it, unless
        # one is found already
        near = np.abs(at - at[c]) <= PAIR_MAX_S
        lo_r, hi_r = PAIR_SIZE_RATIO
        if any(near[k] and jump[k] * size < 0 for k, _ in steps):
            continue
        cand = near & ~taken & (z > PAIR_K) & (jump * size < 0)
        cand &= (np.abs(jump) >= lo_r * abs(size)) & (np.abs(jump) <= hi_r * abs(size))
        # the strongest that is a step (a turn's bend is not: :func:`_keeps_its_size`)
        for k in sorted(np.flatnonzero(cand), key=lambda i: -z[i]):
            if _keeps_its_size(t, e, int(first[k + 1])):
                taken |= np.abs(at - at[k]) < STEP_WINDOW_S
                steps.append((int(k), float(jump[k])))
                break
    out = []
    for c, size in sorted(steps):
        # the sample the step starts at, within the bins either side of the boundary: the split
        # of least squares (a quadratic each side over the same span)
        a0 = int(first[c])
        a1 = int(first[c + 2]) if c + 2 < nb else t.size
        lo = int(np.searchsorted(t, t[a0] - STEP_WINDOW_S))
        hi = int(np.searchsorted(t, t[min(a1, t.size - 1)] + STEP_WINDOW_S, side="right"))
        best, where = math.inf, int(first[c + 1])
        for k in range(max(a0, lo + 3), min(a1, hi - 3) + 1):
            rss = _quadratic_rss(t[lo:k], e[lo:k]) + _quadratic_rss(t[k:hi], e[k:hi])
            if rss < best:
                best, where = rss, k
        # its size from the samples themselves (a bin that holds the step mixes both levels)
        fine = _window_jump(t, e, where, STEP_WINDOW_S)
        if math.isfinite(fine):
            size = fine
        # the measured height jumps by minus the residual's jump (e = h_ins - h_alt)
        out.append((where, -size))
    return out


def find_height_faults(time, residual_m, height_m=None) -> HeightFaults:
    """Spikes, frozen stretches and steps of the height channel from its residual against the
    inertial height.

    Parameters
    ----------
    time : ndarray (k,)
        Sample times, s, increasing.
    residual_m : ndarray (k,)
        Mechanized minus measured height at those times, m
        (:func:`gravsurvey.inm.identify.vertical_residual`).
    height_m : ndarray (k,), optional
        The measured heights themselves (for :func:`frozen_samples`).

    Returns
    -------
    HeightFaults
        Indices into ``time``.
    """
    t = np.asarray(time, float)
    e = np.asarray(residual_m, float)
    if t.size < 16:
        return HeightFaults()
    frozen = frozen_samples(t, height_m) if height_m is not None else np.zeros(0, np.int64)
    keep = np.ones(t.size, bool)
    keep[frozen] = False
    live = np.flatnonzero(keep)
    spikes = live[single_sample_outliers(e[live], SPIKE_K)]
    keep[spikes] = False
    dt = float(np.median(np.diff(t)))
    live = np.flatnonzero(keep)
    blocks = live[short_blocks(t[live], e[live], dt)]
    spikes = np.union1d(spikes, blocks)
    keep[blocks] = False
    idx = np.flatnonzero(keep)
    steps = [(int(idx[k]), size) for k, size in _find_steps(t[idx], e[idx], dt)]
    dropped = np.union1d(frozen, spikes).astype(np.int64)
    return HeightFaults(spikes=dropped, steps=steps, frozen=int(frozen.size))


def repair_heights(height, faults: HeightFaults) -> np.ndarray:
    """The heights with the spikes set to NaN and each step taken off every sample after it, m.

    Parameters
    ----------
    height : ndarray (k,)
        Measured heights, m (the samples :func:`find_height_faults` indexed).
    faults : HeightFaults
    """
    h = np.array(height, float)
    for start, size in faults.steps:
        h[start:] -= size
    h[faults.spikes] = math.nan
    return h


def estimate_latency(time, residual_m, vertical_velocity_mps, highpass_s=LATENCY_HIGHPASS_S, outlier_k=None):
    """How late the height stamps are against the inertial time base, s, and its standard error.

    A height stamped ``L`` after it was measured gives ``e(t) = h_ins(t) - h(t - L) ~ dh_ins +
    L v_z(t)``: the residual follows the vertical velocity. ``L`` is the least-squares slope of
    the residual on ``v_z``, both less their running mean over ``highpass_s`` (the inertial
    height error is slow; the turbulence's vertical motion is not), its standard error from the
    scatter about the fit. Several axes (columns) are pooled into one slope: the GNSS
    positions' latency (:func:`gravsurvey.inm.gnssqc.estimate_gnss_latency`) is the same
    regression on the horizontal residual and velocity.

    Parameters
    ----------
    time : ndarray (k,)
        Height sample times, s.
    residual_m : ndarray (k,) or (k, m)
        Mechanized minus measured height (or position on ``m`` axes), m.
    vertical_velocity_mps : ndarray, shaped as ``residual_m``
        The mechanization's vertical velocity (velocity on the same axes) at those times, m/s.
    highpass_s : float
        Window of the running mean taken off both, s.
    outlier_k : float, optional
        Residuals of the fit beyond this many robust sigmas are bridged (interpolated from
        their neighbours before the high-pass, whose running mean would spread them over a
        window) and left out of a second fit. None: one fit (the heights' spikes are dropped
        before, by :func:`find_height_faults`; a refit there moved 0.100 s to 0.106 s on quick
        U214, the heavy tails of a turbulent residual being where ``v_z`` is largest).

    Returns
    -------
    latency_s, sigma_s : float
        NaN when there is nothing to regress on.
    """
    fit = _latency_regressors(time, residual_m, vertical_velocity_mps, highpass_s, outlier_k)
    if fit is None:
        return math.nan, math.nan
    x, y, use, _ = fit
    slope, res, sxx = _slope(x, y, use)
    # the high-pass correlates neighbouring residuals little at these windows; the robust
    # scale keeps a spike or two from inflating the error
    return slope, robust_sigma(res[use]) / math.sqrt(sxx)


def estimate_latency_drift(time, residual_m, velocity_mps, highpass_s=LATENCY_HIGHPASS_S, outlier_k=None):
    """A latency that changes linearly over the record (a clock running fast or slow): the
    latency at the record's middle and its change per second, with their standard errors.

    The regression of :func:`estimate_latency` with a second regressor, the high-passed velocity
    times the time from the middle: ``e ~ (L0 + L1 (t - t_mid)) v``.

    Returns
    -------
    latency_s, sigma_s : float
        At the middle of the record, s.
    rate, rate_sigma : float
        Change of the latency per second of record (s/s; x 1e6 for ppm).
        All NaN when there is nothing to regress on.
    """
    nan = (math.nan,) * 4
    fit = _latency_regressors(time, residual_m, velocity_mps, highpass_s, outlier_k)
    if fit is None:
        return nan
    x, y, use, t = fit
    tm = 0.5 * (t[0] + t[-1])
    a = np.stack([x[use], (x * (t - tm)[:, None])[use]], axis=1)
    ata = a.T @ a
    try:
        cov = np.linalg.inv(ata)
    except np.linalg.LinAlgError:
        return nan
    if not np.all(np.isfinite(cov)) or np.any(np.diag(cov) <= 0):
        return nan
    beta = cov @ (a.T @ y[use])
    scale = robust_sigma(y[use] - a @ beta)
    sig = scale * np.sqrt(np.diag(cov))
    return float(beta[0]), float(sig[0]), float(beta[1]), float(sig[1])


def _latency_regressors(time, residual_m, velocity_mps, highpass_s, outlier_k):
    """The high-passed velocity ``x`` and residual ``y`` (k, m), the samples to use (k, m) and the
    times (k,) of the latency regressions; None when there is nothing to regress on."""
    t = np.asarray(time, float)
    e = np.asarray(residual_m, float)
    v = np.asarray(velocity_mps, float)
    if t.size < 32:
        return None
    dt = float(np.median(np.diff(t)))
    w = max(3, int(round(highpass_s / max(dt, 1e-9))))
    if e.ndim == 1:
        e, v = e[:, None], v[:, None]
    x = v - running_mean(v, w)
    # the running mean is one-sided at the ends and mixes both sides across a gap: the samples
    # within half a window of either are left out
    use = np.ones(e.shape, bool)
    use[edge_samples(t, highpass_s, max(STEP_MAX_GAP_S, 3.0 * dt))] = False
    y = e - running_mean(e, w)
    slope, res, _ = _slope(x, y, use)
    if not math.isfinite(slope):
        return None
    bad = use & (np.abs(res) > outlier_k * robust_sigma(res[use])) if outlier_k is not None else None
    if bad is not None and bad.any():
        e = e.copy()
        for j in range(e.shape[1]):
            good = ~bad[:, j]
            if good.sum() < 2:
                return None
            e[~good, j] = np.interp(t[~good], t[good], e[good, j])
        y = e - running_mean(e, w)
        use = use & ~bad
        if not math.isfinite(_slope(x, y, use)[0]):
            return None
    return x, y, use, t


def _slope(x, y, use):
    """Least-squares slope of ``y`` on ``x`` over the samples ``use`` (pooled), the residuals
    ``y - slope x`` at every sample and ``sum x^2``; NaN slope when ``x`` is nil there."""
    xs, ys = x[use], y[use]
    sxx = float(xs @ xs)
    if not sxx > 0.0:
        return math.nan, None, 0.0
    slope = float(xs @ ys) / sxx
    return slope, y - slope * x, sxx


def coarse_height_offset(nav, alt_time, alt_height, ellipsoid):
    """A height clock seconds out of step with the IMU: the shift of the height stamps that best
    explains the heights by the mechanized height, s, and how much it explains.

    The latency regression (:func:`estimate_latency`) is linear in the latency and reads a 3-s
    offset as 1.25 s; an 18-s one (heights in GPS time, the IMU in UTC) it does not see at all,
    and the flight's error went from 0.44 to 50 mGal with exit 0 (quick U214). Here the
    residual ``h_ins(t - L) - h(t)`` is formed for shifts ``L`` every :data:`COARSE_STEP_S` s
    within :data:`COARSE_MAX_S` s, then every :data:`COARSE_FINE_STEP_S` s about the best, and
    the variance of its :data:`LATENCY_HIGHPASS_S` high-pass compared (the aircraft's vertical
    motion, metres over seconds, cancels only at the right shift).

    Parameters
    ----------
    nav : gravsurvey.inm.mechanization.Navigation
        The first, unaided mechanization.
    alt_time, alt_height : ndarray (k,)
        Finite height samples inside the mechanization's span (s, m).
    ellipsoid : Ellipsoid

    Returns
    -------
    offset_s : float or None
        The stamps are late by this much; None unless at least :data:`COARSE_MIN_S` and
        dividing the variance by :data:`COARSE_MIN_RATIO` or more.
    ratio : float
        Variance at no shift over the variance at the best shift (1 when no shift helps; NaN
        when there is nothing to compare).
    """
    t = np.asarray(alt_time, float)
    h = np.asarray(alt_height, float)
    if t.size < 32:
        return None, math.nan
    step = max(1, t.size // COARSE_MAX_SAMPLES)
    t, h = t[::step], h[::step]
    dt = float(np.median(np.diff(t)))
    w = max(3, int(round(LATENCY_HIGHPASS_S / max(dt, 1e-9))))
    # samples whose shifted time leaves the mechanization are left out at every shift alike
    keep = (t - COARSE_MAX_S >= nav.time[0] + 1.0) & (t + COARSE_MAX_S <= nav.time[-1] - 1.0)
    if keep.sum() < 32:
        return None, math.nan

    # the residual at no shift, once; a shift then only moves the inertial radius along the
    # track, ``e_L(t) = e(t) + |r_ins|(t - L) - |r_ins|(t)`` (the ellipsoid's radius under the
    # aircraft changes over L seconds by a ramp the high-pass takes off), with |r_ins| at 10 Hz
    # (linear interpolation's radial error a_up dt^2 / 8: about 1 mm in turbulence)
    tk, hk = t[keep], h[keep]
    _, e0 = vertical_residual(nav, tk, hk, ellipsoid)
    k = max(1, int(round(0.1 / max(float(np.median(np.diff(nav.time[:1000]))), 1e-9))))
    t_nav = nav.time[::k]
    r_nav = np.linalg.norm(nav.r_i[::k], axis=1)
    r_now = np.interp(tk, t_nav, r_nav)

    def variance(shift):
        e = e0 + np.interp(tk - shift, t_nav, r_nav) - r_now
        return float(np.var(e - running_mean(e, w)))

    coarse = np.arange(-COARSE_MAX_S, COARSE_MAX_S + 1e-9, COARSE_STEP_S)
    v = np.array([variance(x) for x in coarse])
    best = float(coarse[int(np.argmin(v))])
    fine = np.arange(best - COARSE_STEP_S, best + COARSE_STEP_S + 1e-9, COARSE_FINE_STEP_S)
    vf = np.array([variance(x) for x in fine])
    best = float(fine[int(np.argmin(vf))])
    v0 = variance(0.0)
    ratio = v0 / float(vf.min()) if vf.min() > 0 else math.inf
    if abs(best) < COARSE_MIN_S or not ratio >= COARSE_MIN_RATIO:
        return None, ratio
    return best, ratio


def gnss_height_fraction(alt_time, alt_height, gnss_time, gnss_height) -> float:
    """Fraction of the height channel's samples that are the GNSS's own heights.

    A log without an altimeter gives the GNSS heights as the height channel (``topics:
    {altimeter: /fix}``, or the GNSS file's height column): the same numbers then enter the
    filter twice, as the height measurement and as the GNSS position's up component, each with
    its own noise taken as independent of the other's - the vertical channel weighted as two
    receivers.  A sample counts when a GNSS sample lies within :data:`SAME_SAMPLE_S` of it with
    a height within :data:`SAME_HEIGHT_M`.

    Parameters
    ----------
    alt_time, alt_height : ndarray (n,)
        Height channel, s and m.
    gnss_time, gnss_height : ndarray (k,)
        GNSS times (sorted) and ellipsoidal heights, s and m.

    Returns
    -------
    float
        In [0, 1]; 0 when either channel is empty.
    """
    ta, ha = np.asarray(alt_time, float), np.asarray(alt_height, float)
    tg, hg = np.asarray(gnss_time, float), np.asarray(gnss_height, float)
    if ta.size == 0 or tg.size == 0:
        return 0.0
    # the nearest GNSS sample of each height sample
    hi = np.minimum(np.searchsorted(tg, ta), tg.size - 1)
    lo = np.maximum(hi - 1, 0)
    j = np.where(np.abs(tg[lo] - ta) <= np.abs(tg[hi] - ta), lo, hi)
    same = (np.abs(tg[j] - ta) <= SAME_SAMPLE_S) & (np.abs(hg[j] - ha) <= SAME_HEIGHT_M)
    return float(np.count_nonzero(same)) / ta.size


#: Blocks of this span, s, in which a height channel's local noise is measured
#: (:func:`noisy_stretches`), or of :data:`NOISE_MIN_SAMPLES` samples where longer.
NOISE_BLOCK_S = 10.0
#: A block is noisy when its noise is this many times the channel's (robust sigmas of the
#: residual's second differences): a GNSS's float stretch is metres where its fixed solution is
#: centimetres. On the simulated flights the noisiest block is at most 1.87x (the 20 quick and
#: the 16 issue B/C flights; first differences over 10 s had made turbulent 1-Hz ones 2.03x
#: and marked 330 s of IC07: 0.185 -> 1.73 mGal).
NOISE_FACTOR = 2.5
#: Samples in a block at least: a robust sigma of fewer scatters too much (of 9 first
#: differences one block in a few hundred read twice the whole's; of 30 second differences a
#: turbulent 1-Hz flight's noisiest block 1.9x).
NOISE_MIN_SAMPLES = 60


def noisy_stretches(time, residual_m):
    """Each sample's own noise where its stretch of the channel is noisier than the rest.

    The residual's second differences hold the channel's white noise (the inertial height error
    is slow); their robust sigma over blocks of :data:`NOISE_BLOCK_S` (or
    :data:`NOISE_MIN_SAMPLES` samples) against the whole
    channel's: a block :data:`NOISE_FACTOR` times noisier, or within two blocks of one, marks
    its samples with the largest of those blocks' noise.

    Parameters
    ----------
    time : ndarray (k,)
        Sample times, s, increasing.
    residual_m : ndarray (k,)
        Mechanized minus measured height, m.

    Returns
    -------
    ndarray (k,)
        A sample's height 1-sigma, m, in a noisy stretch; NaN elsewhere.
    """
    t = np.asarray(time, float)
    e = np.asarray(residual_m, float)
    out = np.full(t.size, math.nan)
    if t.size < 2 * NOISE_MIN_SAMPLES:
        return out
    # second differences, centred per block: the first mechanization's height error, slow but
    # bending in turns (its attitude not yet corrected), leaves neither a slope nor a curvature
    d = np.diff(e, 2)
    whole = robust_sigma(d) / math.sqrt(6.0)
    if not whole > 0.0:
        return out
    span = max(NOISE_BLOCK_S, NOISE_MIN_SAMPLES * float(np.median(np.diff(t))))
    block = np.floor((t[1:-1] - t[0]) / span).astype(np.int64)
    nb = int(block[-1]) + 1
    sig = np.full(nb, math.nan)
    # the times increase: each block's differences are one run
    bounds = np.searchsorted(block, np.arange(nb + 1))
    for b in range(nb):
        seg = d[bounds[b] : bounds[b + 1]]
        if seg.size >= NOISE_MIN_SAMPLES // 2:
            sig[b] = robust_sigma(seg) / math.sqrt(6.0)
    noisy = np.where(np.isfinite(sig), sig, 0.0) > NOISE_FACTOR * whole
    if not noisy.any():
        return out
    # the two blocks either side of a noisy one share its noise: a stretch's ends fall inside
    # blocks, and a block half in it reads under the threshold (its samples in the stretch,
    # left to the step search, read as a step)
    worst = np.where(noisy, sig, 0.0)
    near = worst.copy()
    for k in (1, 2):
        near[k:] = np.maximum(near[k:], worst[:-k])
        near[:-k] = np.maximum(near[:-k], worst[k:])
    sample_block = np.clip(np.floor((t - t[0]) / span).astype(np.int64), 0, nb - 1)
    mark = near[sample_block]
    out[mark > 0.0] = mark[mark > 0.0]
    return out
