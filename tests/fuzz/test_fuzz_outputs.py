"""Output paths: no command writes over what it reads — an input file, a file inside an input
folder, a results store — nor over a folder or its own other output. Each case is refused
before any work, in one line naming the option, and every input is left as it was."""

from __future__ import annotations

import gc
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from tests.fuzz.fuzzkit import CAMERA, assert_promise, fingerprint, run, toml_text


@pytest.fixture
def world(tmp_path: Path, chart_images: dict[str, Path], safecolor_chart: dict[str, Any],
          published_table: dict[str, Any]) -> dict[str, Path]:
    """Inputs of every command in one folder: an image, a camera file with its sensitivity
    CSV, a chart, a prediction table and notes."""
    import json

    import colour

    w = {"dir": tmp_path}
    w["image"] = Path(shutil.copy(chart_images["png"], tmp_path / "chart.png"))
    msds = colour.MSDS_CAMERA_SENSITIVITIES["Nikon 5100 (NPL)"]
    w["csv"] = tmp_path / "sens.csv"
    w["csv"].write_text("".join(f"{wl},{r},{g},{b}\n" for wl, (r, g, b)
                                in zip(msds.wavelengths, msds.values, strict=True)))
    camera = dict(CAMERA, sensitivities={"source": "file", "path": "sens.csv"})
    w["camera"] = tmp_path / "camera.toml"
    w["camera"].write_text(toml_text(camera) or "")
    w["chart"] = tmp_path / "chart.json"
    w["chart"].write_text(json.dumps(safecolor_chart))
    w["table"] = tmp_path / "table.json"
    w["table"].write_text(json.dumps(published_table))
    w["notes"] = tmp_path / "notes.md"
    w["notes"].write_text("# notes\n")
    (tmp_path / "reports").mkdir()
    return w


#: (case id, command line from the world, the option named in the error)
CASES: list[tuple[str, Callable[[dict[str, Path]], list[Any]], str]] = [
    ("audit --json IMAGE", lambda w: ["audit", w["image"], "--json", w["image"]], "--json"),
    ("audit --html table", lambda w: ["audit", w["image"], "--table", w["table"], "--html",
                                      w["table"]], "--html"),
    ("audit --json reference", lambda w: ["audit", w["image"], "--reference", w["chart"],
                                          "--json", w["chart"]], "--json"),
    ("audit --json = --html", lambda w: ["audit", w["image"], "--json", w["dir"] / "r.x",
                                         "--html", w["dir"] / "r.x"], "--html"),
    ("gate --junit IMAGE", lambda w: ["gate", w["image"], "--max-delta-e", "3", "--junit",
                                      w["image"]], "--junit"),
    ("gate --html camera", lambda w: ["gate", "--camera", w["camera"], "--max-delta-e", "3",
                                      "--html", w["camera"]], "--html"),
    ("gate --json camera's CSV", lambda w: ["gate", "--camera", w["camera"], "--max-delta-e",
                                            "3", "--json", w["csv"]], "--json"),
    ("check --json camera's CSV", lambda w: ["check", "--camera", w["camera"], "--json",
                                             w["csv"], "--out", w["dir"] / "o"], "--json"),
    ("render --json camera", lambda w: ["render", "--camera", w["camera"], "--json",
                                        w["camera"]], "--json"),
    ("render --json camera's CSV", lambda w: ["render", "--camera", w["camera"], "--json",
                                              w["csv"]], "--json"),
    ("render --out over developed.png", lambda w: [
        "render", "--camera", w["camera"], "--out", w["dir"] / "o", "--json",
        w["dir"] / "o" / "developed.png"], "--json"),
    ("predict --json table", lambda w: ["predict", "--delta-e", "3", "--table", w["table"],
                                        "--json", w["table"]], "--json"),
    ("calibrate --csv chart", lambda w: ["calibrate", "--chart", w["chart"], "--csv",
                                         w["chart"]], "--csv"),
    ("calibrate --markdown = --json", lambda w: ["calibrate", "--chart", w["chart"],
                                                 "--json", w["dir"] / "c", "--markdown",
                                                 w["dir"] / "c"], "--markdown"),
    ("info --json folder", lambda w: ["info", "--no-probe", "--json", w["dir"] / "reports"],
     "--json"),
    ("validate --out over notes", lambda w: [
        "validate", "--report-only", "--store", w["dir"] / "store", "--notes",
        w["dir"] / "validation.md", "--out", w["dir"]], "--out"),
    ("validate --out in store", lambda w: [
        "validate", "--report-only", "--store", w["dir"] / "store", "--out",
        w["dir"] / "store"], "--out"),
]


@pytest.mark.parametrize(("case", "argv", "option"), CASES, ids=[c[0] for c in CASES])
def test_outputs_never_write_over_inputs(case: str, argv: Callable[[dict[str, Path]], list[Any]],
                                         option: str, world: dict[str, Path]) -> None:
    (world["dir"] / "validation.md").write_text("my notes\n")
    (world["dir"] / "o").mkdir(exist_ok=True)
    (world["dir"] / "o" / "developed.png").write_bytes(world["image"].read_bytes())
    (world["dir"] / "store").mkdir(exist_ok=True)
    before = fingerprint([world["dir"]])
    outcome = run(*argv(world))
    assert_promise(outcome, names=[option], before=before, folders=[world["dir"]], codes=(2,))


def test_coco_outputs_never_write_over_inputs(coco: dict[str, Any], tmp_path: Path) -> None:
    """evaluate's --json over an image of --images (it wrote its JSON over one); dataset's
    subsets over --images; sweep's store over --annotations; tables' --prediction and
    --json (with --explain) over the results store."""
    images, ann, model = coco["images"], coco["annotations"], coco["model"]
    one = sorted(images.iterdir())[0]
    before = fingerprint([coco["folder"]])
    r = run("evaluate", "--models", model, "--images", images, "--annotations", ann,
            "--json", one)
    assert_promise(r, names=["--json"], before=before, codes=(2,))

    # dataset: the subset hue_de3 of --out is the input folder itself
    subset = tmp_path / "hue_de3"
    shutil.copytree(images, subset)
    before = fingerprint([tmp_path])
    r = run("dataset", "--images", subset, "--out", tmp_path, "--transforms", "hue",
            "--targets", "3", "--no-progress")
    assert_promise(r, names=["--out"], before=before, codes=(2,))

    # sweep: --annotations is the store file --out would write
    store = tmp_path / "sweep"
    store.mkdir()
    shutil.copy(ann, store / "sweep.sqlite")
    before = fingerprint([store, images, model])
    r = run("sweep", "--models", model, "--images", images, "--annotations",
            store / "sweep.sqlite", "--out", store, "--transforms", "hue", "--targets", "0")
    assert_promise(r, names=["--out"], before=before, codes=(2,))

    # tables: a real store, then outputs aimed at it
    real = tmp_path / "real"
    r = run("sweep", "--models", model, "--images", images, "--annotations", ann, "--out",
            real, "--transforms", "hue", "--targets", "0", "--no-progress")
    assert r.code == 0, r
    gc.collect()  # the in-process sweep's store connection closes now, not during the next run
    before = fingerprint([real])
    for args in (["--prediction", real / "sweep.sqlite"],
                 ["--prediction", real / "new.json"],
                 ["--explain", "model:hue:0", "--json", real / "sweep.sqlite"],
                 ["--out", real]):
        r = run("tables", real, "--annotations", ann, "--no-progress", *args)
        assert_promise(r, names=[args[0] if args[0] != "--explain" else "--json"],
                       before=before, codes=(2,))
    r = run("tables", real, "--annotations", ann, "--no-progress", "--prediction",
            tmp_path / "pred.json")
    assert r.code == 0, r
    assert (tmp_path / "pred.json").is_file() and (real / "report" / "report.html").is_file()
