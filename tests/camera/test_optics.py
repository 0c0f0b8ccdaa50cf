"""The camera's optics (fidelity.camera.optics) against independent references: the Gaussian's
Fourier transform, the zeros of J1, the diffraction cutoff, an erf fitted to a blurred edge;
and the [optics] section of a camera file, through the renderer and the CLI."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fidelity.camera.model import load_camera, read_camera_file
from fidelity.camera.optics import Optics, diffraction_mtf
from fidelity.camera.render import ChartLayout, render_chart
from fidelity.cli import main

REPO = Path(__file__).resolve().parents[2]
SOFT = REPO / "cameras" / "optics" / "nikon5100-soft-lens.toml"
BASE = REPO / "cameras" / "nikon5100-cheung-d65.toml"

#: The head of a camera file that says it is the ideal camera (a camera file names its
#: sensitivities).
IDEAL_HEAD = 'name = "{}"\n[sensitivities]\nsource = "ideal"\n'


def _dtft(kernel: np.ndarray, f: np.ndarray) -> np.ndarray:
    """The DTFT of a centred odd-length 1-D kernel at frequencies f (cycles per sample)."""
    n = np.arange(kernel.size) - kernel.size // 2
    return np.real(np.exp(-2j * np.pi * f[:, None] * n) @ kernel)


F = np.linspace(0.0, 0.5, 201)


@pytest.mark.parametrize("sigma", [1.2, 1.5, 2.0, 3.0, 4.0])
def test_gaussian_kernel_dft_is_the_gaussian_mtf(sigma: float) -> None:
    """Where the sampled kernel does not alias (sigma >= 1.2 px: exp(-pi^2 sigma^2 / 2) < 1e-3
    at Nyquist) its DFT is exp(-2 pi^2 sigma^2 f^2) to 1e-3 up to 0.5 cy/px."""
    o = Optics("gaussian", sigma_px=sigma)
    reference = np.exp(-2 * np.pi ** 2 * sigma ** 2 * F ** 2)
    assert np.max(np.abs(_dtft(o.kernel_1d(), F) - reference)) < 1e-3
    assert np.max(np.abs(o.mtf(F) - reference)) < 1e-15


@pytest.mark.parametrize("sigma", [0.5, 0.7, 1.0, 2.0, 4.0])
def test_gaussian_kernel_dft_is_the_periodised_gaussian(sigma: float) -> None:
    """Any sigma in 0.5-4 px: the sampled kernel's DFT is the Gaussian's transform periodised by
    the sampling (Poisson summation, sum over m of G(f - m), normalised at f = 0), to 1e-4."""
    m = np.arange(-20, 21)[:, None]
    periodised = np.exp(-2 * np.pi ** 2 * sigma ** 2 * (F[None] - m) ** 2).sum(axis=0)
    periodised /= np.exp(-2 * np.pi ** 2 * sigma ** 2 * m[:, 0] ** 2.0).sum()
    got = _dtft(Optics("gaussian", sigma_px=sigma).kernel_1d(), F)
    assert np.max(np.abs(got - periodised)) < 1e-4


@pytest.mark.parametrize("radius", [1.0, 2.5, 4.0])
def test_defocus_mtf_first_zero(radius: float) -> None:
    """The disc's first zero is at f = j1,1 / (2 pi r) = 0.6098 / r (3.8317, the first zero of
    J1, from the tables of Abramowitz & Stegun 9.5)."""
    o = Optics("defocus", radius_px=radius)
    zero = 3.8317059702 / (2 * np.pi * radius)
    assert abs(zero - 0.6098 / radius) < 1e-4 / radius
    assert abs(o.transfer(np.array([zero]))[0]) < 1e-9
    f = np.linspace(0, zero, 2001)[:-1]
    assert np.all(o.transfer(f) > 0)  # no earlier zero
    assert o.transfer(np.array([zero * 1.05]))[0] < 0  # contrast reversal beyond it


def test_diffraction_cutoff_and_formula() -> None:
    """f_c = pitch / (lambda N): 4 um pitch, 550 nm, f/4 -> 1.818 cy/px; the MTF is 0 from there
    on, and at f_c / 2 it is 2/pi (pi/3 - sqrt(3)/4) = 0.3910."""
    o = Optics("diffraction", f_number=4.0, wavelength_nm=550.0, pixel_pitch_um=4.0)
    fc = 4e-6 / (550e-9 * 4.0)
    assert o.cutoff == pytest.approx(fc, rel=1e-12)
    assert o.mtf(np.array([0.0]))[0] == 1.0
    assert o.mtf(np.array([fc / 2]))[0] == pytest.approx(
        2 / np.pi * (np.pi / 3 - np.sqrt(3) / 4), abs=1e-12)
    assert o.mtf(np.array([0.999 * fc]))[0] > 0
    np.testing.assert_allclose(o.mtf(np.array([fc, 1.5 * fc])), 0.0, atol=1e-12)
    assert np.all(np.diff(diffraction_mtf(np.linspace(0, 1, 101), 1.0)) <= 0)


def test_mtf_table_is_interpolated() -> None:
    o = Optics("mtf", mtf_table=((0.0, 1.0), (0.25, 0.5), (0.5, 0.1)))
    np.testing.assert_allclose(o.mtf(np.array([0.0, 0.125, 0.25, 0.375, 0.5, 0.7])),
                               [1.0, 0.75, 0.5, 0.3, 0.1, 0.1])


@pytest.mark.parametrize("sigma", [1.5, 2.0, 3.0])
def test_gaussian_on_a_rendered_step_edge_fits_back_sigma(sigma: float) -> None:
    """A patch edge of the closed-form render (black background to the white patch) blurred,
    a row fitted with an erf: sigma back within 2 %. The fit is low by Sheppard's correction
    of the sampled step (the kernel's CDF at the pixel centres is a normal CDF of variance
    sigma^2 - 1/12 to second order): sqrt(sigma^2 - 1/12) within 0.1 %."""
    from scipy.optimize import curve_fit
    from scipy.special import erf

    layout = ChartLayout.for_patch_size(32)
    values = np.zeros((24, 3))
    values[18] = 0.9
    img = Optics("gaussian", sigma_px=sigma).apply(layout.paint(values))
    y0, y1, x0, _ = layout.patch_box(18)
    row = img[(y0 + y1) // 2, x0 - 7:x0 + 8, 1]
    x = np.arange(x0 - 7, x0 + 8, dtype=float)

    def edge(x: np.ndarray, a: float, b: float, x_edge: float, s: float) -> np.ndarray:
        return b + a * 0.5 * (1 + erf((x - x_edge) / (s * np.sqrt(2))))

    (a, b, x_edge, s), _ = curve_fit(edge, x, row, p0=(1.0, 0.0, x0, 1.0))
    assert abs(s - sigma) / sigma < 0.02
    assert abs(s - math.sqrt(sigma ** 2 - 1 / 12)) / sigma < 1e-3
    assert x_edge == pytest.approx(x0 - 0.5, abs=0.02)  # between the last black and first patch pixel


@pytest.mark.parametrize("optics", [
    Optics("gaussian", sigma_px=2.5), Optics("defocus", radius_px=3.0),
    Optics("diffraction", f_number=8.0, pixel_pitch_um=2.0),
    Optics("mtf", mtf_table=((0.0, 1.0), (0.2, 0.4), (0.6, 0.0))),
    Optics("psf", psf=((0.0, 1.0, 0.0), (1.0, 4.0, 1.0), (0.0, 1.0, 0.0))),
], ids=lambda o: o.kind)
def test_convolution_keeps_the_mean_and_blurs(optics: Optics) -> None:
    rng = np.random.default_rng(3)
    img = rng.random((37, 52, 3))
    out = optics.apply(img)
    assert out.shape == img.shape
    assert abs(out.mean() - img.mean()) < 1e-9
    np.testing.assert_allclose(out.mean(axis=(0, 1)), img.mean(axis=(0, 1)), atol=1e-9)
    assert out.std() < img.std()
    k = optics.kernel()
    assert k.sum() == pytest.approx(1.0, abs=1e-12) and k.shape[0] % 2 == 1


def test_fourier_convolution_matches_the_direct_kernel_inside() -> None:
    """The PSF image's Fourier convolution is the direct one away from the edges."""
    psf = np.array([[0.0, 1.0, 0.0], [1.0, 4.0, 2.0], [0.0, 1.0, 0.0]])
    o = Optics("psf", psf=tuple(map(tuple, psf)))
    img = np.random.default_rng(1).random((20, 24))
    out = o.apply(img)
    k = psf / psf.sum()
    direct = sum(k[i, j] * img[2 - i:18 - i, 2 - j:22 - j] for i in range(3) for j in range(3))
    np.testing.assert_allclose(out[1:17, 1:21], direct, atol=1e-12)


def test_none_is_the_identity() -> None:
    img = np.random.default_rng(0).random((8, 9, 3))
    assert Optics().apply(img) is img


def test_none_is_the_default_and_not_recorded() -> None:
    """A camera file without [optics] (and a built-in camera) has kind "none", which its JSON
    does not mention (the records of existing cameras stay as they were)."""
    for cam in (read_camera_file(BASE), load_camera("nikon-5100")):
        assert cam.optics == Optics() and "optics" not in cam.to_json()


def test_none_section_is_bit_identical(tmp_path: Path) -> None:
    """kind = "none" renders the same bits as a camera without [optics]."""
    (tmp_path / "none.toml").write_text(BASE.read_text(encoding="utf-8")
                                        + '\n[optics]\nkind = "none"\n')
    a, b = render_chart(BASE), render_chart(tmp_path / "none.toml")
    assert np.array_equal(a.linear_image, b.linear_image)
    assert np.array_equal(a.display_image, b.display_image)
    assert a.measurement.mean_delta_e == b.measurement.mean_delta_e
    assert a.to_json()["camera"] == {**b.to_json()["camera"], "source": a.camera.source}


def test_soft_lens_blurs_the_image_not_the_chart_delta_e() -> None:
    """sigma = 1.5 px on 32 px patches: the central windows (8 px from the edges, 5.3 sigma)
    keep their values, so the chart ΔE moves by < 0.01."""
    soft, base = render_chart(SOFT), render_chart(BASE)
    assert soft.camera.optics == Optics("gaussian", sigma_px=1.5)
    assert soft.camera.to_json()["optics"] == {"kind": "gaussian", "sigma_px": 1.5}
    assert np.abs(soft.linear_image - base.linear_image).max() > 0.1  # the edges are blurred
    assert abs(soft.measurement.mean_delta_e - base.measurement.mean_delta_e) < 0.01
    np.testing.assert_allclose(soft.camera_rgb, base.camera_rgb, atol=1e-6)


def test_esfr_measures_the_rendered_blur() -> None:
    """The ISO 12233 e-SFR of a slanted edge blurred by sigma = 2 px: MTF50 = sqrt(ln 2 / 2) /
    (pi sigma) within 3 %."""
    from fidelity.measure.sharpness import esfr

    h, w = 64, 128
    yy, xx = np.mgrid[0:h, 0:w]
    angle = math.radians(5)
    # a pixel-supersampled slanted step (8 x 8 samples per pixel)
    sub = (np.arange(8) + 0.5) / 8
    edge = np.zeros((h, w))
    for dy in sub:
        for dx in sub:
            edge += ((xx + dx - w / 2) * math.cos(angle) - (yy + dy - h / 2) * math.sin(angle)
                     > 0)
    edge = 0.1 + 0.7 * edge / 64
    blurred = Optics("gaussian", sigma_px=2.0).apply(edge)
    result = esfr(blurred)
    expected = math.sqrt(math.log(2) / 2) / (math.pi * 2.0)
    assert result.mtf50 == pytest.approx(expected, rel=0.03)


BAD = [
    ('[optics]\nkind = "bokeh"\n', "[optics].kind",
     "must be one of none, gaussian, defocus, diffraction, mtf, psf, got 'bokeh'"),
    ('[optics]\nkind = "gaussian"\nsigma_px = -1.0\n', "[optics].sigma_px", "must be >= 0"),
    ('[optics]\nkind = "mtf"\nmtf = [[0, 1], [0.3, 0.5], [0.2, 0.2]]\n', "[optics].mtf",
     "monotone in frequency"),
    ('[optics]\nkind = "mtf"\nmtf = [[0, 1], [0.3, 1.5]]\n', "[optics].mtf", "[0, 1]"),
    ('[optics]\nkind = "mtf"\nmtf = [[0.1, 1], [0.3, 0.5]]\n', "[optics].mtf", "start at [0, 1]"),
    ('[optics]\nkind = "gaussian"\n', "[optics].sigma_px", "required"),
    ('[optics]\nkind = "diffraction"\nf_number = 4\n', "[optics].pixel_pitch_um", "required"),
    ('[optics]\nkind = "mtf"\n', "[optics].mtf", "required"),
    ('[optics]\nkind = "psf"\npsf_file = "missing.csv"\n', "[optics].psf_file", "no such file"),
    ('[optics]\nkind = "mtf"\nmtf_file = "missing.csv"\n', "[optics].mtf_file", "missing.csv"),
    ('[optics]\nkind = "mtf"\nmtf_file = "mtf.csv"\n', "[optics].mtf_file", "monotone"),
]


@pytest.mark.parametrize(("body", "field", "problem"), BAD,
                         ids=[b[1] + ":" + b[2][:12] for b in BAD])
def test_bad_optics_one_line_exit_2(tmp_path: Path, body: str, field: str,
                                    problem: str) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text(IDEAL_HEAD.format("bad") + body, encoding="utf-8")
    (tmp_path / "mtf.csv").write_text("0,1\n0.3,0.5\n0.2,0.1\n", encoding="utf-8")
    res = CliRunner().invoke(main, ["check", "--camera", str(bad), "--no-report"])
    assert res.exit_code == 2, res.output
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1, res.output
    assert "bad.toml" in lines[0] and field in lines[0] and problem in lines[0], lines[0]


def test_measured_mtf_and_psf_files(tmp_path: Path) -> None:
    (tmp_path / "mtf.csv").write_text("frequency,mtf\n0,1\n0.25,0.6\n0.5,0.2\n")
    (tmp_path / "psf.csv").write_text("0 1 0\n1 4 1\n0 1 0\n")
    (tmp_path / "m.toml").write_text(IDEAL_HEAD.format("m") + '[optics]\nkind = "mtf"\n'
                                        'mtf_file = "mtf.csv"\n')
    (tmp_path / "p.toml").write_text(IDEAL_HEAD.format("p") + '[optics]\nkind = "psf"\n'
                                        'psf_file = "psf.csv"\n')
    m, p = read_camera_file(tmp_path / "m.toml"), read_camera_file(tmp_path / "p.toml")
    assert m.optics.mtf_table == ((0.0, 1.0), (0.25, 0.6), (0.5, 0.2))
    assert (tmp_path / "mtf.csv") in m.files and (tmp_path / "psf.csv") in p.files
    np.testing.assert_allclose(p.optics.kernel(), np.array([[0, 1, 0], [1, 4, 1], [0, 1, 0]]) / 8)
    # the PSF's MTF: its line spread function (1/8, 6/8, 1/8) -> 3/4 + 1/4 cos(2 pi f)
    np.testing.assert_allclose(p.optics.mtf(F), 0.75 + 0.25 * np.cos(2 * np.pi * F), atol=1e-12)
    assert p.to_json()["optics"]["psf_size"] == [3, 3]
    (tmp_path / "even.csv").write_text("1 1\n1 1\n")
    (tmp_path / "e.toml").write_text(IDEAL_HEAD.format("e") + '[optics]\nkind = "psf"\n'
                                        'psf_file = "even.csv"\n')
    res = CliRunner().invoke(main, ["check", "--camera", str(tmp_path / "e.toml"), "--no-report"])
    assert res.exit_code == 2 and "[optics].psf_file" in res.output and "odd" in res.output


def test_mitsuba_render_gets_the_same_psf() -> None:
    """The Mitsuba renderer's raw image goes through the same optics: the soft-lens render is
    the base camera's render (same seed, same samples) blurred by the PSF."""
    pytest.importorskip("mitsuba")
    kw = {"renderer": "mitsuba", "variant": "scalar_spectral", "spp": 16,
          "pixels_per_patch": 12, "seed": 1}
    soft, base = render_chart(SOFT, **kw), render_chart(BASE, **kw)
    expected = Optics("gaussian", sigma_px=1.5).apply(base.linear_image.astype(np.float64))
    np.testing.assert_allclose(soft.linear_image, expected, rtol=0, atol=2e-6)
    assert np.abs(soft.linear_image - base.linear_image).max() > 0.05


@pytest.mark.parametrize(("section", "limit"), [
    ('kind = "defocus"\nradius_px = 2.0', 0.01),
    ('kind = "diffraction"\nf_number = 8.0\nwavelength_nm = 550\npixel_pitch_um = 2.0', 0.1),
    ('kind = "mtf"\nmtf = [[0, 1], [0.1, 0.7], [0.3, 0.2], [0.5, 0.05]]', 0.1),
], ids=["defocus", "diffraction", "mtf"])
def test_every_kind_renders(tmp_path: Path, section: str, limit: float) -> None:
    """Each kind blurs the render's edges. A 2 px disc ends 6 px short of the central windows:
    the chart ΔE moves by < 0.01. An Airy PSF (f/8, 2 um pixels, 550 nm: lambda N = 2.2 px)
    carries about 2 / (pi x) = 5.6 % of its energy beyond the windows' 8 px margin (x = pi 8 /
    2.2; the tail of 1 - J0^2 - J1^2), which reaches the windows from the neighbouring patches;
    so does a table's slow fall: their ΔE moves by less than 0.1, not 0.01."""
    cam = tmp_path / "cam.toml"
    cam.write_text(BASE.read_text(encoding="utf-8") + f"\n[optics]\n{section}\n")
    soft, base = render_chart(cam), render_chart(BASE)
    assert np.abs(soft.linear_image - base.linear_image).max() > 0.05
    assert abs(soft.measurement.mean_delta_e - base.measurement.mean_delta_e) < limit
