"""Hard numeric cases and odd file names give an answer or one error line (exit 2), never an
internal error (issue 30, requirement 5)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import OpenEXR
import pytest
from click.testing import CliRunner

from fidelity.camera.render import render_chart
from fidelity.cli import main


def _exr(path: Path, linear: np.ndarray, header: dict | None = None) -> Path:
    data = {c: np.ascontiguousarray(linear[..., i]).astype(np.float32)
            for i, c in enumerate("RGB")}
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, **(header or {})}, data).write(
        str(path))
    return path


@pytest.fixture(scope="module")
def render():
    return render_chart("nikon-5100")


def _run(args: list[str]):
    return CliRunner().invoke(main, args, catch_exceptions=False)


def test_denormal_pixels_are_found_and_refused_with_the_exposure_they_need(render, tmp_path):
    """Values about 1e-40 (float32 denormals): the chart is still found (1/peak overflows
    single precision), and the exposure needed (+133 EV) is named as beyond the limit."""
    tiny = _exr(tmp_path / "tiny.exr", np.asarray(render.linear_image, np.float32) * 1e-40)
    r = _run(["audit", str(tiny), "-q"])
    assert r.exit_code == 2
    line = r.output.strip().splitlines()[-1]
    assert line.startswith(f"fidelity: error: {tiny}: ") and "EV" in line
    assert "+133 EV" in line  # log2(1e40 * 0.9 / ~0.18) rounds to 133: the number, computed
    # the same chart a factor 2**-100 down is measured, and equals the plain one
    small = _exr(tmp_path / "small.exr", np.asarray(render.linear_image, np.float32) * 2.0**-100)
    plain = _exr(tmp_path / "plain.exr", np.asarray(render.linear_image, np.float32))
    for path in (small, plain):
        assert _run(["audit", str(path), "--json", str(path.with_suffix(".json")), "-q"]
                    ).exit_code == 0
    a, b = (json.loads(p.with_suffix(".json").read_text()) for p in (small, plain))
    assert a["mean_delta_e"] == pytest.approx(b["mean_delta_e"], abs=1e-3)
    assert a["exposure_ev"] == pytest.approx(b["exposure_ev"] + 100, abs=1e-6)


def test_degenerate_exr_chromaticities_are_an_input_error(render, tmp_path):
    bad = _exr(tmp_path / "degenerate.exr", np.asarray(render.linear_image, np.float32),
               {"chromaticities": (0.3, 0.3, 0.3, 0.3, 0.3, 0.3, 0.3127, 0.329)})
    r = _run(["audit", str(bad), "-q"])
    assert r.exit_code == 2
    line = r.output.strip().splitlines()[-1]
    assert line.startswith(f"fidelity: error: {bad}: chromaticities ")


def test_collinear_primaries_are_refused_by_the_matrix_itself():
    from fidelity.colour.colorimetry import matrix_rgb_to_linear_srgb
    from fidelity.core.errors import InvalidValueError

    with pytest.raises(InvalidValueError, match="chromaticities"):
        matrix_rgb_to_linear_srgb([0.1, 0.1, 0.2, 0.2, 0.3, 0.3, 0.3127, 0.329])
    # nearly degenerate but a triangle: still a matrix, finite
    m = matrix_rgb_to_linear_srgb([0.64, 0.33, 0.30, 0.60, 0.15, 0.0601, 0.3127, 0.3290])
    assert np.all(np.isfinite(m))


def test_names_that_are_not_utf8_are_read_and_written(render, tmp_path):
    """An image, a report and an output folder whose names are not valid UTF-8 (Latin-1 é):
    read through a plain-named link, written as named; the audit equals a plain name's."""
    from fidelity.chart.image import write_png

    folder = os.fsdecode(os.path.join(os.fsencode(tmp_path), b"caf\xe9"))
    os.mkdir(folder)
    odd = os.path.join(folder, os.fsdecode(b"chart-\xe9.png"))
    plain = tmp_path / "chart.png"
    write_png(odd, render.display_image, 16)
    write_png(plain, render.display_image, 16)
    report = os.path.join(folder, os.fsdecode(b"r\xe9.json"))
    html = os.path.join(folder, os.fsdecode(b"r\xe9.html"))
    assert _run(["audit", odd, "--json", report, "--html", html, "-q"]).exit_code == 0
    assert _run(["audit", str(plain), "--json", str(tmp_path / "p.json"), "-q"]).exit_code == 0
    a = json.loads(Path(report).read_text(encoding="utf-8"))
    b = json.loads((tmp_path / "p.json").read_text())
    assert a["mean_delta_e"] == b["mean_delta_e"] and a["source"]["path"] == odd
    assert Path(html).stat().st_size > 0
    out = os.path.join(folder, os.fsdecode(b"render-\xff"))
    assert _run(["render", "--out", out, "-q"]).exit_code == 0
    assert sorted(os.listdir(out)) == ["developed.png", "raw_camera.exr"]
    r = _run(["gate", os.path.join(out, "developed.png"), "--max-delta-e", "3", "-q",
              "--junit", os.path.join(folder, os.fsdecode(b"j\xe9.xml"))])
    assert r.exit_code == 0


def test_a_camera_that_renders_every_patch_black_is_judged(tmp_path):
    camera = tmp_path / "black.toml"
    camera.write_text('name = "black"\n[sensitivities]\nsource = "ideal"\n'
                      '[ccm]\nmethod = "matrix"\nmatrix = [[0,0,0],[0,0,0],[0,0,0]]\n')
    r = _run(["check", "--camera", str(camera), "--out", str(tmp_path / "o"), "-q"])
    assert r.exit_code == 1
    doc = json.loads((tmp_path / "o" / "report.json").read_text())  # strict JSON: no NaN
    assert doc["verdict"]["reason"] == "over-limit" and doc["mean_delta_e"] > 40
    assert all(np.isfinite(p["delta_e"]) for p in doc["patches"])


def test_scene_linear_exr_highlights_above_one_are_measured_as_the_unscaled_chart(tmp_path):
    """A blurred, noisy chart (sigma 1 px, Poisson-Gaussian noise; tests/measure/chartimage.py)
    as a float EXR and the same x4 (white about 4: scene-linear highlights above 1): the audit
    measures both, refusing neither as clipped (a float image has no encoding's maximum), and
    the sharpness (each channel's MTF50, its u and SNR) and the SNR at the grey are the same;
    the photon transfer's read noise and gain in linear units are 4 x, in electrons the same.
    x4 is exact in binary floating point, so the numbers agree to rounding."""
    from tests.measure.chartimage import render as chart  # noqa: PLC0415 (this test only)

    img, _h = chart(angle_deg=5.0, sigma=1.0, pitch=70.0, size=(320, 460), read_noise=0.002,
                    gain=0.0005, seed=3)
    out = {}
    for k in (1.0, 4.0):
        path = _exr(tmp_path / f"x{k:g}.exr", img * k)
        assert _run(["audit", str(path), "--json", str(path.with_suffix(".json")), "-q"]
                    ).exit_code == 0
        out[k] = json.loads(path.with_suffix(".json").read_text())
    one, four = out[1.0], out[4.0]
    assert float(np.max(img * 4.0)) > 3.9
    for a, b in zip(one["sharpness"]["edges"], four["sharpness"]["edges"], strict=True):
        assert a["refusal"] is None and b["refusal"] is None and b["method"] == "e-SFR"
        for ca, cb in zip(a["channels"], b["channels"], strict=True):
            assert ca["refusal"] is None and cb["refusal"] is None, cb
            for key in ("mtf50", "u_mtf50", "snr"):
                assert cb[key] == pytest.approx(ca[key], rel=1e-6), (ca["channel"], key)
    assert four["noise"]["grey_snr_db"] == pytest.approx(one["noise"]["grey_snr_db"], abs=1e-6)
    ta, tb = one["noise"]["photon_transfer"], four["noise"]["photon_transfer"]
    assert tb["saturation"] is None and four["noise"]["refusal"] is None
    assert tb["read_noise"] == pytest.approx(4.0 * ta["read_noise"], rel=1e-6)
    assert tb["gain"] == pytest.approx(4.0 * ta["gain"], rel=1e-6)
    assert tb["read_noise_electrons"] == pytest.approx(ta["read_noise_electrons"], rel=1e-6)
