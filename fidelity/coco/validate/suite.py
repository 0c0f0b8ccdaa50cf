"""The validation's test cases: a folder of camera files and the light each one shoots under.

Suite folder: camera files (``*.toml``, ``*.yaml``, ``*.yml``) and an optional ``suite.toml``
giving each camera's scene illuminant (``default_illuminant = "D65"``; ``[illuminant]`` table
``stem = "A"``) and the chromatic adaptation transform its scene reference is adapted to D65
with (``default_cat = "Bradford"``; ``[cat]`` table ``stem = "CAT02"``; one of
:data:`fidelity.colour.colorimetry.CHROMATIC_ADAPTATION_METHODS`, any case); a camera file
describes the camera, the light and the reference's adaptation are part of the test case
(:func:`load_suite`). ``fidelity suite``, ``check`` of a suite file and ``fidelity validate``
(each camera's chart ΔE: :func:`fidelity.coco.validate.camera.case_chart`) read both.
"""

from __future__ import annotations

import os
import tomllib
from collections.abc import Mapping
from dataclasses import field, replace
from pathlib import Path

from fidelity.camera.model import read_camera_file
from fidelity.colour.colorimetry import CHROMATIC_ADAPTATION_METHODS
from fidelity.colour.spectral import load_illuminant
from fidelity.core.errors import InputFileError
from fidelity.core.fileio import file_sha256
from fidelity.core.record import record

SUITE_FILE = "suite.toml"


BASELINE = "baseline"

#: The chromatic adaptation transform of a case that ``suite.toml`` gives none.
DEFAULT_CAT = "Bradford"


@record
class CameraCase:
    """One test case: a camera file, the illuminant of the scene it shoots and the chromatic
    adaptation transform (``cat``) of its scene reference to D65."""

    name: str
    path: Path
    illuminant: str
    sha256: str
    cat: str = DEFAULT_CAT


@record
class SuiteSettings:
    """What a ``suite.toml`` sets (module docstring): the ``default_illuminant`` and the
    per-camera ``illuminants`` (camera stem -> illuminant), the ``default_cat`` and the
    per-camera ``cats`` (camera stem -> transform, canonical spelling)."""

    default_illuminant: str = "D65"
    illuminants: Mapping[str, str] = field(default_factory=dict)
    default_cat: str = DEFAULT_CAT
    cats: Mapping[str, str] = field(default_factory=dict)

    def illuminant_of(self, stem: str) -> str:
        """The illuminant of camera ``stem``."""
        return self.illuminants.get(stem, self.default_illuminant)

    def cat_of(self, stem: str) -> str:
        """The chromatic adaptation transform of camera ``stem``."""
        return self.cats.get(stem, self.default_cat)


def load_suite(folder: str | os.PathLike[str], default_cat: str | None = None
               ) -> list[CameraCase]:
    """Camera files of ``folder`` with their illuminants and chromatic adaptation transforms
    (module docstring), sorted by name. ``default_cat``: the transform of the cases that
    ``suite.toml`` gives none of their own (None: its ``default_cat``, else Bradford).

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
    settings = (read_suite_file(suite, {p.stem for p in files}) if suite.is_file()
                else SuiteSettings())
    if default_cat is not None:
        settings = replace(settings, default_cat=_cat_name(suite, "--cat", default_cat))
    cases = []
    for p in files:
        if p.stem == BASELINE:
            raise InputFileError(f"{p}: the name {BASELINE!r} is reserved for the ΔE = 0 baseline")
        read_camera_file(p)  # validate early, with the file named
        ill = settings.illuminant_of(p.stem)
        try:
            load_illuminant(ill)
        except Exception as exc:  # noqa: BLE001 - re-raised naming the suite file
            raise InputFileError(
                f"{suite}: {_key(p.stem, settings.illuminants, 'illuminant')}: {exc}") from None
        cases.append(CameraCase(p.stem, p, ill, file_sha256(p), settings.cat_of(p.stem)))
    return cases


#: The fields of a ``suite.toml``.
SUITE_FIELDS = ("default_illuminant", "illuminant", "default_cat", "cat")


def read_suite_file(suite: Path, stems: set[str]) -> SuiteSettings:
    """What a ``suite.toml`` (module docstring) whose folder holds the camera files ``stems``
    sets: its illuminants and chromatic adaptation transforms.

    Raises :class:`InputFileError` naming the file (and the key) for an unreadable or
    malformed file, an unknown field, an unknown transform or a camera stem with no camera
    file.
    """
    try:
        data = tomllib.loads(suite.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise InputFileError(f"{suite}: invalid TOML ({exc})") from exc
    unknown = set(data) - set(SUITE_FIELDS)
    if unknown:
        raise InputFileError(f"{suite}: unknown field {sorted(unknown)[0]!r}; known: "
                             f"{', '.join(SUITE_FIELDS)}")
    default, per = _setting(suite, data, "illuminant", "D65", stems)
    default_cat, cats = _setting(suite, data, "cat", DEFAULT_CAT, stems)
    return SuiteSettings(default, per, _cat_name(suite, "default_cat", default_cat),
                         {k: _cat_name(suite, f"cat.{k}", v) for k, v in cats.items()})


def _setting(suite: Path, data: Mapping[str, object], name: str, fallback: str,
             stems: set[str]) -> tuple[str, dict[str, str]]:
    """``default_NAME`` (a string) and the ``[NAME]`` table (camera stem -> string) of a
    suite file's ``data``."""
    default = data.get(f"default_{name}", fallback)
    per = data.get(name, {})
    if not isinstance(default, str) or not isinstance(per, dict) or not all(
            isinstance(v, str) for v in per.values()):
        raise InputFileError(f"{suite}: default_{name} must be a string and "
                             f"[{name}] a table of strings")
    extra = sorted(set(per) - stems)
    if extra:
        raise InputFileError(f"{suite}: {name}.{extra[0]}: names a camera with no "
                             f"camera file in {suite.parent} ({extra[0]}.toml)")
    return default, dict(per)


def _cat_name(suite: Path, key: str, value: str) -> str:
    """The canonical spelling of the transform ``value`` at ``key`` of the suite file."""
    found = next((m for m in CHROMATIC_ADAPTATION_METHODS if m.lower() == value.lower()), None)
    if found is None:
        raise InputFileError(f"{suite}: {key}: unknown chromatic adaptation transform "
                             f"{value!r}; known: {', '.join(CHROMATIC_ADAPTATION_METHODS)}")
    return found


def _key(stem: str, per: Mapping[str, str], name: str) -> str:
    """The key of ``suite.toml`` that gives camera ``stem`` its ``name`` setting."""
    return f"{name}.{stem}" if stem in per else f"default_{name} (camera {stem})"


def load_suite_file(path: str | os.PathLike[str], default_cat: str | None = None
                    ) -> list[CameraCase]:
    """:func:`load_suite` of the folder of the suite file ``path`` (``.../suite.toml``), with
    its ``default_cat``.

    Raises :class:`InputFileError` for a missing suite file, and as :func:`load_suite`.
    """
    p = Path(path)
    if not p.is_file():
        raise InputFileError(f"{p}: suite file does not exist")
    if p.name != SUITE_FILE:
        raise InputFileError(f"{p}: not a suite file (the suite of a camera folder is named "
                             f"{SUITE_FILE})")
    return load_suite(p.parent, default_cat)


def is_suite_file(argument: str) -> bool:
    """Whether a command-line camera argument is a suite file (named :data:`SUITE_FILE`)."""
    return Path(argument).name == SUITE_FILE


def validated_case(cases: Mapping[str, CameraCase], name: str, sha256: str) -> CameraCase:
    """The case ``name`` of ``cases`` whose camera file a validation measured (its SHA-256
    ``sha256``); an :class:`InputFileError` when the suite lacks it or its file has changed."""
    case = cases.get(name)
    if case is None or case.sha256 != sha256:
        raise InputFileError(f"{name}: the camera file validated is not in the suite "
                             "(missing, or changed since: its SHA-256 differs)")
    return case


__all__ = [
    "BASELINE",
    "DEFAULT_CAT",
    "SUITE_FIELDS",
    "SUITE_FILE",
    "CameraCase",
    "SuiteSettings",
    "is_suite_file",
    "load_suite",
    "load_suite_file",
    "read_suite_file",
    "validated_case",
]
