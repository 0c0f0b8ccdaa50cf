"""The JSON reports: the records' JSON forms with the sentences a person reads beside the numbers.

A record's ``to_json`` holds its fields; the JSON report a command writes (``check``, ``audit``,
``gate``, ``compare``, ``predict``) adds, for each prediction, its ``notes`` and each column's
``note``, and for each verdict its ``message``, written by :mod:`fidelity.report.words`. The
report's layout is the JSON Schema ``fidelity/data/schemas/report.schema.json``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from fidelity.core.fileio import JSONObject, json_ready
from fidelity.pipeline.records import ChartReport, ComparisonReport
from fidelity.prediction.table import Prediction
from fidelity.prediction.verdict import Verdict
from fidelity.report.words import column_note, prediction_notes, verdict_message

if TYPE_CHECKING:
    from fidelity.coco.corruptions import CocoCAnswer
    from fidelity.pipeline.fit import FitReport, SharedFit
    from fidelity.prediction.interval import PredictionInterval, ValidityDomain


def prediction_json(prediction: Prediction,
                    families: Mapping[str, float | None] | None = None) -> dict[str, Any]:
    """:meth:`Prediction.to_json <fidelity.prediction.table.Prediction.to_json>` with the
    ``notes`` and each column's ``note``; with ``families`` (``fidelity predict``: the
    direction-aware ΔmAP of an error entirely of each transform family), also
    ``directional_by_family``."""
    out = prediction.to_json()
    for col, c in out["columns"].items():
        c["note"] = column_note(prediction, col)
    out["notes"] = prediction_notes(prediction)
    if families is not None:
        out["directional_by_family"] = dict(families)
    return out


def predict_json(prediction: Prediction, families: Mapping[str, float | None] | None,
                 interval: PredictionInterval | None, validity: ValidityDomain) -> JSONObject:
    """The JSON report of ``fidelity predict --delta-e``: :func:`prediction_json`, with the
    predicted ΔmAP's ``prediction_interval`` (None where there is nothing to state) and the
    answer's ``validity`` domain (:func:`fidelity.pipeline.check.prediction_domain`)."""
    out: JSONObject = json_ready(prediction_json(prediction, families) | {
        "prediction_interval": interval.to_json() if interval is not None else None,
        "validity": validity.to_json()})
    return out


def coco_c_answer_json(answer: CocoCAnswer) -> dict[str, Any]:
    """The answer of ``fidelity predict --coco-c`` as JSON, its prediction with the notes."""
    return answer.to_json() | {"prediction": prediction_json(answer.prediction)}


def verdict_json(verdict: Verdict, delta_e_name: str = "mean ΔE00") -> dict[str, Any]:
    """:meth:`Verdict.to_json <fidelity.prediction.verdict.Verdict.to_json>` with the
    ``message``."""
    return verdict.to_json() | {"message": verdict_message(verdict, delta_e_name)}


def chart_report_json(report: ChartReport) -> JSONObject:
    """The JSON report of a chart (``check``, ``audit``, ``gate``; the module docstring of
    :mod:`fidelity.pipeline.records` lists its keys), strict JSON values."""
    r = report
    m = r.measurement.to_json()
    patches = m["patches"]
    if r.valid_pixels is not None:
        per_patch = r.bad_pixels.per_patch if r.bad_pixels else {}
        for p, n in zip(patches, r.valid_pixels, strict=True):
            p.update(valid_pixels=int(n), bad_pixels=int(per_patch.get(p["name"], 0)))
    out: JSONObject = json_ready({
        "schema_version": r.schema_version,
        "command": r.command,
        "created": r.created,
        "mean_delta_e": m["mean_delta_e"],
        "max_delta_e": m["max_delta_e"],
        "worst_patch": m["worst_patch"],
        "patches": patches,
        "exposure_ev": r.exposure_ev,
        "bad_pixels": r.bad_pixels.to_json() if r.bad_pixels else None,
        "source": r.source.to_json(),
        "prediction": prediction_json(r.prediction) if r.prediction else None,
        "verdict": verdict_json(r.verdict) if r.verdict else None,
        "details": r.source.details(),
        "provenance": r.provenance.to_json(),
        "bound": r.bound,
        "directional_prediction": r.directional.to_json() if r.directional else None,
        "blind_spots": [b.to_json() for b in r.blind_spots],
        "measured_loss": [x.to_json() for x in r.measured],
        "uncertainty": r.uncertainty.to_json() if r.uncertainty else None,
        "prediction_interval": r.interval.to_json() if r.interval else None,
        "prediction_intervals": [i.to_json() for i in r.intervals],
        "validity": r.validity.to_json() if r.validity else None,
        "noise": r.noise.to_json() if r.noise else None,
        "sharpness": r.sharpness.to_json() if r.sharpness else None,
        "properties": r.properties.to_json() if r.properties else None,
        "exposure": r.exposure.to_json() if r.exposure else None,
        "neutral_ev": r.neutral_ev,
        "diagnosis": r.diagnosis.to_json() if r.diagnosis else None,
    })
    if r.context is not None:
        out["context"] = json_ready(r.context.to_json())
    return out


def comparison_json(report: ComparisonReport) -> JSONObject:
    """The JSON report of a sim-to-real comparison (``compare``): the sim-to-real summary and
    patches first, the two charts' sharpness and noise side by side (``sharpness_noise``:
    :meth:`fidelity.pipeline.simreal.TextureComparison.to_json`), then the two audits as
    :func:`chart_report_json` writes them."""
    r = report
    m = r.measurement.to_json()
    out: JSONObject = json_ready({
        "schema_version": r.schema_version, "command": r.command, "created": r.created,
        "sim_to_real": {"mean_delta_e": m["mean_delta_e"], "max_delta_e": m["max_delta_e"],
                        "worst_patch": m["worst_patch"],
                        "normalisation": r.normalisation.to_json(), "patches": m["patches"],
                        "uncertainty": r.uncertainty.to_json() if r.uncertainty else None},
        "sim_delta_e": r.sim.mean_delta_e, "real_delta_e": r.real.mean_delta_e,
        "prediction": prediction_json(r.prediction),
        "directional_prediction": r.directional.to_json() if r.directional else None,
        "bound": r.bound,
        "verdict": verdict_json(r.verdict) if r.verdict else None,
        "measured_loss": [x.to_json() for x in r.measured],
        "emulation": dict(r.emulation) if r.emulation else None,
        "prediction_interval": r.interval.to_json() if r.interval else None,
        "prediction_intervals": [i.to_json() for i in r.intervals],
        "validity": r.validity.to_json() if r.validity else None,
        "sharpness_noise": r.texture.to_json() if r.texture else None,
        "sim": chart_report_json(r.sim), "real": chart_report_json(r.real),
        "provenance": r.provenance.to_json()})
    return out


def fit_json(report: FitReport) -> JSONObject:
    """The JSON report of ``fidelity fit``: the sim-to-real ΔE00 before and after (the SIM
    image through the ``.cube`` by OpenColorIO, audited again) with their predictions, the
    fitted and cross-validated ΔE00, the ``.cube``'s check against the model and its
    convention (``cube``: input, domain, output, size), the ``warnings``
    (:attr:`fidelity.pipeline.fit.FitReport.warnings`), the correction
    (:meth:`fidelity.pipeline.fit.Correction.to_json`), the files written and the seconds spent."""
    r, c = report, report.correction

    def side(m: Any, p: Prediction) -> dict[str, Any]:
        j = m.to_json()
        return {"mean_delta_e": j["mean_delta_e"], "max_delta_e": j["max_delta_e"],
                "worst_patch": j["worst_patch"], "prediction": prediction_json(p),
                "patches": [{"name": q["name"], "delta_e": q["delta_e"]} for q in j["patches"]]}

    out: JSONObject = json_ready({
        "command": "fit", "created": r.created, "sim": r.sim, "real": r.real,
        "model": c.model.name, "objective": c.objective,
        "before": side(r.before, r.prediction_before),
        "after": side(r.after, r.prediction_after),
        "fitted_mean_delta_e": c.to_json()["fitted_mean_delta_e"],
        "cross_validated_mean_delta_e": c.to_json()["cross_validated_mean_delta_e"],
        "lut_check": r.lut.to_json(), "lut_checks": [x.to_json() for x in r.lut_checks],
        "cube": {"input": "srgb-encoded" if c.encoding == "srgb" else "scene-linear",
                 "domain": [0.0, c.to_json(r.output)["cube_domain"][1]],
                 "output": "srgb-encoded" if r.output == "encoded" else "scene-linear",
                 "size": r.lut.size},
        "warnings": r.warnings,
        "correction": c.to_json(r.output), "files": dict(r.files), "seconds": dict(r.seconds),
        "measured_before": [m.to_json() for m in r.measured_before],
        "measured_after": [m.to_json() for m in r.measured_after],
        "properties": {
            "sim": r.sim_properties.to_json() if r.sim_properties is not None else None,
            "real": r.real_properties.to_json() if r.real_properties is not None else None},
        "camera_fits": [f.to_json() for f in r.camera_fits]})
    return out


def shared_fit_json(shared: SharedFit) -> JSONObject:
    """The JSON report of ``fidelity fit --pair``: the shared matrix, its conditioning and per
    pair the gains, the ΔE00 before and after, fitted and cross-validated, and the full report
    of that pair's correction (:func:`fit_json`)."""
    doc = shared.to_json()
    for pair, rep in zip(doc["pairs"], shared.reports, strict=True):
        pair["report"] = fit_json(rep)
    out: JSONObject = json_ready({"command": "fit", "created": shared.created, **doc,
                                  "seconds": dict(shared.seconds)})
    return out


__all__ = ["chart_report_json", "coco_c_answer_json", "comparison_json", "fit_json",
           "shared_fit_json",
           "prediction_json", "verdict_json"]
