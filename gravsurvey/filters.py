"""Zero-phase low-pass filters (not wavelets): the one Gaussian low-pass, Butterworth.

The Gaussian filter of length ``L`` (the full wavelength, in time, at which the transfer function
is 0.5) has transfer function :func:`gaussian_transfer`, ``exp(-2 pi^2 s^2 f^2)`` with
``s = SIGMA_PER_LENGTH * L``.  Two implementations of that one response:

* :func:`gaussian_fir` + :func:`lowpass_valid`: the truncated FIR kernel applied forward, keeping
  the ``valid`` part (the classic chain, :mod:`gravsurvey.classic`, and tests that pass truth
  through the very same filter);
* :func:`gaussian_lowpass`: the exact response on the DCT-II grid (circular filtering of the
  mirror extension: no shortening, any length; the per-line post-processor).

:func:`butterworth_lowpass` is the forward-backward Butterworth response on the same grid;
:func:`centred_mean` the symmetric running mean (the time repair's and the IMU-gap noise's).
Everything is SI (s, Hz, m, m/s); filters are linear, so any unit of the signal works.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import fft as _sfft

from gravsurvey.errors import ConfigError, DataError

__all__ = [
    "centred_mean",
    "KERNEL_HALF_WIDTH_SIGMAS",
    "SIGMA_PER_LENGTH",
    "gaussian_transfer",
    "gaussian_fir",
    "lowpass_valid",
    "dct_filter",
    "gaussian_lowpass",
    "butterworth_lowpass",
    "lowpass_period_s",
    "lowpass_resolution_m",
]

#: Gaussian kernel truncated at this many standard deviations.
KERNEL_HALF_WIDTH_SIGMAS = 4.0
#: sigma / L for the Gaussian whose transfer function is 0.5 at period L.
SIGMA_PER_LENGTH = math.sqrt(math.log(2.0) / 2.0) / math.pi


def gaussian_fir(filter_length_s: float, dt_s: float) -> np.ndarray:
    """Zero-phase Gaussian FIR kernel.

    Parameters
    ----------
    filter_length_s : float
        L, the full wavelength (in time, s) at which the transfer function is 0.5.
    dt_s : float
        Sample step, s.

    Returns
    -------
    w : ndarray, shape (2K+1,)
        Symmetric weights summing to 1; ``K = ceil(4 s / dt)``, ``s = 0.1874 L``.
    """
    s = SIGMA_PER_LENGTH * filter_length_s
    k = max(1, math.ceil(KERNEL_HALF_WIDTH_SIGMAS * s / dt_s))
    t = np.arange(-k, k + 1) * dt_s
    w = np.exp(-0.5 * (t / s) ** 2)
    return w / w.sum()


def gaussian_transfer(freq_hz, filter_length_s: float):
    """Transfer function of the (untruncated) Gaussian filter: ``exp(-2 pi^2 s^2 f^2)``; 0.5 at f = 1/L."""
    s = SIGMA_PER_LENGTH * filter_length_s
    f = np.asarray(freq_hz, dtype=float)
    return np.exp(-2.0 * math.pi**2 * s**2 * f**2)


def lowpass_valid(x: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Apply a symmetric FIR ``w`` (length 2K+1) once, forward: the ``valid`` part, shape (m - 2K,).

    Output sample ``j`` is centred on input sample ``j + K``: no phase shift.
    """
    x = np.asarray(x, dtype=float)
    if x.shape[0] < w.shape[0]:
        raise DataError(
            f"classic: {x.shape[0]} epochs are fewer than the low-pass kernel's {w.shape[0]}; "
            "flight too short for the filter length"
        )
    if w.shape[0] > 64:
        from scipy.signal import fftconvolve  # lazily: scipy.signal costs ~0.9 s at start-up

        return fftconvolve(x, w, mode="valid")
    return np.convolve(x, w, mode="valid")


def lowpass_period_s(dt_s, speed_mps, resolution_m=None, filter_length_s=None):
    """Filter length (s) of a low-pass given as ``filter_length_s`` or as a half-wavelength
    ``resolution_m`` at ``speed_mps`` (``2 * resolution_m / speed``).

    Raises
    ------
    ConfigError
        Neither is given.
    DataError
        ``resolution_m`` with a speed that is not > 0.
    """
    if filter_length_s is not None:
        return float(filter_length_s)
    if resolution_m is None:
        raise ConfigError(
            "postprocess.resolution_m: required by the low-pass filters (or give postprocess.filter_length_s)"
        )
    if not speed_mps > 0:
        raise DataError(
            f"wavelet post-processor: line speed {speed_mps!r} m/s, expected > 0 "
            "to convert resolution_m to a filter length"
        )
    return 2.0 * float(resolution_m) / float(speed_mps)


def dct_filter(z, dt_s, response):
    """Apply a real, zero-phase frequency response on the DCT-II grid.

    DCT-II filtering is exact circular filtering of the mirror extension of the line: no phase,
    no time shift, no start-up transient, any length.

    Parameters
    ----------
    z : ndarray, shape (N,)
    dt_s : float
        Sample spacing, s.
    response : callable
        ``response(f_hz)`` -> gain, for an ndarray of frequencies (Hz), shape (N,).

    Returns
    -------
    ndarray, shape (N,)
    """
    z = np.asarray(z, dtype=float)
    n = z.size
    f = np.arange(n) / (2.0 * n * dt_s)
    return _sfft.idct(_sfft.dct(z, 2, norm="ortho") * response(f), 2, norm="ortho")


def butterworth_lowpass(z, dt_s, period_s, order=4):
    """Zero-phase Butterworth low-pass: the forward-backward response, mirror extension.

    Applies ``|H(f)|^2 = 1 / (1 + (f / fc)^(2 order))`` (the squared magnitude of the order-
    ``order`` Butterworth prototype, i.e. what forward-backward filtering applies in the steady
    state) on the DCT-II grid, which is exact circular filtering of the mirror extension of the
    line: real response, no phase, no time shift, no start-up transient, any ``N``.

    Parameters
    ----------
    z : ndarray, shape (N,)
    dt_s : float
        Sample spacing, s.
    period_s : float
        Filter length: the period (s) at which the amplitude response is 0.5 (the prototype's
        -3 dB point, ``fc = 1 / period_s``).  Half-wavelength resolution = speed * period_s / 2.
    order : int

    Returns
    -------
    ndarray, shape (N,)
    """
    return dct_filter(z, dt_s, lambda f: 1.0 / (1.0 + (f * period_s) ** (2 * int(order))))


def gaussian_lowpass(z, dt_s, period_s):
    """Zero-phase Gaussian low-pass, mirror extension, response ``exp(-2 pi^2 s^2 f^2)``.

    Parameters
    ----------
    z : ndarray, shape (N,)
    dt_s : float
        Sample spacing, s.
    period_s : float
        Period (s) at which the amplitude response is 0.5.

    Returns
    -------
    ndarray, shape (N,)
    """
    return dct_filter(z, dt_s, lambda f: gaussian_transfer(f, period_s))


def lowpass_resolution_m(period_s, speed_mps):
    """Half-wavelength resolution (m) of a filter of length ``period_s`` at ``speed_mps``."""
    return 0.5 * float(speed_mps) * float(period_s)


def centred_mean(x, width: int) -> np.ndarray:
    """Running mean of ``x`` centred on each sample over ``width`` samples (an even width: the
    mean of the two windows either side of the centre, so the kernel stays symmetric); within
    half a window of either end, the first or last full window's mean.

    Parameters
    ----------
    x : ndarray, shape (m,), m > width
    width : int, >= 1

    Returns
    -------
    ndarray, shape (m,)
    """
    x = np.asarray(x, np.float64)
    m = x.size
    c = np.concatenate([[0.0], np.cumsum(x)])
    box = (c[width:] - c[:-width]) / width  # box[j]: mean of x[j : j + width]
    if width % 2:
        mid = box
        lo = (width - 1) // 2
    else:
        mid = 0.5 * (box[:-1] + box[1:])
        lo = width // 2
    out = np.empty(m)
    out[lo : lo + mid.size] = mid
    out[:lo] = mid[0]
    out[lo + mid.size :] = mid[-1]
    return out
