"""Coarse alignment of a strapdown triad from the data (docs/method.md, "Alignment").

Three free-standing methods, all giving the triad -> ENU matrix ``mat_nt`` at the first IMU
sample and a covariance of its error:

* **static levelling** (:func:`level`): at rest the accelerometers read ``-gravity``: the
  mean specific force is the Up axis on the triad, so roll and pitch follow; the error is
  the horizontal accelerometer error over ``g`` (``1e-3 m/s^2`` -> 0.006 deg).
* **gyrocompassing** (:func:`gyrocompass`): at rest the gyros read the Earth rate, whose
  horizontal part ``W cos(lat)`` (15.04 deg/h at the equator) points north.  A horizontal
  gyro error ``e`` turns the found north by ``e / (W cos lat)`` rad: heading sigma
  ``sqrt(b^2 + s^2 / T) / (W cos lat)`` for a bias sigma ``b`` and one-second noise ``s``
  averaged over ``T`` seconds.  Heading to 1 deg at 45 deg latitude needs a gyro good to
  ``0.0175 * 15.04 * 0.707 = 0.19 deg/h``: navigation grade (0.01 deg/h: 0.05 deg) works,
  tactical (1 deg/h: 5 deg) and MEMS (>= 10 deg/h) cannot and are refused
  (:data:`GYROCOMPASS_MAX_SIGMA_DEG`).
* **velocity matching in motion** (:func:`velocity_matching`): in inertial axes
  ``v_i(t) - v_i(t_r) - int G_i dt = C_it(t0) int C_t0_t(tau) f_t(tau) dtau``, where the
  left side comes from GNSS positions (differentiated locally, normal gravitation at the
  GNSS positions) and ``C_t0_t`` from the gyros alone; the unknown ``v_i(t_r)`` drops out
  by centring both sides over the window.  The unknown rotation ``C_it(t0)``
  maps the integrated triad specific force onto the GNSS velocity increments minus gravity:
  Wahba's problem, solved exactly by an SVD at any initial attitude.  Gravity makes the
  vertical observable at once; heading needs horizontal accelerations (speed changes,
  turns; the Earth's rotation gives a weak signal on long straight legs).

:func:`align` picks the best of them for one flight record and reports the method, the
residual level and heading sigma, the time span of data it needed and warnings.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import DataError
from ..geodesy import (
    WGS84,
    Ellipsoid,
    geodetic_to_ecef,
    mat_en,
    mat_ie,
    normal_gravitation_ecef,
)
from .mechanization import propagate_attitude

#: How a coordinate's sign slips, by (coordinate, written negative).
SIGN_SLIPS = {
    "lat": ("a survey south of the equator written without its sign", "a survey north of the equator written negative"),
    "lon": ("a survey west of Greenwich written without its sign", "a survey east of Greenwich written negative"),
}
#: Half width of the GNSS (and IMU) fits of :func:`match_residual_rms`, s: 0.5-m GNSS noise at
#: 5 Hz leaves 0.05 m/s per axis (0.3 m/s with the alignment's 1-s fits).
MATCH_CHECK_HALF_WINDOW_S = 3.0
#: Heading sigma above which gyrocompassing is refused (the GNSS/motion method is used).
GYROCOMPASS_MAX_SIGMA_DEG = 2.0
#: Prior sigma of a horizontal accelerometer bias used for the levelling sigma, m/s^2
#: (navigation grade, ~50 micro-g); a static levelling cannot separate bias from tilt.
ACCEL_BIAS_SIGMA_MPS2 = 5.0e-4
#: Shortest static period used for levelling / gyrocompassing, s.
MIN_STATIC_S = 5.0
#: Block length of the static-period detector, s.
STATIC_BLOCK_S = 1.0
#: A block is still static while its mean specific force stays within this of the first
#: block's (m/s^2; 0.02 m/s^2 ~ 0.1 deg of tilt) and its mean rate within STATIC_RATE_TOL
#: (rad/s; 0.1 deg/s).  The IMU cannot tell rest from steady straight flight: with GNSS the
#: span also ends where the GNSS positions start to move (:func:`align`).
STATIC_FORCE_TOL = 0.02
STATIC_RATE_TOL = math.radians(0.1)
#: Blocks left out before the first moving one (a smooth start of motion stays below the
#: tolerance for a few seconds and would tilt the levelling).
STATIC_MARGIN_BLOCKS = 5
#: Velocity matching: spacing of the matched epochs (s) and window lengths tried (s).
MATCH_SPACING_S = 2.0
MATCH_WINDOWS_S = (60.0, 120.0, 240.0, 480.0, 900.0, 1800.0)
#: Stop growing the window once the heading sigma is below this, deg.
MATCH_TARGET_HEADING_DEG = 0.05
#: Safety factor on the velocity-matching sigma after the residual-correlation scaling
#: (docs/method.md: the residuals do not show every error, e.g. the gyro-propagated attitude's).
MATCH_SIGMA_INFLATION = 2.0
#: Heading sigma above which the alignment is reported as poor, deg.
POOR_HEADING_DEG = 1.0


@dataclass
class Alignment:
    """Result of a coarse alignment.

    Attributes
    ----------
    mat_nt : ndarray (3, 3)
        Triad -> ENU at the first IMU sample.
    cov_n : ndarray (3, 3)
        Covariance of the attitude error ``theta_n`` on ENU axes, rad^2, with
        ``mat_nt_true = (I + [theta_n x]) mat_nt``; ``theta_n[2]`` is the heading error.
    method : str
        ``static-gyrocompass``, ``velocity-matching`` (in motion, GNSS), or
        ``static-levelling+velocity-matching`` (the static vertical, the motion's north).
    converge_s : float
        Time span of data after the first sample the alignment used, s.
    static_s : float
        Length of the static period found at the start, s (0: none).
    warnings : list of str
    """

    mat_nt: np.ndarray
    cov_n: np.ndarray
    method: str
    converge_s: float
    static_s: float = 0.0
    warnings: list = field(default_factory=list)

    @property
    def sigma_level_rad(self) -> float:
        """Larger 1-sigma of the two level (tilt) errors, rad."""
        return float(math.sqrt(max(self.cov_n[0, 0], self.cov_n[1, 1])))

    @property
    def sigma_heading_rad(self) -> float:
        """1-sigma of the heading error, rad."""
        return float(math.sqrt(self.cov_n[2, 2]))

    @property
    def cov_t(self) -> np.ndarray:
        """Covariance of the attitude error on the triad axes (the filter's ``theta``), rad^2."""
        return self.mat_nt.T @ self.cov_n @ self.mat_nt

    def attitude_deg(self):
        """(roll, pitch, heading) of a forward-left-up body triad, deg."""
        return tuple(math.degrees(a) for a in attitude_from_mat_nb(self.mat_nt))

    def to_dict(self) -> dict:
        """Summary for reports (degrees)."""
        r, p, h = self.attitude_deg()
        return {
            "alignment_method": self.method,
            "alignment_attitude_deg": [r, p, h % 360.0],
            "alignment_sigma_level_deg": math.degrees(self.sigma_level_rad),
            "alignment_sigma_heading_deg": math.degrees(self.sigma_heading_rad),
            "alignment_converge_s": float(self.converge_s),
            "alignment_static_s": float(self.static_s),
        }


def attitude_from_mat_nb(mat_nb):
    """Roll, pitch, heading (rad) of a forward-left-up body from ``mat_nb`` (docs/conventions.md).

    Parameters
    ----------
    mat_nb : ndarray (3, 3)
        Body -> ENU.

    Returns
    -------
    roll, pitch, heading : float
        rad; heading clockwise from north in [0, 2 pi).
    """
    m = np.asarray(mat_nb, float)
    nose, left, roof = m[:, 0], m[:, 1], m[:, 2]
    heading = math.atan2(nose[0], nose[1]) % (2.0 * math.pi)
    pitch = math.asin(max(-1.0, min(1.0, nose[2])))
    roll = math.atan2(left[2], roof[2])
    return roll, pitch, heading


def skew(v):
    """Cross-product matrices ``[v x]``, shape ``(..., 3, 3)`` for ``v`` of shape ``(..., 3)``."""
    v = np.asarray(v, float)
    m = np.zeros(v.shape[:-1] + (3, 3))
    m[..., 0, 1], m[..., 0, 2], m[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    m[..., 1, 0], m[..., 2, 0], m[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    return m


# --------------------------------------------------------------------------
# static
# --------------------------------------------------------------------------


def static_span(time, f_t, w_t) -> float:
    """Length of the static period at the start of an IMU record, s (0: none).

    The record is cut into blocks of :data:`STATIC_BLOCK_S`; the period lasts while each
    block's mean specific force stays within :data:`STATIC_FORCE_TOL` and its mean rate
    within :data:`STATIC_RATE_TOL` of the first block's (vibration averages out in a block;
    a speed change, a turn or a tilt does not).

    Parameters
    ----------
    time : ndarray (n,)
        s.
    f_t, w_t : ndarray (n, 3)
        Specific force (m/s^2) and angular rate (rad/s) on the triad.
    """
    t = np.asarray(time, float)
    f = np.asarray(f_t, float)
    w = np.asarray(w_t, float)
    blk = np.floor((t - t[0]) / STATIC_BLOCK_S).astype(np.int64)
    nb = int(blk[-1]) + 1
    cnt = np.bincount(blk, minlength=nb).astype(float)
    if nb < 2 or cnt[0] == 0:
        return 0.0
    fm = np.stack([np.bincount(blk, f[:, i], nb) for i in range(3)], axis=1)
    wm = np.stack([np.bincount(blk, w[:, i], nb) for i in range(3)], axis=1)
    have = cnt > 0
    fm[have] /= cnt[have, None]
    wm[have] /= cnt[have, None]
    moving = have & (
        (np.linalg.norm(fm - fm[0], axis=1) > STATIC_FORCE_TOL) | (np.linalg.norm(wm - wm[0], axis=1) > STATIC_RATE_TOL)
    )
    first = int(np.argmax(moving)) if moving.any() else nb
    # the blocks just before motion may hold its smooth start: leave them out
    span = max(0.0, (first - STATIC_MARGIN_BLOCKS) * STATIC_BLOCK_S) if moving.any() else float(t[-1] - t[0])
    return float(span)


#: The first GNSS fix may come this long after the first IMU sample and still place it, s:
#: beyond, the IMU record before the fix is placed only when it is at rest until the fix
#: (:func:`rest_through_gnss_lead`).
MAX_GNSS_LEAD_S = 2.0
#: GNSS fixes at rest needed after a late first fix to take it as the position at the IMU's
#: start (the IMU at rest from its start through them), s.
GNSS_LEAD_REST_S = 5.0


def gnss_lead_s(record) -> float:
    """First finite GNSS fix minus the first IMU sample, s (0 without GNSS; < 0: the GNSS first)."""
    gn = record.gnss
    if gn is None or len(gn.time) == 0:
        return 0.0
    ok = np.isfinite(np.asarray(gn.lat, float)) & np.isfinite(np.asarray(gn.lon, float))
    if not ok.any():
        return 0.0
    return float(np.asarray(gn.time, float)[ok][0] - float(record.imu.time[0]))


def rest_through_gnss_lead(record) -> bool:
    """Whether the IMU rests from its first sample until :data:`GNSS_LEAD_REST_S` past the first
    GNSS fix (a receiver that got its fix after power-on, the aircraft parked): the first
    fixes are then the position at the IMU's start.  Measured on the IMU alone
    (:func:`static_span`), on the record up to a little past that point."""
    lead = gnss_lead_s(record)
    t = np.asarray(record.imu.time, float)
    m = t <= t[0] + max(lead, 0.0) + 2.0 * GNSS_LEAD_REST_S
    if m.sum() < 4:
        return False
    rest = static_span(t[m], np.asarray(record.imu.specific_force_t)[m], np.asarray(record.imu.angular_rate_t)[m])
    return rest >= max(lead, 0.0) + GNSS_LEAD_REST_S


def gnss_static_span(gnss, t0, sigma_m, ellipsoid: Ellipsoid = WGS84) -> float:
    """Time from ``t0`` until the GNSS positions move from the first one by more than
    ``5 sigma_m + 0.5 m`` horizontally, s.

    A first fix after ``t0 +`` :data:`MAX_GNSS_LEAD_S` confirms a rest from ``t0`` only when the
    fixes then stay put for :data:`GNSS_LEAD_REST_S` (the caller takes the lesser of this and
    the IMU's own static span, which must cover the time before the fix); else 0."""
    tg = np.asarray(gnss.time, float)
    lat = np.asarray(gnss.lat, float)
    lon = np.asarray(gnss.lon, float)
    ok = np.isfinite(lat) & np.isfinite(lon)
    tg, lat, lon = tg[ok], lat[ok], lon[ok]
    if tg.size < 2:
        return 0.0
    r = geodetic_to_ecef(lat, lon, np.zeros_like(lat), ellipsoid)
    up = r[0] / np.linalg.norm(r[0])
    d = r - r[0]
    horiz = np.linalg.norm(d - np.outer(d @ up, up), axis=1)
    moved = np.flatnonzero(horiz > 5.0 * sigma_m + 0.5)
    end = tg[moved[0]] if moved.size else tg[-1]
    if tg[0] > t0 + MAX_GNSS_LEAD_S and end - tg[0] < GNSS_LEAD_REST_S:
        return 0.0
    return float(max(0.0, end - t0 - STATIC_MARGIN_BLOCKS * STATIC_BLOCK_S))


def level(f_mean_t):
    """Up axis on the triad, roll and pitch from the mean specific force at rest.

    Parameters
    ----------
    f_mean_t : ndarray (3,)
        Mean specific force on the triad, m/s^2 (at rest: ``-gravity``, pointing up).

    Returns
    -------
    up_t : ndarray (3,)
        Unit Up vector on the triad.
    roll, pitch : float
        rad, for a forward-left-up body triad: ``f = g (sin pitch, cos pitch sin roll,
        cos pitch cos roll)`` (docs/conventions.md).
    """
    f = np.asarray(f_mean_t, float)
    n = float(np.linalg.norm(f))
    if not n > 0:
        raise DataError("alignment: zero mean specific force; cannot find the vertical")
    up = f / n
    pitch = math.atan2(f[0], math.hypot(f[1], f[2]))
    roll = math.atan2(f[1], f[2])
    return up, roll, pitch


def gyrocompass(
    f_mean_t,
    w_mean_t,
    lat,
    duration_s,
    gyro_bias_sigma_radps,
    gyro_noise_radps,
    accel_bias_sigma_mps2=ACCEL_BIAS_SIGMA_MPS2,
    accel_noise_mps2=0.0,
    omega=WGS84.omega,
) -> tuple:
    """Static alignment: levelling from the accelerometers and north from the Earth rate.

    Parameters
    ----------
    f_mean_t, w_mean_t : ndarray (3,)
        Mean specific force (m/s^2) and angular rate (rad/s) on the triad over the static span.
    lat : float
        Latitude, rad.
    duration_s : float
        Length of the static span, s.
    gyro_bias_sigma_radps, gyro_noise_radps : float
        Gyro bias sigma and one-second white-noise sigma, rad/s.
    accel_bias_sigma_mps2, accel_noise_mps2 : float
        Accelerometer bias sigma and one-second noise, m/s^2.

    Returns
    -------
    mat_nt : ndarray (3, 3)
        Triad -> ENU (rows: East, North, Up on the triad).
    cov_n : ndarray (3, 3)
        Diagonal error covariance on ENU axes, rad^2.
    warnings : list of str
        Non-empty when the heading is not usable (gyro too noisy, rate inconsistent with
        the Earth rate); ``mat_nt`` then still carries the levelling.
    """
    up, _, _ = level(f_mean_t)
    g = float(np.linalg.norm(f_mean_t))
    w = np.asarray(w_mean_t, float)
    w_h = w - (w @ up) * up
    earth_h = omega * math.cos(lat)
    gyro_err = math.sqrt(gyro_bias_sigma_radps**2 + gyro_noise_radps**2 / max(duration_s, 1e-9))
    s_head = gyro_err / earth_h if earth_h > 0 else math.inf
    s_level = math.sqrt(accel_bias_sigma_mps2**2 + accel_noise_mps2**2 / max(duration_s, 1e-9)) / g
    warn = []
    degph = math.radians(1.0) / 3600.0
    if math.degrees(s_head) > GYROCOMPASS_MAX_SIGMA_DEG:
        warn.append(
            f"gyro too noisy for gyrocompassing: gyro error {gyro_err / degph:.3g} deg/h against the Earth rate's "
            f"horizontal {earth_h / degph:.3g} deg/h gives a heading sigma of {math.degrees(s_head):.3g} deg "
            f"(> {GYROCOMPASS_MAX_SIGMA_DEG} deg)"
        )
    elif abs(np.linalg.norm(w_h) - earth_h) > 4.0 * gyro_err + 0.2 * earth_h:
        warn.append(
            f"gyrocompassing refused: horizontal rate {np.linalg.norm(w_h) / degph:.3g} deg/h at rest, expected the "
            f"Earth rate's {earth_h / degph:.3g} deg/h (gyro bias beyond its sigma {gyro_bias_sigma_radps / degph:.3g} "
            "deg/h, or the platform was moving)"
        )
    north = w_h / np.linalg.norm(w_h) if np.linalg.norm(w_h) > 0 else _any_perpendicular(up)
    east = np.cross(north, up)
    mat_nt = np.stack([east, north, up])
    mat_nt = _orthonormal(mat_nt)
    cov = np.diag([s_level**2, s_level**2, (s_head if not warn else math.pi) ** 2])
    return mat_nt, cov, warn


def hemisphere_check(
    up_t, w_mean_t, lat, duration_s, gyro_bias_sigma_radps, gyro_noise_radps, source, omega=WGS84.omega
):
    """Refuse a GNSS latitude whose sign the gyros contradict at rest.

    At rest the gyros read the Earth's rate, whose vertical part ``Omega sin(lat)`` changes
    sign at the equator. A survey south of it written without the sign (or with the hemisphere
    column left out) has the vertical rate of the other hemisphere: the navigation then turns
    at ``2 Omega sin(lat)`` (22 deg/h at 47 deg) and failed as "did not settle" with advice
    about the gyro bias (fuzzing, 2026-12-04). Judged only when the rate matches the other
    hemisphere within ``4 sigma + 20 %`` and misses this one by three times that.

    Parameters
    ----------
    up_t : ndarray, shape (3,)
        The vertical on the triad (from levelling).
    w_mean_t : ndarray, shape (3,)
        Mean angular rate over the static span, rad/s.
    lat : float
        The GNSS latitude, rad.
    duration_s, gyro_bias_sigma_radps, gyro_noise_radps : float
        As :func:`gyrocompass`.
    source : str
        The GNSS file, for the message.

    Raises
    ------
    DataError
    """
    degph = math.radians(1.0) / 3600.0
    gyro_err = math.sqrt(gyro_bias_sigma_radps**2 + gyro_noise_radps**2 / max(duration_s, 1e-9))
    up_rate = float(np.dot(w_mean_t, up_t))
    expected = omega * math.sin(lat)
    tol = 4.0 * gyro_err + 0.2 * abs(expected)
    if abs(up_rate + expected) <= tol and abs(up_rate - expected) > 3.0 * tol:
        hemi = "N" if lat >= 0 else "S"
        raise DataError(
            f"{source}: at rest the gyros read a vertical Earth rate of {up_rate / degph:+.2f} deg/h, the one at "
            f"latitude {abs(math.degrees(lat)):.2f} {'S' if hemi == 'N' else 'N'}; the GNSS latitude "
            f"{abs(math.degrees(lat)):.2f} {hemi} expects {expected / degph:+.2f}: the latitudes' sign is wrong "
            f"({SIGN_SLIPS['lat'][lat < 0]}, or the hemisphere column left out)? "
            "(else an up-gyro bias that large: set model.gyro_bias_sigma_degph to the gyro's datasheet bias)"
        )


def _any_perpendicular(up):
    a = np.eye(3)[int(np.argmin(np.abs(up)))]
    v = a - (a @ up) * up
    return v / np.linalg.norm(v)


def _orthonormal(m):
    u, _, vt = np.linalg.svd(m)
    r = u @ vt
    if np.linalg.det(r) < 0:
        u[:, -1] *= -1
        r = u @ vt
    return r


# --------------------------------------------------------------------------
# in motion, with GNSS
# --------------------------------------------------------------------------


def gnss_inertial_velocity(gnss_time, lat, lon, height, t_query, half_window_s, ellipsoid: Ellipsoid = WGS84):
    """Inertial position and velocity at ``t_query`` from GNSS positions (local quadratic fits).

    Parameters
    ----------
    gnss_time, lat, lon, height : ndarray (k,)
        s (record base), rad, rad, m.
    t_query : ndarray (m,)
        s.
    half_window_s : float
        Half width of each fit, s.

    Returns
    -------
    r_i, v_i : ndarray (m, 3)
        m, m/s; NaN where fewer than 3 samples on both sides of the query lie in the window.
    """
    tg = np.asarray(gnss_time, float)
    r_e = geodetic_to_ecef(np.asarray(lat, float), np.asarray(lon, float), np.asarray(height, float), ellipsoid)
    r_i = np.einsum("nij,nj->ni", mat_ie(tg, ellipsoid.omega), r_e)
    return local_quadratic(tg, r_i, t_query, half_window_s)


def local_quadratic(time, values, t_query, half_window_s):
    """Value and slope at ``t_query`` of quadratics fitted to ``values`` over ``+-half_window_s``.

    Parameters
    ----------
    time : ndarray, shape (k,)
        s, increasing.
    values : ndarray, shape (k, 3)
    t_query : ndarray, shape (m,)
        s.
    half_window_s : float

    Returns
    -------
    value, slope : ndarray, shape (m, 3)
        NaN where fewer than 3 samples lie in the window or the query is not inside them.
    """
    tg = np.asarray(time, float)
    r_i = np.asarray(values, float)
    tq = np.atleast_1d(np.asarray(t_query, float))
    out_r = np.full((tq.size, 3), np.nan)
    out_v = np.full((tq.size, 3), np.nan)
    lo = np.searchsorted(tg, tq - half_window_s, side="left")
    hi = np.searchsorted(tg, tq + half_window_s, side="right")
    for k in range(tq.size):
        a, b = lo[k], hi[k]
        if b - a < 3:
            continue
        dt = tg[a:b] - tq[k]
        if dt[0] > 0.5 * half_window_s or dt[-1] < -0.5 * half_window_s:
            continue  # the query is not inside the samples (gap or end): no extrapolation
        x = np.stack([np.ones_like(dt), dt, dt * dt], axis=1)
        coef, *_ = np.linalg.lstsq(x, r_i[a:b], rcond=None)
        out_r[k], out_v[k] = coef[0], coef[1]
    return out_r, out_v


def residual_correlation_factor(res, max_lag=None) -> float:
    """Variance inflation ``1 + 2 sum_k rho_k`` of a correlated residual series, >= 1.

    Parameters
    ----------
    res : ndarray (n, 3)
        Residuals in time order; the three components' autocorrelations are averaged.
    max_lag : int, optional
        Largest lag summed (default n // 4); the sum stops at the first lag whose
        autocorrelation drops below zero (Geyer's initial positive sequence, simplified).
    """
    r = np.asarray(res, float)
    r = r - r.mean(axis=0)
    n = r.shape[0]
    var = float(np.sum(r * r))
    if n < 4 or var == 0.0:
        return 1.0
    lags = max_lag if max_lag is not None else max(1, n // 4)
    total = 0.0
    for k in range(1, lags + 1):
        rho = float(np.sum(r[k:] * r[:-k])) / var
        if rho <= 0.0:
            break
        total += rho
    return max(1.0, 1.0 + 2.0 * total)


def wahba(a, b):
    """Rotation ``R`` minimising ``sum |a_k - R b_k|^2`` (SVD solution of Wahba's problem).

    Parameters
    ----------
    a, b : ndarray (n, 3)

    Returns
    -------
    ndarray (3, 3), a proper rotation.
    """
    m = np.asarray(a, float).T @ np.asarray(b, float)
    u, _, vt = np.linalg.svd(m)
    d = np.sign(np.linalg.det(u) * np.linalg.det(vt))
    return u @ np.diag([1.0, 1.0, d]) @ vt


def match_vectors(
    time,
    f_t,
    w_t,
    gnss,
    window_s,
    ellipsoid: Ellipsoid = WGS84,
    spacing_s=MATCH_SPACING_S,
    c_t0=None,
    half_window_s=None,
    smooth_imu=False,
    gnss_fits: dict | None = None,
):
    """Both sides of the velocity-matching equation over ``[time[0], time[0] + window_s]``.

    ``v_i(t_k) - int G_i dt = v_i(t_r) + C_it(t0) int C_t0_t f_t dt``: ``a`` the GNSS side, ``b``
    the IMU side on the triad axes at ``time[0]``, both centred (which removes ``v_i(t_r)``), so
    that ``a = R b`` for the rotation ``R = C_it(t0)`` of a consistent triad.

    Parameters
    ----------
    time, f_t, w_t, gnss, window_s, ellipsoid, spacing_s, c_t0
        As :func:`velocity_matching`.
    half_window_s : float, optional
        Half width of the GNSS fits, s (default: 1.5 GNSS steps, at least 1 s).
    smooth_imu : bool
        Fit the IMU side alike (its velocity integrated to a position at the GNSS times, the
        same quadratics' slope): the fits' smoothing then cancels from ``a - R b``, and wide
        fits take the GNSS noise out of the comparison.
    gnss_fits : dict, optional
        The GNSS side (its fits, the gravitation integrated along the track) by channel and
        epochs, kept by a caller that matches many IMU hypotheses over the same windows
        (:func:`gravsurvey.consistency.strapdown_axis_fit`): it depends on the GNSS alone.

    Returns
    -------
    a, b : ndarray, shape (k, 3)
        m/s.
    tq : ndarray, shape (k,)
        Matched epochs, s.

    Raises
    ------
    DataError
        Fewer than 4 epochs with GNSS on both sides.
    """
    t = np.asarray(time, float)
    f = np.asarray(f_t, float)
    if c_t0 is None:
        c_t0 = propagate_attitude(t, w_t, np.eye(3))
    a_t0 = np.einsum("nij,nj->ni", c_t0, f)  # specific force on the triad axes at t0
    # cumulative integral (trapezoid) of C_t0_t f
    u_cum = np.zeros((t.size, 3))
    u_cum[1:] = np.cumsum(0.5 * (a_t0[1:] + a_t0[:-1]) * np.diff(t)[:, None], axis=0)
    tg = np.asarray(gnss.time, float)
    rate = (tg.size - 1) / (tg[-1] - tg[0]) if tg.size > 1 else 1.0
    hw = max(1.0, 1.5 / rate) if half_window_s is None else float(half_window_s)
    t_end = min(t[-1], t[0] + window_s, tg[-1])
    tq = np.arange(max(t[0], tg[0]) + hw, t_end - hw + 1e-9, spacing_s)
    if tq.size < 4:
        raise DataError("alignment: too little GNSS data at the start of the flight for an in-motion alignment")
    key = (id(gnss), ellipsoid, hw, float(tq[0]), float(tq[-1]), tq.size)
    if gnss_fits is not None and key in gnss_fits:
        _, tq, v_q, g_cum = gnss_fits[key]
    else:
        tq, v_q, g_cum = _gnss_side(gnss, tq, hw, ellipsoid)
        if gnss_fits is not None:
            # the channel kept with its fits: its id in the key is not reused while the store lives
            gnss_fits[key] = (gnss, tq, v_q, g_cum)
    if smooth_imu:
        pos = np.zeros_like(u_cum)
        pos[1:] = np.cumsum(0.5 * (u_cum[1:] + u_cum[:-1]) * np.diff(t)[:, None], axis=0)
        inside = (tg >= t[0]) & (tg <= t[-1])
        pos_g = np.stack([np.interp(tg[inside], t, pos[:, i]) for i in range(3)], axis=1)
        _, u_q = local_quadratic(tg[inside], pos_g, tq, hw)
        keep = np.all(np.isfinite(u_q), axis=1)
        tq, g_cum, u_q, v_q = tq[keep], g_cum[keep] - g_cum[keep][0], u_q[keep], v_q[keep]
    else:
        u_q = np.stack([np.interp(tq, t, u_cum[:, i]) for i in range(3)], axis=1)
    # v(t_k) - int G = v(t_r) + C_it(t0) u(t_k): the unknown v(t_r) is removed by centring both
    # sides (differencing against one GNSS velocity would put that fit's error into every epoch)
    a = v_q - g_cum
    b = u_q
    return a - a.mean(axis=0), b - b.mean(axis=0), tq


def _gnss_side(gnss, tq, hw, ellipsoid):
    """:func:`match_vectors`' GNSS side at the epochs ``tq`` (s) with a gap-free fit: the epochs
    (k,), the inertial velocity (k, 3) m/s and the gravitation integrated along the track (k, 3)
    m/s; :class:`DataError` when fewer than 4 epochs are left."""
    tg = np.asarray(gnss.time, float)
    r_q, v_q = gnss_inertial_velocity(tg, gnss.lat, gnss.lon, gnss.height, tq, hw, ellipsoid)
    ok = np.all(np.isfinite(v_q), axis=1)
    tq, r_q, v_q = tq[ok], r_q[ok], v_q[ok]
    if tq.size < 4:
        raise DataError(
            "alignment: too little gap-free GNSS data at the start of the flight for an in-motion alignment"
        )
    # gravitation along the GNSS track (inertial axes), integrated by the trapezoid rule
    m_ie = mat_ie(tq, ellipsoid.omega)
    r_e = np.einsum("nji,nj->ni", m_ie, r_q)
    g_i = np.einsum("nij,nj->ni", m_ie, normal_gravitation_ecef(r_e, ellipsoid))
    g_cum = np.zeros_like(g_i)
    g_cum[1:] = np.cumsum(0.5 * (g_i[1:] + g_i[:-1]) * np.diff(tq)[:, None], axis=0)
    return tq, v_q, g_cum


def match_residual_rms(
    time,
    f_t,
    w_t,
    gnss,
    ellipsoid: Ellipsoid = WGS84,
    half_window_s=MATCH_CHECK_HALF_WINDOW_S,
    c_t0=None,
    gnss_fits: dict | None = None,
) -> float:
    """RMS of ``|a - R b|`` of the best rotation (:func:`match_vectors` with both sides fitted
    alike, :func:`wahba`) over the whole of ``time``, m/s: what is left of the GNSS noise and
    the gyro drift for a consistent triad; tens of m/s through turns for a gyro axis of the
    wrong sign. ``c_t0``: the gyros' attitude history, when already propagated; ``gnss_fits``:
    :func:`match_vectors`' store of the GNSS side, for many calls over the same windows."""
    t = np.asarray(time, float)
    a, b, _ = match_vectors(
        t,
        f_t,
        w_t,
        gnss,
        t[-1] - t[0],
        ellipsoid,
        c_t0=c_t0,
        half_window_s=half_window_s,
        smooth_imu=True,
        gnss_fits=gnss_fits,
    )
    res = a - b @ wahba(a, b).T
    return float(np.sqrt(np.mean(np.sum(res * res, axis=1))))


def velocity_matching(
    time,
    f_t,
    w_t,
    gnss,
    window_s,
    ellipsoid: Ellipsoid = WGS84,
    spacing_s=MATCH_SPACING_S,
    c_t0=None,
    gyro_bias_sigma_radps=0.0,
):
    """In-motion alignment over ``[time[0], time[0] + window_s]`` by velocity matching.

    Parameters
    ----------
    time : ndarray (n,)
        IMU times, s (record base).
    f_t, w_t : ndarray (n, 3)
        Specific force (m/s^2) and angular rate (rad/s) on the triad.
    gnss : GnssChannel
        Positions (rad, rad, m) at their times.
    window_s : float
        Length of data used, s.
    c_t0 : ndarray (n, 3, 3), optional
        ``C_t0_t`` from :func:`propagate_attitude` with the identity (computed when omitted).
    gyro_bias_sigma_radps : float
        Gyro bias sigma, rad/s: the bias turns ``C_t0_t`` by ``b t`` over the window, which
        the least squares do not see; ``(b T / 2)^2`` is added to each axis' variance.

    Returns
    -------
    mat_it0 : ndarray (3, 3)
        Triad -> inertial at ``time[0]``.
    cov_t : ndarray (3, 3)
        Error covariance on the triad axes (``C_true = C (I + [theta x])``), rad^2.
    n_used : int
        Matched epochs.
    """
    t = np.asarray(time, float)
    a, b, tq = match_vectors(t, f_t, w_t, gnss, window_s, ellipsoid, spacing_s, c_t0)
    rot = wahba(a, b)
    res = a - b @ rot.T
    dof = max(3 * res.shape[0] - 6, 1)
    s2 = float(np.sum(res * res)) / dof
    sk = skew(b)
    info = np.einsum("nji,njk->ik", sk, sk)
    # the matched epochs' errors are correlated (overlapping GNSS fits, gyro drift, unmodelled
    # motion): scale by the residuals' own integrated autocorrelation 1 + 2 sum(rho_k)
    # (the effective number of independent epochs is N / that)
    cov = s2 * np.linalg.inv(info) * residual_correlation_factor(res) * MATCH_SIGMA_INFLATION**2
    cov += np.eye(3) * (0.5 * gyro_bias_sigma_radps * (tq[-1] - t[0])) ** 2
    return rot, 0.5 * (cov + cov.T), int(tq.size)


def align(record, params=None, ellipsoid: Ellipsoid = WGS84, lat=None) -> Alignment:
    """Coarse alignment of a strapdown record at its first IMU sample.

    Static levelling + gyrocompassing when the record starts at rest and the gyros are good
    enough; otherwise (or when better) velocity matching against GNSS over a growing window
    (60 s, 120 s, ... up to 30 min, or the record) until the heading sigma is below
    :data:`MATCH_TARGET_HEADING_DEG`.

    Parameters
    ----------
    record : FlightRecord
    params : InmParams, optional
        For the gyro bias/noise and accelerometer noise sigmas (defaults otherwise).
    lat : float, optional
        Latitude for gyrocompassing, rad (default: the first GNSS sample).

    Returns
    -------
    Alignment

    Raises
    ------
    DataError
        Neither a static period nor GNSS to align with.
    """
    from .params import InmParams

    p = params if params is not None else InmParams()
    imu = record.imu
    t = np.asarray(imu.time, float)
    f = np.asarray(imu.specific_force_t, float)
    w = np.asarray(imu.angular_rate_t, float)
    src = record.source or "record"
    warn = []
    static = static_span(t, f, w)
    gn = record.gnss
    have_gnss = gn is not None and len(gn.time) >= 3
    if lat is None and have_gnss:
        lat = float(np.asarray(gn.lat, float)[np.isfinite(gn.lat)][0])
    if have_gnss and static > 0.0:
        static = min(static, gnss_static_span(gn, float(t[0]), p.gnss_horizontal_sigma_m, ellipsoid))
    candidates, static_warn = [], []
    s_b = math.radians(p.gyro_bias_sigma_degph) / 3600.0
    s_n = math.radians(p.gyro_drift_degph) / 3600.0
    if static >= MIN_STATIC_S:
        sel = t <= t[0] + static
        if lat is None:
            warn.append("no GNSS latitude: gyrocompassing assumes 45 deg")
            lat = math.radians(45.0)
        mat, cov, gw = gyrocompass(
            f[sel].mean(axis=0),
            w[sel].mean(axis=0),
            lat,
            static,
            s_b,
            s_n,
            accel_noise_mps2=p.accel_noise_mps2,
            omega=ellipsoid.omega,
        )
        warn += gw
        static_warn = list(gw)
        if not gw and have_gnss:
            hemisphere_check(
                mat[2], w[sel].mean(axis=0), lat, static, s_b, s_n, record.source_of("gnss"), ellipsoid.omega
            )
        # the Earth turns under the static triad: C_it(t0) uses ENU at t0 (mean taken at mid-span;
        # the heading moves by W sin(lat) T/2, below 0.01 deg for 10 min)
        candidates.append(Alignment(mat, cov, "static-gyrocompass" if not gw else "static-levelling", static, static))
    else:
        warn.append("no static period at the start: no levelling or gyrocompassing; aligned in motion")
    if have_gnss:
        # only the longest window's samples are needed (a long 200 Hz record would otherwise
        # hold a (n, 3, 3) attitude history of several 100 MB)
        cut = t <= t[0] + MATCH_WINDOWS_S[-1]
        tw, fw, ww = t[cut], f[cut], w[cut]
        c_t0 = propagate_attitude(tw, ww, np.eye(3))
        best = None
        for win in MATCH_WINDOWS_S:
            span = min(win, tw[-1] - tw[0])
            try:
                rot, cov_t, _ = velocity_matching(tw, fw, ww, gn, span, ellipsoid, c_t0=c_t0, gyro_bias_sigma_radps=s_b)
            except DataError:
                if span >= tw[-1] - tw[0]:
                    break
                continue
            m_in0 = _mat_in_at(gn, t[0], ellipsoid)
            mat = m_in0.T @ rot
            cov_n = mat @ cov_t @ mat.T
            best = Alignment(mat, cov_n, "velocity-matching", span, static)
            if math.degrees(best.sigma_heading_rad) < MATCH_TARGET_HEADING_DEG or span >= tw[-1] - tw[0]:
                break
        if best is not None:
            candidates.append(best)
    if not candidates:
        raise DataError(
            f"{src}: alignment: no static period at the start and no GNSS to align a strapdown triad "
            "with; give flights[].initial.attitude_deg"
        )
    out = min(candidates, key=lambda c: c.sigma_heading_rad)
    stat = candidates[0] if candidates[0].method.startswith("static") else None
    if stat is not None and out is not stat and stat.sigma_level_rad < out.sigma_level_rad:
        # the static levelling is the better vertical: keep the motion's north about it
        up = stat.mat_nt[2]
        north = out.mat_nt[1] - (out.mat_nt[1] @ up) * up
        north /= np.linalg.norm(north)
        mat = np.stack([np.cross(north, up), north, up])
        cov = np.diag([stat.cov_n[0, 0], stat.cov_n[1, 1], out.cov_n[2, 2]])
        out = Alignment(mat, cov, "static-levelling+" + out.method, out.converge_s, static)
    if out.method == "static-levelling":
        raise DataError(
            f"{src}: alignment: heading unknown (gyros too noisy to gyrocompass and no GNSS to align "
            "in motion); give flights[].initial.attitude_deg"
        )
    if math.degrees(out.sigma_heading_rad) > POOR_HEADING_DEG:
        warn.append(
            f"poor alignment: heading sigma {math.degrees(out.sigma_heading_rad):.2g} deg after "
            f"{out.converge_s:.0f} s (no motion: straight, steady flight does not show the heading)"
        )
    elif static_warn:
        # the motion gave the heading: why gyrocompassing could not is no warning (at 86 deg the
        # Earth rate's horizontal part is 1 deg/h, and every high-latitude flight would say so)
        warn = [w for w in warn if w not in static_warn]
    out.warnings = warn
    return out


def _mat_in_at(gnss, t0, ellipsoid):
    """ENU -> inertial at time ``t0`` at the GNSS position nearest in time."""
    tg = np.asarray(gnss.time, float)
    k = int(np.argmin(np.abs(tg - t0)))
    return mat_ie(t0, ellipsoid.omega) @ mat_en(float(gnss.lat[k]), float(gnss.lon[k]))
