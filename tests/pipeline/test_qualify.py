"""``fidelity qualify``: the installed tool against independent references. Each check must
pass here and must fail when the computation it guards is wrong."""

from __future__ import annotations

import base64
import hashlib
import json
from importlib import metadata
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import fidelity.chart.find.cascade as find
import fidelity.colour.colorimetry as cm
from fidelity.cli import main
from fidelity.pipeline.qualify import (
    FAIL,
    NOT_RUN,
    PASS,
    QUALIFICATION_CHECKS,
    CheckNotRunError,
    installed_files,
    qualify,
    run_check,
    synthetic_photo,
)


@pytest.fixture(scope="module")
def result():  # type: ignore[no-untyped-def]
    return qualify()


def test_every_check_that_runs_here_passes_within_its_tolerance(result) -> None:  # type: ignore[no-untyped-def]
    assert [c.name for c in result.checks] == list(QUALIFICATION_CHECKS)
    for c in result.checks:
        if c.status == NOT_RUN:
            assert c.name in ("renderer", "coco-scoring", "ocio-input", "installation")
            assert c.detail and c.deviation is None
            continue
        assert c.status == PASS, c
        assert c.deviation is not None and 0 <= c.deviation <= c.tolerance
        assert c.cases > 0 and c.reference and c.quantity
    assert result.qualified
    by = {c.name: c for c in result.checks}
    assert by["ciede2000"].cases == 68
    # The editable checkout the suite runs from has no wheel RECORD to check against.
    assert by["installation"].status in (NOT_RUN, PASS)


def test_a_wrong_ciede2000_fails_its_check(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    true = cm.delta_e_2000
    monkeypatch.setattr(cm, "delta_e_2000", lambda a, b: true(a, b) * 1.0002)
    check = run_check("ciede2000")
    assert check.status == FAIL and check.deviation is not None and check.deviation > 1e-4


def test_a_wrong_srgb_matrix_fails_its_check(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    wrong = np.array(cm.MATRIX_LINEAR_SRGB_TO_XYZ, copy=True)
    wrong[0, 0] += 1e-4
    monkeypatch.setattr(cm, "MATRIX_LINEAR_SRGB_TO_XYZ", wrong)
    assert run_check("srgb-matrix").status == FAIL


def test_the_coco_scoring_check_fails_on_a_wrong_ap_and_needs_a_scorer(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    import dataclasses

    import fidelity.coco.scoring as scoring

    true = scoring.evaluate_detections
    monkeypatch.setattr(scoring, "evaluate_detections", lambda *a, **k: dataclasses.replace(
        true(*a, **k), map50=true(*a, **k).map50 * 0.999))
    check = run_check("coco-scoring")
    assert check.status == FAIL and check.deviation is not None and check.deviation > 1e-4
    monkeypatch.setattr(scoring, "scorer_available", lambda method: False)
    check = run_check("coco-scoring")
    assert check.status == NOT_RUN and "no COCO scorer" in check.detail


def test_the_finder_check_fails_with_centroids_as_patch_centres(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    # The bias this check found: contour centroids lean to the nearer side of an oblique chart.
    monkeypatch.setattr(find, "perspective_bias", lambda h, cells, side: np.zeros_like(cells))
    check = run_check("chart-finder")
    assert check.status == FAIL and check.deviation is not None and check.deviation > 2.0
    assert run_check("measurement").status == PASS  # windows well inside the patches


def test_a_check_whose_computation_raises_fails_and_names_the_error(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    from fidelity.core.errors import InputFileError

    def lost(*args, **kwargs):  # type: ignore[no-untyped-def]
        raise InputFileError("no chart found")

    monkeypatch.setattr(find, "find_chart", lost)
    check = run_check("chart-finder")
    assert check.status == FAIL and check.deviation is None
    assert check.detail.startswith("raised InputFileError: ")
    assert check.detail.endswith("scene-0.png: no chart found")


def test_a_check_that_raises_not_run_is_named_not_failed(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    import fidelity.camera.render as render
    from fidelity.camera.mitsuba import MitsubaUnavailableError

    true = render.render_chart

    def no_mitsuba(*args, **kwargs):  # type: ignore[no-untyped-def]
        if kwargs.get("renderer") == "mitsuba":
            raise MitsubaUnavailableError("not installed")
        return true(*args, **kwargs)

    monkeypatch.setattr(render, "render_chart", no_mitsuba)
    check = run_check("renderer")
    assert check.status == NOT_RUN and "not installed" in check.detail
    # a qualification in which nothing ran is no qualification
    out = CliRunner().invoke(main, ["qualify", "--checks", "renderer"])
    assert out.exit_code == 1 and "NOT qualified: 0 of 0" in out.output


def test_the_ocio_check_fails_on_a_wrong_conversion_and_needs_opencolorio(monkeypatch
                                                                           ) -> None:  # type: ignore[no-untyped-def]
    import sys

    import fidelity.chart.ocio as ocio

    pytest.importorskip("PyOpenColorIO", reason="pip install 'camera-fidelity[ocio]'")
    true = ocio.convert
    monkeypatch.setattr(ocio, "convert",
                        lambda *a, **k: (true(*a, **k)[0] * np.float32(1.0005), true(*a, **k)[1]))
    check = run_check("ocio-input")
    assert check.status == FAIL and check.deviation is not None and check.deviation > 4e-4
    monkeypatch.setattr(ocio, "convert", true)
    monkeypatch.setitem(sys.modules, "PyOpenColorIO", None)
    check = run_check("ocio-input")
    assert check.status == NOT_RUN and "ocio extra" in check.detail


def test_the_acescct_curve_of_the_check_is_the_specifications() -> None:
    """Against colour-science's ACEScct, a second implementation of S-2016-001."""
    colour = pytest.importorskip("colour", reason="colour-science (the test extra)")
    from fidelity.pipeline.qualify import acescct_encode

    lin = np.array([0.0, 1e-4, 0.001, 0.0078125, 0.0078126, 0.02, 0.18, 1.0, 16.0, 222.0])
    with np.errstate(divide="ignore"):  # colour-science takes log2(0) on the linear segment
        reference = colour.models.log_encoding_ACEScct(lin)
    np.testing.assert_allclose(acescct_encode(lin), reference, atol=1e-12)


def test_synthetic_photo_puts_the_patch_centres_where_it_says() -> None:
    photo, truth, painted = synthetic_photo(((330.0, 250.0), (900.0, 300.0), (880.0, 700.0),
                                             (300.0, 640.0)))
    assert photo.shape == (960, 1280, 3) and painted.shape == (24, 3)
    for centre, colour in zip(truth, painted[[0, 5, 23, 18]], strict=True):
        x, y = np.rint(centre).astype(int)
        np.testing.assert_allclose(photo[y, x], colour, atol=1e-5)


def _record_hash(data: bytes) -> str:
    return "sha256=" + base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(
        b"=").decode()


def _fake_install(root: Path, editable: bool = False, record: bool = True
                  ) -> metadata.Distribution:
    (root / "fidelity").mkdir(parents=True)
    files = {"fidelity/__init__.py": b"x = 1\n", "fidelity/data é.json": b"{}",
             "../../bin/fidelity": b"#!python\n"}
    for name, data in files.items():
        if not name.startswith(".."):
            (root / name).write_bytes(data)
    info = root / "camera_fidelity-0.1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: camera-fidelity\n"
                                   "Version: 0.1.0\n")
    if editable:
        (info / "direct_url.json").write_text(json.dumps(
            {"url": "file:///src", "dir_info": {"editable": True}}))
    if record:
        rows = [f"{name},{_record_hash(data)},{len(data)}" for name, data in files.items()]
        rows.append(f"{info.name}/RECORD,,")
        (info / "RECORD").write_text("\n".join(rows) + "\n", encoding="utf-8")
    return metadata.PathDistribution(info)


def test_installed_files_against_the_wheel_record(tmp_path) -> None:  # type: ignore[no-untyped-def]
    dist = _fake_install(tmp_path / "site")
    # the package's files are checked; a console script, written for the interpreter at hand
    # outside the package (here: not even there), is not
    assert installed_files(dist) == (2, [])
    (tmp_path / "site/fidelity/__init__.py").write_bytes(b"x = 2\n")
    (tmp_path / "site/fidelity/data é.json").unlink()
    n, bad = installed_files(dist)
    assert n == 2 and sorted(bad) == ["fidelity/__init__.py: changed",
                                      "fidelity/data é.json: missing"]


@pytest.mark.parametrize(("editable", "record", "why"),
                         [(True, True, "editable"), (False, False, "no RECORD")])
def test_installed_files_cannot_be_checked_without_a_wheel_record(tmp_path, editable, record,
                                                                  why) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(CheckNotRunError, match=why):
        installed_files(_fake_install(tmp_path / "site", editable=editable, record=record))


def test_cli_writes_the_record_and_exits_by_the_outcome(tmp_path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    out = CliRunner().invoke(main, ["qualify", "--checks", "ciede2000,srgb-matrix,ciede2000",
                                    "--json", str(tmp_path / "q é.json")])
    assert out.exit_code == 0, out.output
    doc = json.loads((tmp_path / "q é.json").read_text(encoding="utf-8"))
    assert doc["kind"] == "fidelity qualification" and doc["qualified"] is True
    assert [c["name"] for c in doc["checks"]] == ["ciede2000", "srgb-matrix"]
    assert doc["tool"]["code_sha256"] and doc["environment"]["python"]
    assert doc["checks"][0]["deviation"] <= doc["checks"][0]["tolerance"]
    true = cm.delta_e_2000
    monkeypatch.setattr(cm, "delta_e_2000", lambda a, b: true(a, b) + 1e-3)
    out = CliRunner().invoke(main, ["qualify", "--checks", "ciede2000"])
    assert out.exit_code == 1 and out.output.splitlines()[1].startswith("fail")


@pytest.mark.parametrize("arg", ["nope", "ciede2000,nope", ","])
def test_cli_unknown_check_is_one_line_exit_2(arg: str) -> None:
    out = CliRunner().invoke(main, ["qualify", "--checks", arg])
    assert out.exit_code == 2
    assert out.output.count("\n") == 1 and out.output.startswith("fidelity: error: --checks")
