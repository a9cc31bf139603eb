"""Gridding: levelled line data -> a regular grid at one altitude, by equivalent sources.

Method
------
Airborne lines sample the field densely along the lines and sparsely across them, at the
heights actually flown. The grid is computed as harmonica's ``EquivalentSources`` computes it
(:func:`point_source_fit`, checked against it: one Jacobian serves every damping tried): point
sources below the data whose field fits the observations (damped least squares); the grid is
their field at a single stated altitude (``altitude_m``: the median flight height by default),
which is an upward/downward continuation of every line to that altitude, done in one step.
verde's biharmonic ``Spline`` is available as ``method: spline`` (2-D, no continuation: it
grids the values at their own heights and says so).

Steps, all automatic from the data (nothing here knows the truth of a simulation):

1. Thin: each line is averaged in bins of ``spacing_m`` along track (block means of
   position, height and value): the grid cannot hold shorter wavelengths, and the fit size
   stays small (a 100-km line at 1 Hz and 80 m/s gives ~1,250 samples, 200 bins at 500 m).
   Beyond :data:`MAX_FIT_POINTS` bins the bins are lengthened until the survey fits.
2. Line spacing: the median distance from a line's bins to the nearest bin of another
   line of the same kind (``line`` names; ties are ignored); defaults derive from it:
   ``spacing_m`` = line spacing / 4, source depth 1.5 line spacings below the data,
   ``max_distance_m`` = 0.6 line spacing (grid cells farther than this from any bin are NaN:
   no extrapolation beyond the survey).
3. Cross-validation: ``cv_folds``-fold block k-fold (verde ``BlockKFold``, blocks of one line
   spacing, fixed random state) over the damping candidates :data:`DAMPINGS` (unless
   configured); the one with the lowest held-out RMS is used for the final fit on all data;
   that RMS (mGal) and R^2 are reported as the grid's cross-validation score.
4. Sigma: each cell's 1-sigma (:func:`_grid_sigma`): the ordinary-kriging interpolation error
   of a covariance fitted to the lines, the data's stated errors (not averaged down across
   lines) and the fit's misfit, the field's part scaled so that the cross-validation residuals
   of step 3 have the spread it predicts (docs/survey.md, "The grid's sigma").

Units: m, mGal (named); the grid's coordinates are the projected easting/northing of the
survey (its EPSG code is written into the netCDF file).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from gravsurvey.drift import exponential, matern32
from gravsurvey.errors import DataError
from gravsurvey.pool import single_threaded_blas

__all__ = [
    "GRID_METHODS",
    "GridOptions",
    "GridResult",
    "thin_lines",
    "line_spacing",
    "field_covariance",
    "kriging_variance",
    "point_source_jacobian",
    "point_source_predict",
    "point_source_fit",
    "grid_lines",
    "continuation_difference",
    "sigma_notes",
    "write_grid_netcdf",
]

GRID_METHODS = ("equivalent_sources", "spline")
#: damping candidates tried by cross-validation (harmonica's damping of the source coefficients)
DAMPINGS = (1e-2, 1.0, 100.0)
#: source depth below the data, in units of the line spacing (deeper sources: smoother field)
DEPTH_FACTOR = 1.5
#: along-track thinning bin, in grid spacings
THIN_PER_SPACING = 1.0
#: cells farther from the data than this (in line spacings) are left empty: half a spacing is the
#: farthest a cell between two lines can be; a little more keeps the cells next to the lines' ends
MAX_DISTANCE_PER_LINE_SPACING = 0.6
#: most thinned points fitted: the equivalent-source Jacobian is points x points float64
#: (4,000 points: 128 MB); larger surveys are thinned more coarsely along the lines
MAX_FIT_POINTS = 4000
#: Two lines whose median separation is below this are one track flown twice (a reflight, or
#: another flight over the same line), m: they do not give the line spacing.
REPEAT_LINE_M = 100.0
#: the grid is at least this fine relative to the line spacing
SPACING_PER_LINE_SPACING = 0.25
#: nearest thinned points in each cell's kriging variance (the grid's sigma layer)
SIGMA_NEIGHBOURS = 32
#: field correlation lengths tried by :func:`field_covariance`, in line spacings
COVARIANCE_LENGTHS = tuple(float(x) for x in np.geomspace(0.1, 30.0, 40))
#: longest along-line lag in the field covariance fit, in line spacings
COVARIANCE_MAX_LAG = 4.0
#: most cells kriged for the sigma layer (finer grids: kriged on a coarser lattice, interpolated)
SIGMA_MAX_CELLS = 10_000
#: the grid's cross-validation RMS this far (a factor) above its sigma model's largest
#: prediction of it is said in the survey's notes (:func:`sigma_notes`)
SIGMA_CV_MISMATCH = 1.5
#: range of the cross-validation's scale on the field's part of the grid's error variance
CV_SCALE_RANGE = (1e-4, 1e4)


@dataclass
class GridOptions:
    """The ``grid:`` configuration section (docs/config.md).

    Attributes
    ----------
    enabled : bool or None
        None (default): grid when the survey has >= 2 lines; False: never.
    method : str
        ``equivalent_sources`` (default) or ``spline``.
    spacing_m, altitude_m, max_distance_m, depth_m, damping : float or None
        None: chosen from the data (module docstring). ``depth_m`` and ``damping`` given fix
        them (no search over that parameter).
    cv_folds : int
        Cross-validation folds (>= 2).
    """

    enabled: bool | None = None
    method: str = "equivalent_sources"
    spacing_m: float | None = None
    altitude_m: float | None = None
    max_distance_m: float | None = None
    depth_m: float | None = None
    damping: float | None = None
    cv_folds: int = 3


@dataclass
class GridResult:
    """A gridded survey.

    Attributes
    ----------
    easting_m : ndarray, shape (nx,)
    northing_m : ndarray, shape (ny,)
    value_mgal : ndarray, shape (ny, nx)
        NaN farther than ``max_distance_m`` from the data.
    altitude_m : float or None
        Ellipsoidal height of the grid, m (None for the 2-D spline).
    spacing_m, line_spacing_m, max_distance_m : float
    method : str
    depth_m, damping : float or None
        The parameters used (chosen by cross-validation unless configured).
    cv_rms_mgal, cv_r2 : float
        Held-out RMS and R^2 of the chosen parameters.
    n_data : int
        Thinned data points fitted.
    thinning_m : float
        Along-line bin length of the thinning, m (one cell, or more for surveys beyond
        :data:`MAX_FIT_POINTS` bins).
    candidates : list of dict
        Every (depth_m, damping, cv_rms_mgal) tried.
    sigma_mgal : ndarray, shape (ny, nx) or None
        1-sigma of ``value_mgal`` about the survey's level (NaN where the value is);
        ``sigma_info`` how it was found (:func:`_grid_sigma`).
    """

    easting_m: np.ndarray
    northing_m: np.ndarray
    value_mgal: np.ndarray
    altitude_m: float | None
    spacing_m: float
    line_spacing_m: float
    max_distance_m: float
    method: str
    depth_m: float | None
    damping: float | None
    cv_rms_mgal: float
    cv_r2: float
    n_data: int
    candidates: list = field(default_factory=list)
    thinning_m: float = float("nan")
    sigma_mgal: np.ndarray | None = None
    sigma_info: dict = field(default_factory=dict)

    def summary(self) -> dict:
        """JSON-able facts for summary.json."""
        v = self.value_mgal[np.isfinite(self.value_mgal)]
        return {
            "method": self.method,
            "shape": [int(self.northing_m.size), int(self.easting_m.size)],
            "spacing_m": self.spacing_m,
            "altitude_m": self.altitude_m,
            "line_spacing_m": self.line_spacing_m,
            "max_distance_m": self.max_distance_m,
            "depth_m": self.depth_m,
            "damping": self.damping,
            "cv_rms_mgal": self.cv_rms_mgal,
            "cv_r2": self.cv_r2,
            "n_data": self.n_data,
            "thinning_m": self.thinning_m,
            "filled_cells": int(v.size),
            "min_mgal": float(v.min()) if v.size else None,
            "max_mgal": float(v.max()) if v.size else None,
            "candidates": self.candidates,
            "sigma": self.sigma_info or None,
        }


def thin_lines(easting_m, northing_m, height_m, value_mgal, line_id, step_m: float, extra=(), counts: bool = False):
    """Block means along each line in bins of ``step_m`` of along-track distance.

    Parameters
    ----------
    easting_m, northing_m, height_m, value_mgal : array_like, shape (n,)
    line_id : array_like, shape (n,)
        Any hashable label per sample; a line's samples in along-track order.
    step_m : float
    extra : sequence of array_like, shape (n,)
        More per-sample quantities averaged in the same bins (NaN allowed: a bin holding one
        is NaN); returned after the line labels.
    counts : bool
        Also return the number of samples averaged in each bin (last).

    Returns
    -------
    e, n, h, v : ndarray, shape (m,)
        Bins in line order, and along each line in along-track order.
    line : ndarray, shape (m,)
        The line label of each bin.
    *extra : ndarray, shape (m,)
        One per ``extra`` given.
    count : ndarray, shape (m,)
        Samples per bin (float), when ``counts``.
    """
    e = np.asarray(easting_m, float)
    n = np.asarray(northing_m, float)
    h = np.asarray(height_m, float)
    v = np.asarray(value_mgal, float)
    more = [np.broadcast_to(np.asarray(x, float), e.shape) for x in extra]
    lid = np.asarray(line_id).astype(str)
    ok = np.isfinite(e) & np.isfinite(n) & np.isfinite(h) & np.isfinite(v)
    e, n, h, v, lid = e[ok], n[ok], h[ok], v[ok], lid[ok]
    more = [x[ok] for x in more]
    if e.size == 0:
        z = np.zeros(0)
        return (z, z, z, z, np.zeros(0, dtype=str), *(z for _ in more), *((z,) if counts else ()))
    names, code = np.unique(lid, return_inverse=True)
    # along-track distance restarts at every line (samples of a line are contiguous after a stable sort)
    order = np.argsort(code, kind="stable")
    e, n, h, v, code = e[order], n[order], h[order], v[order], code[order]
    more = [x[order] for x in more]
    step = np.hypot(np.diff(e), np.diff(n))
    new = np.concatenate(([True], code[1:] != code[:-1]))
    step = np.concatenate(([0.0], step))
    step[new] = 0.0
    dist = np.cumsum(step)
    start = np.maximum.accumulate(np.where(new, dist, 0.0))
    b = np.floor((dist - start) / step_m).astype(np.int64)
    key = code.astype(np.int64) * (int(b.max()) + 1) + b
    _, inv, cnt = np.unique(key, return_inverse=True, return_counts=True)
    mean = lambda x: np.bincount(inv, x) / cnt  # noqa: E731
    first = np.zeros(cnt.size, np.int64)
    first[inv[::-1]] = np.arange(inv.size)[::-1]
    tail = (cnt.astype(float),) if counts else ()
    return (mean(e), mean(n), mean(h), mean(v), names[code[first]], *(mean(x) for x in more), *tail)


def line_spacing(easting_m, northing_m, line) -> float:
    """Median distance from each line's points to the nearest point of another line, m.

    Uses the lines named like survey lines (``L..``) when there are >= 2 of them (tie lines
    cross them and would give zero), else every line.
    """
    from scipy.spatial import cKDTree

    e = np.asarray(easting_m, float)
    n = np.asarray(northing_m, float)
    lab = np.asarray(line).astype(str)
    base = np.array([s.rsplit("/", 1)[-1] for s in lab])
    main = np.char.startswith(base, "L")
    if len(np.unique(lab[main])) >= 2:
        e, n, lab = e[main], n[main], lab[main]
    names = np.unique(lab)
    if names.size < 2:
        raise DataError("grid: need at least 2 lines to estimate the line spacing")
    pts_of = {nm: np.column_stack([e[lab == nm], n[lab == nm]]) for nm in names}
    box_lo = {nm: p.min(axis=0) for nm, p in pts_of.items()}
    box_hi = {nm: p.max(axis=0) for nm, p in pts_of.items()}
    trees = {}
    d = []
    for nm, pts in pts_of.items():
        # the nearest other line that is not this track flown again (another flight's or a
        # reflight's pass within REPEAT_LINE_M): a repeat would give a spacing of metres.  The
        # gap between two lines' bounding boxes is below every point's distance, so below the
        # median: lines are tried nearest box first and the rest skipped once a gap reaches the
        # best separation (a survey of L lines queries ~2 neighbours per line, not L - 1)
        gaps = sorted(
            (float(np.hypot(*np.maximum(0.0, np.maximum(box_lo[o] - box_hi[nm], box_lo[nm] - box_hi[o])))), o)
            for o in names
            if o != nm
        )
        best = math.inf
        for gap, other in gaps:
            if gap >= best:
                break
            if other not in trees:
                trees[other] = cKDTree(pts_of[other])
            sep = float(np.median(trees[other].query(pts)[0]))
            if sep > REPEAT_LINE_M:
                best = min(best, sep)
        if math.isfinite(best):
            d.append(best)
    if not d:
        raise DataError(f"grid: every line lies within {REPEAT_LINE_M:g} m of another: no line spacing")
    return float(np.median(d))


def matern52(r, length):
    """Matern-5/2 correlation ``(1 + x + x^2 / 3) exp(-x)``, ``x = sqrt(5) r / length``."""
    x = math.sqrt(5.0) * r / length
    return (1.0 + x + x * x / 3.0) * np.exp(-x)


def layer_correlation(r, length):
    """Correlation ``(1 + (r / length)^2)^(-3/2)`` of the vertical attraction of random point
    sources on a layer at depth ``length / 2`` below the data (its power spectrum
    ``exp(-2 |k| depth)``)."""
    return (1.0 + np.square(r / length)) ** -1.5


#: covariance shapes :func:`field_covariance` chooses from, each ``corr(r, length)`` (the
#: Matern-3/2 is the drift stage's, :func:`gravsurvey.drift.matern32`)
CORRELATIONS = {"matern32": matern32, "matern52": matern52, "layer": layer_correlation}


def _noise_correlation(dist_m, length_m):
    """Along-line correlation of a line's data errors, ``exp(-d / length)`` (0 length: white)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = exponential(dist_m, length_m)
    return np.where(length_m > 0.0, rho, (dist_m == 0.0).astype(float))


def sample_spacing(easting_m, northing_m, line) -> np.ndarray:
    """Each sample's line's median along-track sample spacing, m, shape (n,) (NaN for a line
    of one sample or with a non-finite position)."""
    e = np.asarray(easting_m, float)
    n = np.asarray(northing_m, float)
    _, code = np.unique(np.asarray(line).astype(str), return_inverse=True)
    out = np.full(e.size, np.nan)
    step = np.hypot(np.diff(e), np.diff(n))
    same = (code[1:] == code[:-1]) & np.isfinite(step)
    for c in np.unique(code[1:][same]):
        out[code == c] = np.median(step[same & (code[1:] == c)])
    return out


def bin_mean_variance_ratio(bin_m, spacing_m, length_m) -> np.ndarray:
    """Variance of a bin's mean over a sample's, for errors correlated along the line as
    ``exp(-d / length_m)``: the continuous average over ``bin_m``,
    ``2 (l/T)^2 (T/l - 1 + exp(-T/l))``, but never below one over the samples in the bin.

    Parameters
    ----------
    bin_m : float or ndarray, shape (m,)
        The stretch of line each bin's samples cover, m.
    spacing_m, length_m : ndarray, shape (m,)
        Sample spacing (NaN: one sample per bin) and correlation length (0: white), m.
    """
    count = np.maximum(1.0, bin_m / np.where(np.isfinite(spacing_m) & (spacing_m > 0), spacing_m, bin_m))
    white = ~(length_m > 0.0)
    x = bin_m / np.where(white, 1.0, length_m)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        cont = np.where(x > 1e-6, 2.0 * (x - 1.0 + np.exp(-x)) / np.square(x), 1.0)
    cont = np.where(white, 0.0, cont)
    return np.clip(np.maximum(cont, 1.0 / count), 0.0, 1.0)


def field_covariance(easting_m, northing_m, value_mgal, line, noise_sigma_mgal, noise_length_m, max_lag_m, lengths_m):
    """The field's covariance from the lines: ``s2 * corr(r, length)``, the shape ``corr`` of
    :data:`CORRELATIONS` and its length that fit the along-line empirical covariance (less the
    data errors' own covariance) best in least squares.

    Parameters
    ----------
    easting_m, northing_m, value_mgal : ndarray, shape (m,)
        Thinned points, each line's points together and in along-track order
        (:func:`thin_lines`).
    line : ndarray, shape (m,)
        Line label per point.
    noise_sigma_mgal, noise_length_m : ndarray, shape (m,)
        The data's 1-sigma error (NaN: unknown) and its along-line correlation length (0: white).
    max_lag_m : float
        Longest lag fitted, m.
    lengths_m : sequence of float
        Correlation lengths tried, m.

    Returns
    -------
    shape : str
        The correlation of the best fit, a key of :data:`CORRELATIONS`.
    s2_mgal2 : float
        The field's variance, mGal^2.
    length_m : float
    nugget_mgal2 : float
        The points' variance not explained by the field at lag 0 (their error where it is not
        given), mGal^2, >= 0.
    """
    e, n = np.asarray(easting_m, float), np.asarray(northing_m, float)
    x = np.asarray(value_mgal, float) - float(np.mean(value_mgal))
    sig = np.nan_to_num(np.asarray(noise_sigma_mgal, float), nan=0.0)
    ell = np.asarray(noise_length_m, float)
    lab = np.asarray(line).astype(str)
    nbins = 24  # lag bins of max_lag_m / 24
    csum = np.zeros(nbins)
    dsum = np.zeros(nbins)
    cnt = np.zeros(nbins)
    for j in range(1, min(x.size, 400)):
        same = lab[j:] == lab[:-j]
        d = np.hypot(e[j:] - e[:-j], n[j:] - n[:-j])
        use = same & (d < max_lag_m)
        if not use.any():
            break
        noise = sig[j:] * sig[:-j] * _noise_correlation(d, 0.5 * (ell[j:] + ell[:-j]))
        b = np.minimum((d[use] / max_lag_m * nbins).astype(int), nbins - 1)
        csum += np.bincount(b, (x[j:] * x[:-j] - noise)[use], nbins)
        dsum += np.bincount(b, d[use], nbins)
        cnt += np.bincount(b, minlength=nbins)
    c0 = float(np.mean(x**2))
    ok = cnt >= 5
    if not ok.any():
        # too few pairs within the lag range to fit: the field is what the errors leave
        s2 = max(c0 - float(np.mean(sig**2)), 0.0)
        return "matern32", s2, float(lengths_m[len(lengths_m) // 2]), c0 - s2
    c = csum[ok] / cnt[ok]
    d = dsum[ok] / cnt[ok]
    w = cnt[ok]
    best = None
    for shape, corr in CORRELATIONS.items():
        for length in lengths_m:
            rho = corr(d, length)
            s2 = max(float(np.sum(w * c * rho) / np.sum(w * rho * rho)), 0.0)
            sse = float(np.sum(w * (c - s2 * rho) ** 2))
            if best is None or sse < best[0]:
                best = (sse, shape, s2, float(length))
    _, shape, s2, length = best
    # the field cannot hold more variance than the points show
    s2 = min(s2, c0)
    return shape, s2, length, max(c0 - s2, 0.0)


def kriging_variance(
    data_xy,
    data_sigma,
    data_line,
    data_noise_length,
    target_xy,
    s2,
    length_m,
    *,
    shape: str = "matern32",
    k: int = SIGMA_NEIGHBOURS,
    target_sigma=None,
    chunk: int = 2048,
):
    """The field's and the data errors' parts of the error variance of an ordinary-kriging
    interpolation at ``target_xy`` from the ``k`` nearest points.

    The field is a Gaussian process of unknown constant mean and covariance
    ``s2 * corr(r, length_m)`` (``corr`` the correlation :data:`CORRELATIONS` names ``shape``);
    a point's value is the field plus an error of 1-sigma ``data_sigma`` correlated along its
    line as ``exp(-d / data_noise_length)``. The weights ``w`` (summing to one: the local level
    is unknown, as a grid's is) are those of that model. The field part is the interpolation's
    error ``s2 - 2 w.k + w.K.w``; the error part is the neighbours' error variance weighted by
    ``|w|``: not reduced by averaging across lines, whose errors the model cannot tell
    independent (a survey's lines share a flight's errors).

    Parameters
    ----------
    data_xy : ndarray, shape (n, 2)
        Easting, northing of the points, m.
    data_sigma, data_noise_length : ndarray, shape (n,)
        mGal, m.
    data_line : ndarray of int, shape (n,)
        Line code per point.
    target_xy : ndarray, shape (m, 2)
    s2 : float
        Field variance, mGal^2.
    length_m : float
    k : int
        Neighbours used per target.
    target_sigma : ndarray, shape (m,), optional
        Given when the targets are data points themselves (held out): their own error variance
        is added to the error part (the value less its prediction).

    Returns
    -------
    field, error : ndarray, shape (m,)
        mGal^2.
    """
    from scipy.spatial import cKDTree

    corr = CORRELATIONS[shape]
    data_xy = np.asarray(data_xy, float)
    data_sigma = np.asarray(data_sigma, float)
    data_line = np.asarray(data_line)
    data_noise_length = np.asarray(data_noise_length, float)
    target_xy = np.asarray(target_xy, float)
    if target_sigma is not None:
        target_sigma = np.asarray(target_sigma, float)
    field_var = np.zeros(target_xy.shape[0])
    error_var = np.zeros(target_xy.shape[0])
    if target_xy.shape[0] == 0:
        return field_var, error_var
    k = int(min(k, data_xy.shape[0]))
    _, nb = cKDTree(data_xy).query(target_xy, k=k)
    nb = np.asarray(nb).reshape(target_xy.shape[0], k)
    jitter = 1e-9 * (s2 + float(np.max(data_sigma)) ** 2) + 1e-12
    for a in range(0, target_xy.shape[0], chunk):
        idx = nb[a : a + chunk]
        c = idx.shape[0]
        p = data_xy[idx]  # (c, k, 2)
        # easting and northing apart: the same sums as over a last axis of 2, 4x faster
        px, py = p[..., 0], p[..., 1]
        dx = px[:, :, None] - px[:, None, :]
        dy = py[:, :, None] - py[:, None, :]
        dd = np.sqrt(dx * dx + dy * dy)
        sig = data_sigma[idx]
        ell = data_noise_length[idx]
        lines = data_line[idx]
        noise = sig[:, :, None] * sig[:, None, :]
        noise *= _noise_correlation(dd, 0.5 * (ell[:, :, None] + ell[:, None, :]))
        noise[lines[:, :, None] != lines[:, None, :]] = 0.0
        kf = s2 * corr(dd, length_m)
        kk = np.zeros((c, k + 1, k + 1))
        np.add(kf, noise, out=kk[:, :k, :k])
        kk[:, np.arange(k), np.arange(k)] += jitter
        kk[:, :k, k] = 1.0
        kk[:, k, :k] = 1.0
        dx = px - target_xy[a : a + chunk, None, 0]
        dy = py - target_xy[a : a + chunk, None, 1]
        dt = np.sqrt(dx * dx + dy * dy)
        ks = s2 * corr(dt, length_m)
        w = np.linalg.solve(kk, np.concatenate([ks, np.ones((c, 1))], axis=1)[..., None])[:, :k, 0]
        fv = s2 - 2.0 * np.sum(w * ks, axis=1) + np.einsum("ci,cij,cj->c", w, kf, w)
        aw = np.abs(w)
        ev = np.sum(aw * sig**2, axis=1) / np.sum(aw, axis=1)
        if target_sigma is not None:
            ev += target_sigma[a : a + chunk] ** 2
        field_var[a : a + chunk] = fv
        error_var[a : a + chunk] = ev
    return np.clip(field_var, 0.0, None), error_var


def point_source_jacobian(coordinates, points) -> np.ndarray:
    """Green's function ``1 / distance`` of unit point sources, the Jacobian of harmonica's
    Cartesian ``EquivalentSources``.

    Parameters
    ----------
    coordinates, points : tuple of 3 ndarray (n,), (m,)
        Easting, northing, upward (m) of the observation points and of the sources.

    Returns
    -------
    ndarray (n, m)
        1/m.
    """
    from scipy.spatial.distance import cdist

    # scipy's compiled distance loop: the same sum of squares in the same order as numpy's
    # broadcast (bit-identical), without its three (n, m) temporaries - 8x faster
    jac = cdist(np.column_stack(coordinates[:3]), np.column_stack(points[:3]))
    np.divide(1.0, jac, out=jac)
    return jac


def point_source_predict(coordinates, points, coefs, block: int = 2_000_000) -> np.ndarray:
    """Field of point sources ``coefs`` at ``coordinates`` (harmonica's ``predict``), in row
    blocks of at most ``block`` matrix elements (bounded memory for large grids).

    ``coefs`` of shape (m,) gives shape (n,); of shape (m, k) (k sets of coefficients of the
    same sources) gives (n, k), from one Jacobian.
    """
    c = tuple(np.asarray(x, float).ravel() for x in coordinates[:3])
    coefs = np.asarray(coefs, float)
    out = np.empty((c[0].size,) + coefs.shape[1:])
    step = max(1, block // max(1, coefs.shape[0]))
    for i in range(0, out.shape[0], step):
        out[i : i + step] = point_source_jacobian(tuple(x[i : i + step] for x in c), points) @ coefs
    return out


def point_source_fit(coordinates, data, depth: float, dampings) -> tuple[tuple, np.ndarray]:
    """Coefficients of point sources ``depth`` below the data fitted to them, for several
    dampings from one Jacobian: harmonica's ``EquivalentSources(depth=depth, damping=d).fit``
    for each ``d`` (verde's ``least_squares``: columns scaled to unit standard deviation,
    ridge ``damping`` on the scaled coefficients, Cholesky solve of the normal equations).

    The Jacobian, its scaling and its normal matrix do not depend on the damping: computed
    once, each further damping is one Cholesky solve (the cross-validation tries several per
    fold).

    Parameters
    ----------
    coordinates : tuple of 3 ndarray, shape (n,)
        Easting, northing, upward of the data, m.
    data : ndarray, shape (n,)
    depth : float
        Sources' depth below their data point, m.
    dampings : sequence of float >= 0, length k

    Returns
    -------
    points : tuple of 3 ndarray, shape (n,)
        The sources, m.
    coefs : ndarray, shape (n, k)
        Coefficients for each damping (in the order given).
    """
    from scipy import linalg

    coords = tuple(np.asarray(x, float).ravel() for x in coordinates[:3])
    data = np.asarray(data, float).ravel()
    points = (coords[0], coords[1], coords[2] - depth)
    jac = point_source_jacobian(coords, points)
    scale = np.std(jac, axis=0)
    scale[scale == 0.0] = 1.0  # as sklearn's scaler: a constant column is left as it is
    jac /= scale
    gram = jac.T @ jac
    rhs = jac.T @ data
    del jac
    m = gram.shape[0]
    coefs = np.empty((m, len(dampings)))
    for k, damping in enumerate(dampings):
        a = gram.copy()
        a.flat[:: m + 1] += float(damping)
        try:
            coefs[:, k] = linalg.solve(a, rhs, assume_a="pos", overwrite_a=True)
        except linalg.LinAlgError:
            # as sklearn's ridge: what Cholesky cannot take (no damping, singular) by least squares
            a = gram.copy()
            a.flat[:: m + 1] += float(damping)
            coefs[:, k] = linalg.lstsq(a, rhs)[0]
    coefs /= scale[:, None]
    return points, coefs


def _fit_predict(method, depth, dampings, coords_fit, v_fit, coords_pred) -> np.ndarray:
    """Fit with each damping and predict at ``coords_pred``: shape (n_pred, len(dampings))."""
    if method == "spline":
        import verde as vd

        out = []
        for damping in dampings:
            sp = vd.Spline(damping=damping)
            sp.fit(coords_fit[:2], v_fit)
            out.append(sp.predict(coords_pred[:2]))
        return np.column_stack(out)
    # harmonica's own Jacobian and prediction are numba kernels that take the Green's function
    # as an argument, which numba cannot cache: every process compiled them again (1.1 s CPU of
    # a 3 s warm run of the sample survey); scipy's distance loop is as fast on these sizes
    points, coefs = point_source_fit(coords_fit, v_fit, depth, dampings)
    return point_source_predict(coords_pred, points, coefs)


def _thinned_for_fit(easting_m, northing_m, height_m, value_mgal, line, o: GridOptions, extra=()):
    """The line spacing, the cell size, the thinning step and the thinned points of a fit.

    The line spacing from a coarse thinning (100 m bins), then the lines averaged in bins of one
    cell (``thin_lines`` with ``extra`` and ``counts``), coarser until at most
    :data:`MAX_FIT_POINTS` bins remain.

    Returns
    -------
    line_spacing_m, spacing_m, step_m : float
    thinned : tuple
        :func:`thin_lines` ``(..., counts=True)`` of the data and ``extra``.
    """
    e0 = np.asarray(easting_m, float)
    n0 = np.asarray(northing_m, float)
    ok = np.isfinite(e0) & np.isfinite(n0) & np.isfinite(np.asarray(value_mgal, float))
    if len(np.unique(np.asarray(line).astype(str)[ok])) < 2:
        raise DataError("grid: need at least 2 lines with values to grid")
    e, n, _h, _v, lab = thin_lines(easting_m, northing_m, height_m, value_mgal, line, 100.0)
    ls = line_spacing(e, n, lab)
    if not ls > 0:
        raise DataError("grid: the lines do not have a measurable spacing (all on one track?)")
    spacing = o.spacing_m or SPACING_PER_LINE_SPACING * ls
    step = THIN_PER_SPACING * spacing
    thinned = thin_lines(easting_m, northing_m, height_m, value_mgal, line, step, extra, True)
    for _ in range(8):
        if thinned[0].size <= MAX_FIT_POINTS:
            break
        # the fit is a dense (points x sources) least-squares problem: a large survey is thinned
        # more coarsely along the lines (never across them) so memory and time stay bounded; a
        # step below the sample spacing thins nothing, so it grows until the points fit
        step = max(step * thinned[0].size / MAX_FIT_POINTS, 1.5 * step)
        thinned = thin_lines(easting_m, northing_m, height_m, value_mgal, line, step, extra, True)
    if thinned[0].size < 10:
        raise DataError(f"grid: only {thinned[0].size} data points after thinning to {step:.0f} m; need >= 10")
    return ls, spacing, step, thinned


def _block_folds(e, n, line_spacing_m: float, cv_folds: int, random_state: int) -> list:
    """Block k-fold splits (blocks of one line spacing) of the points; a small survey may have
    fewer blocks than folds: as many folds as it allows."""
    import verde as vd

    for k in range(cv_folds, 1, -1):
        try:
            folds = vd.BlockKFold(spacing=line_spacing_m, n_splits=k, shuffle=True, random_state=random_state)
            return list(folds.split(np.column_stack([e, n])))
        except ValueError:
            continue
    raise DataError(f"grid: the data span less than 2 blocks of {line_spacing_m:.0f} m: cannot cross-validate")


def _cross_validated_fit(method, depths, damps, coords, v, splits):
    """Held-out residuals of every (depth, damping) candidate over ``splits``.

    Returns
    -------
    candidates : list of dict
        ``depth_m, damping, cv_rms_mgal, cv_r2`` each.
    residuals : list of ndarray, shape (m,)
        Held-out residual of every point, per candidate.
    best : int
        The candidate of least held-out RMS.
    """
    cands = []
    residuals = []
    spread = float(np.sum((v - v.mean()) ** 2))
    for dep in depths:
        res = np.full((v.size, len(damps)), np.nan)
        for tr, te in splits:
            pred = _fit_predict(method, dep, damps, tuple(c[tr] for c in coords), v[tr], tuple(c[te] for c in coords))
            res[te] = v[te][:, None] - pred
        for k, dmp in enumerate(damps):
            rms = float(np.sqrt(np.nanmean(res[:, k] ** 2)))
            # a constant field has no variance to explain: R^2 undefined
            r2 = float(1.0 - np.nansum(res[:, k] ** 2) / spread) if spread > 0.0 else float("nan")
            cands.append({"depth_m": dep, "damping": dmp, "cv_rms_mgal": rms, "cv_r2": r2})
            residuals.append(res[:, k].copy())
    return cands, residuals, min(range(len(cands)), key=lambda i: cands[i]["cv_rms_mgal"])


def _single_threaded_blas(func):
    """``func`` run inside :func:`gravsurvey.pool.single_threaded_blas` (the grid's fits are
    small dense solves that BLAS threads only slow down)."""

    @functools.wraps(func)
    def single(*args, **kwargs):
        with single_threaded_blas():
            return func(*args, **kwargs)

    return single


@_single_threaded_blas
def grid_lines(
    easting_m,
    northing_m,
    height_m,
    value_mgal,
    line,
    options: GridOptions | None = None,
    *,
    random_state: int = 0,
    sigma_mgal=None,
    noise_length_m=None,
) -> GridResult:
    """Grid line data (module docstring), with BLAS single-threaded (:func:`_single_threaded_blas`).

    Parameters
    ----------
    easting_m, northing_m, height_m, value_mgal : array_like, shape (n,)
        Projected position (m), ellipsoidal height (m), levelled value (mGal); NaN rows ignored.
    line : array_like of str, shape (n,)
        Line label per sample (``"<flight>/<line>"``), samples of a line in time order.
    options : GridOptions, optional
    random_state : int
        For the cross-validation folds (fixed: results are reproducible).
    sigma_mgal : array_like, shape (n,), optional
        The values' 1-sigma error, mGal (NaN or None: unknown, then taken from the data's
        variance the field does not explain).
    noise_length_m : float or array_like, shape (n,), optional
        Along-line correlation length of those errors, m (e.g. the line's resolution; None: 0,
        white).

    Returns
    -------
    GridResult

    Raises
    ------
    DataError
        Fewer than 2 lines or too few points to grid.
    """
    import verde as vd

    o = options or GridOptions()
    nsamp = np.asarray(easting_m).shape
    extra = (
        np.full(nsamp, np.nan) if sigma_mgal is None else np.asarray(sigma_mgal, float),
        np.zeros(nsamp) if noise_length_m is None else np.broadcast_to(np.asarray(noise_length_m, float), nsamp),
        sample_spacing(easting_m, northing_m, line),
    )
    ls, spacing, step, thinned = _thinned_for_fit(easting_m, northing_m, height_m, value_mgal, line, o, extra)
    e, n, h, v, lab, sig, ell, dl, cnt = thinned
    # a bin averages the samples it holds: at a line's end or beside a gap (NaN values) fewer
    # than the step over the line's spacing, over a shorter stretch of the line
    held = np.where(np.isfinite(dl) & (dl > 0.0), np.minimum(cnt * dl, step), step)
    sig = sig * np.sqrt(bin_mean_variance_ratio(held, dl, ell))
    altitude = o.altitude_m if o.altitude_m is not None else float(np.median(h))
    maxdist = o.max_distance_m or MAX_DISTANCE_PER_LINE_SPACING * ls
    coords = (e, n, h)

    if o.method == "spline":
        depths = [None]
        damps = [o.damping] if o.damping is not None else [None, 1e-6, 1e-3]
    else:
        depths = [o.depth_m] if o.depth_m is not None else [DEPTH_FACTOR * ls]
        damps = [o.damping] if o.damping is not None else list(DAMPINGS)
    splits = _block_folds(e, n, ls, o.cv_folds, random_state)
    cands, residuals, ibest = _cross_validated_fit(o.method, depths, damps, coords, v, splits)
    best = cands[ibest]
    region = (e.min(), e.max(), n.min(), n.max())
    ge, gn = vd.grid_coordinates(region, spacing=spacing, meshgrid=False, adjust="region")
    GE, GN = np.meshgrid(ge, gn)
    # the grid's cells and the points themselves (the fit's misfit enters the sigma) in one call
    pred_coords = tuple(np.concatenate([a.ravel(), b]) for a, b in zip((GE, GN, np.full(GE.shape, altitude)), coords))
    pred = _fit_predict(o.method, best["depth_m"], [best["damping"]], coords, v, pred_coords)[:, 0]
    val = pred[: GE.size].reshape(GE.shape)
    mask = vd.distance_mask((e, n), maxdist=maxdist, coordinates=(GE, GN))
    val = np.where(mask, val, np.nan)
    sigma, sigma_info = _grid_sigma(
        e, n, v, lab, sig, ell, ls, splits, residuals[ibest], v - pred[GE.size :], GE, GN, mask
    )
    return GridResult(
        easting_m=np.asarray(ge, float),
        northing_m=np.asarray(gn, float),
        value_mgal=val,
        altitude_m=altitude if o.method != "spline" else None,
        spacing_m=float(spacing),
        line_spacing_m=ls,
        max_distance_m=float(maxdist),
        method=o.method,
        depth_m=best["depth_m"],
        damping=best["damping"],
        cv_rms_mgal=best["cv_rms_mgal"],
        cv_r2=best["cv_r2"],
        n_data=int(v.size),
        candidates=cands,
        thinning_m=float(step),
        sigma_mgal=sigma,
        sigma_info=sigma_info,
    )


@_single_threaded_blas
def continuation_difference(
    easting_m,
    northing_m,
    height_m,
    value_mgal,
    line,
    at_easting_m,
    at_northing_m,
    height_a_m,
    height_b_m,
    options: GridOptions | None = None,
    *,
    random_state: int = 0,
) -> tuple[np.ndarray, dict]:
    """How much the field differs between two heights at given points, from the lines.

    Equivalent sources fitted to the line data as :func:`grid_lines` fits them (the same
    thinning, source depth and cross-validated damping; the method is always equivalent
    sources: a 2-D spline cannot continue), evaluated at each point at both heights. At a
    crossover of lines flown at different heights, this is the part of the difference that is
    the field's, not a level error (:func:`gravsurvey.crossovers.find_crossovers`).

    Parameters
    ----------
    easting_m, northing_m, height_m, value_mgal : array_like, shape (n,)
        The line samples: projected position (m), ellipsoidal height (m), value (mGal); NaN
        rows ignored.
    line : array_like of str, shape (n,)
        Line label per sample, samples of a line in time order.
    at_easting_m, at_northing_m, height_a_m, height_b_m : array_like, shape (k,)
        The points and their two heights, m.
    options : GridOptions, optional
        ``spacing_m``, ``depth_m``, ``damping``, ``cv_folds`` as for the grid.

    Returns
    -------
    difference_mgal : ndarray, shape (k,)
        Field at ``height_a_m`` less field at ``height_b_m``, mGal.
    info : dict
        ``depth_m``, ``damping``, ``cv_rms_mgal`` of the fit, ``n_data``.

    Raises
    ------
    DataError
        As :func:`grid_lines`: fewer than 2 lines, too few points, or too small to
        cross-validate.
    """
    o = options or GridOptions()
    ls, _spacing, _step, thinned = _thinned_for_fit(easting_m, northing_m, height_m, value_mgal, line, o)
    e, n, h, v = thinned[:4]
    coords = (e, n, h)
    depths = [o.depth_m] if o.depth_m is not None else [DEPTH_FACTOR * ls]
    damps = [o.damping] if o.damping is not None else list(DAMPINGS)
    splits = _block_folds(e, n, ls, o.cv_folds, random_state)
    cands, _residuals, ibest = _cross_validated_fit("equivalent_sources", depths, damps, coords, v, splits)
    best = cands[ibest]
    ae = np.asarray(at_easting_m, float)
    an = np.asarray(at_northing_m, float)
    ha = np.asarray(height_a_m, float)
    hb = np.asarray(height_b_m, float)
    k = ae.size
    pred = _fit_predict(
        "equivalent_sources",
        best["depth_m"],
        [best["damping"]],
        coords,
        v,
        (np.concatenate([ae, ae]), np.concatenate([an, an]), np.concatenate([ha, hb])),
    )[:, 0]
    info = {
        "depth_m": best["depth_m"],
        "damping": best["damping"],
        "cv_rms_mgal": best["cv_rms_mgal"],
        "n_data": int(v.size),
    }
    return pred[:k] - pred[k:], info


def _grid_sigma(e, n, v, lab, sig, ell, line_spacing_m, splits, cv_residual, fit_residual, GE, GN, mask):
    """The grid's 1-sigma layer (docs/survey.md, "The grid's sigma"): the ordinary-kriging error
    under the field's covariance fitted to the lines (:func:`field_covariance`,
    :func:`kriging_variance`), the data's stated errors and the fit's misfit, the field's part
    scaled so that the grid's own cross-validation residuals have the spread it predicts.

    Parameters
    ----------
    e, n, v, lab, sig, ell : ndarray, shape (m,)
        The thinned points (:func:`thin_lines`): position (m), value and its 1-sigma (mGal, NaN
        unknown), line label, error correlation length (m).
    splits : list of (train, test) index arrays
        The cross-validation folds; ``cv_residual`` (m,) the chosen fit's held-out residuals.
    fit_residual : ndarray, shape (m,)
        The points less the final fit at the points, mGal.
    GE, GN, mask : ndarray, shape (ny, nx)

    Returns
    -------
    sigma : ndarray, shape (ny, nx)
        mGal; NaN where ``mask`` is False.
    info : dict
        JSON-able facts for summary.json.
    """
    _, code = np.unique(lab, return_inverse=True)
    ell = np.where(np.isfinite(ell) & (ell > 0.0), ell, 0.0)
    known = np.isfinite(sig)
    shape, s2, length, nugget = field_covariance(
        e,
        n,
        v,
        lab,
        sig,
        ell,
        COVARIANCE_MAX_LAG * line_spacing_m,
        [f * line_spacing_m for f in COVARIANCE_LENGTHS],
    )
    # an error not given is what the points show beyond the field
    sig = np.where(known, sig, np.sqrt(nugget))
    # what the fit cannot hold along the lines (its sources' depth smooths wavelengths shorter
    # than about the line spacing), beyond the points' own errors: in every cell, held out or not
    misfit = max(float(np.mean(fit_residual**2) - np.mean(sig**2)), 0.0)
    xy = np.column_stack([e, n])
    ok = np.isfinite(cv_residual)
    # the held-out residuals' squares against what the model predicts for them: the errors'
    # part as stated, the field's part scaled (its variance as the cross-validation sees it)
    field_cv = np.zeros(v.size)
    error_cv = np.zeros(v.size)
    for tr, te in splits:
        field_cv[te], error_cv[te] = kriging_variance(
            xy[tr], sig[tr], code[tr], ell[tr], xy[te], s2, length, shape=shape, target_sigma=sig[te]
        )
    spare = float(np.sum(cv_residual[ok] ** 2) - np.sum(error_cv[ok]) - misfit * int(ok.sum()))
    total = float(np.sum(field_cv[ok]))
    scale = float(np.clip(spare / total, *CV_SCALE_RANGE)) if total > 0.0 else 1.0
    sigma = np.full(GE.shape, np.nan)
    # the sigma varies over the line spacing, not the cell: a grid finer than SIGMA_MAX_CELLS
    # cells is kriged on every step-th row and column and interpolated between them
    step = max(1, math.ceil(math.sqrt(mask.sum() / SIGMA_MAX_CELLS)))
    if step > 1:
        rows = np.unique(np.r_[np.arange(0, GE.shape[0], step), GE.shape[0] - 1])
        cols = np.unique(np.r_[np.arange(0, GE.shape[1], step), GE.shape[1] - 1])
        at = np.meshgrid(GE[0, cols], GN[rows, 0])
    else:
        at = (GE[mask], GN[mask])
    field_part, error_part = kriging_variance(
        xy, sig, code, ell, np.column_stack([a.ravel() for a in at]), s2, length, shape=shape
    )
    var = scale * field_part + error_part + misfit
    if step > 1:
        from scipy.interpolate import RegularGridInterpolator

        var = RegularGridInterpolator((GN[rows, 0], GE[0, cols]), var.reshape(at[0].shape))(
            np.column_stack([GN[mask], GE[mask]])
        )
    sigma[mask] = np.sqrt(var)
    filled = sigma[mask]
    info = {
        "method": "kriging",
        "covariance": shape,
        "field_sigma_mgal": float(np.sqrt(s2)),
        "field_length_m": length,
        "data_sigma_mgal": float(np.median(sig)),
        "data_sigma_from": "stated" if known.all() else "data" if not known.any() else "stated and data",
        "data_sigma_length_m": float(np.median(ell)),
        "misfit_mgal": float(np.sqrt(misfit)),
        "field_variance_cv_scale": scale,
        # what the held-out residuals are and what the sigma's model makes them (smaller when
        # the lines share errors, which cancel in a held-out line less its neighbours)
        "cv_rms_mgal": float(np.sqrt(np.mean(cv_residual[ok] ** 2))),
        "cv_rms_predicted_mgal": float(np.sqrt(np.mean(scale * field_cv[ok] + error_cv[ok]) + misfit)),
        "median_mgal": float(np.median(filled)) if filled.size else None,
        "max_mgal": float(np.max(filled)) if filled.size else None,
    }
    return sigma, info


def sigma_notes(info: dict) -> list:
    """Survey notes on a grid's sigma (``GridResult.sigma_info``): said when the grid's own
    cross-validation residuals exceed what the sigma's model makes them, with the field's part
    at its largest scale, by more than :data:`SIGMA_CV_MISMATCH` (the field varies between the
    lines more than the lines show).

    The other way round is not said: errors a flight's lines share (its drift, its level) cancel
    in a held-out line less its neighbours, so residuals smaller than the stated errors make them
    do not show those errors over-stated (on 82 of the 138 unseen-suite flights they are, by
    over 1.5x, while the grid's error/sigma there has median 1.13).
    """
    seen, pred = info.get("cv_rms_mgal"), info.get("cv_rms_predicted_mgal")
    if not seen or not pred or seen <= SIGMA_CV_MISMATCH * pred:
        return []
    return [
        f"grid: the cross-validation residuals ({seen:.2f} mGal RMS) exceed what the grid's "
        f"sigma model makes them ({pred:.2f}): the field varies between the lines more than "
        "the lines show; the grid's sigma may under-state its error"
    ]


def write_grid_netcdf(
    path,
    grid: GridResult,
    crs_epsg: int | None,
    *,
    title: str = "gravsurvey grid",
    variable: str = "gravity_disturbance",
    attrs: dict | None = None,
) -> None:
    """Write a grid as CF-1.8 netCDF (netCDF3 via scipy; readable by GMT, QGIS, xarray).

    Variables: ``easting`` (x, m), ``northing`` (y, m), ``<variable>`` (y, x) in mGal with
    ``grid_mapping = "crs"`` and, when the grid has one, its 1-sigma ``<variable>_sigma`` (mGal); ``crs`` carries ``spatial_ref``/``crs_wkt`` (WKT from pyproj) and
    ``epsg_code``. Global attributes: title, Conventions, altitude, method, cross-validation
    score and whatever ``attrs`` adds (software version, processing parameters).

    The file is written to a temporary name and renamed (never half-written).
    """
    import os
    from pathlib import Path

    import xarray as xr

    path = Path(path)
    da = xr.DataArray(
        grid.value_mgal.astype("float32"),
        dims=("northing", "easting"),
        coords={"northing": grid.northing_m, "easting": grid.easting_m},
        attrs={
            "long_name": "gravity disturbance (g - normal gravity) at the grid altitude",
            "units": "mGal",
            "grid_mapping": "crs",
        },
    )
    da["easting"].attrs = {
        "standard_name": "projection_x_coordinate",
        "long_name": "easting",
        "units": "m",
        "axis": "X",
    }
    da["northing"].attrs = {
        "standard_name": "projection_y_coordinate",
        "long_name": "northing",
        "units": "m",
        "axis": "Y",
    }
    crs_attrs = {}
    if crs_epsg is not None:
        try:
            from pyproj import CRS

            crs = CRS.from_epsg(int(crs_epsg))
            crs_attrs = {**crs.to_cf(), "spatial_ref": crs.to_wkt(), "epsg_code": f"EPSG:{int(crs_epsg)}"}
        except Exception:  # an unknown code still gets written as a label
            crs_attrs = {"epsg_code": f"EPSG:{int(crs_epsg)}"}
    crs_attrs = {k: (v if isinstance(v, (str, int, float)) else str(v)) for k, v in crs_attrs.items()}
    layers = {variable: da}
    if grid.sigma_mgal is not None:
        layers[f"{variable}_sigma"] = xr.DataArray(
            grid.sigma_mgal.astype("float32"),
            dims=("northing", "easting"),
            coords=da.coords,
            attrs={
                "long_name": f"1-sigma of {variable} about the survey's level (kriging error, docs/survey.md)",
                "units": "mGal",
                "grid_mapping": "crs",
            },
        )
    ds = xr.Dataset({**layers, "crs": xr.DataArray(np.int32(0), attrs=crs_attrs)})
    glob = {
        "title": title,
        "Conventions": "CF-1.8",
        "grid_altitude_m": grid.altitude_m if grid.altitude_m is not None else "data heights (2-D spline)",
        "grid_method": grid.method,
        "grid_spacing_m": grid.spacing_m,
        "cv_rms_mgal": grid.cv_rms_mgal,
        "cv_r2": grid.cv_r2,
    }
    for k, val in (attrs or {}).items():
        glob[k] = val if isinstance(val, (str, int, float)) else str(val)
    ds.attrs = {k: v for k, v in glob.items() if v is not None}
    tmp = path.with_name(f"{path.name}.tmp-{os.getpid()}")
    try:
        ds.to_netcdf(tmp, engine="scipy", format="NETCDF3_64BIT")
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
