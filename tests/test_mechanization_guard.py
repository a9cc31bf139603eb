"""Issue 14: the mechanization's finite-state guard. A sample no IMU or altimeter can give, or a
navigation state no flight can have, stops with a DataError naming the channel, the sample and
its time, instead of NaN or a run-away state reaching the filter (or a ZeroDivisionError)."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from inm_truth import parallel_flight  # noqa: E402
from test_io_support import static_flight  # noqa: E402

from gravsurvey.errors import DataError  # noqa: E402
from gravsurvey.inm.mechanization import (  # noqa: E402
    MAX_SPECIFIC_FORCE_MPS2,
    check_navigation_state,
    mechanize,
)
from gravsurvey.inm.params import InitialState  # noqa: E402


def _flight(seconds=60.0):
    tr = parallel_flight(seconds, rate_hz=10.0)
    init = InitialState(tr["lat"][0], tr["lon"][0], tr["height"][0], tr["vel_n"][0].copy(), tr["mat_nt"][0].copy())
    return tr, init


@pytest.mark.parametrize("reference", [False, True])
def test_intact_flight_passes_the_guard(reference):
    tr, init = _flight(20.0)
    nav = mechanize(tr["time"], tr["f_t"], tr["w_t"], init, tr["time"], tr["height"], reference=reference)
    assert np.max(np.linalg.norm(nav.r_i - tr["r_i"], axis=1)) < 1e-3


@pytest.mark.parametrize(
    "channel, k, value",
    [
        ("f_t", 317, 2.6e8),  # a corrupted digit below the ingestion's 1e9 damage limit
        ("f_t", 5, np.nan),
        ("w_t", 400, -np.inf),
        ("w_t", 0, 150.0),
        ("f_t", 599, -1e5),
    ],
)
def test_bad_imu_sample_named_with_its_time(channel, k, value):
    """Injected straight into the mechanization (no ingestion checks in between)."""
    tr, init = _flight()
    data = {"f_t": tr["f_t"].copy(), "w_t": tr["w_t"].copy()}
    data[channel][k, 1] = value
    name = {"f_t": "specific_force", "w_t": "angular_rate"}[channel]
    with pytest.raises(
        DataError,
        match=rf"^imu {name}: sample {k} at t = {tr['time'][k]:.3f} s "
        r"is \[.*\] (m/s\^2|rad/s): expected finite values",
    ):
        mechanize(tr["time"], data["f_t"], data["w_t"], init, tr["time"], tr["height"])


def test_bad_altimeter_height_named_with_its_time():
    tr, init = _flight()
    h = tr["height"].copy()
    h[250] = np.nan
    with pytest.raises(
        DataError,
        match=r"^altimeter height: nan m at t = 25\.000 s \(interpolated "
        r"to IMU sample 250\)",
    ):
        mechanize(tr["time"], tr["f_t"], tr["w_t"], init, tr["time"], h)


@pytest.mark.parametrize("reference", [False, True])
def test_run_away_state_within_input_limits_is_stopped(reference):
    """Every sample within the input limits, but 1500 m/s^2 upward for a minute: the state
    leaves any flight and the error names the first such sample and its time."""
    tr, init = _flight()
    f = tr["f_t"].copy()
    f[:, 2] = 0.75 * MAX_SPECIFIC_FORCE_MPS2
    with pytest.raises(DataError) as exc:
        mechanize(tr["time"], f, tr["w_t"], init, tr["time"], tr["height"], use_ext=False, reference=reference)
    msg = str(exc.value)
    m = re.match(
        r"navigation velocity: inertial speed ([\d.]+) m/s at t = ([\d.]+) s \(IMU sample "
        r"(\d+)\): expected at most 12000 m/s; .*made the mechanization run away$",
        msg,
    )
    assert m, msg
    # ~1490 m/s^2 up (1500 less gravity) on top of ~380 m/s horizontal (flight + Earth rate):
    # 12 km/s after sqrt(12000^2 - 380^2) / 1490 = 8.05 s; the first 10 Hz sample beyond: 8.1 s
    assert float(m.group(2)) == pytest.approx(8.1) and int(m.group(3)) == 81, msg
    assert 12000.0 < float(m.group(1)) < 12000.0 + 1490.0 * 0.1, msg


def test_state_check_names_the_first_bad_quantity():
    n = 10
    t = np.arange(n) * 0.1
    r = np.tile([6.4e6, 0.0, 0.0], (n, 1))
    v = np.tile([0.0, 470.0, 0.0], (n, 1))
    c = np.tile(np.eye(3), (n, 1, 1))
    check_navigation_state(t, r, v, c)
    c[7, 1, 1] = np.nan
    v[8, 0] = 5e4
    with pytest.raises(
        DataError,
        match=r"^navigation attitude: triad->inertial matrix non-finite "
        r"at t = 0\.700 s \(IMU sample 7\)",
    ):
        check_navigation_state(t, r, v, c)
    r[3] = 0.0
    with pytest.raises(
        DataError,
        match=r"^navigation position: geocentric radius 0 m at t = "
        r"0\.300 s \(IMU sample 3\)",
    ):
        check_navigation_state(t, r, v, c)


def test_bad_sample_through_the_estimator(tmp_path):
    """A record that passed ingestion, then one specific force replaced by 5e4 m/s^2 (finite, so
    the estimator's own non-finite check lets it through): the estimate stops with the guard's
    error (before: the filter ran on a run-away navigation)."""
    from gravsurvey.inm.params import InmParams
    from gravsurvey.inm.solve import estimate_anomaly
    from gravsurvey.io.record import AltimeterChannel, FlightRecord, GnssChannel, ImuChannel

    d = static_flight(seconds=30.0)
    t_imu = (d["imu_t"] - d["imu_t"][0]) / 1e9
    t_alt = (d["alt_t"] - d["imu_t"][0]) / 1e9
    f = d["f"].copy()
    f[1234] = [0.0, 0.0, 5e4]
    rec = FlightRecord(
        t0_unix_ns=int(d["imu_t"][0]),
        imu=ImuChannel(t_imu, f, d["w"]),
        altimeter=AltimeterChannel(t_alt, d["h"]),
        gnss=GnssChannel(t_alt, np.radians(d["lat"]), np.radians(d["lon"]), d["gh"]),
        source="imu.csv",
    )
    with pytest.raises(
        DataError,
        match=r"imu specific_force: sample 1234 at t = 12\.340 s is "
        r"\[0, 0, 50000\] m/s\^2",
    ):
        estimate_anomaly(rec, InmParams(), None, "platform")
