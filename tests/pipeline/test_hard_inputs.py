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
