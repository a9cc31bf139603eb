"""A flight across the 180 deg meridian, recorded as receivers write longitude (in [-180, 180)).

The survey map of the simulator runs its longitude on across the antimeridian; its written GNSS
and truth longitudes are wrapped (``simulate.run.wrap_lon_deg``), so the record jumps from
+179.99 to -179.99 deg as a real one does. The same flight flown at 20 deg E is the reference;
the sensors are noiseless, so a mishandled wrap (a 360 deg step, a 40000 km jump in position)
would stand out of an error of 0.008 mGal.
"""

import csv

import numpy as np
import pytest
import yaml

from gravsurvey.pipeline import run_survey
from gravsurvey.simulate.run import quick_sim, simulate_flight, simulate_to_dir, wrap_lon_deg


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
    out = tmp_path / f"lon{lon_deg:+.1f}_{heading_deg:.0f}"
    simulate_to_dir(sim, out)
    res = run_survey(out / "survey.yaml", force=True, plots=False)
    assert not res.failed
    folder = out / yaml.safe_load((out / "survey.yaml").read_text()).get("output", {}).get("dir", "out")
    with open(folder / "profiles.csv") as fh:
        rows = list(csv.DictReader(line for line in fh if not line.startswith("#")))
    lon = np.array([float(r["lon_deg"]) for r in rows])
    err = np.array([float(r["error_mgal"]) for r in rows])
    truth = np.array([float(r["truth_mgal"]) for r in rows])
    keep = slice(len(err) // 6, len(err) - len(err) // 6)
    return float(np.std(err[keep])), float(np.std(truth[keep])), lon


def test_wrap_lon_deg():
    assert wrap_lon_deg(np.array([180.0, 181.25, -181.25, 359.0, 0.0, -180.0])) == pytest.approx(
        [-180.0, -178.75, 178.75, -1.0, 0.0, -180.0]
    )


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
