"""Spectral data, integration and the scene-consistent reference, against independent references
(CIE published white points, colour-science as a second implementation, the SAFE-COLOR table)."""

from __future__ import annotations

import colour
import numpy as np
import pytest

from fidelity.colour.charts import load_chart
from fidelity.colour.colorimetry import (
    WHITEPOINT_D65_XYZ,
    delta_e_2000,
    matrix_chromatic_adaptation,
)
from fidelity.colour.spectral import (
    SPECTRA_SETS,
    WAVELENGTHS_NM,
    load_illuminant,
    load_patch_spectra,
    resample,
    scene_reference,
    tristimulus,
    wavelength_grid,
)
from fidelity.core.errors import FidelityError, InputFileError, InvalidValueError, UnknownNameError

SRGB_D65_XY = np.array([0.3127, 0.3290])


def test_grid_is_380_780_at_1nm_and_steps_divide_it() -> None:
    assert WAVELENGTHS_NM[0] == 380 and WAVELENGTHS_NM[-1] == 780 and WAVELENGTHS_NM.size == 401
    assert wavelength_grid(10).size == 41
    with pytest.raises(InvalidValueError, match="wavelength step"):
        wavelength_grid(3)


def test_resample_extrapolation_rules() -> None:
    wl, v = np.array([400.0, 500.0]), np.array([0.2, 0.4])
    g = np.array([380.0, 450.0, 600.0])
    np.testing.assert_allclose(resample(wl, v, g, extrapolation="constant"), [0.2, 0.3, 0.4])
    np.testing.assert_allclose(resample(wl, v, g, extrapolation="zero"), [0.0, 0.3, 0.0])


@pytest.mark.parametrize("name", sorted(SPECTRA_SETS))
def test_patch_spectra_match_colour_science_and_chart_names(name: str) -> None:
    ps = load_patch_spectra(name)
    ref = colour.SDS_COLOURCHECKERS[name]
    assert len(ps.patch_names) == 24
    for i, sd in enumerate(ref.values()):
        np.testing.assert_allclose(ps.wavelengths, sd.wavelengths)
        np.testing.assert_allclose(ps.reflectance[i], sd.values, atol=1e-6)
    assert ps.patch_names == load_chart("safecolor").patch_names
    assert "source" in ps.provenance


@pytest.mark.parametrize(
    ("name", "published"),
    [("D65", (95.047, 100.0, 108.883)), ("A", (109.850, 100.0, 35.585))],  # CIE 15:2018 table 2
)
def test_illuminant_white_matches_cie_published_values(name: str, published: tuple) -> None:
    _, white = tristimulus(np.ones(WAVELENGTHS_NM.size), load_illuminant(name).on_grid())
    np.testing.assert_allclose(white * 100, published, rtol=5e-4)


def _colour_lab_reference(ill_name: str, set_name: str, cat: str) -> np.ndarray:
    """Second method: colour-science ASTM E308 tristimulus, its CAT, its Lab."""
    shape = colour.SpectralShape(380, 780, 1)
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"].copy().align(shape)
    key = {"F11": "FL11", "LED": "LED-B4"}.get(ill_name, ill_name)
    ill = colour.SDS_ILLUMINANTS[key].copy().align(shape)
    sds = colour.SDS_COLOURCHECKERS[set_name]
    xyz = np.array([colour.sd_to_XYZ(sd.copy().align(shape), cmfs, ill) for sd in sds.values()])
    xyz_w = colour.sd_to_XYZ(colour.sd_ones(shape), cmfs, ill)
    xyz, xyz_w = xyz / xyz_w[1], xyz_w / xyz_w[1]
    adapted = colour.adaptation.chromatic_adaptation_VonKries(
        xyz, xyz_w, WHITEPOINT_D65_XYZ, transform=cat
    )
    return colour.XYZ_to_Lab(adapted, SRGB_D65_XY)


# colour-science warns that a 380-780 nm reflectance cannot take the 360-780 nm shape asked of it
# and keeps 380 nm: the reference integral is unaffected (the integrand starts at 380 nm).
@pytest.mark.filterwarnings("ignore:.*shape could not be honoured")
@pytest.mark.parametrize(
    ("ill", "cat"), [("D65", "Bradford"), ("A", "Bradford"), ("A", "CAT02"), ("F11", "CAT16")]
)
def test_scene_reference_agrees_with_colour_science(ill: str, cat: str) -> None:
    ref = scene_reference(ill, "ColorChecker N Ohta", cat=cat)
    expected = _colour_lab_reference(ill, "ColorChecker N Ohta", cat)
    # colour-science resamples with Sprague interpolation, we interpolate linearly.
    assert float(np.mean(delta_e_2000(ref.lab, expected))) < 0.05
    assert ref.conventions["chromatic_adaptation"].startswith(cat)


def test_white_patch_of_d65_reference_is_near_neutral_and_white_point_exact() -> None:
    ref = scene_reference("D65")
    m = matrix_chromatic_adaptation(ref.white_xyz, WHITEPOINT_D65_XYZ, "Bradford")
    np.testing.assert_allclose(m @ ref.white_xyz, WHITEPOINT_D65_XYZ, atol=1e-12)
    assert abs(ref.lab[18, 1]) < 1.5 and abs(ref.lab[18, 2]) < 3 and ref.lab[18, 0] > 95


def test_scene_reference_is_about_2_delta_e_from_the_safecolor_table() -> None:
    """The SAFE-COLOR Lab table is older D50-based chart data (issue 3: about 2 ΔE00)."""
    ref = scene_reference("D65")
    d = float(np.mean(delta_e_2000(ref.lab, load_chart("safecolor").lab)))
    assert 1.0 < d < 3.5


def test_f11_line_spectrum_shows_sampling_error_at_10nm() -> None:
    """F11's narrow mercury / rare-earth lines are aliased by a 10 nm grid; D65 barely is."""
    de = {}
    for ill in ("F11", "D65"):
        fine = scene_reference(ill, step=1)
        coarse = scene_reference(ill, step=10)
        de[ill] = float(np.mean(delta_e_2000(fine.lab, coarse.lab)))
    assert de["F11"] > 0.3
    assert de["F11"] > 5 * de["D65"]
    # colour-science, integrating F11 on its own 10 nm vs 1 nm grids, sees an error of the same size
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    labs = []
    for step in (1, 10):
        shape = colour.SpectralShape(380, 780, step)
        ill = colour.SDS_ILLUMINANTS["FL11"].copy().align(shape, interpolator=colour.LinearInterpolator)
        c = cmfs.copy().align(shape)
        xyz_w = colour.sd_to_XYZ(colour.sd_ones(shape), c, ill, method="Integration")
        xyz = np.array([colour.sd_to_XYZ(sd.copy().align(shape, interpolator=colour.LinearInterpolator),
                                         c, ill, method="Integration")
                        for sd in colour.SDS_COLOURCHECKERS["BabelColor Average"].values()])
        labs.append(colour.XYZ_to_Lab(xyz / xyz_w[1], colour.XYZ_to_xy(xyz_w)))
    de_colour = float(np.mean(delta_e_2000(labs[0], labs[1])))
    assert de_colour > 0.3
    assert 0.5 < de["F11"] / de_colour < 2.0


def test_user_spd_file_equals_builtin(tmp_path) -> None:
    sd = colour.SDS_ILLUMINANTS["D65"]
    path = tmp_path / "my_d65.csv"
    path.write_text("wavelength,power\n" + "\n".join(f"{w},{v}" for w, v in zip(sd.wavelengths, sd.values, strict=True)))
    user = scene_reference(str(path))
    builtin = scene_reference("D65")
    np.testing.assert_allclose(user.lab, builtin.lab, atol=1e-9)
    assert user.conventions["illuminant_source"].startswith("user SPD file")


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("400,1\n500,-1\n700,1\n", "non-negative"),
        ("400,1\n390,1\n700,1\n", "strictly increasing"),
        ("450,1\n700,1\n", "400-700"),
        ("400,1\n", "at least 2"),
        ("400,1,2\n700,1,2\n", "expected 2 columns"),
        ("400,1\n500,abc\n700,1\n", "not numbers"),
    ],
)
def test_bad_spd_files_fail_clearly(tmp_path, content: str, message: str) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(content)
    with pytest.raises(InputFileError, match=message) as info:
        load_illuminant(str(path))
    assert "bad.csv" in str(info.value)


def test_unknown_names_are_reported() -> None:
    with pytest.raises(UnknownNameError, match="illuminant"):
        load_illuminant("D66")
    with pytest.raises(UnknownNameError, match="reflectance set"):
        load_patch_spectra("Munsell")
    with pytest.raises(FidelityError, match="chromatic adaptation"):
        scene_reference("A", cat="Hunt")
