"""A synthetic line survey with known truth for the levelling, ties and grid tests and the GMT
benchmark (independent of the simulator and of the code under test): an analytic field of
buried point masses, lines and tie lines flown by several flights with per-flight offsets and
drifts, per-line offsets and white noise."""

import numpy as np

from gravsurvey.geodesy import MGAL

G_NEWTON = 6.674e-11


def truth_field_mgal(e, n, h=800.0):
    """Vertical attraction of three buried point masses at height h, mGal (analytic)."""
    out = np.zeros_like(np.asarray(e, float))
    for e0, n0, d, m in ((8e3, 12e3, 2500.0, 2e13), (20e3, 5e3, 3000.0, -1.5e13), (14e3, 20e3, 2000.0, 8e12)):
        dz = h + d
        r2 = (e - e0) ** 2 + (n - n0) ** 2 + dz**2
        out += G_NEWTON * m * dz / r2**1.5 / MGAL
    return out


def simulated_survey(seed=1, noise_mgal=0.2, spacing_m=4000.0, speed=80.0, dt=2.0, tie_tilt_deg=0.0, altitudes=None):
    """3 flights: F1 and F2 fly 4 north-south lines each (24 km), F3 flies 4 east-west ties.

    Each flight gets an offset (2 .. -3 mGal) and a drift (mGal/h); each line an extra offset of
    0.5 mGal RMS; every sample white noise ``noise_mgal``. Returns lines (dicts for
    find_crossovers), the per-flight (offset, drift), and the flights' still readings.
    ``tie_tilt_deg`` turns the ties off east-west (crossings then fall between samples);
    ``altitudes`` maps flight -> flight height, m (default 800 m for all).
    """
    rng = np.random.default_rng(seed)
    flights = {"F1": (2.0, 0.8), "F2": (-1.5, -0.6), "F3": (3.0, 0.4)}
    lines = []
    for f, (off, drift) in flights.items():
        t_now = 600.0  # after a 10 min still reading at the base
        for k in range(4):
            if f == "F3":
                n0 = 2000.0 + k * 6000.0
                e = np.arange(0.0, 28000.0, speed * dt)
                nn = n0 + (e - 14000.0) * np.tan(np.radians(tie_tilt_deg))
                name = f"T{k + 1:02d}"
            else:
                e0 = (k * 2 + (0 if f == "F1" else 1)) * spacing_m / 2 + 1000.0
                nn = np.arange(0.0, 24000.0, speed * dt) + (37.0 if tie_tilt_deg else 0.0)
                if k % 2:
                    nn = nn[::-1]
                e = np.full_like(nn, e0)
                name = f"L{k + 1:02d}"
            t = t_now + np.arange(e.size) * dt
            t_now = t[-1] + 300.0  # a turn
            alt = 800.0 if altitudes is None else float(altitudes[f])
            tru = truth_field_mgal(e, nn, alt)
            err = off + drift * t / 3600.0 + rng.normal(0, 0.5) + rng.normal(0, noise_mgal, e.size)
            lines.append(
                {
                    "flight": f,
                    "line": name,
                    "easting_m": e,
                    "northing_m": nn,
                    "time_s": t,
                    "value_mgal": tru + err,
                    "truth_mgal": tru,
                    "sigma_mgal": np.full(e.size, noise_mgal),
                    "height_m": np.full(e.size, alt),
                }
            )
        flights[f] = (off, drift, t_now + 300.0)
    return lines, flights
