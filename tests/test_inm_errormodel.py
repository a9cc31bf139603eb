"""Error model: signs and transition matrices checked against the nonlinear mechanization."""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from inm_truth import parallel_flight  # noqa: E402

from gravsurvey.inm.errormodel import (  # noqa: E402
    DP,
    DQ,
    F3,
    G,
    TH,
    AltimeterMeasurement,
    discretise,
    epoch_geometry,
    initial_covariance,
)
from gravsurvey.inm.mechanization import mechanize  # noqa: E402
from gravsurvey.inm.params import InitialState, InmParams  # noqa: E402


def test_state_indices_are_seed_order():
    assert list(DQ) == [0, 2, 4] and list(DP) == [1, 3, 5] and (G, F3) == (6, 7)
    p = initial_covariance(InmParams())
    np.testing.assert_allclose(np.diag(p), [2500.0, 0.0025, 2500.0, 0.0025, 2500.0, 0.0025, 1e-6, 1e-10], rtol=1e-12)


@pytest.mark.parametrize(
    "triad,yaw_rate,radius_source",
    [
        ("platform", 0.0, "altimeter"),
        ("strapdown", 0.02, "altimeter"),
        ("strapdown", 0.02, "computed"),
    ],
)
def test_transition_matrices_predict_nonlinear_error_propagation(triad, yaw_rate, radius_source):
    """Perturb the initial state, add an unknown constant disturbance g and a gravimeter bias f3.

    The mechanized solution minus the truth, resolved on the triad, must follow
    x_k = Phi_k ... Phi_1 x_0 (with lambda_s = lambda_f3 = 0 so g and f3 are constants).
    """
    g, f3 = 20e-5, -5e-5
    tr = parallel_flight(900.0, triad=triad, yaw_rate=yaw_rate, disturbance=lambda t: np.full_like(t, g))
    f_t = tr["f_t"].copy()
    f_t[:, 2] += f3
    c0 = tr["mat_it"][0]
    dq0 = np.array([3.0, -2.0, 1.5])
    dp0 = np.array([0.01, 0.02, -0.01])
    # perturbed initial state: r_i = C (q + dq), v_i = C (p + dp); v_i enters through vel_n
    from gravsurvey.geodesy import ecef_to_geodetic, mat_en, mat_ie

    r_pert = tr["r_i"][0] + c0 @ dq0
    lat, lon, h = ecef_to_geodetic(r_pert)
    m_ie = mat_ie(tr["time"][0])
    r_e0 = m_ie.T @ tr["r_i"][0]
    v_true_i = m_ie @ (mat_en(tr["lat"][0], tr["lon"][0]) @ tr["vel_n"][0] + np.cross([0, 0, 7.292115e-5], r_e0))
    v_pert_i = v_true_i + c0 @ dp0
    v_e = m_ie.T @ v_pert_i - np.cross([0, 0, 7.292115e-5], m_ie.T @ r_pert)
    m_ne = mat_en(lat, lon).T
    init = InitialState(float(lat), float(lon), float(h), m_ne @ v_e, m_ne @ m_ie.T @ c0)
    use_ext = radius_source == "altimeter"
    alt_t, alt_h = tr["time"][::10], tr["height"][::10]
    nav = mechanize(tr["time"], f_t, tr["w_t"], init, alt_t, alt_h, use_ext=use_ext)
    idx = np.arange(0, tr["time"].size, 10)
    params = InmParams(anomaly_lambda_per_m=0.0, gravimeter_lambda_per_s=0.0, radius_source=radius_source)
    phi, _ = discretise(epoch_geometry(nav, idx, use_ext), params, 1.0)
    # true error on the triad (computed attitude = true attitude: no gyro errors)
    np.testing.assert_allclose(nav.mat_it, tr["mat_it"], atol=1e-11)
    dr = nav.r_i[idx] - tr["r_i"][idx]
    x = np.zeros(8)
    x[DQ], x[DP], x[G], x[F3] = dq0, dp0, g, f3
    pred = [x]
    for k in range(1, idx.size):
        x = phi[k] @ x
        pred.append(x)
    pred = np.array(pred)
    dq_true = np.einsum("nji,nj->ni", tr["mat_it"][idx], dr)
    err = pred[:, DQ] - dq_true
    # linearisation + the neglected ellipsoid terms of the gradient: measured 3e-4 .. 5e-4 of the error
    scale = np.max(np.abs(dq_true))
    assert scale > 10.0  # the error really grew (g/w0^2 scale)
    assert np.max(np.abs(err)) < 2e-3 * scale
    # measurement model: z = |q| - R_ext = cos(a) n . dq (altimeter exact here)
    z, h, _ = AltimeterMeasurement(alt_t, alt_h, 1.0).build(nav, idx, 0.5)
    zt = np.einsum("kj,kj->k", h[:, 0, DQ], dq_true)
    zp = np.einsum("kj,kj->k", h[:, 0, :], pred)
    assert np.max(np.abs(z[:, 0] - zt)) < 1e-4  # measured 1.8e-5 m
    assert np.max(np.abs(z[:, 0] - zp)) < 0.01 * np.max(np.abs(zt))


def test_discretise_kernel_matches_reference():
    tr = parallel_flight(120.0, triad="strapdown", yaw_rate=0.05)
    init = InitialState(tr["lat"][0], tr["lon"][0], 1000.0, tr["vel_n"][0], tr["mat_nt"][0])
    nav = mechanize(tr["time"], tr["f_t"], tr["w_t"], init, tr["time"][::10], tr["height"][::10])
    idx = np.arange(0, tr["time"].size, 10)
    for rs in ("altimeter", "computed"):
        p = InmParams(radius_source=rs, gravimeter_white_mps2=1e-5)
        geom = epoch_geometry(nav, idx, rs == "altimeter")
        a_phi, a_q = discretise(geom, p, 1.0)
        b_phi, b_q = discretise(geom, p, 1.0, reference=True)
        np.testing.assert_allclose(a_phi, b_phi, rtol=0, atol=1e-12 * np.max(np.abs(b_phi)))
        sc = np.sqrt(np.abs(np.einsum("kii->ki", b_q[1:]))).max(axis=0) + 1e-300
        assert np.max(np.abs(a_q[1:] - b_q[1:]) / np.outer(sc, sc)) < 1e-10
        # noise enters the right states: Markov variance growth 2 lambda sigma^2 dt
        lam_g = p.anomaly_lambda_per_m * geom.speed[5]
        assert a_q[5, G, G] == pytest.approx(p.anomaly_sigma_mps2**2 * (1 - np.exp(-2 * lam_g)), rel=1e-9, abs=0.0)
        assert a_q[5, F3, F3] == pytest.approx(p.gravimeter_sigma_mps2**2 * (1 - np.exp(-2 * 0.025)), rel=1e-9, abs=0.0)


def test_altimeter_measurement_assignment_and_missing():
    tr = parallel_flight(30.0)
    init = InitialState(tr["lat"][0], tr["lon"][0], 1000.0, tr["vel_n"][0], tr["mat_nt"][0])
    alt_t = np.array([0.0, 1.2, 2.0, 2.1, 5.0, 40.0])
    alt_h = np.array([1000.0, 1001.0, 999.0, 1000.5, np.nan, 1000.0])
    nav = mechanize(tr["time"], tr["f_t"], tr["w_t"], init, tr["time"][::10], tr["height"][::10])
    idx = np.arange(0, tr["time"].size, 10)
    z, h, r = AltimeterMeasurement(alt_t, alt_h, 2.0).build(nav, idx, 0.5)
    assert z.shape == (idx.size, 2)
    # z = computed radius - external radius = -(altimeter - true height) here
    assert z[0, 0] == pytest.approx(0.0, abs=1e-6)
    assert z[1, 0] == pytest.approx(-1.0, abs=1e-3)  # 1.2 s -> epoch 1, offset 0.2 s
    assert h[1, 0, DP[2]] == pytest.approx(0.2 * h[1, 0, DQ[2]], rel=1e-9)
    assert sorted(z[2]) == pytest.approx([-0.5, 1.0], abs=1e-3)
    assert np.isnan(z[5]).all() and np.isnan(z[3]).all()  # NaN height and out-of-range time dropped
    assert r[0, 0, 0] == 4.0


def test_altimeter_samples_fill_their_epochs_slots_in_time_order():
    """Several samples per epoch (a 5-Hz altimeter on 1-s epochs, one noisy sample weighed by
    its own sigma): each in its epoch's next slot, as a loop over the samples puts them."""
    tr = parallel_flight(30.0, triad="strapdown", yaw_rate=0.05)
    init = InitialState(tr["lat"][0], tr["lon"][0], 1000.0, tr["vel_n"][0], tr["mat_nt"][0])
    nav = mechanize(tr["time"], tr["f_t"], tr["w_t"], init, tr["time"][::10], tr["height"][::10])
    idx = np.arange(0, tr["time"].size, 10)
    alt_t = np.arange(0.0, 20.0, 0.2)
    alt_h = 1000.0 + 0.1 * np.sin(alt_t)
    own = np.full(alt_t.size, np.nan)
    own[7] = 3.0
    for n_state in (8, 14):
        z, h, r = AltimeterMeasurement(alt_t, alt_h, 2.0, height_sigma_m=own).build(nav, idx, 0.5, n_state)
        assert z.shape == (idx.size, 5) and h.shape == (idx.size, 5, n_state)
        t_ep = nav.time[idx]
        filled = np.zeros(idx.size, dtype=int)
        for j, t in enumerate(alt_t):
            kk = int(np.argmin(np.abs(t_ep - t)))
            s = filled[kk]
            filled[kk] += 1
            assert np.isfinite(z[kk, s])
            assert r[kk, s, s] == (9.0 if j == 7 else 4.0)
            np.testing.assert_allclose(h[kk, s, DP], (t - t_ep[kk]) * h[kk, s, DQ], rtol=1e-12, atol=1e-15)
            other = np.setdiff1d(np.arange(n_state), np.concatenate([DP, TH]))
            np.testing.assert_array_equal(h[kk, s, other], h[kk, 0, other])  # the epoch's geometry
            if n_state == 14:
                # theta's row is the epoch's plus the offset times cos(a) (n x p), |p| ~ 400 m/s:
                # the slots, 0.2 s apart, step by the same amount
                slope = h[kk, 1, TH] - h[kk, 0, TH]
                assert 50.0 < np.linalg.norm(slope) < 120.0
                np.testing.assert_allclose(h[kk, s, TH] - h[kk, 0, TH], s * slope, rtol=0, atol=1e-6)
        for kk in range(idx.size):
            assert np.isnan(z[kk, filled[kk] :]).all()
            assert not h[kk, filled[kk] :].any()


def test_epochs_stay_evenly_spaced_where_the_imu_changes_rate():
    from gravsurvey.inm.solve import filter_epochs

    t = np.arange(0, 6001) / 20.0  # 20 Hz, 300 s
    idx, half = filter_epochs(t, 1.0)
    np.testing.assert_array_equal(idx, np.arange(0, t.size, 20))  # one rate: every 20th sample
    assert half == pytest.approx(0.5, rel=1e-3)
    gappy = np.delete(t, np.arange(2000, 2040))  # a 2-s gap: still one rate
    idx, _ = filter_epochs(gappy, 1.0)
    np.testing.assert_array_equal(idx, np.arange(0, gappy.size, 20))
    # 20 Hz for 100 s, then 10 Hz (a logger that changed its rate): decimating by the mean
    # rate's factor (15) put the epochs 0.75 s apart, then 1.5 s, and a 1-Hz altimeter's
    # samples half way between two late epochs fell outside both windows
    changed = np.concatenate([t[:2000], t[2000::2]])
    idx, half = filter_epochs(changed, 1.0)
    spacing = np.diff(changed[idx])
    np.testing.assert_allclose(spacing, 1.0, atol=1e-9)
    tr = parallel_flight(300.0, rate_hz=20.0)
    keep = np.concatenate([np.arange(2000), np.arange(2000, t.size, 2)])
    init = InitialState(tr["lat"][0], tr["lon"][0], 1000.0, tr["vel_n"][0], tr["mat_nt"][0])
    nav = mechanize(tr["time"][keep], tr["f_t"][keep], tr["w_t"][keep], init, tr["time"][::20], tr["height"][::20])
    alt_t = np.arange(0.0, 300.0, 1.0) + 0.25
    alt = AltimeterMeasurement(alt_t, np.full(alt_t.size, 1000.0), 2.0)
    z, _, _ = alt.build(nav, idx, half)
    assert np.isfinite(z).sum() == alt_t.size  # every sample has its epoch
    old_step = int(round((changed.size - 1) / (changed[-1] - changed[0])))
    z_old, _, _ = alt.build(nav, np.arange(0, changed.size, old_step), 0.5 * old_step * 300.0 / (changed.size - 1))
    assert np.isfinite(z_old).sum() < 0.9 * alt_t.size
