"""Options every command shares, so one idea has one flag everywhere.

The vocabulary (also in the docs' command table):

- ``--images DIR``: a folder of images; ``--annotations FILE``: COCO annotations;
- ``--models A.onnx,B.onnx@250``: ONNX detectors (:class:`ModelList`; ``@N``: that model on at
  most N images); ``--limit N``: at most N images for every model (:data:`LIMIT_HELP`). Both
  select the first N annotated images by image id; with both, the smaller N wins
  (:func:`cap_models`);
- ``--transforms all|NAME,...``: SAFE-COLOR transforms (:class:`TransformNames`);
  ``--targets 0,1,3``: chart ΔE targets of the transforms (:class:`Targets`); ``--delta-e X``:
  a chart's measured ΔE (``predict``); ``--severities 1-5``: COCO-C severities
  (:class:`Severities`);
- ``--encoding``, ``--exposure``, ``--layer``, ``--bayer``, ``--colourspace``,
  ``--ocio-colourspace``, ``--ocio-config``, ``--negatives``, and for a robot recording
  ``--topic``, ``--frame``, ``--time`` (and for a video ``--video-matrix``, ``--video-range``):
  how an image is read (:func:`image_read_options`, one ``read`` argument);
- ``--camera``, ``--illuminant``, ``--reference``, ``--table``, ``--size``: as in ``check``;
- ``--out DIR``: the folder a command writes several files to; ``--json FILE`` (``-`` for
  stdout: then nothing else is printed there), ``--html FILE``, ``--junit FILE``: one report;
- ``-q/--quiet``: print nothing but errors (and JSON asked for on stdout; with ``--json -``
  and no ``-q`` the ordinary printing goes to stderr); ``-v/--verbose``:
  show the traceback of an internal error; ``--progress/--no-progress``: progress bars (default:
  when stderr is a terminal; never in a CI log).
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import io
import math
import os
import re
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import click

from fidelity.chart.read import ReadOptions
from fidelity.chart.recording import FrameSelection, absolute_time_ns, parse_frames
from fidelity.cli.context import STDOUT, command_state, settings_line
from fidelity.cli.values import decision_rule, parse_models
from fidelity.colour.colorimetry import CHROMATIC_ADAPTATION_METHODS
from fidelity.core.errors import InvalidValueError, unknown_name
from fidelity.prediction.calibration import MAX_TARGETS
from fidelity.prediction.directional import BOUNDS
from fidelity.prediction.exposure import DEFAULT_MAX_EXPOSURE_ERROR_EV
from fidelity.prediction.judge import JudgeOptions
from fidelity.prediction.tablefile import CLASS_COLUMNS, SIZES
from fidelity.prediction.transforms import TRANSFORMS
from fidelity.prediction.verdict import SIMPLE
from fidelity.report.evidencefile import evidence_format
from fidelity.scene.manifest import read_manifest

if TYPE_CHECKING:
    from typing import TypeAlias

    from fidelity.coco.sweep import ModelSpec

    # click >= 8.2 types ParamType by its value; the project supports click 8.1 too
    ParamTypeBase: TypeAlias = click.ParamType[Any]
else:
    ParamTypeBase = click.ParamType

F = TypeVar("F", bound=Callable[..., Any])

#: A file argument or option (a path, not a folder).
PATH = click.Path(dir_okay=False, path_type=Path)


# --------------------------------------------------------------------------------------------
# Value types: each parses one idea's text, the same way in every command. A bad value is an
# InvalidValueError naming the option and the value (one line, exit 2).


def _flag(param: click.Parameter | None, default: str) -> str:
    return param.opts[0] if param is not None and param.opts else default


class Targets(ParamTypeBase):
    """Chart ΔE targets of the transforms: ``1,2,3`` and ranges ``1-12`` (inclusive, step 1)
    -> a list of floats. ``baseline``: 0 is allowed (the decode + re-encode baseline)."""

    name = "targets"

    def __init__(self, *, baseline: bool) -> None:
        self.baseline = baseline

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> list[float]:
        if not isinstance(value, str):
            return list(value)
        return self.parse(value, _flag(param, "--targets"))

    def parse(self, text: str, what: str) -> list[float]:
        """The targets of ``text``; errors name ``what`` (the option)."""
        values: list[float] = []
        for part in (p.strip() for p in text.split(",")):
            if not part:
                continue
            m = re.fullmatch(r"(\d+(?:\.\d*)?)-(\d+(?:\.\d*)?)", part)
            try:
                if m:
                    lo, hi = float(m.group(1)), float(m.group(2))
                    if not hi - lo < MAX_TARGETS:  # before the range is built
                        raise InvalidValueError(f"{what}: the range {part} has more than "
                                                f"{MAX_TARGETS} values")
                    values.extend(lo + k for k in range(int(hi - lo) + 1) if lo + k <= hi + 1e-9)
                else:
                    values.append(float(part))
            except ValueError:
                raise InvalidValueError(f"{what}: cannot read {part!r} as a number or a range "
                                        "a-b") from None
            if not all(math.isfinite(v) and (v > 0 or (self.baseline and v == 0))
                       for v in values):
                kind = "non-negative" if self.baseline else "positive"
                raise InvalidValueError(f"{what}: {part!r} is not a {kind} finite ΔE")
        if not values:
            raise InvalidValueError(f"{what}: no values given")
        if len(values) > MAX_TARGETS:
            raise InvalidValueError(f"{what}: {len(values)} values, at most {MAX_TARGETS}")
        return values


class Resolution(ParamTypeBase):
    """``WIDTHxHEIGHT`` in pixels (``640x480``) -> ``(width, height)``."""

    name = "WIDTHxHEIGHT"

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> tuple[int, int]:
        if isinstance(value, tuple):
            return value
        m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", str(value))
        if not m:
            self.fail(f"{value!r}: expected WIDTHxHEIGHT in pixels, e.g. 640x480", param, ctx)
        return int(m.group(1)), int(m.group(2))


class RecordingTime(ParamTypeBase):
    """``--time``: seconds after a recording's first message (``0.5``) -> float, or an
    absolute time (``@1700000000.25``, ``2023-11-14T22:13:20.25Z``) -> its text, checked
    (:func:`fidelity.chart.recording.absolute_time_ns`)."""

    name = "T"

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> float | str:
        if isinstance(value, float | int):
            return float(value)
        text = str(value).strip()
        try:
            return float(text)
        except ValueError:
            pass

        absolute_time_ns(text)  # a bad time is the one-line error here, before any reading
        return text


class FrameRange(ParamTypeBase):
    """``--frames``: frame numbers ``N,M,...`` or a range ``START:STOP[:STEP]`` of a
    recording's topic -> a :class:`fidelity.chart.recording.FrameSelection`."""

    name = "FRAMES"

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> Any:
        if isinstance(value, FrameSelection):
            return value
        return parse_frames(str(value))


class NameList(ParamTypeBase):
    """``all`` or comma-separated names from a known set -> a list of names."""

    name = "names"
    #: What one name is, in errors ("transform").
    what = "name"
    #: Whether ``none`` (no names) is accepted.
    none = False

    def __init__(self, *, none: bool | None = None) -> None:
        if none is not None:
            self.none = none

    def known(self) -> Sequence[str]:
        """The names accepted, in their canonical order (``all``: every one)."""
        raise NotImplementedError

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> list[str]:
        if not isinstance(value, str):
            return list(value)

        known = self.known()
        items = [t.strip() for t in value.split(",") if t.strip()]
        if items == ["all"]:
            return list(known)
        if items == ["none"] and self.none:
            return []
        if not items:
            raise InvalidValueError(f"{_flag(param, '--' + self.name)} {value!r}: names no "
                                    f"{self.what}")
        for t in items:
            if t not in known:
                err = unknown_name(self.what, t, known)
                raise type(err)(f"{_flag(param, '--' + self.name)}: {err}")
        return items


class TransformNames(NameList):
    """``--transforms``: SAFE-COLOR transforms (:data:`fidelity.prediction.transforms.TRANSFORMS`)."""

    name = "transforms"
    what = "transform"

    def known(self) -> Sequence[str]:
        return list(TRANSFORMS)


class DegradationNames(NameList):
    """``--degradations``: blur and noise families
    (:data:`fidelity.coco.degradations.DEGRADATIONS`)."""

    name = "degradations"
    what = "degradation"
    none = True

    def known(self) -> Sequence[str]:
        from fidelity.coco.degradations import DEGRADATIONS  # noqa: PLC0415 (the COCO benchmark, loaded at the call)

        return list(DEGRADATIONS)


class CorruptionNames(NameList):
    """``--corruptions``: COCO-C corruptions, colour and noise or blur
    (:data:`fidelity.coco.corruptions.ALL_CORRUPTIONS`)."""

    name = "corruptions"
    what = "corruption"

    def known(self) -> Sequence[str]:
        from fidelity.coco.corruptions import ALL_CORRUPTIONS  # noqa: PLC0415 (the COCO benchmark, loaded at the call)

        return ALL_CORRUPTIONS


class Severities(ParamTypeBase):
    """``--severities``: COCO-C severities, ``1-5`` or ``1,3,5`` -> sorted distinct ints 1..5."""

    name = "severities"

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> list[int]:
        if not isinstance(value, str):
            return sorted(set(value))
        what = f"{_flag(param, '--severities')} {value!r}"
        out: list[int] = []
        for part in value.split(","):
            a, _, b = part.strip().partition("-")
            try:
                lo, hi = int(a), int(b or a)
            except ValueError:
                raise InvalidValueError(f"{what}: expected e.g. 1-5 or 1,3,5") from None
            if not 1 <= lo <= hi <= 5:
                raise InvalidValueError(f"{what}: severities are 1 to 5")
            out += list(range(lo, hi + 1))
        return sorted(set(out))


class ModelList(ParamTypeBase):
    """``--models A.onnx,B.onnx@250``: ONNX detectors, each optionally ``@N`` (at most the first
    N annotated images by id) -> a tuple of :class:`fidelity.coco.sweep.ModelSpec`
    (:func:`parse_models`)."""

    name = "models"

    def get_metavar(self, param: click.Parameter, *args: Any, **kwargs: Any) -> str:
        return "PATH[@N],..."

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> tuple[ModelSpec, ...]:
        if not isinstance(value, str):
            return tuple(value)
        return parse_models(value, _flag(param, "--models"))


#: One text of ``--limit`` for every command that runs detectors on COCO images.
LIMIT_HELP = ("At most N images for every model: the first N annotated images by image id "
              "(a model's own @N caps it further; the smaller N wins).")


def limit_option(prefix: str = "") -> Callable[[F], F]:
    """``--limit N`` (:data:`LIMIT_HELP`; ``prefix``: e.g. "With --measure: ")."""
    return click.option("--limit", type=click.IntRange(min=1), default=None,
                        help=prefix + LIMIT_HELP)


# --------------------------------------------------------------------------------------------
# Where and how the COCO commands run their detectors and score them


def scorer_option(f: F) -> F:
    """``--scorer``: the COCO AP implementation (evaluate, sweep)."""
    from fidelity.coco.scoring import COCO_SCORERS  # noqa: PLC0415 (the COCO benchmark, loaded at the call)

    return click.option(
        "--scorer", type=click.Choice(["auto", *COCO_SCORERS]), default="auto",
        show_default=True,
        help="COCO AP implementation: pycocotools (reference) or faster-coco-eval (same numbers "
             "to 1e-4, tested; ~6x faster); auto: faster-coco-eval if installed.")(f)


def scores_options(store: str) -> Callable[[F], F]:
    """``--export-scores FILE`` and ``--import-scores FILE``: a results store's finished cells
    without their detections (:mod:`fidelity.coco.scores`; sweep, validate). ``store``: the
    option that names the store's folder."""
    def deco(func: F) -> F:
        func = click.option(
            "--import-scores", "import_scores", default=None, metavar="FILE",
            type=click.Path(dir_okay=False),
            help=f"Only make the store in {store} hold the cells of a scores file it does not "
                 "have (a new store: all; another machine's share of the same run: the rest); "
                 "rerun the command line on it to resume.")(func)
        func = click.option(
            "--export-scores", "export_scores", default=None, metavar="FILE",
            type=click.Path(dir_okay=False),
            help=f"Only write the finished cells of the store in {store} to a scores file "
                 "(JSON; gzip for a .gz name): their scores, fold and bootstrap scores and the "
                 "store's provenance, without the detections; needs --annotations; safe while "
                 "a run goes on.")(func)
        return func
    return deco


def executor_options(func: F) -> F:
    """``--executor``, ``--address``, ``--workers``: where the COCO commands run their
    detectors (sweep, validate, evaluate)."""
    func = click.option(
        "--workers", type=click.IntRange(min=1), default=None,
        help="Ray workers (actors), each with its own ONNX session and image cache "
             "(default: one per CPU of the cluster, or per GPU where it has GPUs).")(func)
    func = click.option(
        "--address", default=None, metavar="auto|ray://HOST:10001|HOST:PORT",
        help="Ray cluster to use: auto (the one started with `ray start` here), a Ray Client "
             "address, or a head node's address (default: start Ray on this machine).")(func)
    func = click.option(
        "--executor", type=click.Choice(["local", "ray"]), default="local", show_default=True,
        help="local: this process runs the detector; ray: Ray actors on this machine or a "
             "cluster run it (pip install 'camera-fidelity[ray]'); the store and the results "
             "are the same.")(func)
    return func


# --------------------------------------------------------------------------------------------
# How an image is read, and what is judged (audit, gate, compare)


#: An image argument: a file, or a recording (a ROS 2 bag is a folder).
IMAGE_PATH = click.Path(path_type=Path)

#: The command-line names of the image-reading options, as :class:`ReadOptions` names them.
READ_OPTION_NAMES = ("layer", "encoding", "exposure", "negatives", "colourspace", "bayer",
                     "topic", "frame", "time", "ocio_colourspace", "ocio_config",
                     "video_matrix", "video_range")


def chart_pair_options(f: F) -> F:
    """``--sim-corners``, ``--real-corners``, ``--sim-ocio-colourspace``,
    ``--real-ocio-colourspace`` and ``--normalise``: where the two charts of a simulated and a
    real image are, each image's own OpenColorIO colourspace, and how the simulated one is
    matched to the real one (compare)."""
    return _chart_pair_options(f, sim_ocio=True)


def fit_pair_options(f: F) -> F:
    """:func:`chart_pair_options` for ``fit``, whose correction maps SIM's own pixel values:
    ``--sim-ocio-colourspace`` is not offered (hidden, it stays accepted only to be refused
    with the reason)."""
    return _chart_pair_options(f, sim_ocio=False)


def _chart_pair_options(f: F, *, sim_ocio: bool) -> F:
    opts = [
        click.option("--sim-corners", default=None,
                     help="X1,Y1,...,X4,Y4: centres of the dark skin, bluish green, black and "
                          "white patches in SIM (default: the chart is found)."),
        click.option("--real-corners", default=None, help="The same for REAL."),
        click.option("--sim-ocio-colourspace", default=None, metavar="NAME",
                     hidden=not sim_ocio, help="SIM's own OpenColorIO colourspace (as --ocio-colourspace, for SIM "
                          "alone; the shared --encoding and --colourspace then describe "
                          "REAL)."),
        click.option("--real-ocio-colourspace", default=None, metavar="NAME",
                     help="The same for REAL." if sim_ocio else
                          "REAL's own OpenColorIO colourspace (as --ocio-colourspace, for "
                          "REAL alone; SIM is read as its own pixel values)."),
        click.option("--normalise", "normalise_mode",
                     type=click.Choice(["exposure", "exposure+wb", "none"]),
                     default="exposure", show_default=True,
                     help="Match the simulated chart to the real one on the neutral patches "
                          "before comparing: exposure, exposure and white balance, or "
                          "nothing."),
    ]
    for opt in reversed(opts):
        f = opt(f)
    return f


def image_read_options(f: F) -> F:
    """``--encoding``, ``--exposure``, ``--layer``, ``--bayer``, ``--colourspace``,
    ``--ocio-colourspace``, ``--ocio-config``, ``--negatives`` and, for a recording,
    ``--topic``, ``--frame``, ``--time``: how an image's pixels are read (audit, gate, compare,
    ...). The command receives them as one argument
    ``read``, a :class:`fidelity.chart.read.ReadOptions` (``max_pixels`` left at None:
    :func:`max_pixels_option` gives it separately)."""

    @functools.wraps(f)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        values = {name: kwargs.pop(name) for name in READ_OPTION_NAMES}
        if values["frame"] is not None and values["time"] is not None:
            raise click.UsageError("give --frame N or --time T, not both")
        return f(*args, read=ReadOptions(**values), **kwargs)

    opts = [
        click.option("--encoding", type=click.Choice(["linear", "srgb"]), default=None,
                     help="Pixel encoding (default: linear for EXR/HDR/float TIFF, sRGB "
                          "otherwise)."),
        click.option("--exposure", default=None,
                     help="auto (neutral patches; default for linear input) or a fixed EV "
                          "(pixels x 2**EV; default 0 for sRGB input)."),
        click.option("--layer", default=None,
                     help="EXR layer (e.g. 'diffuse' for diffuse.R) or part name."),
        click.option(
            "--bayer", type=click.Choice(["RGGB", "BGGR", "GRBG", "GBRG"], case_sensitive=False),
            default=None,
            help="The image is a one-channel camera raw Bayer mosaic (PNG/TIFF) with this CFA "
                 "pattern (top-left 2x2): demosaic it (Malvar 2004, colour-demosaicing), values "
                 "taken as linear."),
        click.option(
            "--colourspace", default=None,
            help="RGB primaries of the pixels: a colour-science name (ACEScg, 'ITU-R BT.2020', "
                 "'Display P3', ...). Default: the EXR's chromaticities attribute, else sRGB."),
        click.option(
            "--ocio-colourspace", default=None, metavar="NAME",
            help="The pixels are in this colourspace of an OpenColorIO config (ACEScct, "
                 "'ARRI LogC4', 'Display P3 - Display', ...): OpenColorIO converts them to "
                 "linear sRGB (scene-referred) or display sRGB. Instead of --encoding and "
                 "--colourspace (pip install 'camera-fidelity[ocio]')."),
        click.option(
            "--ocio-config", default=None, metavar="CONFIG",
            help="The OpenColorIO config of --ocio-colourspace: a file or an ocio:// URI "
                 "(default: $OCIO, else OpenColorIO's built-in default config)."),
        click.option(
            "--negatives", type=click.Choice(["keep", "exclude"]), default="keep",
            show_default=True,
            help="Pixels with a negative channel: keep them in the linear mean (out-of-gamut "
                 "colours in a scene-linear render) or exclude them like NaN/Inf."),
        click.option(
            "--topic", default=None, metavar="NAME",
            help="The input is a ROS 1 bag, a ROS 2 bag (folder, .db3 or .mcap) or an MCAP "
                 "file: read this sensor_msgs/Image or CompressedImage topic (default: its "
                 "only image topic)."),
        click.option(
            "--frame", type=int, default=None, metavar="N",
            help="With a recording: the N-th message of --topic (0 the first, the default; "
                 "-1 the last); with a video: its N-th frame."),
        click.option(
            "--time", type=RecordingTime(), default=None, metavar="T",
            help="With a recording: the message of --topic nearest to T: seconds after the "
                 "recording's first message (0.5), or an absolute time: @SECONDS since the "
                 "epoch (@1700000000.25) or ISO 8601 with its offset "
                 "(2023-11-14T22:13:20.25Z). With a video: the frame nearest to T "
                 "seconds after its first frame."),
        click.option(
            "--video-matrix", type=click.Choice(["bt601", "bt709", "bt2020"]), default=None,
            help="A video's Y'CbCr matrix, instead of its stream's tag (untagged: bt601 "
                 "below 720 lines, bt709 from 720)."),
        click.option(
            "--video-range", type=click.Choice(["limited", "full"]), default=None,
            help="A video's Y'CbCr range, instead of its stream's tag (untagged: limited)."),
    ]
    for opt in reversed(opts):
        wrapper = opt(wrapper)
    return wrapper  # type: ignore[return-value]


def manifest_options(f: F) -> F:
    """``--manifest FILE`` and ``--max-exposure-error EV`` (audit, gate): the chart scene's
    manifest (:func:`fidelity.scene.manifest.read_manifest`) gives the corners, the expected
    exposure, the reference and the illuminant where the command line leaves them at their
    defaults; a fixed exposure (the manifest's or ``--exposure EV``) is judged against the
    image's (:mod:`fidelity.prediction.exposure`). Below :func:`image_read_options` and
    :func:`judge_options`: the command's ``read`` and ``judge`` arguments are completed."""

    @functools.wraps(f)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        path, limit = kwargs.pop("manifest"), kwargs.pop("max_exposure_error")
        read, judge = kwargs["read"], kwargs["judge"]
        source = "--exposure"
        kwargs["edge_target"] = None
        if path is not None:
            manifest = read_manifest(path)
            kwargs["edge_target"] = manifest.edge_target
            ctx = click.get_current_context()
            if kwargs.get("corners") is None:
                kwargs["corners"] = manifest.corners
            if read.exposure is None:
                read, source = dataclasses.replace(read, exposure=manifest.exposure_ev), "manifest"
            for name in ("reference", "illuminant"):
                if ctx.get_parameter_source(name) is click.core.ParameterSource.DEFAULT:
                    kwargs[name] = getattr(manifest, name)
        kwargs["read"] = read
        kwargs["judge"] = dataclasses.replace(judge, max_exposure_error=limit,
                                              exposure_source=source)
        return f(*args, **kwargs)

    opts = [
        click.option(
            "--manifest", type=click.Path(dir_okay=True, path_type=Path), default=None,
            metavar="FILE",
            help="The chart scene's manifest.json (fidelity scene; or its folder): its "
                 "corners, expected exposure, reference and illuminant, where not given. The "
                 "exposure is then fixed at the expected one and judged "
                 "(--max-exposure-error), not normalised away; the sharpness is measured on "
                 "the scene's slanted-edge target at the manifest's corners."),
        click.option(
            "--max-exposure-error", type=click.FloatRange(min=0, min_open=True),
            default=DEFAULT_MAX_EXPOSURE_ERROR_EV, show_default=True, metavar="EV",
            help="With a fixed exposure (--manifest or --exposure EV): the largest error of "
                 "the image's exposure, judged on the neutral patches, that passes (EV)."),
    ]
    for opt in reversed(opts):
        wrapper = opt(wrapper)
    return wrapper  # type: ignore[return-value]


def max_pixels_option(f: F) -> F:
    """``--max-pixels N``: refuse larger images (audit, gate)."""
    return click.option(
        "--max-pixels", type=click.IntRange(min=1), default=None,
        help="Refuse images of more pixels (width x height), checked before decoding; default "
             "150000000 or $FIDELITY_MAX_PIXELS. An audit needs the decoded image plus about 1 "
             "byte per pixel (4 for an 8-bit photo; 60 for --bayer).")(f)


# --------------------------------------------------------------------------------------------
# Output and the options every command shares


def common_options(f: F) -> F:
    """Add ``-q/--quiet`` and ``-v/--verbose`` to a command. Quiet sends the command's ordinary
    printing to nowhere; ``--json -`` sends it to standard error, so that standard output holds
    the JSON alone (:func:`write_json_output`) and the verdict still reaches the log. Unless
    quiet, the command first says which settings file it read and what it took from it
    (:func:`settings_line`)."""

    @functools.wraps(f)
    def wrapper(*args: Any, quiet: bool, verbose: bool, **kwargs: Any) -> Any:
        state = command_state()
        state["verbose"] = bool(state.get("verbose")) or verbose
        state["stdout"] = sys.stdout
        to_stdout = str(kwargs.get("json_path") or "") == STDOUT
        redirect: contextlib.AbstractContextManager[Any] = contextlib.nullcontext()
        if quiet:
            redirect = contextlib.redirect_stdout(io.StringIO())
        elif to_stdout:
            redirect = contextlib.redirect_stdout(sys.stderr)
        with redirect:
            settings = settings_line()
            if settings:
                click.echo(settings)
            return f(*args, **kwargs)

    wrapper = click.option("-v", "--verbose", is_flag=True,
                           help="Show the traceback of an internal error.")(wrapper)
    wrapper = click.option("-q", "--quiet", is_flag=True,
                           help="Print nothing but errors (and JSON asked for on stdout).")(
        wrapper)
    return wrapper  # type: ignore[return-value]


def progress_option(f: F) -> F:
    """``--progress/--no-progress`` (default: show progress when stderr is a terminal)."""
    return click.option("--progress/--no-progress", default=None,
                        help="Progress bars (default: when stderr is a terminal).")(f)


def json_option(help_text: str) -> Callable[[F], F]:
    """``--json FILE`` (``-``: standard output), stored as ``json_path``."""
    return click.option("--json", "json_path", type=click.Path(dir_okay=False), default=None,
                        help=f"{help_text} ('-': standard output).")


#: The command-line names of the judging options, as :class:`JudgeOptions` names them.
JUDGE_OPTION_NAMES = ("size", "table", "bound")


def judge_options(*, bound: bool = True, decision: bool = True) -> Callable[[F], F]:
    """``--size``, ``--table`` and, unless told otherwise, ``--bound``, ``--decision``,
    ``--coverage-factor`` and ``--strict``: how a measured chart is judged (check, audit,
    gate, compare, fit). The command receives them as one argument ``judge``, a
    :class:`fidelity.prediction.judge.JudgeOptions`."""

    def deco(f: F) -> F:
        @functools.wraps(f)
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            values = {name: kwargs.pop(name) for name in JUDGE_OPTION_NAMES if name in kwargs}
            rule = (decision_rule(kwargs.pop("decision"), kwargs.pop("coverage_factor"),
                                  kwargs.pop("strict")) if decision else SIMPLE)
            return f(*args, judge=JudgeOptions(**values, decision=rule), **kwargs)

        opts = [
            click.option("--size", type=click.Choice(list(SIZES)), default="any",
                         show_default=True, help="Detector size class of the predicted loss."),
            click.option("--table", default=None, help="Prediction table (name or JSON path)."),
        ]
        if bound:
            opts.append(click.option(
                "--bound", type=click.Choice(list(BOUNDS)), default="classic", show_default=True,
                help="Prediction that decides a verdict on the predicted loss (--max-dmap of "
                     "gate and compare): the classic worst case over every transform, or the "
                     "direction-aware one (both are reported)."))
        if decision:
            opts += [
                click.option(
                    "--decision", type=click.Choice(["simple", "guarded"]), default="simple",
                    show_default=True,
                    help="Decision rule: simple (pass when value <= limit) or guarded "
                         "(ILAC-G8: pass when value + U <= limit, fail when value - U > "
                         "limit, undecided in between: exit 4, or a fail with --strict)."),
                click.option(
                    "--coverage-factor", type=click.FloatRange(min=0, min_open=True),
                    default=2.0, show_default=True,
                    help="k of the expanded uncertainty U = k u a guarded decision uses (2: "
                         "about 95 % for a normal distribution)."),
                click.option(
                    "--strict", is_flag=True, default=False,
                    help="With --decision guarded: a value within U of the limit fails (exit "
                         "1) instead of being undecided (exit 4)."),
            ]
        for opt in reversed(opts):
            wrapper = opt(wrapper)
        return wrapper  # type: ignore[return-value]

    return deco


def loss_limit_options(f: F) -> F:
    """``--max-dmap P``, ``--class`` and ``--unit``: a limit on the predicted loss, the same
    options with the same meaning in ``check`` and ``gate``
    (:class:`fidelity.prediction.verdict.Criterion` ``max-dmap``)."""
    opts = [
        click.option("--max-dmap", type=float,
                     help="Pass when the predicted ΔmAP (or class ΔAP) <= P, instead of a "
                          "limit on the mean ΔE00."),
        click.option("--class", "cls", type=click.Choice(list(CLASS_COLUMNS)),
                     help="Class of --max-dmap: all (mAP, default), person, bicycle."),
        click.option("--unit", type=click.Choice(["points", "relative"]), default="points",
                     show_default=True,
                     help="Unit of --max-dmap: percentage points or % of baseline."),
    ]
    for opt in reversed(opts):
        f = opt(f)
    return f


class EvidencePath(ParamTypeBase):
    """An ``--evidence`` file: a path whose suffix names its format (``.json``, ``.srmd``,
    ``.stmd``, ``.xqar``; :data:`fidelity.report.evidence.EVIDENCE_FORMATS`)."""

    name = "FILE"

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> Path:
        path = Path(os.fsdecode(PATH.convert(value, param, ctx)))
        evidence_format(path)
        return path


def cat_option(f: F) -> F:
    """``--cat``: the chromatic adaptation of the scene reference to D65 (the choices of
    :data:`fidelity.colour.colorimetry.CHROMATIC_ADAPTATION_METHODS`, as ``render --cat``);
    the spread over the transforms is a type-B component of the ΔE's uncertainty under an
    illuminant other than D65 (:func:`fidelity.measure.uncertainty.adaptation_component`)."""
    return click.option(
        "--cat", type=click.Choice(CHROMATIC_ADAPTATION_METHODS), default="Bradford",
        show_default=True,
        help="Chromatic adaptation of the scene reference to D65. Under an illuminant other "
             "than D65 the spread of the mean ΔE00 over Bradford, CAT02, CAT16 and von Kries "
             "enters its uncertainty as a type-B component (half the range / √3).")(f)


def suite_cat_option(more: str = "") -> Callable[[F], F]:
    """``--cat`` of the commands that read a suite file (``suite``, ``validate``): the
    chromatic adaptation of the scene reference to D65 for the cases the suite file gives no
    ``[cat]`` of their own (None: its ``default_cat``, else Bradford; any case), the same idea
    as :func:`cat_option`'s; ``more``: what the command adds to its help."""
    return click.option(
        "--cat", type=click.Choice(CHROMATIC_ADAPTATION_METHODS, case_sensitive=False),
        default=None,
        help="Chromatic adaptation of the scene reference to D65 for the cases the suite "
             "file gives none of their own ([cat]); default: its default_cat, else "
             "Bradford." + (f" {more}" if more else ""))


def evidence_option(f: F) -> F:
    """``--evidence FILE`` (repeatable): the credibility record of the run in the format of
    each file's suffix (:mod:`fidelity.report.evidence`, :mod:`fidelity.report.ssp`)."""
    return click.option(
        "--evidence", "evidence_paths", type=EvidencePath(), multiple=True,
        help="Write the run's credibility record here, in the format of the file's suffix; "
             "give it once per format. .json: code, environment, inputs with SHA-256, "
             "reference and table provenance, measurement with its uncertainty budget, "
             "prediction with its interval, validity domain, decision rule, verdict. .srmd: "
             "SSP Traceability resource meta data (every input and result with its SHA3-256, "
             "the verdicts and values). .stmd: SSP Traceability task meta data (the "
             "evaluation phase). .xqar: ASAM Quality Checker result (a checker per subject, "
             "failed verdicts as issues).")(f)


def context_option(f: F) -> F:
    """The ``--context FILE`` option (the context of use) of ``check`` and ``suite``."""
    return click.option(
        "--context", "context_path", type=click.Path(dir_okay=False, path_type=Path),
        default=None,
        help="Context of use (TOML): detectors, conditions, acceptance criteria, model risk; "
             "scores the credibility of the evidence for it (docs/context.md).")(f)


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
        click.option("--models", default=None, metavar="PATH[@N],...",
                     help="With --measure: ONNX detector(s), PATH[@N] comma-separated "
                          "(default: the shared yolox_nano.onnx)."),
        limit_option("With --measure: "),
    ]
    for opt in reversed(opts):
        f = opt(f)
    return f


__all__ = [
    "context_option",
    "IMAGE_PATH",
    "LIMIT_HELP",
    "PATH",
    "READ_OPTION_NAMES",
    "Resolution",
    "CorruptionNames",
    "ModelList",
    "NameList",
    "Severities",
    "Targets",
    "TransformNames",
    "JUDGE_OPTION_NAMES",
    "judge_options",
    "cat_option",
    "common_options",
    "executor_options",
    "image_read_options",
    "json_option",
    "limit_option",
    "max_pixels_option",
    "measure_options",
    "progress_option",
    "scorer_option",
    "suite_cat_option",
]
