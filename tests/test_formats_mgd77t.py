"""MGD77T reader, normal gravity formulas, free-air anomaly and Eotvos against NCEI's values.

Data: the real cruise NBP9908 (public domain; tests/data/formats/NOTE.md), the last 3,607 of its
29,607 records.  NCEI's FREEAIR = GRA_OBS - IGF1967 normal gravity, both rounded to 0.1 mGal;
its EOTVOS is the supplier's correction from its own (smoothed) navigation.
"""

from pathlib import Path

import numpy as np
import pytest

from gravsurvey.errors import DataError
from gravsurvey.io.formats import read_mgd77t, read_mgd77t_header
from gravsurvey.io.formats.mgd77t import GRAVITY_FORMULA_CODES
from gravsurvey.marine import eotvos_from_track, free_air_anomaly

DATA = Path(__file__).parent / "data" / "formats"
M77T = DATA / "nbp9908_part.m77t"
MGAL = 1e-5


@pytest.fixture(scope="module")
def cruise():
    return read_mgd77t(M77T)


def test_reads_every_record(cruise):
    assert len(cruise) == 3607
    assert cruise.n_skipped == 0
    assert cruise.meta["survey_id"] == "NBP9908"
    g = np.isfinite(cruise.columns["gra_obs"])
    assert g.sum() == 3592
    # 1-minute records, in time order, 1999
    dt = np.diff(cruise.time_ns)
    assert np.median(dt) == 60 * 10**9 and (dt > 0).all()
    assert 1999 == np.datetime64(int(cruise.time_ns[0]), "ns").astype("datetime64[Y]").astype(int) + 1970
    # first record of the excerpt: 19990905 1758 (file line 26002): -44.26/...; check the stamp
    first = Path(M77T).read_text().splitlines()[1].split("\t")
    t = np.datetime64(f"{first[2][:4]}-{first[2][4:6]}-{first[2][6:]}T{first[3][:2]}:{first[3][2:4]}", "ns")
    assert cruise.time_ns[0] == t.astype(np.int64)
    assert cruise.columns["lat"][0] == pytest.approx(np.radians(float(first[4])), abs=1e-12)
    # the excerpt crosses the dateline: longitudes stay in the file's (-180, 180]
    lon = np.degrees(cruise.columns["lon"])
    assert (np.abs(np.diff(lon)) > 180).sum() == 1
    assert cruise.units["gra_obs"] == "m/s^2" and cruise.units["lat"] == "rad"


def test_free_air_igf1967_matches_ncei_to_rounding(cruise):
    c = cruise.columns
    g = np.isfinite(c["gra_obs"])
    d = (free_air_anomaly(c["gra_obs"], c["lat"], 0.0, "IGF1967") - c["freeair"])[g] / MGAL
    # two values rounded to 0.1 mGal each: |d| <= 0.1 up to the formula's last digits
    # (measured on this excerpt: median 0.004, max 0.103, 5-95 % -0.064..0.072 mGal)
    assert np.abs(d).max() <= 0.105
    assert abs(np.median(d)) < 0.01
    p5, p95 = np.percentile(d, [5, 95])
    assert -0.08 < p5 and p95 < 0.08
    # the other formulas are off by 0.7-0.9 mGal: the check tells which one a supplier used
    for formula, lo, hi in (("GRS80", -0.95, -0.8), ("WGS84", -0.82, -0.65)):
        dd = (free_air_anomaly(c["gra_obs"], c["lat"], 0.0, formula) - c["freeair"])[g] / MGAL
        assert lo < np.median(dd) < hi, formula


def test_eotvos_from_navigation_matches_ncei(cruise):
    c = cruise.columns
    t, _ = cruise.time_s()
    e = eotvos_from_track(t, c["lat"], c["lon"], max_gap_s=90.0) / MGAL
    d = (e - c["eotvos"] / MGAL)[np.isfinite(c["eotvos"]) & np.isfinite(e)]
    assert d.size > 3400
    # measured on this excerpt: median -0.06, 5-95 % -1.29..+2.18 mGal at a ~58 mGal correction
    # (NCEI's column comes from the supplier's smoothed navigation, ours from 1-min positions)
    assert abs(np.median(d)) < 0.2
    p5, p95 = np.percentile(d, [5, 95])
    assert -1.6 < p5 < 0 < p95 < 2.5
    assert np.median(np.abs(c["eotvos"][np.isfinite(c["eotvos"])])) / MGAL > 50


def test_header_file():
    h = read_mgd77t_header(DATA / "nbp9908.h77t")
    assert h["SURVEY_ID"] == "NBP9908" and h["PLATFORM"] == "Nathaniel B. Palmer"
    assert GRAVITY_FORMULA_CODES["3"] == "IGF1967"


def _copy(tmp_path, lines, name="x.m77t"):
    p = tmp_path / name
    p.write_text("\n".join(lines) + "\n")
    return p


def test_damaged_lines_counted_and_skipped(tmp_path):
    lines = M77T.read_text().splitlines()[:201]
    lines[50] = "NBP9908\t0\t1999O905\t1758\t-44\t-170"  # letter O in the date
    lines[60] = lines[60][: len(lines[60]) // 3]  # cut line
    lines[70] = lines[70] + "\t1\t2\t3\t4\t5\t6\t7\t8\t9"  # too many fields
    lines.insert(80, "")  # blank lines are not content
    tb = read_mgd77t(_copy(tmp_path, lines))
    assert len(tb) == 200 - 3
    assert tb.n_skipped == 3 and tb.n_lines == 200
    assert any("line 51" in n for n in tb.notes)


def test_fraction_of_minute_and_timezone(tmp_path):
    head = M77T.read_text().splitlines()[0]
    rows = ["X\t0\t20200101\t1638.5\t10\t20", "X\t-3\t20200101\t2359\t10\t20.01"]
    tb = read_mgd77t(_copy(tmp_path, [head] + rows))
    t0 = np.datetime64("2020-01-01T16:38:30", "ns").astype(np.int64)
    assert tb.time_ns[0] == t0
    # TIMEZONE -3: UTC = local + (-3) h
    assert tb.time_ns[1] == np.datetime64("2020-01-01T20:59", "ns").astype(np.int64)


def test_not_mgd77t(tmp_path):
    p = _copy(tmp_path, ["time_ns,height_m", "1,2"], "a.csv")
    with pytest.raises(DataError, match=r"a\.csv: line 1: not an MGD77T header"):
        read_mgd77t(p)
    head = M77T.read_text().splitlines()[0]
    p = _copy(tmp_path, [head] + ["garbage"] * 5 + M77T.read_text().splitlines()[1:3], "b.m77t")
    with pytest.raises(DataError, match=r"b\.m77t: not a mgd77t file: 2 of 7 .* line 2"):
        read_mgd77t(p)
    with pytest.raises(DataError, match="cannot read"):
        read_mgd77t(tmp_path / "missing.m77t")
