"""Validate the prediction on realistic camera models: predicted against measured ΔmAP.

For every camera file of a suite (:func:`load_suite`):

1. **Predict.** Render the chart (:func:`fidelity.render.render_chart`, closed form) under the
   test case's illuminant, take the chart ΔE (mean CIEDE2000 over the 24 patches) and predict
   the detection loss with every prediction table (:func:`fidelity.prediction.predict`,
   detector size ``n``; the baseline mAP of the detector resolves the paper's points-vs-relative
   ambiguity conservatively).
2. **Measure.** Fit the camera's colour rendering (:func:`fidelity.emulation.fit_emulation`),
   apply it to every COCO image, and run the detectors on the result after the same JPEG round
   trip as the COCO sweep (original quantisation tables and subsampling,
   :func:`fidelity.jpeg.roundtrip_jpeg`); ΔmAP is measured against the ΔE = 0 baseline (the
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

import hashlib
import json
import math
import os
import platform
import sqlite3
import sys
import time
import tomllib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fidelity.errors import InputFileError, InvalidValueError

STORE_NAME = "validation.sqlite"
SUITE_FILE = "suite.toml"
BASELINE = "baseline"
#: Number of interleaved image folds for the standard error of a measured loss.
FOLDS: int = 5
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
    from fidelity.camera import read_camera_file
    from fidelity.spectral import load_illuminant

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
        cases.append(CameraCase(p.stem, p, ill, hashlib.sha256(p.read_bytes()).hexdigest()))
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
    from fidelity.prediction import predict

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
    from fidelity.colorimetry import delta_e_2000, srgb_to_lab

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
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS models (
    model TEXT PRIMARY KEY, file TEXT, sha256 TEXT, limit_images INTEGER, settings TEXT);
CREATE TABLE IF NOT EXISTS cases (camera TEXT PRIMARY KEY, key TEXT NOT NULL, info TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS cells (
    model TEXT NOT NULL, camera TEXT NOT NULL, images INTEGER, map REAL, map50 REAL,
    ap TEXT, folds TEXT, seconds REAL, finished TEXT, PRIMARY KEY (model, camera));
CREATE TABLE IF NOT EXISTS detections (
    model TEXT NOT NULL, camera TEXT NOT NULL, image_id INTEGER NOT NULL, n INTEGER NOT NULL,
    dets BLOB NOT NULL, PRIMARY KEY (model, camera, image_id));
"""


class ValidationStore:
    """The crash-safe SQLite store of a validation run (module docstring)."""

    def __init__(self, folder: str | os.PathLike[str], *, create: bool = True) -> None:
        self.folder = Path(folder)
        self.path = self.folder / STORE_NAME
        if not create and not self.path.is_file():
            raise InputFileError(f"{self.folder}: no validation store ({STORE_NAME}) there")
        self.folder.mkdir(parents=True, exist_ok=True)
        self.db = sqlite3.connect(str(self.path), timeout=60)
        self.db.execute("PRAGMA journal_mode=WAL")
        self.db.execute("PRAGMA synchronous=FULL")
        self.db.executescript(_SCHEMA)
        self.db.commit()

    def close(self) -> None:
        """Close the connection."""
        self.db.close()

    def set_meta(self, key: str, value: Any) -> None:
        """Store a JSON-serialisable provenance value."""
        with self.db:
            self.db.execute("INSERT OR REPLACE INTO meta VALUES (?, ?)", (key, json.dumps(value)))

    def meta(self) -> dict[str, Any]:
        """All provenance values."""
        return {k: json.loads(v) for k, v in self.db.execute("SELECT key, value FROM meta")}

    def register_model(self, model: str, file: str, sha256: str, limit: int | None,
                       settings: dict[str, Any]) -> None:
        """Record a model; a different file under the same name is an error."""
        row = self.db.execute("SELECT sha256, limit_images FROM models WHERE model=?",
                              (model,)).fetchone()
        if row and (row[0] != sha256 or row[1] != limit):
            raise InvalidValueError(f"store {self.path}: model {model!r} was run from another "
                                    f"file or image limit; use a new --store")
        with self.db:
            self.db.execute("INSERT OR REPLACE INTO models VALUES (?, ?, ?, ?, ?)",
                            (model, file, sha256, limit, json.dumps(settings)))

    def models(self) -> dict[str, dict[str, Any]]:
        """Registered models: name -> file, sha256, limit_images, settings."""
        return {m: {"file": f, "sha256": s, "limit_images": lim, "settings": json.loads(st)}
                for m, f, s, lim, st in self.db.execute("SELECT * FROM models")}

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
        from fidelity.sweep import pack_detections

        with self.db:
            self.db.executemany("INSERT OR REPLACE INTO detections VALUES (?, ?, ?, ?, ?)",
                                [(model, camera, int(i), len(d), pack_detections(d))
                                 for i, d in rows])

    def detections(self, model: str, camera: str) -> dict[int, np.ndarray]:
        """Stored detections of a cell: image_id -> (n, 6)."""
        from fidelity.sweep import unpack_detections

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
    from fidelity.cocoeval import evaluate_detections

    out = []
    for k in range(FOLDS):
        fold = list(ids[k::FOLDS])
        s = evaluate_detections(coco, dets, fold)
        out.append({"map": s.map, "person": s.ap.get("person"), "bicycle": s.ap.get("bicycle"),
                    "images": len(fold)})
    return out


# --------------------------------------------------------------------------------------------
# Run
# --------------------------------------------------------------------------------------------


def prepare_case(case: CameraCase, store: ValidationStore, method: str, training: str,
                 cache: Any, image_ids: Sequence[int]) -> tuple[Any, dict[str, Any]]:
    """Render, measure, fit the emulation and check it; the record is stored (resumable)."""
    from fidelity.emulation import EMULATION_METHODS, emulation_accuracy, fit_emulation
    from fidelity.render import render_chart

    key = json.dumps({"sha256": case.sha256, "illuminant": case.illuminant, "method": method,
                      "training": training})
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
                                       "reference_lab", "srgb")} for p in m.to_dict()["patches"]],
        "emulation": {**emu.describe(), "accuracy": acc.to_dict(),
                      "other_methods": {
                          k: emulation_accuracy(fit_emulation(emu.camera, case.illuminant, k,
                                                              training)).to_dict()
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
    """Run (or resume) the validation; ``models`` are :class:`fidelity.sweep.ModelSpec`.

    Per model the baseline cell runs first, then cameras in the given order; each camera's
    emulation table is built once and used for every model.
    """
    import onnxruntime
    from tqdm import tqdm

    from fidelity.cocoeval import evaluate_detections, load_annotations
    from fidelity.detectors import Detector
    from fidelity.jpeg import roundtrip_jpeg
    from fidelity.sweep import ImageCache, file_sha256

    say = log or (lambda s: print(s, file=sys.stderr, flush=True))
    img_dir = Path(images)
    if not img_dir.is_dir():
        raise InputFileError(f"{img_dir}: image folder does not exist")
    coco = load_annotations(annotations)
    all_ids = sorted(coco.getImgIds())
    missing = [i for i in all_ids if not (img_dir / coco.imgs[i]["file_name"]).is_file()]
    if missing:
        raise InputFileError(f"{img_dir}: {len(missing)} annotated images missing, e.g. "
                             f"{coco.imgs[missing[0]]['file_name']}")
    store = ValidationStore(store_dir)
    from fidelity import __version__

    store.set_meta("versions", {"python": platform.python_version(),
                                "onnxruntime": onnxruntime.__version__, "numpy": np.__version__,
                                "fidelity": __version__, "colour": _colour_version()})
    store.set_meta("data", {"images": str(img_dir), "annotations": str(annotations),
                            "image_count": len(all_ids)})
    store.set_meta("machine", {"platform": platform.platform(), "cpus": os.cpu_count(),
                               "threads": threads, "provider": provider})
    store.set_meta("settings", {"emulation_method": method, "training": training,
                                "folds": FOLDS, "size_class": "n",
                                "jpeg": "original quantisation tables and subsampling "
                                        "(fidelity.jpeg.roundtrip_jpeg), as the COCO sweep"})
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
    d = [100.0 * (b[key] - f[key]) for b, f in zip(base_folds, folds, strict=True)
         if b.get(key) is not None and f.get(key) is not None]
    if len(d) < 2:
        return None
    return float(np.std(d, ddof=1) / math.sqrt(len(d)))


def collect_results(store: ValidationStore, tables: Sequence[str] | None = None,
                    bound_table: str | None = None) -> dict[str, Any]:
    """Predicted against measured losses of every finished (camera, model) cell.

    ``tables``: prediction tables to evaluate (default: all available); ``bound_table``: the
    worst-case table whose bound is tested (default :data:`fidelity.prediction.DEFAULT_TABLE`).
    Returns a JSON-ready dict with ``rows`` (one per camera and model), ``summary``,
    ``cameras`` (chart and emulation records), ``models`` and provenance.
    """
    from fidelity.prediction import DEFAULT_TABLE, available_tables

    tabs = list(tables) if tables else available_tables()
    bound = bound_table or DEFAULT_TABLE
    if bound not in tabs:
        tabs.append(bound)
    cases = store.cases()
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
    summary: dict[str, Any] = {"bound_table": bound, "tables": tabs}
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
    "image_delta_e",
    "load_suite",
    "predictions_for",
    "prepare_case",
    "run_validation",
]


def write_report(results: dict[str, Any], out_dir: str | os.PathLike[str]) -> list[Path]:
    """Placeholder replaced below."""
    from fidelity.fileio import write_json_atomic

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out / "validation.json", results)
    return [out / "validation.json"]
