"""Measured loss on COCO (--measure): the cached baseline, the identity camera, patch fits."""

from __future__ import annotations

import numpy as np
import pytest

from fidelity.coco.emulation import PatchEmulation, fit_emulation
from fidelity.core.errors import InvalidValueError


def test_inputs_come_from_options_or_the_shared_folder(monkeypatch, tmp_path):
    from fidelity.coco.measure import resolve_coco_inputs

    monkeypatch.setenv("FIDELITY_SHARED", str(tmp_path / "none"))
    with pytest.raises(InvalidValueError, match=r"--images .*--annotations .*FIDELITY_SHARED"):
        resolve_coco_inputs()
    shared = tmp_path / "shared"
    (shared / "coco" / "val2017").mkdir(parents=True)
    (shared / "models").mkdir()
    (shared / "models" / "yolox_nano.onnx").write_bytes(b"x")
    monkeypatch.setenv("FIDELITY_SHARED", str(shared))
    got = resolve_coco_inputs()
    assert got.images == shared / "coco" / "val2017"
    assert got.models[0].path.name == "yolox_nano.onnx"
    got = resolve_coco_inputs(models=f"{shared / 'models' / 'yolox_nano.onnx'}@40")
    assert got.models[0].limit == 40


def test_a_patch_fit_of_a_chart_on_itself_is_the_identity():
    from fidelity.camera.render import render_chart
    from fidelity.measure.colour import neutral_patches

    m = render_chart("ideal").measurement
    emu = PatchEmulation.fit(m.reference_srgb, m.reference_srgb, neutral_patches(m))
    x = np.random.default_rng(0).random((5000, 3))
    np.testing.assert_allclose(emu.apply(x), x, atol=1e-9)
    assert emu.patch_delta_e().max() < 1e-9


def test_a_patch_fit_agrees_with_the_camera_model_fit():
    """From 24 patches alone, the mapping of the default camera lands within 0.5 ΔE00 (mean
    over 351 training colours) of the one fitted on the camera's spectral model."""
    from fidelity.camera.render import render_chart
    from fidelity.colour.colorimetry import delta_e_2000, srgb_to_lab
    from fidelity.measure.colour import neutral_patches

    m = render_chart("nikon-5100").measurement
    emu = PatchEmulation.fit(m.reference_srgb, m.srgb, neutral_patches(m))
    model = fit_emulation("nikon-5100")
    s = model.samples.reference_srgb
    de = delta_e_2000(srgb_to_lab(emu.apply(s)), srgb_to_lab(model.apply(s)))
    assert float(de.mean()) < 0.5


def test_the_identity_camera_costs_nothing_and_the_baseline_is_cached(shared, tmp_path):
    """Emulating the ideal camera changes no 8-bit image: ΔmAP 0 exactly; a second run
    infers nothing (baseline and mapping come from the store)."""
    from fidelity.coco.measure import MeasureRequest, resolve_coco_inputs
    from fidelity.pipeline.check import check_camera

    req = MeasureRequest(resolve_coco_inputs(), limit=30, store=str(tmp_path / "store"))
    first = check_camera("ideal", measure=req).measured[0]
    assert first.dmap_points == 0.0 and first.dmap_points_se == 0.0
    assert first.inferred == 60 and not first.baseline_cached
    again = check_camera("ideal", measure=req).measured[0]
    assert again.inferred == 0 and again.baseline_cached
    assert again.to_json() | {"seconds": 0} == first.to_json() | {"seconds": 0, "inferred": 0,
                                                                    "baseline_cached": True}


@pytest.mark.slow  # fast twin: test_the_identity_camera_costs_nothing_and_the_baseline_is_cached
def test_audit_measure_of_an_ideal_render_is_zero_within_se(shared, tmp_path):
    from fidelity.camera.render import render_chart
    from fidelity.chart.image import write_png
    from fidelity.coco.measure import MeasureRequest, resolve_coco_inputs
    from fidelity.pipeline.check import audit_image

    write_png(tmp_path / "ideal.png", render_chart("ideal").display_image, 16)
    req = MeasureRequest(resolve_coco_inputs(), limit=50, store=str(tmp_path / "store"))
    m = audit_image(tmp_path / "ideal.png", measure=req).measured[0]
    assert m.images == 50
    assert abs(m.dmap_points) <= 2 * (m.dmap_points_se or 0.0) + 0.05


def test_the_baseline_key_is_reserved(shared, tmp_path):
    from fidelity.coco.measure import measure_mapping, resolve_coco_inputs

    with pytest.raises(InvalidValueError, match="reserved"):
        measure_mapping(lambda a: a, "baseline", resolve_coco_inputs(), limit=2,
                        store=tmp_path)
