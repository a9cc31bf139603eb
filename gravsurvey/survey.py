"""Survey geometry: line segmentation of a flight, and crossovers between lines.

Segmentation
------------
:func:`segment_lines` splits a flight into survey lines (``L01, L02, ...``), tie lines
(``T01, ...``: straight legs across the main direction), transits (``transit01, ...``: straight
legs at other headings), turns (``turn01, ...``: everything moving that is not a straight leg,
including climbs, straights shorter than ``min_line_m`` and curved legs) and static periods (``static01, ...``: ground speed
below ``min_speed_mps``: parked or taxiing). The segments cover the flight without gaps, in time
order. :func:`segments_from_windows` takes explicit time windows from the configuration instead
and :class:`SegmentationOptions` parses the ``lines:`` configuration section.

Crossovers
----------
:func:`find_crossovers` intersects the ground tracks (projected easting/northing polylines) of
every pair of different lines, within a flight and across flights, interpolates each line's value
linearly at the intersection and returns the differences with their statistics (the standard
internal-consistency check of an airborne gravity survey: if both lines carry independent errors
of equal size, ``rms / sqrt(2)`` estimates the error of one line).

Units: SI inside (s, m, rad); the values compared at crossovers are in mGal (named so);
headings and angles at the edges in degrees (named ``_deg``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import uniform_filter1d

from gravsurvey.errors import ConfigError, DataError, check_keys
from gravsurvey.geodesy import radii_of_curvature

__all__ = [
    "Segment",
    "SegmentationOptions",
    "segment_lines",
    "segments_from_windows",
    "segment_flight",
    "segment_table",
    "Crossovers",
    "find_crossovers",
]

KINDS = ("line", "tie", "turn", "static", "transit")


# --------------------------------------------------------------------------------------------
# Segmentation
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Segment:
    """One piece of a flight.

    Attributes
    ----------
    name : str
        ``L01, L02, ...`` for lines, ``T01, ...`` for tie lines, ``turn01, ...``, ``static01, ...``
        (numbered in time order within each kind); the configured name for time windows.
    kind : str
        ``"line"``, ``"tie"``, ``"turn"`` or ``"static"``.
    start_index, stop_index : int
        Sample range ``[start_index, stop_index)`` (Python slice convention) into the arrays the
        segmentation was computed on.
    heading_deg : float
        Mean track heading (clockwise from north, [0, 360)) for lines and tie lines, NaN otherwise.
    """

    name: str
    kind: str
    start_index: int
    stop_index: int
    heading_deg: float = float("nan")

    @property
    def slice(self) -> slice:
        """The sample range as a slice."""
        return slice(self.start_index, self.stop_index)

    def __len__(self) -> int:
        return self.stop_index - self.start_index


def segment_table(segments: list[Segment], time_s: np.ndarray) -> list[dict]:
    """Segments as plain dicts for reports (summary.json).

    Parameters
    ----------
    segments : list of Segment
    time_s : ndarray, shape (n,)
        The time base the segments index, s.

    Returns
    -------
    list of dict
        ``name, kind, start_index, stop_index, n_samples, start_s, stop_s, duration_s,
        heading_deg`` (heading None for turns and static periods).
    """
    time_s = np.asarray(time_s, dtype=float)
    out = []
    for s in segments:
        t0 = float(time_s[s.start_index])
        t1 = float(time_s[s.stop_index - 1])
        out.append(
            {
                "name": s.name,
                "kind": s.kind,
                "start_index": int(s.start_index),
                "stop_index": int(s.stop_index),
                "n_samples": int(s.stop_index - s.start_index),
                "start_s": t0,
                "stop_s": t1,
                "duration_s": t1 - t0,
                "heading_deg": None if not np.isfinite(s.heading_deg) else float(s.heading_deg),
            }
        )
    return out


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Half-open index ranges of the True runs of a boolean array."""
    m = np.concatenate(([False], np.asarray(mask, dtype=bool), [False]))
    d = np.flatnonzero(m[1:] != m[:-1])
    return [(int(a), int(b)) for a, b in zip(d[::2], d[1::2])]


def _wrap_deg(a):
    """Wrap angles to [-180, 180) deg."""
    return (np.asarray(a) + 180.0) % 360.0 - 180.0


def _circmean_deg(h_deg: np.ndarray) -> float:
    r = np.radians(h_deg)
    return float(np.degrees(np.arctan2(np.mean(np.sin(r)), np.mean(np.cos(r)))) % 360.0)


def _check_track(time_s, lat_rad, lon_rad, vel_enu):
    t = np.asarray(time_s, dtype=float)
    if t.ndim != 1 or t.size < 2:
        raise DataError(f"segmentation: time must be a 1-D array of >= 2 samples, got shape {t.shape}")
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        raise DataError("segmentation: time must be finite and strictly increasing")
    lat = np.broadcast_to(np.asarray(lat_rad, dtype=float), t.shape)
    lon = np.broadcast_to(np.asarray(lon_rad, dtype=float), t.shape)
    if vel_enu is None:
        # Track velocity from positions (height ignored: < 0.2 % error in speed at 12 km).
        m_rad, n_rad = radii_of_curvature(lat)
        lon_u = np.unwrap(lon)
        vn = np.gradient(lat, t) * m_rad
        ve = np.gradient(lon_u, t) * n_rad * np.cos(lat)
        v = np.column_stack([ve, vn, np.zeros_like(ve)])
    else:
        v = np.asarray(vel_enu, dtype=float)
        if v.shape != (t.size, 3):
            raise DataError(f"segmentation: vel_enu must have shape ({t.size}, 3), got {v.shape}")
    return t, lat, lon, v


def segment_lines(
    time_s,
    lat_rad,
    lon_rad,
    vel_enu=None,
    *,
    min_line_s: float | None = None,
    heading_tol_deg: float = 10.0,
    min_speed_mps: float = 20.0,
    max_turn_rate_degps: float = 1.0,
    max_vertical_speed_mps: float | None = 4.0,
    speed_tol_mps: float = 10.0,
    smooth_s: float = 10.0,
    merge_gap_s: float = 20.0,
    tie_angle_deg: float = 45.0,
    min_line_m: float = 2000.0,
    transit_angle_deg: float | None = 20.0,
    options: "SegmentationOptions | None" = None,
) -> list[Segment]:
    """Split a flight into straight lines, tie lines, turns and static periods.

    The track heading and ground speed come from the horizontal velocity, smoothed with a
    centred moving average over ``smooth_s`` (turbulence: heading wander of a few degrees, speed
    wobble). A sample is a *straight candidate* when the aircraft moves (smoothed ground speed
    >= ``min_speed_mps``), flies level (smoothed |vertical speed| <= ``max_vertical_speed_mps``)
    and the smoothed heading changes by less than ``max_turn_rate_degps`` over the smoothing
    window. Each run of candidates is split where the heading leaves ``heading_tol_deg`` of the
    run's mean heading or the speed leaves ``speed_tol_mps`` of its median, and each piece is
    extended outwards while both stay within tolerance. Its ends are then trimmed, within
    ``2 * smooth_s`` of each end, to where the heading deviation (and, at an end where the
    growth stopped on speed, i.e. a take-off or landing speed ramp, the speed deviation) first
    exceeds an edge threshold (4 robust standard deviations within the piece; at least 2 deg
    and 1 m/s, at most the tolerances), so a line stops where the turn or the speed ramp
    starts, not where it is a whole tolerance into it. Neighbouring pieces separated by less than ``merge_gap_s``
    (a gust) are merged when their mean headings agree within ``heading_tol_deg / 2`` (so the
    pieces of a slow curve are not chained into a line). On a slow curve the line still takes
    the samples within ``heading_tol_deg`` of its heading: that is the definition of straight.
    Pieces shorter than ``min_line_m`` along track (and, if given, than ``min_line_s``) are not
    lines: survey lines are specified by length, and a time limit would drop short lines flown
    fast (a 120-s limit dropped the 8-km lines and a tie of a survey flown at 70 m/s). Nor are
    pieces whose heading trend turns them by more than ``heading_tol_deg / 2`` over their
    length (pieces of a slow curve, flown under ``max_turn_rate_degps``).

    The dominant direction is the axial heading (modulo 180 deg) carrying the most line length.
    Straight pieces within ``transit_angle_deg`` of it are lines, those within
    ``transit_angle_deg`` of its perpendicular are tie (control) lines, and the straight pieces
    in between are transits (kind ``"transit"``, named ``transit01, ...``: processed, but not
    lines, like turns). With ``transit_angle_deg`` None, pieces more than ``tie_angle_deg``
    from the dominant direction are tie lines and nothing is a transit.

    Parameters
    ----------
    time_s : array_like, shape (n,)
        Strictly increasing time, s.
    lat_rad, lon_rad : array_like, shape (n,)
        Geodetic latitude and longitude, rad (used for the velocity when ``vel_enu`` is None).
    vel_enu : array_like, shape (n, 3), optional
        Velocity relative to the Earth, East-North-Up, m/s. Non-finite rows count as turns.
    min_line_s : float or None
        Shortest line in time, s (None: no time limit; the length limit applies).
    heading_tol_deg : float
        Largest deviation of the smoothed track heading from the line's mean heading, deg.
    min_speed_mps : float
        Below this smoothed ground speed the aircraft is "static" (parked or taxiing), m/s.
    max_turn_rate_degps : float
        Straight candidates turn slower than this, deg/s (a standard-rate turn is 3 deg/s).
    max_vertical_speed_mps : float or None
        Climbs and descents faster than this are not lines, m/s; None disables the test.
    speed_tol_mps : float
        Largest deviation of the smoothed ground speed from the line's median, m/s (a line is
        flown at steady speed: take-off and landing speed ramps are not lines).
    smooth_s : float
        Moving-average window, s.
    merge_gap_s : float
        Pieces on the same heading separated by less than this are one line, s.
    tie_angle_deg : float
        With ``transit_angle_deg`` None: straight pieces whose axial heading differs from the
        dominant one by more than this are tie lines, deg.
    min_line_m : float
        Shortest line along track, m.
    transit_angle_deg : float or None
        Largest axial heading difference of a line from the dominant direction, and of a tie
        line from its perpendicular, deg; pieces in between are transits.
    options : SegmentationOptions, optional
        The ``lines:`` configuration; when given, its detection settings replace the keyword
        arguments above (its ``mode`` and ``windows`` are ignored here: see :func:`segment_flight`).

    Returns
    -------
    list of Segment
        Covering ``[0, n)`` without gaps, in time order.

    Raises
    ------
    DataError
        Time not strictly increasing, or arrays of the wrong shape.
    """
    if options is not None:
        kw = options.detection_kwargs()
        min_line_s, heading_tol_deg, min_speed_mps = kw["min_line_s"], kw["heading_tol_deg"], kw["min_speed_mps"]
        max_turn_rate_degps, max_vertical_speed_mps = kw["max_turn_rate_degps"], kw["max_vertical_speed_mps"]
        smooth_s, merge_gap_s, tie_angle_deg = kw["smooth_s"], kw["merge_gap_s"], kw["tie_angle_deg"]
        speed_tol_mps = kw["speed_tol_mps"]
        min_line_m, transit_angle_deg = kw["min_line_m"], kw["transit_angle_deg"]
    t, _lat, _lon, v = _check_track(time_s, lat_rad, lon_rad, vel_enu)
    n = t.size
    dt = float(np.median(np.diff(t)))
    w = max(1, int(round(smooth_s / dt)))
    finite = np.all(np.isfinite(v), axis=1)
    vv = np.where(finite[:, None], v, 0.0)
    # Smooth the velocity components (not the angle): no wrap problems, speed-weighted heading.
    # Normalised convolution: gaps (non-finite rows) do not drag the averages towards zero.
    wsum = np.maximum(uniform_filter1d(finite.astype(float), w, mode="nearest"), 1e-12)
    ve_s = uniform_filter1d(vv[:, 0], w, mode="nearest") / wsum
    vn_s = uniform_filter1d(vv[:, 1], w, mode="nearest") / wsum
    vu_s = uniform_filter1d(vv[:, 2], w, mode="nearest") / wsum
    speed_s = uniform_filter1d(np.hypot(vv[:, 0], vv[:, 1]), w, mode="nearest") / wsum
    heading = np.degrees(np.arctan2(ve_s, vn_s)) % 360.0
    heading_u = np.degrees(np.unwrap(np.radians(heading)))
    # Heading change across the smoothing window (centred), deg/s.
    h = max(1, w // 2)
    idx = np.arange(n)
    lo = np.clip(idx - h, 0, n - 1)
    hi = np.clip(idx + h, 0, n - 1)
    rate = np.abs(heading_u[hi] - heading_u[lo]) / np.maximum(t[hi] - t[lo], 1e-9)

    moving = finite & (speed_s >= min_speed_mps)
    static = finite & ~moving
    level = np.ones(n, bool) if max_vertical_speed_mps is None else np.abs(vu_s) <= max_vertical_speed_mps
    usable = moving & level
    candidate = usable & (rate < max_turn_rate_degps)

    # shortest core piece: half the shortest line at the typical ground speed, <= 30 s
    v_typ = float(np.median(speed_s[moving])) if moving.any() else max(min_speed_mps, 1.0)
    min_core_s = min(0.5 * min_line_m / max(v_typ, 1.0), 30.0)
    if min_line_s is not None:
        min_core_s = min(min_core_s, 0.25 * min_line_s)
    pieces: list[list] = []  # [start, stop, mean heading (deg), median speed (m/s)]

    def split(a: int, b: int, depth: int = 0) -> None:
        if t[b - 1] - t[a] < min_core_s:
            return
        h0 = _circmean_deg(heading[a:b])
        v0 = float(np.median(speed_s[a:b]))
        ok = (np.abs(_wrap_deg(heading[a:b] - h0)) <= heading_tol_deg) & (np.abs(speed_s[a:b] - v0) <= speed_tol_mps)
        if ok.all():
            pieces.append([a, b, h0, v0])
            return
        if depth > 12:
            return
        if not ok.any():
            # e.g. two headings either side of the mean: halve
            mid = (a + b) // 2
            split(a, mid, depth + 1)
            split(mid, b, depth + 1)
            return
        # both the parts within tolerance and the parts outside it may hold lines
        for ra, rb in _runs(ok) + _runs(~ok):
            split(a + ra, a + rb, depth + 1)

    for a, b in _runs(candidate):
        split(a, b)

    # Grow each piece while heading and speed stay within tolerance, then trim the ends to
    # where the turn or the speed change starts.
    grown = []
    win = max(1, int(round(2.0 * smooth_s / dt)))
    for a, b, h0, v0 in pieces:
        dev = np.abs(_wrap_deg(heading - h0))
        dv = np.abs(speed_s - v0)
        ok = usable & (dev <= heading_tol_deg) & (dv <= speed_tol_mps)  # usable excludes non-finite rows
        while a > 0 and ok[a - 1]:
            a -= 1
        while b < n and ok[b]:
            b += 1
        mad_h = 1.4826 * np.median(np.abs(_wrap_deg(heading[a:b] - _circmean_deg(heading[a:b]))))
        mad_v = 1.4826 * np.median(np.abs(speed_s[a:b] - np.median(speed_s[a:b])))
        edge_h = float(np.clip(4.0 * mad_h, 2.0, heading_tol_deg))
        edge_v = float(np.clip(4.0 * mad_v, 1.0, speed_tol_mps))
        # The speed edge counts only where the growth stopped on speed (a speed ramp): inside
        # a line, gusts move the ground speed by several m/s and must not cut it.
        slow = dv > speed_tol_mps
        slow |= speed_s < min_speed_mps
        bad_h = dev > edge_h
        bad_v = dv > edge_v
        bad = bad_h | bad_v if a > 0 and slow[a - 1] else bad_h
        head = np.flatnonzero(bad[a : min(a + win, b)])
        if head.size:
            a = a + int(head[-1]) + 1
        bad = bad_h | bad_v if b < n and slow[b] else bad_h
        lo_tail = max(a, b - win)
        tail = np.flatnonzero(bad[lo_tail:b])
        if tail.size:
            b = lo_tail + int(tail[0])
        if b - a >= 2:
            grown.append([a, b])
    # Remove overlaps (two pieces that grew into each other), then merge across short gaps.
    grown.sort()
    merged: list[list] = []
    for a, b in grown:
        if merged and a <= merged[-1][1]:
            pa, pb = merged[-1]
            if _same_heading(heading, pa, pb, a, b, heading_tol_deg):
                merged[-1][1] = max(pb, b)
                continue
            a = merged[-1][1]
            if b - a < 2:
                continue
        if (
            merged
            and t[a] - t[merged[-1][1] - 1] <= merge_gap_s
            and not static[merged[-1][1] : a].any()
            and finite[merged[-1][1] : a].all()
            and _same_heading(heading, merged[-1][0], merged[-1][1], a, b, heading_tol_deg)
        ):
            merged[-1][1] = b
            continue
        merged.append([a, b])
    # along-track length of each piece from the raw ground speed (trapezoid rule)
    gs = np.hypot(vv[:, 0], vv[:, 1])
    cum = np.concatenate(([0.0], np.cumsum(0.5 * (gs[1:] + gs[:-1]) * np.diff(t))))
    straight = [
        (a, b) for a, b in merged
        if cum[b - 1] - cum[a] >= min_line_m and (min_line_s is None or t[b - 1] - t[a] >= min_line_s)
        and _heading_drift_deg(t[a:b], heading_u[a:b]) <= 0.5 * heading_tol_deg
    ]

    # Dominant axial direction by line time: histogram of doubled angles, 5-deg bins.
    kinds = {}
    if straight:
        ax = np.array([_circmean_deg(heading[a:b]) % 180.0 for a, b in straight])
        dur = np.array([cum[b - 1] - cum[a] for a, b in straight])  # weights: line length
        bins = np.arange(0.0, 180.0, 5.0)
        # axial distance |ax - c| (mod 180) = |wrap(2 (ax - c))| / 2
        axial = np.abs(_wrap_deg(2.0 * (ax[None, :] - bins[:, None]))) / 2.0
        score = (dur[None, :] * (axial <= tie_angle_deg / 2.0)).sum(axis=1)
        near = axial[int(np.argmax(score))] <= tie_angle_deg / 2.0
        d2 = np.radians(2.0 * ax[near])
        dom = (np.degrees(np.arctan2((dur[near] * np.sin(d2)).sum(), (dur[near] * np.cos(d2)).sum())) / 2.0) % 180.0
        for (a, b), x in zip(straight, ax):
            diff = abs(_wrap_deg(2.0 * (x - dom))) / 2.0
            if transit_angle_deg is None:
                kinds[(a, b)] = "tie" if diff > tie_angle_deg else "line"
            elif diff <= transit_angle_deg:
                kinds[(a, b)] = "line"
            elif diff >= 90.0 - transit_angle_deg:
                kinds[(a, b)] = "tie"
            else:
                kinds[(a, b)] = "transit"

    # Assemble the full cover: lines/ties, then the rest as static or turn runs.
    label = np.zeros(n, dtype=np.int8)  # 0 turn, 1 static, 2 straight
    label[static] = 1
    for a, b in straight:
        label[a:b] = 2
    segs: list[tuple[str, int, int, float]] = []
    for a, b in straight:
        segs.append((kinds[(a, b)], a, b, _circmean_deg(heading[a:b])))
    rest = label != 2
    for a, b in _runs(rest):
        # split the non-line stretch into static and turn runs
        sub = label[a:b]
        for ra, rb in _runs(sub == 1):
            segs.append(("static", a + ra, a + rb, float("nan")))
        for ra, rb in _runs(sub == 0):
            segs.append(("turn", a + ra, a + rb, float("nan")))
    segs.sort(key=lambda s: s[1])
    counters = {"line": 0, "tie": 0, "turn": 0, "static": 0, "transit": 0}
    prefix = {"line": "L", "tie": "T", "turn": "turn", "static": "static", "transit": "transit"}
    out = []
    for kind, a, b, hd in segs:
        counters[kind] += 1
        out.append(Segment(f"{prefix[kind]}{counters[kind]:02d}", kind, int(a), int(b), float(hd)))
    return out


def _heading_drift_deg(t, heading_unwrapped_deg) -> float:
    """Heading change across a piece from its least-squares trend, deg.

    A straight line's heading wanders (turbulence) but has no trend; a piece of a slow curve
    (0.3 deg/s: under the turn-rate limit) turns steadily by up to ``2 * heading_tol_deg``.
    """
    tt = t - t.mean()
    den = float(np.dot(tt, tt))
    if den <= 0:
        return 0.0
    slope = float(np.dot(tt, heading_unwrapped_deg - heading_unwrapped_deg.mean())) / den
    return abs(slope) * float(t[-1] - t[0])


def _same_heading(heading, a0, b0, a1, b1, tol):
    """Do heading[a0:b0] and heading[a1:b1] belong to one line? Means within tol / 2."""
    return abs(_wrap_deg(_circmean_deg(heading[a0:b0]) - _circmean_deg(heading[a1:b1]))) <= 0.5 * tol


def segments_from_windows(time_s, windows: list[dict], *, key_path: str = "lines.windows") -> list[Segment]:
    """Segments from explicit time windows.

    Parameters
    ----------
    time_s : array_like, shape (n,)
        Strictly increasing time of the flight, s (the same time base as the windows:
        s after the flight's first sample).
    windows : list of dict
        Each ``{"name": str, "start_s": float, "stop_s": float}`` and optionally
        ``"kind": "line" | "tie"`` (default: ``"tie"`` if the name starts with ``T`` followed by
        a digit, else ``"line"``). A window includes the samples with
        ``start_s <= t <= stop_s``.
    key_path : str
        Where the windows came from, for error messages.

    Returns
    -------
    list of Segment
        One per window, in the given order (only the windows, no turn/static cover).

    Raises
    ------
    ConfigError
        A window is malformed, names repeat, or a window holds fewer than 2 samples of the flight.
    """
    t = np.asarray(time_s, dtype=float)
    if not isinstance(windows, (list, tuple)) or not windows:
        raise ConfigError(f"{key_path}: expected a non-empty list of {{name, start_s, stop_s}}")
    out = []
    seen = set()
    for i, wdw in enumerate(windows):
        kp = f"{key_path}[{i}]"
        if not isinstance(wdw, dict):
            raise ConfigError(f"{kp}: expected a mapping with name, start_s, stop_s")
        check_keys(wdw, ("name", "start_s", "stop_s", "kind"), kp)
        for k in ("name", "start_s", "stop_s"):
            if k not in wdw:
                raise ConfigError(f"{kp}: missing key '{k}'")
        name = wdw["name"]
        if not isinstance(name, str) or not name:
            raise ConfigError(f"{kp}.name: expected a non-empty string, got {name!r}")
        if name in seen:
            raise ConfigError(f"{kp}.name: '{name}' appears twice")
        seen.add(name)
        try:
            t0 = float(wdw["start_s"])
            t1 = float(wdw["stop_s"])
        except (TypeError, ValueError):
            raise ConfigError(f"{kp}: start_s and stop_s must be numbers (s)") from None
        if not (math.isfinite(t0) and math.isfinite(t1)) or t1 <= t0:
            raise ConfigError(f"{kp}: expected finite start_s < stop_s, got {t0} .. {t1}")
        kind = wdw.get("kind")
        if kind is None:
            kind = "tie" if len(name) > 1 and name[0] == "T" and name[1].isdigit() else "line"
        if kind not in ("line", "tie"):
            raise ConfigError(f"{kp}.kind: expected 'line' or 'tie', got {kind!r}")
        a = int(np.searchsorted(t, t0, side="left"))
        b = int(np.searchsorted(t, t1, side="right"))
        if b - a < 2:
            raise ConfigError(
                f"{kp}: window {t0:g} .. {t1:g} s holds {max(b - a, 0)} samples of the flight "
                f"(flight spans {t[0]:g} .. {t[-1]:g} s)"
            )
        out.append(Segment(name, kind, a, b))
    return out


@dataclass
class SegmentationOptions:
    """The ``lines:`` configuration section.

    Attributes
    ----------
    mode : str
        ``auto`` (straight-line detection, :func:`segment_lines`), ``windows`` (explicit time
        windows, :func:`segments_from_windows`) or ``whole`` (the whole flight is line ``L01``).
    min_line_s, heading_tol_deg, min_speed_mps, max_turn_rate_degps, max_vertical_speed_mps,
    speed_tol_mps, smooth_s, merge_gap_s, tie_angle_deg, min_line_m, transit_angle_deg
        See :func:`segment_lines` (units in the names; ``max_vertical_speed_mps``,
        ``min_line_s`` and ``transit_angle_deg`` may be null).
    windows : list of dict
        For ``mode: windows``: ``{name, start_s, stop_s[, kind]}``, s after the flight's first sample.
    """

    mode: str = "auto"
    min_line_s: float | None = None
    heading_tol_deg: float = 10.0
    min_speed_mps: float = 20.0
    max_turn_rate_degps: float = 1.0
    max_vertical_speed_mps: float | None = 4.0
    speed_tol_mps: float = 10.0
    smooth_s: float = 10.0
    merge_gap_s: float = 20.0
    tie_angle_deg: float = 45.0
    windows: list = field(default_factory=list)
    min_line_m: float = 2000.0
    transit_angle_deg: float | None = 20.0

    _POSITIVE = ("min_line_s", "heading_tol_deg", "max_turn_rate_degps", "smooth_s", "speed_tol_mps", "min_line_m")
    _NULLABLE = ("max_vertical_speed_mps", "min_line_s", "transit_angle_deg")
    _NONNEG = ("min_speed_mps", "merge_gap_s")

    @classmethod
    def keys(cls) -> tuple[str, ...]:
        """Valid configuration keys."""
        return (
            "mode",
            "min_line_s",
            "heading_tol_deg",
            "min_speed_mps",
            "max_turn_rate_degps",
            "max_vertical_speed_mps",
            "speed_tol_mps",
            "smooth_s",
            "merge_gap_s",
            "tie_angle_deg",
            "windows",
            "min_line_m",
            "transit_angle_deg",
        )

    @classmethod
    def from_dict(cls, d: dict | None, key_path: str = "lines") -> "SegmentationOptions":
        """Validate and build from a parsed YAML mapping.

        Raises
        ------
        ConfigError
            Unknown key (nearest valid key suggested), wrong type, out-of-range value, or
            ``mode: windows`` without windows; the message names the key path.
        """
        if d is None:
            d = {}
        if not isinstance(d, dict):
            raise ConfigError(f"{key_path}: expected a mapping, got {type(d).__name__}")
        check_keys(d, cls.keys(), key_path)
        opts = cls()
        if "mode" in d:
            if d["mode"] not in ("auto", "windows", "whole"):
                raise ConfigError(f"{key_path}.mode: expected one of auto, windows, whole, got {d['mode']!r}")
            opts.mode = d["mode"]
        for k in cls.keys():
            if k in ("mode", "windows") or k not in d:
                continue
            val = d[k]
            if k in cls._NULLABLE and val is None:
                setattr(opts, k, None)
                continue
            if isinstance(val, bool) or not isinstance(val, (int, float)) or not math.isfinite(val):
                raise ConfigError(f"{key_path}.{k}: expected a number, got {val!r}")
            val = float(val)
            if k in cls._POSITIVE and val <= 0:
                raise ConfigError(f"{key_path}.{k}: must be > 0, got {val:g}")
            if k in cls._NONNEG and val < 0:
                raise ConfigError(f"{key_path}.{k}: must be >= 0, got {val:g}")
            if k == "tie_angle_deg" and not 0 < val < 90:
                raise ConfigError(f"{key_path}.{k}: must be in (0, 90) deg, got {val:g}")
            if k == "transit_angle_deg" and not 0 < val < 45:
                raise ConfigError(f"{key_path}.{k}: must be in (0, 45) deg or null, got {val:g}")
            if k == "max_vertical_speed_mps" and val <= 0:
                raise ConfigError(f"{key_path}.{k}: must be > 0 or null, got {val:g}")
            setattr(opts, k, val)
        if "windows" in d:
            wins = d["windows"]
            if not isinstance(wins, list):
                raise ConfigError(f"{key_path}.windows: expected a list of {{name, start_s, stop_s}}")
            # Structure checked here; names, numbers and time coverage per flight in segments_from_windows.
            for i, wdw in enumerate(wins):
                kp = f"{key_path}.windows[{i}]"
                if not isinstance(wdw, dict):
                    raise ConfigError(f"{kp}: expected a mapping with name, start_s, stop_s")
                check_keys(wdw, ("name", "start_s", "stop_s", "kind"), kp)
            opts.windows = list(wins)
        if opts.mode == "windows" and not opts.windows:
            raise ConfigError(f"{key_path}.windows: required (a non-empty list) when mode is 'windows'")
        return opts

    def detection_kwargs(self) -> dict:
        """Keyword arguments for :func:`segment_lines`."""
        return {
            k: getattr(self, k)
            for k in self.keys()
            if k not in ("mode", "windows")
        }


def segment_flight(options: SegmentationOptions, time_s, lat_rad, lon_rad, vel_enu=None, *, key_path="lines"):
    """Segment one flight as the configuration says.

    Returns
    -------
    list of Segment
        ``auto``: the full cover from :func:`segment_lines`; ``windows``: the windows;
        ``whole``: a single line ``L01`` over every sample.
    """
    t = np.asarray(time_s, dtype=float)
    if options.mode == "whole":
        if t.size < 2:
            raise DataError(f"segmentation: the flight has {t.size} samples, need >= 2")
        return [Segment("L01", "line", 0, int(t.size))]
    if options.mode == "windows":
        return segments_from_windows(t, options.windows, key_path=f"{key_path}.windows")
    return segment_lines(t, lat_rad, lon_rad, vel_enu, **options.detection_kwargs())


# --------------------------------------------------------------------------------------------
# Crossovers
# --------------------------------------------------------------------------------------------
@dataclass
class Crossovers:
    """Crossover points between lines and their statistics.

    Row ``k`` is one intersection of line ``a`` (earlier in the input list) with line ``b``.
    ``diff_mgal = value_a_mgal - value_b_mgal``. Rows whose value is NaN on either line are kept
    but left out of all statistics.

    Attributes
    ----------
    flight_a, line_a, flight_b, line_b : ndarray of str, shape (k,)
    easting_m, northing_m : ndarray, shape (k,)
        Intersection point, m (the projected coordinates the lines came in).
    time_a_s, time_b_s : ndarray, shape (k,)
        Time on each line at the intersection (interpolated), s.
    value_a_mgal, value_b_mgal, diff_mgal : ndarray, shape (k,)
    angle_deg : ndarray, shape (k,)
        Crossing angle of the two tracks, deg in (0, 90].
    per_line : list of dict
        One per input line: ``flight, line, count, mean_mgal, rms_mgal, rms_over_sqrt2_mgal``,
        with differences taken as (this line - other line).
    """

    flight_a: np.ndarray
    line_a: np.ndarray
    flight_b: np.ndarray
    line_b: np.ndarray
    easting_m: np.ndarray
    northing_m: np.ndarray
    time_a_s: np.ndarray
    time_b_s: np.ndarray
    value_a_mgal: np.ndarray
    value_b_mgal: np.ndarray
    diff_mgal: np.ndarray
    angle_deg: np.ndarray
    per_line: list = field(default_factory=list)

    COLUMNS = (
        "flight_a",
        "line_a",
        "flight_b",
        "line_b",
        "easting_m",
        "northing_m",
        "time_a_s",
        "time_b_s",
        "value_a_mgal",
        "value_b_mgal",
        "diff_mgal",
        "angle_deg",
    )

    def __len__(self) -> int:
        return int(self.diff_mgal.size)

    @property
    def valid(self) -> np.ndarray:
        """Rows with a finite difference."""
        return np.isfinite(self.diff_mgal)

    @property
    def count(self) -> int:
        """Number of crossovers with a finite difference."""
        return int(self.valid.sum())

    @property
    def mean_mgal(self) -> float:
        """Mean difference, mGal (NaN if none)."""
        d = self.diff_mgal[self.valid]
        return float(d.mean()) if d.size else float("nan")

    @property
    def rms_mgal(self) -> float:
        """Root mean square of the differences, mGal (NaN if none)."""
        d = self.diff_mgal[self.valid]
        return float(np.sqrt(np.mean(d**2))) if d.size else float("nan")

    @property
    def rms_over_sqrt2_mgal(self) -> float:
        """RMS / sqrt(2): the error of one line if both carry equal independent errors, mGal."""
        return self.rms_mgal / math.sqrt(2.0)

    def statistics(self) -> dict:
        """Statistics for summary.json (NaN where undefined; the JSON writer makes it null).

        Returns
        -------
        dict
            ``count, count_invalid, mean_mgal, rms_mgal, rms_over_sqrt2_mgal`` for the survey
            and ``per_line``: ``"<flight>/<line>"`` -> ``{count, mean_mgal, rms_mgal,
            rms_over_sqrt2_mgal}`` (differences as this line - other line).
        """
        return {
            "count": self.count,
            "count_invalid": int(len(self) - self.count),
            "mean_mgal": self.mean_mgal,
            "rms_mgal": self.rms_mgal,
            "rms_over_sqrt2_mgal": self.rms_over_sqrt2_mgal,
            "per_line": {
                f"{p['flight']}/{p['line']}": {k: v for k, v in p.items() if k not in ("flight", "line")}
                for p in self.per_line
            },
        }


def _line_arrays(ln: dict, i: int):
    for k in ("flight", "line", "easting_m", "northing_m", "value_mgal", "time_s"):
        if k not in ln:
            raise DataError(f"crossovers: line #{i} lacks '{k}'")
    e = np.asarray(ln["easting_m"], dtype=float)
    nn = np.asarray(ln["northing_m"], dtype=float)
    v = np.asarray(ln["value_mgal"], dtype=float)
    t = np.asarray(ln["time_s"], dtype=float)
    if not (e.ndim == 1 and e.shape == nn.shape == v.shape == t.shape):
        raise DataError(
            f"crossovers: line {ln['flight']}/{ln['line']}: easting_m, northing_m, value_mgal, time_s "
            f"must be 1-D of equal length, got {e.shape}, {nn.shape}, {v.shape}, {t.shape}"
        )
    return e, nn, v, t


class _Track:
    """A line's polyline with per-chunk bounding boxes (the prefilter)."""

    def __init__(self, e, n, v, t, chunk):
        self.e, self.n, self.v, self.t = e, n, v, t
        m = e.size
        self.nseg = max(m - 1, 0)
        ok = np.isfinite(e) & np.isfinite(n)
        self.seg_ok = ok[:-1] & ok[1:] if m > 1 else np.zeros(0, bool)
        self.chunk = chunk
        if self.nseg == 0 or not self.seg_ok.any():
            self.nchunk = 0
            return
        starts = np.arange(0, self.nseg, chunk)
        self.nchunk = starts.size
        # bbox of points [s, s+chunk] inclusive (the last segment's end point belongs to the chunk)
        ee = np.where(ok, e, np.nan)
        nn = np.where(ok, n, np.nan)
        emin = np.fmin.reduceat(ee[:-1], starts)
        emax = np.fmax.reduceat(ee[:-1], starts)
        nmin = np.fmin.reduceat(nn[:-1], starts)
        nmax = np.fmax.reduceat(nn[:-1], starts)
        ends = np.minimum(starts + chunk, m - 1)
        self.emin = np.fmin(emin, ee[ends])
        self.emax = np.fmax(emax, ee[ends])
        self.nmin = np.fmin(nmin, nn[ends])
        self.nmax = np.fmax(nmax, nn[ends])
        self.bbox = (np.nanmin(self.emin), np.nanmax(self.emax), np.nanmin(self.nmin), np.nanmax(self.nmax))


def _intersect(pa0, pa1, pb0, pb1, last_a, last_b):
    """Segment-segment intersection, vectorised.

    Returns t (fraction along a), u (fraction along b), sin of the crossing angle, and a mask.
    Segments are half-open ([p0, p1)) except each line's last segment, so a crossing exactly at a
    shared vertex is counted once. Parallel and collinear segments never intersect here.
    """
    r = pa1 - pa0
    s = pb1 - pb0
    qp = pb0 - pa0
    den = r[:, 0] * s[:, 1] - r[:, 1] * s[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        tt = (qp[:, 0] * s[:, 1] - qp[:, 1] * s[:, 0]) / den
        uu = (qp[:, 0] * r[:, 1] - qp[:, 1] * r[:, 0]) / den
        sin = np.abs(den) / (np.hypot(r[:, 0], r[:, 1]) * np.hypot(s[:, 0], s[:, 1]))
    ok = (den != 0) & (tt >= 0) & (uu >= 0) & ((tt < 1) | (last_a & (tt <= 1))) & ((uu < 1) | (last_b & (uu <= 1)))
    return tt, uu, sin, ok


def find_crossovers(
    lines: list[dict],
    *,
    min_angle_deg: float = 10.0,
    min_time_separation_s: float = 60.0,
    chunk: int = 64,
) -> Crossovers:
    """Crossover points between every pair of different lines.

    The ground track of each line is the polyline through its (easting, northing) samples. Each
    segment pair of two different lines that intersects gives a crossover; the value on each line
    is interpolated linearly between the segment's end samples, as is the time.

    Parameters
    ----------
    lines : list of dict
        ``{"flight": str, "line": str, "easting_m": (m,), "northing_m": (m,),
        "value_mgal": (m,), "time_s": (m,)}``; (flight, line) must be unique. Samples with a
        non-finite position are gaps in the track.
    min_angle_deg : float
        Shallower crossings are dropped, deg: near-parallel tracks have an ill-defined
        intersection (repeated lines are compared by other means).
    min_time_separation_s : float
        Two lines of the same flight must be this far apart in time at the intersection, s;
        drops the trivial touch where one line ends and the next begins.
    chunk : int
        Segments per bounding box in the prefilter (speed only; the result does not depend on it).

    Returns
    -------
    Crossovers
        Rows ordered by line pair (input order) and then along line a.

    Raises
    ------
    DataError
        A line lacks a key, has arrays of unequal length, or (flight, line) repeats.
    """
    tracks = []
    keys = []
    seen = set()
    for i, ln in enumerate(lines):
        e, nn, v, t = _line_arrays(ln, i)
        key = (str(ln["flight"]), str(ln["line"]))
        if key in seen:
            raise DataError(f"crossovers: line {key[0]}/{key[1]} given twice")
        seen.add(key)
        keys.append(key)
        tracks.append(_Track(e, nn, v, t, int(chunk)))
    sin_min = math.sin(math.radians(min_angle_deg))
    rows = {c: [] for c in Crossovers.COLUMNS}
    # candidate pairs: overlapping bounding boxes, found vectorised (a Python loop over all
    # pairs costs ~2 us each: 4 s for 2,000 lines)
    live = [i for i, tr in enumerate(tracks) if tr.nchunk > 0]
    pairs = []
    if len(live) > 1:
        bb = np.array([tracks[i].bbox for i in live])
        li = np.array(live)
        for lo in range(0, len(live), 512):
            blk = bb[lo : lo + 512]
            ov = (
                (blk[:, None, 0] <= bb[None, :, 1])
                & (bb[None, :, 0] <= blk[:, None, 1])
                & (blk[:, None, 2] <= bb[None, :, 3])
                & (bb[None, :, 2] <= blk[:, None, 3])
            )
            a_, b_ = np.nonzero(ov)
            keep = li[b_] > li[lo + a_]
            pairs += list(zip(li[lo + a_][keep].tolist(), li[b_][keep].tolist()))
        pairs.sort()
    for ia, ib in pairs:
        A = tracks[ia]
        B = tracks[ib]
        ov = (
            (A.emin[:, None] <= B.emax[None, :])
            & (B.emin[None, :] <= A.emax[:, None])
            & (A.nmin[:, None] <= B.nmax[None, :])
            & (B.nmin[None, :] <= A.nmax[:, None])
        )
        ca, cb = np.nonzero(ov)
        if ca.size == 0:
            continue
        k = np.arange(A.chunk)
        sa = (ca[:, None, None] * A.chunk + k[None, :, None]) + 0 * k[None, None, :]
        sb = (cb[:, None, None] * B.chunk + k[None, None, :]) + 0 * k[None, :, None]
        sa = sa.ravel()
        sb = sb.ravel()
        keep = (sa < A.nseg) & (sb < B.nseg)
        sa, sb = sa[keep], sb[keep]
        keep = A.seg_ok[sa] & B.seg_ok[sb]
        sa, sb = sa[keep], sb[keep]
        if sa.size == 0:
            continue
        pa0 = np.column_stack([A.e[sa], A.n[sa]])
        pa1 = np.column_stack([A.e[sa + 1], A.n[sa + 1]])
        pb0 = np.column_stack([B.e[sb], B.n[sb]])
        pb1 = np.column_stack([B.e[sb + 1], B.n[sb + 1]])
        tt, uu, sin, ok = _intersect(pa0, pa1, pb0, pb1, sa == A.nseg - 1, sb == B.nseg - 1)
        ok &= sin >= sin_min - 1e-12
        if not ok.any():
            continue
        sa, sb, tt, uu, sin = sa[ok], sb[ok], tt[ok], uu[ok], sin[ok]
        ta = A.t[sa] + tt * (A.t[sa + 1] - A.t[sa])
        tb = B.t[sb] + uu * (B.t[sb + 1] - B.t[sb])
        if keys[ia][0] == keys[ib][0]:
            far = np.abs(ta - tb) >= min_time_separation_s
            sa, sb, tt, uu, sin, ta, tb = (x[far] for x in (sa, sb, tt, uu, sin, ta, tb))
            if sa.size == 0:
                continue
        order = np.lexsort((tt, sa))
        sa, sb, tt, uu, sin, ta, tb = (x[order] for x in (sa, sb, tt, uu, sin, ta, tb))
        va = A.v[sa] + tt * (A.v[sa + 1] - A.v[sa])
        vb = B.v[sb] + uu * (B.v[sb + 1] - B.v[sb])
        m = sa.size
        rows["flight_a"].append(np.full(m, keys[ia][0], dtype=object))
        rows["line_a"].append(np.full(m, keys[ia][1], dtype=object))
        rows["flight_b"].append(np.full(m, keys[ib][0], dtype=object))
        rows["line_b"].append(np.full(m, keys[ib][1], dtype=object))
        rows["easting_m"].append(A.e[sa] + tt * (A.e[sa + 1] - A.e[sa]))
        rows["northing_m"].append(A.n[sa] + tt * (A.n[sa + 1] - A.n[sa]))
        rows["time_a_s"].append(ta)
        rows["time_b_s"].append(tb)
        rows["value_a_mgal"].append(va)
        rows["value_b_mgal"].append(vb)
        rows["diff_mgal"].append(va - vb)
        rows["angle_deg"].append(np.degrees(np.arcsin(np.clip(sin, 0.0, 1.0))))
    cols = {}
    for c, parts in rows.items():
        obj = c in ("flight_a", "line_a", "flight_b", "line_b")
        cols[c] = np.concatenate(parts) if parts else np.zeros(0, dtype=object if obj else float)
    x = Crossovers(**cols)
    x.per_line = _per_line_stats(x, keys)
    return x


def _per_line_stats(x: Crossovers, keys) -> list[dict]:
    """Per-line count, mean, RMS of (this line - other line); one pass over the crossovers."""
    pos = {k: i for i, k in enumerate(keys)}
    ia = np.array([pos[(f, ln)] for f, ln in zip(x.flight_a.astype(str), x.line_a.astype(str))], dtype=np.int64)
    ib = np.array([pos[(f, ln)] for f, ln in zip(x.flight_b.astype(str), x.line_b.astype(str))], dtype=np.int64)
    good = x.valid
    d = x.diff_mgal[good]
    ia, ib = ia[good], ib[good]
    nl = len(keys)
    cnt = np.bincount(ia, minlength=nl) + np.bincount(ib, minlength=nl)
    s1 = np.bincount(ia, d, minlength=nl) - np.bincount(ib, d, minlength=nl)
    s2 = np.bincount(ia, d**2, minlength=nl) + np.bincount(ib, d**2, minlength=nl)
    out = []
    for i, (f, ln) in enumerate(keys):
        c = int(cnt[i])
        rms = math.sqrt(s2[i] / c) if c else float("nan")
        out.append(
            {
                "flight": f,
                "line": ln,
                "count": c,
                "mean_mgal": float(s1[i] / c) if c else float("nan"),
                "rms_mgal": rms,
                "rms_over_sqrt2_mgal": rms / math.sqrt(2.0),
            }
        )
    return out
