"""The conventional scalar airborne-gravity reduction (``classic``), the reference method.

This is what most airborne processors do (DGP, shipgrav and their relatives), kept here so the
3D-INM's gain is measured against it on the same data at the same resolution.  Per output epoch
``t_k`` (a uniform grid at the height channel's rate)::

    dg_raw(t_k) = f_U(t_k) - hdd(t_k) + E(t_k) - gamma(lat_k, h_k)
    dg = LP * dg_raw                      (zero-phase Gaussian FIR, 'valid' part only)

* ``f_U`` -- vertical specific force: the gravimeter (triad z) of an ENU-stabilised platform, or
  ``(mat_nt @ f_t)_U`` for a strapdown triad with an attitude ``mat_nt`` (triad -> ENU) from the
  navigation solution.  It is decimated to the grid by the triangle-weighted mean over
  ``[t_k - dt, t_k + dt]`` (:func:`triangle_mean`), the very kernel through which the height's
  second difference sees the true vertical acceleration, so the aircraft's vertical motion
  cancels identically in ``f_U - hdd`` even where turbulence aliases at the height rate.  (With a
  plain boxcar instead, 5 m turbulence down to 2 s periods leaves ~0.1 mGal after a 300 s
  filter at 1 Hz height: measured, tests/test_classic.py.)
* ``hdd`` -- vertical kinematic acceleration, the second central difference of the height
  channel (GNSS ellipsoidal height when present, else the altimeter) on the grid,
  ``(h[k+1] - 2 h[k] + h[k-1]) / dt^2``.  Differencing amplifies white height noise by
  ``sqrt(6) / dt^2`` (1 m at 1 Hz -> 2.4 m/s^2 per sample); it is the low-pass, which commutes
  with the difference, that brings it down: the result equals the height convolved with the
  second difference of the FIR kernel, exact for quadratics.  For white height noise ``sigma_h``
  the filtered noise is ``sigma_h * sqrt(dt * 3 / (8 sqrt(pi) s^5))`` for a Gaussian of standard
  deviation ``s`` (s): ~0.9 mGal for sigma_h = 1 m, dt = 1 s, a 400 s filter.
* ``E`` -- the full Eotvos correction, closed form with the ellipsoidal radii of curvature::

      E = v_E^2 / (N + h) + v_N^2 / (M + h) + 2 OMEGA v_E cos(lat)

  exact for the Up component of the kinematics in geodetic ENU (transport rate of the ENU frame
  and the Coriolis term); Harlan (1968, eq. 16) is its first-order series in the flattening and
  ``h/a`` (:func:`eotvos_harlan`, agreement tested).  Velocities come from the position track
  (GNSS latitude/longitude differentiated on the grid, ``v_N = (M + h) dlat/dt``,
  ``v_E = (N + h) cos(lat) dlon/dt``, second-order central differences) or from a supplied
  navigation solution (``track=``).
* ``gamma`` -- normal gravity magnitude at the point, exact (:func:`gravsurvey.geodesy.normal_gravity`,
  checked against ``boule``, Li & Goetze 2001).
  The normal gravity vector at flight height leans from the ellipsoid normal by < 1e-5 rad,
  which changes its Up component by < 1e-9 m/s^2: negligible.

Sign: the result is the gravity disturbance, positive = stronger gravity (excess mass), the same
sign as the simulator's truth ``disturbance`` and the 3D-INM estimate.

Filter: Gaussian FIR, zero phase (symmetric kernel applied forward once), truncated at +-4
standard deviations and normalised to unit DC gain.  Its **filter length** ``L`` (s) is the full
wavelength in time at which the transfer function is 0.5 (-6 dB); the half-wavelength spatial
resolution is ``speed * L / 2``.  The Gaussian's standard deviation is
``s = L * sqrt(ln 2 / 2) / pi`` (0.1874 L).  Epochs within the kernel's half width of either end
are not returned (the ``valid`` part of the convolution).

This module must not import :mod:`gravsurvey.simulate` (estimator and simulator share only
:mod:`gravsurvey.geodesy`).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline

from .errors import ConfigError, DataError, DataWarning
from .geodesy import MGAL, WGS84, Ellipsoid, normal_gravity, radii_of_curvature
from .filters import SIGMA_PER_LENGTH, gaussian_fir, lowpass_valid
from .inm.params import TRIADS
from .io.record import FlightRecord

#: Default filter length (full wavelength at -6 dB), s.  model.md: ~400 s reaches ~1 mGal.
DEFAULT_FILTER_LENGTH_S = 400.0


HEIGHT_SOURCES = ("auto", "gnss", "altimeter")


# --------------------------------------------------------------------------
# Result and options
# --------------------------------------------------------------------------


@dataclass
class ClassicResult:
    """Output of :func:`classic_reduction`.

    Attributes
    ----------
    time : ndarray, shape (m,)
        Output epochs, s after ``record.t0_unix_ns`` (uniform, step ``info['dt_s']``).
    disturbance : ndarray, shape (m,)
        Low-passed gravity disturbance, m/s^2, positive = stronger gravity.
    lat, lon : ndarray, shape (m,)
        Geodetic latitude and longitude at the epochs, rad.
    height : ndarray, shape (m,)
        Ellipsoidal height used (m).
    speed : ndarray, shape (m,)
        Ground speed, m/s (horizontal).
    vel_n : ndarray, shape (m, 3)
        ENU velocity used, m/s (Up = central difference of the height).
    raw : ndarray, shape (m,)
        The unfiltered disturbance ``f_up - kinematic + eotvos - normal_gravity``, m/s^2
        (very noisy: the height's second difference is not yet low-passed).
    terms : dict of ndarray, shape (m,)
        The unfiltered terms at the same epochs, m/s^2: ``f_up``, ``kinematic`` (hdd),
        ``eotvos``, ``normal_gravity``, ``raw`` (= f_up - kinematic + eotvos - normal_gravity).
    info : dict
        ``method`` ('classic'), ``filter`` ('gaussian'), ``filter_length_s`` (L),
        ``filter_sigma_s``, ``kernel_half_width_s``, ``speed_mps`` (used for the resolution),
        ``resolution_m`` (half wavelength = speed * L / 2), ``dt_s``, ``height_source``,
        ``velocity_source``, ``notes`` (list of str).
    """

    time: np.ndarray
    disturbance: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    height: np.ndarray
    speed: np.ndarray
    vel_n: np.ndarray
    raw: np.ndarray
    terms: dict = field(default_factory=dict)
    info: dict = field(default_factory=dict)


# --------------------------------------------------------------------------
# Building blocks (public: tests pass truth through the very same filter)
# --------------------------------------------------------------------------


def interval_mean(t: np.ndarray, y: np.ndarray, t_out: np.ndarray, dt_s: float) -> np.ndarray:
    """Mean over ``[t_out - dt/2, t_out + dt/2]`` of the piecewise-linear interpolant of ``y(t)``.

    Exact integral (cumulative trapezoid), so it is a boxcar anti-alias filter for decimating
    the IMU to the output grid at any pair of rates.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Strictly increasing sample times, s; must cover ``[t_out[0]-dt/2, t_out[-1]+dt/2]``.
    y : ndarray, shape (n,)
    t_out : ndarray, shape (m,)
    dt_s : float

    Returns
    -------
    ndarray, shape (m,)
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    cum = np.concatenate(([0.0], np.cumsum(0.5 * (y[1:] + y[:-1]) * np.diff(t))))

    def integral(tq):
        i = np.clip(np.searchsorted(t, tq, side="right") - 1, 0, t.size - 2)
        dtq = tq - t[i]
        slope = (y[i + 1] - y[i]) / (t[i + 1] - t[i])
        return cum[i] + y[i] * dtq + 0.5 * slope * dtq**2

    return (integral(t_out + 0.5 * dt_s) - integral(t_out - 0.5 * dt_s)) / dt_s


def _piecewise_linear_integrals(t, y):
    """Knot values of the first and second running integrals of the linear interpolant of y."""
    h = np.diff(t)
    slope = np.diff(y) / h
    i1 = np.concatenate(([0.0], np.cumsum(y[:-1] * h + 0.5 * slope * h**2)))
    i2 = np.concatenate(([0.0], np.cumsum(i1[:-1] * h + 0.5 * y[:-1] * h**2 + slope * h**3 / 6.0)))
    return i1, i2, slope


def _second_integral_at(t, y, i1, i2, slope, tq):
    i = np.clip(np.searchsorted(t, tq, side="right") - 1, 0, t.size - 2)
    d = tq - t[i]
    return i2[i] + i1[i] * d + 0.5 * y[i] * d**2 + slope[i] * d**3 / 6.0


def triangle_mean(t: np.ndarray, y: np.ndarray, t_out: np.ndarray, dt_s: float, chunk: int = 2048) -> np.ndarray:
    """Triangle-weighted mean over ``[t_out - dt, t_out + dt]`` of the linear interpolant of ``y(t)``.

    The weight ``(dt - |tau|) / dt^2`` is the kernel through which the second difference of a
    height sampled at step ``dt`` sees the true vertical acceleration:
    ``(h(t+dt) - 2h(t) + h(t-dt)) / dt^2 = integral hdd(t+tau) (dt - |tau|)/dt^2 dtau`` exactly.
    Averaging the vertical specific force with the same kernel makes the aircraft's vertical
    acceleration cancel identically in ``f_up - hdd``, including the part that aliases when
    turbulence has periods shorter than ``2 dt``.  Exact for the piecewise-linear interpolant
    (closed-form second running integral), evaluated in chunks with the mean removed so the
    running integrals stay small (rounding < 1e-12 m/s^2).

    Parameters
    ----------
    t : ndarray, shape (n,)
        Strictly increasing sample times, s; must cover ``[t_out[0] - dt, t_out[-1] + dt]``.
    y : ndarray, shape (n,)
    t_out : ndarray, shape (m,)
    dt_s : float
    chunk : int
        Output epochs per chunk.

    Returns
    -------
    ndarray, shape (m,)
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    t_out = np.asarray(t_out, dtype=float)
    out = np.empty(t_out.shape)
    for a in range(0, t_out.size, chunk):
        tq = t_out[a : a + chunk]
        lo = max(0, np.searchsorted(t, tq[0] - dt_s, side="right") - 2)
        hi = min(t.size, np.searchsorted(t, tq[-1] + dt_s, side="left") + 2)
        tt = t[lo:hi]
        ref = float(np.mean(y[lo:hi]))
        yy = y[lo:hi] - ref
        i1, i2, slope = _piecewise_linear_integrals(tt, yy)
        j = [_second_integral_at(tt, yy, i1, i2, slope, tq + k * dt_s) for k in (-1, 0, 1)]
        out[a : a + chunk] = ref + (j[2] - 2.0 * j[1] + j[0]) / dt_s**2
    return out


def eotvos_exact(lat, height, v_east, v_north, ellipsoid: Ellipsoid = WGS84):
    """Full Eotvos correction, closed form, m/s^2 (add to the measured vertical specific force).

    ``E = v_E^2/(N+h) + v_N^2/(M+h) + 2 OMEGA v_E cos(lat)``; M, N the meridian and prime-vertical
    radii of curvature at ``lat`` (rad), ``h`` ellipsoidal height (m), velocities relative to the
    Earth at the aircraft (m/s).  Exact: it is minus the Up component of
    ``(2 Omega_ie + Omega_en) x v`` in geodetic ENU.
    """
    lat = np.asarray(lat, dtype=float)
    m, n = radii_of_curvature(lat, ellipsoid)
    ve = np.asarray(v_east, dtype=float)
    vn = np.asarray(v_north, dtype=float)
    return ve**2 / (n + height) + vn**2 / (m + height) + 2.0 * ellipsoid.omega * ve * np.cos(lat)


def eotvos_harlan(lat, height, ground_speed, track, ellipsoid: Ellipsoid = WGS84):
    """Harlan (1968) eq. 16: the first-order series of :func:`eotvos_exact`, m/s^2.

    ``E = V^2/a [1 + h/a - f (1 - cos^2(lat) (3 - 2 sin^2(track)))] + 2 OMEGA V cos(lat) sin(track) (1 + h/a)``

    ``V`` is the ground speed (speed of the nadir point on the ellipsoid, m/s), ``track`` the
    course clockwise from north (rad).  Kept for comparison; differences from the exact form
    are of order ``f^2``, ``(h/a)^2`` and ``f h/a`` (< 0.01 mGal at 100 m/s, 10 km; tested).
    """
    a, f, w = ellipsoid.a, ellipsoid.f, ellipsoid.omega
    lat = np.asarray(lat, dtype=float)
    c2 = np.cos(lat) ** 2
    s2a = np.sin(track) ** 2
    return ground_speed**2 / a * (
        1.0 + height / a - f * (1.0 - c2 * (3.0 - 2.0 * s2a))
    ) + 2.0 * w * ground_speed * np.cos(lat) * np.sin(track) * (1.0 + height / a)


def second_difference(h: np.ndarray, dt_s: float) -> np.ndarray:
    """``(h[k+1] - 2h[k] + h[k-1]) / dt^2`` with NaN at both ends, shape (m,)."""
    out = np.full(h.shape, np.nan)
    out[1:-1] = (h[2:] - 2.0 * h[1:-1] + h[:-2]) / dt_s**2
    return out


# --------------------------------------------------------------------------
# The reduction
# --------------------------------------------------------------------------


def _on_grid(t_src, y_src, grid, tol):
    """Values of y at grid epochs: direct when the samples sit on the grid, else a cubic spline."""
    if t_src.size == grid.size and np.max(np.abs(t_src - grid)) <= tol:
        return np.asarray(y_src, dtype=float), False
    return CubicSpline(t_src, y_src)(grid), True


def _attr(obj, name):
    if isinstance(obj, dict):
        return obj.get(name)
    return getattr(obj, name, None)


def classic_reduction(
    record: FlightRecord,
    *,
    ellipsoid: Ellipsoid = WGS84,
    resolution_m: float | None = None,
    filter_length_s: float | None = None,
    speed_mps: float | None = None,
    mat_nt: np.ndarray | None = None,
    triad: str = "platform",
    track=None,
    height_source: str = "auto",
) -> ClassicResult:
    """Conventional scalar airborne-gravity reduction of one flight (see the module docstring).

    Parameters
    ----------
    record : FlightRecord
        IMU (triad z = gravimeter for a platform), altimeter and optional GNSS.
    ellipsoid : Ellipsoid
        Reference for heights, radii and normal gravity (WGS84 or GRS80).
    resolution_m : float, optional
        Wanted half-wavelength resolution, m: sets ``L = 2 resolution_m / speed``.
    filter_length_s : float, optional
        Gaussian filter length L (s, full wavelength at -6 dB).  Default 400 s when neither
        this nor ``resolution_m`` is given; giving both is an error.
    speed_mps : float, optional
        Speed used to convert between L and resolution; default: median ground speed.
    mat_nt : ndarray, shape (n_imu, 3, 3), optional
        Triad -> ENU attitude at the IMU epochs (navigation solution).  Required for a
        strapdown triad; when given it is always used.
    triad : {'platform', 'strapdown'}
    track : object or dict, optional
        Navigation solution with ``time`` (s, record base), ``lat``, ``lon`` (rad) and
        ``vel_n`` ((k, 3) ENU, m/s) attributes or keys (e.g. the 3D-INM solution): source of
        position and horizontal velocity when the record has no GNSS (used instead of GNSS
        when given).
    height_source : {'auto', 'gnss', 'altimeter'}

    Returns
    -------
    ClassicResult

    Raises
    ------
    ConfigError
        Conflicting or invalid options (strapdown without attitude, both length and resolution).
    DataError
        No horizontal track (no GNSS and no ``track``), wrong ``mat_nt`` shape, flight shorter
        than the filter, channels that do not overlap.
    """
    notes: list[str] = []
    if triad not in TRIADS:
        raise ConfigError(f"triad: expected platform or strapdown, got {triad!r}")
    if height_source not in HEIGHT_SOURCES:
        raise ConfigError(f"height_source: expected one of {', '.join(HEIGHT_SOURCES)}, got {height_source!r}")
    if filter_length_s is not None and resolution_m is not None:
        raise ConfigError("classic: give filter_length_s or resolution_m, not both")
    if triad == "strapdown" and mat_nt is None:
        raise ConfigError(
            "classic: a strapdown triad needs its attitude mat_nt (triad -> ENU) from the navigation solution"
        )

    imu = record.imu
    t_imu = np.asarray(imu.time, dtype=float)
    f_t = np.asarray(imu.specific_force_t, dtype=float)
    if mat_nt is not None:
        mat_nt = np.asarray(mat_nt, dtype=float)
        if mat_nt.shape != (t_imu.size, 3, 3):
            raise DataError(
                f"classic: mat_nt must have shape ({t_imu.size}, 3, 3) (one per IMU sample), got {mat_nt.shape}"
            )
        # Up row of mat_nt times f_t: the vertical specific force
        f_up_imu = np.einsum("kj,kj->k", mat_nt[:, 2, :], f_t)
    else:
        f_up_imu = f_t[:, 2]

    # ---- height channel
    gnss = record.gnss
    if height_source == "gnss" and gnss is None:
        raise DataError(f"{record.source or 'record'}: height_source gnss but the record has no GNSS channel")
    if gnss is not None and height_source in ("auto", "gnss"):
        t_h, h_src, hs_name = np.asarray(gnss.time, float), np.asarray(gnss.height, float), "gnss"
    else:
        t_h, h_src, hs_name = (
            np.asarray(record.altimeter.time, float),
            np.asarray(record.altimeter.height, float),
            "altimeter",
        )
    good = np.isfinite(h_src) & np.isfinite(t_h)
    if not good.all():
        notes.append(f"{hs_name}: {int((~good).sum())} non-finite heights dropped (interpolated over)")
        t_h, h_src = t_h[good], h_src[good]
    if t_h.size < 3:
        raise DataError(f"{record.source or 'record'}: {hs_name} channel has {t_h.size} finite samples; need >= 3")
    dt = float(np.median(np.diff(t_h)))
    # grid inside the IMU span so every triangle window [t - dt, t + dt] is covered
    lo = max(t_h[0], t_imu[0] + dt)
    hi = min(t_h[-1], t_imu[-1] - dt)
    if hi <= lo:
        raise DataError(f"{record.source or 'record'}: IMU and {hs_name} channels do not overlap in time")
    k0 = math.ceil((lo - t_h[0]) / dt - 1e-9)
    k1 = math.floor((hi - t_h[0]) / dt + 1e-9)
    grid = t_h[0] + dt * np.arange(k0, k1 + 1)
    tol = 1e-6 * dt
    sel = (t_h >= grid[0] - tol) & (t_h <= grid[-1] + tol)
    h, resampled = _on_grid(t_h[sel], h_src[sel], grid, tol)
    if resampled:
        gaps = np.diff(t_h) > 1.5 * dt
        notes.append(
            f"{hs_name} height resampled to a uniform {dt:g} s grid by cubic spline"
            + (f" ({int(gaps.sum())} gaps > 1.5 steps)" if gaps.any() else "")
        )
        if gaps.any():
            warnings.warn(
                f"{record.source or 'record'}: {hs_name} has {int(gaps.sum())} gaps > 1.5 x {dt:g} s; "
                "classic interpolates across them",
                DataWarning,
                stacklevel=2,
            )

    # ---- position and horizontal velocity
    if track is not None:
        parts = [_attr(track, k) for k in ("time", "lat", "lon", "vel_n")]
        if any(p is None for p in parts):
            raise DataError("classic: track needs time (k,), lat, lon (k,) and vel_n (k, 3)")
        tt, lat_t, lon_t, vel = (np.asarray(p, float) for p in parts)
        lon_t = np.unwrap(lon_t)
        if vel.ndim != 2 or vel.shape[1] < 2 or vel.shape[0] != tt.size or lat_t.shape != tt.shape:
            raise DataError(f"classic: track vel_n must have shape ({tt.size}, 3), got {vel.shape}")
        if grid[0] < tt[0] - tol or grid[-1] > tt[-1] + tol:
            keep = (grid >= tt[0] - tol) & (grid <= tt[-1] + tol)
            grid, h = grid[keep], h[keep]
            notes.append("output limited to the span of the navigation track")
            if grid.size < 3:
                raise DataError(
                    f"{record.source or 'record'}: the height channel and the navigation track hardly overlap in time"
                )
        lat = np.interp(grid, tt, lat_t)
        lon = np.interp(grid, tt, lon_t)
        ve = np.interp(grid, tt, vel[:, 0])
        vn = np.interp(grid, tt, vel[:, 1])
        vel_source = "navigation solution (track=)"
    elif gnss is not None:
        tg = np.asarray(gnss.time, float)
        if grid[0] < tg[0] - tol or grid[-1] > tg[-1] + tol:
            keep = (grid >= tg[0] - tol) & (grid <= tg[-1] + tol)
            grid, h = grid[keep], h[keep]
            notes.append("output limited to the GNSS span")
            if grid.size < 3:
                raise DataError(f"{record.source or 'record'}: the height channel and the GNSS hardly overlap in time")
        gsel = (tg >= grid[0] - tol) & (tg <= grid[-1] + tol)
        lat, _ = _on_grid(tg[gsel], np.asarray(gnss.lat, float)[gsel], grid, tol)
        lon, _ = _on_grid(tg[gsel], np.unwrap(np.asarray(gnss.lon, float)[gsel]), grid, tol)
        hg, _ = _on_grid(tg[gsel], np.asarray(gnss.height, float)[gsel], grid, tol)
        m_rad, n_rad = radii_of_curvature(lat, ellipsoid)
        vn = (m_rad + hg) * np.gradient(lat, dt, edge_order=2)
        ve = (n_rad + hg) * np.cos(lat) * np.gradient(lon, dt, edge_order=2)
        vel_source = "GNSS positions, central differences"
    else:
        raise DataError(
            f"{record.source or 'record'}: classic needs a horizontal track for the Eotvos correction: "
            "the record has no GNSS channel and no navigation solution (track=) was given"
        )
    if grid.size < 3:
        raise DataError(f"{record.source or 'record'}: fewer than 3 common epochs for the classic reduction")

    speed = np.hypot(ve, vn)
    if speed_mps is None:
        speed_mps = float(np.median(speed))
    if resolution_m is not None:
        if speed_mps <= 0:
            raise DataError("classic: ground speed is zero; cannot convert resolution_m to a filter length")
        filter_length_s = 2.0 * resolution_m / speed_mps
    elif filter_length_s is None:
        filter_length_s = DEFAULT_FILTER_LENGTH_S
    if not (filter_length_s > 2.0 * dt):
        raise ConfigError(f"classic: filter length {filter_length_s:g} s must exceed two samples ({2 * dt:g} s)")

    # ---- terms on the grid
    f_up = triangle_mean(t_imu, f_up_imu, grid, dt)
    hdd = second_difference(h, dt)
    eot = eotvos_exact(lat, h, ve, vn, ellipsoid)
    gam = normal_gravity(lat, h, ellipsoid)
    raw = f_up - hdd + eot - gam

    # drop the two ends where hdd is undefined, then filter
    w = gaussian_fir(filter_length_s, dt)
    kh = (w.size - 1) // 2
    inner = slice(1, -1)
    dist = lowpass_valid(raw[inner], w)
    out = slice(1 + kh, grid.size - 1 - kh)
    terms = {
        "f_up": f_up[out],
        "kinematic": hdd[out],
        "eotvos": eot[out],
        "normal_gravity": gam[out],
        "raw": raw[out],
    }
    info = {
        "method": "classic",
        "filter": "gaussian",
        "filter_length_s": float(filter_length_s),
        "filter_sigma_s": float(SIGMA_PER_LENGTH * filter_length_s),
        "kernel_half_width_s": float(kh * dt),
        "speed_mps": float(speed_mps),
        "resolution_m": float(speed_mps * filter_length_s / 2.0),
        "dt_s": dt,
        "height_source": hs_name,
        "velocity_source": vel_source,
        "attitude": "mat_nt" if mat_nt is not None else "platform z axis",
        "notes": notes,
    }
    return ClassicResult(
        time=grid[out],
        disturbance=dist,
        lat=lat[out],
        lon=lon[out],
        height=h[out],
        speed=speed[out],
        vel_n=np.column_stack((ve, vn, np.gradient(h, dt)))[out],
        raw=raw[out],
        terms=terms,
        info=info,
    )


def strapdown_attitude(record: FlightRecord, initial, *, ellipsoid: Ellipsoid = WGS84, use_altimeter: bool = True):
    """Triad -> ENU attitude at every IMU epoch from the 3D-INM mechanization, for ``mat_nt``.

    Integrates the gyros from the initial attitude (the navigation the 3D-INM itself uses, with
    the altimeter radius in the gravity model), then ``mat_nt = mat_en^T mat_ie^T mat_it`` at
    the mechanized position.

    Parameters
    ----------
    record : FlightRecord
    initial : gravsurvey.inm.params.InitialState
        State at the first IMU sample (attitude included).
    ellipsoid : Ellipsoid
    use_altimeter : bool
        Gravity model with the altimeter radius (stable vertical channel).

    Returns
    -------
    mat_nt : ndarray, shape (n_imu, 3, 3)
    """
    from .geodesy import ecef_to_geodetic, mat_en, mat_ie
    from .inm.mechanization import mechanize

    t_imu = np.asarray(record.imu.time, float)
    nav = mechanize(
        t_imu,
        record.imu.specific_force_t,
        record.imu.angular_rate_t,
        initial,
        record.altimeter.time,
        record.altimeter.height,
        use_ext=use_altimeter,
        ellipsoid=ellipsoid,
    )
    m_ie = mat_ie(t_imu, ellipsoid.omega)
    r_e = np.einsum("nji,nj->ni", m_ie, nav.r_i)
    lat, lon, _ = ecef_to_geodetic(r_e, ellipsoid)
    m_en = mat_en(lat, lon)
    return np.einsum("nji,nkj,nkl->nil", m_en, m_ie, nav.mat_it)


def disturbance_mgal(result: ClassicResult) -> np.ndarray:
    """The result's disturbance in mGal (edge convenience)."""
    return result.disturbance / MGAL
