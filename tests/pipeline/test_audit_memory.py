"""The audit's memory is bounded per megapixel (issue 30): images are read at their native
depth a band of rows at a time, the finder reduces them a band at a time, the patches are
sampled from windows; each step is checked against the whole-image float computation it
replaces, and whole ``fidelity audit`` processes against their max RSS."""

from __future__ import annotations

import json
import math
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from fidelity.chart import image, locate
from fidelity.chart.find import view
from fidelity.chart.image import as_float32, read_image
from fidelity.measure.blindspots import effective_bits
from fidelity.measure.pixels import measure_pixels
from tests.fixtures.photos import photo, true_corners, write_image
from tests.fixtures.processes import run_process

ROOT = Path(__file__).resolve().parents[2]


def _write(path: Path, pixels: np.ndarray, fmt: object) -> None:
    import OpenImageIO as oiio

    out = oiio.ImageOutput.create(str(path))
    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], fmt)
    assert out.open(str(path), spec)
    out.write_image(pixels)
    out.close()


@pytest.mark.parametrize(("suffix", "dtype", "fmt"), [
    (".png", np.uint8, "uint8"), (".png", np.uint16, "uint16"), (".exr", np.float16, "half"),
    (".tif", np.float32, "float")])
def test_native_read_is_the_float_read_bit_for_bit(tmp_path, monkeypatch, suffix, dtype, fmt):
    """OpenImageIO's own float conversion is the reference; bands of 5 rows are stitched."""
    import OpenImageIO as oiio

    rng = np.random.default_rng(1)
    if np.dtype(dtype).kind == "u":
        data = rng.integers(0, np.iinfo(dtype).max + 1, (37, 23, 3)).astype(dtype)
    else:
        data = rng.normal(0.5, 2.0, (37, 23, 3)).astype(dtype)
    path = tmp_path / f"img{suffix}"
    _write(path, data, getattr(oiio, {"uint8": "UINT8", "uint16": "UINT16", "half": "HALF",
                                      "float": "FLOAT"}[fmt]))
    whole = oiio.ImageInput.open(str(path))
    reference = whole.read_image(0, 0, 0, 3, "float")
    whole.close()
    monkeypatch.setattr(image, "READ_BAND_PIXELS", 5 * 23)
    native = read_image(path, native=True).pixels
    assert native.dtype == (np.float32 if fmt == "float" else dtype)
    assert np.array_equal(native, data)
    assert np.array_equal(as_float32(native), reference)
    assert np.array_equal(read_image(path).pixels, reference)


def test_pyramid_of_codes_equals_halving_the_float_image(monkeypatch):
    """Levels from 8-bit codes, a band of rows at a time, against the whole float32 image
    halved level by level with OpenCV (NaN-free codes, odd sizes cropped the same way)."""
    import cv2

    rng = np.random.default_rng(2)
    codes = rng.integers(0, 256, (203, 157, 3)).astype(np.uint8)
    monkeypatch.setattr(view, "PYRAMID_BAND_PIXELS", 7 * 157)
    pyramid = view.Pyramid(codes)
    level = as_float32(codes)
    for factor in (2, 4, 8):
        h, w = level.shape[0] // 2, level.shape[1] // 2
        level = cv2.resize(level[:2 * h, :2 * w], (w, h), interpolation=cv2.INTER_AREA)
        assert np.array_equal(pyramid.level(factor), level)
    assert np.array_equal(view.Pyramid(codes).level(8), level)  # straight from the image


def test_windows_are_the_pixels_whose_centres_map_into_them():
    """Each window's mask against mapping every pixel of its box to the grid."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        corners = np.array([[300, 250], [1200, 280], [1180, 800], [320, 760]], float)
        corners += rng.normal(0, 50, (4, 2))
        loc = locate.locate_chart(corners, (1000, 1500, 3))
        h_inv = np.linalg.inv(loc.homography)
        pixels = rng.integers(0, 256, (1000, 1500, 3)).astype(np.uint8)
        for (u0, v0), win in zip(locate.grid_centres(), loc.windows, strict=True):
            hh, ww = win.mask.shape
            yy, xx = np.mgrid[win.y0:win.y0 + hh, win.x0:win.x0 + ww]
            uv = locate.apply_homography(h_inv, np.stack([xx, yy], axis=-1).astype(float))
            inside = ((np.abs(uv[..., 0] - u0) <= 0.25 + 1e-9)
                      & (np.abs(uv[..., 1] - v0) <= 0.25 + 1e-9))
            assert np.array_equal(win.mask, inside)
            rows, cols = win
            assert np.array_equal(win.values(pixels), pixels[rows, cols])
            assert win.count == len(rows)


def test_codes_measure_as_their_float_values():
    """An 8-bit image measured as codes (histograms) and as float32 values (pixels)."""
    img = photo(800, 600, fill=0.5)
    corners = true_corners(800, 600, 0.5)
    for encoding in ("srgb", "linear"):
        a = measure_pixels(img, corners, encoding=encoding)
        b = measure_pixels(as_float32(img), corners, encoding=encoding)
        assert a.valid_pixels == b.valid_pixels
        np.testing.assert_allclose(a.measurement.delta_e, b.measurement.delta_e, atol=1e-9)
        np.testing.assert_allclose(a.measurement.noise, b.measurement.noise, atol=1e-12)
        assert a.exposure_ev == pytest.approx(b.exposure_ev, abs=1e-12)


def _steps_reference(codes: np.ndarray, code_range: int) -> tuple[float | None, int, int]:
    """The whole-image count of neighbour steps (numpy.unique of every small step)."""
    a = codes.astype(np.int64)
    limit = max(1, round(0.08 * code_range))
    small = np.concatenate([d[(d > 0) & (d <= limit)] for d in
                            (np.abs(np.diff(a, axis=0)).ravel(),
                             np.abs(np.diff(a, axis=1)).ravel())])
    if small.size < 2000:
        return None, 0, int(small.size)
    values, counts = np.unique(small, return_counts=True)
    mode = int(values[np.argmax(counts)])
    # the quantisation step: the largest divisor of the most common step of which 90 % of
    # the steps are multiples, else (a mode of 4 codes or more) the mean step about the mode
    # if 90 % lie within a code of its multiples, else 1
    q = next((float(d) for d in range(mode, 1, -1)
              if mode % d == 0 and np.mean(small % d == 0) >= 0.9), None)
    if q is None and mode < 4:
        q = 1.0
    if q is None:
        near = small[np.abs(small - mode) <= 1]
        spacing = float(near.mean())
        k = np.maximum(np.rint(small / spacing), 1)
        q = spacing if spacing > 1 and np.mean(np.abs(small - k * spacing) < 1) >= 0.9 else 1.0
    return math.log2(code_range / q + 1.0), q, int(small.size)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.int32])
def test_steps_counted_by_blocks_equal_the_whole_image_count(monkeypatch, dtype):
    from fidelity.measure import blindspots

    rng = np.random.default_rng(4)
    top = 255 if dtype == np.uint8 else 65535
    codes = np.clip(np.cumsum(rng.integers(-3, 4, (301, 211, 3)), axis=1) * (top // 255)
                    + top // 2, 0, top).astype(dtype)
    monkeypatch.setattr(blindspots, "STEP_BLOCK_PIXELS", 9 * 211 * 3)
    assert effective_bits(codes, top) == _steps_reference(codes, top)


def _audit(path: Path, out: Path) -> dict[str, object]:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return run_process([sys.executable, "-m", "fidelity", "audit", str(path), "--json",
                        str(out)], env, cwd=ROOT)


def test_audit_of_a_1x168_image_refuses_it_in_little_memory(tmp_path):
    """OpenCV's chart detector took 6 GB and 20 s on it; no chart can be in it."""
    path = tmp_path / "thin.png"
    write_image(path, np.full((168, 1, 3), 128, np.uint8))
    row = _audit(path, tmp_path / "r.json")
    assert row["exit"] == 2 and "too small" in str(row["stderr"])
    assert float(row["max_rss_mb"]) < 300  # type: ignore[arg-type]


@pytest.mark.slow
def test_audit_of_108_megapixels_stays_under_1_gb(tmp_path):
    """A 12000 x 9000 JPEG whose chart fills the frame: a whole ``fidelity audit`` process
    under 1 GB of max RSS (the image alone is 324 MB as codes, 1.3 GB as float32), the chart
    found where it was drawn and its patches measured as the codes drawn."""
    from fidelity.colour.charts import load_chart

    width, height = 12000, 9000
    path = tmp_path / "chart-108mp.jpg"
    write_image(path, photo(width, height, fill=0.9))
    out = tmp_path / "report.json"
    row = _audit(path, out)
    assert row["exit"] == 0, row["stderr"]
    assert float(row["max_rss_mb"]) < 1000  # type: ignore[arg-type]
    report = json.loads(out.read_text(encoding="utf-8"))
    found = np.array(report["source"]["corners"])
    assert np.abs(found - true_corners(width, height, 0.9)).max() < 1.0
    drawn = np.round(load_chart().srgb * 255) / 255
    measured = np.array([p["srgb"] for p in report["patches"]])
    assert np.abs(measured - drawn).max() < 2.5 / 255  # JPEG quality 90 on flat patches
