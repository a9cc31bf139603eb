"""Kalman filter and RTS smoother kernels vs filterpy and vs the numpy reference."""

import math

import numpy as np
import pytest
import scipy.linalg
from filterpy.kalman import KalmanFilter

from gravsurvey.inm.kalman import (
    expm,
    filter_and_smooth,
    kalman_filter,
    likelihood_gain_z,
    log_likelihood,
    rts_smoother,
    van_loan,
)


def _random_model(rng, nep=300, n=8, m=1, missing=0.1, diag=False):
    """Time-varying stable model with varied scales (like the 3D-INM state)."""
    scales = np.resize(np.array([50.0, 0.05, 50.0, 0.05, 10.0, 0.05, 1e-3, 1e-5]), n)
    phi = np.empty((nep, n, n))
    q = np.empty((nep, n, n))
    h = np.empty((nep, m, n))
    r = np.empty((nep, m, m))
    for k in range(nep):
        a = rng.normal(size=(n, n)) * 0.05 - 0.1 * np.eye(n)
        a = a * scales[:, None] / scales[None, :]
        qc = rng.normal(size=(n, n)) * 0.1
        qc = (qc @ qc.T + 0.01 * np.eye(n)) * np.outer(scales, scales) * 1e-3
        phi[k], q[k] = van_loan(a, qc, 1.0)
        h[k] = rng.normal(size=(m, n)) / scales[None, :]
        rr = rng.normal(size=(m, m)) * 0.1
        r[k] = rr @ rr.T + np.eye(m)
        if diag:  # the compiled filter's sequential scalar path
            r[k] = np.diag(np.diag(r[k]))
    x0 = rng.normal(size=n) * scales
    p0 = np.diag(scales**2)
    xs = np.empty((nep, n))
    x = x0 + rng.normal(size=n) * scales
    z = np.empty((nep, m))
    for k in range(nep):
        if k:
            x = phi[k] @ x + np.linalg.cholesky(q[k] + 1e-300 * np.eye(n)) @ rng.normal(size=n)
        xs[k] = x
        z[k] = h[k] @ x + np.linalg.cholesky(r[k]) @ rng.normal(size=m)
    z[rng.random((nep, m)) < missing] = np.nan
    return x0, p0, phi, q, z, h, r


def _filterpy(x0, p0, phi, q, z, h, r):
    n = x0.size
    m = z.shape[1]
    kf = KalmanFilter(dim_x=n, dim_z=m)
    kf.x = x0.copy()
    kf.P = p0.copy()
    xf, pf = [], []
    for k in range(phi.shape[0]):
        if k:
            kf.predict(F=phi[k], Q=q[k])
        ok = ~np.isnan(z[k])
        if ok.all():
            kf.update(z[k], R=r[k], H=h[k])
        elif ok.any():
            # filterpy has no partial update: do it with a reduced H/R
            kf2 = KalmanFilter(dim_x=n, dim_z=int(ok.sum()))
            kf2.x, kf2.P = kf.x, kf.P
            kf2.update(z[k][ok], R=r[k][np.ix_(ok, ok)], H=h[k][ok])
            kf.x, kf.P = kf2.x, kf2.P
        xf.append(kf.x.copy())
        pf.append(kf.P.copy())
    xf, pf = np.array(xf), np.array(pf)
    # KalmanFilter.rts_smoother uses Fs[k+1] as the transition k -> k+1: our phi convention
    xs, ps, _, _ = kf.rts_smoother(xf, pf, Fs=list(phi), Qs=list(q))
    return xf, pf, xs, ps


def _rel(a, b):
    return np.max(np.abs(a - b)) / np.max(np.abs(b))


def _rel_per_state(a, b):
    """Max relative difference per state component (scales differ by 1e8)."""
    if a.ndim == 2:
        s = np.max(np.abs(b), axis=0)
        return np.max(np.abs(a - b) / s)
    d = np.sqrt(np.abs(np.einsum("kii->ki", b)))
    s = np.max(d, axis=0)
    return np.max(np.abs(a - b) / (s[:, None] * s[None, :]))


@pytest.mark.parametrize("m,diag", [(1, True), (2, False), (3, True)])
def test_filter_and_smoother_match_filterpy(m, diag):
    rng = np.random.default_rng(4 + m)
    model = _random_model(rng, m=m, diag=diag)
    ours = filter_and_smooth(*model)
    xf, pf, xs, ps = _filterpy(*model)
    assert _rel_per_state(ours["x_f"], xf) < 1e-9
    assert _rel_per_state(ours["p_f"], pf) < 1e-9
    assert _rel_per_state(ours["x_s"], xs) < 1e-9
    assert _rel_per_state(ours["p_s"], ps) < 1e-9
    # the smoother must actually change something, and reduce variances
    assert _rel_per_state(ours["x_s"], ours["x_f"]) > 1e-3
    vf = np.einsum("kii->ki", ours["p_f"])
    vs = np.einsum("kii->ki", ours["p_s"])
    assert np.all(vs <= vf * (1 + 1e-9))


@pytest.mark.parametrize("diag", [False, True])
def test_numba_matches_numpy_reference(diag):
    rng = np.random.default_rng(11)
    model = _random_model(rng, nep=200, m=2, missing=0.3, diag=diag)
    a = filter_and_smooth(*model)
    b = filter_and_smooth(*model, reference=True)
    for key in ("x_f", "p_f", "x_s", "p_s"):
        assert _rel_per_state(a[key], b[key]) < 1e-10, key
    ok = ~np.isnan(b["innov"])
    assert np.array_equal(ok, ~np.isnan(a["innov"]))
    assert np.max(np.abs(a["innov"][ok] - b["innov"][ok])) < 1e-8


@pytest.mark.parametrize("n,m,diag", [(14, 3, True), (14, 2, False), (5, 1, True), (13, 2, True)])
def test_other_state_sizes_match_filterpy_and_reference(n, m, diag):
    """The 14-state (GNSS-aided) size and sizes that exercise every column-block remainder."""
    rng = np.random.default_rng(100 + n + m)
    model = _random_model(rng, nep=150, n=n, m=m, missing=0.2, diag=diag)
    ours = filter_and_smooth(*model)
    ref = filter_and_smooth(*model, reference=True)
    xf, pf, xs, ps = _filterpy(*model)
    for key, other in (("x_f", xf), ("p_f", pf), ("x_s", xs), ("p_s", ps)):
        assert _rel_per_state(ours[key], other) < 1e-9, key
        assert _rel_per_state(ours[key], ref[key]) < 1e-10, key
    assert _rel_per_state(ours["x_s"], ours["x_f"]) > 1e-3


def test_public_kernels_equal_the_fused_pipeline_path():
    """kalman_filter + rts_smoother (smoother recomputes phi P_f) == filter_and_smooth (reuses it)."""
    rng = np.random.default_rng(21)
    model = _random_model(rng, nep=120, m=2, missing=0.3, diag=True)
    fused = filter_and_smooth(*model)
    x_f, p_f, x_p, p_p, innov = kalman_filter(*model)
    x_s, p_s = rts_smoother(x_f, p_f, x_p, p_p, model[2])
    for key, val in (("x_f", x_f), ("p_f", p_f), ("x_p", x_p), ("p_p", p_p), ("x_s", x_s), ("p_s", p_s)):
        assert np.array_equal(fused[key], val), key
    assert np.array_equal(fused["innov"], innov, equal_nan=True)
    # and the smoother really used the epochs' own transitions: a wrong phi changes x_s
    x_s2, _ = rts_smoother(x_f, p_f, x_p, p_p, model[2][::-1].copy())
    assert _rel_per_state(x_s2, x_s) > 1e-6


def test_filterpy_module_smoother_indexing_differs():
    """filterpy's module-level rts_smoother uses Fs[k] for k -> k+1: shifted by one vs the method."""
    from filterpy.kalman import rts_smoother

    rng = np.random.default_rng(2)
    x0, p0, phi, q, z, h, r = _random_model(rng, nep=100)
    ours = filter_and_smooth(x0, p0, phi, q, z, h, r)
    xs, ps, _, _ = rts_smoother(ours["x_f"], ours["p_f"], phi[1:], q[1:])
    assert _rel_per_state(ours["x_s"][:-1], xs[:-1]) < 1e-9


def test_expm_and_van_loan_against_scipy():
    rng = np.random.default_rng(3)
    for scale in (1e-3, 1.0, 30.0):
        a = rng.normal(size=(8, 8)) * scale
        assert _rel(expm(a), scipy.linalg.expm(a)) < 1e-11
    # Van Loan vs direct quadrature of int expm(As) Qc expm(As)^T ds
    a = rng.normal(size=(4, 4)) * 0.3
    qc = np.diag([1.0, 2.0, 0.5, 0.1])
    phi, qd = van_loan(a, qc, 2.0)
    s = np.linspace(0, 2.0, 2001)
    vals = np.array([scipy.linalg.expm(a * t) @ qc @ scipy.linalg.expm(a * t).T for t in s])
    quad = scipy.integrate.simpson(vals, x=s, axis=0)
    assert _rel(phi, scipy.linalg.expm(2.0 * a)) < 1e-12
    assert _rel(qd, quad) < 1e-9


@pytest.mark.parametrize("n", [5, 8, 14])
def test_block_van_loan_equals_the_full_matrix_exponential(n):
    """van_loan works on the blocks of the 2n x 2n Van Loan matrix (generated vector products
    for n = 8 and 14, the generic loops otherwise): same result as scipy's expm of the whole
    matrix, with and without the scaling-and-squaring steps."""
    rng = np.random.default_rng(n)
    for scale, dt in ((1e-4, 1.0), (0.05, 1.0), (0.3, 2.0), (3.0, 1.0), (0.4, 4.0)):
        a = rng.normal(size=(n, n)) * scale
        qc = rng.normal(size=(n, n))
        qc = qc @ qc.T * scale  # 1e-4: no squaring (|M| < 0.25); the others need it
        m = np.zeros((2 * n, 2 * n))
        m[:n, :n], m[:n, n:], m[n:, n:] = -a * dt, qc * dt, a.T * dt
        e = scipy.linalg.expm(m)
        phi_ref = e[n:, n:].T
        qd_ref = phi_ref @ e[:n, n:]
        phi, qd = van_loan(a, qc, dt)
        assert _rel(phi, phi_ref) < 1e-12, scale
        assert _rel(qd, 0.5 * (qd_ref + qd_ref.T)) < 1e-12, scale
        assert np.array_equal(qd, qd.T)


@pytest.mark.parametrize("n", [8, 14])
def test_generated_matmul_equals_generic_loops_bit_for_bit(n):
    from gravsurvey.inm import _unrolled
    from gravsurvey.inm import kalman as K

    rng = np.random.default_rng(n)
    a, b = rng.normal(size=(2, n, n)) * np.logspace(-8, 3, n)
    a[0, 1] = -0.0
    out, ref = np.empty((n, n)), np.empty((n, n))
    getattr(_unrolled, f"matmul{n}")(a, b, out)
    K._matmul(a, b, ref, False)
    assert np.array_equal(_bits(out), _bits(ref))
    assert _rel(out, a @ b) < 1e-13


def test_real_inm_model_sequences_match_filterpy():
    """The badly scaled 3D-INM model itself (metres next to 1e-6 m/s^2), 20 min of noisy data."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).parent))
    from inm_truth import parallel_flight

    from gravsurvey.inm.errormodel import AltimeterMeasurement, discretise, epoch_geometry, initial_covariance
    from gravsurvey.inm.mechanization import mechanize
    from gravsurvey.inm.params import InitialState, InmParams

    tr = parallel_flight(1200.0, triad="strapdown", yaw_rate=0.01, disturbance=lambda t: 3e-4 * np.sin(t / 200))
    rng = np.random.default_rng(5)
    f = tr["f_t"] + rng.normal(size=tr["f_t"].shape) * 3e-3
    alt_t, alt_h = tr["time"][::10], tr["height"][::10] + rng.normal(size=tr["time"][::10].size)
    init = InitialState(tr["lat"][0], tr["lon"][0], 1000.0, tr["vel_n"][0], tr["mat_nt"][0])
    nav = mechanize(tr["time"], f, tr["w_t"], init, alt_t, alt_h)
    idx = np.arange(0, tr["time"].size, 10)
    p = InmParams()
    phi, q = discretise(epoch_geometry(nav, idx), p, 1.0)
    z, h, r = AltimeterMeasurement(alt_t, alt_h, 1.0).build(nav, idx, 0.5)
    model = (np.zeros(8), initial_covariance(p), phi, q, z, h, r)
    ours = filter_and_smooth(*model)
    xf, pf, xs, ps = _filterpy(*model)
    for a, b in ((ours["x_f"], xf), (ours["p_f"], pf), (ours["x_s"], xs), (ours["p_s"], ps)):
        assert _rel_per_state(a, b) < 1e-9


# --------------------------------------------------------------------------
# Generated vector steps for 8 states (gravsurvey.inm._unrolled) vs the generic loops
# --------------------------------------------------------------------------


def _bits(a):
    """Bit patterns, so that even the sign of a zero or the payload of a NaN must agree."""
    return np.ascontiguousarray(a).view(np.uint64)


def test_generated_module_is_what_the_generator_writes():
    from gravsurvey.inm import codegen

    assert codegen.TARGET.read_text() == codegen.generate()


def _ins_zeros(model):
    """Zero the entries that are structurally zero in the 14-state INS error model's ``phi``
    (gravity, f3 and gyro-bias rows diagonal, attitude rows only attitude and gyro bias) and
    some columns of ``h``: the vector steps skip zero coefficients, which must not change a bit."""
    model = list(model)
    phi = model[2].copy()
    diag = np.einsum("kii->ki", phi).copy()
    phi[:, 6:, :] = 0.0
    phi[:, 8:11, 8:] = model[2][:, 8:11, 8:]
    np.einsum("kii->ki", phi)[:, 6:] = diag[:, 6:]
    h = model[5].copy()
    h[:, :, 1::3] = 0.0
    model[2], model[5] = phi, h
    return model


@pytest.mark.parametrize(
    "n,m,missing,mixed",
    [(8, 1, 0.1, False), (8, 2, 0.3, False), (8, 3, 0.2, True), (8, 2, 1.0, False), (8, 4, 0.0, True)]
    + [(14, 1, 0.1, False), (14, 2, 0.3, False), (14, 3, 0.2, True), (14, 2, 1.0, False), (14, 4, 0.0, True)],
)
def test_unrolled_steps_equal_the_generic_loops_bit_for_bit(n, m, missing, mixed):
    """Same model through the fixed-size vector steps (generated for 8 states, gravsurvey.inm._unrolled;
    loops for 14, gravsurvey.inm.kalman14) and through the generic loops.

    ``mixed``: every third epoch has a non-diagonal R (that epoch falls back to the generic
    batch update inside the same run); ``missing=1.0``: prediction-only epochs.  For 14 states,
    the INS model's structural zeros in ``phi`` and ``h`` (skipped by the vector steps).
    """
    rng = np.random.default_rng(40 + m + n)
    model = list(_random_model(rng, nep=240, n=n, m=m, missing=missing, diag=True))
    if n == 14:
        model = _ins_zeros(model)
    if mixed:
        r = model[6].copy()
        r[::3, 0, 1] = r[::3, 1, 0] = 0.3
        model[6] = r
    a = filter_and_smooth(*model)
    b = filter_and_smooth(*model, unrolled=False)
    for key in a:
        assert np.array_equal(_bits(a[key]), _bits(b[key])), key
    # the public kernels (the smoother recomputes phi P_f) take the same steps
    fa = kalman_filter(*model)
    fb = kalman_filter(*model, unrolled=False)
    for u, v in zip(fa, fb):
        assert np.array_equal(_bits(u), _bits(v))
    sa = rts_smoother(*fa[:4], model[2])
    sb = rts_smoother(*fb[:4], model[2], unrolled=False)
    for u, v in zip(sa, sb):
        assert np.array_equal(_bits(u), _bits(v))
    if missing < 1.0:
        assert _rel_per_state(a["x_s"], a["x_f"]) > 1e-3


@pytest.mark.parametrize("n", [8])
def test_unrolled_steps_directly_against_the_generic_step_functions(n):
    """One filter epoch and one smoother epoch through filter_step{n} / rts_step{n} themselves."""
    from gravsurvey.inm import _unrolled
    from gravsurvey.inm import kalman as K

    filter_step = getattr(_unrolled, f"filter_step{n}")
    rts_step = getattr(_unrolled, f"rts_step{n}")
    rng = np.random.default_rng(8)
    x0, p0, phi, q, z, h, r = _random_model(rng, nep=3, n=n, m=2, missing=0.0, diag=True)
    x_f, p_f, x_p, p_p, innov = K.kalman_filter(x0, p0, phi, q, z, h, r, unrolled=False)
    # epoch 2 again, with the generated step
    x_f2, p_f2, x_p2, p_p2, innov2 = x_f.copy(), p_f.copy(), x_p.copy(), p_p.copy(), innov.copy()
    for arr in (x_f2, p_f2, x_p2, p_p2, innov2):
        arr[2] = np.nan
    phi_pf = np.empty((1, n, n))
    filter_step(2, phi, q, z, h, r, x_f2, p_f2, x_p2, p_p2, innov2, phi_pf, 0)
    for u, v in ((x_f2, x_f), (p_f2, p_f), (x_p2, x_p), (p_p2, p_p), (innov2, innov)):
        assert np.array_equal(_bits(u), _bits(v))
    expected = np.empty((n, n))
    K._matmul(phi[2], p_f[1], expected, False)
    assert np.array_equal(_bits(phi_pf[0]), _bits(expected))
    # the smoother step for epoch 1 from epoch 2
    x_s, p_s = K.rts_smoother(x_f, p_f, x_p, p_p, phi, unrolled=False)
    x_s2, p_s2 = x_s.copy(), p_s.copy()
    x_s2[1] = p_s2[1] = np.nan
    a = np.empty((1, n, n))
    K._matmul(phi[2], p_f[1], a[0], False)
    rts_step(1, x_f, p_f, x_p, p_p, a, 0, x_s2, p_s2)
    assert np.array_equal(_bits(x_s2), _bits(x_s))
    assert np.array_equal(_bits(p_s2), _bits(p_s))


def test_outputs_are_separate_aligned_arrays():
    from gravsurvey.inm import kalman as K

    shapes = ((300, 14), (300, 14, 14), (300, 3), (0, 14))
    arrays = K._outputs(shapes)
    for a, shape in zip(arrays, shapes):
        assert a.shape == shape and a.dtype == np.float64 and a.flags.c_contiguous and a.flags.writeable
        assert a.size == 0 or a.ctypes.data % 64 == 0
    assert arrays[0].ctypes.data % (2 << 20) == 0
    for i, a in enumerate(arrays):  # no overlap: each keeps what was written into it
        a[...] = i
    for i, a in enumerate(arrays):
        assert np.all(a == i)


def test_non_contiguous_inputs_are_accepted():
    rng = np.random.default_rng(9)
    model = _random_model(rng, nep=60, n=8, m=2, missing=0.2, diag=True)
    a = filter_and_smooth(*model)
    fortran = [np.asfortranarray(x) for x in model]
    strided = [np.repeat(x, 2, axis=0)[::2] if x.ndim > 1 else x for x in fortran]
    for args in (fortran, strided):
        out = kalman_filter(*args)
        assert np.array_equal(out[0], a["x_f"]) and np.array_equal(out[1], a["p_f"])
        x_s, p_s = rts_smoother(*[np.asfortranarray(o) for o in out[:4]], np.asfortranarray(model[2]))
        assert np.array_equal(x_s, a["x_s"]) and np.array_equal(p_s, a["p_s"])


def _aided_model(duration_s=600.0, seed=6):
    """The GNSS-aided (errormodel.N_STATE_AIDED) model as gravsurvey.inm.solve builds it, on an
    analytic flight with noisy sensors, and ``(T, T^-1)`` of its true-error basis."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).parent))
    from inm_truth import parallel_flight

    from gravsurvey.inm.errormodel import (
        N_STATE_AIDED,
        AltimeterMeasurement,
        GnssMeasurement,
        discretise,
        epoch_geometry,
        initial_covariance,
        true_error_basis,
    )
    from gravsurvey.inm.mechanization import mechanize
    from gravsurvey.inm.params import InitialState, InmParams
    from gravsurvey.inm.solve import stack_measurements

    tr = parallel_flight(duration_s, disturbance=lambda t: 3e-4 * np.sin(t / 200))
    rng = np.random.default_rng(seed)
    f = tr["f_t"] + rng.normal(size=tr["f_t"].shape) * 3e-3
    t1 = tr["time"][::10]
    alt_h = tr["height"][::10] + rng.normal(size=t1.size)
    init = InitialState(tr["lat"][0], tr["lon"][0], 1000.0, tr["vel_n"][0], tr["mat_nt"][0])
    nav = mechanize(tr["time"], f, tr["w_t"], init, t1, alt_h)
    idx = np.arange(0, tr["time"].size, 10)
    p = InmParams()
    n = N_STATE_AIDED
    phi, q = discretise(epoch_geometry(nav, idx), p, 1.0, aided=True)
    gn = GnssMeasurement(
        t1,
        tr["lat"][::10] + rng.normal(size=t1.size) / 6.4e6,
        tr["lon"][::10] + rng.normal(size=t1.size) / 4.5e6,
        tr["height"][::10] + 2.0 * rng.normal(size=t1.size),
        1.0,
        2.0,
    )
    z, h, r = stack_measurements(
        [AltimeterMeasurement(t1, alt_h, 1.0).build(nav, idx, 0.5, n), gn.build(nav, idx, 0.5, n)]
    )
    c = nav.mat_it[idx[0]]
    model = (np.zeros(n), initial_covariance(p, c.T @ nav.r_i[idx[0]], c.T @ nav.v_i[idx[0]]), phi, q, z, h, r)
    c = nav.mat_it[idx]
    basis = true_error_basis(np.einsum("nji,nj->ni", c, nav.r_i[idx]), np.einsum("nji,nj->ni", c, nav.v_i[idx]))
    return model, basis


def _sigmas(a, b, p_b):
    """Largest difference in units of each epoch's own sigmas (covariances: sigma_i sigma_j)."""
    sd = np.sqrt(np.einsum("kii->ki", p_b))
    if a.ndim == 2:
        return np.max(np.abs(a - b) / sd)
    return np.max(np.abs(a - b) / (sd[:, :, None] * sd[:, None, :]))


def test_gnss_aided_14_state_model_matches_filterpy_to_1e9_in_the_true_error_basis():
    """The filter a default (GNSS-aided) run uses, against filterpy on identical Phi, Q, H, R, x0,
    P0 and z (missing epochs and missing components included).  In the pipeline's basis the two
    cannot agree to 1e-9 (nearly singular covariance: see the next test and docs/benchmarks.md);
    in the true-error basis, the same model, they agree to rounding."""
    from gravsurvey.inm.errormodel import N_STATE_AIDED
    from gravsurvey.inm.kalman import change_basis, restore_basis

    model, (t, t_inv) = _aided_model(400.0, 7)
    assert model[0].size == N_STATE_AIDED and model[4].shape[1] == 4
    z = model[4].copy()
    z[::7, 1:] = np.nan  # no GNSS at these epochs
    z[::11, 0] = np.nan  # no altimeter
    z[3::13, 2] = np.nan  # one GNSS component missing: a partial update
    model = model[:4] + (z,) + model[5:]
    x0, p0, phi, q, h = change_basis(t, t_inv, model[0], model[1], model[2], model[3], model[5])
    basis_model = (x0, p0, phi, q, z, h, model[6])
    ours = filter_and_smooth(*basis_model)
    xf, pf, xs, ps = _filterpy(*basis_model)
    for key, other in (("x_f", xf), ("p_f", pf), ("x_s", xs), ("p_s", ps)):
        assert _rel_per_state(ours[key], other) < 1e-9, key
    assert _rel_per_state(ours["x_s"], ours["x_f"]) > 1e-3  # the smoother did something
    # the same filter: mapped back, the estimate is the pipeline-basis one (to that basis' rounding)
    plain = filter_and_smooth(*model)
    x_back, p_back = restore_basis(t_inv, ours["x_s"], ours["p_s"])
    assert _sigmas(x_back, plain["x_s"], plain["p_s"]) < 1e-5
    assert _sigmas(p_back, plain["p_s"], plain["p_s"]) < 1e-3


@pytest.mark.skipif(np.finfo(np.longdouble).eps > 1e-18, reason="needs an extended-precision np.longdouble")
def test_gnss_aided_14_state_smoother_matches_extended_precision():
    """In the pipeline's basis the 14-state GNSS-aided model is badly conditioned (the seed's dq
    carries the attitude error times the Earth's radius: smallest correlation eigenvalue ~1e-6,
    variances from 1e7 m^2 down to 1e-18 rad^2/s^2).  Our compiled path (scaled Cholesky in
    the smoother, scalar Joseph updates) must stay on the extended-precision answer;
    double-precision inverse-based smoothers (filterpy, our numpy reference) do not."""
    from gravsurvey.inm.kalman import filter_and_smooth_exact

    model, _ = _aided_model(600.0, 6)
    _, _, xs, ps = filter_and_smooth_exact(*model)

    def errors(x, pcov):
        return _sigmas(x, xs, ps), _sigmas(pcov, ps, ps)

    ours = filter_and_smooth(*model)
    ex, ep = errors(ours["x_s"], ours["p_s"])
    assert ex < 1e-5 and ep < 1e-4, (ex, ep)
    # the generic loops are the same numbers (the vector steps of gravsurvey.inm.kalman14, to the
    # bit); the numpy reference shows the problem is hard
    generic = filter_and_smooth(*model, unrolled=False)
    for key in ours:
        assert np.array_equal(_bits(generic[key]), _bits(ours[key])), key
    ref = filter_and_smooth(*model, reference=True)
    assert errors(ref["x_s"], ref["p_s"])[1] > 100 * ep


@pytest.mark.parametrize("diag", [True, False])
def test_log_likelihood_is_the_joint_gaussian_density_of_the_measurements(diag):
    # the prediction-error decomposition: the filter's innovations and their covariances give
    # the log density of all the measurements at once, computed here from their joint
    # covariance (every measurement a linear map of the initial error, the process and the
    # measurement noises)
    rng = np.random.default_rng(11)
    n, m, nep = 4, 2, 40
    x0, p0, phi, q, z, h, r = _random_model(rng, nep=nep, n=n, m=m, missing=0.2, diag=diag)
    out = filter_and_smooth(x0, p0, phi, q, z, h, r)
    terms = log_likelihood(out["p_p"], out["innov"], z, h, r)
    ll = terms.sum()
    n_w = n * nep + m * nep
    a = np.zeros((nep * m, n_w))  # z - mean = a w
    res_k = np.empty((nep, m))
    cov_w = np.zeros((n_w, n_w))
    cov_w[:n, :n] = p0
    for k in range(1, nep):
        cov_w[k * n : (k + 1) * n, k * n : (k + 1) * n] = q[k]
    for k in range(nep):
        j = n * nep + k * m
        cov_w[j : j + m, j : j + m] = r[k]
    state = np.zeros((n, n_w))  # x_k - its mean as a map of w
    state[:, :n] = np.eye(n)
    mean = np.array(x0, float)
    for k in range(nep):
        if k:
            state = phi[k] @ state
            state[:, k * n : (k + 1) * n] += np.eye(n)
            mean = phi[k] @ mean
        a[k * m : (k + 1) * m] = h[k] @ state
        a[k * m : (k + 1) * m, n * nep + k * m : n * nep + (k + 1) * m] = np.eye(m)
        res_k[k] = z[k] - h[k] @ mean
    ok = np.isfinite(z.ravel())
    a = a[ok]
    cov_z = a @ cov_w @ a.T
    res = res_k.ravel()[ok]
    _, logdet = np.linalg.slogdet(cov_z)
    expected = -0.5 * (logdet + res @ np.linalg.solve(cov_z, res))
    # an epoch without a measurement adds nothing
    assert np.all(terms[~np.isfinite(z).any(axis=1)] == 0.0)
    assert ll == pytest.approx(expected, rel=1e-9, abs=1e-6)
    # and it ranks models: a random walk measured in white noise, its step variance found
    # back by the likelihood within 20 % from 2000 epochs (a tenth or ten times it far less likely)
    rng = np.random.default_rng(3)
    nep, q_true = 2000, 0.1
    walk = np.cumsum(rng.normal(scale=math.sqrt(q_true), size=nep))
    z1 = (walk + rng.normal(size=nep))[:, None]
    h1, r1 = np.ones((nep, 1, 1)), np.ones((nep, 1, 1))
    scales = np.geomspace(0.1, 10.0, 41)
    lls = []
    for scale in scales:
        q1 = np.full((nep, 1, 1), q_true * scale)
        o = filter_and_smooth(np.zeros(1), np.eye(1), np.ones((nep, 1, 1)), q1, z1, h1, r1)
        lls.append(log_likelihood(o["p_p"], o["innov"], z1, h1, r1))
    totals = [t.sum() for t in lls]
    i_best = int(np.argmax(totals))
    assert 0.8 < scales[i_best] < 1.25
    assert totals[i_best] - totals[0] > 50.0 and totals[i_best] - totals[-1] > 50.0
    # how clearly, in standard errors of the per-epoch differences: ten times off by many,
    # a neighbour on the grid (12 % off) by less than two
    i_true = int(np.argmin(np.abs(np.log(scales))))
    assert likelihood_gain_z(lls[i_true], lls[-1]) > 5.0
    assert likelihood_gain_z(lls[i_true], lls[0]) > 5.0
    assert abs(likelihood_gain_z(lls[i_true], lls[i_true + 1])) < 2.0
    assert likelihood_gain_z(lls[-1], lls[i_true]) == pytest.approx(-likelihood_gain_z(lls[i_true], lls[-1]))
    assert math.isnan(likelihood_gain_z(lls[i_true], lls[i_true]))
    assert math.isnan(likelihood_gain_z(lls[i_true], lls[i_true][:-1]))
