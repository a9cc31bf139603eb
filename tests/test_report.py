"""Plots: valid PNGs, deterministic, showing the data they were given."""

import struct

import numpy as np
import pytest
from matplotlib.collections import PathCollection, PolyCollection

from gravsurvey import report
from gravsurvey.crossovers import find_crossovers

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def png_size(path):
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC and data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


def profile_data(n=300):
    x = np.linspace(0.0, 600.0, n)
    truth = 5 * np.sin(x / 60.0)
    kalman = truth + np.random.default_rng(0).normal(0, 1.0, n)
    final = truth + 0.3
    sigma = np.full(n, 1.2)
    return x, kalman, final, sigma, truth


def test_profile_plot_png_and_content(tmp_path):
    x, k, f, s, tr = profile_data()
    p = tmp_path / "plots" / "F01_L01.png"
    report.plot_line_profile(p, x, k, f, s, tr, title="F01 L01")
    assert png_size(p) == (1000, 450)
    fig = report.figure_line_profile(x, k, f, s, tr, title="F01 L01")
    ax = fig.axes[0]
    lines = {ln.get_label(): ln for ln in ax.get_lines()}
    assert set(lines) == {"kalman", "final", "truth"}
    np.testing.assert_array_equal(lines["kalman"].get_ydata(), k)
    np.testing.assert_array_equal(lines["truth"].get_ydata(), tr)
    band = [c for c in ax.collections if isinstance(c, PolyCollection)][0]
    verts = band.get_paths()[0].vertices
    # the band spans kalman - sigma .. kalman + sigma
    assert verts[:, 1].min() == pytest.approx((k - s).min()) and verts[:, 1].max() == pytest.approx((k + s).max())
    # RMS of final - truth = 0.3 exactly, stated in the title
    assert "RMS 0.30 mGal" in ax.get_title()
    fig2 = report.figure_line_profile(x, k, f, s)
    assert {ln.get_label() for ln in fig2.axes[0].get_lines()} == {"kalman", "final"}
    # the legend names the product as the caller says (the pipeline: the line's post-processor)
    assert [t.get_text() for t in ax.get_legend().get_texts()].count("final") == 1
    fig3 = report.figure_line_profile(x, k, f, s, final_label="final (ti_cosphi)")
    assert "final (ti_cosphi)" in [t.get_text() for t in fig3.axes[0].get_legend().get_texts()]


def test_plots_are_deterministic(tmp_path):
    x, k, f, s, tr = profile_data()
    a, b = tmp_path / "a.png", tmp_path / "b.png"
    report.plot_line_profile(a, x, k, f, s, tr)
    report.plot_line_profile(b, x, k, f, s, tr)
    assert a.read_bytes() == b.read_bytes()


def grid_lines():
    f = lambda e, n: 10 * np.sin(e / 3000.0) * np.cos(n / 4000.0)  # noqa: E731
    out = []
    for i in range(4):
        e = np.linspace(0, 12000, 200)
        nn = np.full(200, 1000.0 + 3000 * i)
        out.append(
            {
                "flight": "F01",
                "line": f"L{i + 1:02d}",
                "easting_m": e,
                "northing_m": nn,
                "value_mgal": f(e, nn) + 0.2 * i,
                "time_s": np.arange(200.0) + 1000 * i,
            }
        )
    for j in range(2):
        nn = np.linspace(0, 12000, 200)
        e = np.full(200, 2000.0 + 6000 * j)
        out.append(
            {
                "flight": "F01",
                "line": f"T{j + 1:02d}",
                "easting_m": e,
                "northing_m": nn,
                "value_mgal": f(e, nn),
                "time_s": np.arange(200.0) + 9000 + 1000 * j,
            }
        )
    return out


def test_survey_map_and_histogram(tmp_path):
    lines = grid_lines()
    x = find_crossovers(lines)
    assert len(x) == 8
    e = np.concatenate([ln["easting_m"] for ln in lines])
    n = np.concatenate([ln["northing_m"] for ln in lines])
    v = np.concatenate([ln["value_mgal"] for ln in lines])
    ids = np.concatenate([[f"{ln['flight']}/{ln['line']}"] * 200 for ln in lines])
    p = tmp_path / "map.png"
    report.plot_survey_map(p, e, n, v, ids, x, title="survey", crs_label="EPSG:32653")
    assert png_size(p) == (900, 800)
    fig = report.figure_survey_map(e, n, v, ids, x)
    ax = fig.axes[0]
    cols = {c.get_gid(): c for c in ax.collections if isinstance(c, PathCollection)}
    np.testing.assert_allclose(cols["crossovers"].get_offsets(), np.column_stack([x.easting_m, x.northing_m]) / 1e3)
    np.testing.assert_allclose(cols["tracks"].get_array(), v)
    assert sorted(t.get_text() for t in ax.texts) == sorted(set(ids))
    h = tmp_path / "hist.png"
    report.plot_crossover_histogram(h, x, title="crossovers")
    png_size(h)
    hf = report.figure_crossover_histogram(x)
    rms = np.sqrt(np.mean(x.diff_mgal**2))
    assert "n = 8" in hf.axes[0].get_title() and f"RMS {rms:.2f}" in hf.axes[0].get_title()
    counts = sum(p.get_height() for p in hf.axes[0].patches)
    assert counts == 8


def test_empty_crossovers_and_map_without_them(tmp_path):
    x = find_crossovers(grid_lines()[:2])  # two parallel lines: none
    assert len(x) == 0
    p = tmp_path / "hist.png"
    report.plot_crossover_histogram(p, x)
    png_size(p)
    assert "no crossovers" in report.figure_crossover_histogram(x).axes[0].get_title()
    q = tmp_path / "map.png"
    report.plot_survey_map(q, [0, 1, 2], [0, 0, 0], [np.nan, 1.0, 2.0], ["a", "a", "a"])
    png_size(q)


def _layout_figures():
    """Figures whose margins come from report's own layout: small and large values (offset
    texts "1e6"), long titles and labels, two panels, the map with its colour bar, the
    histogram with and without crossovers."""
    from types import SimpleNamespace

    x, kalman, final, sigma, truth = profile_data()
    hz = {c: np.sin(x / 50 + i) for i, c in enumerate(("dg_north_mgal", "dg_east_mgal"))}
    hz.update({c: np.full_like(x, 0.5) for c in ("dg_north_sigma_mgal", "dg_east_sigma_mgal")})
    s = -3e4
    yield report.figure_line_profile(x, kalman, final, sigma, truth, title="L1")
    yield report.figure_line_profile(x * 1e4, kalman * s, final * s, sigma, truth * s, title="a long title " * 9)
    yield report.figure_line_profile(x, kalman * 1e-7, final * 1e-7, None, title="", x_label="time, s")
    yield report.figure_line_profile(x, kalman, final, sigma, truth, title="two panels", horizontal=hz)
    t = np.linspace(0.0, 1.0, 200)
    e = np.concatenate([700e3 + 400 * t, 700e3 + 400 * t[::-1]])
    n = np.concatenate([4980e3 + 0.3 * t, 4980e3 + 50 + 0.3 * t])
    ids = np.where(np.arange(400) < 200, "F01/L1", "F01/A_LONG_LINE_NAME")
    yield report.figure_survey_map(e, n, np.sin(np.arange(400) / 30) * 40, ids, title="tiny survey")
    yield report.figure_survey_map(e * 10, n * 3, np.arange(400.0) * 1e4, ids, crs_label="EPSG:32632 UTM 32N")
    rng = np.random.default_rng(0)
    yield report.figure_crossover_histogram(SimpleNamespace(diff_mgal=rng.normal(3e5, 2e4, 500)), title="X")
    yield report.figure_crossover_histogram(None, title="none")


@pytest.mark.parametrize("k", range(8))
def test_layout_matches_tight_layout(k):
    """The margins computed from text metrics fit the decorations as matplotlib's tight_layout
    does (same padding): within 1 px of it, so nothing is clipped that tight_layout shows."""
    fig = list(_layout_figures())[k]
    ours = {a: getattr(fig.subplotpars, a) for a in ("left", "right", "top", "bottom", "hspace")}
    fig.tight_layout()
    ref = {a: getattr(fig.subplotpars, a) for a in ours}
    w, h = fig.bbox.width, fig.bbox.height
    for a, scale in (("left", w), ("right", w), ("top", h), ("bottom", h)):
        assert abs(ours[a] - ref[a]) * scale <= 1.0, (a, ours[a], ref[a])
    if len(fig.axes) > 1 and fig.axes[1].get_subplotspec().get_topmost_subplotspec().rowspan.start == 1:
        assert abs(ours["hspace"] - ref["hspace"]) < 0.01
