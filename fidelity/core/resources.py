"""Locate the data that ships with fidelity (charts, scene templates, package data).

``charts/`` and ``scenes/`` live at the top of the source tree; a wheel carries them as
``fidelity/_resources/``. Package data proper (calibration and prediction tables, built-in
cameras) lives in ``fidelity/data/``.
"""

from __future__ import annotations

import os
from pathlib import Path

from fidelity.core.errors import InputFileError

_PACKAGE = Path(__file__).resolve().parent.parent


def resource_dir(kind: str) -> Path:
    """Folder of shipped resources of ``kind`` (``"charts"``, ``"scenes"``, ``"data"``)."""
    if kind == "data":
        return _PACKAGE / "data"
    for candidate in (_PACKAGE / "_resources" / kind, _PACKAGE.parent / kind):
        if candidate.is_dir():
            return candidate
    raise InputFileError(f"resource folder {kind!r} not found next to the fidelity package")


def source_root() -> Path:
    """The folder holding the ``fidelity`` package: in a source checkout, the repository's
    root, against which the committed evidence files (``reports/coco/...``) are named."""
    return _PACKAGE.parent


def shared_dir() -> Path | None:
    """The project's shared data folder: ``$FIDELITY_SHARED`` or ``../shared`` beside the repo."""
    env = os.environ.get("FIDELITY_SHARED")
    if env:
        return Path(env) if Path(env).is_dir() else None
    candidate = _PACKAGE.parent.parent / "shared"
    return candidate if candidate.is_dir() else None
