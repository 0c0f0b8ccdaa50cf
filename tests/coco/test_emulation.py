"""Tests for fidelity.coco.emulation against closed forms and colour-science."""

from __future__ import annotations

import numpy as np
import pytest

from fidelity.camera.model import camera_from_dict
from fidelity.coco.emulation import (
    EMULATION_METHODS,
    _trilinear,
    camera_samples,
    emulation_accuracy,
    fit_emulation,
    fit_root_polynomial,
    root_polynomial_terms,
    training_reflectances,
)
from fidelity.colour.colorimetry import delinearize_srgb, linearize_srgb
from fidelity.core.errors import UnknownNameError

#: Rotation of linear RGB by -30 degrees about the grey axis (cameras/bad-hue-rotation.toml).
HUE_MATRIX = np.array([[0.91068, 0.33333, -0.24402], [-0.24402, 0.91068, 0.33333],
                       [0.33333, -0.24402, 0.91068]])


def matrix_camera(matrix: np.ndarray, tone: str = "srgb", bits: int | None = None):
    """Exact (CIE CMF) sensor + a given CCM: its colour rendering has a closed form."""
    d = {"name": "m", "sensitivities": {"source": "ideal"},
         "white_balance": {"method": "illuminant"},
         "ccm": {"method": "matrix", "matrix": matrix.tolist()}, "tone": {"curve": tone}}
    if bits:
        d["quantisation"] = {"bits": bits}
    return camera_from_dict(d)


def closed_form(x: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """sRGB encode(clip(M @ linearize(x))) -- the matrix camera's output for reference x."""
    return delinearize_srgb(np.clip(linearize_srgb(x) @ matrix.T, 0.0, 1.0))


def test_root_polynomial_terms_match_colour_science() -> None:
    import colour

    rng = np.random.default_rng(1)
    x = rng.normal(0.3, 0.4, (200, 3))  # includes negative components (out of gamut)
    ref = colour.characterisation.polynomial_expansion_Finlayson2015(x, 2, True)
    np.testing.assert_allclose(root_polynomial_terms(x), ref, atol=1e-12)


def test_fit_root_polynomial_recovers_a_known_mapping() -> None:
    rng = np.random.default_rng(2)
    m = rng.normal(0, 0.3, (3, 6)) + np.hstack([np.eye(3), np.zeros((3, 3))])
    x = rng.uniform(0, 1, (60, 3))
    y = root_polynomial_terms(x) @ m.T
    np.testing.assert_allclose(fit_root_polynomial(x, y), m, atol=1e-9)


def test_fit_root_polynomial_equals_colour_sciences() -> None:
    """The fit equals colour-science's ``matrix_colour_correction`` ("Finlayson 2015", degree
    2, root-polynomial), the function it replaces on the COCO pipeline's path."""
    import colour

    rng = np.random.default_rng(5)
    x = rng.normal(0.3, 0.4, (150, 3))
    y = x @ rng.normal(0, 0.5, (3, 3)) + rng.normal(0, 0.02, (150, 3))
    ref = colour.characterisation.matrix_colour_correction(
        x, y, method="Finlayson 2015", degree=2, root_polynomial_expansion=True)
    np.testing.assert_allclose(fit_root_polynomial(x, y), ref, rtol=1e-13, atol=1e-13)


def test_shipped_training_reflectances_are_colour_sciences() -> None:
    """The training set read from the shipped file equals the one built from colour-science
    itself (the code it replaces: its datasets, resampled to the grid), to the last bit."""
    import colour

    from fidelity.coco.emulation import _msds_rows

    got = training_reflectances("colour-science")
    rows = list(got.reflectance[:24])
    t = colour.characterisation.read_training_data_rawtoaces_v1()
    rows += list(_msds_rows(t.wavelengths, t.values))
    for group in (colour.quality.SDS_TCS, colour.quality.SDS_VS):
        rows += [_msds_rows(sd.wavelengths, sd.values[:, None])[0]
                 for sds in group.values() for sd in sds.values()]
    for name in ("ColorChecker N Ohta", "ISO 17321-1", "PMC"):
        rows += [_msds_rows(sd.wavelengths, sd.values[:, None])[0]
                 for sd in colour.SDS_COLOURCHECKERS[name].values()]
    np.testing.assert_array_equal(got.reflectance, np.clip(np.vstack(rows), 0.0, None))
    assert got.names[24] == f"rawtoaces v1 training data: {t.labels[0]}"


def test_training_set_holds_chart_and_colour_science_data() -> None:
    s = training_reflectances("colour-science")
    chart = training_reflectances("chart")
    np.testing.assert_array_equal(s.reflectance[:24], chart.reflectance)
    assert [n.split(": ", 1)[1] for n in s.names[:24]] == list(chart.names)
    assert s.sources["rawtoaces v1 training data"] == 190
    assert s.reflectance.shape[0] == sum(s.sources.values()) > 300
    assert np.all(s.reflectance >= 0)


@pytest.mark.parametrize("method", EMULATION_METHODS)
def test_exact_camera_emulates_to_identity(method: str) -> None:
    cam = camera_from_dict({"name": "i", "sensitivities": {"source": "ideal"},
                            "white_balance": {"method": "illuminant"}, "tone": {"curve": "linear"}})
    emu = fit_emulation(cam, "D65", method)
    x = np.random.default_rng(3).uniform(0, 1, (3000, 3))
    # white balance gains of the tabulated D65 vs the sRGB white differ by ~1e-4
    assert np.abs(emu.apply(x) - x).max() < 2e-3


@pytest.mark.parametrize("training", ["chart", "colour-science"])
def test_matrix_camera_is_emulated_in_closed_form(training: str) -> None:
    emu = fit_emulation(matrix_camera(HUE_MATRIX), "D65", "root-polynomial", training)
    np.testing.assert_allclose(emu.matrix[:, 3:], 0.0, atol=1e-3)  # no root terms needed
    x = np.random.default_rng(4).uniform(0, 1, (3000, 3))
    assert np.abs(emu.apply(x) - closed_form(x, HUE_MATRIX)).max() < 2e-3


def test_quantisation_is_applied() -> None:
    emu = fit_emulation(matrix_camera(np.eye(3), bits=3), "D65", "root-polynomial", "chart")
    y = emu.apply(np.random.default_rng(5).uniform(0, 1, (500, 3)))
    np.testing.assert_allclose(y * 7, np.round(y * 7), atol=1e-9)


def test_camera_samples_agree_with_the_renderer() -> None:
    """Independent paths: render_chart paints and samples an image; camera_samples does not."""
    from fidelity.camera.render import render_chart

    cam = camera_from_dict({"name": "n", "sensitivities": {"source": "Nikon 5100 (NPL)"},
                            "exposure": {"mode": "auto"},
                            "white_balance": {"method": "grey-world"},
                            "ccm": {"method": "fit"}, "tone": {"curve": "srgb"}})
    s = camera_samples(cam, "A", training_reflectances("chart"))
    r = render_chart(cam, "A")
    np.testing.assert_allclose(s.camera_srgb, np.clip(r.measurement.srgb, 0, 1), atol=1e-9)
    np.testing.assert_allclose(s.reference_srgb, np.clip(r.measurement.reference_srgb, 0, 1),
                               atol=1e-9)


def test_trilinear_is_exact_for_affine_functions() -> None:
    g = np.linspace(0, 1, 5)
    grid = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1)
    a = np.array([[0.2, 0.5, -0.1], [0.0, 1.0, 0.3], [0.7, -0.2, 0.1]])
    lut = grid @ a.T + 0.05
    x = np.random.default_rng(6).uniform(0, 1, (100, 3))
    np.testing.assert_allclose(_trilinear(lut, x), x @ a.T + 0.05, atol=1e-12)


def test_lut3d_reproduces_training_colours_better_in_sample() -> None:
    cam = camera_from_dict({"name": "s", "sensitivities": {"source": "Sigma SDMerrill (NPL)"},
                            "exposure": {"mode": "auto"},
                            "white_balance": {"method": "illuminant"},
                            "ccm": {"method": "fit"}, "tone": {"curve": "srgb"}})
    from fidelity.colour.colorimetry import delta_e_2000, srgb_to_lab

    errs = {}
    for m in EMULATION_METHODS:
        emu = fit_emulation(cam, "F11", m)
        s = emu.samples
        errs[m] = delta_e_2000(srgb_to_lab(emu.apply(s.reference_srgb)),
                               srgb_to_lab(s.camera_srgb)).mean()
    assert errs["lut3d"] < errs["root-polynomial"] < 3.0


@pytest.mark.slow
def test_distinct_colour_path_table_and_float_path_give_the_same_codes(shared) -> None:
    """The two 8-bit paths of apply_uint8 (the first images mapped on their distinct colours;
    later ones through the 2^24-entry table, built in about 5 s from per-channel look-ups of
    the root-polynomial terms) and the float path give the same codes, on random pixels and on
    real photos (every colour a COCO image holds). The lut3d table is apply() on every triple,
    the distinct-colour path's own computation."""
    from PIL import Image

    from fidelity.coco.dataset import to_uint8

    emu = fit_emulation(matrix_camera(HUE_MATRIX), "D65", "root-polynomial", "chart")
    photos = sorted((shared / "coco" / "val2017").glob("*.jpg"))[:2]
    images = [np.random.default_rng(7).integers(0, 256, (8, 9, 3), dtype=np.uint8)]
    images += [np.asarray(Image.open(p).convert("RGB")) for p in photos]
    direct = [emu.apply_uint8(img) for img in images]
    assert emu._cube is None  # a few images: no table
    emu.cube()
    for img, d in zip(images, direct, strict=True):
        np.testing.assert_array_equal(emu.apply_uint8(img), d)
    np.testing.assert_array_equal(direct[0], to_uint8(emu.apply(images[0] / 255.0)))
    # the table of a few images' own colours (a validation run on a few images): the rows of
    # the full table for those colours; an image with another colour is refused
    from fidelity.coco.dataset import PixelMap, colour_codes

    codes = np.unique(np.concatenate([colour_codes(img).ravel() for img in images]))
    own = PixelMap.of_codes("hue", codes, emu.map_codes(codes))
    full = PixelMap("hue", None, "cube", emu.cube())
    for img in images:
        np.testing.assert_array_equal(own(img), full(img))
    gap = np.flatnonzero(np.diff(codes.astype(np.int64)) > 1)[0]  # the first colour left out
    between = int(codes[gap]) + 1
    outside = [c for c in (0, (1 << 24) - 1) if c not in codes]  # below the first, above the last
    for code in [between, *outside]:
        other = images[1].copy()
        other[5, 7] = [(code >> 16) & 255, (code >> 8) & 255, code & 255]
        with pytest.raises(RuntimeError, match="colours its table was not made for"):
            own(other)


def test_a_table_of_some_colours_checks_its_codes() -> None:
    """Codes must be sorted and distinct with one (r, g, b) row each; an empty table refuses
    every image; the 24-bit code is (r << 16) | (g << 8) | b."""
    from fidelity.coco.dataset import PixelMap, colour_codes
    from fidelity.core.errors import InvalidValueError

    assert colour_codes(np.array([[[1, 2, 3], [255, 255, 255]]], np.uint8)).tolist() == [
        [66051, (1 << 24) - 1]]
    for codes, values in [([3, 1], [[0, 0, 0]] * 2), ([1, 1], [[0, 0, 0]] * 2),
                          ([1, 2], [[0, 0, 0]])]:
        with pytest.raises(InvalidValueError):
            PixelMap.of_codes("x", np.array(codes), np.array(values))
    empty = PixelMap.of_codes("x", np.empty(0, np.uint32), np.empty((0, 3), np.uint8))
    with pytest.raises(RuntimeError):
        empty(np.zeros((1, 1, 3), np.uint8))
    no_pixels = np.zeros((0, 4, 3), np.uint8)  # an image without pixels has no other colour
    assert empty(no_pixels).shape == (0, 4, 3)
    assert PixelMap.build("hue", 10.0, direct=True)(no_pixels).shape == (0, 4, 3)
    two = PixelMap.of_codes("x", np.array([0, 66051]), np.array([[9, 9, 9], [7, 8, 9]]))
    img = np.array([[[1, 2, 3], [0, 0, 0], [1, 2, 3]]], np.uint8)
    assert two(img).tolist() == [[[7, 8, 9], [9, 9, 9], [7, 8, 9]]]


def test_the_table_is_built_once_enough_distinct_colours_were_mapped(monkeypatch) -> None:
    """After CUBE_AFTER_COLOURS distinct colours mapped one image at a time, apply_uint8 builds
    the table (a sweep's images then cost one look-up per pixel)."""
    import fidelity.coco.emulation as em

    monkeypatch.setattr(em, "CUBE_AFTER_COLOURS", 100)
    emu = fit_emulation(matrix_camera(HUE_MATRIX), "D65", "root-polynomial", "chart")
    built = []
    monkeypatch.setattr(type(emu), "cube", lambda self, chunk=0: built.append(1) or
                        np.zeros((1 << 24, 3), np.uint8))
    rng = np.random.default_rng(3)
    emu.apply_uint8(rng.integers(0, 256, (8, 9, 3), dtype=np.uint8))  # 72 colours
    assert not built
    emu.apply_uint8(rng.integers(0, 256, (8, 9, 3), dtype=np.uint8))  # 144 in all
    assert not built
    emu.apply_uint8(rng.integers(0, 256, (8, 9, 3), dtype=np.uint8))  # now over 100
    assert built


def test_table_entry_of_a_pixel_is_its_own_colour() -> None:
    """Fast twin of the test above: the table row apply_uint8 reads for a pixel is the one
    cube() fills from that pixel's code values (so table and float path agree)."""
    from fidelity.coco.dataset import all_triples

    img = np.random.default_rng(7).integers(0, 256, (8, 9, 3), dtype=np.uint8)
    idx = (img[..., 0].astype(np.uint32) << 16) | (img[..., 1].astype(np.uint32) << 8) \
        | img[..., 2]
    for i, pixel in zip(idx.ravel(), img.reshape(-1, 3), strict=True):
        np.testing.assert_array_equal(all_triples(int(i), int(i) + 1)[0], pixel / 255.0)


def test_accuracy_of_an_exactly_emulable_camera_is_small() -> None:
    emu = fit_emulation(matrix_camera(HUE_MATRIX), "D65", "root-polynomial", "chart")
    acc = emulation_accuracy(emu).summary()
    # the only differences left: 8-bit rounding of the chart and out-of-gamut (cyan) clipping
    assert acc.chart_mean_delta_e < 0.5
    assert abs(acc.emulated_chart_delta_e - acc.camera_chart_delta_e) < 0.5


def test_unknown_method_and_training_are_named() -> None:
    with pytest.raises(UnknownNameError, match="emulation method"):
        fit_emulation(matrix_camera(np.eye(3)), method="spline")
    with pytest.raises(UnknownNameError, match="training set"):
        training_reflectances("munsell")


def test_holdout_training_set_leaves_the_chart_out() -> None:
    full = training_reflectances("colour-science")
    held = training_reflectances("colour-science-no-chart")
    assert len(held.names) == len(full.names) - 24
    assert not any(n.startswith("chart") for n in held.names)
    np.testing.assert_array_equal(held.reflectance, full.reflectance[24:])
