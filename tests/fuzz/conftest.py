"""Fixtures of the fuzz suite: valid inputs that the generators damage."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from fidelity.core.resources import resource_dir


@pytest.fixture(scope="session")
def chart_images(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A rendered chart (the built-in camera) as PNG, JPEG and EXR."""
    import numpy as np

    from fidelity.camera.render import render_chart
    from fidelity.chart.image import write_exr, write_png
    from tests.fuzz.fuzzkit import write_image

    folder = tmp_path_factory.mktemp("charts")
    r = render_chart("nikon-5100", pixels_per_patch=16)
    display = np.clip(r.display_image, 0, 1)
    return {
        "png": write_png(folder / "chart.png", display, 8),
        "exr": write_exr(folder / "chart.exr", r.linear_image),
        "jpg": write_image(folder / "chart.jpg", np.round(display * 255).astype(np.uint8)),
    }


@pytest.fixture(scope="session")
def safecolor_chart() -> dict[str, Any]:
    """The shipped SAFE-COLOR chart file's content."""
    doc: dict[str, Any] = json.loads((resource_dir("charts") / "safecolor.json").read_text())
    return doc


@pytest.fixture(scope="session")
def published_table() -> dict[str, Any]:
    """The shipped safecolor-2025 prediction table's content."""
    from fidelity.prediction.tablefile import prediction_dir

    doc: dict[str, Any] = json.loads((prediction_dir() / "safecolor-2025.json").read_text())
    return doc


@pytest.fixture(scope="session")
def coco(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """A three-image COCO set and a stand-in detector that runs on it."""
    pytest.importorskip("onnxruntime")
    pytest.importorskip("onnx")
    pytest.importorskip("pycocotools")
    from tests.fuzz.fuzzkit import coco_set, onnx_model, ultralytics_output

    folder = tmp_path_factory.mktemp("coco")
    images, ann, doc = coco_set(folder)
    model = onnx_model(folder / "model.onnx", ultralytics_output())
    return {"images": images, "annotations": ann, "doc": doc, "model": model,
            "folder": folder}
