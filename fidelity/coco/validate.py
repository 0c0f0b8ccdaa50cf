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
   image set (image ``i`` of the id-sorted list in fold ``i mod 5``): SE = std(fold ΔmAP)/sqrt(5).

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
import math
import os
import platform
import sys
import time
import tomllib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fidelity.coco.scoring import FOLDS  # interleaved image folds for standard errors
from fidelity.coco.store import ResultsStore, pack_detections, unpack_detections
from fidelity.errors import InputFileError, InvalidValueError
from fidelity.fileio import file_sha256, portable_paths

STORE_NAME = "validation.sqlite"
SUITE_FILE = "suite.toml"
BASELINE = "baseline"
#: Classes compared (``all`` = mAP@[.50:.95] over the 80 COCO classes).
CLASSES: tuple[str, ...] = ("all", "person", "bicycle")
#: Loss columns compared (prediction-table column names).
LOSS_COLUMNS: dict[str, str] = {
    "all": "dmap_points",
    "all-relative": "dmap_relative",
    "person": "dap_person_points",
    "bicycle": "dap_bicycle_points",
}
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
# Chart side: ΔE, error profile, prediction, emulation accuracy
# --------------------------------------------------------------------------------------------


def chart_error_profile(measurement: Any) -> dict[str, Any]:
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
    return {
        "mean_abs_dl": float(comp[0]), "mean_abs_dc": float(comp[1]), "mean_abs_dh": float(comp[2]),
        "share_l": float(share[0]), "share_c": float(share[1]), "share_h": float(share[2]),
        "mean_dl": float(dl.mean()), "mean_dc": float(dc.mean()),
        "contrast_ratio": float(lab[:, 0].std() / ref[:, 0].std()),
        "neutral_cast_ab": [float(cast[0]), float(cast[1])],
        "dominant": ("lightness", "chroma", "hue")[int(np.argmax(comp))],
        "worst_patch": measurement.patch_names[int(np.argmax(de))],
        "worst_patch_delta_e": float(de.max()),
    }


def predictions_for(delta_e: float, baseline_map_percent: float | None,
                    tables: Sequence[str], size: str = "n") -> dict[str, dict[str, Any]]:
    """Predicted losses of every column for each table name: table -> column -> value."""
    from fidelity.prediction.table import predict

    out = {}
    for t in tables:
        p = predict(delta_e, size=size, table=t, baseline_map=baseline_map_percent,
                    transforms=False)
        out[t] = {col: p.columns[col].value for col in LOSS_COLUMNS.values()}
        out[t]["status"] = {col: p.columns[col].status for col in LOSS_COLUMNS.values()}
        out[t]["kind"] = p.table.kind
    return out


def image_delta_e(emu: Any, images: Sequence[np.ndarray]) -> dict[str, float]:
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
    return {"mean": float(v.mean()), "p95": float(np.percentile(v, 95)),
            "images": len(images), "pixel_stride": step}


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
"""


class ValidationStore(ResultsStore):
    """The crash-safe SQLite store of a validation run (module docstring)."""

    store_name = STORE_NAME
    kind = "validation"
    schema = _SCHEMA

    def _model_conflict(self, stored_sha256: str, stored_limit: int | None, sha256: str,
                        limit: int | None) -> str | None:
        """A validation compares cameras on one image set: the image limit must match too."""
        if stored_sha256 != sha256 or stored_limit != limit:
            return "was run from another file or image limit; use a new --store"
        return None

    def case(self, camera: str) -> tuple[str, dict[str, Any]] | None:
        """(key, info) of a camera's chart/prediction/emulation record, or None."""
        row = self.db.execute("SELECT key, info FROM cases WHERE camera=?", (camera,)).fetchone()
        return (row[0], json.loads(row[1])) if row else None

    def set_case(self, camera: str, key: str, info: dict[str, Any]) -> None:
        """Store a camera's record under its identity ``key``."""
        with self.db:
            self.db.execute("INSERT OR REPLACE INTO cases VALUES (?, ?, ?)",
                            (camera, key, json.dumps(info)))

    def cases(self) -> dict[str, dict[str, Any]]:
        """All camera records."""
        return {c: json.loads(i) for c, _, i in self.db.execute("SELECT * FROM cases")}

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
        """Stored detections of a cell: image_id -> (n, 6)."""
        return {i: unpack_detections(b) for i, b in self.db.execute(
            "SELECT image_id, dets FROM detections WHERE model=? AND camera=?", (model, camera))}

    def cell(self, model: str, camera: str) -> dict[str, Any] | None:
        """A finished cell, or None."""
        cur = self.db.execute("SELECT * FROM cells WHERE model=? AND camera=?", (model, camera))
        row = cur.fetchone()
        if row is None:
            return None
        d = {c[0]: v for c, v in zip(cur.description, row, strict=True)}
        d["ap"], d["folds"] = json.loads(d["ap"]), json.loads(d["folds"])
        return d

    def cells(self) -> list[dict[str, Any]]:
        """All finished cells."""
        rows = self.db.execute("SELECT model, camera FROM cells ORDER BY model, camera").fetchall()
        return [c for m, k in rows if (c := self.cell(m, k)) is not None]

    def finish_cell(self, model: str, camera: str, score: Any, folds: list[dict[str, Any]],
                    seconds: float) -> None:
        """Record a finished cell with its full-set score and per-fold scores."""
        with self.db:
            self.db.execute("INSERT OR REPLACE INTO cells VALUES (?,?,?,?,?,?,?,?,?)",
                            (model, camera, score.images, score.map, score.map50,
                             json.dumps(score.ap), json.dumps(folds), seconds,
                             time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())))


def _fold_scores(coco: Any, dets: dict[int, np.ndarray], ids: Sequence[int]) -> list[dict[str, Any]]:
    from fidelity.coco.scoring import score_folds

    return score_folds(coco, dets, ids, FOLDS)


# --------------------------------------------------------------------------------------------
# Run
# --------------------------------------------------------------------------------------------


def prepare_case(case: CameraCase, store: ValidationStore, method: str, training: str,
                 cache: Any, image_ids: Sequence[int]) -> tuple[Any, dict[str, Any]]:
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
    info = {
        "camera": case.name, "file": case.path.name, "sha256": case.sha256,
        "description": emu.camera.description, "illuminant": case.illuminant,
        "chart_delta_e": float(m.mean_delta_e), "chart_max_delta_e": float(m.max_delta_e),
        "profile": chart_error_profile(m),
        "render": {"renderer": render.renderer, "conventions": {
            k: render.conventions[k] for k in ("exposure_gain", "white_balance_gains", "ccm")}},
        "patches": [{k: p[k] for k in ("name", "delta_e", "delta_l", "delta_c", "delta_h", "lab",
                                       "reference_lab", "srgb")} for p in m.to_json()["patches"]],
        "emulation": {**emu.describe(), "accuracy": acc.to_json(),
                      "other_methods": {
                          k: emulation_accuracy(fit_emulation(emu.camera, case.illuminant, k,
                                                              training)).to_json()
                          for k in EMULATION_METHODS if k != method}},
        "image_delta_e": image_delta_e(emu, sample),
        "seconds": time.perf_counter() - t0,
    }
    store.set_case(case.name, key, info)
    return emu, info


def run_validation(cases: Sequence[CameraCase], models: Sequence[Any],
                   images: str | os.PathLike[str], annotations: str | os.PathLike[str],
                   store_dir: str | os.PathLike[str], *, method: str = "root-polynomial",
                   training: str = "colour-science", threads: int | None = 1,
                   provider: str = "auto", batch_commit: int = 25, progress: bool = True,
                   log: Callable[[str], None] | None = None) -> ValidationStore:
    """Run (or resume) the validation; ``models`` are :class:`fidelity.coco.sweep.ModelSpec`.

    Per model the baseline cell runs first, then cameras in the given order; each camera's
    emulation table is built once and used for every model.
    """
    import onnxruntime
    from tqdm import tqdm

    from fidelity.coco.detectors import Detector
    from fidelity.coco.jpeg import roundtrip_jpeg
    from fidelity.coco.scoring import evaluate_detections, load_annotated_images
    from fidelity.coco.sweep import ImageCache

    say = log or (lambda s: print(s, file=sys.stderr, flush=True))
    img_dir, coco, all_ids = load_annotated_images(images, annotations)
    store = ValidationStore(store_dir)
    from fidelity import __version__

    store.set_meta("versions", {"python": platform.python_version(),
                                "onnxruntime": onnxruntime.__version__, "numpy": np.__version__,
                                "fidelity": __version__, "colour": _colour_version()})
    store.set_meta("data", {"images": str(Path(img_dir).resolve()),
                            "annotations": str(Path(annotations).resolve()),
                            "image_count": len(all_ids)})
    store.set_meta("machine", {"platform": platform.platform(), "cpus": os.cpu_count(),
                               "threads": threads, "provider": provider})
    store.set_meta("settings", {"emulation_method": method, "training": training,
                                "folds": FOLDS, "size_class": "n",
                                "jpeg": "original quantisation tables and subsampling "
                                        "(fidelity.coco.jpeg.roundtrip_jpeg), as the COCO sweep"})
    store.set_meta("cameras", [{"camera": c.name, "file": c.path.name,
                                "illuminant": c.illuminant} for c in cases])
    cache = ImageCache(img_dir, coco)
    dets_by_model = []
    for spec in models:
        det = Detector(spec.path, threads=threads, provider=provider)
        ids = all_ids[: spec.limit] if spec.limit else all_ids
        store.register_model(det.name, spec.path.name, file_sha256(spec.path), spec.limit,
                             det.describe())
        dets_by_model.append((det, ids))
    store.set_meta("models_run", [{"model": d.name, "images": len(i)} for d, i in dets_by_model])

    def run_cell(det: Any, ids: Sequence[int], camera: str, fn: Callable[[np.ndarray], np.ndarray]
                 ) -> None:
        if store.cell(det.name, camera):
            return
        t0 = time.perf_counter()
        have = store.stored_images(det.name, camera)
        todo = [i for i in ids if i not in have]
        batch: list[tuple[int, np.ndarray]] = []
        for i in tqdm(todo, desc=f"{camera} / {det.name}", unit="img", disable=not progress,
                      leave=False, mininterval=5):
            rgb, settings = cache.get(i)
            batch.append((i, det(roundtrip_jpeg(fn(rgb), settings))))
            if len(batch) >= batch_commit:
                store.add_detections(det.name, camera, batch)
                batch = []
        if batch:
            store.add_detections(det.name, camera, batch)
        dets = store.detections(det.name, camera)
        score = evaluate_detections(coco, dets, ids)
        folds = _fold_scores(coco, dets, ids)
        dt = time.perf_counter() - t0
        store.finish_cell(det.name, camera, score, folds, dt)
        say(f"{time.strftime('%H:%M:%S')} {camera} / {det.name}: mAP={score.map:.4f} "
            f"person={score.ap.get('person')} images={len(ids)} new={len(todo)} {dt:.1f}s")

    for det, ids in dets_by_model:
        run_cell(det, ids, BASELINE, lambda a: a)
    for case in cases:
        if all(store.cell(d.name, case.name) for d, _ in dets_by_model) and store.case(case.name):
            continue
        emu, info = prepare_case(case, store, method, training, cache, all_ids)
        say(f"{time.strftime('%H:%M:%S')} {case.name} ({case.illuminant}): chart ΔE "
            f"{info['chart_delta_e']:.2f}, emulation chart ΔE00 mean "
            f"{info['emulation']['accuracy']['chart_mean_delta_e']:.2f} max "
            f"{info['emulation']['accuracy']['chart_max_delta_e']:.2f}")
        emu.cube()
        for det, ids in dets_by_model:
            run_cell(det, ids, case.name, emu.apply_uint8)
        del emu
    return store


def _colour_version() -> str:
    import colour

    return str(colour.__version__)


# --------------------------------------------------------------------------------------------
# Results
# --------------------------------------------------------------------------------------------


def _loss(base: float | None, value: float | None) -> float | None:
    if base is None or value is None:
        return None
    return 100.0 * (base - value)


def _se(base_folds: list[dict[str, Any]], folds: list[dict[str, Any]], key: str) -> float | None:
    from fidelity.coco.scoring import paired_standard_error

    return paired_standard_error([b.get(key) for b in base_folds], [f.get(key) for f in folds])


def holdout_accuracy(cases: Sequence[CameraCase], method: str = "root-polynomial"
                     ) -> dict[str, dict[str, Any]]:
    """Out-of-sample emulation accuracy per camera: the mapping fitted on the colour-science
    reflectances *without* the 24 chart patches, checked on the chart
    (:func:`fidelity.coco.emulation.emulation_accuracy`)."""
    from fidelity.coco.emulation import emulation_accuracy, fit_emulation

    return {c.name: emulation_accuracy(fit_emulation(c.path, c.illuminant, method,
                                                     "colour-science-no-chart")).to_json()
            for c in cases}


def collect_results(store: ValidationStore, tables: Sequence[str] | None = None,
                    bound_table: str | None = None,
                    suite: Sequence[CameraCase] | None = None) -> dict[str, Any]:
    """Predicted against measured losses of every finished (camera, model) cell.

    ``tables``: prediction tables to evaluate (default: all available); ``bound_table``: the
    worst-case table whose bound is tested (default :data:`fidelity.prediction.table.DEFAULT_TABLE`).
    Returns a JSON-ready dict with ``rows`` (one per camera and model), ``summary``,
    ``cameras`` (chart and emulation records), ``models`` and provenance. With ``suite`` (the
    camera cases), each stored camera also gets its out-of-sample emulation accuracy
    (:func:`holdout_accuracy`) under ``emulation.holdout``, and stored cameras that are not in
    the suite (renamed or removed camera files) are left out of the results and listed under
    ``summary.not_in_suite``.
    """
    from fidelity.prediction.table import DEFAULT_TABLE, available_tables

    tabs = list(tables) if tables else available_tables()
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
            cases[name].setdefault("emulation", {})["holdout"] = acc
    cells = {(c["model"], c["camera"]): c for c in store.cells()}
    models = store.models()
    rows = []
    for (model, camera), c in sorted(cells.items()):
        if camera == BASELINE or camera not in cases:
            continue
        b = cells.get((model, BASELINE))
        if b is None:
            continue
        info = cases[camera]
        measured = {
            "dmap_points": _loss(b["map"], c["map"]),
            "dmap_relative": 100.0 * (b["map"] - c["map"]) / b["map"] if b["map"] else None,
            "dap_person_points": _loss(b["ap"].get("person"), c["ap"].get("person")),
            "dap_bicycle_points": _loss(b["ap"].get("bicycle"), c["ap"].get("bicycle")),
        }
        se = {"dmap_points": _se(b["folds"], c["folds"], "map"),
              "dap_person_points": _se(b["folds"], c["folds"], "person"),
              "dap_bicycle_points": _se(b["folds"], c["folds"], "bicycle")}
        se["dmap_relative"] = (None if se["dmap_points"] is None else
                               100.0 * se["dmap_points"] / (100.0 * b["map"]))
        pred = predictions_for(info["chart_delta_e"], 100.0 * b["map"], tabs)
        checks = {}
        for cls, col in LOSS_COLUMNS.items():
            p, m = pred[bound][col], measured[col]
            if p is None or m is None:
                checks[cls] = {"predicted": p, "measured": m, "within": None}
                continue
            s = se[col]
            checks[cls] = {"predicted": p, "measured": m, "se": s, "within": m <= p,
                           "excess": m - p,
                           "within_2se": (m - 2 * s) <= p if s is not None else None,
                           "status": pred[bound]["status"][col]}
        rows.append({"camera": camera, "model": model, "illuminant": info["illuminant"],
                     "chart_delta_e": info["chart_delta_e"], "images": c["images"],
                     "baseline_map": b["map"], "map": c["map"],
                     "baseline_ap": {k: b["ap"].get(k) for k in ("person", "bicycle")},
                     "ap": {k: c["ap"].get(k) for k in ("person", "bicycle")},
                     "measured": measured, "se": se, "predicted": pred, "bound": checks})
    summary: dict[str, Any] = {"bound_table": bound, "tables": tabs,
                               "not_in_suite": not_in_suite}
    for cls in LOSS_COLUMNS:
        judged = [r for r in rows if r["bound"][cls]["within"] is not None]
        ok = [r for r in judged if r["bound"][cls]["within"]]
        ok2 = [r for r in judged if r["bound"][cls].get("within_2se")]
        cams = sorted({r["camera"] for r in judged})
        cams_ok = [k for k in cams if all(r["bound"][cls]["within"] for r in judged
                                          if r["camera"] == k)]
        summary[cls] = {"cells": len(judged), "within": len(ok), "within_2se": len(ok2),
                        "cameras": len(cams), "cameras_within": len(cams_ok),
                        "share_cameras_within": len(cams_ok) / len(cams) if cams else None,
                        "failures": [(r["camera"], r["model"]) for r in judged
                                     if not r["bound"][cls]["within"]]}
    return {"rows": rows, "summary": summary, "cameras": cases, "models": models,
            "baselines": {m: cells[(m, BASELINE)] for m in models if (m, BASELINE) in cells},
            "meta": store.meta()}


# --------------------------------------------------------------------------------------------
# Report
# --------------------------------------------------------------------------------------------

_CLASS_TITLES = {"all": "mAP@[.50:.95] (all classes)", "person": "AP person",
                 "bicycle": "AP bicycle", "all-relative": "mAP relative to baseline"}


def _fmt(v: float | None, nd: int = 2) -> str:
    return "–" if v is None else f"{v:.{nd}f}"


def _spearman(x: Sequence[float], y: Sequence[float]) -> float | None:
    """Spearman rank correlation (scipy.stats.spearmanr); None for fewer than 3 pairs."""
    if len(x) < 3:
        return None
    from scipy.stats import spearmanr

    r = spearmanr(x, y).statistic
    return None if not np.isfinite(r) else float(r)


def failure_reason(row: dict[str, Any], cls: str, camera: dict[str, Any]) -> str:
    """One-paragraph, data-derived explanation of a bound failure (for the report).

    Combines: the excess over the bound in units of the measurement's standard error; where on
    the table the prediction came from (status); the direction of the chart error (shares of
    |ΔL'|, |ΔC'|, |ΔH'|, signed mean ΔL' and ΔC', lightness contrast ratio, neutral cast); and
    the image-level ΔE00 of the emulation compared with the chart ΔE.
    """
    b = row["bound"][cls]
    prof = camera["profile"]
    parts = [f"measured {b['measured']:.2f} > predicted {b['predicted']:.2f} "
             f"(excess {b['excess']:.2f}"]
    se = b.get("se")
    if se:
        parts[0] += f", {b['excess'] / se:.1f} SE; SE {se:.2f})"
        parts.append("inside sampling noise (excess < 2 SE)" if b["excess"] < 2 * se else
                     "larger than the sampling noise (excess >= 2 SE)")
    else:
        parts[0] += ")"
    if b.get("status") == "below-range":
        parts.append("the chart ΔE lies below the table's first point, so the bound there is the "
                     "first point's value")
    parts.append(f"chart error mostly {prof['dominant']} (|ΔL'| {prof['share_l']:.0%}, "
                 f"|ΔC'| {prof['share_c']:.0%}, |ΔH'| {prof['share_h']:.0%}; mean ΔL' "
                 f"{prof['mean_dl']:+.1f}, mean ΔC' {prof['mean_dc']:+.1f}, contrast ratio "
                 f"{prof['contrast_ratio']:.2f}, neutral cast a*,b* "
                 f"{prof['neutral_cast_ab'][0]:+.1f},{prof['neutral_cast_ab'][1]:+.1f})")
    ide = camera.get("image_delta_e", {})
    if ide:
        parts.append(f"on photos the emulation moves colours by ΔE00 {ide['mean']:.1f} on average "
                     f"(p95 {ide['p95']:.1f}) against chart ΔE {camera['chart_delta_e']:.1f}")
    return "; ".join(parts) + "."


def _plain_ticks(ax: Any) -> None:
    """Symlog axes labelled with plain numbers (0.5, 1, 10) instead of powers of ten."""
    from matplotlib.ticker import FuncFormatter, SymmetricalLogLocator

    for axis in (ax.xaxis, ax.yaxis):
        if axis.get_scale() == "symlog":
            axis.set_major_locator(SymmetricalLogLocator(base=10, linthresh=1.0,
                                                         subs=[1.0, 2.0, 5.0]))
            axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))


def _plot_scatter(rows: list[dict[str, Any]], table: str, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    classes = ("all", "person", "bicycle")
    fig, axes = plt.subplots(1, 3, figsize=(15, 5))
    models = sorted({r["model"] for r in rows})
    markers = dict(zip(models, "osD^v", strict=False))
    for ax, cls in zip(axes, classes, strict=True):
        col = LOSS_COLUMNS[cls]
        lo, hi = 0.0, 1.0
        for m in models:
            pts = [(r["predicted"][table][col], r["measured"][col], r["se"][col] or 0.0)
                   for r in rows if r["model"] == m and r["predicted"][table][col] is not None
                   and r["measured"][col] is not None]
            if not pts:
                continue
            p, y, s = (np.array(v) for v in zip(*pts, strict=True))
            ax.errorbar(p, y, yerr=2 * s, fmt=markers[m], ms=5, alpha=0.8, capsize=2,
                        label=f"{m} (±2 SE)")
            lo, hi = min(lo, y.min() - 2 * s.max(), p.min()), max(hi, y.max() + 2 * s.max(),
                                                                 p.max())
        ax.plot([lo, hi], [lo, hi], "k--", lw=1, label="identity (measured = predicted)")
        ax.fill_between([lo, hi], [lo, hi], [lo, lo], color="tab:green", alpha=0.06,
                        label="bound holds")
        ax.set_xscale("symlog", linthresh=1.0)
        ax.set_yscale("symlog", linthresh=1.0)
        _plain_ticks(ax)
        ax.set_xlabel(f"predicted Δ{_CLASS_TITLES[cls]} (points, {table})")
        ax.set_ylabel("measured loss (points)")
        ax.set_title(_CLASS_TITLES[cls])
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot_vs_delta_e(rows: list[dict[str, Any]], tables: Sequence[str], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fidelity.prediction.table import predict_curve

    classes = ("all", "person", "bicycle")
    fig, axes = plt.subplots(1, 3, figsize=(15, 5))
    models = sorted({r["model"] for r in rows})
    xmax = max([r["chart_delta_e"] for r in rows] + [6.0]) * 1.05
    grid = np.linspace(0, xmax, 300)
    for ax, cls in zip(axes, classes, strict=True):
        col = LOSS_COLUMNS[cls]
        for m, mk in zip(models, "osD^v", strict=False):
            pts = [(r["chart_delta_e"], r["measured"][col], r["se"][col] or 0.0) for r in rows
                   if r["model"] == m and r["measured"][col] is not None]
            if pts:
                x, y, s = (np.array(v) for v in zip(*pts, strict=True))
                ax.errorbar(x, y, yerr=2 * s, fmt=mk, ms=5, alpha=0.8, capsize=2,
                            label=f"measured, {m}")
        for t, ls in zip(tables, ("-", "--", ":", "-."), strict=False):
            try:
                y = predict_curve(grid, col, size="n", table=t)
            except Exception:  # noqa: BLE001 - a table without this column is skipped
                continue
            if np.all(np.isnan(y)):
                continue
            ax.plot(grid, y, ls, color="k", lw=1.2, label=f"worst case, {t}")
        ax.axhline(0, color="grey", lw=0.5)
        ax.set_yscale("symlog", linthresh=1.0)
        _plain_ticks(ax)
        ax.set_xlabel("chart ΔE00 of the camera (mean over 24 patches)")
        ax.set_ylabel(f"loss of {_CLASS_TITLES[cls]} (points)")
        ax.set_title(_CLASS_TITLES[cls])
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot_emulation(cameras: dict[str, dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = sorted(cameras, key=lambda k: cameras[k]["chart_delta_e"])
    fig, ax = plt.subplots(figsize=(12, 4.5))
    x = np.arange(len(names))
    acc = [cameras[n]["emulation"]["accuracy"] for n in names]
    ax.bar(x - 0.2, [a["chart_mean_delta_e"] for a in acc], 0.4, label="mean ΔE00 (chart)")
    ax.bar(x + 0.2, [a["chart_max_delta_e"] for a in acc], 0.4, label="max ΔE00 (chart)")
    ax.set_xticks(x, names, rotation=75, ha="right", fontsize=7)
    ax.set_ylabel("ΔE00 emulated vs camera")
    ax.set_title("Emulation accuracy: fitted mapping applied to the 8-bit reference chart vs the "
                 "camera's rendered chart")
    ax.legend()
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def report_markdown(results: dict[str, Any], figures: dict[str, str],
                    notes: str | None = None) -> str:
    """The Markdown report (see :func:`write_report`); ``notes`` (Markdown) is included as the
    "Analysis" section."""
    rows, summ, cams, meta = (results["rows"], results["summary"], results["cameras"],
                              results["meta"])
    bound = summ["bound_table"]
    models = results["models"]
    lines: list[str] = []
    add = lines.append
    add("# Validation: predicted against measured detection loss for realistic camera models\n")
    add("Generated by `fidelity validate` (fidelity/validate.py) from the results store; every "
        "number below is computed from stored detections and chart renders.\n")
    add("## What was run\n")
    data = portable_paths(meta.get("data", {}))
    add(f"- Images: COCO val2017 subset at `{data.get('images')}` "
        f"({data.get('image_count')} annotated images), annotations `{data.get('annotations')}`.")
    for m, info in sorted(models.items()):
        n = info["limit_images"] or data.get("image_count")
        add(f"- Model `{m}` (`{info['file']}`, sha256 {info['sha256'][:16]}…): first {n} images by "
            f"id; layout {info['settings'].get('layout')}, input "
            f"{info['settings'].get('input_size')}, conventions "
            f"{info['settings'].get('conventions')}, threads {info['settings'].get('threads')}.")
    add(f"- Cameras: {len(cams)} camera files from `cameras/` (listed below with their scene "
        "illuminants); chart rendered in closed form; ΔE = mean CIEDE2000 over the 24 patches "
        "against the scene-consistent reference.")
    gone = results["summary"].get("not_in_suite")
    if gone:
        add(f"- Left out: {len(gone)} camera(s) in the store but not in the suite given "
            f"(renamed or removed camera files): {', '.join(gone)}.")
    st = meta.get("settings", {})
    add(f"- Emulation: `{st.get('emulation_method')}` fitted on `{st.get('training')}` "
        "reflectances (chart + colour-science spectral data); JPEG: "
        f"{st.get('jpeg')}. ΔE = 0 baseline: the same round trip without colour change.")
    add(f"- Prediction: `fidelity.prediction.table.predict(chart ΔE, size='n', baseline_map=...)` with "
        f"tables {', '.join(f'`{t}`' for t in summ['tables'])}; the bound tested is `{bound}`.")
    add(f"- Standard errors: {FOLDS} interleaved image folds, SE = std(fold loss)/√{FOLDS}.")
    add(f"- Versions: {meta.get('versions')}; machine: {meta.get('machine')}.")
    finished = sorted({r['camera'] for r in rows})
    add(f"- Finished: {len(rows)} (camera, model) cells, {len(finished)} of {len(cams)} cameras "
        "with at least one model.\n")

    if notes:
        add("## Analysis\n")
        add(notes.strip() + "\n")
    add(f"## Does the worst-case table (`{bound}`) bound the measured loss?\n")
    add("| class | cells within bound | within bound up to 2 SE | cameras within bound (all models) | share |")
    add("|---|---|---|---|---|")
    for cls in LOSS_COLUMNS:
        s = summ[cls]
        share = "–" if s["share_cameras_within"] is None else f"{100 * s['share_cameras_within']:.0f} %"
        add(f"| {cls} | {s['within']}/{s['cells']} | {s['within_2se']}/{s['cells']} | "
            f"{s['cameras_within']}/{s['cameras']} | {share} |")
    add("")
    for t in summ["tables"]:
        xs = [(r["predicted"][t]["dmap_points"], r["measured"]["dmap_points"]) for r in rows
              if r["predicted"][t]["dmap_points"] is not None]
        if xs:
            p, m = zip(*xs, strict=True)
            err = np.array(m) - np.array(p)
            add(f"- `{t}` ({rows[0]['predicted'][t]['kind']}): mAP measured − predicted: median "
                f"{np.median(err):+.2f} points, max {err.max():+.2f}; Spearman ρ(predicted, "
                f"measured) = {_fmt(_spearman(p, m))}; within for "
                f"{int(np.sum(err <= 0))}/{len(err)} cells.")
    de = [r["chart_delta_e"] for r in rows]
    loss = [r["measured"]["dmap_points"] for r in rows]
    add(f"- Spearman ρ(chart ΔE, measured ΔmAP) = {_fmt(_spearman(de, loss))}; ρ(photo ΔE00 of "
        "the emulation on COCO images, measured ΔmAP) = "
        f"{_fmt(_spearman([cams[r['camera']].get('image_delta_e', {}).get('mean', np.nan) for r in rows], loss))}"
        " (all cells, both models).")
    for m in sorted({r["model"] for r in rows}):
        mr = [r for r in rows if r["model"] == m]
        add(f"  - `{m}`: ρ(chart ΔE, ΔmAP) = "
            f"{_fmt(_spearman([r['chart_delta_e'] for r in mr], [r['measured']['dmap_points'] for r in mr]))}"
            f" over {len(mr)} cameras; largest measured ΔmAP "
            f"{max(r['measured']['dmap_points'] for r in mr):.2f} points.")
    add("")

    for key, title in (("scatter", "Predicted against measured (identity line dashed)"),
                       ("vs_delta_e", "Measured loss against chart ΔE with the worst-case curves"),
                       ("emulation", "Emulation accuracy")):
        for f in figures.get(key, "").split(";"):
            if f:
                add(f"### {title}\n\n![{title}]({f})\n")

    add("## Every case where the bound fails\n")
    any_fail = False
    for cls in ("all", "all-relative", "person", "bicycle"):
        fails = [r for r in rows if r["bound"][cls]["within"] is False]
        if not fails:
            continue
        any_fail = True
        add(f"### {_CLASS_TITLES[cls]}\n")
        for r in sorted(fails, key=lambda r: -r["bound"][cls]["excess"]):
            add(f"- **{r['camera']}** / {r['model']} ({r['illuminant']}, chart ΔE "
                f"{r['chart_delta_e']:.2f}): {failure_reason(r, cls, cams[r['camera']])}")
        add("")
    if not any_fail:
        add("None: every finished cell is within the bound.\n")

    add("## Per camera\n")
    add("Losses in percentage points (positive = worse than the baseline), measured ± SE; "
        f"predicted = `{bound}`.\n")
    add("| camera | illuminant | chart ΔE | dominant error (L/C/H share) | contrast | photo ΔE00 | "
        "model | ΔmAP meas. | ΔmAP pred. | Δperson meas. | Δperson pred. | Δbicycle meas. | "
        "Δbicycle pred. |")
    add("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in sorted(rows, key=lambda r: (r["chart_delta_e"], r["model"])):
        c = cams[r["camera"]]
        pr = c["profile"]
        b = r["bound"]

        def cell(k: str, b: dict[str, Any] = b) -> str:
            v = b[k]
            if v["measured"] is None:
                return "–"
            s = f"{v['measured']:.2f}" + (f" ± {v['se']:.2f}" if v.get("se") else "")
            return f"**{s}**" if v["within"] is False else s

        add(f"| {r['camera']} | {r['illuminant']} | {r['chart_delta_e']:.2f} | {pr['dominant']} "
            f"({pr['share_l']:.2f}/{pr['share_c']:.2f}/{pr['share_h']:.2f}) | "
            f"{pr['contrast_ratio']:.2f} | {_fmt(c.get('image_delta_e', {}).get('mean'), 1)} | "
            f"{r['model']} | {cell('all')} | {_fmt(b['all']['predicted'])} | {cell('person')} | "
            f"{_fmt(b['person']['predicted'])} | {cell('bicycle')} | "
            f"{_fmt(b['bicycle']['predicted'])} |")
    add("\nBold: measured loss above the worst-case prediction.\n")
    other = [t for t in summ["tables"] if t != bound]
    if other:
        add("Other tables' predictions of ΔmAP (points):\n")
        add("| camera | model | chart ΔE | measured | " + " | ".join(other) + " |")
        add("|---|---|---|---|" + "---|" * len(other))
        for r in sorted(rows, key=lambda r: (r["chart_delta_e"], r["model"])):
            add(f"| {r['camera']} | {r['model']} | {r['chart_delta_e']:.2f} | "
                f"{_fmt(r['measured']['dmap_points'])} | "
                + " | ".join(_fmt(r["predicted"][t]["dmap_points"]) for t in other) + " |")
        add("")

    add("## Emulation accuracy\n")
    add("The fitted mapping is applied to the reference chart as an 8-bit image (the same 256³ "
        "table used on COCO) and compared with the camera's own rendered chart (CIEDE2000 per "
        "patch). Training: mean and 95th percentile over all training colours (in-sample). "
        "Chart ΔE columns: the camera's chart ΔE and the emulated chart's, both against the "
        "reference.\n")
    add("Held out: the same method fitted without the 24 chart spectra, checked on the chart "
        "(out of sample).\n")
    add("| camera | illuminant | chart ΔE camera | chart ΔE emulated | chart mean | chart max "
        "(patch) | held-out chart mean / max | training mean | training p95 | "
        "other method chart mean / max |")
    add("|---|---|---|---|---|---|---|---|---|---|")
    accs = []
    for name in sorted(cams, key=lambda k: cams[k]["chart_delta_e"]):
        c = cams[name]
        a = c["emulation"]["accuracy"]
        accs.append(a)
        h = c["emulation"].get("holdout")
        hold = "–" if not h else f"{h['chart_mean_delta_e']:.2f} / {h['chart_max_delta_e']:.2f}"
        oth = "; ".join(f"{k}: {v['chart_mean_delta_e']:.2f} / {v['chart_max_delta_e']:.2f}"
                        for k, v in c["emulation"].get("other_methods", {}).items())
        add(f"| {name} | {c['illuminant']} | {a['camera_chart_delta_e']:.2f} | "
            f"{a['emulated_chart_delta_e']:.2f} | {a['chart_mean_delta_e']:.2f} | "
            f"{a['chart_max_delta_e']:.2f} ({a['chart_worst_patch']}) | {hold} | "
            f"{a['training_mean_delta_e']:.2f} | {a['training_p95_delta_e']:.2f} | {oth} |")
    if accs:
        means = np.array([a["chart_mean_delta_e"] for a in accs])
        maxes = np.array([a["chart_max_delta_e"] for a in accs])
        gap = np.array([abs(a["emulated_chart_delta_e"] - a["camera_chart_delta_e"]) for a in accs])
        add(f"\nOver {len(accs)} cameras: chart mean ΔE00 (emulated vs camera) at most "
            f"{means.max():.2f} (median {np.median(means):.2f}); worst single patch "
            f"{maxes.max():.2f}; the emulated chart's ΔE differs from the camera's by at most "
            f"{gap.max():.2f}.")
        hs = [cams[n]["emulation"]["holdout"] for n in cams if cams[n]["emulation"].get("holdout")]
        if hs:
            hm = np.array([h["chart_mean_delta_e"] for h in hs])
            add(f"Held out (chart spectra not in the fit): chart mean ΔE00 at most {hm.max():.2f} "
                f"(median {np.median(hm):.2f}); worst single patch "
                f"{max(h['chart_max_delta_e'] for h in hs):.2f}.")
        add("")

    add("## Cameras\n")
    add("| camera | illuminant | description |")
    add("|---|---|---|")
    for name in sorted(cams):
        add(f"| {name} | {cams[name]['illuminant']} | {cams[name]['description']} |")
    add("")
    add("## Baselines (ΔE = 0: JPEG round trip only)\n")
    for m, b in sorted(results["baselines"].items()):
        add(f"- `{m}`: mAP {b['map']:.4f}, AP50 {b['map50']:.4f}, person "
            f"{_fmt(b['ap'].get('person'), 4)}, bicycle {_fmt(b['ap'].get('bicycle'), 4)} on "
            f"{b['images']} images.")
    add("")
    return "\n".join(lines)


def write_report(results: dict[str, Any], out_dir: str | os.PathLike[str],
                 notes: str | None = None) -> list[Path]:
    """Write ``validation.md``, ``validation.html``, ``validation.json`` and PNG plots.

    Plots: predicted vs measured with the identity line per class (all, person, bicycle), one
    figure per prediction table; measured loss against chart ΔE with the tables' worst-case
    curves; emulation accuracy per camera. Files are written atomically.
    """
    from fidelity.fileio import write_bytes_atomic, write_json_atomic, write_text_atomic

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rows = results["rows"]
    figures: dict[str, str] = {}
    written: list[Path] = []

    def png(name: str, fn: Callable[[Path], None]) -> str:
        import tempfile

        with tempfile.TemporaryDirectory() as tmp:
            p = Path(tmp) / name
            fn(p)
            written.append(write_bytes_atomic(out / name, p.read_bytes()))
        return name

    if rows:
        bound = results["summary"]["bound_table"]
        order = [bound] + [t for t in results["summary"]["tables"] if t != bound]
        figures["scatter"] = ";".join(
            png(f"predicted-vs-measured-{t}.png", lambda p, t=t: _plot_scatter(rows, t, p))
            for t in order)
        figures["vs_delta_e"] = png("loss-vs-chart-delta-e.png",
                                    lambda p: _plot_vs_delta_e(rows, order, p))
    if results["cameras"]:
        figures["emulation"] = png("emulation-accuracy.png",
                                   lambda p: _plot_emulation(results["cameras"], p))
    md = report_markdown(results, figures, notes)
    written.append(write_text_atomic(out / "validation.md", md))
    written.append(write_text_atomic(out / "validation.html", _markdown_to_html(md)))
    written.append(write_json_atomic(out / "validation.json", _json_safe(results)))
    return written


def _json_safe(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_json_safe(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, np.generic):
        return _json_safe(obj.item())
    return obj


def _markdown_to_html(md: str) -> str:
    """Minimal Markdown -> HTML for this report: headings, lists, pipe tables, images, bold,
    inline code, fenced code blocks. (No external dependency; the report's Markdown is generated, not free-form.)"""
    import html
    import re

    def inline(s: str) -> str:
        s = html.escape(s)
        s = re.sub(r"!\[([^\]]*)\]\(([^)]+)\)", r'<img alt="\1" src="\2" style="max-width:100%">', s)
        s = re.sub(r"\*\*([^*]+)\*\*", r"<b>\1</b>", s)
        s = re.sub(r"(?<![*\w])\*([^*\s][^*]*)\*(?![*\w])", r"<i>\1</i>", s)
        return re.sub(r"`([^`]+)`", r"<code>\1</code>", s)

    out = ["<!DOCTYPE html><html><head><meta charset='utf-8'><title>fidelity validation</title>"
           "<style>body{font-family:sans-serif;max-width:1400px;margin:2em auto;padding:0 1em}"
           "table{border-collapse:collapse;font-size:12px}td,th{border:1px solid #ccc;"
           "padding:2px 6px}th{background:#eee}code{background:#f4f4f4}</style></head><body>"]
    in_list = in_table = in_code = False
    prev_blank = True
    for line in md.splitlines():
        if line.startswith("```"):
            out.append("</pre>" if in_code else "<pre>")
            in_code = not in_code
            continue
        if in_code:
            out.append(html.escape(line))
            continue
        if line.startswith("  - "):  # one nesting level is shown as a plain item
            line = line[2:]
        if in_list and not line.startswith("- "):
            out.append("</ul>")
            in_list = False
        if in_table and not line.startswith("|"):
            out.append("</table>")
            in_table = False
        if line.startswith("#"):
            level = len(line) - len(line.lstrip("#"))
            out.append(f"<h{level}>{inline(line[level:].strip())}</h{level}>")
        elif line.startswith("- "):
            if not in_list:
                out.append("<ul>")
                in_list = True
            out.append(f"<li>{inline(line[2:])}</li>")
        elif line.startswith("|"):
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if all(set(c) <= {"-", ":"} for c in cells):
                continue
            tag = "th" if not in_table else "td"
            if not in_table:
                out.append("<table>")
                in_table = True
            out.append("<tr>" + "".join(f"<{tag}>{inline(c)}</{tag}>" for c in cells) + "</tr>")
        elif line.strip():
            if out[-1].endswith("</p>") and not prev_blank:  # continue the paragraph
                out[-1] = out[-1][:-4] + " " + inline(line) + "</p>"
            else:
                out.append(f"<p>{inline(line)}</p>")
        prev_blank = not line.strip()
    if in_list:
        out.append("</ul>")
    if in_table:
        out.append("</table>")
    out.append("</body></html>")
    return "\n".join(out) + "\n"


__all__ = [
    "BASELINE",
    "CLASSES",
    "FOLDS",
    "LOSS_COLUMNS",
    "CameraCase",
    "ValidationStore",
    "chart_error_profile",
    "collect_results",
    "default_store",
    "holdout_accuracy",
    "image_delta_e",
    "load_suite",
    "predictions_for",
    "prepare_case",
    "run_validation",
    "write_report",
]

