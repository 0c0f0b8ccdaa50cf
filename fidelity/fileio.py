"""Atomic file output and input checks shared by every command.

Outputs are written to a temporary file in the destination folder and renamed into place, so a
reader never sees a half-written file and an interrupted run leaves no partial output. Inputs are
never written to: :func:`atomic_output` refuses a destination that is one of the declared inputs.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
import tempfile
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

from fidelity.errors import InputFileError


@contextlib.contextmanager
def atomic_output(
    path: str | os.PathLike[str], protect: Iterable[str | os.PathLike[str]] = ()
) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it to ``path`` when the block succeeds.

    ``protect`` lists input paths that must never be overwritten; naming one of them as output
    raises :class:`InputFileError`.
    """
    target = Path(path)
    for p in protect:
        if Path(p).exists() and target.exists() and target.resolve() == Path(p).resolve():
            raise InputFileError(f"{target}: refusing to write over an input file")
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp" + target.suffix,
                               dir=target.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    # mkstemp creates the file private (0600); an output gets the usual 0666 & ~umask.
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp_path, 0o666 & ~umask)
    try:
        yield tmp_path
        os.replace(tmp_path, target)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def write_text_atomic(path: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically and return the path."""
    with atomic_output(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def write_bytes_atomic(path: str | os.PathLike[str], data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically and return the path."""
    with atomic_output(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


#: A JSON object as the records' ``to_json`` give it (strict JSON after :func:`json_ready`).
JSONObject = dict[str, Any]


@runtime_checkable
class SupportsJson(Protocol):
    """A record that writes itself as JSON (the ``to_json`` of the project's dataclasses)."""

    def to_json(self) -> Any:
        """The record as JSON-ready Python values."""
        ...


def json_ready(obj: Any) -> Any:
    """``obj`` as strict JSON values: records with a ``to_json`` method are written by it,
    numpy scalars and arrays become Python numbers and lists, tuples lists, paths strings,
    mapping keys strings, and NaN or +-Inf ``None``. The one JSON cleaner of the project (chart
    reports, COCO tables, validation)."""
    if isinstance(obj, SupportsJson) and not isinstance(obj, type):
        return json_ready(obj.to_json())
    if isinstance(obj, Mapping):
        return {str(k): json_ready(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_ready(v) for v in obj]
    if hasattr(obj, "tolist") and hasattr(obj, "dtype"):  # numpy array or scalar
        return json_ready(obj.tolist())
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    return obj


def write_json_atomic(path: str | os.PathLike[str], obj: Any) -> Path:
    """Write ``obj`` as indented JSON (NaN is rejected: not valid JSON) atomically."""
    return write_text_atomic(path, json.dumps(obj, indent=2, allow_nan=False) + "\n")


PathLike = str | os.PathLike[str]


def check_outputs(outputs: Mapping[str, PathLike | None],
                  inputs: Mapping[str, PathLike | None] | None = None) -> None:
    """Refuse, before any work is done, an output that is an input or is named twice.

    ``outputs`` and ``inputs`` map a label (the option, e.g. ``"--junit"``) to a path or
    ``None`` (not given). An input that does not exist as a file is skipped (built-in names such
    as a camera or table name); an output is the same file as an input when both name one
    existing file (:func:`os.path.samefile`, so links and relative paths are seen through).
    Raises :class:`InputFileError` naming the output, its option and the input; also for an
    output that is an existing folder.
    """
    given = {k: Path(v) for k, v in outputs.items() if v is not None}
    files = {k: Path(v) for k, v in (inputs or {}).items()
             if v is not None and Path(v).is_file()}
    for out_label, out in given.items():
        if out.is_dir():
            raise InputFileError(f"{out}: {out_label} names a folder; give a file name")
        if not out.exists():
            continue
        for in_label, src in files.items():
            if os.path.samefile(out, src):
                raise InputFileError(f"{out}: {out_label} names the input {in_label} "
                                     f"({src}); refusing to write over an input file")
    seen: dict[Path, str] = {}
    for out_label, out in given.items():
        key = out.resolve()
        if key in seen:
            raise InputFileError(f"{out}: named by both {seen[key]} and {out_label}; give each "
                                 "output its own file")
        seen[key] = out_label


def require_file(path: str | os.PathLike[str], what: str = "input file") -> Path:
    """Return ``path`` as a :class:`Path` if it is an existing readable file, else raise."""
    p = Path(path)
    if not p.exists():
        raise InputFileError(f"{p}: {what} does not exist")
    if not p.is_file():
        raise InputFileError(f"{p}: {what} is not a regular file")
    if not os.access(p, os.R_OK):
        raise InputFileError(f"{p}: {what} is not readable")
    return p


def portable_paths(data: Any) -> Any:
    """Provenance that names the data, not the machine: in a dict, every string that is a path
    is cut to its last two parts (``/data/shared/coco/val2017`` -> ``coco/val2017``)."""
    if not isinstance(data, dict):
        return data
    return {k: str(Path(*Path(v).parts[-2:])) if isinstance(v, str) and os.sep in v else v
            for k, v in data.items()}


def file_sha256(path: str | os.PathLike[str]) -> str:
    """SHA-256 hex digest of a file's bytes, read in 1 MiB blocks (provenance of inputs)."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()
