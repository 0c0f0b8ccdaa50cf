"""The shared results store: crash-safe provenance and the model-identity rules of each store."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fidelity.coco.scoring import CocoScore
from fidelity.coco.store import RegisteredModel, pack_detections, unpack_detections
from fidelity.coco.sweep import SweepStore
from fidelity.coco.validate.store import ValidationStore
from fidelity.core.errors import InputFileError, InvalidValueError


def test_detections_round_trip_as_float32() -> None:
    d = np.array([[1.5, 2.0, 30.25, 40.0, 0.9, 3.0]])
    np.testing.assert_array_equal(unpack_detections(pack_detections(d)), d.astype(np.float32))


@pytest.mark.parametrize("store_cls", [SweepStore, ValidationStore])
def test_meta_and_models_survive_reopening(tmp_path: Path, store_cls: type) -> None:
    s = store_cls(tmp_path)
    s.set_meta("grid", {"targets": [0, 3]})
    s.register_model("m", "m.onnx", "aa" * 32, 100, {"conf": 0.001})
    s.close()
    again = store_cls(tmp_path, create=False)
    assert again.meta() == {"grid": {"targets": [0, 3]}}
    assert again.models()["m"] == RegisteredModel("m.onnx", "aa" * 32, 100, {"conf": 0.001})
    with pytest.raises(InputFileError, match=store_cls.store_name):
        store_cls(tmp_path / "elsewhere", create=False)


def test_the_sweep_may_change_a_models_image_limit_but_not_its_file(tmp_path: Path) -> None:
    s = SweepStore(tmp_path)
    s.register_model("m", "m.onnx", "aa" * 32, 100, {})
    s.register_model("m", "m.onnx", "aa" * 32, 250, {})  # extend the run over the same model
    with pytest.raises(InvalidValueError, match="different file"):
        s.register_model("m", "m.onnx", "bb" * 32, 250, {})


def test_an_extended_sweep_keeps_the_registrations_it_replaced(tmp_path: Path) -> None:
    s = SweepStore(tmp_path)
    s.register_model("m", "m.onnx", "aa" * 32, 250, {"threads": 2, "conf": 0.001})
    s.register_model("m", "m.onnx", "aa" * 32, 250, {"threads": 2, "conf": 0.001})  # a resume
    assert "earlier" not in s.models()["m"].settings
    s.register_model("m", "m.onnx", "aa" * 32, 500, {"threads": 1, "conf": 0.001})
    s.register_model("m", "m.onnx", "aa" * 32, 1000, {"threads": 1, "conf": 0.001})
    got = s.models()["m"]
    assert got.limit_images == 1000
    assert got.settings == {"threads": 1, "conf": 0.001,
                               "earlier": [{"limit_images": 250, "threads": 2},
                                           {"limit_images": 500}]}


@pytest.mark.parametrize("store_cls", [SweepStore, ValidationStore])
def test_detections_of_other_preprocessing_are_not_mixed(tmp_path: Path,
                                                         store_cls: type) -> None:
    """A store made by a version that prepared images differently is not extended (its cells
    would mix two preprocessings); a resume with the same preprocessing is."""
    old = {"conventions": {"preprocess": "letterbox centred, pad 114, bilinear, RGB/255"}}
    new = {"conventions": {"preprocess": "long side with ceil sizes, INTER_LINEAR on uint8"}}
    s = store_cls(tmp_path)
    s.register_model("m", "m.onnx", "aa" * 32, 100, old)
    s.register_model("m", "m.onnx", "aa" * 32, 100, old | {"threads": 2})
    with pytest.raises(InvalidValueError, match="other preprocessing"):
        s.register_model("m", "m.onnx", "aa" * 32, 100, new)


def test_a_validation_keeps_one_image_set_per_model(tmp_path: Path) -> None:
    """Narrowing a model's image set would compare cameras on two sets: refused."""
    s = ValidationStore(tmp_path)
    s.register_model("m", "m.onnx", "aa" * 32, 100, {})
    with pytest.raises(InvalidValueError, match="image limit"):
        s.register_model("m", "m.onnx", "aa" * 32, 50, {})
    s.register_model("u", "u.onnx", "bb" * 32, None, {})
    with pytest.raises(InvalidValueError, match="image limit"):
        s.register_model("u", "u.onnx", "bb" * 32, 100, {})


@pytest.mark.parametrize("limit", [250, None])
def test_a_validation_extended_to_more_images_keeps_its_detections(tmp_path: Path,
                                                                   limit: int | None) -> None:
    """The first 100 images by id are a prefix of the first 250 (or of all): their detections
    stay, the model's scored cells go (to be scored over the larger set), the other model's
    cells stay, and the replaced limit is kept in the provenance."""
    s = ValidationStore(tmp_path)
    score = CocoScore(0.3, 0.5, 0.3, {"person": 0.4}, 100, 7)
    for model in ("m", "other"):
        s.register_model(model, f"{model}.onnx", model[0] * 64, 100, {})
        s.add_detections(model, "cam", [(1, np.zeros((0, 6), np.float32))])
        s.finish_cell(model, "cam", score, [], 1.0)
    s.register_model("m", "m.onnx", "m" * 64, limit, {})
    assert s.cell("m", "cam") is None
    assert s.stored_images("m", "cam") == {1}
    assert s.cell("other", "cam") is not None
    assert s.models()["m"].limit_images == limit
    assert s.models()["m"].settings["earlier"] == [{"limit_images": 100}]
    s.register_model("m", "m.onnx", "m" * 64, limit, {})  # a resume at the new limit
    assert s.stored_images("m", "cam") == {1}


def _open_together(folder: str, barrier: object, results: object) -> None:
    import traceback

    barrier.wait()  # type: ignore[attr-defined]
    try:
        store = SweepStore(folder)
        store.set_meta("opened", True)
        results.put("ok")  # type: ignore[attr-defined]
    except Exception:  # noqa: BLE001 - reported to the test
        results.put(traceback.format_exc())  # type: ignore[attr-defined]


def test_two_processes_creating_one_store_at_once(tmp_path: Path) -> None:
    """SQLite refuses the switch to WAL at once ("database is locked", no busy wait) while
    another connection creates the same file; before the store retried it, about one process
    in three failed here (two sweep processes started together on a new --out)."""
    import multiprocessing as mp

    ctx = mp.get_context("fork")
    failures = []
    for i in range(30):
        barrier, results = ctx.Barrier(2), ctx.Queue()
        procs = [ctx.Process(target=_open_together, args=(str(tmp_path / f"s{i}"), barrier,
                                                          results)) for _ in range(2)]
        for p in procs:
            p.start()
        for p in procs:
            p.join(timeout=120)
        failures += [r for r in (results.get(timeout=10) for _ in procs) if r != "ok"]
    assert not failures, failures[0]


def test_a_second_open_in_the_same_process_never_touches_the_file(tmp_path, monkeypatch):
    """Closing any descriptor of an SQLite file drops every POSIX lock the process holds on it,
    SQLite's too: with a store open, opening it again (a scoring thread's connection) must not
    read the file outside SQLite, or another process's writes corrupt it (found by two sweeps
    on one store: "database disk image is malformed" in 2 of 12 runs)."""
    import builtins

    from fidelity.coco.sweep import SweepStore

    first = SweepStore(tmp_path)
    real_open = builtins.open
    path = str(first.path)

    def guarded_open(file, *args, **kwargs):
        assert str(file) != path, "the store file was opened outside SQLite while in use"
        return real_open(file, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", guarded_open)
    second = SweepStore(tmp_path, create=False)
    second.close()
    monkeypatch.setattr(builtins, "open", real_open)
    first.close()
    third = SweepStore(tmp_path, create=False)  # no connection left: the file is checked again
    third.close()


def test_a_store_dropped_while_the_open_counter_is_busy_does_not_deadlock(tmp_path):
    """A connection dropped without close() is closed by its ``__del__``, which the garbage
    collector may run inside any allocation, also while this thread holds the lock of the
    open-store counter (found as a hang of the suite in CI: ``check_sqlite_file`` collected a
    dropped connection inside ``Path.resolve``). Run in a child process with a time limit, so
    that a regression fails instead of hanging the suite."""
    import subprocess
    import sys

    code = (
        "import gc, sys\n"
        "from pathlib import Path\n"
        "from fidelity.coco import store\n"
        "from fidelity.coco.sweep import SweepStore\n"
        "s = SweepStore(Path(sys.argv[1]))\n"
        "db = s.db\n"
        "s.db = None\n"
        "with store._OPEN_LOCK:\n"
        "    del db\n"
        "    gc.collect()\n"
        "    assert not store._OPEN_STORES, store._OPEN_STORES\n"
        "print('ok')\n")
    r = subprocess.run([sys.executable, "-c", code, str(tmp_path)], capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 0 and r.stdout.strip() == "ok", r.stderr[-2000:]


def test_an_evaluation_cache_is_kept_per_preprocessing(tmp_path) -> None:
    """evaluate's per-image cache is named by what decides the detections, the detector's
    preprocessing included: a version that prepares images differently starts its own."""
    from fidelity.coco.store import evaluation_store_dir

    def folder(pre: str | None) -> Path:
        return evaluation_store_dir("aa" * 32, "cpu", "f" * 16, tmp_path, preprocessing=pre)

    assert folder("letterbox centred, bilinear") == folder("letterbox centred, bilinear")
    assert folder("letterbox centred, bilinear") != folder("ceil sizes, INTER_LINEAR on uint8")
    assert folder(None).parent == tmp_path
