"""The seed's 8-state error model for a general triad, its exact discretisation,
and the (pluggable) measurement models.

State (seed 004 order), errors = computed minus true, on the triad axes::

    x = (dq1, dp1, dq2, dp2, dq3, dp3, g, f3)

``dq``, ``dp``: errors of the triad-resolved position ``q`` (m) and inertial
velocity ``p`` (m/s); ``g``: the gravity disturbance along the ellipsoid
normal (m/s^2, positive = stronger gravity, i.e. anomalous gravitation
``-g * Up``); ``f3``: the gravimeter (third accelerometer) error (m/s^2).

Continuous model (general triad, ``q0 = q/|q|``, ``n`` the ellipsoid normal
and ``e3`` the third triad axis, all on the triad)::

    d(dq)/dt = dp - w x dq + q x nu
    d(dp)/dt = dG + (f1, f2, f3) - w x dp + p x nu + g n
    dG       = -w0^2 dq + 3 w0^2 q0 ((q0 - cos(a) n).dq + eps)  (radius from the altimeter)
             = -w0^2 (dq - 3 q0 q0.dq)                      (radius computed)
    dg/dt    = -lambda_g g + sqrt(2 lambda_g) sigma_s u_g,   lambda_g = lambda_s v(t)
    df3/dt   = -lambda_f3 f3 + sqrt(2 lambda_f3) sigma_f3 u_f3
    z        = |q|_computed - R_external = cos(a) n.dq - eps   (cos a = n.q0)

Sign of ``g``: the mechanization uses normal gravitation only; the true
gravitation has the extra ``-g Up``, so the computed inertial velocity gains
``+g Up`` relative to the truth: ``+g n`` in ``d(dp)/dt``.

With GNSS position aiding the state is extended to 14 (attitude error ``theta`` and gyro
bias ``b`` on the triad, :func:`continuous_model_n`), because GNSS sees the true position
error ``C (dq + q x theta)`` while the seed's ``dq`` carries the attitude error as position.
``model.accel_bias_states`` adds the constant biases ``BA1, BA2`` of accelerometers 1 and 2
(16 states, ``d(dp)/dt += (ba1, ba2, 0)``): on straight legs a horizontal bias looks like a
tilt, and in turns that wrong tilt leaks the horizontal specific force into the vertical.
Vector gravimetry (``model.horizontal``) adds two more, 18: the horizontal disturbance
``GN, GE`` (north, east, Markov in distance; ``d(dp)/dt += -C^T (g_n N + g_e E)``;
docs/method.md section 8).

Exact discretisation: with ``y = (C dq, C dp, g, f3)`` (``C`` the computed
triad->inertial matrix) the ``w x`` terms cancel, and the model becomes
``dy/dt = A_y y + noise`` with ``A_y`` varying only at the Earth/transport
rate (and with the triad's third axis).  Per epoch ``A_y`` and its noise
density are evaluated at the IMU sample nearest the interval midpoint and
discretised exactly with Van Loan's method; the triad rotation over the
interval is exact: ``Phi_x = T_k^T Phi_y T_k-1``, ``T = diag(C, C, 1, 1)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg
from numba import njit

from ..geodesy import WGS84, Ellipsoid, ecef_to_geodetic, geodetic_to_ecef, mat_en, mat_ie, normal_gravitation_ecef
from .alignment import skew
from .identify import horizontal_prior
from .kalman import matmul_into, transpose_into, van_loan

#: State indices (seed 004 order).
DQ1, DP1, DQ2, DP2, DQ3, DP3, G, F3 = range(8)
N_STATE = 8
DQ = np.array([DQ1, DQ2, DQ3])
DP = np.array([DP1, DP2, DP3])
#: Position in the block order (dq1..3, dp1..3, g, f3) of each seed index.
_PERM = np.array([0, 3, 1, 4, 2, 5, 6, 7])
#: Extension for position (GNSS) aiding: attitude error ``theta`` and gyro bias ``b`` on the
#: triad (rad, rad/s), after the seed's eight states.
TH1, TH2, TH3, BG1, BG2, BG3 = range(8, 14)
N_STATE_AIDED = 14
TH = np.array([TH1, TH2, TH3])
BG = np.array([BG1, BG2, BG3])
#: Attitude sigma (deg) of an attitude that was given (platform, ``initial.attitude_deg``) when
#: ``model.initial_attitude_sigma_deg`` is not set.
GIVEN_ATTITUDE_SIGMA_DEG = 0.05
_PERM_AIDED = np.array([0, 3, 1, 4, 2, 5, 6, 7, 8, 9, 10, 11, 12, 13])
#: Constant biases of accelerometers 1 and 2 (m/s^2, triad axes), after the 14 aided states
#: (``model.accel_bias_states``, and always with ``model.horizontal``).
BA1, BA2 = range(14, 16)
N_STATE_BIAS = 16
BA = np.array([BA1, BA2])
_PERM_BIAS = np.array([0, 3, 1, 4, 2, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15])
#: Vector gravimetry (``model.horizontal``, seed 003): the horizontal gravity disturbance
#: north and east (m/s^2, ``dg = g_true - gamma`` on local ENU), after the 16 states above.
GN, GE = range(16, 18)
N_STATE_VECTOR = 18
GH = np.array([GN, GE])
_PERM_VECTOR = np.array([0, 3, 1, 4, 2, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17])
#: Prior 1-sigma of each horizontal accelerometer bias, m/s^2 (~50 micro-g, the alignment's
#: figure): a navigation-grade accelerometer's datasheet bias is 25-100 micro-g and a tactical
#: one's 0.1-1 mg; 50 micro-g is the navigation-grade middle, and the data (turns) move the
#: estimate well beyond it when a tactical unit is used.
ACCEL_BIAS_SIGMA_MPS2 = 5.0e-4


@dataclass
class EpochGeometry:
    """Per-interval quantities of the error model (interval ``k`` ends at epoch ``k``).

    All vectors on inertial axes, shape (N, 3) unless stated; index 0 unused.
    """

    dt: np.ndarray  # (N,) s
    r_i: np.ndarray  # position at the interval midpoint, m
    v_i: np.ndarray  # inertial velocity at the midpoint, m/s
    up_i: np.ndarray  # ellipsoid normal
    e3_i: np.ndarray  # third triad axis
    e1_i: np.ndarray  # first triad axis
    e2_i: np.ndarray  # second triad axis
    w02: np.ndarray  # (N,) Schuler frequency squared |G|/|r|, 1/s^2
    speed: np.ndarray  # (N,) ground speed, m/s
    mat_it: np.ndarray  # (N, 3, 3) triad->inertial at the epochs


def epoch_geometry(nav, idx, use_ext: bool = True, ellipsoid: Ellipsoid = WGS84) -> EpochGeometry:
    """Evaluate the error-model coefficients for filter epochs at IMU indices ``idx``.

    ``use_ext``: the gravity model takes its radius from the altimeter (see mechanization).
    """
    idx = np.asarray(idx)
    t = nav.time
    mid = np.empty_like(idx)
    mid[0] = idx[0]
    mid[1:] = (idx[1:] + idx[:-1]) // 2
    dt = np.zeros(idx.size)
    dt[1:] = np.diff(t[idx])
    r = nav.r_i[mid]
    v = nav.v_i[mid]
    tm = t[mid]
    m_ie = mat_ie(tm, ellipsoid.omega)
    r_e = np.einsum("nji,nj->ni", m_ie, r)
    lat, lon, _ = ecef_to_geodetic(r_e, ellipsoid)
    m_in = np.einsum("nij,njk->nik", m_ie, mat_en(lat, lon))
    up_i = m_in[:, :, 2]
    if use_ext:
        # the model G(r) = (|r|/R) G_n(r R/|r|) is ~ -mu r / R^3 with R the EXTERNAL radius: its
        # error is linear in dr with w0^2 = |G_n|/R at the altimeter point, not at the computed
        # one (which may be km off while the anomaly is still unestimated)
        p_e = geodetic_to_ecef(lat, lon, nav.h_ext[mid], ellipsoid)
    else:
        p_e = r_e
    w02 = np.linalg.norm(normal_gravitation_ecef(p_e, ellipsoid), axis=1) / np.linalg.norm(p_e, axis=1)
    v_e = np.einsum("nji,nj->ni", m_ie, v) - np.cross([0.0, 0.0, ellipsoid.omega], r_e)
    v_n = np.einsum("nji,nj->ni", m_in, np.einsum("nij,nj->ni", m_ie, v_e))
    speed = np.hypot(v_n[:, 0], v_n[:, 1])
    c_mid = nav.mat_it[mid]
    return EpochGeometry(
        dt,
        r,
        v,
        up_i,
        np.ascontiguousarray(c_mid[:, :, 2]),
        np.ascontiguousarray(c_mid[:, :, 0]),
        np.ascontiguousarray(c_mid[:, :, 1]),
        w02,
        speed,
        np.ascontiguousarray(nav.mat_it[idx]),
    )


def noise_params(params, alt_dt, hprior=None):
    """Vector of the scalar coefficients passed to the kernels.

    ``hprior``: (sigma m/s^2, lambda 1/m) of the horizontal disturbance; None: from the
    vertical prior (:func:`gravsurvey.inm.identify.horizontal_prior`).
    """
    sig_h, lam_h = (
        hprior if hprior is not None else horizontal_prior(params.anomaly_sigma_mps2, params.anomaly_lambda_per_m)
    )
    return np.array(
        [
            params.gyro_drift_radps**2,  # gyro PSD, rad^2/s
            params.accel_noise_mps2**2,  # accel PSD, (m/s^2)^2 s
            params.gravimeter_white_mps2**2,
            params.gravimeter_lambda_per_s,
            params.gravimeter_sigma_mps2,
            params.anomaly_lambda_per_m,
            params.anomaly_sigma_mps2,
            params.altimeter_sigma_m**2 * alt_dt,  # altimeter error as a white noise in the dynamics
            1.0 if params.radius_source == "altimeter" else 0.0,
            0.0,  # gyro-bias random walk PSD (the bias is a constant)
            lam_h,  # horizontal disturbance: spatial rate, 1/m (18 states only)
            sig_h,  # ... and stationary sigma, m/s^2
        ]
    )


@njit(cache=True)
def _skew(v):
    m = np.zeros((3, 3))
    m[0, 1] = -v[2]
    m[0, 2] = v[1]
    m[1, 0] = v[2]
    m[1, 2] = -v[0]
    m[2, 0] = -v[1]
    m[2, 1] = v[0]
    return m


@njit(cache=True)
def continuous_model_n(r, v, up, e1, e2, e3, w02, speed, c, n):
    """``A_y`` and noise density ``Qc_y`` (n, n) in block order, ``n`` = 8, 14, 16 or 18.

    Block order ``(dr, dv, g, f3)`` (n = 8, the seed), ``(dr, dv, g, f3, theta, b)``
    (n = 14), ``(dr, dv, g, f3, theta, b, ba1, ba2)`` (n = 16) or ``(dr, dv, g, f3, theta, b,
    ba1, ba2, g_n, g_e)`` (n = 18, vector gravimetry): ``dr = C dq``, ``dv = C dp``, ``theta``
    (C theta on inertial axes) the attitude error, ``b`` the gyro bias on the triad, ``ba1,
    ba2`` the constant biases of accelerometers 1 and 2 (``d(dv)/dt`` gains ``ba1 e1 + ba2
    e2``) and ``g_n, g_e`` the horizontal disturbance (north, east; ``d(dv)/dt`` gains ``-(g_n
    N + g_e E)``: the mechanization leaves the anomalous gravitation out, so the computed
    velocity lacks it).
    ``c`` = noise parameter vector from
    :func:`noise_params`; ``e1, e2, e3`` are the columns of ``C`` at the interval midpoint.

    With ``theta`` defined by ``C_true = C (I + [theta x])`` the seed's ``dq`` is
    ``C^T dr_i - q x theta`` (the rotation of the triad merges into it) and
    ``d theta/dt = -w x theta - nu`` with the gyro error ``nu = b + white``; on inertial axes
    ``d(C theta)/dt = -C nu``.  The same ``nu`` drives ``dq`` (``+q x nu``) and ``dp``
    (``+p x nu``): the process noise is correlated across the three blocks.  The radius
    ``R_ext`` of the gravity model is taken at the computed latitude, which moves with the
    true position error ``C^T dr_i = dq + q x theta``: the theta part enters like dq.
    """
    s_nu, s_f, s_w, lam_f3, sig_f3, lam_s, sig_s, s_eps, ext = c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7], c[8]
    a = np.zeros((n, n))
    qc = np.zeros((n, n))
    rn = math.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
    r0 = r / rn
    for i in range(3):
        a[i, 3 + i] = 1.0
        a[3 + i, i] = -w02
        a[3 + i, 6] = up[i]
        a[3 + i, 7] = e3[i]
    aided = n >= 14
    if ext == 0.0:
        for i in range(3):
            for j in range(3):
                a[3 + i, j] += 3.0 * w02 * r0[i] * r0[j]
    else:
        # R_ext is taken at the computed latitude: a horizontal error dr changes it by
        # (r0 - n cos a) . dr (a = angle between radial and normal), entering as 3 w0^2 r0 dR
        cosa = r0[0] * up[0] + r0[1] * up[1] + r0[2] * up[2]
        for i in range(3):
            for j in range(3):
                a[3 + i, j] += 3.0 * w02 * r0[i] * (r0[j] - cosa * up[j])
        if aided:
            # ... with dr_i = C dq + r x (C theta): n . (r x th) = th . (n x r)
            nxr = np.empty(3)
            nxr[0] = up[1] * r[2] - up[2] * r[1]
            nxr[1] = up[2] * r[0] - up[0] * r[2]
            nxr[2] = up[0] * r[1] - up[1] * r[0]
            for i in range(3):
                for j in range(3):
                    a[3 + i, 8 + j] += -3.0 * w02 * r0[i] * cosa * nxr[j]
    lam_g = lam_s * speed
    a[6, 6] = -lam_g
    a[7, 7] = -lam_f3
    # gyro drift: d(dr) += [r x] C nu, d(dv) += [v x] C nu, (d(C theta) -= C nu), C nu isotropic
    nb = 9 if aided else 6
    lg = np.zeros((nb, 3))
    # [r x] and [v x] written in place (no call: model_scales runs this function's Python
    # form, and a compiled callee would be loaded or compiled for it)
    for o, x in ((0, r), (3, v)):
        lg[o, 1] = -x[2]
        lg[o, 2] = x[1]
        lg[o + 1, 0] = x[2]
        lg[o + 1, 2] = -x[0]
        lg[o + 2, 0] = -x[1]
        lg[o + 2, 1] = x[0]
    if aided:
        for i in range(3):
            lg[6 + i, i] = -1.0
    qg = s_nu * (lg @ lg.T)
    # rows of lg -> state rows (0..5, then theta at 8..10)
    rows = np.array([0, 1, 2, 3, 4, 5, 8, 9, 10])
    for i in range(nb):
        for j in range(nb):
            qc[rows[i], rows[j]] += qg[i, j]
    if aided:
        # the bias is nu's constant part: the same couplings with C (triad -> inertial)
        cm = np.empty((3, 3))
        for i in range(3):
            cm[i, 0] = e1[i]
            cm[i, 1] = e2[i]
            cm[i, 2] = e3[i]
        lb = lg @ cm
        for i in range(nb):
            for j in range(3):
                a[rows[i], 11 + j] = lb[i, j]
    for i in range(3):
        for j in range(3):
            qc[3 + i, 3 + j] += s_f * (e1[i] * e1[j] + e2[i] * e2[j]) + s_w * e3[i] * e3[j]
            if ext != 0.0:
                qc[3 + i, 3 + j] += 9.0 * w02 * w02 * s_eps * r0[i] * r0[j]
    qc[6, 6] = 2.0 * lam_g * sig_s * sig_s
    qc[7, 7] = 2.0 * lam_f3 * sig_f3 * sig_f3
    if aided:
        for i in range(3):
            qc[11 + i, 11 + i] = c[9]
    if n >= 16:
        for i in range(3):
            a[3 + i, 14] = e1[i]
            a[3 + i, 15] = e2[i]
    if n == 18:
        # local East and North on inertial axes: the inertial z axis is the Earth's axis
        ex = -up[1]
        ey = up[0]
        en = math.sqrt(ex * ex + ey * ey)
        ex /= en
        ey /= en
        east = np.array([ex, ey, 0.0])
        north = np.array([-up[2] * ey, up[2] * ex, up[0] * ey - up[1] * ex])
        lam_h = c[10] * speed
        for i in range(3):
            a[3 + i, 16] = -north[i]
            a[3 + i, 17] = -east[i]
        a[16, 16] = -lam_h
        a[17, 17] = -lam_h
        qc[16, 16] = 2.0 * lam_h * c[11] * c[11]
        qc[17, 17] = 2.0 * lam_h * c[11] * c[11]
    return a, qc


@njit(cache=True)
def continuous_model(r, v, up, e1, e2, e3, w02, speed, c):
    """``A_y`` (8, 8) and noise density ``Qc_y`` (8, 8) in block order (dr, dv, g, f3).

    ``c`` = noise parameter vector from :func:`noise_params`.
    """
    return continuous_model_n(r, v, up, e1, e2, e3, w02, speed, c, 8)


#: Bounds of the balancing exponents (scales 2^-60 .. 2^60): a state whose column or row is
#: empty (e.g. a constant bias) would otherwise be scaled without end.
BALANCE_EXP = 60
#: Coordinate sweeps of the balancing (the exponents no longer change after 2-3 on the
#: flights measured).
BALANCE_SWEEPS = 4


def balance_scales(aa, qq):
    """Per-state scales (powers of two) that balance Van Loan's matrix ``[[-A, Qc], [0, A^T]]``.

    The model mixes units by ~13 orders of magnitude (the gyro bias drives the position with
    the Earth's radius, 6.4e6 m): the 1-norm of Van Loan's matrix is ~1e7 for a 1 s epoch,
    and scaling and squaring took ~26 squarings (4 products each) on top of the 13 Taylor
    terms (3 each), losing ~1e-9 relative accuracy on the way (measured against a 40-digit
    exponential).  In the states ``x / s`` (``A' = S^-1 A S``, ``Qc' = S^-1 Qc S^-1``) the
    norm is ~0.03: no squaring, and the exponential is round-off accurate (1e-16).  Powers of
    two make the change of units exact.

    Osborne's balancing: coordinate sweeps of ``f(u) = sum_(i != j) |a_ij| 2^(u_j - u_i)
    + sum |qc_ij| 2^(-u_i - u_j) / 2`` (the sum of the magnitudes of the matrix's entries,
    convex in ``u``), each coordinate set to its minimiser (``Qc``'s diagonal term taken at
    the current scale) rounded to an integer and bounded by :data:`BALANCE_EXP`.  Any scales
    give the same exponential up to round-off: they only change how many squarings
    :func:`gravsurvey.inm.kalman.van_loan` needs.

    Parameters
    ----------
    aa, qq : ndarray (n, n)
        Magnitudes ``|A|`` (1/s) and ``|Qc|`` (state units^2 / s), e.g. elementwise maxima
        over a few epochs.

    Returns
    -------
    ndarray (n,)
        ``s``, block order.
    """
    n = aa.shape[0]
    u = np.zeros(n)
    e = np.ones(n)
    for _ in range(BALANCE_SWEEPS):
        for i in range(n):
            # f's terms in 2^u_i (column i of A) and in 2^-u_i (row i of A and of Qc)
            grow = 0.0
            shrink = 0.0
            for j in range(n):
                if j != i:
                    grow += aa[j, i] / e[j]
                    shrink += aa[i, j] * e[j]
                shrink += qq[i, j] / e[j]
            if grow == 0.0 and shrink == 0.0:
                continue
            if grow == 0.0:
                ui = float(BALANCE_EXP)
            elif shrink == 0.0:
                ui = -float(BALANCE_EXP)
            else:
                ui = min(float(BALANCE_EXP), max(-float(BALANCE_EXP), float(round(0.5 * math.log2(shrink / grow)))))
            u[i] = ui
            e[i] = 2.0**ui
    return e


@njit(cache=True)
def discretise_kernel(dt, r, v, up, e1, e2, e3, w02, speed, mat_it, c, perm, scale):
    """Transition and process noise of every epoch, seed order (see module docstring).

    The state size is ``perm.shape[0]`` (8; 14 with attitude and gyro-bias states; 16 with
    the horizontal accelerometer biases; 18 with the horizontal disturbance as well).
    The exponential is taken of the model in the states ``x / scale`` and mapped back
    (``scale`` (n,), block order, powers of two: exact; :func:`model_scales`).

    Returns
    -------
    phi, q : ndarray (N, n, n)
        Index 0 is identity / zero.
    """
    nep = dt.shape[0]
    n = perm.shape[0]
    phi = np.zeros((nep, n, n))
    q = np.zeros((nep, n, n))
    # A' = S^-1 A S, Qc' = S^-1 Qc S^-1 and back: Phi = S Phi' S^-1, Qd = S Qd' S
    a_in = np.empty((n, n))
    q_in = np.empty((n, n))
    a_out = np.empty((n, n))
    q_out = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            a_in[i, j] = scale[j] / scale[i]
            q_in[i, j] = 1.0 / (scale[i] * scale[j])
            a_out[i, j] = scale[i] / scale[j]
            q_out[i, j] = scale[i] * scale[j]
    for i in range(n):
        phi[0, i, i] = 1.0
    t_prev = np.eye(n)
    t_cur = np.eye(n)
    t_cur_t = np.empty((n, n))
    w = np.empty((n, n))
    phx = np.empty((n, n))
    qx = np.empty((n, n))
    nblk = 3 if n >= 14 else 2
    for k in range(1, nep):
        a, qc = continuous_model_n(r[k], v[k], up[k], e1[k], e2[k], e3[k], w02[k], speed[k], c, n)
        for i in range(n):
            for j in range(n):
                a[i, j] *= a_in[i, j]
                qc[i, j] *= q_in[i, j]
        phy, qy = van_loan(a, qc, dt[k])
        for i in range(n):
            for j in range(n):
                phy[i, j] *= a_out[i, j]
                qy[i, j] *= q_out[i, j]
        for blk in range(nblk):
            o = 3 * blk if blk < 2 else 8
            for i in range(3):
                for j in range(3):
                    t_prev[o + i, o + j] = mat_it[k - 1, i, j]
                    t_cur[o + i, o + j] = mat_it[k, i, j]
        # phx = t_cur^T phy t_prev, qx = t_cur^T qy t_cur (small fixed-size products, no BLAS)
        transpose_into(t_cur, t_cur_t)
        matmul_into(t_cur_t, phy, w)
        matmul_into(w, t_prev, phx)
        matmul_into(t_cur_t, qy, w)
        matmul_into(w, t_cur, qx)
        # element by element, not `phi[k] = ...`: array assignments and expressions compile
        # numba's broadcast-error formatting (~2 s on a cold start)
        for i in range(n):
            for j in range(n):
                phi[k, i, j] = phx[perm[i], perm[j]]
                q[k, i, j] = 0.5 * (qx[perm[i], perm[j]] + qx[perm[j], perm[i]])
    return phi, q


def _model_at(geom: EpochGeometry, k: int, c: np.ndarray, n: int):
    """``A`` and ``Qc`` (n, n), block order, of epoch ``k`` by the Python form of
    :func:`continuous_model_n` (the reference path and the balancing's few epochs)."""
    return continuous_model_n.py_func(
        geom.r_i[k],
        geom.v_i[k],
        geom.up_i[k],
        geom.e1_i[k],
        geom.e2_i[k],
        geom.e3_i[k],
        float(geom.w02[k]),
        float(geom.speed[k]),
        c,
        n,
    )


def model_scales(geom: EpochGeometry, c: np.ndarray, n: int) -> np.ndarray:
    """:func:`balance_scales` of the model's coefficients at three epochs (first, middle, last).

    Their elementwise maximum magnitudes: the coefficients change only at the Earth and
    transport rates and with the triad's axes.  Evaluated in Python (3 epochs: ~1 ms), so that
    the compiled kernel does not grow (a second call site of :func:`continuous_model_n` in it
    cost ~0.6 s of first-run compilation).
    """
    nep = geom.dt.size
    aa = np.zeros((n, n))
    qq = np.zeros((n, n))
    if nep > 1:
        for k in (1, nep // 2, nep - 1):
            a, qc = _model_at(geom, k, c, n)
            aa = np.maximum(aa, np.abs(a))
            qq = np.maximum(qq, np.abs(qc))
    return balance_scales(aa, qq)


def discretise(
    geom: EpochGeometry,
    params,
    alt_dt: float,
    reference: bool = False,
    aided: bool = False,
    horizontal: bool = False,
    hprior=None,
    accel_bias: bool = False,
):
    """Phi, Q sequences ``(N, n, n)`` for the filter (seed state order).

    Parameters
    ----------
    geom : EpochGeometry
    params : InmParams
    alt_dt : float
        Altimeter sampling interval, s (density of its error in the dynamics).
    reference : bool
        Pure-numpy/scipy path (for tests).
    aided : bool
        14 states: the seed's 8 plus attitude error and gyro bias (position aiding);
        otherwise n = 8.
    horizontal : bool
        With ``aided``: 18 states, the accelerometer biases (``BA1, BA2``) and the horizontal
        disturbance (``GN, GE``) appended (vector gravimetry).
    hprior : tuple of 2 floats, optional
        Horizontal disturbance prior (sigma m/s^2, lambda 1/m); None: from the vertical one
        (:func:`gravsurvey.inm.identify.horizontal_prior`).
    accel_bias : bool
        With ``aided`` (and not ``horizontal``): 16 states, the accelerometer biases
        (``BA1, BA2``) appended.
    """
    c = noise_params(params, alt_dt, hprior)
    perm = state_perm(aided, horizontal, accel_bias)
    n = perm.size
    args = (geom.dt, geom.r_i, geom.v_i, geom.up_i, geom.e1_i, geom.e2_i, geom.e3_i, geom.w02, geom.speed, geom.mat_it)
    if not reference:
        return discretise_kernel(*[np.ascontiguousarray(x) for x in args], c, perm, model_scales(geom, c, n))
    nep = geom.dt.size
    phi = np.zeros((nep, n, n))
    q = np.zeros((nep, n, n))
    phi[0] = np.eye(n)
    for k in range(1, nep):
        a, qc = _model_at(geom, k, c, n)
        m = np.zeros((2 * n, 2 * n))
        dt = geom.dt[k]
        m[:n, :n], m[:n, n:], m[n:, n:] = -a * dt, qc * dt, a.T * dt
        e = scipy.linalg.expm(m)
        phy = e[n:, n:].T
        qy = phy @ e[:n, n:]
        blocks_p = [geom.mat_it[k - 1], geom.mat_it[k - 1], 1.0, 1.0]
        blocks_c = [geom.mat_it[k], geom.mat_it[k], 1.0, 1.0]
        if aided:
            blocks_p += [geom.mat_it[k - 1], np.eye(3)]
            blocks_c += [geom.mat_it[k], np.eye(3)]
        if n > N_STATE_AIDED:
            blocks_p.append(np.eye(n - N_STATE_AIDED))
            blocks_c.append(np.eye(n - N_STATE_AIDED))
        tp = scipy.linalg.block_diag(*blocks_p)
        tc = scipy.linalg.block_diag(*blocks_c)
        phi[k] = (tc.T @ phy @ tp)[np.ix_(perm, perm)]
        qs = (tc.T @ qy @ tc)[np.ix_(perm, perm)]
        q[k] = 0.5 * (qs + qs.T)
    return phi, q


def state_perm(aided: bool, horizontal: bool = False, accel_bias: bool = False) -> np.ndarray:
    """Block order -> seed order permutation; its size is the state size (8, 14, 16 or 18)."""
    if not aided:
        return _PERM
    if horizontal:
        return _PERM_VECTOR
    return _PERM_BIAS if accel_bias else _PERM_AIDED


def initial_covariance(
    params,
    q_t=None,
    p_t=None,
    attitude_cov_t=None,
    horizontal: bool = False,
    hprior=None,
    accel_bias: bool = False,
) -> np.ndarray:
    """Prior covariance at the first epoch (zero prior mean).

    Parameters
    ----------
    params : InmParams
    q_t, p_t : ndarray (3,), optional
        Triad-resolved position (m) and inertial velocity (m/s) at the first epoch.  Given
        both, the 14-state prior of the aided filter: ``dq = C^T dr - q x theta`` and
        ``dp = C^T dv - p x theta`` with independent ``dr`` (initial_position_sigma_m),
        ``dv`` (initial_velocity_sigma_mps) and ``theta`` (initial_attitude_sigma_deg), and
        the gyro bias (gyro_bias_sigma_degph).  Otherwise the seed's diagonal (8, 8).
    attitude_cov_t : ndarray (3, 3), optional
        Covariance of ``theta`` on the triad axes, rad^2 (e.g. from the coarse alignment,
        :attr:`gravsurvey.inm.alignment.Alignment.cov_t`); replaces the isotropic
        ``initial_attitude_sigma_deg``.
    horizontal : bool
        With ``q_t, p_t``: the 18-state prior, the accelerometer biases at
        ``params.accel_bias_mps2`` (the datasheet's; :data:`ACCEL_BIAS_SIGMA_MPS2` when None)
        and the horizontal disturbance at its stationary sigma
        (:func:`gravsurvey.inm.identify.horizontal_prior`), independent of the rest.
    hprior : tuple of 2 floats, optional
        As in :func:`discretise`.
    accel_bias : bool
        With ``q_t, p_t`` (and not ``horizontal``): the 16-state prior, the accelerometer
        biases as with ``horizontal``, independent of the rest.
    """
    if q_t is None or p_t is None:
        d = np.empty(8)
        d[DQ] = params.initial_position_sigma_m**2
        d[DP] = params.initial_velocity_sigma_mps**2
        d[G] = params.initial_anomaly_sigma_mps2**2
        d[F3] = params.initial_gravimeter_sigma_mps2**2
        return np.diag(d)
    # linear map from independent (dr, dv, theta) to (dq, dp, theta), block order
    sq, sv = params.initial_position_sigma_m, params.initial_velocity_sigma_mps
    sa = math.radians(
        GIVEN_ATTITUDE_SIGMA_DEG if params.initial_attitude_sigma_deg is None else params.initial_attitude_sigma_deg
    )
    m = np.zeros((9, 9))
    m[0:3, 0:3] = np.eye(3)
    m[3:6, 3:6] = np.eye(3)
    m[6:9, 6:9] = np.eye(3)
    m[0:3, 6:9] = -_skew.py_func(np.asarray(q_t, float))
    m[3:6, 6:9] = -_skew.py_func(np.asarray(p_t, float))
    indep = np.diag([sq**2] * 3 + [sv**2] * 3 + [sa**2] * 3)
    if attitude_cov_t is not None:
        indep[6:9, 6:9] = np.asarray(attitude_cov_t, float)
    cov = m @ indep @ m.T
    blk = np.zeros((14, 14))
    rows = [0, 1, 2, 3, 4, 5, 8, 9, 10]
    blk[np.ix_(rows, rows)] = cov
    blk[6, 6] = params.initial_anomaly_sigma_mps2**2
    blk[7, 7] = params.initial_gravimeter_sigma_mps2**2
    sb = math.radians(params.gyro_bias_sigma_degph) / 3600.0
    for i in range(11, 14):
        blk[i, i] = sb**2
    p = blk[np.ix_(_PERM_AIDED, _PERM_AIDED)]
    if horizontal or accel_bias:
        n = N_STATE_VECTOR if horizontal else N_STATE_BIAS
        big = np.zeros((n, n))
        big[:N_STATE_AIDED, :N_STATE_AIDED] = p
        sig_ba = ACCEL_BIAS_SIGMA_MPS2 if params.accel_bias_mps2 is None else params.accel_bias_mps2
        big[BA1, BA1] = big[BA2, BA2] = sig_ba**2
        if horizontal:
            sig_h = (
                hprior[0]
                if hprior is not None
                else horizontal_prior(params.anomaly_sigma_mps2, params.anomaly_lambda_per_m)[0]
            )
            big[GN, GN] = big[GE, GE] = sig_h**2
        p = big
    return 0.5 * (p + p.T)


def initial_mean(
    theta_t, q_t, p_t, n_state: int = N_STATE_AIDED, gyro_bias_t=None, dr_t=None, dv_t=None, accel_bias_t=None
) -> np.ndarray:
    """Prior mean (n_state,) of the aided state for an attitude error ``theta_t`` (rad, triad axes).

    The seed's states carry the attitude: ``dq = dr - q x theta`` and ``dp = dv - p x theta``
    (:func:`continuous_model_n`), ``dr``, ``dv`` the position and velocity errors on the triad
    axes (``C^T dr_i``, ``C^T dv_i``; zero mean unless given).  Used when the filter is re-run
    about a corrected initial state while the prior stays the alignment's and the GNSS fit's
    (the prior mean is then the old state seen from the new one).
    ``gyro_bias_t`` (3,), rad/s: the gyro-bias state's prior mean (a re-run whose rates had an
    estimated bias taken off: minus that bias); None: zero.
    ``dr_t``, ``dv_t`` (3,), m and m/s: prior means of ``dr`` and ``dv`` (a re-run from a
    corrected initial position and velocity: minus the corrections); None: zero.
    ``accel_bias_t`` (2,), m/s^2: the prior mean of the bias states ``BA1, BA2`` (a re-run whose
    specific force had an estimated bias taken off: minus that bias; ``n_state`` >= 16); None: zero.
    """
    th = np.asarray(theta_t, float)
    x = np.zeros(n_state)
    x[DQ] = -np.cross(np.asarray(q_t, float), th)
    x[DP] = -np.cross(np.asarray(p_t, float), th)
    if dr_t is not None:
        x[DQ] += np.asarray(dr_t, float)
    if dv_t is not None:
        x[DP] += np.asarray(dv_t, float)
    x[TH] = th
    if gyro_bias_t is not None:
        x[BG] = np.asarray(gyro_bias_t, float)
    if accel_bias_t is not None:
        x[BA] = np.asarray(accel_bias_t, float)
    return x


# --------------------------------------------------------------------------
# Measurement models: objects with .build(nav, idx, epoch_time) -> (z, H, R)
# --------------------------------------------------------------------------


def hermite_position(nav, tq):
    """Mechanized inertial position (n, 3) m at the times ``tq`` (n,) s: cubic Hermite with the
    velocities."""
    t = nav.time
    j = np.clip(np.searchsorted(t, tq, side="right") - 1, 0, t.size - 2)
    h = t[j + 1] - t[j]
    s = ((tq - t[j]) / h)[:, None]
    p0, p1 = nav.r_i[j], nav.r_i[j + 1]
    m0, m1 = nav.v_i[j] * h[:, None], nav.v_i[j + 1] * h[:, None]
    return (
        (2 * s**3 - 3 * s**2 + 1) * p0 + (s**3 - 2 * s**2 + s) * m0 + (-2 * s**3 + 3 * s**2) * p1 + (s**3 - s**2) * m1
    )


def nearest_sample(time_s, t):
    """Index (k,) of the sample of the increasing times ``time_s`` (m,) s nearest each of ``t``
    (k,) s."""
    tb = np.asarray(time_s, float)
    t = np.asarray(t, float)
    if tb.size < 2:
        return np.zeros(t.size, dtype=np.int64)
    j = np.clip(np.searchsorted(tb, t), 1, tb.size - 1)
    return j - ((t - tb[j - 1]) < (tb[j] - t))


def attitude_at(body, t):
    """The attitude of ``body = (time (m,), mat (m, 3, 3))`` at its sample nearest each of the
    times ``t`` (k,) s: (k, 3, 3)."""
    tb, mb = body
    return mb[nearest_sample(tb, t)]


class AltimeterMeasurement:
    """Radial measurement ``z = |q|_computed - R(lat_c, lon_c, h_alt) = cos(a) n.dq - eps``.

    ``R(lat, lon, h)`` is the geocentric radius of the point at the altimeter's
    height and the computed latitude/longitude; a horizontal error moves both
    terms, so the sensitivity is along the ellipsoid normal ``n`` (not the
    radial ``q0``), scaled by ``cos(a) = n.q0`` (a ~ 0.19 deg at 45 deg).

    Each altimeter sample is assigned to the nearest filter epoch (within half
    an epoch); the time offset ``d`` to the epoch is carried in ``H`` as
    ``q0.dq + d q0.dp``.  Several samples per epoch become several components.

    Parameters
    ----------
    time, height : ndarray (m,)
        Altimeter times (s, record base) and ellipsoidal heights (m).
    sigma_m : float
        Altimeter noise, m.
    height_sigma_m : ndarray (m,), optional
        Each sample's own 1-sigma, m, where it is above ``sigma_m`` (NaN: ``sigma_m``): a noisy
        stretch weighed by its own noise.
    """

    def __init__(self, time, height, sigma_m, ellipsoid: Ellipsoid = WGS84, height_sigma_m=None):
        self.time = np.asarray(time, float)
        self.height = np.asarray(height, float)
        self.sigma_m = float(sigma_m)
        self.ellipsoid = ellipsoid
        self.height_sigma = None if height_sigma_m is None else np.asarray(height_sigma_m, float)

    def build(self, nav, idx, half_window, n_state: int = N_STATE):
        """Return ``z (N, m)``, ``H (N, m, n_state)``, ``R (N, m, m)`` with NaN for missing.

        With ``n_state`` = 14 (attitude states) the latitude term of ``R`` sees the true
        position error ``dq + q x theta`` and the offset ``d`` its rate ``dp + p x theta``:
        ``H`` gains ``cos(a) (n x q + d n x p)`` on ``theta``.
        """
        t_ep = nav.time[idx]
        ok = (self.time >= nav.time[0]) & (self.time <= nav.time[-1]) & np.isfinite(self.height)
        ta, ha = self.time[ok], self.height[ok]
        var = np.full(ta.size, self.sigma_m**2)
        if self.height_sigma is not None:
            own = self.height_sigma[ok]
            var = np.where(np.isfinite(own), np.maximum(var, own * own), var)
        nep = t_ep.size
        if ta.size == 0:
            return np.full((nep, 1), np.nan), np.zeros((nep, 1, n_state)), np.ones((nep, 1, 1))
        pos = np.clip(np.searchsorted(t_ep, ta), 0, nep - 1)
        prev = np.clip(pos - 1, 0, nep - 1)
        k = np.where(np.abs(ta - t_ep[prev]) <= np.abs(ta - t_ep[pos]), prev, pos)
        d = ta - t_ep[k]
        use = np.abs(d) <= half_window + 1e-9
        ta, ha, k, d, var = ta[use], ha[use], k[use], d[use], var[use]
        r_c = hermite_position(nav, ta)
        r_e = np.einsum("nji,nj->ni", mat_ie(ta, self.ellipsoid.omega), r_c)
        lat, lon, _ = ecef_to_geodetic(r_e, self.ellipsoid)
        r_ext = np.linalg.norm(geodetic_to_ecef(lat, lon, ha, self.ellipsoid), axis=1)
        zval = np.linalg.norm(r_c, axis=1) - r_ext
        counts = np.bincount(k, minlength=nep)
        m = max(int(counts.max()), 1)
        z = np.full((nep, m), np.nan)
        h = np.zeros((nep, m, n_state))
        r = np.broadcast_to(np.eye(m) * self.sigma_m**2, (nep, m, m)).copy()
        # z = |r_c| - R(lat_c, lon_c, h_alt): a horizontal error moves both terms, so that
        # dz = (n . r0) n . dr - eps: the height error along the ellipsoid normal n
        r_ep = nav.r_i[idx]
        r_e = np.einsum("nji,nj->ni", mat_ie(nav.time[idx], self.ellipsoid.omega), r_ep)
        lat_ep, lon_ep, _ = ecef_to_geodetic(r_e, self.ellipsoid)
        n_e = mat_en(lat_ep, lon_ep)[:, :, 2]
        cosa = np.einsum("ni,ni->n", n_e, r_e / np.linalg.norm(r_e, axis=1)[:, None])
        n_i = np.einsum("nij,nj->ni", mat_ie(nav.time[idx], self.ellipsoid.omega), n_e)
        n_t = np.einsum("nji,nj->ni", nav.mat_it[idx], n_i)
        q0_t = n_t * cosa[:, None]
        if n_state >= N_STATE_AIDED:
            q_t = np.einsum("nji,nj->ni", nav.mat_it[idx], r_ep)
            h_th = np.cross(n_t, q_t) * cosa[:, None]
        # each sample's slot among its epoch's, in time order (a loop over the samples cost
        # 0.75 s per pass on a 3-h flight with a 20-Hz altimeter, the filter itself 0.25 s)
        order = np.argsort(k, kind="stable")
        ks = k[order]
        slot = np.empty(k.size, dtype=np.int64)
        slot[order] = np.arange(k.size) - np.searchsorted(ks, ks, side="left")
        z[k, slot] = zval
        r[k, slot, slot] = var
        kc, sc = k[:, None], slot[:, None]
        h[kc, sc, DQ[None, :]] = q0_t[k]
        h[kc, sc, DP[None, :]] = d[:, None] * q0_t[k]
        if n_state >= N_STATE_AIDED:
            # the offset moves the true error by d (dp + p x theta), p the inertial velocity
            # (~450 m/s): a 0.1-deg attitude error is 0.2 m at d = 0.25 s, ten sigmas of a 2-cm altimeter
            p_t = np.einsum("nji,nj->ni", nav.mat_it[idx], nav.v_i[idx])
            h[kc, sc, TH[None, :]] = h_th[k] + d[:, None] * np.cross(q0_t, p_t)[k]
        return z, h, r


def _nearest_epoch(t_ep, ts, half_window):
    """Index of the nearest filter epoch of each sample time and the offset ``ts - t_ep[k]``;
    ``use`` marks samples within ``half_window`` (s) of their epoch."""
    nep = t_ep.size
    pos = np.clip(np.searchsorted(t_ep, ts), 0, nep - 1)
    prev = np.clip(pos - 1, 0, nep - 1)
    k = np.where(np.abs(ts - t_ep[prev]) <= np.abs(ts - t_ep[pos]), prev, pos)
    d = ts - t_ep[k]
    use = np.abs(d) <= half_window + 1e-9
    return k, d, use


class GnssMeasurement:
    """GNSS position aiding: ``z = M_in^T (r_computed - r_gnss)`` on local ENU axes, m.

    ``r_computed`` is the mechanized inertial position at the GNSS time (cubic Hermite),
    ``r_gnss`` the GNSS geodetic position mapped to the inertial frame, and ``M_in`` the
    local ENU -> inertial rotation at the GNSS point.  The seed's ``dq`` merges the triad's
    attitude error into the position (``dq = C^T dr_i - q x theta``, see
    :func:`continuous_model_n`), and GNSS sees the true position error
    ``dr_i = C (dq + q x theta)`` (``C`` the computed triad -> inertial matrix at the epoch):
    the measurement needs the 14-state model, where a sample at time offset ``d`` from its
    epoch sees ``C (dq + q x theta) + d C (dp + p x theta)`` and has
    ``H = M_in^T C [I, d I, [q x] + d [p x]]`` on ``(dq, dp, theta)`` (``p = C^T v_i``, the
    inertial velocity on the triad: ~450 m/s, so ``d [p x]`` is not small).

    Samples within half an epoch of a filter epoch are averaged there (exact for the linear
    model: the mean of ``H_j x + v_j`` is ``mean(H_j) x + mean(v_j)``); their errors are taken
    as white per sample, so ``R = diag(sh^2, sh^2, sv^2) / n`` for ``n`` samples.

    Parameters
    ----------
    time : ndarray (k,)
        GNSS times, s (record base).
    lat, lon : ndarray (k,)
        Geodetic latitude and longitude, rad.
    height : ndarray (k,)
        Ellipsoidal height, m.
    horizontal_sigma_m, vertical_sigma_m : float
        1-sigma of each sample's east/north and up error, m (> 0).
    ellipsoid : Ellipsoid
    lever_arm_t : ndarray (3,), optional
        Antenna position from the IMU on the triad axes, m.  The antenna sits at
        ``r + C_true l``: the measurement becomes ``z = M_in^T (r_computed + C l - r_gnss)``
        (``C`` the computed attitude at the IMU sample nearest the GNSS time) and
        ``C_true = C (I + [theta x])`` adds ``M_in^T C [l x]`` on ``theta``.
    body_mat_i : tuple (ndarray (m,), ndarray (m, 3, 3)), optional
        Times (s) and the aircraft's axes (FLU) -> inertial, in place of the triad's for
        ``lever_arm_t`` (:func:`attitude_at`): a platform's triad is not the aircraft's (its
        attitude then from the track, :func:`gravsurvey.inm.gnssqc.track_attitude`; no ``theta``
        term).
    height_sigma_m : ndarray (k,), optional
        Each fix's own up 1-sigma, m, where it is above ``vertical_sigma_m`` (NaN: the common
        one): a noisy stretch weighed by its own noise.
    vertical : bool
        Use the up component.  False where the height channel is these same GNSS heights
        (:func:`gravsurvey.inm.heightqc.gnss_height_fraction`): the up component is then NaN
        (missing) and the heights enter once, as the height measurement.
    """

    def __init__(
        self,
        time,
        lat,
        lon,
        height,
        horizontal_sigma_m,
        vertical_sigma_m,
        ellipsoid: Ellipsoid = WGS84,
        lever_arm_t=None,
        vertical: bool = True,
        body_mat_i=None,
        height_sigma_m=None,
    ):
        self.height_sigma = None if height_sigma_m is None else np.asarray(height_sigma_m, float)
        self.lever_arm_t = None if lever_arm_t is None else np.asarray(lever_arm_t, float)
        self.body_mat_i = body_mat_i
        self.vertical = bool(vertical)
        self.time = np.asarray(time, float)
        self.lat = np.asarray(lat, float)
        self.lon = np.asarray(lon, float)
        self.height = np.asarray(height, float)
        self.sigma = np.array([horizontal_sigma_m, horizontal_sigma_m, vertical_sigma_m], float)
        self.ellipsoid = ellipsoid

    def build(self, nav, idx, half_window, n_state: int = N_STATE_AIDED):
        """Return ``z (N, 3)``, ``H (N, 3, n_state)``, ``R (N, 3, 3)`` (ENU), NaN where no sample.

        ``n_state`` = 8 leaves out the attitude term (only right when ``theta`` is negligible
        against the GNSS noise; kept for tests of the geometry).
        """
        t_ep = nav.time[idx]
        nep = t_ep.size
        z = np.full((nep, 3), np.nan)
        h = np.zeros((nep, 3, n_state))
        r = np.broadcast_to(np.diag(self.sigma**2), (nep, 3, 3)).copy()
        ok = (
            (self.time >= nav.time[0])
            & (self.time <= nav.time[-1])
            & np.isfinite(self.lat)
            & np.isfinite(self.lon)
            & np.isfinite(self.height)
        )
        if not ok.any():
            return z, h, r
        ts, lat, lon, hh = self.time[ok], self.lat[ok], self.lon[ok], self.height[ok]
        var_up = np.full(ts.size, self.sigma[2] ** 2)
        if self.height_sigma is not None:
            own = self.height_sigma[ok]
            var_up = np.where(np.isfinite(own), np.maximum(var_up, own * own), var_up)
        k, d, use = _nearest_epoch(t_ep, ts, half_window)
        ts, lat, lon, hh, k, d, var_up = ts[use], lat[use], lon[use], hh[use], k[use], d[use], var_up[use]
        if ts.size == 0:
            return z, h, r
        m_ie = mat_ie(ts, self.ellipsoid.omega)
        r_g = np.einsum("nij,nj->ni", m_ie, geodetic_to_ecef(lat, lon, hh, self.ellipsoid))
        m_in = np.einsum("nij,njk->nik", m_ie, mat_en(lat, lon))
        r_c = hermite_position(nav, ts)
        arm = self.lever_arm_t is not None and np.any(self.lever_arm_t != 0.0)
        if arm:
            arm_i = (
                nav.mat_it[nearest_sample(nav.time, ts)]
                if self.body_mat_i is None
                else attitude_at(self.body_mat_i, ts)
            )
            r_c = r_c + np.einsum("nij,j->ni", arm_i, self.lever_arm_t)
        zs = np.einsum("nji,nj->ni", m_in, r_c - r_g)
        # H (dq block) = M_in^T C_k: ENU <- triad
        c_k = nav.mat_it[idx][k]
        hq = np.einsum("nji,njk->nik", m_in, c_k)
        cnt = np.bincount(k, minlength=nep).astype(float)
        zsum = np.zeros((nep, 3))
        hsum = np.zeros((nep, 3, n_state))
        np.add.at(zsum, k, zs)
        hblk = np.zeros((ts.size, 3, n_state))
        hblk[:, :, DQ] = hq
        hblk[:, :, DP] = d[:, None, None] * hq
        if n_state >= N_STATE_AIDED:
            # q x theta = [q x] theta with q = C^T r on the triad at the epoch, and the offset's
            # d [p x] theta: the true error's rate at the epoch is C (dp + p x theta)
            q_t = np.einsum("nji,nj->ni", c_k, nav.r_i[idx][k])
            p_t = np.einsum("nji,nj->ni", c_k, nav.v_i[idx][k])
            hblk[:, :, TH] = np.einsum("nij,njk->nik", hq, skew(q_t) + d[:, None, None] * skew(p_t))
            if arm and self.body_mat_i is None:
                hblk[:, :, TH] += hq @ skew(self.lever_arm_t)
        np.add.at(hsum, k, hblk)
        have = cnt > 0
        z[have] = zsum[have] / cnt[have, None]
        h[have] = hsum[have] / cnt[have, None, None]
        r[have] /= cnt[have, None, None]
        if self.height_sigma is not None:
            # the mean of the epoch's fixes: the sum of their own variances over the count squared
            vsum = np.bincount(k, weights=var_up, minlength=nep)
            r[have, 2, 2] = vsum[have] / cnt[have] ** 2
        if not self.vertical:
            z[:, 2] = np.nan
        return z, h, r


def true_error_basis(q_t, p_t, n_state: int = N_STATE_AIDED):
    """Change of state basis ``x' = T x`` to the true position and velocity errors of the
    aided model, and its inverse (for :func:`gravsurvey.inm.kalman.change_basis`).

    The seed's ``dq = C^T dr - q x theta`` carries the attitude error scaled by the Earth's
    radius (0.05 deg: 5.6 km against a 1 m GNSS position error), so the aided covariance is
    nearly singular (smallest eigenvalue of the correlation matrix ~1e-6); in the basis
    ``(dq + q x theta, dp + p x theta, g, f3, theta, b)`` = ``(C^T dr, C^T dv, ...)`` it is
    well conditioned (~0.03).  Only the ``dq, dp`` rows change; ``T^-1`` flips the sign of
    the ``theta`` coupling.

    Parameters
    ----------
    q_t, p_t : ndarray (N, 3)
        Computed triad-resolved position (m) and inertial velocity (m/s) at each epoch.
    n_state : int
        State size (>= 11: the attitude states ``TH`` must exist).

    Returns
    -------
    t, t_inv : ndarray (N, n_state, n_state)
    """
    q_t = np.asarray(q_t, float)
    p_t = np.asarray(p_t, float)
    nep = q_t.shape[0]
    t = np.broadcast_to(np.eye(n_state), (nep, n_state, n_state)).copy()
    for rows, v in ((DQ, q_t), (DP, p_t)):
        sk = np.zeros((nep, 3, 3))
        sk[:, 0, 1], sk[:, 0, 2], sk[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
        sk[:, 1, 0], sk[:, 2, 0], sk[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
        t[:, rows[:, None], TH[None, :]] = sk
    t_inv = t.copy()
    t_inv[:, DQ[:, None], TH[None, :]] *= -1.0
    t_inv[:, DP[:, None], TH[None, :]] *= -1.0
    return t, t_inv
