"""Time-base repair and plausibility checks for ingested channels.

Everything here works on integer-nanosecond time stamps and SI values and returns
:class:`Finding` lists; :mod:`gravsurvey.io.ingest` turns findings into warnings, notes and
errors.  Thresholds are module constants so docs/input-formats.md can quote them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from gravsurvey.filters import centred_mean
from gravsurvey.geodesy import MGAL, OMEGA_E, STANDARD_GRAVITY_MPS2, local_displacement

DEG = np.pi / 180.0

# accelerometer: median |F| over the record (aircraft: ~g in level flight)
ACCEL_OK = (8.8, 10.8)  # m/s^2
# altimeter / GNSS ellipsoidal height range (Dead Sea shore to airliner ceiling + margin)
HEIGHT_OK = (-600.0, 15000.0)  # m
# gyro: any |w| above this is not an aircraft or a vehicle (deg/s declared as rad/s?)
GYRO_MAX_OK = 3.5  # rad/s (200 deg/s)
# rest rate check: a quiet window's mean rate vector may differ from the run's median by
# 4 standard errors or this fraction of the median (transport rate changes), else it is a turn
REST_RATE_STEADY_REL = 0.1
# ... and at least this fraction of the quiet windows must be steady for the unit check to run
REST_STEADY_MIN_FRACTION = 0.5
# rest detection: windows where |F| scatters less than this and sits within ACCEL_OK
#: Shortest quiet period (s) on which the gyro-unit check may fail a flight.
REST_MIN_VERDICT_S = 30.0
REST_WINDOW_S = 2.0
REST_ACCEL_STD = 0.05  # m/s^2
# sample-rate stability: steps off nominal by more than this fraction count as irregular
RATE_TOL = 0.2
RATE_IRREGULAR_WARN = 0.01  # warn when more than 1 % of steps are irregular
#: Shortest stretch of steps all off the nominal one that is named as the channel running at
#: another rate, s.
RATE_RUN_MIN_S = 10.0
MAX_LISTED = 10  # gaps/backward steps listed individually
#: Stray time stamps: a cluster of samples more than STRAY_GAP_NS from every other sample of its
#: channel, holding at most STRAY_MAX_FRACTION of them or STRAY_MIN_SAMPLES (a 1-Hz channel's
#: single stamp), and fewer than STRAY_MAX_SAMPLES, is
#: a logger glitch (a stamp of 0, of year 9999, a GPS week off) and is dropped: kept, it would
#: make the channel span decades, and every grid over its time a memory bomb
STRAY_GAP_NS = 3600 * 10**9
STRAY_MAX_FRACTION = 0.001
STRAY_MIN_SAMPLES = 2
STRAY_MAX_SAMPLES = 1000
#: Samples sharing a stamp with different values, as a fraction of the channel, above which the
#: stamps are a logger's quantised or buffered ones (a 50-Hz IMU stamped to 0.1 s, or a block of
#: samples stamped when it was read) and are rebuilt from the sample count
#: (:func:`rebuild_time_base`) instead of keeping the first sample of each stamp.
REBUILD_DUPLICATE_FRACTION = 0.01
#: Stamp jitter (RMS deviation of the steps from the nominal step, over it) above which the
#: stamps are a host's arrival times about a steady sampling clock and are rebuilt.
REBUILD_JITTER = 0.03
#: Least half-width, in samples, of the window that smooths the stamps' deviation from a line.
REBUILD_HALF_WINDOW = 50
#: Without shared stamps, a step of this many nominal steps or more (a dropped sample) ends one
#: stretch of the rebuild; with them, a step between stamps over ``gap_factor`` times its
#: samples' share of time does.
REBUILD_SPLIT_STEPS = 1.75
#: A jitter rebuild that moves no stamp by this fraction of the step or more is not applied.
REBUILD_MIN_SHIFT = 0.01


@dataclass
class Finding:
    """One check result for one channel.

    ``level``: "ok", "info", "warning" (repaired or suspicious) or "error" (refuse to process).
    """

    channel: str
    check: str
    level: str
    message: str
    value: float | None = None


@dataclass
class TimeReport:
    """What :func:`repair_time` found and did (times in ns since the Unix epoch)."""

    n_in: int = 0
    n_out: int = 0
    nominal_step_ns: float = float("nan")
    duplicates: int = 0  # same stamp, same values: dropped
    conflicting_duplicates: int = 0  # same stamp, different values: first kept
    stray: list = field(default_factory=list)  # (t_first_ns, t_last_ns, count) of dropped stray clusters
    n_stray: int = 0
    backward: list = field(default_factory=list)  # (index, t_prev_ns, t_ns) of backward steps
    n_backward: int = 0
    gaps: list = field(default_factory=list)  # (t_before_ns, t_after_ns) after repair
    n_gaps: int = 0
    irregular_fraction: float = 0.0
    jitter: float = 0.0  # std(dt)/nominal over regular steps
    rate_runs: list = field(default_factory=list)  # (t_first_ns, t_last_ns, rate_hz) at another rate
    rebuilt: str = ""  # "coarse" or "jitter" when rebuild_time_base rebuilt the stamps
    rebuilt_shared: int = 0  # samples that had shared a stamp with the one before
    rebuilt_jitter: float = 0.0  # the stamps' jitter before the rebuild, RMS step deviation / step
    rebuilt_shift_ns: float = 0.0  # largest |new - old| stamp
    rebuilt_stamp_step_ns: float = 0.0  # median step between distinct stamps before the rebuild


def repair_time(time_ns, values, gap_factor=5.0):
    """Make a channel's time strictly increasing and describe its time base.

    Samples are put in time order (stable sort, so equal stamps keep file order); samples with
    a stamp equal to the previous one are dropped (counted as duplicates, or conflicting
    duplicates when their values differ: the first is kept); a few samples far from all others
    are dropped as stray stamps (:data:`STRAY_GAP_NS`, counted).  Backward steps in the input
    order are listed with their times.  Gaps are steps longer than ``gap_factor`` times the
    nominal step (the median step).

    Parameters
    ----------
    time_ns : ndarray of int64, shape (n,)
        Measurement times, ns since the Unix epoch.
    values : list of ndarray, each shape (n,) or (n, k)
        Sample values, reordered/filtered along with time.
    gap_factor : float
        Gap threshold as a multiple of the nominal step.

    Returns
    -------
    time_ns : ndarray of int64, shape (m,)
    values : list of ndarray
    report : TimeReport
    """
    t = np.asarray(time_ns, dtype=np.int64)
    rep = TimeReport(n_in=len(t))
    if len(t) > 1:
        # stray stamps first: the steps to and from them are no backward steps of the channel
        order = np.argsort(t, kind="stable")
        keep = np.empty(len(t), bool)
        keep[order] = _stray_keep(t[order], rep)
        if not keep.all():
            t = t[keep]
            values = [v[keep] for v in values]
    if len(t) > 1:
        d = np.diff(t)
        back = np.flatnonzero(d < 0)
        rep.n_backward = len(back)
        rep.backward = [(int(i + 1), int(t[i]), int(t[i + 1])) for i in back[:MAX_LISTED]]
        if len(back):
            order = np.argsort(t, kind="stable")
            t = t[order]
            values = [v[order] for v in values]
        dup = np.flatnonzero(np.diff(t) == 0) + 1
        if len(dup):
            same = np.ones(len(dup), bool)
            for v in values:
                a, b = v[dup], v[dup - 1]
                eq = (a == b) | (np.isnan(a) & np.isnan(b))
                same &= eq.reshape(len(dup), -1).all(axis=1)
            rep.duplicates = int(same.sum())
            # a sample written twice goes; samples that only share a stamp are dropped too,
            # unless so many do that the stamps are the logger's (rebuilt below, all kept)
            drop = dup[same]
            if (~same).sum() < REBUILD_DUPLICATE_FRACTION * len(t):
                drop = dup
                rep.conflicting_duplicates = int((~same).sum())
            keep = np.ones(len(t), bool)
            keep[drop] = False
            t = t[keep]
            values = [v[keep] for v in values]
        if len(t) > 1 and (np.any(np.diff(t) == 0) or _step_jitter(t, gap_factor) > REBUILD_JITTER):
            rebuilt = rebuild_time_base(t, gap_factor)
            if rebuilt is not None and (rebuilt[1]["kind"] == "coarse" or _moves_stamps(t, rebuilt[0])):
                new_t, info = rebuilt
                rep.rebuilt, rep.rebuilt_shared = info["kind"], info["n_shared"]
                rep.rebuilt_jitter, rep.rebuilt_stamp_step_ns = info["jitter"], info["stamp_step_ns"]
                rep.rebuilt_shift_ns = float(np.max(np.abs(new_t - t)))
                t = new_t
            elif np.any(np.diff(t) == 0):
                # no steady sampling clock under the shared stamps: the first of each, as before
                dup = np.flatnonzero(np.diff(t) == 0) + 1
                rep.conflicting_duplicates = len(dup)
                keep = np.ones(len(t), bool)
                keep[dup] = False
                t = t[keep]
                values = [v[keep] for v in values]
    rep.n_out = len(t)
    if len(t) > 1:
        d = np.diff(t).astype(np.float64)
        nom = float(np.median(d))
        rep.nominal_step_ns = nom
        gi = np.flatnonzero(d > gap_factor * nom)
        rep.n_gaps = len(gi)
        rep.gaps = [(int(t[i]), int(t[i + 1])) for i in gi[:MAX_LISTED]]
        regular = d <= gap_factor * nom
        irr = np.abs(d - nom) > RATE_TOL * nom
        rep.irregular_fraction = float(np.mean(irr & regular)) if len(d) else 0.0
        dr = d[regular & ~irr]
        rep.jitter = float(np.std(dr) / nom) if len(dr) > 1 else 0.0
        rep.rate_runs = _rate_runs(t, d, irr & regular)
    return t, values, rep


def _step_jitter(t, gap_factor) -> float:
    """The steps' scatter from stamp to stamp over the nominal step: their RMS deviation, were
    the stamps' errors white, from the median absolute change between consecutive steps (so a
    rate that changed within the record, or a dropped sample now and then, is no jitter); gaps
    left out, 0 for fewer than 4 steps."""
    d = np.diff(np.asarray(t, np.int64)).astype(np.float64)
    if d.size < 4:
        return 0.0
    nom = float(np.median(d))
    if not nom > 0:
        return 0.0
    d = d[d <= gap_factor * nom]
    if d.size < 4:
        return 0.0
    # white stamp errors e: steps d_k = e_k+1 - e_k + nom, changes d_k+1 - d_k with 3 times the
    # steps' variance; 1.4826 x the median absolute value is a standard deviation
    return float(1.4826 * np.median(np.abs(np.diff(d))) / math.sqrt(3.0) / nom)


def _moves_stamps(t, new) -> bool:
    """Whether a rebuilt time base moves any stamp by :data:`REBUILD_MIN_SHIFT` of the median
    step or more (stretches of exact stamps between dropped samples come back as they were)."""
    d = np.diff(np.asarray(t, np.int64))
    return bool(d.size) and float(np.max(np.abs(new - t))) >= REBUILD_MIN_SHIFT * float(np.median(d))


def rebuild_time_base(time_ns, gap_factor=5.0):
    """Stamps rebuilt from the sample count, where a logger's stamps are not the samples' times.

    A sensor samples on its own steady clock; a logger that stamps the samples with a coarse
    clock (a 50-Hz IMU stamped to 0.1 s: runs of five samples on one stamp), when it reads a
    block of them (all stamped alike), or when each arrives at the host (a jitter of
    milliseconds) writes stamps that scatter about the true times.  Dropping the samples that
    share a stamp loses most of the record (four in five above); integrating across jittered
    steps turns the specific force times each step's error into velocity noise.  Here, in the
    stamps' order, stretch by stretch (a gap, or without shared stamps a dropped sample, ends
    one), the stamps are fitted by a line against the sample number and their deviation from it
    smoothed by a centred running mean over at least :data:`REBUILD_HALF_WINDOW` samples each
    side (four times the longest run of one stamp): a rate that drifts slowly is followed, the
    scatter averaged away.  Stamps rounded to their resolution come out right on average;
    stamps of a block read later than it was sampled come out late by the block's mean delay,
    which the GNSS latency check of the aided track measures and takes off.

    Parameters
    ----------
    time_ns : ndarray of int64, shape (n,)
        Non-decreasing stamps, ns since the Unix epoch, one per sample in the order sampled.
    gap_factor : float
        A step between consecutive distinct stamps over this many times the time its samples
        take is a gap (the stretches are rebuilt apart).

    Returns
    -------
    tuple or None
        ``(time_ns, info)``: the rebuilt, strictly increasing stamps (int64, shape (n,)) and
        ``info`` (``kind`` "coarse" or "jitter", ``n_shared`` samples that had shared a stamp,
        ``jitter`` of the steps before, ``stamp_step_ns`` median step between distinct stamps);
        None where no steady sampling rate fits (the rebuilt stamps would not increase).
    """
    t = np.asarray(time_ns, np.int64)
    n = t.size
    if n < 8:
        return None
    start = np.flatnonzero(np.concatenate([[True], np.diff(t) != 0]))
    runs = np.diff(np.concatenate([start, [n]]))
    dstamp = np.diff(t[start]).astype(np.float64)
    if dstamp.size < 2:
        return None
    per_sample = dstamp / runs[:-1]
    step = float(np.median(per_sample))
    if not step > 0:
        return None
    longest = int(runs.max())
    # the smoothing window a whole number of the usual run: the sawtooth of coarse stamps
    # averages out exactly instead of leaving a ripple of a stamp step over the window
    usual = int(np.argmax(np.bincount(runs)))
    width = usual * -(-(2 * max(REBUILD_HALF_WINDOW, 4 * longest) + 1) // usual)
    stamp_step = float(np.median(dstamp))
    if longest > 1:
        limit = gap_factor * np.maximum(runs[:-1] * step, stamp_step)
    else:
        limit = np.full(dstamp.size, REBUILD_SPLIT_STEPS * step)
    cut = np.flatnonzero(dstamp > limit)
    bounds = np.concatenate([[0], start[cut + 1], [n]])
    new = np.empty(n, np.int64)
    for a, b in zip(bounds[:-1], bounds[1:]):
        m = b - a
        if m < 2:
            new[a:b] = t[a:b]
            continue
        k = np.arange(m, dtype=np.float64)
        # ns relative to the stretch's first stamp: exact in float64 for 104 days
        s = (t[a:b] - t[a]).astype(np.float64)
        slope, icpt = np.polyfit(k, s, 1)
        line = icpt + slope * k
        dev = centred_mean(s - line, width) if m > width else np.zeros(m)
        new[a:b] = t[a] + np.round(line + dev).astype(np.int64)
    if np.any(np.diff(new) <= 0):
        return None
    info = {
        "kind": "coarse" if longest > 1 else "jitter",
        "n_shared": int(n - start.size),
        "jitter": _step_jitter(t, gap_factor) if longest == 1 else 0.0,
        "stamp_step_ns": stamp_step,
    }
    return new, info


def _rate_runs(t, d, off):
    """Stretches of at least :data:`RATE_RUN_MIN_S` where every step is off the nominal one:
    the channel ran at another rate there (a logger that changed its rate mid-flight), not
    jitter.  ``(t_first_ns, t_last_ns, rate_hz)`` of the first :data:`MAX_LISTED`."""
    if not off.any():
        return []
    edge = np.diff(np.concatenate([[0], off.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(edge == 1), np.flatnonzero(edge == -1)
    runs = []
    for a, b in zip(starts, ends):
        if (t[b] - t[a]) * 1e-9 >= RATE_RUN_MIN_S:
            runs.append((int(t[a]), int(t[b]), 1e9 / float(np.median(d[a:b]))))
            if len(runs) == MAX_LISTED:
                break
    return runs


def _stray_keep(t_sorted, rep: TimeReport) -> np.ndarray:
    """Which of the sorted stamps to keep: not those of stray clusters (:data:`STRAY_GAP_NS`),
    which ``rep`` counts and lists."""
    keep = np.ones(len(t_sorted), bool)
    cut = np.flatnonzero(np.diff(t_sorted) > STRAY_GAP_NS) + 1
    if not len(cut):
        return keep
    bounds = np.concatenate([[0], cut, [len(t_sorted)]])
    sizes = np.diff(bounds)
    small = (sizes <= max(STRAY_MAX_FRACTION * len(t_sorted), STRAY_MIN_SAMPLES)) & (sizes < STRAY_MAX_SAMPLES)
    if small.all():
        return keep
    for a, b in zip(bounds[:-1][small], bounds[1:][small]):
        keep[a:b] = False
        rep.stray.append((int(t_sorted[a]), int(t_sorted[b - 1]), int(b - a)))
    rep.n_stray = int((~keep).sum())
    return keep


def time_findings(channel, rep: TimeReport, t0_ns=0):
    """Findings (notes/warnings) describing a :class:`TimeReport`; times as s after t0."""
    out = []

    def s(tns):
        return (tns - t0_ns) * 1e-9

    if rep.duplicates:
        out.append(Finding(channel, "duplicates", "warning", f"{channel}: dropped {rep.duplicates} duplicate samples"))
    if rep.conflicting_duplicates:
        out.append(
            Finding(
                channel,
                "duplicates",
                "warning",
                f"{channel}: {rep.conflicting_duplicates} samples share a time stamp "
                "with different values; kept the first of each",
            )
        )
    if rep.rebuilt == "coarse":
        out.append(
            Finding(
                channel,
                "stamps",
                "warning",
                f"{channel}: {rep.rebuilt_shared} samples shared a time stamp with the one before (distinct stamps "
                f"{rep.rebuilt_stamp_step_ns * 1e-9:.3g} s apart for {1e9 / rep.nominal_step_ns:.4g}-Hz samples: the "
                "logger's coarse or block stamps); every sample kept, the stamps rebuilt from the sample count "
                f"(moved by up to {rep.rebuilt_shift_ns * 1e-9:.3g} s)",
                rep.rebuilt_shared,
            )
        )
    elif rep.rebuilt == "jitter":
        out.append(
            Finding(
                channel,
                "stamps",
                "warning",
                f"{channel}: time stamps scatter {100 * rep.rebuilt_jitter:.1f} % of the step about a steady rate "
                "(arrival times or coarse stamps, not sampling times); rebuilt from the sample count "
                f"(moved by up to {rep.rebuilt_shift_ns * 1e-6:.3g} ms)",
                rep.rebuilt_jitter,
            )
        )
    if rep.n_stray:
        from gravsurvey.utc import utc_iso

        lst = ", ".join(
            f"{n} at {utc_iso(a, 0)}" + ("" if a == b else f"..{utc_iso(b, 0)}") for a, b, n in rep.stray[:MAX_LISTED]
        )
        out.append(
            Finding(
                channel,
                "stray",
                "warning",
                f"{channel}: dropped {rep.n_stray} sample(s) with stray time stamps, over "
                f"{STRAY_GAP_NS // 3_600_000_000_000} h from all the channel's other samples: {lst}",
                rep.n_stray,
            )
        )
    if rep.n_backward:
        lst = ", ".join(f"{s(a):.6f}->{s(b):.6f} s" for _, a, b in rep.backward)
        out.append(
            Finding(
                channel,
                "backward",
                "warning",
                f"{channel}: {rep.n_backward} backward time steps (re-sorted): {lst}"
                + (" ..." if rep.n_backward > len(rep.backward) else ""),
            )
        )
    if rep.n_gaps:
        lst = ", ".join(f"{s(a):.3f}-{s(b):.3f} s" for a, b in rep.gaps)
        out.append(
            Finding(
                channel,
                "gaps",
                "warning",
                f"{channel}: {rep.n_gaps} gaps longer than the threshold: {lst}"
                + (" ..." if rep.n_gaps > len(rep.gaps) else ""),
                rep.n_gaps,
            )
        )
    if rep.n_out > 1:
        rate = 1e9 / rep.nominal_step_ns
        lvl = "warning" if rep.irregular_fraction > RATE_IRREGULAR_WARN else "ok"
        out.append(
            Finding(
                channel,
                "rate",
                lvl,
                f"{channel}: nominal rate {rate:.6g} Hz, "
                f"{100 * rep.irregular_fraction:.2f} % of steps off by > "
                f"{100 * RATE_TOL:.0f} %, jitter {100 * rep.jitter:.2f} %"
                + "".join(f"; {hz:.3g} Hz over {s(a):.1f}-{s(b):.1f} s" for a, b, hz in rep.rate_runs)
                + (" (the rate changed within the record)" if rep.rate_runs else ""),
                rate,
            )
        )
    return out


def _rest_mask(f_norm, time_ns, nominal_step_ns):
    """Samples of the longest run of REST_WINDOW_S windows where |F| is steady near g.

    The longest contiguous run (not all rest windows) so that a strapdown triad keeps one
    orientation: the mean rate vector is then Earth rate resolved on a fixed triad.
    """
    n = len(f_norm)
    if n < 4 or not np.isfinite(nominal_step_ns) or nominal_step_ns <= 0:
        return np.zeros(n, bool)
    w = max(4, int(round(REST_WINDOW_S * 1e9 / nominal_step_ns)))
    nw = n // w
    if nw == 0:
        return np.zeros(n, bool)
    blocks = f_norm[: nw * w].reshape(nw, w)
    rest = (blocks.std(axis=1) < REST_ACCEL_STD) & (np.abs(blocks.mean(axis=1) - STANDARD_GRAVITY_MPS2) < 0.3)
    # windows must also be contiguous in time (no gap inside the run)
    tb = time_ns[: nw * w].reshape(nw, w)
    contiguous = np.ones(nw, bool)
    contiguous[1:] = (tb[1:, 0] - tb[:-1, -1]) < 3 * nominal_step_ns
    best, best_len, start = None, 0, None
    for i in range(nw + 1):
        on = i < nw and rest[i] and (start is None or contiguous[i])
        if on and start is None:
            start = i
        elif not on and start is not None:
            if i - start > best_len:
                best, best_len = start, i - start
            start = i if i < nw and rest[i] else None
    mask = np.zeros(n, bool)
    if best is not None:
        mask[best * w : (best + best_len) * w] = True
    return mask


def row_norm(x):
    """Euclidean norm of each row of a 3-vector array.

    Bit-identical to ``np.linalg.norm(x, axis=1)`` (same squares, same left-to-right sum)
    without its (n, 3) temporaries: 1.0 instead of 6.4 ms for 360 000 rows.

    Parameters
    ----------
    x : ndarray, shape (n, 3)
        Vectors in any unit.

    Returns
    -------
    ndarray, shape (n,)
        Their norms, same unit.
    """
    return np.sqrt(x[:, 0] * x[:, 0] + x[:, 1] * x[:, 1] + x[:, 2] * x[:, 2])


def mean_std(x, axis):
    """Mean and (population) standard deviation along one axis, the mean computed once.

    Same operations in the same order as ``x.mean(axis)`` and ``x.std(axis)`` (numpy's sum /
    count; sum of squared deviations / count; sqrt), so both results are bit-identical, while
    ``x.std`` alone would sum ``x`` a second time for its own mean.

    Parameters
    ----------
    x : ndarray of float
        Any shape, any unit.
    axis : int

    Returns
    -------
    mean, std : ndarray
        ``x``'s shape without ``axis``, ``x``'s unit.
    """
    n = x.shape[axis]
    mean = np.add.reduce(x, axis=axis, keepdims=True) / n
    dev = x - mean
    np.multiply(dev, dev, out=dev)
    var = np.add.reduce(dev, axis=axis) / n
    return np.squeeze(mean, axis=axis), np.sqrt(var)


#: Median |specific force| below which, no unit mix-up explaining it, the accelerometer
#: columns are named as a linear acceleration (gravity taken out), m/s^2: under the band of g
#: read as m/s^2 (1 +- 15 %); an aircraft's own accelerations have a median of 0.05-0.5.
LINEAR_ACCEL_MAX = 0.85


def _ratio_name(r, candidates):
    for name, k in candidates:
        if abs(r / k - 1.0) < 0.15:
            return name
    return None


def check_imu(time_ns, f, w, nominal_step_ns, accel_unit="m/s^2", gyro_unit="rad/s"):
    """Plausibility of IMU values (SI after unit conversion).

    Accelerometer: the median of |F| over the record must lie in ``ACCEL_OK`` (an aircraft's
    specific force averages ~g); ~1 means g declared as m/s^2, ~1e6 mGal declared as m/s^2.
    Gyro: any |w| above ``GYRO_MAX_OK`` is implausible; at rest (the longest run of
    ``REST_WINDOW_S`` windows where |F| is steady near g) the mean rate vector must be Earth rate (within a factor of 2)
    when it is measured well (|mean| > 10 standard errors): 57.3x, 1/57.3x, 206265x, 1/206265x
    Earth rate (within a factor of 2) is an error naming the unit mix-up; anything else a
    warning.  Both need a quiet period of at least ``REST_MIN_VERDICT_S`` (a static start);
    a shorter one (seconds of steady flight) is reported as info only.

    Returns
    -------
    list of Finding
    """
    out = []
    fn = row_norm(f)
    wn = row_norm(w)
    if len(fn) == 0:
        return out
    med = float(np.median(fn))
    if ACCEL_OK[0] <= med <= ACCEL_OK[1]:
        out.append(
            Finding(
                "imu", "accel magnitude", "ok", f"imu: median |specific force| {med:.4f} m/s^2 (expected ~9.8)", med
            )
        )
    else:
        dt = nominal_step_ns * 1e-9
        candidates = [
            ("values are in g but declared as m/s^2", 1.0),
            ("values are in mGal but declared as m/s^2", STANDARD_GRAVITY_MPS2 / MGAL),
            ("values are in m/s^2 but declared as g", STANDARD_GRAVITY_MPS2**2),
            ("values are in m/s^2 but declared as mGal", STANDARD_GRAVITY_MPS2 * MGAL),
        ]
        if accel_unit in ("m/s^2", "m/s") and dt > 0.0:
            # navigation-grade IMUs write increments per sample: g x step read as a rate, or
            # g / step when rates are declared as increments
            candidates += [
                (
                    f"values are velocity increments per {dt * 1e3:.4g}-ms sample declared as a rate "
                    "(units accel: m/s with gyro: rad or deg)",
                    STANDARD_GRAVITY_MPS2 * dt,
                ),
                (
                    f"values are rates declared as increments per {dt * 1e3:.4g}-ms sample "
                    "(units accel: m/s^2 with gyro: rad/s)",
                    STANDARD_GRAVITY_MPS2 / dt,
                ),
            ]
        hint = _ratio_name(med, candidates)
        if hint is None and accel_unit == "m/s^2" and med < LINEAR_ACCEL_MAX:
            # below g-declared-as-m/s^2 with no unit that explains it: an accelerometer output
            # with gravity taken out (an INS's "linear" or "free" acceleration), the motion alone
            hint = (
                "a linear acceleration (gravity taken out) instead of the specific force the accelerometers "
                "measure, gravity included"
            )
        out.append(
            Finding(
                "imu",
                "accel magnitude",
                "error",
                f"imu: median |specific force| is {med:.6g} m/s^2 after converting "
                f"from {accel_unit}, expected ~9.8" + (f": {hint}?" if hint else ": wrong unit or axis scaling?"),
                med,
            )
        )
    wmax = float(np.percentile(wn, 99.9))
    if wmax > GYRO_MAX_OK:
        out.append(
            Finding(
                "imu",
                "gyro magnitude",
                "error",
                f"imu: angular rate reaches {wmax:.4g} rad/s (99.9th percentile) after "
                f"converting from {gyro_unit}; more than {GYRO_MAX_OK} rad/s is not a "
                "vehicle: deg/s or deg/h declared as rad/s?",
                wmax,
            )
        )
    rest = _rest_mask(fn, time_ns, nominal_step_ns)
    # |F| steady near g is also true in straight flight and in the gentle parts of turns
    # (bank < ~14 deg): a run of such windows spanning a turn's roll-in has a mean rate of
    # ~0.1-0.5 deg/s, exactly the "deg/s declared as rad/s" signature.  Keep only the windows
    # whose mean rate vector agrees with the run's median (at rest and in straight flight the
    # rate is Earth + transport rate, constant); the test is scale-free, so a real unit
    # mistake (every rate x 57.3) keeps its windows steady and is still caught.
    idx = np.flatnonzero(rest)
    nw_all, steady_windows = 0, 0
    rest_rows = None  # the rest samples as a slice when they are one contiguous run (no gather)
    if idx.size >= 8 and np.isfinite(nominal_step_ns) and nominal_step_ns > 0:
        win = max(4, int(round(REST_WINDOW_S * 1e9 / nominal_step_ns)))
        nw_all = idx.size // win
        if nw_all >= 1:
            used = idx[: nw_all * win]
            # _rest_mask marks one contiguous run: a view then replaces a 3-column gather
            run = slice(int(used[0]), int(used[-1]) + 1) if used[-1] - used[0] + 1 == used.size else None
            # (a fancy-index gather is C-contiguous: so is the view made, for the same sums' order)
            blocks = (np.ascontiguousarray(w[run]) if run is not None else w[used]).reshape(nw_all, win, 3)
            means, stds = mean_std(blocks, axis=1)  # (nw, 3) rad/s
            se_win = row_norm(stds) / np.sqrt(win)  # (nw,)
            centre = np.median(means, axis=0)
            tol = max(4.0 * float(np.median(se_win)), REST_RATE_STEADY_REL * float(np.linalg.norm(centre)))
            steady = row_norm(means - centre) <= tol
            steady_windows = int(steady.sum())
            if run is not None and steady_windows == nw_all:
                rest_rows = run
            else:
                keep = np.zeros(len(fn), bool)
                keep[used.reshape(nw_all, win)[steady].ravel()] = True
                rest = keep
    if nw_all and steady_windows < REST_STEADY_MIN_FRACTION * nw_all:
        out.append(
            Finding(
                "imu",
                "gyro at rest",
                "info",
                f"imu: angular rate not steady in the quiet windows ({steady_windows} of "
                f"{nw_all} windows steady: turning?); gyro unit checked by range only",
            )
        )
    elif (n_rest := (rest_rows.stop - rest_rows.start if rest_rows is not None else int(rest.sum()))) >= 8:
        wr = np.ascontiguousarray(w[rest_rows]) if rest_rows is not None else w[rest]
        wr_mean, wr_std = mean_std(wr, axis=0)
        wmean = float(np.linalg.norm(wr_mean))
        # standard error of the mean rate vector: is the rest rate measured well enough?
        se = float(np.linalg.norm(wr_std) / np.sqrt(len(wr)))
        ratio = wmean / OMEGA_E
        msg = f"imu: at rest ({n_rest} samples) mean angular rate {wmean:.4g} rad/s = {ratio:.4g} x Earth rate"
        # candidates are >= 57x apart, so "within a factor of 2" is unambiguous and tolerates
        # transport rate and slow heading changes in steady level flight
        name = None
        for label, k in (
            ("deg/s declared as rad/s", 1 / DEG),
            ("rad/s declared as deg/s", DEG),
            ("deg/h declared as rad/s", 3600 / DEG),
            ("rad/s declared as deg/h", DEG / 3600),
        ):
            if 0.5 < ratio / k < 2.0:
                name = label
        if wmean < 10 * se:
            out.append(
                Finding(
                    "imu",
                    "gyro at rest",
                    "info",
                    msg + f"; gyro noise (standard error {se:.2g} rad/s) too large to "
                    "check the unit against Earth rate",
                    ratio,
                )
            )
        elif 0.5 < ratio < 2.0:
            out.append(Finding("imu", "gyro at rest", "ok", msg + " (expected ~1)", ratio))
        elif n_rest * nominal_step_ns * 1e-9 < REST_MIN_VERDICT_S:
            # a few seconds of steady |F| in flight (turbulence, a gentle turn) are not a rest;
            # an error or a warning needs a quiet period a real static start gives (quick
            # U1431 and U1441, no static start: 1.4-2 s read as 182 and 360 x Earth rate, "gyro
            # bias, low-grade gyro or wrong unit?" on flights with neither)
            out.append(
                Finding(
                    "imu",
                    "gyro at rest",
                    "info",
                    msg
                    + (f": would read as {name}" if name else ", not ~1")
                    + f", but the quiet period is shorter than {REST_MIN_VERDICT_S:g} s (not a rest); "
                    "gyro unit checked by range only",
                    ratio,
                )
            )
        elif name:
            out.append(
                Finding("imu", "gyro at rest", "error", msg + f" after converting from {gyro_unit}: {name}?", ratio)
            )
        else:
            out.append(
                Finding(
                    "imu",
                    "gyro at rest",
                    "warning",
                    msg + f", expected ~1: gyro bias, low-grade gyro or wrong unit ({gyro_unit})?",
                    ratio,
                )
            )
    else:
        out.append(Finding("imu", "gyro at rest", "info", "imu: no rest period found; gyro unit checked by range only"))
    return out


#: An IMU glitch: a sample off the mean of its two neighbours by more than this many robust
#: sigmas of that same statistic over the record, its neighbours off theirs the other way
#: (:func:`single_sample_outliers`).  A sensor's anti-alias filter makes a real acceleration or
#: rate span samples; one sample alone off both neighbours is a corrupted or dropped reading.
IMU_SPIKE_K = 10.0
#: ... and above this multiple of the statistic's 99th percentile over the record (a real MEMS
#: IMU on a wheeled robot has shocks of 7-24 robust sigmas, the ROS 2 bags of tests/data/ros2-imu:
#: none passes; a corrupted reading stands at hundreds; the 99th percentile stays below the
#: glitches themselves while they are under 0.1 % of the samples).
IMU_SPIKE_TAIL = 4.0
#: Most glitches repaired: beyond this share of the samples it is the signal, not a glitch.
IMU_SPIKE_MAX_FRACTION = 0.001


def robust_sigma(x) -> float:
    """1.4826 x the median absolute deviation of the finite values of ``x``: the sigma of a
    normal sample, unmoved by a few outliers (0 for none)."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return 0.0
    return 1.4826 * float(np.median(np.abs(x - np.median(x))))


def single_sample_outliers(x, k_sigma: float, tail_factor: float | None = None):
    """Samples that stand alone off both neighbours.

    ``r[k] = x[k] - (x[k-1] + x[k+1]) / 2`` is the signal's curvature (small and of one sign
    along a smooth stretch) plus its noise; a lone outlier ``A`` gives ``r = -A/2, A, -A/2``.
    Flagged: ``|r[k]|`` above ``k_sigma`` robust sigmas of ``r`` over the whole series (1.4826
    x its median absolute deviation), with both neighbours' ``r`` of the other sign and at
    least a quarter of it.  Against the series' own scale, so the threshold follows the noise of
    any sensor and unit; a smooth signal (a running median of its differences would follow it
    and leave no noise to scale by) cannot pass the sign test.

    Parameters
    ----------
    x : ndarray (n,)
    k_sigma : float
    tail_factor : float, optional
        Also above this multiple of the 99th percentile of ``|r|`` (about its median): a
        signal with heavy tails of its own (a vehicle's shocks) keeps them; a corrupted
        reading is far beyond any of them.

    Returns
    -------
    ndarray of int
        Indices (interior samples only).
    """
    x = np.asarray(x, float)
    if x.size < 5 or not np.isfinite(x).all():
        return np.zeros(0, np.int64)
    r = x[1:-1] - 0.5 * (x[:-2] + x[2:])
    s = robust_sigma(r)
    if not s > 0.0:
        return np.zeros(0, np.int64)
    level = k_sigma * s
    if tail_factor is not None:
        level = max(level, tail_factor * float(np.quantile(np.abs(r - np.median(r)), 0.99)))
    mid, left, right = r[1:-1], r[:-2], r[2:]
    hit = (
        (np.abs(mid) > level)
        & (left * mid < 0.0)
        & (right * mid < 0.0)
        & (np.abs(left) > 0.25 * np.abs(mid))
        & (np.abs(right) > 0.25 * np.abs(mid))
    )
    return (np.flatnonzero(hit) + 2).astype(np.int64)


#: A column holding its extreme value on at least this many samples ...
SATURATION_MIN_SAMPLES = 10
#: ... this many times as often as the most frequent of the next values towards the bulk (a
#: sensor at its range piles the samples up at one number; noise or coarse digits spread them)
SATURATION_PILE_UP = 5.0
#: How many distinct values next to the extreme make that comparison.
SATURATION_NEIGHBOURS = 20


def saturated_samples(x) -> np.ndarray:
    """Samples of one IMU column held at the column's largest or smallest value: the sensor's
    range, exceeded (an accelerometer of 2 g in a hard turn or turbulence, a logger's clip).

    The test is a pile-up at the extreme: at least :data:`SATURATION_MIN_SAMPLES` samples exactly
    equal to it, :data:`SATURATION_PILE_UP` times as many as of any of the
    :data:`SATURATION_NEIGHBOURS` distinct values next to it.  A constant column (a dead axis, a
    noise-free simulation at rest) is none.

    Parameters
    ----------
    x : ndarray, shape (n,)

    Returns
    -------
    ndarray of bool, shape (n,)
    """
    x = np.asarray(x, float)
    out = np.zeros(x.size, bool)
    fin = x[np.isfinite(x)]
    if fin.size < 10 * SATURATION_MIN_SAMPLES:
        return out
    lo, hi = float(fin.min()), float(fin.max())
    if not hi > lo:
        return out
    for ext, sign in ((hi, 1.0), (lo, -1.0)):
        at = x == ext
        n_at = int(at.sum())
        if n_at < SATURATION_MIN_SAMPLES:
            continue
        # the samples next to the extreme, at most a few times the pile-up's size of them
        rest = sign * fin[fin != ext]
        k = min(rest.size, SATURATION_NEIGHBOURS * n_at)
        if k == 0:
            continue
        top = np.partition(rest, rest.size - k)[rest.size - k :]
        _, counts = np.unique(top, return_counts=True)
        if n_at >= SATURATION_PILE_UP * int(counts[-SATURATION_NEIGHBOURS:].max()):
            out |= at
    return out


def saturated_imu(f, w, t_s=None, accel_unit="m/s^2", gyro_unit="rad/s"):
    """Accelerometer and gyro axes at their range (:func:`saturated_samples`).

    Parameters
    ----------
    f, w : ndarray, shape (n, 3)
        Specific force and angular rate as recorded (SI).
    t_s : ndarray, shape (n,), optional
        Sample times, s after the record's start (for the message).
    accel_unit, gyro_unit : str
        The units the file declared (the values are quoted in SI).

    Returns
    -------
    saturated : ndarray of bool, shape (n,)
        Samples where an accelerometer axis sat at its range.
    findings : list of Finding
        A warning per saturated axis: the value, the count, the runs and the first's times; the
        accelerometers' samples are kept and the filter told their velocity is unknown
        (:func:`gravsurvey.inm.solve.imu_gap_noise`); a gyro's attitude is not repaired.
    """
    n = np.asarray(f).shape[0]
    sat = np.zeros(n, bool)
    out = []
    for name, arr, unit, si in (
        ("specific_force", f, accel_unit, "m/s^2"),
        ("angular_rate", w, gyro_unit, "rad/s"),
    ):
        for j, axis in enumerate("xyz"):
            m = saturated_samples(np.asarray(arr)[:, j])
            if not m.any():
                continue
            edge = np.diff(np.concatenate([[0], m.astype(np.int8), [0]]))
            starts, ends = np.flatnonzero(edge == 1), np.flatnonzero(edge == -1)
            vals = ", ".join(f"{v:.6g}" for v in np.unique(np.asarray(arr)[m, j]))
            first = "" if t_s is None else f" (first {t_s[starts[0]]:.2f}-{t_s[ends[0] - 1]:.2f} s)"
            if name == "specific_force":
                sat |= m
                what = (
                    "the accelerometer's range exceeded (saturated): the samples kept, the velocity over them "
                    "taken as unknown by the filter"
                )
            else:
                what = "the gyro's range exceeded (saturated): the attitude through them is wrong"
            out.append(
                Finding(
                    "imu",
                    "saturation",
                    "warning",
                    f"imu: {name} {axis} held at {vals} {si} (declared {unit}) on {int(m.sum())} samples in "
                    f"{starts.size} runs{first}: {what}",
                    float(m.sum()),
                )
            )
    return sat, out


def repair_imu_glitches(f, w, accel_unit="m/s^2", gyro_unit="rad/s"):
    """Single-sample glitches of the IMU replaced by the mean of their two neighbours, in place.

    A 2 m/s^2 reading on 0.05 % of the samples of a 50 Hz vertical accelerometer put 120-170 mGal
    of error into the estimate (quick U214 and U001 of the unseen suite): each is a velocity
    step the filter reads as gravity.

    Parameters
    ----------
    f, w : ndarray (n, 3)
        Specific force and angular rate (as recorded; repaired in place).
    accel_unit, gyro_unit : str
        For the message.

    Returns
    -------
    list of Finding
        One warning when anything was repaired (or left because there was too much of it).
    """
    out = []
    n = f.shape[0]
    fixed = {}
    for name, arr, unit in (("specific_force", f, accel_unit), ("angular_rate", w, gyro_unit)):
        for j, axis in enumerate("xyz"):
            k = single_sample_outliers(arr[:, j], IMU_SPIKE_K, IMU_SPIKE_TAIL)
            if k.size == 0:
                continue
            if k.size > IMU_SPIKE_MAX_FRACTION * n:
                out.append(
                    Finding(
                        "imu",
                        "glitches",
                        "info",
                        f"imu: {name} {axis}: {k.size} samples off both neighbours (over "
                        f"{IMU_SPIKE_MAX_FRACTION:.1%} of {n}): not repaired, a noisy axis rather than glitches",
                        float(k.size),
                    )
                )
                continue
            jump = np.abs(arr[k, j] - 0.5 * (arr[k - 1, j] + arr[k + 1, j]))
            arr[k, j] = 0.5 * (arr[k - 1, j] + arr[k + 1, j])
            fixed[f"{name} {axis}"] = (k.size, float(jump.max()), unit)
    if fixed:
        listed = ", ".join(f"{c} on {key} (up to {m:.3g} {u})" for key, (c, m, u) in fixed.items())
        total = sum(c for c, _, _ in fixed.values())
        out.append(
            Finding(
                "imu",
                "glitches",
                "warning",
                f"imu: {total} single-sample glitch(es) replaced by the mean of their neighbours: {listed}",
                float(total),
            )
        )
    return out


#: A median offset of a height channel from the GNSS heights beyond this is a warning, m (1.5 mGal
#: of normal gravity; the simulated flights, the same height measured twice, differ by < 0.1 m).
HEIGHT_OFFSET_WARN_M = 5.0
#: The spread (5-95 %) of the height channel less the GNSS heights above which the two are not
#: the same height with an offset (a barometric altitude, a height above ground, a drifting
#: sensor, a GNSS height that jumps): a warning above the first, an error above the second
#: (0.3086 mGal of level per metre; code-grade GNSS heights of 3 m noise spread over 10 m).
HEIGHT_SPREAD_WARN_M = 12.0
HEIGHT_SPREAD_ERROR_M = 20.0


def check_height(channel, h, unit="m", ref=None):
    """Altimeter/GNSS height inside ``HEIGHT_OK``; with ``ref`` (GNSS heights on the same
    times) a ratio of ~3.28 means feet declared as metres."""
    out = []
    if len(h) == 0:
        return out
    lo, hi = float(np.min(h)), float(np.max(h))
    if lo < HEIGHT_OK[0] or hi > HEIGHT_OK[1]:
        out.append(
            Finding(
                channel,
                "height range",
                "error",
                f"{channel}: heights {lo:.6g}..{hi:.6g} m (after converting from "
                f"{unit}) outside {HEIGHT_OK[0]:g}..{HEIGHT_OK[1]:g} m: wrong unit "
                "or not an ellipsoidal height?",
                hi,
            )
        )
    else:
        out.append(Finding(channel, "height range", "ok", f"{channel}: heights {lo:.6g}..{hi:.6g} m", hi))
    if ref is not None and len(ref) == len(h) and len(h) > 0:
        sel = np.abs(ref) > 100.0
        if sel.sum() > 10:
            r = float(np.median(h[sel] / ref[sel]))
            name = _ratio_name(
                r,
                [
                    ("feet declared as metres", 1 / 0.3048),
                    ("metres declared as feet", 0.3048),
                    ("kilometres declared as metres", 1e-3),
                    ("metres declared as kilometres", 1e3),
                ],
            )
            diff = h - ref
            p5, p95 = (float(x) for x in np.percentile(diff, [5.0, 95.0]))
            if name:
                out.append(
                    Finding(
                        channel,
                        "height vs GNSS",
                        "error",
                        f"{channel}: heights are {r:.4g} x the GNSS heights: {name}?",
                        r,
                    )
                )
            elif p95 - p5 > HEIGHT_SPREAD_WARN_M:
                # not an offset: the level error follows the difference along the flight
                out.append(
                    Finding(
                        channel,
                        "height vs GNSS",
                        "error" if p95 - p5 > HEIGHT_SPREAD_ERROR_M else "warning",
                        f"{channel}: heights differ from the GNSS heights by {float(np.median(diff)):+.3g} m "
                        f"(median), varying over {p5:+.3g}..{p95:+.3g} m (5-95 %): not one height with an offset - "
                        "a barometric altitude, a height above ground, a drifting sensor or GNSS heights that "
                        f"jump? Expected ellipsoidal heights of the IMU; {p95 - p5:.3g} m is "
                        f"{(p95 - p5) * 0.3086:.2g} mGal of level",
                        p95 - p5,
                    )
                )
            else:
                d = float(np.median(np.abs(h - ref)))
                off = float(np.median(h - ref))
                if abs(off) >= HEIGHT_OFFSET_WARN_M:
                    # a constant offset: normal gravity is taken at this channel's height, so the
                    # product's level moves by 0.3086 mGal per metre, and a filter holding both
                    # heights sees a conflict it cannot resolve
                    out.append(
                        Finding(
                            channel,
                            "height vs GNSS",
                            "warning",
                            f"{channel}: heights are {off:+.3g} m from the GNSS heights (median): heights above sea "
                            "level (the geoid) against ellipsoidal ones, a barometric altitude, or an antenna offset? "
                            f"Expected ellipsoidal heights of the IMU; {abs(off):.3g} m is "
                            f"{abs(off) * 0.3086:.2g} mGal of level",
                            off,
                        )
                    )
                else:
                    lvl = "ok" if d < 100.0 else "warning"
                    out.append(
                        Finding(
                            channel, "height vs GNSS", lvl, f"{channel}: median |height - GNSS height| {d:.3g} m", d
                        )
                    )
    return out


def check_gnss(lat_deg, lon_deg):
    """Latitude in [-90, 90] deg, longitude in [-180, 360] deg."""
    if len(lat_deg) == 0:
        return []
    if np.any(np.abs(lat_deg) > 90) or np.any(lon_deg < -180) or np.any(lon_deg > 360):
        return [
            Finding(
                "gnss",
                "lat/lon range",
                "error",
                f"gnss: latitude {np.min(lat_deg):.6g}..{np.max(lat_deg):.6g}, longitude "
                f"{np.min(lon_deg):.6g}..{np.max(lon_deg):.6g}: expected degrees in "
                "[-90, 90] and [-180, 360]",
            )
        ]
    return [Finding("gnss", "lat/lon range", "ok", "gnss: latitude/longitude in range")]


#: A frozen channel: a run of at least this many samples that repeat their predecessor in every
#: value, by role (a GNSS that holds its last fix: one held epoch at 80 m/s is a 16-m jump of the
#: track at 5 Hz; a logger that repeats a stale IMU message: a few repeats are a duplicated
#: message, harmless).
FROZEN_MIN_REPEATS = {"gnss": 1, "imu": 3}
#: ... while the GNSS track moves at least this fast over the run, m/s: a vehicle at rest may
#: repeat a reading by nature (a noiseless or quantised sensor), and a held reading at rest is
#: no error.
FROZEN_MOVING_MPS = 1.0
#: ... and (GNSS) by more than this many steps of the positions' recorded resolution over the held
#: time: a CSV written with coarse digits repeats positions while crawling.
FROZEN_QUANTA = 3.0
#: Metres per degree of latitude (the positions' written resolution in metres, roughly).
M_PER_DEG = 111_320.0


def repeat_runs(values) -> list:
    """Runs of rows equal to their predecessor in every column.

    Parameters
    ----------
    values : ndarray, shape (n, k)

    Returns
    -------
    list of (int, int)
        ``(a, b)``: rows ``a + 1 .. b`` repeat row ``a``.
    """
    v = np.asarray(values, float)
    if v.ndim == 1:
        v = v[:, None]
    if v.shape[0] < 2:
        return []
    same = np.all(v[1:] == v[:-1], axis=1)
    edge = np.diff(np.concatenate([[0], same.astype(np.int8), [0]]))
    return [(int(a), int(b)) for a, b in zip(np.flatnonzero(edge == 1), np.flatnonzero(edge == -1))]


def _resolution(x) -> float:
    """The recorded resolution of ``x``: the largest power of ten that every value is a whole
    multiple of (a CSV written with 5 decimals: 1e-5), 0 at full precision."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    for k in range(2, -10, -1):
        q = 10.0**k
        # within the rounding of a decimal written to float64
        tol = 1e-9 + 8.0 * np.finfo(float).eps * np.abs(x) / q
        if x.size and np.all(np.abs(x / q - np.round(x / q)) <= tol):
            return q
    return 0.0


def frozen_gnss(time_ns, lat_deg, lon_deg, height) -> np.ndarray:
    """GNSS epochs that hold the previous fix while the track moves (a receiver or logger
    repeating its last position), to drop.

    A run of repeated positions (latitude, longitude and height all equal to the previous
    epoch) is frozen when the track between the epoch it repeats and the first epoch after it
    moves at least :data:`FROZEN_MOVING_MPS` and by more than :data:`FROZEN_QUANTA` of the
    positions' recorded resolution over the held time. Kept, 5 s of held fixes on a strapdown
    flight at 80 m/s tripled the error (2.2 -> 6.3 mGal, exit 0) and 60 s failed the flight.

    Parameters
    ----------
    time_ns : ndarray of int, shape (n,)
        Increasing.
    lat_deg, lon_deg, height : ndarray, shape (n,)

    Returns
    -------
    ndarray of int
        Indices of the held epochs.
    """
    runs = repeat_runs(np.stack([lat_deg, lon_deg, height], axis=1))
    if not runs:
        return np.zeros(0, np.int64)
    t = (np.asarray(time_ns) - time_ns[0]) * 1e-9
    lat, lon = np.radians(np.asarray(lat_deg, float)), np.radians(np.asarray(lon_deg, float))
    q = max(_resolution(lat_deg), _resolution(lon_deg)) * M_PER_DEG
    out = []
    for a, b in runs:
        if b - a < FROZEN_MIN_REPEATS["gnss"] or b + 1 >= len(t):
            continue
        dist = float(np.hypot(*local_displacement(lat[a], lon[a], lat[b + 1], lon[b + 1])))
        v = dist / (t[b + 1] - t[a])
        if v >= FROZEN_MOVING_MPS and v * (t[b] - t[a]) > FROZEN_QUANTA * q:
            out.append(np.arange(a + 1, b + 1))
    return np.concatenate(out).astype(np.int64) if out else np.zeros(0, np.int64)


def frozen_imu(time_ns, f, w, gnss_time_ns=None, lat_deg=None, lon_deg=None) -> np.ndarray:
    """IMU samples that repeat the previous one in all six values while the GNSS track moves (a
    logger writing a stale message), to drop: the gap they leave splits the flight, where the held
    values would be integrated as a real motion (5 s of them failed a strapdown flight at 80 m/s
    with 4918 mGal).

    A run needs at least ``FROZEN_MIN_REPEATS["imu"]`` repeats, and the GNSS track over the run
    (0.5 s either side) a speed of at least :data:`FROZEN_MOVING_MPS`; without a GNSS track
    nothing is dropped (a vehicle at rest may repeat a quantised or noiseless reading by nature).

    Parameters
    ----------
    time_ns : ndarray of int, shape (n,)
    f, w : ndarray, shape (n, 3)
        Specific force and angular rate (any unit).
    gnss_time_ns, lat_deg, lon_deg : ndarray, shape (m,), optional

    Returns
    -------
    ndarray of int
    """
    if gnss_time_ns is None or len(gnss_time_ns) < 2:
        return np.zeros(0, np.int64)
    runs = [(a, b) for a, b in repeat_runs(np.hstack([f, w])) if b - a >= FROZEN_MIN_REPEATS["imu"]]
    if not runs:
        return np.zeros(0, np.int64)
    ref = int(gnss_time_ns[0])
    tg = (np.asarray(gnss_time_ns) - ref) * 1e-9
    lat, lon = np.radians(np.asarray(lat_deg, float)), np.unwrap(np.radians(np.asarray(lon_deg, float)))
    out = []
    for a, b in runs:
        ta, tb = (int(time_ns[a]) - ref) * 1e-9 - 0.5, (int(time_ns[b]) - ref) * 1e-9 + 0.5
        if ta < tg[0] or tb > tg[-1]:
            continue
        de, dn = local_displacement(
            np.interp(ta, tg, lat), np.interp(ta, tg, lon), np.interp(tb, tg, lat), np.interp(tb, tg, lon)
        )
        if math.hypot(de, dn) / (tb - ta) >= FROZEN_MOVING_MPS:
            out.append(np.arange(a + 1, b + 1))
    return np.concatenate(out).astype(np.int64) if out else np.zeros(0, np.int64)


def frozen_finding(channel, source, time_ns, idx, what):
    """A warning for dropped frozen samples ``idx`` (:func:`frozen_gnss`, :func:`frozen_imu`)."""
    from gravsurvey.utc import utc_iso

    t = np.asarray(time_ns)
    brk = np.flatnonzero(np.diff(idx) > 1)
    starts = np.concatenate([[0], brk + 1])
    stops = np.concatenate([brk, [len(idx) - 1]])
    # a run's duration reaches back to the sample it repeats
    dur = [(int(t[idx[j]]) - int(t[idx[i] - 1])) * 1e-9 for i, j in zip(starts, stops)]
    k = int(np.argmax(dur))
    return Finding(
        channel,
        "frozen",
        "warning",
        f"{channel} ({source}): dropped {len(idx)} sample(s) in {len(starts)} run(s) that repeat {what} while the "
        f"GNSS track moves (a stalled receiver or logger), longest {dur[k]:.3g} s from "
        f"{utc_iso(int(t[idx[starts[k]] - 1]), 1)}: left as gaps",
        float(len(idx)),
    )


def check_epoch(channel, time_ns):
    """Warn when stamps are before 2000 (simulation clock or unset time?)."""
    if len(time_ns) and time_ns[0] < 946684800 * 10**9:
        return [
            Finding(
                channel,
                "epoch",
                "warning",
                f"{channel}: time stamps start at {time_ns[0] * 1e-9:.3f} s after "
                "1970-01-01, before 2000: simulation clock or unset time?",
            )
        ]
    return []


# ----------------------------------------------------------------------------- damage checks
# Values read without a chunk CRC (unchunked files, chunks with CRC 0, check_crc: false) can
# carry flipped bits.  A flipped exponent bit multiplies a float64 by 2**(+-2**k) and a flipped
# time-stamp bit moves a sample by 2**k ns; these checks catch such isolated corruptions and
# leave real signals alone: a sample is dropped only when it disagrees with BOTH neighbours
# while the neighbours agree with each other (a clock restart or a gap is a step, not a spike).
DAMAGE_ABS_MAX = 1e9  # |value| above this is no measurement in any supported unit
DAMAGE_SPIKE_K = 1000.0  # spike > this x the channel's median |second difference| ...
DAMAGE_SPIKE_REL = 0.25  # ... and > this fraction of the neighbours' magnitude
DAMAGE_SPIKE_NEIGHBOURS = 4.0  # ... and > this x the neighbours' own difference
DAMAGE_TIME_K = 50.0  # time-offset spike > this x the median |step| of (time - log time) ...
DAMAGE_TIME_STEP_FRACTION = 0.5  # ... and > this fraction of the nominal sample step
DAMAGE_MAX_FRACTION = 0.01  # a spike test flagging more than 1 % of samples is not bit damage
DAMAGE_RUN_MAX = 64  # longest run of corrupted samples between a jump and the jump back


def _isolated_spikes(x, k_scale, floor):
    """Interior samples of ``x`` (n,) that jump away from both neighbours while the neighbours
    agree: |x[k] - mean(x[k-1], x[k+1])| above ``k_scale`` x its median over the series, above
    ``floor`` (n,) and above DAMAGE_SPIKE_NEIGHBOURS x |x[k+1] - x[k-1]|."""
    n = len(x)
    out = np.zeros(n, bool)
    if n < 3:
        return out
    with np.errstate(invalid="ignore", over="ignore"):
        e = np.abs(x[1:-1] - 0.5 * (x[:-2] + x[2:]))
        c = np.abs(x[2:] - x[:-2])
        fin = np.isfinite(e)
        if not fin.any():
            return out
        s = float(np.median(e[fin]))
        out[1:-1] = fin & (e > k_scale * s) & (e > floor[1:-1]) & (e > DAMAGE_SPIKE_NEIGHBOURS * c)
    return out


def _corrupted_runs(x, k_scale, rel, max_len):
    """Runs of up to ``max_len`` samples of ``x`` (n,) entered and left by a jump (> ``k_scale``
    x the median |step| and > ``rel`` x the level) after which the series returns to the level
    before the run (within ``rel`` x the jump): a corrupted stretch of a decompressed block, not
    a signal (a real level change does not come back).

    Returns
    -------
    mask : ndarray of bool, shape (n,)
    runs : int
        Number of runs found.
    """
    n = len(x)
    out = np.zeros(n, bool)
    if n < 3:
        return out, 0
    with np.errstate(invalid="ignore", over="ignore"):
        dx = np.diff(x)
        fin = np.isfinite(dx)
        if not fin.any():
            return out, 0
        s = float(np.median(np.abs(dx[fin])))
        level = np.maximum(np.abs(x[:-1]), np.abs(x[1:]))
        big = np.flatnonzero(fin & (np.abs(dx) > k_scale * s) & (np.abs(dx) > rel * level))
    a, runs = 0, 0
    while a + 1 < len(big):
        i, j = int(big[a]), int(big[a + 1])
        if j - i <= max_len and abs(x[j + 1] - x[i]) < rel * abs(dx[i]):
            out[i + 1 : j + 1] = True
            runs += 1
            a += 2
        else:
            a += 1
    return out, runs


def damaged_values(role, time_ns, log_time_ns, values, candidates):
    """Samples that show the marks of corrupted bytes, among ``candidates``.

    Checks: non-finite or absurd (> ``DAMAGE_ABS_MAX``) values; latitude/longitude outside
    [-90, 90] / [-180, 360] degrees; a measurement time out of order with both neighbours
    while they are in order (at the ends: with its one neighbour); a spike in (time - log
    time), at the ends too; an isolated value spike (see the ``DAMAGE_SPIKE_*`` constants);
    a run of up to ``DAMAGE_RUN_MAX`` samples entered by such a jump and left by one back to
    the level before it.  A spike test that flags more than ``DAMAGE_MAX_FRACTION``
    of the samples is ignored (that is a property of the signal, left to the plausibility
    checks).

    Parameters
    ----------
    role : str
        ``imu``, ``altimeter`` or ``gnss``.
    time_ns, log_time_ns : ndarray of int64, shape (n,)
        Measurement and MCAP log times, file order.
    values : dict of ndarray, each shape (n,) or (n, 3)
        Decoded values (units as recorded).
    candidates : ndarray of bool, shape (n,)
        Samples that may be dropped (those not protected by a CRC).

    Returns
    -------
    bad : ndarray of bool, shape (n,)
    why : str
        Counts per check, e.g. ``"2 non-finite/absurd, 1 time out of order"``.
    """
    n = len(time_ns)
    cand = np.asarray(candidates, bool)
    counts = {}
    bad = np.zeros(n, bool)

    def add(name, mask, guarded):
        mask = mask & cand & ~bad
        if guarded and mask.sum() > DAMAGE_MAX_FRACTION * n:
            return
        if mask.any():
            counts[name] = counts.get(name, 0) + int(mask.sum())
            bad[:] |= mask

    cols = []
    for k, v in values.items():
        v2 = np.asarray(v, np.float64).reshape(n, -1)
        with np.errstate(invalid="ignore"):
            add("non-finite/absurd", ~np.isfinite(v2).all(axis=1) | (np.abs(v2) > DAMAGE_ABS_MAX).any(axis=1), False)
        if k == "lat_deg":
            add("latitude out of range", (np.abs(v2[:, 0]) > 90.0), True)
        elif k == "lon_deg":
            add("longitude out of range", (v2[:, 0] < -180.0) | (v2[:, 0] > 360.0), True)
        cols += [v2[:, j] for j in range(v2.shape[1])]
    if n >= 3:
        t = np.asarray(time_ns, np.int64)
        prev, nxt = t[:-2], t[2:]
        mid = t[1:-1]
        ooo = np.zeros(n, bool)
        ooo[1:-1] = (prev <= nxt) & ((mid < prev) | (mid > nxt))
        ooo[0] = t[0] > t[1] and t[1] <= t[2]
        ooo[-1] = t[-1] < t[-2] and t[-3] <= t[-2]
        add("time out of order", ooo, True)
        steps = np.diff(t)
        pos = steps[steps > 0]
        nominal = float(np.median(pos)) if len(pos) else 0.0
        d = t.astype(np.float64) - np.asarray(log_time_ns, np.int64).astype(np.float64)
        dd = np.abs(np.diff(d))
        scale = float(np.median(dd)) if len(dd) else 0.0
        tol = max(DAMAGE_TIME_K * scale, DAMAGE_TIME_STEP_FRACTION * nominal)
        spike = np.zeros(n, bool)
        spike[1:-1] = (dd[:-1] > tol) & (dd[1:] > tol) & (np.abs(d[2:] - d[:-2]) <= tol)
        # the first and last samples have one neighbour: off from it while the next pair agrees
        spike[0] = dd[0] > tol and dd[1] <= tol
        spike[-1] = dd[-1] > tol and dd[-2] <= tol
        add("time/log-time spike", spike, True)
        for x in cols:
            with np.errstate(invalid="ignore", over="ignore"):
                mag = DAMAGE_SPIKE_REL * 0.5 * (np.abs(np.roll(x, 1)) + np.abs(np.roll(x, -1)))
            add("value spike", _isolated_spikes(x, DAMAGE_SPIKE_K, mag), True)
            runs, nruns = _corrupted_runs(x, DAMAGE_SPIKE_K, DAMAGE_SPIKE_REL, DAMAGE_RUN_MAX)
            # the 1 % limit counts runs here, not samples: one corrupted block is one event
            if nruns <= max(1.0, DAMAGE_MAX_FRACTION * n):
                add("corrupted run", runs, False)
    return bad, ", ".join(f"{v} {k}" for k, v in counts.items())
