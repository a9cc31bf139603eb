"""Crossovers between survey lines and their statistics.

:func:`find_crossovers` intersects the ground tracks (projected easting/northing polylines) of
every pair of different lines, within a flight and across flights, interpolates each line's value
linearly at the intersection and returns the differences with their statistics (the standard
internal-consistency check of an airborne gravity survey: if both lines carry independent errors
of equal size, ``rms / sqrt(2)`` estimates the error of one line).

Units: projected metres; the values compared at crossovers are in mGal (named so).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from gravsurvey.errors import DataError

__all__ = ["Crossovers", "find_crossovers", "intersect_segments", "with_continuation"]


@dataclass
class Crossovers:
    """Crossover points between lines and their statistics.

    Row ``k`` is one intersection of line ``a`` (earlier in the input list) with line ``b``.
    ``diff_mgal = value_a_mgal - value_b_mgal - continuation_mgal``: the level error the
    crossover shows, the field's own change between the two lines' heights taken off
    (:func:`with_continuation`; 0 until then). Rows whose value is NaN on either line are kept
    but left out of all statistics.

    Attributes
    ----------
    flight_a, line_a, flight_b, line_b : ndarray of str, shape (k,)
    easting_m, northing_m : ndarray, shape (k,)
        Intersection point, m (the projected coordinates the lines came in).
    time_a_s, time_b_s : ndarray, shape (k,)
        Time on each line at the intersection (interpolated), s.
    height_a_m, height_b_m : ndarray, shape (k,)
        Height of each line at the intersection (interpolated), m; NaN where the lines came
        without heights.
    value_a_mgal, value_b_mgal, continuation_mgal, diff_mgal : ndarray, shape (k,)
        ``continuation_mgal``: the field at ``height_a_m`` less the field at ``height_b_m``.
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
    height_a_m: np.ndarray
    height_b_m: np.ndarray
    value_a_mgal: np.ndarray
    value_b_mgal: np.ndarray
    continuation_mgal: np.ndarray
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
        "height_a_m",
        "height_b_m",
        "value_a_mgal",
        "value_b_mgal",
        "continuation_mgal",
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
    h = np.asarray(ln["height_m"], dtype=float) if ln.get("height_m") is not None else np.full(e.shape, np.nan)
    if not (e.ndim == 1 and e.shape == nn.shape == v.shape == t.shape == h.shape):
        raise DataError(
            f"crossovers: line {ln['flight']}/{ln['line']}: easting_m, northing_m, value_mgal, time_s "
            f"(and height_m) must be 1-D of equal length, got {e.shape}, {nn.shape}, {v.shape}, {t.shape}, {h.shape}"
        )
    return e, nn, v, t, h


class _Track:
    """A line's polyline with per-chunk bounding boxes (the prefilter)."""

    def __init__(self, e, n, v, t, h, chunk):
        self.e, self.n, self.v, self.t, self.h = e, n, v, t, h
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


def intersect_segments(pa0, pa1, pb0, pb1, last_a, last_b):
    """Segment-segment intersection, vectorised (points as rows ``(k, 2)``, broadcast).

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
        "value_mgal": (m,), "time_s": (m,)}`` and optionally ``"height_m": (m,)`` (the heights
        at the crossovers, for :func:`with_continuation`); (flight, line) must be unique.
        Samples with a non-finite position are gaps in the track.
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
        e, nn, v, t, h = _line_arrays(ln, i)
        key = (str(ln["flight"]), str(ln["line"]))
        if key in seen:
            raise DataError(f"crossovers: line {key[0]}/{key[1]} given twice")
        seen.add(key)
        keys.append(key)
        tracks.append(_Track(e, nn, v, t, h, int(chunk)))
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
        tt, uu, sin, ok = intersect_segments(pa0, pa1, pb0, pb1, sa == A.nseg - 1, sb == B.nseg - 1)
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
        rows["height_a_m"].append(A.h[sa] + tt * (A.h[sa + 1] - A.h[sa]))
        rows["height_b_m"].append(B.h[sb] + uu * (B.h[sb + 1] - B.h[sb]))
        rows["value_a_mgal"].append(va)
        rows["value_b_mgal"].append(vb)
        rows["continuation_mgal"].append(np.zeros(m))
        rows["diff_mgal"].append(va - vb)
        rows["angle_deg"].append(np.degrees(np.arcsin(np.clip(sin, 0.0, 1.0))))
    cols = {}
    for c, parts in rows.items():
        obj = c in ("flight_a", "line_a", "flight_b", "line_b")
        cols[c] = np.concatenate(parts) if parts else np.zeros(0, dtype=object if obj else float)
    x = Crossovers(**cols)
    x.per_line = _per_line_stats(x, keys)
    return x


def with_continuation(crossovers: Crossovers, continuation_mgal) -> Crossovers:
    """The crossovers with the field's change between the two lines' heights taken off.

    Parameters
    ----------
    crossovers : Crossovers
    continuation_mgal : array_like, shape (k,)
        Field at ``height_a_m`` less field at ``height_b_m`` at each crossover, mGal
        (:func:`gravsurvey.grid.continuation_difference`); NaN is taken as 0.

    Returns
    -------
    Crossovers
        A copy: ``continuation_mgal`` as given, ``diff_mgal = value_a_mgal - value_b_mgal -
        continuation_mgal``, the per-line statistics of those differences.
    """
    c = np.nan_to_num(np.asarray(continuation_mgal, float), nan=0.0)
    if c.shape != crossovers.diff_mgal.shape:
        raise DataError(f"crossovers: {c.size} continuation values for {len(crossovers)} crossovers")
    cols = {k: getattr(crossovers, k) for k in Crossovers.COLUMNS}
    cols["continuation_mgal"] = c
    cols["diff_mgal"] = crossovers.value_a_mgal - crossovers.value_b_mgal - c
    x = Crossovers(**cols)
    x.per_line = _per_line_stats(x, [(p["flight"], p["line"]) for p in crossovers.per_line])
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
