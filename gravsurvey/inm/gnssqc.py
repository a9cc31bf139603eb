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
noise and the altimeter's own share of the vertical channel make it the weakest.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .heightqc import estimate_latency

__all__ = ["estimate_gnss_latency", "latency_is_clear", "shift_gnss"]

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


def shift_gnss(gnss, latency_s: float):
    """The GNSS channel with its stamps moved ``latency_s`` earlier (a copy; the stamps only)."""
    return dataclasses.replace(gnss, time=np.asarray(gnss.time, float) - float(latency_s))
