"""The crash-safe store of a validation run: cells of detector × camera, with their scores.

Store (``<store>/validation.sqlite``, WAL, ``synchronous=FULL``): raw detections per image,
committed every few images, finished cells (COCO scores, per-fold scores and the image
bootstrap's draws, for standard errors), per-camera records (:class:`ValidationStore.case`:
colour's :class:`~fidelity.coco.validate.camera.CameraRecord`) and provenance. A rerun
resumes; a camera whose file, illuminant or emulation method changed is an error (use a new
store). The default store is outside the repository: ``$FIDELITY_CACHE/validation`` or
``~/.cache/fidelity/validation`` (:func:`default_store`). :class:`ValidationCells` is the
store as :func:`fidelity.coco.executor.run_cells` sees it.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fidelity.coco.bootstrap import Draws, draw_scores
from fidelity.coco.scoring import (
    FOLDS,  # interleaved image folds for standard errors
    FoldScore,
    evaluate_detections,
    score_folds,
)
from fidelity.coco.store import ResultsStore, pack_detections, unpack_detections
from fidelity.coco.validate.camera import CameraRecord
from fidelity.core.record import record

if TYPE_CHECKING:
    from fidelity.coco.bootstrap import Draws
    from fidelity.coco.executor import CellWork
    from fidelity.coco.scoring import CocoScore, FoldScore
    from fidelity.coco.store import ThreadStores


STORE_NAME = "validation.sqlite"


def default_store() -> Path:
    """``$FIDELITY_CACHE/validation`` or ``~/.cache/fidelity/validation``."""
    base = os.environ.get("FIDELITY_CACHE")
    return (Path(base) if base else Path.home() / ".cache" / "fidelity") / "validation"


@record
class ValidationCell:
    """A finished (model, camera) cell of the validation store: COCO scores on ``images``
    images (fractions; ``ap`` per class name, None without ground truth), per-fold scores and
    the scores on the image bootstrap's draws (``draws``; None until scored,
    :meth:`ValidationStore.score_draws`) for standard errors, its run time and finish time
    (UTC, ISO 8601)."""

    model: str
    camera: str
    images: int
    map: float
    map50: float
    ap: dict[str, float | None]
    folds: tuple[FoldScore, ...]
    seconds: float
    finished: str
    draws: Draws | None = None

    def to_json(self) -> dict[str, Any]:
        """The cell as ``validation.json`` holds a baseline (the store's columns; the draws are
        the store's alone)."""
        return {"model": self.model, "camera": self.camera, "images": self.images,
                "map": self.map, "map50": self.map50, "ap": self.ap,
                "folds": [f.to_json() for f in self.folds], "seconds": self.seconds,
                "finished": self.finished}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ValidationCell:
        """Inverse of :meth:`to_json`."""
        return cls(d["model"], d["camera"], int(d["images"]), d["map"], d["map50"],
                   dict(d.get("ap") or {}), tuple(FoldScore.from_json(f) for f in d["folds"]),
                   d["seconds"], d["finished"],
                   Draws.from_json(d["draws"]) if d.get("draws") else None)


_SCHEMA = """
CREATE TABLE IF NOT EXISTS cases (camera TEXT PRIMARY KEY, key TEXT NOT NULL, info TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS cells (
    model TEXT NOT NULL, camera TEXT NOT NULL, images INTEGER, map REAL, map50 REAL,
    ap TEXT, folds TEXT, seconds REAL, finished TEXT, PRIMARY KEY (model, camera));
CREATE TABLE IF NOT EXISTS detections (
    model TEXT NOT NULL, camera TEXT NOT NULL, image_id INTEGER NOT NULL, n INTEGER NOT NULL,
    dets BLOB NOT NULL, PRIMARY KEY (model, camera, image_id));
CREATE TABLE IF NOT EXISTS draws (
    model TEXT NOT NULL, camera TEXT NOT NULL, images INTEGER NOT NULL, draws TEXT NOT NULL,
    PRIMARY KEY (model, camera));
CREATE TABLE IF NOT EXISTS imported (cell TEXT PRIMARY KEY, source TEXT NOT NULL);
"""


def extends_limit(stored: int | None, limit: int | None) -> bool:
    """Whether image limit ``limit`` (None: every image) covers a run made at ``stored``:
    the first ``stored`` images by id are then a prefix of the new run's."""
    return stored is not None and (limit is None or limit > stored)


class ValidationStore(ResultsStore):
    """The crash-safe SQLite store of a validation run (module docstring)."""

    store_name = STORE_NAME
    kind = "validation"
    core_tables = ("meta", "models", "cases", "cells", "detections")
    schema = _SCHEMA
    cell_columns = ("model", "camera")

    def _model_conflict(self, stored_sha256: str, stored_limit: int | None, sha256: str,
                        limit: int | None) -> str | None:
        """A validation compares cameras on one image set: the image limit must match, or
        grow (:func:`extends_limit`: the first N images by id are a prefix of the larger
        set, so the stored detections stay valid and :meth:`register_model` drops the
        model's scored cells to be scored again over the larger set)."""
        if stored_sha256 != sha256 or (stored_limit != limit
                                        and not extends_limit(stored_limit, limit)):
            return "was run from another file or image limit; use a new --store"
        return None

    def register_model(self, model: str, file: str, sha256: str, limit: int | None,
                       settings: dict[str, Any]) -> None:
        """Record a model (:meth:`ResultsStore.register_model`); one registered again with a
        larger image limit keeps its detections and loses its scored cells and draws, which
        the run then scores again over the larger image set."""
        row = self.db.execute("SELECT limit_images FROM models WHERE model=?",
                              (model,)).fetchone()
        super().register_model(model, file, sha256, limit, settings)
        if row and row[0] != limit:  # registered: the limit grew (_model_conflict)
            with self.db:
                self.db.execute("DELETE FROM cells WHERE model=?", (model,))
                self.db.execute("DELETE FROM draws WHERE model=?", (model,))

    def case(self, camera: str) -> tuple[str, CameraRecord] | None:
        """(key, record) of a camera's chart/prediction/emulation record, or None."""
        row = self.db.execute("SELECT key, info FROM cases WHERE camera=?", (camera,)).fetchone()
        return (row[0], CameraRecord.from_json(json.loads(row[1]))) if row else None

    def set_case(self, camera: str, key: str, info: CameraRecord) -> None:
        """Store a camera's record under its identity ``key``."""
        with self.db:
            self.db.execute("INSERT OR REPLACE INTO cases VALUES (?, ?, ?)",
                            (camera, key, json.dumps(info.to_json())))

    def cases(self) -> dict[str, CameraRecord]:
        """All camera records."""
        return {c: CameraRecord.from_json(json.loads(i))
                for c, _, i in self.db.execute("SELECT * FROM cases")}

    def stored_images(self, model: str, camera: str) -> set[int]:
        """Image ids whose detections are stored for (model, camera)."""
        return {r[0] for r in self.db.execute(
            "SELECT image_id FROM detections WHERE model=? AND camera=?", (model, camera))}

    def add_detections(self, model: str, camera: str, rows: list[tuple[int, np.ndarray]]) -> None:
        """Store (image_id, detections) pairs in one transaction."""
        with self.db:
            self.db.executemany("INSERT OR REPLACE INTO detections VALUES (?, ?, ?, ?, ?)",
                                [(model, camera, int(i), len(d), pack_detections(d))
                                 for i, d in rows])

    def detections(self, model: str, camera: str) -> dict[int, np.ndarray]:
        """Stored detections of a cell: image_id -> (n, 6). A cell imported from a scores
        file (:mod:`fidelity.coco.scores`) has none: asking is an input error naming it."""
        out = {i: unpack_detections(b) for i, b in self.db.execute(
            "SELECT image_id, dets FROM detections WHERE model=? AND camera=?", (model, camera))}
        if not out:
            self.check_detections((model, camera))
        return out

    def complete_scores(self, coco: Any, method: str = "auto") -> int:
        """The fold scores with the rest of the run and the bootstrap draws of every cell that
        lacks them (:meth:`rescore_folds`, :meth:`score_draws`); how many cells there are."""
        self.rescore_folds(coco)
        self.score_draws(coco)
        return len(self.cells())

    def cell(self, model: str, camera: str) -> ValidationCell | None:
        """A finished cell, or None."""
        cur = self.db.execute("SELECT * FROM cells WHERE model=? AND camera=?", (model, camera))
        row = cur.fetchone()
        if row is None:
            return None
        d = {c[0]: v for c, v in zip(cur.description, row, strict=True)}
        drawn = self.db.execute("SELECT images, draws FROM draws WHERE model=? AND camera=?",
                                (model, camera)).fetchone()
        return ValidationCell.from_json(d | {
            "ap": json.loads(d["ap"]), "folds": json.loads(d["folds"]),
            "draws": json.loads(drawn[1]) if drawn and drawn[0] == d["images"] else None})

    def cells(self) -> list[ValidationCell]:
        """All finished cells."""
        rows = self.db.execute("SELECT model, camera FROM cells ORDER BY model, camera").fetchall()
        return [c for m, k in rows if (c := self.cell(m, k)) is not None]

    def rescore_folds(self, coco: Any, say: Callable[[str], None] | None = None) -> int:
        """Score again, from the stored detections (no inference), the folds of every cell
        whose fold scores lack the rest-of-run scores the jackknife SE needs (cells stored
        before they were; :func:`fidelity.coco.scoring.score_folds`). Returns how many."""
        n = 0
        for c in self.cells():
            if all(f.has_rest for f in c.folds):  # (no folds: fewer than 2 images)
                continue
            dets = self.detections(c.model, c.camera)
            folds = score_folds(coco, dets, sorted(dets), FOLDS, method="auto")
            with self.db:
                self.db.execute("UPDATE cells SET folds=? WHERE model=? AND camera=?",
                                (json.dumps([f.to_json() for f in folds]), c.model, c.camera))
            n += 1
            if say:
                say(f"{c.camera} / {c.model}: folds scored again with the rest of the run")
        return n

    def score_draws(self, coco: Any, say: Callable[[str], None] | None = None) -> int:
        """Score every cell on the image bootstrap's draws (:func:`fidelity.coco.bootstrap.
        draw_scores`, its default draws and seed) from the stored detections, where they are
        not stored for the cell's images, draws and seed yet. Returns how many were scored."""
        n = 0
        for c in self.cells():
            if c.draws is not None and c.draws.current:
                continue
            dets = self.detections(c.model, c.camera)
            draws = draw_scores(coco, dets, sorted(dets))
            with self.db:
                self.db.execute("INSERT OR REPLACE INTO draws VALUES (?, ?, ?, ?)",
                                (c.model, c.camera, draws.images, json.dumps(draws.to_json())))
            n += 1
            if say:
                say(f"{c.camera} / {c.model}: scored on {draws.resamples} bootstrap draws")
        return n

    def finish_cell(self, model: str, camera: str, score: CocoScore,
                    folds: Sequence[FoldScore], seconds: float) -> None:
        """Record a finished cell with its full-set score and per-fold scores."""
        with self.db:
            self.db.execute("INSERT OR REPLACE INTO cells VALUES (?,?,?,?,?,?,?,?,?)",
                            (model, camera, score.images, score.map, score.map50,
                             json.dumps(score.ap), json.dumps([f.to_json() for f in folds]),
                             seconds, time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())))


class ValidationCells:
    """The validation store as :func:`fidelity.coco.executor.run_cells` sees it (a
    :class:`fidelity.coco.executor.CellStore`): cells keyed ``(model, camera)``, scored on
    ``coco`` with their fold scores when their detections are all stored, each logged through
    ``say``. ``store``: the run's connection (the driver's thread); ``stores``: a connection
    per thread, for scoring (a cell may be scored on a thread of its own)."""

    def __init__(self, store: ValidationStore, stores: ThreadStores[ValidationStore],
                 coco: Any, say: Callable[[str], None]) -> None:
        self.store = store
        self.stores = stores
        self.coco = coco
        self.say = say

    def done(self, cell: CellWork) -> bool:
        """Whether the cell is finished."""
        return self.store.cell(*cell.key) is not None

    def stored(self, cell: CellWork) -> set[int]:
        """Image ids whose detections are stored."""
        return self.store.stored_images(*cell.key)

    def add(self, cell: CellWork, rows: Sequence[tuple[int, np.ndarray]]) -> None:
        """Store detections (one transaction)."""
        model, camera = cell.key
        self.store.add_detections(model, camera, list(rows))

    def finish(self, cell: CellWork, seconds: float, new: int) -> None:
        """Score the cell and its folds, record it and log it."""
        model, camera = cell.key
        ids = list(cell.image_ids)
        own = self.stores.get()  # run_cells may score on a thread of its own
        dets = own.detections(model, camera)
        score = evaluate_detections(self.coco, dets, ids)
        folds = score_folds(self.coco, dets, ids, FOLDS, method="auto")
        own.finish_cell(model, camera, score, folds, seconds)
        self.say(f"{time.strftime('%H:%M:%S')} {camera} / {model}: mAP={score.map:.4f} "
                 f"person={score.ap.get('person')} images={len(ids)} new={new} "
                 f"{seconds:.1f}s")


__all__ = [
    "STORE_NAME",
    "extends_limit",
    "ValidationCell",
    "ValidationCells",
    "ValidationStore",
    "default_store",
]
