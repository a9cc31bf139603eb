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
    """

    time: np.ndarray
    specific_force_t: np.ndarray
    angular_rate_t: np.ndarray


@dataclass
class AltimeterChannel:
    """Radial information: ellipsoidal height, m, at ``time`` (s)."""

    time: np.ndarray
    height: np.ndarray


@dataclass
class GnssChannel:
    """GNSS positions: geodetic latitude, longitude (rad), ellipsoidal height (m)."""

    time: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    height: np.ndarray


@dataclass
class FlightRecord:
    """One flight's sensor data, checked and on strictly increasing time bases.

    ``notes`` lists what ingestion found and repaired (one line each), e.g.
    dropped duplicates, gaps, salvaged messages.
    """

    t0_unix_ns: int
    imu: ImuChannel
    altimeter: AltimeterChannel
    gnss: GnssChannel | None = None
    source: str = ""
    notes: list[str] = field(default_factory=list)
