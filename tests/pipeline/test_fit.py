"""fidelity fit (issue 29): correction models recovered from charts with a known error, the
.cube checked through OpenColorIO, the hard cases refused or regularised, the command line."""

from __future__ import annotations

import copy
import functools
import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fidelity.camera.model import camera_from_dict
from fidelity.camera.render import render_chart
from fidelity.chart.image import write_exr, write_png
from fidelity.cli import main
from fidelity.colour.colorimetry import delinearize_srgb, linearize_srgb
from fidelity.core.errors import InvalidValueError
from fidelity.correction.models import (
    CONDITION_LIMIT,
    CURVE_KNOTS,
    MAX_COEFFICIENT,
    cross_validate,
    expand_root_polynomial,
    fit_model,
    patch_delta_e,
    usable_patches,
)

ocio = pytest.importorskip("PyOpenColorIO", reason="fidelity fit needs opencolorio ([fit])")

#: The suite's exact camera (CIE 1931 CMFs x the sRGB matrix: camera RGB is linear sRGB),
#: float output: the "real camera" of the ground-truth tests.
EXACT = {"name": "exact", "sensitivities": {"source": "ideal"},
         "exposure": {"mode": "gain", "gain": 1.0},
         "white_balance": {"method": "illuminant", "illuminant": "scene"},
         "ccm": {"method": "none"}, "tone": {"curve": "srgb"}}


def _rotation(degrees: float) -> np.ndarray:
    """Rodrigues rotation of linear RGB about the grey axis (cameras/bad-hue-rotation.toml)."""
    k = np.ones(3) / math.sqrt(3)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    t = math.radians(degrees)
    return np.eye(3) + math.sin(t) * kx + (1 - math.cos(t)) * kx @ kx


HUE = _rotation(-20.0)
WB = (1.25, 1.0, 0.8)


def _camera(**changes: object):
    d = copy.deepcopy(EXACT)
    d.update(changes)
    return camera_from_dict(d)


def _patches(camera) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """Linear sRGB and encoded sRGB of a camera's rendered chart patches."""
    m = render_chart(camera, pixels_per_patch=8).measurement
    return np.asarray(linearize_srgb(m.srgb)), m.srgb, m.patch_names


@pytest.fixture(scope="module")
def exact():
    return _patches(_camera())


@pytest.fixture(scope="module")
def cases():
    """The suite's exact camera with one known error each."""
    return {
        "hue": _patches(_camera(ccm={"method": "matrix", "matrix": HUE.tolist()})),
        "wb": _patches(_camera(white_balance={"method": "gains", "gains": list(WB)})),
        "gamma": _patches(_camera(tone={"curve": "gamma", "gamma": 2.2})),
        "5bit": _patches(_camera(quantisation={"bits": 5})),
    }


def _weights(sim_srgb, real_srgb, names) -> np.ndarray:
    ex = usable_patches(sim_srgb, real_srgb, names)
    return np.array([0.0 if n in ex else 1.0 for n in names])


# ----------------------------------------------------------------------------------------------
# Models against independent references and known errors
# ----------------------------------------------------------------------------------------------


def test_root_polynomial_terms_and_fit_equal_colour_science(exact, cases):
    """The terms and the unweighted least-squares fit of Finlayson et al. 2015 (degree 2) equal
    colour-science's implementation."""
    from colour.characterisation import (
        matrix_colour_correction,
        polynomial_expansion_Finlayson2015,
    )

    sim = np.clip(cases["hue"][0], 1e-4, None)
    real = np.clip(exact[0], 1e-4, None)
    ours = expand_root_polynomial(sim)
    theirs = polynomial_expansion_Finlayson2015(sim, degree=2, root_polynomial_expansion=True)
    assert np.allclose(np.sort(ours, axis=1), np.sort(theirs, axis=1), atol=1e-12)
    fitted, _ = fit_model(sim, real, "root-polynomial", objective="linear")
    m = matrix_colour_correction(sim, real, method="Finlayson 2015", degree=2,
                                 root_polynomial_expansion=True)
    assert np.allclose(fitted.apply(sim), polynomial_expansion_Finlayson2015(
        sim, degree=2, root_polynomial_expansion=True) @ np.asarray(m).T, atol=1e-9)


@pytest.mark.parametrize("objective", ["linear", "ciede2000"])
def test_a_hue_rotated_matrix_is_recovered(exact, cases, objective):
    sim, srgb, names = cases["hue"]
    w = _weights(srgb, exact[1], names)
    fitted, cond = fit_model(sim, exact[0], "matrix", weights=w, objective=objective)
    # the fit inverts the camera's rotation: out = R^-1 in
    assert np.allclose(fitted.matrix, np.linalg.inv(HUE), atol=1e-4)
    assert cond.ridge == 0.0
    assert patch_delta_e(fitted.apply(sim), exact[0])[w > 0].max() < 0.01
    assert patch_delta_e(sim, exact[0])[w > 0].mean() > 5  # the error was large


def test_wrong_white_balance_gains_are_recovered(exact, cases):
    sim, srgb, names = cases["wb"]
    w = _weights(srgb, exact[1], names)
    fitted, _ = fit_model(sim, exact[0], "gains", weights=w, objective="linear")
    # to 1e-3: the rendered chart is float32 sRGB-encoded pixels, decoded again
    assert np.allclose(fitted.gains, 1.0 / np.array(WB), rtol=1e-3)
    assert np.allclose(fitted.matrix, np.diag(fitted.gains))
    assert patch_delta_e(fitted.apply(sim), exact[0])[w > 0].max() < 0.01


def test_a_gamma_22_curve_is_recovered_by_matrix_and_curve(exact, cases):
    """A gamma 2.2 encoding read as sRGB: matrix+curve brings the chart below 0.5 ΔE00 and its
    curve follows the exact inverse phi(v) = sRGB-encode(v**2.2) within 0.01 at its knots
    (0.2 - 0.8; the knots are where the PCHIP curve is pinned; between, it interpolates)."""
    sim, srgb, names = cases["gamma"]
    w = _weights(srgb, exact[1], names)
    fitted, _ = fit_model(sim, exact[0], "matrix+curve", weights=w, objective="linear")
    de = patch_delta_e(fitted.apply(sim), exact[0])[w > 0]
    assert de.mean() < 0.1 and de.max() < 0.5
    truth = np.asarray(delinearize_srgb(np.asarray(CURVE_KNOTS) ** 2.2))
    assert fitted.curve is not None
    assert np.allclose(fitted.curve, truth, atol=0.01)
    plain, _ = fit_model(sim, exact[0], "matrix", weights=w, objective="linear")
    assert patch_delta_e(plain.apply(sim), exact[0])[w > 0].mean() > 3 * de.mean()


def test_5_bit_banding_is_not_expressible(exact, cases):
    """No model takes a 5-bit chart below 0.5 ΔE00 held out: quantisation is not a colour
    mapping, and cross-validation shows it."""
    sim, srgb, names = cases["5bit"]
    w = _weights(srgb, exact[1], names)
    for model in ("gains", "matrix", "matrix+curve", "root-polynomial"):
        cv = cross_validate(sim, exact[0], model, weights=w, objective="linear")
        assert np.nanmean(cv) > 0.5, model


def test_cross_validation_holds_every_used_patch_out_once(exact, cases):
    sim, srgb, names = cases["hue"]
    w = _weights(srgb, exact[1], names)
    cv = cross_validate(sim, exact[0], "matrix", weights=w, objective="linear")
    assert np.all(np.isnan(cv[w == 0])) and np.all(np.isfinite(cv[w > 0]))
    assert np.nanmax(cv) < 0.01


# ----------------------------------------------------------------------------------------------
# Hard cases
# ----------------------------------------------------------------------------------------------


def test_a_nearly_grey_simulated_chart_is_regularised_with_a_reason(exact):
    real = exact[0]
    grey = real.mean(axis=1, keepdims=True)
    sim = grey + 1e-5 * (real - grey)  # all colour but a trace removed
    fitted, cond = fit_model(sim, real, "matrix", objective="linear")
    assert cond.condition_number > CONDITION_LIMIT and cond.ridge > 0
    assert cond.reason and "condition number" in cond.reason
    assert np.abs(fitted.coefficients).max() <= MAX_COEFFICIENT


def test_a_singular_chart_never_gives_huge_coefficients(exact):
    sim = np.tile([[0.2, 0.2, 0.2]], (24, 1))  # every patch the same grey
    for model in ("matrix", "root-polynomial", "gains"):
        try:
            fitted, _ = fit_model(sim, exact[0], model, objective="linear")
        except InvalidValueError as exc:
            assert "unstable" in str(exc) or "determine" in str(exc)
        else:
            assert np.abs(fitted.coefficients).max() <= MAX_COEFFICIENT


def test_too_few_patches_are_refused(exact):
    w = np.zeros(24)
    w[:4] = 1
    with pytest.raises(InvalidValueError, match="needs at least"):
        fit_model(exact[0], exact[0], "root-polynomial", weights=w)


def test_zero_and_nan_inputs(exact):
    with pytest.raises(InvalidValueError, match="NaN"):
        fit_model(np.full((24, 3), np.nan), exact[0])
    with pytest.raises(InvalidValueError, match="all black"):
        fit_model(np.zeros((24, 3)), exact[0], "matrix", objective="linear")
    tiny = exact[0] * 1e-300  # near-denormal colours would need gains of 1e300: refused
    with pytest.raises(InvalidValueError, match="unstable"):
        fit_model(tiny, exact[0], "gains", objective="linear")


def test_clipped_and_saturated_patches_are_named():
    names = ("a", "b", "c", "d")
    sim = np.array([[0.5, 0.5, 0.5], [1.0, 0.5, 0.2], [0.4, 0.0, 0.3], [0.3, 0.3, 0.3]])
    real = np.array([[0.5, 0.5, 0.5], [0.9, 0.5, 0.2], [0.4, 0.1, 0.3], [0.3, 0.3, 0.3]])
    ex = usable_patches(sim, real, names, real_clipped=("d",))
    assert set(ex) == {"b", "c", "d"}
    assert "saturated in the simulated" in ex["b"] and "black" in ex["c"]
    assert "clipped in the real" in ex["d"]


# ----------------------------------------------------------------------------------------------
# The pipeline, the .cube and OpenColorIO
# ----------------------------------------------------------------------------------------------

PATCH, GAP = 32, 8


def _centre(i: int) -> tuple[float, float]:
    r, c = divmod(i, 6)
    return (GAP + c * (PATCH + GAP) + PATCH / 2 - 0.5, GAP + r * (PATCH + GAP) + PATCH / 2 - 0.5)


CORNERS = ",".join(f"{v:g}" for i in (0, 5, 23, 18) for v in _centre(i))


def _image(colours: np.ndarray) -> np.ndarray:
    img = np.full((4 * PATCH + 5 * GAP, 6 * PATCH + 7 * GAP, 3), 0.05)
    for i, rgb in enumerate(colours):
        r, c = divmod(i, 6)
        y, x = GAP + r * (PATCH + GAP), GAP + c * (PATCH + GAP)
        img[y:y + PATCH, x:x + PATCH] = rgb
    return img


@pytest.fixture(scope="module")
def images(tmp_path_factory, exact, cases):
    folder = tmp_path_factory.mktemp("fit")
    real = write_png(folder / "real.png", _image(np.clip(exact[1], 0, 1)), 16)
    hue = write_png(folder / "hue.png", _image(np.clip(cases["hue"][1], 0, 1)), 16)
    # scene-linear EXR of the hue-rotated camera, at half the light: a shaper cube
    hue_exr = write_exr(folder / "hue.exr", _image(cases["hue"][0] * 0.5))
    grey = write_png(folder / "grey.png", _image(np.repeat(
        np.clip(exact[1], 0, 1).mean(axis=1, keepdims=True), 3, axis=1)), 16)
    bits5 = write_png(folder / "bits5.png", _image(np.clip(cases["5bit"][1], 0, 1)), 16)
    gamma = write_png(folder / "gamma.png", _image(np.clip(cases["gamma"][1], 0, 1)), 16)
    gamma_exr = write_exr(folder / "gamma.exr", _image(cases["gamma"][0] * 0.5))
    return {"real": real, "hue": hue, "hue_exr": hue_exr, "grey": grey, "bits5": bits5,
            "gamma": gamma, "gamma_exr": gamma_exr, "dir": folder}


def test_fit_correction_api_applies_and_writes_a_cube(images, tmp_path):
    import fidelity

    c = fidelity.fit_correction(images["hue"], images["real"], sim_corners=CORNERS,
                                real_corners=CORNERS)
    assert isinstance(c, fidelity.Correction)
    assert c.encoding == "srgb"
    assert float(np.mean(c.fitted_delta_e[[n in c.used for n in c.patch_names]])) < 0.1
    assert c.before_delta_e.mean() > 5
    cube = c.to_cube(tmp_path / "c.cube")
    text = cube.read_text()
    assert "LUT_3D_SIZE 33" in text and text.startswith("# fidelity fit")
    doc = c.to_json()
    assert doc["model"] == "matrix" and len(doc["patches"]) == 24
    assert np.allclose(doc["matrix"], np.linalg.inv(HUE), atol=2e-3)
    # apply() on the chart's own pixels gives the real chart's colours
    out = c.apply(c.sim_pixels)
    from fidelity.colour.colorimetry import delta_e_2000
    from fidelity.correction.lut import apply_processor, cube_processor

    # the cube's own output is in the SIM's encoding, sRGB (issue 57): a lattice even in the
    # encoding, so close to the model on the chart, not exact
    lut = apply_processor(cube_processor(cube), c.sim_pixels)
    assert np.abs(lut - out).max() < 0.02
    assert np.max(delta_e_2000(c.display_lab(lut), c.display_lab(out))) < 0.2
    assert "output: corrected sRGB-encoded (IEC 61966-2-1) values" in text
    assert "(the input's encoding)" in text and "DOMAIN_MAX" not in text
    # the other convention: scene-linear output
    raw = apply_processor(cube_processor(c.to_cube(tmp_path / "l.cube", 65, "linear")),
                          c.sim_pixels)
    assert np.allclose(raw, linearize_srgb(out), atol=2e-3)
    assert "output: corrected scene-linear values" in (tmp_path / "l.cube").read_text()


@pytest.mark.parametrize("sim_key", ["hue", "hue_exr"])
def test_fit_and_verify_through_opencolorio(images, tmp_path, sim_key):
    """The whole loop: the SIM image through the .cube by OpenColorIO's processor, audited
    again, is within 0.5 ΔE00 of REAL; the .cube is within 0.1 ΔE00 of the model over the
    chart and a dense lattice; the OCIO config loads and gives the cube's result."""
    from fidelity.correction.lut import apply_processor, config_processor, cube_processor
    from fidelity.pipeline.fit import fit_and_verify

    rep = fit_and_verify(images[sim_key], images["real"], tmp_path, sim_corners=CORNERS,
                         real_corners=CORNERS)
    assert rep.before.mean_delta_e > 5
    assert rep.after.mean_delta_e < 0.5
    assert rep.lut.passed and rep.lut.grid_p99 <= 0.1 and rep.lut.chart_max <= 0.1
    if sim_key == "hue_exr":
        # a matrix on a lattice even in light: the smallest cube is exact to float32
        assert [c.size for c in rep.lut_checks] == [33]
        assert rep.lut.grid_max <= 0.01 and rep.lut.chart_max <= 0.01
    else:
        # sRGB in, sRGB out: the encoding's toe between the nodes needs a finer lattice
        assert [c.size for c in rep.lut_checks] == [33, 65]
        assert not rep.lut_checks[0].passed
        assert 0.1 < rep.lut.grid_max <= 0.5  # the most saturated colours of the lattice
    assert rep.prediction_after.dmap_points is not None
    assert rep.prediction_before.dmap_points is not None
    assert rep.prediction_after.dmap_points < rep.prediction_before.dmap_points
    text = Path(rep.files["cube"]).read_text()
    assert "LUT_1D_SIZE" not in text  # no shaper: ffmpeg 5.1 misreads one
    if sim_key == "hue_exr":
        assert rep.correction.encoding == "linear"
        assert "DOMAIN_MAX" in text and "scene-linear" in text
    x = rep.correction.sim_pixels
    a = apply_processor(cube_processor(rep.files["cube"]), x)
    b = apply_processor(config_processor(rep.files["ocio"]), x)
    assert np.array_equal(a, b)


def test_a_nearly_grey_real_chart_is_refused(images, tmp_path):
    from fidelity.pipeline.fit import fit_correction

    with pytest.raises(InvalidValueError, match="nearly grey"):
        fit_correction(images["hue"], images["grey"], sim_corners=CORNERS, real_corners=CORNERS)


def test_cli_fit_writes_the_files_and_the_report(images, tmp_path):
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["fit", str(images["hue"]), str(images["real"]), "--out",
                                  str(out), "--sim-corners", CORNERS, "--real-corners", CORNERS,
                                  "--correction", "root-polynomial"])
    assert r.exit_code == 0, r.output
    for name in ("correction.cube", "correction.ocio", "correction.json", "report.json",
                 "report.html"):
        assert (out / name).is_file()
    rep = json.loads((out / "report.json").read_text())
    assert rep["model"] == "root-polynomial"
    assert rep["before"]["mean_delta_e"] > 5 > 0.5 > rep["after"]["mean_delta_e"]
    assert rep["lut_check"]["chart_max_delta_e"] <= 0.1
    assert rep["lut_check"]["grid_p99_delta_e"] <= 0.1
    assert rep["cross_validated_mean_delta_e"] < 0.5
    assert len(rep["correction"]["coefficients"]) == 3
    assert len(rep["correction"]["coefficients"][0]) == 6
    excluded = rep["correction"]["excluded"]
    assert all(p["used"] == (p["name"] not in excluded) for p in rep["correction"]["patches"])


def test_cli_fit_bad_input_is_one_line_exit_2(images, tmp_path):
    r = CliRunner().invoke(main, ["fit", str(tmp_path / "missing.png"), str(images["real"]),
                                  "--out", str(tmp_path / "o")])
    assert r.exit_code == 2
    assert "missing.png" in r.output


def test_a_missing_opencolorio_names_the_extra(monkeypatch):
    import sys

    from fidelity.correction import lut

    monkeypatch.setitem(sys.modules, "PyOpenColorIO", None)  # import raises ImportError
    with pytest.raises(InvalidValueError, match=r"camera-fidelity\[fit\]"):
        lut.ocio()


def test_cli_fit_says_when_the_model_cannot_express_the_difference(images, tmp_path):
    """5-bit banding: the report marks the fit as not expressing the difference."""
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["fit", str(images["bits5"]), str(images["real"]), "--out",
                                  str(out), "--sim-corners", CORNERS, "--real-corners", CORNERS,
                                  "--objective", "linear"])
    # a warning line and exit 1 (issue 57), or exit 0 with --accept-warnings
    assert r.exit_code == 1, r.output
    assert "fidelity: warning: the matrix model does not express this difference" in r.output
    rep = json.loads((out / "report.json").read_text())
    assert rep["correction"]["expressed"] is False
    assert rep["cross_validated_mean_delta_e"] > 0.5
    assert any("does not express" in w for w in rep["warnings"])
    again = CliRunner().invoke(main, ["fit", str(images["bits5"]), str(images["real"]),
                                      "--out", str(tmp_path / "o2"), "--sim-corners", CORNERS,
                                      "--real-corners", CORNERS, "--objective", "linear",
                                      "--accept-warnings"])
    assert again.exit_code == 0, again.output
    assert "fidelity: warning:" in again.output


def test_cli_fit_warns_and_exits_1_when_the_cube_misses_its_check(images, tmp_path,
                                                                  monkeypatch):
    """Issue 57: a cube whose check misses its limit (here only a 9^3 lattice is tried) is a
    warning line and exit 1, not a quiet "limit NOT met"."""
    import fidelity.pipeline.fit as fit_module

    monkeypatch.setattr(fit_module, "CUBE_SIZES", (9,))
    r = CliRunner().invoke(main, ["fit", str(images["hue"]), str(images["real"]), "--out",
                                  str(tmp_path / "o"), "--sim-corners", CORNERS,
                                  "--real-corners", CORNERS])
    assert r.exit_code == 1, r.output
    assert "limit NOT met" in r.output
    assert "fidelity: warning: the .cube (9^3, the largest tried) misses its check" in r.output


def test_cli_fit_of_a_chart_onto_itself_says_there_is_nothing_to_correct(images, tmp_path):
    """Sim equal to real: a note that they already match, not a warning that the model
    cannot express the difference."""
    r = CliRunner().invoke(main, ["fit", str(images["real"]), str(images["real"]), "--out",
                                  str(tmp_path / "out"), "--sim-corners", CORNERS,
                                  "--real-corners", CORNERS])
    assert r.exit_code == 0, r.output
    assert "note: the simulation already matches the real camera" in r.output
    assert "warning" not in r.output
    rep = json.loads((tmp_path / "out" / "report.json").read_text())
    assert rep["before"]["mean_delta_e"] < 0.01 and rep["after"]["mean_delta_e"] < 0.01


def test_the_normalisation_is_left_out_of_the_correction(images, exact, tmp_path):
    """``exposure`` (default) keeps the simulator's exposure: a SIM one stop darker than REAL
    and otherwise equal gets a correction that changes nothing; ``none`` corrects the
    exposure too (linear values doubled)."""
    from fidelity.pipeline.fit import fit_correction

    dark = np.asarray(delinearize_srgb(np.asarray(linearize_srgb(np.clip(exact[1], 0, 1)))
                                       * 0.5))
    sim = write_png(tmp_path / "dark.png", _image(dark), 16)
    keep = fit_correction(sim, images["real"], sim_corners=CORNERS, real_corners=CORNERS,
                          objective="linear")
    assert keep.normalisation.exposure_ev == pytest.approx(1.0, abs=0.01)
    x = keep.sim_pixels
    assert np.abs(keep.apply(x) - x).max() < 2e-3
    fix = fit_correction(sim, images["real"], sim_corners=CORNERS, real_corners=CORNERS,
                         objective="linear", normalise_mode="none")
    lin = np.asarray(linearize_srgb(x))
    assert np.allclose(np.asarray(linearize_srgb(fix.apply(x))), 2 * lin, atol=2e-3)


@pytest.mark.parametrize(("sim_key", "model"), [
    ("gamma", "matrix+curve"), ("gamma_exr", "matrix+curve"), ("gamma", "root-polynomial"),
    ("hue_exr", "root-polynomial")])
def test_a_bending_model_meets_the_lut_tolerance(images, tmp_path, sim_key, model):
    """Requirement 3 for the models that bend (a tone curve, a root-polynomial): the smallest
    cube size whose check passes (within 0.1 ΔE00 of the model over the chart and over 99 % of
    the 41^3 lattice, within 0.5 everywhere) is written, every smaller one tried first and
    refused."""
    from fidelity.correction.lut import CUBE_SIZES
    from fidelity.pipeline.fit import fit_and_verify

    rep = fit_and_verify(images[sim_key], images["real"], tmp_path, model=model,
                         sim_corners=CORNERS, real_corners=CORNERS)
    sizes = [c.size for c in rep.lut_checks]
    assert sizes == list(CUBE_SIZES[:len(sizes)])
    assert not any(c.passed for c in rep.lut_checks[:-1])
    assert rep.lut.passed and rep.lut.grid_max <= 0.5 and rep.lut.chart_max <= 0.1
    assert rep.lut.grid_p99 <= 0.05 and not rep.warnings


def test_the_windows_alone_measure_what_the_whole_corrected_image_measures(images, tmp_path):
    """Requirement 5's shortcut: the SIM's patch windows through OpenColorIO give the same
    patch means as the whole SIM image through OpenColorIO measured in the same windows; and
    fit_and_verify with the corrected image written reports the same after-ΔE00."""
    from fidelity.chart.image import read_image
    from fidelity.correction.lut import apply_processor, config_processor
    from fidelity.pipeline.fit import fit_and_verify, remeasure

    for key in ("hue", "hue_exr"):
        fast = fit_and_verify(images[key], images["real"], tmp_path / key / "fast",
                              model="root-polynomial", sim_corners=CORNERS, real_corners=CORNERS)
        whole = fit_and_verify(images[key], images["real"], tmp_path / key / "whole",
                               model="root-polynomial", sim_corners=CORNERS,
                               real_corners=CORNERS, corrected=True)
        assert "corrected" not in fast.files
        assert Path(whole.files["corrected"]).name == ("corrected.png" if key == "hue"
                                                       else "corrected.exr")
        # the windows through the cube alone, the whole image through correction.ocio (the
        # same cube): the same patch means, the whole image's written to 16 bits or float
        assert np.allclose(fast.after.delta_e, whole.after.delta_e, atol=2e-3)
        assert fast.after.mean_delta_e < 0.5
        # remeasure itself, both ways, on the audit of the SIM image
        from fidelity.measure.pixels import measure_pixels

        img = read_image(images[key])
        audit = measure_pixels(img.pixels, CORNERS, encoding=img.encoding)
        proc = config_processor(fast.files["ocio"])
        a = remeasure(img.pixels, audit, functools.partial(apply_processor, proc))
        b = remeasure(apply_processor(proc, img.pixels), audit)
        assert np.allclose(a, b, atol=1e-7)
        before = img.pixels.copy()
        apply_processor(proc, img.pixels)
        assert np.array_equal(img.pixels, before)  # the input is not written over
        assert not np.allclose(a, remeasure(img.pixels, audit), atol=1e-3)  # it did correct
        written = read_image(whole.files["corrected"])
        assert written.pixels.shape == img.pixels.shape


def test_cli_fit_write_corrected(images, tmp_path):
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["fit", str(images["hue"]), str(images["real"]), "--out",
                                  str(out), "--sim-corners", CORNERS, "--real-corners", CORNERS,
                                  "--write-corrected"])
    assert r.exit_code == 0, r.output
    assert (out / "corrected.png").is_file() and "corrected.png" in r.output


# ----------------------------------------------------------------------------------------------
# One matrix over several illuminants (--pair)
# ----------------------------------------------------------------------------------------------

GAINS_A = np.array([0.8, 1.0, 1.3])  # a white-balance error of the simulator under A


@pytest.fixture(scope="module")
def illuminant_pairs(tmp_path_factory):
    """The suite's exact camera (real) and the same camera with the hue-rotated colour matrix
    (sim), rendered in closed form under D65 and under A; under A the simulator's pixels also
    carry a white-balance error (linear values divided by GAINS_A)."""
    folder = tmp_path_factory.mktemp("pairs")
    out = []
    for ill in ("D65", "A"):
        real = render_chart(_camera(), ill, pixels_per_patch=8).measurement.srgb
        sim = render_chart(_camera(ccm={"method": "matrix", "matrix": HUE.tolist()}), ill,
                           pixels_per_patch=8).measurement.srgb
        if ill == "A":
            sim = delinearize_srgb(np.asarray(linearize_srgb(sim)) / GAINS_A)
        out.append((write_png(folder / f"sim_{ill}.png", _image(np.clip(sim, 0, 1)), 16),
                    write_png(folder / f"real_{ill}.png", _image(np.clip(real, 0, 1)), 16)))
    return out


def test_one_matrix_over_two_illuminants_is_recovered(illuminant_pairs, tmp_path):
    """The shared matrix is the inverse hue rotation, the gains under A undo the white-balance
    error (relative to D65's, which are fixed at 1) and each illuminant's corrected ΔE00 is
    measured through its own cube."""
    from fidelity.pipeline.fit import fit_pairs_and_verify

    shared = fit_pairs_and_verify(illuminant_pairs, tmp_path, sim_corners=CORNERS,
                                  real_corners=CORNERS)
    # the exposure normalisation scales each pair by one number: compare up to scale
    m = shared.matrix.matrix
    assert np.allclose(m / m.sum(axis=1).mean(), np.linalg.inv(HUE), atol=5e-3)
    g = shared.gains[1]
    assert np.allclose(g / g[1], GAINS_A / GAINS_A[1], rtol=5e-3)
    assert np.array_equal(shared.gains[0], np.ones(3))
    for rep in shared.reports:
        # the rotated colours leave the sRGB gamut on a few patches, clipped in the PNG (more
        # of them under A): those are excluded and named; the used ones are corrected
        c = rep.correction
        used = np.array([n not in c.excluded for n in c.patch_names])
        assert 3 <= used.sum() < 24
        assert rep.before.mean_delta_e > 3
        assert rep.after.delta_e[used].max() < 0.5
        assert rep.after.mean_delta_e < rep.before.mean_delta_e / 3
        assert c.cv_mean < 0.5
        assert rep.lut.passed
        assert Path(rep.files["cube"]).is_file()
    assert Path(shared.reports[1].files["cube"]).parent.name == "pair-2"
    doc = shared.to_json()
    assert len(doc["pairs"]) == 2 and doc["pairs"][1]["gains"] == g.tolist()


def test_a_single_matrix_fit_over_both_is_worse_without_the_gains(illuminant_pairs, tmp_path):
    """Without per-illuminant gains the A pair's white-balance error is left over: one plain
    matrix fitted to the A pair alone (reference) does what the shared fit does for it."""
    from fidelity.pipeline.fit import fit_and_verify, fit_pairs_and_verify

    shared = fit_pairs_and_verify(illuminant_pairs, tmp_path / "s", sim_corners=CORNERS,
                                  real_corners=CORNERS)
    alone = fit_and_verify(*illuminant_pairs[1], tmp_path / "a", sim_corners=CORNERS,
                           real_corners=CORNERS, objective="linear")
    assert abs(shared.reports[1].after.mean_delta_e - alone.after.mean_delta_e) < 0.2


def test_cli_fit_pairs_warn_by_pair_and_exit_1(illuminant_pairs, tmp_path, monkeypatch):
    import fidelity.pipeline.fit as fit_module

    monkeypatch.setattr(fit_module, "CUBE_SIZES", (9,))
    args = ["fit", "--sim-corners", CORNERS, "--real-corners", CORNERS]
    for sim, real in illuminant_pairs:
        args += ["--pair", str(sim), str(real)]
    r = CliRunner().invoke(main, [*args, "--out", str(tmp_path / "o1")])
    assert r.exit_code == 1, r.output
    assert "fidelity: warning: pair 1: the .cube (9^3, the largest tried)" in r.output
    ok = CliRunner().invoke(main, [*args, "--out", str(tmp_path / "o2"), "--accept-warnings"])
    assert ok.exit_code == 0, ok.output


def test_cli_fit_pairs(illuminant_pairs, tmp_path):
    out = tmp_path / "out"
    args = ["fit", "--out", str(out), "--sim-corners", CORNERS, "--real-corners", CORNERS]
    for sim, real in illuminant_pairs:
        args += ["--pair", str(sim), str(real)]
    r = CliRunner().invoke(main, args)
    assert r.exit_code == 0, r.output
    rep = json.loads((out / "report.json").read_text())
    assert len(rep["pairs"]) == 2
    for pair in rep["pairs"]:
        assert pair["before_mean_delta_e"] > 3 * pair["after_mean_delta_e"]
        assert pair["fitted_mean_delta_e"] < 0.5
    assert (out / "report.html").is_file() and (out / "pair-2" / "correction.cube").is_file()
    assert "pair 2" in r.output
    bad = CliRunner().invoke(main, ["fit", str(illuminant_pairs[0][0]), str(illuminant_pairs[0][1]),
                                    "--out", str(tmp_path / "o2"), "--pair",
                                    str(illuminant_pairs[1][0]), str(illuminant_pairs[1][1])])
    assert bad.exit_code == 2
    one = CliRunner().invoke(main, ["fit", "--out", str(tmp_path / "o3"), "--pair",
                                    str(illuminant_pairs[1][0]), str(illuminant_pairs[1][1])])
    assert one.exit_code == 2


# ----------------------------------------------------------------------------------------------
# A camera model file instead of a rendered SIM (--camera)
# ----------------------------------------------------------------------------------------------


def test_fit_camera_writes_a_corrected_camera_that_check_confirms(images, tmp_path):
    """The hue-rotated camera as a camera file, fitted onto the exact camera's chart: the
    corrected camera's matrix is the identity (hue matrix times its fitted inverse) up to the
    exposure normalisation's scale, and ``fidelity check corrected.toml`` gives the real
    camera's ΔE00 against the reference within 0.05 (the fit made the simulator match it;
    the corrected camera corrects before its clipping, so it recovers the patches the image
    fit excluded) where the uncorrected camera gives above 5."""
    import tomli_w

    from fidelity.chart.image import read_image
    from fidelity.measure.pixels import measure_pixels

    d = copy.deepcopy(EXACT)
    d["ccm"] = {"method": "matrix", "matrix": HUE.tolist()}
    cam = tmp_path / "hue.toml"
    cam.write_text(tomli_w.dumps(d))
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["fit", "--camera", str(cam), str(images["real"]), "--out",
                                  str(out), "--real-corners", CORNERS])
    assert r.exit_code == 0, r.output
    toml = out / "corrected.toml"
    assert toml.is_file() and (out / "sim_render.png").is_file()
    from fidelity.camera.model import read_camera_file

    m = np.asarray(read_camera_file(toml).ccm.matrix)
    assert np.allclose(m / m.diagonal().mean(), np.eye(3), atol=2e-3)
    real = read_image(images["real"])
    real_de = measure_pixels(real.pixels, CORNERS, encoding=real.encoding).measurement
    checks = {}
    for name, path in (("corrected", toml), ("uncorrected", cam)):
        j = tmp_path / f"{name}.json"
        res = CliRunner().invoke(main, ["check", str(path), "--json", str(j)])
        assert res.exit_code in (0, 1), res.output
        checks[name] = json.loads(j.read_text())["mean_delta_e"]
    assert abs(checks["corrected"] - real_de.mean_delta_e) < 0.05
    assert checks["uncorrected"] > 5
    rep = json.loads((out / "report.json").read_text())
    assert rep["after"]["mean_delta_e"] < 0.5


def test_fit_camera_refuses_what_a_camera_file_cannot_hold(images, tmp_path):
    d = copy.deepcopy(EXACT)
    cam = tmp_path / "c.toml"
    import tomli_w

    cam.write_text(tomli_w.dumps(d))
    r = CliRunner().invoke(main, ["fit", "--camera", str(cam), str(images["real"]), "--out",
                                  str(tmp_path / "o"), "--correction", "root-polynomial"])
    assert r.exit_code == 2 and "3x3 colour matrix" in r.output
    r = CliRunner().invoke(main, ["fit", "--camera", str(cam), str(images["real"]),
                                  str(images["real"]), "--out", str(tmp_path / "o2")])
    assert r.exit_code == 2


# ----------------------------------------------------------------------------------------------
# Measured on COCO (--measure)
# ----------------------------------------------------------------------------------------------


def test_measure_gives_the_coco_loss_before_and_after(images, shared, tmp_path):
    """With a MeasureRequest (``--measure``) the simulator's colours before and after the
    correction are emulated on COCO images and run through YOLOX-nano: for SIM = REAL (an
    identity correction) both losses are exactly 0; for the hue-rotated SIM both are
    measured on the same images, and the report carries them."""
    from fidelity.coco.measure import MeasureRequest, resolve_coco_inputs
    from fidelity.pipeline.fit import fit_and_verify
    from fidelity.report.jsonform import fit_json

    req = MeasureRequest(resolve_coco_inputs(), limit=3, store=str(tmp_path / "store"))
    same = fit_and_verify(images["real"], images["real"], tmp_path / "same",
                          sim_corners=CORNERS, real_corners=CORNERS, measure=req)
    assert [m.model for m in same.measured_after] == ["yolox_nano"]
    for m in (*same.measured_before, *same.measured_after):
        assert m.images == 3 and m.dmap_points == 0.0
    hue = fit_and_verify(images["hue"], images["real"], tmp_path / "hue",
                         sim_corners=CORNERS, real_corners=CORNERS, measure=req)
    b, a = hue.measured_before[0], hue.measured_after[0]
    assert b.images == a.images == 3
    assert np.isfinite(b.dmap_points) and np.isfinite(a.dmap_points)
    assert b.mapping != a.mapping  # two different emulations were measured
    doc = fit_json(hue)
    assert doc["measured_after"][0]["dmap_points"] == a.dmap_points
    from fidelity.report.fit import fit_lines, write_fit_report

    assert sum("COCO" in line for line in fit_lines(hue)) == 2
    html = tmp_path / "report.html"
    write_fit_report(hue, html_path=html)
    assert "measured on COCO after" in html.read_text()


def test_cli_fit_writes_a_credibility_record_that_follows_the_schema(images, tmp_path):
    """fit --evidence: one subject, the pair; the inputs' SHA-256, the measurement after the
    correction, the written files' SHA-256, valid against the shipped evidence schema."""
    import hashlib

    import jsonschema

    from fidelity.report.evidence import evidence_schema

    out, record = tmp_path / "out", tmp_path / "evidence.json"
    r = CliRunner().invoke(main, ["fit", str(images["hue"]), str(images["real"]), "--out",
                                  str(out), "--sim-corners", CORNERS, "--real-corners", CORNERS,
                                  "--evidence", str(record)])
    assert r.exit_code == 0, r.output
    doc = json.loads(record.read_text())
    jsonschema.validate(doc, evidence_schema())
    (subject,) = doc["subjects"]
    sha = {i["role"]: i["sha256"] for i in subject["inputs"]}
    assert sha["simulated image"] == hashlib.sha256(images["hue"].read_bytes()).hexdigest()
    assert sha["real image"] == hashlib.sha256(images["real"].read_bytes()).hexdigest()
    rep = json.loads((out / "report.json").read_text())
    assert subject["measurement"]["value"] == pytest.approx(rep["after"]["mean_delta_e"])
    cube = subject["correction"]["files"]["cube"]
    assert cube["sha256"] == hashlib.sha256((out / "correction.cube").read_bytes()).hexdigest()
    assert doc["record"]["command"] == "fit" and doc["record"]["exit_code"] == 0
    # never over an input
    again = CliRunner().invoke(main, ["fit", str(images["hue"]), str(images["real"]), "--out",
                                      str(tmp_path / "o2"), "--sim-corners", CORNERS,
                                      "--real-corners", CORNERS, "--evidence",
                                      str(images["real"])])
    assert again.exit_code == 2


# ----------------------------------------------------------------------------------------------
# The camera file's optics and noise (fit --camera)
# ----------------------------------------------------------------------------------------------

BASE_CAMERA = Path(__file__).resolve().parents[2] / "cameras" / "nikon5100-cheung-d65.toml"


def _camera_file(folder: Path, name: str, **sections: dict) -> Path:
    import tomllib

    import tomli_w

    data = tomllib.loads(BASE_CAMERA.read_text())
    data.update(sections)
    data["name"] = name
    path = folder / f"{name}.toml"
    path.write_text(tomli_w.dumps(data))
    return path


def _turned_png(camera: Path, path: Path) -> Path:
    """REAL: the camera's turned chart (the check's frame) as a 16-bit PNG, found by the
    audit's finder like any photo of a chart."""
    frame = render_chart(str(camera), "D65", frame=True).frame
    return write_png(path, frame.srgb, 16)


def test_fit_camera_recovers_a_known_lens_and_sensor(tmp_path):
    """REAL is a camera of known optics and noise (Gaussian PSF sigma 1.5 px; full well 5000
    e-, read noise 3 e-); SIM is the same camera with neither. fit --camera gives back sigma
    within 2 % and the full well within 5 % of the truth, the written camera's MTF50 and SNR
    match REAL's, and check of it measures the same."""
    truth = _camera_file(tmp_path, "truth", optics={"kind": "gaussian", "sigma_px": 1.5},
                         noise={"full_well": 5000.0, "read_noise": 3.0, "seed": 7})
    real = _turned_png(truth, tmp_path / "real.png")
    sim = _camera_file(tmp_path, "sim")
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["fit", "--camera", str(sim), str(real), "--out", str(out)])
    assert r.exit_code == 0, r.output
    rep = json.loads((out / "report.json").read_text())
    fits = {f["property"]: f for f in rep["camera_fits"]}
    assert fits["sharpness"]["parameter"] == "optics.sigma_px"
    assert fits["sharpness"]["value"] == pytest.approx(1.5, rel=0.02)
    assert fits["noise"]["value"] == pytest.approx(5000.0, rel=0.05)
    assert fits["sharpness"]["matched"] and fits["noise"]["matched"]
    assert fits["noise"]["before"] is None  # the SIM camera is noiseless: SNR inf
    from fidelity.camera.model import read_camera_file

    cam = read_camera_file(out / "corrected.toml")
    assert cam.optics.kind == "gaussian"
    assert cam.noise.full_well == pytest.approx(fits["noise"]["value"], abs=0.05)
    assert cam.noise.read_noise == 0.0  # the SIM camera's own read noise, kept
    assert "optics fitted: Gaussian PSF sigma" in r.output
    j = tmp_path / "check.json"
    c = CliRunner().invoke(main, ["check", str(out / "corrected.toml"), "--json", str(j)])
    assert c.exit_code in (0, 1), c.output
    got = json.loads(j.read_text())["properties"]["predictions"]
    assert got["sharpness"]["native_x"] == pytest.approx(fits["sharpness"]["real"], rel=0.01)
    assert got["noise"]["native_x"] == pytest.approx(fits["noise"]["real"], rel=0.03)


def test_fit_camera_removes_a_lens_softer_than_real_and_colour_only_keeps_it(tmp_path):
    """A SIM camera with a soft lens fitted onto a sharp, noiseless REAL: no PSF is the
    answer (the lens removed), and noise stays off. With --colour-only the lens stays."""
    real = _turned_png(_camera_file(tmp_path, "sharp"), tmp_path / "real.png")
    soft = _camera_file(tmp_path, "soft", optics={"kind": "gaussian", "sigma_px": 1.0})
    from fidelity.camera.model import read_camera_file

    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["fit", "--camera", str(soft), str(real), "--out", str(out)])
    assert r.exit_code == 0, r.output
    fits = {f["property"]: f for f in json.loads((out / "report.json").read_text())[
        "camera_fits"]}
    assert fits["sharpness"]["value"] == 0.0 and fits["sharpness"]["matched"]
    assert fits["noise"]["value"] is None and fits["noise"]["real"] is None  # inf: noiseless
    assert read_camera_file(out / "corrected.toml").optics.kind == "none"
    kept = tmp_path / "kept"
    r = CliRunner().invoke(main, ["fit", "--camera", str(soft), str(real), "--out", str(kept),
                                  "--colour-only"])
    assert r.exit_code == 0, r.output
    assert read_camera_file(kept / "corrected.toml").optics.sigma_px == 1.0
    assert json.loads((kept / "report.json").read_text())["camera_fits"] == []
    bad = CliRunner().invoke(main, ["fit", str(real), str(real), "--out", str(tmp_path / "b"),
                                    "--colour-only"])
    assert bad.exit_code == 2 and "--colour-only goes with --camera" in bad.output


def test_fit_of_images_compares_sharpness_and_noise_and_says_the_cube_is_colour_only(
        tmp_path):
    """fit SIM REAL (images): the two charts' noise at the detector's input, with its
    predicted loss, is printed and in the JSON; the .cube corrects colour only, and says so."""
    sim = _turned_png(_camera_file(tmp_path, "sim"), tmp_path / "sim.png")
    real = _turned_png(_camera_file(tmp_path, "noisy", noise={"full_well": 2000.0}),
                       tmp_path / "real.png")
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["fit", str(sim), str(real), "--out", str(out)])
    assert r.exit_code == 0, r.output
    assert "sharpness, simulation against real camera at the detector's input" in r.output
    assert "the .cube corrects colour only" in r.output
    props = json.loads((out / "report.json").read_text())["properties"]
    assert math.isinf(float(props["sim"]["predictions"]["noise"]["x"] or math.inf))
    assert props["real"]["predictions"]["noise"]["loss"] > 0
