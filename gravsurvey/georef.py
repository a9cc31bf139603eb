"""Map projection of the georeferenced profile (pyproj).

Geodetic positions (radians, WGS84) to projected easting/northing in metres:
UTM by default, the zone and hemisphere picked from the data (the zone of
the median longitude, north if the median latitude is >= 0), or any
projected CRS given by its EPSG code (config ``output.epsg``).
"""

from __future__ import annotations

import math

import numpy as np

from .errors import ConfigError


def utm_epsg(lat, lon) -> int:
    """EPSG code of the WGS84 / UTM zone containing the median of the points (rad)."""
    lat = np.asarray(lat, float)
    lon = np.asarray(lon, float)
    ok = np.isfinite(lat) & np.isfinite(lon)
    if not ok.any():
        raise ValueError("utm_epsg: no finite positions")
    lon_deg = (math.degrees(float(np.median(np.unwrap(lon[ok])))) + 180.0) % 360.0 - 180.0
    zone = int((lon_deg + 180.0) // 6.0) % 60 + 1
    north = float(np.median(lat[ok])) >= 0.0
    return (32600 if north else 32700) + zone


def project(lat, lon, epsg=None, key: str = "output.epsg"):
    """Project geodetic positions to a map grid.

    Parameters
    ----------
    lat, lon : array_like
        Geodetic latitude and longitude, rad (WGS84).
    epsg : int or None
        Target projected CRS; None picks the UTM zone from the data.
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
        epsg = utm_epsg(lat, lon)
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
