"""Crash-safe SQLite results stores shared by long runs (the COCO sweep, the validation).

A store is one SQLite file in a folder, in WAL mode with ``synchronous=FULL``: every committed
transaction survives ``kill -9`` and a rerun resumes from what is stored. Each store has a
``meta`` table (JSON provenance values) and a ``models`` table (name, file, sha256, image limit,
settings) so that detections of different model files are never mixed; subclasses add their own
tables in :attr:`ResultsStore.schema`. Raw detections are kept as zlib-compressed float32
``(n, 6)`` arrays (x1, y1, x2, y2, score, class), so re-scoring needs no inference.

Long runs (issue 23):

* **Damaged or foreign stores.** Opening checks the file (an SQLite header, not shorter than
  the header says), the format version (``PRAGMA user_version``, :attr:`ResultsStore.format`;
  a store written by a newer fidelity is refused) and every table's columns against the
  schema; a damaged page met later is reported the same way. Each is an
  :class:`~fidelity.core.errors.InputFileError` naming the store, never a traceback.
* **Inputs.** ``images`` records each image a run used (file name, size, SHA-256 of the bytes)
  and ``meta["inputs"]`` the annotation file's SHA-256: a resume over other images or other
  annotations is refused, naming what differs (:meth:`ResultsStore.check_images`,
  :meth:`ResultsStore.check_annotations`); models are checked by their SHA-256
  (:meth:`ResultsStore.register_model`).
* **Leases.** Processes that share a store claim cells in ``leases`` (one owner per cell) and
  keep their ``owners`` row's heartbeat fresh (:class:`LeaseKeeper`); a cell claimed by a live
  owner is left to it, a claim whose owner stopped beating for :data:`LEASE_STALE_S` seconds
  (or whose process is gone, on the same host) is taken over (:meth:`ResultsStore.claim`).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import socket
import sqlite3
import threading
import time
import uuid
import zlib
from collections import Counter
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import field
from pathlib import Path
from typing import Any, ClassVar, Generic, TypeVar

import numpy as np

from fidelity.core.errors import InputFileError, InvalidValueError
from fidelity.core.fileio import file_sha256, remove_stale_temporaries
from fidelity.core.record import record

S = TypeVar("S", bound="ResultsStore")

__all__ = ["LEASE_STALE_S", "Claim", "EvaluationStore", "ImageEntry", "ImageSet",
           "LeaseKeeper", "Owner", "RegisteredModel", "ResultsStore", "evaluation_store_dir",
           "pack_detections", "process_gone", "unpack_detections"]

_COMMON_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS models (
    model TEXT PRIMARY KEY, file TEXT, sha256 TEXT, limit_images INTEGER, settings TEXT);
CREATE TABLE IF NOT EXISTS images (
    image_id INTEGER PRIMARY KEY, file_name TEXT NOT NULL, size INTEGER NOT NULL,
    sha256 TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS owners (
    owner TEXT PRIMARY KEY, host TEXT NOT NULL, pid INTEGER NOT NULL, started REAL NOT NULL,
    heartbeat REAL NOT NULL, info TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS leases (
    cell TEXT PRIMARY KEY, owner TEXT NOT NULL, claimed REAL NOT NULL);
"""

#: Seconds without a heartbeat after which a claim is taken over by another run.
LEASE_STALE_S = 60.0
#: Seconds between two heartbeats of a running owner (:class:`LeaseKeeper`).
HEARTBEAT_S = 10.0


def pack_detections(d: np.ndarray) -> bytes:
    """(n, 6) detections -> zlib-compressed float32 bytes."""
    return zlib.compress(np.ascontiguousarray(d, dtype=np.float32).tobytes(), 1)


def unpack_detections(blob: bytes) -> np.ndarray:
    """Inverse of :func:`pack_detections`."""
    return np.frombuffer(zlib.decompress(blob), dtype=np.float32).reshape(-1, 6)


@record
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
                raise InputFileError(f"{path}: cannot open the results store: {exc}") from exc
        else:
            if str(mode).lower() == "wal":
                return
            if time.monotonic() > deadline:
                raise InputFileError(f"{path}: cannot switch the store to WAL (mode {mode})")
        time.sleep(delay)
        delay = min(2 * delay, 0.25)


_SQLITE_MAGIC = b"SQLite format 3\x00"

#: Store files this process has SQLite connections to (resolved path -> open connections).
#: While one is open, nothing else in the process may open and close that file: closing any
#: file descriptor of it drops every POSIX lock the process holds on it, SQLite's included,
#: and another process's writes then corrupt the database ("How To Corrupt An SQLite
#: Database File", section 2.2).
_OPEN_STORES: Counter[Path] = Counter()
#: Re-entrant: a connection dropped without ``close()`` is closed by ``__del__``, which the
#: garbage collector may run inside any allocation, also while this thread holds the lock.
_OPEN_LOCK = threading.RLock()


def preprocessing_of(settings: Mapping[str, Any]) -> str | None:
    """The preprocessing a detector's registered ``settings`` name
    (``settings["conventions"]["preprocess"]``, :meth:`fidelity.coco.detectors.Detector.describe`);
    None where they name none."""
    conventions = settings.get("conventions")
    found = conventions.get("preprocess") if isinstance(conventions, Mapping) else None
    return str(found) if found is not None else None


def check_sqlite_file(path: Path, kind: str) -> None:
    """Refuse a file that cannot be an intact SQLite database, before SQLite opens it.

    Checks the 16-byte magic string and that the file is not shorter than the page count of
    its header says (when the header's count is valid: its change counter equals its
    version-valid-for number; SQLite file format, section 1.3). An empty file is a new store.
    Raises :class:`InputFileError` naming the file. Skipped while this process has the file
    open through SQLite (it was checked then, and reading it now would drop SQLite's locks).
    """
    resolved = path.resolve()
    with _OPEN_LOCK:
        if _OPEN_STORES[resolved] > 0:
            return
    try:
        size = path.stat().st_size
        with open(path, "rb") as fh:
            head = fh.read(100)
    except FileNotFoundError:
        return
    except OSError as exc:
        raise InputFileError(f"{path}: cannot read the {kind} store: {exc}") from exc
    if size == 0:
        return
    if not head.startswith(_SQLITE_MAGIC) or len(head) < 100:
        raise InputFileError(f"{path}: not a {kind} store (not an SQLite database file)")
    page_size = int.from_bytes(head[16:18], "big")
    page_size = 65536 if page_size == 1 else page_size
    pages = int.from_bytes(head[28:32], "big")
    valid = head[24:28] == head[92:96]
    if valid and pages and page_size and size < pages * page_size:
        raise InputFileError(f"{path}: the {kind} store is truncated ({size} bytes, its header "
                             f"says {pages * page_size}); restore it or start a new store")


class _DamageGuard:
    """Context manager: SQLite's plain DatabaseError (a damaged file; not its subclasses,
    which are about the statement) becomes an input error naming the store."""

    def __init__(self, path: Path, kind: str) -> None:
        self.path, self.kind = path, kind

    def __enter__(self) -> None:
        return None

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None,
                 tb: Any) -> None:
        if kind is sqlite3.DatabaseError:
            raise InputFileError(f"{self.path}: the {self.kind} store is damaged ({exc}); "
                                 "restore it or start a new store") from exc


class _GuardedCursor(sqlite3.Cursor):
    """A cursor that reports a damaged database as an input error naming the store."""

    store_path: Path = Path("?")
    store_kind: str = "results"

    def _guarded(self) -> _DamageGuard:
        return _DamageGuard(self.store_path, self.store_kind)

    def execute(self, sql: str, parameters: Any = (), /) -> _GuardedCursor:
        with self._guarded():
            super().execute(sql, parameters)
        return self

    def executemany(self, sql: str, seq_of_parameters: Any, /) -> _GuardedCursor:
        with self._guarded():
            super().executemany(sql, seq_of_parameters)
        return self

    def fetchone(self) -> Any:
        with self._guarded():
            return super().fetchone()

    def fetchall(self) -> list[Any]:
        with self._guarded():
            return super().fetchall()

    def __next__(self) -> Any:
        with self._guarded():
            return super().__next__()


class _GuardedConnection(sqlite3.Connection):
    """A connection whose statements run on :class:`_GuardedCursor` (damage -> input error),
    counted in :data:`_OPEN_STORES` while it is open."""

    store_path: Path = Path("?")
    store_kind: str = "results"
    _counted: Path | None = None

    def close(self) -> None:
        with _OPEN_LOCK:
            if self._counted is not None:
                _OPEN_STORES[self._counted] -= 1
                if _OPEN_STORES[self._counted] <= 0:
                    del _OPEN_STORES[self._counted]
                self._counted = None
        super().close()

    def __del__(self) -> None:  # a connection dropped without close() is closed by SQLite
        with contextlib.suppress(Exception):
            self.close()

    def _cursor(self) -> _GuardedCursor:
        cur = self.cursor(_GuardedCursor)
        cur.store_path, cur.store_kind = self.store_path, self.store_kind
        return cur

    def execute(self, sql: str, parameters: Any = (), /) -> _GuardedCursor:
        return self._cursor().execute(sql, parameters)

    def executemany(self, sql: str, parameters: Any, /) -> _GuardedCursor:
        return self._cursor().executemany(sql, parameters)


def _connect(path: Path, kind: str) -> _GuardedConnection:
    # each connection is used by one thread at a time; a scoring thread's store is closed by
    # the thread that started it, after the thread has ended
    db = sqlite3.connect(str(path), timeout=BUSY_TIMEOUT_S, factory=_GuardedConnection,
                         check_same_thread=False)
    assert isinstance(db, _GuardedConnection)
    db.store_path, db.store_kind = path, kind
    resolved = path.resolve()
    with _OPEN_LOCK:
        db._counted = resolved
        _OPEN_STORES[resolved] += 1
    return db


def _schema_columns(schema: str) -> dict[str, list[str]]:
    """Table -> column names of a schema script (built in an in-memory database)."""
    mem = sqlite3.connect(":memory:")
    try:
        mem.executescript(schema)
        tables = [r[0] for r in mem.execute("SELECT name FROM sqlite_master WHERE type='table'")]
        return {t: [c[1] for c in mem.execute(f"PRAGMA table_info({t})")] for t in tables}
    finally:
        mem.close()


@record
class Owner:
    """A run that works on a store: a unique ``id``, its ``host``, process id, start time
    (seconds since the epoch) and what it is (``info``: executor, workers; JSON)."""

    id: str
    host: str
    pid: int
    started: float
    info: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def this_process(cls, info: Mapping[str, Any] | None = None) -> Owner:
        """A new owner for a run in this process."""
        return cls(uuid.uuid4().hex, socket.gethostname(), os.getpid(), time.time(),
                   dict(info or {}))


@record
class Claim:
    """A cell claimed by a run: the cell's key (as the store's ``cells`` key, a tuple), its
    :class:`Owner`, when it was claimed and the owner's last heartbeat (seconds since the
    epoch)."""

    cell: tuple[Any, ...]
    owner: Owner
    claimed: float
    heartbeat: float


def process_gone(host: str, pid: int) -> bool:
    """Whether process ``pid`` on ``host`` is known to have ended (only this host can tell)."""
    if host != socket.gethostname():
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except PermissionError:
        return False
    return False


def cell_key(cell: Sequence[Any]) -> str:
    """The text key of a cell in the ``leases`` table (its key columns as a JSON list)."""
    return json.dumps([float(v) if isinstance(v, (int, float)) and not isinstance(v, bool)
                       else v for v in cell])


@record
class ImageEntry:
    """An input image as a run used it: COCO ``image_id``, ``file_name``, ``size`` in bytes
    and the SHA-256 of its bytes (no time stamps: a copy of the same file matches)."""

    image_id: int
    file_name: str
    size: int
    sha256: str


class ImageSet:
    """The annotated images of a run: the folder, the COCO annotations and the ids (ascending).

    :meth:`entries` hashes the files (once); :meth:`read` returns an image's bytes and checks
    them against that hash, so the bytes a detector sees are the bytes the store recorded.
    """

    def __init__(self, folder: Path, coco: Any, ids: Sequence[int]) -> None:
        self.folder = Path(folder)
        self.coco = coco
        self.ids = list(ids)
        self._entries: dict[int, ImageEntry] = {}

    def file_name(self, image_id: int) -> str:
        """The file name of an image id."""
        return str(self.coco.imgs[image_id]["file_name"])

    def path(self, image_id: int) -> Path:
        """The file of an image id."""
        return self.folder / self.file_name(image_id)

    def _read(self, image_id: int) -> bytes:
        p = self.path(image_id)
        try:
            return p.read_bytes()
        except OSError as exc:
            raise InputFileError(f"{p}: cannot read image: {exc}") from exc

    def entries(self, ids: Iterable[int] | None = None) -> dict[int, ImageEntry]:
        """:class:`ImageEntry` of each image id (default: all), hashing files not hashed yet."""
        out = {}
        for i in self.ids if ids is None else ids:
            e = self._entries.get(i)
            if e is None:
                data = self._read(i)
                e = ImageEntry(i, self.file_name(i), len(data), hashlib.sha256(data).hexdigest())
                self._entries[i] = e
            out[i] = e
        return out

    def read(self, image_id: int) -> bytes:
        """The bytes of an image; an error if they differ from the hashed ones."""
        data = self._read(image_id)
        e = self._entries.get(image_id)
        if e is not None and hashlib.sha256(data).hexdigest() != e.sha256:
            raise InputFileError(f"{self.path(image_id)}: the image changed during the run")
        return data

    def fingerprint(self, ids: Iterable[int] | None = None) -> str:
        """SHA-256 over the sorted ``(file name, size, SHA-256)`` of the images: one value
        that names the image set (mtime-independent)."""
        digest = hashlib.sha256()
        for e in sorted(self.entries(ids).values(), key=lambda e: e.file_name):
            digest.update(f"{e.file_name}\t{e.size}\t{e.sha256}\n".encode())
        return digest.hexdigest()


class ResultsStore:
    """Base of the results stores: connection, provenance (``meta``), registered models,
    recorded inputs (``images``) and leases (``owners``, ``leases``).

    Subclasses set :attr:`store_name` (file name in the folder), :attr:`kind` (for messages)
    and :attr:`schema` (their own tables), and may override :meth:`_model_conflict`.
    :attr:`format` is the store format this code writes (``PRAGMA user_version``; 0 is a
    store from before the number was written, read as format 1).
    """

    store_name: ClassVar[str] = "results.sqlite"
    kind: ClassVar[str] = "results"
    schema: ClassVar[str] = ""
    format: ClassVar[int] = 1
    #: Tables every store of this kind has had from its first version (the others, added
    #: later, are created in an older store when it is opened).
    core_tables: ClassVar[tuple[str, ...]] = ("meta", "models")
    #: The key columns of a cell in the ``cells`` table (and of its detections).
    cell_columns: ClassVar[tuple[str, ...]] = ()

    def __init__(self, folder: str | os.PathLike[str], *, create: bool = True) -> None:
        self.folder = Path(folder)
        self.path = self.folder / self.store_name
        if not create and not self.path.is_file():
            raise InputFileError(f"{self.folder}: no {self.kind} store ({self.store_name}) in this folder")
        if self.folder.exists() and not self.folder.is_dir():
            raise InputFileError(f"{self.folder}: not a folder (a {self.kind} store is a folder)")
        check_sqlite_file(self.path, self.kind)
        if not create and self.path.stat().st_size == 0:
            raise InputFileError(f"{self.path}: not a {self.kind} store (an empty file)")
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            self.db = _connect(self.path, self.kind)
            if create:  # a reader (status, tables) changes nothing in the file
                _enter_wal_mode(self.db, self.path)
            self.db.execute("PRAGMA synchronous=FULL")
            have = self._check_schema()
            if have or create:
                missing = [t for t in self.core_tables if t not in have]
                if have and missing:
                    raise InputFileError(f"{self.path}: not a {self.kind} store (no table "
                                         f"{missing[0]!r})")
                if set(_schema_columns(_COMMON_SCHEMA + self.schema)) - have:
                    # one transaction: a second process never sees half the tables
                    self.db.commit()
                    self.db.executescript("BEGIN IMMEDIATE;\n" + _COMMON_SCHEMA + self.schema
                                          + "\nCOMMIT;")
            else:
                raise InputFileError(f"{self.path}: not a {self.kind} store (no tables)")
            version = self.db.execute("PRAGMA user_version").fetchone()[0]
            if create and version != self.format:
                self.db.execute(f"PRAGMA user_version={int(self.format)}")
                self.db.commit()
        except (OSError, sqlite3.OperationalError) as exc:  # a full disk, no permission
            raise InputFileError(f"{self.path}: cannot open the results store: {exc}") from exc

    def _check_schema(self) -> set[str]:
        """Refuse a store of a newer format or whose tables are not this kind's; returns the
        tables it has."""
        version = self.db.execute("PRAGMA user_version").fetchone()[0]
        if version > self.format:
            raise InputFileError(f"{self.path}: {self.kind} store of format {version}, written "
                                 f"by a newer fidelity (this one reads format {self.format} "
                                 "and older); upgrade fidelity or start a new store")
        have = {r[0] for r in self.db.execute(
            "SELECT name FROM sqlite_master WHERE type='table'").fetchall()}
        for table, columns in _schema_columns(_COMMON_SCHEMA + self.schema).items():
            if table not in have:
                continue
            got = [c[1] for c in self.db.execute(f"PRAGMA table_info({table})").fetchall()]
            if got != columns:
                raise InputFileError(
                    f"{self.path}: not a {self.kind} store of this fidelity (table {table!r} "
                    f"has columns {', '.join(got)}; expected {', '.join(columns)})")
        return have

    def close(self) -> None:
        """Close the connection."""
        self.db.close()

    @classmethod
    def full_schema(cls) -> str:
        """The schema script of this kind of store (common and own tables)."""
        return _COMMON_SCHEMA + cls.schema

    @classmethod
    def columns(cls) -> dict[str, list[str]]:
        """Table -> column names of this kind of store."""
        return _schema_columns(cls.full_schema())

    def imported(self) -> dict[str, dict[str, Any]]:
        """Cells imported from a scores file (:mod:`fidelity.coco.scores`), by
        :func:`cell_key`: the file's name, SHA-256 and export time, and the cell's
        ``detections_sha256``. Empty for a store without the table (another kind, or one of
        an earlier version opened to read)."""
        tables = {r[0] for r in self.db.execute(
            "SELECT name FROM sqlite_master WHERE type='table'").fetchall()}
        if "imported" not in tables:
            return {}
        return {k: self._json(src, f"imported cell {k}")
                for k, src in self.db.execute("SELECT cell, source FROM imported")}

    def check_detections(self, key: Sequence[Any]) -> None:
        """Raise :class:`InputFileError` when the cell ``key`` (its :attr:`cell_columns`
        values) was imported from a scores file: its detections are not in this store."""
        source = self.imported().get(cell_key(key))
        if source is not None:
            what = " ".join(f"ΔE {v:g}" if isinstance(v, float) else str(v) for v in key)
            raise InputFileError(
                f"{self.path}: cell {what} was imported from {source.get('file')} without its "
                "detections (what needs them needs the store it was run in)")

    def complete_scores(self, coco: Any, method: str = "auto") -> int:
        """Compute and keep what a report needs of every finished cell and the store lacks
        (fold and draw scores), from the stored detections; how many cells there are. Stores
        with such caches override it."""
        return 0

    def set_meta(self, key: str, value: Any) -> None:
        """Store a JSON-serialisable provenance value."""
        with self.db:
            self.db.execute("INSERT OR REPLACE INTO meta VALUES (?, ?)", (key, json.dumps(value)))

    def _json(self, text: Any, where: str) -> Any:
        """A JSON value the store holds; an input error naming the store when it is not one."""
        try:
            return json.loads(text)
        except (TypeError, ValueError) as exc:
            raise InputFileError(f"{self.path}: the {self.kind} store is damaged ({where} is "
                                 f"not JSON: {exc})") from None

    def meta(self) -> dict[str, Any]:
        """All provenance values."""
        return {k: self._json(v, f"meta {k!r}")
                for k, v in self.db.execute("SELECT key, value FROM meta")}

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
            made, now = preprocessing_of(old), preprocessing_of(settings)
            if made is not None and now is not None and made != now:
                raise InvalidValueError(
                    f"store {self.path}: model {model!r}'s detections were made with other "
                    f"preprocessing ({made}; this version: {now}); they would mix: give a new "
                    "store (this one's scores stay readable, e.g. by tables)")
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
        return {m: RegisteredModel(f, s, lim, self._json(st, f"model {m!r}"))
                for m, f, s, lim, st in self.db.execute("SELECT * FROM models")}


    # recorded inputs --------------------------------------------------------------------------
    def check_images(self, entries: Mapping[int, ImageEntry], folder: str | os.PathLike[str]
                     ) -> int:
        """Refuse images that differ from those recorded for the same ids; record new ones.

        ``entries``: the run's images (:meth:`ImageSet.entries`). An image whose file name,
        size or SHA-256 differs from the store's record of the same id raises
        :class:`InputFileError` naming the store, how many differ and the first one (a resume
        with ``--images`` pointing at another folder with the same file names). Returns how
        many images were recorded for the first time.
        """
        stored = {r[0]: ImageEntry(r[0], r[1], r[2], r[3]) for r in self.db.execute(
            "SELECT image_id, file_name, size, sha256 FROM images").fetchall()}
        differ = [(stored[i], e) for i, e in sorted(entries.items())
                  if i in stored and stored[i] != e]
        if differ:
            old, new = differ[0]
            what = (f"{new.file_name}: {new.size} bytes, sha256 {new.sha256[:12]}, where the "
                    f"store's was {old.size} bytes, sha256 {old.sha256[:12]}")
            raise InputFileError(
                f"{self.path}: the images in {folder} differ from the ones this store was run "
                f"on ({len(differ)} of {len(entries)}, e.g. {what}); give the original images "
                "or start a new store")
        rows = [(e.image_id, e.file_name, e.size, e.sha256) for i, e in entries.items()
                if i not in stored]
        if rows:
            with self.db:
                self.db.executemany("INSERT OR REPLACE INTO images VALUES (?, ?, ?, ?)", rows)
        return len(rows)

    def start_run(self, images: ImageSet, limits: Iterable[int | None],
                  annotations: str | os.PathLike[str]) -> None:
        """Before a run works in this store: a killed run's temporary files removed; the
        images it will use (per model the first ``limit`` of ``images.ids``, all for None) and
        its annotations checked against the store's record (:meth:`check_images`,
        :meth:`check_annotations`; a new store records them); ``meta["data"]`` written."""
        remove_stale_temporaries(self.folder)
        ids = images.ids
        used = sorted({i for n in limits for i in (ids[:n] if n else ids)})
        self.check_images(images.entries(used), images.folder)
        self.check_annotations(annotations, file_sha256(annotations))
        self.set_meta("data", {"images": str(images.folder.resolve()),
                               "annotations": str(Path(annotations).resolve()),
                               "image_count": len(ids)})

    def check_annotations(self, path: str | os.PathLike[str], sha256: str, *,
                          replace: bool = False) -> None:
        """Refuse annotations other than the store's (``meta["inputs"]["annotations"]``).

        The first run records the file's SHA-256; a later run with another file raises
        :class:`InputFileError` naming both, unless ``replace`` (a re-scoring of every cell with
        the new annotations) records the new one.
        """
        inputs = dict(self.meta().get("inputs") or {})
        old = (inputs.get("annotations") or {}).get("sha256")
        if old is not None and old != sha256 and not replace:
            raise InputFileError(
                f"{self.path}: the annotations {path} (sha256 {sha256[:12]}) differ from the "
                f"ones this store was run on (sha256 {old[:12]}, "
                f"{(inputs.get('annotations') or {}).get('file')}); give those, re-score with "
                "the new ones (--rescore) or start a new store")
        inputs["annotations"] = {"file": Path(path).name, "sha256": sha256}
        self.set_meta("inputs", inputs)

    # leases -----------------------------------------------------------------------------------
    def register_owner(self, owner: Owner, now: float | None = None) -> None:
        """Record a run that will claim cells (its first heartbeat)."""
        with self.db:
            self.db.execute("INSERT OR REPLACE INTO owners VALUES (?, ?, ?, ?, ?, ?)",
                            (owner.id, owner.host, owner.pid, owner.started,
                             time.time() if now is None else now, json.dumps(owner.info)))

    def beat(self, owner: str, now: float | None = None) -> None:
        """A heartbeat of ``owner``: its claims stay its own."""
        with self.db:
            self.db.execute("UPDATE owners SET heartbeat=? WHERE owner=?",
                            (time.time() if now is None else now, owner))

    def claim(self, cell: Sequence[Any], owner: str, *, now: float | None = None,
              stale_s: float = LEASE_STALE_S) -> bool:
        """Claim a cell for ``owner``; False when another live owner holds it.

        A claim is taken over when its owner's last heartbeat is more than ``stale_s``
        seconds old, when its owner is not registered, or when its owner's process is known to
        have ended (same host). One ``BEGIN IMMEDIATE`` transaction: two runs never both get
        a cell while its owner is live.
        """
        t = time.time() if now is None else now
        key = cell_key(cell)
        self.db.commit()
        self.db.execute("BEGIN IMMEDIATE")
        try:
            row = self.db.execute(
                "SELECT l.owner, o.heartbeat, o.host, o.pid FROM leases l LEFT JOIN owners o "
                "ON o.owner = l.owner WHERE l.cell=?", (key,)).fetchone()
            free = (row is None or row[0] == owner or row[1] is None
                    or t - float(row[1]) > stale_s or process_gone(row[2], int(row[3])))
            if free:  # a claim is a sign of life too
                self.db.execute("INSERT OR REPLACE INTO leases VALUES (?, ?, ?)", (key, owner, t))
                self.db.execute("UPDATE owners SET heartbeat=? WHERE owner=?", (t, owner))
            self.db.commit()
        except BaseException:
            self.db.rollback()
            raise
        return free

    def release(self, cell: Sequence[Any], owner: str) -> None:
        """Give up ``owner``'s claim on a cell (after finishing it)."""
        with self.db:
            self.db.execute("DELETE FROM leases WHERE cell=? AND owner=?",
                            (cell_key(cell), owner))

    def retire(self, owner: str) -> None:
        """Remove an owner and its claims (a run that ends)."""
        with self.db:
            self.db.execute("DELETE FROM leases WHERE owner=?", (owner,))
            self.db.execute("DELETE FROM owners WHERE owner=?", (owner,))

    def claims(self) -> list[Claim]:
        """Every claim with its owner (owners that left no row are shown as unknown)."""
        tables = {r[0] for r in self.db.execute(
            "SELECT name FROM sqlite_master WHERE type='table'").fetchall()}
        if not {"leases", "owners"} <= tables:  # a store from before claims, opened to read
            return []
        rows = self.db.execute(
            "SELECT l.cell, l.owner, l.claimed, o.host, o.pid, o.started, o.heartbeat, o.info "
            "FROM leases l LEFT JOIN owners o ON o.owner = l.owner ORDER BY l.claimed"
        ).fetchall()
        out = []
        for cell, owner, claimed, host, pid, started, beat, info in rows:
            out.append(Claim(tuple(json.loads(cell)),
                             Owner(owner, host or "?", int(pid or 0), float(started or 0.0),
                                   json.loads(info) if info else {}),
                             float(claimed), float(beat if beat is not None else claimed)))
        return out


class LeaseKeeper:
    """A run's membership in a store's leases: registers the :class:`Owner`, keeps its
    heartbeat fresh every ``every_s`` seconds on a thread of its own (its own connection),
    and retires it (claims dropped) on :meth:`close`.

    ``claim``/``release`` go through the run's own store connection (the thread that writes
    results). A process killed with ``kill -9`` stops beating; its claims are taken over after
    :data:`LEASE_STALE_S` seconds, or at once on the same host (its process id is gone).
    """

    def __init__(self, store: ResultsStore, info: Mapping[str, Any] | None = None, *,
                 every_s: float = HEARTBEAT_S, stale_s: float = LEASE_STALE_S,
                 clock: Callable[[], float] = time.time) -> None:
        self.store = store
        self.owner = Owner.this_process(info)
        self.stale_s = stale_s
        self.clock = clock
        store.register_owner(self.owner, clock())
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._beat, args=(every_s,), daemon=True,
                                        name="fidelity-heartbeat")
        self._thread.start()

    def _beat(self, every_s: float) -> None:
        db = _connect(self.store.path, self.store.kind)
        try:
            while not self._stop.wait(every_s):
                with db:
                    db.execute("UPDATE owners SET heartbeat=? WHERE owner=?",
                               (self.clock(), self.owner.id))
        except sqlite3.Error:  # the store went away; the run itself will report it
            pass
        finally:
            db.close()

    def claim(self, cell: Sequence[Any]) -> bool:
        """Claim a cell for this run (:meth:`ResultsStore.claim`)."""
        return self.store.claim(cell, self.owner.id, now=self.clock(), stale_s=self.stale_s)

    def release(self, cell: Sequence[Any]) -> None:
        """Release a finished cell."""
        self.store.release(cell, self.owner.id)

    def close(self) -> None:
        """Stop the heartbeat and retire the owner."""
        self._stop.set()
        self._thread.join(timeout=5)
        self.store.retire(self.owner.id)


class ThreadStores(Generic[S]):
    """One connection to a store per thread (``open_`` makes one): a run's scoring thread
    reads and writes through its own, never through another thread's. :meth:`close` closes
    every one made."""

    def __init__(self, open_: Callable[[], S]) -> None:
        self._open = open_
        self._local = threading.local()
        self._opened: list[S] = []
        self._lock = threading.Lock()

    def get(self) -> S:
        """This thread's store."""
        st: S | None = getattr(self._local, "store", None)
        if st is None:
            st = self._local.store = self._open()
            with self._lock:
                self._opened.append(st)
        return st

    def close(self) -> None:
        """Close every store this made."""
        with self._lock:
            for st in self._opened:
                st.close()
            self._opened.clear()


class EvaluationStore(ResultsStore):
    """The per-image detections of one ``fidelity evaluate`` (one model, one image set), so
    that a killed evaluation resumes where it stopped and a repeated one scores at once.

    ``detections(image_id, n, dets)``; the folder is :func:`evaluation_store_dir`, named by
    what decides the detections (the model's SHA-256, the execution provider and the image
    set's fingerprint), so a store never mixes two evaluations.
    """

    store_name = "evaluation.sqlite"
    kind = "evaluation"
    core_tables = ("meta", "models", "detections")
    schema = """
CREATE TABLE IF NOT EXISTS detections (
    image_id INTEGER PRIMARY KEY, n INTEGER NOT NULL, dets BLOB NOT NULL);
"""

    def stored_images(self) -> set[int]:
        """Image ids whose detections are stored."""
        return {r[0] for r in self.db.execute("SELECT image_id FROM detections").fetchall()}

    def add_detections(self, rows: Iterable[tuple[int, np.ndarray]]) -> None:
        """Store (image_id, detections) pairs in one transaction."""
        with self.db:
            self.db.executemany("INSERT OR REPLACE INTO detections VALUES (?, ?, ?)",
                                [(int(i), len(d), pack_detections(d)) for i, d in rows])

    def detections(self, ids: Iterable[int] | None = None) -> dict[int, np.ndarray]:
        """Stored detections (of ``ids``, default all): image_id -> (n, 6)."""
        want = None if ids is None else set(ids)
        return {i: unpack_detections(b) for i, b in self.db.execute(
            "SELECT image_id, dets FROM detections").fetchall() if want is None or i in want}


def evaluation_store_dir(model_sha256: str, provider: str, images_fingerprint: str,
                         base: str | os.PathLike[str] | None = None, *,
                         preprocessing: str | None = None) -> Path:
    """Folder of an :class:`EvaluationStore`: ``<base>/<key>``, ``base`` by default
    ``$FIDELITY_CACHE/evaluate`` or ``~/.cache/fidelity/evaluate``; ``key`` is a SHA-256 of
    the model's SHA-256, the provider, the image set's fingerprint and the detector's
    ``preprocessing`` (:func:`preprocessing_of`; first 24 hex digits), so that a version that
    prepares images differently starts a cache of its own."""
    if base is None:
        root = os.environ.get("FIDELITY_CACHE")
        base = (Path(root) if root else Path.home() / ".cache" / "fidelity") / "evaluate"
    # "unclipped": the store holds boxes as the network gives them (evaluate clips for COCO AP)
    key = hashlib.sha256(f"{model_sha256}\n{provider}\n{images_fingerprint}\nunclipped\n"
                         f"{preprocessing or ''}".encode())
    return Path(base) / key.hexdigest()[:24]
