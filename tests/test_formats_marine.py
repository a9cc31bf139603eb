"""Closed-form normal gravity formulas (geodesy) and marine.py against outside values."""

import boule
import numpy as np
import pytest

from gravsurvey.classic import eotvos_exact
from gravsurvey.errors import DataError
from gravsurvey.geodesy import GRS80, WGS84, normal_gravity, normal_gravity_formula, normal_gravity_formula_at_height
from gravsurvey.marine import eotvos_from_track, free_air_anomaly, track_velocity

MGAL = 1e-5
LAT = np.radians(np.linspace(-90, 90, 181))


@pytest.mark.parametrize("name,ell", [("GRS80", boule.GRS80), ("WGS84", boule.WGS84)])
def test_somigliana_equals_boule_on_the_ellipsoid(name, ell):
    ref = ell.normal_gravity((np.zeros_like(LAT), np.degrees(LAT), np.zeros_like(LAT)), si_units=True)
    assert np.abs(normal_gravity_formula(LAT, name) - ref).max() < 1e-9


def test_published_formula_values():
    # equator and pole values as published: IGF1930 978049 / 983221.2, IGF1967 978031.846 /
    # 983217.7, GRS80 978032.67715 / 983218.63685 mGal (Moritz 2000)
    eq, pole = np.array([0.0]), np.array([np.pi / 2])
    assert normal_gravity_formula(eq, "IGF1930")[0] / MGAL == pytest.approx(978049.0, abs=1e-6)
    assert normal_gravity_formula(pole, "IGF1930")[0] / MGAL == pytest.approx(978049 * 1.0052884, abs=1e-6)
    assert normal_gravity_formula(eq, "IGF1967")[0] / MGAL == pytest.approx(978031.846, abs=1e-6)
    assert normal_gravity_formula(pole, "IGF1967")[0] / MGAL == pytest.approx(983217.72, abs=0.01)
    assert normal_gravity_formula(eq, "GRS80")[0] / MGAL == pytest.approx(978032.67715, abs=1e-5)
    assert normal_gravity_formula(pole, "grs80")[0] / MGAL == pytest.approx(983218.63685, abs=1e-5)
    with pytest.raises(ValueError, match="IGF1967"):
        normal_gravity_formula(eq, "IGF1971")


def test_height_term_against_exact():
    for h, tol in ((1000.0, 0.011), (10000.0, 0.071)):
        d = normal_gravity_formula_at_height(LAT, np.full_like(LAT, h), "GRS80") - normal_gravity(
            LAT, np.full_like(LAT, h), GRS80
        )
        assert np.abs(d).max() / MGAL < tol
    fa = free_air_anomaly(np.full(3, 9.8), LAT[:3], 100.0, "IGF1967")
    assert np.allclose(fa, 9.8 - normal_gravity_formula_at_height(LAT[:3], np.full(3, 100.0), "IGF1967"))


def _ship(t, lat0_deg, lon0_deg, ve, vn, ell=WGS84):
    """Positions of a constant-velocity rhumb-ish track, integrated finely (truth)."""
    lat = np.empty(t.size)
    lon = np.empty(t.size)
    la, lo = np.radians(lat0_deg), np.radians(lon0_deg)
    fine = 20
    tt = np.linspace(0.0, t[-1], (t.size - 1) * fine + 1)
    dt = tt[1] - tt[0]
    la_f, lo_f = [la], [lo]
    from gravsurvey.geodesy import radii_of_curvature

    for _ in tt[1:]:
        m, n = radii_of_curvature(la, ell)
        # midpoint rule
        la_mid = la + 0.5 * dt * vn / m
        m, n = radii_of_curvature(la_mid, ell)
        la += dt * vn / m
        lo += dt * ve / (n * np.cos(la_mid))
        la_f.append(la)
        lo_f.append(lo)
    lat = np.array(la_f)[::fine]
    lon = np.array(lo_f)[::fine]
    return lat, lon


def test_eotvos_from_track_against_exact_velocity():
    t = np.arange(0.0, 3600.0, 10.0)
    ve, vn = 5.0, -3.0  # ~11 kn
    lat, lon = _ship(t, -40.0, 179.9, ve, vn)
    lon = np.angle(np.exp(1j * lon))  # wrapped to (-pi, pi]: crosses the dateline
    assert (np.abs(np.diff(lon)) > np.pi).any()
    e_ve, e_vn = track_velocity(t, lat, lon)
    assert np.abs(e_ve - ve).max() < 1e-4 and np.abs(e_vn - vn).max() < 1e-4
    truth = eotvos_exact(lat, 0.0, ve, vn)
    for form in ("harlan", "exact"):
        e = eotvos_from_track(t, lat, lon, form=form)
        assert np.abs(e - truth).max() / MGAL < 0.01, form
    assert np.median(truth) / MGAL == pytest.approx(7.503 * ve / 0.514444 * np.cos(np.radians(40)), rel=0.02)


def test_track_gaps_and_errors():
    t = np.array([0.0, 10, 20, 200, 210, 220])
    lat = np.radians(np.linspace(10, 10.01, 6))
    lon = np.zeros(6)
    ve, vn = track_velocity(t, lat, lon, max_gap_s=50)
    assert np.isnan(vn[2]) and np.isnan(vn[3]) and np.isfinite(vn[[0, 1, 4, 5]]).all()
    with pytest.raises(DataError, match="strictly increasing"):
        track_velocity(t[::-1], lat, lon)
    with pytest.raises(DataError, match="need at least 3"):
        track_velocity(t[:2], lat[:2], lon[:2])


def test_use_normal_gravity_formula_shifts_by_the_formula_difference():
    from types import SimpleNamespace

    from gravsurvey.geodesy import normal_gravity
    from gravsurvey.marine import use_normal_gravity_formula

    lat = np.radians(np.linspace(-60, 60, 50))
    h = np.linspace(0, 3000, 50)
    base = np.full(50, 3.0 * MGAL)
    r = SimpleNamespace(
        lat=lat,
        height=h,
        disturbance=base.copy(),
        raw=base.copy(),
        terms={"raw": base.copy(), "normal_gravity": np.full(50, 9.8)},
        info={},
    )
    use_normal_gravity_formula(r, "exact", GRS80)
    assert np.array_equal(r.disturbance, base) and "exact" in r.info["normal_gravity"]
    use_normal_gravity_formula(r, "IGF1967", GRS80)
    shift = (r.disturbance - base) / MGAL
    want = (normal_gravity(lat, h, GRS80) - normal_gravity_formula_at_height(lat, h, "IGF1967")) / MGAL
    assert np.allclose(shift, want, atol=1e-9) and 0.80 < shift.min() and shift.max() < 0.92
    assert np.allclose(r.raw, r.disturbance) and np.allclose(r.terms["normal_gravity"] - 9.8, -want * MGAL)
    with pytest.raises(ValueError, match="IGF1967"):
        use_normal_gravity_formula(r, "igf67", GRS80)
