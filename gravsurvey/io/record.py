"""The FlightRecord: what ingestion hands to the rest of the pipeline.

Times are float64 seconds relative to ``t0_unix_ns`` (an integer number of
nanoseconds since the Unix epoch, UTC).  ``t0_unix_ns`` is the earliest sample
over all channels, so every channel's time starts at >= 0.  Nanosecond stamps
stay exact in float64 seconds for ~100 days of flight.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class ImuChannel:
    """IMU samples on the instrument triad.

    Attributes
    ----------
    time : ndarray, shape (n,)
        s after ``FlightRecord.t0_unix_ns``, strictly increasing.
    specific_force_t : ndarray, shape (n, 3)
        Specific force resolved on the triad, m/s^2.
    angular_rate_t : ndarray, shape (n, 3)
        Absolute angular rate of the triad resolved on the triad, rad/s.
    saturated : ndarray of bool, shape (n,), or None
        Samples where an accelerometer axis sat at its range (the specific force there is only a
        bound: :func:`gravsurvey.io.checks.saturated_samples`); None: none did.
    """

    time: np.ndarray
    specific_force_t: np.ndarray
    angular_rate_t: np.ndarray
    saturated: np.ndarray | None = None


@dataclass
class AltimeterChannel:
    """Radial information: ellipsoidal height, m, at ``time`` (s).

    ``height_sigma_m`` (shape of ``height``, or None): a sample's own 1-sigma, m, where its
    stretch is noisier than the rest (NaN elsewhere), from the estimator's height check.
    """

    time: np.ndarray
    height: np.ndarray
    height_sigma_m: np.ndarray | None = None


@dataclass
class GnssChannel:
    """GNSS positions: geodetic latitude, longitude (rad), ellipsoidal height (m).

    ``height_sigma_m`` (shape of ``height``, or None): a fix's own height 1-sigma, m, where its
    stretch is noisier than the rest (a float solution; NaN elsewhere), from the estimator's
    height check (:func:`gravsurvey.inm.solve.estimate_anomaly`).
    """

    time: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    height: np.ndarray
    height_sigma_m: np.ndarray | None = None


@dataclass
class GradientChannel:
    """Gravity-gradiometer samples: the gravitation gradient tensor on the instrument triad.

    Attributes
    ----------
    time : ndarray, shape (n,)
        s after ``FlightRecord.t0_unix_ns``, strictly increasing.
    gamma_t : ndarray, shape (n, 3, 3)
        ``d g_i / d x_j`` on the triad's axes, 1/s^2 (SI; files carry Eotvos), symmetric.
    """

    time: np.ndarray
    gamma_t: np.ndarray


@dataclass
class FlightRecord:
    """One flight's sensor data, checked and on strictly increasing time bases.

    ``notes`` lists what ingestion found and repaired (one line each), e.g.
    dropped duplicates, gaps, salvaged messages. ``data_loss`` repeats the notes that mean
    recorded data were lost (a damaged file salvaged up to the damage): the survey job still
    processes what was recovered but reports the flight as a data problem (exit code 1).
    """

    t0_unix_ns: int
    imu: ImuChannel
    altimeter: AltimeterChannel
    gnss: GnssChannel | None = None
    source: str = ""
    notes: list[str] = field(default_factory=list)
    data_loss: list[str] = field(default_factory=list)
    gradient: GradientChannel | None = None  # optional gravity-gradiometer channel
    #: role -> the file (or file and topic) it came from, for messages about one channel
    sources: dict = field(default_factory=dict)

    def source_of(self, role: str) -> str:
        """The file a channel came from (``source``, all of the flight's files, when unknown)."""
        return str(self.sources.get(role) or self.source or "record")

    def epochs(self, rate_hz):
        """Filter epochs (s) at ``rate_hz`` from the first IMU sample through the last one.

        Returns
        -------
        ndarray, shape (m,)
            ``t_imu[0] + k / rate_hz`` for every k with the epoch <= ``t_imu[-1]``.
        """
        t = self.imu.time
        if len(t) == 0:
            return np.zeros(0)
        n = int(np.floor((t[-1] - t[0]) * rate_hz + 1e-9)) + 1
        return t[0] + np.arange(n) / rate_hz

    def altimeter_on(self, epochs, max_gap_s=None):
        """Altimeter height (m) linearly interpolated at ``epochs`` (s); NaN where unavailable.

        See :func:`interp_on_epochs`.
        """
        return interp_on_epochs(self.altimeter.time, self.altimeter.height, epochs, max_gap_s)

    def gnss_on(self, epochs, max_gap_s=None):
        """GNSS latitude, longitude (rad) and height (m) at ``epochs`` (s), NaN where unavailable.

        Longitude is unwrapped before interpolation and wrapped back to (-pi, pi].

        Returns
        -------
        lat, lon, height : ndarray, shape (m,)
        """
        g = self.gnss
        if g is None:
            nan = np.full(len(np.atleast_1d(epochs)), np.nan)
            return nan, nan.copy(), nan.copy()
        vals = np.stack([g.lat, np.unwrap(g.lon), g.height], axis=1)
        out = interp_on_epochs(g.time, vals, epochs, max_gap_s)
        lon = np.angle(np.exp(1j * out[:, 1]))
        lon = np.where(np.isnan(out[:, 1]), np.nan, lon)
        return out[:, 0], lon, out[:, 2]


def interp_on_epochs(time, values, epochs, max_gap_s=None):
    """Linear interpolation of a channel onto other epochs, NaN where it has no data.

    Parameters
    ----------
    time : ndarray, shape (n,)
        Channel times, s, strictly increasing.
    values : ndarray, shape (n,) or (n, k)
        Channel values.
    epochs : ndarray, shape (m,)
        Target times, s (same origin as ``time``).
    max_gap_s : float, optional
        Epochs that fall inside a step of the channel longer than this get NaN (a gap is not
        bridged).  None: bridge every step.

    Returns
    -------
    ndarray, shape (m,) or (m, k)
        NaN before the first and after the last sample (no extrapolation).
    """
    time = np.asarray(time, dtype=np.float64)
    epochs = np.asarray(epochs, dtype=np.float64)
    values = np.asarray(values, dtype=np.float64)
    flat = values.reshape(len(time), int(np.prod(values.shape[1:])))
    out = np.full((len(epochs), flat.shape[1]), np.nan)
    if len(time) == 0:
        return out.reshape((len(epochs),) + values.shape[1:])
    inside = (epochs >= time[0]) & (epochs <= time[-1])
    if max_gap_s is not None and len(time) > 1:
        j = np.clip(np.searchsorted(time, epochs, side="right"), 1, len(time) - 1)
        exact = np.isin(epochs, time)
        inside &= exact | (time[j] - time[j - 1] <= max_gap_s)
    for c in range(flat.shape[1]):
        out[inside, c] = np.interp(epochs[inside], time, flat[:, c])
    return out.reshape((len(epochs),) + values.shape[1:])


def slice_record(record: FlightRecord, t0: float, t1: float, margin_s: float = 0.0) -> FlightRecord:
    """The part of a flight between ``t0`` and ``t1`` (s after ``record.t0_unix_ns``, inclusive).

    The IMU is cut to ``[t0, t1]``; the altimeter and GNSS to ``[t0 - margin_s, t1 + margin_s]``
    (a margin lets interpolation reach the first and last IMU sample). The time base (``t0_unix_ns``)
    is kept, so times of the slice and of the flight are directly comparable. Notes and data-loss
    lines are not copied (they describe the whole flight).

    Parameters
    ----------
    record : FlightRecord
    t0, t1 : float
        s, ``t0 <= t1``.
    margin_s : float
        Extra time of the aiding channels on both sides, s.

    Returns
    -------
    FlightRecord
        Arrays are copies.
    """

    def cut(time, lo, hi):
        t = np.asarray(time, dtype=np.float64)
        return (t >= lo) & (t <= hi)

    m = cut(record.imu.time, t0, t1)
    sat = record.imu.saturated
    imu = ImuChannel(
        record.imu.time[m].copy(),
        record.imu.specific_force_t[m].copy(),
        record.imu.angular_rate_t[m].copy(),
        None if sat is None else sat[m].copy(),
    )
    a = cut(record.altimeter.time, t0 - margin_s, t1 + margin_s)
    own = record.altimeter.height_sigma_m
    alt = AltimeterChannel(
        record.altimeter.time[a].copy(), record.altimeter.height[a].copy(), None if own is None else own[a].copy()
    )
    gnss = None
    if record.gnss is not None:
        g = cut(record.gnss.time, t0 - margin_s, t1 + margin_s)
        gnss = GnssChannel(
            record.gnss.time[g].copy(),
            record.gnss.lat[g].copy(),
            record.gnss.lon[g].copy(),
            record.gnss.height[g].copy(),
            None if record.gnss.height_sigma_m is None else record.gnss.height_sigma_m[g].copy(),
        )
    return FlightRecord(
        t0_unix_ns=record.t0_unix_ns, imu=imu, altimeter=alt, gnss=gnss, source=record.source, sources=record.sources
    )
