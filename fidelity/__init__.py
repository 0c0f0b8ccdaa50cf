"""fidelity: camera-sensor-model colour-fidelity checker for driving simulators.

Implements the SAFE-COLOR method (Damschen, Avula, Mohamad, IEEE IV 2025): colour error of a
simulated camera, measured as CIEDE2000 on a Macbeth ColorChecker, mapped to predicted object
detection loss.

Two pipelines, one folder each:

- the camera check (:mod:`fidelity.pipeline.check`): :mod:`fidelity.colour` (colorimetry, spectra, chart
  data) → :mod:`fidelity.camera` (camera model, closed-form and Mitsuba renderers) →
  :mod:`fidelity.chart` (image reading, chart finding, measurement) → :mod:`fidelity.prediction`
  (transforms, calibration, ΔE → ΔmAP tables, verdicts) → :mod:`fidelity.report` (JSON, HTML,
  JUnit);
- the COCO benchmark (:mod:`fidelity.coco`): transformed datasets → ONNX detectors → COCO
  scoring → the sweep and its store → worst-case tables → validation of realistic cameras.

The names below are the public API; each is imported on first use, so ``import fidelity`` is
fast::

    import fidelity
    report = fidelity.check_camera("nikon-5100")     # render, measure, predict, verdict
    print(report.mean_delta_e, report.verdict.passed)
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from fidelity.core.lazy import lazy_attributes
from fidelity.core.version import __version__

#: Public name -> the module that defines it.
_API: dict[str, str] = {
    # the camera-check pipeline
    "check_camera": "fidelity.pipeline.check",
    "audit_image": "fidelity.pipeline.check",
    "audit_images": "fidelity.pipeline.check",
    "gate": "fidelity.pipeline.check",
    "compare_charts": "fidelity.pipeline.compare",
    "ComparisonReport": "fidelity.pipeline.records",
    "fit_correction": "fidelity.pipeline.fit",
    "Correction": "fidelity.pipeline.fit",
    "FitReport": "fidelity.pipeline.fit",
    # stages
    "delta_e_2000": "fidelity.colour.colorimetry",
    "load_chart": "fidelity.colour.charts",
    "Chart": "fidelity.colour.charts",
    "load_camera": "fidelity.camera.model",
    "CameraModel": "fidelity.camera.model",
    "render_chart": "fidelity.camera.render",
    "ChartRender": "fidelity.camera.render",
    "read_image": "fidelity.chart.image",
    "find_chart": "fidelity.chart.find.cascade",
    "FoundChart": "fidelity.chart.find.result",
    "measure_chart": "fidelity.measure.colour",
    "measure_image": "fidelity.measure.pixels",
    "ChartMeasurement": "fidelity.measure.colour",
    "ImageMeasurement": "fidelity.measure.pixels",
    "ReadOptions": "fidelity.chart.read",
    "JudgeOptions": "fidelity.prediction.judge",
    "apply_transform": "fidelity.prediction.transforms",
    "calibrate_transform": "fidelity.prediction.calibration",
    "predict": "fidelity.prediction.table",
    "predict_directional": "fidelity.prediction.directional",
    "DirectionalPrediction": "fidelity.prediction.directional",
    "error_parts": "fidelity.prediction.directional",
    "chart_blind_spots": "fidelity.measure.blindspots",
    "BlindSpot": "fidelity.measure.blindspots",
    "measure_mapping": "fidelity.coco.measure",
    "MeasuredLoss": "fidelity.coco.measure",
    "corrupt": "fidelity.coco.corruptions",
    "delta_e_limit": "fidelity.prediction.table",
    "Prediction": "fidelity.prediction.table",
    "Criterion": "fidelity.prediction.verdict",
    "Verdict": "fidelity.prediction.verdict",
    "evaluate": "fidelity.prediction.verdict",
    # records
    "ChartReport": "fidelity.pipeline.records",
    "GateResult": "fidelity.pipeline.records",
    # reports
    "write_chart_report": "fidelity.report.chart",
    "write_comparison_report": "fidelity.report.compare",
    # errors
    "FidelityError": "fidelity.core.errors",
}

if TYPE_CHECKING:
    from fidelity.camera.model import CameraModel, load_camera
    from fidelity.camera.render import ChartRender, render_chart
    from fidelity.chart.find.cascade import find_chart
    from fidelity.chart.find.result import FoundChart
    from fidelity.chart.image import read_image
    from fidelity.chart.read import ReadOptions
    from fidelity.coco.corruptions import corrupt
    from fidelity.coco.measure import MeasuredLoss, measure_mapping
    from fidelity.colour.charts import Chart, load_chart
    from fidelity.colour.colorimetry import delta_e_2000
    from fidelity.core.errors import FidelityError
    from fidelity.measure.blindspots import BlindSpot, chart_blind_spots
    from fidelity.measure.colour import ChartMeasurement, measure_chart
    from fidelity.measure.pixels import ImageMeasurement, measure_image
    from fidelity.pipeline.check import audit_image, audit_images, check_camera, gate
    from fidelity.pipeline.compare import compare_charts
    from fidelity.pipeline.fit import Correction, FitReport, fit_correction
    from fidelity.pipeline.records import ChartReport, ComparisonReport, GateResult
    from fidelity.prediction.calibration import calibrate_transform
    from fidelity.prediction.directional import (
        DirectionalPrediction,
        error_parts,
        predict_directional,
    )
    from fidelity.prediction.judge import JudgeOptions
    from fidelity.prediction.table import Prediction, delta_e_limit, predict
    from fidelity.prediction.transforms import apply_transform
    from fidelity.prediction.verdict import Criterion, Verdict, evaluate
    from fidelity.report.chart import write_chart_report
    from fidelity.report.compare import write_comparison_report


#: Import a public name's module on first use (PEP 562).
__getattr__ = lazy_attributes("fidelity", _API, globals())


def __dir__() -> list[str]:
    return sorted(__all__)


__all__ = [
    "__version__",
    "BlindSpot",
    "CameraModel",
    "Chart",
    "ChartMeasurement",
    "ChartRender",
    "ChartReport",
    "ComparisonReport",
    "Correction",
    "Criterion",
    "DirectionalPrediction",
    "FidelityError",
    "FitReport",
    "FoundChart",
    "GateResult",
    "ImageMeasurement",
    "JudgeOptions",
    "MeasuredLoss",
    "Prediction",
    "ReadOptions",
    "Verdict",
    "apply_transform",
    "audit_image",
    "audit_images",
    "calibrate_transform",
    "chart_blind_spots",
    "check_camera",
    "compare_charts",
    "corrupt",
    "delta_e_2000",
    "delta_e_limit",
    "error_parts",
    "evaluate",
    "find_chart",
    "fit_correction",
    "gate",
    "load_camera",
    "load_chart",
    "measure_chart",
    "measure_image",
    "measure_mapping",
    "predict",
    "predict_directional",
    "read_image",
    "render_chart",
    "write_chart_report",
    "write_comparison_report",
]
