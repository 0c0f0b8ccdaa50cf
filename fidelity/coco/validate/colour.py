"""Colour's validation: realistic cameras emulated on COCO, and ``validation.json``.

For every camera of a suite (:mod:`fidelity.coco.validate.suite`):

1. **Predict.** Render the chart (:func:`fidelity.coco.validate.camera.case_chart`, closed
   form) under the test case's illuminant, take the chart ΔE (mean CIEDE2000 over the 24
   patches, against the scene reference adapted to D65 with the case's transform ``cat``)
   and predict the detection loss with every prediction table
   (:func:`fidelity.prediction.table.predict`, detector size ``n``; the baseline mAP of the
   detector resolves the paper's points-vs-relative ambiguity conservatively).
2. **Measure.** Fit the camera's colour rendering
   (:func:`fidelity.coco.emulation.fit_emulation`), apply it to every COCO image, and run the
   detectors on the result after the same JPEG round trip as the COCO sweep (original
   quantisation tables and subsampling, :func:`fidelity.coco.jpeg.roundtrip_jpeg`); ΔmAP is
   measured against the ΔE = 0 baseline (the same round trip with no colour change), in
   percentage points and relative to the baseline, and per class (person, bicycle).
3. **Compare.** The worst-case table bounds a camera when the measured loss is at most the
   prediction (:mod:`fidelity.coco.validate.checks`), with the standard error of every
   measured loss (:func:`fidelity.coco.loss.loss_estimate`, as the sweep tables).

:func:`run_validation` runs (or resumes) steps 1 and 2 into a
:class:`~fidelity.coco.validate.store.ValidationStore`; :func:`collect_results` makes
:class:`ValidationResults` (``validation.json``) of it, with both bounds and the blind-spot
checks per camera (:func:`directional_validation`) and the validity domain
(:func:`validated_cameras`).
"""

from __future__ import annotations

import functools
import json
import os
import platform
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from fidelity.camera.model import read_camera_file
from fidelity.coco.bounds import CameraChart, DirectionalValidation, MeasuredCell, compare_bounds
from fidelity.coco.dataset import PixelMap, colour_codes
from fidelity.coco.driver import StoreRun
from fidelity.coco.emulation import (
    EMULATION_METHODS,
    EMULATION_VERSION,
    emulation_accuracy,
    fit_emulation,
)
from fidelity.coco.executor import (
    DIRECT_IMAGES,
    IDENTITY,
    CellWork,
    ExecutorOptions,
    ImageMap,
    ModelFile,
    PixelTransform,
)
from fidelity.coco.imaging import camera_imaging
from fidelity.coco.loss import LOSS_COLUMNS
from fidelity.coco.scoring import FOLDS, load_annotated_images
from fidelity.coco.store import ImageSet, RegisteredModel
from fidelity.coco.sweep import ImageCache
from fidelity.coco.validate.camera import (
    IMAGE_DE_SAMPLE,
    CameraRecord,
    EmulationRecord,
    case_chart,
    chart_error_profile,
    image_delta_e,
)
from fidelity.coco.validate.checks import (
    ValidationRow,
    ValidationSummary,
    class_summary,
    validation_row,
)
from fidelity.coco.validate.store import ValidationCell, ValidationCells, ValidationStore
from fidelity.coco.validate.suite import BASELINE, DEFAULT_CAT, CameraCase, validated_case
from fidelity.core.errors import InvalidValueError
from fidelity.core.fileio import json_ready, portable_paths
from fidelity.core.record import record
from fidelity.core.version import __version__, installed_version
from fidelity.prediction.interval import (
    DEGRADATIONS,
    STAGES,
    ValidatedCameras,
    validated_degradation,
)
from fidelity.prediction.tablefile import (
    DEFAULT_TABLE,
    TableKind,
    available_tables,
    load_prediction_table,
)

if TYPE_CHECKING:
    from fidelity.coco.dataset import PixelMap
    from fidelity.coco.emulation import AccuracySummary, Emulation
    from fidelity.coco.executor import ExecutorOptions
    from fidelity.coco.sweep import ImageCache, ModelSpec
    from fidelity.prediction.interval import ValidatedCameras


def prepare_case(case: CameraCase, store: ValidationStore, method: str, training: str,
                 cache: ImageCache, image_ids: Sequence[int]
                 ) -> tuple[Emulation, CameraRecord]:
    """Render, measure, fit the emulation and check it; the record is stored (resumable).

    The chart is :func:`~fidelity.coco.validate.camera.case_chart`'s (the case's illuminant
    and chromatic adaptation transform); the record's key names the transform where it is not
    :data:`~fidelity.coco.validate.suite.DEFAULT_CAT`, so that stores recorded before (all
    Bradford) keep their keys and a camera recorded under another transform is not reused."""
    fields: dict[str, Any] = {"sha256": case.sha256, "illuminant": case.illuminant,
                              "method": method, "training": training,
                              "emulation_version": EMULATION_VERSION}
    if case.cat != DEFAULT_CAT:
        fields["cat"] = case.cat
    key = json.dumps(fields)
    have = store.case(case.name)
    if have and have[0] != key:
        raise InvalidValueError(f"store {store.path}: camera {case.name!r} was run with another "
                                f"file, illuminant, chromatic adaptation or emulation method; "
                                f"use a new --store")
    emu = fit_emulation(case.path, case.illuminant, method=method, training=training)
    if have:
        return emu, have[1]
    t0 = time.perf_counter()
    render = case_chart(case, emu.camera)
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
        cat=case.cat,
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
    import onnxruntime

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
                                "illuminant": c.illuminant, "cat": c.cat} for c in cases])
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
            parts: list[Any] = [case.name, case.sha256, case.illuminant, method, training]
            if _has_imaging(case):  # optics, noise or vignetting, emulated per image
                parts.append({"imaging": IMAGING_VERSION})
            key = json.dumps(parts)
            emulated = PixelTransform(key, case.name)
            work += [CellWork((f.name, case.name), f"{case.name} / {f.name}", f, emulated, ids,
                              functools.partial(tables.get, case)) for f, ids in runs]
        run.run(work, ValidationCells(store, run.stores, coco, say), batch_commit=batch_commit,
                progress=progress, say=say)
    store.rescore_folds(coco, say)  # cells an earlier version stored without rest scores
    store.score_draws(coco, say)  # the bootstrap's draws of every cell not scored on them yet
    return store


#: Version of the per-image emulation of optics, noise and vignetting
#: (:mod:`fidelity.coco.imaging`), in the transform key of the cameras that have them.
IMAGING_VERSION = 1


def _has_imaging(case: CameraCase) -> bool:
    cam = read_camera_file(case.path)
    return cam.optics.kind != "none" or cam.noise.enabled or cam.vignetting_fov_deg is not None


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
        self.built: dict[str, ImageMap] = {}
        self.codes: np.ndarray | None = None  # the distinct colours of a small run's images

    def get(self, case: CameraCase) -> ImageMap:
        """The camera's 8-bit table (:meth:`fidelity.coco.emulation.Emulation.cube`, or
        :meth:`~fidelity.coco.emulation.Emulation.map_codes` on the images' colours); for a
        camera with optics, noise or vignetting its
        :class:`~fidelity.coco.imaging.CameraImaging` (colour, lens and sensor per image)."""
        if case.name not in self.built:
            self.built.clear()  # one camera's table at a time
            emu, info = prepare_case(case, self.store, self.method, self.training, self.cache,
                                     self.image_ids)
            acc = info.emulation.accuracy
            imaging = camera_imaging(emu)
            self.say(f"{time.strftime('%H:%M:%S')} {case.name} ({case.illuminant}): chart "
                     f"ΔE {info.chart_delta_e:.2f}, emulation chart ΔE00 mean "
                     f"{acc.chart_mean_delta_e:.2f} max {acc.chart_max_delta_e:.2f}"
                     + ("" if imaging is None else "; optics and noise emulated per image"))
            table: ImageMap
            if imaging is not None:
                table = imaging
            elif len(self.run_ids) <= DIRECT_IMAGES:
                if self.codes is None:
                    self.codes = np.unique(np.concatenate(
                        [colour_codes(self.cache.get(i)[0]).ravel() for i in self.run_ids]
                        or [np.empty(0, np.uint32)]))
                table = PixelMap.of_codes(case.name, self.codes, emu.map_codes(self.codes))
            else:
                table = PixelMap(case.name, None, "cube", emu.cube())
            self.built[case.name] = table
        return self.built[case.name]


def _colour_version() -> str | None:
    """colour-science's version, read from its metadata (the record needs no import of it)."""
    return installed_version("colour-science")


def holdout_accuracy(cases: Sequence[CameraCase], method: str = "root-polynomial"
                     ) -> dict[str, AccuracySummary]:
    """Out-of-sample emulation accuracy per camera: the mapping fitted on the colour-science
    reflectances *without* the 24 chart patches, checked on the chart
    (:func:`fidelity.coco.emulation.emulation_accuracy`)."""
    return {c.name: emulation_accuracy(fit_emulation(c.path, c.illuminant, method,
                                                     "colour-science-no-chart")).summary()
            for c in cases}


@record
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


def collect_results(store: ValidationStore, tables: Sequence[str] | None = None,
                    bound_table: str | None = None,
                    suite: Sequence[CameraCase] | None = None) -> ValidationResults:
    """Predicted against measured losses of every finished (camera, model) cell.

    ``tables``: prediction tables to evaluate (default: all available but the directional ones,
    whose classic curves are their measured table's and whose bound has its own section,
    :func:`directional_validation`); ``bound_table``: the
    worst-case table whose bound is tested (default
    :data:`fidelity.prediction.tablefile.DEFAULT_TABLE`). Returns one
    :class:`~fidelity.coco.validate.checks.ValidationRow` per camera and model, the
    :class:`~fidelity.coco.validate.checks.ValidationSummary`, the camera records, models,
    baselines and provenance. With ``suite`` (the camera cases), each stored camera also gets its
    out-of-sample emulation accuracy (:func:`holdout_accuracy`) as ``emulation.holdout``, and
    stored cameras that are not in the suite (renamed or removed camera files) are left out of
    the results and listed in ``summary.not_in_suite``.
    """
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
        info = cases[camera]
        row, se_method = validation_row(camera, info.illuminant, info.chart_delta_e, b, c,
                                        tabs, bound)
        rows.append(row)
        if se_method is not None:
            methods.add(se_method)
    summary = ValidationSummary(bound, tuple(tabs), tuple(not_in_suite),
                                {cls: class_summary(rows, cls) for cls in LOSS_COLUMNS},
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
                                by_name[name].illuminant if name in by_name else None,
                                rec.cat)
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
    (:meth:`~fidelity.camera.model.CameraModel.stage_kinds`) and of its noise, optics and
    vignetting (:meth:`~fidelity.camera.model.CameraModel.degradations`); the counts of the mean-mAP
    class (``all``) of the summary."""
    cases = {c.name: c for c in suite}
    illuminants: set[str] = set()
    sensitivities: set[str] = set()
    stages: dict[str, set[str]] = {s: set() for s in STAGES}
    seen: dict[str, list[tuple[str, Mapping[str, float]]]] = {d: [] for d in DEGRADATIONS}
    for name, camera_result in results.cameras.items():
        case = validated_case(cases, name, camera_result.sha256)
        cam = read_camera_file(case.path)
        illuminants.add(case.illuminant)
        sensitivities.add(cam.sensitivities.name)
        for stage, kind in cam.stage_kinds().items():
            stages[stage].add(kind)
        for name, degradation in cam.degradations().items():
            seen[name].append(degradation)
    mean = results.summary.classes["all"]

    def order(kinds: set[str]) -> tuple[str, ...]:  # bit depths by number, words by name
        return tuple(sorted(kinds, key=lambda k: (not k.isdigit(), int(k) if k.isdigit()
                                                  else 0, k)))

    return ValidatedCameras(len(results.cameras), tuple(sorted(illuminants)),
                            {s: order(k) for s, k in stages.items()},
                            tuple(sorted(sensitivities)), tuple(results.models), mean.cells,
                            mean.within, mean.within_2se,
                            {d: validated_degradation(v) for d, v in seen.items()})


__all__ = [
    "EmulationTables",
    "ValidationResults",
    "collect_results",
    "directional_validation",
    "holdout_accuracy",
    "prepare_case",
    "run_validation",
    "validated_cameras",
]
