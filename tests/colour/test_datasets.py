"""The colour-science datasets shipped as data (fidelity.colour.datasets) are colour-science's,
and the default paths of check and audit no longer import colour-science or matplotlib."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fidelity.colour import datasets as ds


def _close(shipped, reference, where: str) -> None:
    if isinstance(reference, dict):
        assert shipped.keys() >= reference.keys() - {"source"}, where
        for k in reference.keys() - {"source"}:
            _close(shipped[k], reference[k], f"{where}.{k}")
        return
    a, b = np.asarray(shipped, np.float64), np.asarray(reference, np.float64)
    assert a.shape == b.shape, where
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12, err_msg=where)


def test_shipped_datasets_are_colour_sciences() -> None:
    import json

    shipped = json.loads(ds.data_path().read_text(encoding="utf-8"))
    _close(shipped, ds.colour_science_datasets(), "$")


def test_shipped_training_reflectances_are_colour_sciences() -> None:
    import gzip
    import json

    with gzip.open(ds.data_path().parent / ds.TRAINING_FILE, "rt", encoding="utf-8") as f:
        shipped = json.load(f)
    reference = ds.colour_science_training()
    assert list(shipped["sets"]) == list(reference["sets"])
    for label, items in reference["sets"].items():
        assert [i["name"] for i in shipped["sets"][label]] == [i["name"] for i in items]
        for a, b in zip(shipped["sets"][label], items, strict=True):
            for key in ("wavelengths", "values"):
                _close(a[key], b[key], f"$.{label}.{b['name']}.{key}")


def test_the_loaders_give_the_shipped_numbers() -> None:
    import colour

    wl, cmfs = ds.cmfs_1931()
    ref = colour.MSDS_CMFS[ds.CIE_1931]
    np.testing.assert_array_equal(wl, ref.wavelengths)
    np.testing.assert_allclose(cmfs, ref.values, rtol=1e-12)
    assert cmfs.shape == (wl.size, 3)
    for name in ds.ILLUMINANTS:
        wl, v = ds.illuminant(name)
        np.testing.assert_allclose(v, colour.SDS_ILLUMINANTS[name].values, rtol=1e-12)
    assert ds.illuminant("no such light") is None
    assert ds.camera_sensitivities("Nikon 5100 (NPL)")[1].shape[1] == 3
    np.testing.assert_allclose(ds.adaptation_matrix("Bradford"),
                               colour.CHROMATIC_ADAPTATION_TRANSFORMS["Bradford"], rtol=1e-12)
    primaries, white, to_xyz = ds.colourspace("ACEScg")
    np.testing.assert_allclose(to_xyz, colour.RGB_COLOURSPACES["ACEScg"].matrix_RGB_to_XYZ)
    np.testing.assert_allclose(primaries, colour.RGB_COLOURSPACES["ACEScg"].primaries)
    np.testing.assert_allclose(white, colour.RGB_COLOURSPACES["ACEScg"].whitepoint)


@pytest.mark.parametrize("argv", [["check", "--no-report", "-q"],
                                  ["audit", "{png}", "-q", "--json", "{json}"],
                                  # the HTML reports' figures are SVG written from the numbers
                                  ["check", "-q", "--out", "{out}"],
                                  ["audit", "{png}", "-q", "--html", "{html}"]])
def test_check_and_audit_import_neither_colour_science_nor_matplotlib(argv, tmp_path) -> None:
    """Nor scipy.optimize / scipy.interpolate (0.5-0.8 s of imports: the prediction's solvers
    are fidelity.prediction.scalar), nor urllib.request / ssl (``xml.sax.saxutils``: 15 ms);
    numpy.ma (15 ms; ``np.median``, ``np.percentile`` and ``np.unique`` import it on their
    first call) is allowed to both: a check measures the camera's noise and sharpness as an
    audit does, and the noise fit's medians load it."""
    from fidelity.camera.render import render_chart

    png = tmp_path / "chart.png"
    import OpenImageIO as oiio

    img = (render_chart("nikon-5100").display_image * 255 + 0.5).astype(np.uint8)
    out = oiio.ImageOutput.create(str(png))
    out.open(str(png), oiio.ImageSpec(img.shape[1], img.shape[0], 3, "uint8"))
    out.write_image(img)
    out.close()
    # a plain check loads none of the machinery of its other options (issue 59): the evidence
    # writers (--evidence), the suite runners (a suite file), the qualification run
    # (--context), nor the chart finder (the render knows where its chart is)
    not_check = (("fidelity.report.evidence", "fidelity.cli.suite", "fidelity.pipeline.suite",
                  "fidelity.pipeline.qualify", "fidelity.pipeline.context",
                  "fidelity.chart.find.cascade")
                 if argv[0] == "check" else ())
    args = [a.format(png=png, json=tmp_path / "a.json", out=tmp_path / "out",
                     html=tmp_path / "a.html") for a in argv]
    code = ("import sys\nfrom fidelity.cli import main\n"
            f"try:\n    main({args!r})\nexcept SystemExit as e:\n    code = e.code\n"
            "bad = sorted(m for m in sys.modules if m.split('.')[0] in ('colour', 'matplotlib')\n"
            "             or m.startswith(('scipy.optimize', 'scipy.interpolate'))\n"
            f"             or m in ('urllib.request', 'ssl') or m in {not_check!r})\n"
            "print('IMPORTED', bad)\nsys.exit(code)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       cwd=Path(__file__).resolve().parents[2], timeout=300)
    assert r.returncode in (0, 1), r.stderr
    assert "IMPORTED []" in r.stdout, r.stdout[-2000:]
    html = tmp_path / ("a.html" if "--html" in argv else "out/report.html")
    if "{out}" in argv or "{html}" in argv:
        assert html.read_text(encoding="utf-8").count("<svg ") >= 6


@pytest.mark.parametrize("name", ds.COLOURSPACES)
def test_rgb_to_srgb_matrices_equal_colour_sciences(name) -> None:
    import colour

    from fidelity.colour.colorimetry import matrix_rgb_to_linear_srgb

    srgb = colour.RGB_COLOURSPACES["sRGB"].copy()
    srgb.use_derived_matrix_RGB_to_XYZ = True
    srgb.use_derived_matrix_XYZ_to_RGB = True
    ref = (np.eye(3) if name == "sRGB"
           else colour.matrix_RGB_to_RGB(colour.RGB_COLOURSPACES[name], srgb, "Bradford"))
    np.testing.assert_allclose(matrix_rgb_to_linear_srgb(name), ref, rtol=0, atol=1e-12)
    # EXR chromaticities: the derived (normalised primary) matrix, adapted with CAT02 too
    primaries, white, _ = ds.colourspace(name)
    xy = [*np.ravel(primaries), *white]
    space = colour.RGB_Colourspace("c", primaries, white, use_derived_matrix_RGB_to_XYZ=True,
                                   use_derived_matrix_XYZ_to_RGB=True)
    if name != "sRGB" and np.all(primaries[:, 1] > 0):  # ACES2065-1's blue has y < 0
        np.testing.assert_allclose(matrix_rgb_to_linear_srgb(xy, "CAT02"),
                                   colour.matrix_RGB_to_RGB(space, srgb, "CAT02"),
                                   rtol=0, atol=1e-12)


@pytest.mark.parametrize("method", ["Cheung 2004", "Finlayson 2015"])
def test_the_ccm_fit_equals_colour_sciences(method) -> None:
    import colour

    from fidelity.camera.model import CCM_FIT_METHODS, fit_colour_correction

    rng = np.random.default_rng(2)
    rgb = rng.random((24, 3))
    target = rgb + (rng.random((24, 3)) - 0.5) * 0.5
    ref = colour.characterisation.matrix_colour_correction(rgb, target, method=method,
                                                           **CCM_FIT_METHODS[method])
    np.testing.assert_allclose(fit_colour_correction(rgb, target, method), ref, rtol=0,
                               atol=1e-12)
