"""The covariance of a window mean from its block means keeps the block means' channel
correlation (issue 59's 12 MP under-coverage), checked against a Monte Carlo of the mean."""

import numpy as np

from fidelity.measure import uncertainty as unc


def _window(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    # 64 blocks of 256 pixels: each block its own independent offset per channel (the
    # block-level noise a JPEG leaves), each pixel one common noise in all channels (luma)
    blocks = np.repeat(np.arange(64), 256)
    offset = rng.normal(0.0, 0.02, (64, 3))[blocks]
    common = rng.normal(0.0, 0.1, (blocks.size, 1))
    return 0.5 + offset + common, blocks.astype(np.int64)


def test_block_mean_covariance_matches_monte_carlo_of_the_mean() -> None:
    rng = np.random.default_rng(1)
    means = np.array([_window(rng)[0].mean(axis=0) for _ in range(1500)])
    truth = np.cov(means, rowvar=False)
    x, b = _window(np.random.default_rng(2))
    stated = unc.block_mean_covariance(x, b)
    assert stated is not None
    corr = stated / np.sqrt(np.outer(np.diag(stated), np.diag(stated)))
    true_corr = truth / np.sqrt(np.outer(np.diag(truth), np.diag(truth)))
    # the block means barely correlate; the pixels correlate by about 0.96
    assert np.abs(true_corr[np.triu_indices(3, 1)]).max() < 0.25
    assert np.abs(corr - true_corr).max() < 0.35
    np.testing.assert_allclose(np.diag(stated), np.diag(truth), rtol=0.5)
    # the spread's covariance over its count is this, not the pixel correlation scaled
    sp = unc.patch_spread(x, blocks=b)
    covs, _ = unc.spread_covariances([sp])
    np.testing.assert_allclose(covs[0], stated, rtol=1e-9)
    pixel_corr = np.corrcoef(x, rowvar=False)[0, 1]
    assert pixel_corr > 0.9


def test_patch_spread_design_effect_is_block_design_effects():
    """patch_spread derives each channel's design effect from the block-mean covariance it
    computes: the value block_design_effect gives on the same pixels and blocks."""
    rng = np.random.default_rng(7)
    side, nb = 16, 12
    block_means = rng.normal(0, 0.02, (nb * nb, 3))
    rows, cols = np.divmod(np.arange((side * nb) ** 2), side * nb)
    blocks = unc.image_blocks(rows, cols, side * nb)
    for flat_channel in (None, 2):
        pixels = block_means[blocks] + rng.normal(0, 0.05, (blocks.size, 3))
        if flat_channel is not None:
            pixels[:, flat_channel] = 0.5
        spread = unc.patch_spread(pixels, blocks=blocks)
        assert spread.design is not None
        np.testing.assert_allclose(spread.design, unc.block_design_effect(pixels, blocks),
                                   rtol=1e-12)
        assert spread.design.max() > 1.5


def test_equal_codes_decoded_with_round_off_are_flat_with_no_design_effect():
    """A noise-free 8-bit patch: every pixel the same code, decoded to linear values that
    differ by round-off alone (as numpy's SIMD loops and their scalar tails leave them). The
    channel is flat, its design effect 1, not the ratio of two round-off spreads (a recorded
    gate once stated "largest 3.25e+05")."""
    rng = np.random.default_rng(3)
    side, nb = 16, 6
    rows, cols = np.divmod(np.arange((side * nb) ** 2), side * nb)
    blocks = unc.image_blocks(rows, cols, side * nb)
    base = np.array([0.0578054, 0.2140411, 0.5])
    ulp = np.spacing(base)
    pixels = base + rng.integers(-2, 3, (blocks.size, 3)) * ulp  # a few ulps apart
    pixels[:, 1] = base[1] + (blocks % 2) * 4 * ulp[1]  # whole blocks apart: a "cluster"
    spread = unc.patch_spread(pixels, blocks=blocks)
    assert spread.flat.all()
    assert spread.design is not None
    np.testing.assert_array_equal(spread.design, np.ones(3))
    covs, _ = unc.spread_covariances([spread])
    np.testing.assert_array_equal(covs[0], np.zeros((3, 3)))
    # real noise, however small against the value, is not flat
    noisy = base + rng.normal(0.0, 1e-9, (blocks.size, 3))
    assert not unc.flat_channels(noisy).any()
    assert unc.flat_channels(np.zeros((0, 3))).all()


def _bits(a: object) -> bytes:
    return np.ascontiguousarray(np.asarray(a)).tobytes()


def test_patch_spread_statistics_are_numpys_bit_for_bit():
    """patch_spread computes its statistics in one pass over the pixels beside their codes
    (issue 59: the audit's 24 windows): each is bit for bit what numpy's own cov, mean, var,
    std, ptp and max give, so that an audit's JSON does not move in its last digits."""
    rng = np.random.default_rng(11)
    for n in (1, 2, 3, 7, 100, 4097, 32768):
        codes8 = rng.integers(0, 256, (n, 3)).astype(np.uint8)
        codes = (codes8.astype(np.float32) * np.float32(1 / 255)).astype(np.float64)
        for lin in ((codes8 / 255.0) ** 2.2, rng.normal(0.0, 1.0, (n, 3)),
                    np.full((n, 3), 0.2) + rng.normal(0.0, 1e-17, (n, 3))):
            rows = np.sort(rng.integers(0, 3000, n))
            blocks = unc.image_blocks(rows, rng.integers(0, 300, n), 4000)
            sp = unc.patch_spread(lin, codes, blocks)
            if n >= 2:
                assert _bits(sp.covariance) == _bits(np.cov(lin, rowvar=False, ddof=1))
            flat = np.ptp(lin, axis=0) <= (unc.ROUNDOFF_ULPS * np.finfo(np.float64).eps
                                           * np.max(np.abs(lin), axis=0))
            assert _bits(sp.flat) == _bits(flat)
            assert _bits(sp.code_mean) == _bits(codes.mean(axis=0))
            assert _bits(sp.code_std) == _bits(codes.std(axis=0))
            assert _bits(unc.flat_channels(lin)) == _bits(flat)
            cols = unc._Columns.of(lin)
            assert _bits(cols.mean) == _bits(lin.mean(axis=0))
            if n >= 2:
                assert _bits(cols.variance(ddof=1)) == _bits(lin.var(axis=0, ddof=1))


def test_a_coded_window_spread_is_the_general_one_bit_for_bit():
    """An integer window's spread (issue 59: its lattice sample picked whole pixels at a time
    and gathered beside its code values, pixels._coded_window_spread) is, bit for bit, the
    spread of the same sample picked, linearised and located the general way."""
    from fidelity.chart.image import as_float32
    from fidelity.chart.locate import locate_chart
    from fidelity.measure import pixels

    rng = np.random.default_rng(4)
    for dtype, encoding in ((np.uint8, "srgb"), (np.uint16, "linear")):
        top = np.iinfo(dtype).max
        img = rng.integers(0, top + 1, (1500, 2000, 3)).astype(dtype)
        corners = np.array([[300.0, 280.0], [1700.0, 310.0], [1680.0, 1220.0], [320.0, 1190.0]])
        loc = locate_chart(corners, img.shape, rows=4, cols=6, window=0.9,
                           patch_names=[str(k) for k in range(24)])
        assert any(unc.block_sample(w.y0, w.x0, w.mask) is not None for w in loc.windows[:6])
        for win in loc.windows[:6]:
            vals = win.values(img)
            got = pixels._window_spread(vals, None, encoding, "keep", np.eye(3), True,
                                        1.0 / top, win, img.shape[1])
            keep = unc.block_sample(win.y0, win.x0, win.mask)
            sub = vals if keep is None else vals[keep]
            lin = pixels._code_linear(np.dtype(dtype).str, encoding)[sub]
            codes = as_float32(sub).astype(np.float64)
            rows, cols = win.indices()
            if keep is not None:
                rows, cols = rows[keep], cols[keep]
            want = unc.patch_spread(lin, codes, unc.image_blocks(rows, cols, img.shape[1]),
                                    count=len(vals))
            for field in ("covariance", "flat", "code_mean", "code_std", "design",
                          "clustered"):
                assert _bits(getattr(got, field)) == _bits(getattr(want, field)), field
            assert (got.count, got.sampled) == (want.count, want.sampled)
