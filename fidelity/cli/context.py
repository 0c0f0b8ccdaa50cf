"""The running command's context: its settings file, its standard output (under ``-q`` and
``--json -``), its progress bars, its command line and the evidence files that record it, as
every command reads them."""

from __future__ import annotations

import contextlib
import json
import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click
from click.core import ParameterSource

from fidelity.core.fileio import display_path, json_ready, write_json_atomic
from fidelity.report.evidencefile import invocation_record

if TYPE_CHECKING:
    from typing import TypeAlias


    # click >= 8.2 types ParamType by its value; the project supports click 8.1 too
    ParamTypeBase: TypeAlias = click.ParamType[Any]
else:
    ParamTypeBase = click.ParamType


#: The ``--json`` value that means standard output.
STDOUT = "-"


def command_state() -> dict[str, Any]:
    """The state the command group keeps for the running command (its settings file, verbosity,
    standard output, command line)."""
    ctx = click.get_current_context()
    root = ctx.find_root()
    obj: dict[str, Any] = root.ensure_object(dict)
    return obj


def settings_line() -> str | None:
    """What the running command took from a settings file: ``fidelity: settings FILE: key,
    ...`` (the options whose value came from it, by their flags), or that none of its keys
    applies; None when no settings file was read (none found, or ``--no-config``)."""
    config = command_state().get("config")
    if config is None:
        return None
    ctx = click.get_current_context()
    used = [max(p.opts, key=len) for p in ctx.command.params
            if p.name and ctx.get_parameter_source(p.name) == ParameterSource.DEFAULT_MAP]
    what = ", ".join(used) if used else "no setting applies to this command"
    return f"fidelity: settings {config.path}: {what}"


def from_settings(name: str) -> bool:
    """Whether option ``name`` of the running command has its value from the settings file."""
    return click.get_current_context().get_parameter_source(name) == ParameterSource.DEFAULT_MAP


def show_progress(progress: bool | None) -> bool:
    """Whether to draw progress bars: as asked, else only when stderr is a terminal."""
    if progress is not None:
        return progress
    return sys.stderr.isatty()


def invocation() -> dict[str, Any] | None:
    """The running command line as a credibility record's ``invocation``
    (:func:`fidelity.report.evidencefile.invocation_record`): the arguments the group was given,
    the current folder and the settings file read; None outside a ``fidelity`` command."""
    ctx = click.get_current_context(silent=True)
    obj = ctx.find_root().obj if ctx is not None else None
    if not isinstance(obj, dict) or "argv" not in obj:
        return None
    config = obj.get("config")
    return invocation_record(obj["argv"], config.path if config is not None else None)


def real_stdout() -> Any:
    """The standard output of the command line (also under ``--quiet``)."""
    with contextlib.suppress(RuntimeError):
        out = command_state().get("stdout")
        if out is not None:
            return out
    return sys.stdout


def write_json_output(path: str | os.PathLike[str], obj: Any) -> str:
    """Write JSON to ``path`` atomically, or to standard output for ``-``; returns where."""
    if str(path) == STDOUT:
        out = real_stdout()
        out.write(json.dumps(json_ready(obj), indent=2, allow_nan=False) + "\n")
        out.flush()
        return "standard output"
    return str(write_json_atomic(path, obj))



def evidence_outputs(paths: Sequence[Path]) -> dict[str, Path]:
    """The ``--evidence`` files as :func:`fidelity.core.fileio.check_outputs` labels them."""
    return {("--evidence" if len(paths) == 1 else f"--evidence ({p.name})"): p for p in paths}


def write_evidence_files(paths: Sequence[Path], write: Callable[..., list[Path]],
                         *args: Any, results: Sequence[Path | None] = (),
                         indent: str = "") -> None:
    """Write the evidence files with ``write(paths, *args, results=..., invocation=...)``
    (:func:`fidelity.report.evidence.write_evidence` or ``write_fit_evidence``), ``results``
    being the files the run wrote that exist, ``invocation`` the command line
    (:func:`invocation`), and print each."""
    if not paths:
        return
    wrote = [p for p in results if p is not None and p.is_file()]
    for path in write(paths, *args, results=wrote, invocation=invocation()):
        click.echo(f"{indent}wrote {display_path(path)}")

__all__ = [
    "evidence_outputs",
    "write_evidence_files",
    "STDOUT",
    "command_state",
    "from_settings",
    "invocation",
    "real_stdout",
    "settings_line",
    "show_progress",
    "write_json_output",
]
