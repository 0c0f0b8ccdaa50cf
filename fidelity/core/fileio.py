"""Atomic file output and input checks shared by every command.

Outputs are written to a temporary file in the destination folder and renamed into place, so a
reader never sees a half-written file and an interrupted run leaves no partial output. A
destination that is a symbolic link writes the file it leads to (the temporary file in that
file's folder; a dangling link creates its target), so a link is never replaced. A special file
(a FIFO, a terminal or other character device, ``/dev/stdout``) is written as a stream, once
the output is complete; a path that names one of this process's own file descriptors
(``/dev/stdout``, ``/dev/fd/N``, ``/proc/self/fd/N``) writes that descriptor, as a shell's
redirection does. Inputs are never written to: :func:`atomic_output` refuses a destination that
is one of the declared inputs.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import math
import os
import re
import shutil
import stat
import sys
import tempfile
from collections.abc import Callable, Iterable, Iterator, Mapping
from functools import lru_cache, wraps
from pathlib import Path
from typing import Any, Literal, NamedTuple, Protocol, TypeVar, runtime_checkable

from fidelity.core.errors import InputFileError

#: errno values that mean "the output cannot be written here" (a full disk, a quota, a
#: read-only file system or folder, a file too large for the system's limit), not a bug.
WRITE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM,
                          errno.EFBIG, errno.ENOTDIR, errno.EISDIR, errno.ENAMETOOLONG})


def printable(text: str) -> str:
    """``text`` that can always be written as UTF-8 (a terminal, a log, an XML file): the
    undecodable bytes of a file name, which Python keeps as surrogate escapes, are shown as
    ``\\xNN``, other lone surrogates as ``\\uNNNN``."""
    try:
        text.encode("utf-8")
        return text
    except UnicodeEncodeError:
        return "".join(f"\\x{ord(c) - 0xDC00:02x}" if 0xDC80 <= ord(c) <= 0xDCFF else
                       f"\\u{ord(c):04x}" if 0xD800 <= ord(c) <= 0xDFFF else c for c in text)


def display_path(path: str | os.PathLike[str]) -> str:
    """``path`` as printable text (:func:`printable`)."""
    return printable(os.fsdecode(path))


_T = TypeVar("_T")


def cached_while_unchanged(maxsize: int) -> Callable[[Callable[[Path], _T]], Callable[[Path], _T]]:
    """Decorate a reader of a file: its result is kept, a process long, while the file is
    unchanged (keyed by the path as given, the file it names, its modification time and
    size; at most ``maxsize`` files). Its results must never be modified by a caller; an
    exception is not kept (a broken file is read again)."""

    def decorate(read: Callable[[Path], _T]) -> Callable[[Path], _T]:
        @lru_cache(maxsize=maxsize)
        def keyed(path: Path, resolved: Path, mtime_ns: int, size: int) -> _T:
            return read(path)

        @wraps(read)
        def cached(path: Path) -> _T:
            stat = path.stat()
            return keyed(path, path.resolve(), stat.st_mtime_ns, stat.st_size)

        return cached

    return decorate


def write_error(path: str | os.PathLike[str], exc: OSError) -> InputFileError:
    """The one-line error for an output that could not be written (``exc`` one of
    :data:`WRITE_ERRNOS`): ``<path>: cannot write: <reason>``."""
    reason = exc.strerror or str(exc)
    hint = {errno.ENOSPC: "; free some space or write elsewhere",
            errno.EDQUOT: "; free some space or write elsewhere",
            errno.EROFS: "; write elsewhere",
            errno.EACCES: "; write elsewhere", errno.EPERM: "; write elsewhere"}
    return InputFileError(f"{display_path(path)}: cannot write the output: {reason}"
                          f"{hint.get(exc.errno or 0, '')}")


#: The most symbolic links a path may lead through (Linux's limit, ``ELOOP`` beyond).
MAX_LINKS = 40

#: A path of one of this process's file descriptors, as the links are followed to it
#: (``/dev/stdout`` -> ``/proc/self/fd/1`` -> ``/proc/<pid>/fd/1``).
_OWN_FD = re.compile(r"^/proc/(self|thread-self|\d+)/fd/(\d+)$")


class Destination(NamedTuple):
    """Where an output named ``path`` lands (:func:`destination`).

    ``kind`` is ``"file"`` (a regular file, existing or not: written to a temporary file in the
    folder of ``target``, the path with every link resolved, and renamed onto it),
    ``"stream"`` (a FIFO, a character or block device, a socket: ``target`` opened and written)
    or ``"descriptor"`` (one of this process's open file descriptors, ``fd``: written to it).
    """

    kind: Literal["file", "stream", "descriptor"]
    target: Path
    fd: int | None = None


def link_chain(path: str | os.PathLike[str]) -> list[str]:
    """The absolute paths that ``path`` leads through, itself first, one per symbolic link
    followed (each with its folder's own links resolved), the last one no link (or absent).

    Raises
    ------
    InputFileError
        The links form a loop, or more than :data:`MAX_LINKS` of them.
    """
    hops = [os.path.abspath(os.fspath(path))]
    for _ in range(MAX_LINKS + 1):
        head, tail = os.path.split(hops[-1])
        folder = os.path.realpath(head)
        hops[-1] = os.path.join(folder, tail)
        try:
            text = os.readlink(hops[-1])
        except (OSError, ValueError):  # not a link, or nothing there: the chain ends
            return hops
        hops.append(os.path.join(folder, text))  # an absolute text replaces the folder
    raise InputFileError(f"{display_path(path)}: cannot write: too many levels of symbolic "
                         "links (a loop?)")


def _own_fd(hop: str) -> int | None:
    m = _OWN_FD.match(hop)
    if m is None or m.group(1) not in ("self", "thread-self", str(os.getpid())):
        return None
    return int(m.group(2))


def destination(path: str | os.PathLike[str]) -> Destination:
    """Where writing ``path`` lands: see :class:`Destination`.

    Parameters
    ----------
    path
        The output as the user named it: a file, a symbolic link (to a file, a link, a path not
        there yet, a special file), a special file.

    Returns
    -------
    Destination

    Raises
    ------
    InputFileError
        The links form a loop.
    """
    chain = link_chain(path)
    for hop in chain:
        fd = _own_fd(hop)
        if fd is not None:
            return Destination("descriptor", Path(path), fd)
    try:
        mode = os.stat(chain[-1]).st_mode
    except OSError:  # not there yet (a dangling link: its target), or not reachable
        mode = stat.S_IFREG
    if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
        return Destination("stream", Path(chain[-1]))
    return Destination("file", Path(chain[-1]))


def is_stream(path: str | os.PathLike[str]) -> bool:
    """True when writing ``path`` streams to a special file or a file descriptor rather than
    replacing a file (:func:`destination`)."""
    try:
        return destination(path).kind != "file"
    except InputFileError:
        return False


def _protected(dest: Destination, protect: Iterable[str | os.PathLike[str]]) -> bool:
    """True when the file ``dest`` writes is one of the ``protect`` files (links and relative
    paths seen through, hard links included)."""
    if dest.kind != "file" or not dest.target.exists():
        return False
    for p in protect:
        with contextlib.suppress(OSError):
            if Path(p).exists() and os.path.samefile(dest.target, p):
                return True
    return False


def _temporary_beside(target: Path, where: Path) -> Path:
    """A new empty file in ``target``'s folder (created, with its parents, if needed) named
    after it, with the usual ``0666 & ~umask`` permissions; ``where`` is the output as named,
    for the error of a folder that is a file."""
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
    except FileExistsError:  # the folder's name is taken by a file
        raise InputFileError(f"{display_path(where)}: cannot write: "
                             f"{display_path(target.parent)} is a file, not a folder") from None
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.{os.getpid()}.",
                               suffix=".tmp" + target.suffix, dir=target.parent)
    os.close(fd)
    # mkstemp creates the file private (0600); an output gets the usual 0666 & ~umask.
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    return Path(tmp)


def _stream(source: Path, dest: Destination, where: Path) -> None:
    """Copy the finished output ``source`` to the special file or descriptor of ``dest``
    (``where``: the output as named, for the error of a descriptor not open for writing; a
    reader that left a pipe is :class:`BrokenPipeError`, as for anything printed)."""
    for out in (sys.stdout, sys.stderr):  # what this process printed comes first
        with contextlib.suppress(Exception):
            out.flush()
    with open(source, "rb") as src:
        if dest.fd is not None:
            try:
                with open(os.dup(dest.fd), "wb") as fh:
                    shutil.copyfileobj(src, fh)
            except OSError as exc:
                if exc.errno == errno.EBADF:
                    raise InputFileError(f"{display_path(where)}: cannot write: file "
                                         f"descriptor {dest.fd} is not open for writing"
                                         ) from None
                raise
            return
        try:
            fh = open(dest.target, "wb")  # noqa: SIM115 - closed below
        except OSError as exc:
            if exc.errno == errno.ENXIO:  # a socket: nothing to open
                raise InputFileError(f"{display_path(dest.target)}: cannot write: a socket, "
                                     "not a file") from None
            raise
        with fh:
            shutil.copyfileobj(src, fh)


@contextlib.contextmanager
def atomic_output(
    path: str | os.PathLike[str], protect: Iterable[str | os.PathLike[str]] = ()
) -> Iterator[Path]:
    """Yield a temporary path to write the output to; when the block succeeds, put it at
    ``path``: renamed onto the file ``path`` names (through its symbolic links: a link is never
    replaced), or streamed to it when it is a special file or a file descriptor
    (:func:`destination`).

    ``protect`` lists input paths that must never be overwritten; naming one of them as output
    (directly or through links) raises :class:`InputFileError`. When the output cannot be
    written (a full disk, a read-only folder: an :class:`OSError` with an errno of
    :data:`WRITE_ERRNOS`, raised while the block writes the temporary file or while it is
    renamed or streamed), the temporary file is removed, an earlier file at ``path`` is left as
    it was, and :class:`InputFileError` names ``path``.
    """
    where = Path(path)
    dest = destination(path)
    if _protected(dest, protect):
        raise InputFileError(f"{display_path(where)}: refusing to write over an input file")
    tmp_path: Path | None = None
    scratch: str | None = None
    try:
        if dest.kind == "file":
            tmp_path = _temporary_beside(dest.target, where)
        else:
            scratch = tempfile.mkdtemp(prefix="fidelity-output-")
            tmp_path = Path(scratch) / f"output{where.suffix}"
            tmp_path.touch()
        yield tmp_path
        if dest.kind == "file":
            os.replace(tmp_path, dest.target)
        else:
            _stream(tmp_path, dest, where)
    except OSError as exc:
        if exc.errno in WRITE_ERRNOS:
            raise write_error(where, exc) from None
        raise
    finally:
        if tmp_path is not None:
            with contextlib.suppress(OSError):
                tmp_path.unlink()
        if scratch is not None:
            shutil.rmtree(scratch, ignore_errors=True)


def remove_stale_temporaries(folder: str | os.PathLike[str]) -> list[Path]:
    """Delete the temporary files that :func:`atomic_output` left in ``folder`` when its
    process was killed (``.<name>.<pid>.<random>.tmp<suffix>`` whose process has ended);
    those of live processes (another run writing there now) are kept. Returns the removed
    paths. A resume calls it, so temporary files never survive a resume."""
    d = Path(folder)
    removed: list[Path] = []
    if not d.is_dir():
        return removed
    pattern = re.compile(r"^\..+\.(\d+)\.[^.]+\.tmp[^/]*$")
    for p in d.iterdir():
        m = pattern.match(p.name)
        if not m or not p.is_file():
            continue
        pid = int(m.group(1))
        try:
            os.kill(pid, 0)
            continue  # a live process is writing it
        except ProcessLookupError:
            pass
        except PermissionError:
            continue
        with contextlib.suppress(OSError):
            p.unlink()
            removed.append(p)
    return removed


def write_text_atomic(path: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically and return the path; undecodable bytes of
    file names quoted in it are written as ``\\xNN`` (:func:`printable`)."""
    with atomic_output(path) as tmp:
        tmp.write_text(printable(text), encoding="utf-8")
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


def finite_or_none(x: float | None) -> float | None:
    """A finite number as a float; None, NaN and +-Inf as None (JSON has none of them).

    Parameters
    ----------
    x
        A number or None.

    Returns
    -------
    float or None
    """
    return None if x is None or not math.isfinite(x) else float(x)


def optional_float(x: Any) -> float | None:
    """``x`` as a float, None as None (a record's optional number read back from JSON)."""
    return None if x is None else float(x)


def json_ready(obj: Any) -> Any:
    """``obj`` as strict JSON values: records with a ``to_json`` method are written by it,
    numpy scalars and arrays become Python numbers and lists, tuples lists, paths strings,
    mapping keys strings, and NaN or +-Inf ``None``. The one JSON cleaner of the project (chart
    reports, COCO tables, validation)."""
    if obj is None or type(obj) in (str, int, bool):  # most values: before the slower checks
        return obj
    # isinstance(obj, SupportsJson), without the runtime Protocol check (20 us a value)
    if hasattr(obj, "to_json") and not isinstance(obj, type):
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


def _existing(path: Path) -> str | None:
    """``"file"``, ``"folder"`` or None (absent, or a name that is no path at all)."""
    try:
        return "folder" if path.is_dir() else "file" if path.exists() else None
    except (OSError, ValueError):  # a name too long, with a NUL byte, ...
        return None


def _inside(path: Path, folder: Path) -> bool:
    return path == folder or folder in path.parents


def check_outputs(outputs: Mapping[str, PathLike | None],
                  inputs: Mapping[str, PathLike | None] | None = None, *,
                  stores: Mapping[str, PathLike | None] | None = None) -> None:
    """Refuse, before any work is done, an output that would write over something the command
    reads, or that is named twice.

    ``outputs`` maps a label (the option, e.g. ``"--junit"``) to the path of a file the command
    will write, or ``None`` (not given). ``inputs`` maps labels to what the command reads: a
    file, a folder, or a name that is not a path (a built-in camera or table name: skipped).
    ``stores`` maps labels to results-store folders the command reads (a sweep's or a
    validation's SQLite store). Every path is compared resolved (links and relative paths are
    seen through). Refused, with :class:`InputFileError` naming the output, its option and the
    input:

    - an output that is an input file (:func:`os.path.samefile`);
    - an output inside an input folder, existing or not (``--images``: so a rerun answers as
      the first run did);
    - an output directly inside a store folder, existing or not (the store's database, its
      SQLite companion files, or anything else there; a subfolder such as ``STORE/report`` is
      allowed);
    - an output that is an existing folder, or the same file as another output (a special
      file such as ``/dev/stdout``, which takes each output in turn, may be named twice).
    """
    given = {k: Path(v) for k, v in outputs.items() if v is not None}
    files: dict[str, Path] = {}
    folders: dict[str, Path] = {}
    for label, v in (inputs or {}).items():
        if v is None:
            continue
        kind = _existing(Path(v))
        if kind == "file":
            files[label] = Path(v)
        elif kind == "folder":
            folders[label] = Path(v).resolve()
    store_dirs = {k: Path(v).resolve() for k, v in (stores or {}).items() if v is not None}
    for out_label, out in given.items():
        where = display_path(out)
        kind = _existing(out)
        if kind == "folder":
            raise InputFileError(f"{where}: {out_label} names a folder; give a file name")
        resolved = out.resolve()
        for st_label, st in store_dirs.items():
            if resolved.parent == st:
                raise InputFileError(
                    f"{where}: {out_label} writes into the results store {st_label} "
                    f"({display_path(st)}); refusing to write beside the store's data: give "
                    "another folder (a subfolder such as report/ is fine)")
        for in_label, folder in folders.items():
            if _inside(resolved, folder):  # existing or not: the same answer on every rerun
                raise InputFileError(f"{where}: {out_label} writes inside the input folder "
                                     f"{in_label} ({display_path(folder)}); refusing to write "
                                     "among the inputs: give another folder")
        if kind is None:
            continue
        for in_label, src in files.items():
            if os.path.samefile(out, src):
                raise InputFileError(f"{where}: {out_label} names the input {in_label} "
                                     f"({display_path(src)}); refusing to write over an input "
                                     "file")
    seen: dict[Path, str] = {}
    for out_label, out in given.items():
        if is_stream(out):  # a terminal or pipe takes each output in turn
            continue
        key = out.resolve()
        if key in seen:
            raise InputFileError(f"{display_path(out)}: named by both {seen[key]} and "
                                 f"{out_label}; give each output its own file")
        seen[key] = out_label


def check_output_folders(folders: Mapping[str, PathLike | None],
                         inputs: Mapping[str, PathLike | None]) -> None:
    """Refuse an output folder whose files the command writes one by one (a dataset's subset
    folders) when it is an input folder or holds one: ``folders`` and ``inputs`` map labels to
    paths (``None``: not given). Raises :class:`InputFileError` naming both."""
    for out_label, out in folders.items():
        if out is None:
            continue
        resolved = Path(out).resolve()
        for in_label, src in inputs.items():
            if src is None or _existing(Path(src)) != "folder":
                continue
            if _inside(Path(src).resolve(), resolved):
                raise InputFileError(
                    f"{display_path(out)}: {out_label} would write into the input folder "
                    f"{in_label} ({display_path(src)}); give an output folder outside it")


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


def _file_digest(path: str | os.PathLike[str], algorithm: str) -> str:
    digest = hashlib.new(algorithm)
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def file_sha256(path: str | os.PathLike[str]) -> str:
    """SHA-256 hex digest of a file's bytes, read in 1 MiB blocks (provenance of inputs)."""
    return _file_digest(path, "sha256")


def file_sha3_256(path: str | os.PathLike[str]) -> str:
    """SHA3-256 (FIPS 202) hex digest of a file's bytes, read in 1 MiB blocks: the checksum
    SSP Traceability prescribes (:mod:`fidelity.report.ssp`)."""
    return _file_digest(path, "sha3_256")
