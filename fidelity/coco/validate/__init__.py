"""Validate the prediction on realistic camera models: predicted against measured ΔmAP.

A suite of camera files (:mod:`~fidelity.coco.validate.suite`), each camera's effect
emulated on every COCO image and the detectors run on the result
(:mod:`~fidelity.coco.validate.colour`, through the store driver and executors of
:mod:`fidelity.coco.driver` and :mod:`fidelity.coco.executor`), the cells kept in a
crash-safe store (:mod:`~fidelity.coco.validate.store`), and each cell's measured loss set
beside what the prediction tables predict at the camera's chart value
(:mod:`~fidelity.coco.validate.checks`).

The floor, whatever camera property is validated:

- :mod:`~fidelity.coco.validate.suite`: the test cases (camera files, their illuminants);
- :mod:`~fidelity.coco.validate.store`: the store (cells detector × camera, detections, fold
  and bootstrap scores, per-camera records) and its executor adapter;
- :mod:`~fidelity.coco.validate.checks`: the bound checks (within, within 2 SE), the rows
  and their summaries per class.

Colour's room:

- :mod:`~fidelity.coco.validate.camera`: what the validation records of a camera (its chart
  ΔE under the case's illuminant, the error's direction, its fitted colour emulation);
- :mod:`~fidelity.coco.validate.colour`: the colour emulations run on COCO
  (:func:`~fidelity.coco.validate.colour.run_validation`) and ``validation.json``
  (:func:`~fidelity.coco.validate.colour.collect_results`), with the direction-aware bound
  (:mod:`fidelity.coco.bounds`) and the validity domain.

A second property (sharpness, noise) plugs in beside ``camera.py`` and ``colour.py``: its
camera record (the camera's value on its chart, its emulation's provenance) and a module that
emulates it on COCO through the same store, driver and executors and judges the cells with
:func:`~fidelity.coco.validate.checks.validation_row` and
:func:`~fidelity.coco.validate.checks.class_summary`. The store's ``cases`` table reads
colour's :class:`~fidelity.coco.validate.camera.CameraRecord` and the rows name the chart value
``chart_delta_e``: the property that first needs another record or axis gives them its own.
"""
