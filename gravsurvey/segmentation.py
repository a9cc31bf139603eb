"""Line segmentation of a flight: survey lines, tie lines, transits, turns, static periods.

:func:`segment_lines` splits a flight into survey lines (``L01, L02, ...``), tie lines
(``T01, ...``: straight legs across the main direction), transits (``transit01, ...``: straight
legs at other headings), turns (``turn01, ...``: everything moving that is not a straight leg,
including climbs, straights shorter than ``min_line_m`` and curved legs) and static periods
(``static01, ...``: ground speed below ``min_speed_mps``: parked or taxiing). The segments cover
the flight without gaps, in time order. :func:`segments_from_windows` takes explicit time windows
from the configuration instead; :func:`segment_flight` applies the ``lines:`` section
(:class:`SegmentationOptions`, built by :func:`gravsurvey.settings.segmentation_options`).

Units: SI inside (s, m, rad); headings and angles at the edges in degrees (named ``_deg``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np
from scipy.ndimage import uniform_filter1d

from gravsurvey.crossovers import intersect_segments
from gravsurvey.errors import ConfigError, DataError
from gravsurvey.geodesy import radii_of_curvature, wrap_deg

__all__ = [
    "Segment",
    "SegmentationOptions",
    "SEGMENTATION_MODES",
    "segment_lines",
    "segments_from_windows",
    "segment_flight",
    "segment_table",
    "along_line_legs",
    "flights_across_lines",
]

KINDS = ("line", "tie", "turn", "static", "transit")

#: A straight off the lines' direction by more than half the heading tolerance and shorter than
#: this fraction of the median aligned line is a connecting leg of a turn (kind ``"transit"``);
#: so is a straight on the ties' direction shorter than that which crosses no line.
CONNECTING_LEG_FRACTION = 0.25

#: Transits within this of the lines' direction count with the lines in the drift stage
#: (:func:`along_line_legs`), deg: the default ``transit_angle_deg``.
ALONG_LINE_DEG = 20.0

#: Window of the vertical speed that ``max_climb_mps`` bounds, s: long against turbulence (a
#: 10-m heave over 200 s averages to 0.3 m/s), short against a climb to a survey's altitude.
CLIMB_WINDOW_S = 60.0

#: ``lines.mode`` values: detection, explicit windows, the whole flight as one line
SEGMENTATION_MODES = ("auto", "windows", "whole")


# --------------------------------------------------------------------------------------------
# Segmentation
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Segment:
    """One piece of a flight.

    Attributes
    ----------
    name : str
        ``L01, L02, ...`` for lines, ``T01, ...`` for tie lines, ``turn01, ...``, ``static01, ...``,
        ``transit01, ...`` (numbered in time order within each kind); the configured name for
        time windows.
    kind : str
        ``"line"``, ``"tie"``, ``"transit"``, ``"turn"`` or ``"static"``.
    start_index, stop_index : int
        Sample range ``[start_index, stop_index)`` (Python slice convention) into the arrays the
        segmentation was computed on.
    heading_deg : float
        Mean track heading (clockwise from north, [0, 360)) for lines, tie lines and transits,
        NaN otherwise.
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


def _circmean_deg(h_deg: np.ndarray) -> float:
    r = np.radians(h_deg)
    return float(np.degrees(np.arctan2(np.mean(np.sin(r)), np.mean(np.cos(r)))) % 360.0)


def _axial_mean_deg(h_deg, weights) -> float:
    """Weighted mean of axial headings (a line and its reverse alike), deg in [0, 180)."""
    d2 = np.radians(2.0 * np.asarray(h_deg, float))
    w = np.asarray(weights, float)
    return float(np.degrees(np.arctan2(np.sum(w * np.sin(d2)), np.sum(w * np.cos(d2)))) / 2.0) % 180.0


def _axial_diff_deg(a_deg, b_deg):
    """Axial distance |a - b| modulo 180 deg, in [0, 90]: ``|wrap(2 (a - b))| / 2``."""
    return np.abs(wrap_deg(2.0 * (np.asarray(a_deg, float) - b_deg))) / 2.0


def _piece_ends_en(lat_rad, lon_rad, pieces):
    """First and last finite position of each piece ``[a, b)``, east and north (m) on the
    flight's local plane (:func:`gravsurvey.drift.local_plane`): two arrays of shape (k, 2),
    NaN rows for a piece with fewer than two finite positions."""
    from gravsurvey.drift import local_plane

    idx = np.zeros((len(pieces), 2), dtype=int)
    have = np.zeros(len(pieces), dtype=bool)
    for k, (a, b) in enumerate(pieces):
        ok = np.flatnonzero(np.isfinite(lat_rad[a:b]) & np.isfinite(lon_rad[a:b]))
        if ok.size >= 2:
            idx[k], have[k] = (a + ok[0], a + ok[-1]), True
    east, north = local_plane(np.where(have[:, None], lat_rad[idx], np.nan), lon_rad[idx])
    return np.column_stack([east[:, 0], north[:, 0]]), np.column_stack([east[:, 1], north[:, 1]])


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
    max_climb_mps: float | None = 2.0,
    speed_tol_mps: float = 10.0,
    smooth_s: float = 10.0,
    merge_gap_s: float = 20.0,
    tie_angle_deg: float = 45.0,
    min_line_m: float = 2000.0,
    transit_angle_deg: float | None = 20.0,
    line_heading_deg: float | None = None,
    options: "SegmentationOptions | None" = None,
) -> list[Segment]:
    """Split a flight into straight lines, tie lines, turns and static periods.

    The track heading and ground speed come from the horizontal velocity, smoothed with a
    centred moving average over ``smooth_s`` (turbulence: heading wander of a few degrees, speed
    wobble). A sample is a *straight candidate* when the aircraft moves (smoothed ground speed
    >= ``min_speed_mps``), flies level (smoothed |vertical speed| <= ``max_vertical_speed_mps``,
    and over :data:`CLIMB_WINDOW_S` <= ``max_climb_mps``: a slow steady climb is no line either)
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

    The dominant direction is the axial heading (modulo 180 deg) carrying the most line length
    (``line_heading_deg``, the survey plan's, in its place when given).
    Straight pieces within ``transit_angle_deg`` of it are lines, those within
    ``transit_angle_deg`` of its perpendicular are tie (control) lines, and the straight pieces
    in between are transits (kind ``"transit"``, named ``transit01, ...``: processed, but not
    lines, like turns). Against the flight's own dominant direction, so is a straight within
    ``transit_angle_deg`` of it but more than ``heading_tol_deg / 2`` off and shorter than
    :data:`CONNECTING_LEG_FRACTION` of the median straight that is on it: the offset leg of a
    procedure or teardrop turn, a few km flown 10-15 deg off the line before turning back.
    And so is a straight across it shorter than that which crosses none of the straights on it
    (end points joined, on a local plane): the connecting leg of a racetrack turn, flown
    between the ends of neighbouring lines, which ties nothing.
    With ``transit_angle_deg`` None, pieces more than ``tie_angle_deg`` from the dominant
    direction are tie lines and nothing is a transit.

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
    max_climb_mps : float or None
        Nor are climbs and descents whose vertical speed averaged over :data:`CLIMB_WINDOW_S`
        exceeds this, m/s (a cruise climb at 2-4 m/s on course to the survey area: straight, at
        survey speed, and at heights the lines are not flown at); None disables the test.
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
    line_heading_deg : float or None
        The survey's line direction (the flight plan's), deg clockwise from north, either way
        along the line (axial: 10 and 190 are one direction); it takes the dominant direction's
        place in naming lines and tie lines, so a flight that flew only tie lines names them
        ``T01...``. None: each flight's dominant direction. The legs of turns are told against
        the flight's own dominant direction either way.
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
        max_climb_mps = kw["max_climb_mps"]
        smooth_s, merge_gap_s, tie_angle_deg = kw["smooth_s"], kw["merge_gap_s"], kw["tie_angle_deg"]
        speed_tol_mps = kw["speed_tol_mps"]
        min_line_m, transit_angle_deg = kw["min_line_m"], kw["transit_angle_deg"]
        line_heading_deg = kw["line_heading_deg"]
    t, lat, lon, v = _check_track(time_s, lat_rad, lon_rad, vel_enu)
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
    if max_climb_mps is not None:
        wc = max(1, int(round(CLIMB_WINDOW_S / dt)))
        wc_sum = np.maximum(uniform_filter1d(finite.astype(float), wc, mode="nearest"), 1e-12)
        level &= np.abs(uniform_filter1d(vv[:, 2], wc, mode="nearest") / wc_sum) <= max_climb_mps
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
        ok = (np.abs(wrap_deg(heading[a:b] - h0)) <= heading_tol_deg) & (np.abs(speed_s[a:b] - v0) <= speed_tol_mps)
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
        dev = np.abs(wrap_deg(heading - h0))
        dv = np.abs(speed_s - v0)
        ok = usable & (dev <= heading_tol_deg) & (dv <= speed_tol_mps)  # usable excludes non-finite rows
        while a > 0 and ok[a - 1]:
            a -= 1
        while b < n and ok[b]:
            b += 1
        mad_h = 1.4826 * np.median(np.abs(wrap_deg(heading[a:b] - _circmean_deg(heading[a:b]))))
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
    # each merged piece keeps the grown pieces it was made of (below)
    merged: list[list] = []
    for a, b in grown:
        if merged and a <= merged[-1][1]:
            pa, pb = merged[-1][:2]
            if _same_heading(heading, pa, pb, a, b, heading_tol_deg):
                merged[-1][1] = max(pb, b)
                merged[-1][2].append((a, b))
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
            merged[-1][2].append((a, b))
            continue
        merged.append([a, b, [(a, b)]])
    # along-track length of each piece from the raw ground speed (trapezoid rule)
    gs = np.hypot(vv[:, 0], vv[:, 1])
    cum = np.concatenate(([0.0], np.cumsum(0.5 * (gs[1:] + gs[:-1]) * np.diff(t))))

    def is_straight(a, b):
        return (
            cum[b - 1] - cum[a] >= min_line_m
            and (min_line_s is None or t[b - 1] - t[a] >= min_line_s)
            and _heading_drift_deg(t[a:b], heading_u[a:b]) <= 0.5 * heading_tol_deg
        )

    straight = []
    for a, b, parts in merged:
        if is_straight(a, b):
            straight.append((a, b))
            continue
        # a piece grown out of the slow start of a turn (a wide turn, a climbing one: under the
        # turn-rate limit) overlaps the line before it and merges with it, and the whole then
        # curves: the line is its longest straight part, not lost with the curve
        ok = [(pa, pb) for pa, pb in parts if is_straight(pa, pb)]
        if ok:
            straight.append(max(ok, key=lambda ab: ab[1] - ab[0]))

    # Dominant axial direction by line time: histogram of doubled angles, 5-deg bins.
    kinds = {}
    if straight:
        ax = np.array([_circmean_deg(heading[a:b]) % 180.0 for a, b in straight])
        dur = np.array([cum[b - 1] - cum[a] for a, b in straight])  # weights: line length
        bins = np.arange(0.0, 180.0, 5.0)
        axial = _axial_diff_deg(ax[None, :], bins[:, None])
        score = (dur[None, :] * (axial <= tie_angle_deg / 2.0)).sum(axis=1)
        near = axial[int(np.argmax(score))] <= tie_angle_deg / 2.0
        own = _axial_diff_deg(ax, _axial_mean_deg(ax[near], dur[near]))
        # the lines' direction: the survey plan's where given (a flight that flew the tie lines
        # has them as its own dominant direction), else the flight's own
        diffs = own if line_heading_deg is None else _axial_diff_deg(ax, float(line_heading_deg) % 180.0)
        for (a, b), diff in zip(straight, diffs):
            if transit_angle_deg is None:
                kinds[(a, b)] = "tie" if diff > tie_angle_deg else "line"
            elif diff <= transit_angle_deg:
                kinds[(a, b)] = "line"
            elif diff >= 90.0 - transit_angle_deg:
                kinds[(a, b)] = "tie"
            else:
                kinds[(a, b)] = "transit"
        if transit_angle_deg is not None:
            # the legs of the flight's turns, against the flight's own direction (its lines, or
            # the tie lines a tie flight flew)
            along, across = own <= transit_angle_deg, own >= 90.0 - transit_angle_deg
            straight_kind = np.array([kinds[ab] in ("line", "tie") for ab in straight])
            # a turn flown as an offset leg and a turn back (a procedure or teardrop turn) holds
            # a straight of a few km some 10-15 deg off the lines: a connecting leg, not a survey
            # line (the unseen suite's turns made 7 flown lines into 13)
            on_lines = own <= 0.5 * heading_tol_deg
            if on_lines.any():
                short = dur < CONNECTING_LEG_FRACTION * float(np.median(dur[on_lines]))
                for k, ab in enumerate(straight):
                    if short[k] and along[k] and not on_lines[k] and straight_kind[k]:
                        kinds[ab] = "transit"
                # a turn flown as two 90-deg turns holds a straight of a few km across the lines
                # between the ends of neighbouring lines: a connecting leg, not a tie line, when
                # short and crossing no line (a tie line crosses the lines it ties)
                legs = short & across & straight_kind
                if legs.any():
                    p0, p1 = _piece_ends_en(lat, lon, straight)
                    on = along & np.array([kinds[ab] != "transit" for ab in straight])
                    for k in np.flatnonzero(legs):
                        crossed = intersect_segments(p0[[k]], p1[[k]], p0[on], p1[on], True, True)[3]
                        if not crossed.any():
                            kinds[straight[k]] = "transit"

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


def along_line_legs(segs, max_angle_deg: float = ALONG_LINE_DEG) -> list:
    """The survey lines and the transits within ``max_angle_deg`` of the lines' axial direction
    (a flight without lines: its tie lines and the transits near them).

    Those transits are the offset legs of procedure turns (:data:`CONNECTING_LEG_FRACTION`):
    not survey lines, but straight, steady flight near the lines' heading between them, whose
    data the drift stage uses like a line's (a leg crossing the lines is left out there: the
    smoother's along-track low-pass of a short field differs between crossing directions).

    Parameters
    ----------
    segs : list of Segment
    max_angle_deg : float
        Largest axial heading difference of a transit from the lines' mean direction, deg.

    Returns
    -------
    list of Segment
        In the order of ``segs``.
    """
    # a flight that flew only the tie lines (lines.line_heading_deg given) has them as its
    # parallel legs
    kind = "line" if any(s.kind == "line" for s in segs) else "tie"
    lines = [s for s in segs if s.kind == kind and np.isfinite(s.heading_deg)]
    if not lines:
        return [s for s in segs if s.kind == kind]
    dom = _axial_mean_deg([s.heading_deg for s in lines], [s.stop_index - s.start_index for s in lines])
    return [
        s
        for s in segs
        if s.kind == kind
        or (s.kind == "transit" and np.isfinite(s.heading_deg) and _axial_diff_deg(s.heading_deg, dom) <= max_angle_deg)
    ]


def flights_across_lines(lines, max_angle_deg: float = 45.0) -> list[str]:
    """Notes for flights whose lines run across the survey's lines (a flight that flew the ties).

    Each flight names its lines by its own dominant direction (:func:`segment_lines`), so a
    flight that flew only the tie lines of a survey names them lines. The survey's direction is
    that of the flights that flew tie lines too (their lines are lines by their own evidence),
    or of all flights when none did: the axial direction carrying the most line length within
    ``max_angle_deg``. A flight whose lines run more than ``max_angle_deg`` from it is named.

    Parameters
    ----------
    lines : iterable of (flight, kind, heading_deg, length_m)
        Every line and tie line of the survey: its flight's name, ``"line"`` or ``"tie"``, its
        axial heading (deg from north; NaN: unknown, left out) and its length (m).
    max_angle_deg : float
        Largest axial difference of a flight's lines from the survey's direction, deg.

    Returns
    -------
    list of str
        One note per flight across, naming ``lines.line_heading_deg``.
    """
    per, with_ties = {}, set()
    for flight, kind, heading, length in lines:
        if kind == "tie":
            with_ties.add(flight)
        elif kind == "line" and np.isfinite(heading) and length > 0:
            per.setdefault(flight, []).append((float(heading), float(length)))
    if len(per) < 2:
        return []
    own = {f: (_axial_mean_deg(*zip(*v)), sum(w for _, w in v)) for f, v in per.items()}
    ref_flights = [f for f in own if f in with_ties] or list(own)
    heads = np.array([own[f][0] for f in ref_flights])
    weights = np.array([own[f][1] for f in ref_flights])
    near = _axial_diff_deg(heads[None, :], heads[:, None]) <= max_angle_deg
    best = near[int(np.argmax((near * weights[None, :]).sum(axis=1)))]
    ref = _axial_mean_deg(heads[best], weights[best])
    by = ", ".join(f for f, b in zip(ref_flights, best) if b)
    notes = []
    for f, (h, _) in own.items():
        diff = float(_axial_diff_deg(h, ref))
        if diff > max_angle_deg:
            notes.append(
                f"lines: {f}'s lines run {diff:.0f} deg across the survey's ({ref:.0f} deg, the lines of {by}): "
                "a flight that flew the tie lines? lines.line_heading_deg (the plan's line direction) names "
                "its legs T01..."
            )
    return notes


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
    return abs(wrap_deg(_circmean_deg(heading[a0:b0]) - _circmean_deg(heading[a1:b1]))) <= 0.5 * tol


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
    from gravsurvey.settings import time_windows

    t = np.asarray(time_s, dtype=float)
    out = []
    for i, wdw in enumerate(time_windows(windows, key_path)):
        kp = f"{key_path}[{i}]"
        name, t0, t1 = wdw.name, wdw.start_s, wdw.stop_s
        kind = wdw.kind
        if kind is None:
            kind = "tie" if len(name) > 1 and name[0] == "T" and name[1].isdigit() else "line"
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
    """The ``lines:`` configuration section (validated by :func:`gravsurvey.settings.segmentation_options`).

    Attributes
    ----------
    mode : str
        ``auto`` (straight-line detection, :func:`segment_lines`), ``windows`` (explicit time
        windows, :func:`segments_from_windows`) or ``whole`` (the whole flight is line ``L01``).
    min_line_s, heading_tol_deg, min_speed_mps, max_turn_rate_degps, max_vertical_speed_mps,
    max_climb_mps, speed_tol_mps, smooth_s, merge_gap_s, tie_angle_deg, min_line_m,
    transit_angle_deg, line_heading_deg
        See :func:`segment_lines` (units in the names; ``max_vertical_speed_mps``,
        ``max_climb_mps``, ``min_line_s``, ``transit_angle_deg`` and ``line_heading_deg`` may be
        null).
    windows : list of dict
        For ``mode: windows``: ``{name, start_s, stop_s[, kind]}``, s after the flight's first sample.
    """

    mode: str = "auto"
    min_line_s: float | None = None
    heading_tol_deg: float = 10.0
    min_speed_mps: float = 20.0
    max_turn_rate_degps: float = 1.0
    max_vertical_speed_mps: float | None = 4.0
    max_climb_mps: float | None = 2.0
    speed_tol_mps: float = 10.0
    smooth_s: float = 10.0
    merge_gap_s: float = 20.0
    tie_angle_deg: float = 45.0
    windows: list = field(default_factory=list)
    min_line_m: float = 2000.0
    transit_angle_deg: float | None = 20.0
    line_heading_deg: float | None = None

    @classmethod
    def keys(cls) -> tuple[str, ...]:
        """Valid configuration keys (the attributes)."""
        return tuple(f.name for f in fields(cls))

    def detection_kwargs(self) -> dict:
        """Keyword arguments for :func:`segment_lines`."""
        return {k: getattr(self, k) for k in self.keys() if k not in ("mode", "windows")}


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
