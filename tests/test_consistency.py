"""Gaps, clocks, input consistency and result plausibility (issue 14 items 2-4).

Every case is a damaged copy of sample_data/markov_csv written into a tmp dir
(tests/damage_csv.py); accuracy is checked against the simulator's truth.csv.
"""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).resolve().parent))
import damage_csv as d

from gravsurvey.config import load_config
from gravsurvey.consistency import (
    CheckOptions,
    check_result,
    find_clock_restarts,
    plan_segments,
    specific_force_fixed_frame,
)
from gravsurvey.errors import ConfigError, DataError, DataWarning
from gravsurvey.estimate import FlightEstimate, concatenate_estimates
from gravsurvey.io.ingest import load_flight
from gravsurvey.io.record import slice_record
from gravsurvey.pipeline import process_flight

MGAL = 1e-5


def _flight(tmp_path, prep=None, extra="", initial=None):
    cfg_path = d.copy_sample(tmp_path / "s", extra, initial)
    if prep is not None:
        prep(tmp_path / "s")
    cfg = load_config(cfg_path, output_dir=tmp_path / "out")
    return cfg, cfg.flights[0]


def _rms_on_lines(r):
    err = r.disturbance / MGAL - r.truth_mgal
    on = r.line != ""
    assert np.all(np.isfinite(err[on]))
    return float(np.sqrt(np.mean(err[on] ** 2)))


@pytest.fixture(scope="module")
def intact(tmp_path_factory):
    cfg, fl = _flight(tmp_path_factory.mktemp("intact"))
    return process_flight(cfg, fl)


# ----------------------------------------------------------------------------- no false alarms
def test_intact_sample_passes_every_check(intact):
    r = intact
    assert not any("split" in n or "restart" in n for n in r.notes)
    assert r.data_loss == []
    passed = r.estimator["checks_passed"]  # facts in summary.json, not warnings
    assert not any("time offset" in n or "navigation within" in n for n in r.notes)
    off = [n for n in passed if "time offset:" in n]
    assert off and "+0.0" in off[0] or "-0.0" in off[0]
    assert any("navigation within" in n for n in passed)
    assert _rms_on_lines(r) < 4.0  # 3.36 mGal measured


# ----------------------------------------------------------------------------- gaps
def test_30_minute_gap_splits_into_two_accurate_segments(tmp_path, intact):
    """Measured before: whole flight NaN / -2.6e6 mGal, exit 0."""
    cfg, fl = _flight(tmp_path, lambda p: d.shift_after(p, 480, 1800))
    r = process_flight(cfg, fl)
    assert any("estimated 2 of 2 segments" in n for n in r.notes)
    assert any("split at imu gap" in n and "imu.csv" in n and "1800" in n for n in r.notes)
    # a NaN epoch separates the segments; both sides have lines with finite, accurate output
    assert np.isnan(r.smoothed).sum() == 1
    assert len(r.line_info) == 2
    early, late = r.time < 1000, r.time > 1000
    for part in (early, late):
        on = part & (r.line != "")
        assert on.sum() > 200
        err = r.disturbance[on] / MGAL - r.truth_mgal[on]
        assert np.all(np.isfinite(err))
        assert np.sqrt(np.mean(err**2)) < 6.0  # 5.2 and 4.0 mGal measured (intact: 3.4)
    assert np.nanmax(np.abs(r.smoothed)) / MGAL < 200


def test_imu_gap_of_a_minute_splits_the_flight(tmp_path):
    cfg, fl = _flight(tmp_path, lambda p: d.drop_between(p, "imu", 400, 460))
    r = process_flight(cfg, fl)
    assert any("estimated 2 of 2 segments" in n for n in r.notes)
    # 6.1 mGal measured (3.58 with the earlier default: ti_cosphi after a fixed seed prior; the
    # default product is now the smoothed estimate, and a 400 s first segment keeps the
    # default anomaly prior: solve.MIN_REFINE_S); the point here is the split, not the level
    assert _rms_on_lines(r) < 7.0


def test_a_late_first_gnss_fix_places_the_start_only_if_the_aircraft_waited_for_it(tmp_path, intact):
    """A receiver's first fix 60 s after the IMU's start, the aircraft still parked: its fixes are
    the start's position (before: a quadratic fit extrapolated back over the wait, 9.6 mGal
    against 3.45 intact); 200 s after, the aircraft moving since 120 s: the estimate starts at
    the fix, said (before: the start placed 200 s of taxi and climb away, 94.9 mGal, exit 0)."""
    from gravsurvey.inm.alignment import gnss_lead_s, rest_through_gnss_lead

    for late, rest in ((60.0, True), (200.0, False)):
        cfg, fl = _flight(tmp_path / f"l{late:.0f}", lambda p, a=late: d.drop_between(p, "gnss", -10, a))
        rec = load_flight(fl.ingest, cfg.base_dir)
        assert gnss_lead_s(rec) == pytest.approx(late, abs=0.5) and rest_through_gnss_lead(rec) == rest
        r = process_flight(cfg, fl)
        said = [n for n in r.notes if "the first GNSS fix" in n]
        if rest:
            assert not said and r.time[0] == intact.time[0]
            assert _rms_on_lines(r) < 1.05 * _rms_on_lines(intact)  # 3.47 measured
        else:
            assert len(said) == 1 and "comes 200.0 s after the first IMU sample and the aircraft moved" in said[0]
            assert "(200.0 s) not estimated" in said[0]
            # the estimate starts at the fix, less its first resolution's worth, which has data on
            # one side only (estimate.trim_one_sided_ends)
            (trim,) = [n for n in r.notes if "is left out: it has data on one side only" in n]
            margin = float(trim.split("the estimate within ")[1].split(" s ")[0])
            assert 10.0 < margin < 300.0 and r.time[0] == pytest.approx(late + margin, abs=1.5)
            assert _rms_on_lines(r) < 1.5 * _rms_on_lines(intact)  # 4.73 measured: the line from 20 s after the fix
    # the start given in the config: kept from the IMU's first sample, the given values unchecked
    tr = _truth_start(tmp_path / "l200")
    cfg, fl = _flight(tmp_path / "given", lambda p: d.drop_between(p, "gnss", -10, 200.0), initial=tr)
    assert process_flight(cfg, fl).time[0] == intact.time[0]


def _truth_start(folder):
    """The truth's position and velocity at the first sample, as an ``initial`` block."""
    import csv

    with open(Path(folder) / "s" / "F01" / "truth.csv") as fh:
        row = next(csv.DictReader(ln for ln in fh if not ln.startswith("#")))
    return {
        "lat_deg": float(row["lat_deg"]),
        "lon_deg": float(row["lon_deg"]),
        "height_m": float(row["height_m"]),
        "velocity_enu_mps": [float(row["ve_mps"]), float(row["vn_mps"]), float(row["vu_mps"])],
    }


def test_segment_that_cannot_be_reinitialised_is_data_loss(tmp_path):
    def prep(p):  # GNSS ends before an IMU gap: the second segment has no GNSS to start from
        d.drop_between(p, "gnss", 380, 2000)
        d.drop_between(p, "imu", 400, 460)

    cfg, fl = _flight(tmp_path, prep)
    r = process_flight(cfg, fl)
    assert any("estimated 1 of 2 segments" in n for n in r.notes)
    assert len(r.data_loss) == 1 and "not estimated: initial.lat_deg: missing; the record has no GNSS" in r.data_loss[0]
    assert np.isfinite(r.smoothed).all()


def test_short_imu_gap_is_bridged(tmp_path, intact):
    cfg, fl = _flight(tmp_path, lambda p: d.drop_between(p, "imu", 400, 401.05))
    r = process_flight(cfg, fl)
    assert any("bridged by the mechanization" in n for n in r.notes)
    assert not any("segments" in n for n in r.notes)
    # 3.52 against 3.29 mGal (3.63 against 3.44 before the vertical channel's constant was taken
    # off the specific force: both better, the intact flight by more)
    assert abs(_rms_on_lines(r) - _rms_on_lines(intact)) < 0.25


@pytest.mark.parametrize(
    "case, restamp, says, placed",
    [
        (
            "whole seconds",
            lambda t, rng: t // d.NS * d.NS,
            "samples shared a time stamp with the one before",
            "placed against the GNSS track, moved +0.45 s",
        ),
        ("20-ms jitter", lambda t, rng: t + np.round(rng.normal(0.0, 2e7, t.size)).astype(np.int64), "scatter", None),
    ],
)
def test_imu_stamps_of_a_coarse_clock_or_a_host_lose_no_sample(tmp_path, intact, case, restamp, says, placed):
    """The sample's 10-Hz IMU stamped to the whole second (nine samples in ten shared a stamp
    and were dropped) or on arrival with 20 ms of jitter: every sample is kept, the stamps
    rebuilt from the sample count and said, and the product is the intact one's (3.43 and 3.42
    against 3.45 mGal; 3.41 and 3.46 with the samples dropped or the jitter integrated).  Cut to
    the second, the stamps sit 0.45 s early on average: placed against the GNSS track (the
    corrected track had departed from the GNSS by 2.3 m RMS, said in a note)."""
    rng = np.random.default_rng(7)

    def prep(p):
        def fn(head, rows):
            t = restamp(np.array([int(r[0]) for r in rows], dtype=np.int64), rng)
            for r, v in zip(rows, t):
                r[0] = str(int(v))
            return rows

        d.edit(p, "imu", fn)

    cfg, fl = _flight(tmp_path, prep)
    cfg0, fl0 = _flight(tmp_path / "intact", None)
    n_intact = load_flight(fl0.ingest, cfg0.base_dir).imu.time.size
    assert load_flight(fl.ingest, cfg.base_dir).imu.time.size == n_intact
    r = process_flight(cfg, fl)
    assert r.data_loss == [] and any("F01: imu: " in n and says in n and "rebuilt" in n for n in r.notes)
    assert _rms_on_lines(r) == pytest.approx(_rms_on_lines(intact), rel=0.03)
    assert not any("departs from the GNSS" in n for n in r.notes)
    if placed:
        assert any(placed in n for n in r.notes)
        off = next(n for n in r.estimator["checks_passed"] if "time offset:" in n)
        assert " runs +0.00 s relative to gnss" in off or " runs -0.00 s relative to gnss" in off


def test_rebuilt_imu_stamps_are_placed_only_within_what_they_leave_unknown(tmp_path):
    """Whole-second stamps of a 10-Hz IMU leave its time unknown by up to 0.45 s: an IMU 0.30 s
    late is moved back onto the GNSS track's time; 2 s late is beyond that (a clock fault for the
    time-offset check to name), and 0.1-s stamps (0.045 s unknown) are left to the GNSS latency
    check: both returned as they were."""
    from gravsurvey.io.checks import TimeReport
    from gravsurvey.io.ingest import place_rebuilt_imu

    cfg, fl = _flight(tmp_path)
    rec = load_flight(fl.ingest, cfg.base_dir)
    coarse = TimeReport(rebuilt="coarse", rebuilt_stamp_step_ns=1e9, nominal_step_ns=1e8)

    def late(s):
        return dataclasses.replace(rec, imu=dataclasses.replace(rec.imu, time=rec.imu.time + s))

    placed = place_rebuilt_imu(late(0.3), coarse)
    assert placed.notes[-1].startswith("imu: the rebuilt stamps placed against the GNSS track, moved -0.30 s")

    def absolute(r, ch):  # s after the intact record's t0
        return (r.t0_unix_ns - rec.t0_unix_ns) * 1e-9 + getattr(r, ch).time

    np.testing.assert_allclose(absolute(placed, "imu"), rec.imu.time, atol=0.051)
    for ch in ("gnss", "altimeter"):  # the other channels' times as they were
        np.testing.assert_allclose(absolute(placed, ch), getattr(rec, ch).time, atol=1e-9)
    far = late(2.0)
    assert place_rebuilt_imu(far, coarse) is far
    fine = TimeReport(rebuilt="coarse", rebuilt_stamp_step_ns=1e8 + 9e7, nominal_step_ns=1e8)
    assert place_rebuilt_imu(late(0.3), fine).notes == rec.notes


def test_aiding_gap_is_bridged_and_sigma_grows_across_it(tmp_path, intact):
    def prep(p):
        d.drop_between(p, "altimeter", 400, 460)
        d.drop_between(p, "gnss", 400, 460)

    cfg, fl = _flight(tmp_path, prep)
    r = process_flight(cfg, fl)
    assert not any("segments" in n for n in r.notes)
    gap = (r.time > 400) & (r.time < 460)
    far = (r.time > 250) & (r.time < 330)
    assert r.sigma[gap].max() > 1.03 * np.median(r.sigma[far])  # +7 % measured
    err = r.smoothed / MGAL - r.truth_mgal
    # the error inside the gap stays within the (grown) 3 sigma
    assert np.all(np.abs(err[gap]) < 3 * r.sigma[gap] / MGAL + 1.0)


# ----------------------------------------------------------------------------- clocks
def test_imu_clock_an_hour_out_of_step_is_an_error_naming_both_channels(tmp_path):
    """Measured before: a profile of 0.0000 mGal, exit 0."""
    cfg, fl = _flight(tmp_path, lambda p: d.shift_after(p, -1, 3600, names=("imu",)))
    with pytest.raises(
        DataError,
        match=r"imu \(.*imu\.csv\) 2025-03-10T13:00:00.*altimeter \(.*altimeter\.csv\) "
        r"2025-03-10T12:00:00.*do not overlap",
    ):
        process_flight(cfg, fl)


@pytest.mark.parametrize("factor, unit", [(10**3, "microseconds"), (10**6, "milliseconds")])
def test_gnss_stamps_in_a_larger_unit_than_nanoseconds_are_named(tmp_path, factor, unit):
    """GNSS stamps in us or ms under a time column read as ns (fuzzing, 2026-12-04: 'a clock out of
    step or files of different flights?')."""

    def prep(p):
        d.edit(p, "gnss", lambda h, rows: [[str(int(r[0]) // factor)] + r[1:] for r in rows])

    cfg, fl = _flight(tmp_path, prep)
    with pytest.raises(DataError) as exc:
        process_flight(cfg, fl)
    msg = str(exc.value)
    assert "do not overlap in time" in msg and "\n" not in msg
    assert f"the gnss stamps read {factor:,}x too small: in {unit} but declared as nanoseconds" in msg


@pytest.mark.parametrize("shift_s, says", [(3600, "do not overlap in time"), (300, "clocks out of step")])
def test_a_gnss_clock_minutes_or_hours_out_of_step_is_measured_and_named(tmp_path, shift_s, says):
    """GNSS stamps an hour late (a file in local time) or five minutes late: measured by the
    specific-force correlation at the lag of the records' ends (fuzzing, 2026-12-04: "a clock out
    of step or files of different flights?", and for 600 s on a strapdown flight "the navigation
    did not settle ... set model.gyro_bias_sigma_degph")."""
    cfg, fl = _flight(tmp_path, lambda p: d.shift_after(p, -1, shift_s, names=("gnss",)))
    with pytest.raises(DataError) as exc:
        process_flight(cfg, fl)
    msg = str(exc.value)
    assert says in msg and f"give the flight time_offsets_s: {{gnss: -{shift_s}." in msg and "\n" not in msg
    assert ("(1 h: local time in one file?)" in msg) == (shift_s == 3600)


def test_imu_clock_restart_is_placed_by_gnss(tmp_path):
    """Measured before: 6.3 mGal here (279 mGal in the issue's case), exit 0, nothing said."""
    cfg, fl = _flight(tmp_path, lambda p: d.restart_clock(p, "imu", 600, 300))
    r = process_flight(cfg, fl)
    assert r.data_loss == []
    msg = next(n for n in r.notes if "clock restart" in n)
    assert "imu.csv at sample 6001" in msg and "12:10:00" in msg and "12:05:00" in msg
    assert "3600 samples after it placed at 2025-03-10T12:10:00" in msg and "cross-correlation with GNSS" in msg
    assert _rms_on_lines(r) < 4.0  # 3.35 mGal measured (intact 3.36)


def test_unplaceable_clock_restarts_are_dropped_as_data_loss(tmp_path):
    # two restarts: the samples after the first have no single clock to place
    cfg, fl = _flight(tmp_path, lambda p: (d.restart_clock(p, "imu", 300, 100), d.restart_clock(p, "imu", 700, 200)))
    r = process_flight(cfg, fl)
    assert len(r.data_loss) == 1
    msg = r.data_loss[0]
    assert "imu: clock restart" in msg and "imu.csv at sample 3001" in msg and "12:05:00" in msg
    assert "6600 samples from the restart on dropped" in msg
    # a GNSS restart is never placed (GNSS is the reference)
    cfg, fl = _flight(tmp_path / "g", lambda p: d.restart_clock(p, "gnss", 500, 400))
    r = process_flight(cfg, fl)
    assert len(r.data_loss) == 1 and "gnss: clock restart" in r.data_loss[0]
    assert _rms_on_lines(r) < 4.0  # 3.43 mGal measured


def test_imu_gnss_time_offset_is_measured_and_refused(tmp_path):
    cfg, fl = _flight(tmp_path, lambda p: d.shift_after(p, -1, 5.0, names=("imu",)))
    with pytest.raises(DataError, match=r"imu \(.*imu\.csv\).* runs \+5\.0\d s relative to gnss \(.*gnss\.csv\)"):
        process_flight(cfg, fl)


def test_a_flat_correlation_peak_is_not_a_clock_verdict():
    """Quick unseen flight U602 (platform, 116 m/s, 18.7-mGal field, 3-Hz GNSS) has no clock
    offset, yet the specific forces' correlation peaks at +0.51 s (r = 0.9094; 0.9090 at zero:
    the field, which the GNSS track does not see, is much of the IMU's signal). It was refused
    as "clocks out of step" (fuzzing the unseen generator's seeds 600-619, 2026-12-05); then
    warned "not a verdict, check the clocks"; now the lags within the limit fit as well, which
    is a passed check's note (no offset shown). Its GNSS 20 s late is still refused, with the
    value to give; 2 s late, warned."""
    from gravsurvey.consistency import (
        OFFSET_VERDICT_CORRELATION,
        OFFSET_VERDICT_EVIDENCE,
        PASSED,
        ChannelNames,
        check_gnss_consistency,
        estimate_time_offset,
        time_offset_evidence,
    )
    from gravsurvey.simulate.run import simulate_flight
    from gravsurvey.simulate.unseen import draw_flight_spec, limit_spec
    from sim_record import record_and_initial

    spec = limit_spec(draw_flight_spec(602), 2400.0, 50.0)
    rec = record_and_initial(simulate_flight(spec["sim"]))[0]
    names = ChannelNames({"imu": "imu.csv", "gnss": "gnss.csv"}, {})
    off, c = estimate_time_offset(rec)
    assert abs(off) > CheckOptions().max_time_offset_s and c >= OFFSET_VERDICT_CORRELATION  # the old verdict
    assert time_offset_evidence(rec, c, CheckOptions().max_time_offset_s) < 1.0  # measured 0.00
    notes = check_gnss_consistency(rec, names, CheckOptions())
    said = [n for n in notes if "time offset:" in n]
    assert len(said) == 1 and said[0].startswith(PASSED + "time offset:") and "no offset shown" in said[0]
    two = dataclasses.replace(rec, gnss=dataclasses.replace(rec.gnss, time=rec.gnss.time + 2.0))
    said = [n for n in check_gnss_consistency(two, names, CheckOptions()) if "time offset:" in n]
    assert len(said) == 1 and said[0].startswith("time offset:") and "not a verdict, check the clocks" in said[0]
    late = dataclasses.replace(rec, gnss=dataclasses.replace(rec.gnss, time=rec.gnss.time + 20.0))
    off, c = estimate_time_offset(late)
    assert off == pytest.approx(-20.0, abs=0.6)  # -19.49: the same flat peak, 20 s on
    assert time_offset_evidence(late, c, CheckOptions().max_time_offset_s) > 10 * OFFSET_VERDICT_EVIDENCE  # 169
    with pytest.raises(DataError, match=r"clocks out of step .*time_offsets_s: \{gnss: -(19|20)\.\d\d\}"):
        check_gnss_consistency(late, names, CheckOptions())


def test_a_known_clock_offset_is_named_and_taken_in_the_config(tmp_path, intact):
    """A GNSS in GPS time against an IMU in UTC (18 s): refused, the error names the key and the
    value that puts the clocks in step; given, the flight is estimated as intact."""
    import re

    cfg, fl = _flight(tmp_path / "a", lambda p: d.shift_after(p, -1, 18.0, names=("gnss",)))
    with pytest.raises(DataError, match=r"runs -18\.\d\d s relative to gnss") as err:
        process_flight(cfg, fl)
    hint = re.search(r"time_offsets_s: \{gnss: ([-+0-9.]+)\}", str(err.value))
    assert hint and float(hint.group(1)) == pytest.approx(-18.0, abs=0.1)
    cfg, fl = _flight(tmp_path / "b", lambda p: d.shift_after(p, -1, 18.0, names=("gnss",)))
    assert fl.ingest.time_offsets_ns == {}
    cfg_path = tmp_path / "b" / "s" / "survey.yaml"
    cfg_path.write_text(cfg_path.read_text().replace("\n  triad:", "\n  time_offsets_s: {gnss: -18}\n  triad:", 1))
    cfg = load_config(cfg_path, output_dir=tmp_path / "b" / "out")
    assert cfg.flights[0].ingest.time_offsets_ns == {"gnss": -18 * 10**9}
    r = process_flight(cfg, cfg.flights[0])
    assert _rms_on_lines(r) == pytest.approx(_rms_on_lines(intact), rel=1e-6, abs=1e-6)


def test_time_offsets_are_for_channels_read_from_mcap_or_csv():
    from gravsurvey.settings import FlightSection, validate_section

    with pytest.raises(ConfigError, match=r"flights\[0\]\.time_offsets_s: a gravimeter flight"):
        validate_section(
            FlightSection,
            {
                "inputs": {
                    "gravimeter": {
                        "format": "zls",
                        "file": "x.dat",
                        "offset_mgal": 0.0,
                        "nav": {"format": "nmea", "file": "x.nmea"},
                    }
                },
                "time_offsets_s": {"gnss": 1.0},
            },
            "flights[0]",
        )
    with pytest.raises(ConfigError, match=r"flights\[0\]\.time_offsets_s\.gnss: "):
        validate_section(FlightSection, {"inputs": {"mcap": "x.mcap"}, "time_offsets_s": {"gnss": 1e9}}, "flights[0]")


def test_time_offset_within_the_limit_is_reported(tmp_path):
    cfg, fl = _flight(tmp_path, lambda p: d.shift_after(p, -1, 0.3, names=("imu",)))
    r = process_flight(cfg, fl)
    note = next(n for n in r.estimator["checks_passed"] if "time offset:" in n)
    est = float(note.split(" runs ")[1].split(" s ")[0])
    assert abs(est - 0.3) < 0.1


def test_find_clock_restarts_ignores_jitter_and_filled_holes():
    t = np.arange(100, dtype=np.int64) * 10**8
    jitter = t.copy()
    jitter[[10, 11]] = jitter[[11, 10]]
    assert find_clock_restarts(jitter)[1] == []
    hole = np.concatenate([t[:30], t[60:], t[30:60]])  # a block written late fills its hole
    assert find_clock_restarts(hole)[1] == []
    restart = np.concatenate([t[:60], t[:40] + 5 * 10**7])
    keep, ev = find_clock_restarts(restart)
    assert len(ev) == 1 and ev[0][0] == 60 and ev[0][3] == 40 and keep.sum() == 60
    # two restarts: everything after the first is in an unknown time base
    two = np.concatenate([t[:60], t[20:90], t[40:50]])
    keep, ev = find_clock_restarts(two)
    assert len(ev) == 1 and keep.sum() == 60 and ev[0][3] == 80
    # a glitch burst: a few samples stamped too early, then the clock is back in step
    burst = np.concatenate([t[:60], t[:5] + 10**7, t[60:]])
    keep, ev = find_clock_restarts(burst)
    assert len(ev) == 1 and ev[0][3] == 5 and keep.sum() == 100 and np.all(np.diff(burst[keep]) > 0)


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(50, 400),
    frac=st.floats(0.2, 0.9),
    back_s=st.floats(1.5, 1e4),
    jitter=st.lists(st.integers(1, 398), max_size=5),
)
@example(n=100, frac=0.6, back_s=3.0, jitter=[])
def test_generated_restarts_drop_exactly_the_restarted_samples(n, frac, back_s, jitter):
    t = np.arange(n, dtype=np.int64) * 10**8
    for i in jitter:  # sub-second jitter: adjacent stamps swapped
        if i < n - 1:
            t[[i, i + 1]] = t[[i + 1, i]]
    keep, ev = find_clock_restarts(t)
    assert ev == [] and keep.all()
    j = int(frac * n)
    back = min(int(back_s * 1e9), int(t[:j].max()))  # goes back into the span already recorded
    r = t.copy()
    r[j:] -= back
    keep, ev = find_clock_restarts(r)
    if r[j] < r[j - 1] - 10**9:  # a backward step of more than 1 s: a restart
        assert len(ev) == 1 and ev[0][0] == j and keep[:j].all() and not keep[j:].any()
        # no interleaving of two clocks among the kept samples
        assert np.all(np.diff(np.sort(r[keep])) > 0)
    else:  # shorter steps are jitter for the time repair (re-sort), not restarts
        assert ev == []


# ----------------------------------------------------------------------------- input consistency
@pytest.mark.parametrize(
    "case, prep, cols, hint",
    [
        ("swapped", lambda p: d.swap_columns(p, "gnss", "lat_deg", "lon_deg"), "columns lat_deg, lon_deg", "swapped"),
        (
            "radians",
            lambda p: d.map_columns(p, "gnss", {"lat_deg": np.radians, "lon_deg": np.radians}),
            "columns lat_deg, lon_deg",
            "radians but declared as degrees? (set csv.units.latlon: rad)",
        ),
        (
            "feet",
            lambda p: [d.map_columns(p, n, {"height_m": lambda h: h / 0.3048}) for n in ("gnss", "altimeter")],
            "column height_m",
            "feet but declared as metres? (set csv.units.height: ft)",
        ),
    ],
)
def test_gnss_column_mixups_name_the_column(tmp_path, case, prep, cols, hint):
    cfg, fl = _flight(tmp_path, prep)
    with pytest.raises(DataError) as exc:
        process_flight(cfg, fl)
    msg = str(exc.value)
    assert "gnss.csv " + cols in msg and hint in msg and "\n" not in msg


def test_gnss_positions_in_radians_are_read_with_units_latlon(tmp_path):
    """A receiver's export in radians, declared with ``csv.units.latlon: rad``: the same record
    as the file in degrees (before the key, such a file had to be converted by hand)."""
    cfg, fl = _flight(tmp_path / "deg")
    want = load_flight(fl.ingest, cfg.base_dir).gnss
    cfg_path = d.copy_sample(tmp_path / "rad")
    d.map_columns(tmp_path / "rad", "gnss", {"lat_deg": np.radians, "lon_deg": np.radians})
    text = cfg_path.read_text()
    cfg_path.write_text(text.replace("  triad: platform\n", "  triad: platform\n  csv: {units: {latlon: rad}}\n", 1))
    cfg2 = load_config(cfg_path, output_dir=tmp_path / "out")
    got = load_flight(cfg2.flights[0].ingest, cfg2.base_dir).gnss
    np.testing.assert_allclose(got.lat, want.lat, rtol=0, atol=1e-14)
    np.testing.assert_allclose(got.lon, want.lon, rtol=0, atol=1e-14)
    np.testing.assert_array_equal(got.height, want.height)
    # the same key for an MCAP's GNSS topic (units applied after decoding)
    from gravsurvey.io.ingest import apply_units

    vals = {"lat_deg": np.array([0.5]), "lon_deg": np.array([-2.0]), "height": np.array([10.0])}
    out = apply_units("gnss", vals, {"latlon": "rad", "height": "ft"})
    np.testing.assert_allclose([out["lat_deg"][0], out["lon_deg"][0]], np.degrees([0.5, -2.0]), rtol=1e-15)
    assert out["height"][0] == pytest.approx(3.048, rel=1e-15) and vals["lat_deg"][0] == 0.5


def test_moderate_unexplained_mismatch_is_a_note_not_an_error(tmp_path):
    """An accelerometer bias of 1000 mGal: no column mix-up explains it, below the gross limit."""
    from gravsurvey.consistency import channel_names, check_gnss_consistency

    cfg, fl = _flight(tmp_path, lambda p: d.map_columns(p, "imu", {"fz_mps2": lambda f: f + 0.01}))
    rec = load_flight(fl.ingest, cfg.base_dir)
    notes = check_gnss_consistency(rec, channel_names(fl.ingest, cfg.base_dir), CheckOptions())
    note = next(n for n in notes if n.startswith("gnss vs imu"))
    assert "no column mix-up explains it" in note and "+98" in note  # ~ +985 mGal
    with pytest.raises(DataError, match="wrong latitude, height unit or accelerometer scale"):
        check_gnss_consistency(rec, channel_names(fl.ingest, cfg.base_dir), CheckOptions(max_gravity_mismatch_mgal=150))


def test_heights_in_metres_declared_as_feet_are_named_in_a_warning(tmp_path):
    """Both height channels in metres declared as feet: they agree with each other, and normal
    gravity at the converted heights is 341 mGal off the IMU's, under the 500-mGal limit that
    holds an accelerometer's bias; that the other conversion takes it to 16 mGal is said
    (fuzzing, 2026-12-04: silent, 2.8x the error)."""
    from gravsurvey.consistency import channel_names, check_gnss_consistency

    cfg_path = d.copy_sample(tmp_path / "s")
    text = cfg_path.read_text()
    cfg_path.write_text(text.replace("  triad: platform\n", "  triad: platform\n  csv: {units: {height: ft}}\n", 1))
    cfg = load_config(cfg_path, output_dir=tmp_path / "out")
    fl = cfg.flights[0]
    rec = load_flight(fl.ingest, cfg.base_dir)
    notes = check_gnss_consistency(rec, channel_names(fl.ingest, cfg.base_dir), CheckOptions())
    (hint,) = [n for n in notes if "converted the other way" in n]
    assert "gnss.csv column height_m: the IMU measures a specific force -3" in hint
    assert "height in metres but declared as feet? (then set csv.units.height: m;" in hint
    # the intact sample: no such note
    cfg2, fl2 = _flight(tmp_path / "ok")
    rec2 = load_flight(fl2.ingest, cfg2.base_dir)
    assert not [
        n
        for n in check_gnss_consistency(rec2, channel_names(fl2.ingest, cfg2.base_dir), CheckOptions())
        if "converted" in n
    ]


def test_implausible_gnss_speed_names_the_columns(tmp_path):
    # latitude steps 20x too large (e.g. a scale error): the track "flies" at ~1200 m/s
    cfg, fl = _flight(tmp_path, lambda p: d.map_columns(p, "gnss", {"lat_deg": lambda x: x[0] + 20 * (x - x[0])}))
    with pytest.raises(DataError, match=r"gnss\.csv columns lat_deg, lon_deg: the GNSS track moves at 1[12]\d\d m/s"):
        process_flight(cfg, fl)


def _flip(*cols):
    return lambda p: d.map_columns(p, "imu", {c: (lambda x: -x) for c in cols})


def _swap(a, b):
    """Swap two IMU columns of the sample copied to ``p``."""

    def prep(p):
        def fn(head, rows):
            i, k = head.index(a), head.index(b)
            for r in rows:
                r[i], r[k] = r[k], r[i]
            return rows

        d.edit(p, "imu", fn)

    return prep


_swap_x_z = _swap("fx_mps2", "fz_mps2")


def _refusal(tmp_path, prep, extra="") -> str:
    """The DataError text of processing the sample with ``extra`` flight keys and ``prep``
    applied to its files."""
    cfg_path = d.copy_sample(tmp_path / "s")
    if extra:
        text = cfg_path.read_text()
        cfg_path.write_text(text.replace("  triad: platform\n", "  triad: platform\n" + extra.replace("    ", "  "), 1))
    if prep is not None:
        prep(tmp_path / "s")
    cfg = load_config(cfg_path, output_dir=tmp_path / "out")
    with pytest.raises(DataError) as exc:
        process_flight(cfg, cfg.flights[0])
    return str(exc.value)


@pytest.mark.parametrize(
    "prep, extra, axis",
    [
        # a platform logged forward-right-down, read as the default forward-left-up
        (_flip("fy_mps2", "fz_mps2"), "", "-z"),
        (_flip("wy_radps", "wz_radps", "fy_mps2", "fz_mps2"), "", "-z"),
        # a forward-left-up platform declared FRD
        (None, "    imu_axes: FRD\n", "-z"),
        # the vertical in the first column
        (_swap_x_z, "", "+x"),
    ],
)
def test_platform_axes_not_up_name_the_axes_key(tmp_path, prep, extra, axis):
    """A platform triad whose third axis does not read +g is an error naming the IMU columns, the
    axis gravity lies on and ``imu_axes``, before any navigation (not a run-away or a mirrored
    vertical channel)."""
    msg = _refusal(tmp_path, prep, extra)
    assert "imu.csv columns fx_mps2, fy_mps2, fz_mps2: the platform triad's third axis" in msg
    assert f"gravity lies on the triad's {axis} axis" in msg and "flights[0].imu_axes" in msg and "\n" not in msg


@pytest.mark.parametrize(
    "prep, slopes",
    [
        (_flip("wx_radps"), "x -1.00, y +1.00, z +1.00"),
        (_flip("wy_radps"), "x +1.00, y -1.00, z +1.00"),
        (_flip("wz_radps"), "x +1.00, y +1.00, z -1.00"),
        (_swap("wx_radps", "wy_radps"), "x -4.0"),
    ],
)
def test_platform_gyro_axis_negated_or_swapped_names_the_gyro_columns(tmp_path, prep, slopes):
    """A platform's gyro axis negated, or two swapped: each gyro's 60-s means against the rate
    of an east-north-up frame along the GNSS track (Earth's rate and transport rate) have slope
    -1 or far from 1 instead of +1. Before (fuzzing, 2026-12-04) these ran with exit 0 at 1.8-5.3x
    the intact error; now an error naming the gyro columns and imu_axes."""
    msg = _refusal(tmp_path, prep)
    assert "imu.csv columns wx_radps, wy_radps, wz_radps: the platform gyros do not turn" in msg
    assert f"give slopes {slopes}" in msg and "flights[0].imu_axes" in msg and "\n" not in msg


def test_platform_latitudes_of_the_wrong_sign_name_the_latitude_column(tmp_path):
    """With the GNSS latitudes negated the platform's gyros read slopes x -1, z -1 (the Earth's
    vertical rate and the rate about east change sign): named as the latitude's sign, not as two
    gyro axes negated."""
    msg = _refusal(tmp_path, lambda p: d.map_columns(p, "gnss", {"lat_deg": lambda x: -x}))
    assert "gnss.csv column lat_deg: the platform gyros turn as an east-north-up platform does" in msg
    assert "slopes x +1.00, y +1.00, z +1.00; as written x -1.00, y +1.00, z -1.00" in msg
    assert "the latitudes' sign is wrong" in msg and "\n" not in msg


def test_platform_gyros_in_a_smaller_unit_are_named_not_a_body_fixed_imu(tmp_path):
    """A level platform's gyros written in deg/h and declared deg/s read 3600 x the Earth's rate
    steadily: the refusal names the unit, not a body-fixed IMU (fuzzing, 2026-12-04)."""
    scale = 180.0 / np.pi * 3600.0
    prep = lambda p: d.map_columns(p, "imu", {c: (lambda x: x * scale) for c in ("wx_radps", "wy_radps", "wz_radps")})  # noqa: E731
    msg = _refusal(tmp_path, prep, "    csv: {units: {gyro: deg/s}}\n")
    assert "the platform triad turns about its horizontal axes" in msg
    assert "x the Earth's rate: gyros in deg/h declared as deg/s? (csv.units.gyro)" in msg and "strapdown" not in msg


def test_platform_axes_check_passes_a_level_platform_and_skips_strapdown(intact):
    """The intact platform sample passes with a note of its up-axis reading; a strapdown triad is
    aligned from the data in any orientation and is not checked, however it is turned."""
    from types import SimpleNamespace

    from gravsurvey.consistency import check_platform_axes

    assert any("platform axes: median up-axis specific force +9.8" in n for n in intact.estimator["checks_passed"])
    # and its gyros turn with the Earth and the track (slopes 1.000 on the simulated platforms)
    (rates,) = [n for n in intact.estimator["checks_passed"] if "platform gyros" in n]
    assert "platform gyros: slopes on the Earth's and the transport rate x +1.00, y +1.00, z +1.00" in rates
    t, still = np.arange(100.0), np.zeros((100, 3))
    down = SimpleNamespace(
        imu=SimpleNamespace(time=t, angular_rate_t=still, specific_force_t=np.tile([0.1, 0.0, -9.8], (100, 1)))
    )
    assert check_platform_axes(down, "strapdown") == []
    with pytest.raises(DataError, match=r"^imu: .* -9\.800 m/s\^2 \(after imu_axes\).*-z axis"):
        check_platform_axes(down, "platform")
    # the platform held level in a 45-degree turn: the third axis still reads g
    turn = SimpleNamespace(
        imu=SimpleNamespace(time=t, angular_rate_t=still, specific_force_t=np.tile([6.9, 0.0, 9.8], (100, 1)))
    )
    assert check_platform_axes(turn, "platform")[0].startswith("passed: platform axes")


def test_body_fixed_imu_declared_platform_names_the_triad_key(tmp_path):
    """The strapdown sample (grid_ros2) declared ``triad: platform``: its gyros bank with the
    aircraft in the turns, so the flight is refused before navigation, naming the gyro channel
    and ``flights[i].triad`` (before: "the navigation did not settle ... gyro bias", a wrong hint)."""
    import shutil

    src = Path(__file__).resolve().parents[1] / "sample_data" / "grid_ros2"
    dst = tmp_path / "g"
    shutil.copytree(src, dst)
    cfg_path = dst / "survey.yaml"
    cfg_path.write_text(cfg_path.read_text().replace("triad: strapdown", "triad: platform"))
    cfg = load_config(cfg_path, output_dir=tmp_path / "out")
    for fl in cfg.flights:
        with pytest.raises(DataError) as exc:
            process_flight(cfg, fl)
        msg = str(exc.value)
        assert "the platform triad turns about its horizontal axes at up to 1." in msg
        assert f"set flights[{fl.index}].triad: strapdown" in msg and "\n" not in msg


def test_platform_rate_check_needs_a_sustained_tilt():
    """Earth-rate gyros pass; 40 s of a 1 deg/s roll rate (a bank in and out) is a body-fixed
    IMU; 20 s of it (less than one turn) and a single 1-s spike are not."""
    from types import SimpleNamespace

    from gravsurvey.consistency import check_platform_axes

    t = np.arange(0.0, 1200.0, 0.1)
    f = np.tile([0.0, 0.0, 9.81], (t.size, 1))
    earth = np.tile([0.0, 5.0e-5, 5.0e-5], (t.size, 1))

    def rec(w):
        return SimpleNamespace(imu=SimpleNamespace(time=t, specific_force_t=f, angular_rate_t=w))

    assert check_platform_axes(rec(earth), "platform")[0].startswith("passed: platform axes")
    for seconds, refused in ((40.0, True), (20.0, False)):
        w = earth.copy()
        w[(t > 300) & (t < 300 + seconds), 0] = np.radians(1.0)
        if refused:
            with pytest.raises(DataError, match=r"^imu: the platform triad turns .*set triad: strapdown$"):
                check_platform_axes(rec(w), "platform")
        else:
            check_platform_axes(rec(w), "platform")
    spike = earth.copy()
    spike[(t > 500) & (t < 501), 1] = 1.0
    check_platform_axes(rec(spike), "platform")


def test_wrong_initial_position_names_the_key(tmp_path):
    """A configured ``initial`` that the data contradict is a config error naming the key (exit 2;
    inm.params.resolve_initial_state checks it against GNSS before anything is processed)."""
    cfg, fl = _flight(tmp_path, initial={"lat_deg": 60.5})
    with pytest.raises(ConfigError, match=r"flights\[0\]\.initial\.lat_deg: 60.5 deg is .* m from the GNSS"):
        process_flight(cfg, fl)
    cfg, fl = _flight(tmp_path / "h", initial={"height_m": 1500.0 / 0.3048})
    with pytest.raises(ConfigError, match=r"flights\[0\]\.initial\.height_m: 4921.2\d* m differs from the GNSS"):
        process_flight(cfg, fl)
    cfg, fl = _flight(tmp_path / "v", initial={"velocity_enu_mps": "[0.0, 60.0, 0.0]"})
    with pytest.raises(ConfigError, match=r"flights\[0\]\.initial\.velocity_enu_mps: \[0.000, 60.000, 0.000\]"):
        process_flight(cfg, fl)


# ----------------------------------------------------------------------------- result plausibility
def test_no_lines_is_an_error_unless_allowed(tmp_path):
    cfg, fl = _flight(tmp_path, extra="checks: {}\n")
    cfg.lines.min_line_s = 5000.0
    with pytest.raises(DataError, match="no survey lines found"):
        process_flight(cfg, fl)
    cfg.checks = CheckOptions(allow_no_lines=True)
    r = process_flight(cfg, fl)
    assert r.line_info == {}


def test_disturbance_and_track_limits(tmp_path):
    cfg, fl = _flight(tmp_path, extra="checks: {max_abs_disturbance_mgal: 10}\n")
    with pytest.raises(DataError, match=r"\|disturbance\| reaches .* expected at most 10 mGal"):
        process_flight(cfg, fl)
    cfg.checks = CheckOptions(max_track_deviation_m=0.5)
    with pytest.raises(DataError, match="navigation left the GNSS track"):
        process_flight(cfg, fl)


def test_a_few_gnss_outliers_are_not_a_navigation_off_track(tmp_path):
    t0 = 1741608000000000000

    def prep(p):  # 3 s of GNSS latitude 222 m off (multipath)
        d.edit(
            p,
            "gnss",
            lambda h, rows: [
                r if not (400 <= (int(r[0]) - t0) / 1e9 < 403) else [r[0], repr(float(r[1]) + 0.002)] + r[2:]
                for r in rows
            ],
        )

    cfg, fl = _flight(tmp_path, prep)
    r = process_flight(cfg, fl)
    note = next(n for n in r.estimator["checks_passed"] if "navigation within" in n)
    assert float(note.split("within ")[1].split(" m")[0]) < 20.0  # 7.4 m measured (running median)


def test_check_result_nonfinite(intact):
    import dataclasses

    r = intact
    est = dataclasses.replace(r, smoothed=r.smoothed.copy(), estimator={"gnss_aided": False})
    on = r.line != ""
    final = r.disturbance.copy()
    final[np.flatnonzero(on)[5]] = np.inf
    with pytest.raises(DataError, match="final disturbance has 1 non-finite"):
        check_result("F01", final, on, est, None, CheckOptions(), 1)
    est.smoothed[3] = np.nan
    with pytest.raises(DataError, match="kalman estimate has 1 non-finite"):
        check_result("F01", r.disturbance, on, est, None, CheckOptions(), 1)
    check_result("F01", final, on, est, None, CheckOptions(allow_nonfinite=True), 1)
    # a classic estimate names its series for what it is (no Kalman filter involved)
    cl = dataclasses.replace(
        r,
        method="classic",
        smoothed=None,
        forward=None,
        unfiltered=r.smoothed.copy(),
        sigma=np.full(len(r.time), np.nan),
        estimator={"gnss_aided": False},
    )
    cl.unfiltered[4] = np.nan
    with pytest.raises(DataError, match="unfiltered reduction has 1 non-finite"):
        check_result("F01", r.disturbance, on, cl, None, CheckOptions(), 1)


# ----------------------------------------------------------------------------- pieces
def test_specific_force_on_fixed_axes_undoes_the_triad_rotation():
    """A triad spinning about z at 3 deg/s and wobbling about x: f = (1, 0, 9.8) on fixed axes."""
    t = np.arange(0.0, 120.0, 0.01)
    yaw = np.radians(3.0) * t
    roll = np.radians(2.0) * np.sin(2 * np.pi * t / 7.0)
    rate_roll = np.radians(2.0) * 2 * np.pi / 7.0 * np.cos(2 * np.pi * t / 7.0)
    f_fixed = np.array([1.0, 0.0, 9.8])
    f_t = np.empty((len(t), 3))
    w_t = np.empty((len(t), 3))
    for k in range(len(t)):  # mat_pt = Rz(yaw) Rx(roll); f_t = mat_pt^T f_fixed
        cz, sz, cx, sx = np.cos(yaw[k]), np.sin(yaw[k]), np.cos(roll[k]), np.sin(roll[k])
        rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
        rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
        f_t[k] = (rz @ rx).T @ f_fixed
        # body rate of Rz(yaw) Rx(roll): rx^T [0, 0, yaw'] + [roll', 0, 0]
        w_t[k] = rx.T @ np.array([0, 0, np.radians(3.0)]) + np.array([rate_roll[k], 0, 0])
    _, f_p = specific_force_fixed_frame(t, f_t, w_t, 0.2)
    roll0 = np.array([[1, 0, 0], [0, np.cos(roll[0]), -np.sin(roll[0])], [0, np.sin(roll[0]), np.cos(roll[0])]])
    expect = roll0.T @ f_fixed  # the fixed frame is the triad's first attitude
    assert np.max(np.abs(f_p - expect)) < 2e-3
    # the smoothed magnitude is the true one (what the gravity check relies on)
    assert abs(np.linalg.norm(f_p.mean(axis=0)) - np.linalg.norm(f_fixed)) < 2e-4


def test_slice_record_and_plan(tmp_path):
    cfg, fl = _flight(tmp_path, lambda p: d.drop_between(p, "imu", 400, 460))
    with pytest.warns(DataWarning, match="imu: 1 gaps longer than the threshold: 400.000-460.000 s"):
        rec = load_flight(fl.ingest, cfg.base_dir)
    spans, _, dropped = plan_segments(rec, CheckOptions())
    assert len(spans) == 2 and dropped == []
    assert spans[0][1] == pytest.approx(400.0) and spans[1][0] == pytest.approx(460.0)
    sub = slice_record(rec, *spans[1], margin_s=2.0)
    assert sub.imu.time[0] >= 460.0 and sub.t0_unix_ns == rec.t0_unix_ns
    assert sub.gnss.time[0] >= 458.0 and sub.altimeter.time[-1] <= spans[1][1] + 2.0
    with pytest.raises(DataError, match="no piece of the flight between gaps is at least 60 s"):
        plan_segments(rec, CheckOptions(max_imu_gap_s=0.05))


def test_short_piece_between_gaps_is_data_loss(tmp_path):
    def prep(p):
        d.drop_between(p, "imu", 300, 330)
        d.drop_between(p, "imu", 360, 390)

    cfg, fl = _flight(tmp_path, prep)
    r = process_flight(cfg, fl)
    assert any("estimated 2 of 2 segments" in n for n in r.notes)
    assert len(r.data_loss) == 1 and "shorter than 60 s: not estimated" in r.data_loss[0]
    assert _rms_on_lines(r) < 7.0  # 5.5 mGal measured (two re-initialisations inside the line)


def test_concatenate_puts_a_nan_epoch_between_segments(intact):
    parts = []
    for a, b in ((0, 100), (150, 300)):
        n = b - a
        parts.append(
            FlightEstimate(
                name="F01",
                method="inm",
                t0_unix_ns=intact.t0_unix_ns,
                time=intact.time[a:b],
                lat=intact.lat[a:b],
                lon=intact.lon[a:b],
                height=intact.height[a:b],
                vel_n=np.zeros((n, 3)),
                speed=intact.speed[a:b],
                heading=np.zeros(n),
                disturbance=intact.smoothed[a:b],
                sigma=intact.sigma[a:b],
                smoothed=intact.smoothed[a:b],
                resolution_m=1000.0 * (1 + a),
                estimator={"gnss_aided": a == 0, "identification": {"k": a}},
            )
        )
    c = concatenate_estimates(parts)
    assert len(c.time) == 251 and np.isnan(c.smoothed[100]) and c.segment[100] == -1
    assert np.isnan(c.disturbance[100]) and np.isnan(c.vel_n[100]).all()
    np.testing.assert_array_equal(c.segment[:100], 0)
    np.testing.assert_array_equal(c.segment[101:], 1)
    np.testing.assert_array_equal(c.smoothed[101:], intact.smoothed[150:300])
    assert np.all(np.diff(c.time) > 0)
    # no piece had a forward filter or horizontal components: still absent
    assert c.forward is None and c.dg_north is None and c.horizontal_observable is None
    assert c.resolution_m == 151000.0  # the coarsest piece's
    assert c.estimator["gnss_aided"] is True
    assert c.estimator["identification"] == {"segments": [{"k": 0}, {"k": 150}]}


def test_checks_config_keys(tmp_path):
    with pytest.raises(ConfigError, match=r"checks\.max_imu_gap: unknown key \(did you mean 'max_imu_gap_s'"):
        _flight(tmp_path / "a", extra="checks: {max_imu_gap: 3}\n")
    with pytest.raises(ConfigError, match=r"checks\.allow_no_lines: expected true or false"):
        _flight(tmp_path / "b", extra="checks: {allow_no_lines: 1}\n")
    with pytest.raises(ConfigError, match=r"checks\.max_time_offset_s: expected a number > 0"):
        _flight(tmp_path / "c", extra="checks: {max_time_offset_s: -1}\n")


# ----------------------------------------------------------------------------- the CLI
def test_cli_exit_codes(tmp_path):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    cfg = d.copy_sample(tmp_path / "clock")
    d.shift_after(tmp_path / "clock", -1, 3600, names=("imu",))
    p = subprocess.run(
        [sys.executable, "-m", "gravsurvey", "run", str(cfg), "-o", str(tmp_path / "o1")],
        check=False,
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
        stdin=subprocess.DEVNULL,
    )
    assert p.returncode == 1, p.stderr
    assert "do not overlap" in p.stderr and "Traceback" not in p.stderr
    cfg = d.copy_sample(tmp_path / "gap")
    d.shift_after(tmp_path / "gap", 480, 1800)
    p = subprocess.run(
        [sys.executable, "-m", "gravsurvey", "run", str(cfg), "-o", str(tmp_path / "o2")],
        check=False,
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
        stdin=subprocess.DEVNULL,
    )
    assert p.returncode == 0, p.stderr
    assert (tmp_path / "o2" / "profiles.csv").is_file()


def test_one_absurd_csv_value_is_dropped_and_the_flight_processes(tmp_path, intact):
    """Measured before: one specific force of 2.6e21 m/s^2 in markov_csv's imu.csv gave
    'internal error ZeroDivisionError' in the mechanization."""

    def prep(p):
        d.edit(p, "imu", lambda h, rows: [r if i != 5000 else [r[0], "2.6e21"] + r[2:] for i, r in enumerate(rows)])

    cfg, fl = _flight(tmp_path, prep)
    r = process_flight(cfg, fl)
    assert any("imu: dropped 1 samples with empty, NaN/inf or absurd" in n for n in r.notes)
    assert abs(_rms_on_lines(r) - _rms_on_lines(intact)) < 0.2


def test_held_gnss_fixes_and_a_stale_imu_are_dropped_and_the_flight_processes(tmp_path):
    """20 s of GNSS fixes held (a receiver repeating its last position) refused the flight as 'the
    navigation left the GNSS track by 165 m'; 5 s of a repeated IMU message failed a strapdown
    flight with 4918 mGal (fuzzing, 2026-12-04). Both are dropped, named, and left as gaps."""

    def prep(p):
        d.hold_between(p, "gnss", 400, 420)
        d.hold_between(p, "imu", 300, 310)

    cfg, fl = _flight(tmp_path, prep)
    r = process_flight(cfg, fl)
    said = [n for n in r.notes if "(a stalled receiver or logger)" in n]
    assert any("gnss.csv): dropped 20 sample(s) in 1 run(s) that repeat the previous position" in n for n in said)
    assert any("imu.csv): dropped 100 sample(s) in 1 run(s) that repeat all six values" in n for n in said)
    # the IMU's 10-s hole is longer than checks.max_imu_gap_s: two segments, 6.4 mGal measured
    assert any("estimated 2 of 2 segments" in n for n in r.notes)
    assert _rms_on_lines(r) < 7.0


def test_an_accelerometer_at_its_range_is_named_and_its_velocity_left_to_the_aiding(tmp_path, intact):
    """The sample's north accelerometer clipped at 2 m/s^2 in its turn (206 samples): the filter
    had read the clipped velocity as gravity, 8.16 mGal (intact 3.45) with nothing said; now the
    samples are named and the velocity over them is left to the GNSS and heights: 3.66 (intact
    3.29; 3.72 and 3.44 before the vertical channel's constant was taken off)."""
    cfg, fl = _flight(tmp_path, lambda p: d.map_columns(p, "imu", {"fy_mps2": lambda x: np.clip(x, -2.0, 2.0)}))
    rec = load_flight(fl.ingest, cfg.base_dir)
    assert rec.imu.saturated is not None and rec.imu.saturated.sum() == 206
    r = process_flight(cfg, fl)
    assert any("imu: specific_force y held at -2, 2 m/s^2" in n and "206 samples" in n for n in r.notes)
    assert _rms_on_lines(r) < 1.15 * _rms_on_lines(intact)


def test_imu_gap_noise_covers_gaps_and_saturated_samples_once_per_epoch():
    from gravsurvey.inm.solve import imu_gap_noise, missed_accel_sigma

    S = 0.3  # m/s^2
    t = np.arange(100) * 0.1
    t[55:] += 1.0  # a 1.1-s step: 1.0 s more than the nominal
    idx = np.arange(0, 100, 10)  # epochs at samples 0, 10, ..., 90
    assert imu_gap_noise(np.arange(100) * 0.1, idx, None, S) is None
    var = imu_gap_noise(t, idx, None, S)
    np.testing.assert_allclose(var, np.where(np.arange(10) == 6, (S * 1.0) ** 2, 0.0))
    sat = np.zeros(100, bool)
    sat[21:25] = True  # four samples at the range: their four steps of 0.1 s, one error
    var = imu_gap_noise(t, idx, sat, S)
    np.testing.assert_allclose(var[3], (S * 0.4) ** 2)
    assert var[6] == pytest.approx(S**2) and np.count_nonzero(var) == 2
    # an IMU whose rate halved within the record: no gaps at the lower rate
    halved = np.concatenate([np.arange(50) * 0.1, 4.9 + np.arange(1, 26) * 0.2])
    assert imu_gap_noise(halved, np.arange(0, 75, 5), None, S) is None
    # the specific force a straight line misses: the record's departure from its 1-s running mean
    rng = np.random.default_rng(1)
    tt = np.arange(20_000) * 0.02
    calm = np.column_stack([np.zeros(tt.size), np.sin(tt / 60.0), np.full(tt.size, 9.8)])
    assert missed_accel_sigma(tt, calm) < 1e-4
    rough = calm + np.column_stack([np.zeros(tt.size), np.zeros(tt.size), rng.normal(0.0, 0.5, tt.size)])
    assert missed_accel_sigma(tt, rough) == pytest.approx(0.5 * np.sqrt(1 - 1 / 50), rel=0.03)
