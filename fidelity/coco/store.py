"""Crash-safe SQLite results stores shared by long runs (the COCO sweep, the validation).

A store is one SQLite file in a folder, in WAL mode with ``synchronous=FULL``: every committed
transaction survives ``kill -9`` and a rerun resumes from what is stored. Each store has a
``meta`` table (JSON provenance values) and a ``models`` table (name, file, sha256, image limit,
settings) so that detections of different model files are never mixed; subclasses add their own
tables in :attr:`ResultsStore.schema`. Raw detections are kept as zlib-compressed float32
``(n, 6)`` arrays (x1, y1, x2, y2, score, class), so re-scoring needs no inference.
"""

from __future__ import annotations

import json
import os
import sqlite3
import time
import zlib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from fidelity.errors import InputFileError, InvalidValueError

__all__ = ["RegisteredModel", "ResultsStore", "pack_detections", "unpack_detections"]

_COMMON_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS models (
    model TEXT PRIMARY KEY, file TEXT, sha256 TEXT, limit_images INTEGER, settings TEXT);
"""


def pack_detections(d: np.ndarray) -> bytes:
    """(n, 6) detections -> zlib-compressed float32 bytes."""
    return zlib.compress(np.ascontiguousarray(d, dtype=np.float32).tobytes(), 1)


def unpack_detections(blob: bytes) -> np.ndarray:
    """Inverse of :func:`pack_detections`."""
    return np.frombuffer(zlib.decompress(blob), dtype=np.float32).reshape(-1, 6)


@dataclass(frozen=True)
class RegisteredModel:
    """A model as a store registered it: its ONNX ``file`` name and ``sha256``, the image
    limit of its run (``limit_images``; None = every image) and the detector's ``settings``
    (provenance as the detector describes itself, JSON; ``settings["earlier"]`` lists the
    registrations a run replaced, see :meth:`ResultsStore.register_model`)."""

    file: str
    sha256: str
    limit_images: int | None
    settings: dict[str, Any]

    def to_json(self) -> dict[str, Any]:
        """``{"file", "sha256", "limit_images", "settings"}``."""
        return {"file": self.file, "sha256": self.sha256, "limit_images": self.limit_images,
                "settings": self.settings}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> RegisteredModel:
        """Inverse of :meth:`to_json`."""
        return cls(data["file"], data["sha256"], data.get("limit_images"),
                   dict(data.get("settings") or {}))


#: Seconds a store waits for another process's lock before giving up.
BUSY_TIMEOUT_S = 60.0


def _enter_wal_mode(db: sqlite3.Connection, path: Path) -> None:
    """Switch to WAL, waiting while another process holds the file.

    SQLite answers ``PRAGMA journal_mode=WAL`` with "database is locked" at once, without its
    busy handler, while another connection is creating or switching the same file (two sweep
    processes started together on a new store), so the switch is retried with backoff up to
    :data:`BUSY_TIMEOUT_S`.
    """
    deadline = time.monotonic() + BUSY_TIMEOUT_S
    delay = 0.005
    while True:
        try:
            mode = db.execute("PRAGMA journal_mode=WAL").fetchone()[0]
        except sqlite3.OperationalError as exc:
            if "locked" not in str(exc) or time.monotonic() > deadline:
                raise InputFileError(f"{path}: cannot open the store: {exc}") from exc
        else:
            if str(mode).lower() == "wal":
                return
            if time.monotonic() > deadline:
                raise InputFileError(f"{path}: cannot switch the store to WAL (mode {mode})")
        time.sleep(delay)
        delay = min(2 * delay, 0.25)


class ResultsStore:
    """Base of the results stores: connection, provenance (``meta``) and registered models.

    Subclasses set :attr:`store_name` (file name in the folder), :attr:`kind` (for messages)
    and :attr:`schema` (their own tables), and may override :meth:`_model_conflict`.
    """

    store_name: ClassVar[str] = "results.sqlite"
    kind: ClassVar[str] = "results"
    schema: ClassVar[str] = ""

    def __init__(self, folder: str | os.PathLike[str], *, create: bool = True) -> None:
        self.folder = Path(folder)
        self.path = self.folder / self.store_name
        if not create and not self.path.is_file():
            raise InputFileError(f"{self.folder}: no {self.kind} store ({self.store_name}) in this folder")
        self.folder.mkdir(parents=True, exist_ok=True)
        self.db = sqlite3.connect(str(self.path), timeout=BUSY_TIMEOUT_S)
        _enter_wal_mode(self.db, self.path)
        self.db.execute("PRAGMA synchronous=FULL")
        self.db.executescript(_COMMON_SCHEMA + self.schema)
        self.db.commit()

    def close(self) -> None:
        """Close the connection."""
        self.db.close()

    def set_meta(self, key: str, value: Any) -> None:
        """Store a JSON-serialisable provenance value."""
        with self.db:
            self.db.execute("INSERT OR REPLACE INTO meta VALUES (?, ?)", (key, json.dumps(value)))

    def meta(self) -> dict[str, Any]:
        """All provenance values."""
        return {k: json.loads(v) for k, v in self.db.execute("SELECT key, value FROM meta")}

    def _model_conflict(self, stored_sha256: str, stored_limit: int | None, sha256: str,
                        limit: int | None) -> str | None:
        """Why a model cannot be registered again with these values (None: it can).

        By default only a different file (sha256) conflicts; a different image limit extends
        or narrows the run over the same model.
        """
        if stored_sha256 != sha256:
            return f"was run from a different file (sha256 {stored_sha256[:16]} != {sha256[:16]})"
        return None

    def register_model(self, model: str, file: str, sha256: str, limit: int | None,
                       settings: dict[str, Any]) -> None:
        """Record a model; a conflicting registration (see :meth:`_model_conflict`) is an error.

        A registration that changes the image limit or a setting (a sweep extended with other
        threads, say) keeps what it replaced under ``settings["earlier"]``: one entry per
        replaced registration, ``{"limit_images": ..., <settings that differed>}``, oldest
        first, so that a store's provenance covers every run that made its detections.
        """
        row = self.db.execute("SELECT sha256, limit_images, settings FROM models WHERE model=?",
                              (model,)).fetchone()
        if row:
            why = self._model_conflict(row[0], row[1], sha256, limit)
            if why:
                raise InvalidValueError(f"store {self.path}: model {model!r} {why}")
            old = json.loads(row[2])
            earlier = old.pop("earlier", [])
            changed = {k: v for k, v in old.items() if settings.get(k) != v}
            if changed or row[1] != limit:
                earlier.append({"limit_images": row[1]} | changed)
            if earlier:
                settings = settings | {"earlier": earlier}
        with self.db:
            self.db.execute("INSERT OR REPLACE INTO models VALUES (?, ?, ?, ?, ?)",
                            (model, file, sha256, limit, json.dumps(settings)))

    def models(self) -> dict[str, RegisteredModel]:
        """Registered models by name."""
        return {m: RegisteredModel(f, s, lim, json.loads(st))
                for m, f, s, lim, st in self.db.execute("SELECT * FROM models")}
