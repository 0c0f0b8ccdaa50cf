"""The ``fidelity`` command line: a thin layer over the library.

Each subcommand lives in its own module ``fidelity/cli/<name>.py`` and is registered in
:data:`COMMANDS`; modules are imported only when their command runs (or for ``--help``), so a
slow import (Mitsuba, onnxruntime) never delays another command.

One error boundary (:meth:`LazyGroup.invoke`) turns every failure into an exit code:

- 0: done (a gate passed); 1: a gate failed;
- 2: the input is wrong (:class:`fidelity.errors.FidelityError`, or a usage error of click's
  such as an unknown option or a bad value): one line ``fidelity: error: <input>: <problem>``;
- 3: anything else is a bug: one line on screen, the traceback in a log file
  (:func:`internal_error_log`); ``fidelity -v`` shows it on screen too.
"""

from __future__ import annotations

import datetime as _dt
import importlib
import os
import sys
import tempfile
import traceback
from pathlib import Path
from typing import Any

import click

from fidelity import __version__
from fidelity.errors import FidelityError

#: Exit code of an internal error (a bug), after 0 pass, 1 fail, 2 input error.
EXIT_INTERNAL = 3

#: command name -> "module:attribute" of its click command.
COMMANDS: dict[str, str] = {
    "audit": "fidelity.cli.audit:audit",
    "check": "fidelity.cli.check:check",
    "gate": "fidelity.cli.gate:gate",
    "info": "fidelity.cli.info:info",
    "predict": "fidelity.cli.predict:predict_cmd",
    "calibrate": "fidelity.cli.calibrate:calibrate",
    "dataset": "fidelity.cli.dataset:dataset",
    "evaluate": "fidelity.cli.evaluate:evaluate",
    "render": "fidelity.cli.render:render",
    "sweep": "fidelity.cli.sweep:sweep",
    "tables": "fidelity.cli.tables:tables",
    "validate": "fidelity.cli.validate:validate",
}


def error_line(message: str) -> None:
    """Print ``fidelity: error: <message>`` as one line on stderr."""
    click.echo("fidelity: error: " + " ".join(str(message).split()), err=True)


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
        target = COMMANDS.get(cmd_name)
        if target is None:
            return None
        module_name, attr = target.split(":")
        command: click.Command = getattr(importlib.import_module(module_name), attr)
        return command

    def main(self, *args: Any, **kwargs: Any) -> Any:
        """Run the command line; errors of the group's own options are one line too."""
        kwargs["standalone_mode"] = False
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
            text = traceback.format_exc()
            try:
                log = internal_error_log()
                log.write_text(f"fidelity {__version__}: {' '.join(sys.argv)}\n{text}",
                               encoding="utf-8")
                where = f"the traceback is in {log}"
            except OSError:
                where = "no log could be written"
            verbose = bool(ctx.obj and ctx.obj.get("verbose"))
            if verbose:
                click.echo(text, err=True)
            first = " ".join(str(exc).split())
            click.echo(f"fidelity: internal error: {type(exc).__name__}: {first} (a bug; "
                       f"{where})", err=True)
            sys.exit(EXIT_INTERNAL)


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="fidelity")
@click.option("-v", "--verbose", is_flag=True, help="Show the traceback of an internal error.")
@click.pass_context
def main(ctx: click.Context, verbose: bool) -> None:
    """Colour fidelity of simulated cameras, and what its error costs object detectors.

    \b
    Start with:  fidelity check          (render the built-in camera, measure, predict, verdict)
                 fidelity audit IMAGE    (measure the chart in a render or photo)
                 fidelity gate IMAGE --max-delta-e 3   (pass/fail for CI)
    Exit codes:  0 pass, 1 fail, 2 input error, 3 internal error (a bug; see the log named)
    """
    ctx.obj = {"verbose": verbose}


__all__ = ["COMMANDS", "EXIT_INTERNAL", "LazyGroup", "error_line", "internal_error_log", "main"]
