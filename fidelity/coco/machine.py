"""The processor a run computes on, for the provenance of detections.

onnxruntime chooses its kernels (MLAS) by the processor's instruction set, so the same code,
libraries, images and detector can give other detections on another processor: the int8
``ConvInteger`` detectors' detections differ between an AVX2 and an AVX-512 VNNI / AMX
processor on about one image in eight (reports/coco/cross_machine.md). The stores record
:func:`cpu_description` of every machine that ran in them (:mod:`fidelity.coco.driver`).
"""

from __future__ import annotations

import platform
from typing import Any

__all__ = ["KERNEL_INSTRUCTIONS", "cpu_description"]

#: Instruction-set extensions that choose onnxruntime's (MLAS) kernels (x86-64 and Arm names as
#: Linux's ``/proc/cpuinfo`` spells them).
KERNEL_INSTRUCTIONS = ("sse4_1", "avx", "avx2", "fma", "f16c", "avx512f", "avx512bw",
                       "avx512_vnni", "avx_vnni", "avx512_bf16", "amx_bf16", "amx_int8",
                       "asimd", "asimddp", "i8mm", "sve")


def cpu_description(cpuinfo: str | None = None) -> dict[str, Any]:
    """The processor that computes here: ``{"cpu": model name, "instructions": [...]}``.

    ``instructions``: which of :data:`KERNEL_INSTRUCTIONS` the processor reports (the flags of
    Linux's ``/proc/cpuinfo``, or ``cpuinfo`` given as its text); None where they cannot be read
    (another OS). ``cpu``: the first ``model name`` there, else :func:`platform.processor`.
    """
    if cpuinfo is None:
        try:
            with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as fh:
                cpuinfo = fh.read()
        except OSError:
            cpuinfo = ""
    model, flags = "", None
    for line in cpuinfo.splitlines():
        key, _, value = line.partition(":")
        key = key.strip().lower()
        if key == "model name" and not model:
            model = value.strip()
        elif key in ("flags", "features") and flags is None:
            flags = set(value.split())
    return {"cpu": model or platform.processor() or platform.machine() or None,
            "instructions": None if flags is None else
            [f for f in KERNEL_INSTRUCTIONS if f in flags]}
