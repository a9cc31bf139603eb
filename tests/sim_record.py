"""A simulated flight (gravsurvey.simulate) as the estimator's inputs: record and true initial state."""

import numpy as np

from gravsurvey.inm.params import InitialState
from gravsurvey.io.record import AltimeterChannel, FlightRecord, GnssChannel, ImuChannel


def record_and_initial(s, gnss: bool = True):
    """``(FlightRecord, InitialState)`` of a ``SimulatedFlight`` ``s``: IMU, altimeter and (with
    ``gnss``) GNSS channels as simulated; the initial state is the truth at the first sample."""
    gn = GnssChannel(s.gnss_time, np.radians(s.gnss_lat_deg), np.radians(s.gnss_lon_deg), s.gnss_height)
    rec = FlightRecord(
        s.start_unix_ns,
        ImuChannel(s.imu_time, s.specific_force_t, s.angular_rate_t),
        AltimeterChannel(s.alt_time, s.alt_height),
        gn if gnss else None,
        source="sim",
    )
    tr = s.truth
    init = InitialState(tr["lat"][0], tr["lon"][0], tr["height"][0], tr["vel_n"][0].copy(), tr["mat_nt"][0].copy())
    return rec, init
