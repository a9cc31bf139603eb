"""Flight trajectories with exact derivatives, and the aircraft attitude.

A trajectory is built in three layers, each with analytic time derivatives up
to the third order (jerk), so the specific force and angular rates derived from
it are exact up to floating-point rounding:

1. **Nominal plan** on a flat *survey map*: map east ``x`` and north ``y`` (m)
   as piecewise functions of time made of five primitives: ``static`` (at
   rest), ``ramp`` (straight, speed ``v S(tau)`` or ``v (1 - S(tau))``),
   ``accel`` (straight, speed ``v0 + (v1 - v0) S(tau)``: to and from a line
   flown at its own speed in a wind),
   ``line`` (straight, constant speed) and ``turn`` (constant speed, heading
   ``psi0 + Delta S(tau)``), with ``S(tau) = 35 tau^4 - 84 tau^5 + 70 tau^6 -
   20 tau^7`` the septic smoothstep (its first three derivatives vanish at both
   ends, so heading rate, bank, roll rate, roll acceleration and the
   acceleration are continuous).  Positions inside a turn are the
   integral of ``v (sin psi, cos psi)``, computed by 48-node Gauss-Legendre
   quadrature of an entire function (machine precision); velocity,
   acceleration and jerk are closed form.  Ellipsoidal height ``h(t)`` is
   constant on lines and changes by smoothstep transitions in connectors.
2. **Turbulence**: sums of sinusoids with a low-pass displacement spectrum added
   to ``x``, ``y``, ``h`` and to the attitude angles, multiplied by an envelope
   that is 0 at rest and rises/falls by smoothstep during the speed ramps.
3. **Map to geodetic**: ``lat = lat0 + y / Rm``, ``lon = lon0 + x / Rp`` with
   the constants ``Rm = M(lat0) + h0``, ``Rp = (N(lat0) + h0) cos(lat0)``.  The
   map is linear, so geodetic derivatives are exact; ground speed and track
   differ from the plan's by the map's scale distortion (east speed scales as
   ``cos(lat)/cos(lat0)``: 0.1 % per 5 km of northing at 45 deg), which is part
   of the truth, not an error.

The Earth-relative ENU velocity and acceleration then follow exactly from the
geodetic derivatives (see :func:`geodetic_kinematics`).

Attitude (strapdown body axes x forward, y left, z up; heading clockwise from
north, pitch nose up, roll right wing down; see docs/conventions.md) is the
coordinated-flight attitude of the turbulence-free plan (heading = plan
heading, pitch = flight-path angle ``atan(h_dot / v)``, roll =
``atan(v psi_dot / g0)``) plus the angular turbulence, all with analytic rates.
In a wind (``plan.wind_speed_mps``) the heading is the air velocity's and the roll
that of a turn through the air mass (:func:`crab_attitude`); the ground track stays
the plan's, and with ``plan.hold_speed: air`` each line is flown at the plan speed
through the air (:func:`ground_speed_at_airspeed`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from gravsurvey.errors import ConfigError
from gravsurvey.geodesy import OMEGA_E, WGS84, Ellipsoid, geodetic_to_ecef, mat_en

#: Standard gravity used only to define the coordinated-turn bank angle, m/s^2.
G0_BANK = 9.80665
#: max of S'(tau) on [0, 1] (at tau = 1/2): a turn of angle Delta lasting T has
#: peak rate 2.1875 |Delta| / T.
SMOOTHSTEP_PEAK_RATE = 2.1875
#: Peak acceleration of a change of ground speed between a line and its connectors, m/s^2 (a
#: survey aircraft's gentle power change).
SPEED_CHANGE_MPS2 = 0.5
#: Shortest such change, s.
MIN_SPEED_CHANGE_S = 10.0
#: Time to reach (and leave) the steady rate of a climb after take-off or a descent to land, s.
CLIMB_RAMP_S = 20.0
#: max |S''(tau)| on [0, 1]: bounds the roll rate of a turn (see :func:`turn_duration`).
SMOOTHSTEP_PEAK_ACCEL = 7.513188404

_GL_X, _GL_W = np.polynomial.legendre.leggauss(48)
_GL_X = 0.5 * (_GL_X + 1.0)  # nodes on [0, 1]
_GL_W = 0.5 * _GL_W


# --------------------------------------------------------------------------
# Smoothstep polynomials
# --------------------------------------------------------------------------


def smoothstep(tau):
    """Septic smoothstep ``S = 35 t^4 - 84 t^5 + 70 t^6 - 20 t^7`` and its derivatives.

    The first three derivatives vanish at both ends, so a turn built on it has a
    continuous heading rate, bank angle, roll rate and roll acceleration.

    Returns
    -------
    s, s1, s2, s3, integral : ndarray
        ``S`` and its first three derivatives, and ``int_0^tau S``.
    """
    t = np.asarray(tau, dtype=float)
    t2 = t * t
    t3 = t2 * t
    t4 = t2 * t2
    s = t4 * (35.0 - 84.0 * t + 70.0 * t2 - 20.0 * t3)
    s1 = 140.0 * t3 * (1.0 - t) ** 3
    s2 = 420.0 * t2 * (1.0 - t) ** 2 * (1.0 - 2.0 * t)
    s3 = 840.0 * t * (1.0 - 6.0 * t + 10.0 * t2 - 5.0 * t3)
    integ = t4 * t * (7.0 - 14.0 * t + 10.0 * t2 - 2.5 * t3)
    return s, s1, s2, s3, integ


# --------------------------------------------------------------------------
# Nominal plan
# --------------------------------------------------------------------------


@dataclass
class Segment:
    """One primitive of the nominal plan (map coordinates).

    Attributes
    ----------
    label : str
        Plan segment name (``L01``, ``T01``, ``turn``, ``static``).
    kind : str
        ``static``, ``ramp``, ``line``, ``turn`` or ``accel`` (straight, speed
        ``speed_from + (speed - speed_from) S(tau)``: a change of ground speed).
    t0, duration : float
        Start time (s after the flight start) and duration (s).
    x0, y0 : float
        Map position at the start, m.
    psi0 : float
        Heading at the start, rad clockwise from map north.
    speed : float
        Cruise speed, m/s (``ramp``: the speed at the fast end).
    delta : float
        ``turn``: heading change, rad (positive = right turn);
        ``ramp``: +1 accelerate from rest, -1 decelerate to rest.
    speed_from : float
        ``accel``: the speed at the start, m/s.
    """

    label: str
    kind: str
    t0: float
    duration: float
    x0: float
    y0: float
    psi0: float
    speed: float = 0.0
    delta: float = 0.0
    speed_from: float = 0.0

    def end_state(self):
        """(x, y, psi) at the end of the segment."""
        k = evaluate_segment(self, np.array([self.t0 + self.duration]))
        return float(k["x"][0, 0]), float(k["x"][0, 1]), float(k["psi"][0, 0])


def _turn_integral(psi0, delta, tau):
    """int_0^tau (sin, cos)(psi0 + delta S(u)) du for arrays, by Gauss-Legendre."""
    tau = np.asarray(tau, dtype=float)
    u = tau[..., None] * _GL_X
    s = smoothstep(u)[0]
    ang = np.asarray(psi0)[..., None] + np.asarray(delta)[..., None] * s
    w = tau[..., None] * _GL_W
    return (np.sin(ang) * w).sum(-1), (np.cos(ang) * w).sum(-1)


def turn_duration(delta, speed, max_rate, max_roll_rate=math.inf):
    """Duration (s) of a smoothstep turn by ``delta`` rad at ``speed`` m/s.

    The longer of ``2.1875 |delta| / max_rate`` (peak heading rate = ``max_rate``
    rad/s, i.e. peak bank ``atan(v max_rate / g0)``) and
    ``sqrt(v |delta| 7.513 / (g0 max_roll_rate))`` (peak roll rate
    ``d/dt atan(v psi'/g0) <= v psi''/g0 <= max_roll_rate`` rad/s).
    """
    a = np.abs(np.asarray(delta, dtype=float))
    t_rate = SMOOTHSTEP_PEAK_RATE * a / max_rate
    t_roll = np.sqrt(speed * a * SMOOTHSTEP_PEAK_ACCEL / (G0_BANK * max_roll_rate))
    return np.maximum(t_rate, t_roll)


def turn_displacement(psi0, delta, speed, max_rate, max_roll_rate=math.inf):
    """Map displacement (dx, dy) in m of a smoothstep turn; arrays broadcast.

    Duration from :func:`turn_duration`.  Returns ``(dx, dy, T)``.
    """
    delta = np.asarray(delta, dtype=float)
    dur = turn_duration(delta, speed, max_rate, max_roll_rate)
    ix, iy = _turn_integral(np.broadcast_to(psi0, delta.shape), delta, np.ones_like(delta))
    return speed * dur * ix, speed * dur * iy, dur


def evaluate_segment(seg: Segment, t):
    """Map kinematics of one segment at times ``t`` (s, within the segment).

    Returns
    -------
    dict with ``x`` (n, 2) map east/north (m) and ``x1``, ``x2``, ``x3`` its
    first three time derivatives; ``psi`` (n, 3): heading and its first two
    derivatives; ``speed`` (n, 2): plan speed and its derivative.
    """
    t = np.asarray(t, dtype=float)
    n = t.shape[0]
    tau = (t - seg.t0) / seg.duration if seg.duration > 0 else np.zeros(n)
    tau = np.clip(tau, 0.0, 1.0)
    T = seg.duration
    out = {k: np.zeros((n, 2)) for k in ("x", "x1", "x2", "x3")}
    psi = np.zeros((n, 3))
    spd = np.zeros((n, 2))
    psi[:, 0] = seg.psi0
    if seg.kind in ("static", "line", "ramp", "accel"):
        if seg.kind == "static":
            s0 = s1 = s2 = s3 = np.zeros(n)
        elif seg.kind == "line":
            s0 = seg.speed * (t - seg.t0)
            s1 = np.full(n, seg.speed)
            s2 = s3 = np.zeros(n)
        elif seg.kind == "accel":
            ss, ss1, ss2, ss3, si = smoothstep(tau)
            v0, dv = seg.speed_from, seg.speed - seg.speed_from
            s0 = v0 * T * tau + dv * T * si
            s1, s2, s3 = v0 + dv * ss, dv * ss1 / T, dv * ss2 / T**2
        else:
            ss, ss1, ss2, ss3, si = smoothstep(tau)
            v = seg.speed
            if seg.delta > 0:  # accelerate: speed v S(tau)
                s0, s1, s2, s3 = v * T * si, v * ss, v * ss1 / T, v * ss2 / T**2
            else:  # decelerate: speed v (1 - S(tau))
                s0 = v * T * (tau - si)
                s1, s2, s3 = v * (1.0 - ss), -v * ss1 / T, -v * ss2 / T**2
        spd[:, 0], spd[:, 1] = s1, s2
        e = _unit(seg.psi0)
        out["x"] = np.array([seg.x0, seg.y0]) + s0[:, None] * e
        out["x1"] = s1[:, None] * e
        out["x2"] = s2[:, None] * e
        out["x3"] = s3[:, None] * e
    elif seg.kind == "turn":
        v = seg.speed
        ss, ss1, ss2, ss3, _ = smoothstep(tau)
        p = seg.psi0 + seg.delta * ss
        p1 = seg.delta * ss1 / T
        p2 = seg.delta * ss2 / T**2
        ix, iy = _turn_integral(seg.psi0, seg.delta, tau)
        sp, cp = np.sin(p), np.cos(p)
        out["x"][:, 0] = seg.x0 + v * T * ix
        out["x"][:, 1] = seg.y0 + v * T * iy
        out["x1"][:, 0], out["x1"][:, 1] = v * sp, v * cp
        out["x2"][:, 0], out["x2"][:, 1] = v * cp * p1, -v * sp * p1
        out["x3"][:, 0] = -v * sp * p1**2 + v * cp * p2
        out["x3"][:, 1] = -v * cp * p1**2 - v * sp * p2
        psi[:, 0], psi[:, 1], psi[:, 2] = p, p1, p2
        spd[:, 0] = v
    else:  # pragma: no cover - constructed internally only
        raise ValueError(seg.kind)
    out["psi"] = psi
    out["speed"] = spd
    return out


@dataclass
class AltitudeStep:
    """Height change from ``h_from`` to ``h_to`` over [t0, t0 + duration]: a smoothstep, or
    with ``ramp_s`` > 0 a climb (descent) at a steady rate entered and left by smoothstep
    changes of the rate lasting ``ramp_s`` each (an aircraft's climb after take-off)."""

    t0: float
    duration: float
    h_from: float
    h_to: float
    ramp_s: float = 0.0


@dataclass
class Turbulence:
    """Sums of sinusoids: ``amp[a, k] sin(omega[a, k] t + phase[a, k])``.

    Axis ``a``: 0 map east (m), 1 map north (m), 2 height (m), 3 roll, 4 pitch,
    5 heading (rad).
    """

    amp: np.ndarray
    omega: np.ndarray
    phase: np.ndarray

    @property
    def active(self) -> bool:
        return bool(np.any(self.amp != 0.0))


def turbulence_components(rng, n_comp, sigma, corner_period_s, min_period_s, max_period_s):
    """Amplitudes, angular frequencies and phases of one turbulence axis.

    Frequencies are log-spaced between ``1/max_period_s`` and ``1/min_period_s``
    (jittered by the RNG); the displacement power spectrum is
    ``P(f) ~ 1 / (1 + (f/fc)^2)^2`` (the displacement of a first-order
    low-passed, Dryden-like velocity), normalised so the standard deviation is
    ``sigma``.
    """
    fl, fh = 1.0 / max_period_s, 1.0 / min_period_s
    edges = np.geomspace(fl, fh, n_comp + 1)
    jitter = rng.uniform(0.0, 1.0, n_comp)
    f = edges[:-1] * (edges[1:] / edges[:-1]) ** jitter
    df = np.diff(edges)
    fc = 1.0 / corner_period_s
    p = 1.0 / (1.0 + (f / fc) ** 2) ** 2
    amp = np.sqrt(2.0 * p * df)
    if sigma > 0:
        amp *= sigma / math.sqrt(0.5 * np.sum(amp**2))
    else:
        amp[:] = 0.0
    phase = rng.uniform(0.0, 2.0 * math.pi, n_comp)
    return amp, 2.0 * math.pi * f, phase


@dataclass
class FlightPlan:
    """A complete nominal plan plus turbulence, with the map-to-geodetic constants.

    Attributes
    ----------
    segments : list of Segment
        Contiguous in time, the first starting at ``t = 0``.
    altitude_steps : list of AltitudeStep
    h_start : float
        Height before the first altitude step, m.
    lat0, lon0 : float
        Map origin, rad.
    rm, rp : float
        Map scales: ``lat = lat0 + y / rm``, ``lon = lon0 + x / rp``.
    turbulence : Turbulence
    envelope : tuple
        ``(t_up0, t_up1, t_down0, t_down1)``: turbulence rises by smoothstep on
        [t_up0, t_up1] and falls on [t_down0, t_down1] (s).
    wind_en : tuple
        Steady wind velocity (map east, north), m/s, the air's motion over the ground (a wind
        *from* the west is ``(+w, 0)``); faded in and out with the turbulence envelope.  The
        aircraft holds the plan's ground track and points its nose along its air velocity
        (:func:`crab_attitude`).
    """

    segments: list
    altitude_steps: list
    h_start: float
    lat0: float
    lon0: float
    rm: float
    rp: float
    turbulence: Turbulence
    envelope: tuple = (-math.inf, -math.inf, math.inf, math.inf)
    ellipsoid: Ellipsoid = field(default=WGS84)
    wind_en: tuple = (0.0, 0.0)

    @property
    def duration(self) -> float:
        s = self.segments[-1]
        return s.t0 + s.duration


def map_scales(lat0, h0, ellipsoid: Ellipsoid = WGS84):
    """``(rm, rp)``: metres of map north per radian of latitude, east per radian of longitude."""
    w = math.sqrt(1.0 - ellipsoid.e2 * math.sin(lat0) ** 2)
    m = ellipsoid.a * (1.0 - ellipsoid.e2) / w**3
    nn = ellipsoid.a / w
    return m + h0, (nn + h0) * math.cos(lat0)


# --------------------------------------------------------------------------
# Evaluation
# --------------------------------------------------------------------------


def sinusum_reference(t, amp, omega, phase, chunk=16384):
    """Sum of sinusoids and its first three derivatives at times t; (4, n). Pure numpy."""
    n = t.shape[0]
    out = np.zeros((4, n))
    for i in range(0, n, chunk):
        arg = t[i : i + chunk, None] * omega + phase
        s, c = np.sin(arg), np.cos(arg)
        out[0, i : i + chunk] = s @ amp
        out[1, i : i + chunk] = c @ (amp * omega)
        out[2, i : i + chunk] = -(s @ (amp * omega**2))
        out[3, i : i + chunk] = -(c @ (amp * omega**3))
    return out


@njit(cache=True)
def _sinusum_kernel(t, amp, omega, phase, out):
    for i in range(t.shape[0]):
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        s3 = 0.0
        for k in range(amp.shape[0]):
            w = omega[k]
            arg = t[i] * w + phase[k]
            s = math.sin(arg) * amp[k]
            c = math.cos(arg) * amp[k]
            s0 += s
            s1 += c * w
            s2 -= s * w * w
            s3 -= c * w * w * w
        out[0, i] = s0
        out[1, i] = s1
        out[2, i] = s2
        out[3, i] = s3


def _sinusum(t, amp, omega, phase):
    """Compiled :func:`sinusum_reference` (components with zero amplitude skipped)."""
    out = np.zeros((4, t.shape[0]))
    keep = amp != 0.0
    if np.any(keep):
        _sinusum_kernel(
            np.ascontiguousarray(t, dtype=float), amp[keep].copy(), omega[keep].copy(), phase[keep].copy(), out
        )
    return out


def _envelope(t, env):
    """Turbulence envelope and its first three derivatives; (4, n).

    ``env = (u0, u1, d0, d1)``: 0 before ``u0``, smoothstep up to 1 on
    [u0, u1], 1 until ``d0``, smoothstep down to 0 on [d0, d1].  ``u0 = -inf``
    means no ramp up (1 from the start), ``d0 = inf`` no ramp down.
    """
    u0, u1, d0, d1 = env
    out = np.zeros((4, t.shape[0]))
    out[0] = 1.0
    for a, b, sign in ((u0, u1, 1.0), (d0, d1, -1.0)):
        if not math.isfinite(a):
            continue
        T = b - a
        tau = np.clip((t - a) / T, 0.0, 1.0)
        s, s1, s2, s3, _ = smoothstep(tau)
        if sign > 0:
            f = np.array([s, s1 / T, s2 / T**2, s3 / T**3])
        else:
            f = np.array([1.0 - s, -s1 / T, -s2 / T**2, -s3 / T**3])
        inside = (t > a) & (t < b)
        f[1:, ~inside] = 0.0
        out = _times_envelope(out, f)
    return out


def _times_envelope(e, s):
    """Leibniz product of envelope derivatives ``e`` (4, n) and signal ``s`` (4, n)."""
    return np.array(
        [
            e[0] * s[0],
            e[1] * s[0] + e[0] * s[1],
            e[2] * s[0] + 2 * e[1] * s[1] + e[0] * s[2],
            e[3] * s[0] + 3 * e[2] * s[1] + 3 * e[1] * s[2] + e[0] * s[3],
        ]
    )


def _altitude(t, plan: FlightPlan):
    """Nominal height and its first three derivatives; (4, n)."""
    out = np.zeros((4, t.shape[0]))
    out[0] = plan.h_start
    for st in plan.altitude_steps:
        if st.ramp_s > 0.0:
            out += steady_climb_profile(t, st)
            continue
        tau = np.clip((t - st.t0) / st.duration, 0.0, 1.0)
        s, s1, s2, s3, _ = smoothstep(tau)
        dh = st.h_to - st.h_from
        T = st.duration
        inside = (t > st.t0) & (t < st.t0 + T)
        out[0] += dh * s
        out[1] += np.where(inside, dh * s1 / T, 0.0)
        out[2] += np.where(inside, dh * s2 / T**2, 0.0)
        out[3] += np.where(inside, dh * s3 / T**3, 0.0)
    return out


def steady_climb_profile(t, st: AltitudeStep):
    """Height change of a steady climb (:class:`AltitudeStep` with ``ramp_s``) and its first
    three derivatives; (4, n).  The rate ``c = dh / (duration - ramp_s)`` is reached and left
    by smoothsteps of ``ramp_s``."""
    r, T = st.ramp_s, st.duration
    c = (st.h_to - st.h_from) / (T - r)
    tau = np.clip(t - st.t0, 0.0, T)
    out = np.zeros((4, t.shape[0]))
    up = tau < r
    down = tau > T - r
    mid = ~up & ~down
    s, s1, s2, _, si = smoothstep(tau[up] / r)
    out[:, up] = [c * r * si, c * s, c * s1 / r, c * s2 / r**2]
    out[0, mid] = c * (0.5 * r + tau[mid] - r)
    out[1, mid] = c
    u = (tau[down] - (T - r)) / r
    s, s1, s2, _, si = smoothstep(u)
    out[:, down] = [c * (0.5 * r + T - 2.0 * r + r * (u - si)), c * (1.0 - s), -c * s1 / r, -c * s2 / r**2]
    # before and after the climb the height holds (the derivatives vanish there)
    out[1:, (t <= st.t0) | (t >= st.t0 + T)] = 0.0
    return out


def segment_index(plan: FlightPlan, t):
    """Index of the plan segment containing each time ``t``."""
    starts = np.array([s.t0 for s in plan.segments])
    return np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(starts) - 1)


def evaluate_plan(plan: FlightPlan, t):
    """Map kinematics (nominal + turbulence) and attitude angles at times ``t``.

    Parameters
    ----------
    plan : FlightPlan
    t : ndarray, shape (n,)
        Seconds after the flight start.

    Returns
    -------
    dict
        ``xy`` (4, n, 2) map east/north and derivatives (m, m/s, m/s^2, m/s^3);
        ``h`` (4, n) height and derivatives; ``att`` (3, 2, n): roll, pitch,
        heading (rad) and their rates (rad/s); ``label`` (n,) segment labels.
    """
    t = np.asarray(t, dtype=float)
    n = t.shape[0]
    idx = segment_index(plan, t)
    xy = np.zeros((4, n, 2))
    psi = np.zeros((3, n))
    spd = np.zeros((2, n))
    for k, seg in enumerate(plan.segments):
        m = idx == k
        if not np.any(m):
            continue
        r = evaluate_segment(seg, t[m])
        for j, key in enumerate(("x", "x1", "x2", "x3")):
            xy[j, m] = r[key]
        psi[:, m] = r["psi"].T
        spd[:, m] = r["speed"].T
    h = _altitude(t, plan)

    # nominal coordinated-flight attitude
    v, vd = spd
    u = v * psi[1]  # centripetal acceleration of the plan, m/s^2
    ud = vd * psi[1] + v * psi[2]
    roll = np.arctan(u / G0_BANK)
    roll_d = ud / G0_BANK / (1.0 + (u / G0_BANK) ** 2)
    safe_v = np.where(v > 0, v, 1.0)
    pitch = np.where(v > 0, np.arctan2(h[1], safe_v), 0.0)
    pitch_d = np.where(v > 0, (h[2] * v - h[1] * vd) / (safe_v**2 + h[1] ** 2), 0.0)
    heading, heading_d = psi[0], psi[1]
    tb = plan.turbulence
    windy = plan.wind_en[0] != 0.0 or plan.wind_en[1] != 0.0
    # the wind and the turbulence fade in and out with the same envelope
    env = _envelope(t, plan.envelope) if windy or tb.active else None
    if windy:
        roll, roll_d, heading, heading_d = crab_attitude(xy, psi[0], env, plan.wind_en, _moving_speed(plan)[idx])
    att = np.array([[roll, roll_d], [pitch, pitch_d], [heading, heading_d]])

    if tb.active:
        for a in range(6):
            s = _times_envelope(env, _sinusum(t, tb.amp[a], tb.omega[a], tb.phase[a]))
            if a < 2:
                xy[:, :, a] += s
            elif a == 2:
                h += s
            else:
                att[a - 3, 0] += s[0]
                att[a - 3, 1] += s[1]
    labels = np.array([s.label for s in plan.segments], dtype=object)[idx]
    return {"xy": xy, "h": h, "att": att, "label": labels}


def _moving_speed(plan: FlightPlan):
    """Per segment, its speed (m/s); a hold's is that of the ramp next to it."""
    segs = plan.segments
    out = np.array([seg.speed for seg in segs])
    for k, seg in enumerate(segs):
        if seg.kind == "static":
            near = segs[k + 1] if k + 1 < len(segs) else segs[k - 1] if k > 0 else seg
            out[k] = near.speed
    return out


def crab_attitude(xy, track, env, wind_en, cruise_speed):
    """Heading and coordinated-turn bank of an aircraft flying the plan's ground track in a wind.

    The aircraft flies the nominal ground track at the nominal ground speed ``v``; its nose
    points along its velocity through the air, ``v_air = v_ground - w``, so on a line in a
    crosswind the heading differs from the track by the crab angle ``atan2(-w_cross, v -
    w_along)`` (``w_cross`` the wind's component to the right of the track).  The bank is that
    of a coordinated turn through the air mass, ``atan(a_lat / g0)`` with ``a_lat = |v_air|
    psi_air'`` (zero on straight lines in a steady wind).

    Parameters
    ----------
    xy : ndarray, shape (4, n, 2)
        Nominal map position (east, north) and its first three derivatives (m, m/s, m/s^2,
        m/s^3), before turbulence.
    track : ndarray, shape (n,)
        Plan heading (the ground track), rad clockwise from map north.
    env : ndarray, shape (4, n)
        Wind envelope and its first three derivatives (the turbulence envelope: 0 at rest).
    wind_en : tuple of float
        Wind velocity (map east, north), m/s.
    cruise_speed : float or ndarray, shape (n,)
        Speed of the ramp next to a hold, m/s: at rest (where the wind is faded out) the nose is
        where it will be when the speed ramp starts, the crab of ``cruise_speed`` along
        ``track`` (during a ramp the air velocity scales as the ground speed does, its
        direction fixed).

    Returns
    -------
    roll, roll_rate, heading, heading_rate : ndarray, shape (n,)
        rad and rad/s; the heading continuous with ``track`` (``track`` plus the crab angle).
    """
    w = np.asarray(wind_en, dtype=float)
    air = xy[1] - env[0][:, None] * w
    air1 = xy[2] - env[1][:, None] * w
    air2 = xy[3] - env[2][:, None] * w
    st, ct = np.sin(track), np.cos(track)
    d2 = np.einsum("ni,ni->n", air, air)
    moving = d2 > 0.0
    ax = np.where(moving, air[:, 0], cruise_speed * st - w[0])
    ay = np.where(moving, air[:, 1], cruise_speed * ct - w[1])
    crab = np.arctan2(ax * ct - ay * st, ax * st + ay * ct)  # the air velocity's angle from the track
    safe = np.where(moving, d2, 1.0)
    speed = np.sqrt(safe)
    # |v_air|^2 psi_air' and its derivative (the air1 x air1 terms cancel)
    num = air[:, 1] * air1[:, 0] - air[:, 0] * air1[:, 1]
    num1 = air[:, 1] * air2[:, 0] - air[:, 0] * air2[:, 1]
    dot = np.einsum("ni,ni->n", air, air1)
    heading_d = np.where(moving, num / safe, 0.0)
    u = np.where(moving, num / speed, 0.0)
    ud = np.where(moving, num1 / speed - num * dot / speed**3, 0.0)
    roll = np.arctan(u / G0_BANK)
    roll_d = ud / G0_BANK / (1.0 + (u / G0_BANK) ** 2)
    return roll, roll_d, track + crab, heading_d


# --------------------------------------------------------------------------
# Geodetic kinematics
# --------------------------------------------------------------------------


def geodetic_kinematics(lat, lat1, lat2, lon1, lon2, h, h1, h2, ellipsoid: Ellipsoid = WGS84):
    """Exact ENU velocity and acceleration from geodetic coordinates and derivatives.

    With ``M``, ``N`` the meridian and prime-vertical radii,

    ``v = ((N+h) cos(lat) lon', (M+h) lat', h')`` and ``v' = d v / dt`` by the
    chain rule (``dN/dlat = a e^2 sin cos / W^3``, ``dM/dlat = 3 a (1-e^2) e^2
    sin cos / W^5``).  The acceleration relative to the Earth resolved on ENU is
    ``v' + w_en x v`` with the transport rate ``w_en = (-lat', lon' cos(lat),
    lon' sin(lat))``.

    Parameters
    ----------
    lat : ndarray (n,)
        Geodetic latitude, rad; ``lat1``, ``lat2`` its first two derivatives
        (rad/s, rad/s^2); ``lon1``, ``lon2`` likewise for longitude; ``h``,
        ``h1``, ``h2`` ellipsoidal height (m) and derivatives.

    Returns
    -------
    vel_n : ndarray (n, 3)
        Velocity relative to the Earth, ENU, m/s.
    acc_n : ndarray (n, 3)
        Acceleration relative to the Earth (second derivative of the ECEF
        position) resolved on ENU, m/s^2.
    w_en : ndarray (n, 3)
        Transport rate (angular rate of ENU w.r.t. ECEF) on ENU, rad/s.
    """
    a, e2 = ellipsoid.a, ellipsoid.e2
    s, c = np.sin(lat), np.cos(lat)
    w = np.sqrt(1.0 - e2 * s * s)
    nn = a / w
    mm = a * (1.0 - e2) / w**3
    dn = a * e2 * s * c / w**3
    dm = 3.0 * a * (1.0 - e2) * e2 * s * c / w**5
    ve = (nn + h) * c * lon1
    vn = (mm + h) * lat1
    vu = h1
    ved = (dn * lat1 + h1) * c * lon1 - (nn + h) * s * lat1 * lon1 + (nn + h) * c * lon2
    vnd = (dm * lat1 + h1) * lat1 + (mm + h) * lat2
    vud = h2
    vel = np.stack([ve, vn, vu], axis=-1)
    w_en = np.stack([-lat1, lon1 * c, lon1 * s], axis=-1)
    acc = np.stack([ved, vnd, vud], axis=-1) + np.cross(w_en, vel)
    return vel, acc, w_en


def euler_to_mat_nb(roll, pitch, heading):
    """Body (x fwd, y left, z up) -> ENU rotation matrices, ``(n, 3, 3)``.

    ``mat_nb = Rz(pi/2 - heading) @ Ry(-pitch) @ Rx(roll)`` with ``R*`` the
    right-handed elementary rotations about the ENU/body axes.
    """
    return _rz(0.5 * np.pi - heading) @ _ry(-pitch) @ _rx(roll)


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    m = np.zeros(np.shape(a) + (3, 3))
    m[..., 0, 0] = 1.0
    m[..., 1, 1], m[..., 1, 2], m[..., 2, 1], m[..., 2, 2] = c, -s, s, c
    return m


def _ry(a):
    c, s = np.cos(a), np.sin(a)
    m = np.zeros(np.shape(a) + (3, 3))
    m[..., 1, 1] = 1.0
    m[..., 0, 0], m[..., 0, 2], m[..., 2, 0], m[..., 2, 2] = c, s, -s, c
    return m


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    m = np.zeros(np.shape(a) + (3, 3))
    m[..., 2, 2] = 1.0
    m[..., 0, 0], m[..., 0, 1], m[..., 1, 0], m[..., 1, 1] = c, -s, s, c
    return m


def _skew_z():
    k = np.zeros((3, 3))
    k[0, 1], k[1, 0] = -1.0, 1.0
    return k


def body_rate_nb(roll, pitch, heading, roll_d, pitch_d, heading_d):
    """Angular rate of the body w.r.t. ENU, resolved on the body, ``(n, 3)`` rad/s.

    From ``mat_nb = A B C`` (``A = Rz(pi/2 - psi)``, ``B = Ry(-theta)``,
    ``C = Rx(phi)``): ``w_nb^b = C^T B^T (-psi' e_z) + C^T (-theta' e_y) +
    phi' e_x``.
    """
    n = np.shape(roll)[0]
    c = _rx(roll)
    b = _ry(-pitch)
    ez = np.zeros((n, 3))
    ez[:, 2] = -heading_d
    ey = np.zeros((n, 3))
    ey[:, 1] = -pitch_d
    w = np.einsum("nji,nj->ni", c, np.einsum("nji,nj->ni", b, ez) + ey)
    w[:, 0] += roll_d
    return w


@dataclass
class Kinematics:
    """Exact kinematic truth at a set of times.

    All arrays have leading dimension n.  ``lat``, ``lon`` rad; ``height`` m;
    ``r_e`` (n, 3) ECEF m; ``vel_n``, ``acc_n`` (n, 3) Earth-relative ENU
    velocity (m/s) and acceleration (m/s^2); ``w_en`` (n, 3) transport rate
    (rad/s); ``roll``, ``pitch``, ``heading`` rad and their rates (rad/s);
    ``mat_nb`` (n, 3, 3) body -> ENU; ``w_nb_b`` (n, 3) body rate w.r.t. ENU on
    the body axes; ``att_rates`` (n, 3) roll, pitch, heading rates (rad/s);
    ``label`` (n,) segment names.
    """

    t: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    height: np.ndarray
    r_e: np.ndarray
    vel_n: np.ndarray
    acc_n: np.ndarray
    w_en: np.ndarray
    roll: np.ndarray
    pitch: np.ndarray
    heading: np.ndarray
    att_rates: np.ndarray
    mat_nb: np.ndarray
    w_nb_b: np.ndarray
    label: np.ndarray


def kinematics(plan: FlightPlan, t) -> Kinematics:
    """Evaluate the exact kinematic truth of ``plan`` at times ``t`` (s)."""
    t = np.asarray(t, dtype=float)
    ev = evaluate_plan(plan, t)
    xy, hh = ev["xy"], ev["h"]
    lat = plan.lat0 + xy[0, :, 1] / plan.rm
    lon = plan.lon0 + xy[0, :, 0] / plan.rp
    vel, acc, w_en = geodetic_kinematics(
        lat,
        xy[1, :, 1] / plan.rm,
        xy[2, :, 1] / plan.rm,
        xy[1, :, 0] / plan.rp,
        xy[2, :, 0] / plan.rp,
        hh[0],
        hh[1],
        hh[2],
        plan.ellipsoid,
    )
    r_e = geodetic_to_ecef(lat, lon, hh[0], plan.ellipsoid)
    att = ev["att"]
    roll, pitch, heading = att[0, 0], att[1, 0], att[2, 0]
    mat_nb = euler_to_mat_nb(roll, pitch, heading)
    w_nb = body_rate_nb(roll, pitch, heading, att[0, 1], att[1, 1], att[2, 1])
    return Kinematics(
        t=t,
        lat=lat,
        lon=lon,
        height=hh[0].copy(),
        r_e=r_e,
        vel_n=vel,
        acc_n=acc,
        w_en=w_en,
        roll=roll,
        pitch=pitch,
        heading=np.mod(heading, 2.0 * np.pi),
        att_rates=np.stack([att[0, 1], att[1, 1], att[2, 1]], axis=-1),
        mat_nb=mat_nb,
        w_nb_b=w_nb,
        label=ev["label"],
    )


def earth_rate_n(lat, omega: float = OMEGA_E):
    """Earth rotation rate on ENU, ``(n, 3)`` rad/s: ``(0, W cos lat, W sin lat)``."""
    lat = np.asarray(lat, dtype=float)
    return np.stack([np.zeros_like(lat), omega * np.cos(lat), omega * np.sin(lat)], axis=-1)


def mat_ne(lat, lon):
    """ECEF -> ENU rotation matrices, ``(n, 3, 3)``."""
    return np.swapaxes(mat_en(lat, lon), -1, -2)


# --------------------------------------------------------------------------
# Plan construction
# --------------------------------------------------------------------------

#: Largest north-south distance (m) of any planned point from the map origin:
#: keeps the flat map's scale distortion below ~10 % at 60 deg latitude.
MAP_MAX_NORTH_SOUTH_M = 500_000.0
#: Largest east-west distance (m) of any planned point from the map origin.
MAP_MAX_EAST_WEST_M = 3_000_000.0


def _unit(psi):
    """Map unit vector of heading ``psi``; exact zeros for the cardinal headings."""
    e = np.array([math.sin(psi), math.cos(psi)])
    e[np.abs(e) < 1e-15] = 0.0
    return e


def _wrap_dir(angle, sign):
    """Angle in [0, 2 pi) travelled in direction ``sign`` (+1 right/clockwise)."""
    return sign * np.mod(sign * angle, 2.0 * np.pi)


def connector(p, psi_a, q, psi_b, speed, max_rate, min_duration=0.0, step_m=None, max_roll_rate=math.inf):
    """Turn - straight - turn - run-in path from ``p`` (heading ``psi_a``) to ``q`` (heading ``psi_b``).

    Searches the middle heading ``psi_m`` for the four turn-direction
    combinations such that the residual after both smoothstep turns is a
    non-negative straight leg along ``psi_m``; takes the shortest.  If none
    exists (target too close), a straight run-in ending at ``q`` is added and
    lengthened in steps of ``step_m`` until one does.

    Returns
    -------
    list of (kind, value) with kind ``turn`` (value = heading change, rad) or
    ``line`` (value = length, m), in flying order.
    """
    from scipy.optimize import brentq

    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    radius = speed / max_rate
    step = step_m if step_m is not None else radius
    if step_m is None and speed * min_duration > 150.0 * step:
        # a long least duration (a slow climb from an airfield) needs a longer run-in than the
        # search's 200 steps of one turn radius reach
        step = speed * min_duration / 150.0
    grid = np.linspace(0.0, 2.0 * np.pi, 361)
    eb = _unit(psi_b)

    def parts(psi_m, s1, s2, target):
        d1 = _wrap_dir(psi_m - psi_a, s1)
        d2 = _wrap_dir(psi_b - psi_m, s2)
        x1, y1, t1 = turn_displacement(psi_a, d1, speed, max_rate, max_roll_rate)
        x2, y2, t2 = turn_displacement(psi_m, d2, speed, max_rate, max_roll_rate)
        rx = target[0] - p[0] - x1 - x2
        ry = target[1] - p[1] - y1 - y2
        along = rx * np.sin(psi_m) + ry * np.cos(psi_m)
        cross = rx * np.cos(psi_m) - ry * np.sin(psi_m)
        return d1, d2, along, cross, t1 + t2

    best = None
    found_at = None
    for k in range(200):
        if found_at is not None and k > found_at + 4:
            break
        run_in = k * step
        target = q - run_in * eb
        for s1 in (1.0, -1.0):
            for s2 in (1.0, -1.0):
                d1, d2, along, cross, _ = parts(grid, s1, s2, target)
                sc = np.sign(cross)
                idx = np.nonzero(sc[:-1] * sc[1:] <= 0)[0]
                for i in idx:
                    # skip the jumps where a turn angle wraps
                    if abs(d1[i + 1] - d1[i]) > 1.0 or abs(d2[i + 1] - d2[i]) > 1.0:
                        continue
                    if cross[i] == 0.0:
                        pm = grid[i]
                    else:
                        pm = brentq(
                            lambda x: float(parts(np.array([x]), s1, s2, target)[3][0]),
                            grid[i],
                            grid[i + 1],
                            xtol=1e-15,
                            rtol=1e-15,
                            maxiter=200,
                        )
                    e1, e2, al, _, tt = parts(np.array([pm]), s1, s2, target)
                    if al[0] < 0.0:
                        continue
                    dur = float(tt[0]) + (float(al[0]) + run_in) / speed
                    if dur < min_duration:
                        continue
                    if best is None or dur < best[0]:
                        best = (dur, float(e1[0]), float(al[0]), float(e2[0]), run_in)
                        if found_at is None:
                            found_at = k
    if best is not None:
        _, d1, leg, d2, run_in = best
        out = []
        if abs(d1) > 1e-12:
            out.append(("turn", d1))
        if leg > 0.0:
            out.append(("line", leg))
        if abs(d2) > 1e-12:
            out.append(("turn", d2))
        if run_in > 0.0:
            out.append(("line", run_in))
        return out
    raise ConfigError(  # pragma: no cover - the run-in search always finds one
        "plan: no smooth turn path between two lines; increase the line spacing or max_bank_deg"
    )


class _PlanBuilder:
    """Appends segments keeping time, position and heading continuous."""

    def __init__(self, x, y, psi, speed, max_rate, max_roll_rate=math.inf):
        self.segments = []
        self.t = 0.0
        self.x, self.y, self.psi = x, y, psi
        self.speed = speed
        self.max_rate = max_rate
        self.max_roll_rate = max_roll_rate

    def add(self, label, kind, duration, speed=None, delta=0.0, speed_from=0.0):
        seg = Segment(
            label,
            kind,
            self.t,
            duration,
            self.x,
            self.y,
            self.psi,
            self.speed if speed is None else speed,
            delta,
            speed_from,
        )
        self.segments.append(seg)
        self.t += duration
        if kind == "turn":
            x, y, _ = seg.end_state()
            self.x, self.y = x, y
            self.psi = seg.psi0 + delta
        elif kind == "line":
            e = _unit(self.psi)
            self.x += seg.speed * duration * e[0]
            self.y += seg.speed * duration * e[1]
        elif kind in ("ramp", "accel"):
            # a smoothstep between two speeds covers their mean (a ramp's other speed is 0)
            e = _unit(self.psi)
            self.x += 0.5 * (seg.speed_from + seg.speed) * duration * e[0]
            self.y += 0.5 * (seg.speed_from + seg.speed) * duration * e[1]
        return seg

    def straight(self, label, length, speed=None):
        v = self.speed if speed is None else speed
        if length > 0.0:
            self.add(label, "line", length / v, speed=v)

    def change_speed(self, speed_from, speed_to):
        """A straight speed change (label ``turn``) at :data:`SPEED_CHANGE_MPS2` at most."""
        if speed_to != speed_from:
            self.add(
                "turn", "accel", speed_change_duration(speed_from, speed_to), speed=speed_to, speed_from=speed_from
            )

    def turn(self, label, delta):
        dur = float(turn_duration(delta, self.speed, self.max_rate, self.max_roll_rate))
        self.add(label, "turn", dur, delta=delta)

    def goto(self, q, psi_b, min_duration=0.0):
        """Connector to map point ``q`` arriving with heading ``psi_b``; returns its duration."""
        t0 = self.t
        for kind, val in connector(
            (self.x, self.y),
            self.psi,
            q,
            psi_b,
            self.speed,
            self.max_rate,
            min_duration=min_duration,
            max_roll_rate=self.max_roll_rate,
        ):
            if kind == "turn":
                self.turn("turn", val)
            else:
                self.straight("turn", val)
        # remove the few-nm closure error of the root finder
        self.x, self.y, self.psi = float(q[0]), float(q[1]), psi_b
        return self.t - t0


def grid_lines(plan_cfg):
    """Planned survey and tie lines of a ``grid`` plan on the map.

    Returns
    -------
    list of (label, start (2,), heading rad, length m, altitude m)
    """
    g = plan_cfg["lines"]
    psi = math.radians(g["heading_deg"])
    e, r = _unit(psi), _unit(psi + 0.5 * math.pi)
    n, d, length = g["count"], g["spacing_m"], g["length_m"]
    alt = plan_cfg["altitude_m"]
    # lines.altitudes_m: line i at altitudes_m[i % len] (a survey flown at several levels)
    alts = g.get("altitudes_m") or [alt]
    out = []
    for i in range(n):
        base = i * d * r
        h = alts[i % len(alts)]
        if i % 2 == 0:
            out.append((f"L{i + 1:02d}", base, psi, length, h))
        else:
            out.append((f"L{i + 1:02d}", base + length * e, psi + math.pi, length, h))
    ties = plan_cfg.get("ties") or {}
    m = ties.get("count", 0)
    if m and n > 1:
        ts = ties.get("spacing_m", 0.0)
        t_alt = ties.get("altitude_m", alt)
        offs = [0.5 * (length - (m - 1) * ts) + j * ts for j in range(m)]
        last_at_far_end = (n - 1) % 2 == 0
        order = list(range(m))[::-1] if last_at_far_end else list(range(m))
        tie_len = (n - 1) * d
        for k, j in enumerate(order):
            a = offs[j] * e
            if k % 2 == 0:  # from the last line back towards the first
                out.append((f"T{j + 1:02d}", a + tie_len * r, psi - 0.5 * math.pi, tie_len, t_alt))
            else:
                out.append((f"T{j + 1:02d}", a, psi + 0.5 * math.pi, tie_len, t_alt))
    return out


def plan_extent(plan_cfg):
    """Largest |map east| and |map north| (m) of the planned lines (excluding turns)."""
    pts = []
    if plan_cfg["kind"] == "line":
        psi = math.radians(plan_cfg["heading_deg"])
        length = plan_cfg["line_length_m"]
        pts = [np.zeros(2), length * _unit(psi)]
    else:
        for _, start, psi, length, _ in grid_lines(plan_cfg):
            pts += [start, start + length * _unit(psi)]
    p = np.abs(np.array(pts))
    return float(p[:, 0].max()), float(p[:, 1].max())


def build_plan(plan_cfg, turb_cfg, rng, ellipsoid: Ellipsoid = WGS84, min_period_floor_s=0.0) -> FlightPlan:
    """Build the :class:`FlightPlan` of a validated ``plan`` / ``turbulence`` config.

    Parameters
    ----------
    plan_cfg, turb_cfg : dict
        Validated mappings (see :mod:`gravsurvey.simulate.simconfig`); the line
        plan must carry ``line_length_m``.
    rng : numpy.random.Generator
        Used for the turbulence phases and frequency jitter only.
    """
    v = plan_cfg["speed_mps"]
    wind = wind_velocity_en(plan_cfg.get("wind_speed_mps", 0.0), plan_cfg.get("wind_from_deg", 0.0))
    at_airspeed = plan_cfg.get("hold_speed", "air") == "air"

    def line_speed(psi):
        # ground speed of a line flown at airspeed v: the wind triangle
        if not at_airspeed or wind == (0.0, 0.0):
            return v
        return ground_speed_at_airspeed(v, psi, wind)

    max_rate = G0_BANK * math.tan(math.radians(plan_cfg["max_bank_deg"])) / v
    alt = plan_cfg["altitude_m"]
    climb = plan_cfg["max_climb_rate_mps"]
    ramp = plan_cfg["ramp_s"]
    if plan_cfg["kind"] == "line":
        psi = math.radians(plan_cfg["heading_deg"])
        lines = [("L01", np.zeros(2), psi, plan_cfg["line_length_m"], alt)]
    else:
        lines = grid_lines(plan_cfg)
    _, start, psi0, _, h0 = lines[0]
    v_first, v_last = line_speed(psi0), line_speed(lines[-1][2])
    ground = plan_cfg.get("ground_height_m")
    # parked on the ground: take off at v, climb on the way to the first line, descend after the last
    from_ground = ground is not None and plan_cfg["static_start_s"] > 0
    to_ground = ground is not None and plan_cfg["static_end_s"] > 0
    v_up = v if from_ground else v_first
    pre = start - (0.5 * v_up * ramp * _unit(psi0) if plan_cfg["static_start_s"] > 0 else 0.0)
    b = _PlanBuilder(float(pre[0]), float(pre[1]), psi0, v, max_rate, math.radians(plan_cfg["max_roll_rate_degps"]))
    env_up = (-math.inf, -math.inf)
    if plan_cfg["static_start_s"] > 0:
        b.add("static", "static", plan_cfg["static_start_s"], speed=0.0)
        t_up = b.t
        b.add("turn", "ramp", ramp, delta=1.0, speed=v_up)
        env_up = (t_up, b.t)
        b.x, b.y = float(start[0]), float(start[1])
    steps = []
    h_prev = ground if from_ground else h0
    for k, (label, st, psi, length, h) in enumerate(lines):
        v_line = line_speed(psi)
        if k > 0 or from_ground:
            if k == 0:  # the take-off climb, at a steady rate from the end of the take-off run
                need = steady_climb_duration(h - h_prev, climb)
            else:
                need = 0.0 if h == h_prev else SMOOTHSTEP_PEAK_RATE * abs(h - h_prev) / climb
            t0 = b.t
            # the connector (at v) ends where the speed change to the line's speed starts
            run_in = 0.5 * (v + v_line) * speed_change_duration(v, v_line) if v_line != v else 0.0
            dur = b.goto(st - run_in * _unit(psi), psi, min_duration=need)
            if k == 0 and h != h_prev:
                steps.append(AltitudeStep(t0, need, h_prev, h, ramp_s=CLIMB_RAMP_S))
            elif h != h_prev:
                steps.append(AltitudeStep(t0, dur, h_prev, h))
            b.change_speed(v, v_line)
            b.x, b.y = float(st[0]), float(st[1])  # the speed change's rounding (nm)
        b.straight(label, length, speed=v_line)
        if k < len(lines) - 1 or to_ground:
            b.change_speed(v_line, v)
        h_prev = h
    if to_ground:
        # a loop back over the last line's end, descending at a steady rate at its end, then the
        # landing run along it
        need = steady_climb_duration(ground - h_prev, climb)
        t0 = b.t
        dur = b.goto((b.x, b.y), b.psi, min_duration=need)
        if ground != h_prev:
            steps.append(AltitudeStep(t0 + dur - need, need, h_prev, ground, ramp_s=CLIMB_RAMP_S))
    env_down = (math.inf, math.inf)
    if plan_cfg["static_end_s"] > 0:
        t_dn = b.t
        b.add("turn", "ramp", ramp, delta=-1.0, speed=v if to_ground else v_last)
        env_down = (t_dn, b.t)
        b.add("static", "static", plan_cfg["static_end_s"], speed=0.0)
    lat0 = math.radians(plan_cfg["origin_lat_deg"])
    lon0 = math.radians(plan_cfg["origin_lon_deg"])
    rm, rp = map_scales(lat0, h0, ellipsoid)

    tc = turb_cfg
    amp = np.zeros((6, tc["components"]))
    omg = np.zeros_like(amp)
    phs = np.zeros_like(amp)
    sig = [tc["horizontal_sigma_m"], tc["horizontal_sigma_m"], tc["vertical_sigma_m"]] + [
        math.radians(tc["attitude_sigma_deg"])
    ] * 3
    for a in range(6):
        amp[a], omg[a], phs[a] = turbulence_components(
            rng, tc["components"], sig[a], tc["corner_period_s"], tc["min_period_s"], tc["max_period_s"]
        )
    return FlightPlan(
        segments=b.segments,
        altitude_steps=steps,
        h_start=ground if from_ground else h0,
        lat0=lat0,
        lon0=lon0,
        rm=rm,
        rp=rp,
        turbulence=Turbulence(amp, omg, phs),
        envelope=(env_up[0], env_up[1], env_down[0], env_down[1]),
        ellipsoid=ellipsoid,
        wind_en=wind,
    )


def ground_speed_at_airspeed(airspeed, track, wind_en):
    """Ground speed (m/s) along ``track`` (rad clockwise from north) of an aircraft flying at
    ``airspeed`` (m/s) in the wind ``wind_en`` (map east, north; m/s): the wind triangle
    ``sqrt(airspeed^2 - w_cross^2) + w_along``."""
    e = _unit(track)
    along = wind_en[0] * e[0] + wind_en[1] * e[1]
    cross = wind_en[0] * e[1] - wind_en[1] * e[0]
    return float(math.sqrt(airspeed**2 - cross**2) + along)


def steady_climb_duration(dh_m, rate_mps):
    """Duration (s) of a steady climb (descent) by ``dh_m`` at ``rate_mps`` with
    :data:`CLIMB_RAMP_S` smoothsteps into and out of the rate; a change too small to reach the
    rate takes the two smoothsteps alone (its peak rate ``|dh| / CLIMB_RAMP_S`` below it)."""
    return max(abs(dh_m) / rate_mps, CLIMB_RAMP_S) + CLIMB_RAMP_S


def speed_change_duration(speed_from, speed_to):
    """Duration (s) of a smoothstep speed change peaking at :data:`SPEED_CHANGE_MPS2`."""
    return max(MIN_SPEED_CHANGE_S, SMOOTHSTEP_PEAK_RATE * abs(speed_to - speed_from) / SPEED_CHANGE_MPS2)


def wind_velocity_en(speed_mps, from_deg):
    """Wind velocity (map east, north), m/s, of a wind of ``speed_mps`` blowing *from*
    ``from_deg`` (clockwise from north, as a weather report gives it)."""
    a = math.radians(from_deg)
    return (-float(speed_mps) * math.sin(a), -float(speed_mps) * math.cos(a))
