"""A results store's scores file: its finished cells without their detections, to carry a sweep
or a validation to another machine, resume it there and report it.

A sweep or validation store holds every image's raw detections (about 3.6 MB a cell of 1000
images; 470 MB a detector's sweep): too much to move with the results. What the reports
(``fidelity tables``, ``fidelity validate --report-only``) need of a finished cell is small:
its scores (mAP, per-class AP), its per-fold scores and its bootstrap draws' scores (the
standard errors). A scores file holds every table of the store except the detections and the
claims of running processes (``owners``, ``leases``): the provenance (``meta``), the
registered models, the recorded images, the cells with their cached fold and draw scores (and
a validation's camera records), row for row as the store holds them, and per cell a SHA-256 of
its detections, so that a report built from it names what it was computed from. About 7 kB a
sweep cell gzipped, most of it the 200 draws.

:func:`export_scores` writes it (first computing the fold and draw scores a cell lacks, which
the store keeps: :meth:`fidelity.coco.sweep.SweepStore.complete_scores`); :func:`import_scores`
makes a new store of the same kind hold the same rows, or a store with cells of its own take
the cells it lacks (machines that ran shares of one sweep without a shared disk). A sweep then
resumes there (finished cells are skipped) and the reports read it as they would the first
store. An imported cell has
no detections: what needs them (``--rescore``, re-scoring on other images, ``tables
--explain``) is an input error naming the cell and the file it came from
(:meth:`fidelity.coco.store.ResultsStore.check_detections`).

Format (JSON; gzip-compressed when the file name ends in ``.gz``)::

    {"format": "fidelity-scores", "version": 1, "kind": "sweep" | "validation",
     "fidelity": "<version>", "exported": "<UTC ISO 8601>",
     "tables": {name: {"columns": [...], "rows": [[...], ...]}, ...},
     "detections_sha256": {"<cell key>": "<hex>", ...}}

A cell key is :func:`fidelity.coco.store.cell_key` of the cell's key columns
(:attr:`~fidelity.coco.store.ResultsStore.cell_columns`).
"""

from __future__ import annotations

import contextlib
import gzip
import hashlib
import json
import os
import re
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from fidelity.coco.store import (
    ImageEntry,
    RegisteredModel,
    ResultsStore,
    cell_key,
    preprocessing_of,
    unpack_detections,
)
from fidelity.core.errors import InputFileError
from fidelity.core.fileio import atomic_output, display_path, file_sha256
from fidelity.core.record import record
from fidelity.core.version import __version__

#: The ``format`` of a scores file and the newest ``version`` this code reads and writes.
SCORES_FORMAT = "fidelity-scores"
SCORES_VERSION = 1
#: Tables a scores file leaves out: the detections, and the claims of running processes.
LEFT_OUT = ("detections", "owners", "leases")


@record
class ScoresTransfer:
    """What an export or import moved: the file, its SHA-256, the store's kind, per model
    its cells and how many of them are unreachable (a sweep's)."""

    path: Path
    sha256: str
    kind: str
    models: dict[str, int]
    unreachable: int = 0

    @property
    def cells(self) -> int:
        """How many cells in all."""
        return sum(self.models.values())


def detections_digest(store: ResultsStore, key: tuple[Any, ...]) -> str:
    """SHA-256 of a cell's stored detections (``key``: its :attr:`cell_columns` values): per
    image in ascending id, its id and count as two little-endian int64 and its ``(n, 6)``
    float32 detections' bytes. An imported cell's is the one its file recorded."""
    source = store.imported().get(cell_key(key))
    if source is not None and "detections_sha256" in source:
        return str(source["detections_sha256"])
    h = hashlib.sha256()
    where = " AND ".join(f"{c}=?" for c in store.cell_columns)
    for image_id, blob in store.db.execute(
            f"SELECT image_id, dets FROM detections WHERE {where} ORDER BY image_id", key):
        d = np.ascontiguousarray(unpack_detections(blob), dtype="<f4")
        h.update(np.array([image_id, len(d)], dtype="<i8").tobytes())
        h.update(d.tobytes())
    return h.hexdigest()


def _row_key(row: list[Any], columns: list[str], store: ResultsStore) -> str:
    """The :func:`cell_key` of a row of a table that has the store's cell columns."""
    return cell_key(tuple(row[columns.index(c)] for c in store.cell_columns))


def _tables(store: ResultsStore) -> list[str]:
    return [r[0] for r in store.db.execute(
        "SELECT name FROM sqlite_master WHERE type='table' ORDER BY name")
        if r[0] not in LEFT_OUT]


def _transfer(path: Path, sha256: str, kind: str, tables: dict[str, Any]) -> ScoresTransfer:
    cells = tables.get("cells") or {"columns": [], "rows": []}
    cols = list(cells["columns"])
    i = cols.index("model") if "model" in cols else None
    j = cols.index("status") if "status" in cols else None
    out: dict[str, int] = {}
    for row in cells["rows"]:
        m = str(row[i]) if i is not None else "?"
        out[m] = out.get(m, 0) + 1
    unreachable = sum(j is not None and row[j] == "unreachable" for row in cells["rows"])
    return ScoresTransfer(path, sha256, kind, out, unreachable)


def export_scores(store: ResultsStore, coco: Any, path: str | os.PathLike[str],
                  method: str = "auto") -> ScoresTransfer:
    """Write ``store``'s tables but the detections to the scores file ``path`` (atomically),
    after :meth:`~fidelity.coco.store.ResultsStore.complete_scores` (``coco``: the run's
    annotations; ``method``: the fold scores' COCO scorer). The tables are read in one
    snapshot; a cell that a run still going on finished after its scores were completed is
    left for the next export."""
    store.complete_scores(coco, method)
    tables: dict[str, Any] = {}
    store.db.commit()
    store.db.execute("BEGIN")  # one snapshot of every table, while a run may go on writing
    try:
        for name in _tables(store):
            cur = store.db.execute(f"SELECT * FROM {name}")
            tables[name] = {"columns": [c[0] for c in cur.description],
                            "rows": [list(r) for r in cur.fetchall()]}
    finally:
        store.db.rollback()
    cols = tables["cells"]["columns"]
    # a cell finished after complete_scores has no fold or draw scores yet: the next export's
    cached = [{_row_key(r, tables[t]["columns"], store) for r in tables[t]["rows"]}
              for t in ("folds", "draws") if t in tables]
    status = cols.index("status") if "status" in cols else None
    tables["cells"]["rows"] = [r for r in tables["cells"]["rows"]
                               if (status is not None and r[status] != "done")
                               or all(_row_key(r, cols, store) in c for c in cached)]
    keys = [tuple(r[cols.index(c)] for c in store.cell_columns) for r in tables["cells"]["rows"]]
    doc = {"format": SCORES_FORMAT, "version": SCORES_VERSION, "kind": store.kind,
           "fidelity": _version(),
           "exported": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
           "tables": tables,
           "detections_sha256": {cell_key(k): detections_digest(store, k) for k in keys}}
    text = json.dumps(doc, allow_nan=False, separators=(",", ":")).encode()
    target = Path(path)
    with atomic_output(target, protect=[store.path]) as tmp:
        tmp.write_bytes(gzip.compress(text, mtime=0) if target.suffix == ".gz" else text)
    return _transfer(target, file_sha256(target), store.kind, tables)


def _version() -> str:
    return __version__


def is_scores_file(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` begins as a scores file does (``{"format": "fidelity-scores"``,
    gzip-compressed or not); False for what cannot be read."""
    try:
        with open(path, "rb") as f:
            head = f.read(2)
            f.seek(0)
            start = (gzip.GzipFile(fileobj=f).read(64) if head == b"\x1f\x8b" else f.read(64))
    except (OSError, EOFError):
        return False
    return re.match(rb'\s*\{\s*"format"\s*:\s*"fidelity-scores"', start) is not None


def read_scores(path: str | os.PathLike[str], store_type: type[ResultsStore]
                ) -> dict[str, Any]:
    """A scores file's content, checked against the kind of store it is for: its format,
    version and kind, and every table one of the store's with its columns and rows as long.
    Raises :class:`~fidelity.core.errors.InputFileError` naming the file and the problem."""
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
        raise InputFileError(f"{where}: not a scores file ({exc})") from None
    if not isinstance(doc, dict) or doc.get("format") != SCORES_FORMAT:
        raise InputFileError(f"{where}: not a scores file (no \"format\": \"{SCORES_FORMAT}\")")
    version = doc.get("version")
    if not isinstance(version, int) or version > SCORES_VERSION:
        raise InputFileError(f"{where}: scores file of version {version}, written by a newer "
                             f"fidelity (this one reads version {SCORES_VERSION})")
    kind = store_type.kind
    if doc.get("kind") != kind:
        raise InputFileError(f"{where}: the scores of a {doc.get('kind')} store, not of a "
                             f"{kind} store")
    tables = doc.get("tables")
    if not isinstance(tables, dict) or "cells" not in tables or "meta" not in tables:
        raise InputFileError(f"{where}: no cells and meta tables")
    for name, t in tables.items():
        ok = (isinstance(t, dict) and isinstance(t.get("columns"), list)
              and isinstance(t.get("rows"), list)
              and all(isinstance(r, list) and len(r) == len(t["columns"]) for r in t["rows"]))
        if not ok:
            raise InputFileError(f"{where}: table {name!r} is not columns and rows of their "
                                 "length")
    schema = store_type.columns()
    for name, t in tables.items():
        if name in LEFT_OUT or name == "imported":
            continue
        if name not in schema:
            raise InputFileError(f"{where}: table {name!r} is not one of a {kind} store")
        if list(t["columns"]) != schema[name]:
            raise InputFileError(f"{where}: table {name!r} has columns "
                                 f"{', '.join(t['columns'])}; this fidelity's have "
                                 f"{', '.join(schema[name])}")
    if not isinstance(doc.get("detections_sha256"), dict):
        raise InputFileError(f"{where}: no detections_sha256")
    return doc


#: Provenance lists a merge joins (each distinct entry once, the store's first).
JOINED_META = ("machines", "versions_seen")


def _json_or(text: Any, default: Any) -> Any:
    try:
        return json.loads(text)
    except (TypeError, ValueError):
        return default


def _check_joinable(store: ResultsStore, tables: dict[str, Any], meta: dict[str, Any],
                    where: str) -> None:
    """Refuse to join a scores file into a store that holds cells when the two were not run
    on the same things: a model of the same name from another file (or, in a validation,
    image limit), other preprocessing, other images for the same ids, other annotations, or
    another COCO scorer (``tables``: the file's; ``meta``: its provenance, parsed)."""
    mine = store.models()
    for row in tables.get("models", {}).get("rows", []):
        name, theirs = str(row[0]), RegisteredModel(row[1], row[2], row[3],
                                                     _json_or(row[4], {}) or {})
        if name not in mine:
            continue
        why = store._model_conflict(mine[name].sha256, mine[name].limit_images,
                                    theirs.sha256, theirs.limit_images)
        a, b = preprocessing_of(mine[name].settings), preprocessing_of(theirs.settings)
        if why is None and a is not None and b is not None and a != b:
            why = f"was run with other preprocessing ({b}; this store's: {a})"
        if why:
            raise InputFileError(f"{where}: model {name!r} {why}; its cells cannot join the "
                                 f"store {store.path}")
    images = {int(r[0]): ImageEntry(int(r[0]), str(r[1]), int(r[2]), str(r[3]))
              for r in tables.get("images", {}).get("rows", [])}
    store.check_images(images, where)
    ann = ((meta.get("inputs") or {}).get("annotations") or {}).get("sha256")
    if ann:
        store.check_annotations(where, ann)
    here = {str(e.get("scorer") if isinstance(e, dict) else e)
            for e in store.meta().get("scorers") or []}
    there = {str(e.get("scorer") if isinstance(e, dict) else e)
             for e in meta.get("scorers") or []}
    if here and there and not there <= here:
        raise InputFileError(f"{where}: scored by {', '.join(sorted(there))}, the store "
                             f"{store.path} by {', '.join(sorted(here))}; re-score one of them "
                             "(--rescore) first")


def import_scores(store: ResultsStore, path: str | os.PathLike[str],
                  doc: dict[str, Any] | None = None) -> ScoresTransfer:
    """Make ``store`` hold the cells of the scores file ``path``, in one transaction.

    A new store takes every row. A store that holds cells already (another machine's share of
    the same run) takes the cells it does not have, with their fold and draw scores (and a
    validation's camera records it lacks), after :func:`_check_joinable`; its own cells and
    provenance stay, the machines and versions that computed the file's cells join its lists.
    ``meta["imported"]`` lists the file (name, SHA-256, export time, the fidelity that wrote
    it, how many cells it brought) after those imported before; the ``imported`` table has
    each imported cell's source and detections digest. ``doc``: the file's content as
    :func:`read_scores` returned it (read here when not given). The transfer counts the
    cells the store took."""
    doc = read_scores(path, type(store)) if doc is None else doc
    p = Path(path)
    where = display_path(p)
    tables: dict[str, Any] = doc["tables"]
    theirs = {str(k): _json_or(v, None) for k, v in tables["meta"]["rows"]}
    cols = tables["cells"]["columns"]
    joining = bool(store.db.execute("SELECT COUNT(*) FROM cells").fetchone()[0])
    if joining:
        _check_joinable(store, tables, theirs, where)
    present = {cell_key(tuple(r)) for r in store.db.execute(
        f"SELECT {', '.join(store.cell_columns)} FROM cells")}
    new_cells = [r for r in tables["cells"]["rows"] if _row_key(r, cols, store) not in present]
    sha256 = file_sha256(p)
    if joining and not new_cells:  # the store holds every cell of the file: nothing changes
        return _transfer(p, sha256, store.kind, {"cells": {"columns": cols, "rows": []}})
    source = {"file": p.name, "sha256": sha256, "exported": doc.get("exported"),
              "fidelity": doc.get("fidelity"), "cells": len(new_cells)}
    mine = store.meta()
    digests: dict[str, Any] = doc["detections_sha256"]
    try:
        with store.db:
            for name, t in tables.items():
                if name in LEFT_OUT or name in ("imported", "meta") or not t["rows"]:
                    continue
                rows = t["rows"]
                if all(c in t["columns"] for c in store.cell_columns):  # cells, folds, draws
                    rows = [r for r in rows if _row_key(r, t["columns"], store) not in present]
                elif joining:  # models, images, cases: by their first column, the store's kept
                    have = {r[0]: list(r) for r in store.db.execute(f"SELECT * FROM {name}")}
                    differ = [r for r in rows if r[0] in have and have[r[0]] != list(r)
                              and name == "cases"]
                    if differ:
                        raise InputFileError(f"{where}: {name} {differ[0][0]!r} differs from "
                                             f"the store's ({store.path})")
                    rows = [r for r in rows if r[0] not in have]
                marks = ", ".join("?" * len(t["columns"]))
                store.db.executemany(f"INSERT INTO {name} VALUES ({marks})", rows)
            meta: dict[str, Any] = {k: v for k, v in theirs.items()
                                    if k not in ("last_run", "imported")}
            if joining:
                meta = {k: [*(mine.get(k) or []),
                            *[e for e in theirs.get(k) or [] if e not in (mine.get(k) or [])]]
                        for k in JOINED_META if mine.get(k) or theirs.get(k)}
            before = (mine if joining else theirs).get("imported") or []
            meta["imported"] = [*before, source]
            store.db.executemany("INSERT OR REPLACE INTO meta VALUES (?, ?)",
                                 [(k, json.dumps(v)) for k, v in meta.items()])
            for r in new_cells:
                key = _row_key(r, cols, store)
                store.db.execute("INSERT INTO imported VALUES (?, ?)", (key, json.dumps(
                    source | {"detections_sha256": digests.get(key)})))
    except InputFileError:
        raise
    except Exception as exc:  # noqa: BLE001 - sqlite3 and value errors of a damaged file
        if type(exc).__module__ != "sqlite3" and not isinstance(exc, (TypeError, ValueError)):
            raise
        raise InputFileError(f"{where}: its rows do not fit a {store.kind} store ({exc})"
                             ) from None
    return _transfer(p, sha256, store.kind, {"cells": {"columns": cols, "rows": new_cells}})


def scores_models(doc: dict[str, Any]) -> list[str]:
    """The models whose cells a scores file's content (:func:`read_scores`) holds, in their
    first cell's order."""
    t = doc["tables"]["cells"]
    i = t["columns"].index("model") if "model" in t["columns"] else None
    return [] if i is None else list(dict.fromkeys(str(r[i]) for r in t["rows"]))


def scores_file_entry(path: str | os.PathLike[str], doc: dict[str, Any],
                      root: str | os.PathLike[str] | None = None) -> dict[str, Any]:
    """How a table names a scores file it is rebuilt from (``provenance.scores_files``):
    ``{"path", "sha256", "models"}``. ``path`` is relative to ``root`` (the source checkout,
    e.g. ``reports/coco/resweep/yolox_nano.scores.json.gz``) when the file lies below it,
    else the path as given; ``sha256`` of its bytes; ``models`` those with cells in it
    (:func:`scores_models` of ``doc``, its content)."""
    p = Path(path)
    shown = str(p)
    if root is not None:
        with contextlib.suppress(ValueError):
            shown = p.resolve().relative_to(Path(root).resolve()).as_posix()
    return {"path": shown, "sha256": file_sha256(p), "models": scores_models(doc)}


#: The provenance key (of a store's ``meta``, a tables.json's ``meta`` and a table's
#: ``provenance``) naming the scores files a table is rebuilt from.
SCORES_FILES_KEY = "scores_files"


@contextlib.contextmanager
def scores_store_folder(path: str | os.PathLike[str] | list[str | os.PathLike[str]],
                        store_type: type[ResultsStore],
                        root: str | os.PathLike[str] | None = None) -> Iterator[Path]:
    """A temporary store folder holding the cells of the scores file ``path``, or of each of
    a list of them in turn (:func:`import_scores` into a new ``store_type``), removed when the
    block ends: what ``fidelity tables FILE...`` and ``fidelity sweep --status --out FILE``
    read. Its provenance names the files (``meta["scores_files"]``,
    :func:`scores_file_entry`, paths relative to ``root`` where below it)."""
    paths = list(path) if isinstance(path, list) else [path]
    docs = [read_scores(p, store_type) for p in paths]
    with tempfile.TemporaryDirectory(prefix="fidelity-scores-") as folder:
        store = store_type(folder)
        try:
            for p, doc in zip(paths, docs, strict=True):
                import_scores(store, p, doc)
            entries = [scores_file_entry(p, doc, root) for p, doc in zip(paths, docs,
                                                                         strict=True)]
            with store.db:
                store.db.execute("INSERT OR REPLACE INTO meta VALUES (?, ?)",
                                 (SCORES_FILES_KEY, json.dumps(entries)))
        finally:
            store.close()
        yield Path(folder)


__all__ = ["JOINED_META", "LEFT_OUT", "SCORES_FILES_KEY", "SCORES_FORMAT", "SCORES_VERSION",
           "ScoresTransfer", "detections_digest", "export_scores", "import_scores",
           "is_scores_file", "read_scores", "scores_file_entry", "scores_models",
           "scores_store_folder"]
