"""PNG plots of a run: line profiles, the survey map with crossovers, the crossover histogram.

Figures are built on matplotlib's object API with the Agg canvas (no pyplot, no display, no
global backend switch), so plotting works in cron, CI and worker processes, and the same inputs
give byte-identical PNGs for a given matplotlib version. Each ``plot_*`` function writes the PNG
atomically and returns nothing; the matching ``figure_*`` function returns the
:class:`matplotlib.figure.Figure` (for tests and for callers that want other formats).
"""

from __future__ import annotations

import io
import math
from typing import TYPE_CHECKING

import numpy as np

from gravsurvey.io.writers import atomic_write_bytes

if TYPE_CHECKING:  # matplotlib is imported only when a figure is made (~0.6 s saved otherwise)
    from matplotlib.figure import Figure

__all__ = [
    "figure_line_profile",
    "plot_line_profile",
    "figure_survey_map",
    "plot_survey_map",
    "figure_crossover_histogram",
    "plot_crossover_histogram",
]

_DPI = 100
# Fixed PNG metadata: no timestamps, so identical inputs give identical files.
_METADATA = {"Software": "gravsurvey"}


def _new_figure(figsize) -> Figure:
    """A matplotlib Figure on an Agg canvas (imported here, on first use: runs without plots
    never load it).

    The canvas is attached now, not at saving, so that :func:`_fit_layout` measures text with
    the renderer that later draws the PNG (same size and dpi): text metrics are cached per
    renderer, and each label is measured once.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, dpi=_DPI)
    FigureCanvasAgg(fig)
    return fig


# tight_layout's default padding around the figure and between rows, in font sizes
_PAD_FONTSIZES = 1.08
# matplotlib's fixed distance of an axis' offset text ("1e6") from the tick labels, pt
_OFFSET_TEXT_PAD_PT = 3.0


def _visible_tick_labels(axis):
    """The tick labels of ``axis`` that are drawn: non-empty, visible, tick inside the view."""
    lo, hi = sorted(axis.get_view_interval())
    tol = 1e-10 * max(abs(hi - lo), 1e-300)
    locs = axis.get_majorticklocs()
    labels = axis.get_majorticklabels()  # updates the ticks' positions and texts
    ticks = axis.get_major_ticks(len(locs))
    drawn = {id(t.label1) for t, x in zip(ticks, locs) if lo - tol <= x <= hi + tol}
    drawn |= {id(t.label2) for t, x in zip(ticks, locs) if lo - tol <= x <= hi + tol}
    return [lb for lb in labels if id(lb) in drawn and lb.get_visible() and lb.get_text()]


def _decorations_bbox(ax, renderer):
    """Display-space box (px) of ``ax`` with everything drawn around it: tick labels, axis
    labels, offset texts, title, texts and annotations.

    Computed from text metrics and matplotlib's fixed placement rules (axis label ``labelpad``
    beyond the tick labels, offset text 3 pt beyond them, title at ``titlepad`` above the axes)
    instead of ``Axes.get_tightbbox``, which recomputes every axis' ticks several times (the
    draw that follows does it once more).
    """
    from matplotlib.transforms import Bbox

    px = ax.figure.dpi / 72.0
    ax.apply_aspect()
    box = ax.get_window_extent(renderer)
    boxes = [box]
    y_off = None
    for axis, side in ((ax.xaxis, "x"), (ax.yaxis, "y")):
        if not (ax.axison and axis.get_visible()):
            continue
        tl = [lb.get_window_extent(renderer) for lb in _visible_tick_labels(axis)]
        boxes += tl
        tb = Bbox.union(tl + [box])
        label, offset = axis.label, axis.get_offset_text()
        # the draw sets the offset text ("1e6") from the formatter the tick labels just used
        offset.set_text(axis.get_major_formatter().get_offset())
        lab = label.get_window_extent(renderer) if label.get_visible() and label.get_text() else None
        off = offset.get_window_extent(renderer) if offset.get_visible() and offset.get_text() else None
        if side == "x":
            below = axis.get_label_position() == "bottom"
            edge = tb.y0 if below else tb.y1
            if lab is not None:
                # width taken as 1 px at the label's centre, as tight_layout does: a long label
                # may overhang the axes but must not squeeze them
                gap, h, cx = axis.labelpad * px, lab.height, 0.5 * (box.x0 + box.x1)
                y0, y1 = (edge - gap - h, edge - gap) if below else (edge + gap, edge + gap + h)
                boxes.append(Bbox.from_extents(cx - 0.5, y0, cx + 0.5, y1))
            if off is not None:
                g = _OFFSET_TEXT_PAD_PT * px
                y0, y1 = (tb.y0 - g - off.height, tb.y0) if below else (tb.y1, tb.y1 + g + off.height)
                boxes.append(Bbox.from_extents(box.x1 - off.width, y0, box.x1, y1))
        else:
            left = axis.get_label_position() == "left"
            edge = tb.x0 if left else tb.x1
            if lab is not None:
                gap, w, cy = axis.labelpad * px, lab.width, 0.5 * (box.y0 + box.y1)
                x0, x1 = (edge - gap - w, edge - gap) if left else (edge + gap, edge + gap + w)
                boxes.append(Bbox.from_extents(x0, cy - 0.5, x1, cy + 0.5))
            if off is not None:
                g = _OFFSET_TEXT_PAD_PT * px
                x0 = box.x0 if left else box.x1 - off.width
                # placed on its baseline 3 pt above the axes; a line's descent is at least that of
                # "lp" (matplotlib's text layout rule)
                fp = offset.get_fontproperties()
                d = max(renderer.get_text_width_height_descent(t, fp, False)[2] for t in (offset.get_text(), "lp"))
                y_off = Bbox.from_extents(x0, box.y1 + g - d, x0 + off.width, box.y1 + g - d + off.height)
                boxes.append(y_off)
    if ax.title.get_visible() and ax.title.get_text():
        tb = ax.title.get_window_extent(renderer)
        if y_off is not None and tb.overlaps(y_off) and tb.y0 < y_off.y1:
            # matplotlib raises a title that would overlap the y axis' offset text ("1e6"): its
            # anchor, then at titlepad below its baseline, moves from the axes top to the text's
            tb = Bbox.from_extents(tb.x0, tb.y0 + y_off.y1 - box.y1, tb.x1, tb.y1 + y_off.y1 - box.y1)
        # zero width as in tight_layout: a long title may overhang the axes, not squeeze them
        cx = 0.5 * (tb.x0 + tb.x1)
        boxes.append(Bbox.from_extents(cx - 0.5, tb.y0, cx + 0.5, tb.y1))
    for t in ax.texts:
        if t.get_visible() and t.get_in_layout() and t.get_text():
            boxes.append(t.get_window_extent(renderer))
    return Bbox.union(boxes)


def _fit_layout(fig: Figure) -> None:
    """Set the subplot margins and row spacing so that every axes' decorations fit, as
    ``fig.tight_layout()`` would (same padding, same rule: the overhang of each axes'
    decorations beyond its top-level grid cell), without its repeated tick computations.

    For figures whose axes sit in one column of a top-level grid (rows may hold nested grids,
    e.g. an axes and its colour bar).
    """
    from matplotlib import rcParams

    renderer = fig.canvas.get_renderer()
    W, H = fig.bbox.width, fig.bbox.height
    pad = _PAD_FONTSIZES * float(rcParams["font.size"]) * fig.dpi / 72.0  # px
    nrows = None
    left = right = 0.0
    top, bottom = {}, {}
    for ax in fig.axes:
        ss = ax.get_subplotspec()
        if ss is None:
            continue
        top_ss = ss.get_topmost_subplotspec()
        nrows = top_ss.get_gridspec().nrows
        cell = top_ss.get_position(fig).transformed(fig.transFigure)
        deco = _decorations_bbox(ax, renderer)
        left = max(left, cell.x0 - deco.x0)
        right = max(right, deco.x1 - cell.x1)
        r0, r1 = top_ss.rowspan.start, top_ss.rowspan.stop - 1
        top[r0] = max(top.get(r0, 0.0), deco.y1 - cell.y1)
        bottom[r1] = max(bottom.get(r1, 0.0), cell.y0 - deco.y0)
    if nrows is None:
        return
    lo = (pad + left) / W
    ro = 1.0 - (pad + right) / W
    to = 1.0 - (pad + top.get(0, 0.0)) / H
    bo = (pad + bottom.get(nrows - 1, 0.0)) / H
    kw = {"left": lo, "right": ro, "top": to, "bottom": bo}
    if nrows > 1:
        gap = max(bottom.get(i, 0.0) + top.get(i + 1, 0.0) + pad for i in range(nrows - 1))
        cell_h = ((to - bo) * H - (nrows - 1) * gap) / nrows
        kw["hspace"] = gap / cell_h
    fig.subplots_adjust(**kw)


def _save(fig: Figure, path) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    if not isinstance(fig.canvas, FigureCanvasAgg):
        FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=_DPI, metadata=_METADATA)
    atomic_write_bytes(path, buf.getvalue())


def figure_line_profile(
    x,
    kalman_mgal,
    final_mgal,
    sigma_mgal,
    truth_mgal=None,
    *,
    title: str = "",
    x_label: str = "time, s",
    horizontal=None,
    final_label: str = "final",
) -> Figure:
    """Figure of one line's profile.

    Parameters
    ----------
    x : array_like, shape (n,)
        Abscissa: time (s) or distance along the line (km); say which with ``x_label``.
    kalman_mgal : array_like, shape (n,), or None
        Kalman/RTS estimate before the post-processor, mGal; None for a chain without one
        (classic): then neither it nor the sigma band is drawn.
    final_mgal : array_like, shape (n,)
        Final (post-processed) gravity disturbance, mGal.
    sigma_mgal : array_like, shape (n,), or None
        Posterior standard deviation of the Kalman estimate, mGal; drawn as a band
        ``kalman_mgal +- sigma_mgal`` (1 sigma).
    truth_mgal : array_like, shape (n,), optional
        Simulator truth, mGal; when given, the RMS of ``final - truth`` is in the title.
    title : str
    x_label : str
    horizontal : dict, optional
        ``dg_north_mgal, dg_east_mgal, dg_north_sigma_mgal, dg_east_sigma_mgal`` arrays of shape
        (n,) (NaN where not observable): drawn in a second panel below, with 1-sigma bands.
    final_label : str
        Legend entry of ``final_mgal`` (the pipeline names the line's post-processor:
        ``final (smoothed)`` for the default product, ``final (ti_cosphi)``, ...).

    Returns
    -------
    matplotlib.figure.Figure
        Artists labelled ``kalman``, ``final``, ``truth`` (lines) and ``sigma`` (band) in the
        first axes; ``dg_north``, ``dg_east`` (lines) and their bands in the second.
    """
    x = np.asarray(x, float)
    f = np.asarray(final_mgal, float)
    fig = _new_figure((10, 4.5) if horizontal is None else (10, 7.5))
    ax = fig.add_subplot(1, 1, 1) if horizontal is None else fig.add_subplot(2, 1, 1)
    if kalman_mgal is not None:
        k = np.asarray(kalman_mgal, float)
        if sigma_mgal is not None:
            s = np.asarray(sigma_mgal, float)
            ax.fill_between(x, k - s, k + s, color="tab:blue", alpha=0.2, linewidth=0, label="sigma")
        ax.plot(x, k, color="tab:blue", linewidth=0.8, label="kalman")
    ax.plot(x, f, color="tab:red", linewidth=1.4, label="final")
    full_title = title
    if truth_mgal is not None:
        tr = np.asarray(truth_mgal, float)
        ax.plot(x, tr, color="black", linewidth=1.0, linestyle="--", label="truth")
        d = f - tr
        d = d[np.isfinite(d)]
        if d.size:
            rms = math.sqrt(float(np.mean(d**2)))
            full_title = (
                f"{title}  (final - truth: RMS {rms:.2f} mGal)" if title else f"final - truth: RMS {rms:.2f} mGal"
            )
    handles, labels = ax.get_legend_handles_labels()
    names = {"kalman": "Kalman/RTS", "final": final_label, "truth": "truth", "sigma": "Kalman ± 1σ"}
    ax.legend(handles, [names[lb] for lb in labels], loc="best", fontsize=8)
    ax.set_xlabel(x_label)
    ax.set_ylabel("gravity disturbance, mGal")
    ax.grid(True, alpha=0.3)
    if full_title:
        ax.set_title(full_title, fontsize=10)
    if horizontal is not None:
        ax2 = fig.add_subplot(2, 1, 2, sharex=ax)
        for comp, color in (("north", "tab:green"), ("east", "tab:purple")):
            v = np.asarray(horizontal[f"dg_{comp}_mgal"], float)
            sg = np.asarray(horizontal[f"dg_{comp}_sigma_mgal"], float)
            ax2.fill_between(x, v - sg, v + sg, color=color, alpha=0.2, linewidth=0, label=f"dg_{comp}_sigma")
            ax2.plot(x, v, color=color, linewidth=1.0, label=f"dg_{comp}")
        ax2.legend(loc="best", fontsize=8)
        ax2.set_xlabel(x_label)
        ax2.set_ylabel("horizontal disturbance, mGal")
        ax2.set_title("horizontal components ± 1σ (blank where not observable)", fontsize=9)
        ax2.grid(True, alpha=0.3)
    _fit_layout(fig)
    return fig


def plot_line_profile(
    path,
    x,
    kalman_mgal,
    final_mgal,
    sigma_mgal,
    truth_mgal=None,
    *,
    title: str = "",
    x_label: str = "time, s",
    horizontal=None,
    final_label: str = "final",
) -> None:
    """Write a line's profile plot as PNG (see :func:`figure_line_profile`)."""
    _save(
        figure_line_profile(
            x,
            kalman_mgal,
            final_mgal,
            sigma_mgal,
            truth_mgal,
            title=title,
            x_label=x_label,
            horizontal=horizontal,
            final_label=final_label,
        ),
        path,
    )


def _crossover_arrays(crossovers):
    if crossovers is None:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    return (
        np.asarray(crossovers.easting_m, float),
        np.asarray(crossovers.northing_m, float),
        np.asarray(crossovers.diff_mgal, float),
    )


def figure_survey_map(
    easting_m, northing_m, value_mgal, line_ids, crossovers=None, *, title: str = "", crs_label: str = ""
) -> Figure:
    """Map of the survey: tracks coloured by the anomaly, line labels, crossover marks.

    Parameters
    ----------
    easting_m, northing_m : array_like, shape (n,)
        Projected coordinates, m (drawn in km).
    value_mgal : array_like, shape (n,)
        Colour, mGal (diverging colour map centred on 0, limits at the 98th percentile of |value|).
    line_ids : array_like of str, shape (n,)
        Line label per sample (e.g. ``"F01/L01"``); each line is labelled at its first sample.
    crossovers : gravsurvey.crossovers.Crossovers, optional
        Drawn as black-edged circles, size growing with |diff_mgal|.
    title, crs_label : str

    Returns
    -------
    matplotlib.figure.Figure
        The track scatter has gid ``tracks``; the crossover scatter has gid ``crossovers``.
    """
    e = np.asarray(easting_m, float) / 1e3
    n = np.asarray(northing_m, float) / 1e3
    v = np.asarray(value_mgal, float)
    ids = np.asarray(line_ids).astype(str)
    fig = _new_figure((9, 8))
    ax = fig.add_subplot(1, 1, 1)
    fin = np.isfinite(v)
    lim = float(np.percentile(np.abs(v[fin]), 98)) if fin.any() else 1.0
    lim = lim if lim > 0 else 1.0
    # the track itself in thin grey under the colour (visible where the value is near zero), and a
    # diverging map whose centre is pale yellow, not white
    # one artist for all lines: a NaN vertex between two lines breaks the path there, as separate
    # lines would (a survey has hundreds of lines; each Line2D costs its own draw set-up)
    cut = np.flatnonzero(ids[1:] != ids[:-1]) + 1
    ax.plot(np.insert(e, cut, np.nan), np.insert(n, cut, np.nan), color="0.4", linewidth=0.5, zorder=1)
    sc = ax.scatter(e, n, c=v, s=4, cmap="RdYlBu_r", vmin=-lim, vmax=lim, linewidths=0, gid="tracks", zorder=2)
    cb = fig.colorbar(sc, ax=ax, shrink=0.8)
    cb.set_label("gravity disturbance, mGal")
    # each line labelled at its first sample, in order of appearance (one pass, not one per line)
    lids, first = np.unique(ids, return_index=True)
    for lid, i in sorted(zip(lids.tolist(), first.tolist()), key=lambda p: p[1]):
        if np.isfinite(e[i]) and np.isfinite(n[i]):
            ax.annotate(lid, (e[i], n[i]), fontsize=7, xytext=(3, 3), textcoords="offset points")
    xe, xn, xd = _crossover_arrays(crossovers)
    if xe.size:
        ad = np.abs(np.nan_to_num(xd, nan=0.0))
        size = 15 + 60 * ad / max(float(ad.max()), 1e-12)
        ax.scatter(
            xe / 1e3,
            xn / 1e3,
            s=size,
            facecolors="none",
            edgecolors="black",
            linewidths=0.8,
            gid="crossovers",
            label=f"crossovers ({xe.size}); size ~ |difference|",
        )
        ax.legend(loc="upper right", fontsize=8)
    ax.set_aspect("equal", adjustable="datalim")
    if np.isfinite(e).any():
        x0, x1 = float(np.nanmin(e)), float(np.nanmax(e))
        if x1 > x0:
            from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

            L = _nice_length_km(x1 - x0)
            bar = AnchoredSizeBar(
                ax.transData,
                L,
                f"{L:g} km",
                "lower left",
                pad=0.5,
                frameon=False,
                size_vertical=0.0,
                fontproperties={"size": 9},
            )
            bar.set_gid("scalebar")
            ax.add_artist(bar)
    suffix = f" ({crs_label})" if crs_label else ""
    ax.set_xlabel(f"easting, km{suffix}")
    ax.set_ylabel(f"northing, km{suffix}")
    ax.grid(True, alpha=0.3)
    if title:
        ax.set_title(title, fontsize=10)
    _fit_layout(fig)
    return fig


def plot_survey_map(
    path, easting_m, northing_m, value_mgal, line_ids, crossovers=None, *, title: str = "", crs_label: str = ""
) -> None:
    """Write the survey map as PNG (see :func:`figure_survey_map`)."""
    _save(
        figure_survey_map(easting_m, northing_m, value_mgal, line_ids, crossovers, title=title, crs_label=crs_label),
        path,
    )


def figure_crossover_histogram(crossovers, *, title: str = "") -> Figure:
    """Histogram of crossover differences with count, mean, RMS and RMS/sqrt(2) in the title.

    With no valid crossover the figure says so instead of drawing an empty histogram.
    """
    d = np.asarray(crossovers.diff_mgal, float) if crossovers is not None else np.zeros(0)
    d = d[np.isfinite(d)]
    fig = _new_figure((7, 4.5))
    ax = fig.add_subplot(1, 1, 1)
    if d.size == 0:
        ax.text(0.5, 0.5, "no crossovers", ha="center", va="center", transform=ax.transAxes, fontsize=14)
        ax.set_axis_off()
        stats = "no crossovers"
    else:
        nb = int(np.clip(np.sqrt(d.size) * 2, 5, 60))
        ax.hist(d, bins=nb, color="tab:gray", edgecolor="black", linewidth=0.5)
        rms = math.sqrt(float(np.mean(d**2)))
        ax.axvline(float(d.mean()), color="tab:red", linewidth=1.2, label=f"mean {d.mean():.2f} mGal")
        ax.legend(loc="upper right", fontsize=8)
        ax.set_xlabel("crossover difference (line a - line b), mGal")
        ax.set_ylabel("count")
        stats = f"n = {d.size}, mean {d.mean():.2f}, RMS {rms:.2f}, RMS/√2 {rms / math.sqrt(2):.2f} mGal"
    ax.set_title(f"{title}\n{stats}" if title else stats, fontsize=10)
    _fit_layout(fig)
    return fig


def plot_crossover_histogram(path, crossovers, *, title: str = "") -> None:
    """Write the crossover histogram as PNG (see :func:`figure_crossover_histogram`)."""
    _save(figure_crossover_histogram(crossovers, title=title), path)


# --------------------------------------------------------------------------------------------
# grid map and levelling statistics (matplotlib imported inside: importing report stays cheap)
# --------------------------------------------------------------------------------------------
def _nice_length_km(span_km: float) -> float:
    """A 1, 2 or 5 x 10^k km length near a fifth of ``span_km``."""
    target = max(span_km / 5.0, 1e-3)
    k = math.floor(math.log10(target))
    for m in (5.0, 2.0, 1.0):
        if m * 10**k <= target:
            return m * 10**k
    return 10.0**k


def figure_grid_map(
    easting_m,
    northing_m,
    value_mgal,
    track_easting_m=None,
    track_northing_m=None,
    *,
    track_ids=None,
    crs_label: str = "",
    title: str = "",
    note: str = "",
    sigma_mgal=None,
):
    """Map of a grid: colour in mGal, flight lines, scale bar, CRS label, and the grid's 1-sigma
    as dashed labelled contours.

    Parameters
    ----------
    easting_m : array_like, shape (nx,)
    northing_m : array_like, shape (ny,)
    value_mgal : array_like, shape (ny, nx)
        NaN cells are drawn grey (no data).
    track_easting_m, track_northing_m : array_like, shape (n,), optional
        Flight-line samples, drawn as thin black lines (visible on every colour), split where
        ``track_ids`` changes.
    track_ids : array_like of str, shape (n,), optional
    crs_label : str
        E.g. ``"EPSG:32632 WGS 84 / UTM zone 32N"``: written on the map and the axes.
    title, note : str
        ``note`` (e.g. the grid altitude and cross-validation score) goes under the title.
    sigma_mgal : array_like, shape (ny, nx), optional
        The grid's 1-sigma, mGal: contoured (gid ``sigma``) where it varies.

    Returns
    -------
    matplotlib.figure.Figure
        The grid image has gid ``grid``, the tracks ``tracks``, the scale bar ``scalebar``.
    """
    from matplotlib.figure import Figure

    ge = np.asarray(easting_m, float) / 1e3
    gn = np.asarray(northing_m, float) / 1e3
    v = np.asarray(value_mgal, float)
    fig = Figure(figsize=(9, 8))
    ax = fig.add_subplot(1, 1, 1)
    ax.set_facecolor("0.85")
    fin = np.isfinite(v)
    lim = float(np.percentile(np.abs(v[fin]), 99)) if fin.any() else 1.0
    lim = lim if lim > 0 else 1.0
    # diverging map whose centre is a pale yellow, not white; tracks are drawn in black on top
    im = ax.pcolormesh(
        ge, gn, np.ma.masked_invalid(v), cmap="RdYlBu_r", vmin=-lim, vmax=lim, shading="nearest", gid="grid"
    )
    cb = fig.colorbar(im, ax=ax, shrink=0.8)
    cb.set_label("gravity disturbance, mGal")
    if track_easting_m is not None and track_northing_m is not None:
        te = np.asarray(track_easting_m, float) / 1e3
        tn = np.asarray(track_northing_m, float) / 1e3
        ids = np.asarray(track_ids).astype(str) if track_ids is not None else np.zeros(te.size, dtype=str)
        cut = np.flatnonzero(ids[1:] != ids[:-1]) + 1
        first = True
        for a, b in zip(np.concatenate(([0], cut)), np.concatenate((cut, [te.size]))):
            ax.plot(
                te[a:b], tn[a:b], color="black", linewidth=0.6, gid="tracks", label="flight lines" if first else None
            )
            first = False
    if sigma_mgal is not None:
        sg = np.asarray(sigma_mgal, float)
        fs = sg[np.isfinite(sg)]
        # contours need a 2 x 2 grid at least and a sigma that varies
        if min(sg.shape[-2:]) >= 2 and fs.size and float(fs.max()) > float(fs.min()):
            levels = np.unique(np.round(np.linspace(float(fs.min()), float(fs.max()), 6)[1:-1], 2))
            levels = levels[levels > 0]
            if levels.size:
                cs = ax.contour(
                    ge, gn, np.ma.masked_invalid(sg), levels=levels, colors="0.25", linewidths=0.8, linestyles="dashed"
                )
                cs.set_gid("sigma")
                ax.clabel(cs, fmt="%g", fontsize=7)
                ax.plot([], [], color="0.25", linewidth=0.8, linestyle="dashed", label="1-sigma, mGal")
    if ax.get_legend_handles_labels()[1]:
        ax.legend(loc="upper right", fontsize=8)
    ax.set_aspect("equal", adjustable="datalim")
    x0, x1 = float(np.nanmin(ge)), float(np.nanmax(ge))
    y0, y1 = float(np.nanmin(gn)), float(np.nanmax(gn))
    L = _nice_length_km(x1 - x0)
    xs, ys = x0 + 0.05 * (x1 - x0), y0 + 0.04 * (y1 - y0)
    ax.plot([xs, xs + L], [ys, ys], color="black", linewidth=4, solid_capstyle="butt", gid="scalebar")
    ax.text(xs + L / 2, ys + 0.015 * (y1 - y0), f"{L:g} km", ha="center", va="bottom", fontsize=9)
    if crs_label:
        ax.text(
            0.99,
            0.01,
            crs_label,
            transform=ax.transAxes,
            ha="right",
            va="bottom",
            fontsize=8,
            bbox={"facecolor": "white", "alpha": 0.8, "linewidth": 0},
        )
    suffix = f" ({crs_label.split()[0]})" if crs_label else ""
    ax.set_xlabel(f"easting, km{suffix}")
    ax.set_ylabel(f"northing, km{suffix}")
    head = "\n".join(s for s in (title, note) if s)
    if head:
        ax.set_title(head, fontsize=10)
    fig.tight_layout()
    return fig


def plot_grid_map(path, *args, **kwargs) -> None:
    """Write the grid map as PNG (see :func:`figure_grid_map`)."""
    _save(figure_grid_map(*args, **kwargs), path)


def figure_levelling(levelling, *, title: str = ""):
    """Levelling statistics: crossover differences before and after, and the corrections per line.

    Parameters
    ----------
    levelling : gravsurvey.levelling.Levelling
    """
    from matplotlib.figure import Figure

    b = levelling.before
    a = levelling.after
    d0 = np.asarray(levelling.residual_mgal, float)
    fig = Figure(figsize=(10, 4.5))
    ax1 = fig.add_subplot(1, 2, 1)
    ax2 = fig.add_subplot(1, 2, 2)
    # before: the raw differences are residual + model; rebuilt from the statistics' source
    raw = np.asarray(getattr(levelling, "diff_mgal", np.full_like(d0, np.nan)), float)
    both = np.concatenate([x[np.isfinite(x)] for x in (raw, d0)]) if np.isfinite(d0).any() else np.zeros(1)
    lim = float(np.max(np.abs(both))) if both.size else 1.0
    bins = np.linspace(-lim, lim, 31) if lim > 0 else 10
    if np.isfinite(raw).any():
        ax1.hist(
            raw[np.isfinite(raw)], bins=bins, color="tab:gray", alpha=0.6, label=f"before: RMS {b['rms_mgal']:.2f} mGal"
        )
    ax1.hist(d0[np.isfinite(d0)], bins=bins, color="tab:blue", alpha=0.7, label=f"after: RMS {a['rms_mgal']:.2f} mGal")
    ax1.set_xlabel("crossover difference, mGal")
    ax1.set_ylabel("count")
    ax1.legend(fontsize=8)
    ax1.set_title(f"{b['count']} crossovers ({levelling.model}, datum: {levelling.datum})", fontsize=9)
    labels = [f"{f}/{ln}" for f, ln in levelling.line_keys]
    y = np.arange(len(labels))
    ax2.barh(y, levelling.constant_mgal, color=np.where(levelling.levelled, "tab:blue", "0.7"))
    ax2.set_yticks(y)
    ax2.set_yticklabels(labels, fontsize=7 if len(labels) < 40 else 4)
    ax2.invert_yaxis()
    ax2.set_xlabel("correction (constant), mGal")
    ax2.axvline(0, color="black", linewidth=0.6)
    ax2.set_title("per-line correction (subtracted)", fontsize=9)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def plot_levelling(path, levelling, *, title: str = "") -> None:
    """Write the levelling statistics figure as PNG (see :func:`figure_levelling`)."""
    _save(figure_levelling(levelling, title=title), path)


__all__ += ["figure_grid_map", "plot_grid_map", "figure_levelling", "plot_levelling"]
