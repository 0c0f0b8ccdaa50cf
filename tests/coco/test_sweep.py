"""Sweep store durability (kill -9), resume without redoing cells, and the CI slice."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from fidelity.coco.sweep import (
    ModelSpec,
    SweepStore,
    cell_pace,
    pack_detections,
    plan_cells,
    plan_phases,
    unpack_detections,
)
from fidelity.core.errors import InputFileError, InvalidValueError

REPO = Path(__file__).resolve().parents[2]


def one_line_error(r, *names: str) -> None:  # type: ignore[no-untyped-def]
    """Exit code 2 and one line ``fidelity: error: ...`` that names each of ``names``."""
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("fidelity: error: "), r.output
    assert all(n in lines[0] for n in names) and "Traceback" not in r.output, (names, r.output)


def test_pack_roundtrip() -> None:
    d = np.random.default_rng(0).uniform(0, 600, (57, 6)).astype(np.float32)
    assert np.array_equal(unpack_detections(pack_detections(d)), d)
    assert unpack_detections(pack_detections(np.zeros((0, 6)))).shape == (0, 6)


def test_plan_with_blur_and_noise_families() -> None:
    from fidelity.coco.degradations import DEGRADATIONS, Degradation
    from fidelity.coco.executor import PixelTransform

    blur, noise = DEGRADATIONS["gaussian-blur"].levels, DEGRADATIONS["sensor-noise"].levels
    cells = plan_cells([], [0], ["gaussian-blur", "sensor-noise"])
    assert cells[0] == ("baseline", 0.0) and len(cells) == 1 + len(blur) + len(noise)
    assert cells[1:3] == [("gaussian-blur", blur[0]), ("sensor-noise", noise[0])]
    phases = plan_phases(1, [], [0], "priority", ["gaussian-blur"])
    assert [c for _, p in phases for c in p] == [("baseline", 0.0),
                                                 *[("gaussian-blur", v) for v in blur[::2]],
                                                 *[("gaussian-blur", v) for v in blur[1::2]]]
    spec = PixelTransform.of("gaussian-blur", 1.5, images=8)
    assert not spec.direct and spec.key == "gaussian-blur@1.5"
    assert spec.build() == Degradation("gaussian-blur", 1.5)


def test_plan_and_model_spec() -> None:
    cells = plan_cells(["a", "b"], [3, 0, 1])
    assert cells == [("baseline", 0.0), ("a", 1.0), ("b", 1.0), ("a", 3.0), ("b", 3.0)]
    phases = plan_phases(2, ["a"], [0, 1, 2, 3])
    assert phases == [(0, [("baseline", 0.0), ("a", 1.0), ("a", 3.0)]),
                      (1, [("baseline", 0.0), ("a", 1.0), ("a", 3.0)]),
                      (0, [("a", 2.0)]), (1, [("a", 2.0)])]
    assert plan_phases(2, ["a"], [0, 2], "ascending") == [(0, plan_cells(["a"], [0, 2])),
                                                          (1, plan_cells(["a"], [0, 2]))]
    reverse = plan_phases(2, ["a"], [0, 1, 2, 3], "reverse")
    assert reverse == [(1, [("a", 2.0)]), (0, [("a", 2.0)]),
                       (1, [("a", 3.0), ("a", 1.0), ("baseline", 0.0)]),
                       (0, [("a", 3.0), ("a", 1.0), ("baseline", 0.0)])]
    with pytest.raises(InvalidValueError):
        plan_phases(1, ["a"], [1], "random")
    assert ModelSpec.parse("m.onnx@250") == ModelSpec(Path("m.onnx"), 250)
    assert ModelSpec.parse("m.onnx").limit is None
    with pytest.raises(InvalidValueError):
        ModelSpec.parse("m.onnx@x")


def test_status_of_a_store_being_extended(tmp_path) -> None:
    """Counts from a store built by hand: done on the model's count, unreachable, one cell
    scored on fewer images and extended (under way), one not started; pace from timestamps."""
    from click.testing import CliRunner

    from fidelity.cli import main
    from fidelity.coco.sweep import sweep_status

    s = SweepStore(tmp_path)
    s.set_meta("grid", {"transforms": ["a", "b", "c"], "targets": [0, 3, 6]})
    s.set_meta("data", {"image_count": 10})
    s.register_model("m", "m.onnx", "0" * 64, 4, {})
    s.register_model("all", "all.onnx", "1" * 64, None, {})
    det = np.zeros((1, 6), np.float32)
    for t, e in (("baseline", 0), ("a", 3), ("b", 3)):
        s.finish_cell("m", t, e, param=1.0, status="done", images=4, seconds=180.0)
    s.finish_cell("m", "c", 3, param=None, status="unreachable", reason="r")
    s.finish_cell("m", "a", 6, param=1.0, status="done", images=2, seconds=1.0)  # before
    s.add_detections("m", "a", 6, [(i, det) for i in range(3)])  # extension: 3 of 4 stored
    with s.db:  # finished 60 s and 180 s apart, 180 s a cell: 120 s a cell
        for (t, e), stamp in zip((("baseline", 0), ("a", 3), ("b", 3)),
                                 ("2026-01-01T00:00:00Z", "2026-01-01T00:01:00Z",
                                  "2026-01-01T00:04:00Z"), strict=True):
            s.db.execute("UPDATE cells SET finished=? WHERE model='m' AND transform=? AND "
                         "target=?", (stamp, t, float(e)))
    m, full = sorted(sweep_status(s), key=lambda r: r.model != "m")
    assert (m.images, m.planned, m.done, m.unreachable, m.to_do) == (4, 7, 3, 1, 3)
    assert m.under_way == (("a", 6.0, 3),)
    assert m.images_to_do == 1 + 4 + 4  # a@6 needs one more; b@6 and c@6 all four
    assert m.pace_s == 120.0 and m.left_s == 360.0
    assert (full.images, full.done, full.to_do, full.pace_s) == (10, 0, 7, None)
    r = CliRunner().invoke(main, ["sweep", "--status", "--out", str(tmp_path)])
    assert r.exit_code == 0, r.output
    # one table row per model: images, done/planned, unreachable, to do (the record's fields)
    rows = {ln.split()[0]: ln.split() for ln in r.output.splitlines() if ln.strip()}
    for rec in (m, full):
        assert rows[rec.model][1:5] == [str(rec.images), f"{rec.done}/{rec.planned}",
                                       str(rec.unreachable), str(rec.to_do)], r.output
    # the printed pace and time left are the record's 120 s and 360 s
    assert rows["m"][5:7] == [f"{m.pace_s / 60:.1f}", "min"], r.output


def test_store_survives_kill_9(tmp_path) -> None:
    """A process killed with SIGKILL keeps every committed batch; the store reopens cleanly."""
    script = textwrap.dedent(f"""
        import os, signal, numpy as np
        from fidelity.coco.sweep import SweepStore
        s = SweepStore({str(tmp_path)!r})
        for i in range(5):
            s.add_detections("m", "hue", 3, [(i, np.full((2, 6), i, np.float32))])
        s.db.execute("BEGIN")
        s.db.execute("INSERT INTO detections VALUES ('m','hue',3.0,99,0,x'00')")
        os.kill(os.getpid(), signal.SIGKILL)
    """)
    proc = subprocess.run([sys.executable, "-c", script], cwd=REPO)
    assert proc.returncode == -signal.SIGKILL
    store = SweepStore(tmp_path)
    assert store.stored_images("m", "hue", 3) == {0, 1, 2, 3, 4}  # 99 was never committed
    assert store.detections("m", "hue", 3)[4][0, 0] == 4
    with pytest.raises(InputFileError, match="no sweep store"):
        SweepStore(tmp_path / "elsewhere", create=False)


def test_model_file_change_is_refused(tmp_path) -> None:
    s = SweepStore(tmp_path)
    s.register_model("m", "m.onnx", "aa" * 32, None, {})
    with pytest.raises(InvalidValueError, match="different file"):
        s.register_model("m", "m.onnx", "bb" * 32, None, {})


# ----------------------------------------------------------------------------- CI slice


@pytest.fixture(scope="module")
def coco(shared):
    return (shared / "coco/val2017", shared / "coco/annotations/instances_val2017_subset.json",
            shared / "models/yolox_nano.onnx")


@pytest.mark.shared
def test_ci_slice_sweep_resume_rescore(coco, tmp_path) -> None:
    """A few images, one model, two targets; checked against a direct second computation."""
    from fidelity.coco.dataset import reference_transform
    from fidelity.coco.detectors import Detector
    from fidelity.coco.jpeg import read_jpeg, roundtrip_jpeg
    from fidelity.coco.scoring import evaluate_detections, load_annotations
    from fidelity.coco.sweep import rescore, run_sweep
    from fidelity.prediction.calibration import calibrate_transform

    images, ann, model = coco
    store = run_sweep([ModelSpec(model, 4)], images, ann, tmp_path,
                      ["contrast-inc", "saturation-inc"], [0, 15], threads=2, log=lambda s: None)
    cells = {(c.transform, c.target): c for c in store.cells()}
    assert set(cells) == {("baseline", 0), ("contrast-inc", 15), ("saturation-inc", 15)}
    assert cells[("saturation-inc", 15)].status == "unreachable"
    assert "cannot reach" in cells[("saturation-inc", 15)].reason
    param = calibrate_transform("contrast-inc", 15).param
    assert cells[("contrast-inc", 15)].param == pytest.approx(param)

    # second method: transformed JPEG written and read back, detector, pycocotools
    gt = load_annotations(ann)
    ids = sorted(gt.getImgIds())[:4]
    det = Detector(model, threads=2)
    for transform, p in (("baseline", None), ("contrast-inc", param)):
        dets = {}
        for i in ids:
            rgb, settings = read_jpeg(images / gt.imgs[i]["file_name"])
            t = rgb if p is None else reference_transform(rgb, transform, p)
            dets[i] = det(roundtrip_jpeg(t, settings))
        direct = evaluate_detections(gt, dets, ids, method="pycocotools")  # the reference
        cell = cells[(transform, 0 if p is None else 15)]
        assert cell.map == pytest.approx(direct.map, abs=1e-9)
        assert cell.ap["person"] == pytest.approx(direct.ap["person"], abs=1e-9)
    assert cells[("contrast-inc", 15)].map < cells[("baseline", 0)].map

    # resume: nothing is redone
    before = {(c.transform, c.target): c.finished for c in store.cells()}
    time.sleep(1.1)
    again = run_sweep([ModelSpec(model, 4)], images, ann, tmp_path,
                      ["contrast-inc", "saturation-inc"], [0, 15], threads=2, log=lambda s: None)
    assert {(c.transform, c.target): c.finished for c in again.cells()} == before

    from fidelity.coco.scoring import resolve_scorer

    assert [e["scorer"] for e in again.scorers()] == [resolve_scorer("auto")]
    assert again.scorer_of(again.cells()[0]) == resolve_scorer("auto")
    # re-scoring from the stored detections needs no inference and gives the same numbers
    assert rescore(again, ann, method="pycocotools") == 2
    assert again.scorers() == [{"scorer": "pycocotools", "since": None}]
    # a store scored by pycocotools, then resumed with another scorer, says which cell had which
    again.record_scorer("faster-coco-eval")
    assert again.scorer_of(again.cells()[0]) == "pycocotools"
    later = replace(again.cells()[0], finished="2999-01-01T00:00:00Z")
    assert again.scorer_of(later) == "faster-coco-eval"
    assert again.cell("yolox_nano", "contrast-inc", 15).map == pytest.approx(
        cells[("contrast-inc", 15)].map, abs=1e-12)


@pytest.mark.shared
def test_kill_9_mid_cell_then_resume(coco, tmp_path) -> None:
    """kill -9 a running sweep mid-cell; the rerun keeps the stored images and finishes."""
    images, ann, model = coco
    script = textwrap.dedent(f"""
        from pathlib import Path
        from fidelity.coco.sweep import ModelSpec, run_sweep
        run_sweep([ModelSpec(Path({str(model)!r}), 30)], {str(images)!r}, {str(ann)!r},
                  {str(tmp_path)!r}, [], [0], threads=1, batch_commit=2, log=lambda s: None)
    """)
    proc = subprocess.Popen([sys.executable, "-c", script], cwd=REPO,
                            env={**os.environ, "OMP_NUM_THREADS": "1"})
    store = SweepStore(tmp_path)
    deadline = time.time() + 60
    n = 0
    while time.time() < deadline and proc.poll() is None:
        n = len(store.stored_images("yolox_nano", "baseline", 0))
        if n >= 4:
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    kept = store.detections("yolox_nano", "baseline", 0)
    assert 4 <= len(kept) < 30, "kill came too late to test a mid-cell resume"
    assert store.cell("yolox_nano", "baseline", 0) is None
    from fidelity.coco.sweep import run_sweep

    run_sweep([ModelSpec(model, 30)], images, ann, tmp_path, [], [0], threads=2,
              log=lambda s: None)
    done = store.cell("yolox_nano", "baseline", 0)
    assert done is not None and done.images == 30
    after = store.detections("yolox_nano", "baseline", 0)
    assert len(after) == 30
    for i, d in kept.items():
        assert np.array_equal(after[i], d)


class FakeDetector:
    """Stands in for the ONNX detector (no onnxruntime session): a person box that moves with
    the image's mean colour (so every transform changes the IoU, hence the AP), and a false
    positive."""

    def __init__(self, path: Path, *, threads: int | None = None, provider: str = "auto"):
        self.path = Path(path)

    @property
    def name(self) -> str:
        return self.path.stem

    def describe(self) -> dict[str, str]:
        return {"model": self.name}

    def __call__(self, rgb: np.ndarray) -> np.ndarray:
        dx = 12.0 * float(rgb.mean()) / 255.0
        return np.array([[8 + dx, 8, 40 + dx, 56, 0.8, 0], [30, 4, 60, 20, 0.5, 0]],
                        np.float32)

    def detect_stream(self, items, load, **_):
        """The Detector's loop over many images, one at a time."""
        for item in items:
            yield item, self(load(item))


def synthetic_coco(folder: Path, n: int = 4) -> tuple[Path, Path, Path]:
    """``n`` small JPEG photos with one person box each, their annotations and a model file."""

    from PIL import Image

    images = folder / "images"
    images.mkdir(parents=True)
    rng = np.random.default_rng(1)
    for i in range(1, n + 1):
        pixels = (rng.uniform(0, 255, (64, 64, 3)) * 0.3 + i * 40 % 180).astype(np.uint8)
        Image.fromarray(pixels).save(images / f"{i}.jpg", quality=90)
    ann = folder / "ann.json"
    ann.write_text(json.dumps({
        "images": [{"id": i, "width": 64, "height": 64, "file_name": f"{i}.jpg"}
                   for i in range(1, n + 1)],
        "annotations": [{"id": i, "image_id": i, "category_id": 1, "bbox": [8, 8, 32, 48],
                         "area": 1536, "iscrowd": 0} for i in range(1, n + 1)],
        "categories": [{"id": 1, "name": "person"}]}))
    model = folder / "fake.onnx"
    model.write_bytes(b"not a network")
    return images, ann, model


def test_two_sweeps_share_one_models_cells_fast(tmp_path, monkeypatch) -> None:
    """The fast twin of the test below: priority and reverse order at once (two threads, a
    stand-in detector, synthetic images) fill one store with every cell once, as one run does."""
    import threading

    from fidelity.coco import executor
    from fidelity.coco.sweep import run_sweep

    monkeypatch.setattr(executor, "Detector", FakeDetector)  # where the runner makes one
    images, ann, model = synthetic_coco(tmp_path / "data")
    grid = (["contrast-inc", "contrast-dec"], [0, 3, 6])  # 8-bit tables: quick to build
    logs: dict[str, list[str]] = {"priority": [], "reverse": []}
    errors: list[BaseException] = []

    def run(order: str) -> None:
        try:
            run_sweep([ModelSpec(model, 3)], images, ann, tmp_path / "two", *grid,
                      order=order, log=logs[order].append)
        except BaseException as exc:  # noqa: BLE001 - reported by the test
            errors.append(exc)

    threads = [threading.Thread(target=run, args=(o,)) for o in logs]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    assert not errors, errors
    single = run_sweep([ModelSpec(model, 3)], images, ann, tmp_path / "one", *grid,
                       log=lambda s: None)
    shared = SweepStore(tmp_path / "two")
    expect = {(c.transform, c.target): c for c in single.cells()}
    got = {(c.transform, c.target): c for c in shared.cells()}
    assert set(got) == set(expect) and len(got) == 5
    for key, cell in expect.items():
        assert got[key].images == 3 and got[key].map == pytest.approx(cell.map, abs=1e-12)
        a, b = shared.detections("fake", *key), single.detections("fake", *key)
        assert a.keys() == b.keys() and all(np.array_equal(a[i], b[i]) for i in a)
    assert len({c.map for c in got.values()}) > 1  # the transforms did change the scores
    runs = sum(" images=3 " in line for log in logs.values() for line in log)
    assert len(expect) <= runs <= len(expect) + 1, logs


@pytest.mark.shared
@pytest.mark.slow
def test_two_processes_share_one_models_cells(coco, tmp_path) -> None:
    """Priority and reverse order on one store at once: every cell once, as one process has it
    (two real processes, the real detector; fast twin above)."""
    from fidelity.coco.sweep import run_sweep

    images, ann, model = coco
    grid = (["contrast-inc", "hue"], [0, 3, 6])
    procs = [subprocess.Popen([sys.executable, "-m", "fidelity", "sweep", "--models",
                               f"{model}@5", "--images", str(images), "--annotations", str(ann),
                               "--transforms", ",".join(grid[0]), "--targets", "0,3,6",
                               "--threads", "1", "--order", order, "--out", str(tmp_path / "two")],
                              cwd=REPO, stderr=subprocess.PIPE, text=True)
             for order in ("priority", "reverse")]
    logs = [p.communicate(timeout=300)[1] for p in procs]
    assert [p.returncode for p in procs] == [0, 0], "\n---\n".join(
        "\n".join(log.splitlines()[-15:]) for log in logs)  # the tracebacks' ends, in full
    single = run_sweep([ModelSpec(model, 5)], images, ann, tmp_path / "one", *grid, threads=1,
                       log=lambda s: None)
    shared = SweepStore(tmp_path / "two")
    expect = {(c.transform, c.target): c for c in single.cells()}
    got = {(c.transform, c.target): c for c in shared.cells()}
    assert set(got) == set(expect) and len(got) == 5
    for key, cell in expect.items():
        assert got[key].images == 5
        assert got[key].map == pytest.approx(cell.map, abs=1e-12)
        a, b = shared.detections("yolox_nano", *key), single.detections("yolox_nano", *key)
        assert a.keys() == b.keys() and all(np.array_equal(a[i], b[i]) for i in a)
    # no cell was run twice except, at most, the one the two orders met on
    done = [sum(" images=5 " in line for line in log.splitlines()) for log in logs]
    # each cell line says where it stands in the run order: [k/N] over the 5 planned cells
    ks = [[int(ln.split("[")[1].split("/")[0]) for ln in log.splitlines() if "/5] yolox_nano" in ln]
          for log in logs]
    assert sum(map(len, ks)) >= 5 and all(1 <= k <= 5 for kk in ks for k in kk)
    assert all(kk == sorted(kk) for kk in ks)  # k counts in each process's own order
    assert len(expect) <= sum(done) <= len(expect) + 1, logs


# ----------------------------------------------------------------------------- command line


def test_cli_errors_are_one_line(tmp_path) -> None:
    from click.testing import CliRunner

    from fidelity.cli import main

    r = CliRunner().invoke(main, ["tables", str(tmp_path)])
    one_line_error(r, str(tmp_path))
    r = CliRunner().invoke(main, ["evaluate", "--models", str(tmp_path / "m.onnx"), "--images",
                                  str(tmp_path), "--annotations", str(tmp_path / "a.json")])
    one_line_error(r, str(tmp_path / "m.onnx"))


@pytest.mark.shared
def test_evaluate_names_missing_images_before_inference(coco, tmp_path) -> None:

    from click.testing import CliRunner

    from fidelity.cli import main

    images, ann, model = coco
    data = json.loads(ann.read_text())
    first = min(data["images"], key=lambda im: im["id"])
    folder = tmp_path / "subset"
    folder.mkdir()
    (folder / first["file_name"]).symlink_to(images / first["file_name"])
    r = CliRunner().invoke(main, ["evaluate", "--models", str(model), "--images", str(folder),
                                  "--annotations", str(ann), "--limit", "3", "--no-progress"])
    one_line_error(r, str(folder))
    assert "2 of the 3" in r.output  # the count is in the message only


@pytest.mark.shared
def test_cli_evaluate_sweep_tables(coco, tmp_path) -> None:

    from click.testing import CliRunner

    from fidelity.cli import main
    from fidelity.coco.detectors import PREPROCESSING

    images, ann, model = coco
    run = CliRunner().invoke
    r = run(main, ["evaluate", "--models", str(model), "--images", str(images), "--annotations",
                   str(ann), "--limit", "3", "--threads", "2", "--no-progress", "--json",
                   str(tmp_path / "ev.json"), "--metric", "ultralytics"])
    assert r.exit_code == 0, r.output
    ev = json.loads((tmp_path / "ev.json").read_text())
    assert ev["images"] == 3 and 0 < ev["map"] <= 1 and 0 <= ev["map50"] <= 1
    assert 0 < ev["ultralytics"]["map"] <= 1 and ev["ultralytics"]["version"] == "8.4"
    assert all(v is None or 0 <= v <= 1 for v in ev["ap"].values()) and ev["seconds"] > 0
    conv = ev["detector"]["conventions"]
    assert (conv["family"], conv["conf"], conv["iou"]) == ("yolox", 0.01, 0.65)
    assert ev["detector"]["preprocessing"] == PREPROCESSING["yolox"].describe()  # top-left
    out = tmp_path / "sw"
    r = run(main, ["sweep", "--models", f"{model}@2", "--images", str(images), "--annotations",
                   str(ann), "--transforms", "contrast-dec", "--targets", "0,24", "--out",
                   str(out), "--threads", "2"])
    assert r.exit_code == 0, r.output
    r = run(main, ["tables", str(out), "--out", str(tmp_path / "rep"), "--prediction",
                   str(tmp_path / "p.json")])
    assert r.exit_code == 0, r.output
    tj = json.loads((tmp_path / "rep" / "tables.json").read_text())["tables"]
    # a near-uniform grey image: contrast-dec is the worst case at ΔE 24
    row = {w["delta_e"]: w for w in tj["worst_case"]["yolox_nano"]}[24.0]
    assert row["worst_transform"] == "contrast-dec"
    # annotations found via the store: paired fold standard errors computed
    assert tj["standard_errors"] is True and row["dmap_points_se"] is not None
    r = run(main, ["sweep", "--models", str(model), "--images", str(images), "--annotations",
                   str(ann), "--transforms", "sharpen", "--out", str(out)])
    one_line_error(r, "sharpen")


@pytest.mark.shared
def test_raising_and_lowering_a_model_limit(coco, tmp_path) -> None:
    """model@3 then model@6: only the 3 new images are run; @2 re-scores without inference."""
    from fidelity.coco.scoring import evaluate_detections, load_annotations
    from fidelity.coco.sweep import run_sweep
    from fidelity.coco.tables.grid import cell_deltas

    images, ann, model = coco
    quiet = {"threads": 1, "log": lambda s: None}
    store = run_sweep([ModelSpec(model, 3)], images, ann, tmp_path, ["contrast-inc"], [0, 6],
                      **quiet)
    first = store.detections("yolox_nano", "contrast-inc", 6)
    assert sorted(c.images for c in store.cells()) == [3, 3]

    # a store caught mid-extension: the baseline is on 6 images, the cell still on 3
    gt = load_annotations(ann)
    ids6 = sorted(gt.getImgIds())[:6]
    cells = store.cells()
    base = replace(next(c for c in cells if c.transform == "baseline"), images=6)
    assert cell_deltas([base] + [c for c in cells if c.transform != "baseline"]) == {}

    lines: list[str] = []
    store = run_sweep([ModelSpec(model, 6)], images, ann, tmp_path, ["contrast-inc"], [0, 6],
                      threads=1, log=lines.append)
    assert sorted(c.images for c in store.cells()) == [6, 6]
    assert all("new=3 " in line for line in lines), lines
    after = store.detections("yolox_nano", "contrast-inc", 6)
    assert sorted(after) == ids6
    for i, d in first.items():  # the stored images were not run again
        assert np.array_equal(after[i], d)
    cell = store.cell("yolox_nano", "contrast-inc", 6)
    assert cell.map == pytest.approx(evaluate_detections(gt, after, ids6).map, abs=1e-12)

    lines.clear()
    store = run_sweep([ModelSpec(model, 2)], images, ann, tmp_path, ["contrast-inc"], [0, 6],
                      threads=1, log=lines.append)
    assert all("new=0 " in line for line in lines) and len(lines) == 2
    cell = store.cell("yolox_nano", "contrast-inc", 6)
    assert cell.images == 2
    assert cell.map == pytest.approx(evaluate_detections(gt, after, ids6[:2]).map, abs=1e-12)
    assert len(cell_deltas(store.cells())["yolox_nano"]) == 1


@pytest.mark.shared
def test_tables_of_a_store_caught_mid_extension(coco, tmp_path) -> None:
    """Baseline extended to 6 images, the cell still on 3: both are reported on the first 3."""
    from fidelity.coco.scoring import evaluate_detections, load_annotations
    from fidelity.coco.sweep import run_sweep
    from fidelity.coco.tables.build import build_tables
    from fidelity.coco.tables.colour import TablesResult
    from fidelity.coco.tables.grid import AlignedCount
    from fidelity.report.coco import tables_document
    from fidelity.report.html import render_markdown

    def report_markdown(tables: object) -> str:
        return render_markdown(tables_document(TablesResult(tables, (), ()), figures={}))

    def aligned_json(tables: object) -> object:  # as tables.json has it
        return TablesResult(tables, (), ()).to_json()["tables"]["aligned"]["yolox_nano"]

    images, ann, model = coco
    quiet = {"threads": 1, "log": lambda s: None}
    run_sweep([ModelSpec(model, 3)], images, ann, tmp_path, ["contrast-inc"], [0, 6], **quiet)
    store = run_sweep([ModelSpec(model, 6)], images, ann, tmp_path, ["contrast-inc"], [0],
                      **quiet)
    assert {c.transform: c.images for c in store.cells()} == {"baseline": 6,
                                                               "contrast-inc": 3}
    assert build_tables(store).cells == {}  # without annotations: left out, as before

    gt = load_annotations(ann)
    ids3 = sorted(gt.getImgIds())[:3]
    tables = build_tables(store, gt)
    assert tables.aligned == {"yolox_nano": AlignedCount(3, (3, 6), 1, False)}
    assert tables.models["yolox_nano"].images == 3

    def direct_dmap(ids: list[int]) -> float:  # pycocotools on the stored detections
        base, cell = (evaluate_detections(gt, store.detections("yolox_nano", t, e), ids,
                                          method="pycocotools").map
                      for t, e in (("baseline", 0), ("contrast-inc", 6)))
        return 100 * (base - cell)

    (row,) = tables.cells["yolox_nano"]
    assert row.dmap_points == pytest.approx(direct_dmap(ids3), abs=1e-6)
    assert not tables.worst_case["yolox_nano"][1].partial
    assert store.cell("yolox_nano", "baseline", 0).images == 6  # the store is not changed
    assert aligned_json(tables) == {"images": 3, "stored": [3, 6], "rescored": 1,
                                    "capped": False}

    # an earlier state asked for: both cells re-scored on the first 2 images
    capped = build_tables(store, gt, images={"yolox_nano": 2})
    assert capped.aligned["yolox_nano"] == AlignedCount(2, (3, 6), 2, True)
    (row,) = capped.cells["yolox_nano"]
    assert row.dmap_points == pytest.approx(direct_dmap(ids3[:2]), abs=1e-6)
    assert aligned_json(capped) == {"images": 2, "stored": [3, 6], "rescored": 2,
                                    "capped": True}
    assert capped.models["yolox_nano"].registration.limit_images == 6
    assert capped.models["yolox_nano"].images == 2
    report_markdown(capped)  # the report renders
    # a cap above what every cell has changes nothing
    assert build_tables(store, gt, images={"yolox_nano": 5}).aligned["yolox_nano"].images == 3


@pytest.mark.shared
def test_standard_errors_in_tables(coco, tmp_path) -> None:
    """The ΔmAP SE of the tables is the larger of the spread of the paired bootstrap losses and
    a direct leave-one-fold-out jackknife; a draw's score is that of the drawn images
    re-evaluated by pycocotools; draws and folds are cached."""
    from fidelity.coco.bootstrap import BOOTSTRAP_SEED, bootstrap_weights
    from fidelity.coco.scoring import coco_from_dict, evaluate_detections, load_annotations
    from fidelity.coco.sweep import run_sweep
    from fidelity.coco.tables.build import build_tables

    images, ann, model = coco
    store = run_sweep([ModelSpec(model, 12)], images, ann, tmp_path, ["contrast-inc"], [0, 12],
                      threads=2, log=lambda s: None)
    gt = load_annotations(ann)
    tables = build_tables(store, gt)
    row = tables.cells["yolox_nano"][0]
    ids = sorted(gt.getImgIds())[:12]
    base = store.draw_scores(gt, "yolox_nano", "baseline", 0, ids)
    cell = store.draw_scores(gt, "yolox_nano", "contrast-inc", 12, ids)
    assert base.images == 12 and base.seed == BOOTSTRAP_SEED and base.pairs_with(cell)
    losses = np.array([100 * (b - c) for b, c in zip(base.map, cell.map, strict=True)])
    bd = store.detections("yolox_nano", "baseline", 0)
    cd = store.detections("yolox_nano", "contrast-inc", 12)
    rest = [[i for i in ids if i not in ids[k::5]] for k in range(5)]
    jl = np.array([100 * (evaluate_detections(gt, bd, r, method="pycocotools").map
                          - evaluate_detections(gt, cd, r, method="pycocotools").map)
                   for r in rest])
    jack = float(np.sqrt(4 / 5 * np.sum((jl - jl.mean()) ** 2)))
    assert row.errors.method == "larger"
    assert row.errors.dmap_points == pytest.approx(max(np.std(losses, ddof=1), jack), abs=1e-9)
    assert row.errors.dmap_points > 0
    # draws 0-2 of the cell, re-evaluated as data sets of the drawn images
    dets = store.detections("yolox_nano", "contrast-inc", 12)
    ds = gt.dataset
    w = bootstrap_weights(12, 3, BOOTSTRAP_SEED)
    for b in range(3):
        drawn = [i for i, n in zip(ids, w[b], strict=True) for _ in range(int(n))]
        imgs, anns, d2 = [], [], {}
        for j, src in enumerate(drawn, start=1):
            imgs.append({"id": j, "width": 640, "height": 480})
            anns += [a | {"id": len(anns) + k + 1, "image_id": j} for k, a in
                     enumerate(a for a in ds["annotations"] if a["image_id"] == src)]
            d2[j] = dets.get(src, np.zeros((0, 6), np.float32))
        g2 = coco_from_dict({"images": imgs, "annotations": anns,
                             "categories": ds["categories"]})
        ref = evaluate_detections(g2, d2, list(range(1, 13)), method="pycocotools").map
        assert cell.map[b] == pytest.approx(ref, abs=2e-3)  # ties in score order aside
    worst = tables.worst_case["yolox_nano"][1]
    assert (worst.dmap_points_se, worst.dmap_relative_se) == (
        row.errors.dmap_points, row.errors.dmap_relative)
    n = store.db.execute("SELECT COUNT(*) FROM draws").fetchone()[0]
    assert n == 2  # baseline and the cell, kept for the next report
    assert store.db.execute("SELECT COUNT(*) FROM folds").fetchone()[0] == 2
    again = build_tables(store, gt).cells["yolox_nano"][0].errors
    assert again == row.errors
    assert build_tables(store).cells["yolox_nano"][0].errors is None


def test_cell_pace_of_one_run_two_runs_and_a_pause() -> None:
    assert cell_pace([0.0, 100.0], [100.0, 100.0]) is None  # fewer than 3 finishes
    # one run: a cell every 100 s
    assert cell_pace([0.0, 100.0, 200.0, 300.0], [100.0] * 4) == 100.0
    # two runs side by side, 200 s a cell each, finishing in pairs: 100 s per cell
    assert cell_pace([0.0, 2.0, 200.0, 202.0, 400.0, 402.0], [200.0] * 6) == \
        pytest.approx((2 + 198 + 2 + 198 + 2) / 5)
    # a 10-hour pause between two finishes counts as one cell's time
    assert cell_pace([0.0, 100.0, 36_100.0, 36_200.0], [100.0] * 4) == 100.0
    # unknown run times: the median gap caps
    assert cell_pace([0.0, 50.0, 100.0, 5000.0], [None] * 4) == pytest.approx(50.0)
