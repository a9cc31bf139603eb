"""Separate the gravimeter drift from the field with the survey's lines.

Within one line a slow gravimeter drift and a long-wavelength field look the same (seed 004's
solvability condition; docs/method.md "Drift"): the 1D identification cannot tell them apart and
the smoothed estimate carries the drift.  A survey flies several lines a few km apart, and there
the two differ: the field is a function of *position*, shared by neighbouring lines, the drift a
function of *time*, different on every line.  This stage fits that statement as a Gaussian
process on block averages of the smoothed estimate ``g`` over the flight's lines:

    g(t_i) = F(x_i, y_i) + D(t_i) + c + e_i

* ``F``: the field, isotropic in the horizontal plane, Matern-3/2 covariance
  ``s_F^2 (1 + sqrt(3) r / L) exp(-sqrt(3) r / L)`` (a potential field at flight height is
  smooth; the exponential kernel's roughness lets a strong short-wavelength field pose as drift);
* ``D``: the drift, first-order Gauss-Markov in time, ``s_D^2 exp(-|dt| / tau)`` - the
  gravimeter datasheet's model;
* ``c``: an unknown constant (the gravimeter bias; ties and levelling own it);
* ``e``: white, what the block average leaves of the smoother's error.

The five hyperparameters are found by maximising the likelihood of the block averages, with a
log-normal datasheet prior on the drift (``s_D`` about 1 mGal within a factor 3, ``tau`` about
600 s within a factor 10: :data:`gravsurvey.inm.identify.DRIFT_DEFAULT_SIGMA_MPS2`); the drift's
posterior mean at every epoch is taken off the estimate and its posterior sigma (less the part
common to the whole flight, which the constant absorbs) joins the product's sigma.  The blocks
are :data:`BLOCK_S` long: the likelihood then weighs the long wavelengths, where drift and field
must be told apart, rather than the field's fine structure.  The fitted drift counts as far as
the data need it: its likelihood ratio against the model without drift gives it a weight
(:func:`fitted_weight`, one half at :data:`MIN_LOG_LR`).  The rest of the weight goes to the
datasheet's drift (``s_D``, ``tau`` held at the prior's centre), taken off as far as the lines
show it - its posterior mean, shrunk by what the lines cannot tell - unless the blocks speak
against a drift of that size (:data:`DATASHEET_MIN_LOG_LR`; then to no drift, the fitted
drift taken with its weight below the threshold too, down to :data:`MIN_FITTED_WEIGHT_ALONE`).
The drift taken off is the weighted mean of the two posteriors, its sigma the mixture's (where
the rest goes to no drift, the pipeline adds that share of the drift the smoother passes).

One line leaves the drift unidentifiable; the stage then keeps the estimate as it is, and says
so in the report.  So does a field whose fitted correlation length is below
:data:`MIN_LENGTH_PER_RESOLUTION` times the estimate's along-track resolution: the smoother has
low-passed it along the lines only, and the isotropic field model would read the difference
between neighbouring lines as drift - unless the fitted field is too weak to pose as the fitted
drift (:data:`GUARD_FIELD_PER_DRIFT`).

A tare - a step in the gravimeter's reading (a spring meter after a shock, a strapdown
gravimeter's bias jump) - is a drift the Gauss-Markov model can follow only by growing it to
several times its size, which then soaks up field differences between the lines.  Given the
estimate's step response, :func:`find_tare` scans the blocks for a step, and one the blocks need
(:data:`TARE_MIN_LOG_LR`, the drift model refitted with and without it) is taken off with the
drift (docs/method.md, "Tares").

Where a drift is taken off, :func:`field_filter` Wiener-filters each line against what the
lines left of it: the fit's field spectrum along the track against the drift's posterior
residual (docs/method.md, "The field filter").

All inputs and outputs are SI (s, m, m/s^2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .geodesy import MGAL
from .inm.identify import DRIFT_DEFAULT_SIGMA_MPS2, DRIFT_DEFAULT_TAU_S, markov_psd
from .pool import single_threaded_blas

__all__ = [
    "BLOCK_S",
    "DriftOptions",
    "DriftFit",
    "block_length",
    "line_blocks",
    "fit_drift",
    "datasheet_drift_fit",
    "drift_posterior",
    "log_likelihood",
    "Tare",
    "find_tare",
    "step_response",
    "separate_drift",
    "passed_drift_factor",
    "fitted_weight",
    "matern32",
    "exponential",
    "track_psd_matern32",
    "field_filter_gain",
    "field_filter",
    "field_filter_applies",
]

#: Block length of the averages the model is fitted to, s (9 km at 100 m/s: measured on the
#: unseen suite against 30 and 45 s, docs/benchmarks.md "Drift from the lines").
BLOCK_S = 90.0
#: A block is used when at least this fraction of it lies on one line.
BLOCK_FILL = 0.5
#: Fewest blocks for a fit.
MIN_BLOCKS = 12
#: Most blocks (longer blocks beyond it; the fit is O(n^3)).
MAX_BLOCKS = 600
#: Log-likelihood ratio (with drift over without) below which the drift is not used; 3.0 is
#: the 95 % point of chi-square with 2 degrees of freedom (6.0) halved.
MIN_LOG_LR = 3.0
#: Where the blocks set the datasheet drift aside, the fitted drift is weighed against none
#: (:func:`fitted_weight`) and taken off where its weight is at least this: 0.05, a
#: log-likelihood ratio of 0.06, the fitted drift about as likely as none before the price of
#: its two free parameters.  Below it nothing is taken off.
MIN_FITTED_WEIGHT_ALONE = 0.05
#: The datasheet drift (:func:`datasheet_drift_fit`) is taken off unless the blocks speak
#: against it: its log-likelihood ratio over no drift at least this.  Both models have the same
#: free parameters (the field's and the white term), so the ratio is a Bayes factor; a
#: gravimeter is known to drift, and the data must make its datasheet drift e times less likely
#: than none to set it aside.
DATASHEET_MIN_LOG_LR = -1.0
#: The fitted drift's log-likelihood ratio above which it is checked against a rough field
#: (:func:`separate_drift`); below it the fitted drift carries little weight anyway.
ROUGH_CHECK_MIN_LOG_LR = 1.0
#: Fitted field correlation length below this multiple of the estimate's along-track resolution:
#: the drift is not used (configs/realistic_survey.yaml: 0.8x and 1.3x, where it made the error
#: 2.0-2.5 -> 3.0-3.6 mGal; the unseen flights it helped: 1.8x (U001) and more).
MIN_LENGTH_PER_RESOLUTION = 1.5
#: ... unless the fitted field is weaker than the fitted drift (this multiple of it): smoothing
#: along the lines only turns at most the field's own variation between neighbouring lines into
#: apparent drift, and a field weaker than the drift cannot pose as it (U018 of the unseen
#: suite: field 0.2 mGal, drift 1.1 mGal, its fitted field length 24.9 or 61 km within 0.44 of
#: log-likelihood, either side of the guard; quick U202: field 0.84, drift 1.08, 1.25 -> 0.57
#: mGal once the guard let it through (it was 0.5 until then); the realistic survey the guard is
#: for: 4.0-4.5 mGal of field, 2.7-3.6 of drift, ratios 1.2-1.5).
GUARD_FIELD_PER_DRIFT = 1.0
#: Prior width of the drift's sigma and correlation time (1-sigma factors of the log-normal).
PRIOR_SIGMA_FACTOR = 3.0
PRIOR_TAU_FACTOR = 10.0
#: Bounds of the fit (m/s^2, m, s): field 0.01-1000 mGal over 0.2-1000 km, drift 0.01-20 mGal
#: over 30 s - 1 day, white 0.01-50 mGal.
BOUNDS = {
    "field_sigma_mps2": (0.01 * MGAL, 1000.0 * MGAL),
    "field_length_m": (200.0, 1.0e6),
    "drift_sigma_mps2": (0.01 * MGAL, 20.0 * MGAL),
    "drift_tau_s": (30.0, 86400.0),
    "white_mps2": (0.01 * MGAL, 50.0 * MGAL),
}
_ORDER = tuple(BOUNDS)
#: Field correlation lengths (m) the fit starts from, with the datasheet drift (:func:`_fit`).
FIELD_LENGTH_STARTS_M = (2000.0, 5000.0, 20000.0, 100000.0, 400000.0)
#: A tare is taken off where the blocks need it at this log-likelihood ratio (the step over
#: none, the drift model refitted both ways; one free parameter besides the step's time, which
#: the scan picks among ~30-300 places): on 56 unseen flights without one (40 quick, 16 issue
#: B/C) the largest was 11.3, the next 9.0 (docs/benchmarks.md "A gravimeter tare").
TARE_MIN_LOG_LR = 12.0
#: No tare within this of the line blocks' first and last times, s: there one side of the step
#: has too few blocks to compare, and a flight's start and end carry the smoother's transients
#: (quick U016 without a tare: ratio 29 for a step 74 s into its first line, 6.6 at most beyond).
TARE_EDGE_S = 300.0
#: Most tares taken off one flight.
TARE_MAX = 3
#: Scan step of the tare's time, in blocks.
TARE_SCAN_PER_BLOCK = 3
#: Prior variance of the unknown constant, (m/s^2)^2 (100 mGal: any gravimeter bias).
CONSTANT_VAR = (100.0 * MGAL) ** 2
#: Epochs per piece of the posterior evaluation.
POSTERIOR_CHUNK = 4096
#: Field sigmas (multiples of the blocks' standard deviation) over which the drift's posterior
#: sigma is averaged (:func:`drift_posterior`): 1/64 to 4, in factors of 2.
FIELD_SIGMA_GRID = tuple(2.0**k for k in range(-6, 3))
#: Sigma of the drift in the null model (effectively none), m/s^2.
NO_DRIFT_MPS2 = 1e-3 * MGAL


@dataclass(frozen=True)
class DriftOptions:
    """Settings of the drift separation (config section ``drift``).

    Attributes
    ----------
    estimate : bool
        Separate the drift with the lines (default True).
    block_s : float
        Block length of the fit, s.
    sigma_mps2, tau_s : float
        Centre of the datasheet prior on the drift's Gauss-Markov sigma (m/s^2) and correlation
        time (s); also the datasheet drift taken off when the fitted one is not needed
        (:func:`datasheet_drift_fit`).
    field_filter : bool
        Where a drift is taken off, filter each line against what the lines left of it
        (:func:`field_filter`; default True).
    tares : bool
        Look for tares, steps in the gravimeter's reading, and take off those the lines need
        (:func:`find_tare`; default True).
    """

    estimate: bool = True
    block_s: float = BLOCK_S
    sigma_mps2: float = DRIFT_DEFAULT_SIGMA_MPS2
    tau_s: float = DRIFT_DEFAULT_TAU_S
    field_filter: bool = True
    tares: bool = True


@dataclass(frozen=True)
class DriftFit:
    """Hyperparameters of the field-plus-drift model and the fit's facts (SI)."""

    field_sigma_mps2: float
    field_length_m: float
    drift_sigma_mps2: float
    drift_tau_s: float
    white_mps2: float
    log_lr: float
    blocks: int
    lines: int
    #: Negative log-likelihood of the same blocks without drift (the test's reference).
    nll_without_drift: float = math.nan

    @property
    def vector(self) -> np.ndarray:
        """The hyperparameters in the fit's order (:data:`BOUNDS`)."""
        return np.array([getattr(self, k) for k in _ORDER])

    def report(self) -> dict:
        """summary.json facts: values in mGal, km and s."""
        return {
            "field_sigma_mgal": self.field_sigma_mps2 / MGAL,
            "field_length_km": self.field_length_m / 1000.0,
            "drift_sigma_mgal": self.drift_sigma_mps2 / MGAL,
            "drift_tau_s": self.drift_tau_s,
            "white_mgal": self.white_mps2 / MGAL,
            "log_likelihood_ratio": self.log_lr,
            "blocks": self.blocks,
            "lines": self.lines,
        }


def local_plane(lat, lon, radius_m: float = 6371000.0):
    """East and north (m) about the survey's centre, azimuthal equidistant on a sphere; shape (N,) each.

    The centre is the mean of the positions as unit vectors (for a flight over a pole, or across
    the antimeridian with its longitudes wrapped, a mean of longitudes puts it half a world
    away); distances and azimuths from it are true, so a line's neighbours stay at their true
    distances at any latitude (an equirectangular plane stretched east-west by
    ``cos(lat) / cos(lat0)``: over 30 % across 200 km at 85 deg).  Not
    :func:`gravsurvey.georef.project` (UTM): the fit is sensitive to a change of scale of a few
    1e-4 (U016 0.68 -> 0.72 mGal measured), and its results are stated with this plane.

    Parameters
    ----------
    lat, lon : ndarray, shape (N,)
        Geodetic latitude and longitude, rad; NaN where unknown.
    radius_m : float
        Sphere radius, m.

    Returns
    -------
    east, north : ndarray, shape (N,)
        m; NaN where the position is not finite.
    """
    import pyproj

    lat = np.asarray(lat, float)
    lon = np.asarray(lon, float)
    ok = np.isfinite(lat) & np.isfinite(lon)
    east, north = np.full(lat.shape, np.nan), np.full(lat.shape, np.nan)
    if not ok.any():
        return east, north
    cl = np.cos(lat[ok])
    u = np.array([np.mean(cl * np.cos(lon[ok])), np.mean(cl * np.sin(lon[ok])), np.mean(np.sin(lat[ok]))])
    lat0 = math.degrees(math.atan2(u[2], math.hypot(u[0], u[1])))
    lon0 = math.degrees(math.atan2(u[1], u[0]))
    plane = pyproj.Proj(proj="aeqd", lat_0=lat0, lon_0=lon0, R=float(radius_m))
    east[ok], north[ok] = plane(np.degrees(lon[ok]), np.degrees(lat[ok]))
    return east, north


def block_length(span_s: float, block_s: float = BLOCK_S) -> float:
    """The block length the stage averages a flight of ``span_s`` seconds in, s: ``block_s``, or
    longer where the flight would give more than :data:`MAX_BLOCKS` blocks (the dense fit's
    cost grows with their cube)."""
    return max(float(block_s), float(span_s) / MAX_BLOCKS)


def line_blocks(time, east, north, g, line_id, block_s: float = BLOCK_S):
    """Block averages of ``g`` over each line.

    Parameters
    ----------
    time, east, north, g : ndarray, shape (N,)
        s, m, m, m/s^2.
    line_id : ndarray, shape (N,)
        Line label of every epoch; ``""`` (or None) off the lines.

    Returns
    -------
    blocks : ndarray, shape (M, 4)
        Columns: mean time (s), east (m), north (m), g (m/s^2).
    lines : int
        Number of lines that gave a block.
    """
    time = np.asarray(time, float)
    lab = np.asarray([str(s) if s is not None else "" for s in line_id], dtype=object)
    ok = (lab != "") & np.isfinite(g) & np.isfinite(east) & np.isfinite(north)
    dt = float(np.median(np.diff(time))) if time.size > 1 else 1.0
    need = max(2, int(BLOCK_FILL * block_s / max(dt, 1e-9)))
    idx = np.floor((time - time[0]) / block_s).astype(np.int64)
    rows, used = [], set()
    # one block per (block index, line): sort by line then index and cut at changes
    keys = np.flatnonzero(ok)
    if keys.size == 0:
        return np.zeros((0, 4)), 0
    order = keys[np.lexsort((idx[keys], lab[keys].astype(str)))]
    k_lab, k_idx = lab[order].astype(str), idx[order]
    cut = np.flatnonzero((k_lab[1:] != k_lab[:-1]) | (k_idx[1:] != k_idx[:-1])) + 1
    for part in np.split(order, cut):
        if part.size < need:
            continue
        rows.append((time[part].mean(), east[part].mean(), north[part].mean(), float(np.mean(g[part]))))
        used.add(lab[part[0]])
    if not rows:
        return np.zeros((0, 4)), 0
    b = np.asarray(rows, float)
    return b[np.argsort(b[:, 0])], len(used)


def _block_geometry(blocks):
    """(values about their mean, distances m, time lags s) of the blocks, shapes (M,), (M, M), (M, M)."""
    b = np.asarray(blocks, float)
    y = b[:, 3] - b[:, 3].mean()
    dist = np.hypot(b[:, 1, None] - b[None, :, 1], b[:, 2, None] - b[None, :, 2])
    lag = np.abs(b[:, 0, None] - b[None, :, 0])
    return y, dist, lag


def matern32(r, length):
    """Matern-3/2 correlation ``(1 + s) exp(-s)``, ``s = sqrt(3) r / length`` (r >= 0, m)."""
    s = math.sqrt(3.0) * r / length
    return (1.0 + s) * np.exp(-s)


def exponential(r, length):
    """Exponential (first-order Gauss-Markov) correlation ``exp(-r / length)`` (r >= 0)."""
    return np.exp(-r / length)


#: The field's correlation functions: the model's (Matern-3/2, smooth as a potential field at
#: flight height) and the rough one a drift must also be needed under (:func:`separate_drift`).
FIELD_KERNELS = {"matern32": matern32, "exponential": exponential}


def _assembled(v, k_f, k_d=None):
    """The blocks' covariance under the hyperparameters ``v`` (:data:`BOUNDS` order) from the
    field's correlation matrix ``k_f`` and the drift's ``k_d`` (None: no drift), (M, M): the
    one place the model's terms are added up (:func:`_covariance`, :func:`_nll_and_gradient`)."""
    s_f, _, s_d, _, w = v
    k = s_f**2 * k_f + CONSTANT_VAR
    if k_d is not None:
        k = k + s_d**2 * k_d
    k[np.diag_indices_from(k)] += w**2
    return k


def _covariance(v, dist, lag, drift=True, kernel="matern32"):
    length, tau = v[1], v[3]
    return _assembled(v, FIELD_KERNELS[kernel](dist, length), np.exp(-lag / tau) if drift else None)


def _gaussian_nll(y, alpha, chol) -> float:
    """Negative log-likelihood (constant dropped) of ``y`` under ``K = L L^T``, from ``alpha =
    K^-1 y`` and the factor ``chol`` (its diagonal is ``L``'s)."""
    return 0.5 * float(y @ alpha) + float(np.sum(np.log(np.diag(chol))))


def _neg_log_likelihood(v, dist, lag, y, kernel="matern32"):
    """Gaussian negative log-likelihood (constant dropped), +inf where not positive definite."""
    from scipy.linalg import LinAlgError, cho_factor, cho_solve

    try:
        c = cho_factor(_covariance(v, dist, lag, kernel=kernel), lower=True, check_finite=False)
    except LinAlgError:
        return math.inf
    return _gaussian_nll(y, cho_solve(c, y, check_finite=False), c[0])


def _length_derivative(kernel, r, length):
    """``length * d(correlation)/d(length)`` of the field kernel ``kernel`` at distances ``r``
    (m), beside the correlation itself: the derivative in the log of the length."""
    if kernel == "matern32":
        s = math.sqrt(3.0) * r / length
        e = np.exp(-s)
        return (1.0 + s) * e, s * s * e
    if kernel == "exponential":
        s = r / length
        e = np.exp(-s)
        return e, s * e
    raise ValueError(f"unknown field kernel {kernel!r}; expected one of {sorted(FIELD_KERNELS)}")


def _nll_and_gradient(v, dist, lag, y, kernel="matern32"):
    """:func:`_neg_log_likelihood` and its gradient in the logs of ``v`` (:data:`BOUNDS` order).

    ``d nll / d theta = tr((K^-1 - a a^T) dK / d theta) / 2`` with ``a = K^-1 y``: one
    factorisation for the value and all five derivatives, where finite differences take six.
    (+inf, zeros) where the covariance is not positive definite.

    Returns
    -------
    nll : float
    gradient : ndarray, shape (5,)
    """
    from scipy.linalg import LinAlgError, cho_factor, cho_solve

    s_f, length, s_d, tau, w = v
    k_f, dk_f = _length_derivative(kernel, dist, length)
    k_d = np.exp(-lag / tau)
    k = _assembled(v, k_f, k_d)
    try:
        c = cho_factor(k, lower=True, check_finite=False)
    except LinAlgError:
        return math.inf, np.zeros(5)
    alpha = cho_solve(c, y, check_finite=False)
    inner = cho_solve(c, np.eye(y.size), check_finite=False)
    inner -= np.outer(alpha, alpha)
    grad = 0.5 * np.array(
        [
            2.0 * s_f**2 * np.vdot(inner, k_f),
            s_f**2 * np.vdot(inner, dk_f),
            2.0 * s_d**2 * np.vdot(inner, k_d),
            s_d**2 * np.vdot(inner, k_d * (lag / tau)),
            2.0 * w**2 * np.trace(inner),
        ]
    )
    return _gaussian_nll(y, alpha, c[0]), grad


def _prior_penalty(v, options: DriftOptions) -> float:
    return (
        0.5 * (math.log(v[2] / options.sigma_mps2) / math.log(PRIOR_SIGMA_FACTOR)) ** 2
        + 0.5 * (math.log(v[3] / options.tau_s) / math.log(PRIOR_TAU_FACTOR)) ** 2
    )


def _prior_penalty_gradient(v, options: DriftOptions) -> np.ndarray:
    """Gradient of :func:`_prior_penalty` in the logs of ``v``, shape (5,)."""
    grad = np.zeros(5)
    grad[2] = math.log(v[2] / options.sigma_mps2) / math.log(PRIOR_SIGMA_FACTOR) ** 2
    grad[3] = math.log(v[3] / options.tau_s) / math.log(PRIOR_TAU_FACTOR) ** 2
    return grad


def _fit(
    y,
    dist,
    lag,
    options: DriftOptions,
    with_drift: bool,
    datasheet: bool = False,
    kernel: str = "matern32",
    starts=None,
):
    """Best (negative log-likelihood without prior, parameters) over several starts.

    ``with_drift`` False: no drift (its sigma held at :data:`NO_DRIFT_MPS2`); ``datasheet``:
    the drift held at the datasheet's sigma and correlation time (``options``), the field and
    the white term fitted.  ``starts``: the starting hyperparameters (:data:`BOUNDS` order) in
    place of the default ones.
    """
    from scipy.optimize import minimize

    lo = np.log([BOUNDS[k][0] for k in _ORDER])
    hi = np.log([BOUNDS[k][1] for k in _ORDER])
    scale = max(float(np.std(y)), BOUNDS["field_sigma_mps2"][0])
    # the likelihood has separate optima along the field's length (a short field with a large
    # drift, a long one with a small drift): one start per decade or so of length, so that the
    # best is found whatever the blocks' geometry (with three starts a change of scale of 1e-3
    # moved the fit between optima 1.0 and 2.5 log-likelihood apart on quick U217 and U004)
    if starts is None:
        starts = [(scale, length, options.sigma_mps2, options.tau_s, 0.3 * MGAL) for length in FIELD_LENGTH_STARTS_M]
        starts += [
            (scale, 20000.0, 0.3 * options.sigma_mps2, 3.0 * options.tau_s, 0.3 * MGAL),
            (scale, 2000.0, 2.0 * options.sigma_mps2, options.tau_s / 3.0, 0.3 * MGAL),
        ]
    if not with_drift:
        lo[2] = hi[2] = math.log(NO_DRIFT_MPS2)
    elif datasheet:
        lo[2] = hi[2] = math.log(options.sigma_mps2)
        lo[3] = hi[3] = math.log(options.tau_s)

    def objective(u):
        v = np.exp(u)
        f, grad = _nll_and_gradient(v, dist, lag, y, kernel)
        if with_drift and not datasheet:
            f += _prior_penalty(v, options)
            grad += _prior_penalty_gradient(v, options)
        return f, grad

    best = None
    # BLAS on one thread, as in the pipeline: a notebook's multi-threaded OpenBLAS spent more on
    # waking its threads than on the work (150 blocks: 3.3 s a fit against 0.34 s)
    with single_threaded_blas():
        for s in starts:
            u0 = np.clip(np.log(s), lo, hi)
            r = minimize(objective, u0, jac=True, method="L-BFGS-B", bounds=list(zip(lo, hi)))
            if np.isfinite(r.fun) and (best is None or r.fun < best.fun):
                best = r
    if best is None:
        return math.inf, None
    v = np.exp(best.x)
    return _neg_log_likelihood(v, dist, lag, y, kernel), v


def fit_drift(blocks, lines: int, options: DriftOptions = DriftOptions(), kernel: str = "matern32"):
    """Fit the field-plus-drift model to block averages (:func:`line_blocks`).

    ``kernel``: the field's correlation function (:data:`FIELD_KERNELS`).

    Returns
    -------
    DriftFit or None
        None when there are fewer than :data:`MIN_BLOCKS` blocks or lines < 2.
    """
    return _fit_against_no_drift(blocks, lines, options, datasheet=False, kernel=kernel)


def datasheet_drift_fit(blocks, lines: int, options: DriftOptions = DriftOptions(), nll_without_drift=None):
    """The field fitted under the datasheet's drift (its sigma and correlation time held).

    Parameters
    ----------
    blocks : ndarray, shape (M, 4)
        :func:`line_blocks`.
    lines : int
    options : DriftOptions
        ``sigma_mps2`` and ``tau_s`` are the datasheet drift.
    nll_without_drift : float, optional
        The no-drift model's negative log-likelihood of the same blocks, when already fitted
        (:attr:`DriftFit.nll_without_drift`).

    Returns
    -------
    DriftFit or None
        ``log_lr`` is that of the datasheet drift over no drift (both models fit the same
        three parameters: a Bayes factor); None when the blocks are too few or the fit fails.
    """
    return _fit_against_no_drift(blocks, lines, options, datasheet=True, nll_without_drift=nll_without_drift)


def _fit_against_no_drift(blocks, lines, options, datasheet, nll_without_drift=None, kernel="matern32", fitted=None):
    """:class:`DriftFit` of the model with drift (fitted, or held at the datasheet's) and its
    log-likelihood ratio over the same model without drift (fitted here unless given).
    ``fitted``: the model with drift's ``_fit`` of these blocks, when already made."""
    b = np.asarray(blocks, float)
    if b.shape[0] < MIN_BLOCKS or lines < 2:
        return None
    y, dist, lag = _block_geometry(b)
    nll1, v1 = fitted if fitted is not None else _fit(y, dist, lag, options, True, datasheet=datasheet, kernel=kernel)
    if v1 is None:
        return None
    nll0 = nll_without_drift
    if nll0 is None or not math.isfinite(nll0):
        nll0, _ = _fit(y, dist, lag, options, False, kernel=kernel)
    return DriftFit(
        *(float(x) for x in v1),
        log_lr=float(nll0 - nll1),
        blocks=int(b.shape[0]),
        lines=int(lines),
        nll_without_drift=float(nll0),
    )


def _posterior_at(v, b, y, dist, lag, *times):
    """Under the hyperparameters ``v`` (:data:`BOUNDS` order): the blocks' negative
    log-likelihood (:func:`_neg_log_likelihood`, from the same factorisation), the drift's
    posterior variance about the flight mean at the blocks, then its posterior mean at each
    array of ``times`` (s); None where ``v`` is not positive definite."""
    try:
        chol = np.linalg.cholesky(_covariance(v, dist, lag))
    except np.linalg.LinAlgError:
        return None
    s_d, tau = v[2], v[3]
    alpha = np.linalg.solve(chol.T, np.linalg.solve(chol, y))
    nll = _gaussian_nll(y, alpha, chol)
    means = []
    for t in times:
        mean = np.empty(t.size)
        # in chunks: an (epochs x blocks) matrix of a 10-h flight would take 100s of MB
        for a in range(0, t.size, POSTERIOR_CHUNK):
            dt = np.abs(t[a : a + POSTERIOR_CHUNK, None] - b[None, :, 0])
            mean[a : a + POSTERIOR_CHUNK] = (s_d**2 * np.exp(-dt / tau)) @ alpha
        means.append(mean)
    # posterior covariance of the drift at the blocks, then of its deviation from its mean
    k_bb = s_d**2 * np.exp(-lag / tau)
    w = np.linalg.solve(chol, k_bb)
    post = k_bb - w.T @ w
    m = post.shape[0]
    centre = np.eye(m) - 1.0 / m
    return (nll, np.clip(np.diag(centre @ post @ centre), 0.0, None), *means)


def log_likelihood(fit: DriftFit, blocks) -> float:
    """The blocks' Gaussian log-likelihood (constant dropped) under the hyperparameters of
    ``fit`` (Matern-3/2 field), -inf where their covariance is not positive definite.

    Comparable with a fit's own: :func:`fit_drift`'s optimum has ``-(nll_without_drift -
    log_lr)``, so hyperparameters from elsewhere (a flight's drawn drift, the field's fit to
    the truth alone) can be weighed against what the blocks choose
    (``benchmarks/bench_drift_lines.py``).

    Parameters
    ----------
    fit : DriftFit
        Only its hyperparameters are read (:attr:`DriftFit.vector`).
    blocks : ndarray, shape (M, 4)
        :func:`line_blocks`.
    """
    y, dist, lag = _block_geometry(np.asarray(blocks, float))
    return -_neg_log_likelihood(fit.vector, dist, lag, y)


def drift_posterior(fit: DriftFit, blocks, time, field_sigmas=FIELD_SIGMA_GRID):
    """Posterior mean and sigma of the drift at ``time`` (s), m/s^2, shape (N,) each.

    The mean is the fit's.  The sigma leaves out the part common to the whole flight (the
    constant absorbs it, as the gravimeter bias; the product's sigma is of the error about its
    mean) and holds what the blocks leave open of the field's size: it is the posterior's
    spread averaged over field sigmas ``field_sigmas`` x the blocks' standard deviation (and the
    fit's own), each weighed by its likelihood with the other hyperparameters held, about the
    fit's mean.  Where the likelihood is flat in the field's sigma (few lines: a field of 0.01
    or 0.9 mGal explains the blocks as well, and the drift with it) the fit's own posterior
    claims a certainty the data do not give (docs/method.md, "Drift from the lines").
    ``field_sigmas`` empty: the fit's own posterior alone.
    """
    b = np.asarray(blocks, float)
    y, dist, lag = _block_geometry(b)
    t = np.asarray(time, float)
    # the average is taken at the blocks' times and interpolated, as the variance itself is:
    # the drift is smooth over a block, and the epochs would cost a posterior mean each
    tb = b[:, 0]
    v0 = fit.vector
    own = _posterior_at(v0, b, y, dist, lag, tb, t)
    if own is None:  # a fitted model's covariance is positive definite: its likelihood was finite
        raise np.linalg.LinAlgError("drift model covariance not positive definite")
    nll0, var_b, own_b, mean = own
    lo, hi = BOUNDS["field_sigma_mps2"]
    candidates = [(nll0, var_b, own_b)]
    for k in np.asarray(field_sigmas, float) * max(float(np.std(y)), lo):
        v = v0.copy()
        v[0] = min(max(k, lo), hi)
        post = _posterior_at(v, b, y, dist, lag, tb)
        if post is not None:
            candidates.append(post)
    best = min(c[0] for c in candidates)
    total, acc = 0.0, np.zeros_like(tb)
    for nll, var_i, m_i in candidates:
        w = math.exp(-(nll - best))
        gap = m_i - own_b
        acc += w * (var_i + (gap - gap.mean()) ** 2)
        total += w
    return mean, np.sqrt(np.interp(t, tb, acc / total))


@dataclass(frozen=True)
class Tare:
    """A step in the gravimeter's reading found by the lines (:func:`find_tare`), SI."""

    #: When, s (the time base of the blocks).
    time_s: float
    #: The step, m/s^2 (the reading after less before).
    step_mps2: float
    #: Its 1-sigma, m/s^2.
    sigma_mps2: float
    #: Log-likelihood ratio of the blocks with the step over without (the drift model refitted).
    log_lr: float

    def report(self) -> dict:
        """summary.json facts: mGal and s."""
        return {
            "time_s": self.time_s,
            "step_mgal": self.step_mps2 / MGAL,
            "sigma_mgal": self.sigma_mps2 / MGAL,
            "log_likelihood_ratio": self.log_lr,
        }


def step_response(gain, dt_s: float, span_s: float):
    """The estimate's response to a unit step of the gravimeter at lag 0, as a function of lag.

    A step in the reading reaches the smoothed estimate as a step of the field would: through the
    smoother's zero-phase transfer ``gain`` (its steady state, :func:`gravsurvey.inm.identify.smoother_gain`),
    a ramp centred on the step over about the estimate's resolution.

    Parameters
    ----------
    gain : callable
        ``gain(freq_hz)`` -> real transfer in [0, 1], shape of ``freq_hz``.
    dt_s : float
        The estimate's epoch spacing, s.
    span_s : float
        The record's length, s (the response is computed over four times it).

    Returns
    -------
    callable
        ``r(lag_s)`` -> response, 0 long before the step, 1 long after, ndarray of ``lag_s``'s shape.
    """
    dt = float(dt_s)
    n = int(2 ** math.ceil(math.log2(max(4.0 * float(span_s) / dt, 16.0))))
    h = np.roll(np.fft.irfft(np.asarray(gain(np.fft.rfftfreq(n, dt)), float), n), n // 2)
    s = np.cumsum(h)
    s = s / s[-1] if s[-1] != 0.0 else s
    lags = (np.arange(n) - n // 2) * dt

    def response(lag_s):
        return np.interp(np.asarray(lag_s, float), lags, s, left=0.0, right=1.0)

    return response


def _step_at_blocks(blocks, response, t0: float, block_s: float) -> np.ndarray:
    """The step response at ``t0`` averaged over each block's span (9 points), about its mean, (M,)."""
    offsets = np.linspace(-0.5 * block_s, 0.5 * block_s, 9)
    h = np.mean(response(blocks[:, 0, None] + offsets[None, :] - t0), axis=1)
    return h - h.mean()


def find_tare(blocks, options: DriftOptions, response, block_s: float = BLOCK_S, fitted=None):
    """The tare (a step in the gravimeter's reading) the blocks show best, or None.

    Every time on a grid (:data:`TARE_SCAN_PER_BLOCK` per block, :data:`TARE_EDGE_S` in from the
    first and last block) is scored by the step's generalised-least-squares log-likelihood
    ratio under the field-plus-drift model fitted without a step; at the best, the step is
    estimated with the drift model refitted to the blocks less it (twice), and the ratio is that
    of the refitted models with and without it.  Without the step the drift model grows to
    follow it, and the first score stays low (a 10-mGal tare: 31 after the refit, under 5
    before), so the refit, not the first score, is the test (:data:`TARE_MIN_LOG_LR`).

    Parameters
    ----------
    blocks : ndarray, shape (M, 4)
        :func:`line_blocks`.
    options : DriftOptions
        The drift prior.
    response : callable
        :func:`step_response` of the estimate the blocks average.
    block_s : float
        The blocks' length, s.
    fitted : tuple, optional
        The field-plus-drift model's fit to these blocks without a step (negative
        log-likelihood, hyperparameters), when already made.

    Returns
    -------
    Tare or None
        None when the blocks are too few or too short for a scan.
    """
    b = np.asarray(blocks, float)
    if b.shape[0] < MIN_BLOCKS:
        return None
    y, dist, lag = _block_geometry(b)
    nll0, v0 = fitted if fitted is not None else _fit(y, dist, lag, options, True)
    if v0 is None:
        return None
    inv = np.linalg.inv(_covariance(v0, dist, lag))
    tb = b[:, 0]
    best = None
    for t0 in np.arange(tb[0] + TARE_EDGE_S, tb[-1] - TARE_EDGE_S, block_s / TARE_SCAN_PER_BLOCK):
        h = _step_at_blocks(b, response, float(t0), block_s)
        a, c = float(h @ inv @ y), float(h @ inv @ h)
        if c > 0.0 and (best is None or 0.5 * a * a / c > best[0]):
            best = (0.5 * a * a / c, float(t0), a / c, h)
    if best is None:
        return None
    _, t0, beta, h = best
    # refitted from the fit without the step, and from its field with the datasheet's drift (the
    # size the drift returns to once the step is off)
    starts = [tuple(v0), (v0[0], v0[1], options.sigma_mps2, options.tau_s, v0[4])]
    for _ in range(2):
        _, v1 = _fit(y - beta * h, dist, lag, options, True, starts=starts)
        if v1 is None:
            return None
        inv = np.linalg.inv(_covariance(v1, dist, lag))
        c = float(h @ inv @ h)
        beta = float(h @ inv @ y) / c
    nll1 = _neg_log_likelihood(v1, dist, lag, y - beta * h)
    return Tare(time_s=t0, step_mps2=beta, sigma_mps2=1.0 / math.sqrt(c), log_lr=float(nll0 - nll1))


def passed_drift_factor(report: dict, options: DriftOptions = DriftOptions()) -> float:
    """Factor on the datasheet drift that the stated sigma holds where no drift is taken off.

    A flight whose drift is not used keeps, in its sigma, the datasheet drift the smoother
    passes (:func:`gravsurvey.inm.identify.drift_sigma_passed`, proportional to the drift's
    sigma).  Where the lines set a drift of the datasheet's size aside (:func:`separate_drift`:
    its log-likelihood ratio over no drift under :data:`DATASHEET_MIN_LOG_LR`), they speak for
    a smaller one: the factor is then the fitted drift sigma over the datasheet's (at most 1);
    1 otherwise.  The same holds for the share of no drift where the fitted drift is taken with
    a weight and the rest goes to none (the report's ``rest_to`` ``"none"``).

    Parameters
    ----------
    report : dict
        :func:`separate_drift`'s report.
    options : DriftOptions
        ``sigma_mps2``: the datasheet drift sigma.

    Returns
    -------
    float
        In (0, 1].
    """
    ds = report.get("datasheet_log_likelihood_ratio")
    fitted = report.get("drift_sigma_mgal")
    if (
        (report.get("used") and report.get("rest_to") != "none")
        or ds is None
        or fitted is None
        or not ds < DATASHEET_MIN_LOG_LR
    ):
        return 1.0
    return float(min(1.0, max(float(fitted) * MGAL / options.sigma_mps2, 1e-3)))


def separate_drift(
    time, lat, lon, g, line_id, options: DriftOptions = DriftOptions(), resolution_m: float = 0.0, response=None
):
    """The gravimeter drift of one flight, estimated from its lines.

    Parameters
    ----------
    time : ndarray, shape (N,)
        s.
    lat, lon : ndarray, shape (N,)
        rad.
    g : ndarray, shape (N,)
        Smoothed disturbance estimate, m/s^2.
    line_id : ndarray, shape (N,)
        Line label per epoch, ``""`` off the lines.
    options : DriftOptions
    resolution_m : float
        Half-wavelength resolution of ``g`` along the track, m (0: unknown). The drift is not
        used when the fitted field correlation length is below :data:`MIN_LENGTH_PER_RESOLUTION`
        times it: the estimate then smooths the field along the lines only, an anisotropy the
        isotropic field model reads as drift.
    response : callable, optional
        :func:`step_response` of ``g``: given (and ``options.tares``), the lines are searched for
        tares (:func:`find_tare`, up to :data:`TARE_MAX`), and those the blocks need
        (:data:`TARE_MIN_LOG_LR`) are taken off before the drift is fitted and returned with it.

    Returns
    -------
    drift : ndarray, shape (N,) or None
        Drift to take off ``g``, m/s^2, the tares' steps included (None when neither the drift
        nor a tare is taken off).
    sigma : ndarray, shape (N,) or None
        Its posterior 1-sigma about the flight mean, m/s^2 (the tares' alone where the drift is
        not used).
    report : dict
        ``used`` (bool); ``model`` when used: ``"fitted"`` (the larger weight, or the datasheet
        drift set aside; its fitted sigma and correlation time) or ``"datasheet"`` (the test
        does not need the fitted drift, and the blocks do not speak against the datasheet's; its
        ``reason`` says so), ``fitted_weight`` and ``rest_to`` (``"datasheet"`` or ``"none"``:
        where the rest of the weight went; with ``"none"`` below the test's threshold a
        ``reason`` says so); ``reason`` when not used; the fit's facts (:meth:`DriftFit.report`,
        those of the model used) and ``datasheet_log_likelihood_ratio`` when the datasheet model
        was fitted;
        ``rough_field_log_likelihood_ratio`` where the fitted drift's ratio is at least
        :data:`ROUGH_CHECK_MIN_LOG_LR`: the same fit under an exponential field, whose ratio,
        where smaller, is the one tested and weighed; ``tares`` when any was taken off
        (:meth:`Tare.report` each, ``used`` then still says whether the drift was).
    """

    def not_used(reason, **facts):
        return None, None, {"used": False, "reason": reason, **facts}

    if not options.estimate:
        return not_used("drift.estimate is false")
    time = np.asarray(time, float)
    if not (np.isfinite(lat) & np.isfinite(lon)).any():
        return not_used("no finite position")
    east, north = local_plane(lat, lon)
    block = block_length(float(time[-1] - time[0]) if time.size else 0.0, options.block_s)
    g = np.asarray(g, float)
    blocks, lines = line_blocks(time, east, north, g, line_id, block)
    tares, steps, step_var = [], np.zeros(time.size), np.zeros(time.size)
    # the drift model's fit to the blocks as they stand, made for the search and kept for the drift
    fitted = None
    if options.tares and response is not None and lines >= 2 and blocks.shape[0] >= MIN_BLOCKS:
        on = np.asarray([str(x) if x is not None else "" for x in line_id], dtype=object) != ""
        while len(tares) < TARE_MAX:
            y, dist, lag = _block_geometry(blocks)
            fitted = _fit(y, dist, lag, options, True)
            tare = find_tare(blocks, options, response, block, fitted)
            if tare is None or tare.log_lr < TARE_MIN_LOG_LR:
                break
            tares.append(tare)
            r = response(time - tare.time_s)
            steps += tare.step_mps2 * r
            # the step's error about the flight mean (the constant absorbs a common offset)
            step_var += (tare.sigma_mps2 * (r - np.mean(r[on]))) ** 2
            blocks, lines = line_blocks(time, east, north, g - steps, line_id, block)
            fitted = None
    mean, sigma, report = _drift_of_blocks(blocks, lines, block, time, options, resolution_m, fitted)
    if not tares:
        return mean, sigma, report
    report = {**report, "tares": [t.report() for t in tares]}
    if mean is None:
        return steps, np.sqrt(step_var), report
    return mean + steps, np.sqrt(sigma**2 + step_var), report


def _drift_of_blocks(blocks, lines, block, time, options, resolution_m, fitted=None):
    """:func:`separate_drift`'s drift from the blocks (the tares taken off them): (mean, sigma,
    report) at ``time``; ``fitted``: the drift model's fit to these blocks, when already made."""

    def not_used(reason, **facts):
        return None, None, {"used": False, "reason": reason, **facts}

    if lines < 2:
        return not_used(f"{lines} line(s): the drift needs two or more")
    if blocks.shape[0] < MIN_BLOCKS:
        return not_used(f"{blocks.shape[0]} blocks of {block:g} s, fewer than {MIN_BLOCKS}")
    fit = _fit_against_no_drift(blocks, lines, options, datasheet=False, fitted=fitted)
    if fit is None:
        return not_used("the fit failed")
    ds = datasheet_drift_fit(blocks, lines, options, fit.nll_without_drift)
    fit = _nested_refit(fit, ds, blocks, options)
    rep = {**fit.report(), "block_s": block}
    field_can_pose = fit.field_sigma_mps2 >= GUARD_FIELD_PER_DRIFT * fit.drift_sigma_mps2
    guard = resolution_m > 0 and fit.field_length_m < MIN_LENGTH_PER_RESOLUTION * resolution_m and field_can_pose
    if guard:
        # the datasheet drift too would be read into the field's along-line smoothing
        # (configs/realistic_survey.yaml: 3.06 -> 3.21 mGal with it): left as it is
        return not_used(
            f"the field's correlation length ({fit.field_length_m / 1000:.1f} km) is under "
            f"{MIN_LENGTH_PER_RESOLUTION:g}x the estimate's resolution ({resolution_m / 1000:.1f} km): "
            "the lines cannot tell the drift from the field the estimate smooths along them",
            **rep,
        )

    ds_ok = ds is not None and ds.log_lr >= DATASHEET_MIN_LOG_LR
    # the fitted drift must be needed under a rough field as well: a field rougher than the
    # smooth model allows (several source depths, lines a few km apart) differs between lines
    # in a way the smooth model can only call drift (quick U221: a 6.7 mGal drift under a 123
    # mGal field, log-likelihood ratio 5.3, 0.02 with the rough field)
    log_lr = fit.log_lr
    # the test statistics beside the model's facts, in every report
    tests = {} if ds is None else {"datasheet_log_likelihood_ratio": ds.log_lr}
    if log_lr >= ROUGH_CHECK_MIN_LOG_LR:
        rough = fit_drift(blocks, lines, options, kernel="exponential")
        if rough is not None:
            tests["rough_field_log_likelihood_ratio"] = rough.log_lr
            log_lr = min(log_lr, rough.log_lr)
    shown = f"{fit.log_lr:.1f}" + (f", under a rough field {log_lr:.1f}" if log_lr < fit.log_lr else "")
    reason = f"the lines do not show a drift beyond the datasheet's (log-likelihood ratio {shown} < {MIN_LOG_LR:g})"
    w = fitted_weight(log_lr)
    # where the blocks set the datasheet drift aside, the reason says so
    nor = (
        f"; nor a drift of the datasheet's size (log-likelihood ratio {ds.log_lr:.1f} < {DATASHEET_MIN_LOG_LR:g})"
        if ds is not None and not ds_ok
        else ""
    )
    # with the datasheet drift set aside the fitted one is weighed against none, below the
    # test's threshold too (quick U2012: ratio 2.7, 0.80 -> 0.58 mGal; U2731: 2.3, 0.46 -> 0.31),
    # unless it is hardly more likely than none
    if log_lr < MIN_LOG_LR and not ds_ok and w < MIN_FITTED_WEIGHT_ALONE:
        return not_used(reason + nor, **rep, **tests)
    # the two models of the drift weighed by the data rather than chosen at the test's
    # threshold: the fitted drift's weight is even at MIN_LOG_LR (its two free parameters'
    # price) and grows with the evidence; the other is the datasheet drift, or none where the
    # blocks set that aside (``rest_to``).  Near the threshold a hard choice takes the wrong
    # one whole (docs/benchmarks.md, "Weighing the fitted and the datasheet drift")
    mean_f, sigma_f = drift_posterior(fit, blocks, time)
    if ds_ok:
        mean_d, sigma_d = drift_posterior(ds, blocks, time)
    else:
        mean_d, sigma_d = np.zeros_like(mean_f), np.zeros_like(sigma_f)
    mean = w * mean_f + (1.0 - w) * mean_d
    # the mixture's variance: each model's posterior plus its spread about the average
    # (about the flight mean, as the posteriors: the constant absorbs a common offset)
    gap = mean_f - mean_d
    gap = gap - gap.mean()
    sigma = np.sqrt(w * sigma_f**2 + (1.0 - w) * sigma_d**2 + w * (1.0 - w) * gap**2)
    if w >= 0.5 or not ds_ok:
        model, facts = "fitted", rep
    else:
        model = "datasheet"
        facts = {"reason": reason, **ds.report(), "log_likelihood_ratio": fit.log_lr, "block_s": block}
    rest_to = "datasheet" if ds_ok else "none"
    if not ds_ok and log_lr < MIN_LOG_LR:
        facts = {
            "reason": f"{reason}{nor}: the fitted drift is taken with its weight {w:.2f}, none with the rest",
            **facts,
        }
    report = {"used": True, "model": model, **facts, **tests, "fitted_weight": w, "rest_to": rest_to}
    return mean, sigma, {**report, "drift_rms_mgal": float(np.std(mean) / MGAL)}


def _nested_refit(fit: DriftFit, datasheet: DriftFit | None, blocks, options: DriftOptions) -> DriftFit:
    """The fitted drift refitted from the datasheet fit's optimum where that is the better
    point of the fitted model's own objective, else ``fit``.

    The datasheet model is the fitted one with the drift held at the prior's centre (where the
    prior costs nothing), so the fitted model's best is at least as likely; a start that ends
    on a worse optimum along the field's length would understate the drift's evidence (quick
    U1435: ratio 0.06 against the datasheet's 0.61).
    """
    if datasheet is None:
        return fit
    own = fit.nll_without_drift - fit.log_lr + _prior_penalty(fit.vector, options)
    nested = datasheet.nll_without_drift - datasheet.log_lr + _prior_penalty(datasheet.vector, options)
    if not nested < own:
        return fit
    y, dist, lag = _block_geometry(np.asarray(blocks, float))
    refit = _fit(y, dist, lag, options, True, starts=[tuple(datasheet.vector)])
    better = _fit_against_no_drift(blocks, fit.lines, options, False, fit.nll_without_drift, fitted=refit)
    if better is None or not refit[0] + _prior_penalty(refit[1], options) < own:
        return fit
    return better


def fitted_weight(log_lr: float) -> float:
    """Weight of the fitted drift against the datasheet's (or none), from its test statistic.

    ``1 / (1 + exp(-(log_lr - MIN_LOG_LR)))``: one half at the test's threshold, the posterior
    probability of the fitted model when :data:`MIN_LOG_LR` is the log prior odds against its
    two extra free parameters.
    """
    return 1.0 / (1.0 + math.exp(-(float(log_lr) - MIN_LOG_LR)))


def track_psd_matern32(freq_hz, sigma, length_m, speed_mps):
    """Two-sided PSD along a straight track of an isotropic Matern-3/2 field, (m/s^2)^2/Hz.

    The field's covariance along the track, flown at ``speed_mps``, is ``sigma^2 (1 + a |t|)
    exp(-a |t|)`` with ``a = sqrt(3) v / L``; its spectrum ``4 sigma^2 a^3 / (a^2 + w^2)^2``,
    ``w = 2 pi f``, integrates to ``sigma^2`` over all frequencies.

    Parameters
    ----------
    freq_hz : ndarray
    sigma : float
        Field sigma, m/s^2.
    length_m : float
        Correlation length ``L``, m.
    speed_mps : float
    """
    a = math.sqrt(3.0) * float(speed_mps) / float(length_m)
    w = 2.0 * math.pi * np.asarray(freq_hz, float)
    return 4.0 * float(sigma) ** 2 * a**3 / (a**2 + w**2) ** 2


def field_filter_gain(freq_hz, field_sigma, field_length_m, speed_mps, residual_sigma, tau_s):
    """Gain ``S_F / (S_F + S_R)`` of :func:`field_filter` at ``freq_hz``: the field of the drift
    fit along the track (:func:`track_psd_matern32`) against the drift the lines left
    (:func:`gravsurvey.inm.identify.markov_psd` of its posterior sigma and the fit's correlation time)."""
    s_f = track_psd_matern32(freq_hz, field_sigma, field_length_m, speed_mps)
    s_r = markov_psd(freq_hz, residual_sigma, tau_s)
    return s_f / (s_f + s_r)


def field_filter_applies(fit_report: dict, line_length_m: float) -> bool:
    """Whether :func:`field_filter` may use the drift fit's field on a line: the fit holds a field
    and a drift, and the field's correlation length is at most the line's length (a longer one
    is not measured by the lines - it sits at its fit's bound where the lines are short - and
    its spectrum would cut what they do show: U303 of the held-out draws, 28-km lines and a
    fitted 934 km, 0.37 -> 0.51 mGal)."""
    need = ("field_sigma_mgal", "field_length_km", "drift_tau_s")
    if not fit_report.get("used") or any(not fit_report.get(k) for k in need):
        return False
    return float(fit_report["field_length_km"]) * 1000.0 <= float(line_length_m)


def field_filter(g, dt_s, speed_mps, field_sigma, field_length_m, residual_sigma, tau_s):
    """One line's estimate, the drift taken off, Wiener-filtered against what the lines left of
    the drift.

    After the drift stage the estimate holds the field plus the drift's residual, whose size is
    the posterior sigma and whose spectrum is the drift's (what changes within a block the
    lines cannot tell from the field at all).  Where that residual is strong against the field
    the drift fit found (weak fields, fast drifts), the smoother's resolution - chosen on a
    first pass that counts the drift as field - passes it; this filter takes it down as far as
    the two spectra say, and leaves a strong field as it is (gain near 1).

    Parameters
    ----------
    g : ndarray, shape (N,)
        The line's estimate, m/s^2, at a constant spacing ``dt_s`` (s).
    speed_mps : float
    field_sigma, field_length_m : float
        The drift fit's field (m/s^2, m).
    residual_sigma : float
        The drift's posterior 1-sigma on the line, m/s^2.
    tau_s : float
        The drift's correlation time, s.

    Returns
    -------
    filtered : ndarray, shape (N,)
        Same mean as ``g``.
    error_sigma : float
        Expected 1-sigma of the filtered line's error from the field and the residual,
        ``sqrt(int S_F S_R / (S_F + S_R) df)``, m/s^2 (at most ``residual_sigma``: it takes the
        residual's place in the stated sigma).
    """
    g = np.asarray(g, float)
    n = g.size
    if n < 2 or residual_sigma <= 0.0:
        return g.copy(), float(max(residual_sigma, 0.0))
    # the line mirrored: an even extension has no jump at the ends for the filter to smear
    m = 2 * n
    f = np.fft.rfftfreq(m, dt_s)
    gain = field_filter_gain(f, field_sigma, field_length_m, speed_mps, residual_sigma, tau_s)
    mean = float(np.mean(g))
    x = np.concatenate([g - mean, (g - mean)[::-1]])
    filtered = np.fft.irfft(np.fft.rfft(x) * gain, m)[:n] + mean
    # the Wiener error over all frequencies (both signs), on a log grid wide enough for both
    # spectra's corners
    fe = np.geomspace(1e-8, 0.5 / dt_s, 4000)
    s_f = track_psd_matern32(fe, field_sigma, field_length_m, speed_mps)
    s_r = markov_psd(fe, residual_sigma, tau_s)
    y = s_f * s_r / (s_f + s_r)
    var = 2.0 * float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(fe)))
    return filtered, float(min(math.sqrt(max(var, 0.0)), residual_sigma))
