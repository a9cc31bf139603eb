"""The profile table: its columns (documented order, decimals) and the formatting shared by the
table writers (UTC strings, metadata comment lines, row formatting, line grouping).

A profile table is a dict of equal-length 1-D numpy arrays with the columns of
:data:`PROFILE_COLUMNS` and optionally the estimate, level, attitude, horizontal and truth
columns. ``time_utc`` may be omitted and is ignored if given: it is always derived from
``time_unix_ns`` (nearest ms), so the two cannot disagree.
"""

from __future__ import annotations

import json
import math

import numpy as np

from gravsurvey.crossovers import Crossovers
from gravsurvey.utc import utc_iso_array

from .jsonout import to_jsonable

#: the writers' name for :func:`gravsurvey.utc.utc_iso_array` (milliseconds, rounded half up)
format_utc = utc_iso_array

#: required columns of profiles.csv, in order (docs/outputs.md)
PROFILE_COLUMNS = (
    "flight",
    "line",
    "time_utc",
    "time_unix_ns",
    "lat_deg",
    "lon_deg",
    "height_m",
    "easting_m",
    "northing_m",
    "disturbance_mgal",
    "sigma_mgal",
)
#: optional, written between disturbance_mgal and sigma_mgal: the estimate the product was made
#: from, named for what it is: the Kalman/RTS smoothed estimate (3D-INM) or the classic
#: reduction before its low-pass (no Kalman filter involved); and the gravimeter drift the
#: lines identified and took off the smoothed estimate (gravsurvey.drift)
ESTIMATE_COLUMNS = ("kalman_mgal", "unfiltered_mgal", "drift_mgal")
TRUTH_COLUMNS = ("truth_mgal", "error_mgal")
#: optional: the disturbance after base ties and crossover levelling (docs/outputs.md)
LEVEL_COLUMNS = ("levelled_mgal",)
#: optional: a strapdown triad's estimated attitude and its 1-sigma, deg (NaN for other flights)
ATTITUDE_COLUMNS = ("roll_deg", "pitch_deg", "heading_deg", "roll_sigma_deg", "pitch_sigma_deg", "heading_sigma_deg")
#: optional: horizontal disturbance components, the deflections of the vertical they give
#: (xi = -dg_north / gamma, eta = -dg_east / gamma) and their 1-sigma; NaN where not observable
HORIZONTAL_COLUMNS = (
    "dg_north_mgal",
    "dg_east_mgal",
    "xi_arcsec",
    "eta_arcsec",
    "dg_north_sigma_mgal",
    "dg_east_sigma_mgal",
    "xi_sigma_arcsec",
    "eta_sigma_arcsec",
)
STRING_COLUMNS = ("flight", "line", "time_utc")
# decimals written per float column (see docs/outputs.md for the resolution this gives)
DECIMALS = {
    "lat_deg": 9,
    "lon_deg": 9,
    "height_m": 3,
    "easting_m": 3,
    "northing_m": 3,
    "disturbance_mgal": 4,
    "levelled_mgal": 4,
    "kalman_mgal": 4,
    "unfiltered_mgal": 4,
    "drift_mgal": 4,
    "sigma_mgal": 4,
    "truth_mgal": 4,
    "error_mgal": 4,
    "time_unix_s": 3,
    "roll_deg": 4,
    "pitch_deg": 4,
    "heading_deg": 4,
    "roll_sigma_deg": 5,
    "pitch_sigma_deg": 5,
    "heading_sigma_deg": 5,
    "dg_north_mgal": 4,
    "dg_east_mgal": 4,
    "dg_north_sigma_mgal": 4,
    "dg_east_sigma_mgal": 4,
    "xi_arcsec": 4,
    "eta_arcsec": 4,
    "xi_sigma_arcsec": 4,
    "eta_sigma_arcsec": 4,
}
#: required XYZ columns (the optional estimate, level, horizontal and truth columns follow when present)
XYZ_COLUMNS = ("time_unix_s",) + PROFILE_COLUMNS[4:]
#: crossovers.csv columns: the fields of :class:`gravsurvey.crossovers.Crossovers`, in order
CROSSOVER_COLUMNS = Crossovers.COLUMNS


def profile_columns(table: dict) -> tuple[str, ...]:
    """The columns a profile table will be written with (documented order), checked.

    Raises
    ------
    ValueError
        A required column is missing, only one of the truth columns is present, or the columns
        are not 1-D of equal length (a programming error in the caller, not a data problem).
    """
    missing = [c for c in PROFILE_COLUMNS if c not in table and c != "time_utc"]
    if missing:
        raise ValueError(f"profile table lacks columns {missing}")
    has_truth = [c in table for c in TRUTH_COLUMNS]
    if any(has_truth) and not all(has_truth):
        raise ValueError("profile table: truth_mgal and error_mgal go together")
    horizontal = [c in table for c in HORIZONTAL_COLUMNS]
    if any(horizontal) and not all(horizontal):
        raise ValueError(f"profile table: the horizontal columns {HORIZONTAL_COLUMNS} go together")
    estimate = tuple(c for c in ESTIMATE_COLUMNS if c in table)
    level = tuple(c for c in LEVEL_COLUMNS if c in table)
    attitude = tuple(c for c in ATTITUDE_COLUMNS if c in table)
    cols = (
        PROFILE_COLUMNS[:10]
        + estimate
        + PROFILE_COLUMNS[10:]
        + level
        + attitude
        + (HORIZONTAL_COLUMNS if all(horizontal) else ())
        + (TRUTH_COLUMNS if all(has_truth) else ())
    )
    n = None
    for c in cols:
        if c == "time_utc" and c not in table:
            continue
        a = np.asarray(table[c])
        if a.ndim != 1 or (n is not None and a.size != n):
            raise ValueError(f"profile table column {c}: expected 1-D of length {n}, got shape {a.shape}")
        n = a.size
    return cols


def format_float_column(a, decimals: int) -> list[str]:
    a = np.asarray(a, dtype=float)
    f = f"{{:.{decimals}f}}".format
    return [f(x) if math.isfinite(x) else "NaN" for x in a.tolist()]


def csv_text_field(s: str) -> str:
    if any(ch in s for ch in ',"\n\r'):
        return '"' + s.replace('"', '""') + '"'
    return s


def column_strings(table: dict, col: str) -> list[str]:
    if col == "time_utc":
        # always derived from the exact epoch, so the two columns cannot disagree
        return format_utc(table["time_unix_ns"]).tolist()
    if col == "time_unix_ns":
        return [str(int(x)) for x in np.asarray(table[col], dtype=np.int64).tolist()]
    if col in STRING_COLUMNS:
        vals = [str(x) for x in np.asarray(table[col]).tolist()]
        quoted = {v: csv_text_field(v) for v in set(vals)}  # few distinct names: quote once each
        return [quoted[v] for v in vals]
    return format_float_column(table[col], DECIMALS[col])


def metadata_lines(metadata: dict | None) -> list[str]:
    """``key: value`` lines of a metadata mapping (nested mappings as compact JSON), for headers.

    The pipeline's metadata (docs/outputs.md): survey, crs, units, software, level, processing.
    """
    out = []
    for k, v in (metadata or {}).items():
        if isinstance(v, str):
            txt = v
        else:
            txt = json.dumps(to_jsonable(v), separators=(",", ":"), allow_nan=False, ensure_ascii=False)
        out.append(f"{k}: {' '.join(txt.splitlines())}")
    return out


def resolution_statement(resolution_m) -> str:
    """How a line's product states its resolution in the XYZ header and the plots.

    Parameters
    ----------
    resolution_m : float or None
        Half-wavelength resolution of the line's product, m (summary.json ``resolution_m``);
        ``math.inf`` when the estimator resolves no wavelength of the field above the noise (the
        product is then the line's level, flat within its sigma); None or NaN when the
        product's method states none.

    Returns
    -------
    str
        ``"half-wavelength resolution 4.2 km"``, ``"no wavelength resolved above the noise
        (flat estimate)"`` or ``"half-wavelength resolution not stated"``.
    """
    r = math.nan if resolution_m is None else float(resolution_m)
    if not r > 0.0:  # NaN or not positive
        return "half-wavelength resolution not stated"
    if math.isinf(r):
        return "no wavelength resolved above the noise (flat estimate)"
    return f"half-wavelength resolution {r / 1000.0:.3g} km"


def line_groups(flight, line) -> dict:
    """Row indices of every (flight, line), in order of first appearance; empty line names skipped.

    Linear in the number of rows: a line's rows are found as runs of equal (flight, line)
    (a profile table holds each line's rows contiguously); a pair that appears in several runs
    gets them all, in row order.

    Returns
    -------
    dict
        ``(flight, line) -> ndarray of int``.
    """
    f = np.asarray(flight).astype(str)
    ln = np.asarray(line).astype(str)
    n = f.size
    if n == 0:
        return {}
    change = np.flatnonzero((f[1:] != f[:-1]) | (ln[1:] != ln[:-1])) + 1
    starts = np.concatenate(([0], change))
    stops = np.concatenate((change, [n]))
    runs: dict = {}
    for a, b in zip(starts.tolist(), stops.tolist()):
        key = (f[a], ln[a])
        if key[1] == "":
            continue
        runs.setdefault(key, []).append((a, b))
    return {
        k: (np.arange(v[0][0], v[0][1]) if len(v) == 1 else np.concatenate([np.arange(a, b) for a, b in v]))
        for k, v in runs.items()
    }


def float_rows(arrays, fmts, sep: str, null: str) -> list[str]:
    """Format float columns row by row (one %-operation per row); non-finite -> ``null``."""
    if not arrays:
        return []
    cols = [np.where(np.isfinite(a), a, np.nan).tolist() for a in (np.asarray(x, float) for x in arrays)]
    fmt = sep.join(fmts)
    rows = [fmt % r for r in zip(*cols)]
    # only numbers and 'nan' can appear in these rows
    return [r.replace("nan", null) for r in rows] if null != "nan" else rows
