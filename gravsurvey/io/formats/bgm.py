"""Bell Aerospace / Lockheed BGM-3 marine gravimeter logs.

* **Serial counts** (:func:`read_bgm_serial`): the meter sends ``04:025529 00`` once a second
  (``04`` channel, 6-digit frequency count, ``00`` status) and the ship's logger puts its own
  time stamp in front (``BGM 2022/07/01 12:17:33.492 BGM3 04:024963 00``,
  ``vc01<TAB>2020:244:00:00:00.3244<TAB>04:025229 00``, ``2022-11-07T17:13:45.329611Z 04:024882 00``,
  ``03/13/2022,00:00:02.449,04:025529 00``).  Counts become gravity only with the meter's scale
  factor (mGal per count, from its calibration, e.g. 4.994070552 for BGM-3 S210 on Atlantis).
* **RGS records** (:func:`read_bgm_rgs`): UNOLS "RGS" lines
  ``RGS yyyy/mm/dd hh:mm:ss.sss gravity_mGal counts unix_s scale offset BGM3 <serial> GPS: lat lon ...``.

Columns: ``counts`` (counts), ``status`` (1); with a scale factor or from RGS: ``gravity``
(m/s^2, the meter's raw gravity with its offset); RGS also ``lat``, ``lon`` (rad).
"""

from __future__ import annotations

import os
import re

import numpy as np

from gravsurvey.errors import ConfigError

from .common import MGAL, LineTally, civil_to_ns, finish, parse_logger_stamp, read_lines

_COUNTS = re.compile(r"(?<![\d.])(\d{2}):(\d{5,6})\s+(\d{2})\s*$")


def read_bgm_serial(path, *, scale_mgal_per_count: float | None = None) -> "FormatTable":  # noqa: F821
    """Read a BGM-3 serial-count log with logger time stamps.

    Parameters
    ----------
    path : path-like
    scale_mgal_per_count : float, optional
        The meter's calibration (mGal per count).  Given: a ``gravity`` column (m/s^2) =
        scale x counts x 1e-5.

    Returns
    -------
    FormatTable
        ``format='bgm_serial'``; time = the logger stamp (the meter sends none).  Lines without
        a ``cc:nnnnnn ss`` count or without a recognisable stamp are skipped and counted.

    Raises
    ------
    ConfigError
        A non-positive or non-finite scale factor.
    DataError
        Unreadable file or fewer than half the lines are count records.
    """
    if scale_mgal_per_count is not None and not (np.isfinite(scale_mgal_per_count) and scale_mgal_per_count > 0):
        raise ConfigError(f"bgm scale_mgal_per_count: expected a positive number, got {scale_mgal_per_count!r}")
    path = os.fspath(path)
    tally = LineTally(path)
    times, counts, status = [], [], []
    kind = None  # logger stamp style of the previous line
    for n, ln in enumerate(read_lines(path), start=1):
        s = ln.strip()
        if not s or s.startswith("#"):
            continue
        tally.n_lines += 1
        m = _COUNTS.search(s)
        if m is None:
            tally.bad(n, "no BGM count 'cc:nnnnnn ss'", s)
            continue
        st = parse_logger_stamp(s[: m.start()], kind)
        kind = st[1] if st else kind
        if st is None:
            tally.bad(n, "no logger time stamp before the count", s)
            continue
        times.append(st[0])
        counts.append(float(m.group(2)))
        status.append(float(m.group(3)))
    cols = {"counts": np.asarray(counts), "status": np.asarray(status)}
    units = {"counts": "counts", "status": "1"}
    notes = []
    if scale_mgal_per_count is not None:
        cols["gravity"] = cols["counts"] * scale_mgal_per_count * MGAL
        units["gravity"] = "m/s^2"
        notes.append(f"{path}: gravity = {scale_mgal_per_count:g} mGal/count x counts")
    return finish(path, "bgm_serial", tally, times, cols, units, notes, {"scale_mgal_per_count": scale_mgal_per_count})


def read_bgm_rgs(path) -> "FormatTable":  # noqa: F821
    """Read UNOLS BGM-3 ``RGS`` records.

    Returns
    -------
    FormatTable
        ``format='bgm_rgs'``; columns ``gravity`` (m/s^2), ``counts``, ``lat``, ``lon`` (rad;
        NaN when the GPS fields are missing); time from the record's date and time (UTC).

    Raises
    ------
    DataError
        Unreadable file or fewer than half the lines are RGS records.
    """
    path = os.fspath(path)
    tally = LineTally(path)
    times, grav, counts, lat, lon = [], [], [], [], []
    for n, ln in enumerate(read_lines(path), start=1):
        s = ln.strip()
        if not s or s.startswith("#"):
            continue
        tally.n_lines += 1
        f = s.split()
        if len(f) < 5 or f[0] != "RGS":
            tally.bad(n, "not an RGS record", s)
            continue
        try:
            y, mo, d = (int(x) for x in f[1].split("/"))
            hh, mm, ss = f[2].split(":")
            t = civil_to_ns(y, mo, d, int(hh), int(mm), ss)
            g = float(f[3])
            c = float(f[4])
            la = lo = np.nan
            if "GPS:" in f:
                k = f.index("GPS:")
                la, lo = float(f[k + 1]), float(f[k + 2])
                if abs(la) > 90 or abs(lo) > 360:
                    raise ValueError("GPS position out of range")
        except (ValueError, IndexError) as exc:
            tally.bad(n, f"damaged RGS record ({exc})", s)
            continue
        times.append(t)
        grav.append(g * MGAL)
        counts.append(c)
        lat.append(np.radians(la))
        lon.append(np.radians(lo))
    cols = {"gravity": np.asarray(grav), "counts": np.asarray(counts), "lat": np.asarray(lat), "lon": np.asarray(lon)}
    units = {"gravity": "m/s^2", "counts": "counts", "lat": "rad", "lon": "rad"}
    return finish(path, "bgm_rgs", tally, times, cols, units)
