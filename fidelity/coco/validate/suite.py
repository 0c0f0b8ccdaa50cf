"""The validation's test cases: a folder of camera files and the light each one shoots under.

Suite folder: camera files (``*.toml``, ``*.yaml``, ``*.yml``) and an optional ``suite.toml``
giving each camera's scene illuminant (``default_illuminant = "D65"``; ``[illuminant]`` table
``stem = "A"``); a camera file describes the camera, the light is part of the test case
(:func:`load_suite`).
"""

from __future__ import annotations

import os
import tomllib
from dataclasses import dataclass
from pathlib import Path

from fidelity.camera.model import read_camera_file
from fidelity.colour.spectral import load_illuminant
from fidelity.core.errors import InputFileError
from fidelity.core.fileio import file_sha256

SUITE_FILE = "suite.toml"


BASELINE = "baseline"


@dataclass(frozen=True)
class CameraCase:
    """One test case: a camera file and the illuminant of the scene it shoots."""

    name: str
    path: Path
    illuminant: str
    sha256: str


def load_suite(folder: str | os.PathLike[str]) -> list[CameraCase]:
    """Camera files of ``folder`` with their illuminants (module docstring), sorted by name.

    Raises :class:`InputFileError` for a missing folder, no camera files, an invalid camera
    file, a malformed ``suite.toml`` or one naming a camera that is not there.
    """
    d = Path(folder)
    if not d.is_dir():
        raise InputFileError(f"{d}: camera folder does not exist")
    files = sorted(p for p in d.iterdir() if p.suffix.lower() in (".toml", ".yaml", ".yml")
                   and p.name != SUITE_FILE)
    if not files:
        raise InputFileError(f"{d}: no camera files (*.toml, *.yaml) in the folder")
    suite = d / SUITE_FILE
    default, per = (read_suite_file(suite, {p.stem for p in files}) if suite.is_file()
                    else ("D65", {}))
    cases = []
    for p in files:
        if p.stem == BASELINE:
            raise InputFileError(f"{p}: the name {BASELINE!r} is reserved for the ΔE = 0 baseline")
        read_camera_file(p)  # validate early, with the file named
        ill = per.get(p.stem, default)
        try:
            load_illuminant(ill)
        except Exception as exc:  # noqa: BLE001 - re-raised naming the suite file
            raise InputFileError(f"{suite}: {_key(p.stem, per)}: {exc}") from None
        cases.append(CameraCase(p.stem, p, ill, file_sha256(p)))
    return cases


def read_suite_file(suite: Path, stems: set[str]) -> tuple[str, dict[str, str]]:
    """The ``default_illuminant`` and the ``[illuminant]`` table (camera stem -> illuminant)
    of a ``suite.toml`` (module docstring) whose folder holds the camera files ``stems``.

    Raises :class:`InputFileError` naming the file (and the key) for an unreadable or
    malformed file, an unknown field or a camera stem with no camera file.
    """
    try:
        data = tomllib.loads(suite.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise InputFileError(f"{suite}: invalid TOML ({exc})") from exc
    unknown = set(data) - {"default_illuminant", "illuminant"}
    if unknown:
        raise InputFileError(f"{suite}: unknown field {sorted(unknown)[0]!r}; known: "
                             "default_illuminant, illuminant")
    default = data.get("default_illuminant", "D65")
    per = data.get("illuminant", {})
    if not isinstance(default, str) or not isinstance(per, dict) or not all(
            isinstance(v, str) for v in per.values()):
        raise InputFileError(f"{suite}: default_illuminant must be a string and "
                             "[illuminant] a table of strings")
    extra = sorted(set(per) - stems)
    if extra:
        raise InputFileError(f"{suite}: illuminant.{extra[0]}: names a camera with no "
                             f"camera file in {suite.parent} ({extra[0]}.toml)")
    return default, dict(per)


def _key(stem: str, per: dict[str, str]) -> str:
    """The key of ``suite.toml`` that gives camera ``stem`` its illuminant."""
    return f"illuminant.{stem}" if stem in per else f"default_illuminant (camera {stem})"


def load_suite_file(path: str | os.PathLike[str]) -> list[CameraCase]:
    """:func:`load_suite` of the folder of the suite file ``path`` (``.../suite.toml``).

    Raises :class:`InputFileError` for a missing suite file, and as :func:`load_suite`.
    """
    p = Path(path)
    if not p.is_file():
        raise InputFileError(f"{p}: suite file does not exist")
    if p.name != SUITE_FILE:
        raise InputFileError(f"{p}: not a suite file (the suite of a camera folder is named "
                             f"{SUITE_FILE})")
    return load_suite(p.parent)


__all__ = [
    "BASELINE",
    "SUITE_FILE",
    "CameraCase",
    "load_suite",
    "load_suite_file",
    "read_suite_file",
]
