"""The public Python API: names, lazy import, the pipelines' records and their JSON."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

import fidelity
from fidelity.pipeline.records import ChartReport
from fidelity.report.jsonform import chart_report_json


def test_every_public_name_resolves_and_is_documented():
    for name in fidelity.__all__[1:]:
        obj = getattr(fidelity, name)
        assert obj.__doc__ and len(obj.__doc__.strip()) > 20, name


def test_import_fidelity_is_light():
    code = ("import sys, fidelity; heavy = [m for m in ('numpy', 'scipy', 'matplotlib', "
            "'colour', 'onnxruntime', 'mitsuba', 'cv2') if m in sys.modules]; print(heavy)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_the_version_is_the_installed_distributions():
    """fidelity.core.version is the one place of the version; the build reads it from there."""
    from importlib.metadata import version

    assert fidelity.__version__ == version("camera-fidelity")
    code = ("import sys, fidelity.core.version as v; a = 'importlib.metadata' in sys.modules; "
            "n = v.installed_version('numpy'); print(a, 'importlib.metadata' in sys.modules, n)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "False", version("numpy")]


def test_installed_versions_equal_importlib_metadatas():
    """The provenance reads a distribution's version from its metadata header; importlib's
    parser of the whole file is the second method, over every installed distribution."""
    from importlib.metadata import distributions, version

    from fidelity.core.version import installed_version

    names = {d.metadata["Name"] for d in distributions()}
    assert len(names) > 20
    assert {n: installed_version(n) for n in names} == {n: version(n) for n in names}
    assert installed_version("no-such-distribution-here") is None


def test_installed_version_reads_odd_metadata_folders_as_importlib_does(tmp_path, monkeypatch):
    """Folder names with dots and capitals, an egg-info folder and an egg-info file, a
    dist-info without a version header, and a name installed twice along ``sys.path`` (the
    first wins): the same answers as ``importlib.metadata.version`` on the same path."""
    from importlib.metadata import PackageNotFoundError, version

    from fidelity.core import version as module

    first, second = tmp_path / "first", tmp_path / "second"
    for folder, text in [
        (first / "Zz_Dotted.Name-1.2.3.dist-info" / "METADATA",
         "Metadata-Version: 2.1\r\nName: zz-dotted.name\r\nVersion: 1.2.3\r\n\r\nVersion: 9"),
        (first / "zz_eggdir-0.5-py3.11.egg-info" / "PKG-INFO",
         "Metadata-Version: 1.1\nName: zz-eggdir\nVersion: 0.5\n"),
        (first / "zz_eggfile-2.0.egg-info", "Metadata-Version: 1.1\nName: zz_eggfile\nVersion: 2.0\n"),
        (first / "zz_noversion-1.0.dist-info" / "METADATA", "Metadata-Version: 2.1\nName: zz-noversion\n"),
        (first / "zz_twice-1.0.dist-info" / "METADATA", "Metadata-Version: 2.1\nName: zz-twice\nVersion: 1.0\n"),
        (second / "zz_twice-2.0.dist-info" / "METADATA", "Metadata-Version: 2.1\nName: zz-twice\nVersion: 2.0\n"),
    ]:
        folder.parent.mkdir(parents=True, exist_ok=True)
        folder.write_bytes(text.encode())
    monkeypatch.syspath_prepend(str(second))
    monkeypatch.syspath_prepend(str(first))

    def reference(name):
        try:
            return version(name)
        except PackageNotFoundError:
            return None

    names = ["zz-dotted.name", "ZZ_Dotted-Name", "zz-eggdir", "zz.eggfile", "zz-noversion",
             "zz-twice", "zz-absent"]
    got = {n: module.installed_version(n) for n in names}
    assert got == {n: reference(n) for n in names}
    assert got["zz-dotted.name"] == "1.2.3" and got["zz-twice"] == "1.0"
    assert got["zz-absent"] is None


def test_check_camera_in_three_lines_matches_the_closed_form():
    report = fidelity.check_camera("ideal")
    # the ideal camera is exact under D65 (README: < 0.01 ΔE00)
    assert report.mean_delta_e < 0.01 and report.verdict is not None and report.verdict.passed
    assert report.exit_code == 0
    direct = fidelity.render_chart("ideal").measurement
    np.testing.assert_array_equal(report.measurement.delta_e, direct.delta_e)
    assert report.prediction is not None
    assert report.prediction.dmap_points == fidelity.predict(report.mean_delta_e).dmap_points


def test_chart_report_json_round_trip_is_exact_and_schema_valid(tmp_path):
    pytest.importorskip("jsonschema")
    from fidelity.camera.render import render_chart

    report = fidelity.check_camera("nikon-5100")
    doc = json.loads(json.dumps(chart_report_json(report)))
    assert chart_report_json(ChartReport.from_json(doc)) == doc
    # an image report: the render's display PNG, found and measured
    import OpenImageIO as oiio

    img = (render_chart("nikon-5100").display_image * 65535 + 0.5).astype(np.uint16)
    path = tmp_path / "chart.png"
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(img.shape[1], img.shape[0], 3, "uint16"))
    out.write_image(img)
    out.close()
    audit = fidelity.audit_image(path, reference="scene",
                                 criterion=fidelity.Criterion("max-delta-e", 3.0))
    doc = json.loads(json.dumps(chart_report_json(audit)))
    back = ChartReport.from_json(doc)
    assert chart_report_json(back) == doc
    assert back.source.found is not None  # type: ignore[union-attr]
    # PNG quantisation only: the audit measures what the render measured (README)
    assert audit.mean_delta_e == pytest.approx(report.mean_delta_e, abs=0.02)


def test_from_json_refuses_a_document_that_is_not_a_report():
    pytest.importorskip("jsonschema")
    from fidelity.core.errors import InvalidValueError

    doc = chart_report_json(fidelity.check_camera("ideal"))
    doc["mean_delta_e"] = -1.0
    with pytest.raises(InvalidValueError, match="mean_delta_e"):
        ChartReport.from_json(doc)
