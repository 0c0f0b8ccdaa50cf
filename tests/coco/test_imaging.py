"""A camera's lens and sensor emulated on images (fidelity.coco.imaging): the same PSF as the
camera's render, the Poisson-Gaussian noise of its closed form, in the camera's raw signal."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from fidelity.camera.model import Noise, read_camera_file
from fidelity.camera.optics import Optics
from fidelity.camera.render import ChartLayout, render_chart
from fidelity.coco.degradations import apply_optics, decode_srgb8, degrade_linear
from fidelity.coco.emulation import fit_emulation
from fidelity.coco.imaging import CameraImaging, camera_imaging
from fidelity.core.errors import InvalidValueError

SUITE = Path(__file__).resolve().parents[2] / "cameras" / "properties"


def _image(seed: int = 0, shape: tuple[int, int] = (48, 64)) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (*shape, 3), dtype=np.uint8)


@pytest.mark.parametrize("optics", [Optics("gaussian", sigma_px=0.5),
                                    Optics("gaussian", sigma_px=1.5),
                                    Optics("gaussian", sigma_px=3.0),
                                    Optics("defocus", radius_px=2.0),
                                    Optics("none")])
def test_apply_optics_is_the_renders_psf(optics: Optics) -> None:
    """apply_optics = Optics.apply (what render_chart calls) to float rounding: OpenCV's
    separable filter for a Gaussian, Optics.apply itself for the other kinds."""
    lin = decode_srgb8(_image())
    want = optics.apply(lin)
    got = apply_optics(lin, optics)
    assert got.shape == lin.shape and got.dtype == np.float64
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-13)
    if optics.kind == "gaussian":  # the sweep's gaussian-blur family is the same filter
        np.testing.assert_array_equal(degrade_linear(lin, "gaussian-blur", optics.sigma_px), got)


def test_the_emulations_optics_are_the_cameras_render() -> None:
    """The exact sRGB camera with a 1.5 px Gaussian lens: the emulation blurs the chart's
    unblurred raw image (the scene as linear sRGB: exposure gain 1) exactly as render_chart
    blurs it (1e-13), and its linear signal equals the one render_chart develops from its
    blurred raw image (its white-balance gains, no CCM) to the colour fit's accuracy on this
    camera (4e-4: the root-polynomial mapping fitted on 351 reflectances is not exactly the
    gains), while the blur moves the patches' edges by more than 0.05."""
    cam = read_camera_file(SUITE / "ideal-gauss1.5.toml")
    render = render_chart(cam, "D65")
    assert render.conventions["exposure_gain"] == pytest.approx(1.0)
    gains = np.asarray(render.conventions["white_balance_gains"])
    assert np.abs(gains - 1).max() < 1e-3  # the ideal camera's white is D65's, nearly
    raw = render_chart(replace(cam, optics=Optics()), "D65").linear_image.astype(np.float64)
    layout = ChartLayout.for_patch_size(render.settings["pixels_per_patch"])
    np.testing.assert_allclose(layout.paint(render.camera_rgb), raw, atol=1e-6)  # flat patches
    imaging = camera_imaging(fit_emulation(cam, "D65"))
    assert imaging is not None
    np.testing.assert_allclose(imaging.scene(raw), cam.optics.apply(raw), rtol=0, atol=1e-13)
    developed = imaging.develop(raw, seed=0)
    want = render.linear_image.astype(np.float64) * gains  # develop(): (raw * gains) @ I
    np.testing.assert_allclose(developed, want, rtol=0, atol=1e-3)
    assert np.abs(developed - raw * gains).max() > 0.05  # the lens did blur the patches' edges


def test_a_colour_only_camera_has_no_imaging() -> None:
    assert camera_imaging(fit_emulation(SUITE / "nikon-clean.toml", "D65")) is None
    emu = fit_emulation(SUITE / "nikon-gauss1.0.toml", "D65", method="lut3d")
    with pytest.raises(InvalidValueError, match="root-polynomial"):
        CameraImaging(emu, "x")


@pytest.mark.parametrize(("camera", "full_well", "read_noise"),
                         [("ideal-fw5k-rn10", 5000.0, 10.0), ("nikon-lowlight-iso8", 2500.0, 5.0)])
def test_noise_is_the_poisson_gaussian_closed_form_in_raw(camera: str, full_well: float,
                                                          read_noise: float) -> None:
    """A flat grey image: in the camera's raw signal (the chart's CCM and gains undone) every
    channel's variance is signal / full_well + (read_noise / full_well)^2, i.e. in electrons
    var = signal + read^2 (Poisson shot noise + Gaussian read noise), within 4 sampling SEs
    (SE of a variance: var sqrt(2 / (n - 1))); the mean is the noiseless signal."""
    cam = read_camera_file(SUITE / f"{camera}.toml")
    assert (cam.noise.full_well, cam.noise.read_noise) == (full_well, read_noise)
    imaging = camera_imaging(fit_emulation(cam, "D65"))
    assert imaging is not None
    grey = np.full((400, 400, 3), 118, dtype=np.uint8)
    quiet = CameraImaging(replace(imaging.emulation, camera=replace(cam, noise=Noise())), "q")
    signal = quiet.raw(quiet.linear(grey)).reshape(-1, 3)
    assert np.ptp(signal, axis=0).max() < 1e-12  # flat
    raw = imaging.raw(imaging.linear(grey)).reshape(-1, 3)
    n = raw.shape[0]
    s = signal[0]
    want = s / full_well + (read_noise / full_well) ** 2
    var = raw.var(axis=0, ddof=1)
    np.testing.assert_array_less(np.abs(var - want), 4 * want * np.sqrt(2 / (n - 1)))
    electrons = var * full_well ** 2
    np.testing.assert_allclose(electrons, s * full_well + read_noise ** 2,
                               rtol=4 * np.sqrt(2 / (n - 1)))
    np.testing.assert_array_less(np.abs(raw.mean(axis=0) - s), 4 * np.sqrt(want / n))


def test_noise_is_seeded_by_the_image() -> None:
    imaging = camera_imaging(fit_emulation(SUITE / "ideal-fw5k-rn10.toml", "D65"))
    assert imaging is not None
    a, b = _image(1), _image(2)
    assert np.array_equal(imaging(a), imaging(a.copy()))
    grey = np.full((32, 32, 3), 128, np.uint8)
    g2 = grey.copy()
    g2[0, 0, 0] = 129
    assert not np.array_equal(imaging(grey)[1:], imaging(g2)[1:])
    assert imaging(b).dtype == np.uint8 and imaging(b).shape == b.shape


def test_blur_keeps_a_flat_image_and_softens_an_edge() -> None:
    imaging = camera_imaging(fit_emulation(SUITE / "ideal-gauss2.0.toml", "D65"))
    assert imaging is not None
    flat = np.full((40, 40, 3), 90, np.uint8)
    np.testing.assert_array_equal(imaging(flat), imaging.emulation.apply_uint8(flat))
    edge = np.zeros((40, 40, 3), np.uint8)
    edge[:, 20:] = 255
    out = imaging(edge).astype(int)
    assert 0 < out[20, 19, 1] < 255 and 0 < out[20, 20, 1] < 255
    assert out[20, 0, 1] == 0 and out[20, 39, 1] == 255
