"""The ``fidelity`` command line: a thin layer over the library.

Each subcommand lives in its own module ``fidelity/cli/<name>.py`` and is registered in
:data:`COMMANDS`; modules are imported only when their command runs (or for ``--help``), so a
slow import (Mitsuba, onnxruntime) never delays another command.

Errors caused by input (:class:`fidelity.errors.FidelityError`) print one line on stderr and
exit with code 2. ``fidelity gate`` additionally uses exit code 1 for a failed gate.
"""

from __future__ import annotations

import importlib
import sys
from typing import Any

import click

from fidelity import __version__
from fidelity.errors import FidelityError

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


class LazyGroup(click.Group):
    """A click group whose subcommands are imported on first use."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(COMMANDS)

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        target = COMMANDS.get(cmd_name)
        if target is None:
            return None
        module_name, attr = target.split(":")
        return getattr(importlib.import_module(module_name), attr)

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except FidelityError as exc:
            click.echo(f"fidelity: error: {exc}", err=True)
            sys.exit(exc.exit_code)


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="fidelity")
def main() -> None:
    """Colour fidelity of simulated cameras, and what its error costs object detectors.

    \b
    Start with:  fidelity check          (render the built-in camera, measure, predict, verdict)
                 fidelity audit IMAGE    (measure the chart in a render or photo)
                 fidelity gate IMAGE --max-delta-e 3   (pass/fail for CI)
    """


__all__ = ["COMMANDS", "main"]
