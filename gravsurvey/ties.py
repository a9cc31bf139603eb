"""Base ties: put a flight on an absolute gravity level and remove the gravimeter's linear drift.

Before take-off and after landing the aircraft stands still at a base station whose absolute
gravity ``g_base`` is known (a gravity network station, mGal). The processed gravimeter data at
the base then read ``g_read`` instead; the tie offset is ``o = g_read - g_base``. With a reading
before (``o_0`` at ``t_0``) and after (``o_1`` at ``t_1``) the flight, the offset is taken to
change linearly (the conventional drift model):

    o(t) = o_0 + (o_1 - o_0) * (t - t_0) / (t_1 - t_0)

and ``o(t)`` is subtracted from the flight's values; with one reading only the offset is a
constant and the drift is not known (the summary says so). gravsurvey's values are gravity
disturbances ``delta g = g - gamma(lat, h)`` (``gamma``: normal gravity of the configured
ellipsoid), so the tie works on disturbances: ``o = (g_read - gamma) - (g_base - gamma)`` at the
base's position.

A reading is given either as a value (``reading_mgal``: the absolute gravity the processed data
give at the base, at ``time_s``) or as a time window of the flight log (``start_s``, ``stop_s``:
s after the flight's first sample) in which the aircraft stands at the base: the reading is then
the median of the smoothed (Kalman/RTS) disturbance estimate over the window, and the base
position the median position over the window unless ``base_lat_deg``/``base_height_m`` are given.

Configuration (per flight, docs/config.md)::

    tie:
      base_gravity_mgal: 980862.31      # absolute gravity at the base, mGal
      before: {start_s: 10, stop_s: 250}  # or {reading_mgal: 980864.40, time_s: 0}
      after:  {start_s: 9100, stop_s: 9350}

Units: mGal at the edges (named so), s, rad and m inside.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gravsurvey.errors import DataError
from gravsurvey.geodesy import MGAL, WGS84, normal_gravity

__all__ = ["TieReading", "TieConfig", "FlightTie", "drift_offset", "tie_flight"]

#: plausible absolute gravity on or near the Earth's surface, mGal (catches values given in m/s^2
#: or as anomalies)
G_ABS_RANGE_MGAL = (970_000.0, 990_000.0)
S_PER_H = 3600.0


@dataclass(frozen=True)
class TieReading:
    """One still reading at the base: a value at a time, or a window of the log.

    Attributes
    ----------
    reading_mgal : float or None
        Absolute gravity the processed data read at the base, mGal (value form).
    time_s : float or None
        When (value form), s after the flight's first sample; None: the flight's start (before)
        or end (after).
    start_s, stop_s : float or None
        The still window (window form), s after the flight's first sample.
    """

    reading_mgal: float | None = None
    time_s: float | None = None
    start_s: float | None = None
    stop_s: float | None = None


@dataclass(frozen=True)
class TieConfig:
    """A flight's ``tie:`` section (module docstring)."""

    base_gravity_mgal: float
    before: TieReading | None = None
    after: TieReading | None = None
    base_lat_deg: float | None = None
    base_height_m: float | None = None


def drift_offset(
    time_s, t0_s: float, offset0_mgal: float, t1_s: float | None = None, offset1_mgal: float | None = None
) -> np.ndarray:
    """The tie offset at the given times: linear between two readings, constant with one.

    Parameters
    ----------
    time_s : array_like, shape (n,)
    t0_s, offset0_mgal : float
        First reading's time (s) and offset (mGal).
    t1_s, offset1_mgal : float, optional
        Second reading; None: constant offset.

    Returns
    -------
    ndarray, shape (n,)
        mGal (extrapolated linearly outside [t0, t1]).
    """
    t = np.asarray(time_s, float)
    if t1_s is None or offset1_mgal is None:
        return np.full_like(t, offset0_mgal)
    if t1_s == t0_s:
        raise DataError("tie: the readings before and after are at the same time")
    return offset0_mgal + (offset1_mgal - offset0_mgal) * (t - t0_s) / (t1_s - t0_s)


@dataclass
class FlightTie:
    """A flight's tie result.

    Attributes
    ----------
    offset_before_mgal, offset_after_mgal : float or None
        ``g_read - g_base`` at each reading, mGal.
    time_before_s, time_after_s : float or None
        s after the flight's first sample.
    drift_mgal_per_h : float or None
        ``(o_1 - o_0) / (t_1 - t_0)``; None with one reading.
    reading_sigma_mgal : dict
        For window readings, the robust spread (1.4826 MAD) of the estimate in the window, mGal.
    """

    offset_before_mgal: float | None
    offset_after_mgal: float | None
    time_before_s: float | None
    time_after_s: float | None
    drift_mgal_per_h: float | None
    reading_sigma_mgal: dict

    def correction(self, time_s) -> np.ndarray:
        """Offset to subtract at the given times (s after the flight's first sample), mGal."""
        if self.offset_before_mgal is not None and self.offset_after_mgal is not None:
            return drift_offset(
                time_s, self.time_before_s, self.offset_before_mgal, self.time_after_s, self.offset_after_mgal
            )
        o = self.offset_before_mgal if self.offset_before_mgal is not None else self.offset_after_mgal
        return drift_offset(time_s, 0.0, o)

    def summary(self) -> dict:
        return {
            "offset_before_mgal": self.offset_before_mgal,
            "offset_after_mgal": self.offset_after_mgal,
            "time_before_s": self.time_before_s,
            "time_after_s": self.time_after_s,
            "drift_mgal_per_h": self.drift_mgal_per_h,
            "reading_sigma_mgal": self.reading_sigma_mgal,
        }


def tie_flight(
    tie: TieConfig, time_s, lat_rad, height_m, disturbance_mgal, *, ellipsoid=WGS84, key_path: str = "tie"
) -> FlightTie:
    """Offsets and drift of one flight from its base readings.

    Parameters
    ----------
    tie : TieConfig
    time_s : array_like, shape (n,)
        s after the flight's first sample.
    lat_rad, height_m : array_like, shape (n,)
        Position of the estimate, rad and m (for the base's normal gravity in the window form).
    disturbance_mgal : array_like, shape (n,)
        The flight's smoothed disturbance estimate, mGal (the still reading in the window form).
    ellipsoid : Ellipsoid
        The one the disturbances refer to.
    key_path : str
        For messages.

    Returns
    -------
    FlightTie

    Raises
    ------
    DataError
        A window holds no finite estimate, or lies outside the flight.
    """
    t = np.asarray(time_s, float)
    lat = np.asarray(lat_rad, float)
    h = np.asarray(height_m, float)
    z = np.asarray(disturbance_mgal, float)
    sig = {}

    def one(rd: TieReading, which: str):
        kp = f"{key_path}.{which}"
        if rd.reading_mgal is not None:
            tt = rd.time_s if rd.time_s is not None else (float(t[0]) if which == "before" else float(t[-1]))
            # base disturbance and reading disturbance share gamma: the offset is the difference of absolutes
            return tt, rd.reading_mgal - tie.base_gravity_mgal
        m = (t >= rd.start_s) & (t <= rd.stop_s) & np.isfinite(z)
        if m.sum() < 1:
            raise DataError(
                f"{kp}: window {rd.start_s:g} .. {rd.stop_s:g} s holds no estimate of the flight "
                f"(flight spans {t[0]:g} .. {t[-1]:g} s)"
            )
        read = float(np.median(z[m]))
        sig[which] = float(1.4826 * np.median(np.abs(z[m] - read)))
        blat = math.radians(tie.base_lat_deg) if tie.base_lat_deg is not None else float(np.nanmedian(lat[m]))
        bh = tie.base_height_m if tie.base_height_m is not None else float(np.nanmedian(h[m]))
        gamma_mgal = float(normal_gravity(np.array([blat]), np.array([bh]), ellipsoid)[0]) / MGAL
        return float(np.median(t[m])), read - (tie.base_gravity_mgal - gamma_mgal)

    tb = ob = ta = oa = None
    if tie.before is not None:
        tb, ob = one(tie.before, "before")
    if tie.after is not None:
        ta, oa = one(tie.after, "after")
    drift = None
    if ob is not None and oa is not None:
        if ta <= tb:
            raise DataError(f"{key_path}: the 'after' reading ({ta:g} s) is not later than 'before' ({tb:g} s)")
        drift = (oa - ob) / (ta - tb) * S_PER_H
    return FlightTie(ob, oa, tb, ta, drift, sig)
