"""Exact 8-bit fast transforms, JPEG re-encoding with original settings, dataset writing."""

from __future__ import annotations

import colorsys
import hashlib
import io
import re

import numpy as np
import pytest
from PIL import Image, ImageCms, JpegImagePlugin

from fidelity.coco.dataset import (
    CHANNELWISE,
    PixelMap,
    calibrated_param,
    list_images,
    reference_transform,
    to_uint8,
    write_grid,
    write_transformed_dataset,
)
from fidelity.coco.jpeg import decode_jpeg, encode_jpeg, read_jpeg
from fidelity.core.errors import InputFileError, UnreachableTargetError
from fidelity.prediction.calibration import calibrate_transform
from fidelity.prediction.transforms import TRANSFORMS


def natural_image(h: int = 96, w: int = 128, seed: int = 0) -> np.ndarray:
    """Smooth gradients plus noise: many distinct colours, like a photo."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w]
    base = np.stack([x / w, y / h, 0.5 + 0.5 * np.sin(x / 9.0) * np.cos(y / 7.0)], -1)
    return to_uint8(np.clip(base + rng.normal(0, 0.05, base.shape), 0, 1))


@pytest.mark.parametrize("name", sorted(TRANSFORMS))
def test_fast_path_equals_reference_bit_for_bit(name: str) -> None:
    img = natural_image()
    target = 6.0
    param = calibrate_transform(name, target).param
    assert param is not None
    pm = PixelMap.build(name, param, chunk=1 << 22)
    assert pm.kind == ("channel" if name in CHANNELWISE else
                       "image" if name == "pull_mean" else "cube")
    fast = pm(img)
    ref = reference_transform(img, name, param)
    assert fast.dtype == np.uint8 and np.array_equal(fast, ref)
    # a run on a few images: each image mapped on its distinct colours, no table
    direct = PixelMap.build(name, param, direct=True)
    if pm.kind == "cube":
        assert direct.kind == "direct" and direct.lut is None
        assert np.array_equal(direct(img), fast)
        assert np.array_equal(direct(img[:1, :1]), fast[:1, :1])  # a one-pixel image
    else:
        assert direct.kind == pm.kind


def test_hue_reference_agrees_with_colorsys() -> None:
    """The slow reference itself, against Python's colorsys HSV (an independent HSV)."""
    img = natural_image(8, 8, seed=3)
    out = reference_transform(img, "hue", 40.0)
    for p, q in zip(img.reshape(-1, 3), out.reshape(-1, 3), strict=True):
        h, s, v = colorsys.rgb_to_hsv(*(p / 255.0))
        expect = np.rint(np.array(colorsys.hsv_to_rgb((h + 40 / 360) % 1, s, v)) * 255)
        assert np.abs(q.astype(int) - expect).max() <= 1


def test_contrast_lut_closed_form() -> None:
    pm = PixelMap.build("contrast-inc", 2.0)
    v = np.arange(256, dtype=np.uint8)
    expect = np.rint(np.clip(0.5 + 2.0 * (v / 255 - 0.5), 0, 1) * 255)
    np.testing.assert_array_equal(pm.lut, expect)


def test_channel_tables_on_odd_and_strided_images() -> None:
    """The two-bytes-at-a-time table path and the plain path agree with the reference."""
    pm = PixelMap.build("gamma-inc", 1.7)
    img = natural_image(33, 35, seed=5)  # odd number of bytes
    for view in (img, img[:, 1:], natural_image(32, 34, seed=6)):
        assert np.array_equal(pm(view), reference_transform(view, "gamma-inc", 1.7))


def test_baseline_is_identity() -> None:
    img = natural_image()
    assert np.array_equal(PixelMap.build("baseline", None)(img), img)


def test_unreachable_and_baseline_params() -> None:
    assert calibrated_param("contrast-inc", 0) == (None, None)
    p, reason = calibrated_param("saturation-inc", 24)
    assert p is None and "cannot reach" in reason


def _jpeg(img: np.ndarray, **kw) -> bytes:
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, "JPEG", **kw)
    return buf.getvalue()


def _settings_of(data: bytes) -> tuple[dict, int, str, bytes | None]:
    with Image.open(io.BytesIO(data)) as im:
        return (im.quantization, JpegImagePlugin.get_sampling(im) if im.mode == "RGB" else -1,
                im.mode, im.info.get("icc_profile"))


@pytest.mark.parametrize("sub,quality", [(0, 90), (2, 60), (1, 75)])
def test_reencode_keeps_tables_and_subsampling(sub: int, quality: int) -> None:
    data = _jpeg(natural_image(), quality=quality, subsampling=sub)
    rgb, settings = decode_jpeg(data)
    out = encode_jpeg(rgb, settings)
    q0, s0, _, _ = _settings_of(data)
    q1, s1, _, _ = _settings_of(out)
    assert q1 == q0 and s1 == s0 == sub


def test_grayscale_and_icc_rules() -> None:
    grey = natural_image()[..., 1]
    data = _jpeg(grey, quality=80)
    rgb, settings = decode_jpeg(data)
    assert rgb.shape[2] == 3 and np.array_equal(rgb[..., 0], rgb[..., 2])
    out = encode_jpeg(PixelMap.build("contrast-inc", 1.5)(rgb), settings)
    q, _, mode, _ = _settings_of(out)
    assert mode == "L" and q == _settings_of(data)[0]
    icc = ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB")).tobytes()
    data = _jpeg(natural_image(), quality=85, icc_profile=icc)
    rgb, settings = decode_jpeg(data)
    # pixel values are taken as stored (no colour management): same as decoding without ICC
    with Image.open(io.BytesIO(data)) as im:
        assert np.array_equal(rgb, np.asarray(im.convert("RGB")))
    assert _settings_of(encode_jpeg(rgb, settings))[3] == icc


def test_bad_jpeg_inputs(tmp_path) -> None:
    png = tmp_path / "a.jpg"
    Image.fromarray(natural_image()).save(png, "PNG")
    with pytest.raises(InputFileError, match="not a JPEG"):
        read_jpeg(png)
    (tmp_path / "b.jpg").write_bytes(b"junk")
    with pytest.raises(InputFileError, match=r"b\.jpg: not an image file \(no known image header\)$"):
        read_jpeg(tmp_path / "b.jpg")
    good = io.BytesIO()
    Image.fromarray(natural_image()).save(good, "JPEG")
    (tmp_path / "c.jpg").write_bytes(good.getvalue()[: len(good.getvalue()) // 2])
    with pytest.raises(InputFileError, match=r"c\.jpg: cannot decode JPEG: image file is truncated"):
        read_jpeg(tmp_path / "c.jpg")


def _sha(p) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def test_write_dataset_atomic_resumable_parallel(tmp_path) -> None:
    src = tmp_path / "src"
    src.mkdir()
    for i in range(4):
        (src / f"{i:03d}.jpg").write_bytes(_jpeg(natural_image(seed=i), quality=70,
                                                 subsampling=2))
    before = {p.name: _sha(p) for p in src.iterdir()}
    files = list_images(src)
    out = tmp_path / "out"
    r = write_transformed_dataset(files, out, "hue", 3.0, workers=2, progress=False)
    assert r["written"] == 4 and r["param"] == pytest.approx(5.3363, abs=1e-3)
    sub = out / "hue_de3"
    written = {p.name: p.stat().st_mtime_ns for p in sub.iterdir()}
    assert sorted(written) == sorted(before)  # no temporary files left behind
    r2 = write_transformed_dataset(files, out, "hue", 3.0, workers=1, progress=False)
    assert r2["written"] == 0 and r2["skipped"] == 4
    assert {p.name: p.stat().st_mtime_ns for p in sub.iterdir()} == written
    assert {p.name: _sha(p) for p in src.iterdir()} == before  # originals untouched
    # the written file decodes to the re-encoded transformed image
    rgb, settings = read_jpeg(src / "001.jpg")
    expect = decode_jpeg(encode_jpeg(reference_transform(rgb, "hue", r["param"]), settings))[0]
    assert np.array_equal(read_jpeg(sub / "001.jpg")[0], expect)
    # baseline: decode + re-encode only
    write_transformed_dataset(files, out, "hue", 0, progress=False)
    assert np.array_equal(read_jpeg(out / "baseline" / "001.jpg")[0],
                          decode_jpeg(encode_jpeg(rgb, settings))[0])
    res = write_grid(files[:1], tmp_path / "grid", ["saturation-inc"], [0, 24], progress=False)
    assert "skipped_reason" in res[1] and "cannot reach" in res[1]["skipped_reason"]
    with pytest.raises(UnreachableTargetError):
        write_transformed_dataset(files, out, "saturation-inc", 24, progress=False)
    inplace = tmp_path / "x" / "baseline"
    inplace.mkdir(parents=True)
    (inplace / "a.jpg").write_bytes((src / "000.jpg").read_bytes())
    with pytest.raises(InputFileError, match="overwrite an input"):
        write_transformed_dataset(list_images(inplace), tmp_path / "x", "hue", 0, progress=False)


def test_dataset_command(tmp_path) -> None:
    """The CLI: one cell, a rerun that keeps what exists, the grid form with an unreachable
    cell, and errors as one line with exit 2."""
    from click.testing import CliRunner

    from fidelity.cli import main

    src = tmp_path / "src"
    src.mkdir()
    for i in range(3):
        (src / f"{i:03d}.jpg").write_bytes(_jpeg(natural_image(seed=i), quality=80,
                                                 subsampling=2))
    before = {p.name: _sha(p) for p in src.iterdir()}

    def run(*args: object):
        return CliRunner().invoke(main, ["dataset", "--images", str(src), "--out",
                                         str(tmp_path / "out"), "--no-progress",
                                         *map(str, args)])

    def cells(r) -> dict[str, dict[str, object]]:  # type: ignore[no-untyped-def]
        """The fields of each printed cell line: SUBSET: param P, wrote N, kept K existing."""
        assert r.exit_code == 0, r.output
        out: dict[str, dict[str, object]] = {}
        for ln in r.output.splitlines():
            subset, _, rest = ln.partition(": ")
            m = re.fullmatch(r"param (\S+), wrote (\d+), kept (\d+) existing, \S+ s", rest)
            if m:
                out[subset] = {"param": None if m[1] == "-" else float(m[1]),
                               "wrote": int(m[2]), "kept": int(m[3])}
            elif rest.startswith("skipped: "):
                out[subset] = {"skipped": True}
        return out

    r = run("--transforms", "contrast-inc", "--targets", "3")  # default: one worker per core
    param = calibrate_transform("contrast-inc", 3.0).param
    c = cells(r)
    assert set(c) == {"contrast-inc_de3"}
    assert c["contrast-inc_de3"] == {"param": pytest.approx(param, rel=1e-5), "wrote": 3,
                                     "kept": 0}
    sub = tmp_path / "out/contrast-inc_de3"
    assert sorted(p.name for p in sub.iterdir()) == sorted(before)
    mtimes = {p.name: p.stat().st_mtime_ns for p in sub.iterdir()}
    r = run("--transforms", "contrast-inc", "--targets", "3", "--workers", "1")
    assert cells(r)["contrast-inc_de3"] == {"param": pytest.approx(param, rel=1e-5),
                                            "wrote": 0, "kept": 3}
    assert {p.name: p.stat().st_mtime_ns for p in sub.iterdir()} == mtimes  # kept as they were
    r = run("--transforms", "saturation-inc,hue", "--targets", "0,15")
    c = cells(r)
    assert set(c) == {"baseline", "saturation-inc_de15", "hue_de15"}, r.output
    assert c["baseline"] == {"param": None, "wrote": 3, "kept": 0}
    assert c["saturation-inc_de15"] == {"skipped": True}  # the chart cannot reach ΔE 15
    assert c["hue_de15"]["wrote"] == 3
    assert c["hue_de15"]["param"] == pytest.approx(calibrate_transform("hue", 15.0).param,
                                                   rel=1e-5)
    assert not (tmp_path / "out/saturation-inc_de15").exists()
    assert sorted(p.name for p in (tmp_path / "out/hue_de15").iterdir()) == sorted(before)
    assert {p.name: _sha(p) for p in src.iterdir()} == before  # originals untouched
    for args, names in (((), ("--transforms", "--targets")),
                        (("--transforms", "contrast-up", "--targets", "3"), ("contrast-up",)),
                        (("--transforms", "hue", "--targets", "3", "--param", "5",
                          "--workers", "0"), ("--workers",))):
        r = run(*args)
        assert r.exit_code == 2, r.output
        lines = [ln for ln in r.output.splitlines() if ln.strip()]
        assert len(lines) == 1 and lines[0].startswith("fidelity: error: "), r.output
        assert all(n in lines[0] for n in names) and "Traceback" not in r.output, r.output


def _kernels() -> list[str]:
    from fidelity.coco.dataset import _numba_kernels

    return ["numpy", "numba"] if _numba_kernels() is not None else ["numpy"]


@pytest.mark.shared
def test_pull_mean_fast_path_equals_reference_on_real_images(shared) -> None:
    """The per-colour pull_mean (count-weighted mean Lab) gives the reference's codes exactly,
    with the numpy kernel and the compiled one (when numba is installed)."""
    from fidelity.coco.dataset import PullMeanWorkspace, pull_mean_uint8
    from fidelity.coco.jpeg import read_jpeg

    files = sorted((shared / "coco/val2017").glob("*.jpg"))[:20]
    assert len(files) == 20
    workspaces = {k: PullMeanWorkspace() for k in _kernels()}  # reused across image sizes
    for f in files:
        img = read_jpeg(f)[0]
        for alpha in (0.95, 0.5):
            ref = reference_transform(img, "pull_mean", alpha)
            for kernel, ws in workspaces.items():
                assert np.array_equal(pull_mean_uint8(img, alpha, ws, kernel), ref), \
                    (f.name, alpha, kernel)


@pytest.mark.parametrize("kernel", ["numpy", "numba"])
def test_pull_mean_workspace_repeats_the_colorimetry(kernel: str) -> None:
    """Per-colour Lab round trip of the pull_mean fast path against fidelity.colour.colorimetry.

    Codes exact and Lab to 1e-12 on every code value of each channel, random triples, random
    Lab values in and far out of gamut (negative L, huge chroma: the clipped branch) and the
    near-black linear segments, with chunks small enough that several chunks and a short last
    chunk are used; the numba kernel gives the numpy kernel's bits.
    """
    from fidelity.coco.dataset import PullMeanWorkspace, pull_mean_uint8, to_uint8
    from fidelity.colour.colorimetry import lab_to_srgb, srgb_to_lab

    if kernel not in _kernels():
        pytest.skip("numba is not installed")
    rng = np.random.default_rng(7)
    codes = rng.integers(0, 256, (5000, 3)).astype(np.uint8)
    codes[:256] = np.arange(256, dtype=np.uint8)[:, None]
    codes[256:512, 0] = np.arange(256)
    codes[256:512, 1:] = 0
    ws = PullMeanWorkspace(chunk=777)
    lab = ws.lab_of_codes(codes, kernel).copy()
    np.testing.assert_allclose(lab.T, srgb_to_lab(codes / 255.0), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(lab, PullMeanWorkspace(chunk=1000).lab_of_codes(codes))
    labs = np.concatenate([srgb_to_lab(codes / 255.0),
                           rng.uniform([-10.0, -200.0, -200.0], [120.0, 200.0, 200.0], (5000, 3)),
                           rng.uniform([0.0, -3.0, -3.0], [9.0, 3.0, 3.0], (2000, 3))])
    got = ws.codes_of_lab(np.ascontiguousarray(labs.T), kernel)
    assert np.array_equal(got, to_uint8(lab_to_srgb(labs)))
    # tiny images (fewer colours than channels) and a workspace shrinking back to them
    for n in (1, 2, 3, 4, 2000):
        img = rng.integers(0, 256, (1, n, 3)).astype(np.uint8)
        for alpha in (0.0, 0.3, 1.0):
            assert np.array_equal(pull_mean_uint8(img, alpha, ws, kernel),
                                  reference_transform(img, "pull_mean", alpha)), (n, alpha)


def test_pull_mean_kernels_agree_and_are_named() -> None:
    from fidelity.coco.dataset import PullMeanWorkspace, pull_mean_kernel, pull_mean_uint8
    from fidelity.core.errors import UnknownNameError

    imgs = [natural_image(120, 160, seed=s) for s in range(3)]
    imgs.append(np.zeros((0, 3), np.uint8))
    for kernel in _kernels():
        ws = PullMeanWorkspace()
        for img in imgs:
            out = pull_mean_uint8(img, 0.6, ws, kernel)
            assert out.shape == img.shape and out.dtype == np.uint8
            if img.size:
                assert np.array_equal(out, reference_transform(img, "pull_mean", 0.6)), kernel
    assert pull_mean_kernel("numpy") == "numpy"
    assert pull_mean_kernel("auto") in ("numpy", "numba")
    with pytest.raises(UnknownNameError):
        pull_mean_kernel("cuda")


@pytest.mark.shared
def test_a_few_images_mapped_on_their_colours_equal_the_table_on_real_photos(shared) -> None:
    """A sweep cell of at most DIRECT_IMAGES images maps each image on its distinct colours
    (no 2^24-entry table): the table's codes on real photos; larger cells keep the table."""
    from fidelity.coco.executor import DIRECT_IMAGES, PixelTransform
    from fidelity.coco.jpeg import read_jpeg

    param = calibrate_transform("hue", 6.0).param
    few = PixelTransform.of("hue", param, images=DIRECT_IMAGES)
    many = PixelTransform.of("hue", param, images=DIRECT_IMAGES + 1)
    assert few.direct and not many.direct and few.key != many.key
    assert not PixelTransform.of("baseline", None, images=1).direct
    table, direct = many.build(), few.build()
    assert isinstance(table, PixelMap) and isinstance(direct, PixelMap)
    assert (table.kind, direct.kind) == ("cube", "direct")
    for f in sorted((shared / "coco/val2017").glob("*.jpg"))[:3]:
        img = read_jpeg(f)[0]
        assert np.array_equal(direct(img), table(img))
