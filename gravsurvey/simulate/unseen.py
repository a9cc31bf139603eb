"""Unseen-flight generator: random survey flights drawn from wide ranges with a fixed seed.

The yardstick of issue 12: flights that nothing in gravsurvey was tuned on, processed with the
default configuration.  :func:`draw_flight_spec` draws one flight from the ranges below (same
seed -> same flight, on every machine); :func:`write_flight` writes it with the simulator's own
machinery (:func:`gravsurvey.simulate.run.simulate_to_dir`) into a folder with the sensor logs,
``truth.csv``, a ``survey.yaml`` that holds only what a user knows (file layout, topics, rates
implied by the files, triad; no ``model`` block; docs/simulate.md) and, for the benchmark's
"oracle-tuned" column, an ``oracle.yaml`` with the matched model.
:func:`draw_issue_flight_spec` draws flights as issue 12 describes the three of its table
(``benchmarks/bench_issue_flights.py``).

This module is part of the simulator: it shares no code with the estimator (only
``gravsurvey.geodesy``).

Ranges (docs/simulate.md, "Unseen flights"): random point-mass / dipole / prism fields whose
sources peak at 0.2-1 x a flight scale drawn log-uniform in 0.5-100 mGal, with source distances
below the aircraft giving 1-50 km wavelengths; every sensor noise level and the turbulence
x0.3-x3 of :data:`NOMINAL_SENSORS` / :data:`NOMINAL_TURBULENCE` (log-uniform, independent);
IMU 20-200 Hz, GNSS and height 1-20 Hz; platform or strapdown; any heading; 50-120 m/s;
300-5000 m; 30-240 min of grid lines with turns between them; static periods at start/end
with probability 1/2 each.
"""

from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np

from gravsurvey.geodesy import WGS84, geodetic_to_ecef

from .field import field_model_from_dict, gravity_disturbance
from .simconfig import load_sim_config
from .trajectory import build_plan, map_scales

__all__ = [
    "NOMINAL_SENSORS",
    "NOMINAL_TURBULENCE",
    "RANGES",
    "ISSUE_FLIGHTS",
    "draw_flight_spec",
    "draw_issue_flight_spec",
    "limit_spec",
    "noise_psd",
    "peak_disturbance",
    "spec_summary",
    "write_flight",
]

MGAL = 1e-5
#: Newton's gravitational constant, m^3 kg^-1 s^-2 (CODATA 2018).
GRAV_CONSTANT = 6.67430e-11
#: First element of every generator seed sequence: keeps these draws apart from any other
#: ``default_rng([seed, ...])`` of the simulator.
SEED_TAG = 120_006

#: Nominal sensor errors (x1): a navigation-grade strapdown IMU with a good gravimeter on z and
#: carrier-phase-grade height (configs/realistic_survey.yaml; gravimeter white noise
#: 1 mGal/sqrt(Hz) as in issue 12's table).  Every number is scaled per flight by its own
#: factor in ``RANGES["noise_factor"]``; the gravimeter correlation rate is drawn separately.
NOMINAL_SENSORS = {
    "accelerometer": {"white_sigma_mps2": 5.0e-4, "bias_mps2": [2.0e-4, 1.0e-4]},
    "gravimeter": {"bias_mps2": 2.0e-5, "markov_sigma_mps2": 1.0e-5, "white_sigma_mps2": 1.0e-5},
    "gyro": {"bias_degph": [0.02, 0.01, 0.015], "white_drift_degph": 0.01},
    "altimeter": {"sigma_m": 0.05},
    "gnss": {"horizontal_sigma_m": 0.5, "vertical_sigma_m": 1.0},
}
#: Nominal turbulence (x1), scaled like the sensor errors.
NOMINAL_TURBULENCE = {"vertical_sigma_m": 1.5, "horizontal_sigma_m": 2.0, "attitude_sigma_deg": 1.0}

#: The ranges every draw stays in (tests/test_unseen.py checks them).
RANGES = {
    "noise_factor": (0.3, 3.0),
    "field_scale_mgal": (0.5, 100.0),
    "source_fraction": (0.2, 1.0),  # a source's peak / the flight's field scale
    "wavelength_m": (1000.0, 50000.0),
    "imu_hz": (20, 200),
    "aux_hz": (1, 20),  # GNSS and altimeter
    "speed_mps": (50.0, 120.0),
    "altitude_m": (300.0, 5000.0),
    "duration_s": (1800.0, 14400.0),
    "line_spacing_m": (1000.0, 8000.0),
    "static_s": (120.0, 300.0),
    "gravimeter_lambda_per_s": (0.0005, 0.02),
    "origin_lat_deg": (-60.0, 60.0),
}
#: Largest |latitude| of a survey origin :func:`draw_flight_spec` accepts, deg: lines of up to
#: :data:`MAX_LINE_M` flown poleward from it stay inside the simulator's 89.5 deg
#: (docs/simulate.md "Limits").
MAX_ORIGIN_LAT_DEG = 85.0
#: Longest survey line, m (keeps every plan inside the simulator's survey map).
MAX_LINE_M = 350_000.0
#: Shortest survey line, s of flight.
MIN_LINE_S = 300.0
#: Sources per km of survey line, and their bounds.
SOURCES_PER_KM = 1.0 / 15.0
MIN_SOURCES, MAX_SOURCES = 3, 40
#: Source kinds drawn (equal weight per entry): half point masses, a quarter dipoles and prisms.
SOURCE_KINDS = ("point_masses", "point_masses", "dipoles", "prisms")
#: Clearance between a source and the aircraft's height, m.
MIN_CLEARANCE_M = 100.0
#: wavelength = pi x (distance of the source below the aircraft): the spectrum of a point mass
#: seen from a distance z falls as exp(-2 pi z / wavelength), 1/e at wavelength 2 pi z; its
#: bump is 1.53 z wide at half maximum, half of a sinusoid of wavelength ~3.1 z.
WAVELENGTH_PER_DEPTH = math.pi


def _log_uniform(rng, lo, hi):
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _int_log_uniform(rng, lo, hi):
    return int(min(hi, max(lo, round(_log_uniform(rng, lo, hi + 0.499)))))


def _scaled_sensors(rng, factors: dict) -> dict:
    """NOMINAL_SENSORS scaled by a factor per noise level (random signs for the vector biases)."""
    s = copy.deepcopy(NOMINAL_SENSORS)
    lo, hi = RANGES["noise_factor"]
    for sec, d in s.items():
        for k, v in d.items():
            f = _log_uniform(rng, lo, hi)
            factors[f"{sec}.{k}"] = f
            if isinstance(v, list):
                d[k] = [float(x * f * rng.choice((-1.0, 1.0))) for x in v]
            else:  # the SIM schema takes a gravimeter bias >= 0; its sign is immaterial here
                d[k] = float(v * f)
    s["gravimeter"]["markov_lambda_per_s"] = _log_uniform(rng, *RANGES["gravimeter_lambda_per_s"])
    return s


def _grid_plan(rng, speed, altitude, heading, lat0, lon0, target_s, ell):
    """A grid plan (lines + turns, optional static periods) lasting about ``target_s``."""
    static_start = float(rng.uniform(*RANGES["static_s"])) if rng.random() < 0.5 else 0.0
    static_end = float(rng.uniform(*RANGES["static_s"])) if rng.random() < 0.5 else 0.0
    spacing = float(rng.uniform(*RANGES["line_spacing_m"]))
    n_min = max(2, math.ceil(target_s * speed / MAX_LINE_M))
    count = int(rng.integers(n_min, n_min + 5))
    plan = {
        "kind": "grid",
        "origin_lat_deg": lat0,
        "origin_lon_deg": lon0,
        "altitude_m": altitude,
        "speed_mps": speed,
        "lines": {"count": count, "spacing_m": spacing, "length_m": 20000.0, "heading_deg": heading},
        "static_start_s": static_start,
        "static_end_s": static_end,
    }
    # The overhead (turns, ramps, statics) depends on the count and spacing, not on the line
    # length: one probe per count tried gives the length that meets the target.
    while True:
        probe = _built_plan(plan, ell)
        overhead = probe.duration - count * plan["lines"]["length_m"] / speed
        length = (target_s - overhead) * speed / count
        if length >= MIN_LINE_S * speed or count == 2:
            break
        count -= 1
        plan["lines"]["count"] = count
    plan["lines"]["length_m"] = float(min(MAX_LINE_M, max(MIN_LINE_S * speed, length)))
    return plan


def _built_plan(plan, ell, turbulence=None):
    """:func:`build_plan` of a plan mapping (validated, defaults filled in); for its duration."""
    sim = {"flights": [{"start_utc": "2024-01-01T00:00:00Z", "plan": plan, "turbulence": turbulence}]}
    f = load_sim_config(sim).flights[0]
    return build_plan(f["plan"], f["turbulence"], np.random.default_rng(0), ell)


def _track_point(rng, plan):
    """A random map point (east, north) on or near a survey line, m."""
    g = plan["lines"]
    psi = math.radians(g["heading_deg"])
    along = np.array([math.sin(psi), math.cos(psi)])
    right = np.array([math.cos(psi), -math.sin(psi)])
    i = int(rng.integers(0, g["count"]))
    a = rng.uniform(-0.05, 1.05) * g["length_m"]
    return a * along + i * g["spacing_m"] * right


def _unit_source(kind, rng, lat, lon, z, altitude):
    """One source of unit strength ``z`` m below the aircraft; returns (field key, item)."""
    depth = z - altitude  # below the ellipsoid, m (> 0 by the clearance)
    pos = {"lat_deg": lat, "lon_deg": lon}
    if kind == "point_masses":
        return {**pos, "depth_m": depth, "mass_kg": 1.0e12}
    if kind == "dipoles":
        return {
            **pos,
            "depth_m": depth,
            "mass_kg": 1.0e12,
            "separation_m": float(z * rng.uniform(0.5, 2.0)),
            "azimuth_deg": float(rng.uniform(0.0, 360.0)),
        }
    half_e, half_n = (float(z * rng.uniform(0.5, 1.5)) for _ in range(2))
    thick = float(z * rng.uniform(0.2, 0.6))
    top = max(0.0, depth - 0.5 * thick)
    return {
        **pos,
        "east_m": [-half_e, half_e],
        "north_m": [-half_n, half_n],
        "depth_m": [top, top + thick],
        "density_kgm3": 100.0,
    }


def peak_disturbance(key, item, altitude, z, ell):
    """Largest |gravity disturbance| (m/s^2) of one source on a grid at the flight altitude."""
    model = field_model_from_dict({"type": "model", key: [item]}, "field", ell)
    span = 1.5 * z + float(item.get("separation_m", 0.0)) + max(abs(x) for x in item.get("east_m", [0.0]))
    u = np.linspace(-span, span, 41)
    de, dn = np.meshgrid(u, u)
    rm, rp = map_scales(math.radians(item["lat_deg"]), altitude, ell)
    lat = math.radians(item["lat_deg"]) + dn.ravel() / rm
    lon = math.radians(item["lon_deg"]) + de.ravel() / rp
    r_e = geodetic_to_ecef(lat, lon, np.full(lat.shape, altitude), ell)
    return float(np.max(np.abs(gravity_disturbance(model, r_e, ell))))


def _random_field(rng, plan, altitude, ell, sources_out: list, kinds=SOURCE_KINDS) -> dict:
    """Sources of ``kinds`` (drawn with equal weight per entry) near the lines; amplitudes and
    wavelengths drawn."""
    scale = _log_uniform(rng, *RANGES["field_scale_mgal"])
    line_km = plan["lines"]["count"] * plan["lines"]["length_m"] / 1000.0
    n_src = int(min(MAX_SOURCES, max(MIN_SOURCES, round(line_km * SOURCES_PER_KM))))
    lat0, lon0 = math.radians(plan["origin_lat_deg"]), math.radians(plan["origin_lon_deg"])
    rm, rp = map_scales(lat0, altitude, ell)
    wl_lo = max(RANGES["wavelength_m"][0], WAVELENGTH_PER_DEPTH * (altitude + MIN_CLEARANCE_M))
    wl_hi = RANGES["wavelength_m"][1]
    field = {"type": "model", "point_masses": [], "dipoles": [], "prisms": []}
    for _ in range(n_src):
        kind = str(rng.choice(list(kinds)))
        wavelength = _log_uniform(rng, wl_lo, wl_hi)
        z = wavelength / WAVELENGTH_PER_DEPTH
        x, y = _track_point(rng, plan)
        lat = math.degrees(lat0 + y / rm)
        # a survey by the antimeridian puts sources past +-180 deg: the same place, named in range
        lon = (math.degrees(lon0 + x / rp) + 180.0) % 360.0 - 180.0
        item = _unit_source(kind, rng, lat, lon, z, altitude)
        target = scale * rng.uniform(*RANGES["source_fraction"]) * MGAL
        peak = peak_disturbance(kind, item, altitude, z, ell)
        gain = target / peak
        sign = float(rng.choice((-1.0, 1.0)))
        if kind == "prisms":
            item["density_kgm3"] = float(np.clip(sign * 100.0 * gain, -20000.0, 20000.0))
            amp = abs(item["density_kgm3"]) / 100.0 * peak
        else:
            item["mass_kg"] = float(1.0e12 * gain * (sign if kind == "point_masses" else 1.0))
            if kind == "dipoles":
                item["azimuth_deg"] = float((item["azimuth_deg"] + (180.0 if sign < 0 else 0.0)) % 360.0)
            amp = target
        field[kind].append(item)
        sources_out.append(
            {"kind": kind, "peak_mgal": amp / MGAL, "wavelength_m": wavelength, "distance_below_aircraft_m": z}
        )
    return {k: v for k, v in field.items() if v or k == "type"}, scale


def draw_flight_spec(seed: int, origin_lat_deg: float | None = None) -> dict:
    """Draw one unseen flight.

    Parameters
    ----------
    seed : int >= 0
        Same seed -> the same flight (numpy ``default_rng([SEED_TAG, seed])``).
    origin_lat_deg : float, optional
        Put the survey's origin at this latitude (|lat| <= :data:`MAX_ORIGIN_LAT_DEG`) instead
        of the drawn one (``RANGES["origin_lat_deg"]``): a polar or high-latitude survey with
        everything else as the seed draws it (the field's sources keep their places on the
        survey's map).  The name then carries it: ``U003S80`` for 80 deg S.

    Returns
    -------
    dict
        ``seed``, ``name``; the drawn quantities ``triad``, ``imu_hz``, ``altimeter_hz``,
        ``gnss_hz``, ``speed_mps``, ``altitude_m``, ``heading_deg``, ``target_duration_s``,
        ``duration_s`` (of the built plan, s), ``line_count``, ``line_length_m``,
        ``line_spacing_m``, ``static_start_s``, ``static_end_s``, ``noise_factors``
        (``"section.key"`` -> factor of :data:`NOMINAL_SENSORS`, plus ``turbulence.*``),
        ``field_scale_mgal``, ``sources`` (list of ``kind``, ``peak_mgal``,
        ``wavelength_m``, ``distance_below_aircraft_m``); and ``sim``: the complete SIM
        mapping (docs/simulate.md) that :func:`write_flight` simulates.
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"draw_flight_spec: seed must be an integer >= 0, got {seed!r}")
    seed = int(seed)
    rng = np.random.default_rng([SEED_TAG, seed])
    ell = WGS84
    triad = str(rng.choice(["platform", "strapdown"]))
    imu_hz = _int_log_uniform(rng, *RANGES["imu_hz"])
    gnss_hz = _int_log_uniform(rng, *RANGES["aux_hz"])
    alt_hz = _int_log_uniform(rng, *RANGES["aux_hz"])
    speed = float(rng.uniform(*RANGES["speed_mps"]))
    altitude = float(rng.uniform(*RANGES["altitude_m"]))
    heading = float(rng.uniform(0.0, 360.0))
    target = float(rng.uniform(*RANGES["duration_s"]))
    lat0 = float(rng.uniform(*RANGES["origin_lat_deg"]))
    lon0 = float(rng.uniform(-180.0, 180.0))
    name = f"U{seed:03d}"
    if origin_lat_deg is not None:
        lat0 = float(origin_lat_deg)
        if not abs(lat0) <= MAX_ORIGIN_LAT_DEG:
            raise ValueError(
                f"draw_flight_spec: origin_lat_deg must be within +-{MAX_ORIGIN_LAT_DEG:g} deg, got {origin_lat_deg!r}"
            )
        name += f"{'N' if lat0 >= 0 else 'S'}{abs(lat0):g}"
    factors: dict = {}
    sensors = _scaled_sensors(rng, factors)
    turb = {}
    for k, v in NOMINAL_TURBULENCE.items():
        f = _log_uniform(rng, *RANGES["noise_factor"])
        factors[f"turbulence.{k}"] = f
        turb[k] = float(v * f)
    plan = _grid_plan(rng, speed, altitude, heading, lat0, lon0, target, ell)
    sources: list = []
    field, scale = _random_field(rng, plan, altitude, ell, sources)
    rates = (imu_hz, gnss_hz, alt_hz)
    return _assembled_spec(seed, name, triad, rates, target, plan, turb, sensors, factors, field, scale, sources)


def _assembled_spec(seed, name, triad, rates, target, plan, turb, sensors, factors, field, scale, sources) -> dict:
    """The spec mapping of one drawn flight (:func:`draw_flight_spec`'s Returns), its SIM checked."""
    imu_hz, gnss_hz, alt_hz = rates
    ell = WGS84
    day = 1 + seed % 28
    sim = {
        "name": f"unseen_{name}",
        "seed": seed,
        "formats": ["mcap_ros2"],
        "field": field,
        "flights": [
            {
                "name": "F01",
                "start_utc": f"2025-03-{day:02d}T07:00:00Z",
                "triad": triad,
                "rates": {
                    "imu_hz": float(imu_hz),
                    "altimeter_hz": float(alt_hz),
                    "gnss_hz": float(gnss_hz),
                    "truth_hz": 1.0,
                },
                "plan": plan,
                "turbulence": turb,
                "sensors": sensors,
            }
        ],
    }
    load_sim_config(sim)  # the draw is a valid SIM config by construction; checked here
    built = _built_plan(plan, ell, turb)
    return {
        "seed": seed,
        "name": name,
        "triad": triad,
        "imu_hz": imu_hz,
        "altimeter_hz": alt_hz,
        "gnss_hz": gnss_hz,
        "speed_mps": plan["speed_mps"],
        "altitude_m": plan["altitude_m"],
        "heading_deg": plan["lines"]["heading_deg"],
        "origin_lat_deg": plan["origin_lat_deg"],
        "origin_lon_deg": plan["origin_lon_deg"],
        "target_duration_s": target,
        "duration_s": float(built.duration),
        "line_count": plan["lines"]["count"],
        "line_length_m": plan["lines"]["length_m"],
        "line_spacing_m": plan["lines"]["spacing_m"],
        "static_start_s": plan["static_start_s"],
        "static_end_s": plan["static_end_s"],
        "noise_factors": factors,
        "field_scale_mgal": scale,
        "sources": sources,
        "sim": sim,
    }


#: The three flights of issue 12's table as the issue describes them (an independent
#: simulator's; its exact draws are unknown): point masses plus dipoles, 60-90 min at 72 m/s,
#: the nominal sensors with a gravimeter of 1 mGal/sqrt(Hz) white + Gauss-Markov + a 2 mGal
#: bias.  Per kind: triad, IMU rate (Hz; a pair is drawn log-uniform), GNSS and height rate
#: (Hz), height noise (m), turbulence (x :data:`NOMINAL_TURBULENCE`).
_ISSUE_COMMON = {"imu_hz": (20, 100), "aux_hz": (1, 10), "height_sigma_m": (0.03, 0.10), "turbulence": 1.0}
ISSUE_FLIGHTS = {
    "A": {**_ISSUE_COMMON, "triad": "platform"},
    "B": {**_ISSUE_COMMON, "triad": "strapdown"},
    "C": {
        "triad": "strapdown",
        "imu_hz": (100, 100),
        "aux_hz": (1, 1),
        "height_sigma_m": (0.10, 0.10),
        "turbulence": 3.0,
    },
}
#: Their speed, m/s, and duration range, s.
ISSUE_SPEED_MPS = 72.0
ISSUE_DURATION_S = (3600.0, 5400.0)
#: Their sources: point masses and dipoles, one in four a dipole.
ISSUE_SOURCE_KINDS = ("point_masses", "point_masses", "point_masses", "dipoles")


def draw_issue_flight_spec(kind: str, seed: int) -> dict:
    """Draw one flight like issue 12's table (:data:`ISSUE_FLIGHTS`): what the issue states is
    fixed, the rest (field, altitude, heading, lines, the gravimeter's correlation time) drawn as
    in :func:`draw_flight_spec`.

    Parameters
    ----------
    kind : {"A", "B", "C"}
        A: platform; B: strapdown; C: strapdown, 100 Hz IMU, 1 Hz GNSS and height, 10 cm height
        noise, turbulence x3.
    seed : int >= 0
        Same (kind, seed) -> the same flight; named ``I<kind><seed>`` (``IA00``).

    Returns
    -------
    dict
        As :func:`draw_flight_spec`.
    """
    if kind not in ISSUE_FLIGHTS:
        raise ValueError(f"draw_issue_flight_spec: kind must be one of {sorted(ISSUE_FLIGHTS)}, got {kind!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"draw_issue_flight_spec: seed must be an integer >= 0, got {seed!r}")
    seed = int(seed)
    spec = ISSUE_FLIGHTS[kind]
    rng = np.random.default_rng([SEED_TAG, 12, "ABC".index(kind), seed])
    imu_hz = _int_log_uniform(rng, *spec["imu_hz"])
    aux_hz = _int_log_uniform(rng, *spec["aux_hz"])
    altitude = float(rng.uniform(*RANGES["altitude_m"]))
    heading = float(rng.uniform(0.0, 360.0))
    target = float(rng.uniform(*ISSUE_DURATION_S))
    lat0 = float(rng.uniform(*RANGES["origin_lat_deg"]))
    lon0 = float(rng.uniform(-180.0, 180.0))
    sensors = copy.deepcopy(NOMINAL_SENSORS)
    sensors["altimeter"]["sigma_m"] = _log_uniform(rng, *spec["height_sigma_m"])
    sensors["gravimeter"]["markov_lambda_per_s"] = _log_uniform(rng, *RANGES["gravimeter_lambda_per_s"])
    factors = {"altimeter.sigma_m": sensors["altimeter"]["sigma_m"] / NOMINAL_SENSORS["altimeter"]["sigma_m"]}
    turb = {k: float(v * spec["turbulence"]) for k, v in NOMINAL_TURBULENCE.items()}
    factors.update({f"turbulence.{k}": spec["turbulence"] for k in NOMINAL_TURBULENCE})
    plan = _grid_plan(rng, ISSUE_SPEED_MPS, altitude, heading, lat0, lon0, target, WGS84)
    sources: list = []
    field, scale = _random_field(rng, plan, altitude, WGS84, sources, ISSUE_SOURCE_KINDS)
    rates = (imu_hz, aux_hz, aux_hz)
    name = f"I{kind}{seed:02d}"
    return _assembled_spec(
        seed, name, spec["triad"], rates, target, plan, turb, sensors, factors, field, scale, sources
    )


def limit_spec(spec: dict, max_duration_s: float | None = None, max_imu_hz: float | None = None) -> dict:
    """A cheaper variant of a drawn flight (benchmark ``--quick``, tests).

    Fewer/shorter lines so the flight lasts about ``max_duration_s`` at most, and the IMU rate
    capped at ``max_imu_hz``; everything else (field, noise, speed, ...) as drawn.  The field
    sources stay where they were drawn (some may then lie off the shortened lines).
    """
    out = copy.deepcopy(spec)
    f = out["sim"]["flights"][0]
    if max_imu_hz is not None and f["rates"]["imu_hz"] > max_imu_hz:
        f["rates"]["imu_hz"] = float(max_imu_hz)
        out["imu_hz"] = max_imu_hz
    if max_duration_s is not None and out["duration_s"] > max_duration_s:
        plan = f["plan"]
        g = plan["lines"]
        keep = max_duration_s / out["duration_s"]
        plan["static_start_s"] = min(plan["static_start_s"], 0.05 * max_duration_s)
        plan["static_end_s"] = min(plan["static_end_s"], 0.05 * max_duration_s)
        count = max(2, min(g["count"], round(g["count"] * math.sqrt(keep))))
        length = g["length_m"] * keep * g["count"] / count
        g["count"] = count
        g["length_m"] = float(max(MIN_LINE_S * plan["speed_mps"], length))
        built = _built_plan(plan, WGS84, f["turbulence"])
        out.update(
            duration_s=float(built.duration),
            line_count=g["count"],
            line_length_m=g["length_m"],
            static_start_s=plan["static_start_s"],
            static_end_s=plan["static_end_s"],
        )
    return out


def write_flight(spec: dict, out_dir, oracle: bool = True) -> Path:
    """Simulate a drawn flight into ``out_dir`` (logs, truth.csv, survey.yaml, oracle.yaml).

    Returns
    -------
    Path
        ``out_dir/survey.yaml`` (what a user knows; process with the defaults).
    """
    from .run import simulate_to_dir

    out_dir = Path(out_dir)
    paths = simulate_to_dir(spec["sim"], out_dir, oracle=oracle)
    return paths[-1]


def spec_summary(spec: dict) -> str:
    """One line describing a drawn flight (for tables and logs)."""
    return (
        f"{spec['name']} {spec['triad']} imu {spec['imu_hz']} Hz gnss {spec['gnss_hz']} Hz "
        f"alt {spec['altimeter_hz']} Hz, {spec['speed_mps']:.0f} m/s, {spec['altitude_m']:.0f} m, "
        f"{spec['duration_s'] / 60:.0f} min ({spec['line_count']} x {spec['line_length_m'] / 1000:.0f} km"
        f"{', static start' if spec['static_start_s'] > 0 else ''}), "
        f"field {spec['field_scale_mgal']:.1f} mGal ({len(spec['sources'])} sources)"
    )


def noise_psd(flight: dict, f_hz) -> np.ndarray:
    """One-sided PSD of the along-track disturbance noise of the scalar problem, (m/s^2)^2/Hz.

    The noise a filter of the measured vertical specific force minus the measured height's
    second derivative has to remove, from the flight's drawn sensor errors (docs/simulate.md,
    "Unseen flights", derivation):

    * gravimeter white noise, one-second sigma ``s_w``: ``2 s_w^2`` (one-sided);
    * gravimeter Gauss-Markov error (``sigma``, ``lambda``): ``4 lambda sigma^2 / (lambda^2 + w^2)``;
    * height: altimeter samples (``sigma_h`` at ``R_h``) and GNSS heights (``sigma_v`` at
      ``R_v``) are independent white noises of two-sided PSD ``sigma^2 / R``, the GNSS's plus
      its Gauss-Markov part (``2 l s^2 / (l^2 + w^2)``, ``vertical_markov_sigma_m``, ``l`` one
      over ``markov_tau_s``); combined optimally ``S_z = 1 / (1 / S_h + 1 / S_v)``;
      differentiated twice: ``2 w^4 S_z``.

    ``w = 2 pi f``.  Constant biases are left out (the score removes the mean error); the
    Eotvos error from GNSS velocity noise and the tilt leakage of horizontal accelerometer
    noise are orders of magnitude smaller at the frequencies that matter and are left out too.

    Parameters
    ----------
    flight : dict
        A flight of a SIM mapping (``spec["sim"]["flights"][0]``): ``sensors`` and ``rates``.
    f_hz : array_like
        Frequencies, Hz.
    """
    f = np.asarray(f_hz, dtype=float)
    s = flight["sensors"]
    r = flight["rates"]
    w = 2.0 * math.pi * f
    g = s.get("gravimeter", {})
    psd = 2.0 * float(g.get("white_sigma_mps2", 0.0)) ** 2 * np.ones_like(f)
    sig_m, lam = float(g.get("markov_sigma_mps2", 0.0)), float(g.get("markov_lambda_per_s", 0.025))
    psd = psd + 4.0 * lam * sig_m**2 / (lam**2 + w**2)
    info = np.zeros_like(f)  # height information, 1 / (two-sided PSD), Hz / m^2
    sig_h = float(s.get("altimeter", {}).get("sigma_m", 0.0))
    gn = s.get("gnss", {})
    sig_v = float(gn.get("vertical_sigma_m", 0.0))
    sig_vm = float(gn.get("vertical_markov_sigma_m", 0.0))
    if sig_h > 0:
        info += r["altimeter_hz"] / sig_h**2
    if sig_v > 0 or sig_vm > 0:
        lam_v = 1.0 / float(gn.get("markov_tau_s", 600.0))
        s_v = sig_v**2 / r["gnss_hz"] + 2.0 * lam_v * sig_vm**2 / (lam_v**2 + w**2)
        info += 1.0 / s_v
    has = info > 0
    psd[has] = psd[has] + 2.0 * w[has] ** 4 / info[has]
    return psd
