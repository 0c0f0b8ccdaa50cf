"""Maintenance tools: re-sweeping detectors and rebuilding what reads the shipped COCO tables
(``resweep_model.sh``, ``resweep_queue.sh``, ``after_resweep``), comparing runs and versions
(``compare_tables``, ``compare_validation``, ``compare_preprocessing``, ``cross_machine``,
``reproduction_sample.sh``), the provenance of kept rows (``kept_provenance``), the COCO sweep
(``run_coco_sweep.sh``) and the benchmarks' matplotlib helpers (``plots``). Run as ``python -m
benchmarks.tools.NAME`` or ``benchmarks/tools/NAME.sh`` from the repository root
(docs/benchmarks.md).
"""
