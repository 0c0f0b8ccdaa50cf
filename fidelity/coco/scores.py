"""A sweep's scores file: its finished cells without their detections, to carry a sweep to
another machine, resume it there and report it.

A sweep store holds every image's raw detections (about 3.6 MB a cell of 1000 images, 470 MB
a detector): too much to move with the results (a scores file: 7 kB a cell gzipped). What the report (``fidelity tables``) needs of
a finished cell scored on its model's common image count is small: its scores (mAP, mAP50,
mAP75, per-class AP), its per-fold scores and its bootstrap draws' scores (the standard
errors; :meth:`fidelity.coco.sweep.SweepStore.fold_scores`, ``draw_scores``). The scores file
holds those for every finished cell, with the store's provenance (``meta``), its registered
models and its recorded images, and per cell a SHA-256 of its detections, so that a report
built from it names what it was computed from.

:func:`export_scores` writes it from a store (computing the fold and draw scores a cell does
not have yet, and keeping them in the store); :func:`import_scores` makes a new store hold the
same cells, which a sweep then resumes (its finished cells are skipped) and ``tables`` reports.
An imported cell has no detections: anything that needs them (``--rescore``, re-scoring it on
other images, ``tables --explain``) is an input error naming the cell and the file it came
from (:meth:`fidelity.coco.sweep.SweepStore.detections`).

Format (JSON; gzip-compressed when the file name ends in ``.gz``)::

    {"format": "fidelity-sweep-scores", "version": 1, "fidelity": "<version>",
     "exported": "<UTC ISO 8601>", "meta": {...}, "models": {name: RegisteredModel},
     "images": [[image_id, file_name, size, sha256], ...],
     "cells": [{"model", "transform", "target", "param", "status", "reason", "images", "map",
                "map50", "map75", "ap", "seconds", "finished", "detections_sha256",
                "folds": [FoldScore, ...], "draws": Draws}, ...]}
"""

from __future__ import annotations

import gzip
import hashlib
import json
import os
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fidelity.coco.store import RegisteredModel, unpack_detections
from fidelity.coco.sweep import SweepStore
from fidelity.errors import InputFileError
from fidelity.fileio import atomic_output, display_path, file_sha256

#: The ``format`` of a scores file and the newest ``version`` this code reads and writes.
SCORES_FORMAT = "fidelity-sweep-scores"
SCORES_VERSION = 1

_CELL_FIELDS = ("model", "transform", "target", "param", "status", "reason", "images", "map",
                "map50", "map75", "ap", "seconds", "finished")


@dataclass(frozen=True)
class ScoresTransfer:
    """What an export or import moved: the file, its SHA-256, the cells (done and
    unreachable) and per model how many."""

    path: Path
    sha256: str
    done: int
    unreachable: int
    models: dict[str, int]


def detections_digest(store: SweepStore, model: str, transform: str, target: float) -> str:
    """SHA-256 of a cell's stored detections: per image in ascending id, its id and count as
    two little-endian int64 and its ``(n, 6)`` float32 detections' bytes."""
    import numpy as np

    h = hashlib.sha256()
    rows = store.db.execute("SELECT image_id, dets FROM detections WHERE model=? AND "
                            "transform=? AND target=? ORDER BY image_id",
                            (model, transform, float(target)))
    for image_id, blob in rows:
        d = np.ascontiguousarray(unpack_detections(blob), dtype="<f4")
        h.update(np.array([image_id, len(d)], dtype="<i8").tobytes())
        h.update(d.tobytes())
    return h.hexdigest()


def export_scores(store: SweepStore, coco: Any, path: str | os.PathLike[str],
                  method: str = "auto") -> ScoresTransfer:
    """Write ``store``'s finished cells to the scores file ``path`` (atomically).

    Each done cell's fold and draw scores are those the report uses: on the first ``images``
    image ids of ``coco`` (the cell's own count), computed from the stored detections where the
    store has not kept them yet (``method``: the fold scores' COCO scorer). An imported cell
    keeps its recorded detections digest.
    """
    ids_all = sorted(coco.getImgIds())
    imported = store.imported()
    cells: list[dict[str, Any]] = []
    for c in store.cells():
        row: dict[str, Any] = {k: getattr(c, k) for k in _CELL_FIELDS}
        if c.done:
            ids = ids_all[: int(c.images or 0)]
            key = (c.model, c.transform, float(c.target))
            row["detections_sha256"] = (imported[key]["detections_sha256"] if key in imported
                                        else detections_digest(store, *key))
            row["folds"] = [f.to_json() for f in
                            store.fold_scores(coco, c.model, c.transform, c.target, ids, method)]
            row["draws"] = store.draw_scores(coco, c.model, c.transform, c.target,
                                             ids).to_json()
        cells.append(row)
    images = [list(r) for r in store.db.execute(
        "SELECT image_id, file_name, size, sha256 FROM images ORDER BY image_id")]
    doc = {"format": SCORES_FORMAT, "version": SCORES_VERSION,
           "fidelity": _version(),
           "exported": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
           "meta": store.meta(), "models": {m: r.to_json() for m, r in store.models().items()},
           "images": images, "cells": cells}
    text = json.dumps(doc, allow_nan=False, separators=(",", ":")).encode()
    target = Path(path)
    with atomic_output(target, protect=[store.path]) as tmp:
        tmp.write_bytes(gzip.compress(text, mtime=0) if target.suffix == ".gz" else text)
    return _transfer(target, cells)


def _version() -> str:
    from fidelity.version import __version__

    return __version__


def _transfer(path: Path, cells: list[dict[str, Any]], sha256: str | None = None
              ) -> ScoresTransfer:
    models: dict[str, int] = {}
    for c in cells:
        models[c["model"]] = models.get(c["model"], 0) + 1
    done = sum(c["status"] == "done" for c in cells)
    return ScoresTransfer(path, sha256 or file_sha256(path), done, len(cells) - done, models)


def read_scores(path: str | os.PathLike[str]) -> dict[str, Any]:
    """A scores file's content, checked: its format and version, and every done cell with
    its scores, folds and draws. Raises :class:`~fidelity.errors.InputFileError` naming the
    file and the problem."""
    p = Path(path)
    where = display_path(p)
    try:
        raw = p.read_bytes()
        if raw[:2] == b"\x1f\x8b":
            raw = gzip.decompress(raw)
        doc = json.loads(raw)
    except FileNotFoundError:
        raise InputFileError(f"{where}: no such file") from None
    except (OSError, EOFError, ValueError) as exc:
        raise InputFileError(f"{where}: not a sweep scores file ({exc})") from None
    if not isinstance(doc, dict) or doc.get("format") != SCORES_FORMAT:
        raise InputFileError(f"{where}: not a sweep scores file (no \"format\": "
                             f"\"{SCORES_FORMAT}\")")
    version = doc.get("version")
    if not isinstance(version, int) or version > SCORES_VERSION:
        raise InputFileError(f"{where}: sweep scores file of version {version}, written by a "
                             f"newer fidelity (this one reads version {SCORES_VERSION})")
    for key, kind in (("meta", dict), ("models", dict), ("images", list), ("cells", list)):
        if not isinstance(doc.get(key), kind):
            raise InputFileError(f"{where}: {key!r} is missing or not a {kind.__name__}")
    for i, c in enumerate(doc["cells"]):
        missing = [k for k in _CELL_FIELDS if not isinstance(c, dict) or k not in c]
        if not missing and c["status"] == "done":
            missing = [k for k in ("map", "ap", "images", "folds", "draws",
                                   "detections_sha256") if c.get(k) is None]
        if missing:
            raise InputFileError(f"{where}: cell {i + 1} has no {missing[0]!r}")
        if c["model"] not in doc["models"]:
            raise InputFileError(f"{where}: cell {i + 1}: model {c['model']!r} is not among "
                                 "the file's models")
    return doc


def import_scores(store: SweepStore, path: str | os.PathLike[str]) -> ScoresTransfer:
    """Make ``store`` (a new store: it holds no finished cell) hold the finished cells of the
    scores file ``path``, with its provenance, models, images and cached fold and draw scores,
    in one transaction; ``meta["imported"]`` and the ``imported`` table name the file (by
    name and SHA-256) and each cell's detections digest."""
    from fidelity.coco.bootstrap import Draws
    from fidelity.coco.scoring import FoldScore

    doc = read_scores(path)
    p = Path(path)
    have = store.cells()
    if have:
        raise InputFileError(f"{store.path}: holds {len(have)} finished cells; import a scores "
                             "file into a new store (--out a new folder)")
    sha256 = file_sha256(p)
    source = {"file": p.name, "sha256": sha256, "exported": doc.get("exported"),
              "fidelity": doc.get("fidelity"), "cells": len(doc["cells"])}
    meta: Mapping[str, Any] = doc["meta"]
    db = store.db
    try:
        with db:
            for name, value in meta.items():
                if name not in ("last_run", "imported"):
                    db.execute("INSERT OR REPLACE INTO meta VALUES (?, ?)",
                               (name, json.dumps(value)))
            db.execute("INSERT OR REPLACE INTO meta VALUES (?, ?)",
                       ("imported", json.dumps([*(meta.get("imported") or []), source])))
            for m, r in doc["models"].items():
                reg = RegisteredModel.from_json(r)
                db.execute("INSERT OR REPLACE INTO models VALUES (?, ?, ?, ?, ?)",
                           (m, reg.file, reg.sha256, reg.limit_images, json.dumps(reg.settings)))
            db.executemany("INSERT OR REPLACE INTO images VALUES (?, ?, ?, ?)",
                           [(int(i), str(f), int(s), str(h)) for i, f, s, h in doc["images"]])
            for c in doc["cells"]:
                key = (c["model"], c["transform"], float(c["target"]))
                db.execute("INSERT INTO cells VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?)",
                           (*key, c["param"], c["status"], c["reason"], c["images"], c["map"],
                            c["map50"], c["map75"],
                            None if c["ap"] is None else json.dumps(c["ap"]), c["seconds"],
                            c["finished"]))
                if c["status"] != "done":
                    continue
                folds = [FoldScore.from_json(f).to_json() for f in c["folds"]]
                draws = Draws.from_json(c["draws"]).to_json()
                db.execute("INSERT INTO folds VALUES (?, ?, ?, ?, ?)",
                           (*key, int(c["images"]), json.dumps(folds)))
                db.execute("INSERT INTO draws VALUES (?, ?, ?, ?, ?)",
                           (*key, int(c["images"]), json.dumps(draws)))
                db.execute("INSERT INTO imported VALUES (?, ?, ?, ?)",
                           (*key, json.dumps(source | {
                               "detections_sha256": c["detections_sha256"]})))
    except (KeyError, TypeError, ValueError) as exc:
        raise InputFileError(f"{display_path(p)}: a cell is not as a scores file holds it "
                             f"({type(exc).__name__}: {exc})") from None
    return _transfer(p, doc["cells"], sha256)


__all__ = ["SCORES_FORMAT", "SCORES_VERSION", "ScoresTransfer",
           "detections_digest", "export_scores", "import_scores", "read_scores"]
