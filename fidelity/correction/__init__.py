"""Colour correction: fit the map from a simulated chart's colours onto a real camera's
(:mod:`fidelity.correction.models`) and hand it to a simulator as a 3D LUT that OpenColorIO
loads (:mod:`fidelity.correction.lut`)."""
