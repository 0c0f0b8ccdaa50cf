"""fidelity.measure.noise against independent references: synthetic Poisson-Gaussian sensors of
known read noise and gain, and emva1288 (the EMVA 1288 reference implementation, the test
extra) analysing the same frames with its own classes.

The sensor (EMVA 1288's linear model): ``eta * photons`` electrons, Poisson; plus dark noise
``sigma_d`` electrons (normal), a fixed dark-signal non-uniformity and a fixed photo-response
non-uniformity where asked; times the gain ``K`` (DN per electron), plus a black level;
rounded to integer DN and clipped to 12 bits.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from fidelity.chart.image import demosaic
from fidelity.core.errors import InvalidValueError
from fidelity.measure.noise import (
    PatchNoise,
    RefusedFit,
    patch_noise,
    photon_transfer,
    temporal_and_fixed_pattern,
    variance_uncertainty,
)
from tests.measure import malvar

K = 0.2  # DN per electron
SIGMA_D = 30.0  # electrons
BLACK = 64.0  # DN
ETA = 0.6
#: The Macbeth chart's neutral patches (white 9.5 ... black 2), reflectance.
NEUTRALS = (0.9, 0.59, 0.36, 0.19, 0.09, 0.031)
#: Quantisation adds 1/12 DN^2 to every variance (rounding to integer DN).
READ_DN = math.sqrt((K * SIGMA_D) ** 2 + 1.0 / 12.0)


def sensor(rng, photons, shape, *, dsnu=None, prnu=None, k=K, sigma_d=SIGMA_D, black=BLACK):
    """One frame of the linear sensor model in integer DN."""
    e = rng.poisson(ETA * photons, shape).astype(np.float64)
    if prnu is not None:
        e = e * (1.0 + prnu)
    e = e + rng.normal(0.0, sigma_d, shape)
    if dsnu is not None:
        e = e + dsnu
    return np.clip(np.round(black + k * e), 0, 4095).astype(np.int64)


def chart(rng, white_photons=12000.0, side=40, **kw):
    """The six neutral patches of one chart frame: their pixels (n, 3), grey camera."""
    return [np.repeat(sensor(rng, white_photons * r, (side, side), **kw).reshape(-1, 1), 3, 1)
            for r in NEUTRALS]


def ptc_inputs(patches):
    stats = [patch_noise(p).channel("G") for p in patches]
    return ([s.mean for s in stats], [s.variance for s in stats],
            [p.shape[0] for p in patches])


# --------------------------------------------------------------------------------------------
# per patch


def test_patch_noise_of_gaussian_pixels():
    rng = np.random.default_rng(0)
    mean, sd = np.array([0.3, 0.5, 0.2]), np.array([0.01, 0.02, 0.005])
    z = []
    for _ in range(40):
        px = mean + sd * rng.standard_normal((900, 3))
        p = patch_noise(px)
        for i, name in enumerate("RGB"):
            c = p.channel(name)
            z.append((c.variance - sd[i] ** 2) / c.u_variance)
    z = np.array(z)
    assert abs(z.mean()) < 0.3 and 0.8 < z.std() < 1.2
    c = p.channel("G")
    assert c.snr == pytest.approx(c.mean / c.sigma)
    assert c.snr_db == pytest.approx(20 * math.log10(c.snr))
    y, lum = p.channel("Y"), px @ np.array([0.2126, 0.7152, 0.0722])
    assert y.mean == pytest.approx(float(lum.mean()))
    assert y.variance == pytest.approx(float(np.var(lum, ddof=1)))
    # chroma noise of independent channels: var(R/G)/mean^2 = cR^2 + cG^2 to first order
    rel = sd / mean
    assert p.chroma_r == pytest.approx(math.hypot(rel[0], rel[1]), rel=0.1)
    assert p.chroma_b == pytest.approx(math.hypot(rel[2], rel[1]), rel=0.1)
    assert p.chroma == pytest.approx(math.hypot(p.chroma_r, p.chroma_b))
    assert [c.channel for c in p.channels] == ["R", "G", "B", "Y"] and p.n == 900


def test_variance_uncertainty_matches_the_spread_of_variances():
    """Over 2000 patches of 50 normal and 50 uniform pixels, the mean stated u(s^2) is the
    standard deviation of s^2 (the fourth moment counts: uniform pixels have a smaller one)."""
    rng = np.random.default_rng(1)
    for draw in (lambda: rng.standard_normal(50), lambda: rng.uniform(-1, 1, 50)):
        s2, u = zip(*(variance_uncertainty(draw()) for _ in range(2000)), strict=True)
        assert np.mean(u) == pytest.approx(np.std(s2), rel=0.1)
    x = rng.standard_normal(400)
    assert variance_uncertainty(x, design_effect=4.0)[1] == pytest.approx(
        2 * variance_uncertainty(x)[1])
    with pytest.raises(InvalidValueError):
        variance_uncertainty(x, design_effect=0.5)


def test_patch_noise_hard_cases():
    zeros = patch_noise(np.zeros((100, 3)))
    for c in zeros.channels:
        assert (c.mean, c.variance, c.u_variance) == (0.0, 0.0, 0.0) and math.isnan(c.snr)
    assert zeros.chroma is None
    json.dumps(zeros.to_json(), allow_nan=False)
    flat = patch_noise(np.full((100, 3), 0.4))
    assert flat.channel("G").snr == math.inf and flat.to_json()["channels"][1]["snr"] is None
    # SNR < 3: the SNR is stated, the chroma noise (ratios to a noisy G) is not
    rng = np.random.default_rng(2)
    dim = patch_noise(0.01 + 0.005 * rng.standard_normal((2000, 3)))
    g = dim.channel("G")
    assert g.snr == pytest.approx(2.0, rel=0.1) and g.snr_db == pytest.approx(6.0, abs=1.0)
    assert dim.chroma is None and dim.chroma_r is None
    # posterised 8-bit codes: one code -> 0, exactly
    codes = np.full((64, 3), 77) / 255.0
    assert patch_noise(codes).channel("R").variance == 0.0
    for bad, reason in ((np.zeros((10, 4)), "shape"), (np.zeros(10), "shape"),
                        (np.zeros((1, 3)), "too-few"),
                        (np.array([[0.1, np.nan, 0.2]] * 3), "non-finite")):
        with pytest.raises(RefusedFit) as e:
            patch_noise(bad)
        assert e.value.reason == reason


def test_patch_noise_json():
    p = patch_noise(np.random.default_rng(3).normal(0.5, 0.01, (200, 3)))
    d = p.to_json()
    json.dumps(d, allow_nan=False)
    assert isinstance(p, PatchNoise) and d["channels"][3]["channel"] == "Y"
    assert "R/G" in d["method"]


# --------------------------------------------------------------------------------------------
# photon transfer against the truth


def test_photon_transfer_recovers_read_noise_and_gain():
    """200 chart frames of the known sensor: the errors of gain and read noise over their
    stated uncertainties are standard scores (mean about 0, RMS about 1, few beyond 3)."""
    zk, zr = [], []
    for seed in range(200):
        p = photon_transfer(*ptc_inputs(chart(np.random.default_rng(seed), side=32)),
                            black_level=BLACK)
        zk.append((p.gain - K) / p.u_gain)
        zr.append((p.read_noise - READ_DN) / p.u_read_noise)
        assert p.u_gain / p.gain < 0.1 and p.u_read_noise / p.read_noise < 0.1
    for z in (np.array(zk), np.array(zr)):
        assert abs(z.mean()) < 0.25, z.mean()
        assert 0.85 < np.sqrt(np.mean(z ** 2)) < 1.15, np.sqrt(np.mean(z ** 2))
        assert np.mean(np.abs(z) > 3.0) <= 0.02 and np.all(np.abs(z) < 4.5)
    assert p.electrons_per_unit == pytest.approx(1 / p.gain)
    assert p.read_noise_electrons == pytest.approx(p.read_noise / p.gain)
    assert p.patches == 6 and p.dof == 4


def test_photon_transfer_snr_and_dynamic_range():
    p = photon_transfer(*ptc_inputs(chart(np.random.default_rng(7))), black_level=BLACK,
                        saturation=4095.0)
    sat = 4095.0 - BLACK
    a = READ_DN ** 2
    mu_min = (K + math.sqrt(K * K + 4 * a)) / 2  # mu = sigma(mu) on the true line
    assert p.mu_min == pytest.approx(mu_min, abs=3 * p.u_mu_min)
    dr_db = 20 * math.log10(sat / mu_min)
    assert p.dynamic_range_db == pytest.approx(dr_db, abs=3 * p.u_dynamic_range_db)
    assert p.dynamic_range_stops == pytest.approx(math.log2(p.dynamic_range))
    grey = 0.18 * sat
    assert p.grey_mean == pytest.approx(grey)
    assert p.snr_grey == pytest.approx(grey / math.sqrt(a + K * grey), rel=0.03)
    assert p.snr_grey_db == pytest.approx(20 * math.log10(p.snr_grey))
    q = photon_transfer(*ptc_inputs(chart(np.random.default_rng(7))), black_level=BLACK,
                        grey_mean=BLACK + 500.0)
    assert q.grey_mean == 500.0 and q.dynamic_range is None and q.saturation is None
    json.dumps(q.to_json(), allow_nan=False)
    json.dumps(p.to_json(), allow_nan=False)
    with pytest.raises(InvalidValueError):
        photon_transfer([1.0, 2.0], [1.0, 2.0], [10, 10], black_level=5.0, saturation=4.0)


def test_photon_transfer_of_8bit_values():
    """Normalised 8-bit output (values code / 255), the noise about half a code at the darkest
    patch: the gain is recovered within 10 % (rounding adds 1/12 code^2 to the intercept)."""
    for seed in range(4):
        rng = np.random.default_rng(seed)
        patches = [np.repeat(np.clip(np.round(0.05 * (rng.poisson(4600 * r, (40, 40))
                                                      + rng.normal(0, 12, (40, 40)))),
                                     0, 255).reshape(-1, 1), 3, 1) / 255.0
                   for r in NEUTRALS]
        p = photon_transfer(*ptc_inputs(patches), saturation=1.0)
        assert p.gain * 255 == pytest.approx(0.05, rel=0.1)
        assert p.read_variance * 255 ** 2 == pytest.approx((0.05 * 12) ** 2 + 1 / 12, rel=0.25)


def test_photon_transfer_refusals():
    def refused(reason, *args, **kw):
        with pytest.raises(RefusedFit) as e:
            photon_transfer(*args, **kw)
        assert e.value.reason == reason, str(e.value)

    rng = np.random.default_rng(4)
    one = [patch_noise(np.repeat(sensor(rng, 5000, (30, 30)).reshape(-1, 1), 3, 1))
           for _ in range(4)]
    refused("singular", [100.0] * 4, [s.channel("G").variance for s in one], [900] * 4)
    refused("singular", [0.0, 0.0], [0.0, 0.0], [100, 100])  # zeros: one level
    # posterised: every patch one code
    codes = [np.full((40, 40), round(200 * r)) / 255.0 for r in NEUTRALS]
    refused("zero-variance", [c.mean() for c in codes],
            [patch_noise(np.repeat(c.reshape(-1, 1), 3, 1)).channel("G").variance
             for c in codes], [1600] * 6)
    refused("negative-slope", [10.0, 100.0, 1000.0], [50.0, 30.0, 10.0], [400] * 3)
    refused("too-few", [10.0], [1.0], [100])
    refused("too-few", [10.0, 20.0], [1.0, 2.0], [100, 1])
    refused("shape", [10.0, 20.0], [1.0, 2.0, 3.0], [100, 100, 100])
    refused("shape", [10.0, 20.0], [1.0, -2.0], [100, 100])
    refused("non-finite", [10.0, np.nan], [1.0, 2.0], [100, 100])


# --------------------------------------------------------------------------------------------
# against emva1288, the EMVA 1288 reference implementation


@pytest.fixture
def emva(monkeypatch):
    """emva1288's processing classes; emva1288 1.0.2 calls ``np.asfarray``, which NumPy 2
    removed: an equivalent is put back for the test (``np.asarray(a, float)``)."""
    pytest.importorskip("emva1288", reason="emva1288 (EMVA 1288 reference implementation, "
                                           "the test extra) is not installed")
    if not hasattr(np, "asfarray"):
        monkeypatch.setattr(np, "asfarray",
                            lambda a, dtype=np.float64: np.asarray(a, dtype=dtype),
                            raising=False)
    from emva1288.process import Data1288, Results1288
    from emva1288.process.routines import get_int_imgs

    return Data1288, Results1288, get_int_imgs


SIDE = 64


def emva_series(rng, get_int_imgs, *, dsnu=None, prnu=None, levels=13, spatial_frames=16):
    """A photon-transfer series in emva1288's layout: flat fields at rising exposure (photons
    per pixel, 0 the dark frames), two frames each (temporal), and L frames of a dark and a
    bright field (spatial); the frames themselves beside it."""
    photons = np.linspace(0.0, 25000.0, levels)
    temporal, pairs = {}, {}
    for p in photons:
        pair = [sensor(rng, p, (SIDE, SIDE), dsnu=dsnu, prnu=prnu) for _ in range(2)]
        pairs[float(p)] = pair
        d = get_int_imgs(pair)
        temporal[float(p)] = {"sum": np.sum(d["sum"]), "pvar": np.sum(d["pvar"]),
                              "dmean": d["dmean"]}
    bright = float(photons[levels // 2])
    stacks = {q: [sensor(rng, q, (SIDE, SIDE), dsnu=dsnu, prnu=prnu)
                  for _ in range(spatial_frames)] for q in (0.0, bright)}
    data = {"temporal": {1.0: temporal},
            "spatial": {1.0: {q: get_int_imgs(s) for q, s in stacks.items()}},
            "width": SIDE, "height": SIDE}
    return data, pairs, stacks, photons


def test_one_frame_estimate_agrees_with_emva1288(emva):
    """emva1288's K and temporal dark noise from the full series against the one-frame chart
    estimate (six 40 x 40 neutral patches of one frame, the black level from the dark
    frames): within the estimate's stated uncertainty (3 u) and within 10 %."""
    data_cls, results_cls, get_int_imgs = emva
    for seed in (11, 12, 13):
        rng = np.random.default_rng(seed)
        data, pairs, _stacks, _ = emva_series(rng, get_int_imgs)
        ref = results_cls(data_cls(data).data)
        assert ref.K == pytest.approx(K, rel=0.02)  # the reference itself finds the truth
        black = float(np.mean(pairs[0.0]))
        p = photon_transfer(*ptc_inputs(chart(rng)), black_level=black, saturation=4095.0)
        assert abs(p.gain - ref.K) < 3 * p.u_gain and p.gain == pytest.approx(ref.K, rel=0.1)
        assert abs(p.read_noise - ref.sigma_y_dark) < 3 * p.u_read_noise
        assert p.read_noise == pytest.approx(ref.sigma_y_dark, rel=0.1)
        # the absolute sensitivity threshold (SNR = 1) in electrons: EMVA 1288's
        # sigma_y.dark / K + 1/2 against mu_min / K
        assert p.mu_min / p.gain == pytest.approx(ref.u_e_min, rel=0.1)


def test_temporal_noise_agrees_with_emva1288(emva):
    """The two-frame temporal variance at every level of the series equals emva1288's
    ``s2_y`` (within 2 %; the formulas are the same), and the dark level's its ``s2_ydark``."""
    data_cls, _results_cls, get_int_imgs = emva
    data, pairs, _stacks, photons = emva_series(np.random.default_rng(21), get_int_imgs)
    ref = data_cls(data).data["temporal"]
    for i, p in enumerate(photons[1:]):
        mine = temporal_and_fixed_pattern(np.stack(pairs[float(p)]))
        assert mine.temporal_variance == pytest.approx(ref["s2_y"][i], rel=0.02)
        assert mine.frames == 2 and mine.rows == mine.columns == SIDE
    dark = temporal_and_fixed_pattern(np.stack(pairs[0.0]))
    assert dark.temporal_variance == pytest.approx(ref["s2_ydark"][0], rel=0.02)
    assert dark.temporal_noise == pytest.approx(READ_DN, rel=0.05)


def test_fixed_pattern_noise_agrees_with_emva1288(emva):
    """A sensor with column-wise DSNU, pixel DSNU and PRNU: the spatial variance of 16 frames
    and its column, row and pixel parts equal emva1288's (within 2 %), dark and bright, and
    the dark one is the DSNU put in."""
    data_cls, results_cls, get_int_imgs = emva
    rng = np.random.default_rng(31)
    col = np.repeat(rng.normal(0.0, 8.0, (1, SIDE)), SIDE, axis=0)  # electrons
    dsnu = col + rng.normal(0.0, 10.0, (SIDE, SIDE))
    prnu = rng.normal(0.0, 0.01, (SIDE, SIDE))
    data, _pairs, stacks, _ = emva_series(rng, get_int_imgs, dsnu=dsnu, prnu=prnu)
    ref = results_cls(data_cls(data).data)
    dark = temporal_and_fixed_pattern(np.stack(stacks[0.0]))
    bright = temporal_and_fixed_pattern(np.stack([s for q, s in stacks.items() if q][0]))
    for mine, suffix in ((dark, "_dark"), (bright, "")):
        assert mine.spatial_variance == pytest.approx(getattr(ref, "s_2_y" + suffix), rel=0.02)
        assert mine.column_variance == pytest.approx(getattr(ref, "s_2_y_col" + suffix),
                                                     rel=0.02)
        assert mine.row_variance == pytest.approx(getattr(ref, "s_2_y_row" + suffix),
                                                  rel=0.02, abs=0.05)
        assert mine.pixel_variance == pytest.approx(getattr(ref, "s_2_y_pixel" + suffix),
                                                    rel=0.02)
    assert dark.spatial_variance == pytest.approx(float(np.var(K * dsnu, ddof=1)), rel=0.05)
    assert dark.column_variance == pytest.approx(float(np.var(K * col[0])), rel=0.2)
    assert dark.fixed_pattern_noise == pytest.approx(math.sqrt(dark.spatial_variance))
    assert bright.spatial_variance > dark.spatial_variance  # PRNU adds to the bright one
    json.dumps(bright.to_json(), allow_nan=False)


def test_temporal_noise_hard_cases():
    rng = np.random.default_rng(41)
    frames = np.stack([sensor(rng, 4000, (32, 32)) for _ in range(4)]).astype(float)
    drifted = frames + np.array([0.0, 5.0, -3.0, 10.0])[:, None, None]
    a, b = temporal_and_fixed_pattern(frames), temporal_and_fixed_pattern(drifted)
    assert b.temporal_variance == pytest.approx(a.temporal_variance)  # drift is not noise
    assert a.u_temporal_variance == pytest.approx(
        a.temporal_variance * math.sqrt(2 / (32 * 32 * 3)))
    z = temporal_and_fixed_pattern(np.zeros((2, 8, 8)))
    assert (z.temporal_variance, z.spatial_variance, z.fixed_pattern_noise) == (0.0, 0.0, 0.0)
    for bad, reason in ((np.zeros((1, 8, 8)), "too-few"), (np.zeros((8, 8)), "shape"),
                        (np.full((2, 4, 4), np.inf), "non-finite")):
        with pytest.raises(RefusedFit) as e:
            temporal_and_fixed_pattern(bad)
        assert e.value.reason == reason


@pytest.mark.parametrize("pattern", ["RGGB", "BGGR"])
def test_bayer_mosaic_noise_per_channel_is_the_demosaiced_closed_form(pattern):
    """A flat grey patch as a Bayer mosaic with white noise sigma per site, demosaiced as an
    audit does (Malvar 2004): each channel's sigma is sigma times ``sqrt(mean over the CFA
    sites of sum(k^2))`` of its Malvar kernels (tests/measure/malvar.py: G 0.884, R and B
    0.992, Y 0.833), within 2 % (256 x 256 sites, 3 seeds), and the SNR the mean over it."""
    level, sigma = 0.3, 0.01
    for seed in range(3):
        mosaic = level + np.random.default_rng(seed).normal(0.0, sigma, (256, 256))
        rgb = demosaic(mosaic, pattern)[2:-2, 2:-2]
        p = patch_noise(rgb.reshape(-1, 3))
        for name in "RGBY":
            c = p.channel(name)
            expected = sigma * malvar.noise_factor(name)
            assert c.sigma == pytest.approx(expected, rel=0.02), (seed, name)
            assert c.snr == pytest.approx(level / expected, rel=0.02), (seed, name)
