"""Post-processing of the smoothed anomaly estimate on one survey line.

The seed (004) cleans the Kalman estimate ``z`` of the gravity anomaly with a Mallat pyramid
(orthogonal Daubechies ``db10`` or Coiflet ``coif4``) over ``K = 1 + floor(log2 N)`` levels,
thresholds the detail (H) components of levels ``1..n`` and chooses the level ``n`` and the
threshold vector ``p`` that minimise the projector criterion

    Phi(z, z~) = |(z - z~)^T z~| / (||z - z~|| ||z~||) = |cos phi|.

This module holds

* the faithful rule (method ``"cosphi"``), evaluated exactly as the seed writes it, in the
  signal domain, with a configurable boundary mode and soft or hard thresholding;
* a well-posed variant (method ``"ti_cosphi"``): the same pyramid filters and the same criterion,
  but on the translation-invariant (undecimated, "a trous") pyramid, which is a zero-phase
  linear operator that is *not* an orthogonal projector, so that Phi measures the real overlap
  between the kept and the removed parts (see docs/wavelet.md for the investigation); given the
  estimator's own sigma it never removes more than that sigma (RMS);
* the baselines: VisuShrink, SURE and BayesShrink soft thresholding, and (from
  :mod:`gravsurvey.filters`) the zero-phase low-pass filters used in airborne gravimetry
  (Butterworth forward-backward, Gaussian), parameterised by their half-wavelength resolution at
  the line's speed;
* :func:`postprocess`, the entry point the pipeline calls once per survey line (its
  ``postprocess:`` settings are validated by :func:`gravsurvey.settings.postprocess_options`).

Everything works in SI units (m/s^2 for the anomaly, s, m, m/s); every method is
scale-equivariant (scaling ``z`` and ``sigma`` scales the output), so any consistent unit works.

Levels beyond PyWavelets' recommended maximum
---------------------------------------------
``K = 1 + floor(log2 N)`` is larger than :func:`pywt.dwt_max_level` (which stops when a level's
length falls below the filter length).  PyWavelets still computes those levels exactly (perfect
reconstruction holds to rounding, tested) but warns that all their coefficients feel the
boundary; we silence that warning on purpose and keep all ``K`` levels, as the seed does.  For the
translation-invariant variant a level is a zero-phase filter applied to the even (mirror)
extension of the line, which is defined for any level and any ``N``.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
import pywt
from numba import njit
from scipy import fft as _sfft

from gravsurvey.errors import ConfigError, DataError
from gravsurvey.filters import butterworth_lowpass, gaussian_lowpass, lowpass_period_s, lowpass_resolution_m

__all__ = [
    "METHODS",
    "DEFAULT_METHOD",
    "WAVELETS",
    "BOUNDARY_MODES",
    "LOWPASS_METHODS",
    "PostprocessOptions",
    "n_levels",
    "phi_criterion",
    "wavedec_k",
    "waverec_n",
    "threshold",
    "approximation",
    "cosphi_search",
    "ti_response",
    "ti_approximation",
    "ti_period_samples",
    "ti_cosphi",
    "ti_apply_with_context",
    "visushrink",
    "sure_shrink",
    "bayes_shrink",
    "postprocess",
]

#: Method names accepted by :func:`postprocess` (plus ``"default"``).
METHODS = (
    "ti_cosphi",
    "cosphi",
    "visushrink",
    "sure",
    "bayes",
    "butterworth",
    "gaussian",
    "none",
)

#: The method ``"default"`` resolves to: the smoothed Kalman estimate as it is.  With the
#: identified model the smoother already has the resolution of least expected error, and no
#: post-processor improved on it over unseen flights (docs/wavelet.md, "Default").
DEFAULT_METHOD = "none"

#: Wavelets of the seed, and ``auto`` (choose by the criterion).
WAVELETS = ("db10", "coif4", "auto")

#: Boundary extension modes of the decimated (PyWavelets) pyramid.
BOUNDARY_MODES = (
    "symmetric",
    "periodization",
    "smooth",
    "zero",
    "constant",
    "reflect",
    "periodic",
    "antisymmetric",
    "antireflect",
)

THRESHOLDINGS = ("soft", "hard")

#: Margin of the context extension, in periods ``2^(n+1)`` of the chosen level (see
#: :func:`ti_apply_with_context`).
CONTEXT_MARGIN_PERIODS = 2.0
#: Context consistency gate: a side is used only if the RMS of the part removed there is at
#: most this multiple of the RMS removed on the line.
CONTEXT_GATE_RATIO = 1.25
#: a |cos phi| candidate whose removed part r or kept part z~ has energy below this fraction of
#: ||z||^2 is degenerate ("remove nothing" / "remove everything"): its Phi is rounding noise of
#: the Gram-matrix updates (seen as 4.7e-10 with numpy 2.4 / PyWavelets 1.9) or undefined, never
#: a real angle.  1e-12 is ~1e4 times the float64 rounding of those updates.
DEGENERATE_ENERGY_FRACTION = 1e-12

_WAVELET_METHODS = ("ti_cosphi", "cosphi", "visushrink", "sure", "bayes")
#: post-processors that are low-pass filters (:mod:`gravsurvey.filters`): need a length
LOWPASS_METHODS = ("butterworth", "gaussian")


# --------------------------------------------------------------------------------------------
# Options
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PostprocessOptions:
    """Validated settings of the ``postprocess:`` block.

    Attributes
    ----------
    method : str
        One of :data:`METHODS` or ``"default"``.
    wavelet : str
        ``"db10"``, ``"coif4"`` or ``"auto"`` (the one whose result has the smaller Phi).
    thresholding : str
        ``"soft"`` or ``"hard"``; used by ``cosphi`` and ``visushrink`` (SURE and Bayes are
        soft by construction).
    boundary : str
        PyWavelets extension mode of the decimated pyramid (``cosphi``, ``visushrink``,
        ``sure``, ``bayes``).  Default ``"symmetric"`` (MATLAB's ``'sym'``, the seed's likely
        default).  ``ti_cosphi`` and the low-pass filters always use the even (mirror) extension.
    resolution_m : float or None
        Half-wavelength resolution of the low-pass filters, m (``butterworth``, ``gaussian``).
    filter_length_s : float or None
        Alternative to ``resolution_m``: the filter length (full wavelength at the -6 dB point),
        s; ``resolution_m = speed * filter_length_s / 2``.
    butterworth_order : int
        Order of the Butterworth prototype (applied forward and backward, so the magnitude
        response is squared).
    threshold_steps : int
        Number of threshold values per level tried by the ``cosphi`` coordinate search.
    max_level : int or None
        Upper bound on the level ``n`` searched (default: ``K = 1 + floor(log2 N)``).
    min_level : int
        Lower bound on the level searched by ``ti_cosphi`` (default 1).
    """

    method: str = "default"
    wavelet: str = "auto"
    thresholding: str = "soft"
    boundary: str = "symmetric"
    resolution_m: float | None = None
    filter_length_s: float | None = None
    butterworth_order: int = 4
    threshold_steps: int = 8
    max_level: int | None = None
    min_level: int = 1


# --------------------------------------------------------------------------------------------
# Pyramid helpers
# --------------------------------------------------------------------------------------------
def n_levels(n_samples):
    """The seed's number of pyramid levels, ``K = 1 + floor(log2 N)``.

    Parameters
    ----------
    n_samples : int
        Line length ``N`` >= 1.

    Returns
    -------
    int
    """
    n_samples = int(n_samples)
    if n_samples < 1:
        raise DataError(f"wavelet post-processor: line has {n_samples} samples, expected >= 1")
    return 1 + int(math.floor(math.log2(n_samples)))


def phi_criterion(z, z_tilde):
    """The seed's projector criterion ``Phi = |cos phi|`` between removed and kept parts.

    Parameters
    ----------
    z : ndarray, shape (N,)
        Input vector.
    z_tilde : ndarray, shape (N,)
        Post-processed vector.

    Returns
    -------
    float
        ``|(z - z~)^T z~| / (||z - z~|| ||z~||)``; ``nan`` when either part is exactly zero
        (the angle is then undefined).
    """
    z = np.asarray(z, dtype=float)
    zt = np.asarray(z_tilde, dtype=float)
    r = z - zt
    nr = math.sqrt(float(r @ r))
    nk = math.sqrt(float(zt @ zt))
    if nr == 0.0 or nk == 0.0:
        return float("nan")
    return abs(float(r @ zt)) / (nr * nk)


def _phi_from_dots(rr, rk, kk):
    if rr <= 0.0 or kk <= 0.0:
        return float("nan")
    return abs(rk) / math.sqrt(rr * kk)


def wavedec_k(z, wavelet, mode="symmetric", level=None):
    """Mallat decomposition over ``level`` (default ``K``) levels.

    Parameters
    ----------
    z : ndarray, shape (N,)
    wavelet : str
        PyWavelets name (``"db10"``, ``"coif4"``, ...).
    mode : str
        PyWavelets extension mode.
    level : int, optional
        Number of levels; default ``n_levels(N)``.

    Returns
    -------
    list of ndarray
        ``[a_K, d_K, ..., d_1]`` as :func:`pywt.wavedec` returns them.
    """
    z = np.asarray(z, dtype=float)
    level = n_levels(z.size) if level is None else int(level)
    with warnings.catch_warnings():
        # Levels beyond dwt_max_level are computed exactly; the warning is expected (module doc).
        warnings.simplefilter("ignore", UserWarning)
        return pywt.wavedec(z, wavelet, mode=mode, level=level)


def waverec_n(coeffs, wavelet, mode, n_samples):
    """Inverse of :func:`wavedec_k`, cropped to ``n_samples``."""
    out = pywt.waverec(coeffs, wavelet, mode=mode)
    return out[:n_samples]


def threshold(d, p, kind):
    """Soft or hard thresholding "from zero".

    Parameters
    ----------
    d : ndarray
        Coefficients.
    p : float
        Threshold >= 0.
    kind : {"soft", "hard"}
        Soft: ``sign(d) max(|d| - p, 0)``; hard: ``d`` where ``|d| > p``, else 0.

    Returns
    -------
    ndarray, same shape as ``d``
    """
    d = np.asarray(d, dtype=float)
    if kind == "soft":
        return np.sign(d) * np.maximum(np.abs(d) - p, 0.0)
    if kind == "hard":
        return np.where(np.abs(d) > p, d, 0.0)
    raise ValueError(f"thresholding must be 'soft' or 'hard', got {kind!r}")


def approximation(z, wavelet, level, mode="symmetric"):
    """Full removal of the details of levels ``1..level`` (decimated pyramid).

    Parameters
    ----------
    z : ndarray, shape (N,)
    wavelet : str
    level : int
    mode : str

    Returns
    -------
    ndarray, shape (N,)
        The level-``level`` approximation reconstructed to the signal domain.
    """
    z = np.asarray(z, dtype=float)
    c = wavedec_k(z, wavelet, mode, level=level)
    c = [c[0]] + [np.zeros_like(x) for x in c[1:]]
    return waverec_n(c, wavelet, mode, z.size)


# --------------------------------------------------------------------------------------------
# The seed's rule, faithfully
# --------------------------------------------------------------------------------------------
def _synth_level(shapes, j_index, e, wavelet, mode, n_samples):
    """Signal-domain image of detail coefficients ``e`` placed at list index ``j_index``."""
    c = [np.zeros(s) for s in shapes]
    c[j_index] = e
    return waverec_n(c, wavelet, mode, n_samples)


def _removed_images(z, wavelet, mode, thresholding, steps, kmax):
    """Signal-domain images of the removed detail parts on the threshold grid.

    Returns
    -------
    images : ndarray, shape (kmax, steps + 1, N)
        ``images[j-1, k]`` = synthesis of ``d_j - T(d_j, max|d_j| k / steps)`` (level j alone).
    dmax : ndarray, shape (kmax,)
        ``max |d_j|``.
    details : list of ndarray
        ``d_1 .. d_kmax``.
    """
    n_samples = z.size
    coeffs = wavedec_k(z, wavelet, mode, level=kmax)
    shapes = [c.shape for c in coeffs]
    details = [coeffs[kmax + 1 - j] for j in range(1, kmax + 1)]
    dmax = np.array([float(np.max(np.abs(d))) if d.size else 0.0 for d in details])
    images = np.zeros((kmax, steps + 1, n_samples))
    for j in range(1, kmax + 1):
        d = details[j - 1]
        for k in range(steps + 1):
            e = d - threshold(d, dmax[j - 1] * k / steps, thresholding)
            if np.any(e):
                images[j - 1, k] = _synth_level(shapes, kmax + 1 - j, e, wavelet, mode, n_samples)
    return images, dmax, details


@njit(cache=True)
def _cosphi_descent_kernel(gram, rz, zz, top, steps, max_sweeps, out_k, out_phi):
    """Coordinate descent of the seed's rule on precomputed inner products (numba).

    ``gram[a, b]`` = image_a . image_b with image index ``a = (j - 1) * (steps + 1) + k``;
    ``rz[a]`` = image_a . z.  For every level n = 1..top the thresholds start at k = steps
    (p_j = max|d_j|); ``out_k[n-1, :n]`` receives the chosen grid indices and ``out_phi[n-1]``
    the Phi reached (nan if undefined).
    """
    s1 = steps + 1
    for n in range(1, top + 1):
        ks = np.full(n, steps)
        # r = sum_j image(j, ks[j]); keep rr = r.r, rzs = r.z, and rimg[a] = r . image_a
        na = n * s1
        rimg = np.zeros(na)
        for j in range(n):
            a = j * s1 + ks[j]
            for b in range(na):
                rimg[b] += gram[a, b]
        rr = 0.0
        rzs = 0.0
        for j in range(n):
            a = j * s1 + ks[j]
            rr += rimg[a]
            rzs += rz[a]
        floor = DEGENERATE_ENERGY_FRACTION * zz
        cur = _phi_dots_nb(rr, rzs - rr, zz - 2.0 * rzs + rr, floor)
        for _ in range(max_sweeps):
            changed = False
            for j in range(n):
                old = j * s1 + ks[j]
                best_k = ks[j]
                best_phi = cur
                for k in range(steps, -1, -1):
                    if k == ks[j]:
                        continue
                    new = j * s1 + k
                    # r' = r - img_old + img_new
                    rr2 = rr - 2.0 * rimg[old] + gram[old, old] + 2.0 * (rimg[new] - gram[old, new]) + gram[new, new]
                    rz2 = rzs - rz[old] + rz[new]
                    ph = _phi_dots_nb(rr2, rz2 - rr2, zz - 2.0 * rz2 + rr2, floor)
                    if not np.isnan(ph) and (np.isnan(best_phi) or ph < best_phi):
                        best_k = k
                        best_phi = ph
                if best_k != ks[j]:
                    new = j * s1 + best_k
                    rr = rr - 2.0 * rimg[old] + gram[old, old] + 2.0 * (rimg[new] - gram[old, new]) + gram[new, new]
                    rzs = rzs - rz[old] + rz[new]
                    for b in range(na):
                        rimg[b] += gram[new, b] - gram[old, b]
                    ks[j] = best_k
                    cur = best_phi
                    changed = True
            if not changed:
                break
        for j in range(n):
            out_k[n - 1, j] = ks[j]
        out_phi[n - 1] = cur


@njit(cache=True)
def _phi_dots_nb(rr, rk, kk, floor):
    # a removed or kept part with (near-)zero energy makes Phi rounding noise: undefined (nan)
    if rr <= floor or kk <= floor:
        return np.nan
    return abs(rk) / np.sqrt(rr * kk)


def _phi_candidate(z, r, floor):
    """Phi of the candidate ``z~ = z - r`` from direct dot products; nan when degenerate
    (``r.r`` or ``z~.z~`` at most ``floor``), as in :func:`_phi_dots_nb`."""
    zt = z - r
    return _phi_from_dots_floor(float(r @ r), float(r @ zt), float(zt @ zt), floor)


def _phi_from_dots_floor(rr, rk, kk, floor):
    if rr <= floor or kk <= floor:
        return float("nan")
    return abs(rk) / math.sqrt(rr * kk)


def _cosphi_descent_numpy(images, z, top, steps, max_sweeps):
    """Pure-numpy reference of :func:`_cosphi_descent_kernel`: Phi evaluated directly from the
    signal-domain vectors ``r`` and ``z~ = z - r`` for every candidate (the Phi of
    :func:`phi_criterion`, with the same degenerate-candidate floor as the kernel)."""
    kmax = images.shape[0]
    out_k = np.zeros((kmax, kmax), dtype=np.int64)
    out_phi = np.full(kmax, np.nan)
    floor = DEGENERATE_ENERGY_FRACTION * float(z @ z)
    for n in range(1, top + 1):
        ks = [steps] * n
        r = images[np.arange(n), ks].sum(axis=0)
        cur = _phi_candidate(z, r, floor)
        for _ in range(max_sweeps):
            changed = False
            for j in range(n):
                base = r - images[j, ks[j]]
                best_k, best_phi = ks[j], cur
                for k in range(steps, -1, -1):
                    if k == ks[j]:
                        continue
                    ph = _phi_candidate(z, base + images[j, k], floor)
                    if not np.isnan(ph) and (np.isnan(best_phi) or ph < best_phi):
                        best_k, best_phi = k, ph
                if best_k != ks[j]:
                    ks[j] = best_k
                    r = base + images[j, best_k]
                    cur = best_phi
                    changed = True
            if not changed:
                break
        out_k[n - 1, :n] = ks
        out_phi[n - 1] = cur
    return out_k, out_phi


def cosphi_search(
    z, wavelet="db10", mode="symmetric", thresholding="soft", steps=8, max_level=None, max_sweeps=3, reference=False
):
    """The seed's rule: ``min over (n, p) of Phi(z, z~)``, Phi of the signal-domain vectors.

    For every level ``n = 1..max_level`` the thresholds ``p_j`` of the detail components
    ``j = 1..n`` start at ``max |d_j|`` (the seed's starting point: everything removed) and are
    improved by coordinate descent over the grid ``p_j = max|d_j| k / steps``,
    ``k = steps, ..., 0``, until a sweep changes nothing (at most ``max_sweeps``).  The
    ``(n, p)`` with the smallest Phi wins; exact ties go to the smallest ``n`` (that tie is the
    ill-posedness documented in docs/wavelet.md).
    A candidate that removes nothing (or keeps nothing) is never chosen: its removed (kept)
    energy is at most ``DEGENERATE_ENERGY_FRACTION ||z||^2`` and its Phi is rounding noise or
    undefined, so it counts as nan; when every candidate is degenerate the line is returned
    unchanged with ``n = 0``.

    Because the synthesis is linear, ``z - z~ = sum_j W_j(d_j - T(d_j, p_j))``; the images of
    every (level, grid threshold) are synthesised once and the search runs on their Gram
    matrix, which gives Phi of the signal-domain vectors exactly (to rounding) for any boundary
    mode.  ``reference=True`` runs the same search evaluating every candidate directly in the
    signal domain (pure numpy, slow; used by the tests).

    Parameters
    ----------
    z : ndarray, shape (N,)
        Smoothed anomaly estimate on one line (equally spaced).
    wavelet : str
    mode : str
        PyWavelets boundary mode.
    thresholding : {"soft", "hard"}
    steps : int
        Grid size per level.
    max_level : int, optional
        Largest ``n`` searched, default ``K = 1 + floor(log2 N)``.
    max_sweeps : int
    reference : bool

    Returns
    -------
    z_tilde : ndarray, shape (N,)
    info : dict
        ``n``, ``p`` (thresholds of levels 1..n, unit of ``z``), ``Phi``, ``phi_deg``,
        ``phi_by_level`` (best Phi per level), ``levels_fully_removed`` (largest m such that
        the details of levels 1..m are all zeroed).

    Notes
    -----
    Cost: ``K (steps + 1)`` inverse transforms, O(N L K steps), plus the Gram matrix,
    O(N (K steps)^2) (one BLAS product), plus the search, O(sweeps K^3 steps^2) scalar work
    independent of N.
    """
    z = np.asarray(z, dtype=float)
    n_samples = z.size
    kmax = n_levels(n_samples)
    top = kmax if max_level is None else max(1, min(int(max_level), kmax))
    images, dmax, details = _removed_images(z, wavelet, mode, thresholding, steps, kmax)
    if reference:
        out_k, out_phi = _cosphi_descent_numpy(images, z, top, steps, max_sweeps)
    else:
        flat = images[:top].reshape(top * (steps + 1), n_samples)
        gram = flat @ flat.T
        rz = flat @ z
        out_k = np.zeros((kmax, kmax), dtype=np.int64)
        out_phi = np.full(kmax, np.nan)
        _cosphi_descent_kernel(gram, rz, float(z @ z), top, steps, max_sweeps, out_k, out_phi)
    phi_by_level = [float(x) for x in out_phi[:top]]
    finite = [(v, n) for n, v in enumerate(phi_by_level, start=1) if np.isfinite(v)]
    if not finite:  # nothing removable (e.g. a constant line): leave it as it is
        return z.copy(), {
            "n": 0,
            "p": [],
            "Phi": float("nan"),
            "phi_deg": float("nan"),
            "phi_by_level": phi_by_level,
            "levels_fully_removed": 0,
        }
    phi, n = min(finite)
    ks = out_k[n - 1, :n]
    r = images[np.arange(n), ks].sum(axis=0)
    p = [float(dmax[j] * ks[j] / steps) for j in range(n)]
    full = 0
    for j in range(n):
        if np.any(threshold(details[j], p[j], thresholding)):
            break
        full = j + 1
    return z - r, {
        "n": n,
        "p": p,
        "Phi": float(phi),
        "phi_deg": math.degrees(math.acos(min(1.0, phi))),
        "phi_by_level": phi_by_level,
        "levels_fully_removed": full,
    }


# --------------------------------------------------------------------------------------------
# Translation-invariant (undecimated) pyramid: the well-posed variant
# --------------------------------------------------------------------------------------------
def ti_response(wavelet, level, freq_cyc_per_sample):
    """Amplitude response of the translation-invariant level-``level`` approximation.

    Averaging the decimated projection onto the approximation space ``V_n`` over all ``2^n``
    shifts of the sampling grid (cycle spinning, the undecimated pyramid) gives the zero-phase
    convolution with frequency response ``prod_{k<n} |H(2^k w)|^2 / 2``, ``H`` the scaling
    (low-pass) filter with ``sum h = sqrt 2``.

    Parameters
    ----------
    wavelet : str
    level : int
        ``n >= 0`` (0 gives 1).
    freq_cyc_per_sample : ndarray
        Frequencies, cycles per sample.

    Returns
    -------
    ndarray
        Real response in [0, 1], same shape as ``freq_cyc_per_sample``.
    """
    h = np.asarray(pywt.Wavelet(wavelet).dec_lo, dtype=float)
    f = np.asarray(freq_cyc_per_sample, dtype=float)
    out = np.ones_like(f)
    taps = np.arange(h.size)
    for k in range(int(level)):
        w = 2.0 * np.pi * f * (2**k)
        hw = np.exp(-1j * np.outer(w.ravel(), taps)) @ h
        out = out * (np.abs(hw) ** 2 / 2.0).reshape(f.shape)
    return out


def _level_responses(wavelet, n_samples, top):
    """Responses of the TI approximations of levels 1..top on the DCT-II grid.

    Returns
    -------
    ndarray, shape (top, N)
        ``out[n-1, k]`` = response of level n at ``f_k = k / (2N)`` cycles per sample.
    """
    h = np.asarray(pywt.Wavelet(wavelet).dec_lo, dtype=float)
    m = 2 * n_samples
    # |H(f)|^2 / 2 on the grid j / m, j = 0..m-1 (H is 1-periodic in f); h is folded if m < len
    hp = np.zeros(m)
    np.add.at(hp, np.arange(h.size) % m, h)
    h2 = np.abs(np.fft.fft(hp)) ** 2 / 2.0
    k = np.arange(n_samples, dtype=np.int64)
    out = np.empty((top, n_samples))
    resp = np.ones(n_samples)
    for n in range(1, top + 1):
        resp = resp * h2[(k * (2 ** (n - 1))) % m]
        out[n - 1] = resp
    return out


def ti_approximation(z, wavelet, level, _zf=None):
    """Translation-invariant level-``level`` approximation of ``z`` (zero phase).

    The line is extended by mirror reflection (even, period ``2N``), so no end jump is created
    for any ``N`` and the output has no time shift (real, even response).  Computed as
    ``idct(dct(z) * R)`` with the orthonormal DCT-II, which is exactly the circular filtering
    of the mirror extension.

    Parameters
    ----------
    z : ndarray, shape (N,)
    wavelet : str
    level : int

    Returns
    -------
    ndarray, shape (N,)
    """
    z = np.asarray(z, dtype=float)
    if level <= 0:
        return z.copy()
    resp = _level_responses(wavelet, z.size, int(level))[-1]
    return _sfft.idct(_sfft.dct(z, 2, norm="ortho") * resp, 2, norm="ortho")


def _half_power_period(resp_fn, lo=2.0, hi=1e9):
    """Period (samples) at which a low-pass amplitude response equals 0.5 (bisection in log)."""
    a, b = math.log(lo), math.log(hi)
    if resp_fn(1.0 / lo) >= 0.5:
        return lo
    for _ in range(80):
        m = 0.5 * (a + b)
        if resp_fn(1.0 / math.exp(m)) < 0.5:
            a = m
        else:
            b = m
    return math.exp(0.5 * (a + b))


def ti_period_samples(wavelet, level):
    """Period (samples) at which the level's approximation response is 0.5 (-6 dB)."""
    if level <= 0:
        return 0.0
    return _half_power_period(lambda f: float(ti_response(wavelet, level, np.array([f]))[0]))


def ti_cosphi(z, wavelet="db10", min_level=1, max_level=None, sigma_rms=None):
    """Well-posed projector rule on the translation-invariant pyramid.

    For each level ``n`` the kept part is the translation-invariant approximation ``A_n z``
    (details of levels ``1..n`` fully removed, averaged over all shifts of the pyramid's grid);
    Phi(z, A_n z) is no longer identically zero because ``A_n`` is not an orthogonal projector:
    it measures the spectral overlap of kept and removed parts in the transition band of level
    ``n``, which is small where the line's spectrum has a gap between signal and noise.
    The level chosen is the first local minimum of Phi(n) after its first local maximum
    (fine to coarse): Phi rises while the cut moves into the noise band, peaks, and falls into
    the gap between the noise and the signal.  A plain global minimum is not enough: Phi is
    also tiny at the finest levels (nothing is removed) and at the coarsest (the kept part
    degenerates towards a constant; level K, whose cut lies below the line's fundamental, is
    therefore not searched); see docs/wavelet.md.  With no such valley (common on short lines)
    the coarsest level searched is used and ``info["gap_found"]`` is False (no warning: on
    lines of a few hundred samples this is the normal case, measured better than leaving the
    line unchanged).

    Parameters
    ----------
    z : ndarray, shape (N,)
    wavelet : str
    min_level, max_level : int
        Search range (default 1..K-2: the coarsest level whose -6 dB period ``2^(n+1)`` samples
        still fits in the line; coarser levels turn a short line into a near-straight line).
    sigma_rms : float, optional
        RMS of the estimator's own 1-sigma over the line (unit of ``z``).  When given, levels
        whose removed part has an RMS above it are not searched: the removed part is meant to
        be noise, and it cannot be larger than the error the estimator reports.  (Measured on
        the Markov seed scenario, where the smoother is already optimal: without this guard
        the valley rule removes signal, 10.4 -> 21.3 mGal; with it 11.0 mGal.)

    Returns
    -------
    z_tilde : ndarray, shape (N,)
    info : dict
        ``n``, ``Phi``, ``phi_deg``, ``phi_by_level`` (levels 1..K-2), ``period_samples``
        (-6 dB period), ``gap_found``, ``removed_rms_by_level``, ``sigma_limited_level``
        (largest level allowed by ``sigma_rms``, or None), ``length_limited_level`` (K-2, at
        least 1).

    Notes
    -----
    Cost: one DCT and one inverse DCT, O(N log N), plus O(K N) for Phi at every level
    (inner products on the DCT coefficients).
    """
    z = np.asarray(z, dtype=float)
    n_samples = z.size
    kmax = n_levels(n_samples)
    # Level n keeps periods longer than 2^(n+1) samples (its -6 dB period).  Level K cuts below
    # the line's fundamental (2^(K+1) > 2N on the mirror extension) and level K-1 still cuts at
    # a period longer than the line (2^K > N): their kept parts are close to a constant or a
    # straight line, and Phi is small there for that reason alone.  The search therefore stops
    # at level K-2, the coarsest whose period fits in the line (2^(n+1) <= N).  Measured on
    # lines of 129-165 samples (sample_data/grid_ros2): 3.42 -> 2.60 mGal with level K-1
    # allowed, 2.29 mGal without it; no change on lines >= 2^(n_chosen+2) samples.
    length_top = max(1, kmax - 2)
    top = length_top
    if max_level is not None:
        top = max(1, min(int(max_level), top))
    lo = min(max(1, int(min_level)), top)
    # The orthonormal DCT-II is an orthogonal matrix: the inner products of the kept part
    # idct(c R) and the removed part idct(c (1 - R)) are sums over the DCT coefficients.
    c = _sfft.dct(z, 2, norm="ortho")
    c2 = c * c
    resp = _level_responses(wavelet, n_samples, top)
    kk = (resp**2) @ c2
    rr = ((1.0 - resp) ** 2) @ c2
    rk = (resp * (1.0 - resp)) @ c2
    phis = [float("nan") if n < lo else _phi_from_dots(rr[n - 1], rk[n - 1], kk[n - 1]) for n in range(1, top + 1)]
    removed_rms = [float(math.sqrt(max(v, 0.0) / n_samples)) for v in rr]
    sigma_top = None
    if sigma_rms is not None and np.isfinite(sigma_rms) and sigma_rms > 0:
        # the removed energy grows with n (R_{n+1} <= R_n): the allowed levels are 1..sigma_top
        allowed = [n for n in range(1, top + 1) if removed_rms[n - 1] <= sigma_rms]
        sigma_top = allowed[-1] if allowed else 0
        phis = [v if n <= sigma_top else float("nan") for n, v in enumerate(phis, start=1)]
    n_best, found = _gap_level(phis, lo)
    if n_best is None:  # constant line, or sigma allows no level: nothing to remove
        return z.copy(), {
            "n": 0,
            "Phi": float("nan"),
            "phi_deg": float("nan"),
            "phi_by_level": phis,
            "period_samples": 0.0,
            "gap_found": False,
            "removed_rms_by_level": removed_rms,
            "sigma_limited_level": sigma_top,
            "length_limited_level": length_top,
        }
    phi = phis[n_best - 1]
    return _sfft.idct(c * resp[n_best - 1], 2, norm="ortho"), {
        "n": n_best,
        "Phi": phi,
        "phi_deg": math.degrees(math.acos(min(1.0, phi))),
        "phi_by_level": phis,
        "period_samples": ti_period_samples(wavelet, n_best),
        "gap_found": found,
        "removed_rms_by_level": removed_rms,
        "sigma_limited_level": sigma_top,
        "length_limited_level": length_top,
    }


def _gap_level(phis, lo):
    """The first local minimum of Phi(n) after its first local maximum (1-based level).

    A maximum at the first level searched counts (white noise at the finest scales makes Phi
    fall from the start).  Returns ``(n, found)``: when Phi is still rising or still falling
    at the coarsest level searched, ``n`` is that level and ``found`` is False.
    """
    vals = [(n, v) for n, v in enumerate(phis, start=1) if n >= lo and np.isfinite(v)]
    if not vals:
        return None, False
    i = 0
    while i + 1 < len(vals) and vals[i + 1][1] > vals[i][1]:
        i += 1  # climb to the first local maximum
    if i + 1 >= len(vals):
        return vals[-1][0], False
    while i + 1 < len(vals) and vals[i + 1][1] <= vals[i][1]:
        i += 1  # descend to the following local minimum
    if i + 1 >= len(vals):
        return vals[-1][0], False
    return vals[i][0], True


# --------------------------------------------------------------------------------------------
# Baselines: classical wavelet shrinkage
# --------------------------------------------------------------------------------------------
def _mad_sigma(d):
    return float(np.median(np.abs(d - np.median(d)))) / 0.6744897501960817 if d.size else 0.0


def _baseline_levels(n_samples, wavelet, levels):
    """Levels of the classical shrinkage baselines: PyWavelets' maximum useful level
    (coarsest level still longer than the filter), at least 1, unless given."""
    if levels is not None:
        return int(levels)
    return max(1, pywt.dwt_max_level(n_samples, pywt.Wavelet(wavelet).dec_len))


def _shrink(z, wavelet, mode, levels, per_level):
    z = np.asarray(z, dtype=float)
    levels = _baseline_levels(z.size, wavelet, levels)
    c = wavedec_k(z, wavelet, mode, level=levels)
    kmax = len(c) - 1
    ps = []
    out = [c[0]]
    for idx in range(1, kmax + 1):
        j = kmax + 1 - idx
        d = c[idx]
        p = per_level(j, d)
        ps.append((j, p))
        out.append(threshold(d, p, "soft") if p is not None else d)
    z_tilde = waverec_n(out, wavelet, mode, z.size)
    ps.sort()
    return z_tilde, [p for _, p in ps]


def visushrink(z, wavelet="db10", mode="symmetric", thresholding="soft", levels=None):
    """VisuShrink: universal threshold ``sigma sqrt(2 ln N)`` on every detail level.

    ``sigma`` is the MAD estimate (/0.6745) from the finest detail level (Donoho & Johnstone
    1994).

    Returns
    -------
    z_tilde : ndarray, shape (N,)
    info : dict
        ``p`` (threshold per level 1..K), ``sigma``.
    """
    z = np.asarray(z, dtype=float)
    c = wavedec_k(z, wavelet, mode, level=_baseline_levels(z.size, wavelet, levels))
    sigma = _mad_sigma(c[-1])
    lam = sigma * math.sqrt(2.0 * math.log(max(z.size, 2)))
    out = [c[0]] + [threshold(d, lam, thresholding) for d in c[1:]]
    return waverec_n(out, wavelet, mode, z.size), {"p": [lam] * (len(c) - 1), "sigma": sigma}


def _sure_threshold(d, sigma):
    """Threshold minimising Stein's unbiased risk estimate for soft thresholding (SureShrink
    hybrid rule of Donoho & Johnstone 1995 with the universal fallback for sparse levels)."""
    n = d.size
    if n == 0 or sigma <= 0:
        return 0.0
    x = np.sort(np.abs(d) / sigma)
    universal = math.sqrt(2.0 * math.log(max(n, 2)))
    # sparse level: universal threshold (hybrid rule)
    eta = (float(np.sum(x**2)) - n) / n
    crit = math.log2(max(n, 2)) ** 1.5 / math.sqrt(n)
    if eta <= crit:
        return universal * sigma
    x2 = x**2
    cums = np.cumsum(x2)
    k = np.arange(1, n + 1)
    # risk(t = x_k) = n - 2 k + sum_{i<=k} x_i^2 + (n - k) x_k^2
    risk = n - 2.0 * k + cums + (n - k) * x2
    t = float(x[int(np.argmin(risk))])
    return min(t, universal) * sigma


def sure_shrink(z, wavelet="db10", mode="symmetric", levels=None):
    """SureShrink soft thresholding, level by level, with a level-wise MAD noise estimate.

    The noise of the smoothed Kalman estimate is coloured, so ``sigma_j`` is estimated on each
    level (Johnstone & Silverman 1997) rather than on the finest one only.

    Returns
    -------
    z_tilde : ndarray, shape (N,)
    info : dict
        ``p`` (threshold per level 1..K).
    """
    z_t, ps = _shrink(z, wavelet, mode, levels, lambda j, d: _sure_threshold(d, _mad_sigma(d)))
    return z_t, {"p": ps}


def bayes_shrink(z, wavelet="db10", mode="symmetric", levels=None):
    """BayesShrink soft thresholding (Chang, Yu & Vetterli 2000), level-wise noise estimate.

    ``p_j = sigma_j^2 / sigma_x,j`` with ``sigma_x,j = sqrt(max(var(d_j) - sigma_j^2, 0))``;
    a level with ``sigma_x,j = 0`` is removed entirely.  ``sigma_j`` is the MAD estimate on the
    level itself (coloured noise), see :func:`sure_shrink`.

    Returns
    -------
    z_tilde : ndarray, shape (N,)
    info : dict
        ``p`` (threshold per level 1..K).
    """

    def per_level(j, d):
        if d.size == 0:
            return 0.0
        s = _mad_sigma(d)
        sx2 = float(np.mean(d**2)) - s**2
        if sx2 <= 0.0:
            return float(np.max(np.abs(d)))
        return s**2 / math.sqrt(sx2)

    z_t, ps = _shrink(z, wavelet, mode, levels, per_level)
    return z_t, {"p": ps}


# --------------------------------------------------------------------------------------------
# Entry point
# --------------------------------------------------------------------------------------------
def _wavelet_candidates(name):
    return ("db10", "coif4") if name == "auto" else (name,)


def _check_context(context, z):
    """Validate ``context=(z_full, start, stop)``; return it as (ndarray, int, int)."""
    try:
        z_full, start, stop = context
    except (TypeError, ValueError):
        raise DataError("wavelet post-processor: context must be (z_full, start, stop)") from None
    z_full = np.asarray(z_full, dtype=float)
    if z_full.ndim != 1:
        raise DataError(
            f"wavelet post-processor: context z_full has shape {z_full.shape}, "
            "expected 1-D (the whole flight's estimate)"
        )
    if isinstance(start, bool) or isinstance(stop, bool) or int(start) != start or int(stop) != stop:
        raise DataError(
            f"wavelet post-processor: context start/stop {start!r}/{stop!r}, expected integer sample indices"
        )
    start, stop = int(start), int(stop)
    if not (0 <= start < stop <= z_full.size) or stop - start != z.size:
        raise DataError(
            f"wavelet post-processor: context range [{start}, {stop}) does not hold "
            f"the line's {z.size} samples inside the {z_full.size}-sample flight"
        )
    if not np.array_equal(z_full[start:stop], z):
        raise DataError(
            "wavelet post-processor: context z_full[start:stop] differs from the "
            "line; expected the same estimate the line was cut from"
        )
    return z_full, start, stop


def ti_apply_with_context(
    z_full, start, stop, wavelet, level, margin_periods=CONTEXT_MARGIN_PERIODS, gate_ratio=CONTEXT_GATE_RATIO
):
    """The level-``level`` TI approximation of the line ``z_full[start:stop]``, filtered over
    the line extended on both sides by the flight's own estimate.

    The window is ``z_full[start - M : stop + M]`` with ``M = margin_periods * 2^(level+1)``
    samples (default one -6 dB period of the level), clipped to the flight and
    to the finite samples next to the line; only beyond the window is the mirror extension
    used.  The line's ends then see real data instead of a mirror image, which removes the
    mirror's end bias (a smooth signal with a slope at the end is bent over half a filter
    length) wherever the estimate outside the line is as good as inside it.

    Consistency gate: a side is used only if the part the level removes there (``z - A_n z``
    over the margin) has an RMS at most ``gate_ratio`` times that on the line itself; a noisier
    side (e.g. a turn with large dynamic errors) is dropped and the mirror is used at that end.
    The ratio is not 1 because the RMS over one margin of stationary noise scatters by about
    +-25 % (measured); 1.25 keeps most sides on stationary data and drops most of the realistic
    survey's turns.  Measured in docs/wavelet.md section 7.

    Parameters
    ----------
    z_full : ndarray, shape (M_total,)
        The whole flight's smoothed estimate.
    start, stop : int
        The line is ``z_full[start:stop]``.
    wavelet : str
    level : int
        ``>= 1``.
    margin_periods : float
        Margin on each side, in periods ``2^(level+1)`` samples.
    gate_ratio : float
        Consistency gate (``inf`` disables it).

    Returns
    -------
    ndarray, shape (stop - start,)
    """
    if level <= 0:
        return np.array(z_full[start:stop], dtype=float)
    m = round(margin_periods * 2 ** (int(level) + 1))
    lo, hi = max(0, start - m), min(z_full.size, stop + m)
    bad = ~np.isfinite(z_full[lo:hi])
    if np.any(bad):  # keep only the finite run around the line
        idx = np.flatnonzero(bad) + lo
        left, right = idx[idx < start], idx[idx >= stop]
        if left.size:
            lo = int(left[-1]) + 1
        if right.size:
            hi = int(right[0])
    if lo < start or hi > stop:
        # the gate's removed part is computed on a window one margin wider still, so that the
        # mirror bias at that window's own ends does not reach the margins being judged
        lo2, hi2 = max(0, lo - m), min(z_full.size, hi + m)
        w = np.asarray(z_full[lo2:hi2], dtype=float)
        if np.all(np.isfinite(w)):
            r = w - ti_approximation(w, wavelet, level)
        else:  # non-finite beyond the finite run: judge on the run alone
            lo2, hi2 = lo, hi
            w = np.asarray(z_full[lo:hi], dtype=float)
            r = w - ti_approximation(w, wavelet, level)

        def _ms(x):
            return float(np.mean(x * x))

        limit = gate_ratio**2 * _ms(r[start - lo2 : stop - lo2])
        if lo < start and _ms(r[lo - lo2 : start - lo2]) > limit:
            lo = start
        if hi > stop and _ms(r[stop - lo2 : hi - lo2]) > limit:
            hi = stop
    out = ti_approximation(np.asarray(z_full[lo:hi], dtype=float), wavelet, level)
    return out[start - lo : stop - lo]


def postprocess(z, dt_s, speed_mps, method="default", options=None, sigma=None, context=None, **kwargs):
    """Clean the smoothed anomaly estimate of ONE survey line.

    Parameters
    ----------
    z : ndarray, shape (N,)
        Smoothed Kalman anomaly estimate, equally spaced, any ``N >= 2``, any unit (SI inside
        the pipeline: m/s^2).  Must be finite.
    dt_s : float
        Sample spacing, s.
    speed_mps : float
        Mean ground speed on the line, m/s (converts periods to half-wavelength resolution).
    method : str
        ``"default"`` or one of :data:`METHODS`.  When ``options`` is given and ``method`` is
        ``"default"``, ``options.method`` is used.
    options : PostprocessOptions, optional
        As returned by :func:`gravsurvey.settings.postprocess_options`.
    sigma : float or ndarray, shape (N,), optional
        The estimator's own 1-sigma of ``z`` (e.g. ``InmSolution.sigma_smooth``), same unit.
        ``ti_cosphi`` then never removes more (RMS) than the RMS of ``sigma``: see
        :func:`ti_cosphi`.  Ignored by the other methods.
    context : tuple (z_full, start, stop), optional
        The whole flight's estimate (shape ``(M,)``, same unit) and the line's index range, with
        ``z_full[start:stop]`` equal to ``z``.  ``ti_cosphi`` then chooses the level on the line
        alone, exactly as without context, but applies it to the line extended by up to the
        level's period on each side with the flight's own estimate
        (:func:`ti_apply_with_context`), instead of the mirror image.  This removes the mirror's
        end bias only where the estimate outside the line (turns) is as good as on the line;
        measured in docs/wavelet.md section 7 (it helps on sample_data/grid_ros2 and hurts on
        the realistic survey, whose turn estimates are 2-3x worse).  Ignored by the other
        methods.
    **kwargs
        Otherwise, any key of the ``postprocess:`` block except ``method`` (``wavelet``,
        ``thresholding``, ``boundary``, ``resolution_m``, ``filter_length_s``,
        ``butterworth_order``, ``threshold_steps``, ``max_level``, ``min_level``), validated by
        :func:`gravsurvey.settings.postprocess_options`.

    Returns
    -------
    z_out : ndarray, shape (N,)
        Post-processed estimate, same unit and time base as ``z``.
    info : dict
        ``method`` (resolved), ``wavelet``, ``n`` (level), ``p`` (thresholds, unit of ``z``),
        ``Phi``, ``phi_deg``, ``resolution_m`` (half-wavelength, m, where meaningful, else
        None), plus method-specific entries.

    Raises
    ------
    ConfigError
        Unknown method or invalid option.
    DataError
        Empty, multi-dimensional or non-finite line, or non-positive sample spacing.
    """
    if options is not None:
        if kwargs:
            raise ConfigError("postprocess: give either options=PostprocessOptions or keyword settings, not both")
        opts = options
        if method == "default":
            method = opts.method
    else:
        from gravsurvey.settings import postprocess_options

        opts = postprocess_options(dict(kwargs, method=method))
    if method == "default":
        method = DEFAULT_METHOD
    if method not in METHODS:
        raise ConfigError(
            f"postprocess.method: {method!r} is not allowed; expected one of default, {', '.join(METHODS)}"
        )
    z = np.asarray(z, dtype=float)
    if z.ndim != 1 or z.size < 2:
        raise DataError(f"wavelet post-processor: expected a 1-D line of >= 2 samples, got shape {z.shape}")
    if not np.all(np.isfinite(z)):
        raise DataError(
            f"wavelet post-processor: line holds {int(np.sum(~np.isfinite(z)))} "
            "non-finite samples; expected finite values"
        )
    if not (dt_s > 0 and math.isfinite(dt_s)):
        raise DataError(f"wavelet post-processor: sample spacing {dt_s!r} s, expected > 0")

    sigma_rms = None
    if sigma is not None:
        sg = np.asarray(sigma, dtype=float)
        if sg.ndim and sg.shape != z.shape:
            raise DataError(
                f"wavelet post-processor: sigma has shape {sg.shape}, expected a scalar or the line's shape {z.shape}"
            )
        sg = np.broadcast_to(sg, z.shape)
        ok = np.isfinite(sg)
        if not np.any(ok) or np.any(sg[ok] < 0):
            raise DataError("wavelet post-processor: sigma must hold finite values >= 0")
        sigma_rms = float(np.sqrt(np.mean(sg[ok] ** 2)))
    if context is not None:
        context = _check_context(context, z)
    info = {"method": method, "wavelet": None, "n": None, "p": None, "Phi": None, "phi_deg": None, "resolution_m": None}
    if method == "none":
        return z.copy(), info
    if method in LOWPASS_METHODS:
        period = lowpass_period_s(dt_s, speed_mps, opts.resolution_m, opts.filter_length_s)
        if method == "butterworth":
            out = butterworth_lowpass(z, dt_s, period, opts.butterworth_order)
        else:
            out = gaussian_lowpass(z, dt_s, period)
        phi = phi_criterion(z, out)
        info.update(
            Phi=phi,
            phi_deg=_deg(phi),
            filter_length_s=period,
            resolution_m=lowpass_resolution_m(period, speed_mps) if speed_mps and speed_mps > 0 else None,
        )
        return out, info

    best = None
    for wname in _wavelet_candidates(opts.wavelet):
        out, sub = _run_wavelet(method, z, wname, opts, dt_s, speed_mps, sigma_rms)
        phi = sub.get("Phi")
        if phi is None:
            phi = phi_criterion(z, out)
            sub["Phi"] = phi
            sub["phi_deg"] = _deg(phi)
        key = phi if np.isfinite(phi) else math.inf
        if best is None or key < best[0]:
            best = (key, wname, out, sub)
    _, wname, out, sub = best
    info.update(sub)
    info["wavelet"] = wname
    info["method"] = method
    if method == "ti_cosphi":
        info["context"] = context is not None
        if context is not None and info.get("n"):
            out = ti_apply_with_context(*context, wname, info["n"])
    return out, info


def _deg(phi):
    return math.degrees(math.acos(min(1.0, phi))) if phi is not None and np.isfinite(phi) else float("nan")


def _run_wavelet(method, z, wname, opts, dt_s, speed_mps, sigma_rms=None):
    def res_of_level(m):
        if not m or not (speed_mps and speed_mps > 0):
            return None
        return lowpass_resolution_m(ti_period_samples(wname, m) * dt_s, speed_mps)

    if method == "ti_cosphi":
        out, sub = ti_cosphi(z, wname, min_level=opts.min_level, max_level=opts.max_level, sigma_rms=sigma_rms)
        sub["resolution_m"] = res_of_level(sub["n"])
        return out, sub
    if method == "cosphi":
        out, sub = cosphi_search(
            z, wname, opts.boundary, opts.thresholding, steps=opts.threshold_steps, max_level=opts.max_level
        )
        sub["resolution_m"] = res_of_level(sub["levels_fully_removed"])
        return out, sub
    if method == "visushrink":
        out, sub = visushrink(z, wname, opts.boundary, opts.thresholding)
    elif method == "sure":
        out, sub = sure_shrink(z, wname, opts.boundary)
    else:
        out, sub = bayes_shrink(z, wname, opts.boundary)
    sub["n"] = len(sub["p"])
    return out, sub
