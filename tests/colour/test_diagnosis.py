"""The cause of a chart error (fidelity.colour.diagnosis), on closed-form simulations of the
known mistakes built from the reference chart: an exact exposure error, a black offset, sRGB
values used as linear, white-balance gains, a hue rotation, saturation, published tone curves
(the minimal AgX polynomial, Hable's filmic curve, Narkowicz's ACES fit) and display gammas.
Each diagnosis names the cause with its numbers; a correct chart (exact, 8-bit rounded, with
pixel noise) names none. The independent references are the formulas written out here (and,
where Blender's OpenColorIO config is at hand, the view transforms sampled again)."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np
import pytest

from fidelity.colour import colorimetry as cm
from fidelity.colour.charts import load_reference
from fidelity.colour.diagnosis import (
    VIEW_TRANSFORMS_FILE,
    Diagnosis,
    diagnose,
    view_transforms,
)
from fidelity.core.errors import InvalidValueError
from fidelity.core.resources import resource_dir

ROOT = Path(__file__).resolve().parents[2]
REF = load_reference("scene")
#: The reference patches in linear sRGB, unclipped (cyan's red is negative), and the albedos
#: an sRGB renderer can hold (negatives clipped).
LINEAR = np.asarray(cm.xyz_to_linear_srgb(cm.lab_to_xyz(REF.lab)), np.float64)
ALBEDO = np.clip(LINEAR, 0.0, None)
Y = ALBEDO @ np.array([0.2126, 0.7152, 0.0722])


def srgb_encode(x: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 encoding, written out."""
    x = np.clip(x, 0.0, None)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def srgb_decode(v: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 decoding, written out."""
    v = np.clip(v, 0.0, None)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def display(x: np.ndarray) -> np.ndarray:
    """What an 8-bit PNG of display-linear values holds, decoded again."""
    return srgb_decode(np.round(np.clip(srgb_encode(x), 0, 1) * 255) / 255)


def minimal_agx(x: np.ndarray) -> np.ndarray:
    """B. Wrensch's "Minimal AgX" (2023): the inset matrix, log2 encoding over
    [-12.47393, 4.026069], the 6th-order polynomial fit of AgX's sigmoid, the outset matrix,
    then a power 2.2 to display-linear."""
    inset = np.array([[0.842479062253094, 0.0423282422610123, 0.0423756549057051],
                      [0.0784335999999992, 0.878468636469772, 0.0784336],
                      [0.0792237451477643, 0.0791661274605434, 0.879142973793104]])
    outset = np.array([[1.19687900512017, -0.0528968517574562, -0.0529716355144438],
                       [-0.0980208811401368, 1.15190312990417, -0.0980434501171241],
                       [-0.0990297440797205, -0.0989611768448433, 1.15107367264116]])
    lo, hi = -12.47393, 4.026069
    v = np.clip(np.log2(np.maximum(x @ inset, 1e-10)), lo, hi)
    v = (v - lo) / (hi - lo)
    v = (15.5 * v ** 6 - 40.14 * v ** 5 + 31.96 * v ** 4 - 6.868 * v ** 3 + 0.4298 * v ** 2
         + 0.1191 * v - 0.00232)
    return np.clip(v @ outset, 0.0, 1.0) ** 2.2


def hable(x: np.ndarray) -> np.ndarray:
    """J. Hable's filmic curve ("Uncharted 2", GDC 2010), exposure bias 2, white 11.2."""
    a, b, c, d, e, f = 0.15, 0.50, 0.10, 0.20, 0.02, 0.30

    def curve(v: np.ndarray) -> np.ndarray:
        return (v * (a * v + c * b) + d * e) / (v * (a * v + b) + d * f) - e / f

    return np.clip(curve(2.0 * x) / curve(np.array(11.2)), 0.0, 1.0)


def aces_fit(x: np.ndarray) -> np.ndarray:
    """K. Narkowicz's fit of the ACES RRT + sRGB ODT (2016), with its 0.6 pre-exposure."""
    v = 0.6 * x
    return np.clip(v * (2.51 * v + 0.03) / (v * (2.43 * v + 0.59) + 0.14), 0.0, 1.0)


def only(d: Diagnosis, kind: str):
    assert [c.kind for c in d.causes] == [kind], d.summary()
    return d.causes[0]


# -------------------------------------------------------------------------------------------
# Correct charts: no cause
# -------------------------------------------------------------------------------------------

@pytest.mark.parametrize("case", ["exact", "8-bit", "noise"])
def test_a_correct_chart_has_no_cause(case):
    rng = np.random.default_rng(3)
    measured, disp = {"exact": (ALBEDO, False), "8-bit": (display(ALBEDO), True),
                      "noise": (ALBEDO * (1 + 0.003 * rng.standard_normal(ALBEDO.shape)),
                                False)}[case]
    d = diagnose(measured, LINEAR, display_referred=disp, patch_names=REF.patch_names)
    assert d.causes == () and d.within_noise, d.summary()
    assert d.summary().startswith("no systematic cause: the patches match the reference")
    # the cyan's reference lies outside the sRGB gamut: a note, the known limit
    assert len(d.notes) == 1 and "patch 18 (cyan)" in d.notes[0] and "known limit" in d.notes[0]


def test_an_automatic_exposure_is_reported_not_a_cause():
    d = diagnose(ALBEDO * 4.0, LINEAR, exposure_fixed=False)
    assert d.causes == () and d.exposure_ev == pytest.approx(2.0, abs=1e-6)
    assert "+2.00 EV, is normalised away by the automatic exposure" in d.summary()


# -------------------------------------------------------------------------------------------
# The known mistakes
# -------------------------------------------------------------------------------------------

@pytest.mark.parametrize("ev", [2.0, -1.5, 0.07])
def test_exposure(ev):
    d = diagnose(ALBEDO * 2.0 ** ev, LINEAR)
    c = only(d, "exposure")
    assert c.values["ev"] == pytest.approx(ev, abs=0.005) and d.exposure_ev == c.values["ev"]
    assert c.text.startswith(f"exposure {ev:+.2f} EV")
    assert d.residual_delta_e < 0.01 < d.delta_e


def test_exposure_with_the_expected_one_fixed():
    """--exposure 2 (the image should be at -2 EV): an image at -1 EV is +1 EV wrong."""
    d = diagnose(ALBEDO * 0.5, LINEAR, expected_ev=-2.0)
    assert only(d, "exposure").values["ev"] == pytest.approx(1.0, abs=0.005)


def test_black_offset():
    d = diagnose(ALBEDO + 0.02, LINEAR)
    c = only(d, "black-offset")
    assert c.values["offset"] == pytest.approx(0.02, abs=5e-4)
    assert "+0.0200 of white" in c.text and "black patch 0.0320 -> 0.0520" in c.text


def test_exposure_and_black_offset_together():
    d = diagnose(ALBEDO * 2.0 + 0.01, LINEAR)
    assert [c.kind for c in d.causes] == ["exposure", "black-offset"]
    assert d.cause("exposure").values["ev"] == pytest.approx(1.0, abs=0.01)
    assert d.cause("black-offset").values["offset"] == pytest.approx(0.01, abs=1e-3)


@pytest.mark.parametrize("disp", [False, True])
def test_srgb_values_used_as_linear(disp):
    measured = srgb_encode(ALBEDO)
    d = diagnose(display(measured) if disp else measured, LINEAR, display_referred=disp)
    c = only(d, "tone")
    assert c.tone_curve == "sRGB-encoded values used as linear"
    assert c.text.startswith("gamma / encoding: sRGB-encoded values used as linear")
    assert d.exposure_ev == 0.0


def test_linear_values_decoded_as_srgb():
    c = only(diagnose(srgb_decode(ALBEDO), LINEAR), "tone")
    assert c.tone_curve == "linear values decoded as sRGB"


@pytest.mark.parametrize("gamma", [2.2, 2.4])
def test_display_gamma(gamma):
    """A simulator that encodes with a pure power (CARLA's 2.2, then 2.4), read as sRGB."""
    c = only(diagnose(display(srgb_decode(ALBEDO ** (1 / gamma))), LINEAR,
                      display_referred=True), "tone")
    assert c.values["gamma"] == pytest.approx(gamma, abs=0.03)


def test_white_balance():
    g = np.array([1.15, 1.0, 0.85])
    g = g / (g @ np.array([0.2126, 0.7152, 0.0722]))  # the luminance kept
    d = diagnose(ALBEDO * g, LINEAR)
    c = only(d, "white-balance")
    assert c.values["red_gain"] == pytest.approx(1.15, abs=0.005)
    assert c.values["blue_gain"] == pytest.approx(0.85, abs=0.005)
    assert "red ×1.150, blue ×0.850 relative to green" in c.text


@pytest.mark.parametrize("s", [0.7, 1.3])
def test_saturation(s):
    measured = Y[:, None] + s * (ALBEDO - Y[:, None])
    c = only(diagnose(np.clip(measured, 0, None), LINEAR), "saturation")
    assert c.values["saturation"] == pytest.approx(s, abs=0.01)


@pytest.mark.parametrize("degrees", [10.0, -25.0])
def test_hue_rotation(degrees):
    """A rotation of linear RGB about the grey axis, by SciPy's rotation vectors."""
    from scipy.spatial.transform import Rotation

    r = Rotation.from_rotvec(np.radians(degrees) * np.ones(3) / np.sqrt(3)).as_matrix()
    c = only(diagnose(np.clip(ALBEDO @ r.T, 0, None), LINEAR), "hue")
    assert c.values["hue_degrees"] == pytest.approx(degrees, abs=0.2)


@pytest.mark.parametrize("curve", [minimal_agx, hable, aces_fit])
def test_a_tone_mapped_render_is_named_tone_mapping(curve):
    d = diagnose(display(curve(ALBEDO)), LINEAR, display_referred=True)
    assert d.causes and d.causes[0].kind == "tone", d.summary()
    assert d.causes[0].text.startswith("tone mapping: highlights compressed")
    # the model explains most of the error
    assert d.residual_delta_e < 0.5 * d.delta_e


def test_a_camera_matrix_error_has_no_single_cause():
    """The built-in camera's colour error (its sensitivities against the CIE observer) moves
    each patch its own way: no pipeline part is named."""
    from fidelity.pipeline.check import check_camera

    d = check_camera("nikon-5100").diagnosis
    assert d is not None and d.causes == () and not d.within_noise
    assert "differs from patch to patch" in d.summary()


# -------------------------------------------------------------------------------------------
# The record and its data
# -------------------------------------------------------------------------------------------

def test_json_round_trip_and_speed():
    t0 = time.perf_counter()
    d = diagnose(display(hable(ALBEDO * 1.5)), LINEAR, display_referred=True)
    assert time.perf_counter() - t0 < 5.0
    doc = json.loads(json.dumps(d.to_json()))
    assert Diagnosis.from_json(doc) == d and doc["summary"] == d.summary()


def test_bad_input():
    with pytest.raises(InvalidValueError):
        diagnose(ALBEDO[:, :2], LINEAR)
    with pytest.raises(InvalidValueError):
        diagnose(ALBEDO, LINEAR, used=np.arange(24) < 3)
    with pytest.raises(InvalidValueError):
        diagnose(np.full((24, 3), np.nan), LINEAR)


def _blender_config() -> Path | None:
    env = os.environ.get("FIDELITY_BLENDER_OCIO")
    if env:
        return Path(env)
    found = sorted((ROOT / ".venv-blender").glob(
        "lib/python3*/site-packages/bpy/*/datafiles/colormanagement/config.ocio"))
    return found[-1] if found else None


def test_view_transforms_are_blenders():
    """The shipped neutral curves are Blender's view transforms, sampled again here with
    OpenColorIO from the bpy wheel's config (skipped without it)."""
    ocio = pytest.importorskip("PyOpenColorIO", reason="the [ocio] extra (opencolorio)")
    config = _blender_config()
    if config is None or not config.is_file():
        pytest.skip("Blender's OpenColorIO config not found (.venv-blender with bpy==5.0.1, or "
                    "FIDELITY_BLENDER_OCIO)")
    cfg = ocio.Config.CreateFromFile(str(config))
    doc = json.loads((resource_dir("data") / VIEW_TRANSFORMS_FILE).read_text())
    curves = {t.name: t for t in view_transforms()}
    grey = np.array([[0.18 * 2.0 ** k] * 3 for k in (-4.0, -1.0, 0.0, 1.0, 3.0)], np.float32)
    for entry in doc["transforms"]:
        group = ocio.GroupTransform()
        if entry["look"]:
            group.appendTransform(ocio.LookTransform(src="Linear Rec.709",
                                                     dst="Linear Rec.709", looks=entry["look"]))
        group.appendTransform(ocio.DisplayViewTransform(src="Linear Rec.709", display="sRGB",
                                                        view=entry["view"]))
        out = grey.copy()
        cfg.getProcessor(group).getDefaultCPUProcessor().applyRGB(out)
        expected = srgb_decode(out.astype(np.float64))
        got = curves[entry["name"]](grey.astype(np.float64), np.zeros(0))
        np.testing.assert_allclose(got, expected, rtol=2e-3, atol=1e-5, err_msg=entry["name"])


@pytest.mark.parametrize("tone", [None, "gamma", "display gamma", "tone curve", "AgX"])
def test_a_stack_of_parameters_predicts_each_chart_as_alone(tone):
    """The Jacobian's columns come from one call on a (k, p) stack: each row is the chart of
    its own parameters (to rounding), and the vectorised fit is the column-by-column one."""
    from fidelity.colour import diagnosis as dg

    curve = next((c for c in dg.tone_curves() if c.name == tone), None)
    spec = dg._Spec(exposure=True, offset=True, balance=True, hue=True, saturation=True,
                    tone=curve)
    ref = np.linspace(0.02, 0.9, 72).reshape(24, 3)
    rng = np.random.default_rng(4)
    stack = rng.normal(0.0, 0.2, (7, spec.size))
    together = dg._predict(spec, stack, ref, 0.5, True)
    alone = np.stack([dg._predict(spec, row, ref, 0.5, True) for row in stack])
    assert together.shape == (7, 24, 3)
    np.testing.assert_allclose(together, alone, rtol=1e-13, atol=1e-15)
    target = dg._predict(spec, stack[0], ref, 0.5, False) * 0.9 + 0.01
    lo, hi = dg._bounds(spec)

    def residual(theta):
        return (dg._predict(spec, theta, ref, 0.5, False) - target).reshape(
            *np.shape(theta)[:-1], -1)

    start = np.zeros(spec.size)
    a = dg.least_squares(residual, start, lo, hi, vectorised=True)
    b = dg.least_squares(residual, start, lo, hi)
    # the same fit (its parameters trade off along the model's flat directions: its charts)
    assert a[1] == pytest.approx(b[1], rel=1e-6, abs=1e-14)
    np.testing.assert_allclose(dg._predict(spec, a[0], ref, 0.5, False),
                               dg._predict(spec, b[0], ref, 0.5, False), atol=1e-6)
