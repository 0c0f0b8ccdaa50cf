"""The COCO benchmark: what colour error costs object detectors, measured.

Pipeline: :mod:`~fidelity.coco.dataset` (transformed JPEG copies), :mod:`~fidelity.coco.detectors`
(ONNX detectors), :mod:`~fidelity.coco.scoring` (COCO mAP), :mod:`~fidelity.coco.sweep` (the grid
of models x transforms x ΔE targets, in a :mod:`~fidelity.coco.store`), :mod:`~fidelity.coco.tables`
(worst-case tables), :mod:`~fidelity.coco.emulation` and :mod:`~fidelity.coco.validate` (realistic
cameras emulated on COCO). The tables and the validation are packages with a floor shared by
every camera property and a room per property (colour's so far): their docstrings say where a
second one plugs in.
"""
