"""Identify the estimator's stochastic model from the flight itself.

The 3D-INM Kalman/RTS estimate is only as good as its noise levels and anomaly prior
(``model:`` keys).  A user knows at most a datasheet figure; the rest - the gravimeter's white
noise, the height noise, the anomaly's variance and correlation length - is estimated here from
the flight's own data, by a Whittle (spectral maximum-likelihood) fit of the vertical channel.

The vertical channel in one line
--------------------------------
With the altimeter radius in the gravity model (``radius_source: altimeter``) the mechanized
height ``h_ins`` differs from the measured height ``h_alt = h + eps`` by

    e(t) = h_ins - h_alt,      e'' = f(t) - dg(t) + eps''(t)

where ``f`` is the gravimeter (vertical accelerometer) error and ``dg`` the gravity disturbance
that the normal-gravity model leaves out.  The second difference of ``e`` at the altimeter's
sample spacing ``dt``, ``y_k = (e_{k+1} - 2 e_k + e_{k-1}) / dt^2``, therefore has the two-sided
power spectral density

    S_y(f) = [ 2 s^2 l / (l^2 + (2 pi f)^2) + w^2 * 1 s ] sinc^4(f dt)
             + sigma_eps^2 dt (2 - 2 cos(2 pi f dt))^2 / dt^4

with ``s, l = 1/tau`` the anomaly's Markov sigma and rate in time (the filter's prior; the
spatial rate is ``l / v``), ``w`` the one-second sigma of the vertical white acceleration noise,
``sigma_eps`` the per-sample height noise (``sinc^4`` is the second difference's triangular
average of a continuous process).  The four parameters are found by maximising Whittle's
likelihood ``-sum_k [log S_y(f_k) + I(f_k) / S_y(f_k)]`` over the Hann-tapered periodograms
``I`` of the straight, unaccelerated stretches of the flight (turns couple the horizontal
specific force into the vertical through attitude errors and are left out).  The gravimeter's
slow (Markov) error has the same spectral shape as the anomaly and cannot be told from it within
one flight (seed 004's solvability condition); it is part of ``s, tau``.

The fit is bounded (every parameter within documented physical limits), starts from several
points, and reports each value with a 1-sigma factor from the inverse Hessian of the likelihood.

A fifth parameter, the height wander (a random walk of the height error, ``q / (2 pi f)^2`` in
height: a GNSS solution's slowly varying error over the analysed band), is fitted beside and
kept where the likelihood asks for it (:data:`WALK_MIN_LOG_LR`); the filter, whose height
measurements have white noise, is then given the white sigma that matches it at the chosen
resolution (:func:`filter_height_sigma`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
from dataclasses import dataclass

import numpy as np

from ..geodesy import STANDARD_GRAVITY_MPS2, WGS84, Ellipsoid, ecef_to_geodetic, geodetic_to_ecef, mat_ie
from .params import RADPS_PER_DEGPH

__all__ = [
    "IDENTIFIED_KEYS",
    "SpectralModel",
    "smoother_gain",
    "markov_psd",
    "VerticalFit",
    "vertical_psd",
    "vertical_residual",
    "straight_runs",
    "running_mean",
    "edge_samples",
    "fill_short_gaps",
    "fit_vertical_spectrum",
    "fit_height_wander",
    "identify_params",
    "wiener_resolution_m",
    "filter_height_sigma",
    "wide_prior_params",
    "refine_prior",
    "band_margin",
    "prior_risk",
    "tapered_periodogram",
    "prewhitened_periodogram",
    "smoother_sigma_scale",
    "straight_weight",
    "keep_default_prior",
    "prior_for_resolution",
    "model_resolution_m",
    "spectral_model_of",
    "horizontal_prior",
    "field_attitude_noise_degph",
    "drift_sigma_passed",
    "config_models_drift",
    "white_log_likelihood_ratio",
    "tilt_leak_factor",
    "tilt_leak_exceeds_white",
    "white_less_tilt_leak",
]

#: ``model:`` keys this module identifies (a key given in the config is held fixed instead).
IDENTIFIED_KEYS = ("anomaly_sigma_mps2", "anomaly_lambda_per_m", "gravimeter_white_mps2", "altimeter_sigma_m")

#: Bounds of the fit (SI): anomaly sigma 0.02-1000 mGal, correlation time 5 s - 1 day,
#: white vertical noise 0.001-100 mGal in one second (a MEMS accelerometer's 100 ug/sqrt(Hz)), height noise 0.1 mm - 50 m.
BOUNDS = {
    "anomaly_sigma_mps2": (2e-7, 1e-2),
    "anomaly_tau_s": (5.0, 86400.0),
    "white_mps2": (1e-8, 1e-3),
    "height_sigma_m": (1e-4, 50.0),
    "height_walk_m": (1e-6, 0.3),
}
#: :class:`SpectralModel` fields of the sensors' noise (the others are the anomaly's prior).
NOISE_KEYS = ("white_mps2", "height_sigma_m")
_ORDER = ("anomaly_sigma_mps2", "anomaly_tau_s", "white_mps2", "height_sigma_m")
#: ... and with the height wander (:func:`fit_vertical_spectrum` with ``walk=True``).
_ORDER_WALK = _ORDER + ("height_walk_m",)

#: The height wander (a slowly varying height error: a GNSS solution's ionosphere,
#: troposphere, orbit and multipath errors, minutes long) is taken into the model only when the
#: likelihood prefers it by this much over the white height noise alone.  Over the analysed band
#: (periods of seconds to minutes, above the error's inverse correlation time) such an error is
#: a random walk, ``q / omega^2`` in height, ``q omega^2`` referred to the disturbance - rising
#: with frequency, unlike a field seen from the air; white height noise alone had the filter
#: follow it as field (a 5-cm, 300-s Gauss-Markov GNSS height error: 2.40 mGal at 2 km
#: resolution where the same flight without it gave 0.64 at 14 km; docs/benchmarks.md "A slowly
#: varying GNSS height error").  Without a wander the ratio is about half a chi-square of one
#: degree of freedom (5: a 0.2 % chance); measured on 88 flights without one: under 5 on 87
#: (4.88 and 3.07 the largest, where taking it would give 0.27 -> 0.12 and 0.48 -> 0.60 mGal),
#: 13.9 once (quick U018, where the wander took the place of a white level and the product went
#: 0.32 -> 0.42 mGal).  With 5- and 10-cm wanders, 5.4-427 where found (a threshold of 10
#: missed 10-cm ones on quick U000 at 7.0: 4.97 mGal, found 1.53) and under 5 on 7 of 24 (with
#: the whole record asked where the straight stretches miss it, :func:`fit_height_wander`; its
#: ratio on the 88 flights without a wander: 1.77 at most).
WALK_MIN_LOG_LR = 5.0
#: A wander the whole record finds is kept only where the straight stretches, with it held at
#: the whole record's value, lose less log-likelihood than this against none: where they are
#: long enough to show such a wander and do not, it came from the turns (full-length unseen
#: U016, 232 min of 44-min lines: ratio 8.1 on the whole record, the straight stretches 25.9
#: worse with it; taken, it coarsened the resolution 4.8 -> 11.7 km and the product 0.47 ->
#: 0.79 mGal).  The evidence the whole record needs to find it (WALK_MIN_LOG_LR), the other way:
#: with a wander everywhere, -427 to +0.18 on 24 simulated flights and -4.4 to +4.1 on 64
#: synthetic records of 4-min stretches where only the whole record finds it; with one in the
#: turns only, 5.7 to 50 on 14 synthetic records of 25-min stretches (tests/test_inm_identify.py).
WALK_HELD_MAX_COST = 5.0

#: The white level is used only when the likelihood pins it within this 1-sigma factor ...
WHITE_MAX_FACTOR = 4.0
#: ... else this one-second sigma (1 mGal/sqrt(Hz), a typical gravimeter datasheet figure), m/s^2.
WHITE_DEFAULT_MPS2 = 1e-5
#: ... and only when the data exclude that figure: the fit with the white level held at
#: :data:`WHITE_DEFAULT_MPS2` must be worse by this log-likelihood (2: about the 95 % point of a
#: likelihood-ratio test of one parameter).  The Hessian's factor alone was not enough: the
#: likelihood is flat in the white level wherever it hides under the anomaly, so a factor of
#: 1.4 stood for a level 16x the gravimeter's that the data preferred by 1.9 only (a strapdown
#: flight in heavy turbulence, 1 Hz heights: the product went flat, 1.69 mGal for a bound of
#: 0.89; docs/benchmarks.md, "Flights like issue 12's table").
WHITE_MIN_LOG_LR = 2.0

#: Range of :func:`smoother_sigma_scale`: the seen field's spectrum is an estimate, and a
#: factor beyond it would say more than one flight's periodogram can.
SIGMA_SCALE_BOUNDS = (0.25, 4.0)

#: Horizontal specific force (m/s^2) above which an epoch counts as manoeuvring (about 3 deg of
#: bank); such epochs, dilated by :data:`MANOEUVRE_MARGIN_S`, are left out of the fit.
MANOEUVRE_MPS2 = 0.5
#: Averaging window of the horizontal specific force, s.
MANOEUVRE_WINDOW_S = 20.0
MANOEUVRE_MARGIN_S = 30.0
#: Order of the polynomial removed from each stretch before its periodogram.
DETREND_ORDER = 2
#: Shortest straight stretch used, s.
MIN_RUN_S = 240.0
#: Shortest stretch pooled when no stretch reaches :data:`MIN_RUN_S` (survey lines of a few km),
#: s.  The straight stretches serve the noise levels: the height noise rises as ``f^4`` and
#: dominates the vertical channel above a few mHz (5 cm at 1 Hz exceeds 1 mGal/sqrt(Hz) of white
#: noise above 2 mHz), so a stretch of 60 s - lowest analysed bin 3 / 60 s = 0.05 Hz, 27 bins at
#: 1 Hz - measures it as well as a long one; the white level, which needs the lowest bins, is
#: then left unresolved and defaulted (:data:`WHITE_MAX_FACTOR`) instead of being taken from
#: turns.  The stretches together must still span :data:`MIN_RUN_S`.
SHORT_RUN_S = 60.0
#: Shortest stretch pooled when neither :data:`MIN_RUN_S` nor :data:`SHORT_RUN_S` stretches add up
#: to :data:`MIN_RUN_S` (a height channel with an outage every half minute), s: the height noise
#: (above 0.1 Hz) still shows; the white level does not and is defaulted.
GAP_RUN_S = 20.0
#: Most consecutive height samples a gap may miss to be filled (linearly) before the fit
#: instead of ending a straight stretch: a receiver that drops 1 % of its epochs at random breaks
#: a 6 Hz record every ~17 s, and without the fill no stretch reaches :data:`SHORT_RUN_S`
#: (measured on quick U214: identification failed, 0.44 -> 1.31 mGal).
MAX_FILL_SAMPLES = 5
#: ... or a gap of at most this many seconds (a fast altimeter's short outage): the residual it
#: bridges is the smooth inertial height error plus the height noise, and a straight line
#: over 2 s misses only the noise.
MAX_FILL_S = 2.0
#: Largest share of filled samples in the record: above it the gaps are left as breaks (a fill
#: carries no height noise, and the fit would read the channel as quieter than it is).
MAX_FILL_FRACTION = 0.05


@dataclass(frozen=True)
class SpectralModel:
    """Parameters of the vertical-channel spectrum (all SI).

    Attributes
    ----------
    anomaly_sigma_mps2 : float
        Stationary sigma of the disturbance (plus the gravimeter's slow error), m/s^2.
    anomaly_tau_s : float
        Its correlation time along the flight, s (``1 / lambda_g``).
    white_mps2 : float
        One-second sigma of the white vertical acceleration noise, m/s^2
        (two-sided PSD ``white_mps2**2 * 1 s``).
    height_sigma_m : float
        Per-sample sigma of the height measurement, m.
    height_walk_m : float
        The height error's random walk (the height wander): the sigma of its increment over one
        second, m; two-sided PSD ``q / omega^2`` of the height error with ``q = height_walk_m^2 /
        1 s``.  0 where the heights' noise is white.
    """

    anomaly_sigma_mps2: float
    anomaly_tau_s: float
    white_mps2: float
    height_sigma_m: float
    height_walk_m: float = 0.0

    def as_vector(self) -> np.ndarray:
        return np.log([getattr(self, k) for k in (_ORDER_WALK if self.height_walk_m > 0.0 else _ORDER)])

    @classmethod
    def from_vector(cls, v) -> "SpectralModel":
        return cls(*[float(x) for x in np.exp(v)])


def vertical_psd(freq_hz, model: SpectralModel, dt_s: float) -> np.ndarray:
    """Two-sided PSD of the second-differenced height residual ``y``, (m/s^2)^2/Hz.

    Parameters
    ----------
    freq_hz : ndarray (k,)
        Frequencies, Hz (``0 < f <= 1 / (2 dt)``).
    model : SpectralModel
    dt_s : float
        Sample spacing of ``y`` (the altimeter's), s.
    """
    f = np.asarray(freq_hz, float)
    lam = 1.0 / model.anomaly_tau_s
    s_g = 2.0 * model.anomaly_sigma_mps2**2 * lam / (lam**2 + (2.0 * math.pi * f) ** 2)
    s_w = model.white_mps2**2
    x = math.pi * f * dt_s
    sinc4 = (np.sin(x) / x) ** 4
    d2 = (2.0 - 2.0 * np.cos(2.0 * math.pi * f * dt_s)) ** 2
    s_eps = model.height_sigma_m**2 * dt_s * d2 / dt_s**4
    if model.height_walk_m > 0.0:
        # the wander's q / omega^2 through the same second difference
        s_eps = s_eps + model.height_walk_m**2 * d2 / dt_s**4 / (2.0 * math.pi * f) ** 2
    return (s_g + s_w) * sinc4 + s_eps


def vertical_residual(nav, alt_time, alt_height, ellipsoid: Ellipsoid = WGS84):
    """Mechanized minus measured height at the altimeter's times.

    Parameters
    ----------
    nav : gravsurvey.inm.mechanization.Navigation
        Uncorrected mechanization (inertial position at the IMU times).
    alt_time, alt_height : ndarray (m,)
        Altimeter times (s, record base) and ellipsoidal heights (m), finite.

    Returns
    -------
    time : ndarray (k,)
        Altimeter times inside the mechanization's span, s.
    residual_m : ndarray (k,)
        ``|r_ins| - |r(lat_ins, lon_ins, h_alt)|``: the height difference along the radius, m.
    """
    t = np.asarray(alt_time, float)
    h = np.asarray(alt_height, float)
    ok = (t >= nav.time[0]) & (t <= nav.time[-1]) & np.isfinite(h)
    t, h = t[ok], h[ok]
    # linear interpolation of the inertial position between IMU samples (>= 20 Hz): its
    # radial error is a_up dt^2 / 8 < 1 mm, far below any altimeter's noise
    r_i = np.stack([np.interp(t, nav.time, nav.r_i[:, j]) for j in range(3)], axis=1)
    r_e = np.einsum("nji,nj->ni", mat_ie(t, ellipsoid.omega), r_i)
    lat, lon, _ = ecef_to_geodetic(r_e, ellipsoid)
    r_ext = np.linalg.norm(geodetic_to_ecef(lat, lon, h, ellipsoid), axis=1)
    return t, np.linalg.norm(r_i, axis=1) - r_ext


def running_mean(x, w):
    """Centred running mean over ``w`` samples along axis 0 (shrinking at the ends)."""
    c = np.concatenate([np.zeros((1,) + x.shape[1:]), np.cumsum(x, axis=0)])
    i = np.arange(x.shape[0])
    lo = np.clip(i - w // 2, 0, x.shape[0])
    hi = np.clip(i + w // 2 + 1, 0, x.shape[0])
    return (c[hi] - c[lo]) / (hi - lo).reshape((-1,) + (1,) * (x.ndim - 1))


def edge_samples(time, window_s: float, gap_s: float | None = None) -> np.ndarray:
    """The samples within half a window of the record's first or last one, or of a gap, bool (k,).

    At the ends :func:`running_mean` is one-sided and a residual less its running mean is no
    high-pass: a trend is left in it (a ramp of slope ``a`` leaves ``a window / 4`` at the ends).
    The uncorrected mechanization runs off the heights and the GNSS track by metres a second,
    so regressions on high-passed residuals leave these samples out (quick U1434: the 10 s at
    each end, 5 m off, read as a height latency of 50 ms drifting -156 ppm on exact stamps).
    Across a gap the running mean mixes both sides (a 30-s gap read as a 53-ms latency).

    Parameters
    ----------
    time : ndarray (k,)
        Sample times, s, increasing.
    window_s : float
        The running mean's window, s.
    gap_s : float, optional
        A step between samples longer than this is a gap; None: the ends only.

    Returns
    -------
    ndarray of bool (k,)
        True at the samples to leave out (every sample of a record shorter than the window).
    """
    t = np.asarray(time, float)
    if t.size == 0:
        return np.zeros(0, bool)
    out = (t < t[0] + 0.5 * window_s) | (t > t[-1] - 0.5 * window_s)
    if gap_s is not None:
        for g in np.flatnonzero(np.diff(t) > gap_s):
            out |= (t > t[g] - 0.5 * window_s) & (t < t[g + 1] + 0.5 * window_s)
    return out


def _horizontal_specific_force(nav, f_t, times):
    """Horizontal part of the specific force averaged over :data:`MANOEUVRE_WINDOW_S`, m/s^2 (k,).

    The vector is averaged before its magnitude is taken: turbulence (seconds, zero mean)
    averages out, a turn or a speed change (tens of seconds, one direction) does not.
    """
    f_i = np.einsum("nij,nj->ni", nav.mat_it, np.asarray(f_t, float))
    n = nav.time.size
    dt = float(np.median(np.diff(nav.time)))
    w = max(1, int(round(MANOEUVRE_WINDOW_S / dt)))
    # the averaged force is needed only at the IMU samples that bracket ``times`` (1 Hz
    # altimeter or filter epochs against a 100 Hz IMU): the running sums at every sample, the
    # means, magnitudes and the interpolation at those only - the same numbers as evaluating
    # all samples and interpolating (np.interp on a subset that holds every bracketing pair),
    # at a third of the cost
    x = np.asarray(times, float)
    if 2 * x.size < n:
        j = np.clip(np.searchsorted(nav.time, x, side="right") - 1, 0, n - 1)
        sub = np.unique(np.concatenate([j, np.minimum(j + 1, n - 1)]))
    else:
        sub = np.arange(n)
    c = np.empty((n + 1, 3))
    c[0] = 0.0
    np.cumsum(f_i, axis=0, out=c[1:])
    lo = np.clip(sub - w // 2, 0, n)
    hi = np.clip(sub + w // 2 + 1, 0, n)
    f_i = (c[hi] - c[lo]) / (hi - lo)[:, None]
    r_i = nav.r_i[sub]
    up = r_i / np.linalg.norm(r_i, axis=1)[:, None]
    f_up = np.einsum("ni,ni->n", f_i, up)
    f_h = np.sqrt(np.maximum(np.einsum("ni,ni->n", f_i, f_i) - f_up**2, 0.0))
    return np.interp(x, nav.time[sub], f_h)


def tilt_leak_factor(nav, times, manoeuvring, max_samples: int = 20000) -> float:
    """Mean of ``1 - u_z^2`` over the straight epochs: the tilt's share of the horizontal axes.

    ``u`` is the local up direction on the triad axes.  A strapdown triad's z axis leaves the
    vertical by the aircraft's roll and pitch, so the vertical channel carries the horizontal
    accelerometers' noise with variance ``accel_noise^2 (1 - u_z^2)``; a platform's stays
    level (factor 0).

    Parameters
    ----------
    nav : Navigation
        Uncorrected mechanization.
    times : ndarray (k,)
        Epochs to average over, s (the spectral fit's altimeter times); each takes the attitude
        of the IMU sample at or before it.
    manoeuvring : ndarray (k,) bool
        Epochs left out (the spectral fit's manoeuvre mask, :data:`MANOEUVRE_MPS2`).
    max_samples : int
        At most this many epochs are used (evenly spaced).

    Returns
    -------
    float
        Dimensionless, in [0, 1]; 0 when no epoch is straight.
    """
    k = max(1, np.size(times) // max_samples)
    x = np.asarray(times, float)[::k][~np.asarray(manoeuvring, bool)[::k]]
    if x.size == 0:
        return 0.0
    j = np.clip(np.searchsorted(nav.time, x, side="right") - 1, 0, nav.time.size - 1)
    r_i = nav.r_i[j]
    up_i = r_i / np.linalg.norm(r_i, axis=1)[:, None]
    up_t = np.einsum("nji,nj->ni", nav.mat_it[j], up_i)
    return float(np.clip(np.mean(1.0 - up_t[:, 2] ** 2), 0.0, 1.0))


def tilt_leak_exceeds_white(white_mps2: float, leak_mps2: float, sigma_factor: float | None) -> bool:
    """Whether the modelled leak is beyond two standard errors above the fitted white level.

    The vertical channel cannot carry less noise than the horizontal accelerometers leak into
    it; when the leak computed from ``accel_noise_mps2`` exceeds the white level the data show
    by more than ``sigma_factor^2`` (a multiplicative 2-sigma), the accelerometers are quieter
    than that figure says (the default 1e-3 m/s^2 on a navigation-grade IMU).
    """
    return sigma_factor is not None and leak_mps2 > white_mps2 * sigma_factor**2


def white_less_tilt_leak(white_mps2: float, leak_mps2: float, sigma_factor: float | None) -> float | None:
    """The gravimeter's own white level: the vertical channel's less the tilt leak, m/s^2.

    ``sqrt(white^2 - leak^2)``, not below ``min(white, WHITE_DEFAULT_MPS2)`` (the accelerometer
    figure is a datasheet or default value, the subtraction must not make the gravimeter
    cleaner than a typical one on its strength alone).  None when the correction is within
    the fit's own 1-sigma factor ``sigma_factor`` of the white level (not resolved by the
    data: a platform's leak, a quiet flight's), and when the leak contradicts the data
    (:func:`tilt_leak_exceeds_white`: the accelerometer figure is then not to be trusted).
    """
    if tilt_leak_exceeds_white(white_mps2, leak_mps2, sigma_factor):
        return None
    own = math.sqrt(max(white_mps2**2 - leak_mps2**2, 0.0))
    own = max(own, min(white_mps2, WHITE_DEFAULT_MPS2))
    if sigma_factor is None or own <= 0.0 or white_mps2 / own <= sigma_factor:
        return None
    return own


def straight_runs(
    time, manoeuvring, *, min_run_s: float = MIN_RUN_S, margin_s: float = MANOEUVRE_MARGIN_S
) -> list[tuple[int, int]]:
    """Index ranges ``[a, b)`` of non-manoeuvring stretches without a gap (a step over 1.5x the
    median).

    Parameters
    ----------
    time : ndarray (k,)
        Sample times, s.
    manoeuvring : ndarray of bool (k,)
        True where the platform turns or accelerates.
    min_run_s, margin_s : float
        Shortest run kept; margin removed around every manoeuvring sample, s.
    """
    t = np.asarray(time, float)
    if t.size < 8:
        return []
    dt = float(np.median(np.diff(t)))
    bad = np.asarray(manoeuvring, bool).copy()
    if bad.any():
        # dilate by the margin on both sides
        m = max(1, int(round(margin_s / dt)))
        c = np.concatenate([[0], np.cumsum(bad.astype(np.int64))])
        idx = np.arange(t.size)
        lo = np.clip(idx - m, 0, t.size)
        hi = np.clip(idx + m + 1, 0, t.size)
        bad = (c[hi] - c[lo]) > 0
    # a stretch ends at a gap (what fill_short_gaps left); stamps that jitter about the grid
    # (a logger's receive times) do not end it: the periodogram takes the samples as evenly
    # spaced, and a jitter of sigma_t only adds v_z sigma_t of noise to the residual
    broken = np.diff(t) > 1.5 * dt
    edge = np.diff(np.concatenate([[0], (~bad).astype(np.int8), [0]]))
    runs = []
    for a, b in zip(np.flatnonzero(edge == 1), np.flatnonzero(edge == -1)):
        cuts = np.flatnonzero(broken[a : b - 1]) + a + 1
        bounds = [int(a), *[int(c) for c in cuts], int(b)]
        runs += [(s, e) for s, e in zip(bounds[:-1], bounds[1:]) if (e - s) * dt >= min_run_s]
    return runs


def fill_short_gaps(
    time,
    values,
    max_missing: int = MAX_FILL_SAMPLES,
    max_fraction: float = MAX_FILL_FRACTION,
    max_gap_s: float = MAX_FILL_S,
):
    """Samples missing in short runs put back, linearly interpolated, on the record's own grid.

    Parameters
    ----------
    time : ndarray (k,)
        Sample times, s, increasing.
    values : ndarray (k,)
        Samples (e.g. the vertical residual, m).
    max_missing : int
        A gap of ``round(dt_gap / dt) - 1`` missing samples (``dt`` the median spacing) is filled
        when that count is at most this, or when the gap lasts at most ``max_gap_s``; longer
        gaps stay as they are (they end a stretch).
    max_fraction : float
        Nothing is filled when the fillable samples would exceed this share of the record.
    max_gap_s : float
        s.

    Returns
    -------
    time, values : ndarray (k + filled,)
        With the filled samples in place.
    filled : int
        Number of samples put in.
    """
    t = np.asarray(time, float)
    y = np.asarray(values, float)
    if t.size < 3:
        return t, y, 0
    dt = float(np.median(np.diff(t)))
    if not dt > 0.0:
        return t, y, 0
    gap = np.diff(t)
    missing = np.rint(gap / dt).astype(np.int64) - 1
    fill = (missing >= 1) & ((missing <= max_missing) | (gap <= max_gap_s))
    n_fill = int(missing[fill].sum())
    if n_fill == 0 or n_fill > max_fraction * t.size:
        return t, y, 0
    gaps = np.flatnonzero(fill)
    new_t = np.concatenate([t[i] + (t[i + 1] - t[i]) * np.arange(1, missing[i] + 1) / (missing[i] + 1) for i in gaps])
    all_t = np.concatenate([t, new_t])
    order = np.argsort(all_t, kind="stable")
    return all_t[order], np.concatenate([y, np.interp(new_t, t, y)])[order], n_fill


@dataclass
class VerticalFit:
    """Result of :func:`fit_vertical_spectrum`.

    Attributes
    ----------
    model : SpectralModel
        Maximum-likelihood parameters.
    sigma_factor : dict
        Per parameter, the 1-sigma multiplicative uncertainty ``exp(sd(log p))`` from the
        inverse Hessian of the likelihood (``None`` where the parameter sits on a bound or is
        held fixed).
    at_bound : tuple of str
        Parameters that ended on a bound of :data:`BOUNDS`.
    dt_s : float
        Sample spacing used, s.
    seconds_used : float
        Length of the straight stretches that entered the fit, s.
    n_runs : int
        Number of stretches (pooled: their periodograms enter one likelihood).
    nll : float
        Negative Whittle log-likelihood at the optimum.
    unresolved : tuple of str
        ``("anomaly_tau_s",)`` when the correlation time is longer than the straight stretches
        can show; it is then set to the lowest observed frequency's corner (see the code).
    """

    model: SpectralModel
    sigma_factor: dict
    at_bound: tuple
    dt_s: float
    seconds_used: float
    n_runs: int
    nll: float
    unresolved: tuple = ()
    short_runs: bool = False


def _periodograms(y_runs, dt):
    """Hann-tapered periodograms of the stretches, concatenated.

    Parameters
    ----------
    y_runs : list of ndarray (n_i,)
        Second-differenced height residual of each stretch, m/s^2.
    dt : float
        Sample spacing, s.

    Returns
    -------
    f, i_f, weight : ndarray (k,)
        Frequencies (Hz), two-sided periodogram ((m/s^2)^2/Hz), and the weight that turns a
        sum over bins into a variance averaged over the stretches.
    """
    out = []
    for y in y_runs:
        n = y.size
        k = np.linspace(-1.0, 1.0, n)
        w = np.hanning(n)
        # remove a quadratic (gravimeter bias and drift, and the slow normal-gravity error of
        # the free mechanization's horizontal drift - Schuler period, ~0.8 mGal per km of
        # latitude).  The fit is weighted by the taper: y is a second difference, so an
        # unweighted fit is driven by the height noise of the stretch's end samples and would
        # inject a polynomial of that size - hundreds of mGal - into the lowest bins.
        y = y - np.polyval(np.polyfit(k, y, DETREND_ORDER, w=np.sqrt(w)), k)
        spec = np.fft.rfft(w * y)
        f = np.fft.rfftfreq(n, dt)
        sel = slice(3, n // 2 if n % 2 == 0 else n // 2 + 1)
        i_f = dt * np.abs(spec) ** 2 / np.sum(w**2)
        # DC and the first bins carry the removed polynomial and the taper's leak; no Nyquist
        out.append((f[sel], i_f[sel], np.full(f[sel].size, 2.0 / (n * dt * len(y_runs)))))
    f = np.concatenate([o[0] for o in out])
    i_f = np.concatenate([o[1] for o in out])
    weight = np.concatenate([o[2] for o in out])
    return f, i_f, weight


def _nll(v, f, i_f, dt, fixed_mask, fixed_v):
    """Whittle's negative log-likelihood written from :func:`vertical_psd`: the plain definition
    that :func:`_nll_and_grad` (what the fit uses) evaluates faster, with its gradient."""
    vv = np.where(fixed_mask, fixed_v, v)
    s = vertical_psd(f, SpectralModel.from_vector(vv), dt)
    return float(np.sum(np.log(s) + i_f / s))


def _whittle_terms(f, dt, walk: bool = False):
    """The parts of :func:`vertical_psd` that do not depend on the parameters, (3, k) or (4, k).

    Rows: ``(2 pi f)^2`` (1/s^2), ``sinc^4(f dt)``, the height noise's transfer
    ``dt (2 - 2 cos 2 pi f dt)^2 / dt^4`` (1/s^3) and, with ``walk``, the height wander's
    ``(2 - 2 cos 2 pi f dt)^2 / dt^4 / (2 pi f)^2`` (1/s^2): computed once per fit instead of at
    each of the optimizer's likelihood evaluations.
    """
    f = np.asarray(f, float)
    x = math.pi * f * dt
    om2 = (2.0 * math.pi * f) ** 2
    hk = (2.0 - 2.0 * np.cos(2.0 * x)) ** 2 / dt**3
    rows = [om2, (np.sin(x) / x) ** 4, hk]
    if walk:
        rows.append(hk / (dt * om2))
    return np.stack(rows)


def _psd_parts(v, terms):
    """:func:`vertical_psd` at log-parameters ``v`` and its first derivatives by them.

    Returns
    -------
    s : ndarray (k,)
        The PSD, (m/s^2)^2/Hz.
    d : ndarray (4, k) or (5, k)
        ``dS / d log p`` for the parameters in :data:`_ORDER` (:data:`_ORDER_WALK` with the
        wander's row in ``terms``).
    s_g, r : ndarray (k,)
        The anomaly's Markov PSD and ``(lambda^2 - omega^2) / (lambda^2 + omega^2)``
        (``d log S_g / d log tau``), for the second derivatives.
    """
    sig2, tau, w2, eps2 = np.exp(2.0 * v[0]), np.exp(v[1]), np.exp(2.0 * v[2]), np.exp(2.0 * v[3])
    om2, sinc4, hk = terms[:3]
    lam = 1.0 / tau
    den = lam * lam + om2
    s_g = 2.0 * sig2 * lam / den
    s_eps = eps2 * hk
    s = (s_g + w2) * sinc4 + s_eps
    r = (lam * lam - om2) / den
    rows = [2.0 * s_g * sinc4, s_g * r * sinc4, 2.0 * w2 * sinc4, 2.0 * s_eps]
    if len(terms) > 3:
        s_walk = np.exp(2.0 * v[4]) * terms[3]
        s = s + s_walk
        rows.append(2.0 * s_walk)
    return s, np.stack(rows), s_g, r


def _nll_and_grad(v, terms, i_f, fixed_mask, fixed_v):
    """Whittle's negative log-likelihood (:func:`_nll`) and its exact gradient by ``v``.

    ``d/dp sum [log S + I / S] = sum (S - I) / S^2 dS/dp``: one pass over the bins instead of
    the optimizer's finite differences (five passes per gradient, and a gradient only as
    accurate as their step).  Held parameters get a zero gradient (they do not move).
    """
    vv = np.where(fixed_mask, fixed_v, v)
    s, d, _, _ = _psd_parts(vv, terms)
    q = i_f / s
    g = d @ ((1.0 - q) / s)
    g[fixed_mask] = 0.0
    return float(np.sum(np.log(s) + q)), g


def _nll_hessian(v, terms, i_f):
    """Exact Hessian (4, 4) or (5, 5) of Whittle's negative log-likelihood by the log-parameters ``v``.

    ``sum [(2 I / S - 1) dS_i dS_j / S^2 + (1 - I / S) d2S_ij / S]``; ``d2S`` is nonzero on the
    diagonal and between the anomaly's sigma and correlation time only.
    """
    s, d, s_g, r = _psd_parts(np.asarray(v, float), terms)
    om2, sinc4 = terms[0], terms[1]
    q = i_f / s
    a = (2.0 * q - 1.0) / (s * s)
    out = (d * a) @ d.T
    b = (1.0 - q) / s
    lam2 = np.exp(-2.0 * v[1])
    # second derivatives of S by the log-parameters (the first ones are in _psd_parts)
    d2 = np.array(
        [
            4.0 * s_g * sinc4,
            s_g * (r * r - 4.0 * lam2 * om2 / (lam2 + om2) ** 2) * sinc4,
            2.0 * d[2],
            2.0 * d[3],
            *([2.0 * d[4]] if d.shape[0] > 4 else []),
        ]
    )
    out[np.diag_indices(d.shape[0])] += d2 @ b
    cross = float((2.0 * d[1]) @ b)
    out[0, 1] += cross
    out[1, 0] += cross
    return out


_BLAS_CONTROLLER: list = []


def _single_thread_blas():
    """Context in which BLAS runs on one thread (a no-op without threadpoolctl).

    L-BFGS-B factorises 4 x 4 matrices at every iteration; multi-threaded OpenBLAS spends far
    more on waking and synchronising its threads than on that work - measured 26 ms against
    1.8 ms per 4-parameter optimisation (a toy problem; 2-core machine with other load), which
    made the optimizer's own bookkeeping ~90 % of the fit's time.  The controller scans the
    loaded libraries once (1 ms) and is then reused.
    """
    import contextlib

    try:
        from threadpoolctl import ThreadpoolController
    except ImportError:  # pragma: no cover - scikit-learn (verde, harmonica) brings it
        return contextlib.nullcontext()
    if not _BLAS_CONTROLLER:
        import scipy.optimize  # noqa: F401  (loads scipy's own BLAS, which the scan must see)

        _BLAS_CONTROLLER.append(ThreadpoolController())
    return _BLAS_CONTROLLER[0].limit(limits=1, user_api="blas")


def fit_vertical_spectrum(
    time,
    residual_m,
    manoeuvring=None,
    *,
    fixed: dict | None = None,
    start: SpectralModel | None = None,
    walk: bool = False,
) -> VerticalFit | None:
    """Whittle fit of the vertical-channel spectrum (module docstring).

    Parameters
    ----------
    time : ndarray (k,)
        Altimeter times, s.
    residual_m : ndarray (k,)
        Mechanized minus measured height, m (:func:`vertical_residual`).
    manoeuvring : ndarray of bool (k,), optional
        Epochs to leave out (turns).
    fixed : dict, optional
        Parameters of :class:`SpectralModel` held at a given value (user overrides).
    start : SpectralModel, optional
        An extra starting point (e.g. the configured values).
    walk : bool
        Fit the height wander (``SpectralModel.height_walk_m``) as a fifth parameter; else it
        is 0.

    Returns
    -------
    VerticalFit or None
        None when the flight has no straight stretch of :data:`MIN_RUN_S` and its stretches of
        :data:`SHORT_RUN_S` or more (pooled, ``short_runs``), nor those of :data:`GAP_RUN_S` or
        more, add up to that length.
    """
    from scipy.optimize import minimize

    t = np.asarray(time, float)
    e = np.asarray(residual_m, float)
    if t.size < 16:
        return None
    dt = float(np.median(np.diff(t)))
    man = np.zeros(t.size, bool) if manoeuvring is None else np.asarray(manoeuvring, bool)
    runs = straight_runs(t, man)
    short = False
    for min_run_s in (SHORT_RUN_S, GAP_RUN_S):
        if runs:
            break
        # survey lines shorter than MIN_RUN_S, or a record broken by outages of the height
        # channel: pool the shorter straight stretches (each its own periodogram, one
        # likelihood) rather than fall back to a fit that includes the turns, or to none
        pooled = straight_runs(t, man, min_run_s=min_run_s)
        if sum(b - a for a, b in pooled) * dt >= MIN_RUN_S:
            runs, short = pooled, True
    if not runs:
        return None
    runs = [(a, b) for a, b in runs if b - a >= 16]
    y_runs = [np.diff(e[a:b], 2) / dt**2 for a, b in runs]
    f, i_f, weight = _periodograms(y_runs, dt)
    if f.size < 16:
        return None
    fixed = dict(fixed or {})
    order = _ORDER_WALK if walk else _ORDER
    fixed_mask = np.array([k in fixed for k in order])
    fixed_v = np.array([math.log(fixed[k]) if k in fixed else 0.0 for k in order])
    lo = np.log([BOUNDS[k][0] for k in order])
    hi = np.log([BOUNDS[k][1] for k in order])
    # data-driven starting points: the white level from the middle of the band, the height
    # noise from the top, the anomaly from the lowest frequencies
    fny = 0.5 / dt
    top = i_f[f > 0.7 * fny]
    mid = i_f[(f > 0.01) & (f < 0.05)] if np.any((f > 0.01) & (f < 0.05)) else i_f
    low = i_f[f < 2e-3] if np.any(f < 2e-3) else i_f[: max(1, i_f.size // 50)]
    h_amp = (2.0 - 2.0 * np.cos(math.pi * 0.85)) ** 2 / dt**3
    eps0 = math.sqrt(max(float(np.median(top)) / h_amp, 1e-8)) if top.size else 0.05
    w0 = math.sqrt(max(float(np.median(mid)), 1e-16))
    starts = []
    for tau in (30.0, 300.0, 3000.0):
        s0 = math.sqrt(max(float(np.median(low)) / (2.0 * tau), 1e-14))
        starts.append(np.log([s0, tau, w0, eps0]))
    if start is not None:
        starts.append(start.as_vector()[:4])
    if walk:
        # the wander from the middle of the band (q omega^2 there); from the given start (the
        # four-parameter optimum) also a tenth of it
        fm = float(np.median(f[(f > 0.01) & (f < 0.05)])) if np.any((f > 0.01) & (f < 0.05)) else float(np.median(f))
        k0 = math.sqrt(max(float(np.median(mid)), 1e-16)) / (2.0 * math.pi * fm)
        starts = [np.append(v0, math.log(k0)) for v0 in starts]
        if start is not None:
            starts.append(np.append(starts[-1][:4], math.log(0.1 * k0)))
    terms = _whittle_terms(f, dt, walk)
    best = None
    with _single_thread_blas():
        for v0 in starts:
            v0 = np.clip(np.where(fixed_mask, fixed_v, v0), lo, hi)
            res = minimize(
                _nll_and_grad,
                v0,
                args=(terms, i_f, fixed_mask, fixed_v),
                jac=True,
                method="L-BFGS-B",
                bounds=list(zip(lo, hi)),
            )
            if best is None or res.fun < best.fun:
                best = res
    v = np.where(fixed_mask, fixed_v, best.x)
    at_bound = tuple(
        k for k, x, a, b in zip(order, v, lo, hi) if not fixed_mask[order.index(k)] and (x - a < 1e-3 or b - x < 1e-3)
    )
    free = [i for i, k in enumerate(order) if not fixed_mask[i] and k not in at_bound]
    factors = {k: None for k in order}
    if free:
        hess = _nll_hessian(v, terms, i_f)[np.ix_(free, free)]
        try:
            cov = np.linalg.inv(hess)
            for j, i in enumerate(free):
                if 0 < cov[j, j] < 25.0:
                    factors[order[i]] = float(math.exp(math.sqrt(cov[j, j])))
        except np.linalg.LinAlgError:
            pass
    used = float(sum((b - a) * dt for a, b in runs))
    model = SpectralModel.from_vector(v)
    unresolved = ()
    tau_max = 1.0 / (2.0 * math.pi * float(f.min()))
    if "anomaly_tau_s" not in fixed and "anomaly_sigma_mps2" not in fixed and model.anomaly_tau_s > tau_max:
        # the anomaly's corner lies below the lowest frequency the straight stretches show:
        # only the level of its f^-2 tail, sigma^2 / tau, is measured.  Keep that level and put
        # the corner at the lowest observed frequency (the shortest correlation time the data
        # allow), so the prior claims no long-wavelength knowledge it does not have.
        k = model.anomaly_sigma_mps2**2 / model.anomaly_tau_s
        model = dataclasses.replace(model, anomaly_tau_s=tau_max, anomaly_sigma_mps2=math.sqrt(k * tau_max))
        unresolved = ("anomaly_tau_s",)
        factors["anomaly_tau_s"] = None
        at_bound = tuple(x for x in at_bound if x != "anomaly_tau_s")
    return VerticalFit(model, factors, at_bound, dt, used, len(runs), float(best.fun), unresolved, short)


def wiener_resolution_m(model: SpectralModel, speed_mps: float, dt_s: float = 1.0) -> float:
    """Half-wavelength resolution of the optimal smoother for the identified model, m.

    The RTS smoother of a stationary model is the non-causal Wiener filter
    ``H(f) = S_g / (S_g + S_n)``; its half-power point ``f_c`` is where the anomaly's spectrum
    meets the noise referred to the disturbance, ``S_n = w^2 + sigma_eps^2 dt (2 pi f)^4``, plus
    ``q (2 pi f)^2`` with a height wander (continuous limit of :func:`vertical_psd`).
    Resolution = ``v / (2 f_c)``.
    """
    lam = 1.0 / model.anomaly_tau_s

    def gap(logf):
        f = math.exp(logf)
        s_g = 2.0 * model.anomaly_sigma_mps2**2 * lam / (lam**2 + (2 * math.pi * f) ** 2)
        return math.log(s_g) - math.log(_noise_psd_g(f, model, dt_s))

    lo, hi = math.log(1e-7), math.log(10.0)
    if gap(lo) < 0:
        return float("inf")
    if gap(hi) > 0:
        return speed_mps / (2.0 * 10.0)
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if gap(mid) > 0:
            lo = mid
        else:
            hi = mid
    return speed_mps / (2.0 * math.exp(0.5 * (lo + hi)))


def model_resolution_m(params, speed_mps: float, height_dt_s: float) -> float:
    """Resolution (m) of the smoother for the settings ``params`` as they are (no identification).

    The vertical channel's noise is the gravimeter's white noise plus the height noise
    (``altimeter_sigma_m`` per sample at spacing ``height_dt_s``); see :func:`wiener_resolution_m`.
    """
    v = max(float(speed_mps), 1.0)
    return wiener_resolution_m(spectral_model_of(params, v), v, height_dt_s)


def spectral_model_of(params, speed_mps: float, height_sigma_m: float | None = None, height_walk_m: float = 0.0):
    """The :class:`SpectralModel` of the settings ``params`` (the prior and noise the filter runs
    with), its height noise ``height_sigma_m`` (default ``params.altimeter_sigma_m``) and
    wander ``height_walk_m``, at ``speed_mps`` (time to space)."""
    v = max(float(speed_mps), 1.0)
    return SpectralModel(
        max(params.anomaly_sigma_mps2, 1e-12),
        1.0 / max(params.anomaly_lambda_per_m * v, 1e-12),
        max(params.gravimeter_white_mps2, 1e-12),
        max(params.altimeter_sigma_m if height_sigma_m is None else height_sigma_m, 1e-9),
        height_walk_m,
    )


def prior_for_resolution(
    model: SpectralModel, speed_mps: float, resolution_m: float, dt_s: float = 1.0
) -> SpectralModel:
    """The anomaly sigma that puts the smoother's half-power point at ``resolution_m``.

    Keeps the correlation time and the noise; solves ``S_g(f_c) = S_n(f_c)`` with
    ``f_c = v / (2 resolution)`` for the anomaly sigma: a larger sigma widens the smoother's
    band (finer resolution, more noise), a smaller one narrows it.
    """
    f_c = speed_mps / (2.0 * resolution_m)
    lam = 1.0 / model.anomaly_tau_s
    s_n = _noise_psd_g(f_c, model, dt_s)
    sigma = math.sqrt(s_n * (lam**2 + (2 * math.pi * f_c) ** 2) / (2.0 * lam))
    return dataclasses.replace(model, anomaly_sigma_mps2=sigma)


def white_log_likelihood_ratio(time, residual_m, manoeuvring, fit: VerticalFit, fixed: dict | None = None) -> float:
    """How far the data exclude the datasheet white level: the log-likelihood of ``fit`` over
    the same fit with the white level held at :data:`WHITE_DEFAULT_MPS2`.

    Parameters
    ----------
    time, residual_m, manoeuvring, fixed
        As given to :func:`fit_vertical_spectrum` for ``fit``.
    fit : VerticalFit
        The fit with the white level free.

    Returns
    -------
    float
        >= 0 up to the optimiser's tolerance (``inf`` when the held fit fails); about half a
        chi-square of one degree of freedom when the white level is the datasheet's.
    """
    held = fit_vertical_spectrum(
        time,
        residual_m,
        manoeuvring,
        fixed={**(fixed or {}), "white_mps2": WHITE_DEFAULT_MPS2},
        walk=fit.model.height_walk_m > 0.0,
    )
    return math.inf if held is None else float(held.nll - fit.nll)


def fit_height_wander(time, residual_m, manoeuvring, fit: VerticalFit, fixed: dict | None = None):
    """The vertical fit with the height wander, and how strongly the data ask for it.

    Fitted on the straight stretches like ``fit`` (the four-parameter fit); where they do not
    show it (a log-likelihood ratio under :data:`WALK_MIN_LOG_LR`: survey lines of a few
    minutes leave too few bins below the frequency where a wander overtakes the white height
    noise), the whole record is asked too, turns included, and a wander it finds is held at the
    whole record's value while the straight stretches fit the rest - unless they refuse it
    (:data:`WALK_HELD_MAX_COST`): long enough to show it, they would, and the turns made it.

    Parameters
    ----------
    time, residual_m, manoeuvring, fixed
        As given to :func:`fit_vertical_spectrum` for ``fit``.
    fit : VerticalFit
        The four-parameter fit on the straight stretches.

    Returns
    -------
    tuple or None
        ``(walk_fit, log_likelihood_ratio, where, whole)``: the five-parameter fit, its ratio
        over ``fit`` (or the whole record's over its own four-parameter fit), ``"straight
        stretches"`` or ``"whole record"``, and what the whole record said where it was asked
        (else empty): ``whole_record_log_likelihood_ratio`` and, where it found a wander,
        ``whole_record_height_walk_m`` and ``straight_stretches_cost`` (the straight
        stretches' loss with it held; above :data:`WALK_HELD_MAX_COST` it is refused). None
        when the fit fails.
    """
    fixed = dict(fixed or {})
    wfit = fit_vertical_spectrum(time, residual_m, manoeuvring, fixed=fixed, start=fit.model, walk=True)
    if wfit is None:
        return None
    lr = float(fit.nll - wfit.nll)
    if lr >= WALK_MIN_LOG_LR or manoeuvring is None or not np.any(manoeuvring):
        return wfit, lr, "straight stretches", {}
    whole = fit_vertical_spectrum(time, residual_m, None, fixed=fixed)
    whole_w = (
        fit_vertical_spectrum(time, residual_m, None, fixed=fixed, start=whole.model, walk=True) if whole else None
    )
    if whole_w is None:
        return wfit, lr, "straight stretches", {}
    whole_lr = float(whole.nll - whole_w.nll)
    said = {"whole_record_log_likelihood_ratio": whole_lr}
    if whole_lr < WALK_MIN_LOG_LR:
        return wfit, lr, "straight stretches", said
    held = fit_vertical_spectrum(
        time,
        residual_m,
        manoeuvring,
        fixed={**fixed, "height_walk_m": whole_w.model.height_walk_m},
        start=fit.model,
        walk=True,
    )
    if held is None:
        return wfit, lr, "straight stretches", said
    said.update(
        whole_record_height_walk_m=whole_w.model.height_walk_m, straight_stretches_cost=float(held.nll - fit.nll)
    )
    if said["straight_stretches_cost"] > WALK_HELD_MAX_COST:
        return wfit, lr, "straight stretches", said
    return held, whole_lr, "whole record", said


def height_noise_density(nav, f_t, time, height, ellipsoid: Ellipsoid = WGS84, walk: bool = False):
    """A height channel's white noise against the inertial height, as information per second.

    The vertical-channel spectrum (:func:`fit_vertical_spectrum`, turns left out) fitted to the
    mechanized minus measured heights of one channel: its per-sample height sigma ``s`` at
    sample spacing ``dt`` gives the noise density ``s^2 dt`` (m^2 s), comparable between
    channels of different rates (a 1-Hz channel of 0.1 m and a 25-Hz one of 0.5 m hold the same).

    Parameters
    ----------
    nav : Navigation
    f_t : ndarray, shape (n, 3)
        Specific force on the triad at ``nav.time``, m/s^2.
    time, height : ndarray, shape (k,)
        The channel's times (s, record base) and ellipsoidal heights (m).
    ellipsoid : Ellipsoid

    walk : bool
        Also fit the height wander (:data:`WALK_MIN_LOG_LR`) and return its log-likelihood ratio.

    Returns
    -------
    tuple of float or None
        ``(density_m2s, sigma_m, dt_s)`` (with ``walk``, and the wander's log-likelihood ratio);
        None where the fit finds no straight stretch.
    """
    t = np.asarray(time, float)
    h = np.asarray(height, float)
    ok = np.isfinite(h)
    t, e = vertical_residual(nav, t[ok], h[ok], ellipsoid)
    t, e, _ = fill_short_gaps(t, e)
    if t.size < 16:
        return None
    man = _horizontal_specific_force(nav, f_t, t) > MANOEUVRE_MPS2
    fit = fit_vertical_spectrum(t, e, man)
    if fit is None:
        return None
    s = float(fit.model.height_sigma_m)
    if not walk:
        return s * s * fit.dt_s, s, float(fit.dt_s)
    found = fit_height_wander(t, e, man, fit)
    return s * s * fit.dt_s, s, float(fit.dt_s), (found[1] if found is not None else 0.0)


def digest(*arrays) -> str:
    """A fingerprint of arrays' dtypes, shapes and values (a memo's key)."""
    h = hashlib.blake2b(digest_size=16)
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(repr((a.dtype.str, a.shape)).encode())
        h.update(memoryview(a).cast("B"))
    return h.hexdigest()


def memoised(memo: dict | None, key, fn, *args, **kwargs):
    """``fn(*args, **kwargs)``, kept in ``memo`` under ``key`` and returned from there when asked
    again (``memo`` None: computed every time).  The result is shared, never to be changed."""
    if memo is None:
        return fn(*args, **kwargs)
    if key not in memo:
        memo[key] = fn(*args, **kwargs)
    return memo[key]


def identify_params(
    params, nav, f_t, alt_time, alt_height, speed_mps: float, ellipsoid: Ellipsoid = WGS84, memo: dict | None = None
):
    """Identify the ``model:`` noise levels and anomaly prior of one flight.

    Keys the user set in the config (``params.given``) are held fixed; the others are
    estimated by :func:`fit_vertical_spectrum`.  When ``params.target_resolution_m`` is set,
    the anomaly sigma is then chosen to give that resolution (:func:`prior_for_resolution`).

    Parameters
    ----------
    params : InmParams
    nav : Navigation
        Uncorrected mechanization.
    f_t : ndarray (n, 3)
        Specific force on the triad at ``nav.time``, m/s^2.
    alt_time, alt_height : ndarray (m,)
        Finite altimeter samples.
    speed_mps : float
        Typical ground speed on the straight stretches, m/s (converts time to space).
    ellipsoid : Ellipsoid
    memo : dict, optional
        The vertical channel's spectral fits by their inputs (the residual, the manoeuvres and
        the noise levels held): identifications of one flight with other accelerometer noise
        (which enters only through the tilt leak, after the fits) share them.

    Returns
    -------
    params : InmParams
        A copy with the identified values.
    report : dict
        Per key: ``value``, ``sigma_factor`` (1-sigma multiplicative), ``how``
        (``identified`` / ``config`` / ``default``); plus ``method``, ``seconds_used``,
        ``resolution_m`` and warnings.
    """
    v = max(float(speed_mps), 1.0)
    given = set(getattr(params, "given", ()))
    t, e = vertical_residual(nav, alt_time, alt_height, ellipsoid)
    # a few dropped epochs (real receivers) must not break every straight stretch
    t, e, n_filled = fill_short_gaps(t, e)
    man = _horizontal_specific_force(nav, f_t, t) > MANOEUVRE_MPS2
    fixed = {}
    if "anomaly_sigma_mps2" in given:
        fixed["anomaly_sigma_mps2"] = params.anomaly_sigma_mps2
    if "anomaly_lambda_per_m" in given:
        fixed["anomaly_tau_s"] = 1.0 / max(params.anomaly_lambda_per_m * v, 1e-12)
    if "gravimeter_white_mps2" in given and params.gravimeter_white_mps2 > 0:
        fixed["white_mps2"] = params.gravimeter_white_mps2
    if "altimeter_sigma_m" in given:
        fixed["height_sigma_m"] = params.altimeter_sigma_m
    fixed = {k: min(max(val, BOUNDS[k][0]), BOUNDS[k][1]) for k, val in fixed.items()}
    # "warnings" may have degraded the estimate and reach the user (stderr, log); "notes" are
    # facts of how the fit went that do not (summary.json only)
    report: dict = {"method": "whittle-vertical-spectrum", "warnings": [], "notes": []}
    if n_filled:
        report["notes"].append(
            f"model identification: {n_filled} missing height samples (gaps of at most {MAX_FILL_SAMPLES} "
            f"samples or {MAX_FILL_S:g} s) filled by linear interpolation for the fit"
        )
    report["height_samples_filled"] = n_filled
    # the noise levels are fitted with the anomaly's spectrum free even where the config sets the
    # prior: the prior is the smoother's, a Markov process that need not be the field's spectrum,
    # and held in the fit it made the white level absorb the misfit (a random-walk prior of 283
    # mGal fixed on quick unseen U006: white 69 mGal in 1 s, 16.9 mGal off for 1.9 by default)
    noise_fixed = {k: val for k, val in fixed.items() if k in NOISE_KEYS}
    # the fits below are functions of these inputs alone
    data = digest(t, e, man) if memo is not None else None

    def fitted(name, fn, *args, **kwargs):
        return memoised(memo, (name, data, repr(sorted(kwargs.items())), repr(args[3:])), fn, *args, **kwargs)

    fit = fitted("fit", fit_vertical_spectrum, t, e, man, fixed=noise_fixed)
    whole_flight = False
    if fit is None:
        # no straight stretches long enough (a flight of turns): the noise levels from the whole
        # flight; the turns' attitude-error leak then counts as noise, which errs on the side of
        # smoothing
        fit = fitted("whole", fit_vertical_spectrum, t, e, None, fixed=noise_fixed)
        whole_flight = fit is not None
        if fit is not None:
            report["warnings"].append(
                f"model identification: straight stretches shorter than {MIN_RUN_S:.0f} s in all; noise "
                "levels identified over the whole flight, turns included"
            )
    elif fit.short_runs:
        report["notes"].append(
            f"model identification: no straight stretch of {MIN_RUN_S:.0f} s; {fit.n_runs} shorter stretches "
            f"pooled ({fit.seconds_used:.0f} s)"
        )
    if fit is None:
        report["method"] = "none"
        report["warnings"].append(
            f"model identification: no straight stretch of {MIN_RUN_S:.0f} s with evenly sampled "
            "heights; the configured or default noise levels and anomaly prior are used"
        )
        for k in IDENTIFIED_KEYS:
            report[k] = {
                "value": getattr(params, k),
                "sigma_factor": None,
                "how": "config" if k in given else "default",
            }
        return params, report
    if not whole_flight and "altimeter_sigma_m" not in given:
        # the height wander (WALK_MIN_LOG_LR): fitted as a fifth parameter, kept only when the
        # likelihood prefers it clearly
        found = fitted("wander", fit_height_wander, t, e, man, fit, noise_fixed)
        if found is not None:
            wfit, lr, where, whole_said = found
            report["height_walk"] = {
                "height_walk_m": wfit.model.height_walk_m,
                "sigma_factor": wfit.sigma_factor.get("height_walk_m"),
                "log_likelihood_ratio": lr,
                "found_on": where,
                "applied": lr >= WALK_MIN_LOG_LR,
                **whole_said,
            }
            if where == "straight stretches" and "straight_stretches_cost" in whole_said:  # refused
                report["notes"].append(
                    "model identification: the whole record shows a height wander (log-likelihood ratio "
                    f"{whole_said['whole_record_log_likelihood_ratio']:.1f}) that the straight stretches refuse "
                    f"({whole_said['straight_stretches_cost']:.1f} worse with it): the turns' own errors, not applied"
                )
            if lr >= WALK_MIN_LOG_LR:
                fit = wfit
                if where == "whole record":
                    # held at the whole record's value in the white level's test too
                    noise_fixed = {**noise_fixed, "height_walk_m": wfit.model.height_walk_m}
    m = dataclasses.replace(fit.model, **{k: val for k, val in fixed.items() if k not in NOISE_KEYS})
    white_how = "identified"
    factor_w = fit.sigma_factor.get("white_mps2")
    if "white_mps2" not in fixed and (factor_w is None or factor_w > WHITE_MAX_FACTOR):
        # the white level hides under the height noise (f^4) above and the anomaly below; when
        # the likelihood does not pin it, a typical gravimeter's figure is safer than a value
        # that only absorbed the anomaly's flat part or a short flight's scatter
        m = dataclasses.replace(m, white_mps2=WHITE_DEFAULT_MPS2)
        white_how = "default (not resolved by the data)"
    elif "white_mps2" not in fixed and whole_flight:
        # with the turns in, the likelihood pins a "white" level that is the turns' attitude
        # leak (tens of mGal on a strapdown flight of short lines), and the first pass would then
        # find no field above it and smooth the field away; the datasheet figure instead, and
        # refine_prior's noise calibration raises it if the straight flight shows more
        m = dataclasses.replace(m, white_mps2=WHITE_DEFAULT_MPS2)
        white_how = "default (whole-flight fit: turns dominate the white level)"
    if white_how == "identified" and "white_mps2" not in fixed:
        # the fitted white level is the whole vertical channel's, the horizontal accelerometers'
        # noise through the tilt included; the filter holds that leak already (accel_noise_mps2
        # through its attitude), so counting it again as gravimeter noise smoothed the field
        # away (measured: 4x the gravimeter's white, a resolution of 19 km for 5 km)
        lf = tilt_leak_factor(nav, t, man)
        leak = params.accel_noise_mps2 * math.sqrt(lf)
        own = white_less_tilt_leak(m.white_mps2, leak, factor_w)
        report["tilt_leak"] = {
            "tilt_rms_deg": math.degrees(math.asin(math.sqrt(lf))),
            "leak_mps2": leak,
            "vertical_white_mps2": m.white_mps2,
            "applied": own is not None,
        }
        if own is not None:
            m = dataclasses.replace(m, white_mps2=own)
            white_how = "identified (vertical white less the horizontal accelerometers' leak through the tilt)"
        elif tilt_leak_exceeds_white(m.white_mps2, leak, factor_w):
            report["warnings"].append(
                f"model identification: the vertical channel's white level ({m.white_mps2:.2g} m/s^2) is below "
                f"the noise accel_noise_mps2 = {params.accel_noise_mps2:.2g} would leak into it through the "
                f"{report['tilt_leak']['tilt_rms_deg']:.1f} deg RMS tilt ({leak:.2g}): the horizontal "
                "accelerometers are quieter than that; give accel_noise_mps2 from the datasheet"
            )
        if own is None:
            # the vertical white taken whole as the gravimeter's: only a level the data tell from
            # the datasheet's (the Hessian's factor is local, and the likelihood is flat in the
            # white level below the anomaly's; where the leak is taken off, white_less_tilt_leak
            # floors the remainder at the datasheet figure already)
            held = fitted("white", white_log_likelihood_ratio, t, e, man, fit, noise_fixed)
            report["white_log_likelihood_ratio"] = held
            if held < WHITE_MIN_LOG_LR:
                m = dataclasses.replace(m, white_mps2=WHITE_DEFAULT_MPS2)
                white_how = (
                    f"default (the data do not exclude it: log-likelihood ratio {held:.1f} < {WHITE_MIN_LOG_LR:g})"
                )
    if params.target_resolution_m is not None:
        m = prior_for_resolution(m, v, params.target_resolution_m, fit.dt_s)
    found = {
        "anomaly_sigma_mps2": m.anomaly_sigma_mps2,
        "anomaly_lambda_per_m": 1.0 / (m.anomaly_tau_s * v),
        "gravimeter_white_mps2": m.white_mps2,
        "altimeter_sigma_m": m.height_sigma_m,
    }
    if params.target_resolution_m is None:
        # a configured value is used exactly as written (the fit held it, up to rounding)
        found.update({k: getattr(params, k) for k in IDENTIFIED_KEYS if k in given})
    new = dataclasses.replace(params, **found)
    src = {
        "anomaly_sigma_mps2": "anomaly_sigma_mps2",
        "anomaly_lambda_per_m": "anomaly_tau_s",
        "gravimeter_white_mps2": "white_mps2",
        "altimeter_sigma_m": "height_sigma_m",
    }
    for k in IDENTIFIED_KEYS:
        how = "config" if k in given else "identified"
        if k == "anomaly_sigma_mps2" and params.target_resolution_m is not None:
            how = "target_resolution_m"
        if k == "gravimeter_white_mps2" and how == "identified":
            how = white_how
        factor = None if k in given else fit.sigma_factor.get(src[k])
        report[k] = {"value": getattr(new, k), "sigma_factor": factor, "how": how}
    for k in (k for k in fit.at_bound if k not in fixed):
        # only the height noise is used as fitted: a white level at its bound is replaced by the
        # datasheet figure above, and the anomaly prior is chosen again by refine_prior
        used_as_fitted = k == "height_sigma_m" and report["altimeter_sigma_m"]["how"] == "identified"
        report["warnings" if used_as_fitted else "notes"].append(
            f"model identification: {k} ended on its bound {BOUNDS[k]} (SI); the data say little about it"
        )
    if fit.unresolved and "anomaly_lambda_per_m" not in given:
        report["anomaly_lambda_per_m"]["how"] = "identified (lower bound: straight stretches too short)"
    report["seconds_used"] = fit.seconds_used
    report["straight_runs"] = fit.n_runs
    report["speed_mps"] = v
    report["spectral_model"] = dataclasses.asdict(m)
    report["height_dt_s"] = fit.dt_s
    report["resolution_m"] = wiener_resolution_m(m, v, fit.dt_s)
    return new, report


#: Least gain the chosen prior's smoother keeps below the lowest analysed frequency.
PASS_BELOW_GAIN = 0.9
#: Resolution (m) of the first, deliberately wide pass of :func:`refine_prior`.
WIDE_RESOLUTION_M = 1000.0
#: Correlation time of the wide prior, s (long: it claims no knowledge of the mean level).
WIDE_TAU_S = 3600.0


def _model_of(report) -> SpectralModel:
    return SpectralModel(**report["spectral_model"])


def wide_prior_params(params, report, speed_mps: float):
    """Settings for the first pass: the identified noise and a prior of fine resolution.

    Its smoother passes the signal AND the noise up to :data:`WIDE_RESOLUTION_M`; the spectrum
    of its estimate then shows the signal above the (known) noise at every wavelength longer
    than that, over the whole flight - turns included, where the filter's attitude states
    keep the estimate sound - unlike the straight stretches used for the noise levels.
    """
    v = max(float(speed_mps), 1.0)
    # the wide pass's filter is given the white height noise alone (the wander is taken into
    # the filter's height sigma once the resolution is chosen, filter_height_sigma); its
    # resolution is set against that noise
    m = dataclasses.replace(_model_of(report), anomaly_tau_s=WIDE_TAU_S, height_walk_m=0.0)
    m = prior_for_resolution(m, v, WIDE_RESOLUTION_M, report["height_dt_s"])
    return dataclasses.replace(
        params, anomaly_sigma_mps2=m.anomaly_sigma_mps2, anomaly_lambda_per_m=1.0 / (m.anomaly_tau_s * v)
    )


def smoother_gain(freq_hz, model: SpectralModel, dt_h: float) -> np.ndarray:
    """Steady-state transfer ``S_g / (S_g + S_n)`` of the smoother of ``model`` (its Markov
    prior against the vertical channel's noise, height samples ``dt_h`` s apart) at
    ``freq_hz``; :func:`wiener_resolution_m` is where it is 1/2."""
    f = np.asarray(freq_hz, float)
    s_g = markov_psd(f, model.anomaly_sigma_mps2, model.anomaly_tau_s)
    return s_g / (s_g + _noise_psd_g(f, model, dt_h))


def _noise_psd_g(f, m: SpectralModel, dt_h: float):
    """Noise of the vertical channel referred to the disturbance, two-sided, (m/s^2)^2/Hz."""
    out = m.white_mps2**2 + m.height_sigma_m**2 * dt_h * (2.0 * math.pi * f) ** 4
    if m.height_walk_m > 0.0:
        out = out + m.height_walk_m**2 * (2.0 * math.pi * f) ** 2
    return out


def filter_height_sigma(model: SpectralModel, speed_mps: float, dt_h: float, f_min_hz: float) -> float:
    """The white per-sample height sigma (m) the filter is given for ``model``'s height noise.

    The filter's height measurements have white noise; the height wander (``height_walk_m``)
    is not white.  The sigma whose noise, referred to the disturbance, equals the model's at the
    smoother's half-power point ``f_c`` (:func:`wiener_resolution_m`) puts the filter's
    half-power point at the same frequency: ``s^2 dt w_c^4 = sigma^2 dt w_c^4 + q w_c^2``.
    ``f_c`` is taken no lower than ``f_min_hz`` (the lowest frequency the flight shows, Hz): a
    prior that passes no wavelength the flight holds would otherwise leave the heights a sigma
    of hundreds of metres, and the vertical channel unaided.  Without a wander,
    ``height_sigma_m``.
    """
    if model.height_walk_m <= 0.0:
        return float(model.height_sigma_m)
    v = max(float(speed_mps), 1.0)
    res = wiener_resolution_m(model, v, dt_h)
    f_c = max(v / (2.0 * res) if math.isfinite(res) else 0.0, float(f_min_hz))
    w_c = 2.0 * math.pi * f_c
    return float(math.sqrt(model.height_sigma_m**2 + model.height_walk_m**2 / (dt_h * w_c * w_c)))


def markov_psd(f, sigma, tau):
    """Two-sided PSD of a first-order Gauss-Markov process of ``sigma`` (broadcast) and
    correlation time ``tau`` (s) at ``f`` (Hz): ``2 sigma^2 lam / (lam^2 + w^2)``, ``lam = 1 /
    tau``, ``w = 2 pi f``; it integrates to ``sigma^2`` over all frequencies."""
    lam = 1.0 / tau
    return 2.0 * sigma**2 * lam / (lam**2 + (2.0 * math.pi * f) ** 2)


def prior_risk(f, s_signal, s_noise, sigma, tau) -> float:
    """Expected error variance (up to a constant factor) of the smoother with prior (sigma, tau).

    ``sum_k [(1 - H_k)^2 S_s,k + H_k^2 S_n,k]`` with ``H = S_g / (S_g + S_n)``, the
    steady-state transfer of the RTS smoother built on the Markov prior ``S_g`` - applied to a
    signal of spectrum ``S_s``, whatever its shape.
    """
    s_g = markov_psd(f, sigma, tau)
    h = s_g / (s_g + s_noise)
    return float(np.sum((1.0 - h) ** 2 * s_signal + h**2 * s_noise))


def tapered_periodogram(g, weight, dt_s: float):
    """Two-sided periodogram of ``g`` through the Hann taper times ``weight``.

    ``g`` less a weighted polynomial (:data:`DETREND_ORDER`), ``dt |FFT(w g)|^2 / sum w^2``.

    Parameters
    ----------
    g : ndarray, shape (N,)
        The first pass's estimate, m/s^2.
    weight : ndarray, shape (N,)
        :func:`straight_weight`, in [0, 1].
    dt_s : float
        Sample spacing, s.

    Returns
    -------
    f : ndarray, shape N // 2 + 1
        ``rfftfreq(N, dt_s)``, Hz.
    p : ndarray, shape like ``f``
        (m/s^2)^2/Hz.
    """
    g = np.asarray(g, float)
    k = np.linspace(-1.0, 1.0, g.size)
    w = np.hanning(g.size) * np.asarray(weight, float)
    g = g - np.polyval(np.polyfit(k, g, DETREND_ORDER, w=np.sqrt(w) + 1e-12), k)
    return np.fft.rfftfreq(g.size, dt_s), dt_s * np.abs(np.fft.rfft(w * g)) ** 2 / np.sum(w**2)


def prewhitened_periodogram(g, weight, dt_s: float):
    """Two-sided periodogram of ``g`` on the straight stretches, prewhitened against leakage.

    The first differences of ``g`` (a field's steep spectrum flattened by ``f^2``, the offsets
    between lines gone), less a weighted straight line (the quadratic of ``g``,
    :data:`DETREND_ORDER`), through the Hann taper times ``weight`` (zero in turns, short
    cosine ramps between), divided by ``|2 sin(pi f dt)|^2``.  The ramps of the plain one
    (:func:`tapered_periodogram`) spread a strong field's long-wavelength power over the bands
    where the smoother's resolution is decided (quick U102, a 45 mGal field: 3-5x the field's
    spectrum at 100-200 s periods, 23x at 75 s); this one is within 1.1-1.4x there, but leaks a
    steep noise spectrum downwards instead, so :func:`refine_prior` takes the smaller of the two
    per bin.  Parameters as :func:`tapered_periodogram`; it returns ``(f, p)`` on
    ``rfftfreq(N - 1, dt_s)`` (Hz; (m/s^2)^2/Hz, ``p[0] = 0``).
    """
    g = np.asarray(g, float)
    wt = np.asarray(weight, float)
    m = g.size - 1
    w = np.hanning(g.size)[1:] * np.minimum(wt[1:], wt[:-1])
    k = np.linspace(-1.0, 1.0, m)
    d = np.diff(g)
    d = d - np.polyval(np.polyfit(k, d, DETREND_ORDER - 1, w=np.sqrt(w) + 1e-12), k)
    f = np.fft.rfftfreq(m, dt_s)
    p = dt_s * np.abs(np.fft.rfft(w * d)) ** 2 / np.sum(w**2)
    gain = (2.0 * np.sin(np.pi * f * dt_s)) ** 2
    p[1:] /= gain[1:]
    p[0] = 0.0
    return f, p


def smoother_sigma_scale(f, s_signal, s_noise, sigma, tau) -> float:
    """Factor from the smoother's own 1-sigma to its expected error on the field seen.

    The RTS smoother's covariance is its model's: under the Markov prior ``S_g`` its error
    variance is ``sum S_g S_n / (S_g + S_n)`` (the same sum as :func:`prior_risk` with
    ``S_s = S_g``).  A field seen from the air falls off faster than the Markov tail, so over
    the same bands the error the chosen smoother makes on the field the spectrum shows
    (:func:`prior_risk` with ``S_s`` the counted field) is smaller; on the unseen flights about
    half (docs/method.md, "Honest sigma").  The square root of the two sums' ratio, in
    [:data:`SIGMA_SCALE_BOUNDS`]; 1 when either is nil.

    Parameters
    ----------
    f : ndarray, shape (K,)
        Frequencies of the first pass's periodogram, Hz.
    s_signal, s_noise : ndarray, shape (K,)
        The field counted in each bin and the noise, (m/s^2)^2/Hz.
    sigma, tau : float
        The chosen Markov prior, m/s^2 and s.
    """
    s_g = markov_psd(f, sigma, tau)
    own = float(np.sum(s_g * s_noise / (s_g + s_noise)))
    seen = prior_risk(f, s_signal, s_noise, sigma, tau)
    if not (own > 0.0 and seen > 0.0):
        return 1.0
    return float(np.clip(math.sqrt(seen / own), *SIGMA_SCALE_BOUNDS))


def keep_default_prior(params, report, speed_mps: float, min_s: float, span_s: float = 0.0):
    """The anomaly prior as configured or defaulted (a record too short to identify it).

    The identified noise levels stay; ``report`` says why the prior was not identified, with a
    warning when a default part of it is used (``span_s``: the record's length, s).
    """
    defaults = type(params)()
    given = set(getattr(params, "given", ()))
    new = dataclasses.replace(
        params,
        **{k: getattr(params if k in given else defaults, k) for k in ("anomaly_sigma_mps2", "anomaly_lambda_per_m")},
    )
    report = dict(report)
    for k in ("anomaly_sigma_mps2", "anomaly_lambda_per_m"):
        report[k] = {
            "value": getattr(new, k),
            "sigma_factor": None,
            "how": "config" if k in given else f"default (record shorter than {min_s:.0f} s)",
        }
    if not {"anomaly_sigma_mps2", "anomaly_lambda_per_m"} <= given:
        # the broad default prior smooths a field unlike it to tens of km (issue 12's first
        # finding): the user must know the product rests on it
        report["warnings"] = list(report.get("warnings", [])) + [
            f"model identification: the record ({span_s:.0f} s) is shorter than {min_s:.0f} s, too short "
            "to see the field's spectrum; the anomaly prior is the default "
            f"({defaults.anomaly_sigma_mps2 / 1e-5:.0f} mGal over {1e-3 / defaults.anomaly_lambda_per_m:.0f} km) "
            "where model.anomaly_sigma_mps2 / anomaly_lambda_per_m do not give it"
        ]
    if "spectral_model" in report:
        v = max(float(speed_mps), 1.0)
        m = dataclasses.replace(
            SpectralModel(**report["spectral_model"]),
            anomaly_sigma_mps2=new.anomaly_sigma_mps2,
            anomaly_tau_s=1.0 / (new.anomaly_lambda_per_m * v),
        )
        report["spectral_model"] = dataclasses.asdict(m)
        report["resolution_m"] = wiener_resolution_m(m, v, report["height_dt_s"])
    return new, report


def straight_weight(nav, f_t, times, also=None) -> np.ndarray:
    """Weight in [0, 1] at ``times``: 1 on straight flight, 0 in turns, cosine ramps between.

    Turns (horizontal specific force above :data:`MANOEUVRE_MPS2`, dilated by
    :data:`MANOEUVRE_MARGIN_S`) carry a strapdown system's largest errors; the ramps
    (:data:`MANOEUVRE_MARGIN_S` long) keep a window built on this weight free of the leakage
    a hard cut would bring.  ``also`` (bool at ``times``, optional): more epochs left out the
    same way (where the IMU's specific force is not known).
    """
    t = np.asarray(times, float)
    bad = _horizontal_specific_force(nav, f_t, t) > MANOEUVRE_MPS2
    if also is not None:
        bad = bad | np.asarray(also, bool)
    if t.size < 2:
        return (~bad).astype(float)
    return ramped_weight(bad, float(np.median(np.diff(t))))


def ramped_weight(bad, dt_s: float) -> np.ndarray:
    """Weight in [0, 1] (N,): 0 on the samples ``bad`` (bool (N,), ``dt_s`` s apart) dilated by
    :data:`MANOEUVRE_MARGIN_S`, rising to 1 over a cosine ramp as long (:func:`straight_weight`)."""
    bad = np.asarray(bad, bool)
    m = max(1, int(round(MANOEUVRE_MARGIN_S / dt_s)))
    ramp = np.hanning(2 * m + 1)
    ramp /= ramp.sum()
    # dilate by m, then smooth with a kernel of the same half width: 0 inside the dilated turn's
    # core, rising to 1 over m samples
    c = np.concatenate([[0], np.cumsum(bad.astype(np.int64))])
    i = np.arange(bad.size)
    dil = (c[np.clip(i + m + 1, 0, bad.size)] - c[np.clip(i - m, 0, bad.size)]) > 0
    return np.clip(np.convolve((~dil).astype(float), ramp, mode="same"), 0.0, 1.0)


#: Averaging window (s) of the first-pass estimate whose variance the prior must be able to
#: hold (:func:`field_variance_seen`): long enough that the wide pass's noise averages down.
#: The average is Hann-weighted over twice this span (its first null at ``1 / window``, as a
#: running mean's over the span itself): a running mean's sidelobes fall as ``f^-2`` only and
#: let the height noise, rising as ``f^4`` up to the wide pass's cut-off, through - on a 25-min
#: turning grid its noise through a 120-s running mean was 8.0 mGal, through the Hann 0.7, so a
#: field of 5 mGal along the lines was counted as none (docs/benchmarks.md, "The field's
#: variance through a Hann window").
FIELD_VAR_WINDOW_S = 120.0
#: Least fraction of that variance the prior must hold.
FIELD_VAR_HELD = 0.25
#: Only the variance above this many times the first pass's own noise variance (through the
#: same window) counts as field: the wide pass also carries slow errors its noise model does
#: not hold (the gravimeter's drift, turbulence through attitude errors), which on weak fields
#: exceed the field (measured: 1.24 mGal "seen" on a 0.32 mGal field).
FIELD_VAR_NOISE_MARGIN = 3.0
#: A band of the first pass's spectrum counts as field only this many standard errors above
#: the noise (:func:`refine_prior`): a chance excess of noise must not widen the smoother.
SIGNAL_MARGIN_SE = 2.0
#: Above a band without field, a band counts again only when its excess is this many margins
#: (``SIGNAL_MARGIN_SE`` standard errors each) above the noise: a field's spectral line, not
#: chance (:func:`refine_prior`).
SIGNAL_RESUME_MARGINS = 5.0


def _window_kernel(f, window_s: float, span_s: float, hann: bool = False):
    """|transfer|^2 of "running mean over ``window_s``, then minus the mean over ``span_s``";
    with ``hann``, of the Hann-weighted mean over ``2 window_s`` (:data:`FIELD_VAR_WINDOW_S`)."""
    f = np.asarray(f, float)
    less_mean = 1.0 - np.sinc(f * span_s) ** 2
    if not hann:
        return np.sinc(f * window_s) ** 2 * less_mean
    # a Hann window of length L: sinc(f L) / (1 - (f L)^2), 1/2 at f L = 1
    x = 2.0 * window_s * f
    den = 1.0 - x * x
    near = np.abs(den) < 1e-9
    h = np.where(near, 0.5, np.sinc(x) / np.where(near, 1.0, den))
    return h * h * less_mean


def windowed_variance(psd, window_s: float, span_s: float, hann: bool = False) -> float:
    """Variance of a stationary process seen through :func:`_window_kernel`, (m/s^2)^2.

    Parameters
    ----------
    psd : callable
        Two-sided PSD ``S(f)`` of the process, (m/s^2)^2/Hz, vectorised over ``f`` (Hz).
    window_s, span_s : float
        Running-mean window (with ``hann``, half the Hann window's length) and the record's
        span, s.
    hann : bool
        The Hann-weighted mean of :func:`field_variance_seen` instead of the running mean.
    """
    f = np.geomspace(1e-3 / span_s, 20.0 / window_s, 4000)
    y = psd(f) * _window_kernel(f, window_s, span_s, hann)
    return float(2.0 * np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(f)))


def _windowed_variances(psd, span_s: float, window_s: float = FIELD_VAR_WINDOW_S) -> np.ndarray:
    """:func:`windowed_variance` (Hann-weighted) of several processes at once, (m/s^2)^2 (p,).

    ``psd`` maps the frequencies (Hz, (k,)) to the PSDs ((p, k)); the same quadrature, row by row.
    """
    f = np.geomspace(1e-3 / span_s, 20.0 / window_s, 4000)
    y = psd(f) * _window_kernel(f, window_s, span_s, hann=True)[None, :]
    return 2.0 * np.sum(0.5 * (y[:, 1:] + y[:, :-1]) * np.diff(f)[None, :], axis=1)


def field_variance_seen(g, weight, dt_s: float, window_s: float = FIELD_VAR_WINDOW_S) -> float:
    """Weighted variance of ``g`` averaged with Hann weights over ``2 window_s`` (weights: 0 in
    turns), (m/s^2)^2; :func:`windowed_variance` with ``hann=True`` is a process's through it.

    Parameters
    ----------
    g : ndarray (N,)
        An estimate of the disturbance at spacing ``dt_s``, m/s^2.
    weight : ndarray (N,)
        :func:`straight_weight`.
    """
    m = max(1, int(round(2.0 * window_s / dt_s)))
    if m > np.size(g):
        # a record shorter than the window shows no variance through it
        return 0.0
    # (the end samples of np.hanning are zero: m nonzero weights)
    kern = np.hanning(m + 2)[1:-1]
    kern = kern / kern.sum()
    # the record's ends ramped over half the window, and only epochs whose window holds 3/4 of
    # its weight: a window cut short by a hard end or a turn's ramp is narrower and passes the
    # height noise that rises to the wide pass's cut-off (on height noise alone, through the wide
    # pass's transfer: 9.9x the variance windowed_variance states with the record's hard ends
    # and 1/2 of the weight, 1.4x as here; 2.2x with three turns, within FIELD_VAR_NOISE_MARGIN)
    weight = np.asarray(weight, float).copy()
    weight[0] = weight[-1] = 0.0
    half = np.hanning(max(m // 2, 1) + 2)[1:-1]
    weight = np.minimum(weight, np.convolve(weight, half / half.sum(), mode="same"))
    num = np.convolve(g * weight, kern, mode="same")
    den = np.convolve(weight, kern, mode="same")
    ok = den > 0.75
    if ok.sum() < 2:
        return 0.0
    lp = num[ok] / den[ok]
    w = weight[ok]
    if w.sum() <= 0:
        return 0.0
    mean = float(np.sum(w * lp) / np.sum(w))
    return float(np.sum(w * (lp - mean) ** 2) / np.sum(w))


def band_margin(noise_psd) -> float:
    """:data:`SIGNAL_MARGIN_SE` standard errors of a band's mean excess over the noise, where the
    band holds no field, (m/s^2)^2/Hz.

    Each bin of a periodogram scatters as its own mean times an Exp(1) variate, so the mean of
    ``P / H1^2`` over a band of ``m`` bins whose noise is ``S_n,i`` has the standard error
    ``sqrt(sum S_n,i^2) / m``; ``mean(S_n) / sqrt(m)`` only where the noise is flat across the
    band.  Where it is not, the band's top bins set the scatter: the height noise rises as
    ``f^4``, 120x across the lowest band (bins 3-10) of a short flight with metre-level GNSS
    heights, whose scatter ``mean / sqrt(m)`` understates 1.45x, so that a chance excess
    counted as field (docs/benchmarks.md, "The band's margin where the noise is not flat").

    Parameters
    ----------
    noise_psd : ndarray, shape (m,)
        ``S_n`` at the band's bins (as ``P / H1^2`` sees it), (m/s^2)^2/Hz.
    """
    s = np.asarray(noise_psd, float)
    return float(SIGNAL_MARGIN_SE * np.sqrt(np.sum(s * s)) / s.size)


def non_increasing_fit(values, weights) -> np.ndarray:
    """Weighted least-squares non-increasing fit of ``values`` (pool adjacent violators).

    Parameters
    ----------
    values, weights : ndarray (k,)
        Values in order of increasing frequency, and their weights (> 0).

    Returns
    -------
    ndarray (k,)
        The non-increasing sequence closest to ``values`` in the weighted squared sense.
    """
    mean, wt, cnt = [], [], []  # pooled blocks: mean, weight, length
    for x, y in zip(np.asarray(values, float), np.asarray(weights, float)):
        mean.append(float(x))
        wt.append(float(y))
        cnt.append(1)
        while len(mean) > 1 and mean[-2] < mean[-1]:
            m2, w2, c2 = mean.pop(), wt.pop(), cnt.pop()
            mean[-1] = (mean[-1] * wt[-1] + m2 * w2) / (wt[-1] + w2)
            wt[-1] += w2
            cnt[-1] += c2
    return np.repeat(mean, cnt)


def band_field(excess, margin, bins, freq=None):
    """The field's spectrum per band of a first-pass periodogram, from the bands' excess over the
    noise (log-spaced bands in order of increasing frequency).

    A field seen from the air has a spectrum that falls with frequency (upward continuation): a
    band above one without field holds none - which keeps a chance excess of noise near the top
    of the periodogram (``P / H1^2`` amplifies it there) from widening the smoother - unless it
    stands :data:`SIGNAL_RESUME_MARGINS` margins above the noise, which no chance excess does;
    the bands kept are replaced by their best non-increasing fit (:func:`non_increasing_fit`,
    weighted by their bins).  A field of a few wavelengths seen at a long record's fine
    frequency resolution has empty bands between its lines and little in the lowest band; a
    plain running minimum kept it at the lowest band's level and dropped every line above the
    first gap (the seed's three-wavelength field over a 16-h line: 15.8 mGal RMS with GNSS,
    10.2 without, with stated sigmas of 0.07 and 0.45 mGal; 0.5 and 0.8 with this).

    Parameters
    ----------
    excess, margin : ndarray (k,)
        Per band: mean of ``P / H1^2 - S_n``, and ``SIGNAL_MARGIN_SE`` standard errors of it,
        (m/s^2)^2/Hz.
    bins : ndarray (k,)
        Periodogram bins per band.
    freq : ndarray (k,), optional
        The bands' mean frequencies, Hz.  Given, the unbiased count past the last counted band is
        held under the counted bands' exponential decay (a field seen from the air falls off at
        least as upward continuation makes it, ``exp(-4 pi f h / v)``; a line fitted to the log of
        the counted bands against frequency, never rising, from the last of them on): an excess
        there that does not follow it is the noise's or the gravimeter's slow error (on the unseen
        flights the drawn Markov error of 165-280 s that the first pass passes), not field the
        smoother misses (docs/benchmarks.md, "The missed field against the truth").  Needs two
        counted bands.

    Returns
    -------
    counted, unbiased : ndarray (k,)
        The field counted per band (above the margin) and the same without the margin.
    """
    excess = np.asarray(excess, float)
    margin = np.asarray(margin, float)
    out = []
    for value in (np.maximum(excess - margin, 0.0), np.maximum(excess, 0.0)):
        kept, alive = np.zeros(excess.size), True
        for j, (val, e, m) in enumerate(zip(value, excess, margin)):
            if val > 0.0 and (alive or e >= SIGNAL_RESUME_MARGINS * m):
                alive, kept[j] = True, val
            else:
                alive = False
        out.append(non_increasing_fit(kept, bins) if kept.size else kept)
    counted, unbiased = out
    c = np.flatnonzero(counted > 0)
    if freq is not None and c.size >= 2:
        fc = np.asarray(freq, float)
        slope = min(float(np.polyfit(fc[c], np.log(counted[c]), 1)[0]), 0.0)
        past = np.arange(c[-1] + 1, counted.size)
        unbiased = unbiased.copy()
        unbiased[past] = np.minimum(unbiased[past], counted[c[-1]] * np.exp(slope * (fc[past] - fc[c[-1]])))
    return counted, unbiased


def refine_prior(params, report, g_first, dt_s: float, wide, speed_mps: float, weight=None):
    """Choose the anomaly prior from the spectrum of a first, wide estimate.

    The first estimate ``g1 = H1 (s + n)`` (``H1`` the wide prior's transfer) has the
    periodogram ``P ~ H1^2 (S_s + S_n)``.  Where ``H1 >= 0.5`` the signal's spectrum is
    estimated, band by band, as ``P / H1^2 - S_n`` minus twice its standard error (only
    signal that stands out of the noise counts); above, the signal is taken to be below the
    noise.  The prior (sigma, tau) on a grid that minimises :func:`prior_risk` for that signal
    is kept: the smoother's resolution is thereby the one of least expected error for THIS
    flight's field and noise, not a fixed assumption about either.

    Parameters
    ----------
    params : InmParams
        After :func:`identify_params` (noise identified).
    report : dict
        Its report (updated and returned).
    g_first : ndarray (N,)
        Smoothed disturbance of the first pass at the filter epochs, m/s^2.
    dt_s : float
        Epoch spacing, s.
    wide : InmParams
        The first pass's settings (:func:`wide_prior_params`).
    speed_mps : float
    weight : ndarray (N,), optional
        :func:`straight_weight`: the periodogram's window is the Hann taper times this, so the
        spectrum is that of the straight stretches (turns carry non-field errors), at the
        whole flight's frequency resolution.
    """
    v = max(float(speed_mps), 1.0)
    g = np.asarray(g_first, float)
    wt = np.ones(g.size) if weight is None else np.asarray(weight, float)
    ok = np.isfinite(g)
    g, wt = g[ok], wt[ok]
    report = dict(report)
    if g.size < 64 or wt.sum() < 64:
        return params, report
    noise = _model_of(report)
    dt_h = report["height_dt_s"]
    given = set(getattr(params, "given", ()))
    n = g.size
    span = n * dt_s
    # the field's variance at long wavelengths, as the wide pass sees it (before detrending):
    # the prior must be able to hold it (below)
    var_seen = field_variance_seen(g, wt, dt_s)
    f, p = tapered_periodogram(g, wt, dt_s)
    sel = slice(3, n // 2)
    f, p = f[sel], p[sel]
    s_n = _noise_psd_g(f, noise, dt_h)
    # the wide pass's transfer is its filter's: white height noise alone (wide_prior_params)
    noise1 = dataclasses.replace(noise, height_walk_m=0.0)
    s_n1 = _noise_psd_g(f, noise1, dt_h) if noise.height_walk_m > 0.0 else s_n
    tau1 = 1.0 / (wide.anomaly_lambda_per_m * v)
    s_g1 = markov_psd(f, wide.anomaly_sigma_mps2, tau1)
    h1 = s_g1 / (s_g1 + s_n1)
    valid = h1 >= 0.5
    # calibrate the noise level on the first pass itself: in the top octave of its band (half
    # to full wide resolution, ~1-2 km) an airborne field is weak, so there P / H1^2 is the
    # noise the filter really passes - the vertical-channel fit can miss parts of it (turbulence
    # coupled through attitude errors, GNSS, the gravimeter's slow error).  Only raised, never
    # lowered: a strong short-wavelength field then errs on the side of smoothing.
    top = valid & (f >= 0.5 * float(f[valid].max())) if valid.any() else valid
    if top.sum() >= 8:
        k_noise = float(np.median(p[top] / (h1[top] ** 2 * s_n[top])))
        # the median of a chi-square(2)/2 periodogram is ln 2 of its mean
        k_noise /= math.log(2.0)
        if k_noise > 1.0:
            s_n = s_n * k_noise
            report["noise_scale"] = k_noise
    k_n = float(report.get("noise_scale", 1.0))

    def first_pass_noise(x):
        # the noise in the wide pass's estimate: the noise PSD through that pass's transfer
        sn = k_n * _noise_psd_g(x, noise, dt_h)
        sn1 = k_n * _noise_psd_g(x, noise1, dt_h) if noise.height_walk_m > 0.0 else sn
        sg = markov_psd(x, wide.anomaly_sigma_mps2, tau1)
        return sn * (sg / (sg + sn1)) ** 2

    # less the datasheet drift the wide pass carries as well (DRIFT_DEFAULT_SIGMA_MPS2: a flight
    # cannot tell it from a field; where the config models the drift, the filter holds it): a
    # weak field (0.6 mGal, quick U2630) is not held by a prior that would then pass the drift
    drift_w = 0.0
    if not config_models_drift(given):
        drift_w = windowed_variance(
            lambda x: markov_psd(x, DRIFT_DEFAULT_SIGMA_MPS2, DRIFT_DEFAULT_TAU_S), FIELD_VAR_WINDOW_S, span, hann=True
        )
    noise_w = windowed_variance(first_pass_noise, FIELD_VAR_WINDOW_S, span, hann=True)
    var_field = max(var_seen - FIELD_VAR_NOISE_MARGIN * noise_w - drift_w, 0.0)
    # the lowest band of 8 bins, then log-spaced bands (1 bin and up at the low end, wider
    # above): the periodogram's scatter (100 % per bin) averages down where the bands widen,
    # and each band's margin follows its own size (band_margin); bands of 8 bins at least
    # were measured and lost (docs/benchmarks.md, "The band's margin where the noise is not flat")
    edges = np.unique(np.concatenate([[0], np.geomspace(8, max(valid.sum(), 9), 24).astype(int)]))
    idx_valid = np.flatnonzero(valid)
    # the bands and their margins depend on the noise only; the field counted in them on the
    # periodogram
    bands = [ii for ii in (idx_valid[a:b] for a, b in zip(edges[:-1], edges[1:])) if ii.size]
    margins = [band_margin(s_n[ii]) for ii in bands]
    band_freq = [float(np.mean(f[ii])) for ii in bands]
    # the lowest band's bins and margin: the field it cannot exclude (below)
    lowest = (bands[0], margins[0]) if bands else None

    def counted(pp):
        # the field counted per bin (with the margin) and the unbiased excess (without it, for
        # the sigma)
        sig, pt = np.zeros_like(f), np.zeros_like(f)
        if bands:
            band_excess = [float(np.mean(pp[ii] / h1[ii] ** 2) - np.mean(s_n[ii])) for ii in bands]
            sig_b, pt_b = band_field(band_excess, margins, [ii.size for ii in bands], band_freq)
            for ii, a, b in zip(bands, sig_b, pt_b):
                sig[ii], pt[ii] = a, b
        return sig, pt

    # the prior is chosen on the periodogram with the taper's leakage held down (the smaller of
    # it and the prewhitened one, per bin: each leakage only adds power); the stated sigma
    # counts the field the plain one shows as well (docs/benchmarks.md, "Leakage in the first
    # pass's periodogram")
    f_pw, p_pw = prewhitened_periodogram(g, wt, dt_s)
    s_sig, _ = counted(np.minimum(p, np.interp(f, f_pw, p_pw)))
    s_sig_c, s_pt = counted(p)
    # candidates
    tau_fixed = 1.0 / (params.anomaly_lambda_per_m * v) if "anomaly_lambda_per_m" in given else None
    sig_fixed = params.anomaly_sigma_mps2 if "anomaly_sigma_mps2" in given else None
    taus = [tau_fixed] if tau_fixed else np.geomspace(*BOUNDS["anomaly_tau_s"], 29)
    sigmas = [sig_fixed] if sig_fixed else np.geomspace(*BOUNDS["anomaly_sigma_mps2"], 61)
    # wavelengths longer than the periodogram shows (the flight's length) are not known to be
    # weak: the prior must pass them (H >= PASS_BELOW_GAIN at half the lowest frequency)
    # instead of flattening the estimate to its mean where the data cannot tell
    # (against the height noise alone: the white level is the least certain estimate, inflated
    # by turbulence, and would make this constraint pass noise it need not)
    f_lo = 0.5 * float(f[0])
    # (the white height noise alone: the wander's random walk over-states the noise at the longest
    # wavelengths, where a real one's correlation time ends it)
    s_n_lo = float(
        _noise_psd_g(np.array([f_lo]), dataclasses.replace(noise, white_mps2=0.0, height_walk_m=0.0), dt_h)[0]
    )
    # a prior that cannot hold the field's long-wavelength variance (a strong smooth field under
    # a weak or short-correlated Markov prior: the periodogram band starts at a third of the
    # flight's length and misses it) makes the filter explain the field by other states - the
    # attitude in turns, where tilt couples the horizontal specific force into the vertical -
    # with errors far above the field itself (measured: 94 mGal on a 4.8 mGal field): its
    # variance through the same window must reach the variance seen
    best = None
    fallback = None
    sig_v = np.asarray(sigmas, float)
    # the Markov PSD scales with sigma^2: one integral per correlation time, all of them at once
    unit_vars = _windowed_variances(lambda x: markov_psd(x[None, :], 1.0, np.asarray(taus, float)[:, None]), span)
    for tau, unit_var in zip(taus, unit_vars):
        # every sigma of this correlation time at once; the same arithmetic, element by element,
        # as one candidate at a time (so the same choice, ties included: first of the least)
        s_lo = markov_psd(f_lo, sig_v, tau)
        score = s_lo / (s_lo + s_n_lo) / PASS_BELOW_GAIN
        if var_field > 0.0:
            score = np.minimum(score, sig_v * sig_v * unit_var / var_field / FIELD_VAR_HELD)
        i = int(np.argmax(score))
        if fallback is None or score[i] > fallback[0]:
            fallback = (float(score[i]), float(sig_v[i]), float(tau))
        ok = np.flatnonzero(score >= 1.0)
        if ok.size == 0:
            continue
        s_g = markov_psd(f[None, :], sig_v[ok, None], tau)
        h = s_g / (s_g + s_n)
        risk = np.sum((1.0 - h) ** 2 * s_sig + h**2 * s_n, axis=1)
        i = int(np.argmin(risk))
        if best is None or risk[i] < best[0]:
            best = (float(risk[i]), float(sig_v[ok[i]]), float(tau))
    _, sg, tau = best if best is not None else fallback
    model = dataclasses.replace(noise, anomaly_sigma_mps2=sg, anomaly_tau_s=tau)
    if params.target_resolution_m is not None:
        model = prior_for_resolution(model, v, params.target_resolution_m, dt_h)
    new = dataclasses.replace(
        params, anomaly_sigma_mps2=model.anomaly_sigma_mps2, anomaly_lambda_per_m=1.0 / (model.anomaly_tau_s * v)
    )
    # expected error variance of the chosen smoother: the risk as a variance (two-sided
    # periodogram bins of width 1/(n dt), both signs of frequency)
    expected = prior_risk(f, s_sig_c, s_n, model.anomaly_sigma_mps2, model.anomaly_tau_s) * 2.0 / (n * dt_s)
    # the field the margin did not count (bands within two standard errors of the noise), as
    # the chosen smoother removes it: not in the filter's model, so not in its sigma either
    s_g = markov_psd(f, model.anomaly_sigma_mps2, model.anomaly_tau_s)
    h = s_g / (s_g + s_n)
    missed = float(np.sum((1.0 - h) ** 2 * np.maximum(s_pt - s_sig_c, 0.0))) * 2.0 / (n * dt_s)
    # where no band stands out, the prior flattens the estimate and the unbiased excess can be
    # nil while a field up to the margin still fits the data: the field at the longest
    # wavelengths shown (the lowest band, where a field seen from the air is strongest) that the
    # data cannot exclude, as the chosen smoother flattens it, is then a floor on that part
    # (where a band is counted, the prior holds the field's level and this is not needed)
    unexcluded = 0.0
    if lowest is not None and not np.any(s_sig_c > 0):
        ii, margin = lowest
        unexcluded = float(np.sum((1.0 - h[ii]) ** 2 * margin)) * 2.0 / (n * dt_s)
    report["field_sigma_unexcluded_mps2"] = math.sqrt(unexcluded)
    report["field_sigma_missed_mps2"] = math.sqrt(max(missed, unexcluded, 0.0))
    how_sigma = (
        "target_resolution_m"
        if params.target_resolution_m is not None
        else ("config" if "anomaly_sigma_mps2" in given else "least expected error (first-pass spectrum)")
    )
    report["anomaly_sigma_mps2"] = {"value": new.anomaly_sigma_mps2, "sigma_factor": None, "how": how_sigma}
    report["anomaly_lambda_per_m"] = {
        "value": new.anomaly_lambda_per_m,
        "sigma_factor": None,
        "how": "config" if "anomaly_lambda_per_m" in given else "least expected error (first-pass spectrum)",
    }
    report["spectral_model"] = dataclasses.asdict(model)
    report["resolution_m"] = wiener_resolution_m(model, v, dt_h)
    report["expected_error_mgal"] = math.sqrt(max(expected, 0.0)) / 1e-5
    report["smoother_sigma_scale"] = smoother_sigma_scale(
        f, s_sig_c, s_n, model.anomaly_sigma_mps2, model.anomaly_tau_s
    )
    report["field_std_seen_mgal"] = math.sqrt(var_field) / 1e-5
    report["signal_seen_to_m"] = (v / (2.0 * float(f[s_sig > 0].max()))) if np.any(s_sig > 0) else None
    return new, report


def horizontal_prior(
    anomaly_sigma_mps2: float, anomaly_lambda_per_m: float, g_vertical=None, spacing_m: float | None = None
) -> tuple[float, float]:
    """Gauss-Markov prior of each horizontal disturbance component, from the vertical one.

    A field that is harmonic above its sources (point masses, dipoles, prisms, real terrain
    seen from the air) has, per plane wave of horizontal wavenumber ``k = (k_e, k_n)``,
    disturbance components ``(i k_e, i k_n, |k|) T_k`` (east, north, up) of the disturbing
    potential's amplitude ``T_k``.  Along a track (wavenumber ``k_a`` along, ``k_c`` across)
    the 1-D spectra are integrals over ``k_c``, and since ``k_a^2 + k_c^2 = |k|^2``::

        S_along(k_a) + S_across(k_a) = S_up(k_a)          (exact, every along-track frequency)

    The two horizontal components together carry exactly the vertical's power at every
    along-track frequency (seed 003 reads the horizontal spectrum off the along-track FFT of a
    point-mass "dipole" field; this is that spectrum, from the vertical one).  With an
    isotropic field, or headings that change, north and east take half each:
    ``S_N = S_E = S_up / 2``: the vertical Markov prior with ``sigma / sqrt(2)`` and the same
    correlation.

    Which vertical spectrum: the prior chosen for least expected error
    (:func:`refine_prior`) is right where the data speak, but its stationary sigma and
    correlation can be far from the field's (a long correlation with a large sigma is how a
    Markov process puts a given level into the band).  The vertical channel does not care
    (the altimeter fixes the level); the horizontal one does, because a constant horizontal
    disturbance cannot be told from a constant tilt and only the prior decides it
    (docs/method.md, "Vector gravimetry").  So given the smoothed vertical estimate along the
    flight, the Markov process matched to it is used instead: its variance (the field's
    variance along the flight) and its integral correlation length ``L = int rho(s) ds``
    (autocorrelation up to its first zero), then ``sigma_h = sigma_g / sqrt(2)``,
    ``lambda_h = 1 / L``; never above the vertical prior's sigma / sqrt(2), never below the
    identification's lower bound (0.02 mGal).

    Parameters
    ----------
    anomaly_sigma_mps2 : float
        Sigma of the vertical disturbance prior, m/s^2.
    anomaly_lambda_per_m : float
        Its spatial correlation rate, 1/m.
    g_vertical : ndarray (N,), optional
        Smoothed vertical disturbance along the flight, m/s^2, at spacing ``spacing_m``.
    spacing_m : float, optional
        Along-track distance between its samples, m.

    Returns
    -------
    sigma_mps2 : float
        Stationary sigma of each horizontal component (north, east), m/s^2.
    lambda_per_m : float
        Spatial correlation rate of each, 1/m.
    """
    sig_v, lam_v = float(anomaly_sigma_mps2), float(anomaly_lambda_per_m)
    sig_h = sig_v / math.sqrt(2.0)
    g = None if g_vertical is None else np.asarray(g_vertical, float)
    if g is None or spacing_m is None or not spacing_m > 0:
        return sig_h, lam_v
    g = g[np.isfinite(g)]
    if g.size < 16:
        return sig_h, lam_v
    g = g - g.mean()
    var = float(np.mean(g * g))
    if not var > 0:
        return BOUNDS["anomaly_sigma_mps2"][0], lam_v
    n = g.size
    spec = np.fft.rfft(g, 2 * n)
    acf = np.fft.irfft(np.abs(spec) ** 2)[:n] / (var * np.arange(n, 0, -1))
    zero = np.flatnonzero(acf <= 0.0)
    k = int(zero[0]) if zero.size else n
    length = max(float(np.sum(acf[:k])) * spacing_m, spacing_m)
    sig_g = min(max(math.sqrt(var / 2.0), BOUNDS["anomaly_sigma_mps2"][0]), sig_h)
    return sig_g, 1.0 / length


def field_attitude_noise_degph(anomaly_sigma_mps2: float, anomaly_tau_s: float) -> float | None:
    """The white gyro drift with which a scalar filter's attitude follows the field's horizontal
    components, deg/h (one-second sigma, as ``model.gyro_drift_degph``).

    The scalar model has no states for the horizontal disturbance ``dg_h``; in the velocity
    error it enters as a tilt ``phi`` does (``g x phi``), so the filter can follow it only as a
    tilt ``dg_h / g``, driven by the gyros' white drift.  Each horizontal component is the
    vertical prior with ``sigma / sqrt(2)`` and the same correlation (:func:`horizontal_prior`:
    a harmonic field's two horizontal components carry the vertical's power at every
    along-track frequency).  The rate of a Gauss-Markov process of sigma ``s`` and correlation
    time ``tau`` is, above ``1 / tau``, white of two-sided density ``2 s^2 / tau``; with ``s =
    sigma / (sqrt(2) g)`` that is a gyro white drift of one-second sigma::

        q = sigma / (g sqrt(tau / 1 s))

    On strong fields the filter's likelihood takes a gyro noise of 0.1-10 deg/h where the gyros
    draw 0.003-0.03 (14 of 23 simulated flights over 60 mGal, 2 of 157 under), 14 of the 16
    within ten times this figure; with the simulated field's horizontal components set to zero
    the default is kept (docs/benchmarks.md, "The field's horizontal components pose as gyro
    noise").

    Parameters
    ----------
    anomaly_sigma_mps2 : float
        Sigma of the vertical disturbance prior, m/s^2.
    anomaly_tau_s : float
        Its correlation time along the flight, s.

    Returns
    -------
    float or None
        None where either figure is missing or not positive.
    """
    try:
        sigma, tau = float(anomaly_sigma_mps2), float(anomaly_tau_s)
    except (TypeError, ValueError):
        return None
    if not (sigma > 0 and tau > 0 and math.isfinite(sigma) and math.isfinite(tau)):
        return None
    return sigma / (STANDARD_GRAVITY_MPS2 * math.sqrt(tau)) / RADPS_PER_DEGPH


# --- the gravimeter's slow error (issue 12 item 2) ------------------------------------------
#
# On a straight line at constant speed the gravimeter's slow error and the field enter the one
# vertical channel the same way; the Whittle fit above takes both for "anomaly", and the
# filter's gravimeter state, at the seed's 0.1 mGal / 40 s, holds almost none of it: the
# smoother puts the error into the field and its sigma leaves it out (docs/method.md, "Honest
# sigma").  The stated sigma adds a datasheet drift passed through the smoother.

#: Level of an airborne gravimeter's slow error, m/s^2: 1 mGal (~1 ug), the accuracy class that
#: airborne gravimeter datasheets state (0.5-1 mGal "dynamic accuracy") and the in-run bias
#: stability of a navigation-grade accelerometer.  A flight cannot show it (see above); with the
#: keys ``gravimeter_sigma_mps2`` / ``gravimeter_lambda_per_s`` in the config the filter models
#: the drift itself and this figure is not used.
DRIFT_DEFAULT_SIGMA_MPS2 = 1.0e-5
#: Its correlation time, s: bias-stability figures are stated at averaging times of minutes
#: (the Allan-deviation floor); 10 min.
DRIFT_DEFAULT_TAU_S = 600.0


#: The ``model:`` keys with which the config models the gravimeter's slow error: given, the
#: filter's gravimeter state holds it and the datasheet drift is not assumed besides.
DRIFT_MODEL_KEYS = ("gravimeter_sigma_mps2", "gravimeter_lambda_per_s")


def config_models_drift(given) -> bool:
    """Whether the config models the gravimeter drift itself (any of :data:`DRIFT_MODEL_KEYS`
    among the ``given`` keys); where it does not, the datasheet drift
    (:data:`DRIFT_DEFAULT_SIGMA_MPS2`) is held off the field seen (:func:`refine_prior`) and
    passed into the stated sigma (:func:`drift_sigma_passed`)."""
    return bool(set(DRIFT_MODEL_KEYS) & set(given))


def drift_sigma_passed(
    report, span_s: float, sigma_d: float = DRIFT_DEFAULT_SIGMA_MPS2, tau_d: float = DRIFT_DEFAULT_TAU_S
):
    """1-sigma of a gravimeter drift that the smoother passes into the field estimate, m/s^2.

    A drift the filter does not model is, to it, field: it reaches the estimate through the
    smoother's steady-state transfer ``H = S_g / (S_g + S_n)`` (the identified prior and noise,
    :func:`refine_prior`'s model, with its noise calibration).  Its variance, less the part
    constant over the record (indistinguishable from the gravimeter's bias, which the smoother's
    own sigma leaves out as well), is ``int H^2 S_d (1 - sinc^2(f span)) df``.

    Parameters
    ----------
    report : dict
        The identification report (``spectral_model``, ``height_dt_s``, optional ``noise_scale``).
    span_s : float
        The record's length, s.
    sigma_d, tau_d : float
        The drift's Gauss-Markov sigma (m/s^2) and correlation time (s); default the datasheet
        figure :data:`DRIFT_DEFAULT_SIGMA_MPS2`, :data:`DRIFT_DEFAULT_TAU_S`.

    Returns
    -------
    float
        m/s^2; 0 when the report has no spectral model.
    """
    if "spectral_model" not in report or "height_dt_s" not in report:
        return 0.0
    m = _model_of(report)
    dt_h = float(report["height_dt_s"])
    k_n = float(report.get("noise_scale", 1.0))

    def passed(f):
        s_g = markov_psd(f, m.anomaly_sigma_mps2, m.anomaly_tau_s)
        h = s_g / (s_g + k_n * _noise_psd_g(f, m, dt_h))
        return markov_psd(f, sigma_d, tau_d) * h * h

    # window 1 s: the product's epoch (no further averaging)
    return math.sqrt(max(windowed_variance(passed, 1.0, float(span_s)), 0.0))
