"""Gradiometer-aided inertial navigation after seed 000 (Vasin 1990), as free functions.

A gravity gradiometer measures the gravitation gradient tensor ``T = d g / d r``
(symmetric, trace-free outside the masses; 1 Eotvos = 1e-9 1/s^2).  Seed 000 uses
it three ways, all implemented here (equations in docs/method.md, "Gradiometer-aided
navigation"):

1. **The vertical from the tensor alone** (seed eq. 2.1): the direction of the
   gravitation is the eigenvector ``g0`` of ``T`` whose eigenvalue ``lambda`` solves
   the characteristic equation ``lambda^3 + p lambda + q = 0`` with
   ``p = -tr(T^2)/2``, ``q = -tr(T^3)/3`` (``tr T = 0``) and has the largest modulus
   (``~ +2 w0^2 ~ 3080 E`` near the Earth) -- :func:`characteristic_coefficients`,
   :func:`characteristic_roots`, :func:`vertical_eigen`.
2. **Gravitation propagated instead of modelled** (seed eq. 1.2): on Earth-fixed
   axes a static field gives ``dg_e/dt = T_e V_e`` (V the velocity relative to the
   Earth; the seed's ``u~^T g`` term is the rotation of inertial axes and vanishes
   on Earth-fixed ones) -- :func:`propagate_gravitation_e`.
3. **Error dynamics and correction** (seed sections 2-5): the vertical channel
   stays unstable (``d dv/dt = dg``, ``d dg/dt = lambda dv``: rate ``sqrt(lambda)``)
   unless height-aided; the horizontal channel loses the Schuler restoring term
   (the vertical does not depend on the position error) and becomes a double
   integrator of the accelerometer error plus ``g`` times the eigenvector error
   ``~ r dT_h3 / 3``; per-axis position-aided (3 states) and velocity-aided
   (2 states) correction filters with the seed's closed-form asymptotic gains
   (all poles at ``-l0``) and the full (steady-state and time-varying) Kalman
   filter for the same channel model.

Units: SI inside (m, s, 1/s^2); Eotvos only at the edges (``*_eotvos`` names).
Shapes: tensors ``(n, 3, 3)``, vectors ``(n, 3)``, on whatever axes the caller
uses (the formulas are frame-independent).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg

from gravsurvey.errors import DataError

#: One Eotvos in 1/s^2.
EOTVOS = 1.0e-9

# State indices of the per-axis position-aided channel (seed eq. 4.1, x1..x3) and of
# the dimensional channel used on simulated flights: position error, velocity error,
# lumped acceleration error (accelerometer error + g * eigen-vertical error).
POS = 0
VEL = 1
ACC = 2

# State indices of the vertical channel: height error, vertical velocity error, error
# of the propagated gravitation magnitude.
DH = 0
DVU = 1
DG = 2


# --------------------------------------------------------------------------
# 1. The characteristic equation and the eigen-vertical (seed eq. 2.1)
# --------------------------------------------------------------------------


def _as_tensors(gamma, name="gamma"):
    t = np.asarray(gamma, dtype=float)
    if t.ndim == 2:
        t = t[None]
    if t.ndim != 3 or t.shape[1:] != (3, 3):
        raise DataError(f"{name}: expected an (n, 3, 3) array of gradient tensors in 1/s^2, got shape {t.shape}")
    return t


def characteristic_coefficients(gamma):
    """Coefficients of the seed's characteristic equation ``lambda^3 + p lambda + q = 0``.

    Parameters
    ----------
    gamma : array_like, shape (n, 3, 3) or (3, 3)
        Gravitation gradient tensors, 1/s^2, symmetric and trace-free.

    Returns
    -------
    p, q : ndarray, shape (n,)
        ``p = -tr(T^2)/2`` in 1/s^4 and ``q = -tr(T^3)/3`` in 1/s^6.  For a
        trace-free matrix these are exactly the coefficients of ``det(lambda I - T)``
        (``q = -det T``).
    """
    t = _as_tensors(gamma)
    t2 = t @ t
    p = -0.5 * np.trace(t2, axis1=1, axis2=2)
    q = -np.trace(t2 @ t, axis1=1, axis2=2) / 3.0
    return p, q


def characteristic_roots(gamma):
    """The three real roots of ``lambda^3 + p lambda + q = 0``, ascending.

    Trigonometric (Viete) solution of the depressed cubic, real because ``T`` is
    symmetric: ``lambda_k = 2 sqrt(-p/3) cos(phi/3 - 2 pi k/3)`` with
    ``cos phi = (3 q / (2 p)) sqrt(-3/p)``.

    Parameters
    ----------
    gamma : array_like, shape (n, 3, 3)
        Gradient tensors, 1/s^2 (the trace is removed first: a measured tensor's
        trace is noise).

    Returns
    -------
    lam : ndarray, shape (n, 3)
        Eigenvalues, 1/s^2, ascending.
    """
    t = _as_tensors(gamma)
    t = t - (np.trace(t, axis1=1, axis2=2) / 3.0)[:, None, None] * np.eye(3)
    p, q = characteristic_coefficients(t)
    m = np.sqrt(np.maximum(-p / 3.0, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        c = np.where(m > 0.0, -q / (2.0 * m**3), 0.0)
    phi = np.arccos(np.clip(c, -1.0, 1.0))
    k = np.arange(3)
    lam = 2.0 * m[:, None] * np.cos(phi[:, None] / 3.0 - 2.0 * np.pi * k[None, :] / 3.0)
    return np.sort(lam, axis=1)


def vertical_eigen(gamma, down_hint=None):
    """The seed's gravitational vertical: eigenvalue and unit eigenvector of ``T``.

    The vertical root is the one of largest modulus (``~ +2 w0^2``, the other two
    ``~ -w0^2``).  Its eigenvector is the longest cross product of two rows of
    ``T - lambda I`` (every row is orthogonal to it).

    Parameters
    ----------
    gamma : array_like, shape (n, 3, 3)
        Gradient tensors on some axes, 1/s^2.
    down_hint : array_like, shape (n, 3) or (3,), optional
        Any vector with a positive component along the gravitation on the same
        axes (e.g. minus the mean specific force); fixes the eigenvector's sign.
        Without it the sign is such that the largest-modulus component is negative
        (right for a near-level Up axis).

    Returns
    -------
    lam : ndarray, shape (n,)
        Vertical eigenvalue, 1/s^2 (``|lambda| = |grad |g||``, ~3.08e-6 near the Earth).
    g0 : ndarray, shape (n, 3)
        Unit vector along the gravitation (pointing down), same axes.
    """
    t = _as_tensors(gamma)
    roots = characteristic_roots(t)
    idx = np.argmax(np.abs(roots), axis=1)
    lam = roots[np.arange(roots.shape[0]), idx]
    a = t - lam[:, None, None] * np.eye(3)
    c = np.stack([np.cross(a[:, 0], a[:, 1]), np.cross(a[:, 1], a[:, 2]), np.cross(a[:, 2], a[:, 0])], axis=1)
    norms = np.linalg.norm(c, axis=2)
    best = np.argmax(norms, axis=1)
    g0 = c[np.arange(c.shape[0]), best] / norms[np.arange(c.shape[0]), best][:, None]
    if down_hint is None:
        big = np.argmax(np.abs(g0), axis=1)
        sgn = -np.sign(g0[np.arange(g0.shape[0]), big])
    else:
        hint = np.broadcast_to(np.asarray(down_hint, dtype=float), g0.shape)
        sgn = np.sign(np.einsum("ki,ki->k", g0, hint))
    sgn[sgn == 0.0] = 1.0
    return lam, g0 * sgn[:, None]


# --------------------------------------------------------------------------
# 2. Gravitation propagated by dg/dt = T V (seed eq. 1.2)
# --------------------------------------------------------------------------


def propagate_gravitation_e(t_s, g0_e, gamma_e, vel_e):
    """Integrate ``dg_e/dt = T_e V_e`` from an initial gravitation (trapezoidal rule).

    On Earth-fixed axes a time-invariant field has ``g_e = g_e(r_e)``, so its total
    derivative along the path is ``T_e dr_e/dt``; the seed's inertial form adds
    ``u~^T g`` for the rotation of inertial axes, which is absent here.

    Parameters
    ----------
    t_s : array_like, shape (n,)
        Epochs, s, increasing.
    g0_e : array_like, shape (3,)
        Gravitation at ``t_s[0]``, m/s^2, Earth-fixed axes.
    gamma_e : array_like, shape (n, 3, 3)
        Gradient tensors on Earth-fixed axes, 1/s^2.
    vel_e : array_like, shape (n, 3)
        Velocity relative to the Earth on the same axes, m/s.

    Returns
    -------
    g_e : ndarray, shape (n, 3)
        Propagated gravitation, m/s^2.  Its error grows with the tensor error times
        the distance flown: 1 E over 100 km is 1e-4 m/s^2 = 10 mGal.
    """
    t = np.asarray(t_s, dtype=float)
    gam = _as_tensors(gamma_e, "gamma_e")
    v = np.asarray(vel_e, dtype=float)
    if gam.shape[0] != t.size or v.shape != (t.size, 3):
        raise DataError(
            f"propagate_gravitation_e: expected gamma_e ({t.size}, 3, 3) and vel_e ({t.size}, 3), got {gam.shape} and {v.shape}"
        )
    rate = np.einsum("kij,kj->ki", gam, v)
    inc = 0.5 * (rate[1:] + rate[:-1]) * np.diff(t)[:, None]
    out = np.empty((t.size, 3))
    out[0] = np.asarray(g0_e, dtype=float)
    out[1:] = out[0] + np.cumsum(inc, axis=0)
    return out


# --------------------------------------------------------------------------
# 3. Error dynamics: vertical and horizontal channels
# --------------------------------------------------------------------------


def vertical_channel_matrix(lam, gains=None):
    """Error dynamics of the vertical channel with propagated gravitation (seed section 2).

    States ``(DH, DVU, DG)``: height, vertical velocity, gravitation-magnitude errors;
    ``d dh/dt = dv``, ``d dv/dt = dg`` (the accelerometer sees ``f``; gravitation comes
    from the integral), ``d dg/dt = lambda dv`` (seed eq. 2.3 varied).  With height
    aiding (a measured height error ``dh``) and gains ``(k1, k2, k3)`` the closed loop
    is ``A - k H``, ``H = (1, 0, 0)``.

    Parameters
    ----------
    lam : float
        Vertical eigenvalue, 1/s^2 (``~ 2 w0^2``).
    gains : sequence of 3 floats, optional
        Height-aiding gains (1/s, 1/s^2, 1/s^3); None = free inertial.

    Returns
    -------
    a : ndarray, shape (3, 3)
        System matrix, 1/s.  Free: eigenvalues ``0, +-sqrt(lambda)``: one grows like
        ``exp(sqrt(2) w0 t)`` (time constant ~9.5 min).
    """
    a = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, float(lam), 0.0]])
    if gains is not None:
        a[:, DH] -= np.asarray(gains, dtype=float)
    return a


def height_aiding_gains(l0, lam):
    """Height-aiding gains placing all three vertical-channel poles at ``-l0``.

    ``det(s I - A + k H) = s^3 + k1 s^2 + (k2 - lambda) s + (k3 - lambda k1)``
    ``= (s + l0)^3`` gives ``k1 = 3 l0``, ``k2 = 3 l0^2 + lambda``,
    ``k3 = l0^3 + 3 lambda l0``.

    Parameters
    ----------
    l0 : float
        Pole magnitude, 1/s.
    lam : float
        Vertical eigenvalue, 1/s^2.

    Returns
    -------
    gains : ndarray, shape (3,)
    """
    return np.array([3.0 * l0, 3.0 * l0**2 + lam, l0**3 + 3.0 * lam * l0])


def horizontal_channel_matrix(omega0, gradiometer: bool):
    """Per-axis horizontal error dynamics, states ``(POS, VEL, ACC)``.

    Without a gradiometer the computed vertical tilts with the position error and
    ``d dv/dt = -w0^2 dx + b`` (the Schuler pendulum, period ``2 pi / w0``, 84.4 min
    at the surface).  With the eigen-vertical the tilt does not depend on ``dx``:
    ``d dv/dt = b`` (seed section 2, eq. 3.9: "no oscillations of the instrument
    vertical").  ``b`` (``ACC``) is the lumped acceleration error, constant here.

    Parameters
    ----------
    omega0 : float
        Schuler frequency ``sqrt(g / r)``, rad/s.
    gradiometer : bool

    Returns
    -------
    a : ndarray, shape (3, 3)
    """
    a = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]])
    if not gradiometer:
        a[VEL, POS] = -(omega0**2)
    return a


def eigen_vertical_acceleration_error(d_t_h3, lam_v, lam_h, g):
    """Horizontal acceleration error from an error of the tensor's vertical-horizontal element.

    Seed eq. 3.6/3.8: ``(T - lambda I) dg0 = -(dT - dlambda I) g0`` gives a tilt of the
    eigenvector ``dg0_h = dT_h3 / (lambda_v - lambda_h)`` and an acceleration error
    ``g dg0_h``; near the Earth ``lambda_v - lambda_h = 3 w0^2`` and this is
    ``r dT_h3 / 3``: 1 E -> 2.1e-3 m/s^2.

    Parameters
    ----------
    d_t_h3 : float or ndarray
        Error of ``T_13`` or ``T_23``, 1/s^2.
    lam_v, lam_h : float
        Vertical and horizontal eigenvalues, 1/s^2.
    g : float
        Gravitation magnitude, m/s^2.

    Returns
    -------
    float or ndarray, m/s^2
    """
    return g * np.asarray(d_t_h3) / (lam_v - lam_h)


def propagate_linear(a, x0, dt, n, b=None, u=None):
    """Exact discretisation of ``dx/dt = A x + B u`` with ``u`` held per step.

    Parameters
    ----------
    a : ndarray, shape (m, m)
    x0 : ndarray, shape (m,)
    dt : float
        Step, s.
    n : int
        Number of epochs returned (including ``x0``).
    b : ndarray, shape (m, k), optional
    u : ndarray, shape (n - 1, k), optional

    Returns
    -------
    x : ndarray, shape (n, m)
    """
    m = a.shape[0]
    if b is None:
        phi = scipy.linalg.expm(a * dt)
        gam = None
    else:
        k = b.shape[1]
        big = np.zeros((m + k, m + k))
        big[:m, :m] = a
        big[:m, m:] = b
        e = scipy.linalg.expm(big * dt)
        phi, gam = e[:m, :m], e[:m, m:]
    x = np.empty((n, m))
    x[0] = x0
    for i in range(1, n):
        x[i] = phi @ x[i - 1]
        if gam is not None:
            x[i] += gam @ u[i - 1]
    return x


def oscillation_period(t_s, x):
    """Mean period of a signal's oscillation from its mean-crossings, s (inf if < 2 crossings).

    Parameters
    ----------
    t_s : ndarray, shape (n,)
    x : ndarray, shape (n,)
    """
    y = np.asarray(x, dtype=float) - np.mean(x)
    s = np.signbit(y)
    idx = np.nonzero(s[1:] != s[:-1])[0]
    if idx.size < 2:
        return math.inf
    # linear interpolation of the crossing times
    tc = t_s[idx] - y[idx] * (t_s[idx + 1] - t_s[idx]) / (y[idx + 1] - y[idx])
    return 2.0 * float(np.mean(np.diff(tc)))


# --------------------------------------------------------------------------
# 4. Correction filters: seed asymptotic gains and the Kalman filter
# --------------------------------------------------------------------------


def position_channel_matrix(mu):
    """Seed eq. 4.1 observable subsystem (dimensionless, tau = w0 t): ``x1' = mu x2, x2' = x3, x3' = 0``.

    ``x1`` is the (scaled) position error, measured (``z1* = x1``), ``x2`` the velocity
    error, ``x3`` the lumped gradiometer + accelerometer error ``delta1 + epsilon1``;
    ``mu = max |w_horizontal| / w0`` the seed's small parameter.

    Returns
    -------
    a : ndarray, shape (3, 3); h : ndarray, shape (1, 3)
    """
    a = np.array([[0.0, float(mu), 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]])
    return a, np.array([[1.0, 0.0, 0.0]])


def velocity_channel_matrix():
    """Seed section 5 observable subsystem: ``y1' = y2, y2' = 0``, ``y1`` measured.

    Returns
    -------
    a : ndarray, shape (2, 2); h : ndarray, shape (1, 2)
    """
    return np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[1.0, 0.0]])


def asymptotic_gains_position(l0, mu):
    """Seed eq. 4.2 gains: ``K1 = 3 l0, K2 = 3 l0^2 / mu, K3 = l0^3 / mu`` (all poles at -l0).

    Returns
    -------
    k : ndarray, shape (3,)
    """
    return np.array([3.0 * l0, 3.0 * l0**2 / mu, l0**3 / mu])


def asymptotic_gains_velocity(l0):
    """Seed section 5 gains: ``K1 = 2 l0, K2 = l0^2`` (both poles at -l0).

    Returns
    -------
    k : ndarray, shape (2,)
    """
    return np.array([2.0 * l0, l0**2])


def seed_noise_variances_position(l0, mu, rho2):
    """Seed eq. 4.6 steady-state error variances for white position noise ``mu xi``, intensity ``rho2``.

    Returns
    -------
    d : ndarray, shape (3,)
        ``(33/16 mu^2 l0, 7/4 l0^3, 3/16 l0^5) rho2``.
    """
    return np.array([33.0 / 16.0 * mu**2 * l0, 7.0 / 4.0 * l0**3, 3.0 / 16.0 * l0**5]) * rho2


def seed_noise_variances_velocity(l0, rho2):
    """Seed section 5 steady-state error variances ``(5/4 l0, 1/4 l0^3) rho2``."""
    return np.array([5.0 / 4.0 * l0, 1.0 / 4.0 * l0**3]) * rho2


def closed_loop_matrix(a, h, k):
    """``A - K H`` of an observer with gain column ``k``."""
    return np.asarray(a, dtype=float) - np.outer(np.asarray(k, dtype=float), np.asarray(h, dtype=float)[0])


def steady_state_error_covariance(a, h, k, q, r):
    """Steady-state estimation-error covariance of the observer ``A - K H``.

    Solves ``F P + P F^T + Q + K R K^T = 0`` with ``F = A - K H`` (continuous time,
    white process noise of intensity ``Q`` and measurement noise of intensity ``r``).

    Parameters
    ----------
    a : ndarray (m, m); h : ndarray (1, m); k : ndarray (m,)
    q : ndarray (m, m)
        Process-noise intensity.
    r : float
        Measurement-noise intensity.

    Returns
    -------
    p : ndarray, shape (m, m)
    """
    f = closed_loop_matrix(a, h, k)
    k = np.asarray(k, dtype=float)
    return scipy.linalg.solve_continuous_lyapunov(f, -(np.asarray(q, dtype=float) + r * np.outer(k, k)))


def steady_state_kalman_gain(a, h, q, r):
    """Continuous steady-state Kalman gain ``K = P H^T / r`` (``P`` from the Riccati equation).

    Parameters
    ----------
    a : ndarray (m, m); h : ndarray (1, m)
    q : ndarray (m, m)
        Process-noise intensity (the model's: e.g. a random walk of the gradiometer
        error in the last state).
    r : float
        Measurement-noise intensity.

    Returns
    -------
    k : ndarray, shape (m,)
    p : ndarray, shape (m, m)
        Steady-state error covariance.
    """
    p = scipy.linalg.solve_continuous_are(
        np.asarray(a, float).T, np.asarray(h, float).T, np.asarray(q, float), np.array([[float(r)]])
    )
    return (p @ np.asarray(h, float).T / r)[:, 0], p


def dimensional_gains_position(l0_rad_s):
    """Position-aided gains of the dimensional channel ``(POS, VEL, ACC)`` (``x' = v, v' = b, b' = 0``).

    The seed's gains after undoing its scaling (``x1 = mu dx / r``, ``x2 = dv / (r w0)``,
    ``x3 = b / (r w0^2)``, ``tau = w0 t``): ``(3 L, 3 L^2, L^3)`` with ``L = l0 w0`` in 1/s.
    """
    return np.array([3.0 * l0_rad_s, 3.0 * l0_rad_s**2, l0_rad_s**3])


def run_channel_filters(t_s, z_pos, r_pos, q_acc, l0_rad_s, x0_sigma):
    """Run the asymptotic observer and a discrete Kalman filter on one horizontal axis.

    Channel (with the eigen-vertical, no Schuler term): ``x' = v``, ``v' = b``,
    ``b`` a random walk of intensity ``q_acc``; ``z_pos`` the measured position
    error (INS minus GNSS), white with variance ``r_pos`` per sample.

    Parameters
    ----------
    t_s : ndarray, shape (n,)
        Epochs, s, uniform.
    z_pos : ndarray, shape (n,)
        Position differences, m.
    r_pos : float
        Variance of one position sample, m^2.
    q_acc : float
        Intensity of the random walk of ``b``, (m/s^2)^2 / s.
    l0_rad_s : float
        Pole of the asymptotic observer, 1/s.
    x0_sigma : sequence of 3 floats
        Prior standard deviations of (position, velocity, acceleration) errors.

    Returns
    -------
    x_asym, x_kf : ndarray, shape (n, 3)
        Estimated ``(POS, VEL, ACC)`` errors of both filters.
    k_kf : ndarray, shape (3,)
        The Kalman filter's last gain expressed as a continuous gain (``K / dt``),
        comparable with :func:`dimensional_gains_position`.
    """
    t = np.asarray(t_s, dtype=float)
    dt = float(t[1] - t[0])
    a = horizontal_channel_matrix(0.0, gradiometer=True)
    phi = scipy.linalg.expm(a * dt)
    # discretised random-walk process noise (Van Loan, closed form for the triple integrator)
    qd = q_acc * np.array(
        [[dt**5 / 20, dt**4 / 8, dt**3 / 6], [dt**4 / 8, dt**3 / 3, dt**2 / 2], [dt**3 / 6, dt**2 / 2, dt]]
    )
    n = t.size
    x_kf = np.zeros((n, 3))
    x_as = np.zeros((n, 3))
    x = np.array([z_pos[0], 0.0, 0.0])
    p = np.diag(np.square(np.asarray(x0_sigma, dtype=float)))
    p[POS, POS] = r_pos
    xa = x.copy()
    # asymptotic observer: exact discretisation of x' = A x + K (z - x1) with z held per step
    ka = dimensional_gains_position(l0_rad_s)
    fa = a - np.outer(ka, [1.0, 0.0, 0.0])
    big = np.zeros((4, 4))
    big[:3, :3] = fa
    big[:3, 3] = ka
    e = scipy.linalg.expm(big * dt)
    phi_a, gam_a = e[:3, :3], e[:3, 3]
    k = np.zeros(3)
    x_kf[0], x_as[0] = x, xa
    for i in range(1, n):
        xa = phi_a @ xa + gam_a * z_pos[i - 1]
        x_as[i] = xa
        x = phi @ x
        p = phi @ p @ phi.T + qd
        s = p[POS, POS] + r_pos
        k = p[:, POS] / s
        x = x + k * (z_pos[i] - x[POS])
        p = p - np.outer(k, p[POS, :])
        x_kf[i] = x
    return x_as, x_kf, k / dt


# --------------------------------------------------------------------------
# 5. Flight products for the pipeline (processing.gradiometer: true)
# --------------------------------------------------------------------------


def flight_products(grad_time, gamma_t, nav_time, lat, lon, height, vel_n, disturbance_start, triad, ellipsoid=None):
    """Summary products of a flight's gradient channel (summary.json ``estimator.gradiometer``).

    Rotation invariants on any triad: the vertical eigenvalue (median, spread) and the
    trace (instrument noise/bias indicator).  On a platform triad (axes = ENU) also the
    gravitation propagated by ``dg/dt = T V`` along the navigation solution, started from
    the normal gravitation plus ``disturbance_start`` (vertical) at the first gradient epoch
    (horizontal anomaly assumed 0 there), and the eigen-vertical's tilt from the Up axis.

    Parameters
    ----------
    grad_time : ndarray, shape (m,)
        Gradient epochs, s (record time base).
    gamma_t : ndarray, shape (m, 3, 3)
        Tensors on the triad, 1/s^2.
    nav_time : ndarray, shape (n,)
        Navigation epochs, s.
    lat, lon : ndarray, shape (n,)
        rad.
    height : ndarray, shape (n,)
        m.
    vel_n : ndarray, shape (n, 3)
        ENU velocity, m/s.
    disturbance_start : float
        Gravity disturbance at the start, m/s^2 (e.g. the scalar estimate's first value).
    triad : {"platform", "strapdown"}
    ellipsoid : Ellipsoid, optional
        WGS84 by default.

    Returns
    -------
    products : dict
        JSON-ready numbers (``*_eotvos``, ``*_mgal``, ``*_arcsec``) and, for a platform
        triad, ``time`` (k,) s, ``disturbance`` (k,) m/s^2 and ``horizontal_n`` (k, 2) m/s^2
        (anomalous gravitation east/north) at the gradient epochs inside the navigation span.
    """
    from gravsurvey.geodesy import (
        WGS84,
        geodetic_to_ecef,
        mat_en,
        normal_gravitation_ecef,
    )

    ell = WGS84 if ellipsoid is None else ellipsoid
    gam = _as_tensors(gamma_t, "gamma_t")
    lam_all = characteristic_roots(gam)
    lam_v = lam_all[np.arange(lam_all.shape[0]), np.argmax(np.abs(lam_all), axis=1)]
    out = {
        "samples": int(gam.shape[0]),
        "vertical_eigenvalue_median_eotvos": float(np.median(lam_v) / EOTVOS),
        "vertical_eigenvalue_std_eotvos": float(np.std(lam_v) / EOTVOS),
        "trace_median_eotvos": float(np.median(np.trace(gam, axis1=1, axis2=2)) / EOTVOS),
    }
    if triad != "platform":
        out["note"] = (
            "strapdown triad: dg/dt = T V needs the triad attitude, which the scalar "
            "solution does not carry; only rotation invariants reported"
        )
        return out
    sel = (grad_time >= nav_time[0]) & (grad_time <= nav_time[-1])
    t = np.asarray(grad_time)[sel]
    if t.size < 2:
        out["note"] = "fewer than 2 gradient samples inside the navigation span"
        return out
    la = np.interp(t, nav_time, lat)
    lo = np.interp(t, nav_time, np.unwrap(lon))
    h = np.interp(t, nav_time, height)
    v_n = np.stack([np.interp(t, nav_time, vel_n[:, j]) for j in range(3)], axis=1)
    r_e = geodetic_to_ecef(la, lo, h, ell)
    m_en = mat_en(la, lo)
    g_norm_n = np.einsum("kji,kj->ki", m_en, normal_gravitation_ecef(r_e, ell))
    gam_e = np.einsum("kij,kjl,kml->kim", m_en, gam[sel], m_en)
    v_e = np.einsum("kij,kj->ki", m_en, v_n)
    g0_n = g_norm_n[0] + np.array([0.0, 0.0, -float(disturbance_start)])
    g_e = propagate_gravitation_e(t, m_en[0] @ g0_n, gam_e, v_e)
    anom_n = np.einsum("kji,kj->ki", m_en, g_e) - g_norm_n
    _, g0 = vertical_eigen(gam[sel])
    tilt = np.degrees(np.arccos(np.clip(-g0[:, 2], -1.0, 1.0))) * 3600.0
    out.update(
        {
            "time": t,
            "disturbance": -anom_n[:, 2],
            "horizontal_n": anom_n[:, :2],
            "horizontal_end_mgal": [float(x / 1e-5) for x in anom_n[-1, :2]],
            "eigen_vertical_tilt_rms_arcsec": float(np.sqrt(np.mean(tilt**2))),
        }
    )
    return out
