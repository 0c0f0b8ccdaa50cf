"""Long runs (issue 23): damaged or foreign stores, resumes over other inputs, runs that share a
store through claims, stale temporary files, and kill -9 at random moments."""

from __future__ import annotations

import json
import os
import random
import shutil
import signal
import sqlite3
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fidelity.cli import main
from fidelity.coco.store import Owner
from fidelity.coco.sweep import ModelSpec, SweepStore
from fidelity.coco.validate.store import ValidationStore
from fidelity.core.errors import InputFileError

# among the longest files of the suite: started first, so that a parallel run does not end on it
pytestmark = pytest.mark.early

REPO = Path(__file__).resolve().parents[2]


def _one_line_error(r, *needles: str) -> None:
    """Exit code 2 and one line ``fidelity: error: ...`` that names each of ``needles``."""
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("fidelity: error: "), r.output
    assert all(n in lines[0] for n in needles) and "Traceback" not in r.output, r.output


def _filled_store(folder: Path, rows: int = 400) -> SweepStore:
    s = SweepStore(folder)
    rng = np.random.default_rng(0)
    s.register_model("m", "m.onnx", "aa" * 32, None, {})
    s.add_detections("m", "baseline", 0, [(i, rng.uniform(0, 600, (60, 6)).astype(np.float32))
                                          for i in range(rows)])
    s.set_meta("grid", {"transforms": ["hue"], "targets": [0, 3]})
    s.db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    return s


# ----------------------------------------------------------------------- damaged stores


def _commands(folder: Path) -> list[list[str]]:
    return [["sweep", "--status", "--out", str(folder)],
            ["tables", str(folder), "--out", str(folder / "report")]]


def test_garbage_store_is_one_line_exit_2(tmp_path) -> None:
    (tmp_path / "sweep.sqlite").write_bytes(os.urandom(5000))
    for args in _commands(tmp_path):
        r = CliRunner().invoke(main, args)
        _one_line_error(r, f"{tmp_path / 'sweep.sqlite'}: ")
    from tests.coco.test_sweep import synthetic_coco

    images, ann, model = synthetic_coco(tmp_path / "data")
    r = CliRunner().invoke(main, ["sweep", "--models", str(model), "--images", str(images),
                                  "--annotations", str(ann), "--out", str(tmp_path)])
    _one_line_error(r, f"{tmp_path / 'sweep.sqlite'}: ")
    (tmp_path / "validation.sqlite").write_bytes(b"hello" * 100)
    r = CliRunner().invoke(main, ["validate", "--report-only", "--store", str(tmp_path),
                                  "--out", str(tmp_path / "v")])
    _one_line_error(r, f"{tmp_path / 'validation.sqlite'}: ")


def test_truncated_store_is_refused(tmp_path) -> None:
    s = _filled_store(tmp_path)
    s.close()
    p = tmp_path / "sweep.sqlite"
    data = p.read_bytes()
    assert len(data) > 100_000
    p.write_bytes(data[: len(data) // 2])
    for args in _commands(tmp_path):
        # the store named, and its size as found (the header's is twice that)
        _one_line_error(CliRunner().invoke(main, args), f"{p}: ", "truncated",
                        f"{len(data) // 2} bytes")


def test_damaged_page_is_reported_naming_the_store(tmp_path) -> None:
    s = _filled_store(tmp_path)
    s.close()
    p = tmp_path / "sweep.sqlite"
    data = bytearray(p.read_bytes())
    page = int.from_bytes(data[16:18], "big")
    for k in range(3, len(data) // page):  # b-tree pages past the schema: overwrite headers
        data[k * page: k * page + 8] = b"\xff" * 8
    p.write_bytes(bytes(data))
    with pytest.raises(InputFileError, match="sweep store is damaged"):
        store = SweepStore(tmp_path, create=False)
        store.detections("m", "baseline", 0)
    r = CliRunner().invoke(main, ["sweep", "--status", "--out", str(tmp_path)])
    _one_line_error(r, str(p))


def test_store_of_a_newer_format_or_another_kind(tmp_path) -> None:
    s = SweepStore(tmp_path / "a")
    s.db.execute("PRAGMA user_version=99")
    s.db.commit()
    s.close()
    r = CliRunner().invoke(main, ["sweep", "--status", "--out", str(tmp_path / "a")])
    _one_line_error(r, f"{tmp_path / 'a' / 'sweep.sqlite'}: ", "format 99")
    v = ValidationStore(tmp_path / "b")
    v.close()
    (tmp_path / "c").mkdir()
    shutil.copy(tmp_path / "b" / "validation.sqlite", tmp_path / "c" / "sweep.sqlite")
    r = CliRunner().invoke(main, ["sweep", "--status", "--out", str(tmp_path / "c")])
    _one_line_error(r, f"{tmp_path / 'c' / 'sweep.sqlite'}: ", "'cells'")


def test_a_store_from_before_the_format_number_opens(tmp_path) -> None:
    """Stores written before user_version and the new tables existed are format 1."""
    db = sqlite3.connect(tmp_path / "sweep.sqlite")
    from fidelity.coco import store as store_mod
    from fidelity.coco import sweep as sweep_mod

    db.executescript(store_mod._COMMON_SCHEMA.split("CREATE TABLE IF NOT EXISTS images")[0]
                     + sweep_mod._SCHEMA)
    db.execute("INSERT INTO meta VALUES ('grid', '{}')")
    db.commit()
    db.close()
    s = SweepStore(tmp_path, create=False)  # a reader adds the new tables, not the number
    assert s.meta() == {"grid": {}} and s.claims() == []
    assert s.db.execute("PRAGMA user_version").fetchone()[0] == 0
    s.close()
    s = SweepStore(tmp_path)  # a run writes the format number
    assert s.db.execute("PRAGMA user_version").fetchone()[0] == 1
    assert s.claims() == []


# ----------------------------------------------------------------------- inputs on resume


def _quiet(**kw):
    return {"log": lambda s: None} | kw


def test_resume_over_other_images_or_annotations_is_refused(tmp_path, monkeypatch) -> None:
    from fidelity.coco import executor
    from fidelity.coco.sweep import run_sweep
    from tests.coco.test_sweep import FakeDetector, synthetic_coco

    monkeypatch.setattr(executor, "Detector", FakeDetector)  # where the runner makes one
    images, ann, model = synthetic_coco(tmp_path / "data")
    grid = (["contrast-inc"], [0, 3])
    run_sweep([ModelSpec(model, 3)], images, ann, tmp_path / "out", *grid, **_quiet())
    # the same file names in another folder, one image different
    other = tmp_path / "other"
    shutil.copytree(images, other)
    from PIL import Image

    Image.fromarray(np.zeros((64, 64, 3), np.uint8)).save(other / "2.jpg", quality=90)
    with pytest.raises(InputFileError, match=r"differ from the ones this store was run on "
                                             r"\(1 of 3, e\.g\. 2\.jpg"):
        run_sweep([ModelSpec(model, 3)], other, ann, tmp_path / "out", *grid, **_quiet())
    r = CliRunner().invoke(main, ["sweep", "--models", f"{model}@3", "--images", str(other),
                                  "--annotations", str(ann), "--transforms", "contrast-inc",
                                  "--targets", "0,3", "--out", str(tmp_path / "out")])
    _one_line_error(r, "2.jpg")
    # an identical copy is fine (content, not paths or times, identify the images)
    same = tmp_path / "same"
    shutil.copytree(images, same)
    os.utime(same / "1.jpg", (1, 1))
    run_sweep([ModelSpec(model, 3)], same, ann, tmp_path / "out", *grid, **_quiet())
    # the 4th image is new to the store: recorded when the limit is raised
    run_sweep([ModelSpec(model, 4)], images, ann, tmp_path / "out", *grid, **_quiet())
    assert SweepStore(tmp_path / "out").db.execute(
        "SELECT COUNT(*) FROM images").fetchone()[0] == 4
    # other annotations: refused, except for a re-scoring with them
    data = json.loads(ann.read_text())
    data["annotations"][0]["bbox"] = [0, 0, 10, 10]
    ann2 = tmp_path / "ann2.json"
    ann2.write_text(json.dumps(data))
    with pytest.raises(InputFileError, match="annotations .* differ from the ones"):
        run_sweep([ModelSpec(model, 4)], images, ann2, tmp_path / "out", *grid, **_quiet())
    r = CliRunner().invoke(main, ["sweep", "--rescore", "--annotations", str(ann2), "--out",
                                  str(tmp_path / "out")])
    assert r.exit_code == 0, r.output
    run_sweep([ModelSpec(model, 4)], images, ann2, tmp_path / "out", *grid, **_quiet())


def test_models_empty_is_an_error(tmp_path) -> None:
    r = CliRunner().invoke(main, ["sweep", "--models", "", "--images", str(tmp_path),
                                  "--annotations", str(tmp_path / "a.json"), "--out",
                                  str(tmp_path / "o")])
    _one_line_error(r, "--models")


# ----------------------------------------------------------------------- claims


def test_claims_live_stale_and_dead_owners(tmp_path) -> None:
    s = SweepStore(tmp_path)
    a = Owner("a", "elsewhere", 1, 0.0, {"executor": "ray", "workers": 4})
    b = Owner("b", "elsewhere", 2, 0.0)
    s.register_owner(a, now=100.0)
    s.register_owner(b, now=100.0)
    cell = ("m", "hue", 3.0)
    assert s.claim(cell, "a", now=100.0, stale_s=60)
    assert not s.claim(cell, "b", now=150.0, stale_s=60)  # a is live
    s.beat("a", now=150.0)
    assert not s.claim(cell, "b", now=200.0, stale_s=60)
    assert [(c.cell, c.owner.id, c.owner.info) for c in s.claims()] == \
        [(cell, "a", {"executor": "ray", "workers": 4})]
    assert s.claim(cell, "b", now=211.0, stale_s=60)  # a silent for 61 s: taken over
    assert not s.claim(cell, "a", now=212.0, stale_s=60)
    s.release(cell, "b")
    assert s.claim(cell, "a", now=213.0, stale_s=60)
    # an owner on this host whose process has ended loses its claims at once
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    import socket

    s.register_owner(Owner("dead", socket.gethostname(), gone.pid, 0.0), now=300.0)
    s.claim(("m", "hue", 6.0), "dead", now=300.0)
    assert s.claim(("m", "hue", 6.0), "a", now=301.0, stale_s=60)
    s.retire("a")
    assert s.claims() == []


class _Sim:
    """A simulated run on a store: claims cells in order, stores one image per step."""

    def __init__(self, store: SweepStore, name: str, now: float) -> None:
        self.store = store
        self.owner = Owner(name, "sim-host", 0, now)
        store.register_owner(self.owner, now)
        self.cell: tuple | None = None
        self.alive = True


CELLS = [("m", "hue", float(e)) for e in (1, 2, 3, 4)]
IMAGES_PER_CELL = 3
STALE = 60.0


def _value(cell: tuple, image: int) -> np.ndarray:
    return np.full((1, 6), cell[2] * 10 + image, np.float32)


def _step(sim: _Sim, now: float, log: list) -> None:
    s = sim.store
    if sim.cell is None:
        for cell in CELLS:
            if s.cell(*cell) is None and s.claim(cell, sim.owner.id, now=now, stale_s=STALE):
                sim.cell = cell
                break
        return
    cell = sim.cell
    holder = s.db.execute("SELECT owner FROM leases WHERE cell=?",
                          (json.dumps(list(cell)),)).fetchone()
    log.append(("work", cell, sim.owner.id, holder[0] if holder else None))
    have = s.stored_images(*cell)
    missing = [i for i in range(IMAGES_PER_CELL) if i not in have]
    if missing:
        s.add_detections(*cell, [(missing[0], _value(cell, missing[0]))])
        return
    if s.cell(*cell) is None:
        s.finish_cell(*cell, param=1.0, status="done", images=IMAGES_PER_CELL)
        log.append(("finish", cell, sim.owner.id))
    s.release(cell, sim.owner.id)
    sim.cell = None


@settings(max_examples=40, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.tuples(st.sampled_from([0, 1]),
                          st.sampled_from(["step", "step", "step", "crash", "restart",
                                           "tick", "tick-long"])),
                min_size=5, max_size=60))
def test_two_runs_never_lose_or_duplicate_a_cell(tmp_path_factory, actions) -> None:
    """Random interleavings of claims, heartbeats (every tick, for live runs: the heartbeat
    thread), stored images, crashes (claims left behind) and restarts of two runs on one
    store: a run works only on cells it holds, no cell is finished twice, and once both run to
    the end every cell is finished with every image, each stored once with its value."""
    store = SweepStore(tmp_path_factory.mktemp("sim"))
    store.db.execute("PRAGMA synchronous=OFF")
    now = 1000.0
    sims = [_Sim(store, "p0-0", now), _Sim(store, "p1-0", now)]
    restarts = [0, 0]
    log: list = []
    for who, op in actions:
        sim = sims[who]
        if op == "step" and sim.alive:
            _step(sim, now, log)
        elif op == "crash":
            sim.alive = False
        elif op == "restart" and not sim.alive:
            restarts[who] += 1
            sims[who] = _Sim(store, f"p{who}-{restarts[who]}", now)
        elif op.startswith("tick"):
            now += STALE + 1 if op == "tick-long" else 5.0
            for x in sims:
                if x.alive:
                    store.beat(x.owner.id, now)
    for i, sim in enumerate(sims):  # both run to the end (crashed ones are restarted)
        if not sim.alive:
            sims[i] = _Sim(store, f"p{i}-end", now)
    for _ in range(200):
        if all(store.cell(*c) is not None for c in CELLS):
            break
        now += 5.0
        for sim in sims:
            store.beat(sim.owner.id, now)
            _step(sim, now, log)
        if _ > 100:  # claims of crashed runs go stale
            now += STALE
    works = [e for e in log if e[0] == "work"]
    assert all(owner == holder for _, _, owner, holder in works), "worked on a cell not held"
    finishes = [e[1] for e in log if e[0] == "finish"]
    assert sorted(finishes) == sorted(CELLS), "a cell lost or finished twice"
    for cell in CELLS:
        dets = store.detections(*cell)
        assert sorted(dets) == list(range(IMAGES_PER_CELL))
        assert all(np.array_equal(d, _value(cell, i)) for i, d in dets.items())
    store.close()


# ----------------------------------------------------------------------- temporary files


def test_stale_temporary_files_do_not_survive_a_dataset_resume(tmp_path) -> None:
    from PIL import Image

    from fidelity.coco.dataset import list_images, write_transformed_dataset

    src = tmp_path / "src"
    src.mkdir()
    for i in range(2):
        Image.fromarray(np.full((16, 16, 3), 60 * i, np.uint8)).save(src / f"{i}.jpg")
    out = tmp_path / "out"
    sub = out / "baseline"
    sub.mkdir(parents=True)
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = sub / f".0.jpg.{dead.pid}.x1y2.tmp.jpg"  # as a killed writer leaves it
    stale.write_bytes(b"")
    live = sub / f".1.jpg.{os.getpid()}.x1y2.tmp.jpg"  # being written by a live process
    live.write_bytes(b"")
    write_transformed_dataset(list_images(src), out, "contrast-inc", 0, progress=False)
    assert not stale.exists() and live.exists()
    assert [p.name for p in list_images(sub)] == ["0.jpg", "1.jpg"]  # dot files are not images


# ----------------------------------------------------------------------- kill -9, shared data


@pytest.fixture(scope="module")
def coco(shared):
    return (shared / "coco/val2017", shared / "coco/annotations/instances_val2017_subset.json",
            shared / "models/yolox_nano.onnx")


@pytest.mark.shared
def test_kill_9_at_random_moments_then_resume_equals_an_uninterrupted_run(coco, tmp_path):
    """Four kills at random moments of the work (each after something new was stored), then
    a resume to the end: the store equals an uninterrupted run's, cell by cell, and every
    detection kept across the kills is unchanged."""
    from fidelity.coco.sweep import run_sweep

    images, ann, model = coco
    grid = (["contrast-inc"], [0, 3, 6])
    n = 24  # enough work that each run is still going when it is killed
    script = textwrap.dedent(f"""
        from pathlib import Path
        from fidelity.coco.sweep import ModelSpec, run_sweep
        run_sweep([ModelSpec(Path({str(model)!r}), {n})], {str(images)!r}, {str(ann)!r},
                  {str(tmp_path / "killed")!r}, {grid[0]!r}, {grid[1]!r}, threads=1,
                  batch_commit=2, log=lambda s: None)
    """)
    rng = random.Random(23)

    def stored() -> int:
        p = tmp_path / "killed" / "sweep.sqlite"
        if not p.is_file():
            return 0
        with sqlite3.connect(p) as db:
            try:
                return int(db.execute("SELECT COUNT(*) FROM detections").fetchone()[0])
            except sqlite3.OperationalError:
                return 0

    kills = 0
    kept: dict = {}
    for _ in range(4):
        before = stored()
        proc = subprocess.Popen([sys.executable, "-c", script], cwd=REPO,
                                env={**os.environ, "OMP_NUM_THREADS": "1"})
        deadline = time.time() + 60
        while time.time() < deadline and proc.poll() is None and stored() <= before:
            time.sleep(0.02)
        time.sleep(rng.uniform(0.0, 0.4))
        if proc.poll() is None:
            proc.send_signal(signal.SIGKILL)
            kills += 1
        proc.wait()
        s = SweepStore(tmp_path / "killed")
        for c in [("yolox_nano", "baseline", 0.0), ("yolox_nano", "contrast-inc", 3.0),
                  ("yolox_nano", "contrast-inc", 6.0)]:
            for i, d in s.detections(*c).items():
                if (c, i) in kept:
                    assert np.array_equal(kept[(c, i)], d)
                kept[(c, i)] = d
        s.close()
    assert kills >= 2, "the runs ended before they could be killed"
    resumed = run_sweep([ModelSpec(model, n)], images, ann, tmp_path / "killed", *grid,
                        threads=1, **_quiet())
    whole = run_sweep([ModelSpec(model, n)], images, ann, tmp_path / "whole", *grid, threads=1,
                      **_quiet())
    a = {(c.transform, c.target): c for c in whole.cells()}
    b = {(c.transform, c.target): c for c in resumed.cells()}
    assert a.keys() == b.keys() and len(a) == 3
    for key, c in a.items():
        assert (c.map, c.map50, c.map75, c.ap, c.images) == \
            (b[key].map, b[key].map50, b[key].map75, b[key].ap, b[key].images)
        x, y = whole.detections("yolox_nano", *key), resumed.detections("yolox_nano", *key)
        assert x.keys() == y.keys() and all(np.array_equal(x[i], y[i]) for i in x)
    for (c, i), d in kept.items():
        assert np.array_equal(resumed.detections(*c)[i], d)
    assert resumed.claims() == []
    assert not [p for p in (tmp_path / "killed").iterdir() if ".tmp" in p.name]


@pytest.mark.shared
def test_evaluate_resumes_after_kill_9_and_equals_a_direct_run(coco, tmp_path) -> None:
    """evaluate killed with SIGKILL after some images, then run again: it computes only the
    rest (the store in the cache kept the others) and its scores equal a direct computation
    (the detector on each JPEG, pycocotools)."""
    from fidelity.coco.detectors import Detector
    from fidelity.coco.jpeg import read_jpeg
    from fidelity.coco.scoring import evaluate_detections, load_annotations

    images, ann, model = coco
    n = 60  # the local executor commits every 25 images
    env = {**os.environ, "FIDELITY_CACHE": str(tmp_path / "cache"), "OMP_NUM_THREADS": "1"}
    args = [sys.executable, "-m", "fidelity", "evaluate", "--models", str(model), "--images",
            str(images), "--annotations", str(ann), "--limit", str(n), "--threads", "1",
            "--no-progress", "--scorer", "pycocotools", "--json", str(tmp_path / "e.json")]

    def stored() -> int:
        found = list((tmp_path / "cache" / "evaluate").glob("*/evaluation.sqlite"))
        if not found:
            return 0
        with sqlite3.connect(found[0]) as db:
            try:
                return int(db.execute("SELECT COUNT(*) FROM detections").fetchone()[0])
            except sqlite3.OperationalError:
                return 0

    proc = subprocess.Popen(args, cwd=REPO, env=env, stdout=subprocess.PIPE, text=True)
    deadline = time.time() + 60
    while time.time() < deadline and proc.poll() is None and stored() < 1:
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)
    proc.communicate()
    kept = stored()
    assert 0 < kept < n, "the kill came too late to test a resume"
    r = subprocess.run(args, cwd=REPO, env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    got = json.loads((tmp_path / "e.json").read_text())
    assert got["images"] == n and got["computed"] == n - kept  # the rest came from the store
    gt = load_annotations(ann)
    ids = sorted(gt.getImgIds())[:n]
    det = Detector(model, threads=1)
    direct = evaluate_detections(
        gt, {i: det(read_jpeg(images / gt.imgs[i]["file_name"])[0]) for i in ids}, ids,
        method="pycocotools")
    assert got["map"] == pytest.approx(direct.map, abs=1e-12)
    assert got["ap"] == pytest.approx(direct.ap, abs=1e-12)
    assert not [p for p in tmp_path.iterdir() if ".tmp" in p.name]


def test_status_names_the_run_that_holds_a_cell(tmp_path) -> None:
    """sweep --status while a run works: per claimed cell its stored images, the run's host,
    process, executor and workers, and its last heartbeat."""
    import socket

    s = SweepStore(tmp_path)
    s.set_meta("grid", {"transforms": ["hue"], "targets": [0, 3]})
    s.set_meta("data", {"image_count": 10})
    s.register_model("m", "m.onnx", "aa" * 32, None, {})
    owner = Owner("run1", socket.gethostname(), os.getpid(), time.time(),
                  {"executor": "ray", "workers": 2})
    s.register_owner(owner)
    assert s.claim(("m", "hue", 3.0), "run1")
    s.add_detections("m", "hue", 3, [(i, np.zeros((0, 6), np.float32)) for i in range(4)])
    from fidelity.coco.sweep import sweep_status

    (st,) = sweep_status(s)
    assert st.images == 10 and st.under_way == (("hue", 3.0, 4),)
    (claim,) = st.claims
    assert st.stored == (4,) and claim.cell[1:] == ("hue", 3.0)
    assert (claim.owner.host, claim.owner.pid) == (socket.gethostname(), os.getpid())
    assert claim.owner.info == {"executor": "ray", "workers": 2}
    assert 0 <= time.time() - claim.heartbeat < 2
    r = CliRunner().invoke(main, ["sweep", "--status", "--out", str(tmp_path)])
    assert r.exit_code == 0, r.output
    # the printed status names the run that holds the cell: its host and process
    (line,) = [ln for ln in r.output.splitlines() if f"pid {os.getpid()}" in ln]
    assert socket.gethostname() in line
