"""The version of the ``camera-fidelity`` distribution (provenance of every record), and of any
installed distribution (:func:`installed_version`).

A leaf module: recorded by the stores and reports without importing the package's public API
(:mod:`fidelity` re-exports :data:`__version__`). The one place the version is written: the
build reads it from here (``[tool.hatch.version]`` in ``pyproject.toml``), so the installed
distribution's metadata carries the same string, and no command pays for
``importlib.metadata`` (about 30 ms of start-up) to learn it.
"""

from __future__ import annotations

import os
import re
import sys

__version__ = "0.1.0"


def installed_version(distribution: str) -> str | None:
    """The installed version of ``distribution`` (None: not installed), as
    ``importlib.metadata.version`` gives it: the ``Version:`` field of the metadata header of
    the first ``.dist-info`` or ``.egg-info`` folder of that (normalised) name along
    ``sys.path``. Without ``importlib.metadata``, whose import and whole-file parser with the
    e-mail package cost 30-40 ms of every report's provenance; it answers only where this
    cannot: metadata without a version header, or ``sys.path`` holding an archive (a zipped
    egg), which it searches and this does not."""
    folders = _metadata_folders(tuple(sys.path)).get(_normalised(distribution))
    if folders:
        folder = folders[0]
        if os.path.isdir(folder):
            folder = os.path.join(folder, "PKG-INFO" if folder.endswith(".egg-info")
                                  else "METADATA")
        try:  # (an .egg-info file is the PKG-INFO itself)
            with open(folder, encoding="utf-8", errors="replace") as f:
                text = f.read(1 << 16)
        except OSError:
            text = ""
        header = text.replace("\r\n", "\n").split("\n\n", 1)[0]
        field = re.search(r"^Version:[ \t]*(\S+)[ \t]*$", header, re.M)
        if field:
            return field.group(1)
    elif not any(os.path.isfile(entry) for entry in sys.path if entry):
        return None
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(distribution)
    except PackageNotFoundError:
        return None


def _normalised(name: str) -> str:
    """A distribution name as its metadata folder spells it: runs of ``-``, ``_`` and ``.``
    as one ``_``, lower case (the packaging specification's normalisation)."""
    return re.sub(r"[-_.]+", "_", name).lower()


_FOLDERS: dict[tuple[str, ...], dict[str, tuple[str, ...]]] = {}


def _metadata_folders(path: tuple[str, ...]) -> dict[str, tuple[str, ...]]:
    """Normalised distribution name -> its ``.dist-info`` and ``.egg-info`` folders in the
    folders of ``path`` (``sys.path``), in that order: one listing of each folder, kept for
    the process (per ``path``)."""
    if path not in _FOLDERS:
        found: dict[str, list[str]] = {}
        for entry in path:
            try:
                names = sorted(os.listdir(entry or "."))
            except OSError:
                continue
            for name in names:
                if name.endswith((".dist-info", ".egg-info")):
                    dist = _normalised(name.rsplit(".", 1)[0].split("-", 1)[0])
                    found.setdefault(dist, []).append(os.path.join(entry or ".", name))
        _FOLDERS[path] = {k: tuple(v) for k, v in found.items()}
    return _FOLDERS[path]


__all__ = ["__version__", "installed_version"]
