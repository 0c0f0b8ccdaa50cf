"""Issue 57: the .cube that ``fidelity fit`` writes works where cubes are applied.

The suite's exact camera with a known error (a hue-rotated colour matrix, white-balance gains, a
gamma 2.2 tone curve read as sRGB), rendered in closed form and stored as an 8-bit PNG, a 16-bit
PNG and a float EXR (scene-linear, twice the light: values above 1), is fitted onto the exact
camera's chart (the EXR's gains error unclipped, as a float render holds it). The written cube, with its default convention (the SIM's own encoding), is then
applied to the SIM image by ffmpeg's ``lut3d``, ``oiiotool --ociofiletransform`` and an
OpenColorIO ``FileTransform`` (:mod:`tests.fixtures.cube_tools`, none of fidelity's LUT code),
and each corrected image is compared with REAL as ``fidelity compare`` compares: within
:data:`TOLERANCE` ΔE00 of the corrected ΔE00 that fit reports. A 4x-bright EXR (gains 0.25,
``--exposure 0 --normalise none``) comes back with its white patch at the reference's, not
clamped at 1.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fidelity.chart.image import write_exr, write_png
from fidelity.chart.read import ReadOptions
from fidelity.cli import main
from fidelity.colour.colorimetry import linearize_srgb
from tests.fixtures.cube_tools import TOOLS, apply_cube
from tests.pipeline.test_fit import CORNERS, HUE, PATCH, WB, _camera, _centre, _image, _patches

pytest.importorskip("PyOpenColorIO", reason="fidelity fit needs opencolorio ([fit])")

pytestmark = pytest.mark.slow

#: Largest difference between the ΔE00 of the SIM put through the cube by a tool and the
#: corrected ΔE00 that fit reports (issue 57).
TOLERANCE = 0.3
#: The known errors and the model that expresses each.
ERRORS = {"hue": ("matrix", {"ccm": {"method": "matrix", "matrix": HUE.tolist()}}),
          "wb": ("gains", {"white_balance": {"method": "gains", "gains": list(WB)}}),
          "gamma": ("matrix+curve", {"tone": {"curve": "gamma", "gamma": 2.2}})}
KINDS = ("png8", "png16", "exr")
SUFFIX = {"png8": ".png", "png16": ".png", "exr": ".exr"}
WHITE = 18  # the chart's white patch


def _write(folder: Path, name: str, kind: str, patches: tuple) -> Path:
    linear, encoded = patches[0], patches[1]
    if kind == "exr":  # scene-linear, twice the light: the white patch near 1.8
        return write_exr(folder / f"{name}.exr", _image(2.0 * np.asarray(linear)))
    return write_png(folder / f"{name}-{kind}.png", _image(np.clip(encoded, 0, 1)),
                     8 if kind == "png8" else 16)


@pytest.fixture(scope="module")
def charts(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tools")
    exact = _patches(_camera())
    sims = {}
    for err, (_, changes) in ERRORS.items():
        patches = _patches(_camera(**changes))
        for kind in KINDS:
            if err == "wb" and kind == "exr":
                # a float render does not clip: the gains' white R, 0.9 x 1.25, stays above 1
                patches = (np.asarray(exact[0]) * np.asarray(WB), patches[1])
            sims[(err, kind)] = _write(folder, err, kind, patches)
    real = write_png(folder / "real.png", _image(np.clip(exact[1], 0, 1)), 16)
    bright = write_exr(folder / "bright4.exr", _image(4.0 * np.asarray(exact[0])))
    return {"sims": sims, "real": real, "bright": bright, "dir": folder}


@pytest.fixture(scope="module")
def fits(charts):
    """One fit per known error and SIM kind, default cube convention."""
    from fidelity.pipeline.fit import fit_and_verify

    out = {}
    for (err, kind), sim in charts["sims"].items():
        out[(err, kind)] = fit_and_verify(sim, charts["real"], charts["dir"] / f"fit-{err}-{kind}",
                                          model=ERRORS[err][0], sim_corners=CORNERS,
                                          real_corners=CORNERS)
    return out


def _compared(corrected: Path, real: Path, **kwargs) -> float:
    from fidelity.pipeline.compare import compare_charts

    rep = compare_charts(corrected, real, sim_corners=CORNERS, real_corners=CORNERS, **kwargs)
    return float(rep.measurement.mean_delta_e)


@pytest.mark.parametrize("tool", TOOLS)
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("error", list(ERRORS))
def test_the_cube_applied_by_the_tool_reaches_the_corrected_delta_e(charts, fits, tmp_path,
                                                                   error, kind, tool):
    rep = fits[(error, kind)]
    assert rep.lut.passed and not rep.warnings, (rep.lut_checks, rep.warnings)
    assert rep.before.mean_delta_e > 0.5  # a real error to correct
    sim = charts["sims"][(error, kind)]
    out = apply_cube(tool, sim, Path(rep.files["cube"]), tmp_path / f"corrected{SUFFIX[kind]}")
    got = _compared(out, charts["real"])
    assert abs(got - rep.after.mean_delta_e) <= TOLERANCE, (got, rep.after.mean_delta_e)
    assert got < rep.before.mean_delta_e / 2


def test_the_cube_keeps_the_sims_encoding_and_says_so(fits):
    """sRGB in, sRGB out for the PNGs; scene-linear in, scene-linear out over 0 .. the EXR's
    largest value for the EXR (DOMAIN_MAX, no shaper anywhere: ffmpeg misreads one)."""
    for (_, kind), rep in fits.items():
        text = Path(rep.files["cube"]).read_text()
        assert "LUT_1D_SIZE" not in text and "LUT_3D_INPUT_RANGE" not in text
        title = next(line for line in text.splitlines() if line.startswith("TITLE"))
        if kind == "exr":
            top = rep.correction.domain_max
            assert rep.output == "linear"
            assert f"scene-linear 0..{top:g} in, scene-linear out" in title
            lines = text.splitlines()
            k = next(i for i, line in enumerate(lines) if line.startswith("LUT_3D_SIZE"))
            assert lines[k + 1] == "DOMAIN_MIN 0 0 0"
            assert lines[k + 2] == f"DOMAIN_MAX {top:g} {top:g} {top:g}"
            assert top > 1.7  # the white patch's 1.8 is covered, not clamped at 1
        else:
            assert rep.output == "encoded" and "sRGB-encoded 0..1 in, sRGB-encoded out" in title
            assert "DOMAIN_MAX" not in text


@pytest.fixture(scope="module")
def bright(charts):
    """The exact camera at 4x the light (a missing 1/4 light scale), float EXR, fitted with
    gains, a fixed exposure of 0 and no normalisation: the correction is the exposure."""
    from fidelity.pipeline.fit import fit_and_verify

    return fit_and_verify(charts["bright"], charts["real"], charts["dir"] / "fit-bright",
                          model="gains", sim_corners=CORNERS, real_corners=CORNERS,
                          normalise_mode="none", read=ReadOptions(exposure=0.0))


def _white(path: Path) -> np.ndarray:
    """The mean linear value of the white patch's central 16 x 16 pixels (sRGB-decoded for a
    PNG), read by OpenImageIO."""
    import OpenImageIO as oiio

    px = oiio.ImageBuf(str(path)).get_pixels(oiio.FLOAT)[..., :3]
    x, y = (round(v + 0.5) for v in _centre(WHITE))
    win = px[y - PATCH // 4:y + PATCH // 4, x - PATCH // 4:x + PATCH // 4].reshape(-1, 3)
    lin = win if path.suffix == ".exr" else np.asarray(linearize_srgb(win))
    return np.asarray(lin, np.float64).mean(axis=0)


def test_a_4x_bright_exr_is_fitted_unclamped(bright, charts):
    c = bright.correction
    assert np.allclose(c.model.gains, 0.25, rtol=2e-3)
    # values above 1 are light, not clipping: only cyan (a channel at 0) is left out
    assert not any("clipped" in why for why in c.excluded.values()), c.excluded
    assert set(c.excluded) <= {"cyan"}
    assert c.domain_max >= float(_white(charts["bright"]).max())
    assert bright.before.mean_delta_e > 20 and bright.after.mean_delta_e < 0.05
    assert bright.lut.passed and not bright.warnings


@pytest.mark.parametrize("tool", TOOLS)
def test_a_4x_bright_exr_through_the_tool_is_not_clamped(bright, charts, tmp_path, tool):
    out = apply_cube(tool, charts["bright"], Path(bright.files["cube"]), tmp_path / "c.exr")
    sim_white, real_white = _white(charts["bright"]), _white(charts["real"])
    assert sim_white.min() > 3.0  # the render's white patch, far above 1
    # back at the reference's white (clamped at 1 it would come back at 0.25)
    assert np.allclose(_white(out), real_white, rtol=0.01), (_white(out), real_white)
    got = _compared(out, charts["real"], normalise_mode="none", read=ReadOptions(exposure=0.0))
    assert abs(got - bright.after.mean_delta_e) <= TOLERANCE


def test_cube_output_linear_for_an_srgb_sim(charts, tmp_path):
    """``--cube-output linear``: sRGB in, scene-linear out, said on the terminal, in the
    header and in report.json; oiiotool's float result is the correction."""
    sim = charts["sims"][("hue", "png16")]
    out = tmp_path / "o"
    r = CliRunner().invoke(main, ["fit", str(sim), str(charts["real"]), "--out", str(out),
                                  "--sim-corners", CORNERS, "--real-corners", CORNERS,
                                  "--cube-output", "linear"])
    assert r.exit_code == 0, r.output
    assert "output corrected scene-linear pixels, not the SIM's encoding" in r.output
    text = (out / "correction.cube").read_text()
    assert 'sRGB-encoded 0..1 in, scene-linear out"' in text
    rep = json.loads((out / "report.json").read_text())
    assert rep["cube"]["input"] == "srgb-encoded" and rep["cube"]["output"] == "scene-linear"
    corrected = apply_cube("oiiotool", sim, out / "correction.cube", tmp_path / "c.exr")
    got = _compared(corrected, charts["real"], read=ReadOptions(exposure=0.0))
    assert abs(got - rep["after"]["mean_delta_e"]) <= TOLERANCE


def test_the_terminal_says_the_default_convention(charts, tmp_path):
    sim = charts["sims"][("wb", "png8")]
    r = CliRunner().invoke(main, ["fit", str(sim), str(charts["real"]), "--out",
                                  str(tmp_path / "o"), "--sim-corners", CORNERS,
                                  "--real-corners", CORNERS, "--correction", "gains"])
    assert r.exit_code == 0, r.output
    line = next(x for x in r.output.splitlines() if x.startswith(".cube convention"))
    assert "input the SIM's pixels, sRGB-encoded" in line
    assert "output corrected sRGB-encoded (IEC 61966-2-1) pixels, the SIM's own encoding" in line
    assert "--cube-output linear" in line


def test_a_missing_tool_skips_and_names_it(monkeypatch):
    import tests.fixtures.cube_tools as tools

    monkeypatch.setattr(tools.shutil, "which", lambda name: None)
    for tool in ("ffmpeg", "oiiotool"):
        with pytest.raises(pytest.skip.Exception, match=f"{tool} is not on PATH"):
            tools.require(tool)
