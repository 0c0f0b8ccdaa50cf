"""Camera model: sensitivities, ISP stages and camera files, against closed forms and
colour-science as a second implementation."""

from __future__ import annotations

import colour
import numpy as np
import pytest
from click.testing import CliRunner

from fidelity.camera.model import (
    DEFAULT_CAMERA,
    WHITE_PATCH_INDEX,
    CameraModel,
    Noise,
    ToneCurve,
    WhiteBalance,
    add_sensor_noise,
    apply_tone_curve,
    available_cameras,
    camera_response,
    colour_correction_matrix,
    exposure_gain,
    fit_colour_correction,
    ideal_sensitivities,
    load_camera,
    quantise,
    read_camera_file,
    vignetting_gain,
    white_balance_gains,
)
from fidelity.cli import main
from fidelity.colour.spectral import (
    load_illuminant,
    load_patch_spectra,
    scene_reference,
    tristimulus,
)
from fidelity.core.errors import InputFileError, UnknownNameError


def _patches_under(ill: str = "D65"):
    return load_patch_spectra().on_grid(), load_illuminant(ill).on_grid()


def test_builtin_cameras_include_ideal_and_default() -> None:
    names = available_cameras()
    assert "ideal" in names and DEFAULT_CAMERA in names
    for n in names:
        cam = load_camera(n)
        assert isinstance(cam, CameraModel) and cam.name == n and cam.description


def test_ideal_camera_raw_is_linear_srgb_of_the_tristimulus_values() -> None:
    refl, e = _patches_under("D65")
    raw = camera_response(refl, e, ideal_sensitivities().on_grid())
    xyz, _ = tristimulus(refl, e)
    # colour-science's own sRGB matrix, an independent implementation of IEC 61966-2-1
    expected = colour.XYZ_to_RGB(xyz, "sRGB", apply_cctf_encoding=False)
    np.testing.assert_allclose(raw, expected, atol=2e-4)


def test_real_camera_sensitivities_from_colour_science() -> None:
    cam = load_camera("nikon-5100")
    msds = colour.MSDS_CAMERA_SENSITIVITIES["Nikon 5100 (NPL)"]
    np.testing.assert_allclose(cam.sensitivities.values, msds.values)
    sigma = load_camera("sigma-sdmerrill").sensitivities.on_grid()
    assert np.all(sigma[:20] == 0)  # data start at 400 nm: no response below (zero extrapolation)


def test_exposure_modes() -> None:
    from fidelity.camera.model import Exposure

    p = np.array([[0.2, 0.4, 0.1], [0.5, 0.3, 0.2]])
    assert exposure_gain(Exposure("none"), p) == 1.0
    assert exposure_gain(Exposure("gain", gain=2.5), p) == 2.5
    assert exposure_gain(Exposure("auto", target=0.9), p) == pytest.approx(0.9 / 0.5)


def test_white_balance_methods_make_their_reference_neutral() -> None:
    refl, e = _patches_under("A")
    ill = load_illuminant("A")
    cam = load_camera("nikon-5100")
    raw = camera_response(refl, e, cam.sensitivities.on_grid())
    for method, white in (("white-patch", raw[WHITE_PATCH_INDEX]), ("grey-world", raw.mean(0))):
        g = white_balance_gains(WhiteBalance(method), raw, cam.sensitivities, ill)
        balanced = white * g
        assert g[1] == 1.0
        np.testing.assert_allclose(balanced, balanced[1], rtol=1e-12)
    g = white_balance_gains(WhiteBalance("illuminant", illuminant="scene"), raw, cam.sensitivities, ill)
    perfect_white = camera_response(np.ones(e.size), e, cam.sensitivities.on_grid())
    np.testing.assert_allclose(perfect_white * g, 1.0, rtol=1e-12)
    g = white_balance_gains(WhiteBalance("gains", gains=(2.0, 1.0, 1.5)), raw, cam.sensitivities, ill)
    np.testing.assert_allclose(g, [2.0, 1.0, 1.5])


def test_ccm_fit_equals_least_squares() -> None:
    rng = np.random.default_rng(1)
    cam_rgb = rng.uniform(0.05, 1.0, (24, 3))
    target = cam_rgb @ np.array([[1.6, -0.4, -0.2], [-0.3, 1.5, -0.2], [0.0, -0.5, 1.5]]).T
    target += rng.normal(0, 0.01, target.shape)
    expected = np.linalg.lstsq(cam_rgb, target, rcond=None)[0].T
    for method in ("Cheung 2004", "Finlayson 2015"):
        np.testing.assert_allclose(fit_colour_correction(cam_rgb, target, method), expected, atol=1e-9)
    with pytest.raises(UnknownNameError):
        fit_colour_correction(cam_rgb, target, "Vandermonde")


def test_fitted_ccm_reduces_error_for_a_real_camera() -> None:
    cam = load_camera("nikon-5100")
    ill = load_illuminant("D65")
    refl, e = _patches_under("D65")
    raw = camera_response(refl, e, cam.sensitivities.on_grid())
    raw = raw * exposure_gain(cam.exposure, raw)
    bal = raw * white_balance_gains(cam.white_balance, raw, cam.sensitivities, ill)
    m = colour_correction_matrix(cam, ill)
    target = scene_reference("D65").linear_srgb
    err_fit = np.abs(bal @ m.T - target).mean()
    err_none = np.abs(bal - target).mean()
    assert err_fit < 0.5 * err_none


def test_tone_curves_and_quantisation() -> None:
    x = np.linspace(-0.2, 1.2, 57)
    np.testing.assert_allclose(apply_tone_curve(x, ToneCurve("srgb")),
                               colour.cctf_encoding(np.clip(x, 0, 1), "sRGB"), atol=1e-12)
    np.testing.assert_allclose(apply_tone_curve(x, ToneCurve("gamma", gamma=2.2)),
                               np.clip(x, 0, 1) ** (1 / 2.2), atol=1e-12)
    np.testing.assert_array_equal(apply_tone_curve(x, ToneCurve("linear")), x)  # unclipped
    lut = ((0.0, 0.0), (0.5, 0.8), (1.0, 1.0))
    np.testing.assert_allclose(apply_tone_curve([0.25, 0.75], ToneCurve("lut", lut=lut)), [0.4, 0.9])
    q = quantise(x, 8)
    np.testing.assert_allclose(q * 255, np.round(q * 255), atol=1e-9)
    assert q.min() == 0.0 and q.max() == 1.0
    assert np.max(np.abs(q - np.clip(x, 0, 1))) <= 0.5 / 255 + 1e-12


def test_noise_is_seeded_and_has_the_modelled_variance() -> None:
    flat = np.full((200, 200, 3), 0.25)
    noise = Noise(full_well=5000.0, read_noise=10.0, seed=7)
    a, b = add_sensor_noise(flat, noise), add_sensor_noise(flat, noise)
    np.testing.assert_array_equal(a, b)
    c = add_sensor_noise(flat, noise, seed=8)
    assert not np.array_equal(a, c)
    expected_sigma = np.sqrt(0.25 / 5000 + (10 / 5000) ** 2)  # Poisson + read noise, in raw units
    assert np.std(a) == pytest.approx(expected_sigma, rel=0.03)
    assert np.mean(a) == pytest.approx(0.25, abs=4 * expected_sigma / 200)
    np.testing.assert_array_equal(add_sensor_noise(flat, Noise()), flat)


def test_vignetting_is_cos4_law() -> None:
    g = vignetting_gain(100, 150, 60.0)
    assert g.max() <= 1.0 and g[50, 75] > 0.999
    assert g[0, 0] == pytest.approx(np.cos(np.radians(30.0)) ** 4, rel=0.02)


def test_yaml_and_toml_camera_files_agree(tmp_path) -> None:
    toml = tmp_path / "cam.toml"
    toml.write_text(
        'name = "mine"\n[sensitivities]\nsource = "Nikon 5100 (NPL)"\n'
        '[white_balance]\nmethod = "gains"\ngains = [2.0, 1.0, 1.6]\n'
        '[tone]\ncurve = "gamma"\ngamma = 2.4\n[quantisation]\nbits = 10\n'
        '[noise]\nfull_well = 9000\nread_noise = 4\nseed = 3\n'
    )
    yaml = tmp_path / "cam.yaml"
    yaml.write_text(
        "name: mine\nsensitivities: {source: Nikon 5100 (NPL)}\n"
        "white_balance: {method: gains, gains: [2.0, 1.0, 1.6]}\n"
        "tone: {curve: gamma, gamma: 2.4}\nquantisation: {bits: 10}\n"
        "noise: {full_well: 9000, read_noise: 4, seed: 3}\n"
    )
    a, b = read_camera_file(toml), read_camera_file(yaml)
    assert a.to_json() | {"source": ""} == b.to_json() | {"source": ""}
    assert a.quantisation_bits == 10 and a.noise.seed == 3 and a.tone.gamma == 2.4


def test_user_sensitivity_csv_and_lut_file(tmp_path) -> None:
    msds = colour.MSDS_CAMERA_SENSITIVITIES["Nikon 5100 (NPL)"]
    (tmp_path / "sens.csv").write_text(
        "nm,r,g,b\n" + "\n".join(f"{w},{r},{g},{b}" for w, (r, g, b) in zip(msds.wavelengths, msds.values, strict=True))
    )
    (tmp_path / "lut.csv").write_text("0,0\n0.5,0.7\n1,1\n")
    (tmp_path / "cam.toml").write_text(
        '[sensitivities]\nsource = "file"\npath = "sens.csv"\n[tone]\ncurve = "lut"\nlut = "lut.csv"\n'
    )
    cam = load_camera(tmp_path / "cam.toml")
    np.testing.assert_allclose(cam.sensitivities.on_grid(), load_camera("nikon-5100").sensitivities.on_grid())
    assert cam.tone.lut == ((0.0, 0.0), (0.5, 0.7), (1.0, 1.0))
    assert cam.name == "cam"


@pytest.mark.parametrize(
    ("body", "field", "problem"),
    [
        ('[tone]\ncurve = "s-curve"\n', "[tone].curve", "must be one of"),
        ('[quantisation]\nbits = 0\n', "[quantisation].bits", "integer in [1, 16]"),
        ('[exposure]\nmode = "gain"\ngain = -1\n', "[exposure].gain", "must be > 0"),
        ('[white_balance]\nmethod = "gains"\ngains = [1, 2]\n', "[white_balance].gains", "3 positive"),
        ('[ccm]\nmethod = "matrix"\nmatrix = [[1, 0], [0, 1]]\n', "[ccm].matrix", "3x3"),
        ('[ccm]\nmethod = "fit"\nfit_method = "magic"\n', "[ccm].fit_method", "must be one of"),
        ('[noise]\nfull_well = "lots"\n', "[noise].full_well", "finite number"),
        ('[noise]\nread_noise = 2\n', "[noise].full_well", "required"),
        ('[tone]\ncurv = "srgb"\n', "[tone].curv", "unknown field"),
        ('[sensitivities]\nsource = "Canon 5D"\n', "[sensitivities].source", "must be"),
        ('[white_balance]\nmethod = "illuminant"\nilluminant = "D66"\n',
         "[white_balance].illuminant", "unknown illuminant"),
        ('[vignetting]\ndiagonal_fov_deg = 200\n', "[vignetting].diagonal_fov_deg", "<= 179"),
        # a file without its sensitivities is no camera, not silently the ideal one
        ('name = "only"\n', "[sensitivities]", "required: the camera's spectral sensitivities"),
        ('name = "x"\n[tone]\ncurve = "srgb"\n', "[sensitivities]", "source = 'ideal'"),
        ('[sensitivities]\n', "[sensitivities].source", "required"),
    ],
)
def test_bad_camera_fields_fail_clearly(tmp_path, body: str, field: str, problem: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(body)
    with pytest.raises(InputFileError) as info:
        load_camera(path)
    msg = str(info.value)
    assert "bad.toml" in msg and field in msg and problem in msg, msg


def test_unparseable_and_unknown_cameras(tmp_path) -> None:
    (tmp_path / "broken.toml").write_text("[tone\ncurve = 1")
    with pytest.raises(InputFileError, match="invalid TOML"):
        load_camera(tmp_path / "broken.toml")
    (tmp_path / "broken.yaml").write_text("tone: [1, 2\n")
    with pytest.raises(InputFileError, match="invalid YAML"):
        load_camera(tmp_path / "broken.yaml")
    with pytest.raises(UnknownNameError, match="camera"):
        load_camera("leica-m")
    with pytest.raises(InputFileError, match="does not exist"):
        load_camera(tmp_path / "missing.toml")


def test_lut_outputs_must_be_display_values(tmp_path) -> None:
    path = tmp_path / "lut.toml"
    path.write_text('[tone]\ncurve = "lut"\nlut = [[0, 0], [1, 1.5]]\n')
    with pytest.raises(InputFileError, match=r"\[tone\]\.lut: outputs must lie in \[0, 1\]"):
        load_camera(path)


def test_a_camera_file_of_only_a_name_is_an_input_error(tmp_path) -> None:
    """``name`` alone: exit 2 in one line naming the file and the missing section; with
    ``[sensitivities] source = "ideal"`` it is the ideal camera, as said."""
    only = tmp_path / "cam.toml"
    only.write_text('name = "only"\n')
    r = CliRunner().invoke(main, ["--no-config", "check", "--camera", str(only), "--no-report"])
    assert r.exit_code == 2, r.output
    lines = r.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fidelity: error: camera file ")
    assert "cam.toml: [sensitivities]: required" in lines[0]
    only.write_text('name = "only"\n[sensitivities]\nsource = "ideal"\n')
    assert load_camera(only).sensitivities.name == ideal_sensitivities().name
