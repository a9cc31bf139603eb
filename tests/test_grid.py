"""Gridding (gravsurvey.grid) against an analytic truth field: lines flown at three altitudes,
gridded by equivalent sources at one altitude, compared with the field computed there."""

from __future__ import annotations

import numpy as np
import pytest

from gravsurvey.errors import ConfigError, DataError
from gravsurvey.grid import GridOptions, grid_lines, line_spacing, thin_lines, write_grid_netcdf
from gravsurvey.settings import grid_options
from levelling_truth import random_field_survey, simulated_survey, truth_field_mgal

NOISE_MGAL = 0.2


def _survey_arrays(seed=2):
    lines, _ = simulated_survey(seed=seed, altitudes={"F1": 600.0, "F2": 1400.0, "F3": 1000.0})
    rng = np.random.default_rng(seed)
    cat = lambda k: np.concatenate([ln[k] for ln in lines])  # noqa: E731
    e, n, h = cat("easting_m"), cat("northing_m"), cat("height_m")
    v = cat("truth_mgal") + rng.normal(0, NOISE_MGAL, e.size)  # levelled data: noise only
    lab = np.concatenate([np.full(ln["time_s"].size, f"{ln['flight']}/{ln['line']}") for ln in lines])
    return e, n, h, v, lab


@pytest.fixture(scope="module")
def gridded():
    e, n, h, v, lab = _survey_arrays()
    return grid_lines(e, n, h, v, lab), (e, n, h, v, lab)


def test_grid_matches_truth_at_the_stated_altitude(gridded):
    g, _ = gridded
    assert g.line_spacing_m == pytest.approx(2000.0, rel=0.01)  # F1 and F2 lines interleave at 2 km
    assert g.spacing_m == pytest.approx(500.0, rel=0.01)
    assert g.altitude_m == pytest.approx(1000.0)  # the median flight height
    GE, GN = np.meshgrid(g.easting_m, g.northing_m)
    truth = truth_field_mgal(GE, GN, g.altitude_m)
    ok = np.isfinite(g.value_mgal)
    assert ok.mean() > 0.7  # most of the survey rectangle is filled
    err = g.value_mgal[ok] - truth[ok]
    rms = float(np.sqrt(np.mean(err**2)))
    # measured 0.16 mGal over all filled cells (field std 2.3 mGal, 0.2 mGal noise per sample)
    assert rms < 0.25, rms
    # continuation matters: the field at the lowest lines (600 m) differs from the grid altitude
    # (1000 m) by more than our error
    dz = truth_field_mgal(GE, GN, 600.0)[ok] - truth[ok]
    assert np.sqrt(np.mean(dz**2)) > 1.5 * rms
    # cross-validation score: a held-out RMS of the order of the noise, R^2 near 1
    assert 0.1 < g.cv_rms_mgal < 0.4
    assert g.cv_r2 > 0.98


def test_netcdf_is_cf_and_round_trips(gridded, tmp_path):
    import xarray as xr

    g, _ = gridded
    p = tmp_path / "grid.nc"
    write_grid_netcdf(p, g, 32632, title="test", attrs={"software": "gravsurvey x"})
    with xr.open_dataset(p, engine="scipy") as ds:
        var = ds["gravity_disturbance"]
        assert var.attrs["units"] == "mGal"
        assert var.attrs["grid_mapping"] == "crs"
        assert ds["easting"].attrs["standard_name"] == "projection_x_coordinate"
        assert ds.attrs["Conventions"] == "CF-1.8"
        assert "UTM zone 32N" in ds["crs"].attrs["spatial_ref"]
        assert ds["crs"].attrs["epsg_code"] == "EPSG:32632"
        assert float(ds.attrs["grid_altitude_m"]) == pytest.approx(g.altitude_m)
        np.testing.assert_allclose(var.values, g.value_mgal, atol=1e-4, equal_nan=True)
        sig = ds["gravity_disturbance_sigma"]
        assert sig.attrs["units"] == "mGal"
        np.testing.assert_allclose(sig.values, g.sigma_mgal, atol=1e-4, equal_nan=True)


def test_grid_map_has_tracks_scale_bar_and_crs(gridded, tmp_path):
    from gravsurvey.report import figure_grid_map, plot_grid_map

    g, (e, n, _h, _v, lab) = gridded
    fig = figure_grid_map(
        g.easting_m,
        g.northing_m,
        g.value_mgal,
        e,
        n,
        track_ids=lab,
        crs_label="EPSG:32632 WGS 84 / UTM zone 32N",
        title="t",
        sigma_mgal=g.sigma_mgal,
    )
    ax = fig.axes[0]
    gids = {a.get_gid() for a in ax.get_children()}
    assert {"grid", "tracks", "scalebar", "sigma"} <= gids
    assert "1-sigma, mGal" in [t.get_text() for t in ax.get_legend().get_texts()]
    assert any("EPSG:32632" in t.get_text() for t in ax.texts)
    assert any(t.get_text().endswith("km") for t in ax.texts)
    assert fig.axes[1].get_ylabel() == "gravity disturbance, mGal"
    plot_grid_map(tmp_path / "m.png", g.easting_m, g.northing_m, g.value_mgal, e, n, track_ids=lab)
    assert (tmp_path / "m.png").read_bytes()[:4] == b"\x89PNG"


def test_thinning_and_spacing():
    e = np.concatenate([np.zeros(101), np.full(101, 3000.0)])
    n = np.concatenate([np.arange(101) * 10.0, np.arange(101) * 10.0])
    lab = np.array(["F/L1"] * 101 + ["F/L2"] * 101)
    te, tn, th, tv, tl = thin_lines(e, n, np.zeros(202), np.arange(202.0), lab, 100.0)
    assert te.size == 22  # 0..1000 m in 100-m bins: 11 per line (the last holds one sample)
    assert set(tl) == {"F/L1", "F/L2"}
    assert line_spacing(te, tn, tl) == pytest.approx(3000.0)
    # the samples each bin averages: 10, and 1 in the last; a gap (NaN values) leaves fewer
    *_, cnt = thin_lines(e, n, np.zeros(202), np.arange(202.0), lab, 100.0, counts=True)
    np.testing.assert_array_equal(cnt, ([10.0] * 10 + [1.0]) * 2)
    v = np.arange(202.0)
    v[23:30] = np.nan
    *_, cnt = thin_lines(e, n, np.zeros(202), v, lab, 100.0, counts=True)
    assert cnt[2] == 3.0 and cnt.sum() == 202 - 7


def test_grid_sigma_of_a_bin_counts_the_samples_it_holds(monkeypatch):
    """The stated error of a thinned point is reduced by the samples its bin holds: a line's last,
    partial bin and a bin beside a gap keep more of it than a full bin."""
    import gravsurvey.grid as grid_mod

    seen = {}
    real = grid_mod.bin_mean_variance_ratio

    def spy(bin_m, spacing_m, length_m):
        seen["bin_m"] = np.broadcast_to(np.asarray(bin_m, float), np.shape(spacing_m)).copy()
        return real(bin_m, spacing_m, length_m)

    monkeypatch.setattr(grid_mod, "bin_mean_variance_ratio", spy)
    s = np.arange(0.0, 6005.0, 10.0)
    e = np.concatenate([np.full(s.size, k * 1000.0) for k in range(4)])
    n = np.concatenate([s] * 4)
    lab = np.repeat([f"F/L{k + 1}" for k in range(4)], s.size)
    v = np.sin(e / 3000.0) + np.cos(n / 2000.0)
    v[1000:1040] = np.nan  # line 2: 400 m without values
    grid_lines(
        e, n, np.full(e.size, 500.0), v, lab, sigma_mgal=np.full(e.size, 0.2), options=GridOptions(spacing_m=250.0)
    )
    held = seen["bin_m"]
    # 250-m bins at 10-m spacing: 25 samples, 250 m; the lines' last bins hold 1 sample (10 m);
    # the bins around the gap fewer than 25
    assert held.max() == pytest.approx(250.0)
    assert np.sum(held < 250.0) >= 4 + 1
    assert held.min() == pytest.approx(10.0)


def test_grid_errors():
    with pytest.raises(ConfigError, match="grid.method"):
        grid_options({"method": "kriging"})
    with pytest.raises(ConfigError, match=r"^grid\.spacing_m: expected a number > 0, got -5$"):
        grid_options({"spacing_m": -5})
    with pytest.raises(ConfigError, match="grid.cv_folds"):
        grid_options({"cv_folds": 1})
    with pytest.raises(DataError, match="at least 2 lines"):
        grid_lines(np.arange(10.0), np.zeros(10), np.zeros(10), np.zeros(10), np.array(["F/L1"] * 10))


def test_small_survey_uses_fewer_folds():
    # two 3-km lines 1 km apart: fewer 1-km blocks than 5 folds; the grid is still made
    e = np.concatenate([np.zeros(40), np.full(40, 1000.0)])
    n = np.concatenate([np.linspace(0, 3000, 40)] * 2)
    v = np.sin(n / 1000) + e / 1000
    g = grid_lines(e, n, np.full(80, 500.0), v, np.array(["F/L1"] * 40 + ["F/L2"] * 40), GridOptions(cv_folds=5))
    assert np.isfinite(g.value_mgal).sum() > 20 and np.isfinite(g.cv_rms_mgal)


def test_large_survey_is_thinned_to_the_fit_limit(monkeypatch):
    import gravsurvey.grid as G

    monkeypatch.setattr(G, "MAX_FIT_POINTS", 200)
    e, n, h, v, lab = _survey_arrays()
    g = G.grid_lines(e, n, h, v, lab, GridOptions(damping=0.01))
    assert g.n_data <= 230 and g.thinning_m > g.spacing_m
    GE, GN = np.meshgrid(g.easting_m, g.northing_m)
    ok = np.isfinite(g.value_mgal)
    rms = np.sqrt(np.mean((g.value_mgal[ok] - truth_field_mgal(GE, GN, g.altitude_m)[ok]) ** 2))
    assert rms < 0.6, rms  # coarser along the lines, still the field (std 2.2 mGal)


def test_point_sources_match_harmonica():
    """Our Jacobian, fit and prediction (numba cannot cache harmonica's kernels; one Jacobian
    serves every damping) against harmonica's own EquivalentSources: same coefficients, same
    field, for each damping the cross-validation tries."""
    import harmonica as hm

    from gravsurvey.grid import DAMPINGS, point_source_fit, point_source_jacobian, point_source_predict

    rng = np.random.default_rng(3)
    fit = tuple(rng.uniform(0, 5000, 300) for _ in range(2)) + (rng.uniform(500, 800, 300),)
    v = rng.standard_normal(300)
    pred = tuple(rng.uniform(0, 5000, 1000) for _ in range(2)) + (np.full(1000, 700.0),)
    dampings = (1e-3,) + tuple(DAMPINGS)
    points, coefs = point_source_fit(fit, v, 2000.0, dampings)
    assert coefs.shape == (300, len(dampings))
    got = point_source_predict(pred, points, coefs, block=7 * 300)  # several blocks, all dampings
    assert got.shape == (1000, len(dampings))
    for k, damping in enumerate(dampings):
        ref = hm.EquivalentSources(depth=2000.0, damping=damping).fit(fit, v)
        for ours, theirs in zip(points, ref.points_):
            np.testing.assert_array_equal(ours, theirs)
        np.testing.assert_allclose(coefs[:, k], ref.coefs_, rtol=1e-9, atol=1e-12 * np.abs(ref.coefs_).max())
        want = ref.predict(pred)
        np.testing.assert_allclose(got[:, k], want, rtol=1e-9, atol=1e-12 * np.abs(want).max())
        one = point_source_predict(pred, points, coefs[:, k], block=7 * 300)
        np.testing.assert_allclose(one, want, rtol=1e-9, atol=1e-12 * np.abs(want).max())
    np.testing.assert_allclose(point_source_jacobian(fit, points), ref.jacobian(fit, points), rtol=1e-14)
    # the dampings differ: the fits must too (the normal matrix is not left damped between them)
    assert np.abs(coefs[:, 0] - coefs[:, -1]).max() > 1e-3 * np.abs(coefs[:, 0]).max()


def test_line_spacing_ignores_a_track_flown_again():
    # two flights over the same three lines 3 km apart (a reflight, GNSS scatter of 20 m): the
    # spacing is 3 km, not the 20 m between the passes (which thinned nothing and asked the
    # equivalent-source fit for 11,000 points: 12 GB on configs/realistic_survey.yaml)
    rng = np.random.default_rng(0)
    e, n, lab = [], [], []
    for flight in ("F1", "F2"):
        for i in range(3):
            along = np.linspace(0.0, 20000.0, 201)
            e.append(np.full(along.size, 3000.0 * i) + rng.normal(0.0, 20.0, along.size))
            n.append(along)
            lab.append(np.full(along.size, f"{flight}/L{i + 1:02d}"))
    e, n, lab = np.concatenate(e), np.concatenate(n), np.concatenate(lab)
    assert line_spacing(e, n, lab) == pytest.approx(3000.0, rel=0.02)
    # one track flown twice and nothing else: no spacing, said so
    one = np.char.endswith(lab.astype(str), "L01")
    with pytest.raises(DataError, match="within 100 m of another"):
        line_spacing(e[one], n[one], lab[one])


def test_thinning_reaches_the_fit_limit_below_the_sample_spacing(monkeypatch):
    import gravsurvey.grid as grid_module

    # a step below the sample spacing thins nothing: the thinning must still reach the limit
    monkeypatch.setattr(grid_module, "MAX_FIT_POINTS", 300)
    seen = []
    real = grid_module.point_source_jacobian

    def counting(coordinates, points):
        seen.append(points[0].size)  # one source per fitted point
        return real(coordinates, points)

    monkeypatch.setattr(grid_module, "point_source_jacobian", counting)
    e, n, h, v, lab = _survey_arrays()
    grid_lines(e, n, h, v, lab, GridOptions(spacing_m=20.0, damping=1.0))
    assert seen and max(seen) <= 300


# ---- the grid's sigma -------------------------------------------------------------------------


@pytest.mark.parametrize(
    "seed, spacing_m, noise_length_m",
    [(0, 2000.0, 0.0), (2, 4000.0, 0.0), (4, 3000.0, 3000.0)],
)
def test_grid_sigma_matches_the_error_against_the_field(seed, spacing_m, noise_length_m):
    """The sigma layer against the truth on random fields: error/sigma RMS in [0.7, 1.5] over all
    filled cells (measured 0.88, 1.02, 0.99; over 18 such surveys 0.74-1.25), and larger midway
    between the lines than on them."""
    from scipy.spatial import cKDTree

    e, n, h, v, lab, field = random_field_survey(seed, spacing_m, noise_length_m=noise_length_m)
    g = grid_lines(e, n, h, v, lab, sigma_mgal=np.full(e.size, 0.2), noise_length_m=noise_length_m or None)
    GE, GN = np.meshgrid(g.easting_m, g.northing_m)
    ok = np.isfinite(g.value_mgal)
    assert np.array_equal(ok, np.isfinite(g.sigma_mgal))
    err = g.value_mgal[ok] - field(GE[ok], GN[ok], g.altitude_m)
    err -= err.mean()  # the sigma is about the survey's level
    z = float(np.sqrt(np.mean((err / g.sigma_mgal[ok]) ** 2)))
    assert 0.7 <= z <= 1.5, z
    d = cKDTree(np.column_stack([e, n])).query(np.column_stack([GE[ok], GN[ok]]))[0]
    near, far = g.sigma_mgal[ok][d < 0.15 * spacing_m], g.sigma_mgal[ok][d > 0.35 * spacing_m]
    assert np.median(far) > 1.2 * np.median(near)
    info = g.summary()["sigma"]
    assert info["data_sigma_from"] == "stated"
    assert info["covariance"] in ("matern32", "matern52", "layer")
    assert info["median_mgal"] == pytest.approx(float(np.median(g.sigma_mgal[ok])))


def test_grid_sigma_without_stated_errors(gridded):
    """No sigma given: the points' error is what the fit leaves; on the three-mass survey the
    sigma matches the error against the field (error/sigma RMS measured 0.89)."""
    g, _ = gridded
    GE, GN = np.meshgrid(g.easting_m, g.northing_m)
    ok = np.isfinite(g.value_mgal)
    err = g.value_mgal[ok] - truth_field_mgal(GE, GN, g.altitude_m)[ok]
    z = float(np.sqrt(np.mean((err / g.sigma_mgal[ok]) ** 2)))
    assert 0.7 <= z <= 1.5, z
    assert g.summary()["sigma"]["data_sigma_from"] == "data"


def test_bin_mean_variance_ratio_against_a_direct_sum():
    from gravsurvey.grid import bin_mean_variance_ratio

    # white errors: one over the samples in the bin
    assert bin_mean_variance_ratio(500.0, np.array([100.0]), np.array([0.0]))[0] == pytest.approx(0.2)
    # correlated: the variance of the mean of 50 samples of an AR(1) sequence, summed directly
    dt, ell, c = 10.0, 200.0, 50
    i = np.arange(c)
    direct = np.exp(-np.abs(i[:, None] - i[None, :]) * dt / ell).sum() / c**2
    got = bin_mean_variance_ratio(c * dt, np.array([dt]), np.array([ell]))[0]
    assert got == pytest.approx(direct, rel=0.1)
    # a bin per point, each over the stretch its samples cover
    np.testing.assert_allclose(
        bin_mean_variance_ratio(np.array([500.0, 100.0]), np.array([100.0, 100.0]), np.array([0.0, 0.0])), [0.2, 1.0]
    )
    # errors correlated far beyond the bin: no reduction
    assert bin_mean_variance_ratio(100.0, np.array([10.0]), np.array([1e6]))[0] == pytest.approx(1.0, abs=1e-3)


def test_field_covariance_recovers_a_gaussian_process():
    """Lines drawn from a Matern-3/2 field of known variance and length: both recovered."""
    from gravsurvey.drift import matern32
    from gravsurvey.grid import field_covariance

    rng = np.random.default_rng(5)
    s = np.arange(0.0, 30000.0, 250.0)
    true_s2, true_len = 4.0, 3000.0
    cov = true_s2 * matern32(np.abs(s[:, None] - s[None, :]), true_len)
    chol = np.linalg.cholesky(cov + 1e-9 * np.eye(s.size))
    e, n, v, lab = [], [], [], []
    for k in range(40):  # independent lines (far apart)
        e.append(np.full(s.size, k * 1e6))
        n.append(s)
        v.append(chol @ rng.normal(size=s.size) + rng.normal(0.0, 0.3, s.size))
        lab.append(np.full(s.size, f"L{k}"))
    e, n, v, lab = map(np.concatenate, (e, n, v, lab))
    lengths = np.geomspace(300.0, 30000.0, 40)
    shape, s2, length, nugget = field_covariance(e, n, v, lab, np.full(e.size, 0.3), np.zeros(e.size), 12000.0, lengths)
    assert s2 == pytest.approx(true_s2, rel=0.35)
    assert length == pytest.approx(true_len, rel=0.5) or shape != "matern32"
    assert nugget >= 0.0


def test_kriging_variance_limits():
    from gravsurvey.grid import kriging_variance

    xy = np.column_stack([np.zeros(50), np.arange(50) * 100.0])
    sig = np.full(50, 0.3)
    code = np.zeros(50, int)
    ell = np.zeros(50)
    targets = np.array([[0.0, 2500.0], [50000.0, 2500.0]])
    f, err = kriging_variance(xy, sig, code, ell, targets, 4.0, 2000.0, shape="matern52")
    # on the line the field part is small; far from any data it is the field's variance and the
    # unknown level's (the neighbours' mean, itself uncertain): between s2 and 2 s2
    assert f[0] < 0.05 * 4.0
    assert 4.0 < f[1] < 8.0
    # the error part is the neighbours' (all 0.3 mGal): not averaged down across them
    np.testing.assert_allclose(err, 0.09, rtol=1e-9)
    f2, err2 = kriging_variance(xy, sig, code, ell, targets[:1], 4.0, 2000.0, target_sigma=np.array([0.3]))
    assert err2[0] == pytest.approx(0.18)


def test_sigma_notes_say_a_cross_validation_mismatch():
    from gravsurvey.grid import sigma_notes

    under = sigma_notes({"cv_rms_mgal": 2.0, "cv_rms_predicted_mgal": 1.0})
    assert len(under) == 1 and under[0].startswith("grid: the cross-validation residuals (2.00 mGal RMS)")
    assert "may under-state" in under[0]
    # smaller residuals than predicted are not said: shared errors cancel in them
    assert sigma_notes({"cv_rms_mgal": 1.40, "cv_rms_predicted_mgal": 2.83}) == []
    assert sigma_notes({"cv_rms_mgal": 1.4, "cv_rms_predicted_mgal": 1.0}) == []
    assert sigma_notes({}) == []
