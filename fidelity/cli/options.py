"""Options every command shares, so one idea has one flag everywhere.

The vocabulary (also in the docs' command table):

- ``--images DIR``: a folder of images; ``--annotations FILE``: COCO annotations;
- ``--models A.onnx,B.onnx@250``: ONNX detectors (``@N``: that model on the first N images by
  id); ``--limit N``: at most N images (first N by id) for every model;
- ``--transforms all|NAME,...``: SAFE-COLOR transforms; ``--targets 0,1,3``: chart ΔE targets of
  the transforms; ``--delta-e X``: a chart's measured ΔE (``predict``);
- ``--camera``, ``--illuminant``, ``--reference``, ``--table``, ``--size``: as in ``check``;
- ``--out DIR``: the folder a command writes several files to; ``--json FILE`` (``-`` for
  stdout: then nothing else is printed there), ``--html FILE``, ``--junit FILE``: one report;
- ``-q/--quiet``: print nothing but errors (and JSON asked for on stdout); ``-v/--verbose``:
  show the traceback of an internal error; ``--progress/--no-progress``: progress bars (default:
  when stderr is a terminal; never in a CI log).
"""

from __future__ import annotations

import contextlib
import functools
import io
import json
import os
import sys
from collections.abc import Callable
from typing import Any, TypeVar

import click

F = TypeVar("F", bound=Callable[..., Any])

#: The ``--json`` value that means standard output.
STDOUT = "-"


def _state() -> dict[str, Any]:
    ctx = click.get_current_context()
    root = ctx.find_root()
    obj: dict[str, Any] = root.ensure_object(dict)
    return obj


def common_options(f: F) -> F:
    """Add ``-q/--quiet`` and ``-v/--verbose`` to a command. Quiet (or ``--json -``) sends the
    command's ordinary printing to nowhere; JSON asked for on stdout still goes there
    (:func:`write_json_output`)."""

    @functools.wraps(f)
    def wrapper(*args: Any, quiet: bool, verbose: bool, **kwargs: Any) -> Any:
        state = _state()
        state["verbose"] = bool(state.get("verbose")) or verbose
        state["stdout"] = sys.stdout
        silent = quiet or str(kwargs.get("json_path") or "") == STDOUT
        with contextlib.redirect_stdout(io.StringIO()) if silent else contextlib.nullcontext():
            return f(*args, **kwargs)

    wrapper = click.option("-v", "--verbose", is_flag=True,
                           help="Show the traceback of an internal error.")(wrapper)
    wrapper = click.option("-q", "--quiet", is_flag=True,
                           help="Print nothing but errors (and JSON asked for on stdout).")(
        wrapper)
    return wrapper  # type: ignore[return-value]


def from_settings(name: str) -> bool:
    """Whether option ``name`` of the running command has its value from the settings file."""
    from click.core import ParameterSource

    return click.get_current_context().get_parameter_source(name) == ParameterSource.DEFAULT_MAP


def progress_option(f: F) -> F:
    """``--progress/--no-progress`` (default: show progress when stderr is a terminal)."""
    return click.option("--progress/--no-progress", default=None,
                        help="Progress bars (default: when stderr is a terminal).")(f)


def show_progress(progress: bool | None) -> bool:
    """Whether to draw progress bars: as asked, else only when stderr is a terminal."""
    if progress is not None:
        return progress
    return sys.stderr.isatty()


def json_option(help_text: str) -> Callable[[F], F]:
    """``--json FILE`` (``-``: standard output), stored as ``json_path``."""
    return click.option("--json", "json_path", type=click.Path(dir_okay=False), default=None,
                        help=f"{help_text} ('-': standard output).")


def bound_option(f: F) -> F:
    """``--bound classic|directional``: which prediction decides a ``--max-dmap`` verdict (both
    are reported)."""
    return click.option(
        "--bound", type=click.Choice(["classic", "directional"]), default="classic",
        show_default=True,
        help="Prediction that decides a --max-dmap verdict: the classic worst case over every "
             "transform, or the direction-aware one (both are reported).")(f)


def measure_options(f: F) -> F:
    """``--measure`` and what it runs on: ``--images DIR``, ``--annotations FILE``,
    ``--models A.onnx[@N]``, ``--limit N`` (default: the shared data folder's COCO subset and
    YOLOX-nano)."""
    opts = [
        click.option("--measure", is_flag=True,
                     help="Also measure the loss on COCO: emulate this colour rendering on the "
                          "images and run a detector (ΔmAP ± SE; the baseline is cached)."),
        click.option("--images", default=None, type=click.Path(file_okay=False),
                     help="With --measure: COCO image folder (default: "
                          "$FIDELITY_SHARED/coco/val2017)."),
        click.option("--annotations", default=None, type=click.Path(dir_okay=False),
                     help="With --measure: COCO annotations (default: the shared subset's)."),
        click.option("--models", default=None,
                     help="With --measure: ONNX detector(s), PATH[@N] comma-separated "
                          "(default: the shared yolox_nano.onnx)."),
        click.option("--limit", type=click.IntRange(min=1), default=None,
                     help="With --measure: at most N images (first N by id)."),
    ]
    for opt in reversed(opts):
        f = opt(f)
    return f


def measure_inputs(images: str | None, annotations: str | None, models: str | None
                   ) -> dict[str, Any]:
    """What ``--measure`` reads, for :func:`fidelity.fileio.check_outputs`: the image folder,
    the annotations and each model file."""
    found: dict[str, Any] = {"--images": images, "--annotations": annotations}
    for m in (models or "").split(","):
        path = m.strip().rsplit("@", 1)[0] if "@" in m else m.strip()
        if path:
            found[f"--models ({path})"] = path
    return found


def measure_request(measure: bool, images: str | None, annotations: str | None,
                    models: str | None, limit: int | None) -> Any:
    """The :class:`fidelity.coco.measure.MeasureRequest` of the ``--measure`` options (None
    without ``--measure``; the other options then must not be given)."""
    if not measure:
        if any(v is not None for v in (images, annotations, models, limit)) and not all(
                from_settings(n) for n, v in (("images", images), ("annotations", annotations),
                                              ("models", models), ("limit", limit))
                if v is not None):
            raise click.UsageError("--images, --annotations, --models and --limit go with "
                                   "--measure")
        return None
    from fidelity.coco.measure import MeasureRequest, resolve_coco_inputs

    return MeasureRequest(resolve_coco_inputs(images, annotations, models), limit=limit,
                          progress=show_progress(None))


def real_stdout() -> Any:
    """The standard output of the command line (also under ``--quiet``)."""
    with contextlib.suppress(RuntimeError):
        out = _state().get("stdout")
        if out is not None:
            return out
    return sys.stdout


def write_json_output(path: str | os.PathLike[str], obj: Any) -> str:
    """Write JSON to ``path`` atomically, or to standard output for ``-``; returns where."""
    from fidelity.fileio import json_ready, write_json_atomic

    if str(path) == STDOUT:
        out = real_stdout()
        out.write(json.dumps(json_ready(obj), indent=2, allow_nan=False) + "\n")
        out.flush()
        return "standard output"
    return str(write_json_atomic(path, obj))


__all__ = [
    "STDOUT",
    "bound_option",
    "common_options",
    "from_settings",
    "json_option",
    "measure_inputs",
    "measure_options",
    "measure_request",
    "progress_option",
    "real_stdout",
    "show_progress",
    "write_json_output",
]
