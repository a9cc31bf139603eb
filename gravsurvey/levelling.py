"""Crossover levelling: a least-squares adjustment of line offsets (and trends) at crossovers.

Each survey line ``i`` of flight ``f`` carries an unknown level error (gravimeter offset and
drift left after the flight's processing). The adjustment models it as

    e(t) = c_i  [+ s_i * (t - tm_i)]  [+ d_f * (t - tm_f)]

with ``c_i`` a constant per line (mGal), optionally a trend per line ``s_i`` (mGal/h, about the
line's mid-time ``tm_i``) and optionally a drift per flight ``d_f`` (mGal/h, about the flight's
mid-time ``tm_f``). At a crossover ``k`` of line ``a`` (time ``ta``) with line ``b`` (time
``tb``) the observed difference ``x_k = value_a - value_b`` should equal ``e_a(ta) - e_b(tb)``.
The unknowns minimise ``sum_k w_k r_k^2`` with ``r_k = x_k - (e_a(ta) - e_b(tb))``:

- weights ``w_k = 1 / (sigma_a^2 + sigma_b^2)`` from the lines' 1-sigma at the crossover (unit
  weights where no sigma is known; sigmas below ``sigma_floor_mgal`` are raised to it, so one
  optimistic sigma cannot dominate);
- robust: iteratively reweighted least squares with Huber weights
  ``min(1, k / |r_k / s|)`` (``s`` the normalised median absolute deviation of the weighted
  residuals, ``k = huber_k``), so a crossover spoilt by a turn or a spike loses its pull;
- datum: crossovers fix only differences, so each connected group of lines needs one more
  condition. Per group, the mean constant over the lines of *tied* flights (flights put on an
  absolute level by base ties, :mod:`gravsurvey.ties`) is zero, or, without tied flights, the
  mean constant over all its lines is zero (the convention of GMT ``x2sys_solve``). Trends that
  the crossovers cannot determine (a line with crossovers at one time only) come out zero
  (minimum-norm solution of the remaining rank deficiency). Lines without any crossover are not
  adjusted (correction 0, ``levelled: false``).

Units: mGal for values and corrections, s for times (mGal/h for trends in the results).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.sparse import coo_matrix, diags, identity
from scipy.sparse.linalg import spsolve

from gravsurvey.errors import ConfigError, DataError

__all__ = [
    "LEVELLING_MODELS",
    "LevellingOptions",
    "Levelling",
    "level_crossovers",
    "crossover_statistics",
    "level_survey",
    "choose_levelling",
    "significance_test",
    "understated_sigma_note",
]

LEVELLING_MODELS = ("constant", "line_trend", "flight_trend", "flight_constant")
#: Models tried, in this order after the configured one, when the configured one has too few
#: crossovers (``enabled: null``): each has fewer unknowns than the one before.
FALLBACK_MODELS = ("constant", "flight_constant")
#: trends are solved in mGal/h: times scaled from s to h keep the normal matrix well conditioned
S_PER_H = 3600.0
#: Huber constant: 95 % efficiency for Gaussian residuals
HUBER_K_DEFAULT = 1.345
#: consistency factor of the median absolute deviation for a Gaussian
MAD_TO_SIGMA = 1.4826
#: IRLS stops when no unknown moves by more than this between iterations, mGal (mGal/h)
IRLS_TOL_MGAL = 1e-4
#: A robust unit-weight sigma of the crossovers about the fitted model above this factor says
#: the lines' stated sigmas understate their errors (a factor, not a test: crossover errors
#: correlate along the lines, so the redundancy overstates the degrees of freedom)
SIGMA0_UNDERSTATED = 2.0
#: ... judged only with at least this redundancy (crossovers less unknowns)
SIGMA_CHECK_MIN_REDUNDANCY = 10


@dataclass
class LevellingOptions:
    """The ``levelling:`` configuration section.

    Attributes
    ----------
    enabled : bool or None
        None (default): level when the survey has enough crossovers (``min_crossovers_per_unknown``);
        True: whenever it has crossovers; False: never.
    model : str
        ``constant`` (one offset per line), ``line_trend`` (offset and trend per line) or
        ``flight_trend`` (offset per line and a drift per flight) or ``flight_constant`` (one
        offset shared by all lines of a flight: the reduced model for surveys with few crossovers).
    robust : bool
        Huber IRLS (default True).
    huber_k : float
        Huber constant in robust standard deviations.
    sigma_floor_mgal : float
        Smallest per-line sigma used in the weights, mGal.
    max_iterations : int
        IRLS iterations at most.
    min_crossovers_per_unknown : float
        With ``enabled`` None, a model is used only when the usable crossovers number at least
        this many per estimated unknown (the unknowns minus one datum per group of lines): with
        fewer, the adjustment fits the crossovers' noise (on the former 6-line sample survey,
        5 crossovers for 4 unknowns moved one line's mean error from 1.8 to -1.3 mGal).
    significance : float
        With ``enabled`` None, the corrections are applied only when the F-test of "no level
        errors" against the model rejects it at this level (:func:`significance_test`).
    """

    enabled: bool | None = None
    model: str = "constant"
    robust: bool = True
    huber_k: float = HUBER_K_DEFAULT
    sigma_floor_mgal: float = 0.1
    max_iterations: int = 30
    min_crossovers_per_unknown: float = 2.0
    significance: float = 0.05


def crossover_statistics(diff_mgal, line_a, line_b, line_keys) -> dict:
    """Count, mean, RMS and RMS/sqrt(2) of crossover differences, overall and per line.

    Parameters
    ----------
    diff_mgal : array_like, shape (k,)
        ``value_a - value_b``, mGal (non-finite rows are ignored).
    line_a, line_b : array_like of int, shape (k,)
        Index into ``line_keys`` of each crossover's two lines.
    line_keys : list of str
        Line labels (``"<flight>/<line>"``).

    Returns
    -------
    dict
        ``count, mean_mgal, rms_mgal, rms_over_sqrt2_mgal, per_line`` (label -> the same
        statistics of ``this line - other line``).
    """
    d = np.asarray(diff_mgal, float)
    a = np.asarray(line_a, int)
    b = np.asarray(line_b, int)
    ok = np.isfinite(d)
    d, a, b = d[ok], a[ok], b[ok]
    nl = len(line_keys)

    def stats(cnt, s1, s2):
        if cnt == 0:
            return {
                "count": 0,
                "mean_mgal": float("nan"),
                "rms_mgal": float("nan"),
                "rms_over_sqrt2_mgal": float("nan"),
            }
        rms = math.sqrt(s2 / cnt)
        return {"count": int(cnt), "mean_mgal": s1 / cnt, "rms_mgal": rms, "rms_over_sqrt2_mgal": rms / math.sqrt(2.0)}

    # per line in one pass (bincount), as line a with +d and as line b with -d
    cnt = np.bincount(a, minlength=nl) + np.bincount(b, minlength=nl)
    s1 = np.bincount(a, d, minlength=nl) - np.bincount(b, d, minlength=nl)
    s2 = np.bincount(a, d**2, minlength=nl) + np.bincount(b, d**2, minlength=nl)
    out = stats(d.size, float(d.sum()), float((d**2).sum()))
    out["per_line"] = {line_keys[i]: stats(int(cnt[i]), float(s1[i]), float(s2[i])) for i in range(nl)}
    return out


@dataclass
class Levelling:
    """The result of :func:`level_crossovers`.

    Attributes
    ----------
    model : str
    line_keys : list of (str, str)
        (flight, line) of every line, input order.
    constant_mgal : ndarray, shape (n_lines,)
        ``c_i``, mGal (0 for lines without crossovers).
    trend_mgal_per_h : ndarray, shape (n_lines,)
        ``s_i``, mGal/h (0 unless ``model == "line_trend"``).
    line_mid_s : ndarray, shape (n_lines,)
        ``tm_i``, s (flight time base).
    flight_drift_mgal_per_h : dict
        flight -> ``d_f``, mGal/h (empty unless ``model == "flight_trend"``).
    flight_mid_s : dict
        flight -> ``tm_f``, s.
    levelled : ndarray of bool, shape (n_lines,)
        The line has at least one usable crossover (its correction was estimated).
    residual_mgal : ndarray, shape (k,)
        Crossover differences after levelling (NaN where the input was NaN).
    weight : ndarray, shape (k,)
        Final robust weight of each crossover in [0, 1] (1: full weight).
    before, after : dict
        :func:`crossover_statistics` of the differences before and after.
    iterations : int
    diff_mgal : ndarray, shape (k,)
        The crossover differences before levelling, mGal.
    n_observations, n_unknowns : int
        Usable crossovers, and the unknowns they determine (estimated unknowns minus one datum
        per connected group of lines).
    datum : str
        ``"tied flights"`` or ``"mean of lines"`` (or ``"mixed"`` if groups differ).
    fit_weight : ndarray, shape (k,)
        Final weight of each crossover in the fit, ``weight / (sigma_a^2 + sigma_b^2)``, 1/mGal^2
        (NaN for crossovers not used).
    ls_misfit : (float, float)
        ``sum w x^2`` and ``sum w r^2`` of the plain weighted least-squares fit (``w`` the sigma
        weights, no robust reweighting): the sums of squares of :func:`significance_test`.
    sigma0_robust : float
        Robust unit-weight sigma of the crossovers about the final fit:
        ``1.4826 median(|r_k| sqrt(w_k)) sqrt(n / (n - u))`` with ``w_k = 1 / (sigma_a^2 +
        sigma_b^2)`` (sigmas under ``sigma_floor_mgal`` raised to it); about 1 when the stated
        sigmas are right (NaN without sigmas or without redundancy). The median keeps a few bad
        crossovers (a turn, a spike) from deciding it.
    decision : dict or None
        Set by :func:`choose_levelling`: whether the corrections are applied, by which rule, and
        the statistics of every model tried.
    """

    model: str
    line_keys: list
    constant_mgal: np.ndarray
    trend_mgal_per_h: np.ndarray
    line_mid_s: np.ndarray
    flight_drift_mgal_per_h: dict
    flight_mid_s: dict
    levelled: np.ndarray
    residual_mgal: np.ndarray
    weight: np.ndarray
    before: dict
    after: dict
    iterations: int = 0
    datum: str = "mean of lines"
    notes: list = field(default_factory=list)
    diff_mgal: np.ndarray | None = None
    n_observations: int = 0
    n_unknowns: int = 0
    fit_weight: np.ndarray | None = None
    ls_misfit: tuple = (0.0, 0.0)
    decision: dict | None = None
    sigma0_robust: float = float("nan")

    def correction(self, flight: str, line: str, time_s) -> np.ndarray:
        """The level error of one line at the given times, mGal: subtract it from the values.

        Parameters
        ----------
        flight, line : str
        time_s : array_like, shape (m,)
            Flight time base, s.

        Returns
        -------
        ndarray, shape (m,)
            Zeros for a line the adjustment does not know.
        """
        t = np.asarray(time_s, float)
        i = self.index_of((flight, line))
        if i is None:
            return np.zeros_like(t)
        c = self.constant_mgal[i] + self.trend_mgal_per_h[i] * (t - self.line_mid_s[i]) / S_PER_H
        d = self.flight_drift_mgal_per_h.get(str(flight))
        if d is not None:
            c = c + d * (t - self.flight_mid_s[str(flight)]) / S_PER_H
        return c

    def index_of(self, key) -> int | None:
        """Position of ``(flight, line)`` in :attr:`line_keys` (None if absent); O(1)."""
        pos = self.__dict__.get("_pos")
        if pos is None:
            pos = self.__dict__["_pos"] = {k: i for i, k in enumerate(self.line_keys)}
        return pos.get((str(key[0]), str(key[1])))

    def statistics(self) -> dict:
        """A JSON-able summary: model, datum, before/after statistics, corrections per line."""
        per_line = {}
        for i, (f, ln) in enumerate(self.line_keys):
            lab = f"{f}/{ln}"
            per_line[lab] = {
                "levelled": bool(self.levelled[i]),
                "constant_mgal": float(self.constant_mgal[i]),
                "trend_mgal_per_h": float(self.trend_mgal_per_h[i]),
                "before": self.before["per_line"].get(lab),
                "after": self.after["per_line"].get(lab),
            }
        strip = lambda s: {k: v for k, v in s.items() if k != "per_line"}  # noqa: E731
        return {
            "model": self.model,
            "datum": self.datum,
            "iterations": self.iterations,
            "downweighted": int(np.sum(self.weight < 0.5)),
            "n_observations": self.n_observations,
            "n_unknowns": self.n_unknowns,
            "before": strip(self.before),
            "after": strip(self.after),
            "flight_drift_mgal_per_h": dict(self.flight_drift_mgal_per_h),
            "test": significance_test(self),
            "decision": self.decision,
            "per_line": per_line,
            "notes": list(self.notes),
        }


def _components(n: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Connected-component label of each of ``n`` nodes joined by edges (a, b)."""
    from scipy.sparse.csgraph import connected_components

    g = coo_matrix((np.ones(a.size), (a, b)), shape=(n, n))
    return connected_components(g, directed=False)[1]


def level_crossovers(
    diff_mgal,
    line_a,
    line_b,
    time_a_s,
    time_b_s,
    line_keys,
    line_mid_s,
    *,
    sigma_a_mgal=None,
    sigma_b_mgal=None,
    model: str = "constant",
    robust: bool = True,
    huber_k: float = HUBER_K_DEFAULT,
    sigma_floor_mgal: float = 0.1,
    max_iterations: int = 30,
    tied_flights=(),
    flight_mid_s: dict | None = None,
) -> Levelling:
    """Least-squares levelling of lines from their crossover differences (module docstring).

    Parameters
    ----------
    diff_mgal : array_like, shape (k,)
        ``value_a - value_b`` at each crossover, mGal; non-finite rows are ignored.
    line_a, line_b : array_like of int, shape (k,)
        Index into ``line_keys`` of line a and line b.
    time_a_s, time_b_s : array_like, shape (k,)
        Time of the crossover on each line, s (the flight's time base).
    line_keys : list of (str, str)
        (flight, line) per line.
    line_mid_s : array_like, shape (n_lines,)
        Mid-time of each line, s (the trend's origin).
    sigma_a_mgal, sigma_b_mgal : array_like, shape (k,), optional
        1-sigma of each line's value at the crossover, mGal (NaN or absent: unit weight).
    model : {"constant", "line_trend", "flight_trend"}
    robust : bool
        Huber IRLS.
    huber_k : float
    sigma_floor_mgal : float
    max_iterations : int
    tied_flights : iterable of str
        Flights on an absolute level (base ties): the datum of every group that contains one.
    flight_mid_s : dict, optional
        flight -> mid-time, s (``flight_trend``; default: mean crossover time of the flight).

    Returns
    -------
    Levelling

    Raises
    ------
    DataError
        Arrays of unequal length or line indices out of range.
    """
    if model not in LEVELLING_MODELS:
        raise ConfigError(f"levelling.model: expected one of {', '.join(LEVELLING_MODELS)}, got {model!r}")
    x = np.asarray(diff_mgal, float)
    ia = np.asarray(line_a, int)
    ib = np.asarray(line_b, int)
    ta = np.asarray(time_a_s, float)
    tb = np.asarray(time_b_s, float)
    keys = [(str(f), str(ln)) for f, ln in line_keys]
    nl = len(keys)
    tm = np.asarray(line_mid_s, float)
    if not (x.shape == ia.shape == ib.shape == ta.shape == tb.shape) or x.ndim != 1:
        raise DataError("levelling: crossover arrays must be 1-D of equal length")
    if tm.shape != (nl,):
        raise DataError(f"levelling: line_mid_s must have shape ({nl},), got {tm.shape}")
    if x.size and (ia.min() < 0 or ib.min() < 0 or max(ia.max(), ib.max()) >= nl):
        raise DataError("levelling: crossover line index out of range")
    labels = [f"{f}/{ln}" for f, ln in keys]
    before = crossover_statistics(x, ia, ib, labels)

    sa = np.full(x.size, np.nan) if sigma_a_mgal is None else np.asarray(sigma_a_mgal, float)
    sb = np.full(x.size, np.nan) if sigma_b_mgal is None else np.asarray(sigma_b_mgal, float)
    var = np.maximum(np.where(np.isfinite(sa), sa, 0.0), sigma_floor_mgal) ** 2
    var = var + np.maximum(np.where(np.isfinite(sb), sb, 0.0), sigma_floor_mgal) ** 2
    sigmas_given = bool(np.isfinite(sa).any() or np.isfinite(sb).any())
    if not sigmas_given:
        var = np.ones_like(var)
    ok = np.isfinite(x) & np.isfinite(ta) & np.isfinite(tb)
    k_ok = np.flatnonzero(ok)

    flights = list(dict.fromkeys(f for f, _ in keys))
    fpos = {f: j for j, f in enumerate(flights)}
    fidx = np.array([fpos[f] for f, _ in keys], int) if keys else np.zeros(0, int)
    if flight_mid_s is None:
        flight_mid_s = {}
        for j, f in enumerate(flights):
            tt = np.concatenate([ta[k_ok][fidx[ia[k_ok]] == j], tb[k_ok][fidx[ib[k_ok]] == j]])
            flight_mid_s[f] = float(tt.mean()) if tt.size else 0.0
    fmid = np.array([float(flight_mid_s.get(f, 0.0)) for f in flights])

    # unknowns: constants [0, nc) (one per line, or one per flight for flight_constant), then
    # line trends or flight drifts
    tied = set(str(f) for f in tied_flights)
    per_flight = model == "flight_constant"
    cidx = fidx if per_flight else np.arange(nl)
    nc = len(flights) if per_flight else nl
    col_flight = flights if per_flight else [f for f, _ in keys]
    if per_flight:
        # a crossover within one flight says nothing about the flight's constant
        ok &= cidx[ia] != cidx[ib]
        k_ok = np.flatnonzero(ok)
    has_xo = np.zeros(nl, bool)
    has_xo[ia[k_ok]] = True
    has_xo[ib[k_ok]] = True
    col_xo = np.zeros(nc, bool)
    col_xo[cidx[has_xo]] = True
    n_extra = nl if model == "line_trend" else (len(flights) if model == "flight_trend" else 0)
    nu = nc + n_extra
    m = k_ok.size
    # sparse design matrix: 2 (constant) or 4 (with trends) non-zeros per crossover
    r = np.arange(m)
    rr, cc, vv = [r, r], [cidx[ia[k_ok]], cidx[ib[k_ok]]], [np.ones(m), -np.ones(m)]
    if model == "line_trend":
        rr += [r, r]
        cc += [nc + ia[k_ok], nc + ib[k_ok]]
        vv += [(ta[k_ok] - tm[ia[k_ok]]) / S_PER_H, -(tb[k_ok] - tm[ib[k_ok]]) / S_PER_H]
    elif model == "flight_trend":
        fa, fb = fidx[ia[k_ok]], fidx[ib[k_ok]]
        rr += [r, r]
        cc += [nc + fa, nc + fb]
        vv += [(ta[k_ok] - fmid[fa]) / S_PER_H, -(tb[k_ok] - fmid[fb]) / S_PER_H]
    A = coo_matrix((np.concatenate(vv), (np.concatenate(rr), np.concatenate(cc))), shape=(m, nu)).tocsr()
    y = x[k_ok]
    w0 = 1.0 / var[k_ok]

    # unknowns no crossover touches stay zero
    free = np.zeros(nu, bool)
    free[:nc] = col_xo
    if n_extra:
        free[nc:] = np.asarray(abs(A[:, nc:]).sum(axis=0)).ravel() > 0
    if model == "flight_trend":
        # a tied flight's drift is known from its base readings (gravsurvey.ties): not re-estimated
        free[nc:] &= np.array([f not in tied for f in flights], bool)
    cols = np.flatnonzero(free)
    Af = A[:, cols]

    # datum: per connected group of lines, shifting all its constants together changes no
    # crossover difference; after the solve each group is shifted so that the mean constant of
    # its tied lines (or of all its lines) is zero
    comp = _components(nc, cidx[ia[k_ok]], cidx[ib[k_ok]]) if nc else np.zeros(0, int)
    groups, datums = [], set()
    for g in np.unique(comp[col_xo]):
        members = np.flatnonzero((comp == g) & col_xo)
        tmem = np.array([i for i in members if col_flight[i] in tied], int)
        groups.append((members, tmem if tmem.size else members))
        datums.add("tied flights" if tmem.size else "mean of lines")

    def solve(w):
        # normal equations with a ridge 1e-10 of the largest diagonal: makes the group shifts
        # (and trends no crossover can see) determinate at ~0 without changing the rest
        N = (Af.T @ diags(w) @ Af).tocsc()
        d = N.diagonal()
        ridge = 1e-10 * (float(d.max()) if d.size and d.max() > 0 else 1.0)
        uf = spsolve(N + ridge * identity(N.shape[0], format="csc"), Af.T @ (w * y)) if cols.size else np.zeros(0)
        u = np.zeros(nu)
        u[cols] = np.atleast_1d(uf)
        for members, ref in groups:
            u[members] -= u[ref].mean()
        return u

    rw = np.ones(m)
    it = 0
    u = solve(w0) if m else np.zeros(nu)
    # weighted misfit before and after the plain (non-robust) fit: the F-test's sums of squares
    # (robust reweighting would shrink the after-sum more than the before-sum and inflate F)
    ls_misfit = (float(np.sum(w0 * y**2)), float(np.sum(w0 * (y - A @ u) ** 2))) if m else (0.0, 0.0)
    if robust and m > 2:
        for it in range(1, max_iterations + 1):
            res = (y - A @ u) * np.sqrt(w0)
            s = MAD_TO_SIGMA * np.median(np.abs(res))
            if not s > 0:
                break
            new = np.minimum(1.0, huber_k * s / np.maximum(np.abs(res), 1e-300))
            u_new = solve(w0 * new)
            done = np.max(np.abs(u_new - u)) < IRLS_TOL_MGAL if nu else True
            rw, u = new, u_new
            if done:
                break

    weight = np.full(x.size, np.nan)
    weight[k_ok] = rw
    resid = np.full(x.size, np.nan)
    resid[k_ok] = y - A @ u
    after = crossover_statistics(resid, ia, ib, labels)
    fit_w = np.full(x.size, np.nan)
    fit_w[k_ok] = w0 * rw
    trend = u[nc:] if model == "line_trend" else np.zeros(nl)
    drift = {f: float(u[nc + j]) for j, f in enumerate(flights)} if model == "flight_trend" else {}
    if per_flight:
        # every line of a levelled flight carries its flight's constant
        has_xo = col_xo[cidx]
    notes = []
    if (~has_xo).any():
        notes.append(
            f"{int((~has_xo).sum())} line(s) without crossovers not levelled: "
            + ", ".join(labels[i] for i in np.flatnonzero(~has_xo)[:10])
        )
    ngroups = len(np.unique(comp[col_xo])) if col_xo.any() else 0
    if ngroups > 1:
        notes.append(
            f"the crossovers split the lines into {ngroups} unconnected groups, each levelled to its own datum"
        )
    n_unknowns = int(free.sum()) - int(ngroups)
    sigma0_robust = float("nan")
    if sigmas_given and m > n_unknowns:
        r_w = np.abs(y - A @ u) * np.sqrt(w0)
        sigma0_robust = MAD_TO_SIGMA * float(np.median(r_w)) * math.sqrt(m / (m - n_unknowns))
    return Levelling(
        model=model,
        line_keys=keys,
        constant_mgal=u[cidx].copy(),
        trend_mgal_per_h=np.asarray(trend, float).copy(),
        line_mid_s=tm.copy(),
        flight_drift_mgal_per_h=drift,
        flight_mid_s={f: float(v) for f, v in zip(flights, fmid)},
        levelled=has_xo,
        residual_mgal=resid,
        weight=weight,
        before=before,
        after=after,
        iterations=it,
        datum=datums.pop() if len(datums) == 1 else ("mixed" if datums else "none"),
        notes=notes,
        diff_mgal=x.copy(),
        n_observations=int(m),
        n_unknowns=n_unknowns,
        fit_weight=fit_w,
        ls_misfit=ls_misfit,
        sigma0_robust=sigma0_robust,
    )


def level_survey(crossovers, lines, options: LevellingOptions | None = None, *, tied_flights=()) -> Levelling:
    """Level the lines of a survey from a :class:`gravsurvey.crossovers.Crossovers` result.

    Parameters
    ----------
    crossovers : gravsurvey.crossovers.Crossovers
        From :func:`gravsurvey.crossovers.find_crossovers` on ``lines`` (times in each flight's base).
    lines : list of dict
        ``{"flight", "line", "time_s": (m,)}`` and optionally ``"sigma_mgal": (m,)`` (the 1-sigma
        of the values, interpolated to the crossover times for the weights).
    options : LevellingOptions, optional
    tied_flights : iterable of str

    Returns
    -------
    Levelling
    """
    o = options or LevellingOptions()
    keys = [(str(ln["flight"]), str(ln["line"])) for ln in lines]
    pos = {k: i for i, k in enumerate(keys)}
    fa = np.asarray(crossovers.flight_a).astype(str)
    la = np.asarray(crossovers.line_a).astype(str)
    fb = np.asarray(crossovers.flight_b).astype(str)
    lb = np.asarray(crossovers.line_b).astype(str)
    try:
        ia = np.array([pos[(f, ln)] for f, ln in zip(fa, la)], int)
        ib = np.array([pos[(f, ln)] for f, ln in zip(fb, lb)], int)
    except KeyError as exc:
        raise DataError(f"levelling: crossover names line {exc.args[0]} that is not among the lines") from None
    ta = np.asarray(crossovers.time_a_s, float)
    tb = np.asarray(crossovers.time_b_s, float)
    mids = np.array([0.5 * (np.nanmin(ln["time_s"]) + np.nanmax(ln["time_s"])) for ln in lines], float)

    def sig_at(idx, t):
        out = np.full(t.size, np.nan)
        for i in np.unique(idx):
            s = lines[i].get("sigma_mgal")
            if s is None:
                continue
            s = np.asarray(s, float)
            tt = np.asarray(lines[i]["time_s"], float)
            good = np.isfinite(s) & np.isfinite(tt)
            if good.sum() >= 1:
                sel = idx == i
                out[sel] = np.interp(t[sel], tt[good], s[good])
        return out

    fmid = {}
    for ln in lines:
        t = np.asarray(ln["time_s"], float)
        lo, hi = fmid.get(str(ln["flight"]), (np.inf, -np.inf))
        fmid[str(ln["flight"])] = (min(lo, np.nanmin(t)), max(hi, np.nanmax(t)))
    return level_crossovers(
        crossovers.diff_mgal,
        ia,
        ib,
        ta,
        tb,
        keys,
        mids,
        sigma_a_mgal=sig_at(ia, ta),
        sigma_b_mgal=sig_at(ib, tb),
        model=o.model,
        robust=o.robust,
        huber_k=o.huber_k,
        sigma_floor_mgal=o.sigma_floor_mgal,
        max_iterations=o.max_iterations,
        tied_flights=tied_flights,
        flight_mid_s={f: 0.5 * (a + b) for f, (a, b) in fmid.items()},
    )


def significance_test(lev: Levelling) -> dict:
    """F-test of "the lines have no level errors" against the fitted model.

    With ``S0 = sum_k w_k x_k^2`` (the weighted crossover misfit without corrections),
    ``S1 = sum_k w_k r_k^2`` (after the weighted least-squares fit), ``u`` the estimated unknowns
    and ``n`` the crossovers used, ``F = ((S0 - S1) / u) / (S1 / (n - u))`` follows Fisher's
    F(u, n - u) when the lines have no level errors and the crossover errors are independent
    and Gaussian (the general linear hypothesis test of least squares). The ratio does not
    depend on the scale of the sigmas, so optimistic or pessimistic Kalman sigmas do not bias
    it. ``w_k = 1 / (sigma_a^2 + sigma_b^2)`` without the robust reweighting, which would shrink
    ``S1`` more than ``S0`` and inflate ``F`` (measured: 18 % false alarms instead of 5 % on
    noise-only 4 x 4 grids, ``tests/test_levelling.py``).

    Parameters
    ----------
    lev : Levelling

    Returns
    -------
    dict
        ``redundancy`` (n - u), ``f_statistic``, ``p_value`` (NaN when n <= u or nothing
        was estimated) and ``sigma0_before``, ``sigma0_after`` (the square roots of S0 / n and
        S1 / (n - u): unit-weight standard deviations, 1 for sigmas that are right), and
        ``sigma0_robust`` (:attr:`Levelling.sigma0_robust`).
    """
    n, u = int(lev.n_observations), int(lev.n_unknowns)
    out = {
        "redundancy": n - u,
        "f_statistic": float("nan"),
        "p_value": float("nan"),
        "sigma0_before": float("nan"),
        "sigma0_after": float("nan"),
        "sigma0_robust": float(lev.sigma0_robust),
    }
    if n == 0:
        return out
    s0, s1 = lev.ls_misfit
    out["sigma0_before"] = math.sqrt(s0 / n)
    if u <= 0 or n <= u:
        return out
    from scipy.stats import f as fisher_f

    out["sigma0_after"] = math.sqrt(s1 / (n - u))
    if s1 <= 0:
        out["f_statistic"], out["p_value"] = float("inf"), 0.0
        return out
    fstat = max(s0 - s1, 0.0) / u / (s1 / (n - u))
    out["f_statistic"] = fstat
    out["p_value"] = float(fisher_f.sf(fstat, u, n - u))
    return out


def choose_levelling(crossovers, lines, options: LevellingOptions | None = None, *, tied_flights=()) -> Levelling:
    """Level a survey and decide whether its corrections are applied (``levelling.enabled``).

    ``enabled: false``: nothing is fitted; returns None. ``enabled: true``: the configured
    model, applied whenever there are crossovers. ``enabled: null`` (default): the configured
    model, then the :data:`FALLBACK_MODELS` with fewer unknowns (a constant per line, then one
    per flight), are tried in turn; the first with at least ``min_crossovers_per_unknown``
    crossovers per estimated unknown is fitted, and its corrections are applied only when
    :func:`significance_test` rejects "no level errors" at ``significance`` (p < 0.05 by
    default): the crossovers must show level errors larger than their own noise. Otherwise the
    lines keep their values and the summary says why.

    Parameters
    ----------
    crossovers, lines, options, tied_flights
        As for :func:`level_survey`.

    Returns
    -------
    Levelling or None
        The fitted model with :attr:`Levelling.decision` ``{"applied", "model", "rule",
        "reason", "tried": [...]}`` (every model tried, with its counts and test); None when
        ``enabled`` is false.
    """
    o = options or LevellingOptions()
    if o.enabled is False:
        return None
    flights = {str(ln["flight"]) for ln in lines}
    order = [o.model] + [
        m for m in FALLBACK_MODELS if m != o.model and not (m == "flight_constant" and len(flights) < 2)
    ]
    if o.enabled:
        order = order[:1]
    tried, fits, pick = [], [], 0
    for model in order:
        lev = level_survey(crossovers, lines, replace(o, model=model), tied_flights=tied_flights)
        test = significance_test(lev)
        enough = lev.n_unknowns > 0 and lev.n_observations >= o.min_crossovers_per_unknown * lev.n_unknowns
        tried.append(
            {
                "model": model,
                "n_observations": lev.n_observations,
                "n_unknowns": lev.n_unknowns,
                "enough_crossovers": bool(enough),
                **test,
            }
        )
        fits.append(lev)
        if enough:
            pick = len(fits) - 1
            break
    # without a model that has enough crossovers, the configured one is reported
    lev, last = fits[pick], tried[pick]
    if o.enabled:
        applied, rule = lev.n_observations > 0, "forced (levelling.enabled: true)"
        reason = "" if applied else "no usable crossovers"
    elif not last["enough_crossovers"]:
        applied, rule = False, f"at least {o.min_crossovers_per_unknown:g} crossovers per unknown"
        reason = f"too few crossovers for every model (it needs {rule}): " + "; ".join(
            f"{t['model']} {t['n_observations']} for {t['n_unknowns']} unknowns" for t in tried
        )
    else:
        p = last["p_value"]
        applied = bool(np.isfinite(p) and p < o.significance)
        rule = (
            f"at least {o.min_crossovers_per_unknown:g} crossovers per unknown and the F-test of "
            f"'no level errors' rejected at {o.significance:g}"
        )
        reason = (
            ""
            if applied
            else (
                f"{lev.model}: the crossovers show no significant level errors (F = {last['f_statistic']:.3g}, "
                f"p = {p:.3g} >= {o.significance:g}): the corrections would fit noise"
            )
        )
    lev.decision = {"applied": bool(applied), "model": lev.model, "rule": rule, "reason": reason, "tried": tried}
    return lev


def understated_sigma_note(lev: Levelling) -> str | None:
    """A warning when the crossovers disagree by more than the lines' stated sigmas allow.

    Parameters
    ----------
    lev : Levelling
        A fitted levelling (applied or not); its :attr:`~Levelling.sigma0_robust` is compared
        with :data:`SIGMA0_UNDERSTATED` when the redundancy reaches
        :data:`SIGMA_CHECK_MIN_REDUNDANCY`.

    Returns
    -------
    str or None
        The note, or None when the sigmas are consistent with the crossovers or there are too
        few crossovers to say.
    """
    s0 = float(lev.sigma0_robust)
    redundancy = int(lev.n_observations) - int(lev.n_unknowns)
    if not (np.isfinite(s0) and redundancy >= SIGMA_CHECK_MIN_REDUNDANCY and s0 > SIGMA0_UNDERSTATED):
        return None
    return (
        f"crossovers: after levelling ({lev.model}) the lines still differ by {s0:.1f} times what their "
        f"stated sigma_mgal allows (robust unit-weight sigma over {lev.n_observations} crossovers, "
        f"1 when the sigmas are right): sigma_mgal understates the error of this survey"
    )


#: GMT x2sys definition of the track text files written by :func:`write_gmt_tracks`
GMT_X2SYS_FORMAT = """# gravsurvey track export for GMT x2sys: projected x, y (m), time (s), value (mGal)
#ASCII
#SKIP 1
x a N 1 0 %.3f
y a N 1 0 %.3f
t a N 1 0 %.3f
g a N 1 0 %.4f
"""


def write_gmt_tracks(directory, lines, *, suffix: str = "gst") -> list:
    """Export lines as GMT x2sys track files (one per line) and their format definition.

    Each file ``<flight>_<line>.<suffix>`` holds a header line, then ``x y t g`` rows
    (easting m, northing m, time s of the flight's base, value mGal); samples with a non-finite
    value or position are left out. ``gravsurvey.fmt`` (:data:`GMT_X2SYS_FORMAT`) describes them
    for ``gmt x2sys_init <TAG> -Dgravsurvey.fmt -E<suffix> -F -Ndc -Nsc``.

    Parameters
    ----------
    directory : path-like
    lines : list of dict
        ``{"flight", "line", "easting_m", "northing_m", "time_s", "value_mgal"}``.
    suffix : str

    Returns
    -------
    list of pathlib.Path
        The track files, in the order of ``lines``.
    """
    from pathlib import Path

    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    (d / "gravsurvey.fmt").write_text(GMT_X2SYS_FORMAT)
    out = []
    for ln in lines:
        cols = [np.asarray(ln[k], float) for k in ("easting_m", "northing_m", "time_s", "value_mgal")]
        ok = np.all(np.isfinite(np.column_stack(cols)), axis=1)
        p = d / f"{ln['flight']}_{ln['line']}.{suffix}"
        rows = "\n".join("%.3f %.3f %.3f %.4f" % r for r in zip(*(c[ok] for c in cols)))
        p.write_text(f"# x y t g ({ln['flight']} {ln['line']})\n" + rows + "\n")
        out.append(p)
    return out
