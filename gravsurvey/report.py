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
    """A matplotlib Figure (imported here, on first use: runs without plots never load it)."""
    from matplotlib.figure import Figure

    return Figure(figsize=figsize)


def _save(fig: Figure, path) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=_DPI, metadata=_METADATA)
    atomic_write_bytes(path, buf.getvalue())


def figure_line_profile(x, kalman_mgal, final_mgal, sigma_mgal, truth_mgal=None, *, title: str = "",
                        x_label: str = "time, s") -> Figure:
    """Figure of one line's profile.

    Parameters
    ----------
    x : array_like, shape (n,)
        Abscissa: time (s) or distance along the line (km); say which with ``x_label``.
    kalman_mgal : array_like, shape (n,)
        Kalman/RTS estimate before the wavelet post-processor, mGal.
    final_mgal : array_like, shape (n,)
        Final (post-processed) gravity disturbance, mGal.
    sigma_mgal : array_like, shape (n,)
        Posterior standard deviation of the Kalman estimate, mGal; drawn as a band
        ``kalman_mgal +- sigma_mgal`` (1 sigma).
    truth_mgal : array_like, shape (n,), optional
        Simulator truth, mGal; when given, the RMS of ``final - truth`` is in the title.
    title : str
    x_label : str

    Returns
    -------
    matplotlib.figure.Figure
        Artists labelled ``kalman``, ``final``, ``truth`` (lines) and ``sigma`` (band).
    """
    x = np.asarray(x, float)
    k = np.asarray(kalman_mgal, float)
    f = np.asarray(final_mgal, float)
    s = np.asarray(sigma_mgal, float)
    fig = _new_figure((10, 4.5))
    ax = fig.add_subplot(1, 1, 1)
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
            full_title = f"{title}  (final - truth: RMS {rms:.2f} mGal)" if title else f"final - truth: RMS {rms:.2f} mGal"
    handles, labels = ax.get_legend_handles_labels()
    names = {"kalman": "Kalman/RTS", "final": "final (wavelet)", "truth": "truth", "sigma": "Kalman ± 1σ"}
    ax.legend(handles, [names[lb] for lb in labels], loc="best", fontsize=8)
    ax.set_xlabel(x_label)
    ax.set_ylabel("gravity disturbance, mGal")
    ax.grid(True, alpha=0.3)
    if full_title:
        ax.set_title(full_title, fontsize=10)
    fig.tight_layout()
    return fig


def plot_line_profile(path, x, kalman_mgal, final_mgal, sigma_mgal, truth_mgal=None, *, title: str = "",
                      x_label: str = "time, s") -> None:
    """Write a line's profile plot as PNG (see :func:`figure_line_profile`)."""
    _save(figure_line_profile(x, kalman_mgal, final_mgal, sigma_mgal, truth_mgal, title=title, x_label=x_label), path)


def _crossover_arrays(crossovers):
    if crossovers is None:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    return (np.asarray(crossovers.easting_m, float), np.asarray(crossovers.northing_m, float),
            np.asarray(crossovers.diff_mgal, float))


def figure_survey_map(easting_m, northing_m, value_mgal, line_ids, crossovers=None, *, title: str = "",
                      crs_label: str = "") -> Figure:
    """Map of the survey: tracks coloured by the anomaly, line labels, crossover marks.

    Parameters
    ----------
    easting_m, northing_m : array_like, shape (n,)
        Projected coordinates, m (drawn in km).
    value_mgal : array_like, shape (n,)
        Colour, mGal (diverging colour map centred on 0, limits at the 98th percentile of |value|).
    line_ids : array_like of str, shape (n,)
        Line label per sample (e.g. ``"F01/L01"``); each line is labelled at its first sample.
    crossovers : gravsurvey.survey.Crossovers, optional
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
    sc = ax.scatter(e, n, c=v, s=4, cmap="RdBu_r", vmin=-lim, vmax=lim, linewidths=0, gid="tracks")
    cb = fig.colorbar(sc, ax=ax, shrink=0.8)
    cb.set_label("gravity disturbance, mGal")
    for lid in dict.fromkeys(ids.tolist()):
        i = int(np.flatnonzero(ids == lid)[0])
        if np.isfinite(e[i]) and np.isfinite(n[i]):
            ax.annotate(lid, (e[i], n[i]), fontsize=7, xytext=(3, 3), textcoords="offset points")
    xe, xn, xd = _crossover_arrays(crossovers)
    if xe.size:
        ad = np.abs(np.nan_to_num(xd, nan=0.0))
        size = 15 + 60 * ad / max(float(ad.max()), 1e-12)
        ax.scatter(xe / 1e3, xn / 1e3, s=size, facecolors="none", edgecolors="black", linewidths=0.8,
                   gid="crossovers", label=f"crossovers ({xe.size}); size ~ |difference|")
        ax.legend(loc="upper right", fontsize=8)
    ax.set_aspect("equal", adjustable="datalim")
    suffix = f" ({crs_label})" if crs_label else ""
    ax.set_xlabel(f"easting, km{suffix}")
    ax.set_ylabel(f"northing, km{suffix}")
    ax.grid(True, alpha=0.3)
    if title:
        ax.set_title(title, fontsize=10)
    fig.tight_layout()
    return fig


def plot_survey_map(path, easting_m, northing_m, value_mgal, line_ids, crossovers=None, *, title: str = "",
                    crs_label: str = "") -> None:
    """Write the survey map as PNG (see :func:`figure_survey_map`)."""
    _save(figure_survey_map(easting_m, northing_m, value_mgal, line_ids, crossovers, title=title,
                            crs_label=crs_label), path)


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
    fig.tight_layout()
    return fig


def plot_crossover_histogram(path, crossovers, *, title: str = "") -> None:
    """Write the crossover histogram as PNG (see :func:`figure_crossover_histogram`)."""
    _save(figure_crossover_histogram(crossovers, title=title), path)
