"""A simulated flight (gravsurvey.simulate) as the estimator's inputs: record and true initial state."""

import numpy as np

from gravsurvey.geodesy import MGAL
from gravsurvey.inm.params import InitialState, InmParams
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


def wide_fixed_params(passes: int, **kw) -> InmParams:
    """Settings of the passes tests: the simulated sensors' figures, identification off and a
    wide fixed prior (2 mGal, 130 km), as identification picks on a weak smooth field: it passes
    slow errors, so an error the linearisation leaves shows in full."""
    return InmParams(
        identify=False,
        attitude_passes=passes,
        anomaly_sigma_mps2=2.0e-5,
        anomaly_lambda_per_m=1.0 / 130e3,
        accel_noise_mps2=2.0e-4,
        gyro_drift_degph=0.002,
        gravimeter_white_mps2=1.0e-5,
        altimeter_sigma_m=0.05,
        gnss_horizontal_sigma_m=0.2,
        gnss_vertical_sigma_m=0.5,
        **kw,
    )


def smoothed_rms_mgal(sol, edge_s: float = 300.0) -> float:
    """RMS about its mean of the smoothed disturbance more than ``edge_s`` from either end, mGal
    (over no field: the estimate's error)."""
    t = sol.time - sol.time[0]
    keep = (t > edge_s) & (t < t[-1] - edge_s)
    g = sol.g_smooth[keep]
    return float(np.sqrt(np.mean((g - g.mean()) ** 2))) / MGAL


#: A tactical-grade IMU (the benchmarks' `--gyro 0.75,6 --accel-bias 1e-2,-6e-3`): gyro biases on
#: the triad axes (deg/h), white drift (deg/h in 1 s: 0.1 deg/sqrt(h)), horizontal accelerometer
#: biases (m/s^2).
TACTICAL_IMU = {"gyro_bias_degph": [0.75, -0.525, 0.6], "gyro_white_degph": 6.0, "accel_bias_mps2": [1e-2, -6e-3]}


def with_tactical_imu(spec: dict) -> dict:
    """An unseen-flight spec (``draw_flight_spec``) with :data:`TACTICAL_IMU`'s sensors, in place."""
    sensors = spec["sim"]["flights"][0]["sensors"]
    sensors["gyro"]["bias_degph"] = list(TACTICAL_IMU["gyro_bias_degph"])
    sensors["gyro"]["white_drift_degph"] = TACTICAL_IMU["gyro_white_degph"]
    sensors["accelerometer"]["bias_mps2"] = list(TACTICAL_IMU["accel_bias_mps2"])
    return spec
