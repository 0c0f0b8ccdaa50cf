"""Measure what an image colour mapping costs a detector on COCO: ΔmAP ± SE, baseline cached.

A *mapping* is any function from an (H, W, 3) uint8 sRGB image to another: a camera's
emulated colour rendering (:mod:`fidelity.coco.emulation`), a COCO-C corruption
(:mod:`fidelity.coco.corruptions`). :func:`measure_mapping` runs each detector on every image
twice, as the validation does (:mod:`fidelity.coco.validate`): once through the ΔE = 0
baseline (the JPEG round trip with the original quantisation tables and subsampling,
:func:`fidelity.coco.jpeg.roundtrip_jpeg`, no colour change) and once through the mapping and
the same round trip; ΔmAP = 100 × (baseline mAP − mapped mAP) in percentage points (also
relative to the baseline, and ΔAP of person and bicycle), with its standard error, the larger
of the paired image bootstrap (:func:`fidelity.coco.bootstrap.draw_scores`) and the 5-fold
jackknife (:func:`fidelity.coco.loss.loss_estimate`).

Every image's raw detections go to a crash-safe store (:class:`MeasureStore`, default
``$FIDELITY_CACHE/measure`` or ``~/.cache/fidelity/measure``), keyed by the model file
(sha256), the image set (the image folder and the annotation file's sha256), the mapping (a
key that changes with the mapping: see :meth:`fidelity.coco.emulation.Emulation.key`) and the
image id. So the baseline is computed once per (model, image set) and shared by every later
measurement, a repeated measurement of the same mapping costs only the scoring, and a killed
run resumes where it stopped.

Inputs (:func:`resolve_coco_inputs`): images, annotations and detectors come from options;
without them, from the shared data folder (``$FIDELITY_SHARED`` or ``../shared``: its
``coco/val2017``, ``coco/annotations/instances_val2017_subset.json`` and
``models/yolox_nano.onnx``, the fast detector); without either, an error says what to pass.
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fidelity.coco.bootstrap import BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED, draw_scores
from fidelity.coco.detectors import Detector
from fidelity.coco.jpeg import roundtrip_jpeg
from fidelity.coco.loss import score_loss
from fidelity.coco.scoring import (
    FOLDS,
    evaluate_detections,
    load_annotated_images,
    resolve_scorer,
    score_folds,
)
from fidelity.coco.store import ResultsStore, pack_detections, unpack_detections
from fidelity.coco.sweep import ImageCache, ModelSpec
from fidelity.core.errors import InputFileError, InvalidValueError
from fidelity.core.fileio import file_sha256
from fidelity.core.record import record
from fidelity.core.resources import shared_dir

if TYPE_CHECKING:
    from fidelity.coco.sweep import ModelSpec

#: File name of the store in its folder.
STORE_NAME = "measure.sqlite"
#: Mapping key of the ΔE = 0 baseline (JPEG round trip only).
BASELINE_KEY = "baseline"
#: The detector used when none is named: the fastest of the shared models.
DEFAULT_MODEL = "yolox_nano.onnx"
#: Where the shared data folder keeps the images, annotations and models.
SHARED_IMAGES = Path("coco") / "val2017"
SHARED_ANNOTATIONS = Path("coco") / "annotations" / "instances_val2017_subset.json"
SHARED_MODELS = Path("models")

Mapping8 = Callable[[np.ndarray], np.ndarray]


def default_store() -> Path:
    """``$FIDELITY_CACHE/measure`` or ``~/.cache/fidelity/measure``."""
    base = os.environ.get("FIDELITY_CACHE")
    return (Path(base) if base else Path.home() / ".cache" / "fidelity") / "measure"


# --------------------------------------------------------------------------------------------
# Inputs
# --------------------------------------------------------------------------------------------


@record
class CocoInputs:
    """What a measurement runs on: the image folder, the COCO annotation file and the
    detectors (:class:`fidelity.coco.sweep.ModelSpec`, each optionally limited to its first
    N images by id)."""

    images: Path
    annotations: Path
    models: tuple[ModelSpec, ...]


def resolve_coco_inputs(images: str | os.PathLike[str] | None = None,
                        annotations: str | os.PathLike[str] | None = None,
                        models: str | Sequence[str] | None = None, *,
                        what: str = "--measure") -> CocoInputs:
    """The images, annotations and detectors of a measurement: as given, else from the shared
    data folder (:func:`fidelity.core.resources.shared_dir`); an
    :class:`~fidelity.core.errors.InvalidValueError` naming what to pass when neither has them.

    ``models``: ``"a.onnx,b.onnx@250"`` or a sequence of such items.
    """
    shared = shared_dir()
    missing = []
    img = Path(images) if images else (shared / SHARED_IMAGES if shared else None)
    ann = Path(annotations) if annotations else (shared / SHARED_ANNOTATIONS if shared else None)
    if isinstance(models, str):
        items = [m.strip() for m in models.split(",") if m.strip()]
    else:
        items = [str(m) for m in (models or ())]
    if not items and shared is not None:
        items = [str(shared / SHARED_MODELS / DEFAULT_MODEL)]
    if img is None:
        missing.append("--images DIR (COCO images)")
    if ann is None:
        missing.append("--annotations FILE (COCO annotations)")
    if not items:
        missing.append("--models M.onnx (an ONNX detector)")
    if missing:
        raise InvalidValueError(
            f"{what} runs a detector on COCO images: pass {', '.join(missing)}, or set "
            "FIDELITY_SHARED to the shared data folder (coco/val2017, "
            "coco/annotations/instances_val2017_subset.json, models/yolox_nano.onnx)")
    assert img is not None and ann is not None
    specs = tuple(ModelSpec.parse(m) for m in items)
    for s in specs:
        if not s.path.is_file():
            raise InputFileError(f"{s.path}: model file does not exist")
    return CocoInputs(img, ann, specs)


# --------------------------------------------------------------------------------------------
# Store
# --------------------------------------------------------------------------------------------

_SCHEMA = """
CREATE TABLE IF NOT EXISTS mappings (mapping TEXT PRIMARY KEY, description TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS detections (
    model TEXT NOT NULL, dataset TEXT NOT NULL, mapping TEXT NOT NULL, image_id INTEGER NOT NULL,
    n INTEGER NOT NULL, dets BLOB NOT NULL, PRIMARY KEY (model, dataset, mapping, image_id));
"""


class MeasureStore(ResultsStore):
    """The crash-safe cache of raw detections of :func:`measure_mapping` (module docstring).

    Models are registered under ``<stem>@<sha256[:12]>``, so two files of one name never
    share detections.
    """

    store_name = STORE_NAME
    kind = "measurement"
    schema = _SCHEMA
    core_tables = ("meta", "models", "mappings", "detections")

    def describe_mapping(self, mapping: str, description: Mapping[str, Any]) -> None:
        """Record what a mapping key stands for (provenance)."""
        with self.db:
            self.db.execute("INSERT OR REPLACE INTO mappings VALUES (?, ?)",
                            (mapping, json.dumps(dict(description))))

    def mapping_description(self, mapping: str) -> dict[str, Any] | None:
        """What a mapping key stands for, or None."""
        row = self.db.execute("SELECT description FROM mappings WHERE mapping=?",
                              (mapping,)).fetchone()
        return json.loads(row[0]) if row else None

    def stored_images(self, model: str, dataset: str, mapping: str) -> set[int]:
        """Image ids whose detections are stored."""
        return {r[0] for r in self.db.execute(
            "SELECT image_id FROM detections WHERE model=? AND dataset=? AND mapping=?",
            (model, dataset, mapping))}

    def add_detections(self, model: str, dataset: str, mapping: str,
                       rows: Sequence[tuple[int, np.ndarray]]) -> None:
        """Store (image_id, (n, 6) detections) pairs in one transaction."""
        with self.db:
            self.db.executemany(
                "INSERT OR REPLACE INTO detections VALUES (?, ?, ?, ?, ?, ?)",
                [(model, dataset, mapping, int(i), len(d), pack_detections(d)) for i, d in rows])

    def detections(self, model: str, dataset: str, mapping: str,
                   image_ids: Sequence[int]) -> dict[int, np.ndarray]:
        """Stored detections of ``image_ids`` (those stored): image_id -> (n, 6)."""
        want = {int(i) for i in image_ids}
        return {i: unpack_detections(b) for i, b in self.db.execute(
            "SELECT image_id, dets FROM detections WHERE model=? AND dataset=? AND mapping=?",
            (model, dataset, mapping)) if i in want}


def dataset_key(images: str | os.PathLike[str], annotations: str | os.PathLike[str]) -> str:
    """The identity of an image set: the image folder (resolved) and the annotation file's
    sha256, hashed."""
    text = f"{Path(images).resolve()}|{file_sha256(annotations)}"
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]


# --------------------------------------------------------------------------------------------
# Result
# --------------------------------------------------------------------------------------------


@record
class MeasuredLoss:
    """What a mapping cost one detector on ``images`` COCO images (:func:`measure_mapping`).

    Scores are fractions; losses in percentage points (``dmap_relative`` in % of the baseline
    mAP; None when the baseline mAP is 0), each with its standard error (the larger of the
    paired image bootstrap and the 5-fold jackknife; ``*_se``; None with fewer than 2 usable
    draws and folds), all from :func:`fidelity.coco.loss.loss_estimate`.
    ``seconds``: wall time of the measurement; ``inferred``: images run through the detector
    in it (the rest came from the store); ``baseline_cached``: whether the baseline was
    already stored for every image.

    Attributes
    ----------
    model
        The detector's name (``yolox_nano``, ...).
    model_file
        The ONNX model file's name.
    model_sha256
        The model file's sha256 (hex).
    mapping
        The mapping's key in the store.
    images
        COCO images measured, >= 1 (the first N by id).
    baseline_map
        mAP@[.50:.95] of the ΔE = 0 baseline (JPEG round trip only), a fraction in [0, 1].
    map
        mAP@[.50:.95] through the mapping and the same round trip, a fraction in [0, 1].
    dmap_points
        ΔmAP = 100 (baseline_map - map), percentage points (positive: a loss).
    dmap_points_se
        Its standard error, percentage points; None with too few draws and folds.
    dmap_relative
        The loss in percent of the baseline mAP; None when the baseline mAP is 0.
    dmap_relative_se
        Its standard error, percent; None when not estimable.
    dap_person_points
        ΔAP of the person class, percentage points; None when its AP is undefined on the
        images.
    dap_person_points_se
        Its standard error, percentage points; None when not estimable.
    dap_bicycle_points
        ΔAP of the bicycle class, percentage points; None when its AP is undefined on the
        images.
    dap_bicycle_points_se
        Its standard error, percentage points; None when not estimable.
    seconds
        Wall-clock seconds of the measurement, >= 0.
    inferred
        Images run through the detector in it (baseline and mapping; the rest came from the
        store), >= 0.
    baseline_cached
        Whether the baseline was already stored for every image.
    scorer
        The COCO scorer used: ``faster-coco-eval`` or ``pycocotools``.
    settings
        onnxruntime threads and providers, preprocessing, folds, the standard error's method,
        the JPEG round trip, the dataset key, image folder and annotation file.
    """

    model: str
    model_file: str
    model_sha256: str
    mapping: str
    images: int
    baseline_map: float
    map: float
    dmap_points: float
    dmap_points_se: float | None
    dmap_relative: float | None
    dmap_relative_se: float | None
    dap_person_points: float | None
    dap_person_points_se: float | None
    dap_bicycle_points: float | None
    dap_bicycle_points_se: float | None
    seconds: float
    inferred: int
    baseline_cached: bool
    scorer: str
    settings: Mapping[str, Any]

    def loss(self, column: str) -> tuple[float | None, float | None]:
        """(value, SE) of a prediction column (``dmap_points``, ``dmap_relative``,
        ``dap_person_points``, ``dap_bicycle_points``)."""
        return {"dmap_points": (self.dmap_points, self.dmap_points_se),
                "dmap_relative": (self.dmap_relative, self.dmap_relative_se),
                "dap_person_points": (self.dap_person_points, self.dap_person_points_se),
                "dap_bicycle_points": (self.dap_bicycle_points, self.dap_bicycle_points_se),
                }[column]

    def summary(self) -> str:
        """One line: ``measured ΔmAP 0.31 ± 0.14 points (yolox_nano, 1000 images, 38 s)``."""
        se = f" ± {self.dmap_points_se:.2f}" if self.dmap_points_se is not None else ""
        cached = "" if self.inferred else ", all detections from the store"
        rel = "undefined" if self.dmap_relative is None else f"{self.dmap_relative:.2f}"
        return (f"measured ΔmAP {self.dmap_points:.2f}{se} points, "
                f"{rel} % of baseline mAP {100 * self.baseline_map:.2f} "
                f"({self.model}, {self.images} COCO images, {self.seconds:.0f} s{cached})")

    def to_json(self) -> dict[str, Any]:
        """Field names as keys, in field order."""
        return {"model": self.model, "model_file": self.model_file,
                "model_sha256": self.model_sha256, "mapping": self.mapping,
                "images": self.images, "baseline_map": self.baseline_map, "map": self.map,
                "dmap_points": self.dmap_points, "dmap_points_se": self.dmap_points_se,
                "dmap_relative": self.dmap_relative, "dmap_relative_se": self.dmap_relative_se,
                "dap_person_points": self.dap_person_points,
                "dap_person_points_se": self.dap_person_points_se,
                "dap_bicycle_points": self.dap_bicycle_points,
                "dap_bicycle_points_se": self.dap_bicycle_points_se,
                "seconds": self.seconds, "inferred": self.inferred,
                "baseline_cached": self.baseline_cached, "scorer": self.scorer,
                "settings": dict(self.settings)}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> MeasuredLoss:
        """Inverse of :meth:`to_json`."""
        return cls(str(d["model"]), str(d["model_file"]), str(d["model_sha256"]),
                   str(d["mapping"]), int(d["images"]), float(d["baseline_map"]),
                   float(d["map"]), float(d["dmap_points"]), d.get("dmap_points_se"),
                   d.get("dmap_relative"), d.get("dmap_relative_se"),
                   d.get("dap_person_points"), d.get("dap_person_points_se"),
                   d.get("dap_bicycle_points"), d.get("dap_bicycle_points_se"),
                   float(d["seconds"]), int(d["inferred"]), bool(d["baseline_cached"]),
                   str(d.get("scorer", "")), dict(d.get("settings") or {}))


@record
class MeasureRequest:
    """A measurement asked for by ``check --measure``, ``audit --measure`` or ``compare
    --measure``: what to run on (:class:`CocoInputs`), at most ``limit`` images, the store
    (None: :func:`default_store`), onnxruntime threads and provider, progress bars."""

    inputs: CocoInputs
    limit: int | None = None
    store: str | None = None
    threads: int | None = 1
    provider: str = "auto"
    progress: bool = False

    def run(self, mapping: Mapping8, key: str,
            description: Mapping[str, Any] | None = None) -> list[MeasuredLoss]:
        """:func:`measure_mapping` of ``mapping`` with these settings."""
        return measure_mapping(mapping, key, self.inputs, description=description,
                               limit=self.limit, store=self.store, threads=self.threads,
                               provider=self.provider, progress=self.progress)


# --------------------------------------------------------------------------------------------
# Run
# --------------------------------------------------------------------------------------------


def _run_images(store: MeasureStore, det: Any, model: str, dataset: str, mapping: str,
                fn: Mapping8, ids: Sequence[int], cache: Any, *, batch_commit: int,
                progress: bool, label: str) -> int:
    """Run the detector on the images of ``ids`` not yet stored; returns how many ran."""
    from tqdm import tqdm

    have = store.stored_images(model, dataset, mapping)
    todo = [i for i in ids if i not in have]
    batch: list[tuple[int, np.ndarray]] = []
    per_image = getattr(fn, "for_image", None)
    for i in tqdm(todo, desc=label, unit="img", disable=not progress, leave=False,
                  mininterval=2):
        rgb, settings = cache.get(i)
        mapped = per_image(i)(rgb) if per_image is not None else fn(rgb)
        batch.append((i, det(roundtrip_jpeg(mapped, settings))))
        if len(batch) >= batch_commit:
            store.add_detections(model, dataset, mapping, batch)
            batch = []
    if batch:
        store.add_detections(model, dataset, mapping, batch)
    return len(todo)


def _identity(rgb: np.ndarray) -> np.ndarray:
    return rgb


def measure_mapping(mapping: Mapping8, key: str, inputs: CocoInputs, *,
                    description: Mapping[str, Any] | None = None, limit: int | None = None,
                    store: str | os.PathLike[str] | MeasureStore | None = None,
                    threads: int | None = 1, provider: str = "auto", scorer: str = "auto",
                    batch_commit: int = 25, progress: bool = False,
                    log: Callable[[str], None] | None = None) -> list[MeasuredLoss]:
    """Measure the loss ``mapping`` causes for every detector of ``inputs`` (module docstring).

    Parameters
    ----------
    mapping
        (H, W, 3) uint8 sRGB -> (H, W, 3) uint8 sRGB, applied before the JPEG round trip. A
        mapping with a ``for_image(image_id)`` method (a seeded random corruption,
        :class:`fidelity.coco.spatial.SpatialCorruption`) is asked for each image's own
        mapping by the COCO image id.
    key
        The mapping's identity in the store (equal keys must mean equal mappings).
    inputs
        Images, annotations and detectors (:func:`resolve_coco_inputs`).
    description
        JSON-ready description of the mapping, stored with its key; None:
        ``{"mapping": key}``.
    limit
        At most the first N images by id for every detector (a model's own ``@N`` also
        applies).
    store
        The store (folder or object); None: :func:`default_store`.
    threads
        onnxruntime intra-op threads per detector (>= 1; None: onnxruntime's default).
    provider
        onnxruntime execution provider: ``auto`` (CUDA if present, else CPU), ``cpu`` or
        ``cuda``.
    scorer
        COCO scorer: ``auto`` (``faster-coco-eval`` when installed, else ``pycocotools``),
        ``faster-coco-eval`` or ``pycocotools``.
    batch_commit
        Images' detections written to the store per transaction, >= 1.
    progress
        Show progress bars on stderr.
    log
        Called with one line per detector measured (its :meth:`MeasuredLoss.summary`); None:
        no log.

    Returns
    -------
    list of MeasuredLoss
        One per detector, in the order of ``inputs.models``.

    Raises
    ------
    InvalidValueError
        ``key`` is the reserved ``baseline`` key, or the scorer asked for is not installed.
        Exit code 2.
    InputFileError
        Missing or unreadable images, annotation file or model file. Exit code 2.
    """
    if key == BASELINE_KEY:
        raise InvalidValueError(f"mapping key {key!r} is reserved for the baseline")
    say = log or (lambda s: None)
    st = store if isinstance(store, MeasureStore) else MeasureStore(store or default_store())
    st.describe_mapping(key, description or {"mapping": key})
    img_dir, coco, all_ids = load_annotated_images(inputs.images, inputs.annotations)
    dataset = dataset_key(img_dir, inputs.annotations)
    method = resolve_scorer(scorer)
    cache = ImageCache(img_dir, coco)
    out = []
    for spec in inputs.models:
        t0 = time.perf_counter()
        det = Detector(spec.path, threads=threads, provider=provider)
        sha = file_sha256(spec.path)
        # the preprocessing is part of the key: a cache made by a version that prepared images
        # differently is not reused (its detections would differ)
        pre = hashlib.sha256(det.preprocessing.describe().encode()).hexdigest()[:8]
        model = f"{det.name}@{sha[:12]}:{pre}"
        st.register_model(model, spec.path.name, sha, None, det.describe())
        n = min(x for x in (spec.limit, limit, len(all_ids)) if x is not None)
        ids = all_ids[:n]
        ran_base = _run_images(st, det, model, dataset, BASELINE_KEY, _identity, ids, cache,
                               batch_commit=batch_commit, progress=progress,
                               label=f"baseline / {det.name}")
        ran = _run_images(st, det, model, dataset, key, mapping, ids, cache,
                          batch_commit=batch_commit, progress=progress,
                          label=f"{key[:24]} / {det.name}")
        base_d = st.detections(model, dataset, BASELINE_KEY, ids)
        map_d = st.detections(model, dataset, key, ids)
        b = evaluate_detections(coco, base_d, ids, method=method)
        m = evaluate_detections(coco, map_d, ids, method=method)
        db, dm = draw_scores(coco, base_d, ids), draw_scores(coco, map_d, ids)
        bf = score_folds(coco, base_d, ids, FOLDS, method=method)
        mf = score_folds(coco, map_d, ids, FOLDS, method=method)

        scores_b: dict[str, float | None] = {"map": b.map, **b.ap}
        scores_m: dict[str, float | None] = {"map": m.map, **m.ap}
        loss, person, bicycle = (score_loss(k, scores_b, scores_m, bf, mf, db, dm)
                                 for k in ("map", "person", "bicycle"))
        if loss.points is None:  # both mAPs are numbers
            raise ValueError("a measured cell without mAP")
        result = MeasuredLoss(
            model=det.name, model_file=spec.path.name, model_sha256=sha, mapping=key,
            images=len(ids), baseline_map=b.map, map=m.map,
            dmap_points=loss.points, dmap_points_se=loss.points_se,
            dmap_relative=loss.relative, dmap_relative_se=loss.relative_se,
            dap_person_points=person.points, dap_person_points_se=person.points_se,
            dap_bicycle_points=bicycle.points, dap_bicycle_points_se=bicycle.points_se,
            seconds=time.perf_counter() - t0, inferred=ran + ran_base,
            baseline_cached=ran_base == 0, scorer=method,
            settings={"threads": threads, "providers": det.providers,
                      "preprocess": det.preprocessing.describe(), "folds": FOLDS,
                      "standard_error": {"method": loss.se_method,
                                         "draws": BOOTSTRAP_RESAMPLES, "seed": BOOTSTRAP_SEED},
                      "jpeg": "original quantisation tables and subsampling "
                              "(fidelity.coco.jpeg.roundtrip_jpeg)",
                      "dataset": dataset, "images_folder": str(img_dir),
                      "annotations": str(inputs.annotations)})
        say(f"{time.strftime('%H:%M:%S')} {key} / {det.name}: {result.summary()}")
        out.append(result)
    return out


def stderr_log(line: str) -> None:
    """A log line on stderr (for long runs)."""
    print(line, file=sys.stderr, flush=True)


__all__ = [
    "BASELINE_KEY",
    "DEFAULT_MODEL",
    "STORE_NAME",
    "CocoInputs",
    "MeasureRequest",
    "MeasureStore",
    "MeasuredLoss",
    "dataset_key",
    "default_store",
    "measure_mapping",
    "resolve_coco_inputs",
    "stderr_log",
]
