"""Charts in images: reading, finding, locating and measuring: stage 2 of the camera check.

Modules: :mod:`~fidelity.chart.image` (EXR, HDR, TIFF, PNG, JPEG), :mod:`~fidelity.chart.find`
(find the chart), :mod:`~fidelity.chart.locate` (patch windows from corner centres),
:mod:`~fidelity.chart.measure` (ΔE00 per patch).
"""
