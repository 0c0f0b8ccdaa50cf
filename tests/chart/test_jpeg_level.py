"""A large JPEG's finder level from libjpeg's DCT-scaled decode (issue 59)."""

from __future__ import annotations

import numpy as np
import pytest

from fidelity.chart.find import view
from fidelity.chart.find.cascade import find_chart
from fidelity.chart.image import read_image
from tests.fixtures.photos import photo, true_corners, write_image


@pytest.fixture(scope="module")
def jpeg(tmp_path_factory):
    path = tmp_path_factory.mktemp("jpeg") / "chart.jpg"
    write_image(path, photo(2400, 1800, seed=4, fill=0.6))
    return path


@pytest.mark.parametrize("factor", [2, 4])
def test_decoded_level_is_the_block_means_of_the_pixels(jpeg, factor):
    """The half- and quarter-size decodes against the pyramid's own block means of the
    pixels the reader decoded (an independent path: OpenImageIO's full decode, then area
    averages): within half a code on average and 4 codes (of 255) at 99 % of the pixels; more
    only at the sharp edges of the patches (the scaled IDCT keeps the blocks' low
    frequencies)."""
    img = read_image(jpeg, native=True)
    level = view.jpeg_level(jpeg, img.pixels, factor)
    assert level is not None and level.dtype == np.float32
    means = view.Pyramid(img.pixels).level(factor)
    assert level.shape == means.shape == (1800 // factor, 2400 // factor, 3)
    diff = np.abs(level - means) * 255
    assert diff.mean() < 0.5 and np.percentile(diff, 99) < 4.0, (diff.mean(), diff.max())


@pytest.mark.parametrize("factor", [2, 4])
def test_finder_on_the_decoded_level_finds_the_same_corners(jpeg, factor):
    """Given the decoded level, the finder finds the chart's corner patches where it finds
    them from the full image, within 0.5 px, and both within 1.5 px of the painted ones."""
    img = read_image(jpeg, native=True)
    level = view.jpeg_level(jpeg, img.pixels, factor)
    assert level is not None
    full = find_chart(img.pixels, encoding="srgb").corners
    fast = find_chart(img.pixels, encoding="srgb", levels={factor: level}).corners
    assert np.max(np.abs(fast - full)) < 0.5
    truth = true_corners(2400, 1800, fill=0.6)
    assert np.max(np.abs(fast - truth)) < 1.5 and np.max(np.abs(full - truth)) < 1.5


def test_a_decode_of_other_pixels_is_refused(jpeg):
    """Pixels that are not the file's (a reader's conversion) get no decoded level; a level
    of the wrong size is an error of the pyramid."""
    img = read_image(jpeg, native=True)
    other = (255 - img.pixels).astype(np.uint8)
    assert view.jpeg_level(jpeg, other, 4) is None
    assert view.jpeg_level(jpeg, img.pixels.astype(np.uint16), 4) is None
    assert view.jpeg_level(jpeg, img.pixels, 3) is None  # no such DCT scaling
    from fidelity.core.errors import InvalidValueError

    with pytest.raises(InvalidValueError):
        view.Pyramid(img.pixels, {4: np.zeros((10, 10, 3), np.float32)})


@pytest.mark.parametrize(("size", "factor"), [((3000, 4000), 2), ((9000, 12000), 4),
                                             ((1500, 3199), 1), ((1200, 1600), 1)])
def test_the_audit_decodes_the_level_the_search_view_reads(tmp_path, size, factor):
    """A JPEG whose long side is at least twice the search view's gets that level from the
    decoder (12 MP: half size, 108 MP: a quarter), others none; a PNG never."""
    from fidelity.chart.find.cascade import SEARCH_SIDE
    from fidelity.measure.pixels import _decoded_levels

    h, w = size
    assert view.level_factor(h, w, min(1.0, SEARCH_SIDE / max(h, w))) == factor
    if h * w > 20_000_000:  # the large cases: the rule above, without writing 108 MP files
        return
    pixels = np.full((h, w, 3), 128, np.uint8)
    pixels[: h // 2] = 40
    for suffix in ("jpg", "png"):
        path = tmp_path / f"grey.{suffix}"
        write_image(path, pixels)
        levels = _decoded_levels(read_image(path, native=True))
        if suffix == "png" or factor == 1:
            assert levels is None
        else:
            assert levels is not None and list(levels) == [factor]
            assert levels[factor].shape == (h // factor, w // factor, 3)


def test_the_level_decoded_beside_the_read_is_the_same(tmp_path):
    """measure_image decodes the search level in a thread while it reads the file: the level
    :func:`_search_level` names from the header is the one the pixels' size gives, and the
    level made from the early decode equals the one decoded after the read, bit for bit; a PNG,
    a small JPEG, a missing file and a file that is no image get no early decode."""
    from fidelity.chart.image import stored_size
    from fidelity.measure.pixels import _decode_search_level, _decoded_levels, _search_level

    pixels = np.full((3000, 4000, 3), 128, np.uint8)
    pixels[:1500] = 40
    path = tmp_path / "grey.jpg"
    write_image(path, pixels)
    assert stored_size(path) == (3000, 4000)
    early = _search_level(path)
    assert early == 2
    img = read_image(path, native=True)
    after = _decoded_levels(img)
    beside = _decoded_levels(img, early, _decode_search_level(path, early))
    assert after is not None and beside is not None
    assert np.array_equal(after[2], beside[2])
    small = tmp_path / "small.jpg"
    write_image(small, pixels[:1200, :1600])
    png = tmp_path / "grey.png"
    write_image(png, pixels)
    junk = tmp_path / "junk.jpg"
    junk.write_bytes(b"not a jpeg")
    assert [_search_level(p) for p in (small, png, junk, tmp_path / "missing.jpg")] == [None] * 4
    assert stored_size(junk) is None and stored_size(tmp_path / "missing.jpg") is None


def test_the_manual_states_the_thresholds():
    """docs/audit.md quotes the decoder's threshold and the noise lattice's as the code has
    them."""
    from pathlib import Path

    from fidelity.chart.find.cascade import SEARCH_SIDE
    from fidelity.measure.pixels import NOISE_SAMPLE_PIXELS

    text = (Path(__file__).resolve().parents[2] / "docs" / "audit.md").read_text("utf-8")
    assert f"long side is at least {2 * SEARCH_SIDE} pixels is decoded twice" in text
    assert f"of more than {NOISE_SAMPLE_PIXELS} pixels gives its noise" in text
    for factor in view.JPEG_LEVEL_FACTORS:
        assert f"REDUCED_COLOR_{factor}" in text


def test_an_srgb_view_is_the_decoded_scaled_encoded_region_bit_for_bit():
    """An sRGB view (issue 59: its later steps applied to the decoding table and looked up
    once) holds, value for value, the region's decoded codes scaled by the peak and clipped,
    and their 8-bit encoding in B, G, R order."""
    rng = np.random.default_rng(7)
    img = rng.integers(0, 256, (600, 800, 3)).astype(np.uint8)
    for region, side in (((0, 0, 800, 600), 300), ((40, 30, 500, 420), 1000)):
        got, peak = view.make_view(img, region, side, "srgb")
        codes, _ = view._prepare(view.Pyramid(img), region, side, "srgb", steps=True)
        linear = view._DECODE_LUT[codes] * np.float32(1.0 / peak)
        np.clip(linear, 0.0, 1.0, out=linear)
        steps = linear * np.float32(4095) + np.float32(0.5)
        bgr8 = np.ascontiguousarray(view._ENCODE_LUT[steps.astype(np.uint16)][..., ::-1])
        assert got.linear.dtype == np.float32 and got.linear.tobytes() == linear.tobytes()
        assert got.bgr8.shape == bgr8.shape and got.bgr8.tobytes() == bgr8.tobytes()


@pytest.mark.parametrize(("height", "factor"), [(1800, 4), (1800, 2), (40, 4), (9, 1)])
def test_the_level_is_compared_over_bands_of_rows(height, factor):
    """jpeg_level compares the channel means of the image and its level over the same bands
    of rows (an eighth of the rows: a whole-image pass cost 0.16 s of a 108 MP audit): numpy's
    means of the rows the bands name, the image's ``factor`` times as many; a level of fewer
    rows than a band is compared whole."""
    rng = np.random.default_rng(3)
    codes = rng.integers(0, 256, (height, 120, 3)).astype(np.uint8)
    h = height // factor
    reduced = rng.integers(0, 256, (h, 120 // factor, 3)).astype(np.uint8)
    full, level = view._band_means(codes, reduced, factor)
    band, stride = view.LEVEL_CHECK_BAND, view.LEVEL_CHECK_STRIDE
    rows = [y for y in range(h) if y % (band * stride) < band]
    image_rows = [y * factor + k for y in rows for k in range(factor)]
    assert np.allclose(full, codes[image_rows].reshape(-1, 3).mean(axis=0), rtol=0, atol=1e-9)
    assert np.allclose(level, reduced[rows].reshape(-1, 3).mean(axis=0), rtol=0, atol=1e-9)
    assert len(rows) == (h if h <= band else pytest.approx(h / stride, abs=band))


@pytest.mark.parametrize("shape", [(0, 4, 3), (7, 5, 3), (300, 500, 3)])
def test_the_view_lookup_is_numpy_indexing(shape):
    """_take (a band of indices converted at a time, for every table) gives numpy's
    ``table[index]`` for each table, the band edges and the tables' last entries included."""
    rng = np.random.default_rng(11)
    index = rng.integers(0, 65536, shape).astype(np.uint16)
    if index.size:
        index.reshape(-1)[[0, -1, view.TAKE_BAND - 1 if index.size > view.TAKE_BAND else 0]] \
            = 65535
    floats = rng.random(65536).astype(np.float32)
    codes = rng.integers(0, 256, 65536).astype(np.uint8)
    got_f, got_c = view._take(index, floats, codes)
    assert got_f.dtype == np.float32 and got_c.dtype == np.uint8
    assert got_f.shape == got_c.shape == shape
    assert np.array_equal(got_f, floats[index]) and np.array_equal(got_c, codes[index])


@pytest.mark.parametrize(("shape", "dtype"), [((600, 700, 3), np.float32), ((5, 7, 3), np.float64),
                                              ((0, 3, 3), np.float32)])
def test_the_view_codes_are_the_whole_array_formula(shape, dtype):
    """_codes (a band at a time in one small temporary) gives ``rint(clip(v, 0, 1) * top)``
    of the whole array as uint16, below 0, above 1 and a reversed (strided) view included."""
    rng = np.random.default_rng(5)
    values = (rng.random(shape) * 1.4 - 0.2).astype(dtype)
    for v in (values, values[:, ::-1]):
        ref = np.rint(np.clip(v, 0.0, 1.0) * np.float32(65535)).astype(np.uint16)
        got = view._codes(v, 65535)
        assert got.dtype == np.uint16 and np.array_equal(got, ref)
