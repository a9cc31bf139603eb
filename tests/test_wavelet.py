"""Tests of the wavelet post-processor (gravsurvey.wavelet) against exact identities and truth."""

import math
import warnings

import numpy as np
import pytest
import pywt
from scipy import signal as sps

from gravsurvey import wavelet as W
from gravsurvey.errors import ConfigError, DataError, DataWarning
from gravsurvey.settings import postprocess_options
from gravsurvey import filters as F

MGAL = 1e-5


def _coloured_noise(n, rng, sigma=4 * MGAL, band_s=(100.0, 400.0)):
    """Stationary band-limited noise like the RTS smoother's anomaly error (model.md sec. 3):
    most power at periods 100-400 s at 1 Hz.  Generated longer and cropped (no end effects)."""
    w = rng.standard_normal(n + 4000)
    sos = sps.butter(2, [2.0 / band_s[1], 2.0 / band_s[0]], btype="band", output="sos")
    x = sps.sosfiltfilt(sos, w)[2000 : 2000 + n]
    return sigma * x / np.std(x)


def _smooth_truth(t, phases=(0.0, 1.0, 2.0)):
    return MGAL * (
        30 * np.sin(2 * np.pi * t / 3600 + phases[0])
        + 20 * np.sin(2 * np.pi * t / 1500 + phases[1])
        + 10 * np.sin(2 * np.pi * t / 900 + phases[2])
    )


def _rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


# ---------------------------------------------------------------------------------------------
# Exact identities of the pyramid
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("wavelet", ["db10", "coif4"])
@pytest.mark.parametrize("mode", ["symmetric", "periodization", "smooth", "zero", "reflect"])
@pytest.mark.parametrize("n", [1000, 1023, 4096, 3001])
def test_perfect_reconstruction_all_K_levels(wavelet, mode, n):
    rng = np.random.default_rng(n)
    z = rng.standard_normal(n) * 1e-3 + 2e-3
    c = W.wavedec_k(z, wavelet, mode)
    assert len(c) == W.n_levels(n) + 1 == 2 + int(math.floor(math.log2(n)))
    # all thresholds zero: soft and hard thresholding at p = 0 keep every coefficient
    for kind in ("soft", "hard"):
        c0 = [c[0]] + [W.threshold(d, 0.0, kind) for d in c[1:]]
        z_rec = W.waverec_n(c0, wavelet, mode, n)
        assert np.max(np.abs(z_rec - z)) <= 1e-12 * np.max(np.abs(z))


def _approx_by_single_steps(z, wavelet, mode, level):
    """Level-n approximation by n single-level dwt's and n single-level idwt's (no wavedec)."""
    a = z
    lengths = []
    for _ in range(level):
        lengths.append(a.size)
        a, _d = pywt.dwt(a, wavelet, mode=mode)
    for m in reversed(lengths):
        a = pywt.idwt(a, None, wavelet, mode=mode)[:m]
    return a


@pytest.mark.parametrize("mode", ["symmetric", "periodization"])
@pytest.mark.parametrize("n", [2000, 1531])
def test_full_removal_equals_level_n_approximation(mode, n):
    rng = np.random.default_rng(7)
    z = np.cumsum(rng.standard_normal(n))
    kmax = W.n_levels(n)
    steps = 4
    images, _dmax, _ = W._removed_images(z, "db10", mode, "soft", steps, kmax)
    for level in (1, 3, 6):
        ref = _approx_by_single_steps(z, "db10", mode, level)
        # thresholds at max|d_j| remove everything: z - sum of removed images
        zt = z - images[:level, steps].sum(axis=0)
        scale = np.max(np.abs(z))
        assert np.max(np.abs(zt - ref)) <= 1e-11 * scale
        assert np.max(np.abs(W.approximation(z, "db10", level, mode) - ref)) <= 1e-11 * scale


def test_threshold_rules():
    d = np.array([-3.0, -1.0, 0.5, 2.0, 4.0])
    assert np.array_equal(W.threshold(d, 2.0, "soft"), [-1.0, 0.0, 0.0, 0.0, 2.0])
    assert np.array_equal(W.threshold(d, 2.0, "hard"), [-3.0, 0.0, 0.0, 0.0, 4.0])


# ---------------------------------------------------------------------------------------------
# The criterion
# ---------------------------------------------------------------------------------------------
def test_phi_matches_direct_numpy_for_random_vectors():
    rng = np.random.default_rng(1)
    for _ in range(50):
        n = int(rng.integers(2, 500))
        z, zt = rng.standard_normal(n), rng.standard_normal(n)
        r = z - zt
        direct = abs(np.dot(r, zt)) / (np.linalg.norm(r) * np.linalg.norm(zt))
        assert W.phi_criterion(z, zt) == pytest.approx(direct, rel=1e-12, abs=1e-15)
    assert math.isnan(W.phi_criterion(np.ones(5), np.ones(5)))  # nothing removed: undefined


@pytest.mark.parametrize(
    "mode,kind", [("symmetric", "soft"), ("symmetric", "hard"), ("smooth", "soft"), ("periodization", "soft")]
)
def test_cosphi_search_phi_is_signal_domain_phi(mode, kind):
    """The Gram/numba search reports, per level, the Phi of the signal-domain vectors, equal to
    the pure-numpy reference search that evaluates every candidate directly."""
    rng = np.random.default_rng(3)
    n = 777
    z = np.cumsum(rng.standard_normal(n)) + rng.standard_normal(n)
    zt, info = W.cosphi_search(z, "db10", mode, kind, steps=5)
    zr, info_r = W.cosphi_search(z, "db10", mode, kind, steps=5, reference=True)
    assert info["Phi"] == pytest.approx(W.phi_criterion(z, zt), rel=1e-9)
    np.testing.assert_allclose(info["phi_by_level"], info_r["phi_by_level"], rtol=1e-7, atol=1e-15)
    assert info["n"] == info_r["n"]
    np.testing.assert_allclose(zt, zr, rtol=0, atol=1e-12 * np.max(np.abs(z)))
    assert len(info["p"]) == info["n"]
    assert info["phi_deg"] == pytest.approx(math.degrees(math.acos(info["Phi"])))


@pytest.mark.parametrize(
    "mode,kind",
    [
        ("symmetric", "soft"),
        ("symmetric", "hard"),
        ("smooth", "soft"),
        ("periodization", "soft"),
        ("periodization", "hard"),
    ],
)
def test_cosphi_search_never_returns_a_degenerate_candidate(mode, kind):
    """Issue 14.12: the candidate that removes nothing (all thresholds 0) has Phi = rounding
    (4.7e-10 on numpy 2.4.6 / PyWavelets 1.9.0) in the Gram search and must never win; nor may
    a candidate that keeps nothing.  Both search paths, several lines."""
    for seed in range(4):
        rng = np.random.default_rng(seed)
        n = int(rng.integers(300, 900))
        z = np.cumsum(rng.standard_normal(n)) + rng.standard_normal(n)
        for reference in (False, True):
            zt, info = W.cosphi_search(z, "db10", mode, kind, steps=5, reference=reference)
            zz = float(z @ z)
            removed, kept = float((z - zt) @ (z - zt)), float(zt @ zt)
            assert info["n"] >= 1
            assert removed > 1e-9 * zz, (seed, reference, removed / zz)
            assert kept > 1e-9 * zz, (seed, reference, kept / zz)
            # Phi may be ~0 legitimately (periodization is orthogonal: removing whole levels
            # is an orthogonal projection), but it is the Phi of a real, finite angle
            assert math.isfinite(info["Phi"])
            assert info["Phi"] == pytest.approx(W.phi_criterion(z, zt), rel=1e-9, abs=1e-9)


def test_cosphi_search_on_a_line_with_nothing_to_remove_keeps_it():
    """A constant line has zero detail at every level: every candidate is degenerate, and the
    line comes back unchanged with n = 0 (not a rounding-noise 'best' candidate)."""
    z = np.full(256, 3.0)
    zt, info = W.cosphi_search(z, "db10", "periodization", "soft", steps=4)
    assert info["n"] == 0 and math.isnan(info["Phi"])
    np.testing.assert_array_equal(zt, z)


def test_ti_phi_by_level_is_phi_of_the_output():
    rng = np.random.default_rng(4)
    n = 3000
    z = np.cumsum(rng.standard_normal(n)) + 3 * rng.standard_normal(n)
    _, info = W.ti_cosphi(z, "coif4")
    # levels 1..K-2: the coarsest whose -6 dB period 2^(n+1) still fits in the line
    assert len(info["phi_by_level"]) == W.n_levels(n) - 2 == info["length_limited_level"]
    for level in range(1, W.n_levels(n) - 1):
        a = W.ti_approximation(z, "coif4", level)
        assert info["phi_by_level"][level - 1] == pytest.approx(W.phi_criterion(z, a), rel=1e-9)


# ---------------------------------------------------------------------------------------------
# The finding: the faithful rule is ill-posed with an orthogonal (periodized) transform
# ---------------------------------------------------------------------------------------------
def test_periodized_full_removal_and_hard_thresholding_give_phi_zero():
    rng = np.random.default_rng(5)
    n = 4096  # divisible by 2^K': periodization is exactly orthogonal at every level
    z = np.cumsum(rng.standard_normal(n))
    c = W.wavedec_k(z, "db10", "periodization")
    for level in range(1, W.n_levels(n) + 1):
        a = W.approximation(z, "db10", level, "periodization")
        assert W.phi_criterion(z, a) < 1e-12
    for p_frac in (0.05, 0.3, 0.7):
        ch = [c[0]] + [W.threshold(d, p_frac * np.max(np.abs(d)), "hard") for d in c[1:]]
        zt = W.waverec_n(ch, "db10", "periodization", n)
        assert W.phi_criterion(z, zt) < 1e-12
    # whereas the symmetric extension is not orthogonal: Phi > 0 at full removal
    a = W.approximation(z, "db10", 5, "symmetric")
    assert W.phi_criterion(z, a) > 1e-8


# ---------------------------------------------------------------------------------------------
# The translation-invariant operator
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("wavelet", ["db10", "coif4"])
def test_ti_response_is_cycle_spun_decimated_projection(wavelet):
    """Average of the periodized level-n projections over all 2^n grid shifts = circular
    convolution with response prod |H(2^k w)|^2 / 2."""
    rng = np.random.default_rng(6)
    n, level = 512, 3
    z = rng.standard_normal(n)
    acc = np.zeros(n)
    for s in range(2**level):
        zs = np.roll(z, -s)
        acc += np.roll(W.approximation(zs, wavelet, level, "periodization"), s)
    acc /= 2**level
    f = np.fft.rfftfreq(n)
    ref = np.fft.irfft(np.fft.rfft(z) * W.ti_response(wavelet, level, f), n)
    assert np.max(np.abs(acc - ref)) < 1e-12 * np.max(np.abs(z)) * 10


@pytest.mark.parametrize("level", [3, 6, 8])
def test_ti_half_power_period_measured_on_a_sinusoid(level):
    period = W.ti_period_samples("db10", level)
    assert period == pytest.approx(2 ** (level + 1), rel=0.02)
    n = 40 * int(period)
    t = np.arange(n)
    z = np.sin(2 * np.pi * t / period)
    a = W.ti_approximation(z, "db10", level)
    mid = slice(n // 4, 3 * n // 4)
    amp = np.sqrt(2) * _rms(a[mid])
    assert amp == pytest.approx(0.5, abs=0.01)


def test_lowpass_half_amplitude_at_the_filter_length():
    dt, period = 1.0, 300.0
    n = 30000
    t = np.arange(n) * dt
    z = np.sin(2 * np.pi * t / period)
    mid = slice(n // 4, 3 * n // 4)
    for f in (lambda x: F.butterworth_lowpass(x, dt, period, 4), lambda x: F.gaussian_lowpass(x, dt, period)):
        assert np.sqrt(2) * _rms(f(z)[mid]) == pytest.approx(0.5, abs=0.01)
    _, info = W.postprocess(z, dt, 50.0, "butterworth", resolution_m=7500.0)
    assert info["filter_length_s"] == pytest.approx(300.0)
    assert info["resolution_m"] == pytest.approx(7500.0)


def test_linear_operators_are_time_reversal_equivariant():
    """A zero-phase operator with symmetric boundary handling commutes with time reversal:
    P(z reversed) = P(z) reversed, i.e. it cannot shift anything in time."""
    rng = np.random.default_rng(8)
    z = np.cumsum(rng.standard_normal(5001)) * MGAL
    ops = [
        lambda x: W.ti_approximation(x, "db10", 7),
        lambda x: F.butterworth_lowpass(x, 1.0, 400.0),
        lambda x: F.gaussian_lowpass(x, 1.0, 400.0),
    ]
    for op in ops:
        np.testing.assert_allclose(op(z[::-1]), op(z)[::-1], rtol=0, atol=1e-9 * np.max(np.abs(z)))


# ---------------------------------------------------------------------------------------------
# Against truth: steps, edges, baselines
# ---------------------------------------------------------------------------------------------
def _crossing(y, level, near):
    i = np.nonzero((y[:-1] - level) * (y[1:] - level) <= 0)[0]
    xs = [k + (level - y[k]) / (y[k + 1] - y[k]) for k in i if y[k + 1] != y[k]]
    return min(xs, key=lambda x: abs(x - near))


def test_default_is_the_smoothed_estimate_itself():
    """The default post-processor returns the smoother's estimate unchanged (docs/wavelet.md,
    "Default": none of the post-processors beat the identified smoother on unseen flights)."""
    z = np.sin(np.arange(500) / 30.0) * MGAL
    out, info = W.postprocess(z, 1.0, 50.0, "default")
    assert info["method"] == "none"
    assert np.array_equal(out, z) and out is not z


@pytest.mark.parametrize("method", ["ti_cosphi", "visushrink", "sure", "bayes", "butterworth", "gaussian"])
def test_step_stays_centred(method):
    """A 40 mGal step at a non-dyadic time, plus white noise; the half-height crossing of the
    output, averaged over noise realisations, sits within one sample of the true step."""
    n, t0 = 4001, 1733.5
    offsets = []
    for seed in range(12):
        rng = np.random.default_rng(seed)
        z = np.where(np.arange(n) > t0, 40 * MGAL, 0.0) + 2 * MGAL * rng.standard_normal(n)
        kw = {"filter_length_s": 60.0} if method in ("butterworth", "gaussian") else {}
        out, info = W.postprocess(z, 1.0, 50.0, method, **kw)
        assert out.shape == z.shape
        offsets.append(_crossing(out, 20 * MGAL, t0) - t0)
    assert abs(np.mean(offsets)) < 1.0
    # and the step was actually smoothed, not left alone
    assert info["method"] != "none"


@pytest.mark.parametrize("n", [7201, 8192, 9973])
def test_edges_not_worse_than_input_and_middle_cleaned(n):
    """Smooth anomaly + smoother-like coloured noise, line on its own (no context: mirror
    extension).  Measured: error RMS of the default in the first/last 5 % vs the middle 90 %,
    and vs the input error there.  Issue 5's "edges no larger than the middle" is NOT met
    without context (edges ~10x the middle; docs/wavelet.md section 7); it is met with context,
    see test_context_makes_line_edges_no_worse_than_the_middle."""
    t = np.arange(n, dtype=float)
    edge_in, edge_out, mid_out, mid_in = [], [], [], []
    for seed in range(4):
        rng = np.random.default_rng(100 + seed)
        g = _smooth_truth(t, rng.uniform(0, 2 * np.pi, 3))
        z = g + _coloured_noise(n, rng)
        out, info = W.postprocess(z, 1.0, 50.0, "ti_cosphi")
        k = int(0.05 * n)
        e_in, e_out = z - g, out - g
        edge_in.append(np.r_[e_in[:k], e_in[-k:]])
        edge_out.append(np.r_[e_out[:k], e_out[-k:]])
        mid_in.append(e_in[k:-k])
        mid_out.append(e_out[k:-k])
    e_in, e_out = _rms(np.concatenate(edge_in)), _rms(np.concatenate(edge_out))
    m_in, m_out = _rms(np.concatenate(mid_in)), _rms(np.concatenate(mid_out))
    assert m_out < 0.1 * m_in  # middle: ~0.15 of 4 mGal measured
    assert e_out < 0.5 * e_in  # edges: ~1.3-1.8 of 4 mGal measured (docs/wavelet.md)


def _stationary_flight(seed, m=12000):
    """A whole flight of smooth truth + smoother-like noise (the same statistics everywhere)."""
    rng = np.random.default_rng(seed)
    t = np.arange(m, dtype=float)
    g = _smooth_truth(t, rng.uniform(0, 2 * np.pi, 3))
    return g, g + _coloured_noise(m, rng)


def test_context_makes_line_edges_no_worse_than_the_middle():
    """Issue 5 item 5 (edge artefacts no larger than the middle), met when the flight's estimate
    outside the line is as good as on it: lines of 2000 samples cut from a stationary flight,
    default method with context=(z_full, start, stop).  Measured (6 realisations): edge
    0.76 mGal vs middle 0.75 mGal with context; 2.26 mGal at the edges without it (mirror)."""
    n = 2000
    e_ctx, m_ctx, e_mir = [], [], []
    for seed in range(6):
        g, z = _stationary_flight(700 + seed)
        a = 3000 + 400 * seed
        b = a + n
        out, info = W.postprocess(z[a:b], 1.0, 50.0, "ti_cosphi", context=(z, a, b))
        mirror, info_m = W.postprocess(z[a:b], 1.0, 50.0, "ti_cosphi")
        assert info["n"] == info_m["n"] and info["context"]  # same level: chosen on the line
        k = int(0.05 * n)
        e, em = out - g[a:b], mirror - g[a:b]
        e_ctx.append(np.r_[e[:k], e[-k:]])
        m_ctx.append(e[k:-k])
        e_mir.append(np.r_[em[:k], em[-k:]])
    edge, mid = _rms(np.concatenate(e_ctx)), _rms(np.concatenate(m_ctx))
    assert edge <= 1.25 * mid  # tolerance: RMS over 2 x 5 % of a line of coloured noise scatters
    assert edge < 0.5 * _rms(np.concatenate(e_mir))


def test_context_gate_drops_noisier_sides_and_trivial_context_is_the_mirror():
    _, z = _stationary_flight(41)
    a, b = 4000, 6000
    mirror, info = W.postprocess(z[a:b], 1.0, 50.0, "ti_cosphi")
    # the context is only the line itself: nothing to extend with
    same, _ = W.postprocess(z[a:b], 1.0, 50.0, "ti_cosphi", context=(z[a:b], 0, b - a))
    np.testing.assert_allclose(same, mirror, atol=1e-15 * np.max(np.abs(z)) + 1e-20)
    # both sides 4x noisier than the line in the same band (RMS ~16 vs 4 mGal; like a turn with
    # large dynamic errors): the gate does not use them, the result is the mirror's
    rng = np.random.default_rng(42)
    noisy = z.copy()
    noisy[:a] += np.sqrt(15.0) * _coloured_noise(a, rng)
    noisy[b:] += np.sqrt(15.0) * _coloured_noise(z.size - b, rng)
    gated, _ = W.postprocess(noisy[a:b], 1.0, 50.0, "ti_cosphi", context=(noisy, a, b))
    np.testing.assert_allclose(gated, mirror, rtol=0, atol=1e-12 * np.max(np.abs(z)))
    # the gate's limit is a heuristic: measured here, those noisy sides would still have beaten
    # the mirror's end bias (docs/wavelet.md section 7); with the gate disabled they are used
    leaky = W.ti_apply_with_context(noisy, a, b, info["wavelet"], info["n"], gate_ratio=np.inf)
    assert np.max(np.abs(leaky - mirror)) > 0.1 * MGAL
    # NaN outside the line (e.g. no estimate in a gap) stops the extension there
    holes = z.copy()
    holes[a - 10] = np.nan
    holes[b + 5] = np.nan
    out, _ = W.postprocess(z[a:b], 1.0, 50.0, "ti_cosphi", context=(holes, a, b))
    assert np.all(np.isfinite(out))


def test_context_validation():
    z = np.arange(100.0)
    with pytest.raises(DataError, match="context must be"):
        W.postprocess(z[10:40], 1.0, 50.0, "ti_cosphi", context=z)
    with pytest.raises(DataError, match="does not hold"):
        W.postprocess(z[10:40], 1.0, 50.0, "ti_cosphi", context=(z, 10, 41))
    with pytest.raises(DataError, match="differs from the line"):
        W.postprocess(z[10:40], 1.0, 50.0, "ti_cosphi", context=(z, 11, 41))
    with pytest.raises(DataError, match="expected 1-D"):
        W.postprocess(z[10:40], 1.0, 50.0, "ti_cosphi", context=(z[None, :], 10, 40))


@pytest.mark.parametrize("n", [129, 165, 300, 560])
def test_short_lines_level_fits_the_line_and_beats_the_input(n):
    """Short survey lines (100-600 samples): the level's -6 dB period 2^(n+1) never exceeds the
    line, and the result is closer to truth than the input and than level K-1 (which turned a
    165-sample line of sample_data/grid_ros2 into a near-straight line).  Truth: the seed's
    smooth field 4x compressed (periods 225-900 s), smoother-like noise of 4 mGal, 12
    realisations.  Measured (in / default / level K-1, mGal): 129: 5.13/4.81/7.21,
    165: 4.54/4.33/6.35, 300: 4.04/3.65/12.97, 560: 4.02/3.43/19.17."""
    r_in, r_out, r_k1 = [], [], []
    for seed in range(12):
        rng = np.random.default_rng(500 + seed)
        t = np.arange(n, dtype=float)
        g = _smooth_truth(4 * t, rng.uniform(0, 2 * np.pi, 3))
        z = g + _coloured_noise(n, rng)
        out, info = W.postprocess(z, 1.0, 80.0, "ti_cosphi", sigma=4 * MGAL)
        assert 1 <= info["n"] <= info["length_limited_level"] == W.n_levels(n) - 2
        assert info["period_samples"] <= n
        r_in.append(z - g)
        r_out.append(out - g)
        r_k1.append(W.ti_approximation(z, info["wavelet"], W.n_levels(n) - 1) - g)
    e_out = _rms(np.concatenate(r_out))
    assert e_out < 0.97 * _rms(np.concatenate(r_in))
    assert e_out < 0.8 * _rms(np.concatenate(r_k1))


def test_shrinkage_baselines_beat_white_noise():
    """Classic check: piecewise-smooth signal + white noise; the thresholding baselines remove
    most of the noise (RMS error well below sigma)."""
    rng = np.random.default_rng(11)
    n = 4096
    t = np.linspace(0, 1, n)
    g = np.sqrt(t * (1 - t)) * np.sin(2 * np.pi * 1.05 / (t + 0.05)) + (t > 0.6) * 0.3
    sigma = 0.05
    z = g + sigma * rng.standard_normal(n)
    for method in ("visushrink", "sure", "bayes", "ti_cosphi"):
        out, _ = W.postprocess(z, 1.0, 50.0, method, wavelet="db10")
        assert _rms(out - g) < 0.6 * sigma, method


def test_cosphi_faithful_runs_and_reports():
    rng = np.random.default_rng(12)
    n = 2000
    t = np.arange(n, dtype=float)
    g = _smooth_truth(t * 4)
    z = g + _coloured_noise(n, rng)
    out, info = W.postprocess(z, 1.0, 50.0, "cosphi", wavelet="auto", boundary="symmetric", thresholding="hard")
    assert info["wavelet"] in ("db10", "coif4")
    assert 1 <= info["n"] <= W.n_levels(n)
    assert len(info["p"]) == info["n"]
    assert all(p >= 0 for p in info["p"])
    assert info["Phi"] == pytest.approx(W.phi_criterion(z, out), rel=1e-9)


# ---------------------------------------------------------------------------------------------
# Options and bad input
# ---------------------------------------------------------------------------------------------
def test_options_defaults_and_validation():
    o = postprocess_options(None)
    assert o.method == "default" and o.wavelet == "auto" and o.boundary == "symmetric"
    o = postprocess_options({"method": "butterworth", "resolution_m": 5000})
    assert o.resolution_m == 5000.0
    with pytest.raises(
        ConfigError, match=r"^postprocess\.method: expected one of default, ti_cosphi, .*, got 'wavelets'$"
    ):
        postprocess_options({"method": "wavelets"})
    with pytest.raises(ConfigError, match=r"postprocess\.wavelet.*db10, coif4, auto"):
        postprocess_options({"wavelet": "db4"})
    with pytest.raises(ConfigError, match=r"postprocess\.resolution: unknown key.*resolution_m"):
        postprocess_options({"resolution": 5000})
    with pytest.raises(ConfigError, match=r"^pp\.resolution_m: expected a number > 0, got -1$"):
        postprocess_options({"resolution_m": -1}, key_path="pp")
    with pytest.raises(ConfigError, match=r"not both"):
        postprocess_options({"resolution_m": 1.0, "filter_length_s": 2.0})
    with pytest.raises(ConfigError, match=r"^postprocess\.max_level: must be >= min_level \(3\)$"):
        postprocess_options({"min_level": 3, "max_level": 2})
    with pytest.raises(ConfigError, match=r"postprocess\.boundary.*periodization"):
        postprocess_options({"boundary": "mirror"})
    with pytest.raises(ConfigError, match=r"resolution_m: required"):
        W.postprocess(np.zeros(100) + 1.0, 1.0, 50.0, "gaussian")


def test_bad_lines_raise_data_error():
    with pytest.raises(DataError, match="non-finite"):
        W.postprocess(np.array([1.0, np.nan, 2.0, 3.0]), 1.0, 50.0)
    with pytest.raises(DataError, match=">= 2 samples"):
        W.postprocess(np.array([1.0]), 1.0, 50.0)
    with pytest.raises(DataError, match="sample spacing"):
        W.postprocess(np.ones(10), 0.0, 50.0)
    with pytest.raises(DataError, match="sigma has shape"):
        W.postprocess(np.arange(10.0), 1.0, 50.0, sigma=np.ones(9))
    with pytest.raises(DataError, match="sigma must hold"):
        W.postprocess(np.arange(10.0), 1.0, 50.0, sigma=-1.0)


def test_no_gap_uses_the_coarsest_level_searched():
    z = np.linspace(0.0, 1.0, 500) ** 3  # a smooth curve without noise: Phi(n) rises throughout
    out, info = W.postprocess(z, 1.0, 50.0, "ti_cosphi", wavelet="db10")
    phis = info["phi_by_level"]
    assert len(phis) == W.n_levels(500) - 2  # levels K, K-1 (periods longer than N) excluded
    assert not info["gap_found"]
    assert all(b > a for a, b in zip(phis, phis[1:]))  # measured: monotone, no valley
    assert info["n"] == len(phis)
    np.testing.assert_allclose(out, W.ti_approximation(z, "db10", info["n"]), atol=1e-12)


@pytest.mark.parametrize("n", [2, 3, 8, 33])
def test_short_lines_all_methods(n):
    rng = np.random.default_rng(n)
    z = rng.standard_normal(n)
    for method in W.METHODS:
        kw = {"filter_length_s": 10.0} if method in ("butterworth", "gaussian") else {}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DataWarning)
            out, info = W.postprocess(z, 1.0, 50.0, method, **kw)
        assert out.shape == (n,) and np.all(np.isfinite(out)), method
        assert info["method"] == method


# ---------------------------------------------------------------------------------------------
# Seed scenarios on the real pipeline: simulate + 3D-INM/RTS estimate inside the test run
# ---------------------------------------------------------------------------------------------
SEED_EDGE_S = 600.0  # model.md section 3: drop the first and last 10 minutes


@pytest.fixture(scope="module")
def seed_estimates():
    import sys
    from pathlib import Path

    bench = str(Path(__file__).resolve().parents[1] / "benchmarks")
    if bench not in sys.path:
        sys.path.insert(0, bench)
    from wavelet_study import real_estimate

    return {kind: real_estimate(kind) for kind in ("smooth", "steps", "markov")}


@pytest.mark.parametrize("kind", ["smooth", "steps"])
def test_seed_scenarios_postprocessing_beats_the_smoother(seed_estimates, kind):
    t, z, truth, speed, sigma = seed_estimates[kind]
    keep = (t >= t[0] + SEED_EDGE_S) & (t <= t[-1] - SEED_EDGE_S)
    dt = float(np.median(np.diff(t)))
    out, info = W.postprocess(z, dt, speed, "ti_cosphi", sigma=sigma)
    rms_in = _rms((z - truth)[keep]) / MGAL
    rms_out = _rms((out - truth)[keep]) / MGAL
    # measured (docs/wavelet.md): smooth 4.93 -> 0.62 mGal, steps 4.38 -> 3.45 mGal, n = 8
    assert rms_out < rms_in
    assert info["method"] == "ti_cosphi" and info["n"] >= 1
    assert 5e3 < info["resolution_m"] < 3e4
    if kind == "smooth":
        assert rms_out < 0.5 * rms_in


def test_seed_smooth_default_reaches_the_seeds_figure(seed_estimates):
    """Issue 5: on the smooth seed scenario the default reaches <= 0.99 mGal RMS (the seed's
    own figure).  Measured: 0.62 mGal at 12.8 km half-wavelength."""
    t, z, truth, speed, sigma = seed_estimates["smooth"]
    keep = (t >= t[0] + SEED_EDGE_S) & (t <= t[-1] - SEED_EDGE_S)
    out, info = W.postprocess(z, float(np.median(np.diff(t))), speed, "ti_cosphi", sigma=sigma)
    assert _rms((out - truth)[keep]) / MGAL <= 0.99


def test_seed_smooth_default_reaches_the_estimators_long_period_floor(seed_estimates):
    """The default removes what is removable: on the smooth scenario its error is within
    0.5 mGal (in quadrature) of the smoother's own error at periods > 2000 s, which lies in the
    signal band (900-3600 s) and which no low-pass post-processor can remove.  Measured:
    0.62 mGal total vs 0.46 mGal long-period floor (0.41 mGal in quadrature); the input's
    ~4.9 mGal of 100-600 s noise is gone."""
    t, z, truth, speed, sigma = seed_estimates["smooth"]
    keep = (t >= t[0] + SEED_EDGE_S) & (t <= t[-1] - SEED_EDGE_S)
    out, _ = W.postprocess(z, 1.0, speed, "ti_cosphi", sigma=sigma)
    total = _rms((out - truth)[keep]) / MGAL
    floor = _rms(F.gaussian_lowpass(z - truth, 1.0, 2000.0)[keep]) / MGAL
    assert total**2 <= floor**2 + 0.5**2


def test_seed_markov_sigma_guard_keeps_the_optimal_smoother_nearly_intact(seed_estimates):
    """When the anomaly IS the filter's own Markov model, the RTS estimate is already optimal and
    low-pass post-processing can only remove signal.  Given the smoother's sigma, the default
    never removes more than that sigma: measured 10.4 -> 11.0 mGal (without the guard the
    valley rule picks n = 9 and reaches 21.3 mGal)."""
    t, z, truth, speed, sigma = seed_estimates["markov"]
    keep = (t >= t[0] + SEED_EDGE_S) & (t <= t[-1] - SEED_EDGE_S)
    rms_in = _rms((z - truth)[keep]) / MGAL
    out, info = W.postprocess(z, 1.0, speed, "ti_cosphi", sigma=sigma)
    assert info["removed_rms_by_level"][info["n"] - 1] <= _rms(sigma)
    assert _rms((out - truth)[keep]) / MGAL < 1.15 * rms_in
    out_ng, info_ng = W.postprocess(z, 1.0, speed, "ti_cosphi")
    assert info_ng["n"] > info["n"]  # the guard changed the decision, and for the better
    assert _rms((out_ng - truth)[keep]) > _rms((out - truth)[keep])
