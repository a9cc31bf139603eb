"""Surveys anywhere on Earth: near either pole and across the 180 deg meridian, against the
simulator's truth.

*Polar.* Airborne gravity surveys are flown over Antarctica and the Arctic. The estimator works
in geodetic latitude and longitude (the longitude rate grows as 1/cos(lat)) and the default map
grid is UTM, which ends at 84 deg N and 80 deg S; there the Universal Polar Stereographic grid
takes over (``georef.default_epsg``). The simulator's survey map is exact at any latitude
(docs/simulate.md), so the same plan and the same buried masses, placed relative to the track,
can be flown at each latitude.

*Antimeridian.* The survey map runs its longitude on across 180 deg; the simulator's written
GNSS and truth longitudes are wrapped (``geodesy.wrap_deg``), so the record jumps from
+179.99 to -179.99 deg as a real one does. The same flight flown at 20 deg E is the reference;
the sensors are noiseless, so a mishandled wrap (a 360 deg step, a 40000 km jump in position)
would stand out of an error of 0.008 mGal.
"""

import csv
import json
import math

import numpy as np
import pytest
import yaml

from gravsurvey.georef import UPS_NORTH_EPSG, UPS_SOUTH_EPSG, default_epsg, project
from gravsurvey.pipeline import run_survey
from gravsurvey.geodesy import wrap_deg
from gravsurvey.simulate.run import quick_sim, simulate_flight, simulate_to_dir
from gravsurvey.simulate.trajectory import map_scales

ALTITUDE_M = 1500.0
LON0_DEG = 30.0


def _run(sim, out):
    """Simulate ``sim`` into ``out``, run its default config; ``(rows of profiles.csv, summary,
    output folder)``."""
    simulate_to_dir(sim, out)
    res = run_survey(out / "survey.yaml", force=True, plots=False)
    assert not res.failed
    folder = out / yaml.safe_load((out / "survey.yaml").read_text()).get("output", {}).get("dir", "out")
    with open(folder / "profiles.csv") as fh:
        rows = list(csv.DictReader(line for line in fh if not line.startswith("#")))
    return rows, json.loads((folder / "summary.json").read_text()), folder


def _survey(tmp_path, lat_deg, lon_deg=LON0_DEG):
    """Simulate a 3-line grid with a tie at ``lat_deg``, starting at ``lon_deg``, run the default
    config, return ``(rms_mgal, truth_std_mgal, summary, output folder)`` on the line and tie
    epochs."""
    rm, rp = map_scales(math.radians(lat_deg), ALTITUDE_M)
    rng = np.random.default_rng(7)
    masses = []
    for _ in range(10):
        east, north = rng.uniform(-10e3, 50e3), rng.uniform(-15e3, 5e3)
        masses.append(
            {
                "lat_deg": lat_deg + math.degrees(north / rm),
                "lon_deg": wrap_deg(lon_deg + math.degrees(east / rp)),
                "depth_m": float(rng.uniform(4e3, 9e3)),
                "mass_kg": float(rng.choice([-1.0, 1.0]) * rng.uniform(1e14, 4e14)),
            }
        )
    plan = {
        "kind": "grid",
        "origin_lat_deg": lat_deg,
        "origin_lon_deg": lon_deg,
        "altitude_m": ALTITUDE_M,
        "speed_mps": 80.0,
        "lines": {"count": 3, "spacing_m": 4000.0, "length_m": 40000.0, "heading_deg": 90.0},
        "ties": {"count": 1},
        "static_start_s": 120.0,
    }
    sim = quick_sim(
        imu_hz=10, gnss_hz=2, noise=True, triad="strapdown", field={"type": "model", "point_masses": masses}, plan=plan
    )
    rows, summary, folder = _run(sim, tmp_path / f"lat{lat_deg:+.0f}_lon{lon_deg:+.0f}")
    rows = [r for r in rows if r["line"]]
    err = np.array([float(r["error_mgal"]) for r in rows])
    truth = np.array([float(r["truth_mgal"]) for r in rows])
    assert np.isfinite(err).all()
    return float(np.std(err)), float(np.std(truth)), summary, folder


@pytest.fixture(scope="module")
def mid_latitude(tmp_path_factory):
    return _survey(tmp_path_factory.mktemp("polar"), 45.0)


@pytest.mark.parametrize("lat_deg,epsg", [(-86.0, UPS_SOUTH_EPSG), (86.0, UPS_NORTH_EPSG)])
def test_a_survey_near_the_pole_is_as_accurate_as_at_mid_latitude(tmp_path, mid_latitude, lat_deg, epsg):
    rms_mid, truth_mid, summary_mid, _ = mid_latitude
    rms, truth, summary, folder = _survey(tmp_path, lat_deg)
    # the same field relative to the track (its strength differs by the masses' placement only)
    assert truth == pytest.approx(truth_mid, rel=0.05)
    # the estimate resolves the field at both latitudes, and equally well
    assert rms < 0.35 * truth and rms_mid < 0.35 * truth_mid
    assert rms == pytest.approx(rms_mid, rel=0.1)
    # map products on the polar grid, easting first
    assert summary["crs_epsg"] == epsg and summary_mid["crs_epsg"] == 32636
    assert "UPS" in summary["crs"]["projected"] and "(E,N)" in summary["crs"]["projected"]
    assert summary["crossovers"]["count"] == summary_mid["crossovers"]["count"] >= 2
    assert (folder / "grid.nc").is_file()


def test_default_grid_is_utm_inside_its_extent_and_ups_beyond():
    deg = np.radians
    assert default_epsg(deg([83.9]), deg([20.0])) == 32634
    assert default_epsg(deg([84.1]), deg([20.0])) == UPS_NORTH_EPSG
    assert default_epsg(deg([-79.9]), deg([20.0])) == 32734
    assert default_epsg(deg([-80.1]), deg([20.0])) == UPS_SOUTH_EPSG
    # UPS North: the pole at (2000 km, 2000 km), scale 0.994 there; the 0 deg meridian runs
    # from it to grid south, so a point 1 deg from the pole on it lies due grid south
    e, n, code = project(deg([90.0, 89.0]), deg([0.0, 0.0]))
    assert code == UPS_NORTH_EPSG
    assert e[0] == pytest.approx(2.0e6, abs=1e-3) and n[0] == pytest.approx(2.0e6, abs=1e-3)
    assert e[1] == pytest.approx(2.0e6, abs=1e-3)
    assert 2.0e6 - n[1] == pytest.approx(0.994 * 111.69e3, rel=2e-3)


def _line_error(tmp_path, lon_deg, heading_deg):
    sim = quick_sim(
        duration_s=1800.0,
        lat_deg=10.0,
        lon_deg=lon_deg,
        heading_deg=heading_deg,
        speed_mps=80.0,
        field="seed_smooth",
        triad="strapdown",
    )
    rows, _, _ = _run(sim, tmp_path / f"lon{lon_deg:+.1f}_{heading_deg:.0f}")
    lon = np.array([float(r["lon_deg"]) for r in rows])
    err = np.array([float(r["error_mgal"]) for r in rows])
    truth = np.array([float(r["truth_mgal"]) for r in rows])
    keep = slice(len(err) // 6, len(err) - len(err) // 6)
    return float(np.std(err[keep])), float(np.std(truth[keep])), lon


def test_wrap_deg():
    assert wrap_deg(np.array([180.0, 181.25, -181.25, 359.0, 0.0, -180.0])) == pytest.approx(
        [-180.0, -178.75, 178.75, -1.0, 0.0, -180.0]
    )


def test_a_survey_across_the_antimeridian_is_as_accurate_as_elsewhere(tmp_path, mid_latitude):
    # three lines and a tie from 179.8 deg E to 179.7 deg W: the drift stage, crossovers and grid
    # see both halves of the survey as one
    rms_mid, truth_mid, summary_mid, _ = mid_latitude
    rms, truth, summary, folder = _survey(tmp_path, 45.0, 179.8)
    with open(folder / "profiles.csv") as fh:
        lon = np.array([float(r["lon_deg"]) for r in csv.DictReader(x for x in fh if not x.startswith("#"))])
    assert lon.max() > 179.8 and lon.min() < -179.6  # across it, wrapped as written
    assert truth == pytest.approx(truth_mid, rel=0.05)
    assert rms == pytest.approx(rms_mid, rel=0.1)
    drift, drift_mid = (x["flights"]["F01"]["estimator"]["drift"] for x in (summary, summary_mid))
    assert drift["used"] == drift_mid["used"]
    assert summary["crossovers"]["count"] == summary_mid["crossovers"]["count"] >= 2
    assert (folder / "grid.nc").is_file()


def test_simulated_gnss_longitude_is_wrapped_across_the_antimeridian():
    s = simulate_flight(quick_sim(duration_s=600.0, lat_deg=10.0, lon_deg=179.9, heading_deg=90.0, speed_mps=80.0))
    lon = s.gnss_lon_deg
    assert lon.min() >= -180.0 and lon.max() < 180.0
    assert lon[0] > 179.0 and lon[-1] < -179.0  # it crossed, as a receiver writes it


@pytest.mark.parametrize("lon_deg,heading_deg", [(179.8, 90.0), (-179.8, 270.0)])
def test_a_line_across_the_antimeridian_is_as_accurate_as_elsewhere(tmp_path, lon_deg, heading_deg):
    rms_ref, _, _ = _line_error(tmp_path, 20.0, heading_deg)
    rms, truth, lon = _line_error(tmp_path, lon_deg, heading_deg)
    assert (lon > 179.0).any() and (lon < -179.0).any()  # the product crosses too, wrapped
    assert rms == pytest.approx(rms_ref, rel=0.01)
    assert rms < 0.01 * truth
