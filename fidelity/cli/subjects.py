"""The subjects of ``audit`` and ``gate``: folders of frames expanded, a recording's frames
selected, where each subject's reports go, and writing them and the
frames' summary. One plan for both commands: read, locate, measure, judge, write."""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from statistics import median

import click

from fidelity.chart.image import folder_images, image_suffixes
from fidelity.chart.read import ReadOptions
from fidelity.chart.recording import FrameSelection, topic_frames
from fidelity.chart.video import frame_count, is_video_path
from fidelity.cli.context import STDOUT
from fidelity.colour.charts import load_reference
from fidelity.core.errors import FidelityError, InputFileError
from fidelity.core.fileio import display_path, write_json_atomic
from fidelity.core.record import record
from fidelity.pipeline.frames import FramesNoise, frames_noise
from fidelity.pipeline.records import GateResult
from fidelity.report.chart import write_chart_report
from fidelity.report.gate import OVERVIEW_NAME, write_gate_overview


def expand_folders(paths: Sequence[Path]) -> tuple[Path, ...]:
    """Each IMAGE as given, a folder of images (one without a ROS 2 bag's ``metadata.yaml``)
    replaced by the images in it, in natural order (:func:`fidelity.chart.image.folder_images`;
    ``audit`` and ``gate``); a folder with none is an input error."""
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
    """Each recording once per frame ``frames`` selects on its topic (from its index), or of
    its frames for a video (from its header, :func:`fidelity.chart.video.frame_count`), and
    those frames (``gate --frames``, ``audit --frames``)."""

    paths: list[Path] = []
    frame_of: list[int] = []
    for img in images:
        chosen: str | None
        if is_video_path(img):
            chosen, count = None, frame_count(img)
        else:
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


def recordings_noise(cases: Sequence[GateResult], images: Sequence[Path],
                     frame_of: Sequence[int], read: ReadOptions, reference: str,
                     illuminant: str) -> list[FramesNoise]:
    """Per recording of several frames, their temporal and fixed-pattern noise
    (:func:`fidelity.pipeline.frames.frames_noise`; ``audit --frames``, ``gate --frames``);
    recordings with fewer than 2 measured frames are left out."""
    by: dict[Path, list[tuple[int, GateResult]]] = {}
    for case, path, k in zip(cases, images, frame_of, strict=True):
        by.setdefault(path, []).append((k, case))
    out = []
    ref = None
    for path, items in by.items():
        if sum(c.report is not None for _, c in items) < 2:
            continue
        if ref is None:
            ref = load_reference(reference, illuminant)
        out.append(frames_noise(path, [k for k, _ in items], [c.report for _, c in items],
                                read, ref))
    return out


def write_frames_noise(noise: Sequence[FramesNoise], json_path: str | os.PathLike[str] | None
                       ) -> list[Path]:
    """Write each recording's :class:`fidelity.pipeline.frames.FramesNoise` as
    ``RECORDING-NAME.frames.json`` (``{"frames_noise": ...}``) in the ``--json`` folder of
    several frames' reports; none without ``--json`` or with ``--json -``."""
    if json_path is None or str(json_path) == STDOUT or not noise:
        return []
    folder = Path(json_path)
    return [write_json_atomic(folder / f"{Path(n.recording).name}.frames.json",
                              {"frames_noise": n.to_json()}) for n in noise]


def write_subject_reports(result: GateResult, json_path: Path | None, html_path: Path | None,
                          inputs: Sequence[Path]) -> tuple[GateResult, list[Path]]:
    """Write a gated or audited subject's JSON and HTML reports (never over an ``inputs``
    file); a failure to write them becomes the subject's error, as an input error does.
    Returns the result and the files written."""

    if result.report is None:
        return result, []
    try:
        written = write_chart_report(result.report, json_path=json_path, html_path=html_path,
                                     protect=list(inputs))
    except (FidelityError, OSError) as exc:
        return replace(result, report=None, error=str(exc)), []
    return result, written


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


@record
class SubjectPlan:
    """The subjects of an ``audit`` or ``gate`` run and where their reports go: one plan for
    both commands (read, locate, measure, judge, write).

    Attributes
    ----------
    images
        One image per subject: each IMAGE as given, a folder replaced by its images, a
        recording once per frame of ``frames``.
    frames
        The frame of each subject (``--frames``); None: the images as they are.
    json_paths, html_paths
        Where each subject's JSON and HTML report goes (None: not written).
    overview
        The overview page of several subjects' HTML reports (``index.html`` in the
        ``--html`` folder); None for one subject or without ``--html``.
    to_stdout
        The one subject's JSON report goes to standard output (``--json -``).
    """

    images: tuple[Path, ...]
    frames: list[int] | None
    json_paths: list[Path | None]
    html_paths: list[Path | None]
    overview: Path | None
    to_stdout: bool

    @property
    def many(self) -> bool:
        """Whether there are several subjects (their reports then go into folders)."""
        return len(self.images) > 1

    @property
    def names(self) -> list[str]:
        """Each subject as printed: the image, or ``RECORDING frame K``."""
        if self.frames is None:
            return [display_path(img) for img in self.images]
        return [f"{display_path(img)} frame {k}"
                for img, k in zip(self.images, self.frames, strict=True)]

    @property
    def recordings(self) -> list[str] | None:
        """Each subject's recording as printed (None without ``--frames``)."""
        return None if self.frames is None else [display_path(img) for img in self.images]

    def outputs(self) -> dict[str, Path | None]:
        """The reports' files as :func:`fidelity.core.fileio.check_outputs` labels them."""
        out: dict[str, Path | None] = {}
        for name, jp, hp in zip(self.names, self.json_paths, self.html_paths, strict=True):
            out[f"--json ({name})" if self.many else "--json"] = jp
            out[f"--html ({name})" if self.many else "--html"] = hp
        out["--html (overview)"] = self.overview
        return out

    def inputs(self) -> dict[str, Path]:
        """The images as :func:`fidelity.core.fileio.check_outputs` labels its inputs."""
        return {(f"IMAGE {img}" if self.many else "IMAGE"): img for img in self.images}

    def write_reports(self, cases: Sequence[GateResult]
                      ) -> list[tuple[GateResult, list[Path]]]:
        """Write each subject's JSON and HTML report (:func:`write_subject_reports`); each
        result (a report that could not be written is its error) with the files written."""
        return [write_subject_reports(case, jp, hp, self.images)
                for case, jp, hp in zip(cases, self.json_paths, self.html_paths, strict=True)]

    def write_overview(self, cases: Sequence[GateResult], *, audit: bool,
                       noise: Sequence[FramesNoise] = ()) -> Path | None:
        """Write the overview page of the subjects' HTML reports, if there is one (``noise``:
        the frames' temporal and fixed-pattern noise, :func:`recordings_noise`)."""
        if self.overview is None:
            return None
        return write_gate_overview(
            self.overview, cases, [hp if c.report is not None else None
                                   for c, hp in zip(cases, self.html_paths, strict=True)],
            self.frames, self.recordings, audit=audit, noise=noise)


def output_folder(value: str | os.PathLike[str] | None) -> bool:
    """Whether an output option names a folder by its trailing separator (``out/``)."""
    return value is not None and str(value).endswith(("/", os.sep))


def plan_subjects(images: Sequence[Path], frames: FrameSelection | None, topic: str | None,
                  json_path: str | os.PathLike[str] | None,
                  html_path: str | os.PathLike[str] | None) -> SubjectPlan:
    """The :class:`SubjectPlan` of ``audit`` and ``gate``: folders expanded
    (:func:`expand_folders`), each recording once per frame ``frames`` selects on ``topic``
    (:func:`frame_subjects`), and each subject's report paths: ``--json`` / ``--html``
    themselves for one subject, IMAGE-NAME.json / .html in them for several (or for a folder
    that exists or is written with a trailing separator), the overview page beside several
    HTML reports. ``--json -`` (standard output) takes one subject."""
    paths = expand_folders(images)
    frame_of: list[int] | None = None
    reports_of = paths  # what each subject's report is named after
    if frames is not None:
        paths, frame_of = frame_subjects(paths, frames, topic)
        reports_of = frame_report_names(paths, frame_of)
    many = len(paths) > 1
    to_stdout = json_path is not None and str(json_path) == STDOUT
    if to_stdout and many:
        raise click.UsageError("--json - (standard output) takes one IMAGE; give a folder")
    json_paths = report_paths(reports_of, None if to_stdout or json_path is None
                              else Path(json_path), ".json",
                              folder=many or output_folder(json_path))
    html_paths = report_paths(reports_of, None if html_path is None else Path(html_path),
                              ".html", folder=many or output_folder(html_path))
    overview = Path(html_path) / OVERVIEW_NAME if many and html_path is not None else None
    return SubjectPlan(paths, frame_of, json_paths, html_paths, overview, to_stdout)

__all__ = [
    "SubjectPlan",
    "output_folder",
    "plan_subjects",
    "expand_folders",
    "frame_report_names",
    "frame_subjects",
    "frames_summary",
    "recordings_noise",
    "write_frames_noise",
    "report_paths",
    "write_subject_reports",
]
