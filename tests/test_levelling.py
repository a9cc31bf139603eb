"""Crossover levelling (gravsurvey.levelling) and base ties (gravsurvey.ties) on a simulated
survey with known truth: several flights with per-flight offsets and drifts, per-line offsets,
white noise, tie lines; the truth is an analytic field, so every check is against truth."""

from __future__ import annotations

import numpy as np
import pytest

from gravsurvey.errors import ConfigError, DataError
from gravsurvey.geodesy import MGAL, normal_gravity
from gravsurvey.levelling import LevellingOptions, level_crossovers, level_survey
from gravsurvey.crossovers import find_crossovers
from gravsurvey.ties import tie_flight
from gravsurvey.settings import levelling_options, tie_config
from levelling_truth import simulated_survey


def test_levelling_recovers_relative_levels_and_noise():
    lines, _ = simulated_survey()
    xo = find_crossovers(lines)
    assert xo.count == 4 * 8  # every tie crosses every line once
    lev = level_survey(xo, lines, LevellingOptions(model="flight_trend"))
    before, after = lev.before, lev.after
    assert before["rms_mgal"] > 2.0
    # after: RMS of differences ~ noise * sqrt(2) (fewer degrees of freedom lower it a bit)
    assert after["rms_over_sqrt2_mgal"] < 0.3
    # corrected line errors agree with each other: the spread of (value - correction - truth)
    # over all lines is the noise plus the datum shift only
    resid = []
    for ln in lines:
        c = lev.correction(ln["flight"], ln["line"], ln["time_s"])
        resid.append(ln["value_mgal"] - c - ln["truth_mgal"])
    means = np.array([r.mean() for r in resid])
    assert np.std(means) < 0.3, means
    # datum: mean constant zero
    assert abs(lev.constant_mgal.mean()) < 1e-9


def test_ties_and_levelling_give_absolute_level():
    lines, flights = simulated_survey(seed=3)
    # base ties: still readings of 10 min before (t = 0..600) and after each flight
    rng = np.random.default_rng(7)
    g_base = 980_812.43
    lat_b, h_b = np.radians(47.0), 600.0
    gamma = float(normal_gravity(np.array([lat_b]), np.array([h_b]))[0]) / MGAL
    dist_base = g_base - gamma
    tied = {}
    for f, (off, drift, t_end) in flights.items():
        tt = np.concatenate([np.arange(0, 600.0, 1.0), np.arange(t_end - 600.0, t_end, 1.0)])
        z = dist_base + off + drift * tt / 3600.0 + rng.normal(0, 1.0, tt.size)
        cfg = tie_config(
            {
                "base_gravity_mgal": g_base,
                "before": {"start_s": 0, "stop_s": 599},
                "after": {"start_s": float(t_end - 600), "stop_s": float(t_end)},
            }
        )
        tie = tie_flight(cfg, tt, np.full(tt.size, lat_b), np.full(tt.size, h_b), z)
        assert abs(tie.drift_mgal_per_h - drift) < 0.2
        tied[f] = tie
    tied_lines = []
    for ln in lines:
        ln = dict(ln)
        ln["value_mgal"] = ln["value_mgal"] - tied[ln["flight"]].correction(ln["time_s"])
        tied_lines.append(ln)
    xo = find_crossovers(tied_lines)
    lev = level_survey(xo, tied_lines, LevellingOptions(model="constant"), tied_flights=list(flights))
    assert lev.datum == "tied flights"
    err = np.concatenate(
        [
            ln["value_mgal"] - lev.correction(ln["flight"], ln["line"], ln["time_s"]) - ln["truth_mgal"]
            for ln in tied_lines
        ]
    )
    assert abs(err.mean()) < 0.3  # absolute level
    assert lev.after["rms_over_sqrt2_mgal"] < 0.3  # per-line noise is 0.2 mGal
    # without ties the level is off by the mean flight offset (~1.2 mGal here): the test can fail
    raw = np.concatenate([ln["value_mgal"] - ln["truth_mgal"] for ln in lines])
    assert abs(raw.mean()) > 0.5


def test_robust_levelling_resists_an_outlier():
    lines, _ = simulated_survey(seed=5, noise_mgal=0.1)
    xo = find_crossovers(lines)
    xo.diff_mgal[3] += 25.0  # a spike at one crossover
    lev_r = level_survey(xo, lines, LevellingOptions(model="constant", robust=True))
    lev_p = level_survey(xo, lines, LevellingOptions(model="constant", robust=False))
    assert lev_r.weight[3] < 0.2
    # with the outlier out, the other residuals are at the noise level; plain LS spreads it
    good = np.arange(len(xo)) != 3
    rr = np.sqrt(np.mean(lev_r.residual_mgal[good] ** 2))
    rp = np.sqrt(np.mean(lev_p.residual_mgal[good] ** 2))
    assert rr < 1.0 < rp


def test_exact_constants_small_network():
    # 2 lines x 2 ties, offsets known exactly, no noise: constants recovered (mean-zero datum)
    off = np.array([1.0, -2.0, 0.5, 0.5])
    pairs = [(0, 2), (0, 3), (1, 2), (1, 3)]
    d = np.array([off[a] - off[b] for a, b in pairs])
    lev = level_crossovers(
        d,
        [p[0] for p in pairs],
        [p[1] for p in pairs],
        np.zeros(4),
        np.zeros(4),
        [("F", f"L{i}") for i in range(4)],
        np.zeros(4),
        robust=False,
    )
    np.testing.assert_allclose(lev.constant_mgal, off - off.mean(), atol=1e-9)
    assert lev.after["rms_mgal"] < 1e-9


def test_unconnected_line_is_not_levelled():
    d = np.array([1.0])
    lev = level_crossovers(d, [0], [1], [0.0], [0.0], [("F", "L1"), ("F", "L2"), ("F", "L3")], np.zeros(3))
    assert list(lev.levelled) == [True, True, False]
    assert lev.constant_mgal[2] == 0.0
    assert any("without crossovers" in n for n in lev.notes)


def test_options_and_tie_config_errors():
    with pytest.raises(ConfigError, match="levelling.model"):
        levelling_options({"model": "quadratic"})
    with pytest.raises(ConfigError, match="levelling.huber_kk: unknown key"):
        levelling_options({"huber_kk": 1})
    with pytest.raises(
        ConfigError, match=r"^flights\[0\]\.tie\.base_gravity_mgal: expected a number in \[970000, 990000\], got 9\.81$"
    ):
        tie_config({"base_gravity_mgal": 9.81, "before": {"reading_mgal": 980000.0}})
    with pytest.raises(ConfigError, match="missing required key"):
        tie_config({"before": {"reading_mgal": 980000.0}})
    with pytest.raises(ConfigError, match="either reading_mgal"):
        tie_config({"base_gravity_mgal": 980000.0, "before": {"reading_mgal": 980001.0, "start_s": 1}})
    with pytest.raises(ConfigError, match="needs a base reading"):
        tie_config({"base_gravity_mgal": 980000.0})
    cfg = tie_config({"base_gravity_mgal": 980000.0, "before": {"start_s": 5000, "stop_s": 6000}})
    with pytest.raises(DataError, match="holds no estimate"):
        tie_flight(cfg, np.arange(100.0), np.zeros(100), np.zeros(100), np.zeros(100))


def test_value_ties_linear_drift():
    cfg = tie_config(
        {
            "base_gravity_mgal": 980100.0,
            "before": {"reading_mgal": 980102.0, "time_s": 0},
            "after": {"reading_mgal": 980103.0, "time_s": 7200},
        }
    )
    t = np.array([0.0, 3600.0, 7200.0])
    tie = tie_flight(cfg, t, np.zeros(3), np.zeros(3), np.zeros(3))
    np.testing.assert_allclose(tie.correction(t), [2.0, 2.5, 3.0])
    assert tie.drift_mgal_per_h == pytest.approx(0.5)


def test_against_gmt_x2sys():
    """Crossovers and constant-per-line corrections agree with GMT x2sys_cross/x2sys_solve."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from benchmarks.bench_levelling_gmt import compare, gmt_available

    if not gmt_available():
        pytest.skip("GMT (gmt x2sys_*) not installed: the GMT comparison is skipped (Debian: apt-get install gmt)")
    r = compare()
    assert r["n_gravsurvey"] == r["n_gmt"] == r["n_matched"] == 32
    assert r["max_position_m"] < 0.01  # text export rounds positions to 1 mm
    assert r["max_value_mgal"] < 2e-4  # and values to 1e-4 mGal
    assert r["max_correction_mgal"] < 2e-4


def _one_flight_survey(tmp_path, flight, *, tie=None, plots=False, grid=None):
    """The SurveyConfig of a survey of one processed flight (the output stage alone)."""
    from types import SimpleNamespace

    from gravsurvey.config import SurveyConfig
    from gravsurvey.geodesy import WGS84

    cfg_path = tmp_path / "survey.yaml"
    cfg_path.write_text("survey: {name: t}\n")
    return SurveyConfig(
        path=cfg_path,
        base_dir=tmp_path,
        raw={"survey": {"name": "t"}},
        name="t",
        ellipsoid=WGS84,
        flights=[SimpleNamespace(name=flight.name, tie=tie, index=0)],
        model=None,
        lines=None,
        postprocess=None,
        plots=plots,
        levelling=LevellingOptions(),
        grid=grid,
    )


def test_survey_outputs_tie_level_grid_and_metadata(tmp_path):
    """The output stage end to end on a synthetic processed flight: tie, levelling, grid, metadata."""
    import json
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from benchmarks.bench_outputs import synthetic_flight
    from gravsurvey.grid import GridOptions
    from gravsurvey.io.writers import read_profiles_csv, read_xyz
    from gravsurvey.pipeline import write_survey_outputs

    r = synthetic_flight(0, n_main=8, n_tie=3)  # 24 crossovers for 10 unknowns: levelled
    tie = tie_config(
        {"base_gravity_mgal": 980_800.0, "before": {"reading_mgal": 980_802.0}, "after": {"reading_mgal": 980_802.0}}
    )
    # one damping, 2 folds: fast
    cfg = _one_flight_survey(tmp_path, r, tie=tie, plots=True, grid=GridOptions(damping=1.0, cv_folds=2))
    out = tmp_path / "out"
    summary = write_survey_outputs(cfg, out, [r])
    assert summary["level"]["state"] == "absolute"
    assert summary["flights"][r.name]["tie"]["offset_before_mgal"] == pytest.approx(2.0)
    assert summary["levelling"]["applied"] and summary["levelling"]["datum"] == "tied flights"
    assert summary["levelling"]["after"]["rms_mgal"] < summary["levelling"]["before"]["rms_mgal"]
    assert summary["grid"]["cv_rms_mgal"] > 0 and summary["grid"]["spacing_m"] == pytest.approx(750.0, rel=0.01)
    for f in ("grid.nc", "grid_map.png", "levelling.png", "profiles.csv", "profiles.xyz", "lines.geojson"):
        assert (out / f).is_file(), f
    # the grid's sigma layer, from the profiles' stated sigma
    gs = summary["grid"]["sigma"]
    assert gs["data_sigma_from"] == "stated" and gs["median_mgal"] > 0
    import xarray as xr

    with xr.open_dataset(out / "grid.nc", engine="scipy") as ds:
        sig = ds["gravity_disturbance_sigma"].values
        assert np.array_equal(np.isfinite(sig), np.isfinite(ds["gravity_disturbance"].values))
        assert np.nanmedian(sig) == pytest.approx(gs["median_mgal"], rel=1e-3)
    prof = read_profiles_csv(out / "profiles.csv")
    line = prof["line"].astype(str) != ""
    shift = prof["disturbance_mgal"][line] - prof["levelled_mgal"][line]
    # the tie's 2 mGal plus levelling constants whose mean over the tied lines is zero
    assert np.mean(shift) == pytest.approx(2.0, abs=0.15)
    head = (out / "profiles.csv").read_text().splitlines()[:8]
    assert "# survey: t" in head and any(h.startswith("# crs:") and "EPSG:" in h for h in head)
    assert any(h.startswith("# software: gravsurvey") for h in head)
    xyz = read_xyz(out / "profiles.xyz")
    assert "levelled_mgal" in xyz.columns
    assert any(c.startswith("crs:") and "UTM" in c for c in xyz.comments)
    gj = json.loads((out / "lines.geojson").read_text())
    assert gj["metadata"]["survey"] == "t" and gj["metadata"]["level"] == "absolute"
    assert gj["metadata"]["crs"]["projected_epsg"] == summary["crs_epsg"]
    assert "processing" in gj["metadata"] and "units" in gj["metadata"]


def test_config_sections_validated_with_key_paths(tmp_path):
    import yaml

    from gravsurvey.config import load_config

    root = __import__("pathlib").Path(__file__).resolve().parents[1] / "sample_data" / "seed_line"
    base = yaml.safe_load((root / "survey.yaml").read_text())
    for fl in base["flights"]:
        for k, v in list(fl.get("inputs", {}).items()):
            fl["inputs"][k] = str(root / v)
        fl.pop("truth", None)

    def load(**changes):
        d = {**base, **{k: v for k, v in changes.items() if k != "tie"}}
        if "tie" in changes:
            d["flights"] = [dict(base["flights"][0], tie=changes["tie"])]
        p = tmp_path / "s.yaml"
        p.write_text(yaml.safe_dump(d))
        return load_config(p)

    cfg = load(
        levelling={"model": "flight_trend"},
        grid={"spacing_m": 250},
        tie={"base_gravity_mgal": 980500.0, "before": {"start_s": 0, "stop_s": 60}},
    )
    assert cfg.levelling.model == "flight_trend" and cfg.grid.spacing_m == 250.0
    assert cfg.flights[0].tie.before.stop_s == 60.0
    default = load()
    assert default.levelling.enabled is None and default.grid.enabled is None and default.flights[0].tie is None
    with pytest.raises(ConfigError, match=r"^levelling.modle: unknown key \(did you mean 'model'\?\)"):
        load(levelling={"modle": "constant"})
    with pytest.raises(ConfigError, match=r"^grid.cv_folds: expected an integer >= 2"):
        load(grid={"cv_folds": 1})
    with pytest.raises(ConfigError, match=r"^flights\[0\].tie.after: a window needs both start_s and stop_s"):
        load(tie={"base_gravity_mgal": 980500.0, "after": {"start_s": 5}})


# ---------------------------------------------------------------- the automatic decision (enabled: null)
def _grid_crossovers(n_lines, n_ties, line_off, tie_off, noise, rng, flights=None):
    """Crossover differences of ``n_lines`` x ``n_ties`` crossing lines with known offsets."""
    keys = [(flights[0] if flights else "F", f"L{i}") for i in range(n_lines)]
    keys += [(flights[1] if flights else "F", f"T{j}") for j in range(n_ties)]
    off = np.concatenate([line_off, tie_off])
    a = np.repeat(np.arange(n_lines), n_ties)
    b = n_lines + np.tile(np.arange(n_ties), n_lines)
    d = off[a] - off[b] + rng.normal(0.0, noise, a.size)
    t = np.zeros(a.size)
    return d, a, b, t, keys, off


def _decide(d, a, b, t, keys, **opt):
    """choose_levelling on raw crossover arrays (a tiny Crossovers look-alike)."""
    from types import SimpleNamespace

    from gravsurvey.levelling import choose_levelling

    xo = SimpleNamespace(
        flight_a=np.array([keys[i][0] for i in a]),
        line_a=np.array([keys[i][1] for i in a]),
        flight_b=np.array([keys[i][0] for i in b]),
        line_b=np.array([keys[i][1] for i in b]),
        time_a_s=t,
        time_b_s=t,
        diff_mgal=d,
    )
    lines = [
        {"flight": f, "line": ln, "time_s": np.array([0.0, 1.0]), "sigma_mgal": np.array([0.2, 0.2])} for f, ln in keys
    ]
    return choose_levelling(xo, lines, LevellingOptions(**opt))


def test_decision_applies_real_level_errors_and_declines_noise():
    rng = np.random.default_rng(7)
    # 4 lines x 4 ties (16 crossovers, 7 unknowns): line offsets of 1 mGal RMS, 0.3 mGal noise
    d, a, b, t, keys, off = _grid_crossovers(4, 4, rng.normal(0, 1.0, 4), rng.normal(0, 1.0, 4), 0.3, rng)
    lev = _decide(d, a, b, t, keys)
    dec = lev.decision
    assert dec["applied"] and dec["model"] == "constant", dec
    assert dec["tried"][0]["p_value"] < 1e-3 and dec["tried"][0]["redundancy"] == 16 - 7
    # the corrections recover the offsets (datum: mean zero) to about the noise
    assert np.abs(lev.constant_mgal - (off - off.mean())).max() < 0.5
    # the same survey without level errors: the F-test declines at the 5 % level in about 5 %
    # of surveys (the test's size): count over 200 noise-only surveys
    declined = 0
    for k in range(200):
        d, a, b, t, keys, _ = _grid_crossovers(4, 4, np.zeros(4), np.zeros(4), 0.3, rng)
        declined += not _decide(d, a, b, t, keys).decision["applied"]
    # binomial(200, 0.95): mean 190, sd 3.1
    assert 180 <= declined <= 199, declined
    lev = _decide(d, a, b, t, keys, enabled=True)
    assert lev.decision["applied"] and lev.decision["rule"].startswith("forced")


def test_too_few_crossovers_fall_back_to_one_constant_per_flight():
    rng = np.random.default_rng(3)
    # flight A flies 3 lines, flight B 2 ties: 6 crossovers for 4 line unknowns (too few);
    # the flights differ by 2.5 mGal, lines by 0.1 mGal, noise 0.3 mGal
    d, a, b, t, keys, off = _grid_crossovers(
        3, 2, 1.0 + rng.normal(0, 0.1, 3), -1.5 + rng.normal(0, 0.1, 2), 0.3, rng, flights=("A", "B")
    )
    lev = _decide(d, a, b, t, keys)
    dec = lev.decision
    assert [x["model"] for x in dec["tried"]] == ["constant", "flight_constant"]
    assert not dec["tried"][0]["enough_crossovers"] and dec["tried"][1]["n_unknowns"] == 1
    assert dec["applied"] and dec["model"] == "flight_constant", dec
    # one constant per flight, mean zero: +1.25 and -1.25 within the noise / sqrt(6)
    ca = lev.constant_mgal[[i for i, k in enumerate(keys) if k[0] == "A"]]
    cb = lev.constant_mgal[[i for i, k in enumerate(keys) if k[0] == "B"]]
    assert np.ptp(ca) == 0 and np.ptp(cb) == 0
    assert abs((ca[0] - cb[0]) - 2.5) < 0.4
    # a single flight has no flight-level fallback: too few crossovers, nothing applied
    d, a, b, t, keys, _ = _grid_crossovers(3, 2, rng.normal(0, 1, 3), rng.normal(0, 1, 2), 0.3, rng)
    dec = _decide(d, a, b, t, keys).decision
    assert not dec["applied"] and "too few crossovers" in dec["reason"]
    # the message names the rule it failed and the counts
    assert "it needs at least 2 crossovers per unknown" in dec["reason"], dec["reason"]
    assert "constant 6 for 4 unknowns" in dec["reason"], dec["reason"]
    assert [x["model"] for x in dec["tried"]] == ["constant"]


def test_significance_option_validated():
    assert levelling_options({"significance": 0.01}).significance == 0.01
    with pytest.raises(ConfigError, match=r"^levelling\.significance: expected a number in \(0, 1\), got 5"):
        levelling_options({"significance": 5})
    assert levelling_options({"model": "flight_constant"}).model == "flight_constant"


def test_decision_on_the_simulated_survey_applies_constant():
    """The multi-flight survey with per-flight offsets and drifts: the rule levels it."""
    from gravsurvey.levelling import choose_levelling

    lines, _ = simulated_survey(seed=3)
    lev = choose_levelling(find_crossovers(lines), lines)
    t = lev.decision["tried"][0]
    assert lev.decision["applied"] and lev.decision["model"] == "constant"
    assert (t["n_observations"], t["n_unknowns"]) == (32, 11) and t["p_value"] < 1e-10


def test_understated_sigma_is_reported_from_the_crossovers():
    """The robust unit-weight sigma of the crossovers is about 1 when the lines' stated sigma
    (0.2 mGal each, so 0.28 per crossover) is right, whatever their level errors, and unmoved by
    one wild crossover; crossovers 3.5 times noisier than stated give the warning."""
    from gravsurvey.levelling import SIGMA0_UNDERSTATED, understated_sigma_note

    rng = np.random.default_rng(11)
    stated = 0.2 * np.sqrt(2.0)
    s0 = []
    for k in range(200):
        d, a, b, t, keys, _ = _grid_crossovers(6, 6, rng.normal(0, 1.0, 6), rng.normal(0, 1.0, 6), stated, rng)
        lev = _decide(d, a, b, t, keys, enabled=True)
        s0.append(lev.sigma0_robust)
        assert understated_sigma_note(lev) is None
    assert 0.9 < np.mean(s0) < 1.1 and max(s0) < SIGMA0_UNDERSTATED, (np.mean(s0), max(s0))
    d[0] += 20.0  # one wild crossover (a turn, a spike)
    lev = _decide(d, a, b, t, keys, enabled=True)
    assert lev.sigma0_robust < 1.5 and understated_sigma_note(lev) is None
    assert lev.statistics()["test"]["sigma0_robust"] == lev.sigma0_robust
    d, a, b, t, keys, _ = _grid_crossovers(6, 6, rng.normal(0, 1.0, 6), rng.normal(0, 1.0, 6), 3.5 * stated, rng)
    lev = _decide(d, a, b, t, keys, enabled=True)
    note = understated_sigma_note(lev)
    assert 2.5 < lev.sigma0_robust < 5.0 and note and "understates" in note and "36 crossovers" in note, note
    # too few crossovers to say (redundancy 16 - 7 = 9 < 10): no judgement
    d, a, b, t, keys, _ = _grid_crossovers(4, 4, np.zeros(4), np.zeros(4), 3.5 * stated, rng)
    assert understated_sigma_note(_decide(d, a, b, t, keys, enabled=True)) is None


@pytest.mark.parametrize("sigma_mgal, warned", [(0.5, False), (0.05, True)])
def test_survey_warns_when_crossovers_exceed_the_stated_sigma(tmp_path, sigma_mgal, warned):
    """The survey stage end to end: a flight whose samples carry 0.5 mGal of white noise, stated
    as 0.5 mGal (consistent: no note) or as 0.05 mGal (the crossovers show it: a warning in the
    summary's notes and sigma0_robust in levelling.test; the levelling's 0.1 mGal sigma floor
    makes that 0.1, about 5x under the truth)."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from benchmarks.bench_outputs import synthetic_flight
    from gravsurvey.pipeline import write_survey_outputs

    r = synthetic_flight(0, n_main=8, n_tie=3)
    r.sigma = np.full(r.time.size, sigma_mgal * MGAL)
    summary = write_survey_outputs(_one_flight_survey(tmp_path, r), tmp_path / "out", [r])
    s0 = summary["levelling"]["test"]["sigma0_robust"]
    notes = [n for n in summary["notes"] if "understates" in n]
    if warned:
        assert 3.0 < s0 < 7.0 and len(notes) == 1, (s0, summary["notes"])
    else:
        assert 0.5 < s0 < 1.5 and not notes, (s0, summary["notes"])


def test_crossovers_carry_heights_and_the_continuation_taken_off():
    from gravsurvey.crossovers import with_continuation

    # a north-south line at 600 m and an east-west line climbing 900 -> 1100 m, crossing at (0, 0)
    n = np.linspace(-1000.0, 1000.0, 21)
    a = line("F1", "L1", np.zeros(21), n, np.full(21, 5.0), np.arange(21.0))
    a["height_m"] = np.full(21, 600.0)
    b = line("F1", "T1", n, np.zeros(21), np.full(21, 2.0), 100.0 + np.arange(21.0))
    b["height_m"] = np.linspace(900.0, 1100.0, 21)
    x = find_crossovers([a, b])
    assert len(x) == 1
    assert x.height_a_m[0] == pytest.approx(600.0) and x.height_b_m[0] == pytest.approx(1000.0)
    assert x.continuation_mgal[0] == 0.0 and x.diff_mgal[0] == pytest.approx(3.0)
    y = with_continuation(x, [2.5])
    assert y.diff_mgal[0] == pytest.approx(0.5) and y.value_a_mgal[0] == pytest.approx(5.0)
    assert y.continuation_mgal[0] == 2.5 and x.diff_mgal[0] == pytest.approx(3.0)  # a copy
    assert y.statistics()["per_line"]["F1/L1"]["mean_mgal"] == pytest.approx(0.5)
    with pytest.raises(DataError, match="2 continuation values for 1 crossovers"):
        with_continuation(x, [1.0, 2.0])
    # lines without heights: NaN heights, nothing to continue
    del a["height_m"], b["height_m"]
    z = find_crossovers([a, b])
    assert np.isnan(z.height_a_m[0]) and np.isnan(z.height_b_m[0])


def line(flight, name, e, n, v, t):
    return {"flight": flight, "line": name, "easting_m": e, "northing_m": n, "value_mgal": v, "time_s": t}


def _two_height_survey(line_alt=600.0, tie_alt=1000.0, seed=1):
    """Six north-south lines at ``line_alt`` and three east-west ties at ``tie_alt`` over 40
    buried point masses (a field of ~10 mGal RMS), each line with its own level error (1 mGal
    RMS) and 0.2 mGal white noise: lines as :func:`find_crossovers` takes them, with ``truth``."""
    import harmonica as hm

    rng = np.random.default_rng(seed)
    src = (rng.uniform(0, 12000, 40), rng.uniform(0, 12000, 40), -rng.uniform(500, 3000, 40))
    mass = rng.normal(0, 3e12, 40) * (np.abs(src[2]) / 1000) ** 2
    lines, t0 = [], 0.0
    legs = [(f"L{i + 1:02d}", 1000.0 + 2000.0 * i, None, line_alt) for i in range(6)]
    legs += [(f"T{j + 1:02d}", None, 2000.0 + 4000.0 * j, tie_alt) for j in range(3)]
    for name, e0, n0, alt in legs:
        s = np.arange(0.0, 12000.0, 60.0)
        e, n = (np.full(s.size, e0), s) if e0 is not None else (s, np.full(s.size, n0))
        h = np.full(s.size, alt)
        truth = hm.point_gravity((e, n, h), src, mass, field="g_z")
        value = truth + rng.normal(0, 1.0) + rng.normal(0, 0.2, s.size)
        lines.append({**line("F01", name, e, n, value, t0 + s / 60.0), "height_m": h, "truth": truth})
        t0 += 400.0
    return lines


def _levelled_error(x, lines):
    from gravsurvey.levelling import choose_levelling

    lev = choose_levelling(x, lines)
    err = np.concatenate(
        [
            ln["value_mgal"]
            - (lev.correction(ln["flight"], ln["line"], ln["time_s"]) if lev.decision["applied"] else 0.0)
            - ln["truth"]
            for ln in lines
        ]
    )
    return float(np.std(err)), lev.decision["applied"]


def test_lines_at_two_heights_are_levelled_once_the_field_between_them_is_taken_off():
    """Ties flown 400 m above the lines over a 10-mGal field: their crossovers differ by 3.3 mGal
    RMS of field (the truth at the two heights), which no level error explains; with the
    difference equivalent sources predict taken off, the level errors show and are levelled."""
    from gravsurvey.crossovers import with_continuation
    from gravsurvey.grid import continuation_difference

    lines = _two_height_survey()
    x = find_crossovers(lines)
    byname = {ln["line"]: ln for ln in lines}
    true_dh = np.array(
        [
            np.interp(ta, byname[a]["time_s"], byname[a]["truth"])
            - np.interp(tb, byname[b]["time_s"], byname[b]["truth"])
            for a, b, ta, tb in zip(x.line_a, x.line_b, x.time_a_s, x.time_b_s)
        ]
    )
    assert len(x) == 18 and np.sqrt(np.mean(true_dh**2)) > 3.0
    cat = {k: np.concatenate([ln[k] for ln in lines]) for k in ("easting_m", "northing_m", "height_m", "value_mgal")}
    labels = np.concatenate([[ln["line"]] * ln["easting_m"].size for ln in lines])
    cont, info = continuation_difference(
        cat["easting_m"], cat["northing_m"], cat["height_m"], cat["value_mgal"], labels,
        x.easting_m, x.northing_m, x.height_a_m, x.height_b_m,
    )  # fmt: skip
    # measured 0.46 mGal RMS against 3.28 of the true difference
    assert np.sqrt(np.mean((cont - true_dh) ** 2)) < 0.2 * np.sqrt(np.mean(true_dh**2))
    assert info["n_data"] > 100
    unlevelled = float(np.std(np.concatenate([ln["value_mgal"] - ln["truth"] for ln in lines])))
    raw, raw_applied = _levelled_error(x, lines)
    continued, applied = _levelled_error(with_continuation(x, cont), lines)
    exact, _ = _levelled_error(with_continuation(x, true_dh), lines)
    # measured: unlevelled 0.75, raw differences not levelled, continued 0.38, the true field
    # difference 0.25 mGal
    assert not raw_applied and raw == pytest.approx(unlevelled)
    assert applied and continued < 0.6 * unlevelled and continued < 1.7 * exact


def test_survey_stage_continues_crossovers_of_lines_at_two_heights(tmp_path):
    """Through write_survey_outputs: crossovers.csv carries both heights and the field's change
    between them, the crossover statistics are of what is left, and the levelled lines are
    nearer the truth than the processed ones."""
    import csv
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from benchmarks.bench_outputs import LAT0, LON0, R_EARTH
    from gravsurvey.estimate import FlightEstimate
    from gravsurvey.grid import GridOptions
    from gravsurvey.pipeline import write_survey_outputs

    lines = _two_height_survey()
    cols = {k: [] for k in ("e", "n", "h", "v", "truth", "line")}
    for ln in lines:
        if cols["e"]:  # a turn between legs: not a line
            cols["e"].append(np.full(30, cols["e"][-1][-1]))
            cols["n"].append(np.full(30, cols["n"][-1][-1]))
            cols["h"].append(np.linspace(cols["h"][-1][-1], ln["height_m"][0], 30))
            cols["v"].append(np.full(30, np.nan))
            cols["truth"].append(np.full(30, np.nan))
            cols["line"].append(np.full(30, "", dtype=object))
        for k, src in (
            ("e", "easting_m"),
            ("n", "northing_m"),
            ("h", "height_m"),
            ("v", "value_mgal"),
            ("truth", "truth"),
        ):
            cols[k].append(ln[src])
        cols["line"].append(np.full(ln["easting_m"].size, ln["line"], dtype=object))
    c = {k: np.concatenate(v) for k, v in cols.items()}
    m = c["e"].size
    info = {
        ln["line"]: {"kind": "tie" if ln["line"][0] == "T" else "line", "method": "synthetic", "speed_mps": 60.0}
        for ln in lines
    }
    r = FlightEstimate(
        name="F01",
        method="inm",
        t0_unix_ns=1_700_000_000_000_000_000,
        time=np.arange(m, dtype=float),
        lat=LAT0 + c["n"] / R_EARTH,
        lon=LON0 + c["e"] / (R_EARTH * np.cos(LAT0)),
        height=c["h"],
        vel_n=np.zeros((m, 3)),
        speed=np.full(m, 60.0),
        heading=np.zeros(m),
        smoothed=c["v"] * MGAL,
        forward=c["v"] * MGAL,
        sigma=np.full(m, 0.3 * MGAL),
        disturbance=c["v"] * MGAL,
        line=c["line"],
        line_info=info,
    )
    out = tmp_path / "out"
    summary = write_survey_outputs(_one_flight_survey(tmp_path, r, grid=GridOptions(enabled=False)), out, [r])
    with open(out / "crossovers.csv", newline="") as fh:
        rows = list(csv.DictReader(row for row in fh if not row.startswith("#")))
    assert len(rows) == 18
    for row in rows:
        assert {float(row["height_a_m"]), float(row["height_b_m"])} == {600.0, 1000.0}
        d = float(row["value_a_mgal"]) - float(row["value_b_mgal"]) - float(row["continuation_mgal"])
        assert float(row["diff_mgal"]) == pytest.approx(d, abs=2e-4)
    cont = np.array([float(row["continuation_mgal"]) for row in rows])
    assert np.sqrt(np.mean(cont**2)) > 2.5  # the field's change, not the lines' level errors
    # what is left is the lines' level errors (1 mGal each) and noise, not the 3.3 mGal of field
    assert summary["crossovers"]["rms_mgal"] < 2.0
    assert summary["levelling"]["applied"]
    on = c["line"] != ""
    with open(out / "profiles.csv", newline="") as fh:
        prof = list(csv.DictReader(row for row in fh if not row.startswith("#")))
    lev = np.array([float(p["levelled_mgal"]) for p in prof])[on]
    assert np.std(lev - c["truth"][on]) < 0.6 * np.std(c["v"][on] - c["truth"][on])
