"""Pixels in an OpenColorIO colourspace (``--ocio-colourspace``): the chart encoded by
colour-science (an independent implementation of ACEScct, ARRI LogC3 and Display P3) and
converted back by OpenColorIO measures as the same chart in linear or display sRGB."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fidelity.chart.image import write_exr, write_png
from fidelity.chart.read import ReadOptions
from fidelity.cli import main
from fidelity.core.errors import FidelityError
from fidelity.measure.pixels import measure_image

pytest.importorskip("PyOpenColorIO", reason="OpenColorIO converts the pixels "
                    "(pip install 'camera-fidelity[ocio]')")
colour = pytest.importorskip("colour", reason="colour-science encodes the test images")


@pytest.fixture(scope="module")
def charts(tmp_path_factory) -> dict[str, Path]:
    """The nikon-5100 render's chart as linear sRGB (EXR), display sRGB (PNG) and in the
    encodings under test, each written by colour-science from the same values."""
    from fidelity.camera.render import render_chart

    folder = tmp_path_factory.mktemp("ocio")
    display = np.clip(np.asarray(render_chart("nikon-5100").display_image, np.float64), 0, 1)
    linear = np.maximum(colour.cctf_decoding(display, function="sRGB"), 1e-6)
    srgb, cg = colour.RGB_COLOURSPACES["sRGB"], colour.RGB_COLOURSPACES["ACEScg"]
    awg3 = colour.RGB_COLOURSPACES["ARRI Wide Gamut 3"]
    p3 = colour.RGB_COLOURSPACES["Display P3"]
    acescct = colour.models.log_encoding_ACEScct(
        colour.RGB_to_RGB(linear, srgb, cg, chromatic_adaptation_transform="Bradford"))
    # the ACES configs go through ACES2065-1: Bradford between D65 and the ACES white for
    # Rec.709 and ACEScg, CAT02 in ARRI's own Wide Gamut 3 matrix (its ACES input transform);
    # the direct D65 -> D65 matrix would differ from that round trip by up to 0.14 ΔE00
    ap0 = colour.RGB_COLOURSPACES["ACES2065-1"]
    logc3 = colour.models.log_encoding_ARRILogC3(colour.RGB_to_RGB(
        colour.RGB_to_RGB(linear, srgb, ap0, chromatic_adaptation_transform="Bradford"), ap0,
        awg3, chromatic_adaptation_transform="CAT02"))
    p3_display = colour.RGB_to_RGB(display, srgb, p3, apply_cctf_decoding=True,
                                   apply_cctf_encoding=True)
    return {
        "linear": write_exr(folder / "linear.exr", linear.astype(np.float32)),
        "display": write_png(folder / "display.png", display, 16),
        "acescct": write_exr(folder / "acescct.exr", acescct.astype(np.float32)),
        "logc3": write_exr(folder / "logc3 é.exr", logc3.astype(np.float32)),
        "p3": write_png(folder / "p3.png", np.clip(p3_display, 0, 1), 16),
        "dir": folder,
    }


@pytest.mark.parametrize("key, colourspace, config, same_as, encoding", [
    ("acescct", "ACEScct", None, "linear", "linear"),
    ("logc3", "ARRI LogC3 (EI800)", "ocio://studio-config-latest", "linear", "linear"),
    ("p3", "Display P3 - Display", None, "display", "srgb"),
])
def test_an_encoded_chart_measures_as_the_chart_it_encodes(charts, key, colourspace, config,
                                                            same_as, encoding):
    direct = measure_image(charts[same_as])
    got = measure_image(charts[key], direct.location.corners, read=ReadOptions(
        ocio_colourspace=colourspace, ocio_config=config))
    assert got.image is not None and got.image.ocio is not None
    assert got.image.ocio.colourspace == colourspace and got.image.ocio.encoding == encoding
    assert got.image.encoding == encoding and got.colourspace == "sRGB"
    assert got.image.ocio.config == (config or "ocio://default")
    # OpenColorIO's configs and colour-science round primaries and white points differently
    # (matrices apart by 2e-4): a few thousandths of a ΔE00
    assert got.mean_delta_e == pytest.approx(direct.mean_delta_e, abs=0.01)
    assert np.max(np.abs(got.measurement.delta_e - direct.measurement.delta_e)) < 0.03
    assert direct.mean_delta_e > 0.5  # a chart with an error to measure, not the reference


def test_the_config_comes_from_ocio_when_not_given(charts, monkeypatch):
    monkeypatch.setenv("OCIO", "ocio://studio-config-latest")
    got = measure_image(charts["logc3"], read=ReadOptions(ocio_colourspace="ARRI LogC3 (EI800)"))
    assert got.image is not None and got.image.ocio is not None
    assert got.image.ocio.config == "ocio://studio-config-latest"
    assert got.image.ocio.config_name.startswith("studio-config")


def test_cli_audit_json_and_evidence_name_the_conversion_and_the_config_file(charts, tmp_path):
    import PyOpenColorIO as ocio

    config = tmp_path / "studio config.ocio"
    ocio.Config.CreateFromFile("ocio://studio-config-latest").serialize(str(config))
    r = CliRunner().invoke(main, [
        "audit", str(charts["logc3"]), "--ocio-colourspace", "ARRI LogC3 (EI800)",
        "--ocio-config", str(config), "--json", str(tmp_path / "a.json"),
        "--evidence", str(tmp_path / "e.json")])
    assert r.exit_code == 0, r.output
    assert "OpenColorIO: ARRI LogC3 (EI800) of studio-config" in r.output
    how = json.loads((tmp_path / "a.json").read_text())["source"]["ocio"]
    assert how["colourspace"] == "ARRI LogC3 (EI800)" and how["config"] == str(config)
    assert how["target"] == "Linear Rec.709 (sRGB)" and how["encoding"] == "linear"
    record = json.loads((tmp_path / "e.json").read_text())
    (cfg,) = [i for i in record["subjects"][0]["inputs"] if i["role"] == "OpenColorIO config"]
    import hashlib

    assert cfg["sha256"] == hashlib.sha256(config.read_bytes()).hexdigest()
    assert CliRunner().invoke(main, ["verify", str(tmp_path / "e.json")]).exit_code == 0
    config.write_text(config.read_text() + "\n# edited\n")
    changed = CliRunner().invoke(main, ["verify", str(tmp_path / "e.json")])
    assert changed.exit_code == 1 and "OpenColorIO config" in changed.output


@pytest.mark.parametrize("args, message", [
    (["--ocio-colourspace", "ACEScxx"], "ACEScxx"),
    (["--ocio-colourspace", "ACEScct", "--ocio-config", "missing.ocio"],
     "--ocio-config missing.ocio: no such config file"),
    (["--ocio-colourspace", "ACEScct", "--encoding", "linear"], "leave out --encoding"),
    (["--ocio-colourspace", "ACEScct", "--colourspace", "ACEScg"], "leave out --colourspace"),
    (["--ocio-config", "ocio://default"], "--ocio-colourspace NAME"),
    (["--ocio-colourspace", "Raw"], "a data colourspace"),
])
def test_cli_bad_ocio_options_are_one_line_exit_2(charts, args, message):
    r = CliRunner().invoke(main, ["audit", str(charts["acescct"]), *args])
    assert r.exit_code == 2, r.output
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("fidelity: error: ")
    assert message in r.stderr


def test_fit_refuses_a_conversion_its_cube_could_not_undo(charts, tmp_path):
    r = CliRunner().invoke(main, ["fit", str(charts["acescct"]), str(charts["linear"]),
                                  "--ocio-colourspace", "ACEScct", "--out", str(tmp_path / "o")])
    assert r.exit_code == 2 and "fit writes its correction for the simulator's own" in r.stderr


def test_without_opencolorio_the_error_names_the_extra(charts, monkeypatch):
    monkeypatch.setitem(sys.modules, "PyOpenColorIO", None)
    with pytest.raises(FidelityError, match=r"camera-fidelity\[ocio\]"):
        measure_image(charts["acescct"], read=ReadOptions(ocio_colourspace="ACEScct"))


@pytest.mark.parametrize("where", ["ocio://studio-config-latest", "cfg/studio.ocio"])
def test_settings_name_the_colourspace_and_the_config(charts, tmp_path, monkeypatch, where):
    """A URI stays a URI; a config file is found relative to the settings file."""
    import PyOpenColorIO as ocio

    (tmp_path / "cfg").mkdir()
    ocio.Config.CreateFromFile("ocio://studio-config-latest").serialize(
        str(tmp_path / "cfg" / "studio.ocio"))
    (tmp_path / "fidelity.toml").write_text(
        f'ocio_colourspace = "ARRI LogC3 (EI800)"\nocio_config = "{where}"\n', encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    r = CliRunner().invoke(main, ["audit", str(charts["logc3"]), "--json", "a.json"])
    assert r.exit_code == 0, r.output
    how = json.loads((tmp_path / "a.json").read_text())["source"]["ocio"]
    assert how["config"] == (where if "://" in where else str(tmp_path / where))


def test_a_report_reads_the_image_again_converted_as_the_audit_read_it(charts):
    """The HTML report's picture of the sampling windows shows the converted pixels (the
    image read again with the same conversion), not the file's encoded values."""
    from fidelity.chart.read import read_again

    got = measure_image(charts["acescct"], read=ReadOptions(ocio_colourspace="ACEScct"))
    assert got.image is not None
    again = read_again(got.image)
    linear = read_again(measure_image(charts["linear"]).image)  # type: ignore[arg-type]
    assert again.ocio == got.image.ocio and again.encoding == "linear"
    assert np.allclose(again.pixels, linear.pixels, atol=2e-3)


def test_convert_copies_unless_told_and_passes_nan_through() -> None:
    from fidelity.chart.ocio import convert

    px = np.full((2, 3, 3), 0.4, np.float32)
    px[0, 0] = np.nan
    out, _ = convert(px, "ACEScct")
    assert out is not px and np.all(px[1] == np.float32(0.4))  # the input is left as it was
    assert np.isnan(out[0, 0]).all() and np.isfinite(out[1]).all()
    same, _ = convert(px, "ACEScct", copy=False)
    assert same is px and np.array_equal(px[1], out[1])
    ints = np.full((2, 2, 3), 0.5)  # float64: a new float32 array either way
    assert convert(ints, "ACEScct", copy=False)[0].dtype == np.float32
    frozen = np.full((2, 2, 3), 0.4, np.float32)
    frozen.flags.writeable = False  # e.g. np.frombuffer of bytes: OpenColorIO writes regardless
    assert convert(frozen, "ACEScct", copy=False)[0] is not frozen


def test_compare_reads_each_image_in_its_own_colourspace(charts, tmp_path):
    """A render in ACEScct against a photo in display sRGB: --sim-ocio-colourspace converts
    the render alone; the same chart, so the sim-to-real ΔE00 is about 0 (without it, the
    ACEScct values read as linear light are far off)."""
    def compare(*extra: str) -> dict:  # type: ignore[type-arg]
        out = tmp_path / f"c{len(extra)}.json"
        r = CliRunner().invoke(main, ["compare", str(charts["acescct"]), str(charts["display"]),
                                      *extra, "--json", str(out)])
        assert r.exit_code == 0, r.output
        return json.loads(out.read_text())

    right = compare("--sim-ocio-colourspace", "ACEScct")
    # the shared --encoding describes the other image (the photo) and is not refused
    same = compare("--sim-ocio-colourspace", "ACEScct", "--encoding", "srgb")
    wrong = compare()
    de = [d["sim_to_real"]["mean_delta_e"] for d in (right, same, wrong)]
    assert de[0] < 0.05 and de[1] == de[0] and de[2] > 5, de


def test_fit_takes_reals_own_colourspace_and_refuses_sims(charts, tmp_path):
    r = CliRunner().invoke(main, ["fit", str(charts["linear"]), str(charts["p3"]),
                                  "--real-ocio-colourspace", "Display P3 - Display",
                                  "--out", str(tmp_path / "ok")])
    assert r.exit_code == 0, r.output
    report = json.loads((tmp_path / "ok" / "report.json").read_text())
    assert report["before"]["mean_delta_e"] < 0.05  # the same chart
    r = CliRunner().invoke(main, ["fit", str(charts["acescct"]), str(charts["linear"]),
                                  "--sim-ocio-colourspace", "ACEScct",
                                  "--out", str(tmp_path / "no")])
    assert r.exit_code == 2 and "--sim-ocio-colourspace ACEScct: fit writes its correction" \
        in r.stderr
