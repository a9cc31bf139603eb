"""3D-INM mechanization for an arbitrarily oriented instrument triad.

The seed equations (004 eq. 1, Andreev 002 eq. 2.1-2.4), on the triad axes::

    dq/dt = p - w x q
    dp/dt = G + F - w x p
    dC/dt = C [w x]             C = mat_it, triad -> inertial

with ``q`` the geocentric position and ``p`` the inertial velocity resolved on
the triad, ``w`` the gyro rates and ``F`` the specific force.  Writing
``r_i = C q`` and ``v_i = C p`` turns the first two into ``dr_i/dt = v_i``,
``dv_i/dt = G_i + C F`` exactly (``dC/dt q = C (w x q)`` cancels the
transport terms).  We integrate that inertial form, which has no fast
rotation terms even for a strapdown triad in a turn, and recover
``q = C^T r_i``, ``p = C^T v_i`` on output: the solution is the seed's, with
less integration error.

Integration, per IMU interval ``[t_k, t_k+1]`` (samples are instantaneous
values at their time stamps, docs/formats.md):

1. Attitude: exact rotation ``C_k+1 = C_k Exp(phi_k)`` (Rodrigues).  The
   rate at the interval midpoint ``w_m`` comes from 4-point Lagrange
   interpolation of the samples; the quadratic through ``(w_k, w_m, w_k+1)``
   gives the angle increments of the two half intervals
   ``d1 = dt/24 (5 w_k + 8 w_m - w_k+1)``, ``d2 = dt/24 (-w_k + 8 w_m + 5 w_k+1)``
   and the two-sample coning-corrected rotation vector
   ``phi = d1 + d2 + 2/3 d1 x d2``.
2. Specific force in inertial axes ``a_k = C_k F_k`` at every sample; its
   value at the interval midpoint by 4-point Lagrange interpolation in time
   (3-point at the ends): 4th-order accurate.
3. Translation: classical RK4 on ``(r_i, v_i)``.  The normal gravitation
   (:mod:`gravsurvey.geodesy`) is evaluated on inertial axes: the field of a level ellipsoid
   is symmetric about the Earth's axis, so rotating to ECEF and back is an identity (to
   round-off, 2e-13 relative).  The full closed form is evaluated once per step, at stage 0;
   stages 1-3 take the degree-0/2/4 zonal field ``Z`` (point mass, ``J2``, ``J4``: a
   polynomial, no transcendental calls) at their own point plus the step start's remainder
   ``G - Z`` (``J6`` and beyond, ~4e-7 m/s^2).  That remainder changes by at most 7.2e-13
   m/s^2 per metre at flight heights (measured; test_geodesy), and a stage point is at most
   ``dt |v_i|`` + the altimeter change from stage 0's (6 m at 100 Hz, 60 m at 10 Hz with
   ``|v_i| <= 600 m/s``), so each stage's gravitation is within 4.3e-12 m/s^2 (4.3e-7 mGal)
   of the exact one at 100 Hz, 4.3e-11 (4.3e-6 mGal) at 10 Hz.  Measured against the kernel
   of commit 9111ed4 (four full evaluations per step, iterated geodetic conversion), 1 h of a
   noisy strapdown flight turning at 0.05 rad/s: 6.0e-8 m and 4.2e-11 m/s at 100 Hz, 6.0e-7 m
   and 3.7e-10 m/s at 10 Hz (0.33 m would cost 0.05 mGal); against four full evaluations
   (``mechanize_reference(exact_stages=True)``), 10 min at 10 Hz: 9.4e-8 m, 2.7e-10 m/s
   (tests/test_inm_mechanization.py).

Gravity model with external radius (``use_ext``, Andreev section 6): the
radius ``R`` of the current point is taken from the altimeter's ellipsoidal
height ``h_ext`` at the computed latitude/longitude, and::

    G_model(r) = (|r| / R) * G_normal(r * R / |r|)

which for a point mass is ``-mu r / R^3``: the computed vector with the
external radius in the denominator, so the error is
``dG = -w0^2 dr + 3 w0^2 r0 eps`` and every channel is a Schuler oscillator.
The ellipsoid normal and computed height at the step start (which place ``R``) come from
Bowring's closed form without iteration (:func:`~gravsurvey.geodesy.geodetic_trig_scalar`):
the normal within 4.1e-13 rad below 20 km (6.6e-10 up to 1000 km), the height as exact as the
iterated conversion's (it is stationary in the latitude); over a 60 m step that moves ``R`` by
< 4e-8 m, < 1.2e-13 m/s^2.
With ``use_ext = False`` the computed position is used (vertical channel
unstable, ``dG = -w0^2 (dr - 3 r0 r0.dr)``).

Finite-state guard: :func:`mechanize` refuses inputs no IMU or altimeter can give
(:func:`check_mechanization_inputs`) and a navigation state no flight can have
(:func:`check_navigation_state`) with a :class:`~gravsurvey.errors.DataError` naming the
channel, the sample and its time, instead of letting NaN or a run-away state reach the
filter.  Both are vectorised numpy checks over the whole block, not per sample in Python: on a
2 h flight at 50 Hz (360,001 samples) 0.08-0.10 s of the mechanization's 1.2-1.5 s (loaded
2-core machine).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from ..errors import DataError
from ..geodesy import (
    WGS84,
    Ellipsoid,
    ecef_to_geodetic,
    geodetic_to_ecef,
    geodetic_trig_scalar,
    mat_en,
    mat_ie,
    normal_gravitation_ecef,
    normal_gravitation_inertial_scalar,
    normal_gravitation_j2_j4,
    normal_gravitation_q0,
    zonal4_gravitation_scalar,
)


#: Limits of the finite-state guard.  Inputs beyond them come from no airborne or marine
#: IMU (accelerometers span +-50 g at most, gyros +-4000 deg/s = 70 rad/s) or altimeter:
#: damaged data that passed the ingestion checks, not a manoeuvre.
MAX_SPECIFIC_FORCE_MPS2 = 2000.0  # ~200 g
MAX_ANGULAR_RATE_RADPS = 100.0
EXT_HEIGHT_RANGE_M = (-1.0e5, 1.0e6)
#: A navigated point outside this band of geocentric radius (100 km below the poles' surface
#: to 1000 km above the equator's) or faster than this in inertial space is no flight; it
#: also keeps the gravity model's radius away from zero (a division by zero in the kernel).
RADIUS_RANGE_M = (WGS84.a * (1.0 - WGS84.f) - 1.0e5, WGS84.a + 1.0e6)
MAX_INERTIAL_SPEED_MPS = 1.2e4


# --------------------------------------------------------------------------
# Finite-state guard
# --------------------------------------------------------------------------


def _first_bad(bad_n) -> int:
    return int(np.flatnonzero(bad_n)[0])


def check_mechanization_inputs(time, f_t, w_t, h_ext, use_ext: bool) -> None:
    """Refuse IMU or altimeter samples the mechanization must not integrate.

    Parameters
    ----------
    time : ndarray, shape (n,)
        IMU times, s.
    f_t, w_t : ndarray, shape (n, 3)
        Specific force (m/s^2) and angular rate (rad/s) on the triad.
    h_ext : ndarray, shape (n,)
        External heights at the IMU times, m (checked only when ``use_ext``).
    use_ext : bool

    Raises
    ------
    DataError
        ``imu specific_force: sample k at t = ... s is [...] m/s^2: expected finite values
        within +-2000 m/s^2 ...``, likewise for ``imu angular_rate`` and ``altimeter height``.
    """
    if time.size and not np.isfinite(time).all():
        k = _first_bad(~np.isfinite(time))
        raise DataError(
            f"imu time: sample {k} is {time[k]!r}: expected finite times "
            "(damaged input that passed the ingestion checks)"
        )
    for name, v_n3, limit, unit in (
        ("imu specific_force", f_t, MAX_SPECIFIC_FORCE_MPS2, "m/s^2"),
        ("imu angular_rate", w_t, MAX_ANGULAR_RATE_RADPS, "rad/s"),
    ):
        # NaN fails the comparison too: one pass finds both
        ok_n = (np.abs(v_n3) <= limit).all(axis=1)
        if not ok_n.all():
            k = _first_bad(~ok_n)
            raise DataError(
                f"{name}: sample {k} at t = {time[k]:.3f} s is "
                f"[{', '.join(f'{x:.6g}' for x in v_n3[k])}] {unit}: expected finite "
                f"values within +-{limit:g} {unit} (damaged input that passed the "
                "ingestion checks); the mechanization stops"
            )
    if use_ext:
        lo, hi = EXT_HEIGHT_RANGE_M
        ok_n = (h_ext >= lo) & (h_ext <= hi)
        if not ok_n.all():
            k = _first_bad(~ok_n)
            raise DataError(
                f"altimeter height: {h_ext[k]:.6g} m at t = {time[k]:.3f} s "
                f"(interpolated to IMU sample {k}): expected finite heights within "
                f"{lo:g}..{hi:g} m (damaged input that passed the ingestion checks); "
                "the mechanization stops"
            )


def check_navigation_state(time, r_i, v_i, mat_it) -> None:
    """Refuse a navigation that became non-finite or left every possible flight.

    Parameters
    ----------
    time : ndarray, shape (n,)
        s.
    r_i, v_i : ndarray, shape (n, 3)
        Inertial position (m) and velocity (m/s).
    mat_it : ndarray, shape (n, 3, 3)
        Triad -> inertial.

    Raises
    ------
    DataError
        Naming the first bad sample, its time and the quantity (position radius, inertial
        speed, attitude), e.g. ``navigation position: geocentric radius 9.1e+06 m at t =
        812.300 s (IMU sample 8123): expected 6.26e+06..7.38e+06 m ...``.
    """
    lo, hi = RADIUS_RANGE_M
    radius_n = np.sqrt(np.einsum("ni,ni->n", r_i, r_i))
    speed_n = np.sqrt(np.einsum("ni,ni->n", v_i, v_i))
    att_ok_n = np.isfinite(mat_it.reshape(len(mat_it), 9)).all(axis=1)
    checks = (
        (
            "navigation position",
            "geocentric radius",
            radius_n,
            "m",
            (radius_n >= lo) & (radius_n <= hi),
            f"{lo:.3g}..{hi:.3g} m",
        ),
        (
            "navigation velocity",
            "inertial speed",
            speed_n,
            "m/s",
            speed_n <= MAX_INERTIAL_SPEED_MPS,
            f"at most {MAX_INERTIAL_SPEED_MPS:g} m/s",
        ),
        ("navigation attitude", "triad->inertial matrix", None, "", att_ok_n, "finite"),
    )
    first = [(_first_bad(~ok_n), c) for c in checks for ok_n in [c[4]] if not ok_n.all()]
    if not first:
        return
    k, (name, what, val_n, unit, _, expected) = min(first, key=lambda x: x[0])
    value = f" {val_n[k]:.6g} {unit}" if val_n is not None else " non-finite"
    raise DataError(
        f"{name}: {what}{value} at t = {time[k]:.3f} s (IMU sample {k}): "
        f"expected {expected}; damaged or inconsistent input (imu, altimeter or "
        "initial state) made the mechanization run away"
    )


# --------------------------------------------------------------------------
# Compiled kernels
# --------------------------------------------------------------------------


@njit(cache=True)
def _rot_into(phi, m):
    """Write ``Exp([phi x])`` into the (3, 3) buffer ``m`` (Rodrigues, no allocation)."""
    x, y, z = phi[0], phi[1], phi[2]
    th2 = x * x + y * y + z * z
    if th2 < 1e-8:
        a = 1.0 - th2 / 6.0 + th2 * th2 / 120.0
        b = 0.5 - th2 / 24.0 + th2 * th2 / 720.0
    else:
        th = math.sqrt(th2)
        a = math.sin(th) / th
        b = (1.0 - math.cos(th)) / th2
    # I + a K + b K^2, K^2 = phi phi^T - th2 I
    m[0, 0] = 1.0 + b * (x * x - th2)
    m[1, 1] = 1.0 + b * (y * y - th2)
    m[2, 2] = 1.0 + b * (z * z - th2)
    m[0, 1] = -a * z + b * x * y
    m[1, 0] = a * z + b * x * y
    m[0, 2] = a * y + b * x * z
    m[2, 0] = -a * y + b * x * z
    m[1, 2] = -a * x + b * y * z
    m[2, 1] = a * x + b * y * z


@njit(cache=True)
def rodrigues(phi):
    """Rotation matrix ``Exp([phi x])`` for a rotation vector ``phi`` (rad), (3, 3).

    The allocating form of :func:`_rot_into`, the kernel the mechanization uses (so a test of
    this function tests that kernel).
    """
    m = np.empty((3, 3))
    _rot_into(phi, m)
    return m


@njit(cache=True)
def _lagrange_mid(t, a, k, tm, out):
    """Interpolate a (n,3) at time tm in [t_k, t_k+1] with up to 4 nodes."""
    n = t.shape[0]
    lo = k - 1
    hi = k + 2
    if lo < 0:
        lo = 0
    if hi > n - 1:
        hi = n - 1
    # prefer 3 nodes at the ends
    out[0] = 0.0
    out[1] = 0.0
    out[2] = 0.0
    for i in range(lo, hi + 1):
        li = 1.0
        for j in range(lo, hi + 1):
            if j != i:
                li *= (tm - t[j]) / (t[i] - t[j])
        out[0] += li * a[i, 0]
        out[1] += li * a[i, 1]
        out[2] += li * a[i, 2]


@njit(cache=True)
def _attitude_kernel(t, w, c0, c_out):
    # element by element: an array assignment `c_out[0] = c0` pulls in numba's broadcast-error
    # formatting (string kernels), ~2 s of compilation on a cold start
    for i in range(3):
        for j in range(3):
            c_out[0, i, j] = c0[i, j]
    phi = np.empty(3)
    wm = np.empty(3)
    rot = np.empty((3, 3))
    for k in range(t.shape[0] - 1):
        h = t[k + 1] - t[k]
        _lagrange_mid(t, w, k, t[k] + 0.5 * h, wm)
        # angle increments of the two half intervals, quadratic rate through (w_k, w_m, w_k+1)
        d1x = h / 24.0 * (5.0 * w[k, 0] + 8.0 * wm[0] - w[k + 1, 0])
        d1y = h / 24.0 * (5.0 * w[k, 1] + 8.0 * wm[1] - w[k + 1, 1])
        d1z = h / 24.0 * (5.0 * w[k, 2] + 8.0 * wm[2] - w[k + 1, 2])
        d2x = h / 24.0 * (-w[k, 0] + 8.0 * wm[0] + 5.0 * w[k + 1, 0])
        d2y = h / 24.0 * (-w[k, 1] + 8.0 * wm[1] + 5.0 * w[k + 1, 1])
        d2z = h / 24.0 * (-w[k, 2] + 8.0 * wm[2] + 5.0 * w[k + 1, 2])
        # two-sample coning correction (2/3) d1 x d2
        phi[0] = d1x + d2x + 2.0 / 3.0 * (d1y * d2z - d1z * d2y)
        phi[1] = d1y + d2y + 2.0 / 3.0 * (d1z * d2x - d1x * d2z)
        phi[2] = d1z + d2z + 2.0 / 3.0 * (d1x * d2y - d1y * d2x)
        _rot_into(phi, rot)
        for i in range(3):
            for j in range(3):
                c_out[k + 1, i, j] = (
                    c_out[k, i, 0] * rot[0, j] + c_out[k, i, 1] * rot[1, j] + c_out[k, i, 2] * rot[2, j]
                )


@njit(cache=True)
def _translation_kernel(t, a_i, h_ext, h_ext_mid, use_ext, r0, v0, a, f, gm, omega, r_out, v_out):
    n = t.shape[0]
    for j in range(3):  # not `r_out[0] = r0`: see _attitude_kernel
        r_out[0, j] = r0[j]
        v_out[0, j] = v0[j]
    q0 = normal_gravitation_q0(a, f)
    j2, j4 = normal_gravitation_j2_j4(a, f, gm, omega)
    dx = 0.0
    dy = 0.0
    dz = 0.0
    am = np.empty(3)
    y = np.empty(6)
    ys = np.empty(6)
    kk = np.empty((4, 6))
    acc = np.empty((3, 3))
    for k in range(n - 1):
        tk = t[k]
        dt = t[k + 1] - tk
        tm = tk + 0.5 * dt
        _lagrange_mid(t, a_i, k, tm, am)
        for j in range(3):
            acc[0, j] = a_i[k, j]
            acc[1, j] = am[j]
            acc[2, j] = a_i[k + 1, j]
            y[j] = r_out[k, j]
            y[3 + j] = v_out[k, j]
        # geometry of the external radius at the step start: ellipsoid normal (inertial axes)
        # and computed height; latitude and height do not depend on the longitude, so the
        # inertial coordinates serve as they are
        nx = 0.0
        ny = 0.0
        nz = 0.0
        hc = 0.0
        cosa = 1.0
        if use_ext:
            nz, cl, hc = geodetic_trig_scalar(y[0], y[1], y[2], a, f, 0)
            p = math.sqrt(y[0] * y[0] + y[1] * y[1])
            if p > 0.0:
                nx = cl * y[0] / p
                ny = cl * y[1] / p
            rn = math.sqrt(p * p + y[2] * y[2])
            cosa = (nx * y[0] + ny * y[1] + nz * y[2]) / rn
        for st in range(4):
            if st == 0:
                hs = 0.0
                ia = 0
                hx = h_ext[k]
            elif st == 3:
                hs = dt
                ia = 2
                hx = h_ext[k + 1]
            else:
                hs = 0.5 * dt
                ia = 1
                hx = h_ext_mid[k]
            for j in range(6):
                ys[j] = y[j] + (hs * kk[st - 1, j] if st > 0 else 0.0)
            # the gravity model's point: the computed direction at the external radius
            scale = 1.0
            if use_ext:
                rs = math.sqrt(ys[0] * ys[0] + ys[1] * ys[1] + ys[2] * ys[2])
                dh = nx * (ys[0] - y[0]) + ny * (ys[1] - y[1]) + nz * (ys[2] - y[2])
                scale = (rs + cosa * (hx - hc - dh)) / rs
            px = ys[0] * scale
            py = ys[1] * scale
            pz = ys[2] * scale
            zx, zy, zz = zonal4_gravitation_scalar(px, py, pz, a, gm, j2, j4)
            if st == 0:
                # one full evaluation per step: the stages carry its J6+ remainder unchanged
                # (it changes by <= 7.2e-13 m/s^2 per metre: module docstring, item 3)
                gx, gy, gz = normal_gravitation_inertial_scalar(px, py, pz, a, f, gm, omega, q0)
                dx = gx - zx
                dy = gy - zy
                dz = gz - zz
            else:
                gx = zx + dx
                gy = zy + dy
                gz = zz + dz
            # G_model(r) = (|r| / R) G_normal(r R / |r|)
            back = 1.0 / scale
            gx *= back
            gy *= back
            gz *= back
            kk[st, 0] = ys[3]
            kk[st, 1] = ys[4]
            kk[st, 2] = ys[5]
            kk[st, 3] = gx + acc[ia, 0]
            kk[st, 4] = gy + acc[ia, 1]
            kk[st, 5] = gz + acc[ia, 2]
        for j in range(6):
            y[j] += dt / 6.0 * (kk[0, j] + 2.0 * kk[1, j] + 2.0 * kk[2, j] + kk[3, j])
        for j in range(3):
            r_out[k + 1, j] = y[j]
            v_out[k + 1, j] = y[3 + j]


@njit(cache=True)
def mechanize_kernel(t, f_t, w_t, h_ext, h_ext_mid, use_ext, r0, v0, c0, a, f, gm, omega):
    """Compiled mechanization (see module docstring).

    Parameters
    ----------
    t : ndarray (n,)
        IMU times, s (inertial frame = ECEF at t = 0).
    f_t, w_t : ndarray (n, 3)
        Specific force (m/s^2) and absolute angular rate (rad/s) on the triad.
    h_ext : ndarray (n,)
        External ellipsoidal height at the IMU times, m (ignored unless ``use_ext``).
    h_ext_mid : ndarray (n-1,)
        External height at the interval midpoints, m.
    use_ext : bool
    r0, v0 : ndarray (3,)
        Inertial position (m) and inertial velocity (m/s) at ``t[0]``.
    c0 : ndarray (3, 3)
        Triad -> inertial at ``t[0]``.
    a, f, gm, omega : float
        Ellipsoid parameters.

    Returns
    -------
    r_i, v_i : ndarray (n, 3)
    mat_it : ndarray (n, 3, 3)
    """
    c_out = np.empty((t.shape[0], 3, 3))
    _attitude_kernel(t, w_t, c0, c_out)
    return _translate(t, f_t, c_out, h_ext, h_ext_mid, use_ext, r0, v0, a, f, gm, omega)


@njit(cache=True)
def _translate(t, f_t, c, h_ext, h_ext_mid, use_ext, r0, v0, a, f, gm, omega):
    """The specific force rotated by the attitude ``c`` (n, 3, 3) and integrated: ``(r_i, v_i, c)``."""
    n = t.shape[0]
    a_i = np.empty((n, 3))
    for k in range(n):
        for i in range(3):
            a_i[k, i] = c[k, i, 0] * f_t[k, 0] + c[k, i, 1] * f_t[k, 1] + c[k, i, 2] * f_t[k, 2]
    r_out = np.empty((n, 3))
    v_out = np.empty((n, 3))
    _translation_kernel(t, a_i, h_ext, h_ext_mid, use_ext, r0, v0, a, f, gm, omega, r_out, v_out)
    return r_out, v_out, c


@njit(cache=True)
def _follow_attitude(t, c, t_ep, th_ep):
    """``C_i <- C_i Exp([theta(t_i) x])`` in place: ``theta`` (triad axes, rad) linear in time
    between the epochs ``t_ep`` (ascending) and held beyond them."""
    m = t_ep.shape[0]
    phi = np.empty(3)
    rot = np.empty((3, 3))
    row = np.empty(3)
    j = 0
    for k in range(t.shape[0]):
        tk = t[k]
        while j < m - 2 and t_ep[j + 1] <= tk:
            j += 1
        if m == 1 or tk <= t_ep[0]:
            w, j0, j1 = 0.0, 0, 0
        elif tk >= t_ep[m - 1]:
            w, j0, j1 = 0.0, m - 1, m - 1
        else:
            w, j0, j1 = (tk - t_ep[j]) / (t_ep[j + 1] - t_ep[j]), j, j + 1
        for i in range(3):
            phi[i] = (1.0 - w) * th_ep[j0, i] + w * th_ep[j1, i]
        _rot_into(phi, rot)
        for i in range(3):
            for jj in range(3):
                row[jj] = c[k, i, 0] * rot[0, jj] + c[k, i, 1] * rot[1, jj] + c[k, i, 2] * rot[2, jj]
            for jj in range(3):
                c[k, i, jj] = row[jj]


@njit(cache=True)
def mechanize_following_kernel(t, f_t, w_t, h_ext, h_ext_mid, use_ext, r0, v0, c0, t_ep, th_ep, a, f, gm, omega):
    """:func:`mechanize_kernel` with the attitude turned by ``Exp([theta x])`` at every sample
    before the translation: a navigation that follows an estimated attitude (``theta`` at the
    epochs ``t_ep``, (m, 3) rad on the triad axes, linear between them; :func:`mechanize`'s
    ``follow``)."""
    c_out = np.empty((t.shape[0], 3, 3))
    _attitude_kernel(t, w_t, c0, c_out)
    _follow_attitude(t, c_out, t_ep, th_ep)
    return _translate(t, f_t, c_out, h_ext, h_ext_mid, use_ext, r0, v0, a, f, gm, omega)


# --------------------------------------------------------------------------
# Pure-numpy reference path (slow; for tests)
# --------------------------------------------------------------------------


def _rotvec_to_mat_ref(phi):
    from scipy.spatial.transform import Rotation

    return Rotation.from_rotvec(phi).as_matrix()


def _lagrange_ref(t, a, k, tm):
    nodes = np.arange(max(k - 1, 0), min(k + 2, t.size - 1) + 1)
    w = np.array([np.prod([(tm - t[j]) / (t[i] - t[j]) for j in nodes if j != i]) for i in nodes])
    return w @ a[nodes]


def mechanize_reference(
    t, f_t, w_t, h_ext, h_ext_mid, use_ext, r0, v0, c0, ellipsoid=WGS84, exact_stages=False, follow=None
):
    """Pure-numpy/scipy implementation of :func:`mechanize_kernel` (same algorithm); with
    ``follow`` (``(t_ep, theta_ep)``) of :func:`mechanize_following_kernel`.

    With ``exact_stages`` every RK4 stage evaluates the full normal gravitation instead of
    carrying the step start's J6+ remainder (the scheme up to commit 9111ed4): the tests'
    exact integration, against which the carried remainder's effect is bounded.
    """
    t = np.asarray(t, float)
    n = t.size
    c = np.empty((n, 3, 3))
    c[0] = c0
    for k in range(n - 1):
        dt = t[k + 1] - t[k]
        wm = _lagrange_ref(t, w_t, k, t[k] + 0.5 * dt)
        d1 = dt / 24.0 * (5.0 * w_t[k] + 8.0 * wm - w_t[k + 1])
        d2 = dt / 24.0 * (-w_t[k] + 8.0 * wm + 5.0 * w_t[k + 1])
        c[k + 1] = c[k] @ _rotvec_to_mat_ref(d1 + d2 + 2.0 / 3.0 * np.cross(d1, d2))
    if follow is not None:
        t_ep, th_ep = (np.asarray(a, float) for a in follow)
        th = np.stack([np.interp(t, t_ep, th_ep[:, i]) for i in range(3)], axis=1)
        c = np.einsum("nij,njk->nik", c, _rotvec_to_mat_ref(th))
    a_i = np.einsum("nij,nj->ni", c, f_t)

    j2, j4 = normal_gravitation_j2_j4(*ellipsoid.params())

    def zonal4(p):
        # written out in numpy, not geodesy.zonal4_gravitation_scalar: the test compares two codings
        r2 = p @ p
        s2 = p[2] ** 2 / r2
        a2r2 = ellipsoid.a**2 / r2
        k2 = 1.5 * j2 * a2r2
        k4 = j4 / 8.0 * a2r2**2
        hor = 1.0 + k2 * (1.0 - 5.0 * s2) - 15.0 * k4 * (1.0 - 14.0 * s2 + 21.0 * s2**2)
        ver = 1.0 + k2 * (3.0 - 5.0 * s2) - 5.0 * k4 * (15.0 - 70.0 * s2 + 63.0 * s2**2)
        return -ellipsoid.gm / r2**1.5 * p * np.array([hor, hor, ver])

    r = np.empty((n, 3))
    v = np.empty((n, 3))
    r[0], v[0] = r0, v0
    for k in range(n - 1):
        dt = t[k + 1] - t[k]
        tm = t[k] + 0.5 * dt
        amid = _lagrange_ref(t, a_i, k, tm)
        if use_ext:
            # Bowring's closed form, as the kernel; on inertial axes the longitude is the
            # inertial one, so the normal comes out inertial
            x, yy, z = r[k]
            p = np.hypot(x, yy)
            theta = np.arctan2(z * ellipsoid.a, p * ellipsoid.b)
            ep2 = ellipsoid.e2 / (1.0 - ellipsoid.e2)
            lat = np.arctan2(
                z + ep2 * ellipsoid.b * np.sin(theta) ** 3, p - ellipsoid.e2 * ellipsoid.a * np.cos(theta) ** 3
            )
            big_n = ellipsoid.a / np.sqrt(1.0 - ellipsoid.e2 * np.sin(lat) ** 2)
            hc = p * np.cos(lat) + z * np.sin(lat) - ellipsoid.a**2 / big_n
            n_i = mat_en(lat, np.arctan2(yy, x))[:, 2]
            cosa = n_i @ r[k] / np.linalg.norm(r[k])
        y = np.concatenate([r[k], v[k]])
        stages = [
            (0.0, a_i[k], h_ext[k]),
            (0.5 * dt, amid, h_ext_mid[k]),
            (0.5 * dt, amid, h_ext_mid[k]),
            (dt, a_i[k + 1], h_ext[k + 1]),
        ]
        kprev = np.zeros(6)
        ks = []
        for st, (hs, acc, hx) in enumerate(stages):
            ys = y + hs * kprev
            scale = 1.0
            if use_ext:
                rs = np.linalg.norm(ys[:3])
                scale = (rs + cosa * (hx - hc - n_i @ (ys[:3] - y[:3]))) / rs
            # the normal field is symmetric about the Earth's axis: inertial axes serve as ECEF ones
            p = ys[:3] * scale
            if st == 0 or exact_stages:
                g = normal_gravitation_ecef(p, ellipsoid)
                rest = g - zonal4(p)
            else:
                g = zonal4(p) + rest
            kprev = np.concatenate([ys[3:], g / scale + acc])
            ks.append(kprev)
        y = y + dt / 6.0 * (ks[0] + 2 * ks[1] + 2 * ks[2] + ks[3])
        r[k + 1], v[k + 1] = y[:3], y[3:]
    return r, v, c


# --------------------------------------------------------------------------
# User-facing wrapper
# --------------------------------------------------------------------------


@dataclass
class Navigation:
    """Mechanized (uncorrected) navigation solution at the IMU times.

    Attributes
    ----------
    time : ndarray (n,)
        s, record time base.
    r_i, v_i : ndarray (n, 3)
        Inertial position (m) and velocity (m/s).
    mat_it : ndarray (n, 3, 3)
        Triad -> inertial.
    h_ext : ndarray (n,)
        External (altimeter) ellipsoidal height interpolated to ``time``, m.
    """

    time: np.ndarray
    r_i: np.ndarray
    v_i: np.ndarray
    mat_it: np.ndarray
    h_ext: np.ndarray

    @property
    def q_t(self):
        """Position on the triad, ``C^T r_i``, (n, 3) m."""
        return np.einsum("nji,nj->ni", self.mat_it, self.r_i)

    @property
    def p_t(self):
        """Inertial velocity on the triad, ``C^T v_i``, (n, 3) m/s."""
        return np.einsum("nji,nj->ni", self.mat_it, self.v_i)


def initial_inertial_state(time0, lat, lon, height, vel_n, mat_nt, ellipsoid: Ellipsoid = WGS84):
    """Inertial position, velocity and triad->inertial matrix at record time ``time0``.

    Returns
    -------
    r_i (3,), v_i (3,), mat_it (3, 3)
    """
    r_e = geodetic_to_ecef(lat, lon, height, ellipsoid)
    m_en = mat_en(lat, lon)
    m_ie = mat_ie(time0, ellipsoid.omega)
    v_e = m_en @ np.asarray(vel_n, float) + np.cross([0.0, 0.0, ellipsoid.omega], r_e)
    return m_ie @ r_e, m_ie @ v_e, m_ie @ m_en @ np.asarray(mat_nt, float)


def propagate_attitude(time, w_t, mat_0) -> np.ndarray:
    """Triad attitude from integrated gyro rates (the mechanization's attitude step).

    Parameters
    ----------
    time : ndarray (n,)
        IMU times, s.
    w_t : ndarray (n, 3)
        Absolute angular rate on the triad, rad/s.
    mat_0 : ndarray (3, 3)
        Attitude at ``time[0]`` (any frame ``a`` fixed in inertial space -> triad).

    Returns
    -------
    ndarray (n, 3, 3)
        ``mat_0 @ C_t0_t(t)``: ``C_t0_t`` rotates the triad at ``t`` onto the triad at
        ``time[0]``; with ``mat_0 = I`` the triad's rotation since the first sample.
    """
    t = np.ascontiguousarray(time, dtype=float)
    w = np.ascontiguousarray(w_t, dtype=float)
    out = np.empty((t.size, 3, 3))
    _attitude_kernel(t, w, np.ascontiguousarray(mat_0, dtype=float), out)
    return out


def mechanize(
    time,
    f_t,
    w_t,
    initial,
    alt_time=None,
    alt_height=None,
    use_ext=True,
    ellipsoid: Ellipsoid = WGS84,
    reference=False,
    follow=None,
) -> Navigation:
    """Mechanize a flight from its initial state.

    Parameters
    ----------
    time : ndarray (n,)
        IMU times, s (record base; inertial frame = ECEF at time 0).
    f_t, w_t : ndarray (n, 3)
        Specific force (m/s^2), angular rate (rad/s) on the triad.
    initial : InitialState
        State at ``time[0]``.
    alt_time, alt_height : ndarray (m,)
        Altimeter ellipsoidal heights (m); linearly interpolated (held at the ends).
    use_ext : bool
        Gravity model with the altimeter radius (default) or with the computed one.
    reference : bool
        Use the pure-numpy reference path.
    follow : tuple of ndarray, optional
        ``(t_ep, theta_ep)``: epochs (m,) s, ascending, and attitude corrections (m, 3) rad on
        the triad axes.  The attitude integrated from the rates is turned by
        ``Exp([theta x])`` (``theta`` linear between the epochs) before the specific force is
        rotated and integrated: a navigation about an estimated attitude
        (:func:`gravsurvey.inm.solve.estimate_anomaly`, "following passes").

    Raises
    ------
    DataError
        Inputs or a navigation state beyond the guard's limits (module docstring), naming the
        channel, the IMU sample and its time.
    """
    t = np.ascontiguousarray(time, dtype=float)
    f_t = np.ascontiguousarray(f_t, dtype=float)
    w_t = np.ascontiguousarray(w_t, dtype=float)
    if alt_time is not None and len(alt_time) > 0:
        h_ext = np.interp(t, alt_time, alt_height)
        h_mid = np.interp(0.5 * (t[1:] + t[:-1]), alt_time, alt_height)
    else:
        if use_ext:
            raise ValueError("use_ext needs altimeter data")
        h_ext = np.zeros_like(t)
        h_mid = np.zeros(max(t.size - 1, 0))
    check_mechanization_inputs(t, f_t, w_t, h_ext, bool(use_ext))
    r0, v0, c0 = initial_inertial_state(
        t[0], initial.lat, initial.lon, initial.height, initial.vel_n, initial.mat_nt, ellipsoid
    )
    check_navigation_state(t[:1], r0[None], v0[None], c0[None])
    try:
        if reference:
            r, v, c = mechanize_reference(t, f_t, w_t, h_ext, h_mid, use_ext, r0, v0, c0, ellipsoid, follow=follow)
        elif follow is not None:
            t_ep, th_ep = (np.ascontiguousarray(a, dtype=float) for a in follow)
            r, v, c = mechanize_following_kernel(
                t, f_t, w_t, h_ext, h_mid, bool(use_ext), r0, v0, c0, t_ep, th_ep, *ellipsoid.params()
            )
        else:
            r, v, c = mechanize_kernel(t, f_t, w_t, h_ext, h_mid, bool(use_ext), r0, v0, c0, *ellipsoid.params())
    except ZeroDivisionError:
        # only a state far outside any flight divides by zero (the guard's limits keep the
        # inputs in range, but a long run-away can still get there): say so, as for the rest
        raise DataError(
            "navigation state: the mechanization divided by zero (a run-away "
            "state from damaged or inconsistent input: imu, altimeter or initial "
            "state)"
        ) from None
    check_navigation_state(t, r, v, c)
    return Navigation(t, r, v, c, h_ext)


def navigation_to_geodetic(time, r_i, v_i, ellipsoid: Ellipsoid = WGS84):
    """Inertial position/velocity -> (lat rad, lon rad, h m, vel_n (n,3) ENU m/s relative to the Earth)."""
    m_ie = mat_ie(np.asarray(time, float), ellipsoid.omega)
    r_e = np.einsum("nji,nj->ni", m_ie, r_i)
    v_e = np.einsum("nji,nj->ni", m_ie, v_i) - np.cross([0.0, 0.0, ellipsoid.omega], r_e)
    lat, lon, h = ecef_to_geodetic(r_e, ellipsoid)
    vel_n = np.einsum("nji,nj->ni", mat_en(lat, lon), v_e)
    return lat, lon, h, vel_n
