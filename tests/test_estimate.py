"""The per-flight result type (gravsurvey/estimate.py, issue 17 item 1) and what the deliverables
write from it: horizontal components when estimated, columns named for what they hold (issue 14
item 10)."""

from __future__ import annotations

import csv
import dataclasses
import json
from pathlib import Path
from types import SimpleNamespace

import boule
import numpy as np
import pytest

from gravsurvey.classic import ClassicResult
from gravsurvey.config import SurveyConfig
from gravsurvey.estimate import FlightEstimate, concatenate_estimates, from_classic, from_inm_solution
from gravsurvey.geodesy import MGAL, WGS84
from gravsurvey.grid import GridOptions
from gravsurvey.io.writers import read_xyz
from gravsurvey.levelling import LevellingOptions
from gravsurvey.inm.params import InmParams
from gravsurvey.pipeline import identification_log_lines, line_products, model_used, write_survey_outputs
from gravsurvey.wavelet import PostprocessOptions

R_EARTH = 6_371_000.0
N = 400


def _track():
    t = np.arange(N, dtype=float)
    lat = np.radians(47.0) + 80.0 * t / R_EARTH  # due north at 80 m/s
    lon = np.full(N, np.radians(11.0))
    h = np.full(N, 900.0) + 0.01 * t
    vel = np.column_stack([np.zeros(N), np.full(N, 80.0), np.zeros(N)])
    return t, lat, lon, h, vel


def inm_like(horizontal: bool):
    """An object with the InmSolution fields (and the horizontal ones of the h-vector interface)."""
    t, lat, lon, h, vel = _track()
    g = 20 * MGAL * np.sin(t / 60.0)
    s = SimpleNamespace(
        time=t,
        lat=lat,
        lon=lon,
        height=h,
        vel_n=vel,
        speed=np.full(N, 80.0),
        heading=np.zeros(N),
        g_smooth=g,
        sigma_smooth=np.full(N, 0.8 * MGAL),
        g_forward=g + 1 * MGAL,
        sigma_forward=np.full(N, 1.5 * MGAL),
        resolution_m=2500.0,
        gnss_aided=True,
        identification={"q": 1.0},
        attitude=None,
        attitude_sigma=None,
        alignment=None,
    )
    if horizontal:
        s.dg_horizontal = np.column_stack([30 * MGAL * np.cos(t / 50.0), -12 * MGAL + 0 * t])
        s.dg_horizontal_sigma = np.column_stack([np.full(N, 4 * MGAL), np.full(N, 5 * MGAL)])
        obs = np.ones(N, bool)
        obs[:150] = False  # line L01 (epochs 0-199): 50 of 200 observable; L02: 140 of 200
        obs[200:260] = False
        s.horizontal_observable = obs
    return s


def with_lines(est: FlightEstimate) -> FlightEstimate:
    """Two lines (0-199, 200-399), product = the estimate on lines (no post-processing)."""
    est.line = np.array(["L01"] * 200 + ["L02"] * 200, dtype=object)
    est.line_info = {ln: {"kind": "line", "method": "none", "samples": 200} for ln in ("L01", "L02")}
    return est


def survey_cfg(tmp_path: Path) -> SurveyConfig:
    p = tmp_path / "survey.yaml"
    p.write_text("survey: {name: t}\n")
    return SurveyConfig(
        path=p,
        base_dir=tmp_path,
        raw={"survey": {"name": "t"}},
        name="t",
        ellipsoid=WGS84,
        flights=[],
        model=None,
        lines=None,
        postprocess=None,
        plots=False,
        levelling=LevellingOptions(enabled=False),
        grid=GridOptions(enabled=False),
    )


def read_csv(path):
    rows = list(csv.reader(line for line in open(path, newline="") if not line.startswith("#")))
    return {h: [r[i] for r in rows[1:]] for i, h in enumerate(rows[0])}


def test_from_inm_solution_maps_every_field():
    s = inm_like(horizontal=True)
    e = from_inm_solution(s, name="F01", t0_unix_ns=1_700_000_000 * 10**9)
    assert e.method == "inm" and e.name == "F01"
    np.testing.assert_array_equal(e.smoothed, s.g_smooth)
    np.testing.assert_array_equal(e.disturbance, s.g_smooth)
    np.testing.assert_array_equal(e.forward_sigma, s.sigma_forward)
    np.testing.assert_array_equal(e.dg_north, s.dg_horizontal[:, 0])
    np.testing.assert_array_equal(e.dg_east, s.dg_horizontal[:, 1])
    np.testing.assert_array_equal(e.sigma_east, s.dg_horizontal_sigma[:, 1])
    np.testing.assert_array_equal(e.horizontal_observable, s.horizontal_observable)
    assert e.unfiltered is None and e.resolution_m == 2500.0
    assert e.attitude.shape == (N, 3) and not e.has_attitude
    assert e.estimator["gnss_aided"] is True and e.estimator["kalman_resolution_m"] == 2500.0
    # without the horizontal states: every horizontal field None
    e2 = from_inm_solution(inm_like(horizontal=False))
    assert e2.dg_north is None and e2.horizontal_observable is None and not e2.has_horizontal


def test_horizontal_components_in_every_deliverable(tmp_path):
    s = inm_like(horizontal=True)
    est = with_lines(from_inm_solution(s, name="F01", t0_unix_ns=1_700_000_000 * 10**9))
    cfg = survey_cfg(tmp_path)
    out = tmp_path / "out"
    summary = write_survey_outputs(cfg, out, [est])
    p = read_csv(out / "profiles.csv")
    f = lambda c: np.array([float(v) for v in p[c]])  # noqa: E731
    obs = s.horizontal_observable
    # mGal, blank where not observable
    np.testing.assert_allclose(f("dg_north_mgal")[obs], s.dg_horizontal[obs, 0] / MGAL, atol=6e-5)
    np.testing.assert_allclose(f("dg_east_sigma_mgal")[obs], 5.0, atol=6e-5)
    for c in ("dg_north_mgal", "dg_east_mgal", "xi_arcsec", "eta_arcsec", "xi_sigma_arcsec", "eta_sigma_arcsec"):
        assert np.isnan(f(c)[~obs]).all(), c
    # xi = -dg_north / gamma, eta = -dg_east / gamma, gamma from boule (independent of our geodesy)
    gamma = boule.WGS84.normal_gravity((np.zeros(N), np.degrees(s.lat), s.height), si_units=True)
    arcsec = 180 * 3600 / np.pi
    np.testing.assert_allclose(f("xi_arcsec")[obs], -s.dg_horizontal[obs, 0] / gamma[obs] * arcsec, atol=6e-5)
    np.testing.assert_allclose(f("eta_arcsec")[obs], 12 * MGAL / gamma[obs] * arcsec, atol=6e-5)
    np.testing.assert_allclose(f("eta_sigma_arcsec")[obs], 5 * MGAL / gamma[obs] * arcsec, atol=6e-5)
    assert abs(f("eta_arcsec")[obs][0] - 2.52) < 0.01  # 12 mGal / 9.81 m/s^2 = 2.52 arcsec
    # summary per line: L01 has 50 of 200 epochs observable, L02 140 of 200
    lines = summary["flights"]["F01"]["lines"]
    assert lines["L01"]["horizontal_meaningful"] is False and lines["L01"]["horizontal_observable_fraction"] == 0.25
    assert lines["L02"]["horizontal_meaningful"] is True and lines["L02"]["horizontal_observable_fraction"] == 0.7
    assert lines["L02"]["mean_dg_east_mgal"] == pytest.approx(-12.0, abs=1e-9)
    # XYZ and GeoJSON carry them too
    x = read_xyz(out / "profiles.xyz")
    for c in ("dg_north_mgal", "xi_arcsec", "eta_sigma_arcsec"):
        assert c in x.columns
    l2 = x.lines["Line 1002"]
    np.testing.assert_allclose(l2["dg_east_mgal"][60:], -12.0, atol=6e-5)
    assert np.isnan(l2["dg_east_mgal"][:60]).all()
    gj = json.loads((out / "lines.geojson").read_text())
    props = {ft["properties"]["line"]: ft["properties"] for ft in gj["features"]}
    assert props["L02"]["horizontal_meaningful"] is True and props["L01"]["horizontal_meaningful"] is False
    assert props["L02"]["mean_eta_arcsec"] == pytest.approx(float(np.mean(f("eta_arcsec")[200:][obs[200:]])), abs=1e-4)


def test_profile_plot_has_a_horizontal_panel(tmp_path):
    from gravsurvey import report

    s = inm_like(horizontal=True)
    x = np.arange(N) * 0.08
    h = {
        "dg_north_mgal": s.dg_horizontal[:, 0] / MGAL,
        "dg_east_mgal": s.dg_horizontal[:, 1] / MGAL,
        "dg_north_sigma_mgal": np.full(N, 4.0),
        "dg_east_sigma_mgal": np.full(N, 5.0),
    }
    fig = report.figure_line_profile(x, s.g_smooth / MGAL, s.g_smooth / MGAL, np.full(N, 0.8), horizontal=h)
    assert len(fig.axes) == 2
    lines = {ln.get_label(): ln for ln in fig.axes[1].get_lines()}
    np.testing.assert_array_equal(lines["dg_east"].get_ydata(), h["dg_east_mgal"])
    assert len(report.figure_line_profile(x, s.g_smooth / MGAL, s.g_smooth / MGAL, np.full(N, 0.8)).axes) == 1


def test_no_horizontal_columns_when_not_estimated(tmp_path):
    est = with_lines(from_inm_solution(inm_like(horizontal=False), name="F01"))
    summary = write_survey_outputs(survey_cfg(tmp_path), tmp_path / "out", [est])
    head = read_csv(tmp_path / "out" / "profiles.csv")
    assert not [c for c in head if c.startswith(("dg_", "xi_", "eta_"))]
    assert "kalman_mgal" in head and "unfiltered_mgal" not in head
    assert "horizontal_meaningful" not in summary["flights"]["F01"]["lines"]["L01"]


def test_classic_columns_are_named_for_what_they_hold(tmp_path):
    """Issue 14.10: the classic chain has no Kalman filter; its unfiltered reduction (values of
    +-1e6 mGal) is written as unfiltered_mgal, and no kalman_mgal column exists."""
    t, lat, lon, h, vel = _track()
    raw = 2.8e6 * MGAL * np.sin(t * 1.3)  # the size of the classic unfiltered reduction
    low = 10 * MGAL * np.sin(t / 60.0)
    res = ClassicResult(
        time=t,
        disturbance=low,
        lat=lat,
        lon=lon,
        height=h,
        speed=np.full(N, 80.0),
        vel_n=vel,
        raw=raw,
        info={"method": "classic", "filter": "gaussian", "resolution_m": 4000.0},
    )
    est = from_classic(res, name="F01", t0_unix_ns=1_700_000_000 * 10**9)
    assert est.method == "classic" and est.smoothed is None and est.forward is None
    assert np.isnan(est.sigma).all() and est.product_info["filter"] == "gaussian"
    np.testing.assert_array_equal(est.unprocessed, raw)
    np.testing.assert_allclose(est.heading, 0.0, atol=1e-12)  # due north
    summary = write_survey_outputs(survey_cfg(tmp_path), tmp_path / "out", [with_lines(est)])
    p = read_csv(tmp_path / "out" / "profiles.csv")
    assert "kalman_mgal" not in p and "unfiltered_mgal" in p
    np.testing.assert_allclose([float(v) for v in p["unfiltered_mgal"]], raw / MGAL, atol=6e-5)
    np.testing.assert_allclose([float(v) for v in p["disturbance_mgal"]], low / MGAL, atol=6e-5)
    assert "kalman_mgal" not in read_xyz(tmp_path / "out" / "profiles.xyz").columns
    assert summary["flights"]["F01"]["estimator"] == {"gnss_aided": False, "resolution_m": 4000.0}


def classic_estimate(raw_scale=1.0):
    t, lat, lon, h, vel = _track()
    res = ClassicResult(
        time=t,
        disturbance=10 * MGAL * np.sin(t / 60.0),
        lat=lat,
        lon=lon,
        height=h,
        speed=np.full(N, 80.0),
        vel_n=vel,
        raw=raw_scale * 2.8e6 * MGAL * np.sin(t * 1.3),
        info={"method": "classic", "resolution_m": 4000.0},
    )
    return with_lines(from_classic(res, name="F01", t0_unix_ns=1_700_000_000 * 10**9))


def test_regression_check_compares_the_renamed_columns(tmp_path):
    """`gravsurvey check` compares unfiltered_mgal like kalman_mgal, and a column of the reference
    missing from the result (e.g. a reference from another method) is a difference."""
    from gravsurvey.regression import compare_runs

    cfg = survey_cfg(tmp_path)
    write_survey_outputs(cfg, tmp_path / "a", [classic_estimate()])
    write_survey_outputs(cfg, tmp_path / "b", [classic_estimate(raw_scale=1.001)])
    inm = with_lines(from_inm_solution(inm_like(horizontal=False), name="F01", t0_unix_ns=1_700_000_000 * 10**9))
    write_survey_outputs(cfg, tmp_path / "c", [inm])
    assert compare_runs(tmp_path / "a", tmp_path / "a") == []
    d = compare_runs(tmp_path / "b", tmp_path / "a")
    assert len(d) == 1 and d[0].startswith("profiles.csv unfiltered_mgal: ")
    d = compare_runs(tmp_path / "c", tmp_path / "a")
    assert "profiles.csv: column unfiltered_mgal of the reference missing from the result" in d


def test_identification_warnings_become_the_flights_notes():
    """What may have degraded the estimate reaches the user (stderr, log) as the flight's notes;
    the identification's informational notes stay in summary.json."""
    s = inm_like(horizontal=False)
    warn = "model identification: no straight stretch of 240 s with evenly sampled heights; defaults used"
    s.identification = {"warnings": [warn, warn], "notes": ["model identification: 3 stretches pooled"]}
    e = from_inm_solution(s, name="F07")
    assert e.notes == [f"F07: {warn}"]
    # a flight estimated in pieces: each piece's warning once
    both = concatenate_estimates([e, from_inm_solution(s, name="F07")])
    assert both.notes == [f"F07: {warn}"]
    assert from_inm_solution(inm_like(horizontal=False), name="F07").notes == []


def test_line_solvability_uses_the_prior_the_smoother_used():
    """The seed-004 check at a line's speed is against the identified anomaly correlation, not
    the configured default (which the identification replaced)."""
    model = InmParams()  # gravimeter 0.025 1/s; default anomaly 1e-5 1/m: 80 m/s -> 8e-4 1/s
    s = inm_like(horizontal=False)
    s.identification = {"anomaly_lambda_per_m": {"value": 0.025 / 80.0, "sigma_factor": None, "how": "identified"}}
    e = from_inm_solution(s, name="F01")
    assert model_used(e, model, 0).anomaly_lambda_per_m == pytest.approx(0.025 / 80.0)
    segs = [
        SimpleNamespace(name=n, kind="line", start_index=a, stop_index=a + 200) for n, a in (("L01", 0), ("L02", 200))
    ]
    _, _, notes = line_products(e, segs, PostprocessOptions(), model)
    assert len(notes) == 2 and all("solvability" in n and "F01 L0" in n for n in notes)
    # with the default prior as used (nothing identified) the same lines are fine
    quiet = from_inm_solution(inm_like(horizontal=False), name="F01")
    assert line_products(quiet, segs, PostprocessOptions(), model)[2] == []
    # pieces of a flight split at a gap: each line is checked against its own piece's prior
    two = concatenate_estimates([quiet, e])
    assert model_used(two, model, 10).anomaly_lambda_per_m == model.anomaly_lambda_per_m
    assert model_used(two, model, N + 10).anomaly_lambda_per_m == pytest.approx(0.025 / 80.0)


def test_the_log_states_the_identified_model_and_the_drift():
    s = inm_like(horizontal=False)
    s.identification = {
        "anomaly_sigma_mps2": {"value": 3.2 * MGAL, "sigma_factor": None, "how": "least expected error"},
        "anomaly_lambda_per_m": {"value": 1.0 / 25_000.0, "sigma_factor": None, "how": "least expected error"},
        "altimeter_sigma_m": {"value": 0.05, "sigma_factor": 1.04, "how": "identified"},
        "accel_noise_mps2": {"value": 2.5e-4, "sigma_factor": None, "how": "filter likelihood"},
        "resolution_m": 4200.0,
        "expected_error_mgal": 0.41,
        "smoother_sigma_scale": 0.62,
    }
    e = from_inm_solution(s, name="F01")
    e.estimator["drift"] = {"used": False, "reason": "1 line(s): the drift needs two or more"}
    lines = identification_log_lines(e)
    assert lines[0].startswith("F01: model: anomaly sigma 3.2 mGal, least expected error")
    assert "anomaly correlation length 25 km" in lines[0] and "height noise 0.05 m (x/ 1.04), identified" in lines[0]
    assert "horizontal accelerometer noise 0.00025 m/s^2 in 1 s, filter likelihood" in lines[0]
    assert "resolution 4.2 km" in lines[0] and "expected error 0.41 mGal" in lines[0]
    assert "smoother's sigma x 0.62 for the field seen" in lines[0]
    # the product's sigma is the smoother's times that factor (no drift or missed field here)
    np.testing.assert_allclose(e.sigma, 0.62 * np.asarray(s.sigma_smooth))
    assert lines[1] == "F01: drift: not taken off: 1 line(s): the drift needs two or more"
    assert identification_log_lines(from_classic_like()) == []


def from_classic_like():
    est = from_inm_solution(inm_like(horizontal=False), name="C")
    est.estimator = {"method": "classic", "resolution_m": 3000.0}
    return est


def test_every_product_states_its_resolution(tmp_path, monkeypatch):
    """Issue 12 item 4: each line's half-wavelength resolution (the smoother's, for the default
    product) in summary.json, the XYZ line map and the profile plot's title; a smoother that
    resolves nothing (unbounded resolution: a flat estimate) says so instead of a number."""
    import dataclasses
    import math

    from gravsurvey import report

    segs = [
        SimpleNamespace(name=n, kind="line", start_index=a, stop_index=a + 200) for n, a in (("L01", 0), ("L02", 200))
    ]
    titles, legends = {}, {}

    def capture(path, *args, title="", final_label="final", **kw):
        titles[Path(path).name], legends[Path(path).name] = title, final_label

    monkeypatch.setattr(report, "plot_line_profile", capture)
    for resolution_m, stated in ((2500.0, "half-wavelength resolution 2.5 km"), (math.inf, "no wavelength resolved")):
        s = inm_like(horizontal=False)
        s.resolution_m = resolution_m
        est = from_inm_solution(s, name="F01", t0_unix_ns=1_700_000_000 * 10**9)
        _, est.line_info, _ = line_products(est, segs, PostprocessOptions())
        out = tmp_path / f"out_{resolution_m}"
        summary = write_survey_outputs(dataclasses.replace(survey_cfg(tmp_path), plots=True), out, [est])
        lines = summary["flights"]["F01"]["lines"]
        assert lines["L01"]["resolution_m"] == (resolution_m if math.isfinite(resolution_m) else None)
        assert all(stated in lines[n]["resolution_note"] for n in ("L01", "L02"))
        comments = read_xyz(out / "profiles.xyz").comments
        assert f"Line 1001 = flight F01 line L01; {lines['L01']['resolution_note']}" in comments
        assert sum(stated in c for c in comments) == 3  # the two map lines and the metadata
        csv_head = [ln for ln in (out / "profiles.csv").read_text().splitlines() if ln.startswith("#")]
        resolution = json.loads(next(ln for ln in csv_head if ln.startswith("# resolution: "))[14:])
        assert resolution == {f"F01/{n}": lines[n]["resolution_note"] for n in ("L01", "L02")}
        assert titles["profile_F01_L02.png"] == f"t F01 L02\n{lines['L02']['resolution_note']}"
        assert legends["profile_F01_L02.png"] == "final (smoothed)"
    est.drift = np.full(N, 0.1 * MGAL)  # the drift stage took some off: the legend says so
    write_survey_outputs(dataclasses.replace(survey_cfg(tmp_path), plots=True), tmp_path / "out_drift", [est])
    assert legends["profile_F01_L01.png"] == "final (smoothed less drift)"
    # a flight estimated in pieces states its coarsest piece's resolution; unbounded wins
    pieces = []
    for r in (2500.0, math.inf, math.nan):
        s = inm_like(horizontal=False)
        s.resolution_m = r
        pieces.append(from_inm_solution(s, name="F01"))
    assert concatenate_estimates(pieces[:1] + pieces[2:]).resolution_m == 2500.0
    assert concatenate_estimates(pieces).resolution_m == math.inf
    assert concatenate_estimates(pieces[1:]).resolution_m == math.inf
    assert math.isnan(concatenate_estimates(pieces[2:] * 2).resolution_m)


def test_the_estimate_beside_a_gap_is_left_out_for_a_resolution():
    """A piece's smoothed estimate at a gap has data on one side only and lags the field (quick
    U015 split by a 5-s IMU gap mid-line: -15 mGal at the gap, sigma 2.4; the flight's RMS
    2.36 against 1.17 intact, 1.24 with these epochs left out): within the piece's resolution
    (2.5 km at 80 m/s: 31 s) of each end at a gap, every series is left out; the flight's own
    first and last epochs are not, nor is anything of a piece with no finite resolution."""
    from gravsurvey.estimate import ONE_SIDED_MARGIN, trim_one_sided_ends

    whole = from_inm_solution(inm_like(True), name="F01")
    first = dataclasses.replace(whole, **{k: v[:180] for k, v in _epoch_arrays(whole).items()})
    second = dataclasses.replace(whole, **{k: v[220:] for k, v in _epoch_arrays(whole).items()})
    margin = ONE_SIDED_MARGIN * 2500.0 / 80.0
    (a, b), notes = trim_one_sided_ends([first, second], 0.0, float(N - 1))
    assert a.time[0] == 0.0 and a.time[-1] == pytest.approx(179.0 - margin, abs=1.0)
    assert b.time[0] == pytest.approx(220.0 + margin, abs=1.0) and b.time[-1] == N - 1
    for piece, src in ((a, first), (b, second)):
        keep = np.isin(src.time, piece.time)
        for k, v in _epoch_arrays(src).items():
            np.testing.assert_array_equal(getattr(piece, k), v[keep])
    assert len(notes) == 2 and all("is left out: it has data on one side only" in n for n in notes)
    assert "within 31 s of the gap" in notes[0] and "(2.5 km at 80 m/s)" in notes[0]
    # the pieces joined: the lines end at the left-out stretch like at the gap
    joined = concatenate_estimates([a, b])
    assert len(joined.time) == len(a.time) + len(b.time) + 1
    # a flat piece (nothing resolved) and a flight that is not split are kept whole
    flat = dataclasses.replace(first, resolution_m=float("inf"))
    (same, b2), notes = trim_one_sided_ends([flat, second], 0.0, float(N - 1))
    assert same is flat and len(notes) == 1
    (one,), notes = trim_one_sided_ends([whole], 0.0, float(N - 1))
    assert one is whole and notes == []


def _epoch_arrays(est: FlightEstimate) -> dict:
    n = len(est.time)
    return {
        f.name: v
        for f in dataclasses.fields(est)
        for v in [getattr(est, f.name)]
        if isinstance(v, np.ndarray) and v.ndim >= 1 and v.shape[0] == n
    }
