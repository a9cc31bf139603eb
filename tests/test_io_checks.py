"""Plausibility checks against physics: a simulated flight passes, unit mistakes are caught."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from test_io_csv import CSV_IN, _write_flight_csv
from test_io_support import static_flight

from gravsurvey.errors import DataError, DataWarning
from gravsurvey.filters import centred_mean
from gravsurvey.io import checks as ck
from gravsurvey.io.ingest import load_flight
from gravsurvey.io.record import AltimeterChannel, FlightRecord, GnssChannel, ImuChannel
from gravsurvey.settings import ingest_options


@functools.lru_cache(maxsize=None)
def simulated(triad):
    """A 400 s simulated flight (60 s static, then level flight with turbulence), noisy."""
    from gravsurvey.simulate.run import quick_sim, simulate_flight

    sim = quick_sim(
        duration_s=400,
        imu_hz=50,
        noise=True,
        triad=triad,
        static_start_s=60,
        turbulence={
            "vertical_sigma_m": 1.5,
            "horizontal_sigma_m": 2.0,
            "attitude_sigma_deg": 1.0,
            "corner_period_s": 20.0,
            "min_period_s": 2.0,
            "max_period_s": 600.0,
        },
    )
    return simulate_flight(sim)


def _levels(findings, check):
    return [f.level for f in findings if f.check == check]


@pytest.mark.parametrize("triad", ["platform", "strapdown"])
def test_simulated_flight_passes_and_unit_mistakes_fail(triad):
    s = simulated(triad)
    t, f, w = s.imu_time_ns, s.specific_force_t, s.angular_rate_t
    step = float(np.median(np.diff(t)))
    good = ck.check_imu(t, f, w, step)
    assert _levels(good, "accel magnitude") == ["ok"]
    assert _levels(good, "gyro at rest") == ["ok"]
    rest = next(x for x in good if x.check == "gyro at rest")
    assert 0.9 < rest.value < 1.3  # Earth rate (+ transport rate of level-flight windows)
    assert not [x for x in good if x.level in ("error", "warning")]
    bad = {
        "deg/s declared as rad/s": ck.check_imu(t, f, np.degrees(w), step),
        "rad/s declared as deg/s": ck.check_imu(t, f, np.radians(w), step),
        "deg/h declared as rad/s": ck.check_imu(t, f, np.degrees(w) * 3600, step),
        "values are in g but declared as m/s^2": ck.check_imu(t, f / 9.80665, w, step),
        "values are in mGal but declared as m/s^2": ck.check_imu(t, f * 1e5, w, step),
    }
    for name, fs in bad.items():
        errs = [x.message for x in fs if x.level == "error"]
        assert any(name in m for m in errs), (name, [x.message for x in fs])
        assert all(m.startswith("imu: ") for m in errs)
    h = ck.check_height("altimeter", s.alt_height)
    assert _levels(h, "height range") == ["ok"]
    gh = np.interp(s.alt_time_ns, s.gnss_time_ns, s.gnss_height)
    assert _levels(ck.check_height("altimeter", s.alt_height, ref=gh), "height vs GNSS") == ["ok"]
    ft = ck.check_height("altimeter", s.alt_height / 0.3048, ref=gh)
    assert any("feet declared as metres" in x.message for x in ft if x.level == "error")
    # heights above the geoid against ellipsoidal GNSS heights (a constant 30 m): a warning that
    # names the level it moves; 3 m (an antenna offset, noise) is not
    sea = ck.check_height("altimeter", s.alt_height - 30.0, ref=gh)
    assert [x.level for x in sea if x.check == "height vs GNSS"] == ["warning"]
    assert any("-30 m from the GNSS heights" in x.message and "9.3 mGal of level" in x.message for x in sea)
    assert _levels(ck.check_height("altimeter", s.alt_height + 3.0, ref=gh), "height vs GNSS") == ["ok"]


def test_unit_mistakes_stop_load_flight_with_channel_named(tmp_path):
    # a static period of 40 s: the gyro-unit verdict needs checks.REST_MIN_VERDICT_S (30 s) of rest
    d = static_flight(seconds=40.0)
    _write_flight_csv(tmp_path, d, gyro_scale=180 / np.pi)  # deg/s in a rad/s column
    opts = ingest_options({"inputs": CSV_IN}, "flights[0]")
    with pytest.raises(
        DataError,
        match=r"imu.csv: implausible data: imu: at rest .* "
        r"deg/s declared as rad/s\?",
    ):
        load_flight(opts, tmp_path)
    # declaring the unit fixes it
    ok = ingest_options({"inputs": CSV_IN, "csv": {"units": {"gyro": "deg/s"}}}, "f")
    rec = load_flight(ok, tmp_path)
    np.testing.assert_allclose(rec.imu.angular_rate_t, d["w"], rtol=1e-15)
    _write_flight_csv(tmp_path, d, acc_scale=1 / 9.80665)  # g in an m/s^2 column
    with pytest.raises(
        DataError,
        match=r"imu: median \|specific force\| is 0.99\d+ m/s\^2 after "
        r"converting from m/s\^2, expected ~9.8: values are in "
        r"g but declared as m/s\^2\?",
    ):
        load_flight(opts, tmp_path)
    # gravity taken out (an INS's linear acceleration): named as such, not a unit
    _write_flight_csv(tmp_path, dict(d, f=d["f"] - [0.0, 0.0, 9.80665]))
    with pytest.raises(DataError, match=r"a linear acceleration \(gravity taken out\) instead of the specific force"):
        load_flight(opts, tmp_path)
    _write_flight_csv(tmp_path, d, acc_scale=1 / 9.80665)
    # plausibility: warn -> processed, the finding is a warning and a note
    warn = ingest_options({"inputs": CSV_IN, "checks": {"plausibility": "warn"}}, "f")
    with pytest.warns(DataWarning, match="values are in g"):
        rec = load_flight(warn, tmp_path)
    assert any("values are in g" in n for n in rec.notes)
    # a finding about another channel names that channel's file, not the IMU's
    _write_flight_csv(tmp_path, d)
    g = (tmp_path / "gnss.csv").read_text().splitlines()
    rows = [r.split(",") for r in g[1:]]
    ddmm = [",".join([r[0], repr(float(r[1]) * 100.0), *r[2:]]) for r in rows]  # 47.5 deg as 4750
    (tmp_path / "gnss.csv").write_text("\n".join([g[0], *ddmm]) + "\n")
    with pytest.raises(DataError) as exc:
        load_flight(opts, tmp_path)
    assert "gnss.csv: implausible data: gnss: latitude" in str(exc.value) and "imu.csv" not in str(exc.value)


def test_a_short_quiet_period_gives_no_gyro_unit_verdict():
    """A few seconds of steady |F| (level flight in turbulence) are not a rest: a rate that
    would read as a unit mistake is reported, not an error (unseen flight U004: 2 s, 41.6x)."""
    d = static_flight(seconds=5.0)
    fs = ck.check_imu(d["imu_t"], d["f"], d["w"] * 180 / np.pi, 1e7)
    r = next(x for x in fs if x.check == "gyro at rest")
    assert r.level == "info" and "shorter than 30 s" in r.message


def test_a_short_quiet_period_in_flight_gives_no_gyro_warning():
    """Two seconds of steady |F| in a gentle turn (0.76 deg/s, 182 x Earth rate, no unit's
    ratio) are not a rest either: no warning (quick U1431 warned "gyro bias, low-grade gyro or
    wrong unit?"); the same rate over a minute's quiet period still warns."""
    for seconds, level in ((2.0, "info"), (60.0, "warning")):
        d = static_flight(seconds=seconds)
        w = d["w"] + np.array([0.0, 0.0, 0.01324])
        fs = ck.check_imu(d["imu_t"], d["f"], w, 1e7)
        r = next(x for x in fs if x.check == "gyro at rest")
        assert r.level == level, r.message
        assert (level == "info") == ("shorter than 30 s" in r.message)


def test_rest_rate_consistent_with_earth_rate_in_static_data():
    d = static_flight(seconds=20.0, lat_deg=60.0)
    fs = ck.check_imu(d["imu_t"], d["f"], d["w"], 1e7)
    r = next(x for x in fs if x.check == "gyro at rest")
    assert r.level == "ok" and abs(r.value - 1.0) < 1e-3


def test_height_and_latlon_ranges():
    assert _levels(ck.check_height("altimeter", np.array([100.0, 40000.0])), "height range") == ["error"]
    assert ck.check_gnss(np.array([91.0]), np.array([0.0]))[0].level == "error"
    assert ck.check_gnss(np.array([45.0]), np.array([-179.0]))[0].level == "ok"


def test_rate_stability_and_gap_threshold():
    rng = np.random.default_rng(3)
    t = np.cumsum(np.full(2000, 10_000_000)).astype(np.int64)
    jit = t + (rng.random(2000) < 0.05) * 4_000_000  # 5 % of samples 4 ms late (40 % of step)
    _, _, rep = ck.repair_time(jit, [])
    rate = next(x for x in ck.time_findings("imu", rep) if x.check == "rate")
    assert rate.level == "warning" and abs(rate.value - 100.0) < 1e-9
    _, _, rep = ck.repair_time(t, [])
    assert next(x for x in ck.time_findings("imu", rep) if x.check == "rate").level == "ok"
    gap = np.concatenate([t[:100], t[100:] + 45_000_000])  # one 55 ms step
    assert ck.repair_time(gap, [], gap_factor=5.0)[2].n_gaps == 1
    assert ck.repair_time(gap, [], gap_factor=6.0)[2].n_gaps == 0


def test_a_rate_change_within_the_record_is_named_with_its_span():
    t = np.arange(0, 200_000) * 10_000_000  # 100 Hz, 2000 s
    changed = np.concatenate([t[:100_000], t[100_000::2]])  # 50 Hz after 1000 s
    _, _, rep = ck.repair_time(changed, [])
    rate = next(x for x in ck.time_findings("imu", rep, t0_ns=0) if x.check == "rate")
    assert rate.level == "warning"
    assert "50 Hz over 1000.0-2000.0 s (the rate changed within the record)" in rate.message
    rng = np.random.default_rng(3)
    jit = t[:20_000] + (rng.random(20_000) < 0.05) * 4_000_000  # scattered late samples: no run
    _, _, rep = ck.repair_time(jit, [])
    assert (
        rep.rate_runs == []
        and "changed" not in next(x for x in ck.time_findings("imu", rep) if x.check == "rate").message
    )


def test_conflicting_duplicates_keep_first():
    t = np.array([1, 2, 2, 3], dtype=np.int64)
    v = np.array([10.0, 20.0, 21.0, 30.0])
    t2, (v2,), rep = ck.repair_time(t, [v])
    assert rep.conflicting_duplicates == 1 and rep.duplicates == 0
    np.testing.assert_array_equal(v2, [10.0, 20.0, 30.0])
    np.testing.assert_array_equal(t2, [1, 2, 3])


@pytest.mark.parametrize(
    "stray_ns, shown",
    [
        (0, "1 at 1970-01-01T00:00:00Z"),  # a stamp of 0
        (-1_741_608_050 * 10**9, "1 at 1914-10-24T11:59:10Z"),  # negative
        (7_258_118_400 * 10**9, "1 at 2200-01-01T00:00:00Z"),  # year 2200
        (1_741_608_000 * 10**9 - 1024 * 7 * 86_400 * 10**9, "1 at 2005-07-25T12:00:00Z"),  # a GPS week rollover
    ],
)
def test_a_stray_time_stamp_is_dropped_not_a_decades_long_channel(stray_ns, shown):
    """One sample stamped decades (or a GPS week rollover) away from its 1,000 neighbours: a
    logger glitch. Kept, the channel would span decades and every grid over its time would take
    tens of GB (a run was killed at 24 GB); it is dropped and said, and the steps to and from it
    are no backward steps."""
    t = 1_741_608_000 * 10**9 + np.arange(1000, dtype=np.int64) * 10**7
    t[500] = stray_ns
    v = np.arange(1000.0)
    t2, (v2,), rep = ck.repair_time(t, [v])
    assert len(t2) == 999 and 500.0 not in v2 and np.all(np.diff(t2) > 0)
    assert rep.n_stray == 1 and rep.n_backward == 0
    msgs = [f.message for f in ck.time_findings("imu", rep, int(t2[0])) if f.check == "stray"]
    assert msgs == [
        f"imu: dropped 1 sample(s) with stray time stamps, over 1 h from all the channel's other samples: {shown}"
    ]


def test_no_stray_stamps_in_two_halves_or_a_long_gap():
    """Two halves of a flight an hour and a half apart (a gap, not a glitch), and a 1-Hz channel
    whose last three fixes come after a 2-h gap, keep every sample; a 1-Hz channel's single fix
    two hours off is dropped."""
    base = 1_741_608_000 * 10**9
    halves = np.concatenate([np.arange(500), 5400 * 100 + np.arange(500)]).astype(np.int64) * 10**7 + base
    assert ck.repair_time(halves, [])[2].n_stray == 0
    fixes = np.concatenate([np.arange(960), 960 + 7200 + np.arange(3)]).astype(np.int64) * 10**9 + base
    assert ck.repair_time(fixes, [])[2].n_stray == 0
    one = np.concatenate([np.arange(960), [960 + 7200]]).astype(np.int64) * 10**9 + base
    assert ck.repair_time(one, [])[2].n_stray == 1


def test_heights_that_disagree_with_the_gnss_along_the_flight_are_not_an_offset():
    """The height channel against the GNSS heights (fuzzing, 2026-12-04: each of these ran with
    exit 0 and a warning of a constant offset, 2-20x the intact error): a drift of 50 m over the
    flight and a height above ground are errors, a pressure altitude wandering by 17 m a warning,
    a constant geoid offset the offset warning, code-grade GNSS noise (3 m) nothing; a height in
    kilometres is named as such."""
    rng = np.random.default_rng(0)
    n = 1000
    ref = 1500.0 + 20.0 * np.sin(np.linspace(0, 6, n))  # GNSS heights, m

    def verdict(h):
        (f,) = [f for f in ck.check_height("altimeter", h, "m", ref) if f.check == "height vs GNSS"]
        return f.level, f.message

    assert verdict(ref + np.linspace(0.0, 50.0, n))[0] == "error"
    level, msg = verdict(ref - 178.0 + 120.0 * np.sin(np.linspace(0, 9, n)))
    assert level == "error" and "varying over" in msg and "height above ground" in msg
    level, msg = verdict(ref - 44.0 + np.linspace(0.0, 17.0, n))
    assert level == "warning" and "varying over" in msg
    level, msg = verdict(ref - 30.0 + 0.05 * rng.standard_normal(n))
    assert level == "warning" and "heights are -30 m from the GNSS heights" in msg
    assert verdict(ref + 3.0 * rng.standard_normal(n))[0] == "ok"
    level, msg = verdict(ref / 1000.0)
    assert level == "error" and "kilometres declared as metres" in msg


def _record():
    t = np.arange(0.0, 10.0, 0.5)
    alt_t = np.array([0.0, 1.0, 2.0, 6.0, 7.0])
    return FlightRecord(
        0,
        ImuChannel(t, np.zeros((len(t), 3)), np.zeros((len(t), 3))),
        AltimeterChannel(alt_t, 100.0 + 10.0 * alt_t),
        GnssChannel(np.array([0.0, 2.0]), np.radians([10.0, 10.2]), np.radians([179.9, -179.9]), np.array([5.0, 7.0])),
    )


def test_epoch_helpers_interpolate_and_respect_gaps():
    rec = _record()
    ep = rec.epochs(1.0)
    np.testing.assert_array_equal(ep, np.arange(10.0))
    h = rec.altimeter_on(ep, max_gap_s=2.0)
    np.testing.assert_allclose(h[[0, 1, 2, 6, 7]], [100.0, 110.0, 120.0, 160.0, 170.0])
    assert np.isnan(h[[3, 4, 5, 8, 9]]).all()  # inside the 4 s gap, after the end
    assert np.isfinite(rec.altimeter_on(ep)[3])  # gap bridged when allowed
    lat, lon, hh = rec.gnss_on(np.array([1.0, 3.0]))
    # across the antimeridian: midpoint is 180 deg, not 0
    assert abs(abs(np.degrees(lon[0])) - 180.0) < 1e-9 and np.isnan(lon[1])
    np.testing.assert_allclose([np.degrees(lat[0]), hh[0]], [10.1, 6.0])


@pytest.mark.parametrize("order", ["C", "F"])
def test_fast_row_norm_and_mean_std_are_bit_identical_to_numpy(order):
    """check_imu's helpers replace np.linalg.norm and mean()/std() for speed: the findings'
    values and messages must not change by a single bit."""
    rng = np.random.default_rng(3)
    x = np.asarray(rng.normal(0, 1, (1001, 3)) * [1e-5, 3.0, 7e4], order=order)
    assert np.array_equal(ck.row_norm(x), np.linalg.norm(x, axis=1))
    b = np.ascontiguousarray(x[:1000]).reshape(50, 20, 3)
    for arr, axis in ((x, 0), (b, 1), (b, 0)):
        m, s = ck.mean_std(arr, axis)
        assert np.array_equal(m, arr.mean(axis=axis)) and np.array_equal(s, arr.std(axis=axis))


@pytest.mark.parametrize("turn", [False, True])
def test_rest_rate_matches_plain_numpy_on_contiguous_and_split_rest(turn):
    """The rest mean rate is the plain numpy mean of the steady windows' samples, whether they
    are one contiguous run (read through a view) or split by a turn (gathered by mask)."""
    d = static_flight(seconds=60.0, lat_deg=50.0)
    w = d["w"].copy()
    win = int(round(ck.REST_WINDOW_S * 100.0))
    if turn:  # windows 10-12 turn: not steady, the others are
        w[10 * win : 13 * win] += 0.02
    fs = ck.check_imu(d["imu_t"], d["f"], w, 1e7)
    r = next(x for x in fs if x.check == "gyro at rest")
    keep = np.ones(len(w) // win, bool)
    if turn:
        keep[10:13] = False
    rest = w[: keep.size * win].reshape(keep.size, win, 3)[keep].reshape(-1, 3)
    expected = float(np.linalg.norm(rest.mean(axis=0))) / ck.OMEGA_E
    assert r.level == "ok" and r.value == expected
    assert f"at rest ({len(rest)} samples)" in r.message


@pytest.mark.parametrize("triad", ["platform", "strapdown"])
def test_single_sample_outliers_none_on_a_turbulent_flight_all_where_injected(triad):
    """The simulated flight's turbulence and turns (curvature far above the noise) give none;
    glitches of 10x the noise on a handful of samples are all found and nothing else."""
    s = simulated(triad)
    f, w = s.specific_force_t, s.angular_rate_t
    for arr in (f, w):
        for j in range(3):
            assert ck.single_sample_outliers(arr[:, j], ck.IMU_SPIKE_K).size == 0
    x = f[:, 2].copy()
    rng = np.random.default_rng(4)
    where = np.sort(rng.choice(np.arange(10, x.size - 10), 12, replace=False))
    noise = 1.4826 * np.median(np.abs(np.diff(x, 2) - np.median(np.diff(x, 2)))) / np.sqrt(1.5) / 2
    x[where] += rng.choice([-1.0, 1.0], where.size) * max(50 * noise, 0.05)
    assert ck.single_sample_outliers(x, ck.IMU_SPIKE_K).tolist() == where.tolist()
    # a smooth signal without noise, and a constant one: nothing (no scale, or no sign pattern)
    t = np.linspace(0.0, 60.0, 3001)
    assert ck.single_sample_outliers(9.8 + 3.0 * np.sin(t) ** 3, 10.0).size == 0
    assert ck.single_sample_outliers(np.full(100, 9.8), 10.0).size == 0


def test_imu_glitches_are_repaired_on_load_and_reported(tmp_path):
    """A 2 m/s^2 reading on a few samples (a corrupted packet): load_flight puts the neighbours'
    mean in its place and says so (before: 120-170 mGal of error on the unseen flights)."""
    d = static_flight(seconds=40.0)
    clean = np.array(d["f"], float)
    d["f"] = clean.copy()
    where = [500, 1700, 3100]
    d["f"][where, 2] += 2.0
    d["w"][2200, 0] += 0.05
    _write_flight_csv(tmp_path, d)
    with pytest.warns(DataWarning, match="single-sample glitch"):
        rec = load_flight(ingest_options({"inputs": CSV_IN}, "f"), tmp_path)
    note = [n for n in rec.notes if "glitch" in n]
    assert len(note) == 1 and note[0].startswith("imu: 4 single-sample glitch(es)")
    assert "3 on specific_force z (up to 2 m/s^2)" in note[0] and "1 on angular_rate x" in note[0]
    np.testing.assert_allclose(
        rec.imu.specific_force_t[where, 2], 0.5 * (clean[[w - 1 for w in where], 2] + clean[[w + 1 for w in where], 2])
    )
    others = np.ones(len(clean), bool)
    others[where] = False
    np.testing.assert_array_equal(rec.imu.specific_force_t[others], clean[others])


def test_a_real_imus_shocks_are_not_glitches():
    """The MEMS IMU of a wheeled robot (ROS 2 bags, tests/data/ros2-imu) has shocks of 7-24 robust
    sigmas of the statistic: none is taken for a glitch (the 99th-percentile guard); without the
    guard a few are (what it is there for)."""
    from pathlib import Path

    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    unguarded = 0
    for name in ("robot_localization_test1.mcap", "robot_localization_test2.mcap"):
        rows = []
        with open(Path(__file__).parent / "data" / "ros2-imu" / name, "rb") as fh:
            for schema, _, _, msg in make_reader(fh, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
                if schema.name == "sensor_msgs/msg/Imu":
                    a, w = msg.linear_acceleration, msg.angular_velocity
                    rows.append((a.x, a.y, a.z, w.x, w.y, w.z))
        v = np.array(rows)
        assert v.shape[0] > 3000
        for j in range(6):
            assert ck.single_sample_outliers(v[:, j], ck.IMU_SPIKE_K, ck.IMU_SPIKE_TAIL).size == 0
            unguarded += ck.single_sample_outliers(v[:, j], ck.IMU_SPIKE_K).size
    assert unguarded > 0


# ----------------------------------------------------------------------------- frozen channels
def _track(n=3000, hz=10.0, speed=80.0, seed=0):
    """A GNSS track due north at ``speed`` m/s from 47 N, full-precision noise (0.02 m)."""
    rng = np.random.default_rng(seed)
    t = 1_700_000_000 * 10**9 + np.round(np.arange(n) * 1e9 / hz).astype(np.int64)
    north = speed * np.arange(n) / hz + rng.normal(0, 0.02, n)
    lat = 47.0 + north / ck.M_PER_DEG
    lon = 11.0 + rng.normal(0, 0.02, n) / ck.M_PER_DEG
    return t, lat, lon, 800.0 + rng.normal(0, 0.05, n)


def test_held_gnss_fixes_are_found_exactly_and_only_while_moving():
    t, lat, lon, h = _track()
    for a, b in ((100, 101), (500, 700)):  # one held epoch, and 20 s of them
        lat[a:b], lon[a:b], h[a:b] = lat[a - 1], lon[a - 1], h[a - 1]
    got = ck.frozen_gnss(t, lat, lon, h)
    assert got.tolist() == [100] + list(range(500, 700))
    # at rest a receiver (or a simulator without noise) may repeat a fix: that is no fault
    t, lat, lon, h = _track(speed=0.0)
    lat[500:700], lon[500:700], h[500:700] = lat[499], lon[499], h[499]
    assert ck.frozen_gnss(t, lat, lon, h).size == 0


def test_coarse_digits_of_a_crawling_ship_are_not_held_fixes():
    # 2 m/s at 10 Hz written with 5 decimals (1.1 m): each value repeats for about 5 epochs
    t, lat, lon, h = _track(n=6000, speed=2.0)
    lat, lon, h = np.round(lat, 5), np.round(lon, 5), np.round(h, 0)
    assert len(ck.repeat_runs(np.stack([lat, lon, h], axis=1))) > 100
    assert ck.frozen_gnss(t, lat, lon, h).size == 0


def test_a_stale_imu_message_repeated_while_moving_is_found():
    tg, lat, lon, _ = _track(n=600)
    rng = np.random.default_rng(1)
    n = 6000
    ti = tg[0] + np.round(np.arange(n) * 1e7).astype(np.int64)  # 100 Hz
    f = np.array([0.0, 0.0, 9.81]) + rng.normal(0, 0.05, (n, 3))
    w = rng.normal(0, 1e-3, (n, 3))
    f[2001:2500], w[2001:2500] = f[2000], w[2000]  # 5 s held
    f[3001:3003], w[3001:3003] = f[3000], w[3000]  # a message logged three times: harmless, kept
    assert ck.frozen_imu(ti, f, w, tg, lat, lon).tolist() == list(range(2001, 2500))
    # no GNSS, or a GNSS at rest: a repeating IMU may be the record's nature (noiseless, quantised)
    assert ck.frozen_imu(ti, f, w).size == 0
    assert ck.frozen_imu(ti, f, w, tg, np.full(600, 47.0), np.full(600, 11.0)).size == 0


# ------------------------------------------------------------------ stamps that are not sampling times
_T0 = 1_741_608_000 * 10**9
_STEP = 20_000_000  # 50 Hz


def _true_times(n=20_000, step=_STEP):
    return _T0 + np.arange(n, dtype=np.int64) * step


@pytest.mark.parametrize(
    "kind, stamp, offset_ms",
    [
        # a 50-Hz IMU stamped by a clock of 0.1 s: cut to it (the samples come out (0.1 - 0.02) / 2
        # s early on average), or rounded to it (right on average)
        ("cut", lambda t: t // 100_000_000 * 100_000_000, -40.0),
        ("rounded", lambda t: (t + 50_000_000) // 100_000_000 * 100_000_000, 0.0),
        # blocks of five stamped when read, at the last sample: 40 ms late on average
        ("blocks", lambda t: t.reshape(-1, 5)[:, -1].repeat(5), 40.0),
    ],
)
def test_coarse_or_block_stamps_are_rebuilt_and_every_sample_kept(kind, stamp, offset_ms):
    """Four in five samples shared a stamp and were dropped ("kept the first of each"): now the
    stamps are rebuilt from the sample count, every sample kept, to well under a microsecond of
    the sampling times apart from a constant offset (which the aided track's GNSS latency check
    measures and takes off)."""
    true = _true_times()
    values = np.arange(true.size, dtype=float)
    stamps = stamp(true)
    t, (v,), rep = ck.repair_time(stamps, [values])
    assert rep.n_out == true.size and rep.conflicting_duplicates == 0 and rep.rebuilt == "coarse"
    np.testing.assert_array_equal(v, values)
    err = (t - true) * 1e-6  # ms
    assert abs(err.mean() - offset_ms) < 1e-3 and err.std() < 1e-3
    msg = next(f.message for f in ck.time_findings("imu", rep) if f.check == "stamps")
    shared = true.size - np.unique(stamps).size
    assert msg.startswith(f"imu: {shared} samples shared a time stamp with the one before (distinct stamps 0.1 s apart")
    assert "for 50-Hz samples" in msg and "every sample kept" in msg


def test_jittered_stamps_are_rebuilt_about_the_steady_rate():
    """A host's arrival stamps (2 ms RMS on a 20-ms step) come back within 0.3 ms; a 400-Hz IMU
    stamped in whole milliseconds (steps of 2 and 3 ms) to its 2.5-ms steps."""
    true = _true_times()
    rng = np.random.default_rng(11)
    jittered = true + np.round(rng.normal(0.0, 2e6, true.size)).astype(np.int64)
    t, _, rep = ck.repair_time(jittered, [])
    assert rep.rebuilt == "jitter" and rep.n_out == true.size
    assert np.sqrt(np.mean((t - true) ** 2.0)) < 0.3e6
    assert rep.rebuilt_jitter == pytest.approx(np.sqrt(2.0) * 0.1, rel=0.1)  # steps scatter sqrt(2) x 2 ms
    msg = next(f.message for f in ck.time_findings("imu", rep) if f.check == "stamps")
    assert msg.startswith("imu: time stamps scatter 14.") and "rebuilt from the sample count" in msg
    fast = _true_times(step=2_500_000)
    t, _, rep = ck.repair_time(fast // 1_000_000 * 1_000_000, [])
    assert rep.rebuilt == "jitter"
    steps = np.diff(t)
    # the 2-sample pattern leaves a ripple of the 1-ms stamp step over the 101-sample window
    assert np.all(np.abs(steps - 2_500_000) <= 10_000) and abs(np.mean(t - fast) + 0.25e6) < 1e3


def test_a_gap_within_coarse_stamps_stays_a_gap():
    true = _true_times()
    true = np.concatenate([true[:8000], true[8000:] + 60 * 10**9])  # a minute without samples
    values = np.arange(true.size, dtype=float)  # the samples differ: none is written twice
    t, _, rep = ck.repair_time(true // 100_000_000 * 100_000_000, [values])
    assert rep.rebuilt == "coarse" and rep.n_gaps == 1 and rep.n_out == true.size
    err = (t - true) * 1e-6
    assert np.all(np.abs(err + 40.0) < 1e-3)


@pytest.mark.parametrize(
    "case",
    ["exact", "dropped samples and a gap", "rate change", "a few late samples", "1-Hz fixes, a third missing"],
)
def test_stamps_that_are_sampling_times_are_not_rebuilt(case):
    """Exact stamps, a dropped sample here and there, a rate change within the record, a few
    late samples and a GNSS whose epochs are often missing keep their stamps as written."""
    true = _true_times()
    rng = np.random.default_rng(5)
    if case == "exact":
        t = true
    elif case == "dropped samples and a gap":
        t = np.delete(true, [500, 9000, 9001, 9002, 9003, 9004, 9005, 9006, 15000])
    elif case == "rate change":
        t = np.concatenate([true[:10_000], true[10_000::2]])
    elif case == "a few late samples":
        t = true + (rng.random(true.size) < 0.05) * 8_000_000
    else:
        t = _T0 + np.flatnonzero(rng.random(5000) > 0.33).astype(np.int64) * 10**9
    out, _, rep = ck.repair_time(t, [])
    assert rep.rebuilt == "" and not any(f.check == "stamps" for f in ck.time_findings("x", rep))
    np.testing.assert_array_equal(out, t)


def test_centred_mean_is_symmetric_for_odd_and_even_widths():
    x = np.arange(20.0)
    for width in (1, 3, 4, 5):
        m = centred_mean(x, width)
        half = width // 2
        np.testing.assert_allclose(m[half : x.size - half], x[half : x.size - half])  # a line stays a line
        assert np.all(m[:half] == m[half]) and np.all(m[x.size - half :] == m[x.size - half - 1])
    saw = np.tile(np.arange(4.0), 25)  # the sawtooth of coarse stamps, period 4
    np.testing.assert_allclose(centred_mean(saw, 8), 1.5)


# ------------------------------------------------------------------------------- a sensor at its range
def test_samples_at_a_sensors_range_are_found_and_nothing_else():
    rng = np.random.default_rng(2)
    x = 9.8 + 0.6 * rng.standard_normal(50_000)
    clipped = np.minimum(x, 10.8)  # the top 5 % at the range
    m = ck.saturated_samples(clipped)
    np.testing.assert_array_equal(m, x >= 10.8)
    both = np.clip(x, 8.9, 10.8)
    assert ck.saturated_samples(both).sum() == ((x >= 10.8) | (x <= 8.9)).sum()
    assert not ck.saturated_samples(x).any()  # noise: every value once
    assert not ck.saturated_samples(np.round(x, 1)).any()  # coarse digits: the extremes are rare
    assert not ck.saturated_samples(np.full(1000, 9.8)).any()  # a dead axis or a noise-free rest
    assert not ck.saturated_samples(np.tile([9.8, 9.8 + 2e-15], 500)).any()  # two values alike
    few = x.copy()
    few[:5] = x.max() + 1.0  # five samples at a new extreme: under the count
    assert not ck.saturated_samples(few).any()


def test_saturated_axes_are_named_and_the_accelerometers_marked():
    rng = np.random.default_rng(4)
    n = 20_000
    f = np.column_stack([rng.normal(0, 1, n), rng.normal(0, 1, n), 9.8 + rng.normal(0, 0.5, n)])
    w = rng.normal(0, 0.05, (n, 3))
    f[:, 2] = np.minimum(f[:, 2], 10.5)
    w[:, 0] = np.clip(w[:, 0], -0.1, 0.1)
    t = np.arange(n) * 0.02
    sat, found = ck.saturated_imu(f, w, t)
    np.testing.assert_array_equal(sat, f[:, 2] == 10.5)  # the accelerometer's samples only
    acc, gyro = (x.message for x in found)
    assert acc.startswith(f"imu: specific_force z held at 10.5 m/s^2 (declared m/s^2) on {int(sat.sum())} samples in ")
    assert "the accelerometer's range exceeded (saturated)" in acc and "(first " in acc
    assert (
        gyro.startswith("imu: angular_rate x held at -0.1, 0.1 rad/s") and "the attitude through them is wrong" in gyro
    )
