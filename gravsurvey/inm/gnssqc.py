"""GNSS stamps late (or early) against the IMU: found on the aided track, taken off.

A receiver that stamps its positions when it outputs them, not when it measured them, or a
logger that stamps them on arrival, makes them late by tens to hundreds of milliseconds. At
70 m/s a 0.1-s latency puts the GNSS position 7 m behind the aircraft; the filter bends the
navigation towards it at every turn and speed change, and the vertical channel pays: quick U001
of the unseen suite (strapdown) went from 0.56 to 2.44 mGal at 0.2 s and 7.3 mGal at 0.45 s,
with exit 0, under the 0.5-s limit of the clock check (``checks.max_time_offset_s``, a
cross-correlation of specific-force magnitudes, too coarse for tenths of a second).

After the first pass the smoothed navigation follows the IMU over seconds (the accelerometers
hold it) and the GNSS positions over minutes. Positions stamped ``L`` late give
``r_ins(t) - r_gnss(t) ~ dr(t) + L v(t)``; over ten seconds ``dr`` hardly changes while the
velocity turns and surges, so ``L`` is the slope of the high-passed horizontal residual on the
high-passed horizontal velocity (:func:`gravsurvey.inm.heightqc.estimate_latency`, the height
channel's regression, both axes pooled). The vertical axis is left out: the GNSS height's
noise and the altimeter's own share of the vertical channel make it the weakest. A clock
running slow or fast makes the latency change over the flight: a second regressor, the velocity
times the time from the record's middle, gives its rate (:class:`GnssLatency`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..geodesy import STANDARD_GRAVITY_MPS2
from ..io.checks import robust_sigma
from .heightqc import estimate_latency, estimate_latency_drift
from .identify import edge_samples, running_mean

__all__ = [
    "GnssLatency",
    "GnssLeverArm",
    "estimate_gnss_lever_arm",
    "track_attitude",
    "estimate_gnss_latency",
    "gnss_latency_fit",
    "latency_is_clear",
    "drift_is_clear",
    "shift_gnss",
]

#: Window of the running mean taken off the horizontal residual and velocity, s: the smoothed
#: navigation follows the GNSS positions over longer spans (at 30 s a 0.1-s latency reads as
#: 0.08 s, at 100 s as 0.04 s; at 10 s as 0.097 on quick U001, 0.11 on U214, 0.10 on U006).
LATENCY_HIGHPASS_S = 10.0
#: Residuals beyond this many robust sigmas of the first fit are bridged and left out of a
#: second (``estimate_latency``'s ``outlier_k``): GNSS fixes 30 m off on 0.3 % of the epochs read
#: as 0.044 s of latency on quick U214 with one fit (3.4 standard errors), 0.002 s with two.
LATENCY_OUTLIER_K = 5.0
#: A latency is taken off the GNSS stamps when it is this many standard errors from zero ...
LATENCY_K = 4.0
#: ... and at least this long, s: below it the position error ``v L`` is within a GNSS sigma
#: (at 70 m/s, 0.02 s is 1.4 m, a few tenths of a mGal at most; measured in docs/benchmarks.md).
LATENCY_MIN_S = 0.02
#: Longest latency taken off, s: the regression is linear in ``L`` (0.45 s read as 0.44-0.46);
#: an offset beyond is the clock check's (``checks.max_time_offset_s``), a DataError.
LATENCY_MAX_S = 1.0


def estimate_gnss_latency(time, residual_en_m, velocity_en_mps):
    """How late the GNSS stamps are against the IMU, s, and its standard error.

    Parameters
    ----------
    time : ndarray (k,)
        GNSS epochs, s.
    residual_en_m : ndarray (k, 2)
        Smoothed navigation minus GNSS position, east and north, m.
    velocity_en_mps : ndarray (k, 2)
        The navigation's east and north velocity at those epochs, m/s.

    Fixes far off the fit (multipath, a wrong ambiguity) are bridged and left out of a second
    fit (:data:`LATENCY_OUTLIER_K`).

    Returns
    -------
    latency_s, sigma_s : float
        Positive: the stamps are late. NaN when there is nothing to regress on (fewer than 32
        epochs, or no change of velocity).
    """
    return estimate_latency(
        time, residual_en_m, velocity_en_mps, highpass_s=LATENCY_HIGHPASS_S, outlier_k=LATENCY_OUTLIER_K
    )


def latency_is_clear(latency_s: float, sigma_s: float) -> bool:
    """True when a latency estimate is worth taking off (:data:`LATENCY_K`, :data:`LATENCY_MIN_S`,
    :data:`LATENCY_MAX_S`)."""
    return (
        math.isfinite(latency_s)
        and math.isfinite(sigma_s)
        and abs(latency_s) >= max(LATENCY_K * sigma_s, LATENCY_MIN_S)
        and abs(latency_s) <= LATENCY_MAX_S
    )


def drift_is_clear(rate: float, rate_sigma: float, span_s: float) -> bool:
    """True when a latency drift (s per s of record) is worth taking off: :data:`LATENCY_K`
    standard errors from zero and changing the latency by at least :data:`LATENCY_MIN_S` between
    the record's middle and either end."""
    return (
        math.isfinite(rate)
        and math.isfinite(rate_sigma)
        and abs(rate) >= LATENCY_K * rate_sigma
        and abs(rate) * 0.5 * span_s >= LATENCY_MIN_S
        and abs(rate) * 0.5 * span_s <= LATENCY_MAX_S
    )


def shift_gnss(gnss, latency_s: float, rate: float = 0.0, t_mid_s: float = 0.0):
    """The GNSS channel with its stamps moved ``latency_s + rate (t - t_mid_s)`` earlier (a copy;
    the stamps only)."""
    t = np.asarray(gnss.time, float)
    return dataclasses.replace(gnss, time=t - (float(latency_s) + float(rate) * (t - float(t_mid_s))))


@dataclasses.dataclass
class GnssLatency:
    """How late the GNSS stamps are against the IMU, as measured on one aided track.

    Attributes
    ----------
    latency_s, sigma_s : float
        A constant latency and its standard error, s (:func:`estimate_gnss_latency`).
    mid_latency_s, mid_sigma_s : float
        With a drift: the latency at the record's middle, s.
    rate, rate_sigma : float
        The latency's change per second of record (a clock running slow or fast), s/s.
    t_mid_s, span_s : float
        The middle and the length of the GNSS epochs used, s.
    """

    latency_s: float = math.nan
    sigma_s: float = math.nan
    mid_latency_s: float = math.nan
    mid_sigma_s: float = math.nan
    rate: float = math.nan
    rate_sigma: float = math.nan
    t_mid_s: float = 0.0
    span_s: float = 0.0

    @property
    def drifts(self) -> bool:
        """The latency changes over the record (:func:`drift_is_clear`)."""
        return drift_is_clear(self.rate, self.rate_sigma, self.span_s)

    @property
    def taken_off(self) -> bool:
        """A constant latency or a drift is clear enough to correct."""
        return self.drifts or latency_is_clear(self.latency_s, self.sigma_s)

    def shift(self, gnss):
        """``gnss`` with the measured latency (and drift) taken off its stamps."""
        if self.drifts:
            return shift_gnss(gnss, self.mid_latency_s, self.rate, self.t_mid_s)
        return shift_gnss(gnss, self.latency_s)

    def report(self) -> dict:
        """summary.json's ``identification.gnss_latency``."""
        out = {"latency_s": self.latency_s, "sigma_s": self.sigma_s, "taken_off": self.taken_off}
        if math.isfinite(self.rate):
            out["drift_ppm"] = self.rate * 1e6
            out["drift_sigma_ppm"] = self.rate_sigma * 1e6
            out["drift_taken_off"] = self.drifts
        return out

    def text(self) -> str:
        """What was taken off, for the flight's warning."""
        if self.drifts:
            return (
                f"stamps {self.mid_latency_s:+.3f} s (+-{self.mid_sigma_s:.3f}) late against the IMU at mid-record, "
                f"drifting {self.rate * 1e6:+.0f} ppm (+-{self.rate_sigma * 1e6:.0f}: a clock running "
                f"{'slow' if self.rate > 0 else 'fast'}, {self.rate * 0.5 * self.span_s:+.3f} s at the end)"
            )
        return f"stamps {self.latency_s:+.3f} s (+-{self.sigma_s:.3f}) late against the IMU"


def gnss_latency_fit(time, residual_en_m, velocity_en_mps) -> GnssLatency:
    """:class:`GnssLatency` of a track: the constant latency and the drifting one
    (:func:`gravsurvey.inm.heightqc.estimate_latency_drift`), both with the outlier refit."""
    t = np.asarray(time, float)
    lat, sig = estimate_gnss_latency(t, residual_en_m, velocity_en_mps)
    mid, mid_sig, rate, rate_sig = estimate_latency_drift(
        t, residual_en_m, velocity_en_mps, highpass_s=LATENCY_HIGHPASS_S, outlier_k=LATENCY_OUTLIER_K
    )
    span = float(t[-1] - t[0]) if t.size else 0.0
    return GnssLatency(lat, sig, mid, mid_sig, rate, rate_sig, 0.5 * float(t[0] + t[-1]) if t.size else 0.0, span)


#: Window of the running mean taken off the residual and the lever-arm regressors, s: the
#: antenna's offset swings with the bank of each turn, over tens of seconds, and the smoothed
#: navigation follows the GNSS positions over minutes. Measured on the strapdown fuzzing flight
#: (5-Hz GNSS of 0.5 m, a 2-m mast): 10 s found 1.58 +- 0.37 m up, 30 s 1.76 +- 0.17,
#: 60 s 1.75 +- 0.08; a 6-m forward offset on test_alignment.py's flight read as 4.2 m at 30 s,
#: 3.6 m at 60 s (the smoothed track takes up the rest; the next fits find it).
LEVER_HIGHPASS_S = 30.0
#: A lever-arm component is applied when it is this many standard errors from zero ...
LEVER_K = 5.0
#: ... and at least this long, m: below it the antenna's swing in a 25-degree bank is under
#: 0.1 m, within the GNSS noise.
LEVER_MIN_M = 0.2
#: Longest lever arm applied, m: beyond it the track's residual is something else (a scale
#: factor, a wrong axis), which the track check names; no aircraft's antenna is further.
LEVER_MAX_M = 15.0
#: Residuals beyond this many robust sigmas of a first fit (a wrong fix) are left out of a second.
LEVER_OUTLIER_K = 5.0


@dataclasses.dataclass
class GnssLeverArm:
    """Where the GNSS antenna is from the IMU, as measured on one aided track.

    Attributes
    ----------
    lever_t, sigma_t : ndarray (3,)
        The antenna's position from the IMU on the aircraft's (FLU) axes and its standard
        errors, m; NaN when not observable (no change of attitude).
    """

    lever_t: np.ndarray = dataclasses.field(default_factory=lambda: np.full(3, math.nan))
    sigma_t: np.ndarray = dataclasses.field(default_factory=lambda: np.full(3, math.nan))

    @property
    def _clear(self) -> np.ndarray:
        """The components :data:`LEVER_K` standard errors and :data:`LEVER_MIN_M` from zero,
        m (3,), zero elsewhere."""
        lv, sg = np.asarray(self.lever_t, float), np.asarray(self.sigma_t, float)
        ok = np.isfinite(lv) & np.isfinite(sg) & (np.abs(lv) >= np.maximum(LEVER_K * sg, LEVER_MIN_M))
        return np.where(ok, lv, 0.0)

    @property
    def clear_t(self) -> np.ndarray:
        """The components worth applying, m (3,), zero elsewhere (:attr:`_clear`); all zero
        when they are beyond :data:`LEVER_MAX_M` (not an antenna's offset)."""
        return np.zeros(3) if self.too_long else self._clear

    @property
    def too_long(self) -> bool:
        """A clear offset beyond :data:`LEVER_MAX_M`: not applied."""
        return bool(np.linalg.norm(self._clear) > LEVER_MAX_M)


def estimate_gnss_lever_arm(time, residual_enu_m, mat_enu_t, highpass_s=LEVER_HIGHPASS_S):
    """Where the GNSS antenna is from the IMU, from an aided track's residual, m, and its
    standard errors.

    An antenna at ``l`` on the triad axes, not told to the filter, makes the navigation (at the
    IMU) minus the GNSS positions (at the antenna) ``-C(t) l`` plus the navigation's own slow
    error: the least-squares fit of the residual on the columns of ``C`` (triad -> ENU), both
    less their running mean over ``highpass_s``, all axes pooled. The antenna's offset moves
    with the attitude (the bank of every turn, the heading between lines) and the navigation's
    error does not. Residuals beyond :data:`LEVER_OUTLIER_K` robust sigmas of a first fit are
    left out of a second. The standard errors come from sums over blocks of ``highpass_s`` with their
    neighbours' (the residual of a real receiver is not white over seconds), never below the
    white residual's.

    Parameters
    ----------
    time : ndarray (k,)
        GNSS epochs, s.
    residual_enu_m : ndarray (k, m)
        Navigation at the IMU minus the GNSS positions on ``m`` of the axes east, north, up
        (m = 2: the horizontal only), m.
    mat_enu_t : ndarray (k, 3, 3)
        The attitude at those epochs, triad -> east, north, up.
    highpass_s : float

    Returns
    -------
    lever_t, sigma_t : ndarray (3,)
        NaN when there is nothing to regress on (fewer than 32 epochs, an attitude that does
        not change), or for a component whose standard error exceeds :data:`LEVER_MAX_M`.
    """
    nan = np.full(3, math.nan), np.full(3, math.nan)
    t = np.asarray(time, float)
    e = np.asarray(residual_enu_m, float)
    if e.ndim == 1:
        e = e[:, None]
    m = e.shape[1]
    a = np.asarray(mat_enu_t, float)[:, :m, :]
    if t.size < 32:
        return nan
    dt = float(np.median(np.diff(t)))
    w = max(3, int(round(highpass_s / max(dt, 1e-9))))
    if t.size <= 2 * w:
        return nan
    y = e - running_mean(e, w)
    x = a - np.stack([np.stack([running_mean(a[:, i, j], w) for j in range(3)], axis=1) for i in range(m)], axis=1)
    # the running mean mixes both sides across a gap and is one-sided at the record's ends: the
    # epochs within half a window of either out
    use = ~edge_samples(t, highpass_s, max(1.0, 3.0 * dt))
    use &= np.all(np.isfinite(y), axis=1) & np.all(np.isfinite(x), axis=(1, 2))
    for refit in (False, True):
        xs, ys = x[use], y[use]
        xtx = np.einsum("kij,kil->jl", xs, xs)
        if xs.shape[0] < 32 or not np.all(np.isfinite(xtx)) or np.linalg.cond(xtx) > 1e12:
            return nan
        beta = np.linalg.solve(xtx, np.einsum("kij,ki->j", xs, ys))
        res = y - np.einsum("kij,j->ki", x, beta)
        if refit:
            break
        scale = robust_sigma(res[use])
        bad = use & np.any(np.abs(res) > LEVER_OUTLIER_K * scale, axis=1)
        if scale <= 0 or not bad.any():
            break
        use &= ~bad
    # the score x^T r summed over blocks of one window, each block's sum with its neighbour's
    # (a Bartlett weighting of the residual's correlation over a window)
    g = np.where(use[:, None], np.einsum("kij,ki->kj", x, res), 0.0)
    block = np.floor((t - t[0]) / highpass_s).astype(int)
    gb = np.zeros((int(block[-1]) + 1, 3))
    np.add.at(gb, block, g)
    meat = gb.T @ gb + 0.5 * (gb[1:].T @ gb[:-1] + gb[:-1].T @ gb[1:])
    bread = np.linalg.inv(xtx)
    cov = bread @ meat @ bread
    # never below the white residual's (a high-passed score's block sums can cancel)
    sig = np.maximum(np.sqrt(np.clip(np.diag(cov), 0.0, None)), robust_sigma(res[use]) * np.sqrt(np.diag(bread)))
    # navigation minus GNSS is -C l; a component known no better than LEVER_MAX_M is not seen
    # (a straight line's attitude hardly changes): NaN, not a figure of kilometres
    seen = sig <= LEVER_MAX_M
    return np.where(seen, -beta, math.nan), np.where(seen, sig, math.nan)


#: Below this ground speed the track gives no heading, m/s: the last one is held (taxi, parked).
TRACK_HEADING_MIN_SPEED_MPS = 10.0
#: Window of the centred running mean over the track's heading rate, s: the bank follows the
#: turn, not the heading's wiggles in turbulence (whose own bank is not the track's). On the
#: fuzzing flight's truth a 2-m mast fitted as 1.57 m with 3 s, 1.85 with 6, 1.94 with 10,
#: 2.00 with 15 (an errors-in-variables bias); a roll-in of a few seconds is spread over it.
TRACK_TURN_WINDOW_S = 10.0
#: Window of the centred running mean over the vertical and horizontal speeds whose ratio is
#: the pitch, s: the aircraft climbs along its flight path, but a gust that heaves it up and
#: down for tens of seconds does not pitch it as much (the simulator's turbulence does not pitch
#: it at all). The gust's flight-path angle taken for the pitch put, with the bank's wiggles, a
#: 1.4-cm error on the lines into the heights of an antenna at [3, -1, 1.5] m: a test flight on
#: a platform with GNSS heights 1.16 mGal against 0.25 at the IMU, 0.54 with this mean.
TRACK_PITCH_WINDOW_S = 60.0


def track_attitude(time, vel_enu_mps):
    """The aircraft's axes from its track: FLU -> ENU (n, 3, 3).

    Heading along the horizontal velocity (crab left out), pitch the flight-path angle, bank
    that of a coordinated turn, ``tan(phi) = v dpsi/dt / g``: the attitude that turns an antenna
    offset on a platform's aircraft, whose triad is levelled and says nothing of the aircraft.

    Parameters
    ----------
    time : ndarray (n,)
        s.
    vel_enu_mps : ndarray (n, 3)
        Velocity relative to the Earth, east, north, up, m/s.
    """
    t = np.asarray(time, float)
    v = np.asarray(vel_enu_mps, float)
    vh = np.hypot(v[:, 0], v[:, 1])
    moving = vh >= TRACK_HEADING_MIN_SPEED_MPS
    psi = np.arctan2(v[:, 0], v[:, 1])
    if moving.any():
        k = np.flatnonzero(moving)
        # hold the last heading where the aircraft is too slow to have one (the first before)
        fill = np.maximum.accumulate(np.where(moving, np.arange(t.size), -1))
        fill[fill < 0] = k[0]
        psi = np.unwrap(psi[fill])
    else:
        psi = np.zeros(t.size)
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    rate = np.gradient(psi, t) if t.size > 1 else np.zeros(t.size)
    w = max(1, int(round(TRACK_TURN_WINDOW_S / max(dt, 1e-9))))
    if 1 < w < t.size:
        rate = np.convolve(np.pad(rate, (w // 2, w - 1 - w // 2), mode="edge"), np.ones(w) / w, mode="valid")
    phi = np.where(moving, np.arctan(vh * rate / STANDARD_GRAVITY_MPS2), 0.0)
    vz, vm = v[:, 2], vh
    wp = max(1, int(round(TRACK_PITCH_WINDOW_S / max(dt, 1e-9))))
    if 1 < wp < t.size:
        box = np.ones(wp) / wp
        pad = (wp // 2, wp - 1 - wp // 2)
        vz = np.convolve(np.pad(vz, pad, mode="edge"), box, mode="valid")
        vm = np.convolve(np.pad(vm, pad, mode="edge"), box, mode="valid")
    theta = np.where(moving, np.arctan2(vz, np.maximum(vm, 1e-9)), 0.0)
    sp, cp = np.sin(psi), np.cos(psi)
    st, ct = np.sin(theta), np.cos(theta)
    fwd = np.stack([sp * ct, cp * ct, st], axis=1)
    left0 = np.stack([-cp, sp, np.zeros_like(sp)], axis=1)
    up0 = np.stack([-sp * st, -cp * st, ct], axis=1)
    # a right turn (heading rate > 0) banks the right wing down: the left axis rises
    c, s = np.cos(phi)[:, None], np.sin(phi)[:, None]
    return np.stack([fwd, c * left0 + s * up0, -s * left0 + c * up0], axis=2)
