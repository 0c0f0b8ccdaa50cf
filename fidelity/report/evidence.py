"""The credibility record of a run (``--evidence FILE`` of check, audit, gate, compare, fit).

One JSON document an assessment file can hold, answering what an assessor asks of every
number: which code and data produced it, how uncertain it is, inside which domain it holds and
by which rule pass/fail was decided. Its layout is the JSON Schema
``fidelity/data/schemas/evidence.schema.json`` (:func:`evidence_schema`); the manual's page
"Credibility record" maps each field to the sections of a simulation credibility assessment.

- ``record``: the layout version, when, which command, its exit code and outcome;
- ``invocation`` (layout 1.1; None when the record was made through the API): the command line
  as typed (``argv``, after ``fidelity``), the folder it ran in (``cwd``) and the settings file
  read (path and SHA-256, None when none was), so that the run can be repeated and a relative
  path resolved;
- ``tool``: name, version, the git commit of the source tree (None outside a checkout, with
  ``dirty`` when it has uncommitted changes) and ``code_sha256``, one SHA-256 over every Python
  file of the package that ran (sorted by path: path and bytes);
- ``environment``: Python, platform, the versions of the distribution's dependencies;
- ``decision_rule``: the rule, its coverage factor ``k`` and strictness;
- ``subjects``: per image or camera, its ``inputs`` (role, path, SHA-256, provenance), the
  ``reference`` (name and conventions), the ``prediction_table`` (name, kind, path, SHA-256, the
  table's own provenance: data set, detectors with their file hashes, preprocessing, code), the
  ``measurement`` with its ``uncertainty`` budget, the ``prediction`` with its ``interval``,
  the ``validity`` domain check, the ``verdict`` and the ``error`` of a subject that could not
  be measured;
- ``credibility_sections``: which keys answer which section of an assessment.

The same record is written in the SSP Traceability formats, SRMD and STMD
(:mod:`fidelity.report.ssp`), by the suffix of the file (:data:`EVIDENCE_FORMATS`).

The report layer renders the result records here (:mod:`fidelity.pipeline.records`); nothing is
measured again.
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
import subprocess
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fidelity.camera.model import available_cameras, camera_files
from fidelity.core.errors import FidelityError
from fidelity.core.fileio import (
    JSONObject,
    file_sha256,
    json_ready,
    write_json_atomic,
)
from fidelity.core.resources import resource_dir
from fidelity.core.version import __version__
from fidelity.pipeline.records import (
    ChartReport,
    ComparisonReport,
    ImageSource,
    Provenance,
    RenderSource,
    utc_now,
)
from fidelity.prediction.directional import load_directional_table
from fidelity.prediction.interval import (
    VALIDATED_CAMERAS_FILE,
    ValidityDomain,
    validity_domain,
)
from fidelity.prediction.properties import load_property_table
from fidelity.prediction.validated import PROPERTY_MARGIN_FILE, VALIDATED_BOUND_FILE
from fidelity.report.evidencefile import EVIDENCE_FORMATS, evidence_format, invocation_record
from fidelity.report.jsonform import fit_json, verdict_json

if TYPE_CHECKING:
    from fidelity.pipeline.context import ContextAssessment
    from fidelity.pipeline.fit import FitReport

#: Layout version of the credibility record (1.2: ``record.content_sha256``, the validated
#: cameras' file and the prediction table's scores files with their SHA-256).
EVIDENCE_SCHEMA_VERSION = "1.2"

#: Where the record's hash of its own content is (``record.content_sha256``).
CONTENT_HASH_KEY = "content_sha256"

#: Sections of a simulation credibility assessment and the record's keys that answer them.
CREDIBILITY_SECTIONS: Mapping[str, tuple[str, ...]] = {
    "context of use": ("context_of_use",),
    "model description": ("subjects[].inputs", "subjects[].reference",
                          "subjects[].prediction_table.provenance"),
    "verification": ("tool.version", "tool.commit", "tool.dirty", "tool.code_sha256",
                     "environment"),
    "validation": ("subjects[].prediction_table", "subjects[].property_tables",
                   "subjects[].directional_table", "subjects[].validity"),
    "uncertainty": ("subjects[].measurement.uncertainty", "subjects[].prediction.interval"),
    "traceability": ("subjects[].inputs[].sha256", "subjects[].prediction_table.sha256",
                     "subjects[].prediction_table.scores_files[].sha256",
                     "subjects[].property_tables[].sha256",
                     "subjects[].directional_table.sha256", "context_of_use.file.sha256",
                     "subjects[].validity.validated_cameras.sha256",
                     "subjects[].validated_bound.sha256",
                     "subjects[].property_margin.sha256", "record.content_sha256",
                     "tool.commit", "tool.code_sha256", "record.created", "invocation.argv",
                     "invocation.settings.sha256"),
    "decision": ("decision_rule", "subjects[].verdict", "record.exit_code", "record.outcome"),
}

#: What an exit code means.
OUTCOMES = {0: "pass", 1: "fail", 2: "error", 3: "internal error", 4: "undecided"}

PathArg = str | os.PathLike[str]


def evidence_schema_path() -> Path:
    """Path of the JSON Schema of the credibility record."""
    return resource_dir("data") / "schemas" / "evidence.schema.json"


def evidence_schema() -> JSONObject:
    """The JSON Schema (draft 2020-12) of the credibility record."""
    schema: JSONObject = json.loads(evidence_schema_path().read_text(encoding="utf-8"))
    return schema


def canonical_record_bytes(record: Mapping[str, Any]) -> bytes:
    """The canonical content of a credibility record, over which ``record.content_sha256`` is
    computed: the record as JSON values without that one field, serialised with its keys
    sorted at every level, compact separators (``,`` and ``:``, no spaces), every non-ASCII
    character as its ``\\uXXXX`` escape (so a file name's undecodable byte, held as a lone
    surrogate, has a form too) and the whole encoded as UTF-8, which is then ASCII (floats as
    Python writes them: the
    shortest decimal that reads back to the same number; NaN is not JSON and is refused).

    Parameters
    ----------
    record : Mapping
        The record as written or as read back from its file (``json.load``).

    Returns
    -------
    bytes
        The canonical form; the same for the record in memory and the one read from its
        file, whatever the file's indentation or key order.
    """
    header = dict(record.get("record") or {})
    header.pop(CONTENT_HASH_KEY, None)
    doc = {**record, "record": header}
    return json.dumps(doc, sort_keys=True, separators=(",", ":"), ensure_ascii=True,
                      allow_nan=False).encode("utf-8")


def record_content_sha256(record: Mapping[str, Any]) -> str:
    """The SHA-256 (hex digest, 64 lower-case digits) of :func:`canonical_record_bytes`."""
    return hashlib.sha256(canonical_record_bytes(record)).hexdigest()


def seal_record(record: JSONObject) -> JSONObject:
    """``record`` with ``record.content_sha256`` set to the hash of its content now
    (:func:`record_content_sha256`); sealing again after an edit gives the edited record its
    own hash. The hash shows an edit made without sealing again: it is not a signature."""
    record["record"][CONTENT_HASH_KEY] = record_content_sha256(record)
    return record


def _package_dir() -> Path:
    return Path(__file__).resolve().parent.parent


def code_sha256(package: Path | None = None) -> str:
    """One SHA-256 over the package's Python files, sorted by relative path (path, NUL, bytes,
    NUL for each)."""
    root = package or _package_dir()
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        digest.update(path.relative_to(root).as_posix().encode() + b"\0")
        digest.update(path.read_bytes() + b"\0")
    return digest.hexdigest()


def git_commit(folder: Path | None = None) -> tuple[str | None, bool | None]:
    """The commit of the git checkout holding the package (None outside one) and whether the
    package has uncommitted changes."""
    where = folder or _package_dir()
    try:
        head = subprocess.run(["git", "-C", str(where), "rev-parse", "HEAD"],
                              capture_output=True, text=True, timeout=10)
        if head.returncode != 0:
            return None, None
        status = subprocess.run(["git", "-C", str(where), "status", "--porcelain", "--",
                                 str(where)], capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None, None
    return head.stdout.strip() or None, bool(status.stdout.strip())


def tool_record() -> dict[str, Any]:
    """``tool``: name, version, commit, dirty, code_sha256."""
    commit, dirty = git_commit()
    return {"name": "fidelity", "distribution": "camera-fidelity", "version": __version__,
            "commit": commit, "dirty": dirty, "code_sha256": code_sha256()}


def environment_record() -> dict[str, Any]:
    """``environment``: Python, platform, machine and the versions of the libraries a report
    records (:meth:`fidelity.pipeline.records.Provenance.collect`)."""
    libraries = Provenance.collect(None, None, {}).libraries
    return {"python": platform.python_version(), "implementation":
            platform.python_implementation(), "platform": platform.platform(),
            "machine": platform.machine(), "dependencies": dict(libraries)}


def _file_input(role: str, path: str | os.PathLike[str], sha256: str | None = None,
                provenance: Mapping[str, Any] | None = None) -> dict[str, Any]:
    digest = sha256
    if digest is None:
        try:
            digest = file_sha256(path)
        except OSError:
            digest = None
    return {"role": role, "path": str(path), "sha256": digest,
            "provenance": dict(provenance or {})}


def _inputs(report: ChartReport) -> list[dict[str, Any]]:
    src = report.source
    if isinstance(src, ImageSource):
        info = src.image
        inputs = [_file_input("image", info.path, info.sha256, {
            "format": info.format, "pixel_type": info.pixel_type,
            "size": [info.width, info.height], "encoding": src.encoding,
            "colourspace": src.colourspace, "exposure_mode": src.exposure_mode,
            "corners": src.corners.tolist(),
            "corners_found": src.found.to_json() if src.found else None,
            **({"ocio": info.ocio.to_json()} if info.ocio else {})})]
        if info.ocio is not None and not info.ocio.config.startswith("ocio://"):
            inputs.append(_file_input("OpenColorIO config", info.ocio.config, provenance={
                "name": info.ocio.config_name, "cache_id": info.ocio.config_id}))
        return inputs
    assert isinstance(src, RenderSource)

    out = []
    source = str(src.camera_settings.get("source", src.camera))
    if source == f"built-in {src.camera}" and src.camera in available_cameras():
        out.append(_file_input("camera (built-in)",
                               resource_dir("data") / "cameras" / f"{src.camera}.toml",
                               provenance={"name": src.camera}))
    files = camera_files(source)
    out += [_file_input("camera file" if i == 0 else "camera data", f,
                        provenance={"camera": src.camera}) for i, f in enumerate(files)]
    out.append({"role": "render settings", "path": None, "sha256": None,
                "provenance": {"renderer": src.renderer, "variant": src.variant,
                               "illuminant": src.illuminant,
                               "settings": json_ready(dict(src.render_settings)),
                               "camera": json_ready(dict(src.camera_settings))}})
    return out


def _table(report: ChartReport) -> dict[str, Any] | None:
    p = report.prediction
    if p is None:
        return None
    ref = report.provenance.tables.get("prediction")
    calibration = report.provenance.tables.get("calibration")
    return {"name": p.table.name, "kind": p.table.kind.value,
            "path": ref.path if ref else (str(p.table.path) if p.table.path else None),
            "sha256": ref.sha256 if ref else None, "provenance": dict(p.table.provenance),
            "scores_files": scores_files(p.table.provenance),
            "calibration": calibration.to_json() if calibration else None}


def property_tables(report: ChartReport) -> list[dict[str, Any]]:
    """The sharpness and noise tables a check's prediction judged with (its
    ``properties.predictions``), each once: ``{"name", "property", "path", "sha256",
    "scores_files"}``; path and SHA-256 None for a table not found by its name here."""
    judged = report.properties
    out: list[dict[str, Any]] = []
    seen: set[str] = set()
    for prediction in (judged.predictions if judged is not None else ()):
        if prediction.table in seen:
            continue
        seen.add(prediction.table)
        try:
            table = load_property_table(prediction.table)
        except FidelityError:
            out.append({"name": prediction.table, "property": prediction.property,
                        "path": None, "sha256": None, "scores_files": []})
            continue
        entry = _file_entry(table.path) if table.path else {"path": None, "sha256": None}
        out.append({"name": table.name, "property": table.property, **entry,
                    "scores_files": scores_files(table.provenance)})
    return out


def directional_table(report: ChartReport) -> dict[str, Any] | None:
    """The direction-aware table the report's direction-aware prediction read (its loss and
    its SE): ``{"name", "path", "sha256", "scores_files"}``; None without that prediction,
    path and SHA-256 None for a table not found here."""
    d = report.directional
    if d is None:
        return None
    name = str(d.table.get("name"))
    path = d.table.get("path")
    try:
        table = load_directional_table(str(path) if path else name)
    except FidelityError:
        return {"name": name, "path": None, "sha256": None, "scores_files": []}
    entry = (_file_entry(Path(table.path)) if table.path
             else {"path": None, "sha256": None})
    return {"name": table.name, **entry, "scores_files": scores_files(table.provenance)}


def scores_files(provenance: Mapping[str, Any]) -> list[dict[str, Any]]:
    """The scores files a table's rows rebuild from, as its ``provenance.scores_files`` names
    them: each ``{"path", "sha256", "models"}``, the path relative to the source checkout
    (``reports/coco/...``; a wheel does not ship them); an empty list for a table that names
    none (published bounds)."""
    return [{"path": str(f.get("path")), "sha256": f.get("sha256"),
             "models": list(f.get("models") or [])}
            for f in provenance.get("scores_files") or [] if isinstance(f, Mapping)]


def validated_cameras_file() -> dict[str, Any]:
    """``{"path", "sha256"}`` of the shipped validated cameras
    (:data:`~fidelity.prediction.interval.VALIDATED_CAMERAS_FILE`), which the ``validated
    illuminant`` and ``validated camera kind`` checks of the validity domain quote."""
    return _file_entry(resource_dir("data") / VALIDATED_CAMERAS_FILE)


def validated_bound_file(report: ChartReport) -> dict[str, Any] | None:
    """``{"path", "sha256"}`` of the shipped validated bound
    (:data:`~fidelity.prediction.validated.VALIDATED_BOUND_FILE`) where the report's interval
    states it; None otherwise."""
    if report.interval is None or report.interval.validated_upper is None:
        return None
    return _file_entry(resource_dir("data") / VALIDATED_BOUND_FILE)


def property_margin_file(report: ChartReport) -> dict[str, Any] | None:
    """``{"path", "sha256"}`` of the shipped margin of the combined property loss
    (:data:`~fidelity.prediction.validated.PROPERTY_MARGIN_FILE`) where the report's combined
    loss includes it; None otherwise."""
    j = report.properties
    if j is None or j.combined is None or not j.combined.margin:
        return None
    return _file_entry(resource_dir("data") / PROPERTY_MARGIN_FILE)


def _file_entry(path: Path) -> dict[str, Any]:
    try:
        digest: str | None = file_sha256(path)
    except OSError:
        digest = None
    return {"path": str(path), "sha256": digest}


def _validity(validity: ValidityDomain | None) -> dict[str, Any] | None:
    """The validity domain, with the validated cameras' file when a check quotes it."""
    if validity is None:
        return None
    out = validity.to_json()
    if any(c.name.startswith("validated ") for c in validity.checks):
        out["validated_cameras"] = validated_cameras_file()
    return out


def _subject(subject: str, report: ChartReport | None, error: str | None) -> dict[str, Any]:
    if report is None:
        return {"subject": subject, "error": error or "no report", "inputs": [],
                "reference": None, "prediction_table": None, "measurement": None,
                "prediction": None, "validity": None, "verdict": None}
    p, d = report.prediction, report.directional
    return {
        "subject": subject, "error": None, "command": report.command,
        "inputs": _inputs(report),
        "reference": {"name": report.source.reference,
                      "description": report.source.reference_description,
                      "conventions": json_ready(dict(report.provenance.conventions))},
        "prediction_table": _table(report),
        "property_tables": property_tables(report),
        "directional_table": directional_table(report),
        "validated_bound": validated_bound_file(report),
        "property_margin": property_margin_file(report),
        "measurement": {
            "quantity": "mean ΔE00", "value": report.mean_delta_e,
            "max_delta_e": report.max_delta_e, "worst_patch": report.worst_patch,
            "uncertainty": report.uncertainty.to_json() if report.uncertainty else None},
        "prediction": None if p is None else {
            "delta_e": p.delta_e, "size": p.size, "size_used": p.size_used,
            "dmap_points": p.dmap_points, "dmap_relative": p.dmap_relative,
            "dap_person_points": p.dap_person_points,
            "dap_bicycle_points": p.dap_bicycle_points, "upper_bound": p.upper_bound,
            "interval": report.interval.to_json() if report.interval else None,
            "directional_dmap_points": d.dmap_points if d else None, "bound": report.bound,
            # sharpness and noise judged with colour (the tables, their values, the sum)
            "properties": report.properties.to_json() if report.properties else None},
        "validity": _validity(report.validity),
        "verdict": verdict_json(report.verdict) if report.verdict else None,
    }


def evidence_record(command: str, subjects: Sequence[tuple[str, ChartReport | ComparisonReport
                                                          | None, str | None]],
                    exit_code: int, invocation: Mapping[str, Any] | None = None
                    ) -> JSONObject:
    """The credibility record (module docstring) of ``command`` over ``subjects`` (name,
    report or None, error or None) that ended with ``exit_code``; ``invocation``: the
    command line (:func:`invocation_record`), None for a run through the API."""
    items = []
    rule = None
    context = None
    for name, report, error in subjects:
        chart = report.as_chart_report() if isinstance(report, ComparisonReport) else report
        if context is None and chart is not None and chart.context is not None:
            context = context_of_use(chart.context)
        item = _subject(name, chart, error)
        if isinstance(report, ComparisonReport):
            item["inputs"] = (_subject(name, report.sim, None)["inputs"]
                              + [dict(x, role="real image")
                                 for x in _subject(name, report.real, None)["inputs"]])
        items.append(item)
        if chart is not None and chart.verdict is not None and rule is None:
            rule = chart.verdict.decision.to_json()
    return _record(command, exit_code, rule, items, invocation, context)


def context_of_use(assessment: ContextAssessment) -> dict[str, Any]:
    """The record's ``context_of_use`` (layout 1.2, ``--context``): the context file
    (``file``: path and SHA-256), the context (detectors, conditions, acceptance criteria,
    model risk), the credibility factors and levels, what lies outside the validity domain and
    the acceptance criteria judged per subject (:meth:`ContextAssessment.to_json`)."""
    return {"file": _file_entry(Path(assessment.context.path)), **assessment.to_json()}


def _record(command: str, exit_code: int, rule: Mapping[str, Any] | None,
            subjects: Sequence[Mapping[str, Any]],
            invocation: Mapping[str, Any] | None = None,
            context: Mapping[str, Any] | None = None) -> JSONObject:
    """The record around ``subjects``: its header, the command line, the tool, the
    environment, the decision ``rule``, the ``context`` of use (``--context``; omitted
    without one) and the map to the credibility sections."""
    out: JSONObject = json_ready({
        "record": {"schema": "fidelity credibility record",
                   "schema_version": EVIDENCE_SCHEMA_VERSION, "created": utc_now(),
                   "command": command, "exit_code": int(exit_code),
                   "outcome": OUTCOMES.get(int(exit_code), "unknown")},
        "invocation": dict(invocation) if invocation is not None else None,
        "tool": tool_record(),
        "environment": environment_record(),
        "decision_rule": rule,
        "subjects": list(subjects),
        **({"context_of_use": dict(context)} if context is not None else {}),
        "credibility_sections": {k: list(v) for k, v in CREDIBILITY_SECTIONS.items()},
    })
    return seal_record(out)


def fit_evidence_record(report: FitReport, exit_code: int = 0,
                        invocation: Mapping[str, Any] | None = None) -> JSONObject:
    """The credibility record of ``fidelity fit``: one subject, the pair SIM -> REAL, whose
    inputs are the two images (SHA-256), whose measurement is the sim-to-real mean ΔE00 after
    the correction (SIM through the ``.cube`` by OpenColorIO, measured again), whose prediction
    is that difference's, and which adds ``correction``: the fit's JSON report
    (:func:`fidelity.report.jsonform.fit_json`: before/after, fitted and cross-validated ΔE00,
    the ``.cube``'s check, the model) and the SHA-256 of every file written. A fit has no
    verdict; its validity domain is the prediction table's."""
    p = report.prediction_after
    validity = validity_domain(p)
    files: dict[str, dict[str, str | None]] = {}
    for name, path in report.files.items():
        try:
            files[name] = {"path": path, "sha256": file_sha256(path)}
        except OSError:
            files[name] = {"path": path, "sha256": None}
    subject = {
        "subject": f"{report.sim} -> {report.real}", "error": None, "command": "fit",
        "inputs": [_file_input("simulated image", report.sim),
                   _file_input("real image", report.real)],
        "reference": {"name": "the real camera's chart",
                      "description": "sim-to-real ΔE00: the simulated chart measured against "
                                     "the real camera's, patch by patch",
                      "conventions": {}},
        "prediction_table": {"name": p.table.name, "kind": p.table.kind.value,
                             "path": str(p.table.path) if p.table.path else None,
                             "sha256": (file_sha256(p.table.path) if p.table.path else None),
                             "provenance": dict(p.table.provenance),
                             "scores_files": scores_files(p.table.provenance),
                             "calibration": None},
        "measurement": {"quantity": "sim-to-real mean ΔE00 after the correction",
                        "value": report.after.mean_delta_e,
                        "max_delta_e": report.after.max_delta_e,
                        "worst_patch": report.after.worst_patch, "uncertainty": None,
                        "before": report.before.mean_delta_e},
        "prediction": {"delta_e": p.delta_e, "size": p.size, "size_used": p.size_used,
                       "dmap_points": p.dmap_points, "dmap_relative": p.dmap_relative,
                       "dap_person_points": p.dap_person_points,
                       "dap_bicycle_points": p.dap_bicycle_points,
                       "upper_bound": p.upper_bound, "interval": None,
                       "directional_dmap_points": None, "bound": "classic"},
        "validity": _validity(validity),
        "verdict": None,
        "correction": {"report": fit_json(report), "files": files},
    }
    return _record("fit", exit_code, None, [subject], invocation)


def _write_json(path: PathArg, record: JSONObject, results: Sequence[PathArg]) -> Path:
    return write_json_atomic(path, seal_record(record))


def _write_srmd(path: PathArg, record: JSONObject, results: Sequence[PathArg]) -> Path:
    from fidelity.report.ssp import write_srmd  # noqa: PLC0415 (needs the [ssp] extra)

    return write_srmd(path, record, results)


def _write_stmd(path: PathArg, record: JSONObject, results: Sequence[PathArg]) -> Path:
    from fidelity.report.ssp import write_stmd  # noqa: PLC0415 (needs the [ssp] extra)

    return write_stmd(path, record, results)


def _write_xqar(path: PathArg, record: JSONObject, results: Sequence[PathArg]) -> Path:
    from fidelity.report.xqar import write_xqar  # noqa: PLC0415 (needs the [qc] extra)

    return write_xqar(path, record, results)


#: The writer of each format, in the order they are written: the JSON record first, the SRMD
#: next (it lists the JSON among the results, with its checksum), the STMD last (it lists
#: both; the SRMD as the verdict's).
WRITERS: Mapping[str, Callable[[PathArg, JSONObject, Sequence[PathArg]], Path]] = {
    ".json": _write_json, ".srmd": _write_srmd, ".stmd": _write_stmd, ".xqar": _write_xqar}


def write_record(paths: PathArg | Sequence[PathArg], record: JSONObject,
                 results: Sequence[PathArg] = ()) -> list[Path]:
    """Write ``record`` to each of ``paths`` in the format of its suffix
    (:func:`evidence_format`), atomically, in the order of :data:`WRITERS`; ``results`` are the
    files the run wrote (the SSP formats list them with their checksums, and each evidence file
    written before). Returns the paths written."""
    given = list(dict.fromkeys(Path(p) for p in ([paths] if isinstance(paths, str | os.PathLike)
                                                  else paths)))  # each file once
    order = list(WRITERS)
    written: list[Path] = []
    for path in sorted(given, key=lambda p: order.index(evidence_format(p))):
        written.append(WRITERS[evidence_format(path)](path, record, [*results, *written]))
    return written


def write_evidence(paths: PathArg | Sequence[PathArg], command: str,
                   subjects: Sequence[tuple[str, ChartReport | ComparisonReport | None,
                                            str | None]],
                   exit_code: int, results: Sequence[PathArg] = (),
                   invocation: Mapping[str, Any] | None = None) -> list[Path]:
    """Write the credibility record (:func:`evidence_record`) to ``paths``
    (:func:`write_record`)."""
    return write_record(paths, evidence_record(command, subjects, exit_code, invocation),
                        results)


def write_fit_evidence(paths: PathArg | Sequence[PathArg], report: FitReport,
                       exit_code: int = 0, results: Sequence[PathArg] = (),
                       invocation: Mapping[str, Any] | None = None) -> list[Path]:
    """Write the fit's credibility record (:func:`fit_evidence_record`) to ``paths``
    (:func:`write_record`)."""
    return write_record(paths, fit_evidence_record(report, exit_code, invocation), results)


__all__ = ["CONTENT_HASH_KEY", "CREDIBILITY_SECTIONS", "EVIDENCE_FORMATS",
           "EVIDENCE_SCHEMA_VERSION", "OUTCOMES", "WRITERS", "canonical_record_bytes",
           "code_sha256", "record_content_sha256", "scores_files", "seal_record",
           "validated_bound_file", "property_margin_file", "validated_cameras_file", "environment_record", "evidence_format",
           "evidence_record", "evidence_schema", "evidence_schema_path",
           "fit_evidence_record", "git_commit", "invocation_record", "tool_record", "write_evidence",
           "write_fit_evidence", "write_record"]
