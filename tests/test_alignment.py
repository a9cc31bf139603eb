"""Coarse alignment and attitude estimation (gravsurvey.inm.alignment, issue 13) against known truth.

Truth: the simulator (gravsurvey/simulate) and a real static VectorNav VN-310E recording
(tests/data/real-imu, MPL-2.0) with the device's own attitude solution.
"""

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from gravsurvey.errors import ConfigError, DataError
from gravsurvey.geodesy import MGAL, WGS84
from gravsurvey.inm.alignment import (
    hemisphere_check,
    ACCEL_BIAS_SIGMA_MPS2,
    align,
    attitude_from_mat_nb,
    gyrocompass,
    level,
    static_span,
    wahba,
)
from gravsurvey.inm.params import (
    InitialState,
    InmParams,
    mat_nb_from_attitude,
    resolve_initial_state,
)
from gravsurvey.inm.solve import estimate_anomaly
from gravsurvey.io.record import AltimeterChannel, FlightRecord, GnssChannel, ImuChannel
from gravsurvey.simulate.run import quick_sim, simulate_flight
from gravsurvey.settings import ingest_options, initial_overrides

DATA = Path(__file__).parent / "data" / "real-imu"
DEGPH = math.radians(1.0) / 3600.0

SENSORS = {
    "accelerometer": {"white_sigma_mps2": 5.0e-4},
    "gravimeter": {"markov_sigma_mps2": 1.0e-6, "markov_lambda_per_s": 0.025, "white_sigma_mps2": 1.0e-4},
    "gyro": {"bias_degph": [0.03, -0.02, 0.01], "white_drift_degph": 0.005},
    "altimeter": {"sigma_m": 0.05},
    "gnss": {"horizontal_sigma_m": 0.5, "vertical_sigma_m": 1.0},
}


def _grid(static_s):
    return {
        "kind": "grid",
        "origin_lat_deg": 47.0,
        "origin_lon_deg": 11.0,
        "altitude_m": 800.0,
        "speed_mps": 70.0,
        "lines": {"count": 3, "spacing_m": 3000.0, "length_m": 25000.0, "heading_deg": 0.0},
        "static_start_s": static_s,
    }


def _simulate(static_s, triad="strapdown"):
    """Strapdown (or ``triad``) grid, 22-25 min at 10 Hz, gyro biases <= 0.03 deg/h, 0.5 m GNSS at 5 Hz."""
    sim = quick_sim(
        plan=_grid(static_s),
        triad=triad,
        noise=SENSORS,
        field="seed_smooth",
        gnss_hz=5.0,
        altimeter_hz=5.0,
        seed=3,
        turbulence={"vertical_sigma_m": 1.0, "horizontal_sigma_m": 1.0, "attitude_sigma_deg": 0.5},
    )
    return simulate_flight(sim)


@pytest.fixture(scope="module")
def in_flight():
    """Starts at cruise speed: no static period."""
    return _simulate(0.0)


@pytest.fixture(scope="module")
def static_start():
    return _simulate(120.0)


def _params(**kw):
    # what a user knows from the datasheets of the simulated sensors (accelerometer, gyro, GNSS);
    # the rest at its default: the gravimeter/height noise and the anomaly prior are identified
    # from the flight (model.identify, on by default)
    return InmParams(
        accel_noise_mps2=5e-4, gyro_drift_degph=0.005, gnss_horizontal_sigma_m=0.5, gnss_vertical_sigma_m=1.0, **kw
    )


def _record(s, mount=None, gnss=True):
    """The flight as logged by a triad turned by ``mount`` (triad -> body, default identity) against the body."""
    mount = np.eye(3) if mount is None else mount
    f = s.specific_force_t @ mount  # rows: (mount^T f_b)^T
    w = s.angular_rate_t @ mount
    g = (
        GnssChannel(s.gnss_time, np.radians(s.gnss_lat_deg), np.radians(s.gnss_lon_deg), s.gnss_height)
        if gnss
        else None
    )
    return FlightRecord(
        s.start_unix_ns, ImuChannel(s.imu_time, f, w), AltimeterChannel(s.alt_time, s.alt_height), g, source="sim"
    )


def _exact_initial(s, mount=None):
    tr = s.truth
    mount = np.eye(3) if mount is None else mount
    return InitialState(tr["lat"][0], tr["lon"][0], tr["height"][0], tr["vel_n"][0].copy(), tr["mat_nt"][0] @ mount)


def _rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


def _rms_after_bias(x):
    return _rms(np.asarray(x) - np.mean(x))


def _theta_n(mat_est, mat_true):
    """Attitude error on ENU axes, rad: mat_true = (I + [theta x]) mat_est."""
    e = mat_true @ mat_est.T
    return np.array([e[2, 1] - e[1, 2], e[0, 2] - e[2, 0], e[1, 0] - e[0, 1]]) * 0.5


# --------------------------------------------------------------------------
# building blocks
# --------------------------------------------------------------------------


def test_wahba_recovers_any_rotation():
    rng = np.random.default_rng(1)
    for _ in range(5):
        rot = mat_nb_from_attitude(*rng.uniform(-math.pi, math.pi, 3))
        b = rng.normal(size=(20, 3))
        r = wahba(b @ rot.T, b)
        np.testing.assert_allclose(r, rot, atol=1e-12)
        assert np.linalg.det(r) == pytest.approx(1.0)


def test_levelling_and_gyrocompassing_synthetic():
    """Exact static data: levelling and north to round-off; a gyro bias b turns north by b / (W cos lat)."""
    lat = math.radians(47.0)
    g = 9.81
    for roll, pitch, heading in [(2.0, -3.0, 0.0), (-5.0, 4.0, 135.0), (1.0, 1.0, 290.0)]:
        m_nb = mat_nb_from_attitude(*np.radians([roll, pitch, heading]))
        f_b = m_nb.T @ [0.0, 0.0, g]
        w_b = m_nb.T @ (WGS84.omega * np.array([0.0, math.cos(lat), math.sin(lat)]))
        _, r, p = level(f_b)
        assert math.degrees(r) == pytest.approx(roll, abs=1e-10)
        assert math.degrees(p) == pytest.approx(pitch, abs=1e-10)
        mat, cov, warn = gyrocompass(f_b, w_b, lat, 600.0, 0.01 * DEGPH, 0.005 * DEGPH)
        assert not warn
        np.testing.assert_allclose(mat, m_nb, atol=1e-9)
        # the stated heading sigma: 0.01 deg/h against 15.04 cos(47 deg) = 10.26 deg/h -> 0.056 deg
        assert math.degrees(math.sqrt(cov[2, 2])) == pytest.approx(0.01 / 10.26 * 57.2958, rel=0.01)
        # a 0.01 deg/h bias across north turns the heading by ~0.056 deg: inside 1 sigma
        east_b = m_nb.T @ [1.0, 0.0, 0.0]
        mat2, cov2, _ = gyrocompass(f_b, w_b + 0.01 * DEGPH * east_b, lat, 600.0, 0.01 * DEGPH, 0.005 * DEGPH)
        err = abs(_theta_n(mat2, m_nb)[2])
        assert 0.5 * math.sqrt(cov2[2, 2]) < err < 1.5 * math.sqrt(cov2[2, 2])
    # a tactical gyro (1 deg/h bias sigma): heading sigma 5.6 deg -> refused, says why
    _, cov, warn = gyrocompass(f_b, w_b, lat, 600.0, 1.0 * DEGPH, 0.1 * DEGPH)
    assert warn and "gyro too noisy for gyrocompassing" in warn[0] and cov[2, 2] >= math.pi**2


def test_the_gyros_at_rest_refuse_a_latitude_of_the_wrong_sign():
    """The vertical Earth rate Omega sin(lat) changes sign at the equator: a southern survey's
    latitudes written without the sign are refused naming the GNSS file (fuzzing, 2026-12-04:
    "the navigation did not settle ... set model.gyro_bias_sigma_degph")."""
    lat = math.radians(-33.9)
    up = np.array([0.0, 0.0, 1.0])
    w = WGS84.omega * np.array([0.0, math.cos(lat), math.sin(lat)])
    args = (600.0, 0.05 * DEGPH, 0.01 * DEGPH, "gnss.csv")
    hemisphere_check(up, w, lat, *args)  # as written: passes
    with pytest.raises(DataError) as exc:
        hemisphere_check(up, w, -lat, *args)
    msg = str(exc.value)
    assert msg.startswith(
        "gnss.csv: at rest the gyros read a vertical Earth rate of -8.39 deg/h, the one at latitude 33.90 S"
    )
    assert "the latitudes' sign is wrong" in msg and "\n" not in msg
    # no verdict where the two hemispheres look alike: near the equator, or with a poor gyro
    near = math.radians(0.5)
    hemisphere_check(up, WGS84.omega * np.array([0.0, math.cos(near), -math.sin(near)]), near, *args)
    hemisphere_check(up, w, -lat, 600.0, 10.0 * DEGPH, 0.01 * DEGPH, "gnss.csv")


def test_a_southern_flight_and_its_mirror_image_align(static_start):
    """The simulated flight at 47 N passes; with its latitudes negated align() refuses it."""
    rec = _record(static_start)
    align(rec, _params())
    g = rec.gnss
    rec.gnss = GnssChannel(g.time, -np.asarray(g.lat), g.lon, g.height)
    with pytest.raises(DataError, match="the latitudes' sign is wrong"):
        align(rec, _params())


def test_static_span_detects_the_static_start(static_start, in_flight):
    s = static_start
    span = static_span(s.imu_time, s.specific_force_t, s.angular_rate_t)
    assert 100.0 <= span <= 125.0  # 120 s at rest, then the speed ramp
    assert static_span(in_flight.imu_time, in_flight.specific_force_t, in_flight.angular_rate_t) == 0.0


# --------------------------------------------------------------------------
# alignment accuracy against the simulator's truth
# --------------------------------------------------------------------------


@pytest.mark.parametrize("which", ["in_flight", "static_start"])
def test_alignment_error_inside_three_sigma(which, request):
    s = request.getfixturevalue(which)
    al = align(_record(s), _params())
    th = _theta_n(al.mat_nt, s.truth["mat_nt"][0])
    sig = np.sqrt(np.diag(al.cov_n))
    assert al.method == {"in_flight": "velocity-matching", "static_start": "static-levelling+velocity-matching"}[which]
    assert np.all(np.abs(th) < 3.0 * sig), (np.degrees(th), np.degrees(sig))
    # measured: heading error 0.0044 / 0.0090 deg, sigma 0.050 / 0.037 deg (in flight / static start)
    assert math.degrees(al.sigma_heading_rad) < 0.1
    assert ("no static period" in " ".join(al.warnings)) == (which == "in_flight")


def test_gyrocompassing_without_gnss(static_start):
    """No GNSS: static levelling + gyrocompassing (0.03 deg/h gyros: heading sigma ~0.3 deg)."""
    s = static_start
    al = align(_record(s, gnss=False), _params(), lat=math.radians(47.0))
    assert al.method == "static-gyrocompass"
    th = _theta_n(al.mat_nt, s.truth["mat_nt"][0])
    sig = np.sqrt(np.diag(al.cov_n))
    assert np.all(np.abs(th) < 3.0 * sig), (np.degrees(th), np.degrees(sig))
    assert math.degrees(al.sigma_heading_rad) < 0.5


def test_no_static_and_no_gnss_is_a_data_error(in_flight):
    with pytest.raises(DataError, match="no static period at the start and no GNSS"):
        align(_record(in_flight, gnss=False), _params(), lat=math.radians(47.0))


# mounts: the triad turned against the body by (roll, pitch, heading) deg: the initial attitude
# the estimator must find spans 0-360 deg of heading and up to 5 deg of roll and pitch
MOUNTS = [
    (0.0, 0.0, 0.0),
    (5.0, -3.0, 90.0),
    (-4.0, 5.0, 180.0),
    (3.0, 4.0, 270.0),
    (-5.0, -5.0, 45.0),
    (2.0, -2.0, 330.0),
]


@pytest.mark.parametrize("mount_deg", MOUNTS)
def test_no_initial_block_matches_exact_attitude(in_flight, mount_deg):
    """No initial state given: after the stated convergence time the RMS is within 10 % of the run
    started from the exact attitude, and the attitude error is inside 3 sigma."""
    s = in_flight
    # turned by (roll, pitch, heading) from the body axes (mat_nb_from_attitude(0, 0, 0) is the
    # body's own orientation: nose north)
    mount = mat_nb_from_attitude(*np.radians(mount_deg)) @ mat_nb_from_attitude(0.0, 0.0, 0.0).T
    rec = _record(s, mount)
    p = _params()
    exact = estimate_anomaly(rec, _params(attitude_passes=1), _exact_initial(s, mount), "strapdown")
    init = resolve_initial_state(rec, "strapdown", p)
    sol = estimate_anomaly(rec, p, init, "strapdown")
    assert sol.alignment is not None and sol.passes >= 2
    conv = sol.attitude_converge_s
    assert 0.0 <= conv < 900.0
    keep = sol.time - sol.time[0] >= conv
    g_true = np.interp(sol.time, s.truth["time"], s.truth["disturbance"])
    # RMS after removing the mean error (issue 13's measure: the mean is the gravimeter's bias,
    # which no flight can tell from the field's mean)
    rms = _rms_after_bias((sol.g_smooth - g_true)[keep]) / MGAL
    rms_exact = _rms_after_bias((exact.g_smooth - g_true)[keep]) / MGAL
    # measured: 1.05-1.22 mGal, 1.01-1.05 x the exact-attitude run (1.01-1.19 mGal)
    assert rms <= 1.10 * rms_exact, (rms, rms_exact)
    # attitude against the truth of the turned triad, every epoch after convergence
    k = np.clip(np.searchsorted(s.truth["time"], sol.time), 0, s.truth["time"].size - 1)
    assert np.allclose(s.truth["time"][k], sol.time, atol=1e-6)
    true_att = np.array([attitude_from_mat_nb(m @ mount) for m in s.truth["mat_nt"][k]])
    err = sol.attitude - true_att
    err[:, 2] = (err[:, 2] + math.pi) % (2 * math.pi) - math.pi
    inside = np.abs(err[keep]) < 3.0 * sol.attitude_sigma[keep]
    # measured: every epoch inside on every mount (roll, pitch, heading)
    assert inside.mean(axis=0).min() >= 0.99, inside.mean(axis=0)


def test_given_attitude_disagreeing_with_the_data_is_a_config_error(in_flight):
    s = in_flight
    rec = _record(s)
    r, p, h = np.degrees(attitude_from_mat_nb(s.truth["mat_nt"][0]))
    good = initial_overrides({"attitude_deg": [r, p, h]})
    # consistent, and its stated sigma beats the alignment's (0.038 deg): used, with that sigma
    st = resolve_initial_state(rec, "strapdown", _params(initial_attitude_sigma_deg=0.01), given=good)
    np.testing.assert_allclose(st.mat_nt, s.truth["mat_nt"][0], atol=1e-9)
    assert st.attitude_cov_t is None
    # with the default 0.05 deg the alignment's own attitude is kept
    st = resolve_initial_state(rec, "strapdown", _params(), given=good)
    assert st.attitude_cov_t is not None
    bad = initial_overrides({"attitude_deg": [r, p, h + 2.0]})
    with pytest.raises(ConfigError, match=r"^flights\[0\]\.initial\.attitude_deg: .* disagrees with the alignment"):
        resolve_initial_state(rec, "strapdown", _params(), given=bad, key_path="flights[0].initial")
    far = initial_overrides({"lat_deg": float(s.gnss_lat_deg[0]) + 0.01})
    with pytest.raises(ConfigError, match=r"^initial\.lat_deg: .* m from the GNSS position"):
        resolve_initial_state(rec, "strapdown", _params(), given=far)


def test_mirrored_axes_leave_the_gnss_track(in_flight):
    """A left-handed triad (one axis flipped, e.g. FRD declared as FLU with y only) cannot be aligned:
    the navigation leaves the GNSS track and the flight is a DataError, not a result."""
    rec = _record(in_flight, np.diag([1.0, -1.0, 1.0]))
    with pytest.raises(DataError, match="leaves the GNSS track|made the mechanization run away"):
        estimate_anomaly(rec, _params(), None, "strapdown")


# --------------------------------------------------------------------------
# real data: static VN-310E
# --------------------------------------------------------------------------


def _read(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    head = rows[0]
    arr = np.array(rows[1:], dtype=float)
    return {h: arr[:, i] for i, h in enumerate(head)}


def test_static_levelling_on_real_vn310():
    """Roll and pitch from levelling agree with the VN-310E's own within what its accelerometer biases allow.

    Bound: a horizontal accelerometer bias b tilts the levelled vertical by b / g; with the
    bias sigma ACCEL_BIAS_SIGMA_MPS2 = 5e-4 m/s^2 (the VN-310's datasheet bias stability is
    well below 1e-3 m/s^2, the NOTES' order of magnitude) 3 sigma is 0.0088 deg; the noise of
    the 32 s mean (2.5e-3 m/s^2 per sample / sqrt(1612) -> 6e-5 m/s^2, 0.0004 deg) and the
    device's own attitude scatter (std 0.0015 deg) are added.  Measured: roll differs by
    0.0002 deg, pitch by 0.0028 deg.
    """
    imu = _read(DATA / "vn310-imu-part.csv")
    gn = _read(DATA / "vn310-gnss-part.csv")
    f_frd = np.stack([imu[f"IMU::UncompAccel::{a} [m/s^2]"] for a in "XYZ"], axis=1)
    w_frd = np.stack([imu[f"IMU::UncompGyro::{a} [rad/s]"] for a in "XYZ"], axis=1)
    to_flu = np.diag([1.0, -1.0, -1.0])  # FRD -> FLU (imu_axes: FRD)
    f_t, w_t = f_frd @ to_flu, w_frd @ to_flu
    t = imu["Time [s]"]
    span = static_span(t, f_t, w_t)
    assert span >= 30.0
    _, roll, pitch = level(f_t.mean(axis=0))
    dev_roll = np.mean(gn["Att::YawPitchRoll::R [deg]"])
    dev_pitch = np.mean(gn["Att::YawPitchRoll::P [deg]"])
    g = np.linalg.norm(f_t.mean(axis=0))
    noise = np.std(f_t[:, :2], axis=0).max() / math.sqrt(t.size)
    bound = 3.0 * math.degrees(math.hypot(ACCEL_BIAS_SIGMA_MPS2, noise) / g) + 3.0 * max(
        np.std(gn["Att::YawPitchRoll::R [deg]"]), np.std(gn["Att::YawPitchRoll::P [deg]"])
    )
    assert bound < 0.015
    assert abs(math.degrees(roll) - dev_roll) < bound, (math.degrees(roll), dev_roll, bound)
    assert abs(math.degrees(pitch) - dev_pitch) < bound, (math.degrees(pitch), dev_pitch, bound)
    # gyrocompassing must refuse this MEMS device: its gyro output at rest is bias, ~2e-3 rad/s
    lat = math.radians(float(gn["GNSS1::PosLla::latitude [deg]"][0]))
    _, cov, warn = gyrocompass(f_t.mean(axis=0), w_t.mean(axis=0), lat, span, 10.0 * DEGPH, 0.5 * DEGPH)
    assert warn and cov[2, 2] >= math.pi**2
    # even with an optimistic bias sigma the rate at rest is no Earth rate: refused as inconsistent
    _, cov, warn = gyrocompass(f_t.mean(axis=0), w_t.mean(axis=0), lat, span, 0.01 * DEGPH, 0.005 * DEGPH)
    assert warn and "refused" in warn[0]


def _vn310_options(**extra):

    t = ["GpsCycle", "GpsWeek", "GpsTow [s]"]
    cfg = {
        "inputs": {
            "csv": {"imu": "vn310-imu-part.csv", "altimeter": "vn310-gnss-part.csv", "gnss": "vn310-gnss-part.csv"}
        },
        "csv": {
            "time_format": "gps_week_sow",
            "columns": {
                "imu": {
                    "time": t,
                    **{f"f{a.lower()}": f"IMU::UncompAccel::{a} [m/s^2]" for a in "XYZ"},
                    **{f"w{a.lower()}": f"IMU::UncompGyro::{a} [rad/s]" for a in "XYZ"},
                },
                "altimeter": {"time": t, "height": "GNSS1::PosLla::altitude [m]"},
                "gnss": {
                    "time": t,
                    "lat": "GNSS1::PosLla::latitude [deg]",
                    "lon": "GNSS1::PosLla::longitude [deg]",
                    "height": "GNSS1::PosLla::altitude [m]",
                },
            },
        },
        **extra,
    }
    return ingest_options(cfg, base_dir=DATA)


def test_vn310_csv_with_frd_axes_and_gps_cycle_week_tow():
    """The vendor CSV as a new user would declare it: FRD axes, GpsCycle/GpsWeek/GpsTow time."""
    from gravsurvey.io.ingest import load_flight

    with pytest.warns(Warning):  # the ingest check notes the MEMS gyro bias at rest
        rec = load_flight(_vn310_options(imu_axes="FRD"))
    # GPS week 1024 * 2 + 255 = 2303, TOW 403575.847627 s GPS = 2024-02-29 16:06:15.847627 GPS
    # = 16:05:57.847627 UTC (18 leap seconds)
    import datetime

    t0 = datetime.datetime(2024, 2, 29, 16, 5, 57, 847627, tzinfo=datetime.timezone.utc)
    assert rec.t0_unix_ns == int(t0.timestamp()) * 10**9 + 847627000
    # FRD -> FLU: at rest the z axis now reads +g, y flips sign
    f = rec.imu.specific_force_t.mean(axis=0)
    assert f[2] == pytest.approx(9.80, abs=0.01) and f[1] == pytest.approx(-0.2987, abs=1e-3)
    al = align(rec, InmParams())
    # static and no motion: the vertical from levelling; heading unknown and said so
    assert al.method == "static-levelling+velocity-matching"
    roll, pitch, _ = al.attitude_deg()
    assert roll == pytest.approx(-1.7463, abs=0.01) and pitch == pytest.approx(0.5683, abs=0.01)
    text = " ".join(al.warnings)
    assert "gyrocompassing refused" in text and "poor alignment" in text


def test_gps_cycle_week_tow_time_columns(tmp_path):
    from gravsurvey.errors import DataError
    from gravsurvey.io.csv import read_csv_channel

    p = tmp_path / "alt.csv"
    p.write_text("cyc,wk,tow,h\n2,255,403575.5,10\n2,255,403576.0,11\n")
    t, _ = read_csv_channel(p, "altimeter", {"time": ["cyc", "wk", "tow"], "height": "h"}, "gps_week_sow")
    t2, _ = read_csv_channel(p, "altimeter", {"time": ["wk", "tow"], "height": "h"}, "gps_week_sow")
    assert t[0] - t2[0] == 2 * 1024 * 7 * 86400 * 10**9 and t[1] - t[0] == 500_000_000
    p.write_text("cyc,wk,tow,h\n2,1300,403575.5,10\n")
    with pytest.raises(DataError, match=r"line 2: columns 'cyc', 'wk': expected a roll-over count >= 0 and a 10-bit"):
        read_csv_channel(p, "altimeter", {"time": ["cyc", "wk", "tow"], "height": "h"}, "gps_week_sow")


def test_imu_axes_and_lever_arm_options():
    from gravsurvey.io.ingest import IMU_AXES, imu_axes_matrix

    for m in IMU_AXES.values():
        assert np.linalg.det(m) == pytest.approx(1.0) and np.allclose(m @ m.T, np.eye(3))
    # RFU: the right axis is -left, forward is the sensor's y
    np.testing.assert_allclose(imu_axes_matrix("RFU") @ [0.0, 1.0, 0.0], [1.0, 0.0, 0.0])
    np.testing.assert_allclose(imu_axes_matrix("RFU") @ [1.0, 0.0, 0.0], [0.0, -1.0, 0.0])
    np.testing.assert_allclose(imu_axes_matrix([[0, 1, 0], [-1, 0, 0], [0, 0, 1]]), IMU_AXES["RFU"])
    with pytest.raises(ConfigError, match=r"^flights\[0\]\.imu_axes: expected one of FLU, FRD, RFU"):
        _vn310_options(imu_axes="NED")
    with pytest.raises(ConfigError, match=r"^flights\[0\]\.imu_axes: the matrix must be a proper rotation"):
        _vn310_options(imu_axes=[[1, 0, 0], [0, -1, 0], [0, 0, 1]])
    with pytest.raises(ConfigError, match=r"^flights\[0\]\.gnss_lever_arm_m: expected \[forward, left, up\]"):
        _vn310_options(gnss_lever_arm_m=[1.0, 2.0])
    assert np.array_equal(_vn310_options(gnss_lever_arm_m=[1, 0, 2]).gnss_lever_arm_m, [1.0, 0.0, 2.0])


def test_gnss_lever_arm_is_applied(in_flight):
    """An antenna 6 m ahead of and 2 m above the IMU: with the lever arm declared the track is as
    good as without any arm; declared zero, the navigation is off by metres; not declared, the
    arm is found from the track (said in a warning) and the track is as good."""
    from gravsurvey.geodesy import ecef_to_geodetic, geodetic_to_ecef, mat_en

    s = in_flight
    arm = np.array([6.0, 0.0, 2.0])
    tr = s.truth
    k = np.clip(np.searchsorted(tr["time"], s.gnss_time), 1, tr["time"].size - 1)
    # truth attitude at the GNSS times (nearest truth sample: 5 Hz, same grid as the GNSS)
    m_nt = tr["mat_nt"][k]
    lat, lon = np.radians(s.gnss_lat_deg), np.radians(s.gnss_lon_deg)
    off_e = np.einsum("nij,nj->ni", mat_en(lat, lon), np.einsum("nij,j->ni", m_nt, arm))
    lat2, lon2, h2 = ecef_to_geodetic(geodetic_to_ecef(lat, lon, s.gnss_height) + off_e)
    rec = _record(s)
    rec.gnss = GnssChannel(s.gnss_time, lat2, lon2, h2)

    def track_error(sol):
        la = np.interp(sol.time, tr["time"], tr["lat"])
        lo = np.interp(sol.time, tr["time"], tr["lon"])
        return _rms(np.hypot((sol.lat - la) * 6.37e6, (sol.lon - lo) * 6.37e6 * np.cos(la)))

    with_arm = estimate_anomaly(rec, _params(), None, "strapdown", gnss_lever_arm_t=arm)
    zero = estimate_anomaly(rec, _params(), None, "strapdown", gnss_lever_arm_t=np.zeros(3))
    found = estimate_anomaly(rec, _params(), None, "strapdown")
    base = estimate_anomaly(_record(s), _params(), None, "strapdown")
    assert track_error(with_arm) < 1.5 * track_error(base) + 0.05
    assert track_error(zero) > 3.0
    rep = found.identification["gnss_lever_arm"]
    assert rep["applied"] and "gnss_lever_arm" not in zero.identification
    # the forward offset is the slowest found (at constant speed it is a GNSS latency, and the
    # smoothed track takes up part of it): 5.87 of 6 m, the up 1.89 of 2 m, nothing sideways;
    # the track 0.13 m off (5.9 m declared zero)
    np.testing.assert_allclose(rep["lever_arm_flu_m"], arm, atol=0.8)
    assert track_error(found) < 0.25 * track_error(zero)
    assert any("the antenna is [" in w and "found from the aided track" in w for w in found.warnings)
    # the base flight (no offset) finds none
    assert not base.identification["gnss_lever_arm"]["applied"]


# --------------------------------------------------------------------------
# end to end: the init template and a strapdown sample without an initial block
# --------------------------------------------------------------------------

SAMPLES = Path(__file__).resolve().parents[1] / "sample_data"


def _run_cli(cfg, tmp_path):
    import json
    import os
    import subprocess
    import sys

    r = subprocess.run(
        [sys.executable, "-m", "gravsurvey", "run", str(cfg)],
        capture_output=True,
        text=True,
        timeout=600,
        env=dict(os.environ),
        stdin=subprocess.DEVNULL,
        cwd=tmp_path,
        check=False,
    )
    assert r.returncode == 0, r.stderr
    out = cfg.parent / "out"
    with open(out / "profiles.csv", newline="") as fh:
        rows = list(csv.DictReader(line for line in fh if not line.startswith("#")))  # metadata lines
    return json.loads((out / "summary.json").read_text()), rows


def test_strapdown_sample_without_initial_block(tmp_path):
    """sample_data/grid_ros2 (strapdown) with its initial block deleted: measured 1.706 mGal RMS against
    truth (1.709 with the block; docs/samples.md bound 2.2)."""
    import re
    import shutil

    shutil.copytree(SAMPLES / "grid_ros2", tmp_path / "s")
    cfg = tmp_path / "s" / "survey.yaml"
    text = re.sub(r"  initial:\n(    .*\n)+", "", cfg.read_text())
    assert "initial" not in text
    cfg.write_text(text)
    summary, rows = _run_cli(cfg, tmp_path)
    est = summary["flights"]["F01"]["estimator"]
    assert est["alignment_method"].endswith("velocity-matching") and est["attitude_passes"] >= 2
    assert est["alignment_sigma_heading_deg"] < 0.1 and est["gnss_residual_rms_m"] < 2.0
    # the attitude and its sigma per epoch in the deliverable (issue 13 item 5)
    heading = np.array([float(r["heading_deg"]) for r in rows])
    h_sig = np.array([float(r["heading_sigma_deg"]) for r in rows])
    assert np.isfinite(heading).all() and (0 <= heading).all() and (heading < 360).all()
    assert np.isfinite(h_sig).all() and np.median(h_sig) < 0.1
    err = np.array(
        [float(r["error_mgal"]) for r in rows if r["error_mgal"] not in ("", "nan") and r["flight"] == "F01"]
    )
    err = err[np.isfinite(err)]
    assert err.size > 100 and _rms(err) < 2.2


def test_given_attitude_is_used_when_the_data_cannot_align(in_flight):
    """GNSS only for the first 30 s of a flight that starts in motion: no alignment possible, but a
    given attitude is accepted (unchecked) instead of failing."""
    s = in_flight
    rec = _record(s)
    keep = s.gnss_time <= 3.0
    rec.gnss = GnssChannel(
        s.gnss_time[keep], np.radians(s.gnss_lat_deg[keep]), np.radians(s.gnss_lon_deg[keep]), s.gnss_height[keep]
    )
    with pytest.raises(DataError, match="alignment"):
        resolve_initial_state(rec, "strapdown", _params())
    r, p, h = np.degrees(attitude_from_mat_nb(s.truth["mat_nt"][0]))
    given = initial_overrides({"attitude_deg": [r, p, h]})
    st = resolve_initial_state(rec, "strapdown", _params(), given=given)
    np.testing.assert_allclose(st.mat_nt, s.truth["mat_nt"][0], atol=1e-9)
    assert st.alignment is None and st.attitude_cov_t is None


def test_gnss_outliers_do_not_fail_a_good_flight(in_flight):
    """5 % of the GNSS samples 200 m off (multipath, a bad fix): the track check keeps the flight."""
    s = in_flight
    rec = _record(s)
    lat = np.radians(s.gnss_lat_deg).copy()
    lat[::20] += 200.0 / 6.37e6
    rec.gnss = GnssChannel(s.gnss_time, lat, np.radians(s.gnss_lon_deg), s.gnss_height)
    sol = estimate_anomaly(rec, _params(), None, "strapdown")
    assert sol.gnss_residual_rms_m > 20.0  # the outliers show in the RMS ...
    assert np.isfinite(sol.g_smooth).all()  # ... but the flight is processed


# --------------------------------------------------------------------------
# strapdown columns judged against the GNSS track (consistency.check_strapdown_axes)
# --------------------------------------------------------------------------


def _with_columns(rec, fn):
    f, w = fn(np.array(rec.imu.specific_force_t, float), np.array(rec.imu.angular_rate_t, float))
    return FlightRecord(rec.t0_unix_ns, ImuChannel(rec.imu.time, f, w), rec.altimeter, rec.gnss, source="sim")


def _neg(arr, k):
    arr[:, k] = -arr[:, k]
    return arr


@pytest.mark.parametrize(
    "fault, named",
    [
        (lambda f, w: (_neg(f, 1), w), "column fy: the strapdown IMU's motion fits the GNSS track"),
        (lambda f, w: (f, _neg(w, 2)), "column wz: the strapdown IMU's motion fits the GNSS track"),
        (lambda f, w: (f, w[:, [1, 0, 2]]), "columns wx, wy: "),
        (lambda f, w: (_neg(f, 0), _neg(w, 0)), "columns fx, wx: "),
    ],
)
def test_strapdown_column_faults_are_named(in_flight, fault, named):
    """An accelerometer axis negated (fuzzing, 2026-12-04: exit 0 at 2.4x the error, or
    "|disturbance| reaches 1373 mGal"), a gyro axis negated (a mechanization run-away), two gyro
    axes swapped, one axis of both sensors negated: the fault's hypothesis fits the GNSS velocity
    changes through the turns several times better than the columns as written."""
    from gravsurvey.consistency import ChannelNames, check_strapdown_axes

    names = ChannelNames({"imu": "imu.csv"}, {})
    intact = _record(in_flight)
    (note,) = check_strapdown_axes(intact, "strapdown", names)
    assert note.startswith("passed: strapdown axes: the columns as written fit the GNSS track best")
    with pytest.raises(DataError) as exc:
        check_strapdown_axes(_with_columns(intact, fault), "strapdown", names, "flights[0]")
    msg = str(exc.value)
    assert msg.startswith("imu.csv " + named) and "flights[0].imu_axes" in msg and "\n" not in msg
    assert check_strapdown_axes(intact, "platform", names) == []


def test_strapdown_axes_check_passes_a_mems_gyro_and_a_noisy_gnss():
    """Noise pushes every hypothesis's fit towards the as-written one: with a 10 deg/h gyro bias
    (the triad tilts by 0.3 deg over a window) and 2-m GNSS noise no fault fits better by the
    factor that names one (consistency.STRAPDOWN_AXES_RATIO)."""
    from gravsurvey.consistency import STRAPDOWN_AXES_RATIO, check_strapdown_axes, strapdown_axis_fit

    sensors = {**SENSORS, "gyro": {"bias_degph": [10.0, -8.0, 6.0], "white_drift_degph": 0.5}}
    sensors["gnss"] = {"horizontal_sigma_m": 2.0, "vertical_sigma_m": 3.0}
    sim = quick_sim(
        plan=_grid(0.0), triad="strapdown", noise=sensors, field="seed_smooth", gnss_hz=5.0, altimeter_hz=5.0, seed=4
    )
    rec = _record(simulate_flight(sim))
    base, faults = strapdown_axis_fit(rec)
    assert base.size >= 2
    best = max(float(np.median(base / r)) for _, _, r in faults)
    assert best < 0.5 * STRAPDOWN_AXES_RATIO  # measured 0.99: no verdict either way
    assert check_strapdown_axes(rec, "strapdown")[0].startswith("passed: strapdown axes")


def test_the_axis_hypotheses_share_the_gnss_side_of_the_matching(in_flight, monkeypatch):
    """The GNSS side of velocity matching (the track's fits and its gravitation) depends on the
    GNSS alone: strapdown_axis_fit computes it once per window and track (as written and the
    two mirrored ones) for its 17 hypotheses, and every residual is, to the bit, the one computed
    afresh per hypothesis."""
    import gravsurvey.inm.alignment as alignment
    from gravsurvey.consistency import strapdown_axis_fit

    rec = _record(in_flight)
    calls = []
    fits_of = alignment.gnss_inertial_velocity

    def counted(*args, **kwargs):
        calls.append(1)
        return fits_of(*args, **kwargs)

    monkeypatch.setattr(alignment, "gnss_inertial_velocity", counted)
    base, faults = strapdown_axis_fit(rec)
    shared = len(calls)
    assert base.size >= 2 and len(faults) == 17

    match = alignment.match_vectors

    def afresh(*args, **kwargs):
        return match(*args, **{**kwargs, "gnss_fits": None})

    monkeypatch.setattr(alignment, "match_vectors", afresh)
    calls.clear()
    base_0, faults_0 = strapdown_axis_fit(rec)
    # per window: the track as written for the columns and the 15 column faults, once instead
    # of 16 times; each mirrored track once either way
    assert shared == len(calls) - 15 * base.size
    assert np.array_equal(base, base_0)
    for (d, q, r), (d_0, q_0, r_0) in zip(faults, faults_0):
        assert (d, q) == (d_0, q_0) and np.array_equal(r, r_0)


@pytest.mark.parametrize(
    "q, col, side",
    [
        ("lat", "lat_deg", "north of the equator written negative"),
        ("lon", "lon_deg", "east of Greenwich written negative"),
    ],
)
def test_strapdown_coordinates_of_the_wrong_sign_name_their_column(in_flight, q, col, side):
    """The GNSS track mirrored about the equator (or the Greenwich meridian) is mirrored against the
    IMU as well: named as the coordinate's sign (fuzzing, 2026-12-04: the negated latitudes read as
    the accelerometer's z axis negated, the negated longitudes as the latitudes' sign), with no
    static start to gyrocompass on."""
    from gravsurvey.consistency import ChannelNames, check_strapdown_axes

    rec = _record(in_flight)
    g = rec.gnss
    rec.gnss = GnssChannel(
        g.time, -np.asarray(g.lat) if q == "lat" else g.lat, -np.asarray(g.lon) if q == "lon" else g.lon, g.height
    )
    names = ChannelNames({"gnss": "gnss.csv"}, {"gnss": {"lat": "lat_deg", "lon": "lon_deg"}})
    with pytest.raises(DataError) as exc:
        check_strapdown_axes(rec, "strapdown", names)
    msg = str(exc.value)
    assert msg.startswith(f"gnss.csv column {col}: the strapdown IMU's motion fits the GNSS track")
    word = "latitudes" if q == "lat" else "longitudes"
    assert f"better with the GNSS {word}' sign flipped" in msg and side in msg and "\n" not in msg


def test_near_the_pole_the_motion_aligns_without_a_gyrocompassing_warning():
    """At 86 N the Earth rate's horizontal part is 1.05 deg/h: a 0.05 deg/h gyro cannot
    gyrocompass (2.7 deg), the motion gives the heading, and that is no warning (fuzzing,
    2026-12-04: every high-latitude flight warned 'gyro too noisy for gyrocompassing')."""
    plan = {**_grid(120.0), "origin_lat_deg": 86.0}
    sim = quick_sim(
        plan=plan, triad="strapdown", noise=SENSORS, field="seed_smooth", gnss_hz=5.0, altimeter_hz=5.0, seed=5
    )
    s = simulate_flight(sim)
    al = align(_record(s), _params(gyro_bias_sigma_degph=0.05))
    assert al.method == "static-levelling+velocity-matching" and al.warnings == []
    th = _theta_n(al.mat_nt, s.truth["mat_nt"][0])
    assert np.all(np.abs(th) < 3.0 * np.sqrt(np.diag(al.cov_n)))


def test_an_imu_scale_fault_shows_as_a_systematic_departure_from_the_gnss_track(in_flight):
    """A gyro whose z scale is 1 % off (a turn of 180 deg reads 181.8) ran with exit 0 at 56 mGal
    against 2.2 intact (fuzzing, 2026-12-04): the corrected track then departs from the GNSS
    positions systematically (20-s means) by metres, where GNSS noise leaves a decimetre; that is
    a warning naming the GNSS file and model.gnss_horizontal_sigma_m."""
    intact = estimate_anomaly(_record(in_flight), _params(), None, "strapdown")
    assert intact.gnss_residual_systematic_m < 0.5  # measured 0.06-0.25 m on 36 unseen-suite and issue flights
    assert not any("departs from the GNSS positions" in w for w in intact.identification.get("warnings", []))
    scaled = _with_columns(_record(in_flight), lambda f, w: (f, w * np.array([1.0, 1.0, 1.01])))
    sol = estimate_anomaly(scaled, _params(), None, "strapdown")
    assert sol.gnss_residual_systematic_m > 2.0 * _params().gnss_horizontal_sigma_m
    (msg,) = [w for w in sol.identification["warnings"] if "departs from the GNSS positions" in w]
    assert msg.startswith("sim: the corrected track departs from the GNSS positions systematically by")
    assert "model.gnss_horizontal_sigma_m" in msg and "\n" not in msg


@pytest.mark.parametrize("which, q, k, scale", [("in_flight", "wz", 2, 1.01), ("static_start", "fx", 0, 1.05)])
def test_an_imu_axis_scale_fault_is_found_named_and_divided_out(request, which, q, k, scale):
    """A gyro's z scale 1 % off (56 mGal with exit 0 on a fuzzing flight, 2.23 corrected) or an
    accelerometer's x scale 5 % off (13.5 mGal, 2.24 corrected; seen where the speed changes:
    the take-off run of the flight with a static start): the factor that, dividing the axis,
    best fits the GNSS velocity changes through the manoeuvres is found to 0.2 %, divided out
    and named in a warning with the column; an intact flight is left as it is."""
    from gravsurvey.consistency import ChannelNames, correct_imu_scale

    flight = request.getfixturevalue(which)
    names = ChannelNames({"imu": "imu.csv"}, {})
    rec = _record(flight)
    same, notes = correct_imu_scale(rec, "strapdown", names)
    assert same is rec and notes == []

    def scaled(f, w):
        (f if q[0] == "f" else w)[:, k] *= scale
        return f, w

    fixed, notes = correct_imu_scale(_with_columns(rec, scaled), "strapdown", names)
    (msg,) = notes
    assert msg.startswith(f"imu.csv column {q}: the ") and "divided out before the estimate" in msg and "\n" not in msg
    found = float(msg.split(" reads ")[1].split("x ")[0])
    assert abs(found - scale) < 0.002
    arr = "specific_force_t" if q[0] == "f" else "angular_rate_t"
    np.testing.assert_allclose(getattr(fixed.imu, arr)[:, k], getattr(rec.imu, arr)[:, k] * scale / found, rtol=1e-4)


@pytest.fixture(scope="module")
def platform_flight():
    """The in-flight grid flown on an ENU-stabilised platform."""
    return _simulate(0.0, "platform")


@pytest.mark.parametrize("q, k, scale", [("fy", 1, 1.01), ("fx", 0, 0.99), ("fy", 1, 1.05)])
def test_a_platform_accelerometer_scale_fault_is_found_named_and_divided_out(platform_flight, q, k, scale):
    """A platform's north accelerometer 1 % off put 4.3-5.1 mGal into the CSV sample (3.45 intact)
    and 5 % off 16.6, with exit 0 (fuzzing, 2026-12-05): the platform's attitude is the level
    frame the GNSS track gives, so the factor that best fits the GNSS velocity changes through the
    turns is found (to 0.2 %), divided out and named; an intact flight is left as it is, and a
    fault on the vertical axis is not searched (the GNSS checks refuse its gravity offset). (On
    the CSV sample, 1-Hz GNSS, a 1 % fault stays below the search's gate; here, 5-Hz, it does
    not.)"""
    from gravsurvey.consistency import ChannelNames, correct_imu_scale, imu_scale_fit

    names = ChannelNames({"imu": "imu.csv"}, {})
    rec = _record(platform_flight)
    same, notes = correct_imu_scale(rec, "platform", names)
    assert same is rec and notes == []

    def scaled(f, w):
        f[:, k] *= scale
        return f, w

    fixed, notes = correct_imu_scale(_with_columns(rec, scaled), "platform", names)
    (msg,) = notes
    axis = {"fx": "x (east)", "fy": "y (north)"}[q]
    assert msg.startswith(f"imu.csv column {q}: the platform accelerometer's {axis} axis reads ")
    assert "divided out before the estimate" in msg and "\n" not in msg
    found = float(msg.split(" reads ")[1].split("x ")[0])
    assert abs(found - scale) < 0.002
    np.testing.assert_allclose(
        fixed.imu.specific_force_t[:, k], rec.imu.specific_force_t[:, k] * scale / found, rtol=1e-4
    )
    # only the horizontal accelerometers are searched on a platform
    assert {x[0] for x in imu_scale_fit(_with_columns(rec, scaled), triad="platform")} <= {"fx", "fy"}


def test_a_late_first_fix_confirms_the_rest_only_when_the_fixes_stay_put():
    """The GNSS's part of the static test: a receiver that got its fix 60 s after power-on,
    parked until 120 s, confirms the rest up to the IMU's own static span (before: no static
    alignment at all, the first fix being after the first IMU sample); a late fix already
    moving confirms nothing."""
    from gravsurvey.inm.alignment import STATIC_BLOCK_S, STATIC_MARGIN_BLOCKS, gnss_static_span

    t = np.arange(60.0, 300.0, 1.0)
    lat0, lon0 = math.radians(47.0), math.radians(11.0)
    north = np.where(t < 120.0, 0.0, 50.0 * (t - 120.0))  # parked, then rolling at 50 m/s
    gn = GnssChannel(t, lat0 + north / 6.37e6, np.full(t.size, lon0), np.full(t.size, 800.0))
    span = gnss_static_span(gn, 0.0, 1.0)
    assert span == pytest.approx(120.0 + 1.0 - STATIC_MARGIN_BLOCKS * STATIC_BLOCK_S, abs=1.01)
    moving = GnssChannel(t[70:], gn.lat[70:], gn.lon[70:], gn.height[70:])  # first fix at 130 s
    assert gnss_static_span(moving, 0.0, 1.0) == 0.0
