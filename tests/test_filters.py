"""The zero-phase low-pass filters (gravsurvey/filters.py): one Gaussian response in both forms."""

import math

import numpy as np
import pytest

from gravsurvey import filters as F
from gravsurvey.errors import ConfigError, DataError


def _dct_cosine(n, k, dt):
    """A DCT-II basis vector (exactly one frequency of the DCT grid) and its frequency, Hz."""
    i = np.arange(n)
    return np.cos(math.pi * k * (i + 0.5) / n), k / (2.0 * n * dt)


@pytest.mark.parametrize("length_s", [50.0, 400.0])
def test_gaussian_half_gain_at_the_filter_length_in_both_forms(length_s):
    dt, n = 1.0, 4000
    assert F.gaussian_transfer(1.0 / length_s, length_s) == pytest.approx(0.5, rel=1e-12)
    k = round(2 * n * dt / length_s)  # a grid frequency at 1/L (exactly, for these L)
    x, f = _dct_cosine(n, k, dt)
    assert f == pytest.approx(1.0 / length_s, rel=1e-12)
    np.testing.assert_allclose(F.gaussian_lowpass(x, dt, length_s), 0.5 * x, atol=1e-12)
    # the FIR kernel's own DTFT at 1/L (its truncation at 4 sigma costs < 1e-3)
    w = F.gaussian_fir(length_s, dt)
    m = (w.size - 1) // 2
    dtft = float(np.sum(w * np.cos(2 * math.pi * f * dt * np.arange(-m, m + 1))))
    assert dtft == pytest.approx(0.5, abs=1e-3)


def test_fir_and_dct_gaussian_agree_inside_the_line():
    rng = np.random.default_rng(3)
    dt, length_s = 1.0, 120.0
    x = np.cumsum(rng.normal(size=3000))  # red noise: power at every period
    w = F.gaussian_fir(length_s, dt)
    k = (w.size - 1) // 2
    fir = F.lowpass_valid(x, w)
    dct = F.gaussian_lowpass(x, dt, length_s)[k:-k]
    # away from the ends (the DCT form mirrors the line there) they are the same filter
    inner = slice(3 * k, -3 * k)
    # measured 4e-5 of the signal sigma; an 8 % longer DCT filter is 1.5e-2 away
    assert np.max(np.abs(fir[inner] - dct[inner])) < 2e-4 * np.std(x)


def test_butterworth_half_gain_and_lengths():
    dt, n, period = 0.5, 2000, 100.0
    k = round(2 * n * dt / period)
    x, f = _dct_cosine(n, k, dt)
    assert f == pytest.approx(1.0 / period)
    np.testing.assert_allclose(F.butterworth_lowpass(x, dt, period, 4), 0.5 * x, atol=1e-12)
    assert F.lowpass_period_s(dt, 50.0, resolution_m=2500.0) == pytest.approx(100.0)
    assert F.lowpass_period_s(dt, 50.0, resolution_m=2500.0, filter_length_s=30.0) == 30.0
    assert F.lowpass_resolution_m(100.0, 50.0) == pytest.approx(2500.0)
    with pytest.raises(ConfigError, match="resolution_m: required"):
        F.lowpass_period_s(dt, 50.0)
    with pytest.raises(DataError, match="speed"):
        F.lowpass_period_s(dt, 0.0, resolution_m=1000.0)
