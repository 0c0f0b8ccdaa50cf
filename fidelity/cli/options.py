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
  ``--topic``, ``--frame``, ``--time``: how an image is read (:func:`image_read_options`, one
  ``read`` argument);
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
import functools
import io
import json
import os
import re
import sys
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import click

from fidelity.core.errors import FidelityError, InvalidValueError

if TYPE_CHECKING:
    from typing import TypeAlias

    from fidelity.chart.recording import FrameSelection
    from fidelity.coco.executor import ExecutorOptions
    from fidelity.coco.measure import CocoInputs
    from fidelity.coco.scores import ScoresTransfer
    from fidelity.coco.store import ResultsStore
    from fidelity.coco.sweep import ModelSpec
    from fidelity.pipeline.records import GateResult
    from fidelity.prediction.verdict import Criterion

    # click >= 8.2 types ParamType by its value; the project supports click 8.1 too
    ParamTypeBase: TypeAlias = click.ParamType[Any]
else:
    ParamTypeBase = click.ParamType

F = TypeVar("F", bound=Callable[..., Any])

#: The ``--json`` value that means standard output.
STDOUT = "-"

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
        import math

        from fidelity.prediction.calibration import MAX_TARGETS

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
        from fidelity.chart.recording import absolute_time_ns

        absolute_time_ns(text)  # a bad time is the one-line error here, before any reading
        return text


class FrameRange(ParamTypeBase):
    """``--frames``: frame numbers ``N,M,...`` or a range ``START:STOP[:STEP]`` of a
    recording's topic -> a :class:`fidelity.chart.recording.FrameSelection`."""

    name = "FRAMES"

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> Any:
        from fidelity.chart.recording import FrameSelection, parse_frames

        if isinstance(value, FrameSelection):
            return value
        return parse_frames(str(value))


def expand_folders(paths: Sequence[Path]) -> tuple[Path, ...]:
    """Each IMAGE as given, a folder of images (one without a ROS 2 bag's ``metadata.yaml``)
    replaced by the images in it, in natural order (:func:`fidelity.chart.image.folder_images`;
    ``audit`` and ``gate``); a folder with none is an input error."""
    from fidelity.chart.image import folder_images, image_suffixes
    from fidelity.core.errors import InputFileError
    from fidelity.core.fileio import display_path

    out: list[Path] = []
    for p in paths:
        if not p.is_dir() or (p / "metadata.yaml").is_file():
            out.append(p)
            continue
        try:
            found = folder_images(p)
        except OSError as exc:
            raise InputFileError(f"{display_path(p)}: cannot list the folder "
                                 f"({exc.strerror or exc})") from None
        if not found:
            common = [x for x in (".exr", ".png", ".jpg", ".tif", ".hdr") if x in
                      image_suffixes()]
            raise InputFileError(f"{display_path(p)}: a folder with no image in it "
                                 f"({', '.join(common)}, ...) and no metadata.yaml of a ROS 2 "
                                 "bag")
        out.extend(found)
    return tuple(out)


def frame_subjects(images: Sequence[Path], frames: FrameSelection, topic: str | None
                    ) -> tuple[tuple[Path, ...], list[int]]:
    """Each recording once per frame ``frames`` selects on its topic (from its index), and
    those frames (``gate --frames``, ``audit --frames``)."""
    from fidelity.chart.recording import topic_frames
    from fidelity.core.fileio import display_path

    paths: list[Path] = []
    frame_of: list[int] = []
    for img in images:
        chosen, count = topic_frames(img, topic)
        for k in frames.resolve(count, display_path(img), chosen):
            paths.append(img)
            frame_of.append(k)
    return tuple(paths), frame_of


def frame_report_names(images: Sequence[Path], frame_of: Sequence[int]) -> tuple[Path, ...]:
    """What each frame's report is named after: ``RECORDING.frameK`` (its reports are
    ``RECORDING.frameK.json`` / ``.html`` in the --json / --html folder)."""
    return tuple(Path(f"{img}.frame{k}") for img, k in zip(images, frame_of, strict=True))


def frames_summary(cases: Sequence[GateResult], images: Sequence[Path],
                    frame_of: Sequence[int]) -> list[str]:
    """How the chart ΔE varies over the frames gated or audited (the measured ones), per
    recording."""
    from statistics import median

    from fidelity.core.fileio import display_path

    by: dict[Path, list[tuple[float, int]]] = {}
    for case, path, k in zip(cases, images, frame_of, strict=True):
        if case.report is not None:
            by.setdefault(path, []).append((case.report.mean_delta_e, k))
    lines = []
    for path, values in by.items():
        lo, hi = min(values), max(values)
        many = "s" if len(values) > 1 else ""
        lines.append(f"{display_path(path)}: mean ΔE00 over {len(values)} measured frame{many}: "
                     f"min {lo[0]:.2f} (frame {lo[1]}), median "
                     f"{median(v for v, _ in values):.2f}, max {hi[0]:.2f} (frame {hi[1]})")
    return lines


def write_subject_reports(result: GateResult, json_path: Path | None, html_path: Path | None,
                          inputs: Sequence[Path]) -> tuple[GateResult, list[Path]]:
    """Write a gated or audited subject's JSON and HTML reports (never over an ``inputs``
    file); a failure to write them becomes the subject's error, as an input error does.
    Returns the result and the files written."""
    from fidelity.report.chart import write_chart_report

    if result.report is None:
        return result, []
    try:
        written = write_chart_report(result.report, json_path=json_path, html_path=html_path,
                                     protect=list(inputs))
    except (FidelityError, OSError) as exc:
        return replace(result, report=None, error=str(exc)), []
    return result, written


class NameList(ParamTypeBase):
    """``all`` or comma-separated names from a known set -> a list of names."""

    name = "names"
    #: What one name is, in errors ("transform").
    what = "name"

    def known(self) -> Sequence[str]:
        """The names accepted, in their canonical order (``all``: every one)."""
        raise NotImplementedError

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> list[str]:
        if not isinstance(value, str):
            return list(value)
        from fidelity.core.errors import unknown_name

        known = self.known()
        items = [t.strip() for t in value.split(",") if t.strip()]
        if items == ["all"]:
            return list(known)
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
        from fidelity.prediction.transforms import TRANSFORMS

        return list(TRANSFORMS)


class CorruptionNames(NameList):
    """``--corruptions``: COCO-C colour corruptions
    (:data:`fidelity.coco.corruptions.CORRUPTIONS`)."""

    name = "corruptions"
    what = "corruption"

    def known(self) -> Sequence[str]:
        from fidelity.coco.corruptions import CORRUPTIONS

        return CORRUPTIONS


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


def parse_models(text: str, what: str = "--models") -> tuple[ModelSpec, ...]:
    """``A.onnx,B.onnx@250`` -> :class:`fidelity.coco.sweep.ModelSpec` each (at least one)."""
    from fidelity.coco.sweep import ModelSpec

    specs = tuple(ModelSpec.parse(m.strip()) for m in text.split(",") if m.strip())
    if not specs:
        raise InvalidValueError(f"{what} {text!r}: names no ONNX file")
    return specs


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


def cap_models(models: Sequence[ModelSpec], limit: int | None) -> tuple[ModelSpec, ...]:
    """Each model with ``--limit`` applied: its own ``@N`` or ``limit``, the smaller."""
    if limit is None:
        return tuple(models)
    return tuple(replace(s, limit=min(s.limit or limit, limit)) for s in models)


def model_inputs(models: Sequence[ModelSpec] | None) -> dict[str, Path]:
    """What ``--models`` reads, for :func:`fidelity.core.fileio.check_outputs`: each model file."""
    return {f"--models ({s.path})": s.path for s in models or ()}


def coco_inputs(images: str | None, annotations: str | None,
                models: Sequence[ModelSpec] | None, *, what: str = "--measure") -> CocoInputs:
    """:func:`fidelity.coco.measure.resolve_coco_inputs` of the options' values (those not
    given from the shared data folder)."""
    from fidelity.coco.measure import resolve_coco_inputs

    items = None if models is None else [f"{s.path}@{s.limit}" if s.limit else str(s.path)
                                         for s in models]
    return resolve_coco_inputs(images, annotations, items, what=what)


# --------------------------------------------------------------------------------------------
# Where and how the COCO commands run their detectors and score them


def scorer_option(f: F) -> F:
    """``--scorer``: the COCO AP implementation (evaluate, sweep)."""
    from fidelity.coco.scoring import COCO_SCORERS

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


def transfer_scores(store_type: type[ResultsStore], folder: str, option: str,
                    export_to: str | None, import_from: str | None, annotations: str | None,
                    scorer: str = "auto") -> bool:
    """Do ``--export-scores`` / ``--import-scores`` (:func:`scores_options`) on the store of
    kind ``store_type`` in ``folder`` (named by ``option`` in errors); whether either was
    given (the command then has nothing else to do)."""
    from fidelity.coco import scores
    from fidelity.core.fileio import check_outputs, file_sha256, require_file

    if export_to and import_from:
        raise click.UsageError("--export-scores and --import-scores: one at a time")
    if import_from:
        require_file(import_from, "--import-scores")
        doc = scores.read_scores(import_from, store_type)  # before a store is made
        store = store_type(folder)
        sha = file_sha256(import_from)
        if any(s.get("sha256") == sha for s in store.meta().get("imported") or []):
            click.echo(f"{import_from} is already imported into {store.path}; nothing to do")
            return True
        t = scores.import_scores(store, import_from, doc)
        if not t.cells:
            click.echo(f"{store.path} holds every cell of {import_from}; nothing to do")
            return True
        click.echo(f"{_moved(t)} imported into {store.path}; rerun the command line with "
                   f"{option} {folder} to resume")
        return True
    if export_to:
        if not annotations:
            raise click.UsageError("--export-scores needs --annotations (the fold and bootstrap "
                                   "scores are computed against them)")
        from fidelity.coco.scoring import load_annotations

        store = store_type(folder, create=False)
        check_outputs({"--export-scores": export_to},
                      {"--annotations": annotations, f"{option} ({store.store_name})": store.path,
                       option: Path(folder)})
        t = scores.export_scores(store, load_annotations(annotations), export_to, method=scorer)
        click.echo(f"{_moved(t)} exported to {t.path} (sha256 {t.sha256[:12]})")
        return True
    return False


def _moved(t: ScoresTransfer) -> str:
    per = ", ".join(f"{m} {n}" for m, n in sorted(t.models.items()))
    unreachable = f", {t.unreachable} of them unreachable" if t.unreachable else ""
    return f"{t.cells} cells of a {t.kind} store ({per}{unreachable})"


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


def executor_from(executor: str, address: str | None, workers: int | None,
                  threads: int | None, provider: str) -> ExecutorOptions:
    """The :class:`fidelity.coco.executor.ExecutorOptions` of the command-line values."""
    from fidelity.coco.executor import ExecutorOptions

    return ExecutorOptions(executor, address, workers, threads, provider)


# --------------------------------------------------------------------------------------------
# How an image is read, and what is judged (audit, gate, compare)


#: An image argument: a file, or a recording (a ROS 2 bag is a folder).
IMAGE_PATH = click.Path(path_type=Path)

#: The command-line names of the image-reading options, as :class:`ReadOptions` names them.
READ_OPTION_NAMES = ("layer", "encoding", "exposure", "negatives", "colourspace", "bayer",
                     "topic", "frame", "time", "ocio_colourspace", "ocio_config")


def chart_pair_options(f: F) -> F:
    """``--sim-corners``, ``--real-corners``, ``--sim-ocio-colourspace``,
    ``--real-ocio-colourspace`` and ``--normalise``: where the two charts of a simulated and a
    real image are, each image's own OpenColorIO colourspace, and how the simulated one is
    matched to the real one (compare, fit)."""
    opts = [
        click.option("--sim-corners", default=None,
                     help="X1,Y1,...,X4,Y4: centres of the dark skin, bluish green, black and "
                          "white patches in SIM (default: the chart is found)."),
        click.option("--real-corners", default=None, help="The same for REAL."),
        click.option("--sim-ocio-colourspace", default=None, metavar="NAME",
                     help="SIM's own OpenColorIO colourspace (as --ocio-colourspace, for SIM "
                          "alone; the shared --encoding and --colourspace then describe "
                          "REAL)."),
        click.option("--real-ocio-colourspace", default=None, metavar="NAME",
                     help="The same for REAL."),
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
        from fidelity.chart.read import ReadOptions

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
                 "-1 the last)."),
        click.option(
            "--time", type=RecordingTime(), default=None, metavar="T",
            help="With a recording: the message of --topic nearest to T: seconds after the "
                 "recording's first message (0.5), or an absolute time: @SECONDS since the "
                 "epoch (@1700000000.25) or ISO 8601 with its offset "
                 "(2023-11-14T22:13:20.25Z)."),
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


def make_criterion(max_delta_e: float | None, max_dmap: float | None, cls: str | None,
                   unit: str) -> Criterion:
    """The criterion of ``--max-delta-e`` / ``--max-dmap`` (exactly one), ``--class`` and
    ``--unit`` (gate, compare)."""
    from fidelity.prediction.verdict import Criterion

    if (max_delta_e is None) == (max_dmap is None):
        raise click.UsageError("give exactly one of --max-delta-e X or --max-dmap P")
    if max_delta_e is not None:
        if cls is not None:
            raise click.UsageError("--class goes with --max-dmap, not --max-delta-e")
        return Criterion("max-delta-e", float(max_delta_e))
    return Criterion("max-dmap", float(max_dmap), cls or "all", unit)  # type: ignore[arg-type]


def report_paths(images: tuple[Path, ...], path: Path | None, suffix: str, *,
                 folder: bool = False) -> list[Path | None]:
    """Where each image's report goes: ``path`` itself, or, when ``path`` is a folder
    (``folder``, or an existing directory), the image's file name + ``suffix`` in it."""
    if path is None:
        return [None] * len(images)
    if not (folder or path.is_dir()):
        return [path] * len(images)
    names = [img.name for img in images]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise FidelityError(f"several images are named {', '.join(twice)}: their reports in "
                            f"{path} would collide; gate them in separate runs")
    return [path / f"{n}{suffix}" for n in names]


# --------------------------------------------------------------------------------------------
# Output and the options every command shares


def _state() -> dict[str, Any]:
    ctx = click.get_current_context()
    root = ctx.find_root()
    obj: dict[str, Any] = root.ensure_object(dict)
    return obj


def common_options(f: F) -> F:
    """Add ``-q/--quiet`` and ``-v/--verbose`` to a command. Quiet sends the command's ordinary
    printing to nowhere; ``--json -`` sends it to standard error, so that standard output holds
    the JSON alone (:func:`write_json_output`) and the verdict still reaches the log. Unless
    quiet, the command first says which settings file it read and what it took from it
    (:func:`settings_line`)."""

    @functools.wraps(f)
    def wrapper(*args: Any, quiet: bool, verbose: bool, **kwargs: Any) -> Any:
        state = _state()
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


def settings_line() -> str | None:
    """What the running command took from a settings file: ``fidelity: settings FILE: key,
    ...`` (the options whose value came from it, by their flags), or that none of its keys
    applies; None when no settings file was read (none found, or ``--no-config``)."""
    from click.core import ParameterSource

    config = _state().get("config")
    if config is None:
        return None
    ctx = click.get_current_context()
    used = [max(p.opts, key=len) for p in ctx.command.params
            if p.name and ctx.get_parameter_source(p.name) == ParameterSource.DEFAULT_MAP]
    what = ", ".join(used) if used else "no setting applies to this command"
    return f"fidelity: settings {config.path}: {what}"


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
        help="Prediction that decides a verdict on the predicted loss (--max-dmap of gate and "
             "compare): the classic worst case over every transform, or the direction-aware one "
             "(both are reported).")(f)


def decision_options(f: F) -> F:
    """``--decision simple|guarded``, ``--coverage-factor K`` and ``--strict``: how a verdict
    compares a value that has an uncertainty with its limit
    (:class:`fidelity.prediction.verdict.DecisionRule`; :func:`decision_rule`)."""
    f = click.option(
        "--strict", is_flag=True, default=False,
        help="With --decision guarded: a value within U of the limit fails (exit 1) instead "
             "of being undecided (exit 4).")(f)
    f = click.option(
        "--coverage-factor", type=click.FloatRange(min=0, min_open=True), default=2.0,
        show_default=True,
        help="k of the expanded uncertainty U = k u a guarded decision uses (2: about 95 % "
             "for a normal distribution).")(f)
    return click.option(
        "--decision", type=click.Choice(["simple", "guarded"]), default="simple",
        show_default=True,
        help="Decision rule: simple (pass when value <= limit) or guarded (ILAC-G8: pass when "
             "value + U <= limit, fail when value - U > limit, undecided in between: exit 4, "
             "or a fail with --strict).")(f)


def decision_rule(decision: str, coverage_factor: float, strict: bool) -> Any:
    """The :class:`~fidelity.prediction.verdict.DecisionRule` of the options of
    :func:`decision_options`."""
    from fidelity.prediction.verdict import DecisionRule

    if strict and decision != "guarded":
        raise click.UsageError("--strict goes with --decision guarded")
    return DecisionRule(decision, float(coverage_factor), bool(strict))


class EvidencePath(ParamTypeBase):
    """An ``--evidence`` file: a path whose suffix names its format (``.json``, ``.srmd``,
    ``.stmd``, ``.xqar``; :data:`fidelity.report.evidence.EVIDENCE_FORMATS`)."""

    name = "FILE"

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> Path:
        from fidelity.report.evidence import evidence_format

        path = Path(os.fsdecode(PATH.convert(value, param, ctx)))
        evidence_format(path)
        return path


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
    from fidelity.core.fileio import display_path

    if not paths:
        return
    wrote = [p for p in results if p is not None and p.is_file()]
    for path in write(paths, *args, results=wrote, invocation=invocation()):
        click.echo(f"{indent}wrote {display_path(path)}")


def invocation() -> dict[str, Any] | None:
    """The running command line as a credibility record's ``invocation``
    (:func:`fidelity.report.evidence.invocation_record`): the arguments the group was given,
    the current folder and the settings file read; None outside a ``fidelity`` command."""
    from fidelity.report.evidence import invocation_record

    ctx = click.get_current_context(silent=True)
    obj = ctx.find_root().obj if ctx is not None else None
    if not isinstance(obj, dict) or "argv" not in obj:
        return None
    config = obj.get("config")
    return invocation_record(obj["argv"], config.path if config is not None else None)


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


def measure_inputs(images: str | None, annotations: str | None, models: str | None
                   ) -> dict[str, Any]:
    """What ``--measure`` reads, for :func:`fidelity.core.fileio.check_outputs`: the image folder,
    the annotations and each model file (``models`` read as :class:`ModelList` reads it)."""
    specs = None if models is None else parse_models(models)
    return {"--images": images, "--annotations": annotations} | model_inputs(specs)


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
    from fidelity.core.fileio import json_ready, write_json_atomic

    if str(path) == STDOUT:
        out = real_stdout()
        out.write(json.dumps(json_ready(obj), indent=2, allow_nan=False) + "\n")
        out.flush()
        return "standard output"
    return str(write_json_atomic(path, obj))


__all__ = [
    "IMAGE_PATH",
    "LIMIT_HELP",
    "PATH",
    "READ_OPTION_NAMES",
    "Resolution",
    "STDOUT",
    "CorruptionNames",
    "ModelList",
    "NameList",
    "Severities",
    "Targets",
    "TransformNames",
    "bound_option",
    "cap_models",
    "coco_inputs",
    "common_options",
    "executor_from",
    "executor_options",
    "from_settings",
    "settings_line",
    "image_read_options",
    "json_option",
    "limit_option",
    "make_criterion",
    "max_pixels_option",
    "measure_inputs",
    "measure_options",
    "measure_request",
    "model_inputs",
    "parse_models",
    "progress_option",
    "real_stdout",
    "report_paths",
    "scorer_option",
    "show_progress",
    "write_json_output",
]
