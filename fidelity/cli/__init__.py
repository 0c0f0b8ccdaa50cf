"""The ``fidelity`` command line: a thin layer over the library.

Each subcommand lives in its own module ``fidelity/cli/<name>.py`` and is registered in
:data:`COMMANDS`; modules are imported only when their command runs (or for ``--help``), so a
slow import (Mitsuba, onnxruntime) never delays another command.

One error boundary (:meth:`LazyGroup.invoke`) turns every failure into an exit code:

- 0: done (a gate passed); 1: a gate failed; 4: a gate undecided (``--decision guarded``:
  the value within its expanded uncertainty of the limit; ``--strict`` makes it 1);
- 2: the input is wrong (:class:`fidelity.core.errors.FidelityError`, or a usage error of click's
  such as an unknown option or a bad value): one line ``fidelity: error: <input>: <problem>``;
- 3: anything else is a bug: one line on screen, the traceback in a log file
  (:func:`internal_error_log`); ``fidelity -v`` shows it on screen too.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import errno
import importlib
import os
import sys
import tempfile
import traceback
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import click

from fidelity.core.errors import FidelityError
from fidelity.core.version import __version__

#: Exit code of an internal error (a bug), after 0 pass, 1 fail, 2 input error.
EXIT_INTERNAL = 3

#: command name -> ("module:attribute" of its click command, one-line help). The help listing
#: reads the line from here, so ``fidelity --help`` imports no command (a test keeps both equal).
COMMANDS: dict[str, tuple[str, str]] = {
    "audit": ("fidelity.cli.audit:audit",
              "Measure the chart in IMAGE: ΔE00 per patch, mean and max, exposure, bad pixels."),
    "calibrate": ("fidelity.cli.calibrate:calibrate", "Print the SAFE-COLOR calibration table."),
    "check": ("fidelity.cli.check:check",
              "Is this camera model's colour good enough for perception testing?"),
    "coco-c": ("fidelity.cli.cococ:cococ",
               "Measure COCO-C's corruptions: chart value and ΔmAP per severity."),
    "compare": ("fidelity.cli.compare:compare",
                "Compare a simulated chart with the real camera's: sim-to-real ΔE00 and its "
                "cost."),
    "dataset": ("fidelity.cli.dataset:dataset",
                "Write transformed JPEGs (original quantization tables and subsampling); reruns "
                "resume."),
    "evaluate": ("fidelity.cli.evaluate:evaluate",
                 "Run detectors on a COCO image folder and print COCO box AP."),
    "fit": ("fidelity.cli.fit:fit",
            "Fit the correction from the simulator's chart onto the real camera's, as a 3D "
            "LUT."),
    "gate": ("fidelity.cli.gate:gate",
             "Gate a camera's colour fidelity: exit 0 pass, 1 fail, 2 input error, 3 bug, 4 "
             "undecided (--decision guarded)."),
    "info": ("fidelity.cli.info:info",
             "Versions, Mitsuba variant, ONNX providers, chart detection, shared data found."),
    "predict": ("fidelity.cli.predict:predict_cmd",
                "Predict what a chart ΔE costs detectors, or the ΔE limit of a loss budget."),
    "qualify": ("fidelity.cli.qualify:qualify",
                "Check this installation against independent references (tool "
                "qualification)."),
    "render": ("fidelity.cli.render:render",
               "Render the spectral Macbeth chart through a camera model and measure ΔE00 per "
               "patch."),
    "scene": ("fidelity.cli.scene:scene",
              "Export the chart scene for a simulator: glTF, OpenUSD or Mitsuba 3, with a "
              "manifest."),
    "suite": ("fidelity.cli.suite:suite",
              "Check every camera of a suite file under its own illuminant and chromatic "
              "adaptation."),
    "sweep": ("fidelity.cli.sweep:sweep",
              "Run (or resume) the COCO sweep; one line per finished cell on stderr ([k/N] "
              "cells)."),
    "tables": ("fidelity.cli.tables:tables",
               "Worst case per model and size class, paper comparison, plots, Markdown/HTML "
               "report."),
    "validate": ("fidelity.cli.validate:validate",
                 "Render every camera's chart, predict its ΔmAP, emulate it on COCO and measure "
                 "ΔmAP."),
    "verify": ("fidelity.cli.verify:verify",
               "Check a credibility record against the files it names; --rerun repeats its run."),
}


def error_line(message: str) -> None:
    """Print ``fidelity: error: <message>`` as one line on stderr (undecodable bytes of file
    names shown as ``\\xNN``)."""
    from fidelity.core.fileio import printable

    click.echo("fidelity: error: " + printable(" ".join(str(message).split())), err=True)


#: errno values of an :class:`OSError` that is about the machine, not the program: a full
#: disk, a quota, a read-only or unreadable place, a missing file (exit 2, one line).
ENVIRONMENT_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES,
                                errno.EPERM, errno.EFBIG, errno.ENOENT, errno.ENOTDIR,
                                errno.EISDIR, errno.ENAMETOOLONG, errno.EIO, errno.ELOOP,
                                errno.EMFILE, errno.ENFILE, errno.ENOMEM})

#: Words of SQLite errors that are about the disk, not the program (exit 2, one line).
SQLITE_DISK_ERRORS = ("disk is full", "disk i/o error", "readonly database",
                      "unable to open database file", "not a database",
                      "database disk image is malformed")


def environment_error(exc: BaseException) -> str | None:
    """The one-line message for an exception caused by the machine rather than by fidelity
    (:data:`ENVIRONMENT_ERRNOS`, :data:`SQLITE_DISK_ERRORS`, a module of an extra that is not
    installed), else None."""
    from fidelity.core.fileio import display_path

    if isinstance(exc, ModuleNotFoundError):
        from fidelity.pipeline.environment import DISTRIBUTION, missing_extra

        found = missing_extra(exc.name)
        if found is not None:
            return (f"{found[0]}: not installed; this command needs the [{found[1]}] extra: "
                    f"pip install '{DISTRIBUTION}[{found[1]}]'")
    if isinstance(exc, OSError) and exc.errno in ENVIRONMENT_ERRNOS:
        reason = exc.strerror or str(exc)
        return f"{display_path(exc.filename)}: {reason}" if exc.filename else reason
    if type(exc).__module__ == "sqlite3" and any(w in str(exc).lower()
                                                 for w in SQLITE_DISK_ERRORS):
        return (f"results store: {exc} (the SQLite store in the folder the command writes its "
                "results to; free some space there or give another folder)")
    return None


def internal_error_log() -> Path:
    """A new log file for an internal error's traceback: in ``$FIDELITY_CACHE/logs`` (default
    ``~/.cache/fidelity/logs``), or the system's temporary folder when that is not writable."""
    base = Path(os.environ.get("FIDELITY_CACHE") or Path.home() / ".cache" / "fidelity")
    stamp = _dt.datetime.now().strftime("%Y%m%dT%H%M%S")
    for folder in (base / "logs", Path(tempfile.gettempdir())):
        try:
            folder.mkdir(parents=True, exist_ok=True)
            fd, name = tempfile.mkstemp(prefix=f"fidelity-{stamp}-", suffix=".log", dir=folder)
            os.close(fd)
            return Path(name)
        except OSError:
            continue
    raise OSError("no writable folder for the log")


class LazyGroup(click.Group):
    """A click group whose subcommands are imported on first use, with the error boundary."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(COMMANDS)

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        entry = COMMANDS.get(cmd_name)
        if entry is None:
            return None
        module_name, attr = entry[0].split(":")
        command: click.Command = getattr(importlib.import_module(module_name), attr)
        return command

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        """The command list of ``--help``, from :data:`COMMANDS` (no command is imported)."""
        rows = [(name, help_line) for name, (_, help_line) in sorted(COMMANDS.items())]
        with formatter.section("Commands"):
            formatter.write_dl(rows)

    def main(self, *args: Any, **kwargs: Any) -> Any:
        """Run the command line; errors of the group's own options are one line too. The
        arguments are kept (``ctx.obj["argv"]``) for a credibility record's ``invocation``."""
        kwargs["standalone_mode"] = False
        argv = kwargs.get("args", args[0] if args else None)
        kwargs["obj"] = {"argv": list(sys.argv[1:] if argv is None else argv)}
        try:
            code = super().main(*args, **kwargs)
        except click.exceptions.NoArgsIsHelpError as exc:  # plain `fidelity`: the help
            click.echo(exc.format_message())
            sys.exit(0)
        except click.ClickException as exc:
            error_line(exc.format_message())
            sys.exit(2)
        except click.exceptions.Abort:
            click.echo("fidelity: interrupted", err=True)
            sys.exit(130)
        sys.exit(code if isinstance(code, int) else 0)

    def invoke(self, ctx: click.Context) -> Any:
        try:
            with quiet_warnings(ctx):
                return super().invoke(ctx)
        except FidelityError as exc:
            error_line(str(exc))
            sys.exit(exc.exit_code)
        except click.exceptions.Exit:
            raise
        except click.ClickException as exc:  # usage errors: one line, like every other error
            error_line(exc.format_message())
            sys.exit(2)
        except (click.exceptions.Abort, KeyboardInterrupt):
            click.echo("fidelity: interrupted", err=True)
            sys.exit(130)
        except BrokenPipeError:  # `fidelity ... | head`: the reader left; stop quietly
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
            sys.exit(141)
        except Exception as exc:  # noqa: BLE001 - the boundary: a bug is exit 3, not a traceback
            message = environment_error(exc)
            if message is not None:  # a full disk, a read-only folder: not a bug
                error_line(message)
                sys.exit(2)
            from fidelity.core.fileio import printable

            text = printable(traceback.format_exc())
            try:
                log = internal_error_log()
                log.write_text(f"fidelity {__version__}: {printable(' '.join(sys.argv))}\n"
                               f"{text}", encoding="utf-8")
                where = f"the traceback is in {log}"
            except OSError:
                where = "no log could be written"
            verbose = bool(ctx.obj and ctx.obj.get("verbose"))
            if verbose:
                click.echo(text, err=True)
            first = printable(" ".join(str(exc).split()))
            click.echo(f"fidelity: internal error: {type(exc).__name__}: {first} (a bug; "
                       f"{where})", err=True)
            sys.exit(EXIT_INTERNAL)


@contextlib.contextmanager
def quiet_warnings(ctx: click.Context) -> Iterator[None]:
    """Keep Python warnings (numpy's floating-point warnings, libraries' notices) off the
    screen while a command runs: the results they concern are checked and reported as errors
    instead. With ``-v`` they are printed at the end, one line each."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("default")
        try:
            yield
        finally:
            if ctx.obj and ctx.obj.get("verbose"):
                for w in caught:
                    click.echo(f"fidelity: warning: {w.category.__name__}: {w.message} "
                               f"({w.filename}:{w.lineno})", err=True)


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="fidelity")
@click.option("-v", "--verbose", is_flag=True, help="Show the traceback of an internal error.")
@click.option("--config", "config_path", type=click.Path(dir_okay=False), default=None,
              help="Settings file (default: the nearest fidelity.toml, or pyproject.toml with "
                   "[tool.fidelity], from the working folder up).")
@click.option("--no-config", is_flag=True, help="Ignore any settings file.")
@click.pass_context
def main(ctx: click.Context, verbose: bool, config_path: str | None, no_config: bool) -> None:
    """Colour fidelity of simulated cameras, and what its error costs object detectors.

    \b
    Start with:  fidelity check          (render the built-in camera, measure, predict, verdict)
                 fidelity audit IMAGE    (measure the chart in a render or photo)
                 fidelity gate IMAGE --max-delta-e 3   (pass/fail for CI)
    Exit codes:  0 pass, 1 fail, 2 input error, 3 internal error (a bug; see the log named),
                 4 undecided (--decision guarded: within U of the limit; --strict: 1)
    Settings:    [tool.fidelity] in pyproject.toml or fidelity.toml (camera, max_delta_e,
                 reference, table, ...); options on the command line win.
    """
    ctx.obj = {**(ctx.obj or {}), "verbose": verbose}
    if no_config:
        return
    from fidelity.core.config import find_config, read_config

    found = config_path or find_config()
    if found is not None:
        config = read_config(found, command_names=list(COMMANDS))
        ctx.obj["config"] = config
        ctx.default_map = config.default_map(list(COMMANDS))


__all__ = ["COMMANDS", "ENVIRONMENT_ERRNOS", "EXIT_INTERNAL", "SQLITE_DISK_ERRORS", "LazyGroup",
           "environment_error", "error_line", "internal_error_log", "main", "quiet_warnings"]
