"""Image reading: formats, channel naming, layers, and every kind of bad file.

Files are written by independent writers (the OpenEXR module, Pillow; OpenImageIO only for
formats they cannot write) and read back through fidelity.chart.image.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenEXR
import OpenImageIO as oiio
import pytest
from PIL import Image as PILImage

from fidelity.chart.image import read_image
from fidelity.core.errors import InputFileError
from fidelity.core.fileio import file_sha256

RNG = np.random.default_rng(4)
RGB = RNG.uniform(0.0, 4.0, size=(12, 17, 3)).astype(np.float32)


def exr(path: Path, channels: dict[str, np.ndarray]) -> Path:
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION},
                 {k: np.ascontiguousarray(v) for k, v in channels.items()}).write(str(path))
    return path


def oiio_write(path: Path, pixels: np.ndarray, fmt: str) -> Path:
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], fmt))
    out.write_image(pixels)
    out.close()
    return path


@pytest.mark.parametrize("dtype,rtol", [(np.float32, 0.0), (np.float16, 1e-3)])
@pytest.mark.parametrize("names", [("R", "G", "B"), ("r", "g", "b"), ("red", "green", "blue")])
def test_exr_channel_naming(tmp_path, dtype, rtol, names):
    # a scrambled channel order in the file must not matter
    p = exr(tmp_path / "a.exr", {names[2]: RGB[..., 2].astype(dtype), names[0]: RGB[..., 0].astype(dtype),
                                 names[1]: RGB[..., 1].astype(dtype), "A": np.ones(RGB.shape[:2], dtype)})
    img = read_image(p)
    assert img.pixels.shape == RGB.shape and img.pixels.dtype == np.float32
    np.testing.assert_allclose(img.pixels, RGB.astype(dtype).astype(np.float32), rtol=rtol)
    assert img.encoding == "linear"
    assert img.pixel_type == ("half" if dtype == np.float16 else "float")


def test_exr_layers(tmp_path):
    p = exr(tmp_path / "l.exr", {
        "diffuse.R": RGB[..., 0], "diffuse.G": RGB[..., 1], "diffuse.B": RGB[..., 2],
        "spec.R": RGB[..., 2], "spec.G": RGB[..., 0], "spec.B": RGB[..., 1],
        "depth.Z": RGB[..., 0],
    })
    np.testing.assert_array_equal(read_image(p, layer="diffuse").pixels, RGB)
    np.testing.assert_array_equal(read_image(p, layer="spec").pixels, RGB[..., [2, 0, 1]])
    with pytest.raises(InputFileError, match="several layers.*--layer"):
        read_image(p)
    with pytest.raises(InputFileError, match=r"no layer 'beauty'.*diffuse, spec"):
        read_image(p, layer="beauty")


def test_exr_single_layer_is_used_without_asking(tmp_path):
    p = exr(tmp_path / "s.exr", {"beauty.R": RGB[..., 0], "beauty.G": RGB[..., 1],
                                 "beauty.B": RGB[..., 2], "Z": RGB[..., 0]})
    img = read_image(p)
    np.testing.assert_array_equal(img.pixels, RGB)
    assert img.layer == "beauty"


def test_multipart_exr_by_part_name(tmp_path):
    p1 = OpenEXR.Part({"type": OpenEXR.scanlineimage}, {"RGB": RGB}, name="beauty")
    p2 = OpenEXR.Part({"type": OpenEXR.scanlineimage}, {"R": RGB[..., 1].copy(), "G": RGB[..., 1].copy(),
                                                        "B": RGB[..., 1].copy()}, name="albedo")
    OpenEXR.File([p1, p2]).write(str(tmp_path / "mp.exr"))
    np.testing.assert_array_equal(read_image(tmp_path / "mp.exr", layer="albedo").pixels,
                                  np.repeat(RGB[..., 1:2], 3, axis=-1))
    np.testing.assert_array_equal(read_image(tmp_path / "mp.exr", layer="beauty").pixels, RGB)


def test_exr_keeps_nan_inf_negative(tmp_path):
    bad = RGB.copy()
    bad[0, 0, 0], bad[1, 1, 1], bad[2, 2, 2] = np.nan, np.inf, -0.5
    img = read_image(exr(tmp_path / "b.exr", {"R": bad[..., 0], "G": bad[..., 1], "B": bad[..., 2]}))
    assert np.isnan(img.pixels[0, 0, 0]) and np.isinf(img.pixels[1, 1, 1]) and img.pixels[2, 2, 2] == -0.5


def test_hdr(tmp_path):
    p = oiio_write(tmp_path / "a.hdr", RGB, "float")
    img = read_image(p)
    assert img.encoding == "linear" and img.file_format == "hdr"
    # RGBE: an 8-bit mantissa per channel under the exponent of the pixel's largest channel
    assert np.all(np.abs(img.pixels - RGB) <= RGB.max(axis=-1, keepdims=True) / 128)


@pytest.mark.parametrize("suffix", ["png", "tif"])
def test_16bit(tmp_path, suffix):
    q = RNG.integers(0, 65536, size=(9, 11, 3), dtype=np.uint16)
    img = read_image(oiio_write(tmp_path / f"a.{suffix}", q, "uint16"))
    assert img.encoding == "srgb" and img.pixel_type == "uint16"
    np.testing.assert_allclose(img.pixels, q / 65535.0, atol=1e-7)


def test_8bit_png_and_jpeg(tmp_path):
    q = RNG.integers(0, 256, size=(16, 24, 3), dtype=np.uint8)
    PILImage.fromarray(q, "RGB").save(tmp_path / "a.png")
    img = read_image(tmp_path / "a.png")
    np.testing.assert_allclose(img.pixels, q / 255.0, atol=1e-7)
    flat = np.full((16, 16, 3), (200, 90, 30), np.uint8)
    PILImage.fromarray(flat, "RGB").save(tmp_path / "a.jpg", quality=100, subsampling=0)
    jpg = read_image(tmp_path / "a.jpg")
    assert jpg.encoding == "srgb" and jpg.file_format == "jpeg"
    np.testing.assert_allclose(jpg.pixels, flat / 255.0, atol=2.5 / 255)


def test_sha256(tmp_path):
    import hashlib

    (tmp_path / "x").write_bytes(b"abc")
    assert file_sha256(tmp_path / "x") == hashlib.sha256(b"abc").hexdigest()


# ----------------------------------------------------------------------------- bad input

def test_missing_file(tmp_path):
    with pytest.raises(InputFileError, match=r"nope\.exr.*does not exist"):
        read_image(tmp_path / "nope.exr")


def test_not_an_image(tmp_path):
    (tmp_path / "junk.png").write_bytes(b"this is not a png")
    with pytest.raises(InputFileError, match=r"junk\.png: cannot read image"):
        read_image(tmp_path / "junk.png")


@pytest.mark.parametrize("suffix", ["exr", "png", "jpg"])
def test_truncated(tmp_path, suffix, capfd):
    big = RNG.integers(0, 256, size=(64, 80, 3), dtype=np.uint8)
    src = tmp_path / f"full.{suffix}"
    if suffix == "exr":
        exr(src, {c: (big[..., i] / 255.0).astype(np.float32) for i, c in enumerate("RGB")})
    else:
        PILImage.fromarray(big, "RGB").save(src)
    data = src.read_bytes()
    (tmp_path / f"cut.{suffix}").write_bytes(data[: len(data) * 2 // 3])
    capfd.readouterr()
    with pytest.raises(InputFileError, match=rf"cut\.{suffix}: (truncated or corrupt|cannot read)"):
        read_image(tmp_path / f"cut.{suffix}")
    assert capfd.readouterr().err == ""  # libpng/libjpeg chatter is silenced


def test_one_channel_images(tmp_path):
    PILImage.fromarray(np.zeros((8, 8), np.uint8), "L").save(tmp_path / "grey.png")
    with pytest.raises(InputFileError, match=r"grey\.png: one-channel image"):
        read_image(tmp_path / "grey.png")
    PILImage.fromarray(np.zeros((8, 8, 2), np.uint8), "LA").save(tmp_path / "greya.png")
    with pytest.raises(InputFileError, match="one-channel image"):
        read_image(tmp_path / "greya.png")
    exr(tmp_path / "y.exr", {"Y": RGB[..., 0]})
    with pytest.raises(InputFileError, match=r"y\.exr: one-channel image \(Y\)"):
        read_image(tmp_path / "y.exr")


def test_unknown_channels(tmp_path):
    exr(tmp_path / "xyz.exr", {"X": RGB[..., 0], "Y": RGB[..., 1], "Z": RGB[..., 2]})
    with pytest.raises(InputFileError, match=r"xyz\.exr: unknown channels \(X, Y, Z\)"):
        read_image(tmp_path / "xyz.exr")


def test_pixel_limit_is_checked_before_decoding(tmp_path, monkeypatch):
    """More pixels than the limit: refused from the header (--max-pixels, then
    FIDELITY_MAX_PIXELS, then the default); RGBA and odd channel orders read only R, G, B."""
    from fidelity.chart.image import DEFAULT_MAX_PIXELS, pixel_limit
    from fidelity.core.errors import InvalidValueError

    rgba = np.concatenate([RGB, np.ones(RGB.shape[:2] + (1,), np.float32)], axis=2)
    p = oiio_write(tmp_path / "a.tif", rgba, "float")
    np.testing.assert_array_equal(read_image(p).pixels, RGB)
    assert read_image(p, max_pixels=12 * 17).width == 17
    with pytest.raises(InputFileError, match=r"a.tif: the image is 17x12 \(0.0 megapixels\), "
                                             r"more than the limit"):
        read_image(p, max_pixels=12 * 17 - 1)
    assert pixel_limit() == DEFAULT_MAX_PIXELS
    monkeypatch.setenv("FIDELITY_MAX_PIXELS", "2e8")
    assert pixel_limit() == 200_000_000 and pixel_limit(5) == 5
    for bad in ("0", "-3", "1.5", "lots", "inf"):
        monkeypatch.setenv("FIDELITY_MAX_PIXELS", bad)
        with pytest.raises(InvalidValueError, match=f"FIDELITY_MAX_PIXELS={bad}"):
            pixel_limit()


def test_folder_images_are_in_natural_order_ties_broken_by_name(tmp_path):
    from fidelity.chart.image import folder_images

    names = ["f10.exr", "f2.png", "f02.png", "f1.tif", "F3.JPG", "f2b.png", "notes.txt",
             ".f0.png"]
    for name in reversed(names):
        (tmp_path / name).write_bytes(b"")
    (tmp_path / "f4.png").mkdir()
    assert [p.name for p in folder_images(tmp_path)] == [
        "F3.JPG", "f1.tif", "f02.png", "f2.png", "f2b.png", "f10.exr"]
