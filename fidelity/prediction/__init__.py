"""From chart ΔE to detection loss: stage 3 of the camera check.

Modules: :mod:`~fidelity.prediction.transforms` (the SAFE-COLOR colour transforms),
:mod:`~fidelity.prediction.calibration` (transform parameter per target ΔE),
:mod:`~fidelity.prediction.tablefile` (the ΔE → ΔmAP table files and their registry),
:mod:`~fidelity.prediction.interpolate` (a table's curves read at a ΔE),
:mod:`~fidelity.prediction.table` (the prediction and its inverse, the ΔE limit),
:mod:`~fidelity.prediction.colour` (colour's part: the transform parameters of a ΔE),
:mod:`~fidelity.prediction.verdict` (pass/fail criteria).
"""
