"""Fault injection on CSV inputs (issue 14): a UTF-8 byte-order mark, files cut anywhere,
NaN/inf values.  Outcome: the same data as the clean file, or our DataError naming the file and
line; never another exception."""

from __future__ import annotations

import functools
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from test_io_support import static_flight

from gravsurvey.errors import DataError, DataWarning
from gravsurvey.io.csv import read_csv_channel, sniff_csv_role
from gravsurvey.io.ingest import load_flight
from gravsurvey.io.inspect import inspect_files
from gravsurvey.settings import ingest_options

CSV_IN = {"csv": {"imu": "imu.csv", "altimeter": "altimeter.csv", "gnss": "gnss.csv"}}


@functools.lru_cache(maxsize=None)
def texts(seconds=3.0):
    """Clean CSV texts per docs/formats.md: role -> str."""
    d = static_flight(seconds=seconds)
    imu = ["time_ns,fx_mps2,fy_mps2,fz_mps2,wx_radps,wy_radps,wz_radps"] + [
        ",".join([str(t)] + [repr(float(x)) for x in (*d["f"][k], *d["w"][k])]) for k, t in enumerate(d["imu_t"])
    ]
    alt = ["time_ns,height_m"] + [f"{t},{h!r}" for t, h in zip(d["alt_t"], d["h"].tolist())]
    gnss = ["time_ns,lat_deg,lon_deg,height_m"] + [
        f"{t},{a!r},{b!r},{c!r}"
        for t, a, b, c in zip(d["gnss_t"], d["lat"].tolist(), d["lon"].tolist(), d["gh"].tolist())
    ]
    return {"imu": "\n".join(imu) + "\n", "altimeter": "\n".join(alt) + "\n", "gnss": "\n".join(gnss) + "\n"}


def _loaded(tmp, texts_by_role):
    """Write the CSV texts to ``tmp`` and load the flight: the record and the DataWarnings said."""
    for role, text in texts_by_role.items():
        (Path(tmp) / f"{role}.csv").write_text(text)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rec = load_flight(ingest_options({"inputs": CSV_IN}, "f"), tmp)
    return rec, [str(w.message) for w in caught if issubclass(w.category, DataWarning)]


def _write(tmp, imu_bytes=None):
    for role, text in texts().items():
        (Path(tmp) / f"{role}.csv").write_bytes(text.encode() if role != "imu" or imu_bytes is None else imu_bytes)


def test_bom_accepted_same_data(tmp_path):
    _write(tmp_path)
    clean = load_flight(ingest_options({"inputs": CSV_IN}, "f"), tmp_path)
    for role in ("imu", "altimeter", "gnss"):
        p = tmp_path / f"{role}.csv"
        p.write_bytes(b"\xef\xbb\xbf" + p.read_bytes())
    assert sniff_csv_role(tmp_path / "imu.csv") == "imu"
    rec = load_flight(ingest_options({"inputs": CSV_IN}, "f"), tmp_path)
    np.testing.assert_array_equal(rec.imu.time, clean.imu.time)
    np.testing.assert_array_equal(rec.imu.specific_force_t, clean.imu.specific_force_t)
    np.testing.assert_array_equal(rec.gnss.lat, clean.gnss.lat)
    (rep,) = inspect_files([tmp_path / "imu.csv"])
    assert "error" not in rep and rep["channels"][0]["samples"] == 300


FUZZ = settings(max_examples=40, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])


@FUZZ
@given(frac=st.floats(0.0, 1.0))
@example(frac=0.5)
@example(frac=0.9981)  # cut after a comma of the last line: fewer fields
@example(frac=0.999624)  # inside the last number of the last line: 5.1687...e-05 cut to 5.151 parses
def test_cut_imu_csv_keeps_every_complete_line(frac):
    """A file cut anywhere after its header: every complete line is read exactly as in the
    clean file, and a cut last line is dropped and reported (as damage when it is evidently
    cut). Cut inside the header: DataError naming the file and line."""
    full = texts()["imu"].encode()
    cut = int(frac * len(full))
    head_end = full.index(b"\n") + 1
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "imu.csv"
        p.write_bytes(full[:cut])
        notes, loss = [], []
        try:
            t, v = read_csv_channel(p, "imu", notes=notes, data_loss=loss)
        except DataError as exc:
            msg = str(exc)
            assert cut < head_end, msg  # only a cut header is refused
            assert str(p) in msg and ("line 1" in msg or "no header" in msg), msg
            return
    assert cut >= head_end
    d = static_flight(seconds=3.0)
    complete = full[:cut].count(b"\n") - 1  # lines ending in a newline, less the header
    assert len(t) == complete
    np.testing.assert_array_equal(t, d["imu_t"][:complete])
    np.testing.assert_array_equal(v["specific_force"], d["f"][:complete])
    np.testing.assert_array_equal(v["angular_rate"], d["w"][:complete])
    partial = full[:cut].rsplit(b"\n", 1)[-1] if b"\n" in full[:cut] else b""
    if not partial:
        assert notes == [] and loss == []
        return
    assert len(notes) == 1 and f"{p}: last line (line {complete + 2}" in notes[0], notes
    assert notes[0].endswith("1 row dropped"), notes
    assert f"{len(partial)} byte" in notes[0], notes
    fields = partial.decode().split(",")
    evident = len(fields) < 7 or not fields[0].isdigit() or not all(map(_parses, fields[1:]))
    if evident:
        assert loss == notes and "cut after" in loss[0]
    else:  # all 7 fields present and parsable: it may be cut inside its last number
        assert loss == [] and "has no line end" in notes[0]


def _parses(s):
    try:
        float(s)
    except ValueError:
        return False
    return True


def test_cut_last_line_through_load_flight_is_data_loss(tmp_path):
    """Through ingestion: the complete lines read, the cut row dropped, the damage in
    ``data_loss`` (so the run exits 1) and as a warning."""
    full = texts()["imu"].encode()
    last = full.rstrip(b"\n").rsplit(b"\n", 1)[0] + b"\n"  # without its last line
    cut_at = len(last) + 30  # 30 bytes into the last line (inside its 2nd or 3rd field)
    _write(tmp_path, full[:cut_at])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", DataWarning)
        rec = load_flight(ingest_options({"inputs": CSV_IN}, "f"), tmp_path)
    msg = f"{tmp_path / 'imu.csv'}: last line (line 301) cut after 30 bytes, 1 row dropped"
    assert rec.data_loss == [msg]
    assert [str(w.message) for w in caught].count(msg) == 1
    d = static_flight(seconds=3.0)
    np.testing.assert_array_equal(rec.imu.specific_force_t, d["f"][:299])
    (rep,) = inspect_files([tmp_path / "imu.csv"])
    assert rep["damage"] == [msg] and rep["channels"][0]["messages"] == 299


def test_unterminated_complete_last_line_dropped_with_a_warning(tmp_path):
    """No line end after a complete-looking last line: dropped (its last value may be cut
    short), a warning but not data loss; inspect exits 0 on it."""
    full = texts()["imu"].encode()
    _write(tmp_path, full.rstrip(b"\n"))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", DataWarning)
        rec = load_flight(ingest_options({"inputs": CSV_IN}, "f"), tmp_path)
    assert rec.data_loss == []
    assert any("imu.csv: last line (line 301" in str(w.message) and "has no line end" in str(w.message) for w in caught)
    assert len(rec.imu.time) == 299
    (rep,) = inspect_files([tmp_path / "imu.csv"])
    assert rep["damage"] == [] and rep["channels"][0]["messages"] == 299


@FUZZ
@given(
    rows=st.lists(st.integers(0, 299), min_size=1, max_size=5, unique=True),
    bad=st.sampled_from(["nan", "inf", "-inf", "NaN", "2.6e21", "-1e300", "1e308"]),
)
@example(rows=[150], bad="2.6e21")  # one corrupted digit: crashed the mechanization (ZeroDivisionError)
@example(rows=[7], bad="1e308")  # issue 14: 1e308 values ended in exit 3
def test_nonfinite_values_dropped_and_counted(rows, bad):
    lines = texts()["imu"].split("\n")
    for r in rows:
        fields = lines[1 + r].split(",")
        fields[3] = bad
        lines[1 + r] = ",".join(fields)
    with tempfile.TemporaryDirectory() as tmp:
        _write(tmp, "\n".join(lines).encode())
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", DataWarning)
            rec = load_flight(ingest_options({"inputs": CSV_IN}, "f"), tmp)
    msgs = [str(w.message) for w in caught]
    assert any(f"imu: dropped {len(rows)} samples with empty, NaN/inf or absurd" in m for m in msgs), msgs
    d = static_flight(seconds=3.0)
    keep = np.setdiff1d(np.arange(300), rows)
    np.testing.assert_array_equal(rec.imu.specific_force_t, d["f"][keep])


def test_short_line_in_the_middle_names_file_and_line(tmp_path):
    lines = texts()["imu"].split("\n")
    lines[101] = lines[101][: len(lines[101]) // 2]
    _write(tmp_path, "\n".join(lines).encode())
    with pytest.raises(DataError, match=r"imu.csv: line 102: \d fields, header has 7"):
        load_flight(ingest_options({"inputs": CSV_IN}, "f"), tmp_path)


def test_a_bad_value_is_shown_cut_short_and_nanoseconds_as_seconds_named(tmp_path):
    """A block of NUL bytes in a time field is shown as its first 40 characters and its length,
    not as a 16-kB error line; integer nanoseconds declared as seconds are named as such, not an
    internal OverflowError (fuzzing, 2026-12-04)."""
    lines = texts()["imu"].split("\n")
    lines[101] = "\x00" * 4000 + "," + lines[101].split(",", 1)[1]
    _write(tmp_path, "\n".join(lines).encode())
    with pytest.raises(DataError) as exc:
        load_flight(ingest_options({"inputs": CSV_IN}, "f"), tmp_path)
    msg = str(exc.value)
    assert "imu.csv: line 102, column 'time_ns': expected integer nanoseconds, got '" in msg
    assert msg.endswith("... (4000 characters)") and len(msg) < 500, msg[:600]
    _write(tmp_path)
    with pytest.raises(
        DataError, match=r"imu.csv: line 2, column 'time_ns': expected seconds, got '\d+': past the year 2262"
    ):
        load_flight(ingest_options({"inputs": CSV_IN, "csv": {"time_format": "s"}}, "f"), tmp_path)


def test_a_gnss_row_with_no_fix_is_dropped_not_a_jump_of_the_track(tmp_path):
    """A receiver writes latitude 0, longitude 0 and height 0 without a fix: the row is dropped
    with a warning, not taken for a 5,000-km jump that refuses the flight (fuzzing, 2026-12-04)."""
    t = texts()
    g = t["gnss"].split("\n")
    g[3] = g[3].split(",", 1)[0] + ",0,0,0"
    rec, said = _loaded(tmp_path, {**t, "gnss": "\n".join(g)})
    assert any(m.startswith("gnss: dropped 1 samples at latitude 0, longitude 0 (no fix)") for m in said), said
    assert rec.gnss.time.size == len([ln for ln in t["gnss"].split("\n")[1:] if ln]) - 1
    assert np.all(rec.gnss.lat != 0.0)


def test_quoted_fields_are_read_and_another_delimiter_is_named(tmp_path):
    """A spreadsheet's export quotes every field: read as the plain file; a file separated by
    semicolons names csv.delimiter, not csv.columns (fuzzing, 2026-12-04)."""
    _write(tmp_path)
    plain = load_flight(ingest_options({"inputs": CSV_IN}, "f"), tmp_path)
    for role in ("imu", "altimeter", "gnss"):
        p = tmp_path / f"{role}.csv"
        p.write_text("\n".join(",".join(f'"{x}"' for x in ln.split(",")) for ln in p.read_text().splitlines()) + "\n")
    quoted = load_flight(ingest_options({"inputs": CSV_IN}, "f"), tmp_path)
    np.testing.assert_array_equal(quoted.imu.specific_force_t, plain.imu.specific_force_t)
    np.testing.assert_array_equal(quoted.gnss.lat, plain.gnss.lat)
    _write(tmp_path)
    p = tmp_path / "imu.csv"
    p.write_text(p.read_text().replace(",", ";"))
    with pytest.raises(
        DataError,
        match=r"imu.csv: line 1: column 'time_ns' missing from the header .*the header holds ';': set csv.delimiter$",
    ):
        load_flight(ingest_options({"inputs": CSV_IN}, "f"), tmp_path)


def test_a_repeated_header_of_logs_joined_end_to_end_is_skipped_and_said(tmp_path):
    """Two logs joined end to end, the second with its own header (fuzzing, 2026-12-04: the flight
    refused at "expected integer nanoseconds, got 'time_ns'"): the header line is skipped with a
    warning naming the file and line, every sample kept."""
    t = texts()
    lines = t["imu"].split("\n")
    joined = "\n".join(lines[:150] + [lines[0]] + lines[150:])
    rec, said = _loaded(tmp_path, {**t, "imu": joined})
    assert any(
        m.endswith("imu.csv: skipped 1 repeated header line(s) (line 151): logs joined end to end?") for m in said
    ), said
    assert rec.imu.time.size == len([ln for ln in lines[1:] if ln])


def test_empty_cells_are_no_value_their_rows_dropped_and_counted(tmp_path):
    """A GNSS export leaves the cells of an epoch without a fix empty (fuzzing, 2026-12-04: the
    flight refused at "column 'lat_deg': expected a number, got ''"): those rows are dropped
    and counted like NaN, the rest kept."""
    t = texts()
    g = t["gnss"].split("\n")
    for k in (5, 6, 7):
        g[k] = g[k].split(",", 1)[0] + ",,,"
    rec, said = _loaded(tmp_path, {**t, "gnss": "\n".join(g)})
    assert any(m.startswith("gnss: dropped 3 samples with empty, NaN/inf or absurd") for m in said), said
    assert rec.gnss.time.size == len([ln for ln in g[1:] if ln]) - 3


def test_a_decimal_comma_is_read_in_a_file_separated_by_semicolons(tmp_path):
    """A spreadsheet in a locale with a decimal comma writes ``9,81`` separated by ``;``: read as
    the same numbers bit for bit."""
    t = texts()
    ref = load_flight(ingest_options({"inputs": CSV_IN}, "f"), _written(tmp_path / "a", t))
    local = {r: text.replace(",", ";").replace(".", ",") for r, text in t.items()}
    flight = {"inputs": CSV_IN, "csv": {"delimiter": ";"}}
    rec = load_flight(ingest_options(flight, "f"), _written(tmp_path / "b", local))
    np.testing.assert_array_equal(rec.imu.specific_force_t, ref.imu.specific_force_t)
    np.testing.assert_array_equal(rec.gnss.lat, ref.gnss.lat)


def _written(d, texts_by_role):
    d.mkdir(parents=True, exist_ok=True)
    for role, text in texts_by_role.items():
        (d / f"{role}.csv").write_text(text)
    return d


def _variants():
    """IMU CSV texts a logger or an export may write: plain ones and each kind of damage the
    line-by-line reader names or repairs."""
    t = texts()["imu"]
    lines = t.split("\n")
    head, rows = lines[0], [ln for ln in lines[1:] if ln]
    seconds = "\n".join(
        [head.replace("time_ns", "t_s")]
        + [f"{int(r.split(',')[0]) // 10**9}.{int(r.split(',')[0]) % 10**9:09d}," + r.split(",", 1)[1] for r in rows]
    )
    return {
        "plain": t,
        "crlf": t.replace("\n", "\r\n"),
        "bom": "\ufeff" + t,
        "comments": "# logger v2\n# units SI\n" + t,
        "extra column": "\n".join([head + ",temp_c"] + [r + ",21.5" for r in rows]) + "\n",
        "trailing comma": "\n".join([head + ","] + [r + "," for r in rows]) + "\n",
        "seconds": seconds + "\n",
        "cut last line": t.rstrip("\n")[:-7],
        "no final line end": t.rstrip("\n"),
        "empty cell": t.replace(rows[5], ",".join(rows[5].split(",")[:3] + [""] + rows[5].split(",")[4:]), 1),
        "short line": t.replace(rows[7], ",".join(rows[7].split(",")[:5]), 1),
        "long line": t.replace(rows[7], rows[7] + ",1.0", 1),
        "repeated header": "\n".join(lines[:50] + [head] + lines[50:]),
        "units row": "\n".join([head, "ns,m/s^2,m/s^2,m/s^2,rad/s,rad/s,rad/s"] + lines[1:]),
        "garbage": t.replace(rows[9], "x" * 30, 1),
        "nan and inf": t.replace(
            rows[3], ",".join(rows[3].split(",")[:2] + ["nan", "inf"] + rows[3].split(",")[4:]), 1
        ),
        "header spaces": t.replace(head, head.replace(",", ", "), 1),
        "float time": t.replace(rows[2].split(",")[0], rows[2].split(",")[0] + ".5", 1),
    }


@pytest.mark.parametrize("name", list(_variants()))
def test_a_large_file_read_at_once_is_read_as_line_by_line(tmp_path, monkeypatch, name):
    """Files past ``PLAIN_READ_MIN_BYTES`` that are plain are read by pandas' C parser: the same
    arrays bit for bit, dtype for dtype; anything not plain goes to the line-by-line reader,
    so a damaged file gives the same error, repairs and notes whatever its size."""
    import gravsurvey.io.csv as csv_mod

    path = tmp_path / "imu.csv"
    path.write_bytes(_variants()[name].encode())
    cols = {"time": "t_s"} if name == "seconds" else None
    fmt = "s" if name == "seconds" else "ns"

    def read(min_bytes):
        monkeypatch.setattr(csv_mod, "PLAIN_READ_MIN_BYTES", min_bytes)
        notes, loss = [], []
        try:
            out = read_csv_channel(path, "imu", cols, fmt, notes=notes, data_loss=loss)
        except DataError as exc:
            return ("error", str(exc))
        return out, notes, loss

    careful, at_once = read(2**62), read(0)
    plain = csv_mod.read_csv_at_once(
        path, "imu", {**csv_mod.DEFAULT_COLUMNS["imu"], **(cols or {})}, csv_mod.QUANTITIES["imu"], fmt, {}, ",", False
    )
    # the plain files are read at once (the comparison is not of the careful reader with itself)
    assert (plain is not None) == (
        name in {"plain", "crlf", "bom", "comments", "extra column", "trailing comma", "seconds"}
    )
    if careful[0] == "error":
        assert at_once == careful
        return
    (t1, v1, n1, l1), (t2, v2, n2, l2) = (*careful[0], *careful[1:]), (*at_once[0], *at_once[1:])
    assert t1.dtype == t2.dtype == np.int64 and np.array_equal(t1, t2)
    for k in v1:
        assert v1[k].dtype == v2[k].dtype and np.array_equal(v1[k], v2[k], equal_nan=True), k
    assert (n1, l1) == (n2, l2)
