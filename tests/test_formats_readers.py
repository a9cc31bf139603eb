"""Readers for DGS, BGM-3, NMEA, ZLS, AT1A and GNSS trajectory files.

DGS, BGM-3 and NMEA fixtures are written here in the formats' layouts with our own values (the
real examples are GPL-3.0 and only read by benchmarks/check_vendor_formats.py).  ZLS, AT1A and
trajectory use DGP's Apache-2.0 samples (tests/data/formats/dgp) and DGP's expected values.
"""

import calendar
import datetime
from pathlib import Path

import numpy as np
import pytest

from gravsurvey.errors import ConfigError, DataError
from gravsurvey.io.formats import (
    read_at1a,
    read_bgm_rgs,
    read_bgm_serial,
    read_dgs_laptop,
    read_dgs_raw,
    read_nmea,
    read_trajectory,
    read_zls,
)
from gravsurvey.io.formats.common import gps_to_unix_ns, parse_logger_stamp, week_sow_to_unix_ns

DGP = Path(__file__).parent / "data" / "formats" / "dgp"
MGAL = 1e-5
NS = 10**9


def unix_ns(y, mo, d, h=0, mi=0, s=0.0):
    return calendar.timegm((y, mo, d, h, mi, 0)) * NS + int(round(s * NS))


def civil(t_ns):
    """Unix ns -> naive UTC datetime (microseconds)."""
    return datetime.datetime(1970, 1, 1) + datetime.timedelta(microseconds=int(t_ns) // 1000)


def iso(t_ns):
    return civil(t_ns).isoformat(timespec="microseconds")


# ----------------------------------------------------------------------------- NMEA fixtures
def nmea(body: str) -> str:
    cs = 0
    for ch in body:
        cs ^= ord(ch)
    return f"${body}*{cs:02X}"


def dm(x, deg_digits):
    """Decimal degrees -> NMEA ddmm.mmmmmm and hemisphere."""
    a = abs(x)
    d = int(a)
    return f"{d:0{deg_digits}d}{(a - d) * 60:09.6f}"


def nav_lines(t0_ns, n, lat0, lon0, ve, vn, prefix_style, talker="GP"):
    """GGA/RMC/VTG at 1 Hz for a constant-velocity track; returns (lines, truth dict)."""
    lines, truth = [], {"t": [], "lat": [], "lon": []}
    for k in range(n):
        t = t0_ns + k * NS
        lat = lat0 + vn * k / 111_000.0
        lon = lon0 + ve * k / (111_000.0 * np.cos(np.radians(lat0)))
        lon = (lon + 180) % 360 - 180
        tm = civil(t)
        hms = f"{tm.hour:02d}{tm.minute:02d}{tm.second:02d}.00"
        ddmmyy = f"{tm.day:02d}{tm.month:02d}{tm.year % 100:02d}"
        la, ns_ = dm(lat, 2), "N" if lat >= 0 else "S"
        lo, ew = dm(lon, 3), "E" if lon >= 0 else "W"
        speed_kn = np.hypot(ve, vn) / (1852 / 3600)
        course = np.degrees(np.arctan2(ve, vn)) % 360
        sent = [
            nmea(f"{talker}GGA,{hms},{la},{ns_},{lo},{ew},2,10,0.9,12.50,M,-30.00,M,,"),
            nmea(f"{talker}RMC,{hms},A,{la},{ns_},{lo},{ew},{speed_kn:.2f},{course:.2f},{ddmmyy},,,D"),
            nmea(f"{talker}VTG,{course:.2f},T,,M,{speed_kn:.2f},N,{speed_kn * 1.852:.2f},K,D"),
            nmea("PSXN,20,0,0,0,0"),
        ]
        stamp_ns = t + 250_000_000  # the logger writes 0.25 s after the fix
        st = civil(stamp_ns)
        for s in sent:
            if prefix_style == "none":
                lines.append(s)
            elif prefix_style == "iso":
                lines.append(f"{iso(stamp_ns)}Z {s}")
            elif prefix_style == "unix":
                lines.append(f"{stamp_ns / NS:.3f} {s}")
            elif prefix_style == "mdy":
                lines.append(f"{st.month:02d}/{st.day:02d}/{st.year},{st.strftime('%H:%M:%S.%f')[:-3]},{s}")
        truth["t"].append(t)
        truth["lat"].append(lat)
        truth["lon"].append(lon)
    return lines, {k: np.array(v) for k, v in truth.items()}


@pytest.mark.parametrize("style", ["none", "iso", "unix", "mdy"])
def test_nmea_positions_and_times(tmp_path, style):
    t0 = unix_ns(2023, 1, 20, 23, 59, 55)  # crosses midnight
    lines, truth = nav_lines(t0, 10, -75.33, 179.9995, ve=5.0, vn=1.0, prefix_style=style, talker="IN")
    p = tmp_path / "nav.txt"
    p.write_text("\n".join(lines) + "\n")
    tb = read_nmea(p)
    assert len(tb) == 10 and tb.n_skipped == 0
    np.testing.assert_array_equal(tb.time_ns, truth["t"])
    # ddmm.mmmmmm: 1e-6 minute = 2e-8 deg
    assert np.abs(np.degrees(tb.columns["lat"]) - truth["lat"]).max() < 2e-8
    dlon = (np.degrees(tb.columns["lon"]) - truth["lon"] + 180) % 360 - 180
    assert np.abs(dlon).max() < 2e-8
    assert np.allclose(tb.columns["height"], 12.5 - 30.0)
    assert np.allclose(tb.columns["speed"], np.hypot(5, 1), atol=0.01)
    assert np.allclose(tb.columns["course"], np.arctan2(5, 1), atol=1e-3)
    assert tb.meta["ignored_sentences"] == {"PSXN": 10}
    if style != "none":
        assert tb.meta["logger_minus_fix_s"] == pytest.approx(0.25, abs=1e-3)
        tl = read_nmea(p, time_source="logger")
        np.testing.assert_array_equal(tl.time_ns - truth["t"], np.full(10, 250_000_000))


def test_nmea_damage_counted(tmp_path):
    lines, truth = nav_lines(unix_ns(2022, 7, 1, 12), 20, 41.5, -70.6, 3, 0, "iso")
    gga = [i for i, s in enumerate(lines) if "GGA" in s]
    lines[gga[3]] = lines[gga[3]].replace("4130.", "4131.", 1)  # a changed digit: checksum fails
    lines[gga[5]] = lines[gga[5]][:-2] + "00"  # wrong checksum
    lines[gga[7]] = lines[gga[7]][:40]  # truncated: no checksum, too few fields
    lines[gga[9]] = nmea(lines[gga[9]].split("$")[1].split("*")[0].replace(",2,10,", ",0,10,"))  # no fix
    lines.insert(gga[11], "%%% modem noise %%%")
    p = tmp_path / "nav.txt"
    p.write_text("\n".join(lines) + "\n")
    tb = read_nmea(p)
    assert tb.skipped == {
        "GGA checksum mismatch": 2,
        "damaged GGA sentence (GGA has fewer than 10 fields)": 1,
        "GGA fix quality 0 (no fix)": 1,
        "no NMEA sentence": 1,
    }
    assert len(tb) == 16
    keep = np.setdiff1d(np.arange(20), [3, 5, 7, 9])
    np.testing.assert_array_equal(tb.time_ns, truth["t"][keep])
    assert any("line " in n and "checksum" in n for n in tb.notes)


def test_nmea_refuses_other_files(tmp_path):
    p = tmp_path / "imu.csv"
    p.write_text("time_ns,fx\n" + "\n".join(f"{i},1.0" for i in range(20)) + "\n")
    with pytest.raises(DataError, match=r"imu\.csv: not a NMEA file: 0 of 21 .* line 1"):
        read_nmea(p)
    p = tmp_path / "undated.txt"
    p.write_text(nmea("GPGGA,120000.00,4130.0,N,07040.0,W,1,8,1.0,5.0,M,-30.0,M,,") + "\n")
    with pytest.raises(DataError, match="cannot be dated"):
        read_nmea(p)
    with pytest.raises(ConfigError, match="time_source"):
        read_nmea(p, time_source="gps")


# ----------------------------------------------------------------------------- DGS fixtures
def laptop_line(t_ns, grav, lat, lon, ve=0.5, speed_kn=11.0, course=270.0):
    tm = civil(t_ns)
    f = [
        grav - 500.0,
        grav,
        -0.5,
        -0.6,
        0.003,
        53.37,
        20814,
        5403321,
        31.1,
        50.1,
        ve,
        -0.0018,
        0.1,
        0.25,
        lat,
        lon,
        speed_kn,
        course,
        0.32,
    ]
    body = ",".join(f"{x:.12f}" if isinstance(x, float) else f"{x:16d}" for x in f)
    return (
        body
        + f",{tm.year},{tm.month:02d},{tm.day:02d},{tm.hour:02d},{tm.minute:02d},{tm.second:02d}.{tm.microsecond // 10000:02d},{int(t_ns // NS) % 10**7}"
    )


def test_dgs_laptop_plain_and_prefixed(tmp_path):
    t0 = unix_ns(2019, 7, 11)
    g = 12295.0 + np.arange(30) * 0.25
    rows = [laptop_line(t0 + k * NS, g[k], 48.07, -10.3 - k * 1e-4) for k in range(30)]
    p = tmp_path / "DGS.dat"
    p.write_text("\n".join(rows) + "\n")
    tb = read_dgs_laptop(p)
    assert len(tb) == 30 and tb.n_skipped == 0 and tb.meta["time_source"] == "meter"
    np.testing.assert_array_equal(tb.time_ns, t0 + np.arange(30) * NS)
    assert np.allclose(tb.columns["gravity"] / MGAL, g, atol=1e-9)
    assert np.allclose(tb.columns["speed"], 11.0 * 1852 / 3600)
    assert np.allclose(np.degrees(tb.columns["course"]), 270.0)
    assert np.allclose(np.degrees(tb.columns["lon"]), -10.3 - np.arange(30) * 1e-4)
    assert tb.columns["ve"][0] == 0.5
    # logger prefix (tab, ISO) and a header block, meter clock 12.5 s behind the logger
    hdr = ["# Platform:", "#   Name: R/V Test", "# Parameters:", "#"]
    pre = [f"grav_dgs_proc\t{iso(t0 + k * NS + 12_500_000_000)}Z\t{r}" for k, r in enumerate(rows)]
    pre[7] = pre[7][:80]  # cut line
    pre[9] = pre[9].replace(",2019,", ",2019x,")
    p2 = tmp_path / "SKQ_proc"
    p2.write_text("\n".join(hdr + pre) + "\n")
    tb2 = read_dgs_laptop(p2)
    assert len(tb2) == 28 and tb2.n_skipped == 2 and tb2.n_lines == 30
    assert tb2.meta["logger_minus_meter_s"] == pytest.approx(12.5)
    tl = read_dgs_laptop(p2, time_source="logger")
    assert tl.time_ns[0] == t0 + 12_500_000_000
    # a comma-separated US-date logger prefix (Thompson style) and no GNSS (0/0)
    rows0 = [laptop_line(t0 + k * NS, 9995.9, 0.0, 0.0) for k in range(3)]
    p3 = tmp_path / "TN_proc.Raw"
    p3.write_text("\n".join(f"07/11/2019,00:00:0{k}.033,{r}" for k, r in enumerate(rows0)) + "\n")
    tb3 = read_dgs_laptop(p3)
    assert np.isnan(tb3.columns["lat"]).all() and any("0/0" in n for n in tb3.notes)
    assert tb3.meta["logger_minus_meter_s"] == pytest.approx(0.033)


def test_dgs_laptop_refuses_other_files(tmp_path):
    p = tmp_path / "nav.txt"
    p.write_text(nmea("GPGGA,120000.00,4130.0,N,07040.0,W,1,8,1.0,5.0,M,-30.0,M,,") + "\n")
    with pytest.raises(DataError, match=r"nav\.txt: not a DGS laptop file: 0 of 1 .* line 1"):
        read_dgs_laptop(p)
    with pytest.raises(ConfigError):
        read_dgs_laptop(p, time_source="gps")


def raw_line(counter, grav_counts, stamp):
    return f"$AT1M_3.64_{counter},{grav_counts},1208,-578,4008935,273,498,202,7687710,425,277,-224,266,4061549,0.0000000000,0.0000000000,0.0000,0.0000,{stamp}"


def test_dgs_raw_serial(tmp_path):
    t0 = unix_ns(2023, 6, 16)
    lines = [
        f"{iso(t0 + k * NS + 857719000)}Z {raw_line(198247 + k, -218747 + 10 * k, 1686873601 + k)}" for k in range(10)
    ]
    lines[4] = lines[4].replace(",1208,", ",12x8,")
    lines.append(lines[5].replace("\x00", "") + "\x00")
    p = tmp_path / "raw.txt"
    p.write_bytes(("\n".join(lines) + "\n").encode())
    tb = read_dgs_raw(p)
    assert len(tb) == 10 and tb.n_skipped == 1
    assert tb.meta["time_source"] == "logger" and tb.time_ns[0] == t0 + 857719000
    assert tb.columns["gravity"][0] == -218747 and tb.columns["vcc"][0] == 7687710
    assert tb.units["gravity"] == "counts" and np.isnan(tb.columns["lat"]).all()
    assert any("NUL" in n for n in tb.notes)
    # a synchronised meter clock (yyyymmddhhmmss) is used without a logger
    p2 = tmp_path / "raw2.txt"
    p2.write_text("\n".join(raw_line(k, 5, f"20230616000{k:03d}"[:14]) for k in range(3)) + "\n")
    tb2 = read_dgs_raw(p2)
    assert tb2.meta["time_source"] == "meter" and tb2.time_ns[1] - tb2.time_ns[0] == NS


# ----------------------------------------------------------------------------- BGM-3
def test_bgm_serial_and_rgs(tmp_path):
    lines = [
        "BGM 2022/07/01 12:17:33.492 BGM3 04:024963 00",
        "vc01\t2020:244:00:00:00.3244\t04:025229 00",
        "2022-11-07T17:13:45.329611Z 04:024882 00",
        "03/13/2022,00:00:02.449,04:025529 00",
        "BGM 2022/07/01 12:17:34.492 BGM3 04:02 00",
        "04:024963 00",
    ]
    p = tmp_path / "bgm.txt"
    p.write_text("\n".join(lines) + "\n")
    tb = read_bgm_serial(p, scale_mgal_per_count=5.0)
    assert len(tb) == 4 and tb.n_skipped == 2
    np.testing.assert_array_equal(tb.columns["counts"], [24963, 25229, 24882, 25529])
    assert tb.columns["gravity"][1] / MGAL == pytest.approx(126145.0)
    assert tb.time_ns[0] == unix_ns(2022, 7, 1, 12, 17, 33.492)
    assert tb.time_ns[1] == unix_ns(2020, 8, 31, 0, 0, 0.3244)  # day 244 of a leap year
    with pytest.raises(ConfigError, match="scale_mgal_per_count"):
        read_bgm_serial(p, scale_mgal_per_count=-1)
    rgs = "RGS 2022/07/01 00:00:00.445 980329.272 24980 1656633600.445 4.99 855577.39 BGM3 S210 GPS: 41.523386 -70.671852 1656633599.533 0 0 X"
    p2 = tmp_path / "bgm.RGS"
    p2.write_text(rgs + "\n\n" + rgs.replace("00:00:00.445", "00:00:01.445") + "\n")
    t2 = read_bgm_rgs(p2)
    assert len(t2) == 2 and t2.time_ns[0] == unix_ns(2022, 7, 1, 0, 0, 0.445)
    assert t2.columns["gravity"][0] / MGAL == pytest.approx(980329.272)
    assert np.degrees(t2.columns["lat"][0]) == pytest.approx(41.523386)
    with pytest.raises(DataError, match=r"bgm\.txt: not a bgm_rgs file"):
        read_bgm_rgs(p)


# ----------------------------------------------------------------------------- ZLS (DGP data)
def test_zls_matches_dgp():
    tb = read_zls(DGP / "sample_zls")
    assert len(tb) == 180 and tb.n_skipped == 0 and tb.meta["line_names"] == ["FLIGHT3"]
    # DGP tests/test_gravity_ingestor.py::test_import_zls, row 20 of the hour files
    want = [12754.71, 12747.7, 0.3, -375.8, -1.0, 0.0, -14.0, 5.0, -2.0, 57.0, 4.0, 128.0, -15.0, 34.0]
    names = [
        "gravity",
        "spring_tension",
        "cross_coupling",
        "beam",
        "vcc",
        "al",
        "ax",
        "ve2",
        "ax2",
        "xacc2",
        "lacc2",
        "xacc",
        "lacc",
        "platform_period",
    ]
    got = [tb.columns[c][20] / (MGAL if tb.units[c] == "m/s^2" else 1.0) for c in names]
    assert got == pytest.approx(want, abs=1e-9)
    assert tb.meta["par_port"] == "FFFFFF"
    # 2015 day 316 = 2015-11-12, first line 00:00:01; the second hour file starts at 01:00:01
    assert tb.time_ns[0] == unix_ns(2015, 11, 12, 0, 0, 1)
    assert tb.time_ns[120] == unix_ns(2015, 11, 12, 1, 0, 1)


def test_zls_damage(tmp_path):
    src = (DGP / "sample_zls" / "2015_00.316").read_bytes().decode().splitlines()
    src[5] = src[5][:50]
    src[6] = src[6][:30] + "x" + src[6][31:]
    p = tmp_path / "2015_00.316"
    p.write_text("\n".join(src) + "\n")
    tb = read_zls(p)
    assert len(tb) == 118 and tb.n_skipped == 2
    with pytest.raises(DataError, match=r"sample_trajectory\.txt: not a ZLS file: 0 of 11 .* line 1: line length"):
        read_zls([DGP / "sample_trajectory.txt"])
    (tmp_path / "empty").mkdir()
    with pytest.raises(DataError, match="no ZLS files"):
        read_zls(tmp_path / "empty")


# ----------------------------------------------------------------------------- AT1A, trajectory
def test_at1a_matches_dgp():
    tb = read_at1a(DGP / "sample_gravity.csv")
    # DGP test_import_at1a_no_fill_nans: row 4 (one sample missing before it, not invented here)
    assert len(tb) == 9
    assert tb.columns["gravity"][4] / MGAL == pytest.approx(10061.171360, abs=1e-9)
    assert tb.columns["long_accel"][4] == pytest.approx(-0.026226)
    assert tb.columns["status"][4] == 21061
    # GPS week 1959, SOW 219697.3 (GPS) = 2017-07-25 13:01:19.3 UTC (18 leap seconds)
    assert tb.time_ns[0] == unix_ns(2017, 7, 25, 13, 1, 19.3)
    assert np.diff(tb.time_ns).max() == 200_000_000


def test_trajectory_matches_dgp():
    a = read_trajectory(DGP / "sample_trajectory.txt")
    b = read_trajectory(DGP / "sample_trajectory_week-sow.txt")
    # DGP test_trajectory_ingestor: row 10 lat/lon to 1e-10 deg
    assert np.degrees(a.columns["lat"][9]) == pytest.approx(76.5350241071, abs=1e-10)
    assert np.degrees(a.columns["lon"][9]) == pytest.approx(-68.7218956324, abs=1e-10)
    # the two files are the same positions: GPS date/time and GPS week/SOW give the same UTC
    np.testing.assert_array_equal(a.time_ns, b.time_ns)
    assert a.time_ns[0] == unix_ns(2017, 3, 22, 9, 58, 59.2) - 18 * NS
    assert a.meta["time_system"] == "gps" and a.columns["height"][0] == 82.779


def test_trajectory_errors(tmp_path):
    p = tmp_path / "t.txt"
    p.write_text("a,b,c\n1,2,3\n")
    with pytest.raises(DataError, match=r"t\.txt: line 1: not a trajectory header .*missing lat, lon"):
        read_trajectory(p)
    p.write_text("time,lat,lon\n1,2,3\n")
    with pytest.raises(DataError, match="date\\+time or week\\+sow"):
        read_trajectory(p)
    p.write_text("date time lat lon h_ell\n2020-01-01 00:00:00.5 10 20 30\n2020-01-01 00:00:01.5 10 20\n")
    tb = read_trajectory(p)
    assert len(tb) == 1 and tb.n_skipped == 1 and tb.meta["time_system"] == "utc"
    assert tb.time_ns[0] == unix_ns(2020, 1, 1, 0, 0, 0.5)


def test_time_helpers():
    assert parse_logger_stamp("23+013:00:00:00.113 ")[0] == unix_ns(2023, 1, 13, 0, 0, 0.113)
    assert parse_logger_stamp("seapath\t2020:244:00:00:00.6212\t")[1] == "year_doy"
    assert parse_logger_stamp("no stamp here") is None
    # leap second table: GPS-UTC 13 s in 2000, 18 s in 2020
    assert week_sow_to_unix_ns(1042, "0") == unix_ns(1999, 12, 26) - 13 * NS
    assert gps_to_unix_ns((unix_ns(2020, 1, 1) - 315964800 * NS) + 18 * NS) == unix_ns(2020, 1, 1)


# ----------------------------------------------------------------------------- damage fuzz
def _fixtures(tmp_path):
    """One small valid file per reader: (reader, bytes)."""
    lines, _ = nav_lines(unix_ns(2022, 7, 1, 12), 8, 41.5, -70.6, 3, 0, "iso")
    t0 = unix_ns(2019, 7, 11)
    lap = [laptop_line(t0 + k * NS, 12295.0, 48.07, -10.3) for k in range(8)]
    raw = [f"{iso(t0 + k * NS)}Z {raw_line(k, 5, 1)}" for k in range(8)]
    bgm = [f"BGM 2022/07/01 12:17:3{k}.492 BGM3 04:0249{k}3 00" for k in range(8)]
    m77 = (Path(__file__).parent / "data" / "formats" / "nbp9908_part.m77t").read_text().splitlines()[:9]
    return [
        (read_nmea, "\n".join(lines).encode()),
        (read_dgs_laptop, "\n".join(lap).encode()),
        (read_dgs_raw, "\n".join(raw).encode()),
        (read_bgm_serial, "\n".join(bgm).encode()),
        (read_at1a, (DGP / "sample_gravity.csv").read_bytes()),
        (read_trajectory, (DGP / "sample_trajectory.txt").read_bytes()),
        (read_zls, (DGP / "sample_zls" / "2015_00.316").read_bytes()[:2000]),
        (__import__("gravsurvey.io.formats", fromlist=["read_mgd77t"]).read_mgd77t, "\n".join(m77).encode()),
    ]


def test_damaged_files_give_data_error_or_a_table(tmp_path):
    """Random truncations, byte flips and insertions: a FormatTable or a DataError, nothing else."""
    rng = np.random.default_rng(7)
    for reader, data in _fixtures(tmp_path):
        p = tmp_path / f"f_{reader.__name__}"
        p.write_bytes(data)
        assert len(reader(p)) > 0  # the intact fixture reads
        for _ in range(40):
            b = bytearray(data)
            op = rng.integers(3)
            if op == 0:
                b = b[: rng.integers(0, len(b))]
            elif op == 1:
                for i in rng.integers(0, len(b), size=rng.integers(1, 8)):
                    b[i] = int(rng.integers(0, 256))
            else:
                i = int(rng.integers(0, len(b)))
                b[i:i] = bytes(rng.integers(0, 256, size=int(rng.integers(1, 20))).astype(np.uint8))
            p.write_bytes(bytes(b))
            try:
                tb = reader(p)
            except DataError:
                continue
            assert len(tb.time_ns) == len(next(iter(tb.columns.values())))


def test_nmea_gga_only_dated_by_the_logger_across_midnight(tmp_path):
    # Thompson-style: GGA only, the date comes from the logger stamp, which runs 0.6 s behind
    # the fix clock across midnight
    lines = []
    for k, (stamp, hms) in enumerate(
        (
            ("03/12/2022,23:59:58.900", "235959.50"),
            ("03/12/2022,23:59:59.900", "000000.50"),
            ("03/13/2022,00:00:00.900", "000001.50"),
        )
    ):
        lines.append(f"{stamp},{nmea(f'INGGA,{hms},3217.33152,N,11839.14935,W,5,26,0.8,0.19,M,,,7,1015')}")
    p = tmp_path / "POSMV.Raw"
    p.write_text("\n".join(lines) + "\n")
    tb = read_nmea(p)
    want = unix_ns(2022, 3, 12, 23, 59, 59.5) + np.arange(3) * NS
    np.testing.assert_array_equal(tb.time_ns, want)
    assert tb.meta["logger_minus_fix_s"] == pytest.approx(-0.6)
    assert np.isnan(tb.columns["height"]).all() and any("no geoid separation" in n for n in tb.notes)
