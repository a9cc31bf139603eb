"""Gaps, clocks, input consistency and result plausibility of one flight (issue 14).

Free functions over arrays. Each either returns findings (one-line strings for the flight's
notes) or raises :class:`~gravsurvey.errors.DataError` naming the channel, file and column.
``pipeline._process_flight`` calls them in this order:

1. :func:`check_overlap` - channels that do not overlap in time (a clock out of step, stamps
   in another unit), and :func:`check_platform_axes` - a platform triad's up axis and level.
2. :func:`check_gnss_consistency` - GNSS track against the IMU: speed plausibility, the
   specific-force magnitude the GNSS kinematics imply vs the one the IMU measures (catches
   lat/lon swapped, radians declared as degrees, a wrong height unit), and the IMU-GNSS time
   offset by cross-correlating the two (:func:`estimate_time_offset`).
3. Against the track once it has passed: :func:`check_platform_gyros` (a platform's gyros follow
   the Earth's and the transport rate), :func:`check_strapdown_axes` (a strapdown IMU's
   columns: no negated or swapped axis, nor a coordinate of the wrong sign, fits better) and
   :func:`correct_imu_scale` (an axis's scale-factor error divided out; a platform's horizontal
   accelerometers too).
4. :func:`plan_segments` - the flight is split at IMU gaps longer than
   ``CheckOptions.max_imu_gap_s`` and at gaps of all vertical aiding (altimeter and GNSS)
   longer than ``max_aiding_gap_s``; each segment is estimated on its own
   (:func:`gravsurvey.io.record.slice_record`) and the results concatenated with a NaN epoch
   between segments (:func:`gravsurvey.estimate.concatenate_estimates`).
5. :func:`check_result` - the final product: non-finite values, |disturbance| beyond a
   limit, a navigation that left the GNSS track, no survey lines.

Clock restarts (a channel's time going back) are found on the raw int64 stamps before the
time base is repaired (:func:`drop_clock_restarts`, called by ``io.ingest.load_flight``): a
restarted IMU block is placed in time by cross-correlation with GNSS when that is unique
(:func:`place_by_gnss`), else dropped and reported as data loss.

Limits and their derivation: docs/reliability.md, "Gaps, clocks, consistency".
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from .errors import DataError, GravsurveyError
from .geodesy import MGAL, STANDARD_GRAVITY_MPS2, WGS84, geodetic_to_ecef, mat_en, mat_ie, normal_gravity_ecef
from .utc import utc_after

#: Fastest plausible ground speed of a survey aircraft or ship, m/s (a jet at cruise is
#: ~250 m/s; survey aircraft fly 50-120 m/s).
MAX_GROUND_SPEED_MPS = 350.0
#: Window of the GNSS kinematics (position smoothing and differencing), s: long enough that
#: 1 m GNSS noise gives < 0.01 m/s^2 acceleration noise (sigma sqrt(6) / (W^2 sqrt(W))).
KINEMATIC_WINDOW_S = 10.0
#: Window of the GNSS kinematics for the gravity-consistency check, s: 1.5 m vertical GNSS
#: noise gives ~70 mGal per estimate at 30 s (~1200 mGal at 10 s); the median over a flight
#: then resolves a few tens of mGal.
GRAVITY_WINDOW_S = 30.0
#: Epochs of the running median of the navigation's distance from the GNSS track (31 s at 1 Hz).
TRACK_WINDOW = 31
#: A gravity mismatch beyond this many times ``checks.max_gravity_mismatch_mgal`` fails the
#: flight even when no column mix-up explains it (below: a note; the IMU may be the cause).
GROSS_MISMATCH_FACTOR = 5.0
#: Within the tolerated mismatch, one of at least this (mGal) that a height unit mix-up
#: (metres <-> feet) takes to under UNIT_HINT_FRACTION of it is a warning naming it: heights in
#: metres declared as feet at 1500 m move normal gravity by 322 mGal, under the 500-mGal limit
#: that holds an accelerometer's bias (fuzzing, 2026-12-04: exit 0 at 2.8x the error, silent).
UNIT_HINT_MIN_MGAL = 100.0
UNIT_HINT_FRACTION = 0.25
#: Least correlation with GNSS that places a restarted IMU block in time.
PLACE_MIN_CORRELATION = 0.8
#: Shortest segment worth estimating, s (the GNSS initialisation fits 10 s; the smoother
#: needs a few of the anomaly's correlation times to settle).
MIN_SEGMENT_S = 60.0
#: Initial velocity 1-sigma of a segment re-initialised from GNSS in flight, m/s: the 10 s
#: quadratic fit of ``initial_state_from_gnss`` evaluated at the segment's first sample has a
#: velocity error of a few tenths of a m/s with 1 m GNSS noise (docs/reliability.md).
REINIT_VELOCITY_SIGMA_MPS = 0.5
#: Least correlation of IMU and GNSS specific force that counts as a measured time offset.
MIN_OFFSET_CORRELATION = 0.5
#: Least standard deviation of the GNSS-derived specific force (m/s^2) for the offset search:
#: without manoeuvres there is nothing to correlate.
MIN_OFFSET_SIGNAL_MPS2 = 0.02

#: Correlation an IMU-GNSS offset estimate needs before an offset beyond the limit fails a flight.
OFFSET_VERDICT_CORRELATION = 0.9
#: ... and how much better its lag must fit than any lag within the limit
#: (:func:`time_offset_evidence`, ~ a squared number of standard errors): a flat correlation
#: curve puts its peak anywhere (0.51 s on a flight with no offset, statistic 0.0); offsets of
#: 2 s score 100-300 on flights that manoeuvre, 0.8 s 6-14.
OFFSET_VERDICT_EVIDENCE = 9.0
#: Below this evidence the best lag is no better than the lags within the limit: the data show
#: no offset, and a latency within a second is measured precisely on the aided track
#: (:mod:`gravsurvey.inm.gnssqc`): a note, not a warning.  Exact clocks, quick U1434 -1.09 s (r =
#: 0.90, evidence 0.29), U005 -0.63 s (0.81, 0.01), U602 +0.51 s (0.91, 0.00); their GNSS 2 s
#: late: 5.0, 2.0 and 1.1, warned.
OFFSET_NOTE_EVIDENCE = 1.0

#: An IMU covering less than this share of an aiding channel's time span is said in a note (its
#: stamps at a wrong rate or in other units - a log at 10 Hz stamped at 20 Hz spans half the
#: GNSS's - or its log cut short).
IMU_COVER_FRACTION = 0.8

#: Prefix of a note that records a check passed (a fact for summary.json, not a warning).
PASSED = "passed: "


@dataclass
class CheckOptions:
    """Settings of the consistency and plausibility checks (config section ``checks``).

    Attributes
    ----------
    max_imu_gap_s : float
        IMU gaps up to this long are bridged by the mechanization (it interpolates the
        specific force across); longer ones split the flight into segments, s.
    max_aiding_gap_s : float
        Gaps with neither altimeter nor GNSS samples up to this long are bridged by the free
        INS and the Markov model (the smoothed sigma grows across them); longer ones split the
        flight, s.
    max_time_offset_s : float
        Largest tolerated IMU-GNSS clock offset found by cross-correlation, s.
    max_gravity_mismatch_mgal : float
        Largest tolerated median difference between the specific-force magnitude the IMU
        measures and the one the GNSS kinematics and normal gravity imply, mGal (accelerometer
        bias + anomaly; a wrong latitude or height unit gives thousands).
    max_abs_disturbance_mgal : float
        Largest plausible |gravity disturbance| of the final product, mGal.
    max_track_deviation_m : float
        Largest distance of the GNSS-aided navigation from the GNSS track (running median over
        ``TRACK_WINDOW`` epochs), m.
    allow_no_lines, allow_nonfinite : bool
        Accept a flight without survey lines / with non-finite values in the product.
    """

    max_imu_gap_s: float = 2.0
    max_aiding_gap_s: float = 120.0
    max_time_offset_s: float = 0.5
    max_gravity_mismatch_mgal: float = 500.0
    max_abs_disturbance_mgal: float = 1000.0
    max_track_deviation_m: float = 50.0
    allow_no_lines: bool = False
    allow_nonfinite: bool = False


# ----------------------------------------------------------------------------- helpers
def span_text(t0_unix_ns: int, a: float, b: float) -> str:
    """A time range as UTC text with its length."""
    return f"{utc_after(t0_unix_ns, a)}..{utc_after(t0_unix_ns, b)} ({b - a:.1f} s)"


@dataclass
class ChannelNames:
    """Where a flight's channels come from, for messages: file and column names per role."""

    files: dict  # role -> file (or file + topic)
    columns: dict  # role -> {quantity: column or field name}
    section: str = "csv"  # the flight's input section: "csv" or "mcap" (its `units` keys)

    def column(self, role: str, *quantities: str) -> str:
        """``"<file> column <name>"`` (``columns <a>, <b>``) for a role's quantities."""
        cols = [str(self.columns.get(role, {}).get(q, q)) for q in quantities]
        word = "column" if len(cols) == 1 else "columns"
        return f"{self.files.get(role, role)} {word} {', '.join(cols)}"


def channel_names(ingest, base_dir=None) -> ChannelNames:
    """File and column names of each role from a flight's ingest options (IngestOptions)."""
    from .io.csv import DEFAULT_COLUMNS

    files, cols = {}, {}
    if getattr(ingest, "kind", "csv") == "csv":
        # input_paths lists the CSVs in imu, altimeter, gnss order (those given)
        roles = [r for r in ("imu", "altimeter", "gnss") if r in ingest.csv_paths]
        for role, path in zip(roles, ingest.input_paths(base_dir)):
            files[role] = str(path)
            cols[role] = {**DEFAULT_COLUMNS.get(role, {}), **ingest.csv_columns.get(role, {})}
            if {"x", "y", "z"} <= set(cols[role]):
                # positions read as ECEF X, Y, Z: every geodetic quantity comes from all three
                xyz = f"{cols[role]['x']}/{cols[role]['y']}/{cols[role]['z']} (ECEF)"
                cols[role].update({q: xyz for q in ("lat", "lon", "height")})
    else:
        for role, topic in ingest.topics.items():
            files[role] = f"{ingest.mcap_path} topic {topic}"
            cols[role] = {
                k: (v if isinstance(v, str) else "/".join(v)) for k, v in ingest.json_fields.get(role, {}).items()
            }
    return ChannelNames(files, cols, "csv" if getattr(ingest, "kind", "csv") == "csv" else "mcap")


def channel_spans(record) -> dict:
    """First and last sample time (s after ``record.t0_unix_ns``) of each channel present."""
    out = {"imu": (float(record.imu.time[0]), float(record.imu.time[-1]))}
    if record.altimeter is not None and len(record.altimeter.time):
        out["altimeter"] = (float(record.altimeter.time[0]), float(record.altimeter.time[-1]))
    if record.gnss is not None and len(record.gnss.time):
        out["gnss"] = (float(record.gnss.time[0]), float(record.gnss.time[-1]))
    return out


# ----------------------------------------------------------------------------- clocks
def find_clock_restarts(time_ns, min_jump_s: float = 1.0):
    """Clock restarts in a channel's raw stamps (file order): backward jumps that re-sorting
    would interleave with earlier samples.

    The stamps are cut into runs at every step longer than ``min_jump_s`` (backward, or forward:
    a gap). A run that starts with a backward step is a restart when its time range overlaps
    samples kept before it (re-sorting would interleave two clocks); a block written out of order
    that fills a hole is not. After a restart the channel's time base is unknown: later runs are
    dropped too, until one starts with a forward step to after the last trusted stamp (the clock
    is back in step). Sub-second backward steps (message jitter) are left to the time repair.

    Parameters
    ----------
    time_ns : ndarray of int64, shape (n,)
        Stamps in file order, ns.
    min_jump_s : float
        Backward steps shorter than this are jitter, s.

    Returns
    -------
    keep : ndarray of bool, shape (n,)
        False for the samples whose time is unknown.
    events : list of tuple
        ``(index, t_before_ns, t_after_ns, n_dropped)`` per restart.
    """
    t = np.asarray(time_ns, dtype=np.int64)
    keep = np.ones(len(t), bool)
    events = []
    if len(t) < 3:
        return keep, events
    jump = int(min_jump_s * 1e9)
    d = np.diff(t)
    if not np.any(d < -jump):
        return keep, events
    cuts = np.flatnonzero((d < -jump) | (d > jump)) + 1
    starts = np.concatenate([[0], cuts])
    ends = np.concatenate([cuts, [len(t)]])
    kept = np.sort(t[: ends[0]])  # the first run is trusted
    t_max = int(kept[-1])
    synced = True
    for a, b in zip(starts[1:], ends[1:]):
        run = t[a:b]
        backward = t[a] < t[a - 1]
        if synced and backward:
            lo, hi = int(run.min()), int(run.max())
            inside = np.searchsorted(kept, hi, side="right") - np.searchsorted(kept, lo, side="left")
            if inside > 0:
                synced = False
                keep[a:b] = False
                events.append([int(a), int(t[a - 1]), int(t[a]), int(b - a)])
                continue
        elif not synced:
            if backward or t[a] <= t_max:
                keep[a:b] = False
                events[-1][3] += int(b - a)
                continue
            synced = True
        kept = np.sort(np.concatenate([kept, run]))
        t_max = max(t_max, int(run.max()))
    return keep, [tuple(e) for e in events]


def clock_restart_messages(role: str, source: str, t0_ns: int, events) -> list[str]:
    """One line per restart: channel, file, where the clock jumped and what was dropped."""
    out = []
    for j, tb, ta, n in events:
        out.append(
            f"{role}: clock restart in {source} at sample {j}: time went back from "
            f"{utc_after(t0_ns, (tb - t0_ns) / 1e9)} to {utc_after(t0_ns, (ta - t0_ns) / 1e9)} "
            f"({(tb - ta) / 1e9:.1f} s back); {n} samples from the restart on dropped (their time "
            "is unknown)"
        )
    return out


def place_by_gnss(block_ns, specific_force_t, gnss, kept_ns, min_corr: float = PLACE_MIN_CORRELATION):
    """Time of a block of IMU samples with an unknown clock, by cross-correlation with GNSS.

    The block's smoothed |f| is correlated with the specific force the GNSS track implies
    (:func:`gnss_specific_force`) at every lag that puts the block inside the GNSS span without
    covering IMU samples already kept (a restarted clock's samples come after the restart). The
    best lag is accepted only when it correlates at least ``min_corr`` and every lag more than
    ``2 * KINEMATIC_WINDOW_S`` away correlates at least 0.2 less (a unique match); it is refined
    to ~0.05 s as in :func:`estimate_time_offset`.

    Parameters
    ----------
    block_ns : ndarray of int64, shape (n,)
        The block's stamps (strictly increasing, unknown origin), ns.
    specific_force_t : ndarray, shape (n, 3)
        m/s^2.
    gnss : object
        ``time_ns`` (int64) and ``values`` with ``lat_deg``, ``lon_deg``, ``height`` (a raw
        ingest channel).
    kept_ns : ndarray of int64
        Stamps of the IMU samples already trusted, ns.

    Returns
    -------
    shift_ns : int or None
        Add to ``block_ns`` to get the block's times; None when no unique match.
    corr : float
        Correlation at the best lag (NaN when there was nothing to correlate).
    """
    nan = float("nan")
    g_ns = np.asarray(gnss.time_ns, np.int64)
    b_ns = np.asarray(block_ns, np.int64)
    if len(g_ns) < 30 or len(b_ns) < 30:
        return None, nan
    ref = int(g_ns[0])
    gt = (g_ns - ref) / 1e9
    tm, fg, _ = gnss_specific_force(
        gt, np.radians(gnss.values["lat_deg"]), np.radians(gnss.values["lon_deg"]), gnss.values["height"]
    )
    good = np.isfinite(fg)
    tm, fg = tm[good], fg[good]
    dt = float(np.median(np.diff(gt)))
    tb = (b_ns - b_ns[0]) / 1e9
    if len(tm) < 30 or tb[-1] < 3 * KINEMATIC_WINDOW_S:
        return None, nan
    ts, sm = smooth_imu(tb, np.linalg.norm(np.asarray(specific_force_t, float), axis=1), None, dt)
    ok = np.isfinite(sm)
    ts, sm = ts[ok], sm[ok]
    if len(ts) < 30 or np.std(sm) < MIN_OFFSET_SIGNAL_MPS2:
        return None, nan
    kept = np.sort((np.asarray(kept_ns, np.int64) - ref) / 1e9)

    def corr(lag):
        lo, hi = tb[0] + lag, tb[-1] + lag
        inside = np.searchsorted(kept, hi, side="right") - np.searchsorted(kept, lo, side="left")
        if inside > 0.01 * len(tb):
            return -np.inf
        y = np.interp(ts + lag, tm, fg, left=np.nan, right=np.nan)
        ok = np.isfinite(y)
        if ok.sum() < 0.9 * len(y):  # the kernels trim both series' ends a little differently
            return -np.inf
        a, bb = sm[ok] - sm[ok].mean(), y[ok] - y[ok].mean()
        den = math.sqrt(float(a @ a) * float(bb @ bb))
        return float(a @ bb) / den if den > 0 else -np.inf

    pad = 0.1 * (ts[-1] - ts[0])
    lag_lo, lag_hi = tm[0] - ts[0] - pad, tm[-1] - ts[-1] + pad
    if lag_hi <= lag_lo:
        return None, nan
    coarse = np.arange(lag_lo, lag_hi + 1e-9, max(dt, 0.5))
    c = np.array([corr(x) for x in coarse])
    k = int(np.argmax(c))
    if not np.isfinite(c[k]) or c[k] < min_corr:
        return None, float(c[k]) if np.isfinite(c[k]) else nan
    far = np.abs(coarse - coarse[k]) > 2 * KINEMATIC_WINDOW_S
    if far.any() and np.max(c[far]) > c[k] - 0.2:
        return None, float(c[k])
    fine = np.arange(coarse[k] - 1.0, coarse[k] + 1.0 + 1e-9, 0.05)
    cf = np.array([corr(x) for x in fine])
    j = int(np.argmax(cf))
    best = float(fine[j])
    if 0 < j < len(fine) - 1 and np.all(np.isfinite(cf[j - 1 : j + 2])):
        d = cf[j - 1] - 2 * cf[j] + cf[j + 1]
        if d < 0:
            best += 0.025 * (cf[j - 1] - cf[j + 1]) / d
    return int(ref - b_ns[0] + round(best * 1e9)), float(cf[j])


def drop_clock_restarts(raw: dict, min_jump_s: float = 1.0):
    """Find clock restarts in raw channels; place restarted IMU blocks by GNSS or drop them.

    Samples after a restart have an unknown time (:func:`find_clock_restarts`). An IMU block that
    is one steady run can be placed by cross-correlation with GNSS (:func:`place_by_gnss`,
    when the GNSS clock did not restart itself); everything else is dropped.

    Parameters
    ----------
    raw : dict
        role -> object with ``time_ns`` (int64, file order), ``values`` (dict of arrays with
        the samples along axis 0) and ``source`` (``io.ingest.RawChannel``); changed in place.

    Returns
    -------
    notes : list of str
        Restarts whose samples were placed in time (with the shift and correlation).
    loss : list of str
        Restarts whose samples were dropped (:func:`clock_restart_messages`): data loss.
    """
    starts = [int(ch.time_ns[0]) for ch in raw.values() if len(ch.time_ns)]
    t0 = min(starts) if starts else 0
    found = {role: find_clock_restarts(ch.time_ns, min_jump_s) for role, ch in raw.items()}
    notes, loss = [], []
    for role, ch in raw.items():
        keep, events = found[role]
        if not events:
            continue
        gn = raw.get("gnss")
        drop = ~keep
        tb = ch.time_ns[drop]
        steady = len(tb) > 1 and np.all(np.diff(tb) > 0) and np.max(np.diff(tb)) <= int(min_jump_s * 1e9)
        if role == "imu" and len(events) == 1 and steady and gn is not None and not found["gnss"][1]:
            shift, c = place_by_gnss(tb, ch.values["specific_force"][drop], gn, ch.time_ns[keep])
            if shift is not None:
                ch.time_ns = ch.time_ns.copy()
                ch.time_ns[drop] = tb + shift
                j, tbf, taf, n = events[0]
                notes.append(
                    f"{role}: clock restart in {ch.source} at sample {j}: time went back from "
                    f"{utc_after(t0, (tbf - t0) / 1e9)} to {utc_after(t0, (taf - t0) / 1e9)}; the {n} samples after it "
                    f"placed at {utc_after(t0, (tb[0] + shift - t0) / 1e9)}..{utc_after(t0, (tb[-1] + shift - t0) / 1e9)} "
                    f"by cross-correlation with GNSS (r = {c:.2f})"
                )
                continue
        ch.time_ns = ch.time_ns[keep]
        ch.values = {k: v[keep] for k, v in ch.values.items()}
        loss += clock_restart_messages(role, ch.source, t0, events)
    return notes, loss


#: Range of the median third-axis specific force of a platform triad, in units of the standard
#: gravity ``geodesy.STANDARD_GRAVITY_MPS2`` (9.78 at the equator, 9.83 at the poles): the platform is held
#: level, so over a flight that axis reads gravity (vertical accelerations average out; a
#: 45-degree bank, held level by the platform, leaves it at g).  Outside, the axes are not the
#: platform's east-north-up ones (a down axis reads -1).
PLATFORM_UP_RANGE = (0.7, 1.3)
#: A platform triad held level turns about its horizontal axes at the Earth's and the transport
#: rate only (< 0.005 deg/s); an aircraft's body in a banked turn at 1-2 deg/s (10-s means of
#: the simulated strapdown flights: 1.4-1.7 deg/s).  Horizontal rates above this, deg/s ...
PLATFORM_TILT_RATE_DEGPS = 0.3
#: ... in 10-s means (gyro noise and turbulence average out) ...
PLATFORM_RATE_WINDOW_S = 10.0
#: ... for this long in total, s (one turn between lines), make the triad a body-fixed one.
PLATFORM_TILT_MIN_S = 30.0
#: A platform's gyros read the Earth's rate and the transport rate of its east-north-up frame;
#: in means over this span (s) each axis is regressed on them (the rate the GNSS track implies):
PLATFORM_RATE_BLOCK_S = 60.0
#: ... the slope must lie in this range (1 for the right axis; -1 negated; the 73 platform
#: flights of the unseen and issue suites: 0.974-1.025 on 197 axes judged) ...
PLATFORM_RATE_SLOPE_RANGE = (0.5, 1.5)
#: ... on an axis whose expected rate varies by at least this RMS, deg/h (the east axis sees
#: only the transport rate of the north velocity: 1.6 deg/h at 70 m/s), over this many spans.
PLATFORM_RATE_MIN_RMS_DEGPH = 1.0
PLATFORM_RATE_MIN_BLOCKS = 5
#: A strapdown triad's columns are judged by velocity matching (the GNSS velocity change against
#: the accelerometers resolved through the gyros, :func:`gravsurvey.inm.alignment.match_vectors`)
#: over windows of this length, s (short: a MEMS gyro's drift tilts the triad by 0.3 deg in 2 min)
STRAPDOWN_AXES_WINDOW_S = 120.0
#: ... the this many windows with the largest change of the GNSS velocity (turns and speed
#: changes carry the test), not overlapping
STRAPDOWN_AXES_WINDOWS = 6
#: ... that change at least this much, m/s (a 180-deg turn at 80 m/s: 160) ...
STRAPDOWN_AXES_MIN_DV_MPS = 20.0
#: ... in at least this many windows: a column fault (an axis negated, two swapped, one axis of
#: both sensors negated) is named when its hypothesis fits this many times better (RMS over the
#: windows). Measured on the 89 strapdown flights of the unseen suite (seeds 1-139, limited to 40
#: min and 100 Hz) and the issue's B/C flights 1-8: the nearest wrong hypothesis fits at least
#: 2.6x worse than the columns as written (ratio <= 0.38); with an accelerometer's x or y axis
#: negated its fix fits 2.6-38x better, with the gyro's z axis negated 19-430x; a 10 deg/h gyro
#: with 2-m GNSS blurs them all to 0.8-1.0 (no verdict). Noise draws every ratio towards 1.
STRAPDOWN_AXES_MIN_WINDOWS = 2
STRAPDOWN_AXES_RATIO = 2.0
#: An IMU axis's scale factor is looked for (:func:`imu_scale_fit`) when the columns as
#: written leave a velocity-matching residual above this, m/s (GNSS noise and gyro drift leave
#: 0.06-0.26 m/s on the unseen suite's strapdown flights; a gyro z scale 1 % off 0.30) ...
STRAPDOWN_SCALE_MIN_RESIDUAL_MPS = 0.15
#: ... within 1 +- this ...
STRAPDOWN_SCALE_RANGE = 0.1
#: ... in this many golden-section steps (the bracket shrinks to 0.2 x 0.618^12: 0.06 %) ...
STRAPDOWN_SCALE_STEPS = 12
#: ... and a factor off 1 by more than this that fits STRAPDOWN_AXES_RATIO times better is
#: divided out, with a warning naming the column (:func:`correct_imu_scale`) ...
STRAPDOWN_SCALE_MIN_ERROR = 0.002
#: ... on at most this many axes.
STRAPDOWN_SCALE_AXES = 2
#: A platform's horizontal accelerometer factor is divided out when it fits this many times
#: better than as written (and passed the search's gate: a 1 % change fitting better by a tenth):
#: its attitude comes from the track, not from gyros that drift, and no column fault competes.
#: Measured on the 35 platform flights of the quick unseen suites (seeds 0-19, 200-239, 400-419):
#: as drawn, a 1 % change either way fits at best 0.97x as well (never searched) and the best
#: factor on a 0.1 % grid is 1.000 (0.999 once); with fy 1 % or fx -1 % off the factor is found to
#: 0.03 % at ratios 1.15-1.73 (fx -1 % on U019 not searched), 5 % off at 2.97-7.07.
PLATFORM_SCALE_RATIO = 1.1
#: The hypotheses of the GNSS latitudes' and longitudes' sign (:func:`strapdown_axis_fit`): the
#: track mirrored about the equator or the Greenwich meridian is mirrored against the IMU too.
GNSS_SIGN_FAULTS = {"lat": "the GNSS latitudes' sign flipped", "lon": "the GNSS longitudes' sign flipped"}


def check_platform_axes(record, triad: str, names: ChannelNames | None = None, key_prefix: str = "") -> list[str]:
    """A platform triad's third axis points up: its median specific force is about +g.

    A stabilised platform's axes are east, north and up (``triad: platform``); the navigation
    takes the third for the vertical.  Read with its up axis reversed (a forward-right-down
    declaration, ``imu_axes: FRD``, of a platform logged forward-left-up, or the other way round)
    or with the vertical on another axis, the mechanization runs away within minutes or, worse,
    integrates a mirrored vertical channel: this check names the cause first.  A body-fixed IMU
    declared ``platform`` banks with the aircraft: its gyros turn about the horizontal axes at
    1-2 deg/s in turns, where a platform held level turns at the Earth's rate
    (:data:`PLATFORM_TILT_RATE_DEGPS`); that is refused first, naming ``triad``.  A strapdown
    triad is aligned from the data in any orientation and is not checked.

    Parameters
    ----------
    record : FlightRecord
        Its IMU specific force on the triad after ``imu_axes``, shape (n, 3), m/s^2.
    triad : {"platform", "strapdown"}
    names : ChannelNames, optional
        For the message: the IMU file and its columns.
    key_prefix : str
        The flight's config key (``flights[i]``), for the messages' ``imu_axes`` and ``triad``.

    Returns
    -------
    list of str
        One passed-check note for a platform triad, none otherwise.

    Raises
    ------
    DataError
        The median third-axis specific force outside :data:`PLATFORM_UP_RANGE` x g, naming the
        file, the axis that carries gravity and its sign, and ``imu_axes``; or horizontal turn
        rates of a body-fixed IMU, naming the gyro columns and the flight's ``triad`` key.
    """
    if triad != "platform":
        return []
    key_path = f"{key_prefix}.imu_axes" if key_prefix else "imu_axes"
    _check_platform_rates(record, names, f"{key_prefix}.triad" if key_prefix else "triad")
    f = np.asarray(record.imu.specific_force_t, float)
    if f.ndim != 2 or f.shape[1] != 3 or f.shape[0] == 0:
        return []
    med = np.nanmedian(f, axis=0)
    if not np.all(np.isfinite(med)):
        return []
    up = float(med[2]) / STANDARD_GRAVITY_MPS2
    lo, hi = PLATFORM_UP_RANGE
    if lo <= up <= hi:
        return [f"{PASSED}platform axes: median up-axis specific force {med[2]:+.3f} m/s^2"]
    where = names.column("imu", "fx", "fy", "fz") if names is not None else "imu"
    k = int(np.argmax(np.abs(med)))
    axis = f"{'+-'[int(med[k] < 0)]}{'xyz'[k]}"
    raise DataError(
        f"{where}: the platform triad's third axis reads a median specific force of {med[2]:+.3f} m/s^2 "
        f"(after {key_path}), expected about +{STANDARD_GRAVITY_MPS2:.2f} (up); gravity lies on the triad's {axis} axis "
        f"(median ({med[0]:+.2f}, {med[1]:+.2f}, {med[2]:+.2f}) m/s^2): check {key_path} (FLU and RFU keep "
        "the third axis up, FRD turns it down) and the column order"
    )


def platform_rate_slopes(record, block_s: float = PLATFORM_RATE_BLOCK_S, ellipsoid=WGS84, lat_sign: float = 1.0):
    """Each platform gyro against the rate of an east-north-up frame along the GNSS track.

    Over spans of ``block_s``: the mean angular rate of each gyro, and the frame's rate in
    inertial space the track implies, ``(-v_N / (M + h), Omega cos(lat) + v_E / (N + h),
    Omega sin(lat) + v_E tan(lat) / (N + h))`` (velocity from a line fitted to the GNSS
    positions of the span). ``lat_sign = -1`` takes the latitudes with the other sign (a
    hypothesis about the GNSS column: the Earth's vertical rate and the rate about east change
    sign with it).

    Returns
    -------
    slopes : ndarray, shape (3,)
        Least-squares slope (through zero) of each gyro's means on the expected rate; NaN
        without GNSS or gyro data.
    rms_degph : ndarray, shape (3,)
        RMS of the expected rate per axis, deg/h.
    blocks : int
    """
    from .geodesy import radii_of_curvature

    nan = (np.full(3, np.nan), np.full(3, np.nan), 0)
    g, imu = getattr(record, "gnss", None), record.imu
    w = np.asarray(imu.angular_rate_t, float)
    if g is None or len(g.time) < 10 or w.ndim != 2 or w.shape[1] != 3 or not np.any(w):
        return nan
    t = np.asarray(g.time, float)
    lat = lat_sign * np.asarray(g.lat, float)
    lon = np.unwrap(np.asarray(g.lon, float))
    h = np.asarray(g.height, float)
    ti = np.asarray(imu.time, float)
    edges = np.arange(max(t[0], ti[0]), min(t[-1], ti[-1]), block_s)
    # sample ranges of each span (both series sorted)
    gi = np.searchsorted(t, edges)
    ii = np.searchsorted(ti, edges)
    m, e = [], []
    for k in range(len(edges) - 1):
        ga, gb, ia, ib = gi[k], gi[k + 1], ii[k], ii[k + 1]
        if gb - ga < 5 or ib - ia < 10:
            continue
        tt = t[ga:gb] - t[ga:gb].mean()
        if not np.ptp(tt) > 0:
            continue
        dlat = np.polyfit(tt, lat[ga:gb], 1)[0]
        dlon = np.polyfit(tt, lon[ga:gb], 1)[0]
        phi, hh = float(np.mean(lat[ga:gb])), float(np.mean(h[ga:gb]))
        rm, rn = radii_of_curvature(phi, ellipsoid)
        vn, ve = dlat * (rm + hh), dlon * (rn + hh) * math.cos(phi)
        om = ellipsoid.omega
        e.append(
            [-vn / (rm + hh), om * math.cos(phi) + ve / (rn + hh), om * math.sin(phi) + ve * math.tan(phi) / (rn + hh)]
        )
        m.append(np.nanmean(w[ia:ib], axis=0))
    if not m:
        return nan
    m_a, e_a = np.array(m), np.array(e)
    ok = np.all(np.isfinite(m_a), axis=1) & np.all(np.isfinite(e_a), axis=1)
    m_a, e_a = m_a[ok], e_a[ok]
    if not len(m_a):
        return nan
    den = np.sum(e_a * e_a, axis=0)
    slopes = np.where(den > 0, np.sum(m_a * e_a, axis=0) / np.where(den > 0, den, 1.0), np.nan)
    return slopes, np.degrees(np.sqrt(np.mean(e_a**2, axis=0))) * 3600.0, int(len(m_a))


def check_platform_gyros(record, triad: str, names: ChannelNames | None = None, key_prefix: str = "") -> list[str]:
    """Refuse a platform triad whose gyros do not read the rate of an east-north-up frame along
    the track (:func:`platform_rate_slopes`): a gyro axis negated or two swapped (fuzzing,
    2026-12-04: 1.8-5.3x the intact error with exit 0). A passed-check note otherwise; nothing
    for a strapdown triad, without GNSS or gyro data, or on axes whose expected rate hardly
    varies. Run after the GNSS checks (:func:`check_gnss_consistency`): it trusts the track.

    Raises
    ------
    DataError
        Naming the gyro columns, each judged axis's slope and ``imu_axes``.
    """
    if triad != "platform":
        return []
    key_path = f"{key_prefix}.imu_axes" if key_prefix else "imu_axes"
    slopes, rms, blocks = platform_rate_slopes(record)
    judged = [k for k in range(3) if np.isfinite(slopes[k]) and rms[k] >= PLATFORM_RATE_MIN_RMS_DEGPH]
    if blocks < PLATFORM_RATE_MIN_BLOCKS or not judged:
        return []
    lo, hi = PLATFORM_RATE_SLOPE_RANGE
    text = ", ".join(f"{'xyz'[k]} {slopes[k]:+.2f}" for k in judged)
    if all(lo <= slopes[k] <= hi for k in judged):
        return [f"{PASSED}platform gyros: slopes on the Earth's and the transport rate {text} ({blocks} spans)"]
    flipped, _, _ = platform_rate_slopes(record, lat_sign=-1.0)
    if all(np.isfinite(flipped[k]) and lo <= flipped[k] <= hi for k in judged):
        # the Earth's vertical rate and the transport rate about east change sign with the
        # latitude: a survey south of the equator written without its sign reads as two gyro
        # axes negated
        from .inm.alignment import SIGN_SLIPS

        where = names.column("gnss", "lat") if names is not None else "gnss latitude"
        raise DataError(
            f"{where}: the platform gyros turn as an east-north-up platform does along the GNSS track with "
            f"its latitudes' sign flipped (slopes {', '.join(f'{chr(120 + k)} {flipped[k]:+.2f}' for k in judged)}; "
            f"as written {text}, expected +1): the latitudes' sign is wrong "
            f"({SIGN_SLIPS['lat'][bool(np.median(record.gnss.lat) < 0)]}, or the hemisphere column left out)?"
        )
    where = names.column("imu", "wx", "wy", "wz") if names is not None else "imu"
    raise DataError(
        f"{where}: the platform gyros do not turn as an east-north-up platform along the GNSS track does: "
        f"their {PLATFORM_RATE_BLOCK_S:g}-s means against the Earth's and the transport rate give slopes {text} "
        f"(expected +1; -1 is an axis negated): check {key_path} and the gyro columns' order and signs"
    )


def strapdown_axis_hypotheses():
    """Column faults of a strapdown IMU, as ``(description, quantities, transform)``; ``transform``
    takes ``(f, w)`` (n, 3) to the corrected pair."""

    def neg(which, k):
        def tr(f, w):
            f, w = f.copy(), w.copy()
            for arr in (f,) * ("f" in which) + (w,) * ("w" in which):
                arr[:, k] = -arr[:, k]
            return f, w

        return tr

    def swap(which, i, j):
        def tr(f, w):
            f, w = f.copy(), w.copy()
            arr = f if which == "f" else w
            arr[:, [i, j]] = arr[:, [j, i]]
            return f, w

        return tr

    out = []
    for k, ax in enumerate("xyz"):
        out.append((f"the accelerometer's {ax} axis negated", (f"f{ax}",), neg("f", k)))
        out.append((f"the gyro's {ax} axis negated", (f"w{ax}",), neg("w", k)))
        out.append(
            (
                f"the {ax} axis of both accelerometer and gyro negated (a left-handed triad)",
                (f"f{ax}", f"w{ax}"),
                neg("fw", k),
            )
        )
    for i, j in ((0, 1), (0, 2), (1, 2)):
        a, b = "xyz"[i], "xyz"[j]
        out.append((f"the accelerometer's {a} and {b} axes swapped", (f"f{a}", f"f{b}"), swap("f", i, j)))
        out.append((f"the gyro's {a} and {b} axes swapped", (f"w{a}", f"w{b}"), swap("w", i, j)))
    return out


def manoeuvre_windows(record, ellipsoid=WGS84) -> list:
    """The IMU samples of the flight's strongest manoeuvres: up to :data:`STRAPDOWN_AXES_WINDOWS`
    windows of :data:`STRAPDOWN_AXES_WINDOW_S` that do not overlap, with the largest change of the
    GNSS velocity (at least :data:`STRAPDOWN_AXES_MIN_DV_MPS`).

    Returns
    -------
    list of (time, f_t, w_t)
        ndarray (n,), (n, 3), (n, 3) each; empty without GNSS or manoeuvres.
    """
    from .inm.alignment import gnss_inertial_velocity

    g, imu = record.gnss, record.imu
    if g is None or len(g.time) < 10:
        return []
    t = np.asarray(imu.time, float)
    f = np.asarray(imu.specific_force_t, float)
    w = np.asarray(imu.angular_rate_t, float)
    tg = np.asarray(g.time, float)
    win = STRAPDOWN_AXES_WINDOW_S
    a0, a1 = max(t[0], tg[0]), min(t[-1], tg[-1])
    starts = np.arange(a0, a1 - win, win / 2)
    if not starts.size:
        return []
    _, v0 = gnss_inertial_velocity(tg, g.lat, g.lon, g.height, starts, 1.0, ellipsoid)
    _, v1 = gnss_inertial_velocity(tg, g.lat, g.lon, g.height, starts + win, 1.0, ellipsoid)
    dv = np.linalg.norm(v1 - v0, axis=1)
    dv[~np.isfinite(dv)] = 0.0
    order = [k for k in np.argsort(dv)[::-1] if dv[k] >= STRAPDOWN_AXES_MIN_DV_MPS]
    chosen = []
    for k in order:  # windows that do not overlap
        if all(abs(starts[k] - starts[j]) >= win for j in chosen):
            chosen.append(k)
        if len(chosen) == STRAPDOWN_AXES_WINDOWS:
            break
    out = []
    for k in chosen:
        i0, i1 = np.searchsorted(t, [starts[k], starts[k] + win])
        out.append((t[i0:i1], f[i0:i1], w[i0:i1]))
    return out


def platform_attitude_history(time, gnss, ellipsoid=WGS84) -> np.ndarray:
    """``C_t0_t`` of an ENU-stabilised platform triad over ``time``: the level frame at ``t``
    resolved on the level frame at ``time[0]``, in inertial space (the Earth's turn and the
    track's over the sphere, from the GNSS positions).

    Parameters
    ----------
    time : ndarray, shape (n,)
        s (record base), within the GNSS track.
    gnss : GnssChannel

    Returns
    -------
    ndarray, shape (n, 3, 3)
        As :func:`gravsurvey.inm.mechanization.propagate_attitude` gives a strapdown triad's.
    """
    t = np.asarray(time, float)
    tg = np.asarray(gnss.time, float)
    lat = np.interp(t, tg, np.asarray(gnss.lat, float))
    lon = np.interp(t, tg, np.unwrap(np.asarray(gnss.lon, float)))
    mat_in = mat_ie(t, ellipsoid.omega) @ mat_en(lat, lon)
    return np.einsum("ji,njk->nik", mat_in[0], mat_in)


def _matched_windows(record, ellipsoid, triad: str = "strapdown", gnss_fits: dict | None = None) -> list:
    """:func:`manoeuvre_windows` with the triad's attitude history over each (a strapdown
    triad's from its gyros - only a gyro hypothesis changes it -, a platform's from the GNSS
    track: :func:`platform_attitude_history`) and the velocity-matching residual of the columns
    as written, m/s; a window with a gap in the GNSS is left out.  ``gnss_fits``: the GNSS side
    of the matching kept for the hypotheses to come (:func:`gravsurvey.inm.alignment.match_vectors`)."""
    from .inm.alignment import match_residual_rms
    from .inm.mechanization import propagate_attitude

    out = []
    for tt, ff, ww in manoeuvre_windows(record, ellipsoid):
        if triad == "platform":
            c_t0 = platform_attitude_history(tt, record.gnss, ellipsoid)
        else:
            c_t0 = propagate_attitude(tt, ww, np.eye(3))
        try:
            r0 = match_residual_rms(tt, ff, ww, record.gnss, ellipsoid, c_t0=c_t0, gnss_fits=gnss_fits)
        except DataError:  # a gap in the window
            continue
        out.append((tt, ff, ww, c_t0, r0))
    return out


def imu_scale_fit(record, ellipsoid=WGS84, triad: str = "strapdown") -> list:
    """Each IMU axis's scale factor as the GNSS track shows it: the factor ``s`` by which dividing
    the axis's readings best fits the GNSS velocity changes through the manoeuvres (RMS of the
    velocity-matching residuals over :func:`manoeuvre_windows`; golden-section search in
    ``1 +- STRAPDOWN_SCALE_RANGE``).

    A strapdown triad's six axes are searched; a platform's (``triad="platform"``, ENU-stabilised)
    horizontal accelerometers only, its attitude taken from the track
    (:func:`platform_attitude_history`): its gyros hold the platform level rather than measure
    the motion, and its vertical's scale shows as a gravity offset the GNSS checks refuse
    (:func:`check_gnss_consistency`).

    Returns
    -------
    list of (str, float, float, float)
        ``(quantity, s, residual at s, residual as written)`` for each axis (``fx`` ... ``wz``)
        whose fit a 1 % change improves by a tenth (the others are not searched), m/s; empty
        without manoeuvres or when the columns as written fit within
        :data:`STRAPDOWN_SCALE_MIN_RESIDUAL_MPS`.
    """
    from .inm.alignment import match_residual_rms

    # the GNSS side of every match is the same for all the axes and factors tried
    fits = {}
    windows = _matched_windows(record, ellipsoid, triad, fits)
    if len(windows) < STRAPDOWN_AXES_MIN_WINDOWS:
        return []
    if float(np.sqrt(np.mean(np.square([w[4] for w in windows])))) <= STRAPDOWN_SCALE_MIN_RESIDUAL_MPS:
        return []

    def pooled(q, k, s):
        r = []
        for tt, ff, ww, c, _ in windows:
            f2, w2 = ff, ww
            if q == "f":
                f2 = ff.copy()
                f2[:, k] /= s
            else:
                w2 = ww.copy()
                w2[:, k] /= s
            r.append(
                match_residual_rms(tt, f2, w2, record.gnss, ellipsoid, c_t0=c if q == "f" else None, gnss_fits=fits)
            )
        return float(np.sqrt(np.mean(np.square(r))))

    out = []
    ratio = (math.sqrt(5.0) - 1.0) / 2.0
    if triad == "platform":
        axes = [("f", 0, "x"), ("f", 1, "y")]
    else:
        axes = [(q, k, ax) for q in "fw" for k, ax in enumerate("xyz")]
    for q, k, ax in axes:
        r_1 = pooled(q, k, 1.0)
        # searched only where a 1 % change either way fits better by a tenth
        if min(pooled(q, k, 0.99), pooled(q, k, 1.01)) > 0.9 * r_1:
            continue
        a, b = 1.0 - STRAPDOWN_SCALE_RANGE, 1.0 + STRAPDOWN_SCALE_RANGE
        x1, x2 = b - ratio * (b - a), a + ratio * (b - a)
        y1, y2 = pooled(q, k, x1), pooled(q, k, x2)
        for _ in range(STRAPDOWN_SCALE_STEPS):
            if y1 < y2:
                b, x2, y2 = x2, x1, y1
                x1 = b - ratio * (b - a)
                y1 = pooled(q, k, x1)
            else:
                a, x1, y1 = x1, x2, y2
                x2 = a + ratio * (b - a)
                y2 = pooled(q, k, x2)
        best = x1 if y1 < y2 else x2
        out.append((f"{q}{ax}", best, min(y1, y2), r_1))
    return out


def strapdown_axis_fit(record, ellipsoid=WGS84):
    """Velocity-matching residuals of the columns as written and of each column fault
    (:func:`strapdown_axis_hypotheses`) over the manoeuvres of the flight (turns, speed changes).

    Returns
    -------
    as_written : ndarray, shape (k,)
        RMS residual per judged window, m/s.
    faults : list of (str, tuple, ndarray (k,))
        Each hypothesis with its residuals.
    """
    from .inm.alignment import match_residual_rms

    g = record.gnss
    # the GNSS side of every match is the same for all the hypotheses but the mirrored tracks
    fits = {}
    windows = _matched_windows(record, ellipsoid, gnss_fits=fits)
    if not windows:
        return np.zeros(0), []
    hyps = strapdown_axis_hypotheses()
    # a track mirrored about the equator or the Greenwich meridian (a coordinate of the wrong sign)
    # is mirrored against the IMU too, and would otherwise be read as a negated axis
    mirrored = {
        "lat": dataclasses.replace(g, lat=-np.asarray(g.lat, float)),
        "lon": dataclasses.replace(g, lon=-np.asarray(g.lon, float)),
    }
    hyps += [(GNSS_SIGN_FAULTS["lat"], ("lat",), None), (GNSS_SIGN_FAULTS["lon"], ("lon",), None)]
    res = [
        [
            match_residual_rms(
                tt, *tr(ff, ww), g, ellipsoid, c_t0=None if any(x.startswith("w") for x in q) else c_t0, gnss_fits=fits
            )
            if tr is not None
            else match_residual_rms(tt, ff, ww, mirrored[q[0]], ellipsoid, c_t0=c_t0, gnss_fits=fits)
            for tt, ff, ww, c_t0, _ in windows
        ]
        for _, q, tr in hyps
    ]
    base = np.array([w[4] for w in windows])
    return base, [(d, q, np.array(r)) for (d, q, _), r in zip(hyps, res)]


def correct_imu_scale(record, triad: str, names: ChannelNames | None = None) -> tuple:
    """Divide out an IMU axis's scale-factor error that the GNSS track shows
    (:func:`imu_scale_fit`): off 1 by more than :data:`STRAPDOWN_SCALE_MIN_ERROR` and fitting
    :data:`STRAPDOWN_AXES_RATIO` (a platform's: :data:`PLATFORM_SCALE_RATIO`) times better than as
    written; the best axis first, then the search again (at most :data:`STRAPDOWN_SCALE_AXES`
    axes). Kept, a gyro's z scale 1 % off put 56 mGal into a strapdown flight (2.2 intact) with
    exit 0, a platform's north accelerometer 5 % off 16.6 mGal into the CSV sample (3.45 intact;
    fuzzing, 2026-12-04 and -05). A platform's horizontal accelerometers only
    (:func:`imu_scale_fit`). Run after :func:`check_strapdown_axes`.

    Returns
    -------
    record : FlightRecord
        With the corrected readings (the same object when nothing was found).
    notes : list of str
        One warning per corrected axis, naming the column and the factor.
    """
    notes = []
    if triad not in ("strapdown", "platform"):
        return record, notes
    ratio = PLATFORM_SCALE_RATIO if triad == "platform" else STRAPDOWN_AXES_RATIO
    for _ in range(STRAPDOWN_SCALE_AXES):
        fits = [x for x in imu_scale_fit(record, triad=triad) if abs(x[1] - 1.0) > STRAPDOWN_SCALE_MIN_ERROR]
        fits = [x for x in fits if x[3] >= ratio * x[2]]
        if not fits:
            break
        q, s, r_s, r_1 = max(fits, key=lambda x: x[3] / max(x[2], 1e-12))
        imu = record.imu
        f = np.array(imu.specific_force_t, float)
        w = np.array(imu.angular_rate_t, float)
        (f if q[0] == "f" else w)[:, "xyz".index(q[1])] /= s
        record = dataclasses.replace(record, imu=dataclasses.replace(imu, specific_force_t=f, angular_rate_t=w))
        where = names.column("imu", q) if names is not None else f"imu {q}"
        sensor = "accelerometer" if q[0] == "f" else "gyro"
        axis = {"x": "x (east)", "y": "y (north)"}[q[1]] if triad == "platform" else q[1]
        notes.append(
            f"{where}: the {triad} {sensor}'s {axis} axis reads {s:.4f}x the motion the GNSS track shows "
            f"(velocity-matching residual {r_s:.2g} m/s with its readings divided by {s:.4f}, {r_1:.2g} m/s as "
            f"written): a scale-factor error of {100 * (s - 1):+.2f} %, divided out before the estimate (calibrate "
            f"the IMU)"
        )
    return record, notes


def check_strapdown_axes(record, triad: str, names: ChannelNames | None = None, key_prefix: str = "") -> list[str]:
    """Refuse a strapdown IMU whose columns fit the GNSS track much better with an axis negated,
    two swapped, or one axis of both sensors negated (:func:`strapdown_axis_fit`): kept, an
    accelerometer axis of the wrong sign ran with exit 0 at 2.4x the intact error or failed as
    "|disturbance| reaches 1373 mGal", a gyro axis as a mechanization run-away (fuzzing,
    2026-12-04). A passed-check note otherwise; nothing for a platform triad, without GNSS, or
    without manoeuvres to judge by. Run after the GNSS checks: it trusts the track.

    Raises
    ------
    DataError
        Naming the IMU columns of the fault and ``imu_axes``.
    """
    if triad != "strapdown":
        return []
    base, faults = strapdown_axis_fit(record)
    if base.size < STRAPDOWN_AXES_MIN_WINDOWS:
        return []

    def pooled(r):
        # one window of turns shows a gyro fault that straight accelerations hide
        return float(np.sqrt(np.mean(np.square(r))))

    ratios = [(pooled(base) / max(pooled(r), 1e-12), d, q, r) for d, q, r in faults]
    ratio, desc, quants, r = max(ratios, key=lambda x: x[0])
    fit = f"{pooled(r):.2g} m/s against {pooled(base):.2g} m/s as written"
    if ratio < STRAPDOWN_AXES_RATIO:
        return [
            f"{PASSED}strapdown axes: the columns as written fit the GNSS track best (velocity-matching "
            f"residual {pooled(base):.2g} m/s RMS over {base.size} manoeuvres; the nearest fault, {desc}, "
            f"{1.0 / ratio:.1f}x worse)"
        ]
    if quants in (("lat",), ("lon",)):
        q = quants[0]
        where = names.column("gnss", q) if names is not None else f"gnss {q}"
        from .inm.alignment import SIGN_SLIPS

        negative = bool(np.median(getattr(record.gnss, q)) < 0)
        raise DataError(
            f"{where}: the strapdown IMU's motion fits the GNSS track {ratio:.1f}x better with {desc} (velocity-"
            f"matching residual, RMS over {base.size} manoeuvres of {STRAPDOWN_AXES_WINDOW_S:g} s: {fit}): "
            f"{SIGN_SLIPS[q][negative]}, or the hemisphere column left out?"
        )
    where = names.column("imu", *quants) if names is not None else "imu"
    key_path = f"{key_prefix}.imu_axes" if key_prefix else "imu_axes"
    raise DataError(
        f"{where}: the strapdown IMU's motion fits the GNSS track {ratio:.1f}x better with {desc} (velocity-"
        f"matching residual, RMS over {base.size} manoeuvres of {STRAPDOWN_AXES_WINDOW_S:g} s: {fit}): check the "
        f"columns' signs and order ({key_path} turns both sensors alike)"
    )


def _check_platform_rates(record, names: ChannelNames | None, triad_key: str) -> None:
    """Refuse a "platform" triad whose gyros show it banking with the aircraft
    (:data:`PLATFORM_TILT_RATE_DEGPS` for :data:`PLATFORM_TILT_MIN_S`)."""
    t = np.asarray(record.imu.time, float)
    w = np.asarray(record.imu.angular_rate_t, float)
    if t.size < 3 or w.ndim != 2 or w.shape[1] < 2:
        return
    dt = float(np.median(np.diff(t)))
    k = int(round(PLATFORM_RATE_WINDOW_S / dt)) if dt > 0 else 0
    if k < 1 or t.size <= k:
        return
    rate = np.degrees(np.hypot(*_box(np.nan_to_num(w[:, :2]), k).T))
    above_s = float(np.count_nonzero(rate > PLATFORM_TILT_RATE_DEGPS)) * dt
    if above_s < PLATFORM_TILT_MIN_S:
        return
    where = names.column("imu", "wx", "wy") if names is not None else "imu"
    # a level platform whose rates are read in a unit too small: its steady rate vector is the
    # Earth's (and the transport) rate times the units' ratio, not a body's turns and gusts
    steady = np.linalg.norm(np.nanmedian(w, axis=0)) / (WGS84.omega)
    unit = next(
        (
            text
            for text, k in (
                ("deg/h declared as deg/s", 3600.0),
                ("deg/s declared as rad/s", 180.0 / math.pi),
                ("deg/h declared as rad/s", 3600.0 * 180.0 / math.pi),
            )
            if abs(steady / k - 1.0) < 0.3
        ),
        None,
    )
    raise DataError(
        f"{where}: the platform triad turns about its horizontal axes at up to {rate.max():.2f} deg/s "
        f"({PLATFORM_RATE_WINDOW_S:g}-s means; {above_s:.0f} s above {PLATFORM_TILT_RATE_DEGPS:g} deg/s), where a "
        "stabilised platform holds level (the Earth's rate, under 0.005 deg/s): "
        + (
            f"its median rate vector is {steady:.0f} x the Earth's rate: gyros in {unit}? (csv.units.gyro)"
            if unit
            else f"a body-fixed IMU? set {triad_key}: strapdown"
        )
    )


def _stamp_unit_hint(t0_ns: int, imu_span, other_span, role: str) -> str | None:
    """``"the <channel> stamps read 1,000x too small: in microseconds ..."`` when one channel's
    Unix start time is a power of 1000 times the other's (within 1 %), else None."""
    ref = t0_ns * 1e-9
    a0, b0 = ref + imu_span[0], ref + other_span[0]
    for small, big, name in ((a0, b0, "imu"), (b0, a0, role)):
        if not (0 < small and big > 0):
            continue
        for k, unit in ((1e3, "microseconds"), (1e6, "milliseconds"), (1e9, "seconds")):
            if abs(big / (small * k) - 1.0) < 0.01:
                return (
                    f"the {name} stamps read {k:,.0f}x too small: in {unit} but declared as nanoseconds "
                    "(csv.time_format, or the time column)?"
                )
    return None


def _clock_hint(record) -> str | None:
    """``"the IMU runs ... relative to the gnss ..."`` when the GNSS record is the IMU's shifted in
    time (both ends alike) and the specific forces agree at that lag; else None."""
    shift = _common_shift(record)
    if shift is None:
        return None
    off, c = estimate_time_offset(record, centre_s=shift)
    if off is None or not c >= OFFSET_VERDICT_CORRELATION:
        return None
    hours = abs(off) / 3600.0
    zone = (
        f" ({hours:.0f} h: local time in one file?)" if hours >= 0.99 and abs(hours - round(hours)) * 3600 < 60 else ""
    )
    return (
        f"the IMU runs {off:+.2f} s relative to the gnss{zone} (cross-correlation of specific force, r = {c:.2f}): "
        f"give the flight time_offsets_s: {{gnss: {off:+.2f}}}"
    )


def check_overlap(record, names: ChannelNames | None = None, min_fraction: float = 0.5) -> list[str]:
    """Channels must overlap the IMU in time.

    Raises
    ------
    DataError
        The altimeter or GNSS channel does not overlap the IMU at all (e.g. the IMU clock an
        hour out of step): names both channels, their files and their time ranges.

    Returns
    -------
    list of str
        Notes for channels overlapping less than ``min_fraction`` of the IMU span.
    """
    spans = channel_spans(record)
    t0 = record.t0_unix_ns
    a0, a1 = spans["imu"]
    notes = []
    for role in ("altimeter", "gnss"):
        if role not in spans:
            continue
        b0, b1 = spans[role]
        ov = min(a1, b1) - max(a0, b0)
        fi = names.files.get("imu", "imu") if names else "imu"
        fr = names.files.get(role, role) if names else role
        if ov <= 0:
            raise DataError(
                f"imu ({fi}) {span_text(t0, a0, a1)} and {role} ({fr}) {span_text(t0, b0, b1)} "
                f"do not overlap in time ({max(a0, b0) - min(a1, b1):.1f} s apart): "
                + (
                    _stamp_unit_hint(t0, (a0, a1), (b0, b1), role)
                    or (_clock_hint(record) if role == "gnss" else None)
                    or "a clock out of step or files of different flights?"
                )
            )
        if ov < min_fraction * (a1 - a0):
            notes.append(
                f"{role} covers only {100 * ov / (a1 - a0):.0f} % of the IMU time span: imu "
                f"{span_text(t0, a0, a1)}, {role} {span_text(t0, b0, b1)}"
            )
        elif ov < IMU_COVER_FRACTION * (b1 - b0):
            # the IMU is the short one: its stamps at the wrong rate or in other units, or its log cut
            notes.append(
                f"imu covers only {100 * ov / (b1 - b0):.0f} % of the {role} time span: imu "
                f"{span_text(t0, a0, a1)}, {role} {span_text(t0, b0, b1)} (IMU stamps at a wrong rate or "
                "in other units, or its log cut short?)"
            )
    return notes


# ----------------------------------------------------------------------------- kinematics
def _box(x, n):
    """Centred moving average over ``n`` samples along axis 0 (valid part only)."""
    c = np.cumsum(np.concatenate([np.zeros((1,) + x.shape[1:]), x]), axis=0)
    return (c[n:] - c[:-n]) / n


def _near_samples(t, tg, max_step):
    """True where ``tg`` lies in a step of ``t`` no longer than ``max_step`` (not in a gap)."""
    j = np.clip(np.searchsorted(t, tg, side="right"), 1, len(t) - 1)
    return (t[j] - t[j - 1]) <= max_step


def gnss_specific_force(time, lat, lon, height, window_s: float = KINEMATIC_WINDOW_S, ellipsoid=WGS84):
    """Specific-force magnitude implied by the GNSS track: ``|r'' + 2 w x r' - gamma(r)|``.

    ECEF positions are averaged over ``window_s`` and twice differenced at a spacing of
    ``window_s``; in the rotating Earth frame ``f = r'' + 2 omega x r' - gamma`` with gamma the
    normal gravity vector (gravitation + centrifugal), so the Eotvos effect is included. The
    result equals the true specific force smoothed by the kernel of :func:`imu_specific_force`.

    Parameters
    ----------
    time : ndarray, shape (n,)
        s, strictly increasing, roughly uniform.
    lat, lon : ndarray, shape (n,)
        rad.
    height : ndarray, shape (n,)
        Ellipsoidal height, m.

    Returns
    -------
    t_mid : ndarray, shape (m,)
        Times of the estimates, s.
    f_mag : ndarray, shape (m,)
        m/s^2.
    speed : ndarray, shape (m,)
        Ground speed (ECEF velocity magnitude), m/s.
    """
    t = np.asarray(time, float)
    if len(t) < 8:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    dt = float(np.median(np.diff(t)))
    n = max(2, round(window_s / dt))
    if len(t) < 3 * n + 2:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    # uniform grid; grid points inside a gap (> 2 steps) are invalid, and so is every
    # estimate whose window touches one (no kinematics across gaps)
    tg = np.arange(t[0], t[-1], dt)
    r = geodetic_to_ecef(np.interp(tg, t, lat), np.interp(tg, t, np.unwrap(lon)), np.interp(tg, t, height), ellipsoid)
    r[~_near_samples(t, tg, 2.0 * dt)] = np.nan
    rm = _box(r, n)  # mean over n samples, centred at tg[k] + (n - 1) dt / 2
    tm = tg[: len(rm)] + 0.5 * (n - 1) * dt
    h = n * dt
    acc = (rm[2 * n :] - 2 * rm[n:-n] + rm[: -2 * n]) / h**2
    vel = (rm[2 * n :] - rm[: -2 * n]) / (2 * h)
    rc = rm[n:-n]
    omega = np.array([0.0, 0.0, ellipsoid.omega])
    f = acc + 2.0 * np.cross(omega, vel) - normal_gravity_ecef(rc, ellipsoid)
    return tm[n:-n], np.linalg.norm(f, axis=1), np.linalg.norm(vel, axis=1)


def _kernel(dt, window_s):
    """Kernel of :func:`gnss_specific_force` on the acceleration: box * triangle, on a ``dt`` grid."""
    n = max(2, round(window_s / dt))
    box = np.full(n, 1.0 / n)
    return np.convolve(box, np.convolve(box, box))


def smooth_imu(time, values, t_out, dt, window_s: float = KINEMATIC_WINDOW_S, shift_s=0.0):
    """An IMU quantity smoothed with the kernel of :func:`gnss_specific_force`, at ``t_out``.

    The GNSS estimate's kernel on the acceleration is a box of ``window_s`` convolved with a
    triangle of half-width ``window_s``; the same kernel is applied here. Outputs whose kernel
    touches an IMU gap are NaN.

    Parameters
    ----------
    time : ndarray, shape (n,)
        IMU times, s.
    values : ndarray, shape (n,) or (n, k)
        e.g. ``|f|`` or ``specific_force_t``.
    t_out : ndarray, shape (m,), or None
        Output times, s (+ ``shift_s``); None: return the series on its own grid.
    dt : float
        Grid step of the kernel, s.

    Returns
    -------
    ndarray, shape (m,) or (m, k)
        With ``t_out=None``: ``(grid times, series)``.
    """
    t = np.asarray(time, float)
    v = np.asarray(values, float)
    flat = v.reshape(len(t), -1)
    kern = _kernel(dt, window_s)
    half = 0.5 * (len(kern) - 1) * dt
    tg = np.arange(t[0], t[-1], dt)
    near = _near_samples(t, tg, max(2.0 * dt, 5.0 * float(np.median(np.diff(t)))))
    if t_out is None:  # the smoothed series on its own grid
        out = np.empty((max(len(tg) - len(kern) + 1, 0), flat.shape[1]))
    else:
        out = np.empty((len(np.atleast_1d(t_out)), flat.shape[1]))
    ts = tg[: len(out)] + half
    for c in range(flat.shape[1]):
        fg = np.interp(tg, t, flat[:, c])
        fg[~near] = np.nan
        sm = np.convolve(fg, kern, mode="valid")  # NaN spreads over every window touching a gap
        if t_out is None:
            out[:, c] = sm
        else:
            out[:, c] = np.interp(np.asarray(t_out) + shift_s, tg[: len(sm)] + half, sm, left=np.nan, right=np.nan)
    out = out.reshape((len(out),) + v.shape[1:])
    return (ts, out) if t_out is None else out


def _quat_mul(a, b):
    """Hamilton products of quaternions ``[w, x, y, z]``, ``(..., 4)`` each."""
    w1, x1, y1, z1 = np.moveaxis(a, -1, 0)
    w2, x2, y2, z2 = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ],
        axis=-1,
    )


def _quat_cumprod(d):
    """Running products ``d[0] d[1] ... d[k]`` of quaternions ``(n, 4)`` (a log2(n)-pass scan)."""
    q = d.copy()
    shift = 1
    while shift < len(q):
        q[shift:] = _quat_mul(q[:-shift], q[shift:])
        shift *= 2
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _rotvec_quat(v):
    """Quaternions of rotation vectors ``(n, 3)`` (rad)."""
    ang = np.linalg.norm(v, axis=1)
    sinc = np.where(ang > 0, np.sin(0.5 * ang) / np.where(ang > 0, ang, 1.0), 0.5)
    return np.concatenate([np.cos(0.5 * ang)[:, None], sinc[:, None] * v], axis=1)


def _quat_to_mat(q):
    """Rotation matrices from unit quaternions, ``(n, 4)`` -> ``(n, 3, 3)``."""
    w, x, y, z = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
        ],
        axis=1,
    )


def _step_means(t, values, tg):
    """Means of a sampled quantity over the steps ``[tg[k], tg[k+1]]`` (trapezoid), ``(m-1, k)``."""
    v = np.asarray(values, float).reshape(len(t), -1)
    cum = np.concatenate([np.zeros((1, v.shape[1])), np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t)[:, None], axis=0)])
    at = np.stack([np.interp(tg, t, cum[:, c]) for c in range(v.shape[1])], axis=1)
    return np.diff(at, axis=0) / np.diff(tg)[:, None]


def specific_force_fixed_frame(time, specific_force_t, angular_rate_t, dt):
    """IMU specific force on a frame that does not rotate with the triad, on a ``dt`` grid.

    The gyros are integrated from the first sample (rotation per grid step from the mean rate,
    quaternion products); ``f`` is resolved on that frame. It is fixed in inertial space up to
    the gyro errors, so smoothing it over tens of seconds equals smoothing in the navigation
    frame up to the Earth's rotation over the kernel (0.4 deg in 90 s: ~1 mGal in the magnitude),
    whatever the triad does (turns, turbulence). Needs no initial attitude: only magnitudes
    of the smoothed vector are used.

    Parameters
    ----------
    time : ndarray, shape (n,)
        s.
    specific_force_t, angular_rate_t : ndarray, shape (n, 3)
        m/s^2 and rad/s on the triad.
    dt : float
        Grid step, s.

    Returns
    -------
    tg : ndarray, shape (m,)
        Grid times (step midpoints), s.
    f_p : ndarray, shape (m, 3)
        m/s^2.
    """
    t = np.asarray(time, float)
    edges = np.arange(t[0], t[-1], dt)
    if len(edges) < 3:
        return np.zeros(0), np.zeros((0, 3))
    w = _step_means(t, angular_rate_t, edges) * dt  # rotation vector per step, rad
    f = _step_means(t, specific_force_t, edges)
    # attitude at each step's midpoint: all previous steps, then half of this one
    full = _quat_cumprod(_rotvec_quat(w))
    before = np.concatenate([[[1.0, 0.0, 0.0, 0.0]], full[:-1]])
    q = _quat_mul(before, _rotvec_quat(0.5 * w))
    f_p = np.einsum("nij,nj->ni", _quat_to_mat(q), f)
    return edges[:-1] + 0.5 * dt, f_p


def imu_specific_force(time, specific_force_t, t_out, dt, window_s: float = KINEMATIC_WINDOW_S, shift_s=0.0):
    """Smoothed IMU specific-force magnitude ``kernel * |f|`` at ``t_out`` (:func:`smooth_imu`), m/s^2."""
    fm = np.linalg.norm(np.asarray(specific_force_t, float), axis=1)
    return smooth_imu(time, fm, t_out, dt, window_s, shift_s)


def offset_correlator(record):
    """Correlation of the IMU's and the GNSS track's smoothed specific-force magnitudes as a
    function of the lag (:func:`imu_specific_force` against :func:`gnss_specific_force`).

    Returns
    -------
    corr : callable or None
        ``corr(lag_s) -> float``, the correlation with the IMU series read ``lag_s`` later (-inf
        where fewer than 30 samples overlap); None when the flight has too few GNSS fixes or too
        little manoeuvring to correlate.
    step_s : float
        The GNSS's median step, the grid of both series, s.
    span_s : float
        Time the GNSS estimates span, s (0 with ``corr`` None).
    """
    g = record.gnss
    if g is None or len(g.time) < 30:
        return None, 0.0, 0.0
    tm, fg, _ = gnss_specific_force(g.time, g.lat, g.lon, g.height)
    good = np.isfinite(fg)
    tm, fg = tm[good], fg[good]
    if len(tm) < 30 or np.std(fg) < MIN_OFFSET_SIGNAL_MPS2:
        return None, 0.0, 0.0
    dt = float(np.median(np.diff(g.time)))
    imu = record.imu

    # smoothed once; each lag only re-samples it (it is smooth on the scale of the grid)
    ts, sm = smooth_imu(imu.time, np.linalg.norm(np.asarray(imu.specific_force_t, float), axis=1), None, dt)

    def corr(lag):
        fi = np.interp(tm + lag, ts, sm, left=np.nan, right=np.nan)
        ok = np.isfinite(fi)
        if ok.sum() < 30:
            return -np.inf
        a, b = fi[ok] - fi[ok].mean(), fg[ok] - fg[ok].mean()
        den = math.sqrt(float(a @ a) * float(b @ b))
        return float(a @ b) / den if den > 0 else -np.inf

    return corr, dt, float(tm[-1] - tm[0])


def estimate_time_offset(record, max_lag_s: float = 30.0, step_s: float = 0.05, centre_s: float = 0.0, correlator=None):
    """IMU-GNSS clock offset by cross-correlating the specific-force magnitudes (lags within
    ``max_lag_s`` of ``centre_s``). ``correlator``: the record's :func:`offset_correlator`
    when the caller has it (built here otherwise).

    Returns
    -------
    offset_s : float or None
        IMU time minus GNSS time of the same instant, s (positive: IMU stamps late); None when
        the flight has too little manoeuvring to measure it.
    corr : float
        Correlation at the best lag (NaN when not measured).
    """
    corr, dt, _ = correlator or offset_correlator(record)
    if corr is None:
        return None, float("nan")
    coarse = centre_s + np.arange(-max_lag_s, max_lag_s + 1e-9, max(dt / 2, 0.5))
    c = np.array([corr(x) for x in coarse])
    k = int(np.argmax(c))
    fine = np.arange(coarse[k] - 1.0, coarse[k] + 1.0 + 1e-9, step_s)
    cf = np.array([corr(x) for x in fine])
    k = int(np.argmax(cf))
    best, cbest = float(fine[k]), float(cf[k])
    if 0 < k < len(fine) - 1:  # parabolic refinement
        y0, y1, y2 = cf[k - 1], cf[k], cf[k + 1]
        d = y0 - 2 * y1 + y2
        if d < 0:
            best += 0.5 * step_s * (y0 - y2) / d
    if cbest < MIN_OFFSET_CORRELATION:
        return None, cbest
    return best, cbest


def time_offset_evidence(record, corr_best: float, within_s: float, step_s: float = 0.05, correlator=None) -> float:
    """How much better the best lag fits than any lag within ``within_s`` of zero.

    The fit of the GNSS series on the lagged IMU series leaves ``1 - r^2`` of its variance; the
    statistic is ``n_eff (r_best^2 - r_within^2) / (1 - r_best^2)``, an F-like ratio with one
    degree of freedom, where ``n_eff`` counts independent samples as the span over the smoothing
    kernel's length (``3 KINEMATIC_WINDOW_S``). A correlation curve that is flat over a second
    (a flight with little manoeuvring whose anomaly, which the GNSS track does not see, is much
    of the IMU's signal: measured +0.51 s with r = 0.91 on a flight with no offset, r = 0.9090 at
    zero) gives ~0 however far its peak lies.

    Parameters
    ----------
    record : FlightRecord
        With GNSS.
    corr_best : float
        Correlation at the measured offset (:func:`estimate_time_offset`).
    within_s : float
        Tolerated offset, s (``checks.max_time_offset_s``).
    correlator : tuple, optional
        The record's :func:`offset_correlator` when the caller has it (built here otherwise).

    Returns
    -------
    float
        The statistic (inf when no lag within the tolerance can be correlated; 0 when the best
        lag lies within it).
    """
    corr, _, span = correlator or offset_correlator(record)
    if corr is None:
        return 0.0
    c_in = max(corr(x) for x in np.arange(-within_s, within_s + 1e-9, step_s))
    if not np.isfinite(c_in):
        return float("inf")
    n_eff = span / (3.0 * KINEMATIC_WINDOW_S)
    return float(n_eff * max(corr_best**2 - c_in**2, 0.0) / max(1.0 - corr_best**2, 1e-12))


# ----------------------------------------------------------------------------- input consistency
def gravity_mismatch(record, time, lat, lon, height, ellipsoid=WGS84, window_s: float = GRAVITY_WINDOW_S):
    """Median of the IMU specific-force magnitude minus the GNSS-implied one, m/s^2.

    The GNSS side (:func:`gnss_specific_force`) is ``|kernel * f|`` of a vector on Earth-fixed
    axes; the IMU's ``f`` is put on fixed axes by integrating its gyros
    (:func:`specific_force_fixed_frame`) and smoothed alike. Smoothing the magnitude instead
    (``kernel * |f|``) is biased high by turbulence (+6200 mGal on the simulated turbulent survey),
    smoothing on the triad's axes biased low by its rotation (-150 mGal at 1 deg attitude wobble).
    A large gyro bias smears the fixed axes (about -550 mGal at 2.7e-3 rad/s, a MEMS gyro): see
    :func:`check_gnss_consistency` for how that is kept from failing a flight.

    Parameters
    ----------
    record : FlightRecord
        For the IMU.
    time, lat, lon, height : ndarray, shape (n,)
        A GNSS track (s, rad, rad, m) - the record's, or a hypothesis about its columns.

    Returns
    -------
    diff : float
        m/s^2; NaN when fewer than 10 epochs overlap.
    n : int
        Epochs used.
    """
    tm, fg, _ = gnss_specific_force(time, lat, lon, height, window_s, ellipsoid)
    if len(tm) == 0:
        return float("nan"), 0
    dt = float(np.median(np.diff(time)))
    imu = record.imu
    tp, f_p = specific_force_fixed_frame(imu.time, imu.specific_force_t, imu.angular_rate_t, dt)
    if len(tp) < 10:
        return float("nan"), 0
    fi = np.linalg.norm(smooth_imu(tp, f_p, tm, dt, window_s), axis=1)
    ok = np.isfinite(fi) & np.isfinite(fg)
    if ok.sum() < 10:
        return float("nan"), int(ok.sum())
    return float(np.median(fi[ok] - fg[ok])), int(ok.sum())


#: The ``units`` setting that reads the file as written, per unit mix-up of
#: :func:`mismatch_hints` (a swap of columns has none: the column names are given instead).
MIX_UP_UNITS = {
    "latitude/longitude in radians but declared as degrees": "latlon: rad",
    "height in feet but declared as metres": "height: ft",
    "height in metres but declared as feet": "height: m",
}


def mismatch_hints(record, ellipsoid=WGS84):
    """Column mix-ups of the GNSS channel that would make its track agree with the IMU.

    Each hypothesis (lat/lon swapped, radians declared as degrees, feet <-> metres) is applied
    to the track and :func:`gravity_mismatch` recomputed.

    Returns
    -------
    list of (str, float)
        Hypothesis and its |mismatch|, m/s^2.
    """
    g = record.gnss
    t, lat, lon, h = (np.asarray(x, float) for x in (g.time, g.lat, g.lon, g.height))
    cands = []
    if np.all(np.abs(lon) <= math.pi / 2):
        cands.append(("latitude and longitude swapped", (lon, lat, h)))
    if np.all(np.abs(np.degrees(lat)) <= math.pi / 2):
        cands.append(("latitude/longitude in radians but declared as degrees", (np.degrees(lat), np.degrees(lon), h)))
    cands.append(("height in feet but declared as metres", (lat, lon, h * 0.3048)))
    cands.append(("height in metres but declared as feet", (lat, lon, h / 0.3048)))
    return [(name, abs(gravity_mismatch(record, t, *x, ellipsoid)[0])) for name, x in cands]


def _common_shift(record, max_lag_s: float = 30.0, tol: float = 0.01):
    """IMU start minus GNSS start when both ends of the two records are offset alike (within
    ``tol`` of the span) by more than ``max_lag_s``, s; else None."""
    spans = channel_spans(record)
    if "gnss" not in spans:
        return None
    a0, a1 = spans["imu"]
    b0, b1 = spans["gnss"]
    d0, d1 = a0 - b0, a1 - b1
    if abs(d0) > max_lag_s and abs(d0 - d1) <= tol * max(a1 - a0, b1 - b0):
        return 0.5 * (d0 + d1)
    return None


def check_gnss_consistency(
    record,
    names: ChannelNames,
    opts: CheckOptions,
    ellipsoid=WGS84,
    initial_raw: dict | None = None,
    initial_key: str = "initial",
) -> list[str]:
    """GNSS positions against themselves and the IMU motion.

    * Ground speed from the GNSS track at most ``MAX_GROUND_SPEED_MPS``.
    * Median of (IMU |f| - GNSS-implied |f|) (:func:`gravity_mismatch`) within
      ``max_gravity_mismatch_mgal``: the IMU measures normal gravity at the true latitude and
      height (plus the anomaly and the accelerometer bias); a swapped or radian latitude or a
      height in feet moves normal gravity by 1000-4000 mGal. Beyond the limit it is an error
      naming the columns when a mix-up explains it (:func:`mismatch_hints`) or when it exceeds
      ``GROSS_MISMATCH_FACTOR`` times the limit; otherwise a note (the IMU may be the cause).
    * IMU-GNSS time offset within ``max_time_offset_s`` (when measurable).
    * The ``initial`` block near the GNSS track at the first IMU sample (:func:`check_initial`).

    Raises
    ------
    DataError
        Naming the file and column and what was expected.

    Returns
    -------
    list of str
        Notes (e.g. the measured offset, or that it could not be measured).
    """
    g = record.gnss
    notes = []
    if g is None or len(g.time) < 30:
        return notes
    h_c = names.column("gnss", "height")
    latlon_c = names.column("gnss", "lat", "lon")
    tm, _, speed = gnss_specific_force(g.time, g.lat, g.lon, g.height, KINEMATIC_WINDOW_S, ellipsoid)
    if len(tm) == 0:
        return notes
    if not np.isfinite(speed).any():
        return notes
    vmax = float(np.nanpercentile(speed, 99))
    if vmax > MAX_GROUND_SPEED_MPS:
        raise DataError(
            f"{latlon_c}: the GNSS track moves at {vmax:.4g} m/s (99th percentile), "
            f"expected at most {MAX_GROUND_SPEED_MPS:g} m/s for an aircraft or ship: "
            "wrong scale or unit of the positions, or jumps in them"
        )
    diff, n = gravity_mismatch(record, g.time, g.lat, g.lon, g.height, ellipsoid)
    tol = opts.max_gravity_mismatch_mgal * MGAL
    if np.isfinite(diff) and abs(diff) > tol:
        # a column mix-up that explains the mismatch is an error naming it; so is a gross
        # mismatch; a moderate one without an explanation may be the IMU (accelerometer bias or
        # scale, a MEMS gyro smearing the axes) and is a note, not a failed flight
        good = [
            name
            for name, res in sorted(mismatch_hints(record, ellipsoid), key=lambda x: x[1])
            if res < max(tol, 0.3 * abs(diff))
        ]
        what = (
            f"the IMU measures a specific force {diff / MGAL:+.0f} mGal off the one the GNSS track and "
            f"normal gravity imply (median over {n} epochs; expected within "
            f"{opts.max_gravity_mismatch_mgal:g} mGal, checks.max_gravity_mismatch_mgal)"
        )
        if good:
            cols = h_c if "height" in good[0] else latlon_c
            fix = MIX_UP_UNITS.get(good[0])
            raise DataError(f"{cols}: {what}: {good[0]}?" + (f" (set {names.section}.units.{fix})" if fix else ""))
        if abs(diff) > GROSS_MISMATCH_FACTOR * tol:
            raise DataError(
                f"{names.column('gnss', 'lat', 'lon', 'height')}: {what}: wrong latitude, height "
                "unit or accelerometer scale?"
            )
        notes.append(
            f"gnss vs imu: {what}; no column mix-up explains it and it is less than "
            f"{GROSS_MISMATCH_FACTOR:g} x the limit: accelerometer bias or scale, or a gyro too poor "
            "for the check?"
        )
    elif (
        np.isfinite(diff)
        and abs(diff) >= UNIT_HINT_MIN_MGAL * MGAL
        and (
            unit := [
                (name, res)
                for name, res in mismatch_hints(record, ellipsoid)
                if "height" in name and res < UNIT_HINT_FRACTION * abs(diff)
            ]
        )
    ):
        # a warning, not an error: an accelerometer bias of the same size (a MEMS IMU) would be
        # refused with no way to accept it
        name, res = unit[0]
        notes.append(
            f"{h_c}: the IMU measures a specific force {diff / MGAL:+.0f} mGal off the one the GNSS track and "
            f"normal gravity imply (median over {n} epochs), and {res / MGAL:.0f} mGal with the heights "
            f"converted the other way: {name}? (then set {names.section}.units.{MIX_UP_UNITS[name]}; else an "
            "accelerometer bias that large; the product's level and its vertical accelerations follow the heights)"
        )
    elif np.isfinite(diff):
        # a passed check is a fact for summary.json, not a warning: a good flight prints nothing
        notes.append(
            f"{PASSED}gnss vs imu: median specific-force difference {diff / MGAL:+.1f} mGal "
            f"(limit {opts.max_gravity_mismatch_mgal:g})"
        )
    # the IMU's series smoothed once for the search, the search at the records' shift and the
    # verdict's evidence
    cor = offset_correlator(record)
    off, c = estimate_time_offset(record, correlator=cor)
    shift = _common_shift(record)
    if (off is None or not c >= OFFSET_VERDICT_CORRELATION) and shift is not None:
        # both ends of the GNSS record offset alike from the IMU's by more than the search: a
        # clock (or time zone) out of step, if the specific forces agree there
        off2, c2 = estimate_time_offset(record, centre_s=shift, correlator=cor)
        # and clearly better than at the lags near zero (a grid's turns repeat with its lines)
        if off2 is not None and c2 >= OFFSET_VERDICT_CORRELATION and not c2 <= c + 0.05:
            off, c = off2, c2
    if off is None:
        notes.append(f"{PASSED}imu-gnss time offset: not measurable (too little manoeuvring to correlate)")
    else:
        t0 = record.t0_unix_ns
        a0, a1 = channel_spans(record)["imu"]
        b0, b1 = channel_spans(record)["gnss"]
        txt = (
            f"imu ({names.files.get('imu', 'imu')}) {span_text(t0, a0, a1)} runs {off:+.2f} s "
            f"relative to gnss ({names.files.get('gnss', 'gnss')}) {span_text(t0, b0, b1)} "
            f"(cross-correlation of specific force, r = {c:.2f})"
        )
        beyond = abs(off) > opts.max_time_offset_s
        evidence = time_offset_evidence(record, c, opts.max_time_offset_s, correlator=cor) if beyond else 0.0
        if beyond and c >= OFFSET_VERDICT_CORRELATION and evidence >= OFFSET_VERDICT_EVIDENCE:
            raise DataError(
                f"{txt}; expected within {opts.max_time_offset_s:g} s (checks.max_time_offset_s): clocks out of step "
                f"(if they are known to differ, as GPS time runs 18 s ahead of UTC, give the flight "
                f"time_offsets_s: {{gnss: {off:+.2f}}})"
            )
        if beyond and evidence < OFFSET_NOTE_EVIDENCE:
            notes.append(
                f"{PASSED}time offset: {txt}; beyond {opts.max_time_offset_s:g} s, but the lags within it fit as "
                f"well (evidence {evidence:.2f} < {OFFSET_NOTE_EVIDENCE:g}): no offset shown"
            )
        elif beyond:
            # a weak correlation (turbulence on a strapdown triad) can place the peak a few
            # tenths off on a flight with no offset at all (measured -0.63 s, r = 0.81), and so
            # can a flat one (+0.51 s, r = 0.91, with r = 0.909 at zero): say it
            why = (
                f"the correlation is below {OFFSET_VERDICT_CORRELATION:g}"
                if c < OFFSET_VERDICT_CORRELATION
                else f"lags within it fit almost as well (evidence {evidence:.1f} < {OFFSET_VERDICT_EVIDENCE:g})"
            )
            notes.append(
                f"time offset: {txt}; beyond {opts.max_time_offset_s:g} s but {why}: not a verdict, check the clocks"
            )
        else:
            notes.append(f"{PASSED}time offset: {txt}")
    if initial_raw:
        notes += check_initial(record, initial_raw, initial_key, ellipsoid)
    return notes


def check_initial(
    record,
    initial_raw: dict,
    key: str,
    ellipsoid=WGS84,
    max_horizontal_m: float = 1000.0,
    max_vertical_m: float = 100.0,
    max_velocity_mps: float = 10.0,
) -> list[str]:
    """The configured ``initial`` position against GNSS at the first IMU sample.

    Raises
    ------
    DataError
        Naming ``<key>.lat_deg`` / ``lon_deg`` / ``height_m`` when it is more than
        ``max_horizontal_m`` / ``max_vertical_m`` from the GNSS track, or
        ``<key>.velocity_enu_mps`` more than ``max_velocity_mps`` from the GNSS velocity (a
        10 s fit, :func:`gravsurvey.inm.params.initial_state_from_gnss`).
    """
    g = record.gnss
    t0 = float(record.imu.time[0])
    if g is None or len(g.time) < 3 or not (g.time[0] - 10.0 <= t0 <= g.time[-1]):
        return []
    lat = float(np.interp(t0, g.time, g.lat))
    lon = float(np.interp(t0, g.time, np.unwrap(g.lon)))
    h = float(np.interp(t0, g.time, g.height))
    try:
        ilat, ilon, ih = (
            math.radians(float(initial_raw["lat_deg"])),
            math.radians(float(initial_raw["lon_deg"])),
            float(initial_raw["height_m"]),
        )
    except (KeyError, TypeError, ValueError):
        return []
    r = geodetic_to_ecef(np.array([lat, ilat]), np.array([lon, ilon]), np.array([h, h]), ellipsoid)
    dist = float(np.linalg.norm(r[1] - r[0]))
    if dist > max_horizontal_m:
        bad = "lat_deg" if abs(ilat - lat) * 6.4e6 > max_horizontal_m / 2 else "lon_deg"
        raise DataError(
            f"{key}.{bad}: the initial position ({math.degrees(ilat):.6f}, {math.degrees(ilon):.6f} "
            f"deg) is {dist / 1000:.3g} km from the GNSS track at the first IMU sample "
            f"({math.degrees(lat):.6f}, {math.degrees(lon):.6f} deg); expected within "
            f"{max_horizontal_m:g} m"
        )
    if abs(ih - h) > max_vertical_m:
        raise DataError(
            f"{key}.height_m: {ih:g} m is {ih - h:+.1f} m from the GNSS height {h:.1f} m at the "
            f"first IMU sample; expected within {max_vertical_m:g} m"
        )
    vel = initial_raw.get("velocity_enu_mps")
    if vel is not None and g.time[0] <= t0 + 1.0:
        from .inm.params import initial_state_from_gnss

        try:
            v_gnss = initial_state_from_gnss(record, "platform").vel_n
            dv = float(np.linalg.norm(np.asarray(vel, float) - v_gnss))
        except (GravsurveyError, ValueError, TypeError):
            return []
        if dv > max_velocity_mps:
            raise DataError(
                f"{key}.velocity_enu_mps: {list(map(float, vel))} m/s is {dv:.3g} m/s from the GNSS "
                f"velocity [{v_gnss[0]:.2f}, {v_gnss[1]:.2f}, {v_gnss[2]:.2f}] m/s at the first IMU "
                f"sample (10 s fit); expected within {max_velocity_mps:g} m/s"
            )
    return []


# ----------------------------------------------------------------------------- gaps and segments
def find_gaps(time, max_gap_s: float):
    """Steps of a channel longer than ``max_gap_s``: list of ``(t_before, t_after)``, s."""
    t = np.asarray(time, float)
    if len(t) < 2:
        return []
    i = np.flatnonzero(np.diff(t) > max_gap_s)
    return [(float(t[k]), float(t[k + 1])) for k in i]


def _aiding_gaps(record, max_gap_s):
    """Intervals longer than ``max_gap_s`` without any altimeter or GNSS sample."""
    ts = [np.asarray(record.altimeter.time, float)]
    if record.gnss is not None and len(record.gnss.time):
        ts.append(np.asarray(record.gnss.time, float))
    t = np.unique(np.concatenate(ts))
    a0, a1 = float(record.imu.time[0]), float(record.imu.time[-1])
    # no aiding at the start or end of the IMU span counts too
    t = np.concatenate([[a0] if t[0] - a0 > max_gap_s else [], t, [a1] if a1 - t[-1] > max_gap_s else []])
    return find_gaps(t, max_gap_s)


def plan_segments(record, opts: CheckOptions, names: ChannelNames | None = None, start_given: bool = False):
    """Split a flight at long IMU gaps and long gaps of all vertical aiding; start it at a late
    first GNSS fix when the aircraft moved before it.

    A first GNSS fix more than ``alignment.MAX_GNSS_LEAD_S`` after the first IMU sample places
    the IMU's start only when the IMU rests until past the fix
    (:func:`gravsurvey.inm.alignment.rest_through_gnss_lead`); otherwise the samples before the
    fix are not estimated (no position to start from: extrapolated back over 150 s of taxi and
    take-off, the start was 21 km off and the product 43 mGal wrong), and said.

    Parameters
    ----------
    record : FlightRecord
    opts : CheckOptions
    names : ChannelNames, optional
    start_given : bool
        The config gives the position and velocity at the first IMU sample (``initial``): the
        record is kept from its start whatever the GNSS.

    Returns
    -------
    segments : list of (float, float)
        ``(t_start, t_end)`` of each segment to estimate, s (inclusive IMU sample times).
    notes : list of str
        What was split or bridged, with channel names and UTC ranges.
    dropped : list of str
        Pieces too short to estimate (data lost: reported as a data problem).
    """
    t0 = record.t0_unix_ns
    imu_t = np.asarray(record.imu.time, float)
    cuts = []  # (gap start, gap end, what)
    notes = []
    fi = names.files.get("imu", "imu") if names else "imu"
    for a, b in find_gaps(imu_t, opts.max_imu_gap_s):
        cuts.append((a, b, f"imu gap ({fi}) {span_text(t0, a, b)}"))
    for a, b in _aiding_gaps(record, opts.max_aiding_gap_s):
        cuts.append((a, b, f"no altimeter or gnss samples {span_text(t0, a, b)}"))
    # bridged gaps: longer than 5 nominal steps but within the limit
    if len(imu_t) > 2:
        nom = float(np.median(np.diff(imu_t)))
        short = [(a, b) for a, b in find_gaps(imu_t, 5 * nom) if b - a <= opts.max_imu_gap_s]
        if short:
            notes.append(
                f"imu: {len(short)} gaps of {5 * nom:.3g}-{opts.max_imu_gap_s:g} s bridged by the "
                f"mechanization (longest {max(b - a for a, b in short):.2f} s)"
            )
    cuts.sort()
    merged = []  # overlapping gaps of several channels are one cut
    for a, b, what in cuts:
        if merged and a <= merged[-1][1]:
            merged[-1] = (merged[-1][0], max(b, merged[-1][1]), merged[-1][2] + " and " + what)
        else:
            merged.append((a, b, what))
    segs = []
    start = imu_t[0]
    from .inm.alignment import MAX_GNSS_LEAD_S, gnss_lead_s, rest_through_gnss_lead

    lead = gnss_lead_s(record)
    if lead > MAX_GNSS_LEAD_S and not start_given and not rest_through_gnss_lead(record):
        start = imu_t[0] + lead
        fg = names.files.get("gnss", "gnss") if names else "gnss"
        notes.append(
            f"the first GNSS fix ({fg}) comes {lead:.1f} s after the first IMU sample and the aircraft "
            f"moved before it: {span_text(t0, float(imu_t[0]), start)} not estimated (no position to start from; "
            "give the flight's initial position and velocity at the first IMU sample to use it)"
        )
    for a, b, what in merged:
        a = max(a, start)
        if a > start:
            segs.append((start, a))
        start = max(start, b)
        notes.append(f"split at {what}")
    segs.append((start, imu_t[-1]))
    keep, dropped = [], []
    for a, b in segs:
        n = int(np.count_nonzero((imu_t >= a) & (imu_t <= b)))
        if b - a >= MIN_SEGMENT_S and n >= 8:
            keep.append((float(a), float(b)))
        elif b > a or n:
            dropped.append(
                f"segment {span_text(t0, a, b)} between gaps is shorter than {MIN_SEGMENT_S:g} s: not estimated"
            )
    if not keep:
        splits = "; ".join(n for n in notes if n.startswith("split"))
        # without a split the whole record is short: its time stamps may be in other units
        why = splits or (
            f"the IMU samples span {imu_t[-1] - imu_t[0]:.3g} s, {span_text(t0, float(imu_t[0]), float(imu_t[-1]))}: "
            "a record that short, or time stamps in other units (milliseconds written as nanoseconds? csv.time_format)"
        )
        raise DataError(
            f"{record.source or 'record'}: no piece of the flight between gaps is at least {MIN_SEGMENT_S:g} s long ({why})"
        )
    return keep, notes, dropped


# ----------------------------------------------------------------------------- result plausibility
def track_deviation_m(sol, record, ellipsoid=WGS84):
    """Horizontal distance of the navigation from the GNSS track at the solution epochs, m.

    Returns
    -------
    ndarray, shape (N,)
        NaN where GNSS has no sample within 2 s or the solution is NaN.
    """
    g = record.gnss
    t = np.asarray(sol.time, float)
    if g is None or len(g.time) < 2:
        return np.full(len(t), np.nan)
    glat, glon, gh = record.gnss_on(t, max_gap_s=2.0)
    r_nav = geodetic_to_ecef(sol.lat, sol.lon, gh, ellipsoid)
    r_gn = geodetic_to_ecef(glat, glon, gh, ellipsoid)
    return np.linalg.norm(r_nav - r_gn, axis=1)


def check_result(
    name: str, final_mps2, in_line, sol, record, opts: CheckOptions, n_lines: int, ellipsoid=WGS84
) -> list[str]:
    """Plausibility of a flight's product; DataError naming the cause unless allowed.

    Parameters
    ----------
    name : str
        Flight name (for messages).
    final_mps2 : ndarray, shape (N,)
        Post-processed disturbance, m/s^2 (NaN outside lines).
    in_line : ndarray of bool, shape (N,)
        Epochs on survey lines.
    sol : gravsurvey.estimate.FlightEstimate
        The flight's estimate (epochs with ``segment`` -1 are gaps and not checked).
    n_lines : int
        Number of survey/tie lines found.

    Returns
    -------
    list of str
        Notes (e.g. the largest track deviation).
    """
    notes = []
    if n_lines == 0 and not opts.allow_no_lines:
        raise DataError(
            f"{name}: no survey lines found (straight, level, steady-speed pieces of at least "
            "the lines.min_line_s); nothing to deliver (set checks.allow_no_lines: true to accept)"
        )
    valid = np.asarray(sol.segment) >= 0
    fin = np.asarray(final_mps2, float)
    bad = in_line & valid & ~np.isfinite(fin)
    series = [
        ("kalman estimate", sol.smoothed),
        ("unfiltered reduction", sol.unfiltered),
        ("sigma", sol.sigma),
        ("latitude", sol.lat),
        ("longitude", sol.lon),
        ("height", sol.height),
    ]
    for label, arr in ((lb, a) for lb, a in series if a is not None):
        arr = np.asarray(arr, float)
        if label == "sigma" and not np.isfinite(arr).any():
            continue  # a method without a sigma (classic) reports NaN throughout by design
        nb = int(np.count_nonzero(valid & ~np.isfinite(arr)))
        if nb and not opts.allow_nonfinite:
            raise DataError(
                f"{name}: the {label} has {nb} non-finite values of {int(valid.sum())} epochs "
                "(set checks.allow_nonfinite: true to accept)"
            )
    if bad.any() and not opts.allow_nonfinite:
        raise DataError(
            f"{name}: the final disturbance has {int(bad.sum())} non-finite values on lines "
            "(set checks.allow_nonfinite: true to accept)"
        )
    absf = np.where(in_line & np.isfinite(fin), np.abs(fin), -np.inf)
    if np.isfinite(absf).any():
        k = int(np.argmax(absf))
        vmax = float(absf[k]) / MGAL
        if vmax > opts.max_abs_disturbance_mgal:
            raise DataError(
                f"{name}: |disturbance| reaches {vmax:.4g} mGal at t = {sol.time[k]:.1f} s; "
                f"expected at most {opts.max_abs_disturbance_mgal:g} mGal "
                "(checks.max_abs_disturbance_mgal)"
            )
    if sol.estimator.get("gnss_aided", False):
        # running median over TRACK_WINDOW epochs: a few GNSS outliers (multipath) are not a
        # navigation that left the track
        raw = track_deviation_m(sol, record, ellipsoid)
        dev = np.full(len(raw), np.nan)
        if len(raw) >= TRACK_WINDOW:
            win = np.lib.stride_tricks.sliding_window_view(raw, TRACK_WINDOW)
            with np.errstate(all="ignore"):
                ok = np.isfinite(win).sum(axis=1) > TRACK_WINDOW // 2
                med = np.full(len(win), np.nan)
                if ok.any():
                    med[ok] = np.nanmedian(win[ok], axis=1)
            dev[TRACK_WINDOW // 2 : TRACK_WINDOW // 2 + len(win)] = med
        if np.isfinite(dev).any():
            dmax = float(np.nanmax(dev))
            if dmax > opts.max_track_deviation_m:
                k = int(np.nanargmax(dev))
                raise DataError(
                    f"{name}: the navigation left the GNSS track by {dmax:.4g} m at t = "
                    f"{sol.time[k]:.1f} s; expected within {opts.max_track_deviation_m:g} m "
                    "(checks.max_track_deviation_m)"
                )
            notes.append(f"{PASSED}{name}: navigation within {dmax:.3g} m of the GNSS track")
    return notes
