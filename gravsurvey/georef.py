"""Map projection of the georeferenced profile (pyproj).

Geodetic positions (radians, WGS84) to projected easting/northing in metres:
by default UTM, the zone and hemisphere picked from the data (the zone of
the median longitude, north if the median latitude is >= 0), or, where the
median latitude is outside UTM's extent (north of 84 deg N, south of 80 deg S),
the Universal Polar Stereographic grid of that pole; or any projected CRS given
by its EPSG code (config ``output.epsg``).
"""

from __future__ import annotations

import math

import numpy as np

from .errors import ConfigError


#: UTM's extent, deg: north of the first and south of the second the UPS grids take over
#: (NGA.SIG.0012, the UTM/UPS standard).
UTM_MAX_LAT_DEG = 84.0
UTM_MIN_LAT_DEG = -80.0
#: WGS 84 / UPS North (E,N) and WGS 84 / UPS South (E,N): easting first, as UTM (32661 and
#: 32761 are the same grids with the axes named northing first).
UPS_NORTH_EPSG = 5041
UPS_SOUTH_EPSG = 5042


def default_epsg(lat, lon) -> int:
    """EPSG code of the default grid of the points (rad): their UTM zone (:func:`utm_epsg`), or
    UPS North / South where the median latitude is beyond UTM's extent (polar surveys)."""
    mid = _median_position_deg(lat, lon)
    if mid is not None:
        if mid[0] > UTM_MAX_LAT_DEG:
            return UPS_NORTH_EPSG
        if mid[0] < UTM_MIN_LAT_DEG:
            return UPS_SOUTH_EPSG
    return utm_epsg(lat, lon, mid)


def utm_epsg(lat, lon, median_deg=None) -> int:
    """EPSG code of the WGS84 / UTM zone containing the median of the points (rad);
    ``median_deg``: that median (lat, lon in degrees) when already computed."""
    mid = median_deg if median_deg is not None else _median_position_deg(lat, lon)
    if mid is None:
        raise ValueError("utm_epsg: no finite positions")
    zone = int((mid[1] + 180.0) // 6.0) % 60 + 1
    return (32600 if mid[0] >= 0.0 else 32700) + zone


def _median_position_deg(lat, lon):
    """(median latitude, median longitude wrapped to [-180, 180)) in degrees of the finite
    points (rad; longitudes unwrapped first, so a survey across the antimeridian has its median
    there), or None where there is none."""
    lat = np.asarray(lat, float)
    lon = np.asarray(lon, float)
    ok = np.isfinite(lat) & np.isfinite(lon)
    if not ok.any():
        return None
    lon_deg = (math.degrees(float(np.median(np.unwrap(lon[ok])))) + 180.0) % 360.0 - 180.0
    return math.degrees(float(np.median(lat[ok]))), lon_deg


def project(lat, lon, epsg=None, key: str = "output.epsg"):
    """Project geodetic positions to a map grid.

    Parameters
    ----------
    lat, lon : array_like
        Geodetic latitude and longitude, rad (WGS84).
    epsg : int or None
        Target projected CRS; None picks the default grid from the data (:func:`default_epsg`:
        the UTM zone, UPS beyond UTM's extent).
    key : str
        Config key named in error messages.

    Returns
    -------
    easting_m, northing_m : ndarray
        Same shape as ``lat``.
    epsg : int
        The code used.

    Raises
    ------
    ConfigError
        Unknown or non-projected EPSG code.
    """
    from pyproj import CRS, Transformer
    from pyproj.exceptions import CRSError

    lat = np.asarray(lat, float)
    lon = np.asarray(lon, float)
    if epsg is None:
        epsg = default_epsg(lat, lon)
    if isinstance(epsg, bool) or not isinstance(epsg, (int, np.integer)):
        raise ConfigError(f"{key}: expected an integer EPSG code, got {epsg!r}")
    try:
        crs = CRS.from_epsg(int(epsg))
    except CRSError:
        raise ConfigError(f"{key}: unknown EPSG code {epsg}") from None
    if not crs.is_projected:
        raise ConfigError(f"{key}: EPSG:{epsg} ({crs.name}) is not a projected CRS with metre coordinates")
    tr = Transformer.from_crs(CRS.from_epsg(4326), crs, always_xy=True)
    e, n = tr.transform(np.degrees(lon), np.degrees(lat))
    return np.asarray(e, float), np.asarray(n, float), int(epsg)
