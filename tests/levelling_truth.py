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


def random_field_survey(seed, spacing_m, noise_mgal=0.2, noise_length_m=0.0):
    """8 north-south lines of 24 km ``spacing_m`` apart and 3 east-west ties at 800 m over 120
    random point masses (0.5-4 km deep, anywhere within 5 km of the block): a field of 2-4 mGal
    standard deviation with wavelengths from ~1 km up. The data's error is white
    (``noise_length_m`` 0) or correlated along each line as exp(-d / noise_length_m).

    Returns e, n, h, value (with the error), line label, and ``field(e, n, h)`` (mGal).
    Used by tests/test_grid.py and benchmarks/bench_grid_sigma.py."""
    rng = np.random.default_rng(seed)
    sources = [
        (rng.uniform(-5e3, 29e3), rng.uniform(-5e3, 29e3), rng.uniform(500.0, 4000.0), rng.normal(0.0, 3e12))
        for _ in range(120)
    ]

    def field(e, n, h):
        out = np.zeros_like(e)
        for e0, n0, d, m in sources:
            dz = h + d
            out += G_NEWTON * m * dz / ((e - e0) ** 2 + (n - n0) ** 2 + dz**2) ** 1.5 / MGAL
        return out

    E, N, L = [], [], []
    for k in range(8):
        nn = np.arange(0.0, 24000.0, 160.0)
        E.append(np.full(nn.size, 1000.0 + k * spacing_m))
        N.append(nn)
        L.append(np.full(nn.size, f"F1/L{k:02d}"))
    for k in range(3):
        ee = np.arange(0.0, 8 * spacing_m, 160.0)
        E.append(ee)
        N.append(np.full(ee.size, 2000.0 + k * 9000.0))
        L.append(np.full(ee.size, f"F2/T{k:02d}"))
    e, n, lab = np.concatenate(E), np.concatenate(N), np.concatenate(L)
    h = np.full(e.size, 800.0)
    noise = np.zeros(e.size)
    a = np.exp(-160.0 / noise_length_m) if noise_length_m > 0 else 0.0
    for name in np.unique(lab):
        x = 0.0
        for j in np.flatnonzero(lab == name):
            x = a * x + np.sqrt(1.0 - a * a) * rng.normal(0.0, noise_mgal)
            noise[j] = x
    return e, n, h, field(e, n, h) + noise, lab, field
