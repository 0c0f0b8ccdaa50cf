"""The validity domain's validated cameras (issue 32): the illuminants and the kinds of
processing stages the prediction was validated on, shipped from the validation report, and a
camera check's answer inside or outside them."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import pytest
from click.testing import CliRunner

import fidelity
from fidelity.cli import main
from fidelity.coco.validate.colour import ValidationResults, validated_cameras
from fidelity.coco.validate.properties import PropertyResults, validated_properties
from fidelity.coco.validate.suite import load_suite
from fidelity.prediction.interval import (
    STAGES,
    ValidatedCameras,
    ValidatedDegradation,
    ValidatedProperties,
    degradation_check,
    joined_degradation,
    load_validated_cameras,
    shipped_domain,
    validated_degradation,
)

REPO = Path(__file__).resolve().parents[2]
SHIPPED = REPO / "fidelity" / "data" / "validation-domain.json"
PROPERTIES_DOMAIN = REPO / "reports" / "validation" / "properties-domain.json"


def without_source(doc: dict) -> dict:
    return {k: v for k, v in doc.items() if k != "source"}


def test_shipped_validated_cameras_are_the_validation_reports():
    """The shipped file equals the report's domain.json, and both what this code derives from
    the committed validation.json and the camera files (the shipped data from the shipped
    code); checked against the files read directly too."""
    report = json.loads((REPO / "reports" / "validation" / "validation.json").read_text())
    derived = validated_cameras(ValidationResults.from_json(report),
                                load_suite(REPO / "cameras")).to_json()
    shipped = json.loads(SHIPPED.read_text(encoding="utf-8"))
    beside = json.loads((REPO / "reports" / "validation" / "domain.json").read_text())
    colour = {k: v for k, v in without_source(shipped).items() if k != "properties"}
    assert colour == derived == without_source(beside)
    properties = json.loads(PROPERTIES_DOMAIN.read_text(encoding="utf-8"))
    assert shipped == shipped_domain(beside, properties)
    # independently: suite.toml's illuminants, the summary's counts, the models run
    suite = tomllib.loads((REPO / "cameras" / "suite.toml").read_text(encoding="utf-8"))
    names = set(report["cameras"])
    lights = {suite["illuminant"].get(n, suite["default_illuminant"]) for n in names}
    assert shipped["illuminants"] == sorted(lights)
    assert shipped["cameras"] == len(names) == 30
    assert (shipped["cells"], shipped["within"], shipped["within_2se"]) == tuple(
        report["summary"]["all"][k] for k in ("cells", "within", "within_2se"))
    assert sorted(shipped["models"]) == sorted(report["models"])
    bits = set()
    for n in names:
        camera = tomllib.loads((REPO / "cameras" / f"{n}.toml").read_text(encoding="utf-8"))
        bits.add(str(camera.get("quantisation", {}).get("bits", "float")))
    assert set(shipped["stages"]["bit depth"]) == bits
    assert load_validated_cameras() == ValidatedCameras.from_json(shipped)


VALIDATED = ValidatedCameras(
    cameras=3, illuminants=("A", "D65"),
    stages={"exposure": ("auto",), "white balance": ("grey-world", "white-patch"),
            "colour correction": ("fit",), "tone curve": ("gamma", "srgb"),
            "bit depth": ("8", "12")},
    sensitivities=("Nikon",), models=("yolox_nano",), cells=3, within=2, within_2se=3)


def kinds(**changes: str) -> dict[str, str]:
    base = {"exposure": "auto", "white balance": "white-patch", "colour correction": "fit",
            "tone curve": "srgb", "bit depth": "12"}
    return {**base, **{k.replace("_", " "): v for k, v in changes.items()}}


def test_a_camera_like_those_validated_is_inside():
    light, kind = VALIDATED.camera_checks(kinds(), "D65")
    assert light.inside and kind.inside
    assert "2 of 3 (camera, detector) cells within the measured bound" in kind.detail
    assert set(STAGES) == set(kinds())


@pytest.mark.parametrize(("changes", "illuminant", "outside"), [
    ({}, "D50", "validated illuminant"),
    ({"bit_depth": "10"}, "A", None),          # within the validated 8..12
    ({"bit_depth": "16"}, "A", "bit depth 16 (validated: 8, 12)"),
    ({"bit_depth": "float"}, "A", "bit depth float (validated: 8, 12)"),
    ({"tone_curve": "linear"}, "A", "tone curve linear (validated: gamma, srgb)"),
    ({"white_balance": "none"}, "A", "white balance none"),
])
def test_what_lies_outside_is_named(changes, illuminant, outside):
    light, kind = VALIDATED.camera_checks(kinds(**changes), illuminant)
    if outside is None:
        assert light.inside and kind.inside
    elif outside == "validated illuminant":
        assert not light.inside and kind.inside
        assert light.detail.startswith("illuminant D50: not among those the validation "
                                       "rendered (A, D65)")
    else:
        assert light.inside and not kind.inside and outside in kind.detail


def test_check_states_its_camera_against_the_validated_ones(tmp_path):
    report = fidelity.check_camera("nikon-5100")
    checks = {c.name: c for c in report.validity.checks}
    assert checks["validated illuminant"].inside and checks["validated camera kind"].inside
    # D50 is no illuminant of the validation: the answer says so, on the terminal too
    r = CliRunner().invoke(main, ["--no-config", "check", "--illuminant", "D50",
                                  "--no-report"])
    assert r.exit_code == 0, r.output
    assert "outside the validity domain: illuminant D50: not among those the validation " \
        "rendered" in r.output
    d50 = fidelity.check_camera("nikon-5100", illuminant="D50").validity
    names = {c.name: c.inside for c in d50.checks}
    assert names["validated illuminant"] is False and not d50.inside
    # a float (linear, unquantised) camera: no validated camera had such an output
    linear = tmp_path / "linear.toml"
    text = (REPO / "fidelity" / "data" / "cameras" / "nikon-5100.toml").read_text()
    linear.write_text(text.replace('curve = "srgb"', 'curve = "linear"')
                      .replace("bits = 12", "# no quantisation"), encoding="utf-8")
    kind = {c.name: c for c in fidelity.check_camera(str(linear)).validity.checks}[
        "validated camera kind"]
    assert not kind.inside
    assert "tone curve linear" in kind.detail and "bit depth float" in kind.detail


def test_an_image_audit_states_no_camera_kind(tmp_path):
    """An image's camera and light are not known to the tool: no such check is claimed."""
    r = CliRunner().invoke(main, ["--no-config", "render", "--camera", "nikon-5100", "--out",
                                  str(tmp_path / "r"), "-q"])
    assert r.exit_code == 0, r.output
    report = fidelity.audit_image(tmp_path / "r" / "developed.png")
    names = {c.name for c in report.validity.checks}
    assert not names & {"validated illuminant", "validated camera kind"}


def test_noise_optics_and_vignetting_are_in_the_domain_as_the_validation_spans_them(tmp_path):
    """The shipped domain states the colour validation's cameras' noise, optics and
    vignetting (none of the 30 had any), read from the camera files independently, and the
    sharpness and noise validation's (below); a camera whose noise lies outside both (a full
    well of 500 e-, under the 625 e- of the lowest validated) is outside, on the terminal (one
    line, value against range) and in the HTML (an amber banner, not a plain green PASS)."""
    shipped = json.loads(SHIPPED.read_text(encoding="utf-8"))
    suite = tomllib.loads((REPO / "cameras" / "suite.toml").read_text(encoding="utf-8"))
    files = [tomllib.loads((REPO / "cameras" / f"{n}.toml").read_text(encoding="utf-8"))
             for n in json.loads((REPO / "reports" / "validation" / "validation.json")
                                 .read_text())["cameras"]]
    assert suite and len(files) == 30
    for section, name in (("noise", "noise"), ("optics", "optics"),
                          ("vignetting", "vignetting")):
        had = [f for f in files if f.get(section, {}).get(
            {"noise": "full_well", "optics": "kind", "vignetting": "diagonal_fov_deg"}[section],
            "none") not in (None, "none")]
        assert had == [] and shipped["degradations"][name] == {"kinds": ["none"], "ranges": {}}
    noisy = tmp_path / "noisy.toml"
    text = (REPO / "cameras" / "nikon5100-cheung-d65.toml").read_text(encoding="utf-8")
    noisy.write_text(text + "\n[noise]\nfull_well = 500.0\nread_noise = 3.0\n",
                     encoding="utf-8")
    checks = {c.name: c for c in fidelity.check_camera(str(noisy)).validity.checks}
    assert not checks["validated noise"].inside
    assert checks["validated optics"].inside and checks["validated vignetting"].inside
    plain = {c.name: c for c in fidelity.check_camera(
        str(REPO / "cameras" / "nikon5100-cheung-d65.toml")).validity.checks}
    assert plain["validated noise"].inside
    r = CliRunner().invoke(main, ["--no-config", "check", "--camera", str(noisy), "--html",
                                  str(tmp_path / "r.html"), "--json", str(tmp_path / "r.json")])
    outside = [ln for ln in r.output.splitlines() if "outside the validity domain" in ln]
    assert len(outside) == 1, r.output
    assert "full_well 500 e-" in outside[0] and "read_noise 3 e- rms" in outside[0]
    assert ("the validated cameras' noise: none, shot+read (full_well 625 to 30000 e-, "
            "read_noise 2 to 10 e- rms); the sharpness and noise validation: 39 cameras, 74 of "
            "78 (camera, detector) cells within the combination rule's loss, before the validated margin") in outside[0]
    page = (tmp_path / "r.html").read_text(encoding="utf-8")
    banner = page.split('class="headline tone-', 1)[1]
    verdict = json.loads((tmp_path / "r.json").read_text())["verdict"]["passed"]
    assert banner.startswith("outside" if verdict else "fail")
    if verdict:
        assert "PASS — outside the validity domain" in banner.split("</div>", 1)[0]


@pytest.mark.parametrize(("kind", "params", "validated", "inside"), [
    ("none", {}, ValidatedDegradation(("none",)), True),
    ("shot+read", {"full_well": 500.0, "read_noise": 3.0}, ValidatedDegradation(("none",)),
     False),
    ("shot+read", {"full_well": 500.0, "read_noise": 3.0},
     validated_degradation([("shot+read", {"full_well": 1000.0, "read_noise": 2.0}),
                            ("shot+read", {"full_well": 40000.0, "read_noise": 5.0})]), False),
    ("shot+read", {"full_well": 2000.0, "read_noise": 3.0},
     validated_degradation([("shot+read", {"full_well": 1000.0, "read_noise": 2.0}),
                            ("shot+read", {"full_well": 40000.0, "read_noise": 5.0})]), True),
    ("gaussian", {"sigma_px": 1.0},
     validated_degradation([("none", {}), ("gaussian", {"sigma_px": 0.5})]), False),
    ("none", {}, validated_degradation([("gaussian", {"sigma_px": 0.5})]), False),
])
def test_a_degradation_is_inside_within_the_validated_range(kind, params, validated, inside):
    check = degradation_check("noise", kind, params, validated)
    assert check.inside is inside
    if kind != "none":
        assert all(f"{k} {v:g}" in check.detail for k, v in params.items())
    assert ValidatedDegradation.from_json(validated.to_json()) == validated


def test_the_property_validations_cameras_are_its_reports():
    """The domain's ``properties`` is what this code derives from the committed
    properties.json and the camera files of cameras/properties, and the camera files read
    directly give the same ranges: full well 625 (the ISO 32 low-light sensor's, 20000 e- / 32)
    to 30000 e-, read noise 2-10 e-, Gaussian sigma 0.5-3 px, defocus radius 1.5-3 px."""
    report = json.loads((REPO / "reports" / "validation" / "properties.json").read_text())
    derived = validated_properties(PropertyResults.from_json(report),
                                   load_suite(REPO / "cameras" / "properties")).to_json()
    beside = json.loads(PROPERTIES_DOMAIN.read_text(encoding="utf-8"))
    assert without_source(beside) == derived
    a = report["summary"]["dmap_points"]["all"]
    assert (derived["cameras"], derived["cells"], derived["within"], derived["within_2se"]) == (
        len(report["cameras"]), a["cells"], a["within"], a["within_2se"])
    wells, reads, sigmas, radii = [], [], [], []
    for name in report["cameras"]:
        f = tomllib.loads((REPO / "cameras" / "properties" / f"{name}.toml").read_text("utf-8"))
        if "full_well" in f.get("noise", {}):
            wells.append(f["noise"]["full_well"])
            reads.append(f["noise"]["read_noise"])
        optics = f.get("optics", {})
        (sigmas if optics.get("kind") == "gaussian" else radii).extend(
            [optics[k] for k in ("sigma_px", "radius_px") if k in optics])
    ranges = derived["degradations"]
    assert ranges["noise"]["ranges"]["read_noise"] == [min(reads), max(reads)] == [2.0, 10.0]
    assert ranges["optics"]["ranges"] == {"radius_px": [min(radii), max(radii)],
                                          "sigma_px": [min(sigmas), max(sigmas)]}
    assert ranges["noise"]["ranges"]["full_well"] == [min(wells), max(wells)] == [625.0, 3e4]
    assert load_validated_cameras().properties == ValidatedProperties.from_json(derived)


def test_the_default_camera_is_inside_the_validated_noise():
    """The default camera (Nikon D5100 model, full well 20000 e-, read noise 3 e-): its noise
    lies inside the sharpness and noise validation's cameras, so the check is inside the
    domain and its terminal says nothing of it."""
    checks = {c.name: c for c in fidelity.check_camera("nikon-5100").validity.checks}
    assert checks["validated noise"].inside
    assert "39 cameras, 74 of 78" in checks["validated noise"].detail
    r = CliRunner().invoke(main, ["--no-config", "check", "--no-report"])
    assert r.exit_code == 0 and "outside the validity domain" not in r.output, r.output


@pytest.mark.parametrize(("a", "b", "joined"), [
    (ValidatedDegradation(("none",)), ValidatedDegradation(("none", "shot+read"),
                                                           {"full_well": (625.0, 3e4)}),
     ValidatedDegradation(("none", "shot+read"), {"full_well": (625.0, 3e4)})),
    (ValidatedDegradation(("gaussian",), {"sigma_px": (1.0, 2.0)}),
     ValidatedDegradation(("defocus", "gaussian"), {"radius_px": (1.5, 3.0),
                                                    "sigma_px": (0.5, 1.5)}),
     ValidatedDegradation(("defocus", "gaussian"), {"radius_px": (1.5, 3.0),
                                                    "sigma_px": (0.5, 2.0)})),
])
def test_two_validations_join_kinds_and_widen_ranges(a, b, joined):
    assert joined_degradation(a, b) == joined == joined_degradation(b, a)
