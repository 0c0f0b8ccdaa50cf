"""``fidelity verify``: check a credibility record against the files it names, and optionally
run its command line again and compare the results."""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
import tempfile
from collections.abc import Collection, Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import click

from fidelity.cli import COMMANDS, main
from fidelity.cli.context import write_json_output
from fidelity.cli.options import common_options, json_option
from fidelity.core.config import read_config
from fidelity.core.errors import FidelityError, InputFileError, InvalidValueError
from fidelity.core.fileio import check_outputs, display_path
from fidelity.core.schema import SchemaError
from fidelity.report.chain import chain_findings
from fidelity.report.verify import read_record, rerun_finding, verification_lines, verify_document
from fidelity.report.verify_ssp import ssp_findings

#: The commands whose records can be run again.
RERUNNABLE = ("check", "audit", "gate", "compare", "fit")

#: The options that name what a command writes, and the file or folder (in a temporary folder)
#: a repeated run writes instead: a repeat never writes over the first run's files.
OUTPUTS: Mapping[str, str] = {"out_dir": "out", "out": "out", "json_path": "run.json",
                              "html_path": "run.html", "junit": "junit.xml",
                              "evidence_paths": "record.json"}


def _options(command: click.Command) -> dict[str, click.Option]:
    """Each option string of ``command`` (``--no-report`` too) and its option."""
    out: dict[str, click.Option] = {}
    for param in command.params:
        if isinstance(param, click.Option):
            out.update({o: param for o in (*param.opts, *param.secondary_opts)})
    return out


def _takes_value(command: click.Command) -> dict[str, bool]:
    """Each option string of ``command`` and whether a value follows it."""
    return {o: not (p.is_flag or p.count) for o, p in _options(command).items()}


def rerun_argv(argv: Sequence[str], folder: Path, settings: str | None = None,
               configured: Collection[str] = ()) -> list[str]:
    """The recorded command line ``argv`` (after ``fidelity``) with its output options
    (:data:`OUTPUTS`) sent into ``folder``: each one the command line gives, the settings file
    sets (``configured``: parameter names) or that writes without being asked (a default,
    such as check's report folder); the command's record goes to ``folder/record.json``. The
    settings file is the recorded one: ``settings`` (its path) named with ``--config``, or
    ``--no-config`` when none was read, unless the command line says which. Raises
    :class:`click.UsageError` for a command not in :data:`RERUNNABLE`."""
    values = _takes_value(main)  # the group's own options, before the command
    head: list[str] = []
    i = 0
    while i < len(argv) and argv[i].startswith("-"):
        takes = values.get(argv[i].split("=", 1)[0], False) and "=" not in argv[i]
        head += argv[i:i + 1 + takes]
        i += 1 + takes
    if not any(t.split("=", 1)[0] in ("--config", "--no-config") for t in head):
        head += ["--config", settings] if settings else ["--no-config"]
    name = argv[i] if i < len(argv) else ""
    if name not in RERUNNABLE:
        raise click.UsageError(f"the recorded command line runs {name or 'no command'!r}; "
                               f"--rerun repeats {', '.join(RERUNNABLE)}")
    module, attr = COMMANDS[name][0].split(":")
    command: click.Command = getattr(importlib.import_module(module), attr)
    options = _options(command)
    kept: list[str] = []
    given = set(configured)
    rest = list(argv[i + 1:])
    j = 0
    while j < len(rest):
        token = rest[j]
        if token == "--":
            kept += rest[j:]
            break
        option = options.get(token.split("=", 1)[0] if token.startswith("--") else token)
        if option is None:
            kept.append(token)
            j += 1
            continue
        inline = token.startswith("--") and "=" in token
        n = 1 + (0 if option.is_flag or option.count or inline else option.nargs)
        if option.name not in OUTPUTS:
            kept += rest[j:j + n]
        else:
            given.add(str(option.name))
        j += n
    outputs = []
    for param in command.params:
        if isinstance(param, click.Option) and param.name in OUTPUTS and (
                param.name in given or isinstance(param.default, str | os.PathLike)
                or param.name == "evidence_paths"):  # a path as default: written unasked
            outputs += [param.opts[0], str(folder / OUTPUTS[param.name])]
    return [*head, name, *kept, *outputs]


def _configured(argv: Sequence[str], settings: str | None) -> set[str]:
    """The parameters of the recorded command that the settings file ``settings`` sets (None,
    or a file that cannot be read now: none; the repeat reports the latter)."""
    if settings is None:
        return set()
    try:
        config = read_config(settings, command_names=list(COMMANDS))
    except FidelityError:
        return set()
    names = [a for a in argv if a in COMMANDS]
    return set(config.default_map(names[:1]).get(names[0], {})) if names else set()


def rerun(doc: Mapping[str, Any]) -> tuple[dict[str, Any] | None, int, str]:
    """Run the record's command line again (:func:`rerun_argv`) in the folder it ran in, as a
    process of this Python; returns the new record (None if none was written), the exit code
    and the last line of its errors."""
    invocation = doc.get("invocation")
    if not invocation:
        raise InputFileError("the record holds no command line (made through the API, or by a "
                             "fidelity before record layout 1.1): nothing to run again")
    cwd = invocation.get("cwd")
    try:
        here = bool(cwd) and Path(cwd).is_dir()
    except (OSError, ValueError):  # a name too long, or holding a NUL
        here = False
    if not here:
        raise InputFileError(f"{display_path(cwd or '')[:300]}: the folder the run started in is "
                             "not here; --rerun runs the command line there")
    with tempfile.TemporaryDirectory(prefix="fidelity-rerun-") as tmp:
        settings = (invocation.get("settings") or {}).get("path")
        argv = rerun_argv(invocation["argv"], Path(tmp), settings,
                          _configured(invocation["argv"], settings))
        proc = subprocess.run([sys.executable, "-m", "fidelity", *argv], cwd=cwd,
                              capture_output=True, text=True, env=dict(os.environ),
                              check=False)
        errors = [line for line in proc.stderr.splitlines() if line.strip()]
        try:
            new = read_record(Path(tmp) / OUTPUTS["evidence_paths"])
        except SchemaError:
            new = None
    return new, proc.returncode, errors[-1] if errors else ""


@click.command()
@click.argument("record", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--inputs", "inputs_dir", type=click.Path(file_okay=False, exists=True,
                                                        path_type=Path), default=None,
              help="Folder in which to look for a file (by its name) that is not where the "
                   "record says: inputs handed over beside the record.")
@click.option("--rerun", "run_again", is_flag=True,
              help="Also run the recorded command line again, in the folder it ran in, with "
                   "its outputs sent to a temporary folder, and compare: the same exit code "
                   "and verdicts, each value within the record's standard uncertainty.")
@click.option("--chain", "chain", is_flag=True,
              help="Also walk each table the record names to its raw data: the table's "
                   "SHA-256 as recorded, each scores file it names (in the source checkout) "
                   "with the SHA-256 the table holds, and the table's rows rebuilt from them, "
                   "every number the same.")
@click.option("--annotations", default=None, type=click.Path(dir_okay=False, exists=True,
                                                             path_type=Path),
              help="With --chain: the sweep's COCO annotations, to rebuild the standard "
                   "errors too (default: the shared data's copy of the file the table names; "
                   "without one, the losses are compared without their standard errors).")
@json_option("Write the findings as JSON")
@common_options
def verify(record: Path, inputs_dir: Path | None, run_again: bool, chain: bool,
           annotations: Path | None, json_path: str | None) -> None:
    """Check a credibility record against the files it names; --rerun repeats its run.

    RECORD is the JSON record of check, audit, gate, compare or fit (--evidence FILE.json).

    Every input, prediction and calibration table, settings file and written correction is
    hashed again (SHA-256) and compared with the record; this installation's code and library
    versions are compared with the record's. Exit 0: every file as recorded (and, with
    --rerun, the run reproduced; with --chain, every link from the record to the rows
    rebuilt from the scores files); 1: a file changed or missing, the run not reproduced, or
    a link of the chain broken (named); 2:
    RECORD is not a readable credibility record. A different code or environment is reported,
    not failed: the record stays a true account of its own run.
    """
    check_outputs({"--json": json_path}, {"RECORD": record})
    doc = read_record(record)
    result = verify_document(doc, record, inputs=inputs_dir)
    result = replace(result, findings=(*result.findings,
                                       *ssp_findings(doc, record, inputs_dir)))
    if annotations is not None and not chain:
        raise InvalidValueError("--annotations: it is for --chain (the rows rebuilt with "
                                "their standard errors)")
    if chain:
        result = replace(result, findings=(*result.findings, *chain_findings(
            doc, record, annotations=annotations)))
    if run_again:
        new, code, message = rerun(doc)
        result = replace(result, findings=(*result.findings,
                                           rerun_finding(doc, new, code, message)))
    for line in verification_lines(result):
        click.echo(line)
    if json_path:
        where = write_json_output(json_path, result.to_json())
        if where != "standard output":
            click.echo(f"wrote {where}")
    sys.exit(0 if result.verified else 1)
