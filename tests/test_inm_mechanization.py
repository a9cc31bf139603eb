"""Mechanization against an analytic flight and against its numpy reference path."""

import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from inm_truth import parallel_flight  # noqa: E402

from gravsurvey.geodesy import WGS84  # noqa: E402
from gravsurvey.inm.mechanization import (  # noqa: E402
    initial_inertial_state,
    mechanize,
    mechanize_kernel,
    mechanize_reference,
    navigation_to_geodetic,
    rodrigues,
)
from gravsurvey.inm.params import InitialState  # noqa: E402


def _init(tr):
    return InitialState(tr["lat"][0], tr["lon"][0], tr["height"][0], tr["vel_n"][0].copy(), tr["mat_nt"][0].copy())


def _alt(tr):
    return tr["time"][::10], tr["height"][::10]


def test_rodrigues_is_exact_rotation():
    rng = np.random.default_rng(0)
    for scale in (1e-9, 1e-3, 0.5, 3.0):
        phi = rng.normal(size=3) * scale
        from scipy.spatial.transform import Rotation

        np.testing.assert_allclose(rodrigues(phi), Rotation.from_rotvec(phi).as_matrix(), atol=1e-15, rtol=0)


@pytest.mark.parametrize(
    "triad,yaw_rate",
    [("platform", 0.0), ("strapdown", 0.0), ("strapdown", 0.05)],
)
@pytest.mark.parametrize("use_ext", [True, False])
def test_noiseless_parallel_flight_one_hour(triad, yaw_rate, use_ext):
    """1 h at 10 Hz: position within 1 mm, attitude within 1e-11 rad.

    The bound: RK4 + 4th-order interpolation of the sampled specific force
    have local errors ~dt^5 * (w^4 a) with w ~ 1e-4 rad/s (negligible), so
    what is left is float64 round-off on |r| ~ 6.4e6 m (ulp 1e-9 m) over
    36000 steps and the altimeter interpolation; 1 mm leaves a large margin
    while being 300x below the 0.33 m that would cost 0.05 mGal.
    """
    tr = parallel_flight(3600.0, triad=triad, yaw_rate=yaw_rate)
    nav = mechanize(tr["time"], tr["f_t"], tr["w_t"], _init(tr), *_alt(tr), use_ext=use_ext)
    assert np.max(np.linalg.norm(nav.r_i - tr["r_i"], axis=1)) < 1e-3
    assert np.max(np.abs(nav.mat_it - tr["mat_it"])) < 1e-11
    lat, lon, h, vel_n = navigation_to_geodetic(nav.time, nav.r_i, nav.v_i)
    assert np.max(np.abs(h - 1000.0)) < 1e-3
    assert np.max(np.abs(vel_n - tr["vel_n"])) < 1e-6


def test_anomaly_drives_vertical_error_with_correct_sign():
    """A constant +10 mGal disturbance (stronger gravity) unknown to the mechanization.

    With the altimeter radius the vertical error is a Schuler oscillator
    d2e/dt2 = -w0^2 e + g: e(t) = g/w0^2 (1 - cos w0 t) >= 0, i.e. the
    computed height goes UP (the accelerometers read more than the model's
    gravity).  With the computed radius the vertical channel diverges as
    cosh: e = g/w0'^2 (cosh(w0' t) - 1), w0'^2 = 2 w0^2.
    """
    g = 10e-5
    tr = parallel_flight(1800.0, disturbance=lambda t: np.full_like(t, g))
    w0 = math.sqrt(9.80 / (6.368e6 + 1000.0))
    t = tr["time"]
    nav = mechanize(t, tr["f_t"], tr["w_t"], _init(tr), *_alt(tr), use_ext=True)
    _, _, h, _ = navigation_to_geodetic(t, nav.r_i, nav.v_i)
    e = h - 1000.0
    expect = g / w0**2 * (1 - np.cos(w0 * (t - t[0])))
    assert np.max(np.abs(e - expect)) < 0.01 * np.max(expect)
    nav = mechanize(t, tr["f_t"], tr["w_t"], _init(tr), *_alt(tr), use_ext=False)
    _, _, h, _ = navigation_to_geodetic(t, nav.r_i, nav.v_i)
    w1 = math.sqrt(2.0) * w0
    expect = g / w1**2 * (np.cosh(w1 * (t - t[0])) - 1)
    assert np.max(np.abs((h - 1000.0) - expect)) < 0.01 * np.max(expect)


@pytest.mark.parametrize("use_ext", [True, False])
def test_numba_kernel_matches_numpy_reference(use_ext):
    tr = parallel_flight(60.0, triad="strapdown", yaw_rate=0.1, disturbance=lambda t: 1e-4 * np.sin(t / 10))
    rng = np.random.default_rng(1)
    f = tr["f_t"] + rng.normal(size=tr["f_t"].shape) * 1e-3
    w = tr["w_t"] + rng.normal(size=tr["w_t"].shape) * 1e-4
    alt_t, alt_h = _alt(tr)
    alt_h = alt_h + rng.normal(size=alt_h.shape)
    a = mechanize(tr["time"], f, w, _init(tr), alt_t, alt_h, use_ext=use_ext)
    b = mechanize(tr["time"], f, w, _init(tr), alt_t, alt_h, use_ext=use_ext, reference=True)
    assert np.max(np.abs(a.r_i - b.r_i)) < 1e-6
    assert np.max(np.abs(a.v_i - b.v_i)) < 1e-9
    assert np.max(np.abs(a.mat_it - b.mat_it)) < 1e-13
    # and the noise really moved the solution away from the truth
    assert np.max(np.abs(a.r_i - tr["r_i"])) > 1e-3


def test_triad_quantities_follow_seed_equations():
    """q = C^T r, p = C^T v satisfy dq/dt = p - w x q (checked by finite differences)."""
    tr = parallel_flight(20.0, triad="strapdown", yaw_rate=0.05)
    nav = mechanize(tr["time"], tr["f_t"], tr["w_t"], _init(tr), *_alt(tr))
    q, p, w, dt = nav.q_t, nav.p_t, tr["w_t"], tr["time"][1] - tr["time"][0]
    dq = (-q[4:] + 8 * q[3:-1] - 8 * q[1:-3] + q[:-4]) / (12 * dt)
    rhs = p[2:-2] - np.cross(w[2:-2], q[2:-2])
    # 4th-order difference error ~ dt^4/30 |d5q/dt5| ~ 1e-4/30 * w^5 |q| ~ 7e-6 m/s for w = 0.05 rad/s;
    # the terms themselves are ~1000 m/s (q is nearly along the yaw axis)
    assert np.max(np.abs(rhs)) > 500.0
    assert np.max(np.abs(dq - rhs)) < 1e-3


@pytest.mark.parametrize("use_ext", [True, False])
def test_carried_gravity_remainder_against_exact_stages(use_ext):
    """One normal-gravitation evaluation per step vs four (exact stages), 10 min of a turning flight.

    10 Hz (the coarsest rate we take: the longest stage displacements, 45 m in inertial
    space), a strapdown triad turning at 0.05 rad/s, 120 m/s, sensor noise, a varying
    altimeter height.  Each stage's gravitation is off by at most 1e-12 m/s^2 per metre the
    stage moved (tests/test_geodesy.py::test_zonal4_remainder_changes_slowly), so over T the
    velocity can differ by eps T and the position by eps T^2 / 2 with eps = 1e-12 * 45 m.
    Measured: 2.7e-10 m/s and 9.4e-8 m, against bounds 2.7e-8 m/s and 8.1e-6 m.
    """
    tr = parallel_flight(
        600.0, rate_hz=10.0, triad="strapdown", yaw_rate=0.05, speed=120.0, disturbance=lambda t: 3e-4 * np.sin(t / 30)
    )
    rng = np.random.default_rng(3)
    t = tr["time"]
    f = tr["f_t"] + rng.normal(size=tr["f_t"].shape) * 1e-3
    w = tr["w_t"] + rng.normal(size=tr["w_t"].shape) * 1e-5
    alt_t = t[::10]
    alt_h = tr["height"][::10] + 5.0 * np.sin(alt_t / 20.0)
    h = np.interp(t, alt_t, alt_h)
    hm = np.interp(0.5 * (t[1:] + t[:-1]), alt_t, alt_h)
    r0, v0, c0 = initial_inertial_state(
        t[0], tr["lat"][0], tr["lon"][0], tr["height"][0], tr["vel_n"][0], tr["mat_nt"][0]
    )
    r_x, v_x, _ = mechanize_reference(t, f, w, h, hm, use_ext, r0, v0, c0, exact_stages=True)
    r_k, v_k, _ = mechanize_kernel(t, f, w, h, hm, use_ext, r0, v0, c0, *WGS84.params())
    step_m = np.max(np.linalg.norm(v_x, axis=1)) * np.max(np.diff(t)) + 0.1  # + altimeter change
    eps = 1e-12 * step_m
    span = t[-1] - t[0]
    assert step_m > 40.0
    assert np.max(np.abs(v_k - v_x)) < eps * span
    assert np.max(np.abs(r_k - r_x)) < eps * span**2 / 2.0
    # the flight is no trivial one: the noise moved it tens of metres off the truth
    assert np.max(np.abs(r_k - tr["r_i"])) > 10.0
