"""The COCO sweep: every (model, transform, ΔE target) cell, in a crash-safe SQLite store.

Pipeline per cell, all in memory (equivalent to writing the transformed JPEG files and reading
them back, as SAFE-COLOR did): decoded original (cached in RAM) -> 8-bit transform
(:class:`fidelity.coco.dataset.PixelMap`, exact) -> JPEG encode with the original's tables and
subsampling -> decode -> detector -> raw detections.

Store (``<out>/sweep.sqlite``, WAL journal, ``synchronous=FULL``):

* ``detections(model, transform, target, image_id, n, dets)``: raw detections of every image,
  (n, 6) float32 ``x1, y1, x2, y2, score, class`` (zlib), committed every few images; so a
  ``kill -9`` loses at most one uncommitted batch and re-scoring needs no inference.
* ``cells(model, transform, target, param, status, reason, images, map, map50, map75, ap,
  seconds, finished)``: one row per finished cell (``status`` ``done`` or ``unreachable``).
* ``folds(model, transform, target, images, folds)``: per-fold scores of a finished cell
  (:func:`fidelity.coco.scoring.score_folds`), computed from the stored detections when a report
  asks for standard errors, and kept.
* ``draws(model, transform, target, images, draws)``: the bootstrap draws' scores of a finished
  cell, computed and kept like ``folds``.
* ``imported(cell, source)``: cells that came from a scores file (:mod:`fidelity.coco.scores`;
  their detections are not in the store).
* ``models(model, file, sha256, limit_images, settings)`` and ``meta(key, value)``: provenance
  (versions and ``versions_seen``, data, grid, machine, and ``scorers``: the COCO AP implementations that scored it;
  ``imported``: the scores files imported).

A rerun skips finished cells and the images already stored in unfinished ones. A rerun with a
model's image limit raised (``model.onnx@N``) extends its finished cells: only the new images
are run, the stored ones are kept, and each cell is re-scored on the first N images (baseline
first). A store caught mid-extension holds cells on two image counts; its report scores every
cell of a model on the smaller one (:func:`fidelity.coco.tables.grid.align_image_counts`).
"""

from __future__ import annotations

import datetime
import json
import os
import platform
import sqlite3
import sys
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fidelity.coco.bootstrap import Draws, draw_scores
from fidelity.coco.dataset import BASELINE, calibrated_param
from fidelity.coco.degradations import DEGRADATIONS
from fidelity.coco.driver import StoreRun
from fidelity.coco.executor import CellWork, ExecutorOptions, ModelFile, PixelTransform
from fidelity.coco.jpeg import read_jpeg
from fidelity.coco.scoring import (
    FoldScore,
    evaluate_detections,
    load_annotated_images,
    load_annotations,
    resolve_scorer,
    score_folds,
)
from fidelity.coco.store import ImageSet, ResultsStore, pack_detections, unpack_detections
from fidelity.core.errors import InvalidValueError
from fidelity.core.fileio import file_sha256
from fidelity.core.record import record
from fidelity.core.version import __version__, installed_version

if TYPE_CHECKING:
    from fidelity.coco.bootstrap import Draws
    from fidelity.coco.executor import CellWork, ExecutorOptions
    from fidelity.coco.scoring import FoldScore
    from fidelity.coco.store import Claim, ThreadStores

#: Default targets of the sweep (issue 5): ΔE 0 is the baseline.
SWEEP_TARGETS: tuple[float, ...] = (0, 1, 2, 3, 4, 5, 6, 8, 10, 12, 15, 18, 21, 24)

STORE_NAME = "sweep.sqlite"

_SCHEMA = """
CREATE TABLE IF NOT EXISTS cells (
    model TEXT NOT NULL, transform TEXT NOT NULL, target REAL NOT NULL,
    param REAL, status TEXT NOT NULL, reason TEXT, images INTEGER,
    map REAL, map50 REAL, map75 REAL, ap TEXT, seconds REAL, finished TEXT,
    PRIMARY KEY (model, transform, target));
CREATE TABLE IF NOT EXISTS detections (
    model TEXT NOT NULL, transform TEXT NOT NULL, target REAL NOT NULL,
    image_id INTEGER NOT NULL, n INTEGER NOT NULL, dets BLOB NOT NULL,
    PRIMARY KEY (model, transform, target, image_id));
CREATE TABLE IF NOT EXISTS folds (
    model TEXT NOT NULL, transform TEXT NOT NULL, target REAL NOT NULL,
    images INTEGER NOT NULL, folds TEXT NOT NULL,
    PRIMARY KEY (model, transform, target));
CREATE TABLE IF NOT EXISTS draws (
    model TEXT NOT NULL, transform TEXT NOT NULL, target REAL NOT NULL,
    images INTEGER NOT NULL, draws TEXT NOT NULL,
    PRIMARY KEY (model, transform, target));
CREATE TABLE IF NOT EXISTS imported (cell TEXT PRIMARY KEY, source TEXT NOT NULL);
"""


class SweepStore(ResultsStore):
    """The SQLite results store of a sweep (see module docstring)."""

    store_name = STORE_NAME
    kind = "sweep"
    core_tables = ("meta", "models", "cells", "detections")
    schema = _SCHEMA
    cell_columns = ("model", "transform", "target")

    # detections -----------------------------------------------------------------------------
    def stored_images(self, model: str, transform: str, target: float) -> set[int]:
        """Image ids whose detections are stored for this cell."""
        rows = self.db.execute("SELECT image_id FROM detections WHERE model=? AND transform=? "
                               "AND target=?", (model, transform, float(target)))
        return {r[0] for r in rows}

    def add_detections(self, model: str, transform: str, target: float,
                       rows: Iterable[tuple[int, np.ndarray]]) -> None:
        """Store (image_id, detections) pairs in one transaction."""
        with self.db:
            self.db.executemany(
                "INSERT OR REPLACE INTO detections VALUES (?, ?, ?, ?, ?, ?)",
                [(model, transform, float(target), int(i), len(d), pack_detections(d))
                 for i, d in rows])

    def detections(self, model: str, transform: str, target: float) -> dict[int, np.ndarray]:
        """All stored detections of a cell: image_id -> (n, 6). A cell imported from a scores
        file (:mod:`fidelity.coco.scores`) has none: asking for them is an input error naming
        the cell and the file."""
        rows = self.db.execute("SELECT image_id, dets FROM detections WHERE model=? AND "
                               "transform=? AND target=?", (model, transform, float(target)))
        out = {i: unpack_detections(b) for i, b in rows}
        if not out:
            self.check_detections((model, transform, float(target)))
        return out

    def complete_scores(self, coco: Any, method: str = "auto") -> int:
        """Compute and keep the fold and draw scores of every done cell that lacks them, on
        its own image count (what ``tables`` uses; :meth:`fold_scores`, :meth:`draw_scores`).
        Returns how many cells were done."""
        ids_all = sorted(coco.getImgIds())
        done = [c for c in self.cells() if c.done]
        for c in done:
            ids = ids_all[: int(c.images or 0)]
            self.fold_scores(coco, c.model, c.transform, c.target, ids, method)
            self.draw_scores(coco, c.model, c.transform, c.target, ids)
        return len(done)

    # provenance -----------------------------------------------------------------------------
    def scorers(self) -> list[dict[str, str | None]]:
        """The COCO AP implementations that scored this store, oldest first.

        Each entry is ``{"scorer": name, "since": ISO time or None}``: cells finished from
        ``since`` on (None: from the start) were scored by it. Stores written before the scorer
        was recorded were scored by pycocotools.
        """
        raw = self.meta().get("scorers")
        if raw is None:
            return [{"scorer": "pycocotools", "since": None}] if self.cells() else []
        return [r if isinstance(r, dict) else {"scorer": r, "since": None} for r in raw]

    def record_scorer(self, method: str, *, all_cells: bool = False
                      ) -> list[dict[str, str | None]]:
        """Record that ``method`` scores the cells finished from now on (``all_cells``: all)."""
        now = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
        used = [] if all_cells else self.scorers()
        if not used or used[-1]["scorer"] != method:
            used.append({"scorer": method, "since": None if all_cells or not used else now})
        self.set_meta("scorers", used)
        return used

    def scorer_of(self, cell: SweepCell) -> str | None:
        """Which scorer scored a finished cell (from :meth:`scorers` and its ``finished``).

        Times have 1 s resolution; a cell finished in the second a scorer was recorded counts
        for the earlier one (a run loads its data and models for seconds before its first cell).
        """
        name = None
        for entry in self.scorers():
            if entry["since"] is None or (cell.finished or "") > entry["since"]:
                name = entry["scorer"]
        return name

    def fold_scores(self, coco: Any, model: str, transform: str, target: float,
                    image_ids: Sequence[int], method: str = "auto") -> list[FoldScore]:
        """Per-fold scores of a cell on ``image_ids`` with the scores of the rest of the run
        without each fold (:func:`fidelity.coco.scoring.score_folds`; cached in the ``folds``
        table)."""
        row = self.db.execute("SELECT images, folds FROM folds WHERE model=? AND transform=? "
                              "AND target=?", (model, transform, float(target))).fetchone()
        if row and row[0] == len(image_ids):
            cached = [FoldScore.from_json(f) for f in json.loads(row[1])]
            if all(f.has_rest for f in cached):  # else: scored before the jackknife's scores
                return cached
        folds = score_folds(coco, self.detections(model, transform, target), image_ids,
                            method=method)
        with self.db:
            self.db.execute("INSERT OR REPLACE INTO folds VALUES (?, ?, ?, ?, ?)",
                            (model, transform, float(target), len(image_ids),
                             json.dumps([f.to_json() for f in folds])))
        return folds

    def draw_scores(self, coco: Any, model: str, transform: str, target: float,
                    image_ids: Sequence[int]) -> Draws:
        """A cell's scores on the image bootstrap's draws of ``image_ids``
        (:func:`fidelity.coco.bootstrap.draw_scores` with its default draws and seed; cached in
        the ``draws`` table, computed again when the images, draws or seed differ)."""
        row = self.db.execute("SELECT images, draws FROM draws WHERE model=? AND transform=? "
                              "AND target=?", (model, transform, float(target))).fetchone()
        if row and row[0] == len(image_ids):
            cached = Draws.from_json(json.loads(row[1]))
            if cached.current:
                return cached
        dets = self.detections(model, transform, target)
        draws = draw_scores(coco, dets, image_ids)
        with self.db:
            self.db.execute("INSERT OR REPLACE INTO draws VALUES (?, ?, ?, ?, ?)",
                            (model, transform, float(target), len(image_ids),
                             json.dumps(draws.to_json())))
        return draws

    # cells ----------------------------------------------------------------------------------
    def cell(self, model: str, transform: str, target: float) -> SweepCell | None:
        """A finished cell, or None."""
        cur = self.db.execute("SELECT * FROM cells WHERE model=? AND transform=? AND target=?",
                              (model, transform, float(target)))
        row = cur.fetchone()
        return SweepCell.from_row(cur, row) if row else None

    def cells(self) -> list[SweepCell]:
        """All finished cells (done and unreachable), by model, transform and target."""
        cur = self.db.execute("SELECT * FROM cells ORDER BY model, transform, target")
        return [SweepCell.from_row(cur, r) for r in cur.fetchall()]

    def finish_cell(self, model: str, transform: str, target: float, *, param: float | None,
                    status: str, reason: str | None = None, images: int | None = None,
                    score: Any = None, seconds: float | None = None) -> None:
        """Record a finished (or unreachable) cell."""
        with self.db:
            self.db.execute(
                "INSERT OR REPLACE INTO cells VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?)",
                (model, transform, float(target), param, status, reason, images,
                 None if score is None else score.map, None if score is None else score.map50,
                 None if score is None else score.map75,
                 None if score is None else json.dumps(score.ap), seconds,
                 time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())))


@record
class SweepCell:
    """A finished cell of the sweep store (one row of its ``cells`` table).

    ``status``: ``"done"`` (scored) or ``"unreachable"`` (the transform cannot reach the ΔE
    ``target`` on the chart; ``reason`` says why). A done cell has ``param`` (the calibrated
    transform parameter), ``images`` (how many it was scored on, first N by id), ``map``,
    ``map50``, ``map75`` and ``ap`` (per class name; fractions in [0, 1], None without ground
    truth), ``seconds`` and ``finished`` (UTC, ISO 8601). ``rescored_from`` is not stored: a
    report that re-scores a cell on fewer images sets it to the stored count
    (:func:`fidelity.coco.tables.grid.align_image_counts`).
    """

    model: str
    transform: str
    target: float
    param: float | None
    status: str
    reason: str | None = None
    images: int | None = None
    map: float | None = None
    map50: float | None = None
    map75: float | None = None
    ap: dict[str, float | None] | None = None
    seconds: float | None = None
    finished: str | None = None
    rescored_from: int | None = None

    @property
    def done(self) -> bool:
        """Whether the cell was scored (not unreachable)."""
        return self.status == "done"

    @classmethod
    def from_row(cls, cur: sqlite3.Cursor, row: Sequence[Any]) -> SweepCell:
        """The cell of a ``SELECT * FROM cells`` row (``cur`` names its columns)."""
        d = {c[0]: v for c, v in zip(cur.description, row, strict=True)}
        return cls(model=d["model"], transform=d["transform"], target=float(d["target"]),
                   param=d["param"], status=d["status"], reason=d["reason"],
                   images=d["images"], map=d["map"], map50=d["map50"], map75=d["map75"],
                   ap=json.loads(d["ap"]) if d.get("ap") else None, seconds=d["seconds"],
                   finished=d["finished"])


@record
class ModelSpec:
    """A model to sweep: its ONNX file and how many images (first N by image id; None = all)."""

    path: Path
    limit: int | None = None

    @classmethod
    def parse(cls, text: str) -> ModelSpec:
        """``path.onnx`` or ``path.onnx@N`` (first N images by id)."""
        if "@" in text:
            p, n = text.rsplit("@", 1)
            try:
                lim = int(n)
            except ValueError as exc:
                raise InvalidValueError(f"model {text!r}: image limit {n!r} is not an integer") \
                    from exc
            if lim < 1:
                raise InvalidValueError(f"model {text!r}: image limit must be >= 1")
            return cls(Path(p), lim)
        return cls(Path(text), None)


#: ΔE values at which SAFE-COLOR states its findings (1 % at 3, 3 % at 6, 10 % at 12, mAP 0 at
#: 24, bicycle at 1): with ``order="priority"`` these cells run first, for every model.
PRIORITY_TARGETS: tuple[float, ...] = (1, 3, 6, 12, 24)


def cell_label(transform: str, target: float) -> str:
    """A cell's name in log lines: ``contrast-inc ΔE 3``, ``gaussian-blur sigma 1.5 px``."""
    fam = DEGRADATIONS.get(transform)
    if fam is None:
        return f"{transform} ΔE {target:g}"
    return f"{transform} {fam.parameter} {target:g} {fam.unit}"


def plan_cells(transforms: Sequence[str], targets: Sequence[float],
               degradations: Sequence[str] = (), *, half: int | None = None
               ) -> list[tuple[str, float]]:
    """Cell order within a model: baseline first, then ascending ΔE, transforms in given order,
    then each blur and noise family's levels (:data:`fidelity.coco.degradations.DEGRADATIONS`),
    mildest first, level by level across the families. ``half``: 0 for the families'
    even-numbered levels only, 1 for the odd-numbered ones (the priority order's two phases),
    None for all."""
    cells: list[tuple[str, float]] = []
    if 0 in targets:
        cells.append(("baseline", 0.0))
    for e in sorted(t for t in targets if t != 0):
        for t in transforms:
            cells.append((t, float(e)))
    levels = {d: DEGRADATIONS[d].levels for d in degradations}
    for k in range(max((len(v) for v in levels.values()), default=0)):
        if half is not None and k % 2 != half:
            continue
        cells += [(d, float(v[k])) for d, v in levels.items() if k < len(v)]
    return cells


def plan_phases(n_models: int, transforms: Sequence[str], targets: Sequence[float],
                order: str = "priority", degradations: Sequence[str] = ()
                ) -> list[tuple[int, list[tuple[str, float]]]]:
    """The run order as (model index, cells) phases.

    ``"ascending"``: each model in turn, all its cells (:func:`plan_cells`). ``"priority"``:
    first every model's baseline and :data:`PRIORITY_TARGETS` cells, then every model's rest,
    (and every other level of each blur and noise family in ``degradations``), then every
    model's rest, so that a partial run already covers the paper's thresholds for all models.
    ``"reverse"``:
    the priority order backwards, for a second process that shares a model's cells with one
    running in priority order (they meet in the middle; at most the cell they meet on is
    computed twice, with identical detections).
    """
    if order == "ascending":
        return [(m, plan_cells(transforms, targets, degradations)) for m in range(n_models)]
    if order == "reverse":
        return [(m, cells[::-1]) for m, cells in
                plan_phases(n_models, transforms, targets, "priority", degradations)[::-1]]
    if order != "priority":
        raise InvalidValueError(
            f"order {order!r}: expected 'priority', 'ascending' or 'reverse'")
    first = [t for t in targets if t == 0 or t in PRIORITY_TARGETS]
    rest = [t for t in targets if t not in first]
    phases = [(m, plan_cells(transforms, first, degradations, half=0)) for m in range(n_models)]
    if rest or degradations:
        phases += [(m, plan_cells(transforms, rest, degradations, half=1))
                   for m in range(n_models)]
    return [(m, cells) for m, cells in phases if cells]


class ImageCache:
    """Decoded originals kept in RAM (uint8 RGB + JPEG settings), loaded on first use."""

    def __init__(self, folder: Path, coco: Any) -> None:
        self.folder = folder
        self.coco = coco
        self._cache: dict[int, tuple[np.ndarray, Any]] = {}

    def get(self, image_id: int) -> tuple[np.ndarray, Any]:
        """(rgb, settings) of an image id."""
        hit = self._cache.get(image_id)
        if hit is None:
            hit = read_jpeg(self.folder / self.coco.imgs[image_id]["file_name"])
            self._cache[image_id] = hit
        return hit


def run_sweep(models: Sequence[ModelSpec], images: str | os.PathLike[str],
              annotations: str | os.PathLike[str], out: str | os.PathLike[str],
              transforms: Sequence[str], targets: Sequence[float], *, threads: int | None = 1,
              provider: str = "auto", batch_commit: int = 25, order: str = "priority",
              scorer: str = "auto", log: Callable[[str], None] | None = None,
              progress: bool = False, executor: ExecutorOptions | None = None,
              lease_s: float | None = None, degradations: Sequence[str] = ()) -> SweepStore:
    """Run (or resume) every cell of the grid for each model in order; returns the store.

    ``degradations``: blur and noise families (:data:`fidelity.coco.degradations.DEGRADATIONS`)
    swept at their levels besides the colour ``transforms`` at ``targets``; their cells are
    keyed ``(model, family, level)``.

    ``scorer``: COCO AP implementation (:data:`fidelity.coco.scoring.COCO_SCORERS` or ``"auto"``);
    it is recorded in the store's ``meta`` and in each cell's log line. ``log`` receives one
    line per finished cell, numbered ``[k/N]`` in the run order (N: every planned cell, k
    counts finished ones too); ``progress`` shows one progress bar for the whole plan.

    ``executor``: where the detector runs (:class:`fidelity.coco.executor.ExecutorOptions`;
    default: this process with ``threads`` and ``provider``); ``batch_commit``: images per
    work item of the local executor (detections are committed per item). Cells are claimed in
    the store (:class:`fidelity.coco.store.LeaseKeeper`), so several runs on one store share
    the cells; ``lease_s`` overrides the seconds after which a silent run's claims are taken
    over. Inputs are checked against the store's record (images, annotations, models).
    """
    import onnxruntime

    opts = executor or ExecutorOptions(threads=threads, provider=provider)
    say = log or (lambda s: print(s, file=sys.stderr, flush=True))
    img_dir, coco, all_ids = load_annotated_images(images, annotations)
    method = resolve_scorer(scorer)
    files = [ModelFile.from_path(m.path) for m in models]
    if not files:
        raise InvalidValueError("no models to sweep (--models is empty)")
    store = SweepStore(out)
    image_set = ImageSet(img_dir, coco, all_ids)
    store.start_run(image_set, [m.limit for m in models], annotations)
    import cv2
    import PIL

    versions = {"python": platform.python_version(), "onnxruntime": onnxruntime.__version__,
                "numpy": np.__version__, "Pillow": PIL.__version__, "opencv": cv2.__version__,
                "pycocotools": installed_version("pycocotools"),
                "faster-coco-eval": installed_version("faster-coco-eval"), "fidelity": __version__}
    # every distinct set of versions that has run in this store, first to last (a run resumed
    # elsewhere, or after an upgrade, may detect differently), as meta["machines"] does
    meta = store.meta()
    seen = meta.get("versions_seen") or ([meta["versions"]] if meta.get("versions") else [])
    store.set_meta("versions", versions)
    if not any(same_versions(versions, s) for s in seen):
        store.set_meta("versions_seen", [*seen, versions])
    store.record_scorer(method)
    store.set_meta("grid", {"transforms": list(transforms), "targets": list(targets),
                            **({"degradations": list(degradations)} if degradations else {}),
                            "models": [f"{m.path.name}@{m.limit or len(all_ids)}"
                                       for m in models]})
    plan = plan_phases(len(models), transforms, targets, order, degradations)
    total = sum(len(grid) for _, grid in plan)
    params: dict[tuple[str, float], tuple[float | None, str | None]] = {}
    with StoreRun(store, lambda: SweepStore(store.folder, create=False), image_set,
                  opts) as run:
        run.record_machine({"threads": opts.threads})
        run.register_models(files, [m.limit for m in models])
        run.start_leases(lease_s)
        work: list[CellWork] = []
        number: dict[tuple[Any, ...], int] = {}
        for k, (index, (transform, target)) in enumerate(
                ((i, c) for i, grid in plan for c in grid), start=1):
            f, spec = files[index], models[index]
            ids = all_ids[: spec.limit] if spec.limit else all_ids
            key = (f.name, transform, float(target))
            number[key] = k
            finished = store.cell(*key)
            if finished and (not finished.done or finished.images == len(ids)):
                continue
            if transform == BASELINE:
                param: float | None = None
            elif transform in DEGRADATIONS:  # the level is the parameter
                param = float(target)
            else:
                if (transform, target) not in params:
                    params[(transform, target)] = calibrated_param(transform, target)
                param, reason = params[(transform, target)]
                if param is None:
                    store.finish_cell(*key, param=None, status="unreachable", reason=reason)
                    say(f"[{k}/{total}] {f.name} {transform} ΔE {target:g}: unreachable "
                        f"({reason})")
                    continue
            work.append(CellWork(key, f"{f.name} {cell_label(transform, target)}", f,
                                 PixelTransform.of(transform, param, images=len(ids)),
                                 tuple(ids)))
        run.run(work, SweepCells(store, run.stores, coco, method, number, total, say),
                batch_commit=batch_commit, progress=progress, say=say)
    return store


class SweepCells:
    """The sweep store as :func:`fidelity.coco.executor.run_cells` sees it (a
    :class:`fidelity.coco.executor.CellStore`): cells keyed ``(model, transform, ΔE)``, scored
    with ``method`` on ``coco`` when their detections are all stored, each logged as
    ``[number/total]`` through ``say``.

    ``store``: the run's connection (the driver's thread); ``stores``: a connection per thread,
    for scoring (a cell may be scored on a thread of its own).
    """

    def __init__(self, store: SweepStore, stores: ThreadStores[SweepStore], coco: Any,
                 method: str, number: Mapping[tuple[Any, ...], int], total: int,
                 say: Callable[[str], None]) -> None:
        self.store = store
        self.stores = stores
        self.coco = coco
        self.method = method
        self.number = number
        self.total = total
        self.say = say

    def done(self, cell: CellWork) -> bool:
        """Finished on the cell's image count (or unreachable)."""
        c = self.store.cell(*cell.key)
        return c is not None and (not c.done or c.images == len(cell.image_ids))

    def stored(self, cell: CellWork) -> set[int]:
        """Image ids whose detections are stored."""
        return self.store.stored_images(*cell.key)

    def add(self, cell: CellWork, rows: Sequence[tuple[int, np.ndarray]]) -> None:
        """Store detections (one transaction)."""
        model, transform, target = cell.key
        self.store.add_detections(model, transform, target, rows)

    def finish(self, cell: CellWork, seconds: float, new: int) -> None:
        """Score the cell on its images, record it and log it."""
        model, transform, target = cell.key
        ids = list(cell.image_ids)
        own = self.stores.get()  # run_cells may score on a thread of its own
        score = evaluate_detections(self.coco, own.detections(model, transform, target),
                                    ids, method=self.method)
        param = cell.transform.param
        own.finish_cell(model, transform, target, param=param, status="done",
                        images=len(ids), score=score, seconds=seconds)
        self.say(f"{time.strftime('%H:%M:%S')} [{self.number[cell.key]}/{self.total}] {model} "
                 f"{cell_label(transform, target)} param={param} mAP={score.map:.4f} "
                 f"AP50={score.map50:.4f} person={score.ap.get('person')} "
                 f"images={len(ids)} new={new} {seconds:.1f}s "
                 f"({new / seconds if seconds else 0:.1f} img/s)")


def run_summary(last_run: Mapping[str, Any]) -> str:
    """One line on what a run's executor did (a store's ``meta["last_run"]``): images, work
    items, worker processes, nodes, the workers' busy time and the wall time."""
    workers = list(last_run.get("workers") or [])
    nodes = len({w.split(":")[0] for w in workers})
    procs = len(workers)
    waited = last_run.get("waited") or 0
    return (f"executor {last_run.get('executor')}: {last_run.get('images', 0)} images in "
            f"{last_run.get('items', 0)} work items on {procs} worker "
            f"process{'' if procs == 1 else 'es'} ({nodes} node{'' if nodes == 1 else 's'}), "
            f"{last_run.get('worker_seconds', 0.0):.1f} s of worker time in "
            f"{last_run.get('seconds', 0.0):.1f} s; {last_run.get('cells', 0)} cells finished "
            "here" + (f", {waited} by another run" if waited else ""))


@record
class SweepProgress:
    """Where a sweep stands for one registered model (:func:`sweep_status`).

    ``images``: the image count its cells are run on (its registered limit, else the image
    folder's count); ``planned``: cells of the grid the store last ran (baseline and every
    transform at every non-zero target); ``done`` (on ``images`` images), ``unreachable``,
    ``to_do`` (the rest); ``under_way``: unfinished cells with stored detections, as
    ``(transform, target, stored images)``; ``images_to_do``: detections still missing over the
    cells to do; ``pace_s``: wall seconds per finished cell over the model's last finished cells
    (:func:`cell_pace`; whatever else runs beside it; None with fewer than 3); ``left_s``:
    ``to_do * pace_s``, a rough guide.
    """

    model: str
    images: int | None
    planned: int
    done: int
    unreachable: int
    to_do: int
    under_way: tuple[tuple[str, float, int], ...]
    images_to_do: int
    pace_s: float | None
    left_s: float | None
    claims: tuple[Claim, ...] = ()
    stored: tuple[int, ...] = ()


def sweep_status(store: SweepStore, pace_cells: int = 10) -> list[SweepProgress]:
    """Where a sweep stands, per registered model, from the store alone (no annotations).

    One :class:`SweepProgress` per model; the pace is :func:`cell_pace` of its last
    ``pace_cells`` finished cells. Safe while a sweep writes.
    """
    meta = store.meta()
    grid = meta.get("grid") or {}
    planned = plan_cells(grid.get("transforms") or [], grid.get("targets") or [],
                         [d for d in grid.get("degradations") or () if d in DEGRADATIONS])
    image_count = (meta.get("data") or {}).get("image_count")
    stored: dict[tuple[str, str, float], int] = {
        (m, t, float(e)): n for m, t, e, n in store.db.execute(
            "SELECT model, transform, target, COUNT(*) FROM detections "
            "GROUP BY model, transform, target")}
    claims = store.claims()
    cells: dict[str, dict[tuple[str, float], SweepCell]] = {}
    for c in store.cells():
        cells.setdefault(c.model, {})[(c.transform, c.target)] = c
    out = []
    for model, info in store.models().items():
        n = info.limit_images or image_count
        mine = cells.get(model, {})
        done = {k: c for k, c in mine.items() if c.done and c.images == n}
        unreachable = {k for k, c in mine.items() if c.status == "unreachable"}
        to_do = [k for k in planned if k not in done and k not in unreachable]
        under_way = tuple((t, e, stored[(model, t, e)]) for t, e in to_do  # more than scored
                          if stored.get((model, t, e), 0) > _images_of(mine.get((t, e))))
        images_to_do = sum(max(0, (n or 0) - stored.get((model, t, e), 0)) for t, e in to_do)
        last = sorted((datetime.datetime.strptime(c.finished, "%Y-%m-%dT%H:%M:%SZ"),
                       c.seconds) for c in done.values() if c.finished)[-pace_cells:]
        pace = cell_pace([s.timestamp() for s, _ in last], [d for _, d in last])
        mine_claims = tuple(c for c in claims if c.cell and c.cell[0] == model)
        out.append(SweepProgress(model, n, len(planned), len(done), len(unreachable),
                                 len(to_do), under_way, images_to_do, pace,
                                 None if pace is None else pace * len(to_do), mine_claims,
                                 tuple(stored.get((model, str(c.cell[1]), float(c.cell[2])), 0)
                                       for c in mine_claims)))
    return out


def cell_pace(finished: Sequence[float], seconds: Sequence[float | None]) -> float | None:
    """Wall seconds per finished cell from the finishing times (seconds, ascending) of a
    model's last cells and each cell's own run time (``SweepCell.seconds``; None: unknown).

    The mean gap between finishes, each gap counted at most the cells' median run time: runs
    side by side finish in bunches (a gap near 0, then one near a cell's time), which the mean
    averages out, and a gap longer than a cell takes is a time nothing ran (a pause, a stopped
    machine), counted as one cell. None with fewer than 3 finishes.
    """
    if len(finished) < 3:
        return None
    gaps = np.diff(np.asarray(finished, dtype=np.float64))
    known = [float(s) for s in seconds if s is not None and s > 0]
    cap = float(np.median(known)) if known else float(np.median(gaps))
    return float(np.mean(np.minimum(gaps, cap)))


def _images_of(cell: SweepCell | None) -> int:
    return (cell.images or 0) if cell is not None else 0


def rescore(store: SweepStore, annotations: str | os.PathLike[str], method: str = "auto") -> int:
    """Recompute every done cell's scores from the stored detections (no inference); the
    annotations become the store's recorded ones. A store holding cells imported from a scores
    file is an input error (their detections are elsewhere); nothing is re-scored."""
    for key in store.imported():  # checked first: no cell is re-scored if one cannot be
        store.check_detections(tuple(json.loads(key)))
    method = resolve_scorer(method)
    coco = load_annotations(annotations)
    store.check_annotations(annotations, file_sha256(annotations), replace=True)
    ids_all = sorted(coco.getImgIds())
    models = store.models()
    n = 0
    for c in store.cells():
        if not c.done:
            continue
        reg = models.get(c.model)
        lim = reg.limit_images if reg is not None else None
        ids = ids_all[:lim] if lim else ids_all
        score = evaluate_detections(coco, store.detections(c.model, c.transform, c.target), ids,
                                    method=method)
        store.finish_cell(c.model, c.transform, c.target, param=c.param, status="done",
                          images=len(ids), score=score, seconds=c.seconds)
        n += 1
    store.record_scorer(method, all_cells=True)
    return n


def same_versions(a: Mapping[str, Any], b: Mapping[str, Any]) -> bool:
    """Whether two runs' recorded versions are the same set: equal wherever both name a
    library (an entry written before a library was recorded, such as OpenCV, which resizes
    the images for the detector, is not another set for lacking it)."""
    return all(a[k] == b[k] for k in a.keys() & b.keys())
