"""From chart ΔE to detection loss: stage 3 of the camera check.

Modules: :mod:`~fidelity.prediction.transforms` (the SAFE-COLOR colour transforms),
:mod:`~fidelity.prediction.calibration` (transform parameter per target ΔE),
:mod:`~fidelity.prediction.table` (ΔE → ΔmAP tables and the prediction),
:mod:`~fidelity.prediction.verdict` (pass/fail criteria).
"""
