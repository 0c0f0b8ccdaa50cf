"""Fuzz: COCO annotations and ONNX detectors for ``evaluate`` (and ``sweep``): null, numbers,
missing fields, unknown ids, NaN boxes, no annotations; models with other class counts, NaN
outputs, class indices out of range, damaged files."""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.fuzz.fuzzkit import (
    FAST,
    LONG,
    assert_promise,
    budget,
    damaged_bytes,
    fingerprint,
    json_text,
    mutated,
    onnx_model,
    run,
    ultralytics_output,
    yolox_cells,
)

EXAMPLES = [FAST, pytest.param(LONG, marks=pytest.mark.fuzz)]


def _evaluate(coco: dict[str, Any], *, model: Path | None = None,
              annotations: Path | None = None, codes: tuple[int, ...] = (0, 2),
              names: list[str] | None = None) -> None:
    model = model or coco["model"]
    annotations = annotations or coco["annotations"]
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "e.json"
        before = fingerprint([model, annotations, coco["images"]])
        outcome = run("evaluate", "--models", model, "--images", coco["images"],
                      "--annotations", annotations, "--json", out, "--no-progress")
        assert_promise(outcome, names=names or [str(annotations), str(model)], before=before,
                       outputs=[out], folders=[Path(tmp), coco["folder"]], codes=codes)


@pytest.mark.parametrize("examples", EXAMPLES)
def test_annotations(examples: int, coco: dict[str, Any]) -> None:
    """Annotations with fields changed: scored, or refused naming the file and the field."""

    @budget(examples)
    @given(doc=mutated(coco["doc"]))
    def check(doc: Any) -> None:
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "ann.json"
            path.write_text(json_text(doc))
            _evaluate(coco, annotations=path, names=[str(path)])

    check()


def _changed(doc: dict[str, Any], change: str) -> Any:
    import copy

    d = copy.deepcopy(doc)
    if change == "null":
        return None
    if change == "number":
        return 3
    if change == "no categories":
        d["categories"] = []
    elif change == "no annotations":
        d["annotations"] = []
    elif change == "unknown image id":
        d["annotations"][0]["image_id"] = 999
    elif change == "unknown category id":
        d["annotations"][0]["category_id"] = 999
    elif change == "NaN box":
        d["annotations"][0]["bbox"][2] = float("nan")
    elif change == "no file_name":
        del d["images"][0]["file_name"]
    elif change == "no bbox":
        del d["annotations"][0]["bbox"]
    elif change == "negative box":
        d["annotations"][0]["bbox"][3] = -4.0
    elif change == "duplicate image id":
        d["images"][1]["id"] = d["images"][0]["id"]
    return d


@pytest.mark.parametrize("change", [
    "null", "number", "no categories", "no annotations", "unknown image id",
    "unknown category id", "NaN box", "no file_name", "no bbox", "negative box",
    "duplicate image id"])
def test_annotation_corner_cases(change: str, coco: dict[str, Any], tmp_path: Path) -> None:
    """What the issue found scored as mAP 0.0000 with exit 0, or crashed: now exit 2."""
    path = tmp_path / "ann.json"
    path.write_text(json_text(_changed(coco["doc"], change)))
    _evaluate(coco, annotations=path, codes=(2,), names=[str(path)])


@st.composite
def model_outputs(draw: st.DrawFn) -> tuple[np.ndarray, dict[str, str]]:
    """Raw outputs of a stand-in detector: Ultralytics 1x(4+C)xN with C classes (80 or not),
    YOLOv10 end-to-end 1xKx6 with class indices in or out of range, with NaN or Inf."""
    kind = draw(st.sampled_from(["ultralytics", "e2e"]))
    special = draw(st.sampled_from([None, None, np.nan, np.inf, -np.inf, 1e30]))
    seed = draw(st.integers(0, 1000))
    if kind == "ultralytics":
        classes = draw(st.sampled_from([80, 80, 1, 3, 79, 81, 90]))
        return ultralytics_output(classes, 32, draw(st.integers(0, 5)), seed, special), {}
    rng = np.random.default_rng(seed)
    k = draw(st.integers(1, 10))
    out = np.zeros((1, k, 6), dtype=np.float32)
    out[0, :, :2] = rng.uniform(0, 16, (k, 2))
    out[0, :, 2:4] = out[0, :, :2] + rng.uniform(1, 16, (k, 2))
    out[0, :, 4] = rng.uniform(0, 1, k)
    out[0, :, 5] = draw(st.sampled_from([0, 5, 79, 80, 81, 200, -1, 2.5]))
    if special is not None:
        out[0, draw(st.integers(0, k - 1)), draw(st.integers(0, 5))] = special
    return out, {"end2end": "true"}


@pytest.mark.parametrize("examples", EXAMPLES)
def test_models(examples: int, coco: dict[str, Any]) -> None:
    """Stand-in detectors with odd class counts, NaN scores, class indices >= 80: scored, or
    refused naming the model (exit 2), never a crash in scoring."""

    @budget(examples)
    @given(output=model_outputs())
    def check(output: tuple[np.ndarray, dict[str, str]]) -> None:
        with tempfile.TemporaryDirectory() as tmp:
            model = onnx_model(Path(tmp) / "m.onnx", output[0], metadata=output[1])
            _evaluate(coco, model=model, names=[str(model)])

    check()


@pytest.mark.parametrize("case", ["dynamic input", "two outputs", "rank-3 input",
                                  "unknown layout", "nan scores", "class 80", "79 classes"])
def test_model_corner_cases(case: str, coco: dict[str, Any], tmp_path: Path) -> None:
    """Models the issue found, and layouts no detector has: exit 2 naming the model."""
    path = tmp_path / "m.onnx"
    out = ultralytics_output()
    if case == "dynamic input":
        onnx_model(path, out, input_shape=["batch", 3, 32, 32])
    elif case == "two outputs":
        onnx_model(path, out, outputs=2)
    elif case == "rank-3 input":
        onnx_model(path, out, input_shape=[3, 32, 32])
    elif case == "unknown layout":
        onnx_model(path, np.zeros((1, 7, 7), np.float32))
    elif case == "nan scores":
        onnx_model(path, ultralytics_output(special=np.nan))
    elif case == "class 80":
        e2e = np.zeros((1, 5, 6), np.float32)
        e2e[0, :, 2:5] = [10, 10, 0.9]
        e2e[0, 0, 5] = 80
        onnx_model(path, e2e, metadata={"end2end": "true"})
    else:
        onnx_model(path, np.zeros((1, 83, yolox_cells(32)), np.float32))
    _evaluate(coco, model=path, codes=(2,), names=[str(path)])


@pytest.mark.parametrize("examples", EXAMPLES)
def test_damaged_models(examples: int, coco: dict[str, Any]) -> None:
    """An ONNX file cut short, overwritten or replaced."""
    raw = coco["model"].read_bytes()

    @budget(examples)
    @given(data=st.data())
    def check(data: st.DataObject) -> None:
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "m.onnx"
            path.write_bytes(data.draw(damaged_bytes(raw)))
            _evaluate(coco, model=path, names=[str(path)])

    check()


@pytest.mark.parametrize("examples", EXAMPLES)
def test_damaged_coco_images(examples: int, coco: dict[str, Any]) -> None:
    """One image of the folder cut short, overwritten, replaced, or another format under a
    .jpg name: scored or refused naming the image, for evaluate (and so for sweep)."""
    import shutil

    @budget(examples)
    @given(data=st.data(), kind=st.sampled_from(["damaged", "png", "grey", "cmyk", "tiny"]))
    def check(data: st.DataObject, kind: str) -> None:
        from PIL import Image

        with tempfile.TemporaryDirectory() as tmp:
            folder = Path(tmp) / "img"
            shutil.copytree(coco["images"], folder)
            victim = sorted(folder.iterdir())[0]
            if kind == "damaged":
                victim.write_bytes(data.draw(damaged_bytes(victim.read_bytes())))
            else:
                im = Image.open(coco["images"] / victim.name)
                im = {"png": im, "grey": im.convert("L"), "cmyk": im.convert("CMYK"),
                      "tiny": im.resize((1, 1))}[kind]
                im.save(victim, format="PNG" if kind == "png" else "JPEG")
            images = dict(coco, images=folder)
            _evaluate(images, names=[victim.name])

    check()


def test_sweep_without_models_is_an_error(coco: dict[str, Any], tmp_path: Path) -> None:
    """``sweep --models ''`` did nothing and exited 0; now it says so (exit 2)."""
    for models in ("", ",", " , "):
        r = run("sweep", "--models", models, "--images", coco["images"], "--annotations",
                coco["annotations"], "--out", tmp_path / "s")
        assert_promise(r, names=["--models"], before={}, codes=(2,))


def test_sweep_stops_on_a_broken_model(coco: dict[str, Any], tmp_path: Path) -> None:
    """A detector whose class index is 80 stops the sweep with one line naming it, on the
    first image (it used to fail the same cell at every rerun)."""
    path = tmp_path / "bad.onnx"
    e2e = np.zeros((1, 5, 6), np.float32)
    e2e[0, :, 2:5] = [10, 10, 0.9]
    e2e[0, 0, 5] = 80
    onnx_model(path, e2e, metadata={"end2end": "true"})
    before = fingerprint([path, coco["annotations"], coco["images"]])
    for _ in range(2):
        r = run("sweep", "--models", path, "--images", coco["images"], "--annotations",
                coco["annotations"], "--out", tmp_path / "s", "--transforms", "hue",
                "--targets", "0", "--no-progress")
        assert_promise(r, names=[str(path)], before=before, codes=(2,),
                       folders=[tmp_path / "s"])
