"""Project settings: ``[tool.fidelity]`` in ``pyproject.toml``, or a ``fidelity.toml``.

A simulator repository states its camera, thresholds, table and reference once, so a CI line
shrinks to ``fidelity gate render.exr``::

    [tool.fidelity]              # in fidelity.toml: the same keys at the top level
    camera = "sim/camera.toml"   # paths are relative to the file that names them
    max_delta_e = 3
    reference = "scene"
    table = "coco1000-measured"

    [tool.fidelity.gate]         # a command's own table overrides the shared keys
    junit = "reports/colour.xml"

The file is found from the working folder upwards (the first ``fidelity.toml``, or
``pyproject.toml`` with a ``[tool.fidelity]`` table), or named by ``fidelity --config FILE``;
``fidelity --no-config`` ignores it. Options given on the command line always win. Every key is
declared in :data:`SETTINGS` (its type and the commands' option it sets); a key that is not,
or a value of the wrong type, is an error naming the file and the key.
"""

from __future__ import annotations

import os
import tomllib
from collections.abc import Collection, Mapping
from pathlib import Path
from typing import Any

from fidelity.core.errors import InputFileError
from fidelity.core.record import record

#: The file names looked for, nearest folder first.
CONFIG_FILES = ("fidelity.toml", "pyproject.toml")


@record
class Setting:
    """One settings key: its value ``kind`` (``str``, ``float``, ``int``, ``bool``), the
    parameter name of the commands' option it sets, and whether it is a path (made absolute
    relative to the settings file), or may be one (``maybe_path``: a name, a URI such as
    ``ocio://default``, or a file); ``many``:
    the option is repeatable, the value one of ``kind`` or a list of them."""

    kind: type
    param: str
    path: bool = False
    maybe_path: bool = False
    many: bool = False


#: Every key a settings file may hold (declarative: the validator below only walks this).
SETTINGS: Mapping[str, Setting] = {
    "camera": Setting(str, "camera", maybe_path=True),
    "illuminant": Setting(str, "illuminant", maybe_path=True),
    "renderer": Setting(str, "renderer"),
    "reference": Setting(str, "reference", maybe_path=True),
    "table": Setting(str, "table", maybe_path=True),
    "size": Setting(str, "size"),
    "max_delta_e": Setting(float, "max_delta_e"),
    "max_dmap": Setting(float, "max_dmap"),
    "class": Setting(str, "cls"),
    "unit": Setting(str, "unit"),
    "encoding": Setting(str, "encoding"),
    "exposure": Setting(str, "exposure"),
    "layer": Setting(str, "layer"),
    "colourspace": Setting(str, "colourspace"),
    "ocio_colourspace": Setting(str, "ocio_colourspace"),
    "ocio_config": Setting(str, "ocio_config", maybe_path=True),
    "negatives": Setting(str, "negatives"),
    "junit": Setting(str, "junit", path=True),
    "json": Setting(str, "json_path", path=True),
    "html": Setting(str, "html_path", path=True),
    "out": Setting(str, "out_dir", path=True),
    "images": Setting(str, "images", path=True),
    "annotations": Setting(str, "annotations", path=True),
    "models": Setting(str, "models"),
    "threads": Setting(int, "threads"),
    "provider": Setting(str, "provider"),
    "bound": Setting(str, "bound"),
    "decision": Setting(str, "decision"),
    "coverage_factor": Setting(float, "coverage_factor"),
    "strict": Setting(bool, "strict"),
    "evidence": Setting(str, "evidence_paths", path=True, many=True),
}


@record
class Config:
    """Settings read from ``path``: ``shared`` for every command, ``commands`` per command
    (parameter name -> value)."""

    path: Path
    shared: Mapping[str, Any]
    commands: Mapping[str, Mapping[str, Any]]

    def default_map(self, command_names: list[str]) -> dict[str, dict[str, Any]]:
        """click's ``default_map``: per command, the shared settings and its own."""
        return {name: {**self.shared, **self.commands.get(name, {})} for name in command_names}


def find_config(start: str | os.PathLike[str] | None = None) -> Path | None:
    """The nearest settings file from ``start`` (default: the working folder) upwards."""
    folder = Path(start or Path.cwd()).resolve()
    for d in (folder, *folder.parents):
        for name in CONFIG_FILES:
            p = d / name
            if not p.is_file():
                continue
            if name == "fidelity.toml" or _has_tool_table(p):
                return p
    return None


def _has_tool_table(pyproject: Path) -> bool:
    try:
        doc = tomllib.loads(pyproject.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return False
    tool = doc.get("tool")
    return isinstance(tool, dict) and "fidelity" in tool


def _value(path: Path, where: str, key: str, value: Any) -> Any:
    setting = SETTINGS.get(key)
    if setting is None:
        raise InputFileError(f"{path}: {where}{key}: unknown setting; known: "
                             f"{', '.join(sorted(SETTINGS))}")
    if setting.many:
        values = value if isinstance(value, list) else [value]
        one = Setting(setting.kind, setting.param, setting.path, setting.maybe_path)
        return [_one_value(path, where, key, one, v) for v in values]
    return _one_value(path, where, key, setting, value)


def _one_value(path: Path, where: str, key: str, setting: Setting, value: Any) -> Any:
    kind = setting.kind
    ok = (isinstance(value, kind) and not isinstance(value, bool) if kind is not bool
          else isinstance(value, bool))
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        value, ok = float(value), True
    if not ok:
        raise InputFileError(f"{path}: {where}{key}: expected a {kind.__name__}, got "
                             f"{value!r}")
    if setting.path or (setting.maybe_path and isinstance(value, str) and "://" not in value
                        and (os.sep in value or value.endswith((".toml", ".yaml", ".yml",
                                                                ".json", ".csv", ".ocio")))):
        value = str((path.parent / value).resolve())
    return value


def read_config(path: str | os.PathLike[str], *, command_names: Collection[str]) -> Config:
    """Read and check a settings file (:data:`SETTINGS`); errors name the file and the key.

    ``command_names``: the commands a table of the file may be named after (the caller's: the
    command line passes its own, so this module knows nothing of it).
    """
    p = Path(path)
    try:
        doc = tomllib.loads(p.read_text(encoding="utf-8"))
    except OSError as exc:
        raise InputFileError(f"{p}: cannot read the settings file ({exc.strerror})") from None
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise InputFileError(f"{p}: not a TOML file ({exc})") from None
    table: Any = doc
    prefix = ""
    if p.name == "pyproject.toml":
        table = doc.get("tool", {}).get("fidelity", {})
        prefix = "tool.fidelity."
    if not isinstance(table, dict):
        raise InputFileError(f"{p}: {prefix.rstrip('.')}: expected a table")
    shared: dict[str, Any] = {}
    commands: dict[str, dict[str, Any]] = {}
    for key, value in table.items():
        if isinstance(value, dict):
            if key not in command_names:
                raise InputFileError(f"{p}: {prefix}{key}: not a command; known: "
                                     f"{', '.join(sorted(command_names))}")
            commands[key] = {SETTINGS[k].param if k in SETTINGS else k:
                             _value(p, f"{prefix}{key}.", k, v) for k, v in value.items()}
        else:
            shared[SETTINGS[key].param if key in SETTINGS else key] = _value(p, prefix, key,
                                                                              value)
    return Config(p, shared, commands)


__all__ = ["CONFIG_FILES", "SETTINGS", "Config", "Setting", "find_config", "read_config"]
