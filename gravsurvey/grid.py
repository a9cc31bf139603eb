"""Gridding: levelled line data -> a regular grid at one altitude, by equivalent sources.

Method
------
Airborne lines sample the field densely along the lines and sparsely across them, at the
heights actually flown. The grid is computed with harmonica's ``EquivalentSources``: point
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

Units: m, mGal (named); the grid's coordinates are the projected easting/northing of the
survey (its EPSG code is written into the netCDF file).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from gravsurvey.errors import DataError

__all__ = ["GRID_METHODS", "GridOptions", "GridResult", "thin_lines", "line_spacing", "grid_lines", "write_grid_netcdf"]

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
        }


def thin_lines(easting_m, northing_m, height_m, value_mgal, line_id, step_m: float):
    """Block means along each line in bins of ``step_m`` of along-track distance.

    Parameters
    ----------
    easting_m, northing_m, height_m, value_mgal : array_like, shape (n,)
    line_id : array_like, shape (n,)
        Any hashable label per sample; a line's samples in along-track order.
    step_m : float

    Returns
    -------
    e, n, h, v : ndarray, shape (m,)
    line : ndarray, shape (m,)
        The line label of each bin.
    """
    e = np.asarray(easting_m, float)
    n = np.asarray(northing_m, float)
    h = np.asarray(height_m, float)
    v = np.asarray(value_mgal, float)
    lid = np.asarray(line_id).astype(str)
    ok = np.isfinite(e) & np.isfinite(n) & np.isfinite(h) & np.isfinite(v)
    e, n, h, v, lid = e[ok], n[ok], h[ok], v[ok], lid[ok]
    if e.size == 0:
        z = np.zeros(0)
        return z, z, z, z, np.zeros(0, dtype=str)
    names, code = np.unique(lid, return_inverse=True)
    # along-track distance restarts at every line (samples of a line are contiguous after a stable sort)
    order = np.argsort(code, kind="stable")
    e, n, h, v, code = e[order], n[order], h[order], v[order], code[order]
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
    return mean(e), mean(n), mean(h), mean(v), names[code[first]]


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
    d2 = (coordinates[0][:, None] - points[0][None, :]) ** 2
    d2 += (coordinates[1][:, None] - points[1][None, :]) ** 2
    d2 += (coordinates[2][:, None] - points[2][None, :]) ** 2
    return 1.0 / np.sqrt(d2)


def point_source_predict(coordinates, points, coefs, block: int = 2_000_000) -> np.ndarray:
    """Field of point sources ``coefs`` at ``coordinates`` (harmonica's ``predict``), in row
    blocks of at most ``block`` matrix elements (bounded memory for large grids)."""
    c = tuple(np.asarray(x, float).ravel() for x in coordinates[:3])
    out = np.empty(c[0].size)
    step = max(1, block // max(1, coefs.size))
    for i in range(0, out.size, step):
        out[i : i + step] = point_source_jacobian(tuple(x[i : i + step] for x in c), points) @ coefs
    return out


def _fit_predict(method, depth, damping, coords_fit, v_fit, coords_pred):
    if method == "spline":
        import verde as vd

        sp = vd.Spline(damping=damping)
        sp.fit(coords_fit[:2], v_fit)
        return sp.predict(coords_pred[:2])
    import harmonica as hm

    eqs = hm.EquivalentSources(depth=depth, damping=damping)
    # harmonica's own Jacobian and prediction are numba kernels that take the Green's function
    # as an argument, which numba cannot cache: every process compiled them again (1.1 s CPU of
    # a 3 s warm run of the sample survey); numpy is as fast on these sizes
    eqs.jacobian = point_source_jacobian
    eqs.fit(coords_fit, v_fit)
    return point_source_predict(coords_pred, eqs.points_, eqs.coefs_)


def grid_lines(
    easting_m, northing_m, height_m, value_mgal, line, options: GridOptions | None = None, *, random_state: int = 0
) -> GridResult:
    """Grid line data (module docstring); see :func:`_grid_lines` for the parameters.

    The fits are small dense solves: multi-threaded BLAS gains nothing on them and, on a busy
    machine, lost 30x (0.83 s vs 0.03 s for one 600 x 600 solve measured on the 2-core CI host),
    so BLAS runs single-threaded inside (threadpoolctl, a scikit-learn dependency).
    """
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - scikit-learn (verde, harmonica) brings it
        return _grid_lines(easting_m, northing_m, height_m, value_mgal, line, options, random_state=random_state)
    with threadpool_limits(limits=1, user_api="blas"):
        return _grid_lines(easting_m, northing_m, height_m, value_mgal, line, options, random_state=random_state)


def _grid_lines(
    easting_m, northing_m, height_m, value_mgal, line, options: GridOptions | None = None, *, random_state: int = 0
) -> GridResult:
    """Grid line data (module docstring).

    Parameters
    ----------
    easting_m, northing_m, height_m, value_mgal : array_like, shape (n,)
        Projected position (m), ellipsoidal height (m), levelled value (mGal); NaN rows ignored.
    line : array_like of str, shape (n,)
        Line label per sample (``"<flight>/<line>"``), samples of a line in time order.
    options : GridOptions, optional
    random_state : int
        For the cross-validation folds (fixed: results are reproducible).

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
    e0 = np.asarray(easting_m, float)
    n0 = np.asarray(northing_m, float)
    ok = np.isfinite(e0) & np.isfinite(n0) & np.isfinite(np.asarray(value_mgal, float))
    if len(np.unique(np.asarray(line).astype(str)[ok])) < 2:
        raise DataError("grid: need at least 2 lines with values to grid")
    # line spacing from a coarse thinning (100 m bins), then the real thinning
    e, n, _h, _v, lab = thin_lines(easting_m, northing_m, height_m, value_mgal, line, 100.0)
    ls = line_spacing(e, n, lab)
    if not ls > 0:
        raise DataError("grid: the lines do not have a measurable spacing (all on one track?)")
    spacing = o.spacing_m or SPACING_PER_LINE_SPACING * ls
    step = THIN_PER_SPACING * spacing
    e, n, h, v, lab = thin_lines(easting_m, northing_m, height_m, value_mgal, line, step)
    for _ in range(8):
        if e.size <= MAX_FIT_POINTS:
            break
        # the fit is a dense (points x sources) least-squares problem: a large survey is thinned
        # more coarsely along the lines (never across them) so memory and time stay bounded; a
        # step below the sample spacing thins nothing, so it grows until the points fit
        step = max(step * e.size / MAX_FIT_POINTS, 1.5 * step)
        e, n, h, v, lab = thin_lines(easting_m, northing_m, height_m, value_mgal, line, step)
    if e.size < 10:
        raise DataError(f"grid: only {e.size} data points after thinning to {step:.0f} m; need >= 10")
    altitude = o.altitude_m if o.altitude_m is not None else float(np.median(h))
    maxdist = o.max_distance_m or MAX_DISTANCE_PER_LINE_SPACING * ls
    coords = (e, n, h)

    if o.method == "spline":
        depths = [None]
        damps = [o.damping] if o.damping is not None else [None, 1e-6, 1e-3]
    else:
        depths = [o.depth_m] if o.depth_m is not None else [DEPTH_FACTOR * ls]
        damps = [o.damping] if o.damping is not None else list(DAMPINGS)
    # a small survey may have fewer line-spacing blocks than folds: use as many folds as it allows
    splits = []
    for k in range(o.cv_folds, 1, -1):
        try:
            folds = vd.BlockKFold(spacing=ls, n_splits=k, shuffle=True, random_state=random_state)
            splits = list(folds.split(np.column_stack([e, n])))
            break
        except ValueError:
            continue
    if not splits:
        raise DataError(f"grid: the data span less than 2 blocks of {ls:.0f} m: cannot cross-validate")
    cands = []
    for dep in depths:
        for dmp in damps:
            res = np.full(v.size, np.nan)
            for tr, te in splits:
                pred = _fit_predict(
                    o.method, dep, dmp, tuple(c[tr] for c in coords), v[tr], tuple(c[te] for c in coords)
                )
                res[te] = v[te] - pred
            rms = float(np.sqrt(np.nanmean(res**2)))
            r2 = float(1.0 - np.nansum(res**2) / np.sum((v - v.mean()) ** 2))
            cands.append({"depth_m": dep, "damping": dmp, "cv_rms_mgal": rms, "cv_r2": r2})
    best = min(cands, key=lambda c: c["cv_rms_mgal"])
    region = (e.min(), e.max(), n.min(), n.max())
    ge, gn = vd.grid_coordinates(region, spacing=spacing, meshgrid=False, adjust="region")
    GE, GN = np.meshgrid(ge, gn)
    pred_coords = (GE.ravel(), GN.ravel(), np.full(GE.size, altitude))
    val = _fit_predict(o.method, best["depth_m"], best["damping"], coords, v, pred_coords).reshape(GE.shape)
    mask = vd.distance_mask((e, n), maxdist=maxdist, coordinates=(GE, GN))
    val = np.where(mask, val, np.nan)
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
    )


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
    ``grid_mapping = "crs"``; ``crs`` carries ``spatial_ref``/``crs_wkt`` (WKT from pyproj) and
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
    ds = xr.Dataset({variable: da, "crs": xr.DataArray(np.int32(0), attrs=crs_attrs)})
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
