"""``--limit N`` means one thing in every command that runs detectors on COCO images: at most N
images for every model, the first N annotated images by image id; a model's own ``@N`` caps it
further (the smaller wins). Checked by what each command scores, not by its help."""

from __future__ import annotations

import json
import random
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from fidelity.cli import main

# among the longest files of the suite: started first, so that a parallel run does not end on it
pytestmark = pytest.mark.early

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def small_coco(shared: Path, tmp_path: Path) -> tuple[Path, Path, Path]:
    """Eight images of the shared subset, listed in an order that is not their id order (so
    'first by id' differs from 'first in the file'), and YOLOX-nano."""
    images = shared / "coco" / "val2017"
    ann = shared / "coco" / "annotations" / "instances_val2017_subset.json"
    model = shared / "models" / "yolox_nano.onnx"
    if not (images.is_dir() and ann.is_file() and model.is_file()):
        pytest.skip("shared COCO slice or yolox_nano.onnx missing")
    data = json.loads(ann.read_text())
    picked = random.Random(3).sample(data["images"], 8)
    picked.sort(key=lambda im: -im["id"])  # the file lists the highest id first
    ids = {im["id"] for im in picked}
    small = data | {"images": picked,
                    "annotations": [a for a in data["annotations"] if a["image_id"] in ids]}
    path = tmp_path / "small.json"
    path.write_text(json.dumps(small))
    return images, path, model


@pytest.fixture
def scored(monkeypatch: pytest.MonkeyPatch) -> Callable[[list[str]], set[int]]:
    """Run a command line; the image ids its COCO scores were computed on."""
    import importlib
    import pkgutil
    import sys

    import fidelity
    import fidelity.coco.scoring as scoring

    seen: set[int] = set()
    original = scoring.evaluate_detections

    def spy(coco: Any, detections: Any, ids: Any, *args: Any, **kwargs: Any) -> Any:
        seen.update(int(i) for i in ids)
        return original(coco, detections, ids, *args, **kwargs)

    # every module that binds the scorer (imports are at module level): patched where it is
    # looked up, the modules of the commands imported first
    for info in pkgutil.walk_packages(fidelity.__path__, "fidelity."):
        if info.name.startswith(("fidelity.coco", "fidelity.cli", "fidelity.pipeline")):
            importlib.import_module(info.name)
    for module in list(sys.modules.values()):
        if (getattr(module, "__name__", "").startswith("fidelity")
                and getattr(module, "evaluate_detections", None) is original):
            monkeypatch.setattr(module, "evaluate_detections", spy)

    def run(argv: list[str]) -> set[int]:
        seen.clear()
        r = CliRunner().invoke(main, ["--no-config", *argv])
        assert r.exit_code == 0, r.output
        return set(seen)

    return run


@pytest.mark.shared
@pytest.mark.slow
@pytest.mark.parametrize(("at", "limit", "expect"), [(2, 3, 2), (5, 3, 3)])
def test_the_same_limit_selects_the_same_images_in_every_command(
        small_coco, scored, tmp_path, monkeypatch, at, limit, expect):
    images, ann, model = small_coco
    monkeypatch.setenv("FIDELITY_CACHE", str(tmp_path / "cache"))
    first = set(sorted(im["id"] for im in json.loads(ann.read_text())["images"])[:expect])
    m = str(model) if at is None else f"{model}@{at}"
    coco = ["--images", str(images), "--annotations", str(ann), "--models", m,
            "--limit", str(limit)]
    suite = tmp_path / "cams"
    suite.mkdir()
    shutil.copy(REPO / "cameras" / "ideal-srgb8.toml", suite)
    used = {
        "evaluate": scored(["evaluate", *coco, "--threads", "1", "--no-progress", "-q"]),
        "sweep": scored(["sweep", *coco, "--transforms", "hue", "--targets", "0", "--out",
                         str(tmp_path / "sweep"), "--threads", "1", "--no-progress", "-q"]),
        "validate": scored(["validate", "--cameras", str(suite), *coco, "--out",
                            str(tmp_path / "val"), "--store", str(tmp_path / "valstore"),
                            "--training", "chart", "--no-progress", "-q"]),
        "coco-c": scored(["coco-c", *coco, "--corruptions", "brightness", "--severities", "1",
                          "--out", str(tmp_path / "cococ"), "--store", str(tmp_path / "m"),
                          "--no-progress", "-q"]),
        "check --measure": scored(["check", "--camera", "ideal", "--measure", *coco,
                                   "--no-report", "-q"]),
    }
    assert used == dict.fromkeys(used, first)
