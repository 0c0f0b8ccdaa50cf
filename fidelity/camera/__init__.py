"""Camera models and renderers: stage 1 of the camera check.

Modules: :mod:`~fidelity.camera.model` (camera files, the ISP), :mod:`~fidelity.camera.render`
(render the spectral chart, closed form or Mitsuba), :mod:`~fidelity.camera.mitsuba` (the Mitsuba 3
scene and variant probing).
"""
