"""Analytic flight truth for the INM tests (independent of the simulator).

A flight along a parallel at constant geodetic latitude and height, constant
east speed: in inertial axes the aircraft moves on a circle about the Earth's
axis at rate ``W + v/((N+h) cos lat)``, so its acceleration is exactly
``-(W + w_l)^2 (x, y, 0)``.  Sensors: specific force ``F = a_i - G_i - dG_i``
with the anomalous gravitation ``dG = -disturbance * Up`` and the absolute
rate of an ENU platform, or of a body triad yawing at a constant rate about
Up (a stress test of the rotation handling).  Only gravsurvey.geodesy is
shared with the code under test.
"""

import numpy as np

from gravsurvey.geodesy import (
    WGS84,
    geodetic_to_ecef,
    mat_en,
    mat_ie,
    normal_gravitation_ecef,
    radii_of_curvature,
)


def rz(a):
    c, s = np.cos(a), np.sin(a)
    m = np.zeros(np.shape(a) + (3, 3))
    m[..., 0, 0], m[..., 0, 1], m[..., 1, 0], m[..., 1, 1], m[..., 2, 2] = c, -s, s, c, 1.0
    return m


def parallel_flight(
    duration_s=3600.0,
    rate_hz=10.0,
    lat0_deg=45.0,
    lon0_deg=135.0,
    h=1000.0,
    speed=50.0,
    disturbance=None,
    triad="platform",
    yaw_rate=0.0,
    heading0_deg=90.0,
    t0=0.0,
):
    """Return a dict of truth and noiseless sensor data.

    disturbance : callable(t) -> m/s^2 positive down, or None.
    triad : "platform" (ENU) or "strapdown" (body, initial heading heading0_deg,
        then yawing at yaw_rate rad/s about Up).
    """
    ell = WGS84
    t = t0 + np.arange(int(round(duration_s * rate_hz)) + 1) / rate_hz
    lat0 = np.radians(lat0_deg)
    m_rad, n_rad = radii_of_curvature(lat0)
    wl = speed / ((n_rad + h) * np.cos(lat0))
    lon = np.radians(lon0_deg) + wl * (t - t0)
    lat = np.full_like(t, lat0)
    r_e = geodetic_to_ecef(lat, lon, h)
    m_ie = mat_ie(t)
    r_i = np.einsum("nij,nj->ni", m_ie, r_e)
    wt = ell.omega + wl
    a_i = -(wt**2) * r_i * np.array([1.0, 1.0, 0.0])
    g_i = np.einsum("nij,nj->ni", m_ie, normal_gravitation_ecef(r_e))
    m_in = np.einsum("nij,njk->nik", m_ie, mat_en(lat, lon))
    up_i = m_in[:, :, 2]
    dist = np.zeros_like(t) if disturbance is None else disturbance(t)
    f_i = a_i - g_i + dist[:, None] * up_i
    w_n = wt * np.stack([np.zeros_like(t), np.cos(lat), np.sin(lat)], axis=-1)
    if triad == "platform":
        mat_nt = np.broadcast_to(np.eye(3), (t.size, 3, 3)).copy()
        w_t = w_n
    else:
        # body (fwd, left, up) with heading psi: mat_nb = Rz(pi/2 - psi)
        psi = np.radians(heading0_deg) - yaw_rate * (t - t0)
        mat_nt = rz(0.5 * np.pi - psi)
        w_t = np.einsum("nji,nj->ni", mat_nt, w_n) + np.array([0.0, 0.0, yaw_rate])
    m_it = np.einsum("nij,njk->nik", m_in, mat_nt)
    f_t = np.einsum("nji,nj->ni", m_it, f_i)
    v_n = np.zeros((t.size, 3))
    v_n[:, 0] = speed
    return dict(
        time=t,
        lat=lat,
        lon=lon,
        height=np.full_like(t, h),
        vel_n=v_n,
        r_i=r_i,
        mat_it=m_it,
        mat_nt=mat_nt,
        f_t=f_t,
        w_t=w_t,
        disturbance=dist,
    )
