"""The ten SAFE-COLOR transforms against plain colour-science implementations of Table I."""

from __future__ import annotations

import colour
import numpy as np
import pytest

from fidelity.core.errors import InvalidValueError, UnknownNameError
from fidelity.prediction.transforms import (
    TRANSFORMS,
    apply_transform,
    hsv_to_rgb,
    rgb_to_hsv,
)
from tests.fixtures.colour_reference import reference_transform


def _ref(name: str, rgb: np.ndarray, p: float) -> np.ndarray:
    return reference_transform(name, rgb, p)


def _rgb(n: int = 4000, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    rgb = rng.uniform(0, 1, (n, 3))
    rgb[:10] = np.linspace(0, 1, 10)[:, None]  # greys, black and white
    rgb[10:13] = np.eye(3)  # primaries
    return rgb


PARAMS = {
    "brightness-dec": [-0.3, -1.0], "brightness-inc": [0.2, 1.0],
    "contrast-dec": [0.5, 0.0], "contrast-inc": [1.7, 50.0],
    "gamma-dec": [0.6, 0.01], "gamma-inc": [1.5, 10.0],
    "hue": [5.3, -120.0, 180.0], "pull_mean": [0.7, 0.0],
    "saturation-dec": [0.4, 0.0], "saturation-inc": [2.5, 35.0],
}


def test_registry_holds_the_ten_transforms() -> None:
    assert sorted(TRANSFORMS) == sorted(PARAMS)
    for spec in TRANSFORMS.values():
        lo, hi = sorted(spec.param_range)
        assert lo <= spec.identity <= hi


@pytest.mark.parametrize("name", sorted(PARAMS))
def test_transform_matches_plain_colour_science_formula(name: str) -> None:
    rgb = _rgb()
    for p in PARAMS[name]:
        ours = apply_transform(rgb, name, p)
        np.testing.assert_allclose(ours, _ref(name, rgb, p), atol=1e-9, err_msg=f"{name}({p})")
        assert ours.min() >= 0 and ours.max() <= 1


@pytest.mark.parametrize("name", sorted(PARAMS))
def test_identity_parameter_leaves_image_unchanged(name: str) -> None:
    rgb = _rgb(500, seed=2)
    out = apply_transform(rgb, name, TRANSFORMS[name].identity)
    np.testing.assert_allclose(out, rgb, atol=1e-9)


@pytest.mark.parametrize("name", sorted(PARAMS))
def test_float32_kept_and_input_not_mutated(name: str) -> None:
    rgb = _rgb(300, seed=5).astype(np.float32).reshape(10, 30, 3)
    before = rgb.copy()
    out = apply_transform(rgb, name, PARAMS[name][0])
    assert out.dtype == np.float32
    assert out.shape == rgb.shape
    np.testing.assert_array_equal(rgb, before)
    np.testing.assert_allclose(out, apply_transform(rgb.astype(np.float64), name, PARAMS[name][0]), atol=2e-4)


def test_hsv_matches_colour_science_and_handles_grey_and_black() -> None:
    rgb = _rgb()
    np.testing.assert_allclose(rgb_to_hsv(rgb), colour.RGB_to_HSV(rgb), atol=1e-12)
    np.testing.assert_allclose(hsv_to_rgb(rgb_to_hsv(rgb)), rgb, atol=1e-12)
    hsv = rgb_to_hsv(np.array([[0.5, 0.5, 0.5], [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]))
    np.testing.assert_array_equal(hsv[:, :2], 0.0)
    np.testing.assert_array_equal(hsv[:, 2], [0.5, 0.0, 1.0])
    # Grey pixels stay grey under any hue rotation or saturation gain.
    grey = np.full((1, 3), 0.3)
    np.testing.assert_allclose(apply_transform(grey, "hue", 90.0), grey)
    np.testing.assert_allclose(apply_transform(grey, "saturation-inc", 50.0), grey)


def test_gamma_near_its_lower_bound_is_finite() -> None:
    rgb = np.array([[0.0, 1e-6, 0.04045], [0.5, 1.0, 0.001]])
    out = apply_transform(rgb, "gamma-dec", 0.01)
    assert np.all(np.isfinite(out)) and out.min() >= 0 and out.max() <= 1
    assert out[0, 0] == 0.0  # black stays black: 0^γ = 0


def test_bad_input_raises_clear_errors() -> None:
    rgb = _rgb(20)
    with pytest.raises(InvalidValueError, match="NaN"):
        apply_transform(np.array([[0.1, np.nan, 0.2]]), "hue", 10)
    with pytest.raises(InvalidValueError, match=r"outside \[0, 1\]"):
        apply_transform(np.array([[0.1, 1.5, 0.2]]), "hue", 10)
    with pytest.raises(InvalidValueError, match="shape"):
        apply_transform(np.zeros((4, 2)), "hue", 10)
    with pytest.raises(InvalidValueError, match="outside its range"):
        apply_transform(rgb, "contrast-dec", 1.5)
    with pytest.raises(InvalidValueError, match="outside its range"):
        apply_transform(rgb, "gamma-inc", float("nan"))
    with pytest.raises(UnknownNameError, match="contrast-inc"):
        apply_transform(rgb, "contrast", 1.0)
