"""Validate the prediction on realistic camera models: predicted against measured ΔmAP.

For every camera file of a suite (:func:`load_suite`):

1. **Predict.** Render the chart (:func:`fidelity.camera.render.render_chart`, closed form) under the
   test case's illuminant, take the chart ΔE (mean CIEDE2000 over the 24 patches) and predict
   the detection loss with every prediction table (:func:`fidelity.prediction.table.predict`,
   detector size ``n``; the baseline mAP of the detector resolves the paper's points-vs-relative
   ambiguity conservatively).
2. **Measure.** Fit the camera's colour rendering (:func:`fidelity.coco.emulation.fit_emulation`),
   apply it to every COCO image, and run the detectors on the result after the same JPEG round
   trip as the COCO sweep (original quantisation tables and subsampling,
   :func:`fidelity.coco.jpeg.roundtrip_jpeg`); ΔmAP is measured against the ΔE = 0 baseline (the
   same round trip with no colour change), in percentage points and relative to the baseline,
   and per class (person, bicycle).
3. **Compare.** The worst-case table bounds a camera when the measured loss is at most the
   prediction. A standard error of every measured loss comes from 5 interleaved folds of the
   image set (image ``i`` of the id-sorted list in fold ``i mod 5``): SE = std(fold ΔmAP)/sqrt(5),
   the relative one over each fold's ΔmAP as a share of that fold's baseline
   (:func:`fidelity.coco.loss.loss_estimate`, as the sweep tables).

Suite folder: camera files (``*.toml``, ``*.yaml``, ``*.yml``) and an optional ``suite.toml``
giving each camera's scene illuminant (``default_illuminant = "D65"``; ``[illuminant]`` table
``stem = "A"``); a camera file describes the camera, the light is part of the test case.

Store (``<store>/validation.sqlite``, WAL, ``synchronous=FULL``): raw detections per image,
committed every few images, finished cells, per-camera chart/prediction/emulation records and
provenance. A rerun resumes; a camera whose file, illuminant or emulation method changed is an
error (use a new store). The default store is outside the repository:
``$FIDELITY_CACHE/validation`` or ``~/.cache/fidelity/validation``.
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time
import tomllib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fidelity.coco.bounds import CameraChart, DirectionalValidation, MeasuredCell, compare_bounds
from fidelity.coco.loss import LOSS_COLUMNS, Losses
from fidelity.coco.scoring import FOLDS  # interleaved image folds for standard errors
from fidelity.coco.store import (
    RegisteredModel,
    ResultsStore,
    pack_detections,
    unpack_detections,
)
from fidelity.core.errors import InputFileError, InvalidValueError
from fidelity.core.fileio import file_sha256, json_ready, portable_paths
from fidelity.core.version import __version__

if TYPE_CHECKING:
    from fidelity.coco.bootstrap import Draws
    from fidelity.coco.dataset import PixelMap
    from fidelity.coco.emulation import AccuracySummary, Emulation
    from fidelity.coco.executor import CellWork, ExecutorOptions
    from fidelity.coco.scoring import CocoScore, FoldScore
    from fidelity.coco.store import ThreadStores
    from fidelity.coco.sweep import ImageCache, ModelSpec
    from fidelity.measure.colour import ChartMeasurement
    from fidelity.prediction.interval import ValidatedCameras

STORE_NAME = "validation.sqlite"
SUITE_FILE = "suite.toml"
BASELINE = "baseline"
#: Classes compared (``all`` = mAP@[.50:.95] over the 80 COCO classes).
CLASSES: tuple[str, ...] = ("all", "person", "bicycle")
#: Images and pixel stride used for the image-level ΔE00 of an emulation (analysis only).
IMAGE_DE_SAMPLE: tuple[int, int] = (50, 4)


def default_store() -> Path:
    """``$FIDELITY_CACHE/validation`` or ``~/.cache/fidelity/validation``."""
    base = os.environ.get("FIDELITY_CACHE")
    return (Path(base) if base else Path.home() / ".cache" / "fidelity") / "validation"


# --------------------------------------------------------------------------------------------
# Suite
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CameraCase:
    """One test case: a camera file and the illuminant of the scene it shoots."""

    name: str
    path: Path
    illuminant: str
    sha256: str


def load_suite(folder: str | os.PathLike[str]) -> list[CameraCase]:
    """Camera files of ``folder`` with their illuminants (module docstring), sorted by name.

    Raises :class:`InputFileError` for a missing folder, no camera files, an invalid camera
    file, a malformed ``suite.toml`` or one naming a camera that is not there.
    """
    from fidelity.camera.model import read_camera_file
    from fidelity.colour.spectral import load_illuminant

    d = Path(folder)
    if not d.is_dir():
        raise InputFileError(f"{d}: camera folder does not exist")
    files = sorted(p for p in d.iterdir() if p.suffix.lower() in (".toml", ".yaml", ".yml")
                   and p.name != SUITE_FILE)
    if not files:
        raise InputFileError(f"{d}: no camera files (*.toml, *.yaml) in the folder")
    default, per = "D65", {}
    suite = d / SUITE_FILE
    if suite.is_file():
        try:
            data = tomllib.loads(suite.read_text(encoding="utf-8"))
        except (OSError, tomllib.TOMLDecodeError) as exc:
            raise InputFileError(f"{suite}: invalid TOML ({exc})") from exc
        unknown = set(data) - {"default_illuminant", "illuminant"}
        if unknown:
            raise InputFileError(f"{suite}: unknown field {sorted(unknown)[0]!r}; known: "
                                 "default_illuminant, illuminant")
        default = data.get("default_illuminant", "D65")
        per = data.get("illuminant", {})
        if not isinstance(default, str) or not isinstance(per, dict) or not all(
                isinstance(v, str) for v in per.values()):
            raise InputFileError(f"{suite}: default_illuminant must be a string and "
                                 "[illuminant] a table of strings")
        stems = {p.stem for p in files}
        extra = sorted(set(per) - stems)
        if extra:
            raise InputFileError(f"{suite}: [illuminant] names {extra[0]!r}, which has no "
                                 f"camera file in {d}")
    cases = []
    for p in files:
        if p.stem == BASELINE:
            raise InputFileError(f"{p}: the name {BASELINE!r} is reserved for the ΔE = 0 baseline")
        read_camera_file(p)  # validate early, with the file named
        ill = per.get(p.stem, default)
        try:
            load_illuminant(ill)
        except Exception as exc:  # noqa: BLE001 - re-raised naming the suite file
            raise InputFileError(f"{suite}: camera {p.stem}: {exc}") from None
        cases.append(CameraCase(p.stem, p, ill, file_sha256(p)))
    return cases


# --------------------------------------------------------------------------------------------
# Records
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ErrorProfile:
    """The direction of a chart measurement's error (:func:`chart_error_profile`).

    Mean absolute unweighted CIEDE2000 components ΔL', ΔC', ΔH' and their shares of the sum;
    signed means of ΔL' (lighter > 0) and ΔC' (more chroma > 0); the lightness-contrast ratio
    std(L*)/std(L*_ref); the mean a*, b* cast of the neutral patches; the ``dominant``
    component; the worst patch and its ΔE00.
    """

    mean_abs_dl: float
    mean_abs_dc: float
    mean_abs_dh: float
    share_l: float
    share_c: float
    share_h: float
    mean_dl: float
    mean_dc: float
    contrast_ratio: float
    neutral_cast_ab: tuple[float, float]
    dominant: str
    worst_patch: str
    worst_patch_delta_e: float

    def to_json(self) -> dict[str, Any]:
        """The profile as the store keeps it (field names as keys, in field order)."""
        return {"mean_abs_dl": self.mean_abs_dl, "mean_abs_dc": self.mean_abs_dc,
                "mean_abs_dh": self.mean_abs_dh, "share_l": self.share_l,
                "share_c": self.share_c, "share_h": self.share_h, "mean_dl": self.mean_dl,
                "mean_dc": self.mean_dc, "contrast_ratio": self.contrast_ratio,
                "neutral_cast_ab": list(self.neutral_cast_ab), "dominant": self.dominant,
                "worst_patch": self.worst_patch,
                "worst_patch_delta_e": self.worst_patch_delta_e}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ErrorProfile:
        """Inverse of :meth:`to_json`."""
        cast = d["neutral_cast_ab"]
        return cls(d["mean_abs_dl"], d["mean_abs_dc"], d["mean_abs_dh"], d["share_l"],
                   d["share_c"], d["share_h"], d["mean_dl"], d["mean_dc"], d["contrast_ratio"],
                   (cast[0], cast[1]), d["dominant"], d["worst_patch"],
                   d["worst_patch_delta_e"])


@dataclass(frozen=True)
class ImageDeltaE:
    """How far an emulation moves real photos (:func:`image_delta_e`): mean and 95th
    percentile CIEDE2000 over every ``pixel_stride``-th pixel of ``images`` images."""

    mean: float
    p95: float
    images: int
    pixel_stride: int

    def to_json(self) -> dict[str, Any]:
        """``{"mean", "p95", "images", "pixel_stride"}``."""
        return {"mean": self.mean, "p95": self.p95, "images": self.images,
                "pixel_stride": self.pixel_stride}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ImageDeltaE:
        """Inverse of :meth:`to_json`."""
        return cls(d["mean"], d["p95"], int(d["images"]), int(d["pixel_stride"]))


@dataclass(frozen=True)
class EmulationRecord:
    """A camera's fitted emulation: its ``description`` (provenance as
    :meth:`fidelity.coco.emulation.Emulation.describe` gives it: method, training set, matrix,
    fit time), its ``accuracy``, the accuracy of the ``other_methods`` fitted the same way and,
    in results, the ``holdout`` accuracy (fitted without the chart spectra)."""

    description: dict[str, Any]
    accuracy: AccuracySummary
    other_methods: dict[str, AccuracySummary]
    holdout: AccuracySummary | None = None

    def to_json(self) -> dict[str, Any]:
        """The description's keys, then ``accuracy``, ``other_methods`` (and ``holdout``)."""
        d = self.description | {"accuracy": self.accuracy.to_json(),
                                "other_methods": {k: v.to_json()
                                                  for k, v in self.other_methods.items()}}
        if self.holdout is not None:
            d["holdout"] = self.holdout.to_json()
        return d

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> EmulationRecord:
        """Inverse of :meth:`to_json`."""
        from fidelity.coco.emulation import AccuracySummary

        hold = d.get("holdout")
        return cls({k: v for k, v in d.items()
                    if k not in ("accuracy", "other_methods", "holdout")},
                   AccuracySummary.from_json(d["accuracy"]),
                   {k: AccuracySummary.from_json(v)
                    for k, v in (d.get("other_methods") or {}).items()},
                   AccuracySummary.from_json(hold) if hold else None)


@dataclass(frozen=True)
class CameraRecord:
    """A camera's chart, prediction inputs and emulation, as the store keeps it
    (:func:`prepare_case`).

    ``chart_delta_e``/``chart_max_delta_e``: mean and largest CIEDE2000 over the 24 patches
    of the closed-form render under the case's illuminant; ``profile``: its
    :class:`ErrorProfile`; ``render`` and ``patches``: the render's conventions and per-patch
    values (provenance, JSON); ``emulation``: :class:`EmulationRecord`; ``image_delta_e``:
    :class:`ImageDeltaE` (None in stores written before it was recorded); ``seconds``: the time
    the record took.
    """

    camera: str
    file: str
    sha256: str
    description: str
    illuminant: str
    chart_delta_e: float
    chart_max_delta_e: float
    profile: ErrorProfile
    render: dict[str, Any]
    patches: tuple[dict[str, Any], ...]
    emulation: EmulationRecord
    image_delta_e: ImageDeltaE | None
    seconds: float

    def to_json(self) -> dict[str, Any]:
        """The record as the store and ``validation.json`` hold it."""
        d: dict[str, Any] = {
            "camera": self.camera, "file": self.file, "sha256": self.sha256,
            "description": self.description, "illuminant": self.illuminant,
            "chart_delta_e": self.chart_delta_e, "chart_max_delta_e": self.chart_max_delta_e,
            "profile": self.profile.to_json(), "render": self.render,
            "patches": list(self.patches), "emulation": self.emulation.to_json()}
        if self.image_delta_e is not None:
            d["image_delta_e"] = self.image_delta_e.to_json()
        d["seconds"] = self.seconds
        return d

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> CameraRecord:
        """Inverse of :meth:`to_json`."""
        ide = d.get("image_delta_e")
        return cls(d["camera"], d["file"], d["sha256"], d["description"], d["illuminant"],
                   d["chart_delta_e"], d["chart_max_delta_e"],
                   ErrorProfile.from_json(d["profile"]), dict(d.get("render") or {}),
                   tuple(d.get("patches") or ()), EmulationRecord.from_json(d["emulation"]),
                   ImageDeltaE.from_json(ide) if ide else None, d.get("seconds", 0.0))


@dataclass(frozen=True)
class ValidationCell:
    """A finished (model, camera) cell of the validation store: COCO scores on ``images``
    images (fractions; ``ap`` per class name, None without ground truth), per-fold scores and
    the scores on the image bootstrap's draws (``draws``; None until scored,
    :meth:`ValidationStore.score_draws`) for standard errors, its run time and finish time
    (UTC, ISO 8601)."""

    model: str
    camera: str
    images: int
    map: float
    map50: float
    ap: dict[str, float | None]
    folds: tuple[FoldScore, ...]
    seconds: float
    finished: str
    draws: Draws | None = None

    def to_json(self) -> dict[str, Any]:
        """The cell as ``validation.json`` holds a baseline (the store's columns; the draws are
        the store's alone)."""
        return {"model": self.model, "camera": self.camera, "images": self.images,
                "map": self.map, "map50": self.map50, "ap": self.ap,
                "folds": [f.to_json() for f in self.folds], "seconds": self.seconds,
                "finished": self.finished}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ValidationCell:
        """Inverse of :meth:`to_json`."""
        from fidelity.coco.bootstrap import Draws
        from fidelity.coco.scoring import FoldScore

        return cls(d["model"], d["camera"], int(d["images"]), d["map"], d["map50"],
                   dict(d.get("ap") or {}), tuple(FoldScore.from_json(f) for f in d["folds"]),
                   d["seconds"], d["finished"],
                   Draws.from_json(d["draws"]) if d.get("draws") else None)


#: Key order of the measured losses' standard errors in ``validation.json``.
_SE_KEYS = ("dmap_points", "dap_person_points", "dap_bicycle_points", "dmap_relative")


@dataclass(frozen=True)
class TablePrediction:
    """What one prediction table predicts for a camera (:func:`predictions_for`): the
    ``losses`` (points; relative in %), each column's ``status`` and the table's ``kind``."""

    losses: Losses
    status: dict[str, str]
    kind: str

    def to_json(self) -> dict[str, Any]:
        """The losses' keys, then ``status`` and ``kind``."""
        return self.losses.to_json() | {"status": self.status, "kind": self.kind}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> TablePrediction:
        """Inverse of :meth:`to_json`."""
        return cls(Losses.from_json(d), dict(d.get("status") or {}), d["kind"])


@dataclass(frozen=True)
class BoundCheck:
    """Whether a measured loss is within the worst-case prediction for one class.

    ``within`` is None when either value is missing (then nothing else is set); otherwise
    ``within`` = measured <= predicted, ``excess`` = measured − predicted, ``se`` the
    measurement's standard error, ``within_2se`` = measured − 2 SE <= predicted (None without
    SE) and ``status`` where on the table the prediction came from.
    """

    predicted: float | None
    measured: float | None
    within: bool | None
    se: float | None = None
    excess: float | None = None
    within_2se: bool | None = None
    status: str | None = None

    def to_json(self) -> dict[str, Any]:
        """The check as ``validation.json`` holds it (three keys when not judged)."""
        if self.within is None:
            return {"predicted": self.predicted, "measured": self.measured, "within": None}
        return {"predicted": self.predicted, "measured": self.measured, "se": self.se,
                "within": self.within, "excess": self.excess, "within_2se": self.within_2se,
                "status": self.status}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> BoundCheck:
        """Inverse of :meth:`to_json`."""
        return cls(d.get("predicted"), d.get("measured"), d.get("within"), d.get("se"),
                   d.get("excess"), d.get("within_2se"), d.get("status"))


@dataclass(frozen=True)
class ValidationRow:
    """Predicted against measured loss of one (camera, model) cell (:func:`collect_results`).

    Scores are fractions; ``measured`` and ``se`` are :class:`fidelity.coco.loss.Losses`
    (points, relative in %) against the model's ΔE = 0 baseline; ``predicted``: per table its
    :class:`TablePrediction`; ``bound``: per class of :data:`fidelity.coco.loss.LOSS_COLUMNS`
    the :class:`BoundCheck` of the bound table.
    """

    camera: str
    model: str
    illuminant: str
    chart_delta_e: float
    images: int
    baseline_map: float
    map: float
    baseline_ap: dict[str, float | None]
    ap: dict[str, float | None]
    measured: Losses
    se: Losses
    predicted: dict[str, TablePrediction]
    bound: dict[str, BoundCheck]

    def to_json(self) -> dict[str, Any]:
        """The row as ``validation.json`` holds it."""
        return {"camera": self.camera, "model": self.model, "illuminant": self.illuminant,
                "chart_delta_e": self.chart_delta_e, "images": self.images,
                "baseline_map": self.baseline_map, "map": self.map,
                "baseline_ap": self.baseline_ap, "ap": self.ap,
                "measured": self.measured.to_json(), "se": self.se.to_json(_SE_KEYS),
                "predicted": {t: p.to_json() for t, p in self.predicted.items()},
                "bound": {c: b.to_json() for c, b in self.bound.items()}}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ValidationRow:
        """Inverse of :meth:`to_json`."""
        return cls(d["camera"], d["model"], d["illuminant"], d["chart_delta_e"],
                   int(d["images"]), d["baseline_map"], d["map"], dict(d["baseline_ap"]),
                   dict(d["ap"]), Losses.from_json(d["measured"]), Losses.from_json(d["se"]),
                   {t: TablePrediction.from_json(p) for t, p in d["predicted"].items()},
                   {c: BoundCheck.from_json(b) for c, b in d["bound"].items()})


@dataclass(frozen=True)
class ClassSummary:
    """How often the bound holds for one class: judged ``cells``, ``within`` and
    ``within_2se`` of them; ``cameras`` judged and ``cameras_within`` (every model within),
    their share (None without cameras) and the ``(camera, model)`` ``failures``."""

    cells: int
    within: int
    within_2se: int
    cameras: int
    cameras_within: int
    share_cameras_within: float | None
    failures: tuple[tuple[str, str], ...]

    def to_json(self) -> dict[str, Any]:
        """The summary as ``validation.json`` holds it."""
        return {"cells": self.cells, "within": self.within, "within_2se": self.within_2se,
                "cameras": self.cameras, "cameras_within": self.cameras_within,
                "share_cameras_within": self.share_cameras_within,
                "failures": [list(f) for f in self.failures]}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ClassSummary:
        """Inverse of :meth:`to_json`."""
        return cls(int(d["cells"]), int(d["within"]), int(d["within_2se"]), int(d["cameras"]),
                   int(d["cameras_within"]), d.get("share_cameras_within"),
                   tuple((str(c), str(m)) for c, m in d.get("failures") or ()))


@dataclass(frozen=True)
class ValidationSummary:
    """The bound ``bound_table`` tested, the ``tables`` evaluated, stored cameras left out
    (``not_in_suite``) and per class of :data:`fidelity.coco.loss.LOSS_COLUMNS` its
    :class:`ClassSummary`; ``standard_error``: how the measured losses' SEs were computed,
    ``"larger"``, ``"bootstrap"``, ``"jackknife"``, ``"folds"`` or ``"mixed"``
    (:data:`fidelity.coco.tables.STANDARD_ERROR_WORDS`)."""

    bound_table: str
    tables: tuple[str, ...]
    not_in_suite: tuple[str, ...]
    classes: dict[str, ClassSummary]
    standard_error: str = "folds"

    def to_json(self) -> dict[str, Any]:
        """``{"bound_table", "tables", "not_in_suite", "standard_error", <class>: ...}``."""
        return {"bound_table": self.bound_table, "tables": list(self.tables),
                "not_in_suite": list(self.not_in_suite),
                "standard_error": self.standard_error} | {
                    c: s.to_json() for c, s in self.classes.items()}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ValidationSummary:
        """Inverse of :meth:`to_json`."""
        return cls(d["bound_table"], tuple(d["tables"]), tuple(d.get("not_in_suite") or ()),
                   {c: ClassSummary.from_json(d[c]) for c in LOSS_COLUMNS if c in d},
                   d.get("standard_error", "folds"))


@dataclass(frozen=True)
class ValidationResults:
    """Everything the validation report shows (:func:`collect_results`); :meth:`to_json` is
    ``validation.json``. ``models``: the registered detectors; ``baselines``: each model's
    ΔE = 0 cell; ``meta``: the store's provenance (JSON)."""

    rows: tuple[ValidationRow, ...]
    summary: ValidationSummary
    cameras: dict[str, CameraRecord]
    models: dict[str, RegisteredModel]
    baselines: dict[str, ValidationCell]
    meta: dict[str, Any]
    #: both bounds and the blind-spot checks per camera (:mod:`fidelity.coco.bounds`)
    directional: DirectionalValidation | None = None

    def to_json(self) -> dict[str, Any]:
        """``validation.json`` (strict JSON values)."""
        d: dict[str, Any] = {
            "rows": [r.to_json() for r in self.rows], "summary": self.summary.to_json(),
            "cameras": {k: c.to_json() for k, c in self.cameras.items()},
            "models": {m: r.to_json() for m, r in self.models.items()},
            "baselines": {m: b.to_json() for m, b in self.baselines.items()},
            "meta": self.meta | ({"data": portable_paths(self.meta["data"])}
                                 if self.meta.get("data") else {})}
        if self.directional is not None:
            d["directional"] = self.directional.to_json()
        out: dict[str, Any] = json_ready(d)
        return out

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ValidationResults:
        """Inverse of :meth:`to_json` (reads ``validation.json``)."""
        return cls(tuple(ValidationRow.from_json(r) for r in d["rows"]),
                   ValidationSummary.from_json(d["summary"]),
                   {k: CameraRecord.from_json(c) for k, c in d["cameras"].items()},
                   {m: RegisteredModel.from_json(r) for m, r in d["models"].items()},
                   {m: ValidationCell.from_json(b) for m, b in d["baselines"].items()},
                   dict(d.get("meta") or {}), _directional_from_json(d.get("directional")))


def _directional_from_json(d: Mapping[str, Any] | None) -> DirectionalValidation | None:
    return DirectionalValidation.from_json(d) if d else None


# --------------------------------------------------------------------------------------------
# Chart side: ΔE, error profile, prediction, emulation accuracy
# --------------------------------------------------------------------------------------------


def chart_error_profile(measurement: ChartMeasurement) -> ErrorProfile:
    """Describe a chart measurement's error direction (for the analysis of bound failures).

    Mean absolute unweighted CIEDE2000 components ΔL', ΔC', ΔH' (Sharma et al. 2005) and
    their share of the sum; signed mean ΔL' (lighter > 0) and ΔC' (more chroma > 0); the
    lightness-contrast ratio std(L*)/std(L*_ref) over the 24 patches; the mean a*, b* shift of
    the six neutral patches (white-balance cast); the worst patch.
    """
    dl, dc, dh = (np.asarray(v, float) for v in (measurement.delta_l, measurement.delta_c,
                                                 measurement.delta_h))
    lab, ref = np.asarray(measurement.lab, float), np.asarray(measurement.reference_lab, float)
    comp = np.array([np.abs(dl).mean(), np.abs(dc).mean(), np.abs(dh).mean()])
    share = comp / comp.sum() if comp.sum() > 0 else np.zeros(3)
    neutral = slice(18, 24)
    cast = (lab[neutral, 1:] - ref[neutral, 1:]).mean(axis=0)
    de = np.asarray(measurement.delta_e, float)
    return ErrorProfile(
        mean_abs_dl=float(comp[0]), mean_abs_dc=float(comp[1]), mean_abs_dh=float(comp[2]),
        share_l=float(share[0]), share_c=float(share[1]), share_h=float(share[2]),
        mean_dl=float(dl.mean()), mean_dc=float(dc.mean()),
        contrast_ratio=float(lab[:, 0].std() / ref[:, 0].std()),
        neutral_cast_ab=(float(cast[0]), float(cast[1])),
        dominant=("lightness", "chroma", "hue")[int(np.argmax(comp))],
        worst_patch=measurement.patch_names[int(np.argmax(de))],
        worst_patch_delta_e=float(de.max()),
    )


def predictions_for(delta_e: float, baseline_map_percent: float | None,
                    tables: Sequence[str], size: str = "n") -> dict[str, TablePrediction]:
    """What every prediction table predicts at chart ``delta_e``: table -> prediction."""
    from fidelity.prediction.table import predict

    out = {}
    for t in tables:
        p = predict(delta_e, size=size, table=t, baseline_map=baseline_map_percent,
                    transforms=False)
        out[t] = TablePrediction(
            Losses(*(p.columns[col].value for col in LOSS_COLUMNS.values())),
            {col: p.columns[col].status for col in LOSS_COLUMNS.values()}, p.table.kind)
    return out


def image_delta_e(emu: Emulation, images: Sequence[np.ndarray]) -> ImageDeltaE:
    """Mean and 95th-percentile CIEDE2000 between images and their emulations (every
    ``IMAGE_DE_SAMPLE[1]``-th pixel in both directions): how far the camera moves real photos."""
    from fidelity.colour.colorimetry import delta_e_2000, srgb_to_lab

    step = IMAGE_DE_SAMPLE[1]
    vals = []
    for img in images:
        a = img[::step, ::step]
        b = emu.apply_uint8(a)
        vals.append(delta_e_2000(srgb_to_lab(a.astype(np.float64) / 255.0),
                                 srgb_to_lab(b.astype(np.float64) / 255.0)).ravel())
    v = np.concatenate(vals)
    return ImageDeltaE(float(v.mean()), float(np.percentile(v, 95)), len(images), step)


# --------------------------------------------------------------------------------------------
# Store
# --------------------------------------------------------------------------------------------

_SCHEMA = """
CREATE TABLE IF NOT EXISTS cases (camera TEXT PRIMARY KEY, key TEXT NOT NULL, info TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS cells (
    model TEXT NOT NULL, camera TEXT NOT NULL, images INTEGER, map REAL, map50 REAL,
    ap TEXT, folds TEXT, seconds REAL, finished TEXT, PRIMARY KEY (model, camera));
CREATE TABLE IF NOT EXISTS detections (
    model TEXT NOT NULL, camera TEXT NOT NULL, image_id INTEGER NOT NULL, n INTEGER NOT NULL,
    dets BLOB NOT NULL, PRIMARY KEY (model, camera, image_id));
CREATE TABLE IF NOT EXISTS draws (
    model TEXT NOT NULL, camera TEXT NOT NULL, images INTEGER NOT NULL, draws TEXT NOT NULL,
    PRIMARY KEY (model, camera));
CREATE TABLE IF NOT EXISTS imported (cell TEXT PRIMARY KEY, source TEXT NOT NULL);
"""


class ValidationStore(ResultsStore):
    """The crash-safe SQLite store of a validation run (module docstring)."""

    store_name = STORE_NAME
    kind = "validation"
    core_tables = ("meta", "models", "cases", "cells", "detections")
    schema = _SCHEMA
    cell_columns = ("model", "camera")

    def _model_conflict(self, stored_sha256: str, stored_limit: int | None, sha256: str,
                        limit: int | None) -> str | None:
        """A validation compares cameras on one image set: the image limit must match too."""
        if stored_sha256 != sha256 or stored_limit != limit:
            return "was run from another file or image limit; use a new --store"
        return None

    def case(self, camera: str) -> tuple[str, CameraRecord] | None:
        """(key, record) of a camera's chart/prediction/emulation record, or None."""
        row = self.db.execute("SELECT key, info FROM cases WHERE camera=?", (camera,)).fetchone()
        return (row[0], CameraRecord.from_json(json.loads(row[1]))) if row else None

    def set_case(self, camera: str, key: str, info: CameraRecord) -> None:
        """Store a camera's record under its identity ``key``."""
        with self.db:
            self.db.execute("INSERT OR REPLACE INTO cases VALUES (?, ?, ?)",
                            (camera, key, json.dumps(info.to_json())))

    def cases(self) -> dict[str, CameraRecord]:
        """All camera records."""
        return {c: CameraRecord.from_json(json.loads(i))
                for c, _, i in self.db.execute("SELECT * FROM cases")}

    def stored_images(self, model: str, camera: str) -> set[int]:
        """Image ids whose detections are stored for (model, camera)."""
        return {r[0] for r in self.db.execute(
            "SELECT image_id FROM detections WHERE model=? AND camera=?", (model, camera))}

    def add_detections(self, model: str, camera: str, rows: list[tuple[int, np.ndarray]]) -> None:
        """Store (image_id, detections) pairs in one transaction."""
        with self.db:
            self.db.executemany("INSERT OR REPLACE INTO detections VALUES (?, ?, ?, ?, ?)",
                                [(model, camera, int(i), len(d), pack_detections(d))
                                 for i, d in rows])

    def detections(self, model: str, camera: str) -> dict[int, np.ndarray]:
        """Stored detections of a cell: image_id -> (n, 6). A cell imported from a scores
        file (:mod:`fidelity.coco.scores`) has none: asking is an input error naming it."""
        out = {i: unpack_detections(b) for i, b in self.db.execute(
            "SELECT image_id, dets FROM detections WHERE model=? AND camera=?", (model, camera))}
        if not out:
            self.check_detections((model, camera))
        return out

    def complete_scores(self, coco: Any, method: str = "auto") -> int:
        """The fold scores with the rest of the run and the bootstrap draws of every cell that
        lacks them (:meth:`rescore_folds`, :meth:`score_draws`); how many cells there are."""
        self.rescore_folds(coco)
        self.score_draws(coco)
        return len(self.cells())

    def cell(self, model: str, camera: str) -> ValidationCell | None:
        """A finished cell, or None."""
        cur = self.db.execute("SELECT * FROM cells WHERE model=? AND camera=?", (model, camera))
        row = cur.fetchone()
        if row is None:
            return None
        d = {c[0]: v for c, v in zip(cur.description, row, strict=True)}
        drawn = self.db.execute("SELECT images, draws FROM draws WHERE model=? AND camera=?",
                                (model, camera)).fetchone()
        return ValidationCell.from_json(d | {
            "ap": json.loads(d["ap"]), "folds": json.loads(d["folds"]),
            "draws": json.loads(drawn[1]) if drawn and drawn[0] == d["images"] else None})

    def cells(self) -> list[ValidationCell]:
        """All finished cells."""
        rows = self.db.execute("SELECT model, camera FROM cells ORDER BY model, camera").fetchall()
        return [c for m, k in rows if (c := self.cell(m, k)) is not None]

    def rescore_folds(self, coco: Any, say: Callable[[str], None] | None = None) -> int:
        """Score again, from the stored detections (no inference), the folds of every cell
        whose fold scores lack the rest-of-run scores the jackknife SE needs (cells stored
        before they were; :func:`fidelity.coco.scoring.score_folds`). Returns how many."""
        from fidelity.coco.scoring import score_folds

        n = 0
        for c in self.cells():
            if all(f.has_rest for f in c.folds):  # (no folds: fewer than 2 images)
                continue
            dets = self.detections(c.model, c.camera)
            folds = score_folds(coco, dets, sorted(dets), FOLDS, method="auto")
            with self.db:
                self.db.execute("UPDATE cells SET folds=? WHERE model=? AND camera=?",
                                (json.dumps([f.to_json() for f in folds]), c.model, c.camera))
            n += 1
            if say:
                say(f"{c.camera} / {c.model}: folds scored again with the rest of the run")
        return n

    def score_draws(self, coco: Any, say: Callable[[str], None] | None = None) -> int:
        """Score every cell on the image bootstrap's draws (:func:`fidelity.coco.bootstrap.
        draw_scores`, its default draws and seed) from the stored detections, where they are
        not stored for the cell's images, draws and seed yet. Returns how many were scored."""
        from fidelity.coco.bootstrap import draw_scores

        n = 0
        for c in self.cells():
            if c.draws is not None and c.draws.current:
                continue
            dets = self.detections(c.model, c.camera)
            draws = draw_scores(coco, dets, sorted(dets))
            with self.db:
                self.db.execute("INSERT OR REPLACE INTO draws VALUES (?, ?, ?, ?)",
                                (c.model, c.camera, draws.images, json.dumps(draws.to_json())))
            n += 1
            if say:
                say(f"{c.camera} / {c.model}: scored on {draws.resamples} bootstrap draws")
        return n

    def finish_cell(self, model: str, camera: str, score: CocoScore,
                    folds: Sequence[FoldScore], seconds: float) -> None:
        """Record a finished cell with its full-set score and per-fold scores."""
        with self.db:
            self.db.execute("INSERT OR REPLACE INTO cells VALUES (?,?,?,?,?,?,?,?,?)",
                            (model, camera, score.images, score.map, score.map50,
                             json.dumps(score.ap), json.dumps([f.to_json() for f in folds]),
                             seconds, time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())))


# --------------------------------------------------------------------------------------------
# Run
# --------------------------------------------------------------------------------------------


def prepare_case(case: CameraCase, store: ValidationStore, method: str, training: str,
                 cache: ImageCache, image_ids: Sequence[int]
                 ) -> tuple[Emulation, CameraRecord]:
    """Render, measure, fit the emulation and check it; the record is stored (resumable)."""
    from fidelity.camera.render import render_chart
    from fidelity.coco.emulation import (
        EMULATION_METHODS,
        EMULATION_VERSION,
        emulation_accuracy,
        fit_emulation,
    )

    key = json.dumps({"sha256": case.sha256, "illuminant": case.illuminant, "method": method,
                      "training": training, "emulation_version": EMULATION_VERSION})
    have = store.case(case.name)
    if have and have[0] != key:
        raise InvalidValueError(f"store {store.path}: camera {case.name!r} was run with another "
                                f"file, illuminant or emulation method; use a new --store")
    emu = fit_emulation(case.path, case.illuminant, method=method, training=training)
    if have:
        return emu, have[1]
    t0 = time.perf_counter()
    render = render_chart(emu.camera, case.illuminant)
    m = render.measurement
    acc = emulation_accuracy(emu)
    sample = [cache.get(i)[0] for i in image_ids[: IMAGE_DE_SAMPLE[0]]]
    info = CameraRecord(
        camera=case.name, file=case.path.name, sha256=case.sha256,
        description=emu.camera.description, illuminant=case.illuminant,
        chart_delta_e=float(m.mean_delta_e), chart_max_delta_e=float(m.max_delta_e),
        profile=chart_error_profile(m),
        render={"renderer": render.renderer, "conventions": {
            k: render.conventions[k] for k in ("exposure_gain", "white_balance_gains", "ccm")}},
        patches=tuple({k: p[k] for k in ("name", "delta_e", "delta_l", "delta_c", "delta_h",
                                         "lab", "reference_lab", "srgb")}
                      for p in m.to_json()["patches"]),
        emulation=EmulationRecord(
            emu.describe(), acc.summary(),
            {k: emulation_accuracy(fit_emulation(emu.camera, case.illuminant, k,
                                                 training)).summary()
             for k in EMULATION_METHODS if k != method}),
        image_delta_e=image_delta_e(emu, sample),
        seconds=time.perf_counter() - t0,
    )
    store.set_case(case.name, key, info)
    return emu, info


def run_validation(cases: Sequence[CameraCase], models: Sequence[ModelSpec],
                   images: str | os.PathLike[str], annotations: str | os.PathLike[str],
                   store_dir: str | os.PathLike[str], *, method: str = "root-polynomial",
                   training: str = "colour-science", threads: int | None = 1,
                   provider: str = "auto", batch_commit: int = 25, progress: bool = True,
                   log: Callable[[str], None] | None = None,
                   executor: ExecutorOptions | None = None,
                   lease_s: float | None = None) -> ValidationStore:
    """Run (or resume) the validation; ``models`` are :class:`fidelity.coco.sweep.ModelSpec`.

    Per model the baseline cell runs first, then cameras in the given order; each camera's
    emulation table is built once (by this process) and used for every model. ``executor``:
    where the detectors run (:class:`fidelity.coco.executor.ExecutorOptions`; default: this
    process with ``threads`` and ``provider``); the store is written by this process only,
    its cells claimed so that several runs share them (``lease_s``: see
    :func:`fidelity.coco.sweep.run_sweep`). Inputs are checked against the store's record.
    """
    import functools

    import onnxruntime

    from fidelity.coco.driver import StoreRun
    from fidelity.coco.executor import (
        IDENTITY,
        CellWork,
        ExecutorOptions,
        ModelFile,
        PixelTransform,
    )
    from fidelity.coco.scoring import load_annotated_images
    from fidelity.coco.store import ImageSet
    from fidelity.coco.sweep import ImageCache

    opts = executor or ExecutorOptions(threads=threads, provider=provider)
    say = log or (lambda s: print(s, file=sys.stderr, flush=True))
    img_dir, coco, all_ids = load_annotated_images(images, annotations)
    files = [ModelFile.from_path(m.path) for m in models]
    if not files:
        raise InvalidValueError("no models to run (--models is empty)")
    store = ValidationStore(store_dir)
    image_set = ImageSet(img_dir, coco, all_ids)
    store.start_run(image_set, [m.limit for m in models], annotations)
    import cv2

    store.set_meta("versions", {"python": platform.python_version(),
                                "onnxruntime": onnxruntime.__version__, "numpy": np.__version__,
                                "opencv": cv2.__version__, "fidelity": __version__,
                                "colour": _colour_version()})
    store.set_meta("settings", {"emulation_method": method, "training": training,
                                "folds": FOLDS, "size_class": "n",
                                "jpeg": "original quantisation tables and subsampling "
                                        "(fidelity.coco.jpeg.roundtrip_jpeg), as the COCO sweep"})
    store.set_meta("cameras", [{"camera": c.name, "file": c.path.name,
                                "illuminant": c.illuminant} for c in cases])
    cache = ImageCache(img_dir, coco)
    with StoreRun(store, lambda: ValidationStore(store.folder, create=False), image_set,
                  opts) as run:
        run.record_machine({"threads": opts.threads, "provider": opts.provider})
        run.register_models(files, [m.limit for m in models])
        runs = [(f, tuple(all_ids[: spec.limit] if spec.limit else all_ids))
                for spec, f in zip(models, files, strict=True)]
        store.set_meta("models_run", [{"model": f.name, "images": len(i)} for f, i in runs])
        run.start_leases(lease_s)
        tables = EmulationTables(store, method, training, cache, all_ids, say,
                                 max((ids for _, ids in runs), key=len))
        work = [CellWork((f.name, BASELINE), f"{BASELINE} / {f.name}", f,
                         PixelTransform.of(IDENTITY, None), ids) for f, ids in runs]
        for case in cases:
            done = all(store.cell(f.name, case.name) for f, _ in runs)
            if done:
                if not store.case(case.name):
                    prepare_case(case, store, method, training, cache, all_ids)
                continue
            key = json.dumps([case.name, case.sha256, case.illuminant, method, training])
            emulated = PixelTransform(key, case.name)
            work += [CellWork((f.name, case.name), f"{case.name} / {f.name}", f, emulated, ids,
                              functools.partial(tables.get, case)) for f, ids in runs]
        run.run(work, ValidationCells(store, run.stores, coco, say), batch_commit=batch_commit,
                progress=progress, say=say)
    store.rescore_folds(coco, say)  # cells an earlier version stored without rest scores
    store.score_draws(coco, say)  # the bootstrap's draws of every cell not scored on them yet
    return store


class EmulationTables:
    """The 8-bit emulation tables of a validation run's cameras, built when a cell first needs
    one (:func:`prepare_case` on ``image_ids``, logged through ``say``) and kept one camera at
    a time: the 2^24-entry table, or, where the cells run on at most
    :data:`fidelity.coco.executor.DIRECT_IMAGES` images (``run_ids``, default ``image_ids``:
    every image any cell runs on), the same entries for the colours those images hold only
    (about 3 s a camera spared)."""

    def __init__(self, store: ValidationStore, method: str, training: str, cache: ImageCache,
                 image_ids: Sequence[int], say: Callable[[str], None],
                 run_ids: Sequence[int] | None = None) -> None:
        self.store = store
        self.method = method
        self.training = training
        self.cache = cache
        self.image_ids = image_ids
        self.say = say
        self.run_ids = image_ids if run_ids is None else run_ids
        self.built: dict[str, PixelMap] = {}
        self.codes: np.ndarray | None = None  # the distinct colours of a small run's images

    def get(self, case: CameraCase) -> PixelMap:
        """The camera's 8-bit table (:meth:`fidelity.coco.emulation.Emulation.cube`, or
        :meth:`~fidelity.coco.emulation.Emulation.map_codes` on the images' colours)."""
        from fidelity.coco.dataset import PixelMap, colour_codes
        from fidelity.coco.executor import DIRECT_IMAGES

        if case.name not in self.built:
            self.built.clear()  # one camera's table at a time
            emu, info = prepare_case(case, self.store, self.method, self.training, self.cache,
                                     self.image_ids)
            acc = info.emulation.accuracy
            self.say(f"{time.strftime('%H:%M:%S')} {case.name} ({case.illuminant}): chart "
                     f"ΔE {info.chart_delta_e:.2f}, emulation chart ΔE00 mean "
                     f"{acc.chart_mean_delta_e:.2f} max {acc.chart_max_delta_e:.2f}")
            if len(self.run_ids) <= DIRECT_IMAGES:
                if self.codes is None:
                    self.codes = np.unique(np.concatenate(
                        [colour_codes(self.cache.get(i)[0]).ravel() for i in self.run_ids]
                        or [np.empty(0, np.uint32)]))
                table = PixelMap.of_codes(case.name, self.codes, emu.map_codes(self.codes))
            else:
                table = PixelMap(case.name, None, "cube", emu.cube())
            self.built[case.name] = table
        return self.built[case.name]


class ValidationCells:
    """The validation store as :func:`fidelity.coco.executor.run_cells` sees it (a
    :class:`fidelity.coco.executor.CellStore`): cells keyed ``(model, camera)``, scored on
    ``coco`` with their fold scores when their detections are all stored, each logged through
    ``say``. ``store``: the run's connection (the driver's thread); ``stores``: a connection
    per thread, for scoring (a cell may be scored on a thread of its own)."""

    def __init__(self, store: ValidationStore, stores: ThreadStores[ValidationStore],
                 coco: Any, say: Callable[[str], None]) -> None:
        self.store = store
        self.stores = stores
        self.coco = coco
        self.say = say

    def done(self, cell: CellWork) -> bool:
        """Whether the cell is finished."""
        return self.store.cell(*cell.key) is not None

    def stored(self, cell: CellWork) -> set[int]:
        """Image ids whose detections are stored."""
        return self.store.stored_images(*cell.key)

    def add(self, cell: CellWork, rows: Sequence[tuple[int, np.ndarray]]) -> None:
        """Store detections (one transaction)."""
        model, camera = cell.key
        self.store.add_detections(model, camera, list(rows))

    def finish(self, cell: CellWork, seconds: float, new: int) -> None:
        """Score the cell and its folds, record it and log it."""
        from fidelity.coco.scoring import evaluate_detections, score_folds

        model, camera = cell.key
        ids = list(cell.image_ids)
        own = self.stores.get()  # run_cells may score on a thread of its own
        dets = own.detections(model, camera)
        score = evaluate_detections(self.coco, dets, ids)
        folds = score_folds(self.coco, dets, ids, FOLDS, method="auto")
        own.finish_cell(model, camera, score, folds, seconds)
        self.say(f"{time.strftime('%H:%M:%S')} {camera} / {model}: mAP={score.map:.4f} "
                 f"person={score.ap.get('person')} images={len(ids)} new={new} "
                 f"{seconds:.1f}s")


def _colour_version() -> str | None:
    """colour-science's version, read from its metadata (the record needs no import of it)."""
    from fidelity.core.version import installed_version

    return installed_version("colour-science")


# --------------------------------------------------------------------------------------------
# Results
# --------------------------------------------------------------------------------------------


def holdout_accuracy(cases: Sequence[CameraCase], method: str = "root-polynomial"
                     ) -> dict[str, AccuracySummary]:
    """Out-of-sample emulation accuracy per camera: the mapping fitted on the colour-science
    reflectances *without* the 24 chart patches, checked on the chart
    (:func:`fidelity.coco.emulation.emulation_accuracy`)."""
    from fidelity.coco.emulation import emulation_accuracy, fit_emulation

    return {c.name: emulation_accuracy(fit_emulation(c.path, c.illuminant, method,
                                                     "colour-science-no-chart")).summary()
            for c in cases}


def _bound_check(predicted: float | None, measured: float | None, se: float | None,
                 status: str) -> BoundCheck:
    if predicted is None or measured is None:
        return BoundCheck(predicted, measured, None)
    return BoundCheck(predicted, measured, measured <= predicted, se, measured - predicted,
                      (measured - 2 * se) <= predicted if se is not None else None, status)


def _row(camera: str, info: CameraRecord, b: ValidationCell, c: ValidationCell,
         tables: Sequence[str], bound: str) -> tuple[ValidationRow, str | None]:
    """Predicted against measured loss of one cell ``c`` against its baseline ``b``
    (:func:`fidelity.coco.loss.score_loss`), and how the mAP loss's SE was computed
    (``se_method``; None: no SE)."""
    from fidelity.coco.loss import score_loss

    base: dict[str, float | None] = {"map": b.map, **b.ap}
    cell: dict[str, float | None] = {"map": c.map, **c.ap}
    loss, person, bicycle = (score_loss(k, base, cell, b.folds, c.folds, b.draws, c.draws)
                             for k in ("map", "person", "bicycle"))
    measured = Losses(loss.points, loss.relative, person.points, bicycle.points)
    se = Losses(loss.points_se, loss.relative_se, person.points_se, bicycle.points_se)
    pred = predictions_for(info.chart_delta_e, 100.0 * b.map, tables)
    checks = {cls: _bound_check(pred[bound].losses.get(col), measured.get(col), se.get(col),
                                pred[bound].status[col])
              for cls, col in LOSS_COLUMNS.items()}
    row = ValidationRow(camera, c.model, info.illuminant, info.chart_delta_e, c.images,
                        b.map, c.map, {k: b.ap.get(k) for k in ("person", "bicycle")},
                        {k: c.ap.get(k) for k in ("person", "bicycle")}, measured, se, pred,
                        checks)
    return row, loss.se_method


def _class_summary(rows: Sequence[ValidationRow], cls: str) -> ClassSummary:
    judged = [r for r in rows if r.bound[cls].within is not None]
    ok = [r for r in judged if r.bound[cls].within]
    ok2 = [r for r in judged if r.bound[cls].within_2se]
    cams = sorted({r.camera for r in judged})
    cams_ok = [k for k in cams if all(r.bound[cls].within for r in judged if r.camera == k)]
    return ClassSummary(len(judged), len(ok), len(ok2), len(cams), len(cams_ok),
                        len(cams_ok) / len(cams) if cams else None,
                        tuple((r.camera, r.model) for r in judged if not r.bound[cls].within))


def collect_results(store: ValidationStore, tables: Sequence[str] | None = None,
                    bound_table: str | None = None,
                    suite: Sequence[CameraCase] | None = None) -> ValidationResults:
    """Predicted against measured losses of every finished (camera, model) cell.

    ``tables``: prediction tables to evaluate (default: all available but the directional ones,
    whose classic curves are their measured table's and whose bound has its own section,
    :func:`directional_validation`); ``bound_table``: the
    worst-case table whose bound is tested (default
    :data:`fidelity.prediction.table.DEFAULT_TABLE`). Returns one :class:`ValidationRow` per
    camera and model, the :class:`ValidationSummary`, the camera records, models, baselines
    and provenance. With ``suite`` (the camera cases), each stored camera also gets its
    out-of-sample emulation accuracy (:func:`holdout_accuracy`) as ``emulation.holdout``, and
    stored cameras that are not in the suite (renamed or removed camera files) are left out of
    the results and listed in ``summary.not_in_suite``.
    """
    from fidelity.prediction.table import (
        DEFAULT_TABLE,
        TableKind,
        available_tables,
        load_prediction_table,
    )

    tabs = list(tables) if tables else [
        t for t in available_tables() if load_prediction_table(t).kind != TableKind.DIRECTIONAL]
    bound = bound_table or DEFAULT_TABLE
    if bound not in tabs:
        tabs.append(bound)
    cases = store.cases()
    not_in_suite: list[str] = []
    if suite:
        names = {c.name for c in suite}
        not_in_suite = sorted(k for k in cases if k not in names)
        cases = {k: v for k, v in cases.items() if k in names}
        method = store.meta().get("settings", {}).get("emulation_method", "root-polynomial")
        hold = holdout_accuracy([c for c in suite if c.name in cases], method)
        for name, acc in hold.items():
            cases[name] = replace(cases[name],
                                  emulation=replace(cases[name].emulation, holdout=acc))
    cells = {(c.model, c.camera): c for c in store.cells()}
    models = store.models()
    rows = []
    methods: set[str] = set()
    for (model, camera), c in sorted(cells.items()):
        if camera == BASELINE or camera not in cases:
            continue
        b = cells.get((model, BASELINE))
        if b is None:
            continue
        row, se_method = _row(camera, cases[camera], b, c, tabs, bound)
        rows.append(row)
        if se_method is not None:
            methods.add(se_method)
    summary = ValidationSummary(bound, tuple(tabs), tuple(not_in_suite),
                                {cls: _class_summary(rows, cls) for cls in LOSS_COLUMNS},
                                methods.pop() if len(methods) == 1 else
                                "mixed" if methods else "folds")
    results = ValidationResults(
        tuple(rows), summary, cases, models,
        {m: cells[(m, BASELINE)] for m in models if (m, BASELINE) in cells}, store.meta())
    if suite and rows:
        results = replace(results, directional=directional_validation(results, suite))
    return results


def directional_validation(results: ValidationResults,
                           suite: Sequence[CameraCase] | None = None,
                           table: str | None = None) -> DirectionalValidation:
    """Both bounds and the blind-spot checks on every camera and cell of ``results``
    (:func:`fidelity.coco.bounds.compare_bounds`, against the classic prediction of
    ``results.summary.bound_table``); ``suite``: the camera files, to render each chart (closed
    form) and read its bit depth; ``table``: the direction-aware table (None: the default)."""
    by_name = {c.name: c for c in suite or ()}
    charts = {name: CameraChart(name, rec.chart_delta_e, rec.patches,
                                by_name[name].path if name in by_name else None,
                                by_name[name].illuminant if name in by_name else None)
              for name, rec in results.cameras.items()}
    bound = results.summary.bound_table
    cells = [MeasuredCell(r.camera, r.model, r.chart_delta_e, r.measured, r.se,
                          r.predicted[bound].losses) for r in results.rows]
    return compare_bounds(cells, charts, table)


def validated_cameras(results: ValidationResults, suite: Sequence[CameraCase]
                      ) -> ValidatedCameras:
    """The cameras ``results`` validated, as the validity domain of a prediction states them
    (:class:`~fidelity.prediction.interval.ValidatedCameras`): each camera of the results read
    from its file in ``suite`` (the same SHA-256 as validated, else an
    :class:`InputFileError`), its illuminant and the kinds of its stages
    (:meth:`~fidelity.camera.model.CameraModel.stage_kinds`); the counts of the mean-mAP
    class (``all``) of the summary."""
    from fidelity.camera.model import read_camera_file
    from fidelity.prediction.interval import STAGES, ValidatedCameras

    cases = {c.name: c for c in suite}
    illuminants: set[str] = set()
    sensitivities: set[str] = set()
    stages: dict[str, set[str]] = {s: set() for s in STAGES}
    for name, record in results.cameras.items():
        case = cases.get(name)
        if case is None or case.sha256 != record.sha256:
            raise InputFileError(f"{name}: the camera file validated is not in the suite "
                                 "(missing, or changed since: its SHA-256 differs)")
        cam = read_camera_file(case.path)
        illuminants.add(case.illuminant)
        sensitivities.add(cam.sensitivities.name)
        for stage, kind in cam.stage_kinds().items():
            stages[stage].add(kind)
    mean = results.summary.classes["all"]

    def order(kinds: set[str]) -> tuple[str, ...]:  # bit depths by number, words by name
        return tuple(sorted(kinds, key=lambda k: (not k.isdigit(), int(k) if k.isdigit()
                                                  else 0, k)))

    return ValidatedCameras(len(results.cameras), tuple(sorted(illuminants)),
                            {s: order(k) for s, k in stages.items()},
                            tuple(sorted(sensitivities)), tuple(results.models), mean.cells,
                            mean.within, mean.within_2se)


__all__ = [
    "BASELINE",
    "CLASSES",
    "FOLDS",
    "BoundCheck",
    "CameraCase",
    "CameraRecord",
    "ClassSummary",
    "EmulationRecord",
    "EmulationTables",
    "ErrorProfile",
    "ImageDeltaE",
    "TablePrediction",
    "ValidationCell",
    "ValidationCells",
    "ValidationResults",
    "ValidationRow",
    "ValidationStore",
    "ValidationSummary",
    "chart_error_profile",
    "collect_results",
    "default_store",
    "directional_validation",
    "holdout_accuracy",
    "image_delta_e",
    "load_suite",
    "predictions_for",
    "prepare_case",
    "run_validation",
    "validated_cameras",
]
