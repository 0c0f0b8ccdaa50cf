"""Colorimetry against independent references: Sharma et al. (2005) test data, colour-science."""

from __future__ import annotations

import colour
import numpy as np
import pytest

from fidelity.colour.colorimetry import (
    MATRIX_LINEAR_SRGB_TO_XYZ,
    WHITEPOINT_D65_XYZ,
    delinearize_srgb,
    delta_e,
    delta_e_1976,
    delta_e_2000,
    delta_e_2000_components,
    lab_to_srgb,
    lab_to_xyz,
    linearize_srgb,
    srgb_to_lab,
    xyz_to_lab,
)
from fidelity.core.errors import InvalidValueError, UnknownNameError
from fidelity.pipeline.qualify import sharma_pairs

SHARMA = sharma_pairs()
D65_XY = np.array([0.3127, 0.3290])


def test_sharma_table_has_34_pairs() -> None:
    assert SHARMA.shape == (34, 7)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_ciede2000_reproduces_sharma_2005(dtype: type) -> None:
    lab1 = SHARMA[:, :3].astype(dtype)
    lab2 = SHARMA[:, 3:6].astype(dtype)
    forward = delta_e_2000(lab1, lab2)
    backward = delta_e_2000(lab2, lab1)
    assert forward.dtype == dtype
    np.testing.assert_allclose(forward, SHARMA[:, 6], atol=1e-4, rtol=0)
    np.testing.assert_allclose(backward, SHARMA[:, 6], atol=1e-4, rtol=0)


def test_pair_14_hues_exactly_180_degrees_apart_is_deterministic() -> None:
    # Pair 14: h1' and h2' are exactly 180° apart; the right answer (|Δh'| <= 180° branch) is
    # 4.8045, the other branch gives 4.7461. It must not depend on position in a batch, on the
    # argument order, on the block boundaries or on the dtype.
    p, q = SHARMA[13, :3], SHARMA[13, 3:6]
    assert SHARMA[13, 6] == pytest.approx(4.8045)
    single = float(delta_e_2000(p, q))
    batch = delta_e_2000(np.tile(p, (20000, 1)), np.tile(q, (20000, 1)))
    assert single == pytest.approx(4.8045, abs=1e-4)
    assert np.all(batch == single)
    assert float(delta_e_2000(q, p)) == single
    assert float(delta_e_2000(p.astype(np.float32), q.astype(np.float32))) == pytest.approx(4.8045, abs=1e-4)
    # The mirrored antipodal pair (pair 10: hues ~0° and ~180°) takes the same branch.
    assert float(delta_e_2000(SHARMA[9, :3], SHARMA[9, 3:6])) == pytest.approx(7.1792, abs=1e-4)


def _random_lab_pairs(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    lab1 = np.stack([rng.uniform(0, 100, n), rng.uniform(-128, 128, n), rng.uniform(-128, 128, n)], -1)
    lab2 = lab1 + rng.normal(0, 8, (n, 3))
    # Include achromatic colours, identical colours and pure hues on the axes.
    lab1[:50, 1:] = 0.0
    lab2[50:100] = lab1[50:100]
    lab2[100:150, 1] = 0.0
    return lab1, lab2


def test_ciede2000_agrees_with_colour_science() -> None:
    lab1, lab2 = _random_lab_pairs(100_000)
    ours = delta_e_2000(lab1, lab2)
    ref = colour.delta_E(lab1, lab2, method="CIE 2000")
    np.testing.assert_allclose(ours, ref, atol=1e-9, rtol=0)


def test_ciede2000_is_symmetric_and_zero_on_identity() -> None:
    lab1, lab2 = _random_lab_pairs(20_000, seed=3)
    np.testing.assert_allclose(delta_e_2000(lab1, lab2), delta_e_2000(lab2, lab1), atol=1e-12)
    assert np.all(delta_e_2000(lab1, lab1) == 0.0)


def test_ciede2000_broadcasts_over_leading_shapes() -> None:
    lab1, lab2 = _random_lab_pairs(24)
    grid = delta_e_2000(lab1.reshape(4, 6, 3)[None], lab2.reshape(4, 6, 3))
    assert grid.shape == (1, 4, 6)
    np.testing.assert_allclose(grid.ravel(), delta_e_2000(lab1, lab2))
    assert delta_e_2000(np.zeros((2, 1, 3)), np.ones((5, 3))).shape == (2, 5)
    with pytest.raises(InvalidValueError):
        delta_e_2000(np.zeros((3, 2)), np.zeros((3, 2)))


def test_ciede2000_components_match_closed_form() -> None:
    # Sharma et al. eq. 2-11 by hand for (50, 20, 0) -> (50, 0, 20): G scales a* only, so
    # C1' = 20 (1 + G), C2' = 20, h1' = 0°, h2' = 90°, ΔH' = 2 sqrt(C1' C2') sin(45°).
    g = 0.5 * (1 - np.sqrt(20.0**7 / (20.0**7 + 25.0**7)))
    c1 = 20.0 * (1 + g)
    dl, dc, dh = delta_e_2000_components([50.0, 20.0, 0.0], [50.0, 0.0, 20.0])
    assert float(dl) == 0.0
    assert float(dc) == pytest.approx(20.0 - c1, rel=1e-12)
    assert float(dh) == pytest.approx(2 * np.sqrt(c1 * 20.0) * np.sin(np.radians(45.0)), rel=1e-12)
    # The sign of ΔH' follows the rotation from the first hue to the second.
    assert float(delta_e_2000_components([50.0, 0.0, 20.0], [50.0, 20.0, 0.0])[2]) == pytest.approx(-float(dh))
    assert float(delta_e_2000_components([50, 0, 0], [60, 0, 0])[0]) == 10.0


def test_delta_e_registry() -> None:
    lab1, lab2 = _random_lab_pairs(100)
    np.testing.assert_allclose(delta_e(lab1, lab2, method="CIE 1976"), colour.delta_E(lab1, lab2, method="CIE 1976"))
    np.testing.assert_allclose(delta_e_1976(lab1, lab2), np.linalg.norm(lab2 - lab1, axis=-1))
    with pytest.raises(UnknownNameError, match="CIE 2000"):
        delta_e(lab1, lab2, method="CIE 9999")


def test_srgb_transfer_functions_match_iec_61966_2_1() -> None:
    v = np.linspace(0, 1, 10001)
    np.testing.assert_allclose(linearize_srgb(v), colour.models.eotf_sRGB(v), atol=1e-12)
    np.testing.assert_allclose(delinearize_srgb(v), colour.models.eotf_inverse_sRGB(v), atol=1e-12)
    np.testing.assert_allclose(delinearize_srgb(linearize_srgb(v)), v, atol=1e-12)
    # Thresholds: 0.04045 and 0.0031308, both segments meet there.
    assert linearize_srgb(0.04045) == pytest.approx(0.04045 / 12.92)
    assert delinearize_srgb(0.0031308) == pytest.approx(0.0031308 * 12.92)
    # Out-of-range values extend the segments without NaN.
    assert np.all(np.isfinite(linearize_srgb(np.array([-0.5, 1.5]))))
    assert linearize_srgb(np.float32(0.5)).dtype == np.float32


def test_srgb_to_lab_matches_colour_science() -> None:
    rng = np.random.default_rng(7)
    rgb = rng.uniform(0, 1, (5000, 3))
    # colour-science derives the matrix from the sRGB primaries and D65 (SMPTE RP 177) itself.
    srgb = colour.RGB_COLOURSPACES["sRGB"].copy()
    srgb.use_derived_transformation_matrices(True)
    xyz = colour.RGB_to_XYZ(rgb, srgb, apply_cctf_decoding=True)
    ref = colour.XYZ_to_Lab(xyz, D65_XY)
    np.testing.assert_allclose(srgb_to_lab(rgb), ref, atol=1e-9)
    np.testing.assert_allclose(lab_to_srgb(srgb_to_lab(rgb)), rgb, atol=1e-10)
    np.testing.assert_allclose(srgb_to_lab(np.ones(3)), [100, 0, 0], atol=1e-10)
    np.testing.assert_allclose(srgb_to_lab(np.zeros(3)), [0, 0, 0], atol=1e-10)
    np.testing.assert_allclose(MATRIX_LINEAR_SRGB_TO_XYZ, srgb.matrix_RGB_to_XYZ, atol=1e-12)
    np.testing.assert_allclose(MATRIX_LINEAR_SRGB_TO_XYZ.sum(axis=1), WHITEPOINT_D65_XYZ, atol=1e-12)
    # The IEC 61966-2-1 published (rounded) matrix agrees to its 4 decimals.
    iec = [[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]]
    np.testing.assert_allclose(MATRIX_LINEAR_SRGB_TO_XYZ, iec, atol=6e-5)


def test_lab_xyz_round_trip_including_the_linear_segment() -> None:
    xyz = np.array([[1e-5, 2e-5, 3e-5], [0.001, 0.002, 0.004], [0.3, 0.4, 0.5], [0.95, 1.0, 1.09]])
    np.testing.assert_allclose(lab_to_xyz(xyz_to_lab(xyz)), xyz, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(xyz_to_lab(xyz), colour.XYZ_to_Lab(xyz, D65_XY), atol=1e-9)
    lab32 = xyz_to_lab(xyz.astype(np.float32))
    assert lab32.dtype == np.float32


#: ITU-R BT.2087-0, Annex 1: linear BT.2020 RGB -> linear BT.709 RGB (published to 4 decimals).
BT2087_2020_TO_709 = np.array([[1.6605, -0.5876, -0.0728],
                               [-0.1246, 1.1329, -0.0083],
                               [-0.0182, -0.1006, 1.1187]])


def test_rgb_colourspace_matrix_against_the_published_bt2087_matrix() -> None:
    from fidelity.colour.colorimetry import matrix_rgb_to_linear_srgb

    np.testing.assert_allclose(matrix_rgb_to_linear_srgb("ITU-R BT.2020"), BT2087_2020_TO_709,
                               atol=6e-5)
    # the same primaries given as OpenEXR chromaticities; names are case-insensitive
    xy = (0.708, 0.292, 0.170, 0.797, 0.131, 0.046, 0.3127, 0.3290)
    np.testing.assert_allclose(matrix_rgb_to_linear_srgb(xy),
                               matrix_rgb_to_linear_srgb("itu-r bt.2020"), atol=1e-12)
    assert np.array_equal(matrix_rgb_to_linear_srgb("sRGB"), np.eye(3))
    # ACES (white about D60) is adapted to D65: its white becomes the sRGB white
    np.testing.assert_allclose(matrix_rgb_to_linear_srgb("ACEScg") @ np.ones(3), np.ones(3),
                               atol=1e-6)
    with pytest.raises(UnknownNameError, match="RGB colourspace"):
        matrix_rgb_to_linear_srgb("ProPhoto-ish")
    with pytest.raises(InvalidValueError, match="chromaticities"):
        matrix_rgb_to_linear_srgb((0.7, 0.3, 0.2))
