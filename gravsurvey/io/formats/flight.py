"""A gravimeter file (+ navigation) as a :class:`~gravsurvey.io.record.FlightRecord` for the classic chain.

The classic (conventional) reduction (:mod:`gravsurvey.classic`) needs the vertical specific
force of a stabilised platform, a height channel and a horizontal track.  A marine/airborne
gravimeter on a stabilised platform measures exactly the first: its reading, scaled and tied
(``absolute = scale x reading + offset_mgal``), is the vertical specific force ``f_U``.  So the
record built here has

* ``imu``: ``specific_force_t = (0, 0, f_U)`` (a platform triad, z up) at the meter's epochs,
  ``angular_rate_t = 0`` (the meter measures no rotation; the classic chain needs none);
* ``gnss``: positions and ellipsoidal heights from the navigation file (NMEA, trajectory, RTKLIB) or
  from the gravimeter file's own position columns (MGD77T, DGS laptop, BGM RGS);
* ``altimeter``: the same heights (or a constant ``height_m``, e.g. a ship's meter at sea level).

Config (one flight's ``inputs.gravimeter``, see docs/input-formats.md)::

    gravimeter:
      format: dgs_laptop        # mgd77t | dgs_laptop | at1a | zls | bgm_serial | bgm_rgs
      file: DGS_2019.dat        # or files: [a, b] (a ZLS directory is allowed)
      offset_mgal: 969143.0     # meter reading -> absolute gravity (base tie); required for
                                # meter-unit formats (dgs_laptop, at1a, zls, bgm_serial)
      scale: 1.0                # meter calibration factor applied to the reading first
      counts_scale_mgal: 4.994  # bgm_serial only: mGal per count (required there)
      time_source: auto         # dgs_laptop: auto | meter | logger
      height_m: 0.0             # constant ellipsoidal height of the meter (overrides nav heights)
      nav:                      # optional for formats with positions, required otherwise
        format: nmea            # nmea | trajectory | rtklib
        file: nav.gps
        time_source: auto       # nmea: auto | fix | logger
        time_system: auto       # trajectory: auto | gps | utc

MGD77T's ``GRA_OBS`` is already Eotvos-corrected: the reader's ``EOTVOS`` column is subtracted
again (records without it are dropped and counted) so that the classic chain applies its own
correction from the navigation exactly once.  The processing method must be ``classic``.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gravsurvey.errors import DataError, DataWarning
from gravsurvey.io import checks as ck
from gravsurvey.io.record import AltimeterChannel, FlightRecord, GnssChannel, ImuChannel

from .common import MGAL, NS, FormatTable

#: ``inputs.gravimeter.format`` values and whether the format carries positions / an absolute level.
GRAVIMETER_FORMATS = {
    "mgd77t": {"positions": True, "absolute": True, "marine": True},
    "dgs_laptop": {"positions": True, "absolute": False, "marine": True},
    "at1a": {"positions": False, "absolute": False, "marine": False},
    "zls": {"positions": False, "absolute": False, "marine": False},
    "bgm_serial": {"positions": False, "absolute": False, "marine": True},
    "bgm_rgs": {"positions": True, "absolute": True, "marine": True},
}
NAV_FORMATS = ("nmea", "trajectory", "rtklib")
#: Median absolute gravity (m/s^2) outside this range means a missing or wrong tie/scale.
GRAVITY_OK = (9.70, 9.85)
#: Fastest plausible ground speed (m/s) between consecutive fixes: ship (~49 kn), aircraft.
MAX_SPEED_MARINE = 25.0
MAX_SPEED_AIRBORNE = 250.0


def position_jumps(time_ns, lat, lon, max_speed: float):
    """Steps between consecutive fixes that imply a ground speed above ``max_speed``.

    Parameters
    ----------
    time_ns : ndarray of int64, shape (n,)
        Strictly increasing.
    lat, lon : ndarray, shape (n,)
        rad.
    max_speed : float
        m/s.

    Returns
    -------
    idx : ndarray of int, shape (k,)
        Index ``i`` of each step ``i -> i + 1`` that is a jump.
    speed : ndarray, shape (k,)
        The implied speeds, m/s.
    """
    from gravsurvey.geodesy import local_displacement

    if len(time_ns) < 2:
        return np.zeros(0, int), np.zeros(0)
    lat, lon = np.asarray(lat, float), np.asarray(lon, float)
    d = np.hypot(*local_displacement(lat[:-1], lon[:-1], lat[1:], lon[1:]))
    v = d / (np.diff(time_ns) / NS)
    idx = np.flatnonzero(v > max_speed)
    return idx, v[idx]


@dataclass
class GravimeterOptions:
    """Validated ``inputs.gravimeter`` of one flight (paths as written; see module docstring;
    built by :func:`gravsurvey.settings.gravimeter_options`)."""

    format: str
    files: list
    offset_mgal: float = 0.0
    scale: float = 1.0
    counts_scale_mgal: float | None = None
    time_source: str = "auto"
    height_m: float | None = None
    nav: dict | None = None
    key_path: str = "flights[0].inputs.gravimeter"

    def paths(self, base_dir=None) -> list:
        """Gravimeter file(s) then the navigation file, resolved against ``base_dir``."""

        def res(p):
            return Path(base_dir) / p if base_dir is not None else Path(p)

        out = [res(p) for p in self.files]
        if self.nav is not None:
            out.append(res(self.nav["file"]))
        return out


#: Readers :func:`detect_format` tries, in this order: (format, kind, reader name in
#: :mod:`gravsurvey.io.formats`). The distinctive layouts first; the trajectory text, which
#: takes any table of times and positions, last.
DETECT_ORDER = (
    ("mgd77t", "gravimeter", "read_mgd77t"),
    ("nmea", "navigation", "read_nmea"),
    ("bgm_rgs", "gravimeter", "read_bgm_rgs"),
    ("dgs_laptop", "gravimeter", "read_dgs_laptop"),
    ("at1a", "gravimeter", "read_at1a"),
    ("dgs_raw", "gravimeter", "read_dgs_raw"),
    ("zls", "gravimeter", "read_zls"),
    ("bgm_serial", "gravimeter", "read_bgm_serial"),
    ("rtklib", "navigation", "read_rtklib_pos"),
    ("trajectory", "navigation", "read_trajectory"),
)


def detect_format(path, exclude=()):
    """The first gravimeter or navigation reader that takes a file (:data:`DETECT_ORDER`).

    Each reader refuses a file of which fewer than half the content lines are its records.

    Parameters
    ----------
    path : path-like
    exclude : iterable of str
        Formats not to try (one already refused).

    Returns
    -------
    (format, kind, table, warnings) or None
        ``kind`` is ``"gravimeter"`` or ``"navigation"``; ``table`` the
        :class:`~gravsurvey.io.formats.common.FormatTable` read (at least one record);
        ``warnings`` the texts of the reader's warnings. None when no reader takes it.
    """
    from gravsurvey import errors
    from gravsurvey.io import formats

    for fmt, kind, reader in DETECT_ORDER:
        if fmt in exclude:
            continue
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                table = getattr(formats, reader)(path)
            except (errors.GravsurveyError, ValueError, OSError):
                continue
        if len(table):
            return fmt, kind, table, [str(w.message) for w in caught]
    return None


#: Phrases of the readers' refusals that mean "not a file of this format" (not damage within one).
NOT_THIS_FORMAT = ("not a ", "not an ", "no usable GGA or RMC position fix")


def _with_format_hint(exc: DataError, path, fmt: str, hints: dict) -> DataError:
    """``exc`` with the format the file does read as, when its reader refused it as another
    format (``exc`` holds one of :data:`NOT_THIS_FORMAT`) and another reader takes it
    (:func:`detect_format`, ``fmt`` left out); else ``exc`` itself.

    ``hints`` maps the kind found (``"gravimeter"``, ``"navigation"``) to the hint's text, with
    ``{other}`` for the format found.
    """
    if not any(m in str(exc) for m in NOT_THIS_FORMAT) or not Path(path).is_file():
        return exc
    found = detect_format(path, exclude=(fmt,))
    if found is None:
        return exc
    other, kind = found[:2]
    return DataError(f"{exc}; it reads as a {other} {kind} file{hints[kind].format(other=other)}")


def read_gravimeter(o: GravimeterOptions, base_dir=None) -> FormatTable:
    """Read the gravimeter file(s) of ``o`` with the matching reader.

    A file the reader refuses is named with the format it does read as, when another reader
    takes it (:func:`detect_format`).
    """
    from . import bgm, dgs, mgd77t, zls

    paths = o.paths(base_dir)[: len(o.files)]
    for p in paths:
        if not p.exists():
            raise DataError(f"{p}: gravimeter file not found ({o.key_path})")
    try:
        if o.format == "mgd77t":
            return mgd77t.read_mgd77t(paths[0])
        if o.format == "dgs_laptop":
            return dgs.read_dgs_laptop(paths[0], time_source=o.time_source)
        if o.format == "at1a":
            return dgs.read_at1a(paths[0])
        if o.format == "zls":
            return zls.read_zls(paths[0] if len(paths) == 1 else paths)
        if o.format == "bgm_serial":
            return bgm.read_bgm_serial(paths[0], scale_mgal_per_count=o.counts_scale_mgal)
        return bgm.read_bgm_rgs(paths[0])
    except DataError as exc:
        hints = {"navigation": f": give it as {o.key_path}.nav", "gravimeter": f": {o.key_path}.format: {{other}}?"}
        err = _with_format_hint(exc, paths[0], o.format, hints)
        if err is exc:
            raise
        raise err from None


def read_navigation(nav: dict, base_dir=None, key_path: str = "inputs.gravimeter.nav") -> FormatTable:
    """Read an ``inputs.gravimeter.nav`` or ``inputs.nav`` file (NMEA, trajectory text, RTKLIB).

    A file the reader refuses is named with the format it does read as (:func:`detect_format`).
    """
    from .nmea import read_nmea
    from .rtklib import read_rtklib_pos
    from .trajectory import read_trajectory

    p = Path(base_dir) / nav["file"] if base_dir is not None else Path(nav["file"])
    if not p.exists():
        raise DataError(f"{p}: navigation file not found")
    try:
        if nav["format"] == "nmea":
            return read_nmea(p, time_source=nav.get("time_source", "auto"))
        if nav["format"] == "rtklib":
            return read_rtklib_pos(p)
        return read_trajectory(p, time_system=nav.get("time_system", "auto"))
    except DataError as exc:
        hints = {"navigation": f": {key_path}.format: {{other}}?", "gravimeter": ", not navigation"}
        err = _with_format_hint(exc, p, nav["format"], hints)
        if err is exc:
            raise
        raise err from None


def absolute_gravity(table: FormatTable, o: GravimeterOptions, notes: list) -> np.ndarray:
    """Vertical specific force (m/s^2) = scale x reading + offset, from a gravimeter table, shape (n,)."""
    c = table.columns
    if o.format == "mgd77t":
        g = c["gra_obs"] - c["eotvos"]
        notes.append(
            f"{table.source}: f_up = GRA_OBS - EOTVOS (the supplier's Eotvos correction removed; classic applies its own "
            f"from the navigation); {int(np.isfinite(g).sum())} of {len(g)} records have both"
        )
        reading_mgal = g / MGAL
    else:
        reading_mgal = c["gravity"] / MGAL
    return (o.scale * reading_mgal + o.offset_mgal) * MGAL


def gravimeter_record(
    o: GravimeterOptions, base_dir=None, *, gap_factor: float = 5.0, plausibility: str = "error"
) -> FlightRecord:
    """Read a gravimeter file and its navigation into a checked :class:`FlightRecord`.

    Parameters
    ----------
    o : GravimeterOptions
    base_dir : path, optional
        Directory relative paths refer to.
    gap_factor : float
        Gap threshold (x nominal step) for the time repair, as ``checks.gap_factor``.
    plausibility : {'error', 'warn'}
        What an implausible absolute gravity (missing tie) or height does.

    Returns
    -------
    FlightRecord
        Platform triad; see the module docstring.  ``notes`` holds the readers' notes
        (skipped lines, clocks) and the time repair findings.

    Raises
    ------
    DataError
        Unreadable or wrong-format files (from the readers), no overlap between gravimeter and
        navigation, no usable samples, implausible absolute gravity (``plausibility: error``).
    """
    notes: list[str] = []
    gt = read_gravimeter(o, base_dir)
    notes += gt.notes
    f_up = absolute_gravity(gt, o, notes)
    if o.nav is not None:
        nt = read_navigation(o.nav, base_dir, key_path=f"{o.key_path}.nav")
        notes += nt.notes
        nav_t, lat, lon = nt.time_ns, nt.columns["lat"], nt.columns["lon"]
        height = nt.columns.get("height", np.full(len(nt), np.nan))
        nav_src = nt.source
    else:
        nav_t, lat, lon = gt.time_ns, gt.columns["lat"], gt.columns["lon"]
        height = np.full(len(gt), np.nan)
        nav_src = gt.source
    ok = np.isfinite(lat) & np.isfinite(lon)
    if not ok.all():
        notes.append(f"{nav_src}: {int((~ok).sum())} of {ok.size} records without a position dropped")
    nav_t, lat, lon, height = nav_t[ok], lat[ok], lon[ok], height[ok]
    if o.height_m is not None:
        height = np.full(lat.shape, o.height_m)
        notes.append(f"{nav_src}: height {o.height_m:g} m (inputs.gravimeter.height_m)")
    elif not np.isfinite(height).any():
        if GRAVIMETER_FORMATS[o.format]["marine"]:
            height = np.zeros(lat.shape)
            notes.append(
                f"{nav_src}: no heights: the meter is taken at 0 m (sea level on the ellipsoid); set height_m to change"
            )
        else:
            raise DataError(
                f"{nav_src}: no ellipsoidal heights for the {o.format} flight: give a nav file with heights or height_m"
            )
    else:
        hok = np.isfinite(height)
        if not hok.all():
            notes.append(f"{nav_src}: {int((~hok).sum())} positions without a height dropped")
        nav_t, lat, lon, height = nav_t[hok], lat[hok], lon[hok], height[hok]
    g_ok = np.isfinite(f_up)
    if not g_ok.all():
        notes.append(f"{gt.source}: {int((~g_ok).sum())} of {g_ok.size} gravity records without a value dropped")
    g_t, f_up = gt.time_ns[g_ok], f_up[g_ok]
    if g_t.size < 3 or nav_t.size < 3:
        raise DataError(f"{gt.source}: {g_t.size} gravity and {nav_t.size} navigation samples; need at least 3 of each")

    # time repair per channel (order, duplicates, gaps), as for every other input
    findings = []
    g_t, (f_up,), g_rep = ck.repair_time(g_t, [f_up], gap_factor)
    nav_t, (lat, lon, height), n_rep = ck.repair_time(nav_t, [lat, lon, height], gap_factor)
    t0 = int(min(g_t[0], nav_t[0]))
    findings += ck.time_findings("gravimeter", g_rep, t0) + ck.time_findings("navigation", n_rep, t0)
    if o.format != "mgd77t":  # archive dates are real dates even before 2000
        findings += ck.check_epoch("gravimeter", g_t)
    findings += ck.check_gnss(np.degrees(lat), np.degrees(lon))
    vmax = MAX_SPEED_MARINE if GRAVIMETER_FORMATS[o.format]["marine"] else MAX_SPEED_AIRBORNE
    jumps, jv = position_jumps(nav_t, lat, lon, vmax)
    if jumps.size:
        listed = ", ".join(f"{(nav_t[i] - t0) / NS:.0f} s ({v:.0f} m/s)" for i, v in zip(jumps[:10], jv[:10]))
        findings.append(
            ck.Finding(
                "navigation",
                "position jumps",
                "warning",
                f"navigation: {jumps.size} position jump(s) implying more than {vmax:g} m/s at {listed}: the Eotvos "
                "correction and the profile are wrong within a filter length of them (check the navigation)",
            )
        )
    findings += ck.check_height("navigation", height)
    if min(g_t[-1], nav_t[-1]) <= max(g_t[0], nav_t[0]):
        raise DataError(
            f"{gt.source}: gravimeter ({g_t[0] / NS:.0f}..{g_t[-1] / NS:.0f} s) and navigation "
            f"({nav_t[0] / NS:.0f}..{nav_t[-1] / NS:.0f} s, Unix) do not overlap in time: wrong clock or files?"
        )
    med = float(np.median(f_up))
    if not GRAVITY_OK[0] <= med <= GRAVITY_OK[1]:
        findings.append(
            ck.Finding(
                "gravimeter",
                "gravity level",
                "error",
                f"gravimeter: median absolute gravity {med / MGAL:.1f} mGal is outside "
                f"{GRAVITY_OK[0] / MGAL:.0f}..{GRAVITY_OK[1] / MGAL:.0f} mGal: check {o.key_path}.offset_mgal and scale",
                med,
            )
        )
    errors = [f.message for f in findings if f.level == "error"]
    if errors and plausibility == "error":
        raise DataError(
            f"{gt.source}: implausible data: "
            + "; ".join(errors)
            + " (set checks.plausibility: warn to process anyway)"
        )
    notes += [f.message for f in findings if f.level in ("warning", "error")]
    for n in notes:
        warnings.warn(n, DataWarning, stacklevel=2)

    def rel(t):
        return (t - t0) / NS

    z = np.zeros(f_up.size)
    tn = rel(nav_t)
    return FlightRecord(
        t0_unix_ns=t0,
        imu=ImuChannel(rel(g_t), np.column_stack((z, z, f_up)), np.zeros((f_up.size, 3))),
        altimeter=AltimeterChannel(tn, height.copy()),
        gnss=GnssChannel(tn, lat, lon, height),
        source=", ".join(os.fspath(p) for p in o.paths(base_dir)),
        notes=notes,
    )


def gap_spans(time_s, gap_factor: float):
    """Gaps of a channel: steps longer than ``gap_factor`` x its median step.

    Parameters
    ----------
    time_s : ndarray, shape (n,)
        Strictly increasing sample times, s.
    gap_factor : float

    Returns
    -------
    ndarray, shape (k, 2)
        ``[start, stop]`` of each gap (the samples either side), s.
    """
    t = np.asarray(time_s, float)
    if t.size < 3:
        return np.zeros((0, 2))
    d = np.diff(t)
    i = np.flatnonzero(d > gap_factor * np.median(d))
    return np.column_stack((t[i], t[i + 1]))


def blank_gaps(result, record: FlightRecord, gap_factor: float = 5.0):
    """Set the classic profile to NaN wherever its low-pass window reaches into a data gap.

    The classic reduction bridges gaps of the gravimeter channel linearly and of the navigation
    by a spline, which yields made-up values there (up to 1000 mGal inside a 38-minute gap of the
    real NBP9908 cruise).  For gravimeter inputs these epochs are removed: the filtered
    disturbance is NaN within the kernel half width (+ one step) of every gravimeter or
    navigation gap, the raw one inside the gaps themselves.  In place.

    Parameters
    ----------
    result : ClassicResult
    record : FlightRecord
        The record the result came from (its time base).
    gap_factor : float
        As ``checks.gap_factor``.

    Returns
    -------
    int
        Epochs blanked.
    """
    reach = float(result.info.get("kernel_half_width_s", 0.0)) + float(result.info.get("dt_s", 0.0))
    t = np.asarray(result.time, float)
    bad = np.zeros(t.size, bool)
    inside = np.zeros(t.size, bool)
    spans = [gap_spans(record.imu.time, gap_factor)]
    if record.gnss is not None:
        spans.append(gap_spans(record.gnss.time, gap_factor))
    spans = np.concatenate(spans)
    for a, b in spans:
        bad |= (t > a - reach) & (t < b + reach)
        inside |= (t > a) & (t < b)
    if bad.any():
        result.disturbance = np.where(bad, np.nan, result.disturbance)
        result.raw = np.where(inside, np.nan, result.raw)
        result.info.setdefault("notes", []).append(
            f"{int(bad.sum())} of {t.size} epochs within the filter's reach ({reach:g} s) of {len(spans)} gravimeter/"
            "navigation gaps set to NaN"
        )
    return int(bad.sum())
