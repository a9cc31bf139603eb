"""The stated sigma includes the gravimeter drift the smoother cannot tell from the field
(gravsurvey/inm/identify.py ``drift_sigma_passed``, gravsurvey/estimate.py; issue 12 item 2)."""

import math
import types

import numpy as np
import pytest

from gravsurvey.estimate import from_inm_solution
from gravsurvey.geodesy import MGAL
from gravsurvey.inm import identify as I


def _report(anomaly_sigma, anomaly_tau, white=1e-5, height=0.05, dt_h=1.0):
    model = I.SpectralModel(anomaly_sigma, anomaly_tau, white, height)
    return {"spectral_model": dict(model.__dict__), "height_dt_s": dt_h}


def test_a_wide_prior_passes_the_whole_drift_but_its_flight_mean():
    # H ~ 1 at every frequency the drift has: its variance less the part constant over the span
    sig, tau, span = 1.0 * MGAL, 600.0, 1.0e6
    out = I.drift_sigma_passed(_report(1.0, 1e5, white=1e-9, height=1e-6), span, sig, tau)
    assert out == pytest.approx(sig, rel=0.02)
    # over a span of 4 tau the flight mean takes a known part: E[var about the mean] of a
    # Gauss-Markov record, 1 - 2/x + 2 (1 - exp(-x)) / x^2 with x = span / tau (here the kernel
    # 1 - sinc^2 is the continuous-time approximation of it, within 5 %)
    x = 4.0
    expect = sig * math.sqrt(1.0 - 2.0 / x + 2.0 * (1.0 - math.exp(-x)) / x**2)
    got = I.drift_sigma_passed(_report(1.0, 1e5, white=1e-9, height=1e-6), x * tau, sig, tau)
    assert got == pytest.approx(expect, rel=0.05)


def test_a_narrow_prior_passes_less_and_the_result_grows_with_the_prior():
    sig, tau, span = 1.0 * MGAL, 600.0, 3600.0
    vals = [I.drift_sigma_passed(_report(s * MGAL, 60.0), span, sig, tau) for s in (0.01, 0.1, 1.0, 10.0, 100.0)]
    assert all(b >= a for a, b in zip(vals[:-1], vals[1:]))
    assert vals[0] < 0.05 * sig < vals[-1]
    assert I.drift_sigma_passed({}, span) == 0.0


def _solution(sigma, extra):
    n = sigma.size
    z = np.zeros(n)
    ident = {} if extra is None else {"drift_sigma_passed_mps2": extra}
    return types.SimpleNamespace(
        time=np.arange(n, dtype=float),
        lat=z,
        lon=z,
        height=z,
        vel_n=np.column_stack([z + 50.0, z, z]),
        speed=z + 50.0,
        g_smooth=z,
        g_forward=z,
        sigma_smooth=sigma,
        identification=ident,
    )


def test_product_sigma_adds_the_passed_drift_in_quadrature():
    s = np.array([0.3, 0.4, 0.5]) * MGAL
    est = from_inm_solution(_solution(s, 0.4 * MGAL))
    assert np.allclose(est.sigma, np.hypot(s, 0.4 * MGAL), atol=0.0)
    assert np.array_equal(from_inm_solution(_solution(s, None)).sigma, s)


def test_product_sigma_adds_the_missed_field_too():
    s = np.array([0.3, 0.4, 0.5]) * MGAL
    sol = _solution(s, 0.4 * MGAL)
    sol.identification["field_sigma_missed_mps2"] = 0.3 * MGAL
    assert np.allclose(from_inm_solution(sol).sigma, np.sqrt(s**2 + (0.4 * MGAL) ** 2 + (0.3 * MGAL) ** 2), atol=0.0)
