"""Colour science: CIEDE2000 and colourspaces, spectra and illuminants, chart reference data.

Modules: :mod:`~fidelity.colour.colorimetry` (sRGB, CIELAB, ΔE00), :mod:`~fidelity.colour.spectral`
(patch reflectances, illuminants, the scene reference), :mod:`~fidelity.colour.charts` (reference
charts as data), :mod:`~fidelity.colour.diagnosis` (the likely cause of a chart's error: a small
camera pipeline fitted to its patches).
"""
