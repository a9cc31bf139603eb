"""One per-flight result type, whatever chain made it: :class:`FlightEstimate`.

The 3D-INM chain (:func:`gravsurvey.inm.solve.estimate_anomaly`, an ``InmSolution``) and the
classic chain (:func:`gravsurvey.classic.classic_reduction`, a ``ClassicResult``) are turned
into a :class:`FlightEstimate` by :func:`from_inm_solution` and :func:`from_classic`; a flight
estimated in pieces (split at long gaps) becomes one by :func:`concatenate_estimates`.
Everything downstream (line segmentation, post-processing, ties, crossovers, levelling, grid,
writers, plots, the cache) reads only this type.

SI units throughout (m, s, rad, m/s^2); mGal and degrees appear only in the writers.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from .geodesy import WGS84, Ellipsoid, normal_gravity
from .inm.params import RADPS_PER_DEGPH
from .utc import utc_after

#: arcseconds per radian (deflections of the vertical are written in arcsec)
ARCSEC_PER_RAD = 180.0 * 3600.0 / np.pi

#: ``method`` of an estimate made by the 3D-INM Kalman filter and RTS smoother
METHOD_INM = "inm"
#: ``method`` of an estimate made by the conventional scalar reduction (no Kalman filter)
METHOD_CLASSIC = "classic"


@dataclass
class FlightEstimate:
    """Everything known about one processed flight, per epoch and as facts.

    Built by :func:`from_inm_solution`, :func:`from_classic` or :func:`concatenate_estimates`;
    the pipeline then fills the line fields (``line``, ``line_segments``, ``line_info``) and
    replaces ``disturbance`` by the post-processed product on lines (NaN elsewhere).
    Picklable and cacheable (:mod:`gravsurvey.cache`: arrays and JSON fields only).

    Attributes
    ----------
    name : str
        Flight name.
    method : str
        ``"inm"`` (3D-INM Kalman/RTS) or ``"classic"`` (scalar reduction).
    t0_unix_ns : int
        Unix time of ``time == 0``, ns.
    time : ndarray, shape (N,)
        Epochs, s after ``t0_unix_ns``.
    lat, lon : ndarray, shape (N,)
        Geodetic latitude and longitude, rad.
    height : ndarray, shape (N,)
        Ellipsoidal height, m.
    vel_n : ndarray, shape (N, 3)
        Earth-relative velocity, ENU, m/s.
    speed : ndarray, shape (N,)
        Ground speed, m/s.
    heading : ndarray, shape (N,)
        Track over ground, rad clockwise from north in [0, 2 pi).
    disturbance : ndarray, shape (N,)
        The product: vertical gravity disturbance, m/s^2, positive = stronger gravity. Out of
        a chain: the chain's product at every epoch (the smoothed estimate for ``inm``, the
        low-passed reduction for ``classic``); after the pipeline's line stage: the
        post-processed product on lines, NaN elsewhere.
    sigma : ndarray, shape (N,)
        1-sigma of the estimate the product is made from, m/s^2 (the smoother's for ``inm``;
        NaN for ``classic``, which has no error model).
    resolution_m : float
        Half-wavelength resolution of the chain's product, m (NaN when unknown).
    segment : ndarray of int, shape (N,)
        Piece of the flight each epoch was estimated in (0, 1, ...); -1 for gap epochs (the
        separators between pieces, or epochs the chain left empty).
    smoothed : ndarray, shape (N,) or None
        RTS-smoothed estimate, m/s^2 (``inm``; None for a chain without a smoother).
    drift : ndarray, shape (N,) or None
        Gravimeter drift told from the field by the lines (:func:`gravsurvey.drift.separate_drift`),
        m/s^2, taken off ``smoothed`` before post-processing; None when not estimated or not used.
    field_filter : ndarray, shape (N,) or None
        What the field filter took off the estimate less the drift on each line
        (:func:`gravsurvey.drift.field_filter`), m/s^2; None when not applied.
    drift_sigma_passed : float
        The datasheet drift ``sigma`` holds in quadrature because the smoother passes it
        (``identification.drift_sigma_passed_mps2``; the largest of a flight's pieces), m/s^2;
        the drift stage trades it for its posterior (:func:`gravsurvey.pipeline.estimate_drift`).
    forward, forward_sigma : ndarray, shape (N,) or None
        Forward Kalman filter estimate and its 1-sigma, m/s^2 (``inm`` only).
    unfiltered : ndarray, shape (N,) or None
        The classic reduction before its low-pass, m/s^2 (very noisy: +-1e6 mGal is usual);
        None for ``inm``.
    attitude, attitude_sigma : ndarray, shape (N, 3)
        Roll, pitch, heading of a strapdown triad and their 1-sigma, rad; NaN where not
        estimated (platform triad, classic chain).
    dg_north, dg_east : ndarray, shape (N,) or None
        Horizontal gravity-disturbance components, m/s^2 (None when not estimated).
    sigma_north, sigma_east : ndarray, shape (N,) or None
        Their 1-sigma, m/s^2.
    horizontal_observable : ndarray of bool, shape (N,) or None
        Epochs where the horizontal components are observable (meaningful).
    line : ndarray of object, shape (N,)
        Line name of each epoch ('' outside lines); filled by the pipeline.
    line_segments : list of dict
        Line segmentation: ``name, kind, start_s, stop_s, n`` (summary.json ``segments``).
    line_info : dict
        Line name -> post-processor and line facts (summary.json ``lines``).
    product_info : dict
        Facts of a chain's own finished product (classic: filter, length, resolution), reported
        per line when the chain has no smoothed estimate to post-process.
    truth_mgal : ndarray, shape (N,) or None
        Truth disturbance at the epochs, mGal (a user's truth file), or None.
    notes : list of str
        Warnings and findings, each prefixed with the flight name.
    data_loss : list of str
        Input damage the flight was processed despite (exit code 1).
    timings : dict
        Stage -> seconds.
    input_hashes : dict
        Input path -> SHA-256.
    estimator : dict
        Identification, alignment, attitude and check facts for summary.json ``estimator``.
    """

    name: str
    method: str
    t0_unix_ns: int
    time: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    height: np.ndarray
    vel_n: np.ndarray
    speed: np.ndarray
    heading: np.ndarray
    disturbance: np.ndarray
    sigma: np.ndarray
    resolution_m: float = float("nan")
    segment: np.ndarray | None = None
    smoothed: np.ndarray | None = None
    drift: np.ndarray | None = None
    field_filter: np.ndarray | None = None
    drift_sigma_passed: float = 0.0
    forward: np.ndarray | None = None
    forward_sigma: np.ndarray | None = None
    unfiltered: np.ndarray | None = None
    attitude: np.ndarray | None = None
    attitude_sigma: np.ndarray | None = None
    dg_north: np.ndarray | None = None
    dg_east: np.ndarray | None = None
    sigma_north: np.ndarray | None = None
    sigma_east: np.ndarray | None = None
    horizontal_observable: np.ndarray | None = None
    line: np.ndarray | None = None
    line_segments: list = field(default_factory=list)
    line_info: dict = field(default_factory=dict)
    product_info: dict = field(default_factory=dict)
    truth_mgal: np.ndarray | None = None
    notes: list = field(default_factory=list)
    data_loss: list = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    input_hashes: dict = field(default_factory=dict)
    estimator: dict = field(default_factory=dict)

    def __post_init__(self):
        n = len(self.time)
        if self.segment is None:
            self.segment = np.zeros(n, dtype=np.int64)
        if self.line is None:
            self.line = np.full(n, "", dtype=object)
        for name in ("attitude", "attitude_sigma"):
            a = getattr(self, name)
            if a is None or np.shape(a) != (n, 3):
                setattr(self, name, np.full((n, 3), np.nan))

    @property
    def unprocessed(self) -> np.ndarray:
        """The per-epoch estimate before post-processing, m/s^2, shape (N,): ``smoothed``
        (``inm``), else ``unfiltered`` (``classic``), else ``disturbance``."""
        for a in (self.smoothed, self.unfiltered):
            if a is not None:
                return a
        return self.disturbance

    @property
    def has_attitude(self) -> bool:
        """Whether any epoch has an estimated attitude."""
        return bool(np.isfinite(self.attitude).any())

    @property
    def has_horizontal(self) -> bool:
        """Whether the horizontal disturbance components were estimated."""
        return self.dg_north is not None and self.dg_east is not None


def _opt(a, n: int, name: str, dtype=float):
    """``a`` as an (n,) array, or None when absent."""
    if a is None:
        return None
    a = np.asarray(a, dtype=dtype)
    if a.shape != (n,):
        raise ValueError(f"{name}: expected shape ({n},), got {a.shape}")
    return a


def horizontal_fields(sol, n: int) -> dict:
    """FlightEstimate's horizontal fields from a solution's ``dg_horizontal`` (N, 2) [north, east]
    m/s^2, ``dg_horizontal_sigma`` (N, 2) and ``horizontal_observable`` (N,) bool.

    Returns
    -------
    dict
        ``dg_north, dg_east, sigma_north, sigma_east, horizontal_observable``; all None when the
        solution carries no horizontal components (``model.horizontal`` off).
    """
    dg = getattr(sol, "dg_horizontal", None)
    if dg is None:
        return {k: None for k in ("dg_north", "dg_east", "sigma_north", "sigma_east", "horizontal_observable")}
    dg = np.asarray(dg, float)
    if dg.shape != (n, 2):
        raise ValueError(f"dg_horizontal: expected shape ({n}, 2), got {dg.shape}")
    sig = getattr(sol, "dg_horizontal_sigma", None)
    sig = np.full((n, 2), np.nan) if sig is None else np.asarray(sig, float).reshape(n, 2)
    obs = getattr(sol, "horizontal_observable", None)
    obs = np.isfinite(dg).all(axis=1) if obs is None else np.asarray(obs, bool).reshape(n)
    return {
        "dg_north": dg[:, 0].copy(),
        "dg_east": dg[:, 1].copy(),
        "sigma_north": sig[:, 0].copy(),
        "sigma_east": sig[:, 1].copy(),
        "horizontal_observable": obs,
    }


def attitude_report(sol) -> dict:
    """Alignment and attitude-estimation facts of an ``InmSolution`` (summary.json ``estimator``).

    Alignment warnings are raised as Python warnings (the pipeline turns them into notes).
    """
    out = {}
    al = getattr(sol, "alignment", None)
    if al is not None:
        out.update(al.to_dict())
        for w in al.warnings:
            warnings.warn(f"alignment: {w}")
    att_sig = getattr(sol, "attitude_sigma", None)
    if att_sig is not None and np.isfinite(att_sig).any():
        med = np.degrees(np.nanmedian(att_sig, axis=0))
        out["attitude_sigma_median_deg"] = {"roll": float(med[0]), "pitch": float(med[1]), "heading": float(med[2])}
        out["attitude_converge_s"] = float(sol.attitude_converge_s)
        out["gnss_residual_rms_m"] = float(sol.gnss_residual_rms_m)
        out["gnss_residual_systematic_m"] = float(getattr(sol, "gnss_residual_systematic_m", np.nan))
    bias = getattr(sol, "gyro_bias_t", None)
    if bias is not None:
        # the passes re-linearise every GNSS-aided flight (attitude and gyro bias), platform too
        out["attitude_passes"] = int(sol.passes)
        out["attitude_corrections_deg"] = [float(np.degrees(c)) for c in sol.attitude_corrections]
        pv = getattr(sol, "initial_corrections", None) or []
        out["initial_position_corrections_m"] = [float(a) for a, _ in pv]
        out["initial_velocity_corrections_mps"] = [float(b) for _, b in pv]
        tilts = getattr(sol, "follow_tilts_rad", None) or []
        if tilts:
            # passes about a navigation that follows the smoothed attitude (a tactical IMU's tilt;
            # docs/method.md, "Following passes"): the tilt that started each
            out["following_passes_tilt_mrad"] = [float(a * 1e3) for a in tilts]
        rev = getattr(sol, "passes_reverted", None)
        if rev is not None:
            # the passes stopped where a gyro-bias correction kept growing; the estimate is the
            # pass where it began to
            out["passes_reverted"] = {
                "gyro_axis": "xyz"[rev["axis"]],
                "estimate_of_pass": rev["pass"] - 1,
                "bias_corrections_degph": list(rev["bias_corrections_degph"]),
            }
        out["gyro_bias_degph"] = [float(b / RADPS_PER_DEGPH) for b in bias]
        out["gyro_bias_sigma_degph"] = [float(b / RADPS_PER_DEGPH) for b in sol.gyro_bias_sigma_t]
    abias = getattr(sol, "accel_bias_t", None)
    if abias is not None:
        # accelerometers 1 and 2 (triad axes), estimated as states; taken off the specific force
        # between passes when the config gives a datasheet bias (model.accel_bias_mps2)
        out["accel_bias_mps2"] = [float(b) for b in abias]
        out["accel_bias_sigma_mps2"] = [float(b) for b in sol.accel_bias_sigma_t]
        out["accel_bias_taken_off"] = bool(getattr(sol, "accel_bias_taken_off", False))
    return out


def _honest_sigma(sol) -> np.ndarray:
    """The smoother's sigma and, in quadrature, the drift it cannot tell from the field, m/s^2.

    ``identification["drift_sigma_passed_mps2"]`` (:func:`gravsurvey.inm.identify.drift_sigma_passed`)
    is the gravimeter drift of a datasheet that the smoother's model does not hold and passes
    into the estimate (docs/method.md, "Honest sigma").
    """
    ident = getattr(sol, "identification", None) or {}
    sig = np.asarray(sol.sigma_smooth, float) * float(ident.get("smoother_sigma_scale", 1.0))
    extra = math.hypot(
        float(ident.get("drift_sigma_passed_mps2", 0.0)), float(ident.get("field_sigma_missed_mps2", 0.0))
    )
    return np.hypot(sig, extra) if extra > 0.0 else sig


def from_inm_solution(sol, *, name: str = "", t0_unix_ns: int = 0) -> FlightEstimate:
    """The :class:`FlightEstimate` of a 3D-INM solution (``InmSolution`` or an object with its fields).

    The product (``disturbance``) is the RTS-smoothed estimate; the horizontal components are
    taken when the solution has them (``dg_horizontal``, ``dg_horizontal_sigma``,
    ``horizontal_observable``). The identification's warnings (``identification["warnings"]``)
    become the estimate's ``notes``, prefixed with ``name``.

    Parameters
    ----------
    sol : gravsurvey.inm.solve.InmSolution
    name : str
        Flight name.
    t0_unix_ns : int
        Unix time of the solution's ``time == 0``, ns.
    """
    n = len(sol.time)
    g = np.asarray(sol.g_smooth, float)
    vel = np.asarray(sol.vel_n, float)
    heading = getattr(sol, "heading", None)
    if heading is None:
        heading = track_heading(vel)
    res = float(getattr(sol, "resolution_m", np.nan))
    gnss_aided = bool(getattr(sol, "gnss_aided", False))
    ident = getattr(sol, "identification", None) or {}
    # what may have degraded the estimate (model identification, a horizontal estimate not
    # made) reaches the user as the flight's notes; the solver's flight-wide solvability check
    # is left to the per-line one (gravsurvey.pipeline.line_products)
    notes = [f"{name}: {w}" if name else str(w) for w in dict.fromkeys(ident.get("warnings", []))]
    return FlightEstimate(
        name=name,
        method=METHOD_INM,
        t0_unix_ns=int(t0_unix_ns),
        time=np.asarray(sol.time, float),
        lat=np.asarray(sol.lat, float),
        lon=np.asarray(sol.lon, float),
        height=np.asarray(sol.height, float),
        vel_n=vel,
        speed=np.asarray(sol.speed, float),
        heading=np.asarray(heading, float),
        disturbance=g.copy(),
        sigma=_honest_sigma(sol),
        resolution_m=res,
        segment=np.zeros(n, dtype=np.int64),
        smoothed=g,
        drift_sigma_passed=float(ident.get("drift_sigma_passed_mps2", 0.0)),
        forward=np.asarray(sol.g_forward, float),
        forward_sigma=_opt(getattr(sol, "sigma_forward", None), n, "sigma_forward"),
        attitude=getattr(sol, "attitude", None),
        attitude_sigma=getattr(sol, "attitude_sigma", None),
        **horizontal_fields(sol, n),
        estimator={
            **attitude_report(sol),
            "gnss_aided": gnss_aided,
            "identification": ident,
            "kalman_resolution_m": res,
        },
        notes=notes,
    )


def track_heading(vel_n) -> np.ndarray:
    """Track over ground from ENU velocities ``vel_n`` (N, 3), rad clockwise from north in [0, 2 pi)."""
    vel_n = np.asarray(vel_n, float)
    return np.mod(np.arctan2(vel_n[:, 0], vel_n[:, 1]), 2.0 * np.pi)


def from_classic(res, *, name: str = "", t0_unix_ns: int = 0) -> FlightEstimate:
    """The :class:`FlightEstimate` of a :class:`gravsurvey.classic.ClassicResult`.

    The product is the low-passed reduction; ``unfiltered`` keeps the reduction before the
    low-pass; there is no smoothed or forward estimate and no sigma (NaN). Epochs where
    either is NaN (gaps the readers left empty, or the low-pass window reaching into one) are
    gap epochs (``segment`` -1), like the separators between the INS chain's pieces.
    """
    n = len(res.time)
    vel = np.asarray(res.vel_n, float)
    raw = np.asarray(res.raw, float)
    dist = np.asarray(res.disturbance, float)
    resolution = float(res.info.get("resolution_m") or np.nan)
    return FlightEstimate(
        name=name,
        method=METHOD_CLASSIC,
        t0_unix_ns=int(t0_unix_ns),
        time=np.asarray(res.time, float),
        lat=np.asarray(res.lat, float),
        lon=np.asarray(res.lon, float),
        height=np.asarray(res.height, float),
        vel_n=vel,
        speed=np.linalg.norm(vel[:, :2], axis=1),
        heading=track_heading(vel),
        disturbance=dist,
        sigma=np.full(n, np.nan),
        resolution_m=resolution,
        segment=np.where(np.isfinite(raw) & np.isfinite(dist), 0, -1).astype(np.int64),
        unfiltered=raw,
        product_info=dict(res.info),
        estimator={"gnss_aided": False, "resolution_m": resolution},
    )


_SERIES = (
    "lat",
    "lon",
    "height",
    "speed",
    "heading",
    "disturbance",
    "sigma",
    "smoothed",
    "forward",
    "forward_sigma",
    "unfiltered",
    "dg_north",
    "dg_east",
    "sigma_north",
    "sigma_east",
)


#: An estimate is left out within this many times the piece's half-wavelength resolution (in
#: time, at its median speed) of a gap (:func:`trim_one_sided_ends`). Measured on quick unseen
#: flights split by an IMU gap mid-line (RMS error against the intact run's at the same epochs,
#: per part of that time before the gap): U015 14.3 / 9.5 / 2.7 mGal (intact 2.6 / 2.4 / 1.1)
#: over 0-0.25, 0.25-0.5 and 0.5-1 of it, 2.0 against 1.9 beyond; U010 3.0 / 4.8 against
#: 1.7 / 3.4 within it.
ONE_SIDED_MARGIN = 1.0


def trim_one_sided_ends(parts: list[FlightEstimate], first_s: float, last_s: float) -> tuple[list, list]:
    """Leave out the epochs beside every gap between the pieces of a split flight.

    A piece's smoothed estimate at its end has data on one side only: there it lags the field
    by up to the smoother's resolution, and the stated sigma (the model's) does not know the
    field's gradient there (quick U015 split by a 5-s IMU gap mid-line: -15 mGal at the gap,
    sigma 2.4; 1.2 mGal RMS intact). The epochs within :data:`ONE_SIDED_MARGIN` x (the piece's
    ``resolution_m`` / its median speed) of a piece's end that is not the flight's own
    (``first_s``, ``last_s``: the record's first and last IMU time, s) are left out, as if the
    gap were that much longer (lines end there). A piece with no finite resolution (a flat
    estimate) is kept whole, so is one the margins would leave nothing of.

    Returns
    -------
    parts : list of FlightEstimate
        Copies without those epochs (the same objects where nothing was left out).
    notes : list of str
        One per piece end trimmed: its time range and why.
    """
    out, notes = [], []
    for p in parts:
        t = np.asarray(p.time, float)
        speed = np.asarray(p.speed, float)
        speed = float(np.nanmedian(speed)) if np.isfinite(speed).any() else float("nan")
        res = float(p.resolution_m)
        if t.size < 2 or not (math.isfinite(res) and res > 0.0 and math.isfinite(speed) and speed > 0.0):
            out.append(p)
            continue
        margin = ONE_SIDED_MARGIN * res / speed
        keep = np.ones(t.size, bool)
        ends = []
        if t[0] > first_s + 1.0:
            keep &= t >= t[0] + margin
            ends.append((t[0], t[0] + margin))
        if t[-1] < last_s - 1.0:
            keep &= t <= t[-1] - margin
            ends.append((t[-1] - margin, t[-1]))
        if keep.all() or keep.sum() < 2:
            out.append(p)
            continue
        n = t.size
        changes = {}
        for f in dataclasses.fields(p):
            v = getattr(p, f.name)
            if isinstance(v, np.ndarray) and v.ndim >= 1 and v.shape[0] == n:
                changes[f.name] = v[keep]
        out.append(dataclasses.replace(p, **changes))
        for a, b in ends:
            notes.append(
                f"the estimate within {margin:.0f} s of the gap ({utc_after(p.t0_unix_ns, a)}.."
                f"{utc_after(p.t0_unix_ns, b)}) is left out: it has data on one side only and lags the field "
                f"there, up to the piece's resolution ({res / 1000.0:.1f} km at {speed:.0f} m/s)"
            )
    return out, notes


def concatenate_estimates(parts: list[FlightEstimate]) -> FlightEstimate:
    """Join the estimates of the pieces of one flight (split at long gaps) in time order.

    Pieces are joined with one NaN epoch in the middle of each gap (``segment`` -1 there), so
    that plots, line segmentation and post-processing never join across a gap; ``segment`` holds
    each epoch's piece number. Optional series present in only some pieces are NaN in the
    others (``horizontal_observable`` False). ``resolution_m`` is the coarsest piece's (a
    statement that holds for every epoch); the pieces' estimator facts are kept under
    ``estimator["segments"]``.

    Parameters
    ----------
    parts : list of FlightEstimate
        At least one, all with the same ``method`` and ``t0_unix_ns``.
    """
    if not parts:
        raise ValueError("concatenate_estimates: no pieces")
    if len(parts) == 1:
        return parts[0]
    first = parts[0]
    out: dict = {
        k: [] for k in _SERIES + ("time", "vel_n", "segment", "attitude", "attitude_sigma", "horizontal_observable")
    }
    present = {k: any(getattr(p, k) is not None for p in parts) for k in _SERIES}
    for i, p in enumerate(parts):
        n = len(p.time)
        if i > 0:
            out["time"].append(np.array([0.5 * (float(parts[i - 1].time[-1]) + float(p.time[0]))]))
            for k in _SERIES:
                out[k].append(np.array([np.nan]))
            for k in ("vel_n", "attitude", "attitude_sigma"):
                out[k].append(np.full((1, 3), np.nan))
            out["segment"].append(np.array([-1]))
            out["horizontal_observable"].append(np.array([False]))
        out["time"].append(np.asarray(p.time, float))
        for k in _SERIES:
            a = getattr(p, k)
            out[k].append(np.full(n, np.nan) if a is None else np.asarray(a, float))
        for k in ("vel_n", "attitude", "attitude_sigma"):
            out[k].append(np.asarray(getattr(p, k), float))
        # a piece's own gap epochs stay gaps
        out["segment"].append(np.where(np.asarray(p.segment) >= 0, i, -1))
        obs = p.horizontal_observable
        out["horizontal_observable"].append(np.zeros(n, bool) if obs is None else np.asarray(obs, bool))
    arr = {k: np.concatenate(v) for k, v in out.items()}
    for k in _SERIES:
        if not present[k]:
            arr[k] = None
    if arr["dg_north"] is None:
        arr["horizontal_observable"] = None
    res = np.array([p.resolution_m for p in parts], float)
    # an unbounded piece (nothing resolved) is the coarsest: inf, not "unknown" (NaN)
    resolution = float(np.nanmax(res)) if (~np.isnan(res)).any() else float("nan")
    estimator = {
        "gnss_aided": any(bool(p.estimator.get("gnss_aided", False)) for p in parts),
        "identification": {"segments": [p.estimator.get("identification", {}) for p in parts]},
        "segments": [{k: v for k, v in p.estimator.items() if k != "identification"} for p in parts],
    }
    if first.method == METHOD_INM:
        estimator["kalman_resolution_m"] = resolution
    else:
        estimator["resolution_m"] = resolution
    return FlightEstimate(
        name=first.name,
        method=first.method,
        t0_unix_ns=first.t0_unix_ns,
        resolution_m=resolution,
        drift_sigma_passed=max(p.drift_sigma_passed for p in parts),
        notes=list(dict.fromkeys(n for p in parts for n in p.notes)),
        data_loss=[d for p in parts for d in p.data_loss],
        estimator=estimator,
        **arr,
    )


def deflection_arcsec(dg_horizontal, lat, height, ellipsoid: Ellipsoid = WGS84) -> np.ndarray:
    """Deflection of the vertical from a horizontal disturbance component, arcsec.

    ``xi = -dg_north / gamma`` and ``eta = -dg_east / gamma`` with ``gamma`` the normal gravity
    at the point (:func:`gravsurvey.geodesy.normal_gravity`).

    Parameters
    ----------
    dg_horizontal : ndarray, shape (N,)
        North (for xi) or east (for eta) disturbance component, m/s^2 (or its 1-sigma: pass
        the sigma and take the absolute value of the result).
    lat : ndarray, shape (N,)
        Geodetic latitude, rad.
    height : ndarray, shape (N,)
        Ellipsoidal height, m.

    Returns
    -------
    ndarray, shape (N,)
        arcsec.
    """
    lat = np.asarray(lat, float)
    h = np.asarray(height, float)
    ok = np.isfinite(lat) & np.isfinite(h)
    gamma = np.full(lat.shape, np.nan)
    if ok.any():
        gamma[ok] = normal_gravity(lat[ok], h[ok], ellipsoid)
    return -np.asarray(dg_horizontal, float) / gamma * ARCSEC_PER_RAD
